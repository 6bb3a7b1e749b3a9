// wp_tile.h: block-cooperative tiles (design slice 1, docs/design/tiles.md section 5), the CUDA
// side of warp-core/src/tile/. Every result here must agree bit for bit with warp-core's for the
// same block size: tests/cuda_tile_host.rs compiles this header with g++ under the block
// emulator (warp-cuda/cuda/tests/wp_prim_emu.h) and compares.
//
// A tile `wp::tile_t<T, D0>` .. `wp::tile_t<T, D0, D1, D2, D3>` (rank 1 to 4) is a pointer to a
// slot of shared memory holding its elements in row-major order (flattened) (the emitter hands out the slots; a tile never owns
// storage). `WP_TILE_BLOCK_DIM`, the block size, is a compile-time define.
//
// Every operation is cooperative: every thread of the block calls it, with the same arguments,
// under block-uniform control flow. It is a block-strided loop over the elements
// (`for (i = threadIdx.x; i < SIZE; i += WP_TILE_BLOCK_DIM)`) and ends in `__syncthreads()`, so
// its result is visible to every thread when it returns. An output tile may be an input of an
// elementwise operation (each element is read and written by one thread); the output of a
// matmul or a reduction is a slot of its own.
//
//   tile_zeros, tile_ones, tile_arange(out, start, step)   element i: start + T(i) * step (one
//                        multiplication, then one addition, no accumulation; integers wrap)
//   tile_load(out, a, o0[, o1..]), tile_store(a, o0[, o1..], t)   1-D to 4-D against arrays:
//                        element (i, j) is a[o0 + i, o1 + j]; signed offsets (any integer type);
//                        a coordinate outside the array (negative too) reads as T{} and its
//                        store is skipped, neither is a fault. A tile wholly inside an array
//                        with contiguous rows is moved directly (16-byte vectors where the
//                        row starts are aligned); otherwise each in-bounds access goes through
//                        the checked wp::load / wp::store (same values, same faults). Ranks
//                        3 and 4 always take the checked path.
//   tile_add, tile_sub, tile_mul(out, a, b)   tile with tile, tile with scalar, scalar with
//                        tile: the builtins' arithmetic (IEEE for floats, wrapping for integers)
//   tile_neg(out, a)     -a (wrapping for integers, a sign flip for floats)
//   tile_map(out, a, f)  f applied to each element
//   tile_sum, tile_min, tile_max(out, t)   into a 1-element tile, in the order below
//   tile_argmin, tile_argmax(out, t)   the row-major index into a 1-element i32 tile, in the
//                        order below over (value, index) pairs (both shuffled)
//   tile_matmul(c, a, b), tile_matmul_acc(c, a, b)   FMA matmul (f32, f64), see below
//   tile_view(out, t, o0[, o1]), tile_window<op>(d, s, o0[, o1])   a copy of a window of t;
//                        s written (added, ..) into d's window in place; a window outside
//                        the tile faults and moves nothing (the section "Windows" below)
//
// Reduction order (warp-core/src/tile/reduce.rs documents it; the two must stay the same). With
// S elements, BD = WP_TILE_BLOCK_DIM and ACTIVE = min(S, BD) (the lanes that own an element):
//   1. lane l < ACTIVE starts from element l and folds l + BD, l + 2 BD, .. in increasing order;
//      lanes >= ACTIVE are empty;
//   2. in each warp of 32 lanes, for offset = 16, 8, 4, 2, 1: lane i combines its partial (left)
//      with lane i + offset's (`__shfl_down_sync`), when i + offset < 32 and that lane is not
//      empty. Owners are a prefix of the lanes, so a lane whose partner is present is present
//      itself and the empties need no flag; lanes of a partial warp (BD not a multiple of 32)
//      shuffle under the mask of the lanes that exist;
//   3. lane 0 of each non-empty warp writes its result to shared memory; thread 0 folds them in
//      warp order (r = w0; r = op(r, w1); ..) and writes the 1-element output.
// Sums use the builtins' + (IEEE, wrapping for integers); min and max the builtins' (a NaN
// operand loses to a number: fminf/fmaxf). Argmin and argmax combine (value, index) pairs by a
// total order (numbers before NaN, then the value, then the smaller index; -0 and +0 tie), so
// they give the first index of the extremum for every block size; a tile of NaNs gives 0.
//
// Matmul: output c[i][j] is one chain acc = fma(a[i][k], b[k][j], acc) over k = 0..K ascending,
// starting from c[i][j] (tile_matmul_acc) or +0 (tile_matmul), with fmaf/fma: one rounding each,
// whatever the compiler's contraction setting. The outputs are cut into micro-tiles (up to
// 4 x 4, tile_detail::mm_plan) spread over the threads block-strided; each output is computed
// by one thread, in registers, so neither the block size nor the plan changes them.
//
// Host builds: include tests/wp_prim_emu.h first (it provides threadIdx, __syncthreads and
// __shfl_down_sync for fibers); otherwise this header needs CUDA.
//
// Ranks 3 and 4 have the rank-generic operations (constructors, loads, stores, elementwise,
// maps, reductions, reshapes, extract, atomic add); matmul, transpose, broadcast, views, FFTs
// and the linear algebra are rank 1-2. Not yet here (later slices):
// register tiles, scans, tensor cores. The header is not yet a kernel section (no builtin names
// it until the emitter does), so nothing but the host test includes it.
#pragma once

#include "wp_core.h"

#if !defined(WP_TILE_BLOCK_DIM)
#error "wp_tile.h: define WP_TILE_BLOCK_DIM (the block size of the tiled launch)"
#endif

// WP_TILE_SHARED_ALIGNED: a block's shared variable aligned to 16 bytes, in a device function.
#if defined(__CUDACC__)
#define WP_TILE_SHARED_ALIGNED __shared__ __align__(16)
#elif defined(WP_PRIM_EMULATOR)
// One block runs at a time in the emulator: static storage is the block's shared memory.
#define WP_TILE_SHARED_ALIGNED alignas(16) static
#else
#error "wp_tile.h on the host needs the block emulator (include tests/wp_prim_emu.h first)"
#endif

// WP_TILE_UNROLL / WP_TILE_UNROLL_N(n): `#pragma unroll` on the GPU (register blocking needs
// its small loops unrolled, so that the accumulator arrays live in registers); nothing on the
// host, where g++ -Wall would reject the unknown pragma.
#if defined(__CUDACC__)
#define WP_TILE_PRAGMA_(x) _Pragma(#x)
#define WP_TILE_UNROLL WP_TILE_PRAGMA_(unroll)
#define WP_TILE_UNROLL_N(n) WP_TILE_PRAGMA_(unroll n)
#else
#define WP_TILE_UNROLL
#define WP_TILE_UNROLL_N(n)
#endif

namespace wp {

constexpr int TILE_BLOCK_DIM = WP_TILE_BLOCK_DIM;
static_assert(TILE_BLOCK_DIM >= 1 && TILE_BLOCK_DIM <= 1024, "block size in 1..=1024");

/// A tile of shape D... (rank 1 to 4) over a slot of shared memory, row-major (flattened).
template <typename T, int... D>
struct tile_t {
  static_assert(sizeof...(D) >= 1 && sizeof...(D) <= 4, "tiles of rank 1 to 4");
  static_assert(((D > 0) && ...), "a tile has at least one element on every axis");
  static constexpr int RANK = (int)sizeof...(D);
  static constexpr int SIZE = (D * ...);
  /// The bytes of a slot.
  static constexpr usize BYTES = sizeof(T) * (usize)SIZE;
  typedef T elem_t;
  /// The elements, row-major.
  T* data;
  WP_FN explicit tile_t(void* slot) : data(static_cast<T*>(slot)) {}
};

namespace tile_detail {

/// Coordinate `o + i` of an axis of extent `n`, when it lies inside `0..n`: the exact
/// coordinate, without i64 overflow for any offset (warp-core widens to i128).
template <typename O>
WP_FN bool coord(O o, int i, i64 n, i64* c) {
  if constexpr (num<O>::is_signed) {
    const i64 s = (i64)o;
    if (s >= 0) {
      if (s >= n || (i64)i >= n - s) return false;
      *c = s + (i64)i;
      return true;
    }
    // s < 0: o + i >= 0 iff i >= -s (as u64: -i64::MIN is 2^63).
    const u64 neg = 0ull - (u64)s;
    if ((u64)i < neg) return false;
    const u64 v = (u64)i - neg;
    if (v >= (u64)n) return false;
    *c = (i64)v;
    return true;
  } else {
    const u64 u = (u64)o;
    if (n <= 0 || u >= (u64)n || (u64)i >= (u64)n - u) return false;
    *c = (i64)(u + (u64)i);
    return true;
  }
}

/// The array coordinates `c` of row-major element `e` of a rank-3 tile (N0, N1, N2) at offsets
/// (o0, o1, o2) of an array of `shape`, when every axis lies inside it (`coord` per axis).
template <int N0, int N1, int N2, typename O0, typename O1, typename O2>
WP_FN bool coords3(int e, const i64* shape, O0 o0, O1 o1, O2 o2, i64* c) {
  return coord(o0, e / (N1 * N2), shape[0], &c[0]) && coord(o1, (e / N2) % N1, shape[1], &c[1]) &&
         coord(o2, e % N2, shape[2], &c[2]);
}

/// As `coords3`, for a rank-4 tile (N0, N1, N2, N3).
template <int N0, int N1, int N2, int N3, typename O0, typename O1, typename O2, typename O3>
WP_FN bool coords4(int e, const i64* shape, O0 o0, O1 o1, O2 o2, O3 o3, i64* c) {
  return coord(o0, e / (N1 * N2 * N3), shape[0], &c[0]) &&
         coord(o1, (e / (N2 * N3)) % N1, shape[1], &c[1]) &&
         coord(o2, (e / N3) % N2, shape[2], &c[2]) && coord(o3, e % N3, shape[3], &c[3]);
}

/// The builtins' min and max (wp_scalar.h's; repeated here so that the header needs only the
/// core): IEEE fmin/fmax for floats (a NaN operand loses), `<` for integers.
WP_LFN f32 tmin(f32 a, f32 b) { return ::fminf(a, b); }
WP_LFN f32 tmax(f32 a, f32 b) { return ::fmaxf(a, b); }
WP_LFN f64 tmin(f64 a, f64 b) { return ::fmin(a, b); }
WP_LFN f64 tmax(f64 a, f64 b) { return ::fmax(a, b); }
// f16: the f32 ones on the widened values, rounded back (exact: the result is an operand),
// as warp-core's `MinMax for f16`.
WP_LFN f16 tmin(f16 a, f16 b) { return f16_from_f32(::fminf(f16_to_f32(a), f16_to_f32(b))); }
WP_LFN f16 tmax(f16 a, f16 b) { return f16_from_f32(::fmaxf(f16_to_f32(a), f16_to_f32(b))); }
WP_LFN bf16 tmin(bf16 a, bf16 b) { return bf16_from_f32(::fminf(bf16_to_f32(a), bf16_to_f32(b))); }
WP_LFN bf16 tmax(bf16 a, bf16 b) { return bf16_from_f32(::fmaxf(bf16_to_f32(a), bf16_to_f32(b))); }
template <typename T>
WP_FN T tmin(T a, T b) {
  return b < a ? b : a;
}
template <typename T>
WP_FN T tmax(T a, T b) {
  return a < b ? b : a;
}

/// The scalar that scales a tile of vectors (`vec_traits<V>::scalar`; no such type for a
/// scalar element, so the vector overloads below drop out of a scalar tile's overload set).
template <typename V>
using vec_scalar_t = typename vec_traits<V>::scalar;

struct add_op {
  template <typename T>
  WP_FN T operator()(T a, T b) const {
    return detail::s_add(a, b);
  }
  /// Tiles of 2-vectors (complex values): the vector's componentwise `+` (warp-core's glam).
  /// Plain overloads: they win over the template for vector arguments.
  WP_FN Vec2 operator()(const Vec2& a, const Vec2& b) const { return a + b; }
  WP_FN DVec2 operator()(const DVec2& a, const DVec2& b) const { return a + b; }
};
struct sub_op {
  template <typename T>
  WP_FN T operator()(T a, T b) const {
    return detail::s_sub(a, b);
  }
  WP_FN Vec2 operator()(const Vec2& a, const Vec2& b) const { return a - b; }
  WP_FN DVec2 operator()(const DVec2& a, const DVec2& b) const { return a - b; }
};
struct mul_op {
  template <typename T>
  WP_FN T operator()(T a, T b) const {
    return detail::s_mul(a, b);
  }
  /// A vector scaled by its scalar, on either side (each component one multiply).
  WP_FN Vec2 operator()(const Vec2& a, f32 s) const { return a * s; }
  WP_FN Vec2 operator()(f32 s, const Vec2& a) const { return s * a; }
  WP_FN DVec2 operator()(const DVec2& a, f64 s) const { return a * s; }
  WP_FN DVec2 operator()(f64 s, const DVec2& a) const { return s * a; }
};
/// Float division only (integer tiles have no `/` yet): IEEE, as warp-core's.
struct div_op {
  template <typename T>
  WP_FN T operator()(T a, T b) const {
    return a / b;
  }
};
struct min_op {
  template <typename T>
  WP_FN T operator()(T a, T b) const {
    return tmin(a, b);
  }
};
struct max_op {
  template <typename T>
  WP_FN T operator()(T a, T b) const {
    return tmax(a, b);
  }
};

/// `-v`: the builtins' wrapping negation for integers, IEEE negation (the sign bit) for floats.
WP_LFN f32 neg(f32 v) { return -v; }
WP_LFN f64 neg(f64 v) { return -v; }
WP_LFN f16 neg(f16 v) { return -v; }
WP_LFN bf16 neg(bf16 v) { return -v; }
template <typename T>
WP_FN T neg(T v) {
  return w_neg(v);
}

/// `__shfl_down_sync` for the element types: the 32- and 64-bit types CUDA overloads, and the
/// narrower integers through 32 bits.
WP_LFN f32 shfl_down(unsigned mask, f32 v, int off) { return __shfl_down_sync(mask, v, off); }
WP_LFN f64 shfl_down(unsigned mask, f64 v, int off) { return __shfl_down_sync(mask, v, off); }
WP_LFN i32 shfl_down(unsigned mask, i32 v, int off) { return __shfl_down_sync(mask, v, off); }
WP_LFN u32 shfl_down(unsigned mask, u32 v, int off) { return __shfl_down_sync(mask, v, off); }
WP_LFN i64 shfl_down(unsigned mask, i64 v, int off) { return __shfl_down_sync(mask, v, off); }
WP_LFN u64 shfl_down(unsigned mask, u64 v, int off) { return __shfl_down_sync(mask, v, off); }
WP_LFN i8 shfl_down(unsigned mask, i8 v, int off) { return (i8)__shfl_down_sync(mask, (i32)v, off); }
WP_LFN i16 shfl_down(unsigned mask, i16 v, int off) { return (i16)__shfl_down_sync(mask, (i32)v, off); }
WP_LFN u8 shfl_down(unsigned mask, u8 v, int off) { return (u8)__shfl_down_sync(mask, (u32)v, off); }
WP_LFN u16 shfl_down(unsigned mask, u16 v, int off) { return (u16)__shfl_down_sync(mask, (u32)v, off); }
WP_LFN f16 shfl_down(unsigned mask, f16 v, int off) {
  return f16_from_bits((u16)__shfl_down_sync(mask, (u32)v.bits, off));
}
WP_LFN bf16 shfl_down(unsigned mask, bf16 v, int off) {
  return bf16_from_bits((u16)__shfl_down_sync(mask, (u32)v.bits, off));
}

/// The elements `elem(0..S)` (partials of type P) reduced with `op` in the order of the header
/// comment; thread 0 passes the result to `put`. Every thread of the block calls it.
template <typename P, int S, typename Elem, typename Op, typename Put>
WP_FN void reduce_with(Elem elem, Op op, Put put) {
  constexpr int BD = TILE_BLOCK_DIM;
  constexpr int ACTIVE = S < BD ? S : BD;
  constexpr int WARPS = (ACTIVE + 31) / 32;
  // The warps' results, in warp order.
  WP_TILE_SHARED_ALIGNED unsigned char warp_bytes[32 * sizeof(P)];
  P* warp_part = reinterpret_cast<P*>(warp_bytes);
  const int l = (int)threadIdx.x;
  // 1. The lane's partial (P{} and unused when the lane is empty).
  P p{};
  if (l < ACTIVE) {
    p = elem(l);
    for (int e = l + BD; e < S; e += BD) p = op(p, elem(e));
  }
  // 2. The warp's tree. Every thread of the block takes part (the mask names the lanes of its
  // warp that exist); a lane combines only with a present partner.
  const int lane = l & 31;
  const int base = l - lane;
  const int exist = BD - base < 32 ? BD - base : 32;
  const unsigned mask = exist == 32 ? 0xffffffffu : ((1u << exist) - 1u);
  for (int off = 16; off > 0; off >>= 1) {
    const P q = shfl_down(mask, p, off);
    if (lane + off < 32 && base + lane + off < ACTIVE) p = op(p, q);
  }
  if (lane == 0 && base < ACTIVE) warp_part[base / 32] = p;
  __syncthreads();
  // 3. Thread 0 folds the warps in order.
  if (l == 0) {
    P r = warp_part[0];
    for (int w = 1; w < WARPS; ++w) r = op(r, warp_part[w]);
    put(r);
  }
  __syncthreads();
}

/// `t`'s elements reduced with `op` in the order of the header comment, into `out.data[0]`.
template <typename T, int... D, typename Op>
WP_FN void reduce(const tile_t<T, 1>& out, const tile_t<T, D...>& t, Op op) {
  const T* x = t.data;
  reduce_with<T, tile_t<T, D...>::SIZE>([x](int e) { return x[e]; }, op,
                                        [&out](T r) { out.data[0] = r; });
}

/// A `(value, index)` partial of `tile_argmin` / `tile_argmax`.
template <typename T>
struct arg_t {
  T v;
  i32 i;
};

/// Both fields shuffled (the value as `shfl_down` of its type, the index as i32).
template <typename T>
WP_FN arg_t<T> shfl_down(unsigned mask, const arg_t<T>& a, int off) {
  arg_t<T> r;
  r.v = shfl_down(mask, a.v, off);
  r.i = shfl_down(mask, a.i, off);
  return r;
}

/// NaN (a value unordered with itself); never for integers.
WP_LFN bool tnan(f32 v) { return v != v; }
WP_LFN bool tnan(f64 v) { return v != v; }
WP_LFN bool tnan(f16 v) { return v != v; }
WP_LFN bool tnan(bf16 v) { return v != v; }
template <typename T>
WP_FN bool tnan(T) {
  return false;
}

/// The pair that comes first in argmin's (`Max` false) or argmax's (`Max` true) total order:
/// numbers before NaN, then the smaller (larger) value, then the smaller index. `-0` and `+0`
/// are equal values (the index decides). warp-core's `pick` in tile/reduce.rs.
template <bool Max>
struct arg_op {
  template <typename T>
  WP_FN arg_t<T> operator()(const arg_t<T>& a, const arg_t<T>& b) const {
    const bool an = tnan(a.v), bn = tnan(b.v);
    bool b_first;
    if (an != bn) b_first = an;
    else if (an || a.v == b.v) b_first = b.i < a.i;
    else b_first = Max ? b.v > a.v : b.v < a.v;
    return b_first ? b : a;
  }
};

/// The row-major index of `t`'s extremum in `Op`'s order, into `out.data[0]`.
template <typename Op, typename T, int... D>
WP_FN void arg_reduce(const tile_t<i32, 1>& out, const tile_t<T, D...>& t) {
  const T* x = t.data;
  reduce_with<arg_t<T>, tile_t<T, D...>::SIZE>(
      [x](int e) {
        arg_t<T> a;
        a.v = x[e];
        a.i = (i32)e;
        return a;
      },
      Op{}, [&out](const arg_t<T>& r) { out.data[0] = r.i; });
}

}  // namespace tile_detail

// ------------------------------------------------------------------------------------------
// Constructors
// ------------------------------------------------------------------------------------------

/// Every element `v`.
template <typename T, int... D>
WP_FN void tile_fill(const tile_t<T, D...>& out, T v) {
  for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM) out.data[i] = v;
  __syncthreads();
}

/// `tile_zeros`: `T{}`, zero for scalars and the zero vector for `Vec2`/`DVec2`.
template <typename T, int... D>
WP_FN void tile_zeros(const tile_t<T, D...>& out) {
  tile_fill(out, T{});
}

/// `tile_ones`.
template <typename T, int... D>
WP_FN void tile_ones(const tile_t<T, D...>& out) {
  tile_fill(out, (T)1);
}

/// `tile_arange`: element i is `start + T(i) * step` (warp-core's `Tile1::arange`).
template <typename T, int N0>
WP_FN void tile_arange(const tile_t<T, N0>& out, T start, T step) {
  for (int i = (int)threadIdx.x; i < N0; i += WP_TILE_BLOCK_DIM)
    out.data[i] = detail::s_add(start, detail::s_mul(cast<T>((i64)i), step));
  __syncthreads();
}

// ------------------------------------------------------------------------------------------
// Loads and stores
// ------------------------------------------------------------------------------------------

namespace tile_detail {

/// 16-byte alignment of a shared or global address (the vector paths' precondition).
WP_LFN bool aligned16(const void* p) { return ((usize)p & 15) == 0; }

/// 16 raw bytes, copied as one access (LDG.128 / STG.128 / LDS.128 / STS.128): the loads'
/// and stores' vector path moves bits, whatever the element type.
#if defined(__CUDACC__)
typedef uint4 raw16;
#else
struct alignas(16) raw16 {
  u32 w[4];
};
#endif

/// The fast path's plan for one axis-`N` tile access at coordinates `o` (every offset a
/// coordinate of the tile's first element): true, with the first element's coordinates in
/// `c0` (and `c1`), when the whole tile lies inside the array, so that no element needs its
/// own check. `coord` of the first and of the last element proves it (the axis is an
/// interval); every thread computes the same answer (block-uniform).
template <typename O>
WP_FN bool inside(O o, int n, i64 extent, i64* c) {
  i64 last;
  return coord(o, 0, extent, c) && coord(o, n - 1, extent, &last);
}

/// The innermost stride is the element size (rows are contiguous runs of elements), and the
/// byte stride between rows. With WP_CONTIGUOUS the launch checked every array argument is
/// contiguous and row-major, so both follow from the shape (as in wp_core.h's element
/// addressing).
template <typename T, int N>
WP_FN bool inner_contiguous(const array_t<T, N>& a) {
#if defined(WP_CONTIGUOUS)
  (void)a;
  return true;
#else
  return a.strides[N - 1] == (i64)sizeof(T);
#endif
}
template <typename T>
WP_FN i64 row_stride(const array_t<T, 2>& a) {
#if defined(WP_CONTIGUOUS)
  return a.shape[1] * (i64)sizeof(T);
#else
  return a.strides[0];
#endif
}

/// Copies `n` elements from `src` to `dst` cooperatively (one row of a 1-D tile), as 16-byte
/// vectors when both are 16-byte aligned, then the tail element by element.
template <typename T, int n>
WP_FN void copy_run(T* __restrict__ dst, const T* __restrict__ src) {
  constexpr int W = 16 / (int)sizeof(T);
  constexpr int CH = (16 % sizeof(T) == 0) ? n / W : 0;
  int start = 0;
  if (CH > 0 && aligned16(src) && aligned16(dst)) {
    const raw16* s = reinterpret_cast<const raw16*>(src);
    raw16* d = reinterpret_cast<raw16*>(dst);
    for (int q = (int)threadIdx.x; q < CH; q += WP_TILE_BLOCK_DIM) d[q] = s[q];
    start = CH * W;
  }
  for (int i = start + (int)threadIdx.x; i < n; i += WP_TILE_BLOCK_DIM) dst[i] = src[i];
}

/// Copies a tile's N0 rows of N1 elements between a shared slot (rows N1 apart) and an
/// array's rows (`rs` bytes apart from `base`), cooperatively; `ToArray` picks the
/// direction. 16-byte vectors when every row start on both sides is 16-byte aligned (the
/// bases, the row stride and the row's bytes all multiples of 16), one block-uniform test;
/// else element by element.
template <bool ToArray, typename T, int N0, int N1>
WP_FN void copy_rows(T* slot, char* base, i64 rs) {
  constexpr int W = 16 / (int)sizeof(T);
  constexpr bool CAN = 16 % sizeof(T) == 0 && (N1 * (int)sizeof(T)) % 16 == 0;
  if (CAN && aligned16(slot) && aligned16(base) && (rs & 15) == 0) {
    constexpr int CH = CAN ? N1 / W : 1;  // vectors per row
    for (int e = (int)threadIdx.x; e < N0 * CH; e += WP_TILE_BLOCK_DIM) {
      const int i = e / CH, q = e % CH;
      raw16* arr = reinterpret_cast<raw16*>(base + (i64)i * rs) + q;
      raw16* sh = reinterpret_cast<raw16*>(slot + i * N1) + q;
      if (ToArray) *arr = *sh;
      else *sh = *arr;
    }
  } else {
    for (int e = (int)threadIdx.x; e < N0 * N1; e += WP_TILE_BLOCK_DIM) {
      const int i = e / N1, j = e % N1;
      T* arr = reinterpret_cast<T*>(base + (i64)i * rs) + j;
      if (ToArray) *arr = slot[e];
      else slot[e] = *arr;
    }
  }
}

}  // namespace tile_detail

// The fast paths below: when the whole tile lies inside the array (one block-uniform check of
// its first and last coordinates per axis) and the array's rows are contiguous, the elements
// are read and written through the array's base pointer and strides, without a check each.
// This is the same behaviour, not a weaker one: wp::load / wp::store check an index only
// against the shape, and the tile-wide check already proves every index of the tile inside
// it, so none of those checks could fail (a corrupt array, a bad pointer under a valid shape,
// faults neither way). Row starts aligned to 16 bytes, on both sides, move as 16-byte vectors
// (the benchmark's 64 x 16, 16 x 64 and 64 x 64 f32 tiles of 4096 x 4096 arrays: one
// LDG.128 or STG.128 per 4 elements instead of a checked 4-byte access each).

/// `tile_load(a, o)`: element i is `a[o + i]`, or T{} where that is outside the array.
template <typename T, int N0, typename O>
WP_FN void tile_load(const tile_t<T, N0>& out, const array_t<T, 1>& a, O o, ctx_t* ctx) {
  i64 c;
  if (tile_detail::inside(o, N0, a.shape[0], &c) && tile_detail::inner_contiguous(a)) {
    const T* src = reinterpret_cast<const T*>(reinterpret_cast<const char*>(a.data) +
                                              c * a.strides[0]);
#if defined(WP_CONTIGUOUS)
    src = a.data + c;
#endif
    tile_detail::copy_run<T, N0>(out.data, src);
  } else {
    for (int i = (int)threadIdx.x; i < N0; i += WP_TILE_BLOCK_DIM) {
      out.data[i] = tile_detail::coord(o, i, a.shape[0], &c) ? load(a, c, ctx) : T{};
    }
  }
  __syncthreads();
}

/// `tile_load(a, (o0, o1))`: element (i, j) is `a[o0 + i, o1 + j]`, or T{} outside the array.
template <typename T, int N0, int N1, typename O0, typename O1>
WP_FN void tile_load(const tile_t<T, N0, N1>& out, const array_t<T, 2>& a, O0 o0, O1 o1,
                     ctx_t* ctx) {
  i64 s0, s1;
  if (tile_detail::inside(o0, N0, a.shape[0], &s0) &&
      tile_detail::inside(o1, N1, a.shape[1], &s1) && tile_detail::inner_contiguous(a)) {
    const i64 rs = tile_detail::row_stride(a);
    char* base = reinterpret_cast<char*>(a.data) + s0 * rs + s1 * (i64)sizeof(T);
    tile_detail::copy_rows<false, T, N0, N1>(out.data, base, rs);
  } else {
    for (int e = (int)threadIdx.x; e < N0 * N1; e += WP_TILE_BLOCK_DIM) {
      const int i = e / N1, j = e % N1;
      i64 c0, c1;
      const bool in = tile_detail::coord(o0, i, a.shape[0], &c0) &&
                      tile_detail::coord(o1, j, a.shape[1], &c1);
      out.data[e] = in ? load(a, c0, c1, ctx) : T{};
    }
  }
  __syncthreads();
}

/// `tile_store(a, o, t)`: `a[o + i] = t[i]` where `o + i` is inside the array; the rest is
/// skipped.
template <typename T, int N0, typename O>
WP_FN void tile_store(const array_t<T, 1>& a, O o, const tile_t<T, N0>& t, ctx_t* ctx) {
  i64 c;
  if (tile_detail::inside(o, N0, a.shape[0], &c) && tile_detail::inner_contiguous(a)) {
    T* dst = reinterpret_cast<T*>(reinterpret_cast<char*>(a.data) + c * a.strides[0]);
#if defined(WP_CONTIGUOUS)
    dst = a.data + c;
#endif
    tile_detail::copy_run<T, N0>(dst, t.data);
  } else {
    for (int i = (int)threadIdx.x; i < N0; i += WP_TILE_BLOCK_DIM) {
      if (tile_detail::coord(o, i, a.shape[0], &c)) store(a, c, t.data[i], ctx);
    }
  }
  __syncthreads();
}

/// `tile_store(a, (o0, o1), t)`: `a[o0 + i, o1 + j] = t[i, j]` inside the array; the rest is
/// skipped.
template <typename T, int N0, int N1, typename O0, typename O1>
WP_FN void tile_store(const array_t<T, 2>& a, O0 o0, O1 o1, const tile_t<T, N0, N1>& t,
                      ctx_t* ctx) {
  i64 s0, s1;
  if (tile_detail::inside(o0, N0, a.shape[0], &s0) &&
      tile_detail::inside(o1, N1, a.shape[1], &s1) && tile_detail::inner_contiguous(a)) {
    const i64 rs = tile_detail::row_stride(a);
    char* base = reinterpret_cast<char*>(a.data) + s0 * rs + s1 * (i64)sizeof(T);
    tile_detail::copy_rows<true, T, N0, N1>(t.data, base, rs);
  } else {
    for (int e = (int)threadIdx.x; e < N0 * N1; e += WP_TILE_BLOCK_DIM) {
      const int i = e / N1, j = e % N1;
      i64 c0, c1;
      if (tile_detail::coord(o0, i, a.shape[0], &c0) &&
          tile_detail::coord(o1, j, a.shape[1], &c1))
        store(a, c0, c1, t.data[e], ctx);
    }
  }
  __syncthreads();
}

// Ranks 3 and 4: every element through the checked wp::load / wp::store (no fast path: these
// are the uncommon shapes; the result is the same either way), block-strided over the
// row-major flattening.

/// `tile_load(a, (o0, o1, o2))`: element (i, j, k) is `a[o0 + i, o1 + j, o2 + k]`, or T{}
/// outside the array.
template <typename T, int N0, int N1, int N2, typename O0, typename O1, typename O2>
WP_FN void tile_load(const tile_t<T, N0, N1, N2>& out, const array_t<T, 3>& a, O0 o0, O1 o1,
                     O2 o2, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2; e += WP_TILE_BLOCK_DIM) {
    i64 c[3];
    const bool in = tile_detail::coords3<N0, N1, N2>(e, a.shape, o0, o1, o2, c);
    out.data[e] = in ? load(a, c[0], c[1], c[2], ctx) : T{};
  }
  __syncthreads();
}

/// `tile_load(a, (o0, o1, o2, o3))`, as the rank-3 one.
template <typename T, int N0, int N1, int N2, int N3, typename O0, typename O1, typename O2,
          typename O3>
WP_FN void tile_load(const tile_t<T, N0, N1, N2, N3>& out, const array_t<T, 4>& a, O0 o0, O1 o1,
                     O2 o2, O3 o3, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2 * N3; e += WP_TILE_BLOCK_DIM) {
    i64 c[4];
    const bool in = tile_detail::coords4<N0, N1, N2, N3>(e, a.shape, o0, o1, o2, o3, c);
    out.data[e] = in ? load(a, c[0], c[1], c[2], c[3], ctx) : T{};
  }
  __syncthreads();
}

/// `tile_store(a, (o0, o1, o2), t)`: `a[o0 + i, o1 + j, o2 + k] = t[i, j, k]` inside the
/// array; the rest is skipped.
template <typename T, int N0, int N1, int N2, typename O0, typename O1, typename O2>
WP_FN void tile_store(const array_t<T, 3>& a, O0 o0, O1 o1, O2 o2, const tile_t<T, N0, N1, N2>& t,
                      ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2; e += WP_TILE_BLOCK_DIM) {
    i64 c[3];
    if (tile_detail::coords3<N0, N1, N2>(e, a.shape, o0, o1, o2, c))
      store(a, c[0], c[1], c[2], t.data[e], ctx);
  }
  __syncthreads();
}

/// `tile_store(a, (o0, o1, o2, o3), t)`, as the rank-3 one.
template <typename T, int N0, int N1, int N2, int N3, typename O0, typename O1, typename O2,
          typename O3>
WP_FN void tile_store(const array_t<T, 4>& a, O0 o0, O1 o1, O2 o2, O3 o3,
                      const tile_t<T, N0, N1, N2, N3>& t, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2 * N3; e += WP_TILE_BLOCK_DIM) {
    i64 c[4];
    if (tile_detail::coords4<N0, N1, N2, N3>(e, a.shape, o0, o1, o2, o3, c))
      store(a, c[0], c[1], c[2], c[3], t.data[e], ctx);
  }
  __syncthreads();
}

// ------------------------------------------------------------------------------------------
// Elementwise
// ------------------------------------------------------------------------------------------

/// `tile_neg(out, a)` (`-a`): `out[i] = -a[i]`, wrapping for integers (`MIN` stays `MIN`,
/// unsigned `0 - a`), the sign bit flipped for floats (warp-core's `Scalar::s_neg`).
template <typename T, int... D>
WP_FN void tile_neg(const tile_t<T, D...>& out, const tile_t<T, D...>& a) {
  for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)
    out.data[i] = tile_detail::neg(a.data[i]);
  __syncthreads();
}

/// `tile_map(f, a)`: `out[i] = f(a[i])`.
template <typename T, typename U, int... D, typename F>
WP_FN void tile_map(const tile_t<U, D...>& out, const tile_t<T, D...>& a, F f) {
  for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)
    out.data[i] = f(a.data[i]);
  __syncthreads();
}

#define WP_TILE_BINARY(NAME, OP)                                                              \
  /* tile with tile */                                                                        \
  template <typename T, int... D>                                                             \
  WP_FN void NAME(const tile_t<T, D...>& out, const tile_t<T, D...>& a,                       \
                  const tile_t<T, D...>& b) {                                                 \
    for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)         \
      out.data[i] = OP{}(a.data[i], b.data[i]);                                               \
    __syncthreads();                                                                          \
  }                                                                                           \
  /* tile with scalar */                                                                      \
  template <typename T, int... D>                                                             \
  WP_FN void NAME(const tile_t<T, D...>& out, const tile_t<T, D...>& a,                       \
                  typename identity<T>::type s) {                                             \
    for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)         \
      out.data[i] = OP{}(a.data[i], s);                                                       \
    __syncthreads();                                                                          \
  }                                                                                           \
  /* scalar with tile */                                                                      \
  template <typename T, int... D>                                                             \
  WP_FN void NAME(const tile_t<T, D...>& out, typename identity<T>::type s,                   \
                  const tile_t<T, D...>& b) {                                                 \
    for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)         \
      out.data[i] = OP{}(s, b.data[i]);                                                       \
    __syncthreads();                                                                          \
  }                                                                                           \
  /* tile of vectors with their scalar, either side (only `*` is emitted for these) */        \
  template <typename T, int... D>                                                             \
  WP_FN void NAME(const tile_t<T, D...>& out, const tile_t<T, D...>& a,                       \
                  tile_detail::vec_scalar_t<T> s) {                                           \
    for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)         \
      out.data[i] = OP{}(a.data[i], s);                                                       \
    __syncthreads();                                                                          \
  }                                                                                           \
  template <typename T, int... D>                                                             \
  WP_FN void NAME(const tile_t<T, D...>& out, tile_detail::vec_scalar_t<T> s,                 \
                  const tile_t<T, D...>& b) {                                                 \
    for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)         \
      out.data[i] = OP{}(s, b.data[i]);                                                       \
    __syncthreads();                                                                          \
  }
WP_TILE_BINARY(tile_add, tile_detail::add_op)
WP_TILE_BINARY(tile_sub, tile_detail::sub_op)
WP_TILE_BINARY(tile_mul, tile_detail::mul_op)
WP_TILE_BINARY(tile_div, tile_detail::div_op)
#undef WP_TILE_BINARY

/// `tile_map(f, a, b)`: `out[i] = f(a[i], b[i])`.
template <typename T, typename U, typename V, int... D, typename F>
WP_FN void tile_map2(const tile_t<V, D...>& out, const tile_t<T, D...>& a,
                     const tile_t<U, D...>& b, F f) {
  for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)
    out.data[i] = f(a.data[i], b.data[i]);
  __syncthreads();
}

/// `let b = a;` of tiles: a copy into `b`'s slot.
template <typename T, int... D>
WP_FN void tile_copy(const tile_t<T, D...>& out, const tile_t<T, D...>& a) {
  for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)
    out.data[i] = a.data[i];
  __syncthreads();
}

// ------------------------------------------------------------------------------------------
// Threads and tiles
// ------------------------------------------------------------------------------------------

/// `tile(x)`: element `threadIdx.x` is this thread's `x`. The tile is as wide as the block
/// (the launch checks the kernel's `block_dim` against its width).
template <typename T, int N0>
WP_FN void tile(const tile_t<T, N0>& out, T x) {
  static_assert(N0 == WP_TILE_BLOCK_DIM, "tile(x) makes a tile as wide as the block");
  out.data[threadIdx.x] = x;
  __syncthreads();
}

/// `untile(t)`: this thread's element of a tile as wide as the block.
template <typename T, int N0>
WP_FN T untile(const tile_t<T, N0>& t) {
  static_assert(N0 == WP_TILE_BLOCK_DIM, "untile takes a tile as wide as the block");
  return t.data[threadIdx.x];
}

/// The fault of an index outside a tile (warp_core::FaultKind::TileIndex): the index and the
/// shape, `RANK` entries.
template <typename T, int... D>
WP_FN void tile_index_fault(ctx_t* ctx, const i64* idx) {
  const i64 shape[4] = {(i64)D...};
  raise(ctx, FAULT_TILE_INDEX, -1, (i32)sizeof...(D), idx, shape);
}

/// `t[i]`: a read by one thread; outside the tile, a fault and zero.
template <typename T, int N0, typename I>
WP_FN T tile_extract(const tile_t<T, N0>& t, I i, ctx_t* ctx) {
  const i64 c = (i64)i;
  if (!(num<I>::is_signed && c < 0) && (u64)i < (u64)N0) return t.data[c];
  const u64 big = 0x7fffffffffffffffull;
  const i64 idx[1] = {num<I>::is_signed ? c : ((u64)i > big ? (i64)big : (i64)i)};
  tile_index_fault<T, N0>(ctx, idx);
  return T{};
}

/// `t[i, j]`.
template <typename T, int N0, int N1, typename I, typename J>
WP_FN T tile_extract(const tile_t<T, N0, N1>& t, I i, J j, ctx_t* ctx) {
  const bool in0 = !(num<I>::is_signed && (i64)i < 0) && (u64)i < (u64)N0;
  const bool in1 = !(num<J>::is_signed && (i64)j < 0) && (u64)j < (u64)N1;
  if (in0 && in1) return t.data[(i64)i * N1 + (i64)j];
  const i64 idx[2] = {(i64)i, (i64)j};
  tile_index_fault<T, N0, N1>(ctx, idx);
  return T{};
}

namespace tile_detail {
/// Index `i` inside `0..n` (negative values and unsigned values past i64 are outside).
template <typename I>
WP_FN bool index_in(I i, int n) {
  return !(num<I>::is_signed && (i64)i < 0) && (u64)i < (u64)n;
}
}  // namespace tile_detail

/// `t[i, j, k]`.
template <typename T, int N0, int N1, int N2, typename I, typename J, typename K>
WP_FN T tile_extract(const tile_t<T, N0, N1, N2>& t, I i, J j, K k, ctx_t* ctx) {
  if (tile_detail::index_in(i, N0) && tile_detail::index_in(j, N1) && tile_detail::index_in(k, N2))
    return t.data[((i64)i * N1 + (i64)j) * N2 + (i64)k];
  const i64 idx[3] = {(i64)i, (i64)j, (i64)k};
  tile_index_fault<T, N0, N1, N2>(ctx, idx);
  return T{};
}

/// `t[i, j, k, l]`.
template <typename T, int N0, int N1, int N2, int N3, typename I, typename J, typename K,
          typename L>
WP_FN T tile_extract(const tile_t<T, N0, N1, N2, N3>& t, I i, J j, K k, L l, ctx_t* ctx) {
  if (tile_detail::index_in(i, N0) && tile_detail::index_in(j, N1) &&
      tile_detail::index_in(k, N2) && tile_detail::index_in(l, N3))
    return t.data[(((i64)i * N1 + (i64)j) * N2 + (i64)k) * N3 + (i64)l];
  const i64 idx[4] = {(i64)i, (i64)j, (i64)k, (i64)l};
  tile_index_fault<T, N0, N1, N2, N3>(ctx, idx);
  return T{};
}

/// The end of a tile's slot at `offset` holding `bytes`, rounded up to 16 bytes (the next
/// slot's offset). warp-macros' TileInfo computes the block's total with the same rule.
WP_LFN constexpr usize tile_slot_end(usize offset, usize bytes) {
  return (offset + bytes + 15) / 16 * 16;
}

// ------------------------------------------------------------------------------------------
// Reductions
// ------------------------------------------------------------------------------------------

/// `tile_sum`.
template <typename T, int... D>
WP_FN void tile_sum(const tile_t<T, 1>& out, const tile_t<T, D...>& t) {
  tile_detail::reduce(out, t, tile_detail::add_op{});
}

/// `tile_min`.
template <typename T, int... D>
WP_FN void tile_min(const tile_t<T, 1>& out, const tile_t<T, D...>& t) {
  tile_detail::reduce(out, t, tile_detail::min_op{});
}

/// `tile_max`.
template <typename T, int... D>
WP_FN void tile_max(const tile_t<T, 1>& out, const tile_t<T, D...>& t) {
  tile_detail::reduce(out, t, tile_detail::max_op{});
}

/// `tile_argmin`: the row-major index of the smallest element (numbers before NaN: a NaN only
/// when every element is one, index 0 then), the first on ties (`-0` ties with `+0`).
template <typename T, int... D>
WP_FN void tile_argmin(const tile_t<i32, 1>& out, const tile_t<T, D...>& t) {
  tile_detail::arg_reduce<tile_detail::arg_op<false>>(out, t);
}

/// `tile_argmax`: the row-major index of the largest element, as `tile_argmin` otherwise.
template <typename T, int... D>
WP_FN void tile_argmax(const tile_t<i32, 1>& out, const tile_t<T, D...>& t) {
  tile_detail::arg_reduce<tile_detail::arg_op<true>>(out, t);
}

/// `tile_reduce(op, t)` with a user's combining function `op(earlier, later)`.
template <typename T, int... D, typename Op>
WP_FN void tile_reduce(const tile_t<T, 1>& out, const tile_t<T, D...>& t, Op op) {
  tile_detail::reduce(out, t, op);
}

// ------------------------------------------------------------------------------------------
// Matmul (FMA)
// ------------------------------------------------------------------------------------------

namespace tile_detail {
WP_LFN f32 fma_(f32 a, f32 b, f32 c) { return ::fmaf(a, b, c); }
WP_LFN f64 fma_(f64 a, f64 b, f64 c) { return ::fma(a, b, c); }

/// 16 bytes of floats read or written as one access (LDS.128 / STS.128 on the GPU): `W`
/// elements of `T`, `p` 16-byte aligned (the callers check it). On the host, a plain copy.
template <typename T>
struct vec16;
template <>
struct vec16<f32> {
  static constexpr int W = 4;
  WP_FN static void get(const f32* p, f32* v) {
#if defined(__CUDACC__)
    const float4 q = *reinterpret_cast<const float4*>(p);
    v[0] = q.x, v[1] = q.y, v[2] = q.z, v[3] = q.w;
#else
    for (int k = 0; k < 4; ++k) v[k] = p[k];
#endif
  }
  WP_FN static void put(f32* p, const f32* v) {
#if defined(__CUDACC__)
    *reinterpret_cast<float4*>(p) = make_float4(v[0], v[1], v[2], v[3]);
#else
    for (int k = 0; k < 4; ++k) p[k] = v[k];
#endif
  }
};
template <>
struct vec16<f64> {
  static constexpr int W = 2;
  WP_FN static void get(const f64* p, f64* v) {
#if defined(__CUDACC__)
    const double2 q = *reinterpret_cast<const double2*>(p);
    v[0] = q.x, v[1] = q.y;
#else
    v[0] = p[0], v[1] = p[1];
#endif
  }
  WP_FN static void put(f64* p, const f64* v) {
#if defined(__CUDACC__)
    *reinterpret_cast<double2*>(p) = make_double2(v[0], v[1]);
#else
    p[0] = v[0], p[1] = v[1];
#endif
  }
};

/// How a matmul spreads its M x N outputs over the block (register blocking).
///
/// The outputs are cut into micro-tiles of TM rows x TN columns; micro-tile u (of
/// RU = M / TM rows and CU = N / TN columns of micro-tiles) is owned by thread u % BD, which
/// keeps its TM x TN accumulators in registers and, per k, reads TM values of A and TN of B
/// from shared memory once and does TM * TN FMAs with them: (TM + TN) loads for TM * TN FMAs
/// instead of 2 per FMA. For the benchmark's 64 x 64 tile and 256 threads that is 4 x 4, one
/// micro-tile per thread: 16 accumulators, 8 shared loads (2 as 16-byte vectors) per 16 FMAs.
///
/// The plan is the largest micro-tile, at most 4 x 4 (16 accumulators: 32 registers for f64,
/// so the block keeps its occupancy), whose sides divide M and N and that still gives every
/// thread of the block a micro-tile; when none does (tiles smaller than the block), 1 x 1,
/// which is the plain block-strided loop over outputs. Larger blocks get smaller micro-tiles
/// (64 x 64 with 1024 threads: 2 x 2), smaller blocks loop over several (45 threads: 4 x 4,
/// 6 rounds).
///
/// Whatever the plan, each output is still one chain acc = fma(a[i][k], b[k][j], acc) over k
/// ascending from its start value, computed by one thread: the plan changes who computes it
/// and when, never the arithmetic, so every plan gives the bits of warp-core's matmul.
template <typename T, int M, int K, int N>
struct mm_plan {
  static constexpr int BD = TILE_BLOCK_DIM;
  /// Micro-tile sides in order of preference: square first (fewest loads per FMA). Host and
  /// device (it only runs at compile time, in the constants below).
#if defined(__CUDACC__)
  __host__ __device__
#endif
  static constexpr int pick(int which) {
    constexpr int cand[9][2] = {{4, 4}, {4, 2}, {2, 4}, {2, 2}, {4, 1},
                                {1, 4}, {2, 1}, {1, 2}, {1, 1}};
    for (int c = 0; c < 9; ++c) {
      const int tm = cand[c][0], tn = cand[c][1];
      if (M % tm == 0 && N % tn == 0 && (M / tm) * (N / tn) >= BD) return cand[c][which];
    }
    return 1;
  }
  static constexpr int TM = pick(0);
  static constexpr int TN = pick(1);
  static constexpr int RU = M / TM;
  static constexpr int CU = N / TN;
  static constexpr int W = vec16<T>::W;
  /// A's rows read as 16-byte vectors along k (W values of k per access, then W k-steps
  /// from registers): needs every row start 16-byte aligned (K * sizeof(T) a multiple of 16,
  /// the slot's start checked at run time) and k-steps of W.
  static constexpr bool VA = TM > 1 && (K * (int)sizeof(T)) % 16 == 0;
  /// A thread's TN columns contiguous and read (and C written) as 16-byte vectors: needs TN
  /// a multiple of W and row starts aligned (N * sizeof(T) a multiple of 16). Otherwise its
  /// columns are strided by CU (j = uc + CU * q), so that the warp's lanes, which differ in
  /// uc, read consecutive words of B's row: distinct banks, no conflict.
  static constexpr bool VB = TN % W == 0 && (N * (int)sizeof(T)) % 16 == 0;
  /// Blocking at all (1 x 1 is the plain loop).
  static constexpr bool BLOCKED = TM * TN > 1;
};

/// The plain loop: one output per thread at a time, block-strided (tiles smaller than the
/// block, shapes no micro-tile divides, and slots that are not 16-byte aligned).
template <bool Acc, typename T, int M, int K, int N>
WP_FN void matmul_simple(T* c, const T* a, const T* b) {
  for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, j = e % N;
    T acc = Acc ? c[e] : (T)0;
    for (int k = 0; k < K; ++k) acc = fma_(a[i * K + k], b[k * N + j], acc);
    c[e] = acc;
  }
}

/// The register-blocked matmul of `mm_plan` (its `VA` and `VB` only when the slots are
/// 16-byte aligned: `Vec` false turns both off).
///
/// Rows: micro-tile row ur owns rows ur + RU * r (strided, not contiguous). A warp's lanes
/// span few micro-tile rows (2 for 64 x 64, 4 x 4, 256 threads: 16 lanes per row of
/// micro-tiles), and consecutive ur then read A rows K elements apart (64 bytes for K = 16 f32),
/// in different banks; contiguous rows would put them TM * K elements apart, in the same
/// banks (a 2-way conflict on every A read). The lanes of one ur read the same A address
/// (a broadcast).
template <bool Acc, bool Vec, typename T, int M, int K, int N>
WP_FN void matmul_blocked(T* __restrict__ c, const T* __restrict__ a, const T* __restrict__ b) {
  typedef mm_plan<T, M, K, N> P;
  constexpr int TM = P::TM, TN = P::TN, RU = P::RU, CU = P::CU, W = P::W;
  constexpr bool VA = Vec && P::VA, VB = Vec && P::VB;
  for (int u = (int)threadIdx.x; u < RU * CU; u += WP_TILE_BLOCK_DIM) {
    const int ur = u / CU, uc = u % CU;
    // Column q of the micro-tile: contiguous for vector access, else strided by CU.
    auto col = [uc](int q) { return VB ? uc * TN + q : uc + CU * q; };
    T acc[TM][TN];
WP_TILE_UNROLL
    for (int r = 0; r < TM; ++r) {
      T* crow = c + (ur + RU * r) * N;
      if constexpr (VB) {
WP_TILE_UNROLL
        for (int q = 0; q < TN; q += W) {
          if (Acc) vec16<T>::get(crow + col(q), &acc[r][q]);
          else
            for (int w = 0; w < W; ++w) acc[r][q + w] = (T)0;
        }
      } else {
WP_TILE_UNROLL
        for (int q = 0; q < TN; ++q) acc[r][q] = Acc ? crow[col(q)] : (T)0;
      }
    }
    // One k-step: B's row k for the thread's columns, then the TM x TN FMAs. The order of
    // the FMAs within a k-step does not matter (each updates its own accumulator); across
    // k-steps every accumulator sees k ascending.
    auto step = [&](int k, const T* av) {
      T bv[TN];
      const T* brow = b + k * N;
      if constexpr (VB) {
WP_TILE_UNROLL
        for (int q = 0; q < TN; q += W) vec16<T>::get(brow + col(q), &bv[q]);
      } else {
WP_TILE_UNROLL
        for (int q = 0; q < TN; ++q) bv[q] = brow[col(q)];
      }
WP_TILE_UNROLL
      for (int r = 0; r < TM; ++r)
WP_TILE_UNROLL
        for (int q = 0; q < TN; ++q) acc[r][q] = fma_(av[r], bv[q], acc[r][q]);
    };
    if constexpr (VA) {
      // W k-steps per vector read of each of the TM rows of A.
WP_TILE_UNROLL_N(4)
      for (int k0 = 0; k0 < K; k0 += W) {
        T aw[TM][W];
WP_TILE_UNROLL
        for (int r = 0; r < TM; ++r) vec16<T>::get(a + (ur + RU * r) * K + k0, aw[r]);
WP_TILE_UNROLL
        for (int w = 0; w < W; ++w) {
          T av[TM];
WP_TILE_UNROLL
          for (int r = 0; r < TM; ++r) av[r] = aw[r][w];
          step(k0 + w, av);
        }
      }
    } else {
WP_TILE_UNROLL_N(8)
      for (int k = 0; k < K; ++k) {
        T av[TM];
WP_TILE_UNROLL
        for (int r = 0; r < TM; ++r) av[r] = a[(ur + RU * r) * K + k];
        step(k, av);
      }
    }
WP_TILE_UNROLL
    for (int r = 0; r < TM; ++r) {
      T* crow = c + (ur + RU * r) * N;
      if constexpr (VB) {
WP_TILE_UNROLL
        for (int q = 0; q < TN; q += W) vec16<T>::put(crow + col(q), &acc[r][q]);
      } else {
WP_TILE_UNROLL
        for (int q = 0; q < TN; ++q) crow[col(q)] = acc[r][q];
      }
    }
  }
}

template <bool Acc, typename T, int M, int K, int N>
WP_FN void matmul(const tile_t<T, M, N>& c, const tile_t<T, M, K>& a, const tile_t<T, K, N>& b) {
  typedef mm_plan<T, M, K, N> P;
  if constexpr (!P::BLOCKED) {
    matmul_simple<Acc, T, M, K, N>(c.data, a.data, b.data);
  } else if constexpr (P::VA || P::VB) {
    // The emitter's slots are 16-byte aligned (tile_slot_end); a tile made over another
    // pointer takes the scalar accesses. One uniform test per call.
    if (aligned16(a.data) && aligned16(b.data) && aligned16(c.data))
      matmul_blocked<Acc, true, T, M, K, N>(c.data, a.data, b.data);
    else
      matmul_blocked<Acc, false, T, M, K, N>(c.data, a.data, b.data);
  } else {
    matmul_blocked<Acc, false, T, M, K, N>(c.data, a.data, b.data);
  }
  __syncthreads();
}
}  // namespace tile_detail

/// `c += a . b` (Warp's `tile_matmul(a, b, out)`): each output an ascending-k FMA chain from
/// its value. `c` is a slot of its own (neither `a` nor `b`).
template <typename T, int M, int K, int N>
WP_FN void tile_matmul_acc(const tile_t<T, M, N>& c, const tile_t<T, M, K>& a,
                           const tile_t<T, K, N>& b) {
  tile_detail::matmul<true>(c, a, b);
}

/// `c = a . b`: the FMA chains from +0.
template <typename T, int M, int K, int N>
WP_FN void tile_matmul(const tile_t<T, M, N>& c, const tile_t<T, M, K>& a,
                       const tile_t<T, K, N>& b) {
  tile_detail::matmul<false>(c, a, b);
}

// ------------------------------------------------------------------------------------------
// Shapes: transpose and broadcast (warp-core/src/tile/shape.rs)
// ------------------------------------------------------------------------------------------

/// `tile_transpose(a)`: `out[j][i] = a[i][j]`; `out` is a slot of its own.
template <typename T, int M, int N>
WP_FN void tile_transpose(const tile_t<T, N, M>& out, const tile_t<T, M, N>& a) {
  for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, j = e % N;
    out.data[j * M + i] = a.data[e];
  }
  __syncthreads();
}

/// `tile_broadcast(a)` to `(N,)`: numpy's rule, each source dim 1 or the target's.
template <typename T, int S, int N>
WP_FN void tile_broadcast(const tile_t<T, N>& out, const tile_t<T, S>& a) {
  static_assert(S == N || S == 1, "tile_broadcast: each source dim is 1 or the target's");
  for (int j = (int)threadIdx.x; j < N; j += WP_TILE_BLOCK_DIM) out.data[j] = a.data[S == 1 ? 0 : j];
  __syncthreads();
}

/// `tile_broadcast(a)` of `(S,)` to `(M, N)`: the row repeated.
template <typename T, int S, int M, int N>
WP_FN void tile_broadcast(const tile_t<T, M, N>& out, const tile_t<T, S>& a) {
  static_assert(S == N || S == 1, "tile_broadcast: each source dim is 1 or the target's");
  for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM)
    out.data[e] = a.data[S == 1 ? 0 : e % N];
  __syncthreads();
}

/// `tile_broadcast(a)` of `(S0, S1)` to `(M, N)`.
template <typename T, int S0, int S1, int M, int N>
WP_FN void tile_broadcast(const tile_t<T, M, N>& out, const tile_t<T, S0, S1>& a) {
  static_assert((S0 == M || S0 == 1) && (S1 == N || S1 == 1),
                "tile_broadcast: each source dim is 1 or the target's");
  for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM) {
    const int i = S0 == 1 ? 0 : e / N, j = S1 == 1 ? 0 : e % N;
    out.data[e] = a.data[i * S1 + j];
  }
  __syncthreads();
}

// ------------------------------------------------------------------------------------------
// Atomic add of a tile into an array (needs wp_atomic.h in the unit: the emitter adds the
// section; `atomic_add` is found by argument-dependent lookup where this is instantiated)
// ------------------------------------------------------------------------------------------

/// `tile_atomic_add(a, t, o)`: `a[o + i] += t[i]` atomically where inside the array; `old`
/// gets the values before (zero outside).
template <typename T, int N0, typename O>
WP_FN void tile_atomic_add(const tile_t<T, N0>& old, const array_t<T, 1>& a, O o,
                           const tile_t<T, N0>& t, ctx_t* ctx) {
  for (int i = (int)threadIdx.x; i < N0; i += WP_TILE_BLOCK_DIM) {
    i64 c;
    old.data[i] = tile_detail::coord(o, i, a.shape[0], &c) ? atomic_add(a, c, t.data[i], ctx) : T{};
  }
  __syncthreads();
}

/// `tile_atomic_add(a, t, (o0, o1))` into a 2-D array.
template <typename T, int N0, int N1, typename O0, typename O1>
WP_FN void tile_atomic_add(const tile_t<T, N0, N1>& old, const array_t<T, 2>& a, O0 o0, O1 o1,
                           const tile_t<T, N0, N1>& t, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1; e += WP_TILE_BLOCK_DIM) {
    i64 c0, c1;
    const bool in = tile_detail::coord(o0, e / N1, a.shape[0], &c0) &&
                    tile_detail::coord(o1, e % N1, a.shape[1], &c1);
    old.data[e] = in ? atomic_add(a, c0, c1, t.data[e], ctx) : T{};
  }
  __syncthreads();
}

/// `tile_atomic_add(a, t, (o0, o1, o2))` into a 3-D array.
template <typename T, int N0, int N1, int N2, typename O0, typename O1, typename O2>
WP_FN void tile_atomic_add(const tile_t<T, N0, N1, N2>& old, const array_t<T, 3>& a, O0 o0,
                           O1 o1, O2 o2, const tile_t<T, N0, N1, N2>& t, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2; e += WP_TILE_BLOCK_DIM) {
    i64 c[3];
    const bool in = tile_detail::coords3<N0, N1, N2>(e, a.shape, o0, o1, o2, c);
    old.data[e] = in ? atomic_add(a, c[0], c[1], c[2], t.data[e], ctx) : T{};
  }
  __syncthreads();
}

/// `tile_atomic_add(a, t, (o0, o1, o2, o3))` into a 4-D array.
template <typename T, int N0, int N1, int N2, int N3, typename O0, typename O1, typename O2,
          typename O3>
WP_FN void tile_atomic_add(const tile_t<T, N0, N1, N2, N3>& old, const array_t<T, 4>& a, O0 o0,
                           O1 o1, O2 o2, O3 o3, const tile_t<T, N0, N1, N2, N3>& t, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2 * N3; e += WP_TILE_BLOCK_DIM) {
    i64 c[4];
    const bool in = tile_detail::coords4<N0, N1, N2, N3>(e, a.shape, o0, o1, o2, o3, c);
    old.data[e] = in ? atomic_add(a, c[0], c[1], c[2], c[3], t.data[e], ctx) : T{};
  }
  __syncthreads();
}

// ------------------------------------------------------------------------------------------
// Scans of rank-1 tiles (warp-core/src/tile/scan.rs documents the order; the two must stay the
// same): lane l runs through its contiguous chunk [l C, (l + 1) C), C = ceil(S / BD); thread 0
// folds the chunk totals in lane order into prefixes; each element then takes op(prefix, r)
// (chunk 0: r alone).
// ------------------------------------------------------------------------------------------

namespace tile_detail {

template <typename T, int N, typename Op>
WP_FN void scan_inclusive(const tile_t<T, N>& out, const tile_t<T, N>& a, Op op) {
  constexpr int C = (N + WP_TILE_BLOCK_DIM - 1) / WP_TILE_BLOCK_DIM;
  constexpr int CHUNKS = (N + C - 1) / C;
  WP_TILE_SHARED_ALIGNED T totals[CHUNKS];
  const int l = (int)threadIdx.x;
  const int start = l * C;
  if (l < CHUNKS) {
    const int end = start + C < N ? start + C : N;
    T r = a.data[start];
    out.data[start] = r;
    for (int e = start + 1; e < end; ++e) {
      r = op(r, a.data[e]);
      out.data[e] = r;
    }
    totals[l] = r;
  }
  __syncthreads();
  if (l == 0) {
    // totals[k] becomes the prefix of chunk k + 1.
    for (int k = 1; k < CHUNKS; ++k) totals[k] = op(totals[k - 1], totals[k]);
  }
  __syncthreads();
  if (l < CHUNKS && l > 0) {
    const int end = start + C < N ? start + C : N;
    const T p = totals[l - 1];
    for (int e = start; e < end; ++e) out.data[e] = op(p, out.data[e]);
  }
  __syncthreads();
}

}  // namespace tile_detail

/// `tile_scan_inclusive(a)`: running sums (`out` a slot of its own).
template <typename T, int N>
WP_FN void tile_scan_inclusive(const tile_t<T, N>& out, const tile_t<T, N>& a) {
  tile_detail::scan_inclusive(out, a, tile_detail::add_op{});
}

/// `tile_scan_exclusive(a)`: the running sums before each element (zero first).
template <typename T, int N>
WP_FN void tile_scan_exclusive(const tile_t<T, N>& out, const tile_t<T, N>& a) {
  tile_detail::scan_inclusive(out, a, tile_detail::add_op{});
  // Shift right by one: every thread reads its elements' predecessors, then writes.
  T keep[(N + WP_TILE_BLOCK_DIM - 1) / WP_TILE_BLOCK_DIM];
  int k = 0;
  for (int e = (int)threadIdx.x; e < N; e += WP_TILE_BLOCK_DIM) keep[k++] = e > 0 ? out.data[e - 1] : T{};
  __syncthreads();
  k = 0;
  for (int e = (int)threadIdx.x; e < N; e += WP_TILE_BLOCK_DIM) out.data[e] = keep[k++];
  __syncthreads();
}

/// `tile_scan_max_inclusive(a)`: running maxima.
template <typename T, int N>
WP_FN void tile_scan_max_inclusive(const tile_t<T, N>& out, const tile_t<T, N>& a) {
  tile_detail::scan_inclusive(out, a, tile_detail::max_op{});
}

/// `tile_scan_min_inclusive(a)`: running minima.
template <typename T, int N>
WP_FN void tile_scan_min_inclusive(const tile_t<T, N>& out, const tile_t<T, N>& a) {
  tile_detail::scan_inclusive(out, a, tile_detail::min_op{});
}

// ------------------------------------------------------------------------------------------
// Conversions (warp-core/src/tile/convert.rs): element types, shapes, the diagonal
// ------------------------------------------------------------------------------------------

/// `tile_full(x)`: every element `x`.
template <typename T, int... D>
WP_FN void tile_full(const tile_t<T, D...>& out, T x) {
  tile_fill(out, x);
}

/// `tile_astype::<U>(a)`: each element converted with `as`'s meaning (wp::cast, as `x as U`).
template <typename U, typename T, int... D>
WP_FN void tile_astype(const tile_t<U, D...>& out, const tile_t<T, D...>& a) {
  for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)
    out.data[i] = cast<U>(a.data[i]);
  __syncthreads();
}

/// `tile_reshape(a)`, `tile_squeeze(a)`: the elements in row-major order, in another shape of
/// the same size.
template <typename T, int... A, int... B>
WP_FN void tile_reshape(const tile_t<T, B...>& out, const tile_t<T, A...>& a) {
  static_assert(tile_t<T, A...>::SIZE == tile_t<T, B...>::SIZE, "tile_reshape: the sizes differ");
  for (int i = (int)threadIdx.x; i < tile_t<T, A...>::SIZE; i += WP_TILE_BLOCK_DIM) out.data[i] = a.data[i];
  __syncthreads();
}

/// `tile_diag_add(a, d)`: `a` with `d[i]` added to `a[i][i]` (only there: adding zero elsewhere
/// would turn -0 into +0).
template <typename T, int N>
WP_FN void tile_diag_add(const tile_t<T, N, N>& out, const tile_t<T, N, N>& a, const tile_t<T, N>& d) {
  for (int k = (int)threadIdx.x; k < N * N; k += WP_TILE_BLOCK_DIM)
    out.data[k] = (k / N == k % N) ? detail::s_add(a.data[k], d.data[k / N]) : a.data[k];
  __syncthreads();
}

// ---- Windows: tile_view and the in-place forms (warp-core's tile::view) --------------------
//
// A window of extent M at offset o on an axis of extent N must lie inside it (0 <= o and
// o + M <= N); otherwise the operation faults (FAULT_TILE_INDEX with the parent's shape, the
// index being the offsets with the first bad axis's coordinate: the offset where it is out of
// range, else the window's last coordinate), reads and writes nothing, and a view is zeros.
// Every thread checks the same (uniform) offsets, so all take the same path.

namespace tile_detail {

/// The start of a window of extent `m` at offset `o` on an axis of extent `n`; `false` with
/// the coordinate to report in `*bad` when it does not fit.
template <typename O>
WP_FN bool window_start(O o, int m, int n, i64* start, i64* bad) {
  const u64 big = 0x7fffffffffffffffull;
  i64 w;
  if constexpr (num<O>::is_signed) {
    w = (i64)o;
  } else {
    if ((u64)o > big) {
      *bad = (i64)big;
      return false;
    }
    w = (i64)(u64)o;
  }
  if (w < 0 || w >= (i64)n) {
    *bad = w;
    return false;
  }
  if (w + (i64)m - 1 >= (i64)n) {
    *bad = w + (i64)m - 1;
    return false;
  }
  *start = w;
  return true;
}

/// An offset as the fault reports it (u64 beyond i64 saturates, as warp-core's).
template <typename O>
WP_FN i64 offset_index(O o) {
  if constexpr (num<O>::is_signed) return (i64)o;
  return (u64)o > 0x7fffffffffffffffull ? (i64)0x7fffffffffffffffll : (i64)(u64)o;
}

/// The starts of an `(M0, M1)` window at `(o0, o1)` in a tile of shape `(A, B)` (M0 = 1, B
/// for a row), or the fault (then `false`).
template <typename T, int A, int B, typename O0, typename O1>
WP_FN bool window_starts2(O0 o0, O1 o1, int m0, int m1, i64* s0, i64* s1, ctx_t* ctx) {
  i64 bad = 0;
  i64 idx[2] = {offset_index(o0), offset_index(o1)};
  if (!window_start(o0, m0, A, s0, &bad)) {
    idx[0] = bad;
  } else if (!window_start(o1, m1, B, s1, &bad)) {
    idx[1] = bad;
  } else {
    return true;
  }
  tile_index_fault<T, A, B>(ctx, idx);
  return false;
}

}  // namespace tile_detail

/// `tile_view(t, o)` of a 1-D tile: a copy of the `M` elements from `o`.
template <typename T, int A, int M, typename O>
WP_FN void tile_view(const tile_t<T, M>& out, const tile_t<T, A>& t, O o, ctx_t* ctx) {
  static_assert(M <= A, "tile_view: the view is larger than the tile");
  i64 s = 0, bad = 0;
  const bool ok = tile_detail::window_start(o, M, A, &s, &bad);
  if (!ok) {
    const i64 idx[1] = {bad};
    tile_index_fault<T, A>(ctx, idx);
  }
  for (int i = (int)threadIdx.x; i < M; i += WP_TILE_BLOCK_DIM) out.data[i] = ok ? t.data[s + i] : T{};
  __syncthreads();
}

/// `tile_view(t, i)` of a 2-D tile: a copy of row `i`.
template <typename T, int A, int B, typename O>
WP_FN void tile_view(const tile_t<T, B>& out, const tile_t<T, A, B>& t, O o, ctx_t* ctx) {
  i64 s0 = 0, s1 = 0;
  const bool ok = tile_detail::window_starts2<T, A, B>(o, 0, 1, B, &s0, &s1, ctx);
  for (int j = (int)threadIdx.x; j < B; j += WP_TILE_BLOCK_DIM)
    out.data[j] = ok ? t.data[s0 * B + j] : T{};
  __syncthreads();
}

/// `tile_view(t, (o0, o1))` of a 2-D tile: a copy of the `(M, N)` window at `(o0, o1)`.
template <typename T, int A, int B, int M, int N, typename O0, typename O1>
WP_FN void tile_view(const tile_t<T, M, N>& out, const tile_t<T, A, B>& t, O0 o0, O1 o1, ctx_t* ctx) {
  static_assert(M <= A && N <= B, "tile_view: the view is larger than the tile");
  i64 s0 = 0, s1 = 0;
  const bool ok = tile_detail::window_starts2<T, A, B>(o0, o1, M, N, &s0, &s1, ctx);
  for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM)
    out.data[e] = ok ? t.data[(s0 + e / N) * B + s1 + e % N] : T{};
  __syncthreads();
}

/// The element operations of the in-place window forms (warp-core's `tile::view::op`).
enum window_op { WINDOW_ASSIGN, WINDOW_ADD, WINDOW_SUB, WINDOW_AND, WINDOW_OR, WINDOW_XOR };

namespace tile_detail {
template <int Op, typename T>
WP_FN T window_apply(T d, T s) {
  if constexpr (Op == WINDOW_ASSIGN) return s;
  else if constexpr (Op == WINDOW_ADD) return detail::s_add(d, s);
  else if constexpr (Op == WINDOW_SUB) return detail::s_sub(d, s);
  else if constexpr (Op == WINDOW_AND) return (T)(d & s);
  else if constexpr (Op == WINDOW_OR) return (T)(d | s);
  else return (T)(d ^ s);
}
}  // namespace tile_detail

/// `tile_assign(&mut d, s, o)` and the `_inplace` forms, 1-D: `d[o + i] = op(d[o + i], s[i])`.
/// Each thread reads `s` before it writes `d` (the same element), so `s` may be `d` itself.
template <int Op, typename T, int A, int M, typename O>
WP_FN void tile_window(const tile_t<T, A>& d, const tile_t<T, M>& s, O o, ctx_t* ctx) {
  static_assert(M <= A, "tile_assign: the source is larger than the destination");
  i64 st = 0, bad = 0;
  if (tile_detail::window_start(o, M, A, &st, &bad)) {
    for (int i = (int)threadIdx.x; i < M; i += WP_TILE_BLOCK_DIM) {
      const T x = s.data[i];
      d.data[st + i] = tile_detail::window_apply<Op>(d.data[st + i], x);
    }
  } else {
    const i64 idx[1] = {bad};
    tile_index_fault<T, A>(ctx, idx);
  }
  __syncthreads();
}

/// The same, 2-D: the `(M, N)` window of `d` at `(o0, o1)`.
template <int Op, typename T, int A, int B, int M, int N, typename O0, typename O1>
WP_FN void tile_window(const tile_t<T, A, B>& d, const tile_t<T, M, N>& s, O0 o0, O1 o1, ctx_t* ctx) {
  static_assert(M <= A && N <= B, "tile_assign: the source is larger than the destination");
  i64 s0 = 0, s1 = 0;
  if (tile_detail::window_starts2<T, A, B>(o0, o1, M, N, &s0, &s1, ctx)) {
    for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM) {
      const T x = s.data[e];
      T* p = &d.data[(s0 + e / N) * B + s1 + e % N];
      *p = tile_detail::window_apply<Op>(*p, x);
    }
  }
  __syncthreads();
}

// The rows' own names (the emitter calls these): `NAME(d, s, offsets.., ctx)`.
#define WP_TILE_WINDOW_FORM(NAME, OP)                                   \
  template <typename D, typename S, typename... R>                      \
  WP_FN void NAME(const D& d, const S& s, R... rest) {                  \
    tile_window<OP>(d, s, rest...);                                     \
  }
WP_TILE_WINDOW_FORM(tile_assign, WINDOW_ASSIGN)
WP_TILE_WINDOW_FORM(tile_add_inplace, WINDOW_ADD)
WP_TILE_WINDOW_FORM(tile_sub_inplace, WINDOW_SUB)
WP_TILE_WINDOW_FORM(tile_bit_and_inplace, WINDOW_AND)
WP_TILE_WINDOW_FORM(tile_bit_or_inplace, WINDOW_OR)
WP_TILE_WINDOW_FORM(tile_bit_xor_inplace, WINDOW_XOR)
#undef WP_TILE_WINDOW_FORM

}  // namespace wp

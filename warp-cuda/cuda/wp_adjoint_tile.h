// wp_adjoint_tile.h: the adjoints of the tile operations, the CUDA side of
// warp-core/src/tile/adjoint.rs (whose docs give the rules; every formula and every order of
// summation here is the same, so that a tiled kernel's gradients agree with the CPU's).
//
// Conventions: every function accumulates (`+=`) into the adjoints it is given, from `r`, the
// adjoint of the operation's result. Arguments: the operation's inputs, one adjoint per input
// (an array's gradient, a tile's adjoint tile, a scalar's or an offset's adjoint by
// reference), then `r`, then the fault context where the function reads an array's gradient.
// Every function but `adj_tile_extract*` is cooperative, like wp_tile.h's operations: every
// thread of the block calls it with the same arguments, it works block-strided over elements
// and ends in `__syncthreads()`.
//
// A uniform scalar operand (`s` in `t * s`) receives the sum of the elements' contributions
// in the reductions' order (tile_detail::reduce_with), returned to every thread; the caller
// adds it once for the block (thread 0). `adj_tile_extract*` is one thread's: it adds to the
// element with a shared-memory atomic, so when several threads read one element the order of
// their contributions is not fixed (the CPU adds them in lane order).
#pragma once

#include "wp_adjoint_core.h"
#include "wp_tile.h"

namespace wp {

namespace tile_detail {

/// `*p += v` from one thread while others may add to the same element: a shared-memory
/// atomic on the GPU; in the host emulator the block's threads are fibers, which switch only at
/// barriers.
template <typename T>
WP_FN void shared_add(T* p, T v) {
#if defined(__CUDACC__)
  atomicAdd(p, v);
#else
  *p += v;
#endif
}

/// A vector element (a tile of `Vec2`/`DVec2`): component by component.
WP_LFN void shared_add(Vec2* p, Vec2 v) {
  shared_add(&p->x, v.x);
  shared_add(&p->y, v.y);
}
WP_LFN void shared_add(DVec2* p, DVec2 v) {
  shared_add(&p->x, v.x);
  shared_add(&p->y, v.y);
}

/// The sum of `c(e)` for e in 0..S in the reductions' order, returned to every thread (each
/// `c(e)` is called once, by one thread).
template <typename T, int S, typename Elem>
WP_FN T block_total(Elem c) {
  WP_TILE_SHARED_ALIGNED unsigned char total_bytes[sizeof(T) < 16 ? 16 : sizeof(T)];
  T* total = reinterpret_cast<T*>(total_bytes);
  reduce_with<T, S>(c, add_op{}, [total](T r) { *total = r; });
  const T r = *total;
  // The slot is reused by the next call.
  __syncthreads();
  return r;
}

/// The adjoint of a broadcast from `(S0, S1)` to `(M, N)` (each source dim the target's or
/// 1): each source element gains the sum, from zero in ascending row-major order, of the
/// target elements it was copied to.
template <int S0, int S1, int M, int N, typename T>
WP_FN void unbroadcast(T* src, const T* dst) {
  for (int e = (int)threadIdx.x; e < S0 * S1; e += WP_TILE_BLOCK_DIM) {
    const int p = e / S1, q = e % S1;
    const int i0 = S0 == M ? p : 0, i1 = S0 == M ? p + 1 : M;
    const int j0 = S1 == N ? q : 0, j1 = S1 == N ? q + 1 : N;
    T acc = T(0);
    for (int i = i0; i < i1; ++i)
      for (int j = j0; j < j1; ++j) acc = acc + dst[i * N + j];
    src[e] += acc;
  }
  __syncthreads();
}

}  // namespace tile_detail

// ---- A lane's store -------------------------------------------------------------------------

namespace tile_detail {
/// `*p`, leaving `zero` there: one atomic exchange for an f32 or f64 element on the GPU, a
/// plain read and write otherwise.
template <typename T>
WP_FN T exchange(T* p, const T& zero) {
  const T r = *p;
  *p = zero;
  return r;
}
#if defined(__CUDACC__)
WP_LFN f32 exchange(f32* p, const f32& zero) { return atomicExch(p, zero); }
WP_LFN f64 exchange(f64* p, const f64& zero) {
  const unsigned long long z = (unsigned long long)__double_as_longlong(zero);
  return __longlong_as_double((long long)atomicExch((unsigned long long*)p, z));
}
#endif
template <typename T, int N>
WP_FN T grad_take_lanes_idx(const array_t<T, N>& g, const i64* idx, const T& zero, ctx_t* ctx) {
  if (g.data == nullptr) return zero;
  if (!detail::check_idx(g, idx, ctx)) return T{};
  return exchange(detail::elem_ptr_unchecked_idx(g, idx), zero);
}
}  // namespace tile_detail

// `grad_take` in a tiled kernel's lane code (the adjoint of a lane's store): several lanes of a
// block may have stored the same element, and each takes its gradient; the exchange gives it
// to one of them and zero to the others (the CPU's lanes take it in order: lane 0 gets it).
// Scalar float elements only are exchanged atomically (vector elements: one read and write).
#define WP_GRAD_TAKE_LANES(N, PARAMS, ...)                                                   \
  template <typename T>                                                                      \
  WP_FN T grad_take_lanes(const array_t<T, N>& g, PARAMS,                                    \
                          const typename identity<T>::type& zero, ctx_t* ctx) {             \
    const i64 idx[N] = {__VA_ARGS__};                                                        \
    return tile_detail::grad_take_lanes_idx(g, idx, zero, ctx);                              \
  }
#define WP_COMMA ,
WP_GRAD_TAKE_LANES(1, i64 i0, i0)
WP_GRAD_TAKE_LANES(2, i64 i0 WP_COMMA i64 i1, i0, i1)
WP_GRAD_TAKE_LANES(3, i64 i0 WP_COMMA i64 i1 WP_COMMA i64 i2, i0, i1, i2)
WP_GRAD_TAKE_LANES(4, i64 i0 WP_COMMA i64 i1 WP_COMMA i64 i2 WP_COMMA i64 i3, i0, i1, i2, i3)
#undef WP_COMMA
#undef WP_GRAD_TAKE_LANES

// ---- Loads and stores ----------------------------------------------------------------------

/// `t = tile_load(a, o)`: `a.grad[o + i] += r[i]` inside the array (atomically).
template <typename T, int N0, typename O>
WP_FN void adj_tile_load1(const array_t<T, 1>& a, O o, const array_t<T, 1>& adj_a, O&,
                          const tile_t<T, N0>& r, ctx_t* ctx) {
  if (adj_a.data != nullptr) {
    for (int i = (int)threadIdx.x; i < N0; i += WP_TILE_BLOCK_DIM) {
      i64 c;
      if (tile_detail::coord(o, i, a.shape[0], &c)) grad_accum(adj_a, c, r.data[i], ctx);
    }
  }
  __syncthreads();
}

/// `t = tile_load(a, (o0, o1))`.
template <typename T, int N0, int N1, typename O0, typename O1>
WP_FN void adj_tile_load2(const array_t<T, 2>& a, O0 o0, O1 o1, const array_t<T, 2>& adj_a, O0&,
                          O1&, const tile_t<T, N0, N1>& r, ctx_t* ctx) {
  if (adj_a.data != nullptr) {
    for (int e = (int)threadIdx.x; e < N0 * N1; e += WP_TILE_BLOCK_DIM) {
      i64 c0, c1;
      if (tile_detail::coord(o0, e / N1, a.shape[0], &c0) &&
          tile_detail::coord(o1, e % N1, a.shape[1], &c1))
        grad_accum(adj_a, c0, c1, r.data[e], ctx);
    }
  }
  __syncthreads();
}

/// `tile_store(a, t, o)`: each written element's gradient hands over to `t`'s adjoint and is
/// cleared.
template <typename T, int N0, typename O>
WP_FN void adj_tile_store1(const array_t<T, 1>& a, const tile_t<T, N0>&, O o,
                           const array_t<T, 1>& adj_a, const tile_t<T, N0>& adj_t, O&,
                           const unit_t&, ctx_t* ctx) {
  for (int i = (int)threadIdx.x; i < N0; i += WP_TILE_BLOCK_DIM) {
    i64 c;
    if (tile_detail::coord(o, i, a.shape[0], &c)) adj_t.data[i] += grad_take(adj_a, c, T{}, ctx);
  }
  __syncthreads();
}

/// `tile_store(a, t, (o0, o1))`.
template <typename T, int N0, int N1, typename O0, typename O1>
WP_FN void adj_tile_store2(const array_t<T, 2>& a, const tile_t<T, N0, N1>&, O0 o0, O1 o1,
                           const array_t<T, 2>& adj_a, const tile_t<T, N0, N1>& adj_t, O0&, O1&,
                           const unit_t&, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1; e += WP_TILE_BLOCK_DIM) {
    i64 c0, c1;
    if (tile_detail::coord(o0, e / N1, a.shape[0], &c0) &&
        tile_detail::coord(o1, e % N1, a.shape[1], &c1))
      adj_t.data[e] += grad_take(adj_a, c0, c1, T{}, ctx);
  }
  __syncthreads();
}

/// `t = tile_load(a, (o0, o1, o2))`.
template <typename T, int N0, int N1, int N2, typename O0, typename O1, typename O2>
WP_FN void adj_tile_load3(const array_t<T, 3>& a, O0 o0, O1 o1, O2 o2, const array_t<T, 3>& adj_a,
                          O0&, O1&, O2&, const tile_t<T, N0, N1, N2>& r, ctx_t* ctx) {
  if (adj_a.data != nullptr) {
    for (int e = (int)threadIdx.x; e < N0 * N1 * N2; e += WP_TILE_BLOCK_DIM) {
      i64 c[3];
      if (tile_detail::coords3<N0, N1, N2>(e, a.shape, o0, o1, o2, c))
        grad_accum(adj_a, c[0], c[1], c[2], r.data[e], ctx);
    }
  }
  __syncthreads();
}

/// `t = tile_load(a, (o0, o1, o2, o3))`.
template <typename T, int N0, int N1, int N2, int N3, typename O0, typename O1, typename O2,
          typename O3>
WP_FN void adj_tile_load4(const array_t<T, 4>& a, O0 o0, O1 o1, O2 o2, O3 o3,
                          const array_t<T, 4>& adj_a, O0&, O1&, O2&, O3&,
                          const tile_t<T, N0, N1, N2, N3>& r, ctx_t* ctx) {
  if (adj_a.data != nullptr) {
    for (int e = (int)threadIdx.x; e < N0 * N1 * N2 * N3; e += WP_TILE_BLOCK_DIM) {
      i64 c[4];
      if (tile_detail::coords4<N0, N1, N2, N3>(e, a.shape, o0, o1, o2, o3, c))
        grad_accum(adj_a, c[0], c[1], c[2], c[3], r.data[e], ctx);
    }
  }
  __syncthreads();
}

/// `tile_store(a, t, (o0, o1, o2))`.
template <typename T, int N0, int N1, int N2, typename O0, typename O1, typename O2>
WP_FN void adj_tile_store3(const array_t<T, 3>& a, const tile_t<T, N0, N1, N2>&, O0 o0, O1 o1,
                           O2 o2, const array_t<T, 3>& adj_a, const tile_t<T, N0, N1, N2>& adj_t,
                           O0&, O1&, O2&, const unit_t&, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2; e += WP_TILE_BLOCK_DIM) {
    i64 c[3];
    if (tile_detail::coords3<N0, N1, N2>(e, a.shape, o0, o1, o2, c))
      adj_t.data[e] += grad_take(adj_a, c[0], c[1], c[2], T{}, ctx);
  }
  __syncthreads();
}

/// `tile_store(a, t, (o0, o1, o2, o3))`.
template <typename T, int N0, int N1, int N2, int N3, typename O0, typename O1, typename O2,
          typename O3>
WP_FN void adj_tile_store4(const array_t<T, 4>& a, const tile_t<T, N0, N1, N2, N3>&, O0 o0, O1 o1,
                           O2 o2, O3 o3, const array_t<T, 4>& adj_a,
                           const tile_t<T, N0, N1, N2, N3>& adj_t, O0&, O1&, O2&, O3&,
                           const unit_t&, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2 * N3; e += WP_TILE_BLOCK_DIM) {
    i64 c[4];
    if (tile_detail::coords4<N0, N1, N2, N3>(e, a.shape, o0, o1, o2, o3, c))
      adj_t.data[e] += grad_take(adj_a, c[0], c[1], c[2], c[3], T{}, ctx);
  }
  __syncthreads();
}

// ---- Elementwise ---------------------------------------------------------------------------

// `a op b` on two tiles (`_tt`), a tile and a uniform scalar (`_ts`), a scalar and a tile
// (`_st`): the scalar adjoint `FN` per element; a scalar's adjoint is the block total. The
// scalar `S` is the elements' type, or their components' for a tile of vectors (`t * s`).
#define WP_TILE_ADJ_BINARY(NAME, FN)                                                          \
  template <typename T, int... D>                                                             \
  WP_FN void adj_tile_##NAME##_tt(const tile_t<T, D...>& a, const tile_t<T, D...>& b,         \
                                  const tile_t<T, D...>& adj_a, const tile_t<T, D...>& adj_b, \
                                  const tile_t<T, D...>& r) {                                 \
    for (int e = (int)threadIdx.x; e < tile_t<T, D...>::SIZE; e += WP_TILE_BLOCK_DIM)         \
      FN(a.data[e], b.data[e], adj_a.data[e], adj_b.data[e], r.data[e]);                      \
    __syncthreads();                                                                          \
  }                                                                                           \
  template <typename T, typename S, int... D>                                                 \
  WP_FN void adj_tile_##NAME##_ts(const tile_t<T, D...>& a, S s, const tile_t<T, D...>& adj_a, \
                                  S& adj_s, const tile_t<T, D...>& r) {                       \
    adj_s += tile_detail::block_total<S, tile_t<T, D...>::SIZE>([&](int e) {                  \
      S g = S(0);                                                                             \
      FN(a.data[e], s, adj_a.data[e], g, r.data[e]);                                          \
      return g;                                                                               \
    });                                                                                       \
  }                                                                                           \
  template <typename T, typename S, int... D>                                                 \
  WP_FN void adj_tile_##NAME##_st(S s, const tile_t<T, D...>& b, S& adj_s,                    \
                                  const tile_t<T, D...>& adj_b, const tile_t<T, D...>& r) {   \
    adj_s += tile_detail::block_total<S, tile_t<T, D...>::SIZE>([&](int e) {                  \
      S g = S(0);                                                                             \
      FN(s, b.data[e], g, adj_b.data[e], r.data[e]);                                          \
      return g;                                                                               \
    });                                                                                       \
  }
WP_TILE_ADJ_BINARY(add, adj_add)
WP_TILE_ADJ_BINARY(sub, adj_sub)
WP_TILE_ADJ_BINARY(mul, adj_mul)
WP_TILE_ADJ_BINARY(div, adj_div)
#undef WP_TILE_ADJ_BINARY

/// `-t`.
template <typename T, int... D>
WP_FN void adj_tile_neg(const tile_t<T, D...>& a, const tile_t<T, D...>& adj_a,
                        const tile_t<T, D...>& r) {
  for (int e = (int)threadIdx.x; e < tile_t<T, D...>::SIZE; e += WP_TILE_BLOCK_DIM)
    adj_neg(a.data[e], adj_a.data[e], r.data[e]);
  __syncthreads();
}

/// `tile_map(f, a)`: `adj` (a functor calling f's scalar adjoint) on each element.
template <typename T, typename U, int... D, typename F>
WP_FN void adj_tile_map1(const tile_t<T, D...>& a, const tile_t<T, D...>& adj_a,
                         const tile_t<U, D...>& r, F adj) {
  for (int e = (int)threadIdx.x; e < tile_t<T, D...>::SIZE; e += WP_TILE_BLOCK_DIM)
    adj(a.data[e], adj_a.data[e], r.data[e]);
  __syncthreads();
}

/// `tile_map(f, a, b)`.
template <typename T, typename U, typename V, int... D, typename F>
WP_FN void adj_tile_map2(const tile_t<T, D...>& a, const tile_t<U, D...>& b,
                         const tile_t<T, D...>& adj_a, const tile_t<U, D...>& adj_b,
                         const tile_t<V, D...>& r, F adj) {
  for (int e = (int)threadIdx.x; e < tile_t<T, D...>::SIZE; e += WP_TILE_BLOCK_DIM)
    adj(a.data[e], b.data[e], adj_a.data[e], adj_b.data[e], r.data[e]);
  __syncthreads();
}

// ---- Conversions ---------------------------------------------------------------------------

/// `tile_full(x)`: the uniform `x` gets the seed's sum in the reductions' order, returned to
/// every thread (the caller adds it once for the block, as for `t * s`).
template <typename T, int... D>
WP_FN void adj_tile_full(T, T& adj_x, const tile_t<T, D...>& r) {
  adj_x += tile_detail::block_total<T, tile_t<T, D...>::SIZE>([&](int e) { return r.data[e]; });
}

/// `tile_astype::<U>(t)`: each element's seed converted back as `adj_cast` (between floats;
/// nothing to or from an integer).
template <typename T, typename U, int... D>
WP_FN void adj_tile_astype(const tile_t<T, D...>&, const tile_t<T, D...>& adj_t,
                           const tile_t<U, D...>& r) {
  for (int e = (int)threadIdx.x; e < tile_t<T, D...>::SIZE; e += WP_TILE_BLOCK_DIM)
    adj_cast(adj_t.data[e], r.data[e]);
  __syncthreads();
}

// ---- Reductions ----------------------------------------------------------------------------

/// `tile_sum(t)`, `tile_reduce(add, t)`: every element gets the result's adjoint.
template <typename T, int... D>
WP_FN void adj_tile_sum(const tile_t<T, D...>&, const tile_t<T, D...>& adj_t,
                        const tile_t<T, 1>& r) {
  const T g = r.data[0];
  for (int e = (int)threadIdx.x; e < tile_t<T, D...>::SIZE; e += WP_TILE_BLOCK_DIM)
    adj_t.data[e] += g;
  __syncthreads();
}

namespace tile_detail {
/// The extremum `arg_reduce` picks gets the result's adjoint (thread 0 adds it).
template <bool Max, typename T, int... D>
WP_FN void adj_extreme(const tile_t<T, D...>& t, const tile_t<T, D...>& adj_t,
                       const tile_t<T, 1>& r) {
  WP_TILE_SHARED_ALIGNED i32 at[4];
  const T* x = t.data;
  reduce_with<arg_t<T>, tile_t<T, D...>::SIZE>(
      [x](int e) {
        arg_t<T> a;
        a.v = x[e];
        a.i = (i32)e;
        return a;
      },
      arg_op<Max>{}, [](const arg_t<T>& p) { at[0] = p.i; });
  if (threadIdx.x == 0) adj_t.data[at[0]] += r.data[0];
  __syncthreads();
}
}  // namespace tile_detail

/// `tile_min(t)`: to the first smallest element (tile_argmin's).
template <typename T, int... D>
WP_FN void adj_tile_min(const tile_t<T, D...>& t, const tile_t<T, D...>& adj_t,
                        const tile_t<T, 1>& r) {
  tile_detail::adj_extreme<false>(t, adj_t, r);
}

/// `tile_max(t)`: to the first largest element (tile_argmax's).
template <typename T, int... D>
WP_FN void adj_tile_max(const tile_t<T, D...>& t, const tile_t<T, D...>& adj_t,
                        const tile_t<T, 1>& r) {
  tile_detail::adj_extreme<true>(t, adj_t, r);
}

// ---- Shapes --------------------------------------------------------------------------------

/// `tile_reshape(a)`, `tile_squeeze(a)`: `adj_a[k] += r[k]` over the row-major flattenings.
template <typename T, int... A, int... B>
WP_FN void adj_tile_reshape(const tile_t<T, A...>&, const tile_t<T, A...>& adj_a,
                            const tile_t<T, B...>& r) {
  for (int e = (int)threadIdx.x; e < tile_t<T, A...>::SIZE; e += WP_TILE_BLOCK_DIM)
    adj_a.data[e] += r.data[e];
  __syncthreads();
}

/// `tile_diag_add(a, d)`: `adj_a += r`, `adj_d[i] += r[i][i]` (separate loops: a thread's
/// element of `adj_a` is not another's of `adj_d`).
template <typename T, int N>
WP_FN void adj_tile_diag_add(const tile_t<T, N, N>&, const tile_t<T, N>&,
                             const tile_t<T, N, N>& adj_a, const tile_t<T, N>& adj_d,
                             const tile_t<T, N, N>& r) {
  for (int e = (int)threadIdx.x; e < N * N; e += WP_TILE_BLOCK_DIM) adj_a.data[e] += r.data[e];
  for (int i = (int)threadIdx.x; i < N; i += WP_TILE_BLOCK_DIM) adj_d.data[i] += r.data[i * N + i];
  __syncthreads();
}

/// `tile_transpose(a)`: `adj_a[i][j] += r[j][i]`.
template <typename T, int M, int N>
WP_FN void adj_tile_transpose(const tile_t<T, M, N>&, const tile_t<T, M, N>& adj_a,
                              const tile_t<T, N, M>& r) {
  for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM)
    adj_a.data[e] += r.data[(e % N) * M + e / N];
  __syncthreads();
}

/// `tile_broadcast`, rank 1 to rank 1.
template <typename T, int S, int N>
WP_FN void adj_tile_broadcast11(const tile_t<T, S>&, const tile_t<T, S>& adj_a,
                                const tile_t<T, N>& r) {
  tile_detail::unbroadcast<1, S, 1, N>(adj_a.data, r.data);
}

/// `tile_broadcast`, rank 1 (aligned with the last axis) to rank 2.
template <typename T, int S, int M, int N>
WP_FN void adj_tile_broadcast12(const tile_t<T, S>&, const tile_t<T, S>& adj_a,
                                const tile_t<T, M, N>& r) {
  tile_detail::unbroadcast<1, S, M, N>(adj_a.data, r.data);
}

/// `tile_broadcast`, rank 2 to rank 2.
template <typename T, int S0, int S1, int M, int N>
WP_FN void adj_tile_broadcast22(const tile_t<T, S0, S1>&, const tile_t<T, S0, S1>& adj_a,
                                const tile_t<T, M, N>& r) {
  tile_detail::unbroadcast<S0, S1, M, N>(adj_a.data, r.data);
}

// ---- Atomic add ----------------------------------------------------------------------------

/// `old = tile_atomic_add(a, t, o)`: `adj_t[i] += a.grad[o + i]` inside the array (read, not
/// cleared: warp-core's `adj_tile_atomic_add1`); `r`, the old values' adjoint, goes nowhere.
template <typename T, int N0, typename O>
WP_FN void adj_tile_atomic_add1(const array_t<T, 1>& a, const tile_t<T, N0>&, O o,
                                const array_t<T, 1>& adj_a, const tile_t<T, N0>& adj_t, O&,
                                const tile_t<T, N0>&, ctx_t* ctx) {
  for (int i = (int)threadIdx.x; i < N0; i += WP_TILE_BLOCK_DIM) {
    i64 c;
    if (tile_detail::coord(o, i, a.shape[0], &c)) adj_t.data[i] += grad_get(adj_a, c, T{}, ctx);
  }
  __syncthreads();
}

/// `old = tile_atomic_add(a, t, (o0, o1))`.
template <typename T, int N0, int N1, typename O0, typename O1>
WP_FN void adj_tile_atomic_add2(const array_t<T, 2>& a, const tile_t<T, N0, N1>&, O0 o0, O1 o1,
                                const array_t<T, 2>& adj_a, const tile_t<T, N0, N1>& adj_t, O0&,
                                O1&, const tile_t<T, N0, N1>&, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1; e += WP_TILE_BLOCK_DIM) {
    i64 c0, c1;
    if (tile_detail::coord(o0, e / N1, a.shape[0], &c0) &&
        tile_detail::coord(o1, e % N1, a.shape[1], &c1))
      adj_t.data[e] += grad_get(adj_a, c0, c1, T{}, ctx);
  }
  __syncthreads();
}

/// `old = tile_atomic_add(a, t, (o0, o1, o2))`.
template <typename T, int N0, int N1, int N2, typename O0, typename O1, typename O2>
WP_FN void adj_tile_atomic_add3(const array_t<T, 3>& a, const tile_t<T, N0, N1, N2>&, O0 o0, O1 o1,
                                O2 o2, const array_t<T, 3>& adj_a,
                                const tile_t<T, N0, N1, N2>& adj_t, O0&, O1&, O2&,
                                const tile_t<T, N0, N1, N2>&, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2; e += WP_TILE_BLOCK_DIM) {
    i64 c[3];
    if (tile_detail::coords3<N0, N1, N2>(e, a.shape, o0, o1, o2, c))
      adj_t.data[e] += grad_get(adj_a, c[0], c[1], c[2], T{}, ctx);
  }
  __syncthreads();
}

/// `old = tile_atomic_add(a, t, (o0, o1, o2, o3))`.
template <typename T, int N0, int N1, int N2, int N3, typename O0, typename O1, typename O2,
          typename O3>
WP_FN void adj_tile_atomic_add4(const array_t<T, 4>& a, const tile_t<T, N0, N1, N2, N3>&, O0 o0,
                                O1 o1, O2 o2, O3 o3, const array_t<T, 4>& adj_a,
                                const tile_t<T, N0, N1, N2, N3>& adj_t, O0&, O1&, O2&, O3&,
                                const tile_t<T, N0, N1, N2, N3>&, ctx_t* ctx) {
  for (int e = (int)threadIdx.x; e < N0 * N1 * N2 * N3; e += WP_TILE_BLOCK_DIM) {
    i64 c[4];
    if (tile_detail::coords4<N0, N1, N2, N3>(e, a.shape, o0, o1, o2, o3, c))
      adj_t.data[e] += grad_get(adj_a, c[0], c[1], c[2], c[3], T{}, ctx);
  }
  __syncthreads();
}

// ---- Matmul --------------------------------------------------------------------------------

namespace tile_detail {
/// The type a matmul's products accumulate in, and the conversions (warp-core's `MatmulElem`):
/// f32 and f64 in themselves, f16 and bf16 in f32 (widening exact, narrowing rounded once).
template <typename T>
struct mm_elem {
  typedef T acc;
  static WP_FN T widen(T x) { return x; }
  static WP_FN T narrow(T x) { return x; }
};
template <>
struct mm_elem<f16> {
  typedef f32 acc;
  static WP_FN f32 widen(f16 x) { return f16_to_f32(x); }
  static WP_FN f16 narrow(f32 x) { return f16_from_f32(x); }
};
template <>
struct mm_elem<bf16> {
  typedef f32 acc;
  static WP_FN f32 widen(bf16 x) { return bf16_to_f32(x); }
  static WP_FN bf16 narrow(f32 x) { return bf16_from_f32(x); }
};
}  // namespace tile_detail

/// `c = tile_matmul(a, b)` and `tile_matmul(a, b, &mut c)`: `adj_a += r bᵀ`, then
/// `adj_b += aᵀ r`, each element one FMA chain from zero in ascending order in the operands'
/// accumulator type (f16: exact products in f32, rounded once to f16), added to the adjoint.
/// `r` is the result's adjoint: `T` for the returning form, the f32 accumulator's for the
/// accumulating f16 form (warp-core's `adj_tile_matmul`).
template <typename T, typename R, int M, int K, int N>
WP_FN void adj_tile_matmul(const tile_t<T, M, K>& a, const tile_t<T, K, N>& b,
                           const tile_t<T, M, K>& adj_a, const tile_t<T, K, N>& adj_b,
                           const tile_t<R, M, N>& r) {
  typedef tile_detail::mm_elem<T> E;
  typedef tile_detail::mm_elem<R> ER;
  typedef typename E::acc A;
  static_assert(sizeof(A) == sizeof(typename ER::acc), "the seed accumulates like the operands");
  for (int e = (int)threadIdx.x; e < M * K; e += WP_TILE_BLOCK_DIM) {
    const int i = e / K, k = e % K;
    A acc = A(0);
    for (int j = 0; j < N; ++j)
      acc = tile_detail::fma_(ER::widen(r.data[i * N + j]), E::widen(b.data[k * N + j]), acc);
    adj_a.data[e] += E::narrow(acc);
  }
  __syncthreads();
  for (int e = (int)threadIdx.x; e < K * N; e += WP_TILE_BLOCK_DIM) {
    const int k = e / N, j = e % N;
    A acc = A(0);
    for (int i = 0; i < M; ++i)
      acc = tile_detail::fma_(E::widen(a.data[i * K + k]), ER::widen(r.data[i * N + j]), acc);
    adj_b.data[e] += E::narrow(acc);
  }
  __syncthreads();
}

// ---- Threads and elements ------------------------------------------------------------------

/// `x = t[i]` in one thread: `adj_t[i] += r` (a shared-memory atomic; outside the tile, the
/// forward's fault).
template <typename T, int N0, typename I>
WP_FN void adj_tile_extract1(const tile_t<T, N0>& t, I i, const tile_t<T, N0>& adj_t, I&, T r,
                             ctx_t* ctx) {
  (void)tile_extract(t, i, ctx);
  if (!(num<I>::is_signed && (i64)i < 0) && (u64)i < (u64)N0)
    tile_detail::shared_add(&adj_t.data[(i64)i], r);
}

/// `x = t[i, j]` in one thread.
template <typename T, int N0, int N1, typename I, typename J>
WP_FN void adj_tile_extract2(const tile_t<T, N0, N1>& t, I i, J j, const tile_t<T, N0, N1>& adj_t,
                             I&, J&, T r, ctx_t* ctx) {
  (void)tile_extract(t, i, j, ctx);
  const bool in0 = !(num<I>::is_signed && (i64)i < 0) && (u64)i < (u64)N0;
  const bool in1 = !(num<J>::is_signed && (i64)j < 0) && (u64)j < (u64)N1;
  if (in0 && in1) tile_detail::shared_add(&adj_t.data[(i64)i * N1 + (i64)j], r);
}

/// `x = t[i, j, k]` in one thread.
template <typename T, int N0, int N1, int N2, typename I, typename J, typename K>
WP_FN void adj_tile_extract3(const tile_t<T, N0, N1, N2>& t, I i, J j, K k,
                             const tile_t<T, N0, N1, N2>& adj_t, I&, J&, K&, T r, ctx_t* ctx) {
  (void)tile_extract(t, i, j, k, ctx);
  if (tile_detail::index_in(i, N0) && tile_detail::index_in(j, N1) && tile_detail::index_in(k, N2))
    tile_detail::shared_add(&adj_t.data[((i64)i * N1 + (i64)j) * N2 + (i64)k], r);
}

/// `x = t[i, j, k, l]` in one thread.
template <typename T, int N0, int N1, int N2, int N3, typename I, typename J, typename K,
          typename L>
WP_FN void adj_tile_extract4(const tile_t<T, N0, N1, N2, N3>& t, I i, J j, K k, L l,
                             const tile_t<T, N0, N1, N2, N3>& adj_t, I&, J&, K&, L&, T r,
                             ctx_t* ctx) {
  (void)tile_extract(t, i, j, k, l, ctx);
  if (tile_detail::index_in(i, N0) && tile_detail::index_in(j, N1) &&
      tile_detail::index_in(k, N2) && tile_detail::index_in(l, N3))
    tile_detail::shared_add(&adj_t.data[(((i64)i * N1 + (i64)j) * N2 + (i64)k) * N3 + (i64)l], r);
}

/// `t = tile(x)`: the thread's `x` gains its element of `t`'s adjoint.
template <typename T, int N>
WP_FN void adj_tile_lanes(T& adj_x, const tile_t<T, N>& r) {
  if ((int)threadIdx.x < N) adj_x += r.data[threadIdx.x];
  __syncthreads();
}

/// `x = untile(t)`: the thread's element of `t`'s adjoint gains its adjoint of `x`.
template <typename T, int N>
WP_FN void adj_untile(const tile_t<T, N>& adj_t, const T& adj_x) {
  if ((int)threadIdx.x < N) adj_t.data[threadIdx.x] += adj_x;
  __syncthreads();
}

/// A tile adjoint's accumulation (`adj_a += r`, a tile's copy).
template <typename T, int... D>
WP_FN void adj_tile_accum(const tile_t<T, D...>& adj_a, const tile_t<T, D...>& r) {
  for (int e = (int)threadIdx.x; e < tile_t<T, D...>::SIZE; e += WP_TILE_BLOCK_DIM)
    adj_a.data[e] += r.data[e];
  __syncthreads();
}

// ---- A reassigned tile's history on the threads' stacks ----
// Each thread pushes the elements it owns (threadIdx.x + k * WP_TILE_BLOCK_DIM, ascending) on
// its own stack and pops them in the reverse order (warp-core's `push_tile`/`pop_tile` put
// element e on lane e % block_dim's stack in the same order). The pop ends in a barrier: the
// other threads read the restored elements next.

template <typename T, int... D>
WP_FN void adstack_push_tile(adstack_t* st, const tile_t<T, D...>& t, i32 line, ctx_t* ctx) {
  for (int i = (int)threadIdx.x; i < tile_t<T, D...>::SIZE; i += WP_TILE_BLOCK_DIM)
    adstack_push(st, t.data[i], line, ctx);
  // The assignment that follows may write elements other threads have not pushed yet.
  __syncthreads();
}

template <typename T, int... D>
WP_FN void adstack_pop_tile(adstack_t* st, tile_t<T, D...>& t) {
  constexpr int S = tile_t<T, D...>::SIZE;
  const int tx = (int)threadIdx.x;
  if (tx < S) {
    int i = tx + ((S - 1 - tx) / WP_TILE_BLOCK_DIM) * WP_TILE_BLOCK_DIM;
    for (; i >= 0; i -= WP_TILE_BLOCK_DIM) t.data[i] = adstack_pop<T>(st);
  }
  __syncthreads();
}

// ---- Scans ---------------------------------------------------------------------------------

namespace tile_detail {

/// `adj[e] += sum of seed(k) for k >= e`, as the forward's inclusive scan (wp_tile.h's
/// scan_inclusive, warp-core's scan_with) of the reversed seed: lane l runs through chunk l of
/// the reversed order for its total, thread 0 folds the totals into prefixes, and lane l runs
/// through its chunk again adding prefix + running value.
template <typename T, int N, typename Seed>
WP_FN void add_suffix_sums(const tile_t<T, N>& adj, Seed seed) {
  constexpr int C = (N + WP_TILE_BLOCK_DIM - 1) / WP_TILE_BLOCK_DIM;
  constexpr int CHUNKS = (N + C - 1) / C;
  WP_TILE_SHARED_ALIGNED T totals[CHUNKS];
  const int l = (int)threadIdx.x;
  const int start = l * C;
  const int end = start + C < N ? start + C : N;
  if (l < CHUNKS) {
    T r = seed(N - 1 - start);
    for (int p = start + 1; p < end; ++p) r = add_op{}(r, seed(N - 1 - p));
    totals[l] = r;
  }
  __syncthreads();
  if (l == 0) {
    for (int k = 1; k < CHUNKS; ++k) totals[k] = add_op{}(totals[k - 1], totals[k]);
  }
  __syncthreads();
  if (l < CHUNKS) {
    T r = seed(N - 1 - start);
    for (int p = start; p < end; ++p) {
      if (p > start) r = add_op{}(r, seed(N - 1 - p));
      adj_accum(adj.data[N - 1 - p], l > 0 ? add_op{}(totals[l - 1], r) : r);
    }
  }
  __syncthreads();
}

/// Each `r[j]` to the element output j of a max (`Max`) or min scan came from: the first
/// extremum of t[0..=j], a NaN losing to a number (t[0] while all are NaN); thread 0, j
/// ascending.
template <bool Max, typename T, int N>
WP_FN void adj_scan_extreme(const tile_t<T, N>& t, const tile_t<T, N>& adj_t, const tile_t<T, N>& r) {
  if (threadIdx.x == 0) {
    int m = 0;
    for (int j = 0; j < N; ++j) {
      const T v = t.data[j], old = t.data[m];
      const bool better = Max ? v > old : v < old;
      if (better || (old != old && !(v != v))) m = j;
      adj_accum(adj_t.data[m], r.data[j]);
    }
  }
  __syncthreads();
}

}  // namespace tile_detail

/// `tile_scan_inclusive(t)`: `adj_t[i] += sum of r[j] for j >= i`.
template <typename T, int N>
WP_FN void adj_tile_scan_inclusive(const tile_t<T, N>&, const tile_t<T, N>& adj_t, const tile_t<T, N>& r) {
  const T* g = r.data;
  tile_detail::add_suffix_sums(adj_t, [g](int k) { return g[k]; });
}

/// `tile_scan_exclusive(t)`: `adj_t[i] += sum of r[j] for j > i`.
template <typename T, int N>
WP_FN void adj_tile_scan_exclusive(const tile_t<T, N>&, const tile_t<T, N>& adj_t, const tile_t<T, N>& r) {
  const T* g = r.data;
  tile_detail::add_suffix_sums(adj_t, [g](int k) { return k + 1 < N ? g[k + 1] : T{}; });
}

/// `tile_scan_max_inclusive(t)`: each r[j] to the first maximum of t[0..=j].
template <typename T, int N>
WP_FN void adj_tile_scan_max_inclusive(const tile_t<T, N>& t, const tile_t<T, N>& adj_t,
                                       const tile_t<T, N>& r) {
  tile_detail::adj_scan_extreme<true>(t, adj_t, r);
}

/// `tile_scan_min_inclusive(t)`: each r[j] to the first minimum of t[0..=j].
template <typename T, int N>
WP_FN void adj_tile_scan_min_inclusive(const tile_t<T, N>& t, const tile_t<T, N>& adj_t,
                                       const tile_t<T, N>& r) {
  tile_detail::adj_scan_extreme<false>(t, adj_t, r);
}

// ---- Windows: tile_view and the in-place forms (warp-core's tile::adjoint, "Windows") ------
//
// The replayed forward checked each window (and faulted when it did not fit); here a window
// that does not fit moves nothing. The seed `r` of an in-place form is a view of `adj_d`'s own
// slot (one adjoint for `d` before and after): each thread reads an element of it before it
// clears that same element, so the two never race.

namespace tile_detail {

/// The starts of an `(m0, m1)` window at `(o0, o1)` in a tile of shape `(A, B)`; `false` when
/// it does not fit.
template <int A, int B, typename O0, typename O1>
WP_FN bool window_fits2(O0 o0, O1 o1, int m0, int m1, i64* s0, i64* s1) {
  i64 bad = 0;
  return window_start(o0, m0, A, s0, &bad) && window_start(o1, m1, B, s1, &bad);
}

/// The adjoint of an in-place form over the window's elements (`p` the destination's index,
/// `e` the source's): `adj_s[e] += r[p]` (`-=` for the sub); for `tile_assign`, `adj_d[p] = 0`.
template <int Op, typename T>
WP_FN void adj_window_elem(T* adj_d, T* adj_s, const T* r, i64 p, int e) {
  const T g = r[p];
  if constexpr (Op == WINDOW_SUB) adj_s[e] -= g;
  else adj_s[e] += g;
  if constexpr (Op == WINDOW_ASSIGN) adj_d[p] = T{};
}

template <int Op, typename T, int A, int M, typename O>
WP_FN void adj_window1(O o, const tile_t<T, A>& adj_d, const tile_t<T, M>& adj_s, const tile_t<T, A>& r) {
  i64 s = 0, bad = 0;
  if (window_start(o, M, A, &s, &bad))
    for (int i = (int)threadIdx.x; i < M; i += WP_TILE_BLOCK_DIM)
      adj_window_elem<Op>(adj_d.data, adj_s.data, r.data, s + i, i);
  __syncthreads();
}

template <int Op, typename T, int A, int B, int M, int N, typename O0, typename O1>
WP_FN void adj_window2(O0 o0, O1 o1, const tile_t<T, A, B>& adj_d, const tile_t<T, M, N>& adj_s,
                       const tile_t<T, A, B>& r) {
  i64 s0 = 0, s1 = 0;
  if (window_fits2<A, B>(o0, o1, M, N, &s0, &s1))
    for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM)
      adj_window_elem<Op>(adj_d.data, adj_s.data, r.data, (s0 + e / N) * B + s1 + e % N, e);
  __syncthreads();
}

}  // namespace tile_detail

/// `v = tile_view(t, o)` of a 1-D tile: `adj_t[o + i] += r[i]`.
template <typename T, int A, int M, typename O>
WP_FN void adj_tile_view1(const tile_t<T, A>&, O o, const tile_t<T, A>& adj_t, O&,
                          const tile_t<T, M>& r, ctx_t*) {
  i64 s = 0, bad = 0;
  if (tile_detail::window_start(o, M, A, &s, &bad))
    for (int i = (int)threadIdx.x; i < M; i += WP_TILE_BLOCK_DIM) adj_t.data[s + i] += r.data[i];
  __syncthreads();
}

/// `v = tile_view(t, i)` of a 2-D tile (row `i`): `adj_t[i][j] += r[j]`.
template <typename T, int A, int B, typename O>
WP_FN void adj_tile_view1(const tile_t<T, A, B>&, O o, const tile_t<T, A, B>& adj_t, O&,
                          const tile_t<T, B>& r, ctx_t*) {
  i64 s = 0, bad = 0;
  if (tile_detail::window_start(o, 1, A, &s, &bad))
    for (int j = (int)threadIdx.x; j < B; j += WP_TILE_BLOCK_DIM) adj_t.data[s * B + j] += r.data[j];
  __syncthreads();
}

/// `v = tile_view(t, (o0, o1))`: `adj_t[o0 + i][o1 + j] += r[i][j]`.
template <typename T, int A, int B, int M, int N, typename O0, typename O1>
WP_FN void adj_tile_view2(const tile_t<T, A, B>&, O0 o0, O1 o1, const tile_t<T, A, B>& adj_t, O0&,
                          O1&, const tile_t<T, M, N>& r, ctx_t*) {
  i64 s0 = 0, s1 = 0;
  if (tile_detail::window_fits2<A, B>(o0, o1, M, N, &s0, &s1))
    for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM)
      adj_t.data[(s0 + e / N) * B + s1 + e % N] += r.data[e];
  __syncthreads();
}

#define WP_ADJ_TILE_WINDOW(NAME, OP)                                                              \
  template <typename T, int A, int M, typename O>                                                 \
  WP_FN void NAME##1(const tile_t<T, A>&, const tile_t<T, M>&, O o, const tile_t<T, A>& adj_d,     \
                     const tile_t<T, M>& adj_s, O&, const tile_t<T, A>& r, ctx_t*) {              \
    tile_detail::adj_window1<OP>(o, adj_d, adj_s, r);                                             \
  }                                                                                               \
  template <typename T, int A, int B, int M, int N, typename O0, typename O1>                     \
  WP_FN void NAME##2(const tile_t<T, A, B>&, const tile_t<T, M, N>&, O0 o0, O1 o1,                 \
                     const tile_t<T, A, B>& adj_d, const tile_t<T, M, N>& adj_s, O0&, O1&,         \
                     const tile_t<T, A, B>& r, ctx_t*) {                                          \
    tile_detail::adj_window2<OP>(o0, o1, adj_d, adj_s, r);                                        \
  }

/// `tile_assign(&mut d, s, o)`: `adj_s += r` over the window, which is cleared in `adj_d`.
WP_ADJ_TILE_WINDOW(adj_tile_assign, WINDOW_ASSIGN)
/// `tile_add_inplace(&mut d, s, o)`: `adj_s += r` over the window; `adj_d` passes through.
WP_ADJ_TILE_WINDOW(adj_tile_add_inplace, WINDOW_ADD)
/// `tile_sub_inplace(&mut d, s, o)`: `adj_s -= r` over the window; `adj_d` passes through.
WP_ADJ_TILE_WINDOW(adj_tile_sub_inplace, WINDOW_SUB)
#undef WP_ADJ_TILE_WINDOW

}  // namespace wp

// wp_tile_adjoint_driver.cpp: runs wp_adjoint_tile.h's adjoints on the host, one block under the
// emulator (tests/cuda_tile_adjoint_host.rs writes the script, compiles this file for several
// block sizes with -DWP_TILE_BLOCK_DIM=<bd>, and compares the output with warp-core's
// tile::adjoint functions, bit for bit).
//
// Script (argv[1]), one command per line:
//   buf K HEX                   buffer K (0..15): raw bytes ('-': none); a kernel copies its
//                               input tiles from buffers (each thread its elements) and the
//                               arrays below live in them
//   arr KIND SLOT N0 [N1..] K   array argument SLOT (0: the value, 1: its gradient) of KIND
//                               (f1 f2 f3 f4 d1 d2: f32 / f64, of the rank its digit says)
//                               over buffer K,
//                               row-major and contiguous; K '-' for no data (a null gradient);
//                               bound at each run, so a later `buf K` is what it sees
//   off O0 O1 O2 O3             the i64 offsets (or a count) the next run uses
//   run KERNEL                  one block of WP_TILE_BLOCK_DIM threads; prints `out HEX` (what
//                               the kernel wrote) and `fault KIND` or `nofault`
//   dump K                      prints `dump HEX`: buffer K's bytes now
#include "wp_prim_emu.h"
#include "wp_adjoint_tile.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>

using wp::f32;
using wp::f64;
using wp::i64;
using wp::tile_t;

constexpr int NBUF = 16;
constexpr int BD = WP_TILE_BLOCK_DIM;

struct args_t {
  unsigned char* b[NBUF];
  size_t n[NBUF];  // bytes
  wp::array_t<f32, 1> f1[2];
  wp::array_t<f32, 2> f2[2];
  wp::array_t<f32, 3> f3[2];
  wp::array_t<f32, 4> f4[2];
  wp::array_t<f64, 1> d1[2];
  wp::array_t<f64, 2> d2[2];
  i64 o[4];
  unsigned char* out;
  size_t* out_len;
  wp::fault_t* fault;
  wp::u32* flag;
};

template <typename T, int N>
static const wp::array_t<T, N>* arrays(const args_t& a);
template <>
const wp::array_t<f32, 1>* arrays<f32, 1>(const args_t& a) { return a.f1; }
template <>
const wp::array_t<f32, 2>* arrays<f32, 2>(const args_t& a) { return a.f2; }
template <>
const wp::array_t<f64, 1>* arrays<f64, 1>(const args_t& a) { return a.d1; }
template <>
const wp::array_t<f64, 2>* arrays<f64, 2>(const args_t& a) { return a.d2; }

/// A block's shared memory (static storage: the emulator runs one block at a time), carved
/// from the start in the same order in every thread, as the emitter's constant offsets are.
alignas(16) static unsigned char smem[128 * 1024];

template <typename Tile>
Tile slot_at(size_t& at) {
  at = (at + 15) & ~(size_t)15;
  Tile t(smem + at);
  at += Tile::BYTES;
  if (at > sizeof(smem)) std::abort();
  return t;
}
#define SLOTS_BEGIN() size_t smem_at_ = 0
#define SLOT(...) slot_at<__VA_ARGS__>(smem_at_)

[[noreturn]] static void bad(const char* what, int k) {
  std::fprintf(stderr, "driver: %s (buffer %d)\n", what, k);
  std::abort();
}

/// Element `i` of buffer `k` read as a T.
template <typename T>
static T scal(const args_t& a, int k, size_t i) {
  if ((i + 1) * sizeof(T) > a.n[k]) bad("buffer too short for a scalar", k);
  T v;
  std::memcpy(&v, a.b[k] + i * sizeof(T), sizeof(T));
  return v;
}

/// `t` from the first bytes of buffer `k` (each thread copies its elements, block-strided, as
/// a tile operation would), then a barrier.
template <typename Tile>
static void fill(const args_t& a, int k, const Tile& t) {
  typedef typename Tile::elem_t T;
  if (a.n[k] < Tile::BYTES) bad("buffer too short for a tile", k);
  for (int e = (int)threadIdx.x; e < Tile::SIZE; e += BD)
    std::memcpy(&t.data[e], a.b[k] + (size_t)e * sizeof(T), sizeof(T));
  __syncthreads();
}

/// Thread 0 appends `t`'s bytes to the output; the block waits for it before anything
/// overwrites the slot.
template <typename Tile>
static void dump(const args_t& a, const Tile& t) {
  if (threadIdx.x == 0) {
    std::memcpy(a.out + *a.out_len, t.data, Tile::BYTES);
    *a.out_len += Tile::BYTES;
  }
  __syncthreads();
}

/// A value every thread holds (a uniform scalar's adjoint): aborts unless all agree, then
/// thread 0 appends it.
template <typename T>
static void dump_uniform(const args_t& a, T v) {
  static T seen[BD];
  seen[threadIdx.x] = v;
  __syncthreads();
  if (threadIdx.x == 0) {
    for (int l = 1; l < BD; ++l)
      if (std::memcmp(&seen[l], &v, sizeof(T)) != 0) {
        std::fprintf(stderr, "driver: thread %d's uniform value differs from thread 0's\n", l);
        std::abort();
      }
    std::memcpy(a.out + *a.out_len, &v, sizeof(T));
    *a.out_len += sizeof(T);
  }
  __syncthreads();
}

/// Each thread's `v`, in thread order.
template <typename T>
static void dump_lanes(const args_t& a, T v) {
  const size_t base = *a.out_len;
  std::memcpy(a.out + base + (size_t)threadIdx.x * sizeof(T), &v, sizeof(T));
  __syncthreads();
  if (threadIdx.x == 0) *a.out_len = base + (size_t)BD * sizeof(T);
  __syncthreads();
}

// ---- Loads and stores: array 0 the value, array 1 its gradient ----------------------------

/// adj_tile_load1 of a 37-element tile at o0, its adjoint from buffer 2.
template <typename T>
static void k_load1(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto r = SLOT(tile_t<T, 37>);
  fill(a, 2, r);
  const wp::array_t<T, 1>* arr = arrays<T, 1>(a);
  i64 adj_o = 0;
  wp::adj_tile_load1(arr[0], a.o[0], arr[1], adj_o, r, &c);
}

/// adj_tile_load2 of a 5 x 7 tile at (o0, o1) (i32 column offset), adjoint from buffer 2.
template <typename T>
static void k_load2(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto r = SLOT(tile_t<T, 5, 7>);
  fill(a, 2, r);
  const wp::array_t<T, 2>* arr = arrays<T, 2>(a);
  i64 adj_o0 = 0;
  wp::i32 o1 = (wp::i32)a.o[1], adj_o1 = 0;
  wp::adj_tile_load2(arr[0], a.o[0], o1, arr[1], adj_o0, adj_o1, r, &c);
}

/// adj_tile_load3 of a 3 x 4 x 5 f32 tile at (o0, o1, o2) (the last offset an i32), adjoint
/// from buffer 2.
static void k_load3(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto r = SLOT(tile_t<f32, 3, 4, 5>);
  fill(a, 2, r);
  i64 adj_o0 = 0, adj_o1 = 0;
  wp::i32 o2 = (wp::i32)a.o[2], adj_o2 = 0;
  wp::adj_tile_load3(a.f3[0], a.o[0], a.o[1], o2, a.f3[1], adj_o0, adj_o1, adj_o2, r, &c);
}

/// adj_tile_load4 of a 2 x 3 x 2 x 3 f32 tile at (o0, o1, o2, o3), adjoint from buffer 2.
static void k_load4(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto r = SLOT(tile_t<f32, 2, 3, 2, 3>);
  fill(a, 2, r);
  i64 z[4] = {0, 0, 0, 0};
  wp::adj_tile_load4(a.f4[0], a.o[0], a.o[1], a.o[2], a.o[3], a.f4[1], z[0], z[1], z[2], z[3], r,
                     &c);
}

/// adj_tile_store3 of a 3 x 4 x 5 f32 tile at (o0, o1, o2): the tile's adjoint starts from
/// buffer 2 (the tile from buffer 3); outputs the tile's adjoint.
static void k_store3(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 3, 4, 5>);
  auto at = SLOT(tile_t<f32, 3, 4, 5>);
  fill(a, 2, at);
  fill(a, 3, t);
  i64 z[3] = {0, 0, 0};
  wp::adj_tile_store3(a.f3[0], t, a.o[0], a.o[1], a.o[2], a.f3[1], at, z[0], z[1], z[2],
                      wp::unit_t{}, &c);
  dump(a, at);
}

/// adj_tile_store4 of a 2 x 3 x 2 x 3 f32 tile at (o0, o1, o2, o3), as k_store3.
static void k_store4(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 2, 3, 2, 3>);
  auto at = SLOT(tile_t<f32, 2, 3, 2, 3>);
  fill(a, 2, at);
  fill(a, 3, t);
  i64 z[4] = {0, 0, 0, 0};
  wp::adj_tile_store4(a.f4[0], t, a.o[0], a.o[1], a.o[2], a.o[3], a.f4[1], at, z[0], z[1], z[2],
                      z[3], wp::unit_t{}, &c);
  dump(a, at);
}

/// adj_tile_extract3 / adj_tile_extract4: thread l reads element l mod SIZE of a 2 x 3 x 4 and
/// a 2 x 1 x 3 x 2 tile (from buffer 0) with adjoint 1 + l / 8 (exact sums in any order); the
/// adjoints start at zero. Outputs both adjoints.
static void k_extract_nd(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t3 = SLOT(tile_t<f32, 2, 3, 4>);
  auto a3 = SLOT(tile_t<f32, 2, 3, 4>);
  auto t4 = SLOT(tile_t<f32, 2, 1, 3, 2>);
  auto a4 = SLOT(tile_t<f32, 2, 1, 3, 2>);
  fill(a, 0, t3);
  fill(a, 0, t4);
  wp::tile_zeros(a3);
  wp::tile_zeros(a4);
  const int l = (int)threadIdx.x;
  const f32 r = 1.0f + (f32)(l / 8);
  const int e3 = l % 24, e4 = l % 12;
  int i = e3 / 12, j = (e3 / 4) % 3, k = e3 % 4;
  wp::adj_tile_extract3(t3, i, j, k, a3, i, j, k, r, &c);
  __syncthreads();
  int p = e4 / 6, q = 0, u = (e4 / 2) % 3, v = e4 % 2;
  wp::adj_tile_extract4(t4, p, q, u, v, a4, p, q, u, v, r, &c);
  __syncthreads();
  dump(a, a3);
  dump(a, a4);
}

/// adj_tile_store1 of a 37-element tile at o0: the tile's adjoint starts from buffer 2
/// (the tile itself from buffer 3); outputs the tile's adjoint.
template <typename T>
static void k_store1(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<T, 37>);
  auto at = SLOT(tile_t<T, 37>);
  fill(a, 2, at);
  fill(a, 3, t);
  const wp::array_t<T, 1>* arr = arrays<T, 1>(a);
  i64 adj_o = 0;
  wp::adj_tile_store1(arr[0], t, a.o[0], arr[1], at, adj_o, wp::unit_t{}, &c);
  dump(a, at);
}

/// adj_tile_store2 of a 5 x 7 tile at (o0, o1), as k_store1.
template <typename T>
static void k_store2(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<T, 5, 7>);
  auto at = SLOT(tile_t<T, 5, 7>);
  fill(a, 2, at);
  fill(a, 3, t);
  const wp::array_t<T, 2>* arr = arrays<T, 2>(a);
  i64 adj_o0 = 0, adj_o1 = 0;
  wp::adj_tile_store2(arr[0], t, a.o[0], a.o[1], arr[1], at, adj_o0, adj_o1, wp::unit_t{}, &c);
  dump(a, at);
}

// ---- Elementwise -----------------------------------------------------------------------------

/// Buffers: 0 a, 1 b, 2 r, 3 adj_a's start, 4 adj_b's, 5 [s, adj_s's start]. For add, sub,
/// mul, div: _tt (adj_a, adj_b), _ts (adj_a, adj_s), _st (adj_b, adj_s); then neg (adj_a) and
/// accum (adj_a += r). Every adjoint starts afresh from its buffer.
template <typename T, int... D>
static void k_elem(args_t a) {
  typedef tile_t<T, D...> X;
  SLOTS_BEGIN();
  auto x = SLOT(X);
  auto y = SLOT(X);
  auto r = SLOT(X);
  auto ax = SLOT(X);
  auto ay = SLOT(X);
  fill(a, 0, x);
  fill(a, 1, y);
  fill(a, 2, r);
  const T s = scal<T>(a, 5, 0), s0 = scal<T>(a, 5, 1);
#define CASE(OP)                                 \
  fill(a, 3, ax);                                \
  fill(a, 4, ay);                                \
  wp::adj_tile_##OP##_tt(x, y, ax, ay, r);       \
  dump(a, ax);                                   \
  dump(a, ay);                                   \
  fill(a, 3, ax);                                \
  {                                              \
    T as = s0;                                   \
    wp::adj_tile_##OP##_ts(x, s, ax, as, r);     \
    dump(a, ax);                                 \
    dump_uniform(a, as);                         \
  }                                              \
  fill(a, 4, ay);                                \
  {                                              \
    T as = s0;                                   \
    wp::adj_tile_##OP##_st(s, y, as, ay, r);     \
    dump(a, ay);                                 \
    dump_uniform(a, as);                         \
  }
  CASE(add)
  CASE(sub)
  CASE(mul)
  CASE(div)
#undef CASE
  fill(a, 3, ax);
  wp::adj_tile_neg(x, ax, r);
  dump(a, ax);
  fill(a, 3, ax);
  wp::adj_tile_accum(ax, r);
  dump(a, ax);
}

/// Buffers as k_elem (45 elements). map1 of `x / 3` (adj_div), map2 of `x * y` (adj_mul) and
/// of `x / y` (adj_div).
template <typename T>
static void k_map(args_t a) {
  typedef tile_t<T, 45> X;
  SLOTS_BEGIN();
  auto x = SLOT(X);
  auto y = SLOT(X);
  auto r = SLOT(X);
  auto ax = SLOT(X);
  auto ay = SLOT(X);
  fill(a, 0, x);
  fill(a, 1, y);
  fill(a, 2, r);
  fill(a, 3, ax);
  wp::adj_tile_map1(x, ax, r, [](T v, T& av, T g) {
    T unused = T(0);
    wp::adj_div(v, T(3), av, unused, g);
  });
  dump(a, ax);
  fill(a, 3, ax);
  fill(a, 4, ay);
  wp::adj_tile_map2(x, y, ax, ay, r,
                    [](T u, T v, T& au, T& av, T g) { wp::adj_mul(u, v, au, av, g); });
  dump(a, ax);
  dump(a, ay);
  fill(a, 3, ax);
  fill(a, 4, ay);
  wp::adj_tile_map2(x, y, ax, ay, r,
                    [](T u, T v, T& au, T& av, T g) { wp::adj_div(u, v, au, av, g); });
  dump(a, ax);
  dump(a, ay);
}

// ---- Reductions ------------------------------------------------------------------------------

/// Buffers: 0 t, 1 r (one element), 2 adj_t's start. Outputs adj_t after sum, min, max.
template <typename T, int... D>
static void k_red(args_t a) {
  typedef tile_t<T, D...> X;
  SLOTS_BEGIN();
  auto t = SLOT(X);
  auto at = SLOT(X);
  auto r = SLOT(tile_t<T, 1>);
  fill(a, 0, t);
  fill(a, 1, r);
  fill(a, 2, at);
  wp::adj_tile_sum(t, at, r);
  dump(a, at);
  fill(a, 2, at);
  wp::adj_tile_min(t, at, r);
  dump(a, at);
  fill(a, 2, at);
  wp::adj_tile_max(t, at, r);
  dump(a, at);
}

// ---- Shapes ----------------------------------------------------------------------------------

/// Buffers: 0 a (7 x 5), 1 r (5 x 7), 2 adj_a's start.
template <typename T>
static void k_transpose(args_t a) {
  SLOTS_BEGIN();
  auto x = SLOT(tile_t<T, 7, 5>);
  auto ax = SLOT(tile_t<T, 7, 5>);
  auto r = SLOT(tile_t<T, 5, 7>);
  fill(a, 0, x);
  fill(a, 1, r);
  fill(a, 2, ax);
  wp::adj_tile_transpose(x, ax, r);
  dump(a, ax);
}

/// Buffers: 0 r of 40 (rank-1 targets), 1 r of 13 x 11 (rank-2 targets), 2 the adjoints'
/// start (each case takes its first elements). Outputs each case's adjoint.
template <typename T>
static void k_bcast(args_t a) {
  SLOTS_BEGIN();
  auto r1 = SLOT(tile_t<T, 40>);
  auto r2 = SLOT(tile_t<T, 13, 11>);
  fill(a, 0, r1);
  fill(a, 1, r2);
  {
    auto s = SLOT(tile_t<T, 1>);
    fill(a, 2, s);
    wp::adj_tile_broadcast11(s, s, r1);
    dump(a, s);
  }
  {
    auto s = SLOT(tile_t<T, 40>);
    fill(a, 2, s);
    wp::adj_tile_broadcast11(s, s, r1);
    dump(a, s);
  }
  {
    auto s = SLOT(tile_t<T, 11>);
    fill(a, 2, s);
    wp::adj_tile_broadcast12(s, s, r2);
    dump(a, s);
  }
  {
    auto s = SLOT(tile_t<T, 1>);
    fill(a, 2, s);
    wp::adj_tile_broadcast12(s, s, r2);
    dump(a, s);
  }
  {
    auto s = SLOT(tile_t<T, 1, 11>);
    fill(a, 2, s);
    wp::adj_tile_broadcast22(s, s, r2);
    dump(a, s);
  }
  {
    auto s = SLOT(tile_t<T, 13, 1>);
    fill(a, 2, s);
    wp::adj_tile_broadcast22(s, s, r2);
    dump(a, s);
  }
  {
    auto s = SLOT(tile_t<T, 1, 1>);
    fill(a, 2, s);
    wp::adj_tile_broadcast22(s, s, r2);
    dump(a, s);
  }
  {
    auto s = SLOT(tile_t<T, 13, 11>);
    fill(a, 2, s);
    wp::adj_tile_broadcast22(s, s, r2);
    dump(a, s);
  }
}

// ---- Matmul ----------------------------------------------------------------------------------

/// Buffers: 0 a (M x K), 1 b (K x N), 2 r (M x N), 3 adj_a's start, 4 adj_b's.
template <typename T, int M, int K, int N>
static void k_matmul(args_t a) {
  SLOTS_BEGIN();
  auto x = SLOT(tile_t<T, M, K>);
  auto y = SLOT(tile_t<T, K, N>);
  auto r = SLOT(tile_t<T, M, N>);
  auto ax = SLOT(tile_t<T, M, K>);
  auto ay = SLOT(tile_t<T, K, N>);
  fill(a, 0, x);
  fill(a, 1, y);
  fill(a, 2, r);
  fill(a, 3, ax);
  fill(a, 4, ay);
  wp::adj_tile_matmul(x, y, ax, ay, r);
  dump(a, ax);
  dump(a, ay);
}

/// The f16 matmul's adjoint: a, b, adj_a, adj_b f16, `r` of type R (f16: the returning form's
/// seed; f32: the accumulating form's). Buffers as k_matmul.
template <typename R, int M, int K, int N>
static void k_matmul_h(args_t a) {
  SLOTS_BEGIN();
  auto x = SLOT(tile_t<wp::f16, M, K>);
  auto y = SLOT(tile_t<wp::f16, K, N>);
  auto r = SLOT(tile_t<R, M, N>);
  auto ax = SLOT(tile_t<wp::f16, M, K>);
  auto ay = SLOT(tile_t<wp::f16, K, N>);
  fill(a, 0, x);
  fill(a, 1, y);
  fill(a, 2, r);
  fill(a, 3, ax);
  fill(a, 4, ay);
  wp::adj_tile_matmul(x, y, ax, ay, r);
  dump(a, ax);
  dump(a, ay);
}

// ---- Atomic add: array 0 the value, array 1 its gradient ------------------------------------

/// adj_tile_atomic_add1 of a 37-element tile at o0: the tile's adjoint starts from buffer 2,
/// the tile from buffer 3, the old values' adjoint from buffer 4; outputs the tile's adjoint.
template <typename T>
static void k_atomic1(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<T, 37>);
  auto at = SLOT(tile_t<T, 37>);
  auto r = SLOT(tile_t<T, 37>);
  fill(a, 2, at);
  fill(a, 3, t);
  fill(a, 4, r);
  const wp::array_t<T, 1>* arr = arrays<T, 1>(a);
  i64 adj_o = 0;
  wp::adj_tile_atomic_add1(arr[0], t, a.o[0], arr[1], at, adj_o, r, &c);
  dump(a, at);
}

/// adj_tile_atomic_add2 of a 5 x 7 tile at (o0, o1) (i32 column offset), as k_atomic1.
template <typename T>
static void k_atomic2(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<T, 5, 7>);
  auto at = SLOT(tile_t<T, 5, 7>);
  auto r = SLOT(tile_t<T, 5, 7>);
  fill(a, 2, at);
  fill(a, 3, t);
  fill(a, 4, r);
  const wp::array_t<T, 2>* arr = arrays<T, 2>(a);
  i64 adj_o0 = 0;
  wp::i32 o1 = (wp::i32)a.o[1], adj_o1 = 0;
  wp::adj_tile_atomic_add2(arr[0], t, a.o[0], o1, arr[1], at, adj_o0, adj_o1, r, &c);
  dump(a, at);
}

// ---- Threads and elements --------------------------------------------------------------------

/// Buffers: 0 r (N), 1 each thread's adj_x start (by thread index), 2 adj_t's start (N), 3 each
/// thread's adjoint of untile's result. Outputs every thread's adj_x after adj_tile_lanes, then
/// adj_t after adj_untile.
template <typename T, int N>
static void k_lanes(args_t a) {
  SLOTS_BEGIN();
  auto r = SLOT(tile_t<T, N>);
  auto at = SLOT(tile_t<T, N>);
  fill(a, 0, r);
  T x = scal<T>(a, 1, threadIdx.x);
  wp::adj_tile_lanes(x, r);
  dump_lanes(a, x);
  fill(a, 2, at);
  wp::adj_untile(at, scal<T>(a, 3, threadIdx.x));
  dump(a, at);
}

/// Buffers: 0 t (40), 1 adj_t's start, 2 the threads' indices (i64 by thread), 3 the threads'
/// adjoints r. Threads below o0 call adj_tile_extract1; outputs adj_t.
template <typename T>
static void k_extract1(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<T, 40>);
  auto at = SLOT(tile_t<T, 40>);
  fill(a, 0, t);
  fill(a, 1, at);
  if ((i64)threadIdx.x < a.o[0]) {
    const i64 i = scal<i64>(a, 2, threadIdx.x);
    i64 adj_i = 0;
    wp::adj_tile_extract1(t, i, at, adj_i, scal<T>(a, 3, threadIdx.x), &c);
  }
  __syncthreads();
  dump(a, at);
}

/// As k_extract1 for a 5 x 7 tile: buffer 2 holds (i, j) pairs, j as i32.
template <typename T>
static void k_extract2(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<T, 5, 7>);
  auto at = SLOT(tile_t<T, 5, 7>);
  fill(a, 0, t);
  fill(a, 1, at);
  if ((i64)threadIdx.x < a.o[0]) {
    const i64 i = scal<i64>(a, 2, 2 * threadIdx.x);
    const wp::i32 j = (wp::i32)scal<i64>(a, 2, 2 * threadIdx.x + 1);
    i64 adj_i = 0;
    wp::i32 adj_j = 0;
    wp::adj_tile_extract2(t, i, j, at, adj_i, adj_j, scal<T>(a, 3, threadIdx.x), &c);
  }
  __syncthreads();
  dump(a, at);
}

namespace {

struct buffer {
  std::vector<unsigned long long> words;  // 8-byte aligned storage
  size_t bytes = 0;
  unsigned char* data() { return reinterpret_cast<unsigned char*>(words.data()); }
};

int hexval(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return c - 'A' + 10;
}

void unhex(const std::string& hex, buffer& b) {
  b.bytes = hex == "-" ? 0 : hex.size() / 2;
  b.words.assign(b.bytes / 8 + 1, 0);
  for (size_t k = 0; k < b.bytes; ++k)
    b.data()[k] = (unsigned char)(hexval(hex[2 * k]) * 16 + hexval(hex[2 * k + 1]));
}

void print_hex(const char* tag, const unsigned char* p, size_t n) {
  std::printf("%s ", tag);
  for (size_t k = 0; k < n; ++k) std::printf("%02x", p[k]);
  std::printf("\n");
}

/// Points array argument `arr` at `data` (null: no gradient) with the given shape (row-major,
/// contiguous).
template <typename T, int N>
void bind(wp::array_t<T, N>& arr, unsigned char* data, const i64* shape, int index) {
  arr.data = reinterpret_cast<T*>(data);
  i64 stride = (i64)sizeof(T);
  for (int k = N - 1; k >= 0; --k) {
    arr.shape[k] = shape[k];
    arr.strides[k] = stride;
    stride *= shape[k];
  }
  arr.arg = index;
  arr.pad = 0;
}

int run(const char* path) {
  std::ifstream in(path);
  if (!in) {
    std::fprintf(stderr, "cannot open %s\n", path);
    return 2;
  }
  buffer bufs[NBUF];
  struct binding {
    std::string kind;
    int slot = 0;
    i64 shape[4] = {0, 1, 1, 1};
    int buf = -1;
  };
  std::map<std::string, binding> binds;
  std::vector<unsigned char> out(256 * 1024);
  size_t out_len = 0;
  wp::fault_t fault{};
  wp::u32 flag[2] = {0, 0};
  args_t a{};
  a.out = out.data();
  a.out_len = &out_len;
  a.fault = &fault;
  a.flag = &flag[0];
  std::map<std::string, void (*)(args_t)> kernels;
#define BOTH(NAME, ...)                                   \
  kernels[std::string(NAME) + "_f32"] = __VA_ARGS__<f32>; \
  kernels[std::string(NAME) + "_f64"] = __VA_ARGS__<f64>;
  BOTH("load1", k_load1)
  BOTH("load2", k_load2)
  BOTH("store1", k_store1)
  BOTH("store2", k_store2)
  BOTH("map", k_map)
  BOTH("transpose", k_transpose)
  BOTH("bcast", k_bcast)
  BOTH("extract1", k_extract1)
  BOTH("extract2", k_extract2)
#undef BOTH
  kernels["load3_f32"] = k_load3;
  kernels["load4_f32"] = k_load4;
  kernels["store3_f32"] = k_store3;
  kernels["store4_f32"] = k_store4;
  kernels["extract_nd_f32"] = k_extract_nd;
  kernels["elem_f32_300"] = k_elem<f32, 300>;
  kernels["elem_f64_300"] = k_elem<f64, 300>;
  kernels["elem_f32_13x11"] = k_elem<f32, 13, 11>;
  kernels["elem_f64_13x11"] = k_elem<f64, 13, 11>;
  kernels["red_f32_300"] = k_red<f32, 300>;
  kernels["red_f64_300"] = k_red<f64, 300>;
  kernels["red_f32_13x11"] = k_red<f32, 13, 11>;
  kernels["red_f64_13x11"] = k_red<f64, 13, 11>;
  kernels["red_f32_5"] = k_red<f32, 5>;
  kernels["red_f64_5"] = k_red<f64, 5>;
  kernels["lanes_f32_40"] = k_lanes<f32, 40>;
  kernels["lanes_f64_40"] = k_lanes<f64, 40>;
  kernels["lanes_f32_300"] = k_lanes<f32, 300>;
  kernels["lanes_f64_300"] = k_lanes<f64, 300>;
  // The matmul shapes (tests/cuda_tile_adjoint_host.rs names them mm_T_MxKxN).
#define MM(T, M, K, N) kernels["mm_" #T "_" #M "x" #K "x" #N] = k_matmul<T, M, K, N>;
  MM(f32, 7, 13, 5)
  MM(f32, 16, 8, 6)
  MM(f32, 1, 1, 1)
  MM(f32, 3, 33, 2)
  MM(f64, 7, 13, 5)
  MM(f64, 16, 8, 6)
  MM(f64, 1, 1, 1)
  MM(f64, 3, 33, 2)
#undef MM
  // The f16 matmul's adjoint (mmh_R_MxKxN, R the seed's type).
#define MMH(R, M, K, N) kernels["mmh_" #R "_" #M "x" #K "x" #N] = k_matmul_h<wp::R, M, K, N>;
  MMH(f16, 7, 13, 5)
  MMH(f16, 16, 16, 8)
  MMH(f32, 7, 13, 5)
  MMH(f32, 16, 16, 8)
#undef MMH
  kernels["atomic1_f32"] = k_atomic1<f32>;
  kernels["atomic1_f64"] = k_atomic1<f64>;
  kernels["atomic2_f32"] = k_atomic2<f32>;
  kernels["atomic2_f64"] = k_atomic2<f64>;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    std::string cmd;
    ss >> cmd;
    if (cmd.empty()) continue;
    if (cmd == "buf") {
      int k;
      std::string hex;
      ss >> k >> hex;
      if (k < 0 || k >= NBUF) return 2;
      unhex(hex, bufs[k]);
      a.b[k] = bufs[k].data();
      a.n[k] = bufs[k].bytes;
    } else if (cmd == "arr") {
      std::string kind, bk;
      int slot;
      i64 shape[4] = {0, 1, 1, 1};
      ss >> kind >> slot;
      if (kind.size() != 2 || kind[1] < '1' || kind[1] > '4') return 2;
      for (int k = 0; k < kind[1] - '0'; ++k) ss >> shape[k];
      ss >> bk;
      if (slot < 0 || slot > 1) return 2;
      if (kind != "f1" && kind != "f2" && kind != "f3" && kind != "f4" && kind != "d1" &&
          kind != "d2")
        return 2;
      binding& b = binds[kind + std::to_string(slot)];
      b.kind = kind;
      b.slot = slot;
      for (int k = 0; k < 4; ++k) b.shape[k] = shape[k];
      b.buf = bk == "-" ? -1 : std::stoi(bk);
    } else if (cmd == "off") {
      ss >> a.o[0] >> a.o[1] >> a.o[2] >> a.o[3];
    } else if (cmd == "run") {
      std::string name;
      ss >> name;
      auto k = kernels.find(name);
      if (k == kernels.end()) {
        std::fprintf(stderr, "no kernel %s\n", name.c_str());
        return 2;
      }
      // Bound now: a `buf` command after the `arr` may have moved the buffer's bytes.
      for (auto& kv : binds) {
        const binding& b = kv.second;
        unsigned char* data = b.buf < 0 ? nullptr : bufs[b.buf].data();
        const int arg = b.slot + 10 * (int)(b.kind[0] - 'a');
        if (b.kind == "f1") bind(a.f1[b.slot], data, b.shape, arg);
        else if (b.kind == "f2") bind(a.f2[b.slot], data, b.shape, arg);
        else if (b.kind == "f3") bind(a.f3[b.slot], data, b.shape, arg);
        else if (b.kind == "f4") bind(a.f4[b.slot], data, b.shape, arg);
        else if (b.kind == "d1") bind(a.d1[b.slot], data, b.shape, arg);
        else bind(a.d2[b.slot], data, b.shape, arg);
      }
      out_len = 0;
      std::fill(out.begin(), out.end(), (unsigned char)0xCD);
      std::fill(smem, smem + sizeof(smem), (unsigned char)0xCD);
      wp_emu::launch(k->second, 1, BD, a);
      print_hex("out", out.data(), out_len);
      if (flag[0]) {
        std::printf("fault %d\n", fault.kind);
        fault = wp::fault_t{};
        flag[0] = 0;
      } else {
        std::printf("nofault\n");
      }
    } else if (cmd == "dump") {
      int k;
      ss >> k;
      print_hex("dump", bufs[k].data(), bufs[k].bytes);
    } else {
      std::fprintf(stderr, "bad command %s\n", cmd.c_str());
      return 2;
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s SCRIPT\n", argv[0]);
    return 2;
  }
  return run(argv[1]);
}

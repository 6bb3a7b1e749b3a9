// wp_tile_driver.cpp: runs wp_tile.h's operations on the host, one block under the emulator
// (tests/cuda_tile_host.rs writes the script, compiles this file for several block sizes with
// -DWP_TILE_BLOCK_DIM=<bd>, and compares the output with warp-core's tile functions).
//
// Script (argv[1]), one command per line:
//   arr KIND SLOT N0 [N1..] HEX an array argument (KIND f1 f2 f3 f4 d1 d2 i1: f32 / f64 / i32,
//                               of the rank its digit says), row-major and contiguous; HEX its
//                               bytes ('-': none)
//   strides KIND SLOT S0 [S1]   the array's strides now (bytes; its bytes must cover them)
//   off O0 O1 O2 O3             the offsets (i64) the next run uses
//   scal HEX HEX HEX            three f32 scalars (bit patterns, 8 hex digits each)
//   run KERNEL                  one block of WP_TILE_BLOCK_DIM threads; prints `out HEX` (what
//                               the kernel wrote) and `fault KIND` or `nofault`
//   dump KIND SLOT              prints `dump HEX`: the array's bytes now
#include "wp_prim_emu.h"
#include "wp_tile.h"
#include "wp_tile_mma.h"
#include "wp_atomic.h"

// The GEMM pipe's plan instantiates at every block size (a kernel's k-loop is printed over it
// whatever block size it is compiled for); below a warp it is off rather than a compile error.
static_assert(WP_TILE_BLOCK_DIM >= 32 || !wp::tile_gemm_pipe<16, 16, 8>::ON,
              "tile_gemm_pipe: below 32 threads the pipe must be off");
static_assert(wp::tile_gemm_pipe<128, 64, 128>::STAGES >= 1, "tile_gemm_pipe: a plan");

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>

using wp::f32;
using wp::f64;
using wp::i32;
using wp::i64;
using wp::tile_t;

struct args_t {
  wp::array_t<f32, 1> f1[2];
  wp::array_t<f32, 2> f2[3];
  wp::array_t<f32, 3> f3[2];
  wp::array_t<f32, 4> f4[2];
  wp::array_t<f64, 1> d1[1];
  wp::array_t<f64, 2> d2[3];
  wp::array_t<i32, 1> i1[2];
  i64 o[4];
  f32 s[3];
  unsigned char* out;
  wp::fault_t* fault;
  wp::u32* flag;
};

/// A block's shared memory (static storage: the emulator runs one block at a time). Each
/// kernel carves its slots from the start in the same order in every thread, as the emitter's
/// constant offsets will.
alignas(16) static unsigned char smem[128 * 1024];

template <typename Tile>
Tile slot_at(size_t& at) {
  at = (at + 15) & ~(size_t)15;
  Tile t(smem + at);
  at += Tile::BYTES;
  if (at > sizeof(smem)) std::abort();
  return t;
}
#define SLOTS_BEGIN() \
  size_t smem_at_ = 0; \
  (void)smem_at_
#define SLOT(...) slot_at<__VA_ARGS__>(smem_at_)

/// Thread 0 appends `t`'s bytes to the output (after the operation's closing barrier), and the
/// block waits for it before anything overwrites the slot.
template <typename Tile>
void dump(const args_t& a, size_t& at, const Tile& t) {
  if (threadIdx.x == 0) std::memcpy(a.out + at, t.data, Tile::BYTES);
  at += Tile::BYTES;
  __syncthreads();
}

static void k_load1(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 37>);
  wp::tile_load(t, a.f1[0], a.o[0], &c);
  wp::tile_store(a.f1[1], a.o[1], t, &c);
  size_t at = 0;
  dump(a, at, t);
}

/// Rank 3: a (3, 4, 5) tile loaded from f3[0] at (o0, o1, o2), stored into f3[1] at
/// (o1, o2, o3), an element read at (o3 & 1, 2, 4) appended; then atomically added into f3[1]
/// at (o2, o3, o0), the old values appended. Outputs: the tile, the element, the old values.
static void k_load3(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 3, 4, 5>);
  auto old = SLOT(tile_t<f32, 3, 4, 5>);
  wp::tile_load(t, a.f3[0], a.o[0], a.o[1], a.o[2], &c);
  wp::tile_store(a.f3[1], a.o[1], a.o[2], a.o[3], t, &c);
  size_t at = 0;
  dump(a, at, t);
  const f32 x = wp::tile_extract(t, (int)(a.o[3] & 1), 2u, (i64)4, &c);
  if (threadIdx.x == 0) std::memcpy(a.out + at, &x, 4);
  at += 4;
  __syncthreads();
  wp::tile_atomic_add(old, a.f3[1], a.o[2], a.o[3], a.o[0], t, &c);
  dump(a, at, old);
}

/// Rank 4: a (2, 3, 2, 3) tile loaded from f4[0] at (o0, o1, o2, o3), stored into f4[1] at
/// (o3, o2, o1, o0), an element read at (1, 2, 0, 2) appended.
static void k_load4(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 2, 3, 2, 3>);
  wp::tile_load(t, a.f4[0], a.o[0], a.o[1], a.o[2], a.o[3], &c);
  wp::tile_store(a.f4[1], a.o[3], a.o[2], a.o[1], a.o[0], t, &c);
  size_t at = 0;
  dump(a, at, t);
  const f32 x = wp::tile_extract(t, 1, 2, 0, 2, &c);
  if (threadIdx.x == 0) std::memcpy(a.out + at, &x, 4);
  at += 4;
  __syncthreads();
}

static void k_load2(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 5, 7>);
  wp::tile_load(t, a.f2[0], a.o[0], a.o[1], &c);
  wp::tile_store(a.f2[1], a.o[2], a.o[3], t, &c);
  size_t at = 0;
  dump(a, at, t);
}

/// sum, min, max of `t` (already loaded), appended to the output.
template <typename Tile>
static void reductions(const args_t& a, size_t& smem_at_, const Tile& t) {
  typedef typename Tile::elem_t T;
  auto s = SLOT(tile_t<T, 1>);
  auto lo = SLOT(tile_t<T, 1>);
  auto hi = SLOT(tile_t<T, 1>);
  wp::tile_sum(s, t);
  wp::tile_min(lo, t);
  wp::tile_max(hi, t);
  size_t at = 0;
  dump(a, at, s);
  dump(a, at, lo);
  dump(a, at, hi);
}

static void k_red_f32_300(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 300>);
  wp::tile_load(t, a.f1[0], 0, &c);
  reductions(a, smem_at_, t);
}

static void k_red_f32_5(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 5>);
  wp::tile_load(t, a.f1[0], 0, &c);
  reductions(a, smem_at_, t);
}

static void k_red_f32_2d(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 13, 11>);
  wp::tile_load(t, a.f2[0], 0, 0, &c);
  reductions(a, smem_at_, t);
}

static void k_red_i32(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<i32, 200>);
  wp::tile_load(t, a.i1[0], 0, &c);
  reductions(a, smem_at_, t);
}

/// argmin, argmax of `t` (already loaded), appended to the output as two i32.
template <typename Tile>
static void arg_reductions(const args_t& a, size_t& smem_at_, const Tile& t) {
  auto lo = SLOT(tile_t<i32, 1>);
  auto hi = SLOT(tile_t<i32, 1>);
  wp::tile_argmin(lo, t);
  wp::tile_argmax(hi, t);
  size_t at = 0;
  dump(a, at, lo);
  dump(a, at, hi);
}

static void k_arg_f32_300(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 300>);
  wp::tile_load(t, a.f1[0], 0, &c);
  arg_reductions(a, smem_at_, t);
}

static void k_arg_f32_5(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 5>);
  wp::tile_load(t, a.f1[0], 0, &c);
  arg_reductions(a, smem_at_, t);
}

static void k_arg_f32_2d(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f32, 13, 11>);
  wp::tile_load(t, a.f2[0], 0, 0, &c);
  arg_reductions(a, smem_at_, t);
}

static void k_arg_i32(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<i32, 200>);
  wp::tile_load(t, a.i1[0], 0, &c);
  arg_reductions(a, smem_at_, t);
}

/// `-x` of a 40-element f32 tile and of a 40-element i32 tile, then `-x` in place.
static void k_neg(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto x = SLOT(tile_t<f32, 40>);
  auto r = SLOT(tile_t<f32, 40>);
  auto y = SLOT(tile_t<i32, 40>);
  auto q = SLOT(tile_t<i32, 40>);
  wp::tile_load(x, a.f1[0], 0, &c);
  wp::tile_load(y, a.i1[0], 0, &c);
  size_t at = 0;
  wp::tile_neg(r, x);
  dump(a, at, r);
  wp::tile_neg(q, y);
  dump(a, at, q);
  wp::tile_neg(q, q);
  dump(a, at, q);
}

static void k_red_f64(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<f64, 150>);
  wp::tile_load(t, a.d1[0], 0, &c);
  reductions(a, smem_at_, t);
}

/// `+ - *` of tiles and scalars, the constructors, and an in-place update, over two 40-element
/// arrays of T and the scalars (f32 bit patterns, read as T's bits for i32).
template <typename T>
static void arith(const args_t& a, const wp::array_t<T, 1>& ax, const wp::array_t<T, 1>& ay) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  typedef tile_t<T, 40> T40;
  static_assert(sizeof(T) == 4, "scalars are 32-bit patterns");
  T s[3];
  std::memcpy(s, a.s, sizeof(s));
  auto x = SLOT(T40);
  auto y = SLOT(T40);
  auto r = SLOT(T40);
  wp::tile_load(x, ax, 0, &c);
  wp::tile_load(y, ay, 0, &c);
  size_t at = 0;
  wp::tile_add(r, x, y);
  dump(a, at, r);
  wp::tile_sub(r, x, y);
  dump(a, at, r);
  wp::tile_mul(r, x, y);
  dump(a, at, r);
  wp::tile_add(r, x, s[0]);
  dump(a, at, r);
  wp::tile_sub(r, s[0], x);
  dump(a, at, r);
  wp::tile_mul(r, x, s[0]);
  dump(a, at, r);
  wp::tile_zeros(r);
  dump(a, at, r);
  wp::tile_ones(r);
  dump(a, at, r);
  wp::tile_arange(r, s[1], s[2]);
  dump(a, at, r);
  // In place: x = x * y - x (each element read and written by one thread).
  wp::tile_mul(r, x, y);
  wp::tile_sub(x, r, x);
  dump(a, at, x);
}

static void k_arith(args_t a) { arith(a, a.f1[0], a.f1[1]); }
static void k_arith_i32(args_t a) { arith(a, a.i1[0], a.i1[1]); }

static void k_matmul_f32(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto ta = SLOT(tile_t<f32, 7, 13>);
  auto tb = SLOT(tile_t<f32, 13, 5>);
  auto tc = SLOT(tile_t<f32, 7, 5>);
  auto tp = SLOT(tile_t<f32, 7, 5>);
  wp::tile_load(ta, a.f2[0], 0, 0, &c);
  wp::tile_load(tb, a.f2[1], 0, 0, &c);
  wp::tile_load(tc, a.f2[2], 0, 0, &c);
  wp::tile_matmul(tp, ta, tb);
  wp::tile_matmul_acc(tc, ta, tb);
  size_t at = 0;
  dump(a, at, tp);
  dump(a, at, tc);
}

static void k_matmul_f64(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto ta = SLOT(tile_t<f64, 3, 4>);
  auto tb = SLOT(tile_t<f64, 4, 6>);
  auto tp = SLOT(tile_t<f64, 3, 6>);
  wp::tile_load(ta, a.d2[0], 0, 0, &c);
  wp::tile_load(tb, a.d2[1], 0, 0, &c);
  wp::tile_matmul(tp, ta, tb);
  size_t at = 0;
  dump(a, at, tp);
}

/// f16 operands (wp_tile_mma.h; the host has no tensor cores, so its FMA path): arrays 0 and 1
/// (f32 values that f16 holds exactly) converted into f16 tiles, `p = a b` (f16) and
/// `c2 += a b` (f32, c2 from array 2); outputs p, then c2.
template <int M, int K, int N>
static void k_mm16(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto fa = SLOT(tile_t<f32, M, K>);
  auto fb = SLOT(tile_t<f32, K, N>);
  auto ta = SLOT(tile_t<wp::f16, M, K>);
  auto tb = SLOT(tile_t<wp::f16, K, N>);
  auto tc = SLOT(tile_t<f32, M, N>);
  auto tp = SLOT(tile_t<wp::f16, M, N>);
  wp::tile_load(fa, a.f2[0], 0, 0, &c);
  wp::tile_load(fb, a.f2[1], 0, 0, &c);
  wp::tile_load(tc, a.f2[2], 0, 0, &c);
  for (int e = (int)threadIdx.x; e < M * K; e += WP_TILE_BLOCK_DIM)
    ta.data[e] = wp::f16_from_f32(fa.data[e]);
  for (int e = (int)threadIdx.x; e < K * N; e += WP_TILE_BLOCK_DIM)
    tb.data[e] = wp::f16_from_f32(fb.data[e]);
  __syncthreads();
  wp::tile_matmul(tp, ta, tb);
  wp::tile_matmul_acc(tc, ta, tb);
  size_t at = 0;
  dump(a, at, tp);
  dump(a, at, tc);
}

/// bf16 operands (wp_tile_mma.h's bf16 section, the FMA path), as k_mm16: arrays 0 and 1 (f32
/// values that bf16 holds exactly) converted into bf16 tiles, `p = a b` (bf16) and `c2 += a b`
/// (f32, c2 from array 2); outputs p, then c2.
template <int M, int K, int N>
static void k_mmb16(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto fa = SLOT(tile_t<f32, M, K>);
  auto fb = SLOT(tile_t<f32, K, N>);
  auto ta = SLOT(tile_t<wp::bf16, M, K>);
  auto tb = SLOT(tile_t<wp::bf16, K, N>);
  auto tc = SLOT(tile_t<f32, M, N>);
  auto tp = SLOT(tile_t<wp::bf16, M, N>);
  wp::tile_load(fa, a.f2[0], 0, 0, &c);
  wp::tile_load(fb, a.f2[1], 0, 0, &c);
  wp::tile_load(tc, a.f2[2], 0, 0, &c);
  for (int e = (int)threadIdx.x; e < M * K; e += WP_TILE_BLOCK_DIM)
    ta.data[e] = wp::bf16_from_f32(fa.data[e]);
  for (int e = (int)threadIdx.x; e < K * N; e += WP_TILE_BLOCK_DIM)
    tb.data[e] = wp::bf16_from_f32(fb.data[e]);
  __syncthreads();
  wp::tile_matmul(tp, ta, tb);
  wp::tile_matmul_acc(tc, ta, tb);
  size_t at = 0;
  dump(a, at, tp);
  dump(a, at, tc);
}

/// The rank-2 f32 or f64 arguments.
template <typename T>
static const wp::array_t<T, 2>* arrays2(const args_t& a);
template <>
const wp::array_t<f32, 2>* arrays2<f32>(const args_t& a) { return a.f2; }
template <>
const wp::array_t<f64, 2>* arrays2<f64>(const args_t& a) { return a.d2; }
template <typename T>
static const wp::array_t<T, 1>* arrays1(const args_t& a);
template <>
const wp::array_t<f32, 1>* arrays1<f32>(const args_t& a) { return a.f1; }
template <>
const wp::array_t<f64, 1>* arrays1<f64>(const args_t& a) { return a.d1; }

/// `c = a b` and `c2 += a b` of M x K and K x N tiles loaded from arrays 0 and 1 (at (0, 0)),
/// c2 loaded from array 2; outputs both. With `Mis` the tiles start 4 bytes past a 16-byte
/// boundary (the matmul's and the loads' scalar fallbacks).
template <typename T, int M, int K, int N, bool Mis>
static void k_mm(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  const int sh = Mis ? 1 : 0;
  auto sa = SLOT(tile_t<T, M * K + 1>);
  auto sb = SLOT(tile_t<T, K * N + 1>);
  auto sp = SLOT(tile_t<T, M * N + 1>);
  auto sc = SLOT(tile_t<T, M * N + 1>);
  tile_t<T, M, K> ta(sa.data + sh);
  tile_t<T, K, N> tb(sb.data + sh);
  tile_t<T, M, N> tp(sp.data + sh), tc(sc.data + sh);
  const wp::array_t<T, 2>* arr = arrays2<T>(a);
  wp::tile_load(ta, arr[0], 0, 0, &c);
  wp::tile_load(tb, arr[1], 0, 0, &c);
  wp::tile_load(tc, arr[2], 0, 0, &c);
  wp::tile_matmul(tp, ta, tb);
  wp::tile_matmul_acc(tc, ta, tb);
  size_t at = 0;
  dump(a, at, tp);
  dump(a, at, tc);
}

/// A N0 x N1 tile of T loaded from rank-2 array 0 at (o0, o1) and stored into array 1 at
/// (o2, o3); outputs the tile (the caller dumps array 1).
template <typename T, int N0, int N1>
static void k_ld2(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<T, N0, N1>);
  const wp::array_t<T, 2>* arr = arrays2<T>(a);
  wp::tile_load(t, arr[0], a.o[0], a.o[1], &c);
  wp::tile_store(arr[1], a.o[2], a.o[3], t, &c);
  size_t at = 0;
  dump(a, at, t);
}

/// A rank-1 tile of N0 T loaded from array 0 at o0, stored into array 1 at o1 (the f64
/// arguments have one rank-1 slot: f64 stores go back into it, at o1).
template <typename T, int N0>
static void k_ld1(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  SLOTS_BEGIN();
  auto t = SLOT(tile_t<T, N0>);
  const wp::array_t<T, 1>* arr = arrays1<T>(a);
  wp::tile_load(t, arr[0], a.o[0], &c);
  wp::tile_store(arr[sizeof(T) == 4 ? 1 : 0], a.o[1], t, &c);
  size_t at = 0;
  dump(a, at, t);
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

/// Points array argument `arr` at `b` with the given shape (row-major, contiguous).
template <typename T, int N>
void bind(wp::array_t<T, N>& arr, buffer& b, const i64* shape, int index) {
  arr.data = reinterpret_cast<T*>(b.data());
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
  std::map<std::string, buffer> bufs;
  std::vector<unsigned char> out(128 * 1024);
  wp::fault_t fault{};
  wp::u32 flag[2] = {0, 0};
  args_t a{};
  a.out = out.data();
  a.fault = &fault;
  a.flag = &flag[0];
  std::map<std::string, void (*)(args_t)> kernels = {
      {"load1", k_load1},         {"load2", k_load2},           {"red_f32_300", k_red_f32_300},
      {"red_f32_5", k_red_f32_5}, {"red_f32_2d", k_red_f32_2d}, {"red_i32", k_red_i32},
      {"red_f64", k_red_f64},     {"arith", k_arith},           {"matmul_f32", k_matmul_f32},
      {"matmul_f64", k_matmul_f64}, {"arith_i32", k_arith_i32},
      {"arg_f32_300", k_arg_f32_300}, {"arg_f32_5", k_arg_f32_5},
      {"arg_f32_2d", k_arg_f32_2d},   {"arg_i32", k_arg_i32},
      {"neg", k_neg},
      {"load3", k_load3},
      {"load4", k_load4},
  };
  std::map<std::string, size_t> out_bytes = {
      {"load1", 37 * 4},   {"load2", 35 * 4},   {"red_f32_300", 12}, {"red_f32_5", 12},
      {"red_f32_2d", 12},  {"red_i32", 12},     {"red_f64", 24},     {"arith", 10 * 160},
      {"matmul_f32", 280}, {"matmul_f64", 144}, {"arith_i32", 10 * 160},
      {"arg_f32_300", 8},  {"arg_f32_5", 8},    {"arg_f32_2d", 8},   {"arg_i32", 8},
      {"neg", 3 * 160},
      {"load3", 60 * 4 * 2 + 4}, {"load4", 36 * 4 + 4},
  };
  // The register-blocked matmul's shapes (tests/cuda_tile_host.rs names them mm_T_MxKxN, with
  // _mis for the misaligned slots).
#define MM(T, M, K, N)                                                                         \
  kernels["mm_" #T "_" #M "x" #K "x" #N] = k_mm<T, M, K, N, false>;                           \
  kernels["mm_" #T "_" #M "x" #K "x" #N "_mis"] = k_mm<T, M, K, N, true>;                     \
  out_bytes["mm_" #T "_" #M "x" #K "x" #N] = 2 * M * N * sizeof(T);                            \
  out_bytes["mm_" #T "_" #M "x" #K "x" #N "_mis"] = 2 * M * N * sizeof(T);
  MM(f32, 64, 16, 64)
  MM(f32, 32, 12, 24)
  MM(f32, 24, 7, 20)
  MM(f32, 12, 5, 9)
  MM(f32, 16, 8, 6)
  MM(f64, 16, 8, 16)
  MM(f64, 8, 6, 10)
  MM(f64, 64, 8, 64)
#undef MM
#define MM16(M, K, N)                                                                          \
  kernels["mm16_" #M "x" #K "x" #N] = k_mm16<M, K, N>;                                        \
  out_bytes["mm16_" #M "x" #K "x" #N] = M * N * (2 + 4);
  MM16(32, 16, 32)
  MM16(12, 20, 8)
#undef MM16
  kernels["mmb16_32x16x32"] = k_mmb16<32, 16, 32>;
  out_bytes["mmb16_32x16x32"] = 32 * 32 * (2 + 4);
  kernels["mmb16_12x21x9"] = k_mmb16<12, 21, 9>;
  out_bytes["mmb16_12x21x9"] = 12 * 9 * (2 + 4);
#define LD(T, N0, N1)                                                                          \
  kernels["ld2_" #T "_" #N0 "x" #N1] = k_ld2<T, N0, N1>;                                      \
  out_bytes["ld2_" #T "_" #N0 "x" #N1] = N0 * N1 * sizeof(T);
  LD(f32, 4, 8)
  LD(f32, 3, 12)
  LD(f64, 3, 4)
#undef LD
  kernels["ld1_f32_64"] = k_ld1<f32, 64>;
  out_bytes["ld1_f32_64"] = 64 * 4;
  kernels["ld1_f64_9"] = k_ld1<f64, 9>;
  out_bytes["ld1_f64_9"] = 9 * 8;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    std::string cmd;
    ss >> cmd;
    if (cmd.empty()) continue;
    if (cmd == "arr") {
      std::string kind, hex;
      int slot;
      i64 shape[4] = {0, 1, 1, 1};
      ss >> kind >> slot;
      const int rank = kind[1] - '0';
      for (int k = 0; k < rank; ++k) ss >> shape[k];
      ss >> hex;
      buffer& b = bufs[kind + std::to_string(slot)];
      unhex(hex, b);
      const int arg = slot + 10 * (int)(kind[0] - 'a');
      if (kind == "f1") bind(a.f1[slot], b, shape, arg);
      else if (kind == "f2") bind(a.f2[slot], b, shape, arg);
      else if (kind == "f3") bind(a.f3[slot], b, shape, arg);
      else if (kind == "f4") bind(a.f4[slot], b, shape, arg);
      else if (kind == "d1") bind(a.d1[slot], b, shape, arg);
      else if (kind == "d2") bind(a.d2[slot], b, shape, arg);
      else if (kind == "i1") bind(a.i1[slot], b, shape, arg);
      else return 2;
    } else if (cmd == "strides") {
      std::string kind;
      int slot;
      i64 st[2] = {0, 0};
      ss >> kind >> slot >> st[0];
      if (kind[1] == '2') ss >> st[1];
      if (kind == "f1") a.f1[slot].strides[0] = st[0];
      else if (kind == "f2") a.f2[slot].strides[0] = st[0], a.f2[slot].strides[1] = st[1];
      else if (kind == "d1") a.d1[slot].strides[0] = st[0];
      else if (kind == "d2") a.d2[slot].strides[0] = st[0], a.d2[slot].strides[1] = st[1];
      else return 2;
    } else if (cmd == "off") {
      ss >> a.o[0] >> a.o[1] >> a.o[2] >> a.o[3];
    } else if (cmd == "scal") {
      for (int k = 0; k < 3; ++k) {
        std::string h;
        ss >> h;
        const wp::u32 bits = (wp::u32)std::stoul(h, nullptr, 16);
        std::memcpy(&a.s[k], &bits, 4);
      }
    } else if (cmd == "run") {
      std::string name;
      ss >> name;
      auto k = kernels.find(name);
      if (k == kernels.end()) {
        std::fprintf(stderr, "no kernel %s\n", name.c_str());
        return 2;
      }
      std::fill(out.begin(), out.end(), (unsigned char)0xCD);
      std::fill(smem, smem + sizeof(smem), (unsigned char)0xCD);
      wp_emu::launch(k->second, 1, WP_TILE_BLOCK_DIM, a);
      print_hex("out", out.data(), out_bytes.at(name));
      if (flag[0]) {
        std::printf("fault %d\n", fault.kind);
        fault = wp::fault_t{};
        flag[0] = 0;
      } else {
        std::printf("nofault\n");
      }
    } else if (cmd == "dump") {
      std::string kind;
      int slot;
      ss >> kind >> slot;
      buffer& b = bufs.at(kind + std::to_string(slot));
      print_hex("dump", b.data(), b.bytes);
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

// wp_tile_linalg_driver.cpp: runs wp_tile_linalg.h on the host, one block under the emulator
// (tests/cuda_tile_linalg_host.rs compiles it for several block sizes with
// -DWP_TILE_BLOCK_DIM=<bd> and compares the output with warp-core's tile::linalg).
//
// Script (argv[1]), one command per line:
//   run NAME HEX   the case NAME (element, N, right-hand side shape) on the bytes HEX: A (N x N)
//                  then Y (N or N x K), row-major. Prints `out HEX`: L = tile_cholesky(A),
//                  Z = tile_lower_solve(L, Y), X = tile_cholesky_solve(L, Y),
//                  W = tile_upper_solve(L^T, Z), each row-major, in that order. Then
//                  `barriers F L S U`: the block barriers (__syncthreads phases) that the
//                  factor, the lower solve, the Cholesky solve and the upper solve each took.
#include "wp_prim_emu.h"
#include "wp_tile.h"
#include "wp_tile_linalg.h"

#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

using wp::f32;
using wp::f64;
using wp::tile_t;

namespace {

struct args_t {
  const unsigned char* in;
  unsigned char* out;
};

alignas(16) static unsigned char smem[64 * 1024];

/// The block barriers of the last case's four operations (thread 0 writes them: every thread
/// sees the same count between two barriers).
static long long barriers[4];

/// Runs `op` and, in thread 0, stores the barriers it took in `*n`.
template <typename F>
void counted(long long* n, F op) {
  const long long before = wp_emu::block_barriers;
  op();
  if (threadIdx.x == 0) *n = wp_emu::block_barriers - before;
}

template <typename Tile>
Tile slot_at(size_t& at) {
  at = (at + 15) & ~(size_t)15;
  Tile t(smem + at);
  at += Tile::BYTES;
  if (at > sizeof(smem)) std::abort();
  return t;
}

/// Thread 0 copies `t` to the output at `at`; the block waits for it.
template <typename Tile>
void put(const args_t& a, size_t& at, const Tile& t) {
  if (threadIdx.x == 0) std::memcpy(a.out + at, t.data, Tile::BYTES);
  at += Tile::BYTES;
  __syncthreads();
}

/// Thread 0 copies the input at `at` into `t`; the block waits for it.
template <typename Tile>
void get(const args_t& a, size_t& at, const Tile& t) {
  if (threadIdx.x == 0) std::memcpy(t.data, a.in + at, Tile::BYTES);
  at += Tile::BYTES;
  __syncthreads();
}

/// The case's right-hand side tile: `N` (K == 0) or `N x K`.
template <typename T, int N, int K>
struct rhs_of {
  typedef tile_t<T, N, K> type;
};
template <typename T, int N>
struct rhs_of<T, N, 0> {
  typedef tile_t<T, N> type;
};

template <typename T, int N, int K>
void k_case(args_t a) {
  typedef typename rhs_of<T, N, K>::type R;
  size_t s = 0;
  auto A = slot_at<tile_t<T, N, N>>(s);
  auto Y = slot_at<R>(s);
  auto L = slot_at<tile_t<T, N, N>>(s);
  auto Lt = slot_at<tile_t<T, N, N>>(s);
  auto Z = slot_at<R>(s);
  auto X = slot_at<R>(s);
  auto W = slot_at<R>(s);
  size_t in = 0, out = 0;
  get(a, in, A);
  get(a, in, Y);
  counted(&barriers[0], [&] { wp::tile_cholesky(L, A); });
  counted(&barriers[1], [&] { wp::tile_lower_solve(Z, L, Y); });
  counted(&barriers[2], [&] { wp::tile_cholesky_solve(X, L, Y); });
  wp::tile_transpose(Lt, L);
  counted(&barriers[3], [&] { wp::tile_upper_solve(W, Lt, Z); });
  put(a, out, L);
  put(a, out, Z);
  put(a, out, X);
  put(a, out, W);
}

template <typename T, int N, int K>
size_t out_bytes() {
  return sizeof(T) * (size_t)(N * N + 3 * N * (K == 0 ? 1 : K));
}

/// The in-place factor (`a = tile_cholesky(a)` would be one if the emitter aliased them).
template <typename T, int N>
void k_inplace(args_t a) {
  size_t s = 0;
  auto A = slot_at<tile_t<T, N, N>>(s);
  size_t in = 0, out = 0;
  get(a, in, A);
  counted(&barriers[0], [&] { wp::tile_cholesky(A, A); });
  put(a, out, A);
}

void unhex(const std::string& h, std::vector<unsigned char>& b) {
  b.resize(h.size() / 2);
  for (size_t i = 0; i < b.size(); ++i) b[i] = (unsigned char)std::stoul(h.substr(2 * i, 2), nullptr, 16);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s SCRIPT\n", argv[0]);
    return 2;
  }
  std::map<std::string, std::pair<void (*)(args_t), size_t>> cases;
#define CASE(T, N, K) cases[#T "_" #N "_" #K] = {k_case<T, N, K>, out_bytes<T, N, K>()};
  CASE(f32, 1, 0)
  CASE(f32, 4, 0)
  CASE(f32, 5, 3)
  CASE(f32, 16, 0)
  CASE(f32, 16, 3)
  CASE(f32, 32, 0)
  CASE(f64, 4, 2)
  CASE(f64, 16, 0)
  CASE(f64, 32, 0)
  CASE(f64, 32, 2)
#undef CASE
  cases["inplace_f32_16"] = {k_inplace<f32, 16>, sizeof(f32) * 16 * 16};
  std::ifstream in(argv[1]);
  std::string line;
  std::vector<unsigned char> input, out(64 * 1024);
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    std::string cmd, name, hex;
    ss >> cmd >> name >> hex;
    if (cmd.empty()) continue;
    auto c = cases.find(name);
    if (cmd != "run" || c == cases.end()) {
      std::fprintf(stderr, "bad line %s\n", line.c_str());
      return 2;
    }
    unhex(hex, input);
    std::fill(smem, smem + sizeof(smem), (unsigned char)0xCD);
    const args_t a{input.data(), out.data()};
    for (long long& b : barriers) b = 0;
    wp_emu::launch(c->second.first, 1, WP_TILE_BLOCK_DIM, a);
    std::printf("out ");
    for (size_t i = 0; i < c->second.second; ++i) std::printf("%02x", out[i]);
    std::printf("\nbarriers %lld %lld %lld %lld\n", barriers[0], barriers[1], barriers[2],
                barriers[3]);
  }
  return 0;
}

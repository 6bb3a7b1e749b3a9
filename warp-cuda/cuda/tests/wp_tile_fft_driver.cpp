// wp_tile_fft_driver.cpp: runs wp_tile_fft.h on the host, one block under the emulator
// (tests/cuda_tile_fft_host.rs compiles it for several block sizes with
// -DWP_TILE_BLOCK_DIM=<bd> and compares the output with warp-core's tile::fft).
//
// Script (argv[1]), one command per line:
//   run NAME HEX   the case NAME (element, M, N) on the bytes HEX: X (M x N complex values),
//                  row-major. Prints `out HEX`: Y = tile_fft(X), then Z = tile_ifft(Y), each
//                  row-major, both transformed in place in one slot as the emitter does.
//                  `ops_*` cases: the elementwise operators of tiles of vectors (k_ops).
//                  `adj_*` cases: the FFTs' adjoints (k_adj); `vadj_*`: the elementwise
//                  adjoints on tiles of vectors, a uniform scalar's included (k_vadj).
#include "wp_prim_emu.h"
#include "wp_tile.h"
#include "wp_tile_fft.h"
#include "wp_adjoint_tile.h"

#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

using wp::DVec2;
using wp::tile_t;
using wp::Vec2;

namespace {

struct args_t {
  const unsigned char* in;
  unsigned char* out;
};

alignas(16) static unsigned char smem[64 * 1024];

/// Thread 0 copies `t` to the output at `at`; the block waits for it.
template <typename Tile>
void put(const args_t& a, size_t& at, const Tile& t) {
  if (threadIdx.x == 0) std::memcpy(a.out + at, t.data, Tile::BYTES);
  at += Tile::BYTES;
  __syncthreads();
}

template <typename C, int M, int N>
void k_case(args_t a) {
  tile_t<C, M, N> X(smem);
  if (threadIdx.x == 0) std::memcpy(X.data, a.in, decltype(X)::BYTES);
  __syncthreads();
  size_t out = 0;
  wp::tile_fft(X);
  put(a, out, X);
  wp::tile_ifft(X);
  put(a, out, X);
}

/// The elementwise operations of tiles of vectors, as the emitter prints `0.5 * ((x + x) * s
/// - x) + zeros` (s = 1.75), into a slot of their own: `out HEX` of the result.
template <typename C, typename S, int M, int N>
void k_ops(args_t a) {
  tile_t<C, M, N> X(smem), A(smem + 4096), B(smem + 8192);
  if (threadIdx.x == 0) std::memcpy(X.data, a.in, decltype(X)::BYTES);
  __syncthreads();
  const S s = (S)1.75;
  const S h = (S)0.5;
  wp::tile_add(A, X, X);
  wp::tile_mul(B, A, s);
  wp::tile_sub(A, B, X);
  wp::tile_mul(B, h, A);
  wp::tile_zeros(A);
  wp::tile_add(B, B, A);
  size_t out = 0;
  put(a, out, B);
}

/// The FFTs' adjoints as the sweep calls them, the seed a second tile over the adjoint's slot:
/// `out HEX` of the slot after `adj_tile_fft(X, A, A)` (A = X), then after `adj_tile_ifft`.
template <typename C, int M, int N>
void k_adj(args_t a) {
  tile_t<C, M, N> X(smem), A(smem + 16384);
  if (threadIdx.x == 0) {
    std::memcpy(X.data, a.in, decltype(X)::BYTES);
    std::memcpy(A.data, a.in, decltype(A)::BYTES);
  }
  __syncthreads();
  const tile_t<C, M, N> R = A;
  size_t out = 0;
  wp::adj_tile_fft(X, A, R);
  put(a, out, A);
  wp::adj_tile_ifft(X, A, R);
  put(a, out, A);
}

/// The elementwise adjoints on tiles of vectors with the seed R = X reversed: `t * s`,
/// `s * t` (s = 1.75, into A and the scalar's adjoint), `t + u`, `t - u` (into A and B), and a
/// lane's shared add of X[1] into A[0]: `out HEX` of A, B, then the two scalar adjoints.
template <typename C, typename S, int M, int N>
void k_vadj(args_t a) {
  constexpr int SIZE = M * N;
  tile_t<C, M, N> X(smem), R(smem + 4096), A(smem + 8192), B(smem + 12288);
  if (threadIdx.x == 0) {
    std::memcpy(X.data, a.in, decltype(X)::BYTES);
    for (int e = 0; e < SIZE; ++e) R.data[e] = X.data[SIZE - 1 - e];
  }
  __syncthreads();
  wp::tile_zeros(A);
  wp::tile_zeros(B);
  const S s = (S)1.75;
  S gs = S(0), gt = S(0);
  wp::adj_tile_mul_ts(X, s, A, gs, R);
  wp::adj_tile_mul_st(s, X, gt, A, R);
  wp::adj_tile_add_tt(X, R, A, B, R);
  wp::adj_tile_sub_tt(X, R, A, B, R);
  if (threadIdx.x == 0) wp::tile_detail::shared_add(&A.data[0], X.data[1]);
  __syncthreads();
  size_t out = 0;
  put(a, out, A);
  put(a, out, B);
  if (threadIdx.x == 0) {
    std::memcpy(a.out + out, &gs, sizeof(S));
    std::memcpy(a.out + out + sizeof(S), &gt, sizeof(S));
  }
  __syncthreads();
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
#define CASE(C, M, N) cases[#C "_" #M "_" #N] = {k_case<C, M, N>, 2 * sizeof(C) * M * N};
  CASE(Vec2, 3, 1)
  CASE(Vec2, 1, 2)
  CASE(Vec2, 3, 4)
  CASE(Vec2, 5, 8)
  CASE(Vec2, 2, 16)
  CASE(Vec2, 4, 64)
  CASE(Vec2, 1, 256)
  CASE(Vec2, 2, 256)
  CASE(DVec2, 2, 2)
  CASE(DVec2, 3, 32)
  CASE(DVec2, 1, 128)
  CASE(DVec2, 2, 256)
#undef CASE
  cases["adj_Vec2_3_8"] = {k_adj<Vec2, 3, 8>, 2 * sizeof(Vec2) * 24};
  cases["adj_DVec2_2_32"] = {k_adj<DVec2, 2, 32>, 2 * sizeof(DVec2) * 64};
  cases["vadj_Vec2_3_5"] = {k_vadj<Vec2, wp::f32, 3, 5>, 2 * sizeof(Vec2) * 15 + 2 * 4};
  cases["vadj_DVec2_4_9"] = {k_vadj<DVec2, wp::f64, 4, 9>, 2 * sizeof(DVec2) * 36 + 2 * 8};
  cases["ops_Vec2_3_5"] = {k_ops<Vec2, wp::f32, 3, 5>, sizeof(Vec2) * 15};
  cases["ops_DVec2_2_4"] = {k_ops<DVec2, wp::f64, 2, 4>, sizeof(DVec2) * 8};
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
    wp_emu::launch(c->second.first, 1, WP_TILE_BLOCK_DIM, a);
    std::printf("out ");
    for (size_t i = 0; i < c->second.second; ++i) std::printf("%02x", out[i]);
    std::printf("\n");
  }
  return 0;
}

// wp_tile_linalg_adjoint_driver.cpp: runs the adjoints of the tile linear algebra
// (wp_adjoint_tile_linalg.h) and of the scans (wp_adjoint_tile.h) on the host, one block under
// the emulator (tests/cuda_tile_linalg_adjoint_host.rs compiles it for several block sizes
// with -DWP_TILE_BLOCK_DIM=<bd> and compares the output with warp-core's).
//
// Script (argv[1]), one command per line:
//   run NAME HEX   the case NAME on the bytes HEX (row-major, concatenated).
//     lin_<T>_<N>_<K>: M (N x N), Y (N x K), Y1 (N), R (N x K), R1 (N), A (N x N),
//                      RA (N x N), G (N x N), H (N x K), H1 (N). Prints `out HEX`: for
//                      lower, upper and Cholesky solve in turn, with the matrix M, the right-hand
//                      side Y then Y1 and the seed R then R1, the matrix's and the right-hand
//                      side's adjoints, starting from G and H (H1); then the factor's adjoint
//                      of A from seed RA, starting from G.
//     scan_<T>_<S>:    X, R, H (S each). Prints `out HEX`: the adjoints of the inclusive,
//                      exclusive, max and min scans of X from seed R, each starting from H.
// Every seed is copied into a slot of its own first: the adjoints use the seed as scratch.
#include "wp_prim_emu.h"
#include "wp_tile.h"
#include "wp_tile_linalg.h"
#include "wp_adjoint_tile.h"
#include "wp_adjoint_tile_linalg.h"

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

alignas(16) static unsigned char smem[256 * 1024];

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

/// `dst = src` (thread 0; the block waits).
template <typename Tile>
void copy(const Tile& dst, const Tile& src) {
  if (threadIdx.x == 0) std::memcpy(dst.data, src.data, Tile::BYTES);
  __syncthreads();
}

enum class Solve { Lower, Upper, Cholesky };

template <Solve S, typename M, typename X>
void adj_solve(const M& m, const X& y, const M& adj_m, const X& adj_y, const X& r) {
  if (S == Solve::Lower) wp::adj_tile_lower_solve(m, y, adj_m, adj_y, r);
  if (S == Solve::Upper) wp::adj_tile_upper_solve(m, y, adj_m, adj_y, r);
  if (S == Solve::Cholesky) wp::adj_tile_cholesky_solve(m, y, adj_m, adj_y, r);
}

template <typename T, int N, int K>
void k_lin(args_t a) {
  using Mat = tile_t<T, N, N>;
  using Rhs = tile_t<T, N, K>;
  using Vec = tile_t<T, N>;
  size_t s = 0;
  auto M = slot_at<Mat>(s);
  auto Y = slot_at<Rhs>(s);
  auto Y1 = slot_at<Vec>(s);
  auto R = slot_at<Rhs>(s);
  auto R1 = slot_at<Vec>(s);
  auto A = slot_at<Mat>(s);
  auto RA = slot_at<Mat>(s);
  auto G = slot_at<Mat>(s);
  auto H = slot_at<Rhs>(s);
  auto H1 = slot_at<Vec>(s);
  auto seed = slot_at<Rhs>(s);
  auto seed1 = slot_at<Vec>(s);
  auto seedm = slot_at<Mat>(s);
  auto gm = slot_at<Mat>(s);
  auto hy = slot_at<Rhs>(s);
  auto hy1 = slot_at<Vec>(s);
  size_t in = 0, out = 0;
  get(a, in, M);
  get(a, in, Y);
  get(a, in, Y1);
  get(a, in, R);
  get(a, in, R1);
  get(a, in, A);
  get(a, in, RA);
  get(a, in, G);
  get(a, in, H);
  get(a, in, H1);
  auto run = [&](auto tag) {
    constexpr Solve S = decltype(tag)::value;
    copy(gm, G);
    copy(hy, H);
    copy(seed, R);
    adj_solve<S>(M, Y, gm, hy, seed);
    put(a, out, gm);
    put(a, out, hy);
    copy(gm, G);
    copy(hy1, H1);
    copy(seed1, R1);
    adj_solve<S>(M, Y1, gm, hy1, seed1);
    put(a, out, gm);
    put(a, out, hy1);
  };
  run(std::integral_constant<Solve, Solve::Lower>{});
  run(std::integral_constant<Solve, Solve::Upper>{});
  run(std::integral_constant<Solve, Solve::Cholesky>{});
  copy(gm, G);
  copy(seedm, RA);
  wp::adj_tile_cholesky(A, gm, seedm);
  put(a, out, gm);
}

template <typename T, int S>
void k_scan(args_t a) {
  using V = tile_t<T, S>;
  size_t s = 0;
  auto X = slot_at<V>(s);
  auto R = slot_at<V>(s);
  auto H = slot_at<V>(s);
  auto g = slot_at<V>(s);
  size_t in = 0, out = 0;
  get(a, in, X);
  get(a, in, R);
  get(a, in, H);
  copy(g, H);
  wp::adj_tile_scan_inclusive(X, g, R);
  put(a, out, g);
  copy(g, H);
  wp::adj_tile_scan_exclusive(X, g, R);
  put(a, out, g);
  copy(g, H);
  wp::adj_tile_scan_max_inclusive(X, g, R);
  put(a, out, g);
  copy(g, H);
  wp::adj_tile_scan_min_inclusive(X, g, R);
  put(a, out, g);
}

template <typename T, int N, int K>
std::pair<void (*)(args_t), size_t> lin() {
  return {k_lin<T, N, K>, sizeof(T) * (size_t)(3 * 2 * (N * N) + 3 * (N * K + N) + N * N)};
}

template <typename T, int S>
std::pair<void (*)(args_t), size_t> scan() {
  return {k_scan<T, S>, sizeof(T) * (size_t)(4 * S)};
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
  cases["lin_f64_5_3"] = lin<f64, 5, 3>();
  cases["lin_f32_32_4"] = lin<f32, 32, 4>();
  cases["lin_f32_40_2"] = lin<f32, 40, 2>();
  cases["lin_f64_1_1"] = lin<f64, 1, 1>();
  cases["scan_f32_37"] = scan<f32, 37>();
  cases["scan_f64_37"] = scan<f64, 37>();
  cases["scan_f64_1"] = scan<f64, 1>();
  std::ifstream in(argv[1]);
  std::string line;
  std::vector<unsigned char> input, out(256 * 1024);
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

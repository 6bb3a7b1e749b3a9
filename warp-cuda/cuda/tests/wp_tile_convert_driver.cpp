// wp_tile_convert_driver.cpp: runs wp_tile.h's conversions on the host, one block under the
// emulator (tests/cuda_tile_convert_host.rs compiles it for several block sizes with
// -DWP_TILE_BLOCK_DIM=<bd> and compares the output with warp-core's).
//
// Script (argv[1]), one command per line:
//   run NAME HEX   the case NAME on the bytes HEX: X (4 x 6 f32, row-major), then D (4 f32).
//                  Prints `out HEX`: tile_full(2.5) (4 x 6), tile_astype<i32>(X),
//                  tile_astype<f64>(X), tile_reshape<6, 4>(X), tile_squeeze of X's row 1 taken
//                  as a 1 x 6 tile, tile_diag_add(X's leading 4 x 4, D); then the adjoints with
//                  R = X as the result's adjoint: adj_tile_reshape into a zero 6 x 4 from R
//                  (4 x 6), adj_tile_diag_add into zero 4 x 4 and 4 from R's leading 4 x 4,
//                  adj_tile_astype into zero 4 x 6 f32 from `wide` and from `ints`, and
//                  adj_tile_full's value adjoint (from 0.25) from D (a block total: it
//                  depends on the block size).
#include "wp_prim_emu.h"
#include "wp_tile.h"
#include "wp_adjoint_tile.h"

#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

using wp::f32;
using wp::f64;
using wp::i32;
using wp::i64;
using wp::tile_t;

namespace {

struct args_t {
  const unsigned char* in;
  unsigned char* out;
};

alignas(16) static unsigned char smem[64 * 1024];

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

void k_convert(args_t a) {
  size_t s = 0;
  auto X = slot_at<tile_t<f32, 4, 6>>(s);
  auto D = slot_at<tile_t<f32, 4>>(s);
  auto full = slot_at<tile_t<f32, 4, 6>>(s);
  auto ints = slot_at<tile_t<i32, 4, 6>>(s);
  auto wide = slot_at<tile_t<f64, 4, 6>>(s);
  auto re = slot_at<tile_t<f32, 6, 4>>(s);
  auto row = slot_at<tile_t<f32, 1, 6>>(s);
  auto sq = slot_at<tile_t<f32, 6>>(s);
  auto sqr = slot_at<tile_t<f32, 4, 4>>(s);
  auto diag = slot_at<tile_t<f32, 4, 4>>(s);
  auto adj_re = slot_at<tile_t<f32, 6, 4>>(s);
  auto adj_a = slot_at<tile_t<f32, 4, 4>>(s);
  auto adj_d = slot_at<tile_t<f32, 4>>(s);
  auto adj_w = slot_at<tile_t<f32, 4, 6>>(s);
  auto adj_i = slot_at<tile_t<f32, 4, 6>>(s);
  size_t in = 0, out = 0;
  get(a, in, X);
  get(a, in, D);
  wp::tile_full(full, 2.5f);
  wp::tile_astype(ints, X);
  wp::tile_astype(wide, X);
  wp::tile_reshape(re, X);
  for (int j = (int)threadIdx.x; j < 6; j += WP_TILE_BLOCK_DIM) row.data[j] = X.data[6 + j];
  __syncthreads();
  wp::tile_reshape(sq, row);  // the emitter's tile_squeeze
  for (int e = (int)threadIdx.x; e < 16; e += WP_TILE_BLOCK_DIM) sqr.data[e] = X.data[(e / 4) * 6 + e % 4];
  __syncthreads();
  wp::tile_diag_add(diag, sqr, D);
  wp::tile_zeros(adj_re);
  wp::tile_zeros(adj_a);
  wp::tile_zeros(adj_d);
  wp::adj_tile_reshape(re, adj_re, X);
  wp::adj_tile_diag_add(sqr, D, adj_a, adj_d, sqr);
  wp::tile_zeros(adj_w);
  wp::tile_zeros(adj_i);
  wp::adj_tile_astype(X, adj_w, wide);
  wp::adj_tile_astype(X, adj_i, ints);
  f32 gx = 0.25f;
  wp::adj_tile_full(2.5f, gx, D);
  put(a, out, full);
  put(a, out, ints);
  put(a, out, wide);
  put(a, out, re);
  put(a, out, sq);
  put(a, out, diag);
  put(a, out, adj_re);
  put(a, out, adj_a);
  put(a, out, adj_d);
  put(a, out, adj_w);
  put(a, out, adj_i);
  if (threadIdx.x == 0) std::memcpy(a.out + out, &gx, sizeof gx);
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
  cases["convert"] = {k_convert, 4 * (24 + 24 + 24 + 6 + 16 + 24 + 16 + 4 + 24 + 24 + 1) + 8 * 24};
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

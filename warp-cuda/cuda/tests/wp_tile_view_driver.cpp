// wp_tile_view_driver.cpp: runs wp_tile.h's windows (tile_view, tile_window) and
// wp_adjoint_tile.h's adjoints of them on the host, one block under the emulator
// (tests/cuda_tile_view_host.rs compiles it for several block sizes with
// -DWP_TILE_BLOCK_DIM=<bd> and compares the output with warp-core's).
//
// Script (argv[1]), one command per line:
//   run NAME HEX   the case NAME on the bytes HEX: X (4 x 6 f32, row-major), S (2 x 3 f32),
//                  Y (8 f32), I (8 i32), J (3 i32). Prints `out HEX`, in this order:
//                  tile_view<2, 3>(X, 1, 2); tile_view(X, 3) (a row); tile_view<3>(Y, 5);
//                  X with S assigned at (2, 3); X with S added at (1, 0) then subtracted at
//                  (0, 1); I with J xor-ed at 4; the view of X at (3, 2) (outside: zeros) and
//                  its fault (kind, index[0..2], shape[0..2] as i64); then the adjoints into
//                  zero tiles: adj_tile_view2 (X, (1, 2), seed S) and adj_tile_view1 (row 3,
//                  seed Y's first 6) into one adj_X; adj_tile_assign2 at (2, 3) with adj_d = X
//                  (its own seed) and adj_s; adj_tile_add_inplace2 at (1, 0) and
//                  adj_tile_sub_inplace2 at (0, 1) with adj_d = X, into one adj_s.
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
using wp::i32;
using wp::i64;
using wp::tile_t;
using wp::u32;

namespace {

struct args_t {
  const unsigned char* in;
  unsigned char* out;
  wp::fault_t* fault;
  u32* flag;
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

template <typename Tile>
void copy(const Tile& out, const Tile& t) {
  for (int e = (int)threadIdx.x; e < Tile::SIZE; e += WP_TILE_BLOCK_DIM) out.data[e] = t.data[e];
  __syncthreads();
}

void k_view(args_t a) {
  wp::launch_ctx_t rec = wp::launch_ctx_make(a.fault, a.flag);
  wp::ctx_t c = wp::ctx_make(&rec);
  size_t s = 0;
  auto X = slot_at<tile_t<f32, 4, 6>>(s);
  auto S = slot_at<tile_t<f32, 2, 3>>(s);
  auto Y = slot_at<tile_t<f32, 8>>(s);
  auto I = slot_at<tile_t<i32, 8>>(s);
  auto J = slot_at<tile_t<i32, 3>>(s);
  auto v = slot_at<tile_t<f32, 2, 3>>(s);
  auto row = slot_at<tile_t<f32, 6>>(s);
  auto v1 = slot_at<tile_t<f32, 3>>(s);
  auto d = slot_at<tile_t<f32, 4, 6>>(s);
  auto e = slot_at<tile_t<f32, 4, 6>>(s);
  auto bad = slot_at<tile_t<f32, 2, 3>>(s);
  auto seed6 = slot_at<tile_t<f32, 6>>(s);
  auto adj_x = slot_at<tile_t<f32, 4, 6>>(s);
  auto adj_d = slot_at<tile_t<f32, 4, 6>>(s);
  auto adj_s = slot_at<tile_t<f32, 2, 3>>(s);
  auto adj_s2 = slot_at<tile_t<f32, 2, 3>>(s);
  size_t in = 0, out = 0;
  get(a, in, X);
  get(a, in, S);
  get(a, in, Y);
  get(a, in, I);
  get(a, in, J);
  wp::tile_view(v, X, 1, 2, &c);
  wp::tile_view(row, X, (i64)3, &c);
  wp::tile_view(v1, Y, 5u, &c);
  copy(d, X);
  wp::tile_assign(d, S, 2, 3, &c);
  copy(e, X);
  wp::tile_add_inplace(e, S, 1, 0, &c);
  wp::tile_sub_inplace(e, S, 0, 1, &c);
  wp::tile_bit_xor_inplace(I, J, 4, &c);
  const bool before = wp::faulted(&c);
  wp::tile_view(bad, X, 3, 2, &c);
  put(a, out, v);
  put(a, out, row);
  put(a, out, v1);
  put(a, out, d);
  put(a, out, e);
  put(a, out, I);
  put(a, out, bad);
  if (threadIdx.x == 0) {
    const i64 f[5] = {before ? -1 : (i64)a.fault->kind, a.fault->index[0], a.fault->index[1],
                      a.fault->shape[0], a.fault->shape[1]};
    std::memcpy(a.out + out, f, sizeof(f));
  }
  out += 5 * sizeof(i64);
  __syncthreads();
  // Adjoints.
  for (int k = (int)threadIdx.x; k < 6; k += WP_TILE_BLOCK_DIM) seed6.data[k] = Y.data[k];
  wp::tile_zeros(adj_x);
  wp::tile_zeros(adj_s);
  wp::tile_zeros(adj_s2);
  int o0 = 0, o1 = 0;
  i64 o64 = 0;
  wp::adj_tile_view2(X, 1, 2, adj_x, o0, o1, S, &c);
  wp::adj_tile_view1(X, (i64)3, adj_x, o64, seed6, &c);
  copy(adj_d, X);
  wp::adj_tile_assign2(d, S, 2, 3, adj_d, adj_s, o0, o1, adj_d, &c);
  put(a, out, adj_x);
  put(a, out, adj_d);
  put(a, out, adj_s);
  copy(adj_d, X);
  wp::adj_tile_sub_inplace2(e, S, 0, 1, adj_d, adj_s2, o0, o1, adj_d, &c);
  wp::adj_tile_add_inplace2(e, S, 1, 0, adj_d, adj_s2, o0, o1, adj_d, &c);
  put(a, out, adj_d);
  put(a, out, adj_s2);
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
  cases["view"] = {k_view, 4 * (6 + 6 + 3 + 24 + 24 + 8 + 6) + 8 * 5 + 4 * (24 + 24 + 6 + 24 + 6)};
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
    wp::fault_t fault{};
    u32 flag[2] = {0, 0};
    const args_t a{input.data(), out.data(), &fault, &flag[0]};
    wp_emu::launch(c->second.first, 1, WP_TILE_BLOCK_DIM, a);
    std::printf("out ");
    for (size_t i = 0; i < c->second.second; ++i) std::printf("%02x", out[i]);
    std::printf("\n");
  }
  return 0;
}

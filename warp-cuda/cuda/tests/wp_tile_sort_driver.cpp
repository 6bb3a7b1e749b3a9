// wp_tile_sort_driver.cpp: runs wp_tile_sort.h on the host, one block under the emulator
// (tests/cuda_tile_sort_host.rs compiles it for several block sizes with
// -DWP_TILE_BLOCK_DIM=<bd> and compares the output with warp-core's tile::sort).
//
// Script (argv[1]), one command per line:
//   run NAME HEX   the case NAME (key type, N) on the bytes HEX: the N keys, then N i64
//                  values. Prints `out HEX`: P = tile_sort(keys), then, as the emitter does for
//                  `tile_sort(&mut keys, &mut values)`, values = tile_permute(values, P) and
//                  keys = tile_permute(keys, P) in place; P, keys, values in that order.
#include "wp_prim_emu.h"
#include "wp_tile.h"
#include "wp_tile_sort.h"

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
using wp::u32;
using wp::u64;

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

template <typename K, int N>
void k_case(args_t a) {
  size_t s = 0;
  auto keys = slot_at<tile_t<K, N>>(s);
  auto vals = slot_at<tile_t<i64, N>>(s);
  auto p = slot_at<tile_t<i32, N>>(s);
  size_t in = 0, out = 0;
  get(a, in, keys);
  get(a, in, vals);
  wp::tile_sort(p, keys);
  wp::tile_permute(vals, vals, p);
  wp::tile_permute(keys, keys, p);
  put(a, out, p);
  put(a, out, keys);
  put(a, out, vals);
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
#define CASE(K, N) cases[#K "_" #N] = {k_case<K, N>, (sizeof(i32) + sizeof(K) + sizeof(i64)) * (size_t)N};
  CASE(f32, 1)
  CASE(f32, 7)
  CASE(f32, 64)
  CASE(f32, 100)
  CASE(f32, 1000)
  CASE(f64, 100)
  CASE(f64, 1000)
  CASE(i32, 100)
  CASE(u32, 100)
  CASE(i64, 100)
  CASE(u64, 100)
#undef CASE
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

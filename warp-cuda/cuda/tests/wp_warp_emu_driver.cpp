// wp_warp_emu_driver.cpp: the block emulator's warp-synchronous operations (wp_prim_emu.h:
// `__syncwarp`, `__shfl_sync`, `__shfl_down_sync`, `__shfl_up_sync`, `__ballot_sync`,
// `__match_any_sync`, and `__popc`, `__clz`) on small kernels of one block of 64 threads (two
// warps) or 16 (one partial warp); tests/cuda_warp_emu_host.rs runs each case and reads what
// it prints.
//
//   race       each lane writes its slot of shared memory and reads its neighbour's (lane + 1
//              of the same warp) with no __syncwarp between: prints `stale N`, the reads that
//              saw the slot before the neighbour wrote it (the emulator must show the race)
//   synced     the same with __syncwarp() between: `stale 0`
//   independent  warp 1 exchanges through shared memory 5 times with __syncwarp while warp 0
//              waits at __syncthreads: prints `ok B`, B the block barriers taken (1)
//   shfl       __shfl_sync (a rotation, a broadcast) and __shfl_down_sync: `ok` or what differs
//   divergent  lane 0 waits at __syncthreads, lanes 1..31 at __syncwarp: the emulator aborts
//   exited     lane 5 leaves the kernel, the others __syncwarp with it in the mask: aborts
//   vote       ballots, matches, __shfl_up_sync, __popc and __clz in two warps, and ballots and
//              matches in a partial warp of 16 with its own mask: `ok` or what differs
//   mixed      half a warp in a ballot, the other half in a shuffle of the same mask: aborts
//   past_block a block of 16 threads ballots with the whole warp's mask: aborts
//   up_outside __shfl_up_sync reads a lane below the mask's first: aborts
#include "wp_prim_emu.h"

#include <cstdio>
#include <cstring>
#include <string>

namespace {

struct args_t {
  int* out;
};

constexpr int THREADS = 64;
constexpr unsigned ALL = 0xffffffffu;

/// Each lane's slot, then its neighbour's read; `sync` puts a __syncwarp between.
template <bool Sync>
void k_neighbour(args_t a) {
  static int s[THREADS];
  const int t = (int)threadIdx.x, base = t - t % 32;
  // A value no lane writes, so that a read before the write shows.
  s[t] = -1;
  __syncthreads();
  s[t] = t + 1;
  if (Sync) __syncwarp(ALL);
  const int n = base + (t % 32 + 1) % 32;
  a.out[t] = s[n] != n + 1;
}

void k_independent(args_t a) {
  static int s[THREADS];
  const int t = (int)threadIdx.x;
  if (t >= 32) {
    // Warp 1 alone: a ring of exchanges that only warp barriers order.
    int v = t;
    for (int r = 0; r < 5; ++r) {
      s[t] = v;
      __syncwarp(ALL);
      v = s[32 + (t - 32 + 1) % 32];
      __syncwarp(ALL);
    }
    a.out[t] = v;
  }
  __syncthreads();
  a.out[t] = t < 32 ? 0 : a.out[t] - (32 + (t - 32 + 5) % 32);
}

void k_shfl(args_t a) {
  const int t = (int)threadIdx.x, lane = t % 32;
  int bad = 0;
  // A rotation: lane l reads lane l + 3 (mod 32) of its own warp.
  bad += __shfl_sync(ALL, t * 10, (lane + 3) % 32) != (t - lane + (lane + 3) % 32) * 10;
  // A broadcast of a double from lane 7.
  bad += __shfl_sync(ALL, 0.5 * t, 7) != 0.5 * (t - lane + 7);
  // Down by 4: past the warp's end the caller keeps its own value.
  const int d = __shfl_down_sync(ALL, t, 4);
  bad += d != (lane + 4 < 32 ? t + 4 : t);
  a.out[t] = bad;
}

void k_vote(args_t a) {
  const int t = (int)threadIdx.x, lane = t % 32;
  int bad = 0;
  // Ballot: the lanes whose index is a multiple of 3.
  unsigned want = 0;
  for (int l = 0; l < 32; l += 3) want |= 1u << l;
  bad += __ballot_sync(ALL, lane % 3 == 0) != want;
  // Match: the lanes with the same index mod 5 (a value that differs between the warps, so
  // a match across warps would show).
  unsigned peers = 0;
  for (int l = lane % 5; l < 32; l += 5) peers |= 1u << l;
  bad += __match_any_sync(ALL, (unsigned)(lane % 5 + 100 * (t / 32))) != peers;
  // Up by 3: the lowest three lanes keep their own; 64-bit values.
  const unsigned long long u = __shfl_up_sync(ALL, 1000ull * t, 3);
  bad += u != 1000ull * (lane >= 3 ? t - 3 : t);
  bad += __popc(0xf0f0u) != 8;
  bad += __clz(0) != 32;
  bad += __clz(1) != 31;
  bad += __clz(-1) != 0;
  a.out[t] = bad;
}

/// A block of 16 threads: a partial warp, its collectives on its own mask.
void k_vote16(args_t a) {
  const int t = (int)threadIdx.x;
  constexpr unsigned HALF = 0xffffu;
  int bad = 0;
  bad += __ballot_sync(HALF, t >= 10) != 0xfc00u;
  bad += __match_any_sync(HALF, t / 4) != (0xfu << (t / 4 * 4));
  bad += __shfl_up_sync(HALF, t, 1) != (t > 0 ? t - 1 : t);
  a.out[t] = bad;
}

void k_mixed(args_t) {
  if (threadIdx.x % 32 < 16) (void)__ballot_sync(ALL, 1);
  else (void)__shfl_sync(ALL, 1, 0);
}

void k_past_block(args_t) { (void)__ballot_sync(ALL, 1); }

void k_up_outside(args_t) {
  constexpr unsigned FROM4 = 0xfffffff0u;
  if (threadIdx.x % 32 >= 4) (void)__shfl_up_sync(FROM4, 1, 3);
}

void k_divergent(args_t) {
  if (threadIdx.x % 32 == 0) __syncthreads();
  else __syncwarp(ALL);
}

void k_exited(args_t) {
  if (threadIdx.x == 5) return;
  __syncwarp(ALL);
}

int sum(const int* v) {
  int n = 0;
  for (int i = 0; i < THREADS; ++i) n += v[i];
  return n;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CASE\n", argv[0]);
    return 2;
  }
  const std::string c = argv[1];
  int out[THREADS];
  std::memset(out, 0, sizeof(out));
  const args_t a{out};
  if (c == "race" || c == "synced") {
    wp_emu::launch(c == "race" ? k_neighbour<false> : k_neighbour<true>, 1, THREADS, a);
    std::printf("stale %d\n", sum(out));
  } else if (c == "independent") {
    const long long before = wp_emu::block_barriers;
    wp_emu::launch(k_independent, 1, THREADS, a);
    if (sum(out) != 0) std::printf("wrong %d\n", sum(out));
    else std::printf("ok %lld\n", wp_emu::block_barriers - before);
  } else if (c == "shfl") {
    wp_emu::launch(k_shfl, 1, THREADS, a);
    if (sum(out) != 0) std::printf("wrong %d\n", sum(out));
    else std::printf("ok\n");
  } else if (c == "vote") {
    wp_emu::launch(k_vote, 1, THREADS, a);
    wp_emu::launch(k_vote16, 1, 16, a);  // the first 16 slots again
    if (sum(out) != 0) std::printf("wrong %d\n", sum(out));
    else std::printf("ok\n");
  } else if (c == "mixed" || c == "past_block" || c == "up_outside") {
    if (c == "mixed") wp_emu::launch(k_mixed, 1, THREADS, a);
    if (c == "past_block") wp_emu::launch(k_past_block, 1, 16, a);
    if (c == "up_outside") wp_emu::launch(k_up_outside, 1, THREADS, a);
    std::printf("finished\n");
  } else if (c == "divergent") {
    wp_emu::launch(k_divergent, 1, THREADS, a);
    std::printf("finished\n");
  } else if (c == "exited") {
    wp_emu::launch(k_exited, 1, THREADS, a);
    std::printf("finished\n");
  } else {
    std::fprintf(stderr, "no case %s\n", c.c_str());
    return 2;
  }
  return 0;
}

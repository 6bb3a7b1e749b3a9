// wp_tile_sort.h: the tile sort, the CUDA side of warp-core/src/tile/sort.rs:
//
//   tile_sort(p, keys)         p[r] = the index of the r-th element of `keys` in the order
//                              below (the sorting permutation); `p` is a slot of its own
//   tile_permute(out, t, p)    out[r] = t[p[r]]; `out` may be `t` (the sort permutes in place)
//
// `tile_sort(&mut keys, &mut values)` lowers to `p = tile_sort(keys)`, then
// `values = tile_permute(values, p)` and `keys = tile_permute(keys, p)`.
//
// The order (warp-core's, so the permutation is the same bits on both backends): elements by
// (key, index), the index being the position before the sort. Keys compare with `<`, except
// that a NaN is after every number and NaNs tie (so they come last, in their original order);
// -0 and +0 tie. (key, index) is a strict total order, so every correct sort gives the one
// permutation; tests/cuda_tile_sort_host.rs runs this header under the block emulator against
// warp-core.
//
// The sort: a bitonic network over P, the power of two at least N, in the form whose every
// comparator puts the smaller element at the lower position (each merge starts with a mirror
// step, (i, i') with i' = the block's last index - (i's offset), then halving steps
// (i, i + j)). Positions N..P stand for elements after every real one: a comparator (i, q) with
// q >= N would keep them where they are, so it is skipped and no padding is stored. Each step is
// P / 2 independent comparators spread over the threads block-strided, one barrier after each:
// log2(P) (log2(P) + 1) / 2 barriers for any block size and length (55 for N = 1000). The keys
// are sorted in a shared copy alongside their indices, which go to `p`.
#pragma once

#include "wp_core.h"
#include "wp_tile.h"

namespace wp {

namespace tile_sort_detail {

/// Whether key `a` comes strictly before `b`: `<`, a NaN after every number, NaNs tied.
WP_LFN bool key_lt(f32 a, f32 b) { return !(a != a) && ((b != b) || a < b); }
WP_LFN bool key_lt(f64 a, f64 b) { return !(a != a) && ((b != b) || a < b); }
template <typename T>
WP_FN bool key_lt(T a, T b) {
  return a < b;
}

/// The smallest power of two >= n (n >= 1).
WP_LFN constexpr int pow2_at_least(int n, int p = 1) { return p >= n ? p : pow2_at_least(n, 2 * p); }

}  // namespace tile_sort_detail

/// `tile_sort(keys)`: the sorting permutation of a 1-D tile (see above).
template <typename K, int N>
WP_FN void tile_sort(const tile_t<i32, N>& p, const tile_t<K, N>& keys) {
  using tile_sort_detail::key_lt;
  constexpr int BD = WP_TILE_BLOCK_DIM;
  constexpr int P = tile_sort_detail::pow2_at_least(N);
  // The keys' working copy (the input stays as it is); bytes, as an element type with a
  // constructor may not be a __shared__ array.
  WP_TILE_SHARED_ALIGNED unsigned char key_bytes[N * sizeof(K)];
  K* kk = reinterpret_cast<K*>(key_bytes);
  const int l = (int)threadIdx.x;
  for (int i = l; i < N; i += BD) {
    kk[i] = keys.data[i];
    p.data[i] = i;
  }
  __syncthreads();
  for (int k = 2; k <= P; k <<= 1) {
    for (int j = k >> 1; j > 0; j >>= 1) {
      for (int c = l; c < P / 2; c += BD) {
        int i, q;
        if (j == (k >> 1)) {
          // The mirror step of a merge of blocks of k: offset o of block b with its mirror.
          const int b = c / j, o = c % j;
          i = b * k + o;
          q = b * k + k - 1 - o;
        } else {
          i = 2 * j * (c / j) + c % j;
          q = i + j;
        }
        if (q < N) {
          const K ki = kk[i], kq = kk[q];
          const i32 ii = p.data[i], iq = p.data[q];
          if (key_lt(kq, ki) || (!key_lt(ki, kq) && iq < ii)) {
            kk[i] = kq;
            kk[q] = ki;
            p.data[i] = iq;
            p.data[q] = ii;
          }
        }
      }
      __syncthreads();
    }
  }
}

/// `tile_permute(t, p)`: out[r] = t[p[r]], through a shared copy of `t`, so `out` may be `t`.
template <typename T, int N>
WP_FN void tile_permute(const tile_t<T, N>& out, const tile_t<T, N>& t, const tile_t<i32, N>& p) {
  constexpr int BD = WP_TILE_BLOCK_DIM;
  WP_TILE_SHARED_ALIGNED unsigned char bytes[N * sizeof(T)];
  T* copy = reinterpret_cast<T*>(bytes);
  const int l = (int)threadIdx.x;
  for (int i = l; i < N; i += BD) copy[i] = t.data[i];
  __syncthreads();
  for (int r = l; r < N; r += BD) out.data[r] = copy[p.data[r]];
  __syncthreads();
}

}  // namespace wp

// wp_tile_fft.h: FFTs of tiles of complex values, the CUDA side of warp-core/src/tile/fft.rs:
//
//   tile_fft(t)    each row of t: tile_t<Vec2 | DVec2, M, N> transformed in place along the
//                  last axis, X[k] = sum_j x[j] e^(-2 pi i jk / N) (numpy's fft)
//   tile_ifft(t)   the inverse, e^(+2 pi i jk / N), unnormalised (Warp's: ifft(fft(x)) = N x)
//   adj_tile_fft(t, adj_t, r), adj_tile_ifft(t, adj_t, r)   their adjoints, each the other
//                  transform of the seed, in the adjoint's slot
//
// N is a power of two. Every result is bit for bit warp-core's, for every block size: the
// roundings and their order are those fft.rs documents (separate IEEE adds, multiplies,
// divides and square roots; the section compiles without FMA contraction; no sin/cos, whose
// CUDA and Rust versions differ), only spread over the threads.
// tests/cuda_tile_fft_host.rs runs this header under the block emulator against warp-core.
//
// How the work is spread: the twiddle table w[k] = e^(+2 pi i k / N), k < N/2, is built in
// static shared memory, one entry per thread block-strided (each from the f64 half-angle
// cosines and sines of 2 pi / 2^j, about log2 N complex products, rounded once); then the
// radix-2 stages in passes of up to three: a pass splits each row into groups of 2^R elements
// closed under its R stages' pairings, and one thread loads a group, runs its R stages of
// butterflies in registers and stores it (radix-8 for N = 64: two passes, three barriers in
// all instead of seven, and a quarter of the shared-memory traffic). The first pass reads its
// groups from the bit-reversed places, all of a thread's groups before a barrier and the
// writes after it, so the permutation costs no pass of its own (when a thread's groups fit
// in FUSED_BYTES of registers; otherwise it is a pass of its own, one thread per swapped pair).
// Every butterfly is still the one fft.rs computes, with its operands and twiddle, so the
// grouping changes no bit.
#pragma once

#include "wp_core.h"
#include "wp_tile.h"

namespace wp {

namespace tile_fft_detail {

/// The parts' scalar of a complex element, and an f64 rounded to it.
template <typename C>
struct cx;
template <>
struct cx<Vec2> {
  typedef f32 S;
  static WP_FN S round(f64 v) { return (f32)v; }
};
template <>
struct cx<DVec2> {
  typedef f64 S;
  static WP_FN S round(f64 v) { return v; }
};

/// log2 of a power of two.
// Device-callable (as wp_tile.h's `tile_slot_end`): NVRTC runs without --expt-relaxed-constexpr.
WP_LFN constexpr int log2_pow2(int n) {
  int l = 0;
  for (; n > 1; n /= 2) ++l;
  return l;
}

/// The twiddle e^(+2 pi i k / 2^L) in f64 (warp-core's `twiddle64`): the half-angle (c, s) of
/// 2 pi / 2^j for j = 1..L, then the product over the set bits b of k, ascending, of those of
/// j = L - b, from (1, 0).
template <int L>
WP_FN void twiddle64(int k, f64* re_out, f64* im_out) {
  f64 bc[L > 0 ? L : 1], bs[L > 0 ? L : 1];
  f64 c = -1.0, s = 0.0;
  for (int j = 1; j <= L; ++j) {
    if (j == 2) {
      c = 0.0;
      s = 1.0;
    } else if (j > 2) {
      const f64 c2 = ::sqrt((1.0 + c) * 0.5);
      s = s / (c2 + c2);
      c = c2;
    }
    bc[j - 1] = c;
    bs[j - 1] = s;
  }
  f64 re = 1.0, im = 0.0;
  for (int b = 0; (k >> b) != 0; ++b) {
    if ((k >> b) & 1) {
      const f64 tc = bc[L - b - 1], ts = bs[L - b - 1];
      const f64 r = re * tc - im * ts;
      const f64 i = re * ts + im * tc;
      re = r;
      im = i;
    }
  }
  *re_out = re;
  *im_out = im;
}

/// Bits 0..L of i reversed.
template <int L>
WP_FN int bit_reverse(int i) {
  int r = 0;
  for (int b = 0; b < L; ++b) r |= ((i >> b) & 1) << (L - 1 - b);
  return r;
}

/// One butterfly of the order fft.rs documents: `u = w x1` (each product rounded, then the
/// sum; no FMA: --fmad=false), `x1 = x0 - u`, `x0 = x0 + u`; the forward transform conjugates
/// the table's `w`.
template <bool Inverse, typename C>
WP_FN void butterfly(C& x0, C& x1, const C w) {
  typedef typename cx<C>::S S;
  const S wr = w.x;
  const S wi = Inverse ? w.y : -w.y;
  const S ur = wr * x1.x - wi * x1.y;
  const S ui = wr * x1.y + wi * x1.x;
  C o0, o1;
  o1.x = x0.x - ur;
  o1.y = x0.y - ui;
  o0.x = x0.x + ur;
  o0.y = x0.y + ui;
  x0 = o0;
  x1 = o1;
}

WP_LFN constexpr int cdiv(int a, int b) { return (a + b - 1) / b; }

/// Stages S0 .. S0 + R of one group, in registers: the group is the 2^R elements
/// `base + j 2^S0` of a row (`base = g 2^(S0+R) + p`, `p < 2^S0`), closed under those stages'
/// pairings; at stage S0 + k the pair (j0, j0 + 2^k) sits at position `p + (j0 mod 2^k) 2^S0`
/// of its 2^(S0+k+1)-block, whose twiddle index that times N / 2^(S0+k+1) is.
template <bool Inverse, int S0, int R, int N, typename C>
WP_FN void group_stages(C (&v)[1 << R], int p, const C* tw) {
WP_TILE_UNROLL
  for (int k = 0; k < R; ++k) {
WP_TILE_UNROLL
    for (int blk = 0; blk < (1 << R); blk += (2 << k)) {
WP_TILE_UNROLL
      for (int jj = 0; jj < (1 << k); ++jj) {
        butterfly<Inverse>(v[blk + jj], v[blk + jj + (1 << k)],
                           tw[(p + (jj << S0)) * (N >> (S0 + k + 1))]);
      }
    }
  }
}

/// Where group q of a pass starts: its row's first element and `base`, `p` as above.
template <int S0, int R, int N>
WP_FN void group_at(int q, int* row, int* base, int* p) {
  constexpr int GPR = N / (1 << R);
  const int b = q % GPR;
  *row = (q / GPR) * N;
  *p = b & ((1 << S0) - 1);
  *base = ((b >> S0) << (S0 + R)) + *p;
}

/// The most bytes of complex values a thread keeps in registers across the first pass's
/// barrier: 64 32-bit registers (32 `Vec2`, 16 `DVec2`), past which they would spill.
constexpr int FUSED_BYTES = 256;

/// One pass: stages S0 .. S0 + R of every group, each group loaded, transformed in registers
/// and stored back by one thread, a barrier after. `First` fuses the bit-reversal permutation
/// into the loads: every group of the block is read (from the permuted places) before the
/// barrier and written after it, so it needs the thread's groups in registers (`PER` of them).
template <bool Inverse, bool First, int S0, int R, typename C, int M, int N>
WP_FN void pass(C* d, const C* tw) {
  constexpr int G = 1 << R;
  constexpr int NG = M * (N / G);
  constexpr int PER = First ? cdiv(NG, WP_TILE_BLOCK_DIM) : 1;
  constexpr int L = log2_pow2(N);
  if constexpr (First) {
    C v[PER][G];
WP_TILE_UNROLL
    for (int u = 0; u < PER; ++u) {
      const int q = (int)threadIdx.x + u * WP_TILE_BLOCK_DIM;
      if (q < NG) {
        int row, base, p;
        group_at<S0, R, N>(q, &row, &base, &p);
WP_TILE_UNROLL
        for (int j = 0; j < G; ++j) v[u][j] = d[row + bit_reverse<L>(base + (j << S0))];
      }
    }
    __syncthreads();
WP_TILE_UNROLL
    for (int u = 0; u < PER; ++u) {
      const int q = (int)threadIdx.x + u * WP_TILE_BLOCK_DIM;
      if (q < NG) {
        int row, base, p;
        group_at<S0, R, N>(q, &row, &base, &p);
        group_stages<Inverse, S0, R, N>(v[u], p, tw);
WP_TILE_UNROLL
        for (int j = 0; j < G; ++j) d[row + base + (j << S0)] = v[u][j];
      }
    }
  } else {
    for (int q = (int)threadIdx.x; q < NG; q += WP_TILE_BLOCK_DIM) {
      int row, base, p;
      group_at<S0, R, N>(q, &row, &base, &p);
      C v[G];
WP_TILE_UNROLL
      for (int j = 0; j < G; ++j) v[j] = d[row + base + (j << S0)];
      group_stages<Inverse, S0, R, N>(v, p, tw);
WP_TILE_UNROLL
      for (int j = 0; j < G; ++j) d[row + base + (j << S0)] = v[j];
    }
  }
  __syncthreads();
}

/// Stages S0 .. L in passes of at most three (eight values a group: two passes for N = 64),
/// the stages spread evenly over the passes.
template <bool Inverse, bool First, int S0, typename C, int M, int N>
WP_FN void passes(C* d, const C* tw) {
  constexpr int L = log2_pow2(N);
  if constexpr (S0 < L) {
    constexpr int LEFT = L - S0;
    constexpr int R = cdiv(LEFT, cdiv(LEFT, 3));
    pass<Inverse, First, S0, R, C, M, N>(d, tw);
    passes<Inverse, false, S0 + R, C, M, N>(d, tw);
  }
}

template <bool Inverse, typename C, int M, int N>
WP_FN void transform(const tile_t<C, M, N>& t) {
  static_assert((N & (N - 1)) == 0, "tile_fft: the last dim must be a power of two");
  constexpr int L = log2_pow2(N);
  constexpr int H = N / 2 > 0 ? N / 2 : 1;
  if constexpr (N >= 2) {
    // The table: static shared memory of its own, outside the tiles' slots. The first pass's
    // barrier (or the permutation's) orders its writes before any butterfly reads it.
    WP_TILE_SHARED_ALIGNED C tw[H];
    for (int k = (int)threadIdx.x; k < N / 2; k += WP_TILE_BLOCK_DIM) {
      f64 re, im;
      twiddle64<L>(k, &re, &im);
      tw[k].x = cx<C>::round(re);
      tw[k].y = cx<C>::round(im);
    }
    constexpr int R0 = cdiv(L, cdiv(L, 3));
    constexpr int PER0 = cdiv(M * (N >> R0), WP_TILE_BLOCK_DIM);
    if constexpr ((PER0 << R0) * (int)sizeof(C) <= FUSED_BYTES) {
      passes<Inverse, true, 0, C, M, N>(t.data, tw);
    } else {
      // Too many groups a thread to hold across a barrier: the permutation on its own (it
      // reads only elements no thread writes before the barrier), then plain passes.
      for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM) {
        const int i = e % N;
        const int j = bit_reverse<L>(i);
        if (i < j) {
          const int f = e - i + j;
          const C a = t.data[e];
          t.data[e] = t.data[f];
          t.data[f] = a;
        }
      }
      __syncthreads();
      passes<Inverse, false, 0, C, M, N>(t.data, tw);
    }
  } else {
    __syncthreads();
  }
}

}  // namespace tile_fft_detail

/// `tile_fft(&mut t)`.
template <typename C, int M, int N>
WP_FN void tile_fft(const tile_t<C, M, N>& t) {
  tile_fft_detail::transform<false>(t);
}

/// `tile_ifft(&mut t)` (unnormalised).
template <typename C, int M, int N>
WP_FN void tile_ifft(const tile_t<C, M, N>& t) {
  tile_fft_detail::transform<true>(t);
}

/// The adjoint of `tile_fft(&mut t)` (warp-core's tile::adjoint::adj_tile_fft): the inverse
/// transform of the seed. The transform is in place, so the seed `r` is a second tile over
/// the slot of `adj_t` (the sweep passes the same one): transforming it replaces the adjoint
/// after the transform with the adjoint before it.
template <typename C, int M, int N>
WP_FN void adj_tile_fft(const tile_t<C, M, N>&, const tile_t<C, M, N>& adj_t,
                        const tile_t<C, M, N>& r) {
  (void)r;
  tile_fft_detail::transform<true>(adj_t);
}

/// The adjoint of `tile_ifft(&mut t)`: the forward transform of the seed, as adj_tile_fft.
template <typename C, int M, int N>
WP_FN void adj_tile_ifft(const tile_t<C, M, N>&, const tile_t<C, M, N>& adj_t,
                         const tile_t<C, M, N>& r) {
  (void)r;
  tile_fft_detail::transform<false>(adj_t);
}

}  // namespace wp

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
// bit-reversal permutation of every row (element i of a row swaps with rev(i) when i < rev(i):
// one thread per pair); then log2 N radix-2 stages, each M * N/2 independent butterflies
// block-strided over the threads, with a barrier after each. A butterfly reads and writes only
// its own pair, so the threads' share of the work changes no bit.
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
WP_FN constexpr int log2_pow2(int n) {
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

template <bool Inverse, typename C, int M, int N>
WP_FN void transform(const tile_t<C, M, N>& t) {
  static_assert((N & (N - 1)) == 0, "tile_fft: the last dim must be a power of two");
  typedef typename cx<C>::S S;
  constexpr int L = log2_pow2(N);
  constexpr int H = N / 2 > 0 ? N / 2 : 1;
  if constexpr (N >= 2) {
    // The table: static shared memory of its own, outside the tiles' slots.
    WP_TILE_SHARED_ALIGNED C tw[H];
    for (int k = (int)threadIdx.x; k < N / 2; k += WP_TILE_BLOCK_DIM) {
      f64 re, im;
      twiddle64<L>(k, &re, &im);
      tw[k].x = cx<C>::round(re);
      tw[k].y = cx<C>::round(im);
    }
    // The permutation reads only elements that no thread writes before this barrier.
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
    // Stage s: pairs `half = 2^s` apart; the index arithmetic in shifts and masks (N is a
    // compile-time power of two, `half` one at run time).
    for (int s = 0; s < L; ++s) {
      const int half = 1 << s;
      const int step = N >> (s + 1);
      for (int q = (int)threadIdx.x; q < M * (N / 2); q += WP_TILE_BLOCK_DIM) {
        const int r = q / (N / 2), b = q % (N / 2);
        const int g = b >> s, p = b & (half - 1);
        const int i0 = r * N + (g << (s + 1)) + p;
        const int i1 = i0 + half;
        const C w = tw[p * step];
        const S wr = w.x;
        const S wi = Inverse ? w.y : -w.y;
        const C x1 = t.data[i1];
        const C x0 = t.data[i0];
        // u = w x1: each product rounded, then the sum (no FMA: --fmad=false).
        const S ur = wr * x1.x - wi * x1.y;
        const S ui = wr * x1.y + wi * x1.x;
        C o0, o1;
        o1.x = x0.x - ur;
        o1.y = x0.y - ui;
        o0.x = x0.x + ur;
        o0.y = x0.y + ui;
        t.data[i1] = o1;
        t.data[i0] = o0;
      }
      __syncthreads();
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

// wp_tile_linalg.h: dense linear algebra on tiles, the CUDA side of warp-core/src/tile/linalg.rs:
//
//   tile_cholesky(L, A)             L L^T = A, from A's lower triangle; all NaN when a pivot is
//                                   not positive (A not positive definite, or a NaN)
//   tile_lower_solve(X, L, Y)       L X = Y, forward substitution
//   tile_upper_solve(X, U, Z)       U X = Z, back substitution
//   tile_cholesky_solve(X, L, Y)    L L^T X = Y
//
// Y, Z, X are 1-D tiles of N elements or 2-D tiles of N x K (K right-hand sides). Every result
// is bit for bit warp-core's, for every block size: the roundings and their order are those
// linalg.rs documents (separate IEEE multiplies, subtractions, divisions and square roots; the
// section compiles without FMA contraction), only spread over the threads.
// tests/cuda_tile_linalg_host.rs runs this header under the block emulator against warp-core.
//
// How the work is spread (one barrier per column, N + 2 in all, for any block size):
// - Cholesky, right-looking on a symmetric working copy W (the output's slot): W starts as A
//   with its lower triangle mirrored to the upper. At step j every thread reads the pivot
//   W[j][j] (final since the last barrier) and computes d = sqrt(W[j][j]) and r = 1 / d in
//   registers. The threads then update the trailing square, W[i][k] -= (W[i][j] r) (W[j][k] r)
//   for i, k > j, which is warp-core's left-looking sum for L[i][k] term by term (k ascending):
//   the products are the same rounded values, and W stays exactly symmetric, so reading row j
//   instead of column j (contiguous, no bank conflicts) changes nothing. Column j - 1 is scaled
//   into L (by the previous step's r, kept in a register) during step j, when nothing reads it.
//   A non-positive pivot is seen by every thread alike, so the early exit is block-uniform.
// - Solves, column sweeps: at step i every thread computes x_i = X[i][c] / M[i][i] for its
//   columns and subtracts M[k][i] x_i from the rows k still below (forward) or above (back)
//   the sweep; row i - 1 (or i + 1) is divided by its diagonal in the same step. Each row
//   receives its subtractions in warp-core's order: j ascending forward, descending back.
//
// The output is a slot of its own (the emitter never aliases it with L), except that
// tile_cholesky is also correct in place (its first pass only writes the upper triangle, from
// the lower).
#pragma once

#include "wp_core.h"
#include "wp_tile.h"

namespace wp {

namespace tile_linalg_detail {

WP_FN f32 tsqrt(f32 v) { return ::sqrtf(v); }
WP_FN f64 tsqrt(f64 v) { return ::sqrt(v); }
WP_FN f32 tnan(f32) { return f32_nan(); }
WP_FN f64 tnan(f64) { return f64_nan(); }

/// The rows and columns of a right-hand side: `N` rows of `K` values.
template <typename X>
struct rhs;
template <typename T, int N>
struct rhs<tile_t<T, N>> {
  static constexpr int ROWS = N, COLS = 1;
};
template <typename T, int N, int K>
struct rhs<tile_t<T, N, K>> {
  static constexpr int ROWS = N, COLS = K;
};

/// Substitution in place on `x` (holding the right-hand side, rows of COLS values): solves
/// M x = b with M lower (`Lower`, i ascending) or upper triangular, where M[i][j] is
/// m[i][j], or m[j][i] when `Trans`. Ends in a barrier.
template <bool Lower, bool Trans, typename T, int N, typename X>
WP_FN void substitute(const tile_t<T, N, N>& m, const X& x) {
  constexpr int C = rhs<X>::COLS;
  static_assert(rhs<X>::ROWS == N, "the right-hand side has as many rows as the matrix");
  T* __restrict__ xs = x.data;
  const T* __restrict__ ms = m.data;
  for (int s = 0; s < N; ++s) {
    const int i = Lower ? s : N - 1 - s;
    const int prev = Lower ? i - 1 : i + 1;
    const T di = ms[i * N + i];
    for (int e = (int)threadIdx.x; e < N * C; e += WP_TILE_BLOCK_DIM) {
      const int k = e / C, c = e % C;
      if (s > 0 && k == prev) {
        // The row the last step finished: its solution.
        xs[e] = xs[e] / ms[prev * N + prev];
      } else if (Lower ? k > i : k < i) {
        const T mki = Trans ? ms[i * N + k] : ms[k * N + i];
        xs[e] = xs[e] - mki * (xs[i * C + c] / di);
      }
    }
    __syncthreads();
  }
  const int last = Lower ? N - 1 : 0;
  for (int c = (int)threadIdx.x; c < C; c += WP_TILE_BLOCK_DIM)
    xs[last * C + c] = xs[last * C + c] / ms[last * N + last];
  __syncthreads();
}

template <typename X>
WP_FN void copy_rhs(const X& out, const X& y) {
  constexpr int S = rhs<X>::ROWS * rhs<X>::COLS;
  for (int e = (int)threadIdx.x; e < S; e += WP_TILE_BLOCK_DIM) out.data[e] = y.data[e];
  __syncthreads();
}

}  // namespace tile_linalg_detail

/// `L = tile_cholesky(A)` (see the top of this file).
template <typename T, int N>
WP_FN void tile_cholesky(const tile_t<T, N, N>& out, const tile_t<T, N, N>& a) {
  using tile_linalg_detail::tsqrt;
  T* __restrict__ w = out.data;
  // W = A's lower triangle, mirrored (in place too: only the upper triangle is written, and
  // only from the lower).
  for (int e = (int)threadIdx.x; e < N * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, k = e % N;
    w[e] = i >= k ? a.data[e] : a.data[k * N + i];
  }
  __syncthreads();
  bool bad = false;
  T d_prev = (T)0, r_prev = (T)0;
  for (int j = 0; j < N; ++j) {
    const T p = w[j * N + j];
    // Every thread reads the same pivot: the branch is block-uniform.
    if (!(p > (T)0)) {
      bad = true;
      break;
    }
    const T d = tsqrt(p);
    const T r = (T)1 / d;
    // The trailing rows j + 1 .. N, whole (N is a compile-time constant, so `/` and `%` are
    // cheap; the columns up to j are skipped, about a third of the iterations over the factor).
    for (int e = (int)threadIdx.x; e < (N - 1 - j) * N; e += WP_TILE_BLOCK_DIM) {
      const int i = j + 1 + e / N, k = e % N;
      if (k > j) {
        const T li = w[i * N + j] * r;
        const T lk = w[j * N + k] * r;
        w[i * N + k] = w[i * N + k] - li * lk;
      }
    }
    // Column j - 1 into L: its diagonal and the elements below it.
    if (j > 0) {
      for (int i = j - 1 + (int)threadIdx.x; i < N; i += WP_TILE_BLOCK_DIM) {
        if (i == j - 1) w[i * N + i] = d_prev;
        else w[i * N + (j - 1)] = w[i * N + (j - 1)] * r_prev;
      }
    }
    d_prev = d;
    r_prev = r;
    __syncthreads();
  }
  // The last column's diagonal, the zero upper triangle; or NaN everywhere.
  for (int e = (int)threadIdx.x; e < N * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, k = e % N;
    if (bad) w[e] = tile_linalg_detail::tnan((T)0);
    else if (k > i) w[e] = (T)0;
    else if (i == N - 1 && k == N - 1) w[e] = d_prev;
  }
  __syncthreads();
}

/// `X = tile_lower_solve(L, Y)`: L X = Y.
template <typename T, int N, typename X>
WP_FN void tile_lower_solve(const X& out, const tile_t<T, N, N>& l, const X& y) {
  tile_linalg_detail::copy_rhs(out, y);
  tile_linalg_detail::substitute<true, false>(l, out);
}

/// `X = tile_upper_solve(U, Z)`: U X = Z.
template <typename T, int N, typename X>
WP_FN void tile_upper_solve(const X& out, const tile_t<T, N, N>& u, const X& z) {
  tile_linalg_detail::copy_rhs(out, z);
  tile_linalg_detail::substitute<false, false>(u, out);
}

/// `X = tile_cholesky_solve(L, Y)`: L L^T X = Y (forward with L, back with L^T).
template <typename T, int N, typename X>
WP_FN void tile_cholesky_solve(const X& out, const tile_t<T, N, N>& l, const X& y) {
  tile_linalg_detail::copy_rhs(out, y);
  tile_linalg_detail::substitute<true, false>(l, out);
  tile_linalg_detail::substitute<false, true>(l, out);
}

}  // namespace wp

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
// How the work is spread, for N <= 32 with a whole first warp (WP_TILE_BLOCK_DIM >= 32; the
// common case, e.g. the batched 32 x 32 solves of benches/gpu.rs --tile-cholesky): warp 0
// alone, warp-synchronously (__shfl_sync, no shared memory between lanes), the other warps
// waiting at the operation's one closing barrier (one __syncthreads per call instead of one per
// column). Lanes N .. 31 compute on zeros and store nothing.
// - Cholesky (cholesky_warp): lane k holds column k of the working matrix W (A's lower
//   triangle) in registers, right-looking. At step j every lane takes the pivot W[j][j] from
//   lane j, computes d = sqrt(W[j][j]) and r = 1 / d, and then, for i = j + 1 .. N - 1, takes
//   W[i][j] from lane j and forms L[i][j] = W[i][j] r; lane k > j keeps L[k][j] when i reaches k
//   and subtracts L[i][j] L[k][j] from W[i][k]: warp-core's sum for L[i][k] (or pivot k's),
//   term j, in the same order (j ascending), with the same rounded products. Two multiplies,
//   a subtraction, a shuffle and a select per element and step; no barrier.
// - Solves (sweep_warp): lane k holds row k of one right-hand side column in a register. At
//   step s every lane takes x_s = X[s] / M[s][s] from lane s's value, and the rows still to go
//   subtract M[k][s] x_s (forward: s ascending; back: descending), each row in warp-core's
//   order. The Cholesky solve runs both sweeps on the register: one load of Y, one store of X.
// Otherwise (N > 32, or blocks of fewer than 32 threads) the block-wide forms, one barrier per
// column, N + 2 in all, for any block size:
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
// tile_cholesky is also correct in place (the block-wide first pass only writes the upper
// triangle, from the lower; in the warp form each lane reads and writes only its own column,
// all reads before its writes).
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

/// Whether an N x N operation runs warp-synchronously: the matrix fits a warp (a lane per
/// column or row) and the block has a whole first warp. Otherwise the block-wide forms above.
template <int N>
struct in_warp {
  static constexpr bool value = N <= 32 && WP_TILE_BLOCK_DIM >= 32;
};

constexpr unsigned WARP_ALL = 0xffffffffu;

/// Cholesky by warp 0 alone (every lane calls it; see the top of this file): lane k holds column
/// k of the working matrix W in registers and right-looks, with no barrier and no shared memory
/// between the load of its column and the store of L's. Written for few instructions per
/// element update and few per-lane predicates (the compiler keeps one predicate per step, not
/// one per element):
/// - lane k's rows i < k (W's strict upper triangle) are scratch: loaded from whatever A holds
///   there and updated like the rest, never read back (every value a lane takes by shuffle, and
///   every value stored, is of its lower part), so the update needs no `i >= k` test;
/// - column j stays unscaled in lane j after step j (no lane updates it again); lane j keeps
///   that step's d and r and scales its column as it stores it (the same product W[i][j] r);
/// - a pivot that is not positive does not branch: the factor runs on (on NaNs) and the store
///   writes NaN everywhere, as warp-core.
template <typename T, int N>
WP_FN void cholesky_warp(T* w, const T* a) {
  const int k = (int)threadIdx.x;
  T c[N];
  // Row i across the lanes: no bank conflicts.
  WP_TILE_UNROLL
  for (int i = 0; i < N; ++i) c[i] = k < N ? a[i * N + k] : (T)0;
  bool ok = true;
  T dk = (T)0, rk = (T)0;
  WP_TILE_UNROLL
  for (int j = 0; j < N; ++j) {
    // The pivot W[j][j], final since step j - 1, from lane j: the same bits in every lane.
    const T p = __shfl_sync(WARP_ALL, c[j], j);
    ok = ok && p > (T)0;
    const T d = tsqrt(p);
    const T r = (T)1 / d;
    if (k == j) {
      dk = d;
      rk = r;
    }
    // The lanes that still update (columns right of j); the finished ones keep their bits.
    const bool live = k > j;
    // L[k][j], which lane k takes from the stream below at i == k, before its first use in its
    // lower part (rows i < k use 0: scratch).
    T lk = (T)0;
    WP_TILE_UNROLL
    for (int i = j + 1; i < N; ++i) {
      // L[i][j] = W[i][j] r, from lane j: every lane computes the same product.
      const T li = __shfl_sync(WARP_ALL, c[i], j) * r;
      lk = k == i ? li : lk;
      // warp-core's j-th term of L[i][k]'s sum (of pivot k's when i == k): j ascending.
      if (live) c[i] = c[i] - li * lk;
    }
  }
  // L's column k (row i across the lanes again), zero above the diagonal; or all NaN.
  if (k < N) {
    WP_TILE_UNROLL
    for (int i = 0; i < N; ++i)
      w[i * N + k] = !ok ? tnan((T)0) : i > k ? c[i] * rk : i == k ? dk : (T)0;
  }
}

/// One substitution sweep by warp 0 (every lane calls it) on `x`, lane k's row k of one
/// right-hand side column, in registers: M x = b with M lower (`Lower`, i ascending) or upper
/// triangular, M[i][j] being m[i][j], or m[j][i] when `Trans`. At step s every lane takes
/// x_s = x[s] / M[s][s] from lane s's value and the rows still to go subtract M[k][s] x_s: each
/// row receives its terms in warp-core's order (s ascending forward, descending back).
template <bool Lower, bool Trans, typename T, int N>
WP_FN T sweep_warp(const T* __restrict__ ms, T x) {
  const int k = (int)threadIdx.x;
  // `x` is one register and a shuffle takes its source lane from a register, so the loop needs
  // no unrolling; a little lets the loads of the next steps start early without holding all
  // N diagonals and coefficients in registers (which would cost the block occupancy).
  WP_TILE_UNROLL_N(4)
  for (int t = 0; t < N; ++t) {
    const int s = Lower ? t : N - 1 - t;
    const T xs = __shfl_sync(WARP_ALL, x, s) / ms[s * N + s];
    if (k == s) {
      x = xs;
    } else if (k < N && (Lower ? k > s : k < s)) {
      // M[k][s]: a row of m across the lanes when `Trans` (no bank conflicts), a column
      // otherwise.
      const T mks = Trans ? ms[s * N + k] : ms[k * N + s];
      x = x - mks * xs;
    }
  }
  return x;
}

/// `out` = the solution of the sweeps `Fwd` (with M = m, or m^T when `FwdTrans`) and, when
/// `Both`, then `Back` (M = m^T): warp 0 solves the right-hand side columns one after another,
/// each from `y` to `out` in registers (so `out` may be `y`); one barrier at the end.
template <bool Both, bool FwdLower, typename T, int N, typename X>
WP_FN void solve_warp(const X& out, const tile_t<T, N, N>& m, const X& y) {
  constexpr int C = rhs<X>::COLS;
  static_assert(rhs<X>::ROWS == N, "the right-hand side has as many rows as the matrix");
  const int k = (int)threadIdx.x;
  if (k < 32) {
  WP_TILE_UNROLL_N(1)
    for (int c = 0; c < C; ++c) {
      T x = k < N ? y.data[k * C + c] : (T)0;
      x = sweep_warp<FwdLower, false, T, N>(m.data, x);
      if (Both) x = sweep_warp<false, true, T, N>(m.data, x);
      if (k < N) out.data[k * C + c] = x;
    }
  }
  __syncthreads();
}

}  // namespace tile_linalg_detail

/// `L = tile_cholesky(A)` (see the top of this file).
template <typename T, int N>
WP_FN void tile_cholesky(const tile_t<T, N, N>& out, const tile_t<T, N, N>& a) {
  using tile_linalg_detail::tsqrt;
  if constexpr (tile_linalg_detail::in_warp<N>::value) {
    // Warp 0 factors; the other warps wait at the one barrier.
    if (threadIdx.x < 32) tile_linalg_detail::cholesky_warp<T, N>(out.data, a.data);
    __syncthreads();
    return;
  }
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
  if constexpr (tile_linalg_detail::in_warp<N>::value) {
    tile_linalg_detail::solve_warp<false, true>(out, l, y);
    return;
  }
  tile_linalg_detail::copy_rhs(out, y);
  tile_linalg_detail::substitute<true, false>(l, out);
}

/// `X = tile_upper_solve(U, Z)`: U X = Z.
template <typename T, int N, typename X>
WP_FN void tile_upper_solve(const X& out, const tile_t<T, N, N>& u, const X& z) {
  if constexpr (tile_linalg_detail::in_warp<N>::value) {
    tile_linalg_detail::solve_warp<false, false>(out, u, z);
    return;
  }
  tile_linalg_detail::copy_rhs(out, z);
  tile_linalg_detail::substitute<false, false>(u, out);
}

/// `X = tile_cholesky_solve(L, Y)`: L L^T X = Y (forward with L, back with L^T).
template <typename T, int N, typename X>
WP_FN void tile_cholesky_solve(const X& out, const tile_t<T, N, N>& l, const X& y) {
  if constexpr (tile_linalg_detail::in_warp<N>::value) {
    tile_linalg_detail::solve_warp<true, true>(out, l, y);
    return;
  }
  tile_linalg_detail::copy_rhs(out, y);
  tile_linalg_detail::substitute<true, false>(l, out);
  tile_linalg_detail::substitute<false, true>(l, out);
}

}  // namespace wp

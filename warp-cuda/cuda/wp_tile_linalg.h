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
// common case, e.g. the batched 32 x 32 solves of benches/gpu.rs --tile-cholesky): whole warps,
// warp-synchronously (__shfl_sync, no shared memory between lanes), the other warps waiting at
// the operation's one closing barrier (one __syncthreads per call instead of one per column).
// Lanes N .. 31 compute on zeros and store nothing.
// - Cholesky (cholesky_warp, warp 0): lane k holds column k of the working matrix W (A's lower
//   triangle) in registers, right-looking. At step j every lane takes the pivot W[j][j] from
//   lane j, computes d = sqrt(W[j][j]) and r = 1 / d, and then, for i = j + 1 .. N - 1, takes
//   W[i][j] from lane j and forms L[i][j] = W[i][j] r; lane k > j keeps L[k][j] when i reaches k
//   and subtracts L[i][j] L[k][j] from W[i][k]: warp-core's sum for L[i][k] (or pivot k's),
//   term j, in the same order (j ascending), with the same rounded products. Two multiplies,
//   a subtraction, a shuffle and a select per element and step; no barrier.
// - Solves (solve_warp; right-hand side column c to warp c mod warps): lane k holds row k of
//   its column in a register, and row k of the matrix in registers (row_warp: read along
//   diagonals, free of bank conflicts, then rotated into place). At step s every lane takes
//   x_s = X[s] / M[s][s] from lane s's value, and the rows still to go subtract M[k][s] x_s
//   (forward: s ascending; back: descending), each row in warp-core's order. The Cholesky
//   solve runs both sweeps on the register (the back one reading L's rows directly, which is
//   free of conflicts): one load of Y, one store of X.
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

WP_LFN f32 tsqrt(f32 v) { return ::sqrtf(v); }
WP_LFN f64 tsqrt(f64 v) { return ::sqrt(v); }
WP_LFN f32 tnan(f32) { return f32_nan(); }
WP_LFN f64 tnan(f64) { return f64_nan(); }

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

/// The warp forms are calls, not inlined (on the GPU): the generated kernel loops over the
/// block's tiles, and the compiler hoists what the tile operations compute from `threadIdx.x`
/// (addresses: dozens of registers) out of that loop, where inlined code would keep them live
/// across the whole factor and solve. Measured with ptxas (CUDA 12.9, sm_90) on the kernel of
/// benches/gpu.rs --tile-cholesky (f32, 32 x 32, 64 threads): 128 registers inlined, 96 as
/// calls.
#if defined(__CUDACC__)
#define WP_LINALG_CALL __device__ __noinline__
#else
#define WP_LINALG_CALL inline
#endif

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
WP_LINALG_CALL void cholesky_warp(T* w, const T* a) {
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

/// Row k of `ms` into lane k's registers, `row[s] = ms[k][s]`, without bank conflicts: a
/// column of a row-major 32-wide f32 tile lies in one bank, so reading `ms[k][s]` across the
/// lanes for each s would serialise (31 ways at the first step of a forward sweep). Instead
/// lane k reads its row from column k on, wrapping (`row[t] = ms[k][(k + t) mod N]`: each load
/// a diagonal, over distinct banks), then rotates its registers by k, a power of two per bit of
/// k (a select per element and bit: registers cannot be indexed by the lane).
template <typename T, int N>
WP_FN void row_warp(const T* __restrict__ ms, int k, T (&row)[N]) {
  WP_TILE_UNROLL
  for (int t = 0; t < N; ++t) {
    int col = k + t;
    if (col >= N) col -= N;
    row[t] = k < N ? ms[k * N + col] : (T)0;
  }
  // row[t] = ms[k][(k + t) mod N]; after the rotations by the bits b of k,
  // row[s] = old row[(s - k) mod N] = ms[k][s].
  WP_TILE_UNROLL
  for (int b = 1; b < N; b *= 2) {
    const bool on = (k & b) != 0;
    T prev[N];
    WP_TILE_UNROLL
    for (int s = 0; s < N; ++s) prev[s] = row[s];
    WP_TILE_UNROLL
    for (int s = 0; s < N; ++s) row[s] = on ? prev[(s - b + N) % N] : prev[s];
  }
}

/// Step s of a substitution sweep by a warp on `x`, lane k's row k of one right-hand side
/// column: every lane takes x_s = x[s] / M[s][s] from lane s's value; lane s keeps it, and the
/// rows still to go (below s when `Lower`, above otherwise) subtract M[k][s] x_s, `mks()` being
/// M[k][s] (called only by them). Over the steps (s ascending forward, descending back) each
/// row receives its terms in warp-core's order.
template <bool Lower, typename T, int N, typename Coef>
WP_FN T sweep_step(const T* __restrict__ ms, int k, int s, T x, Coef mks) {
  const T xs = __shfl_sync(WARP_ALL, x, s) / ms[s * N + s];
  if (k == s) return xs;
  if (k < N && (Lower ? k > s : k < s)) return x - mks() * xs;
  return x;
}

/// A sweep with M = m, its coefficients M[k][s] from lane k's row (`row_warp`).
template <bool Lower, typename T, int N>
WP_FN T sweep_rows(const T* __restrict__ ms, int k, const T (&row)[N], T x) {
  // Whole: `row` is indexed by the step.
  WP_TILE_UNROLL
  for (int t = 0; t < N; ++t) {
    const int s = Lower ? t : N - 1 - t;
    x = sweep_step<Lower, T, N>(ms, k, s, x, [&] { return row[s]; });
  }
  return x;
}

/// A sweep with M = m^T: M[k][s] = ms[s][k], row s of m across the lanes (no bank conflicts).
template <bool Lower, typename T, int N>
WP_FN T sweep_trans(const T* __restrict__ ms, int k, T x) {
  // A shuffle takes its source lane from a register, so the loop needs no unrolling; a little
  // lets the next steps' loads start early without holding them all in registers.
  WP_TILE_UNROLL_N(4)
  for (int t = 0; t < N; ++t) {
    const int s = Lower ? t : N - 1 - t;
    x = sweep_step<Lower, T, N>(ms, k, s, x, [&] { return ms[s * N + k]; });
  }
  return x;
}

/// `out` = the solution of M x = y: M = m lower (`Lower`) or upper triangular, and when
/// `Cholesky`, then m^T x = (that) (m lower). The right-hand side columns are spread over the
/// block's whole warps (column c to warp c mod warps), each warp sweeping its columns one after
/// another from `y` to `out` in a register (so `out` may be `y`), lane k with row k; a warp
/// with a column loads its lanes' rows of m once (`row_warp`). One barrier at the end.
template <bool Cholesky, bool Lower, typename T, int N, typename X>
WP_LINALG_CALL void solve_warp(const X out, const tile_t<T, N, N> m, const X y) {
  constexpr int C = rhs<X>::COLS;
  static_assert(rhs<X>::ROWS == N, "the right-hand side has as many rows as the matrix");
  // A partial last warp takes no column (its shuffles would name missing lanes). One column:
  // warp 0, spelled so that the compiler sees the lane and the column as known (measured with
  // ptxas on the benchmark's kernel: the general spelling costs it 40 more registers).
  constexpr int WARPS = C == 1 ? 1 : WP_TILE_BLOCK_DIM / 32;
  const int warp = (int)threadIdx.x / 32;
  if (warp < WARPS && warp < C) {
    const int k = (int)threadIdx.x % 32;
    T row[N];
    row_warp<T, N>(m.data, k, row);
    WP_TILE_UNROLL_N(1)
    for (int c = WARPS == 1 ? 0 : warp; c < C; c += WARPS) {
      T x = k < N ? y.data[k * C + c] : (T)0;
      x = sweep_rows<Lower, T, N>(m.data, k, row, x);
      if (Cholesky) x = sweep_trans<false, T, N>(m.data, k, x);
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

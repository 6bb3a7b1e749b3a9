// wp_adjoint_tile_linalg.h: the adjoints of the tile linear algebra (wp_tile_linalg.h), the
// CUDA side of warp-core/src/tile/adjoint_linalg.rs, whose docs give the rules and the order of
// every sum; the roundings here are the same ones in the same order (separate multiplies and
// adds, the section compiles without FMA contraction), so the gradients are warp-core's bits.
// tests/cuda_tile_linalg_adjoint_host.rs runs this header under the block emulator against
// warp-core.
//
//   adj_tile_lower_solve(L, Y, adj_L, adj_Y, R)      X = L^-1 Y
//   adj_tile_upper_solve(U, Z, adj_U, adj_Z, R)      X = U^-1 Z
//   adj_tile_cholesky_solve(L, Y, adj_L, adj_Y, R)   X = (L L^T)^-1 Y
//   adj_tile_cholesky(A, adj_A, R)                   L = chol(A), into A's lower triangle
//
// Cooperative as the forwards: every thread calls with the same arguments; each ends in a
// barrier. Each recomputes what it needs of the forward (the solution, the factor) with the
// forward's own function, so it sees the forward's bits, into static shared scratch (N x K for
// a solve's solution, twice for the Cholesky solve; N x N for the factor: counted with the
// kernel's static shared memory in the launch's budget; beyond CUDA's 48 KiB of static shared
// memory, e.g. a 64 x 64 f64 Cholesky solve's, a compile error naming the operation). The seed R is scratch too: its slot
// is the result's adjoint, which the sweep clears right after the call and nothing reads
// before, so the adjoint solves run in place there. The solves use the block-wide sweeps
// (tile_linalg_detail::substitute) at every size, which warp-core's order fixes as much as the
// warp forms.
#pragma once

#include "wp_adjoint_core.h"
#include "wp_tile_linalg.h"
#include "wp_adjoint_tile.h"

namespace wp {

namespace tile_linalg_adjoint_detail {

using tile_linalg_detail::rhs;
using tile_linalg_detail::substitute;

/// The static shared memory a block may declare (CUDA's limit: beyond it only dynamic shared
/// memory, which the tiles' slots use). Scratch above it fails at compile time with the
/// assertions below rather than with ptxas's "too much shared data".
constexpr usize STATIC_SHARED_LIMIT = 48 * 1024;

/// `adj[i][j] -= sum_c a[i][c] b[j][c]` (from zero, c ascending; rows of C values) over the
/// lower (`Lower`, i >= j) or upper triangle.
template <bool Lower, int C, typename T, int N>
WP_FN void sub_outer(const tile_t<T, N, N>& adj, const T* a, const T* b) {
  for (int e = (int)threadIdx.x; e < N * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, j = e % N;
    if (Lower ? i >= j : i <= j) {
      T s = (T)0;
      for (int c = 0; c < C; ++c) s = s + a[i * C + c] * b[j * C + c];
      adj.data[e] = adj.data[e] - s;
    }
  }
  __syncthreads();
}

/// `adj += w`, element by element.
template <typename X>
WP_FN void add_into(const X& adj, const X& w) {
  constexpr int S = rhs<X>::ROWS * rhs<X>::COLS;
  for (int e = (int)threadIdx.x; e < S; e += WP_TILE_BLOCK_DIM) adj.data[e] = adj.data[e] + w.data[e];
  __syncthreads();
}

}  // namespace tile_linalg_adjoint_detail

/// `X = tile_lower_solve(L, Y)`: W = L^-T R (in R), adj_Y += W, adj_L -= tril(W X^T).
template <typename T, int N, typename X>
WP_FN void adj_tile_lower_solve(const tile_t<T, N, N>& l, const X& y, const tile_t<T, N, N>& adj_l,
                                const X& adj_y, const X& r) {
  namespace d = tile_linalg_adjoint_detail;
  constexpr int C = d::rhs<X>::COLS;
  static_assert(sizeof(T) * N * C <= d::STATIC_SHARED_LIMIT,
                "backward through tile_lower_solve: its N x K scratch exceeds 48 KiB of static shared memory");
  WP_TILE_SHARED_ALIGNED T xs[d::rhs<X>::ROWS * C];
  const X x(xs);
  tile_lower_solve(x, l, y);
  d::substitute<false, true>(l, r);
  d::add_into(adj_y, r);
  d::sub_outer<true, C>(adj_l, r.data, x.data);
}

/// `X = tile_upper_solve(U, Z)`: W = U^-T R (in R), adj_Z += W, adj_U -= triu(W X^T).
template <typename T, int N, typename X>
WP_FN void adj_tile_upper_solve(const tile_t<T, N, N>& u, const X& z, const tile_t<T, N, N>& adj_u,
                                const X& adj_z, const X& r) {
  namespace d = tile_linalg_adjoint_detail;
  constexpr int C = d::rhs<X>::COLS;
  static_assert(sizeof(T) * N * C <= d::STATIC_SHARED_LIMIT,
                "backward through tile_upper_solve: its N x K scratch exceeds 48 KiB of static shared memory");
  WP_TILE_SHARED_ALIGNED T xs[d::rhs<X>::ROWS * C];
  const X x(xs);
  tile_upper_solve(x, u, z);
  d::substitute<true, true>(u, r);
  d::add_into(adj_z, r);
  d::sub_outer<false, C>(adj_u, r.data, x.data);
}

/// `X = tile_cholesky_solve(L, Y)` through Z = L^-1 Y, X = L^-T Z: Zbar = L^-1 R,
/// adj_L -= tril(X Zbar^T), Ybar = L^-T Zbar, adj_Y += Ybar, adj_L -= tril(Ybar Z^T).
template <typename T, int N, typename X>
WP_FN void adj_tile_cholesky_solve(const tile_t<T, N, N>& l, const X& y,
                                   const tile_t<T, N, N>& adj_l, const X& adj_y, const X& r) {
  namespace d = tile_linalg_adjoint_detail;
  constexpr int C = d::rhs<X>::COLS;
  static_assert(2 * sizeof(T) * N * C <= d::STATIC_SHARED_LIMIT,
                "backward through tile_cholesky_solve: its two N x K scratch tiles exceed 48 KiB of static shared memory");
  WP_TILE_SHARED_ALIGNED T zs[d::rhs<X>::ROWS * C];
  WP_TILE_SHARED_ALIGNED T xs[d::rhs<X>::ROWS * C];
  const X z(zs), x(xs);
  // The forward's two sweeps: Z, then X from a copy of it.
  tile_lower_solve(z, l, y);
  tile_linalg_detail::copy_rhs(x, z);
  d::substitute<false, true>(l, x);
  d::substitute<true, false>(l, r);
  d::sub_outer<true, C>(adj_l, x.data, r.data);
  d::substitute<false, true>(l, r);
  d::add_into(adj_y, r);
  d::sub_outer<true, C>(adj_l, r.data, z.data);
}

/// `L = tile_cholesky(A)`: W = Phi(L^T R) mirrored (in R), X = L^-T W, B = L^-T X^T (in R),
/// adj_A += B on the strict lower triangle and B / 2 on the diagonal.
template <typename T, int N>
WP_FN void adj_tile_cholesky(const tile_t<T, N, N>& a, const tile_t<T, N, N>& adj_a,
                             const tile_t<T, N, N>& r) {
  namespace d = tile_linalg_adjoint_detail;
  static_assert(sizeof(T) * N * N <= d::STATIC_SHARED_LIMIT,
                "backward through tile_cholesky: its N x N scratch exceeds 48 KiB of static shared memory");
  WP_TILE_SHARED_ALIGNED T ls[N * N];
  const tile_t<T, N, N> l(ls);
  tile_cholesky(l, a);
  T* __restrict__ w = r.data;
  // W's lower triangle in place, a column per thread, rows ascending: W[i][j] reads R's rows
  // i .. N - 1 of column j, which this thread has not overwritten yet.
  for (int j = (int)threadIdx.x; j < N; j += WP_TILE_BLOCK_DIM) {
    for (int i = j; i < N; ++i) {
      T s = (T)0;
      for (int k = i; k < N; ++k) s = s + ls[k * N + i] * w[k * N + j];
      w[i * N + j] = s;
    }
  }
  __syncthreads();
  // The mirror: the upper triangle from the lower (reads and writes apart).
  for (int e = (int)threadIdx.x; e < N * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, j = e % N;
    if (i < j) w[e] = w[j * N + i];
  }
  __syncthreads();
  d::substitute<false, true>(l, r);
  // X^T in place: each pair swapped by one thread.
  for (int e = (int)threadIdx.x; e < N * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, j = e % N;
    if (i > j) {
      const T t = w[e];
      w[e] = w[j * N + i];
      w[j * N + i] = t;
    }
  }
  __syncthreads();
  d::substitute<false, true>(l, r);
  for (int e = (int)threadIdx.x; e < N * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, j = e % N;
    if (i > j) adj_a.data[e] = adj_a.data[e] + w[e];
    else if (i == j) adj_a.data[e] = adj_a.data[e] + w[e] * (T)0.5;
  }
  __syncthreads();
}

}  // namespace wp

// wp_adjoint_matrix.h: adjoints of the non-square matrices' operators and builtins
// (warp-core/src/adjoint/matrix.rs, step for step: every rule accumulates in the order
// written there; a sum is formed first, in ascending index, then added).
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions.
#pragma once
#include "wp_adjoint_linalg.h"
#include "wp_adjoint_spatial.h"
#include "wp_matrix.h"

namespace wp {

template <typename M>
WP_FN WP_IF_RC(M, void) adj_add(const M&, const M&, M& adj_a, M& adj_b, const M& g) {
  adj_a += g;
  adj_b += g;
}
template <typename M>
WP_FN WP_IF_RC(M, void) adj_sub(const M&, const M&, M& adj_a, M& adj_b, const M& g) {
  adj_a += g;
  adj_b -= g;
}
template <typename M>
WP_FN WP_IF_RC(M, void) adj_neg(const M&, M& adj_a, const M& g) {
  adj_a -= g;
}
template <typename M>
WP_FN WP_IF_RC(M, void) adj_mul(const M& a, typename mshape<M>::scalar s, M& adj_a,
                                typename mshape<M>::scalar& adj_s, const M& g) {
  detail::zip_vs(a, s, adj_a, adj_s, g, detail::l_mul());
}
template <typename M>
WP_FN WP_IF_RC(M, void) adj_mul(typename mshape<M>::scalar s, const M& b,
                                typename mshape<M>::scalar& adj_s, M& adj_b, const M& g) {
  detail::zip_sv(s, b, adj_s, adj_b, g, detail::l_mul());
}
template <typename M>
WP_FN WP_IF_RC(M, void) adj_div(const M& a, typename mshape<M>::scalar s, M& adj_a,
                                typename mshape<M>::scalar& adj_s, const M& g) {
  detail::zip_vs(a, s, adj_a, adj_s, g, detail::l_div());
}

/// `m * x`: adj_m[i][j] += g[i] x[j], then adj_x[j] += sum_i m[i][j] g[i].
template <typename M>
WP_FN WP_IF_RC(M, void) adj_mul(const M& m, const typename mshape<M>::row& x, M& adj_m,
                                typename mshape<M>::row& adj_x,
                                const typename vec_of<typename mshape<M>::scalar, mshape<M>::R>::type& g) {
  typedef mshape<M> T;
  typedef typename T::row W;
  typedef typename vec_of<typename T::scalar, T::R>::type V;
  for (int i = 0; i < T::R; ++i)
    for (int j = 0; j < T::C; ++j) T::at(adj_m, i, j) += vec_traits<V>::get(g, i) * vec_traits<W>::get(x, j);
  for (int j = 0; j < T::C; ++j) {
    typename T::scalar r = T::get(m, 0, j) * vec_traits<V>::get(g, 0);
    for (int i = 1; i < T::R; ++i) r += T::get(m, i, j) * vec_traits<V>::get(g, i);
    vec_traits<W>::at(adj_x, j) += r;
  }
}

/// `a * b`: adj_a[i][k] += sum_j g[i][j] b[k][j], then adj_b[k][j] += sum_i a[i][k] g[i][j].
template <typename A, typename B>
WP_FN typename detail::rc_enable<(mshape<A>::is_rc || mshape<B>::is_rc) && mshape<A>::is_mat &&
                                     mshape<B>::is_mat && mshape<A>::C == mshape<B>::R,
                                 void>::type
adj_mul(const A& a, const B& b, A& adj_a, B& adj_b,
        const typename mat_of<typename mshape<A>::scalar, mshape<A>::R, mshape<B>::C>::type& g) {
  typedef typename mat_of<typename mshape<A>::scalar, mshape<A>::R, mshape<B>::C>::type O;
  typedef typename mshape<A>::scalar S;
  constexpr int R = mshape<A>::R, K = mshape<A>::C, C = mshape<B>::C;
  for (int i = 0; i < R; ++i)
    for (int k = 0; k < K; ++k) {
      S r = mshape<O>::get(g, i, 0) * mshape<B>::get(b, k, 0);
      for (int j = 1; j < C; ++j) r += mshape<O>::get(g, i, j) * mshape<B>::get(b, k, j);
      mshape<A>::at(adj_a, i, k) += r;
    }
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < C; ++j) {
      S r = mshape<A>::get(a, 0, k) * mshape<O>::get(g, 0, j);
      for (int i = 1; i < R; ++i) r += mshape<A>::get(a, i, k) * mshape<O>::get(g, i, j);
      mshape<B>::at(adj_b, k, j) += r;
    }
}

/// `transpose(m)`: adj_m += g^T.
template <typename M>
WP_FN WP_IF_RC(M, void) adj_transpose(
    const M&, M& adj_m,
    const typename mat_of<typename mshape<M>::scalar, mshape<M>::C, mshape<M>::R>::type& g) {
  adj_m += transpose(g);
}

/// `outer(a, b)`: adj_a[i] += sum_j g[i][j] b[j], then adj_b[j] += sum_i g[i][j] a[i].
template <typename A, typename B>
WP_FN typename detail::rc_enable<vshape<A>::is_vec && vshape<B>::is_vec && vshape<A>::N != vshape<B>::N,
                                 void>::type
adj_outer(const A& a, const B& b, A& adj_a, B& adj_b,
          const typename mat_of<typename vshape<A>::scalar, vshape<A>::N, vshape<B>::N>::type& g) {
  typedef typename mat_of<typename vshape<A>::scalar, vshape<A>::N, vshape<B>::N>::type O;
  typedef typename vshape<A>::scalar S;
  constexpr int N = vshape<A>::N, M = vshape<B>::N;
  for (int i = 0; i < N; ++i) {
    S r = mshape<O>::get(g, i, 0) * vec_traits<B>::get(b, 0);
    for (int j = 1; j < M; ++j) r += mshape<O>::get(g, i, j) * vec_traits<B>::get(b, j);
    vec_traits<A>::at(adj_a, i) += r;
  }
  for (int j = 0; j < M; ++j) {
    S r = mshape<O>::get(g, 0, j) * vec_traits<A>::get(a, 0);
    for (int i = 1; i < N; ++i) r += mshape<O>::get(g, i, j) * vec_traits<A>::get(a, i);
    vec_traits<B>::at(adj_b, j) += r;
  }
}

/// `ddot(a, b)`: adj_a[k] += g b[k], adj_b[k] += g a[k], row by row.
template <typename M>
WP_FN WP_IF_RC(M, void) adj_ddot(const M& a, const M& b, M& adj_a, M& adj_b,
                                 typename mshape<M>::scalar g) {
  for (int k = 0; k < vec_traits<M>::N; ++k) {
    vec_traits<M>::at(adj_a, k) += g * vec_traits<M>::get(b, k);
    vec_traits<M>::at(adj_b, k) += g * vec_traits<M>::get(a, k);
  }
}

}  // namespace wp

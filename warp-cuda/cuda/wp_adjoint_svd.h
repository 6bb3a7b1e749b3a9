// wp_adjoint_svd.h: adjoints of the "svd" section (decompositions and their tuples).
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions. An adjoint
// translation unit includes wp_adjoint_core.h and the adjoint headers of the builtin-table
// sections its kernel uses (warp_cuda::ADJOINT_SECTIONS), so NVRTC parses no more than it
// needs.
#pragma once
#include "wp_adjoint_linalg.h"
#include "wp_svd.h"

namespace wp {

// ------------------------------------------------------------------------------------------
// Decompositions (warp-core/src/adjoint/svd.rs): tuple adjoints, adj_svd3, adj_svd2,
// adj_eig3, adj_qr3 (Warp's formulas; products on rows, left to right, as on the CPU)
// ------------------------------------------------------------------------------------------

// Tuples' zero and accumulation: wp_adjoint_core.h.

namespace detail {
namespace svd {
template <typename S, int N, typename F>
WP_FN void zip_rows(const S (&a)[N][N], const S (&b)[N][N], S (&out)[N][N], F f) {
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) out[i][j] = f(a[i][j], b[i][j]);
}
template <typename S>
WP_FN S sub_(S x, S y) { return x - y; }
template <typename S>
WP_FN S add_(S x, S y) { return x + y; }
template <typename S>
WP_FN S mul_(S x, S y) { return x * y; }
/// A difference moved to at least eps in magnitude (+eps for an exact 0; NaN stays).
template <typename S>
WP_FN S gap(S d) {
  const S eps = cfg<S>::eps();
  if (d >= (S)0 && d < eps) return eps;
  if (d < (S)0 && d > -eps) return -eps;
  return d;
}
template <typename S>
WP_FN rows2<S> mul2(const rows2<S>& a, const rows2<S>& b) {
  rows2<S> r;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) r.m[i][j] = a.m[i][0] * b.m[0][j] + a.m[i][1] * b.m[1][j];
  return r;
}
template <typename S>
WP_FN rows2<S> mul2_tn(const rows2<S>& a, const rows2<S>& b) {
  rows2<S> r;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) r.m[i][j] = a.m[0][i] * b.m[0][j] + a.m[1][i] * b.m[1][j];
  return r;
}
template <typename S>
WP_FN rows2<S> mul2_nt(const rows2<S>& a, const rows2<S>& b) {
  rows2<S> r;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) r.m[i][j] = a.m[i][0] * b.m[j][0] + a.m[i][1] * b.m[j][1];
  return r;
}

/// The SVD adjoint shared by svd3 (N = 3) and svd2 (N = 2): u_term + v_term + sigma_term.
template <typename S, int N, typename R, typename Mul, typename MulTn, typename MulNt>
WP_FN R adj_svd_rows(const R& u, const S* s, const R& v, const R& gu, const S* gs, const R& gv,
                     Mul mul, MulTn mul_tn, MulNt mul_nt) {
  const S one = (S)1, z = (S)0, eps = -cfg<S>::eps();
  R f;
  for (int i = 0; i < N; ++i) f.m[i][i] = z;
  for (int i = 0; i < N; ++i)
    for (int j = i + 1; j < N; ++j) {
      const S fij = one / wp::min(s[j] * s[j] - s[i] * s[i], eps);
      f.m[i][j] = fij;
      f.m[j][i] = -fij;
    }
  R us;
  for (int i = 0; i < N; ++i)
    for (int k = 0; k < N; ++k) us.m[i][k] = u.m[i][k] * gs[k];
  const R sigma_term = mul_nt(us, v);
  R d, ku, kv, t;
  zip_rows(mul_tn(u, gu).m, mul_tn(gu, u).m, d.m, sub_<S>);
  zip_rows(f.m, d.m, ku.m, mul_<S>);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) t.m[i][j] = ku.m[i][j] * s[j];
  const R u_term = mul_nt(mul(u, t), v);
  zip_rows(mul_tn(v, gv).m, mul_tn(gv, v).m, d.m, sub_<S>);
  zip_rows(f.m, d.m, kv.m, mul_<S>);
  const R kv_vt = mul_nt(kv, v);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) t.m[i][j] = s[i] * kv_vt.m[i][j];
  const R v_term = mul(u, t);
  R total;
  zip_rows(u_term.m, v_term.m, total.m, add_<S>);
  zip_rows(total.m, sigma_term.m, total.m, add_<S>);
  return total;
}
}  // namespace svd
}  // namespace detail

#define WP_ADJ_SVD3(M, V, S)                                                                  \
  WP_LFN void adj_svd3(const M& a, M& adj_a, const tuple_t<M, V, M>& g) {                      \
    namespace d = detail::svd;                                                                \
    d::rows3<S> u, v;                                                                         \
    S s[3];                                                                                   \
    d::svd3_rows(d::to_rows<3>(a), u, s, v);                                                    \
    const S gs[3] = {g.f1.x, g.f1.y, g.f1.z};                                                 \
    const d::rows3<S> total = d::adj_svd_rows<S, 3>(                                          \
        u, s, v, d::to_rows<3>(g.f0), gs, d::to_rows<3>(g.f2), d::mul3<S>, d::mul3_tn<S>,         \
        d::mul3_nt<S>);                                                                       \
    adj_accum(adj_a, d::from_rows<M>(total));                                                \
  }                                                                                           \
  WP_LFN void adj_eig3(const M& a, M& adj_a, const tuple_t<M, V>& g) {                         \
    namespace d = detail::svd;                                                                \
    d::rows3<S> q;                                                                            \
    S e[3];                                                                                   \
    d::eig3_rows(d::to_rows<3>(a), q, e);                                                       \
    const S gd[3] = {g.f1.x, g.f1.y, g.f1.z};                                                 \
    const S one = (S)1, z = (S)0;                                                             \
    const S f01 = one / d::gap(e[1] - e[0]);                                                  \
    const S f02 = one / d::gap(e[2] - e[0]);                                                  \
    const S f12 = one / d::gap(e[2] - e[1]);                                                  \
    const S f[3][3] = {{z, f01, f02}, {-f01, z, f12}, {-f02, -f12, z}};                       \
    const S dbar[3][3] = {{gd[0], z, z}, {z, gd[1], z}, {z, z, gd[2]}};                       \
    d::rows3<S> h, inner;                                                                     \
    d::zip_rows(f, d::mul3_tn(q, d::to_rows<3>(g.f0)).m, h.m, d::mul_<S>);                      \
    d::zip_rows(dbar, h.m, inner.m, d::add_<S>);                                              \
    adj_accum(adj_a, d::from_rows<M>(d::mul3(q, d::mul3_nt(inner, q))));                     \
  }                                                                                           \
  WP_LFN void adj_qr3(const M& a, M& adj_a, const tuple_t<M, M>& g) {                          \
    namespace d = detail::svd;                                                                \
    d::rows3<S> q, r;                                                                         \
    d::qr_rows(d::to_rows<3>(a), q, r);                                                         \
    const d::rows3<S> gq = d::to_rows<3>(g.f0), gr = d::to_rows<3>(g.f1);                         \
    d::rows3<S> m, c, x, rt;                                                                  \
    d::zip_rows(d::mul3_nt(r, gr).m, d::mul3_tn(gq, q).m, m.m, d::sub_<S>);                   \
    for (int i = 0; i < 3; ++i)                                                               \
      for (int j = 0; j < 3; ++j) {                                                           \
        c.m[i][j] = m.m[i > j ? i : j][i < j ? i : j];                                        \
        rt.m[i][j] = r.m[j][i];                                                               \
      }                                                                                       \
    d::zip_rows(gq.m, d::mul3(q, c).m, x.m, d::add_<S>);                                      \
    const d::rows3<S> inv = d::to_rows<3>(inverse(d::from_rows<M>(rt)));                       \
    adj_accum(adj_a, d::from_rows<M>(d::mul3(x, inv)));                                      \
  }
WP_ADJ_SVD3(Mat3, Vec3, f32)
WP_ADJ_SVD3(DMat3, DVec3, f64)
#undef WP_ADJ_SVD3

#define WP_ADJ_SVD2(M, V, S)                                                                  \
  WP_LFN void adj_svd2(const M& a, M& adj_a, const tuple_t<M, V, M>& g) {                      \
    namespace d = detail::svd;                                                                \
    d::rows2<S> u, v;                                                                         \
    S s[2];                                                                                   \
    d::svd2_rows(d::to_rows<2>(a), u, s, v);                                                    \
    const S gs[2] = {g.f1.x, g.f1.y};                                                         \
    const d::rows2<S> total = d::adj_svd_rows<S, 2>(                                          \
        u, s, v, d::to_rows<2>(g.f0), gs, d::to_rows<2>(g.f2), d::mul2<S>, d::mul2_tn<S>,         \
        d::mul2_nt<S>);                                                                       \
    adj_accum(adj_a, d::from_rows<M>(total));                                                \
  }
WP_ADJ_SVD2(Mat2, Vec2, f32)
WP_ADJ_SVD2(DMat2, DVec2, f64)
#undef WP_ADJ_SVD2

}  // namespace wp

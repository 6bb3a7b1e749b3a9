// wp_adjoint_spatial.h: adjoints of the spatial vectors and matrices: their operators and the
// "spatial" section (warp-core/src/adjoint/spatial.rs, step for step: every rule accumulates in
// the order written there; a sum is formed first, in ascending index, then added).
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions. An adjoint
// translation unit includes wp_adjoint_core.h and the adjoint headers of the builtin-table
// sections its kernel uses (warp_cuda::ADJOINT_SECTIONS), so NVRTC parses no more than it
// needs.
#pragma once
#include "wp_adjoint_builtins.h"
#include "wp_adjoint_transform.h"
#include "wp_spatial.h"

namespace wp {

// The lane-by-lane operators of a spatial type T of scalar S.
#define WP_ADJ_SPATIAL_LANES(T, S)                                                             \
  WP_LFN void adj_add(const T&, const T&, T& adj_a, T& adj_b, const T& g) {                     \
    adj_a += g;                                                                                \
    adj_b += g;                                                                                \
  }                                                                                            \
  WP_LFN void adj_sub(const T&, const T&, T& adj_a, T& adj_b, const T& g) {                     \
    adj_a += g;                                                                                \
    adj_b -= g;                                                                                \
  }                                                                                            \
  WP_LFN void adj_neg(const T&, T& adj_a, const T& g) { adj_a -= g; }                           \
  WP_LFN void adj_mul(const T& a, S s, T& adj_a, S& adj_s, const T& g) {                        \
    detail::zip_vs(a, s, adj_a, adj_s, g, detail::l_mul());                                    \
  }                                                                                            \
  WP_LFN void adj_mul(S s, const T& b, S& adj_s, T& adj_b, const T& g) {                        \
    detail::zip_sv(s, b, adj_s, adj_b, g, detail::l_mul());                                    \
  }                                                                                            \
  WP_LFN void adj_div(const T& a, S s, T& adj_a, S& adj_s, const T& g) {                        \
    detail::zip_vs(a, s, adj_a, adj_s, g, detail::l_div());                                    \
  }

#define WP_ADJ_SPATIAL(SV, SM, V3, M3, X, S)                                                   \
  WP_ADJ_SPATIAL_LANES(SV, S)                                                                  \
  WP_ADJ_SPATIAL_LANES(SM, S)                                                                  \
  /* m * x: adj_m[i][j] += g[i] x[j]; adj_x[j] += sum_i m[i][j] g[i] */                        \
  WP_LFN void adj_mul(const SM& m, const SV& x, SM& adj_m, SV& adj_x, const SV& g) {            \
    typedef vec_traits<SM> TM;                                                                 \
    typedef vec_traits<SV> TV;                                                                 \
    for (int i = 0; i < 6; ++i)                                                                \
      for (int j = 0; j < 6; ++j) TM::at(adj_m, i * 6 + j) += TV::get(g, i) * TV::get(x, j);   \
    for (int j = 0; j < 6; ++j) {                                                              \
      S r = TM::get(m, j) * TV::get(g, 0);                                                     \
      for (int i = 1; i < 6; ++i) r += TM::get(m, i * 6 + j) * TV::get(g, i);                  \
      TV::at(adj_x, j) += r;                                                                   \
    }                                                                                          \
  }                                                                                            \
  /* a * b: adj_a[i][k] += sum_j g[i][j] b[k][j]; adj_b[k][j] += sum_i a[i][k] g[i][j] */      \
  WP_LFN void adj_mul(const SM& a, const SM& b, SM& adj_a, SM& adj_b, const SM& g) {            \
    typedef vec_traits<SM> TM;                                                                 \
    for (int i = 0; i < 6; ++i)                                                                \
      for (int k = 0; k < 6; ++k) {                                                            \
        S r = TM::get(g, i * 6) * TM::get(b, k * 6);                                           \
        for (int j = 1; j < 6; ++j) r += TM::get(g, i * 6 + j) * TM::get(b, k * 6 + j);        \
        TM::at(adj_a, i * 6 + k) += r;                                                         \
      }                                                                                        \
    for (int k = 0; k < 6; ++k)                                                                \
      for (int j = 0; j < 6; ++j) {                                                            \
        S r = TM::get(a, k) * TM::get(g, j);                                                   \
        for (int i = 1; i < 6; ++i) r += TM::get(a, i * 6 + k) * TM::get(g, i * 6 + j);       \
        TM::at(adj_b, k * 6 + j) += r;                                                         \
      }                                                                                        \
  }                                                                                            \
  WP_LFN void adj_transpose(const SM&, SM& adj_m, const SM& g) { adj_m += transpose(g); }       \
  WP_LFN void adj_outer(const SV& a, const SV& b, SV& adj_a, SV& adj_b, const SM& g) {          \
    typedef vec_traits<SM> TM;                                                                 \
    typedef vec_traits<SV> TV;                                                                 \
    for (int i = 0; i < 6; ++i) {                                                              \
      S r = TM::get(g, i * 6) * TV::get(b, 0);                                                 \
      for (int j = 1; j < 6; ++j) r += TM::get(g, i * 6 + j) * TV::get(b, j);                  \
      TV::at(adj_a, i) += r;                                                                   \
    }                                                                                          \
    for (int j = 0; j < 6; ++j) {                                                              \
      S r = TM::get(g, j) * TV::get(a, 0);                                                     \
      for (int i = 1; i < 6; ++i) r += TM::get(g, i * 6 + j) * TV::get(a, i);                  \
      TV::at(adj_b, j) += r;                                                                   \
    }                                                                                          \
  }                                                                                            \
  WP_LFN void adj_spatial_vector(const V3&, const V3&, V3& adj_w, V3& adj_v, const SV& g) {     \
    adj_w += spatial_top(g);                                                                   \
    adj_v += spatial_bottom(g);                                                                \
  }                                                                                            \
  WP_LFN void adj_spatial_vector_scalars(S, S, S, S, S, S, S& a0, S& a1, S& a2, S& a3, S& a4,   \
                                        S& a5, const SV& g) {                                  \
    a0 += g.f0;                                                                                \
    a1 += g.f1;                                                                                \
    a2 += g.f2;                                                                                \
    a3 += g.f3;                                                                                \
    a4 += g.f4;                                                                                \
    a5 += g.f5;                                                                                \
  }                                                                                            \
  WP_LFN void adj_spatial_top(const SV&, SV& adj_a, const V3& g) {                              \
    adj_a = SV##_new(spatial_top(adj_a) + g, spatial_bottom(adj_a));                           \
  }                                                                                            \
  WP_LFN void adj_spatial_bottom(const SV&, SV& adj_a, const V3& g) {                           \
    adj_a = SV##_new(spatial_top(adj_a), spatial_bottom(adj_a) + g);                           \
  }                                                                                            \
  WP_LFN void adj_spatial_dot(const SV& a, const SV& b, SV& adj_a, SV& adj_b, S g) {            \
    typedef vec_traits<SV> TV;                                                                 \
    for (int k = 0; k < 6; ++k)                                                                \
      detail::l_mul()(TV::get(a, k), TV::get(b, k), TV::at(adj_a, k), TV::at(adj_b, k), g);    \
  }                                                                                            \
  WP_LFN void adj_spatial_cross(const SV& a, const SV& b, SV& adj_a, SV& adj_b, const SV& g) {  \
    const V3 wa = spatial_top(a), va = spatial_bottom(a);                                      \
    const V3 wb = spatial_top(b), vb = spatial_bottom(b);                                      \
    V3 awa = spatial_top(adj_a), ava = spatial_bottom(adj_a);                                  \
    V3 awb = spatial_top(adj_b), avb = spatial_bottom(adj_b);                                  \
    adj_cross(wa, wb, awa, awb, spatial_top(g));                                               \
    adj_cross(va, wb, ava, awb, spatial_bottom(g));                                            \
    adj_cross(wa, vb, awa, avb, spatial_bottom(g));                                            \
    adj_a = SV##_new(awa, ava);                                                                \
    adj_b = SV##_new(awb, avb);                                                                \
  }                                                                                            \
  WP_LFN void adj_spatial_cross_dual(const SV& a, const SV& b, SV& adj_a, SV& adj_b,            \
                                    const SV& g) {                                             \
    const V3 wa = spatial_top(a), va = spatial_bottom(a);                                      \
    const V3 wb = spatial_top(b), vb = spatial_bottom(b);                                      \
    V3 awa = spatial_top(adj_a), ava = spatial_bottom(adj_a);                                  \
    V3 awb = spatial_top(adj_b), avb = spatial_bottom(adj_b);                                  \
    adj_cross(wa, wb, awa, awb, spatial_top(g));                                               \
    adj_cross(va, vb, ava, avb, spatial_top(g));                                               \
    adj_cross(wa, vb, awa, avb, spatial_bottom(g));                                            \
    adj_a = SV##_new(awa, ava);                                                                \
    adj_b = SV##_new(awb, avb);                                                                \
  }                                                                                            \
  WP_LFN void adj_spatial_adjoint(const M3&, const M3&, M3& adj_r, M3& adj_s, const SM& g) {    \
    typedef vec_traits<SM> TM;                                                                 \
    for (int i = 0; i < 3; ++i)                                                                \
      for (int j = 0; j < 3; ++j) {                                                            \
        S& r = vec_traits<V3>::at(mat_traits<M3>::at(adj_r, j), i);                            \
        r += TM::get(g, i * 6 + j);                                                            \
        r += TM::get(g, (i + 3) * 6 + j + 3);                                                  \
        vec_traits<V3>::at(mat_traits<M3>::at(adj_s, j), i) += TM::get(g, (i + 3) * 6 + j);    \
      }                                                                                        \
  }                                                                                            \
  WP_LFN void adj_velocity_at_point(const SV& qd, const V3& r, SV& adj_qd, V3& adj_r,            \
                                   const V3& g) {                                              \
    V3 aw = spatial_top(adj_qd);                                                               \
    adj_cross(spatial_top(qd), r, aw, adj_r, g);                                               \
    adj_qd = SV##_new(aw, spatial_bottom(adj_qd) + g);                                         \
  }                                                                                            \
  WP_LFN void adj_transform_twist(const X& t, const SV& x, X& adj_t, SV& adj_x, const SV& g) {  \
    const V3 w1 = t.q * spatial_top(x);                                                        \
    V3 gw = spatial_top(g);                                                                    \
    adj_cross(t.p, w1, adj_t.p, gw, spatial_bottom(g));                                        \
    V3 aw = spatial_top(adj_x), av = spatial_bottom(adj_x);                                    \
    adj_mul(t.q, spatial_bottom(x), adj_t.q, av, spatial_bottom(g));                           \
    adj_mul(t.q, spatial_top(x), adj_t.q, aw, gw);                                             \
    adj_x = SV##_new(aw, av);                                                                  \
  }                                                                                            \
  WP_LFN void adj_transform_wrench(const X& t, const SV& x, X& adj_t, SV& adj_x, const SV& g) { \
    const V3 f1 = t.q * spatial_bottom(x);                                                     \
    V3 gf = spatial_bottom(g);                                                                 \
    adj_cross(t.p, f1, adj_t.p, gf, spatial_top(g));                                           \
    V3 atau = spatial_top(adj_x), af = spatial_bottom(adj_x);                                  \
    adj_mul(t.q, spatial_top(x), adj_t.q, atau, spatial_top(g));                               \
    adj_mul(t.q, spatial_bottom(x), adj_t.q, af, gf);                                          \
    adj_x = SV##_new(atau, af);                                                                \
  }
WP_ADJ_SPATIAL(SpatialVector, SpatialMatrix, Vec3, Mat3, Transform, f32)
WP_ADJ_SPATIAL(DSpatialVector, DSpatialMatrix, DVec3, DMat3, DTransform, f64)
#undef WP_ADJ_SPATIAL
#undef WP_ADJ_SPATIAL_LANES

}  // namespace wp

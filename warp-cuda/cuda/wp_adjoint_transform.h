// wp_adjoint_transform.h: adjoints of the rigid transforms: their operators and the "transform"
// section.
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions. An adjoint
// translation unit includes wp_adjoint_core.h and the adjoint headers of the builtin-table
// sections its kernel uses (warp_cuda::ADJOINT_SECTIONS), so NVRTC parses no more than it
// needs.
#pragma once
#include "wp_adjoint_linalg.h"
#include "wp_transform.h"

namespace wp {
// Rigid transforms (warp-core/src/adjoint/transform.rs): operators and the "transform" section
// ------------------------------------------------------------------------------------------

#define WP_ADJ_XFORM(X, V3, V4, Q, M3, M4, S)                                                    \
  WP_LFN void adj_add(const X&, const X&, X& adj_a, X& adj_b, const X& g) {                       \
    adj_a += g;                                                                                  \
    adj_b += g;                                                                                  \
  }                                                                                              \
  WP_LFN void adj_sub(const X&, const X&, X& adj_a, X& adj_b, const X& g) {                       \
    adj_a += g;                                                                                  \
    adj_b -= g;                                                                                  \
  }                                                                                              \
  WP_LFN void adj_neg(const X&, X& adj_a, const X& g) { adj_a -= g; }                             \
  WP_LFN void adj_mul(const X& a, S s, X& adj_a, S& adj_s, const X& g) {                          \
    detail::zip_vs(a, s, adj_a, adj_s, g, detail::l_mul());                                      \
  }                                                                                              \
  WP_LFN void adj_mul(S s, const X& b, S& adj_s, X& adj_b, const X& g) {                          \
    detail::zip_sv(s, b, adj_s, adj_b, g, detail::l_mul());                                      \
  }                                                                                              \
  WP_LFN void adj_transform_multiply(const X& a, const X& b, X& adj_a, X& adj_b, const X& g) {    \
    adj_mul(a.q, b.p, adj_a.q, adj_b.p, g.p);                                                    \
    adj_a.p += g.p;                                                                              \
    adj_mul(a.q, b.q, adj_a.q, adj_b.q, g.q);                                                    \
  }                                                                                              \
  WP_LFN void adj_mul(const X& a, const X& b, X& adj_a, X& adj_b, const X& g) {                   \
    adj_transform_multiply(a, b, adj_a, adj_b, g);                                               \
  }                                                                                              \
  WP_LFN void adj_lerp(const X& a, const X& b, S t, X& adj_a, X& adj_b, S& adj_t, const X& g) {   \
    typedef vec_traits<X> T;                                                                     \
    for (int i = 0; i < 7; ++i)                                                                  \
      detail::l_lerp(T::get(a, i), T::get(b, i), t, T::at(adj_a, i), T::at(adj_b, i), adj_t,    \
                     T::get(g, i));                                                              \
  }                                                                                              \
  WP_LFN void adj_transformation(const V3&, const Q&, V3& adj_p, Q& adj_q, const X& g) {          \
    adj_p += g.p;                                                                                \
    adj_q += g.q;                                                                                \
  }                                                                                              \
  WP_LFN void adj_transform_get_translation(const X&, X& adj_t, const V3& g) { adj_t.p += g; }    \
  WP_LFN void adj_transform_get_rotation(const X&, X& adj_t, const Q& g) { adj_t.q += g; }        \
  WP_LFN void adj_transform_point(const X& t, const V3& x, X& adj_t, V3& adj_x, const V3& g) {    \
    adj_mul(t.q, x, adj_t.q, adj_x, g);                                                          \
    adj_t.p += g;                                                                                \
  }                                                                                              \
  WP_LFN void adj_transform_vector(const X& t, const V3& x, X& adj_t, V3& adj_x, const V3& g) {   \
    adj_mul(t.q, x, adj_t.q, adj_x, g);                                                          \
  }                                                                                              \
  /* forward: qi = conj(q), r = -(qi * p) */                                                     \
  WP_LFN void adj_transform_inverse(const X& t, X& adj_t, const X& g) {                           \
    const Q qi = quat_inverse(t.q);                                                              \
    Q adj_qi = g.q;                                                                              \
    adj_mul(qi, t.p, adj_qi, adj_t.p, -g.p);                                                     \
    adj_quat_inverse(t.q, adj_t.q, adj_qi);                                                      \
  }                                                                                              \
  WP_LFN void adj_inverse(const X& t, X& adj_t, const X& g) { adj_transform_inverse(t, adj_t, g); } \
  WP_LFN void adj_transform_to_matrix(const X& t, X& adj_t, const M4& g) {                        \
    const M3 g3 = M3##_from_cols(V3##_new(g.x_axis.x, g.x_axis.y, g.x_axis.z),                   \
                                 V3##_new(g.y_axis.x, g.y_axis.y, g.y_axis.z),                   \
                                 V3##_new(g.z_axis.x, g.z_axis.y, g.z_axis.z));                  \
    adj_quat_to_matrix(t.q, adj_t.q, g3);                                                        \
    adj_t.p += V3##_new(g.w_axis.x, g.w_axis.y, g.w_axis.z);                                     \
  }                                                                                              \
  WP_LFN void adj_transform_from_matrix(const M4& m, M4& adj_m, const X& g) {                     \
    const M3 m3 = M3##_from_cols(V3##_new(m.x_axis.x, m.x_axis.y, m.x_axis.z),                   \
                                 V3##_new(m.y_axis.x, m.y_axis.y, m.y_axis.z),                   \
                                 V3##_new(m.z_axis.x, m.z_axis.y, m.z_axis.z));                  \
    M3 a3 = M3##_from_cols(V3##_new(adj_m.x_axis.x, adj_m.x_axis.y, adj_m.x_axis.z),             \
                           V3##_new(adj_m.y_axis.x, adj_m.y_axis.y, adj_m.y_axis.z),             \
                           V3##_new(adj_m.z_axis.x, adj_m.z_axis.y, adj_m.z_axis.z));            \
    adj_quat_from_matrix(m3, a3, g.q);                                                           \
    adj_m.x_axis = V4##_new(a3.x_axis.x, a3.x_axis.y, a3.x_axis.z, adj_m.x_axis.w);              \
    adj_m.y_axis = V4##_new(a3.y_axis.x, a3.y_axis.y, a3.y_axis.z, adj_m.y_axis.w);              \
    adj_m.z_axis = V4##_new(a3.z_axis.x, a3.z_axis.y, a3.z_axis.z, adj_m.z_axis.w);              \
    adj_m.w_axis.x += g.p.x;                                                                     \
    adj_m.w_axis.y += g.p.y;                                                                     \
    adj_m.w_axis.z += g.p.z;                                                                     \
  }                                                                                              \
  /* 4x4 matrices: adj_m.{x,y,z}_axis[k] += g[k] * x.{x,y,z}; adj_x.c += column c . g. */       \
  WP_LFN void adj_transform_vector(const M4& m, const V3& x, M4& adj_m, V3& adj_x, const V3& g) { \
    adj_m.x_axis.x += g.x * x.x;                                                                 \
    adj_m.x_axis.y += g.y * x.x;                                                                 \
    adj_m.x_axis.z += g.z * x.x;                                                                 \
    adj_m.y_axis.x += g.x * x.y;                                                                 \
    adj_m.y_axis.y += g.y * x.y;                                                                 \
    adj_m.y_axis.z += g.z * x.y;                                                                 \
    adj_m.z_axis.x += g.x * x.z;                                                                 \
    adj_m.z_axis.y += g.y * x.z;                                                                 \
    adj_m.z_axis.z += g.z * x.z;                                                                 \
    adj_x.x += (m.x_axis.x * g.x + m.x_axis.y * g.y) + m.x_axis.z * g.z;                         \
    adj_x.y += (m.y_axis.x * g.x + m.y_axis.y * g.y) + m.y_axis.z * g.z;                         \
    adj_x.z += (m.z_axis.x * g.x + m.z_axis.y * g.y) + m.z_axis.z * g.z;                         \
  }                                                                                              \
  WP_LFN void adj_transform_point(const M4& m, const V3& x, M4& adj_m, V3& adj_x, const V3& g) {  \
    adj_transform_vector(m, x, adj_m, adj_x, g);                                                 \
    adj_m.w_axis.x += g.x;                                                                       \
    adj_m.w_axis.y += g.y;                                                                       \
    adj_m.w_axis.z += g.z;                                                                       \
  }
WP_ADJ_XFORM(Transform, Vec3, Vec4, Quat, Mat3, Mat4, f32)
WP_ADJ_XFORM(DTransform, DVec3, DVec4, DQuat, DMat3, DMat4, f64)
#undef WP_ADJ_XFORM

}  // namespace wp

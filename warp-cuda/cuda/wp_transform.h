// wp_transform.h: section "transform" of the builtin table (warp-core/src/builtins/transform.rs
// and the Transform methods of warp-core/src/transform.rs), for Transform and DTransform (the
// types and their operators are in wp_core.h):
//
//   transformation(p, q)            (p, q)
//   transform_get_translation(t)    t.p;  transform_get_rotation(t): t.q
//   transform_multiply(a, b)        a * b = (a.q * b.p + a.p, a.q * b.q)
//   transform_point(t, x)           t.q * x + t.p (glam's q * v, as quat_rotate)
//   transform_vector(t, x)          t.q * x
//   transform_inverse(t), inverse   (-(conj(q) * p), conj(q))
//   transform_to_matrix(t)          quat_to_matrix(q) in the upper-left block, p in column 3
//   transform_from_matrix(m)        (m.w_axis.xyz, quat_from_matrix(upper-left block))
//   lerp(a, b, t)                   a * (1 - t) + b * t lane by lane
//   transform_point(m, x)           Mat4/DMat4: glam's transform_point3, lane k
//                                   ((x_axis[k] * x.x + y_axis[k] * x.y) + z_axis[k] * x.z) + w_axis[k]
//   transform_vector(m, x)          glam's transform_vector3 (the same without w_axis)
#pragma once
#include "wp_linalg.h"

namespace wp {

#define WP_TRANSFORM(X, V3, V4, Q, M3, M4, S)                                             \
  WP_LFN X transformation(const V3& p, const Q& q) { return X##_new(p, q); }               \
  WP_LFN V3 transform_get_translation(const X& t) { return t.p; }                          \
  WP_LFN Q transform_get_rotation(const X& t) { return t.q; }                              \
  WP_LFN X transform_multiply(const X& a, const X& b) { return a * b; }                    \
  WP_LFN V3 transform_point(const X& t, const V3& x) { return t.q * x + t.p; }             \
  WP_LFN V3 transform_vector(const X& t, const V3& x) { return t.q * x; }                  \
  WP_LFN X transform_inverse(const X& t) {                                                 \
    const Q qi = quat_inverse(t.q);                                                       \
    return X##_new(-(qi * t.p), qi);                                                      \
  }                                                                                       \
  WP_LFN X inverse(const X& t) { return transform_inverse(t); }                            \
  WP_LFN M4 transform_to_matrix(const X& t) {                                              \
    const M3 r = quat_to_matrix(t.q);                                                     \
    return M4##_from_cols(V4##_new(r.x_axis.x, r.x_axis.y, r.x_axis.z, (S)0),             \
                          V4##_new(r.y_axis.x, r.y_axis.y, r.y_axis.z, (S)0),             \
                          V4##_new(r.z_axis.x, r.z_axis.y, r.z_axis.z, (S)0),             \
                          V4##_new(t.p.x, t.p.y, t.p.z, (S)1));                           \
  }                                                                                       \
  WP_LFN X transform_from_matrix(const M4& m) {                                            \
    const M3 r = M3##_from_cols(V3##_new(m.x_axis.x, m.x_axis.y, m.x_axis.z),             \
                                V3##_new(m.y_axis.x, m.y_axis.y, m.y_axis.z),             \
                                V3##_new(m.z_axis.x, m.z_axis.y, m.z_axis.z));            \
    return X##_new(V3##_new(m.w_axis.x, m.w_axis.y, m.w_axis.z), quat_from_matrix(r));    \
  }                                                                                       \
  WP_LFN X lerp(const X& a, const X& b, S t) {                                             \
    X r = a;                                                                              \
    for (int i = 0; i < 7; ++i)                                                           \
      vec_traits<X>::at(r, i) =                                                           \
          vec_traits<X>::get(a, i) * ((S)1 - t) + vec_traits<X>::get(b, i) * t;           \
    return r;                                                                             \
  }                                                                                       \
  WP_LFN V3 transform_point(const M4& m, const V3& x) {                                    \
    return V3##_new(((m.x_axis.x * x.x + m.y_axis.x * x.y) + m.z_axis.x * x.z) + m.w_axis.x, \
                    ((m.x_axis.y * x.x + m.y_axis.y * x.y) + m.z_axis.y * x.z) + m.w_axis.y, \
                    ((m.x_axis.z * x.x + m.y_axis.z * x.y) + m.z_axis.z * x.z) + m.w_axis.z); \
  }                                                                                       \
  WP_LFN V3 transform_vector(const M4& m, const V3& x) {                                   \
    return V3##_new((m.x_axis.x * x.x + m.y_axis.x * x.y) + m.z_axis.x * x.z,             \
                    (m.x_axis.y * x.x + m.y_axis.y * x.y) + m.z_axis.y * x.z,             \
                    (m.x_axis.z * x.x + m.y_axis.z * x.y) + m.z_axis.z * x.z);            \
  }
WP_TRANSFORM(Transform, Vec3, Vec4, Quat, Mat3, Mat4, f32)
WP_TRANSFORM(DTransform, DVec3, DVec4, DQuat, DMat3, DMat4, f64)
#undef WP_TRANSFORM

}  // namespace wp

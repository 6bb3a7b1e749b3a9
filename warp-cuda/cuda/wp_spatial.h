// wp_spatial.h: section "spatial" of the builtin table (warp-core/src/builtins/spatial.rs and
// the methods of warp-core/src/spatial.rs), for SpatialVector/SpatialMatrix and their f64 twins
// (the types and their operators are in wp_core.h):
//
//   spatial_vector(w, v)            (w.x, w.y, w.z, v.x, v.y, v.z); spatial_vector_scalars(a0..a5)
//   spatial_top(a), spatial_bottom(a)   lanes 0..2, lanes 3..5
//   spatial_dot(a, b)               ((((a0 b0 + a1 b1) + a2 b2) + a3 b3) + a4 b4) + a5 b5
//   spatial_cross(a, b)             (wa x wb, va x wb + wa x vb)   (cross: wp_vector.h's)
//   spatial_cross_dual(a, b)        (wa x wb + va x vb, wa x vb)
//   spatial_adjoint(r, s)           [[r, 0], [s, r]] in 3x3 blocks (entry (i, j) of a block is
//                                   row i, column j of the glam column-major 3x3 matrix)
//   velocity_at_point(qd, r)        v + w x r   (qd = (w, v))
//   transform_twist(t, x)           w' = q w, v' = q v + p x w'   (q w: glam's rotation)
//   transform_wrench(t, x)          f' = q f, tau' = q tau + p x f'
//   transpose(m), outer(a, b)       the linalg rows' overloads for spatial types
#pragma once
#include "wp_vector.h"
#include "wp_transform.h"

namespace wp {

#define WP_SPATIAL(SV, SM, V3, M3, X, S)                                                  \
  WP_LFN SV spatial_vector(const V3& w, const V3& v) { return SV##_new(w, v); }            \
  WP_LFN SV spatial_vector_scalars(S a0, S a1, S a2, S a3, S a4, S a5) {                   \
    return SV##_new6(a0, a1, a2, a3, a4, a5);                                             \
  }                                                                                       \
  WP_LFN V3 spatial_top(const SV& a) { return V3##_new(a.f0, a.f1, a.f2); }                \
  WP_LFN V3 spatial_bottom(const SV& a) { return V3##_new(a.f3, a.f4, a.f5); }             \
  WP_LFN S spatial_dot(const SV& a, const SV& b) { return SV##_dot(a, b); }                \
  WP_LFN SV spatial_cross(const SV& a, const SV& b) {                                      \
    const V3 wa = spatial_top(a), va = spatial_bottom(a);                                 \
    const V3 wb = spatial_top(b), vb = spatial_bottom(b);                                 \
    return SV##_new(cross(wa, wb), cross(va, wb) + cross(wa, vb));                        \
  }                                                                                       \
  WP_LFN SV spatial_cross_dual(const SV& a, const SV& b) {                                 \
    const V3 wa = spatial_top(a), va = spatial_bottom(a);                                 \
    const V3 wb = spatial_top(b), vb = spatial_bottom(b);                                 \
    return SV##_new(cross(wa, wb) + cross(va, vb), cross(wa, vb));                        \
  }                                                                                       \
  WP_LFN SM spatial_adjoint(const M3& r, const M3& s) {                                    \
    SM m = SM##_ZERO();                                                                   \
    for (int i = 0; i < 3; ++i)                                                           \
      for (int j = 0; j < 3; ++j) {                                                       \
        const S rij = vec_traits<V3>::get(mat_traits<M3>::get(r, j), i);                  \
        vec_traits<SM>::at(m, i * 6 + j) = rij;                                           \
        vec_traits<SM>::at(m, (i + 3) * 6 + j + 3) = rij;                                 \
        vec_traits<SM>::at(m, (i + 3) * 6 + j) = vec_traits<V3>::get(mat_traits<M3>::get(s, j), i); \
      }                                                                                   \
    return m;                                                                             \
  }                                                                                       \
  WP_LFN V3 velocity_at_point(const SV& qd, const V3& r) {                                 \
    return spatial_bottom(qd) + cross(spatial_top(qd), r);                                \
  }                                                                                       \
  WP_LFN SV transform_twist(const X& t, const SV& x) {                                     \
    const V3 w = t.q * spatial_top(x);                                                    \
    return SV##_new(w, t.q * spatial_bottom(x) + cross(t.p, w));                          \
  }                                                                                       \
  WP_LFN SV transform_wrench(const X& t, const SV& x) {                                    \
    const V3 f = t.q * spatial_bottom(x);                                                 \
    return SV##_new(t.q * spatial_top(x) + cross(t.p, f), f);                             \
  }                                                                                       \
  WP_LFN SM transpose(const SM& m) {                                                       \
    SM r;                                                                                 \
    for (int i = 0; i < 6; ++i)                                                           \
      for (int j = 0; j < 6; ++j) vec_traits<SM>::at(r, j * 6 + i) = vec_traits<SM>::get(m, i * 6 + j); \
    return r;                                                                             \
  }                                                                                       \
  WP_LFN SM outer(const SV& a, const SV& b) {                                              \
    SM r;                                                                                 \
    for (int i = 0; i < 6; ++i)                                                           \
      for (int j = 0; j < 6; ++j)                                                         \
        vec_traits<SM>::at(r, i * 6 + j) = vec_traits<SV>::get(a, i) * vec_traits<SV>::get(b, j); \
    return r;                                                                             \
  }
WP_SPATIAL(SpatialVector, SpatialMatrix, Vec3, Mat3, Transform, f32)
WP_SPATIAL(DSpatialVector, DSpatialMatrix, DVec3, DMat3, DTransform, f64)
#undef WP_SPATIAL

}  // namespace wp

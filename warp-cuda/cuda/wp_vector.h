// wp_vector.h: section "vector" of the builtin table (warp-core/src/builtins/math.rs).
//
//   dot(a, b)      every glam vector; the component products summed left to right starting
//                  from 0 (((0 + x*x') + y*y') + ...), wrapping for integer vectors.
//   cross(a, b)    Vec3, DVec3, IVec3 (wrapping): (a.y*b.z - a.z*b.y, a.z*b.x - a.x*b.z,
//                  a.x*b.y - a.y*b.x).
//   length(v)      float vectors: sqrt(dot(v, v)).
//   normalize(v)   float vectors: v / length(v) componentwise, or the zero vector unless
//                  length(v) > 0 (so zero and NaN-length vectors give zero, never NaN).
#pragma once
#include "wp_scalar.h"

namespace wp {

#define WP_VEC_DOT(V, S)                                                              \
  WP_FN S dot(const V& a, const V& b) {                                               \
    S acc = (S)0;                                                                     \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                        \
      acc = detail::s_add(acc, detail::s_mul(vec_traits<V>::get(a, i), vec_traits<V>::get(b, i))); \
    return acc;                                                                       \
  }
WP_VEC_DOT(Vec2, f32)
WP_VEC_DOT(Vec3, f32)
WP_VEC_DOT(Vec4, f32)
WP_VEC_DOT(DVec2, f64)
WP_VEC_DOT(DVec3, f64)
WP_VEC_DOT(DVec4, f64)
WP_VEC_DOT(IVec2, i32)
WP_VEC_DOT(IVec3, i32)
WP_VEC_DOT(IVec4, i32)
WP_VEC_DOT(UVec2, u32)
WP_VEC_DOT(UVec3, u32)
WP_VEC_DOT(UVec4, u32)
#undef WP_VEC_DOT

#define WP_VEC_CROSS(V)                                                         \
  WP_FN V cross(const V& a, const V& b) {                                       \
    using detail::s_mul;                                                        \
    using detail::s_sub;                                                        \
    return V##_new(s_sub(s_mul(a.y, b.z), s_mul(a.z, b.y)),                     \
                   s_sub(s_mul(a.z, b.x), s_mul(a.x, b.z)),                     \
                   s_sub(s_mul(a.x, b.y), s_mul(a.y, b.x)));                    \
  }
WP_VEC_CROSS(Vec3)
WP_VEC_CROSS(DVec3)
WP_VEC_CROSS(IVec3)
#undef WP_VEC_CROSS

#define WP_VEC_LENGTH(V, S)                                                     \
  WP_FN S length(const V& v) { return sqrt(dot(v, v)); }                        \
  WP_FN V normalize(const V& v) {                                               \
    const S l = length(v);                                                      \
    if (l > (S)0) return detail::vmap(v, [l](S x) { return x / l; });           \
    return V##_ZERO();                                                          \
  }
WP_VEC_LENGTH(Vec2, f32)
WP_VEC_LENGTH(Vec3, f32)
WP_VEC_LENGTH(Vec4, f32)
WP_VEC_LENGTH(DVec2, f64)
WP_VEC_LENGTH(DVec3, f64)
WP_VEC_LENGTH(DVec4, f64)
#undef WP_VEC_LENGTH

}  // namespace wp

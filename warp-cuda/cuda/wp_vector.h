// wp_vector.h: section "vector" of the builtin table (warp-core/src/builtins/math.rs).
//
//   dot(a, b)      every glam vector; the component products summed left to right starting
//                  from 0 (((0 + x*x') + y*y') + ...), wrapping for integer vectors.
//   cross(a, b)    Vec3, DVec3, IVec3 (wrapping): (a.y*b.z - a.z*b.y, a.z*b.x - a.x*b.z,
//                  a.x*b.y - a.y*b.x).
//   length(v)      float vectors: sqrt(dot(v, v)), rescaled where that over/underflows.
//   normalize(v)   float vectors: v / length(v) componentwise, or the zero vector unless
//                  length(v) > 0 (so zero and NaN-length vectors give zero, never NaN).
//
// Rescaled norms (warp-core/src/builtins/norm.rs, whose module docs give the reasoning; the
// same operations in the same order, so results agree bit for bit without FMA contraction):
// the squared norm s = dot(v, v) is used as is when it lies in [2^-100, FLT_MAX] (f64
// [2^-1000, DBL_MAX]). Otherwise (detail::norm_rescaled) v is multiplied by the power of two k
// that brings its largest |component| into [1, 2) (clamped to 2^+-126, f64 2^+-1022), exact,
// and length = sqrt(dot(w, w)) * (1/k), normalize = w / sqrt(dot(w, w)). Zero, NaN and
// infinite largest components keep k = 1 and the plain formula's results. The quaternion
// norms (wp_linalg.h) and the adjoints (wp_adjoint_builtins.h, wp_adjoint_linalg.h) use the
// same helpers.
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

namespace detail {

/// Whether sqrt(s) of a squared norm is accurate: s in [2^-100, FLT_MAX] (f64 [2^-1000,
/// DBL_MAX]); false for NaN. warp-core's NormScalar::norm_sq_is_safe.
WP_FN bool norm_sq_safe(f32 s) { return s >= f32_from_bits(27u << 23) && s <= f32_max(); }
WP_FN bool norm_sq_safe(f64 s) { return s >= f64_from_bits(23ull << 52) && s <= f64_max(); }

/// For a finite m > 0: k, a power of two with m * k in [1, 2) clamped to 2^+-126, and
/// inv = 1/k; false (k, inv untouched) for zero, NaN and infinity. NormScalar::pow2_pair.
WP_FN bool pow2_pair(f32 m, f32& k, f32& inv) {
  if (!(m > 0.0f && m <= f32_max())) return false;
  const i32 e = (i32)((f32_to_bits(m) >> 23) & 0xffu) - 127;
  i32 p = -e;
  p = p < -126 ? -126 : (p > 126 ? 126 : p);
  k = f32_from_bits((u32)(127 + p) << 23);
  inv = f32_from_bits((u32)(127 - p) << 23);
  return true;
}
WP_FN bool pow2_pair(f64 m, f64& k, f64& inv) {
  if (!(m > 0.0 && m <= f64_max())) return false;
  const i64 e = (i64)((f64_to_bits(m) >> 52) & 0x7ffull) - 1023;
  i64 p = -e;
  p = p < -1022 ? -1022 : (p > 1022 ? 1022 : p);
  k = f64_from_bits((u64)(1023 + p) << 52);
  inv = f64_from_bits((u64)(1023 - p) << 52);
  return true;
}

/// The slow path's scaled vector (warp-core's norm::rescaled): w = k v and l = |w| for the
/// power of two k of the largest |component| (found by `>` from 0, so NaN lanes are
/// skipped), or w = v, l = sqrt(s), k = inv = 1 when that is zero, infinite or NaN.
/// `dotself(a)` is the type's own dot(a, a).
template <typename V, typename S, typename Dot>
WP_FN void norm_rescaled(const V& v, S s, Dot dotself, V& w, S& l, S& k, S& inv) {
  typedef vec_traits<V> T;
  S m = (S)0;
  for (int i = 0; i < T::N; ++i) {
    const S a = wp::abs(T::get(v, i));
    if (a > m) m = a;
  }
  if (pow2_pair(m, k, inv)) {
    for (int i = 0; i < T::N; ++i) T::at(w, i) = T::get(v, i) * k;
    l = wp::sqrt(dotself(w));
  } else {
    w = v;
    l = wp::sqrt(s);
    k = (S)1;
    inv = (S)1;
  }
}

/// (w, |w|, k) for length, normalize and their adjoints: v, sqrt(s), 1 on the fast path,
/// else norm_rescaled.
template <typename V, typename S, typename Dot>
WP_FN void norm_parts(const V& v, Dot dotself, V& w, S& l, S& k) {
  const S s = dotself(v);
  if (norm_sq_safe(s)) {
    w = v;
    l = wp::sqrt(s);
    k = (S)1;
  } else {
    S inv;
    norm_rescaled(v, s, dotself, w, l, k, inv);
  }
}

}  // namespace detail

#define WP_VEC_LENGTH(V, S)                                                     \
  WP_FN S length(const V& v) {                                                  \
    const S s = dot(v, v);                                                      \
    if (detail::norm_sq_safe(s)) return sqrt(s);                                \
    V w;                                                                        \
    S l, k, inv;                                                                \
    detail::norm_rescaled(v, s, [](const V& a) { return dot(a, a); }, w, l, k, inv); \
    return l * inv;                                                             \
  }                                                                             \
  WP_FN V normalize(const V& v) {                                               \
    V w;                                                                        \
    S l, k;                                                                     \
    detail::norm_parts(v, [](const V& a) { return dot(a, a); }, w, l, k);       \
    if (l > (S)0) return detail::vmap(w, [l](S x) { return x / l; });           \
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

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
// every length and normalize multiplies v by the power of two k that brings its largest
// |component| into [1, 2) (clamped to 2^+-126, f64 2^+-1022), exact, and applies the plain
// formulas to w = k v: length = sqrt(dot(w, w)) * (1/k), normalize = w / sqrt(dot(w, w)).
// Where the plain formula was accurate these are its results bit for bit; where its squares
// overflowed or underflowed (components beyond about 1e19 or below 1e-19 in f32) they are
// still accurate. Branch-free, so that the CPU's loops vectorise. The quaternion norms
// (wp_linalg.h) and the adjoints (wp_adjoint_builtins.h, wp_adjoint_linalg.h) share
// detail::norm_scaled.
#pragma once
#include "wp_scalar.h"

namespace wp {

#define WP_VEC_DOT(V, S)                                                              \
  WP_LFN S dot(const V& a, const V& b) {                                               \
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
  WP_LFN V cross(const V& a, const V& b) {                                       \
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

/// For m >= 0 (not NaN): k, the power of two with m * k in [1, 2) clamped to 2^+-126, and
/// inv = 1/k (warp-core's NormScalar::pow2_pair): m clamped to [2^-126, 2^126] by selects,
/// its exponent bits eb are 1/k (the mantissa cleared), and k has the exponent 254 - E.
WP_LFN void pow2_pair(f32 m, f32& k, f32& inv) {
  const f32 lo = f32_from_bits(1u << 23), hi = f32_from_bits(253u << 23);
  m = m > lo ? m : lo;
  m = m < hi ? m : hi;
  const u32 eb = f32_to_bits(m) & 0x7f800000u;
  k = f32_from_bits(0x7f000000u - eb);
  inv = f32_from_bits(eb);
}
WP_LFN void pow2_pair(f64 m, f64& k, f64& inv) {
  const f64 lo = f64_from_bits(1ull << 52), hi = f64_from_bits(2045ull << 52);
  m = m > lo ? m : lo;
  m = m < hi ? m : hi;
  const u64 eb = f64_to_bits(m) & 0x7ff0000000000000ull;
  k = f64_from_bits(0x7fe0000000000000ull - eb);
  inv = f64_from_bits(eb);
}

/// The scaled vector and its parts (warp-core's norm::scaled): w = k v, l = |w| =
/// sqrt(dotself(w)), k and inv = 1/k, for the power of two k of the largest |component|
/// (taken by `>` from 0, so NaN lanes are skipped). `dotself(a)` is the type's dot(a, a).
template <typename V, typename S, typename Dot>
WP_FN void norm_scaled(const V& v, Dot dotself, V& w, S& l, S& k, S& inv) {
  typedef vec_traits<V> T;
  S m = (S)0;
  // wp::max (IEEE fmax) returns the operand that is not NaN, as `a > m ? a : m` from 0 does
  // (`m` is never NaN), in one instruction with the absolute value folded in (FMNMX |a|)
  // where the comparison takes a compare and a select.
  for (int i = 0; i < T::N; ++i) m = wp::max(wp::abs(T::get(v, i)), m);
  pow2_pair(m, k, inv);
  for (int i = 0; i < T::N; ++i) T::at(w, i) = T::get(v, i) * k;
  l = wp::sqrt(dotself(w));
}

}  // namespace detail

#define WP_VEC_LENGTH(V, S)                                                     \
  WP_LFN S length(const V& v) {                                                  \
    V w;                                                                        \
    S l, k, inv;                                                                \
    detail::norm_scaled(v, [](const V& a) { return dot(a, a); }, w, l, k, inv); \
    return l * inv;                                                             \
  }                                                                             \
  WP_LFN V normalize(const V& v) {                                               \
    V w;                                                                        \
    S l, k, inv;                                                                \
    detail::norm_scaled(v, [](const V& a) { return dot(a, a); }, w, l, k, inv); \
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

// wp_linalg.h: section "linalg" of the builtin table (warp-core/src/builtins/linalg.rs).
//
//   length_sq(v)            vectors: dot(v, v); quaternions: ((x*x + y*y) + z*z) + w*w.
//   outer(a, b)             float vectors: the matrix with column j = a * b[j].
//   diag(v)                 float vectors: the diagonal matrix.
//   cw_mul(a, b), cw_div    float vectors and matrices: lane by lane * and /.
//   transpose(m)            matrices.
//   determinant(m)          glam's order: Mat2/DMat2 x.x*y.y - x.y*y.x; Mat3/DMat3 z.(x cross y);
//                           DMat4 glam's scalar cofactor expansion; Mat4 glam's SSE2 code
//                           (glm's glm_mat4_determinant_lowp), lane by lane.
//   inverse(m)              the zero matrix when determinant(m) == 0, else glam's inverse
//                           (Mat2 and Mat4: its SSE2 code lane by lane).
//   inverse(q)              the conjugate (-x, -y, -z, w).
//   trace(m), ddot(a, b)    left to right (ddot over the lanes in column-major order).
//   skew(v)                 Vec3/DVec3: columns (0, z, -y), (-z, 0, x), (y, -x, 0).
//   dot, length, normalize  quaternions: left to right; normalize gives the identity when the
//                           length is not positive; length and normalize rescaled by a
//                           power of two as the vectors' are (wp_vector.h).
//   quat_from_axis_angle, quat_rotate (q * v), quat_rotate_inv (conjugate(q) * v),
//   quat_inverse, quat_to_matrix (glam's Mat3::from_quat), quat_from_matrix (glam's
//   Quat::from_mat3), quat_slerp (Warp's axis-angle definition).
//   quat_from_euler, quat_to_euler (Warp's @wp.funcs of math.py, branch for branch;
//                           warp-core/src/builtins/euler.rs).
#pragma once
#include "wp_scalar.h"
#include "wp_vector.h"

namespace wp {

namespace detail {
/// An SSE register as four lanes, for transcribing glam's SSE2 code lane by lane.
struct m4 {
  f32 v[4];
};
WP_LFN m4 m4_of(const Vec4& a) { return m4{{a.x, a.y, a.z, a.w}}; }
WP_LFN Vec4 m4_vec(const m4& a) { return Vec4_new(a.v[0], a.v[1], a.v[2], a.v[3]); }
WP_LFN m4 m4_set(f32 a, f32 b, f32 c, f32 d) { return m4{{a, b, c, d}}; }
/// _mm_shuffle_ps(a, b, imm): lanes a[imm&3], a[(imm>>2)&3], b[(imm>>4)&3], b[(imm>>6)&3].
WP_LFN m4 shuf(const m4& a, const m4& b, int imm) {
  return m4{{a.v[imm & 3], a.v[(imm >> 2) & 3], b.v[(imm >> 4) & 3], b.v[(imm >> 6) & 3]}};
}
/// _mm_movehl_ps(a, b): b2, b3, a2, a3.
WP_LFN m4 movehl(const m4& a, const m4& b) { return m4{{b.v[2], b.v[3], a.v[2], a.v[3]}}; }
WP_LFN m4 operator*(const m4& a, const m4& b) {
  return m4{{a.v[0] * b.v[0], a.v[1] * b.v[1], a.v[2] * b.v[2], a.v[3] * b.v[3]}};
}
WP_LFN m4 operator+(const m4& a, const m4& b) {
  return m4{{a.v[0] + b.v[0], a.v[1] + b.v[1], a.v[2] + b.v[2], a.v[3] + b.v[3]}};
}
WP_LFN m4 operator-(const m4& a, const m4& b) {
  return m4{{a.v[0] - b.v[0], a.v[1] - b.v[1], a.v[2] - b.v[2], a.v[3] - b.v[3]}};
}
/// glam's SSE2 dot4: (x*x' + z*z') + (y*y' + w*w').
WP_LFN f32 dot4(const m4& a, const m4& b) {
  const m4 p = a * b;
  return (p.v[0] + p.v[2]) + (p.v[1] + p.v[3]);
}
/// glam's scalar Vec3 dot (no leading zero): (x*x' + y*y') + z*z'.
template <typename V3>
WP_FN typename vec_traits<V3>::scalar dot3(const V3& a, const V3& b) {
  return (a.x * b.x + a.y * b.y) + a.z * b.z;
}
/// The quaternion dot, left to right without a leading zero.
template <typename Q>
WP_FN typename vec_traits<Q>::scalar qdot(const Q& a, const Q& b) {
  return ((a.x * b.x + a.y * b.y) + a.z * b.z) + a.w * b.w;
}
}  // namespace detail

// ------------------------------------------------------------------------------------------
// Vectors
// ------------------------------------------------------------------------------------------

#define WP_LINALG_VEC(V, M, S)                                                          \
  WP_LFN S length_sq(const V& v) { return dot(v, v); }                                   \
  WP_LFN M outer(const V& a, const V& b) {                                               \
    M m;                                                                                \
    for (int j = 0; j < vec_traits<V>::N; ++j) mat_traits<M>::at(m, j) = a * vec_traits<V>::get(b, j); \
    return m;                                                                           \
  }                                                                                     \
  WP_LFN M diag(const V& v) { return M##_from_diagonal(v); }                             \
  WP_LFN V cw_mul(const V& a, const V& b) { return a * b; }                              \
  WP_LFN V cw_div(const V& a, const V& b) { return a / b; }
WP_LINALG_VEC(Vec2, Mat2, f32)
WP_LINALG_VEC(Vec3, Mat3, f32)
WP_LINALG_VEC(Vec4, Mat4, f32)
WP_LINALG_VEC(DVec2, DMat2, f64)
WP_LINALG_VEC(DVec3, DMat3, f64)
WP_LINALG_VEC(DVec4, DMat4, f64)
#undef WP_LINALG_VEC
WP_LFN i32 length_sq(const IVec2& v) { return dot(v, v); }
WP_LFN i32 length_sq(const IVec3& v) { return dot(v, v); }
WP_LFN i32 length_sq(const IVec4& v) { return dot(v, v); }
WP_LFN u32 length_sq(const UVec2& v) { return dot(v, v); }
WP_LFN u32 length_sq(const UVec3& v) { return dot(v, v); }
WP_LFN u32 length_sq(const UVec4& v) { return dot(v, v); }

// ------------------------------------------------------------------------------------------
// Matrices
// ------------------------------------------------------------------------------------------

#define WP_LINALG_MAT(M, V, S)                                                          \
  WP_LFN M cw_mul(const M& a, const M& b) {                                              \
    M r;                                                                                \
    for (int i = 0; i < mat_traits<M>::N; ++i) mat_traits<M>::at(r, i) = mat_traits<M>::get(a, i) * mat_traits<M>::get(b, i); \
    return r;                                                                           \
  }                                                                                     \
  WP_LFN M cw_div(const M& a, const M& b) {                                              \
    M r;                                                                                \
    for (int i = 0; i < mat_traits<M>::N; ++i) mat_traits<M>::at(r, i) = mat_traits<M>::get(a, i) / mat_traits<M>::get(b, i); \
    return r;                                                                           \
  }                                                                                     \
  WP_LFN M transpose(const M& m) {                                                       \
    M r;                                                                                \
    for (int i = 0; i < mat_traits<M>::N; ++i)                                          \
      for (int j = 0; j < mat_traits<M>::N; ++j)                                        \
        vec_traits<V>::at(mat_traits<M>::at(r, i), j) = vec_traits<V>::get(mat_traits<M>::get(m, j), i); \
    return r;                                                                           \
  }                                                                                     \
  WP_LFN S trace(const M& m) {                                                           \
    S acc = m.x_axis.x;                                                                 \
    for (int i = 1; i < mat_traits<M>::N; ++i) acc = acc + vec_traits<V>::get(mat_traits<M>::get(m, i), i); \
    return acc;                                                                         \
  }                                                                                     \
  WP_LFN S ddot(const M& a, const M& b) {                                                \
    S acc = (S)0;                                                                       \
    for (int k = 0; k < vec_traits<M>::N; ++k) acc = acc + vec_traits<M>::get(a, k) * vec_traits<M>::get(b, k); \
    return acc;                                                                         \
  }
WP_LINALG_MAT(Mat2, Vec2, f32)
WP_LINALG_MAT(Mat3, Vec3, f32)
WP_LINALG_MAT(Mat4, Vec4, f32)
WP_LINALG_MAT(DMat2, DVec2, f64)
WP_LINALG_MAT(DMat3, DVec3, f64)
WP_LINALG_MAT(DMat4, DVec4, f64)
#undef WP_LINALG_MAT

// 2x2 (glam's SSE2 Mat2 and scalar DMat2 agree lane for lane).
#define WP_LINALG_MAT2(M, V, S)                                                         \
  WP_LFN S determinant(const M& m) { return m.x_axis.x * m.y_axis.y - m.x_axis.y * m.y_axis.x; } \
  WP_LFN M inverse(const M& m) {                                                         \
    const S det = determinant(m);                                                       \
    if (det == (S)0) return M##_ZERO();                                                 \
    const S r = (S)1 / det;                                                             \
    return M##_from_cols(V##_new(m.y_axis.y * r, m.x_axis.y * -r),                      \
                         V##_new(m.y_axis.x * -r, m.x_axis.x * r));                     \
  }
WP_LINALG_MAT2(Mat2, Vec2, f32)
WP_LINALG_MAT2(DMat2, DVec2, f64)
#undef WP_LINALG_MAT2

// 3x3 (glam's scalar Mat3/DMat3).
#define WP_LINALG_MAT3(M, V, S)                                                         \
  WP_LFN S determinant(const M& m) { return detail::dot3(m.z_axis, cross(m.x_axis, m.y_axis)); } \
  WP_LFN M inverse(const M& m) {                                                         \
    const V t0 = cross(m.y_axis, m.z_axis);                                             \
    const V t1 = cross(m.z_axis, m.x_axis);                                             \
    const V t2 = cross(m.x_axis, m.y_axis);                                             \
    const S det = detail::dot3(m.z_axis, t2);                                           \
    if (det == (S)0) return M##_ZERO();                                                 \
    const V r = V##_splat((S)1 / det);                                                  \
    return transpose(M##_from_cols(t0 * r, t1 * r, t2 * r));                            \
  }                                                                                     \
  WP_LFN M skew(const V& v) {                                                            \
    const S z = (S)0;                                                                   \
    return M##_from_cols(V##_new(z, v.z, -v.y), V##_new(-v.z, z, v.x), V##_new(v.y, -v.x, z)); \
  }
WP_LINALG_MAT3(Mat3, Vec3, f32)
WP_LINALG_MAT3(DMat3, DVec3, f64)
#undef WP_LINALG_MAT3

// DMat4: glam's scalar code.
WP_LFN f64 determinant(const DMat4& m) {
  const f64 m00 = m.x_axis.x, m01 = m.x_axis.y, m02 = m.x_axis.z, m03 = m.x_axis.w;
  const f64 m10 = m.y_axis.x, m11 = m.y_axis.y, m12 = m.y_axis.z, m13 = m.y_axis.w;
  const f64 m20 = m.z_axis.x, m21 = m.z_axis.y, m22 = m.z_axis.z, m23 = m.z_axis.w;
  const f64 m30 = m.w_axis.x, m31 = m.w_axis.y, m32 = m.w_axis.z, m33 = m.w_axis.w;
  const f64 a2323 = m22 * m33 - m23 * m32;
  const f64 a1323 = m21 * m33 - m23 * m31;
  const f64 a1223 = m21 * m32 - m22 * m31;
  const f64 a0323 = m20 * m33 - m23 * m30;
  const f64 a0223 = m20 * m32 - m22 * m30;
  const f64 a0123 = m20 * m31 - m21 * m30;
  return m00 * (m11 * a2323 - m12 * a1323 + m13 * a1223) -
         m01 * (m10 * a2323 - m12 * a0323 + m13 * a0223) +
         m02 * (m10 * a1323 - m11 * a0323 + m13 * a0123) -
         m03 * (m10 * a1223 - m11 * a0223 + m12 * a0123);
}
WP_LFN DMat4 inverse(const DMat4& m) {
  if (determinant(m) == 0.0) return DMat4_ZERO();
  const f64 m00 = m.x_axis.x, m01 = m.x_axis.y, m02 = m.x_axis.z, m03 = m.x_axis.w;
  const f64 m10 = m.y_axis.x, m11 = m.y_axis.y, m12 = m.y_axis.z, m13 = m.y_axis.w;
  const f64 m20 = m.z_axis.x, m21 = m.z_axis.y, m22 = m.z_axis.z, m23 = m.z_axis.w;
  const f64 m30 = m.w_axis.x, m31 = m.w_axis.y, m32 = m.w_axis.z, m33 = m.w_axis.w;
  const f64 c00 = m22 * m33 - m32 * m23, c02 = m12 * m33 - m32 * m13, c03 = m12 * m23 - m22 * m13;
  const f64 c04 = m21 * m33 - m31 * m23, c06 = m11 * m33 - m31 * m13, c07 = m11 * m23 - m21 * m13;
  const f64 c08 = m21 * m32 - m31 * m22, c10 = m11 * m32 - m31 * m12, c11 = m11 * m22 - m21 * m12;
  const f64 c12 = m20 * m33 - m30 * m23, c14 = m10 * m33 - m30 * m13, c15 = m10 * m23 - m20 * m13;
  const f64 c16 = m20 * m32 - m30 * m22, c18 = m10 * m32 - m30 * m12, c19 = m10 * m22 - m20 * m12;
  const f64 c20 = m20 * m31 - m30 * m21, c22 = m10 * m31 - m30 * m11, c23 = m10 * m21 - m20 * m11;
  const DVec4 f0 = DVec4_new(c00, c00, c02, c03), f1 = DVec4_new(c04, c04, c06, c07);
  const DVec4 f2 = DVec4_new(c08, c08, c10, c11), f3 = DVec4_new(c12, c12, c14, c15);
  const DVec4 f4 = DVec4_new(c16, c16, c18, c19), f5 = DVec4_new(c20, c20, c22, c23);
  const DVec4 v0 = DVec4_new(m10, m00, m00, m00), v1 = DVec4_new(m11, m01, m01, m01);
  const DVec4 v2 = DVec4_new(m12, m02, m02, m02), v3 = DVec4_new(m13, m03, m03, m03);
  const DVec4 i0 = v1 * f0 - v2 * f1 + v3 * f2;
  const DVec4 i1 = v0 * f0 - v2 * f3 + v3 * f4;
  const DVec4 i2 = v0 * f1 - v1 * f3 + v3 * f5;
  const DVec4 i3 = v0 * f2 - v1 * f4 + v2 * f5;
  const DVec4 sa = DVec4_new(1.0, -1.0, 1.0, -1.0), sb = DVec4_new(-1.0, 1.0, -1.0, 1.0);
  const DMat4 inv = DMat4_from_cols(i0 * sa, i1 * sb, i2 * sa, i3 * sb);
  const DVec4 col0 = DVec4_new(inv.x_axis.x, inv.y_axis.x, inv.z_axis.x, inv.w_axis.x);
  const DVec4 d0 = m.x_axis * col0;
  const f64 d1 = d0.x + d0.y + d0.z + d0.w;
  return inv * (1.0 / d1);
}

// Mat4: glam's SSE2 code, lane by lane (shuffles are exact; the arithmetic is per lane).
WP_LFN f32 determinant(const Mat4& m) {
  using namespace detail;
  const m4 y = m4_of(m.y_axis), z = m4_of(m.z_axis), w = m4_of(m.w_axis);
  const m4 swp2a = shuf(z, z, 0x16), swp3a = shuf(w, w, 0xEF);
  const m4 swp2b = shuf(z, z, 0xEF), swp3b = shuf(w, w, 0x16);
  const m4 swp2c = shuf(z, z, 0x06), swp3c = shuf(w, w, 0x60);
  const m4 mula = swp2a * swp3a, mulb = swp2b * swp3b, mulc = swp2c * swp3c;
  const m4 sube = mula - mulb;
  const m4 subf = movehl(mulc, mulc) - mulc;
  const m4 subfaca = shuf(sube, sube, 0x90);
  const m4 mulfaca = shuf(y, y, 0x01) * subfaca;
  const m4 subtmpb = shuf(sube, subf, 0x0D);
  const m4 subfacb = shuf(subtmpb, subtmpb, 0xD4);
  const m4 mulfacb = shuf(y, y, 0x5A) * subfacb;
  const m4 subres = mulfaca - mulfacb;
  const m4 subtmpc = shuf(sube, subf, 0x4A);
  const m4 subfacc = shuf(subtmpc, subtmpc, 0xF8);
  const m4 mulfacc = shuf(y, y, 0xBF) * subfacc;
  const m4 detcof = (subres + mulfacc) * m4_set(1.0f, -1.0f, 1.0f, -1.0f);
  return dot4(m4_of(m.x_axis), detcof);
}
WP_LFN Mat4 inverse(const Mat4& m) {
  using namespace detail;
  if (determinant(m) == 0.0f) return Mat4_ZERO();
  const m4 x = m4_of(m.x_axis), y = m4_of(m.y_axis), z = m4_of(m.z_axis), w = m4_of(m.w_axis);
  // fac_k = swp00 * swp01 - swp02 * swp03 with swp0a = shuf(w, z, A), swp0b = shuf(w, z, B),
  // swp00 = shuf(z, y, B), swp01 = shuf(swp0a, swp0a, 0x80), swp02 = shuf(swp0b, swp0b, 0x80),
  // swp03 = shuf(z, y, A).
  auto fac = [&](int a, int b) {
    const m4 swp0a = shuf(w, z, a), swp0b = shuf(w, z, b);
    const m4 swp00 = shuf(z, y, b), swp01 = shuf(swp0a, swp0a, 0x80);
    const m4 swp02 = shuf(swp0b, swp0b, 0x80), swp03 = shuf(z, y, a);
    return swp00 * swp01 - swp02 * swp03;
  };
  const m4 fac0 = fac(0xFF, 0xAA), fac1 = fac(0xFF, 0x55), fac2 = fac(0xAA, 0x55);
  const m4 fac3 = fac(0xFF, 0x00), fac4 = fac(0xAA, 0x00), fac5 = fac(0x55, 0x00);
  const m4 sign_a = m4_set(-1.0f, 1.0f, -1.0f, 1.0f);  // _mm_set_ps(1, -1, 1, -1)
  const m4 sign_b = m4_set(1.0f, -1.0f, 1.0f, -1.0f);  // _mm_set_ps(-1, 1, -1, 1)
  auto vec = [&](int k) {
    const m4 t = shuf(y, x, k);
    return shuf(t, t, 0xA8);
  };
  const m4 vec0 = vec(0x00), vec1 = vec(0x55), vec2 = vec(0xAA), vec3 = vec(0xFF);
  const m4 inv0 = sign_b * ((vec1 * fac0 - vec2 * fac1) + vec3 * fac2);
  const m4 inv1 = sign_a * ((vec0 * fac0 - vec2 * fac3) + vec3 * fac4);
  const m4 inv2 = sign_b * ((vec0 * fac1 - vec1 * fac3) + vec3 * fac5);
  const m4 inv3 = sign_a * ((vec0 * fac2 - vec1 * fac4) + vec2 * fac5);
  const m4 row0 = shuf(inv0, inv1, 0x00), row1 = shuf(inv2, inv3, 0x00);
  const m4 row2 = shuf(row0, row1, 0x88);
  const f32 rcp = 1.0f / dot4(x, row2);
  const m4 r = m4_set(rcp, rcp, rcp, rcp);
  return Mat4_from_cols(m4_vec(inv0 * r), m4_vec(inv1 * r), m4_vec(inv2 * r), m4_vec(inv3 * r));
}

// ------------------------------------------------------------------------------------------
// Quaternions
// ------------------------------------------------------------------------------------------

#define WP_LINALG_QUAT(Q, V3, M3, S)                                                    \
  WP_LFN S dot(const Q& a, const Q& b) { return detail::qdot(a, b); }                    \
  WP_LFN S length_sq(const Q& q) { return detail::qdot(q, q); }                          \
  /* length, normalize: rescaled by a power of two (wp_vector.h). */                   \
  WP_LFN S length(const Q& q) {                                                          \
    Q w;                                                                                \
    S l, k, inv;                                                                        \
    detail::norm_scaled(q, [](const Q& a) { return detail::qdot(a, a); }, w, l, k, inv); \
    return l * inv;                                                                     \
  }                                                                                     \
  WP_LFN Q normalize(const Q& q) {                                                       \
    Q w;                                                                                \
    S l, k, inv;                                                                        \
    detail::norm_scaled(q, [](const Q& a) { return detail::qdot(a, a); }, w, l, k, inv); \
    if (l > (S)0) return Q##_from_xyzw(w.x / l, w.y / l, w.z / l, w.w / l);             \
    return Q##_IDENTITY();                                                              \
  }                                                                                     \
  WP_LFN Q quat_inverse(const Q& q) { return Q##_from_xyzw(-q.x, -q.y, -q.z, q.w); }     \
  WP_LFN Q inverse(const Q& q) { return quat_inverse(q); }                               \
  WP_LFN Q quat_from_axis_angle(const V3& axis, S angle) {                               \
    const S h = angle * (S)0.5;                                                         \
    const S s = sin(h), c = cos(h);                                                     \
    const V3 v = axis * s;                                                              \
    return Q##_from_xyzw(v.x, v.y, v.z, c);                                             \
  }                                                                                     \
  WP_LFN V3 quat_rotate(const Q& q, const V3& v) { return q * v; }                       \
  WP_LFN V3 quat_rotate_inv(const Q& q, const V3& v) { return quat_inverse(q) * v; }     \
  WP_LFN M3 quat_to_matrix(const Q& q) {                                                 \
    const S x2 = q.x + q.x, y2 = q.y + q.y, z2 = q.z + q.z;                             \
    const S xx = q.x * x2, xy = q.x * y2, xz = q.x * z2;                                \
    const S yy = q.y * y2, yz = q.y * z2, zz = q.z * z2;                                \
    const S wx = q.w * x2, wy = q.w * y2, wz = q.w * z2;                                \
    return M3##_from_cols(V3##_new((S)1 - (yy + zz), xy + wz, xz - wy),                 \
                          V3##_new(xy - wz, (S)1 - (xx + zz), yz + wx),                 \
                          V3##_new(xz + wy, yz - wx, (S)1 - (xx + yy)));                \
  }                                                                                     \
  WP_LFN Q quat_from_matrix(const M3& m) {                                               \
    const S m00 = m.x_axis.x, m01 = m.x_axis.y, m02 = m.x_axis.z;                       \
    const S m10 = m.y_axis.x, m11 = m.y_axis.y, m12 = m.y_axis.z;                       \
    const S m20 = m.z_axis.x, m21 = m.z_axis.y, m22 = m.z_axis.z;                       \
    if (m22 <= (S)0) {                                                                  \
      const S dif10 = m11 - m00, omm22 = (S)1 - m22;                                    \
      if (dif10 <= (S)0) {                                                              \
        const S f = omm22 - dif10, inv = (S)0.5 / sqrt(f);                              \
        return Q##_from_xyzw(f * inv, (m01 + m10) * inv, (m02 + m20) * inv, (m12 - m21) * inv); \
      } else {                                                                          \
        const S f = omm22 + dif10, inv = (S)0.5 / sqrt(f);                              \
        return Q##_from_xyzw((m01 + m10) * inv, f * inv, (m12 + m21) * inv, (m20 - m02) * inv); \
      }                                                                                 \
    } else {                                                                            \
      const S sum10 = m11 + m00, opm22 = (S)1 + m22;                                    \
      if (sum10 <= (S)0) {                                                              \
        const S f = opm22 - sum10, inv = (S)0.5 / sqrt(f);                              \
        return Q##_from_xyzw((m02 + m20) * inv, (m12 + m21) * inv, f * inv, (m01 - m10) * inv); \
      } else {                                                                          \
        const S f = opm22 + sum10, inv = (S)0.5 / sqrt(f);                              \
        return Q##_from_xyzw((m12 - m21) * inv, (m20 - m02) * inv, (m01 - m10) * inv, f * inv); \
      }                                                                                 \
    }                                                                                   \
  }                                                                                     \
  WP_LFN Q quat_slerp(const Q& q0, const Q& q1, S t) {                                   \
    const Q d = quat_inverse(q0) * q1;                                                  \
    const V3 v = V3##_new(d.x, d.y, d.z);                                               \
    const V3 n = normalize(v);                                                          \
    const V3 axis = d.w < (S)0 ? -n : n;                                                \
    const S angle = (S)2 * atan2(length(v), abs(d.w));                                  \
    return q0 * quat_from_axis_angle(axis, t * angle);                                  \
  }
WP_LINALG_QUAT(Quat, Vec3, Mat3, f32)
WP_LINALG_QUAT(DQuat, DVec3, DMat3, f64)
#undef WP_LINALG_QUAT

// ----- quat_from_euler, quat_to_euler: warp-core/src/builtins/euler.rs, step for step -----
namespace detail {
// The axis an index names in quat_from_euler (0 is x, 1 is y, else z).
WP_LFN int euler_axis(i32 n) { return n == 0 ? 0 : n == 1 ? 1 : 2; }
// The lane of (w, x, y, z) a 1-based index reads in quat_to_euler (2: y, 3: z, else x).
WP_LFN int euler_pick(long long n) { return n == 2 ? 2 : n == 3 ? 3 : 1; }
// quat_to_euler's steps, which its adjoint reads again (warp-core's ToEuler).
template <typename S>
struct ToEuler {
  bool not_proper;
  S e;
  int pi, pj, pk;
  S a, b, c, d, quo, n;
  int branch;
  int slot[3];
  S out[3];
};
}  // namespace detail

// EPS: Warp's 1e-6; PI, HALF_PI: Rust's consts of the type.
#define WP_LINALG_EULER(Q, V3, S, EPS, PI, HALF_PI)                                     \
  WP_LFN detail::ToEuler<S> to_euler_steps(const Q& q, i32 i0, i32 j0, i32 k0) {         \
    const S qa[4] = {q.w, q.x, q.y, q.z};                                               \
    const long long i = (long long)i0 + 1, j = (long long)j0 + 1;                       \
    long long k = (long long)k0 + 1;                                                    \
    detail::ToEuler<S> p;                                                               \
    p.not_proper = true;                                                                \
    if (i == k) {                                                                       \
      p.not_proper = false;                                                             \
      k = 6 - i - j;                                                                    \
    }                                                                                   \
    p.e = (S)((double)(i - j) * (double)(j - k) * (double)(k - i) / 2.0);               \
    p.pi = detail::euler_pick(i);                                                       \
    p.pj = detail::euler_pick(j);                                                       \
    p.pk = detail::euler_pick(k);                                                       \
    S a = qa[0], b = qa[p.pi], c = qa[p.pj], d = qa[p.pk] * p.e;                        \
    if (p.not_proper) {                                                                 \
      a -= qa[p.pj];                                                                    \
      b += qa[p.pk] * p.e;                                                              \
      c += qa[0];                                                                       \
      d -= qa[p.pi];                                                                    \
    }                                                                                   \
    const S s = a * a + b * b;                                                          \
    p.n = s + c * c + d * d;                                                            \
    p.quo = ((S)2 * s) / p.n;                                                           \
    S t2 = acos(p.quo - (S)1);                                                          \
    const S tp = atan2(b, a), tm = atan2(d, c);                                         \
    const S zero = (S)0;                                                                \
    S t1, t3;                                                                           \
    if (abs(t2) < EPS) {                                                                \
      t1 = zero;                                                                        \
      t3 = (S)2 * tp - zero;                                                            \
      p.branch = 0;                                                                     \
    } else if (abs(t2 - PI) < EPS) {                                                    \
      t1 = zero;                                                                        \
      t3 = (S)2 * tm + zero;                                                            \
      p.branch = 1;                                                                     \
    } else {                                                                            \
      t1 = tp - tm;                                                                     \
      t3 = tp + tm;                                                                     \
      p.branch = 2;                                                                     \
    }                                                                                   \
    if (p.not_proper) {                                                                 \
      t2 -= HALF_PI;                                                                    \
      t3 *= p.e;                                                                        \
    }                                                                                   \
    p.slot[0] = 0;                                                                      \
    p.slot[1] = 1;                                                                      \
    p.slot[2] = 2;                                                                      \
    if (i == 2) {                                                                       \
      p.slot[0] = 1;                                                                    \
      p.slot[1] = 0;                                                                    \
    } else if (i == 3) {                                                                \
      p.slot[0] = 2;                                                                    \
      p.slot[2] = 0;                                                                    \
    }                                                                                   \
    p.slot[j == 1 ? 0 : j == 2 ? 1 : 2] = 1;                                            \
    p.slot[k == 1 ? 0 : k == 2 ? 1 : 2] = 2;                                            \
    const S t[3] = {t1, t2, t3};                                                        \
    p.a = a;                                                                            \
    p.b = b;                                                                            \
    p.c = c;                                                                            \
    p.d = d;                                                                            \
    for (int m = 0; m < 3; ++m) p.out[m] = t[p.slot[m]];                                \
    return p;                                                                           \
  }                                                                                     \
  WP_LFN V3 quat_to_euler(const Q& q, i32 i, i32 j, i32 k) {                             \
    const detail::ToEuler<S> p = to_euler_steps(q, i, j, k);                            \
    return V3##_new(p.out[0], p.out[1], p.out[2]);                                      \
  }                                                                                     \
  /* The axis quaternion n (0: i, 1: j, 2: k) of quat_from_euler and its half angle. */ \
  WP_LFN Q euler_axis_quat(const V3& e, i32 idx, S& h) {                                 \
    const S ea[3] = {e.x, e.y, e.z};                                                    \
    const int ax = detail::euler_axis(idx);                                             \
    h = (S)0.5 * ea[ax];                                                                \
    S l[4] = {(S)0, (S)0, (S)0, (S)0};                                                  \
    l[ax] = sin(h);                                                                     \
    l[3] = cos(h);                                                                      \
    return Q##_from_xyzw(l[0], l[1], l[2], l[3]);                                       \
  }                                                                                     \
  WP_LFN Q quat_from_euler(const V3& e, i32 i, i32 j, i32 k) {                           \
    S h;                                                                                \
    const Q qi = euler_axis_quat(e, i, h);                                              \
    const Q qj = euler_axis_quat(e, j, h);                                              \
    const Q qk = euler_axis_quat(e, k, h);                                              \
    return qk * (qj * qi);                                                              \
  }
WP_LINALG_EULER(Quat, Vec3, f32, 1e-6f, 3.14159265358979323846f, 1.57079632679489661923f)
WP_LINALG_EULER(DQuat, DVec3, f64, 1e-6, 3.14159265358979323846, 1.57079632679489661923)
#undef WP_LINALG_EULER

}  // namespace wp

// wp_svd.h: section "svd" of the builtin table: the matrix decompositions of
// warp-core/src/builtins/svd.rs (read its documentation for the algorithms and conventions),
// as results of `tuple_t`, Rust's tuples (element k is `f<k>`):
//
//   svd3(a) -> tuple_t<M, V, M>   Mat3/DMat3: (U, sigma, V), a = U diag(sigma) V^T, U and V
//                                 rotations, sigma0 >= sigma1 >= |sigma2|, sigma2 of det(a)'s sign.
//   svd2(a) -> tuple_t<M, V, M>   Mat2/DMat2: (U, sigma, V), sigma >= 0, det U = sign(det a).
//   qr3(a)  -> tuple_t<M, M>      Mat3/DMat3: (Q, R), a = Q R, Q a rotation.
//   eig3(a) -> tuple_t<M, V>      Mat3/DMat3 symmetric: (Q, d), a = Q diag(d) Q^T, unsorted.
//
// NVIDIA Warp's algorithms (warp/native/svd.h): Jacobi sweeps with approximate Givens rotations
// accumulated as a quaternion (5 sweeps for f32, where Warp has 4; 8 for f64), Givens QR. Every operation is the
// CPU's, in the same order, on rows (`rows3<S>`, m[row][col]), so the results agree bit for bit
// with warp-core when nothing is contracted into an FMA (NVRTC --fmad=false); Warp's GPU
// `rsqrt` is `1 / sqrt` here, as on the CPU. Checked by tests/cuda_host_cpp.rs.
#pragma once
#include "wp_scalar.h"
#include "wp_vector.h"
#include "wp_linalg.h"

namespace wp {

// The decompositions return `tuple_t` (wp_core.h).

namespace detail {
namespace svd {

/// Warp's `_svd_config` and the approximate Givens constants (f64 values rounded to S).
template <typename S>
struct cfg;
template <>
struct cfg<f32> {
  static WP_FN f32 eps() { return 1e-6f; }
  static WP_FN int sweeps() { return 5; }  // Warp: 4 (see warp-core builtins/svd.rs)
};
template <>
struct cfg<f64> {
  static WP_FN f64 eps() { return 1e-12; }
  static WP_FN int sweeps() { return 8; }
};
template <typename S> WP_FN S gamma() { return (S)5.82842712474619; }
template <typename S> WP_FN S cstar() { return (S)0.9238795325112867; }
template <typename S> WP_FN S sstar() { return (S)0.3826834323650898; }
template <typename S> WP_FN S sqrt1_2() { return (S)0.7071067811865476; }

/// A square matrix as rows (m[row][col]): the decompositions' working form.
template <typename S, int N>
struct rows {
  S m[N][N];
};
template <typename S>
using rows3 = rows<S, 3>;
template <typename S>
using rows2 = rows<S, 2>;

/// A glam (column-major) matrix as rows, and back.
template <int N, typename M>
WP_FN rows<typename vec_traits<M>::scalar, N> to_rows(const M& a) {
  rows<typename vec_traits<M>::scalar, N> r;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) r.m[i][j] = vec_traits<M>::get(a, j * N + i);
  return r;
}
template <typename M, int N>
WP_FN M from_rows(const rows<typename vec_traits<M>::scalar, N>& r) {
  M a;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) vec_traits<M>::at(a, j * N + i) = r.m[i][j];
  return a;
}

/// a b, a^T b, a b^T: each entry summed left to right.
template <typename S>
WP_FN rows3<S> mul3(const rows3<S>& a, const rows3<S>& b) {
  rows3<S> r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      r.m[i][j] = a.m[i][0] * b.m[0][j] + a.m[i][1] * b.m[1][j] + a.m[i][2] * b.m[2][j];
  return r;
}
template <typename S>
WP_FN rows3<S> mul3_tn(const rows3<S>& a, const rows3<S>& b) {
  rows3<S> r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      r.m[i][j] = a.m[0][i] * b.m[0][j] + a.m[1][i] * b.m[1][j] + a.m[2][i] * b.m[2][j];
  return r;
}
template <typename S>
WP_FN rows3<S> mul3_nt(const rows3<S>& a, const rows3<S>& b) {
  rows3<S> r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      r.m[i][j] = a.m[i][0] * b.m[j][0] + a.m[i][1] * b.m[j][1] + a.m[i][2] * b.m[j][2];
  return r;
}

/// The half-angle pair (ch, sh) approximately zeroing the block's off-diagonal entry.
template <typename S>
WP_FN void approx_givens(S a11, S a21, S a22, S& ch, S& sh) {
  const S c = (S)2 * (a11 - a22);
  const S s = a21;
  const bool first_order = gamma<S>() * s * s < c * c;
  const S w = (S)1 / wp::sqrt(c * c + s * s);
  ch = first_order ? w * c : cstar<S>();
  sh = first_order ? w * s : sstar<S>();
}

/// One Jacobi rotation of the lower triangle s = (s11, s21, s22, s31, s32, s33), accumulated
/// into the quaternion q = (x, y, z, w); then the next plane is relabelled to come first.
template <typename S>
WP_FN void jacobi_rotation(S* s, S* q, int x, int y, int z) {
  const S s11 = s[0], s21 = s[1], s22 = s[2], s31 = s[3], s32 = s[4], s33 = s[5];
  S ch, sh;
  approx_givens(s11, s21, s22, ch, sh);
  const S scale = ch * ch + sh * sh;
  const S c = (ch * ch - sh * sh) / scale;
  const S t = ((S)2 * sh * ch) / scale;
  const S n11 = c * (c * s11 + t * s21) + t * (c * s21 + t * s22);
  const S n21 = c * (-t * s11 + c * s21) + t * (-t * s21 + c * s22);
  const S n22 = -t * (-t * s11 + c * s21) + c * (-t * s21 + c * s22);
  const S n31 = c * s31 + t * s32;
  const S n32 = -t * s31 + c * s32;
  const S tmp[3] = {q[0] * sh, q[1] * sh, q[2] * sh};
  const S shw = sh * q[3];
  for (int k = 0; k < 4; ++k) q[k] = q[k] * ch;
  q[z] = q[z] + shw;
  q[3] = q[3] - tmp[z];
  q[x] = q[x] + tmp[y];
  q[y] = q[y] - tmp[x];
  s[0] = n22;
  s[1] = n32;
  s[2] = s33;
  s[3] = n21;
  s[4] = n31;
  s[5] = n11;
}

template <typename S>
WP_FN void jacobi(S* s, S* q) {
  q[0] = (S)0;
  q[1] = (S)0;
  q[2] = (S)0;
  q[3] = (S)1;
  for (int k = 0; k < cfg<S>::sweeps(); ++k) {
    jacobi_rotation(s, q, 0, 1, 2);
    jacobi_rotation(s, q, 1, 2, 0);
    jacobi_rotation(s, q, 2, 0, 1);
  }
}

template <typename S>
WP_FN rows3<S> quat_rows(const S* q) {
  const S x = q[0], y = q[1], z = q[2], w = q[3];
  const S xx = x * x, yy = y * y, zz = z * z;
  const S xz = x * z, xy = x * y, yz = y * z;
  const S wx = w * x, wy = w * y, wz = w * z;
  const S one = (S)1, two = (S)2;
  rows3<S> r;
  r.m[0][0] = one - two * (yy + zz);
  r.m[0][1] = two * (xy - wz);
  r.m[0][2] = two * (xz + wy);
  r.m[1][0] = two * (xy + wz);
  r.m[1][1] = one - two * (xx + zz);
  r.m[1][2] = two * (yz - wx);
  r.m[2][0] = two * (xz - wy);
  r.m[2][1] = two * (yz + wx);
  r.m[2][2] = one - two * (xx + yy);
  return r;
}

template <typename S>
WP_FN void eig3_rows(const rows3<S>& a, rows3<S>& q, S* d) {
  S s[6] = {a.m[0][0], a.m[1][0], a.m[1][1], a.m[2][0], a.m[2][1], a.m[2][2]};
  S quat[4];
  jacobi(s, quat);
  q = quat_rows(quat);
  const rows3<S> u = mul3(mul3_tn(q, a), q);
  d[0] = u.m[0][0];
  d[1] = u.m[1][1];
  d[2] = u.m[2][2];
}

/// The half-angle pair of the rotation taking (a1, a2) to (rho, 0).
template <typename S>
WP_FN void qr_givens(S a1, S a2, S& ch, S& sh) {
  const S eps = cfg<S>::eps();
  const S rho = wp::sqrt(a1 * a1 + a2 * a2);
  sh = rho > eps ? a2 : (S)0;
  ch = wp::abs(a1) + wp::max(rho, eps);
  if (a1 < (S)0) {
    const S t = sh;
    sh = ch;
    ch = t;
  }
  const S w = (S)1 / wp::sqrt(ch * ch + sh * sh);
  ch = ch * w;
  sh = sh * w;
}

template <typename S>
WP_FN void rotate_rows(rows3<S>& m, int i, int j, S ch, S sh) {
  const S c = (S)1 - (S)2 * sh * sh;
  const S t = (S)2 * ch * sh;
  const S ri[3] = {m.m[i][0], m.m[i][1], m.m[i][2]};
  const S rj[3] = {m.m[j][0], m.m[j][1], m.m[j][2]};
  for (int k = 0; k < 3; ++k) {
    m.m[i][k] = c * ri[k] + t * rj[k];
    m.m[j][k] = -t * ri[k] + c * rj[k];
  }
}

template <typename S>
WP_FN void qr_rows(const rows3<S>& b, rows3<S>& q, rows3<S>& r) {
  r = b;
  S ch1, sh1, ch2, sh2, ch3, sh3;
  qr_givens(r.m[0][0], r.m[1][0], ch1, sh1);
  rotate_rows(r, 0, 1, ch1, sh1);
  qr_givens(r.m[0][0], r.m[2][0], ch2, sh2);
  rotate_rows(r, 0, 2, ch2, sh2);
  qr_givens(r.m[1][1], r.m[2][1], ch3, sh3);
  rotate_rows(r, 1, 2, ch3, sh3);
  const S one = (S)1, two = (S)2, four = (S)4, eight = (S)8;
  const S s1 = sh1 * sh1, s2 = sh2 * sh2, s3 = sh3 * sh3;
  const S m1 = -one + two * s1, m2 = -one + two * s2, m3 = -one + two * s3;
  q.m[0][0] = m1 * m2;
  q.m[0][1] = four * ch2 * ch3 * m1 * sh2 * sh3 + two * ch1 * sh1 * m3;
  q.m[0][2] = four * ch1 * ch3 * sh1 * sh3 - two * ch2 * m1 * sh2 * m3;
  q.m[1][0] = two * ch1 * sh1 * (one - two * s2);
  q.m[1][1] = -eight * ch1 * ch2 * ch3 * sh1 * sh2 * sh3 + m1 * m3;
  q.m[1][2] = -two * ch3 * sh3 + four * sh1 * (ch3 * sh1 * sh3 + ch1 * ch2 * sh2 * m3);
  q.m[2][0] = two * ch2 * sh2;
  q.m[2][1] = two * ch3 * (one - two * s2) * sh3;
  q.m[2][2] = m2 * m3;
}

/// Columns i and j of b and v swapped, the new column j negated.
template <typename S>
WP_FN void swap_neg(rows3<S>& b, rows3<S>& v, int i, int j) {
  for (int r = 0; r < 3; ++r) {
    const S x = b.m[r][i];
    b.m[r][i] = b.m[r][j];
    b.m[r][j] = -x;
    const S y = v.m[r][i];
    v.m[r][i] = v.m[r][j];
    v.m[r][j] = -y;
  }
}

template <typename S>
WP_FN S col_len2(const rows3<S>& b, int k) {
  return b.m[0][k] * b.m[0][k] + b.m[1][k] * b.m[1][k] + b.m[2][k] * b.m[2][k];
}

template <typename S>
WP_FN void svd3_rows(const rows3<S>& a, rows3<S>& u, S* sigma, rows3<S>& v) {
  const rows3<S> ata = mul3_tn(a, a);
  S s[6] = {ata.m[0][0], ata.m[1][0], ata.m[1][1], ata.m[2][0], ata.m[2][1], ata.m[2][2]};
  S quat[4];
  jacobi(s, quat);
  v = quat_rows(quat);
  rows3<S> b = mul3(a, v);
  S rho[3] = {col_len2(b, 0), col_len2(b, 1), col_len2(b, 2)};
  if (rho[0] < rho[1]) {
    swap_neg(b, v, 0, 1);
    const S t = rho[0];
    rho[0] = rho[1];
    rho[1] = t;
  }
  if (rho[0] < rho[2]) {
    swap_neg(b, v, 0, 2);
    const S t = rho[0];
    rho[0] = rho[2];
    rho[2] = t;
  }
  if (rho[1] < rho[2]) swap_neg(b, v, 1, 2);
  rows3<S> r;
  qr_rows(b, u, r);
  sigma[0] = r.m[0][0];
  sigma[1] = r.m[1][1];
  sigma[2] = r.m[2][2];
}

template <typename S>
WP_FN void svd2_rows(const rows2<S>& a, rows2<S>& u, S* sigma, rows2<S>& v) {
  const S a11 = a.m[0][0], a12 = a.m[0][1], a21 = a.m[1][0], a22 = a.m[1][1];
  const S zero = (S)0, one = (S)1, two = (S)2, half = (S)0.5;
  const S p = a11 * a11 + a21 * a21;
  const S r = a11 * a12 + a21 * a22;
  const S q = a12 * a12 + a22 * a22;
  const S trace = p + q;
  const S diff = p - q;
  const S disc = diff * diff + (S)4 * r * r;
  if (disc == zero) {
    const S s = wp::sqrt(half * trace);
    sigma[0] = s;
    sigma[1] = s;
    u.m[0][0] = one;
    u.m[0][1] = zero;
    u.m[1][0] = zero;
    u.m[1][1] = one;
    v = u;
    return;
  }
  const S root = wp::sqrt(disc);
  const S l1 = (trace + root) * half;
  const S l2 = (trace - root) * half;
  const S inv_s1 = one / wp::sqrt(l1);
  const S s1 = one / inv_s1;
  const S s2 = wp::sqrt(l2 < zero ? zero : l2);
  const S vy = diff - root + two * r;
  const S vx = diff + root - two * r;
  const S len2 = vx * vx + vy * vy;
  S v11, v21;
  if (len2 == zero) {
    v11 = sqrt1_2<S>();
    v21 = sqrt1_2<S>();
  } else {
    const S inv = one / wp::sqrt(len2);
    v11 = vx * inv;
    v21 = vy * inv;
  }
  const S u11 = (a11 * v11 + a12 * v21) * inv_s1;
  const S u21 = (a21 * v11 + a22 * v21) * inv_s1;
  const S det = a11 * a22 - a12 * a21;
  const S sign = det < zero ? -one : one;
  u.m[0][0] = u11;
  u.m[0][1] = -u21 * sign;
  u.m[1][0] = u21;
  u.m[1][1] = u11 * sign;
  v.m[0][0] = v11;
  v.m[0][1] = -v21;
  v.m[1][0] = v21;
  v.m[1][1] = v11;
  sigma[0] = s1;
  sigma[1] = s2;
}

}  // namespace svd
}  // namespace detail

#define WP_SVD3_OPS(M, V, S)                                                                  \
  WP_LFN tuple_t<M, V, M> svd3(const M& a) {                                                   \
    detail::svd::rows3<S> u, v;                                                               \
    S s[3];                                                                                   \
    detail::svd::svd3_rows(detail::svd::to_rows<3>(a), u, s, v);                                \
    return tuple_t<M, V, M>{detail::svd::from_rows<M>(u), V##_new(s[0], s[1], s[2]),         \
                            detail::svd::from_rows<M>(v)};                                   \
  }                                                                                           \
  WP_LFN tuple_t<M, V> eig3(const M& a) {                                                      \
    detail::svd::rows3<S> q;                                                                  \
    S d[3];                                                                                   \
    detail::svd::eig3_rows(detail::svd::to_rows<3>(a), q, d);                                   \
    return tuple_t<M, V>{detail::svd::from_rows<M>(q), V##_new(d[0], d[1], d[2])};           \
  }                                                                                           \
  WP_LFN tuple_t<M, M> qr3(const M& a) {                                                       \
    detail::svd::rows3<S> q, r;                                                               \
    detail::svd::qr_rows(detail::svd::to_rows<3>(a), q, r);                                     \
    return tuple_t<M, M>{detail::svd::from_rows<M>(q), detail::svd::from_rows<M>(r)};       \
  }
WP_SVD3_OPS(Mat3, Vec3, f32)
WP_SVD3_OPS(DMat3, DVec3, f64)
#undef WP_SVD3_OPS

#define WP_SVD2_OPS(M, V, S)                                                                  \
  WP_LFN tuple_t<M, V, M> svd2(const M& a) {                                                   \
    detail::svd::rows2<S> u, v;                                                               \
    S s[2];                                                                                   \
    detail::svd::svd2_rows(detail::svd::to_rows<2>(a), u, s, v);                                \
    return tuple_t<M, V, M>{detail::svd::from_rows<M>(u), V##_new(s[0], s[1]),               \
                            detail::svd::from_rows<M>(v)};                                   \
  }
WP_SVD2_OPS(Mat2, Vec2, f32)
WP_SVD2_OPS(DMat2, DVec2, f64)
#undef WP_SVD2_OPS

}  // namespace wp

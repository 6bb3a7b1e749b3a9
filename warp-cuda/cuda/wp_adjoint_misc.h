// wp_adjoint_misc.h: adjoints of the "misc" section.
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions. An adjoint
// translation unit includes wp_adjoint_core.h and the adjoint headers of the builtin-table
// sections its kernel uses (warp_cuda::ADJOINT_SECTIONS), so NVRTC parses no more than it
// needs.
#pragma once
#include "wp_adjoint_transform.h"
#include "wp_adjoint_svd.h"
#include "wp_misc.h"

namespace wp {

WP_LFN void adj_copysign(f32 x, f32 y, f32& adj_x, f32&, f32 adj_ret) {
  if (copysign(1.0f, x) == copysign(1.0f, y)) adj_x += adj_ret; else adj_x -= adj_ret;
}
WP_LFN void adj_copysign(f64 x, f64 y, f64& adj_x, f64&, f64 adj_ret) {
  if (copysign(1.0, x) == copysign(1.0, y)) adj_x += adj_ret; else adj_x -= adj_ret;
}

#define WP_ADJ_MISC_FVEC(V, S)                                                                  \
  WP_LFN void adj_min_element(const V& v, V& adj_v, S g) { vec_traits<V>::at(adj_v, (int)argmin(v)) += g; } \
  WP_LFN void adj_max_element(const V& v, V& adj_v, S g) { vec_traits<V>::at(adj_v, (int)argmax(v)) += g; } \
  WP_LFN void adj_norm_l1(const V& v, V& adj_v, S g) {                                           \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                                  \
      adj_abs(vec_traits<V>::get(v, i), vec_traits<V>::at(adj_v, i), g);                       \
  }                                                                                             \
  WP_LFN void adj_norm_l2(const V& v, V& adj_v, S g) { adj_length(v, adj_v, g); }               \
  WP_LFN void adj_norm_huber(const V& v, S delta, V& adj_v, S& adj_delta, S g) {                 \
    const S half = (S)1 / ((S)1 + (S)1);                                                        \
    const S a = dot(v, v);                                                                      \
    if (a <= delta * delta) {                                                                   \
      adj_length_sq(v, adj_v, half * g);                                                        \
    } else {                                                                                    \
      const S s = sqrt(a);                                                                      \
      adj_delta += g * (s - half * delta);                                                      \
      const S t = delta * g;                                                                    \
      adj_delta -= t * half;                                                                    \
      S adj_a = (S)0;                                                                           \
      adj_sqrt(a, adj_a, t);                                                                    \
      adj_length_sq(v, adj_v, adj_a);                                                           \
    }                                                                                           \
  }                                                                                             \
  WP_LFN void adj_norm_pseudo_huber(const V& v, S delta, V& adj_v, S& adj_delta, S g) {          \
    const S a = dot(v, v);                                                                      \
    const S dd = delta * delta;                                                                 \
    const S q = a / dd;                                                                         \
    const S u = (S)1 + q;                                                                       \
    adj_delta += g * sqrt(u);                                                                   \
    S adj_u = (S)0;                                                                             \
    adj_sqrt(u, adj_u, delta * g);                                                              \
    const S gb = adj_u / dd;                                                                    \
    S adj_dd = (S)0;                                                                            \
    adj_dd -= gb * q;                                                                           \
    adj_delta += adj_dd * delta;                                                                \
    adj_delta += adj_dd * delta;                                                                \
    adj_length_sq(v, adj_v, gb);                                                                \
  }                                                                                             \
  WP_LFN void adj_smooth_normalize(const V& v, S delta, V& adj_v, S& adj_delta, const V& g) {    \
    const S n = norm_pseudo_huber(v, delta);                                                    \
    S adj_n = (S)0;                                                                             \
    for (int i = 0; i < vec_traits<V>::N; ++i) {                                                \
      const S gi = vec_traits<V>::get(g, i) / n;                                                \
      vec_traits<V>::at(adj_v, i) += gi;                                                        \
      adj_n -= gi * (vec_traits<V>::get(v, i) / n);                                             \
    }                                                                                           \
    adj_norm_pseudo_huber(v, delta, adj_v, adj_delta, adj_n);                                   \
  }
WP_ADJ_MISC_FVEC(Vec2, f32)
WP_ADJ_MISC_FVEC(Vec3, f32)
WP_ADJ_MISC_FVEC(Vec4, f32)
WP_ADJ_MISC_FVEC(DVec2, f64)
WP_ADJ_MISC_FVEC(DVec3, f64)
WP_ADJ_MISC_FVEC(DVec4, f64)
#undef WP_ADJ_MISC_FVEC

#define WP_ADJ_MISC_IVEC(V, S)                                                                  \
  WP_LFN void adj_min_element(const V&, V&, S) {}                                                \
  WP_LFN void adj_max_element(const V&, V&, S) {}
WP_ADJ_MISC_IVEC(IVec2, i32)
WP_ADJ_MISC_IVEC(IVec3, i32)
WP_ADJ_MISC_IVEC(IVec4, i32)
WP_ADJ_MISC_IVEC(UVec2, u32)
WP_ADJ_MISC_IVEC(UVec3, u32)
WP_ADJ_MISC_IVEC(UVec4, u32)
#undef WP_ADJ_MISC_IVEC

#define WP_ADJ_MISC_DIAG(M, V)                                                                  \
  WP_LFN void adj_get_diag(const M&, M& adj_m, const V& g) {                                     \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                                  \
      vec_traits<V>::at(mat_traits<M>::at(adj_m, i), i) += vec_traits<V>::get(g, i);            \
  }
WP_ADJ_MISC_DIAG(Mat2, Vec2)
WP_ADJ_MISC_DIAG(Mat3, Vec3)
WP_ADJ_MISC_DIAG(Mat4, Vec4)
WP_ADJ_MISC_DIAG(DMat2, DVec2)
WP_ADJ_MISC_DIAG(DMat3, DVec3)
WP_ADJ_MISC_DIAG(DMat4, DVec4)
#undef WP_ADJ_MISC_DIAG

namespace detail {
template <typename Q, typename S>
WP_FN void quat_add_lanes(Q& q, S x, S y, S z, S w) {
  q.x += x;
  q.y += y;
  q.z += z;
  q.w += w;
}
}  // namespace detail

#define WP_ADJ_MISC_QUAT(Q, V3, M3, M4, S)                                                      \
  WP_LFN void adj_quat_to_axis_angle(const Q& q, Q& adj_q, const tuple_t<V3, S>& g) {            \
    const V3 v = V3##_new(q.x, q.y, q.z);                                                       \
    const bool neg = q.w < (S)0;                                                                \
    const S len = length(v);                                                                    \
    const S aw = abs(q.w);                                                                      \
    S adj_len = (S)0, adj_aw = (S)0;                                                            \
    adj_atan2(len, aw, adj_len, adj_aw, g.f1 * (S)2);                                           \
    S adj_w = (S)0;                                                                             \
    adj_abs(q.w, adj_w, adj_aw);                                                                \
    V3 adj_v = adj_zero<V3>();                                                                  \
    adj_length(v, adj_v, adj_len);                                                              \
    const V3 adj_n = neg ? -g.f0 : g.f0;                                                        \
    adj_normalize(v, adj_v, adj_n);                                                             \
    detail::quat_add_lanes(adj_q, adj_v.x, adj_v.y, adj_v.z, adj_w);                            \
  }                                                                                             \
  WP_LFN void adj_quat_rpy(S roll, S pitch, S yaw, S& adj_roll, S& adj_pitch, S& adj_yaw,        \
                          const Q& g) {                                                         \
    const S hy = yaw * (S)0.5, hr = roll * (S)0.5, hp = pitch * (S)0.5;                         \
    const S cy = cos(hy), sy = sin(hy), cr = cos(hr), sr = sin(hr), cp = cos(hp), sp = sin(hp); \
    const S gcy = ((g.w * (cr * cp) + g.x * (sr * cp)) + g.y * (cr * sp)) - g.z * (sr * sp);    \
    const S gsy = ((g.w * (sr * sp) - g.x * (cr * sp)) + g.y * (sr * cp)) + g.z * (cr * cp);    \
    const S gcr = ((g.w * (cy * cp) - g.x * (sy * sp)) + g.y * (cy * sp)) + g.z * (sy * cp);    \
    const S gsr = ((g.w * (sy * sp) + g.x * (cy * cp)) + g.y * (sy * cp)) - g.z * (cy * sp);    \
    const S gcp = ((g.w * (cy * cr) + g.x * (cy * sr)) + g.y * (sy * sr)) + g.z * (sy * cr);    \
    const S gsp = ((g.w * (sy * sr) - g.x * (sy * cr)) + g.y * (cy * cr)) - g.z * (cy * sr);    \
    adj_yaw += (gsy * cy - gcy * sy) * (S)0.5;                                                  \
    adj_roll += (gsr * cr - gcr * sr) * (S)0.5;                                                 \
    adj_pitch += (gsp * cp - gcp * sp) * (S)0.5;                                                \
  }                                                                                             \
  WP_LFN void adj_quat_to_rpy(const Q& q, Q& adj_q, const V3& g) {                               \
    const S x = q.x, y = q.y, z = q.z, w = q.w;                                                 \
    const S t0 = (S)2 * (w * x + y * z);                                                        \
    const S t1 = (S)1 - (S)2 * (x * x + y * y);                                                 \
    const S u = (S)2 * (w * y - z * x);                                                         \
    const S t2 = min(max(u, (S)-1), (S)1);                                                      \
    const S t3 = (S)2 * (w * z + x * y);                                                        \
    const S t4 = (S)1 - (S)2 * (y * y + z * z);                                                 \
    S a0 = (S)0, a1 = (S)0, a3 = (S)0, a4 = (S)0, at2 = (S)0, au = (S)0;                        \
    adj_atan2(t0, t1, a0, a1, g.x);                                                             \
    adj_asin(t2, at2, g.y);                                                                     \
    S alo = (S)0, ahi = (S)0;                                                                   \
    adj_clamp(u, (S)-1, (S)1, au, alo, ahi, at2);                                               \
    adj_atan2(t3, t4, a3, a4, g.z);                                                             \
    S gx = (S)0, gy = (S)0, gz = (S)0, gw = (S)0;                                               \
    const S b0 = a0 * (S)2;                                                                     \
    gw += b0 * x;                                                                               \
    gx += b0 * w;                                                                               \
    gy += b0 * z;                                                                               \
    gz += b0 * y;                                                                               \
    const S b1 = a1 * (S)2;                                                                     \
    gx -= b1 * (x + x);                                                                         \
    gy -= b1 * (y + y);                                                                         \
    const S bu = au * (S)2;                                                                     \
    gw += bu * y;                                                                               \
    gy += bu * w;                                                                               \
    gz -= bu * x;                                                                               \
    gx -= bu * z;                                                                               \
    const S b3 = a3 * (S)2;                                                                     \
    gw += b3 * z;                                                                               \
    gz += b3 * w;                                                                               \
    gx += b3 * y;                                                                               \
    gy += b3 * x;                                                                               \
    const S b4 = a4 * (S)2;                                                                     \
    gy -= b4 * (y + y);                                                                         \
    gz -= b4 * (z + z);                                                                         \
    detail::quat_add_lanes(adj_q, gx, gy, gz, gw);                                              \
  }                                                                                             \
  WP_LFN void adj_quat_twist(const V3& axis, const Q& q, V3& adj_axis, Q& adj_q, const Q& g) {   \
    const V3 a = V3##_new(q.x, q.y, q.z);                                                       \
    const S p = dot(a, axis);                                                                   \
    const Q t = Q##_from_xyzw(p * axis.x, p * axis.y, p * axis.z, q.w);                         \
    Q adj_t = adj_zero<Q>();                                                                    \
    adj_normalize(t, adj_t, g);                                                                 \
    const V3 adj_b = V3##_new(adj_t.x, adj_t.y, adj_t.z);                                       \
    const S adj_p = dot(adj_b, axis);                                                           \
    adj_axis += V3##_new(adj_b.x * p, adj_b.y * p, adj_b.z * p);                                \
    V3 adj_a = adj_zero<V3>();                                                                  \
    adj_dot(a, axis, adj_a, adj_axis, adj_p);                                                   \
    detail::quat_add_lanes(adj_q, adj_a.x, adj_a.y, adj_a.z, adj_t.w);                          \
  }                                                                                             \
  WP_LFN void adj_misc_twist_angle(const V3& axis, const Q& q, V3& adj_axis, Q& adj_q, S g,      \
                                  bool is_signed) {                                             \
    const V3 v = V3##_new(q.x, q.y, q.z);                                                       \
    const S d = dot(axis, v);                                                                   \
    const S s = is_signed ? d : abs(d);                                                         \
    S adj_s = (S)0, adj_w = (S)0;                                                               \
    adj_atan2(s, q.w, adj_s, adj_w, g * (S)2);                                                  \
    S adj_d = (S)0;                                                                             \
    if (is_signed)                                                                              \
      adj_d += adj_s;                                                                           \
    else                                                                                        \
      adj_abs(d, adj_d, adj_s);                                                                 \
    V3 adj_v = adj_zero<V3>();                                                                  \
    adj_dot(axis, v, adj_axis, adj_v, adj_d);                                                   \
    detail::quat_add_lanes(adj_q, adj_v.x, adj_v.y, adj_v.z, adj_w);                            \
  }                                                                                             \
  WP_LFN void adj_quat_twist_angle(const V3& axis, const Q& q, V3& adj_axis, Q& adj_q, S g) {    \
    adj_misc_twist_angle(axis, q, adj_axis, adj_q, g, false);                                   \
  }                                                                                             \
  WP_LFN void adj_quat_twist_angle_signed(const V3& axis, const Q& q, V3& adj_axis, Q& adj_q,    \
                                         S g) {                                                 \
    adj_misc_twist_angle(axis, q, adj_axis, adj_q, g, true);                                    \
  }                                                                                             \
  WP_LFN void adj_transform_compose(const V3&, const Q& q, const V3& s, V3& adj_p, Q& adj_q,     \
                                   V3& adj_s, const M4& g) {                                    \
    const M3 r = quat_to_matrix(q);                                                             \
    const V3 g0 = V3##_new(g.x_axis.x, g.x_axis.y, g.x_axis.z);                                 \
    const V3 g1 = V3##_new(g.y_axis.x, g.y_axis.y, g.y_axis.z);                                 \
    const V3 g2 = V3##_new(g.z_axis.x, g.z_axis.y, g.z_axis.z);                                 \
    adj_s.x += dot(g0, r.x_axis);                                                               \
    adj_s.y += dot(g1, r.y_axis);                                                               \
    adj_s.z += dot(g2, r.z_axis);                                                               \
    adj_p += V3##_new(g.w_axis.x, g.w_axis.y, g.w_axis.z);                                      \
    adj_quat_to_matrix(q, adj_q, M3##_from_cols(g0 * s.x, g1 * s.y, g2 * s.z));                 \
  }                                                                                             \
  WP_LFN void adj_transform_decompose(const M4& m, M4& adj_m, const tuple_t<V3, Q, V3>& g) {     \
    const V3 c[3] = {V3##_new(m.x_axis.x, m.x_axis.y, m.x_axis.z),                              \
                     V3##_new(m.y_axis.x, m.y_axis.y, m.y_axis.z),                              \
                     V3##_new(m.z_axis.x, m.z_axis.y, m.z_axis.z)};                             \
    S s[3];                                                                                     \
    V3 n[3] = {c[0], c[1], c[2]};                                                               \
    for (int j = 0; j < 3; ++j) {                                                               \
      s[j] = length(c[j]);                                                                      \
      if (s[j] != (S)0) n[j] = V3##_new(c[j].x / s[j], c[j].y / s[j], c[j].z / s[j]);           \
    }                                                                                           \
    M3 adj_r = adj_zero<M3>();                                                                  \
    adj_quat_from_matrix(M3##_from_cols(n[0], n[1], n[2]), adj_r, g.f1);                        \
    for (int j = 0; j < 3; ++j) {                                                               \
      const V3 adj_n = mat_traits<M3>::get(adj_r, j);                                           \
      V3 adj_c = adj_zero<V3>();                                                                \
      S adj_sj = vec_traits<V3>::get(g.f2, j);                                                  \
      if (s[j] != (S)0) {                                                                       \
        for (int i = 0; i < 3; ++i) {                                                           \
          const S gb = vec_traits<V3>::get(adj_n, i) / s[j];                                    \
          vec_traits<V3>::at(adj_c, i) += gb;                                                   \
          adj_sj -= gb * vec_traits<V3>::get(n[j], i);                                          \
        }                                                                                       \
      } else {                                                                                  \
        for (int i = 0; i < 3; ++i) vec_traits<V3>::at(adj_c, i) += vec_traits<V3>::get(adj_n, i); \
      }                                                                                         \
      adj_length(c[j], adj_c, adj_sj);                                                          \
      for (int i = 0; i < 3; ++i) vec_traits<M4>::at(adj_m, 4 * j + i) += vec_traits<V3>::get(adj_c, i); \
    }                                                                                           \
    for (int i = 0; i < 3; ++i) vec_traits<M4>::at(adj_m, 12 + i) += vec_traits<V3>::get(g.f0, i); \
  }
WP_ADJ_MISC_QUAT(Quat, Vec3, Mat3, Mat4, f32)
WP_ADJ_MISC_QUAT(DQuat, DVec3, DMat3, DMat4, f64)
#undef WP_ADJ_MISC_QUAT

}  // namespace wp

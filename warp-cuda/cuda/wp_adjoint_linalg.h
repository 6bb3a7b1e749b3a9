// wp_adjoint_linalg.h: adjoints of the "linalg" section (vector, matrix and quaternion builtins).
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions. An adjoint
// translation unit includes wp_adjoint_core.h and the adjoint headers of the builtin-table
// sections its kernel uses (warp_cuda::ADJOINT_SECTIONS), so NVRTC parses no more than it
// needs.
#pragma once
#include "wp_adjoint_builtins.h"
#include "wp_linalg.h"

namespace wp {

// ------------------------------------------------------------------------------------------
// Vector, matrix and quaternion builtins (warp-core/src/adjoint/linalg.rs)
// ------------------------------------------------------------------------------------------

// ----- length_sq: adj_v[i] += (v[i] + v[i]) * g -----
#define WP_ADJ_LENSQ(V, S)                                                       \
  WP_LFN void adj_length_sq(const V& v, V& adj_v, S g) {                          \
    typedef vec_traits<V> T;                                                     \
    for (int i = 0; i < T::N; ++i) T::at(adj_v, i) += (T::get(v, i) + T::get(v, i)) * g; \
  }
WP_ADJ_LENSQ(Vec2, f32)
WP_ADJ_LENSQ(Vec3, f32)
WP_ADJ_LENSQ(Vec4, f32)
WP_ADJ_LENSQ(DVec2, f64)
WP_ADJ_LENSQ(DVec3, f64)
WP_ADJ_LENSQ(DVec4, f64)
WP_ADJ_LENSQ(Quat, f32)
WP_ADJ_LENSQ(DQuat, f64)
#undef WP_ADJ_LENSQ
WP_LFN void adj_length_sq(const IVec2&, IVec2&, i32) {}
WP_LFN void adj_length_sq(const IVec3&, IVec3&, i32) {}
WP_LFN void adj_length_sq(const IVec4&, IVec4&, i32) {}
WP_LFN void adj_length_sq(const UVec2&, UVec2&, u32) {}
WP_LFN void adj_length_sq(const UVec3&, UVec3&, u32) {}
WP_LFN void adj_length_sq(const UVec4&, UVec4&, u32) {}

// ----- outer, diag, cw_mul, cw_div (vectors), and the matrix builtins -----
#define WP_ADJ_LINALG(V, M, S)                                                           \
  WP_LFN void adj_outer(const V& a, const V& b, V& adj_a, V& adj_b, const M& g) {         \
    adj_a += g * b;                                                                      \
    adj_b += detail::adj_transpose(g) * a;                                               \
  }                                                                                      \
  WP_LFN void adj_diag(const V&, V& adj_v, const M& g) {                                  \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                           \
      vec_traits<V>::at(adj_v, i) += vec_traits<V>::get(mat_traits<M>::get(g, i), i);    \
  }                                                                                      \
  WP_LFN void adj_cw_mul(const V& a, const V& b, V& adj_a, V& adj_b, const V& g) {        \
    detail::zip_vv(a, b, adj_a, adj_b, g, detail::l_mul());                              \
  }                                                                                      \
  WP_LFN void adj_cw_div(const V& a, const V& b, V& adj_a, V& adj_b, const V& g) {        \
    detail::zip_vv(a, b, adj_a, adj_b, g, detail::l_div());                              \
  }                                                                                      \
  WP_LFN void adj_cw_mul(const M& a, const M& b, M& adj_a, M& adj_b, const M& g) {        \
    detail::zip_vv(a, b, adj_a, adj_b, g, detail::l_mul());                              \
  }                                                                                      \
  WP_LFN void adj_cw_div(const M& a, const M& b, M& adj_a, M& adj_b, const M& g) {        \
    detail::zip_vv(a, b, adj_a, adj_b, g, detail::l_div());                              \
  }                                                                                      \
  WP_LFN void adj_transpose(const M&, M& adj_m, const M& g) { adj_m += detail::adj_transpose(g); } \
  WP_LFN void adj_trace(const M&, M& adj_m, S g) {                                        \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                           \
      vec_traits<V>::at(mat_traits<M>::at(adj_m, i), i) += g;                            \
  }                                                                                      \
  WP_LFN void adj_ddot(const M& a, const M& b, M& adj_a, M& adj_b, S g) {                 \
    typedef vec_traits<M> T;                                                             \
    for (int k = 0; k < T::N; ++k) {                                                     \
      T::at(adj_a, k) += g * T::get(b, k);                                               \
      T::at(adj_b, k) += g * T::get(a, k);                                               \
    }                                                                                    \
  }                                                                                      \
  /* inverse: T = transpose(inverse(m)); adj_m -= (T * G) * T. */                        \
  WP_LFN void adj_inverse(const M& m, M& adj_m, const M& g) {                             \
    const M t = detail::adj_transpose(inverse(m));                                       \
    adj_m -= (t * g) * t;                                                                \
  }
WP_ADJ_LINALG(Vec2, Mat2, f32)
WP_ADJ_LINALG(Vec3, Mat3, f32)
WP_ADJ_LINALG(Vec4, Mat4, f32)
WP_ADJ_LINALG(DVec2, DMat2, f64)
WP_ADJ_LINALG(DVec3, DMat3, f64)
WP_ADJ_LINALG(DVec4, DMat4, f64)
#undef WP_ADJ_LINALG

// ----- determinant: adj_m += g * cofactor(m) -----
#define WP_ADJ_DET2(M, S)                                                         \
  WP_LFN void adj_determinant(const M& m, M& a, S g) {                             \
    a.x_axis.x += g * m.y_axis.y;                                                 \
    a.x_axis.y -= g * m.y_axis.x;                                                 \
    a.y_axis.x -= g * m.x_axis.y;                                                 \
    a.y_axis.y += g * m.x_axis.x;                                                 \
  }
WP_ADJ_DET2(Mat2, f32)
WP_ADJ_DET2(DMat2, f64)
#undef WP_ADJ_DET2
#define WP_ADJ_DET3(M, V, S)                                                      \
  WP_LFN void adj_determinant(const M& m, M& a, S g) {                             \
    a.x_axis += wp::cross(m.y_axis, m.z_axis) * g;                                \
    a.y_axis += wp::cross(m.z_axis, m.x_axis) * g;                                \
    a.z_axis += wp::cross(m.x_axis, m.y_axis) * g;                                \
  }                                                                               \
  WP_LFN void adj_skew(const V&, V& adj_v, const M& g) {                           \
    adj_v.x += g.y_axis.z - g.z_axis.y;                                           \
    adj_v.y += g.z_axis.x - g.x_axis.z;                                           \
    adj_v.z += g.x_axis.y - g.y_axis.x;                                           \
  }
WP_ADJ_DET3(Mat3, Vec3, f32)
WP_ADJ_DET3(DMat3, DVec3, f64)
#undef WP_ADJ_DET3
/* 4x4: each entry's signed 3x3 minor (the remaining columns and rows in order). */
#define WP_ADJ_DET4(M, M3, V3, S)                                                  \
  WP_LFN void adj_determinant(const M& m, M& a, S g) {                              \
    for (int c = 0; c < 4; ++c) {                                                  \
      for (int r = 0; r < 4; ++r) {                                                \
        V3 cols[3];                                                                \
        for (int k = 0; k < 3; ++k) {                                              \
          const int cc = k < c ? k : k + 1;                                        \
          for (int j = 0; j < 3; ++j)                                              \
            vec_traits<V3>::at(cols[k], j) =                                       \
                vec_traits<M>::get(m, cc * 4 + (j < r ? j : j + 1));               \
        }                                                                          \
        const S d = determinant(M3##_from_cols(cols[0], cols[1], cols[2]));        \
        const S cof = ((r + c) % 2 == 1) ? -d : d;                                 \
        vec_traits<M>::at(a, c * 4 + r) += g * cof;                                \
      }                                                                            \
    }                                                                              \
  }
WP_ADJ_DET4(Mat4, Mat3, Vec3, f32)
WP_ADJ_DET4(DMat4, DMat3, DVec3, f64)
#undef WP_ADJ_DET4

// ----- quaternions -----
#define WP_ADJ_QUAT_LINALG(Q, V3, M3, S)                                                         \
  WP_LFN void adj_dot(const Q& a, const Q& b, Q& adj_a, Q& adj_b, S g) {                          \
    for (int i = 0; i < 4; ++i) {                                                                \
      vec_traits<Q>::at(adj_a, i) += g * vec_traits<Q>::get(b, i);                               \
      vec_traits<Q>::at(adj_b, i) += g * vec_traits<Q>::get(a, i);                               \
    }                                                                                            \
  }                                                                                              \
  /* length, normalize: the vector rules, rescaled likewise (detail::norm_scaled). */           \
  WP_LFN void adj_length(const Q& v, Q& adj_v, S g) {                                             \
    Q w;                                                                                         \
    S l, k, inv;                                                                                   \
    detail::norm_scaled(v, [](const Q& a) { return detail::qdot(a, a); }, w, l, k, inv);          \
    if (l > (S)0) {                                                                              \
      const S gl = g / l;                                                                        \
      for (int i = 0; i < 4; ++i) vec_traits<Q>::at(adj_v, i) += vec_traits<Q>::get(w, i) * gl;  \
    }                                                                                            \
  }                                                                                              \
  WP_LFN void adj_normalize(const Q& v, Q& adj_v, const Q& g) {                                   \
    Q w;                                                                                         \
    S l, k, inv;                                                                                   \
    detail::norm_scaled(v, [](const Q& a) { return detail::qdot(a, a); }, w, l, k, inv);          \
    if (l > (S)0) {                                                                              \
      const Q n = Q##_from_xyzw(w.x / l, w.y / l, w.z / l, w.w / l);                             \
      const S d = detail::qdot(n, g);                                                            \
      for (int i = 0; i < 4; ++i)                                                                \
        vec_traits<Q>::at(adj_v, i) +=                                                           \
            ((vec_traits<Q>::get(g, i) - vec_traits<Q>::get(n, i) * d) / l) * k;                 \
    }                                                                                            \
  }                                                                                              \
  WP_LFN void adj_quat_inverse(const Q&, Q& adj_q, const Q& g) {                                  \
    adj_q.x -= g.x;                                                                              \
    adj_q.y -= g.y;                                                                              \
    adj_q.z -= g.z;                                                                              \
    adj_q.w += g.w;                                                                              \
  }                                                                                              \
  WP_LFN void adj_inverse(const Q& q, Q& adj_q, const Q& g) { adj_quat_inverse(q, adj_q, g); }    \
  WP_LFN void adj_quat_from_axis_angle(const V3& axis, S angle, V3& adj_axis, S& adj_angle,       \
                                      const Q& g) {                                              \
    const S h = angle * (S)0.5;                                                                  \
    const S s = sin(h), c = cos(h);                                                              \
    adj_axis += V3##_new(g.x, g.y, g.z) * s;                                                     \
    const S d = (g.x * axis.x + g.y * axis.y) + g.z * axis.z;                                    \
    adj_angle += (d * c - g.w * s) * (S)0.5;                                                     \
  }                                                                                              \
  WP_LFN void adj_quat_rotate(const Q& q, const V3& v, Q& adj_q, V3& adj_v, const V3& g) {        \
    adj_mul(q, v, adj_q, adj_v, g);                                                              \
  }                                                                                              \
  WP_LFN void adj_quat_rotate_inv(const Q& q, const V3& v, Q& adj_q, V3& adj_v, const V3& g) {    \
    Q ac = adj_zero<Q>();                                                                        \
    adj_mul(quat_inverse(q), v, ac, adj_v, g);                                                   \
    adj_quat_inverse(q, adj_q, ac);                                                              \
  }                                                                                              \
  WP_LFN void adj_quat_to_matrix(const Q& q, Q& adj_q, const M3& gm) {                            \
    const V3 g0 = gm.x_axis, g1 = gm.y_axis, g2 = gm.z_axis;                                     \
    const S x = q.x, y = q.y, z = q.z, w = q.w;                                                  \
    const S a = g0.y + g1.x, b = g0.z + g2.x, c = g1.z + g2.y;                                   \
    const S p = g1.z - g2.y, r = g2.x - g0.z, s = g0.y - g1.x;                                   \
    const S dx = g1.y + g2.z, dy = g0.x + g2.z, dz = g0.x + g1.y;                                \
    adj_q.x += (((a * y + b * z) + p * w) - (dx * x + dx * x)) * (S)2;                           \
    adj_q.y += (((a * x + c * z) + r * w) - (dy * y + dy * y)) * (S)2;                           \
    adj_q.z += (((b * x + c * y) + s * w) - (dz * z + dz * z)) * (S)2;                           \
    adj_q.w += ((p * x + r * y) + s * z) * (S)2;                                                 \
  }                                                                                              \
  WP_LFN void adj_quat_from_matrix(const M3& m, M3& adj_m, const Q& g) {                          \
    S l[9];                                                                                      \
    for (int i = 0; i < 9; ++i) l[i] = vec_traits<M3>::get(m, i);                                \
    const S m00 = l[0], m11 = l[4], m22 = l[8];                                                  \
    const S gq[4] = {g.x, g.y, g.z, g.w};                                                        \
    int k;                                                                                       \
    S sd[3];                                                                                     \
    int oj[3], op[3], oq[3];                                                                     \
    S os[3];                                                                                     \
    S f;                                                                                         \
    auto set = [&](int kk, S s0, S s1, S s2, int j0, int p0, int q0, S t0, int j1, int p1,      \
                   int q1, S t1, int j2, int p2, int q2, S t2) {                                 \
      k = kk; sd[0] = s0; sd[1] = s1; sd[2] = s2;                                                \
      oj[0] = j0; op[0] = p0; oq[0] = q0; os[0] = t0;                                            \
      oj[1] = j1; op[1] = p1; oq[1] = q1; os[1] = t1;                                            \
      oj[2] = j2; op[2] = p2; oq[2] = q2; os[2] = t2;                                            \
    };                                                                                           \
    if (m22 <= (S)0) {                                                                           \
      if (m11 - m00 <= (S)0) {                                                                   \
        set(0, 1, -1, -1, 1, 1, 3, 1, 2, 2, 6, 1, 3, 5, 7, -1);                                  \
        f = ((S)1 - m22) - (m11 - m00);                                                          \
      } else {                                                                                   \
        set(1, -1, 1, -1, 0, 1, 3, 1, 2, 5, 7, 1, 3, 6, 2, -1);                                  \
        f = ((S)1 - m22) + (m11 - m00);                                                          \
      }                                                                                          \
    } else if (m11 + m00 <= (S)0) {                                                              \
      set(2, -1, -1, 1, 0, 2, 6, 1, 1, 5, 7, 1, 3, 1, 3, -1);                                    \
      f = ((S)1 + m22) - (m11 + m00);                                                            \
    } else {                                                                                     \
      set(3, 1, 1, 1, 0, 5, 7, -1, 1, 6, 2, -1, 2, 1, 3, -1);                                    \
      f = ((S)1 + m22) + (m11 + m00);                                                            \
    }                                                                                            \
    const S inv = (S)0.5 / sqrt(f);                                                              \
    S sum = (S)0;                                                                                \
    S a[9];                                                                                      \
    for (int i = 0; i < 9; ++i) a[i] = vec_traits<M3>::get(adj_m, i);                           \
    for (int o = 0; o < 3; ++o) {                                                                \
      const S lin = os[o] > (S)0 ? l[op[o]] + l[oq[o]] : l[op[o]] - l[oq[o]];                    \
      sum += gq[oj[o]] * lin;                                                                    \
      const S al = gq[oj[o]] * inv;                                                              \
      a[op[o]] += al;                                                                            \
      if (os[o] > (S)0) a[oq[o]] += al; else a[oq[o]] -= al;                                     \
    }                                                                                            \
    const S af = gq[k] * (inv * (S)0.5) + sum * -(inv / (f + f));                                \
    const int diag[3] = {0, 4, 8};                                                               \
    for (int i = 0; i < 3; ++i) {                                                                \
      if (sd[i] > (S)0) a[diag[i]] += af; else a[diag[i]] -= af;                                 \
    }                                                                                            \
    for (int i = 0; i < 9; ++i) vec_traits<M3>::at(adj_m, i) = a[i];                             \
  }                                                                                              \
  WP_LFN void adj_quat_slerp(const Q& q0, const Q& q1, S t, Q& adj_q0, Q& adj_q1, S& adj_t,       \
                            const Q& g) {                                                        \
    const Q c = quat_inverse(q0);                                                                \
    const Q d = c * q1;                                                                          \
    const V3 v = V3##_new(d.x, d.y, d.z);                                                        \
    const V3 n = normalize(v);                                                                   \
    const bool neg = d.w < (S)0;                                                                 \
    const V3 axis = neg ? -n : n;                                                                \
    const S len = length(v);                                                                     \
    const S aw = abs(d.w);                                                                       \
    const S angle = (S)2 * atan2(len, aw);                                                       \
    const S ta = t * angle;                                                                      \
    const Q r = quat_from_axis_angle(axis, ta);                                                  \
    Q adj_r = adj_zero<Q>();                                                                     \
    adj_mul(q0, r, adj_q0, adj_r, g);                                                            \
    V3 adj_axis = adj_zero<V3>();                                                                \
    S adj_ta = (S)0;                                                                             \
    adj_quat_from_axis_angle(axis, ta, adj_axis, adj_ta, adj_r);                                 \
    adj_t += adj_ta * angle;                                                                     \
    const S adj_at = (adj_ta * t) * (S)2;                                                        \
    S adj_len = (S)0, adj_aw = (S)0;                                                             \
    adj_atan2(len, aw, adj_len, adj_aw, adj_at);                                                 \
    S adj_dw = (S)0;                                                                             \
    adj_abs(d.w, adj_dw, adj_aw);                                                                \
    V3 adj_v = adj_zero<V3>();                                                                   \
    adj_length(v, adj_v, adj_len);                                                               \
    const V3 adj_n = neg ? -adj_axis : adj_axis;                                                 \
    adj_normalize(v, adj_v, adj_n);                                                              \
    const Q adj_d = Q##_from_xyzw(adj_v.x, adj_v.y, adj_v.z, adj_dw);                            \
    Q adj_c = adj_zero<Q>();                                                                     \
    adj_mul(c, q1, adj_c, adj_q1, adj_d);                                                        \
    adj_quat_inverse(q0, adj_q0, adj_c);                                                         \
  }
WP_ADJ_QUAT_LINALG(Quat, Vec3, Mat3, f32)
WP_ADJ_QUAT_LINALG(DQuat, DVec3, DMat3, f64)
#undef WP_ADJ_QUAT_LINALG

// ----- quat_from_euler, quat_to_euler: warp-core/src/adjoint/euler.rs, step for step -----
#define WP_ADJ_EULER(Q, V3, S)                                                                   \
  WP_LFN void adj_quat_from_euler(const V3& e, i32 i, i32 j, i32 k, V3& adj_e, i32&, i32&, i32&,  \
                                 const Q& g) {                                                   \
    const i32 idx[3] = {i, j, k};                                                                \
    S h[3];                                                                                      \
    Q qs[3];                                                                                     \
    for (int n = 0; n < 3; ++n) qs[n] = euler_axis_quat(e, idx[n], h[n]);                        \
    const Q t = qs[1] * qs[0];                                                                   \
    Q gq[3] = {adj_zero<Q>(), adj_zero<Q>(), adj_zero<Q>()};                                     \
    Q gt = adj_zero<Q>();                                                                        \
    adj_mul(qs[2], t, gq[2], gt, g);                                                             \
    adj_mul(qs[1], qs[0], gq[1], gq[0], gt);                                                     \
    S ge[3] = {(S)0, (S)0, (S)0};                                                                \
    for (int n = 2; n >= 0; --n) {                                                               \
      const int ax = detail::euler_axis(idx[n]);                                                 \
      S gh = (S)0;                                                                               \
      adj_cos(h[n], gh, gq[n].w);                                                                \
      adj_sin(h[n], gh, vec_traits<Q>::get(gq[n], ax));                                          \
      ge[ax] += (S)0.5 * gh;                                                                     \
    }                                                                                            \
    adj_e.x += ge[0];                                                                            \
    adj_e.y += ge[1];                                                                            \
    adj_e.z += ge[2];                                                                            \
  }                                                                                              \
  WP_LFN void adj_quat_to_euler(const Q& q, i32 i, i32 j, i32 k, Q& adj_q, i32&, i32&, i32&,      \
                               const V3& g) {                                                    \
    const detail::ToEuler<S> p = to_euler_steps(q, i, j, k);                                     \
    S gt[3] = {(S)0, (S)0, (S)0};                                                                \
    const S gl3[3] = {g.x, g.y, g.z};                                                            \
    for (int m = 0; m < 3; ++m) gt[p.slot[m]] += gl3[m];                                         \
    const S g1 = gt[0], g2 = gt[1];                                                              \
    S g3 = gt[2];                                                                                \
    if (p.not_proper) g3 *= p.e;                                                                 \
    S gtp = (S)0, gtm = (S)0;                                                                    \
    if (p.branch == 0) {                                                                         \
      gtp += (S)2 * g3;                                                                          \
    } else if (p.branch == 1) {                                                                  \
      gtm += (S)2 * g3;                                                                          \
    } else {                                                                                     \
      gtp += g3;                                                                                 \
      gtm += g3;                                                                                 \
      gtp += g1;                                                                                 \
      gtm -= g1;                                                                                 \
    }                                                                                            \
    S ga = (S)0, gb = (S)0, gc = (S)0, gd = (S)0;                                                \
    adj_atan2(p.d, p.c, gd, gc, gtm);                                                            \
    adj_atan2(p.b, p.a, gb, ga, gtp);                                                            \
    S gquo = (S)0;                                                                               \
    adj_acos(p.quo - (S)1, gquo, g2);                                                            \
    const S gn = -(gquo * p.quo) / p.n;                                                          \
    const S gs = (S)2 * (gquo / p.n) + gn;                                                       \
    gc += (S)2 * p.c * gn;                                                                       \
    gd += (S)2 * p.d * gn;                                                                       \
    ga += (S)2 * p.a * gs;                                                                       \
    gb += (S)2 * p.b * gs;                                                                       \
    S gl[4] = {(S)0, (S)0, (S)0, (S)0};                                                          \
    if (p.not_proper) {                                                                          \
      gl[p.pi] -= gd;                                                                            \
      gl[0] += gc;                                                                               \
      gl[p.pk] += p.e * gb;                                                                      \
      gl[p.pj] -= ga;                                                                            \
    }                                                                                            \
    gl[p.pk] += p.e * gd;                                                                        \
    gl[p.pj] += gc;                                                                              \
    gl[p.pi] += gb;                                                                              \
    gl[0] += ga;                                                                                 \
    adj_q.x += gl[1];                                                                            \
    adj_q.y += gl[2];                                                                            \
    adj_q.z += gl[3];                                                                            \
    adj_q.w += gl[0];                                                                            \
  }
WP_ADJ_EULER(Quat, Vec3, f32)
WP_ADJ_EULER(DQuat, DVec3, f64)
#undef WP_ADJ_EULER

}  // namespace wp

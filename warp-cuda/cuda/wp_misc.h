// wp_misc.h: section "misc" of the builtin table (warp-core/src/builtins/misc.rs): more of
// Warp's vector, quaternion and transform builtins, and lower_bound. Same operations in the
// same order as the Rust (see its module documentation):
//
//   copysign(x, y)             f32, f64: x's magnitude with y's sign bit.
//   nonzero(x)                 every integer and float scalar: x != 0 ? 1 : 0.
//   block_dim()                threads per block of the launch (1 on the host, as on the CPU).
//   min_element(v), max_element(v)   float and integer vectors: min/max folded from lane 0.
//   argmin(v), argmax(v)       u32: the first strictly better non-NaN lane, from the first
//                              non-NaN one; 0 when every lane is NaN.
//   get_diag(m)                matrices: the diagonal.
//   norm_l1, norm_l2, norm_huber, norm_pseudo_huber, smooth_normalize   float vectors.
//   quat_to_axis_angle(q)      tuple_t<V3, S>; quat_rpy(roll, pitch, yaw); quat_to_rpy(q);
//   quat_twist(axis, q), quat_twist_angle(axis, q), quat_twist_angle_signed(axis, q).
//   transform_compose(p, q, s) Mat4/DMat4; transform_decompose(m): tuple_t<V3, Q, V3>.
//   lower_bound(a, value), lower_bound_range(a, lo, hi, value)   1-D arrays of scalars, the
//                              reads checked (a fault returns 0, as the other accesses' zero
//                              values).
//   expect_eq(a, b), expect_neq(a, b)   bool: a == b, !(a == b) (warp-core builtins/expect.rs).
//   expect_near(a, b, tol)     bool: every lane has (x <= y ? y - x : x - y) <= tol (false for
//                              NaN), float scalars and vectors. Generated code raises the
//                              fault of a false one (wp::assert_fail).
#pragma once
#include "wp_svd.h"
#include "wp_transform.h"

namespace wp {

// ----- scalars -----
// On the sign bits, as IEEE and Rust define it: CUDA's copysign leaves a NaN's sign alone
// (measured on sm_90), which would make the backends disagree on NaN inputs.
WP_LFN f32 copysign(f32 x, f32 y) {
  return f32_from_bits((f32_to_bits(x) & 0x7fffffffu) | (f32_to_bits(y) & 0x80000000u));
}
WP_LFN f64 copysign(f64 x, f64 y) {
  return f64_from_bits((f64_to_bits(x) & 0x7fffffffffffffffull) |
                       (f64_to_bits(y) & 0x8000000000000000ull));
}

WP_LFN i32 block_dim() {
#if defined(__CUDA_ARCH__)
  return (i32)blockDim.x;
#else
  return 1;
#endif
}
template <typename T>
WP_FN T nonzero(T x) {
  return x != (T)0 ? (T)1 : (T)0;
}

// ----- test expectations: the checks (true when the expectation holds) -----
template <typename T>
WP_FN bool expect_eq(const T& a, const T& b) {
  return a == b;
}
template <typename T>
WP_FN bool expect_neq(const T& a, const T& b) {
  return !(a == b);
}
namespace detail {
template <typename S>
WP_FN bool near_lane(S a, S b, S tol) {
  const S d = a <= b ? b - a : a - b;
  return d <= tol;
}
}  // namespace detail
template <typename T, typename S>
WP_FN bool expect_near(const T& a, const T& b, S tol) {
  if constexpr (vec_traits<T>::is_vec) {
    for (int k = 0; k < vec_traits<T>::N; ++k) {
      if (!detail::near_lane(vec_traits<T>::get(a, k), vec_traits<T>::get(b, k), tol)) return false;
    }
    return true;
  } else {
    return detail::near_lane(a, b, tol);
  }
}

// ----- one-vector reductions -----
namespace detail {
template <typename S>
WP_FN bool nan_like(S x) {
  return x != x;
}
template <typename V, bool Min>
WP_FN u32 arg_extreme(const V& v) {
  typedef vec_traits<V> tr;
  int r = 0;
  while (r < tr::N && nan_like(tr::get(v, r))) ++r;
  if (r == tr::N) return 0;
  for (int i = r + 1; i < tr::N; ++i) {
    if (nan_like(tr::get(v, i))) continue;
    if (Min ? tr::get(v, i) < tr::get(v, r) : tr::get(v, i) > tr::get(v, r)) r = i;
  }
  return (u32)r;
}
}  // namespace detail

#define WP_MISC_REDUCE(V, S)                                                            \
  WP_LFN S min_element(const V& v) {                                                     \
    S r = vec_traits<V>::get(v, 0);                                                     \
    for (int i = 1; i < vec_traits<V>::N; ++i) r = min(r, vec_traits<V>::get(v, i));    \
    return r;                                                                           \
  }                                                                                     \
  WP_LFN S max_element(const V& v) {                                                     \
    S r = vec_traits<V>::get(v, 0);                                                     \
    for (int i = 1; i < vec_traits<V>::N; ++i) r = max(r, vec_traits<V>::get(v, i));    \
    return r;                                                                           \
  }                                                                                     \
  WP_LFN u32 argmin(const V& v) { return detail::arg_extreme<V, true>(v); }             \
  WP_LFN u32 argmax(const V& v) { return detail::arg_extreme<V, false>(v); }
WP_MISC_REDUCE(Vec2, f32)
WP_MISC_REDUCE(Vec3, f32)
WP_MISC_REDUCE(Vec4, f32)
WP_MISC_REDUCE(DVec2, f64)
WP_MISC_REDUCE(DVec3, f64)
WP_MISC_REDUCE(DVec4, f64)
WP_MISC_REDUCE(IVec2, i32)
WP_MISC_REDUCE(IVec3, i32)
WP_MISC_REDUCE(IVec4, i32)
WP_MISC_REDUCE(UVec2, u32)
WP_MISC_REDUCE(UVec3, u32)
WP_MISC_REDUCE(UVec4, u32)
#undef WP_MISC_REDUCE

// ----- matrices: get_diag -----
#define WP_MISC_DIAG(M, V)                                                              \
  WP_LFN V get_diag(const M& m) {                                                        \
    V r;                                                                                \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                          \
      vec_traits<V>::at(r, i) = vec_traits<V>::get(mat_traits<M>::get(m, i), i);        \
    return r;                                                                           \
  }
WP_MISC_DIAG(Mat2, Vec2)
WP_MISC_DIAG(Mat3, Vec3)
WP_MISC_DIAG(Mat4, Vec4)
WP_MISC_DIAG(DMat2, DVec2)
WP_MISC_DIAG(DMat3, DVec3)
WP_MISC_DIAG(DMat4, DVec4)
#undef WP_MISC_DIAG

// ----- norms (Warp's math.py) -----
#define WP_MISC_NORMS(V, S)                                                             \
  WP_LFN S norm_l1(const V& v) {                                                         \
    S n = (S)0;                                                                         \
    for (int i = 0; i < vec_traits<V>::N; ++i) n += abs(vec_traits<V>::get(v, i));      \
    return n;                                                                           \
  }                                                                                     \
  WP_LFN S norm_l2(const V& v) { return length(v); }                                     \
  WP_LFN S norm_huber(const V& v, S delta) {                                             \
    const S a = dot(v, v);                                                              \
    if (a <= delta * delta) return (S)0.5 * a;                                          \
    return delta * (sqrt(a) - (S)0.5 * delta);                                          \
  }                                                                                     \
  WP_LFN S norm_pseudo_huber(const V& v, S delta) {                                      \
    const S a = dot(v, v);                                                              \
    return delta * sqrt((S)1 + a / (delta * delta));                                    \
  }                                                                                     \
  WP_LFN V smooth_normalize(const V& v, S delta) {                                       \
    const S n = norm_pseudo_huber(v, delta);                                            \
    return detail::vmap(v, [n](S x) { return x / n; });                                 \
  }
WP_MISC_NORMS(Vec2, f32)
WP_MISC_NORMS(Vec3, f32)
WP_MISC_NORMS(Vec4, f32)
WP_MISC_NORMS(DVec2, f64)
WP_MISC_NORMS(DVec3, f64)
WP_MISC_NORMS(DVec4, f64)
#undef WP_MISC_NORMS

// ----- quaternions and transforms -----
#define WP_MISC_QUAT(Q, V3, V4, M3, M4, S)                                              \
  WP_LFN tuple_t<V3, S> quat_to_axis_angle(const Q& q) {                                 \
    const V3 v = V3##_new(q.x, q.y, q.z);                                               \
    const V3 n = normalize(v);                                                          \
    const V3 axis = q.w < (S)0 ? -n : n;                                                \
    return tuple_t<V3, S>{axis, (S)2 * atan2(length(v), abs(q.w))};                     \
  }                                                                                     \
  WP_LFN Q quat_rpy(S roll, S pitch, S yaw) {                                            \
    const S cy = cos(yaw * (S)0.5), sy = sin(yaw * (S)0.5);                             \
    const S cr = cos(roll * (S)0.5), sr = sin(roll * (S)0.5);                           \
    const S cp = cos(pitch * (S)0.5), sp = sin(pitch * (S)0.5);                         \
    const S w = cy * cr * cp + sy * sr * sp;                                            \
    const S x = cy * sr * cp - sy * cr * sp;                                            \
    const S y = cy * cr * sp + sy * sr * cp;                                            \
    const S z = sy * cr * cp - cy * sr * sp;                                            \
    return Q##_from_xyzw(x, y, z, w);                                                   \
  }                                                                                     \
  WP_LFN V3 quat_to_rpy(const Q& q) {                                                    \
    const S x = q.x, y = q.y, z = q.z, w = q.w;                                         \
    const S t0 = (S)2 * (w * x + y * z);                                                \
    const S t1 = (S)1 - (S)2 * (x * x + y * y);                                         \
    const S t2 = min(max((S)2 * (w * y - z * x), (S)-1), (S)1);                         \
    const S t3 = (S)2 * (w * z + x * y);                                                \
    const S t4 = (S)1 - (S)2 * (y * y + z * z);                                         \
    return V3##_new(atan2(t0, t1), asin(t2), atan2(t3, t4));                            \
  }                                                                                     \
  WP_LFN Q quat_twist(const V3& axis, const Q& q) {                                      \
    const S p = dot(V3##_new(q.x, q.y, q.z), axis);                                     \
    return normalize(Q##_from_xyzw(p * axis.x, p * axis.y, p * axis.z, q.w));           \
  }                                                                                     \
  WP_LFN S quat_twist_angle(const V3& axis, const Q& q) {                                \
    return (S)2 * atan2(abs(dot(axis, V3##_new(q.x, q.y, q.z))), q.w);                  \
  }                                                                                     \
  WP_LFN S quat_twist_angle_signed(const V3& axis, const Q& q) {                         \
    return (S)2 * atan2(dot(axis, V3##_new(q.x, q.y, q.z)), q.w);                       \
  }                                                                                     \
  WP_LFN M4 transform_compose(const V3& p, const Q& q, const V3& s) {                    \
    const M3 r = quat_to_matrix(q);                                                     \
    const V3 c0 = r.x_axis * s.x, c1 = r.y_axis * s.y, c2 = r.z_axis * s.z;             \
    return M4##_from_cols(V4##_new(c0.x, c0.y, c0.z, (S)0), V4##_new(c1.x, c1.y, c1.z, (S)0), \
                          V4##_new(c2.x, c2.y, c2.z, (S)0), V4##_new(p.x, p.y, p.z, (S)1)); \
  }                                                                                     \
  WP_LFN tuple_t<V3, Q, V3> transform_decompose(const M4& m) {                           \
    const V3 p = V3##_new(m.w_axis.x, m.w_axis.y, m.w_axis.z);                          \
    V3 c[3] = {V3##_new(m.x_axis.x, m.x_axis.y, m.x_axis.z),                            \
               V3##_new(m.y_axis.x, m.y_axis.y, m.y_axis.z),                            \
               V3##_new(m.z_axis.x, m.z_axis.y, m.z_axis.z)};                           \
    S s[3];                                                                             \
    for (int j = 0; j < 3; ++j) {                                                       \
      s[j] = length(c[j]);                                                              \
      if (s[j] != (S)0) {                                                               \
        const S l = s[j];                                                               \
        c[j] = V3##_new(c[j].x / l, c[j].y / l, c[j].z / l);                            \
      }                                                                                 \
    }                                                                                   \
    const Q q = quat_from_matrix(M3##_from_cols(c[0], c[1], c[2]));                     \
    return tuple_t<V3, Q, V3>{p, q, V3##_new(s[0], s[1], s[2])};                        \
  }
WP_MISC_QUAT(Quat, Vec3, Vec4, Mat3, Mat4, f32)
WP_MISC_QUAT(DQuat, DVec3, DVec4, DMat3, DMat4, f64)
#undef WP_MISC_QUAT

// ----- lower_bound (Warp's binary search; hi - 1 when no element is >= value) -----
template <typename T>
WP_FN i32 lower_bound_range(const array_t<T, 1>& a, i32 lo, i32 hi, T value, ctx_t* ctx) {
  i32 lower = lo;
  i32 upper = w_sub(hi, (i32)1);
  while (lower < upper) {
    const i32 mid = (i32)((i64)lower + ((i64)upper - (i64)lower) / 2);
    if (load(a, (i64)mid, ctx) < value)
      lower = mid + 1;
    else
      upper = mid;
    if (faulted(ctx)) return 0;
  }
  return lower;
}
template <typename T>
WP_FN i32 lower_bound(const array_t<T, 1>& a, T value, ctx_t* ctx) {
  const i64 n = a.shape[0];
  return lower_bound_range(a, (i32)0, n > (i64)2147483647 ? (i32)2147483647 : (i32)n, value, ctx);
}

}  // namespace wp

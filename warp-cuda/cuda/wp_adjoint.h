// wp_adjoint.h: reverse-mode adjoints (namespace `wp`), the CUDA mirror of warp-core's
// `adjoint` module (warp-core/src/adjoint/{mod,ops,builtins,cast,lanes}.rs) and of the gradient
// accessors of `GradView` (warp-core/src/grad.rs).
//
// Conventions (as on the CPU):
//   * The adjoint of a value has the value's own type. Integer, integer-vector and bool values
//     are not differentiable: every adjoint function taking them is a no-op.
//   * Every adjoint function ACCUMULATES (`+=`) into its adjoint arguments (non-const
//     references), given the adjoint `adj_ret` of the operation's result:
//       adj_<op>(a, b, adj_a, adj_b, adj_ret)     op in add sub mul div rem
//       adj_neg(a, adj_a, adj_ret)
//       adj_<builtin>(args.., adj_args.., adj_ret) min max clamp abs sign floor ceil sqrt exp
//                                                 log sin cos tan atan2 pow lerp dot length
//                                                 normalize cross asin acos atan sinh cosh
//                                                 tanh exp2 log2 log10 cbrt erf erfc erfinv
//                                                 erfcinv round rint trunc frac step degrees
//                                                 radians smoothstep noise pnoise
//       adj_svd3 adj_svd2 adj_eig3 adj_qr3(a, adj_a, adj_ret)  adj_ret: the tuple_t of the
//                                                 results' adjoints (forward recomputed)
//       adj_copysign adj_min_element adj_max_element adj_get_diag adj_norm_l1 adj_norm_l2
//       adj_norm_huber adj_norm_pseudo_huber adj_smooth_normalize adj_quat_rpy adj_quat_to_rpy
//       adj_quat_twist adj_quat_twist_angle(_signed) adj_transform_compose (section "misc")
//       adj_quat_to_axis_angle adj_transform_decompose(x, adj_x, adj_ret)  adj_ret: the tuple_t
//       adj_cast(adj_from, adj_to)                template over the 13 scalar types
//     for exactly the operand types the Rust functions take (the kernel language's operator
//     combinations and the builtin table's signatures, with glam's meaning of each operator).
//   * adj_zero<T>() / zero<T>() / zero_like(x): the zero adjoint (quaternions: (0, 0, 0, 0));
//     adj_accum(a, v): `a += v` for float types, a no-op for the others.
//   * grad_accum / grad_take / grad_get: an array's gradient in an adjoint kernel (an
//     `array_t` whose `data` is null when the array has no gradient).
//
// Floating point: every formula is evaluated in the order the Rust function documents
// (left to right, the same temporaries), so that the GPU agrees with the CPU bit for bit when
// nothing is contracted into an FMA (NVRTC: `--fmad=false`) and the math library agrees
// (sqrt, floor, trunc are exact everywhere; exp, log, sin, cos, tan, pow, sinh, cosh, tanh,
// exp2, cbrt, erfinv, erfcinv come from CUDA's libdevice on the GPU and may differ in the
// last bits from the CPU's, as the forward ones do).
// The edge rules are the CPU's: min/max send the whole adjoint to the operand the forward
// returned (ties to the first, a lone NaN loses, two NaNs to the first); clamp goes through
// max then min in reverse; abs uses sign(0) = +1; length/normalize give nothing at the zero
// vector; pow skips d/dx when y == 0 and d/dy unless x > 0; atan2 gives nothing at (0, 0);
// division is `gb = g / b; adj_a += gb; adj_b -= gb * (a / b)`.
//
// Checked by tests/cuda_adjoint_host.rs against warp-core: bit for bit on the host (g++), and
// on an H200 (nvcc and NVRTC, --fmad=false) bit for bit except the exp/sin/cos/tan/pow adjoints.
//
// `%`: Rust's float `%` (fmod) has the adjoint `adj_b -= g * trunc(a / b)`. This library's
// Vec4 `%` is glam's SSE floored modulo `a - floor(a / b) * b` (wp_core.h); its adjoint is
// `adj_b -= g * floor(a / b)`, with the ordinary floor, which is what warp-core computes where
// glam's Vec4 `%` is floored (x86_64: it asks glam at run time).
#pragma once
#include "wp_core.h"
#include "wp_scalar.h"
#include "wp_vector.h"
#include "wp_linalg.h"
#include "wp_transform.h"
#include "wp_svd.h"
#include "wp_misc.h"
#include "wp_atomic.h"
#include "wp_rand.h"

namespace wp {

// ------------------------------------------------------------------------------------------
// Zero and accumulation (warp_core::adjoint::Adjoint)
// ------------------------------------------------------------------------------------------

namespace detail {
/// The scalar type of T (T itself for scalars; the lane type of vectors, matrices, quats).
template <typename T, bool Scalar = num<T>::is_int || num<T>::is_float || num<T>::is_bool>
struct adj_scalar_of {
  typedef T type;
};
template <typename T>
struct adj_scalar_of<T, false> {
  typedef typename vec_traits<T>::scalar type;
};
template <typename T>
struct adj_is_scalar {
  static constexpr bool value = num<T>::is_int || num<T>::is_float || num<T>::is_bool;
};
/// Whether T has a (float) adjoint: f32, f64 and the float vectors, matrices, quaternions.
template <typename T>
struct adj_is_float {
  static constexpr bool value = num<typename adj_scalar_of<T>::type>::is_float;
};
}  // namespace detail

/// The zero adjoint of T: 0, 0.0, false, the zero vector or matrix, the quaternion (0, 0, 0, 0).
template <typename T>
WP_FN T adj_zero() {
  if constexpr (detail::adj_is_scalar<T>::value) {
    return (T)0;
  } else {
    typedef typename vec_traits<T>::scalar S;
    T r;
    for (int i = 0; i < vec_traits<T>::N; ++i) vec_traits<T>::at(r, i) = (S)0;
    return r;
  }
}
/// `warp_core::adjoint::zero`: the same as adj_zero<T>().
template <typename T>
WP_FN T zero() {
  return adj_zero<T>();
}
/// `warp_core::zero_like`: the zero adjoint of x's type.
template <typename T>
WP_FN T zero_like(const T&) {
  return adj_zero<T>();
}
/// `a += v` for float types (componentwise); a no-op for integer, integer-vector and bool
/// types, whose adjoint is always zero.
template <typename T>
WP_FN void adj_accum(T& a, const typename identity<T>::type& v) {
  if constexpr (detail::adj_is_float<T>::value) a += v;
}

// ------------------------------------------------------------------------------------------
// Lane adjoints (warp-core/src/adjoint/lanes.rs)
// ------------------------------------------------------------------------------------------

namespace detail {
template <typename F> WP_FN bool adj_isnan(F x) { return !(x == x); }
WP_FN f32 adj_trunc(f32 x) { return ::truncf(x); }
WP_FN f64 adj_trunc(f64 x) { return ::trunc(x); }
WP_FN f16 adj_trunc(f16 x) { return f16_from_f32(::truncf(f16_to_f32(x))); }

/// `min(a, b)` returned `a`: `a <= b`, or `b` alone is NaN, or both are NaN.
template <typename F>
WP_FN bool min_takes_first(F a, F b) {
  if (adj_isnan(a)) return adj_isnan(b);
  return adj_isnan(b) || a <= b;
}
/// `max(a, b)` returned `a` (as min_takes_first with `a >= b`).
template <typename F>
WP_FN bool max_takes_first(F a, F b) {
  if (adj_isnan(a)) return adj_isnan(b);
  return adj_isnan(b) || a >= b;
}

// Binary lanes: (a, b, adj_a, adj_b, g).
struct l_add {
  template <typename F> WP_FN void operator()(F, F, F& aa, F& ab, F g) const { aa += g; ab += g; }
};
struct l_sub {
  template <typename F> WP_FN void operator()(F, F, F& aa, F& ab, F g) const { aa += g; ab -= g; }
};
struct l_mul {
  template <typename F> WP_FN void operator()(F a, F b, F& aa, F& ab, F g) const {
    aa += g * b;
    ab += g * a;
  }
};
struct l_div {
  template <typename F> WP_FN void operator()(F a, F b, F& aa, F& ab, F g) const {
    const F gb = g / b;
    aa += gb;
    ab -= gb * (a / b);
  }
};
/// Rust's float `%` (fmod): `adj_a += g; adj_b -= g * trunc(a / b)`.
struct l_rem_trunc {
  template <typename F> WP_FN void operator()(F a, F b, F& aa, F& ab, F g) const {
    aa += g;
    ab -= g * adj_trunc(a / b);
  }
};
/// Floored `%` (this library's Vec4 `%`): `adj_a += g; adj_b -= g * floor(a / b)`.
struct l_rem_floor {
  template <typename F> WP_FN void operator()(F a, F b, F& aa, F& ab, F g) const {
    aa += g;
    ab -= g * wp::floor(a / b);
  }
};
struct l_min {
  template <typename F> WP_FN void operator()(F a, F b, F& aa, F& ab, F g) const {
    if (min_takes_first(a, b))
      aa += g;
    else
      ab += g;
  }
};
struct l_max {
  template <typename F> WP_FN void operator()(F a, F b, F& aa, F& ab, F g) const {
    if (max_takes_first(a, b))
      aa += g;
    else
      ab += g;
  }
};
/// `abs`: `adj_x += g * sign(x)` (sign(0) = sign(-0) = sign(NaN) = +1).
template <typename F>
WP_FN void l_abs(F x, F& ax, F g) {
  ax += g * wp::sign(x);
}
/// `lerp`: `adj_a += g * (1 - t); adj_b += g * t; adj_t += g * (b - a)`.
template <typename F>
WP_FN void l_lerp(F a, F b, F t, F& aa, F& ab, F& at, F g) {
  aa += g * ((F)1 - t);
  ab += g * t;
  at += g * (b - a);
}

// Lane iteration over vectors, matrices (column-major) and quaternions (x, y, z, w).
template <typename V, typename L>
WP_FN void zip_vv(const V& a, const V& b, V& aa, V& ab, const V& g, L f) {
  typedef vec_traits<V> T;
  for (int i = 0; i < T::N; ++i) f(T::get(a, i), T::get(b, i), T::at(aa, i), T::at(ab, i), T::get(g, i));
}
/// `v op s`: `s`'s adjoint collects the lanes' contributions in lane order.
template <typename V, typename L>
WP_FN void zip_vs(const V& a, typename vec_traits<V>::scalar s, V& aa,
                  typename vec_traits<V>::scalar& as, const V& g, L f) {
  typedef vec_traits<V> T;
  for (int i = 0; i < T::N; ++i) f(T::get(a, i), s, T::at(aa, i), as, T::get(g, i));
}
/// `s op v`: `s`'s adjoint collects the lanes' contributions in lane order.
template <typename V, typename L>
WP_FN void zip_sv(typename vec_traits<V>::scalar s, const V& b, typename vec_traits<V>::scalar& as,
                  V& ab, const V& g, L f) {
  typedef vec_traits<V> T;
  for (int i = 0; i < T::N; ++i) f(s, T::get(b, i), as, T::at(ab, i), T::get(g, i));
}

/// The transpose of a square matrix (data movement only).
template <typename M>
WP_FN M adj_transpose(const M& m) {
  constexpr int n = mat_traits<M>::N;
  M r;
  for (int c = 0; c < n; ++c)
    for (int k = 0; k < n; ++k) vec_traits<M>::at(r, c * n + k) = vec_traits<M>::get(m, k * n + c);
  return r;
}
/// glam's Vec3::dot / DVec3::dot: `(x*x' + y*y') + z*z'` (not the builtin dot, which starts
/// from 0 and so differs in the sign of a zero result).
template <typename V3>
WP_FN typename vec_traits<V3>::scalar glam_dot3(const V3& a, const V3& b) {
  return (a.x * b.x + a.y * b.y) + a.z * b.z;
}
}  // namespace detail

// ------------------------------------------------------------------------------------------
// Operators (warp-core/src/adjoint/ops.rs)
// ------------------------------------------------------------------------------------------

// ----- integers: no-ops -----
// (LT, RT, OT: the operand and result types as passed; L, R: the operand types.)
#define WP_ADJ_NOOP_BIN(LT, RT, OT, L, R)                                           \
  WP_FN void adj_add(LT, RT, L&, R&, OT) {}                                         \
  WP_FN void adj_sub(LT, RT, L&, R&, OT) {}                                         \
  WP_FN void adj_mul(LT, RT, L&, R&, OT) {}                                         \
  WP_FN void adj_div(LT, RT, L&, R&, OT) {}                                         \
  WP_FN void adj_rem(LT, RT, L&, R&, OT) {}
#define WP_ADJ_NOOP_INT(T)          \
  WP_ADJ_NOOP_BIN(T, T, T, T, T)    \
  WP_FN void adj_neg(T, T&, T) {}
WP_ADJ_NOOP_INT(i8)
WP_ADJ_NOOP_INT(i16)
WP_ADJ_NOOP_INT(i32)
WP_ADJ_NOOP_INT(i64)
WP_ADJ_NOOP_INT(u8)
WP_ADJ_NOOP_INT(u16)
WP_ADJ_NOOP_INT(u32)
WP_ADJ_NOOP_INT(u64)
#define WP_ADJ_NOOP_IVEC(V, S)                                 \
  WP_ADJ_NOOP_BIN(const V&, const V&, const V&, V, V)          \
  WP_ADJ_NOOP_BIN(const V&, S, const V&, V, S)                 \
  WP_ADJ_NOOP_BIN(S, const V&, const V&, S, V)                 \
  WP_FN void adj_neg(const V&, V&, const V&) {}
WP_ADJ_NOOP_IVEC(IVec2, i32)
WP_ADJ_NOOP_IVEC(IVec3, i32)
WP_ADJ_NOOP_IVEC(IVec4, i32)
WP_ADJ_NOOP_IVEC(UVec2, u32)
WP_ADJ_NOOP_IVEC(UVec3, u32)
WP_ADJ_NOOP_IVEC(UVec4, u32)
#undef WP_ADJ_NOOP_IVEC
#undef WP_ADJ_NOOP_INT
#undef WP_ADJ_NOOP_BIN

// ----- float scalars -----
#define WP_ADJ_FSCALAR_OPS(S)                                                                        \
  WP_FN void adj_add(S a, S b, S& adj_a, S& adj_b, S adj_ret) { detail::l_add()(a, b, adj_a, adj_b, adj_ret); } \
  WP_FN void adj_sub(S a, S b, S& adj_a, S& adj_b, S adj_ret) { detail::l_sub()(a, b, adj_a, adj_b, adj_ret); } \
  WP_FN void adj_mul(S a, S b, S& adj_a, S& adj_b, S adj_ret) { detail::l_mul()(a, b, adj_a, adj_b, adj_ret); } \
  WP_FN void adj_div(S a, S b, S& adj_a, S& adj_b, S adj_ret) { detail::l_div()(a, b, adj_a, adj_b, adj_ret); } \
  WP_FN void adj_rem(S a, S b, S& adj_a, S& adj_b, S adj_ret) {                                      \
    detail::l_rem_trunc()(a, b, adj_a, adj_b, adj_ret);                                              \
  }                                                                                                  \
  WP_FN void adj_neg(S, S& adj_a, S adj_ret) { adj_a -= adj_ret; }
WP_ADJ_FSCALAR_OPS(f32)
WP_ADJ_FSCALAR_OPS(f64)
WP_ADJ_FSCALAR_OPS(f16)
#undef WP_ADJ_FSCALAR_OPS

// ----- float vectors: lane by lane, with a scalar on either side -----
#define WP_ADJ_FVEC_OP(V, S, NAME, LANE)                                                          \
  WP_FN void NAME(const V& a, const V& b, V& adj_a, V& adj_b, const V& adj_ret) {                \
    detail::zip_vv(a, b, adj_a, adj_b, adj_ret, LANE());                                         \
  }                                                                                              \
  WP_FN void NAME(const V& a, S b, V& adj_a, S& adj_b, const V& adj_ret) {                       \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, LANE());                                         \
  }                                                                                              \
  WP_FN void NAME(S a, const V& b, S& adj_a, V& adj_b, const V& adj_ret) {                       \
    detail::zip_sv(a, b, adj_a, adj_b, adj_ret, LANE());                                         \
  }
#define WP_ADJ_FVEC_OPS(V, S, REM)                                     \
  WP_ADJ_FVEC_OP(V, S, adj_add, detail::l_add)                         \
  WP_ADJ_FVEC_OP(V, S, adj_sub, detail::l_sub)                         \
  WP_ADJ_FVEC_OP(V, S, adj_mul, detail::l_mul)                         \
  WP_ADJ_FVEC_OP(V, S, adj_div, detail::l_div)                         \
  WP_ADJ_FVEC_OP(V, S, adj_rem, REM)                                   \
  WP_FN void adj_neg(const V&, V& adj_a, const V& adj_ret) { adj_a -= adj_ret; }
WP_ADJ_FVEC_OPS(Vec2, f32, detail::l_rem_trunc)
WP_ADJ_FVEC_OPS(Vec3, f32, detail::l_rem_trunc)
WP_ADJ_FVEC_OPS(Vec4, f32, detail::l_rem_floor)  // Vec4 `%` is floored (see the top)
WP_ADJ_FVEC_OPS(DVec2, f64, detail::l_rem_trunc)
WP_ADJ_FVEC_OPS(DVec3, f64, detail::l_rem_trunc)
WP_ADJ_FVEC_OPS(DVec4, f64, detail::l_rem_trunc)
#undef WP_ADJ_FVEC_OPS
#undef WP_ADJ_FVEC_OP

// ----- matrices (column-major) -----
#define WP_ADJ_MAT_OPS(M, V, S)                                                                  \
  /* A + B, A - B */                                                                             \
  WP_FN void adj_add(const M&, const M&, M& adj_a, M& adj_b, const M& adj_ret) {                 \
    adj_a += adj_ret;                                                                            \
    adj_b += adj_ret;                                                                            \
  }                                                                                              \
  WP_FN void adj_sub(const M&, const M&, M& adj_a, M& adj_b, const M& adj_ret) {                 \
    adj_a += adj_ret;                                                                            \
    adj_b -= adj_ret;                                                                            \
  }                                                                                              \
  /* A * B: adj_a += g * B^T; adj_b += A^T * g (glam products). */                               \
  WP_FN void adj_mul(const M& a, const M& b, M& adj_a, M& adj_b, const M& adj_ret) {             \
    adj_a += adj_ret * detail::adj_transpose(b);                                                 \
    adj_b += detail::adj_transpose(a) * adj_ret;                                                 \
  }                                                                                              \
  /* M * v: adj_m.col(j) += g * v[j]; adj_v += M^T * g. */                                       \
  WP_FN void adj_mul(const M& a, const V& b, M& adj_a, V& adj_b, const V& adj_ret) {             \
    for (int j = 0; j < mat_traits<M>::N; ++j)                                                   \
      mat_traits<M>::at(adj_a, j) += adj_ret * vec_traits<V>::get(b, j);                         \
    adj_b += detail::adj_transpose(a) * adj_ret;                                                 \
  }                                                                                              \
  WP_FN void adj_mul(const M& a, S b, M& adj_a, S& adj_b, const M& adj_ret) {                    \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, detail::l_mul());                                \
  }                                                                                              \
  WP_FN void adj_div(const M& a, S b, M& adj_a, S& adj_b, const M& adj_ret) {                    \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, detail::l_div());                                \
  }                                                                                              \
  WP_FN void adj_mul(S a, const M& b, S& adj_a, M& adj_b, const M& adj_ret) {                    \
    detail::zip_sv(a, b, adj_a, adj_b, adj_ret, detail::l_mul());                                \
  }                                                                                              \
  /* s / M is M / s (glam 0.30's quirk, mirrored by the forward): roles swapped back. */         \
  WP_FN void adj_div(S a, const M& b, S& adj_a, M& adj_b, const M& adj_ret) {                    \
    detail::zip_vs(b, a, adj_b, adj_a, adj_ret, detail::l_div());                                \
  }                                                                                              \
  WP_FN void adj_neg(const M&, M& adj_a, const M& adj_ret) { adj_a -= adj_ret; }
WP_ADJ_MAT_OPS(Mat2, Vec2, f32)
WP_ADJ_MAT_OPS(Mat3, Vec3, f32)
WP_ADJ_MAT_OPS(Mat4, Vec4, f32)
WP_ADJ_MAT_OPS(DMat2, DVec2, f64)
WP_ADJ_MAT_OPS(DMat3, DVec3, f64)
WP_ADJ_MAT_OPS(DMat4, DVec4, f64)
#undef WP_ADJ_MAT_OPS

// ----- quaternions -----
#define WP_ADJ_QUAT_OPS(Q, V3, S)                                                                \
  WP_FN void adj_add(const Q&, const Q&, Q& adj_a, Q& adj_b, const Q& adj_ret) {                 \
    adj_a += adj_ret;                                                                            \
    adj_b += adj_ret;                                                                            \
  }                                                                                              \
  WP_FN void adj_sub(const Q&, const Q&, Q& adj_a, Q& adj_b, const Q& adj_ret) {                 \
    adj_a += adj_ret;                                                                            \
    adj_b -= adj_ret;                                                                            \
  }                                                                                              \
  /* p * q (Hamilton): the transpose of the bilinear map in each argument. */                    \
  WP_FN void adj_mul(const Q& a, const Q& b, Q& adj_a, Q& adj_b, const Q& adj_ret) {             \
    const S x0 = a.x, y0 = a.y, z0 = a.z, w0 = a.w;                                              \
    const S x1 = b.x, y1 = b.y, z1 = b.z, w1 = b.w;                                              \
    const S gx = adj_ret.x, gy = adj_ret.y, gz = adj_ret.z, gw = adj_ret.w;                      \
    adj_a += Q##_from_xyzw(gx * w1 - gy * z1 + gz * y1 - gw * x1,                                \
                           gx * z1 + gy * w1 - gz * x1 - gw * y1,                                \
                           -gx * y1 + gy * x1 + gz * w1 - gw * z1,                               \
                           gx * x1 + gy * y1 + gz * z1 + gw * w1);                               \
    adj_b += Q##_from_xyzw(gx * w0 + gy * z0 - gz * y0 - gw * x0,                                \
                           -gx * z0 + gy * w0 + gz * x0 - gw * y0,                               \
                           gx * y0 - gy * x0 + gz * w0 - gw * z0,                                \
                           gx * x0 + gy * y0 + gz * z0 + gw * w0);                               \
  }                                                                                              \
  /* q * v (glam's rotation formula, exact for any q = (b, w)): */                               \
  /*   adj_v += g (w^2 - b.b) + b (2 b.g) + (g x b)(2 w)                         */              \
  /*   adj_w += 2 (w (g.v) + g.(b x v))                                          */              \
  /*   adj_b += g (2 v.b) + v (2 b.g) - b (2 v.g) + (v x g)(2 w)                 */              \
  WP_FN void adj_mul(const Q& a, const V3& v, Q& adj_a, V3& adj_b, const V3& adj_ret) {          \
    const S two = (S)2;                                                                          \
    const S w = a.w;                                                                             \
    const V3 b = V3##_new(a.x, a.y, a.z);                                                        \
    const V3 g = adj_ret;                                                                        \
    const S bb = detail::glam_dot3(b, b);                                                        \
    const S bg = detail::glam_dot3(b, g);                                                        \
    const S vb = detail::glam_dot3(v, b);                                                        \
    const S vg = detail::glam_dot3(v, g);                                                        \
    adj_b += g * (w * w - bb) + b * (two * bg) + wp::cross(g, b) * (two * w);                    \
    const V3 ab = g * (two * vb) + v * (two * bg) - b * (two * vg) + wp::cross(v, g) * (two * w); \
    const S aw = two * (w * vg + detail::glam_dot3(g, wp::cross(b, v)));                         \
    adj_a += Q##_from_xyzw(ab.x, ab.y, ab.z, aw);                                                \
  }                                                                                              \
  WP_FN void adj_mul(const Q& a, S b, Q& adj_a, S& adj_b, const Q& adj_ret) {                    \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, detail::l_mul());                                \
  }                                                                                              \
  WP_FN void adj_div(const Q& a, S b, Q& adj_a, S& adj_b, const Q& adj_ret) {                    \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, detail::l_div());                                \
  }                                                                                              \
  WP_FN void adj_neg(const Q&, Q& adj_a, const Q& adj_ret) { adj_a -= adj_ret; }
WP_ADJ_QUAT_OPS(Quat, Vec3, f32)
WP_ADJ_QUAT_OPS(DQuat, DVec3, f64)
#undef WP_ADJ_QUAT_OPS

// ------------------------------------------------------------------------------------------
// Builtins (warp-core/src/adjoint/builtins.rs)
// ------------------------------------------------------------------------------------------

// ----- min, max, clamp -----
// (T: the type; CT: the type as passed.)
#define WP_ADJ_NOOP_MINMAX(T, CT)                          \
  WP_FN void adj_min(CT, CT, T&, T&, CT) {}                \
  WP_FN void adj_max(CT, CT, T&, T&, CT) {}                \
  WP_FN void adj_clamp(CT, CT, CT, T&, T&, T&, CT) {}
WP_ADJ_NOOP_MINMAX(i8, i8)
WP_ADJ_NOOP_MINMAX(i16, i16)
WP_ADJ_NOOP_MINMAX(i32, i32)
WP_ADJ_NOOP_MINMAX(i64, i64)
WP_ADJ_NOOP_MINMAX(u8, u8)
WP_ADJ_NOOP_MINMAX(u16, u16)
WP_ADJ_NOOP_MINMAX(u32, u32)
WP_ADJ_NOOP_MINMAX(u64, u64)
WP_ADJ_NOOP_MINMAX(IVec2, const IVec2&)
WP_ADJ_NOOP_MINMAX(IVec3, const IVec3&)
WP_ADJ_NOOP_MINMAX(IVec4, const IVec4&)
WP_ADJ_NOOP_MINMAX(UVec2, const UVec2&)
WP_ADJ_NOOP_MINMAX(UVec3, const UVec3&)
WP_ADJ_NOOP_MINMAX(UVec4, const UVec4&)
#undef WP_ADJ_NOOP_MINMAX

/// clamp(x, lo, hi) = min(max(x, lo), hi): the min rule, then the max rule (reverse order);
/// the max step always runs, with the (possibly zero) adjoint the min step left for m.
#define WP_ADJ_FMINMAX(T, CT, MIN_BODY, MAX_BODY)                                          \
  WP_FN void adj_min(CT a, CT b, T& adj_a, T& adj_b, CT adj_ret) { MIN_BODY; }             \
  WP_FN void adj_max(CT a, CT b, T& adj_a, T& adj_b, CT adj_ret) { MAX_BODY; }             \
  WP_FN void adj_clamp(CT x, CT lo, CT hi, T& adj_x, T& adj_lo, T& adj_hi, CT adj_ret) {   \
    const T m = wp::max(x, lo);                                                            \
    T adj_m = adj_zero<T>();                                                               \
    adj_min(m, hi, adj_m, adj_hi, adj_ret);                                                \
    adj_max(x, lo, adj_x, adj_lo, adj_m);                                                  \
  }
#define WP_ADJ_FMINMAX_S(S)                                                                \
  WP_ADJ_FMINMAX(S, S, detail::l_min()(a, b, adj_a, adj_b, adj_ret),                       \
                 detail::l_max()(a, b, adj_a, adj_b, adj_ret))
#define WP_ADJ_FMINMAX_V(V)                                                                \
  WP_ADJ_FMINMAX(V, const V&, detail::zip_vv(a, b, adj_a, adj_b, adj_ret, detail::l_min()), \
                 detail::zip_vv(a, b, adj_a, adj_b, adj_ret, detail::l_max()))
WP_ADJ_FMINMAX_S(f32)
WP_ADJ_FMINMAX_S(f64)
WP_ADJ_FMINMAX_S(f16)
WP_ADJ_FMINMAX_V(Vec2)
WP_ADJ_FMINMAX_V(Vec3)
WP_ADJ_FMINMAX_V(Vec4)
WP_ADJ_FMINMAX_V(DVec2)
WP_ADJ_FMINMAX_V(DVec3)
WP_ADJ_FMINMAX_V(DVec4)
#undef WP_ADJ_FMINMAX_V
#undef WP_ADJ_FMINMAX_S
#undef WP_ADJ_FMINMAX

// ----- abs, sign, floor, ceil -----
#define WP_ADJ_NOOP_SIGNED(T, CT)         \
  WP_FN void adj_abs(CT, T&, CT) {}         \
  WP_FN void adj_sign(CT, T&, CT) {}
WP_ADJ_NOOP_SIGNED(i8, i8)
WP_ADJ_NOOP_SIGNED(i16, i16)
WP_ADJ_NOOP_SIGNED(i32, i32)
WP_ADJ_NOOP_SIGNED(i64, i64)
WP_ADJ_NOOP_SIGNED(IVec2, const IVec2&)
WP_ADJ_NOOP_SIGNED(IVec3, const IVec3&)
WP_ADJ_NOOP_SIGNED(IVec4, const IVec4&)
#undef WP_ADJ_NOOP_SIGNED

/// abs: `adj_x += adj_ret * sign(x)` (sign(0) = +1); sign, floor, ceil: piecewise constant.
#define WP_ADJ_FSCALAR_SIGNED(S)                                                      \
  WP_FN void adj_abs(S x, S& adj_x, S adj_ret) { detail::l_abs(x, adj_x, adj_ret); }  \
  WP_FN void adj_sign(S, S&, S) {}                                                    \
  WP_FN void adj_floor(S, S&, S) {}                                                   \
  WP_FN void adj_ceil(S, S&, S) {}
WP_ADJ_FSCALAR_SIGNED(f32)
WP_ADJ_FSCALAR_SIGNED(f64)
WP_ADJ_FSCALAR_SIGNED(f16)
#undef WP_ADJ_FSCALAR_SIGNED
#define WP_ADJ_FVEC_SIGNED(V)                                                              \
  WP_FN void adj_abs(const V& x, V& adj_x, const V& adj_ret) {                             \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                             \
      detail::l_abs(vec_traits<V>::get(x, i), vec_traits<V>::at(adj_x, i), vec_traits<V>::get(adj_ret, i)); \
  }                                                                                        \
  WP_FN void adj_sign(const V&, V&, const V&) {}
WP_ADJ_FVEC_SIGNED(Vec2)
WP_ADJ_FVEC_SIGNED(Vec3)
WP_ADJ_FVEC_SIGNED(Vec4)
WP_ADJ_FVEC_SIGNED(DVec2)
WP_ADJ_FVEC_SIGNED(DVec3)
WP_ADJ_FVEC_SIGNED(DVec4)
#undef WP_ADJ_FVEC_SIGNED

// ----- float scalar functions -----
#define WP_ADJ_FSCALAR_FNS(S)                                                                \
  /* sqrt: adj_x += g * (0.5 / sqrt(x)) (infinite at 0, NaN below, as in Warp). */           \
  WP_FN void adj_sqrt(S x, S& adj_x, S adj_ret) {                                            \
    const S half = (S)1 / ((S)1 + (S)1);                                                     \
    adj_x += adj_ret * (half / wp::sqrt(x));                                                 \
  }                                                                                          \
  WP_FN void adj_exp(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::exp(x); }            \
  WP_FN void adj_log(S x, S& adj_x, S adj_ret) { adj_x += adj_ret / x; }                     \
  WP_FN void adj_sin(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::cos(x); }            \
  WP_FN void adj_cos(S x, S& adj_x, S adj_ret) { adj_x -= adj_ret * wp::sin(x); }            \
  WP_FN void adj_tan(S x, S& adj_x, S adj_ret) {                                             \
    const S c = wp::cos(x);                                                                  \
    adj_x += adj_ret / (c * c);                                                              \
  }                                                                                          \
  /* atan2(y, x): d = x*x + y*y; nothing at the origin. */                                   \
  WP_FN void adj_atan2(S y, S x, S& adj_y, S& adj_x, S adj_ret) {                            \
    if (x == (S)0 && y == (S)0) return;                                                      \
    const S d = x * x + y * y;                                                               \
    adj_y += adj_ret * (x / d);                                                              \
    adj_x -= adj_ret * (y / d);                                                              \
  }                                                                                          \
  /* pow(x, y): d/dx unless y == 0; d/dy only when x > 0. */                                 \
  WP_FN void adj_pow(S x, S y, S& adj_x, S& adj_y, S adj_ret) {                              \
    if (y != (S)0) adj_x += adj_ret * (y * wp::pow(x, y - (S)1));                            \
    if (x > (S)0) adj_y += adj_ret * (wp::pow(x, y) * wp::log(x));                           \
  }                                                                                          \
  WP_FN void adj_lerp(S a, S b, S t, S& adj_a, S& adj_b, S& adj_t, S adj_ret) {              \
    detail::l_lerp(a, b, t, adj_a, adj_b, adj_t, adj_ret);                                   \
  }
WP_ADJ_FSCALAR_FNS(f32)
WP_ADJ_FSCALAR_FNS(f64)
WP_ADJ_FSCALAR_FNS(f16)
#undef WP_ADJ_FSCALAR_FNS

// ----- more float scalar functions (warp-core/src/adjoint/builtins.rs, same order) -----
// LN2, LN10, TWO_SQRTPI (2/sqrt(pi)), SQRTPI_2 (sqrt(pi)/2): Rust's constants, by bit pattern.
#define WP_ADJ_FSCALAR_MORE(S, LN2, LN10, TWO_SQRTPI, SQRTPI_2)                               \
  /* asin/acos: d = sqrt(1 - x*x); only when d > 0 (the clamp is flat at |x| >= 1). */       \
  WP_FN void adj_asin(S x, S& adj_x, S adj_ret) {                                            \
    const S d = wp::sqrt((S)1 - x * x);                                                      \
    if (d > (S)0) adj_x += adj_ret / d;                                                      \
  }                                                                                          \
  WP_FN void adj_acos(S x, S& adj_x, S adj_ret) {                                            \
    const S d = wp::sqrt((S)1 - x * x);                                                      \
    if (d > (S)0) adj_x -= adj_ret / d;                                                      \
  }                                                                                          \
  WP_FN void adj_atan(S x, S& adj_x, S adj_ret) { adj_x += adj_ret / (x * x + (S)1); }       \
  WP_FN void adj_sinh(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::cosh(x); }          \
  WP_FN void adj_cosh(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::sinh(x); }          \
  WP_FN void adj_tanh(S x, S& adj_x, S adj_ret) {                                            \
    const S t = wp::tanh(x);                                                                 \
    adj_x += adj_ret * ((S)1 - t * t);                                                       \
  }                                                                                          \
  WP_FN void adj_exp2(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * (wp::exp2(x) * (LN2)); } \
  WP_FN void adj_log2(S x, S& adj_x, S adj_ret) { adj_x += adj_ret / (x * (LN2)); }          \
  WP_FN void adj_log10(S x, S& adj_x, S adj_ret) { adj_x += adj_ret / (x * (LN10)); }        \
  WP_FN void adj_cbrt(S x, S& adj_x, S adj_ret) {                                            \
    const S c = wp::cbrt(x);                                                                 \
    const S three = (S)1 + (S)1 + (S)1;                                                      \
    adj_x += adj_ret / (three * (c * c));                                                    \
  }                                                                                          \
  WP_FN void adj_erf(S x, S& adj_x, S adj_ret) {                                             \
    adj_x += adj_ret * ((TWO_SQRTPI) * wp::exp(-(x * x)));                                   \
  }                                                                                          \
  WP_FN void adj_erfc(S x, S& adj_x, S adj_ret) {                                            \
    adj_x -= adj_ret * ((TWO_SQRTPI) * wp::exp(-(x * x)));                                   \
  }                                                                                          \
  WP_FN void adj_erfinv(S x, S& adj_x, S adj_ret) {                                          \
    const S r = wp::erfinv(x);                                                               \
    adj_x += adj_ret * ((SQRTPI_2) * wp::exp(r * r));                                        \
  }                                                                                          \
  WP_FN void adj_erfcinv(S x, S& adj_x, S adj_ret) {                                         \
    const S r = wp::erfcinv(x);                                                              \
    adj_x -= adj_ret * ((SQRTPI_2) * wp::exp(r * r));                                        \
  }                                                                                          \
  WP_FN void adj_round(S, S&, S) {}                                                          \
  WP_FN void adj_rint(S, S&, S) {}                                                           \
  WP_FN void adj_trunc(S, S&, S) {}                                                          \
  WP_FN void adj_step(S, S&, S) {}                                                           \
  /* frac = x - trunc(x): slope 1. */                                                        \
  WP_FN void adj_frac(S, S& adj_x, S adj_ret) { adj_x += adj_ret; }                          \
  WP_FN void adj_degrees(S, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::degrees((S)1); }   \
  WP_FN void adj_radians(S, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::radians((S)1); }   \
  /* smoothstep: d = e1 - e0, t = (x - e0) / d; only when 0 < t < 1. */                     \
  WP_FN void adj_smoothstep(S e0, S e1, S x, S& adj_e0, S& adj_e1, S& adj_x, S adj_ret) {    \
    const S d = e1 - e0;                                                                     \
    const S t = (x - e0) / d;                                                                \
    if (t > (S)0 && t < (S)1) {                                                              \
      const S six = ((S)1 + (S)1 + (S)1) * ((S)1 + (S)1);                                    \
      const S g = adj_ret * (six * t * ((S)1 - t) / d);                                      \
      adj_x += g;                                                                            \
      adj_e0 += g * (t - (S)1);                                                              \
      adj_e1 -= g * t;                                                                       \
    }                                                                                        \
  }
WP_ADJ_FSCALAR_MORE(f32, f32_from_bits(0x3f317218u), f32_from_bits(0x40135d8eu),
                    f32_from_bits(0x3f906ebbu), f32_from_bits(0x3f62dfc5u))
WP_ADJ_FSCALAR_MORE(f64, f64_from_bits(0x3fe62e42fefa39efull), f64_from_bits(0x40026bb1bbb55516ull),
                    f64_from_bits(0x3ff20dd750429b6dull), f64_from_bits(0x3fec5bf891b4ef6bull))
// f16: the f64 constants rounded once (warp-core/src/adjoint/float16.rs); every step of each
// formula is an f16 operation, as on the CPU.
WP_ADJ_FSCALAR_MORE(f16, f16_from_bits(0x398Cu), f16_from_bits(0x409Bu), f16_from_bits(0x3C83u),
                    f16_from_bits(0x3B17u))
#undef WP_ADJ_FSCALAR_MORE

// step on integers: not differentiable.
#define WP_ADJ_NOOP_STEP(T) WP_FN void adj_step(T, T&, T) {}
WP_ADJ_NOOP_STEP(i8)
WP_ADJ_NOOP_STEP(i16)
WP_ADJ_NOOP_STEP(i32)
WP_ADJ_NOOP_STEP(i64)
WP_ADJ_NOOP_STEP(u8)
WP_ADJ_NOOP_STEP(u16)
WP_ADJ_NOOP_STEP(u32)
WP_ADJ_NOOP_STEP(u64)
#undef WP_ADJ_NOOP_STEP

// ----- float vector functions: lerp, dot, length, normalize -----
#define WP_ADJ_FVEC_FNS(V, S)                                                                     \
  /* lerp, per component in order: the lane rule, adj_t collecting every lane. */                \
  WP_FN void adj_lerp(const V& a, const V& b, S t, V& adj_a, V& adj_b, S& adj_t, const V& adj_ret) { \
    typedef vec_traits<V> T;                                                                      \
    for (int i = 0; i < T::N; ++i)                                                                \
      detail::l_lerp(T::get(a, i), T::get(b, i), t, T::at(adj_a, i), T::at(adj_b, i), adj_t,      \
                     T::get(adj_ret, i));                                                         \
  }                                                                                               \
  /* dot: adj_a[i] += g * b[i]; adj_b[i] += g * a[i]. */                                          \
  WP_FN void adj_dot(const V& a, const V& b, V& adj_a, V& adj_b, S adj_ret) {                     \
    typedef vec_traits<V> T;                                                                      \
    for (int i = 0; i < T::N; ++i) {                                                              \
      T::at(adj_a, i) += adj_ret * T::get(b, i);                                                  \
      T::at(adj_b, i) += adj_ret * T::get(a, i);                                                  \
    }                                                                                             \
  }                                                                                               \
  /* length: adj_v[i] += v[i] * (g / l) when l > 0. */                                            \
  WP_FN void adj_length(const V& v, V& adj_v, S adj_ret) {                                        \
    typedef vec_traits<V> T;                                                                      \
    const S l = wp::length(v);                                                                    \
    if (l > (S)0) {                                                                               \
      const S gl = adj_ret / l;                                                                   \
      for (int i = 0; i < T::N; ++i) T::at(adj_v, i) += T::get(v, i) * gl;                        \
    }                                                                                             \
  }                                                                                               \
  /* normalize: n = v / l, d = dot(n, g); adj_v[i] += (g[i] - n[i] * d) / l when l > 0. */        \
  WP_FN void adj_normalize(const V& v, V& adj_v, const V& adj_ret) {                              \
    typedef vec_traits<V> T;                                                                      \
    const S l = wp::length(v);                                                                    \
    if (l > (S)0) {                                                                               \
      V n;                                                                                        \
      for (int i = 0; i < T::N; ++i) T::at(n, i) = T::get(v, i) / l;                              \
      const S d = wp::dot(n, adj_ret);                                                            \
      for (int i = 0; i < T::N; ++i)                                                              \
        T::at(adj_v, i) += (T::get(adj_ret, i) - T::get(n, i) * d) / l;                           \
    }                                                                                             \
  }
WP_ADJ_FVEC_FNS(Vec2, f32)
WP_ADJ_FVEC_FNS(Vec3, f32)
WP_ADJ_FVEC_FNS(Vec4, f32)
WP_ADJ_FVEC_FNS(DVec2, f64)
WP_ADJ_FVEC_FNS(DVec3, f64)
WP_ADJ_FVEC_FNS(DVec4, f64)
#undef WP_ADJ_FVEC_FNS

#define WP_ADJ_NOOP_DOT(V, S) \
  WP_FN void adj_dot(const V&, const V&, V&, V&, S) {}
WP_ADJ_NOOP_DOT(IVec2, i32)
WP_ADJ_NOOP_DOT(IVec3, i32)
WP_ADJ_NOOP_DOT(IVec4, i32)
WP_ADJ_NOOP_DOT(UVec2, u32)
WP_ADJ_NOOP_DOT(UVec3, u32)
WP_ADJ_NOOP_DOT(UVec4, u32)
#undef WP_ADJ_NOOP_DOT

// ----- cross: adj_a += b x g; adj_b += g x a (the builtin cross) -----
#define WP_ADJ_CROSS(V)                                                              \
  WP_FN void adj_cross(const V& a, const V& b, V& adj_a, V& adj_b, const V& adj_ret) { \
    adj_a += wp::cross(b, adj_ret);                                                  \
    adj_b += wp::cross(adj_ret, a);                                                  \
  }
WP_ADJ_CROSS(Vec3)
WP_ADJ_CROSS(DVec3)
#undef WP_ADJ_CROSS
WP_FN void adj_cross(const IVec3&, const IVec3&, IVec3&, IVec3&, const IVec3&) {}

// ------------------------------------------------------------------------------------------
// Casts (warp-core/src/adjoint/cast.rs)
// ------------------------------------------------------------------------------------------

/// Adjoint of `x as To` for the 13 scalar types: between f32 and f64 (either way, or to the
/// same type) `adj_from += (From)adj_to`; a no-op when either side is an integer or bool.
template <typename From, typename To>
WP_FN void adj_cast(From& adj_from, To adj_to) {
  static_assert(detail::adj_is_scalar<From>::value && detail::adj_is_scalar<To>::value,
                "adj_cast: scalar types only");
  if constexpr (num<From>::is_float && num<To>::is_float) adj_from += (From)adj_to;
}

// ------------------------------------------------------------------------------------------
// Gradients of array arguments (warp_core::GradView)
// ------------------------------------------------------------------------------------------
//
// `g` is the gradient array of an array argument, of the same shape; `g.data == nullptr` when
// the array has none. Indices are checked like `load`/`store` (OutOfBounds with `g.arg`).
//   grad_accum(g, idx.., v, ctx)      g[idx] += v, atomically per float component (the
//                                     adjoint of a read); nothing without a gradient; a
//                                     bounds-checked no-op for integer and bool elements.
//   grad_take(g, idx.., zero, ctx)    returns g[idx] and sets it to `zero` (the adjoint of a
//                                     write); `zero` without a gradient; T{} on a fault.
//   grad_get(g, idx.., zero, ctx)     returns g[idx] (the adjoint of an atomic add); `zero`
//                                     without a gradient; T{} on a fault.
// Device: each float component is one atomicAdd (wp_atomic.h's helpers), the element as a
// whole is not updated atomically. Host builds: a plain add (single-threaded use only).

namespace detail {
template <typename T>
WP_FN void grad_add_p(T* p, const T& v) {
  if constexpr (num<T>::is_float) {
    atomic_add_p(p, v);
  } else if constexpr (!adj_is_scalar<T>::value) {
    if constexpr (adj_is_float<T>::value) {
      for (int i = 0; i < vec_traits<T>::N; ++i)
        atomic_add_p(&vec_traits<T>::at(*p, i), vec_traits<T>::get(v, i));
    }
  }
}
template <typename T, int N>
WP_FN void grad_accum_idx(const array_t<T, N>& g, const i64* idx, const T& v, ctx_t* ctx) {
  if (g.data == nullptr) return;
  T* p = elem_ptr_idx(g, idx, ctx);
  if (p != nullptr) grad_add_p(p, v);
}
template <typename T, int N>
WP_FN T grad_take_idx(const array_t<T, N>& g, const i64* idx, const T& zero, ctx_t* ctx) {
  if (g.data == nullptr) return zero;
  T* p = elem_ptr_idx(g, idx, ctx);
  if (p == nullptr) return T{};
  const T r = *p;
  *p = zero;
  return r;
}
template <typename T, int N>
WP_FN T grad_get_idx(const array_t<T, N>& g, const i64* idx, const T& zero, ctx_t* ctx) {
  if (g.data == nullptr) return zero;
  return load_idx(g, idx, ctx);
}
}  // namespace detail

#define WP_GRAD_FNS(N, PARAMS, ...)                                                                \
  template <typename T>                                                                            \
  WP_FN void grad_accum(const array_t<T, N>& g, PARAMS, const typename identity<T>::type& v,       \
                        ctx_t* ctx) {                                                              \
    const i64 idx[N] = {__VA_ARGS__};                                                              \
    detail::grad_accum_idx(g, idx, v, ctx);                                                        \
  }                                                                                                \
  template <typename T>                                                                            \
  WP_FN T grad_take(const array_t<T, N>& g, PARAMS, const typename identity<T>::type& zero,        \
                    ctx_t* ctx) {                                                                  \
    const i64 idx[N] = {__VA_ARGS__};                                                              \
    return detail::grad_take_idx(g, idx, zero, ctx);                                               \
  }                                                                                                \
  template <typename T>                                                                            \
  WP_FN T grad_get(const array_t<T, N>& g, PARAMS, const typename identity<T>::type& zero,         \
                   ctx_t* ctx) {                                                                   \
    const i64 idx[N] = {__VA_ARGS__};                                                              \
    return detail::grad_get_idx(g, idx, zero, ctx);                                                \
  }
#define WP_COMMA ,
WP_GRAD_FNS(1, i64 i0, i0)
WP_GRAD_FNS(2, i64 i0 WP_COMMA i64 i1, i0, i1)
WP_GRAD_FNS(3, i64 i0 WP_COMMA i64 i1 WP_COMMA i64 i2, i0, i1, i2)
WP_GRAD_FNS(4, i64 i0 WP_COMMA i64 i1 WP_COMMA i64 i2 WP_COMMA i64 i3, i0, i1, i2, i3)
#undef WP_COMMA
#undef WP_GRAD_FNS

// ------------------------------------------------------------------------------------------
// Adjoint kernels: unit results, the per-thread stack, thread-owned gradients, atomic winners
// ------------------------------------------------------------------------------------------

/// A unit func's result (carries no gradient).
struct unit_t {};
WP_FN unit_t zero_like(const unit_t&) { return unit_t{}; }
WP_FN void adj_accum(unit_t&, const unit_t&) {}
/// A value type for a declared result: `void` (a unit func's) becomes `unit_t`.
template <typename T>
struct value_of {
  typedef T type;
};
template <>
struct value_of<void> {
  typedef unit_t type;
};

/// Fault kind of a full adjoint stack (warp_core::FaultKind::AdStackOverflow): index[0] is the
/// source line, shape[0] the capacity in bytes.
enum { FAULT_ADSTACK_OVERFLOW = 4 };

/// The bounded per-thread stack of an adjoint kernel (warp_core::AdStack), in the thread's
/// local memory. After an overflow (a fault) pushes do nothing and pops give zero values, so
/// the thread finishes without touching memory out of bounds; backward reports the fault.
struct adstack_t {
  char* base;
  i32 cap;
  i32 top;
  i32 overflow;
  i32 pad;
};

WP_FN adstack_t adstack_new(char* buf, i32 cap) {
  adstack_t s;
  s.base = buf;
  s.cap = cap;
  s.top = 0;
  s.overflow = 0;
  s.pad = 0;
  return s;
}

namespace detail {
// Byte copy (NVRTC has no __builtin_memcpy; the compiler turns this into plain moves).
WP_FN void copy_bytes(char* dst, const char* src, int n) {
  for (int i = 0; i < n; ++i) dst[i] = src[i];
}
}  // namespace detail

template <typename T>
WP_FN void adstack_push(adstack_t* s, const T& v, i32 line, ctx_t* ctx) {
  if (s->overflow) return;
  if (s->top + (i32)sizeof(T) > s->cap) {
    s->overflow = 1;
    const i64 idx[1] = {(i64)line};
    const i64 shape[1] = {(i64)s->cap};
    raise(ctx, FAULT_ADSTACK_OVERFLOW, -1, 1, idx, shape);
    return;
  }
  detail::copy_bytes(s->base + s->top, reinterpret_cast<const char*>(&v), (int)sizeof(T));
  s->top += (i32)sizeof(T);
}

template <typename T>
WP_FN T adstack_pop(adstack_t* s) {
  T v{};
  if (s->overflow || s->top < (i32)sizeof(T)) return v;
  s->top -= (i32)sizeof(T);
  detail::copy_bytes(reinterpret_cast<char*>(&v), s->base + s->top, (int)sizeof(T));
  return v;
}

/// `g[idx] += v` without atomics and without a bounds check: only for an element no other
/// thread touches, at an index known to be in bounds (thread-index accesses of a launch whose
/// arrays cover the grid).
template <typename T, int N>
WP_FN void grad_accum_own_idx(const array_t<T, N>& g, const i64* idx, const T& v) {
  if (g.data == nullptr) return;
  adj_accum(*detail::elem_ptr_unchecked_idx(g, idx), v);
}
template <typename T>
WP_FN void grad_accum_own(const array_t<T, 1>& g, i64 i0, const typename identity<T>::type& v) {
  const i64 idx[1] = {i0};
  grad_accum_own_idx(g, idx, v);
}
template <typename T>
WP_FN void grad_accum_own(const array_t<T, 2>& g, i64 i0, i64 i1,
                          const typename identity<T>::type& v) {
  const i64 idx[2] = {i0, i1};
  grad_accum_own_idx(g, idx, v);
}
template <typename T>
WP_FN void grad_accum_own(const array_t<T, 3>& g, i64 i0, i64 i1, i64 i2,
                          const typename identity<T>::type& v) {
  const i64 idx[3] = {i0, i1, i2};
  grad_accum_own_idx(g, idx, v);
}
template <typename T>
WP_FN void grad_accum_own(const array_t<T, 4>& g, i64 i0, i64 i1, i64 i2, i64 i3,
                          const typename identity<T>::type& v) {
  const i64 idx[4] = {i0, i1, i2, i3};
  grad_accum_own_idx(g, idx, v);
}

/// Sets `g[idx]` to the zero adjoint without a bounds check (same contract as
/// `grad_accum_own`): the deferred clear of a write-only thread-owned array's gradient.
template <typename T, int N>
WP_FN void grad_clear_own_idx(const array_t<T, N>& g, const i64* idx) {
  if (g.data == nullptr) return;
  *detail::elem_ptr_unchecked_idx(g, idx) = adj_zero<T>();
}
template <typename T>
WP_FN void grad_clear_own(const array_t<T, 1>& g, i64 i0) {
  const i64 idx[1] = {i0};
  grad_clear_own_idx(g, idx);
}
template <typename T>
WP_FN void grad_clear_own(const array_t<T, 2>& g, i64 i0, i64 i1) {
  const i64 idx[2] = {i0, i1};
  grad_clear_own_idx(g, idx);
}
template <typename T>
WP_FN void grad_clear_own(const array_t<T, 3>& g, i64 i0, i64 i1, i64 i2) {
  const i64 idx[3] = {i0, i1, i2};
  grad_clear_own_idx(g, idx);
}
template <typename T>
WP_FN void grad_clear_own(const array_t<T, 4>& g, i64 i0, i64 i1, i64 i2, i64 i3) {
  const i64 idx[4] = {i0, i1, i2, i3};
  grad_clear_own_idx(g, idx);
}

/// warp_core::adj_atomic_extreme: the adjoint of atomic_min/atomic_max goes to `v` where it
/// equals the array's value after the launch (componentwise for vectors).
template <typename T>
WP_FN void adj_atomic_extreme(const T& cur, const T& v, T& adj_v, const T& grad) {
  if constexpr (num<T>::is_float) {
    if (cur == v) adj_v += grad;
  } else if constexpr (!detail::adj_is_scalar<T>::value && detail::adj_is_float<T>::value) {
    for (int i = 0; i < vec_traits<T>::N; ++i)
      if (vec_traits<T>::get(cur, i) == vec_traits<T>::get(v, i))
        vec_traits<T>::at(adj_v, i) += vec_traits<T>::get(grad, i);
  }
}

// ------------------------------------------------------------------------------------------
// Vector, matrix and quaternion builtins (warp-core/src/adjoint/linalg.rs)
// ------------------------------------------------------------------------------------------

// ----- length_sq: adj_v[i] += (v[i] + v[i]) * g -----
#define WP_ADJ_LENSQ(V, S)                                                       \
  WP_FN void adj_length_sq(const V& v, V& adj_v, S g) {                          \
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
WP_FN void adj_length_sq(const IVec2&, IVec2&, i32) {}
WP_FN void adj_length_sq(const IVec3&, IVec3&, i32) {}
WP_FN void adj_length_sq(const IVec4&, IVec4&, i32) {}
WP_FN void adj_length_sq(const UVec2&, UVec2&, u32) {}
WP_FN void adj_length_sq(const UVec3&, UVec3&, u32) {}
WP_FN void adj_length_sq(const UVec4&, UVec4&, u32) {}

// ----- outer, diag, cw_mul, cw_div (vectors), and the matrix builtins -----
#define WP_ADJ_LINALG(V, M, S)                                                           \
  WP_FN void adj_outer(const V& a, const V& b, V& adj_a, V& adj_b, const M& g) {         \
    adj_a += g * b;                                                                      \
    adj_b += detail::adj_transpose(g) * a;                                               \
  }                                                                                      \
  WP_FN void adj_diag(const V&, V& adj_v, const M& g) {                                  \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                           \
      vec_traits<V>::at(adj_v, i) += vec_traits<V>::get(mat_traits<M>::get(g, i), i);    \
  }                                                                                      \
  WP_FN void adj_cw_mul(const V& a, const V& b, V& adj_a, V& adj_b, const V& g) {        \
    detail::zip_vv(a, b, adj_a, adj_b, g, detail::l_mul());                              \
  }                                                                                      \
  WP_FN void adj_cw_div(const V& a, const V& b, V& adj_a, V& adj_b, const V& g) {        \
    detail::zip_vv(a, b, adj_a, adj_b, g, detail::l_div());                              \
  }                                                                                      \
  WP_FN void adj_cw_mul(const M& a, const M& b, M& adj_a, M& adj_b, const M& g) {        \
    detail::zip_vv(a, b, adj_a, adj_b, g, detail::l_mul());                              \
  }                                                                                      \
  WP_FN void adj_cw_div(const M& a, const M& b, M& adj_a, M& adj_b, const M& g) {        \
    detail::zip_vv(a, b, adj_a, adj_b, g, detail::l_div());                              \
  }                                                                                      \
  WP_FN void adj_transpose(const M&, M& adj_m, const M& g) { adj_m += detail::adj_transpose(g); } \
  WP_FN void adj_trace(const M&, M& adj_m, S g) {                                        \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                           \
      vec_traits<V>::at(mat_traits<M>::at(adj_m, i), i) += g;                            \
  }                                                                                      \
  WP_FN void adj_ddot(const M& a, const M& b, M& adj_a, M& adj_b, S g) {                 \
    typedef vec_traits<M> T;                                                             \
    for (int k = 0; k < T::N; ++k) {                                                     \
      T::at(adj_a, k) += g * T::get(b, k);                                               \
      T::at(adj_b, k) += g * T::get(a, k);                                               \
    }                                                                                    \
  }                                                                                      \
  /* inverse: T = transpose(inverse(m)); adj_m -= (T * G) * T. */                        \
  WP_FN void adj_inverse(const M& m, M& adj_m, const M& g) {                             \
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
  WP_FN void adj_determinant(const M& m, M& a, S g) {                             \
    a.x_axis.x += g * m.y_axis.y;                                                 \
    a.x_axis.y -= g * m.y_axis.x;                                                 \
    a.y_axis.x -= g * m.x_axis.y;                                                 \
    a.y_axis.y += g * m.x_axis.x;                                                 \
  }
WP_ADJ_DET2(Mat2, f32)
WP_ADJ_DET2(DMat2, f64)
#undef WP_ADJ_DET2
#define WP_ADJ_DET3(M, V, S)                                                      \
  WP_FN void adj_determinant(const M& m, M& a, S g) {                             \
    a.x_axis += wp::cross(m.y_axis, m.z_axis) * g;                                \
    a.y_axis += wp::cross(m.z_axis, m.x_axis) * g;                                \
    a.z_axis += wp::cross(m.x_axis, m.y_axis) * g;                                \
  }                                                                               \
  WP_FN void adj_skew(const V&, V& adj_v, const M& g) {                           \
    adj_v.x += g.y_axis.z - g.z_axis.y;                                           \
    adj_v.y += g.z_axis.x - g.x_axis.z;                                           \
    adj_v.z += g.x_axis.y - g.y_axis.x;                                           \
  }
WP_ADJ_DET3(Mat3, Vec3, f32)
WP_ADJ_DET3(DMat3, DVec3, f64)
#undef WP_ADJ_DET3
/* 4x4: each entry's signed 3x3 minor (the remaining columns and rows in order). */
#define WP_ADJ_DET4(M, M3, V3, S)                                                  \
  WP_FN void adj_determinant(const M& m, M& a, S g) {                              \
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
  WP_FN void adj_dot(const Q& a, const Q& b, Q& adj_a, Q& adj_b, S g) {                          \
    for (int i = 0; i < 4; ++i) {                                                                \
      vec_traits<Q>::at(adj_a, i) += g * vec_traits<Q>::get(b, i);                               \
      vec_traits<Q>::at(adj_b, i) += g * vec_traits<Q>::get(a, i);                               \
    }                                                                                            \
  }                                                                                              \
  WP_FN void adj_length(const Q& v, Q& adj_v, S g) {                                             \
    const S l = wp::length(v);                                                                   \
    if (l > (S)0) {                                                                              \
      const S gl = g / l;                                                                        \
      for (int i = 0; i < 4; ++i) vec_traits<Q>::at(adj_v, i) += vec_traits<Q>::get(v, i) * gl;  \
    }                                                                                            \
  }                                                                                              \
  WP_FN void adj_normalize(const Q& v, Q& adj_v, const Q& g) {                                   \
    const S l = wp::length(v);                                                                   \
    if (l > (S)0) {                                                                              \
      const Q n = Q##_from_xyzw(v.x / l, v.y / l, v.z / l, v.w / l);                             \
      const S d = detail::qdot(n, g);                                                            \
      for (int i = 0; i < 4; ++i)                                                                \
        vec_traits<Q>::at(adj_v, i) += (vec_traits<Q>::get(g, i) - vec_traits<Q>::get(n, i) * d) / l; \
    }                                                                                            \
  }                                                                                              \
  WP_FN void adj_quat_inverse(const Q&, Q& adj_q, const Q& g) {                                  \
    adj_q.x -= g.x;                                                                              \
    adj_q.y -= g.y;                                                                              \
    adj_q.z -= g.z;                                                                              \
    adj_q.w += g.w;                                                                              \
  }                                                                                              \
  WP_FN void adj_inverse(const Q& q, Q& adj_q, const Q& g) { adj_quat_inverse(q, adj_q, g); }    \
  WP_FN void adj_quat_from_axis_angle(const V3& axis, S angle, V3& adj_axis, S& adj_angle,       \
                                      const Q& g) {                                              \
    const S h = angle * (S)0.5;                                                                  \
    const S s = sin(h), c = cos(h);                                                              \
    adj_axis += V3##_new(g.x, g.y, g.z) * s;                                                     \
    const S d = (g.x * axis.x + g.y * axis.y) + g.z * axis.z;                                    \
    adj_angle += (d * c - g.w * s) * (S)0.5;                                                     \
  }                                                                                              \
  WP_FN void adj_quat_rotate(const Q& q, const V3& v, Q& adj_q, V3& adj_v, const V3& g) {        \
    adj_mul(q, v, adj_q, adj_v, g);                                                              \
  }                                                                                              \
  WP_FN void adj_quat_rotate_inv(const Q& q, const V3& v, Q& adj_q, V3& adj_v, const V3& g) {    \
    Q ac = adj_zero<Q>();                                                                        \
    adj_mul(quat_inverse(q), v, ac, adj_v, g);                                                   \
    adj_quat_inverse(q, adj_q, ac);                                                              \
  }                                                                                              \
  WP_FN void adj_quat_to_matrix(const Q& q, Q& adj_q, const M3& gm) {                            \
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
  WP_FN void adj_quat_from_matrix(const M3& m, M3& adj_m, const Q& g) {                          \
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
  WP_FN void adj_quat_slerp(const Q& q0, const Q& q1, S t, Q& adj_q0, Q& adj_q1, S& adj_t,       \
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

// ------------------------------------------------------------------------------------------
// Perlin noise (warp-core: adjoint/noise.rs): adj_x[k] += grad[k] * adj_ret, with the
// gradient of wp_rand.h's `perlin` and unfused operations (so bit for bit with the CPU); the
// state and the periods are integers and get nothing.
// ------------------------------------------------------------------------------------------

namespace detail {
WP_FN void adj_noise_accum(f32& adj_x, const f32* g, f32 adj_ret) {
  adj_x = rn_add(adj_x, rn_mul(g[0], adj_ret));
}
template <typename V>
WP_FN void adj_noise_accum(V& adj_x, const f32* g, f32 adj_ret) {
  for (int k = 0; k < vec_traits<V>::N; ++k) {
    vec_traits<V>::at(adj_x, k) = rn_add(vec_traits<V>::get(adj_x, k), rn_mul(g[k], adj_ret));
  }
}
}  // namespace detail

#define WP_ADJ_NOISE(V, P)                                                                  \
  WP_FN void adj_noise(u32 state, V x, u32& adj_state, V& adj_x, f32 adj_ret) {             \
    (void)adj_state;                                                                        \
    f32 l[4], g[4];                                                                         \
    detail::noise_lanes(x, l);                                                              \
    detail::perlin(state, l, nullptr, detail::noise_dim<V>::N, g);                          \
    detail::adj_noise_accum(adj_x, g, adj_ret);                                             \
  }                                                                                         \
  WP_FN void adj_pnoise(u32 state, V x, P period, u32& adj_state, V& adj_x, P& adj_period, \
                        f32 adj_ret) {                                                      \
    (void)adj_state;                                                                        \
    (void)adj_period;                                                                       \
    f32 l[4], g[4];                                                                         \
    i32 p[4];                                                                               \
    detail::noise_lanes(x, l);                                                              \
    detail::noise_periods(period, p);                                                       \
    detail::perlin(state, l, p, detail::noise_dim<V>::N, g);                                \
    detail::adj_noise_accum(adj_x, g, adj_ret);                                             \
  }
WP_ADJ_NOISE(f32, i32)
WP_ADJ_NOISE(Vec2, IVec2)
WP_ADJ_NOISE(Vec3, IVec3)
WP_ADJ_NOISE(Vec4, IVec4)
#undef WP_ADJ_NOISE
// Rigid transforms (warp-core/src/adjoint/transform.rs): operators and the "transform" section
// ------------------------------------------------------------------------------------------

#define WP_ADJ_XFORM(X, V3, V4, Q, M3, M4, S)                                                    \
  WP_FN void adj_add(const X&, const X&, X& adj_a, X& adj_b, const X& g) {                       \
    adj_a += g;                                                                                  \
    adj_b += g;                                                                                  \
  }                                                                                              \
  WP_FN void adj_sub(const X&, const X&, X& adj_a, X& adj_b, const X& g) {                       \
    adj_a += g;                                                                                  \
    adj_b -= g;                                                                                  \
  }                                                                                              \
  WP_FN void adj_neg(const X&, X& adj_a, const X& g) { adj_a -= g; }                             \
  WP_FN void adj_mul(const X& a, S s, X& adj_a, S& adj_s, const X& g) {                          \
    detail::zip_vs(a, s, adj_a, adj_s, g, detail::l_mul());                                      \
  }                                                                                              \
  WP_FN void adj_mul(S s, const X& b, S& adj_s, X& adj_b, const X& g) {                          \
    detail::zip_sv(s, b, adj_s, adj_b, g, detail::l_mul());                                      \
  }                                                                                              \
  WP_FN void adj_transform_multiply(const X& a, const X& b, X& adj_a, X& adj_b, const X& g) {    \
    adj_mul(a.q, b.p, adj_a.q, adj_b.p, g.p);                                                    \
    adj_a.p += g.p;                                                                              \
    adj_mul(a.q, b.q, adj_a.q, adj_b.q, g.q);                                                    \
  }                                                                                              \
  WP_FN void adj_mul(const X& a, const X& b, X& adj_a, X& adj_b, const X& g) {                   \
    adj_transform_multiply(a, b, adj_a, adj_b, g);                                               \
  }                                                                                              \
  WP_FN void adj_lerp(const X& a, const X& b, S t, X& adj_a, X& adj_b, S& adj_t, const X& g) {   \
    typedef vec_traits<X> T;                                                                     \
    for (int i = 0; i < 7; ++i)                                                                  \
      detail::l_lerp(T::get(a, i), T::get(b, i), t, T::at(adj_a, i), T::at(adj_b, i), adj_t,    \
                     T::get(g, i));                                                              \
  }                                                                                              \
  WP_FN void adj_transformation(const V3&, const Q&, V3& adj_p, Q& adj_q, const X& g) {          \
    adj_p += g.p;                                                                                \
    adj_q += g.q;                                                                                \
  }                                                                                              \
  WP_FN void adj_transform_get_translation(const X&, X& adj_t, const V3& g) { adj_t.p += g; }    \
  WP_FN void adj_transform_get_rotation(const X&, X& adj_t, const Q& g) { adj_t.q += g; }        \
  WP_FN void adj_transform_point(const X& t, const V3& x, X& adj_t, V3& adj_x, const V3& g) {    \
    adj_mul(t.q, x, adj_t.q, adj_x, g);                                                          \
    adj_t.p += g;                                                                                \
  }                                                                                              \
  WP_FN void adj_transform_vector(const X& t, const V3& x, X& adj_t, V3& adj_x, const V3& g) {   \
    adj_mul(t.q, x, adj_t.q, adj_x, g);                                                          \
  }                                                                                              \
  /* forward: qi = conj(q), r = -(qi * p) */                                                     \
  WP_FN void adj_transform_inverse(const X& t, X& adj_t, const X& g) {                           \
    const Q qi = quat_inverse(t.q);                                                              \
    Q adj_qi = g.q;                                                                              \
    adj_mul(qi, t.p, adj_qi, adj_t.p, -g.p);                                                     \
    adj_quat_inverse(t.q, adj_t.q, adj_qi);                                                      \
  }                                                                                              \
  WP_FN void adj_inverse(const X& t, X& adj_t, const X& g) { adj_transform_inverse(t, adj_t, g); } \
  WP_FN void adj_transform_to_matrix(const X& t, X& adj_t, const M4& g) {                        \
    const M3 g3 = M3##_from_cols(V3##_new(g.x_axis.x, g.x_axis.y, g.x_axis.z),                   \
                                 V3##_new(g.y_axis.x, g.y_axis.y, g.y_axis.z),                   \
                                 V3##_new(g.z_axis.x, g.z_axis.y, g.z_axis.z));                  \
    adj_quat_to_matrix(t.q, adj_t.q, g3);                                                        \
    adj_t.p += V3##_new(g.w_axis.x, g.w_axis.y, g.w_axis.z);                                     \
  }                                                                                              \
  WP_FN void adj_transform_from_matrix(const M4& m, M4& adj_m, const X& g) {                     \
    const M3 m3 = M3##_from_cols(V3##_new(m.x_axis.x, m.x_axis.y, m.x_axis.z),                   \
                                 V3##_new(m.y_axis.x, m.y_axis.y, m.y_axis.z),                   \
                                 V3##_new(m.z_axis.x, m.z_axis.y, m.z_axis.z));                  \
    M3 a3 = M3##_from_cols(V3##_new(adj_m.x_axis.x, adj_m.x_axis.y, adj_m.x_axis.z),             \
                           V3##_new(adj_m.y_axis.x, adj_m.y_axis.y, adj_m.y_axis.z),             \
                           V3##_new(adj_m.z_axis.x, adj_m.z_axis.y, adj_m.z_axis.z));            \
    adj_quat_from_matrix(m3, a3, g.q);                                                           \
    adj_m.x_axis = V4##_new(a3.x_axis.x, a3.x_axis.y, a3.x_axis.z, adj_m.x_axis.w);              \
    adj_m.y_axis = V4##_new(a3.y_axis.x, a3.y_axis.y, a3.y_axis.z, adj_m.y_axis.w);              \
    adj_m.z_axis = V4##_new(a3.z_axis.x, a3.z_axis.y, a3.z_axis.z, adj_m.z_axis.w);              \
    adj_m.w_axis.x += g.p.x;                                                                     \
    adj_m.w_axis.y += g.p.y;                                                                     \
    adj_m.w_axis.z += g.p.z;                                                                     \
  }                                                                                              \
  /* 4x4 matrices: adj_m.{x,y,z}_axis[k] += g[k] * x.{x,y,z}; adj_x.c += column c . g. */       \
  WP_FN void adj_transform_vector(const M4& m, const V3& x, M4& adj_m, V3& adj_x, const V3& g) { \
    adj_m.x_axis.x += g.x * x.x;                                                                 \
    adj_m.x_axis.y += g.y * x.x;                                                                 \
    adj_m.x_axis.z += g.z * x.x;                                                                 \
    adj_m.y_axis.x += g.x * x.y;                                                                 \
    adj_m.y_axis.y += g.y * x.y;                                                                 \
    adj_m.y_axis.z += g.z * x.y;                                                                 \
    adj_m.z_axis.x += g.x * x.z;                                                                 \
    adj_m.z_axis.y += g.y * x.z;                                                                 \
    adj_m.z_axis.z += g.z * x.z;                                                                 \
    adj_x.x += (m.x_axis.x * g.x + m.x_axis.y * g.y) + m.x_axis.z * g.z;                         \
    adj_x.y += (m.y_axis.x * g.x + m.y_axis.y * g.y) + m.y_axis.z * g.z;                         \
    adj_x.z += (m.z_axis.x * g.x + m.z_axis.y * g.y) + m.z_axis.z * g.z;                         \
  }                                                                                              \
  WP_FN void adj_transform_point(const M4& m, const V3& x, M4& adj_m, V3& adj_x, const V3& g) {  \
    adj_transform_vector(m, x, adj_m, adj_x, g);                                                 \
    adj_m.w_axis.x += g.x;                                                                       \
    adj_m.w_axis.y += g.y;                                                                       \
    adj_m.w_axis.z += g.z;                                                                       \
  }
WP_ADJ_XFORM(Transform, Vec3, Vec4, Quat, Mat3, Mat4, f32)
WP_ADJ_XFORM(DTransform, DVec3, DVec4, DQuat, DMat3, DMat4, f64)
#undef WP_ADJ_XFORM

// ------------------------------------------------------------------------------------------
// Decompositions (warp-core/src/adjoint/svd.rs): tuple adjoints, adj_svd3, adj_svd2,
// adj_eig3, adj_qr3 (Warp's formulas; products on rows, left to right, as on the CPU)
// ------------------------------------------------------------------------------------------

template <typename A, typename B, typename C>
WP_FN tuple_t<A, B, C> zero_like(const tuple_t<A, B, C>& t) {
  return tuple_t<A, B, C>{zero_like(t.f0), zero_like(t.f1), zero_like(t.f2)};
}
template <typename A, typename B>
WP_FN tuple_t<A, B> zero_like(const tuple_t<A, B>& t) {
  return tuple_t<A, B>{zero_like(t.f0), zero_like(t.f1)};
}
template <typename A, typename B, typename C>
WP_FN void adj_accum(tuple_t<A, B, C>& a, const tuple_t<A, B, C>& v) {
  adj_accum(a.f0, v.f0);
  adj_accum(a.f1, v.f1);
  adj_accum(a.f2, v.f2);
}
template <typename A, typename B>
WP_FN void adj_accum(tuple_t<A, B>& a, const tuple_t<A, B>& v) {
  adj_accum(a.f0, v.f0);
  adj_accum(a.f1, v.f1);
}

namespace detail {
namespace svd {
template <typename S, int N, typename F>
WP_FN void zip_rows(const S (&a)[N][N], const S (&b)[N][N], S (&out)[N][N], F f) {
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) out[i][j] = f(a[i][j], b[i][j]);
}
template <typename S>
WP_FN S sub_(S x, S y) { return x - y; }
template <typename S>
WP_FN S add_(S x, S y) { return x + y; }
template <typename S>
WP_FN S mul_(S x, S y) { return x * y; }
/// A difference moved to at least eps in magnitude (+eps for an exact 0; NaN stays).
template <typename S>
WP_FN S gap(S d) {
  const S eps = cfg<S>::eps();
  if (d >= (S)0 && d < eps) return eps;
  if (d < (S)0 && d > -eps) return -eps;
  return d;
}
template <typename S>
WP_FN rows2<S> mul2(const rows2<S>& a, const rows2<S>& b) {
  rows2<S> r;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) r.m[i][j] = a.m[i][0] * b.m[0][j] + a.m[i][1] * b.m[1][j];
  return r;
}
template <typename S>
WP_FN rows2<S> mul2_tn(const rows2<S>& a, const rows2<S>& b) {
  rows2<S> r;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) r.m[i][j] = a.m[0][i] * b.m[0][j] + a.m[1][i] * b.m[1][j];
  return r;
}
template <typename S>
WP_FN rows2<S> mul2_nt(const rows2<S>& a, const rows2<S>& b) {
  rows2<S> r;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) r.m[i][j] = a.m[i][0] * b.m[j][0] + a.m[i][1] * b.m[j][1];
  return r;
}

/// The SVD adjoint shared by svd3 (N = 3) and svd2 (N = 2): u_term + v_term + sigma_term.
template <typename S, int N, typename R, typename Mul, typename MulTn, typename MulNt>
WP_FN R adj_svd_rows(const R& u, const S* s, const R& v, const R& gu, const S* gs, const R& gv,
                     Mul mul, MulTn mul_tn, MulNt mul_nt) {
  const S one = (S)1, z = (S)0, eps = -cfg<S>::eps();
  R f;
  for (int i = 0; i < N; ++i) f.m[i][i] = z;
  for (int i = 0; i < N; ++i)
    for (int j = i + 1; j < N; ++j) {
      const S fij = one / wp::min(s[j] * s[j] - s[i] * s[i], eps);
      f.m[i][j] = fij;
      f.m[j][i] = -fij;
    }
  R us;
  for (int i = 0; i < N; ++i)
    for (int k = 0; k < N; ++k) us.m[i][k] = u.m[i][k] * gs[k];
  const R sigma_term = mul_nt(us, v);
  R d, ku, kv, t;
  zip_rows(mul_tn(u, gu).m, mul_tn(gu, u).m, d.m, sub_<S>);
  zip_rows(f.m, d.m, ku.m, mul_<S>);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) t.m[i][j] = ku.m[i][j] * s[j];
  const R u_term = mul_nt(mul(u, t), v);
  zip_rows(mul_tn(v, gv).m, mul_tn(gv, v).m, d.m, sub_<S>);
  zip_rows(f.m, d.m, kv.m, mul_<S>);
  const R kv_vt = mul_nt(kv, v);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) t.m[i][j] = s[i] * kv_vt.m[i][j];
  const R v_term = mul(u, t);
  R total;
  zip_rows(u_term.m, v_term.m, total.m, add_<S>);
  zip_rows(total.m, sigma_term.m, total.m, add_<S>);
  return total;
}
}  // namespace svd
}  // namespace detail

#define WP_ADJ_SVD3(M, V, S)                                                                  \
  WP_FN void adj_svd3(const M& a, M& adj_a, const tuple_t<M, V, M>& g) {                      \
    namespace d = detail::svd;                                                                \
    d::rows3<S> u, v;                                                                         \
    S s[3];                                                                                   \
    d::svd3_rows(d::to_rows<3>(a), u, s, v);                                                    \
    const S gs[3] = {g.f1.x, g.f1.y, g.f1.z};                                                 \
    const d::rows3<S> total = d::adj_svd_rows<S, 3>(                                          \
        u, s, v, d::to_rows<3>(g.f0), gs, d::to_rows<3>(g.f2), d::mul3<S>, d::mul3_tn<S>,         \
        d::mul3_nt<S>);                                                                       \
    adj_accum(adj_a, d::from_rows<M>(total));                                                \
  }                                                                                           \
  WP_FN void adj_eig3(const M& a, M& adj_a, const tuple_t<M, V>& g) {                         \
    namespace d = detail::svd;                                                                \
    d::rows3<S> q;                                                                            \
    S e[3];                                                                                   \
    d::eig3_rows(d::to_rows<3>(a), q, e);                                                       \
    const S gd[3] = {g.f1.x, g.f1.y, g.f1.z};                                                 \
    const S one = (S)1, z = (S)0;                                                             \
    const S f01 = one / d::gap(e[1] - e[0]);                                                  \
    const S f02 = one / d::gap(e[2] - e[0]);                                                  \
    const S f12 = one / d::gap(e[2] - e[1]);                                                  \
    const S f[3][3] = {{z, f01, f02}, {-f01, z, f12}, {-f02, -f12, z}};                       \
    const S dbar[3][3] = {{gd[0], z, z}, {z, gd[1], z}, {z, z, gd[2]}};                       \
    d::rows3<S> h, inner;                                                                     \
    d::zip_rows(f, d::mul3_tn(q, d::to_rows<3>(g.f0)).m, h.m, d::mul_<S>);                      \
    d::zip_rows(dbar, h.m, inner.m, d::add_<S>);                                              \
    adj_accum(adj_a, d::from_rows<M>(d::mul3(q, d::mul3_nt(inner, q))));                     \
  }                                                                                           \
  WP_FN void adj_qr3(const M& a, M& adj_a, const tuple_t<M, M>& g) {                          \
    namespace d = detail::svd;                                                                \
    d::rows3<S> q, r;                                                                         \
    d::qr_rows(d::to_rows<3>(a), q, r);                                                         \
    const d::rows3<S> gq = d::to_rows<3>(g.f0), gr = d::to_rows<3>(g.f1);                         \
    d::rows3<S> m, c, x, rt;                                                                  \
    d::zip_rows(d::mul3_nt(r, gr).m, d::mul3_tn(gq, q).m, m.m, d::sub_<S>);                   \
    for (int i = 0; i < 3; ++i)                                                               \
      for (int j = 0; j < 3; ++j) {                                                           \
        c.m[i][j] = m.m[i > j ? i : j][i < j ? i : j];                                        \
        rt.m[i][j] = r.m[j][i];                                                               \
      }                                                                                       \
    d::zip_rows(gq.m, d::mul3(q, c).m, x.m, d::add_<S>);                                      \
    const d::rows3<S> inv = d::to_rows<3>(inverse(d::from_rows<M>(rt)));                       \
    adj_accum(adj_a, d::from_rows<M>(d::mul3(x, inv)));                                      \
  }
WP_ADJ_SVD3(Mat3, Vec3, f32)
WP_ADJ_SVD3(DMat3, DVec3, f64)
#undef WP_ADJ_SVD3

#define WP_ADJ_SVD2(M, V, S)                                                                  \
  WP_FN void adj_svd2(const M& a, M& adj_a, const tuple_t<M, V, M>& g) {                      \
    namespace d = detail::svd;                                                                \
    d::rows2<S> u, v;                                                                         \
    S s[2];                                                                                   \
    d::svd2_rows(d::to_rows<2>(a), u, s, v);                                                    \
    const S gs[2] = {g.f1.x, g.f1.y};                                                         \
    const d::rows2<S> total = d::adj_svd_rows<S, 2>(                                          \
        u, s, v, d::to_rows<2>(g.f0), gs, d::to_rows<2>(g.f2), d::mul2<S>, d::mul2_tn<S>,         \
        d::mul2_nt<S>);                                                                       \
    adj_accum(adj_a, d::from_rows<M>(total));                                                \
  }
WP_ADJ_SVD2(Mat2, Vec2, f32)
WP_ADJ_SVD2(DMat2, DVec2, f64)
#undef WP_ADJ_SVD2

}  // namespace wp

// ------------------------------------------------------------------------------------------
// Section "misc" (warp-core: adjoint/misc.rs, the same steps in the same order)
// ------------------------------------------------------------------------------------------

namespace wp {

WP_FN void adj_copysign(f32 x, f32 y, f32& adj_x, f32&, f32 adj_ret) {
  if (copysign(1.0f, x) == copysign(1.0f, y)) adj_x += adj_ret; else adj_x -= adj_ret;
}
WP_FN void adj_copysign(f64 x, f64 y, f64& adj_x, f64&, f64 adj_ret) {
  if (copysign(1.0, x) == copysign(1.0, y)) adj_x += adj_ret; else adj_x -= adj_ret;
}

#define WP_ADJ_MISC_FVEC(V, S)                                                                  \
  WP_FN void adj_min_element(const V& v, V& adj_v, S g) { vec_traits<V>::at(adj_v, (int)argmin(v)) += g; } \
  WP_FN void adj_max_element(const V& v, V& adj_v, S g) { vec_traits<V>::at(adj_v, (int)argmax(v)) += g; } \
  WP_FN void adj_norm_l1(const V& v, V& adj_v, S g) {                                           \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                                  \
      adj_abs(vec_traits<V>::get(v, i), vec_traits<V>::at(adj_v, i), g);                       \
  }                                                                                             \
  WP_FN void adj_norm_l2(const V& v, V& adj_v, S g) { adj_length(v, adj_v, g); }               \
  WP_FN void adj_norm_huber(const V& v, S delta, V& adj_v, S& adj_delta, S g) {                 \
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
  WP_FN void adj_norm_pseudo_huber(const V& v, S delta, V& adj_v, S& adj_delta, S g) {          \
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
  WP_FN void adj_smooth_normalize(const V& v, S delta, V& adj_v, S& adj_delta, const V& g) {    \
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
  WP_FN void adj_min_element(const V&, V&, S) {}                                                \
  WP_FN void adj_max_element(const V&, V&, S) {}
WP_ADJ_MISC_IVEC(IVec2, i32)
WP_ADJ_MISC_IVEC(IVec3, i32)
WP_ADJ_MISC_IVEC(IVec4, i32)
WP_ADJ_MISC_IVEC(UVec2, u32)
WP_ADJ_MISC_IVEC(UVec3, u32)
WP_ADJ_MISC_IVEC(UVec4, u32)
#undef WP_ADJ_MISC_IVEC

#define WP_ADJ_MISC_DIAG(M, V)                                                                  \
  WP_FN void adj_get_diag(const M&, M& adj_m, const V& g) {                                     \
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
  WP_FN void adj_quat_to_axis_angle(const Q& q, Q& adj_q, const tuple_t<V3, S>& g) {            \
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
  WP_FN void adj_quat_rpy(S roll, S pitch, S yaw, S& adj_roll, S& adj_pitch, S& adj_yaw,        \
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
  WP_FN void adj_quat_to_rpy(const Q& q, Q& adj_q, const V3& g) {                               \
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
  WP_FN void adj_quat_twist(const V3& axis, const Q& q, V3& adj_axis, Q& adj_q, const Q& g) {   \
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
  WP_FN void adj_misc_twist_angle(const V3& axis, const Q& q, V3& adj_axis, Q& adj_q, S g,      \
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
  WP_FN void adj_quat_twist_angle(const V3& axis, const Q& q, V3& adj_axis, Q& adj_q, S g) {    \
    adj_misc_twist_angle(axis, q, adj_axis, adj_q, g, false);                                   \
  }                                                                                             \
  WP_FN void adj_quat_twist_angle_signed(const V3& axis, const Q& q, V3& adj_axis, Q& adj_q,    \
                                         S g) {                                                 \
    adj_misc_twist_angle(axis, q, adj_axis, adj_q, g, true);                                    \
  }                                                                                             \
  WP_FN void adj_transform_compose(const V3&, const Q& q, const V3& s, V3& adj_p, Q& adj_q,     \
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
  WP_FN void adj_transform_decompose(const M4& m, M4& adj_m, const tuple_t<V3, Q, V3>& g) {     \
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

// wp_adjoint_core.h: zero and accumulation, lane adjoints, operators, casts, array gradients and
// the adjoint kernels' runtime (per-thread stack, thread-owned gradients, atomic winners).
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions. An adjoint
// translation unit includes wp_adjoint_core.h and the adjoint headers of the builtin-table
// sections its kernel uses (warp_cuda::ADJOINT_SECTIONS), so NVRTC parses no more than it
// needs.
#pragma once
#include "wp_core.h"
#include "wp_vector.h"  // floor, sign (via wp_scalar.h) and cross: the operators' adjoints use them
#include "wp_atomic.h"  // gradients of arrays are accumulated atomically

namespace wp {

// ------------------------------------------------------------------------------------------
// Zero and accumulation (warp_core::adjoint::Adjoint)
// ------------------------------------------------------------------------------------------

namespace detail {
/// The scalar type of T (T itself for scalars; the lane type of vectors, matrices, quats).
template <typename T>
struct adj_scalar_of : scalar_of<T> {};
template <typename T>
struct adj_is_scalar {
  static constexpr bool value = num<T>::is_int || num<T>::is_float || num<T>::is_bool;
};
/// Whether T has a (float) adjoint: f32, f64 and the float vectors, matrices, quaternions.
template <typename T>
struct adj_is_float {
  static constexpr bool value = num<typename adj_scalar_of<T>::type>::is_float;
};
/// Whether T is a kernel object or a query state (`hash_grid_t`, `hash_grid_query_t`: a
/// `wp_object_tag` member type): no gradient; its zero is the value-initialised object, what
/// an adjoint declares for a func's object argument (warp_core's `Adjoint` for the views).
template <typename T, typename = void>
struct adj_is_object {
  static constexpr bool value = false;
};
template <typename T>
struct adj_is_object<T, typename T::wp_object_tag> {
  static constexpr bool value = true;
};
}  // namespace detail

/// The zero adjoint of T: 0, 0.0, false, the zero vector or matrix, the quaternion (0, 0, 0, 0).
template <typename T>
WP_FN T adj_zero() {
  if constexpr (detail::adj_is_scalar<T>::value) {
    return (T)0;
  } else if constexpr (detail::adj_is_object<T>::value) {
    return T{};
  } else if constexpr (detail::is_local_array<T>::value) {
    T r;
    for (auto& e : r.data) e = adj_zero<typename detail::is_local_array<T>::elem>();
    return r;
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
/// `warp_core::GradSeed`: the adjoint `wp::grad(f)(..)` gives f's result, one in every lane.
template <typename T>
WP_FN T adj_one() {
  if constexpr (detail::adj_is_scalar<T>::value) {
    return (T)1;
  } else {
    typedef typename vec_traits<T>::scalar S;
    T r;
    for (int i = 0; i < vec_traits<T>::N; ++i) vec_traits<T>::at(r, i) = (S)1;
    return r;
  }
}
template <typename A, typename B>
WP_FN void adj_one_into(tuple_t<A, B>& t) {
  t.f0 = adj_one<A>();
  t.f1 = adj_one<B>();
}
template <typename A, typename B, typename C>
WP_FN void adj_one_into(tuple_t<A, B, C>& t) {
  t.f0 = adj_one<A>();
  t.f1 = adj_one<B>();
  t.f2 = adj_one<C>();
}
template <typename A, typename B, typename C, typename D>
WP_FN void adj_one_into(tuple_t<A, B, C, D>& t) {
  t.f0 = adj_one<A>();
  t.f1 = adj_one<B>();
  t.f2 = adj_one<C>();
  t.f3 = adj_one<D>();
}
template <typename T>
WP_FN void adj_one_into(T& t) {
  t = adj_one<T>();
}
/// The stack a `wp::grad` call gives the func's adjoint: the adjoint units' per-thread size
/// (`WP_ADSTACK_BYTES`, the runtime's `adstack_bytes`), or in a forward unit, which is
/// compiled without it, the runtime's default (config.rs `DEFAULT_ADSTACK_BYTES`; a test
/// there keeps the two equal).
#ifdef WP_ADSTACK_BYTES
#define WP_GRAD_STACK_BYTES WP_ADSTACK_BYTES
#else
#define WP_GRAD_STACK_BYTES 4096
#endif

/// `a += v` for float types (componentwise); a no-op for integer, integer-vector and bool
/// types, whose adjoint is always zero.
template <typename T>
WP_FN void adj_accum(T& a, const typename identity<T>::type& v) {
  if constexpr (detail::adj_is_object<T>::value) {
    (void)a;
    (void)v;
  } else if constexpr (detail::adj_is_float<T>::value) {
    a += v;
  }
}

/// A local array's adjoint: element by element.
template <typename T, int N>
WP_FN void adj_accum(local_array_t<T, N>& a, const local_array_t<T, N>& v) {
  for (int i = 0; i < N; ++i) adj_accum(a.data[i], v.data[i]);
}
/// The sum of a local array's elements from zero in index order (the adjoint of `[v; N]`,
/// warp_core::local_array::sum).
template <typename T, int N>
WP_FN T local_sum(const local_array_t<T, N>& a) {
  T s = adj_zero<T>();
  for (int i = 0; i < N; ++i) adj_accum(s, a.data[i]);
  return s;
}

// ------------------------------------------------------------------------------------------
// Lane adjoints (warp-core/src/adjoint/lanes.rs)
// ------------------------------------------------------------------------------------------

namespace detail {
template <typename F> WP_FN bool adj_isnan(F x) { return !(x == x); }
WP_LFN f32 adj_trunc(f32 x) { return ::truncf(x); }
WP_LFN f64 adj_trunc(f64 x) { return ::trunc(x); }
WP_LFN f16 adj_trunc(f16 x) { return f16_from_f32(::truncf(f16_to_f32(x))); }
WP_LFN bf16 adj_trunc(bf16 x) { return bf16_from_f32(::truncf(bf16_to_f32(x))); }

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
  WP_LFN void adj_add(LT, RT, L&, R&, OT) {}                                         \
  WP_LFN void adj_sub(LT, RT, L&, R&, OT) {}                                         \
  WP_LFN void adj_mul(LT, RT, L&, R&, OT) {}                                         \
  WP_LFN void adj_div(LT, RT, L&, R&, OT) {}                                         \
  WP_LFN void adj_rem(LT, RT, L&, R&, OT) {}
#define WP_ADJ_NOOP_INT(T)          \
  WP_ADJ_NOOP_BIN(T, T, T, T, T)    \
  WP_LFN void adj_neg(T, T&, T) {}
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
  WP_LFN void adj_neg(const V&, V&, const V&) {}
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
  WP_LFN void adj_add(S a, S b, S& adj_a, S& adj_b, S adj_ret) { detail::l_add()(a, b, adj_a, adj_b, adj_ret); } \
  WP_LFN void adj_sub(S a, S b, S& adj_a, S& adj_b, S adj_ret) { detail::l_sub()(a, b, adj_a, adj_b, adj_ret); } \
  WP_LFN void adj_mul(S a, S b, S& adj_a, S& adj_b, S adj_ret) { detail::l_mul()(a, b, adj_a, adj_b, adj_ret); } \
  WP_LFN void adj_div(S a, S b, S& adj_a, S& adj_b, S adj_ret) { detail::l_div()(a, b, adj_a, adj_b, adj_ret); } \
  WP_LFN void adj_rem(S a, S b, S& adj_a, S& adj_b, S adj_ret) {                                      \
    detail::l_rem_trunc()(a, b, adj_a, adj_b, adj_ret);                                              \
  }                                                                                                  \
  WP_LFN void adj_neg(S, S& adj_a, S adj_ret) { adj_a -= adj_ret; }
WP_ADJ_FSCALAR_OPS(f32)
WP_ADJ_FSCALAR_OPS(f64)
WP_ADJ_FSCALAR_OPS(f16)
WP_ADJ_FSCALAR_OPS(bf16)
#undef WP_ADJ_FSCALAR_OPS

// ----- float vectors: lane by lane, with a scalar on either side -----
#define WP_ADJ_FVEC_OP(V, S, NAME, LANE)                                                          \
  WP_LFN void NAME(const V& a, const V& b, V& adj_a, V& adj_b, const V& adj_ret) {                \
    detail::zip_vv(a, b, adj_a, adj_b, adj_ret, LANE());                                         \
  }                                                                                              \
  WP_LFN void NAME(const V& a, S b, V& adj_a, S& adj_b, const V& adj_ret) {                       \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, LANE());                                         \
  }                                                                                              \
  WP_LFN void NAME(S a, const V& b, S& adj_a, V& adj_b, const V& adj_ret) {                       \
    detail::zip_sv(a, b, adj_a, adj_b, adj_ret, LANE());                                         \
  }
#define WP_ADJ_FVEC_OPS(V, S, REM)                                     \
  WP_ADJ_FVEC_OP(V, S, adj_add, detail::l_add)                         \
  WP_ADJ_FVEC_OP(V, S, adj_sub, detail::l_sub)                         \
  WP_ADJ_FVEC_OP(V, S, adj_mul, detail::l_mul)                         \
  WP_ADJ_FVEC_OP(V, S, adj_div, detail::l_div)                         \
  WP_ADJ_FVEC_OP(V, S, adj_rem, REM)                                   \
  WP_LFN void adj_neg(const V&, V& adj_a, const V& adj_ret) { adj_a -= adj_ret; }
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
  WP_LFN void adj_add(const M&, const M&, M& adj_a, M& adj_b, const M& adj_ret) {                 \
    adj_a += adj_ret;                                                                            \
    adj_b += adj_ret;                                                                            \
  }                                                                                              \
  WP_LFN void adj_sub(const M&, const M&, M& adj_a, M& adj_b, const M& adj_ret) {                 \
    adj_a += adj_ret;                                                                            \
    adj_b -= adj_ret;                                                                            \
  }                                                                                              \
  /* A * B: adj_a += g * B^T; adj_b += A^T * g (glam products). */                               \
  WP_LFN void adj_mul(const M& a, const M& b, M& adj_a, M& adj_b, const M& adj_ret) {             \
    adj_a += adj_ret * detail::adj_transpose(b);                                                 \
    adj_b += detail::adj_transpose(a) * adj_ret;                                                 \
  }                                                                                              \
  /* M * v: adj_m.col(j) += g * v[j]; adj_v += M^T * g. */                                       \
  WP_LFN void adj_mul(const M& a, const V& b, M& adj_a, V& adj_b, const V& adj_ret) {             \
    for (int j = 0; j < mat_traits<M>::N; ++j)                                                   \
      mat_traits<M>::at(adj_a, j) += adj_ret * vec_traits<V>::get(b, j);                         \
    adj_b += detail::adj_transpose(a) * adj_ret;                                                 \
  }                                                                                              \
  WP_LFN void adj_mul(const M& a, S b, M& adj_a, S& adj_b, const M& adj_ret) {                    \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, detail::l_mul());                                \
  }                                                                                              \
  WP_LFN void adj_div(const M& a, S b, M& adj_a, S& adj_b, const M& adj_ret) {                    \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, detail::l_div());                                \
  }                                                                                              \
  WP_LFN void adj_mul(S a, const M& b, S& adj_a, M& adj_b, const M& adj_ret) {                    \
    detail::zip_sv(a, b, adj_a, adj_b, adj_ret, detail::l_mul());                                \
  }                                                                                              \
  /* s / M is M / s (glam 0.30's quirk, mirrored by the forward): roles swapped back. */         \
  WP_LFN void adj_div(S a, const M& b, S& adj_a, M& adj_b, const M& adj_ret) {                    \
    detail::zip_vs(b, a, adj_b, adj_a, adj_ret, detail::l_div());                                \
  }                                                                                              \
  WP_LFN void adj_neg(const M&, M& adj_a, const M& adj_ret) { adj_a -= adj_ret; }
WP_ADJ_MAT_OPS(Mat2, Vec2, f32)
WP_ADJ_MAT_OPS(Mat3, Vec3, f32)
WP_ADJ_MAT_OPS(Mat4, Vec4, f32)
WP_ADJ_MAT_OPS(DMat2, DVec2, f64)
WP_ADJ_MAT_OPS(DMat3, DVec3, f64)
WP_ADJ_MAT_OPS(DMat4, DVec4, f64)
#undef WP_ADJ_MAT_OPS

// ----- quaternions -----
#define WP_ADJ_QUAT_OPS(Q, V3, S)                                                                \
  WP_LFN void adj_add(const Q&, const Q&, Q& adj_a, Q& adj_b, const Q& adj_ret) {                 \
    adj_a += adj_ret;                                                                            \
    adj_b += adj_ret;                                                                            \
  }                                                                                              \
  WP_LFN void adj_sub(const Q&, const Q&, Q& adj_a, Q& adj_b, const Q& adj_ret) {                 \
    adj_a += adj_ret;                                                                            \
    adj_b -= adj_ret;                                                                            \
  }                                                                                              \
  /* p * q (Hamilton): the transpose of the bilinear map in each argument. */                    \
  WP_LFN void adj_mul(const Q& a, const Q& b, Q& adj_a, Q& adj_b, const Q& adj_ret) {             \
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
  WP_LFN void adj_mul(const Q& a, const V3& v, Q& adj_a, V3& adj_b, const V3& adj_ret) {          \
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
  WP_LFN void adj_mul(const Q& a, S b, Q& adj_a, S& adj_b, const Q& adj_ret) {                    \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, detail::l_mul());                                \
  }                                                                                              \
  WP_LFN void adj_div(const Q& a, S b, Q& adj_a, S& adj_b, const Q& adj_ret) {                    \
    detail::zip_vs(a, b, adj_a, adj_b, adj_ret, detail::l_div());                                \
  }                                                                                              \
  WP_LFN void adj_neg(const Q&, Q& adj_a, const Q& adj_ret) { adj_a -= adj_ret; }
WP_ADJ_QUAT_OPS(Quat, Vec3, f32)
WP_ADJ_QUAT_OPS(DQuat, DVec3, f64)
#undef WP_ADJ_QUAT_OPS
// ------------------------------------------------------------------------------------------
// Casts (warp-core/src/adjoint/cast.rs)
// ------------------------------------------------------------------------------------------

/// Adjoint of `x as To` for the scalar types: between floats (either way, or to the same type)
/// `adj_from += adj_to as From`, rounded as the forward cast rounds (`cast`: f16 and bf16
/// have no C++ conversion to each other); a no-op when either side is an integer or bool.
template <typename From, typename To>
WP_FN void adj_cast(From& adj_from, To adj_to) {
  static_assert(detail::adj_is_scalar<From>::value && detail::adj_is_scalar<To>::value,
                "adj_cast: scalar types only");
  if constexpr (num<From>::is_float && num<To>::is_float) adj_from += cast<From>(adj_to);
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
/// A struct's array field (`[f32; 4]`): element by element.
template <typename T, int N>
WP_FN void grad_add_p(local_array_t<T, N>* p, const local_array_t<T, N>& v) {
  for (int i = 0; i < N; ++i) grad_add_p(&p->data[i], v.data[i]);
}
template <typename T, int N>
WP_FN void grad_accum_idx(const array_t<T, N>& g, const i64* idx, const T& v, ctx_t* ctx) {
  if (g.data == nullptr) return;
  if (check_idx(g, idx, ctx)) grad_add_p(elem_ptr_unchecked_idx(g, idx), v);
}
template <typename T, int N>
WP_FN T grad_take_idx(const array_t<T, N>& g, const i64* idx, const T& zero, ctx_t* ctx) {
  if (g.data == nullptr) return zero;
  if (!check_idx(g, idx, ctx)) return T{};
  T* p = elem_ptr_unchecked_idx(g, idx);
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

/// Tuples (`tuple_t`, wp_core.h): zero and accumulation element by element, for 2 to 7
/// elements.
template <typename A, typename B>
WP_FN tuple_t<A, B> zero_like(const tuple_t<A, B>& t) {
  return tuple_t<A, B>{zero_like(t.f0), zero_like(t.f1)};
}
template <typename A, typename B>
WP_FN void adj_accum(tuple_t<A, B>& a, const tuple_t<A, B>& v) {
  adj_accum(a.f0, v.f0);
  adj_accum(a.f1, v.f1);
}
template <typename A, typename B, typename C>
WP_FN tuple_t<A, B, C> zero_like(const tuple_t<A, B, C>& t) {
  return tuple_t<A, B, C>{zero_like(t.f0), zero_like(t.f1), zero_like(t.f2)};
}
template <typename A, typename B, typename C>
WP_FN void adj_accum(tuple_t<A, B, C>& a, const tuple_t<A, B, C>& v) {
  adj_accum(a.f0, v.f0);
  adj_accum(a.f1, v.f1);
  adj_accum(a.f2, v.f2);
}
template <typename A, typename B, typename C, typename D>
WP_FN tuple_t<A, B, C, D> zero_like(const tuple_t<A, B, C, D>& t) {
  return tuple_t<A, B, C, D>{zero_like(t.f0), zero_like(t.f1), zero_like(t.f2), zero_like(t.f3)};
}
template <typename A, typename B, typename C, typename D>
WP_FN void adj_accum(tuple_t<A, B, C, D>& a, const tuple_t<A, B, C, D>& v) {
  adj_accum(a.f0, v.f0);
  adj_accum(a.f1, v.f1);
  adj_accum(a.f2, v.f2);
  adj_accum(a.f3, v.f3);
}
template <typename A, typename B, typename C, typename D, typename E>
WP_FN tuple_t<A, B, C, D, E> zero_like(const tuple_t<A, B, C, D, E>& t) {
  return tuple_t<A, B, C, D, E>{zero_like(t.f0), zero_like(t.f1), zero_like(t.f2), zero_like(t.f3), zero_like(t.f4)};
}
template <typename A, typename B, typename C, typename D, typename E>
WP_FN void adj_accum(tuple_t<A, B, C, D, E>& a, const tuple_t<A, B, C, D, E>& v) {
  adj_accum(a.f0, v.f0);
  adj_accum(a.f1, v.f1);
  adj_accum(a.f2, v.f2);
  adj_accum(a.f3, v.f3);
  adj_accum(a.f4, v.f4);
}
template <typename A, typename B, typename C, typename D, typename E, typename F>
WP_FN tuple_t<A, B, C, D, E, F> zero_like(const tuple_t<A, B, C, D, E, F>& t) {
  return tuple_t<A, B, C, D, E, F>{zero_like(t.f0), zero_like(t.f1), zero_like(t.f2), zero_like(t.f3), zero_like(t.f4), zero_like(t.f5)};
}
template <typename A, typename B, typename C, typename D, typename E, typename F>
WP_FN void adj_accum(tuple_t<A, B, C, D, E, F>& a, const tuple_t<A, B, C, D, E, F>& v) {
  adj_accum(a.f0, v.f0);
  adj_accum(a.f1, v.f1);
  adj_accum(a.f2, v.f2);
  adj_accum(a.f3, v.f3);
  adj_accum(a.f4, v.f4);
  adj_accum(a.f5, v.f5);
}
template <typename A, typename B, typename C, typename D, typename E, typename F, typename G>
WP_FN tuple_t<A, B, C, D, E, F, G> zero_like(const tuple_t<A, B, C, D, E, F, G>& t) {
  return tuple_t<A, B, C, D, E, F, G>{zero_like(t.f0), zero_like(t.f1), zero_like(t.f2), zero_like(t.f3), zero_like(t.f4), zero_like(t.f5), zero_like(t.f6)};
}
template <typename A, typename B, typename C, typename D, typename E, typename F, typename G>
WP_FN void adj_accum(tuple_t<A, B, C, D, E, F, G>& a, const tuple_t<A, B, C, D, E, F, G>& v) {
  adj_accum(a.f0, v.f0);
  adj_accum(a.f1, v.f1);
  adj_accum(a.f2, v.f2);
  adj_accum(a.f3, v.f3);
  adj_accum(a.f4, v.f4);
  adj_accum(a.f5, v.f5);
  adj_accum(a.f6, v.f6);
}

/// A unit value (`unit_t`, wp_core.h) carries no gradient.
WP_LFN unit_t zero_like(const unit_t&) { return unit_t{}; }
WP_LFN void adj_accum(unit_t&, const unit_t&) {}
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

WP_LFN adstack_t adstack_new(char* buf, i32 cap) {
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
WP_LFN void copy_bytes(char* dst, const char* src, int n) {
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

/// `g[idx] += v` without a bounds check: only at an index known to be in bounds (thread-index
/// accesses of a launch whose arrays cover the grid). No other thread of this launch touches
/// the element. `alone` (the launch's LAUNCH_ALONE): no other launch runs meanwhile either, so
/// the add is a plain load, add and store. Otherwise a launch on another stream may add to the
/// same element (two tapes' backward passes sharing a parameter array), and the add is atomic
/// per float component like `grad_accum`'s. (The atomic add made the particle benchmark's
/// backward pass 1.4 times slower than the plain one on an H100.)
template <typename T, int N>
WP_FN void grad_accum_own_idx(const array_t<T, N>& g, const i64* idx, const T& v, bool alone) {
  if (g.data == nullptr) return;
  T* p = detail::elem_ptr_unchecked_idx(g, idx);
  if (alone) {
    adj_accum(*p, v);
    return;
  }
  // Unqualified, as in `grad_accum_idx`: a user struct's `grad_add_p` (made with the struct's
  // definition, in the global namespace) is found by argument-dependent lookup.
  using detail::grad_add_p;
  grad_add_p(p, v);
}
template <typename T>
WP_FN void grad_accum_own(const array_t<T, 1>& g, i64 i0, const typename identity<T>::type& v,
                          bool alone) {
  const i64 idx[1] = {i0};
  grad_accum_own_idx(g, idx, v, alone);
}
template <typename T>
WP_FN void grad_accum_own(const array_t<T, 2>& g, i64 i0, i64 i1,
                          const typename identity<T>::type& v, bool alone) {
  const i64 idx[2] = {i0, i1};
  grad_accum_own_idx(g, idx, v, alone);
}
template <typename T>
WP_FN void grad_accum_own(const array_t<T, 3>& g, i64 i0, i64 i1, i64 i2,
                          const typename identity<T>::type& v, bool alone) {
  const i64 idx[3] = {i0, i1, i2};
  grad_accum_own_idx(g, idx, v, alone);
}
template <typename T>
WP_FN void grad_accum_own(const array_t<T, 4>& g, i64 i0, i64 i1, i64 i2, i64 i3,
                          const typename identity<T>::type& v, bool alone) {
  const i64 idx[4] = {i0, i1, i2, i3};
  grad_accum_own_idx(g, idx, v, alone);
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

}  // namespace wp

// wp_adjoint_builtins.h: adjoints of the "scalar" and "vector" sections (min, max, clamp, the
// float functions, lerp (of every type but transforms), dot, length, normalize, cross).
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions. An adjoint
// translation unit includes wp_adjoint_core.h and the adjoint headers of the builtin-table
// sections its kernel uses (warp_cuda::ADJOINT_SECTIONS), so NVRTC parses no more than it
// needs.
#pragma once
#include "wp_adjoint_core.h"
#include "wp_scalar.h"
#include "wp_vector.h"

namespace wp {

// ------------------------------------------------------------------------------------------
// Builtins (warp-core/src/adjoint/builtins.rs)
// ------------------------------------------------------------------------------------------

// ----- min, max, clamp -----
// (T: the type; CT: the type as passed.)
#define WP_ADJ_NOOP_MINMAX(T, CT)                          \
  WP_LFN void adj_min(CT, CT, T&, T&, CT) {}                \
  WP_LFN void adj_max(CT, CT, T&, T&, CT) {}                \
  WP_LFN void adj_clamp(CT, CT, CT, T&, T&, T&, CT) {}
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
  WP_LFN void adj_min(CT a, CT b, T& adj_a, T& adj_b, CT adj_ret) { MIN_BODY; }             \
  WP_LFN void adj_max(CT a, CT b, T& adj_a, T& adj_b, CT adj_ret) { MAX_BODY; }             \
  WP_LFN void adj_clamp(CT x, CT lo, CT hi, T& adj_x, T& adj_lo, T& adj_hi, CT adj_ret) {   \
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
WP_ADJ_FMINMAX_S(bf16)
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
  WP_LFN void adj_abs(CT, T&, CT) {}         \
  WP_LFN void adj_sign(CT, T&, CT) {}
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
  WP_LFN void adj_abs(S x, S& adj_x, S adj_ret) { detail::l_abs(x, adj_x, adj_ret); }  \
  WP_LFN void adj_sign(S, S&, S) {}                                                    \
  WP_LFN void adj_floor(S, S&, S) {}                                                   \
  WP_LFN void adj_ceil(S, S&, S) {}
WP_ADJ_FSCALAR_SIGNED(f32)
WP_ADJ_FSCALAR_SIGNED(f64)
WP_ADJ_FSCALAR_SIGNED(f16)
WP_ADJ_FSCALAR_SIGNED(bf16)
#undef WP_ADJ_FSCALAR_SIGNED
#define WP_ADJ_FVEC_SIGNED(V)                                                              \
  WP_LFN void adj_abs(const V& x, V& adj_x, const V& adj_ret) {                             \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                             \
      detail::l_abs(vec_traits<V>::get(x, i), vec_traits<V>::at(adj_x, i), vec_traits<V>::get(adj_ret, i)); \
  }                                                                                        \
  WP_LFN void adj_sign(const V&, V&, const V&) {}
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
  WP_LFN void adj_sqrt(S x, S& adj_x, S adj_ret) {                                            \
    const S half = (S)1 / ((S)1 + (S)1);                                                     \
    adj_x += adj_ret * (half / wp::sqrt(x));                                                 \
  }                                                                                          \
  WP_LFN void adj_exp(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::exp(x); }            \
  WP_LFN void adj_log(S x, S& adj_x, S adj_ret) { adj_x += adj_ret / x; }                     \
  WP_LFN void adj_sin(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::cos(x); }            \
  WP_LFN void adj_cos(S x, S& adj_x, S adj_ret) { adj_x -= adj_ret * wp::sin(x); }            \
  WP_LFN void adj_tan(S x, S& adj_x, S adj_ret) {                                             \
    const S c = wp::cos(x);                                                                  \
    adj_x += adj_ret / (c * c);                                                              \
  }                                                                                          \
  /* atan2(y, x): d = x*x + y*y; nothing at the origin. */                                   \
  WP_LFN void adj_atan2(S y, S x, S& adj_y, S& adj_x, S adj_ret) {                            \
    if (x == (S)0 && y == (S)0) return;                                                      \
    const S d = x * x + y * y;                                                               \
    adj_y += adj_ret * (x / d);                                                              \
    adj_x -= adj_ret * (y / d);                                                              \
  }                                                                                          \
  /* pow(x, y): d/dx unless y == 0; d/dy only when x > 0. */                                 \
  WP_LFN void adj_pow(S x, S y, S& adj_x, S& adj_y, S adj_ret) {                              \
    if (y != (S)0) adj_x += adj_ret * (y * wp::pow(x, y - (S)1));                            \
    if (x > (S)0) adj_y += adj_ret * (wp::pow(x, y) * wp::log(x));                           \
  }                                                                                          \
  WP_LFN void adj_lerp(S a, S b, S t, S& adj_a, S& adj_b, S& adj_t, S adj_ret) {              \
    detail::l_lerp(a, b, t, adj_a, adj_b, adj_t, adj_ret);                                   \
  }
WP_ADJ_FSCALAR_FNS(f32)
WP_ADJ_FSCALAR_FNS(f64)
WP_ADJ_FSCALAR_FNS(f16)
WP_ADJ_FSCALAR_FNS(bf16)
#undef WP_ADJ_FSCALAR_FNS

// ----- more float scalar functions (warp-core/src/adjoint/builtins.rs, same order) -----
// LN2, LN10, TWO_SQRTPI (2/sqrt(pi)), SQRTPI_2 (sqrt(pi)/2): Rust's constants, by bit pattern.
#define WP_ADJ_FSCALAR_MORE(S, LN2, LN10, TWO_SQRTPI, SQRTPI_2)                               \
  /* asin/acos: d = sqrt(1 - x*x); only when d > 0 (the clamp is flat at |x| >= 1). */       \
  WP_LFN void adj_asin(S x, S& adj_x, S adj_ret) {                                            \
    const S d = wp::sqrt((S)1 - x * x);                                                      \
    if (d > (S)0) adj_x += adj_ret / d;                                                      \
  }                                                                                          \
  WP_LFN void adj_acos(S x, S& adj_x, S adj_ret) {                                            \
    const S d = wp::sqrt((S)1 - x * x);                                                      \
    if (d > (S)0) adj_x -= adj_ret / d;                                                      \
  }                                                                                          \
  WP_LFN void adj_atan(S x, S& adj_x, S adj_ret) { adj_x += adj_ret / (x * x + (S)1); }       \
  WP_LFN void adj_sinh(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::cosh(x); }          \
  WP_LFN void adj_cosh(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::sinh(x); }          \
  WP_LFN void adj_tanh(S x, S& adj_x, S adj_ret) {                                            \
    const S t = wp::tanh(x);                                                                 \
    adj_x += adj_ret * ((S)1 - t * t);                                                       \
  }                                                                                          \
  WP_LFN void adj_exp2(S x, S& adj_x, S adj_ret) { adj_x += adj_ret * (wp::exp2(x) * (LN2)); } \
  WP_LFN void adj_log2(S x, S& adj_x, S adj_ret) { adj_x += adj_ret / (x * (LN2)); }          \
  WP_LFN void adj_log10(S x, S& adj_x, S adj_ret) { adj_x += adj_ret / (x * (LN10)); }        \
  WP_LFN void adj_cbrt(S x, S& adj_x, S adj_ret) {                                            \
    const S c = wp::cbrt(x);                                                                 \
    const S three = (S)1 + (S)1 + (S)1;                                                      \
    adj_x += adj_ret / (three * (c * c));                                                    \
  }                                                                                          \
  WP_LFN void adj_erf(S x, S& adj_x, S adj_ret) {                                             \
    adj_x += adj_ret * ((TWO_SQRTPI) * wp::exp(-(x * x)));                                   \
  }                                                                                          \
  WP_LFN void adj_erfc(S x, S& adj_x, S adj_ret) {                                            \
    adj_x -= adj_ret * ((TWO_SQRTPI) * wp::exp(-(x * x)));                                   \
  }                                                                                          \
  WP_LFN void adj_erfinv(S x, S& adj_x, S adj_ret) {                                          \
    const S r = wp::erfinv(x);                                                               \
    adj_x += adj_ret * ((SQRTPI_2) * wp::exp(r * r));                                        \
  }                                                                                          \
  WP_LFN void adj_erfcinv(S x, S& adj_x, S adj_ret) {                                         \
    const S r = wp::erfcinv(x);                                                              \
    adj_x -= adj_ret * ((SQRTPI_2) * wp::exp(r * r));                                        \
  }                                                                                          \
  WP_LFN void adj_round(S, S&, S) {}                                                          \
  WP_LFN void adj_rint(S, S&, S) {}                                                           \
  WP_LFN void adj_trunc(S, S&, S) {}                                                          \
  WP_LFN void adj_step(S, S&, S) {}                                                           \
  /* frac = x - trunc(x): slope 1. */                                                        \
  WP_LFN void adj_frac(S, S& adj_x, S adj_ret) { adj_x += adj_ret; }                          \
  WP_LFN void adj_degrees(S, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::degrees((S)1); }   \
  WP_LFN void adj_radians(S, S& adj_x, S adj_ret) { adj_x += adj_ret * wp::radians((S)1); }   \
  /* smoothstep: d = e1 - e0, t = (x - e0) / d; only when 0 < t < 1. */                     \
  WP_LFN void adj_smoothstep(S e0, S e1, S x, S& adj_e0, S& adj_e1, S& adj_x, S adj_ret) {    \
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
// bf16 likewise (warp-core/src/adjoint/bfloat16.rs).
WP_ADJ_FSCALAR_MORE(bf16, bf16_from_bits(0x3F31u), bf16_from_bits(0x4013u), bf16_from_bits(0x3F90u),
                    bf16_from_bits(0x3F63u))
#undef WP_ADJ_FSCALAR_MORE

// step on integers: not differentiable.
#define WP_ADJ_NOOP_STEP(T) WP_LFN void adj_step(T, T&, T) {}
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
  WP_LFN void adj_lerp(const V& a, const V& b, S t, V& adj_a, V& adj_b, S& adj_t, const V& adj_ret) { \
    typedef vec_traits<V> T;                                                                      \
    for (int i = 0; i < T::N; ++i)                                                                \
      detail::l_lerp(T::get(a, i), T::get(b, i), t, T::at(adj_a, i), T::at(adj_b, i), adj_t,      \
                     T::get(adj_ret, i));                                                         \
  }                                                                                               \
  /* dot: adj_a[i] += g * b[i]; adj_b[i] += g * a[i]. */                                          \
  WP_LFN void adj_dot(const V& a, const V& b, V& adj_a, V& adj_b, S adj_ret) {                     \
    typedef vec_traits<V> T;                                                                      \
    for (int i = 0; i < T::N; ++i) {                                                              \
      T::at(adj_a, i) += adj_ret * T::get(b, i);                                                  \
      T::at(adj_b, i) += adj_ret * T::get(a, i);                                                  \
    }                                                                                             \
  }                                                                                               \
  /* length: adj_v[i] += w[i] * (g / l) when l > 0, for the rescaled w = k v, l = |w| */        \
  /* (detail::norm_scaled, wp_vector.h). */                                                     \
  WP_LFN void adj_length(const V& v, V& adj_v, S adj_ret) {                                        \
    typedef vec_traits<V> T;                                                                      \
    V w;                                                                                          \
    S l, k, inv;                                                                                    \
    detail::norm_scaled(v, [](const V& a) { return wp::dot(a, a); }, w, l, k, inv);                \
    if (l > (S)0) {                                                                               \
      const S gl = adj_ret / l;                                                                   \
      for (int i = 0; i < T::N; ++i) T::at(adj_v, i) += T::get(w, i) * gl;                        \
    }                                                                                             \
  }                                                                                               \
  /* normalize: n = w / l, d = dot(n, g); adj_v[i] += ((g[i] - n[i] * d) / l) * k when l > 0. */ \
  WP_LFN void adj_normalize(const V& v, V& adj_v, const V& adj_ret) {                              \
    typedef vec_traits<V> T;                                                                      \
    V w;                                                                                          \
    S l, k, inv;                                                                                    \
    detail::norm_scaled(v, [](const V& a) { return wp::dot(a, a); }, w, l, k, inv);                \
    if (l > (S)0) {                                                                               \
      V n;                                                                                        \
      for (int i = 0; i < T::N; ++i) T::at(n, i) = T::get(w, i) / l;                              \
      const S d = wp::dot(n, adj_ret);                                                            \
      for (int i = 0; i < T::N; ++i)                                                              \
        T::at(adj_v, i) += ((T::get(adj_ret, i) - T::get(n, i) * d) / l) * k;                    \
    }                                                                                             \
  }
WP_ADJ_FVEC_FNS(Vec2, f32)
WP_ADJ_FVEC_FNS(Vec3, f32)
WP_ADJ_FVEC_FNS(Vec4, f32)
WP_ADJ_FVEC_FNS(DVec2, f64)
WP_ADJ_FVEC_FNS(DVec3, f64)
WP_ADJ_FVEC_FNS(DVec4, f64)
#undef WP_ADJ_FVEC_FNS

// ----- lerp of matrices, quaternions, spatial vectors and matrices: the lane rule in -----
// ----- vec_traits' lane order (wp_scalar.h's forward), adj_t collecting every lane    -----
#define WP_ADJ_LANES_LERP(T, S)                                                                  \
  WP_LFN void adj_lerp(const T& a, const T& b, S t, T& adj_a, T& adj_b, S& adj_t, const T& g) {   \
    typedef vec_traits<T> L;                                                                     \
    for (int i = 0; i < L::N; ++i)                                                               \
      detail::l_lerp(L::get(a, i), L::get(b, i), t, L::at(adj_a, i), L::at(adj_b, i), adj_t,     \
                     L::get(g, i));                                                              \
  }
WP_ADJ_LANES_LERP(Mat2, f32)
WP_ADJ_LANES_LERP(Mat3, f32)
WP_ADJ_LANES_LERP(Mat4, f32)
WP_ADJ_LANES_LERP(DMat2, f64)
WP_ADJ_LANES_LERP(DMat3, f64)
WP_ADJ_LANES_LERP(DMat4, f64)
WP_ADJ_LANES_LERP(Quat, f32)
WP_ADJ_LANES_LERP(DQuat, f64)
WP_ADJ_LANES_LERP(SpatialVector, f32)
WP_ADJ_LANES_LERP(SpatialMatrix, f32)
WP_ADJ_LANES_LERP(DSpatialVector, f64)
WP_ADJ_LANES_LERP(DSpatialMatrix, f64)
#undef WP_ADJ_LANES_LERP

#define WP_ADJ_NOOP_DOT(V, S) \
  WP_LFN void adj_dot(const V&, const V&, V&, V&, S) {}
WP_ADJ_NOOP_DOT(IVec2, i32)
WP_ADJ_NOOP_DOT(IVec3, i32)
WP_ADJ_NOOP_DOT(IVec4, i32)
WP_ADJ_NOOP_DOT(UVec2, u32)
WP_ADJ_NOOP_DOT(UVec3, u32)
WP_ADJ_NOOP_DOT(UVec4, u32)
#undef WP_ADJ_NOOP_DOT

// ----- cross: adj_a += b x g; adj_b += g x a (the builtin cross) -----
#define WP_ADJ_CROSS(V)                                                              \
  WP_LFN void adj_cross(const V& a, const V& b, V& adj_a, V& adj_b, const V& adj_ret) { \
    adj_a += wp::cross(b, adj_ret);                                                  \
    adj_b += wp::cross(adj_ret, a);                                                  \
  }
WP_ADJ_CROSS(Vec3)
WP_ADJ_CROSS(DVec3)
#undef WP_ADJ_CROSS
WP_LFN void adj_cross(const IVec3&, const IVec3&, IVec3&, IVec3&, const IVec3&) {}

}  // namespace wp

// wp_scalar.h: section "scalar" of the builtin table (warp-core/src/builtins/math.rs).
//
//   min, max, clamp   all integer and float scalars, and every glam vector (componentwise);
//                     floats are IEEE fmin/fmax: a NaN operand loses to the other.
//   abs, sign         signed integers (abs wraps: abs(MIN) == MIN), f32, f64, float vectors,
//                     IVec2-4; sign(x) = -1 if x < 0 else +1 (sign(0) = sign(-0.0) = sign(NaN) = 1).
//   floor ceil sqrt exp log sin cos tan atan2 pow     f32 (the ...f functions), f64.
//   lerp(a, b, t)     a * (1 - t) + b * t; f32, f64, float vectors with a scalar t; square
//                     matrices, quaternions, spatial vectors and matrices lane by lane.
//   asin acos atan sinh cosh tanh exp2 log2 log10 cbrt erf erfc erfinv erfcinv round rint
//   trunc frac degrees radians smoothstep                f32, f64;
//   step              every integer and float scalar; isfinite isnan isinf   f32, f64, float
//                     vectors (all finite / any NaN / any infinite), returning bool.
//   Semantics as warp-core/src/builtins/math.rs: asin/acos clamp to [-1, 1] (NaN stays NaN);
//   round is half away from zero, rint half to even, frac(x) = x - trunc(x); step(x) = 1 if
//   x < 0 else 0; smoothstep clamps t = (x - e0) / (e1 - e0) to [0, 1] (so e0 == e1 gives 0
//   for x <= e0 and 1 above); degrees/radians multiply by 180/pi and pi/180 rounded to the
//   type (Rust's to_degrees/to_radians; bit patterns below). `mod` has no function here: the
//   macro lowers it to the `%` operator.
//
// erf family: on the GPU, CUDA's erff/erfcf/erfinvf/erfcinvf and the double versions. glibc
// has no erfinv, so on the host these run `detail::special`, a line-for-line transcription of
// warp-core/src/builtins/special.rs (same operations in the same order, libm's exp/log/sqrt and
// fma), which therefore matches the CPU backend bit for bit on the host.
//
// f16 (at the end): each builtin is the f32 one on the widened arguments, rounded once.
//
// Accuracy: floor, ceil and sqrt are exact on both backends. The transcendental functions
// (exp, log, sin, cos, tan, atan2, pow, asin, acos, atan, sinh, cosh, tanh, exp2, log2,
// log10, cbrt) call the platform's libm on the CPU (glibc, through Rust's std) and CUDA's
// math library on the GPU; CUDA documents errors of 1 to 4 ulp for them (e.g. sinf 2, tanf 4,
// powf 4 ulp), so the backends may differ in the last bits there. round, rint, trunc, frac,
// degrees, radians, step and the classification functions are exact on both.
#pragma once
#include "wp_core.h"

namespace wp {

// ------------------------------------------------------------------------------------------
// min / max / clamp
// ------------------------------------------------------------------------------------------

#define WP_INT_MINMAX(T)                                           \
  WP_LFN T min(T a, T b) { return b < a ? b : a; }                  \
  WP_LFN T max(T a, T b) { return a < b ? b : a; }                  \
  WP_LFN T clamp(T x, T lo, T hi) { return min(max(x, lo), hi); }
WP_INT_MINMAX(i8)
WP_INT_MINMAX(i16)
WP_INT_MINMAX(i32)
WP_INT_MINMAX(i64)
WP_INT_MINMAX(u8)
WP_INT_MINMAX(u16)
WP_INT_MINMAX(u32)
WP_INT_MINMAX(u64)
#undef WP_INT_MINMAX

WP_LFN f32 min(f32 a, f32 b) { return ::fminf(a, b); }
WP_LFN f32 max(f32 a, f32 b) { return ::fmaxf(a, b); }
WP_LFN f32 clamp(f32 x, f32 lo, f32 hi) { return min(max(x, lo), hi); }
WP_LFN f64 min(f64 a, f64 b) { return ::fmin(a, b); }
WP_LFN f64 max(f64 a, f64 b) { return ::fmax(a, b); }
WP_LFN f64 clamp(f64 x, f64 lo, f64 hi) { return min(max(x, lo), hi); }

#define WP_VEC_MINMAX(V, S)                                                                   \
  WP_LFN V min(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return min(x, y); }); } \
  WP_LFN V max(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return max(x, y); }); } \
  WP_LFN V clamp(const V& x, const V& lo, const V& hi) { return min(max(x, lo), hi); }
WP_VEC_MINMAX(Vec2, f32)
WP_VEC_MINMAX(Vec3, f32)
WP_VEC_MINMAX(Vec4, f32)
WP_VEC_MINMAX(DVec2, f64)
WP_VEC_MINMAX(DVec3, f64)
WP_VEC_MINMAX(DVec4, f64)
WP_VEC_MINMAX(IVec2, i32)
WP_VEC_MINMAX(IVec3, i32)
WP_VEC_MINMAX(IVec4, i32)
WP_VEC_MINMAX(UVec2, u32)
WP_VEC_MINMAX(UVec3, u32)
WP_VEC_MINMAX(UVec4, u32)
#undef WP_VEC_MINMAX

// ------------------------------------------------------------------------------------------
// abs / sign
// ------------------------------------------------------------------------------------------

#define WP_INT_SIGNED(T)                                         \
  WP_LFN T abs(T x) { return x < (T)0 ? w_neg(x) : x; }           \
  WP_LFN T sign(T x) { return x < (T)0 ? (T)-1 : (T)1; }
WP_INT_SIGNED(i8)
WP_INT_SIGNED(i16)
WP_INT_SIGNED(i32)
WP_INT_SIGNED(i64)
#undef WP_INT_SIGNED

WP_LFN f32 abs(f32 x) { return ::fabsf(x); }
WP_LFN f32 sign(f32 x) { return x < 0.0f ? -1.0f : 1.0f; }
WP_LFN f64 abs(f64 x) { return ::fabs(x); }
WP_LFN f64 sign(f64 x) { return x < 0.0 ? -1.0 : 1.0; }

#define WP_VEC_SIGNED(V, S)                                                                \
  WP_LFN V abs(const V& a) { return detail::vmap(a, [](S x) { return abs(x); }); }          \
  WP_LFN V sign(const V& a) { return detail::vmap(a, [](S x) { return sign(x); }); }
WP_VEC_SIGNED(Vec2, f32)
WP_VEC_SIGNED(Vec3, f32)
WP_VEC_SIGNED(Vec4, f32)
WP_VEC_SIGNED(DVec2, f64)
WP_VEC_SIGNED(DVec3, f64)
WP_VEC_SIGNED(DVec4, f64)
WP_VEC_SIGNED(IVec2, i32)
WP_VEC_SIGNED(IVec3, i32)
WP_VEC_SIGNED(IVec4, i32)
#undef WP_VEC_SIGNED

// ------------------------------------------------------------------------------------------
// Float functions (f32 stays f32: the ...f variants, never a silent double)
// ------------------------------------------------------------------------------------------

WP_LFN f32 floor(f32 x) { return ::floorf(x); }
WP_LFN f32 ceil(f32 x) { return ::ceilf(x); }
WP_LFN f32 sqrt(f32 x) { return ::sqrtf(x); }
WP_LFN f32 exp(f32 x) { return ::expf(x); }
WP_LFN f32 log(f32 x) { return ::logf(x); }
WP_LFN f32 sin(f32 x) { return ::sinf(x); }
WP_LFN f32 cos(f32 x) { return ::cosf(x); }
WP_LFN f32 tan(f32 x) { return ::tanf(x); }
WP_LFN f32 atan2(f32 y, f32 x) { return ::atan2f(y, x); }
WP_LFN f32 pow(f32 x, f32 y) { return ::powf(x, y); }

WP_LFN f64 floor(f64 x) { return ::floor(x); }
WP_LFN f64 ceil(f64 x) { return ::ceil(x); }
WP_LFN f64 sqrt(f64 x) { return ::sqrt(x); }
WP_LFN f64 exp(f64 x) { return ::exp(x); }
WP_LFN f64 log(f64 x) { return ::log(x); }
WP_LFN f64 sin(f64 x) { return ::sin(x); }
WP_LFN f64 cos(f64 x) { return ::cos(x); }
WP_LFN f64 tan(f64 x) { return ::tan(x); }
WP_LFN f64 atan2(f64 y, f64 x) { return ::atan2(y, x); }
WP_LFN f64 pow(f64 x, f64 y) { return ::pow(x, y); }

// ------------------------------------------------------------------------------------------
// More float functions (see the top for their semantics)
// ------------------------------------------------------------------------------------------

namespace detail {
/// x clamped to [-1, 1] by comparisons (NaN passes through).
template <typename S>
WP_FN S unit_clamp(S x) { return x < (S)-1 ? (S)-1 : (x > (S)1 ? (S)1 : x); }
}  // namespace detail

WP_LFN f32 asin(f32 x) { return ::asinf(detail::unit_clamp(x)); }
WP_LFN f32 acos(f32 x) { return ::acosf(detail::unit_clamp(x)); }
WP_LFN f32 atan(f32 x) { return ::atanf(x); }
WP_LFN f32 sinh(f32 x) { return ::sinhf(x); }
WP_LFN f32 cosh(f32 x) { return ::coshf(x); }
WP_LFN f32 tanh(f32 x) { return ::tanhf(x); }
WP_LFN f32 exp2(f32 x) { return ::exp2f(x); }
WP_LFN f32 log2(f32 x) { return ::log2f(x); }
WP_LFN f32 log10(f32 x) { return ::log10f(x); }
WP_LFN f32 cbrt(f32 x) { return ::cbrtf(x); }
WP_LFN f32 round(f32 x) { return ::roundf(x); }
WP_LFN f32 rint(f32 x) { return ::rintf(x); }
WP_LFN f32 trunc(f32 x) { return ::truncf(x); }
WP_LFN f32 frac(f32 x) { return x - ::truncf(x); }
// 180/pi and pi/180 rounded to f32 (Rust's f32::to_degrees / to_radians).
WP_LFN f32 degrees(f32 x) { return x * f32_from_bits(0x42652ee1u); }
WP_LFN f32 radians(f32 x) { return x * f32_from_bits(0x3c8efa35u); }
WP_LFN f32 smoothstep(f32 e0, f32 e1, f32 x) {
  const f32 t = clamp((x - e0) / (e1 - e0), 0.0f, 1.0f);
  return t * t * (3.0f - 2.0f * t);
}

WP_LFN f64 asin(f64 x) { return ::asin(detail::unit_clamp(x)); }
WP_LFN f64 acos(f64 x) { return ::acos(detail::unit_clamp(x)); }
WP_LFN f64 atan(f64 x) { return ::atan(x); }
WP_LFN f64 sinh(f64 x) { return ::sinh(x); }
WP_LFN f64 cosh(f64 x) { return ::cosh(x); }
WP_LFN f64 tanh(f64 x) { return ::tanh(x); }
WP_LFN f64 exp2(f64 x) { return ::exp2(x); }
WP_LFN f64 log2(f64 x) { return ::log2(x); }
WP_LFN f64 log10(f64 x) { return ::log10(x); }
WP_LFN f64 cbrt(f64 x) { return ::cbrt(x); }
WP_LFN f64 round(f64 x) { return ::round(x); }
WP_LFN f64 rint(f64 x) { return ::rint(x); }
WP_LFN f64 trunc(f64 x) { return ::trunc(x); }
WP_LFN f64 frac(f64 x) { return x - ::trunc(x); }
// 180/pi and pi/180 rounded to f64 (Rust's f64::to_degrees / to_radians).
WP_LFN f64 degrees(f64 x) { return x * f64_from_bits(0x404ca5dc1a63c1f8ull); }
WP_LFN f64 radians(f64 x) { return x * f64_from_bits(0x3f91df46a2529d39ull); }
WP_LFN f64 smoothstep(f64 e0, f64 e1, f64 x) {
  const f64 t = clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// ----- step: 1 if x < 0 else 0 (unsigned: always 0) -----
#define WP_STEP_SIGNED(T) \
  WP_LFN T step(T x) { return x < (T)0 ? (T)1 : (T)0; }
#define WP_STEP_UNSIGNED(T) \
  WP_LFN T step(T) { return (T)0; }
WP_STEP_SIGNED(i8)
WP_STEP_SIGNED(i16)
WP_STEP_SIGNED(i32)
WP_STEP_SIGNED(i64)
WP_STEP_SIGNED(f32)
WP_STEP_SIGNED(f64)
WP_STEP_UNSIGNED(u8)
WP_STEP_UNSIGNED(u16)
WP_STEP_UNSIGNED(u32)
WP_STEP_UNSIGNED(u64)
#undef WP_STEP_SIGNED
#undef WP_STEP_UNSIGNED

// ----- isfinite / isnan / isinf (comparisons only: no dependence on <cmath> macros) -----
WP_LFN bool isnan(f32 x) { return x != x; }
WP_LFN bool isinf(f32 x) { return ::fabsf(x) == f32_inf(); }
WP_LFN bool isfinite(f32 x) { return ::fabsf(x) < f32_inf(); }
WP_LFN bool isnan(f64 x) { return x != x; }
WP_LFN bool isinf(f64 x) { return ::fabs(x) == f64_inf(); }
WP_LFN bool isfinite(f64 x) { return ::fabs(x) < f64_inf(); }
#define WP_VEC_CLASSIFY(V)                                                     \
  WP_LFN bool isfinite(const V& v) {                                            \
    bool r = true;                                                             \
    for (int i = 0; i < vec_traits<V>::N; ++i) r = r && isfinite(vec_traits<V>::get(v, i)); \
    return r;                                                                  \
  }                                                                            \
  WP_LFN bool isnan(const V& v) {                                               \
    bool r = false;                                                            \
    for (int i = 0; i < vec_traits<V>::N; ++i) r = r || isnan(vec_traits<V>::get(v, i)); \
    return r;                                                                  \
  }                                                                            \
  WP_LFN bool isinf(const V& v) {                                               \
    bool r = false;                                                            \
    for (int i = 0; i < vec_traits<V>::N; ++i) r = r || isinf(vec_traits<V>::get(v, i)); \
    return r;                                                                  \
  }
WP_VEC_CLASSIFY(Vec2)
WP_VEC_CLASSIFY(Vec3)
WP_VEC_CLASSIFY(Vec4)
WP_VEC_CLASSIFY(DVec2)
WP_VEC_CLASSIFY(DVec3)
WP_VEC_CLASSIFY(DVec4)
#undef WP_VEC_CLASSIFY

// ----- erf, erfc, erfinv, erfcinv -----
#if defined(__CUDACC__)
WP_LFN f32 erf(f32 x) { return ::erff(x); }
WP_LFN f32 erfc(f32 x) { return ::erfcf(x); }
WP_LFN f32 erfinv(f32 x) { return ::erfinvf(x); }
WP_LFN f32 erfcinv(f32 x) { return ::erfcinvf(x); }
WP_LFN f64 erf(f64 x) { return ::erf(x); }
WP_LFN f64 erfc(f64 x) { return ::erfc(x); }
WP_LFN f64 erfinv(f64 x) { return ::erfinv(x); }
WP_LFN f64 erfcinv(f64 x) { return ::erfcinv(x); }
#else
namespace detail {
namespace special {
// warp-core/src/builtins/special.rs, transcribed (see there for the method and accuracy).
constexpr f64 TWO_OVER_SQRT_PI = 1.12837916709551257390;  // core::f64::consts::FRAC_2_SQRT_PI
constexpr f64 SQRT_PI = 1.772453850905516;
constexpr f64 PI = 3.14159265358979323846;
constexpr f64 ERFC_ZERO_AT = 28.0;

inline void square(f64 x, f64& p, f64& e) {
  p = x * x;
  e = std::fma(x, x, -p);
}
inline f64 exp_neg_sq(f64 x) {
  f64 p, e;
  square(x, p, e);
  return std::exp(-p) * (1.0 - e);
}
inline f64 erfc_cf(f64 x) {
  u32 n = (u32)(10.0 + 240.0 / (x * x));
  f64 f = x;
  while (n > 0) {
    f = x + ((f64)n * 0.5) / f;
    n -= 1;
  }
  return f;
}
inline f64 erf_series(f64 x) {
  const f64 two_x2 = 2.0 * (x * x);
  f64 term = x, sum = x;
  u32 n = 1;
  for (;;) {
    term = term * two_x2 / (f64)(2 * n + 1);
    const f64 next = sum + term;
    if (next == sum) break;
    sum = next;
    n += 1;
  }
  return TWO_OVER_SQRT_PI * sum * exp_neg_sq(x);
}
inline f64 erfc_tail(f64 x) {
  if (x >= ERFC_ZERO_AT) return 0.0;
  return exp_neg_sq(x) / (SQRT_PI * erfc_cf(x));
}
inline f64 erf(f64 x) {
  if (x != x) return x;
  if (std::fabs(x) < 1.0) return erf_series(x);
  const f64 r = 1.0 - erfc_tail(std::fabs(x));
  return x < 0.0 ? -r : r;
}
inline f64 erfc(f64 x) {
  if (x != x) return x;
  if (x >= 1.0) return erfc_tail(x);
  if (x > -1.0) return 1.0 - erf_series(x);
  return 2.0 - erfc_tail(-x);
}
inline f64 winitzki(f64 w) {
  const f64 A = 0.147;
  const f64 t = 2.0 / (PI * A) + 0.5 * w;
  return std::sqrt(std::sqrt(t * t - w / A) - t);
}
inline f64 erfinv_central(f64 y) {
  const f64 a = std::fabs(y);
  f64 x = winitzki(std::log((1.0 - a) * (1.0 + a)));
  for (int i = 0; i < 3; ++i) {
    const f64 u = (erf(x) - a) / (TWO_OVER_SQRT_PI * exp_neg_sq(x));
    x -= u / (1.0 + x * u);
  }
  return y < 0.0 ? -x : x;
}
inline f64 erfcinv_tail(f64 z) {
  const f64 lnz = std::log(z);
  f64 x = winitzki(std::log(z * (2.0 - z)));
  for (int i = 0; i < 5; ++i) {
    f64 h, dh;
    if (x >= 1.0) {
      f64 p, e;
      square(x, p, e);
      const f64 f = erfc_cf(x);
      h = -p - e - std::log(SQRT_PI * f) - lnz;
      dh = -2.0 * f;
    } else {
      const f64 c = erfc(x);
      h = std::log(c) - lnz;
      dh = -(TWO_OVER_SQRT_PI * exp_neg_sq(x)) / c;
    }
    x -= h / dh;
  }
  return x;
}
inline f64 erfinv(f64 y) {
  const f64 a = std::fabs(y);
  if (a != a || a > 1.0) return f64_nan();
  if (a == 1.0) return y < 0.0 ? -f64_inf() : f64_inf();
  if (a == 0.0) return y;
  if (a <= 0.5) return erfinv_central(y);
  const f64 x = erfcinv_tail(1.0 - a);
  return y < 0.0 ? -x : x;
}
inline f64 erfcinv(f64 z) {
  if (z != z || !(z >= 0.0 && z <= 2.0)) return f64_nan();
  if (z == 0.0) return f64_inf();
  if (z == 2.0) return -f64_inf();
  if (z < 0.5) return erfcinv_tail(z);
  if (z <= 1.5) {
    const f64 y = 1.0 - z;
    return y == 0.0 ? 0.0 : erfinv_central(y);
  }
  return -erfcinv_tail(2.0 - z);
}
}  // namespace special
}  // namespace detail
WP_LFN f32 erf(f32 x) { return (f32)detail::special::erf((f64)x); }
WP_LFN f32 erfc(f32 x) { return (f32)detail::special::erfc((f64)x); }
WP_LFN f32 erfinv(f32 x) { return (f32)detail::special::erfinv((f64)x); }
WP_LFN f32 erfcinv(f32 x) { return (f32)detail::special::erfcinv((f64)x); }
WP_LFN f64 erf(f64 x) { return detail::special::erf(x); }
WP_LFN f64 erfc(f64 x) { return detail::special::erfc(x); }
WP_LFN f64 erfinv(f64 x) { return detail::special::erfinv(x); }
WP_LFN f64 erfcinv(f64 x) { return detail::special::erfcinv(x); }
#endif

// ------------------------------------------------------------------------------------------
// lerp
// ------------------------------------------------------------------------------------------

WP_LFN f32 lerp(f32 a, f32 b, f32 t) { return a * (1.0f - t) + b * t; }
WP_LFN f64 lerp(f64 a, f64 b, f64 t) { return a * (1.0 - t) + b * t; }

#define WP_VEC_LERP(V, S) \
  WP_LFN V lerp(const V& a, const V& b, S t) { return detail::vzip(a, b, [t](S x, S y) { return lerp(x, y, t); }); }
WP_VEC_LERP(Vec2, f32)
WP_VEC_LERP(Vec3, f32)
WP_VEC_LERP(Vec4, f32)
WP_VEC_LERP(DVec2, f64)
WP_VEC_LERP(DVec3, f64)
WP_VEC_LERP(DVec4, f64)
#undef WP_VEC_LERP

// Square matrices (column-major lanes), quaternions (x, y, z, w; not renormalized, as Warp),
// spatial vectors and matrices (row-major lanes): lane by lane, in vec_traits' order.
#define WP_LANES_LERP(T, S)                                                                 \
  WP_LFN T lerp(const T& a, const T& b, S t) {                                               \
    T r = a;                                                                                \
    for (int i = 0; i < vec_traits<T>::N; ++i)                                              \
      vec_traits<T>::at(r, i) = lerp(vec_traits<T>::get(a, i), vec_traits<T>::get(b, i), t); \
    return r;                                                                               \
  }
WP_LANES_LERP(Mat2, f32)
WP_LANES_LERP(Mat3, f32)
WP_LANES_LERP(Mat4, f32)
WP_LANES_LERP(DMat2, f64)
WP_LANES_LERP(DMat3, f64)
WP_LANES_LERP(DMat4, f64)
WP_LANES_LERP(Quat, f32)
WP_LANES_LERP(DQuat, f64)
WP_LANES_LERP(SpatialVector, f32)
WP_LANES_LERP(SpatialMatrix, f32)
WP_LANES_LERP(DSpatialVector, f64)
WP_LANES_LERP(DSpatialMatrix, f64)
#undef WP_LANES_LERP

// ------------------------------------------------------------------------------------------
// f16: every builtin is its f32 version on the widened arguments, rounded once to f16
// (warp-core/src/float16.rs). Exact where the f32 builtin is (min max clamp abs sign floor
// ceil sqrt round rint trunc frac step); the transcendental ones inherit the f32 functions'
// few-ulp differences between platforms, which rounding to f16 mostly hides (one f16 ulp at
// most).
// ------------------------------------------------------------------------------------------

#define WP_F16_1(NAME) \
  WP_LFN f16 NAME(f16 x) { return f16_from_f32(NAME(f16_to_f32(x))); }
#define WP_F16_2(NAME) \
  WP_LFN f16 NAME(f16 x, f16 y) { return f16_from_f32(NAME(f16_to_f32(x), f16_to_f32(y))); }
#define WP_F16_3(NAME)                                                                  \
  WP_LFN f16 NAME(f16 x, f16 y, f16 z) {                                                 \
    return f16_from_f32(NAME(f16_to_f32(x), f16_to_f32(y), f16_to_f32(z)));             \
  }
WP_F16_2(min)
WP_F16_2(max)
WP_F16_3(clamp)
WP_F16_1(abs)
WP_F16_1(sign)
WP_F16_1(floor)
WP_F16_1(ceil)
WP_F16_1(sqrt)
WP_F16_1(exp)
WP_F16_1(log)
WP_F16_1(sin)
WP_F16_1(cos)
WP_F16_1(tan)
WP_F16_2(atan2)
WP_F16_2(pow)
WP_F16_1(asin)
WP_F16_1(acos)
WP_F16_1(atan)
WP_F16_1(sinh)
WP_F16_1(cosh)
WP_F16_1(tanh)
WP_F16_1(exp2)
WP_F16_1(log2)
WP_F16_1(log10)
WP_F16_1(cbrt)
WP_F16_1(round)
WP_F16_1(rint)
WP_F16_1(trunc)
WP_F16_1(frac)
WP_F16_1(degrees)
WP_F16_1(radians)
WP_F16_1(erf)
WP_F16_1(erfc)
WP_F16_1(erfinv)
WP_F16_1(erfcinv)
WP_F16_3(smoothstep)
WP_F16_3(lerp)
#undef WP_F16_3
#undef WP_F16_2
#undef WP_F16_1
WP_LFN f16 step(f16 x) { return f16_from_f32(step(f16_to_f32(x))); }
WP_LFN bool isnan(f16 x) { return isnan(f16_to_f32(x)); }
WP_LFN bool isinf(f16 x) { return isinf(f16_to_f32(x)); }
WP_LFN bool isfinite(f16 x) { return isfinite(f16_to_f32(x)); }
// bf16: the same, rounded once to bf16 (warp-core/src/bfloat16.rs).
#define WP_BF16_1(NAME) \
  WP_LFN bf16 NAME(bf16 x) { return bf16_from_f32(NAME(bf16_to_f32(x))); }
#define WP_BF16_2(NAME) \
  WP_LFN bf16 NAME(bf16 x, bf16 y) { return bf16_from_f32(NAME(bf16_to_f32(x), bf16_to_f32(y))); }
#define WP_BF16_3(NAME)                                                                  \
  WP_LFN bf16 NAME(bf16 x, bf16 y, bf16 z) {                                                 \
    return bf16_from_f32(NAME(bf16_to_f32(x), bf16_to_f32(y), bf16_to_f32(z)));             \
  }
WP_BF16_2(min)
WP_BF16_2(max)
WP_BF16_3(clamp)
WP_BF16_1(abs)
WP_BF16_1(sign)
WP_BF16_1(floor)
WP_BF16_1(ceil)
WP_BF16_1(sqrt)
WP_BF16_1(exp)
WP_BF16_1(log)
WP_BF16_1(sin)
WP_BF16_1(cos)
WP_BF16_1(tan)
WP_BF16_2(atan2)
WP_BF16_2(pow)
WP_BF16_1(asin)
WP_BF16_1(acos)
WP_BF16_1(atan)
WP_BF16_1(sinh)
WP_BF16_1(cosh)
WP_BF16_1(tanh)
WP_BF16_1(exp2)
WP_BF16_1(log2)
WP_BF16_1(log10)
WP_BF16_1(cbrt)
WP_BF16_1(round)
WP_BF16_1(rint)
WP_BF16_1(trunc)
WP_BF16_1(frac)
WP_BF16_1(degrees)
WP_BF16_1(radians)
WP_BF16_1(erf)
WP_BF16_1(erfc)
WP_BF16_1(erfinv)
WP_BF16_1(erfcinv)
WP_BF16_3(smoothstep)
WP_BF16_3(lerp)
#undef WP_BF16_3
#undef WP_BF16_2
#undef WP_BF16_1
WP_LFN bf16 step(bf16 x) { return bf16_from_f32(step(bf16_to_f32(x))); }
WP_LFN bool isnan(bf16 x) { return isnan(bf16_to_f32(x)); }
WP_LFN bool isinf(bf16 x) { return isinf(bf16_to_f32(x)); }
WP_LFN bool isfinite(bf16 x) { return isfinite(bf16_to_f32(x)); }

// ----- isfinite / isnan / isinf of quaternions and matrices (warp-core builtins::misc):
// every lane finite, some lane NaN, some lane infinite (the vector rules over vec_traits) -----
#define WP_LANES_CLASSIFY(T)                                                   \
  WP_LFN bool isfinite(const T& v) {                                            \
    bool r = true;                                                             \
    for (int i = 0; i < vec_traits<T>::N; ++i) r = r && isfinite(vec_traits<T>::get(v, i)); \
    return r;                                                                  \
  }                                                                            \
  WP_LFN bool isnan(const T& v) {                                               \
    bool r = false;                                                            \
    for (int i = 0; i < vec_traits<T>::N; ++i) r = r || isnan(vec_traits<T>::get(v, i)); \
    return r;                                                                  \
  }                                                                            \
  WP_LFN bool isinf(const T& v) {                                               \
    bool r = false;                                                            \
    for (int i = 0; i < vec_traits<T>::N; ++i) r = r || isinf(vec_traits<T>::get(v, i)); \
    return r;                                                                  \
  }
WP_LANES_CLASSIFY(Quat)
WP_LANES_CLASSIFY(DQuat)
WP_LANES_CLASSIFY(Mat2)
WP_LANES_CLASSIFY(Mat3)
WP_LANES_CLASSIFY(Mat4)
WP_LANES_CLASSIFY(DMat2)
WP_LANES_CLASSIFY(DMat3)
WP_LANES_CLASSIFY(DMat4)
#undef WP_LANES_CLASSIFY

}  // namespace wp

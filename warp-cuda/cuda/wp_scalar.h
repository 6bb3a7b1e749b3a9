// wp_scalar.h: section "scalar" of the builtin table (warp-core/src/builtins/math.rs).
//
//   min, max, clamp   all integer and float scalars, and every glam vector (componentwise);
//                     floats are IEEE fmin/fmax: a NaN operand loses to the other.
//   abs, sign         signed integers (abs wraps: abs(MIN) == MIN), f32, f64, float vectors,
//                     IVec2-4; sign(x) = -1 if x < 0 else +1 (sign(0) = sign(-0.0) = sign(NaN) = 1).
//   floor ceil sqrt exp log sin cos tan atan2 pow     f32 (the ...f functions), f64.
//   lerp(a, b, t)     a * (1 - t) + b * t; f32, f64, float vectors with a scalar t.
//
// Accuracy: floor, ceil and sqrt are exact on both backends. The transcendental functions
// (exp, log, sin, cos, tan, atan2, pow) call the platform's libm on the CPU (glibc, through
// Rust's std) and CUDA's math library on the GPU; CUDA documents errors of 1 to 4 ulp for
// them (e.g. sinf 2, tanf 4, powf 4 ulp), so the backends may differ in the last bits there.
#pragma once
#include "wp_core.h"

namespace wp {

// ------------------------------------------------------------------------------------------
// min / max / clamp
// ------------------------------------------------------------------------------------------

#define WP_INT_MINMAX(T)                                           \
  WP_FN T min(T a, T b) { return b < a ? b : a; }                  \
  WP_FN T max(T a, T b) { return a < b ? b : a; }                  \
  WP_FN T clamp(T x, T lo, T hi) { return min(max(x, lo), hi); }
WP_INT_MINMAX(i8)
WP_INT_MINMAX(i16)
WP_INT_MINMAX(i32)
WP_INT_MINMAX(i64)
WP_INT_MINMAX(u8)
WP_INT_MINMAX(u16)
WP_INT_MINMAX(u32)
WP_INT_MINMAX(u64)
#undef WP_INT_MINMAX

WP_FN f32 min(f32 a, f32 b) { return ::fminf(a, b); }
WP_FN f32 max(f32 a, f32 b) { return ::fmaxf(a, b); }
WP_FN f32 clamp(f32 x, f32 lo, f32 hi) { return min(max(x, lo), hi); }
WP_FN f64 min(f64 a, f64 b) { return ::fmin(a, b); }
WP_FN f64 max(f64 a, f64 b) { return ::fmax(a, b); }
WP_FN f64 clamp(f64 x, f64 lo, f64 hi) { return min(max(x, lo), hi); }

#define WP_VEC_MINMAX(V, S)                                                                   \
  WP_FN V min(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return min(x, y); }); } \
  WP_FN V max(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return max(x, y); }); } \
  WP_FN V clamp(const V& x, const V& lo, const V& hi) { return min(max(x, lo), hi); }
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
  WP_FN T abs(T x) { return x < (T)0 ? w_neg(x) : x; }           \
  WP_FN T sign(T x) { return x < (T)0 ? (T)-1 : (T)1; }
WP_INT_SIGNED(i8)
WP_INT_SIGNED(i16)
WP_INT_SIGNED(i32)
WP_INT_SIGNED(i64)
#undef WP_INT_SIGNED

WP_FN f32 abs(f32 x) { return ::fabsf(x); }
WP_FN f32 sign(f32 x) { return x < 0.0f ? -1.0f : 1.0f; }
WP_FN f64 abs(f64 x) { return ::fabs(x); }
WP_FN f64 sign(f64 x) { return x < 0.0 ? -1.0 : 1.0; }

#define WP_VEC_SIGNED(V, S)                                                                \
  WP_FN V abs(const V& a) { return detail::vmap(a, [](S x) { return abs(x); }); }          \
  WP_FN V sign(const V& a) { return detail::vmap(a, [](S x) { return sign(x); }); }
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

WP_FN f32 floor(f32 x) { return ::floorf(x); }
WP_FN f32 ceil(f32 x) { return ::ceilf(x); }
WP_FN f32 sqrt(f32 x) { return ::sqrtf(x); }
WP_FN f32 exp(f32 x) { return ::expf(x); }
WP_FN f32 log(f32 x) { return ::logf(x); }
WP_FN f32 sin(f32 x) { return ::sinf(x); }
WP_FN f32 cos(f32 x) { return ::cosf(x); }
WP_FN f32 tan(f32 x) { return ::tanf(x); }
WP_FN f32 atan2(f32 y, f32 x) { return ::atan2f(y, x); }
WP_FN f32 pow(f32 x, f32 y) { return ::powf(x, y); }

WP_FN f64 floor(f64 x) { return ::floor(x); }
WP_FN f64 ceil(f64 x) { return ::ceil(x); }
WP_FN f64 sqrt(f64 x) { return ::sqrt(x); }
WP_FN f64 exp(f64 x) { return ::exp(x); }
WP_FN f64 log(f64 x) { return ::log(x); }
WP_FN f64 sin(f64 x) { return ::sin(x); }
WP_FN f64 cos(f64 x) { return ::cos(x); }
WP_FN f64 tan(f64 x) { return ::tan(x); }
WP_FN f64 atan2(f64 y, f64 x) { return ::atan2(y, x); }
WP_FN f64 pow(f64 x, f64 y) { return ::pow(x, y); }

// ------------------------------------------------------------------------------------------
// lerp
// ------------------------------------------------------------------------------------------

WP_FN f32 lerp(f32 a, f32 b, f32 t) { return a * (1.0f - t) + b * t; }
WP_FN f64 lerp(f64 a, f64 b, f64 t) { return a * (1.0 - t) + b * t; }

#define WP_VEC_LERP(V, S) \
  WP_FN V lerp(const V& a, const V& b, S t) { return detail::vzip(a, b, [t](S x, S y) { return lerp(x, y, t); }); }
WP_VEC_LERP(Vec2, f32)
WP_VEC_LERP(Vec3, f32)
WP_VEC_LERP(Vec4, f32)
WP_VEC_LERP(DVec2, f64)
WP_VEC_LERP(DVec3, f64)
WP_VEC_LERP(DVec4, f64)
#undef WP_VEC_LERP

}  // namespace wp

// wp_core.h: the core of warp-lang's CUDA C++ builtin library (namespace `wp`).
//
// Generated kernels include this library and are compiled by NVRTC; the same headers also
// compile as plain host C++17 (g++/clang++) so that generated code can be checked on the CPU.
// Every function here must agree bit for bit with the CPU implementation in warp-core
// (warp-core/src/{ops,range,view,grid,fault}.rs and builtins/): same types, same edge cases.
//
// Contents:
//   * integer/float typedefs (i8..u64, isize = i64, usize = u64, f32, f64) and `num<T>` traits;
//   * `f16` (half precision, the layout of `half::f16`): conversions, arithmetic through f32;
//   * `bf16` (brain float, the layout of `half::bf16`): the same, in software on every arch;
//   * the glam types with glam 0.30's x86_64 layout (Vec4, Mat2, Mat4 and Quat are 16-byte
//     aligned because glam stores them in SSE registers), constructors and constants as free
//     functions (`Vec3_new`, `Vec3_splat`, `Vec3_ZERO()`, `Mat3_from_cols`, `Quat_IDENTITY()`...);
//   * operators with glam's meaning, including two glam quirks (Vec4 `%`, scalar / matrix);
//   * warp-core's spatial vectors and 6x6 matrices (`SpatialVector`, `SpatialMatrix` and their
//     f64 twins: lanes f0..f5, rows f0..f5) and their operators (`SpatialVector_new`,
//     `SpatialMatrix_from_rows`, `_ZERO()`, `SpatialMatrix_IDENTITY()`, lane-by-lane ops, products);
//   * warp-core's rigid transforms (`Transform`, `DTransform`: p, padding, q) and their
//     operators (`Transform_new`, `Transform_IDENTITY()`, composition `*`, lane-by-lane ops);
//   * integer semantics of warp_core::ops (`w_add` ... `w_shr`), Rust `as` casts (`cast<To>`),
//     literals (`lit_like`, `scalar_lit_like`, `int_like`);
//   * faults (`fault_t`, `launch_ctx_t`, `ctx_t`, `raise`), arrays (`array_t`, `load`, `store`,
//     ...), range loops (`range_t`), the launch grid (`launch_t`, `unflatten`).
//
// Floating point: results match the CPU only if the compiler does not contract a*b+c into an
// FMA. NVRTC contracts by default: compile with `--fmad=false` (and without
// `--use_fast_math`, which would also flush denormals and approximate division and sqrt).
#pragma once

#if defined(__CUDACC__)
#define WP_FN __device__ __forceinline__
#if !defined(__CUDACC_RTC__)
#include <cstdio>  // device printf under nvcc (NVRTC declares printf itself)
#endif
#else
#define WP_FN inline
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#endif

// WP_LFN: a library function that the front end analyses only where a unit calls it. NVRTC's
// C++ front end checks every non-template function body it is handed, and the families of
// operators and adjoints (one overload per scalar, vector and matrix type) were most of a
// unit's front-end time; a function template's body is analysed only when it is instantiated.
// The template parameter is never deduced or named (an enum class that no caller spells), so
// the parameter types stay fixed: the same implicit conversions apply as for a plain function,
// explicit template arguments (`f<T>(..)`) never select one, and in a tie with a real template
// it is preferred, as a plain function is (checked with NVRTC and g++). A new function at
// namespace scope in a kernel section uses it; WP_FN stays on templates, members, functions
// declared before their definition (the two would repeat the default template argument) and
// the standalone build libraries.
namespace wp {
enum class lazy_t {};
}  // namespace wp
#define WP_LFN template <::wp::lazy_t = ::wp::lazy_t{}> WP_FN

namespace wp {

// ------------------------------------------------------------------------------------------
// Scalars
// ------------------------------------------------------------------------------------------

typedef signed char i8;
typedef short i16;
typedef int i32;
typedef long long i64;
typedef unsigned char u8;
typedef unsigned short u16;
typedef unsigned int u32;
typedef unsigned long long u64;
typedef i64 isize;
typedef u64 usize;
typedef float f32;
typedef double f64;

static_assert(sizeof(i8) == 1 && sizeof(i16) == 2 && sizeof(i32) == 4 && sizeof(i64) == 8,
              "integer sizes");
static_assert(sizeof(u8) == 1 && sizeof(u16) == 2 && sizeof(u32) == 4 && sizeof(u64) == 8,
              "integer sizes");
static_assert(sizeof(f32) == 4 && sizeof(f64) == 8, "float sizes");

/// Traits of a scalar type. `unsigned_t`: the unsigned type of the same width; `wide_t`: the
/// unsigned type wrapping arithmetic is done in (at least 32 bits, so that `u16 * u16` never
/// goes through a signed `int`); `lo`/`hi`: the bounds of Rust's saturating float->int `as`
/// (`x <= lo` gives MIN, `x >= hi` gives MAX; both are powers of two, exact in f32 and f64).
template <typename T>
struct num {
  static constexpr bool is_int = false;
  static constexpr bool is_float = false;
  static constexpr bool is_signed = false;
  static constexpr bool is_bool = false;
};

#define WP_NUM_INT(T, U, W, BITS, SIGNED, MINV, MAXV, LO, HI) \
  template <>                                                  \
  struct num<T> {                                              \
    typedef U unsigned_t;                                      \
    typedef W wide_t;                                          \
    static constexpr bool is_int = true;                       \
    static constexpr bool is_float = false;                    \
    static constexpr bool is_signed = SIGNED;                  \
    static constexpr bool is_bool = false;                     \
    static constexpr int bits = BITS;                          \
    static constexpr T min_value = MINV;                       \
    static constexpr T max_value = MAXV;                       \
    static constexpr double lo = LO;                           \
    static constexpr double hi = HI;                           \
  };

WP_NUM_INT(i8, u8, u32, 8, true, (i8)(-128), (i8)127, -128.0, 128.0)
WP_NUM_INT(i16, u16, u32, 16, true, (i16)(-32768), (i16)32767, -32768.0, 32768.0)
WP_NUM_INT(i32, u32, u32, 32, true, (-2147483647 - 1), 2147483647, -2147483648.0, 2147483648.0)
WP_NUM_INT(i64, u64, u64, 64, true, (-9223372036854775807LL - 1), 9223372036854775807LL,
           -9223372036854775808.0, 9223372036854775808.0)
WP_NUM_INT(u8, u8, u32, 8, false, (u8)0, (u8)255, 0.0, 256.0)
WP_NUM_INT(u16, u16, u32, 16, false, (u16)0, (u16)65535, 0.0, 65536.0)
WP_NUM_INT(u32, u32, u32, 32, false, 0u, 4294967295u, 0.0, 4294967296.0)
WP_NUM_INT(u64, u64, u64, 64, false, 0ull, 18446744073709551615ull, 0.0, 18446744073709551616.0)
#undef WP_NUM_INT

template <>
struct num<f32> {
  static constexpr bool is_int = false;
  static constexpr bool is_float = true;
  static constexpr bool is_signed = true;
  static constexpr bool is_bool = false;
  static constexpr int bits = 32;
};
template <>
struct num<f64> {
  static constexpr bool is_int = false;
  static constexpr bool is_float = true;
  static constexpr bool is_signed = true;
  static constexpr bool is_bool = false;
  static constexpr int bits = 64;
};
template <>
struct num<bool> {
  static constexpr bool is_int = false;
  static constexpr bool is_float = false;
  static constexpr bool is_signed = false;
  static constexpr bool is_bool = true;
  static constexpr int bits = 1;
};

// Bit casts (IEEE bit patterns).
WP_LFN u32 f32_to_bits(f32 x) {
#if defined(__CUDACC__)
  return __float_as_uint(x);
#else
  u32 u;
  std::memcpy(&u, &x, 4);
  return u;
#endif
}
WP_LFN f32 f32_from_bits(u32 u) {
#if defined(__CUDACC__)
  return __uint_as_float(u);
#else
  f32 x;
  std::memcpy(&x, &u, 4);
  return x;
#endif
}
WP_LFN u64 f64_to_bits(f64 x) {
#if defined(__CUDACC__)
  return (u64)__double_as_longlong(x);
#else
  u64 u;
  std::memcpy(&u, &x, 8);
  return u;
#endif
}
WP_LFN f64 f64_from_bits(u64 u) {
#if defined(__CUDACC__)
  return __longlong_as_double((long long)u);
#else
  f64 x;
  std::memcpy(&x, &u, 8);
  return x;
#endif
}

/// Rust's float constants (bit exact).
WP_LFN f32 f32_nan() { return f32_from_bits(0x7fc00000u); }
WP_LFN f32 f32_inf() { return f32_from_bits(0x7f800000u); }
WP_LFN f32 f32_max() { return f32_from_bits(0x7f7fffffu); }
WP_LFN f64 f64_nan() { return f64_from_bits(0x7ff8000000000000ull); }
WP_LFN f64 f64_inf() { return f64_from_bits(0x7ff0000000000000ull); }
WP_LFN f64 f64_max() { return f64_from_bits(0x7fefffffffffffffull); }
template <typename S> WP_FN S float_nan();
template <> WP_FN f32 float_nan<f32>() { return f32_nan(); }
template <> WP_FN f64 float_nan<f64>() { return f64_nan(); }
template <typename S> WP_FN S float_inf();
template <> WP_FN f32 float_inf<f32>() { return f32_inf(); }
template <> WP_FN f64 float_inf<f64>() { return f64_inf(); }
template <typename S> WP_FN S float_max();
template <> WP_FN f32 float_max<f32>() { return f32_max(); }
template <> WP_FN f64 float_max<f64>() { return f64_max(); }

/// `nan<T>()` / `inf<T>()` for T = f32, f64: Rust's f32::NAN (0x7fc00000) and INFINITY.
template <typename T> WP_FN T nan() { return float_nan<T>(); }
template <typename T> WP_FN T inf() { return float_inf<T>(); }

// ------------------------------------------------------------------------------------------
// f16 (Warp's float16; warp-core/src/float16.rs, the `half` crate's f16)
// ------------------------------------------------------------------------------------------
//
// `wp::f16` is its IEEE binary16 bit pattern (2 bytes, align 2: the layout of `half::f16`).
// No cuda_fp16.h: this library is self-contained under NVRTC. Every operation converts to f32
// exactly, computes in f32 and rounds to f16 once, to nearest even (as `half` does):
//   * f32 -> f16: PTX `cvt.rn.f16.f32` on the device; on the host a transcription of
//     `half`'s software conversion (`f32_to_f16_fallback`), equal to it bit for bit (NaNs
//     included: quiet, sign and top payload bits kept; the device gives its canonical NaN);
//   * f16 -> f32: PTX `cvt.f32.f16`; on the host `half`'s `f16_to_f32_fallback`;
//   * f64 -> f16: rounded once, in software on both (warp_core::float16::f16_from_f64);
//   * + - * / and comparisons through f32; unary `-` flips the sign bit (as `half`).
// Since f32 has more than twice f16's precision plus two bits, + - * / and sqrt rounded twice
// (to f32, then f16) are correctly rounded f16 operations: both backends agree bit for bit.

namespace detail {
/// Leading zeros of the low 16 bits of `x` (x < 2^16).
WP_LFN i32 clz16(u32 x) {
  i32 n = 0;
  for (u32 bit = 0x8000u; bit != 0 && (x & bit) == 0; bit >>= 1) ++n;
  return n;
}
/// `half`'s f32_to_f16_fallback, transcribed: round to nearest even, overflow to infinity.
WP_LFN u16 f32_to_f16_soft(f32 value) {
  const u32 x = f32_to_bits(value);
  const u32 sign = x & 0x80000000u;
  const u32 exp = x & 0x7F800000u;
  const u32 man = x & 0x007FFFFFu;
  if (exp == 0x7F800000u) {
    const u32 nan_bit = man == 0 ? 0u : 0x0200u;
    return (u16)((sign >> 16) | 0x7C00u | nan_bit | (man >> 13));
  }
  const u32 half_sign = sign >> 16;
  const i32 half_exp = ((i32)(exp >> 23) - 127) + 15;
  if (half_exp >= 0x1F) return (u16)(half_sign | 0x7C00u);
  if (half_exp <= 0) {
    if (14 - half_exp > 24) return (u16)half_sign;
    const u32 m = man | 0x00800000u;
    u32 half_man = m >> (14 - half_exp);
    const u32 round_bit = 1u << (13 - half_exp);
    if ((m & round_bit) != 0 && (m & (3u * round_bit - 1u)) != 0) half_man += 1;
    return (u16)(half_sign | half_man);
  }
  const u32 he = (u32)half_exp << 10;
  const u32 hm = man >> 13;
  const u32 round_bit = 0x00001000u;
  if ((man & round_bit) != 0 && (man & (3u * round_bit - 1u)) != 0)
    return (u16)((half_sign | he | hm) + 1u);
  return (u16)(half_sign | he | hm);
}
/// `half`'s f16_to_f32_fallback, transcribed: exact (NaNs made quiet).
WP_LFN f32 f16_to_f32_soft(u16 i) {
  if ((i & 0x7FFFu) == 0) return f32_from_bits((u32)i << 16);
  const u32 half_sign = i & 0x8000u;
  const u32 half_exp = i & 0x7C00u;
  const u32 half_man = i & 0x03FFu;
  if (half_exp == 0x7C00u) {
    if (half_man == 0) return f32_from_bits((half_sign << 16) | 0x7F800000u);
    return f32_from_bits((half_sign << 16) | 0x7FC00000u | (half_man << 13));
  }
  const u32 sign = half_sign << 16;
  if (half_exp == 0) {
    const i32 e = clz16(half_man) - 6;
    const u32 exp = (u32)(127 - 15 - e) << 23;
    const u32 man = (half_man << (14 + e)) & 0x7FFFFFu;
    return f32_from_bits(sign | exp | man);
  }
  const u32 exp = (u32)((((i32)half_exp >> 10) - 15) + 127) << 23;
  return f32_from_bits(sign | exp | (half_man << 13));
}
}  // namespace detail

/// f32 -> f16 bits, round to nearest even.
WP_LFN u16 f32_to_f16_bits(f32 x) {
#if defined(__CUDACC__)
  u16 r;
  asm("cvt.rn.f16.f32 %0, %1;" : "=h"(r) : "f"(x));
  return r;
#else
  return detail::f32_to_f16_soft(x);
#endif
}
/// f16 bits -> f32, exact.
WP_LFN f32 f16_bits_to_f32(u16 b) {
#if defined(__CUDACC__)
  f32 r;
  asm("cvt.f32.f16 %0, %1;" : "=f"(r) : "h"(b));
  return r;
#else
  return detail::f16_to_f32_soft(b);
#endif
}
/// f64 -> f16 bits, rounded once to nearest even (Rust's `x as f16`; not f64 -> f32 -> f16,
/// which rounds twice): the value is scaled by a power of two to units of its f16 ulp,
/// rounded to an integer (rint: ties to even) and scaled back, all exact in f64.
WP_LFN u16 f64_to_f16_bits(f64 x) {
  const u64 bits = f64_to_bits(x);
  const u16 sign = (u16)((bits >> 48) & 0x8000u);
  const f64 a = f64_from_bits(bits & 0x7FFFFFFFFFFFFFFFull);
  if (!(a == a)) return (u16)(sign | 0x7E00u | (u16)((bits >> 42) & 0x3FFu));
  if (a >= 65520.0) return (u16)(sign | 0x7C00u);  // the tie above f16::MAX rounds up
  const i32 e = (i32)((bits >> 52) & 0x7FFu) - 1023;
  const i32 ulp = (e > -14 ? e : -14) - 10;
  const f64 down = f64_from_bits((u64)(1023 - ulp) << 52);  // 2^-ulp
  const f64 up = f64_from_bits((u64)(1023 + ulp) << 52);    // 2^ulp
  const f64 r = ::rint(a * down) * up;                      // an f16 value (or 0)
  return (u16)(sign | f32_to_f16_bits((f32)r));
}

struct f16;
WP_FN f16 f16_from_bits(u16 b);

/// Half precision: the bit pattern of `half::f16`. Conversions are explicit (`(f32)h`,
/// `(f16)x`, `wp::cast<T>`), so no f16 operation silently becomes an f32 one.
struct f16 {
  u16 bits;
  f16() = default;
  explicit WP_FN f16(f32 x) : bits(f32_to_f16_bits(x)) {}
  explicit WP_FN f16(f64 x) : bits(f64_to_f16_bits(x)) {}
  explicit WP_FN f16(int x) : bits(f32_to_f16_bits((f32)x)) {}
  explicit WP_FN operator f32() const { return f16_bits_to_f32(bits); }
  explicit WP_FN operator f64() const { return (f64)f16_bits_to_f32(bits); }
};
static_assert(sizeof(f16) == 2 && alignof(f16) == 2, "f16 layout (half::f16)");

WP_FN f16 f16_from_bits(u16 b) {
  f16 h;
  h.bits = b;
  return h;
}
WP_LFN f16 f16_from_f32(f32 x) { return f16_from_bits(f32_to_f16_bits(x)); }
WP_LFN f16 f16_from_f64(f64 x) { return f16_from_bits(f64_to_f16_bits(x)); }
WP_LFN f32 f16_to_f32(f16 h) { return f16_bits_to_f32(h.bits); }

WP_LFN f16 operator+(f16 a, f16 b) { return f16_from_f32(f16_to_f32(a) + f16_to_f32(b)); }
WP_LFN f16 operator-(f16 a, f16 b) { return f16_from_f32(f16_to_f32(a) - f16_to_f32(b)); }
WP_LFN f16 operator*(f16 a, f16 b) { return f16_from_f32(f16_to_f32(a) * f16_to_f32(b)); }
WP_LFN f16 operator/(f16 a, f16 b) { return f16_from_f32(f16_to_f32(a) / f16_to_f32(b)); }
WP_LFN f16 operator-(f16 a) { return f16_from_bits((u16)(a.bits ^ 0x8000u)); }
WP_LFN f16& operator+=(f16& a, f16 b) { return a = a + b; }
WP_LFN f16& operator-=(f16& a, f16 b) { return a = a - b; }
WP_LFN f16& operator*=(f16& a, f16 b) { return a = a * b; }
WP_LFN f16& operator/=(f16& a, f16 b) { return a = a / b; }
WP_LFN bool operator==(f16 a, f16 b) { return f16_to_f32(a) == f16_to_f32(b); }
WP_LFN bool operator!=(f16 a, f16 b) { return f16_to_f32(a) != f16_to_f32(b); }
WP_LFN bool operator<(f16 a, f16 b) { return f16_to_f32(a) < f16_to_f32(b); }
WP_LFN bool operator<=(f16 a, f16 b) { return f16_to_f32(a) <= f16_to_f32(b); }
WP_LFN bool operator>(f16 a, f16 b) { return f16_to_f32(a) > f16_to_f32(b); }
WP_LFN bool operator>=(f16 a, f16 b) { return f16_to_f32(a) >= f16_to_f32(b); }

template <>
struct num<f16> {
  static constexpr bool is_int = false;
  static constexpr bool is_float = true;
  static constexpr bool is_signed = true;
  static constexpr bool is_bool = false;
  static constexpr int bits = 16;
};
template <> WP_FN f16 float_nan<f16>() { return f16_from_bits(0x7E00u); }
template <> WP_FN f16 float_inf<f16>() { return f16_from_bits(0x7C00u); }
template <> WP_FN f16 float_max<f16>() { return f16_from_bits(0x7BFFu); }

// ------------------------------------------------------------------------------------------
// bf16 (Warp's bfloat16; warp-core/src/bfloat16.rs, the `half` crate's bf16)
// ------------------------------------------------------------------------------------------
//
// `wp::bf16` is the top half of an f32's bits (2 bytes, align 2: the layout of `half::bf16`):
// f32's exponent range, 8 significant bits. As f16, every operation widens to f32 exactly,
// computes in f32 and rounds to bf16 once, to nearest even; the conversions are software on
// every architecture (a shift and an add, as `half`'s; no cuda_bf16.h, which NVRTC would need
// on its include path), so both backends give the same bits, NaNs included:
//   * f32 -> bf16: `half`'s f32_to_bf16, transcribed (NaN: the top bits, quiet bit set);
//   * bf16 -> f32: the bits shifted up (exact; `half` also sets a NaN's quiet bit);
//   * f64 -> bf16 and 64-bit integers -> bf16: rounded once (warp_core::bfloat16).
// f32's 24 bits are more than twice bf16's 8 plus two, so + - * / and sqrt rounded twice are
// correctly rounded bf16 operations.

WP_LFN u16 f32_to_bf16_bits(f32 x) {
  const u32 u = f32_to_bits(x);
  if ((u & 0x7FFFFFFFu) > 0x7F800000u) return (u16)((u >> 16) | 0x0040u);
  // Round bit set, and a sticky bit or the kept lowest bit set: up (ties to even).
  const bool up = (u & 0x8000u) != 0 && (u & 0x17FFFu) != 0;
  return (u16)((u >> 16) + (up ? 1u : 0u));
}
WP_LFN f32 bf16_bits_to_f32(u16 b) {
  const u32 u = (u32)b << 16;
  // A NaN gets its quiet bit, as `half`'s bf16_to_f32.
  return f32_from_bits((b & 0x7FFFu) > 0x7F80u ? (u | 0x00400000u) : u);
}
/// f64 -> bf16 bits, rounded once to nearest even (warp_core::bfloat16::bf16_from_f64): as
/// f64_to_f16_bits, in units of the bf16 ulp (2^(e-7), 2^-133 below 2^-126).
WP_LFN u16 f64_to_bf16_bits(f64 x) {
  const u64 bits = f64_to_bits(x);
  const u16 sign = (u16)((bits >> 48) & 0x8000u);
  const f64 a = f64_from_bits(bits & 0x7FFFFFFFFFFFFFFFull);
  // NaN: as Rust's `x as f32` then `half` (quiet, the top payload bits).
  if (!(a == a)) return (u16)(sign | 0x7FC0u | (u16)((bits >> 45) & 0x3Fu));
  // From the midpoint between bf16::MAX and 2^128 ((2 - 2^-8) 2^127) on: infinity.
  if (a >= f64_from_bits(0x47EFF00000000000ull)) return (u16)(sign | 0x7F80u);
  const i32 e = (i32)((bits >> 52) & 0x7FFu) - 1023;
  const i32 ulp = (e > -126 ? e : -126) - 7;
  const f64 down = f64_from_bits((u64)(1023 - ulp) << 52);  // 2^-ulp
  const f64 up = f64_from_bits((u64)(1023 + ulp) << 52);    // 2^ulp
  const f64 r = ::rint(a * down) * up;                      // a bf16 value (or 0), exact in f32
  return (u16)(sign | (u16)(f32_to_bits((f32)r) >> 16));
}
/// An integer's magnitude rounded once to bf16 bits: above 2^25 the bits below the 25th
/// are folded into a sticky bit (exact in f64 then), so f32's own rounding of a large
/// integer cannot round a second time (warp_core::bfloat16's int_to_bf16).
WP_LFN u16 u64_to_bf16_bits(u64 a) {
  i32 cut = 0;
  u64 sticky = 0;
  while ((a >> 25) != 0) {
    sticky |= a & 1u;
    a >>= 1;
    ++cut;
  }
  a |= sticky;
  return f64_to_bf16_bits((f64)a * f64_from_bits((u64)(1023 + cut) << 52));
}

/// Brain float: the bit pattern of `half::bf16`. Conversions are explicit, as f16's.
struct bf16 {
  u16 bits;
  bf16() = default;
  explicit WP_FN bf16(f32 x) : bits(f32_to_bf16_bits(x)) {}
  explicit WP_FN bf16(f64 x) : bits(f64_to_bf16_bits(x)) {}
  explicit WP_FN bf16(int x) : bits(f32_to_bf16_bits((f32)x)) {}
  explicit WP_FN operator f32() const { return bf16_bits_to_f32(bits); }
  explicit WP_FN operator f64() const { return (f64)bf16_bits_to_f32(bits); }
};
static_assert(sizeof(bf16) == 2 && alignof(bf16) == 2, "bf16 layout (half::bf16)");

WP_FN bf16 bf16_from_bits(u16 b) {
  bf16 h;
  h.bits = b;
  return h;
}
WP_LFN bf16 bf16_from_f32(f32 x) { return bf16_from_bits(f32_to_bf16_bits(x)); }
WP_LFN bf16 bf16_from_f64(f64 x) { return bf16_from_bits(f64_to_bf16_bits(x)); }
WP_LFN f32 bf16_to_f32(bf16 h) { return bf16_bits_to_f32(h.bits); }

WP_LFN bf16 operator+(bf16 a, bf16 b) { return bf16_from_f32(bf16_to_f32(a) + bf16_to_f32(b)); }
WP_LFN bf16 operator-(bf16 a, bf16 b) { return bf16_from_f32(bf16_to_f32(a) - bf16_to_f32(b)); }
WP_LFN bf16 operator*(bf16 a, bf16 b) { return bf16_from_f32(bf16_to_f32(a) * bf16_to_f32(b)); }
WP_LFN bf16 operator/(bf16 a, bf16 b) { return bf16_from_f32(bf16_to_f32(a) / bf16_to_f32(b)); }
WP_LFN bf16 operator-(bf16 a) { return bf16_from_bits((u16)(a.bits ^ 0x8000u)); }
WP_LFN bf16& operator+=(bf16& a, bf16 b) { return a = a + b; }
WP_LFN bf16& operator-=(bf16& a, bf16 b) { return a = a - b; }
WP_LFN bf16& operator*=(bf16& a, bf16 b) { return a = a * b; }
WP_LFN bf16& operator/=(bf16& a, bf16 b) { return a = a / b; }
WP_LFN bool operator==(bf16 a, bf16 b) { return bf16_to_f32(a) == bf16_to_f32(b); }
WP_LFN bool operator!=(bf16 a, bf16 b) { return bf16_to_f32(a) != bf16_to_f32(b); }
WP_LFN bool operator<(bf16 a, bf16 b) { return bf16_to_f32(a) < bf16_to_f32(b); }
WP_LFN bool operator<=(bf16 a, bf16 b) { return bf16_to_f32(a) <= bf16_to_f32(b); }
WP_LFN bool operator>(bf16 a, bf16 b) { return bf16_to_f32(a) > bf16_to_f32(b); }
WP_LFN bool operator>=(bf16 a, bf16 b) { return bf16_to_f32(a) >= bf16_to_f32(b); }

template <>
struct num<bf16> {
  static constexpr bool is_int = false;
  static constexpr bool is_float = true;
  static constexpr bool is_signed = true;
  static constexpr bool is_bool = false;
  static constexpr int bits = 16;
};
template <> WP_FN bf16 float_nan<bf16>() { return bf16_from_bits(0x7FC0u); }
template <> WP_FN bf16 float_inf<bf16>() { return bf16_from_bits(0x7F80u); }
template <> WP_FN bf16 float_max<bf16>() { return bf16_from_bits(0x7F7Fu); }

namespace detail {
template <typename A, typename B> struct same_type { static constexpr bool value = false; };
template <typename A> struct same_type<A, A> { static constexpr bool value = true; };
}  // namespace detail

/// Like std::declval: only for unevaluated operands (`decltype(wp::declval<T>().x)`).
#if defined(__CUDACC__)
template <typename T> __device__ T declval();
#else
template <typename T> T declval();
#endif

/// Rust's tuples `(A, B, ..)` of 2 to 7 elements, members `f0`, `f1`, ..: what a builtin
/// returning a tuple returns (a decomposition's factors, a mesh query's result), a tuple
/// local, a func's tuple parameter or result (and what a func with `&mut` parameters returns).
template <typename... T>
struct tuple_t;
template <typename A, typename B>
struct tuple_t<A, B> {
  A f0;
  B f1;
};
template <typename A, typename B, typename C>
struct tuple_t<A, B, C> {
  A f0;
  B f1;
  C f2;
};
template <typename A, typename B, typename C, typename D>
struct tuple_t<A, B, C, D> {
  A f0;
  B f1;
  C f2;
  D f3;
};
template <typename A, typename B, typename C, typename D, typename E>
struct tuple_t<A, B, C, D, E> {
  A f0;
  B f1;
  C f2;
  D f3;
  E f4;
};
template <typename A, typename B, typename C, typename D, typename E, typename F>
struct tuple_t<A, B, C, D, E, F> {
  A f0;
  B f1;
  C f2;
  D f3;
  E f4;
  F f5;
};
template <typename A, typename B, typename C, typename D, typename E, typename F, typename G>
struct tuple_t<A, B, C, D, E, F, G> {
  A f0;
  B f1;
  C f2;
  D f3;
  E f4;
  F f5;
  G f6;
};

/// `(a, b, ..)`: a tuple of values whose types the caller may not spell (a func's result, a
/// struct field): deduced, by value, so without `const`.
template <typename A, typename B>
WP_FN tuple_t<A, B> make_tuple(A a, B b) {
  return tuple_t<A, B>{a, b};
}
template <typename A, typename B, typename C>
WP_FN tuple_t<A, B, C> make_tuple(A a, B b, C c) {
  return tuple_t<A, B, C>{a, b, c};
}
template <typename A, typename B, typename C, typename D>
WP_FN tuple_t<A, B, C, D> make_tuple(A a, B b, C c, D d) {
  return tuple_t<A, B, C, D>{a, b, c, d};
}
template <typename A, typename B, typename C, typename D, typename E>
WP_FN tuple_t<A, B, C, D, E> make_tuple(A a, B b, C c, D d, E e) {
  return tuple_t<A, B, C, D, E>{a, b, c, d, e};
}
template <typename A, typename B, typename C, typename D, typename E, typename F>
WP_FN tuple_t<A, B, C, D, E, F> make_tuple(A a, B b, C c, D d, E e, F f) {
  return tuple_t<A, B, C, D, E, F>{a, b, c, d, e, f};
}
template <typename A, typename B, typename C, typename D, typename E, typename F, typename G>
WP_FN tuple_t<A, B, C, D, E, F, G> make_tuple(A a, B b, C c, D d, E e, F f, G g) {
  return tuple_t<A, B, C, D, E, F, G>{a, b, c, d, e, f, g};
}

/// The unit value `()`: the first element of what a func with `&mut` parameters and no
/// result returns (its result, then the parameters' final values), and a unit func's result
/// in an adjoint.
struct unit_t {};

/// The type T itself, in a non-deduced context (the value parameter of store and atomics is
/// converted to the array's element type instead of taking part in deduction).
template <typename T> struct identity { typedef T type; };

// ------------------------------------------------------------------------------------------
// Faults
// ------------------------------------------------------------------------------------------

/// Fault kinds (fault_t::kind).
enum fault_kind : i32 {
  FAULT_NONE = 0,
  FAULT_OUT_OF_BOUNDS = 1,
  FAULT_DIVISION_BY_ZERO = 2,
  FAULT_BAD_STEP = 3,
  // 4 is FAULT_ADSTACK_OVERFLOW (wp_adjoint_core.h).
  FAULT_NON_FINITE = 5,
  FAULT_TILE_INDEX = 6,
  FAULT_NON_FINITE_INPUT = 7,
  FAULT_ASSERTION = 8,
  FAULT_LOCAL_INDEX = 9,
  FAULT_DETERMINISTIC_RECORDS = 10,
};

/// The first fault of the launches that share a record, filled by the first faulting thread
/// (88 bytes, align 8):
///   0 kind (i32), 4 arg (i32: the kernel parameter index for OutOfBounds, else -1),
///   8 index[4] (i64), 40 shape[4] (i64), 72 ndim (i32), 76 kernel (i32: the faulting launch's
///   kernel id, copied from launch_ctx_t::kernel; 0 when the launcher set none), 80 launch
///   (u64: the faulting launch's number, copied from launch_ctx_t::launch; 0 when the launcher
///   set none).
/// OutOfBounds: index/shape hold `ndim` entries. DivisionByZero: ndim 0. BadStep: ndim 1,
/// index[0] is the step, shape all 0. NonFinite (a NaN or infinite volume sample position,
/// warp_core::FaultKind::NonFinite): ndim 3, index[0..3] are the coordinates' f64 bit
/// patterns (x, y, z), shape all 0. TileIndex (an index outside a tile, wp_tile.h): index and
/// shape hold `ndim` entries (the tile's rank). NonFiniteInput (an element with a NaN or
/// infinite coordinate in an input of a host object's build step, warp_core::FaultKind::
/// NonFiniteInput): arg is the operation's argument (its index in the names the runtime
/// gives the step), ndim 4, index[0] the element's index and index[1..4] its coordinates' f64
/// bit patterns, shape all 0. Assertion (a failed `assert!`, `debug_assert!` or `expect_*`,
/// warp_core::FaultKind::AssertionFailed): ndim 3, index[0] the source line, index[1] the
/// column (the host finds the message by both in the `asserts` tables of the kernel and its
/// callees), index[2] the thread's flat launch index (-1 in a func), shape all 0. LocalIndex
/// (an index outside a fixed-size local array, warp_core::FaultKind::LocalIndex): ndim 3,
/// index[0] the index, index[1] the array's length, index[2] the source line, shape all 0.
/// DeterministicRecords (a thread of a `#[kernel(deterministic)]` launch past its record limit,
/// warp_core::FaultKind::DeterministicRecords): ndim 2, index[0] the thread's flat launch
/// index, index[1] the limit, shape all 0.
/// Unused entries are 0.
struct fault_t {
  i32 kind;
  i32 arg;
  i64 index[4];
  i64 shape[4];
  i32 ndim;
  i32 kernel;
  u64 launch;
};
static_assert(sizeof(fault_t) == 88 && alignof(fault_t) == 8, "fault_t layout");

/// A launch's fault record (32 bytes, align 8), the same for all its threads:
///   0 fault (fault_t*, device memory), 8 fault_flag (u32*, device memory, 0 = no fault yet),
///   16 reserved (i16, 0; a thread's own fault mark is ctx_t::raised), 18 flags (i16: the
///   launch's CTX_* bits, set by the host: CTX_DEBUG, the runtime's debug mode, which
///   `debug_assert!` reads through `debug_mode`), 20 kernel (i32: an id
///   the host gives each loaded kernel, copied into the fault record so that a fault names its
///   kernel even when launches of several kernels are in flight, as in a replayed graph),
///   24 launch (u64: the launch's number, copied into the fault record likewise).
/// A kernel entry takes it as a `WP_GRID_CONST` parameter; `fault` and `fault_flag` may be
/// null: faults then only mark the thread's ctx_t.
struct launch_ctx_t {
  fault_t* fault;
  u32* fault_flag;
  i16 reserved;
  i16 flags;
  i32 kernel;
  u64 launch;
};
static_assert(sizeof(launch_ctx_t) == 32 && alignof(launch_ctx_t) == 8, "launch_ctx_t layout");
/// launch_ctx_t::flags: the runtime's debug mode is on for this launch (`debug_assert!` is
/// checked).
constexpr i16 CTX_DEBUG = 1;

/// A kernel entry's launch_ctx_t parameter is `__grid_constant__` (sm_70 and later, which
/// covers every architecture CUDA 13 compiles for): it stays in the parameter space, so its
/// address is a constant the compiler can rematerialize where it is needed (the cold fault
/// path) instead of holding the record's fields in registers, or copying the record to local
/// memory, through the whole kernel.
#if defined(__CUDACC__)
#define WP_GRID_CONST __grid_constant__
#else
#define WP_GRID_CONST
#endif

/// Per-thread fault context: the launch's record and this thread's mark (`raised`: set to 1
/// by `raise`; starts at 0). A kernel builds one per thread (`ctx_make(&record)`) and passes
/// its address down. A faulting call returns a harmless value and the thread goes on (unlike
/// the CPU's `?`, which stops it); library code checks `faulted(ctx)` where going on would be
/// unsafe, and a failed assertion in a kernel ends its thread.
struct ctx_t {
  const launch_ctx_t* rec;
  i32 raised;
};

/// The fault context of a host object's build step whose kernel raises faults (40 bytes, in
/// the step's record): the launch_ctx_t its threads raise with (the runtime fills fault,
/// fault_flag, kernel and launch before the launch), then `names`, the runtime's own (what it
/// names the fault's operation and arguments by; never read here).
struct step_fault_t {
  launch_ctx_t ctx;
  u64 names;
};
static_assert(sizeof(step_fault_t) == 40 && alignof(step_fault_t) == 8, "step_fault_t layout");

/// A launch record with no flags, kernel id or launch number (device helpers that raise
/// outside a kernel launch's record, and host tests).
WP_LFN launch_ctx_t launch_ctx_make(fault_t* fault, u32* fault_flag) {
  launch_ctx_t r;
  r.fault = fault;
  r.fault_flag = fault_flag;
  r.reserved = 0;
  r.flags = 0;
  r.kernel = 0;
  r.launch = 0;
  return r;
}

/// A thread's fresh context on `rec`, which must outlive it.
WP_LFN ctx_t ctx_make(const launch_ctx_t* rec) {
  ctx_t c;
  c.rec = rec;
  c.raised = 0;
  return c;
}

/// Fills the shared record if this is the first fault of the launch (compare-and-swap of
/// `*fault_flag` from 0 to 1). Does not mark the thread: `raise` and its callers do.
WP_LFN void raise_record(const launch_ctx_t* rec, i32 kind, i32 arg, i32 ndim, const i64* index,
                         const i64* shape) {
  if (rec->fault_flag == nullptr || rec->fault == nullptr) return;
  bool first;
#if defined(__CUDACC__)
  first = atomicCAS(rec->fault_flag, 0u, 1u) == 0u;
#elif defined(__GNUC__) || defined(__clang__)
  u32 expected = 0u;
  first = __atomic_compare_exchange_n(rec->fault_flag, &expected, 1u, false, __ATOMIC_ACQ_REL,
                                      __ATOMIC_ACQUIRE);
#else
  first = *rec->fault_flag == 0u;  // single-threaded host fallback
  if (first) *rec->fault_flag = 1u;
#endif
  if (!first) return;
  fault_t* f = rec->fault;
  f->kind = kind;
  f->arg = arg;
  f->ndim = ndim;
  f->kernel = rec->kernel;
  f->launch = rec->launch;
  for (int k = 0; k < 4; ++k) {
    f->index[k] = (index != nullptr && k < ndim) ? index[k] : 0;
    f->shape[k] = (shape != nullptr && k < ndim) ? shape[k] : 0;
  }
#if defined(__CUDACC__)
  __threadfence();
#endif
}

/// Records a fault: marks this thread's context, and if this is the first fault of the launch
/// fills the shared record.
WP_LFN void raise(ctx_t* ctx, i32 kind, i32 arg = -1, i32 ndim = 0, const i64* index = nullptr,
                 const i64* shape = nullptr) {
  ctx->raised = 1;
  raise_record(ctx->rec, kind, arg, ndim, index, shape);
}

/// The out-of-bounds fault of a 1-D access, out of line: a call on the cold path keeps the
/// checked access itself a compare and a branch that rarely goes, where `raise` inlined at
/// every access lengthened the hot path (the DEM's contact kernel, H200: 204 us inlined,
/// 187 us with this call; 166 us with no checks at all). It takes the launch's record alone
/// (the caller marks its thread's ctx_t): in a kernel that record is the entry's
/// `WP_GRID_CONST` parameter, whose address costs no register to keep. The context's address
/// would move the thread's ctx_t to local memory (394 us), and the record by value kept its
/// five fields live in registers through the kernel (the BVH box query: 46 registers against
/// 38).
#if defined(__CUDACC__)
static __device__ __noinline__ void raise_out_of_bounds_1d(const launch_ctx_t* rec, i32 arg,
                                                           i64 index, i64 len) {
#else
inline void raise_out_of_bounds_1d(const launch_ctx_t* rec, i32 arg, i64 index, i64 len) {
#endif
  const i64 idx[1] = {index};
  const i64 shape[1] = {len};
  raise_record(rec, FAULT_OUT_OF_BOUNDS, arg, 1, idx, shape);
}

/// True once this thread raised a fault.
WP_LFN bool faulted(const ctx_t* ctx) { return ctx->raised != 0; }

/// A failed assertion (`assert!`, `debug_assert!` in debug mode, `expect_*`) at `line` and
/// `column` of the user's source, in the thread of flat launch index `thread` (-1 in a func).
/// The thread goes on, as after any fault on a GPU.
WP_LFN void assert_fail(ctx_t* ctx, i64 line, i64 column, i64 thread) {
  const i64 at[3] = {line, column, thread};
  raise(ctx, FAULT_ASSERTION, -1, 3, at, nullptr);
}

/// Whether the launch runs in the runtime's debug mode (the guard of `debug_assert!`): the
/// same for every thread of a launch, so the branch on it is uniform.
WP_LFN bool debug_mode(const ctx_t* ctx) { return (ctx->rec->flags & CTX_DEBUG) != 0; }

// ------------------------------------------------------------------------------------------
// Casts: Rust `as`
// ------------------------------------------------------------------------------------------

/// `x as To` with Rust's semantics: float -> int saturates (NaN -> 0, no C++ UB); int -> int
/// truncates or sign/zero-extends; int -> float and float -> float round to nearest;
/// bool -> int is 0 or 1.
template <typename To, typename From>
WP_FN To cast(From x) {
  if constexpr (detail::same_type<From, To>::value) {
    return x;
  } else if constexpr (detail::same_type<To, f16>::value) {
    // To f16: f64 rounded once; f32 directly; integers through f32 (exact below 2^24, and
    // infinite in f16 either way above).
    if constexpr (detail::same_type<From, f64>::value) {
      return f16_from_f64(x);
    } else if constexpr (num<From>::is_bool) {
      return f16_from_f32(x ? 1.0f : 0.0f);
    } else {
      return f16_from_f32((f32)x);
    }
  } else if constexpr (detail::same_type<From, f16>::value) {
    return cast<To>(f16_to_f32(x));  // f16 -> f32 is exact; then Rust's rules from f32
  } else if constexpr (detail::same_type<To, bf16>::value) {
    // To bf16: rounded once from every type; integers of more than 24 bits through the
    // sticky fold (u64_to_bf16_bits), where f32 would round first.
    if constexpr (detail::same_type<From, f64>::value) {
      return bf16_from_f64(x);
    } else if constexpr (num<From>::is_bool) {
      return bf16_from_f32(x ? 1.0f : 0.0f);
    } else if constexpr (num<From>::is_int) {
      if constexpr (num<From>::is_signed) {
        const u64 m = x < 0 ? (u64)0 - (u64)(i64)x : (u64)(i64)x;
        const u16 b = u64_to_bf16_bits(m);
        return bf16_from_bits(x < 0 ? (u16)(b | 0x8000u) : b);
      } else {
        return bf16_from_bits(u64_to_bf16_bits((u64)x));
      }
    } else {
      return bf16_from_f32((f32)x);  // f32 directly; f16 -> f32 exact, then once
    }
  } else if constexpr (detail::same_type<From, bf16>::value) {
    return cast<To>(bf16_to_f32(x));  // bf16 -> f32 is exact; then Rust's rules from f32
  } else if constexpr (num<From>::is_float && num<To>::is_int) {
    if (!(x == x)) return (To)0;
    if constexpr (num<To>::is_signed) {
      if (x <= (From)num<To>::lo) return num<To>::min_value;
    } else {
      if (x <= (From)0) return (To)0;
    }
    if (x >= (From)num<To>::hi) return num<To>::max_value;
    return (To)x;  // in range after truncation
  } else if constexpr (num<From>::is_int && num<To>::is_int) {
    return (To)(typename num<To>::unsigned_t)x;  // modular
  } else if constexpr (num<From>::is_bool && num<To>::is_int) {
    return x ? (To)1 : (To)0;
  } else {
    return (To)x;  // int -> float, float -> float, identity
  }
}

// ------------------------------------------------------------------------------------------
// Integer semantics (warp_core::ops::WrapInt): wrapping + - * neg, checked / %, masked shifts
// ------------------------------------------------------------------------------------------

#define WP_INT_OPS(T)                                                                       \
  WP_LFN T w_add(T a, T b) {                                                                 \
    typedef num<T>::unsigned_t U;                                                           \
    typedef num<T>::wide_t W;                                                               \
    return (T)(U)((W)(U)a + (W)(U)b);                                                       \
  }                                                                                         \
  WP_LFN T w_sub(T a, T b) {                                                                 \
    typedef num<T>::unsigned_t U;                                                           \
    typedef num<T>::wide_t W;                                                               \
    return (T)(U)((W)(U)a - (W)(U)b);                                                       \
  }                                                                                         \
  WP_LFN T w_mul(T a, T b) {                                                                 \
    typedef num<T>::unsigned_t U;                                                           \
    typedef num<T>::wide_t W;                                                               \
    return (T)(U)((W)(U)a * (W)(U)b);                                                       \
  }                                                                                         \
  WP_LFN T w_neg(T a) {                                                                      \
    typedef num<T>::unsigned_t U;                                                           \
    typedef num<T>::wide_t W;                                                               \
    return (T)(U)((W)0 - (W)(U)a);                                                          \
  }                                                                                         \
  /* `/`: DivisionByZero fault (returns 0) on b == 0; MIN / -1 wraps to MIN. */             \
  WP_LFN T w_div(T a, T b, ctx_t* ctx) {                                                     \
    if (b == (T)0) {                                                                        \
      raise(ctx, FAULT_DIVISION_BY_ZERO);                                                   \
      return (T)0;                                                                          \
    }                                                                                       \
    if (num<T>::is_signed && a == num<T>::min_value && b == (T)-1) return a;                \
    return (T)(a / b);                                                                      \
  }                                                                                         \
  /* `%`: DivisionByZero fault (returns 0) on b == 0; MIN % -1 is 0. Sign of the dividend. */ \
  WP_LFN T w_rem(T a, T b, ctx_t* ctx) {                                                     \
    if (b == (T)0) {                                                                        \
      raise(ctx, FAULT_DIVISION_BY_ZERO);                                                   \
      return (T)0;                                                                          \
    }                                                                                       \
    if (num<T>::is_signed && a == num<T>::min_value && b == (T)-1) return (T)0;             \
    return (T)(a % b);                                                                      \
  }                                                                                         \
  /* `<<`: the shift amount is masked to the bit width (Rust wrapping_shl). */              \
  WP_LFN T w_shl(T a, u32 s) {                                                               \
    typedef num<T>::unsigned_t U;                                                           \
    typedef num<T>::wide_t W;                                                               \
    return (T)(U)((W)(U)a << (s & (u32)(num<T>::bits - 1)));                                \
  }                                                                                         \
  /* `>>`: arithmetic for signed types, amount masked (Rust wrapping_shr). */               \
  WP_LFN T w_shr(T a, u32 s) { return (T)(a >> (s & (u32)(num<T>::bits - 1))); }

WP_INT_OPS(i8)
WP_INT_OPS(i16)
WP_INT_OPS(i32)
WP_INT_OPS(i64)
WP_INT_OPS(u8)
WP_INT_OPS(u16)
WP_INT_OPS(u32)
WP_INT_OPS(u64)
#undef WP_INT_OPS

/// Float `%` (Rust's `%` on f32/f64 is C's fmod: the result has the sign of the dividend).
WP_LFN f32 frem(f32 a, f32 b) { return ::fmodf(a, b); }
WP_LFN f64 frem(f64 a, f64 b) { return ::fmod(a, b); }
WP_LFN f32 fmod(f32 a, f32 b) { return ::fmodf(a, b); }  // same as frem
WP_LFN f64 fmod(f64 a, f64 b) { return ::fmod(a, b); }
// f16 `%`: fmod in f32 (exact), rounded to f16 (exact too), as `half`'s `%`.
WP_LFN f16 frem(f16 a, f16 b) { return f16_from_f32(::fmodf(f16_to_f32(a), f16_to_f32(b))); }
WP_LFN f16 fmod(f16 a, f16 b) { return frem(a, b); }
WP_LFN bf16 frem(bf16 a, bf16 b) { return bf16_from_f32(::fmodf(bf16_to_f32(a), bf16_to_f32(b))); }
WP_LFN bf16 fmod(bf16 a, bf16 b) { return frem(a, b); }

namespace detail {
// Scalar arithmetic of builtins (warp_core::builtins::Scalar): wrapping for ints, IEEE else.
#define WP_S_INT(T)                                       \
  WP_LFN T s_add(T a, T b) { return w_add(a, b); }         \
  WP_LFN T s_sub(T a, T b) { return w_sub(a, b); }         \
  WP_LFN T s_mul(T a, T b) { return w_mul(a, b); }
WP_S_INT(i8)
WP_S_INT(i16)
WP_S_INT(i32)
WP_S_INT(i64)
WP_S_INT(u8)
WP_S_INT(u16)
WP_S_INT(u32)
WP_S_INT(u64)
#undef WP_S_INT
WP_LFN f32 s_add(f32 a, f32 b) { return a + b; }
WP_LFN f32 s_sub(f32 a, f32 b) { return a - b; }
WP_LFN f32 s_mul(f32 a, f32 b) { return a * b; }
WP_LFN f64 s_add(f64 a, f64 b) { return a + b; }
WP_LFN f64 s_sub(f64 a, f64 b) { return a - b; }
WP_LFN f64 s_mul(f64 a, f64 b) { return a * b; }
// f16: its operators (one f32 operation, rounded once), as `half`'s.
WP_LFN f16 s_add(f16 a, f16 b) { return a + b; }
WP_LFN f16 s_sub(f16 a, f16 b) { return a - b; }
WP_LFN f16 s_mul(f16 a, f16 b) { return a * b; }
WP_LFN bf16 s_add(bf16 a, bf16 b) { return a + b; }
WP_LFN bf16 s_sub(bf16 a, bf16 b) { return a - b; }
WP_LFN bf16 s_mul(bf16 a, bf16 b) { return a * b; }
}  // namespace detail

// ------------------------------------------------------------------------------------------
// Vectors (glam 0.30 on x86_64)
// ------------------------------------------------------------------------------------------

/// Traits of vector, matrix and quaternion types: `scalar`, `N` (components, matrices: number
/// of scalars), `get(v, i)` / `at(v, i)` (component i, x first).
template <typename V>
struct vec_traits {
  static constexpr bool is_vec = false;
};

#define WP_VEC_COMMON(V, S, NN, GET)                                                  \
  template <>                                                                         \
  struct vec_traits<V> {                                                              \
    typedef S scalar;                                                                 \
    static constexpr int N = NN;                                                      \
    static constexpr bool is_vec = true;                                              \
    static WP_FN S get(const V& v, int i) { return GET; }                             \
    static WP_FN S& at(V& v, int i) { return GET; }                                   \
  };                                                                                  \
  WP_LFN V V##_splat(S s) {                                                            \
    V r;                                                                              \
    for (int i = 0; i < NN; ++i) vec_traits<V>::at(r, i) = s;                         \
    return r;                                                                         \
  }                                                                                   \
  WP_LFN V V##_ZERO() { return V##_splat((S)0); }                                      \
  WP_LFN V V##_ONE() { return V##_splat((S)1); }                                       \
  WP_LFN V V##_unit(int k, S s) {                                                      \
    V r = V##_ZERO();                                                                 \
    vec_traits<V>::at(r, k) = s;                                                      \
    return r;                                                                         \
  }                                                                                   \
  WP_LFN V V##_X() { return V##_unit(0, (S)1); }                                       \
  WP_LFN V V##_Y() { return V##_unit(1, (S)1); }                                       \
  WP_LFN bool operator==(const V& a, const V& b) {                                     \
    bool r = true;                                                                    \
    for (int i = 0; i < NN; ++i) r = r && (vec_traits<V>::get(a, i) == vec_traits<V>::get(b, i)); \
    return r;                                                                         \
  }                                                                                   \
  WP_LFN bool operator!=(const V& a, const V& b) { return !(a == b); }

#define WP_GET2 (i == 0 ? v.x : v.y)
#define WP_GET3 (i == 0 ? v.x : (i == 1 ? v.y : v.z))
#define WP_GET4 (i == 0 ? v.x : (i == 1 ? v.y : (i == 2 ? v.z : v.w)))

#define WP_VEC2(V, S, AL)                                                            \
  struct alignas(AL) V {                                                             \
    S x, y;                                                                          \
  };                                                                                 \
  WP_LFN V V##_new(S x, S y) {                                                        \
    V r;                                                                             \
    r.x = x;                                                                         \
    r.y = y;                                                                         \
    return r;                                                                        \
  }                                                                                  \
  WP_VEC_COMMON(V, S, 2, WP_GET2)
#define WP_VEC3(V, S, AL)                                                            \
  struct alignas(AL) V {                                                             \
    S x, y, z;                                                                       \
  };                                                                                 \
  WP_LFN V V##_new(S x, S y, S z) {                                                   \
    V r;                                                                             \
    r.x = x;                                                                         \
    r.y = y;                                                                         \
    r.z = z;                                                                         \
    return r;                                                                        \
  }                                                                                  \
  WP_VEC_COMMON(V, S, 3, WP_GET3)                                                    \
  WP_LFN V V##_Z() { return V##_unit(2, (S)1); }
#define WP_VEC4(V, S, AL)                                                            \
  struct alignas(AL) V {                                                             \
    S x, y, z, w;                                                                    \
  };                                                                                 \
  WP_LFN V V##_new(S x, S y, S z, S w) {                                              \
    V r;                                                                             \
    r.x = x;                                                                         \
    r.y = y;                                                                         \
    r.z = z;                                                                         \
    r.w = w;                                                                         \
    return r;                                                                        \
  }                                                                                  \
  WP_VEC_COMMON(V, S, 4, WP_GET4)                                                    \
  WP_LFN V V##_Z() { return V##_unit(2, (S)1); }                                      \
  WP_LFN V V##_W() { return V##_unit(3, (S)1); }

WP_VEC2(Vec2, f32, 4)
WP_VEC3(Vec3, f32, 4)
WP_VEC4(Vec4, f32, 16)  // glam's Vec4 is an __m128 on x86_64
WP_VEC2(DVec2, f64, 8)
WP_VEC3(DVec3, f64, 8)
WP_VEC4(DVec4, f64, 8)
WP_VEC2(IVec2, i32, 4)
WP_VEC3(IVec3, i32, 4)
WP_VEC4(IVec4, i32, 4)
WP_VEC2(UVec2, u32, 4)
WP_VEC3(UVec3, u32, 4)
WP_VEC4(UVec4, u32, 4)

// Signed constants (float and IVec): NEG_ONE, NEG_X.. NEG_W; MIN/MAX for every vector.
#define WP_VEC_NEG2(V, S)                                        \
  WP_LFN V V##_NEG_ONE() { return V##_splat((S)-1); }             \
  WP_LFN V V##_NEG_X() { return V##_unit(0, (S)-1); }             \
  WP_LFN V V##_NEG_Y() { return V##_unit(1, (S)-1); }
#define WP_VEC_NEG3(V, S) \
  WP_VEC_NEG2(V, S)       \
  WP_LFN V V##_NEG_Z() { return V##_unit(2, (S)-1); }
#define WP_VEC_NEG4(V, S) \
  WP_VEC_NEG3(V, S)       \
  WP_LFN V V##_NEG_W() { return V##_unit(3, (S)-1); }
WP_VEC_NEG2(Vec2, f32)
WP_VEC_NEG3(Vec3, f32)
WP_VEC_NEG4(Vec4, f32)
WP_VEC_NEG2(DVec2, f64)
WP_VEC_NEG3(DVec3, f64)
WP_VEC_NEG4(DVec4, f64)
WP_VEC_NEG2(IVec2, i32)
WP_VEC_NEG3(IVec3, i32)
WP_VEC_NEG4(IVec4, i32)
#undef WP_VEC_NEG2
#undef WP_VEC_NEG3
#undef WP_VEC_NEG4

#define WP_VEC_FLOAT_CONSTS(V, S)                                      \
  WP_LFN V V##_MIN() { return V##_splat(-float_max<S>()); }             \
  WP_LFN V V##_MAX() { return V##_splat(float_max<S>()); }              \
  WP_LFN V V##_INFINITY() { return V##_splat(float_inf<S>()); }         \
  WP_LFN V V##_NEG_INFINITY() { return V##_splat(-float_inf<S>()); }    \
  WP_LFN V V##_NAN() { return V##_splat(float_nan<S>()); }
WP_VEC_FLOAT_CONSTS(Vec2, f32)
WP_VEC_FLOAT_CONSTS(Vec3, f32)
WP_VEC_FLOAT_CONSTS(Vec4, f32)
WP_VEC_FLOAT_CONSTS(DVec2, f64)
WP_VEC_FLOAT_CONSTS(DVec3, f64)
WP_VEC_FLOAT_CONSTS(DVec4, f64)
#undef WP_VEC_FLOAT_CONSTS
#define WP_VEC_INT_CONSTS(V, S)                                        \
  WP_LFN V V##_MIN() { return V##_splat(num<S>::min_value); }           \
  WP_LFN V V##_MAX() { return V##_splat(num<S>::max_value); }
WP_VEC_INT_CONSTS(IVec2, i32)
WP_VEC_INT_CONSTS(IVec3, i32)
WP_VEC_INT_CONSTS(IVec4, i32)
WP_VEC_INT_CONSTS(UVec2, u32)
WP_VEC_INT_CONSTS(UVec3, u32)
WP_VEC_INT_CONSTS(UVec4, u32)
#undef WP_VEC_INT_CONSTS

#undef WP_VEC2
#undef WP_VEC3
#undef WP_VEC4
#undef WP_VEC_COMMON

namespace detail {
template <typename V, typename F>
WP_FN V vmap(const V& a, F f) {
  V r;
  for (int i = 0; i < vec_traits<V>::N; ++i) vec_traits<V>::at(r, i) = f(vec_traits<V>::get(a, i));
  return r;
}
template <typename V, typename F>
WP_FN V vzip(const V& a, const V& b, F f) {
  V r;
  for (int i = 0; i < vec_traits<V>::N; ++i)
    vec_traits<V>::at(r, i) = f(vec_traits<V>::get(a, i), vec_traits<V>::get(b, i));
  return r;
}
/// glam's SSE floor (DirectXMath XMVectorFloor): as floorf except that -0.0 floors to +0.0
/// (and values in (-1, 0) go through truncation then -1). Used by Vec4's `%` only.
WP_LFN f32 sse_floor(f32 v) {
  const u32 mag = f32_to_bits(v) & 0x7fffffffu;
  if ((i32)mag < (i32)0x4b000000) {  // |v| < 2^23: has a fraction; NaN and inf excluded
    f32 r = (f32)(i32)v;             // truncate (cvttps2dq + cvtdq2ps)
    if (r > v) r = r + -1.0f;
    return r;
  }
  return v;
}
}  // namespace detail

// Float vector arithmetic: componentwise, glam's operators.
#define WP_FVEC_OPS(V, S)                                                                        \
  WP_LFN V operator+(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return x + y; }); } \
  WP_LFN V operator-(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return x - y; }); } \
  WP_LFN V operator*(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return x * y; }); } \
  WP_LFN V operator/(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return x / y; }); } \
  WP_LFN V operator+(const V& a, S s) { return a + V##_splat(s); }                               \
  WP_LFN V operator-(const V& a, S s) { return a - V##_splat(s); }                               \
  WP_LFN V operator*(const V& a, S s) { return a * V##_splat(s); }                               \
  WP_LFN V operator/(const V& a, S s) { return a / V##_splat(s); }                               \
  WP_LFN V operator%(const V& a, S s) { return a % V##_splat(s); }                               \
  WP_LFN V operator+(S s, const V& a) { return V##_splat(s) + a; }                               \
  WP_LFN V operator-(S s, const V& a) { return V##_splat(s) - a; }                               \
  WP_LFN V operator*(S s, const V& a) { return V##_splat(s) * a; }                               \
  WP_LFN V operator/(S s, const V& a) { return V##_splat(s) / a; }                               \
  WP_LFN V operator%(S s, const V& a) { return V##_splat(s) % a; }                               \
  WP_LFN V operator-(const V& a) { return detail::vmap(a, [](S x) { return -x; }); }            \
  WP_LFN V& operator+=(V& a, const V& b) { return a = a + b; }                                   \
  WP_LFN V& operator-=(V& a, const V& b) { return a = a - b; }                                   \
  WP_LFN V& operator*=(V& a, const V& b) { return a = a * b; }                                   \
  WP_LFN V& operator/=(V& a, const V& b) { return a = a / b; }                                   \
  WP_LFN V& operator%=(V& a, const V& b) { return a = a % b; }                                   \
  WP_LFN V& operator*=(V& a, S s) { return a = a * s; }                                          \
  WP_LFN V& operator/=(V& a, S s) { return a = a / s; }

// `%` is Rust's float `%` (fmod) per component, except for Vec4: glam's SSE Vec4 computes
// `a - floor(a / b) * b` (a floored modulo, with glam's SSE floor).
WP_LFN Vec2 operator%(const Vec2& a, const Vec2& b) { return detail::vzip(a, b, [](f32 x, f32 y) { return frem(x, y); }); }
WP_LFN Vec3 operator%(const Vec3& a, const Vec3& b) { return detail::vzip(a, b, [](f32 x, f32 y) { return frem(x, y); }); }
WP_LFN Vec4 operator%(const Vec4& a, const Vec4& b) {
  return detail::vzip(a, b, [](f32 x, f32 y) { return x - detail::sse_floor(x / y) * y; });
}
WP_LFN DVec2 operator%(const DVec2& a, const DVec2& b) { return detail::vzip(a, b, [](f64 x, f64 y) { return frem(x, y); }); }
WP_LFN DVec3 operator%(const DVec3& a, const DVec3& b) { return detail::vzip(a, b, [](f64 x, f64 y) { return frem(x, y); }); }
WP_LFN DVec4 operator%(const DVec4& a, const DVec4& b) { return detail::vzip(a, b, [](f64 x, f64 y) { return frem(x, y); }); }

WP_FVEC_OPS(Vec2, f32)
WP_FVEC_OPS(Vec3, f32)
WP_FVEC_OPS(Vec4, f32)
WP_FVEC_OPS(DVec2, f64)
WP_FVEC_OPS(DVec3, f64)
WP_FVEC_OPS(DVec4, f64)
#undef WP_FVEC_OPS

// Integer vectors: arithmetic only through w_* (componentwise; a zero in any component of a
// divisor faults before anything is computed, as in warp_core::ops).
#define WP_IVEC_OPS(V, S)                                                                        \
  WP_LFN V w_add(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return w_add(x, y); }); } \
  WP_LFN V w_sub(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return w_sub(x, y); }); } \
  WP_LFN V w_mul(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return w_mul(x, y); }); } \
  WP_LFN V w_neg(const V& a) { return detail::vmap(a, [](S x) { return w_neg(x); }); }           \
  WP_LFN bool any_zero(const V& b) {                                                             \
    bool z = false;                                                                             \
    for (int i = 0; i < vec_traits<V>::N; ++i) z = z || vec_traits<V>::get(b, i) == (S)0;      \
    return z;                                                                                   \
  }                                                                                             \
  WP_LFN V w_div(const V& a, const V& b, ctx_t* ctx) {                                           \
    if (any_zero(b)) {                                                                          \
      raise(ctx, FAULT_DIVISION_BY_ZERO);                                                       \
      return V##_ZERO();                                                                        \
    }                                                                                           \
    return detail::vzip(a, b, [ctx](S x, S y) { return w_div(x, y, ctx); });                    \
  }                                                                                             \
  WP_LFN V w_rem(const V& a, const V& b, ctx_t* ctx) {                                           \
    if (any_zero(b)) {                                                                          \
      raise(ctx, FAULT_DIVISION_BY_ZERO);                                                       \
      return V##_ZERO();                                                                        \
    }                                                                                           \
    return detail::vzip(a, b, [ctx](S x, S y) { return w_rem(x, y, ctx); });                    \
  }                                                                                             \
  WP_LFN V w_shl(const V& a, u32 s) { return detail::vmap(a, [s](S x) { return w_shl(x, s); }); } \
  WP_LFN V w_shr(const V& a, u32 s) { return detail::vmap(a, [s](S x) { return w_shr(x, s); }); } \
  WP_LFN V operator&(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return (S)(x & y); }); } \
  WP_LFN V operator|(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return (S)(x | y); }); } \
  WP_LFN V operator^(const V& a, const V& b) { return detail::vzip(a, b, [](S x, S y) { return (S)(x ^ y); }); } \
  WP_LFN V operator~(const V& a) { return detail::vmap(a, [](S x) { return (S)~x; }); }
WP_IVEC_OPS(IVec2, i32)
WP_IVEC_OPS(IVec3, i32)
WP_IVEC_OPS(IVec4, i32)
WP_IVEC_OPS(UVec2, u32)
WP_IVEC_OPS(UVec3, u32)
WP_IVEC_OPS(UVec4, u32)
#undef WP_IVEC_OPS

// ------------------------------------------------------------------------------------------
// Matrices (column-major, columns x_axis.. w_axis)
// ------------------------------------------------------------------------------------------

struct alignas(16) Mat2 {  // glam's Mat2 is one __m128 on x86_64
  Vec2 x_axis, y_axis;
};
struct Mat3 {
  Vec3 x_axis, y_axis, z_axis;
};
struct alignas(16) Mat4 {
  Vec4 x_axis, y_axis, z_axis, w_axis;
};
struct DMat2 {
  DVec2 x_axis, y_axis;
};
struct DMat3 {
  DVec3 x_axis, y_axis, z_axis;
};
struct DMat4 {
  DVec4 x_axis, y_axis, z_axis, w_axis;
};

/// Column access for matrices: `mat_traits<M>::col(m, i)`.
template <typename M>
struct mat_traits {
  static constexpr bool is_mat = false;
};

#define WP_MAT_COMMON(M, V, S, NN, GETC, FROMCOLS_PARAMS, FROMCOLS_BODY)                       \
  template <>                                                                                  \
  struct mat_traits<M> {                                                                       \
    typedef V column;                                                                          \
    typedef S scalar;                                                                          \
    static constexpr int N = NN;                                                               \
    static constexpr bool is_mat = true;                                                       \
    static WP_FN V get(const M& m, int i) { return GETC; }                                     \
    static WP_FN V& at(M& m, int i) { return GETC; }                                           \
  };                                                                                           \
  template <>                                                                                  \
  struct vec_traits<M> {                                                                       \
    typedef S scalar;                                                                          \
    static constexpr int N = NN * NN;                                                          \
    static constexpr bool is_vec = false;                                                      \
    static WP_FN S get(const M& m, int i) {                                                    \
      return vec_traits<V>::get(mat_traits<M>::get(m, i / NN), i % NN);                        \
    }                                                                                          \
    static WP_FN S& at(M& m, int i) { return vec_traits<V>::at(mat_traits<M>::at(m, i / NN), i % NN); } \
  };                                                                                           \
  WP_LFN M M##_from_cols FROMCOLS_PARAMS {                                                      \
    M m;                                                                                       \
    FROMCOLS_BODY;                                                                             \
    return m;                                                                                  \
  }                                                                                            \
  WP_LFN M M##_from_diagonal(const V& d) {                                                      \
    M m;                                                                                       \
    for (int i = 0; i < NN; ++i) {                                                             \
      V c = V##_ZERO();                                                                        \
      vec_traits<V>::at(c, i) = vec_traits<V>::get(d, i);                                      \
      mat_traits<M>::at(m, i) = c;                                                             \
    }                                                                                          \
    return m;                                                                                  \
  }                                                                                            \
  WP_LFN M M##_splat_cols(const V& c) {                                                         \
    M m;                                                                                       \
    for (int i = 0; i < NN; ++i) mat_traits<M>::at(m, i) = c;                                  \
    return m;                                                                                  \
  }                                                                                            \
  WP_LFN M M##_ZERO() { return M##_splat_cols(V##_ZERO()); }                                    \
  WP_LFN M M##_NAN() { return M##_splat_cols(V##_NAN()); }                                      \
  WP_LFN M M##_IDENTITY() { return M##_from_diagonal(V##_ONE()); }                              \
  template <typename F>                                                                        \
  WP_FN M mmap_##M(const M& a, F f) {                                                          \
    M r;                                                                                       \
    for (int i = 0; i < NN; ++i) mat_traits<M>::at(r, i) = f(mat_traits<M>::get(a, i));       \
    return r;                                                                                  \
  }                                                                                            \
  WP_LFN M operator+(const M& a, const M& b) {                                                  \
    M r;                                                                                       \
    for (int i = 0; i < NN; ++i) mat_traits<M>::at(r, i) = mat_traits<M>::get(a, i) + mat_traits<M>::get(b, i); \
    return r;                                                                                  \
  }                                                                                            \
  WP_LFN M operator-(const M& a, const M& b) {                                                  \
    M r;                                                                                       \
    for (int i = 0; i < NN; ++i) mat_traits<M>::at(r, i) = mat_traits<M>::get(a, i) - mat_traits<M>::get(b, i); \
    return r;                                                                                  \
  }                                                                                            \
  WP_LFN M operator-(const M& a) { return mmap_##M(a, [](const V& c) { return -c; }); }         \
  /* M * v: x_axis * v.x + y_axis * v.y + ..., summed left to right. */                        \
  WP_LFN V operator*(const M& a, const V& v) {                                                  \
    V r = mat_traits<M>::get(a, 0) * vec_traits<V>::get(v, 0);                                 \
    for (int i = 1; i < NN; ++i) r = r + mat_traits<M>::get(a, i) * vec_traits<V>::get(v, i);  \
    return r;                                                                                  \
  }                                                                                            \
  WP_LFN M operator*(const M& a, const M& b) {                                                  \
    M r;                                                                                       \
    for (int i = 0; i < NN; ++i) mat_traits<M>::at(r, i) = a * mat_traits<M>::get(b, i);       \
    return r;                                                                                  \
  }                                                                                            \
  WP_LFN M operator*(const M& a, S s) { return mmap_##M(a, [s](const V& c) { return c * s; }); } \
  WP_LFN M operator*(S s, const M& a) { return a * s; }                                         \
  WP_LFN M operator/(const M& a, S s) { return mmap_##M(a, [s](const V& c) { return c / s; }); } \
  /* glam 0.30 quirk: `s / M` is implemented as `M.div_scalar(s)`, i.e. M / s. */              \
  WP_LFN M operator/(S s, const M& a) { return a / s; }                                         \
  WP_LFN M& operator+=(M& a, const M& b) { return a = a + b; }                                  \
  WP_LFN M& operator-=(M& a, const M& b) { return a = a - b; }                                  \
  WP_LFN M& operator*=(M& a, const M& b) { return a = a * b; }                                  \
  WP_LFN M& operator*=(M& a, S s) { return a = a * s; }                                         \
  WP_LFN M& operator/=(M& a, S s) { return a = a / s; }                                         \
  WP_LFN bool operator==(const M& a, const M& b) {                                              \
    bool r = true;                                                                             \
    for (int i = 0; i < NN; ++i) r = r && (mat_traits<M>::get(a, i) == mat_traits<M>::get(b, i)); \
    return r;                                                                                  \
  }                                                                                            \
  WP_LFN bool operator!=(const M& a, const M& b) { return !(a == b); }

#define WP_GETC2 (i == 0 ? m.x_axis : m.y_axis)
#define WP_GETC3 (i == 0 ? m.x_axis : (i == 1 ? m.y_axis : m.z_axis))
#define WP_GETC4 (i == 0 ? m.x_axis : (i == 1 ? m.y_axis : (i == 2 ? m.z_axis : m.w_axis)))
#define WP_COMMA ,

WP_MAT_COMMON(Mat2, Vec2, f32, 2, WP_GETC2, (const Vec2& x WP_COMMA const Vec2& y),
              m.x_axis = x; m.y_axis = y)
WP_MAT_COMMON(Mat3, Vec3, f32, 3, WP_GETC3,
              (const Vec3& x WP_COMMA const Vec3& y WP_COMMA const Vec3& z),
              m.x_axis = x; m.y_axis = y; m.z_axis = z)
WP_MAT_COMMON(Mat4, Vec4, f32, 4, WP_GETC4,
              (const Vec4& x WP_COMMA const Vec4& y WP_COMMA const Vec4& z WP_COMMA const Vec4& w),
              m.x_axis = x; m.y_axis = y; m.z_axis = z; m.w_axis = w)
WP_MAT_COMMON(DMat2, DVec2, f64, 2, WP_GETC2, (const DVec2& x WP_COMMA const DVec2& y),
              m.x_axis = x; m.y_axis = y)
WP_MAT_COMMON(DMat3, DVec3, f64, 3, WP_GETC3,
              (const DVec3& x WP_COMMA const DVec3& y WP_COMMA const DVec3& z),
              m.x_axis = x; m.y_axis = y; m.z_axis = z)
WP_MAT_COMMON(DMat4, DVec4, f64, 4, WP_GETC4,
              (const DVec4& x WP_COMMA const DVec4& y WP_COMMA const DVec4& z WP_COMMA const DVec4& w),
              m.x_axis = x; m.y_axis = y; m.z_axis = z; m.w_axis = w)
#undef WP_MAT_COMMON
#undef WP_GETC2
#undef WP_GETC3
#undef WP_GETC4
#undef WP_COMMA

// ------------------------------------------------------------------------------------------
// Quaternions (x, y, z, w)
// ------------------------------------------------------------------------------------------

struct alignas(16) Quat {  // an __m128 on x86_64
  f32 x, y, z, w;
};
struct DQuat {
  f64 x, y, z, w;
};

#define WP_QUAT_COMMON(Q, V3, S)                                                          \
  template <>                                                                             \
  struct vec_traits<Q> {                                                                  \
    typedef S scalar;                                                                     \
    static constexpr int N = 4;                                                           \
    static constexpr bool is_vec = false;                                                 \
    static WP_FN S get(const Q& v, int i) { return WP_GET4; }                             \
    static WP_FN S& at(Q& v, int i) { return WP_GET4; }                                   \
  };                                                                                      \
  WP_LFN Q Q##_from_xyzw(S x, S y, S z, S w) {                                             \
    Q q;                                                                                  \
    q.x = x;                                                                              \
    q.y = y;                                                                              \
    q.z = z;                                                                              \
    q.w = w;                                                                              \
    return q;                                                                             \
  }                                                                                       \
  WP_LFN Q Q##_IDENTITY() { return Q##_from_xyzw((S)0, (S)0, (S)0, (S)1); }                \
  WP_LFN Q Q##_NAN() {                                                                     \
    const S n = float_nan<S>();                                                           \
    return Q##_from_xyzw(n, n, n, n);                                                     \
  }                                                                                       \
  WP_LFN Q operator+(const Q& a, const Q& b) { return detail::vzip(a, b, [](S p, S q) { return p + q; }); } \
  WP_LFN Q operator-(const Q& a, const Q& b) { return detail::vzip(a, b, [](S p, S q) { return p - q; }); } \
  WP_LFN Q operator*(const Q& a, S s) { return detail::vmap(a, [s](S p) { return p * s; }); }   \
  WP_LFN Q operator/(const Q& a, S s) { return detail::vmap(a, [s](S p) { return p / s; }); }   \
  /* glam: -q is q * -1.0 */                                                              \
  WP_LFN Q operator-(const Q& a) { return a * (S)-1; }                                     \
  /* glam's mul_vec3: v*(w*w - b.b) + b*(2 v.b) + (b x v)*(2w), b = (x, y, z). */         \
  WP_LFN V3 operator*(const Q& q, const V3& v) {                                           \
    const S w = q.w;                                                                      \
    const V3 b = V3##_new(q.x, q.y, q.z);                                                 \
    const S b2 = (b.x * b.x + b.y * b.y) + b.z * b.z;                                     \
    const S vb = (v.x * b.x + v.y * b.y) + v.z * b.z;                                     \
    const V3 c = V3##_new(b.y * v.z - v.y * b.z, b.z * v.x - v.z * b.x, b.x * v.y - v.x * b.y); \
    return (v * (w * w - b2) + b * (vb * (S)2)) + c * (w * (S)2);                         \
  }                                                                                       \
  WP_LFN Q& operator+=(Q& a, const Q& b) { return a = a + b; }                             \
  WP_LFN Q& operator-=(Q& a, const Q& b) { return a = a - b; }                             \
  WP_LFN Q& operator*=(Q& a, const Q& b) { return a = a * b; }                             \
  WP_LFN Q& operator*=(Q& a, S s) { return a = a * s; }                                    \
  WP_LFN Q& operator/=(Q& a, S s) { return a = a / s; }                                    \
  WP_LFN bool operator==(const Q& a, const Q& b) {                                         \
    return a.x == b.x && a.y == b.y && a.z == b.z && a.w == b.w;                          \
  }                                                                                       \
  WP_LFN bool operator!=(const Q& a, const Q& b) { return !(a == b); }

// Hamilton products, each in glam's exact evaluation order (they differ: Quat uses SSE).
struct Quat;
WP_FN Quat operator*(const Quat& l, const Quat& r);
struct DQuat;
WP_FN DQuat operator*(const DQuat& l, const DQuat& r);
WP_QUAT_COMMON(Quat, Vec3, f32)
WP_QUAT_COMMON(DQuat, DVec3, f64)
#undef WP_QUAT_COMMON
#undef WP_GET2
#undef WP_GET3
#undef WP_GET4

/// glam's SSE `Quat::mul_quat` (rtm::quat_mul), lane by lane.
WP_FN Quat operator*(const Quat& l, const Quat& r) {
  Quat q;
  q.x = (l.w * r.x + l.x * r.w) + (l.y * r.z - l.z * r.y);
  q.y = (l.w * r.y - l.x * r.z) + (l.y * r.w + l.z * r.x);
  q.z = (l.w * r.z + l.x * r.y) + (l.z * r.w - l.y * r.x);
  q.w = (l.w * r.w - l.x * r.x) + (-(l.y * r.y) - l.z * r.z);
  return q;
}
/// glam's scalar `DQuat::mul_quat`.
WP_FN DQuat operator*(const DQuat& l, const DQuat& r) {
  DQuat q;
  q.x = ((l.w * r.x + l.x * r.w) + l.y * r.z) - l.z * r.y;
  q.y = ((l.w * r.y - l.x * r.z) + l.y * r.w) + l.z * r.x;
  q.z = ((l.w * r.z + l.x * r.y) - l.y * r.x) + l.z * r.w;
  q.w = ((l.w * r.w - l.x * r.x) - l.y * r.y) - l.z * r.z;
  return q;
}

// ------------------------------------------------------------------------------------------
// Rigid transforms (warp-core's Transform, DTransform; warp-core/src/transform.rs)
// ------------------------------------------------------------------------------------------

// Transform: p at 0, a padding lane at 12 (zero in every transform made here, ignored by every
// operation), q at 16: 32 bytes, 16-byte aligned like Quat. DTransform: p at 0, q at 24, 56
// bytes. As lanes (vec_traits, N = 7): p.x, p.y, p.z, q.x, q.y, q.z, q.w.
// The operators here are the type's own (composition, lane-by-lane +, -, * by a scalar,
// negation, ==); the builtins are in wp_transform.h.
struct alignas(16) Transform {
  Vec3 p;
  f32 pad = 0.0f;
  Quat q;
};
struct DTransform {
  DVec3 p;
  DQuat q;
};

#define WP_XFORM_COMMON(X, V3, Q, S)                                                      \
  template <>                                                                             \
  struct vec_traits<X> {                                                                  \
    typedef S scalar;                                                                     \
    static constexpr int N = 7;                                                           \
    static constexpr bool is_vec = false;                                                 \
    static WP_FN S get(const X& t, int i) {                                               \
      return i < 3 ? vec_traits<V3>::get(t.p, i) : vec_traits<Q>::get(t.q, i - 3);        \
    }                                                                                     \
    static WP_FN S& at(X& t, int i) {                                                     \
      return i < 3 ? vec_traits<V3>::at(t.p, i) : vec_traits<Q>::at(t.q, i - 3);          \
    }                                                                                     \
  };                                                                                      \
  WP_LFN X X##_new(const V3& p, const Q& q) {                                              \
    X t;                                                                                  \
    t.p = p;                                                                              \
    t.q = q;                                                                              \
    return t;                                                                             \
  }                                                                                       \
  WP_LFN X X##_IDENTITY() { return X##_new(V3##_ZERO(), Q##_IDENTITY()); }                 \
  /* a * b: b applies first (Warp's transform_multiply). */                               \
  WP_LFN X operator*(const X& a, const X& b) { return X##_new(a.q * b.p + a.p, a.q * b.q); } \
  WP_LFN X operator*(const X& a, S s) { return X##_new(a.p * s, a.q * s); }                \
  WP_LFN X operator*(S s, const X& a) { return a * s; }                                    \
  WP_LFN X operator+(const X& a, const X& b) { return X##_new(a.p + b.p, a.q + b.q); }     \
  WP_LFN X operator-(const X& a, const X& b) { return X##_new(a.p - b.p, a.q - b.q); }     \
  WP_LFN X operator-(const X& a) { return X##_new(-a.p, -a.q); }                           \
  WP_LFN X& operator+=(X& a, const X& b) { return a = a + b; }                             \
  WP_LFN X& operator-=(X& a, const X& b) { return a = a - b; }                             \
  WP_LFN X& operator*=(X& a, const X& b) { return a = a * b; }                             \
  WP_LFN X& operator*=(X& a, S s) { return a = a * s; }                                    \
  WP_LFN bool operator==(const X& a, const X& b) { return a.p == b.p && a.q == b.q; }      \
  WP_LFN bool operator!=(const X& a, const X& b) { return !(a == b); }
WP_XFORM_COMMON(Transform, Vec3, Quat, f32)
WP_XFORM_COMMON(DTransform, DVec3, DQuat, f64)
#undef WP_XFORM_COMMON

// ------------------------------------------------------------------------------------------
// Spatial vectors and matrices (warp-core's SpatialVector, SpatialMatrix, DSpatialVector,
// DSpatialMatrix; warp-core/src/spatial.rs)
// ------------------------------------------------------------------------------------------

// A spatial vector is six scalars f0..f5 (a kernel's `v[k]` is `v.fk`), a spatial matrix six
// spatial vectors, its rows (row-major, as Warp's mat_t<6, 6>): no padding. As lanes
// (vec_traits): a vector's six, a matrix's 36 row by row. The operators here are the types'
// own (lane by lane +, -, negation, * and / by a scalar, ==; the matrix-vector and
// matrix-matrix products, each sum left to right in ascending index as warp-core's); the
// builtins are in wp_spatial.h.
struct SpatialVector {
  f32 f0, f1, f2, f3, f4, f5;
};
struct DSpatialVector {
  f64 f0, f1, f2, f3, f4, f5;
};
struct SpatialMatrix {
  SpatialVector f0, f1, f2, f3, f4, f5;
};
struct DSpatialMatrix {
  DSpatialVector f0, f1, f2, f3, f4, f5;
};

#define WP_SPATIAL_PICK6(x, i) \
  (i == 0 ? x.f0 : i == 1 ? x.f1 : i == 2 ? x.f2 : i == 3 ? x.f3 : i == 4 ? x.f4 : x.f5)
#define WP_SPATIAL_COMMON(SV, SM, V3, S)                                                        \
  template <>                                                                                   \
  struct vec_traits<SV> {                                                                       \
    typedef S scalar;                                                                           \
    static constexpr int N = 6;                                                                 \
    static constexpr bool is_vec = false;                                                       \
    static WP_FN S get(const SV& v, int i) { return WP_SPATIAL_PICK6(v, i); }                   \
    static WP_FN S& at(SV& v, int i) { return WP_SPATIAL_PICK6(v, i); }                         \
  };                                                                                            \
  WP_LFN const SV& SM##_row(const SM& m, int i) { return WP_SPATIAL_PICK6(m, i); }              \
  WP_LFN SV& SM##_row_at(SM& m, int i) { return WP_SPATIAL_PICK6(m, i); }                        \
  template <>                                                                                   \
  struct vec_traits<SM> {                                                                       \
    typedef S scalar;                                                                           \
    static constexpr int N = 36;                                                                \
    static constexpr bool is_vec = false;                                                       \
    static WP_FN S get(const SM& m, int i) { return vec_traits<SV>::get(SM##_row(m, i / 6), i % 6); } \
    static WP_FN S& at(SM& m, int i) { return vec_traits<SV>::at(SM##_row_at(m, i / 6), i % 6); } \
  };                                                                                            \
  WP_LFN SV SV##_new6(S a0, S a1, S a2, S a3, S a4, S a5) {                                      \
    SV r;                                                                                       \
    r.f0 = a0;                                                                                  \
    r.f1 = a1;                                                                                  \
    r.f2 = a2;                                                                                  \
    r.f3 = a3;                                                                                  \
    r.f4 = a4;                                                                                  \
    r.f5 = a5;                                                                                  \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN SV SV##_ZERO() { return SV##_new6((S)0, (S)0, (S)0, (S)0, (S)0, (S)0); }                \
  WP_LFN SV SV##_new(const V3& w, const V3& v) { return SV##_new6(w.x, w.y, w.z, v.x, v.y, v.z); } \
  WP_LFN SM SM##_from_rows(const SV& r0, const SV& r1, const SV& r2, const SV& r3, const SV& r4,  \
                          const SV& r5) {                                                       \
    SM m;                                                                                       \
    m.f0 = r0;                                                                                  \
    m.f1 = r1;                                                                                  \
    m.f2 = r2;                                                                                  \
    m.f3 = r3;                                                                                  \
    m.f4 = r4;                                                                                  \
    m.f5 = r5;                                                                                  \
    return m;                                                                                   \
  }                                                                                             \
  WP_LFN SM SM##_ZERO() {                                                                        \
    const SV z = SV##_ZERO();                                                                   \
    return SM##_from_rows(z, z, z, z, z, z);                                                    \
  }                                                                                             \
  WP_LFN SM SM##_IDENTITY() {                                                                    \
    SM m = SM##_ZERO();                                                                         \
    for (int i = 0; i < 6; ++i) vec_traits<SV>::at(SM##_row_at(m, i), i) = (S)1;               \
    return m;                                                                                   \
  }                                                                                             \
  WP_SPATIAL_LANES(SV, S)                                                                       \
  WP_SPATIAL_LANES(SM, S)                                                                       \
  /* ((((a0 b0 + a1 b1) + a2 b2) + a3 b3) + a4 b4) + a5 b5 */                                   \
  WP_LFN S SV##_dot(const SV& a, const SV& b) {                                                  \
    S r = a.f0 * b.f0;                                                                          \
    for (int k = 1; k < 6; ++k) r += vec_traits<SV>::get(a, k) * vec_traits<SV>::get(b, k);    \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN SV operator*(const SM& m, const SV& x) {                                                \
    SV r;                                                                                       \
    for (int i = 0; i < 6; ++i) vec_traits<SV>::at(r, i) = SV##_dot(SM##_row(m, i), x);        \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN SM operator*(const SM& a, const SM& b) {                                                \
    SM r;                                                                                       \
    for (int i = 0; i < 6; ++i)                                                                 \
      for (int j = 0; j < 6; ++j) {                                                             \
        S acc = vec_traits<SM>::get(a, i * 6) * vec_traits<SM>::get(b, j);                      \
        for (int k = 1; k < 6; ++k)                                                             \
          acc += vec_traits<SM>::get(a, i * 6 + k) * vec_traits<SM>::get(b, k * 6 + j);         \
        vec_traits<SM>::at(r, i * 6 + j) = acc;                                                 \
      }                                                                                         \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN SM& operator*=(SM& a, const SM& b) { return a = a * b; }
// Lane-by-lane operators of a spatial type T of scalar S.
#define WP_SPATIAL_LANES(T, S)                                                                  \
  WP_LFN T operator+(const T& a, const T& b) {                                                   \
    T r;                                                                                        \
    for (int k = 0; k < vec_traits<T>::N; ++k)                                                  \
      vec_traits<T>::at(r, k) = vec_traits<T>::get(a, k) + vec_traits<T>::get(b, k);           \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN T operator-(const T& a, const T& b) {                                                   \
    T r;                                                                                        \
    for (int k = 0; k < vec_traits<T>::N; ++k)                                                  \
      vec_traits<T>::at(r, k) = vec_traits<T>::get(a, k) - vec_traits<T>::get(b, k);           \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN T operator-(const T& a) {                                                               \
    T r;                                                                                        \
    for (int k = 0; k < vec_traits<T>::N; ++k) vec_traits<T>::at(r, k) = -vec_traits<T>::get(a, k); \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN T operator*(const T& a, S s) {                                                          \
    T r;                                                                                        \
    for (int k = 0; k < vec_traits<T>::N; ++k) vec_traits<T>::at(r, k) = vec_traits<T>::get(a, k) * s; \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN T operator*(S s, const T& a) {                                                          \
    T r;                                                                                        \
    for (int k = 0; k < vec_traits<T>::N; ++k) vec_traits<T>::at(r, k) = s * vec_traits<T>::get(a, k); \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN T operator/(const T& a, S s) {                                                          \
    T r;                                                                                        \
    for (int k = 0; k < vec_traits<T>::N; ++k) vec_traits<T>::at(r, k) = vec_traits<T>::get(a, k) / s; \
    return r;                                                                                   \
  }                                                                                             \
  WP_LFN T& operator+=(T& a, const T& b) { return a = a + b; }                                   \
  WP_LFN T& operator-=(T& a, const T& b) { return a = a - b; }                                   \
  WP_LFN T& operator*=(T& a, S s) { return a = a * s; }                                          \
  WP_LFN T& operator/=(T& a, S s) { return a = a / s; }                                          \
  WP_LFN bool operator==(const T& a, const T& b) {                                               \
    for (int k = 0; k < vec_traits<T>::N; ++k)                                                  \
      if (!(vec_traits<T>::get(a, k) == vec_traits<T>::get(b, k))) return false;                \
    return true;                                                                                \
  }                                                                                             \
  WP_LFN bool operator!=(const T& a, const T& b) { return !(a == b); }
WP_SPATIAL_COMMON(SpatialVector, SpatialMatrix, Vec3, f32)
WP_SPATIAL_COMMON(DSpatialVector, DSpatialMatrix, DVec3, f64)
#undef WP_SPATIAL_COMMON
#undef WP_SPATIAL_LANES
#undef WP_SPATIAL_PICK6

// ------------------------------------------------------------------------------------------
// Layout: glam 0.30, x86_64, default features (SSE2, no "cuda"/"scalar-math" feature)
// ------------------------------------------------------------------------------------------

#define WP_LAYOUT(T, SIZE, ALIGN) \
  static_assert(sizeof(T) == SIZE && alignof(T) == ALIGN, #T " must match glam's layout");
WP_LAYOUT(Vec2, 8, 4)
WP_LAYOUT(Vec3, 12, 4)
WP_LAYOUT(Vec4, 16, 16)
WP_LAYOUT(DVec2, 16, 8)
WP_LAYOUT(DVec3, 24, 8)
WP_LAYOUT(DVec4, 32, 8)
WP_LAYOUT(IVec2, 8, 4)
WP_LAYOUT(IVec3, 12, 4)
WP_LAYOUT(IVec4, 16, 4)
WP_LAYOUT(UVec2, 8, 4)
WP_LAYOUT(UVec3, 12, 4)
WP_LAYOUT(UVec4, 16, 4)
WP_LAYOUT(Mat2, 16, 16)
WP_LAYOUT(Mat3, 36, 4)
WP_LAYOUT(Mat4, 64, 16)
WP_LAYOUT(DMat2, 32, 8)
WP_LAYOUT(DMat3, 72, 8)
WP_LAYOUT(DMat4, 128, 8)
WP_LAYOUT(Quat, 16, 16)
WP_LAYOUT(DQuat, 32, 8)
WP_LAYOUT(Transform, 32, 16)  // p (12) + pad (4) + q (16): q at 16, as warp-core's
WP_LAYOUT(DTransform, 56, 8)  // p (24) + q (32): q at 24
WP_LAYOUT(SpatialVector, 24, 4)  // six f32, no padding (warp-core's SpatialVector)
WP_LAYOUT(DSpatialVector, 48, 8)
WP_LAYOUT(SpatialMatrix, 144, 4)  // six rows, row-major
WP_LAYOUT(DSpatialMatrix, 288, 8)
#undef WP_LAYOUT

// ------------------------------------------------------------------------------------------
// Literals (warp_core::ops::FromLiteral)
// ------------------------------------------------------------------------------------------

namespace detail {
template <typename T, bool IsVec = vec_traits<T>::is_vec>
struct literal;
template <typename T>
struct literal<T, false> {  // scalars
  static WP_FN T from_f64(f64 v) { return cast<T>(v); }
  static WP_FN T from_i64(i64 v) { return cast<T>(v); }
};
template <typename T>
struct literal<T, true> {  // vectors: splat
  typedef typename vec_traits<T>::scalar S;
  static WP_FN T splat(S s) {
    T r;
    for (int i = 0; i < vec_traits<T>::N; ++i) vec_traits<T>::at(r, i) = s;
    return r;
  }
  static WP_FN T from_f64(f64 v) { return splat(cast<S>(v)); }
  static WP_FN T from_i64(i64 v) { return splat(cast<S>(v)); }
};
// Spatial vectors and matrices splat too (warp-core's FromLiteral for them), every lane.
template <>
struct literal<SpatialVector, false> : literal<SpatialVector, true> {};
template <>
struct literal<DSpatialVector, false> : literal<DSpatialVector, true> {};
template <>
struct literal<SpatialMatrix, false> : literal<SpatialMatrix, true> {};
template <>
struct literal<DSpatialMatrix, false> : literal<DSpatialMatrix, true> {};
}  // namespace detail

namespace detail {
template <typename T> struct remove_cvref { typedef T type; };
template <typename T> struct remove_cvref<const T> { typedef T type; };
template <typename T> struct remove_cvref<volatile T> { typedef T type; };
template <typename T> struct remove_cvref<const volatile T> { typedef T type; };
template <typename T> struct remove_cvref<T&> : remove_cvref<T> {};
template <typename T> struct remove_cvref<T&&> : remove_cvref<T> {};
}  // namespace detail

/// The literal `v` as a `T` (`v as T`; vectors splat `v as S`). `T` may be cv/ref-qualified
/// (`wp::lit_like<decltype(x)>(2.0)` with x a `const Vec3&` gives a Vec3).
template <typename T>
WP_FN typename detail::remove_cvref<T>::type lit_like(f64 v) {
  return detail::literal<typename detail::remove_cvref<T>::type>::from_f64(v);
}
template <typename T>
WP_FN T lit_like(const T&, f64 v) {
  return detail::literal<T>::from_f64(v);
}
namespace detail {
/// The lane type of T: T itself for scalars; the scalar of vectors, matrices, quaternions,
/// transforms and spatial values (their `vec_traits`).
template <typename T, bool Scalar = num<T>::is_int || num<T>::is_float || num<T>::is_bool>
struct scalar_of {
  typedef T type;
};
template <typename T>
struct scalar_of<T, false> {
  typedef typename vec_traits<T>::scalar type;
};
}  // namespace detail
/// The lane type of T, which may be cv/ref-qualified (a `decltype`).
template <typename T>
using scalar_of_t = typename detail::scalar_of<typename detail::remove_cvref<T>::type>::type;
/// The literal `v` in T's lane type: an unsuffixed literal in a builtin's scalar position
/// beside a value the macro could not type (`lerp(f(a), f(b), 0.5)`), which as a C++ `double`
/// would make the call ambiguous or fail a template's deduction.
template <typename T>
WP_FN scalar_of_t<T> scalar_lit_like(f64 v) {
  return cast<scalar_of_t<T>>(v);
}
/// The integer `v` (a range loop's value) as a `T`.
template <typename T>
WP_FN typename detail::remove_cvref<T>::type int_like(i64 v) {
  return detail::literal<typename detail::remove_cvref<T>::type>::from_i64(v);
}
template <typename T>
WP_FN T int_like(const T&, i64 v) {
  return detail::literal<T>::from_i64(v);
}

// ------------------------------------------------------------------------------------------
// Arrays
// ------------------------------------------------------------------------------------------

/// An `Array<T, N>` kernel argument. Byte layout (align 8, size 16 + 16 N):
///   0 data (T*), 8 shape[N] (i64), 8 + 8N strides[N] (i64, in BYTES),
///   8 + 16N arg (i32: the parameter's index, reported in OutOfBounds faults), 12 + 16N pad.
/// N = 1: 32 bytes, 2: 48, 3: 64, 4: 80.
template <typename T, int N>
struct array_t {
  T* data;
  i64 shape[N];
  i64 strides[N];
  i32 arg;
  i32 pad;
};
static_assert(sizeof(array_t<float, 1>) == 32 && sizeof(array_t<float, 2>) == 48 &&
                  sizeof(array_t<float, 3>) == 64 && sizeof(array_t<float, 4>) == 80 &&
                  alignof(array_t<float, 1>) == 8,
              "array_t layout");

/// Number of elements (usize, like ArrayView::len).
template <typename T, int N>
WP_FN usize len(const array_t<T, N>& a) {
  u64 n = 1;
  for (int k = 0; k < N; ++k) n *= (u64)a.shape[k];
  return n;
}
/// Extent of dimension k (usize, like ArrayView::shape()[k]).
template <typename T, int N>
WP_FN usize extent(const array_t<T, N>& a, int k) {
  return (usize)a.shape[k];
}

/// The bounds check of an in-kernel view (warp-core's ArrayView::view_check): `index` when
/// `index < bound` (`<=` when `inclusive`), else an out-of-bounds fault of `a`'s parameter
/// with the shape `[bound]`, and 0.
template <typename T, int N>
WP_FN usize view_check(const array_t<T, N>& a, i64 index, usize bound, bool inclusive, ctx_t* ctx) {
  const u64 u = (u64)index;
  if (u < (u64)bound || (inclusive && u == (u64)bound)) return (usize)u;
  const i64 shape = (i64)bound;
  raise(ctx, FAULT_OUT_OF_BOUNDS, a.arg, 1, &index, &shape);
  return 0;
}

namespace detail {
/// The element at `idx` (assumed in bounds). With `WP_CONTIGUOUS` defined, the translation
/// unit was compiled for a launch whose array arguments are all contiguous and row-major
/// (the runtime checks that): the strides follow from the shape and the element size, which
/// the compiler knows, instead of being loaded and multiplied at run time.
template <typename T, int N>
WP_FN T* elem_ptr_unchecked_idx(const array_t<T, N>& a, const i64* idx) {
#if defined(WP_CONTIGUOUS)
  i64 flat = idx[0];
  for (int k = 1; k < N; ++k) flat = flat * a.shape[k] + idx[k];
  return a.data + flat;
#else
  i64 off = 0;
  for (int k = 0; k < N; ++k) off += idx[k] * a.strides[k];
  return (T*)((char*)a.data + off);
#endif
}
/// Whether `idx` lies inside `a`'s shape; if not, records the out-of-bounds fault (the
/// array's `arg`, the whole index and the shape).
///
/// Checked accesses branch on this, never on a null element pointer: `a.data + offset` is not
/// known to be non-null, so a pointer test costs a 64-bit compare and a branch per access
/// (measured in the DEM's neighbour loop: two per candidate, beside the bounds checks).
template <typename T, int N>
WP_FN bool check_idx(const array_t<T, N>& a, const i64* idx, ctx_t* ctx) {
  if constexpr (N == 1) {
    if ((u64)idx[0] >= (u64)a.shape[0]) {
      ctx->raised = 1;
      raise_out_of_bounds_1d(ctx->rec, a.arg, idx[0], a.shape[0]);
      return false;
    }
    return true;
  } else {
    for (int k = 0; k < N; ++k) {
      // Negative indices compare as huge unsigned values, as in warp-core.
      if ((u64)idx[k] >= (u64)a.shape[k]) {
        raise(ctx, FAULT_OUT_OF_BOUNDS, a.arg, N, idx, a.shape);
        return false;
      }
    }
    return true;
  }
}
template <typename T, int N>
WP_FN T* elem_ptr_idx(const array_t<T, N>& a, const i64* idx, ctx_t* ctx) {
  return check_idx(a, idx, ctx) ? elem_ptr_unchecked_idx(a, idx) : nullptr;
}
template <typename T, int N>
WP_FN T load_idx(const array_t<T, N>& a, const i64* idx, ctx_t* ctx) {
  if (!check_idx(a, idx, ctx)) return T{};
  return *elem_ptr_unchecked_idx(a, idx);
}
template <typename T, int N>
WP_FN void store_idx(const array_t<T, N>& a, const i64* idx, const T& v, ctx_t* ctx) {
  if (check_idx(a, idx, ctx)) *elem_ptr_unchecked_idx(a, idx) = v;
}
}  // namespace detail

// Bounds-checked access: an index outside [0, shape) records OutOfBounds (with the array's
// `arg`, the whole index and the shape) and touches nothing; load returns T{}.
template <typename T>
WP_FN T* elem_ptr(const array_t<T, 1>& a, i64 i0, ctx_t* ctx) {
  const i64 idx[1] = {i0};
  return detail::elem_ptr_idx(a, idx, ctx);
}
template <typename T>
WP_FN T* elem_ptr(const array_t<T, 2>& a, i64 i0, i64 i1, ctx_t* ctx) {
  const i64 idx[2] = {i0, i1};
  return detail::elem_ptr_idx(a, idx, ctx);
}
template <typename T>
WP_FN T* elem_ptr(const array_t<T, 3>& a, i64 i0, i64 i1, i64 i2, ctx_t* ctx) {
  const i64 idx[3] = {i0, i1, i2};
  return detail::elem_ptr_idx(a, idx, ctx);
}
template <typename T>
WP_FN T* elem_ptr(const array_t<T, 4>& a, i64 i0, i64 i1, i64 i2, i64 i3, ctx_t* ctx) {
  const i64 idx[4] = {i0, i1, i2, i3};
  return detail::elem_ptr_idx(a, idx, ctx);
}
template <typename T>
WP_FN T load(const array_t<T, 1>& a, i64 i0, ctx_t* ctx) {
  const i64 idx[1] = {i0};
  return detail::load_idx(a, idx, ctx);
}
template <typename T>
WP_FN T load(const array_t<T, 2>& a, i64 i0, i64 i1, ctx_t* ctx) {
  const i64 idx[2] = {i0, i1};
  return detail::load_idx(a, idx, ctx);
}
template <typename T>
WP_FN T load(const array_t<T, 3>& a, i64 i0, i64 i1, i64 i2, ctx_t* ctx) {
  const i64 idx[3] = {i0, i1, i2};
  return detail::load_idx(a, idx, ctx);
}
template <typename T>
WP_FN T load(const array_t<T, 4>& a, i64 i0, i64 i1, i64 i2, i64 i3, ctx_t* ctx) {
  const i64 idx[4] = {i0, i1, i2, i3};
  return detail::load_idx(a, idx, ctx);
}
template <typename T>
WP_FN void store(const array_t<T, 1>& a, i64 i0, const typename identity<T>::type& v, ctx_t* ctx) {
  const i64 idx[1] = {i0};
  detail::store_idx(a, idx, v, ctx);
}
template <typename T>
WP_FN void store(const array_t<T, 2>& a, i64 i0, i64 i1, const typename identity<T>::type& v, ctx_t* ctx) {
  const i64 idx[2] = {i0, i1};
  detail::store_idx(a, idx, v, ctx);
}
template <typename T>
WP_FN void store(const array_t<T, 3>& a, i64 i0, i64 i1, i64 i2, const typename identity<T>::type& v, ctx_t* ctx) {
  const i64 idx[3] = {i0, i1, i2};
  detail::store_idx(a, idx, v, ctx);
}
template <typename T>
WP_FN void store(const array_t<T, 4>& a, i64 i0, i64 i1, i64 i2, i64 i3, const typename identity<T>::type& v, ctx_t* ctx) {
  const i64 idx[4] = {i0, i1, i2, i3};
  detail::store_idx(a, idx, v, ctx);
}

// Unchecked access: only for indices known to be in bounds (thread-index accesses after the
// launch checked that the array covers the grid).
template <typename T>
WP_FN T load_unchecked(const array_t<T, 1>& a, i64 i0) {
  const i64 idx[1] = {i0};
  return *detail::elem_ptr_unchecked_idx(a, idx);
}
template <typename T>
WP_FN T load_unchecked(const array_t<T, 2>& a, i64 i0, i64 i1) {
  const i64 idx[2] = {i0, i1};
  return *detail::elem_ptr_unchecked_idx(a, idx);
}
template <typename T>
WP_FN T load_unchecked(const array_t<T, 3>& a, i64 i0, i64 i1, i64 i2) {
  const i64 idx[3] = {i0, i1, i2};
  return *detail::elem_ptr_unchecked_idx(a, idx);
}
template <typename T>
WP_FN T load_unchecked(const array_t<T, 4>& a, i64 i0, i64 i1, i64 i2, i64 i3) {
  const i64 idx[4] = {i0, i1, i2, i3};
  return *detail::elem_ptr_unchecked_idx(a, idx);
}
template <typename T>
WP_FN void store_unchecked(const array_t<T, 1>& a, i64 i0, const typename identity<T>::type& v) {
  const i64 idx[1] = {i0};
  *detail::elem_ptr_unchecked_idx(a, idx) = v;
}
template <typename T>
WP_FN void store_unchecked(const array_t<T, 2>& a, i64 i0, i64 i1, const typename identity<T>::type& v) {
  const i64 idx[2] = {i0, i1};
  *detail::elem_ptr_unchecked_idx(a, idx) = v;
}
template <typename T>
WP_FN void store_unchecked(const array_t<T, 3>& a, i64 i0, i64 i1, i64 i2, const typename identity<T>::type& v) {
  const i64 idx[3] = {i0, i1, i2};
  *detail::elem_ptr_unchecked_idx(a, idx) = v;
}
template <typename T>
WP_FN void store_unchecked(const array_t<T, 4>& a, i64 i0, i64 i1, i64 i2, i64 i3, const typename identity<T>::type& v) {
  const i64 idx[4] = {i0, i1, i2, i3};
  *detail::elem_ptr_unchecked_idx(a, idx) = v;
}

/// True when every index of `lo..hi` (a loop's range, any integer type) is inside the 1-D
/// array `a`: then the loop's accesses of `a` at its variable need no check each. An empty
/// range is inside every array.
template <typename T, typename I>
WP_FN bool range_inside(const array_t<T, 1>& a, I lo, I hi) {
  if (!(lo < hi)) return true;
  // lo >= 0 (only a signed type can fail it; i64 holds every signed value) and hi <= shape;
  // with 0 <= lo < hi, hi is non-negative, so the u64 comparison is exact.
  return !(num<I>::is_signed && (i64)lo < 0) && (u64)hi <= (u64)a.shape[0];
}

/// True when the array covers the launch dims (every thread-index access is in bounds).
template <typename T, int N>
WP_FN bool covers(const array_t<T, N>& a, const i64* dims) {
  for (int k = 0; k < N; ++k)
    if (a.shape[k] < dims[k]) return false;
  return true;
}

// ------------------------------------------------------------------------------------------
// Local arrays (warp_core::local_array): `[T; N]` in a kernel or func
// ------------------------------------------------------------------------------------------

/// A fixed-size local array: a value, copied, passed and returned whole as Rust's `[T; N]`
/// is (a C array in a struct, so that it can be). `local_array_t<T, N>{}` is all zeros.
template <typename T, int N>
struct local_array_t {
  static_assert(N > 0, "a local array holds at least one element");
  T data[N];
  /// `[v; N]`.
  static WP_FN local_array_t splat(const T& v) {
    local_array_t a;
    for (int i = 0; i < N; ++i) a.data[i] = v;
    return a;
  }
};

namespace detail {
template <typename T>
struct is_local_array {
  static constexpr bool value = false;
};
template <typename T, int N>
struct is_local_array<local_array_t<T, N>> {
  static constexpr bool value = true;
  typedef T elem;
};
/// The fault of an index outside `0..n` at `line` (FAULT_LOCAL_INDEX, see fault_t).
WP_LFN void local_index_fault(i64 i, i64 n, i64 line, ctx_t* ctx) {
  const i64 at[3] = {i, n, line};
  raise(ctx, FAULT_LOCAL_INDEX, -1, 3, at, nullptr);
}
}  // namespace detail

/// `a[i]` (warp_core::local_array::get): an index outside `0..N` (negative ones compare as
/// huge) records LocalIndex with the source line and gives T{}.
template <typename T, int N>
WP_FN T local_get(const local_array_t<T, N>& a, i64 i, i64 line, ctx_t* ctx) {
  if ((u64)i < (u64)N) return a.data[i];
  detail::local_index_fault(i, N, line, ctx);
  return T{};
}
/// `a[i] = v` (warp_core::local_array::set): outside `0..N`, LocalIndex and nothing written.
template <typename T, int N>
WP_FN void local_set(local_array_t<T, N>& a, i64 i, const typename identity<T>::type& v, i64 line,
                     ctx_t* ctx) {
  if ((u64)i < (u64)N) {
    a.data[i] = v;
    return;
  }
  detail::local_index_fault(i, N, line, ctx);
}
/// `a.len()` of a local array a kernel cannot name the type of (a struct's array field).
template <typename T, int N>
WP_FN usize len(const local_array_t<T, N>&) {
  return (usize)N;
}
/// The element of an adjoint at an index the replay checked (warp_core::local_array::at_mut):
/// element 0 for any other index, which a faulting thread (it goes on) may reach, so that the
/// access stays in bounds.
template <typename T, int N>
WP_FN T& local_at(local_array_t<T, N>& a, i64 i) {
  return a.data[(u64)i < (u64)N ? i : 0];
}

// Lanes at run-time indices (warp_core::local_array::Lanes and Columns): a kernel's `v[i]` of
// a vector, quaternion (x, y, z, w) or spatial vector, a spatial matrix's row `m[i]`, and a
// glam matrix's column (`col_get`: `m[(i, j)]` is lane i of column j), with local arrays'
// faults and `local_at`'s in-bounds rule for adjoints.
#define WP_LANES(PRE, T, E, NN, GET, AT)                                          \
  WP_LFN E PRE##_get(const T& a, i64 i, i64 line, ctx_t* ctx) {                     \
    if ((u64)i < (u64)(NN)) return GET(a, (int)i);                                 \
    detail::local_index_fault(i, NN, line, ctx);                                   \
    return E{};                                                                    \
  }                                                                                \
  WP_LFN void PRE##_set(T& a, i64 i, const E& v, i64 line, ctx_t* ctx) {            \
    if ((u64)i < (u64)(NN)) {                                                      \
      AT(a, (int)i) = v;                                                           \
      return;                                                                      \
    }                                                                              \
    detail::local_index_fault(i, NN, line, ctx);                                   \
  }                                                                                \
  WP_LFN E& PRE##_at(T& a, i64 i) { return AT(a, (u64)i < (u64)(NN) ? (int)i : 0); }
#define WP_VEC_LANES(T) \
  WP_LANES(local, T, vec_traits<T>::scalar, vec_traits<T>::N, vec_traits<T>::get, vec_traits<T>::at)
#define WP_MAT_LANES(M) \
  WP_LANES(col, M, mat_traits<M>::column, mat_traits<M>::N, mat_traits<M>::get, mat_traits<M>::at)
WP_VEC_LANES(Vec2)
WP_VEC_LANES(Vec3)
WP_VEC_LANES(Vec4)
WP_VEC_LANES(DVec2)
WP_VEC_LANES(DVec3)
WP_VEC_LANES(DVec4)
WP_VEC_LANES(IVec2)
WP_VEC_LANES(IVec3)
WP_VEC_LANES(IVec4)
WP_VEC_LANES(UVec2)
WP_VEC_LANES(UVec3)
WP_VEC_LANES(UVec4)
WP_VEC_LANES(Quat)
WP_VEC_LANES(DQuat)
WP_VEC_LANES(SpatialVector)
WP_VEC_LANES(DSpatialVector)
WP_LANES(local, SpatialMatrix, SpatialVector, 6, SpatialMatrix_row, SpatialMatrix_row_at)
WP_LANES(local, DSpatialMatrix, DSpatialVector, 6, DSpatialMatrix_row, DSpatialMatrix_row_at)
WP_MAT_LANES(Mat2)
WP_MAT_LANES(Mat3)
WP_MAT_LANES(Mat4)
WP_MAT_LANES(DMat2)
WP_MAT_LANES(DMat3)
WP_MAT_LANES(DMat4)
#undef WP_VEC_LANES
#undef WP_MAT_LANES
#undef WP_LANES

// ------------------------------------------------------------------------------------------
// Range loops (warp_core::RangeProg)
// ------------------------------------------------------------------------------------------

/// `count` values `first + n * step`, n in [0, count) (24 bytes).
struct range_t {
  i64 first;
  i64 step;
  i64 count;
};

namespace detail {
// Wrapping i64 arithmetic (Rust release-build semantics; no C++ signed-overflow UB).
WP_LFN i64 wadd64(i64 a, i64 b) { return (i64)((u64)a + (u64)b); }
WP_LFN i64 wmul64(i64 a, i64 b) { return (i64)((u64)a * (u64)b); }
}  // namespace detail

/// `start..end`, or `start..=end` when `inclusive`; count clamped to [0, i64::MAX].
WP_LFN range_t range_new(i64 start, i64 end, bool inclusive) {
  range_t r;
  r.first = start;
  r.step = 1;
  if (inclusive ? end < start : end <= start) {
    r.count = 0;
  } else {
    const u64 d = (u64)end - (u64)start;  // exact: end >= start
    const u64 maxc = 9223372036854775807ull;
    if (inclusive)
      r.count = d >= maxc ? (i64)maxc : (i64)(d + 1);
    else
      r.count = d > maxc ? (i64)maxc : (i64)d;
  }
  return r;
}
/// `.rev()`.
WP_LFN range_t range_rev(range_t r) {
  if (r.count == 0) return r;
  range_t o;
  o.first = detail::wadd64(r.first, detail::wmul64(r.step, r.count - 1));
  o.step = (i64)(0ull - (u64)r.step);
  o.count = r.count;
  return o;
}
/// `.step_by(k)`; k <= 0 records BadStep (ndim 1, index[0] = k) and gives an empty range.
WP_LFN range_t range_step_by(range_t r, i64 k, ctx_t* ctx) {
  if (k <= 0) {
    const i64 idx[1] = {k};
    raise(ctx, FAULT_BAD_STEP, -1, 1, idx, nullptr);
    range_t e;
    e.first = r.first;
    e.step = r.step;
    e.count = 0;
    return e;
  }
  range_t o;
  o.first = r.first;
  o.step = detail::wmul64(r.step, k);
  o.count = detail::wadd64(r.count, k - 1) / k;
  return o;
}
/// The n-th value.
WP_LFN i64 range_at(const range_t& r, i64 n) { return detail::wadd64(r.first, detail::wmul64(n, r.step)); }

// ------------------------------------------------------------------------------------------
// Launch grid (warp_core::Grid)
// ------------------------------------------------------------------------------------------

/// Launch dimensions (48 bytes, align 8): 0 dims[4] (i64; unused trailing entries 1),
/// 32 total (i64), 40 ndim (i32), 44 pad.
struct launch_t {
  i64 dims[4];
  i64 total;
  i32 ndim;
  /// Flags set by the host for this launch (warp_runtime's `cuda/launch.rs`):
  ///   LAUNCH_FAST   every array the kernel indexes by the thread index covers the grid, so
  ///                 those accesses skip their bounds checks;
  ///   LAUNCH_ALONE  (adjoint launches) nothing else runs on the GPU while this launch does:
  ///                 the host queued it on the default stream outside a capture, and every
  ///                 other stream's work is ordered before or after it. The gradients of
  ///                 thread-owned elements are then plain adds (`grad_accum_own`).
  i32 flags;
};
constexpr i32 LAUNCH_FAST = 1;
constexpr i32 LAUNCH_ALONE = 2;
static_assert(sizeof(launch_t) == 48 && alignof(launch_t) == 8, "launch_t layout");

/// The n-dimensional index of thread `flat`, row-major (the last dimension varies fastest).
WP_LFN void unflatten(const launch_t& l, i64 flat, i64* out, int n) {
  for (int d = n - 1; d >= 1; --d) {
    const i64 e = l.dims[d];
    out[d] = flat % e;
    flat /= e;
  }
  if (n > 0) out[0] = flat;
}

#if defined(__CUDACC__)
/// This thread's flat index in a 1-D CUDA launch (i64, so that grids over 2^31 work).
WP_LFN i64 flat_thread_id() { return (i64)blockIdx.x * (i64)blockDim.x + (i64)threadIdx.x; }
#endif

}  // namespace wp

// ------------------------------------------------------------------------------------------
// Deterministic accumulation: `#[kernel(deterministic)]` (warp-runtime's cuda/deterministic.rs,
// docs/book/src/deterministic.md)
// ------------------------------------------------------------------------------------------
//
// A deterministic kernel does not add its float `atomic_add`/`atomic_sub` (nor, in its adjoint,
// its gradient accumulations) into memory: each thread writes records into its own slots of a
// buffer, one record per float lane (the element's lane address, the value's bits, the lane
// type and the operation). Slot `flat * lanes + k` is the thread's k-th lane record, so the
// slot index is the launch order: flat thread index, then program order within the thread.
// After the launch the runtime orders the slots by (address, slot) with two stable 32-bit
// radix sorts (the low address words, then the high ones) and `det_apply_at` adds each lane's
// records into it one after the other, with the element type's own `+`/`-`: the lane ends as
// `((old + r0) + r1) + ..`, as warp-runtime's cpu/deterministic.rs adds them on the CPU, so
// both give the same bits. A lane record and the CPU's element record give the same result:
// the CPU adds an element's lanes independently too (componentwise atomics).
namespace wp {

/// A record's tag: the lane type times 2, plus 1 for a subtraction.
constexpr u8 DET_F32 = 0;
constexpr u8 DET_F64 = 2;
constexpr u8 DET_F16 = 4;
constexpr u8 DET_BF16 = 6;
constexpr u8 DET_SUB = 1;
/// The key of an unused slot: after every address in the order.
constexpr u64 DET_UNUSED = ~0ull;

/// A deterministic launch's record buffer, passed to its entry after the launch_ctx_t (40
/// bytes, align 8; warp-runtime's cuda/deterministic.rs `DetArgs`):
///   0 keys (u64*: each slot's lane address, DET_UNUSED when unused), 8 values (u64*: the
///   value's bits, zero-extended), 16 tags (u8*), 24 lanes (i64: lane slots per thread),
///   32 limit (i32: recorded calls per thread), 36 pad.
struct det_t {
  u64* keys;
  u64* values;
  u8* tags;
  i64 lanes;
  i32 limit;
  i32 pad;
};
static_assert(sizeof(det_t) == 40 && alignof(det_t) == 8, "det_t layout");

/// One thread's recording: its first slot, how many lane slots and calls it has used.
struct det_thread_t {
  u64* keys;
  u64* values;
  u8* tags;
  i64 base;
  i64 cap;
  i64 used;
  i64 flat;
  i32 calls;
  i32 limit;
};

WP_LFN det_thread_t det_begin(const det_t& d, i64 flat) {
  det_thread_t t;
  t.keys = d.keys;
  t.values = d.values;
  t.tags = d.tags;
  t.base = flat * d.lanes;
  t.cap = d.lanes;
  t.used = 0;
  t.flat = flat;
  t.calls = 0;
  t.limit = d.limit;
  return t;
}

/// The end of a thread: its unused slots marked (every slot is written each launch, so the
/// buffer needs no clearing).
WP_LFN void det_end(det_thread_t* t) {
  for (i64 s = t->used; s < t->cap; ++s) t->keys[t->base + s] = DET_UNUSED;
}

/// The fault of a thread past its limit (the CPU's `FaultKind::DeterministicRecords`).
WP_LFN void det_fault(det_thread_t* t, ctx_t* ctx) {
  const i64 at[2] = {t->flat, (i64)t->limit};
  raise(ctx, FAULT_DETERMINISTIC_RECORDS, -1, 2, at, nullptr);
}

/// Counts one recorded call (an accumulation, whatever its lane count); past the limit a
/// fault, and the call records nothing.
WP_LFN bool det_call(det_thread_t* t, ctx_t* ctx) {
  if (t->calls >= t->limit) {
    det_fault(t, ctx);
    return false;
  }
  ++t->calls;
  return true;
}

namespace detail {
template <typename T> struct det_lane;
template <> struct det_lane<f32> {
  static constexpr u8 tag = DET_F32;
  static WP_FN u64 bits(f32 x) { return (u64)f32_to_bits(x); }
  static WP_FN f32 from(u64 b) { return f32_from_bits((u32)b); }
};
template <> struct det_lane<f64> {
  static constexpr u8 tag = DET_F64;
  static WP_FN u64 bits(f64 x) { return (u64)f64_to_bits(x); }
  static WP_FN f64 from(u64 b) { return f64_from_bits(b); }
};
template <> struct det_lane<f16> {
  static constexpr u8 tag = DET_F16;
  static WP_FN u64 bits(f16 x) { return (u64)x.bits; }
  static WP_FN f16 from(u64 b) { return f16_from_bits((u16)b); }
};
template <> struct det_lane<bf16> {
  static constexpr u8 tag = DET_BF16;
  static WP_FN u64 bits(bf16 x) { return (u64)x.bits; }
  static WP_FN bf16 from(u64 b) { return bf16_from_bits((u16)b); }
};
}  // namespace detail

/// Records `*p op= v` for one float lane. The slots are sized for the kernel's widest element
/// (the runtime's `lanes`); running out anyway is the limit's fault, never a write past them.
template <typename S>
WP_FN void det_record_lane(det_thread_t* t, S* p, S v, u8 op, ctx_t* ctx) {
  if (t->used >= t->cap) {
    det_fault(t, ctx);
    return;
  }
  const i64 s = t->base + t->used++;
  t->keys[s] = (u64)p;
  t->values[s] = detail::det_lane<S>::bits(v);
  t->tags[s] = (u8)(detail::det_lane<S>::tag + op);
}

/// Records `*p op= v` lane by lane: a float, or each float lane of a vector, matrix,
/// quaternion, transform or spatial value (`vec_traits`), as `grad_add_p` adds them; nothing
/// for integers and bools (no gradient). A struct's lanes: the overload made with its
/// definition (found by argument-dependent lookup); a local array's: element by element.
template <typename T>
WP_FN void det_record_p(det_thread_t* t, T* p, const T& v, u8 op, ctx_t* ctx) {
  if constexpr (num<T>::is_float) {
    det_record_lane(t, p, v, op, ctx);
  } else if constexpr (!(num<T>::is_int || num<T>::is_bool)) {
    typedef typename vec_traits<T>::scalar S;
    if constexpr (num<S>::is_float) {
      for (int i = 0; i < vec_traits<T>::N; ++i)
        det_record_lane(t, &vec_traits<T>::at(*p, i), vec_traits<T>::get(v, i), op, ctx);
    }
  }
}
template <typename T, int N>
WP_FN void det_record_p(det_thread_t* t, local_array_t<T, N>* p, const local_array_t<T, N>& v,
                        u8 op, ctx_t* ctx) {
  for (int i = 0; i < N; ++i) det_record_p(t, &p->data[i], v.data[i], op, ctx);
}

namespace detail {
/// `atomic_add`/`atomic_sub` of a deterministic kernel: the index checked now (a fault
/// records nothing), the call counted, the value recorded; returns `v` (the old value does not
/// exist; the macro refuses a use of it).
template <typename T, int N>
WP_FN T det_atomic_idx(const array_t<T, N>& a, const i64* idx, const T& v, u8 op,
                       det_thread_t* t, ctx_t* ctx) {
  if (!check_idx(a, idx, ctx)) return v;
  if (!det_call(t, ctx)) return v;
  det_record_p(t, elem_ptr_unchecked_idx(a, idx), v, op, ctx);
  return v;
}
/// `g[idx] += v` in a deterministic kernel's adjoint (what `grad_accum` adds at once).
template <typename T, int N>
WP_FN void det_grad_idx(const array_t<T, N>& g, const i64* idx, const T& v, det_thread_t* t,
                        ctx_t* ctx) {
  if (g.data == nullptr) return;
  if (!check_idx(g, idx, ctx)) return;
  if (!det_call(t, ctx)) return;
  // Unqualified: a user struct's `det_record_p` is found by argument-dependent lookup.
  det_record_p(t, elem_ptr_unchecked_idx(g, idx), v, (u8)0, ctx);
}
}  // namespace detail

#define WP_DET_FNS(N, PARAMS, ...)                                                                 \
  template <typename T>                                                                            \
  WP_FN T det_atomic_add(const array_t<T, N>& a, PARAMS, typename identity<T>::type v,             \
                         det_thread_t* t, ctx_t* ctx) {                                            \
    const i64 idx[N] = {__VA_ARGS__};                                                              \
    return detail::det_atomic_idx(a, idx, v, (u8)0, t, ctx);                                       \
  }                                                                                                \
  template <typename T>                                                                            \
  WP_FN T det_atomic_sub(const array_t<T, N>& a, PARAMS, typename identity<T>::type v,             \
                         det_thread_t* t, ctx_t* ctx) {                                            \
    const i64 idx[N] = {__VA_ARGS__};                                                              \
    return detail::det_atomic_idx(a, idx, v, DET_SUB, t, ctx);                                     \
  }                                                                                                \
  template <typename T>                                                                            \
  WP_FN void det_grad_accum(const array_t<T, N>& g, PARAMS, const typename identity<T>::type& v,   \
                            det_thread_t* t, ctx_t* ctx) {                                         \
    const i64 idx[N] = {__VA_ARGS__};                                                              \
    detail::det_grad_idx(g, idx, v, t, ctx);                                                       \
  }
#define WP_COMMA ,
WP_DET_FNS(1, i64 i0, i0)
WP_DET_FNS(2, i64 i0 WP_COMMA i64 i1, i0, i1)
WP_DET_FNS(3, i64 i0 WP_COMMA i64 i1 WP_COMMA i64 i2, i0, i1, i2)
WP_DET_FNS(4, i64 i0 WP_COMMA i64 i1 WP_COMMA i64 i2 WP_COMMA i64 i3, i0, i1, i2, i3)
#undef WP_COMMA
#undef WP_DET_FNS

// The ordering and the additions after the launch, one slot per call (the kernel's
// `@@ENTRY@@_det_*` entries run them over the slots; the host harness in
// tests/cuda_deterministic_host.rs calls them directly).

/// Step 1: slot `i`'s low address word, and its index, for the first stable sort.
WP_LFN void det_prepare_at(const det_t& d, u32* word, u32* order, i64 i) {
  word[i] = (u32)d.keys[i];
  order[i] = (u32)i;
}

/// Step 2: after the sort by low words, the high word of the slot at position `j`, for the
/// second stable sort (which leaves the slots in (address, slot) order).
WP_LFN void det_high_at(const det_t& d, u32* word, const u32* order, i64 j) {
  word[j] = (u32)(d.keys[order[j]] >> 32);
}

namespace detail {
/// Adds the records of lane type S from position `j` of the ordered slots into the lane at
/// `key`, in order, while the key and the type last; returns the position after them.
template <typename S>
WP_FN i64 det_run(const det_t& d, const u32* order, i64 n, i64 j, u64 key) {
  S* p = (S*)key;
  S acc = *p;
  const u8 type = d.tags[order[j]] >> 1;
  for (; j < n; ++j) {
    const u32 o = order[j];
    const u8 tag = d.tags[o];
    if (d.keys[o] != key || (tag >> 1) != type) break;
    const S v = det_lane<S>::from(d.values[o]);
    acc = (tag & DET_SUB) != 0 ? acc - v : acc + v;
  }
  *p = acc;
  return j;
}
}  // namespace detail

/// Step 3: if position `j` of the ordered slots (`n` of them) starts a lane's records, adds
/// them all into the lane, in order; other positions and unused slots do nothing.
WP_LFN void det_apply_at(const det_t& d, const u32* order, i64 n, i64 j) {
  const u64 key = d.keys[order[j]];
  if (key == DET_UNUSED) return;
  if (j > 0 && d.keys[order[j - 1]] == key) return;
  while (j < n && d.keys[order[j]] == key) {
    switch (d.tags[order[j]] >> 1) {
      case DET_F32 >> 1: j = detail::det_run<f32>(d, order, n, j, key); break;
      case DET_F64 >> 1: j = detail::det_run<f64>(d, order, n, j, key); break;
      case DET_F16 >> 1: j = detail::det_run<f16>(d, order, n, j, key); break;
      default: j = detail::det_run<bf16>(d, order, n, j, key); break;
    }
  }
}

}  // namespace wp

namespace wp {
/// Rust's `!` on a value whose type the macro could not see: logical on bool, bitwise on
/// integers (what `!` means in Rust for each).
WP_LFN bool not_(bool x) { return !x; }
template <typename T> WP_FN T not_(T x) { return ~x; }
}  // namespace wp

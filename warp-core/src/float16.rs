//! `f16` (Warp's `float16`): the half-precision scalar of the kernel language.
//!
//! The type is the [`half`] crate's [`f16`](struct@half::f16) (IEEE binary16: 1 sign bit, 5 exponent bits, 10
//! mantissa bits; largest finite value 65504, smallest subnormal 2^-24). Its rules:
//!
//! * **Arithmetic** `+ - * / %`: each operation converts both operands to `f32` exactly,
//!   computes in `f32` and rounds the result to `f16` once, to nearest, ties to even (what
//!   `half`'s operators do, and what Warp does on the CPU). Because `f32` has more than twice
//!   `f16`'s precision plus two bits (24 >= 2 * 11 + 2), rounding twice is innocuous for
//!   `+ - * /` and `sqrt`: the result is the correctly rounded `f16` operation. `%` is exact.
//!   The CUDA library computes the same way (`wp::f16` in `wp_core.h`), so both backends agree
//!   bit for bit (NaN payloads aside).
//! * **Builtins** (the scalar math group): `f16(f(f32(x)))`, the `f32` builtin on the widened
//!   arguments, rounded once ([`crate::builtins::math`]'s traits are implemented that way here).
//! * **Casts** (`as`, Rust's meaning): to `f16` from `f32` and `f64` round to nearest even
//!   and overflow to infinity (from 65520 up); from integers likewise (exact through `f32`,
//!   since an integer that `f32` rounds is far beyond `f16`'s range). From `f16`, every value
//!   is exact in `f32` and `f64`; to integers the cast saturates and NaN becomes 0.
//!   [`f16_from_f64`] rounds once: `half::f16::from_f64` may round twice (through `f32`, or by
//!   dropping the low mantissa bits first), which gives a different result for some values
//!   just off a tie.
//! * **Adjoints** have the value's type: `f16` adjoints, each step of an adjoint formula
//!   rounded as the arithmetic above (as Warp's float16 adjoints).

use crate::builtins::math::{Classify, Float, Lerp, MinMax, Scalar, Signed};

pub use half::f16;

/// `x` rounded to the nearest `f16`, ties to even (Rust's `x as f16`): overflow gives an
/// infinity of `x`'s sign, NaN stays NaN (quiet, with `x`'s sign and the top 10 bits of its
/// payload, as `half` converts NaNs).
pub fn f16_from_f64(x: f64) -> f16 {
    let bits = x.to_bits();
    let sign = ((bits >> 48) & 0x8000) as u16;
    let a = x.abs();
    if a.is_nan() {
        return f16::from_bits(sign | 0x7E00 | ((bits >> 42) & 0x3FF) as u16);
    }
    // From 65520 (the midpoint between f16::MAX and 2^16, which rounds to even, upwards) on.
    if a >= 65520.0 {
        return f16::from_bits(sign | 0x7C00);
    }
    // 2^(e - 10) for normal f16 values, 2^-24 below 2^-14.
    let r = round_to_ulp(a, -14, 10);
    // `r` is an f16 value (or 2^16 when `a` rounds up past f16::MAX, which the check above
    // excludes), so both conversions are exact.
    f16::from_bits(sign | f16::from_f32(r as f32).to_bits())
}

/// The finite `a >= 0` rounded to nearest, ties to even, on the grid of a binary float with
/// `frac` fraction bits and smallest normal exponent `min_exp` (its ulp at `a`: 2^(e - frac)
/// for `a` in [2^e, 2^(e+1)), e >= min_exp; 2^(min_exp - frac) below). The rounding step of
/// [`f16_from_f64`] and `bf16_from_f64`.
pub(crate) fn round_to_ulp(a: f64, min_exp: i32, frac: i32) -> f64 {
    let e = ((a.to_bits() >> 52) & 0x7FF) as i32 - 1023;
    let ulp = e.max(min_exp) - frac;
    // Scaling by powers of two is exact here (no overflow, and scaling up never underflows).
    (a * pow2(-ulp)).round_ties_even() * pow2(ulp)
}

/// 2^k as an f64, for -1022 <= k <= 1023.
pub(crate) fn pow2(k: i32) -> f64 {
    f64::from_bits(((1023 + k) as u64) << 52)
}

/// `x as f16` for every numeric scalar of the kernel language (what generated code calls for
/// a cast to `f16`).
pub trait ToF16: Copy {
    /// The value rounded to the nearest `f16` (ties to even; overflow to infinity).
    fn to_f16(self) -> f16;
}

/// `x as T` for an `f16` `x` and every numeric scalar `T` (what generated code calls for a
/// cast from `f16`).
pub trait FromF16: Copy {
    /// The `f16` value as `Self`: exact for floats; for integers Rust's saturating float cast
    /// (NaN to 0).
    fn from_f16(x: f16) -> Self;
}

macro_rules! int_f16 {
    ($($t:ty),*) => {$(
        impl ToF16 for $t {
            #[inline(always)]
            fn to_f16(self) -> f16 {
                // Exact in f32 below 2^24; above, f32 rounds but the f16 result is infinite
                // either way.
                f16::from_f32(self as f32)
            }
        }
        impl FromF16 for $t {
            #[inline(always)]
            fn from_f16(x: f16) -> Self {
                x.to_f32() as $t
            }
        }
    )*};
}
int_f16!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);

impl ToF16 for f32 {
    #[inline(always)]
    fn to_f16(self) -> f16 {
        f16::from_f32(self)
    }
}
impl ToF16 for f64 {
    #[inline(always)]
    fn to_f16(self) -> f16 {
        f16_from_f64(self)
    }
}
impl ToF16 for f16 {
    #[inline(always)]
    fn to_f16(self) -> f16 {
        self
    }
}
impl FromF16 for f32 {
    #[inline(always)]
    fn from_f16(x: f16) -> Self {
        x.to_f32()
    }
}
impl FromF16 for f64 {
    #[inline(always)]
    fn from_f16(x: f16) -> Self {
        x.to_f64()
    }
}
impl FromF16 for f16 {
    #[inline(always)]
    fn from_f16(x: f16) -> Self {
        x
    }
}

/// `x as T` between any two numeric scalars of the kernel language, `f16` included, and from
/// `bool` to the integers: what generated code calls where the macro cannot see the source
/// type (a func's result), since `as` itself has no `f16`.
pub trait AsScalar<T>: Copy {
    /// `self as T` (Rust's meaning; through [`ToF16`]/[`FromF16`] where `f16` is involved).
    fn as_scalar(self) -> T;
}

macro_rules! as_scalar {
    (@row $f:ty; [$($t:ty),*]) => {$(
        impl AsScalar<$t> for $f {
            #[inline(always)]
            fn as_scalar(self) -> $t {
                self as $t
            }
        }
    )*};
    ($to:tt <- $($f:ty),*) => {$(
        as_scalar!(@row $f; $to);
        impl AsScalar<f16> for $f {
            #[inline(always)]
            fn as_scalar(self) -> f16 {
                self.to_f16()
            }
        }
        impl AsScalar<$f> for f16 {
            #[inline(always)]
            fn as_scalar(self) -> $f {
                <$f as FromF16>::from_f16(self)
            }
        }
    )*};
}
as_scalar!(
    [i8, i16, i32, i64, isize, u8, u16, u32, u64, usize, f32, f64]
    <- i8, i16, i32, i64, isize, u8, u16, u32, u64, usize, f32, f64
);
as_scalar!(@row bool; [i8, i16, i32, i64, isize, u8, u16, u32, u64, usize]);
impl AsScalar<f16> for f16 {
    #[inline(always)]
    fn as_scalar(self) -> f16 {
        self
    }
}

impl crate::ops::FromLiteral for f16 {
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        f16_from_f64(v)
    }
    #[inline(always)]
    fn from_i64(v: i64) -> Self {
        v.to_f16()
    }
}

// ------------------------------------------------------------------------------------------
// Builtins: the f32 builtin on the widened arguments, rounded once.
// ------------------------------------------------------------------------------------------

/// `f(x)` in f32, rounded to the 16-bit float `H`.
#[inline(always)]
pub(crate) fn via1<H: Half16>(x: H, f: impl Fn(f32) -> f32) -> H {
    H::from_f32(f(x.to_f32()))
}

/// `f(x, y)` in f32, rounded to the 16-bit float `H`.
#[inline(always)]
pub(crate) fn via2<H: Half16>(x: H, y: H, f: impl Fn(f32, f32) -> f32) -> H {
    H::from_f32(f(x.to_f32(), y.to_f32()))
}

/// The two 16-bit floats (`f16`, `bf16`): exact widening to f32, one rounding back.
pub(crate) trait Half16: Copy {
    fn to_f32(self) -> f32;
    fn from_f32(x: f32) -> Self;
}
impl Half16 for f16 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        f16::to_f32(self)
    }
    #[inline(always)]
    fn from_f32(x: f32) -> Self {
        f16::from_f32(x)
    }
}
impl Half16 for half::bf16 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        half::bf16::to_f32(self)
    }
    #[inline(always)]
    fn from_f32(x: f32) -> Self {
        half::bf16::from_f32(x)
    }
}

/// Unary builtins of a 16-bit float: the f32 builtin, rounded once.
macro_rules! via_f32 {
    ($($m:ident),*) => {$(
        #[inline(always)]
        fn $m(self) -> Self {
            $crate::float16::via1(self, <f32 as Float>::$m)
        }
    )*};
}

pub(crate) use via_f32;

/// The scalar math traits of a 16-bit float (`f16`, `bf16`): each builtin the `f32` one on
/// the widened arguments, rounded once.
macro_rules! half_math {
    ($t:ident) => {
        impl Scalar for $t {
            const ZERO: Self = $t::ZERO;
            const ONE: Self = $t::ONE;
            #[inline(always)]
            fn s_add(self, o: Self) -> Self {
                self + o
            }
            #[inline(always)]
            fn s_sub(self, o: Self) -> Self {
                self - o
            }
            #[inline(always)]
            fn s_mul(self, o: Self) -> Self {
                self * o
            }
            #[inline(always)]
            fn s_neg(self) -> Self {
                -self
            }
        }

        impl MinMax for $t {
            #[inline(always)]
            fn w_min(self, o: Self) -> Self {
                $crate::float16::via2(self, o, f32::w_min)
            }
            #[inline(always)]
            fn w_max(self, o: Self) -> Self {
                $crate::float16::via2(self, o, f32::w_max)
            }
        }

        impl Signed for $t {
            #[inline(always)]
            fn w_abs(self) -> Self {
                $crate::float16::via1(self, f32::w_abs)
            }
            #[inline(always)]
            fn w_sign(self) -> Self {
                $crate::float16::via1(self, f32::w_sign)
            }
        }

        impl Float for $t {
            $crate::float16::via_f32!(
                w_floor, w_ceil, w_sqrt, w_exp, w_log, w_sin, w_cos, w_tan, w_asin, w_acos, w_atan,
                w_sinh, w_cosh, w_tanh, w_exp2, w_log2, w_log10, w_cbrt, w_erf, w_erfc, w_erfinv,
                w_erfcinv, w_round, w_rint, w_trunc, w_degrees, w_radians
            );
            #[inline(always)]
            fn w_atan2(self, x: Self) -> Self {
                $crate::float16::via2(self, x, f32::w_atan2)
            }
            #[inline(always)]
            fn w_pow(self, y: Self) -> Self {
                $crate::float16::via2(self, y, f32::w_pow)
            }
            #[inline(always)]
            fn w_isfinite(self) -> bool {
                self.is_finite()
            }
            #[inline(always)]
            fn w_isnan(self) -> bool {
                self.is_nan()
            }
            #[inline(always)]
            fn w_isinf(self) -> bool {
                self.is_infinite()
            }
            #[inline(always)]
            fn w_smoothstep(self, e1: Self, x: Self) -> Self {
                $t::from_f32(self.to_f32().w_smoothstep(e1.to_f32(), x.to_f32()))
            }
        }

        impl Classify for $t {
            #[inline(always)]
            fn w_isfinite(self) -> bool {
                self.is_finite()
            }
            #[inline(always)]
            fn w_isnan(self) -> bool {
                self.is_nan()
            }
            #[inline(always)]
            fn w_isinf(self) -> bool {
                self.is_infinite()
            }
        }

        impl Lerp for $t {
            type Scalar = $t;
            #[inline(always)]
            fn w_lerp(self, b: Self, t: Self) -> Self {
                $t::from_f32(self.to_f32().w_lerp(b.to_f32(), t.to_f32()))
            }
        }
    };
}
pub(crate) use half_math;
half_math!(f16);

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact value of an f16 bit pattern (finite).
    fn value(b: u16) -> f64 {
        f16::from_bits(b).to_f64()
    }

    #[test]
    fn f64_to_f16_is_correctly_rounded() {
        // Every f16 value, the midpoints between neighbours and points just off them.
        for b in 0u16..0x7C00 {
            let v = value(b);
            assert_eq!(f16_from_f64(v).to_bits(), b);
            assert_eq!(f16_from_f64(-v).to_bits(), b | 0x8000);
            let next = if b == 0x7BFF { 65536.0 } else { value(b + 1) };
            let mid = (v + next) / 2.0;
            let even = if b & 1 == 0 { b } else { b + 1 };
            let even = if even == 0x7C00 { 0x7C00 } else { even };
            assert_eq!(f16_from_f64(mid).to_bits(), even, "tie above {b:#x}");
            let below = f64::from_bits(mid.to_bits() - 1);
            let above = f64::from_bits(mid.to_bits() + 1);
            assert_eq!(
                f16_from_f64(below).to_bits(),
                b,
                "below the tie above {b:#x}"
            );
            assert_eq!(f16_from_f64(above).to_bits(), (b + 1).min(0x7C00));
        }
        // Where `half::f16::from_f64` rounds twice: 1 + 2^-11 + 2^-40 is above the tie, but
        // through f32 it becomes the tie and then 1.0.
        let x = 1.0 + 2f64.powi(-11) + 2f64.powi(-40);
        assert_eq!(f16_from_f64(x).to_bits(), 0x3C01);
        assert_eq!(f16_from_f64(65519.99).to_bits(), 0x7BFF);
        assert_eq!(f16_from_f64(65520.0).to_bits(), 0x7C00);
        assert_eq!(f16_from_f64(-1e300).to_bits(), 0xFC00);
        assert_eq!(f16_from_f64(f64::INFINITY).to_bits(), 0x7C00);
        assert_eq!(f16_from_f64(2f64.powi(-25)).to_bits(), 0); // tie to even: 0
        assert_eq!(f16_from_f64(2f64.powi(-25) * 1.5).to_bits(), 1);
        assert_eq!(f16_from_f64(-1e-300).to_bits(), 0x8000);
        assert_eq!(f16_from_f64(f64::MIN_POSITIVE / 4.0).to_bits(), 0);
        // NaN: quiet, sign and top payload bits kept, as `half` does.
        for x in [f64::NAN, -f64::NAN, f64::from_bits(0x7FF0_0000_0000_0001)] {
            let h = f16_from_f64(x);
            assert!(h.is_nan());
            assert_eq!(h.to_bits(), f16::from_f32(x as f32).to_bits());
        }
        // Values exact in f32 round the same as half's (single) f32 rounding.
        let mut s = 0x1234_5678u32;
        for _ in 0..200_000 {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            let x = f32::from_bits(s);
            let a = f16_from_f64(x as f64);
            let b = f16::from_f32(x);
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{x:e}"
            );
        }
    }

    #[test]
    fn casts() {
        assert_eq!(70000i32.to_f16(), f16::INFINITY);
        assert_eq!((-70000i64).to_f16(), f16::NEG_INFINITY);
        assert_eq!(2049u32.to_f16().to_f32(), 2048.0); // tie to even
        assert_eq!(2051u32.to_f16().to_f32(), 2052.0);
        assert_eq!(u64::MAX.to_f16(), f16::INFINITY);
        assert_eq!(i32::from_f16(f16::INFINITY), i32::MAX);
        assert_eq!(u8::from_f16(f16::from_f32(300.0)), 255);
        assert_eq!(u8::from_f16(f16::from_f32(-3.5)), 0);
        assert_eq!(i16::from_f16(f16::from_f32(-3.75)), -3);
        assert_eq!(i64::from_f16(f16::NAN), 0);
        assert_eq!(f64::from_f16(f16::MIN_POSITIVE_SUBNORMAL), 2f64.powi(-24));
        assert_eq!(
            <f16 as crate::ops::FromLiteral>::from_f64(0.1).to_bits(),
            0x2E66
        );
        assert_eq!(AsScalar::<i32>::as_scalar(f16::from_f32(-7.5)), -7);
        assert_eq!(AsScalar::<f16>::as_scalar(2049i32).to_f32(), 2048.0);
        assert_eq!(AsScalar::<u8>::as_scalar(300i32), 44);
        assert_eq!(AsScalar::<i64>::as_scalar(true), 1);
        assert_eq!(AsScalar::<f64>::as_scalar(0.1f32), 0.1f32 as f64);
    }

    #[test]
    fn builtins_round_the_f32_result_once() {
        use crate::builtins::math as m;
        let h = f16::from_f32;
        for b in (0u16..=0xFFFF).step_by(7) {
            let x = f16::from_bits(b);
            let xf = x.to_f32();
            let same = |a: f16, e: f32| {
                let e = h(e);
                assert!(
                    a.to_bits() == e.to_bits() || (a.is_nan() && e.is_nan()),
                    "{b:#x}"
                );
            };
            same(m::sqrt(x), xf.sqrt());
            same(m::exp(x), xf.exp());
            same(m::sin(x), xf.sin());
            same(m::floor(x), xf.floor());
            same(m::abs(x), xf.abs());
            same(m::sign(x), if xf < 0.0 { -1.0 } else { 1.0 });
            same(m::min(x, h(0.5)), xf.min(0.5));
            same(m::clamp(x, h(-2.0), h(3.0)), xf.clamp(-2.0, 3.0).max(-2.0));
            same(m::pow(x, h(1.5)), xf.powf(1.5));
            same(m::lerp(x, h(3.0), h(0.25)), xf * 0.75 + 3.0 * 0.25);
            assert_eq!(m::isnan(x), xf.is_nan());
            assert_eq!(m::isfinite(x), xf.is_finite());
        }
        // NaN loses in min/max, as for f32.
        assert_eq!(m::max(f16::NAN, f16::ONE), f16::ONE);
        assert_eq!(m::sign(f16::NEG_ZERO), f16::ONE);
        assert_eq!(m::step(h(-1.0)), f16::ONE);
    }
}

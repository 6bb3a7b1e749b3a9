//! `bf16` (Warp's `bfloat16`): the brain-float scalar of the kernel language and a tile element.
//!
//! The type is the [`half`] crate's [`bf16`](struct@half::bf16): 1 sign bit, 8 exponent bits
//! (f32's range: largest finite value about 3.39e38, smallest subnormal 2^-133), 7 mantissa
//! bits (8 significant bits: a relative rounding error of at most 2^-8). Its rules are
//! [`f16`](crate::float16)'s:
//!
//! * **Arithmetic** `+ - * / %`: each operation widens both operands to `f32` exactly,
//!   computes in `f32` and rounds the result to `bf16` once, to nearest, ties to even
//!   (`half`'s operators, Warp's `bfloat16` operators). As for f16, `f32`'s 24 bits are more
//!   than twice bf16's 8 plus two, so the double rounding is innocuous for `+ - * /` and
//!   `sqrt`: each is the correctly rounded bf16 operation. The CUDA library computes the same
//!   way (`wp::bf16` in `wp_core.h`, the same software rounding), so both backends agree bit
//!   for bit on every number; an operation whose result is NaN gives a NaN on both, whose
//!   payload is each platform's f32 NaN (the conversions themselves keep payloads).
//! * **Builtins**: `bf16(f(f32(x)))`, the `f32` builtin on the widened arguments, rounded once.
//! * **Casts** (`as`, Rust's meaning): to `bf16` from every scalar rounds to nearest even,
//!   once ([`bf16_from_f64`] for `f64`: `half::bf16::from_f64` drops the low 32 bits of the
//!   f64 first and so rounds some values just off a tie the wrong way), overflowing to
//!   infinity; NaN stays NaN (quiet). From `bf16`, every value is exact in `f32` and `f64`;
//!   to integers the cast saturates and NaN becomes 0. Between `f16` and `bf16` through `f32`
//!   (exact), rounded once.
//! * **Adjoints** have the value's type: `bf16` adjoints, each step of an adjoint formula one
//!   bf16 operation.
//! * **Tiles**: loads, stores, elementwise maps and `tile_matmul` with an f32 accumulator
//!   ([`crate::tile::MatmulElem`]).

use crate::builtins::math::{Classify, Float, Lerp, MinMax, Scalar, Signed};
use crate::float16::{pow2, round_to_ulp, AsScalar, FromF16, ToF16};

pub use half::bf16;
use half::f16;

/// `x` rounded to the nearest `bf16`, ties to even, once (Rust's `x as bf16` would be):
/// overflow gives an infinity of `x`'s sign, NaN stays NaN (quiet, with `x`'s sign and the
/// top 6 bits of its payload below the quiet bit, as `half` converts an f32 NaN).
pub fn bf16_from_f64(x: f64) -> bf16 {
    let bits = x.to_bits();
    let sign = ((bits >> 48) & 0x8000) as u16;
    let a = x.abs();
    if a.is_nan() {
        return bf16::from_f32(x as f32);
    }
    // From the midpoint between bf16::MAX ((2 - 2^-7) 2^127) and 2^128 on, rounding (to even,
    // upwards) overflows.
    if a >= (2.0 - 2f64.powi(-8)) * 2f64.powi(127) {
        return bf16::from_bits(sign | 0x7F80);
    }
    // 2^(e - 7) for normal values, 2^-133 below 2^-126.
    let r = round_to_ulp(a, -126, 7);
    // `r` is a bf16 value, exact in f32, so both conversions below are exact.
    bf16::from_bits(sign | bf16::from_f32(r as f32).to_bits())
}

/// `x as bf16` for every numeric scalar of the kernel language (what generated code calls for
/// a cast to `bf16`).
pub trait ToBf16: Copy {
    /// The value rounded to the nearest `bf16` (ties to even, once; overflow to infinity).
    fn to_bf16(self) -> bf16;
}

/// `x as T` for a `bf16` `x` and every numeric scalar `T` (what generated code calls for a
/// cast from `bf16`).
pub trait FromBf16: Copy {
    /// The `bf16` value as `Self`: exact for f32 and f64; rounded once for f16; for integers
    /// Rust's saturating float cast (NaN to 0).
    fn from_bf16(x: bf16) -> Self;
}

macro_rules! int_bf16 {
    ($($t:ty),*) => {$(
        impl ToBf16 for $t {
            #[inline(always)]
            fn to_bf16(self) -> bf16 {
                // Rounded once: through f64 (exact for 32-bit integers; for 64-bit ones f64
                // may round, so the value goes through the i128 path below instead).
                int_to_bf16(self as i128)
            }
        }
        impl FromBf16 for $t {
            #[inline(always)]
            fn from_bf16(x: bf16) -> Self {
                x.to_f32() as $t
            }
        }
    )*};
}
int_bf16!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);

/// An integer rounded once to bf16: `f32`'s rounding (24 bits) followed by bf16's (8 bits)
/// could round twice for integers above 2^24, so the integer is first cut to 9 significant
/// bits (8 kept and a sticky bit for everything below the round bit), which f64 holds
/// exactly, and rounded from there.
#[inline(always)]
fn int_to_bf16(v: i128) -> bf16 {
    let a = v.unsigned_abs();
    let n = 128 - a.leading_zeros() as i32; // significant bits
    let sticky_cut = n - 25; // keep 25 bits: exact in f32 is 24, so keep a sticky below
    let a = if sticky_cut > 0 {
        let low = a & ((1u128 << sticky_cut) - 1);
        (a >> sticky_cut) | u128::from(low != 0)
    } else {
        a
    };
    // `a` has at most 25 bits and is exact in f64; its bf16 rounding is the integer's (the
    // sticky bit sits far below bf16's round bit).
    let m = bf16_from_f64(a as f64 * pow2(sticky_cut.max(0)));
    if v < 0 {
        -m
    } else {
        m
    }
}

impl ToBf16 for f32 {
    #[inline(always)]
    fn to_bf16(self) -> bf16 {
        bf16::from_f32(self)
    }
}
impl ToBf16 for f64 {
    #[inline(always)]
    fn to_bf16(self) -> bf16 {
        bf16_from_f64(self)
    }
}
impl ToBf16 for bf16 {
    #[inline(always)]
    fn to_bf16(self) -> bf16 {
        self
    }
}
impl ToBf16 for f16 {
    #[inline(always)]
    fn to_bf16(self) -> bf16 {
        // f16 -> f32 is exact; one rounding.
        bf16::from_f32(self.to_f32())
    }
}
impl FromBf16 for f32 {
    #[inline(always)]
    fn from_bf16(x: bf16) -> Self {
        x.to_f32()
    }
}
impl FromBf16 for f64 {
    #[inline(always)]
    fn from_bf16(x: bf16) -> Self {
        x.to_f64()
    }
}
impl FromBf16 for bf16 {
    #[inline(always)]
    fn from_bf16(x: bf16) -> Self {
        x
    }
}
impl FromBf16 for f16 {
    #[inline(always)]
    fn from_bf16(x: bf16) -> Self {
        // bf16 -> f32 is exact; one rounding to f16.
        f16::from_f32(x.to_f32())
    }
}
impl ToF16 for bf16 {
    #[inline(always)]
    fn to_f16(self) -> f16 {
        f16::from_bf16(self)
    }
}
impl FromF16 for bf16 {
    #[inline(always)]
    fn from_f16(x: f16) -> Self {
        x.to_bf16()
    }
}

macro_rules! as_scalar_bf16 {
    ($($f:ty),*) => {$(
        impl AsScalar<bf16> for $f {
            #[inline(always)]
            fn as_scalar(self) -> bf16 {
                self.to_bf16()
            }
        }
        impl AsScalar<$f> for bf16 {
            #[inline(always)]
            fn as_scalar(self) -> $f {
                <$f as FromBf16>::from_bf16(self)
            }
        }
    )*};
}
as_scalar_bf16!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize, f32, f64, f16);
impl AsScalar<bf16> for bf16 {
    #[inline(always)]
    fn as_scalar(self) -> bf16 {
        self
    }
}

impl crate::ops::FromLiteral for bf16 {
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        bf16_from_f64(v)
    }
    #[inline(always)]
    fn from_i64(v: i64) -> Self {
        v.to_bf16()
    }
}

crate::float16::half_math!(bf16);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f64_to_bf16_is_correctly_rounded() {
        // Every finite bf16 value, the midpoints between neighbours and points just off them.
        for b in 0u16..0x7F80 {
            let v = bf16::from_bits(b).to_f64();
            assert_eq!(bf16_from_f64(v).to_bits(), b);
            assert_eq!(bf16_from_f64(-v).to_bits(), b | 0x8000);
            let next = if b == 0x7F7F {
                2f64.powi(128)
            } else {
                bf16::from_bits(b + 1).to_f64()
            };
            let mid = (v + next) / 2.0;
            let even = if b & 1 == 0 { b } else { b + 1 };
            assert_eq!(bf16_from_f64(mid).to_bits(), even, "tie above {b:#x}");
            let below = f64::from_bits(mid.to_bits() - 1);
            let above = f64::from_bits(mid.to_bits() + 1);
            assert_eq!(
                bf16_from_f64(below).to_bits(),
                b,
                "below the tie above {b:#x}"
            );
            assert_eq!(
                bf16_from_f64(above).to_bits(),
                b + 1,
                "above the tie above {b:#x}"
            );
        }
        // Where `half::bf16::from_f64` rounds wrongly: 1 + 2^-8 + 2^-40 is above the tie
        // (1 + 2^-8), but half drops the bits below 2^-20 first and rounds the tie to even.
        let x = 1.0 + 2f64.powi(-8) + 2f64.powi(-40);
        assert_eq!(bf16_from_f64(x).to_bits(), 0x3F81);
        assert_eq!(bf16::from_f64(x).to_bits(), 0x3F80);
        assert_eq!(bf16_from_f64(-1e300).to_bits(), 0xFF80);
        assert_eq!(bf16_from_f64(f64::INFINITY).to_bits(), 0x7F80);
        assert_eq!(bf16_from_f64(2f64.powi(-134)).to_bits(), 0); // tie to even: 0
        assert_eq!(bf16_from_f64(1.5 * 2f64.powi(-134)).to_bits(), 1);
        assert_eq!(bf16_from_f64(-1e-300).to_bits(), 0x8000);
        for x in [f64::NAN, -f64::NAN, f64::from_bits(0x7FF0_0000_0000_0001)] {
            let h = bf16_from_f64(x);
            assert!(h.is_nan());
            assert_eq!(h.to_bits() & 0x8000, ((x.to_bits() >> 48) & 0x8000) as u16);
        }
        // Values exact in f32 round the same as half's (single) f32 rounding.
        let mut s = 0x1234_5678u32;
        for _ in 0..200_000 {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            let x = f32::from_bits(s);
            let a = bf16_from_f64(x as f64);
            let b = bf16::from_f32(x);
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{x:e}"
            );
        }
    }

    #[test]
    fn casts() {
        // 257 = 2^8 + 1 is a tie between 256 and 258: to even, 256.
        assert_eq!(257i32.to_bf16().to_f32(), 256.0);
        assert_eq!(259u32.to_bf16().to_f32(), 260.0);
        // 2^24 + 2^16 + 1 is just above the tie between 2^24 and 2^24 + 2^17: f32 would
        // round it to the tie first (2^24 + 2^16), then to even, 2^24; once, it rounds up.
        let v = (1i64 << 24) + (1 << 16) + 1;
        assert_eq!(v.to_bf16().to_f64(), ((1i64 << 24) + (1 << 17)) as f64);
        assert_eq!(
            (-v).to_bf16().to_f64(),
            -(((1i64 << 24) + (1 << 17)) as f64)
        );
        assert_eq!(u64::MAX.to_bf16().to_f64(), 2f64.powi(64));
        assert_eq!(i64::MIN.to_bf16().to_f64(), -(2f64.powi(63)));
        assert_eq!(0u8.to_bf16().to_bits(), 0);
        assert_eq!(i32::from_bf16(bf16::INFINITY), i32::MAX);
        assert_eq!(u8::from_bf16(bf16::from_f32(300.0)), 255);
        assert_eq!(i16::from_bf16(bf16::from_f32(-3.75)), -3);
        assert_eq!(i64::from_bf16(bf16::NAN), 0);
        assert_eq!(f64::from_bf16(bf16::from_bits(1)), 2f64.powi(-133));
        // bf16 <-> f16: 1e5 overflows f16; 0.1 (f16 0x2E66) rounds once to bf16.
        assert_eq!(f16::from_bf16(bf16::from_f32(1e5)), f16::INFINITY);
        let h = f16::from_bits(0x2E66);
        assert_eq!(h.to_bf16(), bf16::from_f32(h.to_f32()));
        assert!(f16::from_bf16(bf16::NAN).is_nan());
        assert_eq!(
            <bf16 as crate::ops::FromLiteral>::from_f64(0.1).to_bits(),
            0x3DCD
        );
        assert_eq!(AsScalar::<i32>::as_scalar(bf16::from_f32(-7.5)), -7);
        assert_eq!(AsScalar::<bf16>::as_scalar(257i32).to_f32(), 256.0);
        assert_eq!(
            AsScalar::<f16>::as_scalar(bf16::from_f32(0.5)).to_f32(),
            0.5
        );
    }

    #[test]
    fn builtins_round_the_f32_result_once() {
        use crate::builtins::math as m;
        let h = bf16::from_f32;
        for b in (0u16..=0xFFFF).step_by(7) {
            let x = bf16::from_bits(b);
            let xf = x.to_f32();
            let same = |a: bf16, e: f32| {
                let e = h(e);
                assert!(
                    a.to_bits() == e.to_bits() || (a.is_nan() && e.is_nan()),
                    "{b:#x}"
                );
            };
            same(m::sqrt(x), xf.sqrt());
            same(m::exp(x), xf.exp());
            same(m::sin(x), xf.sin());
            same(m::abs(x), xf.abs());
            same(m::min(x, h(0.5)), xf.min(0.5));
            same(m::pow(x, h(1.5)), xf.powf(1.5));
            same(x + h(1.0), xf + 1.0);
            same(x * h(3.0), xf * 3.0);
            assert_eq!(m::isnan(x), xf.is_nan());
        }
        assert_eq!(m::max(bf16::NAN, bf16::ONE), bf16::ONE);
    }
}

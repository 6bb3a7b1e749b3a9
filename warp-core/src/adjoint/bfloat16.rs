//! Adjoints of `bf16` values, as [`f16`'s](super::float16): the adjoint has the value's type
//! (as Warp's bfloat16 adjoints), and every step of an adjoint formula is one `bf16` operation
//! (computed in `f32`, rounded once; see [`crate::bfloat16`]).

use half::{bf16, f16};

use super::cast::AdjCast;
use super::lanes::{l_abs, l_lerp, l_max, l_min};
use super::{AdjFloat, AdjLerp, AdjMinMax, AdjSigned, Adjoint};
use crate::bfloat16::{FromBf16, ToBf16};

impl Adjoint for bf16 {
    #[inline(always)]
    fn adj_zero() -> Self {
        bf16::ZERO
    }
    #[inline(always)]
    fn adj_accum(&mut self, v: Self) {
        *self += v;
    }
}

impl AdjFloat for bf16 {
    #[inline(always)]
    fn adj_is_nan(self) -> bool {
        self.is_nan()
    }
    #[inline(always)]
    fn adj_trunc(self) -> Self {
        bf16::from_f32(self.to_f32().trunc())
    }
    // The f64 constants rounded once to bf16 (checked below).
    const LN_2: Self = bf16::from_bits(0x3F31);
    const LN_10: Self = bf16::from_bits(0x4013);
    const FRAC_2_SQRT_PI: Self = bf16::from_bits(0x3F90);
    const SQRT_PI_2: Self = bf16::from_bits(0x3F63);
}

impl AdjMinMax for bf16 {
    #[inline(always)]
    fn adj_min(a: bf16, b: bf16, adj_a: &mut bf16, adj_b: &mut bf16, adj_ret: bf16) {
        l_min(a, b, adj_a, adj_b, adj_ret)
    }
    #[inline(always)]
    fn adj_max(a: bf16, b: bf16, adj_a: &mut bf16, adj_b: &mut bf16, adj_ret: bf16) {
        l_max(a, b, adj_a, adj_b, adj_ret)
    }
}

impl AdjSigned for bf16 {
    #[inline(always)]
    fn adj_abs(x: bf16, adj_x: &mut bf16, adj_ret: bf16) {
        l_abs(x, adj_x, adj_ret)
    }
}

impl AdjLerp for bf16 {
    #[inline(always)]
    fn adj_lerp(a: bf16, b: bf16, t: bf16, aa: &mut bf16, ab: &mut bf16, at: &mut bf16, g: bf16) {
        l_lerp(a, b, t, aa, ab, at, g)
    }
}

// Casts: between bf16 and the other floats `adj_from += adj_to as From` (rounded as the
// forward cast rounds); with an integer or bool on either side, nothing.
impl AdjCast<bf16> for bf16 {
    #[inline(always)]
    fn adj_cast(adj_from: &mut bf16, adj_to: bf16) {
        *adj_from += adj_to;
    }
}
macro_rules! float_bf16_cast {
    ($($t:ident),*) => {$(
        impl AdjCast<$t> for bf16 {
            #[inline(always)]
            fn adj_cast(adj_from: &mut bf16, adj_to: $t) {
                *adj_from += adj_to.to_bf16();
            }
        }
        impl AdjCast<bf16> for $t {
            #[inline(always)]
            fn adj_cast(adj_from: &mut $t, adj_to: bf16) {
                *adj_from += <$t as FromBf16>::from_bf16(adj_to);
            }
        }
    )*};
}
float_bf16_cast!(f32, f64, f16);
macro_rules! noop_bf16_cast {
    ($($t:ty),*) => {$(
        impl AdjCast<$t> for bf16 {
            #[inline(always)]
            fn adj_cast(_adj_from: &mut bf16, _adj_to: $t) {}
        }
        impl AdjCast<bf16> for $t {
            #[inline(always)]
            fn adj_cast(_adj_from: &mut $t, _adj_to: bf16) {}
        }
    )*};
}
noop_bf16_cast!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);
impl AdjCast<bf16> for bool {
    #[inline(always)]
    fn adj_cast(_adj_from: &mut bool, _adj_to: bf16) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adjoint::{adj_cast, adj_div, adj_mul};
    use crate::bfloat16::bf16_from_f64;

    #[test]
    fn constants_are_the_f64_constants_rounded_once() {
        use core::f64::consts as c;
        assert_eq!(<bf16 as AdjFloat>::LN_2, bf16_from_f64(c::LN_2));
        assert_eq!(<bf16 as AdjFloat>::LN_10, bf16_from_f64(c::LN_10));
        assert_eq!(
            <bf16 as AdjFloat>::FRAC_2_SQRT_PI,
            bf16_from_f64(c::FRAC_2_SQRT_PI)
        );
        assert_eq!(
            <bf16 as AdjFloat>::SQRT_PI_2,
            bf16_from_f64(c::PI.sqrt() / 2.0)
        );
    }

    #[test]
    fn formulas_round_each_step() {
        let h = bf16::from_f32;
        let (a, b, g) = (h(3.0), h(7.0), h(0.1));
        let (mut aa, mut ab) = (bf16::ZERO, bf16::ZERO);
        adj_div(a, b, &mut aa, &mut ab, g);
        let gb = h(g.to_f32() / b.to_f32());
        assert_eq!(aa, gb);
        assert_eq!(ab, -h(gb.to_f32() * h(a.to_f32() / b.to_f32()).to_f32()));
        let (mut aa, mut ab) = (bf16::ZERO, bf16::ZERO);
        adj_mul(a, b, &mut aa, &mut ab, g);
        assert_eq!(aa, h(g.to_f32() * 7.0));
        let mut af = 1.0f32;
        adj_cast(&mut af, h(0.5));
        assert_eq!(af, 1.5);
        let mut ab16 = bf16::ZERO;
        adj_cast(&mut ab16, 0.1f64);
        assert_eq!(ab16.to_bits(), 0x3DCD);
        let mut ah = f16::ZERO;
        adj_cast(&mut ah, h(0.5));
        assert_eq!(ah.to_f32(), 0.5);
        let mut ai = 0i32;
        adj_cast(&mut ai, h(3.0));
        assert_eq!(ai, 0);
    }
}

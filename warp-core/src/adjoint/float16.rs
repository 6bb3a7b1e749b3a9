//! Adjoints of `f16` values: the adjoint has the value's type (as Warp's float16 adjoints),
//! and every step of an adjoint formula is one `f16` operation (computed in `f32`, rounded
//! once; see [`crate::float16`]).

use half::f16;

use super::cast::AdjCast;
use super::lanes::{l_abs, l_lerp, l_max, l_min};
use super::{AdjFloat, AdjLerp, AdjMinMax, AdjSigned, Adjoint};
use crate::float16::{FromF16, ToF16};

impl Adjoint for f16 {
    #[inline(always)]
    fn adj_zero() -> Self {
        f16::ZERO
    }
    #[inline(always)]
    fn adj_accum(&mut self, v: Self) {
        *self += v;
    }
}

impl AdjFloat for f16 {
    #[inline(always)]
    fn adj_is_nan(self) -> bool {
        self.is_nan()
    }
    #[inline(always)]
    fn adj_trunc(self) -> Self {
        f16::from_f32(self.to_f32().trunc())
    }
    // The f64 constants rounded once to f16 (checked below).
    const LN_2: Self = f16::from_bits(0x398C);
    const LN_10: Self = f16::from_bits(0x409B);
    const FRAC_2_SQRT_PI: Self = f16::from_bits(0x3C83);
    const SQRT_PI_2: Self = f16::from_bits(0x3B17);
}

impl AdjMinMax for f16 {
    #[inline(always)]
    fn adj_min(a: f16, b: f16, adj_a: &mut f16, adj_b: &mut f16, adj_ret: f16) {
        l_min(a, b, adj_a, adj_b, adj_ret)
    }
    #[inline(always)]
    fn adj_max(a: f16, b: f16, adj_a: &mut f16, adj_b: &mut f16, adj_ret: f16) {
        l_max(a, b, adj_a, adj_b, adj_ret)
    }
}

impl AdjSigned for f16 {
    #[inline(always)]
    fn adj_abs(x: f16, adj_x: &mut f16, adj_ret: f16) {
        l_abs(x, adj_x, adj_ret)
    }
}

impl AdjLerp for f16 {
    #[inline(always)]
    fn adj_lerp(a: f16, b: f16, t: f16, aa: &mut f16, ab: &mut f16, at: &mut f16, g: f16) {
        l_lerp(a, b, t, aa, ab, at, g)
    }
}

// Casts: between f16 and the other floats `adj_from += adj_to as From` (rounded as the
// forward cast rounds); with an integer or bool on either side, nothing.
impl AdjCast<f16> for f16 {
    #[inline(always)]
    fn adj_cast(adj_from: &mut f16, adj_to: f16) {
        *adj_from += adj_to;
    }
}
macro_rules! float_f16_cast {
    ($($t:ident),*) => {$(
        impl AdjCast<$t> for f16 {
            #[inline(always)]
            fn adj_cast(adj_from: &mut f16, adj_to: $t) {
                *adj_from += adj_to.to_f16();
            }
        }
        impl AdjCast<f16> for $t {
            #[inline(always)]
            fn adj_cast(adj_from: &mut $t, adj_to: f16) {
                *adj_from += <$t as FromF16>::from_f16(adj_to);
            }
        }
    )*};
}
float_f16_cast!(f32, f64);
macro_rules! noop_f16_cast {
    ($($t:ty),*) => {$(
        impl AdjCast<$t> for f16 {
            #[inline(always)]
            fn adj_cast(_adj_from: &mut f16, _adj_to: $t) {}
        }
        impl AdjCast<f16> for $t {
            #[inline(always)]
            fn adj_cast(_adj_from: &mut $t, _adj_to: f16) {}
        }
    )*};
}
noop_f16_cast!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);
impl AdjCast<f16> for bool {
    #[inline(always)]
    fn adj_cast(_adj_from: &mut bool, _adj_to: f16) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adjoint::{adj_add, adj_cast, adj_div, adj_mul, adj_sin, adj_sqrt};
    use crate::float16::f16_from_f64;

    #[test]
    fn constants_are_the_f64_constants_rounded_once() {
        assert_eq!(
            <f16 as AdjFloat>::LN_2,
            f16_from_f64(core::f64::consts::LN_2)
        );
        assert_eq!(
            <f16 as AdjFloat>::LN_10,
            f16_from_f64(core::f64::consts::LN_10)
        );
        assert_eq!(
            <f16 as AdjFloat>::FRAC_2_SQRT_PI,
            f16_from_f64(core::f64::consts::FRAC_2_SQRT_PI)
        );
        assert_eq!(
            <f16 as AdjFloat>::SQRT_PI_2,
            f16_from_f64(core::f64::consts::PI.sqrt() / 2.0)
        );
    }

    #[test]
    fn formulas_round_each_step() {
        let h = f16::from_f32;
        let (a, b, g) = (h(3.0), h(7.0), h(0.1));
        let (mut aa, mut ab) = (f16::ZERO, f16::ZERO);
        adj_div(a, b, &mut aa, &mut ab, g);
        // gb = g / b; adj_a += gb; adj_b -= gb * (a / b), each op rounded to f16.
        let gb = h(g.to_f32() / b.to_f32());
        assert_eq!(aa, gb);
        assert_eq!(ab, -h(gb.to_f32() * h(a.to_f32() / b.to_f32()).to_f32()));
        let (mut aa, mut ab) = (h(1.0), f16::ZERO);
        adj_add(a, b, &mut aa, &mut ab, g);
        adj_mul(a, b, &mut aa, &mut ab, g);
        assert_eq!(
            aa,
            h(h(1.0 + g.to_f32()).to_f32() + h(g.to_f32() * 7.0).to_f32())
        );
        let mut ax = f16::ZERO;
        adj_sqrt(h(4.0), &mut ax, h(1.0));
        assert_eq!(ax, h(0.25));
        let mut ax = f16::ZERO;
        adj_sin(f16::ZERO, &mut ax, h(2.0));
        assert_eq!(ax, h(2.0));
        let mut af = 1.0f32;
        adj_cast(&mut af, h(0.5));
        assert_eq!(af, 1.5);
        let mut ah = f16::ZERO;
        adj_cast(&mut ah, 0.1f64);
        assert_eq!(ah.to_bits(), 0x2E66);
        let mut ai = 0i32;
        adj_cast(&mut ai, h(3.0));
        assert_eq!(ai, 0);
    }
}

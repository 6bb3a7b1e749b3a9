//! Arithmetic with one meaning on every backend.
//!
//! Integer `+ - * << >>` wrap (two's complement, as CUDA does, and without Rust's debug-build
//! overflow panic); integer `/` and `%` by zero are faults; `MIN / -1` wraps. Float arithmetic
//! is IEEE and needs no helper.

use crate::fault::{Fault, FaultKind, KResult};

/// Casts to and from `f16` (generated code writes `x as f16` as `ToF16::to_f16(x)`, and a cast
/// of a value it cannot type as `AsScalar::<T>::as_scalar(x)`).
pub use crate::bfloat16::{FromBf16, ToBf16};
pub use crate::float16::{AsScalar, FromF16, ToF16};

/// Integer arithmetic with wrapping semantics and checked division.
pub trait WrapInt: Copy {
    /// Wrapping `+`.
    fn w_add(self, o: Self) -> Self;
    /// Wrapping `-`.
    fn w_sub(self, o: Self) -> Self;
    /// Wrapping `*`.
    fn w_mul(self, o: Self) -> Self;
    /// Wrapping negation.
    fn w_neg(self) -> Self;
    /// `/`: a fault on division by zero, wrapping on `MIN / -1`.
    fn w_div(self, o: Self, kernel: &'static str) -> KResult<Self>;
    /// `%`: a fault on division by zero, wrapping on `MIN % -1`.
    fn w_rem(self, o: Self, kernel: &'static str) -> KResult<Self>;
    /// `<<` with the shift amount taken modulo the bit width (as CUDA's hardware does).
    fn w_shl(self, s: u32) -> Self;
    /// `>>` (arithmetic for signed types), shift amount modulo the bit width.
    fn w_shr(self, s: u32) -> Self;
}

macro_rules! wrap_int {
    ($($t:ty),*) => {$(
        impl WrapInt for $t {
            #[inline(always)] fn w_add(self, o: Self) -> Self { self.wrapping_add(o) }
            #[inline(always)] fn w_sub(self, o: Self) -> Self { self.wrapping_sub(o) }
            #[inline(always)] fn w_mul(self, o: Self) -> Self { self.wrapping_mul(o) }
            #[inline(always)] fn w_neg(self) -> Self { self.wrapping_neg() }
            #[inline(always)]
            fn w_div(self, o: Self, kernel: &'static str) -> KResult<Self> {
                if o == 0 { return Err(Fault::new(kernel, FaultKind::DivisionByZero)); }
                Ok(self.wrapping_div(o))
            }
            #[inline(always)]
            fn w_rem(self, o: Self, kernel: &'static str) -> KResult<Self> {
                if o == 0 { return Err(Fault::new(kernel, FaultKind::DivisionByZero)); }
                Ok(self.wrapping_rem(o))
            }
            #[inline(always)] fn w_shl(self, s: u32) -> Self { self.wrapping_shl(s) }
            #[inline(always)] fn w_shr(self, s: u32) -> Self { self.wrapping_shr(s) }
        }
    )*};
}
wrap_int!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);

macro_rules! wrap_int_vec {
    ($($v:ty),*) => {$(
        /// Componentwise, with the scalar rules (a zero in any component of a divisor faults).
        impl WrapInt for $v {
            #[inline(always)] fn w_add(self, o: Self) -> Self { self.wrapping_add(o) }
            #[inline(always)] fn w_sub(self, o: Self) -> Self { self.wrapping_sub(o) }
            #[inline(always)] fn w_mul(self, o: Self) -> Self { self.wrapping_mul(o) }
            #[inline(always)] fn w_neg(self) -> Self { <$v>::ZERO.wrapping_sub(self) }
            #[inline(always)]
            fn w_div(self, o: Self, kernel: &'static str) -> KResult<Self> {
                if o.to_array().contains(&0) { return Err(Fault::new(kernel, FaultKind::DivisionByZero)); }
                Ok(self.wrapping_div(o))
            }
            #[inline(always)]
            fn w_rem(self, o: Self, kernel: &'static str) -> KResult<Self> {
                if o.to_array().contains(&0) { return Err(Fault::new(kernel, FaultKind::DivisionByZero)); }
                let (a, b) = (self.to_array(), o.to_array());
                Ok(<$v>::from_array(std::array::from_fn(|k| a[k].wrapping_rem(b[k]))))
            }
            #[inline(always)]
            fn w_shl(self, s: u32) -> Self { <$v>::from_array(self.to_array().map(|c| c.wrapping_shl(s))) }
            #[inline(always)]
            fn w_shr(self, s: u32) -> Self { <$v>::from_array(self.to_array().map(|c| c.wrapping_shr(s))) }
        }
    )*};
}
use glam::{IVec2, IVec3, IVec4, UVec2, UVec3, UVec4};
wrap_int_vec!(IVec2, IVec3, IVec4, UVec2, UVec3, UVec4);

/// A literal of the same type as another value: what generated code writes for an
/// unsuffixed literal whose context is a value the macro could not type (a user func's
/// result, a struct field). For vectors the literal is splatted, which for `+ - * / %` with a
/// scalar means the same as glam's vector-scalar operators.
pub trait FromLiteral: Copy {
    /// The literal `v` (an integer or a float literal's value) in this type.
    fn from_f64(v: f64) -> Self;
    /// The integer `v` in this type (range loops over values of this type).
    fn from_i64(v: i64) -> Self;
}

macro_rules! from_literal_scalar {
    ($($t:ty),*) => {$(
        impl FromLiteral for $t {
            #[inline(always)] fn from_f64(v: f64) -> Self { v as $t }
            #[inline(always)] fn from_i64(v: i64) -> Self { v as $t }
        }
    )*};
}
from_literal_scalar!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize, f32, f64);

macro_rules! from_literal_vec {
    ($($v:ty : $s:ty),*) => {$(
        impl FromLiteral for $v {
            #[inline(always)] fn from_f64(v: f64) -> Self { <$v>::splat(v as $s) }
            #[inline(always)] fn from_i64(v: i64) -> Self { <$v>::splat(v as $s) }
        }
    )*};
}
from_literal_vec!(
    glam::Vec2: f32, glam::Vec3: f32, glam::Vec4: f32, glam::DVec2: f64, glam::DVec3: f64, glam::DVec4: f64,
    IVec2: i32, IVec3: i32, IVec4: i32, UVec2: u32, UVec3: u32, UVec4: u32
);

/// The literal `v` with the type of `like` (see [`FromLiteral`]).
#[inline(always)]
pub fn lit_like<T: FromLiteral>(_like: &T, v: f64) -> T {
    T::from_f64(v)
}

/// The integer `v` (a range loop's value) with the type of `like`.
#[inline(always)]
pub fn int_like<T: FromLiteral>(_like: &T, v: i64) -> T {
    T::from_i64(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn integer_semantics() {
        assert_eq!(i32::MAX.w_add(1), i32::MIN);
        assert_eq!(i32::MIN.w_div(-1, "k").unwrap(), i32::MIN);
        assert_eq!(
            7i32.w_div(0, "k").unwrap_err().kind,
            FaultKind::DivisionByZero
        );
        assert_eq!((-7i32).w_rem(3, "k").unwrap(), -1);
        assert_eq!(1u32.w_shl(33), 2);
    }

    #[test]
    fn integer_vector_semantics() {
        use glam::{ivec2, uvec2};
        assert_eq!(
            ivec2(i32::MAX, 1).w_add(glam::IVec2::ONE),
            ivec2(i32::MIN, 2)
        );
        assert_eq!(uvec2(0, 5).w_sub(uvec2(1, 1)), uvec2(u32::MAX, 4));
        assert_eq!(ivec2(i32::MIN, 3).w_neg(), ivec2(i32::MIN, -3));
        assert_eq!(
            ivec2(7, 7).w_div(ivec2(1, 0), "k").unwrap_err().kind,
            FaultKind::DivisionByZero
        );
        assert_eq!(ivec2(-7, 7).w_rem(ivec2(3, 3), "k").unwrap(), ivec2(-1, 1));
    }

    #[test]
    fn literals_like_a_value() {
        assert_eq!(lit_like(&2.5f64, 1.0), 1.0f64);
        assert_eq!(lit_like(&glam::Vec3::ONE, 2.0), glam::Vec3::splat(2.0));
        assert_eq!(int_like(&0usize, 7), 7usize);
    }
}

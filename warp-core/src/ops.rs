//! Arithmetic with one meaning on every backend.
//!
//! Integer `+ - * << >>` wrap (two's complement, as CUDA does, and without Rust's debug-build
//! overflow panic); integer `/` and `%` by zero are faults; `MIN / -1` wraps. Float arithmetic
//! is IEEE and needs no helper.

use crate::fault::{Fault, FaultKind, KResult};

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

/// A shift amount of any integer type, as the `u32` that `wrapping_shl` takes.
#[inline(always)]
pub fn shift_amount<S: Into<i128> + Copy>(s: S) -> u32 {
    (s.into() & 0xff) as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn integer_semantics() {
        assert_eq!(i32::MAX.w_add(1), i32::MIN);
        assert_eq!(i32::MIN.w_div(-1, "k").unwrap(), i32::MIN);
        assert_eq!(7i32.w_div(0, "k").unwrap_err().kind, FaultKind::DivisionByZero);
        assert_eq!((-7i32).w_rem(3, "k").unwrap(), -1);
        assert_eq!(1u32.w_shl(33), 2);
    }
}

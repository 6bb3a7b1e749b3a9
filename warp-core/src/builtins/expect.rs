//! The checks of Warp's test expectations (the table's "misc" section, `wp_misc.h` on CUDA):
//! `expect_eq(a, b)`, `expect_neq(a, b)`, `expect_near(a, b, tol)`. Each returns whether the
//! expectation holds; written as a statement in a kernel (`expect_eq(a, b);`), a false one is
//! a fault (`FaultKind::AssertionFailed`), which the generated code raises.
//!
//! * `expect_eq`: `a == b` (a NaN equals nothing; vectors, quaternions and matrices compare
//!   every lane); `expect_neq`: `a != b`, its negation;
//! * `expect_near` (float scalars and vectors): every lane `x`, `y` has `|x - y| <= tol`,
//!   computed as `(x <= y ? y - x : x - y) <= tol` in the type itself, so that a NaN lane (or
//!   two equal infinities, whose difference is NaN) fails, as `abs(x - y) <= tol` does in Warp.

use glam::{DVec2, DVec3, DVec4, Vec2, Vec3, Vec4};

use super::math::Scalar;
use crate::{bf16, f16};

/// `expect_near`'s check: float scalars and float vectors, lane by lane.
pub trait Near: Copy {
    /// The lane type (the tolerance's).
    type S: Copy;
    /// Whether every lane of `self` is within `tol` of `o`'s.
    fn w_near(self, o: Self, tol: Self::S) -> bool;
}

/// `|a - b| <= tol` without `abs`, false for NaN.
#[inline(always)]
fn near_lane<T: Scalar>(a: T, b: T, tol: T) -> bool {
    let d = if a <= b { b.s_sub(a) } else { a.s_sub(b) };
    d <= tol
}

macro_rules! near_scalar_impl {
    ($($t:ty),*) => {$(
        impl Near for $t {
            type S = $t;
            #[inline(always)]
            fn w_near(self, o: Self, tol: $t) -> bool {
                near_lane(self, o, tol)
            }
        }
    )*};
}
near_scalar_impl!(f32, f64, f16, bf16);

macro_rules! near_vec_impl {
    ($($v:ident: $s:ident),*) => {$(
        impl Near for $v {
            type S = $s;
            #[inline(always)]
            fn w_near(self, o: Self, tol: $s) -> bool {
                let (a, b) = (self.to_array(), o.to_array());
                (0..a.len()).all(|k| near_lane(a[k], b[k], tol))
            }
        }
    )*};
}
near_vec_impl!(Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64);

/// Whether `a == b` (the check of `expect_eq`).
#[inline(always)]
pub fn expect_eq<T: PartialEq>(a: T, b: T) -> bool {
    a == b
}

/// Whether `a != b` (the check of `expect_neq`).
#[inline(always)]
pub fn expect_neq<T: PartialEq>(a: T, b: T) -> bool {
    a != b
}

/// Whether every lane of `a` is within `tol` of `b`'s (the check of `expect_near`).
#[inline(always)]
pub fn expect_near<T: Near>(a: T, b: T, tol: T::S) -> bool {
    a.w_near(b, tol)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq_and_neq_follow_ieee() {
        assert!(expect_eq(1.5f32, 1.5));
        assert!(!expect_eq(f32::NAN, f32::NAN));
        assert!(expect_neq(f32::NAN, f32::NAN));
        assert!(expect_eq(0.0f64, -0.0));
        assert!(expect_eq(
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(1.0, 2.0, 3.0)
        ));
        assert!(expect_neq(
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(1.0, 2.0, 4.0)
        ));
        assert!(expect_eq(7i32, 7) && expect_neq(7u64, 8));
    }

    #[test]
    fn near_is_lane_by_lane_and_fails_on_nan() {
        // Exact binary fractions: no rounding decides these.
        assert!(expect_near(1.0f32, 1.25, 0.25));
        assert!(!expect_near(1.0f32, 1.5, 0.25));
        assert!(expect_near(1.5f64, 1.0, 0.5));
        assert!(!expect_near(f32::NAN, 1.0, 1e30));
        assert!(!expect_near(f64::INFINITY, f64::INFINITY, 1e300));
        let a = Vec3::new(1.0, 2.0, 3.0);
        assert!(expect_near(a, Vec3::new(1.25, 1.75, 3.0), 0.25));
        assert!(!expect_near(a, Vec3::new(1.0, 2.0, 3.5), 0.25));
        assert!(expect_near(
            DVec2::new(0.0, 0.0),
            DVec2::new(-0.5, 0.5),
            0.5
        ));
        assert!(expect_near(
            f16::from_f32(1.0),
            f16::from_f32(1.5),
            f16::from_f32(0.5)
        ));
        assert!(!expect_near(
            bf16::from_f32(1.0),
            bf16::from_f32(2.0),
            bf16::from_f32(0.5)
        ));
    }
}

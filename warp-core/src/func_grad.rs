//! What `wp::grad(f)(..)` needs on the CPU: the seed its call gives `f`'s adjoint for the
//! adjoint of the result ([`GradSeed`], Warp's `T(1)`), and a scratch adjoint stack per thread
//! ([`with_grad_stack`]), so that a forward kernel evaluating a func's gradient allocates
//! nothing per call.
//!
//! `wp::grad(f)(x, y)` is `f`'s generated (or custom) adjoint run with the result's adjoint
//! set to one in every lane and the parameters' adjoints starting at zero: for a scalar
//! result, the partial derivatives `(df/dx, df/dy)`; for a vector result, the derivatives of
//! the sum of its lanes (Warp's convention).

use crate::grad::AdStack;
use crate::spatial::{DSpatialMatrix, DSpatialVector, SpatialMatrix, SpatialVector};
use glam::{DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, Mat2, Mat3, Mat4, Quat};
use glam::{Vec2, Vec3, Vec4};
use std::cell::Cell;

/// The adjoint `wp::grad(f)` gives `f`'s result: one in every float lane (Warp's `T(1)`).
/// Implemented for the float scalars, vectors, matrices, quaternions and spatial types and for
/// tuples of them (a func with several results); a func with another result (an integer, a
/// struct) has no gradient `wp::grad` could seed.
#[diagnostic::on_unimplemented(
    message = "`wp::grad` cannot seed a result of type `{Self}`",
    label = "the func's result",
    note = "`wp::grad(f)` needs `f` to return a float scalar, vector, matrix, quaternion or spatial value (or a tuple of them)"
)]
pub trait GradSeed: Copy {
    /// One in every float lane.
    fn grad_seed() -> Self;
}

macro_rules! seed_scalar {
    ($($t:ty => $one:expr),* $(,)?) => {$(
        impl GradSeed for $t {
            #[inline(always)]
            fn grad_seed() -> Self {
                $one
            }
        }
    )*};
}
seed_scalar!(
    f32 => 1.0,
    f64 => 1.0,
    crate::f16 => crate::f16::ONE,
    crate::bf16 => crate::bf16::ONE,
    Vec2 => Vec2::ONE,
    Vec3 => Vec3::ONE,
    Vec4 => Vec4::ONE,
    DVec2 => DVec2::ONE,
    DVec3 => DVec3::ONE,
    DVec4 => DVec4::ONE,
    Mat2 => Mat2::from_cols_array(&[1.0; 4]),
    Mat3 => Mat3::from_cols_array(&[1.0; 9]),
    Mat4 => Mat4::from_cols_array(&[1.0; 16]),
    DMat2 => DMat2::from_cols_array(&[1.0; 4]),
    DMat3 => DMat3::from_cols_array(&[1.0; 9]),
    DMat4 => DMat4::from_cols_array(&[1.0; 16]),
    Quat => Quat::from_xyzw(1.0, 1.0, 1.0, 1.0),
    DQuat => DQuat::from_xyzw(1.0, 1.0, 1.0, 1.0),
    SpatialVector => SpatialVector::from_array([1.0; 6]),
    DSpatialVector => DSpatialVector::from_array([1.0; 6]),
    SpatialMatrix => {
        let r = SpatialVector::from_array([1.0; 6]);
        SpatialMatrix(r, r, r, r, r, r)
    },
    DSpatialMatrix => {
        let r = DSpatialVector::from_array([1.0; 6]);
        DSpatialMatrix(r, r, r, r, r, r)
    },
);

macro_rules! seed_tuple {
    ($(($($t:ident),+)),* $(,)?) => {$(
        impl<$($t: GradSeed),+> GradSeed for ($($t,)+) {
            #[inline(always)]
            fn grad_seed() -> Self {
                ($($t::grad_seed(),)+)
            }
        }
    )*};
}
seed_tuple!((A, B), (A, B, C), (A, B, C, D));

thread_local! {
    /// This thread's scratch stack for `wp::grad` calls (taken while one runs).
    static SCRATCH: Cell<Option<AdStack>> = const { Cell::new(None) };
}

/// Runs `f` with an empty adjoint stack of `capacity` bytes: this thread's scratch stack,
/// or a fresh one while the scratch stack is in use (a `wp::grad` call inside a func whose
/// gradient another call is evaluating) or too small.
pub fn with_grad_stack<R>(
    kernel: &'static str,
    capacity: usize,
    f: impl FnOnce(&mut AdStack) -> R,
) -> R {
    let mut stack = SCRATCH
        .with(Cell::take)
        .filter(|s| s.capacity() == capacity)
        .unwrap_or_else(|| AdStack::new(capacity, kernel));
    stack.clear();
    let out = f(&mut stack);
    SCRATCH.with(|s| s.set(Some(stack)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_are_one_in_every_lane() {
        assert_eq!(f32::grad_seed(), 1.0);
        assert_eq!(DVec3::grad_seed(), DVec3::ONE);
        assert_eq!(Mat2::grad_seed().to_cols_array(), [1.0; 4]);
        assert_eq!(SpatialMatrix::grad_seed().5.to_array(), [1.0; 6]);
        assert_eq!(<(f32, Vec2)>::grad_seed(), (1.0, Vec2::ONE));
    }

    #[test]
    fn nested_calls_get_their_own_stack() {
        let depth = with_grad_stack("k", 64, |outer| {
            outer.push(1.0f32, 1).unwrap();
            with_grad_stack("k", 64, |inner| {
                assert!(
                    inner.is_empty(),
                    "the inner call must not see the outer pushes"
                );
                inner.len()
            })
        });
        assert_eq!(depth, 0);
        // The scratch stack comes back empty for the next call.
        with_grad_stack("k", 64, |s| assert!(s.is_empty()));
    }
}

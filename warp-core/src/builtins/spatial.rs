//! Spatial-vector builtins (CPU side of the table's "spatial" section; CUDA:
//! `warp-cuda/cuda/wp_spatial.h`).
//!
//! Each is the [`SpatialVector`]/[`SpatialMatrix`] method of the same meaning (see
//! [`crate::spatial`] for the formulas and their order of evaluation); `transpose` and `outer`
//! of spatial types go through the [`Transpose`] and [`Outer`] traits of the builtins of those
//! names.

use glam::{DMat3, DVec3, Mat3, Vec3};

use super::linalg::{Outer, Transpose};
use super::math::Lerp;
use crate::spatial::{DSpatialMatrix, DSpatialVector, SpatialMatrix, SpatialVector};
use crate::transform::{DTransform, Transform};

/// `spatial_vector(w, v)`: `Vec3` (making a [`SpatialVector`]), `DVec3` (a [`DSpatialVector`]).
pub trait SpatialParts: Copy {
    /// The spatial vector type.
    type SV: Copy;
    /// The spatial vector `(w, v)`.
    fn w_spatial_vector(w: Self, v: Self) -> Self::SV;
}

/// The six-scalar `spatial_vector`: `f32`, `f64`.
pub trait SpatialScalar: Copy {
    /// The spatial vector type.
    type SV: Copy;
    /// The spatial vector with these lanes.
    fn w_spatial_vector6(a: [Self; 6]) -> Self::SV;
}

/// The spatial-vector builtins: [`SpatialVector`], [`DSpatialVector`].
pub trait SpatialOps: Copy {
    /// The scalar.
    type S: Copy;
    /// The 3-vector.
    type V3: Copy;
    /// `spatial_top`.
    fn w_top(self) -> Self::V3;
    /// `spatial_bottom`.
    fn w_bottom(self) -> Self::V3;
    /// `spatial_dot`.
    fn w_spatial_dot(self, b: Self) -> Self::S;
    /// `spatial_cross`.
    fn w_spatial_cross(self, b: Self) -> Self;
    /// `spatial_cross_dual`.
    fn w_spatial_cross_dual(self, b: Self) -> Self;
    /// `velocity_at_point`.
    fn w_velocity_at_point(self, r: Self::V3) -> Self::V3;
}

/// `spatial_adjoint(r, s)`: `Mat3` (making a [`SpatialMatrix`]), `DMat3` (a [`DSpatialMatrix`]).
pub trait SpatialAdjointParts: Copy {
    /// The spatial matrix type.
    type SM: Copy;
    /// See [`SpatialMatrix::adjoint`].
    fn w_spatial_adjoint(r: Self, s: Self) -> Self::SM;
}

/// `transform_twist`, `transform_wrench`: [`Transform`], [`DTransform`].
pub trait TwistOps: Copy {
    /// The spatial vector type.
    type SV: Copy;
    /// See [`SpatialVector::transform_twist`].
    fn w_twist(self, x: Self::SV) -> Self::SV;
    /// See [`SpatialVector::transform_wrench`].
    fn w_wrench(self, x: Self::SV) -> Self::SV;
}

/// The spatial vector with top `w` and bottom `v` (`SpatialVector::new(w, v)` in kernels).
#[inline(always)]
pub fn spatial_vector<V: SpatialParts>(w: V, v: V) -> V::SV {
    V::w_spatial_vector(w, v)
}

/// The spatial vector with these six lanes (Warp's six-scalar `spatial_vector`).
#[inline(always)]
pub fn spatial_vector_scalars<S: SpatialScalar>(a0: S, a1: S, a2: S, a3: S, a4: S, a5: S) -> S::SV {
    S::w_spatial_vector6([a0, a1, a2, a3, a4, a5])
}

/// Lanes 0 to 2.
#[inline(always)]
pub fn spatial_top<X: SpatialOps>(a: X) -> X::V3 {
    a.w_top()
}

/// Lanes 3 to 5.
#[inline(always)]
pub fn spatial_bottom<X: SpatialOps>(a: X) -> X::V3 {
    a.w_bottom()
}

/// The dot product, summed left to right.
#[inline(always)]
pub fn spatial_dot<X: SpatialOps>(a: X, b: X) -> X::S {
    a.w_spatial_dot(b)
}

/// The motion cross product `a × b`.
#[inline(always)]
pub fn spatial_cross<X: SpatialOps>(a: X, b: X) -> X {
    a.w_spatial_cross(b)
}

/// The force cross product `a ×* b`.
#[inline(always)]
pub fn spatial_cross_dual<X: SpatialOps>(a: X, b: X) -> X {
    a.w_spatial_cross_dual(b)
}

/// The linear velocity `v + w × r` of the point at offset `r` from the origin of the twist
/// `qd = (w, v)` (angular on top, as Warp's spatial vectors).
#[inline(always)]
pub fn velocity_at_point<X: SpatialOps>(qd: X, r: X::V3) -> X::V3 {
    qd.w_velocity_at_point(r)
}

/// `[[r, 0], [s, r]]` in 3x3 blocks.
#[inline(always)]
pub fn spatial_adjoint<M: SpatialAdjointParts>(r: M, s: M) -> M::SM {
    M::w_spatial_adjoint(r, s)
}

/// The twist `x` mapped by `t`.
#[inline(always)]
pub fn transform_twist<X: TwistOps>(t: X, x: X::SV) -> X::SV {
    t.w_twist(x)
}

/// The wrench `x` mapped by `t`.
#[inline(always)]
pub fn transform_wrench<X: TwistOps>(t: X, x: X::SV) -> X::SV {
    t.w_wrench(x)
}

macro_rules! spatial_impl {
    ($($sv:ident, $sm:ident: $s:ident, $v3:ident, $m3:ident, $x:ident);*) => {$(
        impl SpatialParts for $v3 {
            type SV = $sv;
            #[inline(always)]
            fn w_spatial_vector(w: $v3, v: $v3) -> $sv {
                $sv::new(w, v)
            }
        }
        impl SpatialScalar for $s {
            type SV = $sv;
            #[inline(always)]
            fn w_spatial_vector6(a: [$s; 6]) -> $sv {
                $sv::from_array(a)
            }
        }
        impl SpatialOps for $sv {
            type S = $s;
            type V3 = $v3;
            #[inline(always)]
            fn w_top(self) -> $v3 {
                self.top()
            }
            #[inline(always)]
            fn w_bottom(self) -> $v3 {
                self.bottom()
            }
            #[inline(always)]
            fn w_spatial_dot(self, b: Self) -> $s {
                self.dot(b)
            }
            #[inline(always)]
            fn w_spatial_cross(self, b: Self) -> Self {
                self.cross(b)
            }
            #[inline(always)]
            fn w_spatial_cross_dual(self, b: Self) -> Self {
                self.cross_dual(b)
            }
            #[inline(always)]
            fn w_velocity_at_point(self, r: $v3) -> $v3 {
                self.velocity_at_point(r)
            }
        }
        impl SpatialAdjointParts for $m3 {
            type SM = $sm;
            #[inline(always)]
            fn w_spatial_adjoint(r: $m3, s: $m3) -> $sm {
                $sm::adjoint(r, s)
            }
        }
        impl TwistOps for $x {
            type SV = $sv;
            #[inline(always)]
            fn w_twist(self, x: $sv) -> $sv {
                x.transform_twist(self)
            }
            #[inline(always)]
            fn w_wrench(self, x: $sv) -> $sv {
                x.transform_wrench(self)
            }
        }
        // `lerp`: lane by lane (a spatial matrix row-major), as Warp's vectors and matrices.
        impl Lerp for $sv {
            type Scalar = $s;
            #[inline(always)]
            fn w_lerp(self, b: Self, t: $s) -> Self {
                let (x, y) = (self.to_array(), b.to_array());
                $sv::from_array(core::array::from_fn(|k| x[k].w_lerp(y[k], t)))
            }
        }
        impl Lerp for $sm {
            type Scalar = $s;
            #[inline(always)]
            fn w_lerp(self, b: Self, t: $s) -> Self {
                let (x, y) = (self.to_rows_array(), b.to_rows_array());
                $sm::from_rows_array(core::array::from_fn(|i| {
                    core::array::from_fn(|j| x[i][j].w_lerp(y[i][j], t))
                }))
            }
        }
        impl Outer for $sv {
            type Mat = $sm;
            #[inline(always)]
            fn w_outer_of(self, b: Self) -> $sm {
                self.outer(b)
            }
        }
        impl Transpose for $sm {
            type T = $sm;
            #[inline(always)]
            fn w_transposed(self) -> Self {
                self.transpose()
            }
        }
    )*};
}
spatial_impl!(
    SpatialVector, SpatialMatrix: f32, Vec3, Mat3, Transform;
    DSpatialVector, DSpatialMatrix: f64, DVec3, DMat3, DTransform
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtins::{outer, transpose};
    use glam::Quat;

    #[test]
    fn builtins_are_the_methods() {
        let (w, v) = (Vec3::new(1.0, 2.0, 3.0), Vec3::new(-0.5, 0.25, 2.0));
        let a = spatial_vector(w, v);
        assert_eq!(a, SpatialVector::new(w, v));
        assert_eq!(a, spatial_vector_scalars(1.0f32, 2.0, 3.0, -0.5, 0.25, 2.0));
        assert_eq!((spatial_top(a), spatial_bottom(a)), (w, v));
        let b = SpatialVector::from_array([0.3, 0.7, -1.1, 2.0, -0.5, 0.9]);
        assert_eq!(spatial_dot(a, b), a.dot(b));
        assert_eq!(spatial_cross(a, b), a.cross(b));
        assert_eq!(spatial_cross_dual(a, b), a.cross_dual(b));
        assert_eq!(outer(a, b), a.outer(b));
        assert_eq!(transpose(outer(a, b)), b.outer(a));
        let r = Mat3::from_quat(Quat::from_rotation_y(0.3));
        assert_eq!(spatial_adjoint(r, r), SpatialMatrix::adjoint(r, r));
        let t = Transform::new(v, Quat::from_rotation_x(0.4));
        assert_eq!(transform_twist(t, a), a.transform_twist(t));
        assert_eq!(transform_wrench(t, a), a.transform_wrench(t));
        let d = spatial_vector(DVec3::X, DVec3::Y);
        assert_eq!(spatial_bottom(d), DVec3::Y);
        // glam's outer and transpose still dispatch.
        assert_eq!(
            outer(Vec3::X, Vec3::Y),
            Mat3::from_cols(Vec3::ZERO, Vec3::X, Vec3::ZERO)
        );
        assert_eq!(transpose(Mat3::IDENTITY), Mat3::IDENTITY);
    }
}

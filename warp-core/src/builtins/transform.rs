//! Rigid-transform builtins (CPU side of the table's "transform" section; CUDA:
//! `warp-cuda/cuda/wp_transform.h`).
//!
//! Each is the [`Transform`]/[`DTransform`] method of the same meaning (see
//! [`crate::transform`] for the formulas), plus glam's `Mat4::transform_point3` /
//! `transform_vector3` for the 4x4-matrix overloads of `transform_point` / `transform_vector`
//! (`m * (x, 1)` and `m * (x, 0)` without a perspective divide, summed in glam's order: lane
//! `k` is `((x_axis[k] * x.x + y_axis[k] * x.y) + z_axis[k] * x.z) (+ w_axis[k])`).
//! `inverse(t)` and `lerp(a, b, t)` of transforms go through the [`Inverse`] and [`Lerp`]
//! traits of the builtins of those names.

use glam::{DMat4, DQuat, DVec3, Mat4, Quat, Vec3};

use super::linalg::Inverse;
use super::math::Lerp;
use crate::transform::{DTransform, Transform};

/// The pieces of a transform, for `transformation(p, q)`: `Vec3` (with `Quat`, making a
/// [`Transform`]) and `DVec3` (with `DQuat`, making a [`DTransform`]).
pub trait XformParts: Copy {
    /// The rotation type.
    type Q: Copy;
    /// The transform type.
    type X: Copy;
    /// The transform `(p, q)`.
    fn w_transformation(p: Self, q: Self::Q) -> Self::X;
}

/// The transform builtins: [`Transform`], [`DTransform`].
pub trait XformOps: Copy {
    /// The scalar.
    type S: Copy;
    /// The translation type.
    type V3: Copy;
    /// The rotation type.
    type Q: Copy;
    /// The 4x4 matrix type.
    type M4: Copy;
    /// `p`.
    fn w_translation(self) -> Self::V3;
    /// `q`.
    fn w_rotation(self) -> Self::Q;
    /// `self * b`.
    fn w_multiply(self, b: Self) -> Self;
    /// The inverse (see [`Transform::inverse`]).
    fn w_inverse(self) -> Self;
    /// The 4x4 matrix (see [`Transform::to_matrix`]).
    fn w_to_matrix(self) -> Self::M4;
}

/// `transform_from_matrix`: `Mat4` (making a [`Transform`]), `DMat4` (a [`DTransform`]).
pub trait XformMatrix: Copy {
    /// The transform type.
    type X: Copy;
    /// See [`Transform::from_matrix`].
    fn w_transform_from_matrix(self) -> Self::X;
}

/// `transform_point`, `transform_vector`: transforms and 4x4 matrices.
pub trait TransformPoint: Copy {
    /// The 3-vector type.
    type V3: Copy;
    /// `x` as a point.
    fn w_transform_point(self, x: Self::V3) -> Self::V3;
    /// `x` as a direction.
    fn w_transform_vector(self, x: Self::V3) -> Self::V3;
}

/// The transform that rotates by `q`, then translates by `p` (Warp's `transformation`;
/// `Transform::new(p, q)` in kernels).
#[inline(always)]
pub fn transformation<V: XformParts>(p: V, q: V::Q) -> V::X {
    V::w_transformation(p, q)
}

/// The translation `t.p`.
#[inline(always)]
pub fn transform_get_translation<X: XformOps>(t: X) -> X::V3 {
    t.w_translation()
}

/// The rotation `t.q`.
#[inline(always)]
pub fn transform_get_rotation<X: XformOps>(t: X) -> X::Q {
    t.w_rotation()
}

/// The composition `a * b` (`b` applies first).
#[inline(always)]
pub fn transform_multiply<X: XformOps>(a: X, b: X) -> X {
    a.w_multiply(b)
}

/// `x` as a point under `t`: `t.q * x + t.p` for a transform, glam's
/// `m.transform_point3(x)` for a 4x4 matrix.
#[inline(always)]
pub fn transform_point<T: TransformPoint>(t: T, x: T::V3) -> T::V3 {
    t.w_transform_point(x)
}

/// `x` as a direction under `t`: `t.q * x` for a transform, glam's
/// `m.transform_vector3(x)` for a 4x4 matrix.
#[inline(always)]
pub fn transform_vector<T: TransformPoint>(t: T, x: T::V3) -> T::V3 {
    t.w_transform_vector(x)
}

/// The inverse of a rigid transform (Warp's `transform_inverse`; also `inverse(t)`).
#[inline(always)]
pub fn transform_inverse<X: XformOps>(t: X) -> X {
    t.w_inverse()
}

/// The 4x4 matrix of a transform.
#[inline(always)]
pub fn transform_to_matrix<X: XformOps>(t: X) -> X::M4 {
    t.w_to_matrix()
}

/// The transform of a 4x4 rigid-motion matrix.
#[inline(always)]
pub fn transform_from_matrix<M: XformMatrix>(m: M) -> M::X {
    m.w_transform_from_matrix()
}

macro_rules! xform_impl {
    ($($x:ident: $s:ident, $v3:ident, $q:ident, $m4:ident);*) => {$(
        impl XformParts for $v3 {
            type Q = $q;
            type X = $x;
            #[inline(always)]
            fn w_transformation(p: $v3, q: $q) -> $x {
                $x::new(p, q)
            }
        }
        impl XformOps for $x {
            type S = $s;
            type V3 = $v3;
            type Q = $q;
            type M4 = $m4;
            #[inline(always)]
            fn w_translation(self) -> $v3 {
                self.p
            }
            #[inline(always)]
            fn w_rotation(self) -> $q {
                self.q
            }
            #[inline(always)]
            fn w_multiply(self, b: Self) -> Self {
                self * b
            }
            #[inline(always)]
            fn w_inverse(self) -> Self {
                self.inverse()
            }
            #[inline(always)]
            fn w_to_matrix(self) -> $m4 {
                self.to_matrix()
            }
        }
        impl XformMatrix for $m4 {
            type X = $x;
            #[inline(always)]
            fn w_transform_from_matrix(self) -> $x {
                $x::from_matrix(self)
            }
        }
        impl TransformPoint for $x {
            type V3 = $v3;
            #[inline(always)]
            fn w_transform_point(self, x: $v3) -> $v3 {
                self.transform_point(x)
            }
            #[inline(always)]
            fn w_transform_vector(self, x: $v3) -> $v3 {
                self.transform_vector(x)
            }
        }
        impl TransformPoint for $m4 {
            type V3 = $v3;
            #[inline(always)]
            fn w_transform_point(self, x: $v3) -> $v3 {
                self.transform_point3(x)
            }
            #[inline(always)]
            fn w_transform_vector(self, x: $v3) -> $v3 {
                self.transform_vector3(x)
            }
        }
        impl Inverse for $x {
            #[inline(always)]
            fn w_inverse(self) -> Self {
                self.inverse()
            }
        }
        impl Lerp for $x {
            type Scalar = $s;
            #[inline(always)]
            fn w_lerp(self, b: Self, t: $s) -> Self {
                self.lerp(b, t)
            }
        }
    )*};
}
xform_impl!(Transform: f32, Vec3, Quat, Mat4; DTransform: f64, DVec3, DQuat, DMat4);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtins::{inverse, lerp};

    #[test]
    fn builtins_are_the_methods() {
        let t = transformation(
            Vec3::new(1.0, 2.0, 3.0),
            Quat::from_axis_angle(Vec3::Y, 0.5),
        );
        let x = Vec3::new(-0.5, 0.25, 2.0);
        assert_eq!(transform_point(t, x), t.q * x + t.p);
        assert_eq!(transform_vector(t, x), t.q * x);
        assert_eq!(transform_get_translation(t), t.p);
        assert_eq!(transform_get_rotation(t), t.q);
        assert_eq!(transform_multiply(t, t), t * t);
        assert_eq!(transform_inverse(t), inverse(t));
        let m = transform_to_matrix(t);
        assert_eq!(transform_point(m, x), m.transform_point3(x));
        assert_eq!(transform_vector(m, x), m.transform_vector3(x));
        assert_eq!(transform_from_matrix(m).p, t.p);
        assert_eq!(lerp(t, t, 0.5), t.lerp(t, 0.5));
        let d = transformation(DVec3::X, DQuat::IDENTITY);
        assert_eq!(transform_point(d, DVec3::Y), DVec3::new(1.0, 1.0, 0.0));
    }
}

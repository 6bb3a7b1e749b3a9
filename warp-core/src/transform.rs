//! Rigid transforms: [`Transform`] (f32) and [`DTransform`] (f64), NVIDIA Warp's
//! `wp.transform` / `wp.transformd`.
//!
//! A transform is a translation `p` and a rotation quaternion `q`; it maps a point `x` to
//! `q * x + p` (rotate, then translate). glam has no such type, so it lives here, with the
//! same operations on the host (plain Rust methods) as in kernels (builtins of the table's
//! "transform" section, on both backends).
//!
//! # Layout
//!
//! Both are `#[repr(C)]` and [`bytemuck::Pod`], so they can be array elements and kernel
//! arguments, and the CUDA library mirrors them (`wp::Transform`, `wp::DTransform` in
//! `warp-cuda/cuda/wp_core.h`, checked there by `static_assert`):
//!
//! | type         | `p` at | padding          | `q` at | size | align (x86_64)            |
//! |--------------|--------|------------------|--------|------|---------------------------|
//! | `Transform`  | 0      | 4 bytes at 12    | 16     | 32   | 16 (glam's SSE2 `Quat`)   |
//! | `DTransform` | 0      | none             | 24     | 56   | 8                         |
//!
//! Warp's `transform` is 7 packed floats (28 bytes); glam's `Quat` is 16-byte aligned, so an
//! explicit padding lane sits between `p` and `q` here. It is private, zero in every
//! transform this crate makes, and ignored by `==`, `Debug`, `Display` and every operation.
//! Where something treats a transform as lanes ([`Transform::to_array`], gradients, `lerp`),
//! the seven lanes are `p.x, p.y, p.z, q.x, q.y, q.z, q.w`.
//!
//! # Operations (Warp's definitions; glam's formulas where glam has the piece)
//!
//! * `a * b` (`transform_multiply`): `(a.q * b.p + a.p, a.q * b.q)`, the transform that
//!   applies `b` first;
//! * [`transform_point`](Transform::transform_point): `q * x + p`;
//!   [`transform_vector`](Transform::transform_vector): `q * x` (glam's rotation formula, as
//!   `quat_rotate`: exact for a unit `q`, scaled by `|q|²` otherwise);
//! * [`inverse`](Transform::inverse): `(-(q̄ * p), q̄)` with `q̄` the conjugate (the inverse
//!   for a unit `q`, as Warp's);
//! * `a + b`, `a - b`, `a * s`, `s * a`, `-a`: lane by lane (Warp's `add`, `sub`, `mul`,
//!   `neg` overloads; the rotation stops being unit, as in Warp);
//! * [`to_matrix`](Transform::to_matrix): the 4x4 matrix with `Mat3::from_quat(q)` in its
//!   upper-left block and `p` in its last column; [`from_matrix`](Transform::from_matrix):
//!   `p` from the last column, `q` by `Quat::from_mat3` of the upper-left block (not
//!   normalized, as the `quat_from_matrix` builtin);
//! * [`lerp`](Transform::lerp): `a * (1 - t) + b * t` lane by lane.

use core::fmt;
use core::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

use glam::{DMat3, DMat4, DQuat, DVec3, Mat3, Mat4, Quat, Vec3};

macro_rules! transform_type {
    (
        $(#[$doc:meta])*
        $t:ident, $s:ident, $v3:ident, $q:ident, $m3:ident, $m4:ident,
        pad: [$($pad:ident: $pt:ty = $pz:expr),*], name: $name:literal
    ) => {
        $(#[$doc])*
        #[repr(C)]
        #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $t {
            /// The translation.
            pub p: $v3,
            $($pad: $pt,)*
            /// The rotation (a unit quaternion for a rigid motion).
            pub q: $q,
        }

        impl $t {
            /// The identity: no translation, the identity rotation.
            pub const IDENTITY: Self = Self::new($v3::ZERO, $q::IDENTITY);

            /// The transform that rotates by `q`, then translates by `p` (Warp's
            /// `transformation(p, q)`).
            #[inline(always)]
            pub const fn new(p: $v3, q: $q) -> Self {
                Self { p, $($pad: $pz,)* q }
            }

            /// The seven lanes `p.x, p.y, p.z, q.x, q.y, q.z, q.w`.
            #[inline]
            pub fn to_array(&self) -> [$s; 7] {
                let (p, q) = (self.p, self.q);
                [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
            }

            /// The transform with lanes `a` (in [`Self::to_array`]'s order).
            #[inline]
            pub fn from_array(a: [$s; 7]) -> Self {
                Self::new($v3::new(a[0], a[1], a[2]), $q::from_xyzw(a[3], a[4], a[5], a[6]))
            }

            /// `x` as a point: rotated by `q`, then translated by `p` (`q * x + p`).
            #[inline]
            pub fn transform_point(&self, x: $v3) -> $v3 {
                self.q * x + self.p
            }

            /// `x` as a direction: rotated by `q` only (`q * x`).
            #[inline]
            pub fn transform_vector(&self, x: $v3) -> $v3 {
                self.q * x
            }

            /// The inverse of a rigid transform: `(-(q̄ * p), q̄)` with `q̄ = q.conjugate()`
            /// (exact for a unit `q`; no normalization, as in Warp).
            #[inline]
            pub fn inverse(&self) -> Self {
                let qi = self.q.conjugate();
                Self::new(-(qi * self.p), qi)
            }

            /// The 4x4 matrix of the transform: `Mat3::from_quat(q)` in the upper-left
            /// block, `p` in the last column, `(0, 0, 0, 1)` in the last row.
            #[inline]
            pub fn to_matrix(&self) -> $m4 {
                let r = $m3::from_quat(self.q);
                $m4::from_cols(
                    r.x_axis.extend(0.0),
                    r.y_axis.extend(0.0),
                    r.z_axis.extend(0.0),
                    self.p.extend(1.0),
                )
            }

            /// The transform of a 4x4 rigid-motion matrix: `p` from the last column, `q` by
            /// `Quat::from_mat3` of the upper-left 3x3 block (not normalized; the last row is
            /// not read).
            #[inline]
            pub fn from_matrix(m: $m4) -> Self {
                let r = $m3::from_cols(m.x_axis.truncate(), m.y_axis.truncate(), m.z_axis.truncate());
                Self::new(m.w_axis.truncate(), $q::from_mat3(&r))
            }

            /// `self * (1 - t) + b * t`, lane by lane (Warp's `lerp` of transforms: the
            /// rotation is not renormalized).
            #[inline]
            pub fn lerp(self, b: Self, t: $s) -> Self {
                let (x, y) = (self.to_array(), b.to_array());
                Self::from_array(core::array::from_fn(|k| x[k] * (1.0 - t) + y[k] * t))
            }

            /// Whether every lane is finite.
            #[inline]
            pub fn is_finite(&self) -> bool {
                self.p.is_finite() && self.q.is_finite()
            }
        }

        impl Default for $t {
            /// [`Self::IDENTITY`].
            #[inline]
            fn default() -> Self {
                Self::IDENTITY
            }
        }

        impl PartialEq for $t {
            /// Lane by lane (the padding is not compared).
            #[inline]
            fn eq(&self, o: &Self) -> bool {
                self.p == o.p && self.q == o.q
            }
        }

        impl fmt::Debug for $t {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.debug_struct($name).field("p", &self.p).field("q", &self.q).finish()
            }
        }

        impl fmt::Display for $t {
            /// `{p: [x, y, z], q: [x, y, z, w]}`.
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{{p: {}, q: {}}}", self.p, self.q)
            }
        }

        impl Mul for $t {
            type Output = $t;
            /// The composition `self ∘ b` (Warp's `transform_multiply`): `b` applies first.
            #[inline]
            fn mul(self, b: $t) -> $t {
                $t::new(self.q * b.p + self.p, self.q * b.q)
            }
        }

        impl Mul<$s> for $t {
            type Output = $t;
            /// Every lane times `s`.
            #[inline]
            fn mul(self, s: $s) -> $t {
                $t::new(self.p * s, self.q * s)
            }
        }

        impl Mul<$t> for $s {
            type Output = $t;
            /// Every lane times `self` (the same as `t * self`).
            #[inline]
            fn mul(self, t: $t) -> $t {
                t * self
            }
        }

        impl Add for $t {
            type Output = $t;
            /// Lane by lane.
            #[inline]
            fn add(self, b: $t) -> $t {
                $t::new(self.p + b.p, self.q + b.q)
            }
        }

        impl Sub for $t {
            type Output = $t;
            /// Lane by lane.
            #[inline]
            fn sub(self, b: $t) -> $t {
                $t::new(self.p - b.p, self.q - b.q)
            }
        }

        impl Neg for $t {
            type Output = $t;
            /// Every lane negated (glam's `-q` for the rotation).
            #[inline]
            fn neg(self) -> $t {
                $t::new(-self.p, -self.q)
            }
        }

        impl AddAssign for $t {
            #[inline]
            fn add_assign(&mut self, b: $t) {
                *self = *self + b;
            }
        }

        impl SubAssign for $t {
            #[inline]
            fn sub_assign(&mut self, b: $t) {
                *self = *self - b;
            }
        }

        impl From<$t> for $m4 {
            /// The transform's matrix (its `to_matrix`).
            #[inline]
            fn from(t: $t) -> $m4 {
                t.to_matrix()
            }
        }

        // The layout the CUDA library mirrors (see the module documentation).
        const _: () = {
            assert!(core::mem::offset_of!($t, p) == 0);
            assert!(core::mem::offset_of!($t, q) == core::mem::size_of::<$t>() - core::mem::size_of::<$q>());
        };
    };
}

transform_type!(
    /// A rigid transform in `f32`: translation `p` and rotation `q` (Warp's `transform`).
    ///
    /// `#[repr(C)]`, 32 bytes: `p` at 0, a private zero padding lane at 12, `q` at 16 (see
    /// the [module documentation](self)).
    ///
    /// ```
    /// use warp_core::Transform;
    /// use glam::{Quat, Vec3};
    /// let t = Transform::new(Vec3::new(1.0, 0.0, 0.0), Quat::from_rotation_z(core::f32::consts::FRAC_PI_2));
    /// let x = t.transform_point(Vec3::X);
    /// assert!((x - Vec3::new(1.0, 1.0, 0.0)).length() < 1e-6);
    /// assert!((t * t.inverse()).p.length() < 1e-6);
    /// ```
    Transform, f32, Vec3, Quat, Mat3, Mat4, pad: [pad: f32 = 0.0], name: "Transform"
);

transform_type!(
    /// A rigid transform in `f64`: translation `p` and rotation `q` (Warp's `transformd`).
    ///
    /// `#[repr(C)]`, 56 bytes: `p` at 0, `q` at 24, no padding (see the
    /// [module documentation](self)).
    DTransform, f64, DVec3, DQuat, DMat3, DMat4, pad: [], name: "DTransform"
);

impl Transform {
    /// The `f64` transform with the same lanes.
    pub fn as_dtransform(&self) -> DTransform {
        DTransform::new(self.p.as_dvec3(), self.q.as_dquat())
    }
}

impl DTransform {
    /// The `f32` transform with the lanes rounded to `f32`.
    pub fn as_transform(&self) -> Transform {
        Transform::new(self.p.as_vec3(), self.q.as_quat())
    }
}

const _: () = {
    assert!(core::mem::size_of::<Transform>() == 32);
    assert!(core::mem::offset_of!(Transform, q) == 16);
    assert!(core::mem::size_of::<DTransform>() == 56);
    assert!(core::mem::offset_of!(DTransform, q) == 24);
};

// Gradients of transform arrays: the seven lanes add atomically, `p` and `q` each through
// their own element type (the padding lane is never touched).
macro_rules! grad_element {
    ($($t:ident: $v3:ident, $q:ident);*) => {$(
        impl crate::grad::GradElement for $t {
            #[inline(always)]
            unsafe fn grad_add(ptr: *mut Self, v: Self) {
                // SAFETY: `ptr` is a live, aligned element (forwarded contract), so are its
                // fields.
                unsafe {
                    <$v3 as crate::grad::GradElement>::grad_add(core::ptr::addr_of_mut!((*ptr).p), v.p);
                    <$q as crate::grad::GradElement>::grad_add(core::ptr::addr_of_mut!((*ptr).q), v.q);
                }
            }
        }
    )*};
}
grad_element!(Transform: Vec3, Quat; DTransform: DVec3, DQuat);

#[cfg(test)]
mod tests {
    use super::*;

    fn t1() -> DTransform {
        DTransform::new(
            DVec3::new(0.5, -1.0, 2.0),
            DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.7),
        )
    }
    fn t2() -> DTransform {
        DTransform::new(
            DVec3::new(-0.3, 0.25, 1.5),
            DQuat::from_axis_angle(DVec3::new(0.0, -1.0, 3.0).normalize(), -1.9),
        )
    }

    #[test]
    fn composition_is_application_in_order() {
        let (a, b) = (t1(), t2());
        let x = DVec3::new(0.3, 0.9, -1.7);
        let lhs = (a * b).transform_point(x);
        let rhs = a.transform_point(b.transform_point(x));
        assert!((lhs - rhs).length() < 1e-14, "{lhs} vs {rhs}");
        let v = (a * b).transform_vector(x) - a.transform_vector(b.transform_vector(x));
        assert!(v.length() < 1e-14);
        // The matrix of a composition is the product of the matrices.
        let m = (a * b).to_matrix() - a.to_matrix() * b.to_matrix();
        assert!(m.to_cols_array().iter().all(|e| e.abs() < 1e-14));
    }

    #[test]
    fn inverse_and_matrix_round_trips() {
        let a = t1();
        let id = a * a.inverse();
        assert!(id.p.length() < 1e-15 && (id.q.w.abs() - 1.0).abs() < 1e-15);
        let back = DTransform::from_matrix(a.to_matrix());
        assert!((back.p - a.p).length() == 0.0);
        assert!(back.q.dot(a.q).abs() > 1.0 - 1e-15);
        assert_eq!(Transform::IDENTITY.to_matrix(), Mat4::IDENTITY);
        assert_eq!(Transform::from_matrix(Mat4::IDENTITY), Transform::IDENTITY);
    }

    #[test]
    fn lanes_padding_and_lane_ops() {
        let t = Transform::from_array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        assert_eq!(t.to_array(), [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        let bytes: [u32; 8] = bytemuck::cast(t);
        assert_eq!(bytes[3], 0, "the padding lane is zero");
        assert_eq!((t + t).to_array(), (t * 2.0).to_array());
        assert_eq!((2.0 * t).to_array(), (t * 2.0).to_array());
        assert_eq!((t - t).to_array(), [0.0; 7]);
        assert_eq!((-t).to_array(), t.to_array().map(|x| -x));
        assert_eq!(t.lerp(-t, 0.5).to_array(), [0.0; 7]);
        assert_eq!(
            format!("{}", Transform::IDENTITY),
            "{p: [0, 0, 0], q: [0, 0, 0, 1]}"
        );
        assert!(!Transform::new(Vec3::NAN, Quat::IDENTITY).is_finite());
        assert_eq!(Transform::default(), Transform::IDENTITY);
        assert_eq!(t.as_dtransform().as_transform(), t);
    }
}

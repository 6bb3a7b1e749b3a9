//! Adjoints of the rigid-transform operators and builtins ([`crate::builtins::transform`]),
//! Warp's rules (`warp/native/spatial.h`), through the quaternion adjoints where the forward
//! goes through a quaternion operation. `g` is `adj_ret`; every rule accumulates, in the
//! order written (the CUDA mirror, `wp_adjoint.h`, does the same steps):
//!
//! * `a + b`, `a - b`, `-a`: fieldwise (`adj_a += g`, `adj_b ±= g`, `adj_a -= g`);
//! * `t * s`, `s * t`: the lane rule of `*` over the seven lanes `p.x .. q.w`, `s`'s adjoint
//!   collecting them in that order; `lerp(a, b, t)`: the lane rule of `lerp`, likewise;
//! * `a * b` (`transform_multiply`): `adj_mul(a.q, b.p)` with `g.p` (rotation adjoint), then
//!   `adj_a.p += g.p`, then the Hamilton product's adjoint `adj_mul(a.q, b.q)` with `g.q`;
//! * `transformation(p, q)`: `adj_p += g.p`, `adj_q += g.q`; `transform_get_translation`:
//!   `adj_t.p += g`; `transform_get_rotation`: `adj_t.q += g`;
//! * `transform_point(t, x)`: `adj_mul(t.q, x)` with `g`, then `adj_t.p += g`;
//!   `transform_vector(t, x)`: `adj_mul(t.q, x)` with `g`;
//! * `transform_inverse(t)` (and `inverse(t)`), forward `q̄ = conjugate(q)`,
//!   `r = -(q̄ * p)`: with `adj_q̄ = g.q`, `adj_mul(q̄, t.p)` with `-g.p` into `adj_q̄` and
//!   `adj_t.p`, then `adj_t.q += conjugate(adj_q̄)`;
//! * `transform_to_matrix(t)`: `adj_quat_to_matrix(t.q)` with the upper-left 3x3 block of
//!   `G`, then `adj_t.p += G.w_axis.xyz`;
//! * `transform_from_matrix(m)`: `adj_quat_from_matrix` of the upper-left block, accumulated
//!   into that block of `adj_m`, then `adj_m.w_axis.xyz += g.p`;
//! * 4x4 `transform_point(m, x)`: `adj_m.{x,y,z}_axis[k] += g[k] * x.{x,y,z}` and
//!   `adj_m.w_axis[k] += g[k]` for `k < 3`; `adj_x.x += (x_axis.x * g.x + x_axis.y * g.y) +
//!   x_axis.z * g.z` (likewise `y`, `z` with `y_axis`, `z_axis`); `transform_vector(m, x)`
//!   the same without the `w_axis` term.

use glam::{DMat3, DMat4, DQuat, DVec3, Mat3, Mat4, Quat, Vec3};

use super::lanes::{l_lerp, l_mul, zip_sv, zip_vs, zip_vv, Lanes};
use super::linalg::{AdjInverse, AdjQuat};
use super::ops::{AdjAdd, AdjMul, AdjNeg, AdjSub};
use super::{AdjLerp, Adjoint};
use crate::builtins::transform::{TransformPoint, XformMatrix, XformOps, XformParts};
use crate::transform::{DTransform, Transform};

/// Adjoint of `transformation(p, q)`: `Vec3`, `DVec3`.
pub trait AdjXformParts: XformParts + Adjoint {
    /// See [`adj_transformation`].
    fn adj_transformation(p: Self, q: Self::Q, adj_p: &mut Self, adj_q: &mut Self::Q, g: Self::X);
}

/// Adjoint of `transformation(p, q)`: `adj_p += g.p`, `adj_q += g.q`.
#[inline(always)]
pub fn adj_transformation<V: AdjXformParts>(
    p: V,
    q: V::Q,
    adj_p: &mut V,
    adj_q: &mut V::Q,
    adj_ret: V::X,
) {
    V::adj_transformation(p, q, adj_p, adj_q, adj_ret)
}

/// Adjoints of the transform builtins: [`Transform`], [`DTransform`].
pub trait AdjXform: XformOps + Adjoint {
    /// See [`adj_transform_get_translation`].
    fn adj_translation(t: Self, adj_t: &mut Self, g: Self::V3);
    /// See [`adj_transform_get_rotation`].
    fn adj_rotation(t: Self, adj_t: &mut Self, g: Self::Q);
    /// See [`adj_transform_multiply`].
    fn adj_multiply(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, g: Self);
    /// See [`adj_transform_inverse`].
    fn adj_xform_inverse(t: Self, adj_t: &mut Self, g: Self);
    /// See [`adj_transform_to_matrix`].
    fn adj_to_matrix(t: Self, adj_t: &mut Self, g: Self::M4);
}

/// Adjoint of `transform_get_translation(t)`: `adj_t.p += g`.
#[inline(always)]
pub fn adj_transform_get_translation<X: AdjXform>(t: X, adj_t: &mut X, adj_ret: X::V3) {
    X::adj_translation(t, adj_t, adj_ret)
}

/// Adjoint of `transform_get_rotation(t)`: `adj_t.q += g`.
#[inline(always)]
pub fn adj_transform_get_rotation<X: AdjXform>(t: X, adj_t: &mut X, adj_ret: X::Q) {
    X::adj_rotation(t, adj_t, adj_ret)
}

/// Adjoint of `transform_multiply(a, b)` (`a * b`; see the module documentation).
#[inline(always)]
pub fn adj_transform_multiply<X: AdjXform>(a: X, b: X, adj_a: &mut X, adj_b: &mut X, adj_ret: X) {
    X::adj_multiply(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoint of `transform_inverse(t)` (see the module documentation).
#[inline(always)]
pub fn adj_transform_inverse<X: AdjXform>(t: X, adj_t: &mut X, adj_ret: X) {
    X::adj_xform_inverse(t, adj_t, adj_ret)
}

/// Adjoint of `transform_to_matrix(t)` (see the module documentation).
#[inline(always)]
pub fn adj_transform_to_matrix<X: AdjXform>(t: X, adj_t: &mut X, adj_ret: X::M4) {
    X::adj_to_matrix(t, adj_t, adj_ret)
}

/// Adjoint of `transform_from_matrix(m)`: `Mat4`, `DMat4`.
pub trait AdjXformMatrix: XformMatrix + Adjoint {
    /// See [`adj_transform_from_matrix`].
    fn adj_from_matrix(m: Self, adj_m: &mut Self, g: Self::X);
}

/// Adjoint of `transform_from_matrix(m)` (see the module documentation).
#[inline(always)]
pub fn adj_transform_from_matrix<M: AdjXformMatrix>(m: M, adj_m: &mut M, adj_ret: M::X) {
    M::adj_from_matrix(m, adj_m, adj_ret)
}

/// Adjoints of `transform_point`, `transform_vector`: transforms and 4x4 matrices.
pub trait AdjTransformPoint: TransformPoint<V3: Adjoint> + Adjoint {
    /// See [`adj_transform_point`].
    fn adj_point(t: Self, x: Self::V3, adj_t: &mut Self, adj_x: &mut Self::V3, g: Self::V3);
    /// See [`adj_transform_vector`].
    fn adj_vector(t: Self, x: Self::V3, adj_t: &mut Self, adj_x: &mut Self::V3, g: Self::V3);
}

/// Adjoint of `transform_point(t, x)` (see the module documentation).
#[inline(always)]
pub fn adj_transform_point<T: AdjTransformPoint>(
    t: T,
    x: T::V3,
    adj_t: &mut T,
    adj_x: &mut T::V3,
    adj_ret: T::V3,
) {
    T::adj_point(t, x, adj_t, adj_x, adj_ret)
}

/// Adjoint of `transform_vector(t, x)` (see the module documentation).
#[inline(always)]
pub fn adj_transform_vector<T: AdjTransformPoint>(
    t: T,
    x: T::V3,
    adj_t: &mut T,
    adj_x: &mut T::V3,
    adj_ret: T::V3,
) {
    T::adj_vector(t, x, adj_t, adj_x, adj_ret)
}

macro_rules! xform_adj {
    ($($x:ident: $s:ident, $v3:ident, $q:ident, $m3:ident, $m4:ident);*) => {$(
        impl Adjoint for $x {
            /// All seven lanes zero (the rotation too: not the identity).
            #[inline(always)]
            fn adj_zero() -> Self {
                $x::new($v3::ZERO, $q::from_xyzw(0.0, 0.0, 0.0, 0.0))
            }
            #[inline(always)]
            fn adj_accum(&mut self, v: Self) {
                *self += v;
            }
        }
        impl Lanes for $x {
            type S = $s;
            type A = [$s; 7];
            #[inline(always)]
            fn lanes(self) -> [$s; 7] {
                self.to_array()
            }
            #[inline(always)]
            fn from_lanes(a: [$s; 7]) -> Self {
                $x::from_array(a)
            }
        }
        impl AdjAdd for $x {
            type Output = $x;
            #[inline(always)]
            fn adj_add(_a: $x, _b: $x, adj_a: &mut $x, adj_b: &mut $x, g: $x) {
                *adj_a += g;
                *adj_b += g;
            }
        }
        impl AdjSub for $x {
            type Output = $x;
            #[inline(always)]
            fn adj_sub(_a: $x, _b: $x, adj_a: &mut $x, adj_b: &mut $x, g: $x) {
                *adj_a += g;
                *adj_b -= g;
            }
        }
        impl AdjNeg for $x {
            #[inline(always)]
            fn adj_neg(_a: $x, adj_a: &mut $x, g: $x) {
                *adj_a -= g;
            }
        }
        impl AdjMul for $x {
            type Output = $x;
            #[inline(always)]
            fn adj_mul(a: $x, b: $x, adj_a: &mut $x, adj_b: &mut $x, g: $x) {
                <$x as AdjXform>::adj_multiply(a, b, adj_a, adj_b, g)
            }
        }
        impl AdjMul<$s> for $x {
            type Output = $x;
            #[inline(always)]
            fn adj_mul(a: $x, s: $s, adj_a: &mut $x, adj_s: &mut $s, g: $x) {
                zip_vs(a, s, adj_a, adj_s, g, l_mul)
            }
        }
        impl AdjMul<$x> for $s {
            type Output = $x;
            #[inline(always)]
            fn adj_mul(s: $s, b: $x, adj_s: &mut $s, adj_b: &mut $x, g: $x) {
                zip_sv(s, b, adj_s, adj_b, g, l_mul)
            }
        }
        impl AdjLerp for $x {
            #[inline(always)]
            fn adj_lerp(a: $x, b: $x, t: $s, aa: &mut $x, ab: &mut $x, at: &mut $s, g: $x) {
                zip_vv(a, b, aa, ab, g, |x, y, ax: &mut $s, ay: &mut $s, gi| {
                    l_lerp(x, y, t, ax, ay, at, gi)
                })
            }
        }
        impl AdjInverse for $x {
            #[inline(always)]
            fn adj_inverse(t: $x, adj_t: &mut $x, g: $x) {
                <$x as AdjXform>::adj_xform_inverse(t, adj_t, g)
            }
        }
        impl AdjXformParts for $v3 {
            #[inline(always)]
            fn adj_transformation(_p: $v3, _q: $q, adj_p: &mut $v3, adj_q: &mut $q, g: $x) {
                *adj_p += g.p;
                *adj_q += g.q;
            }
        }
        impl AdjXform for $x {
            #[inline(always)]
            fn adj_translation(_t: $x, adj_t: &mut $x, g: $v3) {
                adj_t.p += g;
            }
            #[inline(always)]
            fn adj_rotation(_t: $x, adj_t: &mut $x, g: $q) {
                adj_t.q += g;
            }
            #[inline(always)]
            fn adj_multiply(a: $x, b: $x, adj_a: &mut $x, adj_b: &mut $x, g: $x) {
                <$q as AdjMul<$v3>>::adj_mul(a.q, b.p, &mut adj_a.q, &mut adj_b.p, g.p);
                adj_a.p += g.p;
                <$q as AdjMul>::adj_mul(a.q, b.q, &mut adj_a.q, &mut adj_b.q, g.q);
            }
            #[inline(always)]
            fn adj_xform_inverse(t: $x, adj_t: &mut $x, g: $x) {
                let qi = t.q.conjugate();
                let mut adj_qi = g.q;
                <$q as AdjMul<$v3>>::adj_mul(qi, t.p, &mut adj_qi, &mut adj_t.p, -g.p);
                <$q as AdjQuat>::adj_conjugate(t.q, &mut adj_t.q, adj_qi);
            }
            #[inline(always)]
            fn adj_to_matrix(t: $x, adj_t: &mut $x, g: $m4) {
                let g3 = $m3::from_cols(g.x_axis.truncate(), g.y_axis.truncate(), g.z_axis.truncate());
                <$q as AdjQuat>::adj_to_matrix(t.q, &mut adj_t.q, g3);
                adj_t.p += g.w_axis.truncate();
            }
        }
        impl AdjXformMatrix for $m4 {
            #[inline(always)]
            fn adj_from_matrix(m: $m4, adj_m: &mut $m4, g: $x) {
                let m3 = $m3::from_cols(m.x_axis.truncate(), m.y_axis.truncate(), m.z_axis.truncate());
                let mut a3 = $m3::from_cols(
                    adj_m.x_axis.truncate(),
                    adj_m.y_axis.truncate(),
                    adj_m.z_axis.truncate(),
                );
                <$q as AdjQuat>::adj_from_matrix(m3, &mut a3, g.q);
                adj_m.x_axis = a3.x_axis.extend(adj_m.x_axis.w);
                adj_m.y_axis = a3.y_axis.extend(adj_m.y_axis.w);
                adj_m.z_axis = a3.z_axis.extend(adj_m.z_axis.w);
                let w = adj_m.w_axis.truncate() + g.p;
                adj_m.w_axis = w.extend(adj_m.w_axis.w);
            }
        }
        impl AdjTransformPoint for $x {
            #[inline(always)]
            fn adj_point(t: $x, x: $v3, adj_t: &mut $x, adj_x: &mut $v3, g: $v3) {
                <$q as AdjMul<$v3>>::adj_mul(t.q, x, &mut adj_t.q, adj_x, g);
                adj_t.p += g;
            }
            #[inline(always)]
            fn adj_vector(t: $x, x: $v3, adj_t: &mut $x, adj_x: &mut $v3, g: $v3) {
                <$q as AdjMul<$v3>>::adj_mul(t.q, x, &mut adj_t.q, adj_x, g);
            }
        }
        impl AdjTransformPoint for $m4 {
            #[inline(always)]
            fn adj_point(m: $m4, x: $v3, adj_m: &mut $m4, adj_x: &mut $v3, g: $v3) {
                <$m4 as AdjTransformPoint>::adj_vector(m, x, adj_m, adj_x, g);
                let w = adj_m.w_axis.truncate() + g;
                adj_m.w_axis = w.extend(adj_m.w_axis.w);
            }
            #[inline(always)]
            fn adj_vector(m: $m4, x: $v3, adj_m: &mut $m4, adj_x: &mut $v3, g: $v3) {
                let cols = [m.x_axis.truncate(), m.y_axis.truncate(), m.z_axis.truncate()];
                let xs = [x.x, x.y, x.z];
                let mut a = [adj_m.x_axis, adj_m.y_axis, adj_m.z_axis];
                for (c, ac) in a.iter_mut().enumerate() {
                    let v = ac.truncate() + g * xs[c];
                    *ac = v.extend(ac.w);
                }
                adj_m.x_axis = a[0];
                adj_m.y_axis = a[1];
                adj_m.z_axis = a[2];
                let d = |c: $v3| (c.x * g.x + c.y * g.y) + c.z * g.z;
                adj_x.x += d(cols[0]);
                adj_x.y += d(cols[1]);
                adj_x.z += d(cols[2]);
            }
        }
    )*};
}
xform_adj!(
    Transform: f32, Vec3, Quat, Mat3, Mat4;
    DTransform: f64, DVec3, DQuat, DMat3, DMat4
);

#[cfg(test)]
mod tests {
    use super::*;

    /// Central differences of a scalar function of the seven lanes of a transform and the
    /// three of a vector, against the adjoints (f64).
    fn check(
        f: impl Fn(DTransform, DVec3) -> f64,
        adj: impl Fn(DTransform, DVec3, &mut DTransform, &mut DVec3),
    ) {
        let t = DTransform::new(
            DVec3::new(0.4, -1.1, 0.7),
            DQuat::from_xyzw(0.3, -0.2, 0.5, 0.8),
        );
        let x = DVec3::new(-0.6, 0.9, 1.3);
        let (mut at, mut ax) = (DTransform::adj_zero(), DVec3::ZERO);
        adj(t, x, &mut at, &mut ax);
        let h = 1e-6;
        for k in 0..7 {
            let mut p = t.to_array();
            let mut m = p;
            p[k] += h;
            m[k] -= h;
            let fd =
                (f(DTransform::from_array(p), x) - f(DTransform::from_array(m), x)) / (2.0 * h);
            assert!(
                (fd - at.to_array()[k]).abs() < 1e-7,
                "lane {k}: {fd} vs {}",
                at.to_array()[k]
            );
        }
        for k in 0..3 {
            let (mut p, mut m) = (x, x);
            p[k] += h;
            m[k] -= h;
            let fd = (f(t, p) - f(t, m)) / (2.0 * h);
            assert!((fd - ax[k]).abs() < 1e-7, "x[{k}]: {fd} vs {}", ax[k]);
        }
    }

    #[test]
    fn adjoints_match_central_differences() {
        let probe = DVec3::new(0.3, -0.7, 1.1);
        let pt = DTransform::new(
            DVec3::new(1.0, 2.0, -0.5),
            DQuat::from_xyzw(-0.1, 0.4, 0.2, 0.9),
        );
        check(
            |t, x| t.transform_point(x).dot(probe),
            |t, x, at, ax| adj_transform_point(t, x, at, ax, probe),
        );
        check(
            |t, x| t.transform_vector(x).dot(probe),
            |t, x, at, ax| adj_transform_vector(t, x, at, ax, probe),
        );
        // t * pt and pt * t, through the lanes of the result.
        let w = DTransform::from_array([0.5, -0.25, 1.0, 0.3, -0.6, 0.2, 0.7]);
        let dotx = |a: DTransform| {
            a.to_array()
                .iter()
                .zip(w.to_array())
                .map(|(a, b)| a * b)
                .sum::<f64>()
        };
        check(
            |t, _| dotx(t * pt),
            |t, _, at, _| {
                let mut ab = DTransform::adj_zero();
                adj_transform_multiply(t, pt, at, &mut ab, w)
            },
        );
        check(
            |t, _| dotx(pt * t),
            |t, _, at, _| {
                let mut aa = DTransform::adj_zero();
                adj_transform_multiply(pt, t, &mut aa, at, w)
            },
        );
        check(
            |t, _| dotx(t.inverse()),
            |t, _, at, _| adj_transform_inverse(t, at, w),
        );
        let gm = DMat4::from_cols_array(&core::array::from_fn(|k| (k as f64 * 0.37).sin()));
        check(
            |t, _| {
                let m = t.to_matrix();
                m.to_cols_array()
                    .iter()
                    .zip(gm.to_cols_array())
                    .map(|(a, b)| a * b)
                    .sum()
            },
            |t, _, at, _| adj_transform_to_matrix(t, at, gm),
        );
        // The matrix overloads, with the lanes of t's matrix as the inputs.
        check(
            |t, x| {
                t.to_matrix().transform_point3(x).dot(probe)
                    + t.to_matrix().transform_vector3(x).dot(x)
            },
            |t, x, at, ax| {
                let m = t.to_matrix();
                let mut am = DMat4::ZERO;
                adj_transform_point(m, x, &mut am, ax, probe);
                adj_transform_vector(m, x, &mut am, ax, x);
                *ax += m.transform_vector3(x); // the second use of x
                adj_transform_to_matrix(t, at, am);
            },
        );
        // from_matrix(to_matrix(t)) with a unit rotation is t (up to the sign of q).
        let unit = |t: DTransform| DTransform::new(t.p, t.q.normalize());
        check(
            |t, _| dotx(DTransform::from_matrix(unit(t).to_matrix())),
            |t, _, at, _| {
                let u = unit(t);
                let m = u.to_matrix();
                let mut am = DMat4::ZERO;
                adj_transform_from_matrix(m, &mut am, w);
                let mut au = DTransform::adj_zero();
                adj_transform_to_matrix(u, &mut au, am);
                at.p += au.p;
                let mut aq = DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
                super::super::adj_normalize(t.q, &mut aq, au.q);
                at.q += aq;
            },
        );
        check(
            |t, _| dotx(t.lerp(pt, 0.3)) + dotx(t * 1.7) + dotx(-t) + dotx(t + pt) + dotx(pt - t),
            |t, _, at, _| {
                let (mut ab, mut ats) = (DTransform::adj_zero(), 0.0);
                adj_lerp(t, pt, 0.3, at, &mut ab, &mut ats, w);
                let mut s = 0.0;
                <DTransform as AdjMul<f64>>::adj_mul(t, 1.7, at, &mut s, w);
                <DTransform as AdjNeg>::adj_neg(t, at, w);
                <DTransform as AdjAdd>::adj_add(t, pt, at, &mut ab, w);
                <DTransform as AdjSub>::adj_sub(pt, t, &mut ab, at, w);
            },
        );
    }

    use super::super::adj_lerp;
}

//! Adjoints of the vector, matrix and quaternion builtins ([`crate::builtins::linalg`]).
//!
//! Same convention as every adjoint here: `adj_<name>(args.., adj_args.., adj_ret)`
//! accumulates. Rules (`g` is `adj_ret`):
//!
//! * `length_sq(v)`: `adj_v[i] += (v[i] + v[i]) * g` (nothing for integer vectors);
//! * `outer(a, b)`: `adj_a += G * b`, `adj_b += Gᵀ * a` (glam's matrix-vector products);
//! * `diag(v)`: `adj_v[i] += G[i][i]`; `trace(m)`: `adj_m[i][i] += g`;
//! * `cw_mul`, `cw_div`: the lane rules of `*` and `/`; `ddot(a, b)`: `adj_a[k] += g * b[k]`,
//!   `adj_b[k] += g * a[k]` lane by lane (column-major);
//! * `transpose(m)`: `adj_m += Gᵀ`;
//! * `determinant(m)`: `adj_m += g * cofactor(m)`, which is defined for singular matrices too
//!   (2x2: `(y.y, -y.x; -x.y, x.x)`; 3x3: columns `y × z`, `z × x`, `x × y`; 4x4: each entry's
//!   signed 3x3 minor, that minor's determinant being glam's `Mat3` one of the remaining
//!   columns and rows in order);
//! * `inverse(m)`: with `T = transpose(inverse(m))`, `adj_m -= (T * G) * T` (Giles 2008); at a
//!   singular matrix the forward is the constant zero matrix and so is this (`T = 0`);
//! * `skew(v)`: `adj_v.x += G.y_axis.z - G.z_axis.y`, `adj_v.y += G.z_axis.x - G.x_axis.z`,
//!   `adj_v.z += G.x_axis.y - G.y_axis.x`;
//! * quaternion `dot`, `length`, `normalize`: the vector rules over the lanes `x, y, z, w` (with
//!   the quaternion dot's order); `normalize` gives nothing where the forward returned the
//!   identity;
//! * `inverse(q)`, `quat_inverse(q)`: `adj_q += (-g.x, -g.y, -g.z, g.w)`;
//! * `quat_rotate(q, v)`: the adjoint of glam's `q * v` (`adj_mul`); `quat_rotate_inv(q, v)`:
//!   that of `conjugate(q) * v`, then through the conjugate;
//! * `quat_from_axis_angle(axis, angle)`: with `h = angle * 0.5`, `s = sin h`, `c = cos h`:
//!   `adj_axis += g.xyz * s`, `adj_angle += (((g.x*a.x + g.y*a.y) + g.z*a.z) * c - g.w * s) * 0.5`;
//! * `quat_to_matrix(q)`: the derivative of glam's `from_quat` polynomial (see
//!   [`adj_quat_to_matrix`]);
//! * `quat_from_matrix(m)`: through the branch the forward took: with `f` the branch's
//!   `4 q_k²` term and `inv = 0.5 / sqrt(f)`, `q_k = f * inv` and the others `L_j * inv`:
//!   `adj_f = g_k * (inv * 0.5) + (Σ g_j L_j) * -(inv / (f + f))`, `adj_L_j = g_j * inv`;
//! * `quat_slerp(q0, q1, t)`: the reverse of its forward's steps with the adjoints of `*`,
//!   `quat_from_axis_angle`, `atan2`, `abs`, `length` and `normalize` — so, like those, it
//!   gives nothing through the axis where `conjugate(q0) * q1` has a zero vector part (at
//!   `q0 == q1` the gradient of the result with respect to the inputs' difference is lost).

use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};

use super::builtins::{AdjDot, AdjFloatVec};
use super::lanes::{l_div, l_mul, zip_vv};
use super::ops::AdjMul;
use super::{adj_abs, adj_atan2, adj_length, adj_normalize, AdjFloat, Adjoint};
use crate::builtins::linalg::{Inverse, QuatOps, SquareMat};
use crate::builtins::math::{Float, FloatVec, Signed, VecOps};

/// Adjoint of `length_sq`: vectors and quaternions; a no-op for integer vectors.
pub trait AdjLengthSq: VecOps + Adjoint {
    /// See [`adj_length_sq`].
    fn adj_length_sq(v: Self, adj_v: &mut Self, adj_ret: Self::Scalar);
}

/// Adjoint of `length_sq(v)`: `adj_v[i] += (v[i] + v[i]) * g`.
#[inline(always)]
pub fn adj_length_sq<V: AdjLengthSq>(v: V, adj_v: &mut V, adj_ret: V::Scalar) {
    V::adj_length_sq(v, adj_v, adj_ret)
}

/// Adjoints of the vector-to-matrix builtins: float vectors.
pub trait AdjVecMat: Adjoint + Sized {
    /// The matrix.
    type Mat;
    /// See [`adj_outer`].
    fn adj_outer(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, adj_ret: Self::Mat);
    /// See [`adj_diag`].
    fn adj_diag(v: Self, adj_v: &mut Self, adj_ret: Self::Mat);
}

/// Adjoint of `outer`: the float vectors (through [`AdjVecMat`]) and the spatial vectors,
/// and two vectors of different lengths (`crate::matrix`).
pub trait AdjOuter<B = Self>: Adjoint + Sized {
    /// The matrix.
    type Mat;
    /// See [`adj_outer`].
    fn adj_outer_of(a: Self, b: B, adj_a: &mut Self, adj_b: &mut B, adj_ret: Self::Mat);
}

/// Adjoint of `transpose`: the glam matrices (through [`AdjMat`]), the spatial matrices and
/// the non-square matrices.
pub trait AdjTranspose: Adjoint + Sized {
    /// The transpose's type.
    type T;
    /// See [`adj_transpose`].
    fn adj_transposed(m: Self, adj_m: &mut Self, adj_ret: Self::T);
}

/// Adjoint of `ddot`: the glam matrices (through [`AdjMat`]) and the non-square matrices.
pub trait AdjDdot: Adjoint + Sized {
    /// The scalar.
    type S;
    /// See [`adj_ddot`].
    fn adj_ddot_of(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, adj_ret: Self::S);
}

impl<M: AdjMat> AdjDdot for M {
    type S = <M as SquareMat>::S;
    #[inline(always)]
    fn adj_ddot_of(a: M, b: M, adj_a: &mut M, adj_b: &mut M, g: Self::S) {
        M::adj_ddot(a, b, adj_a, adj_b, g)
    }
}

/// Adjoint of `outer(a, b)`: `adj_a += G * b`, `adj_b += Gᵀ * a`.
#[inline(always)]
pub fn adj_outer<A: AdjOuter<B>, B>(a: A, b: B, adj_a: &mut A, adj_b: &mut B, adj_ret: A::Mat) {
    A::adj_outer_of(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoint of `diag(v)`: `adj_v[i] += G[i][i]`.
#[inline(always)]
pub fn adj_diag<V: AdjVecMat>(v: V, adj_v: &mut V, adj_ret: V::Mat) {
    V::adj_diag(v, adj_v, adj_ret)
}

/// Adjoints of `cw_mul`, `cw_div`: float vectors and matrices.
pub trait AdjCw: Adjoint {
    /// See [`adj_cw_mul`].
    fn adj_cw_mul(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, adj_ret: Self);
    /// See [`adj_cw_div`].
    fn adj_cw_div(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, adj_ret: Self);
}

/// Adjoint of `cw_mul(a, b)`: the lane rule of `*`.
#[inline(always)]
pub fn adj_cw_mul<T: AdjCw>(a: T, b: T, adj_a: &mut T, adj_b: &mut T, adj_ret: T) {
    T::adj_cw_mul(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoint of `cw_div(a, b)`: the lane rule of `/`.
#[inline(always)]
pub fn adj_cw_div<T: AdjCw>(a: T, b: T, adj_a: &mut T, adj_b: &mut T, adj_ret: T) {
    T::adj_cw_div(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoints of the matrix builtins: `Mat2-4`, `DMat2-4`.
pub trait AdjMat: SquareMat + Adjoint {
    /// See [`adj_transpose`].
    fn adj_transpose(m: Self, adj_m: &mut Self, adj_ret: Self);
    /// See [`adj_determinant`].
    fn adj_determinant(m: Self, adj_m: &mut Self, adj_ret: Self::S);
    /// See [`adj_trace`].
    fn adj_trace(m: Self, adj_m: &mut Self, adj_ret: Self::S);
    /// See [`adj_ddot`].
    fn adj_ddot(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, adj_ret: Self::S);
}

/// Adjoint of `transpose(m)`: `adj_m += Gᵀ`.
#[inline(always)]
pub fn adj_transpose<M: AdjTranspose>(m: M, adj_m: &mut M, adj_ret: M::T) {
    M::adj_transposed(m, adj_m, adj_ret)
}

/// Adjoint of `determinant(m)`: `adj_m += g * cofactor(m)` (see the module documentation).
#[inline(always)]
pub fn adj_determinant<M: AdjMat>(m: M, adj_m: &mut M, adj_ret: M::S) {
    M::adj_determinant(m, adj_m, adj_ret)
}

/// Adjoint of `trace(m)`: `adj_m[i][i] += g`.
#[inline(always)]
pub fn adj_trace<M: AdjMat>(m: M, adj_m: &mut M, adj_ret: M::S) {
    M::adj_trace(m, adj_m, adj_ret)
}

/// Adjoint of `ddot(a, b)`: `adj_a[k] += g * b[k]`, `adj_b[k] += g * a[k]`.
#[inline(always)]
pub fn adj_ddot<M: AdjDdot>(a: M, b: M, adj_a: &mut M, adj_b: &mut M, adj_ret: M::S) {
    M::adj_ddot_of(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoint of `inverse`: matrices and quaternions.
pub trait AdjInverse: Inverse + Adjoint {
    /// See [`adj_inverse`].
    fn adj_inverse(x: Self, adj_x: &mut Self, adj_ret: Self);
}

/// Adjoint of `inverse(m)`: `adj_m -= (T * G) * T` with `T = transpose(inverse(m))`; of
/// `inverse(q)`: `adj_q += (-g.x, -g.y, -g.z, g.w)`.
#[inline(always)]
pub fn adj_inverse<T: AdjInverse>(x: T, adj_x: &mut T, adj_ret: T) {
    T::adj_inverse(x, adj_x, adj_ret)
}

/// Adjoint of `skew`: `Vec3`, `DVec3`.
pub trait AdjSkew: Adjoint + Sized {
    /// The matrix.
    type Mat;
    /// See [`adj_skew`].
    fn adj_skew(v: Self, adj_v: &mut Self, adj_ret: Self::Mat);
}

/// Adjoint of `skew(v)` (see the module documentation).
#[inline(always)]
pub fn adj_skew<V: AdjSkew>(v: V, adj_v: &mut V, adj_ret: V::Mat) {
    V::adj_skew(v, adj_v, adj_ret)
}

/// Adjoints of the quaternion builtins: `Quat`, `DQuat`.
pub trait AdjQuat: QuatOps<S: AdjFloat> + Adjoint {
    /// See [`adj_quat_from_axis_angle`].
    fn adj_from_axis_angle(
        axis: Self::V3,
        angle: Self::S,
        adj_axis: &mut Self::V3,
        adj_angle: &mut Self::S,
        adj_ret: Self,
    );
    /// See [`adj_quat_rotate`].
    fn adj_rotate(q: Self, v: Self::V3, adj_q: &mut Self, adj_v: &mut Self::V3, adj_ret: Self::V3);
    /// See [`adj_quat_rotate_inv`].
    fn adj_rotate_inv(
        q: Self,
        v: Self::V3,
        adj_q: &mut Self,
        adj_v: &mut Self::V3,
        adj_ret: Self::V3,
    );
    /// See [`adj_quat_inverse`].
    fn adj_conjugate(q: Self, adj_q: &mut Self, adj_ret: Self);
    /// See [`adj_quat_to_matrix`].
    fn adj_to_matrix(q: Self, adj_q: &mut Self, adj_ret: Self::M3);
    /// See [`adj_quat_from_matrix`].
    fn adj_from_matrix(m: Self::M3, adj_m: &mut Self::M3, adj_ret: Self);
    /// See [`adj_quat_slerp`].
    #[allow(clippy::too_many_arguments)]
    fn adj_slerp(
        q0: Self,
        q1: Self,
        t: Self::S,
        adj_q0: &mut Self,
        adj_q1: &mut Self,
        adj_t: &mut Self::S,
        adj_ret: Self,
    );
}

/// Adjoint of `quat_from_axis_angle(axis, angle)` (see the module documentation).
#[inline(always)]
pub fn adj_quat_from_axis_angle<Q: AdjQuat>(
    axis: Q::V3,
    angle: Q::S,
    adj_axis: &mut Q::V3,
    adj_angle: &mut Q::S,
    adj_ret: Q,
) {
    Q::adj_from_axis_angle(axis, angle, adj_axis, adj_angle, adj_ret)
}

/// Adjoint of `quat_rotate(q, v) = q * v`.
#[inline(always)]
pub fn adj_quat_rotate<Q: AdjQuat>(
    q: Q,
    v: Q::V3,
    adj_q: &mut Q,
    adj_v: &mut Q::V3,
    adj_ret: Q::V3,
) {
    Q::adj_rotate(q, v, adj_q, adj_v, adj_ret)
}

/// Adjoint of `quat_rotate_inv(q, v) = conjugate(q) * v`.
#[inline(always)]
pub fn adj_quat_rotate_inv<Q: AdjQuat>(
    q: Q,
    v: Q::V3,
    adj_q: &mut Q,
    adj_v: &mut Q::V3,
    adj_ret: Q::V3,
) {
    Q::adj_rotate_inv(q, v, adj_q, adj_v, adj_ret)
}

/// Adjoint of `quat_inverse(q)`: `adj_q += (-g.x, -g.y, -g.z, g.w)`.
#[inline(always)]
pub fn adj_quat_inverse<Q: AdjQuat>(q: Q, adj_q: &mut Q, adj_ret: Q) {
    Q::adj_conjugate(q, adj_q, adj_ret)
}

/// Adjoint of `quat_to_matrix(q)`, glam's `from_quat`: with `G`'s columns `g0, g1, g2`,
/// `a = g0.y + g1.x`, `b = g0.z + g2.x`, `c = g1.z + g2.y` (the symmetric pairs),
/// `p = g1.z - g2.y`, `r = g2.x - g0.z`, `s = g0.y - g1.x` (the antisymmetric ones), and the
/// diagonal sums `dx = g1.y + g2.z`, `dy = g0.x + g2.z`, `dz = g0.x + g1.y`:
/// `adj_x += (((a*y + b*z) + p*w) - (dx*x + dx*x)) * 2`,
/// `adj_y += (((a*x + c*z) + r*w) - (dy*y + dy*y)) * 2`,
/// `adj_z += (((b*x + c*y) + s*w) - (dz*z + dz*z)) * 2`,
/// `adj_w += ((p*x + r*y) + s*z) * 2`.
#[inline(always)]
pub fn adj_quat_to_matrix<Q: AdjQuat>(q: Q, adj_q: &mut Q, adj_ret: Q::M3) {
    Q::adj_to_matrix(q, adj_q, adj_ret)
}

/// Adjoint of `quat_from_matrix(m)` (see the module documentation).
#[inline(always)]
pub fn adj_quat_from_matrix<Q: AdjQuat>(m: Q::M3, adj_m: &mut Q::M3, adj_ret: Q) {
    Q::adj_from_matrix(m, adj_m, adj_ret)
}

/// Adjoint of `quat_slerp(q0, q1, t)` (see the module documentation).
#[inline(always)]
pub fn adj_quat_slerp<Q: AdjQuat>(
    q0: Q,
    q1: Q,
    t: Q::S,
    adj_q0: &mut Q,
    adj_q1: &mut Q,
    adj_t: &mut Q::S,
    adj_ret: Q,
) {
    Q::adj_slerp(q0, q1, t, adj_q0, adj_q1, adj_t, adj_ret)
}

// ------------------------------------------------------------------------------------------
// Implementations
// ------------------------------------------------------------------------------------------

macro_rules! noop_length_sq {
    ($($v:ty),*) => {$(
        impl AdjLengthSq for $v {
            #[inline(always)]
            fn adj_length_sq(_v: $v, _adj_v: &mut $v, _adj_ret: <$v as VecOps>::Scalar) {}
        }
    )*};
}
noop_length_sq!(IVec2, IVec3, IVec4, UVec2, UVec3, UVec4);

macro_rules! float_length_sq {
    ($($v:ident),*) => {$(
        impl AdjLengthSq for $v {
            #[inline(always)]
            fn adj_length_sq(v: $v, adj_v: &mut $v, g: <$v as VecOps>::Scalar) {
                let x = v.to_array();
                let mut a = adj_v.to_array();
                for i in 0..x.len() {
                    a[i] += (x[i] + x[i]) * g;
                }
                *adj_v = $v::from_array(a);
            }
        }
    )*};
}
float_length_sq!(Vec2, Vec3, Vec4, DVec2, DVec3, DVec4, Quat, DQuat);

macro_rules! vec_mat {
    ($($v:ident: $m:ident, $n:literal);* $(;)?) => {$(
        impl AdjOuter for $v {
            type Mat = $m;
            #[inline(always)]
            fn adj_outer_of(a: $v, b: $v, adj_a: &mut $v, adj_b: &mut $v, g: $m) {
                <$v as AdjVecMat>::adj_outer(a, b, adj_a, adj_b, g)
            }
        }
        impl AdjTranspose for $m {
            type T = $m;
            #[inline(always)]
            fn adj_transposed(m: $m, adj_m: &mut $m, g: $m) {
                <$m as AdjMat>::adj_transpose(m, adj_m, g)
            }
        }
        impl AdjVecMat for $v {
            type Mat = $m;
            #[inline(always)]
            fn adj_outer(a: $v, b: $v, adj_a: &mut $v, adj_b: &mut $v, g: $m) {
                *adj_a += g * b;
                *adj_b += g.transpose() * a;
            }
            #[inline(always)]
            fn adj_diag(_v: $v, adj_v: &mut $v, g: $m) {
                *adj_v += $v::from_array(core::array::from_fn(|i| g.col(i)[i]));
            }
        }
        impl AdjCw for $v {
            #[inline(always)]
            fn adj_cw_mul(a: $v, b: $v, adj_a: &mut $v, adj_b: &mut $v, g: $v) {
                zip_vv(a, b, adj_a, adj_b, g, l_mul)
            }
            #[inline(always)]
            fn adj_cw_div(a: $v, b: $v, adj_a: &mut $v, adj_b: &mut $v, g: $v) {
                zip_vv(a, b, adj_a, adj_b, g, l_div)
            }
        }
        impl AdjCw for $m {
            #[inline(always)]
            fn adj_cw_mul(a: $m, b: $m, adj_a: &mut $m, adj_b: &mut $m, g: $m) {
                zip_vv(a, b, adj_a, adj_b, g, l_mul)
            }
            #[inline(always)]
            fn adj_cw_div(a: $m, b: $m, adj_a: &mut $m, adj_b: &mut $m, g: $m) {
                zip_vv(a, b, adj_a, adj_b, g, l_div)
            }
        }
        impl AdjMat for $m {
            #[inline(always)]
            fn adj_transpose(_m: $m, adj_m: &mut $m, g: $m) {
                *adj_m += g.transpose();
            }
            #[inline(always)]
            fn adj_determinant(m: $m, adj_m: &mut $m, g: <$m as SquareMat>::S) {
                cofactor_accum(m, adj_m, g);
            }
            #[inline(always)]
            fn adj_trace(_m: $m, adj_m: &mut $m, g: <$m as SquareMat>::S) {
                for i in 0..$n {
                    adj_m.col_mut(i)[i] += g;
                }
            }
            #[inline(always)]
            fn adj_ddot(a: $m, b: $m, adj_a: &mut $m, adj_b: &mut $m, g: <$m as SquareMat>::S) {
                let (a, b) = (a.to_cols_array(), b.to_cols_array());
                let (mut aa, mut ab) = (adj_a.to_cols_array(), adj_b.to_cols_array());
                for k in 0..a.len() {
                    aa[k] += g * b[k];
                    ab[k] += g * a[k];
                }
                *adj_a = $m::from_cols_array(&aa);
                *adj_b = $m::from_cols_array(&ab);
            }
        }
        impl AdjInverse for $m {
            #[inline(always)]
            fn adj_inverse(m: $m, adj_m: &mut $m, g: $m) {
                let t = m.w_inverse().transpose();
                *adj_m -= (t * g) * t;
            }
        }
    )*};
}
vec_mat!(
    Vec2: Mat2, 2; Vec3: Mat3, 3; Vec4: Mat4, 4;
    DVec2: DMat2, 2; DVec3: DMat3, 3; DVec4: DMat4, 4;
);

/// `adj_m += g * cofactor(m)`, per size.
trait Cofactor: Copy {
    type S;
    fn cofactor_accum(m: Self, adj_m: &mut Self, g: Self::S);
}
#[inline(always)]
fn cofactor_accum<M: Cofactor>(m: M, adj_m: &mut M, g: M::S) {
    M::cofactor_accum(m, adj_m, g)
}
macro_rules! cofactor2 {
    ($($m:ident: $s:ident),*) => {$(
        impl Cofactor for $m {
            type S = $s;
            #[inline(always)]
            fn cofactor_accum(m: $m, a: &mut $m, g: $s) {
                a.x_axis.x += g * m.y_axis.y;
                a.x_axis.y -= g * m.y_axis.x;
                a.y_axis.x -= g * m.x_axis.y;
                a.y_axis.y += g * m.x_axis.x;
            }
        }
    )*};
}
cofactor2!(Mat2: f32, DMat2: f64);
macro_rules! cofactor3 {
    ($($m:ident: $s:ident),*) => {$(
        impl Cofactor for $m {
            type S = $s;
            #[inline(always)]
            fn cofactor_accum(m: $m, a: &mut $m, g: $s) {
                a.x_axis += m.y_axis.cross(m.z_axis) * g;
                a.y_axis += m.z_axis.cross(m.x_axis) * g;
                a.z_axis += m.x_axis.cross(m.y_axis) * g;
            }
        }
    )*};
}
cofactor3!(Mat3: f32, DMat3: f64);
macro_rules! cofactor4 {
    ($($m:ident: $m3:ident, $v3:ident, $s:ident),*) => {$(
        impl Cofactor for $m {
            type S = $s;
            #[inline(always)]
            fn cofactor_accum(m: $m, a: &mut $m, g: $s) {
                for c in 0..4 {
                    for r in 0..4 {
                        let cols: [$v3; 3] = core::array::from_fn(|k| {
                            let cc = if k < c { k } else { k + 1 };
                            let col = m.col(cc);
                            let rows: [$s; 3] = core::array::from_fn(|j| {
                                col[if j < r { j } else { j + 1 }]
                            });
                            $v3::from_array(rows)
                        });
                        let d = $m3::from_cols(cols[0], cols[1], cols[2]).determinant();
                        let cof = if (r + c) % 2 == 1 { -d } else { d };
                        a.col_mut(c)[r] += g * cof;
                    }
                }
            }
        }
    )*};
}
cofactor4!(Mat4: Mat3, Vec3, f32, DMat4: DMat3, DVec3, f64);

macro_rules! skew {
    ($($v:ident: $m:ident),*) => {$(
        impl AdjSkew for $v {
            type Mat = $m;
            #[inline(always)]
            fn adj_skew(_v: $v, adj_v: &mut $v, g: $m) {
                adj_v.x += g.y_axis.z - g.z_axis.y;
                adj_v.y += g.z_axis.x - g.x_axis.z;
                adj_v.z += g.x_axis.y - g.y_axis.x;
            }
        }
    )*};
}
skew!(Vec3: Mat3, DVec3: DMat3);

macro_rules! quat_adj {
    ($($q:ident: $v3:ident, $m3:ident, $s:ident);*) => {$(
        impl AdjDot for $q {
            #[inline(always)]
            fn adj_dot(a: $q, b: $q, adj_a: &mut $q, adj_b: &mut $q, g: $s) {
                let (a, b) = (a.to_array(), b.to_array());
                let (mut aa, mut ab) = (adj_a.to_array(), adj_b.to_array());
                for i in 0..4 {
                    aa[i] += g * b[i];
                    ab[i] += g * a[i];
                }
                *adj_a = $q::from_array(aa);
                *adj_b = $q::from_array(ab);
            }
        }
        impl AdjFloatVec for $q {
            // The vector rules, rescaled likewise (`builtins::norm`).
            #[inline(always)]
            fn adj_length(v: $q, adj_v: &mut $q, g: $s) {
                crate::builtins::norm::adj_length(v, adj_v, g)
            }
            #[inline(always)]
            fn adj_normalize(v: $q, adj_v: &mut $q, g: $q) {
                crate::builtins::norm::adj_normalize(v, adj_v, g)
            }
        }
        impl AdjInverse for $q {
            #[inline(always)]
            fn adj_inverse(q: $q, adj_q: &mut $q, g: $q) {
                <$q as AdjQuat>::adj_conjugate(q, adj_q, g)
            }
        }
        impl AdjQuat for $q {
            #[inline(always)]
            fn adj_from_axis_angle(axis: $v3, angle: $s, adj_axis: &mut $v3, adj_angle: &mut $s, g: $q) {
                let h = angle * 0.5;
                let (s, c) = (h.w_sin(), h.w_cos());
                *adj_axis += $v3::new(g.x, g.y, g.z) * s;
                let d = (g.x * axis.x + g.y * axis.y) + g.z * axis.z;
                *adj_angle += (d * c - g.w * s) * 0.5;
            }
            #[inline(always)]
            fn adj_rotate(q: $q, v: $v3, adj_q: &mut $q, adj_v: &mut $v3, g: $v3) {
                <$q as AdjMul<$v3>>::adj_mul(q, v, adj_q, adj_v, g)
            }
            #[inline(always)]
            fn adj_rotate_inv(q: $q, v: $v3, adj_q: &mut $q, adj_v: &mut $v3, g: $v3) {
                let mut ac = <$q as Adjoint>::adj_zero();
                <$q as AdjMul<$v3>>::adj_mul(q.conjugate(), v, &mut ac, adj_v, g);
                <$q as AdjQuat>::adj_conjugate(q, adj_q, ac);
            }
            #[inline(always)]
            fn adj_conjugate(_q: $q, adj_q: &mut $q, g: $q) {
                adj_q.x -= g.x;
                adj_q.y -= g.y;
                adj_q.z -= g.z;
                adj_q.w += g.w;
            }
            #[inline(always)]
            fn adj_to_matrix(q: $q, adj_q: &mut $q, gm: $m3) {
                let (g0, g1, g2) = (gm.x_axis, gm.y_axis, gm.z_axis);
                let (x, y, z, w) = (q.x, q.y, q.z, q.w);
                let a = g0.y + g1.x;
                let b = g0.z + g2.x;
                let c = g1.z + g2.y;
                let p = g1.z - g2.y;
                let r = g2.x - g0.z;
                let s = g0.y - g1.x;
                let dx = g1.y + g2.z;
                let dy = g0.x + g2.z;
                let dz = g0.x + g1.y;
                adj_q.x += (((a * y + b * z) + p * w) - (dx * x + dx * x)) * 2.0;
                adj_q.y += (((a * x + c * z) + r * w) - (dy * y + dy * y)) * 2.0;
                adj_q.z += (((b * x + c * y) + s * w) - (dz * z + dz * z)) * 2.0;
                adj_q.w += ((p * x + r * y) + s * z) * 2.0;
            }
            #[inline(always)]
            fn adj_from_matrix(m: $m3, adj_m: &mut $m3, g: $q) {
                // Lanes of m: [m00, m01, m02, m10, m11, m12, m20, m21, m22] (column-major).
                let l = m.to_cols_array();
                let (m00, m11, m22) = (l[0], l[4], l[8]);
                let gq = [g.x, g.y, g.z, g.w];
                // (main lane k, sign of m00, m11, m22 in f, the other lanes as
                // (q lane, lane of m, lane of m, sign of the second)).
                let (k, sd, others): (usize, [$s; 3], [(usize, usize, usize, $s); 3]) =
                    if m22 <= 0.0 {
                        if m11 - m00 <= 0.0 {
                            (0, [1.0, -1.0, -1.0], [(1, 1, 3, 1.0), (2, 2, 6, 1.0), (3, 5, 7, -1.0)])
                        } else {
                            (1, [-1.0, 1.0, -1.0], [(0, 1, 3, 1.0), (2, 5, 7, 1.0), (3, 6, 2, -1.0)])
                        }
                    } else if m11 + m00 <= 0.0 {
                        (2, [-1.0, -1.0, 1.0], [(0, 2, 6, 1.0), (1, 5, 7, 1.0), (3, 1, 3, -1.0)])
                    } else {
                        (3, [1.0, 1.0, 1.0], [(0, 5, 7, -1.0), (1, 6, 2, -1.0), (2, 1, 3, -1.0)])
                    };
                // The forward's f, in its own order.
                let f = match k {
                    0 => (1.0 - m22) - (m11 - m00),
                    1 => (1.0 - m22) + (m11 - m00),
                    2 => (1.0 + m22) - (m11 + m00),
                    _ => (1.0 + m22) + (m11 + m00),
                };
                let inv = 0.5 / f.w_sqrt();
                let mut sum: $s = 0.0;
                let mut a = adj_m.to_cols_array();
                for &(j, p, q, sq) in &others {
                    let lin = if sq > 0.0 { l[p] + l[q] } else { l[p] - l[q] };
                    sum += gq[j] * lin;
                    let al = gq[j] * inv;
                    a[p] += al;
                    if sq > 0.0 { a[q] += al } else { a[q] -= al }
                }
                let af = gq[k] * (inv * 0.5) + sum * -(inv / (f + f));
                for (i, lane) in [0usize, 4, 8].into_iter().enumerate() {
                    if sd[i] > 0.0 { a[lane] += af } else { a[lane] -= af }
                }
                *adj_m = $m3::from_cols_array(&a);
            }
            #[inline(always)]
            fn adj_slerp(q0: $q, q1: $q, t: $s, adj_q0: &mut $q, adj_q1: &mut $q, adj_t: &mut $s, g: $q) {
                // Forward replay.
                let c = q0.conjugate();
                let d = c * q1;
                let v = $v3::new(d.x, d.y, d.z);
                let n = v.w_normalize();
                let neg = d.w < 0.0;
                let axis = if neg { -n } else { n };
                let len = v.w_length();
                let aw = d.w.w_abs();
                let angle = 2.0 * len.w_atan2(aw);
                let ta = t * angle;
                let r = $q::from_axis_angle(axis, ta);
                // Reverse.
                let zq = <$q as Adjoint>::adj_zero();
                let zv = <$v3 as Adjoint>::adj_zero();
                let mut adj_r = zq;
                <$q as super::ops::AdjMul>::adj_mul(q0, r, adj_q0, &mut adj_r, g);
                let (mut adj_axis, mut adj_ta) = (zv, 0.0);
                <$q as AdjQuat>::adj_from_axis_angle(axis, ta, &mut adj_axis, &mut adj_ta, adj_r);
                *adj_t += adj_ta * angle;
                let adj_at = (adj_ta * t) * 2.0;
                let (mut adj_len, mut adj_aw) = (0.0, 0.0);
                adj_atan2(len, aw, &mut adj_len, &mut adj_aw, adj_at);
                let mut adj_dw = 0.0;
                adj_abs(d.w, &mut adj_dw, adj_aw);
                let mut adj_v = zv;
                adj_length(v, &mut adj_v, adj_len);
                let adj_n = if neg { -adj_axis } else { adj_axis };
                adj_normalize(v, &mut adj_v, adj_n);
                let adj_d = $q::from_xyzw(adj_v.x, adj_v.y, adj_v.z, adj_dw);
                let mut adj_c = zq;
                <$q as super::ops::AdjMul>::adj_mul(c, q1, &mut adj_c, adj_q1, adj_d);
                <$q as AdjQuat>::adj_conjugate(q0, adj_q0, adj_c);
            }
        }
    )*};
}
quat_adj!(Quat: Vec3, Mat3, f32; DQuat: DVec3, DMat3, f64);

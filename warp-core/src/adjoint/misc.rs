//! Adjoints of the builtins of [`crate::builtins::misc`].
//!
//! Same convention as every adjoint here: `adj_<name>(args.., adj_args.., adj_ret)`
//! accumulates; tuple results take the tuple of their adjoints. Each one replays its forward
//! and runs the reverse of its steps through the adjoints of the operations it is made of
//! (`adj_abs`, `adj_sqrt`, `adj_atan2`, `adj_length`, `adj_normalize`, ...), in the order
//! written below, which `wp_adjoint.h` follows (so the backends agree bit for bit). `g` is
//! `adj_ret`:
//!
//! * `copysign(x, y)`: `adj_x += g` where `x` and `y` have the same sign bit, else `-= g`;
//!   nothing to `y` (Warp's: the result depends on `y` only through its sign);
//! * `min_element(v)`, `max_element(v)`: the whole of `g` to the lane `argmin(v)`
//!   (`argmax(v)`) names (Warp's); nothing for integer vectors;
//! * `get_diag(m)`: `adj_m[i][i] += g[i]`;
//! * `norm_l1(v)`: `adj_abs` per lane; `norm_l2`: `adj_length`;
//! * `norm_huber(v, d)`: below the threshold `adj_length_sq(v, 0.5 * g)`, else
//!   `adj_d += g * (sqrt(a) - 0.5 * d)`, `t = d * g`, `adj_d -= t * 0.5`, then `adj_sqrt` and
//!   `adj_length_sq` with `t`;
//! * `norm_pseudo_huber(v, d)`: `adj_d += g * s` (`s = sqrt(1 + q)`, `q = a / (d * d)`), then
//!   `adj_sqrt(1 + q, d * g)`, the division rule (`gb = adj_u / dd`, `adj_dd -= gb * q`),
//!   `adj_d += adj_dd * d` twice, `adj_length_sq(v, gb)`;
//! * `smooth_normalize(v, d)`: with `n` the pseudo-Huber norm, per lane `gi = g[i] / n`,
//!   `adj_v[i] += gi`, `adj_n -= gi * (v[i] / n)`, then `norm_pseudo_huber`'s adjoint with
//!   `adj_n`;
//! * `quat_to_axis_angle(q)`: `adj_atan2` with `g.1 * 2`, `adj_abs(w)`, `adj_length`, and
//!   `adj_normalize` with `±g.0`;
//! * `quat_rpy(roll, pitch, yaw)`: the derivatives of the four products with respect to each
//!   half-angle cosine and sine, then `adj_h += (g_s * c - g_c * s) * 0.5`;
//! * `quat_to_rpy(q)`: `adj_atan2`, `adj_asin`, `adj_clamp`, then the polynomials' terms;
//! * `quat_twist(axis, q)`: the quaternion `adj_normalize`, then `b = p * axis` and
//!   `p = dot(xyz, axis)`; `quat_twist_angle(_signed)`: `adj_atan2` with `g * 2`, `adj_abs`
//!   (unsigned only), `adj_dot`;
//! * `transform_compose(p, q, s)`: `adj_s[j] += dot(G[j].xyz, R[j])`, `adj_p += G[3].xyz`,
//!   `adj_quat_to_matrix(q, G[j].xyz * s[j])`;
//! * `transform_decompose(m)`: `adj_quat_from_matrix` of the normalized columns, the division
//!   rule per lane where a column's length is not zero (else the adjoint passes through),
//!   `adj_length` with that plus the scale's adjoint, into the upper-left block; the position's
//!   adjoint into the translation column.

use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};

use super::builtins::{AdjDot, AdjFloatVec};
use super::linalg::{AdjLengthSq, AdjQuat};
use super::{adj_abs, adj_asin, adj_atan2, adj_clamp, adj_sqrt, AdjFloat, Adjoint};
use crate::builtins::linalg::QuatOps;
use crate::builtins::math::{Float, FloatVec, MinMax, Scalar, Signed, VecOps};
use crate::builtins::misc::{CopySign, Decompose, GetDiag, Norms, QuatMisc, VecReduce};

// ------------------------------------------------------------------------------------------
// Traits and public adjoints
// ------------------------------------------------------------------------------------------

/// Adjoint of `copysign`: `f32`, `f64`.
pub trait AdjCopySign: CopySign + AdjFloat {}
impl AdjCopySign for f32 {}
impl AdjCopySign for f64 {}

/// Adjoint of `copysign(x, y)`: `adj_x += g` when the sign bits agree, else `adj_x -= g`.
#[inline(always)]
pub fn adj_copysign<F: AdjCopySign>(x: F, y: F, adj_x: &mut F, _adj_y: &mut F, adj_ret: F) {
    if F::ONE.w_copysign(x) == F::ONE.w_copysign(y) {
        *adj_x += adj_ret;
    } else {
        *adj_x -= adj_ret;
    }
}

/// Adjoints of the one-vector reductions: float vectors (integer vectors: no-ops).
pub trait AdjReduce: VecReduce + Adjoint {
    /// Adds `g` to lane `i`.
    fn adj_lane(adj_v: &mut Self, i: u32, g: Self::S);
}

/// Adjoint of `min_element(v)`: `adj_v[argmin(v)] += g`.
#[inline(always)]
pub fn adj_min_element<V: AdjReduce>(v: V, adj_v: &mut V, adj_ret: V::S) {
    V::adj_lane(adj_v, v.w_argmin(), adj_ret)
}

/// Adjoint of `max_element(v)`: `adj_v[argmax(v)] += g`.
#[inline(always)]
pub fn adj_max_element<V: AdjReduce>(v: V, adj_v: &mut V, adj_ret: V::S) {
    V::adj_lane(adj_v, v.w_argmax(), adj_ret)
}

/// Adjoint of `get_diag`: square float matrices.
pub trait AdjGetDiag: GetDiag + Adjoint {
    /// See [`adj_get_diag`].
    fn adj_get_diag(m: Self, adj_m: &mut Self, adj_ret: Self::V);
}

/// Adjoint of `get_diag(m)`: `adj_m[i][i] += g[i]`.
#[inline(always)]
pub fn adj_get_diag<M: AdjGetDiag>(m: M, adj_m: &mut M, adj_ret: M::V) {
    M::adj_get_diag(m, adj_m, adj_ret)
}

/// Adjoints of the norms: float vectors.
pub trait AdjNorms: Norms<Scalar: AdjFloat> + AdjFloatVec + AdjLengthSq {
    /// See [`adj_norm_l1`].
    fn adj_norm_l1(v: Self, adj_v: &mut Self, adj_ret: Self::Scalar);
    /// See [`adj_smooth_normalize`].
    fn adj_smooth_normalize(
        v: Self,
        delta: Self::Scalar,
        adj_v: &mut Self,
        adj_delta: &mut Self::Scalar,
        adj_ret: Self,
    );
}

/// Adjoint of `norm_l1(v)`: `adj_abs` per lane.
#[inline(always)]
pub fn adj_norm_l1<V: AdjNorms>(v: V, adj_v: &mut V, adj_ret: V::Scalar) {
    V::adj_norm_l1(v, adj_v, adj_ret)
}

/// Adjoint of `norm_l2(v)`: `adj_length`.
#[inline(always)]
pub fn adj_norm_l2<V: AdjNorms>(v: V, adj_v: &mut V, adj_ret: V::Scalar) {
    V::adj_length(v, adj_v, adj_ret)
}

/// Adjoint of `norm_huber(v, delta)` (see the module documentation).
#[inline(always)]
pub fn adj_norm_huber<V: AdjNorms>(
    v: V,
    delta: V::Scalar,
    adj_v: &mut V,
    adj_delta: &mut V::Scalar,
    adj_ret: V::Scalar,
) {
    let one = <V::Scalar as Scalar>::ONE;
    let half = one / (one + one);
    let a = v.w_dot(v);
    if a <= delta * delta {
        V::adj_length_sq(v, adj_v, half * adj_ret);
    } else {
        let s = a.w_sqrt();
        *adj_delta += adj_ret * (s - half * delta);
        let t = delta * adj_ret;
        *adj_delta -= t * half;
        let mut adj_a = V::Scalar::adj_zero();
        adj_sqrt(a, &mut adj_a, t);
        V::adj_length_sq(v, adj_v, adj_a);
    }
}

/// Adjoint of `norm_pseudo_huber(v, delta)` (see the module documentation).
#[inline(always)]
pub fn adj_norm_pseudo_huber<V: AdjNorms>(
    v: V,
    delta: V::Scalar,
    adj_v: &mut V,
    adj_delta: &mut V::Scalar,
    adj_ret: V::Scalar,
) {
    let a = v.w_dot(v);
    let dd = delta * delta;
    let q = a / dd;
    let u = <V::Scalar as Scalar>::ONE + q;
    *adj_delta += adj_ret * u.w_sqrt();
    let mut adj_u = V::Scalar::adj_zero();
    adj_sqrt(u, &mut adj_u, delta * adj_ret);
    let gb = adj_u / dd;
    let mut adj_dd = V::Scalar::adj_zero();
    adj_dd -= gb * q;
    *adj_delta += adj_dd * delta;
    *adj_delta += adj_dd * delta;
    V::adj_length_sq(v, adj_v, gb);
}

/// Adjoint of `smooth_normalize(v, delta)` (see the module documentation).
#[inline(always)]
pub fn adj_smooth_normalize<V: AdjNorms>(
    v: V,
    delta: V::Scalar,
    adj_v: &mut V,
    adj_delta: &mut V::Scalar,
    adj_ret: V,
) {
    V::adj_smooth_normalize(v, delta, adj_v, adj_delta, adj_ret)
}

/// Adjoints of the quaternion builtins of this section: `Quat`, `DQuat`.
pub trait AdjQuatMisc:
    QuatMisc<S: AdjFloat, V3: AdjDot<Scalar = Self::S> + AdjFloatVec> + AdjQuat
{
    /// See [`adj_quat_to_axis_angle`].
    fn adj_to_axis_angle(q: Self, adj_q: &mut Self, adj_ret: (Self::V3, Self::S));
    /// See [`adj_quat_rpy`].
    #[allow(clippy::too_many_arguments)]
    fn adj_rpy(
        roll: Self::S,
        pitch: Self::S,
        yaw: Self::S,
        adj_roll: &mut Self::S,
        adj_pitch: &mut Self::S,
        adj_yaw: &mut Self::S,
        adj_ret: Self,
    );
    /// See [`adj_quat_to_rpy`].
    fn adj_to_rpy(q: Self, adj_q: &mut Self, adj_ret: Self::V3);
    /// See [`adj_quat_twist`].
    fn adj_twist(axis: Self::V3, q: Self, adj_axis: &mut Self::V3, adj_q: &mut Self, g: Self);
    /// See [`adj_quat_twist_angle`].
    fn adj_twist_angle(
        axis: Self::V3,
        q: Self,
        adj_axis: &mut Self::V3,
        adj_q: &mut Self,
        g: Self::S,
        signed: bool,
    );
}

/// Adjoint of `quat_to_axis_angle(q)`; `adj_ret` is `(adj_axis, adj_angle)`.
#[inline(always)]
pub fn adj_quat_to_axis_angle<Q: AdjQuatMisc>(q: Q, adj_q: &mut Q, adj_ret: (Q::V3, Q::S)) {
    Q::adj_to_axis_angle(q, adj_q, adj_ret)
}

/// Adjoint of `quat_rpy(roll, pitch, yaw)`.
#[inline(always)]
pub fn adj_quat_rpy<Q: AdjQuatMisc>(
    roll: Q::S,
    pitch: Q::S,
    yaw: Q::S,
    adj_roll: &mut Q::S,
    adj_pitch: &mut Q::S,
    adj_yaw: &mut Q::S,
    adj_ret: Q,
) {
    Q::adj_rpy(roll, pitch, yaw, adj_roll, adj_pitch, adj_yaw, adj_ret)
}

/// Adjoint of `quat_to_rpy(q)`.
#[inline(always)]
pub fn adj_quat_to_rpy<Q: AdjQuatMisc>(q: Q, adj_q: &mut Q, adj_ret: Q::V3) {
    Q::adj_to_rpy(q, adj_q, adj_ret)
}

/// Adjoint of `quat_twist(axis, q)`.
#[inline(always)]
pub fn adj_quat_twist<Q: AdjQuatMisc>(
    axis: Q::V3,
    q: Q,
    adj_axis: &mut Q::V3,
    adj_q: &mut Q,
    adj_ret: Q,
) {
    Q::adj_twist(axis, q, adj_axis, adj_q, adj_ret)
}

/// Adjoint of `quat_twist_angle(axis, q)`.
#[inline(always)]
pub fn adj_quat_twist_angle<Q: AdjQuatMisc>(
    axis: Q::V3,
    q: Q,
    adj_axis: &mut Q::V3,
    adj_q: &mut Q,
    adj_ret: Q::S,
) {
    Q::adj_twist_angle(axis, q, adj_axis, adj_q, adj_ret, false)
}

/// Adjoint of `quat_twist_angle_signed(axis, q)`.
#[inline(always)]
pub fn adj_quat_twist_angle_signed<Q: AdjQuatMisc>(
    axis: Q::V3,
    q: Q,
    adj_axis: &mut Q::V3,
    adj_q: &mut Q,
    adj_ret: Q::S,
) {
    Q::adj_twist_angle(axis, q, adj_axis, adj_q, adj_ret, true)
}

/// Adjoints of `transform_compose` (by the 3-vector) and `transform_decompose` (by the 4x4
/// matrix).
pub trait AdjCompose: Adjoint + Sized {
    /// The quaternion.
    type Q;
    /// The 4x4 matrix.
    type M4;
    /// See [`adj_transform_compose`].
    #[allow(clippy::too_many_arguments)]
    fn adj_compose(
        p: Self,
        q: Self::Q,
        s: Self,
        adj_p: &mut Self,
        adj_q: &mut Self::Q,
        adj_s: &mut Self,
        adj_ret: Self::M4,
    );
}

/// Adjoint of `transform_compose(p, q, s)`.
#[inline(always)]
pub fn adj_transform_compose<V: AdjCompose>(
    p: V,
    q: V::Q,
    s: V,
    adj_p: &mut V,
    adj_q: &mut V::Q,
    adj_s: &mut V,
    adj_ret: V::M4,
) {
    V::adj_compose(p, q, s, adj_p, adj_q, adj_s, adj_ret)
}

/// Adjoint of `transform_decompose`: `Mat4`, `DMat4`.
pub trait AdjDecompose: Decompose + Adjoint {
    /// See [`adj_transform_decompose`].
    fn adj_decompose(m: Self, adj_m: &mut Self, adj_ret: (Self::V, Self::Q, Self::V));
}

/// Adjoint of `transform_decompose(m)`; `adj_ret` is `(adj_p, adj_q, adj_s)`.
#[inline(always)]
pub fn adj_transform_decompose<M: AdjDecompose>(m: M, adj_m: &mut M, adj_ret: (M::V, M::Q, M::V)) {
    M::adj_decompose(m, adj_m, adj_ret)
}

// ------------------------------------------------------------------------------------------
// Implementations
// ------------------------------------------------------------------------------------------

macro_rules! reduce_float {
    ($($v:ident: $s:ident),*) => {$(
        impl AdjReduce for $v {
            #[inline(always)]
            fn adj_lane(adj_v: &mut Self, i: u32, g: $s) {
                let mut a = adj_v.to_array();
                a[i as usize] += g;
                *adj_v = $v::from_array(a);
            }
        }
        impl AdjNorms for $v {
            #[inline(always)]
            fn adj_norm_l1(v: Self, adj_v: &mut Self, g: $s) {
                let x = v.to_array();
                let mut a = adj_v.to_array();
                for (a, x) in a.iter_mut().zip(x) {
                    adj_abs(x, a, g);
                }
                *adj_v = $v::from_array(a);
            }
            #[inline(always)]
            fn adj_smooth_normalize(v: Self, delta: $s, adj_v: &mut Self, adj_delta: &mut $s, g: Self) {
                let n = v.w_norm_pseudo_huber(delta);
                let (x, g) = (v.to_array(), g.to_array());
                let mut a = adj_v.to_array();
                let mut adj_n: $s = 0.0;
                for i in 0..a.len() {
                    let gi = g[i] / n;
                    a[i] += gi;
                    adj_n -= gi * (x[i] / n);
                }
                *adj_v = $v::from_array(a);
                adj_norm_pseudo_huber(v, delta, adj_v, adj_delta, adj_n);
            }
        }
    )*};
}
reduce_float!(Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64);

macro_rules! reduce_int {
    ($($v:ident: $s:ident),*) => {$(
        impl AdjReduce for $v {
            #[inline(always)]
            fn adj_lane(_adj_v: &mut Self, _i: u32, _g: $s) {}
        }
    )*};
}
reduce_int!(IVec2: i32, IVec3: i32, IVec4: i32, UVec2: u32, UVec3: u32, UVec4: u32);

macro_rules! diag_adj {
    ($($m:ident: $v:ident),*) => {$(
        impl AdjGetDiag for $m {
            #[inline(always)]
            fn adj_get_diag(_m: Self, adj_m: &mut Self, g: $v) {
                let n = g.to_array().len();
                let mut a = adj_m.to_cols_array();
                for (i, gi) in g.to_array().into_iter().enumerate() {
                    a[i * n + i] += gi;
                }
                *adj_m = $m::from_cols_array(&a);
            }
        }
    )*};
}
diag_adj!(Mat2: Vec2, Mat3: Vec3, Mat4: Vec4, DMat2: DVec2, DMat3: DVec3, DMat4: DVec4);

macro_rules! quat_adj {
    ($($q:ident: $v3:ident, $m3:ident, $m4:ident, $s:ident);*) => {$(
        impl AdjQuatMisc for $q {
            #[inline(always)]
            fn adj_to_axis_angle(q: Self, adj_q: &mut Self, g: ($v3, $s)) {
                let v = $v3::new(q.x, q.y, q.z);
                let neg = q.w < 0.0;
                let len = v.w_length();
                let aw = q.w.w_abs();
                let (mut adj_len, mut adj_aw) = (0.0, 0.0);
                adj_atan2(len, aw, &mut adj_len, &mut adj_aw, g.1 * 2.0);
                let mut adj_w = 0.0;
                adj_abs(q.w, &mut adj_w, adj_aw);
                let mut adj_v = $v3::ZERO;
                <$v3 as AdjFloatVec>::adj_length(v, &mut adj_v, adj_len);
                let adj_n = if neg { -g.0 } else { g.0 };
                <$v3 as AdjFloatVec>::adj_normalize(v, &mut adj_v, adj_n);
                *adj_q = quat_add(*adj_q, adj_v.x, adj_v.y, adj_v.z, adj_w);
            }
            #[inline(always)]
            fn adj_rpy(roll: $s, pitch: $s, yaw: $s, adj_roll: &mut $s, adj_pitch: &mut $s, adj_yaw: &mut $s, g: Self) {
                let (hy, hr, hp) = (yaw * 0.5, roll * 0.5, pitch * 0.5);
                let (cy, sy) = (hy.w_cos(), hy.w_sin());
                let (cr, sr) = (hr.w_cos(), hr.w_sin());
                let (cp, sp) = (hp.w_cos(), hp.w_sin());
                let gcy = ((g.w * (cr * cp) + g.x * (sr * cp)) + g.y * (cr * sp)) - g.z * (sr * sp);
                let gsy = ((g.w * (sr * sp) - g.x * (cr * sp)) + g.y * (sr * cp)) + g.z * (cr * cp);
                let gcr = ((g.w * (cy * cp) - g.x * (sy * sp)) + g.y * (cy * sp)) + g.z * (sy * cp);
                let gsr = ((g.w * (sy * sp) + g.x * (cy * cp)) + g.y * (sy * cp)) - g.z * (cy * sp);
                let gcp = ((g.w * (cy * cr) + g.x * (cy * sr)) + g.y * (sy * sr)) + g.z * (sy * cr);
                let gsp = ((g.w * (sy * sr) - g.x * (sy * cr)) + g.y * (cy * cr)) - g.z * (cy * sr);
                *adj_yaw += (gsy * cy - gcy * sy) * 0.5;
                *adj_roll += (gsr * cr - gcr * sr) * 0.5;
                *adj_pitch += (gsp * cp - gcp * sp) * 0.5;
            }
            #[inline(always)]
            fn adj_to_rpy(q: Self, adj_q: &mut Self, g: $v3) {
                let (x, y, z, w) = (q.x, q.y, q.z, q.w);
                let t0 = 2.0 * (w * x + y * z);
                let t1 = 1.0 - 2.0 * (x * x + y * y);
                let u = 2.0 * (w * y - z * x);
                let t2 = u.w_max(-1.0).w_min(1.0);
                let t3 = 2.0 * (w * z + x * y);
                let t4 = 1.0 - 2.0 * (y * y + z * z);
                let (mut a0, mut a1, mut a3, mut a4, mut at2, mut au) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
                adj_atan2(t0, t1, &mut a0, &mut a1, g.x);
                adj_asin(t2, &mut at2, g.y);
                let (mut alo, mut ahi) = (0.0, 0.0);
                adj_clamp(u, -1.0, 1.0, &mut au, &mut alo, &mut ahi, at2);
                adj_atan2(t3, t4, &mut a3, &mut a4, g.z);
                let (mut gx, mut gy, mut gz, mut gw): ($s, $s, $s, $s) = (0.0, 0.0, 0.0, 0.0);
                let b0 = a0 * 2.0;
                gw += b0 * x;
                gx += b0 * w;
                gy += b0 * z;
                gz += b0 * y;
                let b1 = a1 * 2.0;
                gx -= b1 * (x + x);
                gy -= b1 * (y + y);
                let bu = au * 2.0;
                gw += bu * y;
                gy += bu * w;
                gz -= bu * x;
                gx -= bu * z;
                let b3 = a3 * 2.0;
                gw += b3 * z;
                gz += b3 * w;
                gx += b3 * y;
                gy += b3 * x;
                let b4 = a4 * 2.0;
                gy -= b4 * (y + y);
                gz -= b4 * (z + z);
                *adj_q = quat_add(*adj_q, gx, gy, gz, gw);
            }
            #[inline(always)]
            fn adj_twist(axis: $v3, q: Self, adj_axis: &mut $v3, adj_q: &mut Self, g: Self) {
                let a = $v3::new(q.x, q.y, q.z);
                let p = a.w_dot(axis);
                let t = $q::from_xyzw(p * axis.x, p * axis.y, p * axis.z, q.w);
                let mut adj_t = $q::from_xyzw(0.0, 0.0, 0.0, 0.0);
                <$q as AdjFloatVec>::adj_normalize(t, &mut adj_t, g);
                let adj_b = $v3::new(adj_t.x, adj_t.y, adj_t.z);
                let adj_p = adj_b.w_dot(axis);
                *adj_axis += $v3::new(adj_b.x * p, adj_b.y * p, adj_b.z * p);
                let mut adj_a = $v3::ZERO;
                <$v3 as AdjDot>::adj_dot(a, axis, &mut adj_a, adj_axis, adj_p);
                *adj_q = quat_add(*adj_q, adj_a.x, adj_a.y, adj_a.z, adj_t.w);
            }
            #[inline(always)]
            fn adj_twist_angle(axis: $v3, q: Self, adj_axis: &mut $v3, adj_q: &mut Self, g: $s, signed: bool) {
                let v = $v3::new(q.x, q.y, q.z);
                let d = axis.w_dot(v);
                let s = if signed { d } else { d.w_abs() };
                let (mut adj_s, mut adj_w) = (0.0, 0.0);
                adj_atan2(s, q.w, &mut adj_s, &mut adj_w, g * 2.0);
                let mut adj_d = 0.0;
                if signed {
                    adj_d += adj_s;
                } else {
                    adj_abs(d, &mut adj_d, adj_s);
                }
                let mut adj_v = $v3::ZERO;
                <$v3 as AdjDot>::adj_dot(axis, v, adj_axis, &mut adj_v, adj_d);
                *adj_q = quat_add(*adj_q, adj_v.x, adj_v.y, adj_v.z, adj_w);
            }
        }
        impl AdjCompose for $v3 {
            type Q = $q;
            type M4 = $m4;
            #[inline(always)]
            fn adj_compose(_p: Self, q: $q, s: Self, adj_p: &mut Self, adj_q: &mut $q, adj_s: &mut Self, g: $m4) {
                let r = q.w_to_matrix();
                let (g0, g1, g2) = (g.x_axis.truncate(), g.y_axis.truncate(), g.z_axis.truncate());
                adj_s.x += g0.w_dot(r.x_axis);
                adj_s.y += g1.w_dot(r.y_axis);
                adj_s.z += g2.w_dot(r.z_axis);
                *adj_p += g.w_axis.truncate();
                let adj_r = $m3::from_cols(g0 * s.x, g1 * s.y, g2 * s.z);
                <$q as AdjQuat>::adj_to_matrix(q, adj_q, adj_r);
            }
        }
        impl AdjDecompose for $m4 {
            #[inline(always)]
            fn adj_decompose(m: Self, adj_m: &mut Self, g: ($v3, $q, $v3)) {
                let c = [m.x_axis.truncate(), m.y_axis.truncate(), m.z_axis.truncate()];
                let mut s = [0.0; 3];
                let mut n = c;
                for j in 0..3 {
                    s[j] = c[j].w_length();
                    if s[j] != 0.0 {
                        n[j] = $v3::new(c[j].x / s[j], c[j].y / s[j], c[j].z / s[j]);
                    }
                }
                let mut adj_r = $m3::ZERO;
                <$q as AdjQuat>::adj_from_matrix($m3::from_cols(n[0], n[1], n[2]), &mut adj_r, g.1);
                let gs = g.2.to_array();
                let mut a = adj_m.to_cols_array();
                for j in 0..3 {
                    let adj_n = adj_r.col(j).to_array();
                    let (cj, nj) = (c[j].to_array(), n[j].to_array());
                    let mut adj_c = [0.0; 3];
                    let mut adj_sj = gs[j];
                    if s[j] != 0.0 {
                        for i in 0..3 {
                            let gb = adj_n[i] / s[j];
                            adj_c[i] += gb;
                            adj_sj -= gb * nj[i];
                        }
                    } else {
                        for i in 0..3 {
                            adj_c[i] += adj_n[i];
                        }
                    }
                    let mut adj_cv = $v3::from_array(adj_c);
                    <$v3 as AdjFloatVec>::adj_length(c[j], &mut adj_cv, adj_sj);
                    let _ = cj;
                    for (i, x) in adj_cv.to_array().into_iter().enumerate() {
                        a[4 * j + i] += x;
                    }
                }
                for (i, x) in g.0.to_array().into_iter().enumerate() {
                    a[12 + i] += x;
                }
                *adj_m = $m4::from_cols_array(&a);
            }
        }
    )*};
}
quat_adj!(Quat: Vec3, Mat3, Mat4, f32; DQuat: DVec3, DMat3, DMat4, f64);

/// `q + (x, y, z, w)` lane by lane (every lane added, as `wp_adjoint.h` does).
#[inline(always)]
fn quat_add<Q: QuatLanes>(q: Q, x: Q::S, y: Q::S, z: Q::S, w: Q::S) -> Q {
    q.add_lanes(x, y, z, w)
}

trait QuatLanes {
    type S;
    fn add_lanes(self, x: Self::S, y: Self::S, z: Self::S, w: Self::S) -> Self;
}
macro_rules! quat_lanes {
    ($($q:ident: $s:ident),*) => {$(
        impl QuatLanes for $q {
            type S = $s;
            #[inline(always)]
            fn add_lanes(self, x: $s, y: $s, z: $s, w: $s) -> Self {
                $q::from_xyzw(self.x + x, self.y + y, self.z + z, self.w + w)
            }
        }
    )*};
}
quat_lanes!(Quat: f32, DQuat: f64);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtins::misc as f;

    /// Central differences of a scalar function of 4 f64 inputs.
    fn fd(h: impl Fn([f64; 4]) -> f64, x: [f64; 4]) -> [f64; 4] {
        let e = 1e-6;
        core::array::from_fn(|k| {
            let (mut a, mut b) = (x, x);
            a[k] += e;
            b[k] -= e;
            (h(a) - h(b)) / (2.0 * e)
        })
    }

    fn close(a: [f64; 4], b: [f64; 4]) {
        for k in 0..4 {
            assert!(
                (a[k] - b[k]).abs() < 1e-7 * (1.0 + b[k].abs()),
                "{a:?} vs {b:?}"
            );
        }
    }

    #[test]
    fn against_central_differences() {
        let x = [0.3, -0.5, 0.7, 0.4];
        let probe = DVec3::new(0.3, -1.1, 0.7);
        let qp = DQuat::from_xyzw(0.2, 0.5, -0.3, 0.9);
        let q_of = |x: [f64; 4]| DQuat::from_xyzw(x[0], x[1], x[2], x[3]);
        // quat_to_axis_angle, quat_to_rpy, quat_twist(_angle)(_signed) in q.
        let axis = DVec3::new(0.0, 0.6, 0.8);
        type Fq = fn(DQuat) -> f64;
        type Aq = Box<dyn Fn(DQuat, &mut DQuat)>;
        let cases: [(Fq, Aq); 5] = [
            (
                |q| {
                    let (a, t) = f::quat_to_axis_angle(q);
                    a.dot(DVec3::new(0.3, -1.1, 0.7)) + 2.0 * t
                },
                Box::new(move |q, aq| adj_quat_to_axis_angle(q, aq, (probe, 2.0))),
            ),
            (
                |q| f::quat_to_rpy(q).dot(DVec3::new(0.3, -1.1, 0.7)),
                Box::new(move |q, aq| adj_quat_to_rpy(q, aq, probe)),
            ),
            (
                |q| {
                    f::quat_twist(DVec3::new(0.0, 0.6, 0.8), q)
                        .dot(DQuat::from_xyzw(0.2, 0.5, -0.3, 0.9))
                },
                Box::new(move |q, aq| {
                    let mut ax = DVec3::ZERO;
                    adj_quat_twist(axis, q, &mut ax, aq, qp)
                }),
            ),
            (
                |q| f::quat_twist_angle(DVec3::new(0.0, 0.6, 0.8), q),
                Box::new(move |q, aq| {
                    let mut ax = DVec3::ZERO;
                    adj_quat_twist_angle(axis, q, &mut ax, aq, 1.0)
                }),
            ),
            (
                |q| f::quat_twist_angle_signed(DVec3::new(0.0, 0.6, 0.8), q),
                Box::new(move |q, aq| {
                    let mut ax = DVec3::ZERO;
                    adj_quat_twist_angle_signed(axis, q, &mut ax, aq, 1.0)
                }),
            ),
        ];
        for (k, (fwd, adj)) in cases.iter().enumerate() {
            let mut aq = DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
            adj(q_of(x), &mut aq);
            let want = fd(|x| fwd(q_of(x)), x);
            eprintln!("case {k}");
            close(aq.to_array(), want);
        }
        // quat_rpy in its angles.
        let mut g = [0.0; 4];
        let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
        adj_quat_rpy(x[0], x[1], x[2], &mut a, &mut b, &mut c, qp);
        g[0] = a;
        g[1] = b;
        g[2] = c;
        let want = fd(|x| f::quat_rpy::<DQuat>(x[0], x[1], x[2]).dot(qp), x);
        close(g, [want[0], want[1], want[2], 0.0]);
        // Norms in v and delta (both branches of Huber).
        for d in [0.5, 3.0] {
            let v_of = |x: [f64; 4]| DVec3::new(x[0], x[1], x[2]);
            let xs = [x[0], x[1], x[2], d];
            type Fn2 = fn(DVec3, f64, &mut DVec3, &mut f64, f64);
            type Fw = fn(DVec3, f64) -> f64;
            let fs: [(Fw, Fn2); 3] = [
                (f::norm_huber, adj_norm_huber),
                (f::norm_pseudo_huber, adj_norm_pseudo_huber),
                (
                    |v, d| f::smooth_normalize(v, d).dot(DVec3::new(0.3, -1.1, 0.7)),
                    |v, d, av, ad, g| {
                        adj_smooth_normalize(v, d, av, ad, DVec3::new(0.3, -1.1, 0.7) * g)
                    },
                ),
            ];
            for (fwd, adj) in fs {
                let (mut av, mut ad) = (DVec3::ZERO, 0.0);
                adj(v_of(xs), xs[3], &mut av, &mut ad, 1.0);
                let want = fd(|x| fwd(v_of(x), x[3]), xs);
                close([av.x, av.y, av.z, ad], want);
            }
        }
        // transform_compose / decompose through a probe.
        let m_probe = DMat4::from_cols_array(&core::array::from_fn(|i| (i as f64 * 0.37).sin()));
        let p = DVec3::new(1.0, -2.0, 0.5);
        let s = DVec3::new(2.0, 0.5, 1.5);
        let (mut ap, mut aq, mut as_) = (
            DVec3::ZERO,
            DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
            DVec3::ZERO,
        );
        adj_transform_compose(p, q_of(x), s, &mut ap, &mut aq, &mut as_, m_probe);
        let ddot = |a: DMat4, b: DMat4| {
            a.to_cols_array()
                .iter()
                .zip(b.to_cols_array())
                .map(|(x, y)| x * y)
                .sum::<f64>()
        };
        let want = fd(|x| ddot(f::transform_compose(p, q_of(x), s), m_probe), x);
        close(aq.to_array(), want);
        let want = fd(
            |y| {
                ddot(
                    f::transform_compose(p, q_of(x), DVec3::new(y[0], y[1], y[2])),
                    m_probe,
                )
            },
            [s.x, s.y, s.z, 0.0],
        );
        close([as_.x, as_.y, as_.z, 0.0], want);
        let m = f::transform_compose(p, q_of(x).normalize(), s);
        let mut am = DMat4::ZERO;
        let gq = DQuat::from_xyzw(0.2, 0.5, -0.3, 0.9);
        adj_transform_decompose(m, &mut am, (probe, gq, DVec3::new(0.5, 1.0, -1.0)));
        let loss = |m: DMat4| {
            let (p, q, s) = f::transform_decompose(m);
            p.dot(probe) + q.dot(gq) + s.dot(DVec3::new(0.5, 1.0, -1.0))
        };
        for k in [0usize, 1, 5, 6, 10, 12, 13] {
            let mut a = m.to_cols_array();
            a[k] += 1e-6;
            let mut b = m.to_cols_array();
            b[k] -= 1e-6;
            let want = (loss(DMat4::from_cols_array(&a)) - loss(DMat4::from_cols_array(&b))) / 2e-6;
            let got = am.to_cols_array()[k];
            assert!(
                (got - want).abs() < 1e-6,
                "decompose lane {k}: {got} vs {want}"
            );
        }
        // Reductions, copysign, get_diag.
        let v = DVec3::new(0.5, -2.0, 3.0);
        let mut av = DVec3::ZERO;
        adj_min_element(v, &mut av, 1.0);
        adj_max_element(v, &mut av, 2.0);
        assert_eq!(av, DVec3::new(0.0, 1.0, 2.0));
        let (mut ax, mut ay) = (0.0, 0.0);
        adj_copysign(2.0f64, -1.0, &mut ax, &mut ay, 1.5);
        assert_eq!((ax, ay), (-1.5, 0.0));
        adj_copysign(-2.0f64, -1.0, &mut ax, &mut ay, 1.0);
        adj_copysign(0.5f64, 3.0, &mut ax, &mut ay, 4.0);
        assert_eq!((ax, ay), (3.5, 0.0));
        let mut am = DMat3::ZERO;
        adj_get_diag(DMat3::IDENTITY, &mut am, v);
        assert_eq!(am, DMat3::from_diagonal(v));
        let mut av = DVec3::ZERO;
        adj_norm_l1(v, &mut av, 2.0);
        assert_eq!(av, DVec3::new(2.0, -2.0, 2.0));
    }
}

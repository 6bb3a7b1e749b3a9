//! More of Warp's vector, quaternion and transform builtins (CPU side of the table's "misc"
//! section, `wp_misc.h` on CUDA), and its `lower_bound`.
//!
//! Every formula is written out in the order both libraries evaluate it (left to right, the
//! same temporaries, no fused multiply-add), so that the backends agree bit for bit where the
//! math library does (`sqrt` everywhere; `sin`, `cos`, `atan2`, `asin` are each platform's):
//!
//! * `copysign(x, y)`: `x`'s magnitude with `y`'s sign bit (Rust's `f32::copysign`, C's
//!   `copysign`); `nonzero(x)`: `1` if `x != 0` else `0` (so `1` for NaN, `0` for `-0.0`);
//! * `min_element(v)`, `max_element(v)` (Warp's one-vector `min`/`max`): `min` (`fmin`) folded
//!   from lane 0, so NaN lanes are skipped unless all are NaN; `argmin(v)`, `argmax(v)`: the
//!   first index of a strictly smaller (larger) non-NaN lane, starting from the first non-NaN
//!   lane; `0` when every lane is NaN (Warp's rule), as a `u32`;
//! * `get_diag(m)`: the diagonal of a square matrix, as a vector;
//! * `isfinite`, `isnan`, `isinf` of quaternions and matrices: every lane finite, some lane
//!   NaN, some lane infinite;
//! * `norm_l1(v) = ((0 + |x|) + |y|) + ..`; `norm_l2(v) = length(v)`;
//!   `norm_huber(v, d)`: with `a = dot(v, v)`, `0.5 * a` if `a <= d * d`, else
//!   `d * (sqrt(a) - 0.5 * d)`; `norm_pseudo_huber(v, d) = d * sqrt(1 + a / (d * d))`;
//!   `smooth_normalize(v, d) = v / norm_pseudo_huber(v, d)` lane by lane (Warp's `@wp.func`s);
//! * `quat_to_axis_angle(q) -> (axis, angle)`: `axis = ±normalize(xyz)` (the sign of `w`),
//!   `angle = 2 atan2(length(xyz), |w|)` (Warp's; the identity gives the zero axis, angle 0);
//! * `quat_rpy(roll, pitch, yaw)`: with `c* = cos(* 0.5)`, `s* = sin(* 0.5)`:
//!   `x = cy*sr*cp - sy*cr*sp`, `y = cy*cr*sp + sy*sr*cp`, `z = sy*cr*cp - cy*sr*sp`,
//!   `w = cy*cr*cp + sy*sr*sp` (each product left to right), Warp's;
//! * `quat_to_rpy(q)`: `(atan2(2(wx + yz), 1 - 2(xx + yy)), asin(clamp(2(wy - zx), -1, 1)),
//!   atan2(2(wz + xy), 1 - 2(yy + zz)))`, Warp's;
//! * `quat_twist(axis, q) = normalize((dot(xyz, axis) * axis, w))` (the zero quaternion
//!   normalizes to the identity, this crate's rule); `quat_twist_angle(axis, q) =
//!   2 atan2(|dot(axis, xyz)|, w)`, `quat_twist_angle_signed` without the `abs`;
//! * `transform_compose(p, q, s)`: the 4x4 matrix with columns `R.x_axis * s.x`,
//!   `R.y_axis * s.y`, `R.z_axis * s.z`, `(p, 1)`, where `R = quat_to_matrix(q)` (glam's
//!   `Mat4::from_scale_rotation_translation(s, q, p)` computes the same);
//!   `transform_decompose(m) -> (p, q, s)`: `p` the translation column, `s` the lengths of the
//!   upper-left columns, each column divided by its length when that is not zero, and
//!   `q = quat_from_matrix` of the result (not normalized, as `quat_from_matrix` here);
//! * `lower_bound(a, value)`, `lower_bound(a, lo, hi, value)`: Warp's binary search over a
//!   sorted 1-D array: the first index `i` in `[lo, hi)` with `a[i] >= value`, **or `hi - 1`
//!   when there is none** (Warp's loop never returns `hi`), and `lo` when the range is empty;
//!   every element read is a checked access, so a range outside the array is a fault.

use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};

use super::linalg::QuatOps;
use super::math::{Classify, Float, FloatVec, MinMax, Scalar, Signed, VecOps};
use crate::{ArrayView, KResult};

// ------------------------------------------------------------------------------------------
// Traits
// ------------------------------------------------------------------------------------------

/// `copysign`: `f32`, `f64`.
pub trait CopySign: Float {
    /// `self`'s magnitude with `y`'s sign bit.
    fn w_copysign(self, y: Self) -> Self;
}

/// The one-vector reductions: float and integer vectors.
pub trait VecReduce: Copy {
    /// The lane type.
    type S: Copy;
    /// The smallest lane (`fmin` folded from lane 0 for floats).
    fn w_min_element(self) -> Self::S;
    /// The largest lane (`fmax` folded from lane 0 for floats).
    fn w_max_element(self) -> Self::S;
    /// The index of the smallest non-NaN lane (the first of equal ones); 0 if all are NaN.
    fn w_argmin(self) -> u32;
    /// The index of the largest non-NaN lane (the first of equal ones); 0 if all are NaN.
    fn w_argmax(self) -> u32;
}

/// `get_diag`: square float matrices.
pub trait GetDiag: Copy {
    /// The column type.
    type V: Copy;
    /// The diagonal.
    fn w_get_diag(self) -> Self::V;
}

/// The norms of Warp's `math.py`: float vectors.
pub trait Norms: FloatVec<Scalar: Float> {
    /// See [`norm_l1`].
    fn w_norm_l1(self) -> Self::Scalar;
    /// See [`norm_huber`].
    fn w_norm_huber(self, delta: Self::Scalar) -> Self::Scalar;
    /// See [`norm_pseudo_huber`].
    fn w_norm_pseudo_huber(self, delta: Self::Scalar) -> Self::Scalar;
    /// See [`smooth_normalize`].
    fn w_smooth_normalize(self, delta: Self::Scalar) -> Self;
}

/// The quaternion builtins of this section: `Quat`, `DQuat`.
pub trait QuatMisc: QuatOps {
    /// See [`quat_to_axis_angle`].
    fn w_to_axis_angle(self) -> (Self::V3, Self::S);
    /// See [`quat_rpy`].
    fn w_rpy(roll: Self::S, pitch: Self::S, yaw: Self::S) -> Self;
    /// See [`quat_to_rpy`].
    fn w_to_rpy(self) -> Self::V3;
    /// See [`quat_twist`].
    fn w_twist(axis: Self::V3, q: Self) -> Self;
    /// See [`quat_twist_angle`].
    fn w_twist_angle(axis: Self::V3, q: Self, signed: bool) -> Self::S;
}

/// `transform_compose`: `Vec3` (with `Quat`, `Mat4`), `DVec3` (with `DQuat`, `DMat4`).
pub trait Compose: Copy {
    /// The quaternion.
    type Q: Copy;
    /// The 4x4 matrix.
    type M4: Copy;
    /// See [`transform_compose`].
    fn w_compose(p: Self, q: Self::Q, s: Self) -> Self::M4;
}

// ------------------------------------------------------------------------------------------
// Public builtins
// ------------------------------------------------------------------------------------------

/// `x`'s magnitude with `y`'s sign bit.
#[inline(always)]
pub fn copysign<F: CopySign>(x: F, y: F) -> F {
    x.w_copysign(y)
}

/// The number of threads per block of the launch: 1 on the CPU, where a launch has no blocks
/// (Warp's CPU value too); the CUDA library returns `blockDim.x`
/// (`config::cuda_block_dim`).
#[inline(always)]
pub fn block_dim() -> i32 {
    1
}

/// `1` if `x != 0`, else `0` (NaN gives 1, `-0.0` gives 0).
#[inline(always)]
pub fn nonzero<T: Scalar>(x: T) -> T {
    if x != T::ZERO {
        T::ONE
    } else {
        T::ZERO
    }
}

/// The smallest lane of `v` (Warp's `min(v)`; NaN lanes skipped unless all are NaN).
#[inline(always)]
pub fn min_element<V: VecReduce>(v: V) -> V::S {
    v.w_min_element()
}

/// The largest lane of `v` (Warp's `max(v)`; NaN lanes skipped unless all are NaN).
#[inline(always)]
pub fn max_element<V: VecReduce>(v: V) -> V::S {
    v.w_max_element()
}

/// The index of the smallest non-NaN lane of `v` (the first of equal ones; 0 if all are NaN).
#[inline(always)]
pub fn argmin<V: VecReduce>(v: V) -> u32 {
    v.w_argmin()
}

/// The index of the largest non-NaN lane of `v` (the first of equal ones; 0 if all are NaN).
#[inline(always)]
pub fn argmax<V: VecReduce>(v: V) -> u32 {
    v.w_argmax()
}

/// The diagonal of a square matrix.
#[inline(always)]
pub fn get_diag<M: GetDiag>(m: M) -> M::V {
    m.w_get_diag()
}

/// The L1 norm `sum |v[i]|`, left to right from 0.
#[inline(always)]
pub fn norm_l1<V: Norms>(v: V) -> V::Scalar {
    v.w_norm_l1()
}

/// The L2 norm, `length(v)`.
#[inline(always)]
pub fn norm_l2<V: Norms>(v: V) -> V::Scalar {
    v.w_length()
}

/// The Huber norm: `0.5 |v|²` where `|v|² <= delta²`, else `delta (|v| - 0.5 delta)`.
#[inline(always)]
pub fn norm_huber<V: Norms>(v: V, delta: V::Scalar) -> V::Scalar {
    v.w_norm_huber(delta)
}

/// The pseudo-Huber norm `delta sqrt(1 + |v|² / delta²)`.
#[inline(always)]
pub fn norm_pseudo_huber<V: Norms>(v: V, delta: V::Scalar) -> V::Scalar {
    v.w_norm_pseudo_huber(delta)
}

/// `v / norm_pseudo_huber(v, delta)`.
#[inline(always)]
pub fn smooth_normalize<V: Norms>(v: V, delta: V::Scalar) -> V {
    v.w_smooth_normalize(delta)
}

/// The rotation axis and angle of `q` (see the module documentation).
#[inline(always)]
pub fn quat_to_axis_angle<Q: QuatMisc>(q: Q) -> (Q::V3, Q::S) {
    q.w_to_axis_angle()
}

/// The quaternion of roll, pitch and yaw angles (Warp's `quat_rpy`).
#[inline(always)]
pub fn quat_rpy<Q: QuatMisc>(roll: Q::S, pitch: Q::S, yaw: Q::S) -> Q {
    Q::w_rpy(roll, pitch, yaw)
}

/// Roll, pitch and yaw of `q` (Warp's `quat_to_rpy`).
#[inline(always)]
pub fn quat_to_rpy<Q: QuatMisc>(q: Q) -> Q::V3 {
    q.w_to_rpy()
}

/// The twist of `q` about the unit `axis` (swing-twist decomposition).
#[inline(always)]
pub fn quat_twist<Q: QuatMisc>(axis: Q::V3, q: Q) -> Q {
    Q::w_twist(axis, q)
}

/// The unsigned twist angle of `q` about the unit `axis`.
#[inline(always)]
pub fn quat_twist_angle<Q: QuatMisc>(axis: Q::V3, q: Q) -> Q::S {
    Q::w_twist_angle(axis, q, false)
}

/// The signed twist angle of `q` about the unit `axis`.
#[inline(always)]
pub fn quat_twist_angle_signed<Q: QuatMisc>(axis: Q::V3, q: Q) -> Q::S {
    Q::w_twist_angle(axis, q, true)
}

/// The 4x4 matrix translating by `p` after rotating by `q` after scaling by `s`.
#[inline(always)]
pub fn transform_compose<V: Compose>(p: V, q: V::Q, s: V) -> V::M4 {
    V::w_compose(p, q, s)
}

/// `(p, q, s)` with `transform_compose(p, q, s) == m` for such matrices.
#[inline(always)]
pub fn transform_decompose<M: Decompose>(m: M) -> (M::V, M::Q, M::V) {
    M::w_decompose_m(m)
}

/// `transform_decompose` by its matrix type.
pub trait Decompose: Copy {
    /// The 3-vector.
    type V: Copy;
    /// The quaternion.
    type Q: Copy;
    /// See [`transform_decompose`].
    fn w_decompose_m(self) -> (Self::V, Self::Q, Self::V);
}

/// Warp's `lower_bound` over the whole 1-D array (see the module documentation).
#[inline(always)]
pub fn lower_bound<T: Copy + PartialOrd>(a: &ArrayView<T, 1>, value: T) -> KResult<i32> {
    let n = i32::try_from(a.shape()[0]).unwrap_or(i32::MAX);
    lower_bound_range(a, 0, n, value)
}

/// Warp's `lower_bound` over `[lo, hi)` of a 1-D array (see the module documentation).
#[inline(always)]
pub fn lower_bound_range<T: Copy + PartialOrd>(
    a: &ArrayView<T, 1>,
    lo: i32,
    hi: i32,
    value: T,
) -> KResult<i32> {
    let mut lower = lo;
    let mut upper = hi.wrapping_sub(1);
    while lower < upper {
        // `lower + (upper - lower) / 2` without overflow (the difference fits an i64).
        let mid = (lower as i64 + (upper as i64 - lower as i64) / 2) as i32;
        if a.load(mid)? < value {
            lower = mid + 1;
        } else {
            upper = mid;
        }
    }
    Ok(lower)
}

// ------------------------------------------------------------------------------------------
// Implementations
// ------------------------------------------------------------------------------------------

macro_rules! copysign_impl {
    ($($s:ident),*) => {$(
        impl CopySign for $s {
            #[inline(always)]
            fn w_copysign(self, y: Self) -> Self {
                self.copysign(y)
            }
        }
    )*};
}
copysign_impl!(f32, f64);

/// `x != x`: NaN for floats, never for integers.
#[inline(always)]
#[allow(clippy::eq_op)]
fn nan_like<S: PartialOrd>(x: &S) -> bool {
    x != x
}

macro_rules! reduce_impl {
    ($($v:ident: $s:ident),*) => {$(
        impl VecReduce for $v {
            type S = $s;
            #[inline(always)]
            fn w_min_element(self) -> $s {
                let a = self.to_array();
                let mut r = a[0];
                for x in &a[1..] {
                    r = r.w_min(*x);
                }
                r
            }
            #[inline(always)]
            fn w_max_element(self) -> $s {
                let a = self.to_array();
                let mut r = a[0];
                for x in &a[1..] {
                    r = r.w_max(*x);
                }
                r
            }
            #[inline(always)]
            fn w_argmin(self) -> u32 {
                arg_extreme(&self.to_array(), |x, r| x < r)
            }
            #[inline(always)]
            fn w_argmax(self) -> u32 {
                arg_extreme(&self.to_array(), |x, r| x > r)
            }
        }
    )*};
}
reduce_impl!(
    Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64,
    IVec2: i32, IVec3: i32, IVec4: i32, UVec2: u32, UVec3: u32, UVec4: u32
);

/// The first non-NaN lane `r`, then every later non-NaN lane `x` with `better(x, r)`.
#[inline(always)]
fn arg_extreme<S: PartialOrd + Copy>(a: &[S], better: impl Fn(S, S) -> bool) -> u32 {
    let Some(mut r) = a.iter().position(|x| !nan_like(x)) else {
        return 0;
    };
    for i in r + 1..a.len() {
        if !nan_like(&a[i]) && better(a[i], a[r]) {
            r = i;
        }
    }
    r as u32
}

macro_rules! diag_impl {
    ($($m:ident: $v:ident),*) => {$(
        impl GetDiag for $m {
            type V = $v;
            #[inline(always)]
            fn w_get_diag(self) -> $v {
                $v::from_array(core::array::from_fn(|i| self.col(i)[i]))
            }
        }
        impl Classify for $m {
            #[inline(always)]
            fn w_isfinite(self) -> bool {
                self.to_cols_array().iter().all(|x| x.is_finite())
            }
            #[inline(always)]
            fn w_isnan(self) -> bool {
                self.to_cols_array().iter().any(|x| x.is_nan())
            }
            #[inline(always)]
            fn w_isinf(self) -> bool {
                self.to_cols_array().iter().any(|x| x.is_infinite())
            }
        }
    )*};
}
diag_impl!(Mat2: Vec2, Mat3: Vec3, Mat4: Vec4, DMat2: DVec2, DMat3: DVec3, DMat4: DVec4);

macro_rules! norms_impl {
    ($($v:ident: $s:ident),*) => {$(
        impl Norms for $v {
            #[inline(always)]
            fn w_norm_l1(self) -> $s {
                let mut n: $s = 0.0;
                for x in self.to_array() {
                    n += x.w_abs();
                }
                n
            }
            #[inline(always)]
            fn w_norm_huber(self, delta: $s) -> $s {
                let a = self.w_dot(self);
                if a <= delta * delta {
                    0.5 * a
                } else {
                    delta * (a.w_sqrt() - 0.5 * delta)
                }
            }
            #[inline(always)]
            fn w_norm_pseudo_huber(self, delta: $s) -> $s {
                let a = self.w_dot(self);
                delta * (1.0 + a / (delta * delta)).w_sqrt()
            }
            #[inline(always)]
            fn w_smooth_normalize(self, delta: $s) -> Self {
                let n = self.w_norm_pseudo_huber(delta);
                $v::from_array(self.to_array().map(|x| x / n))
            }
        }
    )*};
}
norms_impl!(Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64);

macro_rules! quat_misc_impl {
    ($($q:ident: $v3:ident, $v4:ident, $m3:ident, $m4:ident, $s:ident);*) => {$(
        impl Classify for $q {
            #[inline(always)]
            fn w_isfinite(self) -> bool {
                self.to_array().iter().all(|x| x.is_finite())
            }
            #[inline(always)]
            fn w_isnan(self) -> bool {
                self.to_array().iter().any(|x| x.is_nan())
            }
            #[inline(always)]
            fn w_isinf(self) -> bool {
                self.to_array().iter().any(|x| x.is_infinite())
            }
        }
        impl QuatMisc for $q {
            #[inline(always)]
            fn w_to_axis_angle(self) -> ($v3, $s) {
                let v = $v3::new(self.x, self.y, self.z);
                let n = v.w_normalize();
                let axis = if self.w < 0.0 { -n } else { n };
                (axis, 2.0 * v.w_length().w_atan2(self.w.w_abs()))
            }
            #[inline(always)]
            fn w_rpy(roll: $s, pitch: $s, yaw: $s) -> Self {
                let (cy, sy) = ((yaw * 0.5).w_cos(), (yaw * 0.5).w_sin());
                let (cr, sr) = ((roll * 0.5).w_cos(), (roll * 0.5).w_sin());
                let (cp, sp) = ((pitch * 0.5).w_cos(), (pitch * 0.5).w_sin());
                let w = cy * cr * cp + sy * sr * sp;
                let x = cy * sr * cp - sy * cr * sp;
                let y = cy * cr * sp + sy * sr * cp;
                let z = sy * cr * cp - cy * sr * sp;
                $q::from_xyzw(x, y, z, w)
            }
            #[inline(always)]
            fn w_to_rpy(self) -> $v3 {
                let (x, y, z, w) = (self.x, self.y, self.z, self.w);
                let t0 = 2.0 * (w * x + y * z);
                let t1 = 1.0 - 2.0 * (x * x + y * y);
                let t2 = (2.0 * (w * y - z * x)).w_max(-1.0).w_min(1.0);
                let t3 = 2.0 * (w * z + x * y);
                let t4 = 1.0 - 2.0 * (y * y + z * z);
                $v3::new(t0.w_atan2(t1), t2.w_asin(), t3.w_atan2(t4))
            }
            #[inline(always)]
            fn w_twist(axis: $v3, q: Self) -> Self {
                let a = $v3::new(q.x, q.y, q.z);
                let p = a.w_dot(axis);
                let b = $v3::new(p * axis.x, p * axis.y, p * axis.z);
                $q::from_xyzw(b.x, b.y, b.z, q.w).w_normalize()
            }
            #[inline(always)]
            fn w_twist_angle(axis: $v3, q: Self, signed: bool) -> $s {
                let d = axis.w_dot($v3::new(q.x, q.y, q.z));
                let s = if signed { d } else { d.w_abs() };
                2.0 * s.w_atan2(q.w)
            }
        }
        impl Compose for $v3 {
            type Q = $q;
            type M4 = $m4;
            #[inline(always)]
            fn w_compose(p: $v3, q: $q, s: $v3) -> $m4 {
                let r = q.w_to_matrix();
                $m4::from_cols(
                    (r.x_axis * s.x).extend(0.0),
                    (r.y_axis * s.y).extend(0.0),
                    (r.z_axis * s.z).extend(0.0),
                    p.extend(1.0),
                )
            }
        }
        impl Decompose for $m4 {
            type V = $v3;
            type Q = $q;
            #[inline(always)]
            fn w_decompose_m(self) -> ($v3, $q, $v3) {
                let p = self.w_axis.truncate();
                let mut c = [self.x_axis.truncate(), self.y_axis.truncate(), self.z_axis.truncate()];
                let mut s = [0.0; 3];
                for (cj, sj) in c.iter_mut().zip(s.iter_mut()) {
                    *sj = cj.w_length();
                    if *sj != 0.0 {
                        let l = *sj;
                        *cj = $v3::new(cj.x / l, cj.y / l, cj.z / l);
                    }
                }
                let q = $q::w_from_matrix($m3::from_cols(c[0], c[1], c[2]));
                (p, q, $v3::from_array(s))
            }
        }
    )*};
}
quat_misc_impl!(Quat: Vec3, Vec4, Mat3, Mat4, f32; DQuat: DVec3, DVec4, DMat3, DMat4, f64);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reductions_skip_nan() {
        let v = Vec4::new(f32::NAN, 3.0, -1.0, -1.0);
        assert_eq!(min_element(v), -1.0);
        assert_eq!(max_element(v), 3.0);
        assert_eq!(argmin(v), 2);
        assert_eq!(argmax(v), 1);
        assert_eq!(argmin(Vec3::splat(f32::NAN)), 0);
        assert!(min_element(Vec2::splat(f32::NAN)).is_nan());
        assert_eq!(argmax(IVec3::new(4, 9, 9)), 1);
        assert_eq!(min_element(UVec3::new(4, 9, 2)), 2);
    }

    #[test]
    fn closed_forms() {
        assert_eq!(copysign(3.0f32, -0.0), -3.0);
        assert_eq!(nonzero(-0.0f64), 0.0);
        assert_eq!(nonzero(f32::NAN), 1.0);
        assert_eq!(nonzero(-3i32), 1);
        let v = DVec3::new(3.0, -4.0, 0.0);
        assert_eq!(norm_l1(v), 7.0);
        assert_eq!(norm_l2(v), 5.0);
        assert_eq!(norm_huber(v, 10.0), 12.5);
        assert_eq!(norm_huber(v, 1.0), 4.5);
        assert_eq!(norm_pseudo_huber(v, 1.0), 26f64.sqrt());
        assert_eq!(get_diag(DMat3::from_diagonal(v)), v);
        let (axis, angle) = quat_to_axis_angle(DQuat::from_axis_angle(DVec3::Y, -0.5));
        assert!((axis - DVec3::NEG_Y).length() < 1e-15 && (angle - 0.5).abs() < 1e-15);
        let q = quat_rpy::<DQuat>(0.1, -0.2, 0.3);
        let e = quat_to_rpy(q);
        assert!((e - DVec3::new(0.1, -0.2, 0.3)).length() < 1e-15, "{e}");
        let m = transform_compose(DVec3::new(1.0, 2.0, 3.0), q, DVec3::new(2.0, 0.5, 3.0));
        let g = DMat4::from_scale_rotation_translation(
            DVec3::new(2.0, 0.5, 3.0),
            q,
            DVec3::new(1.0, 2.0, 3.0),
        );
        assert_eq!(m, g);
        let (p, r, s) = transform_decompose(m);
        assert_eq!(p, DVec3::new(1.0, 2.0, 3.0));
        assert!((s - DVec3::new(2.0, 0.5, 3.0)).length() < 1e-14);
        assert!((r.dot(q).abs() - 1.0).abs() < 1e-14);
        let t = quat_twist(
            DVec3::Z,
            DQuat::from_axis_angle(DVec3::Z, 0.7) * DQuat::from_axis_angle(DVec3::X, 0.2),
        );
        assert!((quat_twist_angle(DVec3::Z, t) - 0.7).abs() < 1e-14);
        assert!((quat_twist_angle_signed(DVec3::NEG_Z, t) + 0.7).abs() < 1e-14);
        assert!(isnan(DQuat::from_xyzw(0.0, f64::NAN, 0.0, 1.0)));
        assert!(!isfinite(Mat2::from_diagonal(Vec2::new(
            1.0,
            f32::INFINITY
        ))));
    }

    use super::super::math::{isfinite, isnan};
}

//! `quat_from_euler(e, i, j, k)` and `quat_to_euler(q, i, j, k)`: Warp's `@wp.func`s of
//! `warp/_src/math.py` (NVIDIA/warp `9934a4e`), transcribed branch for branch (the CUDA
//! mirror, `wp_linalg.h`, does the same steps; the adjoints, `adjoint/linalg.rs`, reverse
//! them). `i`, `j`, `k` are axis indices, 0 = x, 1 = y, 2 = z.
//!
//! * `quat_from_euler`: `q = q_k * (q_j * q_i)` with `q_n` the rotation by `e[n]` about axis
//!   `n` (`(sin(e[n]/2) along the axis, cos(e[n]/2))`): extrinsic rotations about the fixed
//!   axes `i`, then `j`, then `k`. An index other than 0 or 1 means z, as Warp's `else`
//!   branches choose the axis (where Warp's `e[i]` would read out of bounds).
//! * `quat_to_euler`: the axis-indexed angles (`e[i]`, `e[j]`, `e[k]` placed by axis, so that
//!   `quat_from_euler(quat_to_euler(q, i, j, k), i, j, k)` is `±q` for a Tait-Bryan sequence,
//!   `i != k`), by the formula for scalar-first quaternions Warp cites (Bernardes and Viollet,
//!   2022): with `(q0, q1, q2, q3) = (w, x, y, z)` and 1-based `i, j, k`, a proper sequence
//!   (`i == k`) takes `k = 6 - i - j`; `ε` is the Levi-Civita symbol of `(i, j, k)`;
//!   `a = q0, b = q_i, c = q_j, d = ε q_k`, and for a Tait-Bryan sequence `a -= q_j`,
//!   `b += ε q_k`, `c += q0`, `d -= q_i`; then `θ2 = acos(2 (a² + b²) / (a² + b² + c² + d²) -
//!   1)` (the builtin `acos`, clamped to `[-1, 1]`), `θ+ = atan2(b, a)`, `θ- = atan2(d, c)`;
//!   `θ1 = θ+ - θ-`, `θ3 = θ+ + θ-` except within `1e-6` of the singular `θ2 = 0` (`θ1 = 0`,
//!   `θ3 = 2 θ+`) and `θ2 = π` (`θ1 = 0`, `θ3 = 2 θ-`), Warp's gimbal-lock branches; a
//!   Tait-Bryan sequence then takes `θ2 -= π/2`, `θ3 *= ε`. The angles are placed as Warp
//!   places them: `(θ1, θ2, θ3)`, then `θ1` swapped into slot `i`, then `θ2` written to slot `j`
//!   and `θ3` to slot `k`. The index arithmetic is done in 64 bits (`ε` through f64), so no
//!   index overflows; indices outside `0..=2` give Warp's branches' results, meaningless ones.

use glam::{DQuat, DVec3, Quat, Vec3};

use super::math::{Float, Signed};

/// The axis an index names in `quat_from_euler` (Warp's branches: 0 is x, 1 is y, else z).
#[inline(always)]
pub(crate) fn axis(n: i32) -> usize {
    match n {
        0 => 0,
        1 => 1,
        _ => 2,
    }
}

/// The lane of `(q0, q1, q2, q3) = (w, x, y, z)` a 1-based axis index reads in
/// `quat_to_euler` (Warp's branches: 2 is q2, 3 is q3, else q1).
#[inline(always)]
pub(crate) fn pick(n: i64) -> usize {
    match n {
        2 => 2,
        3 => 3,
        _ => 1,
    }
}

/// What `quat_to_euler` computes on the way, which its adjoint reads again.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ToEuler<S> {
    /// A Tait-Bryan sequence (`i != k`).
    pub not_proper: bool,
    /// The Levi-Civita symbol of the (1-based, completed) sequence.
    pub e: S,
    /// The lanes of `(w, x, y, z)` that `b`, `c` and `d` read: `pick(i)`, `pick(j)`, `pick(k)`.
    pub pi: usize,
    pub pj: usize,
    pub pk: usize,
    pub a: S,
    pub b: S,
    pub c: S,
    pub d: S,
    /// `(2 (a² + b²)) / (a² + b² + c² + d²)`, `acos`'s argument plus one.
    pub quo: S,
    /// `a² + b² + c² + d²`.
    pub n: S,
    /// 0: `θ2` near 0; 1: near `π`; 2: neither.
    pub branch: u8,
    /// Which of `θ1, θ2, θ3` (0, 1, 2) each of the result's lanes `x, y, z` holds.
    pub slot: [usize; 3],
    /// The result's lanes.
    pub out: [S; 3],
}

/// `quat_from_euler`'s axis quaternions `q_i, q_j, q_k` of the angles of `e` (lanes `x, y, z`)
/// and their half-angles' sines and cosines, which its adjoint reads again.
pub(crate) struct FromEuler<S> {
    /// The axes `axis(i)`, `axis(j)`, `axis(k)`.
    pub ax: [usize; 3],
    /// The half angles.
    pub h: [S; 3],
    /// The axis quaternions' lanes `x, y, z, w`.
    pub q: [[S; 4]; 3],
}

macro_rules! euler_impl {
    ($($q:ident, $v3:ident, $s:ident, $from:ident, $to:ident);*) => {$(
        /// The steps of `quat_from_euler` (see the module documentation).
        pub(crate) fn $from(e: $v3, i: i32, j: i32, k: i32) -> FromEuler<$s> {
            let ea = e.to_array();
            let ax = [axis(i), axis(j), axis(k)];
            let h = [0.5 * ea[ax[0]], 0.5 * ea[ax[1]], 0.5 * ea[ax[2]]];
            let q = core::array::from_fn(|n| {
                let mut l = [0.0; 4];
                l[ax[n]] = h[n].w_sin();
                l[3] = h[n].w_cos();
                l
            });
            FromEuler { ax, h, q }
        }

        /// The steps of `quat_to_euler` (see the module documentation).
        pub(crate) fn $to(q: $q, i: i32, j: i32, k: i32) -> ToEuler<$s> {
            let qa = [q.w, q.x, q.y, q.z];
            let (i, j, mut k) = (i as i64 + 1, j as i64 + 1, k as i64 + 1);
            let mut not_proper = true;
            if i == k {
                not_proper = false;
                k = 6 - i - j;
            }
            let e = ((i - j) as f64 * (j - k) as f64 * (k - i) as f64 / 2.0) as $s;
            let (pi, pj, pk) = (pick(i), pick(j), pick(k));
            let (mut a, mut b, mut c, mut d) = (qa[0], qa[pi], qa[pj], qa[pk] * e);
            if not_proper {
                a -= qa[pj];
                b += qa[pk] * e;
                c += qa[0];
                d -= qa[pi];
            }
            let s = a * a + b * b;
            let n = s + c * c + d * d;
            let quo = (2.0 * s) / n;
            let t2 = (quo - 1.0).w_acos();
            let tp = b.w_atan2(a);
            let tm = d.w_atan2(c);
            // Warp's t1 = 0 on the singular branches, which its t3 formulas add.
            let zero: $s = 0.0;
            let (t1, mut t3, branch) = if t2.w_abs() < 1e-6 {
                (zero, 2.0 * tp - zero, 0)
            } else if (t2 - core::$s::consts::PI).w_abs() < 1e-6 {
                (zero, 2.0 * tm + zero, 1)
            } else {
                (tp - tm, tp + tm, 2)
            };
            let mut t2o = t2;
            if not_proper {
                t2o -= core::$s::consts::FRAC_PI_2;
                t3 *= e;
            }
            let mut slot = [0, 1, 2];
            if i == 2 {
                slot[0] = 1;
                slot[1] = 0;
            } else if i == 3 {
                slot[0] = 2;
                slot[2] = 0;
            }
            slot[match j { 1 => 0, 2 => 1, _ => 2 }] = 1;
            slot[match k { 1 => 0, 2 => 1, _ => 2 }] = 2;
            let t = [t1, t2o, t3];
            ToEuler {
                not_proper, e, pi, pj, pk, a, b, c, d, quo, n, branch, slot,
                out: [t[slot[0]], t[slot[1]], t[slot[2]]],
            }
        }

        impl EulerOps for $q {
            type V3 = $v3;
            #[inline]
            fn w_from_euler(e: $v3, i: i32, j: i32, k: i32) -> Self {
                let p = $from(e, i, j, k);
                let [qi, qj, qk] = p.q.map($q::from_array);
                qk * (qj * qi)
            }
            #[inline]
            fn w_to_euler(self, i: i32, j: i32, k: i32) -> $v3 {
                $v3::from_array($to(self, i, j, k).out)
            }
        }
        impl EulerAngles for $v3 {
            type Q = $q;
        }
    )*};
}

/// `quat_from_euler`, `quat_to_euler`: [`Quat`], [`DQuat`].
pub trait EulerOps: Copy {
    /// The 3-vector of angles.
    type V3: Copy;
    /// See [`quat_from_euler`].
    fn w_from_euler(e: Self::V3, i: i32, j: i32, k: i32) -> Self;
    /// See [`quat_to_euler`].
    fn w_to_euler(self, i: i32, j: i32, k: i32) -> Self::V3;
}

/// The angle vectors of `quat_from_euler`: [`Vec3`] (making a [`Quat`]), [`DVec3`] (a
/// [`DQuat`]).
pub trait EulerAngles: Copy {
    /// The quaternion type.
    type Q: EulerOps<V3 = Self>;
}

euler_impl!(
    Quat, Vec3, f32, from_euler_f32, to_euler_f32;
    DQuat, DVec3, f64, from_euler_f64, to_euler_f64
);

/// The rotation by the angles `e` (radians, read by axis: `e.x` about x, ...) about the fixed
/// axes `i`, then `j`, then `k` (0 = x, 1 = y, 2 = z): `q_k * q_j * q_i` (Warp's).
#[inline(always)]
pub fn quat_from_euler<V: EulerAngles>(e: V, i: i32, j: i32, k: i32) -> V::Q {
    V::Q::w_from_euler(e, i, j, k)
}

/// The angles of `q` for the axis sequence `(i, j, k)`, placed by axis (Warp's; see the
/// module documentation for the formula and its gimbal-lock branches).
#[inline(always)]
pub fn quat_to_euler<Q: EulerOps>(q: Q, i: i32, j: i32, k: i32) -> Q::V3 {
    q.w_to_euler(i, j, k)
}

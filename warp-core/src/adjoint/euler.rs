//! Adjoints of `quat_from_euler` and `quat_to_euler` ([`crate::builtins::euler`]): the
//! reverse of their steps, in the order written (the CUDA mirror, `wp_adjoint_linalg.h`, does
//! the same steps). `g` is `adj_ret`; the integer axis indices get no adjoint.
//!
//! * `quat_from_euler(e, i, j, k)`, forward `q = q_k * (q_j * q_i)`: the Hamilton product's
//!   adjoint of `q_k * t` with `g`, then of `q_j * q_i` with `t`'s; then for `n = k, j, i`
//!   the half angle's adjoint `adj_h_n` from `adj_cos(h_n)` with the `w` lane's and
//!   `adj_sin(h_n)` with the axis lane's, and `adj_e[axis(n)] += 0.5 adj_h_n` (lanes of `e`
//!   collected first, then added `x, y, z`).
//! * `quat_to_euler(q, i, j, k)`: each result lane's adjoint to the angle its slot holds
//!   (lanes `x, y, z` in order); for a Tait-Bryan sequence `adj_θ3 *= ε` (the `-π/2` shift has
//!   none); on the branch near `θ2 = 0` `adj_θ+ = 2 adj_θ3`, near `π` `adj_θ- = 2 adj_θ3`
//!   (`θ1 = 0` there: its adjoint is dropped), else `adj_θ+ = adj_θ3 + adj_θ1`,
//!   `adj_θ- = adj_θ3 - adj_θ1`; `adj_atan2(d, c)` with `adj_θ-`, `adj_atan2(b, a)` with
//!   `adj_θ+`, `adj_acos` of `quo - 1` with `adj_θ2` (nothing where it is clamped or at `±1`,
//!   as the builtin's); through `quo = (2 s) / n`, `n = s + c² + d²`, `s = a² + b²`:
//!   `adj_n = -(adj_quo quo) / n`, `adj_s = 2 (adj_quo / n) + adj_n`, `adj_c += 2 c adj_n`,
//!   `adj_d += 2 d adj_n`, `adj_a += 2 a adj_s`, `adj_b += 2 b adj_s`; then, for a Tait-Bryan
//!   sequence, `q_i -= adj_d`, `q0 += adj_c`, `q_k += ε adj_b`, `q_j -= adj_a`; then
//!   `q_k += ε adj_d`, `q_j += adj_c`, `q_i += adj_b`, `q0 += adj_a` (lanes of
//!   `(w, x, y, z)` collected first, then added `x, y, z, w`).

use glam::{DQuat, DVec3, Quat, Vec3};

use super::builtins::{adj_acos, adj_atan2, adj_cos, adj_sin};
use super::ops::AdjMul;
use crate::builtins::euler::{from_euler_f32, from_euler_f64, to_euler_f32, to_euler_f64};
use crate::builtins::euler::{EulerAngles, EulerOps};

/// Adjoints of `quat_from_euler`, `quat_to_euler`: [`Quat`], [`DQuat`].
pub trait AdjEuler: EulerOps {
    /// See [`adj_quat_from_euler`].
    fn adj_from_euler(e: Self::V3, i: i32, j: i32, k: i32, adj_e: &mut Self::V3, g: Self);
    /// See [`adj_quat_to_euler`].
    fn adj_to_euler(q: Self, i: i32, j: i32, k: i32, adj_q: &mut Self, g: Self::V3);
}

/// Adjoint of `quat_from_euler(e, i, j, k)` (see the module documentation).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn adj_quat_from_euler<V: EulerAngles>(
    e: V,
    i: i32,
    j: i32,
    k: i32,
    adj_e: &mut V,
    _adj_i: &mut i32,
    _adj_j: &mut i32,
    _adj_k: &mut i32,
    adj_ret: V::Q,
) where
    V::Q: AdjEuler,
{
    V::Q::adj_from_euler(e, i, j, k, adj_e, adj_ret)
}

/// Adjoint of `quat_to_euler(q, i, j, k)` (see the module documentation).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn adj_quat_to_euler<Q: AdjEuler>(
    q: Q,
    i: i32,
    j: i32,
    k: i32,
    adj_q: &mut Q,
    _adj_i: &mut i32,
    _adj_j: &mut i32,
    _adj_k: &mut i32,
    adj_ret: Q::V3,
) {
    Q::adj_to_euler(q, i, j, k, adj_q, adj_ret)
}

macro_rules! euler_adj {
    ($($q:ident, $v3:ident, $s:ident, $from:ident, $to:ident);*) => {$(
        impl AdjEuler for $q {
            fn adj_from_euler(e: $v3, i: i32, j: i32, k: i32, adj_e: &mut $v3, g: $q) {
                let p = $from(e, i, j, k);
                let [qi, qj, qk] = p.q.map($q::from_array);
                let t = qj * qi;
                let zero = $q::from_xyzw(0.0, 0.0, 0.0, 0.0);
                let (mut gqk, mut gt) = (zero, zero);
                <$q as AdjMul>::adj_mul(qk, t, &mut gqk, &mut gt, g);
                let (mut gqj, mut gqi) = (zero, zero);
                <$q as AdjMul>::adj_mul(qj, qi, &mut gqj, &mut gqi, gt);
                let gq = [gqi.to_array(), gqj.to_array(), gqk.to_array()];
                let mut ge: [$s; 3] = [0.0; 3];
                for n in [2, 1, 0] {
                    let mut gh: $s = 0.0;
                    adj_cos(p.h[n], &mut gh, gq[n][3]);
                    adj_sin(p.h[n], &mut gh, gq[n][p.ax[n]]);
                    ge[p.ax[n]] += 0.5 * gh;
                }
                adj_e.x += ge[0];
                adj_e.y += ge[1];
                adj_e.z += ge[2];
            }

            fn adj_to_euler(q: $q, i: i32, j: i32, k: i32, adj_q: &mut $q, g: $v3) {
                let p = $to(q, i, j, k);
                let mut gt: [$s; 3] = [0.0; 3];
                for (lane, gl) in g.to_array().into_iter().enumerate() {
                    gt[p.slot[lane]] += gl;
                }
                let (g1, g2, mut g3) = (gt[0], gt[1], gt[2]);
                if p.not_proper {
                    g3 *= p.e;
                }
                let (mut gtp, mut gtm): ($s, $s) = (0.0, 0.0);
                match p.branch {
                    0 => gtp += 2.0 * g3,
                    1 => gtm += 2.0 * g3,
                    _ => {
                        gtp += g3;
                        gtm += g3;
                        gtp += g1;
                        gtm -= g1;
                    }
                }
                let (mut ga, mut gb, mut gc, mut gd): ($s, $s, $s, $s) = (0.0, 0.0, 0.0, 0.0);
                adj_atan2(p.d, p.c, &mut gd, &mut gc, gtm);
                adj_atan2(p.b, p.a, &mut gb, &mut ga, gtp);
                let mut gquo: $s = 0.0;
                adj_acos(p.quo - 1.0, &mut gquo, g2);
                let gn = -(gquo * p.quo) / p.n;
                let gs = 2.0 * (gquo / p.n) + gn;
                gc += 2.0 * p.c * gn;
                gd += 2.0 * p.d * gn;
                ga += 2.0 * p.a * gs;
                gb += 2.0 * p.b * gs;
                // Lanes of (w, x, y, z).
                let mut gl: [$s; 4] = [0.0; 4];
                if p.not_proper {
                    gl[p.pi] -= gd;
                    gl[0] += gc;
                    gl[p.pk] += p.e * gb;
                    gl[p.pj] -= ga;
                }
                gl[p.pk] += p.e * gd;
                gl[p.pj] += gc;
                gl[p.pi] += gb;
                gl[0] += ga;
                adj_q.x += gl[1];
                adj_q.y += gl[2];
                adj_q.z += gl[3];
                adj_q.w += gl[0];
            }
        }
    )*};
}
euler_adj!(
    Quat, Vec3, f32, from_euler_f32, to_euler_f32;
    DQuat, DVec3, f64, from_euler_f64, to_euler_f64
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtins::euler::{quat_from_euler, quat_to_euler};

    const SEQS: [[i32; 3]; 12] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
        [0, 1, 0],
        [0, 2, 0],
        [1, 0, 1],
        [1, 2, 1],
        [2, 0, 2],
        [2, 1, 2],
    ];

    fn aa(axis: i32, a: f64) -> DQuat {
        DQuat::from_axis_angle(DVec3::AXES[axis as usize], a)
    }

    /// The angles rebuild the rotation: `q_k(θ3) q_j(θ2) q_i(θ1)` (proper: `k = i`), with
    /// `θ1` at slot `i`, `θ2` at `j`, `θ3` at the third axis of a proper sequence or at `k`.
    #[test]
    fn angles_rebuild_the_rotation() {
        let q = DQuat::from_xyzw(0.3, -0.5, 0.2, 0.7).normalize();
        for [i, j, k] in SEQS {
            let e = quat_to_euler(q, i, j, k);
            let m = if i == k { 3 - i - j } else { k };
            let (t1, t2, t3) = (e[i as usize], e[j as usize], e[m as usize]);
            let r = aa(k, t3) * aa(j, t2) * aa(i, t1);
            let err = (r - q).length().min((r + q).length());
            assert!(err < 1e-14, "{:?}: {e:?} err {err:e}", [i, j, k]);
        }
    }

    /// The adjoints against central differences (f64, h = 1e-6; smooth functions of O(1)
    /// inputs away from gimbal lock: truncation and rounding about 1e-9, tolerance 1e-7).
    #[test]
    fn adjoints_match_central_differences() {
        let h = 1e-6;
        let w = DVec3::new(0.4, 0.9, -0.6);
        let wq = DQuat::from_xyzw(0.3, -0.5, 0.2, 0.7);
        for [i, j, k] in SEQS {
            let e = DVec3::new(0.3, 0.8, -0.4);
            let mut ge = DVec3::ZERO;
            let (mut a, mut b, mut c) = (0, 0, 0);
            adj_quat_from_euler(e, i, j, k, &mut ge, &mut a, &mut b, &mut c, wq);
            for l in 0..3 {
                let mut d = DVec3::ZERO;
                d[l] = h;
                let f = |x: DVec3| quat_from_euler(x, i, j, k).dot(wq);
                let fd = (f(e + d) - f(e - d)) / (2.0 * h);
                assert!(
                    (ge[l] - fd).abs() < 1e-7,
                    "from {:?} lane {l}: {} vs {fd}",
                    [i, j, k],
                    ge[l]
                );
            }
            let q = DQuat::from_xyzw(0.35, -0.45, 0.25, 0.8);
            let mut gq = DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
            adj_quat_to_euler(q, i, j, k, &mut gq, &mut a, &mut b, &mut c, w);
            for l in 0..4 {
                let mut d = [0.0; 4];
                d[l] = h;
                let d = DQuat::from_array(d);
                let f = |x: DQuat| quat_to_euler(x, i, j, k).dot(w);
                let fd = (f(q + d) - f(q - d)) / (2.0 * h);
                let g = gq.to_array()[l];
                assert!(
                    (g - fd).abs() < 1e-7,
                    "to {:?} lane {l}: {g} vs {fd}",
                    [i, j, k]
                );
            }
        }
    }
}

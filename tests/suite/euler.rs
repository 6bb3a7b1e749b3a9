//! `quat_from_euler` and `quat_to_euler` (Warp's `@wp.func`s of math.py, builtins here): Warp's
//! own expectations (`warp/tests/test_math.py`: `quat_helpers`, `quat_euler_roundtrip`),
//! closed forms in f64 (the product of axis-angle quaternions; the round trip for every
//! Tait-Bryan sequence), warp-core's functions (bit for bit on the CPU, [`gpu_tol`] on CUDA),
//! the gimbal-lock branches and non-finite inputs, and gradcheck in f64 away from gimbal lock.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::__private::builtins as bi;
use wp::prelude::*;

backend_tests!(
    euler_warp_expectations_f32,
    euler_closed_forms_f64,
    euler_singular_and_nonfinite,
    euler_gradients_match_finite_differences,
);

/// The six Tait-Bryan sequences (Warp's `TAIT_BRYAN_SEQUENCES` order) and the six proper ones.
const TAIT_BRYAN: [[i32; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];
const PROPER: [[i32; 3]; 6] = [
    [0, 1, 0],
    [0, 2, 0],
    [1, 0, 1],
    [1, 2, 1],
    [2, 0, 2],
    [2, 1, 2],
];

/// Backend parity: 0 on the CPU (the kernel calls warp-core's functions); on CUDA its libm
/// (sin, cos, acos, atan2 within 2 to 4 ulp) and FMA contraction: a few ulp of angles and
/// lanes of size <= 4, so 1e-5 in f32 and 1e-13 in f64, with margin.
fn gpu_tol(dev: &wp::Device, f32: bool) -> f64 {
    match (dev.is_cpu(), f32) {
        (true, _) => 0.0,
        (false, true) => 1e-5,
        (false, false) => 1e-13,
    }
}

/// `min(|a - b|, |a + b|)` over the four lanes (Warp's `quat_sign_invariant_error`).
fn qerr(a: DQuat, b: DQuat) -> f64 {
    (a - b).length().min((a + b).length())
}

#[wp::kernel]
pub(crate) fn k_euler32(
    e: Array<Vec3>,
    q: Array<Quat>,
    seq: Array<i32>,
    qo: Array<Quat>,
    eo: Array<Vec3>,
) {
    let n = tid();
    let i = seq[n * 3];
    let j = seq[n * 3 + 1];
    let k = seq[n * 3 + 2];
    qo[n] = quat_from_euler(e[n], i, j, k);
    eo[n] = quat_to_euler(q[n], i, j, k);
}

#[wp::kernel]
pub(crate) fn k_euler64(
    e: Array<DVec3>,
    q: Array<DQuat>,
    seq: Array<i32>,
    qo: Array<DQuat>,
    eo: Array<DVec3>,
) {
    let n = tid();
    let i = seq[n * 3];
    let j = seq[n * 3 + 1];
    let k = seq[n * 3 + 2];
    qo[n] = quat_from_euler(e[n], i, j, k);
    eo[n] = quat_to_euler(q[n], i, j, k);
}

/// Literal axis indices (Warp writes them so): `quat_from_euler(e, 2, 1, 0)`.
#[wp::kernel]
pub(crate) fn k_euler_literals(e: Array<Vec3>, qo: Array<Quat>, eo: Array<Vec3>) {
    let q = quat_from_euler(e[0], 2, 1, 0);
    qo[0] = q;
    eo[0] = quat_to_euler(q, 2, 1, 0);
}

fn run32(dev: &wp::Device, e: &[Vec3], q: &[Quat], seq: &[[i32; 3]]) -> (Vec<Quat>, Vec<Vec3>) {
    let n = e.len();
    let s: Vec<i32> = seq.concat();
    let (qo, eo) = (zeros::<Quat, 1>(n, dev), zeros::<Vec3, 1>(n, dev));
    wp::launch(
        k_euler32,
        n,
        (&arr(e, dev), &arr(q, dev), &arr(&s, dev), &qo, &eo),
        dev,
    )
    .unwrap();
    (host(&qo), host(&eo))
}

fn run64(dev: &wp::Device, e: &[DVec3], q: &[DQuat], seq: &[[i32; 3]]) -> (Vec<DQuat>, Vec<DVec3>) {
    let n = e.len();
    let s: Vec<i32> = seq.concat();
    let (qo, eo) = (zeros::<DQuat, 1>(n, dev), zeros::<DVec3, 1>(n, dev));
    wp::launch(
        k_euler64,
        n,
        (&arr(e, dev), &arr(q, dev), &arr(&s, dev), &qo, &eo),
        dev,
    )
    .unwrap();
    (host(&qo), host(&eo))
}

/// Warp's `quat_helpers` and `quat_euler_roundtrip` cases, in f32 with Warp's tolerances
/// (1e-5 and, for the round trips near gimbal lock, 1e-4).
fn euler_warp_expectations_f32(dev: &wp::Device) {
    let q = |x: Quat| x.as_dquat();
    // quat_from_euler((0.4, -0.2, 0.3), 2, 1, 0), Warp's printed value.
    let e = [Vec3::new(0.4, -0.2, 0.3)];
    let (qo, eo) = {
        let (qo_, eo_) = (zeros::<Quat, 1>(1, dev), zeros::<Vec3, 1>(1, dev));
        wp::launch(k_euler_literals, 1, (&arr(&e, dev), &qo_, &eo_), dev).unwrap();
        (host(&qo_), host(&eo_))
    };
    let want = DQuat::from_xyzw(0.18083558, -0.12628517, 0.12611651, 0.96718415);
    assert!(qerr(q(qo[0]), want) < 1e-5, "zyx: {:?}", qo[0]);
    // and back: the same angles (a Tait-Bryan sequence away from gimbal lock).
    assert!((eo[0] - e[0]).length() < 1e-5, "zyx back: {:?}", eo[0]);
    // Round trips, the single-axis case, the decomposition of a compound rotation.
    let ex = Vec3::new(0.2, -0.1, 0.3);
    let qx = Quat::from_axis_angle(Vec3::X, ex.x);
    let cases_e = [ex, Vec3::new(0.25, -0.4, 0.15), Vec3::new(ex.x, 0.0, 0.0)];
    let seqs = [[0, 1, 2], [1, 0, 2], [0, 1, 2]];
    let (qs, _) = run32(dev, &cases_e, &[Quat::IDENTITY; 3], &seqs);
    let (_, back) = run32(dev, &[Vec3::ZERO; 3], &qs, &seqs);
    let (qb, _) = run32(dev, &back, &[Quat::IDENTITY; 3], &seqs);
    assert!(qerr(q(qb[0]), q(qs[0])) < 1e-5, "xyz round trip");
    assert!(qerr(q(qb[1]), q(qs[1])) < 1e-5, "yxz round trip");
    assert!(
        (q(qs[2]) - q(qx)).length() < 1e-5,
        "single axis = from_axis_angle"
    );
    let (_, dec) = run32(dev, &[Vec3::ZERO], &[qx], &[[2, 1, 0]]);
    assert!(
        (dec[0] - Vec3::new(ex.x, 0.0, 0.0)).length() < 1e-5,
        "zyx of an x rotation"
    );
    // Every Tait-Bryan sequence, and e[j] near +-pi/2 (1e-4 from gimbal lock).
    let half_pi = std::f32::consts::FRAC_PI_2;
    for d in [None, Some(half_pi - 1e-4), Some(-half_pi + 1e-4)] {
        let es: Vec<Vec3> = TAIT_BRYAN
            .iter()
            .map(|s| {
                let mut e = Vec3::new(0.31, -0.27, 0.41);
                if let Some(d) = d {
                    e[s[1] as usize] = d;
                }
                e
            })
            .collect();
        let (qs, _) = run32(dev, &es, &[Quat::IDENTITY; 6], &TAIT_BRYAN);
        let (_, back) = run32(dev, &[Vec3::ZERO; 6], &qs, &TAIT_BRYAN);
        let (qb, _) = run32(dev, &back, &[Quat::IDENTITY; 6], &TAIT_BRYAN);
        for (s, seq) in TAIT_BRYAN.iter().enumerate() {
            let tol = if d.is_some() { 1e-4 } else { 1e-5 };
            assert!(
                qerr(q(qb[s]), q(qs[s])) < tol,
                "round trip {seq:?} at {d:?}: {:?} -> {:?}",
                qs[s],
                qb[s]
            );
        }
    }
    // Gimbal lock exactly: e = (0.6, pi/2, 0.2) about (2, 1, 0) comes back as the same rotation.
    let (qs, _) = run32(
        dev,
        &[Vec3::new(0.6, half_pi, 0.2)],
        &[Quat::IDENTITY],
        &[[2, 1, 0]],
    );
    let (_, back) = run32(dev, &[Vec3::ZERO], &qs, &[[2, 1, 0]]);
    let (qb, _) = run32(dev, &back, &[Quat::IDENTITY], &[[2, 1, 0]]);
    assert!(back[0].is_finite(), "gimbal angles {:?}", back[0]);
    assert!(qerr(q(qb[0]), q(qs[0])) < 1e-5, "gimbal round trip");
}

/// Angles of size <= 1.2 (the middle one in (-1.2, 1.2) for Tait-Bryan, shifted into
/// (0.37, 2.77) for proper sequences: away from gimbal lock).
fn angles(n: usize, proper: bool) -> Vec<DVec3> {
    let r = |k: f64| ((k * 12.9898).sin() * 43758.5453).fract() * 1.2;
    (0..n)
        .map(|s| {
            let k = s as f64 * 3.0;
            let mut e = DVec3::new(r(k), r(k + 1.0), r(k + 2.0));
            if proper {
                e[PROPER[s][1] as usize] = e[PROPER[s][1] as usize].abs() + 0.37;
                e[PROPER[s][1] as usize] += 0.2 * (s as f64);
            }
            e
        })
        .collect()
}

/// f64: `quat_from_euler` is `q_k * q_j * q_i` of glam's axis-angle quaternions (the same
/// formula in another order: 1e-15 of unit lanes, 1e-14 with margin); `quat_to_euler` of it
/// gives the angles back for every Tait-Bryan sequence (1e-13: `acos` near its ends loses
/// digits); for the proper sequences the angles rebuild the rotation as `q_i(θ3) q_j(θ2)
/// q_i(θ1)`; both against warp-core.
fn euler_closed_forms_f64(dev: &wp::Device) {
    let gt = gpu_tol(dev, false);
    let aa = |axis: i32, a: f64| DQuat::from_axis_angle(DVec3::AXES[axis as usize], a);
    for (seqs, proper) in [(TAIT_BRYAN, false), (PROPER, true)] {
        let es = angles(6, proper);
        let (qs, _) = run64(dev, &es, &[DQuat::IDENTITY; 6], &seqs);
        let (_, back) = run64(dev, &[DVec3::ZERO; 6], &qs, &seqs);
        for (s, &[i, j, k]) in seqs.iter().enumerate() {
            let e = es[s];
            let want = aa(k, e[k as usize]) * aa(j, e[j as usize]) * aa(i, e[i as usize]);
            assert!(
                (qs[s] - want).length() < 1e-14,
                "{:?}: {:?} vs {want:?}",
                seqs[s],
                qs[s]
            );
            let host_q = bi::quat_from_euler(e, i, j, k);
            assert!((qs[s] - host_q).length() <= gt, "{:?} host", seqs[s]);
            let host_e = bi::quat_to_euler(qs[s], i, j, k);
            assert!((back[s] - host_e).length() <= gt, "{:?} host back", seqs[s]);
            if !proper {
                assert!(
                    (back[s] - e).length() < 1e-13,
                    "{:?}: {:?} vs {e:?}",
                    seqs[s],
                    back[s]
                );
            } else {
                // Slots: θ1 at i, θ2 at j, θ3 at the third axis 3 - i - j.
                let m = (3 - i - j) as usize;
                let (t1, t2, t3) = (back[s][i as usize], back[s][j as usize], back[s][m]);
                let rebuilt = aa(i, t3) * aa(j, t2) * aa(i, t1);
                assert!(qerr(rebuilt, qs[s]) < 1e-13, "{:?}: {:?}", seqs[s], back[s]);
            }
        }
    }
}

/// The gimbal-lock branches (Tait-Bryan middle angle exactly `±pi/2`, proper middle angle 0
/// and `pi`): finite angles that rebuild the rotation; non-finite inputs: a NaN lane or an
/// infinite angle gives NaN everywhere (`acos`, `atan2` and `sin` of them are NaN and every
/// output lane depends on them), not a panic or a fault.
fn euler_singular_and_nonfinite(dev: &wp::Device) {
    let h = std::f64::consts::FRAC_PI_2;
    let pi = std::f64::consts::PI;
    let es = [
        DVec3::new(0.6, h, 0.2),
        DVec3::new(0.3, -h, -0.5),
        DVec3::new(0.4, 0.0, 0.7),
        DVec3::new(0.4, pi, 0.7),
    ];
    let seqs = [[2, 1, 0], [0, 1, 2], [0, 1, 0], [0, 1, 0]];
    let (qs, _) = run64(dev, &es, &[DQuat::IDENTITY; 4], &seqs);
    let (_, back) = run64(dev, &[DVec3::ZERO; 4], &qs, &seqs);
    for (s, &[i, j, k]) in seqs.iter().enumerate() {
        assert!(back[s].is_finite(), "{:?}: {:?}", es[s], back[s]);
        let m = if i == k {
            (3 - i - j) as usize
        } else {
            k as usize
        };
        let aa = |axis: i32, a: f64| DQuat::from_axis_angle(DVec3::AXES[axis as usize], a);
        let (t1, t2, t3) = (back[s][i as usize], back[s][j as usize], back[s][m]);
        let rebuilt = if i == k {
            aa(i, t3) * aa(j, t2) * aa(i, t1)
        } else {
            aa(k, t3) * aa(j, t2) * aa(i, t1)
        };
        // Within the 1e-6 branch the first angle is set to 0 and the third takes the rest:
        // the rotation is kept up to the angle error the threshold admits (~1e-6).
        assert!(qerr(rebuilt, qs[s]) < 1e-5, "{:?}: {:?}", es[s], back[s]);
    }
    let nan_q = DQuat::from_xyzw(f64::NAN, 0.0, 0.0, 1.0);
    let inf_e = DVec3::new(f64::INFINITY, 0.1, 0.2);
    let (qo, eo) = run64(dev, &[inf_e], &[nan_q], &[[0, 1, 2]]);
    assert!(
        qo[0].to_array().iter().all(|x| x.is_nan()),
        "inf angle: {:?}",
        qo[0]
    );
    assert!(
        eo[0].to_array().iter().all(|x| x.is_nan()),
        "NaN quaternion: {:?}",
        eo[0]
    );
}

/// A loss through both builtins, nonlinear in the angles and in the quaternion's lanes (not
/// unit: `quat_to_euler` is invariant to `q`'s scale, and its gradient is checked off the
/// unit sphere too).
#[wp::kernel]
pub(crate) fn k_euler_loss(x: Array<f64>, seq: Array<i32>, loss: Array<f64>) {
    let n = tid();
    let o = n * 7;
    let i = seq[n * 3];
    let j = seq[n * 3 + 1];
    let k = seq[n * 3 + 2];
    let e = DVec3::new(x[o], x[o + 1], x[o + 2]);
    let q = DQuat::from_xyzw(x[o + 3], x[o + 4], x[o + 5], x[o + 6]);
    let p = quat_from_euler(e, i, j, k);
    let a = quat_to_euler(q, i, j, k);
    let b = quat_to_euler(p * q, i, j, k);
    loss[n] = p.dot(DQuat::from_xyzw(0.3, -0.5, 0.2, 0.7))
        + a.dot(DVec3::new(0.4, 0.9, -0.6))
        + b.dot(b) * 0.25;
}

/// `gradcheck` in f64 (central differences, step 1e-6) on every Tait-Bryan and proper
/// sequence, at inputs checked here to be away from gimbal lock (the middle angle at least
/// 0.2 from the singular values, where the angles' second derivatives are below ~1e2): the
/// truncation error is below 1e2 · 1e-12 and rounding about 1e-16 · 10 / 1e-6 = 1e-9, so
/// atol = rtol = 1e-6 has margin and would miss no wrong rule (those are O(1) wrong).
fn euler_gradients_match_finite_differences(dev: &wp::Device) {
    let seqs: Vec<[i32; 3]> = TAIT_BRYAN.iter().chain(PROPER.iter()).copied().collect();
    let n = seqs.len();
    let r = |k: f64| ((k * 78.233).sin() * 43758.5453).fract();
    // Away from gimbal lock: the middle angle of a, b and p's own, computed on the host; each
    // sequence takes the first of its candidate inputs that clears the margin.
    let clear = |s: usize, x: &[f64]| {
        let [i, j, k] = seqs[s];
        let e = DVec3::new(x[0], x[1], x[2]);
        let q = DQuat::from_xyzw(x[3], x[4], x[5], x[6]);
        let p = bi::quat_from_euler(e, i, j, k);
        [q, p * q].into_iter().all(|qq| {
            let t2 = bi::quat_to_euler(qq, i, j, k)[j as usize];
            let (lo, hi) = if i == k {
                (0.0, std::f64::consts::PI)
            } else {
                (-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2)
            };
            t2 - lo > 0.2 && hi - t2 > 0.2
        })
    };
    let mut xs: Vec<f64> = Vec::with_capacity(n * 7);
    for s in 0..n {
        let x = (0..64)
            .map(|t| -> Vec<f64> {
                (0..7)
                    .map(|c| r((s * 7 + c + 1000 * t) as f64) * 1.4 - 0.7)
                    .collect()
            })
            .find(|x| clear(s, x))
            .unwrap_or_else(|| panic!("no input for sequence {s} clears gimbal lock"));
        xs.extend(x);
    }
    let x = arr(&xs, dev).with_grad().unwrap();
    let sq: Vec<i32> = seqs.concat();
    let sq = arr(&sq, dev);
    let loss = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_euler_loss, n, (&x, &sq, &loss), dev),
        &[&x],
        &[&loss],
        wp::GradcheckOptions {
            eps: 1e-6,
            atol: 1e-6,
            rtol: 1e-6,
        },
    )
    .unwrap();
    assert!(report.passed, "{report:?}");
    // Every input has a gradient but, for a proper sequence (i == k), the angle in the slot of
    // the third axis: `quat_from_euler` reads `e[i]` for both of its i-rotations (Warp's
    // definition), so that slot is not read at all.
    let untouched: Vec<usize> = (0..report.analytic[0].len())
        .filter(|&c| report.analytic.iter().all(|r| r[c] == 0.0))
        .collect();
    let unread: Vec<usize> = (0..n)
        .filter(|&s| seqs[s][0] == seqs[s][2])
        .map(|s| s * 7 + (3 - seqs[s][0] - seqs[s][1]) as usize)
        .collect();
    assert_eq!(untouched, unread, "inputs without a gradient");
}

//! The builtins of the "misc" section (warp-core `builtins::misc`, `wp_misc.h`) on both
//! backends, against independent f64 references (glam's own functions where glam has the
//! operation, formulas written out here otherwise) or closed forms, and their overloads and
//! aliases (`min(v)`, `v.min_element()`, `lower_bound(a, lo, hi, v)`, the norms' default
//! `delta`, `div_approx`, `inverse_approx`, `sample_cdf`).

use crate::{arr, assert_close_f64, host, zeros};
use warp_lang as wp;
use wp::prelude::*;
use wp::{Error, FaultKind};

backend_tests!(
    vector_reductions,
    scalar_and_matrix_builtins,
    norms,
    quaternion_builtins,
    transform_compose_decompose,
    lower_bound_and_sample_cdf,
    lower_bound_faults,
    approximate_operations,
    block_dim_of_the_launch,
);

// ------------------------------------------------------------------------------------------
// One-vector min/max, argmin/argmax (integers and floats, NaN lanes)
// ------------------------------------------------------------------------------------------

#[wp::kernel]
fn k_reduce(
    v: Array<Vec4>,
    iv: Array<IVec3>,
    fo: Array<f32, 2>,
    io: Array<i32, 2>,
    uo: Array<u32, 2>,
) {
    let i = tid();
    let a = v[i];
    let b = iv[i];
    fo[(i, 0)] = min(a);
    fo[(i, 1)] = max(a);
    fo[(i, 2)] = a.min_element();
    fo[(i, 3)] = a.max_element();
    io[(i, 0)] = min(b);
    io[(i, 1)] = b.max_element();
    uo[(i, 0)] = argmin(a);
    uo[(i, 1)] = argmax(a);
    uo[(i, 2)] = argmin(b);
    uo[(i, 3)] = argmax(b);
}

fn vector_reductions(dev: &wp::Device) {
    let nan = f32::NAN;
    let vs = [
        Vec4::new(3.0, -1.0, 2.0, -1.0),
        Vec4::new(nan, 5.0, nan, 7.0),
        Vec4::splat(nan),
        Vec4::new(0.5, 0.5, 0.5, 0.5),
        Vec4::new(-f32::INFINITY, 0.0, f32::INFINITY, 1.0),
    ];
    let ivs = [
        IVec3::new(4, -9, 2),
        IVec3::new(i32::MAX, i32::MIN, 0),
        IVec3::new(7, 7, 7),
        IVec3::new(1, 5, 5),
        IVec3::new(-3, -3, 8),
    ];
    // Warp's rules written out: NaN lanes skipped, the first of equal lanes, 0 if all NaN.
    let want_f: [(f32, f32, u32, u32); 5] = [
        (-1.0, 3.0, 1, 0),
        (5.0, 7.0, 1, 3),
        (nan, nan, 0, 0),
        (0.5, 0.5, 0, 0),
        (-f32::INFINITY, f32::INFINITY, 0, 2),
    ];
    let want_i = [
        [-9, 4, 1, 0],
        [i32::MIN, i32::MAX, 1, 0],
        [7, 7, 0, 0],
        [1, 5, 0, 1],
        [-3, 8, 0, 2],
    ];
    let n = vs.len();
    let (fo, io, uo) = (
        zeros::<f32, 2>((n, 4), dev),
        zeros::<i32, 2>((n, 2), dev),
        zeros::<u32, 2>((n, 4), dev),
    );
    wp::launch(
        k_reduce,
        n,
        (&arr(&vs, dev), &arr(&ivs, dev), &fo, &io, &uo),
        dev,
    )
    .unwrap();
    let (fo, io, uo) = (host(&fo), host(&io), host(&uo));
    for k in 0..n {
        let (mn, mx, am, ax) = want_f[k];
        for (j, w) in [mn, mx, mn, mx].into_iter().enumerate() {
            let g = fo[k * 4 + j];
            assert!(
                g == w || (g.is_nan() && w.is_nan()),
                "row {k} col {j}: {g} vs {w}"
            );
        }
        assert_eq!([uo[k * 4], uo[k * 4 + 1]], [am, ax], "row {k}");
        let [imn, imx, iam, iax] = want_i[k];
        assert_eq!([io[k * 2], io[k * 2 + 1]], [imn, imx], "int row {k}");
        assert_eq!(
            [uo[k * 4 + 2], uo[k * 4 + 3]],
            [iam as u32, iax as u32],
            "int row {k}"
        );
    }
}

// ------------------------------------------------------------------------------------------
// copysign, nonzero, get_diag, classification of quaternions and matrices
// ------------------------------------------------------------------------------------------

#[wp::kernel]
fn k_scalar_matrix(
    x: Array<f64>,
    m: Array<DMat3>,
    q: Array<Quat>,
    so: Array<f64, 2>,
    io: Array<i32, 2>,
    vo: Array<DVec3>,
    bo: Array<i32, 2>,
) {
    let i = tid();
    let a = x[i];
    so[(i, 0)] = copysign(2.5, a);
    so[(i, 1)] = a.copysign(-1.0);
    so[(i, 2)] = nonzero(a);
    io[(i, 0)] = nonzero(i as i32 - 1);
    vo[i] = get_diag(m[i]);
    let mm = m[i];
    let qq = q[i];
    bo[(i, 0)] = if isfinite(mm) { 1 } else { 0 };
    bo[(i, 1)] = if isnan(mm) { 1 } else { 0 };
    bo[(i, 2)] = if mm.is_infinite() { 1 } else { 0 };
    bo[(i, 3)] = if qq.is_finite() { 1 } else { 0 };
    bo[(i, 4)] = if isnan(qq) { 1 } else { 0 };
    bo[(i, 5)] = if isinf(qq) { 1 } else { 0 };
}

fn scalar_and_matrix_builtins(dev: &wp::Device) {
    let xs = [-3.0f64, 0.0, -0.0, f64::NAN];
    let ms = [
        DMat3::from_cols(
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(4.0, 5.0, 6.0),
            DVec3::new(7.0, 8.0, 9.0),
        ),
        DMat3::from_diagonal(DVec3::new(f64::NAN, 1.0, 2.0)),
        DMat3::from_cols(DVec3::ZERO, DVec3::new(0.0, f64::INFINITY, 0.0), DVec3::Z),
        DMat3::IDENTITY,
    ];
    let qs = [
        Quat::IDENTITY,
        Quat::from_xyzw(0.0, f32::NAN, 0.0, 1.0),
        Quat::from_xyzw(f32::NEG_INFINITY, 0.0, 0.0, 1.0),
        Quat::from_xyzw(f32::NAN, f32::INFINITY, 0.0, 1.0),
    ];
    let n = xs.len();
    let so = zeros::<f64, 2>((n, 3), dev);
    let io = zeros::<i32, 2>((n, 1), dev);
    let vo = zeros::<DVec3, 1>(n, dev);
    let bo = zeros::<i32, 2>((n, 6), dev);
    wp::launch(
        k_scalar_matrix,
        n,
        (
            &arr(&xs, dev),
            &arr(&ms, dev),
            &arr(&qs, dev),
            &so,
            &io,
            &vo,
            &bo,
        ),
        dev,
    )
    .unwrap();
    let (so, io, vo, bo) = (host(&so), host(&io), host(&vo), host(&bo));
    for k in 0..n {
        let x = xs[k];
        assert_eq!(
            so[k * 3].to_bits(),
            2.5f64.copysign(x).to_bits(),
            "copysign {x}"
        );
        assert_eq!(
            so[k * 3 + 1].to_bits(),
            x.copysign(-1.0).to_bits(),
            "method {x}"
        );
        assert_eq!(
            so[k * 3 + 2],
            if x != 0.0 { 1.0 } else { 0.0 },
            "nonzero {x}"
        );
        assert_eq!(io[k], if k == 1 { 0 } else { 1 });
        let d = DVec3::new(ms[k].x_axis.x, ms[k].y_axis.y, ms[k].z_axis.z);
        assert!(
            vo[k] == d || (k == 1 && vo[k].x.is_nan() && (vo[k].y, vo[k].z) == (d.y, d.z)),
            "{k}"
        );
        let m = ms[k].to_cols_array();
        let q = qs[k].to_array();
        let want = [
            m.iter().all(|v| v.is_finite()),
            m.iter().any(|v| v.is_nan()),
            m.iter().any(|v| v.is_infinite()),
            q.iter().all(|v| v.is_finite()),
            q.iter().any(|v| v.is_nan()),
            q.iter().any(|v| v.is_infinite()),
        ];
        for (j, w) in want.into_iter().enumerate() {
            assert_eq!(bo[k * 6 + j], w as i32, "row {k} classification {j}");
        }
    }
}

// ------------------------------------------------------------------------------------------
// Norms (Warp's math.py formulas written out in f64 here)
// ------------------------------------------------------------------------------------------

#[wp::kernel]
fn k_norms(v: Array<DVec3>, d: f64, so: Array<f64, 2>, vo: Array<DVec3, 2>) {
    let i = tid();
    let a = v[i];
    so[(i, 0)] = norm_l1(a);
    so[(i, 1)] = norm_l2(a);
    so[(i, 2)] = norm_huber(a, d);
    so[(i, 3)] = norm_huber(a);
    so[(i, 4)] = norm_pseudo_huber(a, d);
    so[(i, 5)] = norm_pseudo_huber(a);
    vo[(i, 0)] = smooth_normalize(a, d);
    vo[(i, 1)] = smooth_normalize(a);
}

fn huber(v: DVec3, d: f64) -> f64 {
    let l = v.length();
    if l <= d {
        0.5 * l * l
    } else {
        d * (l - 0.5 * d)
    }
}

fn pseudo_huber(v: DVec3, d: f64) -> f64 {
    (d * d + v.length_squared()).sqrt()
}

/// Tolerance 1e-14 relative: a handful of roundings of numbers of size ~1 (the references
/// use other, algebraically equal, formulas).
fn norms(dev: &wp::Device) {
    let vs = [
        DVec3::new(3.0, -4.0, 0.0),
        DVec3::new(0.1, 0.2, -0.05),
        DVec3::ZERO,
        DVec3::new(-1.5, 2.5, 0.7),
    ];
    let d = 1.7;
    let n = vs.len();
    let (so, vo) = (zeros::<f64, 2>((n, 6), dev), zeros::<DVec3, 2>((n, 2), dev));
    wp::launch(k_norms, n, (&arr(&vs, dev), d, &so, &vo), dev).unwrap();
    let (so, vo) = (host(&so), host(&vo));
    for (k, &v) in vs.iter().enumerate() {
        let want = [
            v.x.abs() + v.y.abs() + v.z.abs(),
            v.length(),
            huber(v, d),
            huber(v, 1.0),
            pseudo_huber(v, d),
            pseudo_huber(v, 1.0),
        ];
        for (j, w) in want.into_iter().enumerate() {
            assert_close_f64(so[k * 6 + j], w, 1e-14, &format!("norm {j} of {v}"));
        }
        for (j, dd) in [d, 1.0].into_iter().enumerate() {
            let w = v / pseudo_huber(v, dd);
            assert!(
                (vo[k * 2 + j] - w).length() <= 1e-14,
                "smooth_normalize {v} {dd}"
            );
        }
    }
}

// ------------------------------------------------------------------------------------------
// Quaternions: axis-angle, roll-pitch-yaw, twist
// ------------------------------------------------------------------------------------------

#[wp::kernel]
pub(crate) fn k_quats(
    q: Array<DQuat>,
    e: Array<DVec3>,
    axis: DVec3,
    vo: Array<DVec3, 2>,
    so: Array<f64, 2>,
    qo: Array<DQuat, 2>,
) {
    let i = tid();
    let (ax, angle) = quat_to_axis_angle(q[i]);
    vo[(i, 0)] = ax;
    so[(i, 0)] = angle;
    vo[(i, 1)] = quat_to_rpy(q[i]);
    let r = e[i];
    qo[(i, 0)] = quat_rpy(r.x, r.y, r.z);
    qo[(i, 1)] = quat_twist(axis, q[i]);
    so[(i, 1)] = quat_twist_angle(axis, q[i]);
    so[(i, 2)] = quat_twist_angle_signed(axis, q[i]);
}

/// References: glam's `to_axis_angle` and `from_euler` (its `EulerRot::XYZ` is Warp's
/// roll-pitch-yaw up to the order of composition, written out here as `z * y * x`), and the
/// twist as the projection onto the axis written in f64. Tolerance 1e-13 (a few roundings and
/// libm's or libdevice's sin/cos/atan2 within a few ulp).
fn quaternion_builtins(dev: &wp::Device) {
    let qs = [
        DQuat::from_axis_angle(DVec3::new(0.0, 0.6, 0.8), 1.1),
        DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -2.0).normalize(), -2.5),
        DQuat::from_xyzw(0.1, -0.3, 0.2, -0.9).normalize(), // w < 0: the axis flips
        DQuat::IDENTITY,
    ];
    let es = [
        DVec3::new(0.1, -0.2, 0.3),
        DVec3::new(1.2, 0.4, -2.0),
        DVec3::new(-0.5, 1.0, 3.0),
        DVec3::ZERO,
    ];
    let axis = DVec3::new(0.0, 0.6, 0.8);
    let n = qs.len();
    let vo = zeros::<DVec3, 2>((n, 2), dev);
    let so = zeros::<f64, 2>((n, 3), dev);
    let qo = zeros::<DQuat, 2>((n, 2), dev);
    wp::launch(
        k_quats,
        n,
        (&arr(&qs, dev), &arr(&es, dev), axis, &vo, &so, &qo),
        dev,
    )
    .unwrap();
    let (vo, so, qo) = (host(&vo), host(&so), host(&qo));
    let tol = 1e-13;
    for k in 0..n {
        let q = qs[k];
        // Axis-angle: the rotation it names is q's (up to the sign of q).
        let (ax, angle) = (vo[k * 2], so[k * 3]);
        let back = DQuat::from_axis_angle(ax, angle);
        assert!(
            (back.dot(q).abs() - 1.0).abs() < tol,
            "axis-angle of {q}: {ax} {angle}"
        );
        assert!(
            (0.0..=std::f64::consts::PI + tol).contains(&angle),
            "{angle}"
        );
        if q == DQuat::IDENTITY {
            assert_eq!((ax, angle), (DVec3::ZERO, 0.0));
        }
        // Roll-pitch-yaw: extrinsic x, then y, then z.
        let e = es[k];
        let want = DQuat::from_axis_angle(DVec3::Z, e.z)
            * DQuat::from_axis_angle(DVec3::Y, e.y)
            * DQuat::from_axis_angle(DVec3::X, e.x);
        assert!(
            (qo[k * 2] - want).length() < tol,
            "quat_rpy {e}: {} vs {want}",
            qo[k * 2]
        );
        // quat_to_rpy inverts quat_rpy (pitch within (-pi/2, pi/2)).
        let rpy = vo[k * 2 + 1];
        let again = DQuat::from_axis_angle(DVec3::Z, rpy.z)
            * DQuat::from_axis_angle(DVec3::Y, rpy.y)
            * DQuat::from_axis_angle(DVec3::X, rpy.x);
        assert!(
            (again.dot(q).abs() - 1.0).abs() < tol,
            "quat_to_rpy of {q}: {rpy}"
        );
        // Twist: the normalized projection of the vector part onto the axis.
        let p = DVec3::new(q.x, q.y, q.z).dot(axis);
        let t = DQuat::from_xyzw(p * axis.x, p * axis.y, p * axis.z, q.w).normalize();
        assert!((qo[k * 2 + 1] - t).length() < tol, "twist of {q}");
        let signed = 2.0 * p.atan2(q.w);
        assert_close_f64(so[k * 3 + 2], signed, tol, "twist angle signed");
        assert_close_f64(so[k * 3 + 1], 2.0 * p.abs().atan2(q.w), tol, "twist angle");
    }
}

// ------------------------------------------------------------------------------------------
// transform_compose / transform_decompose
// ------------------------------------------------------------------------------------------

#[wp::kernel]
fn k_compose(
    p: Array<DVec3>,
    q: Array<DQuat>,
    s: Array<DVec3>,
    mo: Array<DMat4>,
    po: Array<DVec3, 2>,
    qo: Array<DQuat>,
) {
    let i = tid();
    let m = transform_compose(p[i], q[i], s[i]);
    mo[i] = m;
    let (pp, qq, ss) = transform_decompose(m);
    po[(i, 0)] = pp;
    po[(i, 1)] = ss;
    qo[i] = qq;
}

#[wp::kernel]
fn k_compose32(p: Array<Vec3>, q: Array<Quat>, s: Array<Vec3>, mo: Array<Mat4>) {
    let i = tid();
    mo[i] = transform_compose(p[i], q[i], s[i]);
}

/// compose is glam's `from_scale_rotation_translation`, bit for bit on the CPU (the same
/// products; 1e-15 relative on CUDA for FMA contraction); decompose gives back the parts
/// (positive scales) within 1e-14.
fn transform_compose_decompose(dev: &wp::Device) {
    let ps = [
        DVec3::new(1.0, -2.0, 0.5),
        DVec3::ZERO,
        DVec3::new(10.0, 0.0, -3.0),
    ];
    let qs = [
        DQuat::from_axis_angle(DVec3::new(0.0, 0.6, 0.8), 0.9),
        DQuat::IDENTITY,
        DQuat::from_xyzw(0.3, -0.5, 0.1, 0.8).normalize(),
    ];
    let ss = [
        DVec3::new(2.0, 0.5, 3.0),
        DVec3::ONE,
        DVec3::new(0.1, 7.0, 1.0),
    ];
    let n = ps.len();
    let (mo, po, qo) = (
        zeros::<DMat4, 1>(n, dev),
        zeros::<DVec3, 2>((n, 2), dev),
        zeros::<DQuat, 1>(n, dev),
    );
    wp::launch(
        k_compose,
        n,
        (
            &arr(&ps, dev),
            &arr(&qs, dev),
            &arr(&ss, dev),
            &mo,
            &po,
            &qo,
        ),
        dev,
    )
    .unwrap();
    let (mo, po, qo) = (host(&mo), host(&po), host(&qo));
    let rel = if dev.is_cpu() { 0.0 } else { 1e-15 };
    for k in 0..n {
        let want = DMat4::from_scale_rotation_translation(ss[k], qs[k], ps[k]);
        for (g, w) in mo[k].to_cols_array().into_iter().zip(want.to_cols_array()) {
            assert_close_f64(g, w, rel, "transform_compose");
        }
        assert_eq!(po[k * 2], ps[k]);
        assert!(
            (po[k * 2 + 1] - ss[k]).length() < 1e-14,
            "scale {}",
            po[k * 2 + 1]
        );
        assert!(
            (qo[k].dot(qs[k]).abs() - 1.0).abs() < 1e-14,
            "rotation {}",
            qo[k]
        );
    }
    let p32: Vec<Vec3> = ps.iter().map(|p| p.as_vec3()).collect();
    let q32: Vec<Quat> = qs.iter().map(|q| q.as_quat()).collect();
    let s32: Vec<Vec3> = ss.iter().map(|s| s.as_vec3()).collect();
    let mo = zeros::<Mat4, 1>(n, dev);
    wp::launch(
        k_compose32,
        n,
        (&arr(&p32, dev), &arr(&q32, dev), &arr(&s32, dev), &mo),
        dev,
    )
    .unwrap();
    for (k, m) in host(&mo).into_iter().enumerate() {
        let want = Mat4::from_scale_rotation_translation(s32[k], q32[k], p32[k]);
        let tol = if dev.is_cpu() { 0.0 } else { 1e-6 };
        for (g, w) in m.to_cols_array().into_iter().zip(want.to_cols_array()) {
            assert!(
                (g - w).abs() <= tol * w.abs().max(1.0),
                "f32 compose {g} vs {w}"
            );
        }
    }
}

// ------------------------------------------------------------------------------------------
// lower_bound, sample_cdf
// ------------------------------------------------------------------------------------------

#[wp::kernel]
pub(crate) fn k_lower_bound(a: Array<f32>, vals: Array<f32>, lo: i32, hi: i32, out: Array<i32, 2>) {
    let i = tid();
    out[(i, 0)] = lower_bound(a, vals[i]);
    out[(i, 1)] = lower_bound(a, lo, hi, vals[i]);
}

#[wp::kernel]
fn k_ilower_bound(a: Array<i64>, out: Array<i32>) {
    let i = tid();
    out[i] = lower_bound(a, i as i64 * 3 - 4);
}

#[wp::kernel]
pub(crate) fn k_sample_cdf(cdf: Array<f32>, seed: i32, counts: Array<i32>, states: Array<u32>) {
    let i = tid();
    let mut s = rand_init(seed, i as i32);
    let k = sample_cdf(&mut s, cdf);
    atomic_add(counts, k, 1);
    states[i] = s;
}

#[wp::kernel]
fn k_draws_after(seed: i32, states: Array<u32>) {
    let i = tid();
    let mut s = rand_init(seed, i as i32);
    let _u = randf(&mut s);
    states[i] = s;
}

/// Warp's search written out: the first index in `[lo, hi)` whose element is `>= v`, or
/// `hi - 1` when there is none, `lo` for an empty range.
fn warp_lower_bound(a: &[f32], lo: i32, hi: i32, v: f32) -> i32 {
    let (mut l, mut u) = (lo, hi - 1);
    while l < u {
        let m = l + (u - l) / 2;
        if a[m as usize] < v {
            l = m + 1;
        } else {
            u = m;
        }
    }
    l
}

fn lower_bound_and_sample_cdf(dev: &wp::Device) {
    let a = [0.1f32, 0.2, 0.2, 0.5, 0.9, 1.0];
    let vals = [-1.0f32, 0.1, 0.15, 0.2, 0.21, 0.9, 0.95, 1.0, 2.0, f32::NAN];
    let n = vals.len();
    for (lo, hi) in [(0, 6), (2, 5), (3, 3), (1, 2)] {
        let out = zeros::<i32, 2>((n, 2), dev);
        wp::launch(
            k_lower_bound,
            n,
            (&arr(&a, dev), &arr(&vals, dev), lo, hi, &out),
            dev,
        )
        .unwrap();
        let out = host(&out);
        for (k, &v) in vals.iter().enumerate() {
            let whole = warp_lower_bound(&a, 0, 6, v);
            assert_eq!(out[k * 2], whole, "lower_bound(a, {v})");
            // No element compares below NaN: the search ends at the range's start.
            let first_ge = a
                .iter()
                .position(|&x| x >= v || v.is_nan())
                .map_or(5, |p| p as i32);
            assert_eq!(whole, first_ge, "closed form for {v}");
            assert_eq!(
                out[k * 2 + 1],
                warp_lower_bound(&a, lo, hi, v),
                "[{lo}, {hi}) {v}"
            );
        }
    }
    let ia: Vec<i64> = vec![-5, -1, 0, 0, 4, 9, 100];
    let out = zeros::<i32, 1>(8, dev);
    wp::launch(k_ilower_bound, 8, (&arr(&ia, dev), &out), dev).unwrap();
    for (i, g) in host(&out).into_iter().enumerate() {
        let v = i as i64 * 3 - 4;
        let want = ia.iter().position(|&x| x >= v).map_or(6, |p| p as i32);
        assert_eq!(g, want, "i64 lower_bound of {v}");
    }
    // sample_cdf: one draw per thread, frequencies of a 4-bin distribution within 5 sigma,
    // and the state advanced by exactly one step (as one randf).
    let cdf = [0.1f32, 0.4, 0.45, 1.0];
    let n = 20_000usize;
    let counts = zeros::<i32, 1>(4, dev);
    let states = zeros::<u32, 1>(n, dev);
    wp::launch(k_sample_cdf, n, (&arr(&cdf, dev), 7, &counts, &states), dev).unwrap();
    let probs = [0.1, 0.3, 0.05, 0.55];
    for (k, c) in host(&counts).into_iter().enumerate() {
        let p: f64 = probs[k];
        let sigma = (n as f64 * p * (1.0 - p)).sqrt();
        assert!(
            (c as f64 - n as f64 * p).abs() < 5.0 * sigma,
            "bin {k}: {c}"
        );
    }
    let after = zeros::<u32, 1>(n, dev);
    wp::launch(k_draws_after, n, (7, &after), dev).unwrap();
    assert_eq!(host(&states), host(&after));
}

#[wp::kernel]
fn k_lower_bound_oob(a: Array<f32>, hi: i32, out: Array<i32>) {
    out[0] = lower_bound(a, 0, hi, 0.95);
}

/// A range past the array's end is an out-of-bounds fault from the launch (Warp: undefined).
fn lower_bound_faults(dev: &wp::Device) {
    let a = arr(&[0.1f32, 0.5, 0.9], dev);
    let out = zeros::<i32, 1>(1, dev);
    match wp::launch(k_lower_bound_oob, 1, (&a, 8, &out), dev) {
        Err(Error::Fault(f)) => {
            assert!(
                matches!(f.kind, FaultKind::OutOfBounds { arg: "a", .. }),
                "{f:?}"
            );
        }
        other => panic!("expected an out-of-bounds fault, got {other:?}"),
    }
    wp::launch(k_lower_bound_oob, 1, (&a, 3, &out), dev).unwrap();
    assert_eq!(host(&out), vec![2]);
}

// ------------------------------------------------------------------------------------------
// div_approx, inverse_approx: the exact operations here
// ------------------------------------------------------------------------------------------

#[wp::kernel]
fn k_approx(
    x: Array<f32>,
    v: Array<Vec3>,
    m: Array<Mat3>,
    so: Array<f32>,
    vo: Array<Vec3, 2>,
    mo: Array<Mat3>,
) {
    let i = tid();
    so[i] = div_approx(x[i], 3.0);
    vo[(i, 0)] = div_approx(v[i], x[i]);
    vo[(i, 1)] = div_approx(x[i], v[i]);
    mo[i] = inverse_approx(m[i]);
}

fn approximate_operations(dev: &wp::Device) {
    let xs = [1.0f32, -2.5, 7.0];
    let vs = [
        Vec3::new(1.0, 2.0, 3.0),
        Vec3::new(-0.5, 4.0, 0.25),
        Vec3::splat(9.0),
    ];
    let ms = [
        Mat3::from_cols(
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.5, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 4.0),
        ),
        Mat3::IDENTITY,
        Mat3::from_cols(Vec3::X, Vec3::X, Vec3::Z), // singular: zero, as inverse
    ];
    let (so, vo, mo) = (
        zeros::<f32, 1>(3, dev),
        zeros::<Vec3, 2>((3, 2), dev),
        zeros::<Mat3, 1>(3, dev),
    );
    wp::launch(
        k_approx,
        3,
        (
            &arr(&xs, dev),
            &arr(&vs, dev),
            &arr(&ms, dev),
            &so,
            &vo,
            &mo,
        ),
        dev,
    )
    .unwrap();
    let (so, vo, mo) = (host(&so), host(&vo), host(&mo));
    for k in 0..3 {
        assert_eq!(so[k], xs[k] / 3.0);
        assert_eq!(vo[k * 2], vs[k] / xs[k]);
        assert_eq!(vo[k * 2 + 1], xs[k] / vs[k]);
        let want = if ms[k].determinant() == 0.0 {
            Mat3::ZERO
        } else {
            ms[k].inverse()
        };
        // Bit for bit on the CPU; CUDA may contract the cofactor products into FMAs.
        let tol = if dev.is_cpu() { 0.0 } else { 1e-6 };
        for (g, w) in mo[k].to_cols_array().into_iter().zip(want.to_cols_array()) {
            assert!(
                (g - w).abs() <= tol * w.abs().max(1.0),
                "inverse_approx {g} vs {w}"
            );
        }
    }
}

#[wp::kernel]
fn k_block_dim(out: Array<i32>) {
    let i = tid();
    out[i] = block_dim();
}

/// `block_dim()`: the CUDA block size the launch used (`config::cuda_block_dim`); 1 on the CPU.
fn block_dim_of_the_launch(dev: &wp::Device) {
    let out = zeros::<i32, 1>(300, dev);
    wp::launch(k_block_dim, 300, (&out,), dev).unwrap();
    let want = if dev.is_cpu() {
        1
    } else {
        wp::config::cuda_block_dim() as i32
    };
    assert!(want > 1 || dev.is_cpu());
    assert_eq!(host(&out), vec![want; 300]);
}

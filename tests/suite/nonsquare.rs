//! Non-square matrices (`Mat23` .. `Mat64`, `DMat23` ..): operators (with glam's square and
//! the spatial matrices on either side of a product), `transpose`, `outer` of vectors of
//! different lengths, `ddot`, rows and lanes at literal and run-time indices (read and
//! written), constructors, arrays, parameters, struct fields, funcs, local arrays, and
//! gradients (reverse through a Tape and `gradcheck`, forward through `jvp`).
//!
//! Values are checked against the host API (warp-core's methods and operators, the same Rust
//! functions the CPU backend calls): bit for bit on the CPU; on CUDA within [`gpu_tol`].

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    nonsquare_ops_f64,
    nonsquare_ops_f32,
    nonsquare_lanes_rows_and_locals,
    nonsquare_struct_field_and_func,
    nonsquare_gradcheck,
    nonsquare_array_gradients,
    nonsquare_jvp_matches_the_jacobian,
);

/// Backend parity, normwise: 0 on the CPU (the kernel runs the host's own Rust functions); on
/// CUDA, FMA contraction changes roundings: each entry is at most ~20 roundings (a product of
/// a 6-long inner dimension, then a sum) of values of size <= 10, so 2e-6 (f32, eps 6e-8) and
/// 1e-14 (f64, eps 1.1e-16) relative to the result's largest entry, with margin.
fn gpu_tol(dev: &wp::Device, f32: bool) -> f64 {
    match (dev.is_cpu(), f32) {
        (true, _) => 0.0,
        (false, true) => 2e-6,
        (false, false) => 1e-14,
    }
}

/// Max over entries of |got - want| / max(1, max |want|).
#[track_caller]
fn close(got: &[f64], want: &[f64], tol: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}");
    let scale = want.iter().fold(1.0f64, |m, w| m.max(w.abs()));
    let d = got
        .iter()
        .zip(want)
        .map(|(g, w)| if g == w { 0.0 } else { (g - w).abs() / scale })
        .fold(0.0, f64::max);
    assert!(
        d <= tol,
        "{what}: got {got:?}, want {want:?} ({d:e} > {tol:e})"
    );
}

fn m23(seed: f64) -> DMat23 {
    DMat23::from_rows_array(std::array::from_fn(|i| {
        std::array::from_fn(|j| ((i * 3 + j) as f64 * 0.37 + seed).sin() * 2.0)
    }))
}
fn m63(seed: f64) -> DMat63 {
    DMat63::from_rows_array(std::array::from_fn(|i| {
        std::array::from_fn(|j| ((i * 3 + j) as f64 * 0.53 + seed).cos())
    }))
}
fn flat<const R: usize, const C: usize>(a: [[f64; C]; R]) -> Vec<f64> {
    a.iter().flatten().copied().collect()
}

// ----- operators and builtins -----

#[wp::kernel]
pub(crate) fn k_ops_f64(
    a: Array<DMat23>,
    b: Array<DMat32>,
    s: Array<DMat3>,
    x: Array<DVec3>,
    y: Array<DVec2>,
    n: Array<DMat63>,
    out_v: Array<DVec2>,
    out_sq: Array<DMat2>,
    out_as: Array<DMat23>,
    out_sb: Array<DMat32>,
    out_t: Array<DMat32>,
    out_outer: Array<DMat32>,
    out_lin: Array<DMat23>,
    out_dd: Array<f64>,
    out_sm: Array<DSpatialMatrix>,
    out_sv: Array<DSpatialVector>,
) {
    let i = tid();
    let (ai, bi) = (a[i], b[i]);
    out_v[i] = ai * x[i];
    out_sq[i] = ai * bi;
    out_as[i] = ai * s[i];
    out_sb[i] = s[i] * bi;
    out_t[i] = transpose(ai);
    out_outer[i] = outer(x[i], y[i]);
    out_lin[i] = (ai + ai * 2.0 - ai / 3.0) - 0.5 * -ai;
    out_dd[i] = ddot(ai, transpose(bi));
    let ni = n[i];
    out_sm[i] = ni * transpose(ni);
    out_sv[i] = ni * x[i];
}

/// Every operator and builtin of a `DMat23` (and `DMat63`) against warp-core's host API.
fn nonsquare_ops_f64(dev: &wp::Device) {
    let k = 3;
    let a: Vec<DMat23> = (0..k).map(|i| m23(i as f64)).collect();
    let b: Vec<DMat32> = (0..k).map(|i| m23(0.5 + i as f64).transpose()).collect();
    let s: Vec<DMat3> = (0..k)
        .map(|i| DMat3::from_cols_array(&std::array::from_fn(|j| (j as f64 + i as f64).sin())))
        .collect();
    let x: Vec<DVec3> = (0..k)
        .map(|i| DVec3::new(0.5, -1.0 + i as f64, 2.0))
        .collect();
    let y: Vec<DVec2> = (0..k).map(|i| DVec2::new(1.5, -0.25 * i as f64)).collect();
    let n: Vec<DMat63> = (0..k).map(|i| m63(i as f64)).collect();
    let (aa, ab, as_, ax, ay, an) = (
        arr(&a, dev),
        arr(&b, dev),
        arr(&s, dev),
        arr(&x, dev),
        arr(&y, dev),
        arr(&n, dev),
    );
    let ov = zeros::<DVec2, 1>(k, dev);
    let osq = zeros::<DMat2, 1>(k, dev);
    let oas = zeros::<DMat23, 1>(k, dev);
    let osb = zeros::<DMat32, 1>(k, dev);
    let ot = zeros::<DMat32, 1>(k, dev);
    let oo = zeros::<DMat32, 1>(k, dev);
    let ol = zeros::<DMat23, 1>(k, dev);
    let od = zeros::<f64, 1>(k, dev);
    let osm = zeros::<DSpatialMatrix, 1>(k, dev);
    let osv = zeros::<DSpatialVector, 1>(k, dev);
    wp::launch(
        k_ops_f64,
        k,
        (
            &aa, &ab, &as_, &ax, &ay, &an, &ov, &osq, &oas, &osb, &ot, &oo, &ol, &od, &osm, &osv,
        ),
        dev,
    )
    .unwrap();
    let tol = gpu_tol(dev, false);
    let (gv, gsq, gas, gsb, gt, go, gl, gd, gsm, gsv) = (
        host(&ov),
        host(&osq),
        host(&oas),
        host(&osb),
        host(&ot),
        host(&oo),
        host(&ol),
        host(&od),
        host(&osm),
        host(&osv),
    );
    for i in 0..k {
        let ai = a[i];
        close(&gv[i].to_array(), &(ai * x[i]).to_array(), tol, "m * x");
        close(
            &gsq[i].to_cols_array(),
            &(ai * b[i]).to_cols_array(),
            tol,
            "Mat23 * Mat32",
        );
        close(
            &flat(gas[i].to_rows_array()),
            &flat((ai * s[i]).to_rows_array()),
            tol,
            "Mat23 * Mat3",
        );
        close(
            &flat(gsb[i].to_rows_array()),
            &flat((s[i] * b[i]).to_rows_array()),
            tol,
            "Mat3 * Mat32",
        );
        assert_eq!(gt[i], ai.transpose(), "transpose is exact");
        assert_eq!(
            go[i],
            wp::__private::builtins::outer(x[i], y[i]),
            "outer is exact"
        );
        // outer(a, b)[i][j] = a[i] b[j] (shape (3, 2), Warp's).
        assert_eq!(go[i][(2, 1)], x[i].z * y[i].y);
        let lin = (ai + ai * 2.0 - ai / 3.0) - 0.5 * -ai;
        close(
            &flat(gl[i].to_rows_array()),
            &flat(lin.to_rows_array()),
            tol,
            "lanes",
        );
        let dd = wp::__private::builtins::ddot(ai, b[i].transpose());
        close(&[gd[i]], &[dd], tol, "ddot");
        let sm: DSpatialMatrix = n[i] * n[i].transpose();
        close(
            &flat(gsm[i].to_rows_array()),
            &flat(sm.to_rows_array()),
            tol,
            "Mat63 * Mat36",
        );
        close(
            &gsv[i].to_array(),
            &(n[i] * x[i]).to_array(),
            tol,
            "Mat63 * Vec3",
        );
    }
}

#[wp::kernel]
pub(crate) fn k_ops_f32(
    a: Array<Mat34>,
    x: Array<Vec4>,
    out: Array<Vec3>,
    out4: Array<Vec4>,
    t: Array<Mat43>,
) {
    let i = tid();
    let m = a[i];
    out[i] = m * x[i];
    out4[i] = transpose(m) * Vec3::new(1.0, 2.0, 3.0);
    t[i] = transpose(m * 2.0) * Mat3::IDENTITY;
}

/// f32 (a 16-byte aligned `Mat34`, rows of `Vec4`) against the host API.
fn nonsquare_ops_f32(dev: &wp::Device) {
    let k = 4;
    let a: Vec<Mat34> = (0..k)
        .map(|i| {
            Mat34::from_rows_array(std::array::from_fn(|r| {
                std::array::from_fn(|c| ((r * 4 + c + i) as f32 * 0.3).sin())
            }))
        })
        .collect();
    let x: Vec<Vec4> = (0..k)
        .map(|i| Vec4::new(1.0, -0.5, i as f32, 2.0))
        .collect();
    let (aa, ax) = (arr(&a, dev), arr(&x, dev));
    let (out, out4) = (zeros::<Vec3, 1>(k, dev), zeros::<Vec4, 1>(k, dev));
    let t = zeros::<Mat43, 1>(k, dev);
    wp::launch(k_ops_f32, k, (&aa, &ax, &out, &out4, &t), dev).unwrap();
    let (go, go4, gt) = (host(&out), host(&out4), host(&t));
    let tol = gpu_tol(dev, true);
    let f = |v: &[f32]| -> Vec<f64> { v.iter().map(|x| *x as f64).collect() };
    for i in 0..k {
        close(
            &f(&go[i].to_array()),
            &f(&(a[i] * x[i]).to_array()),
            tol,
            "f32 m * x",
        );
        let w4 = a[i].transpose() * Vec3::new(1.0, 2.0, 3.0);
        close(
            &f(&go4[i].to_array()),
            &f(&w4.to_array()),
            tol,
            "f32 transpose * x",
        );
        let wt = (a[i] * 2.0).transpose() * Mat3::IDENTITY;
        let f = |m: Mat43| -> Vec<f64> {
            m.to_rows_array()
                .iter()
                .flatten()
                .map(|v| *v as f64)
                .collect()
        };
        close(&f(gt[i]), &f(wt), tol, "f32 transpose * Mat3");
    }
}

// ----- rows, lanes, locals -----

#[wp::kernel]
pub(crate) fn k_lanes(a: Array<Mat23>, idx: Array<i32>, out: Array<f32>, rows: Array<Vec3>) {
    let i = tid();
    let mut m = a[i];
    let (r, c) = (idx[0] as usize, idx[1] as usize);
    // Reads at literal and run-time indices.
    out[i * 4] = m[(1, 2)] + m[0].y;
    out[i * 4 + 1] = m[(r, c)];
    rows[i * 2] = m[r];
    // Writes: a lane, a row, at literal and run-time indices.
    m[(0, 1)] = 10.0;
    m[(r, c)] = m[(r, c)] + 1.0;
    m[1] = m[1] * 2.0;
    rows[i * 2 + 1] = m[1];
    out[i * 4 + 2] = m[(0, 1)];
    // Constructors and a local array of matrices.
    let z = Mat23::from_rows(Vec3::new(1.0, 2.0, 3.0), m[0])
        + Mat23::ZERO
        + Mat23::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.5);
    let mut loc = [Mat23::ZERO; 3];
    loc[r] = z;
    loc[2][(1, 0)] = 7.0;
    out[i * 4 + 3] = loc[r][(1, 2)] + loc[2][(1, 0)];
}

/// Lanes and rows (literal and run-time indices, read and written), `from_rows`, `ZERO`,
/// `row`, and local arrays of matrices; an index past the rows faults (`LocalIndex`).
fn nonsquare_lanes_rows_and_locals(dev: &wp::Device) {
    let k = 2;
    let a: Vec<Mat23> = (0..k).map(|i| m23(i as f64)).map(to_f32).collect();
    let aa = arr(&a, dev);
    let idx = arr(&[1i32, 0], dev);
    let (out, rows) = (zeros::<f32, 1>(4 * k, dev), zeros::<Vec3, 1>(2 * k, dev));
    wp::launch(k_lanes, k, (&aa, &idx, &out, &rows), dev).unwrap();
    let (go, gr) = (host(&out), host(&rows));
    for i in 0..k {
        let m = a[i];
        assert_eq!(go[i * 4], m[(1, 2)] + m[0].y);
        assert_eq!(go[i * 4 + 1], m[(1, 0)]);
        assert_eq!(gr[i * 2], m[1]);
        let mut w = m;
        w[(0, 1)] = 10.0;
        w[(1, 0)] += 1.0;
        w[1] *= 2.0;
        assert_eq!(gr[i * 2 + 1], w[1]);
        assert_eq!(go[i * 4 + 2], 10.0);
        assert_eq!(go[i * 4 + 3], (w[0].z + 0.5) + 7.0);
    }
    // Row 2 of a 2-row matrix.
    let bad = arr(&[2i32, 0], dev);
    let e = wp::launch(k_lanes, k, (&aa, &bad, &out, &rows), dev)
        .expect_err("row 2 of a Mat23 is out of range");
    let text = crate::chain(&e);
    assert!(text.contains("k_lanes") && text.contains('2'), "{text}");
}

fn to_f32(m: DMat23) -> Mat23 {
    Mat23::from_rows_array(m.to_rows_array().map(|r| r.map(|v| v as f32)))
}

// ----- structs and funcs -----

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
pub(crate) struct Jac {
    j: Mat23,
    w: f32,
}

#[wp::func]
fn project(j: Mat23, v: Vec3) -> Mat32 {
    outer(v, j * v)
}

#[wp::kernel]
pub(crate) fn k_struct(js: Array<Jac>, v: Array<Vec3>, out: Array<Mat32>) {
    let i = tid();
    let s = js[i];
    let j: Mat23 = s.j;
    out[i] = project(j, v[i]) * s.w;
    let mut c = s;
    let mut jj: Mat23 = c.j;
    jj[(1, 1)] = s.w;
    c.j = jj;
    js[i] = c;
}

/// A matrix as a struct field and as a func's argument and result.
fn nonsquare_struct_field_and_func(dev: &wp::Device) {
    let k = 3;
    let js: Vec<Jac> = (0..k)
        .map(|i| Jac {
            j: to_f32(m23(i as f64 + 0.2)),
            w: 1.5 + i as f32,
        })
        .collect();
    let v: Vec<Vec3> = (0..k).map(|i| Vec3::new(0.5, i as f32, -1.0)).collect();
    let (aj, av, out) = (arr(&js, dev), arr(&v, dev), zeros::<Mat32, 1>(k, dev));
    wp::launch(k_struct, k, (&aj, &av, &out), dev).unwrap();
    let (gj, go) = (host(&aj), host(&out));
    let tol = gpu_tol(dev, true);
    for i in 0..k {
        let want: Mat32 = wp::__private::builtins::outer(v[i], js[i].j * v[i]) * js[i].w;
        let f = |m: Mat32| -> Vec<f64> {
            m.to_rows_array()
                .iter()
                .flatten()
                .map(|x| *x as f64)
                .collect()
        };
        close(&f(go[i]), &f(want), tol, "func through a struct field");
        let mut w = js[i];
        w.j[(1, 1)] = w.w;
        assert_eq!(gj[i], w, "field lane written back");
    }
}

// ----- gradients -----

/// Every differentiable operation of a non-square matrix in one scalar loss per thread, the
/// inputs assembled from f64 scalars (so that `gradcheck` nudges each entry).
#[wp::kernel]
pub(crate) fn k_loss(xs: Array<f64>, loss: Array<f64>) {
    let i = tid();
    let o = i * 12;
    // Warp's scalar constructor, row by row.
    let a = DMat23::new(xs[o], xs[o + 1], xs[o + 2], xs[o + 3], xs[o + 4], xs[o + 5]);
    let u = DVec3::new(xs[o + 6], xs[o + 7], xs[o + 8]);
    let v = DVec2::new(xs[o + 9], xs[o + 10]);
    let s = xs[o + 11];
    let b = outer(u, v) * s - transpose(a) / 3.0;
    let p = a * b;
    let q = a * DMat3::from_cols(u, u * 0.5, DVec3::new(1.0, -1.0, s));
    let w = a * u;
    let big = DMat63::from_rows(u, u * 2.0, a[0], a[1], u * s, -u);
    let sm = big * transpose(big);
    let sv = big * u;
    let mut c = a;
    c[(1, 2)] = c[(0, 1)] * s;
    c[0] = c[0] + u;
    loss[i] = ddot(p, p) + ddot(q, c) + w.dot(v) + spatial_dot(sm * sv, sv) * 0.01 + ddot(-c, a);
}

/// `gradcheck` of [`k_loss`] (f64; step 1e-6, central differences: truncation O(h^2) of
/// polynomials with O(1)-O(10) coefficients and rounding 1e-16/1e-6 give about 1e-9; tolerance
/// 1e-5 absolute and relative, the spatial suite's).
fn nonsquare_gradcheck(dev: &wp::Device) {
    let n = 3;
    let xs: Vec<f64> = (0..n * 12).map(|k| ((k as f64) * 0.731).sin()).collect();
    let xs = arr(&xs, dev).with_grad().unwrap();
    let loss = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_loss, n, (&xs, &loss), dev),
        &[&xs],
        &[&loss],
        wp::GradcheckOptions {
            eps: 1e-6,
            atol: 1e-5,
            rtol: 1e-5,
        },
    )
    .unwrap();
    assert!(report.passed, "{report:?}");
    let touched = (0..report.analytic[0].len())
        .filter(|&c| report.analytic.iter().any(|r| r[c] != 0.0))
        .count();
    assert_eq!(
        touched,
        report.analytic[0].len(),
        "every input has a gradient"
    );
}

#[wp::kernel]
pub(crate) fn k_array_loss(ms: Array<Mat23>, xs: Array<Vec3>, w: Vec2, loss: Array<f32>) {
    let i = tid();
    atomic_add(loss, 0, (ms[i] * xs[i]).dot(w));
}

/// `loss = Σ (m_i x_i) · w` through a Tape over arrays of matrices: `d/dx_i = m_iᵀ w` and
/// `d/dm_i = outer(w, x_i)` (bit for bit on the CPU; `gpu_tol` on CUDA).
fn nonsquare_array_gradients(dev: &wp::Device) {
    let k = 4;
    let m0: Vec<Mat23> = (0..k).map(|i| to_f32(m23(i as f64))).collect();
    let x0: Vec<Vec3> = (0..k)
        .map(|i| Vec3::new(1.0, -0.5 * i as f32, 0.25))
        .collect();
    let w = Vec2::new(0.7, -1.3);
    let ms = arr(&m0, dev).with_grad().unwrap();
    let xs = arr(&x0, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_array_loss, k, (&ms, &xs, w, &loss), dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    let (gm, gx) = (host(&ms.grad().unwrap()), host(&xs.grad().unwrap()));
    let tol = gpu_tol(dev, true);
    let f = |v: &[f32]| -> Vec<f64> { v.iter().map(|x| *x as f64).collect() };
    for i in 0..k {
        let want_x = m0[i].transpose() * w;
        close(&f(&gx[i].to_array()), &f(&want_x.to_array()), tol, "d/dx");
        let want_m: Mat23 = wp::__private::builtins::outer(w, x0[i]);
        close(
            &f(gm[i].to_rows_array().as_flattened()),
            &f(want_m.to_rows_array().as_flattened()),
            tol,
            "d/dm",
        );
    }
}

/// Forward mode through the operators, `transpose`, `outer`, `ddot`, lane writes and the
/// scalar constructor.
#[wp::kernel]
pub(crate) fn k_fwd(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let o = i * 5;
    let mut a = DMat23::ZERO;
    a[(0, 0)] = x[o];
    a[(0, 2)] = x[o + 1] * x[o];
    a[(1, 1)] = x[o + 2];
    a[(1, 2)] = 0.5;
    let a = a + DMat23::new(0.0, x[o + 3], 0.0, 1.0, 0.0, x[o + 4]);
    let mut u = DVec2::ZERO;
    u[0] = x[o + 3];
    u[1] = x[o + 4] * x[o + 2];
    let b = outer(a[1], u) + transpose(a) * 2.0 * (a * transpose(a));
    let c = a * b * a - a / 3.0;
    y[i] = ddot(c, a) + (c * a[0]).dot(u) + transpose(c)[(2, 1)];
}

/// `jvp` against the reverse Jacobian times the direction (f64: both exact derivatives with
/// the same roundings in another order, relative 1e-12) and against central differences
/// (h = 1e-6: truncation and rounding about 1e-10 for this polynomial, relative 1e-7).
fn nonsquare_jvp_matches_the_jacobian(dev: &wp::Device) {
    let n = 3;
    let xs: Vec<f64> = (0..n * 5)
        .map(|k| ((k as f64) * 0.61).sin() * 1.5)
        .collect();
    let vs: Vec<f64> = (0..n * 5).map(|k| ((k as f64) * 1.37).cos()).collect();
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(n, dev));
    wp::jvp(k_fwd, n, (&x, &y), (&v, &y_dot), dev).unwrap();
    let got = host(&y_dot);
    let j = wp::jacobian(|| wp::launch(k_fwd, n, (&x, &y), dev), &[&x], &[&y]).unwrap();
    let jv: Vec<f64> = j
        .iter()
        .map(|r| r.iter().zip(&vs).map(|(a, b)| a * b).sum())
        .collect();
    let h = 1e-6;
    let shifted = |s: f64| {
        let xp: Vec<f64> = xs.iter().zip(&vs).map(|(a, b)| a + s * b).collect();
        let (xp, yp) = (arr(&xp, dev), zeros::<f64, 1>(n, dev));
        wp::launch(k_fwd, n, (&xp, &yp), dev).unwrap();
        host(&yp)
    };
    let (p, m) = (shifted(h), shifted(-h));
    for k in 0..n {
        let tol = 1e-12 * jv[k].abs().max(1.0);
        assert!(
            (got[k] - jv[k]).abs() <= tol,
            "jvp vs J v [{k}]: {} vs {}",
            got[k],
            jv[k]
        );
        let fd = (p[k] - m[k]) / (2.0 * h);
        assert!(
            (got[k] - fd).abs() <= 1e-7 * fd.abs().max(1.0),
            "jvp vs central differences [{k}]: {} vs {fd}",
            got[k]
        );
        assert!(got[k] != 0.0, "a nonzero tangent [{k}]");
    }
}

//! Spatial vectors and matrices (`SpatialVector`, `SpatialMatrix` and their f64 twins): the
//! builtins of the "spatial" section, the operators, literal indexing and component writes,
//! arrays, parameters and struct fields, and gradients through a Tape.
//!
//! Values are checked twice: against the host API (warp-core's methods, the same Rust
//! functions the CPU backend calls: bit for bit on the CPU; on CUDA within [`gpu_tol`]), and
//! against closed forms computed here in f64 (the motion and force cross products as 6x6 block
//! matrices of 3x3 skew matrices, the motion transform `spatial_adjoint(R, skew(p) R)`, the
//! force transform as its inverse transpose, the power `twist · wrench` kept) within
//! [`ref_tol`].

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    spatial_f64,
    spatial_f32,
    spatial_struct_field_and_func,
    spatial_gradients_match_finite_differences,
    spatial_array_gradients,
    spatial_jvp_matches_the_jacobian,
    velocity_at_point_f64,
    velocity_at_point_f32,
    velocity_at_point_nonfinite,
    velocity_at_point_gradients,
    velocity_at_point_jvp,
);

/// Backend parity, normwise: 0 on the CPU (the kernel runs the host's own Rust functions); on
/// CUDA, FMA contraction changes roundings: each lane here is at most ~40 roundings (a 6x6
/// product's sums of six, twice) of values of size <= 40, so 5e-6 (f32, eps 6e-8) and 1e-14
/// (f64, eps 1.1e-16) relative to the result's largest lane, with margin.
fn gpu_tol(dev: &wp::Device, f32: bool) -> f64 {
    match (dev.is_cpu(), f32) {
        (true, _) => 0.0,
        (false, true) => 5e-6,
        (false, false) => 1e-14,
    }
}

/// Against the f64 closed forms: the kernel's own roundings (f32: a few dozen roundings of
/// eps 6e-8 in a sum of terms of the result's size; f64: likewise with eps 1.1e-16), and the
/// references' (f64) in another order: 5e-6 for f32, 1e-13 for f64.
fn ref_tol(f32: bool) -> f64 {
    if f32 {
        5e-6
    } else {
        1e-13
    }
}

/// Max over lanes of |got - want| / max(1, max |want|).
fn normwise(got: &[f64], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(1.0f64, |m, w| m.max(w.abs()));
    got.iter()
        .zip(want)
        .map(|(g, w)| if g == w { 0.0 } else { (g - w).abs() / scale })
        .fold(0.0, f64::max)
}

#[track_caller]
fn close(got: &[f64], want: &[f64], tol: f64, what: &str) {
    let d = normwise(got, want);
    assert!(
        d <= tol,
        "{what}: got {got:?}, want {want:?} ({d:e} > {tol:e})"
    );
}

fn lanes_v(v: DSpatialVector) -> Vec<f64> {
    v.to_array().to_vec()
}
fn lanes_m(m: DSpatialMatrix) -> Vec<f64> {
    m.to_rows_array().concat()
}

// ----- f64 closed forms -----

/// `skew(p) x = p × x`.
fn skew(p: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, p.z, -p.y),
        DVec3::new(-p.z, 0.0, p.x),
        DVec3::new(p.y, -p.x, 0.0),
    )
}

/// The 6x6 matrix of 3x3 blocks `[[a, b], [c, d]]` (glam column-major blocks).
fn blocks(a: DMat3, b: DMat3, c: DMat3, d: DMat3) -> DSpatialMatrix {
    let mut m = [[0.0; 6]; 6];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = a.col(j)[i];
            m[i][j + 3] = b.col(j)[i];
            m[i + 3][j] = c.col(j)[i];
            m[i + 3][j + 3] = d.col(j)[i];
        }
    }
    DSpatialMatrix::from_rows_array(m)
}

/// Featherstone's motion cross-product matrix `a×` = `[[w×, 0], [v×, w×]]`.
fn crm(a: DSpatialVector) -> DSpatialMatrix {
    let (w, v) = (skew(a.top()), skew(a.bottom()));
    blocks(w, DMat3::ZERO, v, w)
}

/// The plain f64 matrix-vector product (row-major), written out.
fn mv(m: DSpatialMatrix, x: DSpatialVector) -> DSpatialVector {
    let a = m.to_rows_array();
    DSpatialVector::from_array(std::array::from_fn(|i| {
        (0..6).map(|k| a[i][k] * x[k]).sum()
    }))
}

fn mm(a: DSpatialMatrix, b: DSpatialMatrix) -> DSpatialMatrix {
    let (a, b) = (a.to_rows_array(), b.to_rows_array());
    DSpatialMatrix::from_rows_array(std::array::from_fn(|i| {
        std::array::from_fn(|j| (0..6).map(|k| a[i][k] * b[k][j]).sum())
    }))
}

fn tr(m: DSpatialMatrix) -> DSpatialMatrix {
    let a = m.to_rows_array();
    DSpatialMatrix::from_rows_array(std::array::from_fn(|i| std::array::from_fn(|j| a[j][i])))
}

/// Inputs: spatial vectors with lanes of size <= 3, a matrix with entries of size <= 1, and
/// rigid transforms (unit rotations, translations of size <= 3).
fn inputs() -> Vec<(DSpatialVector, DSpatialVector, DSpatialMatrix, DTransform)> {
    let r = |k: f64| ((k * 12.9898).sin() * 43758.5453).fract() * 2.0 - 1.0;
    let sv = |k: f64| DSpatialVector::from_array(std::array::from_fn(|j| 3.0 * r(k + j as f64)));
    (0..7)
        .map(|i| {
            let k = i as f64 * 41.0;
            let m = DSpatialMatrix::from_rows_array(std::array::from_fn(|a| {
                std::array::from_fn(|b| r(k + 100.0 + (a * 6 + b) as f64))
            }));
            let q =
                DQuat::from_xyzw(r(k + 20.0), r(k + 21.0), r(k + 22.0), r(k + 23.0)).normalize();
            let t = DTransform::new(
                DVec3::new(3.0 * r(k + 24.0), 3.0 * r(k + 25.0), 3.0 * r(k + 26.0)),
                q,
            );
            (sv(k), sv(k + 7.0), m, t)
        })
        .collect()
}

/// One kernel body for both precisions: every spatial builtin, operator and spelling.
macro_rules! spatial_kernel {
    ($name:ident, $sv:ident, $sm:ident, $x:ident, $v3:ident, $m3:ident, $s:ident) => {
        #[wp::kernel]
        pub(crate) fn $name(
            a: Array<$sv>,
            b: Array<$sv>,
            m: Array<$sm>,
            t: Array<$x>,
            s: $s,
            sm: $sm,
            vo: Array<$sv, 2>,
            mo: Array<$sm, 2>,
            so: Array<$s, 2>,
            wo: Array<$v3, 2>,
        ) {
            let i = tid();
            let x = a[i];
            let y = b[i];
            let mi = m[i];
            let ti = t[i];
            vo[(i, 0)] = spatial_cross(x, y);
            vo[(i, 1)] = spatial_cross_dual(x, y);
            vo[(i, 2)] = x + y;
            vo[(i, 3)] = x - y;
            vo[(i, 4)] = x * s;
            vo[(i, 5)] = 2.0 * x;
            vo[(i, 6)] = x / s;
            vo[(i, 7)] = -x;
            vo[(i, 8)] = mi * x;
            vo[(i, 9)] = $sv::new(spatial_top(x), spatial_bottom(y));
            vo[(i, 10)] = spatial_vector(spatial_bottom(x), spatial_top(y));
            vo[(i, 11)] = spatial_vector(x[0], x[1], y[2], y[3], x[4], y[5]);
            vo[(i, 12)] = transform_twist(ti, x);
            vo[(i, 13)] = transform_wrench(ti, y);
            vo[(i, 14)] = mi[2];
            let mut z = $sv::ZERO;
            z[0] = x[5];
            z[3] += y[1];
            z[5] = mi[1][4];
            vo[(i, 15)] = z;
            mo[(i, 0)] = mi * sm;
            mo[(i, 1)] = mi + sm;
            mo[(i, 2)] = mi - sm;
            mo[(i, 3)] = transpose(mi);
            mo[(i, 4)] = mi.transpose();
            mo[(i, 5)] = outer(x, y);
            let r = $m3::from_quat(ti.q);
            mo[(i, 6)] = spatial_adjoint(r, skew(ti.p) * r);
            mo[(i, 7)] = mi * s;
            mo[(i, 8)] = -mi;
            mo[(i, 9)] = $sm::IDENTITY * mi;
            mo[(i, 10)] = $sm::from_rows(y, x, y, x, $sv::ZERO, x);
            let mut w = $sm::ZERO;
            w[(1, 2)] = mi[(2, 1)];
            w[4] = x;
            w[5][5] = 3.0;
            mo[(i, 11)] = w;
            mo[(i, 12)] = mi / s;
            so[(i, 0)] = spatial_dot(x, y);
            so[(i, 1)] = spatial_dot(transform_twist(ti, x), transform_wrench(ti, y));
            so[(i, 2)] = mi[(3, 4)];
            if x == x && x != y && mi == mi {
                so[(i, 3)] = 1.0;
            }
            wo[(i, 0)] = spatial_top(x);
            wo[(i, 1)] = spatial_bottom(x);
        }
    };
}
spatial_kernel!(
    k_spatial64,
    DSpatialVector,
    DSpatialMatrix,
    DTransform,
    DVec3,
    DMat3,
    f64
);
spatial_kernel!(
    k_spatial32,
    SpatialVector,
    SpatialMatrix,
    Transform,
    Vec3,
    Mat3,
    f32
);

/// Runs a `spatial_kernel!` and checks it: `$up` and `$upm` take a kernel value to f64, `$dn`
/// and `$dnm` the f64 inputs to the kernel's precision.
macro_rules! spatial_test {
    ($dev:expr, $kernel:ident, $sv:ident, $sm:ident, $x:ident, $v3:ident, $m3:ident, $s:ident,
     $f32:expr, $dn:expr, $dnm:expr, $dnx:expr, $up:expr, $upm:expr) => {{
        let dev: &wp::Device = $dev;
        let (dn, dnm, dnx): (
            fn(DSpatialVector) -> $sv,
            fn(DSpatialMatrix) -> $sm,
            fn(DTransform) -> $x,
        ) = ($dn, $dnm, $dnx);
        let (up, upm): (fn($sv) -> DSpatialVector, fn($sm) -> DSpatialMatrix) = ($up, $upm);
        let ins = inputs();
        let n = ins.len();
        let a: Vec<$sv> = ins.iter().map(|c| dn(c.0)).collect();
        let b: Vec<$sv> = ins.iter().map(|c| dn(c.1)).collect();
        let m: Vec<$sm> = ins.iter().map(|c| dnm(c.2)).collect();
        let t: Vec<$x> = ins.iter().map(|c| dnx(c.3)).collect();
        let s: $s = 0.625;
        let sm: $sm = dnm(ins[1].2);
        let (vo, mo) = (zeros::<$sv, 2>((n, 16), dev), zeros::<$sm, 2>((n, 13), dev));
        let (so, wo) = (zeros::<$s, 2>((n, 4), dev), zeros::<$v3, 2>((n, 2), dev));
        wp::launch(
            $kernel,
            n,
            (
                &arr(&a, dev),
                &arr(&b, dev),
                &arr(&m, dev),
                &arr(&t, dev),
                s,
                sm,
                &vo,
                &mo,
                &so,
                &wo,
            ),
            dev,
        )
        .unwrap();
        let (vo, mo, so, wo) = (host(&vo), host(&mo), host(&so), host(&wo));
        let (gt, rt) = (gpu_tol(dev, $f32), ref_tol($f32));
        for i in 0..n {
            let (x, y, mi, ti) = (a[i], b[i], m[i], t[i]);
            let up_x = |t: $x| DTransform::from_array(t.to_array().map(|v| v as f64));
            let (dx, dy, dm, dsm) = (up(x), up(y), upm(mi), upm(sm));
            let dt = up_x(ti);
            let v = |k: usize| up(vo[i * 16 + k]);
            let mk = |k: usize| upm(mo[i * 13 + k]);
            let w = |what: &str| format!("row {i}: {what}");
            // The host API (bit for bit on the CPU).
            let host_v: [($sv, &str); 16] = [
                (x.cross(y), "spatial_cross"),
                (x.cross_dual(y), "spatial_cross_dual"),
                (x + y, "x + y"),
                (x - y, "x - y"),
                (x * s, "x * s"),
                (2.0 * x, "2 * x"),
                (x / s, "x / s"),
                (-x, "-x"),
                (mi * x, "m * x"),
                ($sv::new(x.top(), y.bottom()), "SpatialVector::new"),
                ($sv::new(x.bottom(), y.top()), "spatial_vector(w, v)"),
                (
                    $sv::from_array([x[0], x[1], y[2], y[3], x[4], y[5]]),
                    "spatial_vector(6 scalars)",
                ),
                (x.transform_twist(ti), "transform_twist"),
                (y.transform_wrench(ti), "transform_wrench"),
                (mi[2], "m[2]"),
                (
                    $sv::from_array([x[5], 0.0, 0.0, y[1], 0.0, mi[1][4]]),
                    "lane writes",
                ),
            ];
            for (k, (want, what)) in host_v.iter().enumerate() {
                close(&lanes_v(v(k)), &lanes_v(up(*want)), gt, &w(what));
            }
            let r = $m3::from_quat(ti.q);
            let skew_p = {
                let p = ti.p;
                $m3::from_cols(
                    $v3::new(0.0, p.z, -p.y),
                    $v3::new(-p.z, 0.0, p.x),
                    $v3::new(p.y, -p.x, 0.0),
                )
            };
            let mut wm = $sm::ZERO;
            wm[(1, 2)] = mi[(2, 1)];
            wm[4] = x;
            wm[5][5] = 3.0;
            let host_m: [($sm, &str); 13] = [
                (mi * sm, "m * sm"),
                (mi + sm, "m + sm"),
                (mi - sm, "m - sm"),
                (mi.transpose(), "transpose"),
                (mi.transpose(), "m.transpose()"),
                (x.outer(y), "outer"),
                ($sm::adjoint(r, skew_p * r), "spatial_adjoint"),
                (mi * s, "m * s"),
                (-mi, "-m"),
                ($sm::IDENTITY * mi, "I * m"),
                ($sm::from_rows(y, x, y, x, $sv::ZERO, x), "from_rows"),
                (wm, "entry and row writes"),
                (mi / s, "m / s"),
            ];
            for (k, (want, what)) in host_m.iter().enumerate() {
                close(&lanes_m(mk(k)), &lanes_m(upm(*want)), gt, &w(what));
            }
            let sc = |k: usize| so[i * 4 + k] as f64;
            close(&[sc(0)], &[x.dot(y) as f64], gt, &w("spatial_dot"));
            close(&[sc(2)], &[mi[3][4] as f64], 0.0, &w("m[(3, 4)]"));
            assert_eq!(sc(3), 1.0, "{}", w("== and !="));
            assert_eq!(
                wo[i * 2].to_array(),
                x.top().to_array(),
                "{}",
                w("spatial_top")
            );
            assert_eq!(
                wo[i * 2 + 1].to_array(),
                x.bottom().to_array(),
                "{}",
                w("spatial_bottom")
            );
            // The closed forms, in f64.
            close(&lanes_v(v(0)), &lanes_v(mv(crm(dx), dy)), rt, &w("a× b"));
            close(
                &lanes_v(v(1)),
                &lanes_v(mv(tr(crm(dx)) * -1.0, dy)),
                rt,
                &w("a×* b = -(a×)ᵀ b"),
            );
            close(&lanes_v(v(8)), &lanes_v(mv(dm, dx)), rt, &w("m x"));
            close(&lanes_m(mk(0)), &lanes_m(mm(dm, dsm)), rt, &w("m sm"));
            close(&lanes_m(mk(3)), &lanes_m(tr(dm)), 0.0, &w("transpose"));
            let dr = DMat3::from_quat(dt.q);
            let xm = blocks(dr, DMat3::ZERO, skew(dt.p) * dr, dr);
            close(
                &lanes_m(mk(6)),
                &lanes_m(xm),
                rt,
                &w("spatial_adjoint(R, skew(p) R)"),
            );
            close(&lanes_v(v(12)), &lanes_v(mv(xm, dx)), rt, &w("twist = X m"));
            // The force transform is X⁻ᵀ: with X⁻¹ the motion transform of t⁻¹.
            let ti_ = dt.inverse();
            let dri = DMat3::from_quat(ti_.q);
            let xi = blocks(dri, DMat3::ZERO, skew(ti_.p) * dri, dri);
            // (In f32 the rotation rounded to f32 is unit to about 1e-7, within `rt`.)
            close(
                &lanes_m(mm(xm, xi)),
                &lanes_m(DSpatialMatrix::IDENTITY),
                rt,
                &w("X X⁻¹"),
            );
            close(
                &lanes_v(v(13)),
                &lanes_v(mv(tr(xi), dy)),
                rt,
                &w("wrench = X⁻ᵀ f"),
            );
            // Power is frame independent: twist(t, m) · wrench(t, f) = m · f.
            close(&[sc(1)], &[dx.dot(dy)], rt * 10.0, &w("power kept"));
        }
    }};
}

fn spatial_f64(dev: &wp::Device) {
    spatial_test!(
        dev,
        k_spatial64,
        DSpatialVector,
        DSpatialMatrix,
        DTransform,
        DVec3,
        DMat3,
        f64,
        false,
        |v| v,
        |m| m,
        |t| t,
        |v| v,
        |m| m
    );
}

fn spatial_f32(dev: &wp::Device) {
    spatial_test!(
        dev,
        k_spatial32,
        SpatialVector,
        SpatialMatrix,
        Transform,
        Vec3,
        Mat3,
        f32,
        true,
        DSpatialVector::as_spatial,
        DSpatialMatrix::as_spatial,
        |t: DTransform| t.as_transform(),
        SpatialVector::as_dspatial,
        SpatialMatrix::as_dspatial
    );
}

// ----- structs and funcs -----

/// A spatial vector and matrix as struct fields.
#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
pub(crate) struct Body {
    twist: SpatialVector,
    inertia: SpatialMatrix,
    mass: f32,
}

#[wp::func]
fn momentum(b: Body) -> SpatialVector {
    b.inertia * b.twist
}

#[wp::kernel]
pub(crate) fn k_bodies(bodies: Array<Body>, out: Array<SpatialVector>, ke: Array<f32>) {
    let i = tid();
    let b = bodies[i];
    let h = momentum(b);
    out[i] = h;
    ke[i] = 0.5 * spatial_dot(b.twist, h);
    // A field's type is the struct's business (the macro cannot see it): annotated, its
    // lanes can be indexed.
    let mut tw: SpatialVector = b.twist;
    tw[0] = b.mass;
    let mut c = b;
    c.twist = tw;
    bodies[i] = c;
}

fn spatial_struct_field_and_func(dev: &wp::Device) {
    let bodies: Vec<Body> = inputs()
        .iter()
        .map(|c| Body {
            twist: c.0.as_spatial(),
            inertia: (c.2 * c.2.transpose()).as_spatial(),
            mass: 2.5,
        })
        .collect();
    let n = bodies.len();
    let (ab, out, ke) = (
        arr(&bodies, dev),
        zeros::<SpatialVector, 1>(n, dev),
        zeros::<f32, 1>(n, dev),
    );
    wp::launch(k_bodies, n, (&ab, &out, &ke), dev).unwrap();
    let (got_b, got_h, got_ke) = (host(&ab), host(&out), host(&ke));
    let tol = gpu_tol(dev, true);
    for (k, b) in bodies.iter().enumerate() {
        let h = b.inertia * b.twist;
        close(
            &lanes_v(got_h[k].as_dspatial()),
            &lanes_v(h.as_dspatial()),
            tol,
            "momentum",
        );
        close(
            &[got_ke[k] as f64],
            &[(0.5 * b.twist.dot(h)) as f64],
            tol,
            "kinetic energy",
        );
        let mut want = *b;
        want.twist[0] = 2.5;
        assert_eq!(got_b[k], want, "field lane written back {k}");
    }
}

// ----- gradients -----

/// Every differentiable spatial builtin and operator in one scalar loss per thread, the
/// inputs assembled from f64 scalars (so that `gradcheck` nudges each lane).
#[wp::kernel]
pub(crate) fn k_spatial_loss(xs: Array<f64>, ms: Array<f64>, tq: Array<f64>, loss: Array<f64>) {
    let i = tid();
    let o = i * 12;
    let x = spatial_vector(xs[o], xs[o + 1], xs[o + 2], xs[o + 3], xs[o + 4], xs[o + 5]);
    let y = DSpatialVector::new(
        DVec3::new(xs[o + 6], xs[o + 7], xs[o + 8]),
        DVec3::new(xs[o + 9], xs[o + 10], xs[o + 11]),
    );
    let mut m = DSpatialMatrix::ZERO;
    m[0] = spatial_vector(ms[0], ms[1], ms[2], ms[3], ms[4], ms[5]);
    m[(1, 1)] = ms[6];
    m[(3, 2)] = ms[7];
    m[5][0] = ms[8];
    m[4] = x;
    let t = DTransform::new(
        DVec3::new(tq[0], tq[1], tq[2]),
        DQuat::from_xyzw(tq[3], tq[4], tq[5], tq[6]),
    );
    let r = DMat3::from_cols(
        DVec3::new(ms[9], ms[10], ms[11]),
        DVec3::new(ms[12], ms[13], ms[14]),
        DVec3::new(ms[15], ms[16], ms[17]),
    );
    let adj = spatial_adjoint(r, r * 0.5);
    let c = spatial_cross(x, y) + spatial_cross_dual(y, x) * 0.5 - x / 3.0;
    let mm = (m * transpose(adj)) * 0.25 - outer(c, y) * 0.125 + m.transpose();
    let z = mm * transform_twist(t, c) + (-transform_wrench(t, y));
    let mut l = spatial_dot(z, x) + spatial_top(z).dot(DVec3::new(0.3, -0.2, 0.1));
    l += spatial_bottom(c).dot(DVec3::new(-0.4, 0.7, 0.2)) + z[3] * mm[(2, 5)] + (2.0 * y)[1];
    loss[i] = l;
}

/// `gradcheck` in f64: the analytic Jacobian (the Tape's backward through every adjoint above)
/// against central differences with step 1e-6. The loss is a polynomial of degree <= 6 in
/// inputs of size <= 3, so its third derivatives are below ~1e4 and the truncation error below
/// 1e4 · 1e-12 = 1e-8; the rounding error is about 1e-16 · |loss| (<= 1e4) / 1e-6 = 1e-6: an
/// absolute and relative tolerance of 1e-5 holds with margin and would miss no wrong rule
/// (those are O(1) wrong).
fn spatial_gradients_match_finite_differences(dev: &wp::Device) {
    let ins = inputs();
    let n = 3;
    let xs: Vec<f64> = ins[..n]
        .iter()
        .flat_map(|c| [c.0.to_array(), c.1.to_array()].concat())
        .collect();
    let ms: Vec<f64> = (0..18).map(|k| ((k as f64) * 0.731).sin()).collect();
    let t = ins[3].3;
    let tq: Vec<f64> = t.to_array().to_vec();
    let xs = arr(&xs, dev).with_grad().unwrap();
    let ms = arr(&ms, dev).with_grad().unwrap();
    let tq = arr(&tq, dev).with_grad().unwrap();
    let loss = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_spatial_loss, n, (&xs, &ms, &tq, &loss), dev),
        &[&xs, &ms, &tq],
        &[&loss],
        wp::GradcheckOptions {
            eps: 1e-6,
            atol: 1e-5,
            rtol: 1e-5,
        },
    )
    .unwrap();
    assert!(report.passed, "{report:?}");
    // Not vacuous: every input reaches the loss somewhere.
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
pub(crate) fn k_spatial_array_loss(
    xs: Array<SpatialVector>,
    ms: Array<SpatialMatrix>,
    w: SpatialVector,
    loss: Array<f32>,
) {
    let i = tid();
    atomic_add(loss, 0, spatial_dot(ms[i] * xs[i], w));
}

/// `loss = Σ (m_i x_i) · w` through a Tape over arrays of spatial vectors and matrices:
/// `d loss / d x_i = m_iᵀ w` and `d loss / d m_i = w x_iᵀ`, warp-core's adjoints (bit for bit
/// on the CPU; `gpu_tol` on CUDA).
fn spatial_array_gradients(dev: &wp::Device) {
    let ins = inputs();
    let x0: Vec<SpatialVector> = ins.iter().map(|c| c.0.as_spatial()).collect();
    let m0: Vec<SpatialMatrix> = ins.iter().map(|c| c.2.as_spatial()).collect();
    let n = x0.len();
    let xs = arr(&x0, dev).with_grad().unwrap();
    let ms = arr(&m0, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let w = ins[0].1.as_spatial();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_spatial_array_loss, n, (&xs, &ms, w, &loss), dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    let (gx, gm) = (host(&xs.grad().unwrap()), host(&ms.grad().unwrap()));
    let tol = gpu_tol(dev, true);
    for k in 0..n {
        let want_x = m0[k].transpose() * w;
        close(
            &lanes_v(gx[k].as_dspatial()),
            &lanes_v(want_x.as_dspatial()),
            tol,
            "d/dx",
        );
        close(
            &lanes_m(gm[k].as_dspatial()),
            &lanes_m(w.outer(x0[k]).as_dspatial()),
            tol,
            "d/dm",
        );
    }
}

/// Forward mode through the rows with a tangent rule (`spatial_top`, `spatial_bottom`,
/// `spatial_dot`, `spatial_cross`, `spatial_cross_dual`, `transpose`, `outer`), the
/// operators and lane writes and reads; the values are assembled by lane writes (the
/// constructors have no forward rule).
#[wp::kernel]
pub(crate) fn k_spatial_fwd(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let o = i * 6;
    let mut a = DSpatialVector::ZERO;
    let mut b = DSpatialVector::ZERO;
    a[0] = x[o];
    a[1] = x[o + 1];
    a[2] = x[o + 2] * x[o];
    a[3] = 0.5;
    a[4] = x[o + 3];
    a[5] = x[o + 4];
    b[0] = x[o + 5];
    b[2] = x[o + 1] * x[o + 3];
    b[3] = -1.0;
    b[5] = x[o + 2];
    let c = spatial_cross(a, b) - spatial_cross_dual(b, a) * 0.5;
    let m = outer(c, a) + transpose(outer(b, c));
    let z = m * a + (2.0 * c) / 3.0;
    y[i] = spatial_dot(z, b) + spatial_top(z).dot(spatial_bottom(c)) + m[(2, 4)] * z[1];
}

/// `jvp` against the reverse Jacobian times the direction (f64: both exact derivatives with the
/// same roundings in another order, relative 1e-12) and against central differences (h = 1e-6:
/// truncation and rounding about 1e-10 for this polynomial of O(1) inputs, relative 1e-7).
fn spatial_jvp_matches_the_jacobian(dev: &wp::Device) {
    let n = 3;
    let xs: Vec<f64> = (0..n * 6)
        .map(|k| ((k as f64) * 0.61).sin() * 1.5)
        .collect();
    let vs: Vec<f64> = (0..n * 6).map(|k| ((k as f64) * 1.37).cos()).collect();
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(n, dev));
    wp::jvp(k_spatial_fwd, n, (&x, &y), (&v, &y_dot), dev).unwrap();
    let got = host(&y_dot);
    let j = wp::jacobian(|| wp::launch(k_spatial_fwd, n, (&x, &y), dev), &[&x], &[&y]).unwrap();
    let jv: Vec<f64> = j
        .iter()
        .map(|r| r.iter().zip(&vs).map(|(a, b)| a * b).sum())
        .collect();
    for k in 0..n {
        let tol = 1e-12 * jv[k].abs().max(1.0);
        assert!(
            (got[k] - jv[k]).abs() <= tol,
            "jvp vs J v [{k}]: {} vs {}",
            got[k],
            jv[k]
        );
    }
    let h = 1e-6;
    let shifted = |s: f64| {
        let xp: Vec<f64> = xs.iter().zip(&vs).map(|(a, b)| a + s * b).collect();
        let (xp, yp) = (arr(&xp, dev), zeros::<f64, 1>(n, dev));
        wp::launch(k_spatial_fwd, n, (&xp, &yp), dev).unwrap();
        host(&yp)
    };
    let (p, m) = (shifted(h), shifted(-h));
    for k in 0..n {
        let fd = (p[k] - m[k]) / (2.0 * h);
        assert!(
            (got[k] - fd).abs() <= 1e-7 * fd.abs().max(1.0),
            "jvp vs central differences [{k}]: {} vs {fd}",
            got[k]
        );
        assert!(got[k] != 0.0, "a nonzero tangent [{k}]");
    }
}

// ----- velocity_at_point -----

/// `velocity_at_point` in both spellings, for both precisions.
macro_rules! velocity_kernel {
    ($name:ident, $sv:ident, $v3:ident) => {
        #[wp::kernel]
        pub(crate) fn $name(qd: Array<$sv>, r: Array<$v3>, out: Array<$v3, 2>) {
            let i = tid();
            out[(i, 0)] = velocity_at_point(qd[i], r[i]);
            out[(i, 1)] = qd[i].velocity_at_point(r[i]);
        }
    };
}
velocity_kernel!(k_velocity64, DSpatialVector, DVec3);
velocity_kernel!(k_velocity32, SpatialVector, Vec3);

/// The cases: Warp's own (`warp/tests/test_math.py`, `spatial_helpers`: the twist
/// `((0, 0, 2), (1, 2, 3))` at `r = (0.5, 0, 0)` moves at `(1, 3, 3)`), then the inputs'
/// twists at offsets of size <= 3.
fn velocity_cases() -> Vec<(DSpatialVector, DVec3)> {
    let mut c = vec![(
        DSpatialVector::new(DVec3::new(0.0, 0.0, 2.0), DVec3::new(1.0, 2.0, 3.0)),
        DVec3::new(0.5, 0.0, 0.0),
    )];
    for (k, (x, y, _, _)) in inputs().into_iter().enumerate() {
        c.push((x, y.bottom() + DVec3::splat(k as f64 * 0.25)));
    }
    c
}

/// `v + w × r` in f64 as the matrix product `skew(w) r` (another order than the kernel's).
fn velocity_ref(qd: DSpatialVector, r: DVec3) -> DVec3 {
    qd.bottom() + skew(qd.top()) * r
}

fn velocity_at_point_f64(dev: &wp::Device) {
    let cases = velocity_cases();
    let n = cases.len();
    let qd: Vec<DSpatialVector> = cases.iter().map(|c| c.0).collect();
    let r: Vec<DVec3> = cases.iter().map(|c| c.1).collect();
    let out = zeros::<DVec3, 2>((n, 2), dev);
    wp::launch(k_velocity64, n, (&arr(&qd, dev), &arr(&r, dev), &out), dev).unwrap();
    let got = host(&out);
    let (gt, rt) = (gpu_tol(dev, false), ref_tol(false));
    assert_eq!(got[0].to_array(), [1.0, 3.0, 3.0], "Warp's test_math case");
    for k in 0..n {
        let host_v = qd[k].velocity_at_point(r[k]);
        for s in 0..2 {
            let g = got[k * 2 + s].to_array();
            close(
                &g,
                &host_v.to_array(),
                gt,
                &format!("case {k} spelling {s}: host"),
            );
            let want = velocity_ref(qd[k], r[k]).to_array();
            close(
                &g,
                &want,
                rt,
                &format!("case {k} spelling {s}: v + skew(w) r"),
            );
        }
    }
}

fn velocity_at_point_f32(dev: &wp::Device) {
    let cases = velocity_cases();
    let n = cases.len();
    let qd: Vec<SpatialVector> = cases.iter().map(|c| c.0.as_spatial()).collect();
    let r: Vec<Vec3> = cases.iter().map(|c| c.1.as_vec3()).collect();
    let out = zeros::<Vec3, 2>((n, 2), dev);
    wp::launch(k_velocity32, n, (&arr(&qd, dev), &arr(&r, dev), &out), dev).unwrap();
    let got = host(&out);
    let (gt, rt) = (gpu_tol(dev, true), ref_tol(true));
    assert_eq!(got[0].to_array(), [1.0, 3.0, 3.0], "Warp's test_math case");
    for k in 0..n {
        let host_v = qd[k].velocity_at_point(r[k]);
        let up = |v: Vec3| v.as_dvec3().to_array();
        for s in 0..2 {
            let g = up(got[k * 2 + s]);
            close(&g, &up(host_v), gt, &format!("case {k} spelling {s}: host"));
            // The reference of the f32 inputs, widened exactly.
            let want = velocity_ref(qd[k].as_dspatial(), r[k].as_dvec3()).to_array();
            close(
                &g,
                &want,
                rt,
                &format!("case {k} spelling {s}: v + skew(w) r"),
            );
        }
    }
}

/// IEEE propagation, lane by lane as the formula reads: an infinite angular lane times a
/// zero offset lane is NaN where the cross product forms that product (`w = (inf, 0, 0)`,
/// `r = (0, 1, 0)`: `w × r = (0·0 - 1·0, 0·0 - 0·inf, inf·1 - 0·0) = (0, NaN, inf)`), and a
/// NaN linear lane stays in its own lane.
fn velocity_at_point_nonfinite(dev: &wp::Device) {
    let qd = vec![
        DSpatialVector::new(
            DVec3::new(f64::INFINITY, 0.0, 0.0),
            DVec3::new(1.0, 2.0, 3.0),
        ),
        DSpatialVector::new(DVec3::new(0.0, 0.0, 1.0), DVec3::new(f64::NAN, 2.0, 3.0)),
    ];
    let r = vec![DVec3::new(0.0, 1.0, 0.0), DVec3::new(1.0, 0.0, 0.0)];
    let out = zeros::<DVec3, 2>((2, 2), dev);
    wp::launch(k_velocity64, 2, (&arr(&qd, dev), &arr(&r, dev), &out), dev).unwrap();
    let got = host(&out);
    for s in 0..2 {
        let a = got[s];
        assert!(
            a.x == 1.0 && a.y.is_nan() && a.z == f64::INFINITY,
            "inf w: {a:?}"
        );
        let b = got[2 + s];
        // w × r = (0, 1, 0) for w = (0, 0, 1), r = (1, 0, 0).
        assert!(b.x.is_nan() && b.y == 3.0 && b.z == 3.0, "NaN v: {b:?}");
    }
}

/// A loss through `velocity_at_point` in both spellings, nonlinear in the twist and the offset
/// (so that every term of the adjoint meets a different weight).
#[wp::kernel]
pub(crate) fn k_velocity_loss(xs: Array<f64>, loss: Array<f64>) {
    let i = tid();
    let o = i * 9;
    // Lane writes (the spatial constructors have no forward rule).
    let mut qd = DSpatialVector::ZERO;
    qd[0] = xs[o];
    qd[1] = xs[o + 1];
    qd[2] = xs[o + 2];
    qd[3] = xs[o + 3];
    qd[4] = xs[o + 4];
    qd[5] = xs[o + 5];
    let r = DVec3::new(xs[o + 6], xs[o + 7], xs[o + 8]);
    let v = velocity_at_point(qd, r);
    let u = (qd * 0.5).velocity_at_point(v);
    loss[i] = v.dot(v) + u.dot(DVec3::new(0.3, -0.7, 0.2)) + v.x * r.y;
}

/// `gradcheck` in f64, central differences with step 1e-6: the loss is a polynomial of degree
/// <= 4 in inputs of size <= 3, third derivatives below ~1e3, truncation below 1e-9 and
/// rounding about 1e-16 · 1e3 / 1e-6 = 1e-7; atol = rtol = 1e-5 has margin and would miss no
/// wrong rule (those are O(1) wrong).
fn velocity_at_point_gradients(dev: &wp::Device) {
    let n = 4;
    let xs: Vec<f64> = (0..n * 9)
        .map(|k| ((k as f64) * 0.77 + 0.3).sin() * 2.0)
        .collect();
    let xs = arr(&xs, dev).with_grad().unwrap();
    let loss = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_velocity_loss, n, (&xs, &loss), dev),
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
    assert_eq!(touched, n * 9, "every input has a gradient");
}

/// Forward mode through `velocity_at_point`'s rule, against the reverse Jacobian times the
/// direction (both exact derivatives, roundings in another order: relative 1e-12).
fn velocity_at_point_jvp(dev: &wp::Device) {
    let n = 3;
    let xs: Vec<f64> = (0..n * 9)
        .map(|k| ((k as f64) * 0.53).cos() * 1.5)
        .collect();
    let vs: Vec<f64> = (0..n * 9).map(|k| ((k as f64) * 1.31).sin()).collect();
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(n, dev));
    wp::jvp(k_velocity_loss, n, (&x, &y), (&v, &y_dot), dev).unwrap();
    let got = host(&y_dot);
    let j = wp::jacobian(
        || wp::launch(k_velocity_loss, n, (&x, &y), dev),
        &[&x],
        &[&y],
    )
    .unwrap();
    for k in 0..n {
        let jv: f64 = j[k].iter().zip(&vs).map(|(a, b)| a * b).sum();
        assert!(
            (got[k] - jv).abs() <= 1e-12 * jv.abs().max(1.0),
            "jvp vs J v [{k}]: {} vs {jv}",
            got[k]
        );
        assert!(got[k] != 0.0, "a nonzero tangent [{k}]");
    }
}

//! `lerp` of square matrices, quaternions and spatial vectors and matrices (Warp's overloads
//! beyond scalars, vectors and transforms, whose tests are in `builtins.rs` and
//! `transforms.rs`): `a * (1 - t) + b * t` lane by lane, the quaternion not renormalized.
//!
//! Checked against Warp's own expected values (`warp/tests/test_lerp.py`, all exact at
//! `t = 0.5`), against warp-core's `lerp` (the function the CPU backend calls: bit for bit on
//! the CPU; on CUDA within [`gpu_tol`]), against the lane formula in f64, for what non-finite
//! inputs give, and through `gradcheck` and `jvp` in f64.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    lerp_overloads_f32,
    lerp_overloads_f64,
    lerp_warp_expected_values,
    lerp_nonfinite,
    lerp_overloads_gradients,
    lerp_overloads_jvp,
);

/// Backend parity: 0 on the CPU (the kernel runs warp-core's function); on CUDA one FMA
/// contraction per lane changes at most one rounding of a value of size <= 3 (f32 eps 6e-8,
/// f64 1.1e-16): 1e-6 and 1e-15 absolute, with margin.
fn gpu_tol(dev: &wp::Device, f32: bool) -> f64 {
    match (dev.is_cpu(), f32) {
        (true, _) => 0.0,
        (false, true) => 1e-6,
        (false, false) => 1e-15,
    }
}

/// Every lane of the kernel's result against `want` within `tol` (absolute: lanes <= 3).
#[track_caller]
fn close(got: &[f64], want: &[f64], tol: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            g == w || (g - w).abs() <= tol,
            "{what} lane {k}: got {g}, want {w} (tol {tol:e})"
        );
    }
}

/// Deterministic lanes in [-3, 3].
fn lane(k: usize) -> f64 {
    ((k as f64 * 12.9898).sin() * 43758.5453).fract() * 3.0
}

macro_rules! lerp_kernel {
    ($name:ident, $s:ident, $m2:ident, $m3:ident, $m4:ident, $q:ident, $sv:ident, $sm:ident) => {
        #[wp::kernel]
        pub(crate) fn $name(
            t: Array<$s>,
            m2: Array<$m2>,
            m3: Array<$m3>,
            m4: Array<$m4>,
            q: Array<$q>,
            sv: Array<$sv>,
            sm: Array<$sm>,
            o2: Array<$m2, 2>,
            o3: Array<$m3, 2>,
            o4: Array<$m4, 2>,
            oq: Array<$q, 2>,
            osv: Array<$sv, 2>,
            osm: Array<$sm, 2>,
        ) {
            // Thread i interpolates element i towards element i + 1.
            let i = tid();
            let s = t[i];
            o2[(i, 0)] = lerp(m2[i], m2[i + 1], s);
            o2[(i, 1)] = m2[i].lerp(m2[i + 1], s);
            o3[(i, 0)] = lerp(m3[i], m3[i + 1], s);
            o3[(i, 1)] = m3[i].lerp(m3[i + 1], s);
            o4[(i, 0)] = lerp(m4[i], m4[i + 1], s);
            o4[(i, 1)] = m4[i].lerp(m4[i + 1], s);
            oq[(i, 0)] = lerp(q[i], q[i + 1], s);
            oq[(i, 1)] = q[i].lerp(q[i + 1], s);
            osv[(i, 0)] = lerp(sv[i], sv[i + 1], s);
            osv[(i, 1)] = sv[i].lerp(sv[i + 1], s);
            osm[(i, 0)] = lerp(sm[i], sm[i + 1], s);
            osm[(i, 1)] = sm[i].lerp(sm[i + 1], s);
        }
    };
}
lerp_kernel!(
    k_lerp32,
    f32,
    Mat2,
    Mat3,
    Mat4,
    Quat,
    SpatialVector,
    SpatialMatrix
);
lerp_kernel!(
    k_lerp64,
    f64,
    DMat2,
    DMat3,
    DMat4,
    DQuat,
    DSpatialVector,
    DSpatialMatrix
);

/// One type's lanes: to and from a flat array (matrices column-major, spatial matrices
/// row-major: lerp does not care, each lane is its own).
trait Lanes: Copy + wp::Element {
    fn lanes(self) -> Vec<f64>;
    fn of(l: &[f64]) -> Self;
}
macro_rules! lanes {
    ($($t:ty: $n:literal, |$x:ident| $to:expr, |$l:ident| $from:expr);* $(;)?) => {$(
        impl Lanes for $t {
            fn lanes(self) -> Vec<f64> {
                let $x = self;
                $to
            }
            fn of($l: &[f64]) -> Self {
                $from
            }
        }
    )*};
}
lanes!(
    Mat2: 4, |x| x.to_cols_array().map(f64::from).to_vec(),
        |l| Mat2::from_cols_array(&std::array::from_fn(|k| l[k] as f32));
    Mat3: 9, |x| x.to_cols_array().map(f64::from).to_vec(),
        |l| Mat3::from_cols_array(&std::array::from_fn(|k| l[k] as f32));
    Mat4: 16, |x| x.to_cols_array().map(f64::from).to_vec(),
        |l| Mat4::from_cols_array(&std::array::from_fn(|k| l[k] as f32));
    Quat: 4, |x| x.to_array().map(f64::from).to_vec(),
        |l| Quat::from_array(std::array::from_fn(|k| l[k] as f32));
    SpatialVector: 6, |x| x.to_array().map(f64::from).to_vec(),
        |l| SpatialVector::from_array(std::array::from_fn(|k| l[k] as f32));
    SpatialMatrix: 36, |x| x.to_rows_array().concat().iter().map(|&v| v as f64).collect(),
        |l| SpatialMatrix::from_rows_array(std::array::from_fn(|i| std::array::from_fn(|j| l[i * 6 + j] as f32)));
    DMat2: 4, |x| x.to_cols_array().to_vec(), |l| DMat2::from_cols_slice(l);
    DMat3: 9, |x| x.to_cols_array().to_vec(), |l| DMat3::from_cols_slice(l);
    DMat4: 16, |x| x.to_cols_array().to_vec(), |l| DMat4::from_cols_slice(l);
    DQuat: 4, |x| x.to_array().to_vec(), |l| DQuat::from_slice(l);
    DSpatialVector: 6, |x| x.to_array().to_vec(),
        |l| DSpatialVector::from_array(std::array::from_fn(|k| l[k]));
    DSpatialMatrix: 36, |x| x.to_rows_array().concat(),
        |l| DSpatialMatrix::from_rows_array(std::array::from_fn(|i| std::array::from_fn(|j| l[i * 6 + j])));
);

/// `n + 1` values of a type with `lanes` lanes, lane `k` of value `v` being `lane(seed + ..)`.
fn values<T: Lanes>(n: usize, lanes: usize, seed: usize) -> Vec<T> {
    (0..=n)
        .map(|v| {
            let l: Vec<f64> = (0..lanes).map(|k| lane(seed + v * 37 + k)).collect();
            T::of(&l)
        })
        .collect()
}

/// The six overloads, each checked against warp-core and against the lane formula in f64.
struct Run<'a> {
    dev: &'a wp::Device,
    ts: Vec<f64>,
    f32: bool,
}

impl Run<'_> {
    /// `ins` are the kernel's inputs of one type, `out` its (n, 2) output; `host` warp-core's
    /// `lerp` of that type.
    fn check<T: Lanes>(&self, ins: &[T], out: &[T], host: impl Fn(T, T, usize) -> T, what: &str) {
        let gt = gpu_tol(self.dev, self.f32);
        // The formula in f64 on the (exactly widened) inputs: f32 rounds each of its three
        // operations once (relative 6e-8 of lanes <= 3, so about 1e-6 absolute); f64 likewise
        // at 1.1e-16 (about 1e-15).
        let rt = if self.f32 { 1e-6 } else { 1e-15 };
        for i in 0..self.ts.len() {
            let (a, b, t) = (ins[i].lanes(), ins[i + 1].lanes(), self.ts[i]);
            let want: Vec<f64> = a
                .iter()
                .zip(&b)
                .map(|(x, y)| x * (1.0 - t) + y * t)
                .collect();
            let h = host(ins[i], ins[i + 1], i).lanes();
            for s in 0..2 {
                let got = out[i * 2 + s].lanes();
                close(
                    &got,
                    &h,
                    gt,
                    &format!("{what} [{i}] spelling {s}: warp-core"),
                );
                close(
                    &got,
                    &want,
                    rt,
                    &format!("{what} [{i}] spelling {s}: formula"),
                );
            }
        }
    }
}

macro_rules! lerp_test {
    ($dev:expr, $kernel:ident, $f32:expr, $s:ident, $m2:ident, $m3:ident, $m4:ident, $q:ident,
     $sv:ident, $sm:ident) => {{
        let dev: &wp::Device = $dev;
        let n = 5;
        // t in and beyond [0, 1] (Warp extrapolates likewise), exact in f32.
        let ts: Vec<$s> = vec![0.0, 0.25, 0.5, 1.0, -0.75];
        let (m2, m3, m4) = (
            values::<$m2>(n, 4, 1),
            values::<$m3>(n, 9, 2),
            values::<$m4>(n, 16, 3),
        );
        let (q, sv, sm) = (
            values::<$q>(n, 4, 4),
            values::<$sv>(n, 6, 5),
            values::<$sm>(n, 36, 6),
        );
        let (o2, o3, o4) = (
            zeros::<$m2, 2>((n, 2), dev),
            zeros::<$m3, 2>((n, 2), dev),
            zeros::<$m4, 2>((n, 2), dev),
        );
        let (oq, osv, osm) = (
            zeros::<$q, 2>((n, 2), dev),
            zeros::<$sv, 2>((n, 2), dev),
            zeros::<$sm, 2>((n, 2), dev),
        );
        wp::launch(
            $kernel,
            n,
            (
                &arr(&ts, dev),
                &arr(&m2, dev),
                &arr(&m3, dev),
                &arr(&m4, dev),
                &arr(&q, dev),
                &arr(&sv, dev),
                &arr(&sm, dev),
                &o2,
                &o3,
                &o4,
                &oq,
                &osv,
                &osm,
            ),
            dev,
        )
        .unwrap();
        let run = Run {
            dev,
            ts: ts.iter().map(|&t| t as f64).collect(),
            f32: $f32,
        };
        // warp-core's lerp, generic: one closure per type.
        macro_rules! l {
            () => {
                |a, b, i: usize| wp::__private::builtins::lerp(a, b, ts[i])
            };
        }
        run.check(&m2, &host(&o2), l!(), "Mat2");
        run.check(&m3, &host(&o3), l!(), "Mat3");
        run.check(&m4, &host(&o4), l!(), "Mat4");
        run.check(&q, &host(&oq), l!(), "Quat");
        run.check(&sv, &host(&osv), l!(), "SpatialVector");
        run.check(&sm, &host(&osm), l!(), "SpatialMatrix");
    }};
}

fn lerp_overloads_f32(dev: &wp::Device) {
    lerp_test!(
        dev,
        k_lerp32,
        true,
        f32,
        Mat2,
        Mat3,
        Mat4,
        Quat,
        SpatialVector,
        SpatialMatrix
    );
}

fn lerp_overloads_f64(dev: &wp::Device) {
    lerp_test!(
        dev,
        k_lerp64,
        false,
        f64,
        DMat2,
        DMat3,
        DMat4,
        DQuat,
        DSpatialVector,
        DSpatialMatrix
    );
}

#[wp::kernel]
pub(crate) fn k_lerp_warp(
    m2: Array<Mat2>,
    m3: Array<Mat3>,
    m4: Array<Mat4>,
    q: Array<Quat>,
    sv: Array<SpatialVector>,
    sm: Array<SpatialMatrix>,
    t: f32,
) {
    // In place: element 0 becomes lerp(element 0, element 1, t).
    m2[0] = lerp(m2[0], m2[1], t);
    m3[0] = lerp(m3[0], m3[1], t);
    m4[0] = lerp(m4[0], m4[1], t);
    q[0] = lerp(q[0], q[1], t);
    sv[0] = lerp(sv[0], sv[1], t);
    sm[0] = lerp(sm[0], sm[1], t);
}

/// Warp's `TEST_DATA` of test_lerp.py for these types: `b` is `a + 2` lane by lane (Warp's
/// matrices written row by row; here the same lanes are read into glam's columns, which lerp,
/// lane by lane, does not see), and `lerp(a, b, 0.5) = a + 1`, exactly. Warp's quaternion case
/// is `(1, 2, 3, 4)` to `(3, 4, 5, 6)`: `(2, 3, 4, 5)`, not renormalized.
fn lerp_warp_expected_values(dev: &wp::Device) {
    // Warp's rows: a cyclic shift of 1..n per row, b the same plus 2.
    let cyc = |n: usize| -> Vec<f64> {
        (0..n * n)
            .map(|k| (((k % n) + n - k / n) % n + 1) as f64)
            .collect()
    };
    let plus = |v: &[f64], d: f64| -> Vec<f64> { v.iter().map(|x| x + d).collect() };
    let (c2, c3, c4, c6) = (cyc(2), cyc(3), cyc(4), cyc(6));
    let qa = vec![1.0, 2.0, 3.0, 4.0];
    let sva = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    let m2 = arr(&[Mat2::of(&c2), Mat2::of(&plus(&c2, 2.0))], dev);
    let m3 = arr(&[Mat3::of(&c3), Mat3::of(&plus(&c3, 2.0))], dev);
    let m4 = arr(&[Mat4::of(&c4), Mat4::of(&plus(&c4, 2.0))], dev);
    let q = arr(&[Quat::of(&qa), Quat::of(&plus(&qa, 2.0))], dev);
    let sv = arr(
        &[SpatialVector::of(&sva), SpatialVector::of(&plus(&sva, 2.0))],
        dev,
    );
    let sm = arr(
        &[SpatialMatrix::of(&c6), SpatialMatrix::of(&plus(&c6, 2.0))],
        dev,
    );
    wp::launch(k_lerp_warp, 1, (&m2, &m3, &m4, &q, &sv, &sm, 0.5f32), dev).unwrap();
    assert_eq!(host(&m2)[0].lanes(), plus(&c2, 1.0), "mat22");
    assert_eq!(host(&m3)[0].lanes(), plus(&c3, 1.0), "mat33");
    assert_eq!(host(&m4)[0].lanes(), plus(&c4, 1.0), "mat44");
    assert_eq!(host(&q)[0].lanes(), vec![2.0, 3.0, 4.0, 5.0], "quat");
    assert_eq!(host(&sv)[0].lanes(), plus(&sva, 1.0), "spatial_vector");
    assert_eq!(host(&sm)[0].lanes(), plus(&c6, 1.0), "spatial_matrix");
}

/// IEEE propagation through `a * (1 - t) + b * t`, lane by lane: an infinite lane of `a`
/// survives `t = 0` (`inf * 1 + b * 0`) and is NaN at `t = 1` (`inf * 0`); `t = inf` makes
/// every lane NaN (`a * -inf + b * inf` is `inf - inf` where `a` and `b` have a lane's sign,
/// and `0 * inf` where a lane is 0); a NaN lane stays in its lane.
fn lerp_nonfinite(dev: &wp::Device) {
    let mut a = [0.5f32, -1.0, 2.0, 0.0];
    a[1] = f32::INFINITY;
    let mut b = [1.0f32, 1.0, 3.0, 0.0];
    b[2] = f32::NAN;
    let m = |l: [f32; 4]| Mat2::from_cols_array(&l);
    let q = |l: [f32; 4]| Quat::from_array(l);
    let cases: [(f32, [f32; 4]); 3] = [
        (0.0, [0.5, f32::INFINITY, f32::NAN, 0.0]),
        (1.0, [1.0, f32::NAN, f32::NAN, 0.0]),
        (f32::INFINITY, [f32::NAN; 4]),
    ];
    for (t, want) in cases {
        let m2 = arr(&[m(a), m(b)], dev);
        let m3 = arr(&[Mat3::ZERO, Mat3::ZERO], dev);
        let m4 = arr(&[Mat4::ZERO, Mat4::ZERO], dev);
        let qs = arr(&[q(a), q(b)], dev);
        let sv = arr(&[SpatialVector::ZERO; 2], dev);
        let sm = arr(&[SpatialMatrix::ZERO; 2], dev);
        wp::launch(k_lerp_warp, 1, (&m2, &m3, &m4, &qs, &sv, &sm, t), dev).unwrap();
        let same = |got: [f32; 4], what: &str| {
            for k in 0..4 {
                let (g, w) = (got[k], want[k]);
                assert!(
                    g == w || (g.is_nan() && w.is_nan()),
                    "{what} t = {t} lane {k}: got {g}, want {w}"
                );
            }
        };
        same(host(&m2)[0].to_cols_array(), "Mat2");
        same(host(&qs)[0].to_array(), "Quat");
        if t.is_infinite() {
            // Zero lanes too: 0 * -inf + 0 * inf.
            assert!(
                host(&m3)[0].to_cols_array().iter().all(|x| x.is_nan()),
                "Mat3 at t = inf"
            );
        } else {
            assert_eq!(host(&m3)[0], Mat3::ZERO, "Mat3 of zeros at t = {t}");
        }
    }
}

/// Every overload in one f64 loss per thread, the values assembled from scalars (so that
/// `gradcheck` nudges each lane), nonlinear in each (so that every lane's adjoint meets a
/// different weight).
#[wp::kernel]
pub(crate) fn k_lerp_loss(x: Array<f64>, loss: Array<f64>) {
    let i = tid();
    let o = i * 24;
    let t = x[o];
    let a = DMat3::from_cols(
        DVec3::new(x[o + 1], x[o + 2], x[o + 3]),
        DVec3::new(x[o + 4], x[o + 5], x[o + 6]),
        DVec3::new(0.5, x[o + 7], -0.25),
    );
    let b = DMat3::from_cols(
        DVec3::new(x[o + 8], 0.75, x[o + 9]),
        DVec3::new(x[o + 10], x[o + 11], 0.125),
        DVec3::new(x[o + 12], x[o + 13], x[o + 14]),
    );
    let m = lerp(a, b, t);
    let p = DQuat::from_xyzw(x[o + 15], x[o + 16], x[o + 17], x[o + 18]);
    let r = DQuat::from_xyzw(x[o + 19], x[o + 20], 0.5, x[o + 21]);
    let qq = p.lerp(r, 1.0 - t * 0.5);
    let mut u = DSpatialVector::ZERO;
    u[0] = x[o + 22];
    u[3] = x[o + 23];
    u[5] = t;
    let mut w = DSpatialVector::ZERO;
    w[1] = x[o + 1];
    w[3] = x[o + 8];
    w[4] = 2.0;
    let z = lerp(u, w, t * t);
    let mut sa = DSpatialMatrix::ZERO;
    sa[(0, 1)] = x[o + 2];
    sa[(4, 5)] = x[o + 23];
    let mut sb = DSpatialMatrix::ZERO;
    sb[(0, 1)] = x[o + 9];
    sb[(2, 3)] = x[o + 22];
    let n = sa.lerp(sb, t);
    let mm = m * m;
    loss[i] = mm.x_axis.y
        + mm.z_axis.z * m.y_axis.x
        + qq.dot(qq)
        + qq.w * p.x
        + spatial_dot(z, z)
        + z[0] * u[3]
        + n[(0, 1)] * n[(0, 1)]
        + n[(2, 3)] * t
        + n[(4, 5)];
}

fn lerp_inputs(n: usize) -> Vec<f64> {
    (0..n * 24)
        .map(|k| ((k as f64) * 0.917 + 0.2).sin() * 1.5)
        .collect()
}

/// `gradcheck` in f64, central differences with step 1e-6: the loss is a polynomial of degree
/// <= 5 in inputs of size <= 1.5, its third derivatives below ~1e3, so truncation below 1e-9
/// and rounding about 1e-16 · 1e2 / 1e-6 = 1e-8: atol = rtol = 1e-6 has margin and would miss
/// no wrong rule (those are O(1) wrong).
fn lerp_overloads_gradients(dev: &wp::Device) {
    let n = 3;
    let x = arr(&lerp_inputs(n), dev).with_grad().unwrap();
    let loss = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_lerp_loss, n, (&x, &loss), dev),
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
    let touched = (0..report.analytic[0].len())
        .filter(|&c| report.analytic.iter().any(|r| r[c] != 0.0))
        .count();
    assert_eq!(touched, n * 24, "every input has a gradient");
}

/// `lerp`'s forward rule on these types against the reverse Jacobian times the direction (both
/// exact derivatives, roundings in another order: relative 1e-12).
fn lerp_overloads_jvp(dev: &wp::Device) {
    let n = 3;
    let xs = lerp_inputs(n);
    let vs: Vec<f64> = (0..n * 24).map(|k| ((k as f64) * 1.77).cos()).collect();
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(n, dev));
    wp::jvp(k_lerp_loss, n, (&x, &y), (&v, &y_dot), dev).unwrap();
    let got = host(&y_dot);
    let j = wp::jacobian(|| wp::launch(k_lerp_loss, n, (&x, &y), dev), &[&x], &[&y]).unwrap();
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

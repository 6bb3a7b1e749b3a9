//! The matrix decompositions `svd3`, `eig3`, `qr3`, `svd2` (tuple results, destructured by
//! `let`), in f32 and f64, against their defining properties and closed forms.
//!
//! Tolerances: the decompositions are built from rotations (Warp's algorithms: Jacobi sweeps
//! accumulated as a quaternion, 5 sweeps in f32 (Warp: 4) and 8 in f64, then three Givens
//! rotations),
//! so their rounding error grows with the number of rotations, not with the matrix. Each of
//! the `3 * sweeps` Jacobi rotations leaves the accumulated quaternion's norm off by about
//! 2 ulps, and the rotation matrix of a quaternion `q` is off from orthogonal by `4 (|q| - 1)`;
//! the Givens rotations of the QR and the products `A V`, `Qᵀ A Q` add a few more. So
//! `tol = 24 * sweeps * eps` (f32: 120 eps = 1.4e-5; f64: 192 eps = 4.3e-14), relative to
//! `max |A|`, bounds orthogonality (`UᵀU - I`), reconstruction (`U diag(σ) Vᵀ - A`) and the
//! singular values and eigenvalues against closed forms (Weyl: a perturbation of the matrix by
//! `δ` moves them by at most `δ`) — once the sweeps have converged. Measured on 20,000 random
//! matrices: orthogonality within 31 eps (f32) and 61 eps (f64), reconstruction within 67 eps
//! (f64). Convergence: 8 sweeps always converge in f64 here, and 5 in f32 (Warp's 4 do not
//! for about 1 random matrix in 40: reconstruction errors up to 1.4e-2 of `max |A|`, which is
//! why f32 runs 5; see docs/book/src/builtins.md); random matrices are checked in both precisions. On CUDA the compiler may contract products into FMAs, which changes the
//! last bits but not these bounds.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    svd3_properties_f64,
    svd3_properties_f32,
    svd3_random,
    svd3_edge_cases,
    eig3_closed_forms,
    qr3_properties,
    svd2_properties,
    nan_input_terminates,
);

/// All four 3x3 decompositions of each matrix, in the precision of the arrays.
#[wp::kernel]
fn k_decomp<T: Float>(
    a: Array<Mat3<T>>,
    u: Array<Mat3<T>>,
    s: Array<Vec3<T>>,
    v: Array<Mat3<T>>,
    eq: Array<Mat3<T>>,
    ed: Array<Vec3<T>>,
    qq: Array<Mat3<T>>,
    qr: Array<Mat3<T>>,
) {
    let i = tid();
    let m = a[i];
    let (uu, sigma, vv) = svd3(m);
    u[i] = uu;
    s[i] = sigma;
    v[i] = vv;
    // eig3 of the symmetric part.
    let (q, d) = wp::eig3((m + m.transpose()) * 0.5);
    eq[i] = q;
    ed[i] = d;
    let (q2, r): (Mat3<T>, Mat3<T>) = qr3(m);
    qq[i] = q2;
    qr[i] = r;
}

#[wp::kernel]
fn k_svd2<T: Float>(a: Array<Mat2<T>>, u: Array<Mat2<T>>, s: Array<Vec2<T>>, v: Array<Mat2<T>>) {
    let i = tid();
    let (uu, sigma, vv) = svd2(a[i]);
    u[i] = uu;
    s[i] = sigma;
    v[i] = vv;
}

/// What `k_decomp` computes, back in f64.
struct Decomp {
    u: DMat3,
    s: DVec3,
    v: DMat3,
    eq: DMat3,
    ed: DVec3,
    qq: DMat3,
    qr: DMat3,
}

/// Runs `k_decomp` in one precision on `ms` (rounded to it) and brings the results back in f64.
macro_rules! run_in {
    ($name:ident, $m:ty, $v:ty, $to_m:expr, $m_back:expr, $v_back:expr) => {
        fn $name(ms: &[DMat3], dev: &wp::Device) -> Vec<Decomp> {
            let n = ms.len();
            let ms: Vec<$m> = ms.iter().map($to_m).collect();
            let a = arr(&ms, dev);
            let mats = || zeros::<$m, 1>(n, dev);
            let (u, v, eq, qq, qr) = (mats(), mats(), mats(), mats(), mats());
            let (s, ed) = (zeros::<$v, 1>(n, dev), zeros::<$v, 1>(n, dev));
            wp::launch(k_decomp, n, (&a, &u, &s, &v, &eq, &ed, &qq, &qr), dev).unwrap();
            let back_m = |x: &wp::Array<$m>| host(x).into_iter().map($m_back).collect::<Vec<_>>();
            let back_v = |x: &wp::Array<$v>| host(x).into_iter().map($v_back).collect::<Vec<_>>();
            let (u, s, v, eq, ed, qq, qr) = (
                back_m(&u),
                back_v(&s),
                back_m(&v),
                back_m(&eq),
                back_v(&ed),
                back_m(&qq),
                back_m(&qr),
            );
            (0..n)
                .map(|i| Decomp {
                    u: u[i],
                    s: s[i],
                    v: v[i],
                    eq: eq[i],
                    ed: ed[i],
                    qq: qq[i],
                    qr: qr[i],
                })
                .collect()
        }
    };
}
run_in!(
    run64,
    DMat3,
    DVec3,
    |m: &DMat3| *m,
    |m: DMat3| m,
    |v: DVec3| v
);
run_in!(
    run32,
    Mat3,
    Vec3,
    |m: &DMat3| m.as_mat3(),
    |m: Mat3| m.as_dmat3(),
    |v: Vec3| v.as_dvec3()
);

/// `24 * sweeps * eps` (see the module documentation).
const TOL32: f64 = 24.0 * 5.0 * f32::EPSILON as f64;
const TOL64: f64 = 24.0 * 8.0 * f64::EPSILON;

fn max_abs(m: DMat3) -> f64 {
    m.to_cols_array().iter().fold(0.0, |a, x| a.max(x.abs()))
}

fn diagonal(m: DMat3) -> DVec3 {
    DVec3::new(m.x_axis.x, m.y_axis.y, m.z_axis.z)
}

fn rot(axis: DVec3, angle: f64) -> DMat3 {
    DMat3::from_quat(DQuat::from_axis_angle(axis.normalize(), angle))
}

/// `r1 diag(s) r2ᵀ`: a matrix with singular values `|s|` (rotations keep them).
fn with_singular_values(s: [f64; 3], k: usize) -> DMat3 {
    let k = k as f64;
    let r1 = rot(DVec3::new(1.0, 2.0 + k, -0.5), 0.7 + 0.3 * k);
    let r2 = rot(DVec3::new(-0.3, 1.0, 2.0 - k), -1.1 + 0.2 * k);
    r1 * DMat3::from_diagonal(DVec3::from_array(s)) * r2.transpose()
}

/// The SVD's defining properties within `tol` (relative to `max |a|`); `want` the singular
/// values if known (`|σ|`, descending).
#[track_caller]
fn check_svd(a: DMat3, d: &Decomp, tol: f64, want: Option<[f64; 3]>, what: &str) {
    let scale = max_abs(a).max(f64::MIN_POSITIVE);
    let (u, s, v) = (d.u, d.s, d.v);
    let back = u * DMat3::from_diagonal(s) * v.transpose();
    let rec = max_abs(back - a) / scale;
    assert!(
        rec <= tol,
        "{what}: reconstruction {rec:e} > {tol:e} ({a} -> {s})"
    );
    for (m, name) in [(u, "U"), (v, "V")] {
        let o = max_abs(m.transpose() * m - DMat3::IDENTITY);
        assert!(o <= tol, "{what}: {name} orthogonality {o:e}");
        // Rotations, never reflections (Warp's convention: the sign goes to σ2).
        assert!(
            (m.determinant() - 1.0).abs() <= 3.0 * tol,
            "{what}: det {name}"
        );
    }
    // Sorted by the lengths of the columns of `A V`; σ is the diagonal of `R`, equal to those
    // lengths up to rounding (so two singular values at rounding level may come out swapped).
    let slack = tol * scale;
    assert!(
        s.x + slack >= s.y && s.y + slack >= s.z.abs(),
        "{what}: not sorted: {s}"
    );
    assert!(
        s.x >= 0.0 && s.y >= 0.0,
        "{what}: negative leading singular value {s}"
    );
    let det = a.determinant();
    if det.abs() > 10.0 * tol * scale * scale * scale {
        assert_eq!(s.z < 0.0, det < 0.0, "{what}: sign of σ2 {s} vs det {det}");
    }
    if let Some(w) = want {
        for k in 0..3 {
            let e = (s[k].abs() - w[k]).abs() / scale;
            assert!(e <= tol, "{what}: σ{k} = {} vs {} ({e:e})", s[k], w[k]);
        }
    }
}

/// Matrices with known singular values that 4 sweeps in f32 resolve too.
fn known() -> Vec<(DMat3, [f64; 3])> {
    let mut v = Vec::new();
    for (k, s) in [
        [3.0f64, 2.0, 1.0],
        [5.0, 1.0, -0.5],
        [2.0, 2.0, 1.0], // repeated
        [1.0, 1.0, 1.0], // all equal: a rotation
        [4.0, 0.5, 0.0], // rank 2
        [3.0, 0.0, 0.0], // rank 1
        [1.0, 1e-3, 1e-3],
    ]
    .iter()
    .enumerate()
    {
        let sorted = [s[0], s[1], s[2].abs()];
        v.push((with_singular_values(*s, k), sorted));
    }
    v.push((
        DMat3::from_diagonal(DVec3::new(3.0, -1.0, 2.0)),
        [3.0, 2.0, 1.0],
    ));
    v.push((
        DMat3::from_diagonal(DVec3::new(0.5, 4.0, 2.0)),
        [4.0, 2.0, 0.5],
    ));
    v
}

fn svd3_properties_f64(dev: &wp::Device) {
    let cases = known();
    let ms: Vec<DMat3> = cases.iter().map(|c| c.0).collect();
    let got = run64(&ms, dev);
    for (k, ((a, want), d)) in cases.iter().zip(&got).enumerate() {
        check_svd(*a, d, TOL64, Some(*want), &format!("f64 case {k}"));
    }
}

fn svd3_properties_f32(dev: &wp::Device) {
    let cases = known();
    let ms: Vec<DMat3> = cases.iter().map(|c| c.0).collect();
    let got = run32(&ms, dev);
    for (k, ((a, want), d)) in cases.iter().zip(&got).enumerate() {
        // The input itself rounded to f32 (its singular values move by at most that much).
        let a32 = a.as_mat3().as_dmat3();
        check_svd(a32, d, TOL32, Some(*want), &format!("f32 case {k}"));
    }
}

/// 500 random matrices (entries in [-1, 1)) in f64 and in f32, where 8 and 5 sweeps converge.
fn svd3_random(dev: &wp::Device) {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let ms: Vec<DMat3> = (0..500)
        .map(|_| DMat3::from_cols_array(&std::array::from_fn(|_| next())))
        .collect();
    let got = run64(&ms, dev);
    for (k, (a, d)) in ms.iter().zip(&got).enumerate() {
        check_svd(*a, d, TOL64, None, &format!("random {k}"));
        // eig3 of the symmetric part: Q orthogonal, S Q = Q diag(d).
        let sym = (*a + a.transpose()) * 0.5;
        let res = max_abs(sym * d.eq - d.eq * DMat3::from_diagonal(d.ed)) / max_abs(sym);
        assert!(res <= TOL64, "random {k}: eig3 residual {res:e}");
        let o = max_abs(d.eq.transpose() * d.eq - DMat3::IDENTITY);
        assert!(o <= TOL64, "random {k}: eig3 orthogonality {o:e}");
    }
    // f32: the same matrices rounded to f32 (the reference is the rounded matrix).
    let got = run32(&ms, dev);
    for (k, (a, d)) in ms.iter().zip(&got).enumerate() {
        let a32 = a.as_mat3().as_dmat3();
        check_svd(a32, d, TOL32, None, &format!("f32 random {k}"));
        let sym = (a32 + a32.transpose()) * 0.5;
        let res = max_abs(sym * d.eq - d.eq * DMat3::from_diagonal(d.ed)) / max_abs(sym);
        assert!(res <= TOL32, "f32 random {k}: eig3 residual {res:e}");
    }
}

/// Zero, identity, diagonal (exact), rank-deficient and reflected inputs, in both precisions.
fn svd3_edge_cases(dev: &wp::Device) {
    let ms = [
        DMat3::ZERO,
        DMat3::IDENTITY,
        DMat3::from_diagonal(DVec3::new(3.0, 2.0, 1.0)),
        DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0)), // a reflection
        DMat3::from_cols(
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(2.0, 4.0, 6.0),
            DVec3::ZERO,
        ),
    ];
    for (got, tol) in [(run64(&ms, dev), TOL64), (run32(&ms, dev), TOL32)] {
        // The zero matrix: σ = 0 exactly, U and V rotations (V is the Jacobi sweeps' fixed
        // π/4 rotations: they have nothing to diagonalize).
        assert_eq!(got[0].s, DVec3::ZERO, "svd3(0)");
        check_svd(ms[0], &got[0], tol, Some([0.0; 3]), "zero");
        assert_eq!(got[0].ed, DVec3::ZERO, "eig3(0)");
        // The identity: all of AᵀA's eigenvalues tie, so every Jacobi rotation is the fixed
        // π/4 one: U = V is a rotation, not the identity, and σ = 1.
        check_svd(ms[1], &got[1], tol, Some([1.0; 3]), "identity");
        assert!(max_abs(got[1].u - got[1].v) <= tol, "svd3(I): U = V");
        // Diagonal with distinct descending positive entries: exact (every rotation is the
        // identity).
        let k = 2;
        assert_eq!(got[k].u, DMat3::IDENTITY, "svd3 U of a diagonal");
        assert_eq!(got[k].v, DMat3::IDENTITY, "svd3 V of a diagonal");
        assert_eq!(got[k].s, diagonal(ms[k]), "svd3 σ of a diagonal");
        assert_eq!(got[k].eq, DMat3::IDENTITY, "eig3 Q of a diagonal");
        assert_eq!(got[k].ed, diagonal(ms[k]), "eig3 d of a diagonal");
        // A reflection: σ = (1, 1, -1), U and V rotations.
        check_svd(ms[3], &got[3], tol, Some([1.0; 3]), "reflection");
        assert!(
            got[3].s.z < 0.0,
            "the reflection is carried by σ2: {}",
            got[3].s
        );
        // Rank one: σ = (|c| |(1, 2, 0)|, 0, 0) with c = (1, 2, 3).
        let s0 = 14f64.sqrt() * 5f64.sqrt();
        check_svd(ms[4], &got[4], tol, Some([s0, 0.0, 0.0]), "rank one");
    }
}

/// eig3 against closed forms: the eigenvalues (unsorted: compared as sets) and `S Q = Q D`.
fn eig3_closed_forms(dev: &wp::Device) {
    // (symmetric matrix, its eigenvalues ascending)
    let r = rot(DVec3::new(0.2, -1.0, 0.7), 0.9);
    let cases: [(DMat3, [f64; 3]); 5] = [
        (
            DMat3::from_cols(
                DVec3::new(2.0, 1.0, 0.0),
                DVec3::new(1.0, 2.0, 0.0),
                DVec3::Z * 5.0,
            ),
            [1.0, 3.0, 5.0],
        ),
        // a + 2b once, a - b twice (a = 1, b = 0.5): a repeated eigenvalue.
        (
            DMat3::from_cols(
                DVec3::new(1.0, 0.5, 0.5),
                DVec3::new(0.5, 1.0, 0.5),
                DVec3::new(0.5, 0.5, 1.0),
            ),
            [0.5, 0.5, 2.0],
        ),
        (
            r * DMat3::from_diagonal(DVec3::new(-2.0, 0.5, 3.0)) * r.transpose(),
            [-2.0, 0.5, 3.0],
        ),
        (
            DMat3::from_diagonal(DVec3::new(4.0, -1.0, 2.0)),
            [-1.0, 2.0, 4.0],
        ),
        (DMat3::IDENTITY * 2.0, [2.0, 2.0, 2.0]),
    ];
    let ms: Vec<DMat3> = cases.iter().map(|c| c.0).collect();
    for (got, tol, prec) in [
        (run64(&ms, dev), TOL64, "f64"),
        (run32(&ms, dev), TOL32, "f32"),
    ] {
        for (k, ((a, want), d)) in cases.iter().zip(&got).enumerate() {
            let a = if prec == "f32" {
                a.as_mat3().as_dmat3()
            } else {
                *a
            };
            let scale = max_abs(a);
            let mut ev = d.ed.to_array();
            ev.sort_by(|x, y| x.partial_cmp(y).unwrap());
            for i in 0..3 {
                let e = (ev[i] - want[i]).abs() / scale;
                assert!(e <= tol, "{prec} eig3 case {k}: {ev:?} vs {want:?}");
            }
            let res = max_abs(a * d.eq - d.eq * DMat3::from_diagonal(d.ed)) / scale;
            assert!(res <= tol, "{prec} eig3 case {k}: residual {res:e}");
            let o = max_abs(d.eq.transpose() * d.eq - DMat3::IDENTITY);
            assert!(o <= tol, "{prec} eig3 case {k}: orthogonality {o:e}");
            assert!(
                (d.eq.determinant() - 1.0).abs() <= 3.0 * tol,
                "{prec}: Q is a rotation"
            );
        }
        // A diagonal matrix comes back exactly, in its own order (not sorted).
        assert_eq!(got[3].ed, DVec3::new(4.0, -1.0, 2.0), "{prec}");
        assert_eq!(got[3].eq, DMat3::IDENTITY, "{prec}");
    }
}

/// qr3: `A = Q R`, `Q` a rotation, `R` upper triangular with a non-negative diagonal but for
/// `R22`, which has the sign of `det A`.
fn qr3_properties(dev: &wp::Device) {
    let mut ms: Vec<DMat3> = known().into_iter().map(|c| c.0).collect();
    ms.push(DMat3::from_cols(
        DVec3::new(-1.0, 2.0, 0.5),
        DVec3::new(0.0, 1.0, 3.0),
        DVec3::new(2.0, -1.0, 1.0),
    ));
    ms.push(DMat3::ZERO);
    for (got, tol, prec) in [
        (run64(&ms, dev), TOL64, "f64"),
        (run32(&ms, dev), TOL32, "f32"),
    ] {
        for (k, (a, d)) in ms.iter().zip(&got).enumerate() {
            let a = if prec == "f32" {
                a.as_mat3().as_dmat3()
            } else {
                *a
            };
            let scale = max_abs(a).max(f64::MIN_POSITIVE);
            let (q, r) = (d.qq, d.qr);
            assert!(
                max_abs(q * r - a) / scale <= tol,
                "{prec} qr3 {k}: reconstruction"
            );
            assert!(
                max_abs(q.transpose() * q - DMat3::IDENTITY) <= tol,
                "{prec} qr3 {k}: Q"
            );
            assert!(
                (q.determinant() - 1.0).abs() <= 3.0 * tol,
                "{prec} qr3 {k}: det Q"
            );
            for (i, j) in [(1, 0), (2, 0), (2, 1)] {
                let below = r.col(j)[i].abs() / scale;
                assert!(
                    below <= tol,
                    "{prec} qr3 {k}: R[{i}][{j}] = {}",
                    r.col(j)[i]
                );
            }
            assert!(
                r.x_axis.x >= 0.0 && r.y_axis.y >= 0.0,
                "{prec} qr3 {k}: diagonal {r}"
            );
            let det = a.determinant();
            if det.abs() > 10.0 * tol * scale * scale * scale {
                assert_eq!(r.z_axis.z < 0.0, det < 0.0, "{prec} qr3 {k}: sign of R22");
            }
        }
    }
}

/// svd2: `A = U diag(σ) Vᵀ`, `σ0 ≥ σ1 ≥ 0`, `V` a rotation, `det U = sign(det A)`; a repeated
/// singular value gives identities; a rank-one matrix gives `σ1 = 0`, not NaN.
fn svd2_properties(dev: &wp::Device) {
    let ms = [
        DMat2::from_cols_array(&[1.0, 2.0, -3.0, 0.5]),
        DMat2::from_cols_array(&[0.3, -0.8, 0.9, 0.2]),
        DMat2::from_cols_array(&[1.0, 2.0, 2.0, 4.0]), // rank one
        DMat2::from_diagonal(DVec2::new(2.0, 2.0)),    // repeated
        DMat2::from_diagonal(DVec2::new(-1.0, 3.0)),   // a reflection
        DMat2::ZERO,
    ];
    let check = |a: DMat2, u: DMat2, s: DVec2, v: DMat2, tol: f64, what: String| {
        let scale = a
            .to_cols_array()
            .iter()
            .fold(f64::MIN_POSITIVE, |m, x| m.max(x.abs()));
        let back = u * DMat2::from_diagonal(s) * v.transpose();
        let rec = (back - a)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, x| m.max(x.abs()))
            / scale;
        assert!(rec <= tol, "{what}: reconstruction {rec:e} ({s})");
        assert!(s.x >= s.y && s.y >= 0.0, "{what}: σ {s}");
        let sign = if a.determinant() < 0.0 { -1.0 } else { 1.0 };
        assert!(
            (u.determinant() - sign).abs() <= 3.0 * tol,
            "{what}: det U {}",
            u.determinant()
        );
        assert!((v.determinant() - 1.0).abs() <= 3.0 * tol, "{what}: det V");
    };
    // A closed form: 2x2 has few roundings; 16 eps covers them.
    let (t32, t64) = (16.0 * f32::EPSILON as f64, 16.0 * f64::EPSILON);
    let n = ms.len();
    let a = arr(&ms, dev);
    let (u, s, v) = (
        zeros::<DMat2, 1>(n, dev),
        zeros::<DVec2, 1>(n, dev),
        zeros::<DMat2, 1>(n, dev),
    );
    wp::launch(k_svd2, n, (&a, &u, &s, &v), dev).unwrap();
    let (u, s, v) = (host(&u), host(&s), host(&v));
    for k in 0..n {
        check(ms[k], u[k], s[k], v[k], t64, format!("f64 svd2 {k}"));
    }
    assert_eq!(
        (u[3], s[3], v[3]),
        (DMat2::IDENTITY, DVec2::new(2.0, 2.0), DMat2::IDENTITY)
    );
    assert_eq!(s[5], DVec2::ZERO);
    assert!(s[2].y.abs() <= t64 * 4.0, "rank one: σ1 = {}", s[2].y);
    let ms32: Vec<Mat2> = ms.iter().map(|m| m.as_mat2()).collect();
    let a = arr(&ms32, dev);
    let (u, s, v) = (
        zeros::<Mat2, 1>(n, dev),
        zeros::<Vec2, 1>(n, dev),
        zeros::<Mat2, 1>(n, dev),
    );
    wp::launch(k_svd2, n, (&a, &u, &s, &v), dev).unwrap();
    let (u, s, v) = (host(&u), host(&s), host(&v));
    for k in 0..n {
        let (uu, ss, vv) = (u[k].as_dmat2(), s[k].as_dvec2(), v[k].as_dmat2());
        check(ms32[k].as_dmat2(), uu, ss, vv, t32, format!("f32 svd2 {k}"));
    }
    assert!(!s[2].y.is_nan(), "rank one in f32: σ1 = {}", s[2].y);
}

/// A NaN anywhere: the fixed sweep counts end as always; σ, U and the eigenvalues are NaN
/// (visible), V and Q finite rotations (the Jacobi test is false for NaN and takes the fixed
/// rotation).
fn nan_input_terminates(dev: &wp::Device) {
    let mut m = with_singular_values([3.0, 2.0, 1.0], 0).to_cols_array();
    m[4] = f64::NAN;
    let ms = [DMat3::from_cols_array(&m)];
    for got in [run64(&ms, dev), run32(&ms, dev)] {
        let d = &got[0];
        assert!(d.s.is_nan() && d.u.is_nan(), "svd3: σ {} U {}", d.s, d.u);
        assert!(d.v.is_finite(), "svd3: V {}", d.v);
        assert!(
            max_abs(d.v.transpose() * d.v - DMat3::IDENTITY) < 1e-5,
            "V a rotation"
        );
        assert!(
            d.ed.is_nan() && d.eq.is_finite(),
            "eig3: d {} Q {}",
            d.ed,
            d.eq
        );
        assert!(d.qq.is_nan() && d.qr.is_nan(), "qr3");
    }
}

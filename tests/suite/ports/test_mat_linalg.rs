//! Port of the non-square cases of Warp's matrix linear-algebra tests,
//! `warp/tests/matrix/test_mat_linalg.py` (they were `warp/tests/test_mat.py` before Warp split
//! that file): the `mat32` (shape `(3, 2)`) and `mat23` parts of `test_matvec_multiplication`,
//! `test_vecmat_multiplication`, `test_matmat_multiplication` and `test_transpose`, each on
//! its values and on its gradients, once per precision (f32, f64). As Warp's, the gradients are
//! taken one output component at a time: the kernel and a select kernel under a tape, backward
//! from the selected component, the inputs' gradients compared with the closed form, then
//! `tape.zero()`.
//!
//! Ported (Warp test -> here, each for f32 and f64): `test_matvec_multiplication`'s
//! `m32[0] * v32[0]` -> `matvec_*`; `test_vecmat_multiplication`'s `v32[0] * m23[0]` (a row
//! vector times a matrix) -> `vecmat_*`, written `transpose(m23) * v` (the language has no
//! vector-times-matrix operator; Warp's `v * m` is `mᵀ v`); `test_matmat_multiplication`'s
//! `b32[0] * a2[0]` (a `mat32` times a `mat22`) -> `matmat_*`; `test_transpose`'s
//! `transpose(m32[0])` -> `transpose_*`. Tolerances are Warp's, absolute, per precision:
//! matvec and vecmat `5 * 5e-6` (f32) and `5 * 1e-8` (f64) on values, `2 *` that base on
//! gradients; matmat `5 * 5e-6` / `5 * 5e-7` on values, `10 *` the base on gradients; transpose
//! `1e-6` / `1e-8` on values and exact gradients (Warp compares them without `tol`).
//! References are computed in f64 from the inputs.
//!
//! Adapted: Warp's inputs are standard normal draws (`numpy.random.default_rng(123)`); here a
//! fixed hash in [-1, 1), the same sizes. Warp's `@` spelling is the same operator as `*`, so
//! its second half of each output vector is not repeated.
//!
//! Not ported: the square cases (the suite's matrix tests cover glam's), the integer and
//! float16 instances (there are no integer or f16 matrices), and `test_outer_product`'s
//! `outer(vec2, vec5)` (there is no 5-vector; the suite's `nonsquare` module takes `outer` of
//! vectors of lengths 2, 3, 4 and 6).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    matvec_f32,
    matvec_f64,
    vecmat_f32,
    vecmat_f64,
    matmat_f32,
    matmat_f64,
    transpose_f32,
    transpose_f64,
);

fn matvec_f32(dev: &wp::Device) {
    f32s::matvec(dev)
}
fn matvec_f64(dev: &wp::Device) {
    f64s::matvec(dev)
}
fn vecmat_f32(dev: &wp::Device) {
    f32s::vecmat(dev)
}
fn vecmat_f64(dev: &wp::Device) {
    f64s::vecmat(dev)
}
fn matmat_f32(dev: &wp::Device) {
    f32s::matmat(dev)
}
fn matmat_f64(dev: &wp::Device) {
    f64s::matmat(dev)
}
fn transpose_f32(dev: &wp::Device) {
    f32s::transpose(dev)
}
fn transpose_f64(dev: &wp::Device) {
    f64s::transpose(dev)
}

/// Fixed pseudo-random numbers in [-1, 1) (a sine hash), standing in for Warp's draws.
fn noise(k: usize) -> f64 {
    ((k as f64 * 12.9898 + 0.5).sin() * 43758.5453).rem_euclid(1.0) * 2.0 - 1.0
}

#[track_caller]
fn near(got: &[f64], want: &[f64], tol: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: lengths");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= tol,
            "{what}[{k}]: got {g:e}, want {w:e} (Warp's absolute tolerance {tol:e})"
        );
    }
}

/// `out[0] = input[index]`: Warp's `output_select_kernel`.
#[wp::kernel]
fn select<T: Float>(input: Array<T>, index: i32, out: Array<T>) {
    out[0] = input[index];
}

/// The precision-specific kernels and test bodies: `$tol` is Warp's matvec/vecmat/matmat base
/// tolerance, `$tol_mm` its matmat one, `$tol_t` its transpose one.
macro_rules! mat_ports {
    ($m:ident, $s:ident, $m32:ident, $m23:ident, $m2:ident, $v2:ident,
     $tol:expr, $tol_mm:expr, $tol_t:expr) => {
        pub(super) mod $m {
            use super::{arr, host, near, noise, select, wp, zeros};
            use wp::prelude::*;

            fn m32(offset: usize) -> $m32 {
                $m32::from_rows_array(std::array::from_fn(|i| {
                    std::array::from_fn(|j| noise(offset + 2 * i + j) as $s)
                }))
            }
            fn e32(m: $m32) -> [[f64; 2]; 3] {
                m.to_rows_array().map(|r| r.map(|x| x as f64))
            }
            fn e23(m: $m23) -> [[f64; 3]; 2] {
                m.to_rows_array().map(|r| r.map(|x| x as f64))
            }
            fn f64s(v: &[$s]) -> Vec<f64> {
                v.iter().map(|&x| x as f64).collect()
            }
            fn flat<const R: usize, const C: usize>(a: [[f64; C]; R]) -> Vec<f64> {
                a.iter().flatten().copied().collect()
            }

            /// Runs `launch` and the select kernel on output element `i` under a tape,
            /// backward from it; `read` takes the inputs' gradients before the tape is zeroed.
            fn grad_of<R>(
                dev: &wp::Device,
                out: &wp::Array<$s>,
                i: usize,
                launch: impl Fn(),
                read: impl Fn() -> R,
            ) -> R {
                let cmp = zeros::<$s, 1>(1, dev).with_grad().unwrap();
                let tape = wp::Tape::new();
                {
                    let _rec = tape.record();
                    launch();
                    wp::launch(select, 1, (out, i as i32, &cmp), dev).unwrap();
                }
                tape.backward(&cmp).unwrap();
                let r = read();
                tape.zero().unwrap();
                r
            }

            #[wp::kernel]
            fn k_matvec(v32: Array<$v2>, m32: Array<$m32>, out: Array<$s>) {
                let r = m32[0] * v32[0];
                let mut idx = 0;
                for i in 0..3 {
                    out[idx] = 2.0 * r[i];
                    idx += 1;
                }
            }

            pub fn matvec(dev: &wp::Device) {
                let tol = $tol;
                let (m, v) = (m32(0), $v2::new(noise(40) as $s, noise(41) as $s));
                let (am, av) = (
                    arr(&[m], dev).with_grad().unwrap(),
                    arr(&[v], dev).with_grad().unwrap(),
                );
                let out = zeros::<$s, 1>(3, dev).with_grad().unwrap();
                let launch = || wp::launch(k_matvec, 1, (&av, &am, &out), dev).unwrap();
                launch();
                let (e, x) = (e32(m), [v.x as f64, v.y as f64]);
                let want: Vec<f64> = (0..3)
                    .map(|i| 2.0 * (e[i][0] * x[0] + e[i][1] * x[1]))
                    .collect();
                near(&f64s(&host(&out)), &want, 5.0 * tol, "2 m32 * v");
                for i in 0..3 {
                    let (gv, gm) = grad_of(dev, &out, i, launch, || {
                        (host(&av.grad().unwrap())[0], host(&am.grad().unwrap())[0])
                    });
                    near(
                        &f64s(&gv.to_array()),
                        &[2.0 * e[i][0], 2.0 * e[i][1]],
                        2.0 * tol,
                        "d/dv",
                    );
                    let mut want = [[0.0; 2]; 3];
                    want[i] = [2.0 * x[0], 2.0 * x[1]];
                    near(&flat(e32(gm)), &flat(want), 2.0 * tol, "d/dm");
                }
            }

            #[wp::kernel]
            fn k_vecmat(v32: Array<$v2>, m23: Array<$m23>, out: Array<$s>) {
                // Warp's `v * m` (a row vector times a matrix) is `transpose(m) * v`.
                let r = transpose(m23[0]) * v32[0];
                let mut idx = 0;
                for i in 0..3 {
                    out[idx] = 2.0 * r[i];
                    idx += 1;
                }
            }

            pub fn vecmat(dev: &wp::Device) {
                let tol = $tol;
                let m = m32(10).transpose();
                let v = $v2::new(noise(50) as $s, noise(51) as $s);
                let (am, av) = (
                    arr(&[m], dev).with_grad().unwrap(),
                    arr(&[v], dev).with_grad().unwrap(),
                );
                let out = zeros::<$s, 1>(3, dev).with_grad().unwrap();
                let launch = || wp::launch(k_vecmat, 1, (&av, &am, &out), dev).unwrap();
                launch();
                let (e, x) = (e23(m), [v.x as f64, v.y as f64]);
                let want: Vec<f64> = (0..3)
                    .map(|i| 2.0 * (x[0] * e[0][i] + x[1] * e[1][i]))
                    .collect();
                near(&f64s(&host(&out)), &want, 5.0 * tol, "2 v * m23");
                for i in 0..3 {
                    let (gv, gm) = grad_of(dev, &out, i, launch, || {
                        (host(&av.grad().unwrap())[0], host(&am.grad().unwrap())[0])
                    });
                    near(
                        &f64s(&gv.to_array()),
                        &[2.0 * e[0][i], 2.0 * e[1][i]],
                        2.0 * tol,
                        "d/dv",
                    );
                    let mut want = [[0.0; 3]; 2];
                    want[0][i] = 2.0 * x[0];
                    want[1][i] = 2.0 * x[1];
                    near(&flat(e23(gm)), &flat(want), 2.0 * tol, "d/dm");
                }
            }

            #[wp::kernel]
            fn k_matmat(a2: Array<$m2>, b32: Array<$m32>, out: Array<$s>) {
                let c = b32[0] * a2[0];
                let mut idx = 0;
                for i in 0..3 {
                    for j in 0..2 {
                        out[idx] = 2.0 * c[(i, j)];
                        idx += 1;
                    }
                }
            }

            pub fn matmat(dev: &wp::Device) {
                let tol = $tol_mm;
                let b = m32(20);
                let a = $m2::from_cols_array(&std::array::from_fn(|k| noise(60 + k) as $s));
                let (aa, ab) = (
                    arr(&[a], dev).with_grad().unwrap(),
                    arr(&[b], dev).with_grad().unwrap(),
                );
                let out = zeros::<$s, 1>(6, dev).with_grad().unwrap();
                let launch = || wp::launch(k_matmat, 1, (&aa, &ab, &out), dev).unwrap();
                launch();
                let eb = e32(b);
                let ea = |i: usize, j: usize| a.col(j)[i] as f64;
                let want: Vec<f64> = (0..6)
                    .map(|k| {
                        let (i, j) = (k / 2, k % 2);
                        2.0 * (eb[i][0] * ea(0, j) + eb[i][1] * ea(1, j))
                    })
                    .collect();
                near(&f64s(&host(&out)), &want, 5.0 * tol, "2 b32 * a2");
                for k in 0..6 {
                    let (i, j) = (k / 2, k % 2);
                    let (ga, gb) = grad_of(dev, &out, k, launch, || {
                        (host(&aa.grad().unwrap())[0], host(&ab.grad().unwrap())[0])
                    });
                    // d/da[:, j] = 2 b[i, :]; d/db[i, :] = 2 a[:, j].
                    let mut want_a = [[0.0; 2]; 2];
                    want_a[0][j] = 2.0 * eb[i][0];
                    want_a[1][j] = 2.0 * eb[i][1];
                    let got_a = [
                        [ga.col(0)[0] as f64, ga.col(1)[0] as f64],
                        [ga.col(0)[1] as f64, ga.col(1)[1] as f64],
                    ];
                    near(&flat(got_a), &flat(want_a), 10.0 * tol, "d/da");
                    let mut want_b = [[0.0; 2]; 3];
                    want_b[i] = [2.0 * ea(0, j), 2.0 * ea(1, j)];
                    near(&flat(e32(gb)), &flat(want_b), 10.0 * tol, "d/db");
                }
            }

            #[wp::kernel]
            fn k_transpose(m32: Array<$m32>, out: Array<$s>) {
                let t = 2.0 * transpose(m32[0]);
                let mut idx = 0;
                for i in 0..2 {
                    for j in 0..3 {
                        out[idx] = t[(i, j)];
                        idx += 1;
                    }
                }
            }

            pub fn transpose(dev: &wp::Device) {
                let tol = $tol_t;
                let m = m32(30);
                let am = arr(&[m], dev).with_grad().unwrap();
                let out = zeros::<$s, 1>(6, dev).with_grad().unwrap();
                let launch = || wp::launch(k_transpose, 1, (&am, &out), dev).unwrap();
                launch();
                let e = e32(m);
                let want: Vec<f64> = (0..6).map(|k| 2.0 * e[k % 3][k / 3]).collect();
                near(&f64s(&host(&out)), &want, tol, "2 transpose(m32)");
                for k in 0..6 {
                    let (i, j) = (k / 3, k % 3);
                    let g = grad_of(dev, &out, k, launch, || host(&am.grad().unwrap())[0]);
                    let mut want = [[0.0; 2]; 3];
                    want[j][i] = 2.0;
                    assert_eq!(flat(e32(g)), flat(want), "gradient of component ({i}, {j})");
                }
            }
        }
    };
}

mat_ports!(f32s, f32, Mat32, Mat23, Mat2, Vec2, 5.0e-6, 5.0e-6, 1.0e-6);
mat_ports!(f64s, f64, DMat32, DMat23, DMat2, DVec2, 1.0e-8, 5.0e-7, 1.0e-8);

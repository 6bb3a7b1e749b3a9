//! Port of Warp's `warp/tests/test_spatial.py`, its spatial-algebra tests: spatial vectors
//! built from six scalars and from two 3-vectors, read by lane, the spatial dot and cross
//! products (motion and force), `spatial_top` / `spatial_bottom`, the spatial matrix-vector
//! product and `spatial_adjoint`, each on its values and on its gradients. As Warp's, each test
//! runs once per precision (here f32 and f64) and takes its gradients one output component at a
//! time: the kernel and a select kernel under a tape, backward from the selected component,
//! the inputs' gradients compared with the closed form, then `tape.zero()`.
//!
//! Ported (Warp test -> here, each for f32 and f64): `test_spatial_vector_constructors` ->
//! `constructors_*`, `test_spatial_vector_indexing` -> `indexing_*`, `test_spatial_dot` ->
//! `dot_*`, `test_spatial_cross` -> `cross_*`, `test_spatial_top_bottom` -> `top_bottom_*`,
//! `test_spatial_matvec_multiplication` -> `matvec_*`, `test_spatial_adjoint` ->
//! `adjoint_*`. Tolerances are Warp's, absolute, per precision: `1e-6` (f32) and `1e-8` (f64),
//! `5e-6` (f32) for the matrix-vector product, ten times the tolerance for the dot product's
//! first gradient and `spatial_adjoint`'s gradients, exact for the one-hot gradients Warp
//! compares without `tol`. References are computed in f64 from the inputs.
//!
//! Adapted: Warp's kernels loop over lanes with a run-time index (`for i in range(6):
//! out[i] = 2 * c[i]`); a spatial value's lanes are read here by literal index only, so the
//! loops are written out. Warp's inputs are standard normal draws
//! (`numpy.random.default_rng(123)`); here a fixed hash in [-1, 1), the same sizes.
//!
//! Not ported: the float16 instances (there are no f16 spatial types); the rest of the file,
//! its transform tests (`test_transform_*`: constructors from seven scalars and keyword
//! arguments, run-time lane indexing and slicing `t[0:3]`, component assignment through
//! indices, `transform_get_translation` and friends) and its spatial-matrix tests other than
//! the matrix-vector product and `spatial_adjoint` (constructors from 36 scalars, which the
//! language does not have, run-time indexing, scalar multiplication, addition, the
//! matrix-matrix product, transpose, outer product): left for a later round; the language has
//! the operations (see the suite's `spatial` module) except the 36-scalar constructor and
//! run-time lane indices.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    constructors_f32,
    constructors_f64,
    indexing_f32,
    indexing_f64,
    dot_f32,
    dot_f64,
    cross_f32,
    cross_f64,
    top_bottom_f32,
    top_bottom_f64,
    matvec_f32,
    matvec_f64,
    adjoint_f32,
    adjoint_f64,
);

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

/// A one-hot row of `n`: `2` at `i`.
fn two_at(n: usize, i: usize) -> Vec<f64> {
    let mut e = vec![0.0; n];
    e[i] = 2.0;
    e
}

/// The precision-specific kernels and test bodies.
macro_rules! spatial_ports {
    ($m:ident, $s:ident, $sv:ident, $sm:ident, $v3:ident, $m3:ident, $tol:expr, $tol_mv:expr) => {
        pub(super) mod $m {
            use super::{arr, host, near, noise, select, two_at, wp, zeros};
            use wp::prelude::*;

            const TOL: f64 = $tol;

            fn scalars(offset: usize, n: usize) -> Vec<$s> {
                (0..n).map(|k| noise(offset + k) as $s).collect()
            }
            fn sv(offset: usize) -> $sv {
                $sv::from_array(std::array::from_fn(|k| noise(offset + k) as $s))
            }
            fn lanes(v: $sv) -> Vec<f64> {
                v.to_array().iter().map(|&x| x as f64).collect()
            }
            fn f64s(v: &[$s]) -> Vec<f64> {
                v.iter().map(|&x| x as f64).collect()
            }

            /// Runs `launch` and the select kernel on output element `i` under a tape, backward
            /// from it; `read` takes the inputs' gradients before the tape is zeroed.
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
            fn k_component_constructor(input: Array<$s>, out: Array<$s>) {
                let result =
                    spatial_vector(input[0], input[1], input[2], input[3], input[4], input[5]);
                out[0] = 2.0 * result[0];
                out[1] = 2.0 * result[1];
                out[2] = 2.0 * result[2];
                out[3] = 2.0 * result[3];
                out[4] = 2.0 * result[4];
                out[5] = 2.0 * result[5];
            }

            #[wp::kernel]
            fn k_vector_constructor(input: Array<$s>, out: Array<$s>) {
                let result = spatial_vector(
                    $v3::new(input[0], input[1], input[2]),
                    $v3::new(input[3], input[4], input[5]),
                );
                out[0] = 2.0 * result[0];
                out[1] = 2.0 * result[1];
                out[2] = 2.0 * result[2];
                out[3] = 2.0 * result[3];
                out[4] = 2.0 * result[4];
                out[5] = 2.0 * result[5];
            }

            pub fn constructors(dev: &wp::Device) {
                for (k, vector_form) in [false, true].into_iter().enumerate() {
                    let x = scalars(10 * k, 6);
                    let input = arr(&x, dev).with_grad().unwrap();
                    let out = zeros::<$s, 1>(6, dev).with_grad().unwrap();
                    let launch = || {
                        if vector_form {
                            wp::launch(k_vector_constructor, 1, (&input, &out), dev).unwrap();
                        } else {
                            wp::launch(k_component_constructor, 1, (&input, &out), dev).unwrap();
                        }
                    };
                    launch();
                    let want: Vec<f64> = f64s(&x).iter().map(|v| 2.0 * v).collect();
                    near(&f64s(&host(&out)), &want, TOL, "2 spatial_vector(..)");
                    for i in 0..6 {
                        let g = grad_of(dev, &out, i, launch, || host(&input.grad().unwrap()));
                        assert_eq!(f64s(&g), two_at(6, i), "gradient of component {i}");
                    }
                }
            }

            #[wp::kernel]
            fn k_indexing(input: Array<$sv>, out: Array<$s>) {
                let elem = input[0];
                out[0] = 2.0 * elem[0];
                out[1] = 2.0 * elem[1];
                out[2] = 2.0 * elem[2];
                out[3] = 2.0 * elem[3];
                out[4] = 2.0 * elem[4];
                out[5] = 2.0 * elem[5];
            }

            pub fn indexing(dev: &wp::Device) {
                let v = sv(20);
                let input = arr(&[v], dev).with_grad().unwrap();
                let out = zeros::<$s, 1>(6, dev).with_grad().unwrap();
                let launch = || wp::launch(k_indexing, 1, (&input, &out), dev).unwrap();
                launch();
                let want: Vec<f64> = lanes(v).iter().map(|x| 2.0 * x).collect();
                near(&f64s(&host(&out)), &want, TOL, "2 v[i]");
                for i in 0..6 {
                    let g = grad_of(dev, &out, i, launch, || host(&input.grad().unwrap())[0]);
                    assert_eq!(lanes(g), two_at(6, i), "gradient of lane {i}");
                }
            }

            #[wp::kernel]
            fn k_dot(s: Array<$sv>, v: Array<$sv>, dot: Array<$s>) {
                dot[0] = 2.0 * spatial_dot(v[0], s[0]);
            }

            pub fn dot(dev: &wp::Device) {
                let (sv0, vv0) = (sv(30), sv(40));
                let s = arr(&[sv0], dev).with_grad().unwrap();
                let v = arr(&[vv0], dev).with_grad().unwrap();
                let d = zeros::<$s, 1>(1, dev).with_grad().unwrap();
                let tape = wp::Tape::new();
                {
                    let _rec = tape.record();
                    wp::launch(k_dot, 1, (&s, &v, &d), dev).unwrap();
                }
                let want: f64 = 2.0
                    * lanes(sv0)
                        .iter()
                        .zip(lanes(vv0))
                        .map(|(a, b)| a * b)
                        .sum::<f64>();
                near(&[host(&d)[0] as f64], &[want], TOL, "2 spatial_dot(v, s)");
                tape.backward(&d).unwrap();
                let two = |x: $sv| lanes(x).iter().map(|a| 2.0 * a).collect::<Vec<_>>();
                near(
                    &lanes(host(&s.grad().unwrap())[0]),
                    &two(vv0),
                    10.0 * TOL,
                    "d/ds",
                );
                near(&lanes(host(&v.grad().unwrap())[0]), &two(sv0), TOL, "d/dv");
            }

            #[wp::kernel]
            fn k_cross(
                s: Array<$sv>,
                v: Array<$sv>,
                outputs: Array<$s>,
                outputs_dual: Array<$s>,
                outputs_wcrossw: Array<$s>,
                outputs_vcrossw: Array<$s>,
                outputs_wcrossv: Array<$s>,
                outputs_vcrossv: Array<$s>,
            ) {
                let c = spatial_cross(s[0], v[0]);
                let d = spatial_cross_dual(s[0], v[0]);
                outputs[0] = 2.0 * c[0];
                outputs[1] = 2.0 * c[1];
                outputs[2] = 2.0 * c[2];
                outputs[3] = 2.0 * c[3];
                outputs[4] = 2.0 * c[4];
                outputs[5] = 2.0 * c[5];
                outputs_dual[0] = 2.0 * d[0];
                outputs_dual[1] = 2.0 * d[1];
                outputs_dual[2] = 2.0 * d[2];
                outputs_dual[3] = 2.0 * d[3];
                outputs_dual[4] = 2.0 * d[4];
                outputs_dual[5] = 2.0 * d[5];
                let sw = spatial_top(s[0]);
                let sv = spatial_bottom(s[0]);
                let vw = spatial_top(v[0]);
                let vv = spatial_bottom(v[0]);
                let wcrossw = sw.cross(vw);
                let vcrossw = sv.cross(vw);
                let wcrossv = sw.cross(vv);
                let vcrossv = sv.cross(vv);
                outputs_wcrossw[0] = wcrossw.x;
                outputs_wcrossw[1] = wcrossw.y;
                outputs_wcrossw[2] = wcrossw.z;
                outputs_vcrossw[0] = vcrossw.x;
                outputs_vcrossw[1] = vcrossw.y;
                outputs_vcrossw[2] = vcrossw.z;
                outputs_wcrossv[0] = wcrossv.x;
                outputs_wcrossv[1] = wcrossv.y;
                outputs_wcrossv[2] = wcrossv.z;
                outputs_vcrossv[0] = vcrossv.x;
                outputs_vcrossv[1] = vcrossv.y;
                outputs_vcrossv[2] = vcrossv.z;
            }

            pub fn cross(dev: &wp::Device) {
                let (sv0, vv0) = (sv(50), sv(60));
                let s = arr(&[sv0], dev).with_grad().unwrap();
                let v = arr(&[vv0], dev).with_grad().unwrap();
                let outs: Vec<wp::Array<$s>> = [6, 6, 3, 3, 3, 3]
                    .iter()
                    .map(|&n| zeros::<$s, 1>(n, dev).with_grad().unwrap())
                    .collect();
                let launch = || {
                    let args = (
                        &s, &v, &outs[0], &outs[1], &outs[2], &outs[3], &outs[4], &outs[5],
                    );
                    wp::launch(k_cross, 1, args, dev).unwrap();
                };
                launch();
                // The closed forms in f64: c = (sw x vw, sv x vw + sw x vv), the dual
                // (sw x vw + sv x vv, sw x vv).
                let (a, b) = (lanes(sv0), lanes(vv0));
                let x = |p: &[f64], q: &[f64]| {
                    [
                        p[1] * q[2] - p[2] * q[1],
                        p[2] * q[0] - p[0] * q[2],
                        p[0] * q[1] - p[1] * q[0],
                    ]
                };
                let (sw, svv, vw, vv) = (&a[..3], &a[3..], &b[..3], &b[3..]);
                let (ww, vw_, wv, vv_) = (x(sw, vw), x(svv, vw), x(sw, vv), x(svv, vv));
                let o: Vec<Vec<f64>> = outs.iter().map(|o| f64s(&host(o))).collect();
                let want_c: Vec<f64> = (0..6)
                    .map(|k| 2.0 * if k < 3 { ww[k] } else { vw_[k - 3] + wv[k - 3] })
                    .collect();
                let want_d: Vec<f64> = (0..6)
                    .map(|k| 2.0 * if k < 3 { ww[k] + vv_[k] } else { wv[k - 3] })
                    .collect();
                near(&o[0], &want_c, TOL, "2 spatial_cross");
                near(&o[1], &want_d, TOL, "2 spatial_cross_dual");
                // Warp's gradient check: the spatial products' gradients are those of their
                // 3-vector cross products, combined as the closed forms combine them.
                let grads = |out: usize, i: usize| {
                    grad_of(dev, &outs[out], i, launch, || {
                        let g = |a: &wp::Array<$sv>| lanes(host(&a.grad().unwrap())[0]);
                        (g(&s), g(&v))
                    })
                };
                let comb = |terms: &[(f64, &(Vec<f64>, Vec<f64>))]| {
                    let mut r = (vec![0.0; 6], vec![0.0; 6]);
                    for (c, (gs, gv)) in terms {
                        for k in 0..6 {
                            r.0[k] += c * gs[k];
                            r.1[k] += c * gv[k];
                        }
                    }
                    r
                };
                for i in 0..3 {
                    let (cw, cv, dw, dv) =
                        (grads(0, i), grads(0, i + 3), grads(1, i), grads(1, i + 3));
                    let (gww, gvw, gwv, gvv) = (grads(2, i), grads(3, i), grads(4, i), grads(5, i));
                    let checks = [
                        ("d spatial_cross[w]", &cw, comb(&[(2.0, &gww)])),
                        ("d spatial_cross[v]", &cv, comb(&[(2.0, &gvw), (2.0, &gwv)])),
                        (
                            "d spatial_cross_dual[w]",
                            &dw,
                            comb(&[(2.0, &gww), (2.0, &gvv)]),
                        ),
                        ("d spatial_cross_dual[v]", &dv, comb(&[(2.0, &gwv)])),
                    ];
                    for (what, got, want) in checks {
                        near(&got.0, &want.0, TOL, &format!("{what} {i} / ds"));
                        near(&got.1, &want.1, TOL, &format!("{what} {i} / dv"));
                    }
                }
            }

            #[wp::kernel]
            fn k_top_bottom(s: Array<$sv>, outputs: Array<$s>) {
                let top = spatial_top(s[0]);
                let bottom = spatial_bottom(s[0]);
                outputs[0] = 2.0 * top.x;
                outputs[1] = 2.0 * top.y;
                outputs[2] = 2.0 * top.z;
                outputs[3] = 2.0 * bottom.x;
                outputs[4] = 2.0 * bottom.y;
                outputs[5] = 2.0 * bottom.z;
            }

            pub fn top_bottom(dev: &wp::Device) {
                let v = sv(70);
                let s = arr(&[v], dev).with_grad().unwrap();
                let out = zeros::<$s, 1>(6, dev).with_grad().unwrap();
                let launch = || wp::launch(k_top_bottom, 1, (&s, &out), dev).unwrap();
                launch();
                let want: Vec<f64> = lanes(v).iter().map(|x| 2.0 * x).collect();
                near(&f64s(&host(&out)), &want, TOL, "2 (top, bottom)");
                for i in 0..6 {
                    let g = grad_of(dev, &out, i, launch, || host(&s.grad().unwrap())[0]);
                    assert_eq!(lanes(g), two_at(6, i), "gradient of component {i}");
                }
            }

            #[wp::kernel]
            fn k_matvec(v: Array<$sv>, m: Array<$sm>, outcomponents: Array<$s>) {
                let result = m[0] * v[0];
                outcomponents[0] = 2.0 * result[0];
                outcomponents[1] = 2.0 * result[1];
                outcomponents[2] = 2.0 * result[2];
                outcomponents[3] = 2.0 * result[3];
                outcomponents[4] = 2.0 * result[4];
                outcomponents[5] = 2.0 * result[5];
            }

            pub fn matvec(dev: &wp::Device) {
                let tol = $tol_mv;
                let vv = sv(80);
                let rows: [[$s; 6]; 6] =
                    std::array::from_fn(|i| std::array::from_fn(|j| noise(100 + 6 * i + j) as $s));
                let mm = $sm::from_rows_array(rows);
                let v = arr(&[vv], dev).with_grad().unwrap();
                let m = arr(&[mm], dev).with_grad().unwrap();
                let out = zeros::<$s, 1>(6, dev).with_grad().unwrap();
                let launch = || wp::launch(k_matvec, 1, (&v, &m, &out), dev).unwrap();
                launch();
                let x = lanes(vv);
                let row = |i: usize| rows[i].iter().map(|&a| a as f64).collect::<Vec<_>>();
                let want: Vec<f64> = (0..6)
                    .map(|i| 2.0 * row(i).iter().zip(&x).map(|(a, b)| a * b).sum::<f64>())
                    .collect();
                near(&f64s(&host(&out)), &want, tol, "2 m v");
                for i in 0..6 {
                    let (gv, gm) = grad_of(dev, &out, i, launch, || {
                        (host(&v.grad().unwrap())[0], host(&m.grad().unwrap())[0])
                    });
                    let want_v: Vec<f64> = row(i).iter().map(|a| 2.0 * a).collect();
                    near(&lanes(gv), &want_v, tol, &format!("d(m v)[{i}]/dv"));
                    let want_m: Vec<f64> = (0..36)
                        .map(|k| if k / 6 == i { 2.0 * x[k % 6] } else { 0.0 })
                        .collect();
                    let got_m: Vec<f64> = gm
                        .to_rows_array()
                        .concat()
                        .iter()
                        .map(|&a| a as f64)
                        .collect();
                    near(&got_m, &want_m, tol, &format!("d(m v)[{i}]/dm"));
                }
            }

            #[wp::kernel]
            fn k_adjoint(r: Array<$m3>, s: Array<$m3>, out: Array<$s>) {
                let m = 2.0 * spatial_adjoint(r[0], s[0]);
                out[0] = m[(0, 0)];
                out[1] = m[(0, 1)];
                out[2] = m[(0, 2)];
                out[3] = m[(0, 3)];
                out[4] = m[(0, 4)];
                out[5] = m[(0, 5)];
                out[6] = m[(1, 0)];
                out[7] = m[(1, 1)];
                out[8] = m[(1, 2)];
                out[9] = m[(1, 3)];
                out[10] = m[(1, 4)];
                out[11] = m[(1, 5)];
                out[12] = m[(2, 0)];
                out[13] = m[(2, 1)];
                out[14] = m[(2, 2)];
                out[15] = m[(2, 3)];
                out[16] = m[(2, 4)];
                out[17] = m[(2, 5)];
                out[18] = m[(3, 0)];
                out[19] = m[(3, 1)];
                out[20] = m[(3, 2)];
                out[21] = m[(3, 3)];
                out[22] = m[(3, 4)];
                out[23] = m[(3, 5)];
                out[24] = m[(4, 0)];
                out[25] = m[(4, 1)];
                out[26] = m[(4, 2)];
                out[27] = m[(4, 3)];
                out[28] = m[(4, 4)];
                out[29] = m[(4, 5)];
                out[30] = m[(5, 0)];
                out[31] = m[(5, 1)];
                out[32] = m[(5, 2)];
                out[33] = m[(5, 3)];
                out[34] = m[(5, 4)];
                out[35] = m[(5, 5)];
            }

            pub fn adjoint(dev: &wp::Device) {
                // Row-major 3x3 entries, as Warp's numpy matrices.
                let ra: [$s; 9] = std::array::from_fn(|k| noise(200 + k) as $s);
                let sa: [$s; 9] = std::array::from_fn(|k| noise(300 + k) as $s);
                let rm = $m3::from_cols_array(&ra).transpose();
                let smat = $m3::from_cols_array(&sa).transpose();
                let r = arr(&[rm], dev).with_grad().unwrap();
                let s = arr(&[smat], dev).with_grad().unwrap();
                let out = zeros::<$s, 1>(36, dev).with_grad().unwrap();
                let launch = || wp::launch(k_adjoint, 1, (&r, &s, &out), dev).unwrap();
                launch();
                // [[R, 0], [S, R]], times 2.
                let want: Vec<f64> = (0..36)
                    .map(|k| {
                        let (i, j) = (k / 6, k % 6);
                        2.0 * match (i / 3, j / 3) {
                            (0, 0) | (1, 1) => ra[3 * (i % 3) + j % 3] as f64,
                            (1, 0) => sa[3 * (i % 3) + j % 3] as f64,
                            _ => 0.0,
                        }
                    })
                    .collect();
                near(&f64s(&host(&out)), &want, TOL, "2 spatial_adjoint(R, S)");
                let rows = |m: $m3| -> Vec<f64> {
                    m.transpose()
                        .to_cols_array()
                        .iter()
                        .map(|&a| a as f64)
                        .collect()
                };
                for i in 0..6 {
                    for j in 0..6 {
                        let (gr, gs) = grad_of(dev, &out, 6 * i + j, launch, || {
                            (host(&r.grad().unwrap())[0], host(&s.grad().unwrap())[0])
                        });
                        let mut want_r = vec![0.0; 9];
                        if i / 3 == j / 3 {
                            want_r[3 * (i % 3) + j % 3] = 2.0;
                        }
                        let mut want_s = vec![0.0; 9];
                        if i / 3 == 1 && j / 3 == 0 {
                            want_s[3 * (i % 3) + j % 3] = 2.0;
                        }
                        near(
                            &rows(gr),
                            &want_r,
                            10.0 * TOL,
                            &format!("d out[{i}, {j}] / dR"),
                        );
                        near(
                            &rows(gs),
                            &want_s,
                            10.0 * TOL,
                            &format!("d out[{i}, {j}] / dS"),
                        );
                    }
                }
            }
        }
    };
}

spatial_ports!(
    p32,
    f32,
    SpatialVector,
    SpatialMatrix,
    Vec3,
    Mat3,
    1.0e-6,
    5.0e-6
);
spatial_ports!(
    p64,
    f64,
    DSpatialVector,
    DSpatialMatrix,
    DVec3,
    DMat3,
    1.0e-8,
    1.0e-8
);

fn constructors_f32(dev: &wp::Device) {
    p32::constructors(dev);
}
fn constructors_f64(dev: &wp::Device) {
    p64::constructors(dev);
}
fn indexing_f32(dev: &wp::Device) {
    p32::indexing(dev);
}
fn indexing_f64(dev: &wp::Device) {
    p64::indexing(dev);
}
fn dot_f32(dev: &wp::Device) {
    p32::dot(dev);
}
fn dot_f64(dev: &wp::Device) {
    p64::dot(dev);
}
fn cross_f32(dev: &wp::Device) {
    p32::cross(dev);
}
fn cross_f64(dev: &wp::Device) {
    p64::cross(dev);
}
fn top_bottom_f32(dev: &wp::Device) {
    p32::top_bottom(dev);
}
fn top_bottom_f64(dev: &wp::Device) {
    p64::top_bottom(dev);
}
fn matvec_f32(dev: &wp::Device) {
    p32::matvec(dev);
}
fn matvec_f64(dev: &wp::Device) {
    p64::matvec(dev);
}
fn adjoint_f32(dev: &wp::Device) {
    p32::adjoint(dev);
}
fn adjoint_f64(dev: &wp::Device) {
    p64::adjoint(dev);
}

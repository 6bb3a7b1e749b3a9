//! The tile linear algebra (`tile_cholesky`, `tile_cholesky_solve`, `tile_lower_solve`,
//! `tile_upper_solve`) on every backend: batches of random symmetric positive definite systems
//! of 4, 16 and 32 unknowns in f32 and f64, one system per block.
//!
//! Two kinds of check:
//! - **Exact:** each backend's factor and solutions are warp-core's (`tile::linalg`, run here on
//!   the host) bit for bit, at several block sizes. The CPU backend calls those functions; the
//!   CUDA section runs the same roundings in the same order (no FMA contraction), and
//!   tests/cuda_tile_linalg_host.rs checks it under the block emulator. So CPU == GPU exactly.
//!   (NaN results compare as NaN: a GPU's NaN bits need not be the host's.)
//! - **Accuracy, against float64:** the normwise backward errors
//!   `|L Lᵀ - A| / |A|` and `|A x - y| / (|A| |x| + |y|)` (infinity norms, evaluated in f64)
//!   must be below `4 N eps` of the element type. Cholesky and triangular substitution are
//!   backward stable with bounds of order `N eps` (Higham, ch. 8 and 10); the values measured
//!   on these systems are at most `0.18 N eps`, so the factor 4 only leaves room, it does not
//!   hide an error of the algorithm (a wrong term would give O(1)).

// The code the kernel macro generates for a tiled kernel's CPU block rounds up by hand, and
// clippy reports it at the kernel (as in tiles.rs).
#![allow(clippy::manual_div_ceil)]

use crate::{arr, host, zeros};
use warp_core::tile::{self as ct, Tile1, Tile2};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    cholesky_and_solves_f32,
    cholesky_and_solves_f64,
    cholesky_solve_of_several_right_hand_sides,
    not_positive_definite_gives_nan,
    backward_through_cholesky_f32,
);

/// A kernel factoring `B` systems of `N` unknowns (rows `b N ..` of `a`, `y`): it stores `L`,
/// `x = cholesky_solve(L, y)`, `z = lower_solve(L, y)` and `w = upper_solve(Lᵀ, z)` (= `x`).
macro_rules! chol_kernel {
    ($name:ident, $t:ident, $n:tt) => {
        #[wp::kernel]
        fn $name(
            a: Array<$t, 2>,
            y: Array<$t>,
            l: Array<$t, 2>,
            x: Array<$t>,
            z: Array<$t>,
            w: Array<$t>,
        ) {
            let b = tid();
            let o = (b * $n) as i32;
            let ta = tile_load::<$n, $n>(a, (o, 0));
            let ty = tile_load::<$n>(y, o);
            let tl = tile_cholesky(ta);
            let tx = tile_cholesky_solve(tl, ty);
            let tz = tile_lower_solve(tl, ty);
            let tu = tile_transpose(tl);
            let tw = tile_upper_solve(tu, tz);
            tile_store(l, tl, (o, 0));
            tile_store(x, tx, o);
            tile_store(z, tz, o);
            tile_store(w, tw, o);
        }
    };
}

chol_kernel!(k_chol_f32_4, f32, 4);
chol_kernel!(k_chol_f32_16, f32, 16);
chol_kernel!(k_chol_f32_32, f32, 32);
chol_kernel!(k_chol_f64_4, f64, 4);
chol_kernel!(k_chol_f64_16, f64, 16);
chol_kernel!(k_chol_f64_32, f64, 32);

/// Seeded values in [-1, 1).
fn values(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// `B Bᵀ + n I` for a random `B`, row-major: symmetric positive definite.
fn spd(n: usize, r: &mut impl FnMut() -> f64) -> Vec<f64> {
    let b: Vec<f64> = (0..n * n).map(|_| r()).collect();
    let mut a = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            let d: f64 = (0..n).map(|k| b[i * n + k] * b[j * n + k]).sum();
            a[i * n + j] = d + if i == j { n as f64 } else { 0.0 };
        }
    }
    a
}

fn inf_norm(m: &[f64], rows: usize, cols: usize) -> f64 {
    (0..rows)
        .map(|i| (0..cols).map(|j| m[i * cols + j].abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// The backward errors of a factor and a solution, in f64 (see the module's docs).
fn backward_errors(a: &[f64], l: &[f64], x: &[f64], y: &[f64], n: usize) -> (f64, f64) {
    let an = inf_norm(a, n, n);
    let mut llt = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            llt[i * n + j] =
                (0..n).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>() - a[i * n + j];
        }
    }
    let res: Vec<f64> = (0..n)
        .map(|i| (0..n).map(|k| a[i * n + k] * x[k]).sum::<f64>() - y[i])
        .collect();
    let xn = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let yn = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    (
        inf_norm(&llt, n, n) / an,
        res.iter().fold(0.0f64, |m, v| m.max(v.abs())) / (an * xn + yn),
    )
}

/// Same bits, where a NaN equals any NaN.
fn same<T: Copy + Into<f64>>(a: T, b: T) -> bool {
    let (a, b): (f64, f64) = (a.into(), b.into());
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// Runs a `chol_kernel!` kernel over `batch` random systems at several block sizes and checks
/// it: exactly against warp-core, within `4 N eps` against f64.
macro_rules! check_chol {
    ($dev:expr, $kernel:ident, $t:ident, $n:tt, $eps:expr, $seed:expr) => {{
        const N: usize = $n;
        let dev: &wp::Device = $dev;
        let batch = 5usize;
        let mut r = values($seed);
        let mut a64 = Vec::new();
        let mut y64 = Vec::new();
        for _ in 0..batch {
            a64.extend(spd(N, &mut r));
            y64.extend((0..N).map(|_| r()));
        }
        let a: Vec<$t> = a64.iter().map(|&v| v as $t).collect();
        let y: Vec<$t> = y64.iter().map(|&v| v as $t).collect();
        let da = wp::Array::from_slice_shape(&a, (batch * N, N), dev).unwrap();
        let dy = arr(&y, dev);
        let dl = zeros::<$t, 2>((batch * N, N), dev);
        let (dx, dz, dw) = (
            zeros::<$t, 1>(batch * N, dev),
            zeros::<$t, 1>(batch * N, dev),
            zeros::<$t, 1>(batch * N, dev),
        );
        for bd in [32, 64, 128] {
            wp::launch_tiled($kernel, batch, (&da, &dy, &dl, &dx, &dz, &dw), bd, dev).unwrap();
            let (l, x, z, w) = (host(&dl), host(&dx), host(&dz), host(&dw));
            for s in 0..batch {
                let sa = Tile2::<$t, N, N> {
                    data: std::array::from_fn(|i| std::array::from_fn(|j| a[(s * N + i) * N + j])),
                };
                let sy = Tile1::<$t, N> {
                    data: std::array::from_fn(|i| y[s * N + i]),
                };
                let hl = ct::cholesky(&sa);
                let hx = ct::cholesky_solve1(&hl, &sy);
                let hz = ct::lower_solve1(&hl, &sy);
                let hw = ct::upper_solve1(&ct::transpose(&hl), &hz);
                for i in 0..N {
                    for j in 0..N {
                        let g = l[(s * N + i) * N + j];
                        assert!(
                            same(g, hl.data[i][j]),
                            "L[{i}][{j}] of system {s}, block_dim {bd}: {g} vs {}",
                            hl.data[i][j]
                        );
                    }
                    let k = s * N + i;
                    assert!(
                        same(x[k], hx.data[i]),
                        "x[{i}] of system {s}, block_dim {bd}"
                    );
                    assert!(
                        same(z[k], hz.data[i]),
                        "z[{i}] of system {s}, block_dim {bd}"
                    );
                    assert!(
                        same(w[k], hw.data[i]),
                        "w[{i}] of system {s}, block_dim {bd}"
                    );
                }
                // Against float64: the matrix and right-hand side as stored (in T), exactly.
                let sa64: Vec<f64> = a[s * N * N..(s + 1) * N * N]
                    .iter()
                    .map(|&v| v as f64)
                    .collect();
                let sy64: Vec<f64> = y[s * N..(s + 1) * N].iter().map(|&v| v as f64).collect();
                let sl64: Vec<f64> = l[s * N * N..(s + 1) * N * N]
                    .iter()
                    .map(|&v| v as f64)
                    .collect();
                let sx64: Vec<f64> = x[s * N..(s + 1) * N].iter().map(|&v| v as f64).collect();
                let (ef, es) = backward_errors(&sa64, &sl64, &sx64, &sy64, N);
                let tol = 4.0 * N as f64 * $eps;
                assert!(
                    ef < tol,
                    "|LLt - A|/|A| = {ef:e} >= {tol:e} (N {N}, block_dim {bd})"
                );
                assert!(
                    es < tol,
                    "|Ax - y| backward error {es:e} >= {tol:e} (N {N}, block_dim {bd})"
                );
            }
        }
    }};
}

fn cholesky_and_solves_f32(dev: &wp::Device) {
    let eps = f32::EPSILON as f64;
    check_chol!(dev, k_chol_f32_4, f32, 4, eps, 1);
    check_chol!(dev, k_chol_f32_16, f32, 16, eps, 2);
    check_chol!(dev, k_chol_f32_32, f32, 32, eps, 3);
}

fn cholesky_and_solves_f64(dev: &wp::Device) {
    let eps = f64::EPSILON;
    check_chol!(dev, k_chol_f64_4, f64, 4, eps, 4);
    check_chol!(dev, k_chol_f64_16, f64, 16, eps, 5);
    check_chol!(dev, k_chol_f64_32, f64, 32, eps, 6);
}

#[wp::kernel]
fn k_chol_multi(a: Array<f64, 2>, y: Array<f64, 2>, x: Array<f64, 2>, z: Array<f64, 2>) {
    let b = tid();
    let o = (b * 16) as i32;
    let ta = tile_load::<16, 16>(a, (o, 0));
    let ty = tile_load::<16, 3>(y, (o, 0));
    let tl = tile_cholesky(ta);
    let tx: Tile<f64, 16, 3> = tile_cholesky_solve(tl, ty);
    let tz = tile_lower_solve(tl, ty);
    tile_store(x, tx, (o, 0));
    tile_store(z, tz, (o, 0));
}

/// A 2-D right-hand side (Warp allows `(N, K)`): 3 columns solved at once, each exactly as
/// warp-core solves it, and each column the same bits as a 1-D solve of it.
fn cholesky_solve_of_several_right_hand_sides(dev: &wp::Device) {
    const N: usize = 16;
    let batch = 3;
    let mut r = values(9);
    let mut a = Vec::new();
    for _ in 0..batch {
        a.extend(spd(N, &mut r));
    }
    let y: Vec<f64> = (0..batch * N * 3).map(|_| r()).collect();
    let da = wp::Array::from_slice_shape(&a, (batch * N, N), dev).unwrap();
    let dy = wp::Array::from_slice_shape(&y, (batch * N, 3), dev).unwrap();
    let dx = zeros::<f64, 2>((batch * N, 3), dev);
    let dz = zeros::<f64, 2>((batch * N, 3), dev);
    for bd in [1, 32, 96] {
        wp::launch_tiled(k_chol_multi, batch, (&da, &dy, &dx, &dz), bd, dev).unwrap();
        let (x, z) = (host(&dx), host(&dz));
        for s in 0..batch {
            let sa = Tile2::<f64, N, N> {
                data: std::array::from_fn(|i| std::array::from_fn(|j| a[(s * N + i) * N + j])),
            };
            let sy = Tile2::<f64, N, 3> {
                data: std::array::from_fn(|i| std::array::from_fn(|c| y[(s * N + i) * 3 + c])),
            };
            let hl = ct::cholesky(&sa);
            let hx = ct::cholesky_solve2(&hl, &sy);
            let hz = ct::lower_solve2(&hl, &sy);
            for i in 0..N {
                for c in 0..3 {
                    let k = (s * N + i) * 3 + c;
                    assert_eq!(
                        x[k].to_bits(),
                        hx.data[i][c].to_bits(),
                        "x[{i}][{c}], block_dim {bd}"
                    );
                    assert_eq!(
                        z[k].to_bits(),
                        hz.data[i][c].to_bits(),
                        "z[{i}][{c}], block_dim {bd}"
                    );
                    let col = Tile1::<f64, N> {
                        data: std::array::from_fn(|r| sy.data[r][c]),
                    };
                    assert_eq!(
                        ct::cholesky_solve1(&hl, &col).data[i].to_bits(),
                        hx.data[i][c].to_bits()
                    );
                }
            }
        }
    }
}

/// A matrix with a negative pivot (symmetric, not positive definite): the whole factor is NaN,
/// and so is the solution, on every backend; the well-posed system in the same launch is not
/// affected (each block is its own system).
fn not_positive_definite_gives_nan(dev: &wp::Device) {
    const N: usize = 4;
    let mut r = values(12);
    let good = spd(N, &mut r);
    // Pivot 2 is 1 - 4 = -3.
    let mut bad = vec![0.0f64; N * N];
    for i in 0..N {
        bad[i * N + i] = 1.0;
    }
    bad[N] = 2.0;
    bad[1] = 2.0;
    let a: Vec<f32> = good.iter().chain(&bad).map(|&v| v as f32).collect();
    let y: Vec<f32> = (0..2 * N).map(|k| k as f32 + 1.0).collect();
    let da = wp::Array::from_slice_shape(&a, (2 * N, N), dev).unwrap();
    let dy = arr(&y, dev);
    let dl = zeros::<f32, 2>((2 * N, N), dev);
    let (dx, dz, dw) = (
        zeros::<f32, 1>(2 * N, dev),
        zeros::<f32, 1>(2 * N, dev),
        zeros::<f32, 1>(2 * N, dev),
    );
    wp::launch_tiled(k_chol_f32_4, 2, (&da, &dy, &dl, &dx, &dz, &dw), 32, dev).unwrap();
    let (l, x) = (host(&dl), host(&dx));
    assert!(l[..N * N].iter().all(|v| v.is_finite()), "{l:?}");
    assert!(x[..N].iter().all(|v| v.is_finite()));
    assert!(
        l[N * N..].iter().all(|v| v.is_nan()),
        "the bad system's factor: {l:?}"
    );
    assert!(x[N..].iter().all(|v| v.is_nan()));
}

/// Backward through a kernel that factors and solves in f32 (the gradchecks are f64's, in
/// tile_grad_linalg.rs): `x = A⁻¹ y` with `A` symmetric, so `ȳ = A⁻¹ x̄`, here `A⁻¹ 1`.
/// Tolerance: 1e-4 relative to the largest element, a few hundred f32 roundings of a
/// well-conditioned 4 x 4 system.
fn backward_through_cholesky_f32(dev: &wp::Device) {
    const N: usize = 4;
    let mut r = values(13);
    let a64 = spd(N, &mut r);
    let a: Vec<f32> = a64.iter().map(|&v| v as f32).collect();
    let da = wp::Array::from_slice_shape(&a, (N, N), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let dy = arr(&[1.0f32; N], dev).with_grad().unwrap();
    let dl = zeros::<f32, 2>((N, N), dev).with_grad().unwrap();
    let (dx, dz, dw) = (
        zeros::<f32, 1>(N, dev).with_grad().unwrap(),
        zeros::<f32, 1>(N, dev),
        zeros::<f32, 1>(N, dev),
    );
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_chol_f32_4, 1, (&da, &dy, &dl, &dx, &dz, &dw), 32, dev).unwrap();
    }
    tape.backward(&dx).unwrap();
    let gy = host(&dy.grad().unwrap());
    // A⁻¹ 1 in f64 from warp-core's factor.
    let a_t = Tile2::<f64, N, N> {
        data: std::array::from_fn(|i| std::array::from_fn(|j| a64[i * N + j])),
    };
    let want = ct::cholesky_solve1(&ct::cholesky(&a_t), &Tile1 { data: [1.0; N] }).data;
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (g, w) in gy.iter().zip(want) {
        assert!((*g as f64 - w).abs() <= 1e-4 * scale, "{gy:?} vs {want:?}");
    }
    let ga = host(&da.grad().unwrap());
    assert!(
        ga.iter().all(|v| v.is_finite()) && ga.iter().any(|v| *v != 0.0),
        "{ga:?}"
    );
}

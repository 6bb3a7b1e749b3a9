//! The batched Cholesky solve of `examples/tile_cholesky.rs`, shared with the GPU benchmark's
//! `--tile-cholesky` section (benches/gpu.rs includes this file), so that both measure the same
//! kernel: the systems, the kernel, and the float64 reference.
//!
//! System `s` is rows `s N .. (s + 1) N` of `a` (a `(batch N) x N` array, each block `A_s`,
//! row-major) and elements `s N ..` of `y`; the kernel writes `x_s` with `A_s x_s = y_s` into
//! `x`, one block per system: `tile_load`, `tile_cholesky`, `tile_cholesky_solve`,
//! `tile_store`. The matrices are `B Bᵀ + I` for `B` uniform in [-1, 1) (Wishart-like: their
//! eigenvalues lie in about [1, 45] at N = 32), the right-hand sides uniform in [-1, 1).

// Each includer uses its own subset.
#![allow(dead_code)]
// The code the kernel macro generates for a tiled kernel's CPU block rounds up by hand, and
// clippy reports it at the kernel (as in tile_gemm.rs).
#![allow(clippy::manual_div_ceil)]

use rand::Rng as _;
use warp_lang as wp;
use wp::prelude::*;

/// The order of the systems.
pub const N: usize = 32;

/// `x_s = A_s⁻¹ y_s` for each block `s` (f32).
#[wp::kernel]
pub fn chol_solve_f32(a: Array<f32, 2>, y: Array<f32>, x: Array<f32>) {
    let s = tid();
    let o = (s * N) as i32;
    let ta = tile_load::<N, N>(a, (o, 0));
    let ty = tile_load::<N>(y, o);
    let l = tile_cholesky(ta);
    let tx = tile_cholesky_solve(l, ty);
    tile_store(x, tx, o);
}

/// The same in f64.
#[wp::kernel]
pub fn chol_solve_f64(a: Array<f64, 2>, y: Array<f64>, x: Array<f64>) {
    let s = tid();
    let o = (s * N) as i32;
    let ta = tile_load::<N, N>(a, (o, 0));
    let ty = tile_load::<N>(y, o);
    let l = tile_cholesky(ta);
    let tx = tile_cholesky_solve(l, ty);
    tile_store(x, tx, o);
}

/// `batch` systems (`B Bᵀ + I`, right-hand sides uniform in [-1, 1)) in float64, seeded: the
/// matrices row-major one after another, and the right-hand sides.
pub fn systems(batch: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut r = super::common::rng(seed);
    let mut a = vec![0.0f64; batch * N * N];
    let mut b = [0.0f64; N * N];
    for s in 0..batch {
        for v in b.iter_mut() {
            *v = r.random::<f64>() * 2.0 - 1.0;
        }
        let m = &mut a[s * N * N..(s + 1) * N * N];
        for i in 0..N {
            for j in 0..=i {
                let d: f64 = (0..N).map(|k| b[i * N + k] * b[j * N + k]).sum();
                let v = d + if i == j { 1.0 } else { 0.0 };
                m[i * N + j] = v;
                m[j * N + i] = v;
            }
        }
    }
    let y = (0..batch * N)
        .map(|_| r.random::<f64>() * 2.0 - 1.0)
        .collect();
    (a, y)
}

/// The float64 solution of system `s` of `a`, `y` (as given: a float32 run passes its rounded
/// inputs widened, so the reference solves exactly the system the kernel was handed), by an
/// unblocked float64 Cholesky factor and two substitutions.
pub fn reference(a: &[f64], y: &[f64], s: usize) -> [f64; N] {
    let m = &a[s * N * N..(s + 1) * N * N];
    let mut l = [[0.0f64; N]; N];
    for j in 0..N {
        let p = m[j * N + j] - (0..j).map(|k| l[j][k] * l[j][k]).sum::<f64>();
        l[j][j] = p.sqrt();
        for i in j + 1..N {
            l[i][j] = (m[i * N + j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>()) / l[j][j];
        }
    }
    let mut x = [0.0f64; N];
    for i in 0..N {
        x[i] = (y[s * N + i] - (0..i).map(|k| l[i][k] * x[k]).sum::<f64>()) / l[i][i];
    }
    for i in (0..N).rev() {
        x[i] = (x[i] - (i + 1..N).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    x
}

/// max over the systems `checked` of |x - x64|_inf / |x64|_inf, `x64` the [`reference`]
/// solution of the same (widened) inputs: the forward error, which grows with each system's
/// condition number (about cond · u).
pub fn max_error(a: &[f64], y: &[f64], x: &[f64], checked: &[usize]) -> f64 {
    let mut worst = 0.0f64;
    for &s in checked {
        let r = reference(a, y, s);
        let norm = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let err = (0..N).fold(0.0f64, |m, i| m.max((x[s * N + i] - r[i]).abs()));
        // NaN (a failed factor) must show, not vanish in `max`.
        worst = if err.is_nan() {
            f64::NAN
        } else {
            worst.max(err / norm)
        };
        if worst.is_nan() {
            break;
        }
    }
    worst
}

/// `samples` seeded system indices below `batch` (all of them when there are no more), always
/// including the last.
pub fn checked_systems(batch: usize, samples: usize) -> Vec<usize> {
    if batch <= samples {
        return (0..batch).collect();
    }
    let mut r = super::common::rng(17);
    let mut v: Vec<usize> = (0..samples.saturating_sub(1))
        .map(|_| r.random_range(0..batch))
        .collect();
    v.push(batch - 1);
    v
}

/// max over the systems `checked` of the normwise backward error
/// |A x - y|_inf / (|A|_inf |x|_inf + |y|_inf), in float64: how far `x` is from solving a
/// nearby system exactly, independent of the conditioning (a backward-stable solve keeps it
/// of the order of N u).
pub fn max_backward_error(a: &[f64], y: &[f64], x: &[f64], checked: &[usize]) -> f64 {
    let mut worst = 0.0f64;
    for &s in checked {
        let m = &a[s * N * N..(s + 1) * N * N];
        let xs = &x[s * N..(s + 1) * N];
        let ys = &y[s * N..(s + 1) * N];
        let an = (0..N)
            .map(|i| (0..N).map(|k| m[i * N + k].abs()).sum::<f64>())
            .fold(0.0f64, f64::max);
        let xn = xs.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let yn = ys.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let res = (0..N)
            .map(|i| ((0..N).map(|k| m[i * N + k] * xs[k]).sum::<f64>() - ys[i]).abs())
            .fold(0.0f64, |a, v| if v.is_nan() { f64::NAN } else { a.max(v) });
        let e = res / (an * xn + yn);
        if e.is_nan() {
            return f64::NAN;
        }
        worst = worst.max(e);
    }
    worst
}

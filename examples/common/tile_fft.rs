//! The batched FFT of `examples/tile_fft.rs`, shared with the GPU benchmark's `--tile-fft`
//! section (benches/gpu.rs includes this file), so that both measure the same kernel: the
//! signals, the kernel, and the float64 reference.
//!
//! The input is `rows` complex signals of `N = 64` points (a `rows x N` array of `Vec2`, `x` the
//! real part), uniform in [-1, 1)²; block `b` loads rows `b M .. (b + 1) M` as one
//! `Tile<Vec2, M, N>`, transforms them with `tile_fft` and stores the spectra.

// Each includer uses its own subset.
#![allow(dead_code)]
// The code the kernel macro generates for a tiled kernel's CPU block rounds up by hand, and
// clippy reports it at the kernel (as in tile_cholesky.rs).
#![allow(clippy::manual_div_ceil)]

use rand::Rng as _;
use warp_lang as wp;
use wp::prelude::*;

/// The transform's length.
pub const N: usize = 64;
/// Rows a block transforms together.
pub const M: usize = 8;

/// `y = fft(x)` row by row, `M` rows a block.
#[wp::kernel]
pub fn fft_rows(x: Array<Vec2, 2>, y: Array<Vec2, 2>) {
    let b = tid();
    let o = (b * M) as i32;
    let mut t = tile_load::<M, N>(x, (o, 0));
    tile_fft(&mut t);
    tile_store(y, t, (o, 0));
}

/// The same in f64.
#[wp::kernel]
pub fn fft_rows_f64(x: Array<DVec2, 2>, y: Array<DVec2, 2>) {
    let b = tid();
    let o = (b * M) as i32;
    let mut t = tile_load::<M, N>(x, (o, 0));
    tile_fft(&mut t);
    tile_store(y, t, (o, 0));
}

/// `rows` signals of `N` points, seeded, as (re, im) pairs in float64.
pub fn signals(rows: usize, seed: u64) -> Vec<(f64, f64)> {
    let mut r = super::common::rng(seed);
    (0..rows * N)
        .map(|_| (r.random::<f64>() * 2.0 - 1.0, r.random::<f64>() * 2.0 - 1.0))
        .collect()
}

/// The float64 DFT of one row (the exact angle `2 pi (jk mod N) / N`, libm's sin and cos).
pub fn dft(x: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let n = x.len();
    (0..n)
        .map(|k| {
            let mut acc = (0.0, 0.0);
            for (j, &(a, b)) in x.iter().enumerate() {
                let th = -2.0 * std::f64::consts::PI * ((j * k) % n) as f64 / n as f64;
                let (s, c) = th.sin_cos();
                acc.0 += a * c - b * s;
                acc.1 += a * s + b * c;
            }
            acc
        })
        .collect()
}

/// Rows checked against the float64 DFT: all of them, or `samples` seeded ones.
pub fn checked_rows(rows: usize, samples: usize) -> Vec<usize> {
    if rows <= samples {
        return (0..rows).collect();
    }
    let mut r = super::common::rng(7);
    (0..samples).map(|_| r.random_range(0..rows)).collect()
}

/// The worst relative error over the checked rows: `max_k |y_k - Y_k| / max_k |Y_k|` (complex
/// moduli), `Y` the float64 DFT of the same (rounded) input `x`.
pub fn max_error(x: &[(f64, f64)], y: &[(f64, f64)], checked: &[usize]) -> f64 {
    let mut worst = 0.0f64;
    for &r in checked {
        let want = dft(&x[r * N..(r + 1) * N]);
        let scale = want.iter().map(|w| w.0.hypot(w.1)).fold(0.0, f64::max);
        let err = want
            .iter()
            .zip(&y[r * N..(r + 1) * N])
            .map(|(w, g)| (w.0 - g.0).hypot(w.1 - g.1))
            .fold(0.0, f64::max);
        // A NaN must show, not vanish in max.
        worst = if err.is_nan() {
            f64::NAN
        } else {
            worst.max(err / scale)
        };
    }
    worst
}

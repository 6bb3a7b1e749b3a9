//! Batched FFTs with tiles: thousands of 64-point complex signals, `M` rows a block
//! (`tile_load`, `tile_fft`, `tile_store`, launched with `wp::launch_tiled`), Warp's
//! example_tile_fft at scale. Prints the time per batch next to the error against a float64
//! DFT.
//!
//! ```text
//! cargo run --release --example tile_fft -- [--device cpu|cuda:0] [--rows 65536] [--f64]
//!     [--reps 5] [--block-dim 64] [--samples 256]
//! ```
//! The signals are uniform in [-1, 1)², seeded. The error is the worst over the checked rows
//! (all of them, or `--samples` seeded ones) of `max_k |y_k - Y_k| / max_k |Y_k|`, `Y` the
//! float64 DFT of the same rounded input. A radix-2 FFT's error grows as `eps log2 N`, and
//! the verdict checks it against `4 eps log2 N` (eps = 2^-23 in f32, 2^-52 in f64).
//!
//! Both backends compute the same bits (the CUDA library runs warp-core's order of roundings
//! spread over the block's threads), so the error printed does not depend on the device.

mod common;
#[path = "common/tile_fft.rs"]
mod tile_fft;

use clap::Parser;
use glam::{DVec2, Vec2};
use std::time::Instant;

use common::{num, DeviceArg};
use tile_fft::{checked_rows, fft_rows, fft_rows_f64, max_error, signals, M, N};
use warp_lang as wp;

/// Batched 64-point FFTs with tiles: time per batch and the error against float64.
#[derive(Parser, Debug)]
struct Args {
    #[command(flatten)]
    device: DeviceArg,
    /// Signals transformed per launch (a multiple of the rows a block takes, 8)
    #[arg(long, default_value = "65536", value_parser = num::<usize>)]
    rows: usize,
    /// Transform in f64 (default f32)
    #[arg(long)]
    f64: bool,
    /// Timed launches after a warm-up; the median is printed
    #[arg(long, default_value = "5", value_parser = num::<usize>)]
    reps: usize,
    /// Threads per block
    #[arg(long, default_value = "64", value_parser = num::<usize>)]
    block_dim: usize,
    /// Rows checked against the float64 DFT (all of them when there are fewer)
    #[arg(long, default_value = "256", value_parser = num::<usize>)]
    samples: usize,
}

/// Median milliseconds of `reps` runs of `f` after one warm-up run (which also compiles the
/// kernel on a GPU), the device synchronised around each run; and the warm-up's.
fn median_ms(reps: usize, mut f: impl FnMut() -> wp::Result<()>) -> wp::Result<(f64, f64)> {
    let t = Instant::now();
    f()?;
    wp::synchronize()?;
    let first = t.elapsed().as_secs_f64() * 1e3;
    let mut times = Vec::with_capacity(reps);
    for _ in 0..reps {
        let t = Instant::now();
        f()?;
        wp::synchronize()?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok((times[times.len() / 2], first))
}

fn main() -> wp::Result<()> {
    let args = Args::parse();
    if args.rows == 0 || !args.rows.is_multiple_of(M) || args.reps == 0 || args.block_dim == 0 {
        eprintln!(
            "tile_fft: --rows must be a positive multiple of {M}, --reps and --block-dim at least 1 (got {}, {}, {})",
            args.rows, args.reps, args.block_dim
        );
        std::process::exit(2);
    }
    let dev = args.device.get()?;
    let elem = if args.f64 { "f64" } else { "f32" };
    println!(
        "{} signals of {N} points in {elem} on {dev}, {M} a block of {} threads",
        args.rows, args.block_dim
    );
    let x64 = signals(args.rows, 2026);
    let (rows, bd, blocks) = (args.rows, args.block_dim, args.rows / M);
    let (t, first, x, y, eps) = if args.f64 {
        let xh: Vec<DVec2> = x64.iter().map(|&(a, b)| DVec2::new(a, b)).collect();
        let dx = wp::Array::from_slice_shape(&xh, (rows, N), &dev)?;
        let dy = wp::Array::<DVec2, 2>::zeros((rows, N), &dev)?;
        let (t, first) = median_ms(args.reps, || {
            wp::launch_tiled(fft_rows_f64, blocks, (&dx, &dy), bd, &dev)
        })?;
        let y: Vec<(f64, f64)> = dy.to_vec()?.iter().map(|v| (v.x, v.y)).collect();
        (t, first, x64, y, f64::EPSILON)
    } else {
        let xh: Vec<Vec2> = x64
            .iter()
            .map(|&(a, b)| Vec2::new(a as f32, b as f32))
            .collect();
        let dx = wp::Array::from_slice_shape(&xh, (rows, N), &dev)?;
        let dy = wp::Array::<Vec2, 2>::zeros((rows, N), &dev)?;
        let (t, first) = median_ms(args.reps, || {
            wp::launch_tiled(fft_rows, blocks, (&dx, &dy), bd, &dev)
        })?;
        let y: Vec<(f64, f64)> = dy
            .to_vec()?
            .iter()
            .map(|v| (v.x as f64, v.y as f64))
            .collect();
        // The reference transforms the rounded inputs the kernel was given.
        let x = xh.iter().map(|v| (v.x as f64, v.y as f64)).collect();
        (t, first, x, y, f32::EPSILON as f64)
    };
    let checked = checked_rows(rows, args.samples);
    let err = max_error(&x, &y, &checked);
    println!(
        "\n{:>12} {:>14} {:>14} {:>16}",
        "ms / batch", "signals / s", "first run ms", "relative error"
    );
    println!(
        "{t:>12.3} {:>14.3e} {first:>14.1} {err:>16.2e}",
        rows as f64 / (t * 1e-3)
    );
    println!(
        "(median of {} launches after a warm-up, which includes compiling on a GPU; error: the \
         worst of {} checked rows, against a float64 DFT)",
        args.reps,
        checked.len()
    );
    let bound = 4.0 * eps * (N.trailing_zeros() as f64);
    common::verdict(
        "tile_fft",
        err <= bound,
        &format!("relative error <= 4 eps log2 N = {bound:.2e}"),
    );
    common::print_compiled();
    Ok(())
}

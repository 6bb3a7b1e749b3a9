//! Batched dense solves with tiles: `A_s x_s = y_s` for thousands of symmetric positive
//! definite 32 x 32 systems, one block per system (`tile_load`, `tile_cholesky`,
//! `tile_cholesky_solve`, `tile_store`, launched with `wp::launch_tiled`). Prints the time per
//! batch next to the error against a float64 reference.
//!
//! ```text
//! cargo run --release --example tile_cholesky -- [--device cpu|cuda:0] [--batch 4096]
//!     [--f64] [--reps 5] [--block-dim 64] [--samples 512]
//! ```
//! The systems are `B Bᵀ + I` with `B` uniform in [-1, 1) (eigenvalues in about [1, 45]),
//! right-hand sides uniform in [-1, 1), seeded. Two errors, each the worst over the
//! checked systems (all of them, or `--samples` seeded ones):
//! - forward: |x - x64| / |x64| (infinity norms), `x64` the float64 solution of the same
//!   rounded inputs. It grows with the condition number (about cond · u), so it is reported,
//!   not judged;
//! - backward: |A x - y| / (|A| |x| + |y|) in float64. Cholesky with substitutions is backward
//!   stable: this stays of the order of N u whatever the conditioning, and the verdict checks
//!   it against 4 N u (u = 2^-24 in f32, 2^-53 in f64), the same bound as the test suite.
//!
//! Both backends compute the same bits (the CUDA library runs warp-core's order of roundings
//! spread over the block's threads), so the errors printed do not depend on the device.

mod common;
#[path = "common/tile_cholesky.rs"]
mod tile_cholesky;

use clap::Parser;
use std::time::Instant;

use common::{num, DeviceArg};
use tile_cholesky::{
    checked_systems, chol_solve_f32, chol_solve_f64, max_backward_error, max_error, systems, N,
};
use warp_lang as wp;

/// Batched 32 x 32 Cholesky solves with tiles: time per batch and the error against float64.
#[derive(Parser, Debug)]
struct Args {
    #[command(flatten)]
    device: DeviceArg,
    /// Systems solved per launch
    #[arg(long, default_value = "4096", value_parser = num::<usize>)]
    batch: usize,
    /// Solve in f64 (default f32)
    #[arg(long)]
    f64: bool,
    /// Timed launches after a warm-up; the median is printed
    #[arg(long, default_value = "5", value_parser = num::<usize>)]
    reps: usize,
    /// Threads per block
    #[arg(long, default_value = "64", value_parser = num::<usize>)]
    block_dim: usize,
    /// Systems checked against float64 (all of them when the batch is smaller)
    #[arg(long, default_value = "512", value_parser = num::<usize>)]
    samples: usize,
}

/// Median milliseconds of `reps` runs of `f` after one warm-up run (which also compiles the
/// kernel on a GPU), the device synchronised around each run.
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

/// Solves the batch in `T` (f32 or f64): the time, the first run's, and the solution widened.
fn solve<T: wp::Element + Copy + Into<f64>>(
    args: &Args,
    dev: &wp::Device,
    a: &[T],
    y: &[T],
    launch: impl Fn(&wp::Array<T, 2>, &wp::Array<T>, &wp::Array<T>) -> wp::Result<()>,
) -> wp::Result<(f64, f64, Vec<f64>)> {
    let da = wp::Array::from_slice_shape(a, (args.batch * N, N), dev)?;
    let dy = wp::Array::from_slice(y, dev)?;
    let dx = wp::Array::from_slice(y, dev)?;
    let (t, first) = median_ms(args.reps, || launch(&da, &dy, &dx))?;
    let x = dx.to_vec()?.into_iter().map(Into::into).collect();
    Ok((t, first, x))
}

fn main() -> wp::Result<()> {
    let args = Args::parse();
    if args.batch == 0 || args.reps == 0 || args.block_dim == 0 {
        eprintln!(
            "tile_cholesky: --batch, --reps and --block-dim must be at least 1 (got {}, {}, {})",
            args.batch, args.reps, args.block_dim
        );
        std::process::exit(2);
    }
    let dev = args.device.get()?;
    let elem = if args.f64 { "f64" } else { "f32" };
    println!(
        "{} systems of {N} x {N} in {elem} on {dev}, one block of {} threads each",
        args.batch, args.block_dim
    );
    let (a64, y64) = systems(args.batch, 2026);
    let (bd, batch) = (args.block_dim, args.batch);
    let (t, first, x, a, y, u) = if args.f64 {
        let (t, first, x) = solve(&args, &dev, &a64, &y64, |a, y, x| {
            wp::launch_tiled(chol_solve_f64, batch, (a, y, x), bd, &dev)
        })?;
        (t, first, x, a64, y64, f64::EPSILON / 2.0)
    } else {
        let a32: Vec<f32> = a64.iter().map(|&v| v as f32).collect();
        let y32: Vec<f32> = y64.iter().map(|&v| v as f32).collect();
        let (t, first, x) = solve(&args, &dev, &a32, &y32, |a, y, x| {
            wp::launch_tiled(chol_solve_f32, batch, (a, y, x), bd, &dev)
        })?;
        // The reference solves the rounded inputs the kernel was given.
        let a = a32.iter().map(|&v| v as f64).collect();
        let y = y32.iter().map(|&v| v as f64).collect();
        (t, first, x, a, y, f32::EPSILON as f64 / 2.0)
    };
    let checked = checked_systems(args.batch, args.samples);
    let forward = max_error(&a, &y, &x, &checked);
    let backward = max_backward_error(&a, &y, &x, &checked);
    println!(
        "\n{:>12} {:>14} {:>14} {:>16} {:>16}",
        "ms / batch", "systems / s", "first run ms", "forward error", "backward error"
    );
    println!(
        "{t:>12.3} {:>14.3e} {first:>14.1} {forward:>16.2e} {backward:>16.2e}",
        args.batch as f64 / (t * 1e-3)
    );
    println!(
        "(median of {} launches after a warm-up, which includes compiling on a GPU; errors: the \
         worst of {} checked systems, against float64)",
        args.reps,
        checked.len()
    );
    let bound = 4.0 * N as f64 * 2.0 * u;
    common::verdict(
        "tile_cholesky",
        backward <= bound,
        &format!("backward error <= 4 N eps = {bound:.2e}"),
    );
    common::print_compiled();
    Ok(())
}

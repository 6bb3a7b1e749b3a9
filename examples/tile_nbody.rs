//! All-pairs gravitational n-body with tiles: each block loads the bodies `TILE` at a time into
//! shared memory (`tile_load` of a `(TILE, 4)` chunk of `(x, y, z, m)` rows, launched with
//! `wp::launch_tiled`), and each lane sums the chunk's pulls on its own body, reading the tile's
//! elements; against examples/nbody.rs's scalar kernel (one thread per body, every position read
//! from global memory), the same physics in the same run. Warp's example_tile_nbody, with the
//! accuracy measured.
//!
//! ```text
//! cargo run --release --example tile_nbody -- [--device cpu|cuda:0] [--n 16384] [--steps 200]
//!     [--dt 0.005] [--softening 0.05] [--block-dim 64] [--samples 256]
//! ```
//! The bodies start in the unit ball near virial equilibrium (G = 1, total mass 1; see
//! `common/tile_nbody.rs`), and each kernel runs `--steps` leapfrog steps from there, one launch
//! a step. Printed for each kernel:
//! - the time per step (after a warm-up launch, which compiles on a GPU) and pair interactions
//!   per second;
//! - the error of the first step's accelerations against float64 (of the same f32 start state),
//!   over all bodies or `--samples` seeded ones: `max_c |a_ic - A_ic| / sum_j |term_ij|`, the
//!   rounding of the sum relative to its terms' magnitudes (the sum itself may cancel to about
//!   0 at a body near the centre). The verdict checks it against `(n + 16) u` (u = 2^-24): an f32
//!   sum of n terms rounds n - 1 times, each time by at most u times the sum of the magnitudes
//!   (the textbook bound, every order of summation meets it), and each term carries about 14 u
//!   of its own. Typical errors are nearer `sqrt(n) u` (printed beside it);
//! - the energy drift `|E(T) - E(0)| / |E(0)|` over the run (float64 energy at whole steps: the
//!   half-step velocities are kicked half a step by float64 accelerations), mostly the scheme's
//!   `O(dt^2)` truncation, the same for both kernels.
//!
//! Then the range probes: two coincident bodies (the softening makes their pull exactly zero
//! instead of 0/0), masses from 1e-40 to 1e30 in one system (finite, within the bound), and
//! masses past `f32::MAX eps^3`, whose own terms overflow: reported as a divergence naming the
//! array, index and value, not returned silently.

mod common;
#[path = "common/tile_nbody.rs"]
mod tile_nbody;

use clap::Parser;
use std::time::Instant;

use common::{num, DeviceArg};
use glam::DVec3;
use tile_nbody::{Kernel, Sim};
use warp_lang as wp;

/// All-pairs n-body: tiled (shared memory) against scalar, time per step, the accelerations'
/// error against float64 and the energy drift.
#[derive(Parser, Debug)]
struct Args {
    #[command(flatten)]
    device: DeviceArg,
    /// Bodies [default: 16384 on a GPU, 1024 on the CPU]
    #[arg(long, value_parser = num::<usize>)]
    n: Option<usize>,
    /// Leapfrog steps of each kernel [default: 200 on a GPU, 20 on the CPU]
    #[arg(long, value_parser = num::<usize>)]
    steps: Option<usize>,
    /// Time step
    #[arg(long, default_value_t = 0.005)]
    dt: f64,
    /// Softening length eps (coincident bodies then pull with zero force, not 0/0)
    #[arg(long, default_value_t = tile_nbody::SOFTENING)]
    softening: f64,
    /// Threads per block of the tiled kernel (each owns one body)
    #[arg(long, default_value = "64", value_parser = num::<usize>)]
    block_dim: usize,
    /// Bodies whose accelerations are checked against float64 (all when there are fewer)
    #[arg(long, default_value = "256", value_parser = num::<usize>)]
    samples: usize,
}

/// One kernel's run: what the table prints.
struct Row {
    kernel: Kernel,
    ms: f64,
    first_ms: f64,
    /// The first step's accelerations (at the start state).
    a0: Vec<DVec3>,
    error: f64,
    /// The relative energy drift, or why the run stopped.
    drift: Result<f64, String>,
}

#[allow(clippy::too_many_arguments)]
fn run(
    kernel: Kernel,
    x0: &[DVec3],
    v_half: &[DVec3],
    m: &[f64],
    e0: f64,
    args: &Args,
    steps: usize,
    checked: &[usize],
    dev: &wp::Device,
) -> wp::Result<Row> {
    let eps = args.softening;
    // The warm-up: one step (compiling the kernel on a GPU), whose accelerations are a(x_0).
    let t = Instant::now();
    let mut warm = Sim::new(kernel, x0, v_half, m, eps, args.dt, dev)?;
    warm.step()?;
    wp::synchronize()?;
    let first_ms = t.elapsed().as_secs_f64() * 1e3;
    let a0 = warm.accelerations()?;
    let error = tile_nbody::acceleration_error(&a0, x0, m, eps, checked);
    // The timed run, from the start state again.
    let mut sim = Sim::new(kernel, x0, v_half, m, eps, args.dt, dev)?;
    wp::synchronize()?;
    let t = Instant::now();
    for _ in 0..steps {
        sim.step()?;
    }
    wp::synchronize()?;
    let ms = t.elapsed().as_secs_f64() * 1e3 / steps as f64;
    let drift = match sim.check_finite() {
        Err(e) => Err(e.to_string()),
        Ok(()) => {
            let (x, m) = sim.bodies()?;
            let v = tile_nbody::half_kick(&x, &sim.velocities()?, &m, eps, 0.5 * args.dt);
            let change = (tile_nbody::energy(&x, &v, &m, eps) - e0).abs();
            // Relative, except for a system of zero energy (one body at rest).
            Ok(if e0 == 0.0 { change } else { change / e0.abs() })
        }
    };
    Ok(Row {
        kernel,
        ms,
        first_ms,
        a0,
        error,
        drift,
    })
}

fn main() -> wp::Result<()> {
    let args = Args::parse();
    let (eps, dt) = (args.softening, args.dt);
    // Checked before the device starts, naming the options and the values given.
    if args.n == Some(0)
        || args.steps == Some(0)
        || !(1..=1024).contains(&args.block_dim)
        || !(eps > 0.0 && eps.is_finite())
        || !(dt > 0.0 && dt.is_finite())
    {
        eprintln!(
            "tile_nbody: --n and --steps must be at least 1, --block-dim in 1..=1024, \
             --softening and --dt positive and finite (got {:?}, {:?}, {}, {eps}, {dt})",
            args.n, args.steps, args.block_dim
        );
        std::process::exit(2);
    }
    let dev = args.device.get()?;
    let gpu = dev.is_cuda();
    let n = args.n.unwrap_or(if gpu { 16384 } else { 1024 });
    let steps = args.steps.unwrap_or(if gpu { 200 } else { 20 });
    let bd = args.block_dim;
    println!(
        "{n} bodies on {dev}, softening {eps}, {steps} leapfrog steps of {dt}; tiled: blocks of \
         {bd} threads, {} bodies a tile",
        tile_nbody::TILE
    );
    let (x0, v0, m) = tile_nbody::start(n, 2026);
    let e0 = tile_nbody::energy(&x0, &v0, &m, eps);
    let v_half = tile_nbody::half_kick(&x0, &v0, &m, eps, -0.5 * dt);
    let checked = tile_nbody::checked_bodies(n, args.samples);
    let mut rows = Vec::new();
    for kernel in [Kernel::Tiled { block_dim: bd }, Kernel::Scalar] {
        rows.push(run(
            kernel, &x0, &v_half, &m, e0, &args, steps, &checked, &dev,
        )?);
    }
    println!(
        "\n{:<8} {:>10} {:>14} {:>13} {:>15} {:>14}",
        "kernel", "ms / step", "pairs / s", "first run ms", "accel. error", "energy drift"
    );
    for r in &rows {
        let drift = match &r.drift {
            Ok(d) => format!("{d:.2e}"),
            Err(_) => "diverged".into(),
        };
        println!(
            "{:<8} {:>10.3} {:>14.3e} {:>13.1} {:>15.2e} {:>14}",
            r.kernel.name(),
            r.ms,
            (n * n) as f64 / (r.ms * 1e-3),
            r.first_ms,
            r.error,
            drift
        );
    }
    for r in &rows {
        if let Err(why) = &r.drift {
            println!("{}: {why}", r.kernel.name());
        }
    }
    let (tiled, scalar) = (&rows[0], &rows[1]);
    println!(
        "tiled / scalar time: {:.3}; E(0) = {e0:.6}",
        tiled.ms / scalar.ms
    );
    // The two sum in the same order with the same operations: on the CPU the same bits; a GPU
    // compiler may contract differently in the two kernels.
    let same = tiled
        .a0
        .iter()
        .zip(&scalar.a0)
        .filter(|(a, b)| a != b)
        .count();
    if same == 0 {
        println!("tiled and scalar accelerations: the same bits for all {n} bodies");
    } else {
        let diff = checked
            .iter()
            .map(|&i| {
                let scale = tile_nbody::acceleration_f64(&x0, &m, eps, i).1;
                (tiled.a0[i] - scalar.a0[i]).abs().max_element() / scale
            })
            .fold(0.0, f64::max);
        println!(
            "tiled and scalar accelerations differ for {same} of {n} bodies, by at most \
             {diff:.2e} of the terms' sum over the checked ones"
        );
    }
    let bound = tile_nbody::error_bound(n);
    println!(
        "(time: {steps} steps after a warm-up step, which includes compiling on a GPU; \
         accel. error: the worst of {} bodies against float64, relative to the sum of the terms' \
         lengths; typical f32 rounding sqrt(n) u = {:.2e}; energy drift: |E(T) - E(0)| / |E(0)| \
         in float64)",
        checked.len(),
        (n as f64).sqrt() * f32::EPSILON as f64 / 2.0
    );

    println!(
        "\nrange probes (one step each, softening {}):",
        tile_nbody::SOFTENING
    );
    let mut probes_ok = true;
    for case in tile_nbody::cases() {
        for kernel in [Kernel::Tiled { block_dim: bd }, Kernel::Scalar] {
            let got = tile_nbody::stability(&case, kernel, &dev);
            let bound = tile_nbody::error_bound(case.x.len());
            let (text, ok) = match (&got, case.finite) {
                (Ok(e), true) => (format!("finite, error {e:.2e}"), *e <= bound),
                (Ok(e), false) => (format!("finite (error {e:.2e}), expected a report"), false),
                (Err(wp::Error::Diverged { .. }), false) => {
                    (format!("reported: {}", got.as_ref().unwrap_err()), true)
                }
                (Err(e), _) => (format!("error: {e}"), false),
            };
            probes_ok &= ok;
            println!("  {:<52} {:<7} {text}", case.name, kernel.name());
        }
    }

    let ok = |e: f64| e <= bound;
    let drifts_finite = rows.iter().all(|r| r.drift.is_ok());
    common::verdict(
        "tile_nbody",
        ok(tiled.error) && ok(scalar.error) && drifts_finite && probes_ok,
        &format!(
            "both kernels' acceleration errors <= (n + 16) u = {bound:.2e}, finite runs, and the \
             range probes finite within their bound or reported"
        ),
    );
    common::print_compiled();
    Ok(())
}

//! The seed particle program's gradient through a checkpointed rollout (`wp::Checkpointed`):
//! memory for about sqrt(T) states instead of a full tape's T + 1 states with gradients.
//!
//! ```text
//! cargo run --release --example checkpoint -- [--device cpu|cuda:0] [--particles 1000000]
//!     [--steps 1000] [--snapshots K] [--compare-particles 10000] [--compare-steps 1000]
//!     [--plot-dir DIR]
//! ```
//! Runs on the GPU when there is one. The main run (default 1M particles x 1000 steps) prints
//! the forward and backward times, the recomputed steps, the states and bytes held at the peak
//! against a full tape's (computed from the schedule) and the gradients' errors against the
//! closed form (dL/dx0 = 2 x_T, dL/dv0 = 2 c x_T, see `common/seed_ad.rs`). The comparison run,
//! first (default 10k particles x 1000 steps, where a full tape fits in memory;
//! `--compare-particles 0` skips it), runs a full tape too and prints the largest differences
//! of the gradients (0 on the CPU: the same adjoints on the same inputs in the same order),
//! then sweeps the snapshot budget at that size (2, 4, 8, .. snapshots, below the steps) and
//! prints the trade-off as a table (states held, MiB, steps recomputed, time) and as the plot
//! `<--plot-dir or target/report>/checkpoint.svg` (memory falls as the budget shrinks,
//! recomputation and time rise). On Linux each run also
//! prints the process's measured peak resident memory (host memory: on a GPU the states live
//! in device memory and the schedule's figures are the ones to read).

mod common;
#[path = "common/seed_ad.rs"]
mod seed_ad;

use clap::Parser;
use seed_ad::{
    seed_closed_form_errors, seed_start, step, sum_sq, SEED_B as B, SEED_DT as DT,
    SEED_GRAVITY as GRAVITY, SEED_MASS as MASS,
};
use std::time::Instant;
use warp_lang as wp;
use warp_report::{sci, Curves, Table};
use wp::prelude::*;

type State = (wp::Array<Vec3>, wp::Array<Vec3>);

/// The seed program's initial state (as `particle_gradients` makes it), with gradients.
fn initial(n: usize, dev: &wp::Device) -> wp::Result<State> {
    let (x0, v0) = seed_start(n);
    Ok((
        wp::Array::from_slice(&x0, dev)?.with_grad()?,
        wp::Array::from_slice(&v0, dev)?.with_grad()?,
    ))
}

/// Resets the process's peak resident memory (Linux: `clear_refs` 5); false elsewhere.
fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The process's peak resident memory in bytes since the last reset (Linux `VmHWM`).
fn peak_rss() -> Option<usize> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

fn mib(bytes: usize) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

/// The gradients of a checkpointed rollout and what it took.
struct Run {
    gx: Vec<Vec3>,
    gv: Vec<Vec3>,
    x_t: Vec<Vec3>,
    forward_ms: f64,
    backward_ms: f64,
    report: wp::CheckpointReport,
    recomputed: u64,
}

/// L = sum |x_T|^2 through a checkpointed rollout of `steps` steps with `snapshots` (default:
/// the square-root budget).
fn checkpointed(
    n: usize,
    steps: usize,
    snapshots: Option<usize>,
    dev: &wp::Device,
) -> wp::Result<Run> {
    let s0 = initial(n, dev)?;
    let budget = snapshots.unwrap_or_else(|| wp::Checkpointed::<State>::sqrt_budget(steps));
    let mut roll = wp::Checkpointed::new(&s0, steps, budget, |_t, (x0, v0), (x1, v1)| {
        wp::launch(step, n, (x0, v0, x1, v1, B, MASS, GRAVITY, DT), dev)
    })?;
    let loss = wp::Array::<f32>::zeros(1, dev)?.with_grad()?;
    wp::synchronize()?;
    let t = Instant::now();
    let tape = wp::Tape::new();
    let x_t = {
        let (x, _) = roll.forward()?;
        let _rec = tape.record();
        wp::launch(sum_sq, n, (x, &loss), dev)?;
        x.clone()
    };
    wp::synchronize()?;
    let forward_ms = t.elapsed().as_secs_f64() * 1e3;
    // The final state's values, read before the backward pass reuses the working states.
    let x_t = x_t.to_vec()?;
    let t = Instant::now();
    tape.backward(&loss)?;
    roll.backward()?;
    wp::synchronize()?;
    let backward_ms = t.elapsed().as_secs_f64() * 1e3;
    let (report, recomputed) = (roll.report().clone(), roll.recomputed());
    drop(roll);
    Ok(Run {
        gx: s0.0.grad().expect("with_grad").to_vec()?,
        gv: s0.1.grad().expect("with_grad").to_vec()?,
        x_t,
        forward_ms,
        backward_ms,
        report,
        recomputed,
    })
}

/// The same gradients through a full tape (T + 1 states with gradients), and its time.
fn full_tape(n: usize, steps: usize, dev: &wp::Device) -> wp::Result<(Vec<Vec3>, Vec<Vec3>, f64)> {
    let (x0, v0) = initial(n, dev)?;
    let mut xs = vec![x0];
    let mut vs = vec![v0];
    for _ in 0..steps {
        xs.push(wp::Array::<Vec3>::zeros(n, dev)?.with_grad()?);
        vs.push(wp::Array::<Vec3>::zeros(n, dev)?.with_grad()?);
    }
    let loss = wp::Array::<f32>::zeros(1, dev)?.with_grad()?;
    wp::synchronize()?;
    let t = Instant::now();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        for s in 0..steps {
            let args = (&xs[s], &vs[s], &xs[s + 1], &vs[s + 1], B, MASS, GRAVITY, DT);
            wp::launch(step, n, args, dev)?;
        }
        wp::launch(sum_sq, n, (&xs[steps], &loss), dev)?;
    }
    tape.backward(&loss)?;
    wp::synchronize()?;
    let ms = t.elapsed().as_secs_f64() * 1e3;
    Ok((
        xs[0].grad().expect("with_grad").to_vec()?,
        vs[0].grad().expect("with_grad").to_vec()?,
        ms,
    ))
}

/// The largest absolute difference of two gradients, and whether they are the same bits.
fn max_diff(a: &[Vec3], b: &[Vec3]) -> (f32, bool) {
    let d = a
        .iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).abs().max_element())
        .fold(0.0f32, f32::max);
    let same = a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits));
    (d, same)
}

/// The seed program's gradient through a checkpointed tape: memory against recomputation,
/// and the gradient against a full tape's.
#[derive(Parser)]
struct Cli {
    /// Particles in the checkpointed runs
    #[arg(long, value_name = "N", default_value = "1_000_000", value_parser = common::num::<usize>)]
    particles: usize,
    /// Steps in the checkpointed runs
    #[arg(long, value_name = "T", default_value_t = 1000, value_parser = common::num::<usize>)]
    steps: usize,
    /// Snapshots the checkpointed tape keeps [default: `Checkpointed::sqrt_budget`, about
    /// the square root of the steps]
    #[arg(long, value_name = "K", value_parser = common::num::<usize>)]
    snapshots: Option<usize>,
    /// Particles in the comparison with a full tape (0: no comparison)
    #[arg(long, value_name = "N", default_value = "10_000", value_parser = common::num::<usize>)]
    compare_particles: usize,
    /// Steps in the comparison with a full tape
    #[arg(long, value_name = "T", default_value_t = 1000, value_parser = common::num::<usize>)]
    compare_steps: usize,
    #[command(flatten)]
    device: common::DeviceArg,
    #[command(flatten)]
    plot: common::PlotDirArg,
}

/// The snapshot budgets of the trade-off sweep: 2, 4, 8, .. below `steps` (fewer than two
/// snapshots recompute about T^2 / 2 steps: minutes at the comparison's size).
fn sweep_budgets(steps: usize) -> Vec<usize> {
    std::iter::successors(Some(2usize), |k| Some(k * 2))
        .take_while(|&k| k < steps)
        .collect()
}

/// The memory against recomputation trade-off of `n` particles x `steps` steps over the
/// snapshot budgets: its table, printed, and its plot, written.
fn budget_sweep(
    n: usize,
    steps: usize,
    budgets: &[usize],
    dev: &wp::Device,
    bar: &indicatif::ProgressBar,
) -> wp::Result<()> {
    let mut table = Table::new([
        "snapshots",
        "states held",
        "MiB held",
        "steps recomputed",
        "forward + backward (ms)",
    ]);
    let mut curves = Curves::new(
        format!("checkpointed gradient, {n} particles x {steps} steps on {dev}"),
        "value",
    );
    for &k in budgets {
        bar.set_message(format!("{k} snapshots"));
        let run = checkpointed(n, steps, Some(k), dev)?;
        bar.inc(1);
        let ms = run.forward_ms + run.backward_ms;
        let r = &run.report;
        table.push([
            k.to_string(),
            r.states_held.to_string(),
            format!("{:.2}", mib(r.bytes_held)),
            run.recomputed.to_string(),
            format!("{ms:.1}"),
        ]);
        curves.push("MiB held", k as f64, mib(r.bytes_held));
        curves.push("forward + backward (ms)", k as f64, ms);
        curves.push(
            "steps recomputed / T",
            k as f64,
            run.recomputed as f64 / steps as f64,
        );
    }
    bar.suspend(|| {
        println!(
        "  snapshot budget against memory and recomputation (a full tape: {} states):\n\n{table}",
        sci((steps + 1) as f64)
    );
        common::write_plot("checkpoint", |path| {
            curves.write_svg(path).map_err(|e| e.to_string())
        });
        println!();
    });
    Ok(())
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.device.get()?;
    cli.plot.init();
    let (n, steps, snapshots) = (cli.particles, cli.steps, cli.snapshots);
    let (cn, csteps) = (cli.compare_particles, cli.compare_steps);

    // Warm-up: loads `step`, `sum_sq` and their adjoints (compiles them on a GPU).
    checkpointed(16, 4, Some(1), &dev)?;

    // The comparison first: the allocator may keep memory a larger run freed, which would
    // count in a later run's measured peak.
    let budgets = if cn > 0 {
        sweep_budgets(csteps)
    } else {
        Vec::new()
    };
    // One tick per run: the comparison's two, the budget sweep's, then the main run's (long:
    // 1M particles x 1000 steps by default).
    let bar = common::progress(if cn > 0 { 2 + budgets.len() as u64 } else { 0 } + 1);
    if cn > 0 {
        bar.set_message("comparison: checkpointed");
        let measured = reset_peak_rss();
        let run = checkpointed(cn, csteps, snapshots, &dev)?;
        let ck_rss = peak_rss().filter(|_| measured);
        bar.inc(1);
        bar.set_message("comparison: full tape");
        let measured = reset_peak_rss();
        let (gx, gv, full_ms) = full_tape(cn, csteps, &dev)?;
        let full_rss = peak_rss().filter(|_| measured);
        bar.inc(1);
        let r = &run.report;
        // Printed with the bar hidden (indicatif draws it again below).
        bar.suspend(|| {
            println!("against a full tape, {cn} particles x {csteps} steps on \"{dev}\":");
            println!(
                "  checkpointed: {} states held, {:.1} MiB, forward + backward {:.1} ms, {} steps \
             recomputed",
                r.states_held,
                mib(r.bytes_held),
                run.forward_ms + run.backward_ms,
                run.recomputed
            );
            println!(
                "  full tape:    {} states with gradients, {:.1} MiB, forward + backward {:.1} ms",
                r.full_tape_states,
                mib(r.full_tape_bytes),
                full_ms
            );
            if let (Some(a), Some(b)) = (ck_rss, full_rss) {
                println!(
                    "  measured peak resident memory: checkpointed {:.1} MiB, full tape {:.1} MiB",
                    mib(a),
                    mib(b)
                );
            }
            let (dx, sx) = max_diff(&run.gx, &gx);
            let (dv, sv) = max_diff(&run.gv, &gv);
            let word = |same: bool| if same { "bit-identical" } else { "differ" };
            println!("  max |dL/dx0 difference| {dx:e} ({})", word(sx));
            println!("  max |dL/dv0 difference| {dv:e} ({})\n", word(sv));
        });
        budget_sweep(cn, csteps, &budgets, &dev, &bar)?;
    }
    bar.set_message(format!("{n} particles x {steps} steps"));
    let measured = reset_peak_rss();
    let run = checkpointed(n, steps, snapshots, &dev)?;
    let rss = peak_rss().filter(|_| measured);
    bar.finish_and_clear();
    println!("seed particle program, {n} particles x {steps} steps on \"{dev}\"");
    println!("{}", run.report);
    println!(
        "  forward {:.1} ms, backward {:.1} ms (ratio {:.2}); the backward pass recomputed {} \
         steps",
        run.forward_ms,
        run.backward_ms,
        run.backward_ms / run.forward_ms,
        run.recomputed
    );
    if let Some(rss) = rss {
        println!(
            "  measured: peak resident memory of the process {:.1} MiB, at most (it may \
             include memory the allocator kept from the comparison; states held by the \
             schedule: {:.1} MiB{})",
            mib(rss),
            mib(run.report.bytes_held),
            if dev.is_cpu() { "" } else { " on the GPU" }
        );
    }
    let (ex, ev) = seed_closed_form_errors(&run.x_t, &run.gx, &run.gv, steps);
    println!("  max relative error of dL/dx0 vs 2 x_T:   {ex:.2e}");
    println!("  max relative error of dL/dv0 vs 2 c x_T: {ev:.2e}");
    Ok(())
}

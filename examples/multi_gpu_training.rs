//! Data-parallel differentiable simulation on several GPUs: many randomised environments split
//! across the GPUs, one Tape per GPU, the gradients summed with an NCCL all-reduce every
//! iteration, and the same loss curve as on one GPU.
//!
//! ```text
//! cargo run --release --example multi_gpu_training -- [--gpus 4] [--envs 1_048_576]
//!     [--steps 64] [--iterations 20] [--plot-dir DIR]
//! ```
//! The task: one open-loop control sequence `u[s]` (a force for each of `--steps` steps, shared
//! by every environment) must bring a particle to the origin at the last step, whatever its
//! environment's start point and wind (drawn at random per environment: domain randomisation).
//! Environment `i` steps `a = u[s] + wind_i - drag v + g`, `v' = v + a dt`, `x' = x + v' dt`;
//! the loss is the mean over all environments of `|x_T|^2`. Rank `r` of `G` simulates its
//! block of environments, records the steps and its part of the loss (already divided by the
//! total number of environments) on its own Tape, runs backward, all-reduces (sums) the loss
//! and the gradient of `u` across ranks, and takes the same Adam step on every rank, so the
//! parameters stay identical everywhere. One host thread drives each GPU.
//!
//! Printed:
//! 1. the loss curve on 1 GPU and on G GPUs, and their largest relative difference (the same
//!    computation up to the order of floating-point sums: within 1e-4 relative, f32);
//! 2. strong scaling (the same total environments on 1, 2, .. G GPUs): time per iteration,
//!    speed-up and efficiency `T1 / (G TG)`;
//! 3. weak scaling (the same environments per GPU): efficiency `T1 / TG`;
//! 4. for each, the share of an iteration spent in communication: from the moment this rank's
//!    backward pass has finished to the moment its all-reduces have (waiting for slower ranks
//!    included), the slowest rank's share.
//!
//! Plots, in `<--plot-dir or target/report>/`: `multi_gpu_training.svg`, the loss curve of
//! every GPU count (they lie on each other), and `multi_gpu_training_scaling.svg`, ms per
//! iteration against the GPU count with the ideal of each scaling. A progress bar counts the
//! runs.

mod common;

use clap::Parser;
use std::sync::Arc;
use std::time::Instant;

use warp_lang as wp;
use warp_report::{sci, Table};
use wp::distributed::{Communicator, ReduceOp};
use wp::prelude::*;

/// One step of every environment of this rank: reads row `s`, writes row `s + 1`.
#[wp::kernel]
fn env_step(
    x: Array<Vec3, 2>,
    v: Array<Vec3, 2>,
    wind: Array<Vec3>,
    u: Array<Vec3>,
    drag: f32,
    dt: f32,
    s: i32,
) {
    let i = tid();
    let vs = v[(s, i)];
    let a = u[s] + wind[i] - vs * drag + vec3(0.0, -9.81, 0.0);
    let vn = vs + a * dt;
    v[(s + 1, i)] = vn;
    x[(s + 1, i)] = x[(s, i)] + vn * dt;
}

/// loss += scale |x_T|^2 for every environment of this rank.
#[wp::kernel]
fn final_distance(x: Array<Vec3, 2>, last: i32, scale: f32, loss: Array<f32>) {
    let i = tid();
    let p = x[(last, i)];
    atomic_add(loss, 0, scale * dot(p, p));
}

#[derive(Parser, Debug)]
#[command(about = "Data-parallel differentiable simulation over several GPUs (NCCL all-reduce)")]
struct Args {
    /// The most GPUs to use (all visible ones by default); runs 1, 2, 4, .. up to it.
    #[arg(long, value_parser = common::cli::num::<usize>)]
    gpus: Option<usize>,
    /// Environments in the strong-scaling runs (split across the GPUs), and per GPU in the
    /// weak-scaling runs.
    #[arg(long, default_value = "1048576", value_parser = common::cli::num::<usize>)]
    envs: usize,
    /// Simulation steps per rollout.
    #[arg(long, default_value = "64", value_parser = common::cli::num::<usize>)]
    steps: usize,
    /// Optimisation iterations per run (the first is not timed: it compiles and warms up).
    #[arg(long, default_value = "20", value_parser = common::cli::num::<usize>)]
    iterations: usize,
    #[command(flatten)]
    plot: common::PlotDirArg,
}

const DT: f32 = 1.0 / 60.0;
const DRAG: f32 = 0.5;

/// What one run measured on one rank.
struct RankRun {
    losses: Vec<f32>,
    /// Seconds per iteration (timed iterations only).
    per_iteration: f64,
    /// Seconds per iteration from "backward done" to "all-reduces done".
    communication: f64,
}

/// Start point and wind of environment `i` (the same whatever the split: a hash of `i`).
fn environment(i: usize) -> (Vec3, Vec3) {
    let h = |k: u64| {
        let mut z =
            (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ k.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 31)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    };
    (
        Vec3::new(4.0 * h(1), 2.0 + h(2), 4.0 * h(3)),
        Vec3::new(2.0 * h(4), 0.5 * h(5), 2.0 * h(6)),
    )
}

/// One rank's part of a run: environments `first .. first + count` of `total`.
fn rank_run(
    comm: &Communicator,
    first: usize,
    count: usize,
    total: usize,
    args: &Args,
) -> wp::Result<RankRun> {
    let dev = comm.device().clone();
    let steps = args.steps;
    let (x0, wind): (Vec<Vec3>, Vec<Vec3>) = (first..first + count).map(environment).unzip();
    let mut xs = vec![Vec3::ZERO; (steps + 1) * count];
    xs[..count].copy_from_slice(&x0);
    let x = wp::Array::from_slice_shape(&xs, (steps + 1, count), &dev)?.with_grad()?;
    let v = wp::Array::<Vec3, 2>::zeros((steps + 1, count), &dev)?.with_grad()?;
    let wind = wp::Array::from_slice(&wind, &dev)?;
    let u = wp::Array::<Vec3>::zeros(steps, &dev)?.with_grad()?;
    let loss = wp::Array::<f32>::zeros(1, &dev)?.with_grad()?;
    let mut adam = wp::optim::Adam::new(0.5);
    adam.add(&u)?;
    let grad_u = u.grad().expect("with_grad");
    let grad_loss = loss.grad().expect("with_grad");
    let scale = 1.0 / total as f32;
    let mut losses = Vec::new();
    let (mut timed, mut comm_time) = (0.0, 0.0);
    for it in 0..args.iterations {
        let start = Instant::now();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            for s in 0..steps {
                wp::launch(
                    env_step,
                    count,
                    (&x, &v, &wind, &u, DRAG, DT, s as i32),
                    &dev,
                )?;
            }
            loss.fill(0.0)?;
            wp::launch(
                final_distance,
                count,
                (&x, steps as i32, scale, &loss),
                &dev,
            )?;
        }
        tape.backward(&loss)?;
        comm.synchronize()?;
        let comm_start = Instant::now();
        // The loss (for the curve) and the gradient: sums over every environment.
        comm.all_reduce_in_place(&grad_u, ReduceOp::Sum)?;
        comm.all_reduce_in_place(&loss, ReduceOp::Sum)?;
        comm.synchronize()?;
        let comm_end = Instant::now();
        adam.step()?;
        losses.push(loss.to_vec()?[0]);
        // Gradients accumulate from one backward pass to the next: clear them all.
        x.zero_grad()?;
        v.zero_grad()?;
        grad_loss.fill(0.0)?;
        adam.zero_grad()?;
        comm.synchronize()?;
        if it > 0 {
            timed += start.elapsed().as_secs_f64();
            comm_time += (comm_end - comm_start).as_secs_f64();
        }
    }
    let n = (args.iterations.max(2) - 1) as f64;
    Ok(RankRun {
        losses,
        per_iteration: timed / n,
        communication: comm_time / n,
    })
}

/// A run on the first `g` GPUs with `total` environments split evenly.
fn run(gpus: &[wp::Device], g: usize, total: usize, args: &Args) -> wp::Result<Vec<RankRun>> {
    let comms = Arc::new(Communicator::for_devices(&gpus[..g])?);
    let per = total / g;
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..g)
            .map(|r| {
                let comms = comms.clone();
                s.spawn(move || {
                    let count = if r == g - 1 {
                        total - per * (g - 1)
                    } else {
                        per
                    };
                    rank_run(&comms[r], r * per, count, total, args)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("rank thread panicked"))
            .collect()
    })
}

fn main() {
    let args = Args::parse();
    if let Err(e) = real_main(&args) {
        eprintln!("multi_gpu_training: {e}");
        std::process::exit(1);
    }
}

fn real_main(args: &Args) -> wp::Result<()> {
    wp::init();
    args.plot.init();
    let all: Vec<wp::Device> = wp::devices().into_iter().filter(|d| d.is_cuda()).collect();
    let max = args.gpus.unwrap_or(all.len()).min(all.len());
    if max == 0 || !wp::distributed::nccl_available() {
        return Err(wp::Error::NoDevice {
            name: "cuda".into(),
            reason: format!(
                "this example needs CUDA GPUs and NCCL ({} GPU(s); NCCL: {:?})",
                all.len(),
                wp::distributed::nccl_version()
            ),
        });
    }
    let counts: Vec<usize> = std::iter::successors(Some(1usize), |g| Some(g * 2))
        .take_while(|g| *g <= max)
        .collect();
    println!(
        "{} environments x {} steps, {} iterations, GPUs: {}, NCCL {:?}",
        args.envs,
        args.steps,
        args.iterations,
        all[..max]
            .iter()
            .map(|d| d.name().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        wp::distributed::nccl_version()?
    );
    // Strong scaling, with the loss curves.
    let mut strong = Table::new([
        "GPUs",
        "ms / iteration",
        "speed-up",
        "efficiency",
        "communication",
        "final loss",
        "max rel. loss diff vs 1 GPU",
    ]);
    let mut base: Option<(Vec<f32>, f64)> = None;
    let mut worst_diff = 0.0f64;
    // One tick per run: strong and weak scaling, each on 1, 2, .. G GPUs.
    let bar = common::progress(2 * counts.len() as u64);
    let (mut strong_ms, mut weak_ms) = (Vec::new(), Vec::new());
    // The loss curve of every GPU count, plotted against the iteration.
    let mut curves = warp_report::Curves::new(
        format!(
            "multi_gpu_training: mean |x_T|^2 over {} environments",
            args.envs
        ),
        "loss",
    );
    let mut curve_table = None;
    for &g in &counts {
        bar.set_message(format!("strong scaling, {g} GPUs"));
        let runs = run(&all, g, args.envs, args)?;
        bar.inc(1);
        let t = runs.iter().map(|r| r.per_iteration).fold(0.0, f64::max);
        let c = runs
            .iter()
            .map(|r| r.communication / r.per_iteration)
            .fold(0.0, f64::max);
        let losses = &runs[0].losses;
        // Every rank holds the same reduced loss.
        for r in &runs[1..] {
            assert_eq!(&r.losses, losses, "ranks disagree on the reduced loss");
        }
        let (curve, t1) = base.get_or_insert_with(|| (losses.clone(), t));
        let diff = curve
            .iter()
            .zip(losses)
            .map(|(a, b)| ((a - b) / a).abs() as f64)
            .fold(0.0, f64::max);
        worst_diff = worst_diff.max(diff);
        strong_ms.push((g, t * 1e3));
        for (k, l) in losses.iter().enumerate() {
            curves.push(&format!("{g} GPUs"), k as f64, *l as f64);
        }
        strong.push([
            g.to_string(),
            format!("{:.3}", t * 1e3),
            format!("{:.2}", *t1 / t),
            format!("{:.0}%", 100.0 * *t1 / (g as f64 * t)),
            format!("{:.1}%", 100.0 * c),
            sci(losses[losses.len() - 1] as f64),
            sci(diff),
        ]);
        if g == *counts.last().unwrap() {
            let mut table = Table::new(["iteration", "loss, 1 GPU", &format!("loss, {g} GPUs")]);
            for (k, (a, b)) in base.as_ref().unwrap().0.iter().zip(losses).enumerate() {
                if k % (args.iterations / 10).max(1) == 0 || k + 1 == losses.len() {
                    table.push([k.to_string(), sci(*a as f64), sci(*b as f64)]);
                }
            }
            curve_table = Some(table);
        }
    }
    // Weak scaling.
    let mut weak = Table::new([
        "GPUs",
        "environments",
        "ms / iteration",
        "efficiency",
        "communication",
    ]);
    let mut t1 = None;
    for &g in &counts {
        bar.set_message(format!("weak scaling, {g} GPUs"));
        let runs = run(&all, g, args.envs * g, args)?;
        bar.inc(1);
        let t = runs.iter().map(|r| r.per_iteration).fold(0.0, f64::max);
        let c = runs
            .iter()
            .map(|r| r.communication / r.per_iteration)
            .fold(0.0, f64::max);
        let t1 = *t1.get_or_insert(t);
        weak_ms.push((g, t * 1e3));
        weak.push([
            g.to_string(),
            (args.envs * g).to_string(),
            format!("{:.3}", t * 1e3),
            format!("{:.0}%", 100.0 * t1 / t),
            format!("{:.1}%", 100.0 * c),
        ]);
    }
    bar.finish_and_clear();
    if let Some(table) = curve_table {
        println!("\nLoss curves\n\n{table}");
    }
    common::write_plot("multi_gpu_training", |path| {
        curves.write_svg(path).map_err(|e| e.to_string())
    });
    println!(
        "\nStrong scaling: {} environments in all\n\n{strong}",
        args.envs
    );
    println!(
        "\nWeak scaling: {} environments per GPU\n\n{weak}",
        args.envs
    );
    common::write_scaling_plot(
        "multi_gpu_training_scaling",
        &format!(
            "training: strong ({} environments) and weak ({} per GPU) scaling",
            args.envs, args.envs
        ),
        "ms / iteration",
        &strong_ms,
        &weak_ms,
    );
    let ok = worst_diff <= 1e-4;
    println!(
        "\n{}: the loss curves on 1 and {} GPUs differ by at most {} relative (tolerance 1e-4: \
         f32 sums over {} environments in another order)",
        if ok { "PASS" } else { "FAIL" },
        counts.last().unwrap(),
        sci(worst_diff),
        args.envs
    );
    if !ok {
        std::process::exit(1);
    }
    Ok(())
}

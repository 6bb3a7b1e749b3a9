//! A hanging mass-spring chain with stiffness from 1e2 to 1e7 N/m: semi-implicit Euler
//! against XPBD (a thread per chain sweeping its springs in order) and XPBD by colour (the
//! springs coloured on the device, a thread per spring of a colour), each against an f64
//! Runge-Kutta reference at a fine step.
//!
//! ```text
//! cargo run --release --example springs -- [--device cpu|cuda:0] [--chains N]
//!     [--t-end 0.5] [--substeps 10] [--iterations 1] [--halvings 8] [--plot-dir DIR]
//! ```
//! A chain of 20 springs (1 m, 1.05 kg) is released at rest along the horizontal and falls
//! for `--t-end` seconds. For each stiffness the step is swept from 1/60 s down by halvings;
//! each run reports its error (max distance of a particle of the chain from the reference at
//! the end), its run time, its energy drift (relative to the chain falling its own length)
//! and whether it stayed stable (the divergence guard found no NaN or infinity, and every
//! particle stayed within 5 chain lengths of the pin). A summary gives the largest stable step of each
//! solver and stiffness, beside the linear-stability bound 2 / omega_max of explicit
//! integration. Plots: `<plot-dir>/springs_k<k>.svg`.

mod common;
#[path = "common/springs.rs"]
mod springs;

use clap::Parser;
use std::collections::HashMap;
use std::time::Instant;

use springs::{Chains, Solver};
use warp_lang as wp;
// The sparse tier, for common/springs.rs (its coloured XPBD series).
use warp_report::frame::{Camera, Frame, Lines, Points};
use warp_report::{sci, Run, Sweep, Table};
use wp::sparse;

/// Runs `solver` at stiffness `k` and step `dt` until `t_end` and measures it against `reference`
/// (with `graph`, each 256 steps as a replay of a captured graph).
fn run(
    dev: &wp::Device,
    chains: usize,
    (solver, graph): (Solver, bool),
    k: f64,
    dt: f64,
    t_end: f64,
    reference: &[glam::DVec3],
) -> wp::Result<Run> {
    let steps = (t_end / dt).round() as u64;
    let mut state = Chains::new(chains, dev)?;
    // Warm-up (compiles on a GPU) on a throwaway state, outside the timing; the coloured
    // series colours its springs here too (allocations and read-backs, which a capture refuses).
    Chains::new(1, dev)?.step(solver, k as f32, dt as f32, dev)?;
    if let Solver::XpbdColored { .. } = solver {
        state.colouring(dev)?;
    }
    wp::synchronize()?;
    let e0 = springs::energy(
        &springs::start(),
        &vec![glam::DVec3::ZERO; springs::PARTICLES],
        k,
    );
    // With `--graph`, each 256 steps are a replay of a captured graph (an even count: Euler
    // swaps two arrays each step).
    let mut stepper = common::Stepper::new(graph, 256);
    let t = Instant::now();
    let mut s = 0u64;
    while s < steps {
        let n = (stepper.len() as u64).min(steps - s);
        stepper.advance(dev, n as usize, &mut || {
            state.step(solver, k as f32, dt as f32, dev)
        })?;
        s += n;
        // The divergence guard: stop at the first NaN or infinity and say where.
        if let Err(e) = state.x.check_finite("x") {
            let secs = t.elapsed().as_secs_f64();
            return Ok(Run::unstable(s, secs, format!("by step {s}: {e}")));
        }
    }
    wp::synchronize()?;
    let seconds = t.elapsed().as_secs_f64();
    let (x, v) = state.first()?;
    let drift = (springs::energy(&x, &v, k) - e0) / springs::energy_scale();
    let error = x
        .iter()
        .zip(reference)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0f64, f64::max);
    // Bounded means within a ball of 5 chain lengths (the softest chain hangs at about twice
    // its length); the energy drift is reported, not judged: XPBD's elastic energy counts the
    // stretch its sweeps leave unresolved.
    let bound = 5.0 * (springs::SEGMENTS as f64 * springs::REST);
    Ok(if !state.within(bound as f32)? || !error.is_finite() {
        let why = format!("left the ball of {bound} m around the pin");
        Run::unstable(steps, seconds, why).extra(drift)
    } else {
        Run::stable(steps, error, seconds).extra(drift)
    })
}

/// A hanging mass-spring chain, stiffness 1e2 to 1e7 N/m: semi-implicit Euler against
/// XPBD and XPBD by colour, each against an f64 Runge-Kutta reference.
#[derive(Parser)]
struct Cli {
    /// Chains simulated side by side [default: 4096 on a GPU, 16 on the CPU]
    #[arg(long, value_name = "N", value_parser = common::num::<usize>)]
    chains: Option<usize>,
    /// Simulated time (s)
    #[arg(long, default_value_t = 0.5)]
    t_end: f64,
    /// XPBD substeps per step
    #[arg(long, default_value_t = 10, value_parser = common::num::<i32>)]
    substeps: i32,
    /// XPBD constraint iterations per substep
    #[arg(long, default_value_t = 1, value_parser = common::num::<i32>)]
    iterations: i32,
    /// Halvings of the step from 1/60 s
    #[arg(long, default_value_t = 8, value_parser = common::num::<u32>)]
    halvings: u32,
    /// Also run each series as replays of a captured graph
    #[arg(long)]
    graph: bool,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let gpu = dev.is_cuda();
    let chains = cli.chains.unwrap_or(if gpu { 4096 } else { 16 });
    let (t_end, substeps, iterations, halvings) =
        (cli.t_end, cli.substeps, cli.iterations, cli.halvings);
    let stiffnesses = [1e2, 1e3, 1e4, 1e5, 1e6, 1e7];
    let solvers = [
        ("semi-implicit Euler", Solver::Euler),
        (
            "XPBD",
            Solver::Xpbd {
                substeps,
                iterations,
            },
        ),
        (
            "XPBD colored",
            Solver::XpbdColored {
                substeps,
                iterations,
            },
        ),
    ];
    let steps: Vec<f64> = (0..=halvings)
        .map(|j| 1.0 / 60.0 / 2f64.powi(j as i32))
        .collect();
    println!(
        "mass-spring chain: {} springs, {chains} chains on \"{dev}\", until t = {t_end} s, \
         XPBD with {substeps} substeps of {iterations} Gauss-Seidel sweep(s)",
        springs::SEGMENTS
    );
    let mut probe = Chains::new(chains, &dev)?;
    let colours = probe.colouring(&dev)?.1.len();
    println!(
        "XPBD colored: the {} springs in {colours} colours (Jones-Plassmann on the device), \
         a launch per colour and sweep",
        chains * springs::SEGMENTS
    );

    let mut largest: HashMap<(usize, &str), Option<f64>> = HashMap::new();
    let mut drift_at_60hz: HashMap<(usize, &str), f64> = HashMap::new();
    // The frame: each stiffness's reference chain at t_end.
    let mut frame = Frame::new(
        format!("springs: the chain at t = {t_end} s for each stiffness (RK4 reference)"),
        Camera::orthographic([0.0, 0.0, 1.0], [0.0; 3], [0.0, 1.0, 0.0]),
    )
    .note("released at rest along +x, pinned at the origin; colour: log10 k (N/m)");
    let (mut beads, mut bead_k) = (Vec::new(), Vec::new());
    for (ki, &k) in stiffnesses.iter().enumerate() {
        // The reference: RK4 in f64 at a step resolving the fastest spring mode 20 times
        // over; its own error is estimated against a run at twice that step.
        let dt_ref = (0.05 / springs::omega_max(k)).min(1e-4);
        let t = Instant::now();
        let reference = springs::reference(k, t_end, dt_ref);
        let coarse = springs::reference(k, t_end, 2.0 * dt_ref);
        let chain: Vec<[f64; 3]> = reference.iter().map(|&p| common::p3(p)).collect();
        frame = frame.lines(Lines::polyline(&chain));
        bead_k.extend(chain.iter().map(|_| k.log10()));
        beads.extend(chain);
        let ref_err = reference
            .iter()
            .zip(&coarse)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0f64, f64::max);
        println!(
            "\nk = {}: reference RK4 f64 at dt = {} ({:.2} s), |ref(dt) - ref(2 dt)| = {}",
            sci(k),
            sci(dt_ref),
            t.elapsed().as_secs_f64(),
            sci(ref_err)
        );
        let mut sweep = Sweep::new(
            format!("mass-spring chain, k = {} N/m, on {dev}", sci(k)),
            "dt",
        )
        .with_extras(&["energy drift"])
        .progress((steps.len() * solvers.len() * common::graph_modes(cli.graph).len()) as u64);
        for (name, solver) in solvers {
            for &dt in &steps {
                let row = sweep.record(
                    name,
                    dt,
                    run(&dev, chains, (solver, false), k, dt, t_end, &reference)?,
                );
                if dt == steps[0] {
                    drift_at_60hz.insert(
                        (ki, name),
                        row.run.extras.first().copied().unwrap_or(f64::NAN),
                    );
                }
            }
            largest.insert((ki, name), sweep.largest_stable(name));
            // `--graph`: the same runs as replays of captured graphs, a series of their own.
            if common::graph_modes(cli.graph).len() > 1 {
                let graph_name = format!("{name} graph");
                for &dt in &steps {
                    let r = run(&dev, chains, (solver, true), k, dt, t_end, &reference)?;
                    sweep.record(&graph_name, dt, r);
                }
            }
        }
        common::finish(&sweep, &format!("springs_k{}", sci(k)));
    }

    let frame = frame.points(Points::new(beads, 0.012).values("log10 k", bead_k));
    common::write_frame("springs", &frame);
    cli.scene.record_last("springs", &frame);

    println!("\nlargest stable dt on the grid 1/60 s / 2^j (j = 0..{halvings}), and energy drift at 1/60 s");
    let mut t = Table::new([
        "k (N/m)",
        "2/omega_max",
        "semi-implicit Euler",
        "XPBD",
        "XPBD colored",
        "Euler drift @60Hz",
        "XPBD drift @60Hz",
        "colored drift @60Hz",
    ]);
    let show = |v: Option<f64>| v.map_or("none".to_string(), sci);
    let drift = |v: f64| {
        if v.is_nan() {
            "unstable".to_string()
        } else {
            sci(v)
        }
    };
    for (ki, &k) in stiffnesses.iter().enumerate() {
        let e = "semi-implicit Euler";
        t.push([
            sci(k),
            sci(2.0 / springs::omega_max(k)),
            show(largest[&(ki, e)]),
            show(largest[&(ki, "XPBD")]),
            show(largest[&(ki, "XPBD colored")]),
            drift(drift_at_60hz[&(ki, e)]),
            drift(drift_at_60hz[&(ki, "XPBD")]),
            drift(drift_at_60hz[&(ki, "XPBD colored")]),
        ]);
    }
    print!("{t}");
    common::print_compiled();
    Ok(())
}

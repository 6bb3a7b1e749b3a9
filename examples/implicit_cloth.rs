//! A mass-spring cloth, stiffness 1e2 to 1e5 N/m: semi-implicit Euler against XPBD by colour
//! and backward Euler by Newton's method, whose linear systems are a `Bsr<Mat3>` assembled in a
//! kernel and solved by the sparse tier's CG with block Jacobi.
//!
//! ```text
//! cargo run --release --example implicit_cloth -- [--device cpu|cuda:0] [--n N] [--n-ref 6]
//!     [--k 1e2,1e3,1e4,1e5] [--t-end 0.5] [--halvings N] [--newton 3] [--substeps 10]
//!     [--rtol 1e-5] [--max-iter 2000] [--cg-graph] [--damping 0] [--plot-dir DIR]
//! ```
//! The cloth (examples/cloth.rs's, without drag): 1 m x 1 m, 0.2 kg, an n x n grid of
//! particles (`--n`: 64 on a GPU, 12 on the CPU) joined by structural and shear springs of
//! stiffness k and bending springs of k / 20, held at two corners, released flat and at rest,
//! falling for `--t-end` seconds. For each stiffness the step is swept from 1/30 s down by
//! halvings, and each series runs twice: on the n x n cloth (stability, energy, wall time, CG
//! iterations) and on a small `--n-ref` cloth whose f64 Runge-Kutta reference (on the host,
//! at 1/32 of its explicit bound) gives the error (the largest distance of a particle from
//! the reference at t_end). A run is unstable when a state is not finite or a spring is
//! stretched past 2 rest lengths (checked 10 times a run).
//!
//! Series: semi-implicit Euler (a thread per particle); XPBD with the springs coloured on the
//! device (`--substeps`, one sweep each); backward Euler, `--newton` Newton iterations a step,
//! the first Baraff and Witkin's `(M - h D - h² K) Δv = h (f + h K v)`, each a CG solve
//! (`--rtol`, `--max-iter`) on a matrix whose pattern was built once from the springs and whose
//! blocks a kernel rewrites each iteration. A summary gives the largest stable step of each
//! series and stiffness beside the explicit bound `2 / ω_max` (ω_max by power iteration on the
//! linearised cloth), backward Euler's CG iterations per Newton iteration and the wall time
//! per simulated second. Plots: `<plot-dir>/implicit_cloth_k<k>.svg`; the frame: the cloth at
//! t_end (backward Euler at 1/30 s, the stiffest k).
//!
//! The exit status is 1 unless backward Euler is stable at every step and stiffness, semi-
//! implicit Euler diverges at some step where backward Euler is stable, and backward Euler's
//! error falls at first order (at least 0.8) between the two finest steps at the softest k.

mod common;
#[path = "common/implicit_cloth.rs"]
mod implicit_cloth;

use std::collections::HashMap;
use std::time::Instant;

use clap::Parser;
use implicit_cloth::{Outcome, Params, Series};
use warp_lang as wp;
use warp_report::frame::{Frame, TriMesh};
use warp_report::{sci, Run, Sweep, Table};
// `implicit_cloth` reaches the sparse tier as `super::sparse`.
use wp::sparse;

/// A mass-spring cloth, k = 1e2..1e5 N/m: semi-implicit Euler, XPBD by colour and backward
/// Euler (Newton, CG on a block sparse matrix) against an f64 Runge-Kutta reference.
#[derive(Parser)]
struct Cli {
    /// Particles per side of the cloth [default: 64 on a GPU, 12 on the CPU]
    #[arg(long, value_name = "N", value_parser = common::num::<usize>)]
    n: Option<usize>,
    /// Particles per side of the small cloth the errors are measured on
    #[arg(long, default_value_t = 6, value_parser = common::num::<usize>)]
    n_ref: usize,
    /// Stiffnesses (N/m) of the structural and shear springs, comma separated
    #[arg(long, value_delimiter = ',', default_values_t = [1e2, 1e3, 1e4, 1e5])]
    k: Vec<f64>,
    /// Simulated time (s)
    #[arg(long, default_value_t = 0.5)]
    t_end: f64,
    /// Halvings of the step from 1/30 s [default: 5 on a GPU, 4 on the CPU]
    #[arg(long, value_name = "N", value_parser = common::num::<u32>)]
    halvings: Option<u32>,
    /// Newton iterations per backward Euler step
    #[arg(long, default_value_t = 3, value_parser = common::num::<usize>)]
    newton: usize,
    /// XPBD substeps per step (one constraint sweep each)
    #[arg(long, default_value_t = 10, value_parser = common::num::<i32>)]
    substeps: i32,
    /// CG's relative tolerance in each Newton iteration
    #[arg(long, default_value_t = 1e-5)]
    rtol: f64,
    /// CG's iteration limit (a solve stopped there is an inexact Newton step, counted)
    #[arg(long, default_value_t = 2000, value_parser = common::num::<usize>)]
    max_iter: usize,
    /// Run each CG solve as a graph it captures and launches (`Mode::Graph`) instead of
    /// reading its state back every 10 iterations (`Mode::Host`)
    #[arg(long)]
    cg_graph: bool,
    /// Damping along each spring (N s/m)
    #[arg(long, default_value_t = 0.0)]
    damping: f64,
    #[command(flatten)]
    scene: common::SceneArgs,
}

/// The smallest first-order rate accepted for backward Euler's error at the softest k.
const MIN_ORDER: f64 = 0.8;

/// State checks per run.
const CHECKS: usize = 10;

/// One row of the sweep: the run on the large cloth, with the error of the same series and
/// step on the small cloth.
fn to_run(big: &Outcome, error: f64, t_end: f64) -> Run {
    let run = if big.stable {
        Run::stable(big.steps as u64, error, big.seconds)
    } else {
        Run::unstable(big.steps as u64, big.seconds, big.why.clone())
    };
    run.extra(big.drift())
        .extra(big.max_drift())
        .extra(big.mean_cg())
        .extra(big.seconds / t_end)
        .extra(big.cg_unconverged as f64)
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let gpu = dev.is_cuda();
    let n = cli.n.unwrap_or(if gpu { 64 } else { 12 });
    let halvings = cli.halvings.unwrap_or(if gpu { 5 } else { 4 });
    let t_end = cli.t_end;
    let bad_k = cli.k.is_empty() || cli.k.iter().any(|k| !(k.is_finite() && *k > 0.0));
    let bad_t = t_end.is_nan() || t_end <= 0.0;
    let bad_rtol = cli.rtol.is_nan() || cli.rtol <= 0.0;
    let bad_damping = cli.damping.is_nan() || cli.damping < 0.0;
    let bad_counts = cli.newton < 1 || cli.substeps < 1 || cli.max_iter < 1;
    if n < 3 || cli.n_ref < 3 || bad_k || bad_t || bad_rtol || bad_damping || bad_counts {
        eprintln!(
            "implicit_cloth: --n and --n-ref must be at least 3, --k positive and finite, \
             --t-end and --rtol positive, --damping not negative, --newton, --substeps and \
             --max-iter at least 1"
        );
        std::process::exit(2);
    }
    let mut ks = cli.k.clone();
    ks.sort_by(f64::total_cmp);
    let series = [
        Series::Euler,
        Series::XpbdColored {
            substeps: cli.substeps,
            iterations: 1,
        },
        Series::BackwardEuler {
            newton: cli.newton,
            rtol: cli.rtol,
            max_iter: cli.max_iter,
            graph: cli.cg_graph,
        },
    ];
    let steps: Vec<f64> = (0..=halvings)
        .map(|j| 1.0 / 30.0 / 2f64.powi(j as i32))
        .collect();
    let kd = cli.damping;
    let probe = Params { n, k: ks[0], kd };
    let mut cloth = implicit_cloth::Cloth::new(probe, &dev)?;
    println!(
        "implicit cloth: {n} x {n} particles ({} springs, errors on a {m} x {m} cloth) on \
         \"{dev}\", until t = {t_end} s; XPBD: {} colours, {} substeps; backward Euler: {} \
         Newton iterations, CG + block Jacobi to rtol {} ({} blocks of 3 x 3)",
        probe.springs().len(),
        cloth.colours(&dev)?,
        cli.substeps,
        cli.newton,
        sci(cli.rtol),
        cloth.matrix_blocks(&dev)?,
        m = cli.n_ref,
    );
    drop(cloth);

    let mut largest: HashMap<(usize, &str), Option<f64>> = HashMap::new();
    let mut bound = Vec::new();
    let mut be_cg = Vec::new();
    let mut per_sim_s: HashMap<(usize, &str), f64> = HashMap::new();
    let mut pass = true;
    let mut explicit_beaten = false;
    let mut why = Vec::new();
    let mut last_frame = None;
    for (ki, &k) in ks.iter().enumerate() {
        let params = Params { n, k, kd };
        let small = Params {
            n: cli.n_ref,
            k,
            kd,
        };
        let omega = params.omega_max();
        bound.push(2.0 / omega);
        // The reference on the small cloth: RK4 in f64 at 1/32 of its explicit bound; its own
        // error estimated against a run at twice that step.
        let t = Instant::now();
        let dt_ref = (2.0 / small.omega_max() / 32.0).min(1e-3);
        let (reference, _) = small.reference(t_end, dt_ref);
        let (coarse, _) = small.reference(t_end, 2.0 * dt_ref);
        let ref_err = reference
            .iter()
            .zip(&coarse)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0f64, f64::max);
        println!(
            "\nk = {}: 2/omega_max = {} s; reference RK4 f64 at dt = {} ({:.2} s), \
             |ref(dt) - ref(2 dt)| = {}",
            sci(k),
            sci(2.0 / omega),
            sci(dt_ref),
            t.elapsed().as_secs_f64(),
            sci(ref_err)
        );
        let mut sweep = Sweep::new(
            format!("implicit cloth {n} x {n}, k = {} N/m, on {dev}", sci(k)),
            "dt",
        )
        .with_extras(&[
            "energy drift",
            "max |drift|",
            "CG its/Newton",
            "wall s/sim s",
            "CG at max-iter",
        ])
        .progress((steps.len() * series.len()) as u64);
        let mut be_errors = Vec::new();
        for s in series {
            let name = s.name();
            for &dt in &steps {
                let big = implicit_cloth::simulate(params, s, dt, t_end, CHECKS, false, &dev)?;
                let little = implicit_cloth::simulate(small, s, dt, t_end, CHECKS, false, &dev)?;
                let error = little.error(&reference);
                if let Series::BackwardEuler { .. } = s {
                    be_errors.push(error);
                    if !big.stable || !little.stable {
                        pass = false;
                        why.push(format!(
                            "backward Euler unstable at k = {}, dt = {}",
                            sci(k),
                            sci(dt)
                        ));
                    }
                    if dt == steps[0] {
                        be_cg.push(big.mean_cg());
                        if ki + 1 == ks.len() {
                            last_frame = Some(big.x.clone());
                        }
                    }
                }
                sweep.record(name, dt, to_run(&big, error, t_end));
            }
            let best = sweep.largest_stable(name);
            largest.insert((ki, name), best);
            // The wall time per simulated second at the series' largest stable step.
            if let Some(dt) = best {
                let row = sweep
                    .rows()
                    .iter()
                    .find(|r| r.series == name && r.param == dt)
                    .expect("recorded above");
                per_sim_s.insert((ki, name), row.run.seconds / t_end);
            }
        }
        // Explicit diverged at a step where backward Euler held: the scene's point.
        let euler = sweep
            .rows()
            .iter()
            .filter(|r| r.series == "semi-implicit Euler" && !r.run.stability.is_stable());
        if euler.count() > 0 {
            explicit_beaten = true;
        }
        if ki == 0 && be_errors.len() >= 2 {
            let l = be_errors.len();
            let order = implicit_cloth::order(be_errors[l - 2], be_errors[l - 1]);
            println!(
                "backward Euler's error order between dt = {} and {}: {order:.3}",
                sci(steps[l - 2]),
                sci(steps[l - 1])
            );
            if order.is_nan() || order < MIN_ORDER {
                pass = false;
                why.push(format!(
                    "backward Euler's order {order:.3} at k = {} is below {MIN_ORDER}",
                    sci(k)
                ));
            }
        }
        common::finish(&sweep, &format!("implicit_cloth_k{}", sci(k)));
    }
    if !explicit_beaten {
        pass = false;
        why.push("semi-implicit Euler was stable at every step: no step shows the claim".into());
    }

    println!(
        "\nlargest stable dt on the grid 1/30 s / 2^j (j = 0..{halvings}); backward Euler's CG \
         iterations per Newton iteration at 1/30 s; wall time per simulated second at each \
         series' largest stable step"
    );
    let mut t = Table::new([
        "k (N/m)",
        "2/omega_max",
        "semi-implicit Euler",
        "XPBD colored",
        "backward Euler",
        "BE CG its @1/30",
        "Euler s/sim s",
        "XPBD s/sim s",
        "BE s/sim s",
    ]);
    let show = |v: Option<f64>| v.map_or("none".to_string(), sci);
    let secs = |v: Option<&f64>| v.map_or("-".to_string(), |&s| format!("{s:.3}"));
    let names = ["semi-implicit Euler", "XPBD colored", "backward Euler"];
    for (ki, &k) in ks.iter().enumerate() {
        t.push([
            sci(k),
            sci(bound[ki]),
            show(largest[&(ki, names[0])]),
            show(largest[&(ki, names[1])]),
            show(largest[&(ki, names[2])]),
            format!("{:.1}", be_cg[ki]),
            secs(per_sim_s.get(&(ki, names[0]))),
            secs(per_sim_s.get(&(ki, names[1]))),
            secs(per_sim_s.get(&(ki, names[2]))),
        ]);
    }
    print!("{t}");

    if let Some(x) = last_frame {
        let points: Vec<[f64; 3]> = x.iter().map(|&p| common::p3(p)).collect();
        let start: Vec<[f64; 3]> = Params { n, k: ks[0], kd }
            .start()
            .iter()
            .map(|&p| common::p3(p))
            .collect();
        let grid = common::grid_triangles(n);
        let all: Vec<[f64; 3]> = [&start[..], &points[..]].concat();
        let (lo, hi) = common::bounds(&all);
        let frame = Frame::new(
            format!(
                "implicit cloth: {n} x {n} particles at t = {t_end} s, k = {} N/m, backward \
                 Euler at dt = 1/30 s",
                sci(ks[ks.len() - 1])
            ),
            common::camera(lo, hi, [1.4, 0.5, 1.0], [0.0, 1.0, 0.0]),
        )
        .note("held at two corners; wireframe: the start")
        .mesh(
            TriMesh::new(start, grid.clone())
                .wireframe()
                .colour([170, 170, 170]),
        )
        .mesh(TriMesh::new(points, grid).colour([220, 120, 90]));
        common::write_frame("implicit_cloth", &frame);
        cli.scene.record_last("implicit_cloth", &frame);
    }
    common::print_compiled();
    println!(
        "\nimplicit_cloth: {}",
        if pass {
            format!(
                "pass (backward Euler stable at every step and stiffness, semi-implicit Euler \
                 not; backward Euler's error order >= {MIN_ORDER} at the softest k)"
            )
        } else {
            format!("FAIL: {}", why.join("; "))
        }
    );
    if !pass {
        std::process::exit(1);
    }
    Ok(())
}

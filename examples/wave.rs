//! The 1-D wave equation u_tt = c^2 u_xx on [0, 1] with fixed ends, by the leapfrog finite
//! difference scheme, against the analytic standing wave u = sin(pi x) cos(pi c t).
//!
//! ```text
//! cargo run --release --example wave -- [--n 1024] [--device cpu|cuda:0] [--plot-dir DIR]
//! ```
//! Sweeps the Courant number r = c dt / dx at a fixed grid: below 1 the error is the scheme's
//! dispersion, about (1 - r^2) dx^2 (plus f32 rounding over more steps), so it shrinks toward
//! r = 1, where the 1-D scheme is exact up to rounding; past 1 (the CFL limit) it blows up,
//! which the divergence guard (`Array::check_finite`) reports with the step and the index.
//! Prints error against run time for each r on two grids, writes the plot
//! (target/report/wave.svg), and prints what it compiled.

mod common;

use clap::Parser;
use std::f64::consts::PI;
use std::time::Instant;
use warp_lang as wp;
use warp_report::frame::{Camera, Frame, Lines, Points};
use warp_report::{Run, Sweep};
use wp::prelude::*;

/// One leapfrog step: u_next = 2 u - u_prev + r^2 (u[i+1] - 2 u[i] + u[i-1]), ends held at 0.
#[wp::kernel]
fn leapfrog(u_prev: Array<f32>, u: Array<f32>, u_next: Array<f32>, r2: f32) {
    let i = tid();
    let n = u.len();
    if i == 0 || i == n - 1 {
        u_next[i] = 0.0;
    } else {
        u_next[i] = 2.0 * u[i] - u_prev[i] + r2 * (u[i + 1] - 2.0 * u[i] + u[i - 1]);
    }
}

/// The first step from rest: u1 = u0 + r^2 / 2 (u0[i+1] - 2 u0[i] + u0[i-1]).
#[wp::kernel]
fn first_step(u0: Array<f32>, u1: Array<f32>, r2: f32) {
    let i = tid();
    let n = u0.len();
    if i == 0 || i == n - 1 {
        u1[i] = 0.0;
    } else {
        u1[i] = u0[i] + 0.5 * r2 * (u0[i + 1] - 2.0 * u0[i] + u0[i - 1]);
    }
}

/// The 1-D wave equation by leapfrog against the analytic standing wave.
#[derive(Parser)]
struct Cli {
    /// Grid points of the finest grid
    #[arg(long, default_value_t = 1024, value_parser = common::num::<usize>)]
    n: usize,
    /// Also run each series as replays of a captured graph
    #[arg(long)]
    graph: bool,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let n = cli.n;
    let (c, t_end) = (1.0f64, 1.0f64);
    println!(
        "wave equation on \"{dev}\", c = {c}, until t = {t_end}, grids of {} and {n} points",
        n / 4
    );
    let ratios = [0.25f64, 0.5, 0.9, 1.0, 1.01, 1.1];
    let grids = [n / 4, n];
    let mut sweep = Sweep::new(
        format!("1-D wave equation, leapfrog f32, on {dev}"),
        "r = c dt/dx",
    )
    .progress((ratios.len() * grids.len() * common::graph_modes(cli.graph).len()) as u64);
    // The frame: the coarse grid's string at t_end at r = 0.9 (stable) and r = 1.01 (past
    // the CFL limit), against the exact standing wave.
    let mut shown: Vec<(f64, Vec<f32>)> = Vec::new();
    for n in grids {
        for &graph in common::graph_modes(cli.graph) {
            for r in ratios {
                let (run, u) = run(&dev, n, c, r, t_end, graph)?;
                if n == grids[0] && !graph && (r == 0.9 || r == 1.01) {
                    shown.push((r, u));
                }
                let series = if graph {
                    format!("{n} points graph")
                } else {
                    format!("{n} points")
                };
                sweep.record(&series, r, run);
            }
        }
    }
    common::finish(&sweep, "wave");
    let m = grids[0];
    let dx = 1.0 / (m - 1) as f64;
    let exact: Vec<[f64; 3]> = (0..=200)
        .map(|i| {
            let x = i as f64 / 200.0;
            [x, (PI * x).sin() * (PI * c * t_end).cos(), 0.0]
        })
        .collect();
    let mut frame = Frame::new(
        format!("wave: the string at t = {t_end} on {m} points (f32 leapfrog)"),
        Camera::orthographic([0.5, 0.0, 1.0], [0.5, 0.0, 0.0], [0.0, 1.0, 0.0]),
    )
    .size(800, 420)
    .note("line: the exact standing wave sin(pi x) cos(pi c t); dots: the scheme, colour: r = c dt/dx")
    .lines(Lines::polyline(&exact).colour([120, 120, 120]).width(2.0));
    let (mut dots, mut dot_r) = (Vec::new(), Vec::new());
    for (r, u) in &shown {
        // Past the CFL limit the string can have grown without bound: clamp to the picture.
        for (i, &v) in u.iter().enumerate().step_by(2) {
            dots.push([i as f64 * dx, (v as f64).clamp(-1.5, 1.5), 0.0]);
            dot_r.push(*r);
        }
    }
    frame = frame.points(Points::new(dots, 0.006).values("r", dot_r));
    common::write_frame("wave", &frame);
    cli.scene.record_last("wave", &frame);
    common::print_compiled();
    Ok(())
}

/// Runs the scheme at Courant number `r` on `n` points until `t_end`; the error is the max
/// difference from the analytic standing wave at the time reached. Also returns the string
/// at the end (nothing for a run the divergence guard stopped).
/// With `graph`, each 192 steps (a multiple of the three arrays' rotation) are a replay of a
/// captured graph.
fn run(
    dev: &wp::Device,
    n: usize,
    c: f64,
    r: f64,
    t_end: f64,
    graph: bool,
) -> wp::Result<(Run, Vec<f32>)> {
    let dx = 1.0 / (n - 1) as f64;
    let x: Vec<f64> = (0..n).map(|i| i as f64 * dx).collect();
    let u0: Vec<f32> = x.iter().map(|&x| (PI * x).sin() as f32).collect();
    let dt = r * dx / c;
    let steps = (t_end / dt).round() as usize;
    let r2 = (r * r) as f32;
    let mut a = wp::Array::from_slice(&u0, dev)?;
    let mut b = wp::Array::<f32>::zeros(n, dev)?;
    let mut next = wp::Array::<f32>::zeros(n, dev)?;
    // Warm-up (compiles on a GPU), outside the timing.
    wp::launch(first_step, n, (&a, &b, r2), dev)?;
    wp::launch(leapfrog, n, (&a, &b, &next, r2), dev)?;
    wp::synchronize()?;
    let t = Instant::now();
    wp::launch(first_step, n, (&a, &b, r2), dev)?;
    let mut stepper = common::Stepper::new(graph, 192);
    let mut s = 1;
    while s < steps {
        let k = stepper.len().min(steps - s);
        stepper.advance(dev, k, &mut || {
            wp::launch(leapfrog, n, (&a, &b, &next, r2), dev)?;
            (a, b, next) = (b.clone(), next.clone(), a.clone());
            Ok(())
        })?;
        s += k;
        // The divergence guard: a NaN or infinity stops the run and says where.
        if let Err(e) = b.check_finite("u") {
            let run = Run::unstable(
                s as u64,
                t.elapsed().as_secs_f64(),
                format!("by step {s}: {e}"),
            );
            return Ok((run, Vec::new()));
        }
    }
    wp::synchronize()?;
    let seconds = t.elapsed().as_secs_f64();
    let u = b.to_vec()?;
    let t_reached = steps as f64 * dt;
    let err = x
        .iter()
        .zip(&u)
        .map(|(&x, &v)| (v as f64 - (PI * x).sin() * (PI * c * t_reached).cos()).abs())
        .fold(0.0f64, f64::max);
    // Growth the guard has not caught yet (finite but far above the wave's amplitude 1).
    let run = if err.is_finite() && err < 1.0 {
        Run::stable(steps as u64, err, seconds)
    } else {
        Run::unstable(steps as u64, seconds, format!("error {err:.1e} at the end"))
    };
    Ok((run, u))
}

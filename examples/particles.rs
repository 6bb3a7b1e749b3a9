//! The seed program: particles under gravity with linear drag, integrated by semi-implicit
//! Euler, as in the Warp introduction this project grew from.
//!
//! ```text
//! cargo run --release --example particles -- [--n 10000000] [--steps 100] [--device cpu|cuda:0]
//! ```
//!
//! It prints the first final positions, the run time, and two errors:
//! - against the closed-form solution of the ODE  v' = -(b/m) v + g  (this is the time
//!   discretisation error of the scheme, O(dt));
//! - against the exact solution of the discrete recurrence evaluated in f64 (this is the
//!   rounding error of running the scheme in f32, which is what the kernel is responsible for).
//!
//! Then it sweeps dt over the same time span on `--sweep-n` particles (100,000; 0 skips it),
//! in f32 and in f64, printing error against the closed form next to run time and writing
//! the plot `<--plot-dir or target/report>/particles.svg`: the error falls as O(dt) until
//! f32 rounding takes over. With `--graph` the sweep also runs each series as replays of a
//! captured 25-step graph (series "f32 graph", "f64 graph": the same errors, the launch costs
//! of a graph).

mod common;

use clap::Parser;
use rand::Rng as _;
use std::time::Instant;
use warp_lang as wp;
use warp_report::frame::{Frame, Lines, Points};
use warp_report::{Run, Sweep};
use wp::prelude::*;

#[wp::kernel]
fn integrate(x: Array<Vec3>, v: Array<Vec3>, b: f32, mass: f32, gravity: Vec3, dt: f32) {
    let i = tid();
    let a = -b * v[i] / mass + gravity;
    v[i] += a * dt;
    x[i] += v[i] * dt;
}

fn uniform_vec3(rng: &mut common::Rng, lo: f32, hi: f32) -> Vec3 {
    let mut c = || lo + (hi - lo) * rng.random::<f64>() as f32;
    Vec3::new(c(), c(), c())
}

/// The closed form of x' = v, v' = -k v + g at time t, per component.
fn exact(x0: f64, v0: f64, g: f64, k: f64, t: f64) -> f64 {
    let vinf = g / k; // terminal velocity
    x0 + vinf * t + (v0 - vinf) * (1.0 - (-k * t).exp()) / k
}

/// The same scheme in f64, for the sweep's precision series.
#[wp::kernel]
fn integrate_f64(x: Array<DVec3>, v: Array<DVec3>, b: f64, mass: f64, gravity: DVec3, dt: f64) {
    let i = tid();
    let a = -b * v[i] / mass + gravity;
    v[i] += a * dt;
    x[i] += v[i] * dt;
}

/// The dt sweep: `n` particles from the same start until the same end time `t_end`, in f32
/// and in f64; the error is the max distance from the closed form.
fn sweep(
    dev: &wp::Device,
    n: usize,
    x0: &[Vec3],
    v0: &[Vec3],
    t_end: f64,
    graph: bool,
) -> wp::Result<()> {
    let (mass, b, g) = (0.1f64, 0.05f64, 9.81f64);
    let (x0, v0) = (&x0[..n], &v0[..n]);
    let counts = [25u64, 50, 100, 200, 400, 800, 1600];
    let mut sweep = Sweep::new(
        format!("particles: linear drag with gravity, semi-implicit Euler, {n} particles on {dev}"),
        "dt",
    )
    .progress((2 * common::graph_modes(graph).len() * counts.len()) as u64);
    for (double, graph) in [false, true]
        .into_iter()
        .flat_map(|d| common::graph_modes(graph).iter().map(move |&g| (d, g)))
    {
        // Warm-up on one particle (compiles on a GPU), outside the timing.
        if double {
            let w = wp::Array::<DVec3>::zeros(1, dev)?;
            wp::launch(integrate_f64, 1, (&w, &w, b, mass, DVec3::ZERO, 0.0), dev)?;
        } else {
            let w = wp::Array::<Vec3>::zeros(1, dev)?;
            let (b, mass) = (b as f32, mass as f32);
            wp::launch(integrate, 1, (&w, &w, b, mass, Vec3::ZERO, 0.0), dev)?;
        }
        for &steps in &counts {
            let dt = t_end / steps as f64;
            wp::synchronize()?;
            // Timed: the steps, from uploaded start state to finished last step (with
            // `--graph`, including the capture of a 25-step graph).
            let mut stepper = common::Stepper::new(graph, 25);
            let mut run = |step: &mut dyn FnMut() -> wp::Result<()>| -> wp::Result<f64> {
                wp::synchronize()?;
                let t = Instant::now();
                let mut s = 0;
                while s < steps as usize {
                    let k = stepper.len().min(steps as usize - s);
                    stepper.advance(dev, k, step)?;
                    s += k;
                }
                wp::synchronize()?;
                Ok(t.elapsed().as_secs_f64())
            };
            let (xs, seconds): (Vec<DVec3>, f64) = if double {
                let x = wp::Array::from_vec(x0.iter().map(|p| p.as_dvec3()).collect(), dev)?;
                let v = wp::Array::from_vec(v0.iter().map(|p| p.as_dvec3()).collect(), dev)?;
                let gravity = DVec3::new(0.0, 0.0, -g);
                let seconds =
                    run(&mut || wp::launch(integrate_f64, n, (&x, &v, b, mass, gravity, dt), dev))?;
                (x.to_vec()?, seconds)
            } else {
                let x = wp::Array::from_slice(x0, dev)?;
                let v = wp::Array::from_slice(v0, dev)?;
                let gravity = Vec3::new(0.0, 0.0, -g as f32);
                let (b, mass, dt) = (b as f32, mass as f32, dt as f32);
                let seconds =
                    run(&mut || wp::launch(integrate, n, (&x, &v, b, mass, gravity, dt), dev))?;
                let xs = x.to_vec()?.iter().map(|p| p.as_dvec3()).collect();
                (xs, seconds)
            };
            let mut error = 0.0f64;
            for i in 0..n {
                for c in 0..3 {
                    let gc = if c == 2 { -g } else { 0.0 };
                    let want = exact(x0[i][c] as f64, v0[i][c] as f64, gc, b / mass, t_end);
                    error = error.max((xs[i][c] - want).abs());
                }
            }
            let series = match (double, graph) {
                (false, false) => "f32",
                (false, true) => "f32 graph",
                (true, false) => "f64",
                (true, true) => "f64 graph",
            };
            sweep.record(series, dt, Run::stable(steps, error, seconds));
        }
    }
    common::finish(&sweep, "particles");
    Ok(())
}

/// The particles (one in `stride`) after `steps` steps, at time `t`, coloured by speed, in
/// their bounding box.
fn frame(xs: &[Vec3], vs: &[Vec3], stride: usize, steps: usize, t: f64) -> Frame {
    let pos: Vec<[f64; 3]> = xs.iter().step_by(stride).map(|&p| common::p3(p)).collect();
    let (lo, hi) = common::bounds(&pos);
    Frame::new(
        format!(
            "particles: {} particles after {steps} steps (t = {t:.2} s)",
            xs.len()
        ),
        common::camera(lo, hi, [1.0, -1.6, 0.8], [0.0, 0.0, 1.0]),
    )
    .note("gravity along -z, linear drag; colour: speed")
    .lines(Lines::bounding_box(lo, hi))
    .points(Points::new(pos, 0.004 * common::diagonal(lo, hi)).values(
        "speed (m/s)",
        vs.iter().step_by(stride).map(|v| v.length() as f64),
    ))
}

/// The seed program: particles under gravity with linear drag (semi-implicit Euler), its
/// errors against the closed form and the exact discrete solution, and a dt sweep.
#[derive(Parser)]
struct Cli {
    /// Particles in the timed run
    #[arg(
        long,
        value_name = "COUNT",
        default_value = "10_000_000",
        value_parser = common::num::<usize>
    )]
    n: usize,
    /// Steps in the timed run
    #[arg(long, default_value_t = 100, value_parser = common::num::<usize>)]
    steps: usize,
    /// Particles in the dt sweep (0: no sweep)
    #[arg(
        long,
        value_name = "COUNT",
        default_value = "100_000",
        value_parser = common::num::<usize>
    )]
    sweep_n: usize,
    /// Also run each series of the sweep as replays of a captured graph
    #[arg(long)]
    graph: bool,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let (n, steps, sweep_n) = (cli.n, cli.steps, cli.sweep_n);
    let dev = cli.scene.init()?;

    // The seed's constants.
    let mass = 0.1f32; // kg
    let g = 9.81f32; // m/s^2
    let b = 0.05f32; // kg/s
    let dt = 0.01 * (2.0 * mass / b); // s
    let gravity = Vec3::new(0.0, 0.0, -g);

    let mut rng = common::rng(12345);
    let x0: Vec<Vec3> = (0..n).map(|_| uniform_vec3(&mut rng, -1.0, 1.0)).collect();
    let v0: Vec<Vec3> = (0..n).map(|_| uniform_vec3(&mut rng, -0.5, 0.5)).collect();
    let x = wp::Array::from_slice(&x0, &dev)?;
    let v = wp::Array::from_slice(&v0, &dev)?;

    // One warm-up launch on copies, so that the timing below excludes first-launch costs.
    let (xw, vw) = (
        wp::Array::from_slice(&x0[..1], &dev)?,
        wp::Array::from_slice(&v0[..1], &dev)?,
    );
    wp::launch(integrate, 1, (&xw, &vw, b, mass, gravity, dt), &dev)?;
    wp::synchronize()?;

    // With `--rerun`, a frame every `every` steps; the clock stops while one is recorded.
    let mut rec = cli.scene.recorder("particles");
    let every = common::record::every(steps);
    let stride = common::record::stride(n);
    let record = |rec: &mut common::record::Recorder, step: usize| -> wp::Result<()> {
        let t = dt as f64 * step as f64;
        rec.frame(step, t, &frame(&x.to_vec()?, &v.to_vec()?, stride, step, t));
        Ok(())
    };
    if rec.is_on() {
        record(&mut rec, 0)?;
    }
    let mut elapsed = std::time::Duration::ZERO;
    let mut t0 = Instant::now();
    for step in 1..=steps {
        wp::launch(integrate, n, (&x, &v, b, mass, gravity, dt), &dev)?;
        if rec.is_on() && (step % every == 0 || step == steps) {
            wp::synchronize()?;
            elapsed += t0.elapsed();
            record(&mut rec, step)?;
            t0 = Instant::now();
        }
    }
    wp::synchronize()?;
    elapsed += t0.elapsed();
    rec.finish();
    let xs = x.to_vec()?;

    // Errors, in f64.
    let k = (b / mass) as f64;
    let dt64 = dt as f64;
    let t = dt64 * steps as f64;
    let r = 1.0 - k * dt64; // the scheme's per-step velocity factor
    let mut err_ode = 0.0f64;
    let mut err_discrete = 0.0f64;
    for i in 0..n {
        for c in 0..3 {
            let gc = gravity[c] as f64;
            let (xi, vi) = (x0[i][c] as f64, v0[i][c] as f64);
            let vinf = gc / k; // terminal velocity
            let exact = exact(xi, vi, gc, k, t);
            // Closed form of v_{n+1} = r v_n + g dt, x_{n+1} = x_n + v_{n+1} dt.
            let geometric = r * (1.0 - r.powi(steps as i32)) / (1.0 - r);
            let discrete = xi + dt64 * (steps as f64 * vinf + (vi - vinf) * geometric);
            let got = xs[i][c] as f64;
            err_ode = err_ode.max((got - exact).abs());
            err_discrete = err_discrete.max((got - discrete).abs());
        }
    }

    println!("particles: {n} particles x {steps} steps on \"{dev}\" (dt = {dt} s)");
    for (i, p) in xs.iter().take(3).enumerate() {
        println!("  x[{i}] = [{:.6}, {:.6}, {:.6}]", p.x, p.y, p.z);
    }
    let ms = elapsed.as_secs_f64() * 1e3;
    println!(
        "  time: {ms:.2} ms ({:.3} ms/step, {:.1} GB/s effective)",
        ms / steps as f64,
        // Each step reads and writes x and v: 4 x 12 bytes per particle.
        (48.0 * n as f64 * steps as f64) / elapsed.as_secs_f64() / 1e9
    );
    println!(
        "  max |x - closed form of the ODE|       = {err_ode:.3e} m (time discretisation, O(dt))"
    );
    println!("  max |x - exact discrete solution, f64| = {err_discrete:.3e} m (f32 rounding)");
    common::write_frame("particles", &frame(&xs, &v.to_vec()?, 1, steps, t));
    if sweep_n > 0 {
        sweep(&dev, sweep_n.min(n), &x0, &v0, t, cli.graph)?;
    }
    common::print_compiled();
    Ok(())
}

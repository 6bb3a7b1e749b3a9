//! Gravitational n-body with softening, integrated by leapfrog (kick-drift-kick): energy and
//! momentum drift over long runs, f32 against f64, compensated (Kahan) against plain
//! accumulation.
//!
//! ```text
//! cargo run --release --example nbody -- [--device cpu|cuda:0] [--n 256] [--t-end 2]
//!     [--halvings 5] [--plot-dir DIR]
//! ```
//! The bodies start in a uniform ball with isotropic random velocities near virial
//! equilibrium (G = 1, total mass 1, radius 1, softening 0.05), centre of mass at rest.
//! The reference is what the exact dynamics conserve:
//! - energy: the relative energy error |E(T) - E(0)| / |E(0)| is the sweep's error. It has two
//!   parts, the scheme's truncation (O(dt^2), shrinking with dt) and rounding, which grows with
//!   the number of steps; f32 plain accumulation reaches its rounding floor first.
//! - momentum: leapfrog with pairwise forces conserves the total momentum exactly in exact
//!   arithmetic (the pair forces cancel), so its drift, relative to the sum of |m v|, is
//!   rounding alone: it separates f32 from f64 and plain from compensated sums cleanly.
//!
//! "Compensated" applies Kahan summation both to each body's force sum and to the position
//! and velocity updates (with a compensation array each).

mod common;

use clap::Parser;
use rand::Rng as _;
use rand_distr::StandardNormal;
use std::time::Instant;

use glam::DVec3;
use warp_lang as wp;
use warp_report::frame::{Frame, Points};
use warp_report::{Run, Sweep};
use wp::prelude::*;

/// Acceleration of body i: the sum over j of m_j d / (|d|^2 + eps^2)^(3/2), d = x_j - x_i (the
/// j = i term is zero), summed plainly or with Kahan compensation. Generic: the launch runs
/// the f32 or the f64 instance, after the arrays' type.
#[wp::kernel]
pub fn accelerations<T: Float>(
    x: Array<Vec3<T>>,
    m: Array<T>,
    a: Array<Vec3<T>>,
    eps2: T,
    compensated: bool,
) {
    let i = tid();
    let xi = x[i];
    let mut sum = Vec3::<T>::ZERO;
    let mut carry = Vec3::<T>::ZERO;
    for j in 0..x.len() {
        let d = x[j] - xi;
        let r2 = dot(d, d) + eps2;
        let term = d * (m[j] / (r2 * sqrt(r2)));
        if compensated {
            let y = term - carry;
            let t = sum + y;
            carry = (t - sum) - y;
            sum = t;
        } else {
            sum += term;
        }
    }
    a[i] = sum;
}

/// `s += inc`, plainly or with the Kahan carry `c` (updated in place).
#[wp::func]
fn add<T: Float>(s: Array<Vec3<T>>, c: Array<Vec3<T>>, i: usize, inc: Vec3<T>, compensated: bool) {
    if compensated {
        let y = inc - c[i];
        let t = s[i] + y;
        c[i] = (t - s[i]) - y;
        s[i] = t;
    } else {
        s[i] += inc;
    }
}

/// Half kick then drift: v += a dt / 2; x += v dt.
#[wp::kernel]
pub fn kick_drift<T: Float>(
    x: Array<Vec3<T>>,
    v: Array<Vec3<T>>,
    a: Array<Vec3<T>>,
    xc: Array<Vec3<T>>,
    vc: Array<Vec3<T>>,
    dt: T,
    compensated: bool,
) {
    let i = tid();
    add::<T>(v, vc, i, a[i] * (0.5 * dt), compensated);
    add::<T>(x, xc, i, v[i] * dt, compensated);
}

/// The closing half kick: v += a dt / 2.
#[wp::kernel]
pub fn kick<T: Float>(
    v: Array<Vec3<T>>,
    a: Array<Vec3<T>>,
    vc: Array<Vec3<T>>,
    dt: T,
    compensated: bool,
) {
    let i = tid();
    add::<T>(v, vc, i, a[i] * (0.5 * dt), compensated);
}

const SOFTENING: f64 = 0.05;

/// The start state: positions, velocities, masses (f64).
fn start(n: usize) -> (Vec<DVec3>, Vec<DVec3>, Vec<f64>) {
    let mut rng = common::rng(2026);
    let mut x = Vec::with_capacity(n);
    while x.len() < n {
        let p = DVec3::new(
            rng.random::<f64>(),
            rng.random::<f64>(),
            rng.random::<f64>(),
        ) * 2.0
            - 1.0;
        if p.length_squared() <= 1.0 {
            x.push(p);
        }
    }
    // Uniform ball of mass 1, radius 1: potential energy -3/5, so a virial kinetic energy of
    // 3/10, i.e. an rms speed of sqrt(0.6).
    let mut v: Vec<DVec3> = (0..n)
        .map(|_| {
            DVec3::new(
                rng.sample::<f64, _>(StandardNormal),
                rng.sample::<f64, _>(StandardNormal),
                rng.sample::<f64, _>(StandardNormal),
            ) * (0.6f64 / 3.0).sqrt()
        })
        .collect();
    let (cx, cv) = (
        x.iter().sum::<DVec3>() / n as f64,
        v.iter().sum::<DVec3>() / n as f64,
    );
    x.iter_mut().for_each(|p| *p -= cx);
    v.iter_mut().for_each(|p| *p -= cv);
    (x, v, vec![1.0 / n as f64; n])
}

/// Total energy with the same softened potential the kernels integrate, in f64.
fn energy(x: &[DVec3], v: &[DVec3], m: &[f64]) -> f64 {
    let kinetic: f64 = v
        .iter()
        .zip(m)
        .map(|(v, m)| 0.5 * m * v.length_squared())
        .sum();
    let mut potential = 0.0;
    for i in 0..x.len() {
        for j in i + 1..x.len() {
            let r2 = x[i].distance_squared(x[j]) + SOFTENING * SOFTENING;
            potential -= m[i] * m[j] / r2.sqrt();
        }
    }
    kinetic + potential
}

fn momentum(v: &[DVec3], m: &[f64]) -> (DVec3, f64) {
    let p = v.iter().zip(m).map(|(v, m)| *v * *m).sum();
    let scale = v.iter().zip(m).map(|(v, m)| v.length() * m).sum();
    (p, scale)
}

/// One leapfrog run in f32 or f64; returns the final positions and velocities in f64.
macro_rules! run_in {
    ($s:ty, $vt:ty, $to:ident, $from:ident, $dev:expr, $x:expr, $v:expr, $m:expr, $dt:expr, $steps:expr, $comp:expr, $graph:expr) => {{
        let dev = $dev;
        let n = $x.len();
        let x = wp::Array::from_vec($x.iter().map(|p| p.$to()).collect(), dev)?;
        let v = wp::Array::from_vec($v.iter().map(|p| p.$to()).collect(), dev)?;
        let m = wp::Array::from_vec($m.iter().map(|&m| m as $s).collect(), dev)?;
        let a = wp::Array::zeros(n, dev)?;
        let (xc, vc) = (wp::Array::zeros(n, dev)?, wp::Array::zeros(n, dev)?);
        let (eps2, dt) = ((SOFTENING * SOFTENING) as $s, $dt as $s);
        // The first launches compile on a GPU: outside the timing (on scratch arrays, so
        // that the start state is untouched).
        let (ws, wv) = (wp::Array::zeros(1, dev)?, wp::Array::zeros(1, dev)?);
        wp::launch(accelerations, 1, (&ws, &m, &wv, eps2, $comp), dev)?;
        wp::launch(kick_drift, 1, (&ws, &wv, &wv, &ws, &wv, dt, $comp), dev)?;
        wp::launch(kick, 1, (&wv, &wv, &ws, dt, $comp), dev)?;
        wp::launch(accelerations, n, (&x, &m, &a, eps2, $comp), dev)?;
        wp::synchronize()?;
        let t = Instant::now();
        let mut blew_up = None;
        // With `--graph`, each 512 steps are a replay of a captured graph.
        let mut stepper = common::Stepper::new($graph, 512);
        let mut s = 0u64;
        while s < $steps {
            let k = (stepper.len() as u64).min($steps - s);
            stepper.advance(dev, k as usize, &mut || {
                wp::launch(kick_drift, n, (&x, &v, &a, &xc, &vc, dt, $comp), dev)?;
                wp::launch(accelerations, n, (&x, &m, &a, eps2, $comp), dev)?;
                wp::launch(kick, n, (&v, &a, &vc, dt, $comp), dev)
            })?;
            s += k;
            if let Err(e) = v.check_finite("v") {
                blew_up = Some(format!("by step {s}: {e}"));
                break;
            }
        }
        wp::synchronize()?;
        let seconds = t.elapsed().as_secs_f64();
        let back = |a: &wp::Array<$vt>| -> wp::Result<Vec<DVec3>> {
            Ok(a.to_vec()?.iter().map(|p| p.$from()).collect())
        };
        (back(&x)?, back(&v)?, seconds, blew_up)
    }};
}

/// The bodies within 3 of the centre of mass (at rest at the origin; a few escaped ones would
/// shrink the cluster to a dot), coloured by speed.
fn bodies_frame(x: &[DVec3], v: &[DVec3], title: String) -> Frame {
    let r = 3.0;
    let near: Vec<usize> = (0..x.len()).filter(|&i| x[i].length() < r).collect();
    Frame::new(
        title,
        common::camera([-r; 3], [r; 3], [1.0, 0.6, 1.4], [0.0, 1.0, 0.0]),
    )
    .note(format!(
        "softening {SOFTENING}, started in a unit ball near virial equilibrium; {} within \
         {r} of the centre of mass drawn; colour: speed",
        near.len()
    ))
    .points(
        Points::new(near.iter().map(|&i| common::p3(x[i])), 0.02)
            .values("speed", near.iter().map(|&i| v[i].length())),
    )
}

/// `--rerun`: a leapfrog run in f64 with Kahan sums from the start state, `steps` steps of
/// `dt`, a frame every `record::every(steps)` steps.
fn record(
    dev: &wp::Device,
    x0: &[DVec3],
    v0: &[DVec3],
    m: &[f64],
    dt: f64,
    steps: usize,
    rec: &mut common::record::Recorder,
) -> wp::Result<()> {
    let n = x0.len();
    let x = wp::Array::from_slice(x0, dev)?;
    let v = wp::Array::from_slice(v0, dev)?;
    let m = wp::Array::from_slice(m, dev)?;
    let a = wp::Array::<DVec3>::zeros(n, dev)?;
    let (xc, vc) = (
        wp::Array::<DVec3>::zeros(n, dev)?,
        wp::Array::<DVec3>::zeros(n, dev)?,
    );
    let eps2 = SOFTENING * SOFTENING;
    let every = common::record::every(steps);
    let mut snap = |step: usize| -> wp::Result<()> {
        let t = step as f64 * dt;
        let title = format!("n-body: {n} bodies at t = {t:.3} (f64 Kahan, dt = {dt})");
        rec.frame(step, t, &bodies_frame(&x.to_vec()?, &v.to_vec()?, title));
        Ok(())
    };
    wp::launch(accelerations, n, (&x, &m, &a, eps2, true), dev)?;
    snap(0)?;
    for step in 1..=steps {
        wp::launch(kick_drift, n, (&x, &v, &a, &xc, &vc, dt, true), dev)?;
        wp::launch(accelerations, n, (&x, &m, &a, eps2, true), dev)?;
        wp::launch(kick, n, (&v, &a, &vc, dt, true), dev)?;
        if step % every == 0 || step == steps {
            snap(step)?;
        }
    }
    Ok(())
}

/// Gravitational n-body by leapfrog: energy and momentum drift, f32 against f64, Kahan
/// against plain accumulation.
#[derive(Parser)]
struct Cli {
    /// Bodies [default: 4096 on a GPU, 256 on the CPU]
    #[arg(long, value_parser = common::num::<usize>)]
    n: Option<usize>,
    /// Simulated time
    #[arg(long, default_value_t = 2.0)]
    t_end: f64,
    /// Halvings of the time step in the sweep
    #[arg(long, default_value_t = 5, value_parser = common::num::<u32>)]
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
    let n = cli.n.unwrap_or(if gpu { 4096 } else { 256 });
    let (t_end, halvings) = (cli.t_end, cli.halvings);
    let (x0, v0, m) = start(n);
    let e0 = energy(&x0, &v0, &m);
    println!(
        "n-body: {n} bodies on \"{dev}\", softening {SOFTENING}, leapfrog until t = {t_end}, \
         E(0) = {e0:.6}"
    );
    let variants = [
        ("f32 plain", false, false),
        ("f32 Kahan", false, true),
        ("f64 plain", true, false),
        ("f64 Kahan", true, true),
    ];
    let dts: Vec<f64> = (0..=halvings).map(|j| 0.01 / 2f64.powi(j as i32)).collect();
    let mut sweep = Sweep::new(
        format!("n-body ({n} bodies), relative energy error, on {dev}"),
        "dt",
    )
    .with_extras(&["momentum drift"])
    .progress((variants.len() * dts.len() * common::graph_modes(cli.graph).len()) as u64);
    let variants: Vec<(String, bool, bool, bool)> = variants
        .into_iter()
        .flat_map(|(name, double, comp)| {
            common::graph_modes(cli.graph).iter().map(move |&graph| {
                let name = if graph {
                    format!("{name} graph")
                } else {
                    name.to_string()
                };
                (name, double, comp, graph)
            })
        })
        .collect();
    // The frame: the last run's bodies at t_end (f64 Kahan at the smallest dt).
    let mut last = None;
    for (name, double, compensated, graph) in variants.iter().cloned() {
        for &dt in &dts {
            let steps = (t_end / dt).round() as u64;
            let (x, v, seconds, blew_up) = if double {
                run_in!(
                    f64,
                    DVec3,
                    clone,
                    clone,
                    &dev,
                    x0,
                    v0,
                    m,
                    dt,
                    steps,
                    compensated,
                    graph
                )
            } else {
                run_in!(
                    f32,
                    glam::Vec3,
                    as_vec3,
                    as_dvec3,
                    &dev,
                    x0,
                    v0,
                    m,
                    dt,
                    steps,
                    compensated,
                    graph
                )
            };
            let run = match blew_up {
                Some(why) => Run::unstable(steps, seconds, why),
                None => {
                    let error = ((energy(&x, &v, &m) - e0) / e0).abs();
                    let (p, scale) = momentum(&v, &m);
                    Run::stable(steps, error, seconds).extra(p.length() / scale)
                }
            };
            sweep.record(&name, dt, run);
            last = Some((name.clone(), dt, x, v));
        }
    }
    common::finish(&sweep, "nbody");
    if let Some((name, dt, x, v)) = last {
        let title = format!("n-body: {n} bodies at t = {t_end} ({name}, dt = {dt})");
        common::write_frame("nbody", &bodies_frame(&x, &v, title));
    }
    let mut rec = cli.scene.recorder("nbody");
    if rec.is_on() {
        // The recording: one more run of the frame's variant (f64 Kahan at the smallest dt),
        // about 100 frames of it.
        let dt = dts.last().copied().unwrap_or(0.01);
        record(
            &dev,
            &x0,
            &v0,
            &m,
            dt,
            (t_end / dt).round() as usize,
            &mut rec,
        )?;
        rec.finish();
    }
    common::print_compiled();
    Ok(())
}

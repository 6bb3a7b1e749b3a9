//! The autodiff example's computation, shared by `examples/autodiff.rs`, the build-time
//! compiled `examples/prebuilt` (whose build script compiles these kernels to cubins) and the
//! GPU benchmark's AD section (benches/gpu.rs includes this file), so all of them measure the
//! same kernels:
//!
//! - the seed function f(x) = sin(x^2) ln x + x^3 / sqrt(1 - x^2) and its derivative by a
//!   tape (the first result, against the closed form);
//! - the seed program written for the tape (each step writes new state arrays, so that
//!   backward can replay every step) and the gradient of its final positions.

// Each includer uses its own subset.
#![allow(dead_code)]

use std::time::Instant;
use warp_lang as wp;
use wp::prelude::*;

/// y = f(x) = sin(x^2) ln x + x^3 / sqrt(1 - x^2), elementwise.
#[wp::kernel]
pub fn seed(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let v = x[i];
    y[i] = sin(v * v) * log(v) + v * v * v / sqrt(1.0 - v * v);
}

/// f(x) and f'(x) in closed form.
pub fn seed_closed_form(x: f64) -> (f64, f64) {
    let s = (1.0 - x * x).sqrt();
    let f = (x * x).sin() * x.ln() + x * x * x / s;
    let df = 2.0 * x * (x * x).cos() * x.ln()
        + (x * x).sin() / x
        + 3.0 * x * x / s
        + x.powi(4) / (s * s * s);
    (f, df)
}

/// f(0.5) and f'(0.5) through the `seed` kernel and a tape on `dev`: the program's first
/// result (on a GPU the first launch of `seed`, forward and adjoint).
pub fn first_result(dev: &wp::Device) -> wp::Result<(f64, f64)> {
    let x = wp::Array::from_slice(&[0.5f64], dev)?.with_grad()?;
    let y = wp::Array::<f64>::zeros(1, dev)?.with_grad()?;
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(seed, 1, (&x, &y), dev)?;
    }
    tape.backward(&y)?;
    let g = x.grad().expect("with_grad").to_vec()?[0];
    Ok((y.to_vec()?[0], g))
}

/// The machine-readable line `benches/cold_start.rs` reads: the time from `start` to now (the
/// first result), the derivative `df`'s relative error against the closed form, and what
/// loading the kernels cost so far (the compile reports: how many variants in how many units
/// (a kernel's forward and adjoint compiled as one unit count once), how many units NVRTC
/// compiled, how many variants the disk cache served or came from ahead-of-time cubins, the
/// time from their first launch to a loaded module and NVRTC's, summed, the slowest unit's
/// NVRTC time, and each compiled unit as `kernel:halves:ms`).
pub fn cold_start_line(start: Instant, dev: &wp::Device, df: f64) -> String {
    let first_ms = start.elapsed().as_secs_f64() * 1e3;
    let reports = wp::compile_reports();
    let count = |f: &dyn Fn(&wp::CompileReport) -> bool| reports.iter().filter(|r| f(r)).count();
    // (An empty f64 sum is -0.0.)
    let sum = |f: fn(&wp::CompileReport) -> f64| 0.0 + reports.iter().map(f).sum::<f64>();
    let compiled: Vec<&wp::CompileReport> = reports
        .iter()
        .filter(|r| r.is_unit() && !r.cache_hit)
        .collect();
    let units_ms: Vec<String> = compiled
        .iter()
        .map(|r| {
            let halves = match (r.one_unit, r.adjoint) {
                (true, _) => "fwd+adj",
                (false, true) => "adj",
                (false, false) => "fwd",
            };
            format!("{}:{halves}:{:.1}", r.kernel, r.compile_ms)
        })
        .collect();
    let max_ms = compiled.iter().map(|r| r.compile_ms).fold(0.0, f64::max);
    let (_, want) = seed_closed_form(0.5);
    format!(
        "cold_start first_result_ms={first_ms:.2} rel_error={:.2e} kernel_loading_ms={:.3} \
         nvrtc_ms={:.1} nvrtc_max_ms={max_ms:.1} variants={} units={} nvrtc={} cache_hits={} \
         aot={} unit_ms={} device={dev}",
        ((df - want) / want).abs(),
        sum(|r| r.total_ms),
        sum(|r| r.compile_ms),
        reports.len(),
        count(&|r| r.is_unit()),
        compiled.len(),
        count(&|r| r.cache_hit && !r.aot),
        count(&|r| r.aot),
        if units_ms.is_empty() {
            "-".to_string()
        } else {
            units_ms.join(",")
        },
    )
}

/// One step of the seed program: (x0, v0) -> (x1, v1), semi-implicit Euler with linear drag.
#[wp::kernel]
pub fn step(
    x0: Array<Vec3>,
    v0: Array<Vec3>,
    x1: Array<Vec3>,
    v1: Array<Vec3>,
    b: f32,
    mass: f32,
    gravity: Vec3,
    dt: f32,
) {
    let i = tid();
    let a = -b * v0[i] / mass + gravity;
    let v = v0[i] + a * dt;
    v1[i] = v;
    x1[i] = x0[i] + v * dt;
}

/// loss += sum over particles of |x|^2.
#[wp::kernel]
pub fn sum_sq(x: Array<Vec3>, loss: Array<f32>) {
    let i = tid();
    atomic_add(loss, 0, dot(x[i], x[i]));
}

/// The seed program's drag (kg/s), mass (kg), step (s) and gravity, shared by its scenes.
pub const SEED_B: f32 = 0.05;
pub const SEED_MASS: f32 = 0.1;
pub const SEED_DT: f32 = 0.01;
pub const SEED_GRAVITY: Vec3 = Vec3::new(0.0, 0.0, -9.81);

/// The seed program's initial positions and velocities for `n` particles.
pub fn seed_start(n: usize) -> (Vec<Vec3>, Vec<Vec3>) {
    let x0 = (0..n)
        .map(|i| Vec3::new((i % 100) as f32 * 0.01, (i % 7) as f32 * 0.1, 1.0))
        .collect();
    let v0 = (0..n)
        .map(|i| Vec3::new(1.0, (i % 3) as f32 - 1.0, 0.0))
        .collect();
    (x0, v0)
}

/// The largest relative errors of dL/dx0 (`gx`) and dL/dv0 (`gv`) against their closed forms
/// 2 x_T and 2 c x_T, for L = sum |x_T|^2 after `steps` steps of the seed program with its
/// constants: r = 1 - b dt / m, c = dt (r + r^2 + ... + r^T).
pub fn seed_closed_form_errors(x_t: &[Vec3], gx: &[Vec3], gv: &[Vec3], steps: usize) -> (f64, f64) {
    let r = 1.0 - (SEED_B * SEED_DT / SEED_MASS) as f64;
    let c: f64 = SEED_DT as f64 * (1..=steps).map(|k| r.powi(k as i32)).sum::<f64>();
    let (mut ex, mut ev) = (0.0f64, 0.0f64);
    for k in 0..x_t.len() {
        let xt = x_t[k].as_dvec3();
        ex = ex.max(
            (gx[k].as_dvec3() - 2.0 * xt).abs().max_element()
                / (2.0 * xt).abs().max_element().max(1.0),
        );
        ev = ev.max(
            (gv[k].as_dvec3() - 2.0 * c * xt).abs().max_element()
                / (2.0 * c * xt).abs().max_element().max(1.0),
        );
    }
    (ex, ev)
}

/// The gradient of the seed program's final positions for `n` particles over `steps` steps:
/// dL/dx0 = 2 x_T and dL/dv0 = 2 c x_T for L = sum |x_T|^2, with r = 1 - b dt / m and
/// c = dt (r + r^2 + ... + r^T). Runs once to warm up (on a GPU: compiles or loads `step`,
/// `sum_sq` and their adjoints), then times a forward and a backward pass and prints both
/// with the largest relative errors against the closed forms.
pub fn particle_gradients(n: usize, steps: usize, dev: &wp::Device) -> wp::Result<()> {
    let (b, mass, dt) = (SEED_B, SEED_MASS, SEED_DT);
    let (x0, v0) = seed_start(n);
    let mut xs = vec![wp::Array::from_slice(&x0, dev)?.with_grad()?];
    let mut vs = vec![wp::Array::from_slice(&v0, dev)?.with_grad()?];
    for _ in 0..steps {
        xs.push(wp::Array::<Vec3>::zeros(n, dev)?.with_grad()?);
        vs.push(wp::Array::<Vec3>::zeros(n, dev)?.with_grad()?);
    }
    let loss = wp::Array::<f32>::zeros(1, dev)?.with_grad()?;
    let tape = wp::Tape::new();
    // Warm-up (compiles the kernels on a GPU), then the timed run.
    {
        let _rec = tape.record();
        wp::launch(
            step,
            n,
            (&xs[0], &vs[0], &xs[1], &vs[1], b, mass, Vec3::ZERO, dt),
            dev,
        )?;
        wp::launch(sum_sq, n, (&xs[1], &loss), dev)?;
    }
    tape.backward(&loss)?;
    tape.reset()?;
    loss.fill(0.0)?;
    for a in xs.iter().chain(&vs) {
        a.zero_grad()?;
    }
    loss.zero_grad()?;
    wp::synchronize()?;
    let t = Instant::now();
    {
        let _rec = tape.record();
        for s in 0..steps {
            let args = (
                &xs[s],
                &vs[s],
                &xs[s + 1],
                &vs[s + 1],
                b,
                mass,
                SEED_GRAVITY,
                dt,
            );
            wp::launch(step, n, args, dev)?;
        }
        wp::launch(sum_sq, n, (&xs[steps], &loss), dev)?;
    }
    wp::synchronize()?;
    let fwd = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    tape.backward(&loss)?;
    wp::synchronize()?;
    let bwd = t.elapsed().as_secs_f64() * 1e3;
    // Closed forms, in f64 from the f32 final positions.
    let (gx, gv) = (
        xs[0].grad().expect("with_grad").to_vec()?,
        vs[0].grad().expect("with_grad").to_vec()?,
    );
    let (ex, ev) = seed_closed_form_errors(&xs[steps].to_vec()?, &gx, &gv, steps);
    println!(
        "particles {n} x {steps} steps on \"{dev}\": forward {fwd:.1} ms, backward {bwd:.1} ms \
         (ratio {:.2})",
        bwd / fwd
    );
    println!("  max relative error of dL/dx0 vs 2 x_T:   {ex:.2e}");
    println!("  max relative error of dL/dv0 vs 2 c x_T: {ev:.2e}");
    Ok(())
}

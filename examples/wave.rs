//! The 1-D wave equation u_tt = c^2 u_xx on [0, 1] with fixed ends, by the leapfrog finite
//! difference scheme, against the analytic standing wave u = sin(pi x) cos(pi c t).
//!
//! ```text
//! cargo run --release --example wave -- [--n 1024] [--device cpu|cuda:0]
//! ```
//! Sweeps the Courant number r = c dt / dx at a fixed grid: below 1 the error is the scheme's
//! dispersion, about (1 - r^2) dx^2 (plus f32 rounding over more steps), so it shrinks toward
//! r = 1, where the 1-D scheme is exact up to rounding; past 1 (the CFL limit) it blows up,
//! which the divergence guard (`Array::check_finite`) reports with the step and the index.
//! Prints error against run time for each r, and what it compiled.

use std::time::Instant;
use warp_lang as wp;
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

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    let k = args.iter().position(|a| a == name)?;
    args.get(k + 1).cloned()
}

fn main() -> wp::Result<()> {
    wp::init();
    let dev = match arg("--device") {
        Some(d) => wp::get_device(&d)?,
        None => wp::get_preferred_device(),
    };
    let n: usize = arg("--n").and_then(|v| v.parse().ok()).unwrap_or(1024);
    let dx = 1.0 / (n - 1) as f64;
    let c = 1.0f64;
    let t_end = 1.0f64;
    let x: Vec<f64> = (0..n).map(|i| i as f64 * dx).collect();
    let u0: Vec<f32> = x
        .iter()
        .map(|&x| (std::f64::consts::PI * x).sin() as f32)
        .collect();
    println!("wave equation, {n} points on \"{dev}\", c = {c}, until t = {t_end}");
    println!(
        "{:>6} {:>8} {:>12} {:>10}  stable",
        "r", "steps", "max error", "time (ms)"
    );
    for r in [0.25f64, 0.5, 0.9, 1.0, 1.01, 1.1] {
        let dt = r * dx / c;
        let steps = (t_end / dt).round() as usize;
        let r2 = (r * r) as f32;
        let mut a = wp::Array::from_slice(&u0, &dev)?;
        let mut b = wp::Array::<f32>::zeros(n, &dev)?;
        let mut next = wp::Array::<f32>::zeros(n, &dev)?;
        // Warm-up (compiles on a GPU), outside the timing.
        wp::launch(first_step, n, (&a, &b, r2), &dev)?;
        wp::launch(leapfrog, n, (&a, &b, &next, r2), &dev)?;
        wp::synchronize()?;
        let t = Instant::now();
        wp::launch(first_step, n, (&a, &b, r2), &dev)?;
        let mut blew_up = None;
        for s in 1..steps {
            wp::launch(leapfrog, n, (&a, &b, &next, r2), &dev)?;
            (a, b, next) = (b, next, a);
            if s % 64 == 0 {
                if let Err(e) = b.check_finite("u") {
                    blew_up = Some((s, e));
                    break;
                }
            }
        }
        let u = b.to_vec()?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let t_reached = steps as f64 * dt;
        let err = x
            .iter()
            .zip(&u)
            .map(|(&x, &v)| {
                let exact =
                    (std::f64::consts::PI * x).sin() * (std::f64::consts::PI * c * t_reached).cos();
                (v as f64 - exact).abs()
            })
            .fold(0.0f64, f64::max);
        match blew_up {
            None if err.is_finite() && err < 1.0 => {
                println!("{r:>6} {steps:>8} {err:>12.3e} {ms:>10.2}  yes")
            }
            None => println!("{r:>6} {steps:>8} {err:>12.3e} {ms:>10.2}  no (error {err:.1e})"),
            Some((s, e)) => println!(
                "{r:>6} {steps:>8} {:>12} {ms:>10.2}  no: at step {s}, {e}",
                "-"
            ),
        }
    }
    println!("compiled:");
    for r in wp::compile_reports() {
        println!(
            "  {}{}: {} bytes of CUDA, NVRTC {:.1} ms (cache hit {})",
            r.kernel,
            if r.adjoint { " (adjoint)" } else { "" },
            r.source_bytes,
            r.compile_ms,
            r.cache_hit
        );
    }
    if wp::compile_reports().is_empty() {
        println!("  (CPU: the kernels are Rust, compiled by cargo; no adjoint was built)");
    }
    Ok(())
}

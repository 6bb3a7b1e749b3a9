//! Reverse-mode AD of the seed function f(x) = sin(x^2) ln x + x^3 / sqrt(1 - x^2) at
//! x = 0.5, where f'(0.5) = 0.7854595 (closed form below), plus the 1M-particle gradient of
//! the seed program's final positions: dL/dx0 = 2 x_T and dL/dv0 = 2 c x_T for
//! L = sum |x_T|^2, with r = 1 - b dt / m and c = dt (r + r^2 + ... + r^T).
//!
//! ```text
//! cargo run --release --example autodiff -- [--n 1000000] [--steps 100] [--device cpu|cuda:0] [--load]
//! ```
//! Runs on the GPU when there is one. `--load` compiles the three kernels and their adjoints
//! up front (`wp::load_with_adjoints`) instead of one by one at first launch; the time to the
//! first result is printed either way (cold: with an empty kernel cache).

#[path = "common/seed_ad.rs"]
mod seed_ad;

use seed_ad::{step, sum_sq};
use std::time::Instant;
use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn seed(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let v = x[i];
    y[i] = sin(v * v) * log(v) + v * v * v / sqrt(1.0 - v * v);
}

fn closed_form(x: f64) -> f64 {
    let s = (1.0 - x * x).sqrt();
    2.0 * x * (x * x).cos() * x.ln() + (x * x).sin() / x + 3.0 * x * x / s + x.powi(4) / (s * s * s)
}

fn arg(name: &str, default: usize) -> usize {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|k| args.get(k + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() -> wp::Result<()> {
    let start = Instant::now();
    wp::init();
    let args: Vec<String> = std::env::args().collect();
    let dev = match args.iter().position(|a| a == "--device") {
        Some(k) => wp::get_device(args.get(k + 1).map(String::as_str).unwrap_or("cpu"))?,
        None => wp::get_preferred_device(),
    };
    if args.iter().any(|a| a == "--load") {
        let kernels = [
            wp::kernel_info(seed),
            wp::kernel_info(step),
            wp::kernel_info(sum_sq),
        ];
        wp::load_with_adjoints(&kernels, &dev)?;
    }

    // 1. The seed function.
    let x = wp::Array::from_slice(&[0.5f64], &dev)?.with_grad()?;
    let y = wp::Array::<f64>::zeros(1, &dev)?.with_grad()?;
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(seed, 1, (&x, &y), &dev)?;
    }
    tape.backward(&y)?;
    let g = x.grad().expect("with_grad").to_vec()?[0];
    println!(
        "first result after {:.0} ms (from the start of main)",
        start.elapsed().as_secs_f64() * 1e3
    );
    let want = closed_form(0.5);
    println!("f(0.5)  = {:.7}", y.to_vec()?[0]);
    println!(
        "f'(0.5) = {g:.7} (tape)   {want:.7} (closed form)   relative error {:.1e}",
        ((g - want) / want).abs()
    );

    // 2. Gradients through the particle program.
    let (n, steps) = (arg("--n", 1_000_000), arg("--steps", 100));
    let (b, mass, g_z, dt) = (0.05f32, 0.1f32, -9.81f32, 0.01f32);
    let x0: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new((i % 100) as f32 * 0.01, (i % 7) as f32 * 0.1, 1.0))
        .collect();
    let v0: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(1.0, (i % 3) as f32 - 1.0, 0.0))
        .collect();
    let mut xs = vec![wp::Array::from_slice(&x0, &dev)?.with_grad()?];
    let mut vs = vec![wp::Array::from_slice(&v0, &dev)?.with_grad()?];
    for _ in 0..steps {
        xs.push(wp::Array::<Vec3>::zeros(n, &dev)?.with_grad()?);
        vs.push(wp::Array::<Vec3>::zeros(n, &dev)?.with_grad()?);
    }
    let loss = wp::Array::<f32>::zeros(1, &dev)?.with_grad()?;
    let tape = wp::Tape::new();
    // Warm-up (compiles the kernels on a GPU), then the timed run.
    {
        let _rec = tape.record();
        wp::launch(
            step,
            n,
            (&xs[0], &vs[0], &xs[1], &vs[1], b, mass, Vec3::ZERO, dt),
            &dev,
        )?;
        wp::launch(sum_sq, n, (&xs[1], &loss), &dev)?;
    }
    tape.backward(&loss)?;
    tape.reset();
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
                Vec3::new(0.0, 0.0, g_z),
                dt,
            );
            wp::launch(step, n, args, &dev)?;
        }
        wp::launch(sum_sq, n, (&xs[steps], &loss), &dev)?;
    }
    wp::synchronize()?;
    let fwd = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    tape.backward(&loss)?;
    wp::synchronize()?;
    let bwd = t.elapsed().as_secs_f64() * 1e3;
    // Closed forms, in f64 from the f32 final positions.
    let r = 1.0 - (b * dt / mass) as f64;
    let c: f64 = dt as f64 * (1..=steps).map(|k| r.powi(k as i32)).sum::<f64>();
    let x_t = xs[steps].to_vec()?;
    let (gx, gv) = (
        xs[0].grad().expect("with_grad").to_vec()?,
        vs[0].grad().expect("with_grad").to_vec()?,
    );
    let (mut ex, mut ev) = (0.0f64, 0.0f64);
    for k in 0..n {
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
    println!(
        "particles {n} x {steps} steps on \"{dev}\": forward {fwd:.1} ms, backward {bwd:.1} ms \
         (ratio {:.2})",
        bwd / fwd
    );
    println!("  max relative error of dL/dx0 vs 2 x_T:   {ex:.2e}");
    println!("  max relative error of dL/dv0 vs 2 c x_T: {ev:.2e}");
    // On a GPU: the forward kernels and, because backward ran, their adjoints.
    print!("{}", wp::compile_summary());
    Ok(())
}

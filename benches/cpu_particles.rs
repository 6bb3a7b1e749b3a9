//! CPU backend against its baselines, measured in the same run: one step of the seed particle
//! program over 1M particles, as a warp-lang kernel, as a plain serial Rust loop and as a
//! hand-written rayon loop over the same data.
//!
//! ```text
//! cargo bench --bench cpu_particles
//! ```
//!
//! Criterion prints its statistics for each; at the end the bench prints a table of medians,
//! the ratios (kernel / rayon, serial / kernel) and the largest difference between the
//! kernel's result and the serial loop's (the same f32 arithmetic, so it should be zero).

use criterion::{black_box, Criterion};
use rayon::prelude::*;
use std::time::Duration;
use warp_lang as wp;

mod common;
use common::median;
use wp::prelude::*;

const N: usize = 1_000_000;
const B: f32 = 0.05;
const MASS: f32 = 0.1;
const DT: f32 = 0.01 * (2.0 * MASS / B);
const GRAVITY: Vec3 = Vec3::new(0.0, 0.0, -9.81);

#[wp::kernel]
fn integrate(x: Array<Vec3>, v: Array<Vec3>, b: f32, mass: f32, gravity: Vec3, dt: f32) {
    let i = tid();
    let a = -b * v[i] / mass + gravity;
    v[i] += a * dt;
    x[i] += v[i] * dt;
}

/// The step's parameters, passed at run time (through `black_box`) as the kernel gets them,
/// so that the baselines cannot fold them into constants.
#[derive(Clone, Copy)]
struct Params {
    b: f32,
    mass: f32,
    gravity: Vec3,
    dt: f32,
}

fn params() -> Params {
    black_box(Params {
        b: B,
        mass: MASS,
        gravity: GRAVITY,
        dt: DT,
    })
}

#[inline(always)]
fn step_one(x: &mut Vec3, v: &mut Vec3, p: Params) {
    let a = -p.b * *v / p.mass + p.gravity;
    *v += a * p.dt;
    *x += *v * p.dt;
}

fn serial(x: &mut [Vec3], v: &mut [Vec3]) {
    let p = params();
    for (x, v) in x.iter_mut().zip(v.iter_mut()) {
        step_one(x, v, p);
    }
}

fn hand_rayon(x: &mut [Vec3], v: &mut [Vec3]) {
    let p = params();
    x.par_iter_mut()
        .zip(v.par_iter_mut())
        .for_each(|(x, v)| step_one(x, v, p));
}

fn start() -> (Vec<Vec3>, Vec<Vec3>) {
    let x = (0..N)
        .map(|i| Vec3::new(i as f32 * 1e-6, 0.5, -0.25))
        .collect();
    let v = (0..N)
        .map(|i| Vec3::new(0.1, -((i % 7) as f32) * 0.01, 0.2))
        .collect();
    (x, v)
}

fn main() {
    let dev = wp::cpu();
    let (x0, v0) = start();
    let xa = wp::Array::from_slice(&x0, &dev).expect("x");
    let va = wp::Array::from_slice(&v0, &dev).expect("v");
    let (mut xs, mut vs) = (x0.clone(), v0.clone());
    let (mut xr, mut vr) = (x0.clone(), v0.clone());

    let mut c = Criterion::default()
        .configure_from_args()
        .warm_up_time(Duration::from_millis(500));
    let mut g = c.benchmark_group("particles_1M_step");
    g.bench_function("warp_kernel", |bch| {
        bch.iter(|| {
            wp::launch(integrate, N, (&xa, &va, B, MASS, GRAVITY, DT), &dev).expect("launch")
        })
    });
    g.bench_function("serial_loop", |bch| {
        bch.iter(|| serial(black_box(&mut xs), black_box(&mut vs)))
    });
    g.bench_function("hand_rayon", |bch| {
        bch.iter(|| hand_rayon(black_box(&mut xr), black_box(&mut vr)))
    });
    g.finish();

    // The ratio table, from medians taken here in the same process.
    let runs = 31;
    let tk = median(runs, || {
        wp::launch(integrate, N, (&xa, &va, B, MASS, GRAVITY, DT), &dev).expect("launch")
    });
    let ts = median(runs, || serial(black_box(&mut xs), black_box(&mut vs)));
    let tr = median(runs, || hand_rayon(black_box(&mut xr), black_box(&mut vr)));

    // Accuracy: the same number of steps from the same start, kernel against serial loop.
    let xk = wp::Array::from_slice(&x0, &dev).expect("x");
    let vk = wp::Array::from_slice(&v0, &dev).expect("v");
    let (mut xc, mut vc) = (x0.clone(), v0.clone());
    for _ in 0..10 {
        wp::launch(integrate, N, (&xk, &vk, B, MASS, GRAVITY, DT), &dev).expect("launch");
        serial(&mut xc, &mut vc);
    }
    let max_diff = xk
        .to_vec()
        .expect("read")
        .iter()
        .zip(&xc)
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0f32, f32::max);

    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "\nparticles, 1M, one step, {} rayon threads (median of {runs}):",
        rayon::current_num_threads()
    );
    println!("  warp kernel : {:8.3} ms", ms(tk));
    println!("  serial loop : {:8.3} ms", ms(ts));
    println!("  hand rayon  : {:8.3} ms", ms(tr));
    println!(
        "  kernel / hand rayon = {:.2}x (target <= 1.2x)",
        ms(tk) / ms(tr)
    );
    println!(
        "  serial / kernel     = {:.2}x (target >= 1.6x on 2 cores)",
        ms(ts) / ms(tk)
    );
    println!(
        "  accuracy: max |x_kernel - x_serial| after 10 steps = {max_diff:e} (same f32 arithmetic)"
    );
}

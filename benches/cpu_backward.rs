//! The CPU adjoint of a kernel against a hand-written rayon adjoint, measured in the same run:
//! one backward pass of `y[i] = 3 x[i]^2 + p[i]` over 4M elements, through a `Tape`, against
//! the same gradient written by hand with plain (non-atomic) adds.
//!
//! ```text
//! cargo bench --bench cpu_backward
//! ```
//!
//! The generated adjoint adds a thread-owned read's gradient atomically (an uncontended
//! atomic add per element: several backward passes on different host threads may share a
//! parameter array's gradient), and the hand-written one does not; the ratio is what that
//! safety and the rest of the generated code cost. At the end the bench prints the medians,
//! the ratio and the largest difference between the two gradients (the same f32 arithmetic:
//! zero).

use criterion::{black_box, Criterion};
use rayon::prelude::*;
use std::time::Duration;
use warp_lang as wp;

mod common;
use common::median;
use wp::prelude::*;

const N: usize = 4_000_000;

#[wp::kernel]
fn square_plus(x: Array<f32>, p: Array<f32>, y: Array<f32>) {
    let i = tid();
    y[i] = 3.0 * x[i] * x[i] + p[i];
}

/// Gradients by hand, as the tape computes them with the output's gradient seeded with ones:
/// the store hands `y`'s gradient back and clears it, `x` receives `3 x gy + 3 x gy`
/// (the two reads), `p` receives `gy`.
fn hand_adjoint(x: &[f32], gx: &mut [f32], gp: &mut [f32], gy: &mut [f32]) {
    gy.par_iter_mut().for_each(|g| *g = 1.0);
    x.par_iter()
        .zip(gx.par_iter_mut())
        .zip(gp.par_iter_mut())
        .zip(gy.par_iter_mut())
        .for_each(|(((&x, gx), gp), gy)| {
            let g = *gy;
            *gy = 0.0;
            let t = 3.0 * x * g;
            *gx += t;
            *gx += t;
            *gp += g;
        });
}

fn main() {
    let dev = wp::cpu();
    let x0: Vec<f32> = (0..N).map(|i| (i % 1000) as f32 * 1e-3 - 0.5).collect();
    let x = wp::Array::from_slice(&x0, &dev)
        .and_then(|a| a.with_grad())
        .expect("x");
    let p = wp::Array::<f32>::zeros(N, &dev)
        .and_then(|a| a.with_grad())
        .expect("p");
    let y = wp::Array::<f32>::zeros(N, &dev)
        .and_then(|a| a.with_grad())
        .expect("y");
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(square_plus, N, (&x, &p, &y), &dev).expect("launch");
    }
    let (mut gx, mut gp, mut gy) = (vec![0.0f32; N], vec![0.0f32; N], vec![0.0f32; N]);

    let mut c = Criterion::default()
        .configure_from_args()
        .warm_up_time(Duration::from_millis(500));
    let mut g = c.benchmark_group("backward_4M");
    g.bench_function("tape_backward", |b| {
        b.iter(|| tape.backward(&y).expect("backward"))
    });
    g.bench_function("hand_rayon", |b| {
        b.iter(|| hand_adjoint(black_box(&x0), &mut gx, &mut gp, &mut gy))
    });
    g.finish();

    let runs = 31;
    let tt = median(runs, || tape.backward(&y).expect("backward"));
    let th = median(runs, || {
        hand_adjoint(black_box(&x0), &mut gx, &mut gp, &mut gy)
    });

    // Accuracy: one backward from zeroed gradients each way.
    tape.zero().expect("zero");
    tape.backward(&y).expect("backward");
    let (mut hx, mut hp, mut hy) = (vec![0.0f32; N], vec![0.0f32; N], vec![0.0f32; N]);
    hand_adjoint(&x0, &mut hx, &mut hp, &mut hy);
    let diff = |a: &wp::Array<f32>, b: &[f32]| {
        a.grad()
            .expect("grad")
            .to_vec()
            .expect("read")
            .iter()
            .zip(b)
            .map(|(u, v)| (u - v).abs())
            .fold(0.0f32, f32::max)
    };
    let (dx, dp) = (diff(&x, &hx), diff(&p, &hp));

    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "\nbackward of y = 3 x^2 + p, 4M elements, {} rayon threads (median of {runs}):",
        rayon::current_num_threads()
    );
    println!("  tape backward : {:8.3} ms", ms(tt));
    println!("  hand rayon    : {:8.3} ms", ms(th));
    println!("  tape / hand rayon = {:.2}x", ms(tt) / ms(th));
    println!("  accuracy: max |dL/dx - hand| = {dx:e}, max |dL/dp - hand| = {dp:e} (same f32 arithmetic)");
}

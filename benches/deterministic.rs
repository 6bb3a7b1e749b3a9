//! What `#[kernel(deterministic)]` costs, measured in the same run as the ordinary kernel:
//! a contended accumulation (every thread adds into one of 4 bins) and a sparse one (every
//! thread adds into its own element and its neighbour's), 1M threads each, f32.
//!
//! ```text
//! cargo bench --bench deterministic                      # the CPU
//! cargo bench --bench deterministic --features cuda      # and cuda:0 when there is one
//! ```
//!
//! Prints the median milliseconds of each (`common::median_ms`: 15 runs after a warm-up) and
//! the ratio deterministic / ordinary, on the CPU and on `cuda:0` when there is one (the GPU
//! rows say why they are missing otherwise). On the CPU the ordinary contended kernel is a
//! compare-exchange loop per add on 4 hot words; the deterministic one pushes a record per add
//! and sorts and adds the records after the launch. On a GPU the ordinary kernels are
//! `atomicAdd`s; the deterministic ones write a record per lane into their thread's slots,
//! then two radix sorts of the slots (the low and the high address words) and one pass that
//! adds each element's run in order follow the launch (warp-runtime's cuda/deterministic.rs).
//! The "gather bwd" row is a backward launch: every thread reads one of 7 shared elements,
//! whose gradients the ordinary adjoint adds atomically and the deterministic one records.

use warp_lang as wp;

mod common;
use common::median_ms;
use wp::prelude::*;

const N: usize = 1 << 20;

#[wp::kernel]
fn contended(x: Array<f32>, bins: Array<f32>) {
    let i = tid();
    atomic_add(bins, i % 4, x[i]);
}

#[wp::kernel(deterministic)]
fn contended_det(x: Array<f32>, bins: Array<f32>) {
    let i = tid();
    atomic_add(bins, i % 4, x[i]);
}

#[wp::kernel]
fn sparse(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    atomic_add(out, i, x[i]);
    atomic_add(out, (i + 1) % x.len(), 0.5 * x[i]);
}

#[wp::kernel(deterministic)]
fn sparse_det(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    atomic_add(out, i, x[i]);
    atomic_add(out, (i + 1) % x.len(), 0.5 * x[i]);
}

#[wp::kernel]
fn gather(x: Array<f32>, w: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = x[i % 7] * w[i];
}

#[wp::kernel(deterministic)]
fn gather_det(x: Array<f32>, w: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = x[i % 7] * w[i];
}

fn row(dev: &wp::Device, what: &str, plain: f64, det: wp::Result<f64>) {
    let dev = dev.to_string();
    match det {
        Ok(det) => println!(
            "{dev:<8} {what:<10} ordinary {plain:>9.3} ms   deterministic {det:>9.3} ms   ratio {:>6.2}",
            det / plain
        ),
        Err(wp::Error::Deterministic { why, .. }) => {
            println!("{dev:<8} {what:<10} ordinary {plain:>9.3} ms   deterministic: {why}")
        }
        Err(e) => panic!("{what} on {dev}: {e}"),
    }
}

fn bench(dev: &wp::Device) -> wp::Result<()> {
    let xs: Vec<f32> = (0..N)
        .map(|i| ((i * 7919) % 1000) as f32 * 1e-3 - 0.5)
        .collect();
    let x = wp::Array::from_slice(&xs, dev)?;
    let bins = wp::Array::<f32>::zeros(4, dev)?;
    let out = wp::Array::<f32>::zeros(N, dev)?;
    let plain = median_ms(|| wp::launch(contended, N, (&x, &bins), dev))?;
    let det = median_ms(|| wp::launch(contended_det, N, (&x, &bins), dev));
    row(dev, "contended", plain, det);
    let plain = median_ms(|| wp::launch(sparse, N, (&x, &out), dev))?;
    let det = median_ms(|| wp::launch(sparse_det, N, (&x, &out), dev));
    row(dev, "sparse", plain, det);
    // Backward: each timed run zeroes x's gradient, seeds y's and runs the adjoint launch.
    let xg = wp::Array::from_slice(&xs[..7], dev)?.with_grad()?;
    let w = wp::Array::from_slice(&xs, dev)?.with_grad()?;
    let y = wp::Array::<f32>::zeros(N, dev)?.with_grad()?;
    let backward = |det: bool| -> wp::Result<f64> {
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            match det {
                true => wp::launch(gather_det, N, (&xg, &w, &y), dev)?,
                false => wp::launch(gather, N, (&xg, &w, &y), dev)?,
            }
        }
        median_ms(|| {
            // (The adjoint of the store takes y's gradient: it is seeded again each run.)
            xg.zero_grad()?;
            y.grad().expect("made with a gradient").fill(1.0)?;
            tape.backward_from_grads()
        })
    };
    let plain = backward(false)?;
    row(dev, "gather bwd", plain, backward(true));
    Ok(())
}

fn main() {
    println!("deterministic accumulation, {N} threads, f32");
    bench(&wp::cpu()).expect("CPU");
    match wp::get_device("cuda:0") {
        Ok(dev) => bench(&dev).expect("cuda:0"),
        Err(e) => println!("cuda:0   not timed: {e}"),
    }
}

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
//! the ratio deterministic / ordinary. The ordinary contended kernel is a compare-exchange
//! loop per add on 4 hot words; the deterministic one pushes a record per add and sorts and
//! adds the records after the launch. On a GPU the deterministic path is not built yet: the
//! bench says so instead of timing it.

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

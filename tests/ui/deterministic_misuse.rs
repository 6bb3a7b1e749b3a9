// `#[kernel(deterministic)]` refuses what it cannot keep deterministic, at the call: a float
// accumulation's old value (there is none: the adds happen after the launch), a float
// exchange (the last writer wins), and tiles; `max_records` is at least 1.
use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel(deterministic)]
fn uses_old_value(a: Array<f32>, out: Array<f32>) {
    let i = tid();
    let old = atomic_add(a, 0, 1.0);
    out[i] = old;
}

#[wp::kernel(deterministic)]
fn exchanges_floats(a: Array<f64>) {
    let i = tid();
    atomic_exch(a, 0, i as f64);
}

#[wp::kernel(deterministic)]
fn integer_old_value_is_fine(count: Array<i32>, out: Array<i32>) {
    let i = tid();
    out[i] = atomic_add(count, 0, 1);
}

#[wp::kernel(deterministic)]
fn tiled(a: Array<f32>, out: Array<f32>) {
    let t = tile_load::<32>(a, 0);
    tile_store(out, t, 0);
}

#[wp::kernel(deterministic(max_records = 0))]
fn no_records(a: Array<f32>) {
    atomic_add(a, 0, 1.0);
}

fn main() {}

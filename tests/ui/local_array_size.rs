use warp_lang as wp;
use wp::prelude::*;

const NONE: usize = 0;
const HUGE: usize = 1 << 20;

// A length that names a const of 0: only rustc knows the value.
#[wp::kernel]
fn empty_by_const(out: Array<f32>) {
    let a = [0.0f32; NONE];
    out[tid()] = a.len() as f32;
}

// 8 MiB of f64 per thread: more than a local array may take.
#[wp::kernel]
fn too_big(out: Array<f64>) {
    let a = [1.0f64; HUGE];
    out[tid()] = a[0];
}

// The same through a literal length.
#[wp::func]
fn too_big_literal(x: f32) -> f32 {
    let a = [x; 100000];
    a[1]
}

fn main() {}

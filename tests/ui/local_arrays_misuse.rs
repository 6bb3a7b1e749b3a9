use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn misuse(out: Array<f32>, n: i32) {
    let i = tid();
    let mixed = [1.0f32, 2.0f64];
    let dynamic = [0.0f32; n];
    let c = [0.0f32; 4];
    let x = c[1.5];
    let f = 0.5f32;
    let x2 = c[f];
    let y = c + 1.0;
    out[i] = c;
    let z = sin(c);
    let w = c.x;
    c[0] = 1.0;
    let two = c[(0, 1)];
}

#[wp::kernel]
fn as_parameter(a: [f32; 4]) {}

#[wp::func]
fn empty(s: f32) -> f32 {
    let a = [s; 0];
    s
}

#[derive(Clone, Copy, wp::Struct)]
#[repr(C)]
struct Inner {
    v: f32,
}

// Array fields hold what local arrays hold: not user structs.
#[derive(Clone, Copy, wp::Struct)]
#[repr(C)]
struct WithArray {
    values: [Inner; 4],
}

fn main() {}

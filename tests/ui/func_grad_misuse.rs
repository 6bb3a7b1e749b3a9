// `wp::grad(f)` refuses funcs it cannot differentiate, at the call, with the reason.
use warp_lang as wp;
use wp::prelude::*;

#[wp::func]
fn takes_array(a: Array<f32>, x: f32) -> f32 {
    a[0] * x
}

#[wp::func]
fn int_result(x: f32) -> i32 {
    x as i32
}

// The old value of an atomic picks where it writes: no adjoint.
#[wp::func]
fn no_adjoint(slots: Array<i32>, out: Array<f32>, x: f32) -> f32 {
    let k = atomic_add(slots, 0, 1);
    out[k] = x;
    x
}

#[wp::func]
fn scalar(x: f32) -> f32 {
    x * x
}

#[wp::kernel]
fn k(a: Array<f32>, slots: Array<i32>, out: Array<f32>) {
    let i = tid();
    out[i] = wp::grad(takes_array)(a, 1.0);
    out[i] = wp::grad(int_result)(1.0);
    out[i] = wp::grad(no_adjoint)(slots, out, 1.0);
}

#[wp::kernel]
fn k2(out: Array<f32>) {
    let i = tid();
    out[i] = wp::grad(1.0)(2.0);
    out[i] = wp::grad(scalar, scalar)(2.0);
}

fn main() {}

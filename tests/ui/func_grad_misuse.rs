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

// A float stored into a volume has no adjoint yet: nor has the func.
#[wp::func]
fn no_adjoint(v: Volume<f32>, x: f32) -> f32 {
    volume_store(v, 0, 0, 0, x);
    x * x
}

#[wp::func]
fn scalar(x: f32) -> f32 {
    x * x
}

#[wp::kernel]
fn k(a: Array<f32>, v: Volume<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = wp::grad(takes_array)(a, 1.0);
    out[i] = wp::grad(int_result)(1.0);
    let (_, g) = wp::grad(no_adjoint)(v, 1.0);
    out[i] = g;
}

#[wp::kernel]
fn k2(out: Array<f32>) {
    let i = tid();
    out[i] = wp::grad(1.0)(2.0);
    out[i] = wp::grad(scalar, scalar)(2.0);
}

fn main() {}

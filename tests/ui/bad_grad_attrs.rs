// Custom gradients name value parameters of the func, and a kernel option must exist.
use warp_lang as wp;
use wp::prelude::*;

#[wp::func]
fn dx(x: f32, adj: f32) -> f32 {
    adj * x
}

#[wp::func(grad(y = dx))]
fn f(x: f32) -> f32 {
    x * x
}

#[wp::func(grad(a = dx))]
fn g(a: Array<f32>, x: f32) -> f32 {
    a[0] * x
}

#[wp::kernel(enable_backward = 3)]
fn k(a: Array<f32>) {
    let i = tid();
    a[i] = f(a[i]) + g(a, 1.0);
}

fn main() {}

use warp_lang as wp;
use wp::prelude::*;

wp::overloads!(score);

#[wp::func(overload)]
fn score(x: f32) -> f32 {
    x
}

#[wp::func(overload)]
fn score(x: f64) -> f64 {
    x
}

#[wp::func(overload)]
fn score(x: f32, n: i32) -> f32 {
    x * n as f32
}

#[wp::func]
fn cube<T: Float>(x: T) -> T {
    x * x * x
}

#[wp::kernel]
fn no_overload(x: Array<f32>, n: Array<i64>) {
    let i = tid();
    // No overload of `score` takes (f32, i64).
    x[i] = score(x[i], n[i]);
}

#[wp::kernel]
fn ambiguous(x: Array<f32>) {
    let i = tid();
    // An unsuffixed literal fits both the f32 and the f64 overload.
    x[i] = score(1.5);
}

#[wp::kernel]
fn no_instance(n: Array<i64>) {
    let i = tid();
    // No instance of `cube` takes an i64.
    n[i] = cube(n[i]);
}

fn main() {}

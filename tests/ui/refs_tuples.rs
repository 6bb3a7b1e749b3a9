use warp_lang as wp;
use wp::prelude::*;

// Tuples and `&mut` parameters: what the language refuses, at the user's span.

#[wp::func]
fn accumulate(acc: &mut f32, x: f32) {
    *acc += x;
}

#[wp::func]
fn sq(x: f32) -> f32 {
    x * x
}

#[wp::func]
fn swap(a: &mut f32, b: &mut f32) {
    let t = *a;
    *a = *b;
    *b = t;
}

// A shared reference adds nothing to a value; an array is no `&mut` value.
#[wp::func]
fn shared(x: &f32, a: &mut Array<f32>) -> f32 {
    1.0
}

// A `&mut` parameter's value is `*acc`; it is assigned through `*acc = ..`.
#[wp::func]
fn bare(acc: &mut f32) {
    let y = acc + 1.0;
    acc = 2.0;
    accumulate(&mut acc, 1.0);
}

#[wp::kernel]
fn k(x: Array<f32>, pair: (f32, f32)) {
    let i = tid();
    let mut a = x[i];
    let b = 1.0f32;
    swap(&mut a, &mut a);
    accumulate(&mut a, a + 1.0);
    accumulate(&mut b, 1.0);
    accumulate(&x[i], 1.0);
    let s = *a;
}

// Calls whose `&mut` arguments do not match the func's `&mut` parameters: rustc's check.
#[wp::kernel]
fn mismatched(x: Array<f32>) {
    let i = tid();
    let mut a = x[i];
    accumulate(a, 1.0);
    x[i] = sq(&mut a);
}

#[wp::func]
fn two() -> (f32, f32) {
    (1.0, 2.0)
}

#[wp::kernel]
fn tuples(x: Array<f32>) {
    let i = tid();
    let t = (x[i], 1.0);
    let (a, b, c) = t;
    let (d, e) = x[i];
    println!("{:?}", t);
    let u = (x[i], x);
    x[i] = t.2;
    x[i] = x[i].0;
}

// A func's tuple result has the length its pattern says: rustc's check.
#[wp::kernel]
fn func_arity(x: Array<f32>) {
    let i = tid();
    let (a, b, c) = two();
    x[i] = a;
}

fn main() {}

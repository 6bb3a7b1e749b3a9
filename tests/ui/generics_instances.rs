use warp_lang as wp;
use wp::prelude::*;

// Not an array element: the listed type fails the bound where it is written.
#[derive(Clone, Copy)]
struct Plain {
    x: f32,
}

#[wp::func(instances(T = [f32, Plain]))]
fn first<T: Element>(a: T, b: T) -> T {
    let _ = b;
    a
}

wp::overloads!(combine);

#[wp::func(overload)]
fn combine(a: i32, b: i32) -> i32 {
    a - b
}

// A second overload for i32: two definitions of one overload.
#[wp::func(overload)]
fn combine(a: i32, b: i32) -> i32 {
    a + b
}

#[wp::func(overload)]
fn combine<V: Vector>(a: V, b: V) -> V {
    a + b
}

#[wp::kernel]
fn calls(x: Array<f32>, i: Array<i32>) {
    let k = tid();
    // No overload takes an f32 first argument.
    x[k] = combine::<f32>(x[k], 1.0);
    // A generic func without an instance for i32.
    i[k] = first::<i32>(i[k], 2);
}

#[wp::kernel]
fn ints<I: Int>(a: Array<I>, s: I) {
    let k = tid();
    a[k] = a[k] * s;
}

fn main() -> wp::Result<()> {
    let dev = wp::cpu();
    let a = wp::Array::<i64>::zeros(4, &dev)?;
    // An i64 array with an i32 scale: no instance takes both.
    wp::launch(ints, 4, (&a, 2i32), &dev)?;
    Ok(())
}

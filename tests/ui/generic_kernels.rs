use warp_lang as wp;
use wp::prelude::*;

// A bound other than Float.
#[wp::kernel]
fn copy_bound<T: Copy>(x: Array<T>) {
    let _ = x[0];
}

// T in no parameter: the launch could not pick an instance.
#[wp::kernel]
fn hidden_param<T: Float>(out: Array<f32>) {
    let x: T = 1.0;
    out[0] = x as f32;
}

// `Vec3` where `Vec3<T>` was meant: fine for f32, a type error in the f64 instance only.
#[wp::kernel]
fn forgot_family<T: Float>(v: Array<Vec3>, s: T) {
    let i = tid();
    v[i] = v[i] * s;
}

#[wp::kernel]
fn scale<T: Float>(x: Array<T>, s: T) {
    let i = tid();
    x[i] = x[i] * s;
}

fn main() -> wp::Result<()> {
    let dev = wp::cpu();
    let x = wp::Array::<f32>::zeros(4, &dev)?;
    // An f32 array with an f64 scale: no instance takes both.
    wp::launch(scale, 4, (&x, 2.0f64), &dev)?;
    Ok(())
}

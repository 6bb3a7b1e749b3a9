//! The seed program written for the tape: each step writes new state arrays, so that
//! backward can replay every step. Shared by `examples/autodiff.rs` and the GPU benchmark's
//! AD section (benches/gpu.rs includes this file), so both measure the same kernels.

use warp_lang as wp;
use wp::prelude::*;

/// One step of the seed program: (x0, v0) -> (x1, v1), semi-implicit Euler with linear drag.
#[wp::kernel]
pub fn step(
    x0: Array<Vec3>,
    v0: Array<Vec3>,
    x1: Array<Vec3>,
    v1: Array<Vec3>,
    b: f32,
    mass: f32,
    gravity: Vec3,
    dt: f32,
) {
    let i = tid();
    let a = -b * v0[i] / mass + gravity;
    let v = v0[i] + a * dt;
    v1[i] = v;
    x1[i] = x0[i] + v * dt;
}

/// loss += sum over particles of |x|^2.
#[wp::kernel]
pub fn sum_sq(x: Array<Vec3>, loss: Array<f32>) {
    let i = tid();
    atomic_add(loss, 0, dot(x[i], x[i]));
}

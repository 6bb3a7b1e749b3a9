// `same_shape` names array parameters (or `dim`): the validator checks the names against the
// kernel's lowered signature.
use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel(same_shape(x, v, dim), same_shape(x, scale, velocity))]
fn scale(x: Array<f32>, v: Array<f32>, scale: f32) {
    let i = tid();
    v[i] = x[i] * scale;
}

fn main() {}

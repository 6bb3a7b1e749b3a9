use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn k(v: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    out[i] = v[i].magnitude();
}

fn main() {}

use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn k(a: Array<f32>, x: f32, y: f64, v: Vec3) {
    let i = tid();
    let s = x + y;
    let w = v * y;
    a[i] = y;
    let n = sqrt(3);
}

fn main() {}

use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn k(a: Array<f32>) {
    let i = tid();
    let f = |x: f32| x * 2.0;
    a[i] = 1.0;
}

fn main() {}

use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn k(a: Array<f32>, n: i32) {
    let i = tid();
    match n {
        0 => a[i] = 0.0,
        _ => a[i] = 1.0,
    }
    let t = (1.0,);
    'outer: for j in 0..n {
        break 'outer;
    }
    for x in a {}
    let q = a.len().unwrap();
}

fn main() {}

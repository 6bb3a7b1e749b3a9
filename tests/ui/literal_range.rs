use warp_lang as wp;
use wp::prelude::*;

// A literal must fit the type it takes (Rust's `overflowing_literals`): a float that rounds to
// infinity in its type, an integer past i128 (which no type holds, so it cannot wrap), an
// integer out of its type's range.
#[wp::kernel]
fn k(a: Array<f32>, h: Array<f16>, n: Array<i32>) {
    let i = tid();
    a[i] = 1e39;
    let x: f64 = 1e309;
    h[i] = h[i] * 65520.0;
    n[i] = 340282366920938463463374607431768211455;
    n[i] = 2147483648;
}

fn main() {}

// `break` and `continue` belong to loops: the validator says where one is not.
use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn k(a: Array<f32>) {
    let i = tid();
    for j in 0..4 {
        if j == 1 {
            continue;
        }
        a[i] += 1.0;
    }
    if a[i] > 2.0 {
        break;
    }
    continue;
}

fn main() {}

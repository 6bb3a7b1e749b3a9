use warp_lang as wp;
use wp::prelude::*;

#[wp::func]
fn fact(n: i32) -> i32 {
    if n <= 1 { 1 } else { n * fact(n - 1) }
}

fn main() {}

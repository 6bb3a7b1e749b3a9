use warp_lang as wp;
use wp::prelude::*;

#[wp::func]
fn ping(n: i32) -> i32 {
    pong(n - 1)
}

#[wp::func]
fn pong(n: i32) -> i32 {
    ping(n - 1)
}

fn main() {}

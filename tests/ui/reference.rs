use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn by_ref(x: &f32, a: Array<f32>) {
    a[tid()] = 1.0;
}

#[wp::kernel]
fn take_ref(a: Array<f32>, s: f32) {
    let r = &s;
}

fn main() {}

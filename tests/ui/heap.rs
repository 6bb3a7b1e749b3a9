use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn strings(name: String, a: Array<f32>) {}

#[wp::kernel]
fn vectors(a: Array<f32>) {
    let v = Vec::new();
    let w = vec![1.0, 2.0];
}

fn main() {}

// A view is a name for part of an array, resolved into accesses of the array: the validator
// refuses any other use of it (each statement once), after the front end has accepted the
// kernel.
use warp_lang as wp;
use wp::prelude::*;

#[wp::func]
fn first(a: Array<f32>) -> f32 {
    a[0]
}

#[wp::kernel]
fn misuse(m: Array<f32, 2>, x: Array<f32>) {
    let i = tid();
    let r = m.row(i);
    // Indexing, measuring and viewing again are fine.
    x[i] = r[0] + r.len() as f32 + r.view(1..2)[0];
    // A view is not a value a func can take (yet).
    x[i] = first(m.row(i));
    // Nor one to print.
    println!("{:?}", r);
}

fn main() {}

use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn misuse(m: Array<f32, 2>, x: Array<f32>) {
    let i = tid();
    // (A view used as a value is the validator's error: views_as_values.rs.)
    // Views are immutable names.
    let mut r = m.row(i);
    // `row` of a 1-D array would be an element.
    let e = x.row(i);
    // `view` takes a range.
    let v = x.view(i);
}

fn main() {}

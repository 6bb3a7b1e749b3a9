use warp_lang as wp;
use wp::prelude::*;

#[wp::func]
fn first(a: Array<f32>) -> f32 {
    a[0]
}

#[wp::kernel]
fn misuse(m: Array<f32, 2>, x: Array<f32>) {
    let i = tid();
    // A view is not a value a func can take (yet).
    x[i] = first(m.row(i));
    // Views are immutable names.
    let mut r = m.row(i);
    // `row` of a 1-D array would be an element.
    let e = x.row(i);
    // `view` takes a range.
    let v = x.view(i);
}

fn main() {}

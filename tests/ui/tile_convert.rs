use warp_lang as wp;
use wp::prelude::*;

// The conversions' shape and element rules, each an error at its call.
#[wp::kernel]
fn reshape_size(a: Array<f32, 2>) {
    let t = tile_load::<4, 6>(a, (0, 0));
    let r = tile_reshape::<5, 5>(t);
}

#[wp::kernel]
fn diag_not_square(a: Array<f32, 2>, d: Array<f32>) {
    let t = tile_load::<4, 6>(a, (0, 0));
    let v = tile_load::<4>(d, 0);
    let r = tile_diag_add(t, v);
}

#[wp::kernel]
fn diag_length(a: Array<f32, 2>, d: Array<f32>) {
    let t = tile_load::<4, 4>(a, (0, 0));
    let v = tile_load::<5>(d, 0);
    let r = tile_diag_add(t, v);
}

#[wp::kernel]
fn full_value(n: i32) {
    let t = tile_full::<f32, 8>(n);
}

#[wp::kernel]
fn astype_without_element(a: Array<f32>) {
    let t = tile_load::<8>(a, 0);
    let u = tile_astype(t);
}

fn main() {}

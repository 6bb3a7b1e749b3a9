use warp_lang as wp;
use wp::prelude::*;

const TM: usize = 16;
const KB: usize = 4;

// The tile linear algebra's shape and element rules, each an error at its call.
#[wp::kernel]
fn not_square(a: Array<f32, 2>) {
    let x = tile_load::<4, 8>(a, (0, 0));
    let l = tile_cholesky(x);
}

#[wp::kernel]
fn one_dim(v: Array<f32>) {
    let x = tile_load::<16>(v, 0);
    let l = tile_cholesky(x);
}

#[wp::kernel]
fn int_elements(a: Array<i32, 2>) {
    let x = tile_load::<4, 4>(a, (0, 0));
    let l = tile_cholesky(x);
}

#[wp::kernel]
fn fill_mode(a: Array<f32, 2>) {
    let x = tile_load::<4, 4>(a, (0, 0));
    let u = tile_cholesky(x, 1);
}

#[wp::kernel]
fn rhs_length(a: Array<f32, 2>, v: Array<f32>) {
    let l = tile_load::<4, 4>(a, (0, 0));
    let y = tile_load::<5>(v, 0);
    let z = tile_lower_solve(l, y);
}

#[wp::kernel]
fn rhs_rows(a: Array<f32, 2>) {
    let u = tile_load::<4, 4>(a, (0, 0));
    let y = tile_load::<3, 4>(a, (0, 0));
    let x = tile_upper_solve(u, y);
}

#[wp::kernel]
fn rhs_element(a: Array<f32, 2>, v: Array<f64>) {
    let l = tile_load::<4, 4>(a, (0, 0));
    let y = tile_load::<4>(v, 0);
    let x = tile_cholesky_solve(l, y);
}

// Named consts the macro cannot compare: rustc does (TM is 16, KB is 4).
#[wp::kernel]
fn consts(a: Array<f32, 2>, v: Array<f32>) {
    let l = tile_load::<TM, TM>(a, (0, 0));
    let y = tile_load::<KB>(v, 0);
    let x = tile_cholesky_solve(l, y);
}

fn main() {}

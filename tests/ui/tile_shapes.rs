use warp_lang as wp;
use wp::prelude::*;

const TM: usize = 16;
const TK: usize = 8;
const KB: usize = 4;

// Tile shape errors the macro decides, each at its call.
#[wp::kernel]
fn inner_dims(a: Array<f32, 2>, c: Array<f32, 2>) {
    let x = tile_load::<16, 8>(a, (0, 0));
    let y = tile_load::<4, 16>(a, (0, 0));
    let p = tile_matmul(x, y);
}

#[wp::kernel]
fn store_rank(a: Array<f32, 2>, v: Array<f32>) {
    let x = tile_load::<16, 8>(a, (0, 0));
    tile_store(v, x, 0);
}

#[wp::kernel]
fn store_elem(a: Array<f32, 2>, d: Array<f64, 2>) {
    let x = tile_load::<16, 8>(a, (0, 0));
    tile_store(d, x, (0, 0));
}

#[wp::kernel]
fn add_shapes(a: Array<f32, 2>) {
    let x = tile_load::<16, 8>(a, (0, 0));
    let s = tile_load::<8, 8>(a, (0, 0));
    let q = x + s;
}

#[wp::kernel]
fn annotation(a: Array<f32, 2>) {
    let r: Tile<f32, 16, 4> = tile_load(a, (16, 8), (0, 0));
}

#[wp::kernel]
fn no_shape(a: Array<f32, 2>) {
    let (i, j) = tid();
    let u = tile_load(a, (i as i32, j as i32));
}

#[wp::kernel]
fn zero_dim() {
    let w = tile_zeros::<f32, 0>();
}

#[wp::kernel]
fn rank5(a: Array<f32, 2>) {
    let z = tile_zeros::<f32, 2, 2, 2, 2, 2>();
}

// Named consts the macro cannot compare: rustc compares them (TK is 8, KB is 4).
#[wp::kernel]
fn consts(a: Array<f32, 2>, c: Array<f32, 2>) {
    let x = tile_load::<TM, TK>(a, (0, 0));
    let y = tile_load::<KB, TM>(a, (0, 0));
    let p = tile_matmul(x, y);
    tile_store(c, p, (0, 0));
}

#[wp::kernel]
fn tile_param(t: Tile<f32, 16>) {}

// f16 products accumulate in f32: an f16 accumulator, or operands of two element types, are
// refused.
#[wp::kernel]
fn f16_into_f16(a: Array<f16, 2>) {
    let x = tile_load::<16, 16>(a, (0, 0));
    let mut acc = tile_zeros::<f16, 16, 16>();
    tile_matmul(x, x, &mut acc);
}

#[wp::kernel]
fn mixed_elems(a: Array<f16, 2>, b: Array<f32, 2>) {
    let x = tile_load::<16, 16>(a, (0, 0));
    let y = tile_load::<16, 16>(b, (0, 0));
    let p = tile_matmul(x, y);
}

fn main() {}

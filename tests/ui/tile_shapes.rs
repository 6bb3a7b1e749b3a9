use warp_lang as wp;
use wp::prelude::*;

const TM: usize = 16;
const TK: usize = 8;
const KB: usize = 4;

// Tile shape errors the macro decides, each at its call: a matmul's inner dimensions, a store
// into an array of another rank or element, an operator on tiles of different shapes, a shape
// annotation that differs from the made tile's, a load without a shape, a tile parameter.
#[wp::kernel]
fn k(a: Array<f32, 2>, v: Array<f32>, d: Array<f64, 2>) {
    let (i, j) = tid();
    let x = tile_load::<16, 8>(a, (0, 0));
    let y = tile_load::<4, 16>(a, (0, 0));
    let p = tile_matmul(x, y);
    tile_store(v, x, 0);
    tile_store(d, x, (0, 0));
    let s = tile_load::<8, 8>(a, (0, 0));
    let q = x + s;
    let r: Tile<f32, 16, 4> = tile_load(a, (0, 0));
    let u = tile_load(a, (i as i32, j as i32));
    let w = tile_zeros::<f32, 0>();
    let z = tile_load::<16, 16, 16>(a, (0, 0));
}

// Named consts the macro cannot compare: rustc compares them (TK is 8, KB is 4).
#[wp::kernel]
fn k_consts(a: Array<f32, 2>, c: Array<f32, 2>) {
    let x = tile_load::<TM, TK>(a, (0, 0));
    let y = tile_load::<KB, TM>(a, (0, 0));
    let p = tile_matmul(x, y);
    tile_store(c, p, (0, 0));
}

#[wp::kernel]
fn k_param(t: Tile<f32, 16>) {}

fn main() {}

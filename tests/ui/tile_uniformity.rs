use warp_lang as wp;
use wp::prelude::*;

// Tile operations are block-cooperative: under control flow that depends on the thread, or
// with an offset that does, they are errors at the call.
#[wp::kernel]
fn divergent(a: Array<f32>, out: Array<f32>) {
    if lane() < 4 {
        let t = tile_load::<32>(a, 0);
        tile_store(out, t, 0);
    }
}

#[wp::kernel]
fn varying_offset(a: Array<f32>) {
    let u = tile_load::<32>(a, lane() as i32);
}

// A scalar that varies by thread is no tile_map constant nor a tile operator's operand: the
// block computes the tile once.
#[wp::kernel]
fn varying_map_constant(a: Array<f32>, out: Array<f32>) {
    let t = tile_load::<32>(a, 0);
    let u = tile_map(add, t, lane() as f32);
    tile_store(out, u, 0);
}

#[wp::kernel]
fn varying_scalar_operand(a: Array<f32>, out: Array<f32>) {
    let t = tile_load::<32>(a, 0);
    let s = lane() as f32 * 0.5;
    let u = t * s;
    tile_store(out, u, 0);
}

// `tile(x)` needs its width: the block size.
#[wp::kernel]
fn no_width(a: Array<f32>) {
    let w = tile(a[tid()]);
}

#[wp::kernel(block_dim = 64)]
fn other_width(a: Array<f32>) {
    let w = tile::<32>(a[tid()]);
}

// Funcs cannot use tiles yet.
#[wp::func]
fn f(a: Array<f32>) -> f32 {
    let t = tile_load::<8>(a, 0);
    1.0
}

fn main() {}

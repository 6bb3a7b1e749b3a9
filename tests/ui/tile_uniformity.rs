use warp_lang as wp;
use wp::prelude::*;

// Tile operations are block-cooperative: under control flow that depends on the thread, or
// with an offset that does, they are errors at the call; `tile(x)` needs its width; funcs
// cannot use tiles yet.
#[wp::kernel]
fn k(a: Array<f32>, out: Array<f32>) {
    let b = tid();
    if lane() < 4 {
        let t = tile_load::<32>(a, 0);
        tile_store(out, t, 0);
    }
    let u = tile_load::<32>(a, lane() as i32);
    let w = tile(a[b]);
}

#[wp::func]
fn f(a: Array<f32>) -> f32 {
    let t = tile_load::<8>(a, 0);
    1.0
}

fn main() {}

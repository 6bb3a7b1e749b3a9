use warp_lang as wp;
use wp::prelude::*;

// glam has no cross product on unsigned vectors: the checker says so at the call.
#[wp::kernel]
fn k(a: Array<UVec3>, b: Array<IVec3>) {
    let i = tid();
    let c = cross(a[i], a[i]);
    let d = cross(b[i], b[i]);
}

fn main() {}

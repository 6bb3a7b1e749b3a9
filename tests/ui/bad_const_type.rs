use warp_lang as wp;
use wp::prelude::*;

const ROT: Mat3 = Mat3::IDENTITY;

#[wp::kernel]
fn uses_a_matrix_const(v: Array<Vec3>) {
    let i = tid();
    // A const of a type kernels cannot read (yet).
    v[i] = ROT * v[i];
}

fn main() {}

use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn residual(a: Bsr<Mat3>, x: Array<Vec3>, r: Array<Vec3>) {
    let i = tid();
    let mut s = Vec3::ZERO;
    for k in bsr_row(a, i as i32) {
        s += bsr_block(a, k) * x[bsr_col(a, k)];
    }
    r[i] = s;
}

// A row is iterated where it is made; a block has the matrix's block type; the structure
// queries take a matrix, not its arrays.
#[wp::kernel]
fn misuse(a: Bsr<Mat3>, x: Array<Vec3>, out: Array<i32>) {
    let i = tid();
    let q = bsr_row(a, 0);
    let b: Mat2 = bsr_block(a, 0);
    bsr_set_block(a, 0, x[i]);
    out[i] = bsr_nnz(x);
}

// Its adds are not ordered in a deterministic kernel.
#[wp::kernel(deterministic)]
fn assemble(a: Bsr<Mat3>) {
    bsr_add_block(a, tid() as i32, Mat3::IDENTITY);
}

// A matrix holds blocks, not vectors.
#[wp::kernel]
fn bad_block(a: Bsr<Vec3>) {}

fn main() {}

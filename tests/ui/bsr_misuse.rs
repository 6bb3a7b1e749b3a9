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

// A matrix holds blocks, not vectors.
#[wp::kernel]
fn bad_block(a: Bsr<Vec3>) {}

fn main() -> wp::Result<()> {
    let dev = wp::cpu();
    let rows = wp::Array::from_slice(&[0, 1], &dev)?;
    let vals = wp::Array::from_slice(&[Mat2::IDENTITY; 2], &dev)?;
    let a = wp::sparse::Bsr::from_triplets(2, 2, &rows, &rows, &vals)?;
    let x = wp::Array::<Vec3>::zeros(2, &dev)?;
    // A matrix of Mat2 blocks where the kernel takes Mat3 blocks.
    wp::launch(residual, 2, (&a, &x, &x), &dev)?;
    Ok(())
}

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

fn main() -> wp::Result<()> {
    let dev = wp::cpu();
    let rows = wp::Array::from_slice(&[0, 1], &dev)?;
    let vals = wp::Array::from_slice(&[Mat2::IDENTITY; 2], &dev)?;
    let a = Bsr::from_triplets(2, 2, &rows, &rows, &vals)?;
    let x = wp::Array::<Vec3>::zeros(2, &dev)?;
    // A matrix of Mat2 blocks where the kernel takes Mat3 blocks.
    wp::launch(residual, 2, (&a, &x, &x), &dev)?;
    Ok(())
}

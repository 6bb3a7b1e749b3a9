use warp_lang as wp;
use wp::prelude::*;

// The decompositions return tuples (checked against patterns and annotations); svd3 takes
// 3x3.
#[wp::kernel]
fn k(a: Array<Mat3>, b: Array<Mat2>, out: Array<Vec3>) {
    let i = tid();
    let (u, s, v) = svd3(b[i]);
    let r: Vec3 = svd3(a[i]);
    out[i] = eig3(a[i]).2;
    let (q, d, e) = eig3(a[i]);
    let (u2, s2, v2): (Mat3, Vec3, DMat3) = svd3(a[i]);
    let (x, y) = a[i];
    let (q3, r3) = qr3(svd3(a[i]));
}

fn main() {}

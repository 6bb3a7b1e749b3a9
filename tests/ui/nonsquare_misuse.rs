use warp_lang as wp;
use wp::prelude::*;

// A vector of the wrong length for a matrix's columns, products whose inner dimensions differ,
// a row and a lane past the end, two shapes added, `ddot` of two shapes, `outer` of a literal,
// the scalar constructor with too few entries.
#[wp::kernel]
fn k(a: Array<Mat23>, v: Array<Vec3>, w: Array<Vec2>, m: Mat32, out: Array<f32>) {
    let i = tid();
    let x = a[i] * w[i];
    let y = a[i] * a[i];
    let z = a[i] * Mat2::IDENTITY;
    out[i] = a[i][(2, 0)];
    out[i] = a[i][(0, 3)];
    let s = a[i] + m;
    out[i] = ddot(a[i], m);
    let o = outer(v[i], 1.0);
    let n = Mat23::new(1.0, 2.0);
}

fn main() {}

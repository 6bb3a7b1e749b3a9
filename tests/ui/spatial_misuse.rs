use warp_lang as wp;
use wp::prelude::*;

// A 3-vector where a spatial vector is wanted, the wrong arity, a lane past 5, a product the
// types do not have, and a matrix where a transform is wanted.
#[wp::kernel]
fn k(a: Array<SpatialVector>, v: Array<Vec3>, m: SpatialMatrix, out: Array<f32>) {
    let i = tid();
    out[i] = spatial_dot(a[i], v[i]);
    out[i] = spatial_dot(a[i]);
    let w = spatial_vector(v[i], v[i], v[i]);
    out[i] = a[i][6];
    let x = a[i] * m;
    let y = transform_twist(m, a[i]);
}

fn main() {}

use warp_lang as wp;
use wp::prelude::*;

// A transform does not multiply a vector (Warp neither: point or direction is the caller's
// choice), has no field but `p` and `q`, and DTransform::new wants f64 parts.
#[wp::kernel]
fn k(t: Array<Transform>, v: Array<Vec3>, out: Array<Vec3>) {
    let i = tid();
    out[i] = t[i] * v[i];
    out[i] = t[i].r;
    let d = DTransform::new(v[i], Quat::IDENTITY);
}

fn main() {}

use warp_lang as wp;
use wp::prelude::*;

#[derive(Clone, Copy, wp::Struct)]
#[repr(C)]
struct Frame {
    m: Mat3,
}

// Literal lanes out of range (past the end, negative, a matrix's row and a spatial vector's
// lane), a glam matrix's single index (glam's column or Warp's row: neither is assumed), too
// many indices, a float index, bases without lanes, and a struct field's matrix entry (its
// type is rustc's to see).
#[wp::kernel]
fn k(v: Array<Vec3>, m: Mat3, t: Transform, s: SpatialVector, f: Frame, out: Array<f32>) {
    let i = tid();
    out[i] = v[i][3];
    out[i] = v[i][-1];
    out[i] = m[(3, 0)];
    out[i] = s[6];
    let c = m[i];
    out[i] = m[(0, 1, 2)];
    out[i] = v[i][(0, 1)];
    out[i] = v[i][out[i]];
    out[i] = t[i];
    out[i] = out[i][0];
    out[i] = f.m[(i, 0)];
}

fn main() {}

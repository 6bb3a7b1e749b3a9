use warp_lang as wp;
use wp::prelude::*;

const ROT: Mat3 = Mat3::IDENTITY;
const lower_case_is_a_variable: f32 = 1.0;

#[wp::kernel]
fn uses_consts(v: Array<Vec3>) {
    let i = tid();
    // A const of a type kernels cannot read.
    v[i] = ROT * v[i];
    // Not SCREAMING_CASE: taken for a missing variable.
    v[i] = v[i] * lower_case_is_a_variable;
}

fn main() {}

use warp_lang as wp;
use wp::prelude::*;

// One parameter more than a kernel takes (`MAX_PARAMS`, 32).
#[wp::kernel]
fn too_many(
    out: Array<f32>,
    a0: f32,
    a1: f32,
    a2: f32,
    a3: f32,
    a4: f32,
    a5: f32,
    a6: f32,
    a7: f32,
    a8: f32,
    a9: f32,
    a10: f32,
    a11: f32,
    a12: f32,
    a13: f32,
    a14: f32,
    a15: f32,
    a16: f32,
    a17: f32,
    a18: f32,
    a19: f32,
    a20: f32,
    a21: f32,
    a22: f32,
    a23: f32,
    a24: f32,
    a25: f32,
    a26: f32,
    a27: f32,
    a28: f32,
    a29: f32,
    a30: f32,
    a31: f32,
) {
    out[tid()] = a0 + a31;
}

fn main() {}

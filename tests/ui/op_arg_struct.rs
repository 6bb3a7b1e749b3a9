// A kernel that takes a struct cannot become a kernel op: its parameters do not cross into a
// framework (wrap it in an Op::computation, which builds the struct inside its body).
use warp_lang as wp;
use warp_runtime::ops::Op;
use wp::prelude::*;

#[derive(Clone, Copy, wp::Struct)]
#[repr(C)]
struct Params {
    scale: f32,
}

#[wp::kernel]
fn scaled(p: Params, x: Array<f32>, y: Array<f32>) {
    let i = tid();
    y[i] = p.scale * x[i];
}

fn main() {
    let _ = Op::kernel("scaled", scaled).outputs(["y"]).build();
}

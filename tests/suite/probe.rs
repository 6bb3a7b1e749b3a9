use warp_lang as wp;
use wp::prelude::*;

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
pub struct P {
    g: Vec3,
    n: i32,
}

#[wp::kernel]
fn probe_loop_named(p: P, out: Array<i32>) {
    let mut s = 0;
    for j in 0..p.n {
        s += j;
    }
    out[0] = s;
}

#[wp::kernel]
fn probe_scale(p: P, v: Array<Vec3>) {
    let mut g = p.g;
    g *= 2.0;
    v[0] = g;
}

#[wp::kernel]
fn probe_scale2(p: P, v: Array<Vec3>) {
    v[0] = p.g * 2.0;
}

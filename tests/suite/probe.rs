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

#[wp::func]
fn sq(x: f32) -> f32 {
    x * x
}

#[wp::func]
fn is_pos(x: f32) -> bool {
    x > 0.0
}

#[wp::func]
fn twice64(x: f64) -> f64 {
    x * 2.0
}

#[wp::func]
fn bump(mut x: i32) -> i32 {
    x += 1;
    x * 2
}

#[wp::kernel]
fn probe_b(a: Array<f32>) {
    let i = wp::tid();
    a[i] = sq(a[i]).min(1.0);
    a[i] = wp::min(a[i], 0.5);
}

#[wp::kernel]
fn probe_c(a: Array<f32>, mut n: i32, out: Array<i32>) {
    let i = tid();
    n += bump(n);
    if is_pos(a[i]) && n > 0 {
        out[i] = n;
    }
}

#[wp::kernel]
fn probe_h(out: Array<Vec3>, x: f32) {
    let v: Vec3 = Vec3::ZERO;
    let a: f32 = 1;
    out[0] = v + Vec3::splat(a);
    let idx = x as usize;
    out[idx] = v;
}

#[wp::kernel]
fn probe_j(c: bool, x: f64, out: Array<f64>) {
    let y = if c { twice64(x) } else { 0.5 };
    out[0] = y;
}

#[wp::kernel]
fn probe_j2(c: bool, x: f64, out: Array<f64>) {
    let y = if c { 0.5 } else { twice64(x) };
    out[0] = y;
}

#[wp::kernel]
fn probe_f(out: Array<UVec2>) {
    out[0] = UVec2::ZERO - UVec2::ONE;
}

#[wp::kernel]
fn probe_m(x: f64, out: Array<f64>) {
    out[0] = max(twice64(x), 0.5);
    let y = twice64(x);
    let z = y * 2.0 + 1;
    out[1] = z;
}

use warp_lang as wp;
use wp::prelude::*;

#[derive(Clone, Copy, wp::Struct)]
#[repr(C)]
struct Particle {
    pos: Vec3,
    mass: f32,
}

// Refused by the macro, at the literal.
#[wp::kernel]
fn refused(xs: Array<Vec3>, out: Array<Particle>) {
    let i = tid();
    let a = Particle { pos: xs[i], .. };
    let b = Vec3 { x: 1.0, y: 2.0, z: 3.0 };
    let c = Particle { 0: xs[i], mass: 1.0 };
    let d = Particle { pos: xs[i], mass: 1.0, ..xs[i].x };
    let e = Particle { pos: xs[i], mass: xs };
}

// Refused by rustc, at the field: missing, unknown, repeated, mistyped.
#[wp::kernel]
fn missing_field(xs: Array<Vec3>, out: Array<Particle>) {
    let i = tid();
    out[i] = Particle { pos: xs[i] };
}

#[wp::kernel]
fn unknown_field(xs: Array<Vec3>, out: Array<Particle>) {
    let i = tid();
    out[i] = Particle {
        pos: xs[i],
        mass: 1.0,
        charge: 2.0,
    };
}

#[wp::func]
fn repeated_field(p: Vec3) -> Particle {
    Particle {
        pos: p,
        mass: 1.0,
        mass: 2.0,
    }
}

#[wp::func]
fn mistyped_field(p: Vec3) -> Particle {
    Particle { pos: p.x, mass: 1.0 }
}

// An array field indexed with two indices at once.
#[derive(Clone, Copy, wp::Struct)]
#[repr(C)]
struct Grid {
    cells: [[f32; 2]; 2],
}

#[wp::kernel]
fn two_indices(g: Grid, out: Array<f32>) {
    out[0] = g.cells[(0, 1)];
}

fn main() {}

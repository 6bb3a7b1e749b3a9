//! `#[derive(wp::Struct)]` structs as kernel parameters and as array elements: field reads,
//! field writes, compound assignment on fields (nested ones included), whole-element copies.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    struct_parameter,
    struct_array_fields,
    struct_local_copy,
    struct_in_func,
    nested_structs,
);

/// A struct whose field is another user struct (defined after it here: the generated CUDA
/// orders definitions by dependency, not by source order).
#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Body {
    state: State,
    mass: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct State {
    pos: Vec3,
    vel: Vec3,
}

#[wp::kernel]
fn k_nested(bodies: Array<Body>, push: State, dt: f32) {
    let i = tid();
    let mut b = bodies[i];
    b.state.vel += push.vel / b.mass;
    b.state.pos += b.state.vel * dt + push.pos;
    bodies[i] = b;
}

fn nested_structs(dev: &wp::Device) {
    // The CUDA unit defines State (once) before Body, which has a State field.
    let src = wp::cuda_source::assemble(<k_nested as wp::Kernel>::info()).text;
    let (state, body) = (src.find("struct State {"), src.find("struct Body {"));
    assert!(state.is_some() && state < body, "{src}");
    assert_eq!(src.matches("struct State {").count(), 1);
    let host: Vec<Body> = (0..5)
        .map(|k| Body {
            state: State {
                pos: Vec3::splat(k as f32),
                vel: Vec3::new(1.0, 0.0, -(k as f32)),
            },
            mass: 1.0 + k as f32,
        })
        .collect();
    let bodies = arr(&host, dev);
    let push = State {
        pos: Vec3::new(0.5, 0.25, 0.0),
        vel: Vec3::new(0.0, 2.0, 0.0),
    };
    wp::launch(k_nested, 5, (&bodies, push, 0.5), dev).unwrap();
    let want: Vec<Body> = host
        .iter()
        .map(|b| {
            let mut b = *b;
            b.state.vel += push.vel / b.mass;
            b.state.pos += b.state.vel * 0.5 + push.pos;
            b
        })
        .collect();
    // Exact on the CPU; on CUDA `vel * dt + pos` may contract into an FMA (one rounding
    // fewer): within 2 ulps of values below 8.
    let got = bodies.to_vec().unwrap();
    for (g, w) in got.iter().zip(&want) {
        assert_eq!((g.state.vel, g.mass), (w.state.vel, w.mass));
        assert!(g.state.pos.abs_diff_eq(w.state.pos, 2e-6), "{g:?} vs {w:?}");
        if dev.is_cpu() {
            assert_eq!(g.state.pos, w.state.pos);
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Params {
    damping: f64,
    gravity: Vec3,
    dt: f32,
    steps: i32,
    flags: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Particle {
    pos: Vec3,
    vel: Vec3,
    mass: f32,
    id: i32,
}

#[wp::kernel]
fn k_params(p: Params, out: Array<f64>, v: Array<Vec3>) {
    out[0] = p.dt as f64;
    out[1] = p.steps as f64;
    out[2] = p.damping;
    out[3] = p.gravity.z as f64;
    out[4] = p.flags as f64;
    let mut g = p.gravity;
    // `for _ in 0..p.steps` (a bound of a type the macro cannot see) does not compile: see
    // the report. The cast gives the bound a known type.
    for _ in 0..(p.steps as i32) {
        g *= 2.0;
    }
    v[0] = g;
}

fn struct_parameter(dev: &wp::Device) {
    let p = Params {
        gravity: vec3(0.0, 0.0, -9.81),
        dt: 0.01,
        steps: 3,
        damping: 0.1,
        flags: 0xABCD,
    };
    let (out, v) = (zeros::<f64, 1>(5, dev), zeros::<Vec3, 1>(1, dev));
    wp::launch(k_params, 1, (p, &out, &v), dev).unwrap();
    assert_eq!(
        host(&out),
        vec![
            f64::from(0.01f32),
            3.0,
            0.1,
            f64::from(-9.81f32),
            f64::from(0xABCDu32)
        ]
    );
    assert_eq!(host(&v), vec![p.gravity * 8.0]);
}

#[wp::kernel]
fn k_particles(ps: Array<Particle>, p: Params, ids: Array<i32>, speed: Array<f32>) {
    let i = tid();
    ids[i] = ps[i].id;
    speed[i] = ps[i].vel.y;
    ps[i].vel += p.gravity * p.dt;
    ps[i].pos += ps[i].vel * p.dt;
    ps[i].mass = ps[i].mass * 2.0;
    ps[i].id += 1000;
    ps[i].pos.x -= 1.0;
    ps[i].vel.z = 0.5;
}

fn particles() -> Vec<Particle> {
    (0..5)
        .map(|k| Particle {
            pos: vec3(k as f32, 0.5 * k as f32, 1.0),
            vel: vec3(1.0, -(k as f32), 0.25),
            mass: 1.0 + k as f32,
            id: k * 10,
        })
        .collect()
}

fn struct_array_fields(dev: &wp::Device) {
    let p = Params {
        gravity: vec3(0.0, -10.0, 0.0),
        dt: 0.5,
        steps: 0,
        damping: 0.0,
        flags: 0,
    };
    let ps0 = particles();
    let ps = arr(&ps0, dev);
    let (ids, speed) = (zeros::<i32, 1>(5, dev), zeros::<f32, 1>(5, dev));
    wp::launch(k_particles, 5, (&ps, p, &ids, &speed), dev).unwrap();
    assert_eq!(host(&ids), ps0.iter().map(|q| q.id).collect::<Vec<_>>());
    assert_eq!(
        host(&speed),
        ps0.iter().map(|q| q.vel.y).collect::<Vec<_>>()
    );
    let want: Vec<Particle> = ps0
        .iter()
        .map(|q| {
            let mut q = *q;
            q.vel += p.gravity * p.dt;
            q.pos += q.vel * p.dt;
            q.mass *= 2.0;
            q.id += 1000;
            q.pos.x -= 1.0;
            q.vel.z = 0.5;
            q
        })
        .collect();
    // Multiples of 0.25 throughout: exact with or without FMA.
    assert_eq!(host(&ps), want);
}

#[wp::kernel]
fn k_struct_copy(src: Array<Particle>, dst: Array<Particle>) {
    let i = tid();
    let mut q = src[i];
    q.id = q.id * 2 + 1;
    q.pos.y += 1.0;
    q.mass -= 0.5;
    dst[i] = q;
    let r = src[i];
    dst[i].vel = r.vel * 3.0;
}

fn struct_local_copy(dev: &wp::Device) {
    let ps0 = particles();
    let (src, dst) = (arr(&ps0, dev), zeros::<Particle, 1>(5, dev));
    wp::launch(k_struct_copy, 5, (&src, &dst), dev).unwrap();
    let want: Vec<Particle> = ps0
        .iter()
        .map(|q| {
            let mut q = *q;
            q.id = q.id * 2 + 1;
            q.pos.y += 1.0;
            q.mass -= 0.5;
            q.vel *= 3.0;
            q
        })
        .collect();
    assert_eq!(host(&dst), want);
    assert_eq!(host(&src), ps0, "the source is untouched");
}

#[wp::func]
fn momentum(q: Particle) -> Vec3 {
    q.vel * q.mass
}

#[wp::func]
fn heavier(q: Particle, p: Params) -> f32 {
    q.mass * p.dt
}

#[wp::kernel]
fn k_struct_func(ps: Array<Particle>, p: Params, out: Array<Vec3>, m: Array<f32>) {
    let i = tid();
    out[i] = momentum(ps[i]);
    m[i] = heavier(ps[i], p);
}

fn struct_in_func(dev: &wp::Device) {
    let ps0 = particles();
    let p = Params {
        gravity: Vec3::ZERO,
        dt: 0.25,
        steps: 1,
        damping: 1.0,
        flags: 0,
    };
    let (out, m) = (zeros::<Vec3, 1>(5, dev), zeros::<f32, 1>(5, dev));
    wp::launch(k_struct_func, 5, (&arr(&ps0, dev), p, &out, &m), dev).unwrap();
    assert_eq!(
        host(&out),
        ps0.iter().map(|q| q.vel * q.mass).collect::<Vec<_>>()
    );
    assert_eq!(
        host(&m),
        ps0.iter().map(|q| q.mass * 0.25).collect::<Vec<_>>()
    );
}

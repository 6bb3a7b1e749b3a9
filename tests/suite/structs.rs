//! `#[derive(wp::Struct)]` structs as kernel parameters and as array elements: field reads,
//! field writes, compound assignment on fields (nested ones included), whole-element copies;
//! struct literals (shorthand, nested, `..base`, through funcs); fixed-size array fields read
//! and written at constant and dynamic indices; gradients through both.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    struct_parameter,
    struct_array_fields,
    struct_local_copy,
    struct_in_func,
    nested_structs,
    struct_literals,
    struct_literal_only_in_kernel,
    array_fields,
    array_field_index_faults,
    struct_literal_gradient,
    array_field_gradient,
    forward_mode_refuses_structs,
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

// ---- struct literals ----

#[wp::func]
fn at_rest(pos: Vec3, mass: f32) -> Particle {
    Particle {
        pos,
        vel: Vec3::ZERO,
        mass,
        id: -1,
    }
}

#[wp::func]
fn kick(q: Particle, dv: Vec3) -> Particle {
    Particle {
        vel: q.vel + dv,
        ..q
    }
}

#[wp::kernel]
fn k_literals(xs: Array<Vec3>, out: Array<Particle>, bodies: Array<Body>, rest: Array<Particle>) {
    let i = tid();
    let pos = xs[i];
    let vel = pos * 2.0;
    let mass = 1.5;
    // Shorthand, an unsuffixed literal typed by its field, an expression.
    let p = Particle {
        pos,
        vel,
        mass,
        id: i as i32 * 3,
    };
    // Stored whole, then updated from another literal with `..base`.
    out[i] = p;
    out[i] = Particle {
        mass: p.mass + 0.25,
        ..kick(p, Vec3::new(0.0, 1.0, 0.0))
    };
    // Nested literals, the inner one in a field of the outer.
    bodies[i] = Body {
        state: State {
            pos: p.pos,
            vel: Vec3::X,
        },
        mass: 2.0,
    };
    // A literal returned by a func.
    rest[i] = at_rest(pos, 4.0);
}

fn struct_literals(dev: &wp::Device) {
    let xs_h: Vec<Vec3> = (0..4).map(|k| vec3(k as f32, 0.5, -(k as f32))).collect();
    let out = zeros::<Particle, 1>(4, dev);
    let bodies = zeros::<Body, 1>(4, dev);
    let rest = zeros::<Particle, 1>(4, dev);
    wp::launch(k_literals, 4, (&arr(&xs_h, dev), &out, &bodies, &rest), dev).unwrap();
    // Sums and doubles of multiples of 0.5: exact on both backends.
    let want: Vec<Particle> = xs_h
        .iter()
        .enumerate()
        .map(|(k, &pos)| Particle {
            pos,
            vel: pos * 2.0 + Vec3::Y,
            mass: 1.75,
            id: k as i32 * 3,
        })
        .collect();
    assert_eq!(host(&out), want);
    let want: Vec<Body> = xs_h
        .iter()
        .map(|&pos| Body {
            state: State { pos, vel: Vec3::X },
            mass: 2.0,
        })
        .collect();
    assert_eq!(host(&bodies), want);
    let want: Vec<Particle> = xs_h
        .iter()
        .map(|&pos| Particle {
            pos,
            vel: Vec3::ZERO,
            mass: 4.0,
            id: -1,
        })
        .collect();
    assert_eq!(host(&rest), want);
}

/// A kernel that names a struct only in a literal (none of its parameters has the type):
/// its CUDA unit still defines the struct.
#[wp::kernel]
fn k_literal_only(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    let s = State {
        pos: Vec3::splat(x[i]),
        vel: Vec3::new(1.0, 2.0, 3.0),
    };
    let t = State {
        vel: s.vel * 2.0,
        ..s
    };
    out[i] = t.pos.x + t.vel.z;
}

fn struct_literal_only_in_kernel(dev: &wp::Device) {
    let src = wp::cuda_source::assemble(<k_literal_only as wp::Kernel>::info()).text;
    assert_eq!(src.matches("struct State {").count(), 1, "{src}");
    let out = zeros::<f32, 1>(3, dev);
    wp::launch(
        k_literal_only,
        3,
        (&arr(&[1.0f32, -2.0, 0.5], dev), &out),
        dev,
    )
    .unwrap();
    assert_eq!(host(&out), vec![7.0, 4.0, 6.5]);
}

// ---- array fields ----

/// The length of `Cloth::rest`: a module const, whose value the CUDA definition gets at
/// assembly.
const NREST: usize = 3;

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Cloth {
    weights: [f32; 4],
    corners: [Vec3; 2],
    rest: [f32; NREST],
    grid: [[i32; 2]; 2],
    frame: [Mat3; 1],
}

fn cloth(k: usize) -> Cloth {
    let f = k as f32;
    Cloth {
        weights: [f, f + 1.0, f + 2.0, f + 3.0],
        corners: [vec3(f, 0.0, 1.0), vec3(-f, 2.0, 0.5)],
        rest: [0.5, 1.0, 1.5],
        grid: [[k as i32, 1], [2, 3]],
        frame: [Mat3::from_cols(vec3(1.0, f, 0.0), Vec3::Y, Vec3::Z)],
    }
}

#[wp::kernel]
fn k_array_fields(cs: Array<Cloth>, c: Cloth, j: Array<i32>, out: Array<f32>) {
    let i = tid();
    let k = j[i];
    // Reads: a parameter's and an array element's fields, at constant and dynamic indices.
    out[i] = c.weights[k] + cs[i].weights[3] + cs[i].corners[1].y + cs[i].rest[k % 3];
    let mut s = cs[i];
    let mut total = 0.0;
    for m in 0..s.weights.len() {
        total += s.weights[m];
    }
    // Writes: a local's element (whole, compound, a lane of a vector element, nested).
    s.weights[k] = total;
    s.rest[2] *= 4.0;
    s.corners[0].z = s.frame[0].x_axis.y;
    s.grid[1][k % 2] += 10;
    cs[i] = s;
    // Writes inside an array element.
    cs[i].corners[1] = c.corners[0];
    cs[i].weights[0] -= 0.5;
    // A literal with array fields.
    let mut g = Cloth {
        weights: [1.0; 4],
        corners: [Vec3::X, c.corners[1]],
        rest: c.rest,
        grid: [[k, 0], [0, k]],
        frame: s.frame,
    };
    g.weights[k] = -1.0;
    out[i] += g.weights[0] + g.weights[1] + g.corners[1].x + g.grid[1][1] as f32;
}

fn array_fields(dev: &wp::Device) {
    // The C++ definition has the const length's value.
    let src = wp::cuda_source::assemble(<k_array_fields as wp::Kernel>::info()).text;
    assert!(src.contains("wp::local_array_t<wp::f32, 3> rest;"), "{src}");
    let cs_h: Vec<Cloth> = (0..4).map(cloth).collect();
    let c = cloth(7);
    let j_h = [0i32, 3, 1, 2];
    let (cs, out) = (arr(&cs_h, dev), zeros::<f32, 1>(4, dev));
    wp::launch(k_array_fields, 4, (&cs, c, &arr(&j_h, dev), &out), dev).unwrap();
    // Small integers and halves: every sum is exact on both backends.
    let mut want_out = Vec::new();
    let want: Vec<Cloth> = cs_h
        .iter()
        .zip(j_h)
        .map(|(q, k)| {
            let k = k as usize;
            let mut o = c.weights[k] + q.weights[3] + q.corners[1].y + q.rest[k % 3];
            let mut s = *q;
            let total: f32 = s.weights.iter().sum();
            s.weights[k] = total;
            s.rest[2] *= 4.0;
            s.corners[0].z = s.frame[0].x_axis.y;
            s.grid[1][k % 2] += 10;
            s.corners[1] = c.corners[0];
            s.weights[0] -= 0.5;
            let mut gw = [1.0f32; 4];
            gw[k] = -1.0;
            o += gw[0] + gw[1] + c.corners[1].x + k as f32;
            want_out.push(o);
            s
        })
        .collect();
    assert_eq!(host(&cs), want);
    assert_eq!(host(&out), want_out);
}

#[wp::kernel]
fn k_field_oob(cs: Array<Cloth>, j: Array<i32>, out: Array<f32>) {
    let i = tid();
    out[i] = cs[i].weights[j[i]];
}

fn array_field_index_faults(dev: &wp::Device) {
    let cs = arr(&[cloth(0), cloth(1)], dev);
    let out = zeros::<f32, 1>(2, dev);
    let err = wp::launch(k_field_oob, 2, (&cs, &arr(&[1i32, 4], dev), &out), dev).unwrap_err();
    let wp::Error::Fault(f) = &err else {
        panic!("not a fault: {err}");
    };
    let src = include_str!("structs.rs");
    let line = 1 + src
        .lines()
        .position(|l| l.trim() == "out[i] = cs[i].weights[j[i]];")
        .unwrap() as u32;
    assert_eq!(f.kernel, "k_field_oob");
    assert_eq!(
        f.kind,
        wp::FaultKind::LocalIndex {
            index: 4,
            len: 4,
            line
        }
    );
}

// ---- gradients ----

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Bead {
    pos: DVec3,
    w: [f64; 3],
    mass: f64,
}

#[wp::func]
fn bead_energy(b: Bead) -> f64 {
    b.mass * b.pos.length_squared() + b.w[0] * b.w[2]
}

/// A literal built from differentiable inputs (shorthand, an array field, `..base`, passed to
/// a func and stored) and a loss from its fields.
#[wp::kernel]
fn k_bead_loss(x: Array<f64>, beads: Array<Bead>, loss: Array<f64>) {
    let i = tid();
    let pos = DVec3::new(x[3 * i], x[3 * i + 1] * x[3 * i], x[3 * i + 2]);
    let mass = x[3 * i + 1];
    let b = Bead {
        pos,
        w: [sin(mass), mass * 2.0, pos.z],
        mass,
    };
    let c = Bead {
        mass: b.mass * b.w[1],
        ..b
    };
    beads[i] = c;
    let k = (i % 3) as usize;
    atomic_add(loss, 0, bead_energy(c) + c.w[k] * c.pos.y);
}

fn struct_literal_gradient(dev: &wp::Device) {
    let x = arr(&[0.5f64, -1.25, 2.0, 1.5, 0.75, -0.5], dev)
        .with_grad()
        .unwrap();
    let beads = zeros::<Bead, 1>(2, dev).with_grad().unwrap();
    let loss = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    // f64 central differences with step 1e-6 against the tape: the loss is a smooth
    // polynomial-and-sine of inputs of order 1, so truncation error is ~1e-12 and rounding
    // ~1e-10; the f64 defaults (atol 1e-8, rtol 1e-6) leave room for both.
    let report = wp::gradcheck(
        || wp::launch(k_bead_loss, 2, (&x, &beads, &loss), dev),
        &[&x],
        &[&loss],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    // The struct written whole is the struct as built.
    let b = host(&beads)[1];
    assert_eq!(b.mass, 0.75 * 0.75 * 2.0);
    assert_eq!(b.w, [0.75f64.sin(), 1.5, -0.5]);
}

/// Array fields of struct array elements read at dynamic indices, written, and a loss from
/// them: the gradient lands in the struct array's gradient, field by field.
#[wp::kernel]
fn k_bead_fields(beads: Array<Bead>, j: Array<i32>, out: Array<f64>) {
    let i = tid();
    let k = j[i];
    let mut b = beads[i];
    b.w[k] = b.w[k] * b.mass + b.pos.x;
    let mut s = 0.0f64;
    for m in 0..3 {
        s += b.w[m] * b.w[m];
    }
    out[i] = s + beads[i].w[2] * beads[i].pos.y;
}

fn array_field_gradient(dev: &wp::Device) {
    let beads_h = [
        Bead {
            pos: DVec3::new(0.5, -1.0, 2.0),
            w: [1.0, -0.5, 0.25],
            mass: 2.0,
        },
        Bead {
            pos: DVec3::new(-1.5, 0.75, 0.0),
            w: [0.5, 2.0, -1.0],
            mass: 0.5,
        },
    ];
    let beads = arr(&beads_h, dev).with_grad().unwrap();
    let j = arr(&[1i32, 2], dev);
    let out = zeros::<f64, 1>(2, dev).with_grad().unwrap();
    // Every field is an f64: the struct array's bytes are an `Array<f64>` sharing its
    // gradient, which gradcheck perturbs one scalar at a time. A polynomial of degree 4 in
    // inputs of order 1: the f64 defaults (step 1e-6, atol 1e-8, rtol 1e-6) hold with
    // orders of magnitude to spare.
    let flat = beads.reinterpret::<f64>().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_bead_fields, 2, (&beads, &j, &out), dev),
        &[&flat],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    // One entry by hand: d out[0] / d w[1] of bead 0 (k = 1): 2 (w1 m + x) m.
    let b = beads_h[0];
    let want = 2.0 * (b.w[1] * b.mass + b.pos.x) * b.mass;
    // Bead 0's w[1] is f64 number 4 of the flat array (pos: 0..3, w: 3..6).
    let got = report.analytic[0][4];
    assert!((got - want).abs() <= 1e-12 * want.abs(), "{got} vs {want}");
}

#[wp::kernel]
fn k_bead_jvp(x: Array<f64>, out: Array<f64>) {
    let i = tid();
    let b = Bead {
        pos: DVec3::splat(x[i]),
        w: [x[i]; 3],
        mass: 2.0,
    };
    out[i] = b.mass * b.w[1];
}

/// Forward mode does not follow struct values yet (the macro cannot tell a struct's integer
/// fields from its float ones): a struct built from differentiated values is refused, never a
/// silently zero tangent.
fn forward_mode_refuses_structs(dev: &wp::Device) {
    let x = arr(&[1.0f64, 2.0], dev);
    let out = zeros::<f64, 1>(2, dev);
    let (x_dot, out_dot) = (arr(&[1.0f64, 1.0], dev), zeros::<f64, 1>(2, dev));
    let err = wp::jvp(k_bead_jvp, 2, (&x, &out), (&x_dot, &out_dot), dev).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(
            err,
            wp::Error::NoTangent {
                kernel: "k_bead_jvp",
                ..
            }
        ),
        "{msg}"
    );
    assert!(msg.contains("`Bead`"), "{msg}");
}

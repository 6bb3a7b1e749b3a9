//! Particles falling onto a deforming triangle mesh: a wavy terrain whose points a kernel moves
//! every step (with their velocities), the mesh refit every step, and each particle's contact
//! through `mesh_query_point` (its closest point and the side it is on), pushed out of the
//! surface and its velocity reflected relative to the surface's (`mesh_eval_velocity`).
//!
//! What it reports (error next to run time):
//! 1. a still terrain and elastic contacts (restitution 1): the drift of the total energy
//!    (kinetic + potential) after 1 s against dt; the largest penetration before each
//!    step's push-out, relative to the radius;
//! 2. the moving terrain: the largest penetration against dt, whether any particle ended up
//!    under the surface (the contact's failure mode at large dt: tunnelling through), and the
//!    time per step with the refit.
//!
//! The largest stable dt is where particles stay above the surface.
//!
//! `cargo run --release --example mesh_contact [-- --device cpu|cuda:0 --n 20000]`

mod common;

use clap::Parser;
use rand::Rng as _;
use std::time::Instant;

use warp_lang as wp;
use warp_report::frame::{Frame, Points, TriMesh};
use warp_report::{Run, Sweep};
use wp::prelude::*;

const RADIUS: f32 = 0.01;
const GRAVITY: f32 = -9.81;
/// The side walls' half width (the terrain spans [-1, 1]^2).
const WALL: f32 = 0.95;

/// The terrain's height and its time derivative at rest point `x` (a travelling wave).
#[wp::func]
fn wave(x: Vec3, t: f32, amp: f32, omega: f32) -> Vec2 {
    let phase = 3.0 * x.x + omega * t;
    let c = cos(2.0 * x.y);
    vec2(amp * sin(phase) * c, amp * omega * cos(phase) * c)
}

/// Moves the terrain's points to time `t`, with their velocities.
#[wp::kernel]
fn deform(rest: Array<Vec3>, points: Array<Vec3>, vel: Array<Vec3>, t: f32, amp: f32, omega: f32) {
    let i = tid();
    let r = rest[i];
    let h = wave(r, t, amp, omega);
    points[i] = vec3(r.x, r.y, r.z + h.x);
    vel[i] = vec3(0.0, 0.0, h.y);
}

/// One step of a particle: gravity, then a contact with the mesh within a radius: pushed out
/// along the direction to its closest point (on the side the query's sign says it is), its
/// velocity relative to the surface reflected with restitution `e` when it approaches; then
/// the side walls. The penetration before the push-out goes to `pen` (atomic max).
#[wp::kernel]
fn step(mesh: Mesh, x: Array<Vec3>, v: Array<Vec3>, dt: f32, e: f32, pen: Array<f32>) {
    let i = tid();
    let mut vi = v[i] + vec3(0.0, 0.0, GRAVITY) * dt;
    let mut xi = x[i] + vi * dt;
    let (found, sign, face, u, w) = mesh_query_point(mesh, xi, 4.0 * RADIUS);
    if found {
        let c = mesh_eval_position(mesh, face, u, w);
        let d = length(xi - c);
        // The outward direction: away from the surface on the outside, towards it inside.
        let mut n = mesh_eval_face_normal(mesh, face);
        if d > 1.0e-9 {
            n = (xi - c) * (sign / d);
        }
        let depth = RADIUS - d * sign;
        if depth > 0.0 {
            atomic_max(pen, 0, depth);
            xi = xi + n * depth;
            let vs = mesh_eval_velocity(mesh, face, u, w);
            let vn = dot(vi - vs, n);
            if vn < 0.0 {
                vi = vi - n * ((1.0 + e) * vn);
            }
        }
    }
    // Side walls inside the terrain's edge keep the particles over it (past the edge of an
    // open mesh, "below the surface" would mean nothing).
    if abs(xi.x) > WALL {
        xi.x = clamp(xi.x, -WALL, WALL);
        vi.x = -vi.x * e;
    }
    if abs(xi.y) > WALL {
        xi.y = clamp(xi.y, -WALL, WALL);
        vi.y = -vi.y * e;
    }
    x[i] = xi;
    v[i] = vi;
}

/// The terrain's quads per side.
const TERRAIN: usize = 128;

/// A terrain of `k x k` quads over [-1, 1]^2 at z = 0 (two triangles each, normals up).
fn terrain(k: usize) -> (Vec<Vec3>, Vec<i32>) {
    let mut p = Vec::new();
    for j in 0..=k {
        for i in 0..=k {
            let s = |a: usize| -1.0 + 2.0 * a as f32 / k as f32;
            p.push(Vec3::new(s(i), s(j), 0.0));
        }
    }
    let at = |i: usize, j: usize| (j * (k + 1) + i) as i32;
    let mut ix = Vec::new();
    for j in 0..k {
        for i in 0..k {
            ix.extend_from_slice(&[at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            ix.extend_from_slice(&[at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    (p, ix)
}

/// Particles on a jittered lattice in [-0.8, 0.8]^2 x [0.2, 0.6], at rest.
fn particles(n: usize) -> Vec<Vec3> {
    let side = (n as f64).cbrt().ceil() as usize;
    let mut r = common::rng(3);
    let mut x = Vec::with_capacity(n);
    'outer: for a in 0..side {
        for b in 0..side {
            for c in 0..side {
                if x.len() == n {
                    break 'outer;
                }
                let mut f = |k: usize, lo: f32, hi: f32| {
                    lo + (hi - lo) * (k as f32 + 0.5 + 0.3 * (r.random::<f64>() as f32 - 0.5))
                        / side as f32
                };
                let (px, py) = (f(a, -0.8, 0.8), f(b, -0.8, 0.8));
                let pz = f(c, 0.2, 0.6);
                x.push(Vec3::new(px, py, pz));
            }
        }
    }
    x
}

/// Kinetic plus potential energy per unit mass, summed (f64).
fn energy(x: &[Vec3], v: &[Vec3]) -> f64 {
    x.iter()
        .zip(v)
        .map(|(p, u)| 0.5 * u.as_dvec3().length_squared() - GRAVITY as f64 * p.z as f64)
        .sum()
}

struct Outcome {
    drift: f64,
    penetration: f64,
    below: usize,
    ms_per_step: f64,
    finite: bool,
    /// The end state, for the frame: positions, velocities, the terrain's points.
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    terrain: Vec<Vec3>,
}

/// Runs 1 s with step `dt`: the terrain moving (`amp` > 0) or still, restitution `e`.
///
/// With a recorder, about 100 frames of the run go to it (the step time then includes them).
fn simulate(
    dev: &wp::Device,
    n: usize,
    dt: f32,
    amp: f32,
    e: f32,
    mut rec: Option<&mut common::record::Recorder>,
) -> wp::Result<Outcome> {
    let (rest_h, ix) = terrain(TERRAIN);
    let rest = wp::Array::from_slice(&rest_h, dev)?;
    let pts = wp::Array::from_slice(&rest_h, dev)?;
    let vel = wp::Array::<Vec3>::zeros(rest_h.len(), dev)?;
    let omega = 4.0f32;
    wp::launch(
        deform,
        rest_h.len(),
        (&rest, &pts, &vel, 0.0f32, amp, omega),
        dev,
    )?;
    let indices = wp::Array::from_slice(&ix, dev)?;
    let mut mesh = wp::Mesh::new(&pts, &indices, Some(&vel))?;
    let x0 = particles(n);
    let x = wp::Array::from_slice(&x0, dev)?;
    let v = wp::Array::<Vec3>::zeros(n, dev)?;
    let pen = wp::Array::<f32>::zeros(1, dev)?;
    let e0 = energy(&x0, &vec![Vec3::ZERO; n]);
    let steps = (1.0 / dt).round() as usize;
    let every = common::record::every(steps);
    let stride = common::record::stride(n);
    let snap = |rec: &mut common::record::Recorder, s: usize| -> wp::Result<()> {
        let t = s as f64 * dt as f64;
        let title = format!(
            "mesh_contact: {n} particles on the moving terrain at t = {t:.3} s (dt = {dt})"
        );
        let frame = contact_frame(&x.to_vec()?, &v.to_vec()?, &pts.to_vec()?, stride, title);
        rec.frame(s, t, &frame);
        Ok(())
    };
    if let Some(rec) = rec.as_deref_mut() {
        snap(rec, 0)?;
    }
    wp::synchronize()?;
    let t0 = Instant::now();
    for s in 0..steps {
        if amp > 0.0 {
            let t = (s + 1) as f32 * dt;
            wp::launch(
                deform,
                rest_h.len(),
                (&rest, &pts, &vel, t, amp, omega),
                dev,
            )?;
            mesh.refit()?;
        }
        wp::launch(step, n, (&mesh, &x, &v, dt, e, &pen), dev)?;
        if let Some(rec) = rec.as_deref_mut() {
            if (s + 1) % every == 0 || s + 1 == steps {
                snap(rec, s + 1)?;
            }
        }
    }
    wp::synchronize()?;
    let ms_per_step = t0.elapsed().as_secs_f64() * 1e3 / steps as f64;
    let (xs, vs) = (x.to_vec()?, v.to_vec()?);
    let finite = xs.iter().chain(&vs).all(|p| p.is_finite());
    // Under the surface: below the terrain's height at the particle (the still or the final
    // wave), by more than the radius.
    let t_end = steps as f32 * dt;
    let below = xs
        .iter()
        .filter(|p| {
            let phase = 3.0 * p.x + omega * t_end;
            let h = amp * phase.sin() * (2.0 * p.y).cos();
            p.x.abs() < 1.0 && p.y.abs() < 1.0 && p.z < h - RADIUS
        })
        .count();
    Ok(Outcome {
        drift: ((energy(&xs, &vs) - e0) / e0.abs()).abs(),
        penetration: pen.to_vec()?[0] as f64 / RADIUS as f64,
        below,
        ms_per_step,
        finite,
        x: xs,
        v: vs,
        terrain: pts.to_vec()?,
    })
}

/// The particles (one in `stride`) on the terrain, drawn at every 8th point of its grid (512
/// of its 32K triangles: enough for its smooth waves at the picture's scale, and the SVG stays
/// small), coloured by speed.
fn contact_frame(x: &[Vec3], v: &[Vec3], terrain: &[Vec3], stride: usize, title: String) -> Frame {
    let (k, every) = (TERRAIN / 8, 8);
    let at = |i: usize, j: usize| j * (k + 1) + i;
    let mut pts = Vec::new();
    for j in 0..=k {
        for i in 0..=k {
            pts.push(common::p3(terrain[j * every * (TERRAIN + 1) + i * every]));
        }
    }
    let mut tris = Vec::new();
    for j in 0..k {
        for i in 0..k {
            tris.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            tris.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    let pos: Vec<[f64; 3]> = x.iter().step_by(stride).map(|&p| common::p3(p)).collect();
    Frame::new(
        title,
        common::camera(
            [-1.0, -1.0, -0.1],
            [1.0, 1.0, 0.6],
            [0.9, -1.6, 1.1],
            [0.0, 0.0, 1.0],
        ),
    )
    .note(
        "the terrain (drawn at 1/64 of its triangles) is deformed and refit every step; \
         colour: speed",
    )
    .mesh(TriMesh::new(pts, tris).colour([190, 180, 160]))
    .points(Points::new(pos, RADIUS as f64).values(
        "speed (m/s)",
        v.iter().step_by(stride).map(|v| v.length() as f64),
    ))
}

/// Particles falling onto a deforming triangle-mesh terrain: energy drift and penetration
/// against dt, on a still and on a moving terrain.
#[derive(Parser)]
struct Cli {
    /// Particles [default: 50000 on a GPU, 5000 on the CPU]
    #[arg(long, value_name = "PARTICLES", value_parser = common::num::<usize>)]
    n: Option<usize>,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let n = cli.n.unwrap_or(if dev.is_cpu() { 5_000 } else { 50_000 });
    println!("{n} particles (radius {RADIUS}) on a 32K-triangle terrain, 1 s, on {dev}");

    let mut still = Sweep::new(
        format!("still terrain, elastic contacts, on {dev}: |energy drift| after 1 s"),
        "dt (s)",
    )
    .with_extras(&["max penetration / r", "under the surface"])
    // One tick per time step size (the moving terrain's run of each comes with it).
    .progress(5);
    let mut moving = Sweep::new(
        format!("moving terrain (refit every step), inelastic, on {dev}: max penetration / r"),
        "dt (s)",
    )
    .with_extras(&["ms per step", "under the surface"]);
    // A few steps first: the kernels compile (on a GPU) before anything is timed.
    simulate(&dev, 16, 0.25, 0.08, 0.0, None)?;
    let mut last = None;
    for dt in [4e-3f32, 2e-3, 1e-3, 5e-4, 2.5e-4] {
        let steps = (1.0 / dt).round() as u64;
        let o = simulate(&dev, n, dt, 0.0, 1.0, None)?;
        let run = if o.finite {
            Run::stable(steps, o.drift, o.ms_per_step * steps as f64 / 1e3)
        } else {
            Run::unstable(
                steps,
                o.ms_per_step * steps as f64 / 1e3,
                "non-finite state",
            )
        };
        still.record(
            "f32",
            dt as f64,
            run.extra(o.penetration).extra(o.below as f64),
        );
        let o = simulate(&dev, n, dt, 0.08, 0.0, None)?;
        let run = if o.finite && o.below == 0 {
            Run::stable(steps, o.penetration, o.ms_per_step * steps as f64 / 1e3)
        } else {
            Run::unstable(
                steps,
                o.ms_per_step * steps as f64 / 1e3,
                format!("{} particles under the surface", o.below),
            )
        };
        moving.record(
            "f32",
            dt as f64,
            run.extra(o.ms_per_step).extra(o.below as f64),
        );
        last = Some((dt, o));
    }
    common::finish(&still, "mesh_contact_still");
    common::finish(&moving, "mesh_contact_moving");
    if let Some((dt, o)) = last {
        let title =
            format!("mesh_contact: {n} particles on the moving terrain at t = 1 s (dt = {dt})");
        common::write_frame(
            "mesh_contact",
            &contact_frame(&o.x, &o.v, &o.terrain, 1, title),
        );
        let mut rec = cli.scene.recorder("mesh_contact");
        if rec.is_on() {
            // The recording: the frame's run (moving terrain, the smallest dt) once more.
            simulate(&dev, n, dt, 0.08, 0.0, Some(&mut rec))?;
            rec.finish();
        }
    }
    common::print_compiled();
    Ok(())
}

//! Particles colliding with a signed distance field stored in a sparse volume: a torus's exact
//! SDF sampled on a grid into a `Volume<f32>`, read back in kernels with trilinear
//! interpolation (`volume_sample_grad`: the distance and its gradient, the contact normal).
//!
//! What it reports (error next to run time):
//! 1. the sampled distance and normal against the analytic SDF, over points near the surface,
//!    against the voxel size (trilinear interpolation of a smooth field: the distance error
//!    falls as h^2, the normal's as h), next to the time of a million samples and the build;
//! 2. particles dropped onto the torus, pushed out along the sampled normal: the deepest
//!    penetration the exact SDF sees, relative to the radius, against the voxel size, next to
//!    the time per step.
//!
//! `cargo run --release --example volume_sdf [-- --device cpu|cuda:0 --n 1000000]`

mod common;

use clap::Parser;
use rand::Rng as _;
use std::time::Instant;

use warp_lang as wp;
use warp_report::frame::{Frame, Points, TriMesh};
use warp_report::{Run, Sweep};
use wp::prelude::*;

const MAJOR: f32 = 0.6;
const MINOR: f32 = 0.25;
/// The band around the surface the accuracy is measured in (and particles live in).
const BAND: f32 = 0.1;
const RADIUS: f32 = 0.01;
const GRAVITY: f32 = -9.81;

/// The torus's exact signed distance (axis y), negative inside.
#[wp::func]
fn torus_sdf(p: Vec3) -> f32 {
    let q = vec2(length(vec2(p.x, p.z)) - MAJOR, p.y);
    length(q) - MINOR
}

/// Its exact gradient (unit length away from the core circle and the axis).
#[wp::func]
fn torus_normal(p: Vec3) -> Vec3 {
    let a = length(vec2(p.x, p.z));
    let q = vec2(a - MAJOR, p.y);
    normalize(vec3(q.x * p.x / a, q.y, q.x * p.z / a))
}

/// The SDF at the voxels of an `n^3` grid of spacing `h` from `origin`.
#[wp::kernel]
fn fill(out: Array<f32, 3>, origin: Vec3, h: f32) {
    let (i, j, k) = tid();
    out[(i, j, k)] = torus_sdf(origin + vec3(i as f32, j as f32, k as f32) * h);
}

/// The sampled distance's and normal's errors at each point: `derr` the distance's, `aerr`
/// the angle (radians) between the sampled and the exact normal.
#[wp::kernel]
fn errors(vol: Volume<f32>, pts: Array<Vec3>, derr: Array<f32>, aerr: Array<f32>) {
    let i = tid();
    let p = pts[i];
    let uvw = volume_world_to_index(vol, p);
    let (d, g) = volume_sample_grad(vol, uvw, VOLUME_LINEAR);
    derr[i] = abs(d - torus_sdf(p));
    let c = dot(normalize(g), torus_normal(p));
    aerr[i] = acos(clamp(c, -1.0, 1.0));
}

/// The sampled distance only (what is timed).
#[wp::kernel]
fn sample(vol: Volume<f32>, pts: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    out[i] = volume_sample(vol, volume_world_to_index(vol, pts[i]), VOLUME_LINEAR);
}

/// One step of a particle: gravity, then the contact with the volume's surface within the
/// radius: pushed out along the sampled normal, the approaching velocity reflected with
/// restitution `e`. `pen` gets the deepest penetration after the push-out, by the exact SDF.
#[wp::kernel]
fn step(vol: Volume<f32>, x: Array<Vec3>, v: Array<Vec3>, dt: f32, e: f32, pen: Array<f32>) {
    let i = tid();
    let mut vi = v[i] + vec3(0.0, GRAVITY, 0.0) * dt;
    let mut xi = x[i] + vi * dt;
    let uvw = volume_world_to_index(vol, xi);
    let (d, g) = volume_sample_grad(vol, uvw, VOLUME_LINEAR);
    let depth = RADIUS - d;
    if depth > 0.0 && length(g) > 0.0 {
        // The gradient is in index space; the map is a uniform scale, so its direction is
        // the world normal's.
        let n = normalize(g);
        xi = xi + n * depth;
        let vn = dot(vi, n);
        if vn < 0.0 {
            vi = vi - n * ((1.0 + e) * vn);
        }
    }
    atomic_max(pen, 0, RADIUS - torus_sdf(xi));
    x[i] = xi;
    v[i] = vi;
}

/// Points uniformly distributed in the band `|sdf| < BAND` (rejection sampling, host f64).
fn band_points(n: usize, seed: u64) -> Vec<Vec3> {
    let mut r = common::rng(seed);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let mut c = || (2.0 * r.random::<f64>() - 1.0) as f32;
        let p = Vec3::new(c(), 0.45 * c(), c());
        let q = Vec2::new(Vec2::new(p.x, p.z).length() - MAJOR, p.y);
        if (q.length() - MINOR).abs() < BAND {
            out.push(p);
        }
    }
    out
}

/// The torus's SDF on an `n^3` grid over [-1, 1]^3 (spacing `2 / (n - 1)`), as a volume:
/// the grid filled by a kernel, then built from the dense values with background `1`.
fn build(dev: &wp::Device, n: usize) -> wp::Result<(wp::Volume<f32>, f64)> {
    let h = 2.0 / (n - 1) as f32;
    let origin = Vec3::splat(-1.0);
    let dense = wp::Array::<f32, 3>::zeros((n, n, n), dev)?;
    wp::launch(fill, (n, n, n), (&dense, origin, h), dev)?;
    let values = dense.to_vec()?;
    let t0 = Instant::now();
    let map = wp::VolumeMap::uniform(h as f64, origin.as_dvec3().to_array());
    let vol = wp::Volume::from_dense(&values, [n, n, n], 1.0f32, &map, dev)?;
    wp::synchronize()?;
    Ok((vol, t0.elapsed().as_secs_f64() * 1e3))
}

/// Seconds per launch of `sample` over the points (the median of 5 after a warm-up).
fn time_samples(
    dev: &wp::Device,
    vol: &wp::Volume<f32>,
    pts: &wp::Array<Vec3>,
    out: &wp::Array<f32>,
) -> wp::Result<f64> {
    let mut t = Vec::new();
    for k in 0..6 {
        wp::synchronize()?;
        let t0 = Instant::now();
        wp::launch(sample, pts.len(), (vol, pts, out), dev)?;
        wp::synchronize()?;
        if k > 0 {
            t.push(t0.elapsed().as_secs_f64());
        }
    }
    t.sort_by(f64::total_cmp);
    Ok(t[t.len() / 2])
}

/// Particles in the band above the torus, falling for 0.5 s with step `dt`: the deepest
/// penetration (exact SDF) over the run relative to the radius, and ms per step.
///
/// With a recorder (and the volume's resolution, for the title), about 100 frames of the run
/// go to it (the step time then includes them).
fn drop_particles(
    dev: &wp::Device,
    vol: &wp::Volume<f32>,
    n: usize,
    dt: f32,
    mut rec: Option<(&mut common::record::Recorder, usize)>,
) -> wp::Result<(f64, f64, bool, Vec<Vec3>)> {
    let x0: Vec<Vec3> = band_points(4 * n, 7)
        .into_iter()
        .filter(|p| {
            let q = Vec2::new(Vec2::new(p.x, p.z).length() - MAJOR, p.y);
            q.length() - MINOR > 2.0 * RADIUS
        })
        .take(n)
        .collect();
    let x = wp::Array::from_slice(&x0, dev)?;
    let v = wp::Array::<Vec3>::zeros(x0.len(), dev)?;
    let pen = wp::Array::<f32>::full(1, -1.0, dev)?;
    let steps = (0.5 / dt).round() as usize;
    let (every, stride) = (
        common::record::every(steps),
        common::record::stride(x0.len()),
    );
    let snap = |rec: &mut common::record::Recorder, res: usize, s: usize| -> wp::Result<()> {
        let t = s as f64 * dt as f64;
        let title = format!(
            "volume_sdf: {} particles dropped around a torus SDF sampled at {res}^3, at {t:.3} s",
            x0.len()
        );
        rec.frame(s, t, &torus_frame(&x.to_vec()?, stride, title));
        Ok(())
    };
    if let Some((rec, res)) = rec.as_mut() {
        snap(rec, *res, 0)?;
    }
    wp::synchronize()?;
    let t0 = Instant::now();
    for s in 1..=steps {
        wp::launch(step, x0.len(), (vol, &x, &v, dt, 0.5f32, &pen), dev)?;
        if let Some((rec, res)) = rec.as_mut() {
            if s % every == 0 || s == steps {
                snap(rec, *res, s)?;
            }
        }
    }
    wp::synchronize()?;
    let ms = t0.elapsed().as_secs_f64() * 1e3 / steps as f64;
    let end = x.to_vec()?;
    let finite = end.iter().all(|p| p.is_finite());
    Ok((pen.to_vec()?[0] as f64 / RADIUS as f64, ms, finite, end))
}

/// Particles colliding with a torus's signed distance field in a sparse volume: sampling
/// error and penetration against the voxel size.
#[derive(Parser)]
struct Cli {
    /// Points near the surface [default: 1000000 on a GPU, 200000 on the CPU]
    #[arg(long, value_name = "POINTS", value_parser = common::num::<usize>)]
    n: Option<usize>,
    /// The finest grid's voxels per side [default: 257 on a GPU, 129 on the CPU]
    #[arg(long, value_name = "N", value_parser = common::num::<usize>)]
    max_res: Option<usize>,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let n = cli
        .n
        .unwrap_or(if dev.is_cpu() { 200_000 } else { 1_000_000 });
    let max_res = cli.max_res.unwrap_or(if dev.is_cpu() { 129 } else { 257 });
    println!(
        "torus SDF (R = {MAJOR}, r = {MINOR}) in a Volume<f32> over [-1, 1]^3; {n} points \
         within {BAND} of the surface; on {dev}"
    );
    let pts_h = band_points(n, 1);
    let pts = wp::Array::from_slice(&pts_h, &dev)?;
    let derr = wp::Array::<f32>::zeros(n, &dev)?;
    let aerr = wp::Array::<f32>::zeros(n, &dev)?;
    let out = wp::Array::<f32>::zeros(n, &dev)?;

    let acc = Sweep::new(
        format!("sampled SDF vs the exact torus, on {dev}: max |distance error|"),
        "voxel size",
    )
    .with_extras(&[
        "rms distance error",
        "max normal error (deg)",
        "ns per sample",
        "build ms",
    ]);
    // The accuracy sweep's bar (the contact runs of each grid come with them).
    let mut acc = acc.progress(common::grid_count(17, max_res));
    let mut contact = Sweep::new(
        format!("particles on the volume's torus (dt 1e-3, 0.5 s), on {dev}: max penetration / r"),
        "voxel size",
    )
    .with_extras(&["ms per step"]);
    let mut last = None;
    let mut rec = cli.scene.recorder("volume_sdf");
    let mut res = 17;
    while res <= max_res {
        let h = 2.0 / (res - 1) as f64;
        let (vol, build_ms) = build(&dev, res)?;
        wp::launch(errors, n, (&vol, &pts, &derr, &aerr), &dev)?;
        let (d, a) = (derr.to_vec()?, aerr.to_vec()?);
        let max_d = d.iter().fold(0f32, |m, x| m.max(*x)) as f64;
        let rms = (d.iter().map(|x| (*x as f64).powi(2)).sum::<f64>() / n as f64).sqrt();
        let max_a = a.iter().fold(0f32, |m, x| m.max(*x)) as f64;
        let secs = time_samples(&dev, &vol, &pts, &out)?;
        let finite = d.iter().chain(&a).all(|x| x.is_finite());
        let run = if finite {
            Run::stable(n as u64, max_d, secs)
        } else {
            Run::unstable(n as u64, secs, "non-finite sample")
        };
        acc.record(
            "f32",
            h,
            run.extra(rms)
                .extra(max_a.to_degrees())
                .extra(secs * 1e9 / n as f64)
                .extra(build_ms),
        );
        let parts = if dev.is_cpu() { 20_000 } else { 200_000 };
        let (pen, ms, ok, end) = drop_particles(&dev, &vol, parts, 1e-3, None)?;
        if 2 * res - 1 > max_res && rec.is_on() {
            // The recording: the finest volume's run once more, outside the timing.
            drop_particles(&dev, &vol, parts, 1e-3, Some((&mut rec, res)))?;
            rec.finish();
            rec = common::record::Recorder::off();
        }
        last = Some((res, end));
        let steps = 500u64;
        let run = if ok {
            Run::stable(steps, pen.max(0.0), ms * steps as f64 / 1e3)
        } else {
            Run::unstable(steps, ms * steps as f64 / 1e3, "non-finite state")
        };
        contact.record("f32", h, run.extra(ms));
        res = 2 * res - 1;
    }
    common::finish(&acc, "volume_sdf_accuracy");
    common::finish(&contact, "volume_sdf_contact");
    if let Some((res, end)) = last {
        let title = format!(
            "volume_sdf: {} particles dropped around a torus SDF sampled at {res}^3, at 0.5 s",
            end.len()
        );
        common::write_frame("volume_sdf", &torus_frame(&end, 1, title));
    }
    common::print_compiled();
    Ok(())
}

/// The exact torus as a coarse parametric mesh (48 x 16 quads), and the particles (one in
/// `stride`) on the volume's version of it, coloured by height.
fn torus_frame(x: &[Vec3], stride: usize, title: String) -> Frame {
    let (nu, nv) = (48usize, 16usize);
    let mut pts = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let (u, v) = (
                std::f64::consts::TAU * i as f64 / nu as f64,
                std::f64::consts::TAU * j as f64 / nv as f64,
            );
            let ring = MAJOR as f64 + MINOR as f64 * v.cos();
            pts.push([ring * u.cos(), MINOR as f64 * v.sin(), ring * u.sin()]);
        }
    }
    let at = |i: usize, j: usize| (i % nu) * nv + j % nv;
    let tris: Vec<[usize; 3]> = (0..nu)
        .flat_map(|i| (0..nv).map(move |j| (i, j)))
        .flat_map(|(i, j)| {
            [
                [at(i, j), at(i + 1, j), at(i + 1, j + 1)],
                [at(i, j), at(i + 1, j + 1), at(i, j + 1)],
            ]
        })
        .collect();
    let end: Vec<Vec3> = x.iter().step_by(stride).copied().collect();
    Frame::new(
        title,
        common::camera([-1.0; 3], [1.0; 3], [0.2, 1.0, 1.1], [0.0, 1.0, 0.0]),
    )
    .note("the exact torus as a mesh; contacts push out along volume_sample_grad, those off the top fall; colour: height")
    .mesh(TriMesh::new(pts, tris).colour([200, 200, 200]).closed())
    .points(
        Points::new(end.iter().map(|&p| common::p3(p)), RADIUS as f64)
            .values("height", end.iter().map(|p| p.y as f64)),
    )
}

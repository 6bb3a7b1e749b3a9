//! Marching cubes of an analytic surface, and the extracted mesh used with the mesh queries:
//! a torus's SDF sampled on n^3 grids, `wp::MarchingCubes` extracting its zero level set, and
//! the Hausdorff distance between the mesh and the exact torus measured both ways: every
//! vertex's distance to the surface (the exact SDF), and the distance from points on the exact
//! surface to the mesh (`mesh_query_point_no_sign` on a `wp::Mesh` over the extraction).
//!
//! What it reports (error next to run time): the Hausdorff distance relative to the grid
//! spacing h against h (linear interpolation along the edges: it falls as h^2), the signed
//! volume against the torus's 2 pi^2 R r^2, next to the extraction's time and the mesh's
//! build; then the extracted mesh's signed distance queries against the exact SDF.
//!
//! `cargo run --release --example marching_cubes [-- --device cpu|cuda:0 --max-res 257]`

mod common;

use clap::Parser;
use rand::Rng as _;
use std::time::Instant;

use warp_lang as wp;
use warp_report::frame::{Frame, TriMesh};
use warp_report::{Run, Sweep};
use wp::prelude::*;

const MAJOR: f32 = 0.6;
const MINOR: f32 = 0.25;

#[wp::func]
fn torus_sdf(p: Vec3) -> f32 {
    let q = vec2(length(vec2(p.x, p.z)) - MAJOR, p.y);
    length(q) - MINOR
}

/// The SDF on the grid: node (i, j, k) at `-1 + (i, j, k) h`.
#[wp::kernel]
fn fill(out: Array<f32, 3>, h: f32) {
    let (i, j, k) = tid();
    out[(i, j, k)] = torus_sdf(vec3(i as f32, j as f32, k as f32) * h - Vec3::splat(1.0));
}

/// Each vertex (grid-index space) to the world box, in place, and its |SDF| into `err`.
#[wp::kernel]
fn to_world(verts: Array<Vec3>, h: f32, err: Array<f32>) {
    let i = tid();
    let p = verts[i] * h - Vec3::splat(1.0);
    verts[i] = p;
    err[i] = abs(torus_sdf(p));
}

/// Each surface point's distance to the mesh (into `err`), and the signed distance's error
/// at each query point (into `serr`).
#[wp::kernel]
fn to_mesh(mesh: Mesh, surf: Array<Vec3>, err: Array<f32>, q: Array<Vec3>, serr: Array<f32>) {
    let i = tid();
    let p = surf[i];
    let (found, _s, face, u, v) = mesh_query_point_no_sign(mesh, p, 1.0);
    let mut d = 1.0;
    if found {
        d = length(p - mesh_eval_position(mesh, face, u, v));
    }
    err[i] = d;
    let x = q[i];
    let (hit, sign, f2, u2, v2) = mesh_query_point(mesh, x, 2.0);
    let mut sd = 2.0;
    if hit {
        sd = length(x - mesh_eval_position(mesh, f2, u2, v2)) * sign;
    }
    serr[i] = abs(sd - torus_sdf(x));
}

/// Points on the exact torus (uniform in its angles) and query points in [-1, 1]^3.
fn samples(n: usize) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut r = common::rng(11);
    let mut surf = Vec::with_capacity(n);
    let mut q = Vec::with_capacity(n);
    for _ in 0..n {
        let (u, v) = (
            std::f64::consts::TAU * r.random::<f64>(),
            std::f64::consts::TAU * r.random::<f64>(),
        );
        let (big, small) = (MAJOR as f64, MINOR as f64);
        let rad = big + small * v.cos();
        surf.push(Vec3::new(
            (rad * u.cos()) as f32,
            (small * v.sin()) as f32,
            (rad * u.sin()) as f32,
        ));
        let mut c = || (2.0 * r.random::<f64>() - 1.0) as f32;
        q.push(Vec3::new(c(), c(), c()));
    }
    (surf, q)
}

/// The mesh's signed volume (divergence theorem, f64).
fn signed_volume(p: &[Vec3], ix: &[i32]) -> f64 {
    ix.chunks_exact(3)
        .map(|t| {
            let [a, b, c] = [0, 1, 2].map(|k| p[t[k] as usize].as_dvec3());
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

/// Marching cubes of a torus: the extracted surface's distance from the true one as the grid
/// is refined.
#[derive(Parser)]
struct Cli {
    /// The finest grid's samples per side [default: 257 on a GPU, 129 on the CPU]
    #[arg(long, value_name = "N", value_parser = common::num::<usize>)]
    max_res: Option<usize>,
    /// Points sampled on the surfaces to measure the error
    #[arg(
        long,
        value_name = "POINTS",
        default_value = "100_000",
        value_parser = common::num::<usize>
    )]
    n: usize,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let max_res = cli.max_res.unwrap_or(if dev.is_cpu() { 129 } else { 257 });
    let n = cli.n;
    println!("marching cubes of a torus (R = {MAJOR}, r = {MINOR}) in [-1, 1]^3, on {dev}");
    let (surf_h, q_h) = samples(n);
    let surf = wp::Array::from_slice(&surf_h, &dev)?;
    let q = wp::Array::from_slice(&q_h, &dev)?;
    let exact_volume = 2.0 * std::f64::consts::PI.powi(2) * MAJOR as f64 * (MINOR as f64).powi(2);

    let mut sweep = Sweep::new(
        format!("marching cubes vs the exact torus, on {dev}: Hausdorff distance / h"),
        "grid spacing h",
    )
    .with_extras(&[
        "vertices -> surface / h",
        "surface -> mesh / h",
        "volume rel. error",
        "triangles",
        "extract ms",
        "mesh build ms",
        "max |signed query - sdf|",
    ])
    .progress(common::grid_count(17, max_res));
    // The frame: the extraction on the 33^3 grid (about 5K triangles: a small file that
    // still shows the faceting).
    let mut shown = None;
    let mut res = 17;
    while res <= max_res {
        let h = 2.0 / (res - 1) as f32;
        let field = wp::Array::<f32, 3>::zeros((res, res, res), &dev)?;
        wp::launch(fill, (res, res, res), (&field, h), &dev)?;
        let mut mc = wp::MarchingCubes::new(res, res, res, &dev)?;
        mc.surface(&field, 0.0)?; // compiles on a GPU; then timed
        wp::synchronize()?;
        let t0 = Instant::now();
        mc.surface(&field, 0.0)?;
        wp::synchronize()?;
        let extract_ms = t0.elapsed().as_secs_f64() * 1e3;
        let verts = mc.verts().clone();
        let nv = verts.len();
        let err = wp::Array::<f32>::zeros(nv.max(n), &dev)?;
        wp::launch(to_world, nv, (&verts, h, &err), &dev)?;
        let v_err = err.to_vec()?[..nv].iter().fold(0f32, |m, x| m.max(*x)) as f64;
        let t1 = Instant::now();
        let indices = mc.indices().clone();
        let mesh = wp::Mesh::new(&verts, &indices, None)?;
        wp::synchronize()?;
        let build_ms = t1.elapsed().as_secs_f64() * 1e3;
        let serr = wp::Array::<f32>::zeros(n, &dev)?;
        wp::launch(to_mesh, n, (&mesh, &surf, &err, &q, &serr), &dev)?;
        let s_err = err.to_vec()?[..n].iter().fold(0f32, |m, x| m.max(*x)) as f64;
        let signed = serr.to_vec()?.iter().fold(0f32, |m, x| m.max(*x)) as f64;
        let (p, ix) = (verts.to_vec()?, indices.to_vec()?);
        let vol_err = (signed_volume(&p, &ix) - exact_volume).abs() / exact_volume;
        if res == 33 || shown.is_none() {
            shown = Some((res, p.clone(), ix.clone()));
        }
        let hd = v_err.max(s_err) / h as f64;
        let run = if hd.is_finite() {
            Run::stable(res as u64, hd, extract_ms / 1e3)
        } else {
            Run::unstable(res as u64, extract_ms / 1e3, "non-finite distance")
        };
        sweep.record(
            "f32",
            h as f64,
            run.extra(v_err / h as f64)
                .extra(s_err / h as f64)
                .extra(vol_err)
                .extra((ix.len() / 3) as f64)
                .extra(extract_ms)
                .extra(build_ms)
                .extra(signed),
        );
        res = 2 * res - 1;
    }
    common::finish(&sweep, "marching_cubes");
    if let Some((res, p, ix)) = shown {
        let tris: Vec<[usize; 3]> = ix
            .chunks(3)
            .map(|t| [t[0] as usize, t[1] as usize, t[2] as usize])
            .collect();
        let frame = Frame::new(
            format!(
                "marching_cubes: the torus's zero level set on a {res}^3 grid, {} triangles",
                tris.len()
            ),
            common::camera([-1.0; 3], [1.0; 3], [0.3, 1.0, 1.2], [0.0, 1.0, 0.0]),
        )
        .note(format!(
            "R = {MAJOR}, r = {MINOR}, flat shaded (faces turned away not drawn)"
        ))
        .mesh(
            TriMesh::new(p.iter().map(|&v| common::p3(v)), tris)
                .colour([120, 170, 210])
                .closed(),
        );
        common::write_frame("marching_cubes", &frame);
        cli.scene.record_last("marching_cubes", &frame);
    }
    common::print_compiled();
    Ok(())
}

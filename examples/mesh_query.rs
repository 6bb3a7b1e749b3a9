//! The seed's point projection: query points projected onto a triangle mesh with
//! `mesh_query_point` and `mesh_eval_position`, the building block of collision detection.
//!
//! What it reports (error next to run time):
//! 1. projection of 1M points (uniform in [-2, 2]^2 x [-1, 1]) onto a 200K-triangle torus
//!    (R = 1, r = 0.4): the time of the query kernel and of the mesh build, and the error of
//!    the distance to the projected point against a brute-force f64 search over every
//!    triangle for 1000 of the points;
//! 2. the signed distance of the same kind of points against the closed-form SDF of a torus
//!    and of a sphere, swept over the tessellation: the error falls as the faceting does
//!    (about r (1 - cos(pi / n)), second order in the segment count n); the time grows with
//!    the triangle count (a point far from the surface has more small triangles at nearly its
//!    distance to rule out); the sign is checked where the point lies outside the faceting
//!    band;
//! 3. the projection onto a mesh read from an OBJ file (`wp::objects::ObjMesh`, cargo feature
//!    `obj`): `examples/assets/torus_knot.obj` (a knotted tube of 4096 triangles, written as
//!    quads the reader triangulates), or `--obj PATH`, with the points scaled into its box;
//!    time, and the distance error against brute force on 1000 points.
//!
//! `cargo run --release --example mesh_query [-- --device cpu|cuda:0 --n 1000000 --obj PATH]`

mod common;
#[path = "common/meshes.rs"]
mod meshes;

use clap::Parser;
use rand::Rng as _;
use std::time::Instant;

use glam::DVec3;
use warp_lang as wp;
use warp_report::frame::{Frame, Lines, Points, TriMesh};
use warp_report::{Run, Sweep};
use wp::prelude::*;

/// Each query point's closest point on the mesh and its signed distance (negative inside;
/// `max_dist` beyond which a point finds nothing: then its distance is `max_dist`).
#[wp::kernel]
fn project(mesh: Mesh, q: Array<Vec3>, max_dist: f32, closest: Array<Vec3>, dist: Array<f32>) {
    let i = tid();
    let p = q[i];
    let (found, sign, face, u, v) = mesh_query_point(mesh, p, max_dist);
    if found {
        let c = mesh_eval_position(mesh, face, u, v);
        closest[i] = c;
        dist[i] = length(p - c) * sign;
    } else {
        closest[i] = p;
        dist[i] = max_dist;
    }
}

/// A closed-form signed distance.
type Sdf = Box<dyn Fn(DVec3) -> f64>;

/// `n` points uniform in the box `[lo, hi]`.
fn points(n: usize, lo: Vec3, hi: Vec3, seed: u64) -> Vec<Vec3> {
    let mut r = common::rng(seed);
    (0..n)
        .map(|_| {
            let t = Vec3::new(
                r.random::<f64>() as f32,
                r.random::<f64>() as f32,
                r.random::<f64>() as f32,
            );
            lo + (hi - lo) * t
        })
        .collect()
}

/// Builds the mesh and projects `q` onto it: (build ms, query ms, closest points, distances).
fn run(
    m: &meshes::TriMesh,
    q: &wp::Array<Vec3>,
    dev: &wp::Device,
) -> wp::Result<(f64, f64, Vec<Vec3>, Vec<f32>)> {
    let n = q.len();
    let points = wp::Array::from_slice(&m.points, dev)?;
    let indices = wp::Array::from_slice(&m.indices, dev)?;
    let closest = wp::Array::<Vec3>::zeros(n, dev)?;
    let dist = wp::Array::<f32>::zeros(n, dev)?;
    // Warm-up: the first launch compiles (on a GPU) and the first build allocates.
    let mesh = wp::Mesh::new(&points, &indices, None)?;
    wp::launch(project, n, (&mesh, q, 10.0f32, &closest, &dist), dev)?;
    wp::synchronize()?;
    let t = Instant::now();
    let mesh = wp::Mesh::new(&points, &indices, None)?;
    wp::synchronize()?;
    let build = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    wp::launch(project, n, (&mesh, q, 10.0f32, &closest, &dist), dev)?;
    wp::synchronize()?;
    let query = t.elapsed().as_secs_f64() * 1e3;
    Ok((build, query, closest.to_vec()?, dist.to_vec()?))
}

/// Points projected onto triangle meshes: against brute force, signed distances against
/// closed forms, and a mesh read from an OBJ file.
#[derive(Parser)]
struct Cli {
    /// Query points [default: 1000000 on a GPU, 200000 on the CPU]
    #[arg(long, value_name = "POINTS", value_parser = common::num::<usize>)]
    n: Option<usize>,
    /// The OBJ file of the last part [default: examples/assets/torus_knot.obj]
    #[arg(long, value_name = "PATH")]
    obj: Option<String>,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let n = cli
        .n
        .unwrap_or(if dev.is_cpu() { 200_000 } else { 1_000_000 });
    let box_lo = Vec3::new(-2.0, -2.0, -1.0);
    let box_hi = Vec3::new(2.0, 2.0, 1.0);
    let qs = points(n, box_lo, box_hi, 1);
    let q = wp::Array::from_slice(&qs, &dev)?;

    // 1. The projection against brute force.
    let torus = meshes::torus(500, 200, 1.0, 0.4);
    let (build, query, closest, dist) = run(&torus, &q, &dev)?;
    let check: Vec<usize> = (0..1000).map(|k| k * (n / 1000)).collect();
    let (mut worst, mut off_surface) = (0.0f64, 0.0f64);
    for &k in &check {
        let p = qs[k].as_dvec3();
        worst = worst.max((dist[k].abs() as f64 - meshes::brute_distance(&torus, p)).abs());
        // The projected point lies on the mesh: its own distance to the mesh is ~0.
        off_surface = off_surface.max(meshes::brute_distance(&torus, closest[k].as_dvec3()));
    }
    println!(
        "1. projection of {n} points onto a {}-triangle torus on {dev}: query {query:.2} ms, \
         build {build:.2} ms; against brute force (f64, {} points): distance error {}, \
         projected points off the surface by at most {}",
        torus.triangles(),
        check.len(),
        warp_report::sci(worst),
        warp_report::sci(off_surface),
    );

    // 2. Signed distance against the closed-form SDFs, over the tessellation.
    let mut sweep = Sweep::new(
        format!("signed distance on {dev}: max |d_mesh - sdf| over {n} points"),
        "triangles",
    )
    .with_extras(&["build ms", "wrong signs"])
    .progress(2 * 6); // a torus and a sphere at each of 6 tessellations
    println!("\n2. signed distance against the closed-form SDF, over the tessellation");
    for k in [1usize, 2, 4, 8, 16, 32] {
        let cases: [(&str, meshes::TriMesh, Sdf); 2] = [
            (
                "torus",
                meshes::torus(25 * k, 10 * k, 1.0, 0.4),
                Box::new(|p| meshes::torus_sdf(p, 1.0, 0.4)),
            ),
            (
                "sphere",
                meshes::sphere(8 * k, 16 * k, 1.0),
                Box::new(|p: DVec3| p.length() - 1.0),
            ),
        ];
        for (name, m, sdf) in cases {
            let (build, query, _, dist) = run(&m, &q, &dev)?;
            let mut worst = 0.0f64;
            let mut wrong = 0usize;
            for (p, d) in qs.iter().zip(&dist) {
                let exact = sdf(p.as_dvec3());
                let e = (*d as f64 - exact).abs();
                worst = worst.max(e);
                // Outside the faceting band (chord error < 0.02 from k = 2 on) the sign is
                // the closed form's.
                if exact.abs() > 0.05 && (exact < 0.0) != (*d < 0.0) {
                    wrong += 1;
                }
            }
            let run = Run::stable(n as u64, worst, query / 1e3)
                .extra(build)
                .extra(wrong as f64);
            sweep.record(name, m.triangles() as f64, run);
        }
    }
    common::finish(&sweep, "mesh_query_sdf");

    // 3. A mesh from an OBJ file.
    let path = cli.obj.unwrap_or_else(|| {
        concat!(env!("CARGO_MANIFEST_DIR"), "/assets/torus_knot.obj").to_string()
    });
    let obj = wp::objects::ObjMesh::load(&path)?;
    let m = meshes::TriMesh {
        points: obj.points,
        indices: obj.indices,
    };
    let (lo, hi) = m
        .points
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), p| {
            (l.min(*p), h.max(*p))
        });
    // The same points, moved from the query box into the mesh's box grown by a quarter.
    let (pad, box_size) = ((hi - lo) * 0.25, box_hi - box_lo);
    let qs3: Vec<Vec3> = qs
        .iter()
        .map(|p| lo - pad + (*p - box_lo) / box_size * (hi - lo + 2.0 * pad))
        .collect();
    let q3 = wp::Array::from_slice(&qs3, &dev)?;
    let (build, query, closest3, dist) = run(&m, &q3, &dev)?;
    let worst = check
        .iter()
        .map(|&k| (dist[k].abs() as f64 - meshes::brute_distance(&m, qs3[k].as_dvec3())).abs())
        .fold(0.0, f64::max);
    println!(
        "\n3. projection of {n} points onto {path} ({} points, {} triangles) on {dev}: query \
         {query:.2} ms, build {build:.2} ms; distance error against brute force (f64, {} \
         points): {}",
        m.points.len(),
        m.triangles(),
        check.len(),
        warp_report::sci(worst),
    );
    // The frame: the mesh, and 300 of the query points joined to their closest points.
    let shown: Vec<usize> = (0..n).step_by(n.div_ceil(300).max(1)).collect();
    let name = std::path::Path::new(&path)
        .file_name()
        .map_or(path.clone(), |f| f.to_string_lossy().into_owned());
    let (lo, hi) = (common::p3(lo - pad), common::p3(hi + pad));
    let frame = Frame::new(
        format!("mesh_query: {} points projected onto {name}", shown.len()),
        common::camera(lo, hi, [0.4, 0.5, 1.0], [0.0, 1.0, 0.0]),
    )
    .note(format!(
        "{} triangles (mesh_query_point); lines to the closest points; colour: distance",
        m.triangles()
    ))
    .mesh(
        TriMesh::new(
            m.points.iter().map(|&p| common::p3(p)),
            m.indices
                .chunks(3)
                .map(|t| [t[0] as usize, t[1] as usize, t[2] as usize])
                .collect(),
        )
        .colour([214, 170, 120])
        .closed(),
    )
    .lines(
        Lines::new(
            shown
                .iter()
                .map(|&k| [common::p3(qs3[k]), common::p3(closest3[k])]),
        )
        .colour([120, 120, 120])
        .width(0.6),
    )
    .points(
        Points::new(
            shown.iter().map(|&k| common::p3(qs3[k])),
            0.004 * common::diagonal(lo, hi),
        )
        .values("distance", shown.iter().map(|&k| dist[k].abs() as f64)),
    );
    common::write_frame("mesh_query", &frame);
    cli.scene.record_last("mesh_query", &frame);
    common::print_compiled();
    Ok(())
}

//! GPU benchmark of the geometry queries against NVIDIA Warp timed on the same GPU in the same
//! run (`benches/py/warp_mesh.py`, shared/DESIGN.md's workloads), with each result's error
//! against a brute-force f64 reference on a subset next to its time.
//!
//! ```text
//! cargo bench --bench geometry                 # needs a CUDA device; SKIPPED otherwise
//! # on the GPU machine, with Warp unpacked by ../shared/tools/warp-bundle:
//! PYTHONPATH=/root/warp-lang .gpu/bin/geometry-*
//! ```
//!
//! - Mesh: a torus (R = 1, r = 0.4) on a 500 x 200 grid, 200K triangles: build and refit.
//! - 1M query points uniform in [-2, 2]^2 x [-1, 1]: `mesh_query_point` (signed) and
//!   `mesh_query_point_no_sign` with max_dist 10; the distance of 2000 of them against brute
//!   force in f64, and the sign against the torus's closed-form SDF. The signed query is
//!   timed against Warp's `mesh_query_point` (its sign from three axis-aligned rays) and
//!   against `mesh_query_point_sign_normal` (the angle-weighted pseudonormal, as here);
//!   `mesh_query_point_sign_parity` against Warp's with its defaults (one ray), with the same
//!   error columns.
//! - 1M rays from the radius-3 sphere aimed at random points of the torus's box:
//!   `mesh_query_ray`; 500 of them against a brute-force ray cast.
//! - A Bvh of 1M boxes (centres uniform in 10^3, half extents U[0.025, 0.075]): build, refit,
//!   and `bvh_query_aabb` per box counting overlaps; 2000 counts against brute force.
//! - The CPU backend: 100K `mesh_query_point_no_sign` queries on all threads, against Warp's
//!   single-threaded CPU figure in DESIGN.md (Warp's CPU compiler is not in the bundle).

use glam::DVec3;
use std::time::Instant;
use warp_lang as wp;
use wp::prelude::*;

mod common;

use common::{json_number, median_ms, python_side, ratio};
use rand::Rng as _;

#[path = "../examples/common/meshes.rs"]
mod meshes;

#[wp::kernel]
fn query_point(mesh: Mesh, pts: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    let p = pts[i];
    let (found, sign, face, u, v) = mesh_query_point(mesh, p, 10.0);
    let mut d = 0.0;
    if found {
        d = length(p - mesh_eval_position(mesh, face, u, v)) * sign;
    }
    out[i] = d;
}

#[wp::kernel]
fn query_point_sign_parity(mesh: Mesh, pts: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    let p = pts[i];
    let (found, sign, face, u, v) = mesh_query_point_sign_parity(mesh, p, 10.0);
    let mut d = 0.0;
    if found {
        d = length(p - mesh_eval_position(mesh, face, u, v)) * sign;
    }
    out[i] = d;
}

#[wp::kernel]
fn query_point_no_sign(mesh: Mesh, pts: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    let p = pts[i];
    let (found, _sign, face, u, v) = mesh_query_point_no_sign(mesh, p, 10.0);
    let mut d = 0.0;
    if found {
        d = length(p - mesh_eval_position(mesh, face, u, v));
    }
    out[i] = d;
}

#[wp::kernel]
fn query_ray(mesh: Mesh, start: Array<Vec3>, dir: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    let (found, _sign, _face, t, _u, _v, _normal) = mesh_query_ray(mesh, start[i], dir[i], 100.0);
    let mut hit = -1.0;
    if found {
        hit = t;
    }
    out[i] = hit;
}

#[wp::kernel]
fn count_overlaps(bvh: Bvh, lo: Array<Vec3>, hi: Array<Vec3>, out: Array<i32>) {
    let i = tid();
    let mut c = 0;
    for b in bvh_query_aabb(bvh, lo[i], hi[i]) {
        if b >= 0 {
            c += 1;
        }
    }
    out[i] = c;
}

fn main() -> wp::Result<()> {
    wp::init();
    let dev = match wp::get_device("cuda:0") {
        Ok(d) => d,
        Err(e) => {
            println!("geometry bench SKIPPED: no CUDA device ({e})");
            return Ok(());
        }
    };
    println!("geometry bench on {dev}");
    let n = 1_000_000usize;
    let warp = python_side("benches/py/warp_mesh.py", &[n.to_string()]);
    match &warp {
        Ok(_) => println!("Warp side: ran in this process's run"),
        Err(e) => println!("Warp side not run: {e}"),
    }
    let theirs = |k: &str| warp.as_ref().ok().and_then(|t| json_number(t, k));
    let row = |what: &str, ours: f64, key: &str, error: String| {
        println!(
            "{what:<34} {ours:8.3} ms {}   {error}",
            ratio(ours, theirs(key))
        );
    };

    let torus = meshes::torus(500, 200, 1.0, 0.4);
    let points = wp::Array::from_slice(&torus.points, &dev)?;
    let indices = wp::Array::from_slice(&torus.indices, &dev)?;
    println!(
        "torus: {} triangles            warp-lang  Warp 1.19, ratio warp-lang / Warp   error",
        torus.triangles()
    );
    let build = median_ms(|| wp::Mesh::new(&points, &indices, None).map(drop))?;
    row("mesh build", build, "mesh_build_ms", String::new());
    let mut mesh = wp::Mesh::new(&points, &indices, None)?;
    let refit = median_ms(|| mesh.refit())?;
    row("mesh refit", refit, "mesh_refit_ms", String::new());

    // Query points, and the reference on a subset.
    let mut r = common::rng(0x243f_6a88);
    let qs: Vec<Vec3> = (0..n)
        .map(|_| {
            Vec3::new(
                r.random::<f32>() * 4.0 - 2.0,
                r.random::<f32>() * 4.0 - 2.0,
                r.random::<f32>() * 2.0 - 1.0,
            )
        })
        .collect();
    let q = wp::Array::from_slice(&qs, &dev)?;
    let out = wp::Array::<f32>::zeros(n, &dev)?;
    let subset: Vec<usize> = (0..2000).map(|k| k * (n / 2000)).collect();
    let signed = median_ms(|| wp::launch(query_point, n, (&mesh, &q, &out), &dev))?;
    let d = out.to_vec()?;
    // The largest distance error and the wrong signs on the subset, and the inside fraction.
    let check_signed = |d: &[f32]| {
        let (mut worst, mut wrong_sign) = (0.0f64, 0usize);
        for &k in &subset {
            let p = qs[k].as_dvec3();
            let exact = meshes::brute_distance(&torus, p);
            worst = worst.max((d[k].abs() as f64 - exact).abs());
            // Points nearer the surface than the faceting (about 1e-4 here) may take either
            // sign.
            let sdf = meshes::torus_sdf(p, 1.0, 0.4);
            if sdf.abs() > 1e-3 && (sdf < 0.0) != (d[k] < 0.0) {
                wrong_sign += 1;
            }
        }
        let inside = d.iter().filter(|&&x| x < 0.0).count() as f64 / n as f64;
        (worst, wrong_sign, inside)
    };
    let (worst, wrong_sign, inside) = check_signed(&d);
    let fraction = |key| theirs(key).map_or("-".into(), |f| format!("{f:.4}"));
    row(
        "mesh_query_point (signed)",
        signed,
        "query_point_ms",
        format!(
            "|d| vs brute force: max {worst:.1e}; wrong signs {wrong_sign} of {}; inside \
             {inside:.4} (Warp's points, three-ray sign: {})",
            subset.len(),
            fraction("signed_inside_fraction")
        ),
    );
    // The same sign method on both sides: Warp's pseudonormal variant.
    row(
        "  vs Warp's _sign_normal",
        signed,
        "query_point_sign_normal_ms",
        format!(
            "Warp's inside fraction {}",
            fraction("sign_normal_inside_fraction")
        ),
    );
    // The parity sign: one ray, on both sides (Warp's defaults: n_sample 1).
    let parity = median_ms(|| wp::launch(query_point_sign_parity, n, (&mesh, &q, &out), &dev))?;
    let (worst, wrong_sign, inside) = check_signed(&out.to_vec()?);
    row(
        "mesh_query_point_sign_parity",
        parity,
        "query_point_sign_parity_ms",
        format!(
            "|d| vs brute force: max {worst:.1e}; wrong signs {wrong_sign} of {}; inside \
             {inside:.4} (Warp's points, its parity: {})",
            subset.len(),
            fraction("sign_parity_inside_fraction")
        ),
    );
    let unsigned = median_ms(|| wp::launch(query_point_no_sign, n, (&mesh, &q, &out), &dev))?;
    let d = out.to_vec()?;
    let worst = subset
        .iter()
        .map(|&k| (d[k] as f64 - meshes::brute_distance(&torus, qs[k].as_dvec3())).abs())
        .fold(0.0, f64::max);
    let mean = d.iter().map(|&x| x as f64).sum::<f64>() / n as f64;
    row(
        "mesh_query_point_no_sign",
        unsigned,
        "query_point_no_sign_ms",
        format!(
            "max {worst:.1e}; mean distance {mean:.4} (Warp's points: {})",
            theirs("mean_distance").map_or("-".into(), |m| format!("{m:.4}"))
        ),
    );

    // Rays from the radius-3 sphere towards the torus's box.
    let mut starts = Vec::with_capacity(n);
    let mut dirs = Vec::with_capacity(n);
    for _ in 0..n {
        let s = loop {
            let v = Vec3::new(r.random::<f32>(), r.random::<f32>(), r.random::<f32>()) * 2.0
                - Vec3::ONE;
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                break v / l * 3.0;
            }
        };
        let target = Vec3::new(
            r.random::<f32>() * 2.8 - 1.4,
            r.random::<f32>() * 2.8 - 1.4,
            r.random::<f32>() * 0.8 - 0.4,
        );
        starts.push(s);
        dirs.push((target - s).normalize());
    }
    let (rs, rd) = (
        wp::Array::from_slice(&starts, &dev)?,
        wp::Array::from_slice(&dirs, &dev)?,
    );
    let rays = median_ms(|| wp::launch(query_ray, n, (&mesh, &rs, &rd, &out), &dev))?;
    let t = out.to_vec()?;
    let hits = t.iter().filter(|&&x| x >= 0.0).count() as f64 / n as f64;
    let (mut worst, mut missed) = (0.0f64, 0usize);
    for k in (0..500).map(|k| k * (n / 500)) {
        let exact = meshes::brute_ray(&torus, starts[k].as_dvec3(), dirs[k].as_dvec3());
        match (exact, t[k] >= 0.0) {
            (Some(e), true) => worst = worst.max((t[k] as f64 - e).abs()),
            (None, false) => {}
            _ => missed += 1,
        }
    }
    row(
        "mesh_query_ray",
        rays,
        "query_ray_ms",
        format!(
            "hits {:.1}% (Warp {}); t vs brute force: max {worst:.1e}, {missed} of 500 disagree",
            hits * 100.0,
            theirs("ray_hit_fraction").map_or("-".into(), |h| format!("{:.1}%", h * 100.0))
        ),
    );

    // A Bvh of 1M boxes.
    let (mut lo, mut hi) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for _ in 0..n {
        let c = Vec3::new(r.random::<f32>(), r.random::<f32>(), r.random::<f32>()) * 10.0;
        let h = Vec3::new(r.random::<f32>(), r.random::<f32>(), r.random::<f32>()) * 0.05
            + Vec3::splat(0.025);
        lo.push(c - h);
        hi.push(c + h);
    }
    let (l, h) = (
        wp::Array::from_slice(&lo, &dev)?,
        wp::Array::from_slice(&hi, &dev)?,
    );
    let bvh_build = median_ms(|| wp::Bvh::new(&l, &h).map(drop))?;
    row(
        "bvh build, 1M boxes",
        bvh_build,
        "bvh_build_ms",
        String::new(),
    );
    let mut bvh = wp::Bvh::new(&l, &h)?;
    let bvh_refit = median_ms(|| bvh.refit())?;
    row("bvh refit", bvh_refit, "bvh_refit_ms", String::new());
    let counts = wp::Array::<i32>::zeros(n, &dev)?;
    let overlaps = median_ms(|| wp::launch(count_overlaps, n, (&bvh, &l, &h, &counts), &dev))?;
    let c = counts.to_vec()?;
    let mean = c.iter().map(|&x| x as f64).sum::<f64>() / n as f64;
    let overlap = |a: usize, b: usize| (lo[a].cmple(hi[b]) & lo[b].cmple(hi[a])).all();
    let wrong = (0..2000)
        .map(|k| k * (n / 2000))
        .filter(|&k| (0..n).filter(|&j| overlap(k, j)).count() != c[k] as usize)
        .count();
    row(
        "bvh_query_aabb, 1M boxes",
        overlaps,
        "bvh_query_aabb_ms",
        format!(
            "{mean:.2} overlaps each (Warp {}); {wrong} of 2000 counts differ from brute force",
            theirs("bvh_mean_overlaps").map_or("-".into(), |m| format!("{m:.2}"))
        ),
    );

    // The CPU backend: 100K unsigned point queries, all threads.
    let cpu = wp::get_device("cpu")?;
    let nc = 100_000;
    let cpu_mesh = wp::Mesh::new(
        &wp::Array::from_slice(&torus.points, &cpu)?,
        &wp::Array::from_slice(&torus.indices, &cpu)?,
        None,
    )?;
    let qc = wp::Array::from_slice(&qs[..nc], &cpu)?;
    let oc = wp::Array::<f32>::zeros(nc, &cpu)?;
    let start = Instant::now();
    wp::launch(query_point_no_sign, nc, (&cpu_mesh, &qc, &oc), &cpu)?;
    let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
    let dc = oc.to_vec()?;
    let differ = dc.iter().zip(&d[..nc]).filter(|(a, b)| a != b).count();
    println!(
        "CPU ({} threads), {nc} mesh_query_point_no_sign: {cpu_ms:.1} ms; Warp 1.19 \
         single-threaded CPU (DESIGN.md): 1908 ms, speed-up {:.1}x (goal >= 10x); distances \
         differ from the GPU's at {differ} points (the CPU tree is SAH-built, the GPU's a \
         linear BVH: the same closest distance, found through other nodes)",
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        1908.0 / cpu_ms
    );
    let _ = DVec3::ZERO;
    Ok(())
}

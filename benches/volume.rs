//! GPU benchmark of the sparse volumes and marching cubes against NVIDIA Warp timed on the
//! same GPU in the same run (`benches/py/warp_volume.py`, the issue's workloads), each result's
//! error against a closed form next to its time.
//!
//! ```text
//! cargo bench --bench volume                   # needs a CUDA device; SKIPPED otherwise
//! # on the GPU machine, with Warp unpacked by ../shared/tools/warp-bundle:
//! PYTHONPATH=/root/warp-lang .gpu/bin/volume-*
//! ```
//!
//! - A sparse SDF over a 256^3 index box (voxel size 1/128, origin -1): the 8^3 leaves whose
//!   centres lie within 16 voxels of a torus (R = 0.6, r = 0.25, axis y), allocated by tiles
//!   with background 0.1, every voxel storing the torus's exact SDF (a kernel's
//!   `volume_store`). Timed: the allocation and the fill.
//! - 1M points uniform in the band |sdf| < 0.05: `volume_world_to_index` then a trilinear
//!   `volume_sample`; the error against the exact SDF (max over all points) next to the time.
//! - Allocation from 1M world points uniform in the band: `Volume::allocate_by_voxels` of
//!   their voxels (an OnIndex grid), starting from the points in GPU memory.
//! - Marching cubes of the 256^3 dense torus SDF at 0: the largest distance of a vertex from
//!   the exact surface next to the time.

use warp_lang as wp;
use wp::prelude::*;

mod common;

use common::{json_number, median_ms, python_side, ratio};
use rand::Rng as _;

const RES: usize = 256;
const H: f64 = 2.0 / RES as f64;
const MAJOR: f32 = 0.6;
const MINOR: f32 = 0.25;

#[wp::func]
fn torus_sdf(p: Vec3) -> f32 {
    let q = vec2(length(vec2(p.x, p.z)) - MAJOR, p.y);
    length(q) - MINOR
}

/// Every voxel of the tiles (`tid() = (tile, voxel)`) stores the SDF at its centre.
#[wp::kernel]
fn fill_tiles(vol: Volume<f32>, tiles: Array<IVec3>) {
    let (t, v) = tid();
    let o = tiles[t];
    let i = o.x + (v / 64) as i32;
    let j = o.y + (v / 8 % 8) as i32;
    let k = o.z + (v % 8) as i32;
    let p = volume_index_to_world(vol, vec3(i as f32, j as f32, k as f32));
    volume_store(vol, i, j, k, torus_sdf(p));
}

#[wp::kernel]
fn sample(vol: Volume<f32>, pts: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    out[i] = volume_sample(vol, volume_world_to_index(vol, pts[i]), VOLUME_LINEAR);
}

#[wp::kernel]
fn dense_sdf(out: Array<f32, 3>, h: f32) {
    let (i, j, k) = tid();
    out[(i, j, k)] = torus_sdf(vec3(i as f32, j as f32, k as f32) * h - Vec3::splat(1.0));
}

fn sdf64(p: Vec3) -> f64 {
    let p = p.as_dvec3();
    let q = glam::DVec2::new(glam::DVec2::new(p.x, p.z).length() - MAJOR as f64, p.y);
    q.length() - MINOR as f64
}

/// The leaf origins of the box whose centre is within 16 voxels of the surface (every
/// trilinear tap of a point within 0.05 of it then lands in an allocated leaf).
fn band_tiles() -> Vec<IVec3> {
    let mut t = Vec::new();
    for a in (0..RES).step_by(8) {
        for b in (0..RES).step_by(8) {
            for c in (0..RES).step_by(8) {
                let centre = [a, b, c].map(|x| (-1.0 + (x as f64 + 3.5) * H) as f32);
                if sdf64(Vec3::from_array(centre)).abs() < 16.0 * H {
                    t.push(IVec3::new(a as i32, b as i32, c as i32));
                }
            }
        }
    }
    t
}

/// `n` points uniform in the band `|sdf| < band`.
fn band_points(n: usize, band: f64, r: &mut common::Rng) -> Vec<Vec3> {
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let p = Vec3::new(
            r.random::<f32>() * 2.0 - 1.0,
            (r.random::<f32>() * 2.0 - 1.0) * 0.45,
            r.random::<f32>() * 2.0 - 1.0,
        );
        if sdf64(p).abs() < band {
            out.push(p);
        }
    }
    out
}

fn main() -> wp::Result<()> {
    wp::init();
    let dev = match wp::get_device("cuda:0") {
        Ok(d) => d,
        Err(e) => {
            println!("volume bench SKIPPED: no CUDA device ({e})");
            return Ok(());
        }
    };
    println!("volume bench on {dev}");
    let n = 1_000_000usize;
    let warp = python_side("benches/py/warp_volume.py", &[n.to_string()]);
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
    println!(
        "                                   warp-lang  Warp 1.19, ratio warp-lang / Warp   error"
    );

    // The sparse SDF.
    let tiles_h = band_tiles();
    let tiles = wp::Array::from_slice(&tiles_h, &dev)?;
    let map = wp::VolumeMap::uniform(H, [-1.0; 3]);
    let build = || -> wp::Result<wp::Volume<f32>> {
        let vol = wp::Volume::allocate_by_tiles(&tiles_h, 0.1f32, &map, &dev)?;
        wp::launch(fill_tiles, (tiles_h.len(), 512), (&vol, &tiles), &dev)?;
        Ok(vol)
    };
    let build_ms = median_ms(|| build().map(drop))?;
    row(
        "sparse SDF: allocate by tiles + fill",
        build_ms,
        "sdf_build_ms",
        format!(
            "{} leaves (Warp: {})",
            tiles_h.len(),
            theirs("tiles").map_or("-".into(), |t| format!("{t}"))
        ),
    );
    let vol = build()?;
    let mut r = common::rng(0x5eed_1234);
    let pts_h = band_points(n, 0.05, &mut r);
    let pts = wp::Array::from_slice(&pts_h, &dev)?;
    let out = wp::Array::<f32>::zeros(n, &dev)?;
    let ms = median_ms(|| wp::launch(sample, n, (&vol, &pts, &out), &dev))?;
    let got = out.to_vec()?;
    let worst = pts_h
        .iter()
        .zip(&got)
        .map(|(p, d)| (*d as f64 - sdf64(*p)).abs())
        .fold(0.0, f64::max);
    let mean = got.iter().map(|x| *x as f64).sum::<f64>() / n as f64;
    row(
        "1M trilinear samples (sparse SDF)",
        ms,
        "sample_ms",
        format!(
            "max |d - exact| {worst:.1e} (h = {H:.1e}); mean {mean:.4} (Warp's: {})",
            theirs("mean_sample").map_or("-".into(), |m| format!("{m:.4}"))
        ),
    );

    // Allocation from 1M points already on the GPU.
    let alloc_h = band_points(n, 0.05, &mut r);
    let alloc = wp::Array::from_slice(&alloc_h, &dev)?;
    let mut voxels = 0;
    let ms = median_ms(|| {
        let v = wp::Volume::allocate_by_points(&alloc, &map)?;
        voxels = v.voxel_count();
        Ok(())
    })?;
    row(
        "allocate_by_voxels, 1M points",
        ms,
        "allocate_voxels_ms",
        format!(
            "{voxels} active voxels (Warp: {})",
            theirs("allocated_voxels").map_or("-".into(), |t| format!("{t}"))
        ),
    );

    // Marching cubes of the dense field.
    let field = wp::Array::<f32, 3>::zeros((RES, RES, RES), &dev)?;
    let step = 2.0 / (RES - 1) as f32;
    wp::launch(dense_sdf, (RES, RES, RES), (&field, step), &dev)?;
    let mut mc = wp::MarchingCubes::new(RES, RES, RES, &dev)?;
    let ms = median_ms(|| mc.surface(&field, 0.0))?;
    let verts = mc.verts().to_vec()?;
    let tris = mc.indices().len() / 3;
    // Vertices are in grid-index space: to the world box [-1, 1]^3.
    let worst = verts
        .iter()
        .map(|v| sdf64(*v * step - Vec3::ONE).abs())
        .fold(0.0, f64::max);
    row(
        "marching cubes 256^3",
        ms,
        "mc_ms",
        format!(
            "{tris} triangles (Warp: {}); max vertex |sdf| {worst:.1e} (h = {step:.1e})",
            theirs("mc_triangles").map_or("-".into(), |t| format!("{t}"))
        ),
    );
    Ok(())
}

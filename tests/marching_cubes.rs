//! `wp::MarchingCubes` (Warp's marching cubes): the tables, the meshes of closed-form fields
//! against their exact surfaces, topology and orientation, Warp 1.19's own output, bad input,
//! the C++ steps (`warp-cuda/cuda/wp_marching_cubes.h`) against the CPU bit for bit on the host
//! (g++), and the CPU against a GPU (skipped, saying so, without one).
//!
//! Orientation rule under test: a node is outside where its value is `>= threshold`; the
//! triangles wind counter-clockwise seen from outside, so for a signed distance (negative
//! inside) the normals `(b - a) x (c - a)` point out and a closed surface's signed volume is
//! positive.

use std::collections::HashMap;
use std::process::Command;

use warp_lang as wp;
use wp::prelude::*;
use wp::MarchingCubes;

#[path = "common/host_cpp.rs"]
mod host_cpp;

// ------------------------------------------------------------------------------------------
// Helpers
// ------------------------------------------------------------------------------------------

/// The values of `f(i, j, k)` on a `dims` grid, row-major with z fastest (Warp's `[x, y, z]`).
fn grid(dims: [usize; 3], f: impl Fn(f64, f64, f64) -> f64) -> Vec<f32> {
    let mut v = Vec::with_capacity(dims.iter().product());
    for i in 0..dims[0] {
        for j in 0..dims[1] {
            for k in 0..dims[2] {
                v.push(f(i as f64, j as f64, k as f64) as f32);
            }
        }
    }
    v
}

/// The mesh of `values` (a `dims` field) at `threshold` on `dev`: vertices and flat indices.
fn surface(
    dev: &wp::Device,
    dims: [usize; 3],
    values: &[f32],
    threshold: f32,
) -> (Vec<Vec3>, Vec<i32>) {
    let field = wp::Array::from_slice_shape(values, (dims[0], dims[1], dims[2]), dev).unwrap();
    let mut mc = MarchingCubes::new(dims[0], dims[1], dims[2], dev).unwrap();
    mc.surface(&field, threshold).unwrap();
    (mc.verts().to_vec().unwrap(), mc.indices().to_vec().unwrap())
}

/// Checks that the mesh is closed and consistently oriented, and returns its Euler
/// characteristic `V - E + F`: every index names a vertex, every vertex is used, no triangle
/// repeats a vertex, and every directed edge `a -> b` occurs exactly once with its twin
/// `b -> a` also occurring exactly once (so every edge has two triangles, which traverse it in
/// opposite directions).
fn closed_euler(nverts: usize, idx: &[i32]) -> Result<i64, String> {
    if !idx.len().is_multiple_of(3) {
        return Err(format!("{} indices", idx.len()));
    }
    let mut used = vec![false; nverts];
    let mut directed: HashMap<(i32, i32), usize> = HashMap::new();
    for (t, tri) in idx.chunks_exact(3).enumerate() {
        for &v in tri {
            if v < 0 || v as usize >= nverts {
                return Err(format!("triangle {t} has index {v} of {nverts} vertices"));
            }
            used[v as usize] = true;
        }
        if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
            return Err(format!("triangle {t} repeats a vertex: {tri:?}"));
        }
        for e in 0..3 {
            *directed.entry((tri[e], tri[(e + 1) % 3])).or_default() += 1;
        }
    }
    if let Some(v) = used.iter().position(|u| !u) {
        return Err(format!("vertex {v} is in no triangle"));
    }
    for (&(a, b), &n) in &directed {
        if n != 1 {
            return Err(format!("directed edge {a} -> {b} occurs {n} times"));
        }
        if directed.get(&(b, a)) != Some(&1) {
            return Err(format!(
                "edge {a} -> {b} has no twin {b} -> {a}: a hole or a flip"
            ));
        }
    }
    let (v, e, f) = (
        nverts as i64,
        (directed.len() / 2) as i64,
        (idx.len() / 3) as i64,
    );
    Ok(v - e + f)
}

/// The signed volume of a closed mesh (positive when the normals point out), in f64.
fn signed_volume(verts: &[Vec3], idx: &[i32]) -> f64 {
    idx.chunks_exact(3)
        .map(|t| {
            let [a, b, c] = [0, 1, 2].map(|k| verts[t[k] as usize].as_dvec3());
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

/// The sphere of radius `r` around `c`, as a signed distance (negative inside).
fn sphere(c: [f64; 3], r: f64) -> impl Fn(f64, f64, f64) -> f64 {
    move |x, y, z| ((x - c[0]).powi(2) + (y - c[1]).powi(2) + (z - c[2]).powi(2)).sqrt() - r
}

/// The torus around the z axis through `c`, radii `big` (to the tube's centre) and `small`
/// (the tube's), as a signed distance.
fn torus(c: [f64; 3], big: f64, small: f64) -> impl Fn(f64, f64, f64) -> f64 {
    move |x, y, z| {
        let (x, y, z) = (x - c[0], y - c[1], z - c[2]);
        let q = (x * x + y * y).sqrt() - big;
        (q * q + z * z).sqrt() - small
    }
}

/// A small deterministic generator (xorshift) for the random fields.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    /// An integer in `lo..=hi`.
    fn int(&mut self, lo: i64, hi: i64) -> i64 {
        lo + (self.next() % (hi - lo + 1) as u64) as i64
    }
    /// A float in [0, 1).
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// `inner` (a `dims` field) padded with one layer of `outside` on every side.
fn padded(dims: [usize; 3], inner: &[f32], outside: f32) -> ([usize; 3], Vec<f32>) {
    let p = dims.map(|d| d + 2);
    let mut v = vec![outside; p.iter().product()];
    for i in 0..dims[0] {
        for j in 0..dims[1] {
            for k in 0..dims[2] {
                v[((i + 1) * p[1] + j + 1) * p[2] + k + 1] = inner[(i * dims[1] + j) * dims[2] + k];
            }
        }
    }
    (p, v)
}

// ------------------------------------------------------------------------------------------
// The tables
// ------------------------------------------------------------------------------------------

/// The tables' own consistency: the derived grid-edge table is Warp's, every triangle's edges
/// are crossed in its case (endpoints on different sides), complementary cases have as many
/// vertices, and the tables have Warp's sizes and extremes.
#[test]
fn tables_are_consistent() {
    // Warp 1.19's `_MC_EDGE_OFFSETS`.
    let warp: [[u8; 4]; 12] = [
        [0, 0, 0, 0],
        [1, 0, 0, 1],
        [0, 1, 0, 0],
        [0, 0, 0, 1],
        [0, 0, 1, 0],
        [1, 0, 1, 1],
        [0, 1, 1, 0],
        [0, 0, 1, 1],
        [0, 0, 0, 2],
        [1, 0, 0, 2],
        [1, 1, 0, 2],
        [0, 1, 0, 2],
    ];
    assert_eq!(MarchingCubes::EDGE_GRID_OFFSETS, warp);
    let r = MarchingCubes::CASE_TO_TRI_RANGE;
    assert_eq!((r[0], r[1], r[255], r[256]), (0, 0, 2460, 2460));
    for c in 0..256usize {
        let tris = &MarchingCubes::TRI_LOCAL_INDICES[r[c] as usize..r[c + 1] as usize];
        assert_eq!(tris.len() % 3, 0, "case {c}");
        let mut crossed = 0u16;
        for &e in tris {
            let [a, b] = MarchingCubes::EDGE_TO_CORNERS[e as usize];
            assert_ne!(
                (c >> a) & 1,
                (c >> b) & 1,
                "case {c} uses uncrossed edge {e}"
            );
            crossed |= 1 << e;
        }
        // Every crossed edge of the case has its vertex in a triangle.
        for (e, [a, b]) in MarchingCubes::EDGE_TO_CORNERS.iter().enumerate() {
            let is_crossed = (c >> a) & 1 != (c >> b) & 1;
            assert_eq!(is_crossed, crossed >> e & 1 == 1, "case {c} edge {e}");
        }
    }
    let max = (0..256).map(|c| r[c + 1] - r[c]).max().unwrap();
    assert_eq!(max, 15);
}

// ------------------------------------------------------------------------------------------
// Closed-form fields
// ------------------------------------------------------------------------------------------

/// A sphere of radius 15 (grid spacing h = 1): every vertex within h^2 / (8 (r - h)) + 1e-4 of
/// the sphere (a vertex is where the linear interpolant of the distance along its edge is
/// zero, so its distance to the sphere is the interpolation error of the distance function,
/// at most h^2 / 8 times its second derivative along the edge, which is at most 1 / (r - h)
/// within h of the sphere; 1e-4 covers the f32 field and arithmetic at coordinates below 50),
/// closed, Euler characteristic 2, normals out (signed volume positive, and every normal away
/// from the centre), and the volume within 3 d / r of 4/3 pi r^3, where d bounds how far a
/// triangle's points are from the sphere: the vertex error plus the linear interpolation error
/// over a triangle inside a cell, at most M R^2 / 2 with R = sqrt(3) h / 2 the radius of a
/// ball around the cell and M = 1 / (r - 2 h) the curvature bound there (a volume deficit of
/// at most area * d = 3 d / r of the volume: 0.8%).
#[test]
fn sphere_is_close_closed_and_outward() {
    let dev = wp::cpu();
    let dims = [40, 42, 44];
    let (c, r) = ([19.3, 20.6, 21.1], 15.0);
    let (verts, idx) = surface(&dev, dims, &grid(dims, sphere(c, r)), 0.0);
    let tol = 1.0 / (8.0 * (r - 1.0)) + 1e-4;
    let err = verts
        .iter()
        .map(|v| sphere(c, r)(v.x as f64, v.y as f64, v.z as f64).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "sphere: {} vertices, {} triangles, max distance {err:.2e} (tolerance {tol:.2e})",
        verts.len(),
        idx.len() / 3
    );
    assert!(err <= tol, "a vertex is {err} from the sphere");
    assert!(err > 1e-4, "suspiciously exact: {err}");
    assert_eq!(closed_euler(verts.len(), &idx), Ok(2));
    let vol = signed_volume(&verts, &idx);
    let exact = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
    eprintln!("sphere volume {vol:.3} against {exact:.3}");
    assert!(vol > 0.0, "inward normals: volume {vol}");
    let d = 3.0 / (8.0 * (r - 2.0)) + tol;
    assert!(
        (vol - exact).abs() < 3.0 * d / r * exact,
        "{vol} against {exact}"
    );
    // Every triangle's normal points away from the centre (a local check of orientation).
    for t in idx.chunks_exact(3) {
        let [a, b, cc] = [0, 1, 2].map(|k| verts[t[k] as usize]);
        let n = (b - a).cross(cc - a);
        let m = (a + b + cc) / 3.0 - Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32);
        assert!(n.dot(m) >= 0.0, "triangle {t:?} faces inwards");
    }
}

/// A torus (radii R = 12 and r = 5 around the z axis): every vertex within h^2 / 8 * M + 1e-4
/// of it, with M = max(1 / (r - h), 1 / (R - r - h)) (the distance's second derivative is at
/// most the larger curvature of its level sets within h of the surface: around the tube
/// 1 / (r - h), around the axis at most 1 / (R - r - h)), closed, Euler characteristic 0,
/// normals out, and the volume within 2 d / r of 2 pi^2 R r^2 (d as for the sphere, with the
/// curvature bound taken at 2 h: 6.3%; the measured deficit is 0.8%).
#[test]
fn torus_is_close_closed_and_outward() {
    let dev = wp::cpu();
    let dims = [40, 38, 20];
    let (c, big, small) = ([19.4, 18.7, 9.6], 12.0, 5.0);
    let (verts, idx) = surface(&dev, dims, &grid(dims, torus(c, big, small)), 0.0);
    let tol = (1.0f64 / (small - 1.0)).max(1.0 / (big - small - 1.0)) / 8.0 + 1e-4;
    let err = verts
        .iter()
        .map(|v| torus(c, big, small)(v.x as f64, v.y as f64, v.z as f64).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "torus: {} vertices, {} triangles, max distance {err:.2e} (tolerance {tol:.2e})",
        verts.len(),
        idx.len() / 3
    );
    assert!(err <= tol, "a vertex is {err} from the torus");
    assert_eq!(closed_euler(verts.len(), &idx), Ok(0));
    let vol = signed_volume(&verts, &idx);
    let exact = 2.0 * std::f64::consts::PI.powi(2) * big * small * small;
    eprintln!("torus volume {vol:.3} against {exact:.3}");
    let d = 3.0 / 8.0 * (1.0f64 / (small - 2.0)).max(1.0 / (big - small - 2.0)) + tol;
    assert!(vol > 0.0, "inward normals: volume {vol}");
    assert!(
        (vol - exact).abs() < 2.0 * d / small * exact,
        "{vol} against {exact}"
    );
}

/// Planes: `x_a - 3.3` along each axis gives vertices all with exactly the same coordinate
/// `a` (one per edge of that axis crossing the plane: n_b * n_c of them, 2 (n_b - 1)
/// (n_c - 1) triangles, each normal exactly along +a); a tilted plane (a linear field, which
/// linear interpolation reproduces up to rounding) gives vertices on it within 1e-5 and
/// normals all along its gradient.
#[test]
fn planes_are_exactly_planar() {
    let dev = wp::cpu();
    let dims = [9, 7, 6];
    for a in 0..3 {
        let values = grid(dims, |x, y, z| [x, y, z][a] - 3.3);
        let (verts, idx) = surface(&dev, dims, &values, 0.0);
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        assert_eq!(verts.len(), dims[b] * dims[c], "axis {a}");
        assert_eq!(idx.len() / 3, 2 * (dims[b] - 1) * (dims[c] - 1), "axis {a}");
        let x0 = verts[0][a];
        assert!((x0 - 3.3).abs() < 1e-6, "{x0}");
        for v in &verts {
            assert_eq!(
                v[a].to_bits(),
                x0.to_bits(),
                "axis {a}: {v:?} off the plane"
            );
        }
        for t in idx.chunks_exact(3) {
            let [p, q, r] = [0, 1, 2].map(|k| verts[t[k] as usize]);
            let n = (q - p).cross(r - p);
            assert!(
                n[a] > 0.0 && n[b] == 0.0 && n[c] == 0.0,
                "axis {a}: normal {n:?}"
            );
        }
    }
    let g = Vec3::new(1.0, 2.0, -1.5);
    let values = grid(dims, |x, y, z| x + 2.0 * y - 1.5 * z - 4.7);
    let (verts, idx) = surface(&dev, dims, &values, 0.25);
    assert!(!idx.is_empty());
    for v in &verts {
        let d = (g.dot(*v) - 4.95) / g.length();
        assert!(d.abs() < 1e-5, "{v:?} is {d} off the plane");
    }
    for t in idx.chunks_exact(3) {
        let [p, q, r] = [0, 1, 2].map(|k| verts[t[k] as usize]);
        let n = (q - p).cross(r - p);
        // Degenerate triangles (vertices at coincident positions) have no direction.
        if n.length() > 1e-4 {
            assert!(n.normalize().dot(g.normalize()) > 0.999, "normal {n:?}");
        }
    }
}

/// Every pair of face-adjacent cells, in every configuration of their 12 corners and along
/// each axis, padded with outside nodes so that the surface is closed: always closed and
/// consistently oriented (the tables resolve each ambiguous face the same way from both sides).
/// This covers every case of a single cell too.
#[test]
fn every_two_cell_configuration_is_closed() {
    let dev = wp::cpu();
    for axis in 0..3 {
        let mut dims = [2, 2, 2];
        dims[axis] = 3;
        let (pd, _) = padded(dims, &[0.0; 12], 1.0);
        let field = wp::Array::<f32, 3>::zeros((pd[0], pd[1], pd[2]), &dev).unwrap();
        let mut mc = MarchingCubes::new(pd[0], pd[1], pd[2], &dev).unwrap();
        for bits in 0..1u32 << 12 {
            let inner: Vec<f32> = (0..12)
                .map(|b| if bits >> b & 1 == 1 { 1.0 } else { -1.0 })
                .collect();
            let (_, values) = padded(dims, &inner, 1.0);
            let flat = field.reshape(values.len()).unwrap();
            let host = wp::Array::from_slice(&values, &dev).unwrap();
            flat.copy_from(&host).unwrap();
            mc.surface(&field, 0.0).unwrap();
            let verts = mc.verts().to_vec().unwrap();
            let idx = mc.indices().to_vec().unwrap();
            if let Err(e) = closed_euler(verts.len(), &idx) {
                panic!("axis {axis}, corners {bits:012b}: {e}");
            }
            if bits == (1 << 12) - 1 {
                assert!(
                    verts.is_empty() && idx.is_empty(),
                    "all outside: no surface"
                );
            }
        }
    }
}

/// Random fields of small integers (so that many node values equal the threshold exactly),
/// padded with outside nodes: closed and consistently oriented, and the signed volume is
/// positive whenever there is a surface.
#[test]
fn random_fields_with_ties_are_closed() {
    let dev = wp::cpu();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for round in 0..12 {
        let dims = [
            rng.int(2, 12) as usize,
            rng.int(2, 12) as usize,
            rng.int(2, 12) as usize,
        ];
        let inner: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|_| rng.int(-2, 2) as f32)
            .collect();
        let (pd, values) = padded(dims, &inner, 1.0);
        let (verts, idx) = surface(&dev, pd, &values, 0.0);
        if let Err(e) = closed_euler(verts.len(), &idx) {
            panic!("round {round}, dims {dims:?}: {e}");
        }
        if !idx.is_empty() {
            let vol = signed_volume(&verts, &idx);
            assert!(vol > 0.0, "round {round}: volume {vol}");
        }
    }
}

// ------------------------------------------------------------------------------------------
// Warp's conventions and output
// ------------------------------------------------------------------------------------------

// What Warp 1.19 (`wp.MarchingCubes(6, 5, 7).surface(field, 0.0)` on the CPU) returned for
// the field `(i - 2.5)^2 + (j - 2)^2 + 0.5 (k - 3)^2 - 4.25` (exact in f32, with nodes exactly
// at the threshold).

/// Warp 1.19's vertices for that field, as f32 bits (x, y, z per vertex).
#[rustfmt::skip]
const WARP_VERTS: [u32; 258] = [
    0x3f600000, 0x3f800000, 0x40000000, 0x3f400000, 0x3f800000, 0x40400000, 0x3f600000, 0x3f800000,
    0x40800000, 0x3f200000, 0x40000000, 0x40000000, 0x3f000000, 0x40000000, 0x40400000, 0x3f200000,
    0x40000000, 0x40800000, 0x3f600000, 0x40400000, 0x40000000, 0x3f400000, 0x40400000, 0x40400000,
    0x3f600000, 0x40400000, 0x40800000, 0x3f800000, 0x3f555555, 0x40000000, 0x3f800000, 0x3f2aaaab,
    0x40400000, 0x3f800000, 0x3f555555, 0x40800000, 0x3fc00000, 0x3f800000, 0x3f800000, 0x3f800000,
    0x3f800000, 0x3fd55556, 0x3f800000, 0x3f800000, 0x408aaaaa, 0x3fc00000, 0x3f800000, 0x40a00000,
    0x3f800000, 0x40000000, 0x3f800000, 0x3f800000, 0x40000000, 0x3f800000, 0x3f800000, 0x40000000,
    0x40a00000, 0x3f800000, 0x40000000, 0x40a00000, 0x3fc00000, 0x40400000, 0x3f800000, 0x3f800000,
    0x40400000, 0x3fd55556, 0x3f800000, 0x404aaaab, 0x40000000, 0x3f800000, 0x40555555, 0x40400000,
    0x3f800000, 0x404aaaab, 0x40800000, 0x3f800000, 0x40400000, 0x408aaaaa, 0x3fc00000, 0x40400000,
    0x40a00000, 0x40000000, 0x3f2aaaab, 0x3f800000, 0x40000000, 0x3e2aaaab, 0x40000000, 0x40000000,
    0x00000000, 0x40400000, 0x40000000, 0x3e2aaaab, 0x40800000, 0x40000000, 0x3f2aaaab, 0x40a00000,
    0x40000000, 0x3f800000, 0x3f19999a, 0x40000000, 0x3f800000, 0x40accccd, 0x40000000, 0x40000000,
    0x3e4ccccd, 0x40000000, 0x40000000, 0x40b9999a, 0x40000000, 0x40400000, 0x3f19999a, 0x40000000,
    0x40555555, 0x3f800000, 0x40000000, 0x40755555, 0x40000000, 0x40000000, 0x40800000, 0x40400000,
    0x40000000, 0x40755555, 0x40800000, 0x40000000, 0x40555555, 0x40a00000, 0x40000000, 0x40400000,
    0x40accccd, 0x40400000, 0x3f2aaaab, 0x3f800000, 0x40400000, 0x3e2aaaab, 0x40000000, 0x40400000,
    0x00000000, 0x40400000, 0x40400000, 0x3e2aaaab, 0x40800000, 0x40400000, 0x3f2aaaab, 0x40a00000,
    0x40400000, 0x3f800000, 0x3f19999a, 0x40600000, 0x3f800000, 0x3f800000, 0x40600000, 0x3f800000,
    0x40a00000, 0x40400000, 0x3f800000, 0x40accccd, 0x40400000, 0x40000000, 0x3e4ccccd, 0x40800000,
    0x40000000, 0x3f800000, 0x40800000, 0x40000000, 0x40a00000, 0x40400000, 0x40000000, 0x40b9999a,
    0x40400000, 0x40400000, 0x3f19999a, 0x40600000, 0x40400000, 0x3f800000, 0x40400000, 0x40555555,
    0x3f800000, 0x40400000, 0x40755555, 0x40000000, 0x40400000, 0x40800000, 0x40400000, 0x40400000,
    0x40755555, 0x40800000, 0x40600000, 0x40400000, 0x40a00000, 0x40400000, 0x40555555, 0x40a00000,
    0x40400000, 0x40400000, 0x40accccd, 0x40800000, 0x3f555555, 0x40000000, 0x40800000, 0x3f2aaaab,
    0x40400000, 0x40800000, 0x3f555555, 0x40800000, 0x40800000, 0x3f800000, 0x3fd55556, 0x40840000,
    0x3f800000, 0x40000000, 0x40880000, 0x3f800000, 0x40400000, 0x40840000, 0x3f800000, 0x40800000,
    0x40800000, 0x3f800000, 0x408aaaaa, 0x40800000, 0x40000000, 0x3f800000, 0x408c0000, 0x40000000,
    0x40000000, 0x40900000, 0x40000000, 0x40400000, 0x408c0000, 0x40000000, 0x40800000, 0x40800000,
    0x40000000, 0x40a00000, 0x40800000, 0x40400000, 0x3fd55556, 0x40840000, 0x40400000, 0x40000000,
    0x40800000, 0x404aaaab, 0x40000000, 0x40880000, 0x40400000, 0x40400000, 0x40800000, 0x40555555,
    0x40400000, 0x40840000, 0x40400000, 0x40800000, 0x40800000, 0x404aaaab, 0x40800000, 0x40800000,
    0x40400000, 0x408aaaaa,
];

/// Warp 1.19's indices for that field.
#[rustfmt::skip]
const WARP_INDICES: [i32; 504] = [
    13, 9, 0, 9, 10, 1, 0, 9, 1, 10, 11, 2, 1, 10, 2, 11, 14, 2, 17, 13, 0, 3, 17, 0,
    0, 1, 3, 1, 4, 3, 1, 2, 4, 2, 5, 4, 14, 18, 5, 2, 14, 5, 21, 17, 3, 6, 21, 3,
    3, 4, 6, 4, 7, 6, 4, 5, 7, 5, 8, 7, 18, 25, 8, 5, 18, 8, 21, 6, 22, 6, 7, 23,
    22, 6, 23, 7, 8, 24, 23, 7, 24, 8, 25, 24, 32, 27, 12, 13, 12, 27, 13, 27, 9, 9, 27, 28,
    28, 29, 9, 9, 29, 10, 29, 30, 10, 10, 30, 11, 15, 14, 11, 15, 11, 31, 31, 11, 30, 31, 33, 15,
    34, 32, 12, 16, 34, 12, 12, 17, 16, 13, 17, 12, 19, 14, 15, 18, 14, 19, 33, 35, 19, 15, 33, 19,
    36, 34, 16, 20, 36, 16, 16, 21, 20, 17, 21, 16, 26, 18, 19, 25, 18, 26, 35, 42, 26, 19, 35, 26,
    36, 20, 37, 20, 21, 22, 20, 22, 37, 37, 22, 38, 38, 22, 39, 22, 23, 39, 39, 23, 40, 23, 24, 40,
    25, 26, 41, 25, 41, 24, 24, 41, 40, 26, 42, 41, 32, 48, 43, 27, 32, 43, 43, 44, 27, 27, 44, 28,
    44, 45, 28, 28, 45, 29, 45, 46, 29, 29, 46, 30, 46, 47, 30, 30, 47, 31, 31, 47, 51, 33, 31, 51,
    48, 32, 52, 52, 32, 34, 51, 55, 33, 55, 35, 33, 52, 34, 56, 56, 34, 36, 55, 64, 35, 64, 42, 35,
    56, 36, 37, 58, 56, 37, 58, 37, 59, 37, 38, 59, 59, 38, 60, 38, 39, 60, 60, 39, 61, 39, 40, 61,
    61, 40, 63, 40, 41, 63, 63, 41, 42, 64, 63, 42, 43, 48, 49, 49, 68, 65, 49, 65, 43, 43, 65, 44,
    65, 66, 44, 44, 66, 45, 66, 67, 45, 45, 67, 46, 72, 50, 47, 72, 47, 67, 67, 47, 46, 47, 50, 51,
    53, 49, 48, 52, 53, 48, 68, 53, 73, 49, 53, 68, 77, 50, 72, 54, 50, 77, 50, 54, 55, 51, 50, 55,
    57, 53, 52, 56, 57, 52, 73, 57, 78, 53, 57, 73, 85, 54, 77, 62, 54, 85, 54, 62, 64, 55, 54, 64,
    57, 56, 58, 78, 57, 58, 78, 58, 80, 80, 58, 59, 80, 59, 82, 59, 60, 82, 82, 60, 84, 60, 61, 84,
    62, 85, 84, 62, 84, 63, 63, 84, 61, 62, 63, 64, 65, 68, 69, 66, 65, 69, 70, 66, 69, 67, 66, 70,
    71, 67, 70, 67, 71, 72, 74, 69, 68, 73, 74, 68, 69, 74, 70, 70, 74, 75, 70, 75, 71, 71, 75, 76,
    71, 76, 77, 72, 71, 77, 79, 74, 73, 78, 79, 73, 74, 79, 75, 75, 79, 81, 75, 81, 76, 76, 81, 83,
    76, 83, 85, 77, 76, 85, 79, 78, 80, 81, 79, 80, 82, 81, 80, 83, 81, 82, 84, 83, 82, 83, 84, 85,
];

/// The same field gives Warp's mesh: the same indices, and the same vertices (the coordinate
/// along each vertex's edge bit for bit; Warp interpolates the other two as well,
/// `p * (1 - t) + p * t`, which may differ from `p` by an ulp: within 1 ulp of Warp's there).
#[test]
fn matches_warp_1_19() {
    let dims = [6, 5, 7];
    let values = grid(dims, |i, j, k| {
        (i - 2.5).powi(2) + (j - 2.0).powi(2) + 0.5 * (k - 3.0).powi(2) - 4.25
    });
    let (verts, idx) = surface(&wp::cpu(), dims, &values, 0.0);
    let want_verts = WARP_VERTS;
    assert_eq!(verts.len() * 3, want_verts.len());
    assert_eq!(idx, WARP_INDICES);
    for (n, v) in verts.iter().enumerate() {
        for a in 0..3 {
            let w = f32::from_bits(want_verts[3 * n + a]);
            let ulps = (v[a].to_bits() as i64 - w.to_bits() as i64).abs();
            assert!(
                ulps <= 1,
                "vertex {n} coordinate {a}: {} against Warp's {w}",
                v[a]
            );
        }
    }
}

/// Bounds: node (0, 0, 0) at `lower`, the last node at `upper`; the default (neither set) is
/// grid-index space, and setting the defaults explicitly changes nothing, bit for bit.
#[test]
fn bounds_map_the_grid() {
    let dev = wp::cpu();
    let dims = [12, 10, 9];
    let values = grid(dims, sphere([5.5, 4.4, 4.1], 3.3));
    let field = wp::Array::from_slice_shape(&values, (12, 10, 9), &dev).unwrap();
    let mut mc = MarchingCubes::new(12, 10, 9, &dev).unwrap();
    mc.surface(&field, 0.0).unwrap();
    let plain = mc.verts().to_vec().unwrap();
    let idx = mc.indices().to_vec().unwrap();
    mc.set_bounds(Some(Vec3::ZERO), Some(Vec3::new(11.0, 9.0, 8.0)))
        .unwrap();
    mc.surface(&field, 0.0).unwrap();
    assert_eq!(mc.verts().to_vec().unwrap(), plain);
    let (lo, hi) = (Vec3::new(-1.0, 2.0, 0.5), Vec3::new(1.0, 3.0, 4.5));
    mc.set_bounds(Some(lo), Some(hi)).unwrap();
    assert_eq!((mc.lower(), mc.upper()), (Some(lo), Some(hi)));
    mc.surface(&field, 0.0).unwrap();
    let mapped = mc.verts().to_vec().unwrap();
    assert_eq!(mc.indices().to_vec().unwrap(), idx);
    let delta = (hi - lo) / Vec3::new(11.0, 9.0, 8.0);
    for (p, m) in plain.iter().zip(&mapped) {
        let want = lo + *p * delta;
        assert!(
            (want - *m).abs().max_element() < 1e-5,
            "{m:?} against {want:?}"
        );
    }
    // Only `upper` set: the origin stays at lower = 0.
    mc.set_bounds(None, Some(Vec3::new(22.0, 18.0, 16.0)))
        .unwrap();
    mc.surface(&field, 0.0).unwrap();
    for (p, m) in plain.iter().zip(mc.verts().to_vec().unwrap()) {
        assert!((*p * 2.0 - m).abs().max_element() < 1e-5);
    }
}

/// A strided field (a transposed view) gives the mesh of its contiguous copy; a `resize`
/// takes fields of the new size; an empty surface (all values on one side) is empty and its
/// mesh is the empty mesh.
#[test]
fn strided_fields_resize_and_empty_surfaces() {
    let dev = wp::cpu();
    let dims = [7, 8, 9];
    let values = grid(dims, sphere([3.2, 3.9, 4.4], 2.7));
    // Stored as (z, y, x), viewed as (x, y, z).
    let mut zyx = vec![0.0f32; values.len()];
    for i in 0..7 {
        for j in 0..8 {
            for k in 0..9 {
                zyx[(k * 8 + j) * 7 + i] = values[(i * 8 + j) * 9 + k];
            }
        }
    }
    let stored = wp::Array::from_slice_shape(&zyx, (9, 8, 7), &dev).unwrap();
    let view = stored.transpose();
    assert!(!view.is_contiguous());
    let mut mc = MarchingCubes::new(7, 8, 9, &dev).unwrap();
    mc.surface(&view, 0.0).unwrap();
    let want = surface(&dev, dims, &values, 0.0);
    assert_eq!(mc.verts().to_vec().unwrap(), want.0);
    assert_eq!(mc.indices().to_vec().unwrap(), want.1);

    mc.resize(3, 4, 5).unwrap();
    assert_eq!(mc.dims(), [3, 4, 5]);
    let small = wp::Array::<f32, 3>::full((3, 4, 5), -1.0, &dev).unwrap();
    mc.surface(&small, 0.0).unwrap();
    assert_eq!((mc.verts().len(), mc.indices().len()), (0, 0));
    let mesh = mc.to_mesh().unwrap();
    assert_eq!(mesh.num_faces(), 0);
}

/// The mesh queries on `to_mesh`: the closest point's sign is negative inside the sphere and
/// positive outside (which needs the closed, outward mesh), and the closest point is on the
/// sphere within the chord tolerance of `sphere_is_close_closed_and_outward` (a point of a
/// triangle is within 3 h^2 / (8 (r - 2 h)) of the sphere beyond its vertices' error).
#[wp::kernel]
fn k_sign(mesh: Mesh, q: Array<Vec3>, sign: Array<f32>, cp: Array<Vec3>) {
    let i = tid();
    let (found, s, face, u, v) = mesh_query_point(mesh, q[i], 1.0e6);
    if found {
        sign[i] = s;
        cp[i] = mesh_eval_position(mesh, face, u, v);
    }
}

#[test]
fn to_mesh_has_inside_and_outside() {
    let dev = wp::cpu();
    let dims = [24, 24, 24];
    let (c, r) = ([11.6, 11.2, 12.3], 8.0);
    let values = grid(dims, sphere(c, r));
    let field = wp::Array::from_slice_shape(&values, (24, 24, 24), &dev).unwrap();
    let mut mc = MarchingCubes::new(24, 24, 24, &dev).unwrap();
    mc.surface(&field, 0.0).unwrap();
    let mesh = mc.to_mesh().unwrap();
    let mut rng = Rng(12345);
    let q: Vec<Vec3> = (0..500)
        .map(|_| Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 23.0)
        .collect();
    let qa = wp::Array::from_slice(&q, &dev).unwrap();
    let sign = wp::Array::<f32>::zeros(q.len(), &dev).unwrap();
    let cp = wp::Array::<Vec3>::zeros(q.len(), &dev).unwrap();
    wp::launch(k_sign, q.len(), (&mesh, &qa, &sign, &cp), &dev).unwrap();
    let (sign, cp) = (sign.to_vec().unwrap(), cp.to_vec().unwrap());
    let d = sphere(c, r);
    let mut checked = 0;
    for i in 0..q.len() {
        let di = d(q[i].x as f64, q[i].y as f64, q[i].z as f64);
        // Points within the mesh's distance from the sphere may fall on either side.
        if di.abs() > 0.1 {
            assert_eq!(sign[i] < 0.0, di < 0.0, "point {:?} at distance {di}", q[i]);
            checked += 1;
        }
        let e = d(cp[i].x as f64, cp[i].y as f64, cp[i].z as f64).abs();
        let tol = 3.0 / (8.0 * (r - 2.0)) + 1.0 / (8.0 * (r - 1.0)) + 1e-4;
        assert!(e < tol, "closest point {:?} is {e} off", cp[i]);
    }
    assert!(checked > 400);
}

// ------------------------------------------------------------------------------------------
// Bad input
// ------------------------------------------------------------------------------------------

/// The error text of `r`.
fn err<T: std::fmt::Debug>(r: wp::Result<T>) -> String {
    r.expect_err("should fail").to_string()
}

#[test]
fn bad_input_is_an_error() {
    let dev = wp::cpu();
    for (dims, name) in [([1, 4, 4], "nx"), ([4, 0, 4], "ny"), ([4, 4, 1], "nz")] {
        let e = err(MarchingCubes::new(dims[0], dims[1], dims[2], &dev));
        assert!(
            e.contains(&format!("`{name}`")) && e.contains("at least 2"),
            "{e}"
        );
    }
    let e = err(MarchingCubes::new(1 << 20, 1 << 20, 2, &dev));
    assert!(e.contains("nx * ny * nz"), "{e}");
    let e = err(MarchingCubes::new(usize::MAX, 2, 2, &dev));
    assert!(e.contains("nx * ny * nz"), "{e}");

    let mut mc = MarchingCubes::new(4, 5, 6, &dev).unwrap();
    let e = err(mc.resize(4, 1, 6));
    assert!(e.contains("`ny`"), "{e}");
    assert_eq!(mc.dims(), [4, 5, 6], "a failed resize changes nothing");

    let wrong = wp::Array::<f32, 3>::zeros((4, 6, 5), &dev).unwrap();
    let e = err(mc.surface(&wrong, 0.0));
    assert!(e.contains("`field`") && e.contains("[4, 6, 5]"), "{e}");

    let values = grid([4, 5, 6], sphere([1.5, 2.0, 2.5], 1.2));
    let field = wp::Array::from_slice_shape(&values, (4, 5, 6), &dev).unwrap();
    mc.surface(&field, 0.0).unwrap();
    assert!(!mc.verts().is_empty());
    for t in [f32::NAN, f32::INFINITY] {
        let e = err(mc.surface(&field, t));
        assert!(e.contains("`threshold`"), "{e}");
    }
    // A failed surface leaves the empty mesh, not the last one.
    assert_eq!((mc.verts().len(), mc.indices().len()), (0, 0));

    for (bad, shown) in [(f32::NAN, "NaN"), (f32::NEG_INFINITY, "-inf")] {
        let mut v = values.clone();
        // Nodes [3, 1, 2] and [2, 4, 5]: the first in row-major order is named.
        v[(3 * 5 + 1) * 6 + 2] = bad;
        v[(2 * 5 + 4) * 6 + 5] = f32::INFINITY;
        let f = wp::Array::from_slice_shape(&v, (4, 5, 6), &dev).unwrap();
        let e = err(mc.surface(&f, 0.0));
        assert!(
            e.contains("`field`") && e.contains("value inf at node [2, 4, 5]"),
            "{e}"
        );
        v[(2 * 5 + 4) * 6 + 5] = 0.5;
        let f = wp::Array::from_slice_shape(&v, (4, 5, 6), &dev).unwrap();
        let e = err(mc.surface(&f, 0.0));
        assert!(
            e.contains(&format!("value {shown} at node [3, 1, 2]")),
            "{e}"
        );
        assert_eq!((mc.verts().len(), mc.indices().len()), (0, 0));
    }
    // The object still works after errors.
    mc.surface(&field, 0.0).unwrap();
    assert!(!mc.verts().is_empty());

    let e = err(mc.set_bounds(Some(Vec3::new(0.0, f32::NAN, 0.0)), None));
    assert!(e.contains("`lower`"), "{e}");
    let e = err(mc.set_bounds(None, Some(Vec3::splat(f32::INFINITY))));
    assert!(e.contains("`upper`"), "{e}");
    assert_eq!((mc.lower(), mc.upper()), (None, None));
}

// ------------------------------------------------------------------------------------------
// The C++ steps on the host, and a GPU
// ------------------------------------------------------------------------------------------

/// The test fields: (dims, values, threshold, bounds).
type Case = ([usize; 3], Vec<f32>, f32, Option<(Vec3, Vec3)>);

fn cases() -> Vec<Case> {
    let mut rng = Rng(77);
    let mut out: Vec<Case> = vec![
        (
            [30, 31, 29],
            grid([30, 31, 29], sphere([14.3, 15.1, 13.7], 11.0)),
            0.0,
            None,
        ),
        (
            [34, 33, 16],
            grid([34, 33, 16], torus([16.4, 16.1, 7.7], 10.0, 4.0)),
            0.25,
            Some((Vec3::new(-1.0, -1.0, -0.5), Vec3::new(1.0, 1.0, 0.5))),
        ),
        (
            [6, 5, 7],
            grid([6, 5, 7], |i, j, k| {
                (i - 2.5).powi(2) + (j - 2.0).powi(2) + 0.5 * (k - 3.0).powi(2) - 4.25
            }),
            0.0,
            None,
        ),
    ];
    // Random fields: small integers (ties with the threshold) and continuous values, some
    // with values far apart (a large threshold - value and value difference).
    for r in 0..4 {
        let dims = [
            rng.int(2, 14) as usize,
            rng.int(2, 14) as usize,
            rng.int(2, 14) as usize,
        ];
        let n: usize = dims.iter().product();
        let values: Vec<f32> = (0..n)
            .map(|_| match r {
                0 | 1 => rng.int(-2, 2) as f32,
                2 => rng.unit() * 2.0 - 1.0,
                _ => (rng.unit() - 0.5) * 3.0e38,
            })
            .collect();
        let t = if r == 2 { 0.1 } else { 0.0 };
        out.push((dims, values, t, None));
    }
    out
}

/// The mesh of a case on `dev`.
fn case_mesh(dev: &wp::Device, c: &Case) -> (Vec<Vec3>, Vec<i32>) {
    let (dims, values, t, bounds) = c;
    let field = wp::Array::from_slice_shape(values, (dims[0], dims[1], dims[2]), dev).unwrap();
    let mut mc = MarchingCubes::new(dims[0], dims[1], dims[2], dev).unwrap();
    if let Some((lo, hi)) = bounds {
        mc.set_bounds(Some(*lo), Some(*hi)).unwrap();
    }
    mc.surface(&field, *t).unwrap();
    (mc.verts().to_vec().unwrap(), mc.indices().to_vec().unwrap())
}

/// A mesh as text, floats as their bits: what the C++ driver prints.
fn mesh_text(verts: &[Vec3], idx: &[i32]) -> String {
    let mut s = format!("{} {}\n", verts.len(), idx.len() / 3);
    for v in verts {
        s.push_str(&format!(
            "{:08x} {:08x} {:08x}\n",
            v.x.to_bits(),
            v.y.to_bits(),
            v.z.to_bits()
        ));
    }
    for t in idx.chunks_exact(3) {
        s.push_str(&format!("{} {} {}\n", t[0], t[1], t[2]));
    }
    s
}

/// The C++ driver: reads a case (dims, threshold, lower, delta as u32 words, then the
/// values), runs the header's steps over every node in order with serial inclusive scans
/// between them, and prints the mesh as `mesh_text` does (or `bad <node>`).
const DRIVER: &str = r#"
#include <cstdio>
#include <vector>
#include "wp_marching_cubes.h"
using namespace wp;

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  FILE* f = fopen(argv[1], "rb");
  if (!f) return 2;
  std::vector<u32> in;
  u32 word;
  while (fread(&word, 4, 1, f) == 1) in.push_back(word);
  fclose(f);
  size_t at = 0;
  i32 dims[3];
  for (int a = 0; a < 3; ++a) dims[a] = (i32)in[at++];
  auto fl = [&](u32 u) { f32 x; memcpy(&x, &u, 4); return x; };
  const f32 thr = fl(in[at++]);
  f32 lower[3], delta[3];
  for (int a = 0; a < 3; ++a) lower[a] = fl(in[at++]);
  for (int a = 0; a < 3; ++a) delta[a] = fl(in[at++]);
  const i32 n = dims[0] * dims[1] * dims[2];
  std::vector<f32> field(n);
  for (i32 i = 0; i < n; ++i) field[i] = fl(in[at++]);
  std::vector<i32> codes(n), vscan(n), tscan(n), totals(2);
  mc_count_t c{(u64)field.data(), (u64)codes.data(), (u64)vscan.data(), (u64)tscan.data(), 0,
               {dims[0], dims[1], dims[2]}, thr};
  i32 bad = -1;
  for (i32 i = 0; i < n; ++i)
    if (!mc_count_node(c, i) && bad < 0) bad = i;
  if (bad >= 0) { printf("bad %d\n", bad); return 0; }
  for (i32 i = 1; i < n; ++i) { vscan[i] += vscan[i - 1]; tscan[i] += tscan[i - 1]; }
  mc_totals_t t{(u64)vscan.data(), (u64)tscan.data(), (u64)totals.data(), (i64)n};
  mc_totals(t);
  const i32 nv = totals[0], nt = totals[1];
  std::vector<f32> verts(3 * (size_t)nv + 1);
  std::vector<i32> indices(3 * (size_t)nt + 1);
  mc_emit_t e{(u64)field.data(), (u64)codes.data(), (u64)vscan.data(), (u64)tscan.data(),
              (u64)verts.data(), (u64)indices.data(), {dims[0], dims[1], dims[2]}, thr,
              {lower[0], lower[1], lower[2]}, {delta[0], delta[1], delta[2]}, nv, nt};
  for (i32 i = 0; i < n; ++i) mc_emit_node(e, i);
  printf("%d %d\n", nv, nt);
  for (i32 v = 0; v < nv; ++v) {
    u32 b[3];
    memcpy(b, &verts[3 * (size_t)v], 12);
    printf("%08x %08x %08x\n", b[0], b[1], b[2]);
  }
  for (i32 k = 0; k < nt; ++k)
    printf("%d %d %d\n", indices[3 * k], indices[3 * k + 1], indices[3 * k + 2]);
  return 0;
}
"#;

/// The header compiles as host C++ (g++, warnings as errors, no FMA contraction), and its
/// steps, run over every node in order, give the CPU backend's mesh bit for bit on every test
/// case (closed-form fields, bounds, ties at the threshold, values near f32's limits).
#[test]
fn cpp_steps_match_the_cpu_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED marching_cubes::cpp_steps_match_the_cpu_bit_for_bit: no g++");
        return;
    }
    let (dir, exe) =
        host_cpp::compile_driver("marching_cubes", DRIVER, &["WP_MARCHING_CUBES_BUILD"]);
    for (k, case) in cases().iter().enumerate() {
        let (dims, values, t, bounds) = case;
        let (lo, hi) = bounds.unwrap_or((
            Vec3::ZERO,
            Vec3::new(
                (dims[0] - 1) as f32,
                (dims[1] - 1) as f32,
                (dims[2] - 1) as f32,
            ),
        ));
        let delta: [f32; 3] = std::array::from_fn(|a| (hi[a] - lo[a]) / (dims[a] - 1) as f32);
        let mut words: Vec<u32> = dims.iter().map(|d| *d as u32).collect();
        words.push(t.to_bits());
        words.extend(lo.to_array().map(f32::to_bits));
        words.extend(delta.map(f32::to_bits));
        words.extend(values.iter().map(|v| v.to_bits()));
        let input = dir.join(format!("case{k}.bin"));
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        std::fs::write(&input, bytes).unwrap();
        let run = Command::new(&exe).arg(&input).output().unwrap();
        assert!(run.status.success(), "driver on case {k}");
        let got = String::from_utf8(run.stdout).unwrap();
        let (verts, idx) = case_mesh(&wp::cpu(), case);
        assert!(!idx.is_empty(), "case {k} has no surface");
        let want = mesh_text(&verts, &idx);
        if got != want {
            let (g, w): (Vec<&str>, Vec<&str>) = (got.lines().collect(), want.lines().collect());
            let at = (0..g.len().max(w.len()))
                .find(|&i| g.get(i) != w.get(i))
                .unwrap_or(0);
            panic!(
                "case {k}: the C++ steps differ from the CPU at line {at} (line 0 is the counts, \
                 then one per vertex, then one per triangle): C++ {:?}, Rust {:?}",
                g.get(at),
                w.get(at)
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The CPU and the first GPU give the same mesh, bit for bit, on every test case (the steps
/// are the same operations on both); skipped, saying so, without a GPU.
#[test]
fn cpu_and_gpu_meshes_are_identical() {
    let gpu = match wp::get_device("cuda:0") {
        Ok(d) => d,
        Err(e) => {
            eprintln!(
                "SKIPPED marching_cubes::cpu_and_gpu_meshes_are_identical: no CUDA device ({e})"
            );
            return;
        }
    };
    for (k, case) in cases().iter().enumerate() {
        let cpu = case_mesh(&wp::cpu(), case);
        let dev = case_mesh(&gpu, case);
        assert_eq!(cpu.1, dev.1, "case {k}: indices differ");
        let bits = |v: &[Vec3]| -> Vec<[u32; 3]> {
            v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
        };
        assert_eq!(bits(&cpu.0), bits(&dev.0), "case {k}: vertices differ");
    }
    // Errors on the GPU too: a NaN names its node.
    let mut v = grid([5, 5, 5], sphere([2.0, 2.0, 2.0], 1.5));
    v[(5 + 2) * 5 + 3] = f32::NAN; // node [1, 2, 3]
    let field = wp::Array::from_slice_shape(&v, (5, 5, 5), &gpu).unwrap();
    let mut mc = MarchingCubes::new(5, 5, 5, &gpu).unwrap();
    let e = err(mc.surface(&field, 0.0));
    assert!(e.contains("NaN") && e.contains("[1, 2, 3]"), "{e}");
}

/// NVRTC accepts the marching cubes build library (`wp_marching_cubes.h` with its kernels) for
/// sm_90 (H100, H200) and sm_80 (A100) with the runtime's options, without warnings: needs
/// libnvrtc, no GPU; skipped, saying so, without it.
#[test]
fn nvrtc_compiles_the_kernels() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED marching_cubes::nvrtc_compiles_the_kernels: {e}");
        return;
    }
    let lib = wp::objects::build_libraries()
        .find(|l| l.section() == "marching_cubes")
        .expect("the marching cubes library is listed");
    for arch in [90, 80] {
        let c = wp::objects::compile_library(&lib, arch)
            .unwrap_or_else(|e| panic!("{} for sm_{arch}: {e}", lib.section()));
        assert!(!c.cubin.is_empty());
        assert!(!c.log.contains("warning"), "sm_{arch}: {}", c.log);
    }
}

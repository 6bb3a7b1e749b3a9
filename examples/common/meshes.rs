//! Procedural triangle meshes with closed-form signed distances (for the mesh examples, the
//! geometry bench and its Warp side, `benches/py/warp_mesh.py`, which builds the same torus),
//! and brute-force references in f64.

#![allow(dead_code)] // each user takes its own subset

use glam::{DVec3, Vec3};

/// A triangle mesh: points and three indices per triangle, counter-clockwise seen from
/// outside (the normal `(b - a) x (c - a)` points out).
pub struct TriMesh {
    pub points: Vec<Vec3>,
    pub indices: Vec<i32>,
}

impl TriMesh {
    /// Triangles.
    pub fn triangles(&self) -> usize {
        self.indices.len() / 3
    }

    /// Triangle `f`'s corners in f64.
    pub fn corners(&self, f: usize) -> [DVec3; 3] {
        let p = |k: usize| self.points[self.indices[3 * f + k] as usize].as_dvec3();
        [p(0), p(1), p(2)]
    }
}

/// A torus around the z axis (tube centre radius `big`, tube radius `small`) on an `nu x nv`
/// grid of quads, two triangles each: the DESIGN.md benchmark's mesh at 500 x 200.
pub fn torus(nu: usize, nv: usize, big: f32, small: f32) -> TriMesh {
    let mut points = Vec::with_capacity(nu * nv);
    for i in 0..nu {
        let u = i as f64 * std::f64::consts::TAU / nu as f64;
        for j in 0..nv {
            let v = j as f64 * std::f64::consts::TAU / nv as f64;
            let ring = big as f64 + small as f64 * v.cos();
            points.push(Vec3::new(
                (ring * u.cos()) as f32,
                (ring * u.sin()) as f32,
                (small as f64 * v.sin()) as f32,
            ));
        }
    }
    let mut indices = Vec::with_capacity(6 * nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            let at = |i: usize, j: usize| ((i % nu) * nv + j % nv) as i32;
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    TriMesh { points, indices }
}

/// The torus's signed distance (negative inside the tube).
pub fn torus_sdf(p: DVec3, big: f64, small: f64) -> f64 {
    let q = ((p.x * p.x + p.y * p.y).sqrt() - big).hypot(p.z);
    q - small
}

/// A UV sphere of radius `r` at the origin: `nlat` bands (poles as single points), `nlon`
/// segments.
pub fn sphere(nlat: usize, nlon: usize, r: f32) -> TriMesh {
    let mut points = vec![Vec3::new(0.0, 0.0, r)];
    for i in 1..nlat {
        let th = i as f64 * std::f64::consts::PI / nlat as f64;
        for j in 0..nlon {
            let ph = j as f64 * std::f64::consts::TAU / nlon as f64;
            points.push(
                (DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * r as f64)
                    .as_vec3(),
            );
        }
    }
    points.push(Vec3::new(0.0, 0.0, -r));
    let south = points.len() as i32 - 1;
    let ring = |i: usize, j: usize| (1 + (i - 1) * nlon + j % nlon) as i32;
    let mut indices = Vec::new();
    for j in 0..nlon {
        indices.extend_from_slice(&[0, ring(1, j), ring(1, j + 1)]);
        indices.extend_from_slice(&[south, ring(nlat - 1, j + 1), ring(nlat - 1, j)]);
    }
    for i in 1..nlat - 1 {
        for j in 0..nlon {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i + 1, j),
                ring(i + 1, j + 1),
                ring(i, j + 1),
            );
            indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    TriMesh { points, indices }
}

/// The closest point of triangle `t` to `p` (Ericson's regions, in f64).
pub fn closest_on_triangle(p: DVec3, t: [DVec3; 3]) -> DVec3 {
    let [a, b, c] = t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// The distance from `p` to the mesh, by brute force over every triangle (f64).
pub fn brute_distance(m: &TriMesh, p: DVec3) -> f64 {
    (0..m.triangles())
        .map(|f| (closest_on_triangle(p, m.corners(f)) - p).length())
        .fold(f64::INFINITY, f64::min)
}

/// The first hit of the ray `start + t dir` (t >= 0) on the mesh, by brute force
/// (Möller-Trumbore in f64), or `None`.
pub fn brute_ray(m: &TriMesh, start: DVec3, dir: DVec3) -> Option<f64> {
    let mut best: Option<f64> = None;
    for f in 0..m.triangles() {
        let [a, b, c] = m.corners(f);
        let (e1, e2) = (b - a, c - a);
        let h = dir.cross(e2);
        let det = e1.dot(h);
        if det.abs() < 1e-14 {
            continue;
        }
        let s = start - a;
        let u = s.dot(h) / det;
        let q = s.cross(e1);
        let v = dir.dot(q) / det;
        if u < 0.0 || v < 0.0 || u + v > 1.0 {
            continue;
        }
        let t = e2.dot(q) / det;
        if t >= 0.0 && best.is_none_or(|b| t < b) {
            best = Some(t);
        }
    }
    best
}

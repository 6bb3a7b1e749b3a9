//! `wp::Mesh` (Warp's triangle mesh) on both backends, every query from a kernel against brute
//! force over the triangles: procedural meshes (a UV sphere and a torus, with degenerate
//! triangles added: a collinear one and a point), query points at random, on vertices and on
//! edges; closest points (signed: inside/outside the closed meshes), furthest points, ray hits
//! (rays parallel to faces included), faces in a box, evaluation at barycentrics (positions,
//! velocities, normals); the empty mesh; a kernel deforming `mesh.points()`, then `refit`,
//! then queries; Warp's other sign methods (`mesh_query_point_sign_normal`, `_sign_parity`)
//! against the analytic solids and bit for bit across backends; gradchecks through
//! `mesh_query_point_no_sign` (and the signed queries) + `mesh_eval_position`; bad
//! input (errors naming the argument); an OBJ file read and queried against its closed form.

use crate::bvh::Rng;
use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::__private::objects::geometry::{closest_point_triangle, intersect_ray_triangle};
use wp::prelude::*;
use wp::Error;

backend_tests!(
    closest_points_match_brute_force,
    furthest_points_match_brute_force,
    rays_match_brute_force,
    rays_parallel_to_faces_miss,
    box_queries_match_brute_force,
    evaluation_at_barycentrics,
    empty_mesh_finds_nothing,
    deform_then_refit_then_query,
    gradients_through_the_closest_point,
    sign_methods_agree,
    gradients_through_the_signed_queries,
    bad_input_is_an_error,
    obj_files_load_and_query,
);

// ------------------------------------------------------------------------------------------
// Kernels
// ------------------------------------------------------------------------------------------

/// Closest point within `max_d` of `q[i]`, signed: whether found, the point, the sign.
#[wp::kernel]
fn k_closest(
    mesh: Mesh,
    q: Array<Vec3>,
    max_d: f32,
    found: Array<i32>,
    cp: Array<Vec3>,
    sign: Array<f32>,
) {
    let i = tid();
    let (result, s, face, u, v) = mesh_query_point(mesh, q[i], max_d);
    if result {
        found[i] = 1;
        cp[i] = mesh_eval_position(mesh, face, u, v);
        sign[i] = s;
    }
}

/// As `k_closest`, unsigned.
#[wp::kernel]
fn k_closest_no_sign(mesh: Mesh, q: Array<Vec3>, max_d: f32, found: Array<i32>, cp: Array<Vec3>) {
    let i = tid();
    let (result, s, face, u, v) = mesh_query_point_no_sign(mesh, q[i], max_d);
    if result && s == 0.0 {
        found[i] = 1;
        cp[i] = mesh_eval_position(mesh, face, u, v);
    }
}

/// The three signed queries and the unsigned one at `q[i]`: `signs[i] = (pseudonormal,
/// sign_normal, parity)`; `same[i] = 1` when the parity query's result, face and barycentrics
/// are the unsigned query's.
#[wp::kernel]
fn k_signs(mesh: Mesh, q: Array<Vec3>, max_d: f32, signs: Array<Vec3>, same: Array<i32>) {
    let i = tid();
    let (r0, s0, _f0, _u0, _v0) = mesh_query_point(mesh, q[i], max_d);
    let (r1, s1, _f1, _u1, _v1) = mesh_query_point_sign_normal(mesh, q[i], max_d);
    let (r2, s2, f2, u2, v2) = mesh_query_point_sign_parity(mesh, q[i], max_d);
    let (r3, _s3, f3, u3, v3) = mesh_query_point_no_sign(mesh, q[i], max_d);
    signs[i] = vec3(s0, s1, s2);
    if r0 == r3 && r1 == r3 && r2 == r3 && f2 == f3 && u2 == u3 && v2 == v3 {
        same[i] = 1;
    }
}

#[wp::kernel]
fn k_furthest(mesh: Mesh, q: Array<Vec3>, min_d: f32, found: Array<i32>, fp: Array<Vec3>) {
    let i = tid();
    let (result, _s, face, u, v) = mesh_query_furthest_point_no_sign(mesh, q[i], min_d);
    if result {
        found[i] = 1;
        fp[i] = mesh_eval_position(mesh, face, u, v);
    }
}

#[wp::kernel]
fn k_ray(
    mesh: Mesh,
    start: Array<Vec3>,
    dir: Array<Vec3>,
    max_t: f32,
    found: Array<i32>,
    ts: Array<f32>,
    hit: Array<Vec3>,
) {
    let i = tid();
    let (result, _sign, face, t, u, v, _normal) = mesh_query_ray(mesh, start[i], dir[i], max_t);
    if result {
        found[i] = 1;
        ts[i] = t;
        hit[i] = mesh_eval_position(mesh, face, u, v);
    }
}

#[wp::kernel]
fn k_aabb(mesh: Mesh, lo: Array<Vec3>, hi: Array<Vec3>, faces: Array<i32, 2>, counts: Array<i32>) {
    let i = tid();
    let mut c = 0;
    for f in mesh_query_aabb(mesh, lo[i], hi[i]) {
        if (c as usize) < faces.shape()[1] {
            faces[(i, c)] = f;
        }
        c += 1;
    }
    counts[i] = c;
}

/// At face `i`, barycentrics `(u, v)`: the position, the velocity, the normal.
#[wp::kernel]
fn k_eval(mesh: Mesh, uv: Array<Vec2>, pos: Array<Vec3>, vel: Array<Vec3>, nrm: Array<Vec3>) {
    let i = tid();
    let u = uv[i].x;
    let v = uv[i].y;
    pos[i] = mesh_eval_position(mesh, i, u, v);
    vel[i] = mesh_eval_velocity(mesh, i, u, v);
    nrm[i] = mesh_eval_face_normal(mesh, i);
}

/// Deforms the mesh's own points: `p -> s p + d`.
#[wp::kernel]
fn k_deform(points: Array<Vec3>, s: f32, d: Vec3) {
    let i = tid();
    points[i] = points[i] * s + d;
}

/// `out[i] = w . c(x_i)`, with `c` the closest point of the mesh to `x_i` (3 f32s each).
#[wp::kernel]
fn k_energy(mesh: Mesh, x: Array<f32>, w: Vec3, out: Array<f32>) {
    let i = tid();
    let p = vec3(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
    let (result, _s, face, u, v) = mesh_query_point_no_sign(mesh, p, 100.0);
    if result {
        out[i] = dot(w, mesh_eval_position(mesh, face, u, v));
    }
}

/// As `k_energy` through the signed queries: `w . c(x_i)` by the parity's closest point
/// plus half of it by the pseudonormal's (`sign_normal`).
#[wp::kernel]
fn k_energy_signed(mesh: Mesh, x: Array<f32>, w: Vec3, out: Array<f32>) {
    let i = tid();
    let p = vec3(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
    let (r1, _s1, f1, u1, v1) = mesh_query_point_sign_parity(mesh, p, 100.0);
    let (r2, _s2, f2, u2, v2) = mesh_query_point_sign_normal(mesh, p, 100.0);
    if r1 && r2 {
        out[i] = dot(w, mesh_eval_position(mesh, f1, u1, v1))
            + 0.5 * dot(w, mesh_eval_position(mesh, f2, u2, v2));
    }
}

// ------------------------------------------------------------------------------------------
// Meshes and references
// ------------------------------------------------------------------------------------------

/// A mesh on the host.
#[derive(Clone)]
struct HostMesh {
    points: Vec<Vec3>,
    indices: Vec<i32>,
}

impl HostMesh {
    fn tri(&self, f: usize) -> [Vec3; 3] {
        [0, 1, 2].map(|k| self.points[self.indices[3 * f + k] as usize])
    }
    fn faces(&self) -> usize {
        self.indices.len() / 3
    }
    fn upload(&self, dev: &wp::Device) -> wp::Mesh {
        wp::Mesh::new(&arr(&self.points, dev), &arr(&self.indices, dev), None).unwrap()
    }
    /// The closest distance from `p` to the mesh.
    fn distance(&self, p: Vec3) -> f32 {
        (0..self.faces())
            .map(|f| {
                let [a, b, c] = self.tri(f);
                (closest_point_triangle(a, b, c, p).position(a, b, c) - p).length()
            })
            .fold(f32::INFINITY, f32::min)
    }
    /// Adds degenerate triangles: a collinear one along the first face's first edge (its
    /// midpoint a new point) and one collapsed onto a vertex.
    fn with_degenerates(mut self) -> HostMesh {
        let [a, b, _] = self.tri(0);
        let (i0, i1) = (self.indices[0], self.indices[1]);
        self.points.push((a + b) * 0.5);
        let m = self.points.len() as i32 - 1;
        self.indices.extend([i0, i1, m, i1, i1, i1]);
        self
    }
}

/// A UV sphere of radius `r` (`rings` bands, `segs` segments), welded, outward-facing.
fn sphere(r: f32, rings: usize, segs: usize) -> HostMesh {
    let mut pts = vec![Vec3::new(0.0, 0.0, r)];
    for i in 1..rings {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segs {
            let ph = 2.0 * std::f32::consts::PI * j as f32 / segs as f32;
            pts.push(Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * r);
        }
    }
    pts.push(Vec3::new(0.0, 0.0, -r));
    let south = pts.len() as i32 - 1;
    let at = |i: usize, j: usize| (1 + (i - 1) * segs + j % segs) as i32;
    let mut ix = Vec::new();
    for j in 0..segs {
        ix.extend([0, at(1, j), at(1, j + 1)]);
        ix.extend([south, at(rings - 1, j + 1), at(rings - 1, j)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segs {
            ix.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            ix.extend([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    HostMesh {
        points: pts,
        indices: ix,
    }
}

/// A torus around the z axis (radii `big`, `small`), welded, outward-facing.
fn torus(big: f32, small: f32, n: usize, m: usize) -> HostMesh {
    let mut pts = Vec::new();
    for i in 0..n {
        let a = 2.0 * std::f32::consts::PI * i as f32 / n as f32;
        for j in 0..m {
            let b = 2.0 * std::f32::consts::PI * j as f32 / m as f32;
            let rr = big + small * b.cos();
            pts.push(Vec3::new(rr * a.cos(), rr * a.sin(), small * b.sin()));
        }
    }
    let at = |i: usize, j: usize| ((i % n) * m + j % m) as i32;
    let mut ix = Vec::new();
    for i in 0..n {
        for j in 0..m {
            ix.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            ix.extend([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    HostMesh {
        points: pts,
        indices: ix,
    }
}

/// The test meshes with a classifier for points clearly inside (-1) or outside (+1) (None:
/// too close to the surface to say from the smooth shape).
/// Whether a point is clearly inside (-1) or outside (+1) a test mesh's smooth shape.
type Inside = fn(Vec3) -> Option<f32>;

fn meshes() -> Vec<(&'static str, HostMesh, Inside)> {
    fn in_sphere(p: Vec3) -> Option<f32> {
        let l = p.length();
        (l < 0.8).then_some(-1.0).or((l > 1.05).then_some(1.0))
    }
    fn in_torus(p: Vec3) -> Option<f32> {
        let d = ((p.x * p.x + p.y * p.y).sqrt() - 1.0).hypot(p.z);
        (d < 0.3).then_some(-1.0).or((d > 0.46).then_some(1.0))
    }
    vec![
        ("sphere", sphere(1.0, 12, 16).with_degenerates(), in_sphere),
        (
            "torus",
            torus(1.0, 0.4, 24, 12).with_degenerates(),
            in_torus,
        ),
    ]
}

/// Query points: random in a box around the mesh, every vertex, every edge midpoint of the
/// first faces, points just off the surface.
fn query_points(m: &HostMesh, seed: u64) -> Vec<Vec3> {
    let mut rng = Rng(seed);
    let mut q: Vec<Vec3> = (0..200).map(|_| rng.vec(-2.0, 2.0)).collect();
    q.extend(m.points.iter().step_by(3));
    for f in 0..m.faces().min(40) {
        let [a, b, c] = m.tri(f);
        q.extend([(a + b) * 0.5, (b + c) * 0.5, (a + b + c) / 3.0 * 1.01]);
    }
    q
}

fn tol(dev: &wp::Device) -> f32 {
    if dev.is_cpu() {
        2e-6
    } else {
        1e-5
    }
}

// ------------------------------------------------------------------------------------------
// Tests
// ------------------------------------------------------------------------------------------

fn closest_points_match_brute_force(dev: &wp::Device) {
    for (name, m, inside) in meshes() {
        let mesh = m.upload(dev);
        assert_eq!(mesh.num_faces(), m.faces());
        let qs = query_points(&m, 17);
        let n = qs.len();
        let q = arr(&qs, dev);
        for max_d in [10.0f32, 0.15] {
            let (found, cp, sign) = (
                zeros::<i32, 1>(n, dev),
                zeros::<Vec3, 1>(n, dev),
                zeros::<f32, 1>(n, dev),
            );
            wp::launch(k_closest, n, (&mesh, &q, max_d, &found, &cp, &sign), dev).unwrap();
            let (found, cp, sign) = (host(&found), host(&cp), host(&sign));
            let (f2, cp2) = (zeros::<i32, 1>(n, dev), zeros::<Vec3, 1>(n, dev));
            wp::launch(k_closest_no_sign, n, (&mesh, &q, max_d, &f2, &cp2), dev).unwrap();
            let (f2, cp2) = (host(&f2), host(&cp2));
            for (i, p) in qs.iter().enumerate() {
                let want = m.distance(*p);
                if (want - max_d).abs() < 1e-4 {
                    continue;
                }
                let expect = want < max_d;
                assert_eq!(
                    found[i] == 1,
                    expect,
                    "{name} {i} at {p}: {want} vs {max_d}"
                );
                assert_eq!(f2[i], found[i], "{name} {i}: no_sign");
                if !expect {
                    continue;
                }
                for (what, c) in [("signed", cp[i]), ("no_sign", cp2[i])] {
                    let got = (c - *p).length();
                    assert!(
                        (got - want).abs() <= tol(dev) * (1.0 + want),
                        "{name} {what} {i} at {p}: distance {got}, brute force {want}"
                    );
                    assert!(m.distance(c) <= 1e-5, "{name} {i}: {c} is not on the mesh");
                }
                if let Some(s) = inside(*p) {
                    assert_eq!(sign[i], s, "{name} {i} at {p}: sign");
                }
            }
        }
    }
}

fn furthest_points_match_brute_force(dev: &wp::Device) {
    for (name, m, _) in meshes() {
        let mesh = m.upload(dev);
        let qs = query_points(&m, 3);
        let n = qs.len();
        let (found, fp) = (zeros::<i32, 1>(n, dev), zeros::<Vec3, 1>(n, dev));
        wp::launch(
            k_furthest,
            n,
            (&mesh, &arr(&qs, dev), 0.0, &found, &fp),
            dev,
        )
        .unwrap();
        let (found, fp) = (host(&found), host(&fp));
        for (i, p) in qs.iter().enumerate() {
            let want = m
                .indices
                .iter()
                .map(|k| (m.points[*k as usize] - *p).length())
                .fold(0.0f32, f32::max);
            assert_eq!(found[i], 1, "{name} {i}");
            let got = (fp[i] - *p).length();
            assert!(
                (got - want).abs() <= tol(dev) * (1.0 + want),
                "{name} {i} at {p}: furthest {got}, brute force {want}"
            );
        }
        // Nothing lies beyond the furthest point.
        let (found, fp) = (zeros::<i32, 1>(1, dev), zeros::<Vec3, 1>(1, dev));
        wp::launch(
            k_furthest,
            1,
            (&mesh, &arr(&[Vec3::ZERO], dev), 5.0, &found, &fp),
            dev,
        )
        .unwrap();
        assert_eq!(host(&found), vec![0], "{name}");
    }
}

/// The first hit by brute force: `(t, point)`.
fn first_hit(m: &HostMesh, s: Vec3, d: Vec3, max_t: f32) -> Option<f32> {
    (0..m.faces())
        .filter_map(|f| {
            let [a, b, c] = m.tri(f);
            let h = intersect_ray_triangle(s, d, a, b, c);
            (h.result && h.t < max_t).then_some(h.t)
        })
        .reduce(f32::min)
}

fn run_rays(
    mesh: &wp::Mesh,
    s: &[Vec3],
    d: &[Vec3],
    max_t: f32,
    dev: &wp::Device,
) -> (Vec<i32>, Vec<f32>, Vec<Vec3>) {
    let n = s.len();
    let (found, ts, hit) = (
        zeros::<i32, 1>(n, dev),
        zeros::<f32, 1>(n, dev),
        zeros::<Vec3, 1>(n, dev),
    );
    wp::launch(
        k_ray,
        n,
        (mesh, &arr(s, dev), &arr(d, dev), max_t, &found, &ts, &hit),
        dev,
    )
    .unwrap();
    (host(&found), host(&ts), host(&hit))
}

fn rays_match_brute_force(dev: &wp::Device) {
    for (name, m, _) in meshes() {
        let mesh = m.upload(dev);
        let mut rng = Rng(23);
        let (mut s, mut d) = (Vec::new(), Vec::new());
        for k in 0..200 {
            let start = rng.vec(-3.0, 3.0);
            let target = rng.vec(-0.5, 0.5);
            s.push(start);
            // Some rays through vertices and edge midpoints.
            let aim = match k % 4 {
                0 => m.points[rng.below(m.points.len())],
                1 => {
                    let [a, b, _] = m.tri(rng.below(m.faces()));
                    (a + b) * 0.5
                }
                _ => target,
            };
            d.push(aim - start);
        }
        for max_t in [100.0f32, 0.7] {
            let (found, ts, hit) = run_rays(&mesh, &s, &d, max_t, dev);
            for i in 0..s.len() {
                let want = first_hit(&m, s[i], d[i], max_t);
                if let Some(t) = want {
                    if (t - max_t).abs() < 1e-4 {
                        continue;
                    }
                }
                assert_eq!(found[i] == 1, want.is_some(), "{name} ray {i}: {want:?}");
                if let Some(t) = want {
                    assert!(
                        (ts[i] - t).abs() <= tol(dev) * (1.0 + t),
                        "{name} ray {i}: t {} vs {t}",
                        ts[i]
                    );
                    let p = s[i] + d[i] * ts[i];
                    assert!(
                        (hit[i] - p).length() <= 1e-4,
                        "{name} ray {i}: {} vs {p}",
                        hit[i]
                    );
                }
            }
        }
    }
}

fn rays_parallel_to_faces_miss(dev: &wp::Device) {
    // A flat 4 x 4 patch in z = 0.
    let mut points = Vec::new();
    for y in 0..5 {
        for x in 0..5 {
            points.push(Vec3::new(x as f32, y as f32, 0.0));
        }
    }
    let mut indices = Vec::new();
    for y in 0..4 {
        for x in 0..4 {
            let k = y * 5 + x;
            indices.extend([k, k + 1, k + 6, k, k + 6, k + 5]);
        }
    }
    let m = HostMesh { points, indices };
    let mesh = m.upload(dev);
    let s = [
        Vec3::new(-1.0, 0.5, 0.0),
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(0.5, 0.5, 1.0),
        Vec3::new(2.0, 2.0, -1.0),
    ];
    let d = [
        Vec3::X,
        Vec3::new(1.0, 1.0, 0.0),
        -Vec3::Z,
        Vec3::new(0.1, 0.0, 1.0),
    ];
    let (found, ts, _) = run_rays(&mesh, &s, &d, 1e6, dev);
    assert_eq!(found, vec![0, 0, 1, 1], "in-plane rays never hit");
    assert_eq!(&ts[2..], &[1.0, 1.0]);
}

fn box_queries_match_brute_force(dev: &wp::Device) {
    for (name, m, _) in meshes() {
        let mesh = m.upload(dev);
        let mut rng = Rng(31);
        let (mut lo, mut hi) = (Vec::new(), Vec::new());
        for _ in 0..100 {
            let l = rng.vec(-1.5, 1.5);
            lo.push(l);
            hi.push(l + rng.vec(0.0, 0.6));
        }
        let n = lo.len();
        const SLOTS: usize = 400;
        let (faces, counts) = (zeros::<i32, 2>([n, SLOTS], dev), zeros::<i32, 1>(n, dev));
        wp::launch(
            k_aabb,
            n,
            (&mesh, &arr(&lo, dev), &arr(&hi, dev), &faces, &counts),
            dev,
        )
        .unwrap();
        let (flat, counts) = (host(&faces), host(&counts));
        for i in 0..n {
            let k = counts[i] as usize;
            assert!(k <= SLOTS);
            let mut got = flat[i * SLOTS..i * SLOTS + k].to_vec();
            got.sort_unstable();
            let want: Vec<i32> = (0..m.faces())
                .filter(|f| {
                    let [a, b, c] = m.tri(*f);
                    let (l, u) = (a.min(b).min(c), a.max(b).max(c));
                    l.cmple(hi[i]).all() && lo[i].cmple(u).all()
                })
                .map(|f| f as i32)
                .collect();
            assert_eq!(got, want, "{name} box {i}");
        }
    }
}

fn evaluation_at_barycentrics(dev: &wp::Device) {
    let m = sphere(2.0, 6, 8).with_degenerates();
    let vel: Vec<Vec3> = m
        .points
        .iter()
        .map(|p| Vec3::new(p.y, -p.x, 2.0 * p.z))
        .collect();
    let mesh = wp::Mesh::new(
        &arr(&m.points, dev),
        &arr(&m.indices, dev),
        Some(&arr(&vel, dev)),
    )
    .unwrap();
    let n = m.faces();
    let mut rng = Rng(2);
    let uv: Vec<Vec2> = (0..n)
        .map(|_| Vec2::new(rng.f() * 0.5, rng.f() * 0.5))
        .collect();
    let (pos, v, nrm) = (
        zeros::<Vec3, 1>(n, dev),
        zeros::<Vec3, 1>(n, dev),
        zeros::<Vec3, 1>(n, dev),
    );
    wp::launch(k_eval, n, (&mesh, &arr(&uv, dev), &pos, &v, &nrm), dev).unwrap();
    let (pos, v, nrm) = (host(&pos), host(&v), host(&nrm));
    for f in 0..n {
        let ix = [0, 1, 2].map(|k| m.indices[3 * f + k] as usize);
        let (u, w) = (uv[f].x, uv[f].y);
        let interp = |x: [Vec3; 3]| x[0] * u + x[1] * w + x[2] * (1.0 - u - w);
        let [a, b, c] = ix.map(|i| m.points[i]);
        assert!((pos[f] - interp([a, b, c])).length() <= 1e-5, "face {f}");
        assert!(
            (v[f] - interp(ix.map(|i| vel[i]))).length() <= 1e-5,
            "face {f}"
        );
        let want = (b - a).cross(c - a).normalize_or_zero();
        assert!(
            (nrm[f] - want).length() <= 1e-5,
            "face {f}: {} vs {want}",
            nrm[f]
        );
    }
    // The degenerate faces' normal is zero.
    assert_eq!(nrm[n - 1], Vec3::ZERO);
    // A face outside the mesh is a fault naming the mesh.
    let more = zeros::<Vec3, 1>(n + 1, dev);
    let uv1 = arr(&vec![Vec2::ZERO; n + 1], dev);
    match wp::launch(k_eval, n + 1, (&mesh, &uv1, &more, &more, &more), dev) {
        Err(Error::Fault(f)) => assert!(f.to_string().contains("mesh"), "{f}"),
        r => panic!("a face past the end: {r:?}"),
    }
}

fn empty_mesh_finds_nothing(dev: &wp::Device) {
    let mesh = wp::Mesh::new(&arr::<Vec3>(&[], dev), &arr::<i32>(&[], dev), None).unwrap();
    assert_eq!((mesh.num_faces(), mesh.num_points()), (0, 0));
    let q = arr(&[Vec3::ZERO, Vec3::splat(5.0)], dev);
    let (found, cp, sign) = (
        zeros::<i32, 1>(2, dev),
        zeros::<Vec3, 1>(2, dev),
        zeros(2, dev),
    );
    wp::launch(k_closest, 2, (&mesh, &q, 1e9, &found, &cp, &sign), dev).unwrap();
    assert_eq!(host(&found), vec![0, 0]);
    wp::launch(k_furthest, 2, (&mesh, &q, 0.0, &found, &cp), dev).unwrap();
    assert_eq!(host(&found), vec![0, 0]);
    let (f, _, _) = run_rays(&mesh, &[Vec3::ZERO], &[Vec3::X], 1e9, dev);
    assert_eq!(f, vec![0]);
    let (faces, counts) = (zeros::<i32, 2>([1, 1], dev), zeros::<i32, 1>(1, dev));
    let big = arr(&[Vec3::splat(1e30)], dev);
    let small = arr(&[Vec3::splat(-1e30)], dev);
    wp::launch(k_aabb, 1, (&mesh, &small, &big, &faces, &counts), dev).unwrap();
    assert_eq!(host(&counts), vec![0]);
}

fn deform_then_refit_then_query(dev: &wp::Device) {
    let m = torus(1.0, 0.4, 16, 8);
    let mut mesh = m.upload(dev);
    let kept = mesh.clone();
    let (s, d) = (1.5f32, Vec3::new(3.0, 0.0, -1.0));
    wp::launch(k_deform, m.points.len(), (mesh.points(), s, d), dev).unwrap();
    mesh.refit().unwrap();
    let moved = HostMesh {
        points: host(mesh.points()),
        indices: m.indices.clone(),
    };
    assert_eq!(moved.points[5], m.points[5] * s + d);
    let qs: Vec<Vec3> = query_points(&m, 9).iter().map(|p| *p * s + d).collect();
    let n = qs.len();
    let (found, cp, sign) = (
        zeros::<i32, 1>(n, dev),
        zeros::<Vec3, 1>(n, dev),
        zeros(n, dev),
    );
    wp::launch(
        k_closest,
        n,
        (&mesh, &arr(&qs, dev), 100.0, &found, &cp, &sign),
        dev,
    )
    .unwrap();
    let (found, cp) = (host(&found), host(&cp));
    for (i, p) in qs.iter().enumerate() {
        let want = moved.distance(*p);
        assert_eq!(found[i], 1);
        let got = (cp[i] - *p).length();
        assert!(
            (got - want).abs() <= tol(dev) * 2.0 * (1.0 + want),
            "{i} at {p}: {got} vs {want}"
        );
    }
    // The clone kept its tree (copy-on-write), the refit kept the shape.
    let (a, b) = (kept.tree_host().unwrap(), mesh.tree_host().unwrap());
    assert_eq!((&a.1, &a.2), (&b.1, &b.2));
    assert_ne!(a.0, b.0);
}

fn gradients_through_the_closest_point(dev: &wp::Device) {
    let m = sphere(1.0, 8, 10);
    let mesh = m.upload(dev);
    // Query points off face interiors (the centroids pushed out), where the closest point
    // moves smoothly with the query point.
    let mut x = Vec::new();
    for f in (0..m.faces()).step_by(7) {
        let [a, b, c] = m.tri(f);
        let p = (a + b + c) / 3.0 * 1.15;
        x.extend(p.to_array());
    }
    let n = x.len() / 3;
    let x = arr(&x, dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(n, dev).with_grad().unwrap();
    let w = Vec3::new(0.3, -1.0, 0.7);
    let mut forward = || wp::launch(k_energy, n, (&mesh, &x, w, &out), dev);
    let report = wp::gradcheck(
        &mut forward,
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f32>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    let nonzero = report
        .analytic
        .iter()
        .flatten()
        .filter(|g| g.abs() > 1e-2)
        .count();
    assert!(nonzero >= 2 * n, "too few nonzero gradients: {nonzero}");
}

/// `mesh_query_point_sign_normal` is `mesh_query_point`; `mesh_query_point_sign_parity`
/// finds the unsigned query's point and signs it right wherever the analytic solid is
/// decided (the margins of `meshes()`: the meshes are coarse facetings); on a GPU, all of it
/// bit for bit the CPU's.
fn sign_methods_agree(dev: &wp::Device) {
    let cpu = wp::cpu();
    for (name, m, inside) in meshes() {
        let mut qs = query_points(&m, 29);
        // Points whose parity ray runs through a vertex.
        qs.extend(
            m.points
                .iter()
                .step_by(5)
                .map(|p| *p - Vec3::new(0.9375, 0.75, 1.0) * 0.25),
        );
        let n = qs.len();
        let run = |dev: &wp::Device| {
            let (mesh, q) = (m.upload(dev), arr(&qs, dev));
            let (signs, same) = (zeros::<Vec3, 1>(n, dev), zeros::<i32, 1>(n, dev));
            wp::launch(k_signs, n, (&mesh, &q, 10.0f32, &signs, &same), dev).unwrap();
            (host(&signs), host(&same))
        };
        let (signs, same) = run(dev);
        let mut decided = 0;
        for (i, p) in qs.iter().enumerate() {
            assert_eq!(same[i], 1, "{name} {i} at {p}: parity's closest point");
            let [s0, s1, s2] = signs[i].to_array();
            assert_eq!(s0.to_bits(), s1.to_bits(), "{name} {i} at {p}: sign_normal");
            assert!(s2 == 1.0 || s2 == -1.0, "{name} {i} at {p}: parity {s2}");
            if let Some(s) = inside(*p) {
                assert_eq!(s2, s, "{name} {i} at {p}: parity sign");
                decided += 1;
            }
        }
        assert!(decided > 150, "{name}: {decided}");
        if !dev.is_cpu() {
            let (cs, csame) = run(&cpu);
            assert_eq!(csame, same, "{name}: CPU and {dev:?}");
            for i in 0..n {
                assert_eq!(
                    cs[i].to_array().map(f32::to_bits),
                    signs[i].to_array().map(f32::to_bits),
                    "{name} {i} at {}: CPU and {dev:?}",
                    qs[i]
                );
            }
        }
    }
}

/// The gradcheck of `gradients_through_the_closest_point` through the signed queries (their
/// adjoints are the unsigned one's: the sign is piecewise constant).
fn gradients_through_the_signed_queries(dev: &wp::Device) {
    let m = sphere(1.0, 8, 10);
    let mesh = m.upload(dev);
    let mut x = Vec::new();
    for f in (0..m.faces()).step_by(7) {
        let [a, b, c] = m.tri(f);
        x.extend(((a + b + c) / 3.0 * 1.15).to_array());
    }
    let n = x.len() / 3;
    let x = arr(&x, dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(n, dev).with_grad().unwrap();
    let w = Vec3::new(0.3, -1.0, 0.7);
    let mut forward = || wp::launch(k_energy_signed, n, (&mesh, &x, w, &out), dev);
    let report = wp::gradcheck(
        &mut forward,
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f32>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    let nonzero = report
        .analytic
        .iter()
        .flatten()
        .filter(|g| g.abs() > 1e-2)
        .count();
    assert!(nonzero >= 2 * n, "too few nonzero gradients: {nonzero}");
}

fn bad_input_is_an_error(dev: &wp::Device) {
    let has = |e: &Error, s: &str| {
        let t = e.to_string();
        assert!(t.contains(s), "`{s}` not in: {t}");
    };
    let p = arr(&[Vec3::ZERO, Vec3::X, Vec3::Y], dev);
    let e = wp::Mesh::new(&p, &arr(&[0, 1, 2, 0], dev), None).unwrap_err();
    has(&e, "argument `indices`");
    has(&e, "multiple of 3");
    let e = wp::Mesh::new(&p, &arr(&[0, 1, 2, 0, 5, 1], dev), None).unwrap_err();
    has(&e, "argument `indices`");
    has(&e, "5 at position 4");
    let e = wp::Mesh::new(&p, &arr(&[0, 1, -2], dev), None).unwrap_err();
    has(&e, "-2 at position 2");
    let nan = arr(&[Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::Y], dev);
    let e = wp::Mesh::new(&nan, &arr(&[0, 1, 2], dev), None).unwrap_err();
    has(&e, "argument `points`");
    has(&e, "index 1");
    let e = wp::Mesh::new(&p, &arr(&[0, 1, 2], dev), Some(&arr(&[Vec3::ZERO], dev))).unwrap_err();
    has(&e, "argument `velocities`");
    // A refit of non-finite points (on a GPU a fault, reported at once in debug mode), or of
    // a points array of another length, is refused.
    let mut mesh = wp::Mesh::new(&p, &arr(&[0, 1, 2], dev), None).unwrap();
    mesh.points().copy_from(&nan).unwrap();
    let e = mesh.refit().unwrap_err();
    has(&e, "argument `points`");
    has(&e, "index 1");
    // (The mesh's points are `p`'s memory: refilled from a new array.)
    let good = arr(&[Vec3::ZERO, Vec3::X, Vec3::Y], dev);
    mesh.points().copy_from(&good).unwrap();
    mesh.refit().unwrap();
    mesh.set_points(&arr(&[Vec3::ZERO; 4], dev)).unwrap();
    let e = mesh.refit().unwrap_err();
    has(&e, "argument `points`");
    has(&e, "built with 3");
    let q = arr(&[Vec3::ZERO], dev);
    let (found, cp, sign) = (
        zeros::<i32, 1>(1, dev),
        zeros::<Vec3, 1>(1, dev),
        zeros(1, dev),
    );
    let e = wp::launch(k_closest, 1, (&mesh, &q, 1.0, &found, &cp, &sign), dev).unwrap_err();
    has(&e, "argument `mesh`");
    let other = if dev.is_cpu() {
        wp::get_device("cuda:0").ok()
    } else {
        Some(wp::cpu())
    };
    match other {
        Some(other) => {
            let e = wp::Mesh::new(&p, &arr(&[0, 1, 2], &other), None).unwrap_err();
            has(&e, "argument `indices`");
            has(&e, other.alias());
            let there = wp::Mesh::new(
                &arr(&[Vec3::ZERO, Vec3::X, Vec3::Y], &other),
                &arr(&[0, 1, 2], &other),
                None,
            )
            .unwrap();
            match wp::launch(k_closest, 1, (&there, &q, 1.0, &found, &cp, &sign), dev) {
                Err(Error::DeviceMismatch { arg: "mesh", .. }) => {}
                r => panic!("a mesh of another device: {r:?}"),
            }
        }
        None => {
            eprintln!("mesh::bad_input_is_an_error: one device only, other-device cases skipped")
        }
    }
}

// ------------------------------------------------------------------------------------------
// OBJ files
// ------------------------------------------------------------------------------------------

/// The cube [-1, 1]^3 as OBJ text: quads (the reader triangulates them), outward facing, in
/// two objects, the second naming its vertices by negative (relative) indices; a comment, a
/// texture coordinate and a normal the reader skips.
const CUBE_OBJ: &str = "\
# the cube [-1, 1]^3
o first
v -1 -1 -1
v 1 -1 -1
v 1 1 -1
v -1 1 -1
v -1 -1 1
v 1 -1 1
v 1 1 1
v -1 1 1
vt 0.5 0.5
vn 0 0 1
f 1 4 3 2
f 5 6 7 8
f 1 2 6 5
o second
f -5 -1 -2 -6
f -8 -4 -1 -5
f -7 -6 -2 -3
";

/// The cube's signed distance (closed form).
fn cube_sdf(p: Vec3) -> f32 {
    let q = p.abs() - Vec3::ONE;
    q.max(Vec3::ZERO).length() + q.max_element().min(0.0)
}

/// An OBJ file read (from text and from a file), built into a mesh on the device, and
/// queried: the signed distance against the cube's closed form; unreadable and malformed
/// files are errors naming what is wrong.
fn obj_files_load_and_query(dev: &wp::Device) {
    let obj = wp::objects::ObjMesh::parse(CUBE_OBJ).unwrap();
    assert_eq!(obj.triangles(), 12, "6 quads, 2 triangles each");
    assert!(obj.points.iter().all(|p| p.abs() == Vec3::ONE));
    let path = std::env::temp_dir().join(format!("wp_cube_{}.obj", std::process::id()));
    std::fs::write(&path, CUBE_OBJ).unwrap();
    let loaded = wp::objects::ObjMesh::load(&path);
    std::fs::remove_file(&path).ok();
    assert_eq!(loaded.unwrap(), obj);

    let mesh = obj.to_mesh(dev).unwrap();
    let mut rng = Rng(29);
    let qs: Vec<Vec3> = (0..500).map(|_| rng.vec(-3.0, 3.0)).collect();
    let n = qs.len();
    let (found, cp, sign) = (
        zeros::<i32, 1>(n, dev),
        zeros::<Vec3, 1>(n, dev),
        zeros::<f32, 1>(n, dev),
    );
    let q = arr(&qs, dev);
    wp::launch(k_closest, n, (&mesh, &q, 10.0f32, &found, &cp, &sign), dev).unwrap();
    let (found, cp, sign) = (host(&found), host(&cp), host(&sign));
    for (i, p) in qs.iter().enumerate() {
        let want = cube_sdf(*p);
        assert_eq!(found[i], 1, "{i} at {p}");
        // f32 distances of O(1): a few ulps of the coordinates, as the other mesh tests.
        let got = (cp[i] - *p).length();
        assert!(
            (got - want.abs()).abs() <= tol(dev) * (1.0 + want.abs()),
            "{i} at {p}: distance {got}, closed form {want}"
        );
        if want.abs() > 1e-3 {
            assert_eq!(sign[i], want.signum(), "{i} at {p}: sign");
        }
    }

    let e = wp::objects::ObjMesh::load("/nonexistent/mesh.obj").unwrap_err();
    assert!(e.to_string().contains("/nonexistent/mesh.obj"), "{e}");
    let e = wp::objects::ObjMesh::parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap_err();
    assert!(e.to_string().contains("ObjMesh::parse"), "{e}");
}

/// The CUDA translation units of the mesh and BVH kernels name what `wp_geometry.h`,
/// `wp_bvh.h` and `wp_mesh.h` (and their adjoint parts) must provide: the object types, the
/// queries taking the fault context last, the tuple results, the adjoints with `__ctx`. Checks
/// the generated text only (no header needed); `WP_PRINT_SOURCES=1` prints it.
#[test]
fn cuda_sources_name_the_library_functions() {
    let fwd = wp::cuda_source::assemble(&<k_closest as wp::Kernel>::INFO).text;
    let adj = wp::cuda_source::assemble_adjoint(&<k_energy as wp::Kernel>::INFO).text;
    let signed = wp::cuda_source::assemble(&<k_signs as wp::Kernel>::INFO).text;
    let adj_signed = wp::cuda_source::assemble_adjoint(&<k_energy_signed as wp::Kernel>::INFO).text;
    let bvh = wp::cuda_source::assemble(&<crate::bvh::k_ray as wp::Kernel>::INFO).text;
    let ray = wp::cuda_source::assemble(&<k_ray as wp::Kernel>::INFO).text;
    if std::env::var("WP_PRINT_SOURCES").is_ok() {
        println!("{fwd}\n----\n{adj}\n----\n{bvh}\n----\n{ray}");
    }
    for (src, want) in [
        (&fwd, "#include \"wp_mesh.h\""),
        (&fwd, "wp::mesh_t"),
        (
            &fwd,
            "wp::tuple_t<bool, wp::f32, wp::i32, wp::f32, wp::f32>",
        ),
        (&fwd, "wp::mesh_query_point("),
        (&fwd, "wp::mesh_eval_position("),
        (&adj, "#include \"wp_adjoint_mesh.h\""),
        (&adj, "wp::adj_mesh_query_point_no_sign("),
        (&adj, "wp::adj_mesh_eval_position("),
        (&signed, "wp::mesh_query_point_sign_normal("),
        (&signed, "wp::mesh_query_point_sign_parity("),
        (&adj_signed, "wp::adj_mesh_query_point_sign_normal("),
        (&adj_signed, "wp::adj_mesh_query_point_sign_parity("),
        (&bvh, "#include \"wp_bvh.h\""),
        (&bvh, "wp::bvh_query_ray_t"),
        (&bvh, "wp::bvh_query_ray_next("),
        (&bvh, "wp::bvh_query_ray_done("),
        (&bvh, "wp::bvh_query_ray_item("),
        (
            &ray,
            "wp::tuple_t<bool, wp::f32, wp::i32, wp::f32, wp::f32, wp::f32, wp::Vec3>",
        ),
    ] {
        assert!(src.contains(want), "`{want}` not in:\n{src}");
    }
}

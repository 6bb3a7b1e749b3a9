//! `wp::HashGrid` (Warp's hash grid) on both backends: `for j in hash_grid_query(grid, p, r)`
//! against brute force (after the distance test: exactly the points within `r`; before it:
//! exactly the points in the buckets of the cells of the box `p ± r`, each once), for random
//! points reaching far outside the grid's nominal extent (negative too, past Warp's 2^20-cell
//! offset), duplicates, radii below, at and above the cell width and wider than the grid;
//! the empty point set; `hash_grid_point_id`; `break`/`continue`; queries in `#[func]`s; bad
//! input (errors naming the argument, faults naming the grid); CPU and CUDA giving the same
//! buffers, candidates and counts; gradients through what the loop body reads (gradcheck of a
//! neighbour-sum energy), and a tape replaying against the grid its launch ran with.

use std::collections::HashSet;

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::__private::objects::hash_grid::{bucket, cell_coord, point_bucket};
use wp::prelude::*;
use wp::{Error, FaultKind};

backend_tests!(
    neighbours_match_brute_force,
    empty_point_set,
    point_ids_are_in_bucket_order,
    jumps_and_funcs,
    bad_input_is_an_error,
    gradients_through_the_loop_body,
    tape_keeps_the_grid_it_ran_with,
);

// ------------------------------------------------------------------------------------------
// Kernels
// ------------------------------------------------------------------------------------------

/// For query point `q[i]`: the neighbours within `r` (in `nbrs[i]`, as many as fit), their
/// count and the count of candidates the query yielded.
#[wp::kernel]
fn k_neighbours(
    grid: HashGrid,
    x: Array<Vec3>,
    q: Array<Vec3>,
    r: f32,
    nbrs: Array<i32, 2>,
    counts: Array<i32>,
    cands: Array<i32>,
) {
    let i = tid();
    let p = q[i];
    let mut c = 0;
    let mut m = 0;
    for j in hash_grid_query(grid, p, r) {
        m += 1;
        if length(x[j] - p) <= r {
            if (c as usize) < nbrs.shape()[1] {
                nbrs[(i, c)] = j as i32;
            }
            c += 1;
        }
    }
    counts[i] = c;
    cands[i] = m;
}

#[wp::kernel]
fn k_point_ids(grid: HashGrid, ids: Array<i32>) {
    let i = tid();
    ids[i] = hash_grid_point_id(grid, i) as i32;
}

/// The query in a func: the number of points within `r` of `p`.
#[wp::func]
fn count_within(grid: HashGrid, x: Array<Vec3>, p: Vec3, r: f32) -> i32 {
    let mut c = 0;
    for j in wp::hash_grid_query(grid, p, r) {
        if length(x[j] - p) <= r {
            c += 1;
        }
    }
    c
}

/// `continue` past the point itself; `break` at the first other neighbour (in candidate
/// order); the count through a func, and through `hash_grid_point_id`'s order (thread `t`
/// takes point `hash_grid_point_id(grid, t)`).
#[wp::kernel]
fn k_jumps(grid: HashGrid, x: Array<Vec3>, r: f32, first: Array<i32>, counts: Array<i32>) {
    let t = tid();
    let i = hash_grid_point_id(grid, t);
    let p = x[i];
    let mut f = -1;
    for j in hash_grid_query(grid, p, r) {
        if j == i {
            continue;
        }
        if length(x[j] - p) <= r {
            f = j as i32;
            break;
        }
    }
    first[i] = f;
    counts[i] = count_within(grid, x, p, r);
}

/// A neighbour-sum energy in f64: `e_i = sum over j != i within h of (h - |x_i - x_j|)^3`
/// (smooth where pairs enter and leave), positions as 3 f64s per point; the query point is
/// the f32 position. Through a func, so the func's adjoint replays the query loop too.
#[wp::func]
fn pair_energy(grid: HashGrid, x: Array<f64>, i: usize, h: f64) -> f64 {
    let xi = dvec3(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
    let mut e: f64 = 0.0;
    for j in hash_grid_query(grid, vec3(xi.x as f32, xi.y as f32, xi.z as f32), h as f32) {
        if j != i {
            let d = xi - dvec3(x[3 * j], x[3 * j + 1], x[3 * j + 2]);
            let s = h - length(d);
            if s > 0.0 {
                e += s * s * s;
            }
        }
    }
    e
}

#[wp::kernel]
pub(crate) fn k_energy(grid: HashGrid, x: Array<f64>, h: f64, out: Array<f64>) {
    let i = tid();
    out[i] = pair_energy(grid, x, i, h) * (1.0 + 0.5 * i as f64);
}

// ------------------------------------------------------------------------------------------
// Data and references
// ------------------------------------------------------------------------------------------

/// A small deterministic generator (xorshift64*), for reproducible point clouds.
struct Rng(u64);

impl Rng {
    fn f(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let u = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40;
        u as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
    fn vec(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
}

const DIMS: [usize; 3] = [8, 5, 3];
const CELL: f32 = 0.5;

/// Points mostly in a box 3 times the grid's nominal extent around 0 (so many wrap, from
/// negative coordinates too), some far away (beyond 2^20 cells: Warp's offset trick would
/// fail there), and duplicates.
fn cloud(seed: u64) -> Vec<Vec3> {
    let mut rng = Rng(seed);
    let mut pts: Vec<Vec3> = (0..300).map(|_| rng.vec(-3.0, 3.0)).collect();
    pts.extend((0..30).map(|_| rng.vec(-1000.0, 1000.0)));
    pts.extend((0..10).map(|_| rng.vec(-1.0, 1.0) + Vec3::new(-1.0e6, 2.0e6, 0.0)));
    for k in 0..30 {
        pts.push(pts[k * 7]);
    }
    pts
}

/// Query points: every point, points near them, far ones.
fn queries(pts: &[Vec3], seed: u64) -> Vec<Vec3> {
    let mut rng = Rng(seed);
    let mut q: Vec<Vec3> = pts.to_vec();
    q.extend(pts.iter().step_by(3).map(|p| *p + rng.vec(-0.3, 0.3)));
    q.extend((0..20).map(|_| rng.vec(-5000.0, 5000.0)));
    q.push(Vec3::new(-1.0e6, 2.0e6, 0.25));
    q
}

/// The number of points in the buckets of the cells overlapping `p ± r` (each bucket once),
/// from the definition: cells `floor(x / h)`, at most `dim` cells per axis.
fn expected_candidates(pts: &[Vec3], p: Vec3, r: f32) -> usize {
    let dims = DIMS.map(|d| d as i32);
    let inv = 1.0 / CELL;
    // A negative or NaN radius: nothing.
    if r.is_nan() || r < 0.0 {
        return 0;
    }
    let mut axes: Vec<Vec<i64>> = Vec::new();
    for (a, x) in p.to_array().into_iter().enumerate() {
        let lo = cell_coord(x - r, inv) as i64;
        let hi = cell_coord(x + r, inv) as i64;
        let n = (hi - lo + 1).clamp(0, dims[a] as i64);
        axes.push((lo..lo + n).collect());
    }
    let mut buckets = HashSet::new();
    for &z in &axes[2] {
        for &y in &axes[1] {
            for &x in &axes[0] {
                assert!(buckets.insert(bucket(dims, [x, y, z])), "a bucket twice");
            }
        }
    }
    pts.iter()
        .filter(|pt| buckets.contains(&point_bucket(dims, inv, **pt)))
        .count()
}

/// No query point lies within 1e-6 relative (about 16 ulp) of `r` from a point: the distance test then gives
/// the same answer whatever the last bits of the distance (CUDA contracts its products into
/// FMAs), so neighbour sets compare exactly on both backends.
fn no_pair_at_the_radius(pts: &[Vec3], qs: &[Vec3], r: f32) {
    for (i, q) in qs.iter().enumerate() {
        for (j, p) in pts.iter().enumerate() {
            let d = (*p - *q).length();
            assert!(
                (d - r).abs() > 1e-6 * r,
                "test data: point {j} lies at the radius {r} of query {i} ({d})"
            );
        }
    }
}

/// The results of `k_neighbours` for every query.
struct Found {
    nbrs: Vec<Vec<i32>>,
    counts: Vec<i32>,
    cands: Vec<i32>,
}

const MAX_NBRS: usize = 200;

fn run_neighbours(dev: &wp::Device, pts: &[Vec3], qs: &[Vec3], r: f32) -> (wp::HashGrid, Found) {
    let x = arr(pts, dev);
    let q = arr(qs, dev);
    let mut grid = wp::HashGrid::new(DIMS[0], DIMS[1], DIMS[2], dev).unwrap();
    grid.build(&x, CELL).unwrap();
    let n = qs.len();
    let nbrs = zeros::<i32, 2>([n, MAX_NBRS], dev);
    let (counts, cands) = (zeros::<i32, 1>(n, dev), zeros::<i32, 1>(n, dev));
    wp::launch(
        k_neighbours,
        n,
        (&grid, &x, &q, r, &nbrs, &counts, &cands),
        dev,
    )
    .unwrap();
    let flat = host(&nbrs);
    let counts = host(&counts);
    let nbrs = (0..n)
        .map(|i| {
            let k = (counts[i] as usize).min(MAX_NBRS);
            let mut v = flat[i * MAX_NBRS..i * MAX_NBRS + k].to_vec();
            v.sort_unstable();
            v
        })
        .collect();
    let found = Found {
        nbrs,
        counts,
        cands: host(&cands),
    };
    (grid, found)
}

// ------------------------------------------------------------------------------------------
// Tests
// ------------------------------------------------------------------------------------------

fn neighbours_match_brute_force(dev: &wp::Device) {
    let pts = cloud(0x9e37_79b9_7f4a_7c15);
    let qs = queries(&pts, 7);
    // Below, at and above the cell width, and a box wider than the grid.
    for r in [0.2f32, 0.5, 1.3, 3.0] {
        no_pair_at_the_radius(&pts, &qs, r);
        let (grid, found) = run_neighbours(dev, &pts, &qs, r);
        assert_eq!(grid.num_points(), Some(pts.len()));
        for (i, p) in qs.iter().enumerate() {
            let want: Vec<i32> = (0..pts.len())
                .filter(|j| (pts[*j] - *p).length() <= r)
                .map(|j| j as i32)
                .collect();
            assert!(want.len() <= MAX_NBRS, "the test's slots are too few");
            assert_eq!(found.nbrs[i], want, "query {i} at {p} (r {r})");
            assert_eq!(found.counts[i] as usize, want.len(), "query {i}");
            assert_eq!(
                found.cands[i] as usize,
                expected_candidates(&pts, *p, r),
                "query {i} at {p} (r {r}): candidates"
            );
        }
        // The same buffers, candidates and counts as the CPU backend.
        if !dev.is_cpu() {
            let (cpu_grid, cpu) = run_neighbours(&wp::cpu(), &pts, &qs, r);
            assert_eq!(
                host(&grid.point_ids().unwrap()),
                host(&cpu_grid.point_ids().unwrap())
            );
            let ((s, e), (cs, ce)) = (grid.cell_ranges().unwrap(), cpu_grid.cell_ranges().unwrap());
            assert_eq!((host(&s), host(&e)), (host(&cs), host(&ce)));
            assert_eq!(
                found.cands, cpu.cands,
                "r {r}: candidate counts, CUDA vs CPU"
            );
            assert_eq!(
                found.counts, cpu.counts,
                "r {r}: neighbour counts, CUDA vs CPU"
            );
        }
    }
    // A negative or NaN radius yields nothing.
    for r in [-1.0f32, f32::NAN] {
        let (_, found) = run_neighbours(dev, &pts, &qs[..5], r);
        assert_eq!(found.cands, vec![0; 5], "r {r}");
    }
}

fn empty_point_set(dev: &wp::Device) {
    let qs = [Vec3::ZERO, Vec3::splat(-7.5), Vec3::new(1e5, 0.0, -1e5)];
    let (grid, found) = run_neighbours(dev, &[], &qs, 2.0);
    assert_eq!(grid.num_points(), Some(0));
    assert_eq!(found.cands, vec![0; 3]);
    assert_eq!(found.counts, vec![0; 3]);
    // No point to name.
    let ids = zeros::<i32, 1>(1, dev);
    match wp::launch(k_point_ids, 1, (&grid, &ids), dev) {
        Err(Error::Fault(f)) => assert!(
            matches!(&f.kind, FaultKind::OutOfBounds { arg: "grid", shape, .. } if *shape == vec![0]),
            "{f}"
        ),
        r => panic!("point_id of an empty grid: {r:?}"),
    }
}

fn point_ids_are_in_bucket_order(dev: &wp::Device) {
    let pts = cloud(3);
    let x = arr(&pts, dev);
    let mut grid = wp::HashGrid::new(DIMS[0], DIMS[1], DIMS[2], dev).unwrap();
    grid.build(&x, CELL).unwrap();
    let n = pts.len();
    let ids = zeros::<i32, 1>(n, dev);
    wp::launch(k_point_ids, n, (&grid, &ids), dev).unwrap();
    let ids = host(&ids);
    assert_eq!(ids, host(&grid.point_ids().unwrap()));
    // A permutation, sorted by bucket, by index within a bucket.
    let dims = DIMS.map(|d| d as i32);
    let key = |i: i32| (point_bucket(dims, 1.0 / CELL, pts[i as usize]), i);
    let mut sorted = ids.clone();
    sorted.sort_unstable_by_key(|i| key(*i));
    assert_eq!(ids, sorted);
    let mut perm = ids.clone();
    perm.sort_unstable();
    assert_eq!(perm, (0..n as i32).collect::<Vec<_>>());
    // One past the last point: a fault naming the grid, the index and the point count.
    let more = zeros::<i32, 1>(n + 1, dev);
    match wp::launch(k_point_ids, n + 1, (&grid, &more), dev) {
        Err(Error::Fault(f)) => assert_eq!(
            f.kind,
            FaultKind::OutOfBounds {
                arg: "grid",
                index: vec![n as i128],
                shape: vec![n]
            },
            "{f}"
        ),
        r => panic!("point_id past the end: {r:?}"),
    }
}

fn jumps_and_funcs(dev: &wp::Device) {
    let pts = cloud(11);
    let n = pts.len();
    let x = arr(&pts, dev);
    let mut grid = wp::HashGrid::new(DIMS[0], DIMS[1], DIMS[2], dev).unwrap();
    grid.build(&x, CELL).unwrap();
    let r = 0.4;
    no_pair_at_the_radius(&pts, &pts, r);
    let (first, counts) = (zeros::<i32, 1>(n, dev), zeros::<i32, 1>(n, dev));
    wp::launch(k_jumps, n, (&grid, &x, r, &first, &counts), dev).unwrap();
    let (first, counts) = (host(&first), host(&counts));
    for i in 0..n {
        let within = |j: usize| (pts[j] - pts[i]).length() <= r;
        let want = (0..n).filter(|j| within(*j)).count();
        let others = (0..n).filter(|j| *j != i && within(*j)).count();
        assert_eq!(counts[i] as usize, want, "point {i}");
        match first[i] {
            -1 => assert_eq!(others, 0, "point {i}: a neighbour was missed"),
            j => assert!(j as usize != i && within(j as usize), "point {i}: {j}"),
        }
    }
    if !dev.is_cpu() {
        // The same candidate order: the same first neighbour, and the same counts.
        let cpu = wp::cpu();
        let xc = arr(&pts, &cpu);
        let mut gc = wp::HashGrid::new(DIMS[0], DIMS[1], DIMS[2], &cpu).unwrap();
        gc.build(&xc, CELL).unwrap();
        let (fc, cc) = (zeros::<i32, 1>(n, &cpu), zeros::<i32, 1>(n, &cpu));
        wp::launch(k_jumps, n, (&gc, &xc, r, &fc, &cc), &cpu).unwrap();
        assert_eq!(first, host(&fc));
        assert_eq!(counts, host(&cc));
    }
}

fn bad_input_is_an_error(dev: &wp::Device) {
    let has = |e: &Error, s: &str| {
        let t = e.to_string();
        assert!(t.contains(s), "`{s}` not in: {t}");
    };
    for (d, name) in [
        ([0, 4, 4], "dim_x"),
        ([4, 0, 4], "dim_y"),
        ([4, 4, 0], "dim_z"),
    ] {
        has(&wp::HashGrid::new(d[0], d[1], d[2], dev).unwrap_err(), name);
    }
    let mut grid = wp::HashGrid::new(4, 4, 4, dev).unwrap();
    let x = arr(&[Vec3::ZERO, Vec3::ONE], dev);
    for r in [0.0f32, -0.5, f32::NAN, f32::INFINITY] {
        has(&grid.build(&x, r).unwrap_err(), "argument `radius`");
    }
    let nan = arr(&[Vec3::ZERO, Vec3::ONE, Vec3::new(f32::NAN, 0.0, 0.0)], dev);
    let e = grid.build(&nan, 1.0).unwrap_err();
    has(&e, "argument `points`");
    has(&e, "index 2");
    // Never built (a failed build counts as none).
    let ids = zeros::<i32, 1>(2, dev);
    let e = wp::launch(k_point_ids, 2, (&grid, &ids), dev).unwrap_err();
    has(&e, "argument `grid`");
    has(&e, "never built");
    grid.build(&x, 1.0).unwrap();
    wp::launch(k_point_ids, 2, (&grid, &ids), dev).unwrap();
    // Another device: a grid built there, points from there.
    let other = if dev.is_cpu() {
        wp::get_device("cuda:0").ok()
    } else {
        Some(wp::cpu())
    };
    match other {
        Some(other) => {
            let mut there = wp::HashGrid::new(4, 4, 4, &other).unwrap();
            there
                .build(&arr(&[Vec3::ZERO, Vec3::ONE], &other), 1.0)
                .unwrap();
            match wp::launch(k_point_ids, 2, (&there, &ids), dev) {
                Err(Error::DeviceMismatch { arg: "grid", .. }) => {}
                r => panic!("a grid of another device: {r:?}"),
            }
            let e = grid.build(&arr(&[Vec3::ZERO], &other), 1.0).unwrap_err();
            has(&e, "argument `points`");
            has(&e, other.alias());
        }
        None => eprintln!(
            "hash_grid::bad_input_is_an_error: one device only, other-device cases skipped"
        ),
    }
}

/// The energy test's data: 12 points in a 1.2-wide cube (as 3 f64s each, with a gradient),
/// so that with h = 0.6 each has several neighbours and some pairs lie outside h; the output
/// (with a gradient); a grid of 2 x 2 x 2 buckets (cells of 0.5, so far points share buckets)
/// built from the positions.
pub(crate) fn energy_case(dev: &wp::Device) -> (wp::Array<f64>, wp::Array<f64>, wp::HashGrid) {
    let mut rng = Rng(5);
    let pts: Vec<f64> = (0..36).map(|_| rng.range(-0.6, 0.6) as f64).collect();
    let x = arr(&pts, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(pts.len() / 3, dev).with_grad().unwrap();
    let mut grid = wp::HashGrid::new(2, 2, 2, dev).unwrap();
    build_from_f64(&mut grid, &x).unwrap();
    (x, out, grid)
}

/// Builds `grid` from positions stored as 3 f64s each.
fn build_from_f64(grid: &mut wp::HashGrid, x: &wp::Array<f64>) -> wp::Result<()> {
    let v: Vec<Vec3> = x
        .to_vec()?
        .chunks(3)
        .map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32))
        .collect();
    grid.build(&wp::Array::from_slice(&v, x.device())?, 0.5)
}

fn gradients_through_the_loop_body(dev: &wp::Device) {
    let (x, out, mut grid) = energy_case(dev);
    let pts = host(&x);
    let n = out.len();
    let h = 0.6f64;
    // The grid is rebuilt from the current positions at every evaluation (the nudged ones
    // too); the tape keeps the grid of the recorded launch (copy-on-write).
    let mut forward = || -> wp::Result<()> {
        build_from_f64(&mut grid, &x)?;
        wp::launch(k_energy, n, (&grid, &x, h, &out), dev)
    };
    let report = wp::gradcheck(
        &mut forward,
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    let nonzero = report
        .analytic
        .iter()
        .flatten()
        .filter(|g| g.abs() > 1e-3)
        .count();
    assert!(nonzero > 2 * n, "too few pairs interact: {nonzero}");
    // The energy itself, against brute force.
    let e = host(&out);
    for i in 0..n {
        let xi = &pts[3 * i..3 * i + 3];
        let mut want = 0.0f64;
        for j in 0..n {
            let xj = &pts[3 * j..3 * j + 3];
            let d = ((xi[0] - xj[0]).powi(2) + (xi[1] - xj[1]).powi(2) + (xi[2] - xj[2]).powi(2))
                .sqrt();
            if j != i && h - d > 0.0 {
                want += (h - d).powi(3);
            }
        }
        want *= 1.0 + 0.5 * i as f64;
        assert!(
            (e[i] - want).abs() <= 1e-12 * want.abs().max(1.0),
            "{i}: {} vs {want}",
            e[i]
        );
    }
}

/// A tape replays a launch against the grid the launch ran with, even after the grid was
/// rebuilt (copy-on-write): the gradient is the same as without the rebuild.
fn tape_keeps_the_grid_it_ran_with(dev: &wp::Device) {
    let grads = |rebuild: bool| {
        let (x, out, mut grid) = energy_case(dev);
        let n = out.len();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            wp::launch(k_energy, n, (&grid, &x, 0.6, &out), dev).unwrap();
        }
        if rebuild {
            // Every point far from every other: a replay on this grid would find no pair.
            let far: Vec<Vec3> = (0..n).map(|k| Vec3::splat(100.0 * k as f32)).collect();
            grid.build(&arr(&far, dev), 0.5).unwrap();
            assert_eq!(grid.num_points(), Some(n));
        }
        out.grad().unwrap().fill(1.0).unwrap();
        tape.backward_from_grads().unwrap();
        host(&x.grad().unwrap())
    };
    let (kept, plain) = (grads(true), grads(false));
    assert!(plain.iter().any(|g| *g != 0.0));
    assert_eq!(kept, plain);
}

/// NVRTC accepts every host object's build library (the hash grid's: `wp_hash_grid.h` with
/// `WP_HASH_GRID_BUILD`) for
/// sm_90 (H100, H200) and sm_80 (A100) with the runtime's options: needs libnvrtc, no GPU;
/// skipped, saying so, without it.
#[test]
fn nvrtc_compiles_the_build_kernels() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED hash_grid::nvrtc_compiles_the_build_kernels: {e}");
        return;
    }
    // The hash grid's, the BVH's, marching cubes', the volume's and the sparse tier's two
    // (its steps, its structure operations).
    assert_eq!(wp::objects::build_libraries().count(), 6);
    for lib in wp::objects::build_libraries() {
        for arch in [90, 80] {
            let c = wp::objects::compile_library(&lib, arch)
                .unwrap_or_else(|e| panic!("{} for sm_{arch}: {e}", lib.section()));
            assert!(!c.cubin.is_empty());
            assert!(
                !c.log.contains("warning"),
                "{} sm_{arch}: {}",
                lib.section(),
                c.log
            );
        }
    }
}

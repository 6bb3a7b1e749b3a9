//! Graphs of the work beyond launches, fills and copies (`graph.rs` has those): the parallel
//! primitives with a device count, a hash grid's builds with the kernels that query them (a
//! DEM frame, a build per substep), and BVH and mesh refits with their queries, recorded
//! through the backend seam and replayed with changed array contents, against the same
//! operations in the same order made plainly: equal bit for bit (the same work on the same
//! device). What would allocate or read back inside a capture is an `Error::Capture` at the
//! call; a recorded build or refit of non-finite input reports it at the replay (the CPU) or
//! at the synchronisation after it (a GPU), and the next replay of finite input is right.

use crate::{arr, host, zeros};
use warp_core::objects::BvhNode;
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    primitives_with_device_counts_replay_as_plain_calls,
    hash_grid_frame_replays_as_plain_frames,
    frame_of_substeps_builds_the_grid_each_substep,
    hash_grid_builds_that_would_allocate_are_refused,
    a_recorded_build_reports_a_non_finite_point,
    bvh_refit_frame_replays_as_plain_frames,
    mesh_refit_frame_replays_as_plain_frames,
    refits_of_a_shared_tree_are_refused_in_a_capture,
    a_recorded_refit_reports_non_finite_input,
    builds_that_read_back_are_refused,
);

/// The neighbours of each point within `r` (itself excluded), as a DEM contact pass counts
/// them.
#[wp::kernel]
fn gb_neighbours(grid: HashGrid, x: Array<Vec3>, r: f32, counts: Array<i32>) {
    let i = tid();
    let p = x[i];
    let mut c = 0;
    for j in hash_grid_query(grid, p, r) {
        if j != i && length(x[j] - p) <= r {
            c += 1;
        }
    }
    counts[i] = c;
}

/// `x += v * dt`, and `v` pushed by the neighbour count (the frame's integration).
#[wp::kernel]
fn gb_drift(x: Array<Vec3>, v: Array<Vec3>, counts: Array<i32>, dt: f32) {
    let i = tid();
    v[i] = v[i] + vec3(0.0, counts[i] as f32 * 0.01, 0.0);
    x[i] = x[i] + v[i] * dt;
}

/// A deterministic pseudo-random stream (xorshift), so the tests need no dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 32) as u32
    }

    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * (self.next() >> 8) as f32 / (1u32 << 24) as f32
    }
}

// ------------------------------------------------------------------------------------------
// Primitives
// ------------------------------------------------------------------------------------------

/// The arrays of one run of [`run_primitives`].
struct Prims {
    a: wp::Array<f32>,
    scan: wp::Array<f32>,
    sum: wp::Array<f32>,
    ints: wp::Array<i32>,
    max: wp::Array<i32>,
    int_scan: wp::Array<i32>,
    keys: wp::Array<u32>,
    vals: wp::Array<i32>,
    flags: wp::Array<i32>,
    out: wp::Array<i32>,
    out_count: wp::Array<i32>,
    count: wp::Array<i32>,
}

impl Prims {
    fn new(n: usize, dev: &wp::Device) -> Prims {
        Prims {
            a: zeros(n, dev),
            scan: zeros(n, dev),
            sum: zeros(1, dev),
            ints: zeros(n, dev),
            max: zeros(1, dev),
            int_scan: zeros(n, dev),
            keys: zeros(n, dev),
            vals: zeros(n, dev),
            flags: zeros(n, dev),
            out: zeros(n, dev),
            out_count: zeros(1, dev),
            count: zeros(1, dev),
        }
    }

    /// New contents from `seed` (outputs set to a marker, so that what a run leaves alone
    /// past the count compares too), and the device count `count`.
    fn set(&self, seed: u64, count: i32) {
        let n = self.a.len();
        let dev = self.a.device();
        let mut rng = Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
        let a: Vec<f32> = (0..n).map(|_| rng.range(-4.0, 4.0)).collect();
        let ints: Vec<i32> = (0..n).map(|_| rng.next() as i32 >> 8).collect();
        // Few distinct keys: the sort's stability shows in the values.
        let keys: Vec<u32> = (0..n).map(|_| rng.next() % 97).collect();
        let vals: Vec<i32> = (0..n as i32).collect();
        let flags: Vec<i32> = (0..n)
            .map(|_| rng.next().is_multiple_of(3) as i32)
            .collect();
        self.a.copy_from(&arr(&a, dev)).unwrap();
        self.ints.copy_from(&arr(&ints, dev)).unwrap();
        self.keys.copy_from(&arr(&keys, dev)).unwrap();
        self.vals.copy_from(&arr(&vals, dev)).unwrap();
        self.flags.copy_from(&arr(&flags, dev)).unwrap();
        self.count.copy_from(&arr(&[count], dev)).unwrap();
        for o in [&self.scan, &self.sum] {
            o.fill(-1.5).unwrap();
        }
        for o in [&self.max, &self.int_scan, &self.out, &self.out_count] {
            o.fill(-7).unwrap();
        }
    }

    /// Every output, on the host, to compare two runs.
    #[allow(clippy::type_complexity)]
    fn outputs(
        &self,
    ) -> (
        Vec<f32>,
        Vec<f32>,
        Vec<i32>,
        Vec<i32>,
        Vec<u32>,
        Vec<i32>,
        Vec<i32>,
    ) {
        let (out, n) = (host(&self.out), host(&self.out_count));
        (
            host(&self.scan),
            host(&self.sum),
            [host(&self.max), host(&self.int_scan)].concat(),
            [out, n].concat(),
            host(&self.keys),
            host(&self.vals),
            host(&self.count),
        )
    }
}

/// Each primitive once on `p`: with the device count (scan in place too, a reduction of each
/// kind, the radix sort, a compaction of the sorted values) and one with a host count.
fn run_primitives(p: &Prims) -> wp::Result<()> {
    wp::array_scan_n(&p.a, &p.scan, &p.count, true)?;
    wp::array_sum_n(&p.a, &p.sum, &p.count)?;
    wp::array_max_n(&p.ints, &p.max, &p.count)?;
    wp::radix_sort_pairs(&p.keys, &p.vals, &p.count, Some(7))?;
    wp::compact_n(&p.vals, &p.flags, &p.out, &p.out_count, &p.count)?;
    wp::array_scan(&p.ints, &p.int_scan, false)
}

/// A graph of every primitive with a device count, replayed with new contents and new counts
/// (read at each replay: all, half, a few, none), gives what the plain calls give.
fn primitives_with_device_counts_replay_as_plain_calls(dev: &wp::Device) {
    let n = 3000;
    let (plain, captured) = (Prims::new(n, dev), Prims::new(n, dev));
    // On a GPU a primitive compiles its module and sizes its scratch at its first use, which
    // a capture refuses: the plain calls come first (the same lengths).
    plain.set(1, n as i32);
    run_primitives(&plain).unwrap();
    captured.set(1, n as i32);
    let before = captured.outputs();
    let graph = wp::capture(dev, || run_primitives(&captured)).unwrap();
    assert_eq!(graph.launches(), 0, "primitives are not kernel launches");
    assert!(graph.node_count() >= 6, "{graph:?}");
    // Nothing ran at capture.
    assert_eq!(captured.outputs(), before);
    let runs = [
        (2, n as i32),
        (3, n as i32 / 2),
        (4, 17),
        (5, 0),
        (6, n as i32 - 1),
    ];
    for (seed, count) in runs {
        plain.set(seed, count);
        run_primitives(&plain).unwrap();
        captured.set(seed, count);
        graph.launch().unwrap();
        let want = plain.outputs();
        assert_eq!(captured.outputs(), want, "seed {seed}, count {count}");
        // The run did something: the compaction kept what the flags say.
        let kept = want.3[n];
        assert!(count < 3 || kept > 0, "count {count} kept {kept}");
    }
    // Twice in a row: a replay reads its inputs afresh (the sort in place sorted them).
    graph.launch().unwrap();
    run_primitives(&plain).unwrap();
    assert_eq!(captured.outputs(), plain.outputs());
}

// ------------------------------------------------------------------------------------------
// Hash grid builds
// ------------------------------------------------------------------------------------------

/// One DEM-like frame's state: points, velocities, neighbour counts, and the grid.
struct Frame {
    x: wp::Array<Vec3>,
    v: wp::Array<Vec3>,
    counts: wp::Array<i32>,
    grid: wp::HashGrid,
}

const RADIUS: f32 = 0.12;
const DT: f32 = 0.01;

impl Frame {
    fn new(n: usize, dev: &wp::Device) -> Frame {
        Frame::with_grid(n, 16, dev)
    }

    /// A frame's state with a grid of `dim^3` buckets.
    fn with_grid(n: usize, dim: usize, dev: &wp::Device) -> Frame {
        let mut grid = wp::HashGrid::new(dim, dim, dim, dev).unwrap();
        grid.reserve(n).unwrap();
        Frame {
            x: zeros(n, dev),
            v: zeros(n, dev),
            counts: zeros(n, dev),
            grid,
        }
    }

    /// New points from `seed` (a cloud around the origin reaching past the grid's extent,
    /// dense enough for neighbours) and velocities.
    fn set(&self, seed: u64) {
        let n = self.x.len();
        let dev = self.x.device();
        let mut rng = Rng(seed.wrapping_mul(0xd1b5_4a32_d192_ed03) | 1);
        let mut p = || {
            Vec3::new(
                rng.range(-1.5, 1.5),
                rng.range(-1.5, 1.5),
                rng.range(-0.5, 0.5),
            )
        };
        let x: Vec<Vec3> = (0..n).map(|_| p()).collect();
        let v: Vec<Vec3> = (0..n).map(|_| p() * 0.1).collect();
        self.x.copy_from(&arr(&x, dev)).unwrap();
        self.v.copy_from(&arr(&v, dev)).unwrap();
    }

    /// A frame: the grid built from the points, the contacts counted, the points moved.
    fn step(&mut self) -> wp::Result<()> {
        self.substeps(1)
    }

    /// A frame of `k` substeps, each a build, the contacts counted and the points moved.
    fn substeps(&mut self, k: usize) -> wp::Result<()> {
        let (n, dev) = (self.x.len(), self.x.device().clone());
        for _ in 0..k {
            self.grid.build(&self.x, RADIUS)?;
            wp::launch(
                gb_neighbours,
                n,
                (&self.grid, &self.x, RADIUS, &self.counts),
                &dev,
            )?;
            wp::launch(gb_drift, n, (&self.x, &self.v, &self.counts, DT), &dev)?;
        }
        Ok(())
    }

    /// The state after a frame: points, velocities, counts, and the grid's sorted point ids
    /// and bucket ranges.
    #[allow(clippy::type_complexity)]
    fn state(&self) -> (Vec<Vec3>, Vec<Vec3>, Vec<i32>, Vec<i32>, Vec<i32>, Vec<i32>) {
        let (starts, ends) = self.grid.cell_ranges().unwrap();
        (
            host(&self.x),
            host(&self.v),
            host(&self.counts),
            host(&self.grid.point_ids().unwrap()),
            host(&starts),
            host(&ends),
        )
    }
}

/// A DEM frame (the hash grid's build: its keys step, the radix sort of the pairs, its ranges
/// step; a query kernel; an integration kernel) captured into one graph, replayed frame after
/// frame, with the points replaced between two frames: the same state as plain frames.
fn hash_grid_frame_replays_as_plain_frames(dev: &wp::Device) {
    wp::load(
        &[wp::kernel_info(gb_neighbours), wp::kernel_info(gb_drift)],
        dev,
    )
    .unwrap();
    let n = 2000;
    let (mut plain, mut captured) = (Frame::new(n, dev), Frame::new(n, dev));
    plain.set(1);
    captured.set(1);
    // On a GPU a build's first use loads its kernels and sizes the sort's scratch, which a
    // capture refuses: a plain frame first (on both, so they stay equal).
    plain.step().unwrap();
    captured.step().unwrap();
    let before = captured.state();
    let graph = wp::capture(dev, || captured.step()).unwrap();
    assert_eq!(graph.launches(), 2);
    // Nothing ran at capture.
    assert_eq!(captured.state(), before);
    let mut contacts = 0;
    for frame in 0..6 {
        if frame == 3 {
            plain.set(2);
            captured.set(2);
        }
        plain.step().unwrap();
        graph.launch().unwrap();
        let want = plain.state();
        assert_eq!(captured.state(), want, "frame {frame}");
        contacts += want.2.iter().map(|&c| c as usize).sum::<usize>();
    }
    // The frames had contacts to count (a grid that found nothing would compare equal too).
    assert!(contacts > n, "{contacts} contacts");
}

/// A frame of substeps (a build in each, as the DEM scene's) captured into one graph: the grid
/// is built several times in the capture, in its own buffers, and the replays give what
/// plain frames give. The grid has buckets enough that a build zeroes the last build's ranges
/// from its keys (in the graph too, but at its first build), so stale ranges would show.
fn frame_of_substeps_builds_the_grid_each_substep(dev: &wp::Device) {
    wp::load(
        &[wp::kernel_info(gb_neighbours), wp::kernel_info(gb_drift)],
        dev,
    )
    .unwrap();
    let (n, k) = (1500, 4);
    let (mut plain, mut captured) = (Frame::with_grid(n, 32, dev), Frame::with_grid(n, 32, dev));
    plain.set(5);
    captured.set(5);
    plain.step().unwrap();
    captured.step().unwrap();
    let graph = wp::capture(dev, || captured.substeps(k)).unwrap();
    assert_eq!(graph.launches(), 2 * k);
    let mut moved = 0.0f32;
    for frame in 0..4 {
        if frame == 2 {
            // Other points: every bucket range the last replay left must go.
            plain.set(6);
            captured.set(6);
        }
        let before = host(&plain.x);
        plain.substeps(k).unwrap();
        graph.launch().unwrap();
        let want = plain.state();
        assert_eq!(captured.state(), want, "frame {frame}");
        moved += want
            .0
            .iter()
            .zip(&before)
            .map(|(a, b)| (*a - *b).length())
            .sum::<f32>();
    }
    assert!(moved > 0.0, "the frames moved nothing");
}

/// A build inside a capture allocates nothing: a grid without room for the points, or whose
/// buffers a clone made before the capture shares (the clone keeps them: the build would
/// write a copy), is refused at the build, and the grid builds plainly afterwards. Built
/// twice in one capture, a grid writes its own buffers both times.
fn hash_grid_builds_that_would_allocate_are_refused(dev: &wp::Device) {
    wp::load(&[wp::kernel_info(gb_neighbours)], dev).unwrap();
    let n = 500;
    let mut f = Frame::new(n, dev);
    f.set(3);
    let x = f.x.clone();
    let counts = f.counts.clone();
    let mut small = wp::HashGrid::new(8, 8, 8, dev).unwrap();
    let e = wp::capture(dev, || small.build(&x, RADIUS));
    crate::graph::assert_refused(e, "reserve(500)");
    assert!(!small.is_built());
    // Built once plainly (a GPU's first use), then shared with a clone.
    f.step().unwrap();
    let kept = f.grid.clone();
    let grid = &mut f.grid;
    let e = wp::capture(dev, || grid.build(&x, RADIUS));
    crate::graph::assert_refused(e, "clone of the grid");
    drop(kept);
    // The discarded capture let go of the grid: a plain frame works.
    f.step().unwrap();
    assert!(f.grid.is_built());
    // Queried, then built twice in one capture (the launches hold the grid): recorded.
    let grid = &mut f.grid;
    let graph = wp::capture(dev, || {
        wp::launch(gb_neighbours, n, (&*grid, &x, RADIUS, &counts), dev)?;
        grid.build(&x, RADIUS)?;
        wp::launch(gb_neighbours, n, (&*grid, &x, RADIUS, &counts), dev)?;
        grid.build(&x, RADIUS)
    })
    .unwrap();
    graph.launch().unwrap();
    let ids = host(&f.grid.point_ids().unwrap());
    f.grid.build(&x, RADIUS).unwrap();
    assert_eq!(host(&f.grid.point_ids().unwrap()), ids);
}

/// What a replay reports: its own error (the CPU, whose replay stops there) or, on a GPU,
/// the fault the next synchronisation reports.
fn replay_error(graph: &wp::Graph) -> wp::Error {
    match graph.launch().and_then(|()| wp::synchronize()) {
        Err(e) => e,
        Ok(()) => panic!("the replay of non-finite input reported nothing"),
    }
}

/// Checks a recorded operation's report of non-finite input: it names the operation, the
/// argument and the index, on the CPU as the operation's error and on a GPU as a
/// `NonFiniteInput` fault of the replay's launch.
#[track_caller]
fn assert_non_finite(e: &wp::Error, what: &str, arg: &str, index: usize, dev: &wp::Device) {
    let t = e.to_string();
    for s in [
        what,
        &format!("argument `{arg}`"),
        &format!("at index {index}:"),
    ] {
        assert!(t.contains(s), "`{s}` not in: {t}");
    }
    if !dev.is_cpu() {
        match e {
            wp::Error::Fault(f) => {
                assert_eq!(f.kernel, what);
                assert!(f.launch.is_some(), "{f}");
                assert!(
                    matches!(&f.kind, wp::FaultKind::NonFiniteInput { arg: a, index: i, values }
                        if *a == arg && *i == index && values.len() == 3),
                    "{f:?}"
                );
            }
            e => panic!("a GPU reports a fault, not {e:?}"),
        }
    }
}

/// A recorded build cannot read its check of the points back: it reports a non-finite point
/// itself, when replayed; the next replay of finite points is a plain frame's.
fn a_recorded_build_reports_a_non_finite_point(dev: &wp::Device) {
    wp::load(
        &[wp::kernel_info(gb_neighbours), wp::kernel_info(gb_drift)],
        dev,
    )
    .unwrap();
    let n = 800;
    let (mut plain, mut captured) = (Frame::new(n, dev), Frame::new(n, dev));
    plain.set(7);
    captured.set(7);
    plain.step().unwrap();
    captured.step().unwrap();
    let graph = wp::capture(dev, || captured.step()).unwrap();
    let good = host(&captured.x);
    let mut bad = good.clone();
    bad[611] = Vec3::new(0.0, f32::NAN, 0.0);
    bad[97] = Vec3::new(f32::INFINITY, 0.0, 0.0);
    captured.x.copy_from(&arr(&bad, dev)).unwrap();
    let e = replay_error(&graph);
    assert_non_finite(&e, "HashGrid::build", "points", 97, dev);
    captured.x.copy_from(&arr(&good, dev)).unwrap();
    plain.x.copy_from(&arr(&good, dev)).unwrap();
    let v = host(&plain.v);
    captured.v.copy_from(&arr(&v, dev)).unwrap();
    graph.launch().unwrap();
    plain.step().unwrap();
    assert_eq!(captured.state(), plain.state());
}

/// The builds that read sizes or checks back (a BVH's and a mesh's: their boxes on the CPU,
/// their checks on a GPU) are refused inside a capture, on every backend; a refit reads
/// nothing back and is recorded.
fn builds_that_read_back_are_refused(dev: &wp::Device) {
    let lo = arr(&[Vec3::ZERO, Vec3::ONE], dev);
    let hi = arr(&[Vec3::ONE, Vec3::splat(2.0)], dev);
    let mut bvh = wp::Bvh::new(&lo, &hi).unwrap();
    let indices = arr(&[0, 1, 0], dev);
    let scope = wp::ScopedCapture::new(dev).unwrap();
    crate::graph::assert_refused(wp::Bvh::new(&lo, &hi), "cannot be recorded");
    crate::graph::assert_refused(wp::Mesh::new(&lo, &indices, None), "cannot be recorded");
    bvh.refit().unwrap();
    let graph = scope.finish().unwrap();
    assert_eq!(graph.launches(), 0);
    graph.launch().unwrap();
    bvh.refit().unwrap();
}

// ------------------------------------------------------------------------------------------
// BVH and mesh refits
// ------------------------------------------------------------------------------------------

/// Moves box `i` (both corners) by `v[i] * dt`.
#[wp::kernel]
fn gb_move_boxes(lo: Array<Vec3>, hi: Array<Vec3>, v: Array<Vec3>, dt: f32) {
    let i = tid();
    lo[i] = lo[i] + v[i] * dt;
    hi[i] = hi[i] + v[i] * dt;
}

/// The boxes that overlap box `i` (itself included), and the smallest other one.
#[wp::kernel]
fn gb_overlaps(bvh: Bvh, lo: Array<Vec3>, hi: Array<Vec3>, counts: Array<i32>, first: Array<i32>) {
    let i = tid();
    let mut c = 0;
    let mut f = -1;
    for j in bvh_query_aabb(bvh, lo[i], hi[i]) {
        c += 1;
        if j != i as i32 && (f < 0 || j < f) {
            f = j;
        }
    }
    counts[i] = c;
    first[i] = f;
}

/// Moves point `i` by `v[i] * dt` (a deforming mesh).
#[wp::kernel]
fn gb_move_points(x: Array<Vec3>, v: Array<Vec3>, dt: f32) {
    let i = tid();
    x[i] = x[i] + v[i] * dt;
}

/// The closest point of the mesh to query `i`: its face and the point.
#[wp::kernel]
fn gb_closest(mesh: Mesh, q: Array<Vec3>, face: Array<i32>, cp: Array<Vec3>) {
    let i = tid();
    let (found, _s, f, u, v) = mesh_query_point_no_sign(mesh, q[i], 100.0);
    if found {
        face[i] = f;
        cp[i] = mesh_eval_position(mesh, f, u, v);
    } else {
        face[i] = -1;
    }
}

/// Boxes moving through each other: the BVH, its boxes' velocities, and what the queries
/// found.
struct Boxes {
    bvh: wp::Bvh,
    v: wp::Array<Vec3>,
    counts: wp::Array<i32>,
    first: wp::Array<i32>,
}

impl Boxes {
    fn new(n: usize, seed: u64, dev: &wp::Device) -> Boxes {
        let mut rng = Rng(seed.wrapping_mul(0x2545_f491_4f6c_dd1d) | 1);
        let mut lo = Vec::with_capacity(n);
        let mut hi = Vec::with_capacity(n);
        let mut v = Vec::with_capacity(n);
        for _ in 0..n {
            let c = Vec3::new(
                rng.range(-2.0, 2.0),
                rng.range(-2.0, 2.0),
                rng.range(-2.0, 2.0),
            );
            let e = Vec3::new(
                rng.range(0.01, 0.2),
                rng.range(0.01, 0.2),
                rng.range(0.01, 0.2),
            );
            lo.push(c - e);
            hi.push(c + e);
            v.push(Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ));
        }
        Boxes {
            bvh: wp::Bvh::new(&arr(&lo, dev), &arr(&hi, dev)).unwrap(),
            v: arr(&v, dev),
            counts: zeros(n, dev),
            first: zeros(n, dev),
        }
    }

    /// A frame: twice the boxes moved, the tree refit, the overlaps found.
    fn frame(&mut self) -> wp::Result<()> {
        let (n, dev) = (self.v.len(), self.v.device().clone());
        for _ in 0..2 {
            let (lo, hi) = (self.bvh.lowers().clone(), self.bvh.uppers().clone());
            let (lo, hi) = (&lo, &hi);
            wp::launch(gb_move_boxes, n, (lo, hi, &self.v, DT * 10.0), &dev)?;
            self.bvh.refit()?;
            let args = (&self.bvh, lo, hi, &self.counts, &self.first);
            wp::launch(gb_overlaps, n, args, &dev)?;
        }
        Ok(())
    }

    /// The tree, the boxes and what the queries found.
    #[allow(clippy::type_complexity)]
    fn state(&self) -> (Vec<BvhNode>, Vec<Vec3>, Vec<Vec3>, Vec<i32>, Vec<i32>) {
        (
            self.bvh.tree_host().unwrap().0,
            host(self.bvh.lowers()),
            host(self.bvh.uppers()),
            host(&self.counts),
            host(&self.first),
        )
    }
}

/// Boxes moved by a kernel, the BVH refit, its overlaps queried, twice a frame, captured into
/// one graph (two refits of one BVH in it) and replayed: the tree and what the queries found
/// are a plain frame's, bit for bit, frame after frame.
fn bvh_refit_frame_replays_as_plain_frames(dev: &wp::Device) {
    wp::load(
        &[wp::kernel_info(gb_move_boxes), wp::kernel_info(gb_overlaps)],
        dev,
    )
    .unwrap();
    let n = 3000;
    let (mut plain, mut captured) = (Boxes::new(n, 11, dev), Boxes::new(n, 11, dev));
    plain.frame().unwrap();
    captured.frame().unwrap();
    let before = captured.state();
    let graph = wp::capture(dev, || captured.frame()).unwrap();
    assert_eq!(graph.launches(), 4);
    assert_eq!(captured.state(), before, "nothing ran at capture");
    let mut hits = 0;
    for frame in 0..5 {
        plain.frame().unwrap();
        graph.launch().unwrap();
        let want = plain.state();
        assert_eq!(captured.state(), want, "frame {frame}");
        hits += want.3.iter().map(|&c| c as usize - 1).sum::<usize>();
    }
    // The boxes met (a refit that left the tree stale would find too few, or none).
    assert!(hits > n, "{hits} overlaps");
    // The refit tree holds the moved boxes: every query found its own box.
    assert!(host(&captured.counts).iter().all(|&c| c >= 1));
}

/// A mesh deformed by a kernel, refit, and queried (closest points), captured and replayed:
/// a plain frame's tree and results, bit for bit.
fn mesh_refit_frame_replays_as_plain_frames(dev: &wp::Device) {
    wp::load(
        &[wp::kernel_info(gb_move_points), wp::kernel_info(gb_closest)],
        dev,
    )
    .unwrap();
    // A wavy sheet of (k + 1)^2 points, two triangles per cell.
    let k = 40usize;
    let mut points = Vec::new();
    let mut velocities = Vec::new();
    for a in 0..=k {
        for b in 0..=k {
            let (x, z) = (
                a as f32 / k as f32 * 4.0 - 2.0,
                b as f32 / k as f32 * 4.0 - 2.0,
            );
            points.push(Vec3::new(x, 0.2 * (3.0 * x).sin() * z.cos(), z));
            velocities.push(Vec3::new(0.1 * z, (2.0 * x).cos(), -0.1 * x));
        }
    }
    let mut indices = Vec::new();
    for a in 0..k {
        for b in 0..k {
            let p = (a * (k + 1) + b) as i32;
            let q = p + (k + 1) as i32;
            indices.extend([p, q, p + 1, p + 1, q, q + 1]);
        }
    }
    let mut rng = Rng(77);
    let queries: Vec<Vec3> = (0..2000)
        .map(|_| {
            Vec3::new(
                rng.range(-2.5, 2.5),
                rng.range(-1.0, 1.0),
                rng.range(-2.5, 2.5),
            )
        })
        .collect();
    struct Sheet {
        mesh: wp::Mesh,
        v: wp::Array<Vec3>,
        q: wp::Array<Vec3>,
        face: wp::Array<i32>,
        cp: wp::Array<Vec3>,
    }
    let sheet = || {
        let mesh = wp::Mesh::new(&arr(&points, dev), &arr(&indices, dev), None).unwrap();
        Sheet {
            mesh,
            v: arr(&velocities, dev),
            q: arr(&queries, dev),
            face: zeros(queries.len(), dev),
            cp: zeros(queries.len(), dev),
        }
    };
    let frame = |s: &mut Sheet| -> wp::Result<()> {
        let n = s.v.len();
        wp::launch(gb_move_points, n, (s.mesh.points(), &s.v, DT * 5.0), dev)?;
        s.mesh.refit()?;
        let m = s.q.len();
        wp::launch(gb_closest, m, (&s.mesh, &s.q, &s.face, &s.cp), dev)
    };
    let state = |s: &Sheet| {
        (
            s.mesh.tree_host().unwrap(),
            host(s.mesh.points()),
            host(&s.face),
            host(&s.cp),
        )
    };
    let (mut plain, mut captured) = (sheet(), sheet());
    frame(&mut plain).unwrap();
    frame(&mut captured).unwrap();
    let graph = wp::capture(dev, || frame(&mut captured)).unwrap();
    assert_eq!(graph.launches(), 2);
    let first = state(&plain).0;
    for i in 0..4 {
        frame(&mut plain).unwrap();
        graph.launch().unwrap();
        assert!(state(&captured) == state(&plain), "frame {i}");
    }
    let last = state(&plain).0;
    assert_eq!(
        (&first.1, &first.2),
        (&last.1, &last.2),
        "a refit keeps the shape"
    );
    assert_ne!(first.0, last.0, "the refits moved the boxes");
}

/// A clone of a BVH (a tape's) made before a capture keeps its tree: a refit inside the
/// capture would have to write a copy (an allocation) and is refused; without the clone the
/// refit is recorded. A plain refit of a shared tree writes the copy (the clone keeps its
/// tree).
fn refits_of_a_shared_tree_are_refused_in_a_capture(dev: &wp::Device) {
    let mut b = Boxes::new(200, 3, dev);
    let kept = b.bvh.clone();
    let bvh = &mut b.bvh;
    crate::graph::assert_refused(wp::capture(dev, || bvh.refit()), "clone made before");
    let tree = kept.tree_host().unwrap();
    wp::launch(
        gb_move_boxes,
        200,
        (b.bvh.lowers(), b.bvh.uppers(), &b.v, 1.0f32),
        dev,
    )
    .unwrap();
    b.bvh.refit().unwrap();
    assert_eq!(kept.tree_host().unwrap(), tree, "the clone kept its tree");
    assert_ne!(b.bvh.tree_host().unwrap().0, tree.0);
    drop(kept);
    // Queried, then refit: the capture's own launch holds the tree, which stays the capture's.
    wp::load(&[wp::kernel_info(gb_overlaps)], dev).unwrap();
    let graph = wp::capture(dev, || {
        let (lo, hi) = (b.bvh.lowers().clone(), b.bvh.uppers().clone());
        wp::launch(
            gb_overlaps,
            200,
            (&b.bvh, &lo, &hi, &b.counts, &b.first),
            dev,
        )?;
        b.bvh.refit()
    })
    .unwrap();
    graph.launch().unwrap();
}

/// A recorded refit of non-finite boxes (a mesh's points) reports the first such index
/// (lowers before uppers) when replayed; the next replay of finite input is a plain
/// refit's.
fn a_recorded_refit_reports_non_finite_input(dev: &wp::Device) {
    let mut b = Boxes::new(500, 8, dev);
    let graph = {
        let bvh = &mut b.bvh;
        wp::capture(dev, || bvh.refit()).unwrap()
    };
    let (lo, hi) = (host(b.bvh.lowers()), host(b.bvh.uppers()));
    let (mut bad_lo, mut bad_hi) = (lo.clone(), hi.clone());
    bad_hi[31] = Vec3::new(1.0, 2.0, f32::NAN);
    bad_hi[400] = Vec3::NEG_INFINITY;
    b.bvh.uppers().copy_from(&arr(&bad_hi, dev)).unwrap();
    let e = replay_error(&graph);
    assert_non_finite(&e, "Bvh::refit", "uppers", 31, dev);
    bad_lo[250] = Vec3::new(f32::NAN, 0.0, 0.0);
    b.bvh.lowers().copy_from(&arr(&bad_lo, dev)).unwrap();
    let e = replay_error(&graph);
    assert_non_finite(&e, "Bvh::refit", "lowers", 250, dev);
    // Finite again: the replay refits as a plain refit does (the check words were reset).
    b.bvh.lowers().copy_from(&arr(&lo, dev)).unwrap();
    b.bvh.uppers().copy_from(&arr(&hi, dev)).unwrap();
    graph.launch().unwrap();
    wp::synchronize().unwrap();
    let replayed = b.bvh.tree_host().unwrap();
    let fresh = Boxes::new(500, 8, dev);
    let mut fresh_bvh = fresh.bvh;
    fresh_bvh.refit().unwrap();
    assert_eq!(replayed, fresh_bvh.tree_host().unwrap());
    // A mesh: its points.
    let points = arr(&[Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z], dev);
    let mut mesh = wp::Mesh::new(&points, &arr(&[0, 1, 2, 0, 2, 3], dev), None).unwrap();
    let graph = wp::capture(dev, || mesh.refit()).unwrap();
    let nan = [
        Vec3::ZERO,
        Vec3::X,
        Vec3::Y,
        Vec3::new(0.0, 0.0, f32::INFINITY),
    ];
    points.copy_from(&arr(&nan, dev)).unwrap();
    assert_non_finite(&replay_error(&graph), "Mesh::refit", "points", 3, dev);
    points
        .copy_from(&arr(&[Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z], dev))
        .unwrap();
    graph.launch().unwrap();
    wp::synchronize().unwrap();
}

//! Graphs of the work beyond launches, fills and copies (`graph.rs` has those): the parallel
//! primitives with a device count, and a hash grid's build with the kernels that query it (a
//! DEM frame), recorded through the backend seam and replayed with changed array contents,
//! against the same operations in the same order made plainly: equal bit for bit (the same
//! work on the same device). What would allocate or read back inside a capture is an
//! `Error::Capture` at the call.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    primitives_with_device_counts_replay_as_plain_calls,
    hash_grid_frame_replays_as_plain_frames,
    hash_grid_builds_that_would_allocate_are_refused,
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
        let mut grid = wp::HashGrid::new(16, 16, 16, dev).unwrap();
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
        let (n, dev) = (self.x.len(), self.x.device().clone());
        self.grid.build(&self.x, RADIUS)?;
        wp::launch(
            gb_neighbours,
            n,
            (&self.grid, &self.x, RADIUS, &self.counts),
            &dev,
        )?;
        wp::launch(gb_drift, n, (&self.x, &self.v, &self.counts, DT), &dev)
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

/// A build inside a capture allocates nothing: a grid without room for the points, or built
/// twice in one capture (the launch recorded after the first build holds its buffers), is
/// refused at the build, and the grid builds plainly afterwards.
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
    // Built once plainly (a GPU's first use), then twice in one capture.
    f.step().unwrap();
    let grid = &mut f.grid;
    let e = wp::capture(dev, || {
        grid.build(&x, RADIUS)?;
        wp::launch(gb_neighbours, n, (&*grid, &x, RADIUS, &counts), dev)?;
        grid.build(&x, RADIUS)
    });
    crate::graph::assert_refused(e, "once per capture");
    // The discarded capture let go of the grid: a plain frame works.
    f.step().unwrap();
    assert!(f.grid.is_built());
}

/// The builds that read sizes or checks back (a BVH's: its boxes on the CPU, its check of
/// them on a GPU) are refused inside a capture, on every backend.
fn builds_that_read_back_are_refused(dev: &wp::Device) {
    let lo = arr(&[Vec3::ZERO, Vec3::ONE], dev);
    let hi = arr(&[Vec3::ONE, Vec3::splat(2.0)], dev);
    let mut bvh = wp::Bvh::new(&lo, &hi).unwrap();
    let scope = wp::ScopedCapture::new(dev).unwrap();
    crate::graph::assert_refused(wp::Bvh::new(&lo, &hi), "cannot be recorded");
    crate::graph::assert_refused(bvh.refit(), "cannot be recorded");
    let graph = scope.finish().unwrap();
    assert_eq!(graph.launches(), 0);
    graph.launch().unwrap();
    bvh.refit().unwrap();
}

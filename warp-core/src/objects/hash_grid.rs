//! Warp's hash grid, kernel side: [`HashGridView`] (what a `HashGrid` kernel parameter is on
//! the CPU), the neighbour query and `hash_grid_point_id`. The CUDA library's `wp_hash_grid.h`
//! takes the same steps in the same order, so both backends visit the same candidates in the
//! same order.
//!
//! # The grid
//!
//! Space is cut into cubic cells of width `h` (the `radius` the grid was built with); the cell
//! of a coordinate `x` is `floor(x * (1 / h))` as an `i32` (Rust's `as`: saturating, NaN to 0).
//! A grid of `dim_x x dim_y x dim_z` buckets covers an unbounded domain by wrapping: cell
//! `(cx, cy, cz)` goes to bucket `(cx mod dim_x, cy mod dim_y, cz mod dim_z)` (the Euclidean
//! remainder, so negative cells wrap too), linearised as `(z * dim_y + y) * dim_x + x`. A build
//! sorts the point indices by bucket (by index within a bucket) and records each bucket's range
//! `[start, end)` in that order; an empty bucket has `start == end`.
//!
//! # The query
//!
//! `hash_grid_query(grid, p, r)` visits the buckets of the cells overlapping the box
//! `[p - r, p + r]`, x fastest, at most `dim` cells per axis (a wider box would visit a bucket
//! twice: every bucket is then visited once), and yields every point of each bucket: the
//! candidates. Every point within distance `r` of `p` is a candidate (its cell lies in the box,
//! as `floor` and the rounding of `p - r`, `p + r` and of the products are monotone); other
//! points of the same buckets are candidates too, so the caller tests the distance, as in
//! Warp. A radius that is negative or NaN gives no candidate.
//!
//! Differences from Warp, both for the better and neither visible to a distance test: Warp
//! truncates toward zero (`int(x / h)`, so the cells left and right of 0 share a bucket index)
//! and offsets coordinates by 2^20 before its `%` (wrong below -2^20 cells); here cells are
//! floored and wrapped by the Euclidean remainder for every `i32` cell.
//!
//! Every buffer read is a checked [`ArrayView`] access: a corrupt grid or a bad
//! `hash_grid_point_id` index is a fault naming the grid's parameter, and a query ends after at
//! most `dim_x * dim_y * dim_z` buckets whatever the buffers hold.

use glam::Vec3;

use crate::{ArrayView, Fault, FaultKind, KResult, KernelIndex};

/// A built hash grid as a kernel thread sees it: the point indices in bucket order (a checked
/// view, whose names its faults carry), each bucket's start and end in that order, the bucket
/// counts per axis and the inverse cell width. `Copy`; owns nothing (the runtime keeps the
/// buffers alive for the launch).
///
/// Kept small on purpose (88 bytes): a query step takes the grid by value at every candidate,
/// and a view much larger than this is copied with a `memcpy` call per step that the optimiser
/// does not remove (measured: 6x slower CPU queries with three full array views here). The
/// bucket ranges need no check per read, as every bucket index is below the bucket count and
/// [`HashGridView::new`] checks that both buffers hold that many.
#[derive(Clone, Copy)]
pub struct HashGridView {
    point_ids: ArrayView<i32, 1>,
    cell_starts: *const i32,
    cell_ends: *const i32,
    dims: [i32; 3],
    cell_width_inv: f32,
}

#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<HashGridView>() == 88);

// SAFETY: read-only pointers into buffers the runtime keeps alive for the whole launch.
unsafe impl Send for HashGridView {}
unsafe impl Sync for HashGridView {}

impl std::fmt::Debug for HashGridView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HashGridView")
            .field("points", &self.point_ids.len())
            .field("dims", &self.dims)
            .field("cell_width_inv", &self.cell_width_inv)
            .finish()
    }
}

impl HashGridView {
    /// The out-of-bounds fault of the grid's points at `id`, a candidate that is not a point
    /// index (what a read of the points at `id` reports).
    #[cold]
    #[inline(never)]
    fn not_a_point(&self, id: i32) -> Box<Fault> {
        let (kernel, arg) = self.point_ids.names();
        Fault::new(
            kernel,
            FaultKind::OutOfBounds {
                arg,
                index: vec![id as i128],
                shape: vec![self.point_ids.len()],
            },
        )
    }

    /// A view of a grid's buffers: `point_ids` (the point indices in bucket order),
    /// `cell_starts` and `cell_ends` (one entry per bucket, `dims[0] * dims[1] * dims[2]`,
    /// contiguous), and `1 / cell width`. Inconsistent contents make faults, never undefined
    /// behaviour.
    ///
    /// # Panics
    /// When a dim is below 1, their product exceeds `i32::MAX`, or a range buffer is shorter
    /// than the bucket count or not contiguous (the runtime makes grids that satisfy all of
    /// these; this is a host-side constructor, never called by a kernel thread).
    pub fn new(
        point_ids: ArrayView<i32, 1>,
        cell_starts: ArrayView<i32, 1>,
        cell_ends: ArrayView<i32, 1>,
        dims: [i32; 3],
        cell_width_inv: f32,
    ) -> Self {
        let cells = cell_count(dims).unwrap_or_else(|| {
            panic!("hash grid dims {dims:?}: each at least 1, product at most i32::MAX")
        });
        for (name, v) in [("cell_starts", cell_starts), ("cell_ends", cell_ends)] {
            assert!(
                v.len() >= cells as usize && (cells == 1 || v.strides() == [1]),
                "hash grid {name}: {} entries with stride {:?} for {cells} buckets",
                v.len(),
                v.strides()
            );
        }
        HashGridView {
            point_ids,
            cell_starts: cell_starts.as_ptr(),
            cell_ends: cell_ends.as_ptr(),
            dims,
            cell_width_inv,
        }
    }

    /// A grid of one empty bucket and no points: what an adjoint's placeholder for a grid
    /// value holds (`Adjoint::adj_zero`); a query finds nothing and every point read faults.
    pub fn empty() -> Self {
        static EMPTY_BUCKET: i32 = 0;
        // SAFETY: a view of zero elements never dereferences its pointer (every index is out
        // of bounds), so a dangling, aligned pointer is a valid one.
        let none = unsafe {
            ArrayView::new(
                std::ptr::NonNull::<i32>::dangling().as_ptr(),
                [0],
                [1],
                "hash grid",
                "grid",
            )
        };
        HashGridView {
            point_ids: none,
            cell_starts: &EMPTY_BUCKET,
            cell_ends: &EMPTY_BUCKET,
            dims: [1, 1, 1],
            cell_width_inv: 1.0,
        }
    }

    /// The start and end of bucket `b` in bucket order.
    #[inline(always)]
    fn bucket_range(&self, b: i32) -> (i32, i32) {
        debug_assert!(b >= 0 && b < self.dims[0] * self.dims[1] * self.dims[2]);
        // SAFETY: `b` is a bucket index (`bucket` wraps every cell into the dims), below the
        // bucket count that `new` checked both buffers hold.
        unsafe {
            (
                self.cell_starts.add(b as usize).read(),
                self.cell_ends.add(b as usize).read(),
            )
        }
    }

    /// Buckets per axis.
    pub fn dims(&self) -> [i32; 3] {
        self.dims
    }

    /// Points in the grid.
    pub fn num_points(&self) -> usize {
        self.point_ids.len()
    }

    /// `1 / cell width`.
    pub fn cell_width_inv(&self) -> f32 {
        self.cell_width_inv
    }
}

/// `dims[0] * dims[1] * dims[2]` when every dim is at least 1 and the product fits an `i32`.
pub fn cell_count(dims: [i32; 3]) -> Option<i32> {
    if dims.iter().any(|d| *d < 1) {
        return None;
    }
    dims[0].checked_mul(dims[1])?.checked_mul(dims[2])
}

/// The cell of coordinate `x` for `1 / cell width` `inv`: `floor(x * inv)` as an `i32`
/// (saturating; NaN is cell 0).
#[inline(always)]
pub fn cell_coord(x: f32, inv: f32) -> i32 {
    // `floor` without the libm call it is on x86-64 without SSE4.1 (a tenth of a CPU build):
    // truncate (saturating, NaN to 0), then step down when that rounded up. Exact: where
    // `t as f32` rounds (|t| > 2^24) `y` is an integer, so `t == y`.
    let y = x * inv;
    let t = y as i32;
    t.saturating_sub((t as f32 > y) as i32)
}

/// The bucket of cell `(x, y, z)` (any `i64` coordinates): each wrapped into `[0, dim)` by the
/// Euclidean remainder, then `(z * dim_y + y) * dim_x + x`.
#[inline(always)]
pub fn bucket(dims: [i32; 3], cell: [i64; 3]) -> i32 {
    let (x, y, z) = (
        wrap(cell[0], dims[0]),
        wrap(cell[1], dims[1]),
        wrap(cell[2], dims[2]),
    );
    (z * dims[1] + y) * dims[0] + x
}

/// `c` wrapped into `[0, d)` (`d >= 1`) by the Euclidean remainder, without dividing when it
/// is there already (points within the grid's nominal extent: a 64-bit division costs tens of
/// cycles, three per point of a build).
#[inline(always)]
fn wrap(c: i64, d: i32) -> i32 {
    if (c as u64) < d as u64 {
        c as i32
    } else {
        c.rem_euclid(d as i64) as i32
    }
}

/// The bucket of point `p` in a grid of `dims` buckets and `1 / cell width` `inv`: what a build
/// sorts by.
#[inline(always)]
pub fn point_bucket(dims: [i32; 3], inv: f32, p: Vec3) -> i32 {
    let c = |x: f32| cell_coord(x, inv) as i64;
    bucket(dims, [c(p.x), c(p.y), c(p.z)])
}

/// The state of a neighbour query (Warp's `hash_grid_query_t`, without the grid, which every
/// step takes: a loop pushes this state on the adjoint stack at every iteration, so it stays
/// 48 bytes). Made by [`hash_grid_query`], advanced by [`hash_grid_query_next`].
///
/// The box's cells are walked with counters, x fastest, and their buckets kept wrapped by one
/// conditional subtraction per step: no division or remainder per cell (on a GPU a 64-bit
/// remainder is a long software sequence, and a query visits 27 cells).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C)]
pub struct HashGridQuery {
    /// The box's first cell per axis, wrapped into `[0, dim)`.
    lo: [i32; 3],
    /// Cells of the box per axis (all 0 for an empty query), each at most the grid's dim.
    span: [i32; 3],
    /// The current cell's offsets in the box per axis: `at_x` is -1 before the first cell,
    /// and the query has visited every cell once `at_z` reaches `span[2]`.
    at_x: i32,
    at_y: i32,
    at_z: i32,
    /// The next position in bucket order within the current bucket, and its end.
    next: i32,
    end: i32,
    /// The current candidate; -1 before the first and once the query is done.
    point: i32,
}

const _: () = assert!(std::mem::size_of::<HashGridQuery>() == 48);

/// Starts a neighbour query of `grid` around `p` with radius `radius`: the state before the
/// first candidate (see the module docs for which buckets it visits).
#[inline(always)]
pub fn hash_grid_query(grid: HashGridView, p: Vec3, radius: f32) -> KResult<HashGridQuery> {
    let mut q = HashGridQuery {
        at_x: -1,
        point: -1,
        ..HashGridQuery::default()
    };
    // A negative or NaN radius: no cell (span 0 on every axis).
    if radius >= 0.0 {
        let inv = grid.cell_width_inv;
        for (a, x) in p.to_array().into_iter().enumerate() {
            let lo = cell_coord(x - radius, inv);
            let hi = cell_coord(x + radius, inv);
            q.lo[a] = wrap(lo as i64, grid.dims[a]);
            // At least 1: `floor` is monotone and `x - r <= x + r` for r >= 0 (NaN `x` is
            // cell 0 on both sides).
            q.span[a] = (hi as i64 - lo as i64 + 1).clamp(1, grid.dims[a] as i64) as i32;
        }
    }
    Ok(q)
}

/// The query advanced to its next candidate, or to its end (then [`hash_grid_query_done`]).
/// Once done it stays done.
// Inlined into the query loop so that the state stays in registers (called, it round-trips
// through memory at every candidate: a quarter of a CPU query's time, measured with perf).
#[inline(always)]
pub fn hash_grid_query_next(grid: HashGridView, mut q: HashGridQuery) -> KResult<HashGridQuery> {
    loop {
        if q.next < q.end {
            // SAFETY: `0 <= next < end <= point count`: checked when the bucket was entered
            // below (states are made and changed only by these functions).
            let id = unsafe { grid.point_ids.load_unchecked(q.next as usize) };
            q.next += 1;
            // Every candidate is a point index, which the CUDA emitter's query loops rely on.
            // The fault is made out of line: with the error built in the candidate's path
            // (`point_ids.load(id)?`), the DEM example's CPU frame executed 17% more
            // instructions than without the check (callgrind); out of line, 2.7% more.
            if (id as u32) >= grid.point_ids.len() as u32 {
                return Err(grid.not_a_point(id));
            }
            q.point = id;
            return Ok(q);
        }
        // The next cell of the box, x fastest (an empty box has span[2] == 0: done at once).
        if q.at_z < q.span[2] {
            q.at_x += 1;
            if q.at_x >= q.span[0] {
                q.at_x = 0;
                q.at_y += 1;
                if q.at_y >= q.span[1] {
                    q.at_y = 0;
                    q.at_z += 1;
                }
            }
        }
        if q.at_z >= q.span[2] {
            q.next = 0;
            q.end = 0;
            q.point = -1;
            return Ok(q);
        }
        let b = bucket_at(grid.dims, &q);
        let (start, end) = grid.bucket_range(b);
        q.next = start;
        // Bounded by the point count, whatever the buffer holds: a query never runs longer
        // than its buckets' points, and reads no point outside them.
        q.end = end.min(grid.point_ids.len() as i32);
        if q.next < 0 && q.next < q.end {
            // A corrupt start: the out-of-bounds fault of the grid's points.
            grid.point_ids.load(q.next)?;
        }
    }
}

/// The bucket of the query's current cell: the box's wrapped first cell plus the offsets,
/// wrapped by one subtraction (both are below the dim, so their sum is below twice the dim;
/// summed as `u32`, which holds twice any `i32`).
#[inline(always)]
fn bucket_at(dims: [i32; 3], q: &HashGridQuery) -> i32 {
    let w = |lo: i32, at: i32, d: i32| {
        let c = lo as u32 + at as u32;
        (if c >= d as u32 { c - d as u32 } else { c }) as i32
    };
    let (x, y, z) = (
        w(q.lo[0], q.at_x, dims[0]),
        w(q.lo[1], q.at_y, dims[1]),
        w(q.lo[2], q.at_z, dims[2]),
    );
    (z * dims[1] + y) * dims[0] + x
}

/// Whether the query has no more candidates.
#[inline(always)]
pub fn hash_grid_query_done(q: HashGridQuery) -> bool {
    q.point < 0
}

/// The query's current candidate, a point index (valid until [`hash_grid_query_done`]).
#[inline(always)]
pub fn hash_grid_query_point(q: HashGridQuery) -> usize {
    q.point as usize
}

/// The `i`-th point of the grid in bucket order (Warp's `hash_grid_point_id`: threads that
/// take their point this way traverse the grid coherently); an index outside the point count
/// is an out-of-bounds fault of the grid's parameter.
#[inline(always)]
pub fn hash_grid_point_id<I: KernelIndex<1>>(grid: HashGridView, i: I) -> KResult<usize> {
    Ok(grid.point_ids.load(i)? as usize)
}

// Grid values carry no gradient: the placeholder is an empty grid; query states carry none
// either (what depends on them, the candidates, are indices).
no_gradient!(
    HashGridView = HashGridView::empty(),
    HashGridQuery = HashGridQuery::default(),
);

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid built by sorting, as the runtime builds it.
    struct Built {
        ids: Vec<i32>,
        starts: Vec<i32>,
        ends: Vec<i32>,
        dims: [i32; 3],
        inv: f32,
    }

    impl Built {
        fn new(points: &[Vec3], dims: [i32; 3], h: f32) -> Built {
            let inv = 1.0 / h;
            let mut keys: Vec<(i32, i32)> = points
                .iter()
                .enumerate()
                .map(|(i, p)| (point_bucket(dims, inv, *p), i as i32))
                .collect();
            keys.sort_unstable();
            let n = cell_count(dims).unwrap() as usize;
            let (mut starts, mut ends) = (vec![0; n], vec![0; n]);
            for (k, (b, _)) in keys.iter().enumerate() {
                if k == 0 || keys[k - 1].0 != *b {
                    starts[*b as usize] = k as i32;
                }
                ends[*b as usize] = k as i32 + 1;
            }
            Built {
                ids: keys.iter().map(|k| k.1).collect(),
                starts,
                ends,
                dims,
                inv,
            }
        }

        fn view(&mut self) -> HashGridView {
            let v = |d: &mut Vec<i32>, arg| unsafe {
                ArrayView::new(d.as_mut_ptr(), [d.len()], [1], "k", arg)
            };
            HashGridView::new(
                v(&mut self.ids, "grid"),
                v(&mut self.starts, "grid"),
                v(&mut self.ends, "grid"),
                self.dims,
                self.inv,
            )
        }
    }

    fn candidates(g: HashGridView, p: Vec3, r: f32) -> Vec<usize> {
        let mut q = hash_grid_query(g, p, r).unwrap();
        let mut out = Vec::new();
        loop {
            q = hash_grid_query_next(g, q).unwrap();
            if hash_grid_query_done(q) {
                break;
            }
            out.push(hash_grid_query_point(q));
        }
        // Done stays done.
        assert!(hash_grid_query_done(hash_grid_query_next(g, q).unwrap()));
        out
    }

    #[test]
    fn cells_floor_and_wrap() {
        assert_eq!(cell_coord(-0.5, 1.0), -1);
        assert_eq!(cell_coord(0.5, 1.0), 0);
        assert_eq!(cell_coord(f32::NAN, 1.0), 0);
        assert_eq!(cell_coord(1e30, 1.0), i32::MAX);
        assert_eq!(cell_coord(-f32::INFINITY, 2.0), i32::MIN);
        // The same as `floor` then a saturating cast, across magnitudes, signs, integers and
        // the values next to them, and the cast's saturation points.
        let mut xs = vec![
            0.0f32,
            -0.0,
            2.0f32.powi(31),
            -(2.0f32.powi(31)),
            1e-40,
            -1e-40,
        ];
        for e in -30..40 {
            let m = 2.0f32.powi(e);
            for x in [m, m * 1.37, m * 0.73 + 0.5] {
                for y in [
                    x,
                    -x,
                    f32::from_bits(x.to_bits() + 1),
                    f32::from_bits(x.to_bits() - 1),
                ] {
                    xs.push(y);
                    xs.push(-y);
                }
            }
        }
        for x in xs {
            assert_eq!(cell_coord(x, 1.0), x.floor() as i32, "x = {x:e}");
        }
        let d = [3, 4, 5];
        assert_eq!(bucket(d, [-1, 0, 0]), 2);
        assert_eq!(bucket(d, [0, -1, 0]), 3 * 3);
        assert_eq!(bucket(d, [0, 0, -1]), 4 * 4 * 3);
        assert_eq!(
            bucket(d, [i32::MIN as i64, 0, 0]),
            (i32::MIN as i64).rem_euclid(3) as i32
        );
        assert_eq!(bucket(d, [2, 3, 4]), 3 * 4 * 5 - 1);
        assert_eq!(cell_count([0, 1, 1]), None);
        assert_eq!(cell_count([65536, 65536, 1]), None);
        assert_eq!(cell_count([2, 3, 4]), Some(24));
    }

    #[test]
    fn candidates_cover_the_neighbours_each_once() {
        // Points on a lattice reaching far outside the nominal extent of a 4x3x2 grid, some
        // negative, with duplicates.
        let mut pts = Vec::new();
        for k in 0..300 {
            let f = k as f32;
            pts.push(Vec3::new(
                (f * 0.37).sin() * 9.0,
                (f * 0.11).cos() * 7.0 - 3.0,
                f * 0.05 - 6.0,
            ));
        }
        pts.push(pts[17]);
        pts.push(pts[17]);
        let mut b = Built::new(&pts, [4, 3, 2], 0.75);
        let g = b.view();
        for (qi, p) in pts.iter().enumerate().step_by(7) {
            for r in [0.0, 0.3, 0.75, 2.0, 40.0] {
                let c = candidates(g, *p, r);
                let mut sorted = c.clone();
                sorted.sort_unstable();
                sorted.dedup();
                assert_eq!(
                    sorted.len(),
                    c.len(),
                    "a candidate twice (point {qi}, r {r})"
                );
                for (j, x) in pts.iter().enumerate() {
                    if (*x - *p).length() <= r {
                        assert!(c.contains(&j), "point {j} missing around {qi}, r {r}");
                    }
                }
                if r == 40.0 {
                    assert_eq!(
                        c.len(),
                        pts.len(),
                        "a box wider than the grid visits it all"
                    );
                }
            }
        }
        for r in [-1.0, f32::NAN] {
            assert!(candidates(g, pts[0], r).is_empty());
        }
    }

    #[test]
    fn point_ids_and_faults() {
        let pts = [
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::ZERO,
            Vec3::new(-5.0, 0.0, 0.0),
        ];
        let mut b = Built::new(&pts, [2, 1, 1], 1.0);
        let g = b.view();
        // Buckets: x = 5 -> 1, x = 0 -> 0, x = -5 -> 1: bucket 0 holds point 1, bucket 1
        // points 0 and 2.
        let ids: Vec<usize> = (0..3).map(|i| hash_grid_point_id(g, i).unwrap()).collect();
        assert_eq!(ids, vec![1, 0, 2]);
        let e = hash_grid_point_id(g, 3usize).unwrap_err();
        assert!(e.to_string().contains("argument `grid`"), "{e}");
        assert!(hash_grid_point_id(g, -1i32).is_err());
        // The empty grid: no candidate, and point reads fault.
        let z = HashGridView::empty();
        let q = hash_grid_query(z, Vec3::ZERO, 1.0).unwrap();
        assert!(hash_grid_query_done(hash_grid_query_next(z, q).unwrap()));
        assert!(hash_grid_point_id(z, 0).is_err());
    }

    #[test]
    fn corrupt_buffers_fault_or_end() {
        let pts = [Vec3::ZERO, Vec3::X];
        let mut b = Built::new(&pts, [1, 1, 1], 1.0);
        b.ends[0] = i32::MAX; // ends past the points: clamped
        let g = b.view();
        assert_eq!(candidates(g, Vec3::ZERO, 0.5), vec![0, 1]);
        b.starts[0] = -3;
        let g = b.view();
        let q = hash_grid_query(g, Vec3::ZERO, 0.5).unwrap();
        assert!(hash_grid_query_next(g, q).is_err());
    }
}

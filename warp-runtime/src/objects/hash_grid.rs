//! [`HashGrid`]: Warp's hash grid. Points are bucketed into a uniform grid of
//! `dim_x x dim_y x dim_z` cells that wraps around, so points anywhere (negative, far outside
//! `dims x cell width`) are found; kernels take the grid as a parameter `grid: HashGrid` and
//! iterate `for j in hash_grid_query(grid, p, radius)` over the candidates near `p` (see
//! `warp_core::objects::hash_grid` for the cells, buckets and query, which the CUDA library
//! mirrors).
//!
//! A build is the same on every device, through the backend seam: a per-point step gives
//! each point's bucket and index (`HashGridKeys` in `hash_grid_steps.rs`: rayon on the CPU, a
//! kernel of `wp_hash_grid.h` on a GPU, run by `dispatch::object_step`), the primitives'
//! stable radix sort sorts the pairs by bucket (so by index within a bucket), and a
//! per-position step records each bucket's range in that order (`HashGridRanges`), after the last build's ranges were zeroed (from
//! its keys when they are few against the buckets: a small build on a large grid does not pay
//! for zeroing every bucket). The point indices are sorted in the grid's own
//! buffer; the keys are a buffer of the grid too, so a reserved grid builds without
//! allocating.
//!
//! Copy-on-write: a clone (what a [`Tape`](crate::Tape) keeps of a launch's grid) shares the
//! buffers until one of them is built again, which then gets fresh buffers, so a recorded
//! launch replays in backward against the grid as it was when it ran, even if the simulation
//! rebuilt the grid since.

use std::sync::Arc;

use glam::Vec3;
use warp_core::objects::hash_grid::cell_count;
use warp_core::objects::HashGridView;

use super::hash_grid_steps::{HashGridKeys, HashGridRanges, BUILD_NAMES};
use super::HostObject;
use crate::array::Array;
use crate::backend::StepFault;
use crate::capturing::{self, Keep};
use crate::device::Device;
use crate::dispatch;
use crate::error::{Error, Result};
use crate::kernel::ArgCtx;
use crate::primitives::radix_sort_pairs;

/// A hash grid on one device: `HashGrid::new(dim_x, dim_y, dim_z, &device)`, then
/// [`build`](HashGrid::build) from points before launching kernels that query it (this
/// example runs as a doc test of the `warp_lang` facade):
///
/// ```ignore
/// use warp_lang as wp;
/// use wp::prelude::*;
///
/// #[wp::kernel]
/// fn count_neighbours(grid: HashGrid, x: Array<Vec3>, r: f32, counts: Array<i32>) {
///     let i = tid();
///     let mut n = 0;
///     for j in hash_grid_query(grid, x[i], r) {
///         if j != i && length(x[j] - x[i]) <= r {
///             n += 1;
///         }
///     }
///     counts[i] = n;
/// }
///
/// let dev = wp::cpu();
/// let x = wp::Array::from_slice(&[Vec3::ZERO, Vec3::X * 0.5, Vec3::X * 3.0], &dev).unwrap();
/// let counts = wp::Array::<i32>::zeros(3, &dev).unwrap();
/// let mut grid = wp::HashGrid::new(8, 8, 8, &dev).unwrap();
/// grid.build(&x, 1.0).unwrap();
/// wp::launch(count_neighbours, 3, (&grid, &x, 1.0, &counts), &dev).unwrap();
/// assert_eq!(counts.to_vec().unwrap(), vec![1, 1, 0]);
/// ```
pub struct HashGrid {
    dims: [i32; 3],
    device: Device,
    buffers: Arc<Buffers>,
    /// What the last successful build made; `None` before it (and after a failed one).
    built: Option<Built>,
    /// How the bucket ranges may be zeroed before the next build: `Some(m)` when every
    /// nonzero entry was written from the first `m` keys (then clearing those entries is
    /// enough), `None` when unknown (zero them all).
    ranges_from_keys: Option<usize>,
    /// The capture that recorded the build `ranges_from_keys` describes, if one did: then it
    /// holds within that capture only (each replay runs that build before the next one it
    /// recorded), and is unknown outside it (a replay may or may not have run).
    ranges_capture: Option<u64>,
}

/// The grid's buffers on its device.
struct Buffers {
    /// The point indices in bucket order (the first `num_points` of its capacity).
    point_ids: Array<i32>,
    /// Each bucket's range `[start, end)` in `point_ids` (`start == end`: empty).
    cell_starts: Array<i32>,
    cell_ends: Array<i32>,
    /// The build's sort keys (the points' buckets), as long as `point_ids`.
    keys: Array<i32>,
    /// The build's flag: the smallest index of a non-finite point (`i32::MAX`: none).
    bad: Array<i32>,
}

impl Buffers {
    /// Fresh buffers for `capacity` points and `cells` buckets on `device`.
    fn new(capacity: usize, cells: usize, device: &Device) -> Result<Buffers> {
        Ok(Buffers {
            point_ids: Array::zeros(capacity, device)?,
            cell_starts: Array::zeros(cells, device)?,
            cell_ends: Array::zeros(cells, device)?,
            keys: Array::zeros(capacity, device)?,
            bad: Array::zeros(1, device)?,
        })
    }
}

#[derive(Clone, Copy, Debug)]
struct Built {
    num_points: usize,
    cell_width: f32,
    cell_width_inv: f32,
}

impl Clone for HashGrid {
    /// A grid sharing this one's buffers until either is built again (copy-on-write).
    fn clone(&self) -> Self {
        HashGrid {
            dims: self.dims,
            device: self.device.clone(),
            buffers: Arc::clone(&self.buffers),
            built: self.built,
            ranges_from_keys: self.ranges_from_keys,
            ranges_capture: self.ranges_capture,
        }
    }
}

impl std::fmt::Debug for HashGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HashGrid")
            .field("dims", &self.dims)
            .field("device", &self.device.alias())
            .field("num_points", &self.built.map(|b| b.num_points))
            .field("cell_width", &self.built.map(|b| b.cell_width))
            .finish()
    }
}

/// An `InvalidArgument` from `what` (`"HashGrid::build"`) about its argument `arg`.
fn bad(what: &str, arg: &str, why: impl std::fmt::Display) -> Error {
    Error::InvalidArgument {
        what: format!("{what}: argument `{arg}` {why}"),
    }
}

impl HashGrid {
    /// An empty grid of `dim_x x dim_y x dim_z` buckets on `device` (Warp's
    /// `wp.HashGrid(dim_x, dim_y, dim_z, device)`). Its bucket tables take
    /// `8 * dim_x * dim_y * dim_z` bytes; more buckets mean fewer far points sharing a bucket
    /// with near ones (Warp's examples use 128 per axis).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the dim when one is 0 or their product exceeds
    /// `i32::MAX`; allocation errors of the device.
    pub fn new(dim_x: usize, dim_y: usize, dim_z: usize, device: &Device) -> Result<HashGrid> {
        for (name, d) in [("dim_x", dim_x), ("dim_y", dim_y), ("dim_z", dim_z)] {
            if d == 0 {
                return Err(bad(
                    "HashGrid::new",
                    name,
                    "is 0: every dim must be at least 1",
                ));
            }
        }
        let too_many = || {
            bad(
                "HashGrid::new",
                "dim_x * dim_y * dim_z",
                format!(
                    "is {dim_x} x {dim_y} x {dim_z}, more than i32::MAX buckets (indices are i32, as in Warp)"
                ),
            )
        };
        let (Ok(x), Ok(y), Ok(z)) = (
            i32::try_from(dim_x),
            i32::try_from(dim_y),
            i32::try_from(dim_z),
        ) else {
            return Err(too_many());
        };
        let dims = [x, y, z];
        let cells = cell_count(dims).ok_or_else(too_many)? as usize;
        Ok(HashGrid {
            dims,
            device: device.clone(),
            buffers: Arc::new(Buffers::new(0, cells, device)?),
            built: None,
            ranges_from_keys: Some(0),
            ranges_capture: None,
        })
    }

    /// Buckets per axis.
    pub fn dims(&self) -> [usize; 3] {
        self.dims.map(|d| d as usize)
    }

    /// The device the grid's buffers live on (the device of the launches that take it).
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Whether the grid holds a build (kernels refuse a grid that does not).
    pub fn is_built(&self) -> bool {
        self.built.is_some()
    }

    /// The number of points of the last build (`None` before one).
    pub fn num_points(&self) -> Option<usize> {
        self.built.map(|b| b.num_points)
    }

    /// The cell width of the last build (its `radius`; `None` before one).
    pub fn cell_width(&self) -> Option<f32> {
        self.built.map(|b| b.cell_width)
    }

    /// How many points a build can take without allocating.
    pub fn capacity(&self) -> usize {
        self.buffers.point_ids.len()
    }

    /// The point indices of the last build in bucket order (what `hash_grid_point_id(grid, i)`
    /// returns for each `i`), a view of the grid's buffer: the next build overwrites it. A
    /// value written there that is not a point index makes a query that meets it fault (an
    /// out-of-bounds fault of the grid at that value).
    pub fn point_ids(&self) -> Option<Array<i32>> {
        let b = self.built?;
        self.buffers.point_ids.view(0..b.num_points).ok()
    }

    /// Each bucket's range `[start, end)` in [`point_ids`](HashGrid::point_ids) order, one
    /// entry per bucket (`(z * dim_y + y) * dim_x + x`), as views of the grid's buffers: for
    /// inspection and tests.
    pub fn cell_ranges(&self) -> Option<(Array<i32>, Array<i32>)> {
        self.built?;
        Some((
            self.buffers.cell_starts.clone(),
            self.buffers.cell_ends.clone(),
        ))
    }

    /// Makes room for builds of up to `num_points` points without allocating (Warp's
    /// `reserve`). A grid shared with a clone (a tape's) gets buffers of its own here (the
    /// copy of copy-on-write). A build the grid holds stays valid.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `num_points` exceeds `i32::MAX`; allocation errors.
    pub fn reserve(&mut self, num_points: usize) -> Result<()> {
        if num_points > i32::MAX as usize {
            return Err(bad(
                "HashGrid::reserve",
                "num_points",
                format!("is {num_points}, more than i32::MAX (indices are i32, as in Warp)"),
            ));
        }
        let cap = self.capacity().max(num_points);
        // The points of the build to carry over (none when called by `build`, which is about
        // to overwrite them).
        let kept = self.built.map_or(0, |b| b.num_points);
        match Arc::get_mut(&mut self.buffers) {
            Some(b) if b.point_ids.len() >= num_points => {}
            Some(b) => {
                let ids = Array::zeros(cap, &self.device)?;
                copy_prefix(&ids, &b.point_ids, kept)?;
                b.point_ids = ids;
                b.keys = Array::zeros(cap, &self.device)?;
                // The keys that wrote the ranges are gone.
                self.ranges_from_keys = None;
            }
            None => {
                // Shared with a clone: the clone keeps the old buffers, which are not written
                // again.
                let old = &self.buffers;
                let cells = old.cell_starts.len();
                let fresh = Buffers::new(cap, cells, &self.device)?;
                if self.built.is_some() {
                    copy_prefix(&fresh.point_ids, &old.point_ids, kept)?;
                    copy_prefix(&fresh.cell_starts, &old.cell_starts, cells)?;
                    copy_prefix(&fresh.cell_ends, &old.cell_ends, cells)?;
                }
                self.buffers = Arc::new(fresh);
                self.ranges_from_keys = None;
            }
        }
        Ok(())
    }

    /// Builds the grid from `points` with cells of width `radius` (Warp's `build(points,
    /// radius)`): the point indices sorted by bucket, each bucket's range recorded. Queries of
    /// any radius work on the result (a larger query radius visits more cells); a cell as wide
    /// as the usual query radius visits the fewest points. On a GPU the build is queued like a
    /// launch and reads nothing back: its check of the points is a fault of its own step (see
    /// Errors).
    ///
    /// A failed build leaves the grid unbuilt (kernels refuse it until a build succeeds).
    ///
    /// Inside a [capture](crate::capture) the build is recorded like a launch (the same on
    /// every backend): each replay rebuilds the grid from the contents of `points` at that
    /// time (as many points as now; launches recorded after it take the grid as built), in
    /// the grid's own buffers, so a grid may be built several times in one capture (a DEM
    /// frame's substeps). It must allocate nothing there: [`reserve`](HashGrid::reserve) room
    /// for the points before capturing, pass contiguous points, and let no clone made before
    /// the capture (a tape's) share the grid's buffers. On a GPU, build once before capturing
    /// (the first build loads its kernels and sizes the sort's scratch memory). A recorded
    /// build reports a non-finite point as a build does (below), at the replay.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the argument: `radius` not positive and finite (or so
    /// small that `1 / radius` is infinite); `points` on another device than the grid, with
    /// more than `i32::MAX` points, or, on the CPU, with a NaN or infinite coordinate (the
    /// first such index; the grid is left unbuilt). On a GPU a non-finite point is a fault
    /// ([`FaultKind::NonFiniteInput`](warp_core::FaultKind::NonFiniteInput) naming
    /// `HashGrid::build`, `points` and the first such index) reported by the next
    /// synchronisation, as a kernel's faults are; the grid is then built with that point
    /// bucketed consistently, so queries stay in bounds. (In debug mode the build waits for
    /// its steps, returns the fault and leaves the grid unbuilt, as on the CPU.)
    /// [`Error::Capture`] for a build inside a capture that would allocate (no room
    /// reserved, or buffers a clone made before the capture shares: see above); device
    /// errors.
    pub fn build(&mut self, points: &Array<Vec3>, radius: f32) -> Result<()> {
        if !(radius.is_finite() && radius > 0.0) {
            return Err(bad(
                WHAT,
                "radius",
                format!("is {radius}: the cell width must be positive and finite"),
            ));
        }
        let inv = 1.0 / radius;
        if !inv.is_finite() {
            return Err(bad(
                WHAT,
                "radius",
                format!("is {radius}: too small, 1 / radius is not finite"),
            ));
        }
        if points.device() != &self.device {
            return Err(bad(
                WHAT,
                "points",
                format!(
                    "is on device \"{}\" but the grid is on \"{}\"",
                    points.device().alias(),
                    self.device.alias()
                ),
            ));
        }
        let n = points.len();
        self.built = None;
        // Inside a capture the build is recorded: it must find its buffers (nothing is
        // allocated there), and what the last replay left is unknown at each replay.
        let in_capture = capturing::capturing();
        if in_capture {
            if self.capacity() < n {
                return Err(Error::Capture {
                    what: format!(
                        "{WHAT} of {n} points inside a capture needs room for them, which it \
                         would allocate: call `reserve({n})` on the grid before capturing"
                    ),
                });
            }
            // Written in place at each replay, the launches recorded after the build holding
            // the same buffers (a grid may be built several times in one capture).
            if !capturing::adopt(&self.buffers) {
                return Err(Error::Capture {
                    what: format!(
                        "{WHAT} inside a capture writes the grid's buffers in place, but a \
                         clone of the grid made before the capture (a tape's) shares them and \
                         must keep them: the copy it would write allocates (build once before \
                         capturing, or drop the clone)"
                    ),
                });
            }
        } else {
            self.reserve(n)?;
        }
        // The steps read the points as a contiguous run.
        let copy;
        let points = if points.is_contiguous() {
            points
        } else {
            copy = Array::zeros(n, &self.device)?;
            copy.copy_from(points)?;
            &copy
        };
        let cells = self.buffers.cell_starts.len();
        // Zero the ranges of the last build: from its keys (still in `keys`) when they are few
        // against the buckets, else every entry (a fill, the fastest way to zero them all).
        // Unknown until the new ranges are written. In a graph, from the keys of the build
        // recorded before this one in the same capture (which each replay runs just before);
        // every entry at the capture's first build, whose replays may follow any build.
        let capture = capturing::id();
        let clear_from = self
            .ranges_from_keys
            .take()
            .filter(|_| self.ranges_capture == capture);
        self.ranges_capture = None;
        let b: &Buffers = &self.buffers;
        // What the steps' addresses point into, kept by a graph that records them.
        let uses = || -> Keep {
            Box::new((
                points.clone(),
                [&b.keys, &b.point_ids, &b.cell_starts, &b.cell_ends, &b.bad].map(Array::clone),
            ))
        };
        match clear_from {
            Some(0) => {}
            Some(m) if m <= cells / 8 => dispatch::object_step_keeping(
                &self.device,
                &HashGridRanges {
                    keys: b.keys.device_address(),
                    starts: b.cell_starts.device_address(),
                    ends: b.cell_ends.device_address(),
                    n: m as i32,
                    buckets: cells as i32,
                    clear: 1,
                    pad: 0,
                    bad: 0,
                    points: 0,
                    fault: StepFault::new(&BUILD_NAMES),
                },
                uses,
            )?,
            _ => {
                b.cell_starts.fill(0)?;
                b.cell_ends.fill(0)?;
            }
        }
        b.bad.fill(i32::MAX)?;
        let step = HashGridKeys {
            points: points.device_address(),
            n: n as u64,
            dims: self.dims,
            inv,
            keys: b.keys.device_address(),
            values: b.point_ids.device_address(),
            bad: b.bad.device_address(),
        };
        dispatch::object_step_keeping(&self.device, &step, uses)?;
        // Buckets lie in 0..cells: sorting by their low bits is sorting by them.
        let bits = (usize::BITS - (cells - 1).leading_zeros()).max(1);
        radix_sort_pairs(&b.keys, &b.point_ids, n, Some(bits))?;
        dispatch::object_step_keeping(
            &self.device,
            &HashGridRanges {
                keys: b.keys.device_address(),
                starts: b.cell_starts.device_address(),
                ends: b.cell_ends.device_address(),
                n: n as i32,
                buckets: cells as i32,
                clear: 0,
                pad: 0,
                // The step reports the points' check itself (a GPU build reads nothing back).
                bad: b.bad.device_address(),
                points: points.device_address(),
                fault: StepFault::new(&BUILD_NAMES),
            },
            uses,
        )?;
        let built = Built {
            num_points: n,
            cell_width: radius,
            cell_width_inv: inv,
        };
        // The ranges step reported the points' check (on the CPU its error returned above; on a
        // GPU a fault, read at the next synchronisation). A build of a non-finite point is
        // complete and consistent. The launches queued (or recorded) next take the grid as
        // built; the next build clears from these keys (in a capture, the next one recorded
        // there).
        self.built = Some(built);
        (self.ranges_from_keys, self.ranges_capture) = (Some(n), capture);
        Ok(())
    }

    /// The build a launch of `ctx.kernel` may use (the launch device is checked by the
    /// [`HostObject`] seam before).
    fn launch_build(&self, ctx: &ArgCtx<'_>) -> Result<Built> {
        self.built.ok_or_else(|| Error::InvalidArgument {
            what: format!(
                "kernel `{}`: argument `{}`: the HashGrid was never built (or its last build \
                 failed): call `build` before launching",
                ctx.kernel, ctx.arg
            ),
        })
    }
}

/// What the build's messages name.
const WHAT: &str = "HashGrid::build";

/// Copies the first `n` elements of `src` into `dst`.
fn copy_prefix(dst: &Array<i32>, src: &Array<i32>, n: usize) -> Result<()> {
    if n == 0 {
        return Ok(());
    }
    dst.view(0..n)?.copy_from(&src.view(0..n)?)
}

/// A `HashGrid` kernel parameter as CUDA kernels receive it: `wp::hash_grid_t` in
/// `warp-cuda/cuda/wp_hash_grid.h`, field for field (48 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CudaHashGrid {
    /// Device address of the point indices in bucket order.
    pub point_ids: u64,
    /// Device address of each bucket's range start.
    pub cell_starts: u64,
    /// Device address of each bucket's range end.
    pub cell_ends: u64,
    /// Buckets per axis.
    pub dims: [i32; 3],
    /// Points in the grid.
    pub num_points: i32,
    /// `1 / cell width`.
    pub cell_width_inv: f32,
    /// The kernel parameter's index (reported in out-of-bounds faults).
    pub arg: i32,
}

const _: () = assert!(std::mem::size_of::<CudaHashGrid>() == 48);

impl HostObject for HashGrid {
    type View = HashGridView;
    type Cuda = CudaHashGrid;

    fn device(&self) -> &Device {
        &self.device
    }

    unsafe fn cpu_view(&self, ctx: &ArgCtx<'_>) -> Result<HashGridView> {
        let built = self.launch_build(ctx)?;
        let b = &self.buffers;
        let ids = b.point_ids.view(0..built.num_points)?;
        Ok(HashGridView::new(
            ids.cpu_view(ctx.kernel, ctx.arg),
            b.cell_starts.cpu_view(ctx.kernel, ctx.arg),
            b.cell_ends.cpu_view(ctx.kernel, ctx.arg),
            self.dims,
            built.cell_width_inv,
        ))
    }

    fn adopt_in_capture(&self) {
        // Shared with a clone made before the capture: not adopted (a rebuild is refused).
        capturing::adopt(&self.buffers);
    }

    fn cuda_record(&self, ctx: &ArgCtx<'_>) -> Result<CudaHashGrid> {
        let built = self.launch_build(ctx)?;
        let b = &self.buffers;
        let ptr = |a: &Array<i32>| a.device_address();
        Ok(CudaHashGrid {
            point_ids: ptr(&b.point_ids),
            cell_starts: ptr(&b.cell_starts),
            cell_ends: ptr(&b.cell_ends),
            dims: self.dims,
            num_points: built.num_points as i32,
            cell_width_inv: built.cell_width_inv,
            arg: ctx.index as i32,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts(dev: &Device, v: &[Vec3]) -> Array<Vec3> {
        Array::from_slice(v, dev).unwrap()
    }

    #[test]
    fn bad_input_is_an_error_naming_the_argument() {
        let dev = crate::cpu();
        for (dims, name) in [
            ([0, 1, 1], "dim_x"),
            ([1, 0, 1], "dim_y"),
            ([1, 1, 0], "dim_z"),
        ] {
            let e = HashGrid::new(dims[0], dims[1], dims[2], &dev).unwrap_err();
            assert!(e.to_string().contains(&format!("`{name}`")), "{e}");
        }
        let e = HashGrid::new(2000, 2000, 2000, &dev).unwrap_err();
        assert!(e.to_string().contains("i32::MAX"), "{e}");
        let mut g = HashGrid::new(4, 4, 4, &dev).unwrap();
        let x = pts(&dev, &[Vec3::ZERO, Vec3::ONE]);
        for r in [0.0, -1.0, f32::NAN, f32::INFINITY, 1e-45] {
            let e = g.build(&x, r).unwrap_err();
            assert!(e.to_string().contains("argument `radius`"), "{r}: {e}");
        }
        let bad_pts = pts(
            &dev,
            &[Vec3::ZERO, Vec3::new(0.0, f32::NAN, 0.0), Vec3::INFINITY],
        );
        let e = g.build(&bad_pts, 1.0).unwrap_err();
        assert!(
            e.to_string().contains("argument `points`") && e.to_string().contains("index 1"),
            "{e}"
        );
        assert!(!g.is_built(), "a failed build leaves the grid unbuilt");
        let e = g.reserve(i32::MAX as usize + 1).unwrap_err();
        assert!(e.to_string().contains("argument `num_points`"), "{e}");
    }

    #[test]
    fn build_sorts_by_bucket_and_copies_on_write() {
        let dev = crate::cpu();
        let mut g = HashGrid::new(2, 1, 1, &dev).unwrap();
        assert!(!g.is_built() && g.point_ids().is_none());
        let x = pts(
            &dev,
            &[Vec3::X * 5.0, Vec3::ZERO, Vec3::X * -5.0, Vec3::X * 0.5],
        );
        g.reserve(100).unwrap();
        assert_eq!(g.capacity(), 100);
        g.build(&x, 1.0).unwrap();
        assert_eq!(g.capacity(), 100, "a reserved grid does not reallocate");
        // Buckets: x = 5 -> cell 5 -> 1; 0 -> 0; -5 -> 1; 0.5 -> 0.
        assert_eq!(g.point_ids().unwrap().to_vec().unwrap(), vec![1, 3, 0, 2]);
        let (s, e) = g.cell_ranges().unwrap();
        assert_eq!(
            (s.to_vec().unwrap(), e.to_vec().unwrap()),
            (vec![0, 2], vec![2, 4])
        );
        // Reserving more keeps the build, shared or not.
        g.reserve(200).unwrap();
        assert_eq!(g.point_ids().unwrap().to_vec().unwrap(), vec![1, 3, 0, 2]);
        let shared = g.clone();
        g.reserve(300).unwrap();
        assert_eq!(g.capacity(), 300);
        assert_eq!(g.point_ids().unwrap().to_vec().unwrap(), vec![1, 3, 0, 2]);
        assert_eq!(g.cell_ranges().unwrap().1.to_vec().unwrap(), vec![2, 4]);
        assert_eq!(shared.capacity(), 200);
        // A clone keeps its build when the original is built again.
        let kept = g.clone();
        g.build(&pts(&dev, &[Vec3::X]), 1.0).unwrap();
        assert_eq!(g.point_ids().unwrap().to_vec().unwrap(), vec![0]);
        assert_eq!(
            kept.point_ids().unwrap().to_vec().unwrap(),
            vec![1, 3, 0, 2]
        );
        assert_eq!(kept.num_points(), Some(4));
        // The empty point set.
        g.build(&Array::zeros(0, &dev).unwrap(), 0.5).unwrap();
        assert_eq!(g.num_points(), Some(0));
        assert_eq!(g.cell_ranges().unwrap().1.to_vec().unwrap(), vec![0, 0]);
    }
}

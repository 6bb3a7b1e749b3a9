//! [`MarchingCubes`]: Warp's marching cubes (`wp.MarchingCubes(nx, ny, nz)`,
//! `mc.surface(field, threshold)`, `mc.verts`, `mc.indices`): the triangle mesh of the surface
//! where a dense field of `nx x ny x nz` node values crosses a threshold.
//!
//! Conventions (Warp 1.19's, `warp/_src/geometry/marching_cubes.py`):
//! - the field is an `Array<f32, 3>` of shape `(nx, ny, nz)` indexed `[x, y, z]` (z fastest);
//! - vertex positions are in grid-index space, node `(i, j, k)` at `(i, j, k)`, unless bounds
//!   are set ([`MarchingCubes::set_bounds`]: node `(0, 0, 0)` at `lower`, node
//!   `(nx - 1, ny - 1, nz - 1)` at `upper`, linearly between);
//! - a node is *outside* where its value is `>= threshold`, *inside* where it is below; the
//!   triangles wind counter-clockwise seen from outside, so for a signed distance (negative
//!   inside, e.g. `|p - c| - r`) their normals `(b - a) x (c - a)` point out of the surface
//!   and a closed surface has positive signed volume;
//! - one vertex per crossed grid edge, shared by the (up to four) cells around the edge, so a
//!   surface that stays inside the box is a closed, consistently oriented mesh (what the mesh
//!   queries' inside/outside sign needs); vertex ids follow (node, axis) order and triangles
//!   cell order, as in Warp;
//! - a vertex on the edge from node value `a` to node value `b` is at the edge's parameter
//!   `t = (threshold - a) / (b - a)` (clamped to `[0, 1]`), interpolated as
//!   `p_a * (1 - t) + p_b * t` along the edge's axis; its other two coordinates are the
//!   edge's exactly (Warp interpolates all three, which can move them by an ulp).
//!
//! A surface is three steps, the same on every device through the `ObjectStep` seam (rayon
//! on the CPU, the kernels of `warp-cuda/cuda/wp_marching_cubes.h` on a GPU, written step for
//! step alike so that both give the same mesh bit for bit): (1) per node, which of its three
//! grid edges the surface crosses, the case of the cell at the node, its vertex and triangle
//! counts and the check for NaN and infinite values; (2) the primitives' inclusive scans of
//! both counts (the vertex and triangle offsets), then a one-thread step copying both totals
//! into one small buffer, the one read back; (3) per node, its vertices and its cell's
//! triangles. The case tables ([`MarchingCubes::CASE_TO_TRI_RANGE`],
//! [`MarchingCubes::TRI_LOCAL_INDICES`]) are written once, in the header, and read from it
//! here at compile time.

use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicI32, Ordering};

use super::mesh::Mesh;
use crate::array::Array;
use crate::backend::{ObjectLibrary, ObjectStep};
use crate::cpp_table;
use crate::device::Device;
use crate::dispatch;
use crate::error::{Error, Result};
use crate::primitives::array_scan;

// ------------------------------------------------------------------------------------------
// The tables (the classic marching cubes tables, as Warp 1.19 has them)
// ------------------------------------------------------------------------------------------

/// Offset of each cell corner from the cell's node; corner `c` is bit `c` of a cell's case.
const CUBE_CORNER_OFFSETS: [[i32; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [1, 1, 1],
    [0, 1, 1],
];

/// The two corners each cell edge joins (the lower corner first).
const EDGE_TO_CORNERS: [[usize; 2]; 12] = [
    [0, 1],
    [1, 2],
    [3, 2],
    [0, 3],
    [4, 5],
    [5, 6],
    [7, 6],
    [4, 7],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

/// Each cell edge as a grid edge: `[dx, dy, dz, axis]`, the edge along `axis` owned by the node
/// at the cell's node plus `(dx, dy, dz)`. Derived from the two tables above.
const EDGE_GRID_OFFSETS: [[u8; 4]; 12] = {
    let mut out = [[0u8; 4]; 12];
    let mut e = 0;
    while e < 12 {
        let a = CUBE_CORNER_OFFSETS[EDGE_TO_CORNERS[e][0]];
        let b = CUBE_CORNER_OFFSETS[EDGE_TO_CORNERS[e][1]];
        let mut axis = 0;
        let mut differ = 0;
        let mut k = 0;
        while k < 3 {
            if a[k] != b[k] {
                // The first corner is the lower one: the edge runs up its axis.
                assert!(b[k] == a[k] + 1);
                axis = k;
                differ += 1;
            }
            out[e][k] = a[k] as u8;
            k += 1;
        }
        assert!(differ == 1);
        out[e][3] = axis as u8;
        e += 1;
    }
    out
};

/// The CUDA library's marching cubes header, which holds the case tables: the one copy of
/// them, read here at compile time ([`cpp_table`]).
const HEADER: &str = include_str!("../../../warp-cuda/cuda/wp_marching_cubes.h");

/// For case `c`, its triangles are `TRI_LOCAL_INDICES[CASE_TO_TRI_RANGE[c]..CASE_TO_TRI_RANGE[c + 1]]`
/// (the header's `mc_case_to_tri_range`).
const CASE_TO_TRI_RANGE: [u16; 257] =
    cpp_table::to_u16(cpp_table::array(HEADER, "mc_case_to_tri_range"));

/// Each case's triangles, three cell edges each (the header's `mc_tri_local_indices`).
const TRI_LOCAL_INDICES: [u8; 2460] =
    cpp_table::to_u8(cpp_table::array(HEADER, "mc_tri_local_indices"));

// The header's grid-edge table is the one derived above from the corner and edge tables.
const _: () = {
    let header: [u8; 48] = cpp_table::to_u8(cpp_table::array(HEADER, "mc_edge_offsets"));
    let mut k = 0;
    while k < 48 {
        assert!(header[k] == EDGE_GRID_OFFSETS[k / 4][k % 4]);
        k += 1;
    }
};

const _: () = assert!(CASE_TO_TRI_RANGE[256] as usize == TRI_LOCAL_INDICES.len());

/// The most triangles one cell's case has (15 table entries).
const MAX_TRIS_PER_CELL: usize = 5;

/// The most nodes a grid may have: every count the steps keep is an `i32` (as Warp's), and a
/// grid of `n` nodes has fewer than `3n` vertices and `5n` triangles.
pub const MAX_NODES: usize = i32::MAX as usize / MAX_TRIS_PER_CELL;

const _: () = {
    let mut c = 0;
    while c < 256 {
        let n = CASE_TO_TRI_RANGE[c + 1] - CASE_TO_TRI_RANGE[c];
        assert!(n.is_multiple_of(3) && n as usize <= 3 * MAX_TRIS_PER_CELL);
        c += 1;
    }
};

// ------------------------------------------------------------------------------------------
// The steps
// ------------------------------------------------------------------------------------------

/// The marching cubes build library: `wp_marching_cubes.h` with its kernels enabled.
pub(crate) static LIBRARY: ObjectLibrary = ObjectLibrary::of("marching_cubes");

/// Step 1, per node `n` of the `dims` grid (field values `f32`, row-major, z fastest): which of
/// its three grid edges the surface crosses (bits 0..2 of the edge mask: the endpoints on
/// different sides of `threshold`), the case of the cell at the node (0 where none starts),
/// into `codes[n] = case | mask << 8`; its vertex count (crossed edges) into `vcount[n]`; the
/// case's triangle count into `tcount[n]`; the smallest node whose value is NaN or infinite
/// into the `i32` at `bad` (atomically lowered; left alone when all are finite).
/// `wp::mc_count_t` in C++ (56 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct MarchingCubesCount {
    pub field: u64,
    pub codes: u64,
    pub vcount: u64,
    pub tcount: u64,
    pub bad: u64,
    pub dims: [i32; 3],
    pub threshold: f32,
}

const _: () = assert!(std::mem::size_of::<MarchingCubesCount>() == 56);

/// Step 2 (one thread): the last entries of the `n`-long inclusive scans at `vscan` and
/// `tscan` (the vertex and triangle totals) into `totals[0]` and `totals[1]`.
/// `wp::mc_totals_t` in C++ (32 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct MarchingCubesTotals {
    pub vscan: u64,
    pub tscan: u64,
    pub totals: u64,
    pub n: i64,
}

const _: () = assert!(std::mem::size_of::<MarchingCubesTotals>() == 32);

/// Step 3, per node: its vertices (`num_verts` `Vec3`s at `verts`) and its cell's triangles
/// (`3 * num_tris` `i32`s at `indices`), from the field, the codes of step 1 and the inclusive
/// scans of its counts (`vscan`, `tscan`); node `(i, j, k)` is at `lower + (i, j, k) * delta`.
/// `wp::mc_emit_t` in C++ (96 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct MarchingCubesEmit {
    pub field: u64,
    pub codes: u64,
    pub vscan: u64,
    pub tscan: u64,
    pub verts: u64,
    pub indices: u64,
    pub dims: [i32; 3],
    pub threshold: f32,
    pub lower: [f32; 3],
    pub delta: [f32; 3],
    pub num_verts: i32,
    pub num_tris: i32,
}

const _: () = assert!(std::mem::size_of::<MarchingCubesEmit>() == 96);

/// The nodes of a `dims` grid (below `MAX_NODES` by construction, so an `i32` product).
fn node_count(dims: [i32; 3]) -> usize {
    dims.iter().map(|d| *d as usize).product()
}

/// Node `n`'s coordinates (row-major, z fastest).
fn node_coords(dims: [i32; 3], n: usize) -> [usize; 3] {
    let (ny, nz) = (dims[1] as usize, dims[2] as usize);
    let r = n / nz;
    [r / ny, r % ny, n % nz]
}

/// The bits set in a 3-bit edge mask (`wp::mc_popc3`).
fn popc3(m: i32) -> i32 {
    (m & 7).count_ones() as i32
}

/// Step 1 at node `n`: `(codes[n], vcount[n], tcount[n], value is finite)` (the C++
/// `mc_count_node`).
fn count_node(f: &[f32], dims: [i32; 3], threshold: f32, n: usize) -> (i32, i32, i32, bool) {
    let [i, j, k] = node_coords(dims, n);
    let stride = [(dims[1] * dims[2]) as usize, dims[2] as usize, 1];
    let has = [
        i + 1 < dims[0] as usize,
        j + 1 < dims[1] as usize,
        k + 1 < dims[2] as usize,
    ];
    let v0 = f[n];
    let o0 = v0 >= threshold;
    let mut mask = 0;
    for a in 0..3 {
        if has[a] && (f[n + stride[a]] >= threshold) != o0 {
            mask |= 1 << a;
        }
    }
    let (mut code, mut ntri) = (0usize, 0);
    if has[0] && has[1] && has[2] {
        for (c, o) in CUBE_CORNER_OFFSETS.iter().enumerate() {
            let m = n + o[0] as usize * stride[0] + o[1] as usize * stride[1] + o[2] as usize;
            if f[m] >= threshold {
                code |= 1 << c;
            }
        }
        ntri = (CASE_TO_TRI_RANGE[code + 1] - CASE_TO_TRI_RANGE[code]) as i32 / 3;
    }
    (code as i32 | mask << 8, popc3(mask), ntri, v0.is_finite())
}

/// A pointer that rayon tasks share, for writes to elements no two tasks share.
#[derive(Clone, Copy)]
struct Shared<T>(*mut T);
// SAFETY: every use writes elements that no other task touches (see the callers).
unsafe impl<T> Send for Shared<T> {}
unsafe impl<T> Sync for Shared<T> {}

impl<T> Shared<T> {
    /// Element `i` (a method, so that closures capture the `Shared`, not its raw pointer).
    fn at(self, i: usize) -> *mut T {
        self.0.wrapping_add(i)
    }
}

// SAFETY (all three steps): `#[repr(C)]` records laid out as the C++ structs of
// `wp_marching_cubes.h` (both sides assert the sizes); `MarchingCubes::surface` passes its own
// scratch (one `i32` per node, 4 totals), a contiguous field of `dims` nodes, and output
// arrays of `num_verts` vertices and `3 * num_tris` indices.
unsafe impl ObjectStep for MarchingCubesCount {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_mc_count";

    fn len(&self) -> usize {
        node_count(self.dims)
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        // SAFETY: `n` field values and `n` codes and counts in distinct host arrays the surface
        // owns (the field is the caller's, only read); nothing else touches them meanwhile.
        let (f, codes, vcount, tcount) = unsafe {
            (
                std::slice::from_raw_parts(self.field as *const f32, n),
                std::slice::from_raw_parts_mut(self.codes as *mut i32, n),
                std::slice::from_raw_parts_mut(self.vcount as *mut i32, n),
                std::slice::from_raw_parts_mut(self.tcount as *mut i32, n),
            )
        };
        // SAFETY: an i32 of the scratch, aligned and sized as an AtomicI32.
        let bad = unsafe { &*(self.bad as *const AtomicI32) };
        let (dims, threshold) = (self.dims, self.threshold);
        codes
            .par_iter_mut()
            .zip(vcount.par_iter_mut())
            .zip(tcount.par_iter_mut())
            .enumerate()
            .with_min_len(4096)
            .for_each(|(i, ((c, v), t))| {
                let (code, nv, nt, finite) = count_node(f, dims, threshold, i);
                if !finite {
                    bad.fetch_min(i as i32, Ordering::Relaxed);
                }
                (*c, *v, *t) = (code, nv, nt);
            });
        Ok(())
    }
}

unsafe impl ObjectStep for MarchingCubesTotals {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_mc_totals";

    fn len(&self) -> usize {
        1
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.n as usize;
        // SAFETY: two scans of `n >= 1` i32s and 2 totals, the surface's own host scratch.
        unsafe {
            let totals = self.totals as *mut i32;
            totals.write(*(self.vscan as *const i32).add(n - 1));
            totals.add(1).write(*(self.tscan as *const i32).add(n - 1));
        }
        Ok(())
    }
}

unsafe impl ObjectStep for MarchingCubesEmit {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_mc_emit";

    fn len(&self) -> usize {
        node_count(self.dims)
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        // SAFETY: `n` field values, codes and scans, the surface's (read only here).
        let (f, codes, vscan, tscan) = unsafe {
            (
                std::slice::from_raw_parts(self.field as *const f32, n),
                std::slice::from_raw_parts(self.codes as *const i32, n),
                std::slice::from_raw_parts(self.vscan as *const i32, n),
                std::slice::from_raw_parts(self.tscan as *const i32, n),
            )
        };
        let verts = Shared(self.verts as *mut Vec3);
        let indices = Shared(self.indices as *mut i32);
        let s = *self;
        (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .for_each(|node| emit_node(&s, f, codes, vscan, tscan, verts, indices, node));
        Ok(())
    }
}

/// Step 3 at node `n` (the C++ `mc_emit_node`, operation for operation).
#[allow(clippy::too_many_arguments)]
fn emit_node(
    s: &MarchingCubesEmit,
    f: &[f32],
    codes: &[i32],
    vscan: &[i32],
    tscan: &[i32],
    verts: Shared<Vec3>,
    indices: Shared<i32>,
    n: usize,
) {
    let dims = s.dims;
    let c = codes[n];
    let mask = (c >> 8) & 7;
    let code = (c & 255) as usize;
    let stride = [(dims[1] * dims[2]) as usize, dims[2] as usize, 1];
    if mask != 0 {
        let idx = node_coords(dims, n);
        let p: [f32; 3] = std::array::from_fn(|a| s.lower[a] + idx[a] as f32 * s.delta[a]);
        let v0 = f[n];
        let mut id = vscan[n] - popc3(mask);
        for a in 0..3 {
            if (mask >> a) & 1 == 0 {
                continue;
            }
            let v1 = f[n + stride[a]];
            // Only overflow (both differences infinite) can make t NaN or leave [0, 1]; NaN -> 0.
            let mut t = (s.threshold - v0) / (v1 - v0);
            // `!(t > 0)` in C++: NaN and -0 become +0.
            if t.is_nan() || t <= 0.0 {
                t = 0.0;
            } else if t > 1.0 {
                t = 1.0;
            }
            let q = s.lower[a] + (idx[a] + 1) as f32 * s.delta[a];
            let mut out = p;
            out[a] = p[a] * (1.0 - t) + q * t;
            if id >= 0 && id < s.num_verts {
                // SAFETY: `id` is below the vertex count, and vertex ids are unique to their
                // edge, so no other task writes this element.
                unsafe { verts.at(id as usize).write(Vec3::from(out)) };
            }
            id += 1;
        }
    }
    let (lo, hi) = (
        CASE_TO_TRI_RANGE[code] as usize,
        CASE_TO_TRI_RANGE[code + 1] as usize,
    );
    if hi > lo {
        let count = hi - lo;
        let first = 3 * (tscan[n] as i64 - (count / 3) as i64);
        if first < 0 || first + count as i64 > 3 * s.num_tris as i64 {
            return;
        }
        for e in lo..hi {
            let [dx, dy, dz, a] = EDGE_GRID_OFFSETS[TRI_LOCAL_INDICES[e] as usize];
            let m = n + dx as usize * stride[0] + dy as usize * stride[1] + dz as usize;
            let mm = (codes[m] >> 8) & 7;
            let id = vscan[m] - popc3(mm) + popc3(mm & ((1 << a) - 1));
            // SAFETY: inside the index array (checked above); the range is this cell's
            // triangles', which no other task writes.
            unsafe { indices.at(first as usize + (e - lo)).write(id) };
        }
    }
}

// ------------------------------------------------------------------------------------------
// The host object
// ------------------------------------------------------------------------------------------

/// The scratch of one grid size on the object's device: one `i32` per node each.
#[derive(Clone)]
struct Scratch {
    /// Step 1's `case | edge mask << 8`.
    codes: Array<i32>,
    /// The vertex counts, then (scanned in place) their inclusive prefix sums.
    vscan: Array<i32>,
    /// The triangle counts, then their inclusive prefix sums.
    tscan: Array<i32>,
    /// `[vertices, triangles, first bad node (i32::MAX: none), unused]`.
    totals: Array<i32>,
}

/// Marching cubes on one device (Warp's `wp.MarchingCubes`): make one for a grid size, then
/// [`surface`](MarchingCubes::surface) fields of that size; the mesh of the last surface is
/// [`verts`](MarchingCubes::verts) and [`indices`](MarchingCubes::indices) (or
/// [`to_mesh`](MarchingCubes::to_mesh) for the mesh queries). See the [module docs](self) for
/// the conventions.
///
/// ```
/// # use warp_runtime as wp;
/// # use glam::Vec3;
/// let dev = wp::cpu();
/// let n = 16;
/// // A sphere of radius 5 around the grid's centre: negative inside.
/// let c = Vec3::splat(7.5);
/// let mut field = Vec::new();
/// for i in 0..n {
///     for j in 0..n {
///         for k in 0..n {
///             field.push((Vec3::new(i as f32, j as f32, k as f32) - c).length() - 5.0);
///         }
///     }
/// }
/// let field = wp::Array::from_slice_shape(&field, (n, n, n), &dev)?;
/// let mut mc = wp::MarchingCubes::new(n, n, n, &dev)?;
/// mc.surface(&field, 0.0)?;
/// let verts = mc.verts().to_vec()?;
/// assert!(verts.iter().all(|v| ((*v - c).length() - 5.0).abs() < 0.1));
/// assert_eq!(mc.indices().len() % 3, 0);
/// # Ok::<(), wp::Error>(())
/// ```
pub struct MarchingCubes {
    dims: [i32; 3],
    device: Device,
    lower: Option<Vec3>,
    upper: Option<Vec3>,
    /// Allocated by the first surface (and again after a resize to another node count).
    scratch: Option<Scratch>,
    verts: Array<Vec3>,
    indices: Array<i32>,
}

impl std::fmt::Debug for MarchingCubes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MarchingCubes")
            .field("dims", &self.dims)
            .field("device", &self.device.alias())
            .field("lower", &self.lower)
            .field("upper", &self.upper)
            .field("num_verts", &self.verts.len())
            .field("num_tris", &(self.indices.len() / 3))
            .finish()
    }
}

/// An `InvalidArgument` from `what` (`"MarchingCubes::surface"`) about its argument `arg`.
fn bad(what: &str, arg: &str, why: impl std::fmt::Display) -> Error {
    Error::InvalidArgument {
        what: format!("{what}: argument `{arg}` {why}"),
    }
}

/// The grid size as `i32`s: every extent at least 2 (a cell), at most `MAX_NODES` nodes.
fn check_dims(what: &str, nx: usize, ny: usize, nz: usize) -> Result<[i32; 3]> {
    for (name, d) in [("nx", nx), ("ny", ny), ("nz", nz)] {
        if d < 2 {
            return Err(bad(
                what,
                name,
                format!("is {d}: a grid needs at least 2 nodes per axis (one cell)"),
            ));
        }
    }
    match nx.checked_mul(ny).and_then(|p| p.checked_mul(nz)) {
        Some(n) if n <= MAX_NODES => Ok([nx as i32, ny as i32, nz as i32]),
        _ => Err(bad(
            what,
            "nx * ny * nz",
            format!(
                "is {nx} x {ny} x {nz}, more than {MAX_NODES} nodes (i32::MAX / 5: the vertex \
                 and triangle counts are i32, as in Warp)"
            ),
        )),
    }
}

impl MarchingCubes {
    /// The offset of each cell corner from the cell's node; corner `c` is bit `c` of a cell's
    /// case (set where the corner's value is `>= threshold`). Warp's `CUBE_CORNER_OFFSETS`.
    pub const CUBE_CORNER_OFFSETS: [[i32; 3]; 8] = CUBE_CORNER_OFFSETS;
    /// The two corners (of [`CUBE_CORNER_OFFSETS`](Self::CUBE_CORNER_OFFSETS)) each of the 12
    /// cell edges joins, the lower corner first. Warp's `EDGE_TO_CORNERS`.
    pub const EDGE_TO_CORNERS: [[usize; 2]; 12] = EDGE_TO_CORNERS;
    /// Each cell edge as a grid edge `[dx, dy, dz, axis]`: the edge along `axis` (0 = x) from
    /// the cell's node plus `(dx, dy, dz)` (derived from the two tables above).
    pub const EDGE_GRID_OFFSETS: [[u8; 4]; 12] = EDGE_GRID_OFFSETS;
    /// 257 offsets: case `c`'s triangles are
    /// `TRI_LOCAL_INDICES[CASE_TO_TRI_RANGE[c]..CASE_TO_TRI_RANGE[c + 1]]`. Warp's
    /// `CASE_TO_TRI_RANGE`.
    pub const CASE_TO_TRI_RANGE: [u16; 257] = CASE_TO_TRI_RANGE;
    /// Every case's triangles, three cell edges (0..12) each, the vertices of a triangle in
    /// counter-clockwise order seen from outside. Warp's `TRI_LOCAL_INDICES`.
    pub const TRI_LOCAL_INDICES: [u8; 2460] = TRI_LOCAL_INDICES;

    /// Marching cubes for fields of `nx x ny x nz` nodes on `device` (Warp's
    /// `wp.MarchingCubes(nx, ny, nz)`; there the device is the field's). Its scratch (16 bytes
    /// per node) is allocated by the first [`surface`](MarchingCubes::surface).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the extent when one is below 2, or naming their
    /// product when the grid has more than [`MAX_NODES`] nodes; allocation errors.
    pub fn new(nx: usize, ny: usize, nz: usize, device: &Device) -> Result<MarchingCubes> {
        let dims = check_dims("MarchingCubes::new", nx, ny, nz)?;
        Ok(MarchingCubes {
            dims,
            device: device.clone(),
            lower: None,
            upper: None,
            scratch: None,
            verts: Array::zeros(0, device)?,
            indices: Array::zeros(0, device)?,
        })
    }

    /// Nodes per axis, `[nx, ny, nz]`.
    pub fn dims(&self) -> [usize; 3] {
        self.dims.map(|d| d as usize)
    }

    /// The device of the object's arrays (and of the fields it takes).
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Changes the grid size for the next surfaces (Warp's `resize`); the mesh of the last
    /// surface stays. The scratch is reallocated at the next surface if the node count changed.
    ///
    /// # Errors
    /// As [`new`](MarchingCubes::new); a failed resize changes nothing.
    pub fn resize(&mut self, nx: usize, ny: usize, nz: usize) -> Result<()> {
        self.dims = check_dims("MarchingCubes::resize", nx, ny, nz)?;
        Ok(())
    }

    /// Sets where the grid lies (Warp's `lower` and `upper`): node `(0, 0, 0)` at `lower`
    /// (`None`: the origin), node `(nx - 1, ny - 1, nz - 1)` at `upper` (`None`:
    /// `(nx - 1, ny - 1, nz - 1)`, so that with neither set a node's position is its index).
    /// Node `(i, j, k)` is at `lower + (i, j, k) * (upper - lower) / (n - 1)`, in f32 in that
    /// order. Takes effect at the next surface.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the bound when it has a NaN or infinite coordinate (a
    /// failed call changes nothing).
    pub fn set_bounds(&mut self, lower: Option<Vec3>, upper: Option<Vec3>) -> Result<()> {
        for (name, b) in [("lower", lower), ("upper", upper)] {
            if let Some(v) = b.filter(|v| !v.is_finite()) {
                return Err(bad(
                    "MarchingCubes::set_bounds",
                    name,
                    format!("is {v:?}: bounds must be finite"),
                ));
            }
        }
        (self.lower, self.upper) = (lower, upper);
        Ok(())
    }

    /// The lower bound set by [`set_bounds`](MarchingCubes::set_bounds) (`None`: the origin).
    pub fn lower(&self) -> Option<Vec3> {
        self.lower
    }

    /// The upper bound set by [`set_bounds`](MarchingCubes::set_bounds) (`None`: the last
    /// node's index).
    pub fn upper(&self) -> Option<Vec3> {
        self.upper
    }

    /// The vertices of the last surface (empty before one, or after a failed one): one per
    /// crossed grid edge, in (node, axis) order. Each surface makes new arrays, so a clone
    /// taken earlier keeps its mesh.
    pub fn verts(&self) -> &Array<Vec3> {
        &self.verts
    }

    /// The triangles of the last surface as a flat array, three vertex indices per triangle
    /// (counter-clockwise seen from outside), in cell order (empty before a surface, or after
    /// a failed one).
    pub fn indices(&self) -> &Array<i32> {
        &self.indices
    }

    /// A [`Mesh`] of the last surface (sharing its vertex array; see [`Mesh::new`]), for the
    /// mesh queries. The empty surface gives the empty mesh.
    ///
    /// # Errors
    /// As [`Mesh::new`] (device errors; the surface's indices and vertices are valid by
    /// construction).
    pub fn to_mesh(&self) -> Result<Mesh> {
        Mesh::new(&self.verts, &self.indices, None)
    }

    /// Extracts the surface where `field` crosses `threshold` (Warp's `surface(field,
    /// threshold)`): afterwards [`verts`](MarchingCubes::verts) and
    /// [`indices`](MarchingCubes::indices) hold its mesh. On a GPU the steps are queued like
    /// launches; the call waits once, to read the totals and the field check back (after the
    /// scans), and returns with the last step queued.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the argument: `field` of another shape than the
    /// grid's `(nx, ny, nz)`, on another device than the object, or with a NaN or infinite
    /// value (naming the first such node, in row-major order, and its value); `threshold` NaN
    /// or infinite; device errors. A failed surface leaves the object with the empty mesh.
    pub fn surface(&mut self, field: &Array<f32, 3>, threshold: f32) -> Result<()> {
        const WHAT: &str = "MarchingCubes::surface";
        // Whatever happens below, the last surface's mesh is no longer this call's result.
        self.verts = Array::zeros(0, &self.device)?;
        self.indices = Array::zeros(0, &self.device)?;
        let dims = self.dims;
        let want = self.dims();
        if field.shape() != want {
            return Err(bad(
                WHAT,
                "field",
                format!(
                    "has shape {:?} but the grid is {want:?} nodes (resize the MarchingCubes \
                     for another size)",
                    field.shape()
                ),
            ));
        }
        if field.device() != &self.device {
            return Err(bad(
                WHAT,
                "field",
                format!(
                    "is on device \"{}\" but the MarchingCubes is on \"{}\"",
                    field.device().alias(),
                    self.device.alias()
                ),
            ));
        }
        if !threshold.is_finite() {
            return Err(bad(
                WHAT,
                "threshold",
                format!("is {threshold}: it must be finite"),
            ));
        }
        let n = node_count(dims);
        // The steps read the field as one contiguous run.
        let field = if field.is_contiguous() {
            field.reshape(n)?
        } else {
            let copy = Array::<f32, 3>::empty(want, &self.device)?;
            copy.copy_from(field)?;
            copy.reshape(n)?
        };
        let s = self.scratch(n)?;
        s.totals.fill(i32::MAX)?;
        dispatch::object_step(
            &self.device,
            &MarchingCubesCount {
                field: field.device_address(),
                codes: s.codes.device_address(),
                vcount: s.vscan.device_address(),
                tcount: s.tscan.device_address(),
                bad: s.totals.device_address() + 8,
                dims,
                threshold,
            },
        )?;
        array_scan(&s.vscan, &s.vscan, true)?;
        array_scan(&s.tscan, &s.tscan, true)?;
        dispatch::object_step(
            &self.device,
            &MarchingCubesTotals {
                vscan: s.vscan.device_address(),
                tscan: s.tscan.device_address(),
                totals: s.totals.device_address(),
                n: n as i64,
            },
        )?;
        // The one wait of a surface.
        let totals = s.totals.to_vec()?;
        if totals[2] != i32::MAX {
            let b = totals[2] as usize;
            let v = field.view(b..b + 1)?.to_vec()?[0];
            let [i, j, k] = node_coords(dims, b);
            return Err(bad(
                WHAT,
                "field",
                format!(
                    "has a non-finite value {v} at node [{i}, {j}, {k}] (the first in row-major \
                     order): marching cubes needs finite values"
                ),
            ));
        }
        let (nv, nt) = (totals[0], totals[1]);
        // The counts are bounded by construction (at most 3 and 5 per node, MAX_NODES nodes):
        // anything else is a broken step, not bad input.
        if nv < 0 || nv as usize > 3 * n || nt < 0 || nt as usize > MAX_TRIS_PER_CELL * n {
            return Err(Error::invalid(format!(
                "{WHAT}: internal error: the counting step found {nv} vertices and {nt} \
                 triangles for {n} nodes"
            )));
        }
        let verts = Array::<Vec3>::empty(nv as usize, &self.device)?;
        let indices = Array::<i32>::empty(3 * nt as usize, &self.device)?;
        let lower = self.lower.unwrap_or(Vec3::ZERO);
        let upper = self.upper.unwrap_or_else(|| {
            Vec3::new(
                (dims[0] - 1) as f32,
                (dims[1] - 1) as f32,
                (dims[2] - 1) as f32,
            )
        });
        // Warp's spacing: (upper - lower) / cells, per axis in f32.
        let delta = std::array::from_fn(|a| (upper[a] - lower[a]) / (dims[a] - 1) as f32);
        dispatch::object_step(
            &self.device,
            &MarchingCubesEmit {
                field: field.device_address(),
                codes: s.codes.device_address(),
                vscan: s.vscan.device_address(),
                tscan: s.tscan.device_address(),
                verts: verts.device_address(),
                indices: indices.device_address(),
                dims,
                threshold,
                lower: lower.to_array(),
                delta,
                num_verts: nv,
                num_tris: nt,
            },
        )?;
        self.verts = verts;
        self.indices = indices;
        Ok(())
    }

    /// The scratch for `n` nodes (allocated when there is none of that size; a clone of
    /// arrays sharing the object's memory).
    fn scratch(&mut self, n: usize) -> Result<Scratch> {
        let s = match self.scratch.take() {
            Some(s) if s.codes.len() == n => s,
            old => {
                // Dropped first: two grids' scratch never coexist.
                drop(old);
                Scratch {
                    codes: Array::zeros(n, &self.device)?,
                    vscan: Array::zeros(n, &self.device)?,
                    tscan: Array::zeros(n, &self.device)?,
                    totals: Array::zeros(4, &self.device)?,
                }
            }
        };
        Ok(self.scratch.insert(s).clone())
    }
}

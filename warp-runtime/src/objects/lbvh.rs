//! A linear BVH build (Karras 2012) and its refit, the same on every device through the
//! `ObjectStep` seam: the centroids' box, a 30-bit Morton code per primitive, the
//! primitives' stable radix sort of (code, index), Karras's hierarchy over the sorted codes
//! (the index breaking ties), and a bottom-up refit. On a GPU the steps are the kernels of
//! `wp_bvh_build.h` (its header comment states the numbering and each step); here they are
//! also written in Rust, step for step, so that the CPU and the GPU make the same tree bit for
//! bit (every step is exact: order-preserving integer min/max, a quantisation with no fused
//! operation, min/max unions).
//!
//! The tree is in warp-core's layout (`warp_core::objects::bvh`): for `n >= 2` primitives the
//! `n - 1` internal nodes come first (the root is internal node 0), then one leaf per sorted
//! primitive; for `n = 1` the root is the leaf; for `n = 0` the empty tree. A linear BVH builds
//! in a few passes over the primitives, so it suits the GPU; its trees are worse than a SAH
//! build's for queries, which is why the CPU keeps `bvh_build::build_sah`.

use super::bvh_build;
use crate::array::Array;
use crate::backend::{ObjectLibrary, ObjectStep, StepFault};
use crate::capturing::Keep;
use crate::device::Device;
use crate::dispatch;
use crate::error::Result;
use crate::kernel::KernelInfo;
use crate::primitives::radix_sort_pairs;
use glam::{Vec3, Vec4};
use rayon::prelude::*;
use warp_core::objects::bvh::BvhNode;
use warp_core::{Fault, FaultKind};

/// The BVH build library: `wp_bvh_build.h` with its kernels enabled.
pub(crate) static LIBRARY: ObjectLibrary = ObjectLibrary::of("bvh_build");

/// The leaf size of a `Bvh`'s linear BVH: one box per leaf, as Warp's `wp.Bvh` (its box and
/// ray queries test each box anyway, so a larger leaf only adds tests).
pub const BVH_LEAF_SIZE: usize = 1;

/// The leaf size of a `Mesh`'s linear BVH: up to 4 triangles per leaf, as Warp's meshes. A
/// closest-point query then tests a few triangles in place of the two child boxes and the
/// stack traffic of each of the 3 levels the leaf replaces.
pub const MESH_LEAF_SIZE: usize = 4;

/// Nodes of a tree over `n` primitives.
pub(crate) fn node_count(n: usize) -> usize {
    (2 * n).saturating_sub(1).max(1)
}

/// The tree's buffers (allocated by the caller on the build's device): `node_count(n)` nodes
/// (as 8 words each), twice as many links (`parents`: each node's parent, then each node's
/// escape), `n` primitive ids, and the refit's counters, one per node,
/// zero (`Array::zeros`; a refit leaves them zero).
pub(crate) struct LbvhTree<'a> {
    pub nodes: &'a Array<i32>,
    pub parents: &'a Array<i32>,
    pub prim_ids: &'a Array<i32>,
    pub counters: &'a Array<i32>,
}

/// What a refit checks and reports (`wp::lbvh_refit_t`'s `bad`, `sources`, `check`,
/// `num_points` and `fault`): the smallest index of a non-finite element, as a fault named by
/// `names` (a `NonFiniteInput` of argument 0 or 1), or a mesh's smallest position of an index
/// outside its points (an `OutOfBounds` of argument 1), raised by the refit itself, so that a
/// refit is one launch that reads nothing back.
pub(crate) struct RefitCheck<'a> {
    /// Two `i32` words at `i32::MAX` (the refit leaves them so): the smallest bad index of
    /// argument 0 and of argument 1.
    pub bad: &'a Array<i32>,
    /// The elements the words index, by argument (reported with the index).
    pub sources: [Option<&'a Array<Vec3>>; 2],
    /// A mesh's indices and its number of points: word 1 is then the smallest position of an
    /// index outside the points (lowered by [`triangle_boxes`]), reported as out of bounds
    /// of argument 1 with index `[position, value]` and shape `[indices, points]` (`sources[1]`
    /// is then `None`).
    pub indices: Option<(&'a Array<i32>, usize)>,
    /// Whether the refit checks the boxes it reads (then `sources` are the lowers and
    /// uppers), or only reports what an earlier step found (a mesh's points, checked by
    /// [`triangle_boxes`]).
    pub check_boxes: bool,
    /// Whether the boxes are by leaf position (box `k` is that of `prim_ids[k]`, as the
    /// triangle boxes' step writes them in leaf order) rather than by primitive.
    pub by_position: bool,
    /// The operation and its arguments, as the fault names them.
    pub names: &'static KernelInfo,
}

/// The build's scratch on one device (its sort's pairs and the centroids' box).
pub(crate) struct Lbvh {
    device: Device,
    keys: Array<u32>,
    values: Array<u32>,
    bounds: Array<u32>,
}

impl Lbvh {
    /// Empty scratch on `device`.
    pub(crate) fn new(device: &Device) -> Result<Lbvh> {
        Ok(Lbvh {
            device: device.clone(),
            keys: Array::empty(0, device)?,
            values: Array::empty(0, device)?,
            bounds: Array::empty(6, device)?,
        })
    }

    /// Builds the tree of the `n = lowers.len()` boxes into `tree` (buffers sized for `n`,
    /// checked by the caller, as are the boxes: finite, `lowers.len() == uppers.len()`), every
    /// subtree over at most `leaf_size` primitives (at least 1) made one leaf.
    pub(crate) fn build(
        &mut self,
        lowers: &Array<Vec3>,
        uppers: &Array<Vec3>,
        tree: &LbvhTree<'_>,
        leaf_size: usize,
    ) -> Result<()> {
        let n = lowers.len();
        if n == 0 {
            let empty: [i32; 8] = bytemuck::cast(BvhNode::EMPTY);
            tree.nodes
                .view(0..8)?
                .copy_from(&Array::from_slice(&empty, &self.device)?)?;
            // The root's parent and escape.
            return tree
                .parents
                .view(0..2)?
                .copy_from(&Array::from_slice(&[-1, -1], &self.device)?);
        }
        // Every element is written before it is read (keys and values by the codes' step):
        // no zeroing here.
        if self.keys.len() < n {
            self.keys = Array::empty(n, &self.device)?;
            self.values = Array::empty(n, &self.device)?;
        }
        // The empty box: min images at their largest, max images at their smallest.
        self.bounds.view(0..3)?.fill(u32::MAX)?;
        self.bounds.view(3..6)?.fill(0)?;
        let (lo, hi) = (lowers.device_address(), uppers.device_address());
        dispatch::object_step(
            &self.device,
            &LbvhBounds {
                lowers: lo,
                uppers: hi,
                bounds: self.bounds.device_address(),
                n: n as i64,
            },
        )?;
        dispatch::object_step(
            &self.device,
            &LbvhMorton {
                lowers: lo,
                uppers: hi,
                bounds: self.bounds.device_address(),
                keys: self.keys.device_address(),
                values: self.values.device_address(),
                n: n as i64,
            },
        )?;
        radix_sort_pairs(&self.keys, &self.values, n, Some(30))?;
        dispatch::object_step(
            &self.device,
            &LbvhHierarchy {
                keys: self.keys.device_address(),
                values: self.values.device_address(),
                nodes: tree.nodes.device_address(),
                parents: tree.parents.device_address(),
                prim_ids: tree.prim_ids.device_address(),
                n: n as i64,
                leaf_size: leaf_size.max(1) as i64,
            },
        )?;
        refit(lowers, uppers, tree, None, || Box::new(()))
    }
}

/// Recomputes the boxes of a linear BVH over `lowers.len()` boxes (the count it was built
/// with), keeping its shape: one step, which allocates nothing and reads nothing back, so a
/// capture records it (`uses()`: the memory its addresses point into, kept for the graph).
/// With `check`, the step checks and reports as [`RefitCheck`] says.
pub(crate) fn refit(
    lowers: &Array<Vec3>,
    uppers: &Array<Vec3>,
    tree: &LbvhTree<'_>,
    check: Option<&RefitCheck<'_>>,
    uses: impl FnOnce() -> Keep,
) -> Result<()> {
    let n = lowers.len();
    if n == 0 {
        return Ok(());
    }
    let addr = |a: Option<&Array<Vec3>>| a.map_or(0, Array::device_address);
    let step = LbvhRefit {
        lowers: lowers.device_address(),
        uppers: uppers.device_address(),
        nodes: tree.nodes.device_address(),
        parents: tree.parents.device_address(),
        prim_ids: tree.prim_ids.device_address(),
        counters: tree.counters.device_address(),
        n: n as i64,
        bad: check.map_or(0, |c| c.bad.device_address()),
        sources: check.map_or([0; 2], |c| {
            let [a, b] = c.sources.map(addr);
            [a, c.indices.map_or(b, |(ix, _)| ix.device_address())]
        }),
        // Bit 0: check the boxes; bit 1: the boxes are by leaf position; bit 2: word 1 is an
        // index position.
        check: check.map_or(0, |c| {
            c.check_boxes as i64
                | ((c.by_position as i64) << 1)
                | ((c.indices.is_some() as i64) << 2)
        }),
        num_points: check.and_then(|c| c.indices).map_or(0, |(_, n)| n as i64),
        fault: StepFault::new(check.map_or(&NO_NAMES, |c| c.names)),
    };
    dispatch::object_step_keeping(lowers.device(), &step, uses)
}

/// The names of a refit that reports nothing (never read: its `bad` is 0).
static NO_NAMES: KernelInfo = KernelInfo {
    name: "refit",
    module: "warp_lang::objects",
    ..KernelInfo::BLANK
};

/// The tree as host vectors: nodes (8 words each), links (parents, then escapes), primitive
/// ids.
pub type HostTree = (Vec<[i32; 8]>, Vec<i32>, Vec<i32>);

/// Builds a linear BVH over `lowers`/`uppers` on their device, then (when `moved` is given)
/// refits it to the moved boxes, and returns it on the host: for tests comparing the CPU's and
/// a GPU's trees bit for bit (the object types use the builder themselves).
#[doc(hidden)]
pub fn build_for_tests(
    lowers: &Array<Vec3>,
    uppers: &Array<Vec3>,
    leaf_size: usize,
    moved: Option<(&Array<Vec3>, &Array<Vec3>)>,
) -> Result<HostTree> {
    let dev = lowers.device().clone();
    let n = lowers.len();
    let nodes = Array::<i32>::zeros(8 * node_count(n), &dev)?;
    let parents = Array::<i32>::zeros(2 * node_count(n), &dev)?;
    let prim_ids = Array::<i32>::zeros(n, &dev)?;
    let counters = Array::<i32>::zeros(node_count(n), &dev)?;
    let tree = LbvhTree {
        nodes: &nodes,
        parents: &parents,
        prim_ids: &prim_ids,
        counters: &counters,
    };
    Lbvh::new(&dev)?.build(lowers, uppers, &tree, leaf_size)?;
    if let Some((lo, hi)) = moved {
        refit(lo, hi, &tree, None, || Box::new(()))?;
        // A refit leaves its counters zero for the next (the kernel resets them).
        if counters.to_vec()?.iter().any(|&c| c != 0) {
            return Err(crate::error::Error::invalid(
                "lbvh refit: a counter was left nonzero".to_string(),
            ));
        }
    }
    let words = nodes.to_vec()?;
    Ok((
        words
            .chunks(8)
            .map(|c| c.try_into().expect("8 words"))
            .collect(),
        parents.to_vec()?,
        prim_ids.to_vec()?,
    ))
}

/// Queues a check of `values` (contiguous `Vec3`s) for NaN and infinite coordinates: the
/// smallest such index lowers the `i32` at `bad` (left alone when all are finite).
pub(crate) fn check_finite(values: &Array<Vec3>, bad: u64) -> Result<()> {
    dispatch::object_step(
        values.device(),
        &LbvhFinite {
            values: values.device_address(),
            bad,
            n: values.len() as i64,
        },
    )
}

/// Queues the boxes of the `lowers.len()` triangles of `points` and `indices` (three each)
/// into `lowers` and `uppers`; the smallest position of an index outside the points lowers
/// the `i32` at `bad` (0: not recorded, for indices checked before); that triangle reads no
/// point and gets an empty box. The smallest index of a point with a NaN or infinite
/// coordinate lowers the `i32` at `bad_point` (0: not checked). With `leaf`, a built tree's
/// `prim_ids` and a mesh's leaf-ordered triangles (`3 * n` corners): the step runs over the
/// leaf positions `k`, writing the box of face `prim_ids[k]` at position `k` (for a refit with
/// [`RefitCheck::by_position`]) and its corners at `3k..3k + 3`
/// (`bvh_build::leaf_triangles`; NaN for a face with an index outside the
/// points): the gather the walks need, fused into the step that reads the vertices anyway. A capture records the step, keeping `uses()`.
pub(crate) fn triangle_boxes(
    points: &Array<Vec3>,
    indices: &Array<i32>,
    lowers: &Array<Vec3>,
    uppers: &Array<Vec3>,
    [bad, bad_point]: [u64; 2],
    leaf: Option<(&Array<i32>, &Array<Vec4>)>,
    uses: impl FnOnce() -> Keep,
) -> Result<()> {
    dispatch::object_step_keeping(
        points.device(),
        &LbvhTriangleBoxes {
            points: points.device_address(),
            indices: indices.device_address(),
            lowers: lowers.device_address(),
            uppers: uppers.device_address(),
            bad,
            n: lowers.len() as i64,
            num_points: points.len() as i64,
            bad_point,
            prim_ids: leaf.map_or(0, |l| l.0.device_address()),
            leaf_tris: leaf.map_or(0, |l| l.1.device_address()),
        },
        uses,
    )
}

/// `wp::lbvh_finite_t`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct LbvhFinite {
    values: u64,
    bad: u64,
    n: i64,
}
const _: () = assert!(std::mem::size_of::<LbvhFinite>() == 24);

/// `wp::lbvh_triangle_boxes_t`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct LbvhTriangleBoxes {
    points: u64,
    indices: u64,
    lowers: u64,
    uppers: u64,
    bad: u64,
    n: i64,
    num_points: i64,
    bad_point: u64,
    prim_ids: u64,
    leaf_tris: u64,
}
const _: () = assert!(std::mem::size_of::<LbvhTriangleBoxes>() == 80);

unsafe impl ObjectStep for LbvhFinite {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_lbvh_finite";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        // SAFETY: `n` vectors and one i32 the caller owns (an i32 is sized and aligned as an
        // AtomicI32).
        let (v, bad) = unsafe {
            (
                std::slice::from_raw_parts(self.values as *const Vec3, self.len()),
                &*(self.bad as *const std::sync::atomic::AtomicI32),
            )
        };
        if let Some(i) = v.par_iter().position_first(|p| !p.is_finite()) {
            bad.fetch_min(i as i32, std::sync::atomic::Ordering::Relaxed);
        }
        Ok(())
    }
}

unsafe impl ObjectStep for LbvhTriangleBoxes {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_lbvh_triangle_boxes";
    fn len(&self) -> usize {
        // The points' check loops over the points, in the same launch.
        match self.bad_point {
            0 => self.n as usize,
            _ => self.n.max(self.num_points) as usize,
        }
    }
    fn run_cpu(&self) -> Result<()> {
        let n = self.n as usize;
        if self.bad_point != 0 {
            // SAFETY: `num_points` points and one i32 the caller owns (sized and aligned as
            // an AtomicI32).
            let (points, bad) = unsafe {
                (
                    std::slice::from_raw_parts(
                        self.points as *const Vec3,
                        self.num_points as usize,
                    ),
                    &*(self.bad_point as *const std::sync::atomic::AtomicI32),
                )
            };
            if let Some(i) = points.par_iter().position_first(|p| !p.is_finite()) {
                bad.fetch_min(i as i32, std::sync::atomic::Ordering::Relaxed);
            }
        }
        // SAFETY: `num_points` points, `3n` indices, `n` boxes and, unless `bad` is 0, one i32
        // the caller owns (an i32 is sized and aligned as an AtomicI32).
        let (points, ix, lo, hi, bad) = unsafe {
            (
                std::slice::from_raw_parts(self.points as *const Vec3, self.num_points as usize),
                std::slice::from_raw_parts(self.indices as *const i32, 3 * n),
                std::slice::from_raw_parts_mut(self.lowers as *mut Vec3, n),
                std::slice::from_raw_parts_mut(self.uppers as *mut Vec3, n),
                (self.bad as *const std::sync::atomic::AtomicI32).as_ref(),
            )
        };
        // SAFETY: unless 0, `n` ids (a permutation of 0..n for a built tree).
        let ids = (self.leaf_tris != 0)
            .then(|| unsafe { std::slice::from_raw_parts(self.prim_ids as *const i32, n) });
        lo.par_iter_mut()
            .zip(hi.par_iter_mut())
            .enumerate()
            .for_each(|(k, (l, h))| {
                // Face order, or (with the corners' copy) leaf order: position k, face ids[k].
                let f = match ids {
                    None => k,
                    Some(ids) => match usize::try_from(ids[k]).ok().filter(|&f| f < n) {
                        Some(f) => f,
                        None => {
                            (*l, *h) = (Vec3::ZERO, Vec3::ZERO);
                            return;
                        }
                    },
                };
                let corner = |k: usize| points.get(usize::try_from(ix[3 * f + k]).ok()?).copied();
                let (Some(a), Some(b), Some(c)) = (corner(0), corner(1), corner(2)) else {
                    for k in 0..3 {
                        if let (None, Some(bad)) = (corner(k), bad) {
                            bad.fetch_min((3 * f + k) as i32, std::sync::atomic::Ordering::Relaxed);
                        }
                    }
                    (*l, *h) = (Vec3::ZERO, Vec3::ZERO);
                    return;
                };
                let min = |x: f32, y: f32, z: f32| x.min(y).min(z);
                let max = |x: f32, y: f32, z: f32| x.max(y).max(z);
                *l = Vec3::new(min(a.x, b.x, c.x), min(a.y, b.y, c.y), min(a.z, b.z, c.z));
                *h = Vec3::new(max(a.x, b.x, c.x), max(a.y, b.y, c.y), max(a.z, b.z, c.z));
            });
        if let Some(ids) = ids {
            // SAFETY: `3n` corners the caller owns.
            let out = unsafe { std::slice::from_raw_parts_mut(self.leaf_tris as *mut Vec4, 3 * n) };
            bvh_build::write_leaf_triangles_par(out, ids, ix, points);
        }
        Ok(())
    }
}

/// `wp::lbvh_bounds_t`: the centroids' box into `bounds` (6 order-preserving images).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct LbvhBounds {
    lowers: u64,
    uppers: u64,
    bounds: u64,
    n: i64,
}
const _: () = assert!(std::mem::size_of::<LbvhBounds>() == 32);

/// `wp::lbvh_morton_t`: codes and indices.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct LbvhMorton {
    lowers: u64,
    uppers: u64,
    bounds: u64,
    keys: u64,
    values: u64,
    n: i64,
}
const _: () = assert!(std::mem::size_of::<LbvhMorton>() == 48);

/// `wp::lbvh_hierarchy_t`: the tree's shape from the sorted codes.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct LbvhHierarchy {
    keys: u64,
    values: u64,
    nodes: u64,
    parents: u64,
    prim_ids: u64,
    n: i64,
    leaf_size: i64,
}
const _: () = assert!(std::mem::size_of::<LbvhHierarchy>() == 56);

/// `wp::lbvh_refit_t`: the boxes, bottom-up, checked and reported as [`RefitCheck`] says.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct LbvhRefit {
    lowers: u64,
    uppers: u64,
    nodes: u64,
    parents: u64,
    prim_ids: u64,
    counters: u64,
    n: i64,
    bad: u64,
    sources: [u64; 2],
    check: i64,
    num_points: i64,
    fault: StepFault,
}
const _: () = assert!(std::mem::size_of::<LbvhRefit>() == 136);

/// The order-preserving `u32` image of an `f32` (`wp::lbvh_ordered`).
fn ordered(x: f32) -> u32 {
    let u = x.to_bits();
    if u & 0x8000_0000 != 0 {
        !u
    } else {
        u | 0x8000_0000
    }
}

/// The inverse of [`ordered`] (`wp::lbvh_unordered`).
fn unordered(u: u32) -> f32 {
    f32::from_bits(if u & 0x8000_0000 != 0 {
        u & 0x7fff_ffff
    } else {
        !u
    })
}

/// A centroid coordinate (`wp::lbvh_centre`).
fn centre(lo: f32, hi: f32) -> f32 {
    0.5 * (lo + hi)
}

/// 10 bits of `x` in `[lo, hi]` (`wp::lbvh_quantize`).
fn quantize(x: f32, lo: f32, hi: f32) -> u32 {
    // NaN-aware: an empty (or NaN) extent and a NaN or non-positive position give 0.
    let ext = hi - lo;
    if ext.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return 0;
    }
    let t = (x - lo) / ext * 1024.0;
    if t.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        0
    } else if t >= 1023.0 {
        1023
    } else {
        t as u32
    }
}

/// The 10 bits of `v` spread to every third bit (`wp::lbvh_spread`).
fn spread(mut v: u32) -> u32 {
    v = (v | (v << 16)) & 0x0300_00FF;
    v = (v | (v << 8)) & 0x0300_F00F;
    v = (v | (v << 4)) & 0x030C_30C3;
    v = (v | (v << 2)) & 0x0924_9249;
    v
}

/// The Morton code of a box's centroid in the centroids' box `b` (`wp::lbvh_code`).
fn code(lo: Vec3, hi: Vec3, b: &[u32; 6]) -> u32 {
    let c = [centre(lo.x, hi.x), centre(lo.y, hi.y), centre(lo.z, hi.z)];
    (0..3).fold(0, |code, a| {
        let q = quantize(c[a], unordered(b[a]), unordered(b[3 + a]));
        code | (spread(q) << (2 - a))
    })
}

/// The common prefix of the (code, index) keys of sorted positions `i` and `j`, or -1 when
/// `j` is outside `0..n` (`wp::lbvh_delta`).
fn delta(keys: &[u32], i: i64, j: i64) -> i32 {
    if j < 0 || j >= keys.len() as i64 {
        return -1;
    }
    let a = ((keys[i as usize] as u64) << 32) | i as u64;
    let b = ((keys[j as usize] as u64) << 32) | j as u64;
    (a ^ b).leading_zeros() as i32
}

/// The escape of a node whose range of sorted positions ends at `last` (`wp::lbvh_escape`):
/// the node a left-first traversal visits after it, which starts at position `last + 1` and is
/// the right child of the internal node that splits after `last`. That child is internal node
/// `last + 1` when that node's range starts there (Karras's direction +1: a right child is
/// numbered by its first position, a left child by its last), else the leaf of `last + 1`.
/// -1 after the last position. Two prefix lengths, no search: each step writes its nodes'.
fn escape(keys: &[u32], last: i64) -> i32 {
    let n = keys.len() as i64;
    let j = last + 1;
    if j >= n {
        -1
    } else if j <= n - 2 && delta(keys, j, j + 1) > delta(keys, j, j - 1) {
        j as i32
    } else {
        (n - 1 + j) as i32
    }
}

/// Internal node `i`'s range `[first, last]` and split (`wp::lbvh_internal`).
fn internal(keys: &[u32], i: i64) -> (i64, i64, i64) {
    let d: i64 = if delta(keys, i, i + 1) > delta(keys, i, i - 1) {
        1
    } else {
        -1
    };
    let dmin = delta(keys, i, i - d);
    let mut lmax = 2;
    while delta(keys, i, i + lmax * d) > dmin {
        lmax *= 2;
    }
    let mut l = 0;
    let mut t = lmax / 2;
    while t >= 1 {
        if delta(keys, i, i + (l + t) * d) > dmin {
            l += t;
        }
        t /= 2;
    }
    let j = i + l * d;
    let dnode = delta(keys, i, j);
    let mut s = 0;
    let mut t = (l + 1) / 2;
    loop {
        if delta(keys, i, i + (s + t) * d) > dnode {
            s += t;
        }
        if t == 1 {
            break;
        }
        t = (t + 1) / 2;
    }
    let split = i + s * d + if d < 0 { -1 } else { 0 };
    (i.min(j), i.max(j), split)
}

/// A pointer rayon tasks share, for writes no two tasks share.
#[derive(Clone, Copy)]
struct Shared<T>(*mut T);
// SAFETY: see each use: disjoint writes only.
unsafe impl<T> Send for Shared<T> {}
unsafe impl<T> Sync for Shared<T> {}
impl<T> Shared<T> {
    fn at(self, i: usize) -> *mut T {
        self.0.wrapping_add(i)
    }
}

// SAFETY (all four steps): `#[repr(C)]` records laid out as the C++ structs of
// `wp_bvh_build.h` (both sides assert the sizes); `Lbvh` passes its own scratch and the
// caller's tree, sized for `n` (see `LbvhTree`).
unsafe impl ObjectStep for LbvhBounds {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_lbvh_bounds";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        // SAFETY: `n` boxes; the 6 bound words are the build's own.
        let (lo, hi, b) = unsafe {
            (
                std::slice::from_raw_parts(self.lowers as *const Vec3, n),
                std::slice::from_raw_parts(self.uppers as *const Vec3, n),
                &mut *(self.bounds as *mut [u32; 6]),
            )
        };
        let found = (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .fold(
                || *b,
                |mut acc, i| {
                    let c = [
                        centre(lo[i].x, hi[i].x),
                        centre(lo[i].y, hi[i].y),
                        centre(lo[i].z, hi[i].z),
                    ];
                    for a in 0..3 {
                        let u = ordered(c[a]);
                        acc[a] = acc[a].min(u);
                        acc[3 + a] = acc[3 + a].max(u);
                    }
                    acc
                },
            )
            .reduce(
                || *b,
                |x, y| {
                    std::array::from_fn(|k| {
                        if k < 3 {
                            x[k].min(y[k])
                        } else {
                            x[k].max(y[k])
                        }
                    })
                },
            );
        *b = found;
        Ok(())
    }
}

unsafe impl ObjectStep for LbvhMorton {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_lbvh_morton";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        // SAFETY: `n` boxes, `n` keys and values (distinct scratch arrays), 6 bound words.
        let (lo, hi, b, keys, values) = unsafe {
            (
                std::slice::from_raw_parts(self.lowers as *const Vec3, n),
                std::slice::from_raw_parts(self.uppers as *const Vec3, n),
                *(self.bounds as *const [u32; 6]),
                std::slice::from_raw_parts_mut(self.keys as *mut u32, n),
                std::slice::from_raw_parts_mut(self.values as *mut u32, n),
            )
        };
        keys.par_iter_mut()
            .zip(values.par_iter_mut())
            .enumerate()
            .with_min_len(4096)
            .for_each(|(i, (k, v))| {
                *k = code(lo[i], hi[i], &b);
                *v = i as u32;
            });
        Ok(())
    }
}

unsafe impl ObjectStep for LbvhHierarchy {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_lbvh_hierarchy";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        // SAFETY: `n` sorted keys and values; `node_count(n)` nodes, twice as many links, `n`
        // ids.
        let (keys, values) = unsafe {
            (
                std::slice::from_raw_parts(self.keys as *const u32, n),
                std::slice::from_raw_parts(self.values as *const u32, n),
            )
        };
        let nodes = Shared(self.nodes as *mut BvhNode);
        let parents = Shared(self.parents as *mut i32);
        let ids = Shared(self.prim_ids as *mut i32);
        let n64 = n as i64;
        let escapes_at = node_count(n);
        (0..n).into_par_iter().with_min_len(1024).for_each(|k| {
            let (nodes, parents, ids) = (nodes, parents, ids);
            let leaf = n - 1 + k;
            // SAFETY: step k writes leaf n - 1 + k, id k, internal node k, the parent links of
            // internal node k's two children and the escapes of internal node k and leaf
            // n - 1 + k: every node has one parent, so no two steps write one element (and
            // parents[0], the root's, only step 0).
            unsafe {
                let l = &mut *nodes.at(leaf);
                l.left = !(k as i32);
                l.right = k as i32 + 1;
                ids.at(k).write(values[k] as i32);
                parents.at(escapes_at + leaf).write(escape(keys, k as i64));
                if k == 0 {
                    parents.at(0).write(-1);
                }
                if k + 1 < n {
                    let (first, last, split) = internal(keys, k as i64);
                    parents.at(escapes_at + k).write(escape(keys, last));
                    let left = if split == first {
                        n64 - 1 + split
                    } else {
                        split
                    };
                    let right = if split + 1 == last {
                        n64 - 1 + split + 1
                    } else {
                        split + 1
                    };
                    let node = &mut *nodes.at(k);
                    if last - first < self.leaf_size {
                        // A subtree over at most leaf_size primitives: one leaf.
                        node.left = !(first as i32);
                        node.right = last as i32 + 1;
                    } else {
                        node.left = left as i32;
                        node.right = right as i32;
                    }
                    parents.at(left as usize).write(k as i32);
                    parents.at(right as usize).write(k as i32);
                }
            }
        });
        Ok(())
    }
}

unsafe impl ObjectStep for LbvhRefit {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_lbvh_refit";
    fn len(&self) -> usize {
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        let count = node_count(n);
        // SAFETY: `count` nodes, twice as many links, `n` ids and boxes, all the caller's; the counters
        // are not needed on the CPU (`bvh_build::refit` keeps its own).
        let (nodes, parents, ids, lo, hi) = unsafe {
            (
                std::slice::from_raw_parts_mut(self.nodes as *mut BvhNode, count),
                std::slice::from_raw_parts(self.parents as *const i32, 2 * count),
                std::slice::from_raw_parts(self.prim_ids as *const i32, n),
                std::slice::from_raw_parts(self.lowers as *const Vec3, n),
                std::slice::from_raw_parts(self.uppers as *const Vec3, n),
            )
        };
        // SAFETY: unless `bad` is 0, two i32 words the caller owns (each sized and aligned as
        // an AtomicI32).
        let bad = (self.bad != 0)
            .then(|| unsafe { &*(self.bad as *const [std::sync::atomic::AtomicI32; 2]) });
        if let (Some(bad), 1) = (bad, self.check & 1) {
            for (word, boxes) in bad.iter().zip([lo, hi]) {
                if let Some(i) = boxes.par_iter().position_first(|p| !p.is_finite()) {
                    word.fetch_min(i as i32, std::sync::atomic::Ordering::Relaxed);
                }
            }
        }
        // The kernel's climb from every primitive's leaf (a leaf over several primitives is
        // one the hierarchy made from an internal node: reached by climbing), with the same
        // unions (min/max: exact and order-free), in any order.
        let first_leaf = n - 1;
        if self.check & 2 != 0 {
            // Boxes by leaf position: position k's box is box k.
            let at: Vec<i32> = (0..n as i32).collect();
            bvh_build::refit_from(nodes, parents, &at, lo, hi, first_leaf..first_leaf + n);
        } else {
            bvh_build::refit_from(nodes, parents, ids, lo, hi, first_leaf..first_leaf + n);
        }
        // The kernel's report: both words reset, the first one set is the fault.
        let Some(bad) = bad else {
            return Ok(());
        };
        let found = bad
            .iter()
            .map(|w| w.swap(i32::MAX, std::sync::atomic::Ordering::Relaxed))
            .collect::<Vec<_>>();
        for (arg, (&i, &source)) in found.iter().zip(&self.sources).enumerate() {
            if i == i32::MAX || source == 0 {
                continue;
            }
            let names = self.fault.names;
            let arg_name = names.params.get(arg).copied().unwrap_or("?");
            if arg == 1 && self.check & 4 != 0 {
                // A mesh's index outside its points, at position `i` of the indices.
                // SAFETY: the source is the `3n` indices, where the boxes' step found it.
                let v = unsafe { *(source as *const i32).add(i as usize) };
                return Err(Fault {
                    kernel: names.name,
                    kind: FaultKind::OutOfBounds {
                        arg: arg_name,
                        index: vec![i128::from(i), i128::from(v)],
                        shape: vec![3 * n, self.num_points as usize],
                    },
                    launch: None,
                }
                .into());
            }
            // SAFETY: the source holds the element the word indexes (the check found it
            // there).
            let v = unsafe { *(source as *const Vec3).add(i as usize) };
            return Err(Fault {
                kernel: names.name,
                kind: FaultKind::NonFiniteInput {
                    arg: arg_name,
                    index: i as usize,
                    values: v.to_array().map(f64::from).to_vec(),
                },
                launch: None,
            }
            .into());
        }
        Ok(())
    }
    fn fault_slot(&mut self) -> Option<&mut StepFault> {
        (self.bad != 0).then_some(&mut self.fault)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boxes(n: usize, seed: u64, dup: bool) -> (Vec<Vec3>, Vec<Vec3>) {
        let mut s = seed;
        let mut r = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut lo = Vec::new();
        let mut hi = Vec::new();
        for i in 0..n {
            let c = if dup && i % 3 == 0 && i > 0 {
                lo[i - 1] + Vec3::splat(0.01)
            } else {
                Vec3::new(r(), r(), r()) * 20.0 - 10.0
            };
            let e = Vec3::new(r(), r(), r()) * 0.1;
            lo.push(c - e);
            hi.push(c + e);
        }
        (lo, hi)
    }

    fn build_on_cpu(lo: &[Vec3], hi: &[Vec3], leaf: usize) -> (Vec<BvhNode>, Vec<i32>, Vec<i32>) {
        let dev = crate::device::get_device("cpu").unwrap();
        let n = lo.len();
        let nodes = Array::<i32>::zeros(8 * node_count(n), &dev).unwrap();
        let parents = Array::<i32>::zeros(2 * node_count(n), &dev).unwrap();
        let ids = Array::<i32>::zeros(n, &dev).unwrap();
        let counters = Array::<i32>::zeros(node_count(n), &dev).unwrap();
        let mut b = Lbvh::new(&dev).unwrap();
        let (l, h) = (
            Array::from_slice(lo, &dev).unwrap(),
            Array::from_slice(hi, &dev).unwrap(),
        );
        let tree = LbvhTree {
            nodes: &nodes,
            parents: &parents,
            prim_ids: &ids,
            counters: &counters,
        };
        b.build(&l, &h, &tree, leaf).unwrap();
        let words = nodes.to_vec().unwrap();
        (
            bytemuck::cast_slice(&words).to_vec(),
            parents.to_vec().unwrap(),
            ids.to_vec().unwrap(),
        )
    }

    #[test]
    fn the_tree_is_in_the_layout_for_every_size() {
        for (n, dup) in [
            (0, false),
            (1, false),
            (2, false),
            (3, true),
            (17, true),
            (1000, false),
            (5000, true),
        ] {
            let (lo, hi) = boxes(n, 0x1234_5678 + n as u64, dup);
            for leaf in [BVH_LEAF_SIZE, 2, MESH_LEAF_SIZE] {
                let (nodes, parents, ids) = build_on_cpu(&lo, &hi, leaf);
                let depth = bvh_build::check_layout(&nodes, &parents, &ids, &lo, &hi)
                    .unwrap_or_else(|e| panic!("n = {n}, leaf {leaf}: {e}"));
                // A Morton tree of random boxes is shallow (about 2 log2 n at most here).
                assert!(
                    depth <= 2 * (usize::BITS - n.leading_zeros()) as usize + 2,
                    "n = {n}: depth {depth}"
                );
                // Every reached leaf holds at most `leaf` primitives, and an internal node
                // more (else it would have been made a leaf).
                let mut work = vec![0usize];
                while let Some(i) = work.pop() {
                    let node = nodes[i];
                    let count = |i: usize| -> usize {
                        let mut stack = vec![i];
                        let mut c = 0;
                        while let Some(j) = stack.pop() {
                            let m = nodes[j];
                            if m.is_leaf() {
                                let (s, e) = m.leaf_range();
                                c += (e - s) as usize;
                            } else {
                                stack.extend([m.left as usize, m.right as usize]);
                            }
                        }
                        c
                    };
                    if node.is_leaf() {
                        assert!(count(i) <= leaf.max(1), "n = {n}, leaf {leaf}: node {i}");
                    } else {
                        assert!(count(i) > leaf, "n = {n}, leaf {leaf}: node {i}");
                        work.extend([node.left as usize, node.right as usize]);
                    }
                }
            }
        }
    }

    #[test]
    fn equal_codes_still_make_a_binary_tree() {
        // Every box the same: every code equal; the index breaks the ties.
        let lo = vec![Vec3::ONE; 64];
        let hi = vec![Vec3::splat(2.0); 64];
        for leaf in [BVH_LEAF_SIZE, MESH_LEAF_SIZE] {
            let (nodes, parents, ids) = build_on_cpu(&lo, &hi, leaf);
            bvh_build::check_layout(&nodes, &parents, &ids, &lo, &hi).unwrap();
        }
    }

    /// A mesh's refit as the runtime queues it: the triangle boxes' step in leaf order (boxes
    /// by position, the corners' copy) and a refit reading the boxes by position gives the
    /// same nodes, bit for bit, as boxes by face and a refit by primitive (the same unions of
    /// the same boxes), and the copy is `bvh_build::leaf_triangles`. On the CPU, and on
    /// `cuda:0` when there is one (the kernels).
    #[test]
    fn a_mesh_refit_in_leaf_order_gives_the_same_tree() {
        static MESH_NAMES: KernelInfo = KernelInfo {
            name: "Mesh::refit",
            params: &["points"],
            ..KernelInfo::BLANK
        };
        let mut devices = vec![crate::device::get_device("cpu").unwrap()];
        devices.extend(crate::device::get_device("cuda:0").ok());
        for dev in devices {
            let (pl, _) = boxes(200, 5, false);
            let faces = 300;
            let ix: Vec<i32> = (0..3 * faces)
                .map(|i| ((i * 37 + i / 3) % 200) as i32)
                .collect();
            let moved: Vec<Vec3> = pl.iter().map(|p| *p * 0.75 + Vec3::X).collect();
            let a = |v: &[Vec3]| Array::from_slice(v, &dev).unwrap();
            let (points, points2) = (a(&pl), a(&moved));
            let indices = Array::from_slice(&ix, &dev).unwrap();
            let n = faces;
            let (lo, hi) = (a(&vec![Vec3::ZERO; n]), a(&vec![Vec3::ZERO; n]));
            let nodes = Array::<i32>::zeros(8 * node_count(n), &dev).unwrap();
            let parents = Array::<i32>::zeros(2 * node_count(n), &dev).unwrap();
            let ids = Array::<i32>::zeros(n, &dev).unwrap();
            let counters = Array::<i32>::zeros(node_count(n), &dev).unwrap();
            let tree = LbvhTree {
                nodes: &nodes,
                parents: &parents,
                prim_ids: &ids,
                counters: &counters,
            };
            triangle_boxes(&points, &indices, &lo, &hi, [0, 0], None, || Box::new(())).unwrap();
            Lbvh::new(&dev)
                .unwrap()
                .build(&lo, &hi, &tree, MESH_LEAF_SIZE)
                .unwrap();
            // By face, by primitive: the reference.
            triangle_boxes(&points2, &indices, &lo, &hi, [0, 0], None, || Box::new(())).unwrap();
            refit(&lo, &hi, &tree, None, || Box::new(())).unwrap();
            let want = nodes.to_vec().unwrap();
            // Scramble the boxes, then the runtime's way.
            triangle_boxes(&points, &indices, &lo, &hi, [0, 0], None, || Box::new(())).unwrap();
            refit(&lo, &hi, &tree, None, || Box::new(())).unwrap();
            assert_ne!(nodes.to_vec().unwrap(), want);
            let tris = Array::<glam::Vec4>::zeros(3 * n, &dev).unwrap();
            let bad = Array::from_slice(&[i32::MAX; 2], &dev).unwrap();
            let check = RefitCheck {
                bad: &bad,
                sources: [Some(&points2), None],
                check_boxes: false,
                by_position: true,
                indices: None,
                names: &MESH_NAMES,
            };
            triangle_boxes(
                &points2,
                &indices,
                &lo,
                &hi,
                [0, bad.device_address()],
                Some((&ids, &tris)),
                || Box::new(()),
            )
            .unwrap();
            refit(&lo, &hi, &tree, Some(&check), || Box::new(())).unwrap();
            assert_eq!(nodes.to_vec().unwrap(), want, "{}", dev.alias());
            let host_ids = ids.to_vec().unwrap();
            assert_eq!(
                tris.to_vec().unwrap(),
                bvh_build::leaf_triangles(&host_ids, &ix, &moved),
                "{}",
                dev.alias()
            );
            assert_eq!(bad.to_vec().unwrap(), vec![i32::MAX; 2]);
        }
    }

    /// A mesh's index written outside its points after the build: the triangle boxes' step
    /// lowers word 1 to its smallest position, and the refit reports it as `OutOfBounds` on
    /// `indices` with index `[position, value]` and shape `[3 * faces, points]` (what the
    /// CPU's `Mesh::refit` error names), a non-finite point first (as the CPU checks the
    /// points first); the bad face gets an empty box and NaN corners, the words are reset,
    /// and a refit from valid indices again gives the reference tree. On the CPU (the step
    /// returns the fault) and on `cuda:0` when there is one (the fault reaches the next
    /// synchronisation).
    #[test]
    fn a_mesh_refit_reports_an_index_outside_the_points() {
        static MESH_NAMES: KernelInfo = KernelInfo {
            name: "Mesh::refit",
            params: &["points", "indices"],
            ..KernelInfo::BLANK
        };
        let mut devices = vec![crate::device::get_device("cpu").unwrap()];
        devices.extend(crate::device::get_device("cuda:0").ok());
        for dev in devices {
            let (pl, _) = boxes(200, 11, false);
            let faces = 300;
            let ix: Vec<i32> = (0..3 * faces)
                .map(|i| ((i * 37 + i / 3) % 200) as i32)
                .collect();
            let a = |v: &[Vec3]| Array::from_slice(v, &dev).unwrap();
            let points = a(&pl);
            let indices = Array::from_slice(&ix, &dev).unwrap();
            let n = faces;
            let (lo, hi) = (a(&vec![Vec3::ZERO; n]), a(&vec![Vec3::ZERO; n]));
            let nodes = Array::<i32>::zeros(8 * node_count(n), &dev).unwrap();
            let parents = Array::<i32>::zeros(2 * node_count(n), &dev).unwrap();
            let ids = Array::<i32>::zeros(n, &dev).unwrap();
            let counters = Array::<i32>::zeros(node_count(n), &dev).unwrap();
            let tree = LbvhTree {
                nodes: &nodes,
                parents: &parents,
                prim_ids: &ids,
                counters: &counters,
            };
            triangle_boxes(&points, &indices, &lo, &hi, [0, 0], None, || Box::new(())).unwrap();
            Lbvh::new(&dev)
                .unwrap()
                .build(&lo, &hi, &tree, MESH_LEAF_SIZE)
                .unwrap();
            let tris = Array::<glam::Vec4>::zeros(3 * n, &dev).unwrap();
            let bad = Array::from_slice(&[i32::MAX; 2], &dev).unwrap();
            let check = RefitCheck {
                bad: &bad,
                sources: [Some(&points), None],
                check_boxes: false,
                by_position: true,
                indices: Some((&indices, pl.len())),
                names: &MESH_NAMES,
            };
            // The runtime's refit: the leaf-order boxes' step into both words, then the refit.
            let mesh_refit = || -> Result<()> {
                let word = bad.device_address();
                triangle_boxes(
                    &points,
                    &indices,
                    &lo,
                    &hi,
                    [word + 4, word],
                    Some((&ids, &tris)),
                    || Box::new(()),
                )?;
                refit(&lo, &hi, &tree, Some(&check), || Box::new(()))
            };
            mesh_refit().unwrap();
            crate::synchronize().unwrap();
            let want = nodes.to_vec().unwrap();
            let fault = |r: Result<()>| -> Fault {
                let r = if dev.is_cpu() {
                    r
                } else {
                    r.unwrap();
                    crate::synchronize()
                };
                match r {
                    Err(crate::error::Error::Fault(f)) => {
                        assert_eq!(bad.to_vec().unwrap(), vec![i32::MAX; 2], "the words reset");
                        f
                    }
                    r => panic!("{}: {r:?}", dev.alias()),
                }
            };
            let set_index = |k: usize, v: i32| {
                indices
                    .view(k..k + 1)
                    .unwrap()
                    .copy_from(&Array::from_slice(&[v], &dev).unwrap())
                    .unwrap();
            };
            // Two bad indices (one past the end, one negative): the smaller position is named.
            set_index(700, -1);
            set_index(301, 200);
            let f = fault(mesh_refit());
            assert_eq!(f.kernel, "Mesh::refit", "{}", dev.alias());
            assert_eq!(
                f.kind,
                FaultKind::OutOfBounds {
                    arg: "indices",
                    index: vec![301, 200],
                    shape: vec![900, 200],
                },
                "{}",
                dev.alias()
            );
            // Face 100 (position 301's) read no point: an empty box at its leaf position and
            // NaN corners in the walks' copy; every other face as the reference has it.
            let host_ids = ids.to_vec().unwrap();
            let k = host_ids.iter().position(|&f| f == 100).unwrap();
            assert_eq!(lo.to_vec().unwrap()[k], Vec3::ZERO);
            assert_eq!(hi.to_vec().unwrap()[k], Vec3::ZERO);
            let corners = tris.to_vec().unwrap();
            assert!(corners[3 * k..3 * k + 3]
                .iter()
                .all(|c| c.x.is_nan() && c.y.is_nan() && c.z.is_nan()));
            // A non-finite point as well: the points are reported first, as on the CPU.
            let nan = Vec3::new(f32::NAN, 0.0, 1.0);
            points.view(5..6).unwrap().copy_from(&a(&[nan])).unwrap();
            let f = fault(mesh_refit());
            assert!(
                matches!(
                    f.kind,
                    FaultKind::NonFiniteInput {
                        arg: "points",
                        index: 5,
                        ..
                    }
                ),
                "{}: {f:?}",
                dev.alias()
            );
            // Valid again: the refit is clean and gives the reference tree and copy.
            points.view(5..6).unwrap().copy_from(&a(&[pl[5]])).unwrap();
            set_index(301, ix[301]);
            set_index(700, ix[700]);
            mesh_refit().unwrap();
            crate::synchronize().unwrap();
            assert_eq!(nodes.to_vec().unwrap(), want, "{}", dev.alias());
            assert_eq!(
                tris.to_vec().unwrap(),
                bvh_build::leaf_triangles(&host_ids, &ix, &pl),
                "{}",
                dev.alias()
            );
        }
    }

    /// The refit's check on the CPU mirrors the kernel's: the smallest bad index, lowers
    /// before uppers, the words reset for the next refit; a mesh's points checked by its
    /// triangle boxes' step and reported by the refit.
    #[test]
    fn a_refit_reports_the_first_non_finite_input() {
        static NAMES: KernelInfo = KernelInfo {
            name: "Bvh::refit",
            params: &["lowers", "uppers"],
            ..KernelInfo::BLANK
        };
        let dev = crate::device::get_device("cpu").unwrap();
        let (lo, hi) = boxes(300, 99, true);
        let n = lo.len();
        let a = |v: &[Vec3]| Array::from_slice(v, &dev).unwrap();
        let (l, h) = (a(&lo), a(&hi));
        let nodes = Array::<i32>::zeros(8 * node_count(n), &dev).unwrap();
        let parents = Array::<i32>::zeros(2 * node_count(n), &dev).unwrap();
        let ids = Array::<i32>::zeros(n, &dev).unwrap();
        let counters = Array::<i32>::zeros(node_count(n), &dev).unwrap();
        let tree = LbvhTree {
            nodes: &nodes,
            parents: &parents,
            prim_ids: &ids,
            counters: &counters,
        };
        Lbvh::new(&dev).unwrap().build(&l, &h, &tree, 1).unwrap();
        let bad = Array::from_slice(&[i32::MAX; 2], &dev).unwrap();
        let check = RefitCheck {
            bad: &bad,
            sources: [Some(&l), Some(&h)],
            check_boxes: true,
            by_position: false,
            indices: None,
            names: &NAMES,
        };
        let refit_err = || match refit(&l, &h, &tree, Some(&check), || Box::new(())) {
            Err(crate::error::Error::Fault(f)) => {
                assert_eq!(bad.to_vec().unwrap(), vec![i32::MAX; 2], "the words reset");
                match f.kind {
                    FaultKind::NonFiniteInput { arg, index, values } => (arg, index, values),
                    k => panic!("{k:?}"),
                }
            }
            r => panic!("{r:?}"),
        };
        refit(&l, &h, &tree, Some(&check), || Box::new(())).unwrap();
        let set = |arr: &Array<Vec3>, i: usize, v: Vec3| {
            arr.view(i..i + 1).unwrap().copy_from(&a(&[v])).unwrap();
        };
        let nan = Vec3::new(1.0, f32::NAN, 2.0);
        set(&h, 40, nan);
        set(&h, 7, Vec3::INFINITY);
        let (arg, index, values) = refit_err();
        assert_eq!((arg, index), ("uppers", 7));
        assert!(values.iter().all(|v| *v == f64::INFINITY));
        // A bad lower corner comes first, whatever its index.
        set(&l, 250, nan);
        let (arg, index, values) = refit_err();
        assert_eq!((arg, index), ("lowers", 250));
        assert!(values[0] == 1.0 && values[1].is_nan() && values[2] == 2.0);
        // Finite again: the refit passes (the words were reset) and gives the tree a build
        // over the same boxes gives.
        set(&l, 250, lo[250]);
        set(&h, 40, hi[40]);
        set(&h, 7, hi[7]);
        refit(&l, &h, &tree, Some(&check), || Box::new(())).unwrap();
        let words = nodes.to_vec().unwrap();
        let (built, _, _) = build_on_cpu(&lo, &hi, 1);
        assert_eq!(bytemuck::cast_slice::<i32, BvhNode>(&words), &built[..]);
        // A mesh's points: checked by the triangle boxes' step into the word the refit
        // reports (argument 0, the points).
        let points = a(&[Vec3::ZERO, Vec3::X, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::Y]);
        let indices = Array::from_slice(&[0, 1, 3], &dev).unwrap();
        let (tl, th) = (a(&[Vec3::ZERO]), a(&[Vec3::ZERO]));
        triangle_boxes(
            &points,
            &indices,
            &tl,
            &th,
            [0, bad.device_address()],
            None,
            || Box::new(()),
        )
        .unwrap();
        assert_eq!(bad.to_vec().unwrap(), vec![2, i32::MAX]);
        assert_eq!(
            (tl.to_vec().unwrap(), th.to_vec().unwrap()),
            (vec![Vec3::ZERO], vec![Vec3::ONE.with_z(0.0)])
        );
    }

    #[test]
    fn codes_and_images() {
        for x in [0.0f32, -0.0, 1.0, -1.0, 1e-30, -1e30, f32::MAX, f32::MIN] {
            assert_eq!(unordered(ordered(x)).to_bits(), x.to_bits());
        }
        assert!(ordered(-1.0) < ordered(-0.5) && ordered(-0.5) < ordered(0.25));
        assert_eq!(spread(0x3ff), 0x0924_9249);
        assert_eq!(quantize(5.0, 0.0, 10.0), 512);
        assert_eq!(quantize(10.0, 0.0, 10.0), 1023);
        assert_eq!(quantize(-1.0, 0.0, 10.0), 0);
        assert_eq!(quantize(3.0, 3.0, 3.0), 0);
    }
}

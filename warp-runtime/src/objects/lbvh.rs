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
use crate::backend::{ObjectLibrary, ObjectStep};
use crate::device::Device;
use crate::dispatch;
use crate::error::Result;
use crate::primitives::radix_sort_pairs;
use glam::Vec3;
use rayon::prelude::*;
use warp_core::objects::bvh::BvhNode;

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
/// (as 8 words each) and parents, `n` primitive ids.
pub(crate) struct LbvhTree<'a> {
    pub nodes: &'a Array<i32>,
    pub parents: &'a Array<i32>,
    pub prim_ids: &'a Array<i32>,
}

/// The build's scratch on one device, kept between builds (grown when needed).
pub(crate) struct Lbvh {
    device: Device,
    keys: Array<u32>,
    values: Array<u32>,
    counters: Array<i32>,
    bounds: Array<u32>,
}

impl Lbvh {
    /// Empty scratch on `device`.
    pub(crate) fn new(device: &Device) -> Result<Lbvh> {
        Ok(Lbvh {
            device: device.clone(),
            keys: Array::empty(0, device)?,
            values: Array::empty(0, device)?,
            counters: Array::empty(0, device)?,
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
            return tree
                .parents
                .view(0..1)?
                .copy_from(&Array::from_slice(&[-1], &self.device)?);
        }
        // Every element is written before it is read (keys and values by the codes' step,
        // counters zeroed by the refit): no zeroing here.
        if self.keys.len() < n {
            self.keys = Array::empty(n, &self.device)?;
            self.values = Array::empty(n, &self.device)?;
            self.counters = Array::empty(n, &self.device)?;
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
        self.refit(lowers, uppers, tree)
    }

    /// Recomputes the boxes of a tree this builder made over `lowers.len()` boxes (the same
    /// count), keeping its shape.
    pub(crate) fn refit(
        &mut self,
        lowers: &Array<Vec3>,
        uppers: &Array<Vec3>,
        tree: &LbvhTree<'_>,
    ) -> Result<()> {
        let n = lowers.len();
        if n == 0 {
            return Ok(());
        }
        if self.counters.len() < n {
            self.counters = Array::empty(n, &self.device)?;
        }
        self.counters.view(0..n)?.fill(0)?;
        dispatch::object_step(
            &self.device,
            &LbvhRefit {
                lowers: lowers.device_address(),
                uppers: uppers.device_address(),
                nodes: tree.nodes.device_address(),
                parents: tree.parents.device_address(),
                prim_ids: tree.prim_ids.device_address(),
                counters: self.counters.device_address(),
                n: n as i64,
            },
        )
    }
}

/// The tree as host vectors: nodes (8 words each), parents, primitive ids.
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
    let parents = Array::<i32>::zeros(node_count(n), &dev)?;
    let prim_ids = Array::<i32>::zeros(n, &dev)?;
    let tree = LbvhTree {
        nodes: &nodes,
        parents: &parents,
        prim_ids: &prim_ids,
    };
    let mut b = Lbvh::new(&dev)?;
    b.build(lowers, uppers, &tree, leaf_size)?;
    if let Some((lo, hi)) = moved {
        b.refit(lo, hi, &tree)?;
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
/// point and gets an empty box.
pub(crate) fn triangle_boxes(
    points: &Array<Vec3>,
    indices: &Array<i32>,
    lowers: &Array<Vec3>,
    uppers: &Array<Vec3>,
    bad: u64,
) -> Result<()> {
    dispatch::object_step(
        points.device(),
        &LbvhTriangleBoxes {
            points: points.device_address(),
            indices: indices.device_address(),
            lowers: lowers.device_address(),
            uppers: uppers.device_address(),
            bad,
            n: lowers.len() as i64,
            num_points: points.len() as i64,
        },
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
}
const _: () = assert!(std::mem::size_of::<LbvhTriangleBoxes>() == 56);

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
        self.n as usize
    }
    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
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
        lo.par_iter_mut()
            .zip(hi.par_iter_mut())
            .enumerate()
            .for_each(|(f, (l, h))| {
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

/// `wp::lbvh_refit_t`: the boxes, bottom-up.
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
}
const _: () = assert!(std::mem::size_of::<LbvhRefit>() == 56);

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
        // SAFETY: `n` sorted keys and values; `node_count(n)` nodes and parents, `n` ids.
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
        (0..n).into_par_iter().with_min_len(1024).for_each(|k| {
            let (nodes, parents, ids) = (nodes, parents, ids);
            let leaf = n - 1 + k;
            // SAFETY: step k writes leaf n - 1 + k, id k, internal node k and the parent
            // links of internal node k's two children: every node has one parent, so no two
            // steps write one element (and parents[0], the root's, only step 0).
            unsafe {
                let l = &mut *nodes.at(leaf);
                l.left = !(k as i32);
                l.right = k as i32 + 1;
                ids.at(k).write(values[k] as i32);
                if k == 0 {
                    parents.at(0).write(-1);
                }
                if k + 1 < n {
                    let (first, last, split) = internal(keys, k as i64);
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
        // SAFETY: `count` nodes and parents, `n` ids and boxes, all the caller's; the counters
        // are not needed on the CPU (`bvh_build::refit` keeps its own).
        let (nodes, parents, ids, lo, hi) = unsafe {
            (
                std::slice::from_raw_parts_mut(self.nodes as *mut BvhNode, count),
                std::slice::from_raw_parts(self.parents as *const i32, count),
                std::slice::from_raw_parts(self.prim_ids as *const i32, n),
                std::slice::from_raw_parts(self.lowers as *const Vec3, n),
                std::slice::from_raw_parts(self.uppers as *const Vec3, n),
            )
        };
        // The kernel's climb from every primitive's leaf (a leaf over several primitives is
        // one the hierarchy made from an internal node: reached by climbing), with the same
        // unions (min/max: exact and order-free), in any order.
        let first_leaf = n - 1;
        bvh_build::refit_from(nodes, parents, ids, lo, hi, first_leaf..first_leaf + n);
        Ok(())
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
        let parents = Array::<i32>::zeros(node_count(n), &dev).unwrap();
        let ids = Array::<i32>::zeros(n, &dev).unwrap();
        let mut b = Lbvh::new(&dev).unwrap();
        let (l, h) = (
            Array::from_slice(lo, &dev).unwrap(),
            Array::from_slice(hi, &dev).unwrap(),
        );
        let tree = LbvhTree {
            nodes: &nodes,
            parents: &parents,
            prim_ids: &ids,
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

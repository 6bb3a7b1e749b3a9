//! The CPU BVH builder: a binned SAH build (rayon over the top of the tree and its binning)
//! and a bottom-up refit, producing the node layout of `warp_core::objects::bvh` (root at
//! node 0, leaves `left = !start`, `prim_ids` grouped by leaf, `parents` the links: each
//! node's parent, -1 at the root, then each node's escape), which every query on either
//! backend reads.
//!
//! # The build
//!
//! Top-down. A node over a range of primitives bins their box centroids into
//! [`SAH_BINS`] bins per axis and picks the plane between bins with the least surface area
//! heuristic cost `A(left) * N(left) + A(right) * N(right)` (areas in f64, so that boxes at
//! 1e30 or 1e-30 neither overflow nor vanish). It becomes a leaf when it holds one primitive,
//! or at most [`MAX_LEAF_SIZE`] and no split is cheaper than testing them all; otherwise it
//! splits. Where binning cannot separate the primitives (all centroids equal, within one bin,
//! or not finite), it splits at the median of the centroids along their longest axis (in
//! index order when that is zero), so every split makes two non-empty halves and the build
//! always terminates, whatever the input (NaN boxes included: the caller validates them; the
//! builder neither hangs nor panics, and a NaN box may simply never be found). Nodes are
//! numbered with the two children of a node adjacent, so the layout is deterministic (the
//! same input gives the same tree, whatever the thread count).
//!
//! Parallelism: ranges above [`PARALLEL_RANGE`] primitives are binned and bounded with rayon
//! (the top of the tree); the subtrees below that size are then built in parallel, one task
//! each, sequentially inside (an explicit work list, no recursion, so a degenerate deep tree
//! cannot overflow a thread's stack), and spliced into the node array.
//!
//! # Leaf size
//!
//! At most [`MAX_LEAF_SIZE`] = 4 primitives, the SAH deciding below that. A leaf is the end of
//! a traversal's descent and the start of its escape (the traversal is stackless, see
//! `warp_core::objects::bvh`), so leaves of 2 to 4 primitives halve the nodes visited compared
//! to single-primitive leaves, while a leaf's primitives still fit in one or two cache lines of
//! `prim_ids` and cost a handful of box or triangle tests. Larger leaves would make every
//! query pay for tests the tree could have culled.

use glam::{DVec3, Vec3, Vec4};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};
use warp_core::objects::bvh::{preorder_escapes, BvhNode};

/// The most primitives in a leaf.
pub const MAX_LEAF_SIZE: usize = 4;

/// Centroid bins per axis in the SAH search.
pub const SAH_BINS: usize = 16;

/// Ranges larger than this are binned in parallel; smaller ones are built as one task each.
pub const PARALLEL_RANGE: usize = 4096;

/// A built tree in the shared layout.
#[derive(Clone, Debug, PartialEq)]
pub struct BuiltBvh {
    /// The nodes; the root is node 0.
    pub nodes: Vec<BvhNode>,
    /// The links, two per node: each node's parent (-1 for the root), then each node's escape
    /// (`warp_core::objects::bvh::preorder_escapes`).
    pub parents: Vec<i32>,
    /// The primitive indices grouped by leaf.
    pub prim_ids: Vec<i32>,
}

impl BuiltBvh {
    /// The empty tree: one empty leaf with an inverted box, no primitive.
    pub fn empty() -> BuiltBvh {
        BuiltBvh {
            nodes: vec![BvhNode::EMPTY],
            parents: vec![-1, -1],
            prim_ids: Vec::new(),
        }
    }
}

/// A box, unioned componentwise with NaN dropped ([`Aabb::union`]).
#[derive(Clone, Copy, Debug)]
struct Aabb {
    lo: Vec3,
    hi: Vec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        lo: Vec3::INFINITY,
        hi: Vec3::NEG_INFINITY,
    };

    fn grow(&mut self, lo: Vec3, hi: Vec3) {
        *self = Aabb::union(*self, Aabb { lo, hi });
    }

    /// The union, by IEEE `minNum`/`maxNum` per component (`f32::min`, CUDA's `fminf`): a NaN
    /// operand is dropped whichever side it is on, so the union is associative and
    /// commutative even with NaN boxes, and a parent always contains its children. (glam's
    /// `Vec3::min` compares, so a NaN on one side wins and a later one loses: not associative.)
    fn union(a: Aabb, b: Aabb) -> Aabb {
        let min = |x: Vec3, y: Vec3| Vec3::new(x.x.min(y.x), x.y.min(y.y), x.z.min(y.z));
        let max = |x: Vec3, y: Vec3| Vec3::new(x.x.max(y.x), x.y.max(y.y), x.z.max(y.z));
        Aabb {
            lo: min(a.lo, b.lo),
            hi: max(a.hi, b.hi),
        }
    }

    /// Half the surface area, in f64 (0 for an empty box).
    fn half_area(&self) -> f64 {
        let e: DVec3 = (self.hi.as_dvec3() - self.lo.as_dvec3()).max(DVec3::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
}

/// The centroid of a box, halved before adding so that huge boxes do not overflow.
#[inline(always)]
fn centroid(lo: Vec3, hi: Vec3) -> Vec3 {
    lo * 0.5 + hi * 0.5
}

/// One SAH bin.
#[derive(Clone, Copy)]
struct Bin {
    count: u32,
    b: Aabb,
}

const EMPTY_BIN: Bin = Bin {
    count: 0,
    b: Aabb::EMPTY,
};

/// The primitive boxes being built over.
#[derive(Clone, Copy)]
struct Prims<'a> {
    lowers: &'a [Vec3],
    uppers: &'a [Vec3],
}

impl Prims<'_> {
    #[inline(always)]
    fn get(&self, id: i32) -> (Vec3, Vec3) {
        (self.lowers[id as usize], self.uppers[id as usize])
    }
}

/// The bounds of a range's boxes and of its centroids.
fn bounds(prims: Prims<'_>, ids: &[i32], parallel: bool) -> (Aabb, Aabb) {
    let one = |id: &i32| {
        let (lo, hi) = prims.get(*id);
        let c = centroid(lo, hi);
        (Aabb { lo, hi }, Aabb { lo: c, hi: c })
    };
    let join = |a: (Aabb, Aabb), b: (Aabb, Aabb)| (Aabb::union(a.0, b.0), Aabb::union(a.1, b.1));
    if parallel {
        ids.par_iter()
            .map(one)
            .reduce(|| (Aabb::EMPTY, Aabb::EMPTY), join)
    } else {
        ids.iter().map(one).fold((Aabb::EMPTY, Aabb::EMPTY), join)
    }
}

/// The bin of centroid coordinate `c` on an axis starting at `lo` with `scale = bins /
/// extent` (NaN and out-of-range values clamp into the end bins; `as` saturates).
#[inline(always)]
fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(SAH_BINS - 1)
}

/// A chosen split: the axis and the first bin of the right side.
#[derive(Clone, Copy, Debug)]
struct Split {
    axis: usize,
    bin: usize,
    lo: f32,
    scale: f32,
}

/// The cheapest SAH split of a range, with its cost, or `None` when binning does not separate
/// the centroids.
fn best_split(prims: Prims<'_>, ids: &[i32], cbox: Aabb, parallel: bool) -> Option<(Split, f64)> {
    let ext = cbox.hi - cbox.lo;
    let mut scales = [0.0f32; 3];
    for a in 0..3 {
        // Only axes along which the centroids spread (finite, positive extent).
        if ext[a] > 0.0 && ext[a].is_finite() {
            scales[a] = SAH_BINS as f32 / ext[a];
            if !scales[a].is_finite() {
                scales[a] = 0.0;
            }
        }
    }
    if scales.iter().all(|s| *s == 0.0) {
        return None;
    }
    let bin_one = |mut bins: [[Bin; SAH_BINS]; 3], id: &i32| {
        let (lo, hi) = prims.get(*id);
        let c = centroid(lo, hi);
        for a in 0..3 {
            if scales[a] > 0.0 {
                let b = &mut bins[a][bin_of(c[a], cbox.lo[a], scales[a])];
                b.count += 1;
                b.b.grow(lo, hi);
            }
        }
        bins
    };
    let merge = |mut x: [[Bin; SAH_BINS]; 3], y: [[Bin; SAH_BINS]; 3]| {
        for a in 0..3 {
            for k in 0..SAH_BINS {
                x[a][k].count += y[a][k].count;
                x[a][k].b = Aabb::union(x[a][k].b, y[a][k].b);
            }
        }
        x
    };
    let empty = [[EMPTY_BIN; SAH_BINS]; 3];
    let bins = if parallel {
        ids.par_chunks(1024)
            .map(|c| c.iter().fold(empty, bin_one))
            .reduce(|| empty, merge)
    } else {
        ids.iter().fold(empty, bin_one)
    };
    let mut best: Option<(Split, f64)> = None;
    for a in 0..3 {
        if scales[a] == 0.0 {
            continue;
        }
        let bs = &bins[a];
        // Right-to-left sweep: the cost of everything from bin k rightwards.
        let mut right = [(0u32, 0.0f64); SAH_BINS];
        let (mut acc, mut n) = (Aabb::EMPTY, 0u32);
        for k in (1..SAH_BINS).rev() {
            acc = Aabb::union(acc, bs[k].b);
            n += bs[k].count;
            right[k] = (n, acc.half_area());
        }
        let (mut acc, mut n) = (Aabb::EMPTY, 0u32);
        for k in 1..SAH_BINS {
            acc = Aabb::union(acc, bs[k - 1].b);
            n += bs[k - 1].count;
            let (nr, ar) = right[k];
            if n == 0 || nr == 0 {
                continue;
            }
            let cost = acc.half_area() * n as f64 + ar * nr as f64;
            if cost.is_finite() && best.is_none_or(|(_, c)| cost < c) {
                best = Some((
                    Split {
                        axis: a,
                        bin: k,
                        lo: cbox.lo[a],
                        scale: scales[a],
                    },
                    cost,
                ));
            }
        }
    }
    best
}

/// Splits a range of at least two primitives: returns the size of the left part, which is
/// in `1..ids.len()`, and whether to make a leaf instead (the SAH's choice for small ranges).
fn split(
    prims: Prims<'_>,
    ids: &mut [i32],
    nbox: Aabb,
    cbox: Aabb,
    parallel: bool,
) -> Option<usize> {
    let n = ids.len();
    debug_assert!(n >= 2);
    let chosen = best_split(prims, ids, cbox, parallel);
    if let Some((_, cost)) = chosen {
        // Relative to testing all: traversing costs about one box test, and the children's
        // tests are weighted by their share of the parent's area.
        let area = nbox.half_area();
        if n <= MAX_LEAF_SIZE && area > 0.0 && area.is_finite() && 1.0 + cost / area >= n as f64 {
            return None;
        }
    } else if n <= MAX_LEAF_SIZE {
        return None;
    }
    if let Some((s, _)) = chosen {
        // Partition by the same bin function the costs were computed with.
        let mut i = 0;
        for j in 0..n {
            let (lo, hi) = prims.get(ids[j]);
            if bin_of(centroid(lo, hi)[s.axis], s.lo, s.scale) < s.bin {
                ids.swap(i, j);
                i += 1;
            }
        }
        if i > 0 && i < n {
            return Some(i);
        }
    }
    // Median fallback along the centroids' longest axis (any order when they coincide).
    let ext = cbox.hi - cbox.lo;
    let axis = if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    };
    let mid = n / 2;
    if ext[axis] > 0.0 {
        ids.select_nth_unstable_by(mid, |a, b| {
            let (ca, cb) = (
                centroid(prims.get(*a).0, prims.get(*a).1)[axis],
                centroid(prims.get(*b).0, prims.get(*b).1)[axis],
            );
            ca.total_cmp(&cb)
        });
    }
    Some(mid)
}

/// A range still to build: `ids[start..end]` into the node at `slot`, whose parent is
/// `parent`.
#[derive(Clone, Copy, Debug)]
struct Task {
    start: usize,
    end: usize,
    slot: usize,
    parent: i32,
}

/// Builds the tree over `ids` (leaf ranges offset by `base`) sequentially, by an explicit
/// work list, into `nodes`/`parents` whose node 0 is the root (parent -1).
fn build_serial(prims: Prims<'_>, ids: &mut [i32], base: usize) -> (Vec<BvhNode>, Vec<i32>) {
    let mut nodes = vec![BvhNode::EMPTY];
    let mut parents = vec![-1];
    let mut work = vec![Task {
        start: 0,
        end: ids.len(),
        slot: 0,
        parent: -1,
    }];
    while let Some(t) = work.pop() {
        let r = &mut ids[t.start..t.end];
        let (nbox, cbox) = bounds(prims, r, false);
        parents[t.slot] = t.parent;
        let cut = if r.len() >= 2 {
            split(prims, r, nbox, cbox, false)
        } else {
            None
        };
        match cut {
            None => {
                nodes[t.slot] = BvhNode::leaf(
                    nbox.lo,
                    nbox.hi,
                    (base + t.start) as i32,
                    (base + t.end) as i32,
                );
            }
            Some(k) => {
                let l = nodes.len();
                nodes.extend([BvhNode::EMPTY; 2]);
                parents.extend([t.slot as i32; 2]);
                nodes[t.slot] = BvhNode::internal(nbox.lo, nbox.hi, l as i32, l as i32 + 1);
                let mid = t.start + k;
                // Left on top: built first, numbered depth-first.
                work.push(Task {
                    start: mid,
                    end: t.end,
                    slot: l + 1,
                    parent: t.slot as i32,
                });
                work.push(Task {
                    start: t.start,
                    end: mid,
                    slot: l,
                    parent: t.slot as i32,
                });
            }
        }
    }
    (nodes, parents)
}

/// Builds a BVH over the boxes `[lowers[i], uppers[i]]` by binned SAH, leaves of at most
/// [`MAX_LEAF_SIZE`] (module docs). No primitive gives the empty tree.
///
/// # Panics
/// When `lowers` and `uppers` differ in length or there are more than `i32::MAX / 2`
/// primitives (the runtime validates both first).
pub fn build_sah(lowers: &[Vec3], uppers: &[Vec3]) -> BuiltBvh {
    assert_eq!(lowers.len(), uppers.len(), "one upper per lower");
    let n = lowers.len();
    assert!(n <= (i32::MAX / 2) as usize, "{n} primitives");
    if n == 0 {
        return BuiltBvh::empty();
    }
    let prims = Prims { lowers, uppers };
    let mut prim_ids: Vec<i32> = (0..n as i32).collect();

    // The top of the tree, splitting large ranges with parallel binning; ranges of at most
    // PARALLEL_RANGE become pending subtrees, their slot reserved.
    let mut nodes = vec![BvhNode::EMPTY];
    let mut parents = vec![-1];
    let mut pending = Vec::new();
    let mut work = vec![Task {
        start: 0,
        end: n,
        slot: 0,
        parent: -1,
    }];
    while let Some(t) = work.pop() {
        if t.end - t.start <= PARALLEL_RANGE {
            pending.push(t);
            continue;
        }
        let r = &mut prim_ids[t.start..t.end];
        let (nbox, cbox) = bounds(prims, r, true);
        let k = split(prims, r, nbox, cbox, true).expect("a large range always splits");
        let l = nodes.len();
        nodes.extend([BvhNode::EMPTY; 2]);
        parents.extend([t.slot as i32; 2]);
        parents[t.slot] = t.parent;
        nodes[t.slot] = BvhNode::internal(nbox.lo, nbox.hi, l as i32, l as i32 + 1);
        let mid = t.start + k;
        work.push(Task {
            start: mid,
            end: t.end,
            slot: l + 1,
            parent: t.slot as i32,
        });
        work.push(Task {
            start: t.start,
            end: mid,
            slot: l,
            parent: t.slot as i32,
        });
    }

    // The subtrees, in parallel, each over its own part of prim_ids (the pending ranges
    // partition 0..n).
    pending.sort_by_key(|t| t.start);
    let mut parts = Vec::with_capacity(pending.len());
    let mut rest: &mut [i32] = &mut prim_ids;
    let mut at = 0;
    for t in &pending {
        debug_assert_eq!(t.start, at);
        let (head, tail) = rest.split_at_mut(t.end - t.start);
        parts.push((*t, head));
        rest = tail;
        at = t.end;
    }
    let subtrees: Vec<(Task, Vec<BvhNode>, Vec<i32>)> = parts
        .into_par_iter()
        .map(|(t, ids)| {
            let (nd, pa) = build_serial(prims, ids, t.start);
            (t, nd, pa)
        })
        .collect();

    // Splice: each subtree's root into its reserved slot, the rest appended.
    for (t, sub_nodes, sub_parents) in subtrees {
        let offset = nodes.len() as i32 - 1;
        let map = |i: i32| if i == 0 { t.slot as i32 } else { i + offset };
        for (i, (mut node, p)) in sub_nodes.into_iter().zip(sub_parents).enumerate() {
            if !node.is_leaf() {
                node.left = map(node.left);
                node.right = map(node.right);
            }
            let parent = if i == 0 { t.parent } else { map(p) };
            if i == 0 {
                nodes[t.slot] = node;
                parents[t.slot] = parent;
            } else {
                nodes.push(node);
                parents.push(parent);
            }
        }
    }
    parents.extend(preorder_escapes(&nodes));
    BuiltBvh {
        nodes,
        parents,
        prim_ids,
    }
}

/// A mesh's triangles in its tree's leaf order, as its build and refits write them (what
/// the mesh queries' walks read; `warp_core::objects::mesh::write_leaf_triangles`): three
/// corners `{x, y, z, 0}` per position of `prim_ids`, NaN corners for an id or index out of
/// range. For the CPU's build and tests comparing the backends.
pub fn leaf_triangles(prim_ids: &[i32], indices: &[i32], points: &[Vec3]) -> Vec<Vec4> {
    let mut out = vec![Vec4::ZERO; 3 * prim_ids.len()];
    write_leaf_triangles_par(&mut out, prim_ids, indices, points);
    out
}

/// `warp_core::objects::mesh::write_leaf_triangles` over rayon, in chunks of positions (each
/// position's corners depend on it alone, so the same values in any order).
pub(crate) fn write_leaf_triangles_par(out: &mut [Vec4], ids: &[i32], ix: &[i32], p: &[Vec3]) {
    const CHUNK: usize = 4096;
    out.par_chunks_mut(3 * CHUNK)
        .zip(ids.par_chunks(CHUNK))
        .for_each(|(o, i)| warp_core::objects::mesh::write_leaf_triangles(o, i, ix, p));
}

/// The boxes of the triangles `indices[3f..3f + 3]` of `points`, or the first position of an
/// index outside the points.
pub(crate) fn triangle_boxes(
    points: &[Vec3],
    indices: &[i32],
) -> Result<(Vec<Vec3>, Vec<Vec3>), usize> {
    if let Some(k) = indices
        .iter()
        .position(|&i| usize::try_from(i).map_or(true, |i| i >= points.len()))
    {
        return Err(k);
    }
    Ok(indices
        .chunks_exact(3)
        .map(|t| {
            let [a, b, c] = [0, 1, 2].map(|k| points[t[k] as usize]);
            (a.min(b).min(c), a.max(b).max(c))
        })
        .unzip())
}

/// A raw pointer to the nodes that refit's threads write through, each its own nodes.
#[derive(Clone, Copy)]
struct NodesPtr(*mut BvhNode);
// SAFETY: refit's threads write disjoint nodes and read only nodes whose writes happen
// before (the counters' acquire-release order).
unsafe impl Send for NodesPtr {}
unsafe impl Sync for NodesPtr {}

impl NodesPtr {
    /// The address of node `i` of `len` (a method, so closures capture the `Sync` wrapper
    /// rather than its raw pointer field).
    fn at(&self, i: usize, len: usize) -> *mut BvhNode {
        assert!(i < len, "bvh refit: node {i} of {len}");
        // SAFETY: in bounds of the nodes slice refit holds mutably for its whole run.
        unsafe { self.0.add(i) }
    }
}

/// Recomputes every node's box from the primitive boxes, bottom-up, keeping the tree's shape
/// (after the primitives moved). Works on any tree in the layout, whatever its numbering: each
/// leaf's box is the union of its primitives' boxes, computed in parallel; then each leaf's
/// thread climbs the parent links, and the second thread to arrive at a node (an atomic
/// counter per node) computes its box from its children's and climbs on, as Warp's refit.
///
/// `parents`: the tree's links (the parents, then the escapes, which a refit does not read).
///
/// # Panics
/// When the buffers are inconsistent (a child, parent or primitive index out of range, a
/// parent link not matching the children): the runtime's own trees never are.
pub fn refit(
    nodes: &mut [BvhNode],
    parents: &[i32],
    prim_ids: &[i32],
    lowers: &[Vec3],
    uppers: &[Vec3],
) {
    let leaves: Vec<usize> = (0..nodes.len()).filter(|i| nodes[*i].is_leaf()).collect();
    refit_from(nodes, parents, prim_ids, lowers, uppers, leaves);
}

/// [`refit`] with its climbs starting from the leaves `starts` (each once). A leaf reached by
/// climbing (a linear BVH's internal node made a leaf, whose children are still linked up to
/// it: see `lbvh.rs`) gets the union of its primitives' boxes when the second child arrives.
pub fn refit_from(
    nodes: &mut [BvhNode],
    parents: &[i32],
    prim_ids: &[i32],
    lowers: &[Vec3],
    uppers: &[Vec3],
    starts: impl IntoParallelIterator<Item = usize>,
) {
    assert_eq!(
        2 * nodes.len(),
        parents.len(),
        "a parent and an escape per node"
    );
    let parents = &parents[..nodes.len()];
    assert_eq!(lowers.len(), uppers.len());
    let arrivals: Vec<AtomicU32> = (0..nodes.len()).map(|_| AtomicU32::new(0)).collect();
    let ptr = NodesPtr(nodes.as_mut_ptr());
    let len = nodes.len();
    let prims_box = |n: &BvhNode| {
        let (start, end) = n.leaf_range();
        let mut b = Aabb::EMPTY;
        for &id in &prim_ids[start as usize..end as usize] {
            b.grow(lowers[id as usize], uppers[id as usize]);
        }
        b
    };
    starts.into_par_iter().for_each(|leaf| {
        // Each node is written only by one thread (its leaf's, or the second to arrive),
        // and read only after its writer's release (below).
        let node_at = |i: usize| ptr.at(i, len);
        // SAFETY: each start is visited by exactly one thread (the caller's list).
        let n = unsafe { &mut *node_at(leaf) };
        assert!(n.is_leaf(), "bvh refit: start {leaf} is not a leaf");
        let b = prims_box(n);
        n.lower = b.lo.to_array();
        n.upper = b.hi.to_array();
        let mut c = leaf;
        let mut steps = 0;
        loop {
            let p = parents[c];
            steps += 1;
            if p < 0 || steps > len {
                break;
            }
            let p = p as usize;
            // The first arrival stops; the second (which sees the first's writes) goes on.
            if arrivals[p].fetch_add(1, Ordering::AcqRel) == 0 {
                break;
            }
            // SAFETY: only the second arrival writes node p; both children are final.
            let pn = unsafe { &mut *node_at(p) };
            let b = if pn.is_leaf() {
                prims_box(pn)
            } else {
                let (l, r) = unsafe { (*node_at(pn.left as usize), *node_at(pn.right as usize)) };
                Aabb::union(
                    Aabb {
                        lo: l.lower(),
                        hi: l.upper(),
                    },
                    Aabb {
                        lo: r.lower(),
                        hi: r.upper(),
                    },
                )
            };
            pn.lower = b.lo.to_array();
            pn.upper = b.hi.to_array();
            c = p;
        }
    });
}

/// Checks a tree against the layout (for builders' tests, the GPU LBVH's included): the root
/// is node 0 with parent -1; every node is reached once from the root, or lies under a leaf
/// (a linear BVH's subtree made one leaf, unreached); children's parent links lead back; every
/// reached node's escape is its left-first successor (`parents` holds the links); leaf
/// ranges are in order and cover `prim_ids`, a permutation of `0..prims`; every box contains
/// its children's (and a leaf's its primitives') exactly.
/// Returns the tree's depth (the root alone is depth 1), or what is wrong.
pub fn check_layout(
    nodes: &[BvhNode],
    parents: &[i32],
    prim_ids: &[i32],
    lowers: &[Vec3],
    uppers: &[Vec3],
) -> Result<usize, String> {
    if nodes.is_empty() || parents.len() != 2 * nodes.len() {
        return Err(format!("{} nodes, {} links", nodes.len(), parents.len()));
    }
    let (parents, escapes) = parents.split_at(nodes.len());
    if parents[0] != -1 {
        return Err(format!("root's parent {}", parents[0]));
    }
    let mut seen = vec![false; nodes.len()];
    let mut covered = vec![0u32; prim_ids.len()];
    let mut depth = 0;
    let mut work = vec![(0usize, 1usize)];
    let contains = |outer: &BvhNode, lo: Vec3, hi: Vec3| {
        outer.lower().cmple(lo).all() && hi.cmple(outer.upper()).all()
    };
    while let Some((i, d)) = work.pop() {
        if std::mem::replace(&mut seen[i], true) {
            return Err(format!("node {i} reached twice"));
        }
        depth = depth.max(d);
        let n = &nodes[i];
        if n.is_leaf() {
            let (s, e) = n.leaf_range();
            if s < 0 || s > e || e as usize > prim_ids.len() {
                return Err(format!("leaf {i}: range {s}..{e}"));
            }
            for k in s..e {
                covered[k as usize] += 1;
                let id = prim_ids[k as usize];
                if id < 0 || id as usize >= lowers.len() {
                    return Err(format!("prim id {id}"));
                }
                let (lo, hi) = (lowers[id as usize], uppers[id as usize]);
                if lo.is_finite() && hi.is_finite() && !contains(n, lo, hi) {
                    return Err(format!("leaf {i} does not contain primitive {id}"));
                }
            }
        } else {
            for c in [n.left, n.right] {
                if c <= 0 || c as usize >= nodes.len() {
                    return Err(format!("node {i}: child {c}"));
                }
                if parents[c as usize] != i as i32 {
                    return Err(format!("node {c}: parent {} not {i}", parents[c as usize]));
                }
                let cn = &nodes[c as usize];
                if cn.lower().is_finite() && !contains(n, cn.lower(), cn.upper()) {
                    return Err(format!("node {i} {n:?} does not contain child {c} {cn:?}"));
                }
                work.push((c as usize, d + 1));
            }
        }
    }
    for i in (0..nodes.len()).filter(|i| !seen[*i]) {
        // Up the parent links to the first node reached: it must be a leaf.
        let mut c = i;
        for _ in 0..nodes.len() {
            let p = parents[c];
            if p < 0 || p as usize >= nodes.len() {
                return Err(format!("node {i} unreachable (parent {p})"));
            }
            c = p as usize;
            if seen[c] {
                break;
            }
        }
        if !(seen[c] && nodes[c].is_leaf()) {
            return Err(format!("node {i} unreachable, not under a leaf"));
        }
    }
    let want = preorder_escapes(nodes);
    if let Some(i) = (0..nodes.len()).find(|&i| seen[i] && escapes[i] != want[i]) {
        return Err(format!("node {i}: escape {} not {}", escapes[i], want[i]));
    }
    if let Some(k) = covered.iter().position(|c| *c != 1) {
        return Err(format!("prim_ids[{k}] in {} leaves", covered[k]));
    }
    let mut ids = prim_ids.to_vec();
    ids.sort_unstable();
    if ids.iter().enumerate().any(|(k, id)| *id != k as i32) || ids.len() != lowers.len() {
        return Err("prim_ids is not a permutation of the primitives".into());
    }
    Ok(depth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use warp_core::objects::bvh::{
        bvh_query_aabb, bvh_query_aabb_done, bvh_query_aabb_item, bvh_query_aabb_next,
        bvh_query_ray, bvh_query_ray_done, bvh_query_ray_item, bvh_query_ray_next, BvhTree,
        BvhView,
    };
    use warp_core::objects::geometry::{aabb_overlap, intersect_ray_aabb, ray_inv_dir};
    use warp_core::objects::mesh::{mesh_query_point, mesh_query_ray, MeshView};
    use warp_core::ArrayView;

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }
        fn f(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (hi - lo) * ((self.next() >> 40) as f32 / (1u64 << 24) as f32)
        }
        fn v(&mut self, lo: f32, hi: f32) -> Vec3 {
            Vec3::new(self.f(lo, hi), self.f(lo, hi), self.f(lo, hi))
        }
    }

    fn boxes(rng: &mut Rng, n: usize) -> (Vec<Vec3>, Vec<Vec3>) {
        let (mut lo, mut hi) = (Vec::new(), Vec::new());
        for _ in 0..n {
            let c = rng.v(-10.0, 10.0);
            let h = rng.v(0.0, 0.5);
            lo.push(c - h);
            hi.push(c + h);
        }
        (lo, hi)
    }

    fn view<'a>(b: &'a mut BuiltBvh, lo: &'a mut [Vec3], hi: &'a mut [Vec3]) -> BvhView {
        unsafe {
            let tree = BvhTree::new(
                ArrayView::new(b.nodes.as_mut_ptr(), [b.nodes.len()], [1], "k", "bvh"),
                ArrayView::new(b.parents.as_mut_ptr(), [b.parents.len()], [1], "k", "bvh"),
                ArrayView::new(b.prim_ids.as_mut_ptr(), [b.prim_ids.len()], [1], "k", "bvh"),
            );
            BvhView::new(
                tree,
                ArrayView::new(lo.as_mut_ptr(), [lo.len()], [1], "k", "bvh"),
                ArrayView::new(hi.as_mut_ptr(), [hi.len()], [1], "k", "bvh"),
            )
        }
    }

    fn aabb_items(v: BvhView, lo: Vec3, hi: Vec3) -> Vec<i32> {
        let mut q = bvh_query_aabb(v, lo, hi).unwrap();
        let mut out = Vec::new();
        loop {
            q = bvh_query_aabb_next(v, q).unwrap();
            if bvh_query_aabb_done(q) {
                break;
            }
            out.push(bvh_query_aabb_item(q));
        }
        out.sort_unstable();
        out
    }

    fn ray_items(v: BvhView, o: Vec3, d: Vec3) -> Vec<i32> {
        let mut q = bvh_query_ray(v, o, d).unwrap();
        let mut out = Vec::new();
        loop {
            q = bvh_query_ray_next(v, q).unwrap();
            if bvh_query_ray_done(q) {
                break;
            }
            out.push(bvh_query_ray_item(q));
        }
        out.sort_unstable();
        out
    }

    #[test]
    fn builds_valid_trees_and_queries_match_brute_force() {
        let mut rng = Rng(9);
        // Sizes around the leaf size and the parallel threshold, and beyond it.
        for n in [1usize, 2, 3, 4, 5, 17, 1000, 4096, 4097, 20000] {
            let (mut lo, mut hi) = boxes(&mut rng, n);
            let mut b = build_sah(&lo, &hi);
            let depth = check_layout(&b.nodes, &b.parents, &b.prim_ids, &lo, &hi).unwrap();
            // SAH on uniform boxes: near-balanced (a generous bound; a degenerate build would
            // be ~n deep).
            assert!(
                depth <= 4 * (usize::BITS - n.leading_zeros()) as usize + 2,
                "{n}: {depth}"
            );
            assert_eq!(b, build_sah(&lo, &hi), "deterministic");
            for k in 0..b.nodes.len() {
                if b.nodes[k].is_leaf() {
                    let (s, e) = b.nodes[k].leaf_range();
                    assert!((1..=MAX_LEAF_SIZE as i32).contains(&(e - s)));
                }
            }
            let v = view(&mut b, &mut lo, &mut hi);
            let (lo, hi) = (lo.clone(), hi.clone());
            for _ in 0..100 {
                let c = rng.v(-11.0, 11.0);
                let h = rng.v(0.0, 2.0);
                let want: Vec<i32> = (0..n as i32)
                    .filter(|i| aabb_overlap(lo[*i as usize], hi[*i as usize], c - h, c + h))
                    .collect();
                assert_eq!(aabb_items(v, c - h, c + h), want);
                let (o, d) = (rng.v(-12.0, 12.0), rng.v(-1.0, 1.0));
                let inv = ray_inv_dir(d);
                let want: Vec<i32> = (0..n as i32)
                    .filter(|i| {
                        intersect_ray_aabb(o, inv, lo[*i as usize], hi[*i as usize]).is_some()
                    })
                    .collect();
                assert_eq!(ray_items(v, o, d), want);
            }
        }
    }

    #[test]
    fn degenerate_inputs() {
        // None: the empty tree.
        let b = build_sah(&[], &[]);
        assert_eq!(b, BuiltBvh::empty());
        check_layout(&b.nodes, &b.parents, &b.prim_ids, &[], &[]).unwrap();
        // One.
        let b = build_sah(&[Vec3::ZERO], &[Vec3::ONE]);
        assert_eq!(b.nodes.len(), 1);
        assert_eq!(b.nodes[0].leaf_range(), (0, 1));
        // All centroids equal (identical boxes, and nested boxes around one centre), many of
        // them, across the parallel threshold: terminates, valid, median depth.
        for n in [5usize, 100, 10000] {
            let lo: Vec<Vec3> = (0..n).map(|i| Vec3::splat(-(i as f32))).collect();
            let hi: Vec<Vec3> = (0..n).map(|i| Vec3::splat(i as f32)).collect();
            let b = build_sah(&lo, &hi);
            let d = check_layout(&b.nodes, &b.parents, &b.prim_ids, &lo, &hi).unwrap();
            assert!(
                d <= 2 + (usize::BITS - n.leading_zeros()) as usize,
                "{n}: {d}"
            );
            let same = vec![Vec3::ONE; n];
            let b = build_sah(&same, &same);
            check_layout(&b.nodes, &b.parents, &b.prim_ids, &same, &same).unwrap();
        }
        // NaN and infinite boxes mixed in: no hang, no panic, a valid permutation.
        let mut rng = Rng(4);
        let (mut lo, mut hi) = boxes(&mut rng, 9000);
        for i in (0..9000).step_by(7) {
            lo[i] = Vec3::NAN;
        }
        for i in (3..9000).step_by(11) {
            hi[i] = Vec3::splat(f32::INFINITY);
        }
        let b = build_sah(&lo, &hi);
        check_layout(&b.nodes, &b.parents, &b.prim_ids, &lo, &hi).unwrap();
        let all_nan = vec![Vec3::NAN; 50];
        let b = build_sah(&all_nan, &all_nan);
        check_layout(&b.nodes, &b.parents, &b.prim_ids, &all_nan, &all_nan).unwrap();
        // Huge and tiny coordinates: SAH still splits (areas in f64), queries still exact.
        for k in [1e30f32, 1e-30] {
            let (lo, hi) = boxes(&mut rng, 3000);
            let (mut lo, mut hi): (Vec<Vec3>, Vec<Vec3>) = (
                lo.iter().map(|x| *x * k).collect(),
                hi.iter().map(|x| *x * k).collect(),
            );
            let mut b = build_sah(&lo, &hi);
            let d = check_layout(&b.nodes, &b.parents, &b.prim_ids, &lo, &hi).unwrap();
            assert!(d < 40, "{k}: depth {d}");
            let (l2, h2) = (lo.clone(), hi.clone());
            let v = view(&mut b, &mut lo, &mut hi);
            let (c, h) = (Vec3::splat(1.0) * k, Vec3::splat(2.0) * k);
            let want: Vec<i32> = (0..3000)
                .filter(|i| aabb_overlap(l2[*i as usize], h2[*i as usize], c - h, c + h))
                .collect();
            assert_eq!(aabb_items(v, c - h, c + h), want);
        }
        // Exponentially spaced boxes (a classic SAH worst case for depth): terminates, and
        // the stackless queries do not care how deep.
        let lo: Vec<Vec3> = (0..120).map(|i| Vec3::splat(2f32.powi(i) - 1.0)).collect();
        let hi: Vec<Vec3> = lo.iter().map(|x| *x + 0.5).collect();
        let b = build_sah(&lo, &hi);
        check_layout(&b.nodes, &b.parents, &b.prim_ids, &lo, &hi).unwrap();
    }

    #[test]
    fn refit_matches_a_rebuild_of_the_boxes() {
        let mut rng = Rng(12);
        for n in [0usize, 1, 7, 5000, 12000] {
            let (lo, hi) = boxes(&mut rng, n);
            let mut b = build_sah(&lo, &hi);
            // Move every box; refit; the layout holds with the new boxes and every node's box
            // is the tight union of what is below it.
            let shift: Vec<Vec3> = (0..n).map(|_| rng.v(-3.0, 3.0)).collect();
            let mut lo2: Vec<Vec3> = lo.iter().zip(&shift).map(|(x, s)| *x + *s).collect();
            let mut hi2: Vec<Vec3> = hi.iter().zip(&shift).map(|(x, s)| *x + *s).collect();
            refit(&mut b.nodes, &b.parents, &b.prim_ids, &lo2, &hi2);
            check_layout(&b.nodes, &b.parents, &b.prim_ids, &lo2, &hi2).unwrap();
            if n > 0 {
                let root = b.nodes[0];
                let tight = (
                    lo2.iter().fold(Vec3::INFINITY, |a, x| a.min(*x)),
                    hi2.iter().fold(Vec3::NEG_INFINITY, |a, x| a.max(*x)),
                );
                assert_eq!((root.lower(), root.upper()), tight);
            } else {
                assert_eq!(b.nodes[0], BvhNode::EMPTY);
            }
            let (l3, h3) = (lo2.clone(), hi2.clone());
            let v = view(&mut b, &mut lo2, &mut hi2);
            for _ in 0..50 {
                let (c, h) = (rng.v(-12.0, 12.0), rng.v(0.0, 2.0));
                let want: Vec<i32> = (0..n as i32)
                    .filter(|i| aabb_overlap(l3[*i as usize], h3[*i as usize], c - h, c + h))
                    .collect();
                assert_eq!(aabb_items(v, c - h, c + h), want);
            }
        }
        // Refit of a tree numbered otherwise (children before parents): the same boxes.
        let (lo, hi) = boxes(&mut rng, 300);
        let b = build_sah(&lo, &hi);
        let m = b.nodes.len();
        let perm = |i: i32| if i == 0 { 0 } else { m as i32 - i };
        let mut nodes = vec![BvhNode::EMPTY; m];
        // The escapes (the second half) are not read by a refit.
        let mut parents = vec![-1; 2 * m];
        for i in 0..m {
            let mut nd = b.nodes[i];
            if !nd.is_leaf() {
                nd.left = perm(nd.left);
                nd.right = perm(nd.right);
            }
            nd.lower = [0.0; 3];
            nd.upper = [0.0; 3];
            nodes[perm(i as i32) as usize] = nd;
            parents[perm(i as i32) as usize] = if b.parents[i] < 0 {
                -1
            } else {
                perm(b.parents[i])
            };
        }
        refit(&mut nodes, &parents, &b.prim_ids, &lo, &hi);
        for i in 0..m {
            assert_eq!(nodes[perm(i as i32) as usize].lower, b.nodes[i].lower);
            assert_eq!(nodes[perm(i as i32) as usize].upper, b.nodes[i].upper);
        }
    }

    /// The builder and the kernel-side mesh queries together: a closed sphere of 20000
    /// triangles (beyond the parallel threshold), its signed query against the analytic sphere
    /// and rays from the centre hitting the back of faces at about the radius.
    #[test]
    fn mesh_over_a_built_tree() {
        let (rings, segs) = (100usize, 100usize);
        let mut pts = vec![Vec3::Z];
        for i in 1..rings {
            let th = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segs {
                let ph = 2.0 * std::f32::consts::PI * j as f32 / segs as f32;
                pts.push(Vec3::new(
                    th.sin() * ph.cos(),
                    th.sin() * ph.sin(),
                    th.cos(),
                ));
            }
        }
        pts.push(-Vec3::Z);
        let s = pts.len() as i32 - 1;
        let at = |i: usize, j: usize| (1 + (i - 1) * segs + j % segs) as i32;
        let mut ix = Vec::new();
        for j in 0..segs {
            ix.extend([0, at(1, j), at(1, j + 1)]);
            ix.extend([s, at(rings - 1, j + 1), at(rings - 1, j)]);
        }
        for i in 1..rings - 1 {
            for j in 0..segs {
                ix.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                ix.extend([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        let (lo, hi): (Vec<Vec3>, Vec<Vec3>) = ix
            .chunks(3)
            .map(|t| {
                let [a, b, c] = [0, 1, 2].map(|k| pts[t[k] as usize]);
                (a.min(b).min(c), a.max(b).max(c))
            })
            .unzip();
        let mut b = build_sah(&lo, &hi);
        check_layout(&b.nodes, &b.parents, &b.prim_ids, &lo, &hi).unwrap();
        let mut soup = leaf_triangles(&b.prim_ids, &ix, &pts);
        let v = unsafe {
            let tree = BvhTree::new(
                ArrayView::new(b.nodes.as_mut_ptr(), [b.nodes.len()], [1], "k", "mesh"),
                ArrayView::new(b.parents.as_mut_ptr(), [b.parents.len()], [1], "k", "mesh"),
                ArrayView::new(
                    b.prim_ids.as_mut_ptr(),
                    [b.prim_ids.len()],
                    [1],
                    "k",
                    "mesh",
                ),
            );
            MeshView::new(
                tree,
                ArrayView::new(pts.as_mut_ptr(), [pts.len()], [1], "k", "mesh"),
                None,
                ArrayView::new(ix.as_mut_ptr(), [ix.len()], [1], "k", "mesh"),
                ArrayView::new(soup.as_mut_ptr(), [soup.len()], [1], "k", "mesh"),
            )
        };
        let mut rng = Rng(3);
        for _ in 0..2000 {
            let p = rng.v(-1.5, 1.5);
            if (p.length() - 1.0).abs() < 0.01 {
                continue;
            }
            let q = mesh_query_point(v, p, f32::MAX).unwrap();
            assert!(q.result);
            assert_eq!(q.sign, if p.length() < 1.0 { -1.0 } else { 1.0 }, "{p}");
            let d = rng.v(-1.0, 1.0);
            let r = mesh_query_ray(v, Vec3::ZERO, d, f32::MAX).unwrap();
            if d.length() > 1e-3 {
                assert!(r.result && r.sign == -1.0, "{d}");
                assert!(((d * r.t).length() - 1.0).abs() < 1e-3);
            }
        }
    }
}

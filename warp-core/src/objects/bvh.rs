//! Warp's BVH, kernel side: the node layout every builder produces and both backends read,
//! [`BvhView`] (what a `Bvh` kernel parameter is on the CPU), and the two iterating queries,
//! [`bvh_query_aabb`] and [`bvh_query_ray`]. The mesh ([`super::mesh`]) reads its triangles'
//! tree through the same [`BvhTree`] and the same traversal.
//!
//! # Layout (shared by every builder: the CPU SAH build in warp-runtime, the GPU LBVH)
//!
//! A tree over `n` primitives (the user's boxes, or a mesh's triangles) is three buffers:
//!
//! - `nodes: [BvhNode]`, 32 bytes each, `#[repr(C)]`:
//!   `lower: [f32; 3], left: i32, upper: [f32; 3], right: i32` (two 16-byte halves, so a GPU
//!   loads a node as two `float4`). **The root is node 0.**
//!   - An **internal** node has `left >= 0` and `right >= 0`: the indices of its two children
//!     (any order in the buffer; both in `1..nodes.len()`).
//!   - A **leaf** has `left < 0`: it holds the primitives `prim_ids[!left .. right]` (`!left`
//!     is `-left - 1`, so `left = !start`); `start <= right`.
//!   - Every node's box contains its children's boxes, a leaf's box its primitives' boxes
//!     (built with `min`/`max` only, so the containment is exact in floating point).
//! - `prim_ids: [i32]`, `n` entries: the primitive indices (into the user's arrays) grouped
//!   by leaf, a permutation of `0..n`.
//! - `parents: [i32]`, **two per node** (the tree's links): first each node's parent, **-1
//!   for the root**, then each node's *escape*, the node a left-first traversal visits after
//!   the node's subtree: the right child of the nearest ancestor whose left subtree holds
//!   the node, **-1 when there is none** (the root, and the last nodes of the traversal).
//!   Refit walks the parents bottom-up; the iterating traversals follow the escapes instead
//!   of keeping a stack (below). [`preorder_escapes`] computes the escapes from the nodes; the
//!   GPU's linear BVH writes them in its hierarchy step, from the sorted codes.
//!
//! The **empty tree** (no primitive) is one leaf with the empty range (`left = !0 = -1`,
//! `right = 0`) and the inverted box `lower = +inf`, `upper = -inf`, which no box test
//! accepts; `prim_ids` is empty and `parents = [-1, -1]`. A tree over one primitive is one
//! leaf.
//!
//! # Traversal: by escape links, with a bounded stack where the state is local
//!
//! Warp keeps a 32-entry stack of node indices in every query state (silently wrong when a
//! deep tree overflows it). Here the iterating queries ([`bvh_query_aabb`], [`bvh_query_ray`],
//! a mesh's box query) keep no stack: they go down to the left child first, and when a
//! subtree is rejected or a leaf finished they go to its escape: one read of four bytes,
//! where climbing the parent links to the first ancestor reached from its left child reads a
//! parent link and a whole parent node per level climbed. Their
//! state is then a position in the tree, so it stays small ([`BvhQueryAabb`]: 44 bytes,
//! pushed on the adjoint stack at every loop iteration), and any depth a builder produces (an
//! LBVH over duplicate Morton codes included) is fine.
//!
//! The searches that run to completion inside one call (closest point, closest hit, the
//! faces around a vertex) order children by a key and keep the farther children on a local
//! ring of `ORDERED_STACK` entries (`walk_ordered`): a pop instead of a climb that
//! re-reads and re-orders every parent, which made those queries several times slower. A
//! tree deeper than the ring loses its oldest entries, and the walk finds them by climbing
//! the parent links, so there is no overflow case either.
//!
//! # Corrupt trees
//!
//! Every read whose index comes from buffer contents is checked: an index outside its
//! buffer (a child, a parent, an escape, a leaf range, a primitive id) is an out-of-bounds
//! fault naming the tree's kernel parameter (an escape when the node it leads to is read). A
//! tree whose indices are in range but whose structure is wrong (a cycle, links that do not
//! match the children) cannot loop forever: a traversal takes at most `2 * nodes + 2` moves,
//! which a well-formed tree never needs, and ends there; the ordered walk also ends where a
//! parent link does not lead back to its child.

// `!(x > t)` is true when `x` is NaN: the negated comparisons below are how NaN takes the
// rejecting branch, on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use super::geometry::{aabb_overlap, intersect_ray_aabb, ray_inv_dir};
use crate::{ArrayView, Fault, FaultKind, KResult};

/// One node of a BVH (see the module docs for the layout): 32 bytes, `#[repr(C)]`.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct BvhNode {
    /// The box's lower corner.
    pub lower: [f32; 3],
    /// An internal node's left child; a leaf's `!start` (negative).
    pub left: i32,
    /// The box's upper corner.
    pub upper: [f32; 3],
    /// An internal node's right child; a leaf's end (exclusive) in `prim_ids`.
    pub right: i32,
}

const _: () = assert!(std::mem::size_of::<BvhNode>() == 32);

impl BvhNode {
    /// The empty tree's only node: an empty leaf with the inverted box `[+inf, -inf]`.
    pub const EMPTY: BvhNode = BvhNode {
        lower: [f32::INFINITY; 3],
        left: !0,
        upper: [f32::NEG_INFINITY; 3],
        right: 0,
    };

    /// A leaf holding `prim_ids[start..end]`.
    pub fn leaf(lower: Vec3, upper: Vec3, start: i32, end: i32) -> BvhNode {
        debug_assert!(0 <= start && start <= end);
        BvhNode {
            lower: lower.to_array(),
            left: !start,
            upper: upper.to_array(),
            right: end,
        }
    }

    /// An internal node with children `left` and `right`.
    pub fn internal(lower: Vec3, upper: Vec3, left: i32, right: i32) -> BvhNode {
        debug_assert!(left >= 0 && right >= 0);
        BvhNode {
            lower: lower.to_array(),
            left,
            upper: upper.to_array(),
            right,
        }
    }

    /// Whether the node is a leaf.
    #[inline(always)]
    pub fn is_leaf(&self) -> bool {
        self.left < 0
    }

    /// A leaf's range `[start, end)` in `prim_ids` (meaningless for an internal node).
    #[inline(always)]
    pub fn leaf_range(&self) -> (i32, i32) {
        (!self.left, self.right)
    }

    /// The box's lower corner.
    #[inline(always)]
    pub fn lower(&self) -> Vec3 {
        Vec3::from_array(self.lower)
    }

    /// The box's upper corner.
    #[inline(always)]
    pub fn upper(&self) -> Vec3 {
        Vec3::from_array(self.upper)
    }
}

/// The address of element 0 of a contiguous view (a dangling, aligned pointer when it is
/// empty, never read then).
///
/// # Panics
/// When the view has at least two elements and they are not adjacent (host-side check).
fn contiguous_ptr<T: Copy>(v: &ArrayView<T, 1>, what: &str) -> *const T {
    if v.is_empty() {
        return std::ptr::NonNull::<T>::dangling().as_ptr();
    }
    let p0 = v.ptr_at(0usize).expect("in bounds");
    if v.len() >= 2 {
        let p1 = v.ptr_at(1usize).expect("in bounds");
        assert!(
            p1 as usize == p0 as usize + std::mem::size_of::<T>(),
            "{what}: the buffer must be contiguous"
        );
    }
    p0
}

/// The part of a built BVH every query reads: the nodes, the links (parents, then escapes),
/// the primitive order (module docs), and the kernel and parameter names its faults carry. `Copy`, owns
/// nothing; 64 bytes. A [`BvhView`] is one plus the primitives' boxes; a mesh view one plus
/// its points and triangles.
#[derive(Clone, Copy)]
pub struct BvhTree {
    nodes: *const BvhNode,
    parents: *const i32,
    prim_ids: *const i32,
    num_nodes: i32,
    num_prims: i32,
    kernel: &'static str,
    arg: &'static str,
}

#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<BvhTree>() == 64);

// SAFETY: read-only pointers into buffers the runtime keeps alive for the whole launch.
unsafe impl Send for BvhTree {}
unsafe impl Sync for BvhTree {}

impl std::fmt::Debug for BvhTree {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BvhTree")
            .field("nodes", &self.num_nodes)
            .field("prims", &self.num_prims)
            .finish()
    }
}

impl BvhTree {
    /// A tree over raw buffers: `num_nodes` nodes, `2 * num_nodes` links (the parents, then
    /// the escapes: module docs), `num_prims` primitive ids; faults carry `kernel` and `arg`.
    ///
    /// # Safety
    /// The pointers must address that many valid elements, alive and unchanged while the tree
    /// (or a copy) is used. Their *contents* need not be consistent: any index read from them
    /// is checked.
    ///
    /// # Panics
    /// When `num_nodes < 1`, or a count is negative.
    pub unsafe fn from_raw(
        nodes: *const BvhNode,
        parents: *const i32,
        num_nodes: i32,
        prim_ids: *const i32,
        num_prims: i32,
        kernel: &'static str,
        arg: &'static str,
    ) -> BvhTree {
        assert!(
            num_nodes >= 1 && num_prims >= 0,
            "a bvh has at least one node (the empty tree has one leaf): {num_nodes} nodes, \
             {num_prims} primitives"
        );
        BvhTree {
            nodes,
            parents,
            prim_ids,
            num_nodes,
            num_prims,
            kernel,
            arg,
        }
    }

    /// A tree over checked views (each contiguous; the names of `nodes` are the faults').
    ///
    /// # Panics
    /// When a view is not contiguous, `nodes` is empty, `parents` (the links: parents, then
    /// escapes) has another length than twice `nodes`', or a length exceeds `i32::MAX`
    /// (host-side checks; the runtime's buffers pass).
    pub fn new(
        nodes: ArrayView<BvhNode, 1>,
        parents: ArrayView<i32, 1>,
        prim_ids: ArrayView<i32, 1>,
    ) -> BvhTree {
        assert_eq!(
            2 * nodes.len(),
            parents.len(),
            "bvh: a parent link and an escape per node"
        );
        assert!(nodes.len() <= i32::MAX as usize && prim_ids.len() <= i32::MAX as usize);
        let (kernel, arg) = nodes.names();
        // SAFETY: views address their elements (ArrayView::new's contract), contiguous as
        // checked, for as long as the launch uses them.
        unsafe {
            BvhTree::from_raw(
                contiguous_ptr(&nodes, "bvh nodes"),
                contiguous_ptr(&parents, "bvh parents"),
                nodes.len() as i32,
                contiguous_ptr(&prim_ids, "bvh prim_ids"),
                prim_ids.len() as i32,
                kernel,
                arg,
            )
        }
    }

    /// The empty tree (module docs), for adjoint placeholders.
    pub fn empty(kernel: &'static str, arg: &'static str) -> BvhTree {
        static NODE: BvhNode = BvhNode::EMPTY;
        static LINKS: [i32; 2] = [-1, -1];
        // SAFETY: one static node, its parent link and escape, no primitive.
        unsafe {
            BvhTree::from_raw(
                &NODE,
                LINKS.as_ptr(),
                1,
                std::ptr::NonNull::dangling().as_ptr(),
                0,
                kernel,
                arg,
            )
        }
    }

    /// Nodes in the tree.
    pub fn num_nodes(&self) -> usize {
        self.num_nodes as usize
    }

    /// Primitives in the tree (the length of `prim_ids`).
    pub fn num_prims(&self) -> usize {
        self.num_prims as usize
    }

    /// The kernel and parameter names faults carry.
    pub fn names(&self) -> (&'static str, &'static str) {
        (self.kernel, self.arg)
    }

    /// Replaces the names faults carry.
    pub fn set_names(&mut self, kernel: &'static str, arg: &'static str) {
        self.kernel = kernel;
        self.arg = arg;
    }

    /// An out-of-bounds fault of this tree's parameter: `index` against a buffer of `len`.
    #[cold]
    #[inline(never)]
    pub fn fault(&self, index: i128, len: usize) -> Box<Fault> {
        Fault::new(
            self.kernel,
            FaultKind::OutOfBounds {
                arg: self.arg,
                index: vec![index],
                shape: vec![len],
            },
        )
    }

    /// Node `i`, or a fault when `i` is outside the nodes.
    #[inline(always)]
    pub fn node(&self, i: i32) -> KResult<BvhNode> {
        if (i as u32) < self.num_nodes as u32 {
            // SAFETY: in bounds (from_raw's contract).
            Ok(unsafe { self.nodes.add(i as usize).read() })
        } else {
            Err(self.fault(i as i128, self.num_nodes as usize))
        }
    }

    /// The parent of node `i` (-1 for the root), or a fault when `i` is outside the nodes.
    #[inline(always)]
    pub fn parent(&self, i: i32) -> KResult<i32> {
        if (i as u32) < self.num_nodes as u32 {
            // SAFETY: in bounds (from_raw's contract).
            Ok(unsafe { self.parents.add(i as usize).read() })
        } else {
            Err(self.fault(i as i128, self.num_nodes as usize))
        }
    }

    /// The node a left-first traversal visits after node `i`'s subtree (module docs), `None`
    /// at the end (a negative escape). `i` is a node the caller read; the escape itself is
    /// checked when its node is read.
    #[inline(always)]
    fn escape(&self, i: i32) -> Option<i32> {
        if (i as u32) >= self.num_nodes as u32 {
            return None; // not a node: callers pass nodes they read, so never taken
        }
        // SAFETY: i is a node, and the links hold 2 * num_nodes entries (from_raw's contract).
        let e = unsafe {
            self.parents
                .add(self.num_nodes as usize + i as usize)
                .read()
        };
        (e >= 0).then_some(e)
    }

    /// The primitive at position `k` of `prim_ids`, or a fault when `k`, or the id read, is
    /// outside `0..num_prims`.
    #[inline(always)]
    pub fn prim(&self, k: i32) -> KResult<i32> {
        if (k as u32) >= self.num_prims as u32 {
            return Err(self.fault(k as i128, self.num_prims as usize));
        }
        // SAFETY: in bounds (from_raw's contract).
        let id = unsafe { self.prim_ids.add(k as usize).read() };
        if (id as u32) < self.num_prims as u32 {
            Ok(id)
        } else {
            Err(self.fault(id as i128, self.num_prims as usize))
        }
    }

    /// A leaf's range, checked against `prim_ids`.
    #[inline(always)]
    fn leaf_range(&self, n: &BvhNode) -> KResult<(i32, i32)> {
        let (start, end) = n.leaf_range();
        if end > self.num_prims {
            return Err(self.fault(end as i128 - 1, self.num_prims as usize));
        }
        // start >= 0 always (the complement of a negative left); an empty range is fine.
        Ok((start, end))
    }

    /// The most moves a traversal takes (module docs).
    #[inline(always)]
    fn max_steps(&self) -> u32 {
        (2 * self.num_nodes as i64 + 2).min(u32::MAX as i64) as u32
    }
}

/// The escapes of a tree's nodes (module docs): for each node, the node a left-first traversal
/// visits after its subtree, -1 for none. What every builder appends to its parent links.
/// Nodes the traversal from the root never reaches (the children of an LBVH subtree made one
/// leaf) get -1. A child index outside the nodes is skipped (a builder's trees have none).
pub fn preorder_escapes(nodes: &[BvhNode]) -> Vec<i32> {
    let mut escapes = vec![-1; nodes.len()];
    // (node, its escape): a left child escapes to its right sibling, a right child where its
    // parent does. At most one entry per node of a tree (each node has one parent), and the
    // pushes are bounded by the nodes' count even for a corrupt one.
    let mut todo = vec![(0usize, -1i32)];
    let mut visited = 0usize;
    while let Some((i, e)) = todo.pop() {
        if i >= nodes.len() || visited == nodes.len() {
            continue;
        }
        visited += 1;
        escapes[i] = e;
        let n = &nodes[i];
        if !n.is_leaf() {
            todo.push((n.right as usize, e));
            todo.push((n.left as usize, n.right));
        }
    }
    escapes
}

/// A built BVH as a kernel thread sees it: its [`BvhTree`] and the primitives' boxes (the
/// user's `lowers` and `uppers`, which the tree was built or refit from, one per primitive).
/// `Copy`, owns nothing; 80 bytes, kept small because every query step takes it by value (a
/// view much larger is copied with a `memcpy` per step, see `HashGridView`).
#[derive(Clone, Copy, Debug)]
pub struct BvhView {
    tree: BvhTree,
    lowers: *const Vec3,
    uppers: *const Vec3,
}

#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<BvhView>() == 80);

// SAFETY: read-only pointers into buffers the runtime keeps alive for the whole launch.
unsafe impl Send for BvhView {}
unsafe impl Sync for BvhView {}

impl BvhView {
    /// A view of a built tree and the boxes it was built over.
    ///
    /// # Panics
    /// When `lowers` or `uppers` is not contiguous or their lengths differ from the tree's
    /// primitive count (host-side checks).
    pub fn new(tree: BvhTree, lowers: ArrayView<Vec3, 1>, uppers: ArrayView<Vec3, 1>) -> Self {
        assert!(
            lowers.len() == tree.num_prims() && uppers.len() == tree.num_prims(),
            "bvh: {} lowers and {} uppers for {} primitives",
            lowers.len(),
            uppers.len(),
            tree.num_prims()
        );
        BvhView {
            tree,
            lowers: contiguous_ptr(&lowers, "bvh lowers"),
            uppers: contiguous_ptr(&uppers, "bvh uppers"),
        }
    }

    /// A view over raw box buffers.
    ///
    /// # Safety
    /// `lowers` and `uppers` must address `tree.num_prims()` valid elements each, alive and
    /// unchanged while the view is used.
    pub unsafe fn from_raw(tree: BvhTree, lowers: *const Vec3, uppers: *const Vec3) -> Self {
        BvhView {
            tree,
            lowers,
            uppers,
        }
    }

    /// The empty tree: what an adjoint's placeholder for a BVH value holds; a query finds
    /// nothing.
    pub fn empty() -> Self {
        let none = std::ptr::NonNull::<Vec3>::dangling().as_ptr();
        BvhView {
            tree: BvhTree::empty("bvh", "bvh"),
            lowers: none,
            uppers: none,
        }
    }

    /// The tree.
    pub fn tree(&self) -> &BvhTree {
        &self.tree
    }

    /// The box of primitive `id` (an id the tree's [`BvhTree::prim`] checked).
    #[inline(always)]
    fn prim_box(&self, id: i32) -> (Vec3, Vec3) {
        debug_assert!((id as u32) < self.tree.num_prims as u32);
        // SAFETY: `id` is below the primitive count (checked by `prim`), which `new` checked
        // both buffers hold.
        unsafe {
            (
                self.lowers.add(id as usize).read(),
                self.uppers.add(id as usize).read(),
            )
        }
    }
}

/// Where a left-first traversal stands: shared by every iterating query (the BVH's and the
/// mesh's). 20 bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct Walk {
    /// The current leaf (the node the next primitive comes from), [`Walk::START`] before the
    /// root, [`Walk::END`] once done.
    node: i32,
    /// The next position in `prim_ids` within the current leaf, and the leaf's end.
    next: i32,
    end: i32,
    /// The current primitive (-1 before the first and once done).
    item: i32,
    /// Moves taken (bounded, see the module docs).
    steps: u32,
}

impl Default for Walk {
    fn default() -> Self {
        Walk::start()
    }
}

impl Walk {
    const START: i32 = -2;
    const END: i32 = -1;

    /// Before the root.
    pub fn start() -> Walk {
        Walk {
            node: Walk::START,
            next: 0,
            end: 0,
            item: -1,
            steps: 0,
        }
    }

    /// Whether the walk is over (or has not produced its first primitive yet).
    #[inline(always)]
    pub fn done(&self) -> bool {
        self.item < 0
    }

    /// The current primitive.
    #[inline(always)]
    pub fn item(&self) -> i32 {
        self.item
    }

    /// Advances to the next primitive that `prim_test` accepts, in a leaf whose box and whose
    /// ancestors' boxes `node_test` accepts; or to the end. Once done it stays done.
    #[inline(always)]
    pub fn next(
        mut self,
        tree: &BvhTree,
        node_test: impl Fn(Vec3, Vec3) -> bool,
        mut prim_test: impl FnMut(i32) -> KResult<bool>,
    ) -> KResult<Walk> {
        loop {
            while self.next < self.end {
                let id = tree.prim(self.next)?;
                self.next += 1;
                if prim_test(id)? {
                    self.item = id;
                    return Ok(self);
                }
            }
            // The current leaf is finished: its escape (it was read, so it is a node).
            let mut n = match self.node {
                Walk::START => Some(0),
                Walk::END => None,
                c => tree.escape(c),
            };
            // Down from `n` to the next accepted leaf, past rejected subtrees by their escapes.
            loop {
                let Some(i) = n else {
                    self.node = Walk::END;
                    self.next = 0;
                    self.end = 0;
                    self.item = -1;
                    return Ok(self);
                };
                self.steps += 1;
                if self.steps > tree.max_steps() {
                    n = None;
                    continue;
                }
                let node = tree.node(i)?;
                if !node_test(node.lower(), node.upper()) {
                    n = tree.escape(i);
                } else if node.is_leaf() {
                    let (start, end) = tree.leaf_range(&node)?;
                    self.node = i;
                    self.next = start;
                    self.end = end;
                    break;
                } else {
                    n = Some(node.left);
                }
            }
        }
    }
}

/// The state of a box query ([`bvh_query_aabb`]): the query box and a [`Walk`]. 44 bytes
/// (Warp's `bvh_query_t` carries a 32-entry stack and the whole BVH: about 250).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct BvhQueryAabb {
    lower: Vec3,
    upper: Vec3,
    walk: Walk,
}

const _: () = assert!(std::mem::size_of::<BvhQueryAabb>() == 44);

/// Starts a query for the primitives whose boxes overlap `[lower, upper]` (touching counts,
/// Warp's `bvh_query_aabb`); advance it with [`bvh_query_aabb_next`]. Each such primitive is
/// yielded exactly once, in no particular order; an inverted or NaN query box yields none.
#[inline(always)]
pub fn bvh_query_aabb(_bvh: BvhView, lower: Vec3, upper: Vec3) -> KResult<BvhQueryAabb> {
    Ok(BvhQueryAabb {
        lower,
        upper,
        walk: Walk::start(),
    })
}

/// The box query advanced to its next primitive, or to its end (then
/// [`bvh_query_aabb_done`]). Once done it stays done.
#[inline(always)]
pub fn bvh_query_aabb_next(bvh: BvhView, mut q: BvhQueryAabb) -> KResult<BvhQueryAabb> {
    let (lo, hi) = (q.lower, q.upper);
    q.walk = q.walk.next(
        &bvh.tree,
        |l, u| aabb_overlap(l, u, lo, hi),
        |id| {
            let (l, u) = bvh.prim_box(id);
            Ok(aabb_overlap(l, u, lo, hi))
        },
    )?;
    Ok(q)
}

/// Whether the box query has no more primitives.
#[inline(always)]
pub fn bvh_query_aabb_done(q: BvhQueryAabb) -> bool {
    q.walk.done()
}

/// The box query's current primitive, an index into the boxes the BVH was built over.
#[inline(always)]
pub fn bvh_query_aabb_item(q: BvhQueryAabb) -> i32 {
    q.walk.item()
}

/// The state of a ray query ([`bvh_query_ray`]): the ray's start, `1 / dir`, and a [`Walk`].
/// 44 bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct BvhQueryRay {
    start: Vec3,
    inv_dir: Vec3,
    walk: Walk,
}

const _: () = assert!(std::mem::size_of::<BvhQueryRay>() == 44);

/// Starts a query for the primitives whose boxes the ray `start + t * dir`, `t >= 0`, meets
/// (touching counts; Warp's `bvh_query_ray`); advance it with [`bvh_query_ray_next`]. Each
/// such primitive is yielded once, in no particular order (not sorted by `t`). Zero
/// direction components are handled (the ray is parallel to those slabs: see
/// [`intersect_ray_aabb`]); NaN yields nothing.
#[inline(always)]
pub fn bvh_query_ray(_bvh: BvhView, start: Vec3, dir: Vec3) -> KResult<BvhQueryRay> {
    Ok(BvhQueryRay {
        start,
        inv_dir: ray_inv_dir(dir),
        walk: Walk::start(),
    })
}

/// The ray query advanced to its next primitive, or to its end (then
/// [`bvh_query_ray_done`]). Once done it stays done.
#[inline(always)]
pub fn bvh_query_ray_next(bvh: BvhView, mut q: BvhQueryRay) -> KResult<BvhQueryRay> {
    let (o, inv) = (q.start, q.inv_dir);
    q.walk = q.walk.next(
        &bvh.tree,
        |l, u| intersect_ray_aabb(o, inv, l, u).is_some(),
        |id| {
            let (l, u) = bvh.prim_box(id);
            Ok(intersect_ray_aabb(o, inv, l, u).is_some())
        },
    )?;
    Ok(q)
}

/// Whether the ray query has no more primitives.
#[inline(always)]
pub fn bvh_query_ray_done(q: BvhQueryRay) -> bool {
    q.walk.done()
}

/// The ray query's current primitive, an index into the boxes the BVH was built over.
#[inline(always)]
pub fn bvh_query_ray_item(q: BvhQueryRay) -> i32 {
    q.walk.item()
}

/// A best-first search of a tree ([`walk_ordered`]): a cost per primitive, minimised, and a
/// lower bound of it per box.
pub(crate) trait OrderedSearch {
    /// A lower bound of the cost of any primitive inside the box (NaN counts as +inf: never
    /// entered).
    fn node_key(&self, lower: Vec3, upper: Vec3) -> f32;
    /// The best cost so far: a box is entered only when its key is strictly below it. It
    /// never rises during a walk (the walk relies on it: see [`walk_ordered`]).
    fn bound(&self) -> f32;
    /// Tests the primitive at position `k` of the tree's `prim_ids` (lowering the bound when
    /// it improves on it). `k` lies in the leaf's range, which the walk checked to be within
    /// `[0, num_prims)`; the primitive's id is `tree.prim(k)` (checked), which a search reads
    /// only where it needs it (a mesh's searches read the triangle at `k` from the mesh's
    /// leaf-ordered copy and map only their result to a face).
    fn visit(&mut self, k: i32) -> KResult<()>;
}

/// A key with NaN mapped to +inf, so that keys are totally ordered.
#[inline(always)]
fn key_of<S: OrderedSearch>(s: &S, n: &BvhNode) -> f32 {
    let k = s.node_key(n.lower(), n.upper());
    if k < f32::INFINITY {
        k
    } else {
        f32::INFINITY
    }
}

/// The children of internal node `n` nearest first (by key; ties to the left child): each as
/// its index, key and node.
#[inline(always)]
fn ordered_children<S: OrderedSearch>(
    tree: &BvhTree,
    s: &S,
    n: &BvhNode,
) -> KResult<[(i32, f32, BvhNode); 2]> {
    let (l, r) = (tree.node(n.left)?, tree.node(n.right)?);
    let (kl, kr) = (key_of(s, &l), key_of(s, &r));
    Ok(if kr < kl {
        [(n.right, kr, r), (n.left, kl, l)]
    } else {
        [(n.left, kl, l), (n.right, kr, r)]
    })
}

/// Entries of [`walk_ordered`]'s stack of farther children (a ring: when a traversal goes
/// deeper than this, the oldest entries, those nearest the root, are dropped and found again
/// by climbing the parent links).
pub(crate) const ORDERED_STACK: usize = 32;

/// Visits the leaves of `tree` nearest first, skipping every box whose key is not below the
/// search's current bound: the traversal of Warp's closest-point and closest-hit queries.
/// Going down, the nearer child is entered first and the farther one, when it passes too, is
/// pushed with its key; a finished subtree pops the next entry and enters it when its key is
/// still below the bound as it then stands ([`OrderedSearch::bound`] never rises, so an entry
/// that failed when pushed would fail when popped). The stack is a ring of
/// [`ORDERED_STACK`] entries; entries dropped from it when a tree is deeper are found again
/// by the stackless climb: from the finished node up the parent links to the nearest
/// ancestor left from its nearer child, whose farther child is tested then. Both orders are
/// the same, depth first and nearest child first. At most `2 * nodes + 2` moves (a descent
/// or a climb step), as every traversal (module docs).
pub(crate) fn walk_ordered<S: OrderedSearch>(tree: &BvhTree, s: &mut S) -> KResult<()> {
    let mut node = tree.node(0)?;
    if !(key_of(s, &node) < s.bound()) {
        return Ok(());
    }
    let max = tree.max_steps();
    let mut steps = 0u32;
    let mut stack = [(0i32, 0f32); ORDERED_STACK];
    let mut held = 0usize; // entries in the ring
    let mut head = 0usize; // where the next push goes
    let mut dropped = false;
    // `node` is node `cur`: a child entered goes on with the node read to order it.
    let mut cur = 0i32;
    'down: loop {
        steps += 1;
        if steps > max {
            return Ok(());
        }
        if node.is_leaf() {
            let (start, end) = tree.leaf_range(&node)?;
            for k in start..end {
                s.visit(k)?;
            }
        } else {
            // ka <= kb (keys are totally ordered, NaN counting as +inf): when the nearer
            // child fails the bound the farther fails too, so there is no case of entering
            // the farther alone.
            let [(a, ka, an), (b, kb, _)] = ordered_children(tree, s, &node)?;
            if ka < s.bound() {
                if kb < s.bound() {
                    stack[head] = (b, kb);
                    head = (head + 1) % ORDERED_STACK;
                    dropped |= held == ORDERED_STACK;
                    held = (held + 1).min(ORDERED_STACK);
                }
                (cur, node) = (a, an);
                continue 'down;
            }
        }
        // `cur` is finished: the next entry still below the bound.
        while held > 0 {
            head = (head + ORDERED_STACK - 1) % ORDERED_STACK;
            held -= 1;
            let (n, k) = stack[head];
            if k < s.bound() {
                (cur, node) = (n, tree.node(n)?);
                continue 'down;
            }
        }
        if !dropped {
            return Ok(());
        }
        // Entries were dropped: climb to the next subtree to enter.
        let mut c = cur;
        loop {
            steps += 1;
            if steps > max {
                return Ok(());
            }
            let p = tree.parent(c)?;
            if p < 0 {
                return Ok(());
            }
            let pn = tree.node(p)?;
            if pn.is_leaf() {
                return Ok(());
            }
            let [(a, _, _), (b, kb, bn)] = ordered_children(tree, s, &pn)?;
            if c == a && b != a {
                if kb < s.bound() {
                    (cur, node) = (b, bn);
                    continue 'down;
                }
            } else if c != b {
                return Ok(()); // a parent link that does not lead back: corrupt
            }
            c = p;
        }
    }
}

// A BVH carries no gradient: the placeholder is the empty tree; query states carry none
// either (what depends on them, the primitives, are indices).
no_gradient!(
    BvhView = BvhView::empty(),
    BvhQueryAabb = BvhQueryAabb::default(),
    BvhQueryRay = BvhQueryRay::default(),
);

#[cfg(test)]
pub(crate) mod tests {
    use super::super::geometry::tests::Rng;
    use super::*;

    /// A tree built by the simplest correct method (median split on the longest axis of the
    /// centroids, leaves of up to `leaf` primitives), in the shared layout: a reference for
    /// the queries, independent of warp-runtime's SAH builder (which its own tests check).
    pub(crate) struct Built {
        pub nodes: Vec<BvhNode>,
        pub parents: Vec<i32>,
        pub prim_ids: Vec<i32>,
        pub lowers: Vec<Vec3>,
        pub uppers: Vec<Vec3>,
    }

    impl Built {
        pub fn new(lowers: &[Vec3], uppers: &[Vec3], leaf: usize) -> Built {
            let mut b = Built {
                nodes: Vec::new(),
                parents: Vec::new(),
                prim_ids: (0..lowers.len() as i32).collect(),
                lowers: lowers.to_vec(),
                uppers: uppers.to_vec(),
            };
            if lowers.is_empty() {
                b.nodes.push(BvhNode::EMPTY);
                b.parents.push(-1);
            } else {
                b.build(0, lowers.len(), -1, leaf);
            }
            b.parents.extend(preorder_escapes(&b.nodes));
            b
        }

        /// The escape links (the second half of `parents`).
        pub fn escapes(&mut self) -> &mut [i32] {
            let n = self.nodes.len();
            &mut self.parents[n..]
        }

        fn build(&mut self, start: usize, end: usize, parent: i32, leaf: usize) -> i32 {
            let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
            for &i in &self.prim_ids[start..end] {
                lo = lo.min(self.lowers[i as usize]);
                hi = hi.max(self.uppers[i as usize]);
            }
            let me = self.nodes.len() as i32;
            self.nodes
                .push(BvhNode::leaf(lo, hi, start as i32, end as i32));
            self.parents.push(parent);
            if end - start <= leaf {
                return me;
            }
            let c = |i: i32| (self.lowers[i as usize] + self.uppers[i as usize]) * 0.5;
            let (mut clo, mut chi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
            for &i in &self.prim_ids[start..end] {
                clo = clo.min(c(i));
                chi = chi.max(c(i));
            }
            let axis = (chi - clo).max_position();
            let (l, u) = (self.lowers.clone(), self.uppers.clone());
            self.prim_ids[start..end].sort_by(|a, b| {
                let (ca, cb) = (
                    (l[*a as usize] + u[*a as usize])[axis],
                    (l[*b as usize] + u[*b as usize])[axis],
                );
                ca.total_cmp(&cb)
            });
            let mid = (start + end) / 2;
            let left = self.build(start, mid, me, leaf);
            let right = self.build(mid, end, me, leaf);
            self.nodes[me as usize] = BvhNode::internal(lo, hi, left, right);
            me
        }

        pub fn tree(&mut self) -> BvhTree {
            let v = |d: &mut Vec<i32>| unsafe {
                ArrayView::new(d.as_mut_ptr(), [d.len()], [1], "k", "bvh")
            };
            let nodes = unsafe {
                ArrayView::new(self.nodes.as_mut_ptr(), [self.nodes.len()], [1], "k", "bvh")
            };
            BvhTree::new(nodes, v(&mut self.parents), v(&mut self.prim_ids))
        }

        pub fn view(&mut self) -> BvhView {
            let tree = self.tree();
            let v = |d: &mut Vec<Vec3>| unsafe {
                ArrayView::new(d.as_mut_ptr(), [d.len()], [1], "k", "bvh")
            };
            BvhView::new(tree, v(&mut self.lowers), v(&mut self.uppers))
        }
    }

    pub(crate) fn random_boxes(
        rng: &mut Rng,
        n: usize,
        extent: f32,
        size: f32,
    ) -> (Vec<Vec3>, Vec<Vec3>) {
        let mut lo = Vec::new();
        let mut hi = Vec::new();
        for _ in 0..n {
            let c = rng.v(-extent, extent);
            let h = rng.v(0.0, size);
            lo.push(c - h);
            hi.push(c + h);
        }
        (lo, hi)
    }

    fn aabb_items(b: BvhView, lo: Vec3, hi: Vec3) -> Vec<i32> {
        let mut q = bvh_query_aabb(b, lo, hi).unwrap();
        let mut out = Vec::new();
        loop {
            q = bvh_query_aabb_next(b, q).unwrap();
            if bvh_query_aabb_done(q) {
                break;
            }
            out.push(bvh_query_aabb_item(q));
        }
        assert!(
            bvh_query_aabb_done(bvh_query_aabb_next(b, q).unwrap()),
            "done stays done"
        );
        out.sort_unstable();
        out
    }

    fn ray_items(b: BvhView, o: Vec3, d: Vec3) -> Vec<i32> {
        let mut q = bvh_query_ray(b, o, d).unwrap();
        let mut out = Vec::new();
        loop {
            q = bvh_query_ray_next(b, q).unwrap();
            if bvh_query_ray_done(q) {
                break;
            }
            out.push(bvh_query_ray_item(q));
        }
        out.sort_unstable();
        out
    }

    #[test]
    fn layout_and_sizes() {
        assert_eq!(std::mem::size_of::<BvhNode>(), 32);
        assert_eq!(std::mem::offset_of!(BvhNode, left), 12);
        assert_eq!(std::mem::offset_of!(BvhNode, upper), 16);
        assert_eq!(std::mem::offset_of!(BvhNode, right), 28);
        assert_eq!(std::mem::size_of::<BvhQueryAabb>(), 44);
        assert_eq!(std::mem::size_of::<BvhQueryRay>(), 44);
        let l = BvhNode::leaf(Vec3::ZERO, Vec3::ONE, 3, 7);
        assert!(l.is_leaf() && l.leaf_range() == (3, 7) && l.left == -4);
        assert!(BvhNode::EMPTY.is_leaf() && BvhNode::EMPTY.leaf_range() == (0, 0));
    }

    #[test]
    fn queries_match_brute_force() {
        let mut rng = Rng(11);
        for (n, leaf) in [
            (1usize, 1usize),
            (2, 1),
            (7, 2),
            (300, 1),
            (1000, 4),
            (513, 3),
        ] {
            let (lo, hi) = random_boxes(&mut rng, n, 10.0, 1.0);
            let mut b = Built::new(&lo, &hi, leaf);
            let v = b.view();
            for _ in 0..200 {
                let c = rng.v(-11.0, 11.0);
                let h = rng.v(0.0, 3.0);
                let got = aabb_items(v, c - h, c + h);
                let want: Vec<i32> = (0..n as i32)
                    .filter(|i| aabb_overlap(lo[*i as usize], hi[*i as usize], c - h, c + h))
                    .collect();
                assert_eq!(got, want);
                let o = rng.v(-15.0, 15.0);
                let mut d = rng.v(-1.0, 1.0);
                if rng.below(3) == 0 {
                    d[rng.below(3)] = 0.0;
                }
                let got = ray_items(v, o, d);
                let inv = ray_inv_dir(d);
                let want: Vec<i32> = (0..n as i32)
                    .filter(|i| {
                        intersect_ray_aabb(o, inv, lo[*i as usize], hi[*i as usize]).is_some()
                    })
                    .collect();
                assert_eq!(got, want);
            }
            // Everything, and nothing.
            let inf = Vec3::splat(f32::INFINITY);
            assert_eq!(aabb_items(v, -inf, inf).len(), n);
            assert!(aabb_items(v, inf, -inf).is_empty());
            assert!(aabb_items(v, Vec3::NAN, inf).is_empty());
            assert!(ray_items(v, Vec3::NAN, Vec3::X).is_empty());
        }
    }

    #[test]
    fn empty_tree_and_extreme_coordinates() {
        let mut b = Built::new(&[], &[], 1);
        let v = b.view();
        let inf = Vec3::splat(f32::INFINITY);
        assert!(aabb_items(v, -inf, inf).is_empty());
        assert!(ray_items(v, Vec3::ZERO, Vec3::X).is_empty());
        assert!(aabb_items(BvhView::empty(), -inf, inf).is_empty());
        // Huge and tiny boxes.
        for k in [1e30f32, 1e-30] {
            let mut rng = Rng(3);
            let (lo, hi) = random_boxes(&mut rng, 200, 10.0, 1.0);
            let (lo, hi): (Vec<Vec3>, Vec<Vec3>) = (
                lo.iter().map(|x| *x * k).collect(),
                hi.iter().map(|x| *x * k).collect(),
            );
            let mut b = Built::new(&lo, &hi, 2);
            let v = b.view();
            for _ in 0..50 {
                let c = rng.v(-10.0, 10.0) * k;
                let h = rng.v(0.0, 3.0) * k;
                let want: Vec<i32> = (0..200)
                    .filter(|i| aabb_overlap(lo[*i as usize], hi[*i as usize], c - h, c + h))
                    .collect();
                assert_eq!(aabb_items(v, c - h, c + h), want);
                let (o, d) = (rng.v(-15.0, 15.0) * k, rng.v(-1.0, 1.0));
                let inv = ray_inv_dir(d);
                let want: Vec<i32> = (0..200)
                    .filter(|i| {
                        intersect_ray_aabb(o, inv, lo[*i as usize], hi[*i as usize]).is_some()
                    })
                    .collect();
                assert_eq!(ray_items(v, o, d), want);
            }
        }
    }

    /// A deep, degenerate tree (a caterpillar of `n` levels, deeper than any fixed stack):
    /// node 2k is internal with children 2k+1 (the leaf of primitive k, box [k, k + 0.5]) and
    /// 2k+2; the last node is a leaf.
    fn caterpillar(n: usize) -> Built {
        let lo: Vec<Vec3> = (0..n).map(|i| Vec3::splat(i as f32)).collect();
        let hi: Vec<Vec3> = lo.iter().map(|x| *x + 0.5).collect();
        let mut nodes = Vec::new();
        let mut parents = Vec::new();
        for k in 0..n {
            let (l, u) = (lo[k], hi[n - 1]);
            if k + 1 < n {
                nodes.push(BvhNode::internal(l, u, 2 * k as i32 + 1, 2 * k as i32 + 2));
                nodes.push(BvhNode::leaf(lo[k], hi[k], k as i32, k as i32 + 1));
                parents.push(if k == 0 { -1 } else { 2 * k as i32 - 2 });
                parents.push(2 * k as i32);
            } else {
                nodes.push(BvhNode::leaf(lo[k], hi[k], k as i32, k as i32 + 1));
                parents.push(2 * k as i32 - 2);
            }
        }
        parents.extend(preorder_escapes(&nodes));
        Built {
            nodes,
            parents,
            prim_ids: (0..n as i32).collect(),
            lowers: lo,
            uppers: hi,
        }
    }

    /// The stackless walk still finds everything in a tree of 2000 levels.
    #[test]
    fn deep_tree() {
        let n = 2000;
        let mut b = caterpillar(n);
        let v = b.view();
        let inf = Vec3::splat(f32::INFINITY);
        assert_eq!(aabb_items(v, -inf, inf), (0..n as i32).collect::<Vec<_>>());
        assert_eq!(
            aabb_items(v, Vec3::splat(1500.2), Vec3::splat(1500.3)),
            vec![1500]
        );
        assert_eq!(ray_items(v, Vec3::splat(-1.0), Vec3::ONE).len(), n);
    }

    /// A search recording its visits: keys are squared distances from `p`; with `prune` the
    /// bound is the best primitive distance so far (a closest-point search), without it the
    /// bound stays at `f32::MAX` and every box is entered.
    struct Recorder<'a> {
        b: &'a Built,
        p: Vec3,
        prune: bool,
        best: f32,
        seen: Vec<i32>,
    }

    impl OrderedSearch for Recorder<'_> {
        fn node_key(&self, lower: Vec3, upper: Vec3) -> f32 {
            super::super::geometry::aabb_distance_sq(self.p, lower, upper)
        }
        fn bound(&self) -> f32 {
            self.best
        }
        fn visit(&mut self, k: i32) -> KResult<()> {
            let id = self.b.prim_ids[k as usize];
            self.seen.push(id);
            let (lo, hi) = (self.b.lowers[id as usize], self.b.uppers[id as usize]);
            let d = self.node_key(lo, hi);
            if self.prune && d < self.best {
                self.best = d;
            }
            Ok(())
        }
    }

    /// The order [`walk_ordered`] must produce, by recursion: nearest child first (ties to
    /// the left), each child entered when its key is below the bound as it stands then.
    fn reference_walk(b: &Built, r: &mut Recorder, i: i32) {
        let n = b.nodes[i as usize];
        if n.is_leaf() {
            let (start, end) = n.leaf_range();
            for k in start..end {
                r.visit(k).unwrap();
            }
            return;
        }
        let key = |c: i32| r.node_key(b.nodes[c as usize].lower(), b.nodes[c as usize].upper());
        let (kl, kr) = (key(n.left), key(n.right));
        let order = if kr < kl {
            [(n.right, kr), (n.left, kl)]
        } else {
            [(n.left, kl), (n.right, kr)]
        };
        for (c, k) in order {
            if k < r.bound() {
                reference_walk(b, r, c);
            }
        }
    }

    /// The ordered walk against the recursion, on balanced trees and on caterpillars far
    /// deeper than its ring (every entry dropped and found again by climbing): the same
    /// visits in the same order, with and without pruning.
    #[test]
    fn ordered_walk_matches_recursion_at_any_depth() {
        let mut rng = Rng(11);
        let (lo, hi) = random_boxes(&mut rng, 500, 10.0, 1.0);
        let mut trees = vec![Built::new(&lo, &hi, 1), Built::new(&lo, &hi, 4)];
        trees.push(caterpillar(200));
        trees.push(caterpillar(ORDERED_STACK + 1));
        trees.push(caterpillar(ORDERED_STACK + 2));
        for mut b in trees {
            let tree = *b.view().tree();
            let n = b.lowers.len() as f32;
            let mut points: Vec<Vec3> = (0..40).map(|_| rng.v(-12.0, 12.0)).collect();
            points.extend([
                Vec3::splat(-50.0),
                Vec3::splat(n + 50.0),
                Vec3::splat(n * 0.5),
            ]);
            for p in points {
                for prune in [false, true] {
                    let fresh = || Recorder {
                        b: &b,
                        p,
                        prune,
                        best: f32::MAX,
                        seen: Vec::new(),
                    };
                    let mut got = fresh();
                    walk_ordered(&tree, &mut got).unwrap();
                    let mut want = fresh();
                    reference_walk(&b, &mut want, 0);
                    assert_eq!(got.seen, want.seen, "p {p}, prune {prune}");
                    if !prune {
                        assert_eq!(got.seen.len(), b.lowers.len());
                    }
                }
            }
        }
    }

    #[test]
    fn corrupt_trees_fault_or_end() {
        let mut rng = Rng(5);
        let (lo, hi) = random_boxes(&mut rng, 64, 10.0, 1.0);
        let inf = Vec3::splat(f32::INFINITY);
        let all = |b: &mut Built| -> KResult<usize> {
            let v = b.view();
            let mut q = bvh_query_aabb(v, -inf, inf)?;
            let mut n = 0;
            loop {
                q = bvh_query_aabb_next(v, q)?;
                if bvh_query_aabb_done(q) {
                    return Ok(n);
                }
                n += 1;
            }
        };
        // A child out of range, a leaf range past the ids, a prim id out of range: faults. (A
        // left child is where the walk goes down; it reaches right children by escapes.)
        let mut b = Built::new(&lo, &hi, 1);
        b.nodes[0].left = 10_000;
        let e = all(&mut b).unwrap_err();
        assert!(e.to_string().contains("argument `bvh`"), "{e}");
        let mut b = Built::new(&lo, &hi, 4);
        let leaf = b.nodes.iter().position(|n| n.is_leaf()).unwrap();
        b.nodes[leaf].right = 65;
        assert!(all(&mut b).is_err());
        let mut b = Built::new(&lo, &hi, 4);
        b.prim_ids[3] = 64;
        assert!(all(&mut b).is_err());
        b.prim_ids[3] = -1;
        assert!(all(&mut b).is_err());
        // An escape outside the nodes: the fault of reading its node.
        let mut b = Built::new(&lo, &hi, 1);
        let first_leaf = b.nodes.iter().position(|n| n.is_leaf()).unwrap();
        b.escapes()[first_leaf] = 10_000;
        let e = all(&mut b).unwrap_err();
        assert!(e.to_string().contains("argument `bvh`"), "{e}");
        // A cycle (a child pointing back to the root), escapes all leading back to the root,
        // a leaf escaping to itself: each ends within the move budget (2 * nodes + 2 moves,
        // each entering one node, so at most nodes + 1 leaves and as many primitives).
        let budget = 2 * (2 * 64 - 1) + 2;
        let mut b = Built::new(&lo, &hi, 1);
        let internal = b.nodes.iter().rposition(|n| !n.is_leaf()).unwrap();
        b.nodes[internal].left = 0;
        assert!(all(&mut b).unwrap() <= budget);
        let mut b = Built::new(&lo, &hi, 1);
        for e in b.escapes().iter_mut() {
            *e = 0;
        }
        assert!(all(&mut b).unwrap() <= budget);
        let mut b = Built::new(&lo, &hi, 1);
        let last_leaf = b.nodes.iter().rposition(|n| n.is_leaf()).unwrap();
        b.escapes()[last_leaf] = last_leaf as i32;
        assert!(all(&mut b).unwrap() <= budget);
        // The parent links play no part in the iterating walk: all wrong, the same result.
        let mut b = Built::new(&lo, &hi, 1);
        for p in b.parents.iter_mut().take(b.nodes.len()).skip(1) {
            *p = 0;
        }
        assert_eq!(all(&mut b).unwrap(), 64);
        // Every node a copy of the root: ends within the move budget.
        let mut b = Built::new(&lo, &hi, 1);
        let root = b.nodes[0];
        for n in b.nodes.iter_mut() {
            *n = root;
        }
        let _ = all(&mut b);
    }
}

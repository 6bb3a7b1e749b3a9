//! [`Bvh`]: Warp's bounding volume hierarchy over boxes. `Bvh::new(&lowers, &uppers)` builds a
//! tree over the boxes `[lowers[i], uppers[i]]` on the arrays' device; kernels take it as a
//! parameter `bvh: Bvh` and iterate `for i in bvh_query_aabb(bvh, lo, hi)` or
//! `for i in bvh_query_ray(bvh, start, dir)` over the boxes that overlap (see
//! `warp_core::objects::bvh` for the node layout and the stackless traversal, which the CUDA
//! library mirrors).
//!
//! The BVH keeps the user's `lowers` and `uppers` arrays (handles sharing their memory, as
//! Warp's `bvh.lowers`): a kernel may move the boxes, then [`Bvh::refit`] recomputes the
//! tree's boxes from them, keeping its shape.
//!
//! # Where the tree is built
//!
//! Every device builds on the host, with the binned SAH builder of
//! [`bvh_build`](super::bvh_build): on a GPU the boxes are copied to the host, the tree built
//! there and its three buffers uploaded; a refit likewise (the boxes down, the nodes up). This
//! is the interim path: a GPU LBVH build and refit (kernels of `wp_bvh.h`, through
//! `dispatch::object_step` like the hash grid's) is a separate task and changes nothing here
//! but the two build functions of `Tree`. The host keeps a copy of the tree, so a GPU refit
//! reads back only the boxes.
//!
//! Copy-on-write: a clone (what a [`Tape`](crate::Tape) keeps of a launch's BVH) shares the
//! tree; a refit gives the refit BVH a new node buffer, so a recorded launch replays in
//! backward against the tree it ran with. (The boxes themselves are the user's arrays, which a
//! replay reads as they are then, like any array argument.)

use std::sync::Arc;

use glam::{Vec3, Vec4};
use warp_core::objects::bvh::{BvhNode, BvhTree};
use warp_core::objects::BvhView;
use warp_core::ArrayView;

use super::bvh_build::{build_sah, refit as refit_nodes, BuiltBvh};
use super::geometry_abi::{CudaBvh, CudaBvhTree};
use super::lbvh::{self, Lbvh, LbvhTree};
use super::HostObject;
use crate::array::Array;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::ArgCtx;

/// An `InvalidArgument` from `what` (`"Bvh::new"`) about its argument `arg`.
pub(crate) fn bad(what: &str, arg: &str, why: impl std::fmt::Display) -> Error {
    Error::InvalidArgument {
        what: format!("{what}: argument `{arg}` {why}"),
    }
}

/// The most primitives a tree takes (the builder's limit: node indices are `i32`, and a tree
/// has up to `2n - 1` nodes).
pub(crate) const MAX_PRIMS: usize = (i32::MAX / 2) as usize;

/// The index and value of the first non-finite vector of `v`.
pub(crate) fn first_non_finite(v: &[Vec3]) -> Option<(usize, Vec3)> {
    v.iter().position(|p| !p.is_finite()).map(|i| (i, v[i]))
}

/// Checks that `a` (argument `arg` of `what`) is on `device`.
pub(crate) fn same_device<T: crate::array::Element>(
    what: &str,
    arg: &str,
    a: &Array<T>,
    device: &Device,
    other: &str,
) -> Result<()> {
    if a.device() == device {
        return Ok(());
    }
    Err(bad(
        what,
        arg,
        format!(
            "is on device \"{}\" but `{other}` is on \"{}\": all arrays of one object must be \
             on one device",
            a.device().alias(),
            device.alias()
        ),
    ))
}

/// Checks that `a` is contiguous (kernels read the object's arrays as plain runs).
pub(crate) fn contiguous<T: crate::array::Element>(
    what: &str,
    arg: &str,
    a: &Array<T>,
) -> Result<()> {
    if a.is_contiguous() {
        return Ok(());
    }
    Err(bad(
        what,
        arg,
        "is not contiguous (a strided view): pass a contiguous array, which the object keeps \
         and kernels read directly",
    ))
}

/// A built tree on one device.
///
/// Built where its device is: on the CPU by the binned SAH builder (better trees, and the CPU
/// has the cores for it), which keeps a host copy that a refit starts from; on a GPU as a
/// linear BVH by the kernels of `wp_bvh_build.h` (`lbvh.rs`), which never leaves the GPU.
/// `parents` and `prim_ids` never change after a build, so refit trees share them.
pub(crate) struct Tree {
    /// The nodes on the device, two `Vec4`s (32 bytes, 16-aligned) per `BvhNode`.
    nodes: Array<Vec4>,
    parents: Array<i32>,
    prim_ids: Array<i32>,
    num_nodes: usize,
    num_prims: usize,
    /// The host copy of a tree built on the host (`None` for a GPU-built tree).
    host: Option<HostTree>,
    /// A device-built tree's refit scratch, kept between refits.
    scratch: std::sync::Mutex<Option<Lbvh>>,
}

/// The host copy of a host-built tree.
struct HostTree {
    nodes: Vec<BvhNode>,
    parents: Arc<Vec<i32>>,
    prim_ids: Arc<Vec<i32>>,
}

/// The nodes as the device buffer holds them.
fn node_words(nodes: &[BvhNode]) -> &[Vec4] {
    bytemuck::cast_slice(nodes)
}

impl Tree {
    /// A tree over the boxes `[lowers[i], uppers[i]]` (validated by the caller: equal lengths,
    /// finite, at most [`MAX_PRIMS`]), built on the host and uploaded to `device`.
    pub(crate) fn build_on_host(lowers: &[Vec3], uppers: &[Vec3], device: &Device) -> Result<Tree> {
        let BuiltBvh {
            nodes,
            parents,
            prim_ids,
        } = build_sah(lowers, uppers);
        Ok(Tree {
            nodes: Array::from_slice(node_words(&nodes), device)?,
            parents: Array::from_slice(&parents, device)?,
            prim_ids: Array::from_slice(&prim_ids, device)?,
            num_nodes: nodes.len(),
            num_prims: prim_ids.len(),
            host: Some(HostTree {
                nodes,
                parents: Arc::new(parents),
                prim_ids: Arc::new(prim_ids),
            }),
            scratch: Default::default(),
        })
    }

    /// A linear BVH over the boxes (contiguous, equal lengths, at most [`MAX_PRIMS`]: checked
    /// by the caller; non-finite corners give a tree that the caller refuses), with leaves of
    /// up to `leaf_size` boxes, built on their device without leaving it (queued: nothing
    /// waits).
    pub(crate) fn build_on_device(
        lowers: &Array<Vec3>,
        uppers: &Array<Vec3>,
        leaf_size: usize,
    ) -> Result<Tree> {
        let device = lowers.device();
        let n = lowers.len();
        let count = lbvh::node_count(n);
        // The build writes every node, parent and id: no zeroing.
        let tree = Tree {
            nodes: Array::empty(2 * count, device)?,
            parents: Array::empty(count, device)?,
            prim_ids: Array::empty(n, device)?,
            num_nodes: count,
            num_prims: n,
            host: None,
            scratch: Default::default(),
        };
        Lbvh::new(device)?.build(
            lowers,
            uppers,
            &tree.lbvh_buffers(&tree.nodes.reinterpret()?),
            leaf_size,
        )?;
        Ok(tree)
    }

    /// The buffers as the LBVH builder takes them (`nodes`: this tree's or a refit's).
    fn lbvh_buffers<'a>(&'a self, nodes: &'a Array<i32>) -> LbvhTree<'a> {
        LbvhTree {
            nodes,
            parents: &self.parents,
            prim_ids: &self.prim_ids,
        }
    }

    /// This host-built tree's shape with its boxes recomputed on the host from the primitive
    /// boxes (as many as when built): a new node buffer, the parents and primitive ids
    /// shared.
    pub(crate) fn refit_on_host(&self, lowers: &[Vec3], uppers: &[Vec3]) -> Result<Tree> {
        let host = self
            .host
            .as_ref()
            .expect("a tree built on the host refits there");
        debug_assert_eq!(lowers.len(), self.num_prims);
        let mut nodes = host.nodes.clone();
        if self.num_prims == 0 {
            // The empty tree keeps its inverted box.
            nodes = vec![BvhNode::EMPTY];
        } else {
            refit_nodes(&mut nodes, &host.parents, &host.prim_ids, lowers, uppers);
        }
        Ok(Tree {
            nodes: Array::from_slice(node_words(&nodes), self.nodes.device())?,
            parents: self.parents.clone(),
            prim_ids: self.prim_ids.clone(),
            num_nodes: self.num_nodes,
            num_prims: self.num_prims,
            host: Some(HostTree {
                nodes,
                parents: Arc::clone(&host.parents),
                prim_ids: Arc::clone(&host.prim_ids),
            }),
            scratch: Default::default(),
        })
    }

    /// This device-built tree's boxes recomputed on its device from the primitive boxes (as
    /// many as when built; queued): in place when `tree` is not shared (no tape holds a clone:
    /// nothing else can see the change), else into a new node buffer, the parents and
    /// primitive ids shared. The scratch of the refit is kept for the next.
    pub(crate) fn refit_on_device(
        tree: &mut Arc<Tree>,
        lowers: &Array<Vec3>,
        uppers: &Array<Vec3>,
    ) -> Result<()> {
        debug_assert!(tree.host.is_none() && lowers.len() == tree.num_prims);
        if tree.num_prims == 0 {
            return Ok(());
        }
        let device = tree.nodes.device().clone();
        let scratch = tree
            .scratch
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take();
        let mut lbvh = match scratch {
            Some(l) => l,
            None => Lbvh::new(&device)?,
        };
        let result = if let Some(t) = Arc::get_mut(tree) {
            lbvh.refit(lowers, uppers, &t.lbvh_buffers(&t.nodes.reinterpret()?))
        } else {
            let nodes = Array::<Vec4>::empty(tree.nodes.len(), &device)?;
            nodes.copy_from(&tree.nodes)?;
            lbvh.refit(lowers, uppers, &tree.lbvh_buffers(&nodes.reinterpret()?))?;
            *tree = Arc::new(Tree {
                nodes,
                parents: tree.parents.clone(),
                prim_ids: tree.prim_ids.clone(),
                num_nodes: tree.num_nodes,
                num_prims: tree.num_prims,
                host: None,
                scratch: Default::default(),
            });
            Ok(())
        };
        *tree.scratch.lock().unwrap_or_else(|p| p.into_inner()) = Some(lbvh);
        result
    }

    /// Primitives in the tree.
    pub(crate) fn num_prims(&self) -> usize {
        self.num_prims
    }

    /// Nodes in the tree.
    pub(crate) fn num_nodes(&self) -> usize {
        self.num_nodes
    }

    /// The tree on the host: nodes, parents, primitive ids (a GPU-built tree is read back).
    pub(crate) fn host(&self) -> Result<(Vec<BvhNode>, Vec<i32>, Vec<i32>)> {
        if let Some(h) = &self.host {
            return Ok((h.nodes.clone(), h.parents.to_vec(), h.prim_ids.to_vec()));
        }
        let words = self.nodes.to_vec()?;
        Ok((
            bytemuck::cast_slice(&words).to_vec(),
            self.parents.to_vec()?,
            self.prim_ids.to_vec()?,
        ))
    }

    /// The CPU kernels' view of the tree; faults carry `ctx`'s names.
    ///
    /// # Safety
    /// As [`HostObject::cpu_view`]: the tree (its arrays) must outlive the view's use.
    pub(crate) unsafe fn cpu_tree(&self, ctx: &ArgCtx<'_>) -> BvhTree {
        let words = self.nodes.cpu_view(ctx.kernel, ctx.arg);
        let n = self.num_nodes;
        let p0 = words
            .ptr_at(0usize)
            .expect("a tree has at least one node")
            .cast::<BvhNode>();
        // SAFETY: the node buffer holds `n` nodes as `2n` contiguous, 16-aligned `Vec4`s (a
        // `BvhNode` is 32 bytes of plain data, align 4).
        let nodes = unsafe { ArrayView::new(p0, [n], [1], ctx.kernel, ctx.arg) };
        BvhTree::new(
            nodes,
            self.parents.cpu_view(ctx.kernel, ctx.arg),
            self.prim_ids.cpu_view(ctx.kernel, ctx.arg),
        )
    }

    /// The CUDA kernels' view of the tree, for the kernel parameter at index `arg`.
    pub(crate) fn cuda_tree(&self, arg: usize) -> CudaBvhTree {
        // wp_bvh.h loads a node as two 16-byte words.
        debug_assert_eq!(self.nodes.device_address() % 16, 0);
        CudaBvhTree {
            nodes: self.nodes.device_address(),
            parents: self.parents.device_address(),
            prim_ids: self.prim_ids.device_address(),
            num_nodes: self.num_nodes as i32,
            num_prims: self.num_prims as i32,
            arg: arg as i32,
            pad: 0,
        }
    }
}

/// A BVH over boxes on one device (Warp's `wp.Bvh(lowers, uppers)`; the suite
/// `tests/suite/bvh.rs` runs kernels like this one):
///
/// ```ignore
/// use warp_lang as wp;
/// use wp::prelude::*;
///
/// #[wp::kernel]
/// fn count_hits(bvh: Bvh, lo: Array<Vec3>, hi: Array<Vec3>, counts: Array<i32>) {
///     let i = tid();
///     let mut n = 0;
///     for _j in bvh_query_aabb(bvh, lo[i], hi[i]) {
///         n += 1;
///     }
///     counts[i] = n;
/// }
///
/// let dev = wp::cpu();
/// let lowers = wp::Array::from_slice(&[Vec3::ZERO, Vec3::splat(2.0)], &dev).unwrap();
/// let uppers = wp::Array::from_slice(&[Vec3::ONE, Vec3::splat(3.0)], &dev).unwrap();
/// let bvh = wp::Bvh::new(&lowers, &uppers).unwrap();
/// let counts = wp::Array::<i32>::zeros(1, &dev).unwrap();
/// let q = wp::Array::from_slice(&[Vec3::splat(0.5)], &dev).unwrap();
/// let r = wp::Array::from_slice(&[Vec3::splat(2.5)], &dev).unwrap();
/// wp::launch(count_hits, 1, (&bvh, &q, &r, &counts), &dev).unwrap();
/// assert_eq!(counts.to_vec().unwrap(), vec![2]);
/// ```
#[derive(Clone)]
pub struct Bvh {
    device: Device,
    lowers: Array<Vec3>,
    uppers: Array<Vec3>,
    tree: Arc<Tree>,
}

impl std::fmt::Debug for Bvh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bvh")
            .field("device", &self.device.alias())
            .field("num_prims", &self.tree.num_prims())
            .field("num_nodes", &self.tree.num_nodes())
            .finish()
    }
}

/// Reads and validates a BVH's boxes: equal lengths, finite, not too many.
fn read_boxes(what: &str, lowers: &Array<Vec3>, uppers: &Array<Vec3>) -> Result<[Vec<Vec3>; 2]> {
    check_box_counts(what, lowers, uppers)?;
    let (lo, hi) = (lowers.to_vec()?, uppers.to_vec()?);
    for (name, v) in [("lowers", &lo), ("uppers", &hi)] {
        if let Some((i, p)) = first_non_finite(v) {
            return Err(bad(
                what,
                name,
                format!("has a non-finite corner at index {i}: {p:?}"),
            ));
        }
    }
    Ok([lo, hi])
}

/// Checks, on their device, that `arrays` (each named) hold no NaN or infinite coordinate:
/// the check is queued after what is queued already (a build), and its flags read back once.
pub(crate) fn check_finite_on_device(what: &str, arrays: &[(&str, &Array<Vec3>)]) -> Result<()> {
    let Some((_, first)) = arrays.first() else {
        return Ok(());
    };
    let flags = Array::from_slice(&vec![i32::MAX; arrays.len()], first.device())?;
    for (k, (_, a)) in arrays.iter().enumerate() {
        lbvh::check_finite(a, flags.device_address() + 4 * k as u64)?;
    }
    for ((name, a), i) in arrays.iter().zip(flags.to_vec()?) {
        if i != i32::MAX {
            let i = i as usize;
            let p = a.view(i..i + 1)?.to_vec()?[0];
            return Err(bad(
                what,
                name,
                format!("has a non-finite value at index {i}: {p:?}"),
            ));
        }
    }
    Ok(())
}

/// Checks a BVH's box counts: equal, not too many.
fn check_box_counts(what: &str, lowers: &Array<Vec3>, uppers: &Array<Vec3>) -> Result<()> {
    if lowers.len() != uppers.len() {
        return Err(bad(
            what,
            "uppers",
            format!(
                "has {} boxes but `lowers` has {}: one upper corner per lower corner",
                uppers.len(),
                lowers.len()
            ),
        ));
    }
    if lowers.len() > MAX_PRIMS {
        return Err(bad(
            what,
            "lowers",
            format!("has {} boxes, more than {MAX_PRIMS}", lowers.len()),
        ));
    }
    Ok(())
}

impl Bvh {
    /// Builds a BVH over the boxes `[lowers[i], uppers[i]]` on the arrays' device (Warp's
    /// `wp.Bvh(lowers, uppers)`). The BVH keeps both arrays (sharing their memory): queries
    /// read the boxes from them, and [`refit`](Bvh::refit) re-reads them. No box gives the
    /// empty tree, whose queries find nothing. A box with a lower corner above its upper one
    /// is never found (as in Warp).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the argument: `lowers` and `uppers` of different
    /// lengths or on different devices, either not contiguous, a NaN or infinite corner (the
    /// first such index and value), more than `i32::MAX / 2` boxes; device errors.
    pub fn new(lowers: &Array<Vec3>, uppers: &Array<Vec3>) -> Result<Bvh> {
        const WHAT: &str = "Bvh::new";
        let device = lowers.device().clone();
        same_device(WHAT, "uppers", uppers, &device, "lowers")?;
        contiguous(WHAT, "lowers", lowers)?;
        contiguous(WHAT, "uppers", uppers)?;
        let tree = if device.is_cpu() {
            let [lo, hi] = read_boxes(WHAT, lowers, uppers)?;
            Tree::build_on_host(&lo, &hi, &device)?
        } else {
            check_box_counts(WHAT, lowers, uppers)?;
            let tree = Tree::build_on_device(lowers, uppers, lbvh::BVH_LEAF_SIZE)?;
            check_finite_on_device(WHAT, &[("lowers", lowers), ("uppers", uppers)])?;
            tree
        };
        Ok(Bvh {
            device,
            lowers: lowers.clone(),
            uppers: uppers.clone(),
            tree: Arc::new(tree),
        })
    }

    /// Recomputes the tree's boxes from the current `lowers` and `uppers` (after a kernel or
    /// the host moved the boxes), keeping the tree's shape (Warp's `refit`): fast, but queries
    /// slow down when the boxes moved far from where they were built (then build a new `Bvh`).
    /// A failed refit leaves the BVH as it was.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `lowers` or `uppers` when a corner is NaN or
    /// infinite; device errors.
    pub fn refit(&mut self) -> Result<()> {
        const WHAT: &str = "Bvh::refit";
        let (lowers, uppers) = (&self.lowers, &self.uppers);
        let tree = if self.device.is_cpu() {
            let [lo, hi] = read_boxes(WHAT, lowers, uppers)?;
            self.tree.refit_on_host(&lo, &hi)?
        } else {
            // Checked before the refit, which may write the tree in place: a failed refit
            // leaves the BVH as it was.
            check_box_counts(WHAT, lowers, uppers)?;
            check_finite_on_device(WHAT, &[("lowers", lowers), ("uppers", uppers)])?;
            return Tree::refit_on_device(&mut self.tree, lowers, uppers);
        };
        self.tree = Arc::new(tree);
        Ok(())
    }

    /// The device the BVH lives on (the device of the launches that take it).
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The boxes' lower corners: the user's array, shared.
    pub fn lowers(&self) -> &Array<Vec3> {
        &self.lowers
    }

    /// The boxes' upper corners: the user's array, shared.
    pub fn uppers(&self) -> &Array<Vec3> {
        &self.uppers
    }

    /// The number of boxes.
    pub fn num_prims(&self) -> usize {
        self.tree.num_prims()
    }

    /// The number of nodes of the tree.
    pub fn num_nodes(&self) -> usize {
        self.tree.num_nodes()
    }

    /// The tree on the host: nodes, parent links and primitive ids in the layout of
    /// `warp_core::objects::bvh`, for inspection and tests (a GPU's tree is read back).
    ///
    /// # Errors
    /// Device errors of the read-back.
    pub fn tree_host(&self) -> Result<(Vec<BvhNode>, Vec<i32>, Vec<i32>)> {
        self.tree.host()
    }
}

impl HostObject for Bvh {
    type View = BvhView;
    type Cuda = CudaBvh;

    fn device(&self) -> &Device {
        &self.device
    }

    unsafe fn cpu_view(&self, ctx: &ArgCtx<'_>) -> Result<BvhView> {
        // SAFETY: the launch borrows the BVH (its tree and arrays) for the view's whole use.
        let tree = unsafe { self.tree.cpu_tree(ctx) };
        Ok(BvhView::new(
            tree,
            self.lowers.cpu_view(ctx.kernel, ctx.arg),
            self.uppers.cpu_view(ctx.kernel, ctx.arg),
        ))
    }

    fn cuda_record(&self, ctx: &ArgCtx<'_>) -> Result<CudaBvh> {
        Ok(CudaBvh {
            tree: self.tree.cuda_tree(ctx.index),
            lowers: self.lowers.device_address(),
            uppers: self.uppers.device_address(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::bvh_build::check_layout;
    use super::*;

    fn arr(v: &[Vec3]) -> Array<Vec3> {
        Array::from_slice(v, &crate::cpu()).unwrap()
    }

    #[test]
    fn builds_refits_and_copies_on_write() {
        let lo: Vec<Vec3> = (0..50).map(|i| Vec3::splat(i as f32)).collect();
        let hi: Vec<Vec3> = lo.iter().map(|p| *p + 0.5).collect();
        let (l, u) = (arr(&lo), arr(&hi));
        let mut bvh = Bvh::new(&l, &u).unwrap();
        assert_eq!(bvh.num_prims(), 50);
        let (n, p, ids) = bvh.tree_host().unwrap();
        check_layout(&n, &p, &ids, &lo, &hi).unwrap();
        let kept = bvh.clone();
        let moved: Vec<Vec3> = lo.iter().map(|p| *p + 100.0).collect();
        l.copy_from(&arr(&moved)).unwrap();
        let moved_hi: Vec<Vec3> = moved.iter().map(|p| *p + 0.5).collect();
        u.copy_from(&arr(&moved_hi)).unwrap();
        bvh.refit().unwrap();
        let (n2, p2, ids2) = bvh.tree_host().unwrap();
        check_layout(&n2, &p2, &ids2, &moved, &moved_hi).unwrap();
        assert_eq!((p2, ids2), (p, ids), "a refit keeps the shape");
        assert_eq!(kept.tree_host().unwrap().0, n, "the clone keeps its tree");
        assert_eq!(n2[0].lower, [100.0; 3]);
    }

    #[test]
    fn empty_and_bad_input() {
        let e = Bvh::new(&arr(&[]), &arr(&[])).unwrap();
        assert_eq!((e.num_prims(), e.num_nodes()), (0, 1));
        let err = Bvh::new(&arr(&[Vec3::ZERO]), &arr(&[])).unwrap_err();
        assert!(err.to_string().contains("argument `uppers`"), "{err}");
        let err = Bvh::new(
            &arr(&[Vec3::ZERO, Vec3::new(0.0, f32::NAN, 0.0)]),
            &arr(&[Vec3::ONE, Vec3::ONE]),
        )
        .unwrap_err();
        let t = err.to_string();
        assert!(
            t.contains("argument `lowers`") && t.contains("index 1"),
            "{t}"
        );
    }
}

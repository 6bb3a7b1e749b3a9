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
//! # Where the tree is built and refit
//!
//! Where its device is: the CPU builds with the binned SAH builder of
//! [`bvh_build`](super::bvh_build) and refits the nodes in place, in one host operation that
//! checks the boxes first; a GPU builds a linear BVH with the kernels of `wp_bvh_build.h`
//! (`lbvh.rs`) and refits with one of them, which checks the boxes it reads and raises the
//! first non-finite one as a fault. Either way a refit allocates nothing and reads nothing
//! back, so a capture records it.
//!
//! Copy-on-write: a clone (what a [`Tape`](crate::Tape) keeps of a launch's BVH) shares the
//! tree; a refit of a shared tree gives the refit BVH a new node buffer, so a recorded launch
//! replays in backward against the tree it ran with. (The boxes themselves are the user's
//! arrays, which a replay reads as they are then, like any array argument.) Inside a capture
//! the refit writes the tree in place at each replay (the launches recorded after it hold the
//! same tree), which a clone made before the capture would see: it is refused then.

use std::sync::Arc;

use glam::{Vec3, Vec4};
use warp_core::objects::bvh::{BvhNode, BvhTree};
use warp_core::objects::BvhView;
use warp_core::ArrayView;

use super::bvh_build::{
    build_sah, leaf_triangles, refit as refit_nodes, triangle_boxes, write_leaf_triangles_par,
    BuiltBvh,
};
use super::geometry_abi::{CudaBvh, CudaBvhTree};
use super::lbvh::{self, Lbvh, LbvhTree, RefitCheck};
use super::HostObject;
use crate::array::Array;
use crate::capturing::{self, Keep};
use crate::device::Device;
use crate::dispatch;
use crate::error::{Error, Result};
use crate::kernel::{ArgCtx, KernelInfo};

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

/// What a BVH's refit names its faults by (the GPU's check of the boxes: argument 0 is
/// `lowers`, 1 `uppers`).
pub(crate) static BVH_REFIT: KernelInfo = KernelInfo {
    name: "Bvh::refit",
    module: "warp_lang::objects",
    params: &["lowers", "uppers"],
    ..KernelInfo::BLANK
};

/// What a mesh's refit names its faults by (the GPU's check of the points, argument 0, and of
/// the indices, argument 1).
pub(crate) static MESH_REFIT: KernelInfo = KernelInfo {
    name: "Mesh::refit",
    module: "warp_lang::objects",
    params: &["points", "indices"],
    ..KernelInfo::BLANK
};

/// What a tree is refit from.
#[derive(Clone, Copy)]
pub(crate) enum RefitFrom<'a> {
    /// A BVH's boxes (as many as the tree's primitives).
    Boxes {
        lowers: &'a Array<Vec3>,
        uppers: &'a Array<Vec3>,
    },
    /// A mesh's triangles: its points and its own indices (checked against the points'
    /// count at the mesh's build; the points are as many).
    Triangles {
        points: &'a Array<Vec3>,
        indices: &'a Array<i32>,
    },
}

impl RefitFrom<'_> {
    /// The arrays the refit reads, kept by a graph that records it.
    fn uses(&self) -> Keep {
        match *self {
            RefitFrom::Boxes { lowers, uppers } => Box::new([lowers.clone(), uppers.clone()]),
            RefitFrom::Triangles { points, indices } => Box::new((points.clone(), indices.clone())),
        }
    }
}

/// A built tree on one device.
///
/// Built where its device is: on the CPU by the binned SAH builder (better trees, and the CPU
/// has the cores for it), refit there in place; on a GPU as a linear BVH by the kernels of
/// `wp_bvh_build.h` (`lbvh.rs`), which never leaves the GPU. `parents` (the links: each node's
/// parent, then each node's escape, `2 * num_nodes` entries) and `prim_ids` never
/// change after a build, so the copy a shared tree's refit makes shares them.
pub(crate) struct Tree {
    /// The nodes on the device, two `Vec4`s (32 bytes, 16-aligned) per `BvhNode`.
    nodes: Array<Vec4>,
    parents: Array<i32>,
    prim_ids: Array<i32>,
    num_nodes: usize,
    num_prims: usize,
    /// A GPU-built tree's refit state (`None` for a tree built on the host, the CPU's).
    device_refit: Option<DeviceRefit>,
    /// A mesh's triangles in leaf order (`bvh_build::leaf_triangles`: three
    /// corners per `prim_ids` position, 16-byte aligned), which the mesh's walks read: written
    /// with the tree at the mesh's build ([`Tree::set_leaf_triangles`]) and by every refit
    /// from triangles, copied with the nodes by a shared tree's refit. `None` for a BVH's.
    leaf_tris: Option<Array<Vec4>>,
}

/// What a GPU tree's refit uses, made with the tree: a refit allocates nothing.
struct DeviceRefit {
    /// One counter per node, zero between refits (each refit leaves them so).
    counters: Array<i32>,
    /// The refit's two check words (`lbvh::RefitCheck`), `i32::MAX` between refits.
    bad: Array<i32>,
    /// A mesh's triangle boxes, the refit's input (its first step writes them); `None` for a
    /// BVH, whose boxes are the user's arrays.
    boxes: Option<[Array<Vec3>; 2]>,
}

impl DeviceRefit {
    /// The state of a tree of `nodes` nodes on `device`, with room for `faces` triangle boxes
    /// for a mesh's tree.
    fn new(nodes: usize, faces: Option<usize>, device: &Device) -> Result<DeviceRefit> {
        Ok(DeviceRefit {
            counters: Array::zeros(nodes, device)?,
            bad: Array::from_slice(&[i32::MAX; 2], device)?,
            // Written whole by the refit's first step.
            boxes: match faces {
                Some(f) => Some([Array::empty(f, device)?, Array::empty(f, device)?]),
                None => None,
            },
        })
    }
}

/// The nodes as the device buffer holds them.
fn node_words(nodes: &[BvhNode]) -> &[Vec4] {
    bytemuck::cast_slice(nodes)
}

impl Tree {
    /// A tree over the boxes `[lowers[i], uppers[i]]` (validated by the caller: equal lengths,
    /// finite, at most [`MAX_PRIMS`]), built on the host and uploaded to `device` (the CPU).
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
            device_refit: None,
            leaf_tris: None,
        })
    }

    /// A linear BVH over the boxes (contiguous, equal lengths, at most [`MAX_PRIMS`]: checked
    /// by the caller; non-finite corners give a tree that the caller refuses), with leaves of
    /// up to `leaf_size` boxes, built on their device without leaving it (queued: nothing
    /// waits). `mesh`: the boxes are a mesh's triangle boxes, which the tree keeps for its
    /// refits to write (else they are the user's, which a refit reads).
    pub(crate) fn build_on_device(
        lowers: &Array<Vec3>,
        uppers: &Array<Vec3>,
        leaf_size: usize,
        mesh: bool,
    ) -> Result<Tree> {
        let device = lowers.device();
        let n = lowers.len();
        let count = lbvh::node_count(n);
        // The build writes every node, link and id: no zeroing.
        let tree = Tree {
            nodes: Array::empty(2 * count, device)?,
            parents: Array::empty(2 * count, device)?,
            prim_ids: Array::empty(n, device)?,
            num_nodes: count,
            num_prims: n,
            device_refit: Some(DeviceRefit {
                boxes: mesh.then(|| [lowers.clone(), uppers.clone()]),
                ..DeviceRefit::new(count, None, device)?
            }),
            leaf_tris: None,
        };
        let refit = tree.device_refit.as_ref().expect("made above");
        Lbvh::new(device)?.build(
            lowers,
            uppers,
            &tree.lbvh_buffers(&tree.nodes.reinterpret()?, refit),
            leaf_size,
        )?;
        Ok(tree)
    }

    /// The buffers as the LBVH builder takes them (`nodes`: this tree's, reinterpreted).
    fn lbvh_buffers<'a>(&'a self, nodes: &'a Array<i32>, refit: &'a DeviceRefit) -> LbvhTree<'a> {
        LbvhTree {
            nodes,
            parents: &self.parents,
            prim_ids: &self.prim_ids,
            counters: &refit.counters,
        }
    }

    /// A copy of this tree with a node buffer (and refit state) of its own, the parents and
    /// primitive ids shared: what a refit of a shared tree writes (copy-on-write).
    fn copy(&self) -> Result<Tree> {
        let device = self.nodes.device();
        let nodes = Array::<Vec4>::empty(self.nodes.len(), device)?;
        nodes.copy_from(&self.nodes)?;
        let device_refit = match &self.device_refit {
            Some(r) => Some(DeviceRefit::new(
                self.num_nodes,
                r.boxes.as_ref().map(|b| b[0].len()),
                device,
            )?),
            None => None,
        };
        // The triangles too: a CPU refit that refuses its input leaves the copy as it was.
        let leaf_tris = match &self.leaf_tris {
            Some(t) => {
                let c = Array::<Vec4>::empty(t.len(), device)?;
                c.copy_from(t)?;
                Some(c)
            }
            None => None,
        };
        Ok(Tree {
            nodes,
            parents: self.parents.clone(),
            prim_ids: self.prim_ids.clone(),
            num_nodes: self.num_nodes,
            num_prims: self.num_prims,
            device_refit,
            leaf_tris,
        })
    }

    /// Makes a mesh's tree's leaf-ordered triangles from `points` and `indices` (the mesh's,
    /// checked against each other by the caller, or refused after this on a GPU: a bad index
    /// gives its triangle NaN corners and reads no point). On the CPU on the host; on a GPU by
    /// the triangle boxes' step in leaf order (queued), which also writes the tree's kept
    /// boxes, by position (what the refits read them as; the build is done with them).
    pub(crate) fn set_leaf_triangles(
        &mut self,
        points: &Array<Vec3>,
        indices: &Array<i32>,
    ) -> Result<()> {
        let device = self.nodes.device().clone();
        // Written whole below (a GPU's step writes every position).
        let out = Array::<Vec4>::empty(3 * self.num_prims, &device)?;
        match &self.device_refit {
            None => {
                let t = leaf_triangles(
                    &self.prim_ids.to_vec()?,
                    &indices.to_vec()?,
                    &points.to_vec()?,
                );
                if !t.is_empty() {
                    out.copy_from(&Array::from_slice(&t, &device)?)?;
                }
            }
            Some(r) => {
                if self.num_prims > 0 {
                    let [lo, hi] = r.boxes.as_ref().expect("a mesh's tree keeps its boxes");
                    lbvh::triangle_boxes(
                        points,
                        indices,
                        lo,
                        hi,
                        [0, 0],
                        Some((&self.prim_ids, &out)),
                        || Box::new(()),
                    )?;
                }
            }
        }
        self.leaf_tris = Some(out);
        Ok(())
    }

    /// A mesh's tree's leaf-ordered triangles (`None` for a BVH's tree).
    pub(crate) fn leaf_triangles(&self) -> Option<&Array<Vec4>> {
        self.leaf_tris.as_ref()
    }

    /// Recomputes the tree's boxes from `from`, keeping its shape, where the tree is (the
    /// CPU: on the host; a GPU: one or two steps there, queued). In place when `tree` is not
    /// shared; a shared tree (a clone, a tape's, holds it) is copied first, so the clone
    /// keeps what it holds. Allocates and reads back nothing otherwise: inside a capture the
    /// refit is recorded, writing in place at each replay (see `capturing::adopt`).
    ///
    /// Non-finite input is an [`Error::InvalidArgument`] on the CPU, checked before the tree is
    /// written (it is left as it was); on a GPU a fault ([`FaultKind::NonFiniteInput`](
    /// warp_core::FaultKind::NonFiniteInput)) that the refit's step raises, reported at the
    /// next synchronisation, after the tree was refit from what it read. A mesh's index
    /// outside its points (written since the build) likewise: refused on the CPU, on a GPU a
    /// [`FaultKind::OutOfBounds`](warp_core::FaultKind::OutOfBounds) on `indices` (index
    /// `[position, value]`, shape `[indices, points]`), its face refit as an empty box.
    pub(crate) fn refit(tree: &mut Arc<Tree>, from: RefitFrom<'_>) -> Result<()> {
        let what = match from {
            RefitFrom::Boxes { .. } => BVH_REFIT.name,
            RefitFrom::Triangles { .. } => MESH_REFIT.name,
        };
        if capturing::capturing() {
            capturing::check_device(tree.nodes.device(), &|| format!("`{what}`"))?;
            if !capturing::adopt(&*tree) {
                return Err(Error::Capture {
                    what: format!(
                        "{what} inside a capture writes the tree in place, but a clone made \
                         before the capture (a tape's) shares it and must keep it: the copy \
                         it would write allocates (refit once before capturing, or drop the \
                         clone)"
                    ),
                });
            }
        } else if Arc::get_mut(tree).is_none() {
            *tree = Arc::new(tree.copy()?);
        }
        match tree.device_refit {
            None => tree.refit_on_host(from),
            Some(_) => tree.refit_on_device(from),
        }
    }

    /// [`Tree::refit`] of a CPU tree: one host operation (recorded inside a capture), which
    /// checks the input, then refits the nodes in place.
    fn refit_on_host(&self, from: RefitFrom<'_>) -> Result<()> {
        let device = self.nodes.device();
        debug_assert!(device.is_cpu());
        // The operation reads and writes the arrays by address (CPU memory), as a build step
        // does: they live as long as this tree, or the graph that records it.
        let at = |a: u64| a as usize;
        let (nodes, parents, ids) = (
            at(self.nodes.device_address()),
            at(self.parents.device_address()),
            at(self.prim_ids.device_address()),
        );
        let (num_nodes, num_prims) = (self.num_nodes, self.num_prims);
        let tris = self
            .leaf_tris
            .as_ref()
            .map_or(0, |t| at(t.device_address()));
        let uses = || -> Keep {
            Box::new((
                [&self.parents, &self.prim_ids].map(Array::clone),
                self.nodes.clone(),
                self.leaf_tris.clone(),
                from.uses(),
            ))
        };
        // SAFETY (of the slices below): the addresses are of contiguous CPU arrays of these
        // lengths, alive for the operation's every run (the tree, or the graph's keep); the
        // refit is the only writer of the nodes while it runs (one thread runs it, in order
        // with the launches that read the tree).
        let refit = move |lo: &[Vec3], hi: &[Vec3]| {
            if num_prims == 0 {
                // The empty tree keeps its one inverted node.
                return;
            }
            let (nodes, parents, ids) = unsafe {
                (
                    std::slice::from_raw_parts_mut(nodes as *mut BvhNode, num_nodes),
                    std::slice::from_raw_parts(parents as *const i32, 2 * num_nodes),
                    std::slice::from_raw_parts(ids as *const i32, num_prims),
                )
            };
            refit_nodes(nodes, parents, ids, lo, hi);
        };
        match from {
            RefitFrom::Boxes { lowers, uppers } => {
                debug_assert!(lowers.len() == num_prims && uppers.len() == num_prims);
                let (lo, hi) = (at(lowers.device_address()), at(uppers.device_address()));
                dispatch::enqueue(device, BVH_REFIT.name, uses, move |_| {
                    let (lo, hi) = unsafe {
                        (
                            std::slice::from_raw_parts(lo as *const Vec3, num_prims),
                            std::slice::from_raw_parts(hi as *const Vec3, num_prims),
                        )
                    };
                    for (name, v) in [("lowers", lo), ("uppers", hi)] {
                        if let Some((i, p)) = first_non_finite(v) {
                            return Err(bad(
                                BVH_REFIT.name,
                                name,
                                format!("has a non-finite corner at index {i}: {p:?}"),
                            ));
                        }
                    }
                    refit(lo, hi);
                    Ok(())
                })
            }
            RefitFrom::Triangles { points, indices } => {
                let num_points = points.len();
                debug_assert_eq!(indices.len(), 3 * num_prims);
                let (p, ix) = (at(points.device_address()), at(indices.device_address()));
                dispatch::enqueue(device, MESH_REFIT.name, uses, move |_| {
                    let (p, ix) = unsafe {
                        (
                            std::slice::from_raw_parts(p as *const Vec3, num_points),
                            std::slice::from_raw_parts(ix as *const i32, 3 * num_prims),
                        )
                    };
                    if let Some((i, v)) = first_non_finite(p) {
                        return Err(bad(
                            MESH_REFIT.name,
                            "points",
                            format!("has a non-finite point at index {i}: {v:?}"),
                        ));
                    }
                    // The mesh checked its indices at its build, but they are an array a
                    // kernel may have written since (`Mesh::indices`).
                    let (lo, hi) = triangle_boxes(p, ix).map_err(|k| {
                        bad(
                            MESH_REFIT.name,
                            "indices",
                            format!(
                                "has {} at position {k}, outside the {num_points} points (the \
                                 mesh's indices were written after its build)",
                                ix[k]
                            ),
                        )
                    })?;
                    refit(&lo, &hi);
                    // The walks' copy of the triangles, in leaf order, from the checked
                    // indices and points.
                    if tris != 0 && num_prims > 0 {
                        // SAFETY: the tree's ids and its `3 * num_prims` corners (see above:
                        // alive for every run, written only by this operation).
                        let (ids, out) = unsafe {
                            (
                                std::slice::from_raw_parts(ids as *const i32, num_prims),
                                std::slice::from_raw_parts_mut(tris as *mut Vec4, 3 * num_prims),
                            )
                        };
                        write_leaf_triangles_par(out, ids, ix, p);
                    }
                    Ok(())
                })
            }
        }
    }

    /// [`Tree::refit`] of a GPU tree: the refit's step (a mesh's: its triangle boxes' step
    /// first), which checks the input and reports what it finds as a fault.
    fn refit_on_device(&self, from: RefitFrom<'_>) -> Result<()> {
        let r = self.device_refit.as_ref().expect("a GPU tree");
        if self.num_prims == 0 {
            return Ok(());
        }
        // The refit kernel leaves its counters zero itself, but a fill first (on the default
        // stream, which joins the user streams: recorded as a memset in a capture) orders this
        // refit after one of the same tree queued on another stream; without it two such
        // refits would overlap, and a counter one of them left behind would spoil every
        // later refit of the tree, silently.
        r.counters.fill(0)?;
        let nodes = self.nodes.reinterpret()?;
        let buffers = self.lbvh_buffers(&nodes, r);
        let uses = || -> Keep {
            Box::new((
                [&self.parents, &self.prim_ids, &r.counters, &r.bad].map(Array::clone),
                self.nodes.clone(),
                (r.boxes.clone(), self.leaf_tris.clone()),
                from.uses(),
            ))
        };
        match from {
            RefitFrom::Boxes { lowers, uppers } => {
                let check = RefitCheck {
                    bad: &r.bad,
                    sources: [Some(lowers), Some(uppers)],
                    check_boxes: true,
                    by_position: false,
                    indices: None,
                    names: &BVH_REFIT,
                };
                lbvh::refit(lowers, uppers, &buffers, Some(&check), uses)
            }
            RefitFrom::Triangles { points, indices } => {
                let [lo, hi] = r.boxes.as_ref().expect("a mesh's tree keeps its boxes");
                // The indices were checked at the mesh's build, but a kernel may have written
                // them since (`Mesh::indices`): the step lowers word 1 to the first position
                // of an index outside the points (that face gets an empty box and NaN
                // corners, reading no point through it), word 0 to the first non-finite
                // point, and the refit reports either as a fault. The step runs in leaf order
                // and writes the walks' copy of the triangles too.
                let word = r.bad.device_address();
                let flags = [word + 4, word];
                let tris = self
                    .leaf_tris
                    .as_ref()
                    .expect("a mesh's tree has its triangles");
                lbvh::triangle_boxes(
                    points,
                    indices,
                    lo,
                    hi,
                    flags,
                    Some((&self.prim_ids, tris)),
                    uses,
                )?;
                let check = RefitCheck {
                    bad: &r.bad,
                    sources: [Some(points), None],
                    check_boxes: false,
                    // The leaf-order step above wrote them by position.
                    by_position: true,
                    indices: Some((indices, points.len())),
                    names: &MESH_REFIT,
                };
                lbvh::refit(lo, hi, &buffers, Some(&check), uses)
            }
        }
    }

    /// Primitives in the tree.
    pub(crate) fn num_prims(&self) -> usize {
        self.num_prims
    }

    /// Nodes in the tree.
    pub(crate) fn num_nodes(&self) -> usize {
        self.num_nodes
    }

    /// The tree on the host: nodes, links (parents, then escapes), primitive ids (read back
    /// from the device).
    pub(crate) fn host(&self) -> Result<(Vec<BvhNode>, Vec<i32>, Vec<i32>)> {
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
            let tree = Tree::build_on_device(lowers, uppers, lbvh::BVH_LEAF_SIZE, false)?;
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
    ///
    /// A refit allocates nothing and reads nothing back (unless a clone of the BVH, a tape's,
    /// shares the tree: the refit then writes a copy, which the clone does not see), so it can
    /// be recorded into a [capture](crate::capture): each replay refits the tree in place from
    /// the boxes as they are then, and the launches recorded after it query the refit tree. A
    /// captured refit of a BVH whose tree a clone made before the capture shares is an
    /// [`Error::Capture`]; a BVH may be refit several times in one capture.
    ///
    /// On the CPU the boxes are checked first: a NaN or infinite corner is an
    /// [`Error::InvalidArgument`] naming `lowers` or `uppers` and the first such index, and the
    /// BVH is left as it was (in a graph, the replay stops there with that error). On a GPU the
    /// refit is queued: its kernel checks every corner it reads, and a non-finite one is a
    /// fault ([`FaultKind::NonFiniteInput`](warp_core::FaultKind::NonFiniteInput) naming
    /// `Bvh::refit`, the argument and the first such index, lowers before uppers) reported by
    /// the next synchronisation (of a replay too), like a kernel's; the tree is then refit from
    /// the values read, non-finite ones included: queries over it stay in bounds, but what
    /// they find is unspecified until a refit from finite boxes.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] (CPU) when a corner is NaN or infinite; [`Error::Capture`]
    /// as above; device errors.
    pub fn refit(&mut self) -> Result<()> {
        Tree::refit(
            &mut self.tree,
            RefitFrom::Boxes {
                lowers: &self.lowers,
                uppers: &self.uppers,
            },
        )
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

    fn adopt_in_capture(&self) {
        // Shared with a clone made before the capture: not adopted (a rebuild is refused).
        capturing::adopt(&self.tree);
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

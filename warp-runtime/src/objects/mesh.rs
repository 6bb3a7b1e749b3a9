//! [`Mesh`]: Warp's triangle mesh. `Mesh::new(&points, &indices, velocities)` builds a BVH
//! over the triangles `points[indices[3f..3f + 3]]` on the arrays' device; kernels take it as a
//! parameter `mesh: Mesh` and call the mesh queries (`mesh_query_point`, `mesh_query_ray`,
//! `for f in mesh_query_aabb(mesh, lo, hi)`, `mesh_eval_position`, ...; see
//! `warp_core::objects::mesh` for their meaning, which the CUDA library mirrors).
//!
//! The mesh keeps the user's `points` (and `velocities`) arrays, sharing their memory, as
//! Warp's `mesh.points`: a kernel may deform the mesh by writing [`Mesh::points`], then
//! [`Mesh::refit`] recomputes the tree's boxes. The indices are copied (the mesh validated
//! them against the points; a later change could not be).
//!
//! # What the queries see: the geometry of the last build or refit
//!
//! The mesh also keeps its triangles in the order of its tree's leaves (three corners per
//! triangle, written at the build and by every refit from the points then): the
//! closest-point, furthest-point, ray and parity queries (`mesh_query_point*`,
//! `mesh_query_furthest_point_no_sign`, `mesh_query_ray`) read the triangles there, a
//! leaf's triangles from consecutive memory, rather than following each face's indices into
//! the points. So these queries see the vertices as of the last [`Mesh::new`] or
//! [`Mesh::refit`], as the tree's boxes already were. Warp's queries read the points array
//! directly; here, after writing the points (or indices) without a refit, those queries go
//! on answering for the mesh as it was at the last refit (consistently: boxes and triangles
//! agree), while `mesh_eval_position`, `mesh_eval_velocity`, `mesh_eval_face_normal` and
//! the box query `mesh_query_aabb` read the current points and indices. A query's
//! `(face, u, v)` fed to `mesh_eval_position` is therefore the closest point found only when
//! the points were not changed since the refit: call [`Mesh::refit`] after moving the points
//! (Warp requires it too, for its boxes). The copy costs 48 bytes per triangle.
//!
//! The tree is built where the mesh is, as for [`Bvh`](super::Bvh): on the CPU by the binned
//! SAH builder over the triangles' boxes; on a GPU the triangles' boxes (with the checks of
//! the indices and the points) and a linear BVH are kernels (`lbvh.rs`), and only the checks'
//! flags are read back, at `new`. The indices are checked at `new` (on a GPU by the
//! triangles' boxes step, which reads no point through a bad index) and again by every
//! refit, since a kernel may write them. A refit reads nothing back: on a GPU the boxes step
//! checks the points and the indices and the refit step reports a non-finite point or an
//! index outside the points as a fault.
//!
//! Copy-on-write: a clone (what a [`Tape`](crate::Tape) keeps) shares the tree; a refit of a
//! shared tree gives the refit mesh a new node buffer, so a recorded launch replays against
//! the tree it ran with.

use std::sync::Arc;

use glam::{Vec3, Vec4};
use warp_core::objects::MeshView;

use super::bvh::{bad, contiguous, first_non_finite, same_device, RefitFrom, Tree, MAX_PRIMS};
use super::bvh_build::triangle_boxes;
use super::geometry_abi::CudaMesh;
use super::lbvh;
use super::HostObject;
use crate::array::Array;
use crate::capturing;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::ArgCtx;

/// A triangle mesh on one device (Warp's `wp.Mesh(points, indices, velocities)`; the suite
/// `tests/suite/mesh.rs` runs kernels like this one):
///
/// ```ignore
/// use warp_lang as wp;
/// use wp::prelude::*;
///
/// #[wp::kernel]
/// fn closest(mesh: Mesh, q: Array<Vec3>, out: Array<Vec3>) {
///     let i = tid();
///     let (found, _sign, face, u, v) = mesh_query_point_no_sign(mesh, q[i], 10.0);
///     if found {
///         out[i] = mesh_eval_position(mesh, face, u, v);
///     }
/// }
///
/// let dev = wp::cpu();
/// let points = wp::Array::from_slice(&[Vec3::ZERO, Vec3::X, Vec3::Y], &dev).unwrap();
/// let indices = wp::Array::from_slice(&[0, 1, 2], &dev).unwrap();
/// let mesh = wp::Mesh::new(&points, &indices, None).unwrap();
/// let q = wp::Array::from_slice(&[Vec3::new(0.25, 0.25, 1.0)], &dev).unwrap();
/// let out = wp::Array::<Vec3>::zeros(1, &dev).unwrap();
/// wp::launch(closest, 1, (&mesh, &q, &out), &dev).unwrap();
/// assert_eq!(out.to_vec().unwrap(), vec![Vec3::new(0.25, 0.25, 0.0)]);
/// ```
///
/// Queries see the geometry of the last build or [`refit`](Mesh::refit): the point and ray
/// queries read a copy of the triangles in the tree's leaf order that the build and every
/// refit write (Warp's read the points array). After changing the points, refit: until then
/// those queries answer for the previous points (with boxes to match), while `mesh_eval_*`
/// and `mesh_query_aabb` read the new ones (see the module docs).
#[derive(Clone)]
pub struct Mesh {
    device: Device,
    points: Array<Vec3>,
    velocities: Option<Array<Vec3>>,
    /// The mesh's own copy of the indices, on its device.
    indices: Array<i32>,
    /// The point count the indices were validated against (the build's).
    num_points: usize,
    tree: Arc<Tree>,
}

impl std::fmt::Debug for Mesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mesh")
            .field("device", &self.device.alias())
            .field("num_points", &self.num_points)
            .field("num_faces", &self.num_faces())
            .field("velocities", &self.velocities.is_some())
            .finish()
    }
}

/// The triangles' boxes on the mesh's device (a GPU's: queued, nothing read back); the
/// first position of an index outside the points lowers the `i32` at `flags[0]`, the first
/// non-finite point the one at `flags[1]`.
fn device_triangle_boxes(
    points: &Array<Vec3>,
    indices: &Array<i32>,
    flags: [u64; 2],
) -> Result<(Array<Vec3>, Array<Vec3>)> {
    let faces = indices.len() / 3;
    // Written whole by the boxes' step.
    let lo = Array::empty(faces, points.device())?;
    let hi = Array::empty(faces, points.device())?;
    lbvh::triangle_boxes(points, indices, &lo, &hi, flags, None, || Box::new(()))?;
    Ok((lo, hi))
}

/// The error of an index `v` at position `k` outside the `n` points.
fn bad_index(what: &str, k: usize, v: i32, n: usize) -> Error {
    bad(
        what,
        "indices",
        format!(
            "has {v} at position {k} (triangle {}), outside the {n} points",
            k / 3
        ),
    )
}

/// Checks host indices against `n` points.
fn check_indices(what: &str, ix: &[i32], n: usize) -> Result<()> {
    match ix.iter().position(|i| *i < 0 || *i as usize >= n) {
        Some(k) => Err(bad_index(what, k, ix[k], n)),
        None => Ok(()),
    }
}

/// Reads the points back and checks them: as many as `n`, all finite.
fn read_points(what: &str, points: &Array<Vec3>, n: usize) -> Result<Vec<Vec3>> {
    check_point_count(what, points, n)?;
    let p = points.to_vec()?;
    if let Some((i, v)) = first_non_finite(&p) {
        return Err(bad(
            what,
            "points",
            format!("has a non-finite point at index {i}: {v:?}"),
        ));
    }
    Ok(p)
}

/// Checks that the points are as many as the mesh was built with (`n`).
fn check_point_count(what: &str, points: &Array<Vec3>, n: usize) -> Result<()> {
    if points.len() != n {
        return Err(bad(
            what,
            "points",
            format!(
                "has {} points but the mesh was built with {n}: its indices were checked \
                 against those (build a new Mesh for a new point count)",
                points.len()
            ),
        ));
    }
    Ok(())
}

/// Checks `velocities` against `points`: device, contiguity, one per point.
fn check_velocities(what: &str, v: &Array<Vec3>, points: &Array<Vec3>) -> Result<()> {
    same_device(what, "velocities", v, points.device(), "points")?;
    contiguous(what, "velocities", v)?;
    if v.len() != points.len() {
        return Err(bad(
            what,
            "velocities",
            format!(
                "has {} velocities for {} points: one per point",
                v.len(),
                points.len()
            ),
        ));
    }
    Ok(())
}

impl Mesh {
    /// Builds a mesh of the triangles `indices[3f], indices[3f + 1], indices[3f + 2]` (indices
    /// into `points`) on the arrays' device, with optional per-point `velocities` (Warp's
    /// `wp.Mesh(points, indices, velocities)`). The mesh keeps `points` and `velocities`
    /// (sharing their memory: [`points`](Mesh::points)) and a copy of the indices. No
    /// triangle gives the empty mesh, whose queries find nothing. Degenerate triangles are
    /// allowed (see `warp_core::objects::mesh` for how queries treat them).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the argument: `indices` whose length is not a
    /// multiple of 3, or with an index outside `0..points.len()` (the first such position and
    /// value); `points` with a NaN or infinite coordinate (the first such index); `velocities`
    /// not one per point; arrays on different devices or not contiguous; more than
    /// `i32::MAX / 2` triangles or `i32::MAX` points; device errors.
    pub fn new(
        points: &Array<Vec3>,
        indices: &Array<i32>,
        velocities: Option<&Array<Vec3>>,
    ) -> Result<Mesh> {
        const WHAT: &str = "Mesh::new";
        let device = points.device().clone();
        same_device(WHAT, "indices", indices, &device, "points")?;
        contiguous(WHAT, "points", points)?;
        if let Some(v) = velocities {
            check_velocities(WHAT, v, points)?;
        }
        let n = points.len();
        if n > i32::MAX as usize {
            return Err(bad(
                WHAT,
                "points",
                format!("has {n} points, more than i32::MAX (indices are i32, as in Warp)"),
            ));
        }
        if !indices.len().is_multiple_of(3) {
            return Err(bad(
                WHAT,
                "indices",
                format!(
                    "has {} entries, not a multiple of 3 (three vertex indices per triangle)",
                    indices.len()
                ),
            ));
        }
        if indices.len() / 3 > MAX_PRIMS {
            return Err(bad(
                WHAT,
                "indices",
                format!("has {} triangles, more than {MAX_PRIMS}", indices.len() / 3),
            ));
        }
        let (dev_indices, tree) = if device.is_cpu() {
            let ix = indices.to_vec()?;
            check_indices(WHAT, &ix, n)?;
            let p = read_points(WHAT, points, n)?;
            let (lo, hi) = triangle_boxes(&p, &ix).map_err(|k| bad_index(WHAT, k, ix[k], n))?;
            let mut tree = Tree::build_on_host(&lo, &hi, &device)?;
            let own = Array::from_slice(&ix, &device)?;
            tree.set_leaf_triangles(points, &own)?;
            (own, tree)
        } else {
            // Everything on the device: the indices and the points are checked by the
            // triangles' boxes step, and only its two flags come back (after the build).
            let own = Array::empty(indices.len(), &device)?;
            own.copy_from(indices)?;
            let flags = Array::from_slice(&[i32::MAX, i32::MAX], &device)?;
            let at = flags.device_address();
            let (lo, hi) = device_triangle_boxes(points, &own, [at, at + 4])?;
            // The tree keeps the boxes: its refits write them.
            let mut tree = Tree::build_on_device(&lo, &hi, lbvh::MESH_LEAF_SIZE, true)?;
            // The walks' copy of the triangles, in leaf order (a bad index, refused below,
            // reads no point there).
            tree.set_leaf_triangles(points, &own)?;
            let f = flags.to_vec()?;
            if f[0] != i32::MAX {
                let k = f[0] as usize;
                let v = indices.view(k..k + 1)?.to_vec()?[0];
                return Err(bad_index(WHAT, k, v, n));
            }
            if f[1] != i32::MAX {
                let i = f[1] as usize;
                let p = points.view(i..i + 1)?.to_vec()?[0];
                return Err(bad(
                    WHAT,
                    "points",
                    format!("has a non-finite point at index {i}: {p:?}"),
                ));
            }
            (own, tree)
        };
        Ok(Mesh {
            indices: dev_indices,
            device,
            points: points.clone(),
            velocities: velocities.cloned(),
            num_points: n,
            tree: Arc::new(tree),
        })
    }

    /// Recomputes the tree's boxes from the current points (after a kernel or the host moved
    /// them), keeping the tree's shape (Warp's `refit`).
    ///
    /// As [`Bvh::refit`](super::Bvh::refit): nothing is allocated or read back (unless a clone
    /// shares the tree), so a refit can be recorded into a capture, which refits in place at
    /// each replay. On the CPU the points are checked first (a failed refit leaves the mesh as
    /// it was); on a GPU the refit's steps check them and a NaN or infinite point is a fault
    /// naming `Mesh::refit`, `points` and the first such index, reported at the next
    /// synchronisation, the tree refit from the values read (queries stay in bounds, their
    /// results unspecified until a refit from finite points). A mesh without triangles has no
    /// box to refit: a GPU checks nothing then. An index a kernel wrote outside the points
    /// since the build, through [`indices`](Mesh::indices), is refused by the CPU's refit,
    /// naming `indices`, its position and value; on a GPU it is a fault
    /// ([`FaultKind::OutOfBounds`](warp_core::FaultKind::OutOfBounds) of `Mesh::refit` on
    /// `indices`, index `[position, value]`, shape `[3 * faces, points]`), reported at the
    /// next synchronisation like a non-finite point's, the refit reading no point through
    /// that index: its triangle gets an empty box and NaN corners in the leaf-ordered
    /// triangles the walks read (the point and ray queries skip it until a refit from valid
    /// indices).
    ///
    /// The refit also rewrites the leaf-ordered triangles the queries read (module docs), in
    /// the same step that reads the vertices for the boxes: queries see the points as of the
    /// last refit.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `points` when the points array (replaced by
    /// [`set_points`](Mesh::set_points)) has another length than the one the mesh was built
    /// with, and on the CPU when a point is NaN or infinite; [`Error::Capture`] inside a
    /// capture when a clone made before it shares the tree; device errors.
    pub fn refit(&mut self) -> Result<()> {
        check_point_count("Mesh::refit", &self.points, self.num_points)?;
        Tree::refit(
            &mut self.tree,
            RefitFrom::Triangles {
                points: &self.points,
                indices: &self.indices,
            },
        )
    }

    /// Replaces the points array (Warp's `mesh.points = a`), for a [`refit`](Mesh::refit)
    /// from it. The new array must have as many points as the mesh was built with: `refit`
    /// and launches refuse it otherwise (the indices were checked against that count).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `points` when it is on another device than the mesh
    /// or not contiguous.
    pub fn set_points(&mut self, points: &Array<Vec3>) -> Result<()> {
        same_device(
            "Mesh::set_points",
            "points",
            points,
            &self.device,
            "the mesh",
        )?;
        contiguous("Mesh::set_points", "points", points)?;
        self.points = points.clone();
        Ok(())
    }

    /// The points: the user's array, shared (writing it deforms the mesh; call
    /// [`refit`](Mesh::refit) before querying the deformed mesh: until then the point and ray
    /// queries see the points of the last refit, the `mesh_eval_*` functions the new ones).
    pub fn points(&self) -> &Array<Vec3> {
        &self.points
    }

    /// The velocities, if any: the user's array, shared.
    pub fn velocities(&self) -> Option<&Array<Vec3>> {
        self.velocities.as_ref()
    }

    /// The mesh's copy of the vertex indices, three per face.
    pub fn indices(&self) -> &Array<i32> {
        &self.indices
    }

    /// The device the mesh lives on (the device of the launches that take it).
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The number of triangles.
    pub fn num_faces(&self) -> usize {
        self.tree.num_prims()
    }

    /// The number of points the mesh was built with.
    pub fn num_points(&self) -> usize {
        self.num_points
    }

    /// The tree over the triangles as built or last refit: nodes, parent links and face ids
    /// in the layout of `warp_core::objects::bvh`, for inspection and tests (a GPU's tree is
    /// read back).
    ///
    /// # Errors
    /// Device errors of the read-back.
    pub fn tree_host(&self) -> Result<(Vec<warp_core::objects::BvhNode>, Vec<i32>, Vec<i32>)> {
        self.tree.host()
    }

    /// The tree's leaf-ordered triangles (a mesh's tree always has them).
    fn leaf_tris(&self) -> &Array<Vec4> {
        self.tree
            .leaf_triangles()
            .expect("a mesh's tree has its leaf-ordered triangles")
    }

    /// The checks of a launch beyond its device: the points as many as built with.
    fn check_launch(&self, ctx: &ArgCtx<'_>) -> Result<()> {
        if self.points.len() != self.num_points {
            return Err(Error::InvalidArgument {
                what: format!(
                    "kernel `{}`: argument `{}`: the Mesh's points array has {} points but the \
                     mesh was built with {}",
                    ctx.kernel,
                    ctx.arg,
                    self.points.len(),
                    self.num_points
                ),
            });
        }
        Ok(())
    }
}

impl HostObject for Mesh {
    type View = MeshView;
    type Cuda = CudaMesh;

    fn device(&self) -> &Device {
        &self.device
    }

    unsafe fn cpu_view(&self, ctx: &ArgCtx<'_>) -> Result<MeshView> {
        self.check_launch(ctx)?;
        // SAFETY: the launch borrows the mesh (its tree and arrays) for the view's whole use.
        let tree = unsafe { self.tree.cpu_tree(ctx) };
        Ok(MeshView::new(
            tree,
            self.points.cpu_view(ctx.kernel, ctx.arg),
            self.velocities
                .as_ref()
                .map(|v| v.cpu_view(ctx.kernel, ctx.arg)),
            self.indices.cpu_view(ctx.kernel, ctx.arg),
            self.leaf_tris().cpu_view(ctx.kernel, ctx.arg),
        ))
    }

    fn adopt_in_capture(&self) {
        // Shared with a clone made before the capture: not adopted (a rebuild is refused).
        capturing::adopt(&self.tree);
    }

    fn cuda_record(&self, ctx: &ArgCtx<'_>) -> Result<CudaMesh> {
        self.check_launch(ctx)?;
        Ok(CudaMesh {
            tree: self.tree.cuda_tree(ctx.index),
            points: self.points.device_address(),
            velocities: self.velocities.as_ref().map_or(0, |v| v.device_address()),
            indices: self.indices.device_address(),
            num_points: self.num_points as i32,
            pad: 0,
            leaf_tris: self.leaf_tris().device_address(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts(v: &[Vec3]) -> Array<Vec3> {
        Array::from_slice(v, &crate::cpu()).unwrap()
    }

    fn ix(v: &[i32]) -> Array<i32> {
        Array::from_slice(v, &crate::cpu()).unwrap()
    }

    #[test]
    fn bad_input_names_the_argument() {
        let p = pts(&[Vec3::ZERO, Vec3::X, Vec3::Y]);
        let has = |e: Error, s: &[&str]| {
            let t = e.to_string();
            for s in s {
                assert!(t.contains(s), "`{s}` not in {t}");
            }
        };
        has(
            Mesh::new(&p, &ix(&[0, 1]), None).unwrap_err(),
            &["argument `indices`", "multiple of 3"],
        );
        has(
            Mesh::new(&p, &ix(&[0, 1, 3]), None).unwrap_err(),
            &["argument `indices`", "3 at position 2"],
        );
        has(
            Mesh::new(&p, &ix(&[0, -1, 2]), None).unwrap_err(),
            &["argument `indices`", "-1 at position 1"],
        );
        let nan = pts(&[Vec3::ZERO, Vec3::X, Vec3::new(0.0, f32::INFINITY, 0.0)]);
        has(
            Mesh::new(&nan, &ix(&[0, 1, 2]), None).unwrap_err(),
            &["argument `points`", "index 2"],
        );
        has(
            Mesh::new(&p, &ix(&[0, 1, 2]), Some(&pts(&[Vec3::ZERO]))).unwrap_err(),
            &["argument `velocities`", "1 velocities for 3 points"],
        );
        let mut m = Mesh::new(&p, &ix(&[0, 1, 2]), None).unwrap();
        m.indices().copy_from(&ix(&[0, 7, 2])).unwrap();
        has(
            m.refit().unwrap_err(),
            &["argument `indices`", "7 at position 1"],
        );
        m.indices().copy_from(&ix(&[0, 1, 2])).unwrap();
        m.refit().unwrap();
        m.set_points(&pts(&[Vec3::ZERO])).unwrap();
        has(
            m.refit().unwrap_err(),
            &["argument `points`", "built with 3"],
        );
        let e = Mesh::new(&pts(&[]), &ix(&[]), None).unwrap();
        assert_eq!((e.num_faces(), e.num_points()), (0, 0));
    }

    /// The leaf-ordered triangles the walks read are `bvh_build::leaf_triangles` of the
    /// tree's ids, the indices and the points of the last build or refit, bit for bit
    /// (compared exactly: a copy, no arithmetic): unchanged by moving the points until the
    /// refit, and a clone made before a refit keeps its own. On the CPU, and on `cuda:0`
    /// when there is one (where the build's and the refit's triangle boxes step writes them).
    #[test]
    fn leaf_triangles_follow_the_build_and_the_refits() {
        let mut devices = vec![crate::cpu()];
        devices.extend(crate::get_device("cuda:0").ok());
        for dev in devices {
            let p0: Vec<Vec3> = (0..40)
                .map(|i| Vec3::new((i % 7) as f32, (i / 7) as f32, (i * i % 5) as f32 * 0.25))
                .collect();
            let faces: Vec<i32> = (0..30)
                .flat_map(|f| [f, f + 1, f + 7].map(|i| i % 40))
                .collect();
            let p = Array::from_slice(&p0, &dev).unwrap();
            let mut m = Mesh::new(&p, &Array::from_slice(&faces, &dev).unwrap(), None).unwrap();
            let got = |m: &Mesh| m.leaf_tris().to_vec().unwrap();
            let want = |m: &Mesh, points: &[Vec3]| {
                let (_, _, ids) = m.tree_host().unwrap();
                let mut sorted = ids.clone();
                sorted.sort_unstable();
                assert_eq!(sorted, (0..30).collect::<Vec<_>>());
                super::super::bvh_build::leaf_triangles(&ids, &faces, points)
            };
            assert_eq!(got(&m), want(&m, &p0), "{}: build", dev.alias());
            let before = m.clone();
            let p1: Vec<Vec3> = p0.iter().map(|q| *q * 1.5 + Vec3::Z).collect();
            p.copy_from(&Array::from_slice(&p1, &dev).unwrap()).unwrap();
            assert_eq!(got(&m), want(&m, &p0), "{}: moved, not refit", dev.alias());
            m.refit().unwrap();
            assert_eq!(got(&m), want(&m, &p1), "{}: refit", dev.alias());
            assert_eq!(
                got(&before),
                want(&before, &p0),
                "{}: the clone",
                dev.alias()
            );
            // The empty mesh: an empty copy, through a shared tree's refit too.
            let mut e = Mesh::new(
                &Array::<Vec3>::empty(0, &dev).unwrap(),
                &Array::<i32>::empty(0, &dev).unwrap(),
                None,
            )
            .unwrap();
            let shared = e.clone();
            e.refit().unwrap();
            assert!(got(&e).is_empty() && got(&shared).is_empty());
        }
    }
}

//! Warp's triangle mesh, kernel side: [`MeshView`] (what a `Mesh` kernel parameter is on the
//! CPU) and its queries: closest point (signed or not), furthest point, closest ray hit,
//! the triangles overlapping a box (iterating), and evaluation at barycentrics.
//!
//! A mesh is `points` (and optionally per-point `velocities`), `indices` (three per
//! triangle, into `points`) and a BVH over its triangles in the layout of [`super::bvh`]
//! (whose primitives are the triangles: a primitive id is a face index).
//!
//! # Conventions (Warp's, so ported kernels give the same numbers)
//!
//! - A face `f` has vertices `p0, p1, p2 = points[indices[3f]], points[indices[3f + 1]],
//!   points[indices[3f + 2]]`; its normal is `normalize((p1 - p0) x (p2 - p0))`.
//! - Barycentrics `(u, v)` name the point `u * p0 + v * p1 + (1 - u - v) * p2`
//!   ([`mesh_eval_position`]).
//! - `mesh_query_point*` report a point only when one lies **strictly** within `max_dist`
//!   (`result` false otherwise, the other fields then meaningless); the furthest point query
//!   only when one lies strictly beyond `min_dist`; `mesh_query_ray` only a hit with
//!   `0 <= t < max_t`.
//! - `sign` is `-1` inside, `+1` outside.
//!
//! # The sign of `mesh_query_point`
//!
//! The angle-weighted pseudonormal of the closest feature (Bærentzen and Aanæs, *Signed
//! distance computation using the angle weighted pseudonormal*, 2005): the point is outside
//! when `n . (p - c) > 0`, with `c` the closest point and `n` the face normal when `c` is
//! inside a face, the sum of the unit normals of the faces sharing the edge when it is on an
//! edge, and the sum of those of the faces around the vertex weighted by their angles there
//! when it is a vertex. The faces sharing an edge or a vertex are found by a second, tiny box
//! query and matched by exact equality of positions (so welded and unwelded meshes alike).
//! For a closed, consistently oriented mesh this is exact: it gives the same answer as the
//! winding number wherever the closest feature is determined (away from the medial axis by
//! more than rounding). Unlike ray casting (Warp's `mesh_query_point` votes with three
//! axis-aligned rays) it needs no watertightness and no epsilon, and on an **open** mesh (a
//! plane patch, a single triangle) it still means something: the side of the surface near the
//! closest point (below a patch whose normals point up is inside). A point exactly on the
//! surface, or whose closest normal sum is perpendicular to `p - c` (in the plane of an open
//! boundary), is inside (`-1`), as in Warp's `mesh_query_point_sign_normal`. Degenerate faces
//! (slivers, see [`SLIVER_RATIO`]) contribute no normal.
//!
//! Warp's other sign methods: `mesh_query_point_sign_normal` is this one under Warp's name;
//! [`mesh_query_point_sign_parity`] counts the faces one ray crosses (exact on closed meshes
//! whatever the normals, see there). Winding numbers are not provided.
//!
//! Differences from Warp, all deliberate: degenerate triangles still count for distances
//! (Warp skips slivers; here their edges are found, which are real surface); `max_dist <= 0`
//! finds nothing (Warp squares it, so `-1` acts as `1`); the furthest point's gradient is zero
//! (it is a vertex; Warp applies the closest point's); `mesh_query_ray`'s `sign` is `±1`
//! (Warp's is the unnormalised determinant, of the same sign).
//!
//! # Scale
//!
//! Distances are compared squared, which in f32 overflows beyond about 1e19 and underflows
//! below 1e-19. Each point query therefore measures in units of a power of two chosen from the
//! root box's extent around the query point (exact, and the same for every candidate), so
//! meshes at 1e30 or 1e-30 are queried as at 1. The geometric predicates scale themselves
//! ([`super::geometry`]), except that the closest-point search computes each face's closest
//! point in its own unit (`Closest::visit`): the same bits, but for a face and a query point
//! both within about 1e-10 of the root box's extent around the point.
//!
//! # The triangles the walks read
//!
//! The closest-point, furthest-point, ray and parity queries (and the sign's walk around an
//! edge or a vertex) read each triangle from the mesh's leaf-ordered copy
//! ([`write_leaf_triangles`]) at its position in the tree's `prim_ids`, and map only their result
//! to a face (`prim_ids`, checked). The runtime writes that copy at the build and every
//! refit, so these queries see the vertices as of then (as the tree's boxes); the box query
//! and the `mesh_eval_*` functions read `indices` and `points` as they are.
//!
//! # Safety
//!
//! Every index read from the buffers is checked (a face, a vertex index, and the tree's, see
//! [`super::bvh`]; a leaf position, which the walks take from a checked leaf range): a
//! corrupt mesh is a fault naming its kernel parameter, never undefined behaviour;
//! traversals are bounded.

// `!(x > t)` is true when `x` is NaN: the negated comparisons below are how NaN takes the
// rejecting branch, on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::{Vec3, Vec4};

use super::bvh::{walk_ordered, BvhTree, OrderedSearch, Walk};
use super::geometry::{
    aabb_distance_sq_scaled, aabb_overlap, closest_point_triangle_scaled, intersect_ray_aabb,
    intersect_ray_aabb_finite, intersect_ray_triangle_in_frame, pow2_scale,
    ray_crosses_triangle_in_frame, ray_inv_dir, ray_inv_dir_finite, RayFrame, TriFeature,
    TriangleClosestPoint, SLIVER_RATIO,
};
use crate::{ArrayView, KResult, KernelIndex};

/// A built mesh as a kernel thread sees it: the BVH over its triangles, the points, the
/// optional velocities, the indices, and the triangles in leaf order (see
/// [`write_leaf_triangles`]). `Copy`, owns nothing; 104 bytes (small on purpose: query steps take
/// it by value, see `HashGridView`).
#[derive(Clone, Copy, Debug)]
pub struct MeshView {
    tree: BvhTree,
    points: *const Vec3,
    /// Null when the mesh has no velocities.
    velocities: *const Vec3,
    indices: *const i32,
    /// `3 * num_prims` corners: the triangle at position `k` of the tree's `prim_ids` is
    /// `leaf_tris[3k..3k + 3]` (`w` unused).
    leaf_tris: *const Vec4,
    num_points: i32,
}

#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<MeshView>() == 104);

/// Writes the triangles of a mesh in the order of its tree's leaves into `out` (what the
/// closest-point, furthest-point, ray and parity walks read; `3 * prim_ids.len()` entries,
/// extra entries left alone): entry `3k + j` is corner `j` of face
/// `prim_ids[k]`, `points[indices[3 * prim_ids[k] + j]]`, with `w = 0`. The walks then read a
/// leaf's triangles from consecutive memory at its positions, instead of the dependent chain
/// `prim_ids -> indices -> points`. The runtime writes it at a mesh's build and at every
/// refit, from the points as they are then (as it does the boxes). A face whose id or vertex
/// index is out of range (only in a corrupt mesh: the runtime checks both) gets NaN
/// corners, which no query reports (every comparison with NaN is false).
pub fn write_leaf_triangles(out: &mut [Vec4], prim_ids: &[i32], indices: &[i32], points: &[Vec3]) {
    let corner = |f: i32, j: usize| -> Option<Vec4> {
        let f = usize::try_from(f).ok()?;
        let i = *indices.get(3 * f + j)?;
        Some(points.get(usize::try_from(i).ok()?)?.extend(0.0))
    };
    for (t, &f) in out.chunks_exact_mut(3).zip(prim_ids) {
        let c = [0, 1, 2].map(|j| corner(f, j));
        let ok = c.iter().all(Option::is_some);
        for (o, c) in t.iter_mut().zip(c) {
            *o = match (ok, c) {
                (true, Some(v)) => v,
                _ => Vec4::new(f32::NAN, f32::NAN, f32::NAN, 0.0),
            };
        }
    }
}

// SAFETY: read-only pointers into buffers the runtime keeps alive for the whole launch.
unsafe impl Send for MeshView {}
unsafe impl Sync for MeshView {}

fn contiguous<T: Copy>(v: &ArrayView<T, 1>, what: &str) -> *const T {
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

impl MeshView {
    /// A view of a mesh: the BVH over its triangles (one primitive per triangle), its points,
    /// optional velocities (one per point), indices (three per triangle) and its triangles in
    /// leaf order ([`write_leaf_triangles`] of the tree, three corners per triangle).
    ///
    /// Faults carry the names of `points` (the tree's are replaced: the mesh is one kernel
    /// parameter).
    ///
    /// # Panics
    /// When a buffer is not contiguous or the lengths disagree (host-side checks).
    pub fn new(
        mut tree: BvhTree,
        points: ArrayView<Vec3, 1>,
        velocities: Option<ArrayView<Vec3, 1>>,
        indices: ArrayView<i32, 1>,
        leaf_tris: ArrayView<Vec4, 1>,
    ) -> Self {
        assert!(
            indices.len() == 3 * tree.num_prims(),
            "mesh: {} indices for a tree of {} triangles",
            indices.len(),
            tree.num_prims()
        );
        assert!(
            leaf_tris.len() == 3 * tree.num_prims(),
            "mesh: {} leaf-ordered corners for a tree of {} triangles",
            leaf_tris.len(),
            tree.num_prims()
        );
        assert!(points.len() <= i32::MAX as usize);
        let (kernel, arg) = points.names();
        tree.set_names(kernel, arg);
        let velocities = match velocities {
            Some(v) => {
                assert_eq!(v.len(), points.len(), "mesh: one velocity per point");
                contiguous(&v, "mesh velocities")
            }
            None => std::ptr::null(),
        };
        MeshView {
            tree,
            points: contiguous(&points, "mesh points"),
            velocities,
            indices: contiguous(&indices, "mesh indices"),
            leaf_tris: contiguous(&leaf_tris, "mesh leaf triangles"),
            num_points: points.len() as i32,
        }
    }

    /// A view over raw buffers (`velocities` null for none).
    ///
    /// # Safety
    /// `points` (and `velocities` unless null) must address `num_points` valid elements,
    /// `indices` `3 * tree.num_prims()` and `leaf_tris` `3 * tree.num_prims()` (the
    /// triangles in leaf order, [`write_leaf_triangles`]), alive and unchanged while the view is
    /// used.
    pub unsafe fn from_raw(
        tree: BvhTree,
        points: *const Vec3,
        velocities: *const Vec3,
        num_points: i32,
        indices: *const i32,
        leaf_tris: *const Vec4,
    ) -> Self {
        assert!(num_points >= 0);
        MeshView {
            tree,
            points,
            velocities,
            indices,
            leaf_tris,
            num_points,
        }
    }

    /// The empty mesh: what an adjoint's placeholder for a mesh value holds; queries find
    /// nothing and face reads fault.
    pub fn empty() -> Self {
        MeshView {
            tree: BvhTree::empty("mesh", "mesh"),
            points: std::ptr::NonNull::dangling().as_ptr(),
            velocities: std::ptr::null(),
            indices: std::ptr::NonNull::dangling().as_ptr(),
            leaf_tris: std::ptr::NonNull::dangling().as_ptr(),
            num_points: 0,
        }
    }

    /// The BVH over the triangles.
    pub fn tree(&self) -> &BvhTree {
        &self.tree
    }

    /// Triangles in the mesh.
    pub fn num_faces(&self) -> usize {
        self.tree.num_prims()
    }

    /// Points in the mesh.
    pub fn num_points(&self) -> usize {
        self.num_points as usize
    }

    /// Whether the mesh has velocities.
    pub fn has_velocities(&self) -> bool {
        !self.velocities.is_null()
    }

    /// The vertex indices of face `f`, each checked against the points; a fault when `f` is
    /// not a face or an index is not a point.
    #[inline(always)]
    fn face_indices<I: KernelIndex<1>>(&self, f: I) -> KResult<[usize; 3]> {
        let [fu] = f.to_usize();
        if fu >= self.tree.num_prims() {
            return Err(self.tree.fault(f.components()[0], self.tree.num_prims()));
        }
        let mut out = [0usize; 3];
        for (k, o) in out.iter_mut().enumerate() {
            // SAFETY: 3 * f + k < 3 * faces, which `new` checked `indices` holds.
            let i = unsafe { self.indices.add(3 * fu + k).read() };
            if (i as u32) >= self.num_points as u32 {
                return Err(self.tree.fault(i as i128, self.num_points as usize));
            }
            *o = i as usize;
        }
        Ok(out)
    }

    /// The three vertices of face `f` (checked as [`MeshView::face_indices`]).
    #[inline(always)]
    fn triangle<I: KernelIndex<1>>(&self, f: I) -> KResult<[Vec3; 3]> {
        let ix = self.face_indices(f)?;
        // SAFETY: checked point indices.
        Ok(ix.map(|i| unsafe { self.points.add(i).read() }))
    }

    /// The triangle at position `k` of the tree's `prim_ids`, from the leaf-ordered copy
    /// ([`write_leaf_triangles`]): the walks pass positions within a leaf's range, which they
    /// checked against `prim_ids`; anything else is a fault (as a `prim_ids` position).
    #[inline(always)]
    fn leaf_triangle(&self, k: i32) -> KResult<[Vec3; 3]> {
        if (k as u32) >= self.tree.num_prims() as u32 {
            return Err(self.tree.fault(k as i128, self.tree.num_prims()));
        }
        let k = k as usize;
        // SAFETY: 3k + 2 < 3 * num_prims, which `new` checked (`from_raw`'s contract).
        Ok([0, 1, 2].map(|j| unsafe { self.leaf_tris.add(3 * k + j).read() }.truncate()))
    }

    /// The three vertex velocities of face `f`, or `None` without velocities.
    #[inline(always)]
    fn triangle_velocities<I: KernelIndex<1>>(&self, f: I) -> KResult<Option<[Vec3; 3]>> {
        let ix = self.face_indices(f)?;
        if self.velocities.is_null() {
            return Ok(None);
        }
        // SAFETY: checked point indices; velocities hold one per point.
        Ok(Some(ix.map(|i| unsafe { self.velocities.add(i).read() })))
    }

    /// The power of two in which a point query around `p` measures (module docs): the root
    /// box's farthest extent from `p` brought into `[1, 2)`; 1 for an empty or non-finite box.
    #[inline(always)]
    fn measure_scale(&self, p: Vec3) -> KResult<f32> {
        let root = self.tree.node(0)?;
        let m = (root.lower() - p).abs().max((root.upper() - p).abs());
        Ok(pow2_scale(m.max_element()))
    }
}

/// The result of a closest or furthest point query (Warp's `mesh_query_point_t`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct MeshQueryPoint {
    /// Whether a point was found (within `max_dist`, or beyond `min_dist`).
    pub result: bool,
    /// `-1` inside, `+1` outside (`mesh_query_point`); 0 from the unsigned queries.
    pub sign: f32,
    /// The face of the point.
    pub face: i32,
    /// The weight of the face's first vertex.
    pub u: f32,
    /// The weight of its second vertex (the third's is `1 - u - v`).
    pub v: f32,
}

/// The result of a ray query (Warp's `mesh_query_ray_t`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct MeshQueryRay {
    /// Whether the ray hits the mesh at some `0 <= t < max_t`.
    pub result: bool,
    /// `+1` when the ray hits the face's front (`dir . normal < 0`), `-1` its back.
    pub sign: f32,
    /// The face hit first.
    pub face: i32,
    /// The hit's ray parameter: the point is `start + t * dir`.
    pub t: f32,
    /// The weight of the face's first vertex at the hit.
    pub u: f32,
    /// The weight of its second vertex.
    pub v: f32,
    /// The face's unit normal (zero for a degenerate face).
    pub normal: Vec3,
}

/// The closest-point search: squared distances in units of `1 / s`. During the walk `face`
/// is the best triangle's position in `prim_ids` (the walk reads triangles by position);
/// [`closest`] maps it to the face at the end.
struct Closest<'a> {
    mesh: &'a MeshView,
    p: Vec3,
    s: f32,
    best: f32,
    face: i32,
    bary: TriangleClosestPoint,
    tri: [Vec3; 3],
}

impl OrderedSearch for Closest<'_> {
    #[inline(always)]
    fn node_key(&self, lower: Vec3, upper: Vec3) -> f32 {
        aabb_distance_sq_scaled(self.p, lower, upper, self.s)
    }
    #[inline(always)]
    fn bound(&self) -> f32 {
        self.best
    }
    /// A face is skipped when its own box is no nearer than the best distance so far (the
    /// box key of a node, on the face's box: a fraction of the closest point's cost). In exact
    /// arithmetic the box distance is a lower bound of the face's, so nothing nearer is
    /// skipped; in f32 the face's computed distance can round below its box's by a few ulps,
    /// so a skipped face may be one whose distance ties the best within rounding, and then
    /// the face reported is that best, equally close within f32 rounding. Both backends skip
    /// the same faces (the same key, the same comparison), so they still agree bit for bit.
    ///
    /// The closest point is computed in the search's unit `s` rather than at a scale of the
    /// face's own (`closest_point_triangle_scaled`): the same barycentrics, bit for bit,
    /// unless its degree-4 intermediates fall below f32's normal range in this unit, which
    /// takes a face and a query point both within about 1e-10 of the root box's extent
    /// around the point, and there the error stays below the face's size. The distance is
    /// then taken from the translated, scaled edges already at hand.
    #[inline(always)]
    fn visit(&mut self, k: i32) -> KResult<()> {
        let [a, b, c] = self.mesh.leaf_triangle(k)?;
        // Rust's f32::min/max (IEEE minNum/maxNum), as fminf/fmaxf on the GPU.
        let lower = Vec3::new(
            a.x.min(b.x).min(c.x),
            a.y.min(b.y).min(c.y),
            a.z.min(b.z).min(c.z),
        );
        let upper = Vec3::new(
            a.x.max(b.x).max(c.x),
            a.y.max(b.y).max(c.y),
            a.z.max(b.z).max(c.z),
        );
        if !(aabb_distance_sq_scaled(self.p, lower, upper, self.s) < self.best) {
            return Ok(());
        }
        let s = self.s;
        let (ab, ac, ap) = ((b - a) * s, (c - a) * s, (self.p - a) * s);
        let r = closest_point_triangle_scaled(ab, ac, ap);
        let d = (ab * r.v + ac * r.w - ap).length_squared();
        if d < self.best {
            self.best = d;
            self.face = k;
            self.bary = r;
            self.tri = [a, b, c];
        }
        Ok(())
    }
}

/// The closest point search, or `None` (with the scale it measured in).
#[inline(always)]
fn closest(mesh: &MeshView, p: Vec3, max_dist: f32) -> KResult<Option<Closest<'_>>> {
    if !(max_dist > 0.0) {
        return Ok(None);
    }
    let s = mesh.measure_scale(p)?;
    let bound = max_dist * s;
    let mut c = Closest {
        mesh,
        p,
        s,
        best: bound * bound,
        face: -1,
        bary: TriangleClosestPoint::default(),
        tri: [Vec3::ZERO; 3],
    };
    walk_ordered(&mesh.tree, &mut c)?;
    if c.face < 0 {
        return Ok(None);
    }
    // The winning position's face (checked: a corrupt prim_ids faults here).
    c.face = mesh.tree.prim(c.face)?;
    Ok(Some(c))
}

/// The closest point of the mesh to `point` lying strictly within `max_dist`, without a sign
/// (`sign` 0; Warp's `mesh_query_point_no_sign`). Ties go to the face visited first.
#[inline]
pub fn mesh_query_point_no_sign(
    mesh: MeshView,
    point: Vec3,
    max_dist: f32,
) -> KResult<MeshQueryPoint> {
    Ok(match closest(&mesh, point, max_dist)? {
        Some(c) => MeshQueryPoint {
            result: true,
            sign: 0.0,
            face: c.face,
            u: c.bary.u,
            v: c.bary.v,
        },
        None => MeshQueryPoint::default(),
    })
}

/// The closest point of the mesh to `point` lying strictly within `max_dist`, with the sign
/// of `point` (`-1` inside, `+1` outside) by the angle-weighted pseudonormal of the closest
/// feature: exact for closed meshes, meaningful for open ones (module docs).
#[inline]
pub fn mesh_query_point(mesh: MeshView, point: Vec3, max_dist: f32) -> KResult<MeshQueryPoint> {
    let Some(c) = closest(&mesh, point, max_dist)? else {
        return Ok(MeshQueryPoint::default());
    };
    let [a, b, cc] = c.tri;
    let n = match c.bary.feature {
        TriFeature::Face => unit_normal(a, b, cc),
        TriFeature::EdgeAB => edge_normal(&mesh, a, b)?,
        TriFeature::EdgeBC => edge_normal(&mesh, b, cc)?,
        TriFeature::EdgeCA => edge_normal(&mesh, cc, a)?,
        TriFeature::VertexA => vertex_normal(&mesh, a)?,
        TriFeature::VertexB => vertex_normal(&mesh, b)?,
        TriFeature::VertexC => vertex_normal(&mesh, cc)?,
    };
    let away = (point - c.bary.position(a, b, cc)) * c.s;
    Ok(MeshQueryPoint {
        result: true,
        sign: if n.dot(away) > 0.0 { 1.0 } else { -1.0 },
        face: c.face,
        u: c.bary.u,
        v: c.bary.v,
    })
}

/// Warp's `mesh_query_point_sign_normal`: [`mesh_query_point`] under Warp's name for its
/// method (the angle-weighted pseudonormal), so that Warp programs port line for line. Warp's
/// optional `epsilon` (the tolerance by which it decides whether the closest point is on an
/// edge or a vertex) is not taken: the closest feature is classified exactly here
/// ([`closest_point_triangle`](super::geometry::closest_point_triangle)'s regions), with no
/// tolerance to choose.
#[inline]
pub fn mesh_query_point_sign_normal(
    mesh: MeshView,
    point: Vec3,
    max_dist: f32,
) -> KResult<MeshQueryPoint> {
    mesh_query_point(mesh, point, max_dist)
}

/// The closest point of the mesh to `point` lying strictly within `max_dist`, as
/// [`mesh_query_point_no_sign`] finds it (the same face, `u`, `v` and `result`), with the sign
/// of `point` from the parity of the number of faces crossed by one ray from it in the
/// direction [`PARITY_DIR`]: odd inside (`-1`), even outside (`+1`); `sign` 0 when nothing is
/// found (Warp's `mesh_query_point_sign_parity`).
///
/// The faces are counted by [`ray_crosses_triangle`](super::geometry::ray_crosses_triangle), whose crossings are exact in sign and
/// whose ties (a ray through an edge or a vertex) are broken consistently between the faces
/// sharing them, so on a closed mesh (every edge shared by an even number of faces, shared
/// vertices at equal positions) the sign is exact whatever the orientation of the faces or
/// the quality of their normals; only a point within rounding of the surface can take either
/// sign. Warp casts `n_sample` rays perturbed by `perturbation_scale` and takes the majority,
/// as its ray-triangle test can count an edge twice or not at all; neither argument is taken
/// here, one ray suffices. On an open mesh the one ray decides (a point below a plane patch
/// whose ray leaves through the patch is inside, one whose ray passes beside it outside).
/// Its cost is one more walk of the tree, along the ray, whatever the closest feature; the
/// pseudonormal of [`mesh_query_point`] walks again only when the closest point is on an edge
/// or a vertex (around it), so this is the cheaper of the two there and the dearer inside a
/// face.
#[inline]
pub fn mesh_query_point_sign_parity(
    mesh: MeshView,
    point: Vec3,
    max_dist: f32,
) -> KResult<MeshQueryPoint> {
    let Some(c) = closest(&mesh, point, max_dist)? else {
        return Ok(MeshQueryPoint::default());
    };
    let mut x = Crossings {
        mesh: &mesh,
        start: point,
        inv_dir: ray_inv_dir(PARITY_DIR),
        frame: RayFrame::new(PARITY_DIR),
        odd: false,
    };
    walk_ordered(&mesh.tree, &mut x)?;
    Ok(MeshQueryPoint {
        result: true,
        sign: if x.odd { -1.0 } else { 1.0 },
        face: c.face,
        u: c.bary.u,
        v: c.bary.v,
    })
}

/// The direction of [`mesh_query_point_sign_parity`]'s ray: that of the unit vector `(0.6,
/// 0.48, 0.64)`, neither along an axis nor a diagonal, so that the faces of meshes aligned
/// with a grid are not grazed. Stored as `(15/16, 3/4, 1)` (the same direction, divided by
/// 0.64), which binary floating point holds exactly, as it does the slopes of the ray's
/// sheared frame (the unit vector's components are not exact, nor their ratios). All its
/// components are positive, which the walk's box test relies on.
pub const PARITY_DIR: Vec3 = Vec3::new(0.9375, 0.75, 1.0);

/// The slack of [`ray_may_meet_box`], relative to the ray parameters it compares: `2^-18`,
/// 64 units in the last place, above the few roundings of the slab test's parameters and the
/// few of [`ray_crosses_triangle`](super::geometry::ray_crosses_triangle)'s sheared ray (each a few units relative to the distance
/// from the start).
const PARITY_BOX_SLACK: f32 = 1.0 / 262144.0;

/// The parity search: every box the ray may meet is entered (key 0, bound +inf; the count is
/// the same in any order), every face of an entered leaf is tested.
struct Crossings<'a> {
    mesh: &'a MeshView,
    start: Vec3,
    inv_dir: Vec3,
    /// `RayFrame::new(PARITY_DIR)`, made once per query (never `None`: the direction is
    /// finite and nonzero).
    frame: Option<RayFrame>,
    odd: bool,
}

impl OrderedSearch for Crossings<'_> {
    #[inline(always)]
    fn node_key(&self, lower: Vec3, upper: Vec3) -> f32 {
        if ray_may_meet_box(self.start, self.inv_dir, lower, upper) {
            0.0
        } else {
            f32::INFINITY
        }
    }
    #[inline(always)]
    fn bound(&self) -> f32 {
        f32::INFINITY
    }
    #[inline(always)]
    fn visit(&mut self, k: i32) -> KResult<()> {
        let [a, b, c] = self.mesh.leaf_triangle(k)?;
        let crosses = self
            .frame
            .is_some_and(|fr| ray_crosses_triangle_in_frame(&fr, self.start, PARITY_DIR, a, b, c));
        if crosses {
            self.odd = !self.odd;
        }
        Ok(())
    }
}

/// Whether the ray `start + t * dir`, `t >= 0`, may meet the box `[lower, upper]`, for a
/// direction whose components are all positive (`inv_dir = 1 / dir`): the slab test with its
/// interval widened by [`PARITY_BOX_SLACK`]. The plain test ([`intersect_ray_aabb`]) can
/// reject by a rounding a box the ray touches at an edge or a corner, where a face's vertex or
/// edge may lie that [`ray_crosses_triangle`](super::geometry::ray_crosses_triangle) counts; a face missed would flip the parity, a
/// box entered needlessly costs a test. Inverted boxes (the empty tree's root) and NaN miss.
#[inline(always)]
fn ray_may_meet_box(start: Vec3, inv_dir: Vec3, lower: Vec3, upper: Vec3) -> bool {
    if !(lower.x <= upper.x && lower.y <= upper.y && lower.z <= upper.z) {
        return false;
    }
    let near = (lower - start) * inv_dir;
    let far = (upper - start) * inv_dir;
    let max = |a: f32, b: f32| if a > b { a } else { b };
    let min = |a: f32, b: f32| if a < b { a } else { b };
    let t0 = max(near.x, max(near.y, near.z));
    let t1 = min(far.x, min(far.y, far.z));
    let slack = (t0.abs() + t1.abs()) * PARITY_BOX_SLACK;
    t0 <= t1 + slack && t1 + slack >= 0.0
}

/// The unit normal of a triangle, computed at a power-of-two scale (any magnitude); zero for
/// a sliver (below [`SLIVER_RATIO`]), whose normal is rounding noise.
#[inline(always)]
fn unit_normal(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (e1, e2) = (b - a, c - a);
    let s = pow2_scale(e1.abs().max(e2.abs()).max_element());
    let (e1, e2) = (e1 * s, e2 * s);
    let n = e1.cross(e2);
    let sum = e1.length_squared() + e2.length_squared() + (e2 - e1).length_squared();
    if n.length() > SLIVER_RATIO * sum {
        n.normalize()
    } else {
        Vec3::ZERO
    }
}

/// The faces around the box `[lo, hi]` (a vertex's point box or an edge's box), each passed
/// to `f` with its vertices, left first: an ordered walk ([`Touching`]) rather than a box
/// query.s [`Walk`], for its stack.
#[inline(always)]
fn for_faces_touching(
    mesh: &MeshView,
    lo: Vec3,
    hi: Vec3,
    f: impl FnMut([Vec3; 3]),
) -> KResult<()> {
    walk_ordered(&mesh.tree, &mut Touching { mesh, lo, hi, f })
}

/// The search of [`for_faces_touching`]: a box overlapping `[lo, hi]` has key 0, any other
/// +inf, and the bound stays 1, so every overlapping box is entered, the left child first
/// (ties go left), and every face of an entered leaf is visited.
struct Touching<'a, F> {
    mesh: &'a MeshView,
    lo: Vec3,
    hi: Vec3,
    f: F,
}

impl<F: FnMut([Vec3; 3])> OrderedSearch for Touching<'_, F> {
    #[inline(always)]
    fn node_key(&self, lower: Vec3, upper: Vec3) -> f32 {
        if aabb_overlap(lower, upper, self.lo, self.hi) {
            0.0
        } else {
            f32::INFINITY
        }
    }
    #[inline(always)]
    fn bound(&self) -> f32 {
        1.0
    }
    #[inline(always)]
    fn visit(&mut self, k: i32) -> KResult<()> {
        (self.f)(self.mesh.leaf_triangle(k)?);
        Ok(())
    }
}

/// The pseudonormal of the edge `x y`: the sum of the unit normals of the faces having both
/// as vertices (by position).
fn edge_normal(mesh: &MeshView, x: Vec3, y: Vec3) -> KResult<Vec3> {
    let mut n = Vec3::ZERO;
    for_faces_touching(mesh, x.min(y), x.max(y), |t| {
        if t.contains(&x) && t.contains(&y) {
            n += unit_normal(t[0], t[1], t[2]);
        }
    })?;
    Ok(n)
}

/// The pseudonormal of the vertex at `x`: the sum of the unit normals of the faces having it
/// as a vertex (by position), each weighted by the face's angle there.
fn vertex_normal(mesh: &MeshView, x: Vec3) -> KResult<Vec3> {
    let mut n = Vec3::ZERO;
    for_faces_touching(mesh, x, x, |t| {
        let Some(k) = t.iter().position(|q| *q == x) else {
            return;
        };
        let (e1, e2) = (t[(k + 1) % 3] - x, t[(k + 2) % 3] - x);
        let s = pow2_scale(e1.abs().max(e2.abs()).max_element());
        let (e1, e2) = (e1 * s, e2 * s);
        let angle = e1.cross(e2).length().atan2(e1.dot(e2));
        n += unit_normal(t[0], t[1], t[2]) * angle;
    })?;
    Ok(n)
}

/// The furthest-point search: squared distances in units of `1 / s`, negated (the walk
/// minimises).
struct Furthest<'a> {
    mesh: &'a MeshView,
    p: Vec3,
    s: f32,
    best: f32,
    face: i32,
    uv: (f32, f32),
}

impl OrderedSearch for Furthest<'_> {
    #[inline(always)]
    fn node_key(&self, lower: Vec3, upper: Vec3) -> f32 {
        let (p, lo, hi) = (self.p * self.s, lower * self.s, upper * self.s);
        // Inverted (empty) boxes hold nothing.
        if !(lo.cmple(hi).all()) {
            return f32::INFINITY;
        }
        -(p - lo).abs().max((p - hi).abs()).length_squared()
    }
    #[inline(always)]
    fn bound(&self) -> f32 {
        -self.best
    }
    /// `face` is the best triangle's position in `prim_ids` during the walk (mapped to the
    /// face at the end, as [`Closest`]).
    #[inline(always)]
    fn visit(&mut self, k: i32) -> KResult<()> {
        let [a, b, c] = self.mesh.leaf_triangle(k)?;
        let d = |q: Vec3| ((q - self.p) * self.s).length_squared();
        let (da, db, dc) = (d(a), d(b), d(c));
        // Warp's choice among the vertices (ties to the later vertex).
        let (dist, uv) = if da > db && da > dc {
            (da, (1.0, 0.0))
        } else if db > dc {
            (db, (0.0, 1.0))
        } else {
            (dc, (0.0, 0.0))
        };
        if dist > self.best {
            self.best = dist;
            self.face = k;
            self.uv = uv;
        }
        Ok(())
    }
}

/// The furthest point of the mesh from `point`, lying strictly beyond `min_dist` (Warp's
/// `mesh_query_furthest_point_no_sign`): always a vertex, reported as a face and
/// barycentrics `(1, 0)`, `(0, 1)` or `(0, 0)`; `sign` 0. A `min_dist` below 0 counts as 0;
/// NaN finds nothing.
#[inline]
pub fn mesh_query_furthest_point_no_sign(
    mesh: MeshView,
    point: Vec3,
    min_dist: f32,
) -> KResult<MeshQueryPoint> {
    if min_dist.is_nan() {
        return Ok(MeshQueryPoint::default());
    }
    let s = mesh.measure_scale(point)?;
    let m = min_dist.max(0.0) * s;
    let mut f = Furthest {
        mesh: &mesh,
        p: point,
        s,
        best: m * m,
        face: -1,
        uv: (0.0, 0.0),
    };
    walk_ordered(&mesh.tree, &mut f)?;
    Ok(if f.face >= 0 {
        MeshQueryPoint {
            result: true,
            sign: 0.0,
            face: mesh.tree.prim(f.face)?,
            u: f.uv.0,
            v: f.uv.1,
        }
    } else {
        MeshQueryPoint::default()
    })
}

/// The closest-hit search along a ray. The ray's frame is made once; boxes are tested by the
/// branch-free slab test when no component of `inv_dir` is infinite ([`intersect_ray_aabb`]
/// otherwise: the same keys); a face's barycentrics are divided out only for a hit nearer
/// than the bound.
struct ClosestHit<'a> {
    mesh: &'a MeshView,
    start: Vec3,
    dir: Vec3,
    inv_dir: Vec3,
    /// `None` for a zero or non-finite direction, which hits no face.
    frame: Option<RayFrame>,
    finite_inv: bool,
    best: MeshQueryRay,
    max_t: f32,
}

impl OrderedSearch for ClosestHit<'_> {
    #[inline(always)]
    fn node_key(&self, lower: Vec3, upper: Vec3) -> f32 {
        let hit = if self.finite_inv {
            intersect_ray_aabb_finite(self.start, self.inv_dir, lower, upper)
        } else {
            intersect_ray_aabb(self.start, self.inv_dir, lower, upper)
        };
        hit.unwrap_or(f32::INFINITY)
    }
    #[inline(always)]
    fn bound(&self) -> f32 {
        if self.best.result {
            self.best.t
        } else {
            self.max_t
        }
    }
    /// `best.face` is the hit triangle's position in `prim_ids` during the walk (mapped to
    /// the face at the end, as [`Closest`]).
    #[inline(always)]
    fn visit(&mut self, k: i32) -> KResult<()> {
        let [a, b, c] = self.mesh.leaf_triangle(k)?;
        let Some(fr) = &self.frame else {
            return Ok(());
        };
        if let Some(h) = intersect_ray_triangle_in_frame(fr, self.start, self.dir, a, b, c) {
            if h.t < self.bound() {
                self.best = MeshQueryRay {
                    result: true,
                    sign: h.sign,
                    face: k,
                    t: h.t,
                    u: h.u(),
                    v: h.v(),
                    normal: Vec3::ZERO,
                };
            }
        }
        Ok(())
    }
}

/// The first hit of the ray `start + t * dir` with the mesh at `0 <= t < max_t` (Warp's
/// `mesh_query_ray`), by the watertight ray-triangle test ([`intersect_ray_triangle`](super::geometry::intersect_ray_triangle): a ray
/// through a shared edge hits one of its faces, a ray parallel to a face never hits it). Ties
/// at equal `t` (a shared edge) go to the face visited first.
#[inline]
pub fn mesh_query_ray(mesh: MeshView, start: Vec3, dir: Vec3, max_t: f32) -> KResult<MeshQueryRay> {
    let mut h = ClosestHit {
        mesh: &mesh,
        start,
        dir,
        inv_dir: ray_inv_dir(dir),
        frame: RayFrame::new(dir),
        finite_inv: ray_inv_dir_finite(ray_inv_dir(dir)),
        best: MeshQueryRay::default(),
        max_t,
    };
    walk_ordered(&mesh.tree, &mut h)?;
    let mut r = h.best;
    if r.result {
        // The normal of the triangle hit (the leaf-ordered copy's), then its face.
        let [a, b, c] = mesh.leaf_triangle(r.face)?;
        r.normal = face_normal(a, b, c);
        r.face = mesh.tree.prim(r.face)?;
    }
    Ok(r)
}

/// `normalize((b - a) x (c - a))` at a power-of-two scale; zero when the cross product is
/// zero (a degenerate face).
#[inline(always)]
fn face_normal(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (e1, e2) = (b - a, c - a);
    let s = pow2_scale(e1.abs().max(e2.abs()).max_element());
    (e1 * s).cross(e2 * s).normalize_or_zero()
}

/// The state of a box query over a mesh's triangles ([`mesh_query_aabb`]): the box and a
/// [`Walk`]. 44 bytes (Warp's `mesh_query_aabb_t` carries the whole mesh and a 32-entry
/// stack).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct MeshQueryAabb {
    lower: Vec3,
    upper: Vec3,
    walk: Walk,
}

const _: () = assert!(std::mem::size_of::<MeshQueryAabb>() == 44);

/// Starts a query for the faces whose bounding boxes overlap `[lower, upper]` (touching
/// counts; Warp's `mesh_query_aabb`): advance it with [`mesh_query_aabb_next`]. Each such face
/// is yielded once, in no particular order. The test is on the triangle's box, as Warp's: a
/// face can be yielded without the triangle itself meeting the box.
#[inline(always)]
pub fn mesh_query_aabb(_mesh: MeshView, lower: Vec3, upper: Vec3) -> KResult<MeshQueryAabb> {
    Ok(MeshQueryAabb {
        lower,
        upper,
        walk: Walk::start(),
    })
}

/// The mesh box query advanced to its next face, or to its end (then
/// [`mesh_query_aabb_done`]). Once done it stays done.
#[inline(always)]
pub fn mesh_query_aabb_next(mesh: MeshView, mut q: MeshQueryAabb) -> KResult<MeshQueryAabb> {
    let (lo, hi) = (q.lower, q.upper);
    q.walk = q.walk.next(
        &mesh.tree,
        |l, u| aabb_overlap(l, u, lo, hi),
        |id| {
            let [a, b, c] = mesh.triangle(id)?;
            Ok(aabb_overlap(a.min(b).min(c), a.max(b).max(c), lo, hi))
        },
    )?;
    Ok(q)
}

/// Whether the mesh box query has no more faces.
#[inline(always)]
pub fn mesh_query_aabb_done(q: MeshQueryAabb) -> bool {
    q.walk.done()
}

/// The mesh box query's current face.
#[inline(always)]
pub fn mesh_query_aabb_item(q: MeshQueryAabb) -> i32 {
    q.walk.item()
}

/// The point of face `face` at barycentrics `(u, v)`: `u * p0 + v * p1 + (1 - u - v) * p2`
/// (Warp's `mesh_eval_position`); a fault when `face` is not a face.
#[inline(always)]
pub fn mesh_eval_position<I: KernelIndex<1>>(
    mesh: MeshView,
    face: I,
    u: f32,
    v: f32,
) -> KResult<Vec3> {
    let [a, b, c] = mesh.triangle(face)?;
    Ok(a * u + b * v + c * (1.0 - u - v))
}

/// The velocity of face `face` at barycentrics `(u, v)`, interpolated like
/// [`mesh_eval_position`] (Warp's `mesh_eval_velocity`); zero for a mesh without velocities;
/// a fault when `face` is not a face.
#[inline(always)]
pub fn mesh_eval_velocity<I: KernelIndex<1>>(
    mesh: MeshView,
    face: I,
    u: f32,
    v: f32,
) -> KResult<Vec3> {
    Ok(match mesh.triangle_velocities(face)? {
        Some([a, b, c]) => a * u + b * v + c * (1.0 - u - v),
        None => Vec3::ZERO,
    })
}

/// The unit normal of face `face`, `normalize((p1 - p0) x (p2 - p0))` (Warp's
/// `mesh_eval_face_normal`); zero for a degenerate face; a fault when `face` is not a face.
#[inline(always)]
pub fn mesh_eval_face_normal<I: KernelIndex<1>>(mesh: MeshView, face: I) -> KResult<Vec3> {
    let [a, b, c] = mesh.triangle(face)?;
    Ok(face_normal(a, b, c))
}

/// Adjoint of [`mesh_eval_position`] with respect to the barycentrics: `adj_u += (p0 - p2) .
/// adj_ret`, `adj_v += (p1 - p2) . adj_ret` (Warp's, which also leaves the points without a
/// gradient). The mesh and the face get none.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn adj_mesh_eval_position<I: KernelIndex<1>>(
    mesh: MeshView,
    face: I,
    _u: f32,
    _v: f32,
    _adj_mesh: &mut MeshView,
    _adj_face: &mut I,
    adj_u: &mut f32,
    adj_v: &mut f32,
    adj_ret: Vec3,
) -> KResult<()> {
    let [a, b, c] = mesh.triangle(face)?;
    *adj_u += (a - c).dot(adj_ret);
    *adj_v += (b - c).dot(adj_ret);
    Ok(())
}

/// Adjoint of [`mesh_eval_velocity`] with respect to the barycentrics, as
/// [`adj_mesh_eval_position`] with the velocities (nothing without velocities).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn adj_mesh_eval_velocity<I: KernelIndex<1>>(
    mesh: MeshView,
    face: I,
    _u: f32,
    _v: f32,
    _adj_mesh: &mut MeshView,
    _adj_face: &mut I,
    adj_u: &mut f32,
    adj_v: &mut f32,
    adj_ret: Vec3,
) -> KResult<()> {
    if let Some([a, b, c]) = mesh.triangle_velocities(face)? {
        *adj_u += (a - c).dot(adj_ret);
        *adj_v += (b - c).dot(adj_ret);
    }
    Ok(())
}

/// The gradient of a found closest point's `(u, v)` with respect to the query point, applied
/// to `adj_ret` (Warp's `adj_mesh_query_point_no_sign`: through the closest point of the face
/// the forward query finds, recomputed here).
fn adj_closest(c: &Closest<'_>, adj_point: &mut Vec3, adj_ret: MeshQueryPoint) {
    let [a, b, cc] = c.tri;
    let g = TriangleClosestPoint {
        u: adj_ret.u,
        v: adj_ret.v,
        w: 0.0,
        feature: TriFeature::Face,
    };
    let mut unused = [Vec3::ZERO; 3];
    let [x, y, z] = &mut unused;
    super::geometry::adj_closest_point_triangle(a, b, cc, c.p, x, y, z, adj_point, g);
}

/// Adjoint of [`mesh_query_point_no_sign`] with respect to the query point: the barycentrics'
/// gradient (zero when the closest point is a vertex, along the edge on an edge, the
/// projection onto the face inside it). `sign`, `face`, `result` and `max_dist` have none.
#[inline]
pub fn adj_mesh_query_point_no_sign(
    mesh: MeshView,
    point: Vec3,
    max_dist: f32,
    _adj_mesh: &mut MeshView,
    adj_point: &mut Vec3,
    _adj_max_dist: &mut f32,
    adj_ret: MeshQueryPoint,
) -> KResult<()> {
    if let Some(c) = closest(&mesh, point, max_dist)? {
        adj_closest(&c, adj_point, adj_ret);
    }
    Ok(())
}

/// The adjoints of the signed point queries with respect to the query point: the unsigned
/// query's ([`adj_mesh_query_point_no_sign`]), since the sign is piecewise constant and the
/// closest point is the same.
macro_rules! signed_query_adjoints {
    ($($name:ident: $query:literal;)*) => {$(
        #[doc = concat!(
            "Adjoint of [`", $query, "`] with respect to the query point, as ",
            "[`adj_mesh_query_point_no_sign`] (the sign is piecewise constant)."
        )]
        #[inline]
        pub fn $name(
            mesh: MeshView,
            point: Vec3,
            max_dist: f32,
            adj_mesh: &mut MeshView,
            adj_point: &mut Vec3,
            adj_max_dist: &mut f32,
            adj_ret: MeshQueryPoint,
        ) -> KResult<()> {
            adj_mesh_query_point_no_sign(
                mesh,
                point,
                max_dist,
                adj_mesh,
                adj_point,
                adj_max_dist,
                adj_ret,
            )
        }
    )*};
}

signed_query_adjoints! {
    adj_mesh_query_point: "mesh_query_point";
    adj_mesh_query_point_sign_normal: "mesh_query_point_sign_normal";
    adj_mesh_query_point_sign_parity: "mesh_query_point_sign_parity";
}

/// Adjoint of [`mesh_query_furthest_point_no_sign`]: nothing (the furthest point is a vertex,
/// whose barycentrics do not move with the query point).
#[inline]
pub fn adj_mesh_query_furthest_point_no_sign(
    _mesh: MeshView,
    _point: Vec3,
    _min_dist: f32,
    _adj_mesh: &mut MeshView,
    _adj_point: &mut Vec3,
    _adj_min_dist: &mut f32,
    _adj_ret: MeshQueryPoint,
) -> KResult<()> {
    Ok(())
}

// A mesh carries no gradient: the placeholder is the empty mesh; the box query's state
// carries none either (what depends on it, the faces, are indices).
no_gradient!(
    MeshView = MeshView::empty(),
    MeshQueryAabb = MeshQueryAabb::default(),
);

/// Accumulates the float fields (`sign`, `u`, `v`); `result` and `face` have none.
impl crate::adjoint::Adjoint for MeshQueryPoint {
    fn adj_zero() -> Self {
        MeshQueryPoint::default()
    }
    fn adj_accum(&mut self, o: Self) {
        self.sign += o.sign;
        self.u += o.u;
        self.v += o.v;
    }
}

/// Accumulates the float fields (`sign`, `t`, `u`, `v`, `normal`); `result` and `face` have
/// none.
impl crate::adjoint::Adjoint for MeshQueryRay {
    fn adj_zero() -> Self {
        MeshQueryRay::default()
    }
    fn adj_accum(&mut self, o: Self) {
        self.sign += o.sign;
        self.t += o.t;
        self.u += o.u;
        self.v += o.v;
        self.normal += o.normal;
    }
}

/// Accumulates `u`, `v`, `w`; the feature has none.
impl crate::adjoint::Adjoint for TriangleClosestPoint {
    fn adj_zero() -> Self {
        TriangleClosestPoint::default()
    }
    fn adj_accum(&mut self, o: Self) {
        self.u += o.u;
        self.v += o.v;
        self.w += o.w;
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::super::bvh::tests::Built;
    use super::super::geometry::tests::Rng;
    use super::super::geometry::{closest_point_triangle, intersect_ray_triangle};
    use super::*;

    /// A mesh and a tree over its triangles' boxes.
    pub(crate) struct TestMesh {
        pub points: Vec<Vec3>,
        pub velocities: Vec<Vec3>,
        pub indices: Vec<i32>,
        pub built: Built,
        /// The triangles in leaf order, made by `view` from the points as they are then.
        pub leaf_tris: Vec<Vec4>,
    }

    impl TestMesh {
        pub fn new(points: Vec<Vec3>, indices: Vec<i32>, leaf: usize) -> TestMesh {
            let (mut lo, mut hi) = (Vec::new(), Vec::new());
            for t in indices.chunks(3) {
                let [a, b, c] = [0, 1, 2].map(|k| points[t[k] as usize]);
                lo.push(a.min(b).min(c));
                hi.push(a.max(b).max(c));
            }
            let velocities = points
                .iter()
                .map(|p| Vec3::new(p.y, -p.x, 2.0 * p.z))
                .collect();
            TestMesh {
                points,
                velocities,
                indices,
                built: Built::new(&lo, &hi, leaf),
                leaf_tris: Vec::new(),
            }
        }

        /// The leaf-ordered triangles of the current points (what a refit writes).
        fn leaf_view(&mut self) -> ArrayView<Vec4, 1> {
            self.leaf_tris = vec![Vec4::ZERO; self.indices.len()];
            write_leaf_triangles(
                &mut self.leaf_tris,
                &self.built.prim_ids,
                &self.indices,
                &self.points,
            );
            unsafe {
                ArrayView::new(
                    self.leaf_tris.as_mut_ptr(),
                    [self.leaf_tris.len()],
                    [1],
                    "k",
                    "mesh",
                )
            }
        }

        pub fn view(&mut self) -> MeshView {
            let tree = self.built.tree();
            let v = |d: &mut Vec<Vec3>| unsafe {
                ArrayView::new(d.as_mut_ptr(), [d.len()], [1], "k", "mesh")
            };
            let ix = unsafe {
                ArrayView::new(
                    self.indices.as_mut_ptr(),
                    [self.indices.len()],
                    [1],
                    "k",
                    "mesh",
                )
            };
            let lt = self.leaf_view();
            let vel = v(&mut self.velocities);
            MeshView::new(tree, v(&mut self.points), Some(vel), ix, lt)
        }

        fn tri(&self, f: usize) -> [Vec3; 3] {
            [0, 1, 2].map(|k| self.points[self.indices[3 * f + k] as usize])
        }
    }

    /// A UV sphere of radius `r`: `rings` latitude bands, `segs` longitude segments, welded,
    /// outward-facing.
    pub(crate) fn sphere(r: f32, rings: usize, segs: usize) -> (Vec<Vec3>, Vec<i32>) {
        let mut pts = vec![Vec3::new(0.0, 0.0, r)];
        for i in 1..rings {
            let th = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segs {
                let ph = 2.0 * std::f32::consts::PI * j as f32 / segs as f32;
                pts.push(Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * r);
            }
        }
        pts.push(Vec3::new(0.0, 0.0, -r));
        let south = pts.len() as i32 - 1;
        let at = |i: usize, j: usize| (1 + (i - 1) * segs + j % segs) as i32;
        let mut ix = Vec::new();
        for j in 0..segs {
            ix.extend([0, at(1, j), at(1, j + 1)]);
            ix.extend([south, at(rings - 1, j + 1), at(rings - 1, j)]);
        }
        for i in 1..rings - 1 {
            for j in 0..segs {
                ix.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                ix.extend([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        (pts, ix)
    }

    /// A torus around z: major radius `big`, minor `small`, outward-facing.
    pub(crate) fn torus(big: f32, small: f32, n: usize, m: usize) -> (Vec<Vec3>, Vec<i32>) {
        let mut pts = Vec::new();
        for i in 0..n {
            let a = 2.0 * std::f32::consts::PI * i as f32 / n as f32;
            for j in 0..m {
                let b = 2.0 * std::f32::consts::PI * j as f32 / m as f32;
                let rr = big + small * b.cos();
                pts.push(Vec3::new(rr * a.cos(), rr * a.sin(), small * b.sin()));
            }
        }
        let at = |i: usize, j: usize| ((i % n) * m + j % m) as i32;
        let mut ix = Vec::new();
        for i in 0..n {
            for j in 0..m {
                ix.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                ix.extend([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        (pts, ix)
    }

    /// A `k x k` patch of the plane z = 0 over `[-1, 1]^2`, normals +z.
    pub(crate) fn patch(k: usize) -> (Vec<Vec3>, Vec<i32>) {
        let mut pts = Vec::new();
        for i in 0..=k {
            for j in 0..=k {
                pts.push(Vec3::new(
                    -1.0 + 2.0 * j as f32 / k as f32,
                    -1.0 + 2.0 * i as f32 / k as f32,
                    0.0,
                ));
            }
        }
        let at = |i: usize, j: usize| (i * (k + 1) + j) as i32;
        let mut ix = Vec::new();
        for i in 0..k {
            for j in 0..k {
                ix.extend([at(i, j), at(i, j + 1), at(i + 1, j + 1)]);
                ix.extend([at(i, j), at(i + 1, j + 1), at(i + 1, j)]);
            }
        }
        (pts, ix)
    }

    fn signed_volume(pts: &[Vec3], ix: &[i32]) -> f32 {
        ix.chunks(3)
            .map(|t| pts[t[0] as usize].dot(pts[t[1] as usize].cross(pts[t[2] as usize])) / 6.0)
            .sum()
    }

    fn soup(rng: &mut Rng, n: usize) -> (Vec<Vec3>, Vec<i32>) {
        let mut pts = Vec::new();
        let mut ix = Vec::new();
        for f in 0..n {
            let c = rng.v(-5.0, 5.0);
            for _ in 0..3 {
                pts.push(c + rng.v(-1.0, 1.0));
            }
            ix.extend([3 * f as i32, 3 * f as i32 + 1, 3 * f as i32 + 2]);
        }
        // Some degenerate faces: a repeated vertex, a collinear one.
        if n > 4 {
            pts[4] = pts[3];
            pts[8] = pts[6] + (pts[7] - pts[6]) * 0.25;
        }
        (pts, ix)
    }

    /// Brute-force closest distance (f64 of the f32 closest points).
    fn brute_closest(m: &TestMesh, p: Vec3) -> f64 {
        (0..m.indices.len() / 3)
            .map(|f| {
                let [a, b, c] = m.tri(f);
                (closest_point_triangle(a, b, c, p)
                    .position(a, b, c)
                    .as_dvec3()
                    - p.as_dvec3())
                .length()
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Tolerance: the same per-triangle closest points as the brute force, so distances
    /// agree up to the tie-breaking among faces within rounding: `1e-6` of the scene scale.
    #[test]
    fn closest_and_furthest_match_brute_force() {
        let mut rng = Rng(21);
        for (n, leaf) in [(1usize, 1usize), (5, 2), (200, 1), (500, 4)] {
            let (pts, ix) = soup(&mut rng, n);
            let mut m = TestMesh::new(pts, ix, leaf);
            let v = m.view();
            for _ in 0..300 {
                let p = rng.v(-8.0, 8.0);
                let want = brute_closest(&m, p);
                for max_dist in [f32::MAX, 3.0, 0.5] {
                    let r = mesh_query_point_no_sign(v, p, max_dist).unwrap();
                    if want < max_dist as f64 - 1e-5 {
                        assert!(r.result, "{p} within {max_dist}: {want}");
                    } else if want > max_dist as f64 + 1e-5 {
                        assert!(!r.result, "{p} beyond {max_dist}: {want}");
                    }
                    if r.result {
                        let q = mesh_eval_position(v, r.face, r.u, r.v).unwrap();
                        let got = (q.as_dvec3() - p.as_dvec3()).length();
                        assert!((got - want).abs() <= 1e-5, "{got} vs {want}");
                        assert_eq!(r.sign, 0.0);
                    }
                }
                // Furthest: a vertex at the largest distance.
                let far = m
                    .points
                    .iter()
                    .map(|q| (q.as_dvec3() - p.as_dvec3()).length())
                    .fold(0.0, f64::max);
                let r = mesh_query_furthest_point_no_sign(v, p, 0.0).unwrap();
                assert!(r.result);
                let q = mesh_eval_position(v, r.face, r.u, r.v).unwrap();
                assert!(((q.as_dvec3() - p.as_dvec3()).length() - far).abs() <= 1e-5);
                assert!([(1.0, 0.0), (0.0, 1.0), (0.0, 0.0)].contains(&(r.u, r.v)));
                assert!(
                    !mesh_query_furthest_point_no_sign(v, p, far as f32 * 1.001)
                        .unwrap()
                        .result
                );
            }
            // Nothing within a non-positive or NaN distance.
            for d in [0.0, -1.0, f32::NAN] {
                assert!(!mesh_query_point_no_sign(v, Vec3::ZERO, d).unwrap().result);
                assert!(!mesh_query_point(v, Vec3::ZERO, d).unwrap().result);
            }
        }
    }

    #[test]
    fn ray_and_aabb_match_brute_force() {
        let mut rng = Rng(8);
        for (n, leaf) in [(1usize, 1usize), (300, 1), (700, 4)] {
            let (pts, ix) = soup(&mut rng, n);
            let mut m = TestMesh::new(pts, ix, leaf);
            let v = m.view();
            let mut hits = 0;
            for _ in 0..400 {
                let o = rng.v(-8.0, 8.0);
                let mut d = rng.v(-1.0, 1.0);
                if rng.below(4) == 0 {
                    d[rng.below(3)] = 0.0;
                }
                let max_t = if rng.below(2) == 0 {
                    f32::MAX
                } else {
                    rng.f(0.0, 10.0)
                };
                let want = (0..n)
                    .filter_map(|f| {
                        let [a, b, c] = m.tri(f);
                        let h = intersect_ray_triangle(o, d, a, b, c);
                        (h.result && h.t < max_t).then_some((h.t, f))
                    })
                    .min_by(|x, y| x.0.total_cmp(&y.0));
                let r = mesh_query_ray(v, o, d, max_t).unwrap();
                assert_eq!(r.result, want.is_some());
                if let Some((t, f)) = want {
                    hits += 1;
                    assert_eq!(r.t, t);
                    let [a, b, c] = m.tri(r.face as usize);
                    let h = intersect_ray_triangle(o, d, a, b, c);
                    assert!(h.result && h.t == t, "face {} vs {f}", r.face);
                    assert_eq!((r.u, r.v, r.sign), (h.u, h.v, h.sign));
                    assert!((r.normal - face_normal(a, b, c)).length() == 0.0);
                    let q = mesh_eval_position(v, r.face, r.u, r.v).unwrap();
                    assert!((q - (o + d * r.t)).length() <= 1e-4 * (1.0 + (o + d * r.t).length()));
                }
                // Box query against brute force.
                let (c, h) = (rng.v(-6.0, 6.0), rng.v(0.0, 2.0));
                let mut q = mesh_query_aabb(v, c - h, c + h).unwrap();
                let mut got = Vec::new();
                loop {
                    q = mesh_query_aabb_next(v, q).unwrap();
                    if mesh_query_aabb_done(q) {
                        break;
                    }
                    got.push(mesh_query_aabb_item(q));
                }
                got.sort_unstable();
                let want: Vec<i32> = (0..n as i32)
                    .filter(|f| {
                        let [a, b, cc] = m.tri(*f as usize);
                        aabb_overlap(a.min(b).min(cc), a.max(b).max(cc), c - h, c + h)
                    })
                    .collect();
                assert_eq!(got, want);
            }
            if n > 1 {
                assert!(hits > 20, "{hits}");
            }
        }
    }

    /// The signed query on closed meshes against the analytic solids. The mesh is a faceted
    /// approximation (chord error below 2% of the radius for these resolutions), so points
    /// within 5% of the analytic surface are skipped; the others must all be classified right.
    #[test]
    fn sign_on_closed_meshes() {
        let mut rng = Rng(1);
        let (pts, ix) = sphere(1.0, 24, 48);
        assert!(signed_volume(&pts, &ix) > 0.0);
        for k in [1.0f32, 1e30, 1e-30] {
            let scaled: Vec<Vec3> = pts.iter().map(|p| *p * k).collect();
            let mut m = TestMesh::new(scaled, ix.clone(), 2);
            let v = m.view();
            let mut n = 0;
            for _ in 0..3000 {
                let p = rng.v(-2.0, 2.0);
                let r = p.length();
                if (r - 1.0).abs() < 0.05 {
                    continue;
                }
                let q = mesh_query_point(v, p * k, f32::MAX).unwrap();
                assert!(q.result);
                assert_eq!(q.sign, if r < 1.0 { -1.0 } else { 1.0 }, "{p} at scale {k}");
                // The distance, in units of k.
                let d = (mesh_eval_position(v, q.face, q.u, q.v).unwrap() / k - p).length();
                assert!((d - (r - 1.0).abs()).abs() < 0.02, "{d} at {p}");
                n += 1;
            }
            assert!(n > 2000);
        }
        let (pts, ix) = torus(1.0, 0.4, 64, 32);
        assert!(signed_volume(&pts, &ix) > 0.0);
        let mut m = TestMesh::new(pts, ix, 4);
        let v = m.view();
        for _ in 0..5000 {
            let p = rng.v(-1.6, 1.6);
            let f = ((p.x * p.x + p.y * p.y).sqrt() - 1.0).hypot(p.z) - 0.4;
            if f.abs() < 0.02 {
                continue;
            }
            let q = mesh_query_point(v, p, f32::MAX).unwrap();
            assert_eq!(q.sign, if f < 0.0 { -1.0 } else { 1.0 }, "{p}");
        }
    }

    /// Points whose closest feature is a vertex or an edge (outside a convex corner, inside a
    /// concave one): the pseudonormal decides, where the nearest face alone would not.
    #[test]
    fn sign_at_vertices_and_edges() {
        // A unit cube (outward), points off its corners and edges.
        let pts: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let mut ix = Vec::new();
        for q in quads {
            ix.extend([q[0], q[1], q[2], q[0], q[2], q[3]]);
        }
        assert!(signed_volume(&pts, &ix) > 0.0);
        let mut m = TestMesh::new(pts.clone(), ix, 1);
        let v = m.view();
        let mut rng = Rng(17);
        for _ in 0..3000 {
            let p = rng.v(-0.5, 1.5);
            let inside = p.cmpgt(Vec3::ZERO).all() && p.cmplt(Vec3::ONE).all();
            let q = mesh_query_point(v, p, f32::MAX).unwrap();
            if p.min_element().abs() > 1e-3 && (p - Vec3::ONE).max_element().abs() > 1e-3 {
                assert_eq!(q.sign, if inside { -1.0 } else { 1.0 }, "{p}");
            }
        }
        // Exactly on vertices, edges and faces: distance 0, inside.
        for p in [
            Vec3::ZERO,
            Vec3::ONE,
            Vec3::new(0.5, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.3),
            Vec3::new(0.5, 0.5, 0.0),
        ] {
            let q = mesh_query_point(v, p, 1.0).unwrap();
            assert!(q.result && q.sign == -1.0, "{p}");
            assert!((mesh_eval_position(v, q.face, q.u, q.v).unwrap() - p).length() < 1e-6);
            let q = mesh_query_point_no_sign(v, p, 1e-3).unwrap();
            assert!(q.result, "{p}");
        }
    }

    /// Open meshes: a single triangle and a plane patch (normals +z): the side of the surface.
    #[test]
    fn sign_on_open_meshes() {
        let mut rng = Rng(23);
        let (pts, ix) = patch(6);
        let mut m = TestMesh::new(pts, ix, 2);
        let mut t = TestMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![0, 1, 2], 1);
        for v in [m.view(), t.view()] {
            for _ in 0..3000 {
                let p = rng.v(-2.0, 2.0);
                if p.z.abs() < 1e-4 {
                    continue;
                }
                let q = mesh_query_point(v, p, f32::MAX).unwrap();
                assert!(q.result);
                assert_eq!(q.sign, if p.z < 0.0 { -1.0 } else { 1.0 }, "{p}");
            }
        }
    }

    #[test]
    fn empty_mesh_and_faults() {
        let mut m = TestMesh::new(Vec::new(), Vec::new(), 1);
        for v in [m.view(), MeshView::empty()] {
            assert!(!mesh_query_point(v, Vec3::ZERO, f32::MAX).unwrap().result);
            assert!(
                !mesh_query_point_no_sign(v, Vec3::ZERO, f32::MAX)
                    .unwrap()
                    .result
            );
            assert!(
                !mesh_query_furthest_point_no_sign(v, Vec3::ZERO, 0.0)
                    .unwrap()
                    .result
            );
            assert!(
                !mesh_query_ray(v, Vec3::ZERO, Vec3::X, f32::MAX)
                    .unwrap()
                    .result
            );
            let inf = Vec3::splat(f32::INFINITY);
            let q = mesh_query_aabb_next(v, mesh_query_aabb(v, -inf, inf).unwrap()).unwrap();
            assert!(mesh_query_aabb_done(q));
            assert!(mesh_eval_position(v, 0, 0.3, 0.3).is_err());
        }
        // Bad face and vertex indices fault, naming the parameter.
        let (pts, ix) = sphere(1.0, 4, 6);
        let mut m = TestMesh::new(pts, ix, 1);
        let v = m.view();
        let e = mesh_eval_position(v, v.num_faces(), 0.3, 0.3).unwrap_err();
        assert!(e.to_string().contains("argument `mesh`"), "{e}");
        assert!(mesh_eval_face_normal(v, -1i32).is_err());
        m.indices[4] = 1000;
        let v = m.view();
        assert!(mesh_eval_velocity(v, 1, 0.0, 0.0).is_err());
        // The walks read the leaf-ordered copy, where that face's corners are NaN: it is
        // never reported (the runtime refuses such an index at a refit; this is a view made
        // over a corrupt mesh).
        let q = mesh_query_point_no_sign(v, Vec3::ZERO, f32::MAX).unwrap();
        assert!(q.result && q.face != 1, "{q:?}");
        let q = mesh_query_point_no_sign(v, m.points[m.indices[3] as usize], f32::MAX).unwrap();
        assert!(q.result && q.face != 1, "{q:?}");
    }

    #[test]
    fn eval_and_normals() {
        let (pts, ix) = sphere(2.0, 6, 8);
        let mut m = TestMesh::new(pts, ix, 1);
        let v = m.view();
        for f in 0..v.num_faces() {
            let [a, b, c] = m.tri(f);
            let p = mesh_eval_position(v, f, 0.2, 0.3).unwrap();
            assert!((p - (a * 0.2 + b * 0.3 + c * 0.5)).length() < 1e-6);
            let vel = mesh_eval_velocity(v, f, 0.2, 0.3).unwrap();
            let w = |q: Vec3| Vec3::new(q.y, -q.x, 2.0 * q.z);
            assert!((vel - (w(a) * 0.2 + w(b) * 0.3 + w(c) * 0.5)).length() < 1e-5);
            let n = mesh_eval_face_normal(v, f).unwrap();
            assert!(
                (n.length() - 1.0).abs() < 1e-6 && n.dot((a + b + c) / 3.0) > 0.0,
                "outward"
            );
        }
        // Without velocities: zero.
        let mut m2 = TestMesh::new(m.points.clone(), m.indices.clone(), 1);
        let tree = m2.built.tree();
        let pv =
            unsafe { ArrayView::new(m2.points.as_mut_ptr(), [m2.points.len()], [1], "k", "mesh") };
        let iv = unsafe {
            ArrayView::new(
                m2.indices.as_mut_ptr(),
                [m2.indices.len()],
                [1],
                "k",
                "mesh",
            )
        };
        let lt = m2.leaf_view();
        let v2 = MeshView::new(tree, pv, None, iv, lt);
        assert_eq!(mesh_eval_velocity(v2, 0, 0.2, 0.3).unwrap(), Vec3::ZERO);
        // A degenerate face's normal is zero.
        let mut d = TestMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0], vec![0, 1, 2], 1);
        assert_eq!(mesh_eval_face_normal(d.view(), 0).unwrap(), Vec3::ZERO);
    }

    /// Gradchecks of the barycentric adjoints: `mesh_eval_*` is linear in `(u, v)`, so the
    /// central difference with `h = 0.01` is exact up to f32 rounding of positions of
    /// magnitude ~2: about `2 * 2^-24 * 2 / 0.02 ≈ 1e-5`; tolerance `1e-4`. For the closest
    /// point query, the barycentrics are affine in the point within a feature's region (the
    /// same face found on both sides; other points skipped): same tolerance.
    #[test]
    fn gradchecks() {
        let (pts, ix) = sphere(2.0, 6, 8);
        let mut m = TestMesh::new(pts, ix, 2);
        let v = m.view();
        let mut rng = Rng(77);
        let h = 0.01f32;
        for f in 0..v.num_faces() as i32 {
            let (u, w) = (rng.f(0.0, 0.5), rng.f(0.0, 0.5));
            let g = rng.v(-1.0, 1.0);
            for vel in [false, true] {
                let eval = |u: f32, w: f32| {
                    if vel {
                        mesh_eval_velocity(v, f, u, w).unwrap()
                    } else {
                        mesh_eval_position(v, f, u, w).unwrap()
                    }
                };
                let nu = (eval(u + h, w) - eval(u - h, w)).dot(g) / (2.0 * h);
                let nv = (eval(u, w + h) - eval(u, w - h)).dot(g) / (2.0 * h);
                let (mut au, mut av) = (0.0, 0.0);
                let (mut am, mut af) = (MeshView::empty(), 0i32);
                if vel {
                    adj_mesh_eval_velocity(v, f, u, w, &mut am, &mut af, &mut au, &mut av, g)
                        .unwrap();
                } else {
                    adj_mesh_eval_position(v, f, u, w, &mut am, &mut af, &mut au, &mut av, g)
                        .unwrap();
                }
                assert!((nu - au).abs() <= 1e-4 * au.abs().max(1.0), "{nu} {au}");
                assert!((nv - av).abs() <= 1e-4 * av.abs().max(1.0), "{nv} {av}");
            }
        }
        let mut checked = 0;
        for _ in 0..2000 {
            let p = rng.v(-3.0, 3.0);
            let g = MeshQueryPoint {
                u: rng.f(-1.0, 1.0),
                v: rng.f(-1.0, 1.0),
                ..Default::default()
            };
            let q0 = mesh_query_point_no_sign(v, p, f32::MAX).unwrap();
            let mut num = Vec3::ZERO;
            let mut same = true;
            for k in 0..3 {
                let mut e = Vec3::ZERO;
                e[k] = h;
                let (qp, qm) = (
                    mesh_query_point_no_sign(v, p + e, f32::MAX).unwrap(),
                    mesh_query_point_no_sign(v, p - e, f32::MAX).unwrap(),
                );
                let [a, b, c] = m.tri(q0.face as usize);
                let feat = |x: Vec3| closest_point_triangle(a, b, c, x).feature;
                same &= qp.face == q0.face
                    && qm.face == q0.face
                    && feat(p + e) == feat(p)
                    && feat(p - e) == feat(p);
                num[k] = (g.u * (qp.u - qm.u) + g.v * (qp.v - qm.v)) / (2.0 * h);
            }
            if !same {
                continue;
            }
            let mut adj = Vec3::ZERO;
            let (mut am, mut ad) = (MeshView::empty(), 0.0);
            adj_mesh_query_point(v, p, f32::MAX, &mut am, &mut adj, &mut ad, g).unwrap();
            // The other signed queries' adjoints are the unsigned one's, bit for bit.
            for f in [
                adj_mesh_query_point_sign_normal,
                adj_mesh_query_point_sign_parity,
                adj_mesh_query_point_no_sign,
            ] {
                let mut other = Vec3::ZERO;
                f(v, p, f32::MAX, &mut am, &mut other, &mut ad, g).unwrap();
                assert_eq!(other, adj, "{p}");
            }
            assert!(
                (num - adj).abs().max_element() <= 1e-4 * adj.abs().max_element().max(1.0),
                "{num} {adj}"
            );
            checked += 1;
        }
        assert!(checked > 500, "{checked}");
    }

    /// A unit cube (outward), two triangles a side.
    fn cube() -> (Vec<Vec3>, Vec<i32>) {
        let pts: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let mut ix = Vec::new();
        for q in quads {
            ix.extend([q[0], q[1], q[2], q[0], q[2], q[3]]);
        }
        (pts, ix)
    }

    /// The parity sign on closed meshes (a sphere at three scales and turned inside out, a
    /// torus, a cube) against the analytic solids and the pseudonormal's sign, for points
    /// farther than a margin from the analytic surface: the sphere and the torus are faceted
    /// (chord error below 2% of the radius), so points within 5% of the sphere's radius or
    /// 0.02 of the torus's surface can lie on either side of the mesh; the cube is exact and
    /// its margin, 1e-3, only keeps points off its faces (where either sign is right). The
    /// closest point is the unsigned query's, bit for bit; `mesh_query_point_sign_normal` is
    /// `mesh_query_point`.
    #[test]
    fn sign_parity_on_closed_meshes() {
        let mut rng = Rng(41);
        let check = |v: MeshView, p: Vec3, outward: bool, want: Option<f32>| {
            let q = mesh_query_point_sign_parity(v, p, f32::MAX).unwrap();
            let u = mesh_query_point_no_sign(v, p, f32::MAX).unwrap();
            let n = mesh_query_point(v, p, f32::MAX).unwrap();
            assert_eq!(n, mesh_query_point_sign_normal(v, p, f32::MAX).unwrap());
            assert!(q.result && u.result);
            assert_eq!((q.face, q.u, q.v), (u.face, u.u, u.v), "{p}");
            if let Some(w) = want {
                assert_eq!(q.sign, w, "parity at {p}");
                // The pseudonormal flips with the faces; the parity does not.
                assert_eq!(n.sign, if outward { w } else { -w }, "pseudonormal at {p}");
            }
        };
        let (pts, ix) = sphere(1.0, 24, 48);
        let flipped: Vec<i32> = ix.chunks(3).flat_map(|t| [t[0], t[2], t[1]]).collect();
        for (k, ix, outward) in [
            (1.0f32, &ix, true),
            (1e30, &ix, true),
            (1e-30, &ix, true),
            (1.0, &flipped, false),
        ] {
            let scaled: Vec<Vec3> = pts.iter().map(|p| *p * k).collect();
            let mut m = TestMesh::new(scaled, ix.clone(), 2);
            let v = m.view();
            for _ in 0..1500 {
                let p = rng.v(-2.0, 2.0);
                let r = p.length();
                let want = ((r - 1.0).abs() >= 0.05).then_some(if r < 1.0 { -1.0 } else { 1.0 });
                check(v, p * k, outward, want);
            }
        }
        let (pts, ix) = torus(1.0, 0.4, 64, 32);
        let mut m = TestMesh::new(pts, ix, 4);
        let v = m.view();
        for _ in 0..3000 {
            let p = rng.v(-1.6, 1.6);
            let f = ((p.x * p.x + p.y * p.y).sqrt() - 1.0).hypot(p.z) - 0.4;
            let want = (f.abs() >= 0.02).then_some(if f < 0.0 { -1.0 } else { 1.0 });
            check(v, p, true, want);
        }
        let (pts, ix) = cube();
        let mut m = TestMesh::new(pts, ix, 1);
        let v = m.view();
        for _ in 0..3000 {
            let p = rng.v(-0.5, 1.5);
            let inside = p.cmpgt(Vec3::ZERO).all() && p.cmplt(Vec3::ONE).all();
            let off = p.min_element().abs() > 1e-3 && (p - Vec3::ONE).max_element().abs() > 1e-3;
            check(v, p, true, off.then_some(if inside { -1.0 } else { 1.0 }));
        }
    }

    /// Rays exactly through the cube's edges and vertices. The ray's sheared frame has the
    /// exact slopes `15/16` and `3/4`, so from a start
    /// `p` at a dyadic height the ray meets the plane z = 1 at a point known exactly. Through the diagonal of the top face the watertight hit test finds both
    /// halves (a parity counted with it would say outside); the tie-broken crossing counts
    /// one. Through a vertex or an edge where the ray leaves the cube: inside; where it only
    /// touches the cube: outside.
    #[test]
    fn sign_parity_through_edges_and_vertices() {
        assert!((PARITY_DIR * 0.64 - Vec3::new(0.6, 0.48, 0.64)).length() < 1e-7);
        let (pts, ix) = cube();
        let mut m = TestMesh::new(pts, ix, 1);
        let v = m.view();
        // The start at height z whose ray meets the plane z = 1 at (x, y).
        let through =
            |x: f32, y: f32, z: f32| Vec3::new(x - 0.9375 * (1.0 - z), y - 0.75 * (1.0 - z), z);
        // The top face's diagonal runs from (0, 0, 1) to (1, 1, 1).
        let p = through(0.5, 0.5, 0.5);
        let hits = (0..v.num_faces())
            .filter(|f| {
                let [a, b, c] = m.tri(*f);
                intersect_ray_triangle(p, PARITY_DIR, a, b, c).result
            })
            .count();
        assert_eq!(hits, 2);
        for (p, want) in [
            (p, -1.0),
            (through(1.0, 1.0, 0.5), -1.0), // leaves through the vertex (1, 1, 1)
            (through(1.0, 0.5, 0.5), -1.0), // through the edge x = z = 1
            (through(0.25, 0.25, 0.75), -1.0), // the diagonal again, elsewhere
            (through(1.0, 0.0, 0.5), 1.0),  // touches the vertex (1, 0, 1) only
            (through(0.5, 0.0, 0.5), 1.0),  // touches the edge y = 0, z = 1 only
            (through(0.0, 1.0, 0.5), 1.0),  // touches the vertex (0, 1, 1) only
        ] {
            let q = mesh_query_point_sign_parity(v, p, f32::MAX).unwrap();
            assert!(q.result);
            assert_eq!(q.sign, want, "{p}");
        }
    }

    /// Open meshes: the one ray decides (a patch of the plane z = 0 over [-1, 1]^2); far
    /// points, outside the root box; nothing found gives sign 0; corrupt meshes fault as the
    /// other queries do.
    #[test]
    fn sign_parity_open_far_and_faults() {
        let (pts, ix) = patch(4);
        let mut m = TestMesh::new(pts, ix, 2);
        let v = m.view();
        for (p, want) in [
            (Vec3::new(0.0, 0.0, -0.1), -1.0), // its ray leaves through the patch
            (Vec3::new(-0.9, -0.9, -2.0), -1.0), // meets z = 0 at (0.975, 0.6)
            (Vec3::new(0.9, 0.0, -1.0), 1.0),  // meets z = 0 at x = 1.8, beside it
            (Vec3::new(0.0, 0.0, 0.1), 1.0),
        ] {
            let q = mesh_query_point_sign_parity(v, p, f32::MAX).unwrap();
            assert!(q.result);
            assert_eq!(q.sign, want, "{p}");
        }
        // Outside the root box: a ray through the whole sphere crosses it twice.
        let (pts, ix) = sphere(1.0, 12, 24);
        let mut m = TestMesh::new(pts, ix, 2);
        let v = m.view();
        for p in [Vec3::splat(10.0), -PARITY_DIR * 10.0, -PARITY_DIR * 1e30] {
            let q = mesh_query_point_sign_parity(v, p, f32::MAX).unwrap();
            assert!(q.result && q.sign == 1.0, "{p}: {q:?}");
        }
        // Nothing within max_dist: as the other queries, sign 0.
        for d in [0.5, 0.0, -1.0, f32::NAN] {
            let q = mesh_query_point_sign_parity(v, Vec3::splat(10.0), d).unwrap();
            assert_eq!(q, MeshQueryPoint::default());
        }
        let mut e = TestMesh::new(Vec::new(), Vec::new(), 1);
        for v in [e.view(), MeshView::empty()] {
            let q = mesh_query_point_sign_parity(v, Vec3::ZERO, f32::MAX).unwrap();
            assert_eq!(q, MeshQueryPoint::default());
        }
        // A corrupt prim_ids entry faults, naming the parameter, when the walk's result is
        // mapped to its face (the walks read triangles by leaf position): here every
        // position's, so whichever wins.
        let (pts, ix) = sphere(1.0, 4, 6);
        let mut m = TestMesh::new(pts, ix, 1);
        let v = m.view();
        let n = m.built.prim_ids.len() as i32;
        m.built.prim_ids.iter_mut().for_each(|i| *i += n);
        let bad = MeshView {
            tree: m.built.tree(),
            ..v
        };
        for p in [Vec3::ZERO, -Vec3::Z - PARITY_DIR * 2.0] {
            // (This view's tree keeps the test tree's parameter name.)
            let e = mesh_query_point_sign_parity(bad, p, f32::MAX).unwrap_err();
            assert!(e.to_string().contains("out of bounds"), "{e}");
            assert!(mesh_query_point_no_sign(bad, p, f32::MAX).is_err());
            assert!(mesh_query_point_sign_normal(bad, p, f32::MAX).is_err());
        }
    }

    /// The closest search's visit: a face whose box is no nearer than the best is skipped, a
    /// face whose box is nearer is computed (and kept only when it is nearer itself).
    #[test]
    fn closest_skips_faces_by_their_box() {
        let pts = vec![
            // Face 0: in z = 0 over [0, 1]^2.
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            // Face 1: the same, moved to x = 3.
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(3.0, 1.0, 0.0),
            // Face 2: in the plane x + y = 0, its box [-1, 1]^2 x [1, 1.5] holding p.
            Vec3::new(-1.0, 1.0, 1.0),
            Vec3::new(1.0, -1.0, 1.0),
            Vec3::new(1.0, -1.0, 1.5),
        ];
        let mut m = TestMesh::new(pts, (0..9).collect(), 4);
        // One leaf over the three faces in order: `visit` takes a position in prim_ids,
        // which is then the face.
        assert_eq!(m.built.prim_ids, [0, 1, 2]);
        let v = m.view();
        let p = Vec3::new(0.25, 0.25, 1.0);
        let search = |best: f32| Closest {
            mesh: &v,
            p,
            s: 1.0,
            best,
            face: -1,
            bary: TriangleClosestPoint::default(),
            tri: [Vec3::ZERO; 3],
        };
        // Face 1's box is at squared distance 2.75^2 + 1: skipped below that.
        let box1 =
            aabb_distance_sq_scaled(p, Vec3::new(3.0, 0.0, 0.0), Vec3::new(4.0, 1.0, 0.0), 1.0);
        assert_eq!(box1, 2.75 * 2.75 + 1.0);
        let mut c = search(box1);
        c.visit(1).unwrap();
        assert_eq!((c.face, c.best), (-1, box1));
        // Just above it, face 1 is computed: its distance is its box's (p is over the box's
        // corner region), so it is not below the bound either.
        let mut c = search(box1 * (1.0 + f32::EPSILON));
        c.visit(1).unwrap();
        assert_eq!((c.face, c.best), (1, box1));
        // Face 2's box holds p (key 0), but the face's nearest point to p is (0, 0, 1), on its
        // edge ab, at squared distance 0.125: computed and rejected under a bound of 0.1,
        // kept under 1.
        let d2 = 0.125;
        let mut c = search(0.1);
        c.visit(2).unwrap();
        assert_eq!(c.face, -1);
        let mut c = search(1.0);
        c.visit(2).unwrap();
        assert_eq!(c.face, 2);
        assert!((c.best - d2).abs() < 1e-6, "{}", c.best);
        // Face 0 under p at height 1: kept with its barycentrics, u * a + v * b + w * c = p's
        // foot (0.25, 0.25, 0).
        let mut c = search(1.5);
        c.visit(0).unwrap();
        assert_eq!((c.face, c.best), (0, 1.0));
        assert_eq!((c.bary.u, c.bary.v, c.bary.w), (0.5, 0.25, 0.25));
        // The query over all three: face 2 is nearest.
        let r = mesh_query_point_no_sign(v, p, f32::MAX).unwrap();
        assert_eq!(r.face, 2);
    }

    /// A mesh of extent 1e-20 at x = 1e20: the query's unit (the extent around the point,
    /// about 2^67) times the point's x overflows f32, so boxes must be measured from the
    /// unscaled offsets (as `aabb_distance_sq_scaled` does) for the mesh to be found at all.
    #[test]
    fn closest_on_a_tiny_mesh_far_from_the_origin() {
        let pts = vec![
            Vec3::new(1e20, 0.0, 0.0),
            Vec3::new(1e20, 1e-20, 0.0),
            Vec3::new(1e20, 0.0, 1e-20),
        ];
        let mut m = TestMesh::new(pts, vec![0, 1, 2], 1);
        let v = m.view();
        let p = Vec3::new(1e20, 2.5e-21, 2.5e-21);
        assert!(p.x * v.measure_scale(p).unwrap() == f32::INFINITY);
        let r = mesh_query_point_no_sign(v, p, f32::MAX).unwrap();
        assert!(r.result);
        // p lies on the face at u * a + v * b + w * c with v = w = 0.25 (to 1e-6: the edges
        // are 1e-20 rounded to f32).
        assert_eq!(r.face, 0);
        assert!(
            (r.u - 0.5).abs() < 1e-6 && (r.v - 0.25).abs() < 1e-6,
            "{r:?}"
        );
        // Beside the face in its plane: the nearest point is on edge ca, at w = 0.25.
        let q = Vec3::new(1e20, -1e-20, 2.5e-21);
        let r = mesh_query_point_no_sign(v, q, f32::MAX).unwrap();
        assert!(r.result && r.face == 0);
        assert!((r.v).abs() < 1e-6 && (r.u - 0.75).abs() < 1e-6, "{r:?}");
    }
}

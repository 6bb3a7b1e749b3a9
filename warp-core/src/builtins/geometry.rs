//! The BVH and mesh builtins (sections "bvh", "mesh", "geometry" of the builtin table): thin
//! adapters from the kernel language's calling convention to the queries of
//! [`objects::bvh`](crate::objects::bvh), [`objects::mesh`](crate::objects::mesh) and
//! [`objects::geometry`](crate::objects::geometry), which hold the algorithms.
//!
//! The adaptations:
//! - Results that Warp returns through output arguments (or as a struct) are tuples here, in
//!   the order of Warp's struct fields, bound by a destructuring `let`:
//!   `let (result, sign, face, u, v) = mesh_query_point(mesh, p, max_dist);` and
//!   `let (result, sign, face, t, u, v, normal) = mesh_query_ray(mesh, start, dir, max_t);`.
//! - Primitive and face indices are `i32` (Warp's `int`), the loop variable of
//!   `for i in bvh_query_aabb(..)` included (the query steps are re-exported unchanged).
//! - `closest_point_triangle(a, b, c, p)` gives the barycentrics `(u, v, w)` as a `Vec3`
//!   (an extension: Warp's is internal to its mesh queries).
//!
//! The adjoints are in [`crate::adjoint`] (`adj_mesh_query_point`, ...), each through the
//! object's own adjoint.

use glam::Vec3;

use crate::objects::{geometry, mesh, MeshView};
use crate::KResult;

pub use crate::objects::bvh::{
    bvh_query_aabb, bvh_query_aabb_done, bvh_query_aabb_item, bvh_query_aabb_next, bvh_query_ray,
    bvh_query_ray_done, bvh_query_ray_item, bvh_query_ray_next,
};
pub use crate::objects::geometry::intersect_tri_tri;
pub use crate::objects::mesh::{
    mesh_eval_face_normal, mesh_eval_position, mesh_eval_velocity, mesh_query_aabb,
    mesh_query_aabb_done, mesh_query_aabb_item, mesh_query_aabb_next,
};

/// A point query's result as the kernel language binds it: `(result, sign, face, u, v)`.
pub type PointResult = (bool, f32, i32, f32, f32);

/// A ray query's result as the kernel language binds it:
/// `(result, sign, face, t, u, v, normal)`.
pub type RayResult = (bool, f32, i32, f32, f32, f32, Vec3);

/// The tuple of a point query's struct.
#[inline(always)]
pub fn point_tuple(r: mesh::MeshQueryPoint) -> PointResult {
    (r.result, r.sign, r.face, r.u, r.v)
}

/// The struct of a point query's tuple (for the adjoints).
#[inline(always)]
pub fn point_struct(t: PointResult) -> mesh::MeshQueryPoint {
    mesh::MeshQueryPoint {
        result: t.0,
        sign: t.1,
        face: t.2,
        u: t.3,
        v: t.4,
    }
}

/// Warp's `mesh_query_point`: the closest point within `max_dist`, signed.
#[inline(always)]
pub fn mesh_query_point(m: MeshView, point: Vec3, max_dist: f32) -> KResult<PointResult> {
    mesh::mesh_query_point(m, point, max_dist).map(point_tuple)
}

/// Warp's `mesh_query_point_no_sign`: the closest point within `max_dist` (`sign` 0).
#[inline(always)]
pub fn mesh_query_point_no_sign(m: MeshView, point: Vec3, max_dist: f32) -> KResult<PointResult> {
    mesh::mesh_query_point_no_sign(m, point, max_dist).map(point_tuple)
}

/// Warp's `mesh_query_point_sign_normal`: `mesh_query_point` under Warp's name for its sign
/// (the angle-weighted pseudonormal).
#[inline(always)]
pub fn mesh_query_point_sign_normal(
    m: MeshView,
    point: Vec3,
    max_dist: f32,
) -> KResult<PointResult> {
    mesh::mesh_query_point_sign_normal(m, point, max_dist).map(point_tuple)
}

/// Warp's `mesh_query_point_sign_parity`: the closest point within `max_dist`, signed by the
/// parity of the faces one ray from `point` crosses.
#[inline(always)]
pub fn mesh_query_point_sign_parity(
    m: MeshView,
    point: Vec3,
    max_dist: f32,
) -> KResult<PointResult> {
    mesh::mesh_query_point_sign_parity(m, point, max_dist).map(point_tuple)
}

/// Warp's `mesh_query_furthest_point_no_sign`: the furthest point beyond `min_dist`.
#[inline(always)]
pub fn mesh_query_furthest_point_no_sign(
    m: MeshView,
    point: Vec3,
    min_dist: f32,
) -> KResult<PointResult> {
    mesh::mesh_query_furthest_point_no_sign(m, point, min_dist).map(point_tuple)
}

/// Warp's `mesh_query_ray`: the first hit at `0 <= t < max_t`.
#[inline(always)]
pub fn mesh_query_ray(m: MeshView, start: Vec3, dir: Vec3, max_t: f32) -> KResult<RayResult> {
    let r = mesh::mesh_query_ray(m, start, dir, max_t)?;
    Ok((r.result, r.sign, r.face, r.t, r.u, r.v, r.normal))
}

/// The closest point of triangle `(a, b, c)` to `p` as barycentrics `(u, v, w)`: the point is
/// `u * a + v * b + w * c` (see [`geometry::closest_point_triangle`]).
#[inline(always)]
pub fn closest_point_triangle(a: Vec3, b: Vec3, c: Vec3, p: Vec3) -> Vec3 {
    let r = geometry::closest_point_triangle(a, b, c, p);
    Vec3::new(r.u, r.v, r.w)
}

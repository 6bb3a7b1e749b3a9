//! Adjoints of the BVH and mesh builtins ([`crate::builtins::geometry`]), each through the
//! object's own adjoint in [`crate::objects::mesh`] or [`crate::objects::geometry`]:
//!
//! * `mesh_query_point`, `mesh_query_point_no_sign`, `mesh_query_point_sign_normal`,
//!   `mesh_query_point_sign_parity`: the query point's adjoint through the
//!   barycentrics `u`, `v` of the closest point (zero at a vertex, along the edge on an edge,
//!   the projection onto the face inside it); `result`, `sign` and `face` have none, nor do
//!   the mesh and `max_dist`.
//! * `mesh_query_furthest_point_no_sign`: none (the furthest point is a vertex).
//! * `mesh_eval_position`, `mesh_eval_velocity`: `u` and `v`'s (the points and velocities get
//!   none, as in Warp).
//! * `closest_point_triangle`: the query point's, through `(u, v, w)` (the vertices get none).
//!
//! Like the forward queries these read the mesh's buffers, so they return a `KResult` (a fault
//! naming the mesh's parameter) and the adjoint code calls them with `?`.

use glam::Vec3;

use crate::builtins::geometry::{point_struct, PointResult};
use crate::objects::geometry::{self, TriFeature, TriangleClosestPoint};
use crate::objects::{mesh, MeshView};
use crate::{KResult, KernelIndex};

// One function written out per builtin (not made by a macro): `tests/architecture.rs` finds
// each builtin's adjoint here by name.

/// Adjoint of `mesh_query_point` with respect to the query point (module docs).
#[inline]
pub fn adj_mesh_query_point(
    m: MeshView,
    point: Vec3,
    max_dist: f32,
    adj_mesh: &mut MeshView,
    adj_point: &mut Vec3,
    adj_max_dist: &mut f32,
    adj_ret: PointResult,
) -> KResult<()> {
    mesh::adj_mesh_query_point(
        m,
        point,
        max_dist,
        adj_mesh,
        adj_point,
        adj_max_dist,
        point_struct(adj_ret),
    )
}

/// Adjoint of `mesh_query_point_no_sign` with respect to the query point (module docs).
#[inline]
pub fn adj_mesh_query_point_no_sign(
    m: MeshView,
    point: Vec3,
    max_dist: f32,
    adj_mesh: &mut MeshView,
    adj_point: &mut Vec3,
    adj_max_dist: &mut f32,
    adj_ret: PointResult,
) -> KResult<()> {
    mesh::adj_mesh_query_point_no_sign(
        m,
        point,
        max_dist,
        adj_mesh,
        adj_point,
        adj_max_dist,
        point_struct(adj_ret),
    )
}

/// Adjoint of `mesh_query_point_sign_normal` with respect to the query point (module docs).
#[inline]
pub fn adj_mesh_query_point_sign_normal(
    m: MeshView,
    point: Vec3,
    max_dist: f32,
    adj_mesh: &mut MeshView,
    adj_point: &mut Vec3,
    adj_max_dist: &mut f32,
    adj_ret: PointResult,
) -> KResult<()> {
    mesh::adj_mesh_query_point_sign_normal(
        m,
        point,
        max_dist,
        adj_mesh,
        adj_point,
        adj_max_dist,
        point_struct(adj_ret),
    )
}

/// Adjoint of `mesh_query_point_sign_parity` with respect to the query point (module docs).
#[inline]
pub fn adj_mesh_query_point_sign_parity(
    m: MeshView,
    point: Vec3,
    max_dist: f32,
    adj_mesh: &mut MeshView,
    adj_point: &mut Vec3,
    adj_max_dist: &mut f32,
    adj_ret: PointResult,
) -> KResult<()> {
    mesh::adj_mesh_query_point_sign_parity(
        m,
        point,
        max_dist,
        adj_mesh,
        adj_point,
        adj_max_dist,
        point_struct(adj_ret),
    )
}

/// Adjoint of `mesh_eval_position` with respect to `u` and `v`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn adj_mesh_eval_position<I: KernelIndex<1>>(
    m: MeshView,
    face: I,
    u: f32,
    v: f32,
    adj_mesh: &mut MeshView,
    adj_face: &mut I,
    adj_u: &mut f32,
    adj_v: &mut f32,
    adj_ret: Vec3,
) -> KResult<()> {
    mesh::adj_mesh_eval_position(m, face, u, v, adj_mesh, adj_face, adj_u, adj_v, adj_ret)
}

/// Adjoint of `mesh_eval_velocity` with respect to `u` and `v`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn adj_mesh_eval_velocity<I: KernelIndex<1>>(
    m: MeshView,
    face: I,
    u: f32,
    v: f32,
    adj_mesh: &mut MeshView,
    adj_face: &mut I,
    adj_u: &mut f32,
    adj_v: &mut f32,
    adj_ret: Vec3,
) -> KResult<()> {
    mesh::adj_mesh_eval_velocity(m, face, u, v, adj_mesh, adj_face, adj_u, adj_v, adj_ret)
}

/// Adjoint of `closest_point_triangle` with respect to the query point `p` (the vertices get
/// none).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn adj_closest_point_triangle(
    a: Vec3,
    b: Vec3,
    c: Vec3,
    p: Vec3,
    adj_a: &mut Vec3,
    adj_b: &mut Vec3,
    adj_c: &mut Vec3,
    adj_p: &mut Vec3,
    adj_ret: Vec3,
) {
    let g = TriangleClosestPoint {
        u: adj_ret.x,
        v: adj_ret.y,
        w: adj_ret.z,
        feature: TriFeature::Face,
    };
    geometry::adj_closest_point_triangle(a, b, c, p, adj_a, adj_b, adj_c, adj_p, g);
}

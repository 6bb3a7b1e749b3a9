//! Spatial queries and geometry: the hash grid, the BVH, the mesh and triangles (sections
//! "hash_grid", "bvh", "mesh", "geometry").

use super::*;

/// The host objects' queries and the triangle tests.
pub(super) const ROWS: &[Builtin] = rows! {
    // Warp's hash grid (warp-core `objects::hash_grid`, wp_hash_grid.h). A query is iterated
    // where it is made, `for j in hash_grid_query(grid, p, r) { .. }`, which
    // `front::lower::query` lowers to the query's state and its steps (Warp's
    // `hash_grid_query_next` is the loop): `next` is a pure function of the grid and the state,
    // written back to the state each iteration, so the adjoint replays the loop like any other
    // and the body's reads get their gradients. Indices are `usize` (Warp's `int`).
    "hash_grid_query": NO_T, (GRID, VEC3, F32) -> GRID_QUERY, "hash_grid", Zero,
        iterate("hash_grid_query_next", "hash_grid_query_done", "hash_grid_query_point"),
        item_bound("wp::hash_grid_item_bound");
    "hash_grid_query_next": NO_T, (GRID, GRID_QUERY) -> GRID_QUERY, "hash_grid", Zero, internal;
    "hash_grid_query_done": NO_T, (GRID_QUERY) -> BOOL, "hash_grid", Zero, internal;
    "hash_grid_query_point": NO_T, (GRID_QUERY) -> USIZE, "hash_grid", Zero, internal;
    "hash_grid_point_id": NO_T, (GRID, Index) -> USIZE, "hash_grid", Zero;
    // Warp's BVH and mesh (warp-core `objects::{bvh, mesh}` through `builtins::geometry`;
    // wp_bvh.h, wp_mesh.h). The iterating queries are `for` loops as the hash grid's; their
    // items, like every primitive and face index here, are `i32` (Warp's `int`). Results Warp
    // returns as a struct are tuples in its field order, bound by a destructuring `let`. The
    // point queries' adjoints give the query point's gradient through `u`, `v`; the
    // evaluations' give `u`'s and `v`'s; the objects get none.
    "bvh_query_aabb": NO_T, (BVH, VEC3, VEC3) -> BVH_AABB, "bvh", Zero,
        iterate("bvh_query_aabb_next", "bvh_query_aabb_done", "bvh_query_aabb_item"),
        item_bound("wp::bvh_item_bound");
    "bvh_query_aabb_next": NO_T, (BVH, BVH_AABB) -> BVH_AABB, "bvh", Zero, internal;
    "bvh_query_aabb_done": NO_T, (BVH_AABB) -> BOOL, "bvh", Zero, internal;
    "bvh_query_aabb_item": NO_T, (BVH_AABB) -> I32, "bvh", Zero, internal;
    "bvh_query_ray": NO_T, (BVH, VEC3, VEC3) -> BVH_RAY, "bvh", Zero,
        iterate("bvh_query_ray_next", "bvh_query_ray_done", "bvh_query_ray_item"),
        item_bound("wp::bvh_item_bound");
    "bvh_query_ray_next": NO_T, (BVH, BVH_RAY) -> BVH_RAY, "bvh", Zero, internal;
    "bvh_query_ray_done": NO_T, (BVH_RAY) -> BOOL, "bvh", Zero, internal;
    "bvh_query_ray_item": NO_T, (BVH_RAY) -> I32, "bvh", Zero, internal;
    "mesh_query_aabb": NO_T, (MESH, VEC3, VEC3) -> MESH_AABB, "mesh", Zero,
        iterate("mesh_query_aabb_next", "mesh_query_aabb_done", "mesh_query_aabb_item"),
        item_bound("wp::mesh_item_bound");
    "mesh_query_aabb_next": NO_T, (MESH, MESH_AABB) -> MESH_AABB, "mesh", Zero, internal;
    "mesh_query_aabb_done": NO_T, (MESH_AABB) -> BOOL, "mesh", Zero, internal;
    "mesh_query_aabb_item": NO_T, (MESH_AABB) -> I32, "mesh", Zero, internal;
    "mesh_query_point": NO_T, (MESH, VEC3, F32) -> POINT_RESULT, "mesh", Adjoint,
        no_tangent,
        results("(result, sign, face, u, v)");
    "mesh_query_point_no_sign": NO_T, (MESH, VEC3, F32) -> POINT_RESULT, "mesh", Adjoint,
        no_tangent,
        results("(result, sign, face, u, v)");
    "mesh_query_point_sign_normal": NO_T, (MESH, VEC3, F32) -> POINT_RESULT, "mesh", Adjoint,
        no_tangent,
        results("(result, sign, face, u, v)");
    "mesh_query_point_sign_parity": NO_T, (MESH, VEC3, F32) -> POINT_RESULT, "mesh", Adjoint,
        no_tangent,
        results("(result, sign, face, u, v)");
    "mesh_query_furthest_point_no_sign": NO_T, (MESH, VEC3, F32) -> POINT_RESULT, "mesh", Zero,
        results("(result, sign, face, u, v)");
    "mesh_query_ray": NO_T, (MESH, VEC3, VEC3, F32) -> RAY_RESULT, "mesh", Zero,
        results("(result, sign, face, t, u, v, normal)");
    "mesh_eval_position": NO_T, (MESH, Index, F32, F32) -> VEC3, "mesh", Adjoint, no_tangent;
    "mesh_eval_velocity": NO_T, (MESH, Index, F32, F32) -> VEC3, "mesh", Adjoint, no_tangent;
    "mesh_eval_face_normal": NO_T, (MESH, Index) -> VEC3, "mesh", Zero;
    // Triangle geometry (warp-core `objects::geometry`, wp_geometry.h): no object needed.
    "closest_point_triangle": NO_T, (VEC3, VEC3, VEC3, VEC3) -> VEC3, "geometry", Adjoint,
        no_tangent,
        extension;
    "intersect_tri_tri": NO_T, (VEC3, VEC3, VEC3, VEC3, VEC3, VEC3) -> BOOL, "geometry", Zero;
};

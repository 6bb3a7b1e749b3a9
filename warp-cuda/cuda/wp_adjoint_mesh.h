// wp_adjoint_mesh.h: adjoints of the "mesh" section (warp-core/src/objects/mesh.rs).
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions. The functions that
// read the mesh can fault, as their forward ones: they take the fault context last (after
// adj_ret) and return at once after a fault.
//
//   adj_mesh_eval_position(m, face, u, v, adj_m, adj_face, adj_u, adj_v, adj_ret, ctx)
//       adj_u += (p0 - p2) . adj_ret, adj_v += (p1 - p2) . adj_ret (the points get nothing)
//   adj_mesh_eval_velocity(..same..)       the same with the velocities (nothing without)
//   adj_mesh_query_point(m, p, max_dist, adj_m, adj_p, adj_max_dist, adj_ret, ctx)
//   adj_mesh_query_point_no_sign(..same..) adj_p through the closest point's barycentrics
//   adj_mesh_query_point_sign_normal, adj_mesh_query_point_sign_parity(..same..): as _no_sign
//       (u, v) of the face the forward query finds (recomputed), as
//       adj_closest_point_triangle with adj_ret (u, v, w = 0)
//   adj_mesh_query_furthest_point_no_sign(..same..)   nothing (the point is a vertex)
//   adj_zero / zero_like / adj_accum for mesh_query_point_t (sign, u, v accumulate) and
//   mesh_query_ray_t (sign, t, u, v, normal); mesh_t and the query states are objects
//   (wp_object_tag: zero value, no gradient).
#pragma once
#include "wp_adjoint_geometry.h"
#include "wp_mesh.h"

namespace wp {

template <>
WP_FN mesh_query_point_t adj_zero<mesh_query_point_t>() {
  return mesh_query_point_t{};
}
WP_LFN mesh_query_point_t zero_like(const mesh_query_point_t&) { return mesh_query_point_t{}; }
WP_LFN void adj_accum(mesh_query_point_t& a, const mesh_query_point_t& v) {
  a.sign += v.sign;
  a.u += v.u;
  a.v += v.v;
}

template <>
WP_FN mesh_query_ray_t adj_zero<mesh_query_ray_t>() {
  return mesh_query_ray_t{};
}
WP_LFN mesh_query_ray_t zero_like(const mesh_query_ray_t&) { return mesh_query_ray_t{}; }
WP_LFN void adj_accum(mesh_query_ray_t& a, const mesh_query_ray_t& v) {
  a.sign += v.sign;
  a.t += v.t;
  a.u += v.u;
  a.v += v.v;
  a.normal += v.normal;
}

template <typename I>
WP_FN void adj_mesh_eval_position(const mesh_t& mesh, I face, f32 u, f32 v, mesh_t& adj_mesh,
                                  I& adj_face, f32& adj_u, f32& adj_v, Vec3 adj_ret,
                                  ctx_t* ctx) {
  (void)u;
  (void)v;
  (void)adj_mesh;
  (void)adj_face;
  Vec3 t[3];
  detail::mesh_triangle(mesh, (i64)face, t, ctx);
  if (faulted(ctx)) return;
  adj_u += detail::g_dot(t[0] - t[2], adj_ret);
  adj_v += detail::g_dot(t[1] - t[2], adj_ret);
}

template <typename I>
WP_FN void adj_mesh_eval_velocity(const mesh_t& mesh, I face, f32 u, f32 v, mesh_t& adj_mesh,
                                  I& adj_face, f32& adj_u, f32& adj_v, Vec3 adj_ret,
                                  ctx_t* ctx) {
  (void)u;
  (void)v;
  (void)adj_mesh;
  (void)adj_face;
  i32 ix[3];
  detail::mesh_face_indices(mesh, (i64)face, ix, ctx);
  if (faulted(ctx) || mesh.velocities == nullptr) return;
  const Vec3 a = mesh.velocities[ix[0]], b = mesh.velocities[ix[1]], c = mesh.velocities[ix[2]];
  adj_u += detail::g_dot(a - c, adj_ret);
  adj_v += detail::g_dot(b - c, adj_ret);
}

WP_LFN void adj_mesh_query_point_no_sign(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                        mesh_t& adj_mesh, Vec3& adj_point, f32& adj_max_dist,
                                        const mesh_query_point_t& adj_ret, ctx_t* ctx) {
  (void)adj_mesh;
  (void)adj_max_dist;
  detail::mesh_closest_t c;
  if (!detail::mesh_closest_search(mesh, point, max_dist, &c, ctx)) return;
  const triangle_closest_point_t g = detail::tri_cp(adj_ret.u, adj_ret.v, 0.0f, TRI_FEATURE_FACE);
  Vec3 t[3];
  detail::mesh_leaf_triangle(mesh, c.at, t);
  Vec3 x = Vec3_ZERO(), y = Vec3_ZERO(), z = Vec3_ZERO();
  adj_closest_point_triangle(t[0], t[1], t[2], c.p, x, y, z, adj_point, g);
}

WP_LFN void adj_mesh_query_point(const mesh_t& mesh, Vec3 point, f32 max_dist, mesh_t& adj_mesh,
                                Vec3& adj_point, f32& adj_max_dist,
                                const mesh_query_point_t& adj_ret, ctx_t* ctx) {
  adj_mesh_query_point_no_sign(mesh, point, max_dist, adj_mesh, adj_point, adj_max_dist, adj_ret,
                               ctx);
}

WP_LFN void adj_mesh_query_point_sign_normal(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                            mesh_t& adj_mesh, Vec3& adj_point, f32& adj_max_dist,
                                            const mesh_query_point_t& adj_ret, ctx_t* ctx) {
  adj_mesh_query_point_no_sign(mesh, point, max_dist, adj_mesh, adj_point, adj_max_dist, adj_ret,
                               ctx);
}

WP_LFN void adj_mesh_query_point_sign_parity(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                            mesh_t& adj_mesh, Vec3& adj_point, f32& adj_max_dist,
                                            const mesh_query_point_t& adj_ret, ctx_t* ctx) {
  adj_mesh_query_point_no_sign(mesh, point, max_dist, adj_mesh, adj_point, adj_max_dist, adj_ret,
                               ctx);
}

WP_LFN void adj_mesh_query_furthest_point_no_sign(const mesh_t&, Vec3, f32, mesh_t&, Vec3&, f32&,
                                                 const mesh_query_point_t&, ctx_t*) {}

// The kernel language binds the point queries' results as tuples (mesh_query_point_t's
// conversion): their adjoints arrive as tuples and go on as the struct.
typedef tuple_t<bool, f32, i32, f32, f32> mesh_query_point_tuple_t;
namespace detail {
WP_LFN mesh_query_point_t mesh_query_point_of(const mesh_query_point_tuple_t& t) {
  return mesh_query_point_t{t.f0, t.f1, t.f2, t.f3, t.f4};
}
}  // namespace detail
WP_LFN void adj_mesh_query_point(const mesh_t& mesh, Vec3 point, f32 max_dist, mesh_t& adj_mesh,
                                Vec3& adj_point, f32& adj_max_dist,
                                const mesh_query_point_tuple_t& adj_ret, ctx_t* ctx) {
  adj_mesh_query_point(mesh, point, max_dist, adj_mesh, adj_point, adj_max_dist,
                       detail::mesh_query_point_of(adj_ret), ctx);
}
WP_LFN void adj_mesh_query_point_no_sign(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                        mesh_t& adj_mesh, Vec3& adj_point, f32& adj_max_dist,
                                        const mesh_query_point_tuple_t& adj_ret, ctx_t* ctx) {
  adj_mesh_query_point_no_sign(mesh, point, max_dist, adj_mesh, adj_point, adj_max_dist,
                               detail::mesh_query_point_of(adj_ret), ctx);
}
WP_LFN void adj_mesh_query_point_sign_normal(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                            mesh_t& adj_mesh, Vec3& adj_point, f32& adj_max_dist,
                                            const mesh_query_point_tuple_t& adj_ret, ctx_t* ctx) {
  adj_mesh_query_point_sign_normal(mesh, point, max_dist, adj_mesh, adj_point, adj_max_dist,
                              detail::mesh_query_point_of(adj_ret), ctx);
}
WP_LFN void adj_mesh_query_point_sign_parity(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                            mesh_t& adj_mesh, Vec3& adj_point, f32& adj_max_dist,
                                            const mesh_query_point_tuple_t& adj_ret, ctx_t* ctx) {
  adj_mesh_query_point_sign_parity(mesh, point, max_dist, adj_mesh, adj_point, adj_max_dist,
                              detail::mesh_query_point_of(adj_ret), ctx);
}
WP_LFN void adj_mesh_query_furthest_point_no_sign(const mesh_t&, Vec3, f32, mesh_t&, Vec3&, f32&,
                                                 const mesh_query_point_tuple_t&, ctx_t*) {}

}  // namespace wp

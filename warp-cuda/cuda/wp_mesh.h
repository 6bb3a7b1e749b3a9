// wp_mesh.h: section "mesh" of the builtin table: NVIDIA Warp's mesh queries, the CUDA mirror
// of warp-core/src/objects/mesh.rs (read that for the conventions: barycentrics (u, v) name
// u * p0 + v * p1 + (1 - u - v) * p2, point queries report a point strictly within max_dist,
// sign -1 inside by the angle-weighted pseudonormal, distances measured in a power-of-two
// unit chosen from the root box). Every step is the Rust one in the same order, over the same
// traversals (wp_bvh.h), so both backends visit the same faces in the same order. Where the
// code is arranged differently for the GPU, the values are still the Rust's bit for bit: the
// closest-point search keeps only the best face during its walk and recomputes that face's
// closest point once afterwards (the same inputs, the same code), and the signed query's edge
// and vertex pseudonormals share one touching walk (mesh_feature_normal) where the Rust has
// two functions.
//
// The walks (closest, furthest, ray, parity, touching) read each triangle from the mesh's
// leaf-ordered copy (`leaf_tris`, warp_core's leaf_triangles: the corners of face
// prim_ids[k] at positions 3k..3k+3, written at build and refit from the points then): three
// 16-byte loads at the leaf position k, instead of the dependent chain prim_ids[k] ->
// indices[3 * id + j] -> points[i] with its checks. They keep k and map only their result to
// a face (prim_ids[k], checked) at the end. k lies in a leaf's range, which the walk checked
// against prim_ids, so the copy's reads are in bounds without a check of their own; the box
// query and mesh_eval_* read the user's indices and points, checked as before.
//
//   mesh_t                                       a Mesh kernel parameter (warp_runtime's CudaMesh)
//   mesh_query_point_t                           MeshQueryPoint (result, sign, face, u, v)
//   mesh_query_ray_t                             MeshQueryRay (result, sign, face, t, u, v, normal)
//   mesh_query_aabb_t                            MeshQueryAabb (44 bytes)
//   mesh_query_point(m, p, max_dist, ctx)        closest point with the inside/outside sign
//   mesh_query_point_no_sign(m, p, max_dist, ctx)
//   mesh_query_point_sign_normal(m, p, max_dist, ctx)   mesh_query_point (Warp's name)
//   mesh_query_point_sign_parity(m, p, max_dist, ctx)   sign by the parity of one ray's crossings
//   mesh_query_furthest_point_no_sign(m, p, min_dist, ctx)
//   mesh_query_ray(m, start, dir, max_t, ctx)    first hit at 0 <= t < max_t (watertight)
//   mesh_query_aabb(m, lo, hi, ctx), mesh_query_aabb_next(m, q, ctx), _done(q), _item(q)
//   mesh_eval_position(m, face, u, v, ctx), mesh_eval_velocity(..), mesh_eval_face_normal(m, face, ctx)
//                                                face: any integer type
//
// The adjoints are in wp_adjoint_mesh.h.
//
// Faults: as wp_bvh.h, reported with the mesh's parameter (`tree.arg`); in addition a face
// outside [0, num_faces) (index: the face; shape: num_faces) and a vertex index outside
// [0, num_points) (index: the vertex index; shape: num_points), the three vertex indices of a
// face checked in order.
//
// Floating point: bit-exact with the CPU except vertex pseudonormals (mesh_query_point when
// the closest point is a vertex), whose angle weights call atan2f: glibc's on the CPU, CUDA's
// (2 ulp) on a GPU. Only the sign depends on them, and only where the weighted normal is
// perpendicular to the offset within those last bits.
//
// Kernel-argument layout (align 8; warp_runtime's #[repr(C)] CudaMesh must match):
//
//   mesh_t, 80 bytes:
//      0 nodes      (const bvh_node_t*)     -+
//      8 parents    (const i32*: links)      |  a bvh_tree_t over the triangles (see wp_bvh.h):
//     16 prim_ids   (const i32*)             |  primitive ids are face indices;
//     24 num_nodes  (i32, >= 1)              |  num_prims is the number of faces
//     28 num_prims  (i32: faces)             |
//     32 arg        (i32: the parameter)     |
//     36 pad        (i32, 0)                -+
//     40 points     (const Vec3*, num_points entries)
//     48 velocities (const Vec3*, num_points entries; null (0) for a mesh without velocities)
//     56 indices    (const i32*, 3 * num_prims entries)
//     64 num_points (i32)
//     68 pad        (i32, 0)
//     72 leaf_tris  (const f32*, 12 * num_prims entries, 16-byte aligned: per leaf position
//                    three corners {x, y, z, 0})
#pragma once
#include "wp_bvh.h"

namespace wp {

/// A Mesh kernel parameter (80 bytes, see the top).
struct mesh_t {
  bvh_tree_t tree;
  const Vec3* points;
  const Vec3* velocities;
  const i32* indices;
  i32 num_points;
  i32 pad;
  const f32* leaf_tris;
  typedef void wp_object_tag;
};
static_assert(sizeof(mesh_t) == 80 && alignof(mesh_t) == 8, "mesh_t layout");

/// MeshQueryPoint (20 bytes): 0 result (bool), 4 sign, 8 face, 12 u, 16 v.
struct mesh_query_point_t {
  bool result;
  f32 sign;
  i32 face;
  f32 u;
  f32 v;
  /// The kernel language's result: `let (result, sign, face, u, v) = mesh_query_point(..)`.
  WP_FN operator tuple_t<bool, f32, i32, f32, f32>() const { return {result, sign, face, u, v}; }
};
static_assert(sizeof(mesh_query_point_t) == 20, "mesh_query_point_t layout");

/// MeshQueryRay (36 bytes): 0 result (bool), 4 sign, 8 face, 12 t, 16 u, 20 v, 24 normal.
struct mesh_query_ray_t {
  bool result;
  f32 sign;
  i32 face;
  f32 t;
  f32 u;
  f32 v;
  Vec3 normal;
  /// The kernel language's result: `let (result, sign, face, t, u, v, normal) = ..`.
  WP_FN operator tuple_t<bool, f32, i32, f32, f32, f32, Vec3>() const {
    return {result, sign, face, t, u, v, normal};
  }
};
static_assert(sizeof(mesh_query_ray_t) == 36, "mesh_query_ray_t layout");

/// MeshQueryAabb (44 bytes): 0 lower, 12 upper, 24 walk.
struct mesh_query_aabb_t {
  Vec3 lower;
  Vec3 upper;
  bvh_walk_t walk;
  typedef void wp_object_tag;
};
static_assert(sizeof(mesh_query_aabb_t) == 44, "mesh_query_aabb_t layout");

namespace detail {

WP_LFN mesh_query_point_t mesh_point_none() {
  mesh_query_point_t r;
  r.result = false;
  r.sign = 0.0f;
  r.face = 0;
  r.u = 0.0f;
  r.v = 0.0f;
  return r;
}

WP_LFN mesh_query_ray_t mesh_ray_none() {
  mesh_query_ray_t r;
  r.result = false;
  r.sign = 0.0f;
  r.face = 0;
  r.t = 0.0f;
  r.u = 0.0f;
  r.v = 0.0f;
  r.normal = Vec3_ZERO();
  return r;
}

/// MeshView::face_indices: the vertex indices of face f, each checked against the points.
/// The three are read before any is checked (all lie in the buffer once f is a face), so
/// that the reads are issued together instead of each waiting on the check before it; the
/// checks then run in the Rust order, so the same index faults.
WP_LFN void mesh_face_indices(const mesh_t& m, i64 f, i32* ix, ctx_t* ctx) {
  if ((u64)f >= (u64)(i64)m.tree.num_prims) {
    bvh_fault(m.tree, f, (i64)m.tree.num_prims, ctx);
    return;
  }
  const i32 i3[3] = {m.indices[3 * f], m.indices[3 * f + 1], m.indices[3 * f + 2]};
  for (int k = 0; k < 3; ++k) {
    if ((u32)i3[k] >= (u32)m.num_points) {
      bvh_fault(m.tree, (i64)i3[k], (i64)m.num_points, ctx);
      return;
    }
    ix[k] = i3[k];
  }
}

/// MeshView::triangle: the three vertices of face f (checked).
WP_LFN void mesh_triangle(const mesh_t& m, i64 f, Vec3* t, ctx_t* ctx) {
  i32 ix[3];
  mesh_face_indices(m, f, ix, ctx);
  if (faulted(ctx)) return;
  for (int k = 0; k < 3; ++k) t[k] = m.points[ix[k]];
}

/// MeshView::leaf_triangle: the triangle at position k of prim_ids, from the leaf-ordered
/// copy. k is a position inside a leaf's range, checked by the walk (the Rust's check of k
/// never fails there): no check here.
WP_LFN void mesh_leaf_triangle(const mesh_t& m, i32 k, Vec3* t) {
#if defined(__CUDACC__)
  // Three 16-byte read-only loads (the runtime allocates the copy 16-byte aligned), issued
  // together: the whole dependent chain of a triangle read is this one step.
  const float4* q = reinterpret_cast<const float4*>(m.leaf_tris) + 3 * (i64)k;
  const float4 a = __ldg(q), b = __ldg(q + 1), c = __ldg(q + 2);
  t[0] = Vec3_new(a.x, a.y, a.z);
  t[1] = Vec3_new(b.x, b.y, b.z);
  t[2] = Vec3_new(c.x, c.y, c.z);
#else
  const f32* q = m.leaf_tris + 12 * (i64)k;
  for (int j = 0; j < 3; ++j) t[j] = Vec3_new(q[4 * j], q[4 * j + 1], q[4 * j + 2]);
#endif
}

/// MeshView::measure_scale: the root box's farthest extent from p, as a power of two.
WP_LFN f32 mesh_measure_scale(const mesh_t& m, Vec3 p, ctx_t* ctx) {
  const bvh_node_t root = bvh_node(m.tree, 0, ctx);
  if (faulted(ctx)) return 1.0f;
  const Vec3 e = g_vmax(g_abs(bvh_node_lower(root) - p), g_abs(bvh_node_upper(root) - p));
  return pow2_scale(g_max_elem(e));
}

/// unit_normal: the unit normal at a power-of-two scale, zero for a sliver.
WP_LFN Vec3 mesh_unit_normal(Vec3 a, Vec3 b, Vec3 c) {
  Vec3 e1 = b - a, e2 = c - a;
  const f32 s = pow2_scale(g_max_elem(g_vmax(g_abs(e1), g_abs(e2))));
  e1 = e1 * s;
  e2 = e2 * s;
  const Vec3 n = g_cross(e1, e2);
  const f32 sum = (g_len_sq(e1) + g_len_sq(e2)) + g_len_sq(e2 - e1);
  if (g_len(n) > WP_SLIVER_RATIO * sum) return n * (1.0f / g_len(n));  // glam's normalize
  return Vec3_ZERO();
}

/// face_normal: normalize_or_zero of the scaled cross product.
WP_LFN Vec3 mesh_face_normal(Vec3 a, Vec3 b, Vec3 c) {
  const Vec3 e1 = b - a, e2 = c - a;
  const f32 s = pow2_scale(g_max_elem(g_vmax(g_abs(e1), g_abs(e2))));
  const Vec3 n = g_cross(e1 * s, e2 * s);
  const f32 rcp = 1.0f / g_len(n);
  if (g_finite(rcp) && rcp > 0.0f) return n * rcp;
  return Vec3_ZERO();
}

/// The search of for_faces_touching (Touching): key 0 for a box overlapping [lo, hi], +inf
/// otherwise, bound 1: every overlapping box entered, left first, every face of its leaves
/// visited.
template <typename F>
struct mesh_touching_t {
  const mesh_t* mesh;
  Vec3 lo, hi;
  F* f;
  WP_FN f32 node_key(Vec3 lower, Vec3 upper) const {
    return aabb_overlap(lower, upper, lo, hi) ? 0.0f : f32_inf();
  }
  WP_FN f32 bound() const { return 1.0f; }
  WP_FN void visit(i32 k, ctx_t* ctx) {
    (void)ctx;
    Vec3 t[3];
    mesh_leaf_triangle(*mesh, k, t);
    (*f)(t);
  }
};

/// for_faces_touching: f(triangle) for every face in a leaf whose boxes overlap [lo, hi] (an
/// ordered walk, for its stack).
template <typename F>
WP_FN void mesh_for_faces_touching(const mesh_t& m, Vec3 lo, Vec3 hi, F f, ctx_t* ctx) {
  mesh_touching_t<F> s;
  s.mesh = &m;
  s.lo = lo;
  s.hi = hi;
  s.f = &f;
  bvh_walk_ordered(m.tree, s, ctx);
}

WP_LFN bool mesh_tri_contains(const Vec3* t, const Vec3& x) {
  return g_eq(t[0], x) || g_eq(t[1], x) || g_eq(t[2], x);
}

/// The pseudonormal of a closest feature other than the face (edge_normal and vertex_normal
/// in one walk): for an edge x y (vertex false), the sum of the unit normals of the faces
/// having both x and y as vertices; for the vertex x (vertex true, y == x), the angle-weighted
/// sum of the unit normals of the faces around x. Both visit the faces in walk order and add
/// the same terms in the same order as the Rust's two functions. One function, so that the
/// signed query inlines one touching walk rather than one per feature (six copies made a
/// 128 KB kernel that spilled inside the closest walk's loop).
WP_LFN Vec3 mesh_feature_normal(const mesh_t& m, Vec3 x, Vec3 y, bool vertex, ctx_t* ctx) {
  Vec3 n = Vec3_ZERO();
  mesh_for_faces_touching(
      m, g_vmin(x, y), g_vmax(x, y),
      [&n, x, y, vertex](const Vec3* t) {
        if (!vertex) {
          if (mesh_tri_contains(t, x) && mesh_tri_contains(t, y))
            n = n + mesh_unit_normal(t[0], t[1], t[2]);
          return;
        }
        // The vertex at x and the two after it, selected without indexing t by a runtime
        // value (which would put t in local memory).
        const bool k0 = g_eq(t[0], x), k1 = !k0 && g_eq(t[1], x), k2 = !k0 && !k1 && g_eq(t[2], x);
        if (!(k0 || k1 || k2)) return;
        const Vec3 next = k0 ? t[1] : (k1 ? t[2] : t[0]);
        const Vec3 after = k0 ? t[2] : (k1 ? t[0] : t[1]);
        Vec3 e1 = next - x, e2 = after - x;
        const f32 s = pow2_scale(g_max_elem(g_vmax(g_abs(e1), g_abs(e2))));
        e1 = e1 * s;
        e2 = e2 * s;
        const f32 angle = ::atan2f(g_len(g_cross(e1, e2)), g_dot(e1, e2));
        n = n + mesh_unit_normal(t[0], t[1], t[2]) * angle;
      },
      ctx);
  return n;
}

/// The closest-point search (Closest): squared distances in units of 1 / s. During the walk
/// it keeps only the best distance and the best triangle's leaf position `at` (the Rust keeps
/// the triangle and its closest point too): fewer registers live across the walk, whose
/// loads are what the query waits on. mesh_closest_search maps `at` to the face (prim_ids,
/// checked) after the walk; mesh_closest recomputes the winning triangle's closest point once,
/// from the same vertices and s by the same code, so the same bits as the visit that chose it.
struct mesh_closest_t {
  const mesh_t* mesh;
  Vec3 p;
  f32 s;
  f32 best;
  i32 at;
  i32 face;
  WP_FN f32 node_key(Vec3 lower, Vec3 upper) const {
    return aabb_distance_sq_scaled(p, lower, upper, s);
  }
  WP_FN f32 bound() const { return best; }
  /// Closest::visit: a face whose own box is no nearer than the best is skipped (see the Rust
  /// for why that is exact up to ties within rounding); the closest point is computed in the
  /// search's unit s and the distance from the scaled edges.
  WP_FN void visit(i32 k, ctx_t* ctx) {
    (void)ctx;
    Vec3 t[3];
    mesh_leaf_triangle(*mesh, k, t);
    const Vec3 a = t[0], b = t[1], c = t[2];
    const Vec3 lower = Vec3_new(::fminf(::fminf(a.x, b.x), c.x), ::fminf(::fminf(a.y, b.y), c.y),
                                ::fminf(::fminf(a.z, b.z), c.z));
    const Vec3 upper = Vec3_new(::fmaxf(::fmaxf(a.x, b.x), c.x), ::fmaxf(::fmaxf(a.y, b.y), c.y),
                                ::fmaxf(::fmaxf(a.z, b.z), c.z));
    if (!(aabb_distance_sq_scaled(p, lower, upper, s) < best)) return;
    const Vec3 ab = (b - a) * s, ac = (c - a) * s, ap = (p - a) * s;
    const triangle_closest_point_t r = closest_point_triangle_scaled(ab, ac, ap);
    const f32 d = g_len_sq((ab * r.v + ac * r.w) - ap);
    if (d < best) {
      best = d;
      at = k;
    }
  }
};

/// closest(): the search run; false (None) when nothing lies within max_dist or on a fault.
/// On true, c->at is the closest triangle's leaf position and c->face its face.
WP_LFN bool mesh_closest_search(const mesh_t& m, Vec3 p, f32 max_dist, mesh_closest_t* c,
                               ctx_t* ctx) {
  if (!(max_dist > 0.0f)) return false;
  const f32 s = mesh_measure_scale(m, p, ctx);
  if (faulted(ctx)) return false;
  const f32 bound = max_dist * s;
  c->mesh = &m;
  c->p = p;
  c->s = s;
  c->best = bound * bound;
  c->at = -1;
  c->face = -1;
  bvh_walk_ordered(m.tree, *c, ctx);
  if (faulted(ctx) || c->at < 0) return false;
  c->face = bvh_prim(m.tree, c->at, ctx);
  return !faulted(ctx);
}

/// mesh_closest_search, then the closest point on the triangle found (*bary) and its
/// vertices (tri[0..3]): Closest::visit's computation repeated on the triangle the walk
/// chose, read again at its leaf position, from the same vertices and s.
WP_LFN bool mesh_closest(const mesh_t& m, Vec3 p, f32 max_dist, mesh_closest_t* c, Vec3* tri,
                        triangle_closest_point_t* bary, ctx_t* ctx) {
  if (!mesh_closest_search(m, p, max_dist, c, ctx)) return false;
  mesh_leaf_triangle(m, c->at, tri);
  const Vec3 a = tri[0];
  const f32 s = c->s;
  *bary = closest_point_triangle_scaled((tri[1] - a) * s, (tri[2] - a) * s, (p - a) * s);
  return true;
}

/// The furthest-point search (Furthest): negated squared distances (the walk minimises);
/// `face` is the best triangle's leaf position during the walk, mapped to its face after.
struct mesh_furthest_t {
  const mesh_t* mesh;
  Vec3 p;
  f32 s;
  f32 best;
  i32 face;
  f32 u, v;
  WP_FN f32 node_key(Vec3 lower, Vec3 upper) const {
    const Vec3 ps = p * s, lo = lower * s, hi = upper * s;
    if (!(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z)) return f32_inf();
    return -g_len_sq(g_vmax(g_abs(ps - lo), g_abs(ps - hi)));
  }
  WP_FN f32 bound() const { return -best; }
  WP_FN void visit(i32 k, ctx_t* ctx) {
    (void)ctx;
    Vec3 t[3];
    mesh_leaf_triangle(*mesh, k, t);
    const f32 da = g_len_sq((t[0] - p) * s), db = g_len_sq((t[1] - p) * s),
              dc = g_len_sq((t[2] - p) * s);
    f32 dist, uu, vv;
    if (da > db && da > dc) {
      dist = da; uu = 1.0f; vv = 0.0f;
    } else if (db > dc) {
      dist = db; uu = 0.0f; vv = 1.0f;
    } else {
      dist = dc; uu = 0.0f; vv = 0.0f;
    }
    if (dist > best) {
      best = dist;
      face = k;
      u = uu;
      v = vv;
    }
  }
};

/// The closest-hit search along a ray (ClosestHit). The ray's frame is made once (the Rust
/// makes it once per ray too), boxes are tested by the branch-free slab test when no
/// component of inv_dir is infinite (intersect_ray_aabb otherwise: the same keys), and a
/// face's barycentrics are divided out only for a hit nearer than the bound (the Rust's
/// order too). best.face is the hit triangle's leaf position during the walk, mapped to its
/// face after.
struct mesh_closest_hit_t {
  const mesh_t* mesh;
  Vec3 start;
  Vec3 dir;
  Vec3 inv_dir;
  ray_frame_t frame;
  bool finite_inv;
  mesh_query_ray_t best;
  f32 max_t;
  WP_FN f32 node_key(Vec3 lower, Vec3 upper) const {
    f32 t;
    const bool hit = finite_inv ? intersect_ray_aabb_finite(start, inv_dir, lower, upper, &t)
                                : intersect_ray_aabb(start, inv_dir, lower, upper, &t);
    return hit ? t : f32_inf();
  }
  WP_FN f32 bound() const { return best.result ? best.t : max_t; }
  WP_FN void visit(i32 k, ctx_t* ctx) {
    (void)ctx;
    Vec3 t[3];
    mesh_leaf_triangle(*mesh, k, t);
    const ray_triangle_candidate_t h =
        intersect_ray_triangle_in_frame(frame, start, dir, t[0], t[1], t[2]);
    if (h.result && h.t < bound()) {
      best.result = true;
      best.sign = h.sign;
      best.face = k;
      best.t = h.t;
      best.u = (f32)(h.uu / h.det);
      best.v = (f32)(h.vv / h.det);
      best.normal = Vec3_ZERO();
    }
  }
};

}  // namespace detail

// ------------------------------------------------------------------------------------------
// Point queries
// ------------------------------------------------------------------------------------------

/// The closest point strictly within max_dist, without a sign (sign 0).
WP_LFN mesh_query_point_t mesh_query_point_no_sign(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                                  ctx_t* ctx) {
  detail::mesh_closest_t c;
  Vec3 t[3];
  triangle_closest_point_t bary;
  if (!detail::mesh_closest(mesh, point, max_dist, &c, t, &bary, ctx))
    return detail::mesh_point_none();
  mesh_query_point_t r;
  r.result = true;
  r.sign = 0.0f;
  r.face = c.face;
  r.u = bary.u;
  r.v = bary.v;
  return r;
}

namespace detail {

/// The sign of `point` (-1 inside) from the closest point `bary` the search found on the
/// face with vertices t[0..3]: the angle-weighted pseudonormal of its feature. The edge's or
/// vertex's ends are selected from the feature and one walk (mesh_feature_normal) serves all
/// six. (Inlined: as a call of its own the kernel's fault context would live in local memory,
/// and 1M signed queries took 99 ms against 76 on an H200.)
WP_LFN f32 mesh_point_sign(const mesh_t& mesh, Vec3 point, const Vec3* t,
                          triangle_closest_point_t bary, f32 s, ctx_t* ctx) {
  const Vec3 a = t[0], b = t[1], cc = t[2];
  const i32 f = bary.feature;
  Vec3 n;
  if (f == TRI_FEATURE_FACE) {
    n = mesh_unit_normal(a, b, cc);
  } else {
    // Edge ab, bc, ca: (x, y) = (a, b), (b, c), (c, a); vertex a, b, c: x = y = the vertex.
    const bool vertex = f == TRI_FEATURE_VERTEX_A || f == TRI_FEATURE_VERTEX_B ||
                        f == TRI_FEATURE_VERTEX_C;
    const Vec3 x = (f == TRI_FEATURE_EDGE_AB || f == TRI_FEATURE_VERTEX_A)   ? a
                   : (f == TRI_FEATURE_EDGE_BC || f == TRI_FEATURE_VERTEX_B) ? b
                                                                              : cc;
    const Vec3 y = vertex ? x : (f == TRI_FEATURE_EDGE_AB ? b : (f == TRI_FEATURE_EDGE_BC ? cc : a));
    n = mesh_feature_normal(mesh, x, y, vertex, ctx);
    if (faulted(ctx)) return 0.0f;
  }
  const Vec3 away = (point - triangle_closest_point_position(bary, a, b, cc)) * s;
  return g_dot(n, away) > 0.0f ? 1.0f : -1.0f;
}

}  // namespace detail

/// The closest point strictly within max_dist, with the sign of the point (-1 inside) by the
/// angle-weighted pseudonormal of the closest feature.
WP_LFN mesh_query_point_t mesh_query_point(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                          ctx_t* ctx) {
  using namespace detail;
  mesh_closest_t c;
  Vec3 t[3];
  triangle_closest_point_t bary;
  if (!mesh_closest(mesh, point, max_dist, &c, t, &bary, ctx)) return mesh_point_none();
  const f32 sign = mesh_point_sign(mesh, point, t, bary, c.s, ctx);
  if (faulted(ctx)) return mesh_point_none();
  mesh_query_point_t r;
  r.result = true;
  r.sign = sign;
  r.face = c.face;
  r.u = bary.u;
  r.v = bary.v;
  return r;
}

/// Warp's mesh_query_point_sign_normal: mesh_query_point under Warp's name for its method.
WP_LFN mesh_query_point_t mesh_query_point_sign_normal(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                                      ctx_t* ctx) {
  return mesh_query_point(mesh, point, max_dist, ctx);
}

namespace detail {

/// PARITY_DIR: the direction of (0.6, 0.48, 0.64), held exactly as (15/16, 3/4, 1).
WP_LFN Vec3 mesh_parity_dir() { return Vec3_new(0.9375f, 0.75f, 1.0f); }

/// PARITY_BOX_SLACK: 2^-18.
#define WP_PARITY_BOX_SLACK (1.0f / 262144.0f)

/// ray_may_meet_box: the slab test for a direction of positive components, widened by the
/// slack relative to the parameters compared; inverted boxes and NaN miss.
WP_LFN bool mesh_ray_may_meet_box(Vec3 start, Vec3 inv_dir, Vec3 lower, Vec3 upper) {
  if (!(lower.x <= upper.x && lower.y <= upper.y && lower.z <= upper.z)) return false;
  const Vec3 lo = lower - start, hi = upper - start;
  const f32 nx = lo.x * inv_dir.x, ny = lo.y * inv_dir.y, nz = lo.z * inv_dir.z;
  const f32 fx = hi.x * inv_dir.x, fy = hi.y * inv_dir.y, fz = hi.z * inv_dir.z;
  const f32 t0 = g_gt_max(nx, g_gt_max(ny, nz));
  const f32 fyz = fy < fz ? fy : fz;
  const f32 t1 = fx < fyz ? fx : fyz;
  const f32 slack = (::fabsf(t0) + ::fabsf(t1)) * WP_PARITY_BOX_SLACK;
  return t0 <= t1 + slack && t1 + slack >= 0.0f;
}

/// The parity search (Crossings): every box the ray may meet entered (key 0, bound +inf),
/// every face of an entered leaf tested.
struct mesh_crossings_t {
  const mesh_t* mesh;
  Vec3 start;
  Vec3 inv_dir;
  ray_frame_t frame;  // ray_frame(mesh_parity_dir()), made once per query
  bool odd;
  WP_FN f32 node_key(Vec3 lower, Vec3 upper) const {
    return mesh_ray_may_meet_box(start, inv_dir, lower, upper) ? 0.0f : f32_inf();
  }
  WP_FN f32 bound() const { return f32_inf(); }
  WP_FN void visit(i32 k, ctx_t* ctx) {
    (void)ctx;
    Vec3 t[3];
    mesh_leaf_triangle(*mesh, k, t);
    if (ray_crosses_triangle_in_frame(frame, start, mesh_parity_dir(), t[0], t[1], t[2])) odd = !odd;
  }
};

}  // namespace detail

/// The closest point strictly within max_dist as mesh_query_point_no_sign finds it, with the
/// sign from the parity of the faces one ray from the point crosses (odd: inside, -1).
WP_LFN mesh_query_point_t mesh_query_point_sign_parity(const mesh_t& mesh, Vec3 point, f32 max_dist,
                                                      ctx_t* ctx) {
  using namespace detail;
  mesh_closest_t c;
  Vec3 t[3];
  triangle_closest_point_t bary;
  if (!mesh_closest(mesh, point, max_dist, &c, t, &bary, ctx)) return mesh_point_none();
  mesh_crossings_t x;
  x.mesh = &mesh;
  x.start = point;
  x.inv_dir = ray_inv_dir(mesh_parity_dir());
  x.frame = ray_frame(mesh_parity_dir());
  x.odd = false;
  bvh_walk_ordered(mesh.tree, x, ctx);
  if (faulted(ctx)) return mesh_point_none();
  mesh_query_point_t r;
  r.result = true;
  r.sign = x.odd ? -1.0f : 1.0f;
  r.face = c.face;
  r.u = bary.u;
  r.v = bary.v;
  return r;
}

/// The furthest point strictly beyond min_dist (a vertex: barycentrics (1, 0), (0, 1) or
/// (0, 0)); min_dist below 0 counts as 0, NaN finds nothing.
WP_LFN mesh_query_point_t mesh_query_furthest_point_no_sign(const mesh_t& mesh, Vec3 point,
                                                           f32 min_dist, ctx_t* ctx) {
  using namespace detail;
  if (min_dist != min_dist) return mesh_point_none();
  const f32 s = mesh_measure_scale(mesh, point, ctx);
  if (faulted(ctx)) return mesh_point_none();
  const f32 m = ::fmaxf(min_dist, 0.0f) * s;
  mesh_furthest_t f;
  f.mesh = &mesh;
  f.p = point;
  f.s = s;
  f.best = m * m;
  f.face = -1;
  f.u = 0.0f;
  f.v = 0.0f;
  bvh_walk_ordered(mesh.tree, f, ctx);
  if (faulted(ctx) || f.face < 0) return mesh_point_none();
  const i32 face = bvh_prim(mesh.tree, f.face, ctx);
  if (faulted(ctx)) return mesh_point_none();
  mesh_query_point_t r;
  r.result = true;
  r.sign = 0.0f;
  r.face = face;
  r.u = f.u;
  r.v = f.v;
  return r;
}

// ------------------------------------------------------------------------------------------
// Ray query
// ------------------------------------------------------------------------------------------

/// The first hit of start + t * dir with the mesh at 0 <= t < max_t (ties at equal t to the
/// face visited first).
WP_LFN mesh_query_ray_t mesh_query_ray(const mesh_t& mesh, Vec3 start, Vec3 dir, f32 max_t,
                                      ctx_t* ctx) {
  using namespace detail;
  mesh_closest_hit_t h;
  h.mesh = &mesh;
  h.start = start;
  h.dir = dir;
  h.inv_dir = ray_inv_dir(dir);
  h.frame = ray_frame(dir);
  h.finite_inv = ray_inv_dir_finite(h.inv_dir);
  h.best = mesh_ray_none();
  h.max_t = max_t;
  bvh_walk_ordered(mesh.tree, h, ctx);
  if (faulted(ctx)) return mesh_ray_none();
  mesh_query_ray_t r = h.best;
  if (r.result) {
    // The normal of the triangle hit (the leaf-ordered copy's), then its face.
    Vec3 t[3];
    mesh_leaf_triangle(mesh, r.face, t);
    r.normal = mesh_face_normal(t[0], t[1], t[2]);
    r.face = bvh_prim(mesh.tree, r.face, ctx);
    if (faulted(ctx)) return mesh_ray_none();
  }
  return r;
}

// ------------------------------------------------------------------------------------------
// Box query (over the faces' bounding boxes)
// ------------------------------------------------------------------------------------------

WP_LFN mesh_query_aabb_t mesh_query_aabb(const mesh_t& mesh, Vec3 lower, Vec3 upper, ctx_t* ctx) {
  (void)mesh;
  (void)ctx;
  mesh_query_aabb_t q;
  q.lower = lower;
  q.upper = upper;
  q.walk = detail::bvh_walk_start();
  return q;
}

WP_LFN mesh_query_aabb_t mesh_query_aabb_next(const mesh_t& mesh, mesh_query_aabb_t q,
                                             ctx_t* ctx) {
  const Vec3 lo = q.lower, hi = q.upper;
  q.walk = detail::bvh_walk_next(
      q.walk, mesh.tree, [lo, hi](Vec3 l, Vec3 u) { return aabb_overlap(l, u, lo, hi); },
      [&mesh, lo, hi](i32 id, ctx_t* c) {
        using namespace detail;
        Vec3 t[3];
        mesh_triangle(mesh, (i64)id, t, c);
        if (faulted(c)) return false;
        return aabb_overlap(g_vmin(g_vmin(t[0], t[1]), t[2]), g_vmax(g_vmax(t[0], t[1]), t[2]),
                            lo, hi);
      },
      ctx);
  return q;
}

WP_LFN bool mesh_query_aabb_done(mesh_query_aabb_t q) { return q.walk.item < 0; }

WP_LFN i32 mesh_query_aabb_item(mesh_query_aabb_t q) { return q.walk.item; }

/// Every face a box query yields is below this (bvh_prim checks each id).
WP_LFN i64 mesh_item_bound(const mesh_t& mesh) { return (i64)mesh.tree.num_prims; }

// ------------------------------------------------------------------------------------------
// Evaluation at barycentrics
// ------------------------------------------------------------------------------------------

/// u * p0 + v * p1 + (1 - u - v) * p2 of face `face` (any integer type); a fault when it is not
/// a face.
template <typename I>
WP_FN Vec3 mesh_eval_position(const mesh_t& mesh, I face, f32 u, f32 v, ctx_t* ctx) {
  Vec3 t[3];
  detail::mesh_triangle(mesh, (i64)face, t, ctx);
  if (faulted(ctx)) return Vec3_ZERO();
  return (t[0] * u + t[1] * v) + t[2] * ((1.0f - u) - v);
}

/// The velocity of face `face` at (u, v), interpolated as the position; zero without
/// velocities (the face is checked all the same).
template <typename I>
WP_FN Vec3 mesh_eval_velocity(const mesh_t& mesh, I face, f32 u, f32 v, ctx_t* ctx) {
  i32 ix[3];
  detail::mesh_face_indices(mesh, (i64)face, ix, ctx);
  if (faulted(ctx) || mesh.velocities == nullptr) return Vec3_ZERO();
  const Vec3 a = mesh.velocities[ix[0]], b = mesh.velocities[ix[1]], c = mesh.velocities[ix[2]];
  return (a * u + b * v) + c * ((1.0f - u) - v);
}

/// The unit normal of face `face` (zero for a degenerate face).
template <typename I>
WP_FN Vec3 mesh_eval_face_normal(const mesh_t& mesh, I face, ctx_t* ctx) {
  Vec3 t[3];
  detail::mesh_triangle(mesh, (i64)face, t, ctx);
  if (faulted(ctx)) return Vec3_ZERO();
  return detail::mesh_face_normal(t[0], t[1], t[2]);
}

}  // namespace wp

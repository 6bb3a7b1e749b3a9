// wp_geometry.h: section "geometry" of the builtin table: the CUDA mirror of
// warp-core/src/objects/geometry.rs (read that for the definitions, the barycentric convention
// `u * a + v * b + w * c`, the power-of-two scaling and the NaN rules). Every function takes the
// Rust steps in the Rust order, with glam's evaluation order for each vector operation, so that
// with no FMA contraction (NVRTC `--fmad=false`, which the runtime always passes for a unit
// including a geometry header; g++ `-ffp-contract=off`) both backends return the same bits.
//
//   SLIVER_RATIO, pow2_scale(m)                     the sliver threshold, the exact rescaling
//   TRI_FEATURE_*                                   TriFeature (i32: Face 0, VertexA..C 1..3,
//                                                   EdgeAB 4, EdgeBC 5, EdgeCA 6)
//   triangle_closest_point_t                        TriangleClosestPoint (u, v, w, feature)
//   closest_point_triangle(a, b, c, p)              the closest point of a triangle
//   closest_point_triangle_scaled(ab, ac, ap)       its core, on a translated, scaled triangle
//   ray_triangle_hit_t                              RayTriangleHit (result, t, u, v, sign)
//   intersect_ray_triangle(start, dir, a, b, c)     watertight ray-triangle (f64 edge functions)
//   ray_crosses_triangle(start, dir, a, b, c)       its crossing for parity counts (ties broken)
//   ray_frame_t, ray_frame(dir)                     RayFrame: the per-ray part of the shear
//   intersect_ray_triangle_in_frame(fr, start, dir, a, b, c), ray_crosses_triangle_in_frame(
//       fr, start, dir, a, b, c)                    the two in a frame made once per ray; the
//                                                   first returns a candidate (t, sign, uu, vv,
//                                                   det) whose u, v the caller divides out
//   aabb_overlap(al, au, bl, bu)                    box-box, touching included
//   intersect_ray_aabb(start, inv_dir, lo, hi, &t)  slab test: Some(t_enter) is `true` and *t
//   intersect_ray_aabb_finite(..), ray_inv_dir_finite(inv_dir)   its branch-free form for an
//                                                   inv_dir with no infinite component
//   ray_inv_dir(dir), aabb_distance_sq(p, lo, hi), aabb_distance_sq_scaled(p, lo, hi, s)
//   intersect_tri_tri(v0, v1, v2, u0, u1, u2)       Möller's interval test, robust variant
//
// The adjoint of closest_point_triangle is in wp_adjoint_geometry.h. Nothing here can fault.
//
// Which Rust operation each helper is (they differ from the builtin-table functions of
// wp_vector.h/wp_scalar.h in the sign of zeros and in NaN handling, and must not be swapped):
//   g_dot        glam Vec3::dot: (x*x' + y*y') + z*z' (the builtin dot starts from 0)
//   g_cross      glam Vec3::cross
//   g_vmin/vmax  glam Vec3::min/max: per component `a < b ? a : b` (a NaN in `b` wins)
//   g_max_elem   glam Vec3::max_element: max(x, max(y, z)) with `a > b ? a : b`
//   fminf/fmaxf  Rust f32::min/max (IEEE minNum/maxNum: a NaN operand loses). The sign of a
//                zero result of min(-0, +0) is unspecified on both sides; no result here
//                depends on it except a barycentric that is exactly zero (then ±0).
//   g_clamp      Rust f32::clamp: `x < lo -> lo; x > hi -> hi` (NaN passes through)
#pragma once
#include "wp_core.h"

namespace wp {

/// warp_core::objects::geometry::SLIVER_RATIO.
#define WP_SLIVER_RATIO 1e-6f
/// The tri-tri distance tolerance (TRI_TRI_EPS), relative to |n| in scaled units.
#define WP_TRI_TRI_EPS 1e-6f

namespace detail {
WP_LFN f32 g_dot(const Vec3& a, const Vec3& b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
WP_LFN Vec3 g_cross(const Vec3& a, const Vec3& b) {
  return Vec3_new(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
}
WP_LFN f32 g_len_sq(const Vec3& a) { return g_dot(a, a); }
WP_LFN f32 g_len(const Vec3& a) { return ::sqrtf(g_dot(a, a)); }
WP_LFN Vec3 g_abs(const Vec3& a) { return Vec3_new(::fabsf(a.x), ::fabsf(a.y), ::fabsf(a.z)); }
WP_LFN Vec3 g_vmin(const Vec3& a, const Vec3& b) {
  return Vec3_new(a.x < b.x ? a.x : b.x, a.y < b.y ? a.y : b.y, a.z < b.z ? a.z : b.z);
}
WP_LFN Vec3 g_vmax(const Vec3& a, const Vec3& b) {
  return Vec3_new(a.x > b.x ? a.x : b.x, a.y > b.y ? a.y : b.y, a.z > b.z ? a.z : b.z);
}
WP_LFN f32 g_gt_max(f32 a, f32 b) { return a > b ? a : b; }
WP_LFN f32 g_max_elem(const Vec3& v) { return g_gt_max(v.x, g_gt_max(v.y, v.z)); }
WP_LFN f32 g_clamp(f32 x, f32 lo, f32 hi) {
  if (x < lo) x = lo;
  if (x > hi) x = hi;
  return x;
}
WP_LFN f32 g_comp(const Vec3& v, int k) { return k == 0 ? v.x : (k == 1 ? v.y : v.z); }
WP_LFN bool g_finite(f32 x) { return (f32_to_bits(x) & 0x7f800000u) != 0x7f800000u; }
WP_LFN bool g_finite3(const Vec3& v) { return g_finite(v.x) && g_finite(v.y) && g_finite(v.z); }
WP_LFN bool g_is_inf(f32 x) { return (f32_to_bits(x) & 0x7fffffffu) == 0x7f800000u; }
/// glam's `==` (per component; -0 == +0, NaN != NaN).
WP_LFN bool g_eq(const Vec3& a, const Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
/// geometry.rs's max_abs: `m = m.max(v.abs().max_element())` over the vectors, from 0. The
/// size is a template parameter and the loop unrolled, so the array stays in registers (over a
/// runtime count it went to local memory, a store per call, in the signed mesh query).
template <int N>
WP_FN f32 g_max_abs(const Vec3 (&vs)[N]) {
  f32 m = 0.0f;
#if defined(__CUDACC__)
#pragma unroll
#endif
  for (int i = 0; i < N; ++i) m = ::fmaxf(m, g_max_elem(g_abs(vs[i])));
  return m;
}
}  // namespace detail

/// A power of two s with m * s in [1, 2) (normal finite positive m; 2^±126 at the clamp), or 1
/// for 0, infinite or NaN m.
WP_LFN f32 pow2_scale(f32 m) {
  if (!(m > 0.0f && m <= f32_max())) return 1.0f;
  const i32 e = (i32)((f32_to_bits(m) >> 23) & 0xffu) - 127;
  i32 k = -e;
  k = k < -126 ? -126 : (k > 126 ? 126 : k);
  return f32_from_bits((u32)(k + 127) << 23);
}

// ------------------------------------------------------------------------------------------
// Closest point on a triangle
// ------------------------------------------------------------------------------------------

enum tri_feature : i32 {
  TRI_FEATURE_FACE = 0,
  TRI_FEATURE_VERTEX_A = 1,
  TRI_FEATURE_VERTEX_B = 2,
  TRI_FEATURE_VERTEX_C = 3,
  TRI_FEATURE_EDGE_AB = 4,
  TRI_FEATURE_EDGE_BC = 5,
  TRI_FEATURE_EDGE_CA = 6,
};

/// TriangleClosestPoint (16 bytes): 0 u, 4 v, 8 w, 12 feature (i32, tri_feature).
struct triangle_closest_point_t {
  f32 u;
  f32 v;
  f32 w;
  i32 feature;
  /// The kernel language's `closest_point_triangle`: the barycentrics (u, v, w).
  WP_FN operator Vec3() const { return Vec3_new(u, v, w); }
};
static_assert(sizeof(triangle_closest_point_t) == 16, "triangle_closest_point_t layout");

/// The point u * a + v * b + w * c.
WP_LFN Vec3 triangle_closest_point_position(const triangle_closest_point_t& r, const Vec3& a,
                                           const Vec3& b, const Vec3& c) {
  return (a * r.u + b * r.v) + c * r.w;
}

namespace detail {
WP_LFN triangle_closest_point_t tri_cp(f32 u, f32 v, f32 w, i32 f) {
  triangle_closest_point_t r;
  r.u = u;
  r.v = v;
  r.w = w;
  r.feature = f;
  return r;
}
/// geometry.rs's on_edge.
WP_LFN triangle_closest_point_t on_edge(i32 edge, f32 t) {
  f32 u, v, w;
  i32 f;
  if (edge == TRI_FEATURE_EDGE_AB) {
    u = 1.0f - t; v = t; w = 0.0f; f = edge;
  } else if (edge == TRI_FEATURE_EDGE_BC) {
    u = 0.0f; v = 1.0f - t; w = t; f = edge;
  } else {
    u = t; v = 0.0f; w = 1.0f - t; f = TRI_FEATURE_EDGE_CA;
  }
  i32 feature;
  if (t <= 0.0f) {
    feature = f == TRI_FEATURE_EDGE_AB ? TRI_FEATURE_VERTEX_A
              : f == TRI_FEATURE_EDGE_BC ? TRI_FEATURE_VERTEX_B
                                         : TRI_FEATURE_VERTEX_C;
  } else if (t >= 1.0f) {
    feature = f == TRI_FEATURE_EDGE_AB ? TRI_FEATURE_VERTEX_B
              : f == TRI_FEATURE_EDGE_BC ? TRI_FEATURE_VERTEX_C
                                         : TRI_FEATURE_VERTEX_A;
  } else {
    feature = f;
  }
  return tri_cp(u, v, w, feature);
}
WP_LFN f32 segment_param(const Vec3& s0, const Vec3& d, const Vec3& q) {
  const f32 dd = g_dot(d, d);
  const f32 t = g_dot(q - s0, d) / dd;
  if (dd > 0.0f && t > 0.0f) return ::fminf(t, 1.0f);
  return 0.0f;
}
WP_LFN f32 ratio(f32 num, f32 den) {
  const f32 t = num / den;
  if (t > 0.0f) return ::fminf(t, 1.0f);
  return 0.0f;
}
/// The degenerate case: the closest of the three edges (ties to ab, bc, ca).
WP_LFN triangle_closest_point_t closest_point_segments(const Vec3& ab, const Vec3& ac,
                                                      const Vec3& ap) {
  const Vec3 zero = Vec3_ZERO();
  const f32 t_ab = segment_param(zero, ab, ap);
  const f32 t_bc = segment_param(ab, ac - ab, ap);
  const f32 t_ca = segment_param(ac, -ac, ap);
  const f32 d_ab = g_len_sq(ab * t_ab - ap);
  const f32 d_bc = g_len_sq((ab + (ac - ab) * t_bc) - ap);
  const f32 d_ca = g_len_sq((ac - ac * t_ca) - ap);
  if (!(d_bc < d_ab) && !(d_ca < d_ab)) return on_edge(TRI_FEATURE_EDGE_AB, t_ab);
  if (!(d_ca < d_bc)) return on_edge(TRI_FEATURE_EDGE_BC, t_bc);
  return on_edge(TRI_FEATURE_EDGE_CA, t_ca);
}
}  // namespace detail

/// closest_point_triangle_scaled: the closest point on the triangle translated to a and
/// scaled by a power of two of the caller's choosing (ab = (b - a) * s, ...); the same bits
/// for every s under which no intermediate leaves the normal range (see the Rust).
WP_LFN triangle_closest_point_t closest_point_triangle_scaled(Vec3 ab, Vec3 ac, Vec3 ap) {
  using namespace detail;
  const Vec3 bc = ac - ab;
  const Vec3 n = g_cross(ab, ac);
  const f32 edges = (g_len_sq(ab) + g_len_sq(ac)) + g_len_sq(bc);
  if (!(g_len(n) > WP_SLIVER_RATIO * edges)) return closest_point_segments(ab, ac, ap);

  const f32 d1 = g_dot(ab, ap);
  const f32 d2 = g_dot(ac, ap);
  if (d1 <= 0.0f && d2 <= 0.0f) return on_edge(TRI_FEATURE_EDGE_AB, 0.0f);
  const Vec3 bp = ap - ab;
  const f32 d3 = g_dot(ab, bp);
  const f32 d4 = g_dot(ac, bp);
  if (d3 >= 0.0f && d4 <= d3) return on_edge(TRI_FEATURE_EDGE_AB, 1.0f);
  f32 vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0f && d1 >= 0.0f && d3 <= 0.0f)
    return on_edge(TRI_FEATURE_EDGE_AB, ratio(d1, d1 - d3));
  const Vec3 cp = ap - ac;
  const f32 d5 = g_dot(ab, cp);
  const f32 d6 = g_dot(ac, cp);
  if (d6 >= 0.0f && d5 <= d6) return on_edge(TRI_FEATURE_EDGE_BC, 1.0f);
  f32 vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0f && d2 >= 0.0f && d6 <= 0.0f)
    return on_edge(TRI_FEATURE_EDGE_CA, 1.0f - ratio(d2, d2 - d6));
  f32 va = d3 * d6 - d5 * d4;
  if (va <= 0.0f && (d4 - d3) >= 0.0f && (d5 - d6) >= 0.0f)
    return on_edge(TRI_FEATURE_EDGE_BC, ratio(d4 - d3, (d4 - d3) + (d5 - d6)));
  va = ::fmaxf(va, 0.0f);
  vb = ::fmaxf(vb, 0.0f);
  vc = ::fmaxf(vc, 0.0f);
  const f32 sum = (va + vb) + vc;
  if (!(sum > 0.0f)) return closest_point_segments(ab, ac, ap);
  const f32 v = vb / sum;
  const f32 w = vc / sum;
  return tri_cp(::fmaxf((1.0f - v) - w, 0.0f), v, w, TRI_FEATURE_FACE);
}

/// The closest point of triangle (a, b, c) to p (Ericson 5.1.5 on the translated, scaled
/// triangle; degenerate triangles as their three edges).
WP_LFN triangle_closest_point_t closest_point_triangle(Vec3 a, Vec3 b, Vec3 c, Vec3 p) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const Vec3 vs[3] = {ab, ac, ap};
  const f32 s = pow2_scale(detail::g_max_abs(vs));
  return closest_point_triangle_scaled(ab * s, ac * s, ap * s);
}

// ------------------------------------------------------------------------------------------
// Ray against triangle (watertight)
// ------------------------------------------------------------------------------------------

/// RayTriangleHit (20 bytes): 0 result (bool), 4 t, 8 u, 12 v, 16 sign (+1 front, -1 back).
struct ray_triangle_hit_t {
  bool result;
  f32 t;
  f32 u;
  f32 v;
  f32 sign;
};
static_assert(sizeof(ray_triangle_hit_t) == 20, "ray_triangle_hit_t layout");

/// A ray's frame for the watertight tests (Rust's `RayFrame`): the direction's dominant axis
/// kz (x and y following cyclically, swapped when it points backwards) and the shear sx, sy.
/// It depends on the direction only, so a walk makes it once per ray rather than once per
/// face (two of the three divisions; sz = 1 / dir[kz] and the parallel test's |dir| are taken
/// only for a face the ray hits). k packs kx | ky << 2 | kz << 4, or is -1 for a zero or
/// non-finite direction (no face is hit or crossed then): fewer registers live across the
/// walk.
struct ray_frame_t {
  i32 k;
  f32 sx, sy;
  WP_FN bool ok() const { return k >= 0; }
  WP_FN int kx() const { return k & 3; }
  WP_FN int ky() const { return (k >> 2) & 3; }
  WP_FN int kz() const { return k >> 4; }
};

namespace detail {
/// tie_broken_side: the sign of the edge function e = p.x * q.y - p.y * q.x once the origin
/// moves by (eps, eps^2): its own, else that of p.y - q.y, else of q.x - p.x; 0 for NaN.
WP_LFN int tie_broken_side(f64 e, f32 px, f32 py, f32 qx, f32 qy) {
  if (e > 0.0) return 1;
  if (e < 0.0) return -1;
  if (!(e == 0.0)) return 0;
  const f32 gx = py - qy;
  if (gx > 0.0f) return 1;
  if (gx < 0.0f) return -1;
  const f32 gy = qx - px;
  if (gy > 0.0f) return 1;
  if (gy < 0.0f) return -1;
  return 0;
}

/// A triangle in a ray's frame (Rust's `Sheared`): the vertices relative to the start at the
/// power-of-two scale s (q), their sheared x, y (xy) and the three edge functions (e: exact
/// f32 products in f64), with the frame's kz for the depths.
struct sheared_t {
  int kz;
  f32 s;
  Vec3 q[3];
  f32 x[3], y[3];
  f64 e[3];
};

/// Shears triangle (a, b, c) into the frame `fr` (ok) of a ray from `start`.
WP_LFN void shear_triangle(const ray_frame_t& fr, Vec3 start, Vec3 a, Vec3 b, Vec3 c,
                          sheared_t& sh) {
  const int kx = fr.kx(), ky = fr.ky(), kz = fr.kz();
  sh.kz = kz;
  sh.q[0] = a - start;
  sh.q[1] = b - start;
  sh.q[2] = c - start;
  sh.s = pow2_scale(g_max_abs(sh.q));
  // Unrolled, so that the arrays stay in registers (see g_max_abs).
#if defined(__CUDACC__)
#pragma unroll
#endif
  for (int k = 0; k < 3; ++k) {
    sh.q[k] = sh.q[k] * sh.s;
    sh.x[k] = g_comp(sh.q[k], kx) - fr.sx * g_comp(sh.q[k], kz);
    sh.y[k] = g_comp(sh.q[k], ky) - fr.sy * g_comp(sh.q[k], kz);
  }
  // The products are exact in f64 (24-bit significands), so contraction cannot change these.
  sh.e[0] = (f64)sh.x[2] * (f64)sh.y[1] - (f64)sh.y[2] * (f64)sh.x[1];
  sh.e[1] = (f64)sh.x[0] * (f64)sh.y[2] - (f64)sh.y[0] * (f64)sh.x[2];
  sh.e[2] = (f64)sh.x[1] * (f64)sh.y[0] - (f64)sh.y[1] * (f64)sh.x[0];
}

/// The ray parameter where the sheared triangle's plane is met, from the edge functions and
/// their sum `det` (nonzero), for the ray along dir; NaN or inf for a degenerate one.
WP_LFN f64 sheared_depth(const sheared_t& sh, Vec3 dir, f64 det) {
  const f32 sz = 1.0f / g_comp(dir, sh.kz);
  const f32 az = sz * g_comp(sh.q[0], sh.kz), bz = sz * g_comp(sh.q[1], sh.kz),
            cz = sz * g_comp(sh.q[2], sh.kz);
  const f64 tt = (sh.e[0] * (f64)az + sh.e[1] * (f64)bz) + sh.e[2] * (f64)cz;
  return tt / det;
}
}  // namespace detail

/// The frame of the ray along `dir` (see ray_frame_t).
WP_LFN ray_frame_t ray_frame(Vec3 dir) {
  using namespace detail;
  ray_frame_t fr;
  const Vec3 ad = g_abs(dir);
  const int kz = (ad.x >= ad.y && ad.x >= ad.z) ? 0 : (ad.y >= ad.z ? 1 : 2);
  const f32 dz = g_comp(dir, kz);
  int kx = (kz + 1) % 3, ky = (kz + 2) % 3;
  fr.k = -1;
  fr.sx = fr.sy = 0.0f;
  if (!(dz != 0.0f && g_finite3(dir))) return fr;
  if (dz < 0.0f) {
    const int t = kx;
    kx = ky;
    ky = t;
  }
  fr.k = kx | (ky << 2) | (kz << 4);
  fr.sx = g_comp(dir, kx) / dz;
  fr.sy = g_comp(dir, ky) / dz;
  return fr;
}

/// A hit of intersect_ray_triangle before its barycentrics are divided out (Rust's
/// `RayTriangleCandidate`): t, the sign, and the edge functions uu, vv with their sum det, from
/// which u = (f32)(uu / det), v = (f32)(vv / det). A closest-hit search compares t with its
/// bound first and divides only for a nearer hit.
struct ray_triangle_candidate_t {
  bool result;
  f32 t;
  f32 sign;
  f64 uu, vv, det;
};

/// intersect_ray_triangle in the ray's frame `fr` (ray_frame(dir)), without the division of
/// the barycentrics: the same hits, t and sign.
WP_LFN ray_triangle_candidate_t intersect_ray_triangle_in_frame(const ray_frame_t& fr, Vec3 start,
                                                               Vec3 dir, Vec3 a, Vec3 b,
                                                               Vec3 c) {
  using namespace detail;
  ray_triangle_candidate_t miss;
  miss.result = false;
  miss.t = 0.0f;
  miss.sign = 0.0f;
  miss.uu = miss.vv = miss.det = 0.0;
  if (!fr.ok()) return miss;
  sheared_t sh;
  shear_triangle(fr, start, a, b, c, sh);
  // The hit is the conjunction of side-effect-free tests, so their order is free: the cheap
  // sign test of the edge functions (most faces fail it) before the parallel test's cross
  // product and square roots.
  const f64 uu = sh.e[0], vv = sh.e[1], ww = sh.e[2];
  const bool inside =
      (uu >= 0.0 && vv >= 0.0 && ww >= 0.0) || (uu <= 0.0 && vv <= 0.0 && ww <= 0.0);
  const f64 det = (uu + vv) + ww;
  if (!(inside && det != 0.0)) return miss;
  // Parallel rays (and degenerate triangles) never hit.
  const Vec3 ab = sh.q[1] - sh.q[0], ac = sh.q[2] - sh.q[0];
  const f32 dn = g_dot(dir, g_cross(ab, ac));
  if (!(::fabsf(dn) > ((1e-6f * g_len(dir)) * g_len(ab)) * g_len(ac))) return miss;
  const f32 t = (f32)sheared_depth(sh, dir, det) / sh.s;
  if (!(t >= 0.0f && g_finite(t))) return miss;
  ray_triangle_candidate_t h;
  h.result = true;
  h.t = t;
  h.sign = dn < 0.0f ? 1.0f : -1.0f;
  h.uu = uu;
  h.vv = vv;
  h.det = det;
  return h;
}

/// Woop, Benthin and Wald's watertight test: shear into the ray's frame, then the signs of
/// three edge functions computed as exact f32 products in f64 (one rounding each, so exact
/// signs: a shared edge evaluates identically for both of its triangles).
WP_LFN ray_triangle_hit_t intersect_ray_triangle(Vec3 start, Vec3 dir, Vec3 a, Vec3 b, Vec3 c) {
  const ray_triangle_candidate_t k =
      intersect_ray_triangle_in_frame(ray_frame(dir), start, dir, a, b, c);
  ray_triangle_hit_t h;
  h.result = k.result;
  h.t = k.t;
  h.u = k.result ? (f32)(k.uu / k.det) : 0.0f;
  h.v = k.result ? (f32)(k.vv / k.det) : 0.0f;
  h.sign = k.sign;
  return h;
}

/// ray_crosses_triangle in the frame `fr` (ray_frame(dir)) of the ray along dir.
WP_LFN bool ray_crosses_triangle_in_frame(const ray_frame_t& fr, Vec3 start, Vec3 dir, Vec3 a,
                                         Vec3 b, Vec3 c) {
  using namespace detail;
  if (!fr.ok()) return false;
  sheared_t sh;
  shear_triangle(fr, start, a, b, c, sh);
  const int su = tie_broken_side(sh.e[0], sh.x[2], sh.y[2], sh.x[1], sh.y[1]);
  const int sv = tie_broken_side(sh.e[1], sh.x[0], sh.y[0], sh.x[2], sh.y[2]);
  const int sw = tie_broken_side(sh.e[2], sh.x[1], sh.y[1], sh.x[0], sh.y[0]);
  if (!(su != 0 && su == sv && sv == sw)) return false;
  const f64 det = (sh.e[0] + sh.e[1]) + sh.e[2];
  if (det == 0.0) return false;
  const f64 t = sheared_depth(sh, dir, det);
  return t >= 0.0 && t - t == 0.0;  // finite: inf - inf and NaN - NaN are NaN
}

/// Whether the ray start + t * dir, t >= 0, crosses triangle (a, b, c) for a parity count:
/// intersect_ray_triangle's sheared edge functions with their exact zeros tie-broken
/// (simulation of simplicity) and no parallel rejection (see the Rust for why).
WP_LFN bool ray_crosses_triangle(Vec3 start, Vec3 dir, Vec3 a, Vec3 b, Vec3 c) {
  return ray_crosses_triangle_in_frame(ray_frame(dir), start, dir, a, b, c);
}

// ------------------------------------------------------------------------------------------
// Boxes
// ------------------------------------------------------------------------------------------

/// Whether boxes [al, au] and [bl, bu] overlap (touching counts); inverted or NaN boxes never.
WP_LFN bool aabb_overlap(Vec3 al, Vec3 au, Vec3 bl, Vec3 bu) {
  return al.x <= bu.x && al.y <= bu.y && al.z <= bu.z && bl.x <= au.x && bl.y <= au.y &&
         bl.z <= au.z && al.x <= au.x && al.y <= au.y && al.z <= au.z;
}

/// The slab test: true (Rust's Some) when the ray meets [lo, hi] at some t >= 0, with the
/// entry parameter in *t_enter (negative from inside); false (None) otherwise.
WP_LFN bool intersect_ray_aabb(Vec3 start, Vec3 inv_dir, Vec3 lower, Vec3 upper, f32* t_enter) {
  using namespace detail;
  f32 t0 = -f32_inf();
  f32 t1 = f32_inf();
  for (int k = 0; k < 3; ++k) {
    const f32 o = g_comp(start, k), inv = g_comp(inv_dir, k);
    const f32 lo = g_comp(lower, k), hi = g_comp(upper, k);
    if (g_is_inf(inv)) {
      if (!(lo <= o && o <= hi)) return false;
    } else {
      const f32 ta = (lo - o) * inv, tb = (hi - o) * inv;
      const f32 nr = inv >= 0.0f ? ta : tb;
      const f32 fr = inv >= 0.0f ? tb : ta;
      if (!(nr <= fr)) return false;
      if (nr > t0) t0 = nr;
      if (fr < t1) t1 = fr;
    }
  }
  if (t0 <= t1 && t1 >= 0.0f) {
    *t_enter = t0;
    return true;
  }
  return false;
}

/// intersect_ray_aabb for an inv_dir with no infinite component (a direction with no zero
/// component; NaN allowed), without a branch: per axis the same two products, the same near
/// and far choice by the sign of inv, and the same updates of t0 and t1, with the early
/// `return false` of an inverted slab folded into `ok`. While ok holds every step is the
/// branching version's; once it fails that version returns false and so does this one: the
/// same result and the same *t_enter.
WP_LFN bool intersect_ray_aabb_finite(Vec3 start, Vec3 inv_dir, Vec3 lower, Vec3 upper,
                                     f32* t_enter) {
  using namespace detail;
  f32 t0 = -f32_inf();
  f32 t1 = f32_inf();
  bool ok = true;
#if defined(__CUDACC__)
#pragma unroll
#endif
  for (int k = 0; k < 3; ++k) {
    const f32 o = g_comp(start, k), inv = g_comp(inv_dir, k);
    const f32 ta = (g_comp(lower, k) - o) * inv, tb = (g_comp(upper, k) - o) * inv;
    const bool pos = inv >= 0.0f;
    const f32 nr = pos ? ta : tb;
    const f32 fr = pos ? tb : ta;
    ok = ok && nr <= fr;
    t0 = nr > t0 ? nr : t0;
    t1 = fr < t1 ? fr : t1;
  }
  *t_enter = t0;
  return ok && t0 <= t1 && t1 >= 0.0f;
}

/// Whether intersect_ray_aabb_finite serves inv_dir (no component infinite).
WP_LFN bool ray_inv_dir_finite(Vec3 inv_dir) {
  return !detail::g_is_inf(inv_dir.x) && !detail::g_is_inf(inv_dir.y) &&
         !detail::g_is_inf(inv_dir.z);
}

/// 1 / dir per component (±inf for zero components).
WP_LFN Vec3 ray_inv_dir(Vec3 dir) { return Vec3_new(1.0f / dir.x, 1.0f / dir.y, 1.0f / dir.z); }

/// Squared distance from p to [lower, upper] (0 inside); clamps by comparisons, so an inverted
/// box is fine.
WP_LFN f32 aabb_distance_sq(Vec3 p, Vec3 lower, Vec3 upper) {
  const auto c = [](f32 x, f32 l, f32 h) {
    const f32 y = x > h ? h : x;
    return y < l ? l : y;
  };
  const Vec3 q = Vec3_new(c(p.x, lower.x, upper.x), c(p.y, lower.y, upper.y),
                          c(p.z, lower.z, upper.z));
  return detail::g_len_sq(q - p);
}

/// aabb_distance_sq_scaled: |(clamp(p, lower, upper) - p) * s|^2 for a power of two s. The
/// clamp by fminf/fmaxf (one instruction each, where the comparisons of aabb_distance_sq take
/// two) selects the same value as the Rust comparisons in every case, NaN included (a NaN
/// bound is passed over by both; a NaN p makes the difference NaN either way), except the
/// sign of a zero, which the difference and its square do not keep: the same bits.
WP_LFN f32 aabb_distance_sq_scaled(Vec3 p, Vec3 lower, Vec3 upper, f32 s) {
  const Vec3 q = Vec3_new(::fmaxf(::fminf(p.x, upper.x), lower.x),
                          ::fmaxf(::fminf(p.y, upper.y), lower.y),
                          ::fmaxf(::fminf(p.z, upper.z), lower.z));
  return detail::g_len_sq((q - p) * s);
}

// ------------------------------------------------------------------------------------------
// Triangle against triangle
// ------------------------------------------------------------------------------------------

namespace detail {
struct g_pt2 {
  f32 x, y;
};
WP_LFN g_pt2 g_p2(f32 x, f32 y) {
  g_pt2 r;
  r.x = x;
  r.y = y;
  return r;
}
WP_LFN bool tt_degenerate(const Vec3* t) {
  const Vec3 e0 = t[1] - t[0], e1 = t[2] - t[0], e2 = t[2] - t[1];
  const f32 sum = (g_len_sq(e0) + g_len_sq(e1)) + g_len_sq(e2);
  return !(g_len(g_cross(e0, e1)) > WP_SLIVER_RATIO * sum);
}
/// Signed distances (times |n|) of pts from t's plane, snapped to 0 within the tolerance.
WP_LFN Vec3 tt_plane_distances(const Vec3* t, const Vec3* pts, f32* d) {
  const Vec3 n = g_cross(t[1] - t[0], t[2] - t[0]);
  const f32 eps = WP_TRI_TRI_EPS * g_len(n);
  for (int i = 0; i < 3; ++i) {
    const f32 x = g_dot(n, pts[i] - t[0]);
    d[i] = ::fabsf(x) <= eps ? 0.0f : x;
  }
  return n;
}
WP_LFN bool tt_same_side(const f32* d) {
  return (d[0] > 0.0f && d[1] > 0.0f && d[2] > 0.0f) ||
         (d[0] < 0.0f && d[1] < 0.0f && d[2] < 0.0f);
}
WP_LFN void tt_projection_axes(const Vec3& n, int* i, int* j) {
  const Vec3 m = g_abs(n);
  if (m.x >= m.y && m.x >= m.z) {
    *i = 1;
    *j = 2;
  } else if (m.y >= m.z) {
    *i = 0;
    *j = 2;
  } else {
    *i = 0;
    *j = 1;
  }
}
WP_LFN f32 tt_orient2(g_pt2 p, g_pt2 q, g_pt2 r) {
  return (q.x - p.x) * (r.y - p.y) - (q.y - p.y) * (r.x - p.x);
}
WP_LFN bool tt_between(g_pt2 a, g_pt2 b, g_pt2 c) {
  return c.x >= ::fminf(a.x, b.x) && c.x <= ::fmaxf(a.x, b.x) && c.y >= ::fminf(a.y, b.y) &&
         c.y <= ::fmaxf(a.y, b.y);
}
WP_LFN bool tt_segments_2d(g_pt2 p, g_pt2 q, g_pt2 r, g_pt2 s) {
  const f32 o1 = tt_orient2(p, q, r), o2 = tt_orient2(p, q, s);
  const f32 o3 = tt_orient2(r, s, p), o4 = tt_orient2(r, s, q);
  if (((o1 > 0.0f && o2 < 0.0f) || (o1 < 0.0f && o2 > 0.0f)) &&
      ((o3 > 0.0f && o4 < 0.0f) || (o3 < 0.0f && o4 > 0.0f)))
    return true;
  return (o1 == 0.0f && tt_between(p, q, r)) || (o2 == 0.0f && tt_between(p, q, s)) ||
         (o3 == 0.0f && tt_between(r, s, p)) || (o4 == 0.0f && tt_between(r, s, q));
}
WP_LFN bool tt_in_triangle_2d(g_pt2 x, const g_pt2* t) {
  const f32 o0 = tt_orient2(t[0], t[1], x), o1 = tt_orient2(t[1], t[2], x),
            o2 = tt_orient2(t[2], t[0], x);
  return (o0 >= 0.0f && o1 >= 0.0f && o2 >= 0.0f) || (o0 <= 0.0f && o1 <= 0.0f && o2 <= 0.0f);
}
WP_LFN bool tt_coplanar(const Vec3& n, const Vec3* a, const Vec3* b) {
  int i, j;
  tt_projection_axes(n, &i, &j);
  g_pt2 pa[3], pb[3];
  for (int k = 0; k < 3; ++k) {
    pa[k] = g_p2(g_comp(a[k], i), g_comp(a[k], j));
    pb[k] = g_p2(g_comp(b[k], i), g_comp(b[k], j));
  }
  for (int e = 0; e < 3; ++e)
    for (int f = 0; f < 3; ++f)
      if (tt_segments_2d(pa[e], pa[(e + 1) % 3], pb[f], pb[(f + 1) % 3])) return true;
  return tt_in_triangle_2d(pa[0], pb) || tt_in_triangle_2d(pb[0], pa);
}
/// The interval a triangle covers on the planes' line; false (None) when every d is zero.
WP_LFN bool tt_interval(const f32* p, const f32* d, f32* lo, f32* hi) {
  int lone;
  if (d[0] * d[1] > 0.0f)
    lone = 2;
  else if (d[0] * d[2] > 0.0f)
    lone = 1;
  else if (d[1] * d[2] > 0.0f || d[0] != 0.0f)
    lone = 0;
  else if (d[1] != 0.0f)
    lone = 1;
  else if (d[2] != 0.0f)
    lone = 2;
  else
    return false;
  const int i = (lone + 1) % 3, j = (lone + 2) % 3;
  const f32 t0 = p[lone] + (p[i] - p[lone]) * (d[lone] / (d[lone] - d[i]));
  const f32 t1 = p[lone] + (p[j] - p[lone]) * (d[lone] / (d[lone] - d[j]));
  if (t0 <= t1) {
    *lo = t0;
    *hi = t1;
  } else {
    *lo = t1;
    *hi = t0;
  }
  return true;
}
WP_LFN bool tt_tri_tri(const Vec3* a, const Vec3* b) {
  f32 da[3], db[3];
  const Vec3 nb = tt_plane_distances(b, a, da);
  if (tt_same_side(da)) return false;
  const Vec3 na = tt_plane_distances(a, b, db);
  if (tt_same_side(db)) return false;
  if ((da[0] == 0.0f && da[1] == 0.0f && da[2] == 0.0f) ||
      (db[0] == 0.0f && db[1] == 0.0f && db[2] == 0.0f))
    return tt_coplanar(na, a, b);
  const Vec3 dir = g_abs(g_cross(na, nb));
  const int k = (dir.x >= dir.y && dir.x >= dir.z) ? 0 : (dir.y >= dir.z ? 1 : 2);
  const f32 pa[3] = {g_comp(a[0], k), g_comp(a[1], k), g_comp(a[2], k)};
  const f32 pb[3] = {g_comp(b[0], k), g_comp(b[1], k), g_comp(b[2], k)};
  f32 a0, a1, b0, b1;
  const bool ia = tt_interval(pa, da, &a0, &a1);
  const bool ib = tt_interval(pb, db, &b0, &b1);
  if (!(ia && ib)) return tt_coplanar(na, a, b);
  return a0 <= b1 && b0 <= a1;
}
/// Whether segment pq meets the non-degenerate triangle t.
WP_LFN bool tt_segment_triangle(const Vec3& p, const Vec3& q, const Vec3* t) {
  const Vec3 pts[3] = {p, q, p};
  f32 d[3];
  const Vec3 n = tt_plane_distances(t, pts, d);
  const f32 dp = d[0], dq = d[1];
  if ((dp > 0.0f && dq > 0.0f) || (dp < 0.0f && dq < 0.0f)) return false;
  int i, j;
  tt_projection_axes(n, &i, &j);
  g_pt2 pt[3];
  for (int k = 0; k < 3; ++k) pt[k] = g_p2(g_comp(t[k], i), g_comp(t[k], j));
  if (dp == 0.0f && dq == 0.0f) {
    const g_pt2 a = g_p2(g_comp(p, i), g_comp(p, j)), b = g_p2(g_comp(q, i), g_comp(q, j));
    if (tt_in_triangle_2d(a, pt)) return true;
    for (int e = 0; e < 3; ++e)
      if (tt_segments_2d(a, b, pt[e], pt[(e + 1) % 3])) return true;
    return false;
  }
  const Vec3 x = p + (q - p) * (dp / (dp - dq));
  return tt_in_triangle_2d(g_p2(g_comp(x, i), g_comp(x, j)), pt);
}
/// Whether two segments come within 4 * TRI_TRI_EPS (Ericson 5.1.9, clamped).
WP_LFN bool tt_segments_touch(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) {
  const Vec3 d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const f32 a = g_dot(d1, d1), e = g_dot(d2, d2), f = g_dot(d2, r);
  f32 s, t;
  if (a <= 0.0f && e <= 0.0f) {
    s = 0.0f;
    t = 0.0f;
  } else if (a <= 0.0f) {
    s = 0.0f;
    t = g_clamp(f / e, 0.0f, 1.0f);
  } else {
    const f32 c = g_dot(d1, r);
    if (e <= 0.0f) {
      s = g_clamp(-c / a, 0.0f, 1.0f);
      t = 0.0f;
    } else {
      const f32 b = g_dot(d1, d2);
      const f32 den = a * e - b * b;
      s = den > 0.0f ? g_clamp((b * f - c * e) / den, 0.0f, 1.0f) : 0.0f;
      t = (b * s + f) / e;
      if (t < 0.0f) {
        t = 0.0f;
        s = g_clamp(-c / a, 0.0f, 1.0f);
      } else if (t > 1.0f) {
        t = 1.0f;
        s = g_clamp((b - c) / a, 0.0f, 1.0f);
      }
    }
  }
  const Vec3 gap = (p0 + d1 * s) - (q0 + d2 * t);
  return g_len(gap) <= WP_TRI_TRI_EPS * 4.0f;
}
}  // namespace detail

/// Whether triangles (v0, v1, v2) and (u0, u1, u2) intersect, touching included.
WP_LFN bool intersect_tri_tri(Vec3 v0, Vec3 v1, Vec3 v2, Vec3 u0, Vec3 u1, Vec3 u2) {
  using namespace detail;
  const Vec3 o = v0;
  Vec3 a[3] = {v0 - o, v1 - o, v2 - o};
  Vec3 b[3] = {u0 - o, u1 - o, u2 - o};
  const Vec3 all[6] = {a[0], a[1], a[2], b[0], b[1], b[2]};
  const f32 s = pow2_scale(g_max_abs(all));
  for (int k = 0; k < 3; ++k) {
    a[k] = a[k] * s;
    b[k] = b[k] * s;
  }
  for (int k = 0; k < 3; ++k)
    if (!g_finite3(a[k])) return false;
  for (int k = 0; k < 3; ++k)
    if (!g_finite3(b[k])) return false;
  const bool da = tt_degenerate(a), db = tt_degenerate(b);
  if (!da && !db) return tt_tri_tri(a, b);
  if (da && !db) {
    for (int e = 0; e < 3; ++e)
      if (tt_segment_triangle(a[e], a[(e + 1) % 3], b)) return true;
    return false;
  }
  if (!da && db) {
    for (int e = 0; e < 3; ++e)
      if (tt_segment_triangle(b[e], b[(e + 1) % 3], a)) return true;
    return false;
  }
  for (int e = 0; e < 3; ++e)
    for (int f = 0; f < 3; ++f)
      if (tt_segments_touch(a[e], a[(e + 1) % 3], b[f], b[(f + 1) % 3])) return true;
  return false;
}

}  // namespace wp

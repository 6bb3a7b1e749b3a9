// wp_adjoint_geometry.h: adjoints of the "geometry" section (warp-core/src/objects/geometry.rs).
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions (accumulate into the
// adjoint arguments; formulas in the Rust order, so bit-exact with --fmad=false).
//
//   adj_closest_point_triangle(a, b, c, p, adj_a, adj_b, adj_c, adj_p, adj_ret)
//       adj_p += du/dp * adj_ret.u + dv/dp * adj_ret.v + dw/dp * adj_ret.w for the feature the
//       forward finds (zero at a vertex, along the edge on an edge, the projection onto the
//       plane inside the face); the vertices get nothing (as on the CPU).
//   adj_zero / zero_like / adj_accum for triangle_closest_point_t (u, v, w accumulate; the
//   feature has none) and ray_triangle_hit_t (no gradient: the CPU has no adjoint for it).
#pragma once
#include "wp_adjoint_core.h"
#include "wp_geometry.h"

namespace wp {

template <>
WP_FN triangle_closest_point_t adj_zero<triangle_closest_point_t>() {
  return triangle_closest_point_t{};
}
WP_LFN triangle_closest_point_t zero_like(const triangle_closest_point_t&) {
  return triangle_closest_point_t{};
}
WP_LFN void adj_accum(triangle_closest_point_t& a, const triangle_closest_point_t& v) {
  a.u += v.u;
  a.v += v.v;
  a.w += v.w;
}

template <>
WP_FN ray_triangle_hit_t adj_zero<ray_triangle_hit_t>() {
  return ray_triangle_hit_t{};
}
WP_LFN ray_triangle_hit_t zero_like(const ray_triangle_hit_t&) { return ray_triangle_hit_t{}; }
WP_LFN void adj_accum(ray_triangle_hit_t&, const ray_triangle_hit_t&) {}

namespace detail {
/// closest_point_triangle_jacobian: rows du/dp, dv/dp, dw/dp for `feature`, computed on the
/// translated, scaled triangle and scaled back.
WP_LFN void closest_point_triangle_jacobian(Vec3 a, Vec3 b, Vec3 c, Vec3 p, i32 feature,
                                           Vec3* rows) {
  Vec3 ab = b - a, ac = c - a;
  const Vec3 ap = p - a;
  const Vec3 vs[3] = {ab, ac, ap};
  const f32 s = pow2_scale(g_max_abs(vs));
  ab = ab * s;
  ac = ac * s;
  const auto edge = [s](Vec3 d) {
    const f32 dd = g_dot(d, d);
    return dd > 0.0f ? d * (s / dd) : Vec3_ZERO();
  };
  const Vec3 z = Vec3_ZERO();
  rows[0] = rows[1] = rows[2] = z;
  switch (feature) {
    case TRI_FEATURE_EDGE_AB: {
      const Vec3 dt = edge(ab);
      rows[0] = -dt;
      rows[1] = dt;
      break;
    }
    case TRI_FEATURE_EDGE_BC: {
      const Vec3 dt = edge(ac - ab);
      rows[1] = -dt;
      rows[2] = dt;
      break;
    }
    case TRI_FEATURE_EDGE_CA: {
      const Vec3 dt = edge(-ac);
      rows[0] = dt;
      rows[2] = -dt;
      break;
    }
    case TRI_FEATURE_FACE: {
      const f32 g00 = g_dot(ab, ab), g01 = g_dot(ab, ac), g11 = g_dot(ac, ac);
      const f32 det = g00 * g11 - g01 * g01;
      if (!(det > 0.0f)) break;
      const f32 k = s / det;
      const Vec3 dv = (ab * g11 - ac * g01) * k;
      const Vec3 dw = (ac * g00 - ab * g01) * k;
      rows[0] = -(dv + dw);
      rows[1] = dv;
      rows[2] = dw;
      break;
    }
    default:  // a vertex: the closest point does not move
      break;
  }
}
}  // namespace detail

WP_LFN void adj_closest_point_triangle(Vec3 a, Vec3 b, Vec3 c, Vec3 p, Vec3& adj_a, Vec3& adj_b,
                                      Vec3& adj_c, Vec3& adj_p,
                                      const triangle_closest_point_t& adj_ret) {
  (void)adj_a;
  (void)adj_b;
  (void)adj_c;
  const i32 f = closest_point_triangle(a, b, c, p).feature;
  Vec3 rows[3];
  detail::closest_point_triangle_jacobian(a, b, c, p, f, rows);
  adj_p = adj_p + ((rows[0] * adj_ret.u + rows[1] * adj_ret.v) + rows[2] * adj_ret.w);
}

/// The kernel language's `closest_point_triangle` returns the barycentrics as a Vec3 (the
/// struct's conversion): its adjoint arrives as one.
WP_LFN void adj_closest_point_triangle(Vec3 a, Vec3 b, Vec3 c, Vec3 p, Vec3& adj_a, Vec3& adj_b,
                                      Vec3& adj_c, Vec3& adj_p, Vec3 adj_ret) {
  adj_closest_point_triangle(a, b, c, p, adj_a, adj_b, adj_c, adj_p,
                             triangle_closest_point_t{adj_ret.x, adj_ret.y, adj_ret.z, 0});
}

}  // namespace wp

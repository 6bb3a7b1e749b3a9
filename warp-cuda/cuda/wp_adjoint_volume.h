// wp_adjoint_volume.h: adjoints of the "volume" section (warp-core/src/adjoint/volume.rs and
// objects/volume.rs). Part of the CUDA adjoint library; see wp_adjoint.h for its conventions.
// The functions that sample take the fault context last (after adj_ret) and return at once
// after a fault, as their forward ones.
//
//   adj_volume_sample(v, uvw, mode, adj_v, adj_uvw, adj_mode, adj_ret, ctx)
//       LINEAR: adj_uvw += dot(x_c, adj_ret) * dw_c over the 8 corners (CLOSEST: nothing);
//       with a gradient grid (v.grad != 0), w_c * adj_ret is added atomically into it at the
//       byte offset each value was read from (leaf value, tile value or root background).
//   adj_volume_sample_grad(v, uvw, mode, adj_v, adj_uvw, adj_mode, adj_ret, ctx)
//       adj_ret = (adj_value, adj_grad): also the mixed second derivatives of the weights
//       into adj_uvw, and adj_grad * dw_c into the value gradients.
//   adj_volume_lookup(v, i, j, k, adj_v, adj_i, adj_j, adj_k, adj_ret, ctx)
//       adj_ret into the gradient grid at the voxel's value.
//   adj_volume_index_to_world(v, uvw, adj_v, adj_uvw, adj_ret, ctx) and the other three
//       transforms: adj_uvw += M^T adj_ret with the f32 Map copy the forward used.
//   adj_volume_sample_index / adj_volume_sample_grad_index(v, uvw, mode, data, bg, adj_v,
//       adj_uvw, adj_mode, adj_data, adj_bg, adj_ret, ctx): the position only (no data or
//       background gradients in this round).
//   volume_store and volume_lookup_index have no adjoint (Grad::Zero).
//
// Value gradients go through wp_atomic.h's helpers: one atomicAdd per float component on the
// device, a plain add on the host (single-threaded host checks only).
#pragma once
#include "wp_adjoint_core.h"
#include "wp_volume.h"

namespace wp {

namespace detail {

/// grad[off] += x, atomically per component.
WP_FN void vol_grad_add(u64 a, f32 x) { atomic_add_p((f32*)a, x); }
WP_FN void vol_grad_add(u64 a, f64 x) { atomic_add_p((f64*)a, x); }
WP_FN void vol_grad_add(u64 a, Vec3 x) {
  atomic_add_p((f32*)a, x.x);
  atomic_add_p((f32*)(a + 4), x.y);
  atomic_add_p((f32*)(a + 8), x.z);
}
WP_FN void vol_grad_add(u64 a, DVec3 x) {
  atomic_add_p((f64*)a, x.x);
  atomic_add_p((f64*)(a + 8), x.y);
  atomic_add_p((f64*)(a + 16), x.z);
}

/// dot(x, y) in the value's scalar type (glam's order for vectors).
WP_FN f32 vol_dot(f32 x, f32 y) { return x * y; }
WP_FN f64 vol_dot(f64 x, f64 y) { return x * y; }
WP_FN f32 vol_dot(Vec3 x, Vec3 y) { return (x.x * y.x + x.y * y.y) + x.z * y.z; }
WP_FN f64 vol_dot(DVec3 x, DVec3 y) { return (x.x * y.x + x.y * y.y) + x.z * y.z; }

/// adj_uvw += d * dw (f64 products rounded to f32 once).
WP_FN void vol_uvw_acc(Vec3& adj_uvw, f32 d, Vec3 dw) {
  adj_uvw.x += d * dw.x;
  adj_uvw.y += d * dw.y;
  adj_uvw.z += d * dw.z;
}
WP_FN void vol_uvw_acc(Vec3& adj_uvw, f64 d, Vec3 dw) {
  adj_uvw.x += (f32)(d * (f64)dw.x);
  adj_uvw.y += (f32)(d * (f64)dw.y);
  adj_uvw.z += (f32)(d * (f64)dw.z);
}

/// `x . adj_grad` as a row over the axes: sum over components c of x_c * adj_grad[c][a].
WP_FN Vec3 vol_xg(f32 x, Vec3 g) { return Vec3_new(x * g.x, x * g.y, x * g.z); }
WP_FN DVec3 vol_xg(f64 x, DVec3 g) { return DVec3_new(x * g.x, x * g.y, x * g.z); }
WP_FN Vec3 vol_xg(Vec3 x, const Mat3& g) {
  return Vec3_new(vol_dot(x, g.x_axis), vol_dot(x, g.y_axis), vol_dot(x, g.z_axis));
}
WP_FN DVec3 vol_xg(DVec3 x, const DMat3& g) {
  return DVec3_new(vol_dot(x, g.x_axis), vol_dot(x, g.y_axis), vol_dot(x, g.z_axis));
}
/// adj_grad * dw: the value gradient of the gradient term (scalar: dot; vector: matrix times
/// vector).
WP_FN f32 vol_gdw(Vec3 g, Vec3 dw) { return (g.x * dw.x + g.y * dw.y) + g.z * dw.z; }
WP_FN f64 vol_gdw(DVec3 g, Vec3 dw) {
  return (g.x * (f64)dw.x + g.y * (f64)dw.y) + g.z * (f64)dw.z;
}
WP_FN Vec3 vol_gdw(const Mat3& g, Vec3 dw) {
  return (vol_scale(dw.x, g.x_axis) + vol_scale(dw.y, g.y_axis)) + vol_scale(dw.z, g.z_axis);
}
WP_FN DVec3 vol_gdw(const DMat3& g, Vec3 dw) {
  return (vol_scale(dw.x, g.x_axis) + vol_scale(dw.y, g.y_axis)) + vol_scale(dw.z, g.z_axis);
}

/// The weight Hessian's product with a row r over the axes: (r H)_b = sum_a r_a H[a][b],
/// H[a][b] = s_a s_b w_c (c the third axis), zero diagonal.
template <typename V>
WP_FN void vol_hess_acc(Vec3& adj_uvw, const vol_stencil_t& s, int c, const V& r) {
  const int ox = (c >> 2) & 1, oy = (c >> 1) & 1, oz = c & 1;
  typedef typename vec_traits<V>::scalar S;
  const S sx = ox ? (S)1 : (S)-1, sy = oy ? (S)1 : (S)-1, sz = oz ? (S)1 : (S)-1;
  const S wx = (S)s.wx[ox], wy = (S)s.wy[oy], wz = (S)s.wz[oz];
  const S hxy = sx * sy * wz, hxz = sx * sz * wy, hyz = sy * sz * wx;
  adj_uvw.x += (f32)(r.y * hxy + r.z * hxz);
  adj_uvw.y += (f32)(r.x * hxy + r.z * hyz);
  adj_uvw.z += (f32)(r.x * hxz + r.y * hyz);
}

}  // namespace detail

template <typename T>
WP_FN void adj_volume_sample(const volume_t<T>& v, Vec3 uvw, i32 mode, volume_t<T>& adj_v,
                             Vec3& adj_uvw, i32& adj_mode, const typename identity<T>::type& adj_ret,
                             ctx_t* ctx) {
  using namespace detail;
  (void)adj_v;
  (void)adj_mode;
  typedef vol_value<T> V;
  if (!vol_finite(uvw, ctx)) return;
  if (!V::has_type(v.grid_type)) return;
  if (mode == VOLUME_CLOSEST) {
    if (v.grad != 0) vol_grad_add(v.grad + vol_value_offset(v, vol_closest(v, uvw)), adj_ret);
    return;
  }
  const vol_stencil_t s = vol_stencil(uvw);
  vol_acc_t a = vol_acc_new();
  for (int c = 0; c < 8; ++c) {
    const u64 off = vol_value_offset(v, vol_corner(v, a, s, c));
    const T x = V::read(v.data + off);
    vol_uvw_acc(adj_uvw, vol_dot(x, adj_ret), vol_dw(s, c));
    if (v.grad != 0) vol_grad_add(v.grad + off, vol_scale(vol_w(s, c), adj_ret));
  }
}

template <typename T>
WP_FN void adj_volume_sample_grad(
    const volume_t<T>& v, Vec3 uvw, i32 mode, volume_t<T>& adj_v, Vec3& adj_uvw, i32& adj_mode,
    const tuple_t<T, typename detail::vol_value<T>::grad>& adj_ret, ctx_t* ctx) {
  using namespace detail;
  (void)adj_v;
  (void)adj_mode;
  typedef vol_value<T> V;
  if (!vol_finite(uvw, ctx)) return;
  if (!V::has_type(v.grid_type)) return;
  if (mode == VOLUME_CLOSEST) {
    if (v.grad != 0) vol_grad_add(v.grad + vol_value_offset(v, vol_closest(v, uvw)), adj_ret.f0);
    return;
  }
  const vol_stencil_t s = vol_stencil(uvw);
  vol_acc_t a = vol_acc_new();
  for (int c = 0; c < 8; ++c) {
    const u64 off = vol_value_offset(v, vol_corner(v, a, s, c));
    const T x = V::read(v.data + off);
    const Vec3 dw = vol_dw(s, c);
    vol_uvw_acc(adj_uvw, vol_dot(x, adj_ret.f0), dw);
    vol_hess_acc(adj_uvw, s, c, vol_xg(x, adj_ret.f1));
    if (v.grad != 0)
      vol_grad_add(v.grad + off, vol_scale(vol_w(s, c), adj_ret.f0) + vol_gdw(adj_ret.f1, dw));
  }
}

template <typename T>
WP_FN void adj_volume_lookup(const volume_t<T>& v, i32 i, i32 j, i32 k, volume_t<T>& adj_v,
                             i32& adj_i, i32& adj_j, i32& adj_k,
                             const typename identity<T>::type& adj_ret, ctx_t* ctx) {
  using namespace detail;
  (void)adj_v;
  (void)adj_i;
  (void)adj_j;
  (void)adj_k;
  (void)ctx;
  typedef vol_value<T> V;
  if constexpr (V::is_float) {
    if (!V::has_type(v.grid_type) || v.grad == 0) return;
    vol_grad_add(v.grad + vol_value_offset(v, vol_lookup(v, i, j, k)), adj_ret);
  } else {
    (void)v;
    (void)adj_ret;
  }
}

namespace detail {
/// adj += M^T g with the f32 3x3 at byte `m` of the Map.
WP_FN void vol_map_mul_t_acc(u64 data, u32 m, Vec3 g, Vec3& adj) {
  f32 r[3];
  for (int col = 0; col < 3; ++col) {
    const u64 a = data + 296u + m + (u64)col * 4u;
    r[col] = (f32_from_bits(vol_ld_u32(a)) * g.x + f32_from_bits(vol_ld_u32(a + 12)) * g.y) +
             f32_from_bits(vol_ld_u32(a + 24)) * g.z;
  }
  adj.x += r[0];
  adj.y += r[1];
  adj.z += r[2];
}
}  // namespace detail

#define WP_ADJ_VOLUME_TRANSFORM(NAME, M)                                                     \
  template <typename T>                                                                      \
  WP_FN void adj_##NAME(const volume_t<T>& v, Vec3 p, volume_t<T>& adj_v, Vec3& adj_p,       \
                        const Vec3& adj_ret, ctx_t* ctx) {                                   \
    (void)p;                                                                                 \
    (void)adj_v;                                                                             \
    (void)ctx;                                                                               \
    detail::vol_map_mul_t_acc(v.data, M, adj_ret, adj_p);                                    \
  }
WP_ADJ_VOLUME_TRANSFORM(volume_index_to_world, detail::VOL_MAT_F)
WP_ADJ_VOLUME_TRANSFORM(volume_index_to_world_dir, detail::VOL_MAT_F)
WP_ADJ_VOLUME_TRANSFORM(volume_world_to_index, detail::VOL_INV_MAT_F)
WP_ADJ_VOLUME_TRANSFORM(volume_world_to_index_dir, detail::VOL_INV_MAT_F)
#undef WP_ADJ_VOLUME_TRANSFORM

template <typename G, typename T>
WP_FN void adj_volume_sample_index(const volume_t<G>& v, Vec3 uvw, i32 mode,
                                   const array_t<T, 1>& data, const typename identity<T>::type& bg,
                                   volume_t<G>& adj_v, Vec3& adj_uvw, i32& adj_mode,
                                   array_t<T, 1>& adj_data, T& adj_bg,
                                   const typename identity<T>::type& adj_ret, ctx_t* ctx) {
  using namespace detail;
  (void)adj_v;
  (void)adj_mode;
  (void)adj_data;
  (void)adj_bg;
  if (!vol_finite(uvw, ctx)) return;
  if (mode == VOLUME_CLOSEST) return;
  const vol_stencil_t s = vol_stencil(uvw);
  vol_acc_t a = vol_acc_new();
  for (int c = 0; c < 8; ++c) {
    const T x = vol_index_value(v, vol_corner(v, a, s, c), data, bg, ctx);
    if (faulted(ctx)) return;
    vol_uvw_acc(adj_uvw, vol_dot(x, adj_ret), vol_dw(s, c));
  }
}

template <typename G, typename T>
WP_FN void adj_volume_sample_grad_index(
    const volume_t<G>& v, Vec3 uvw, i32 mode, const array_t<T, 1>& data,
    const typename identity<T>::type& bg, volume_t<G>& adj_v, Vec3& adj_uvw, i32& adj_mode,
    array_t<T, 1>& adj_data, T& adj_bg,
    const tuple_t<T, typename detail::vol_value<T>::grad>& adj_ret, ctx_t* ctx) {
  using namespace detail;
  (void)adj_v;
  (void)adj_mode;
  (void)adj_data;
  (void)adj_bg;
  if (!vol_finite(uvw, ctx)) return;
  if (mode == VOLUME_CLOSEST) return;
  const vol_stencil_t s = vol_stencil(uvw);
  vol_acc_t a = vol_acc_new();
  for (int c = 0; c < 8; ++c) {
    const T x = vol_index_value(v, vol_corner(v, a, s, c), data, bg, ctx);
    if (faulted(ctx)) return;
    vol_uvw_acc(adj_uvw, vol_dot(x, adj_ret.f0), vol_dw(s, c));
    vol_hess_acc(adj_uvw, s, c, vol_xg(x, adj_ret.f1));
  }
}

}  // namespace wp

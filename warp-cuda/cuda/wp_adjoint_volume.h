// wp_adjoint_volume.h: adjoints of the "volume" section (warp-core/src/adjoint/volume.rs, the
// arithmetic documented in warp-core/src/objects/volume.rs). Part of the CUDA adjoint
// library; see wp_adjoint.h for its conventions. Every function takes the fault context last
// (after adj_ret) and returns at once after a fault, as its forward one; on a fault adj_uvw
// is left unchanged.
//
//   adj_volume_sample(v, uvw, mode, adj_v, adj_uvw, adj_mode, adj_ret, ctx)
//       LINEAR: adj_uvw += the sum over the 8 corners of f32(dot(x_c, adj_ret) * gw_c)
//       (summed in a local f32 vector, added once); CLOSEST: nothing. With a gradient twin
//       (v.grad != 0), w_c * adj_ret is added atomically into it at the byte offset each
//       value was read from (leaf value, tile value or root background), corner by corner;
//       in CLOSEST mode the one voxel gets adj_ret.
//   adj_volume_sample_grad(v, uvw, mode, adj_v, adj_uvw, adj_mode, adj_ret, ctx)
//       adj_ret = (adj_value, adj_grad) as a tuple_t: also the weight Hessian's term into
//       adj_uvw, and adj_grad * gw_c into the values.
//   adj_volume_lookup(v, i, j, k, adj_v, adj_i, adj_j, adj_k, adj_ret, ctx)
//       adj_ret into the twin at the voxel's value (i32 grids: nothing).
//   adj_volume_index_to_world / _dir(v, uvw, adj_v, adj_uvw, adj_ret, ctx): adj_uvw += M^T adj_ret;
//   adj_volume_world_to_index / _dir: adj_xyz += M^-T adj_ret (the f32 map copies).
//   adj_volume_sample_index / adj_volume_sample_grad_index(v, uvw, mode, data, bg, adj_v,
//       adj_uvw, adj_mode, adj_data, adj_bg, adj_ret, ctx): the position's adjoint (LINEAR),
//       and each tap's value adjoint into adj_data (the data's gradient array) at its index,
//       or into adj_bg where the voxel has none (CLOSEST: its one tap, weight 1).
//   volume_store and volume_lookup_index have no adjoint (Grad::Zero).
//
// The twin's adds go through wp_atomic.h's helpers: one atomicAdd per float component on
// the device (relaxed, device scope), a plain add on the host (single-threaded host checks).
// Concurrent adds into one location may land in any order on the GPU, so sums there are
// bit for bit the CPU's only where the order does not matter.
#pragma once
#include "wp_adjoint_core.h"
#include "wp_volume.h"

namespace wp {

namespace detail {

/// grad_add: `*p += x`, atomically per component (i32: nothing, it has no gradient).
WP_LFN void vol_grad_add(u64 p, f32 x) { atomic_add_p((f32*)p, x); }
WP_LFN void vol_grad_add(u64 p, f64 x) { atomic_add_p((f64*)p, x); }
WP_LFN void vol_grad_add(u64 p, i32 x) {
  (void)p;
  (void)x;
}
WP_LFN void vol_grad_add(u64 p, Vec3 x) {
  atomic_add_p((f32*)p, x.x);
  atomic_add_p((f32*)(p + 4), x.y);
  atomic_add_p((f32*)(p + 8), x.z);
}
WP_LFN void vol_grad_add(u64 p, DVec3 x) {
  atomic_add_p((f64*)p, x.x);
  atomic_add_p((f64*)(p + 8), x.y);
  atomic_add_p((f64*)(p + 16), x.z);
}

/// grad_add_at: into the twin of the value at `at` (nothing without a twin).
template <typename T>
WP_FN void vol_grad_add_at(const volume_t<T>& v, vol_addr_t at, const T& x) {
  if (v.grad != 0) vol_grad_add(v.grad + at.offset, x);
}

/// dot(v, a): scalar `v * a`; vector `(v.x*a.x + v.y*a.y) + v.z*a.z`.
WP_LFN f32 vol_dot(f32 v, f32 a) { return v * a; }
WP_LFN f64 vol_dot(f64 v, f64 a) { return v * a; }
WP_LFN f32 vol_dot(Vec3 v, Vec3 a) { return (v.x * a.x + v.y * a.y) + v.z * a.z; }
WP_LFN f64 vol_dot(DVec3 v, DVec3 a) { return (v.x * a.x + v.y * a.y) + v.z * a.z; }

/// vec_mul_grad: `v^T g` per axis a: scalar `v * g_a`; vector
/// `(v.x*g[x][a] + v.y*g[y][a]) + v.z*g[z][a]` (g[c][a]: column a's component c).
WP_LFN void vol_vec_mul_grad(f32 v, Vec3 g, f32* r) {
  r[0] = v * g.x;
  r[1] = v * g.y;
  r[2] = v * g.z;
}
WP_LFN void vol_vec_mul_grad(f64 v, DVec3 g, f64* r) {
  r[0] = v * g.x;
  r[1] = v * g.y;
  r[2] = v * g.z;
}
WP_LFN void vol_vec_mul_grad(Vec3 v, const Mat3& g, f32* r) {
  r[0] = vol_dot(v, g.x_axis);
  r[1] = vol_dot(v, g.y_axis);
  r[2] = vol_dot(v, g.z_axis);
}
WP_LFN void vol_vec_mul_grad(DVec3 v, const DMat3& g, f64* r) {
  r[0] = vol_dot(v, g.x_axis);
  r[1] = vol_dot(v, g.y_axis);
  r[2] = vol_dot(v, g.z_axis);
}

/// grad_mul_vec: `g gw`: scalar `(g_x*gw_x + g_y*gw_y) + g_z*gw_z`; vector, per component c,
/// `(g[c][x]*gw_x + g[c][y]*gw_y) + g[c][z]*gw_z`.
WP_LFN f32 vol_grad_mul_vec(Vec3 g, const f32* gw) {
  return (g.x * gw[0] + g.y * gw[1]) + g.z * gw[2];
}
WP_LFN f64 vol_grad_mul_vec(DVec3 g, const f64* gw) {
  return (g.x * gw[0] + g.y * gw[1]) + g.z * gw[2];
}
template <typename V, typename M, typename S>
WP_FN V vol_mat_mul_vec(const M& g, const S* gw) {
  const V a = g.x_axis, b = g.y_axis, c = g.z_axis;
  V r;
  r.x = (a.x * gw[0] + b.x * gw[1]) + c.x * gw[2];
  r.y = (a.y * gw[0] + b.y * gw[1]) + c.y * gw[2];
  r.z = (a.z * gw[0] + b.z * gw[1]) + c.z * gw[2];
  return r;
}
WP_LFN Vec3 vol_grad_mul_vec(const Mat3& g, const f32* gw) { return vol_mat_mul_vec<Vec3>(g, gw); }
WP_LFN DVec3 vol_grad_mul_vec(const DMat3& g, const f64* gw) {
  return vol_mat_mul_vec<DVec3>(g, gw);
}

/// The value adjoints of the plain builtins: into the twin.
template <typename T>
struct vol_twin_adj_t {
  const volume_t<T>* v;
  WP_FN void operator()(vol_addr_t at, const i32*, const T& a, ctx_t*) const {
    vol_grad_add_at(*v, at, a);
  }
};
/// The value adjoints of the index variants (warp-core's `index_value_adj`): into the data's
/// gradient at the voxel's index, or into the background's adjoint where it has none.
template <typename G, typename T>
struct vol_index_adj_t {
  const volume_t<G>* v;
  const array_t<T, 1>* adj_data;
  T* adj_bg;
  WP_FN void operator()(vol_addr_t at, const i32* ijk, const T& a, ctx_t* ctx) const {
    const u64 idx = vol_voxel_index(*v, at, ijk[0], ijk[1], ijk[2]);
    if (idx > 0) {
      grad_accum(*adj_data, (i64)(idx - 1u), a, ctx);
    } else {
      adj_accum(*adj_bg, a);
    }
  }
};

/// adj_linear: the position adjoint of LINEAR over the values `read` gives (a local f32 sum
/// over the corners, in order), and each corner's value adjoint handed to `value_adj`; false
/// after a fault (the sum is then not to be used).
template <bool WITH_GRAD, typename G, typename T, typename R, typename A>
WP_FN bool vol_adj_linear(const volume_t<G>& v, Vec3 uvw, const T& adj_ret,
                          const typename vol_value<T>::G* adj_grad, const R& read,
                          const A& value_adj, f32* g, ctx_t* ctx) {
  typedef typename vol_value<T>::S S;
  const vol_cell_t c = vol_cell(uvw);
  vol_acc_t acc = vol_acc_new();
  g[0] = g[1] = g[2] = 0.0f;
#if defined(__CUDACC__)
#pragma unroll
#endif
  for (int n = 0; n < 8; ++n) {
    i32 ijk[3];
    const vol_addr_t at = vol_tap(v, c, n, acc, ijk);
    const T x = read(at, ijk, ctx);
    if (faulted(ctx)) return false;
    const vol_corner_t k = vol_corner(c, n);
    const S gw[3] = {(S)k.gw[0], (S)k.gw[1], (S)k.gw[2]};
    const S d = vol_dot(x, adj_ret);
    for (int a = 0; a < 3; ++a) g[a] = g[a] + (f32)(d * gw[a]);
    T va = vol_scale((S)k.w, adj_ret);
    if constexpr (WITH_GRAD) {
      S r[3];
      vol_vec_mul_grad(x, *adj_grad, r);
      const S hxy = (S)k.h[0], hxz = (S)k.h[1], hyz = (S)k.h[2];
      const S h[3] = {r[1] * hxy + r[2] * hxz, r[0] * hxy + r[2] * hyz, r[0] * hxz + r[1] * hyz};
      for (int a = 0; a < 3; ++a) g[a] = g[a] + (f32)h[a];
      va = vol_add(va, vol_grad_mul_vec(*adj_grad, gw));
    }
    value_adj(at, ijk, va, ctx);
    if (faulted(ctx)) return false;
  }
  return true;
}

WP_LFN void vol_uvw_add(Vec3& adj_uvw, const f32* g) {
  adj_uvw.x += g[0];
  adj_uvw.y += g[1];
  adj_uvw.z += g[2];
}

}  // namespace detail

template <typename T>
WP_FN void adj_volume_sample(const volume_t<T>& v, Vec3 uvw, i32 mode, volume_t<T>& adj_v,
                             Vec3& adj_uvw, i32& adj_mode,
                             const typename identity<T>::type& adj_ret, ctx_t* ctx) {
  using namespace detail;
  (void)adj_v;
  (void)adj_mode;
  if (!vol_check_position(uvw, ctx)) return;
  if (mode == VOLUME_CLOSEST) {
    i32 ijk[3];
    vol_grad_add_at(v, vol_closest_tap(v, uvw, ijk), adj_ret);
    return;
  }
  f32 g[3];
  if (vol_adj_linear<false, T, T>(v, uvw, adj_ret, (const typename vol_value<T>::G*)nullptr,
                                  vol_grid_reader_t<T>{&v}, vol_twin_adj_t<T>{&v}, g, ctx))
    vol_uvw_add(adj_uvw, g);
}

template <typename T>
WP_FN void adj_volume_sample_grad(const volume_t<T>& v, Vec3 uvw, i32 mode, volume_t<T>& adj_v,
                                  Vec3& adj_uvw, i32& adj_mode,
                                  const tuple_t<T, typename detail::vol_value<T>::G>& adj_ret,
                                  ctx_t* ctx) {
  using namespace detail;
  (void)adj_v;
  (void)adj_mode;
  if (!vol_check_position(uvw, ctx)) return;
  if (mode == VOLUME_CLOSEST) {
    i32 ijk[3];
    vol_grad_add_at(v, vol_closest_tap(v, uvw, ijk), adj_ret.f0);
    return;
  }
  f32 g[3];
  if (vol_adj_linear<true, T, T>(v, uvw, adj_ret.f0, &adj_ret.f1, vol_grid_reader_t<T>{&v},
                                 vol_twin_adj_t<T>{&v}, g, ctx))
    vol_uvw_add(adj_uvw, g);
}

template <typename T>
WP_FN void adj_volume_lookup(const volume_t<T>& v, i32 i, i32 j, i32 k, volume_t<T>& adj_v,
                             i32& adj_i, i32& adj_j, i32& adj_k,
                             const typename identity<T>::type& adj_ret, ctx_t* ctx) {
  (void)adj_v;
  (void)adj_i;
  (void)adj_j;
  (void)adj_k;
  (void)ctx;
  if (v.grad != 0) detail::vol_grad_add_at(v, detail::vol_locate(v, i, j, k), adj_ret);
}

template <typename G>
WP_FN void adj_volume_index_to_world(const volume_t<G>& v, Vec3 uvw, volume_t<G>& adj_v,
                                     Vec3& adj_uvw, const Vec3& adj_ret, ctx_t* ctx) {
  (void)uvw;
  (void)adj_v;
  (void)ctx;
  adj_uvw += detail::vol_transposed(v.data, detail::VOL_MAT_F, adj_ret);
}
template <typename G>
WP_FN void adj_volume_world_to_index(const volume_t<G>& v, Vec3 xyz, volume_t<G>& adj_v,
                                     Vec3& adj_xyz, const Vec3& adj_ret, ctx_t* ctx) {
  (void)xyz;
  (void)adj_v;
  (void)ctx;
  adj_xyz += detail::vol_transposed(v.data, detail::VOL_INV_MAT_F, adj_ret);
}
template <typename G>
WP_FN void adj_volume_index_to_world_dir(const volume_t<G>& v, Vec3 uvw, volume_t<G>& adj_v,
                                         Vec3& adj_uvw, const Vec3& adj_ret, ctx_t* ctx) {
  adj_volume_index_to_world(v, uvw, adj_v, adj_uvw, adj_ret, ctx);
}
template <typename G>
WP_FN void adj_volume_world_to_index_dir(const volume_t<G>& v, Vec3 xyz, volume_t<G>& adj_v,
                                         Vec3& adj_xyz, const Vec3& adj_ret, ctx_t* ctx) {
  adj_volume_world_to_index(v, xyz, adj_v, adj_xyz, adj_ret, ctx);
}

template <typename G, typename T>
WP_FN void adj_volume_sample_index(const volume_t<G>& v, Vec3 uvw, i32 mode,
                                   const array_t<T, 1>& data, const typename identity<T>::type& bg,
                                   volume_t<G>& adj_v, Vec3& adj_uvw, i32& adj_mode,
                                   array_t<T, 1>& adj_data, T& adj_bg,
                                   const typename identity<T>::type& adj_ret, ctx_t* ctx) {
  using namespace detail;
  (void)adj_v;
  (void)adj_mode;
  if (!vol_check_position(uvw, ctx)) return;
  const vol_index_adj_t<G, T> value_adj{&v, &adj_data, &adj_bg};
  if (mode == VOLUME_CLOSEST) {
    i32 ijk[3];
    const vol_addr_t at = vol_closest_tap(v, uvw, ijk);
    value_adj(at, ijk, adj_ret, ctx);
    return;
  }
  f32 g[3];
  if (vol_adj_linear<false, G, T>(v, uvw, adj_ret, (const typename vol_value<T>::G*)nullptr,
                                  vol_index_reader_t<G, T>{&v, &data, &bg}, value_adj, g, ctx))
    vol_uvw_add(adj_uvw, g);
}

template <typename G, typename T>
WP_FN void adj_volume_sample_grad_index(
    const volume_t<G>& v, Vec3 uvw, i32 mode, const array_t<T, 1>& data,
    const typename identity<T>::type& bg, volume_t<G>& adj_v, Vec3& adj_uvw, i32& adj_mode,
    array_t<T, 1>& adj_data, T& adj_bg,
    const tuple_t<T, typename detail::vol_value<T>::G>& adj_ret, ctx_t* ctx) {
  using namespace detail;
  (void)adj_v;
  (void)adj_mode;
  if (!vol_check_position(uvw, ctx)) return;
  const vol_index_adj_t<G, T> value_adj{&v, &adj_data, &adj_bg};
  if (mode == VOLUME_CLOSEST) {
    i32 ijk[3];
    const vol_addr_t at = vol_closest_tap(v, uvw, ijk);
    value_adj(at, ijk, adj_ret.f0, ctx);
    return;
  }
  f32 g[3];
  if (vol_adj_linear<true, G, T>(v, uvw, adj_ret.f0, &adj_ret.f1,
                                 vol_index_reader_t<G, T>{&v, &data, &bg}, value_adj, g, ctx))
    vol_uvw_add(adj_uvw, g);
}

}  // namespace wp

// wp_adjoint_rand.h: adjoints of the "rand" section (Perlin noise; the draws have none).
// Part of the CUDA adjoint library; see wp_adjoint.h for its conventions. An adjoint
// translation unit includes wp_adjoint_core.h and the adjoint headers of the builtin-table
// sections its kernel uses (warp_cuda::ADJOINT_SECTIONS), so NVRTC parses no more than it
// needs.
#pragma once
#include "wp_adjoint_core.h"
#include "wp_rand.h"

namespace wp {

// ------------------------------------------------------------------------------------------
// Perlin noise (warp-core: adjoint/noise.rs): adj_x[k] += grad[k] * adj_ret, with the
// gradient of wp_rand.h's `perlin` and unfused operations (so bit for bit with the CPU); the
// state and the periods are integers and get nothing.
// ------------------------------------------------------------------------------------------

namespace detail {
WP_LFN void adj_noise_accum(f32& adj_x, const f32* g, f32 adj_ret) {
  adj_x = rn_add(adj_x, rn_mul(g[0], adj_ret));
}
template <typename V>
WP_FN void adj_noise_accum(V& adj_x, const f32* g, f32 adj_ret) {
  for (int k = 0; k < vec_traits<V>::N; ++k) {
    vec_traits<V>::at(adj_x, k) = rn_add(vec_traits<V>::get(adj_x, k), rn_mul(g[k], adj_ret));
  }
}
}  // namespace detail

#define WP_ADJ_NOISE(V, P)                                                                  \
  WP_LFN void adj_noise(u32 state, V x, u32& adj_state, V& adj_x, f32 adj_ret) {             \
    (void)adj_state;                                                                        \
    f32 l[4], g[4];                                                                         \
    detail::noise_lanes(x, l);                                                              \
    detail::perlin(state, l, nullptr, detail::noise_dim<V>::N, g);                          \
    detail::adj_noise_accum(adj_x, g, adj_ret);                                             \
  }                                                                                         \
  WP_LFN void adj_pnoise(u32 state, V x, P period, u32& adj_state, V& adj_x, P& adj_period, \
                        f32 adj_ret) {                                                      \
    (void)adj_state;                                                                        \
    (void)adj_period;                                                                       \
    f32 l[4], g[4];                                                                         \
    i32 p[4];                                                                               \
    detail::noise_lanes(x, l);                                                              \
    detail::noise_periods(period, p);                                                       \
    detail::perlin(state, l, p, detail::noise_dim<V>::N, g);                                \
    detail::adj_noise_accum(adj_x, g, adj_ret);                                             \
  }
WP_ADJ_NOISE(f32, i32)
WP_ADJ_NOISE(Vec2, IVec2)
WP_ADJ_NOISE(Vec3, IVec3)
WP_ADJ_NOISE(Vec4, IVec4)
#undef WP_ADJ_NOISE

}  // namespace wp

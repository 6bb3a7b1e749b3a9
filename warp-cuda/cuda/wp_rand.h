// wp_rand.h: section "rand" of the builtin table: NVIDIA Warp's random number generator and
// Perlin noise, the CUDA mirror of warp-core/src/builtins/{rand,noise}.rs (read those for the
// definitions; this file repeats each operation in the same order).
//
//   rand_pcg(s)                     the PCG hash (one generator step)
//   rand_init(seed), rand_init_offset(seed, offset)       i32 -> u32 state
//   randf(s), randf_range(s, lo, hi), randn(s)           the draw from the state BEFORE it
//   sample_triangle, sample_unit_ring, sample_unit_disk, sample_unit_square  (u32) -> Vec2
//   sample_unit_cube, sample_unit_sphere(_surface), sample_unit_hemisphere(_surface)  -> Vec3
//   poisson(s, lam), poisson_state(s, lam)               the count, and the state after it
//   noise(s, x), pnoise(s, x, period)                     x: f32, Vec2, Vec3, Vec4 (f32 only)
//
// Kernels never mutate a state through these functions: the macro lowers
// `randf(&mut state)` into `r = wp::randf(state); state = wp::rand_pcg(state);` (one step
// per uniform draw; `poisson` writes back `poisson_state`).
//
// Bit for bit with the CPU: integer results and uniform floats are exact; `randf_range`, the
// noise and its adjoint are spelled with `__fmul_rn`/`__fadd_rn`/`__fsub_rn` (never
// contracted into an FMA, whatever `--fmad` says) and CUDA's correctly rounded `sqrtf` and
// `/`, so they match too. The draws that call logf, cosf, sinf, acosf or powf (randn, ring,
// disk, sphere and hemisphere samplers) and poisson (logf, expf) use CUDA's math library,
// within its documented 1 to 4 ulp of glibc's; on the host they are glibc's, as on the CPU.
#pragma once
#include "wp_core.h"

namespace wp {

namespace detail {
// IEEE operations that the compiler may not fuse.
#if defined(__CUDA_ARCH__)
WP_LFN f32 rn_mul(f32 a, f32 b) { return __fmul_rn(a, b); }
WP_LFN f32 rn_add(f32 a, f32 b) { return __fadd_rn(a, b); }
WP_LFN f32 rn_sub(f32 a, f32 b) { return __fsub_rn(a, b); }
#else
WP_LFN f32 rn_mul(f32 a, f32 b) { return a * b; }
WP_LFN f32 rn_add(f32 a, f32 b) { return a + b; }
WP_LFN f32 rn_sub(f32 a, f32 b) { return a - b; }
#endif
}  // namespace detail

// ------------------------------------------------------------------------------------------
// The generator
// ------------------------------------------------------------------------------------------

WP_LFN u32 rand_pcg(u32 state) {
  u32 b = state * 747796405u + 2891336453u;
  u32 c = ((b >> ((b >> 28u) + 4u)) ^ b) * 277803737u;
  return (c >> 22u) ^ c;
}

WP_LFN u32 rand_init(i32 seed) { return rand_pcg((u32)seed); }
WP_LFN u32 rand_init_offset(i32 seed, i32 offset) { return rand_pcg((u32)seed + rand_pcg((u32)offset)); }

namespace detail {
/// The uniform float of an advanced state: top 24 bits times 2^-24 (exact).
WP_LFN f32 rand_unit(u32 s) { return (f32)(s >> 8) * (1.0f / 16777216.0f); }

/// Successive uniform draws (warp-core's `Draws`).
struct draws_t {
  u32 s;
  WP_FN f32 f() {
    s = rand_pcg(s);
    return rand_unit(s);
  }
  WP_FN f32 range(f32 lo, f32 hi) { return rn_add(rn_mul(hi - lo, f()), lo); }
};

constexpr f32 RAND_TWO_PI = 6.28318548202514648438f;  // 2 * (f32)pi, exact
constexpr f32 RANDN_EPSILON = 5.96e-8f;
}  // namespace detail

WP_LFN f32 randf(u32 state) {
  detail::draws_t d{state};
  return d.f();
}

WP_LFN f32 randf_range(u32 state, f32 lo, f32 hi) {
  detail::draws_t d{state};
  return d.range(lo, hi);
}

WP_LFN f32 randn(u32 state) {
  detail::draws_t d{state};
  f32 r = d.f();
  f32 t = d.f();
  return ::sqrtf(-2.0f * ::logf(r + detail::RANDN_EPSILON)) * ::cosf(detail::RAND_TWO_PI * t);
}

WP_LFN Vec2 sample_triangle(u32 state) {
  detail::draws_t d{state};
  f32 r = ::sqrtf(d.f());
  f32 u = 1.0f - r;
  f32 v = d.f() * r;
  return Vec2_new(u, v);
}

WP_LFN Vec2 sample_unit_ring(u32 state) {
  detail::draws_t d{state};
  f32 theta = d.range(0.0f, detail::RAND_TWO_PI);
  return Vec2_new(::cosf(theta), ::sinf(theta));
}

WP_LFN Vec2 sample_unit_disk(u32 state) {
  detail::draws_t d{state};
  f32 r = ::sqrtf(d.f());
  f32 theta = d.range(0.0f, detail::RAND_TWO_PI);
  return Vec2_new(r * ::cosf(theta), r * ::sinf(theta));
}

WP_LFN Vec2 sample_unit_square(u32 state) {
  detail::draws_t d{state};
  f32 x = d.f() - 0.5f;
  f32 y = d.f() - 0.5f;
  return Vec2_new(x, y);
}

WP_LFN Vec3 sample_unit_cube(u32 state) {
  detail::draws_t d{state};
  f32 x = d.f() - 0.5f;
  f32 y = d.f() - 0.5f;
  f32 z = d.f() - 0.5f;
  return Vec3_new(x, y, z);
}

namespace detail {
/// (r cos t sin p, r sin t sin p, r cos p), products left to right; r < 0: no radius.
WP_LFN Vec3 spherical(f32 r, bool has_r, f32 phi, f32 theta) {
  f32 ct = ::cosf(theta), st = ::sinf(theta), sp = ::sinf(phi), cp = ::cosf(phi);
  if (!has_r) return Vec3_new(ct * sp, st * sp, cp);
  return Vec3_new(r * ct * sp, r * st * sp, r * cp);
}
}  // namespace detail

WP_LFN Vec3 sample_unit_sphere_surface(u32 state) {
  detail::draws_t d{state};
  f32 phi = ::acosf(1.0f - 2.0f * d.f());
  f32 theta = d.range(0.0f, detail::RAND_TWO_PI);
  return detail::spherical(0.0f, false, phi, theta);
}

WP_LFN Vec3 sample_unit_sphere(u32 state) {
  detail::draws_t d{state};
  f32 phi = ::acosf(1.0f - 2.0f * d.f());
  f32 theta = d.range(0.0f, detail::RAND_TWO_PI);
  f32 r = ::powf(d.f(), 1.0f / 3.0f);
  return detail::spherical(r, true, phi, theta);
}

WP_LFN Vec3 sample_unit_hemisphere_surface(u32 state) {
  detail::draws_t d{state};
  f32 phi = ::acosf(1.0f - d.f());
  f32 theta = d.range(0.0f, detail::RAND_TWO_PI);
  return detail::spherical(0.0f, false, phi, theta);
}

WP_LFN Vec3 sample_unit_hemisphere(u32 state) {
  detail::draws_t d{state};
  f32 phi = ::acosf(1.0f - d.f());
  f32 theta = d.range(0.0f, detail::RAND_TWO_PI);
  f32 r = ::powf(d.f(), 1.0f / 3.0f);
  return detail::spherical(r, true, phi, theta);
}

// ------------------------------------------------------------------------------------------
// Poisson (warp-core: rand.rs, `poisson_draw`)
// ------------------------------------------------------------------------------------------

constexpr u32 POISSON_MAX_DRAWS = 1024;

namespace detail {
WP_LFN f32 rand_loggam(f32 x) {
  const f32 a[10] = {8.333333333333333e-02f, -2.777777777777778e-03f, 7.936507936507937e-04f,
                     -5.952380952380952e-04f, 8.417508417508418e-04f, -1.917526917526918e-03f,
                     6.410256410256410e-03f,  -2.955065359477124e-02f, 1.796443723688307e-01f,
                     -1.39243221690590e+00f};
  if (x == 1.0f || x == 2.0f) return 0.0f;
  u32 n = x < 7.0f ? cast<u32>(7.0f - x) : 0u;
  f32 x0 = x + (f32)n;
  f32 x2 = (1.0f / x0) * (1.0f / x0);
  f32 lg2pi = 1.8378770664093453f;
  f32 gl0 = a[9];
  for (int k = 8; k >= 0; --k) {
    gl0 *= x2;
    gl0 += a[k];
  }
  f32 gl = gl0 / x0 + 0.5f * lg2pi + (x0 - 0.5f) * ::logf(x0) - x0;
  if (x < 7.0f) {
    for (u32 k = 0; k < n; ++k) {
      gl -= ::logf(x0 - 1.0f);
      x0 -= 1.0f;
    }
  }
  return gl;
}

/// One Poisson draw: the count, and the state after it in `*after`.
WP_LFN u32 poisson_draw(u32 state, f32 lam, u32* after) {
  draws_t d{state};
  if (lam >= 10.0f) {
    f32 slam = ::sqrtf(lam);
    f32 loglam = ::logf(lam);
    f32 b = 0.931f + 2.53f * slam;
    f32 a = -0.059f + 0.02483f * b;
    f32 invalpha = 1.1239f + 1.1328f / (b - 3.4f);
    f32 vr = 0.9277f - 3.6224f / (b - 2.0f);
    u32 k = 0;
    u32 draws = 0;
    while (draws < POISSON_MAX_DRAWS) {
      draws += 2;
      f32 u = d.f() - 0.5f;
      f32 v = d.f();
      f32 us = 0.5f - ::fabsf(u);
      f32 kf = ::floorf((2.0f * a / us + b) * u + lam + 0.43f);
      k = cast<u32>(kf);
      if (us >= 0.07f && v <= vr) {
        *after = d.s;
        return k;
      }
      if (kf < 0.0f || (us < 0.013f && v > us)) continue;
      f32 lhs = ::logf(v) + ::logf(invalpha) - ::logf(a / (us * us) + b);
      f32 rhs = -lam + (f32)k * loglam - rand_loggam((f32)k + 1.0f);
      if (lhs <= rhs) {
        *after = d.s;
        return k;
      }
    }
    *after = d.s;
    return k;
  } else if (lam == 0.0f) {
    *after = state;
    return 0;
  } else {
    f32 enlam = ::expf(-lam);
    u32 x = 0;
    f32 prod = 1.0f;
    for (u32 i = 0; i < POISSON_MAX_DRAWS; ++i) {
      prod *= d.f();
      if (prod > enlam) {
        x += 1;
      } else {
        break;
      }
    }
    *after = d.s;
    return x;
  }
}
}  // namespace detail

WP_LFN u32 poisson(u32 state, f32 lam) {
  u32 after;
  return detail::poisson_draw(state, lam, &after);
}

WP_LFN u32 poisson_state(u32 state, f32 lam) {
  u32 after;
  detail::poisson_draw(state, lam, &after);
  return after;
}

// ------------------------------------------------------------------------------------------
// Perlin noise (warp-core: noise.rs)
// ------------------------------------------------------------------------------------------

namespace detail {
WP_LFN f32 noise_fade(f32 t) {
  return rn_mul(rn_mul(rn_mul(t, t), t), rn_add(rn_mul(t, rn_sub(rn_mul(t, 6.0f), 15.0f)), 10.0f));
}
WP_LFN f32 noise_fade_d(f32 t) {
  return rn_mul(rn_mul(rn_mul(30.0f, t), t), rn_add(rn_mul(t, rn_sub(t, 2.0f)), 1.0f));
}
WP_LFN f32 noise_blend(f32 a, f32 b, f32 t) { return rn_add(rn_mul(rn_sub(b, a), noise_fade(t)), a); }

WP_LFN u32 noise_corner_seed(u32 state, const i32* idx, int n) {
  const u32 primes[4] = {73856093u, 19349663u, 53471161u, 10000019u};
  u32 h = 0;
  for (int k = 0; k < n - 1; ++k) h ^= (u32)idx[k] * primes[k];
  return h ^ ((u32)idx[n - 1] * primes[n - 1] + state);
}

WP_LFN void noise_corner_gradient(u32 seed, int n, f32* g) {
  draws_t d{seed};
  for (int k = 0; k < 4; ++k) g[k] = 0.0f;
  if (n == 1) {
    g[0] = rn_add(rn_mul(2.0f, d.f()), -1.0f);
    return;
  }
  for (int k = 0; k < n; ++k) g[k] = d.f() - 0.5f;
  f32 sq = rn_mul(g[0], g[0]);
  for (int k = 1; k < n; ++k) sq = rn_add(sq, rn_mul(g[k], g[k]));
  f32 len = ::sqrtf(sq);
  for (int k = 0; k < n; ++k) g[k] = len > 0.0f ? g[k] / len : 0.0f;
}

WP_LFN i32 noise_wrap(i32 i, i32 p) {
  if (p == 0) return i;
  i64 m = p < 0 ? -(i64)p : (i64)p;
  i64 r = (i64)i % m;
  if (r < 0) r += m;
  return (i32)r;
}

/// The noise's value, and its gradient into `grad` when `grad` is not null.
WP_LFN f32 perlin(u32 state, const f32* x, const i32* period, int n, f32* grad) {
  i32 lo[4], hi[4];
  f32 d[4];
  for (int k = 0; k < n; ++k) {
    f32 f = ::floorf(x[k]);
    d[k] = rn_sub(x[k], f);
    i32 i = cast<i32>(f);
    if (period != nullptr) {
      lo[k] = noise_wrap(i, period[k]);
      hi[k] = noise_wrap(w_add(lo[k], 1), period[k]);
    } else {
      lo[k] = i;
      hi[k] = w_add(i, 1);
    }
  }
  f32 val[16];
  f32 g[16][4];
  for (int c = 0; c < (1 << n); ++c) {
    i32 idx[4];
    f32 off[4];
    for (int k = 0; k < n; ++k) {
      bool up = ((c >> k) & 1) == 1;
      idx[k] = up ? hi[k] : lo[k];
      off[k] = up ? rn_sub(d[k], 1.0f) : d[k];
    }
    noise_corner_gradient(noise_corner_seed(state, idx, n), n, g[c]);
    f32 v = rn_mul(off[0], g[c][0]);
    for (int k = 1; k < n; ++k) v = rn_add(v, rn_mul(off[k], g[c][k]));
    val[c] = v;
  }
  for (int k = 0; k < n; ++k) {
    f32 t = d[k];
    f32 s = noise_fade(t);
    f32 s1 = grad != nullptr ? noise_fade_d(t) : 0.0f;
    for (int m = 0; m < (1 << (n - k - 1)); ++m) {
      f32 a = val[2 * m], b = val[2 * m + 1];
      if (grad != nullptr) {
        f32 dv = rn_mul(rn_sub(b, a), s1);
        f32 r[4];
        for (int j = 0; j < n; ++j) {
          f32 e = j == k ? 1.0f : 0.0f;
          r[j] = rn_add(rn_add(rn_mul(rn_sub(g[2 * m + 1][j], g[2 * m][j]), s), rn_mul(dv, e)),
                        g[2 * m][j]);
        }
        for (int j = 0; j < n; ++j) g[m][j] = r[j];
      }
      val[m] = noise_blend(a, b, t);
    }
  }
  if (grad != nullptr) {
    for (int j = 0; j < 4; ++j) grad[j] = j < n ? g[0][j] : 0.0f;
  }
  return val[0];
}

template <typename V>
WP_FN void noise_lanes(const V& v, f32* x) {
  for (int k = 0; k < vec_traits<V>::N; ++k) x[k] = vec_traits<V>::get(v, k);
}
WP_LFN void noise_lanes(f32 v, f32* x) { x[0] = v; }
template <typename P>
WP_FN void noise_periods(const P& p, i32* x) {
  for (int k = 0; k < vec_traits<P>::N; ++k) x[k] = vec_traits<P>::get(p, k);
}
WP_LFN void noise_periods(i32 p, i32* x) { x[0] = p; }
template <typename V>
struct noise_dim {
  static constexpr int N = vec_traits<V>::N;
};
template <>
struct noise_dim<f32> {
  static constexpr int N = 1;
};
}  // namespace detail

#define WP_NOISE(V, P)                                                  \
  WP_LFN f32 noise(u32 state, V x) {                                     \
    f32 l[4];                                                           \
    detail::noise_lanes(x, l);                                          \
    return detail::perlin(state, l, nullptr, detail::noise_dim<V>::N, nullptr); \
  }                                                                     \
  WP_LFN f32 pnoise(u32 state, V x, P period) {                          \
    f32 l[4];                                                           \
    i32 p[4];                                                           \
    detail::noise_lanes(x, l);                                          \
    detail::noise_periods(period, p);                                   \
    return detail::perlin(state, l, p, detail::noise_dim<V>::N, nullptr); \
  }
WP_NOISE(f32, i32)
WP_NOISE(Vec2, IVec2)
WP_NOISE(Vec3, IVec3)
WP_NOISE(Vec4, IVec4)
#undef WP_NOISE

}  // namespace wp

//! Perlin gradient noise (CPU side of the table's "rand" section): `noise` and `pnoise` in 1
//! to 4 dimensions, NVIDIA Warp's definitions, f32 only (as in Warp).
//!
//! `noise(state, x)` for `x` an `f32`, `Vec2`, `Vec3` or `Vec4`: the lattice cell of `x` is
//! `floor(x)` (converted with Rust's saturating `as i32`), `d = x - floor(x)` its offset in the
//! cell. Each of the `2^n` corners `c` gets a gradient `g_c` from the generator, seeded by a
//! hash of the corner's integer coordinates and `state` (Warp's primes 73856093, 19349663,
//! 53471161, 10000019: `i_0 p_0 ^ i_1 p_1 ^ .. ^ (i_{n-1} p_{n-1} + state)`, wrapping u32);
//! in 1-D a uniform draw in `[-1, 1)`, else the normalized `sample_unit_square/cube/hypercube`
//! draw. The corner values `dot(d - c, g_c)` are blended along x, then y, z, t with Perlin's
//! quintic `S(t) = t³(t(6t - 15) + 10)`: `blend(a, b, t) = (b - a) S(t) + a`. So the noise is 0
//! at every lattice point, continuous with continuous first derivatives, and in about
//! `[-1, 1]`.
//!
//! `pnoise(state, x, px, ..)`: the same with corner coordinates taken modulo the periods, so
//! that `pnoise(x + k p) == pnoise(x)` exactly for integer `k` (where `x + k p` is exact). The
//! remainder is Euclidean (in `[0, |p|)`); Warp's C `%` gives negative corners for negative
//! `x`, so its `pnoise` is periodic only on `x >= 0`, where both agree. A period of 0 leaves
//! its axis unwrapped (Warp: division by zero).
//!
//! Arithmetic: every operation is one IEEE f32 rounding, in the order written here, and the
//! CUDA library (`wp_rand.h`) does the same operations in the same order with
//! `__fmul_rn`/`__fadd_rn`/`__fsub_rn`, which NVRTC never contracts, and the correctly rounded
//! `sqrt` and `/` of non-fast-math CUDA: the backends agree bit for bit, with or without FMA
//! contraction.

// Lanes are indexed by axis throughout, as the definitions are written.
#![allow(clippy::needless_range_loop)]

use glam::{IVec2, IVec3, IVec4, Vec2, Vec3, Vec4};

use super::rand::rand_pcg;

/// Warp's primes for hashing lattice coordinates, one per axis.
pub(crate) const PRIMES: [u32; 4] = [73_856_093, 19_349_663, 53_471_161, 10_000_019];

/// The noise's argument types: `f32`, `Vec2`, `Vec3`, `Vec4`, with their period types (`i32`,
/// `IVec2`, `IVec3`, `IVec4`).
pub trait NoiseArg: Copy {
    /// One integer period per lane.
    type Period: Copy;
    /// The number of lanes (dimensions).
    const N: usize;
    /// The lanes, padded with zeros.
    fn lanes(self) -> [f32; 4];
    /// The periods, padded with zeros.
    fn periods(p: Self::Period) -> [i32; 4];
    /// `self[k] += g[k] * adj_ret` for each lane.
    fn accum_scaled(&mut self, g: [f32; 4], adj_ret: f32);
}

impl NoiseArg for f32 {
    type Period = i32;
    const N: usize = 1;
    #[inline(always)]
    fn lanes(self) -> [f32; 4] {
        [self, 0.0, 0.0, 0.0]
    }
    #[inline(always)]
    fn periods(p: i32) -> [i32; 4] {
        [p, 0, 0, 0]
    }
    #[inline(always)]
    fn accum_scaled(&mut self, g: [f32; 4], adj_ret: f32) {
        *self += g[0] * adj_ret;
    }
}

macro_rules! noise_vec {
    ($v:ty, $p:ty, $n:literal, [$($l:ident),*]) => {
        impl NoiseArg for $v {
            type Period = $p;
            const N: usize = $n;
            #[inline(always)]
            fn lanes(self) -> [f32; 4] {
                let mut a = [0.0; 4];
                a[..$n].copy_from_slice(&self.to_array());
                a
            }
            #[inline(always)]
            fn periods(p: $p) -> [i32; 4] {
                let mut a = [0; 4];
                a[..$n].copy_from_slice(&p.to_array());
                a
            }
            #[inline(always)]
            fn accum_scaled(&mut self, g: [f32; 4], adj_ret: f32) {
                let mut k = 0;
                $(
                    self.$l += g[k] * adj_ret;
                    k += 1;
                )*
                let _ = k;
            }
        }
    };
}
noise_vec!(Vec2, IVec2, 2, [x, y]);
noise_vec!(Vec3, IVec3, 3, [x, y, z]);
noise_vec!(Vec4, IVec4, 4, [x, y, z, w]);

/// Perlin's quintic fade `t³(t(6t - 15) + 10)`, as `((t t) t) ((t ((t 6) - 15)) + 10)`.
#[inline(always)]
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// The fade's derivative `30 t² (t (t - 2) + 1)`, as `((30 t) t) ((t (t - 2)) + 1)`.
#[inline(always)]
fn fade_d(t: f32) -> f32 {
    30.0 * t * t * (t * (t - 2.0) + 1.0)
}

/// `(b - a) S(t) + a`.
#[inline(always)]
fn blend(a: f32, b: f32, t: f32) -> f32 {
    (b - a) * fade(t) + a
}

/// A corner's gradient seed: the XOR of `i_k p_k` over the axes, the last one plus `state`.
#[inline(always)]
fn corner_seed(state: u32, idx: &[i32; 4], n: usize) -> u32 {
    let mut h = 0u32;
    for k in 0..n - 1 {
        h ^= (idx[k] as u32).wrapping_mul(PRIMES[k]);
    }
    h ^ (idx[n - 1] as u32)
        .wrapping_mul(PRIMES[n - 1])
        .wrapping_add(state)
}

/// A corner's gradient: in 1-D `2 u - 1` (Warp's `randf(seed, -1, 1)`); else the draws
/// `u_k - 0.5` divided by their length (`sqrt` of the left-to-right sum of squares), or zero
/// when that length is 0 (Warp's `normalize`).
#[inline(always)]
fn corner_gradient(seed: u32, n: usize) -> [f32; 4] {
    let mut s = seed;
    let mut g = [0.0f32; 4];
    let mut draw = || {
        s = rand_pcg(s);
        (s >> 8) as f32 * (1.0 / 16_777_216.0)
    };
    if n == 1 {
        g[0] = 2.0 * draw() + -1.0;
        return g;
    }
    for gk in g.iter_mut().take(n) {
        *gk = draw() - 0.5;
    }
    let mut sq = g[0] * g[0];
    for gk in g.iter().take(n).skip(1) {
        sq += gk * gk;
    }
    let len = sq.sqrt();
    for gk in g.iter_mut().take(n) {
        *gk = if len > 0.0 { *gk / len } else { 0.0 };
    }
    g
}

/// The cell of `x`: lower and upper corner coordinates (wrapped by the periods when given) and
/// the offsets `x - floor(x)`.
#[inline(always)]
fn cell(x: [f32; 4], period: Option<[i32; 4]>, n: usize) -> ([i32; 4], [i32; 4], [f32; 4]) {
    let wrap = |i: i32, p: i32| -> i32 {
        if p == 0 {
            i
        } else {
            (i as i64).rem_euclid((p as i64).abs()) as i32
        }
    };
    let (mut lo, mut hi, mut d) = ([0i32; 4], [0i32; 4], [0.0f32; 4]);
    for k in 0..n {
        let f = x[k].floor();
        d[k] = x[k] - f;
        let i = f as i32;
        match period {
            Some(p) => {
                lo[k] = wrap(i, p[k]);
                hi[k] = wrap(lo[k].wrapping_add(1), p[k]);
            }
            None => {
                lo[k] = i;
                hi[k] = i.wrapping_add(1);
            }
        }
    }
    (lo, hi, d)
}

/// A corner's value `dot(d - c, g)` and gradient `g`, for corner bits `c` (bit k: axis k).
#[inline(always)]
fn corner(
    state: u32,
    c: usize,
    lo: &[i32; 4],
    hi: &[i32; 4],
    d: &[f32; 4],
    n: usize,
) -> (f32, [f32; 4]) {
    let mut idx = [0i32; 4];
    let mut off = [0.0f32; 4];
    for k in 0..n {
        let up = (c >> k) & 1 == 1;
        idx[k] = if up { hi[k] } else { lo[k] };
        off[k] = if up { d[k] - 1.0 } else { d[k] };
    }
    let g = corner_gradient(corner_seed(state, &idx, n), n);
    let mut v = off[0] * g[0];
    for k in 1..n {
        v += off[k] * g[k];
    }
    (v, g)
}

/// The noise's value and its gradient with respect to `x` (lanes beyond `n` are zero).
///
/// Corner values are blended pairwise along axis 0, then 1, ...; the gradient of one blend
/// `F = (B - A) S(t) + A` along axis `k` is, lane by lane,
/// `((∇B_j - ∇A_j) S(t) + ((B - A) S'(t)) e_kj) + ∇A_j` (Warp's `interpolate_gradient`).
#[inline(always)]
pub(crate) fn perlin(
    state: u32,
    x: [f32; 4],
    period: Option<[i32; 4]>,
    n: usize,
    want_grad: bool,
) -> (f32, [f32; 4]) {
    let (lo, hi, d) = cell(x, period, n);
    let mut val = [0.0f32; 16];
    let mut grad = [[0.0f32; 4]; 16];
    for c in 0..(1usize << n) {
        let (v, g) = corner(state, c, &lo, &hi, &d, n);
        val[c] = v;
        grad[c] = g;
    }
    for k in 0..n {
        let (t, s) = (d[k], fade(d[k]));
        let s1 = if want_grad { fade_d(d[k]) } else { 0.0 };
        for m in 0..(1usize << (n - k - 1)) {
            let (a, b) = (val[2 * m], val[2 * m + 1]);
            if want_grad {
                let (ga, gb) = (grad[2 * m], grad[2 * m + 1]);
                let dv = (b - a) * s1;
                let mut g = [0.0f32; 4];
                for j in 0..n {
                    let e = if j == k { 1.0 } else { 0.0 };
                    g[j] = (gb[j] - ga[j]) * s + dv * e + ga[j];
                }
                grad[m] = g;
            }
            val[m] = blend(a, b, t);
        }
    }
    (val[0], grad[0])
}

/// `noise(state, x)`: Perlin noise of `x: f32, Vec2, Vec3, Vec4` seeded by `state` (see the
/// module documentation).
#[inline(always)]
pub fn noise<T: NoiseArg>(state: u32, x: T) -> f32 {
    perlin(state, x.lanes(), None, T::N, false).0
}

/// `pnoise(state, x, px, ..)`: periodic Perlin noise, one integer period per lane (written
/// `pnoise(state, xy, px, py)` in a kernel; the macro packs the periods into an `IVec2`).
#[inline(always)]
pub fn pnoise<T: NoiseArg>(state: u32, x: T, period: T::Period) -> f32 {
    perlin(state, x.lanes(), Some(T::periods(period)), T::N, false).0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_on_the_lattice_and_continuous() {
        for s in [0u32, 7, 123_456] {
            for i in -3..4 {
                assert_eq!(noise(s, i as f32), 0.0);
                assert_eq!(noise(s, Vec2::new(i as f32, 2.0)), 0.0);
                assert_eq!(noise(s, Vec3::new(1.0, i as f32, -5.0)), 0.0);
                assert_eq!(noise(s, Vec4::new(1.0, 0.0, i as f32, 3.0)), 0.0);
            }
        }
        // Across a cell boundary the value moves by O(h).
        let s = 99;
        for x in [0.999_9f32, 1.0, 2.5, -0.000_1] {
            let h = 1e-3;
            let a = noise(s, Vec3::new(x, 0.3, 0.7));
            let b = noise(s, Vec3::new(x + h, 0.3, 0.7));
            assert!((a - b).abs() < 10.0 * h, "{x}: {a} {b}");
        }
    }

    #[test]
    fn gradient_matches_differences() {
        let s = 5;
        for p in [
            [0.3f32, 0.6, 0.2, 0.8],
            [-1.7, 2.25, 0.1, 5.5],
            [10.4, -3.3, 7.9, -0.6],
        ] {
            for n in 1..=4 {
                let (_, g) = perlin(s, p, None, n, true);
                for k in 0..n {
                    let h = 1e-2f32;
                    let (mut a, mut b) = (p, p);
                    a[k] -= h;
                    b[k] += h;
                    let fd = (perlin(s, b, None, n, false).0 - perlin(s, a, None, n, false).0)
                        / (2.0 * h);
                    assert!((fd - g[k]).abs() < 2e-2, "n {n} lane {k}: {fd} vs {}", g[k]);
                }
            }
        }
    }

    #[test]
    fn periods_wrap_on_both_sides_of_zero() {
        let s = 17;
        for x in [-7.25f32, -0.375, 0.25, 3.625] {
            assert_eq!(pnoise(s, x, 4), pnoise(s, x + 8.0, 4));
            let v = Vec2::new(x, 0.5 * x);
            assert_eq!(
                pnoise(s, v, IVec2::new(2, 3)),
                pnoise(s, v + Vec2::new(4.0, -6.0), IVec2::new(2, 3))
            );
            // A zero period leaves its axis unwrapped; negative ones count as their size.
            assert_eq!(pnoise(s, x, 0), noise(s, x));
            assert_eq!(pnoise(s, x, -4), pnoise(s, x, 4));
        }
        // Non-negative coordinates below one period are the plain noise's cells.
        assert_eq!(pnoise(s, 1.25f32, 1000), noise(s, 1.25f32));
    }
}

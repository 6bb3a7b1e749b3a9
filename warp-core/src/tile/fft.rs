//! Fast Fourier transforms of tiles: `tile_fft` and `tile_ifft` (Warp's names and semantics).
//!
//! A tile of complex values is a `Tile2<Vec2, M, N>` (or `DVec2`: `x` the real part, `y` the
//! imaginary part, Warp's `vec2f`/`vec2d`); each of its `M` rows is transformed along the last
//! axis, in place, and `N` must be a power of two. The forward transform is numpy's
//! `fft(x)[k] = sum_j x[j] e^(-2 pi i jk / N)`; the inverse uses `e^(+2 pi i jk / N)` and is
//! **unnormalised**, as Warp's (cuFFTDx's): `ifft(fft(x)) = N x`.
//!
//! **The operation order** is part of the contract: the CUDA library (wp_tile_fft.h) runs the
//! same roundings in the same order, spread over the block's threads, so the two back ends give
//! the same bits (tests/cuda_tile_fft_host.rs holds them together). Every step is a separate
//! IEEE add, subtract, multiply, divide or square root (no fused multiply-add: Rust never
//! contracts, and the section compiles with `--fmad=false`); no `sin`/`cos` is called, since
//! the two libraries' are not the same function.
//!
//! - **Twiddles** ([`twiddles`]): `w[k] = e^(+2 pi i k / N)` for `k < N/2`, computed in f64 and
//!   then rounded to the element's scalar once. The angles `2 pi / 2^j` have cosines and sines
//!   from the half-angle formulas: `(c, s) = (-1, 0)` for `j = 1`, `(0, 1)` for `j = 2`, and
//!   then `c' = sqrt((1 + c) * 0.5)`, `s' = s / (c' + c')`. `w[k]` is the product, starting from
//!   `(1, 0)`, of the factors `e^(i 2 pi / 2^(L - b))` of the set bits `b` of `k`, `b`
//!   ascending (`L = log2 N`): about `2 log2 N` roundings of f64, far below an f32's last bit and
//!   a few of an f64's.
//! - **The transform**: an iterative radix-2 Cooley-Tukey on each row: the bit-reversal
//!   permutation, then for `half = 1, 2, 4, .., N/2` every butterfly of pairs `(i0, i1 = i0 +
//!   half)`, `i0 = group * 2 half + p`, with the twiddle `t = w[p * N / (2 half)]` (its
//!   imaginary part negated for the forward transform): `u = t * x[i1]` (`u.re = t.re x.re -
//!   t.im x.im`, `u.im = t.re x.im + t.im x.re`, each product rounded, then the sum), then
//!   `x[i1] = x[i0] - u`, `x[i0] = x[i0] + u`. The butterflies of a stage are independent, so
//!   how the GPU's threads share them does not change a bit.
//!
//! Error: the classic bound for radix-2, `O(eps log2 N)` relative to the transform's norm; the
//! tests hold each element within `4 eps log2 N * sqrt(N) * max|x|` of an f64 DFT.

use super::Tile2;
use glam::{DVec2, Vec2};

/// The complex elements of FFT tiles: `Vec2` (f32) and `DVec2` (f64).
pub trait Complex: Copy {
    /// The scalar of the parts.
    type S: Copy
        + core::ops::Add<Output = Self::S>
        + core::ops::Sub<Output = Self::S>
        + core::ops::Mul<Output = Self::S>
        + core::ops::Neg<Output = Self::S>;
    /// The f64 value rounded to the scalar (round to nearest even).
    fn round(v: f64) -> Self::S;
    /// The complex number `(re, im)`.
    fn new(re: Self::S, im: Self::S) -> Self;
    /// The real part.
    fn re(self) -> Self::S;
    /// The imaginary part.
    fn im(self) -> Self::S;
}

impl Complex for Vec2 {
    type S = f32;
    #[inline(always)]
    fn round(v: f64) -> f32 {
        v as f32
    }
    #[inline(always)]
    fn new(re: f32, im: f32) -> Self {
        Vec2::new(re, im)
    }
    #[inline(always)]
    fn re(self) -> f32 {
        self.x
    }
    #[inline(always)]
    fn im(self) -> f32 {
        self.y
    }
}

impl Complex for DVec2 {
    type S = f64;
    #[inline(always)]
    fn round(v: f64) -> f64 {
        v
    }
    #[inline(always)]
    fn new(re: f64, im: f64) -> Self {
        DVec2::new(re, im)
    }
    #[inline(always)]
    fn re(self) -> f64 {
        self.x
    }
    #[inline(always)]
    fn im(self) -> f64 {
        self.y
    }
}

/// `(c, s)` of the angles `2 pi / 2^j` for `j = 1..=l` (index `j - 1`), by the half-angle
/// formulas (the module's docs).
fn base_angles(l: u32) -> [(f64, f64); 32] {
    let mut b = [(0.0, 0.0); 32];
    let mut c = -1.0f64;
    let mut s = 0.0f64;
    for j in 1..=l.min(32) {
        if j == 2 {
            c = 0.0;
            s = 1.0;
        } else if j > 2 {
            let c2 = ((1.0 + c) * 0.5).sqrt();
            s /= c2 + c2;
            c = c2;
        }
        b[j as usize - 1] = (c, s);
    }
    b
}

/// The twiddle `e^(+2 pi i k / n)` in f64 (`n = 2^l`, `k < n / 2`), before rounding.
fn twiddle64(k: usize, l: u32, base: &[(f64, f64); 32]) -> (f64, f64) {
    let (mut re, mut im) = (1.0f64, 0.0f64);
    let mut b = 0u32;
    while (k >> b) != 0 {
        if (k >> b) & 1 == 1 {
            // Bit b of k: the angle 2 pi 2^b / 2^l = 2 pi / 2^(l - b).
            let (c, s) = base[(l - b) as usize - 1];
            let r = re * c - im * s;
            let i = re * s + im * c;
            re = r;
            im = i;
        }
        b += 1;
    }
    (re, im)
}

/// The twiddles of a transform of length `w.len() * 2` (a power of two): `w[k] = e^(+2 pi i k
/// / n)`, as the module's docs compute them; the CUDA side computes the same table.
pub fn twiddles<C: Complex>(w: &mut [C]) {
    let n = w.len() * 2;
    let l = n.trailing_zeros();
    let base = base_angles(l);
    for (k, d) in w.iter_mut().enumerate() {
        let (re, im) = twiddle64(k, l, &base);
        *d = C::new(C::round(re), C::round(im));
    }
}

/// `a * b` of complex numbers, each product rounded, then the sums (no FMA).
#[inline(always)]
fn cmul<C: Complex>(a: C, b: C) -> C {
    C::new(
        a.re() * b.re() - a.im() * b.im(),
        a.re() * b.im() + a.im() * b.re(),
    )
}

/// One row transformed in place: forward (`inverse == false`) or the unnormalised inverse.
fn row<C: Complex>(x: &mut [C], w: &[C], inverse: bool) {
    let n = x.len();
    if n < 2 {
        return;
    }
    let l = n.trailing_zeros();
    for i in 0..n {
        let j = i.reverse_bits() >> (usize::BITS - l);
        if i < j {
            x.swap(i, j);
        }
    }
    let mut half = 1;
    while half < n {
        let step = n / (2 * half);
        for q in 0..n / 2 {
            let (g, p) = (q / half, q % half);
            let i0 = g * 2 * half + p;
            let i1 = i0 + half;
            let t = w[p * step];
            let t = if inverse { t } else { C::new(t.re(), -t.im()) };
            let u = cmul(t, x[i1]);
            let a = x[i0];
            x[i1] = C::new(a.re() - u.re(), a.im() - u.im());
            x[i0] = C::new(a.re() + u.re(), a.im() + u.im());
        }
        half *= 2;
    }
}

fn transform<C: Complex, const M: usize, const N: usize>(
    t: &Tile2<C, M, N>,
    inverse: bool,
) -> Tile2<C, M, N> {
    const {
        assert!(
            N.is_power_of_two(),
            "tile_fft: the last dim must be a power of two"
        )
    };
    // The table on the stack (`N` entries, half of them used: `N / 2` is not a type's length
    // on stable Rust); nothing here allocates.
    let zero = C::new(C::round(0.0), C::round(0.0));
    let mut w = [zero; N];
    twiddles(&mut w[..N / 2]);
    let mut out = *t;
    for r in out.data.iter_mut() {
        row(r, &w[..N / 2], inverse);
    }
    out
}

/// `tile_fft(&mut t)`: each row's forward transform (numpy's `fft` along the last axis).
pub fn fft<C: Complex, const M: usize, const N: usize>(t: &Tile2<C, M, N>) -> Tile2<C, M, N> {
    transform(t, false)
}

/// `tile_ifft(&mut t)`: each row's inverse transform, unnormalised (`ifft(fft(x)) = N x`).
pub fn ifft<C: Complex, const M: usize, const N: usize>(t: &Tile2<C, M, N>) -> Tile2<C, M, N> {
    transform(t, true)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Seeded values in [-1, 1).
    fn values(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }

    /// The f64 DFT of a row (sin/cos of the exact reduced angle), forward or inverse.
    fn dft(x: &[(f64, f64)], inverse: bool) -> Vec<(f64, f64)> {
        let n = x.len();
        let sign = if inverse { 1.0 } else { -1.0 };
        (0..n)
            .map(|k| {
                let mut acc = (0.0, 0.0);
                for (j, &(a, b)) in x.iter().enumerate() {
                    let th = sign * 2.0 * std::f64::consts::PI * ((j * k) % n) as f64 / n as f64;
                    let (s, c) = th.sin_cos();
                    acc.0 += a * c - b * s;
                    acc.1 += a * s + b * c;
                }
                acc
            })
            .collect()
    }

    fn check<C: Complex, const M: usize, const N: usize>(eps: f64, to64: fn(C::S) -> f64) {
        let mut r = values(N as u64 * 31 + M as u64);
        let t = Tile2::<C, M, N> {
            data: std::array::from_fn(|_| {
                std::array::from_fn(|_| C::new(C::round(r()), C::round(r())))
            }),
        };
        let l = N.trailing_zeros().max(1) as f64;
        // |x| <= sqrt(2) per element; the error bound relative to the row's norm.
        let tol = 4.0 * eps * l * (N as f64).sqrt() * 2f64.sqrt();
        for inverse in [false, true] {
            let y = if inverse { ifft(&t) } else { fft(&t) };
            for (xr, yr) in t.data.iter().zip(&y.data) {
                let x64: Vec<(f64, f64)> =
                    xr.iter().map(|c| (to64(c.re()), to64(c.im()))).collect();
                let want = dft(&x64, inverse);
                for (k, (w, g)) in want.iter().zip(yr).enumerate() {
                    let e = (w.0 - to64(g.re())).abs().max((w.1 - to64(g.im())).abs());
                    assert!(
                        e <= tol,
                        "N={N} inverse={inverse} k={k}: error {e:e} > {tol:e}"
                    );
                }
            }
        }
        // Round trip: ifft(fft(x)) = N x, within the same bound times N.
        let rt = ifft(&fft(&t));
        for (xr, yr) in t.data.iter().zip(&rt.data) {
            for (x, y) in xr.iter().zip(yr) {
                let n = N as f64;
                let e = (to64(x.re()) * n - to64(y.re()))
                    .abs()
                    .max((to64(x.im()) * n - to64(y.im())).abs());
                assert!(e <= 2.0 * n * tol, "round trip N={N}: {e:e}");
            }
        }
    }

    #[test]
    fn fft_matches_an_f64_dft() {
        let e32 = f32::EPSILON as f64;
        let e64 = f64::EPSILON;
        check::<Vec2, 3, 1>(e32, f64::from);
        check::<Vec2, 3, 2>(e32, f64::from);
        check::<Vec2, 2, 4>(e32, f64::from);
        check::<Vec2, 5, 8>(e32, f64::from);
        check::<Vec2, 2, 64>(e32, f64::from);
        check::<Vec2, 1, 256>(e32, f64::from);
        check::<DVec2, 3, 2>(e64, |v| v);
        check::<DVec2, 2, 16>(e64, |v| v);
        check::<DVec2, 2, 128>(e64, |v| v);
        check::<DVec2, 1, 256>(e64, |v| v);
    }

    #[test]
    fn twiddles_are_close_to_sin_cos() {
        // The half-angle construction against libm, in f64: a few ulps at most.
        for l in 1..=12u32 {
            let n = 1usize << l;
            let mut w = vec![DVec2::ZERO; n / 2];
            twiddles(&mut w);
            for (k, v) in w.iter().enumerate() {
                let th = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
                let (s, c) = th.sin_cos();
                assert!((v.x - c).abs() <= 16.0 * f64::EPSILON, "n={n} k={k}");
                assert!((v.y - s).abs() <= 16.0 * f64::EPSILON, "n={n} k={k}");
            }
        }
        // Exact where they should be.
        let mut w = [Vec2::ZERO; 4];
        twiddles(&mut w);
        assert_eq!(w[0], Vec2::new(1.0, 0.0));
        assert_eq!(w[2], Vec2::new(0.0, 1.0));
    }

    #[test]
    fn impulse_and_constant() {
        let mut t = Tile2::<Vec2, 1, 8>::splat(Vec2::ZERO);
        t.data[0][0] = Vec2::new(1.0, 0.0);
        assert_eq!(fft(&t).data[0], [Vec2::new(1.0, 0.0); 8]);
        let c = Tile2::<Vec2, 1, 8>::splat(Vec2::new(1.0, 0.0));
        let f = fft(&c);
        assert_eq!(f.data[0][0], Vec2::new(8.0, 0.0));
        for v in &f.data[0][1..] {
            assert!(v.length() < 1e-6, "{v}");
        }
    }
}

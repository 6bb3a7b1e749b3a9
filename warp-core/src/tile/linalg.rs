//! Dense linear algebra on tiles: `tile_cholesky`, `tile_cholesky_solve`, `tile_lower_solve`,
//! `tile_upper_solve` (Warp's names and semantics, `fill_mode="lower"`).
//!
//! **The operation order** is part of the contract: the CUDA library (wp_tile_linalg.h) runs the
//! same roundings in the same order, spread over the block's threads, so the two back ends give
//! the same bits (tests/cuda_tile_linalg_host.rs holds them together). Every step is a separate
//! IEEE multiply, subtract, divide or square root: no fused multiply-add here (Rust never
//! contracts, and the tile section compiles with `--fmad=false`).
//!
//! - [`cholesky`]: `L` with `L Lᵀ = A`, from `A`'s lower triangle only (the upper is never
//!   read: `A` is taken to be symmetric). For each column `j`: the pivot
//!   `p = A[j][j] - L[j][0]² - L[j][1]² - ..` (the products subtracted one by one, `k`
//!   ascending), `L[j][j] = sqrt(p)`, `r = 1 / L[j][j]`, and below it
//!   `L[i][j] = (A[i][j] - L[i][0] L[j][0] - L[i][1] L[j][1] - ..) * r`, `k` ascending. The
//!   strict upper triangle of `L` is zero.
//! - **Not positive definite:** when a pivot is not positive (`p <= 0` or NaN: `A` is not
//!   symmetric positive definite, or holds a NaN), *every* element of `L` is NaN. Warp's
//!   factor is NaN from the failing column on (and a zero last pivot gives a finite singular
//!   `L` there); filling it all makes the failure visible in any element, e.g. `L[0][0]`.
//! - Triangular solves (`x` with the right-hand side's shape, one column or `K`):
//!   forward substitution (`tile_lower_solve`, `L x = y`) gives
//!   `x[i] = (y[i] - L[i][0] x[0] - L[i][1] x[1] - ..) / L[i][i]`, `j` ascending; back
//!   substitution (`tile_upper_solve`, `U x = z`) gives
//!   `x[i] = (z[i] - U[i][n-1] x[n-1] - U[i][n-2] x[n-2] - ..) / U[i][i]`, `j` *descending*
//!   (the order of the GPU's column sweep). Only the triangle named is read. A zero on the
//!   diagonal divides by zero (inf or NaN, as cuSolverDx's trsm; Warp's scalar fallback
//!   skips that division instead, which hides the singularity).
//! - [`cholesky_solve1`]/[`cholesky_solve2`]: `A x = y` given `L`: forward substitution with
//!   `L`, then back substitution with `Lᵀ` (`U[i][j] = L[j][i]`).
//!
//! Shapes are const generics: a non-square factor or a right-hand side of another length does
//! not compile (the macro reports it first, at the call).

use super::{Tile1, Tile2};
use core::ops::{Add, Div, Mul, Sub};

/// The elements of the linear-algebra tiles: `f32` and `f64`.
pub trait LinalgFloat:
    Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
{
    /// Zero.
    const ZERO: Self;
    /// One.
    const ONE: Self;
    /// One half (the Cholesky adjoint's diagonal).
    const HALF: Self;
    /// A quiet NaN (the factor of a matrix that is not positive definite).
    const NAN: Self;
    /// The correctly rounded square root (IEEE; CUDA's `sqrtf`/`sqrt` without fast math).
    fn sqrt(self) -> Self;
}

impl LinalgFloat for f32 {
    const ZERO: f32 = 0.0;
    const ONE: f32 = 1.0;
    const HALF: f32 = 0.5;
    const NAN: f32 = f32::NAN;
    #[inline(always)]
    fn sqrt(self) -> f32 {
        f32::sqrt(self)
    }
}

impl LinalgFloat for f64 {
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    const HALF: f64 = 0.5;
    const NAN: f64 = f64::NAN;
    #[inline(always)]
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
}

/// The Cholesky factor `L` of `a` (`L Lᵀ = a`), read from `a`'s lower triangle, in the order
/// the module documents; all NaN when `a` is not positive definite.
pub fn cholesky<T: LinalgFloat, const N: usize>(a: &Tile2<T, N, N>) -> Tile2<T, N, N> {
    let mut l = Tile2 {
        data: [[T::ZERO; N]; N],
    };
    for j in 0..N {
        let mut p = a.data[j][j];
        for k in 0..j {
            p = p - l.data[j][k] * l.data[j][k];
        }
        // Not greater than zero: also a NaN pivot (which compares as unordered).
        if p.partial_cmp(&T::ZERO) != Some(core::cmp::Ordering::Greater) {
            return Tile2 {
                data: [[T::NAN; N]; N],
            };
        }
        let d = p.sqrt();
        let r = T::ONE / d;
        l.data[j][j] = d;
        for i in j + 1..N {
            let mut s = a.data[i][j];
            for k in 0..j {
                s = s - l.data[i][k] * l.data[j][k];
            }
            l.data[i][j] = s * r;
        }
    }
    l
}

/// The right-hand sides of a solve: a 1-D tile (one column) or a 2-D tile (`K` columns), as
/// `N` rows of `K` values (public for the solves' adjoints, `tile::adjoint`, which take either).
pub trait Rows<T, const N: usize>: Copy {
    /// The number of columns.
    const K: usize;
    /// Row `i`, column `c`.
    fn at(&self, i: usize, c: usize) -> T;
    /// Sets row `i`, column `c`.
    fn set(&mut self, i: usize, c: usize, v: T);
}

impl<T: Copy, const N: usize> Rows<T, N> for Tile1<T, N> {
    const K: usize = 1;
    #[inline(always)]
    fn at(&self, i: usize, _: usize) -> T {
        self.data[i]
    }
    #[inline(always)]
    fn set(&mut self, i: usize, _: usize, v: T) {
        self.data[i] = v;
    }
}

impl<T: Copy, const N: usize, const K: usize> Rows<T, N> for Tile2<T, N, K> {
    const K: usize = K;
    #[inline(always)]
    fn at(&self, i: usize, c: usize) -> T {
        self.data[i][c]
    }
    #[inline(always)]
    fn set(&mut self, i: usize, c: usize, v: T) {
        self.data[i][c] = v;
    }
}

/// Forward substitution in place: `x` holds `y` and becomes the solution of `M x = y`, `M`
/// lower triangular, `M[i][j]` being `m[i][j]` or, `trans`, `m[j][i]`.
pub(super) fn forward<T: LinalgFloat, X: Rows<T, N>, const N: usize>(
    m: &Tile2<T, N, N>,
    trans: bool,
    x: &mut X,
) {
    let at = |i: usize, j: usize| if trans { m.data[j][i] } else { m.data[i][j] };
    for c in 0..X::K {
        for i in 0..N {
            let mut s = x.at(i, c);
            for j in 0..i {
                s = s - at(i, j) * x.at(j, c);
            }
            x.set(i, c, s / at(i, i));
        }
    }
}

/// Back substitution in place: `x` holds `z` and becomes the solution of `M x = z`, `M` upper
/// triangular, `M[i][j]` being `m[i][j]` or, `trans`, `m[j][i]`; `j` descending.
pub(super) fn back<T: LinalgFloat, X: Rows<T, N>, const N: usize>(
    m: &Tile2<T, N, N>,
    trans: bool,
    x: &mut X,
) {
    let at = |i: usize, j: usize| if trans { m.data[j][i] } else { m.data[i][j] };
    for c in 0..X::K {
        for i in (0..N).rev() {
            let mut s = x.at(i, c);
            for j in (i + 1..N).rev() {
                s = s - at(i, j) * x.at(j, c);
            }
            x.set(i, c, s / at(i, i));
        }
    }
}

/// `x` with `l x = y`, `l` lower triangular (Warp's `tile_lower_solve`), one right-hand side.
pub fn lower_solve1<T: LinalgFloat, const N: usize>(
    l: &Tile2<T, N, N>,
    y: &Tile1<T, N>,
) -> Tile1<T, N> {
    let mut x = *y;
    forward(l, false, &mut x);
    x
}

/// `x` with `l x = y` for `K` right-hand sides (the columns of `y`).
pub fn lower_solve2<T: LinalgFloat, const N: usize, const K: usize>(
    l: &Tile2<T, N, N>,
    y: &Tile2<T, N, K>,
) -> Tile2<T, N, K> {
    let mut x = *y;
    forward(l, false, &mut x);
    x
}

/// `x` with `u x = z`, `u` upper triangular (Warp's `tile_upper_solve`), one right-hand side.
pub fn upper_solve1<T: LinalgFloat, const N: usize>(
    u: &Tile2<T, N, N>,
    z: &Tile1<T, N>,
) -> Tile1<T, N> {
    let mut x = *z;
    back(u, false, &mut x);
    x
}

/// `x` with `u x = z` for `K` right-hand sides.
pub fn upper_solve2<T: LinalgFloat, const N: usize, const K: usize>(
    u: &Tile2<T, N, N>,
    z: &Tile2<T, N, K>,
) -> Tile2<T, N, K> {
    let mut x = *z;
    back(u, false, &mut x);
    x
}

/// `x` with `l lᵀ x = y` (Warp's `tile_cholesky_solve`), one right-hand side.
pub fn cholesky_solve1<T: LinalgFloat, const N: usize>(
    l: &Tile2<T, N, N>,
    y: &Tile1<T, N>,
) -> Tile1<T, N> {
    let mut x = *y;
    forward(l, false, &mut x);
    back(l, true, &mut x);
    x
}

/// `x` with `l lᵀ x = y` for `K` right-hand sides.
pub fn cholesky_solve2<T: LinalgFloat, const N: usize, const K: usize>(
    l: &Tile2<T, N, N>,
    y: &Tile2<T, N, K>,
) -> Tile2<T, N, K> {
    let mut x = *y;
    forward(l, false, &mut x);
    back(l, true, &mut x);
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic values in [-1, 1).
    fn values(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }

    /// `B Bᵀ + N I` for a random `B`: symmetric, well conditioned.
    fn spd<const N: usize>(seed: u64) -> Tile2<f64, N, N> {
        let mut r = values(seed);
        let b: [[f64; N]; N] = std::array::from_fn(|_| std::array::from_fn(|_| r()));
        Tile2 {
            data: std::array::from_fn(|i| {
                std::array::from_fn(|j| {
                    let d: f64 = (0..N).map(|k| b[i][k] * b[j][k]).sum();
                    d + if i == j { N as f64 } else { 0.0 }
                })
            }),
        }
    }

    #[test]
    fn a_known_factor() {
        // A = L Lᵀ with L = [[2, 0, 0], [1, 3, 0], [-1, 2, 4]]: every step is exact.
        let a = Tile2::<f64, 3, 3> {
            data: [[4.0, 2.0, -2.0], [2.0, 10.0, 5.0], [-2.0, 5.0, 21.0]],
        };
        let l = cholesky(&a);
        assert_eq!(l.data, [[2.0, 0.0, 0.0], [1.0, 3.0, 0.0], [-1.0, 2.0, 4.0]]);
        // The upper triangle of `a` is not read.
        let mut b = a;
        b.data[0][2] = 99.0;
        assert_eq!(cholesky(&b), l);
        // x = [1, 2, 3]: y = A x.
        let y = Tile1 {
            data: [2.0, 37.0, 71.0],
        };
        assert_eq!(cholesky_solve1(&l, &y).data, [1.0, 2.0, 3.0]);
        let z = lower_solve1(&l, &y);
        // L z = y and Lᵀ x = z, so upper_solve with Lᵀ gives x.
        let lt = Tile2 {
            data: std::array::from_fn(|i| std::array::from_fn(|j| l.data[j][i])),
        };
        assert_eq!(upper_solve1(&lt, &z).data, [1.0, 2.0, 3.0]);
    }

    #[test]
    fn not_positive_definite_is_all_nan() {
        // Pivot 2 is 1 - 4 < 0.
        let a = Tile2::<f32, 3, 3> {
            data: [[1.0, 0.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        };
        assert!(cholesky(&a).data.iter().flatten().all(|v| v.is_nan()));
        // A zero last pivot too (Warp would give a finite L with a zero diagonal there).
        let z = Tile2::<f64, 2, 2> {
            data: [[1.0, 0.0], [1.0, 1.0]],
        };
        assert!(cholesky(&z).data.iter().flatten().all(|v| v.is_nan()));
        let n = Tile2::<f64, 1, 1> { data: [[f64::NAN]] };
        assert!(cholesky(&n).data[0][0].is_nan());
    }

    #[test]
    fn random_spd_residuals() {
        let a = spd::<16>(3);
        let l = cholesky(&a);
        let mut r = values(5);
        let y = Tile2::<f64, 16, 3> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r())),
        };
        let x = cholesky_solve2(&l, &y);
        for i in 0..16 {
            for j in 0..16 {
                let llt: f64 = (0..16).map(|k| l.data[i][k] * l.data[j][k]).sum();
                // Entries of A are below 21; f64 roundings over 16 terms: 1e-12 is generous.
                assert!((llt - a.data[i][j]).abs() < 1e-12, "{i} {j}");
            }
            for c in 0..3 {
                let ax: f64 = (0..16).map(|k| a.data[i][k] * x.data[k][c]).sum();
                assert!((ax - y.data[i][c]).abs() < 1e-12);
            }
        }
        // One column at a time is the same computation.
        for c in 0..3 {
            let yc = Tile1 {
                data: std::array::from_fn(|i| y.data[i][c]),
            };
            let xc = cholesky_solve1(&l, &yc);
            for i in 0..16 {
                assert_eq!(xc.data[i].to_bits(), x.data[i][c].to_bits());
            }
        }
    }
}

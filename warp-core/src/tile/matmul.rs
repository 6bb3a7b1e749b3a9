//! The tile matrix product with fused multiply-adds (`tile_matmul`, its FMA path).
//!
//! Every output element is one chain of fused multiply-adds over `k = 0..K` in ascending
//! order, `acc = fma(a[i][k], b[k][j], acc)`, each rounded once (Rust's `mul_add`, CUDA's
//! `fmaf`/`fma`). The CUDA library walks `k` in the same order in every thread, so the product
//! is bit-identical on both back ends and independent of the block size.
//!
//! Half precision ([`f16`](struct@crate::f16) operands) accumulates in `f32` ([`MatmulElem::Acc`]): each operand
//! is widened to `f32` (exactly), the chain is the `f32` one above, and the returning form
//! [`matmul`] rounds each output to `f16` once at the end (Warp's dtype rule: the result has
//! `a`'s element). The accumulating form [`matmul_acc`] takes an `f32` accumulator, which is
//! what a GEMM's k-loop keeps. CUDA's FMA fallback computes the same chains, so it agrees bit
//! for bit; its tensor-core path (wp_tile_mma.h) sums each k-step of 16 products in the
//! hardware's order, which agrees only to a tolerance (see the tiles chapter).
//!
//! [`bf16`](struct@crate::bf16) operands do the same (products of two bf16 values are exact in
//! `f32` too); CUDA computes them on its FMA path only, so they agree bit for bit.
//!
//! Shapes are const generics: `a: Tile2<T, M, K>` and `b: Tile2<T, K, N>` must agree on `K`,
//! and the output is `Tile2<T, M, N>`. A mismatch is a type error at compile time, never a
//! run-time check.

use super::Tile2;
use crate::bfloat16::bf16;
use crate::builtins::Scalar;
use crate::float16::f16;

/// A fused multiply-add, `self * b + c` with one rounding: `f32` and `f64`.
pub trait Fma: Copy {
    /// `self * b + c`, rounded once (C's `fma`).
    fn fma(self, b: Self, c: Self) -> Self;
}

impl Fma for f32 {
    #[inline(always)]
    fn fma(self, b: f32, c: f32) -> f32 {
        self.mul_add(b, c)
    }
}

impl Fma for f64 {
    #[inline(always)]
    fn fma(self, b: f64, c: f64) -> f64 {
        self.mul_add(b, c)
    }
}

/// An element of `tile_matmul`'s operands: the type its products accumulate in ([`Acc`]),
/// and the conversions to and from it. `f32` and `f64` accumulate in themselves (the
/// conversions are the identity, so their chains are exactly the [`Fma`] ones); `f16` in
/// `f32` (widening is exact; narrowing rounds to nearest even, once).
///
/// [`Acc`]: MatmulElem::Acc
pub trait MatmulElem: Copy {
    /// The accumulator's type.
    type Acc: Fma + Scalar;
    /// Whether widening costs work (`f16`): the matmul then widens each element of `b` once,
    /// a few rows at a time, instead of once per use.
    const WIDENS: bool = false;
    /// `self` as an accumulator value (exact).
    fn widen(self) -> Self::Acc;
    /// An accumulator rounded back to the operands' type.
    fn narrow(acc: Self::Acc) -> Self;
}

impl MatmulElem for f32 {
    type Acc = f32;
    #[inline(always)]
    fn widen(self) -> f32 {
        self
    }
    #[inline(always)]
    fn narrow(acc: f32) -> f32 {
        acc
    }
}

impl MatmulElem for f64 {
    type Acc = f64;
    #[inline(always)]
    fn widen(self) -> f64 {
        self
    }
    #[inline(always)]
    fn narrow(acc: f64) -> f64 {
        acc
    }
}

impl MatmulElem for f16 {
    type Acc = f32;
    const WIDENS: bool = true;
    #[inline(always)]
    fn widen(self) -> f32 {
        self.to_f32()
    }
    #[inline(always)]
    fn narrow(acc: f32) -> f16 {
        f16::from_f32(acc)
    }
}

/// bf16 operands accumulate in `f32`, as f16's: each product of two widened bf16 values is
/// exact in `f32` (8 + 8 significant bits), so a chain rounds only at its additions.
impl MatmulElem for bf16 {
    type Acc = f32;
    const WIDENS: bool = true;
    #[inline(always)]
    fn widen(self) -> f32 {
        self.to_f32()
    }
    #[inline(always)]
    fn narrow(acc: f32) -> bf16 {
        bf16::from_f32(acc)
    }
}

/// `c += a · b` in place (Warp's `tile_matmul(a, b, out)` with `alpha = beta = 1`): for each
/// `(i, j)`, `acc = c[i][j]`, then `acc = a[i][k].mul_add(b[k][j], acc)` for `k = 0..K`
/// ascending, then `c[i][j] = acc`. The accumulator `c` has the operands' [`MatmulElem::Acc`]
/// type (`f32` for `f16` operands, which are widened exactly).
///
/// The inner dimensions must agree (`K`), and `c` must be `M × N`: the const generics make any
/// other shape a compile error.
pub fn matmul_acc<T: MatmulElem, const M: usize, const K: usize, const N: usize>(
    a: &Tile2<T, M, K>,
    b: &Tile2<T, K, N>,
    c: &mut Tile2<T::Acc, M, N>,
) {
    // With hardware FMA the same loops compile to vector FMAs (`mul_add` is otherwise a libm
    // call per element). The chains, and so the bits, are the same either way.
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has FMA (checked above), all `matmul_fma` needs.
        unsafe { matmul_fma(a, b, c) };
        return;
    }
    matmul_rows(a, b, c);
}

/// The loops of [`matmul_acc`]: row `i` of `c` takes `a[i][k] * b[k]` for `k` ascending, so
/// each `c[i][j]` is its own FMA chain in ascending `k` while the inner loop runs along a row
/// of `b` (contiguous, vectorizable).
#[inline(always)]
fn matmul_rows<T: MatmulElem, const M: usize, const K: usize, const N: usize>(
    a: &Tile2<T, M, K>,
    b: &Tile2<T, K, N>,
    c: &mut Tile2<T::Acc, M, N>,
) {
    if T::WIDENS {
        // Rows k0..k0 + 4 of `b` widened once (K N conversions in all instead of M K N; a
        // 4 x N buffer on the stack), then every row of `c` takes them in ascending k: each
        // c[i][j] still sees k = 0, 1, .. in order, so the chains are the ones below.
        const CH: usize = 4;
        let mut k0 = 0;
        while k0 < K {
            let rows = CH.min(K - k0);
            let bw: [[T::Acc; N]; CH] = std::array::from_fn(|r| {
                let row = &b.data[(k0 + r).min(K - 1)];
                std::array::from_fn(|j| row[j].widen())
            });
            for (arow, crow) in a.data.iter().zip(c.data.iter_mut()) {
                for (r, bwr) in bw.iter().enumerate().take(rows) {
                    let aik = arow[k0 + r].widen();
                    for (cij, bkj) in crow.iter_mut().zip(bwr) {
                        *cij = aik.fma(*bkj, *cij);
                    }
                }
            }
            k0 += rows;
        }
        return;
    }
    for (arow, crow) in a.data.iter().zip(c.data.iter_mut()) {
        for (aik, brow) in arow.iter().zip(&b.data) {
            let aik = aik.widen();
            for (cij, bkj) in crow.iter_mut().zip(brow) {
                *cij = aik.fma(bkj.widen(), *cij);
            }
        }
    }
}

/// [`matmul_rows`] compiled with FMA enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "fma")]
unsafe fn matmul_fma<T: MatmulElem, const M: usize, const K: usize, const N: usize>(
    a: &Tile2<T, M, K>,
    b: &Tile2<T, K, N>,
    c: &mut Tile2<T::Acc, M, N>,
) {
    matmul_rows(a, b, c)
}

/// `a · b` (Warp's `c = tile_matmul(a, b)`): [`matmul_acc`] into a zero accumulator, so each
/// element is the FMA chain starting from `+0`, then rounded once to `T` (for `f16`; the
/// identity for `f32` and `f64`).
///
/// The inner dimensions must agree (`K`); the const generics make a mismatch a compile error.
pub fn matmul<T: MatmulElem, const M: usize, const K: usize, const N: usize>(
    a: &Tile2<T, M, K>,
    b: &Tile2<T, K, N>,
) -> Tile2<T, M, N> {
    let mut c = Tile2::<T::Acc, M, N>::splat(<T::Acc as Scalar>::ZERO);
    matmul_acc(a, b, &mut c);
    Tile2 {
        data: c.data.map(|row| row.map(T::narrow)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic values in [-1, 1) with full mantissas.
    fn values(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }

    #[test]
    fn f32_matmul_matches_the_scalar_fma_loop_exactly_and_f64_closely() {
        let mut r = values(7);
        let a = Tile2::<f32, 5, 17> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r() as f32)),
        };
        let b = Tile2::<f32, 17, 3> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r() as f32)),
        };
        let c0 = Tile2::<f32, 5, 3> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r() as f32)),
        };
        let mut c = c0;
        matmul_acc(&a, &b, &mut c);
        let p = matmul(&a, &b);
        for i in 0..5 {
            for j in 0..3 {
                // Exact: the same chain, written as a scalar loop with the libm-style call.
                let mut acc = c0.data[i][j];
                let mut acc0 = 0.0f32;
                for k in 0..17 {
                    acc = f32::mul_add(a.data[i][k], b.data[k][j], acc);
                    acc0 = f32::mul_add(a.data[i][k], b.data[k][j], acc0);
                }
                assert_eq!(c.data[i][j].to_bits(), acc.to_bits());
                assert_eq!(p.data[i][j].to_bits(), acc0.to_bits());
                // Against f64 (exact products of f32 inputs, one f64 rounding per add): 17
                // f32 roundings of partial sums bounded by sum |a||b| <= 18, so an error of at
                // most 17 * 2^-24 * 18 < 2e-5 in absolute terms.
                let mut r64 = c0.data[i][j] as f64;
                for k in 0..17 {
                    r64 += a.data[i][k] as f64 * b.data[k][j] as f64;
                }
                assert!((c.data[i][j] as f64 - r64).abs() < 2e-5, "{i} {j}");
            }
        }
    }

    #[test]
    fn fma_is_fused() {
        // (1 + 2^-12)^2 = 1 + 2^-11 + 2^-24: an unfused f32 multiply drops the 2^-24 term.
        let x = 1.0f32 + f32::EPSILON * 2048.0;
        let a = Tile2::<f32, 1, 1> { data: [[x]] };
        let mut c = Tile2::<f32, 1, 1> {
            data: [[-(1.0 + 2.0 * f32::EPSILON * 2048.0)]],
        };
        matmul_acc(&a, &a, &mut c);
        assert_eq!(c.data[0][0], 2f32.powi(-24));
        let d = Tile2::<f64, 1, 1> { data: [[3.0]] };
        assert_eq!(matmul(&d, &d).data[0][0], 9.0);
    }

    #[test]
    fn f64_matmul_against_a_naive_product() {
        let mut r = values(11);
        let a = Tile2::<f64, 8, 8> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r())),
        };
        let id = Tile2::<f64, 8, 8> {
            data: std::array::from_fn(|i| std::array::from_fn(|j| (i == j) as u8 as f64)),
        };
        // Multiplying by the identity is exact (each step adds an exact product or zero).
        assert_eq!(matmul(&a, &id), a);
        assert_eq!(matmul(&id, &a), a);
        let p = matmul(&a, &a);
        for i in 0..8 {
            for j in 0..8 {
                let naive: f64 = (0..8).map(|k| a.data[i][k] * a.data[k][j]).sum();
                // Both are within 8 roundings of partial sums bounded by 8: |diff| < 2 * 8 * 8 *
                // 2^-53 < 2e-14.
                assert!((p.data[i][j] - naive).abs() < 2e-14);
            }
        }
    }

    /// f16 operands: each output is the f32 FMA chain of the widened operands (the f32
    /// accumulator of `matmul_acc` exactly; `matmul` that chain from +0 rounded once to f16),
    /// and close to the f64 product. K = 39: the widened rows of `b` come 4 at a time, the
    /// last chunk 3.
    #[test]
    fn f16_operands_accumulate_in_f32_and_round_once() {
        let mut r = values(5);
        let h = |x: f64| f16::from_f64(x);
        let a = Tile2::<f16, 4, 39> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| h(r()))),
        };
        let b = Tile2::<f16, 39, 6> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| h(r()))),
        };
        let c0 = Tile2::<f32, 4, 6> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r() as f32)),
        };
        let mut c = c0;
        matmul_acc(&a, &b, &mut c);
        let p: Tile2<f16, 4, 6> = matmul(&a, &b);
        for i in 0..4 {
            for j in 0..6 {
                let (mut acc, mut acc0, mut r64, mut mag) = (c0.data[i][j], 0f32, 0f64, 0f64);
                for k in 0..39 {
                    let (x, y) = (a.data[i][k].to_f32(), b.data[k][j].to_f32());
                    acc = x.mul_add(y, acc);
                    acc0 = x.mul_add(y, acc0);
                    r64 += x as f64 * y as f64;
                    mag += (x as f64 * y as f64).abs();
                }
                assert_eq!(c.data[i][j].to_bits(), acc.to_bits(), "acc {i} {j}");
                assert_eq!(
                    p.data[i][j].to_bits(),
                    f16::from_f32(acc0).to_bits(),
                    "{i} {j}"
                );
                // Against f64 (the products of f16 values are exact in f32): the f32 chain
                // is within 39 * 2^-24 * sum |a||b|, and the final rounding adds half an f16
                // ulp of the result, at most 2^-11 |result| <= 2^-11 sum |a||b|.
                let bound = (39.0 * 2f64.powi(-24) + 2f64.powi(-11)) * mag;
                assert!((p.data[i][j].to_f64() - r64).abs() <= bound, "{i} {j}");
            }
        }
    }

    /// bf16 operands, as f16's: each output the f32 FMA chain of the widened operands (exact
    /// products: 8 significant bits each), `matmul` that chain from +0 rounded once to bf16;
    /// against f64, the chain's `K 2^-24 S` plus half a bf16 ulp (2^-8 relative), `S` the sum
    /// of the products' magnitudes.
    #[test]
    fn bf16_operands_accumulate_in_f32_and_round_once() {
        let mut r = values(9);
        let h = |x: f64| bf16::from_f64(x);
        let a = Tile2::<bf16, 5, 21> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| h(r()))),
        };
        let b = Tile2::<bf16, 21, 7> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| h(r()))),
        };
        let c0 = Tile2::<f32, 5, 7> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r() as f32)),
        };
        let mut c = c0;
        matmul_acc(&a, &b, &mut c);
        let p: Tile2<bf16, 5, 7> = matmul(&a, &b);
        for i in 0..5 {
            for j in 0..7 {
                let (mut acc, mut acc0, mut r64, mut mag) = (c0.data[i][j], 0f32, 0f64, 0f64);
                for k in 0..21 {
                    let (x, y) = (a.data[i][k].to_f32(), b.data[k][j].to_f32());
                    acc = x.mul_add(y, acc);
                    acc0 = x.mul_add(y, acc0);
                    r64 += x as f64 * y as f64;
                    mag += (x as f64 * y as f64).abs();
                }
                assert_eq!(c.data[i][j].to_bits(), acc.to_bits(), "acc {i} {j}");
                assert_eq!(p.data[i][j].to_bits(), bf16::from_f32(acc0).to_bits());
                let bound = (21.0 * 2f64.powi(-24) + 2f64.powi(-8)) * mag;
                assert!((p.data[i][j].to_f64() - r64).abs() <= bound, "{i} {j}");
            }
        }
    }
}

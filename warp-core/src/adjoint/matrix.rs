//! Adjoints of the non-square matrices' operators and builtins ([`crate::matrix`]). `g` is
//! `adj_ret`; every rule accumulates, in the order written (the CUDA mirror,
//! `wp_adjoint_matrix.h`, does the same steps); a sum is formed first, in ascending index,
//! then added (the spatial matrices' rules, `adjoint/spatial.rs`, for any shape):
//!
//! * `a + b`, `a - b`, `-a`: lane by lane; `a * s`, `s * a`, `a / s`: the lane rules of `*`
//!   and `/`, `s`'s adjoint collecting the lanes row by row;
//! * `m * x`: `adj_m[i][j] += g[i] x[j]`, then `adj_x[j] += Σ_i m[i][j] g[i]`;
//! * `a * b` (any shapes with a non-square one, glam's square matrices by their entries):
//!   `adj_a[i][k] += Σ_j g[i][j] b[k][j]`, then `adj_b[k][j] += Σ_i a[i][k] g[i][j]`;
//! * `transpose(m)`: `adj_m += gᵀ`; `outer(a, b)`: `adj_a[i] += Σ_j g[i][j] b[j]`, then
//!   `adj_b[j] += Σ_i g[i][j] a[i]`; `ddot(a, b)`: `adj_a[k] += g b[k]`, `adj_b[k] += g a[k]`
//!   row by row.

use super::lanes::{l_div, l_mul, zip_sv, zip_vs, Lanes};
use super::linalg::{AdjDdot, AdjOuter, AdjTranspose};
use super::ops::{AdjAdd, AdjDiv, AdjMul, AdjNeg, AdjSub};
use super::Adjoint;
use crate::matrix::{
    for_each_nonsquare, for_each_outer, for_each_product, transpose_rc, MatScalar, RowMajor, Shape,
    VecLanes, VecOf,
};
use crate::matrix::{
    DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63, DMat64,
    Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64,
};
use crate::spatial::{DSpatialMatrix, DSpatialVector, SpatialMatrix, SpatialVector};
use glam::{DMat2, DMat3, DMat4, DVec2, DVec3, DVec4, Mat2, Mat3, Mat4, Vec2, Vec3, Vec4};

/// `adj_a += g bᵀ`, `adj_b += aᵀ g` of `a * b` on entry arrays (see the module
/// documentation for the order).
#[inline(always)]
fn matmul_adj<S: MatScalar, const R: usize, const K: usize, const C: usize>(
    a: [[S; K]; R],
    b: [[S; C]; K],
    adj_a: &mut [[S; K]; R],
    adj_b: &mut [[S; C]; K],
    g: [[S; C]; R],
) {
    for i in 0..R {
        for k in 0..K {
            let mut r = g[i][0] * b[k][0];
            for j in 1..C {
                r += g[i][j] * b[k][j];
            }
            adj_a[i][k] += r;
        }
    }
    for k in 0..K {
        for j in 0..C {
            let mut r = a[0][k] * g[0][j];
            for i in 1..R {
                r += a[i][k] * g[i][j];
            }
            adj_b[k][j] += r;
        }
    }
}

/// Accumulates the entry array `d` into the matrix `m`.
#[inline(always)]
fn accum_rc<S: MatScalar, M: RowMajor<S, R, C>, const R: usize, const C: usize>(
    m: &mut M,
    d: [[S; C]; R],
) {
    let mut e = m.to_rc();
    for i in 0..R {
        for j in 0..C {
            e[i][j] += d[i][j];
        }
    }
    *m = M::from_rc(e);
}

macro_rules! nonsquare_adjoints {
    ($($m:ident, $s:ident, $r:literal, $c:literal);* $(;)?) => {$(
        impl Adjoint for $m {
            #[inline(always)]
            fn adj_zero() -> Self {
                $m::ZERO
            }
            #[inline(always)]
            fn adj_accum(&mut self, v: Self) {
                *self += v;
            }
        }
        // The lanes row by row (the scalar operators' lane rules).
        impl Lanes for $m {
            type S = $s;
            type A = [$s; $r * $c];
            #[inline(always)]
            fn lanes(self) -> [$s; $r * $c] {
                bytemuck::cast(self.to_rows_array())
            }
            #[inline(always)]
            fn from_lanes(a: [$s; $r * $c]) -> Self {
                $m::from_rows_array(bytemuck::cast(a))
            }
        }
        impl AdjAdd for $m {
            type Output = $m;
            #[inline(always)]
            fn adj_add(_a: $m, _b: $m, adj_a: &mut $m, adj_b: &mut $m, g: $m) {
                *adj_a += g;
                *adj_b += g;
            }
        }
        impl AdjSub for $m {
            type Output = $m;
            #[inline(always)]
            fn adj_sub(_a: $m, _b: $m, adj_a: &mut $m, adj_b: &mut $m, g: $m) {
                *adj_a += g;
                *adj_b -= g;
            }
        }
        impl AdjNeg for $m {
            #[inline(always)]
            fn adj_neg(_a: $m, adj_a: &mut $m, g: $m) {
                *adj_a -= g;
            }
        }
        impl AdjMul<$s> for $m {
            type Output = $m;
            #[inline(always)]
            fn adj_mul(a: $m, b: $s, adj_a: &mut $m, adj_b: &mut $s, g: $m) {
                zip_vs(a, b, adj_a, adj_b, g, l_mul)
            }
        }
        impl AdjMul<$m> for $s {
            type Output = $m;
            #[inline(always)]
            fn adj_mul(a: $s, b: $m, adj_a: &mut $s, adj_b: &mut $m, g: $m) {
                zip_sv(a, b, adj_a, adj_b, g, l_mul)
            }
        }
        impl AdjDiv<$s> for $m {
            type Output = $m;
            #[inline(always)]
            fn adj_div(a: $m, b: $s, adj_a: &mut $m, adj_b: &mut $s, g: $m) {
                zip_vs(a, b, adj_a, adj_b, g, l_div)
            }
        }
        impl AdjMul<<$s as VecOf<$c>>::V> for $m {
            type Output = <$s as VecOf<$r>>::V;
            /// `adj_m[i][j] += g[i] x[j]`, then `adj_x[j] += Σ_i m[i][j] g[i]`.
            #[inline(always)]
            fn adj_mul(
                a: $m,
                x: <$s as VecOf<$c>>::V,
                adj_a: &mut $m,
                adj_x: &mut <$s as VecOf<$c>>::V,
                g: Self::Output,
            ) {
                let (m, xl, gl) = (a.to_rows_array(), x.to_lanes(), g.to_lanes());
                let mut am = adj_a.to_rows_array();
                for i in 0..$r {
                    for j in 0..$c {
                        am[i][j] += gl[i] * xl[j];
                    }
                }
                *adj_a = $m::from_rows_array(am);
                let mut ax = adj_x.to_lanes();
                for j in 0..$c {
                    let mut r = m[0][j] * gl[0];
                    for i in 1..$r {
                        r += m[i][j] * gl[i];
                    }
                    ax[j] += r;
                }
                *adj_x = VecLanes::from_lanes(ax);
            }
        }
        impl AdjTranspose for $m {
            type T = <$s as Shape<$c, $r>>::M;
            #[inline(always)]
            fn adj_transposed(_m: $m, adj_m: &mut $m, g: Self::T) {
                accum_rc(adj_m, transpose_rc(g.to_rc()));
            }
        }
        impl AdjDdot for $m {
            type S = $s;
            #[inline(always)]
            fn adj_ddot_of(a: $m, b: $m, adj_a: &mut $m, adj_b: &mut $m, g: $s) {
                let (a, b) = (a.to_rows_array(), b.to_rows_array());
                let (mut aa, mut ab) = (adj_a.to_rows_array(), adj_b.to_rows_array());
                for i in 0..$r {
                    for j in 0..$c {
                        aa[i][j] += g * b[i][j];
                        ab[i][j] += g * a[i][j];
                    }
                }
                *adj_a = $m::from_rows_array(aa);
                *adj_b = $m::from_rows_array(ab);
            }
        }
    )*};
}
for_each_nonsquare!(nonsquare_adjoints);

macro_rules! adj_mul_impls {
    ($s:ident, $k:literal, $l:ident, $r:literal; [$($b:ident: $c:literal),*]) => {$(
        impl AdjMul<$b> for $l {
            type Output = <$s as Shape<$r, $c>>::M;
            #[inline(always)]
            fn adj_mul(a: $l, b: $b, adj_a: &mut $l, adj_b: &mut $b, g: Self::Output) {
                let (mut aa, mut ab) = (
                    <$l as RowMajor<$s, $r, $k>>::to_rc(*adj_a),
                    <$b as RowMajor<$s, $k, $c>>::to_rc(*adj_b),
                );
                matmul_adj::<$s, $r, $k, $c>(a.to_rc(), b.to_rc(), &mut aa, &mut ab, g.to_rc());
                *adj_a = RowMajor::from_rc(aa);
                *adj_b = RowMajor::from_rc(ab);
            }
        }
    )*};
}
for_each_product!(adj_mul_impls);

macro_rules! adj_outer_impls {
    ($s:ident, $a:ident: $n:literal, [$($b:ident: $m:literal),*]) => {$(
        impl AdjOuter<$b> for $a {
            type Mat = <$s as Shape<$n, $m>>::M;
            /// `adj_a[i] += Σ_j g[i][j] b[j]`, then `adj_b[j] += Σ_i g[i][j] a[i]`.
            #[inline(always)]
            fn adj_outer_of(a: $a, b: $b, adj_a: &mut $a, adj_b: &mut $b, g: Self::Mat) {
                let (x, y, g) = (a.to_lanes(), b.to_lanes(), g.to_rc());
                let (mut ax, mut ay) = (adj_a.to_lanes(), adj_b.to_lanes());
                for i in 0..$n {
                    let mut r = g[i][0] * y[0];
                    for j in 1..$m {
                        r += g[i][j] * y[j];
                    }
                    ax[i] += r;
                }
                for j in 0..$m {
                    let mut r = g[0][j] * x[0];
                    for i in 1..$n {
                        r += g[i][j] * x[i];
                    }
                    ay[j] += r;
                }
                *adj_a = VecLanes::from_lanes(ax);
                *adj_b = VecLanes::from_lanes(ay);
            }
        }
    )*};
}
for_each_outer!(adj_outer_impls);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtins::{ddot, outer, transpose};

    /// Central differences of `f` at `x` along every entry of `x`'s row-major lanes, against
    /// the adjoint `adj` (scalar loss): f64 with step 1e-6 gives about 1e-9 relative error
    /// on these polynomial losses (degree 2, so the truncation error is rounding only).
    fn check<M: Lanes<S = f64> + Copy>(x: M, adj: M, f: impl Fn(M) -> f64) {
        const H: f64 = 1e-6;
        let (l, a) = (x.lanes(), adj.lanes());
        for k in 0..l.as_ref().len() {
            let (mut p, mut m) = (x.lanes(), x.lanes());
            p.as_mut()[k] += H;
            m.as_mut()[k] -= H;
            let fd = (f(M::from_lanes(p)) - f(M::from_lanes(m))) / (2.0 * H);
            let got = a.as_ref()[k];
            assert!(
                (fd - got).abs() <= 1e-7 * (1.0 + fd.abs()),
                "lane {k}: fd {fd} adjoint {got}"
            );
        }
    }

    fn m23(seed: f64) -> DMat23 {
        DMat23::from_rows_array(core::array::from_fn(|i| {
            core::array::from_fn(|j| ((i * 3 + j) as f64 * 0.37 + seed).sin())
        }))
    }

    #[test]
    fn products_against_central_differences() {
        let (a, s) = (
            m23(0.1),
            DMat3::from_cols_array(&[0.3, -0.2, 0.9, 1.1, 0.4, -0.7, 0.2, 0.5, -1.3]),
        );
        let b = m23(0.7).transpose();
        let x = DVec3::new(0.5, -1.2, 0.8);
        // loss = ddot(probe, a * b) + ddot(probe2, a * s) + dot(probe3, a * x)
        let p2 = DMat2::from_cols_array(&[0.4, -1.0, 0.6, 0.3]);
        let p23 = m23(2.0);
        let p2v = DVec2::new(-0.3, 1.7);
        let loss = |a: DMat23, b: DMat32, s: DMat3, x: DVec3| {
            ddot(p2, a * b) + ddot(p23, a * s) + p2v.dot(a * x)
        };
        let (mut ga, mut gb, mut gs, mut gx) =
            (DMat23::ZERO, DMat32::ZERO, DMat3::ZERO, DVec3::ZERO);
        let (mut dummy2, mut dummy23, mut dv) = (DMat2::ZERO, DMat23::ZERO, DVec2::ZERO);
        let (mut ga2, mut ga3) = (DMat23::ZERO, DMat23::ZERO);
        // Seed each product's result with the probe's ddot/dot adjoint.
        let (mut gp2, mut gp23) = (DMat2::ZERO, DMat23::ZERO);
        adj_ddot(p2, a * b, &mut dummy2, &mut gp2, 1.0);
        adj_ddot(p23, a * s, &mut dummy23, &mut gp23, 1.0);
        let mut gpv = DVec2::ZERO;
        super::super::adj_dot(p2v, a * x, &mut dv, &mut gpv, 1.0);
        adj_mul(a, b, &mut ga, &mut gb, gp2);
        adj_mul(a, s, &mut ga2, &mut gs, gp23);
        adj_mul(a, x, &mut ga3, &mut gx, gpv);
        let ga = ga + ga2 + ga3;
        check(a, ga, |a| loss(a, b, s, x));
        check(b, gb, |b| loss(a, b, s, x));
        check(s, gs, |s| loss(a, b, s, x));
        check(x, gx, |x| loss(a, b, s, x));
    }

    #[test]
    fn transpose_outer_ddot_and_lanes() {
        let a = m23(0.3);
        let p32 = m23(1.1).transpose();
        let mut ga = DMat23::ZERO;
        adj_transpose(a, &mut ga, p32);
        check(a, ga, |a| ddot(p32, transpose(a)));
        let (u, v) = (DVec3::new(0.2, -0.4, 1.5), DVec2::new(0.9, -0.1));
        let p = m23(0.9).transpose();
        let (mut gu, mut gv) = (DVec3::ZERO, DVec2::ZERO);
        adj_outer(u, v, &mut gu, &mut gv, p);
        check(u, gu, |u| ddot(p, outer(u, v)));
        check(v, gv, |v| ddot(p, outer(u, v)));
        let b = m23(1.9);
        let (mut g1, mut g2) = (DMat23::ZERO, DMat23::ZERO);
        adj_ddot(a, b, &mut g1, &mut g2, 1.0);
        check(a, g1, |a| ddot(a, b));
        // Scalar operators: s * a / t - a.
        let (s, t) = (1.7, -0.6);
        let p = m23(3.3);
        let (mut ga, mut gs, mut gt) = (DMat23::ZERO, 0.0, 0.0);
        let (mut gm, mut gq) = (DMat23::ZERO, DMat23::ZERO);
        adj_sub((s * a) / t, a, &mut gq, &mut ga, p);
        let mut gsa = DMat23::ZERO;
        adj_div(s * a, t, &mut gsa, &mut gt, gq);
        adj_mul(s, a, &mut gs, &mut gm, gsa);
        let ga = ga + gm;
        check(a, ga, |a| ddot(p, (s * a) / t - a));
        let fd = (ddot(p, ((s + 1e-6) * a) / t - a) - ddot(p, ((s - 1e-6) * a) / t - a)) / 2e-6;
        assert!((fd - gs).abs() < 1e-7 * (1.0 + fd.abs()), "{fd} {gs}");
        // A spatial product: 6x3 times 3x6.
        let m = DMat63::from_rows_array(core::array::from_fn(|i| {
            core::array::from_fn(|j| ((i + 2 * j) as f64 * 0.21).cos())
        }));
        let n = m.transpose() * 0.5;
        let probe = DSpatialMatrix::IDENTITY + m * n;
        let (mut gm, mut gn) = (DMat63::ZERO, DMat36::ZERO);
        let r = m * n;
        let mut gp = DSpatialMatrix::ZERO;
        let mut dummy = DSpatialMatrix::ZERO;
        adj_ddot_spatial(probe, r, &mut dummy, &mut gp);
        adj_mul(m, n, &mut gm, &mut gn, gp);
        check(m, gm, |m| spatial_ddot(probe, m * n));
        check(n, gn, |n| spatial_ddot(probe, m * n));
    }

    fn spatial_ddot(a: DSpatialMatrix, b: DSpatialMatrix) -> f64 {
        let (a, b) = (a.to_rows_array(), b.to_rows_array());
        (0..36).map(|k| a[k / 6][k % 6] * b[k / 6][k % 6]).sum()
    }

    fn adj_ddot_spatial(
        a: DSpatialMatrix,
        _b: DSpatialMatrix,
        _ga: &mut DSpatialMatrix,
        gb: &mut DSpatialMatrix,
    ) {
        *gb += a;
    }

    use super::super::{adj_ddot, adj_div, adj_mul, adj_outer, adj_sub, adj_transpose};
}

//! Adjoints of the spatial-vector operators and builtins ([`crate::builtins::spatial`]),
//! Warp's rules (`warp/native/spatial.h`) where Warp writes them. `g` is `adj_ret`; every rule
//! accumulates, in the order written (the CUDA mirror, `wp_adjoint_spatial.h`, does the same
//! steps); a sum is formed first, in ascending index, then added:
//!
//! * `a + b`, `a - b`, `-a`: lane by lane; `a * s`, `s * a`, `a / s`: the lane rules of `*`
//!   and `/`, `s`'s adjoint collecting the lanes in order (matrices: row-major);
//! * `m * x`: `adj_m[i][j] += g[i] x[j]`, then `adj_x[j] += Σ_i m[i][j] g[i]`;
//! * `a * b` (matrices): `adj_a[i][k] += Σ_j g[i][j] b[k][j]`, then
//!   `adj_b[k][j] += Σ_i a[i][k] g[i][j]`;
//! * `transpose(m)`: `adj_m += gᵀ`; `outer(a, b)`: `adj_a[i] += Σ_j g[i][j] b[j]`, then
//!   `adj_b[j] += Σ_i g[i][j] a[i]`;
//! * `spatial_vector(w, v)`: `adj_w += g.top`, `adj_v += g.bottom`; the six-scalar form
//!   `adj_k += g[k]`; `spatial_top`/`spatial_bottom`: `adj_a.top/bottom += g`;
//! * `spatial_dot(a, b)`: the lane rule of `*` with `g`, lane by lane;
//! * `spatial_cross(a, b)`: `adj_cross(wa, wb)` with `g.top`, `adj_cross(va, wb)` with
//!   `g.bottom`, `adj_cross(wa, vb)` with `g.bottom`; `spatial_cross_dual(a, b)`:
//!   `adj_cross(wa, wb)` with `g.top`, `adj_cross(va, vb)` with `g.top`, `adj_cross(wa, vb)`
//!   with `g.bottom` (each the 3-vector `cross` adjoint);
//! * `velocity_at_point(qd, r)`, forward `v + w × r`: `adj_cross(w, r)` with `g` into
//!   `adj_qd.top` and `adj_r`, then `adj_qd.bottom += g`;
//! * `spatial_adjoint(r, s)`: `adj_r[i][j] += g[i][j]`, then `+= g[i + 3][j + 3]`;
//!   `adj_s[i][j] += g[i + 3][j]` (row `i`, column `j` of the 3x3 matrices);
//! * `transform_twist(t, x)`, forward `w' = q w`, `v' = q v + p × w'`: with `gw = g.top`,
//!   `adj_cross(p, w')` with `g.bottom` into `adj_t.p` and `gw`, then the rotation adjoint
//!   (`adj_mul(q, ·)`) of `q v` with `g.bottom` and of `q w` with `gw`;
//!   `transform_wrench(t, x)`, forward `f' = q f`, `τ' = q τ + p × f'`: with `gf = g.bottom`,
//!   `adj_cross(p, f')` with `g.top` into `adj_t.p` and `gf`, then the rotation adjoints of
//!   `q τ` with `g.top` and of `q f` with `gf`.

use glam::{DMat3, DQuat, DVec3, Mat3, Quat, Vec3};

use super::builtins::AdjCross;
use super::lanes::{l_div, l_mul, zip_sv, zip_vs, zip_vv, Lanes};
use super::linalg::{AdjOuter, AdjTranspose};
use super::ops::{AdjAdd, AdjDiv, AdjMul, AdjNeg, AdjSub};
use super::Adjoint;
use crate::builtins::spatial::{
    SpatialAdjointParts, SpatialOps, SpatialParts, SpatialScalar, TwistOps,
};
use crate::spatial::{DSpatialMatrix, DSpatialVector, SpatialMatrix, SpatialVector};
use crate::transform::{DTransform, Transform};

/// Adjoint of `spatial_vector(w, v)`: `Vec3`, `DVec3`.
pub trait AdjSpatialParts: SpatialParts + Adjoint {
    /// See [`adj_spatial_vector`].
    fn adj_spatial_vector(w: Self, v: Self, adj_w: &mut Self, adj_v: &mut Self, g: Self::SV);
}

/// Adjoint of `spatial_vector(w, v)`: `adj_w += g.top`, `adj_v += g.bottom`.
#[inline(always)]
pub fn adj_spatial_vector<V: AdjSpatialParts>(
    w: V,
    v: V,
    adj_w: &mut V,
    adj_v: &mut V,
    adj_ret: V::SV,
) {
    V::adj_spatial_vector(w, v, adj_w, adj_v, adj_ret)
}

/// Adjoint of the six-scalar `spatial_vector`: `f32`, `f64`.
pub trait AdjSpatialScalar: SpatialScalar + Adjoint {
    /// Lane `k` of `g`.
    fn lane(g: Self::SV, k: usize) -> Self;
}

/// Adjoint of the six-scalar `spatial_vector`: `adj_k += g[k]`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn adj_spatial_vector_scalars<S: AdjSpatialScalar + core::ops::AddAssign>(
    _a0: S,
    _a1: S,
    _a2: S,
    _a3: S,
    _a4: S,
    _a5: S,
    adj_a0: &mut S,
    adj_a1: &mut S,
    adj_a2: &mut S,
    adj_a3: &mut S,
    adj_a4: &mut S,
    adj_a5: &mut S,
    adj_ret: S::SV,
) {
    for (k, a) in [adj_a0, adj_a1, adj_a2, adj_a3, adj_a4, adj_a5]
        .into_iter()
        .enumerate()
    {
        *a += S::lane(adj_ret, k);
    }
}

/// Adjoints of the spatial-vector builtins: [`SpatialVector`], [`DSpatialVector`].
pub trait AdjSpatial: SpatialOps + Adjoint {
    /// See [`adj_spatial_top`].
    fn adj_top(a: Self, adj_a: &mut Self, g: Self::V3);
    /// See [`adj_spatial_bottom`].
    fn adj_bottom(a: Self, adj_a: &mut Self, g: Self::V3);
    /// See [`adj_spatial_dot`].
    fn adj_dot(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, g: Self::S);
    /// See [`adj_spatial_cross`].
    fn adj_cross(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, g: Self);
    /// See [`adj_spatial_cross_dual`].
    fn adj_cross_dual(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, g: Self);
    /// See [`adj_velocity_at_point`].
    fn adj_velocity(qd: Self, r: Self::V3, adj_qd: &mut Self, adj_r: &mut Self::V3, g: Self::V3);
}

/// Adjoint of `spatial_top(a)`: lanes 0 to 2 of `adj_a` `+= g`.
#[inline(always)]
pub fn adj_spatial_top<X: AdjSpatial>(a: X, adj_a: &mut X, adj_ret: X::V3) {
    X::adj_top(a, adj_a, adj_ret)
}

/// Adjoint of `spatial_bottom(a)`: lanes 3 to 5 of `adj_a` `+= g`.
#[inline(always)]
pub fn adj_spatial_bottom<X: AdjSpatial>(a: X, adj_a: &mut X, adj_ret: X::V3) {
    X::adj_bottom(a, adj_a, adj_ret)
}

/// Adjoint of `spatial_dot(a, b)`.
#[inline(always)]
pub fn adj_spatial_dot<X: AdjSpatial>(a: X, b: X, adj_a: &mut X, adj_b: &mut X, adj_ret: X::S) {
    X::adj_dot(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoint of `spatial_cross(a, b)` (see the module documentation).
#[inline(always)]
pub fn adj_spatial_cross<X: AdjSpatial>(a: X, b: X, adj_a: &mut X, adj_b: &mut X, adj_ret: X) {
    X::adj_cross(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoint of `velocity_at_point(qd, r)` (see the module documentation).
#[inline(always)]
pub fn adj_velocity_at_point<X: AdjSpatial>(
    qd: X,
    r: X::V3,
    adj_qd: &mut X,
    adj_r: &mut X::V3,
    adj_ret: X::V3,
) {
    X::adj_velocity(qd, r, adj_qd, adj_r, adj_ret)
}

/// Adjoint of `spatial_cross_dual(a, b)` (see the module documentation).
#[inline(always)]
pub fn adj_spatial_cross_dual<X: AdjSpatial>(a: X, b: X, adj_a: &mut X, adj_b: &mut X, adj_ret: X) {
    X::adj_cross_dual(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoint of `spatial_adjoint(r, s)`: `Mat3`, `DMat3`.
pub trait AdjSpatialAdjoint: SpatialAdjointParts + Adjoint {
    /// See [`adj_spatial_adjoint`].
    fn adj_spatial_adjoint(r: Self, s: Self, adj_r: &mut Self, adj_s: &mut Self, g: Self::SM);
}

/// Adjoint of `spatial_adjoint(r, s)` (see the module documentation).
#[inline(always)]
pub fn adj_spatial_adjoint<M: AdjSpatialAdjoint>(
    r: M,
    s: M,
    adj_r: &mut M,
    adj_s: &mut M,
    adj_ret: M::SM,
) {
    M::adj_spatial_adjoint(r, s, adj_r, adj_s, adj_ret)
}

/// Adjoints of `transform_twist`, `transform_wrench`: [`Transform`], [`DTransform`].
pub trait AdjTwist: TwistOps<SV: Adjoint> + Adjoint {
    /// See [`adj_transform_twist`].
    fn adj_twist(t: Self, x: Self::SV, adj_t: &mut Self, adj_x: &mut Self::SV, g: Self::SV);
    /// See [`adj_transform_wrench`].
    fn adj_wrench(t: Self, x: Self::SV, adj_t: &mut Self, adj_x: &mut Self::SV, g: Self::SV);
}

/// Adjoint of `transform_twist(t, x)` (see the module documentation).
#[inline(always)]
pub fn adj_transform_twist<X: AdjTwist>(
    t: X,
    x: X::SV,
    adj_t: &mut X,
    adj_x: &mut X::SV,
    adj_ret: X::SV,
) {
    X::adj_twist(t, x, adj_t, adj_x, adj_ret)
}

/// Adjoint of `transform_wrench(t, x)` (see the module documentation).
#[inline(always)]
pub fn adj_transform_wrench<X: AdjTwist>(
    t: X,
    x: X::SV,
    adj_t: &mut X,
    adj_x: &mut X::SV,
    adj_ret: X::SV,
) {
    X::adj_wrench(t, x, adj_t, adj_x, adj_ret)
}

macro_rules! spatial_adj {
    ($($sv:ident, $sm:ident: $s:ident, $v3:ident, $q:ident, $m3:ident, $x:ident);*) => {$(
        impl Adjoint for $sv {
            #[inline(always)]
            fn adj_zero() -> Self {
                $sv::ZERO
            }
            #[inline(always)]
            fn adj_accum(&mut self, v: Self) {
                *self += v;
            }
        }
        impl Adjoint for $sm {
            #[inline(always)]
            fn adj_zero() -> Self {
                $sm::ZERO
            }
            #[inline(always)]
            fn adj_accum(&mut self, v: Self) {
                *self += v;
            }
        }
        impl Lanes for $sv {
            type S = $s;
            type A = [$s; 6];
            #[inline(always)]
            fn lanes(self) -> [$s; 6] {
                self.to_array()
            }
            #[inline(always)]
            fn from_lanes(a: [$s; 6]) -> Self {
                $sv::from_array(a)
            }
        }
        impl Lanes for $sm {
            type S = $s;
            type A = [$s; 36];
            /// Row-major.
            #[inline(always)]
            fn lanes(self) -> [$s; 36] {
                let r = self.to_rows_array();
                core::array::from_fn(|k| r[k / 6][k % 6])
            }
            #[inline(always)]
            fn from_lanes(a: [$s; 36]) -> Self {
                $sm::from_rows_array(core::array::from_fn(|i| core::array::from_fn(|j| a[i * 6 + j])))
            }
        }
        spatial_adj!(@lanewise $sv, $s);
        spatial_adj!(@lanewise $sm, $s);
        impl AdjMul<$sv> for $sm {
            type Output = $sv;
            #[inline(always)]
            fn adj_mul(m: $sm, x: $sv, adj_m: &mut $sm, adj_x: &mut $sv, g: $sv) {
                for i in 0..6 {
                    for j in 0..6 {
                        adj_m[i][j] += g[i] * x[j];
                    }
                }
                for j in 0..6 {
                    let mut r = m[0][j] * g[0];
                    for i in 1..6 {
                        r += m[i][j] * g[i];
                    }
                    adj_x[j] += r;
                }
            }
        }
        impl AdjMul for $sm {
            type Output = $sm;
            #[inline(always)]
            fn adj_mul(a: $sm, b: $sm, adj_a: &mut $sm, adj_b: &mut $sm, g: $sm) {
                for i in 0..6 {
                    for k in 0..6 {
                        let mut r = g[i][0] * b[k][0];
                        for j in 1..6 {
                            r += g[i][j] * b[k][j];
                        }
                        adj_a[i][k] += r;
                    }
                }
                for k in 0..6 {
                    for j in 0..6 {
                        let mut r = a[0][k] * g[0][j];
                        for i in 1..6 {
                            r += a[i][k] * g[i][j];
                        }
                        adj_b[k][j] += r;
                    }
                }
            }
        }
        impl AdjTranspose for $sm {
            type T = $sm;
            #[inline(always)]
            fn adj_transposed(_m: $sm, adj_m: &mut $sm, g: $sm) {
                *adj_m += g.transpose();
            }
        }
        impl AdjOuter for $sv {
            type Mat = $sm;
            #[inline(always)]
            fn adj_outer_of(a: $sv, b: $sv, adj_a: &mut $sv, adj_b: &mut $sv, g: $sm) {
                for i in 0..6 {
                    let mut r = g[i][0] * b[0];
                    for j in 1..6 {
                        r += g[i][j] * b[j];
                    }
                    adj_a[i] += r;
                }
                for j in 0..6 {
                    let mut r = g[0][j] * a[0];
                    for i in 1..6 {
                        r += g[i][j] * a[i];
                    }
                    adj_b[j] += r;
                }
            }
        }
        impl AdjSpatialParts for $v3 {
            #[inline(always)]
            fn adj_spatial_vector(_w: $v3, _v: $v3, adj_w: &mut $v3, adj_v: &mut $v3, g: $sv) {
                *adj_w += g.top();
                *adj_v += g.bottom();
            }
        }
        impl AdjSpatialScalar for $s {
            #[inline(always)]
            fn lane(g: $sv, k: usize) -> $s {
                g[k]
            }
        }
        impl AdjSpatial for $sv {
            #[inline(always)]
            fn adj_top(_a: $sv, adj_a: &mut $sv, g: $v3) {
                *adj_a = $sv::new(adj_a.top() + g, adj_a.bottom());
            }
            #[inline(always)]
            fn adj_bottom(_a: $sv, adj_a: &mut $sv, g: $v3) {
                *adj_a = $sv::new(adj_a.top(), adj_a.bottom() + g);
            }
            #[inline(always)]
            fn adj_dot(a: $sv, b: $sv, adj_a: &mut $sv, adj_b: &mut $sv, g: $s) {
                zip_vv(a, b, adj_a, adj_b, $sv::ZERO, |x, y, ax: &mut $s, ay: &mut $s, _| {
                    l_mul(x, y, ax, ay, g)
                })
            }
            #[inline(always)]
            fn adj_cross(a: $sv, b: $sv, adj_a: &mut $sv, adj_b: &mut $sv, g: $sv) {
                let (wa, va, wb, vb) = (a.top(), a.bottom(), b.top(), b.bottom());
                let (mut awa, mut ava) = (adj_a.top(), adj_a.bottom());
                let (mut awb, mut avb) = (adj_b.top(), adj_b.bottom());
                <$v3 as AdjCross>::adj_cross(wa, wb, &mut awa, &mut awb, g.top());
                <$v3 as AdjCross>::adj_cross(va, wb, &mut ava, &mut awb, g.bottom());
                <$v3 as AdjCross>::adj_cross(wa, vb, &mut awa, &mut avb, g.bottom());
                *adj_a = $sv::new(awa, ava);
                *adj_b = $sv::new(awb, avb);
            }
            #[inline(always)]
            fn adj_velocity(qd: $sv, r: $v3, adj_qd: &mut $sv, adj_r: &mut $v3, g: $v3) {
                let (mut aw, av) = (adj_qd.top(), adj_qd.bottom());
                <$v3 as AdjCross>::adj_cross(qd.top(), r, &mut aw, adj_r, g);
                *adj_qd = $sv::new(aw, av + g);
            }
            #[inline(always)]
            fn adj_cross_dual(a: $sv, b: $sv, adj_a: &mut $sv, adj_b: &mut $sv, g: $sv) {
                let (wa, va, wb, vb) = (a.top(), a.bottom(), b.top(), b.bottom());
                let (mut awa, mut ava) = (adj_a.top(), adj_a.bottom());
                let (mut awb, mut avb) = (adj_b.top(), adj_b.bottom());
                <$v3 as AdjCross>::adj_cross(wa, wb, &mut awa, &mut awb, g.top());
                <$v3 as AdjCross>::adj_cross(va, vb, &mut ava, &mut avb, g.top());
                <$v3 as AdjCross>::adj_cross(wa, vb, &mut awa, &mut avb, g.bottom());
                *adj_a = $sv::new(awa, ava);
                *adj_b = $sv::new(awb, avb);
            }
        }
        impl AdjSpatialAdjoint for $m3 {
            #[inline(always)]
            fn adj_spatial_adjoint(_r: $m3, _s: $m3, adj_r: &mut $m3, adj_s: &mut $m3, g: $sm) {
                for i in 0..3 {
                    for j in 0..3 {
                        adj_r.col_mut(j)[i] += g[i][j];
                        adj_r.col_mut(j)[i] += g[i + 3][j + 3];
                        adj_s.col_mut(j)[i] += g[i + 3][j];
                    }
                }
            }
        }
        impl AdjTwist for $x {
            #[inline(always)]
            fn adj_twist(t: $x, x: $sv, adj_t: &mut $x, adj_x: &mut $sv, g: $sv) {
                let w1 = t.q * x.top();
                let mut gw = g.top();
                <$v3 as AdjCross>::adj_cross(t.p, w1, &mut adj_t.p, &mut gw, g.bottom());
                let (mut aw, mut av) = (adj_x.top(), adj_x.bottom());
                <$q as AdjMul<$v3>>::adj_mul(t.q, x.bottom(), &mut adj_t.q, &mut av, g.bottom());
                <$q as AdjMul<$v3>>::adj_mul(t.q, x.top(), &mut adj_t.q, &mut aw, gw);
                *adj_x = $sv::new(aw, av);
            }
            #[inline(always)]
            fn adj_wrench(t: $x, x: $sv, adj_t: &mut $x, adj_x: &mut $sv, g: $sv) {
                let f1 = t.q * x.bottom();
                let mut gf = g.bottom();
                <$v3 as AdjCross>::adj_cross(t.p, f1, &mut adj_t.p, &mut gf, g.top());
                let (mut atau, mut af) = (adj_x.top(), adj_x.bottom());
                <$q as AdjMul<$v3>>::adj_mul(t.q, x.top(), &mut adj_t.q, &mut atau, g.top());
                <$q as AdjMul<$v3>>::adj_mul(t.q, x.bottom(), &mut adj_t.q, &mut af, gf);
                *adj_x = $sv::new(atau, af);
            }
        }
    )*};
    // The lane-by-lane operators of a spatial vector or matrix `$t` of scalar `$s`.
    (@lanewise $t:ident, $s:ident) => {
        impl AdjAdd for $t {
            type Output = $t;
            #[inline(always)]
            fn adj_add(_a: $t, _b: $t, adj_a: &mut $t, adj_b: &mut $t, g: $t) {
                *adj_a += g;
                *adj_b += g;
            }
        }
        impl AdjSub for $t {
            type Output = $t;
            #[inline(always)]
            fn adj_sub(_a: $t, _b: $t, adj_a: &mut $t, adj_b: &mut $t, g: $t) {
                *adj_a += g;
                *adj_b -= g;
            }
        }
        impl AdjNeg for $t {
            #[inline(always)]
            fn adj_neg(_a: $t, adj_a: &mut $t, g: $t) {
                *adj_a -= g;
            }
        }
        impl AdjMul<$s> for $t {
            type Output = $t;
            #[inline(always)]
            fn adj_mul(a: $t, s: $s, adj_a: &mut $t, adj_s: &mut $s, g: $t) {
                zip_vs(a, s, adj_a, adj_s, g, l_mul)
            }
        }
        impl AdjMul<$t> for $s {
            type Output = $t;
            #[inline(always)]
            fn adj_mul(s: $s, b: $t, adj_s: &mut $s, adj_b: &mut $t, g: $t) {
                zip_sv(s, b, adj_s, adj_b, g, l_mul)
            }
        }
        impl AdjDiv<$s> for $t {
            type Output = $t;
            #[inline(always)]
            fn adj_div(a: $t, s: $s, adj_a: &mut $t, adj_s: &mut $s, g: $t) {
                zip_vs(a, s, adj_a, adj_s, g, l_div)
            }
        }
    };
}
spatial_adj!(
    SpatialVector, SpatialMatrix: f32, Vec3, Quat, Mat3, Transform;
    DSpatialVector, DSpatialMatrix: f64, DVec3, DQuat, DMat3, DTransform
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adjoint::{adj_outer, adj_transpose};

    type V = DSpatialVector;
    type M = DSpatialMatrix;

    fn v(seed: f64) -> V {
        V::from_array(core::array::from_fn(|k| ((k as f64 + 1.0) * seed).sin()))
    }
    fn m(seed: f64) -> M {
        M::from_row_array(core::array::from_fn(|i| v(seed + i as f64 * 0.37)))
    }
    fn wsum(a: V, w: V) -> f64 {
        a.dot(w)
    }
    fn msum(a: M, w: M) -> f64 {
        (0..6).map(|i| a[i].dot(w[i])).sum()
    }

    /// Central differences in f64 with step 1e-6: the truncation error is O(h²) ≈ 1e-12 times
    /// third derivatives of order 1 and the rounding error about 1e-16 / 1e-6 = 1e-10, so a
    /// tolerance of 1e-7 holds with margin for these functions of O(1) inputs.
    const H: f64 = 1e-6;
    const TOL: f64 = 1e-7;

    fn fd_vec(f: &dyn Fn(V) -> f64, x: V, adj: V, what: &str) {
        for k in 0..6 {
            let (mut p, mut q) = (x, x);
            p[k] += H;
            q[k] -= H;
            let fd = (f(p) - f(q)) / (2.0 * H);
            assert!(
                (fd - adj[k]).abs() < TOL,
                "{what} lane {k}: {fd} vs {}",
                adj[k]
            );
        }
    }
    fn fd_mat(f: &dyn Fn(M) -> f64, x: M, adj: M, what: &str) {
        for i in 0..6 {
            for j in 0..6 {
                let (mut p, mut q) = (x, x);
                p[i][j] += H;
                q[i][j] -= H;
                let fd = (f(p) - f(q)) / (2.0 * H);
                assert!(
                    (fd - adj[i][j]).abs() < TOL,
                    "{what} ({i},{j}): {fd} vs {}",
                    adj[i][j]
                );
            }
        }
    }

    #[test]
    fn operators_match_central_differences() {
        let (a, b, x, w) = (m(0.3), m(0.9), v(0.5), v(1.3));
        let gm = m(1.7);
        // m * x
        let (mut am, mut ax) = (M::ZERO, V::ZERO);
        <M as AdjMul<V>>::adj_mul(a, x, &mut am, &mut ax, w);
        fd_mat(&|a| wsum(a * x, w), a, am, "m*x wrt m");
        fd_vec(&|x| wsum(a * x, w), x, ax, "m*x wrt x");
        // a * b
        let (mut aa, mut ab) = (M::ZERO, M::ZERO);
        <M as AdjMul>::adj_mul(a, b, &mut aa, &mut ab, gm);
        fd_mat(&|a| msum(a * b, gm), a, aa, "a*b wrt a");
        fd_mat(&|b| msum(a * b, gm), b, ab, "a*b wrt b");
        // transpose, outer
        let mut at = M::ZERO;
        adj_transpose(a, &mut at, gm);
        fd_mat(&|a| msum(a.transpose(), gm), a, at, "transpose");
        let (mut ox, mut ow) = (V::ZERO, V::ZERO);
        adj_outer(x, w, &mut ox, &mut ow, gm);
        fd_vec(&|x| msum(x.outer(w), gm), x, ox, "outer wrt a");
        fd_vec(&|w| msum(x.outer(w), gm), w, ow, "outer wrt b");
        // lane ops with a scalar
        let (mut ax, mut s) = (V::ZERO, 0.0);
        <V as AdjDiv<f64>>::adj_div(x, 1.7, &mut ax, &mut s, w);
        fd_vec(&|x| wsum(x / 1.7, w), x, ax, "x / s");
        let fs = |s: f64| wsum(x / s, w);
        assert!(((fs(1.7 + H) - fs(1.7 - H)) / (2.0 * H) - s).abs() < TOL);
        let (mut s, mut am) = (0.0, M::ZERO);
        <f64 as AdjMul<M>>::adj_mul(2.5, a, &mut s, &mut am, gm);
        fd_mat(&|a| msum(2.5 * a, gm), a, am, "s * m");
        let fs = |s: f64| msum(s * a, gm);
        assert!(((fs(2.5 + H) - fs(2.5 - H)) / (2.0 * H) - s).abs() < TOL);
        let (mut aa, mut ab) = (V::ZERO, V::ZERO);
        <V as AdjSub>::adj_sub(x, w, &mut aa, &mut ab, w);
        <V as AdjNeg>::adj_neg(x, &mut aa, w);
        assert_eq!(aa, V::ZERO);
        assert_eq!(ab, -w);
    }

    #[test]
    fn builtins_match_central_differences() {
        use crate::builtins::spatial::*;
        let (a, b, w) = (v(0.5), v(1.1), v(1.3));
        for (name, f, adj) in [
            (
                "cross",
                spatial_cross::<V> as fn(V, V) -> V,
                adj_spatial_cross::<V> as fn(V, V, &mut V, &mut V, V),
            ),
            (
                "cross_dual",
                spatial_cross_dual::<V>,
                adj_spatial_cross_dual::<V>,
            ),
        ] {
            let (mut aa, mut ab) = (V::ZERO, V::ZERO);
            adj(a, b, &mut aa, &mut ab, w);
            fd_vec(&|a| wsum(f(a, b), w), a, aa, name);
            fd_vec(&|b| wsum(f(a, b), w), b, ab, name);
        }
        let (mut aa, mut ab) = (V::ZERO, V::ZERO);
        adj_spatial_dot(a, b, &mut aa, &mut ab, 0.75);
        fd_vec(&|a| 0.75 * spatial_dot(a, b), a, aa, "dot");
        fd_vec(&|b| 0.75 * spatial_dot(a, b), b, ab, "dot");
        let mut aa = V::ZERO;
        let (gt, gb) = (DVec3::new(0.2, -0.4, 0.9), DVec3::new(-1.0, 0.3, 0.6));
        adj_spatial_top(a, &mut aa, gt);
        adj_spatial_bottom(a, &mut aa, gb);
        fd_vec(
            &|a| spatial_top(a).dot(gt) + spatial_bottom(a).dot(gb),
            a,
            aa,
            "top, bottom",
        );
        let (mut aw, mut av) = (DVec3::ZERO, DVec3::ZERO);
        adj_spatial_vector(gt, gb, &mut aw, &mut av, w);
        assert_eq!((aw, av), (w.top(), w.bottom()));
        let mut s = [0.0; 6];
        let [s0, s1, s2, s3, s4, s5] = &mut s;
        adj_spatial_vector_scalars(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, s0, s1, s2, s3, s4, s5, w);
        assert_eq!(s, w.to_array());
        // spatial_adjoint, through every entry of r and s.
        let r = DMat3::from_cols_array(&core::array::from_fn(|k| (k as f64 * 0.7).cos()));
        let s3 = DMat3::from_cols_array(&core::array::from_fn(|k| (k as f64 * 0.3).sin()));
        let gm = m(2.1);
        let (mut ar, mut as_) = (DMat3::ZERO, DMat3::ZERO);
        adj_spatial_adjoint(r, s3, &mut ar, &mut as_, gm);
        for k in 0..9 {
            let d = |mut x: [f64; 9], h: f64| {
                x[k] += h;
                DMat3::from_cols_array(&x)
            };
            let (rc, sc) = (r.to_cols_array(), s3.to_cols_array());
            let fr = (msum(spatial_adjoint(d(rc, H), s3), gm)
                - msum(spatial_adjoint(d(rc, -H), s3), gm))
                / (2.0 * H);
            let fs = (msum(spatial_adjoint(r, d(sc, H)), gm)
                - msum(spatial_adjoint(r, d(sc, -H)), gm))
                / (2.0 * H);
            assert!((fr - ar.to_cols_array()[k]).abs() < TOL, "adjoint r[{k}]");
            assert!((fs - as_.to_cols_array()[k]).abs() < TOL, "adjoint s[{k}]");
        }
        // transform_twist / transform_wrench, through the transform's seven lanes and x.
        let t = DTransform::new(
            DVec3::new(0.4, -1.1, 0.7),
            DQuat::from_xyzw(0.3, -0.2, 0.5, 0.8),
        );
        for (name, f, adj) in [
            (
                "twist",
                transform_twist::<DTransform> as fn(DTransform, V) -> V,
                adj_transform_twist::<DTransform> as fn(DTransform, V, &mut DTransform, &mut V, V),
            ),
            (
                "wrench",
                transform_wrench::<DTransform>,
                adj_transform_wrench::<DTransform>,
            ),
        ] {
            let (mut at, mut ax) = (DTransform::adj_zero(), V::ZERO);
            adj(t, a, &mut at, &mut ax, w);
            fd_vec(&|x| wsum(f(t, x), w), a, ax, name);
            for k in 0..7 {
                let (mut p, mut q) = (t.to_array(), t.to_array());
                p[k] += H;
                q[k] -= H;
                let fd = (wsum(f(DTransform::from_array(p), a), w)
                    - wsum(f(DTransform::from_array(q), a), w))
                    / (2.0 * H);
                let got = at.to_array()[k];
                assert!((fd - got).abs() < TOL, "{name} t lane {k}: {fd} vs {got}");
            }
        }
    }
}

//! Adjoints of the matrix decompositions ([`crate::builtins::svd`]).
//!
//! A decomposition returns a tuple; its adjoint `adj_ret` is the tuple of the outputs'
//! adjoints, and (as every adjoint here) each function recomputes the forward values it needs
//! from the argument and accumulates into `adj_a`. The formulas are Warp's (`svd.h`), each
//! product evaluated as in [`crate::builtins::svd`] (rows, left to right) so that the CUDA
//! library matches bit for bit. With `∘` the entrywise product and `ε` the decomposition's
//! epsilon (1e-6 for f32, 1e-12 for f64):
//!
//! * `svd3`, `svd2` (`(U, σ, V)` with adjoints `(Ū, σ̄, V̄)`): with
//!   `F_ij = 1 / min(σ_j² - σ_i², -ε)` for `i < j`, `F_ji = -F_ij`, `F_ii = 0`,
//!   `ā += U (K_U diag σ) Vᵀ + U (diag σ (K_V Vᵀ)) + U (diag σ̄) Vᵀ`, where
//!   `K_U = F ∘ (UᵀŪ - ŪᵀU)` and `K_V = F ∘ (VᵀV̄ - V̄ᵀV)` (the standard formula, as in
//!   PyTorch). Singular values are sorted, so `σ_j² - σ_i² ≤ 0` for `i < j`: the `min` only
//!   matters where two are within `√ε` of each other (repeated singular values), where `F` is
//!   about `-1/ε` instead of infinite: the gradient stays finite but is large wherever
//!   `Ū` or `V̄` has a component that rotates within the repeated singular subspace (the
//!   true derivative does not exist there). Through `σ` alone (`Ū = V̄ = 0`) it is exact.
//! * `eig3` (`(Q, d)` with adjoints `(Q̄, d̄)`, Giles 2008):
//!   `ā += Q ((diag d̄ + F ∘ (QᵀQ̄)) Qᵀ)` with `F_ij = 1/(d_j - d_i)`, `i ≠ j`, where each
//!   difference of magnitude below `ε` is replaced by `±ε` (its sign; `+ε` for an exact tie).
//!   Warp clamps at 1e-6 for both precisions and leaves an exact tie as a division by zero
//!   (infinite `F`, NaN gradients); here the clamp is the precision's `ε` and a tie is finite.
//!   The result is a gradient for *symmetric* perturbations of `a` (Warp's too): the forward
//!   iteration reads only the lower triangle, so differentiate through a symmetric matrix,
//!   e.g. `eig3(0.5 * (m + m.transpose()))`, to get the gradient with respect to `m`.
//! * `qr3` (`(Q, R)` with adjoints `(Q̄, R̄)`, Walter et al. 2020, eq. 3): with
//!   `M = R R̄ᵀ - Q̄ᵀQ` and `C` its lower triangle mirrored to the upper one,
//!   `ā += (Q̄ + Q C) inverse(Rᵀ)`, where `inverse` is the builtin (zero at a singular `R`,
//!   which then gives no gradient, as in Warp).

use super::Adjoint;
use crate::builtins::svd::{
    eig3_rows, mul3, mul3_nt, mul3_tn, qr_rows, svd2_rows, svd3_rows, Decomp2, Decomp3,
    DecompFloat, Rows2, Rows3,
};

fn zip3<S: DecompFloat>(a: &Rows3<S>, b: &Rows3<S>, f: impl Fn(S, S) -> S) -> Rows3<S> {
    core::array::from_fn(|i| core::array::from_fn(|j| f(a[i][j], b[i][j])))
}

fn zip2<S: DecompFloat>(a: &Rows2<S>, b: &Rows2<S>, f: impl Fn(S, S) -> S) -> Rows2<S> {
    core::array::from_fn(|i| core::array::from_fn(|j| f(a[i][j], b[i][j])))
}

/// `a b` (2x2), left to right.
fn mul2<S: DecompFloat>(a: &Rows2<S>, b: &Rows2<S>) -> Rows2<S> {
    core::array::from_fn(|i| core::array::from_fn(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j]))
}

/// `aᵀ b` (2x2), left to right.
fn mul2_tn<S: DecompFloat>(a: &Rows2<S>, b: &Rows2<S>) -> Rows2<S> {
    core::array::from_fn(|i| core::array::from_fn(|j| a[0][i] * b[0][j] + a[1][i] * b[1][j]))
}

/// `a bᵀ` (2x2), left to right.
fn mul2_nt<S: DecompFloat>(a: &Rows2<S>, b: &Rows2<S>) -> Rows2<S> {
    core::array::from_fn(|i| core::array::from_fn(|j| a[i][0] * b[j][0] + a[i][1] * b[j][1]))
}

/// The adjoint of `svd3(a)` (see the module documentation).
pub fn adj_svd3<M>(a: M, adj_a: &mut M, adj_ret: (M, M::V, M))
where
    M: Decomp3 + Adjoint,
{
    let (u, s, v) = svd3_rows(a.rows());
    let (gu, gs, gv) = (adj_ret.0.rows(), M::comps(adj_ret.1), adj_ret.2.rows());
    let eps = -M::S::EPS;
    let (sx2, sy2, sz2) = (s[0] * s[0], s[1] * s[1], s[2] * s[2]);
    let one = M::S::ONE;
    let f01 = one / (sy2 - sx2).d_min(eps);
    let f02 = one / (sz2 - sx2).d_min(eps);
    let f12 = one / (sz2 - sy2).d_min(eps);
    let z = M::S::ZERO;
    let f = [[z, f01, f02], [-f01, z, f12], [-f02, -f12, z]];
    // U diag(σ̄) Vᵀ.
    let sigma_term = mul3_nt(
        &core::array::from_fn(|i| core::array::from_fn(|k| u[i][k] * gs[k])),
        &v,
    );
    // U (K_U diag σ) Vᵀ.
    let ku = zip3(
        &f,
        &zip3(&mul3_tn(&u, &gu), &mul3_tn(&gu, &u), |x, y| x - y),
        |x, y| x * y,
    );
    let ku_s: Rows3<M::S> = core::array::from_fn(|i| core::array::from_fn(|j| ku[i][j] * s[j]));
    let u_term = mul3_nt(&mul3(&u, &ku_s), &v);
    // U (diag σ (K_V Vᵀ)).
    let kv = zip3(
        &f,
        &zip3(&mul3_tn(&v, &gv), &mul3_tn(&gv, &v), |x, y| x - y),
        |x, y| x * y,
    );
    let kv_vt = mul3_nt(&kv, &v);
    let s_kv_vt: Rows3<M::S> =
        core::array::from_fn(|i| core::array::from_fn(|j| s[i] * kv_vt[i][j]));
    let v_term = mul3(&u, &s_kv_vt);
    let total = zip3(
        &zip3(&u_term, &v_term, |x, y| x + y),
        &sigma_term,
        |x, y| x + y,
    );
    adj_a.adj_accum(M::from_rows(total));
}

/// The adjoint of `svd2(a)` (see the module documentation).
pub fn adj_svd2<M>(a: M, adj_a: &mut M, adj_ret: (M, M::V, M))
where
    M: Decomp2 + Adjoint,
{
    let (u, s, v) = svd2_rows(a.rows());
    let (gu, gs, gv) = (adj_ret.0.rows(), M::comps(adj_ret.1), adj_ret.2.rows());
    let one = M::S::ONE;
    let f01 = one / (s[1] * s[1] - s[0] * s[0]).d_min(-M::S::EPS);
    let z = M::S::ZERO;
    let f = [[z, f01], [-f01, z]];
    let sigma_term = mul2_nt(
        &core::array::from_fn(|i| core::array::from_fn(|k| u[i][k] * gs[k])),
        &v,
    );
    let ku = zip2(
        &f,
        &zip2(&mul2_tn(&u, &gu), &mul2_tn(&gu, &u), |x, y| x - y),
        |x, y| x * y,
    );
    let ku_s: Rows2<M::S> = core::array::from_fn(|i| core::array::from_fn(|j| ku[i][j] * s[j]));
    let u_term = mul2_nt(&mul2(&u, &ku_s), &v);
    let kv = zip2(
        &f,
        &zip2(&mul2_tn(&v, &gv), &mul2_tn(&gv, &v), |x, y| x - y),
        |x, y| x * y,
    );
    let kv_vt = mul2_nt(&kv, &v);
    let s_kv_vt: Rows2<M::S> =
        core::array::from_fn(|i| core::array::from_fn(|j| s[i] * kv_vt[i][j]));
    let v_term = mul2(&u, &s_kv_vt);
    let total = zip2(
        &zip2(&u_term, &v_term, |x, y| x + y),
        &sigma_term,
        |x, y| x + y,
    );
    adj_a.adj_accum(M::from_rows(total));
}

/// `δ` moved away from zero to at least `ε` in magnitude (`+ε` for an exact 0; NaN stays).
#[inline(always)]
fn gap<S: DecompFloat>(d: S) -> S {
    let eps = S::EPS;
    if d >= S::ZERO && d < eps {
        eps
    } else if d < S::ZERO && d > -eps {
        -eps
    } else {
        d
    }
}

/// The adjoint of `eig3(a)` (see the module documentation).
pub fn adj_eig3<M>(a: M, adj_a: &mut M, adj_ret: (M, M::V))
where
    M: Decomp3 + Adjoint,
{
    let (q, d) = eig3_rows(a.rows());
    let (gq, gd) = (adj_ret.0.rows(), M::comps(adj_ret.1));
    let one = M::S::ONE;
    let f01 = one / gap(d[1] - d[0]);
    let f02 = one / gap(d[2] - d[0]);
    let f12 = one / gap(d[2] - d[1]);
    let z = M::S::ZERO;
    let f = [[z, f01, f02], [-f01, z, f12], [-f02, -f12, z]];
    let dbar = [[gd[0], z, z], [z, gd[1], z], [z, z, gd[2]]];
    let inner = zip3(&dbar, &zip3(&f, &mul3_tn(&q, &gq), |x, y| x * y), |x, y| {
        x + y
    });
    let total = mul3(&q, &mul3_nt(&inner, &q));
    adj_a.adj_accum(M::from_rows(total));
}

/// The adjoint of `qr3(a)` (see the module documentation).
pub fn adj_qr3<M>(a: M, adj_a: &mut M, adj_ret: (M, M))
where
    M: Decomp3 + Adjoint,
{
    let (q, r) = qr_rows(a.rows());
    let (gq, gr) = (adj_ret.0.rows(), adj_ret.1.rows());
    let m = zip3(&mul3_nt(&r, &gr), &mul3_tn(&gq, &q), |x, y| x - y);
    let c: Rows3<M::S> = core::array::from_fn(|i| core::array::from_fn(|j| m[i.max(j)][i.min(j)]));
    let x = zip3(&gq, &mul3(&q, &c), |x, y| x + y);
    let rt: Rows3<M::S> = core::array::from_fn(|i| core::array::from_fn(|j| r[j][i]));
    let total = mul3(&x, &M::inverse_rows(rt));
    adj_a.adj_accum(M::from_rows(total));
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DMat2, DMat3, DVec2, DVec3};

    fn dot3(a: DMat3, b: DMat3) -> f64 {
        let (a, b) = (a.to_cols_array(), b.to_cols_array());
        a.iter().zip(&b).map(|(x, y)| x * y).sum()
    }

    /// Central differences of `loss` along `dir` against `<adj, dir>`.
    fn check(loss: impl Fn(DMat3) -> f64, a: DMat3, dir: DMat3, adj: DMat3) {
        let h = 1e-6;
        let fd = (loss(a + dir * h) - loss(a - dir * h)) / (2.0 * h);
        let an = dot3(adj, dir);
        assert!(
            (fd - an).abs() <= 1e-6 * (1.0 + an.abs()),
            "fd {fd} vs adjoint {an}"
        );
    }

    const A: [f64; 9] = [0.9, -0.3, 0.4, 0.2, 1.7, -0.6, 0.5, 0.1, -2.6];
    const G: [f64; 9] = [0.3, -1.1, 0.7, 0.25, 0.5, -0.9, 1.3, -0.2, 0.6];
    const E: [f64; 9] = [0.1, 0.7, -0.4, 0.8, -0.3, 0.2, -0.5, 0.6, 0.9];

    #[test]
    fn svd3_adjoint_matches_central_differences() {
        let a = DMat3::from_cols_array(&A);
        let (gu, gv) = (
            DMat3::from_cols_array(&G),
            DMat3::from_cols_array(&E).transpose(),
        );
        let gs = DVec3::new(0.4, -0.7, 1.1);
        let loss = |m: DMat3| {
            let (u, s, v) = crate::builtins::svd3(m);
            dot3(gu, u) + gs.dot(s) + dot3(gv, v)
        };
        for dir in [
            DMat3::from_cols_array(&E),
            DMat3::from_cols_array(&G).transpose(),
        ] {
            let mut adj = DMat3::IDENTITY;
            adj_svd3(a, &mut adj, (gu, gs, gv));
            check(loss, a, dir, adj - DMat3::IDENTITY);
        }
    }

    #[test]
    fn eig3_adjoint_matches_central_differences_for_symmetric_directions() {
        let m = DMat3::from_cols_array(&A);
        let a = (m + m.transpose()) * 0.5;
        let gq = DMat3::from_cols_array(&G);
        let gd = DVec3::new(0.4, -0.7, 1.1);
        let loss = |m: DMat3| {
            let (q, d) = crate::builtins::eig3(m);
            dot3(gq, q) + gd.dot(d)
        };
        let e = DMat3::from_cols_array(&E);
        let mut adj = DMat3::ZERO;
        adj_eig3(a, &mut adj, (gq, gd));
        check(loss, a, e + e.transpose(), adj);
    }

    #[test]
    fn qr3_adjoint_matches_central_differences() {
        let a = DMat3::from_cols_array(&A);
        let (gq, gr) = (DMat3::from_cols_array(&G), DMat3::from_cols_array(&E));
        let loss = |m: DMat3| {
            let (q, r) = crate::builtins::qr3(m);
            dot3(gq, q) + dot3(gr, r)
        };
        let mut adj = DMat3::ZERO;
        adj_qr3(a, &mut adj, (gq, gr));
        check(loss, a, DMat3::from_cols_array(&E), adj);
        check(loss, a, DMat3::from_cols_array(&G), adj);
    }

    #[test]
    fn svd2_adjoint_matches_central_differences() {
        let a = DMat2::from_cols_array(&[0.9, -0.3, 0.4, 1.7]);
        let (gu, gv) = (
            DMat2::from_cols_array(&[0.3, -1.1, 0.7, 0.25]),
            DMat2::from_cols_array(&[0.5, -0.9, 1.3, -0.2]),
        );
        let gs = DVec2::new(0.4, -0.7);
        let loss = |m: DMat2| {
            let (u, s, v) = crate::builtins::svd2(m);
            let d = |x: DMat2, y: DMat2| {
                x.to_cols_array()
                    .iter()
                    .zip(&y.to_cols_array())
                    .map(|(p, q)| p * q)
                    .sum::<f64>()
            };
            d(gu, u) + gs.dot(s) + d(gv, v)
        };
        let mut adj = DMat2::ZERO;
        adj_svd2(a, &mut adj, (gu, gs, gv));
        let dir = DMat2::from_cols_array(&[0.1, 0.7, -0.4, 0.8]);
        let h = 1e-6;
        let fd = (loss(a + dir * h) - loss(a - dir * h)) / (2.0 * h);
        let an: f64 = adj
            .to_cols_array()
            .iter()
            .zip(&dir.to_cols_array())
            .map(|(p, q)| p * q)
            .sum();
        assert!(
            (fd - an).abs() <= 1e-6 * (1.0 + an.abs()),
            "fd {fd} vs adjoint {an}"
        );
    }
}

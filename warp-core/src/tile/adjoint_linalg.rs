//! Reverse-mode adjoints of the tile linear algebra (`tile_lower_solve`, `tile_upper_solve`,
//! `tile_cholesky_solve`, `tile_cholesky`) and of the scans, re-exported by
//! [`super::adjoint`] (the generated code calls them there, with its conventions: inputs,
//! their adjoints, the result's adjoint `r`, the block size; every adjoint **accumulates**).
//!
//! Each recomputes what it needs of the forward (the solution, the factor) with the forward's
//! own functions, so it sees the forward's bits. Every sum below is a chain from zero in the
//! order stated, each step a separate IEEE multiply and add or subtract (no FMA): the CUDA side
//! (`wp_adjoint_tile_linalg.h`, `wp_adjoint_tile.h`) runs the same roundings in the same order,
//! so the two back ends give the same bits (tests/cuda_tile_linalg_adjoint_host.rs).
//!
//! **Solves** (`x` and the right-hand side: `N` rows of `K` columns, `K = 1` for a 1-D tile).
//! Only the triangle a solve reads receives a gradient, as in Warp:
//! - `x = L⁻¹ y`: `w = L⁻ᵀ x̄` (back substitution with `Lᵀ`, as [`super::linalg`] orders it),
//!   `ȳ += w`, and `L̄[i][j] -= Σ_c w[i][c] x[j][c]` for `i >= j` (`c` ascending);
//! - `x = U⁻¹ z`: `w = U⁻ᵀ x̄` (forward substitution with `Uᵀ`), `z̄ += w`, and
//!   `Ū[i][j] -= Σ_c w[i][c] x[j][c]` for `i <= j`;
//! - `x = (L Lᵀ)⁻¹ y`, through its two solves `z = L⁻¹ y`, `x = L⁻ᵀ z`: `z̄ = L⁻¹ x̄`, then
//!   `L̄[i][j] -= Σ_c x[i][c] z̄[j][c]` (the `Lᵀ` solve's part), `ȳ = L⁻ᵀ z̄`, `ȳ` added, then
//!   `L̄[i][j] -= Σ_c ȳ[i][c] z[j][c]` (the `L` solve's), both for `i >= j`. Warp does not
//!   differentiate this one (its `is_differentiable=False`); the rule is the chain of the two
//!   solves it is made of.
//!
//! **Cholesky** (`L = chol(A)`, from `A`'s lower triangle): the gradient is with respect to
//! that lower triangle, the parameters the forward reads (Warp's convention for
//! `fill_mode="lower"`): an off-diagonal `A[i][j]`, `i > j`, stands for both `A[i][j]` and
//! `A[j][i]` of the symmetric matrix, and the strict upper triangle gets nothing. Murray (2016):
//! with `P = Lᵀ L̄` and `Φ` the lower triangle with the diagonal halved, the symmetric
//! matrix's gradient is `M = L⁻ᵀ Φ(P) L⁻¹`, and the lower triangle's is `M + Mᵀ` off the
//! diagonal and `M[i][i]` on it. Computed as Warp's scalar path does: `W[i][j] = W[j][i] =
//! Σ_{k >= i} L[k][i] L̄[k][j]` for `i >= j` (`k` ascending; only `L̄`'s lower triangle is
//! read, the upper being the forward's constant zeros), `X = L⁻ᵀ W`, `B = L⁻ᵀ Xᵀ` (both back
//! substitutions, column by column), then `Ā[i][j] += B[i][j]` for `i > j` and
//! `Ā[i][i] += B[i][i] · 0.5`. A factor that failed (NaN) gives NaN gradients.
//!
//! **Scans** (rank 1): `y = scan_inclusive(x)` gives `x̄[i] += Σ_{j >= i} ȳ[j]`, the suffix
//! sums, computed as the forward's chunked inclusive scan (see [`super::scan`], for block size
//! `bd`) of the reversed seed; `scan_exclusive` the same of the seed shifted by one
//! (`Σ_{j > i} ȳ[j]`, a zero at the last element). The max and min scans hand `ȳ[j]` to the
//! element their output came from: the first maximum (minimum) of `x[0..=j]`, a NaN losing to
//! a number as in the forward (`x[0]` when all are NaN), added for `j` ascending.

use super::linalg::{back, cholesky, forward, LinalgFloat, Rows};
use super::scan::scan_with;
use super::{Tile1, Tile2};
use crate::adjoint::Adjoint;
use crate::builtins::Scalar;

/// `adj[i][j] -= Σ_c a[i][c] b[j][c]` (from zero, `c` ascending) over the lower (`lower`, `i >=
/// j`) or upper (`i <= j`) triangle.
fn sub_outer<T: LinalgFloat, X: Rows<T, N>, const N: usize>(
    adj: &mut Tile2<T, N, N>,
    a: &X,
    b: &X,
    lower: bool,
) {
    for i in 0..N {
        for j in 0..N {
            if if lower { i >= j } else { i <= j } {
                let mut s = T::ZERO;
                for c in 0..X::K {
                    s = s + a.at(i, c) * b.at(j, c);
                }
                adj.data[i][j] = adj.data[i][j] - s;
            }
        }
    }
}

/// `adj += w`, element by element.
fn add_rows<T: LinalgFloat, X: Rows<T, N>, const N: usize>(adj: &mut X, w: &X) {
    for i in 0..N {
        for c in 0..X::K {
            adj.set(i, c, adj.at(i, c) + w.at(i, c));
        }
    }
}

/// Adjoint of `x = tile_lower_solve(l, y)` (1-D or 2-D `y`; the module documents the rule).
pub fn adj_tile_lower_solve<T: LinalgFloat, X: Rows<T, N>, const N: usize>(
    l: &Tile2<T, N, N>,
    y: &X,
    adj_l: &mut Tile2<T, N, N>,
    adj_y: &mut X,
    r: &X,
    _bd: usize,
) {
    let mut x = *y;
    forward(l, false, &mut x);
    let mut w = *r;
    back(l, true, &mut w);
    add_rows(adj_y, &w);
    sub_outer(adj_l, &w, &x, true);
}

/// Adjoint of `x = tile_upper_solve(u, z)`.
pub fn adj_tile_upper_solve<T: LinalgFloat, X: Rows<T, N>, const N: usize>(
    u: &Tile2<T, N, N>,
    z: &X,
    adj_u: &mut Tile2<T, N, N>,
    adj_z: &mut X,
    r: &X,
    _bd: usize,
) {
    let mut x = *z;
    back(u, false, &mut x);
    let mut w = *r;
    forward(u, true, &mut w);
    add_rows(adj_z, &w);
    sub_outer(adj_u, &w, &x, false);
}

/// Adjoint of `x = tile_cholesky_solve(l, y)`.
pub fn adj_tile_cholesky_solve<T: LinalgFloat, X: Rows<T, N>, const N: usize>(
    l: &Tile2<T, N, N>,
    y: &X,
    adj_l: &mut Tile2<T, N, N>,
    adj_y: &mut X,
    r: &X,
    _bd: usize,
) {
    // The forward's two sweeps (`cholesky_solve*` runs the same on one buffer).
    let mut z = *y;
    forward(l, false, &mut z);
    let mut x = z;
    back(l, true, &mut x);
    let mut g = *r;
    // z̄ = L⁻¹ x̄; the Lᵀ solve's part of L̄.
    forward(l, false, &mut g);
    sub_outer(adj_l, &x, &g, true);
    // ȳ = L⁻ᵀ z̄; the L solve's part.
    back(l, true, &mut g);
    add_rows(adj_y, &g);
    sub_outer(adj_l, &g, &z, true);
}

/// Adjoint of `l = tile_cholesky(a)`, into `a`'s lower triangle (the module's rule).
pub fn adj_tile_cholesky<T: LinalgFloat, const N: usize>(
    a: &Tile2<T, N, N>,
    adj_a: &mut Tile2<T, N, N>,
    r: &Tile2<T, N, N>,
    _bd: usize,
) {
    let l = cholesky(a);
    let mut w = Tile2 {
        data: [[T::ZERO; N]; N],
    };
    for i in 0..N {
        for j in 0..=i {
            let mut s = T::ZERO;
            for k in i..N {
                s = s + l.data[k][i] * r.data[k][j];
            }
            w.data[i][j] = s;
            w.data[j][i] = s;
        }
    }
    back(&l, true, &mut w);
    let mut b: Tile2<T, N, N> = Tile2 {
        data: core::array::from_fn(|i| core::array::from_fn(|j| w.data[j][i])),
    };
    back(&l, true, &mut b);
    for i in 0..N {
        for j in 0..i {
            adj_a.data[i][j] = adj_a.data[i][j] + b.data[i][j];
        }
        adj_a.data[i][i] = adj_a.data[i][i] + b.data[i][i] * T::HALF;
    }
}

/// `adj[e] += Σ_{k >= e} seed(k)`, as the forward's inclusive scan of the reversed seed.
fn add_suffix_sums<T: Scalar + Adjoint, const N: usize>(
    adj: &mut Tile1<T, N>,
    bd: usize,
    seed: impl Fn(usize) -> T,
) {
    let rev: Tile1<T, N> = Tile1 {
        data: core::array::from_fn(|p| seed(N - 1 - p)),
    };
    let s = scan_with(&rev, bd, Scalar::s_add);
    for (e, d) in adj.data.iter_mut().enumerate() {
        d.adj_accum(s.data[N - 1 - e]);
    }
}

/// Adjoint of `tile_scan_inclusive(t)`: `adj_t[i] += Σ_{j >= i} r[j]`.
pub fn adj_tile_scan_inclusive<T: Scalar + Adjoint, const N: usize>(
    _t: &Tile1<T, N>,
    adj_t: &mut Tile1<T, N>,
    r: &Tile1<T, N>,
    bd: usize,
) {
    add_suffix_sums(adj_t, bd, |k| r.data[k]);
}

/// Adjoint of `tile_scan_exclusive(t)`: `adj_t[i] += Σ_{j > i} r[j]`.
pub fn adj_tile_scan_exclusive<T: Scalar + Adjoint, const N: usize>(
    _t: &Tile1<T, N>,
    adj_t: &mut Tile1<T, N>,
    r: &Tile1<T, N>,
    bd: usize,
) {
    add_suffix_sums(
        adj_t,
        bd,
        |k| if k + 1 < N { r.data[k + 1] } else { T::ZERO },
    );
}

/// `r[j]` to the element output `j` came from (`better(new, old)`: `new` replaces the running
/// extremum `old`), `j` ascending.
fn route<T: Scalar + Adjoint, const N: usize>(
    t: &Tile1<T, N>,
    adj_t: &mut Tile1<T, N>,
    r: &Tile1<T, N>,
    better: impl Fn(T, T) -> bool,
) {
    let mut m = 0;
    for j in 0..N {
        // A NaN (`v != v`) loses to a number, as in the forward's max and min.
        let (v, old) = (t.data[j], t.data[m]);
        #[allow(clippy::eq_op)]
        let old_nan = old != old;
        #[allow(clippy::eq_op)]
        let v_nan = v != v;
        if better(v, old) || (old_nan && !v_nan) {
            m = j;
        }
        adj_t.data[m].adj_accum(r.data[j]);
    }
}

/// Adjoint of `tile_scan_max_inclusive(t)`: each `r[j]` to the first maximum of `t[0..=j]`.
pub fn adj_tile_scan_max_inclusive<T: Scalar + Adjoint, const N: usize>(
    t: &Tile1<T, N>,
    adj_t: &mut Tile1<T, N>,
    r: &Tile1<T, N>,
    _bd: usize,
) {
    route(t, adj_t, r, |v, old| v > old);
}

/// Adjoint of `tile_scan_min_inclusive(t)`: each `r[j]` to the first minimum of `t[0..=j]`.
pub fn adj_tile_scan_min_inclusive<T: Scalar + Adjoint, const N: usize>(
    t: &Tile1<T, N>,
    adj_t: &mut Tile1<T, N>,
    r: &Tile1<T, N>,
    _bd: usize,
) {
    route(t, adj_t, r, |v, old| v < old);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tile::linalg::{cholesky_solve2, lower_solve2, upper_solve1};

    fn values(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }

    fn spd<const N: usize>(seed: u64) -> Tile2<f64, N, N> {
        let mut r = values(seed);
        let b: [[f64; N]; N] = core::array::from_fn(|_| core::array::from_fn(|_| r()));
        Tile2 {
            data: core::array::from_fn(|i| {
                core::array::from_fn(|j| {
                    (0..N).map(|k| b[i][k] * b[j][k]).sum::<f64>()
                        + if i == j { N as f64 } else { 0.0 }
                })
            }),
        }
    }

    /// `Σ r ⊙ f(p)` and its central difference along element `(i, j)` of `p` (step 1e-6:
    /// truncation about 1e-12 on these smooth functions, well inside the 1e-7 bound).
    fn fd<P: Copy, const M: usize>(
        p: P,
        at: impl Fn(&mut P) -> &mut f64,
        f: impl Fn(&P) -> [f64; M],
        w: &[f64; M],
    ) -> f64 {
        let h = 1e-6;
        let (mut a, mut b) = (p, p);
        *at(&mut a) += h;
        *at(&mut b) -= h;
        let (fa, fb) = (f(&a), f(&b));
        (0..M).map(|k| w[k] * (fa[k] - fb[k])).sum::<f64>() / (2.0 * h)
    }

    fn close(a: f64, b: f64, what: &str) {
        assert!(
            (a - b).abs() <= 1e-7 * b.abs().max(1.0),
            "{what}: {a} vs {b}"
        );
    }

    #[test]
    fn solves_against_differences() {
        const N: usize = 5;
        const K: usize = 2;
        let a = spd::<N>(1);
        let l = cholesky(&a);
        let mut rv = values(2);
        let y = Tile2::<f64, N, K> {
            data: core::array::from_fn(|_| core::array::from_fn(|_| rv())),
        };
        let r = Tile2::<f64, N, K> {
            data: core::array::from_fn(|_| core::array::from_fn(|_| rv())),
        };
        let wr: [f64; N * K] = core::array::from_fn(|k| r.data[k / K][k % K]);
        let flat = |x: Tile2<f64, N, K>| -> [f64; N * K] {
            core::array::from_fn(|k| x.data[k / K][k % K])
        };
        type Solve = fn(&Tile2<f64, N, N>, &Tile2<f64, N, K>) -> Tile2<f64, N, K>;
        type Adj = fn(
            &Tile2<f64, N, N>,
            &Tile2<f64, N, K>,
            &mut Tile2<f64, N, N>,
            &mut Tile2<f64, N, K>,
            &Tile2<f64, N, K>,
            usize,
        );
        let lt = Tile2 {
            data: core::array::from_fn(|i| core::array::from_fn(|j| l.data[j][i])),
        };
        let upper2: Solve = |u, z| {
            let mut x = *z;
            back(u, false, &mut x);
            x
        };
        let cases: [(&str, Tile2<f64, N, N>, Solve, Adj, bool); 3] = [
            ("lower", l, lower_solve2, adj_tile_lower_solve, true),
            ("upper", lt, upper2, adj_tile_upper_solve, false),
            (
                "cholesky",
                l,
                cholesky_solve2,
                adj_tile_cholesky_solve,
                true,
            ),
        ];
        for (what, m, solve, adj, lower) in cases {
            let (mut am, mut ay) = (Tile2::<f64, N, N>::zeros(), Tile2::<f64, N, K>::zeros());
            adj(&m, &y, &mut am, &mut ay, &r, 1);
            for i in 0..N {
                for c in 0..K {
                    let n = fd(y, |p| &mut p.data[i][c], |p| flat(solve(&m, p)), &wr);
                    close(ay.data[i][c], n, &format!("{what} y[{i}][{c}]"));
                }
                for j in 0..N {
                    let read = if lower { i >= j } else { i <= j };
                    let n = fd(m, |p| &mut p.data[i][j], |p| flat(solve(p, &y)), &wr);
                    if read {
                        close(am.data[i][j], n, &format!("{what} m[{i}][{j}]"));
                    } else {
                        assert_eq!(am.data[i][j], 0.0, "{what}: m[{i}][{j}] is not read");
                        assert_eq!(n, 0.0);
                    }
                }
            }
        }
        // A 1-D right-hand side is the same computation as one column.
        let y1 = Tile1 {
            data: core::array::from_fn(|i| y.data[i][0]),
        };
        let r1 = Tile1 {
            data: core::array::from_fn(|i| r.data[i][0]),
        };
        let (mut am, mut ay) = (Tile2::<f64, N, N>::zeros(), Tile1::<f64, N>::zeros());
        adj_tile_upper_solve(&lt, &y1, &mut am, &mut ay, &r1, 1);
        let wr1 = r1.data;
        for i in 0..N {
            let n = fd(y1, |p| &mut p.data[i], |p| upper_solve1(&lt, p).data, &wr1);
            close(ay.data[i], n, "upper, 1-D");
        }
    }

    #[test]
    fn cholesky_against_differences_of_the_lower_triangle() {
        const N: usize = 6;
        let a = spd::<N>(3);
        let mut rv = values(4);
        // A seed with upper entries too: the factor's upper triangle is constant zero, so
        // they must not matter.
        let r = Tile2::<f64, N, N> {
            data: core::array::from_fn(|_| core::array::from_fn(|_| rv())),
        };
        let wr: [f64; N * N] = core::array::from_fn(|k| r.data[k / N][k % N]);
        let mut ga = Tile2::<f64, N, N>::zeros();
        adj_tile_cholesky(&a, &mut ga, &r, 1);
        let f = |p: &Tile2<f64, N, N>| -> [f64; N * N] {
            let l = cholesky(p);
            core::array::from_fn(|k| l.data[k / N][k % N])
        };
        for i in 0..N {
            for j in 0..N {
                // Perturbs the lower triangle only (the forward never reads the upper).
                let n = fd(a, |p| &mut p.data[i][j], f, &wr);
                if i >= j {
                    close(ga.data[i][j], n, &format!("a[{i}][{j}]"));
                } else {
                    assert_eq!(ga.data[i][j], 0.0);
                    assert_eq!(n, 0.0);
                }
            }
        }
    }

    #[test]
    fn scans_route_their_seeds() {
        let t = Tile1 {
            data: [3.0f64, 1.0, 3.0, 5.0, f64::NAN, 2.0, 5.0],
        };
        let r = Tile1 {
            data: [1.0f64, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0],
        };
        for bd in [1, 2, 3, 7, 64] {
            let mut g = Tile1::<f64, 7>::zeros();
            adj_tile_scan_inclusive(&t, &mut g, &r, bd);
            assert_eq!(g.data, [127.0, 126.0, 124.0, 120.0, 112.0, 96.0, 64.0]);
            let mut g = Tile1::<f64, 7>::zeros();
            adj_tile_scan_exclusive(&t, &mut g, &r, bd);
            assert_eq!(g.data, [126.0, 124.0, 120.0, 112.0, 96.0, 64.0, 0.0]);
        }
        let mut g = Tile1::<f64, 7>::zeros();
        adj_tile_scan_max_inclusive(&t, &mut g, &r, 1);
        // Maxima: 3 (element 0, the first on the tie at 2), then 5 (element 3, not 6).
        assert_eq!(g.data, [7.0, 0.0, 0.0, 120.0, 0.0, 0.0, 0.0]);
        let mut g = Tile1::<f64, 7>::zeros();
        adj_tile_scan_min_inclusive(&t, &mut g, &r, 1);
        assert_eq!(g.data, [1.0, 126.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        // All NaN so far: the seed goes to element 0, then to the first number.
        let n = Tile1 {
            data: [f64::NAN, f64::NAN, 1.0],
        };
        let mut g = Tile1::<f64, 3>::zeros();
        adj_tile_scan_max_inclusive(
            &n,
            &mut g,
            &Tile1 {
                data: [1.0, 2.0, 4.0],
            },
            1,
        );
        assert_eq!(g.data, [3.0, 0.0, 4.0]);
    }
}

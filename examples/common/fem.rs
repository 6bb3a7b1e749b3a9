//! P1 (linear) finite elements on the unit square and the unit cube, assembled into the sparse
//! tier's block sparse matrices and solved by its conjugate gradients: `-Δu = f` in 2-D and
//! 3-D, and linear elasticity `-div σ(u) = f` in 3-D (`Bsr<DMat3>`, a 3 x 3 block per pair of
//! nodes). Shared by the `fem_poisson` example and the scene tests (tests/suite/scenes.rs
//! includes this file), so that the tests check the very kernels the scene runs.
//!
//! The includer brings the sparse tier into scope as `sparse` (the example: `wp::sparse`; the
//! test suite, whose facade has no `sparse` feature: `warp_runtime::sparse`).
//!
//! **Meshes.** `n` cells per side, the nodes on the grid `(i, j[, k]) / n`, numbered
//! `i + (n + 1) (j + (n + 1) k)`. A square is cut into 2 triangles and a cube into 6
//! tetrahedra (Kuhn's subdivision: one simplex per order of the axes, all sharing the
//! diagonal from the cell's low corner to its high one), so that neighbouring cells' faces
//! match. A kernel finds an element's vertices from its index, so no mesh is stored.
//!
//! **Manufactured solution.** `u = Π sin(π x_i)` (zero on the boundary), so `f = d π² u`; for
//! elasticity `u = c s` with `s` that product and `c = (1, -1/2, 1/4)`, whence
//! `f = 3 π² μ s c - (μ + λ) H(s) c` (`H` the Hessian of `s`).
//!
//! **Dirichlet condition u = 0.** The element kernel drops each stiffness triplet that touches
//! a boundary node: `from_triplets` has no drop, so the triplet is sent to that boundary
//! node's diagonal with the value 0 (adding 0 changes no sum). Each node adds `(i, i, 1)`
//! (elasticity: the identity block) when it is on the boundary, `(i, i, 0)` otherwise, and the
//! boundary's load is 0. So the boundary rows and columns of `A` are the identity's: `A` stays
//! symmetric positive definite, and a boundary unknown is exactly 0 at every CG iterate.
//!
//! **Assembly.** The element kernel writes its `(d + 1)²` stiffness triplets and `d + 1` load
//! triplets; `Bsr::from_triplets` sums the duplicates (in triplet order: the same bits on every
//! device). The load goes through a matrix of one column, whose product with `[1]` is the
//! load vector: the same ordered sums, no float atomics.
//!
//! **Quadrature.** Gauss-Legendre with 4 points per direction collapsed onto the simplex
//! (Duffy): 16 points per triangle, exact for polynomials of degree 6, and 64 per
//! tetrahedron, exact to degree 5. It integrates the load and the squared error, whose
//! quadrature error (O(h^5) and beyond) is then far below the O(h^4) squared L2 error.

#![allow(dead_code)] // the test uses part of it

use std::time::Instant;

use super::sparse::{self, Bsr, Mode, Precond, SolveOptions, Stop};
use warp_lang as wp;
use wp::prelude::*;

/// π, for the kernels (a module const: the CUDA source gets its bits).
const PI: f64 = std::f64::consts::PI;
/// Lamé's first parameter λ of the elastic material.
pub const LAMBDA: f64 = 1.0;
/// The shear modulus μ of the elastic material.
pub const MU: f64 = 1.0;
/// The direction `c` of the elastic manufactured solution `u = c s`.
const C_ELASTIC: DVec3 = DVec3::new(1.0, -0.5, 0.25);

/// Which problem a level solves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Problem {
    /// `-Δu = f` on the unit square, triangles, `Bsr<f64>`.
    Poisson2,
    /// `-Δu = f` on the unit cube, tetrahedra, `Bsr<f64>`.
    Poisson3,
    /// Linear elasticity on the unit cube, tetrahedra, `Bsr<DMat3>`.
    Elasticity,
}

impl Problem {
    /// The space dimension.
    pub fn dim(self) -> usize {
        match self {
            Problem::Poisson2 => 2,
            Problem::Poisson3 | Problem::Elasticity => 3,
        }
    }

    /// Elements per cell (2 triangles, 6 tetrahedra).
    pub fn per_cell(self) -> usize {
        if self.dim() == 2 {
            2
        } else {
            6
        }
    }

    /// Unknowns per node.
    pub fn components(self) -> usize {
        if self == Problem::Elasticity {
            3
        } else {
            1
        }
    }

    /// A short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Problem::Poisson2 => "Poisson 2-D",
            Problem::Poisson3 => "Poisson 3-D",
            Problem::Elasticity => "elasticity 3-D",
        }
    }
}

/// What one level measured.
#[derive(Clone, Debug)]
pub struct Level {
    pub problem: Problem,
    /// Cells per side (h = 1/n).
    pub n: usize,
    /// Scalar unknowns, boundary nodes included (their rows are the identity's).
    pub unknowns: usize,
    /// The L2 error `|u_h - u|` (quadrature per element).
    pub error: f64,
    /// The L2 error of the nodal interpolant of `u` (no solve): the yardstick of `error`.
    pub interp_error: f64,
    /// The CG report.
    pub iterations: usize,
    pub stop: Stop,
    /// Stored blocks of the matrix.
    pub nnz: usize,
    /// Seconds: the element kernels and both assemblies (synchronised).
    pub assembly_s: f64,
    /// Seconds: the CG solve (the capture of its graph and its launch, read-back included).
    pub solve_s: f64,
    /// The solution at the nodes (elasticity: `x[3 node + i]`).
    pub x: wp::Array<f64>,
}

/// The observed order `log2(e_h / e_{h/2})` between a level and the next finer one.
pub fn order(coarse: f64, fine: f64) -> f64 {
    (coarse / fine).log2()
}

/// The quadrature rule on the reference simplex of dimension `dim` (2 or 3): points as
/// `(ξ1, ξ2, ξ3, w)` (ξ3 = 0 in 2-D), weights summing to the simplex's volume (1/2, 1/6).
/// Gauss-Legendre with 4 points per direction on the cube `[0, 1]^dim`, collapsed by
/// `ξ1 = a, ξ2 = b (1 - a), ξ3 = c (1 - a) (1 - b)` (Jacobian `(1 - a)` in 2-D,
/// `(1 - a)² (1 - b)` in 3-D).
pub fn quadrature(dim: usize) -> Vec<DVec4> {
    // Gauss-Legendre, 4 points on [-1, 1].
    const X: [f64; 4] = [
        -0.861_136_311_594_052_6,
        -0.339_981_043_584_856_3,
        0.339_981_043_584_856_3,
        0.861_136_311_594_052_6,
    ];
    const W: [f64; 4] = [
        0.347_854_845_137_453_9,
        0.652_145_154_862_546_1,
        0.652_145_154_862_546_1,
        0.347_854_845_137_453_9,
    ];
    let gl: Vec<(f64, f64)> = X
        .iter()
        .zip(W)
        .map(|(&x, w)| ((1.0 + x) / 2.0, w / 2.0))
        .collect();
    let mut rule = Vec::new();
    for &(a, wa) in &gl {
        for &(b, wb) in &gl {
            if dim == 2 {
                rule.push(DVec4::new(a, b * (1.0 - a), 0.0, wa * wb * (1.0 - a)));
                continue;
            }
            for &(c, wc) in &gl {
                let jac = (1.0 - a) * (1.0 - a) * (1.0 - b);
                rule.push(DVec4::new(
                    a,
                    b * (1.0 - a),
                    c * (1.0 - a) * (1.0 - b),
                    wa * wb * wc * jac,
                ));
            }
        }
    }
    rule
}

// ---- geometry (kernel funcs) ----

/// Axis `j` (0, 1, 2) of the `p`-th order of the three axes (0..6: the first axis `p / 2`,
/// the other two ascending or, for odd `p`, descending).
#[wp::func]
fn axis3(p: i32, j: i32) -> i32 {
    let first = p / 2;
    let r0 = if first == 0 { 1 } else { 0 };
    let r1 = if first == 2 { 1 } else { 2 };
    let second = if p % 2 == 0 { r0 } else { r1 };
    if j == 0 {
        first
    } else if j == 1 {
        second
    } else {
        r0 + r1 - second
    }
}

/// Grid coordinates of vertex `k` (0..3) of triangle `e` of the `n x n` grid: the cell's low
/// corner plus a unit step along the first `k` axes of the triangle's order (x then y, or y
/// then x).
#[wp::func]
fn vertex2(e: i32, k: i32, n: i32) -> IVec2 {
    let cell = e / 2;
    let p = e % 2;
    let mut g = IVec2::new(cell % n, cell / n);
    for j in 0..k {
        let a = if p == 0 { j } else { 1 - j };
        g[a] += 1;
    }
    g
}

/// Grid coordinates of vertex `k` (0..4) of tetrahedron `e` of the `n³` grid (Kuhn).
#[wp::func]
fn vertex3(e: i32, k: i32, n: i32) -> IVec3 {
    let cell = e / 6;
    let p = e % 6;
    let mut g = IVec3::new(cell % n, (cell / n) % n, cell / (n * n));
    for j in 0..k {
        g[axis3(p, j)] += 1;
    }
    g
}

#[wp::func]
fn node2(g: IVec2, n: i32) -> i32 {
    g.x + (n + 1) * g.y
}

#[wp::func]
fn node3(g: IVec3, n: i32) -> i32 {
    g.x + (n + 1) * (g.y + (n + 1) * g.z)
}

#[wp::func]
fn boundary2(g: IVec2, n: i32) -> bool {
    g.x == 0 || g.y == 0 || g.x == n || g.y == n
}

#[wp::func]
fn boundary3(g: IVec3, n: i32) -> bool {
    g.x == 0 || g.y == 0 || g.z == 0 || g.x == n || g.y == n || g.z == n
}

// ---- the manufactured solutions ----

#[wp::func]
fn exact2(x: DVec2) -> f64 {
    (PI * x.x).sin() * (PI * x.y).sin()
}

#[wp::func]
fn exact3(x: DVec3) -> f64 {
    (PI * x.x).sin() * (PI * x.y).sin() * (PI * x.z).sin()
}

/// The elastic displacement `c s(x)`.
#[wp::func]
fn exact_elastic(x: DVec3) -> DVec3 {
    C_ELASTIC * exact3(x)
}

/// The elastic body force `3 π² μ s c - (μ + λ) H(s) c`.
#[wp::func]
fn force_elastic(x: DVec3) -> DVec3 {
    let sx = (PI * x.x).sin();
    let sy = (PI * x.y).sin();
    let sz = (PI * x.z).sin();
    let cx = (PI * x.x).cos();
    let cy = (PI * x.y).cos();
    let cz = (PI * x.z).cos();
    let s = sx * sy * sz;
    let p2 = PI * PI;
    let hxy = p2 * cx * cy * sz;
    let hxz = p2 * cx * sy * cz;
    let hyz = p2 * sx * cy * cz;
    let hess = DMat3::from_cols(
        DVec3::new(-p2 * s, hxy, hxz),
        DVec3::new(hxy, -p2 * s, hyz),
        DVec3::new(hxz, hyz, -p2 * s),
    );
    C_ELASTIC * (3.0 * p2 * MU * s) - (hess * C_ELASTIC) * (MU + LAMBDA)
}

// ---- kernels ----

/// One thread per triangle: its 9 stiffness triplets at `9 e ..` and its 3 load triplets at
/// `3 e ..` (row = node; the load matrix has one column), the Dirichlet rows dropped.
#[wp::kernel]
pub fn poisson2_element(
    n: i32,
    quad: Array<DVec4>,
    nq: i32,
    rows: Array<i32>,
    cols: Array<i32>,
    vals: Array<f64>,
    load_rows: Array<i32>,
    load_vals: Array<f64>,
) {
    let e = tid() as i32;
    let h = 1.0 / (n as f64);
    let mut id = [0i32; 3];
    let mut bnd = [false; 3];
    let mut p = [DVec2::ZERO; 3];
    for k in 0..3 {
        let g = vertex2(e, k, n);
        id[k] = node2(g, n);
        bnd[k] = boundary2(g, n);
        p[k] = DVec2::new(g.x as f64, g.y as f64) * h;
    }
    let jac = DMat2::from_cols(p[1] - p[0], p[2] - p[0]);
    let det = determinant(jac).abs();
    let jit = transpose(inverse(jac));
    let mut grad = [DVec2::ZERO; 3];
    grad[1] = jit * DVec2::X;
    grad[2] = jit * DVec2::Y;
    grad[0] = -(grad[1] + grad[2]);
    let area = det * 0.5;
    for a in 0..3 {
        for b in 0..3 {
            let t = 9 * e + 3 * a + b;
            if bnd[a] || bnd[b] {
                let d = if bnd[a] { id[a] } else { id[b] };
                rows[t] = d;
                cols[t] = d;
                vals[t] = 0.0;
            } else {
                rows[t] = id[a];
                cols[t] = id[b];
                vals[t] = area * dot(grad[a], grad[b]);
            }
        }
    }
    // The load ∫ f φ_a: f = 2 π² u.
    let mut f = [0.0f64; 3];
    for q in 0..nq {
        let r = quad[q];
        let lam = [1.0 - r.x - r.y, r.x, r.y];
        let x = p[0] + (p[1] - p[0]) * r.x + (p[2] - p[0]) * r.y;
        let fx = 2.0 * PI * PI * exact2(x) * r.w * det;
        for a in 0..3 {
            f[a] += fx * lam[a];
        }
    }
    for a in 0..3 {
        load_rows[3 * e + a] = id[a];
        load_vals[3 * e + a] = if bnd[a] { 0.0 } else { f[a] };
    }
}

/// One thread per tetrahedron: 16 stiffness triplets at `16 e ..`, 4 load triplets at
/// `4 e ..`.
#[wp::kernel]
pub fn poisson3_element(
    n: i32,
    quad: Array<DVec4>,
    nq: i32,
    rows: Array<i32>,
    cols: Array<i32>,
    vals: Array<f64>,
    load_rows: Array<i32>,
    load_vals: Array<f64>,
) {
    let e = tid() as i32;
    let h = 1.0 / (n as f64);
    let mut id = [0i32; 4];
    let mut bnd = [false; 4];
    let mut p = [DVec3::ZERO; 4];
    for k in 0..4 {
        let g = vertex3(e, k, n);
        id[k] = node3(g, n);
        bnd[k] = boundary3(g, n);
        p[k] = DVec3::new(g.x as f64, g.y as f64, g.z as f64) * h;
    }
    let jac = DMat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]);
    let det = determinant(jac).abs();
    let jit = transpose(inverse(jac));
    let mut grad = [DVec3::ZERO; 4];
    grad[1] = jit * DVec3::X;
    grad[2] = jit * DVec3::Y;
    grad[3] = jit * DVec3::Z;
    grad[0] = -(grad[1] + grad[2] + grad[3]);
    let vol = det / 6.0;
    for a in 0..4 {
        for b in 0..4 {
            let t = 16 * e + 4 * a + b;
            if bnd[a] || bnd[b] {
                let d = if bnd[a] { id[a] } else { id[b] };
                rows[t] = d;
                cols[t] = d;
                vals[t] = 0.0;
            } else {
                rows[t] = id[a];
                cols[t] = id[b];
                vals[t] = vol * dot(grad[a], grad[b]);
            }
        }
    }
    // The load ∫ f φ_a: f = 3 π² u.
    let mut f = [0.0f64; 4];
    for q in 0..nq {
        let r = quad[q];
        let lam = [1.0 - r.x - r.y - r.z, r.x, r.y, r.z];
        let x = p[0] + (p[1] - p[0]) * r.x + (p[2] - p[0]) * r.y + (p[3] - p[0]) * r.z;
        let fx = 3.0 * PI * PI * exact3(x) * r.w * det;
        for a in 0..4 {
            f[a] += fx * lam[a];
        }
    }
    for a in 0..4 {
        load_rows[4 * e + a] = id[a];
        load_vals[4 * e + a] = if bnd[a] { 0.0 } else { f[a] };
    }
}

/// One thread per tetrahedron: 16 block triplets (3 x 3: `vol (μ (g_a . g_b) I + μ g_b g_aᵀ
/// + λ g_a g_bᵀ)`) at `16 e ..`, 12 scalar load triplets at `12 e ..` (row `3 node + i`).
#[wp::kernel]
pub fn elastic_element(
    n: i32,
    quad: Array<DVec4>,
    nq: i32,
    rows: Array<i32>,
    cols: Array<i32>,
    vals: Array<DMat3>,
    load_rows: Array<i32>,
    load_vals: Array<f64>,
) {
    let e = tid() as i32;
    let h = 1.0 / (n as f64);
    let mut id = [0i32; 4];
    let mut bnd = [false; 4];
    let mut p = [DVec3::ZERO; 4];
    for k in 0..4 {
        let g = vertex3(e, k, n);
        id[k] = node3(g, n);
        bnd[k] = boundary3(g, n);
        p[k] = DVec3::new(g.x as f64, g.y as f64, g.z as f64) * h;
    }
    let jac = DMat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]);
    let det = determinant(jac).abs();
    let jit = transpose(inverse(jac));
    let mut grad = [DVec3::ZERO; 4];
    grad[1] = jit * DVec3::X;
    grad[2] = jit * DVec3::Y;
    grad[3] = jit * DVec3::Z;
    grad[0] = -(grad[1] + grad[2] + grad[3]);
    let vol = det / 6.0;
    for a in 0..4 {
        for b in 0..4 {
            let t = 16 * e + 4 * a + b;
            if bnd[a] || bnd[b] {
                let d = if bnd[a] { id[a] } else { id[b] };
                rows[t] = d;
                cols[t] = d;
                vals[t] = DMat3::ZERO;
            } else {
                let ga = grad[a];
                let gb = grad[b];
                let k = DMat3::IDENTITY * (MU * dot(ga, gb))
                    + outer(gb, ga) * MU
                    + outer(ga, gb) * LAMBDA;
                rows[t] = id[a];
                cols[t] = id[b];
                vals[t] = k * vol;
            }
        }
    }
    let mut f = [DVec3::ZERO; 4];
    for q in 0..nq {
        let r = quad[q];
        let lam = [1.0 - r.x - r.y - r.z, r.x, r.y, r.z];
        let x = p[0] + (p[1] - p[0]) * r.x + (p[2] - p[0]) * r.y + (p[3] - p[0]) * r.z;
        let fx = force_elastic(x) * (r.w * det);
        for a in 0..4 {
            f[a] += fx * lam[a];
        }
    }
    for a in 0..4 {
        for i in 0..3 {
            load_rows[12 * e + 3 * a + i] = 3 * id[a] + i;
            load_vals[12 * e + 3 * a + i] = if bnd[a] { 0.0 } else { f[a][i] };
        }
    }
}

/// One thread per node: the Dirichlet diagonal `(i, i, 1)` on the boundary, `(i, i, 0)`
/// inside, at `offset + i` (`dim` 2 or 3).
#[wp::kernel]
pub fn node_diagonal(
    n: i32,
    dim: i32,
    offset: i32,
    rows: Array<i32>,
    cols: Array<i32>,
    vals: Array<f64>,
) {
    let i = tid() as i32;
    let m = n + 1;
    let on = if dim == 2 {
        boundary2(IVec2::new(i % m, i / m), n)
    } else {
        boundary3(IVec3::new(i % m, (i / m) % m, i / (m * m)), n)
    };
    rows[offset + i] = i;
    cols[offset + i] = i;
    vals[offset + i] = if on { 1.0 } else { 0.0 };
}

/// [`node_diagonal`] for 3 x 3 blocks: the identity block on the boundary, zero inside.
#[wp::kernel]
pub fn node_diagonal_block(
    n: i32,
    offset: i32,
    rows: Array<i32>,
    cols: Array<i32>,
    vals: Array<DMat3>,
) {
    let i = tid() as i32;
    let m = n + 1;
    let on = boundary3(IVec3::new(i % m, (i / m) % m, i / (m * m)), n);
    rows[offset + i] = i;
    cols[offset + i] = i;
    vals[offset + i] = if on { DMat3::IDENTITY } else { DMat3::ZERO };
}

/// The nodal interpolant of the exact solution: one thread per node, `dim` 2 or 3, `comps`
/// 1 (Poisson) or 3 (elasticity, `x[3 i + c]`).
#[wp::kernel]
pub fn interpolate(n: i32, dim: i32, comps: i32, x: Array<f64>) {
    let i = tid() as i32;
    let m = n + 1;
    let h = 1.0 / (n as f64);
    if dim == 2 {
        let p = DVec2::new((i % m) as f64, (i / m) as f64) * h;
        x[i] = exact2(p);
    } else {
        let p = DVec3::new((i % m) as f64, ((i / m) % m) as f64, (i / (m * m)) as f64) * h;
        if comps == 1 {
            x[i] = exact3(p);
        } else {
            let u = exact_elastic(p);
            for c in 0..3 {
                x[3 * i + c] = u[c];
            }
        }
    }
}

/// One thread per triangle: `err[e] = sqrt(∫_e (u_h - u)²)` (the square root so that the
/// total is `dot(err, err)`, the tier's fixed-order sum).
#[wp::kernel]
pub fn poisson2_error(n: i32, quad: Array<DVec4>, nq: i32, x: Array<f64>, err: Array<f64>) {
    let e = tid() as i32;
    let h = 1.0 / (n as f64);
    let mut uh = [0.0f64; 3];
    let mut p = [DVec2::ZERO; 3];
    for k in 0..3 {
        let g = vertex2(e, k, n);
        uh[k] = x[node2(g, n)];
        p[k] = DVec2::new(g.x as f64, g.y as f64) * h;
    }
    let det = determinant(DMat2::from_cols(p[1] - p[0], p[2] - p[0])).abs();
    let mut s = 0.0f64;
    for q in 0..nq {
        let r = quad[q];
        let xq = p[0] + (p[1] - p[0]) * r.x + (p[2] - p[0]) * r.y;
        let v = uh[0] * (1.0 - r.x - r.y) + uh[1] * r.x + uh[2] * r.y;
        let d = v - exact2(xq);
        s += d * d * r.w * det;
    }
    err[e] = s.sqrt();
}

/// [`poisson2_error`] on tetrahedra, `comps` 1 (Poisson) or 3 (elasticity: `|u_h - u|²`).
#[wp::kernel]
pub fn tet_error(n: i32, comps: i32, quad: Array<DVec4>, nq: i32, x: Array<f64>, err: Array<f64>) {
    let e = tid() as i32;
    let h = 1.0 / (n as f64);
    let mut uh = [DVec3::ZERO; 4];
    let mut p = [DVec3::ZERO; 4];
    for k in 0..4 {
        let g = vertex3(e, k, n);
        let id = node3(g, n);
        if comps == 1 {
            uh[k] = DVec3::new(x[id], 0.0, 0.0);
        } else {
            uh[k] = DVec3::new(x[3 * id], x[3 * id + 1], x[3 * id + 2]);
        }
        p[k] = DVec3::new(g.x as f64, g.y as f64, g.z as f64) * h;
    }
    let det = determinant(DMat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0])).abs();
    let mut s = 0.0f64;
    for q in 0..nq {
        let r = quad[q];
        let xq = p[0] + (p[1] - p[0]) * r.x + (p[2] - p[0]) * r.y + (p[3] - p[0]) * r.z;
        let v = uh[0] * (1.0 - r.x - r.y - r.z) + uh[1] * r.x + uh[2] * r.y + uh[3] * r.z;
        let u = if comps == 1 {
            DVec3::new(exact3(xq), 0.0, 0.0)
        } else {
            exact_elastic(xq)
        };
        let d = v - u;
        s += dot(d, d) * r.w * det;
    }
    err[e] = s.sqrt();
}

// ---- the host side ----

/// The assembled system of one level: the matrix (scalar or 3 x 3 blocks) and the load.
enum System {
    Scalar(Bsr<f64>),
    Block(Bsr<DMat3>),
}

/// The L2 error of the nodal vector `x` (the solution or the interpolant): the error kernel,
/// then the tier's ordered dot of the per-element roots.
fn l2_error(
    problem: Problem,
    n: usize,
    quad: &wp::Array<DVec4>,
    x: &wp::Array<f64>,
    dev: &wp::Device,
) -> wp::Result<f64> {
    let elements = n.pow(problem.dim() as u32) * problem.per_cell();
    let err = wp::Array::<f64>::zeros(elements, dev)?;
    let out = wp::Array::<f64>::zeros(1, dev)?;
    let nq = quad.len() as i32;
    let ni = n as i32;
    match problem {
        Problem::Poisson2 => wp::launch(poisson2_error, elements, (ni, quad, nq, x, &err), dev)?,
        _ => {
            let comps = problem.components() as i32;
            wp::launch(tet_error, elements, (ni, comps, quad, nq, x, &err), dev)?;
        }
    }
    sparse::dot(&err, &err, &out)?;
    Ok(out.to_vec()?[0].sqrt())
}

/// Solves one level of `problem` with `n` cells per side on `dev`: assembles, solves by CG
/// with block Jacobi (`options`, whose mode is used as given) from zero, and measures the
/// L2 errors of the solution and of the interpolant.
pub fn solve_level(
    problem: Problem,
    n: usize,
    options: &SolveOptions,
    dev: &wp::Device,
) -> wp::Result<Level> {
    if n < 1 {
        return Err(wp::Error::InvalidArgument {
            what: format!("fem::solve_level: `n` (cells per side) must be at least 1, got {n}"),
        });
    }
    let dim = problem.dim();
    let per = dim + 1; // vertices per element
    let comps = problem.components();
    // The kernels index with i32: every triplet, node and unknown index must fit (f64 holds
    // these counts exactly near i32::MAX, and cannot overflow).
    let (nf, d) = (n as f64, dim as i32);
    let (nodes_f, elements_f) = ((nf + 1.0).powi(d), nf.powi(d) * problem.per_cell() as f64);
    let (per_f, comps_f) = (per as f64, comps as f64);
    let largest = (elements_f * per_f * per_f + nodes_f)
        .max(elements_f * per_f * comps_f)
        .max(nodes_f * comps_f);
    let fits = largest <= i32::MAX as f64;
    if !fits {
        return Err(wp::Error::InvalidArgument {
            what: format!(
                "fem::solve_level: `n` = {n} cells per side is too fine for {}: its triplets \
                 would not fit i32 indices",
                problem.name()
            ),
        });
    }
    let nodes = (n + 1).pow(dim as u32);
    let elements = n.pow(dim as u32) * problem.per_cell();
    let unknowns = nodes * comps;
    let quad = wp::Array::from_slice(&quadrature(dim), dev)?;
    let nq = quad.len() as i32;
    let ni = n as i32;

    wp::synchronize()?;
    let t = Instant::now();
    let triplets = elements * per * per + nodes;
    let offset = (elements * per * per) as i32;
    let rows = wp::Array::<i32>::zeros(triplets, dev)?;
    let cols = wp::Array::<i32>::zeros(triplets, dev)?;
    let load_count = elements * per * comps;
    let load_rows = wp::Array::<i32>::zeros(load_count, dev)?;
    let load_cols = wp::Array::<i32>::zeros(load_count, dev)?;
    let load_vals = wp::Array::<f64>::zeros(load_count, dev)?;
    let system = match problem {
        Problem::Poisson2 | Problem::Poisson3 => {
            let vals = wp::Array::<f64>::zeros(triplets, dev)?;
            let args = (ni, &quad, nq, &rows, &cols, &vals, &load_rows, &load_vals);
            if problem == Problem::Poisson2 {
                wp::launch(poisson2_element, elements, args, dev)?;
            } else {
                wp::launch(poisson3_element, elements, args, dev)?;
            }
            let d = dim as i32;
            wp::launch(
                node_diagonal,
                nodes,
                (ni, d, offset, &rows, &cols, &vals),
                dev,
            )?;
            System::Scalar(Bsr::from_triplets(nodes, nodes, &rows, &cols, &vals)?)
        }
        Problem::Elasticity => {
            let vals = wp::Array::<DMat3>::zeros(triplets, dev)?;
            let args = (ni, &quad, nq, &rows, &cols, &vals, &load_rows, &load_vals);
            wp::launch(elastic_element, elements, args, dev)?;
            let diag_args = (ni, offset, &rows, &cols, &vals);
            wp::launch(node_diagonal_block, nodes, diag_args, dev)?;
            System::Block(Bsr::from_triplets(nodes, nodes, &rows, &cols, &vals)?)
        }
    };
    // The load vector: the one-column matrix of the load triplets times [1].
    let load = Bsr::from_triplets(unknowns, 1, &load_rows, &load_cols, &load_vals)?;
    let one = wp::Array::from_slice(&[1.0f64], dev)?;
    let b = wp::Array::<f64>::zeros(unknowns, dev)?;
    sparse::mv(1.0, &load, &one, 0.0, &b)?;
    wp::synchronize()?;
    let assembly_s = t.elapsed().as_secs_f64();
    // The triplets are no longer needed (at the finest levels they are most of the memory).
    drop((rows, cols, load_rows, load_cols, load_vals, load));

    let x = wp::Array::<f64>::zeros(unknowns, dev)?;
    let t = Instant::now();
    let report = match &system {
        System::Scalar(a) => sparse::cg(a, &b, &x, Precond::Jacobi, options)?,
        System::Block(a) => sparse::cg(a, &b, &x, Precond::Jacobi, options)?,
    };
    let solve_s = t.elapsed().as_secs_f64();
    let nnz = match &system {
        System::Scalar(a) => a.nnz()?,
        System::Block(a) => a.nnz()?,
    };
    let error = l2_error(problem, n, &quad, &x, dev)?;
    let interp = wp::Array::<f64>::zeros(unknowns, dev)?;
    let (d, c) = (dim as i32, comps as i32);
    wp::launch(interpolate, nodes, (ni, d, c, &interp), dev)?;
    let interp_error = l2_error(problem, n, &quad, &interp, dev)?;
    Ok(Level {
        problem,
        n,
        unknowns,
        error,
        interp_error,
        iterations: report.iterations,
        stop: report.stop,
        nnz,
        assembly_s,
        solve_s,
        x,
    })
}

/// The solver options of the scene: f64 CG to `rtol` (its algebraic error, about
/// `rtol / (d π²)` in L2 at worst, far below the discretisation error), at most `max_iter`
/// iterations, captured ([`Mode::Graph`]) with a check every 50 iterations.
pub fn options(rtol: f64, max_iter: usize) -> SolveOptions {
    SolveOptions {
        rtol,
        max_iter,
        check_every: 50,
        mode: Mode::Graph,
        ..SolveOptions::default()
    }
}

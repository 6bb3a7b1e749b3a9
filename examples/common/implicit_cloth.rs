//! A mass-spring cloth integrated three ways: semi-implicit Euler (explicit), XPBD by colour,
//! and backward Euler by Newton's method on a `Bsr<Mat3>` solved by the sparse tier's
//! conjugate gradients. The kernels, the scene's set-up, its f64 reference (classical
//! Runge-Kutta on the host) and the run driver, shared by the `implicit_cloth` example and the
//! scene tests (tests/suite/scenes.rs includes this file), so that the tests check the very
//! kernels the scene runs.
//!
//! The includer brings the sparse tier into scope as `sparse` (the example: `wp::sparse`; the
//! test suite, whose facade has no `sparse` feature: `warp_runtime::sparse`).
//!
//! **The cloth** (examples/cloth.rs's): 1 m x 1 m, 0.2 kg, an n x n grid of particles in the
//! plane y = 0 (particle `r n + c` at `(c, 0, r) s`, s = 1 / (n - 1)), joined by structural
//! springs (to the 4 nearest neighbours, stiffness k), shear springs (the 4 diagonals, k) and
//! bending springs (2 apart along the grid, k / 20), optionally damped along each spring
//! (`kd`). The corners `(0, 0)` and `(0, n - 1)` are held (particles 0 and n - 1). It is
//! released at rest, flat, and falls under gravity (-y).
//!
//! **Backward Euler.** `v1 = v0 + dv`, `x1 = x0 + h v1`, `M dv = h f(x1, v1)`. Newton on the
//! residual `g(dv) = h f(x0 + h v, v) - M dv` (`v = v0 + dv`): each iteration solves
//! `(M - h D - h² K) δ = g` and adds `δ` to `dv`, with `K = ∂f/∂x` and `D = ∂f/∂v` at the
//! current iterate. The first iteration is Baraff and Witkin's: it linearises `f` about `x0`
//! instead, `(M - h D - h² K(x0)) dv = h (f(x0, v0) + h K(x0) v0)`. A spring's stiffness block
//! is `k u uᵀ + k max(0, 1 - L / |d|) (I - u uᵀ)` (u the unit direction, L the rest length):
//! its transverse term is negative under compression and clamped to 0 there, so every block is
//! positive semi-definite, `A = M - h D - h² K` is symmetric positive definite, and CG with
//! block Jacobi applies (the clamp makes the later iterations quasi-Newton under compression).
//! The damping block is `kd u uᵀ` (the damping force's derivative in x is left out).
//!
//! **The matrix.** Its pattern (a block per particle and per spring, both ways) is built once
//! from the springs by `Bsr::from_triplets`; each iteration one thread per particle iterates its
//! row (`for s in bsr_row(a, i)`): a column `j` is a neighbour, whose grid offset names the
//! spring (kind and rest length); it writes the off-diagonal blocks and then the diagonal with
//! `bsr_set_block`, and the right-hand side. Each row is written by its own thread, so the
//! values are the same bits on every schedule (no `bsr_add_block`, no float atomics). A held
//! particle's row and column are `m I` on the diagonal and zero elsewhere, its right-hand
//! side 0, so its velocity stays 0 and `A` stays symmetric.

#![allow(dead_code)] // the test uses part of it

use std::ops::Range;
use std::time::Instant;

use super::sparse::{self, Adjacency, Bsr, Coloring, Mode, Precond, SolveOptions, Stop};
use warp_lang as wp;
use wp::prelude::*;

/// The cloth's side (m).
pub const SIZE: f64 = 1.0;
/// The cloth's mass (kg), spread evenly over its particles.
pub const TOTAL_MASS: f64 = 0.2;
/// Gravity (m/s², along -y).
pub const G: f64 = 9.81;
/// Bending springs are this much softer than the structural and shear ones.
pub const BEND_RATIO: f64 = 0.05;
/// The divergence guard: a spring stretched past this many rest lengths has blown up.
pub const STRETCH_LIMIT: f64 = 2.0;

// ---- kernel funcs ----

/// The grid offset `(dr, dc)` of neighbour `o` (0..12): 4 structural, 4 shear, 4 bending.
#[wp::func]
fn offset(o: i32) -> IVec2 {
    let mut d = IVec2::new(0, 1);
    if o == 1 {
        d = IVec2::new(0, -1);
    } else if o == 2 {
        d = IVec2::new(1, 0);
    } else if o == 3 {
        d = IVec2::new(-1, 0);
    } else if o == 4 {
        d = IVec2::new(1, 1);
    } else if o == 5 {
        d = IVec2::new(1, -1);
    } else if o == 6 {
        d = IVec2::new(-1, 1);
    } else if o == 7 {
        d = IVec2::new(-1, -1);
    } else if o == 8 {
        d = IVec2::new(0, 2);
    } else if o == 9 {
        d = IVec2::new(0, -2);
    } else if o == 10 {
        d = IVec2::new(2, 0);
    } else if o == 11 {
        d = IVec2::new(-2, 0);
    }
    d
}

/// The stiffness of the spring along grid offset `d`: `k.x` structural, `k.y` shear, `k.z`
/// bending.
#[wp::func]
fn stiffness(d: IVec2, k: Vec3) -> f32 {
    let ar = if d.x < 0 { -d.x } else { d.x };
    let ac = if d.y < 0 { -d.y } else { d.y };
    let mut s = k.z;
    if ar + ac == 1 {
        s = k.x;
    } else if ar == 1 {
        s = k.y;
    }
    s
}

/// The rest length of the spring along grid offset `d`, grid spacing `spacing`.
#[wp::func]
fn rest_length(d: IVec2, spacing: f32) -> f32 {
    spacing * sqrt((d.x * d.x + d.y * d.y) as f32)
}

/// Whether particle `i` of an `n x n` cloth is held: the corners of row 0.
#[wp::func]
fn held(i: i32, n: i32) -> bool {
    i == 0 || i == n - 1
}

/// The force on a particle at `xi` (velocity `vi`) from the spring to `xj` (`vj`) of stiffness
/// `k`, rest length `rest` and damping `kd`: `(k (|d| - rest) + kd (vj - vi) . u) u`.
#[wp::func]
fn spring_force(xi: Vec3, xj: Vec3, vi: Vec3, vj: Vec3, k: f32, rest: f32, kd: f32) -> Vec3 {
    let d = xj - xi;
    let len = length(d);
    let u = d / len;
    u * (k * (len - rest) + kd * dot(vj - vi, u))
}

// ---- kernels ----

/// One semi-implicit Euler step, a thread per particle: `v1 = v + h f(x, v) / m`,
/// `x1 = x + h v1` (reads one state, writes the other; the caller swaps them). `k`: the
/// (structural, shear, bending) stiffness.
#[wp::kernel]
pub fn euler_step(
    x: Array<Vec3>,
    v: Array<Vec3>,
    x1: Array<Vec3>,
    v1: Array<Vec3>,
    n: i32,
    spacing: f32,
    k: Vec3,
    kd: f32,
    mass: f32,
    gravity: Vec3,
    h: f32,
) {
    let i = tid() as i32;
    if held(i, n) {
        x1[i] = x[i];
        v1[i] = Vec3::ZERO;
    } else {
        let r = i / n;
        let c = i % n;
        let xi = x[i];
        let vi = v[i];
        let mut f = gravity * mass;
        for o in 0..12 {
            let d = offset(o);
            let rr = r + d.x;
            let cc = c + d.y;
            if rr >= 0 && rr < n && cc >= 0 && cc < n {
                let j = rr * n + cc;
                let ks = stiffness(d, k);
                let rest = rest_length(d, spacing);
                f += spring_force(xi, x[j], vi, v[j], ks, rest, kd);
            }
        }
        let vn = vi + f * (h / mass);
        v1[i] = vn;
        x1[i] = xi + vn * h;
    }
}

/// Backward Euler, one Newton iteration's system, a thread per particle writing its row of `a`
/// (pattern fixed) and `rhs[i]`. With `first` = 1, Baraff-Witkin's linearisation about `x0`:
/// `A = M - h D - h² K(x0)`, `rhs = h (f(x0, v0) + h K(x0) v0)` (v = v0 then); with `first` = 0,
/// Newton at the iterate `v`: `A` at `x0 + h v`, `rhs = h f(x0 + h v, v) - M (v - v0)`.
#[wp::kernel]
pub fn be_assemble(
    a: Bsr<Mat3>,
    x0: Array<Vec3>,
    v0: Array<Vec3>,
    v: Array<Vec3>,
    rhs: Array<Vec3>,
    n: i32,
    spacing: f32,
    k: Vec3,
    kd: f32,
    mass: f32,
    gravity: Vec3,
    h: f32,
    first: i32,
) {
    let i = tid() as i32;
    let r = i / n;
    let c = i % n;
    // Where the forces are evaluated: x0 for Baraff-Witkin's step, x0 + h v for Newton's.
    let w = if first == 1 { 0.0 } else { h };
    let xi = x0[i] + v[i] * w;
    let vi = v[i];
    let own = held(i, n);
    let mut f = gravity * mass;
    let mut kv = Vec3::ZERO;
    let mut diag = Mat3::IDENTITY * mass;
    let mut kdiag = -1;
    for s in bsr_row(a, i) {
        let j = bsr_col(a, s);
        if j == i {
            kdiag = s;
        } else {
            let xj = x0[j] + v[j] * w;
            let vj = v[j];
            let d = IVec2::new(j / n - r, j % n - c);
            let ks = stiffness(d, k);
            let rest = rest_length(d, spacing);
            f += spring_force(xi, xj, vi, vj, ks, rest, kd);
            let e = xj - xi;
            let len = length(e);
            let u = e / len;
            let uu = outer(u, u);
            // The transverse term, clamped to 0 under compression (PSD).
            let t = ks * max(1.0 - rest / len, 0.0);
            let hs = uu * (ks - t) + Mat3::IDENTITY * t;
            let blk = hs * (h * h) + uu * (kd * h);
            diag += blk;
            kv += hs * (vj - vi);
            if own || held(j, n) {
                bsr_set_block(a, s, Mat3::ZERO);
            } else {
                bsr_set_block(a, s, -blk);
            }
        }
    }
    if own {
        bsr_set_block(a, kdiag, Mat3::IDENTITY * mass);
        rhs[i] = Vec3::ZERO;
    } else {
        bsr_set_block(a, kdiag, diag);
        if first == 1 {
            rhs[i] = (f + kv * h) * h;
        } else {
            rhs[i] = f * h - (vi - v0[i]) * mass;
        }
    }
}

/// Backward Euler: `v += δ` (a thread per particle).
#[wp::kernel]
pub fn be_update(v: Array<Vec3>, delta: Array<Vec3>) {
    let i = tid();
    v[i] = v[i] + delta[i];
}

/// Backward Euler's positions `x = x0 + h v` (in place: `x` holds x0 until the last Newton
/// iteration).
#[wp::kernel]
pub fn be_positions(x: Array<Vec3>, v: Array<Vec3>, h: f32) {
    let i = tid();
    x[i] = x[i] + v[i] * h;
}

/// Copies `v` to `v0` (the step's start velocities).
#[wp::kernel]
pub fn copy_vec3(src: Array<Vec3>, dst: Array<Vec3>) {
    let i = tid();
    dst[i] = src[i];
}

/// XPBD by colour, part 1 of a substep: a thread per particle keeps its position in `x_prev`
/// and predicts under gravity; the held corners stay.
#[wp::kernel]
pub fn xpbd_predict(
    x: Array<Vec3>,
    v: Array<Vec3>,
    x_prev: Array<Vec3>,
    n: i32,
    gravity: Vec3,
    h: f32,
) {
    let i = tid() as i32;
    let xi = x[i];
    x_prev[i] = xi;
    if !held(i, n) {
        x[i] = xi + (v[i] + gravity * h) * h;
    }
}

/// XPBD: the multipliers to 0 (a thread per spring), at the start of a substep.
#[wp::kernel]
pub fn xpbd_zero(lambda: Array<f32>) {
    lambda[tid()] = 0.0;
}

/// XPBD by colour, part 2: a thread per spring of one colour (`order[start + tid]`) projects
/// it with compliance `1 / (k h²)`. The springs of a colour share no particle, so the threads
/// write disjoint particles; the colours run one after another.
#[wp::kernel]
pub fn xpbd_project_colour(
    x: Array<Vec3>,
    lambda: Array<f32>,
    springs: Array<IVec2>,
    rest: Array<f32>,
    stiff: Array<f32>,
    order: Array<i32>,
    start: i32,
    n: i32,
    inv_mass: f32,
    h: f32,
) {
    let s = order[start + tid() as i32];
    let e = springs[s];
    let wa = if held(e.x, n) { 0.0 } else { inv_mass };
    let wb = if held(e.y, n) { 0.0 } else { inv_mass };
    let alpha = 1.0 / (stiff[s] * h * h);
    let a = x[e.x];
    let b = x[e.y];
    let d = b - a;
    let len = length(d);
    let l = lambda[s];
    let dl = (rest[s] - len - alpha * l) / (wa + wb + alpha);
    lambda[s] = l + dl;
    let u = d / len;
    x[e.x] = a - u * (wa * dl);
    x[e.y] = b + u * (wb * dl);
}

/// XPBD by colour, part 3: velocities from the change in position (a thread per particle).
#[wp::kernel]
pub fn xpbd_velocity(x: Array<Vec3>, v: Array<Vec3>, x_prev: Array<Vec3>, h: f32) {
    let i = tid();
    v[i] = (x[i] - x_prev[i]) / h;
}

// ---- the host side ----

/// The cloth's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Particles per side (at least 3, so that bending springs exist).
    pub n: usize,
    /// Structural and shear stiffness (N/m); bending is `BEND_RATIO` of it.
    pub k: f64,
    /// Damping along each spring (N s/m).
    pub kd: f64,
}

/// One spring: particles `a < b`, stiffness and rest length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    pub a: usize,
    pub b: usize,
    pub k: f64,
    pub rest: f64,
}

impl Params {
    /// The grid spacing (m).
    pub fn spacing(&self) -> f64 {
        SIZE / (self.n - 1) as f64
    }

    /// The mass of a particle (kg).
    pub fn mass(&self) -> f64 {
        TOTAL_MASS / (self.n * self.n) as f64
    }

    /// Particles.
    pub fn particles(&self) -> usize {
        self.n * self.n
    }

    /// The (structural, shear, bending) stiffness.
    pub fn stiffnesses(&self) -> DVec3 {
        DVec3::new(self.k, self.k, self.k * BEND_RATIO)
    }

    /// Whether particle `i` is held.
    pub fn held(&self, i: usize) -> bool {
        i == 0 || i == self.n - 1
    }

    /// The springs, each once (`a < b`), in the kernels' neighbour order of the lower particle.
    pub fn springs(&self) -> Vec<Spring> {
        let n = self.n as i64;
        let ks = self.stiffnesses();
        // The offsets with a positive linear index step: each spring once.
        let offsets = [
            (0, 1, ks.x),
            (1, 0, ks.x),
            (1, 1, ks.y),
            (1, -1, ks.y),
            (0, 2, ks.z),
            (2, 0, ks.z),
        ];
        let mut out = Vec::new();
        for r in 0..n {
            for c in 0..n {
                for &(dr, dc, k) in &offsets {
                    let (rr, cc) = (r + dr, c + dc);
                    if (0..n).contains(&rr) && (0..n).contains(&cc) {
                        out.push(Spring {
                            a: (r * n + c) as usize,
                            b: (rr * n + cc) as usize,
                            k,
                            rest: self.spacing() * ((dr * dr + dc * dc) as f64).sqrt(),
                        });
                    }
                }
            }
        }
        out
    }

    /// The start state: flat in y = 0, at rest.
    pub fn start(&self) -> Vec<DVec3> {
        let s = self.spacing();
        (0..self.particles())
            .map(|i| DVec3::new((i % self.n) as f64 * s, 0.0, (i / self.n) as f64 * s))
            .collect()
    }

    /// Total energy (kinetic, gravitational, elastic), in f64.
    pub fn energy(&self, springs: &[Spring], x: &[DVec3], v: &[DVec3]) -> f64 {
        let m = self.mass();
        let kinetic: f64 = v.iter().map(|v| 0.5 * m * v.length_squared()).sum();
        let gravity: f64 = x.iter().map(|x| m * G * x.y).sum();
        let elastic: f64 = springs
            .iter()
            .map(|s| 0.5 * s.k * ((x[s.b] - x[s.a]).length() - s.rest).powi(2))
            .sum();
        kinetic + gravity + elastic
    }

    /// The energy scale drifts are measured against: the cloth falling its own size.
    pub fn energy_scale(&self) -> f64 {
        TOTAL_MASS * G * SIZE
    }

    /// The largest ratio of a spring's length to its rest length (NaN for a non-finite state).
    pub fn max_stretch(&self, springs: &[Spring], x: &[DVec3]) -> f64 {
        springs
            .iter()
            .map(|s| (x[s.b] - x[s.a]).length() / s.rest)
            .fold(
                0.0,
                |a: f64, b| if b.is_nan() { f64::NAN } else { a.max(b) },
            )
    }

    /// Forces at (x, v), in f64 (held particles' forces are not used).
    fn forces(&self, springs: &[Spring], x: &[DVec3], v: &[DVec3], out: &mut [DVec3]) {
        let gravity = DVec3::new(0.0, -G * self.mass(), 0.0);
        out.fill(gravity);
        for s in springs {
            let d = x[s.b] - x[s.a];
            let len = d.length();
            let u = d / len;
            let f = u * (s.k * (len - s.rest) + self.kd * (v[s.b] - v[s.a]).dot(u));
            out[s.a] += f;
            out[s.b] -= f;
        }
        for i in [0, self.n - 1] {
            out[i] = DVec3::ZERO;
        }
    }

    /// The cloth at `t_end` (positions, velocities) by classical Runge-Kutta in f64 with a
    /// step of about `dt`: the reference.
    pub fn reference(&self, t_end: f64, dt: f64) -> (Vec<DVec3>, Vec<DVec3>) {
        let springs = self.springs();
        let np = self.particles();
        let (mut x, mut v) = (self.start(), vec![DVec3::ZERO; np]);
        let steps = (t_end / dt).ceil().max(1.0) as usize;
        let h = t_end / steps as f64;
        let im = 1.0 / self.mass();
        let z = || vec![DVec3::ZERO; np];
        let (mut a1, mut a2, mut a3, mut a4) = (z(), z(), z(), z());
        let (mut xs, mut vs) = (z(), z());
        let (mut v2, mut v3, mut v4) = (z(), z(), z());
        for _ in 0..steps {
            self.forces(&springs, &x, &v, &mut a1);
            for i in 0..np {
                xs[i] = x[i] + v[i] * (h / 2.0);
                v2[i] = v[i] + a1[i] * (im * h / 2.0);
            }
            vs.copy_from_slice(&v2);
            self.forces(&springs, &xs, &vs, &mut a2);
            for i in 0..np {
                xs[i] = x[i] + v2[i] * (h / 2.0);
                v3[i] = v[i] + a2[i] * (im * h / 2.0);
            }
            vs.copy_from_slice(&v3);
            self.forces(&springs, &xs, &vs, &mut a3);
            for i in 0..np {
                xs[i] = x[i] + v3[i] * h;
                v4[i] = v[i] + a3[i] * (im * h);
            }
            vs.copy_from_slice(&v4);
            self.forces(&springs, &xs, &vs, &mut a4);
            for i in 0..np {
                x[i] += (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]) * (h / 6.0);
                v[i] += (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i]) * (im * h / 6.0);
            }
        }
        (x, v)
    }

    /// The highest angular frequency of the linearised cloth at rest, `sqrt(λ_max(M⁻¹ K))`
    /// over the free particles, by 300 power iterations in f64 (from an alternating start,
    /// close to the highest mode; it converges from below, so `2 / ω_max` is a slight
    /// over-estimate of the explicit step bound).
    pub fn omega_max(&self) -> f64 {
        let springs = self.springs();
        let x = self.start();
        let np = self.particles();
        let mut y: Vec<DVec3> = (0..np)
            .map(|i| {
                let s = if (i / self.n + i % self.n).is_multiple_of(2) {
                    1.0
                } else {
                    -1.0
                };
                DVec3::new(0.3, 1.0, -0.7) * s
            })
            .collect();
        let mut lambda = 0.0;
        for _ in 0..300 {
            for i in [0, self.n - 1] {
                y[i] = DVec3::ZERO;
            }
            let norm = y.iter().map(|p| p.length_squared()).sum::<f64>().sqrt();
            if norm == 0.0 {
                return 0.0;
            }
            y.iter_mut().for_each(|p| *p /= norm);
            let mut ky = vec![DVec3::ZERO; np];
            for s in &springs {
                let u = (x[s.b] - x[s.a]).normalize();
                let f = u * (s.k * u.dot(y[s.b] - y[s.a]));
                ky[s.a] -= f;
                ky[s.b] += f;
            }
            for i in [0, self.n - 1] {
                ky[i] = DVec3::ZERO;
            }
            lambda = ky.iter().zip(&y).map(|(a, b)| a.dot(*b)).sum::<f64>() / self.mass();
            y = ky;
        }
        lambda.max(0.0).sqrt()
    }
}

/// Backward Euler's matrix pattern for a cloth of `params`: a diagonal block per particle and
/// a block per spring both ways, from triplets of zero blocks (so each row's columns ascend).
pub fn pattern(params: Params, dev: &wp::Device) -> wp::Result<Bsr<Mat3>> {
    let np = params.particles();
    let (mut rows, mut cols) = (Vec::new(), Vec::new());
    for i in 0..np as i32 {
        rows.push(i);
        cols.push(i);
    }
    for s in &params.springs() {
        rows.extend([s.a as i32, s.b as i32]);
        cols.extend([s.b as i32, s.a as i32]);
    }
    let zero = vec![Mat3::ZERO; rows.len()];
    Bsr::from_triplets(
        np,
        np,
        &wp::Array::from_slice(&rows, dev)?,
        &wp::Array::from_slice(&cols, dev)?,
        &wp::Array::from_slice(&zero, dev)?,
    )
}

/// Which integrator a run uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Series {
    /// Semi-implicit (symplectic) Euler, a thread per particle.
    Euler,
    /// XPBD (Macklin et al.) with the springs coloured on the device: per substep a launch per
    /// colour and sweep, a thread per spring.
    XpbdColored { substeps: i32, iterations: i32 },
    /// Backward Euler by `newton` Newton iterations (the first Baraff-Witkin's), each a CG
    /// solve with block Jacobi to `rtol` (at most `max_iter` iterations), driven from the host
    /// (`Mode::Host`, a read-back every 10 iterations) or, with `graph`, as a graph each solve
    /// captures and launches (`Mode::Graph`; the same iterations and bits).
    BackwardEuler {
        newton: usize,
        rtol: f64,
        max_iter: usize,
        graph: bool,
    },
}

impl Series {
    /// A short name for tables.
    pub fn name(&self) -> &'static str {
        match self {
            Series::Euler => "semi-implicit Euler",
            Series::XpbdColored { .. } => "XPBD colored",
            Series::BackwardEuler { .. } => "backward Euler",
        }
    }
}

/// What one step did (backward Euler's solves; zeros for the other series).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepStats {
    /// CG iterations of each Newton iteration.
    pub cg_iterations: Vec<usize>,
    /// Solves that stopped at `max_iter` without converging (Newton went on: an inexact step).
    pub cg_unconverged: usize,
    /// With `Cloth::track_residuals`: `|g|` (the Newton residual `h f(x0 + h v, v) - M dv`,
    /// all particles, f32) before the first iteration and after each.
    pub residuals: Vec<f64>,
}

/// The device state of a cloth and a stepper for it.
pub struct Cloth {
    pub params: Params,
    pub x: wp::Array<Vec3>,
    pub v: wp::Array<Vec3>,
    x1: wp::Array<Vec3>,
    v1: wp::Array<Vec3>,
    v0: wp::Array<Vec3>,
    rhs: wp::Array<Vec3>,
    delta: wp::Array<Vec3>,
    norm: wp::Array<f32>,
    /// Backward Euler's matrix: its pattern made once from the springs, made at the first
    /// implicit step.
    matrix: Option<Bsr<Mat3>>,
    /// XPBD's springs (pairs, rest lengths, stiffnesses), multipliers, the springs by colour
    /// and each colour's range, made at the first XPBD step.
    xpbd: Option<Xpbd>,
    /// Compute Newton's residual after each iteration (a read-back each: for the tests).
    pub track_residuals: bool,
}

struct Xpbd {
    springs: wp::Array<IVec2>,
    rest: wp::Array<f32>,
    stiff: wp::Array<f32>,
    lambda: wp::Array<f32>,
    order: wp::Array<i32>,
    colours: Vec<Range<usize>>,
}

impl Cloth {
    /// A cloth at its start state on `dev`.
    pub fn new(params: Params, dev: &wp::Device) -> wp::Result<Cloth> {
        if params.n < 3 {
            return Err(wp::Error::InvalidArgument {
                what: format!(
                    "implicit_cloth::Cloth::new: `n` (particles per side) must be at least 3, \
                     got {}",
                    params.n
                ),
            });
        }
        let good_k = params.k > 0.0 && params.k.is_finite();
        if !good_k || params.kd.is_nan() || params.kd < 0.0 {
            return Err(wp::Error::InvalidArgument {
                what: format!(
                    "implicit_cloth::Cloth::new: `k` must be positive and `kd` not negative, \
                     got k = {}, kd = {}",
                    params.k, params.kd
                ),
            });
        }
        let np = params.particles();
        let start: Vec<Vec3> = params.start().iter().map(|p| p.as_vec3()).collect();
        let z = || wp::Array::<Vec3>::zeros(np, dev);
        Ok(Cloth {
            params,
            x: wp::Array::from_slice(&start, dev)?,
            v: z()?,
            x1: z()?,
            v1: z()?,
            v0: z()?,
            rhs: z()?,
            delta: z()?,
            norm: wp::Array::zeros(1, dev)?,
            matrix: None,
            xpbd: None,
            track_residuals: false,
        })
    }

    /// Makes what `series` needs once (the matrix's pattern, the colouring): allocations and
    /// read-backs, outside any timing.
    pub fn prepare(&mut self, series: Series, dev: &wp::Device) -> wp::Result<()> {
        match series {
            Series::Euler => Ok(()),
            Series::XpbdColored { .. } => self.xpbd(dev).map(|_| ()),
            Series::BackwardEuler { .. } => self.matrix(dev).map(|_| ()),
        }
    }

    /// The number of colours of the springs (made on the device if not yet).
    pub fn colours(&mut self, dev: &wp::Device) -> wp::Result<usize> {
        Ok(self.xpbd(dev)?.colours.len())
    }

    /// Stored blocks of backward Euler's matrix (made if not yet).
    pub fn matrix_blocks(&mut self, dev: &wp::Device) -> wp::Result<usize> {
        self.matrix(dev)?.nnz()
    }

    fn xpbd(&mut self, dev: &wp::Device) -> wp::Result<&Xpbd> {
        if self.xpbd.is_none() {
            let springs = self.params.springs();
            let pairs: Vec<IVec2> = springs
                .iter()
                .map(|s| IVec2::new(s.a as i32, s.b as i32))
                .collect();
            let pairs = wp::Array::from_slice(&pairs, dev)?;
            let g = Adjacency::of_constraints(self.params.particles(), &pairs)?;
            let colouring = Coloring::new(&g, 0)?;
            let colours = colouring.ranges()?;
            let f = |g: fn(&Spring) -> f64| -> Vec<f32> {
                springs.iter().map(|s| g(s) as f32).collect()
            };
            self.xpbd = Some(Xpbd {
                springs: pairs,
                rest: wp::Array::from_slice(&f(|s| s.rest), dev)?,
                stiff: wp::Array::from_slice(&f(|s| s.k), dev)?,
                lambda: wp::Array::zeros(springs.len(), dev)?,
                order: colouring.order,
                colours,
            });
        }
        Ok(self.xpbd.as_ref().expect("made above"))
    }

    /// Backward Euler's matrix, made once ([`pattern`]).
    fn matrix(&mut self, dev: &wp::Device) -> wp::Result<&Bsr<Mat3>> {
        if self.matrix.is_none() {
            self.matrix = Some(pattern(self.params, dev)?);
        }
        Ok(self.matrix.as_ref().expect("made above"))
    }

    /// One step of `series` with step `dt`.
    pub fn step(&mut self, series: Series, dt: f32, dev: &wp::Device) -> wp::Result<StepStats> {
        let p = self.params;
        let (n, spacing, mass) = (p.n as i32, p.spacing() as f32, p.mass() as f32);
        let k = p.stiffnesses().as_vec3();
        let kd = p.kd as f32;
        let gravity = Vec3::new(0.0, -G as f32, 0.0);
        let np = p.particles();
        let mut stats = StepStats::default();
        match series {
            Series::Euler => {
                let args = (
                    &self.x, &self.v, &self.x1, &self.v1, n, spacing, k, kd, mass, gravity, dt,
                );
                wp::launch(euler_step, np, args, dev)?;
                std::mem::swap(&mut self.x, &mut self.x1);
                std::mem::swap(&mut self.v, &mut self.v1);
            }
            Series::XpbdColored {
                substeps,
                iterations,
            } => {
                let h = dt / substeps as f32;
                let inv_mass = 1.0 / mass;
                self.xpbd(dev)?;
                let xp = self.xpbd.as_ref().expect("made above");
                let (x, v, prev) = (&self.x, &self.v, &self.x1);
                for _sub in 0..substeps {
                    wp::launch(xpbd_predict, np, (x, v, prev, n, gravity, h), dev)?;
                    wp::launch(xpbd_zero, xp.lambda.len(), (&xp.lambda,), dev)?;
                    for _sweep in 0..iterations {
                        for r in &xp.colours {
                            let args = (
                                x,
                                &xp.lambda,
                                &xp.springs,
                                &xp.rest,
                                &xp.stiff,
                                &xp.order,
                                r.start as i32,
                                n,
                                inv_mass,
                                h,
                            );
                            wp::launch(xpbd_project_colour, r.len(), args, dev)?;
                        }
                    }
                    wp::launch(xpbd_velocity, np, (x, v, prev, h), dev)?;
                }
            }
            Series::BackwardEuler {
                newton,
                rtol,
                max_iter,
                graph,
            } => {
                self.matrix(dev)?;
                let a = self.matrix.as_ref().expect("made above");
                let options = SolveOptions {
                    rtol,
                    max_iter,
                    check_every: 10,
                    mode: if graph { Mode::Graph } else { Mode::Host },
                    ..SolveOptions::default()
                };
                let b = self.rhs.reinterpret::<f32>()?;
                let delta = self.delta.reinterpret::<f32>()?;
                wp::launch(copy_vec3, np, (&self.v, &self.v0), dev)?;
                let assemble = |first: i32| {
                    let args = (
                        a, &self.x, &self.v0, &self.v, &self.rhs, n, spacing, k, kd, mass, gravity,
                        dt, first,
                    );
                    wp::launch(be_assemble, np, args, dev)
                };
                let residual = |out: &mut Vec<f64>| -> wp::Result<()> {
                    assemble(0)?;
                    sparse::dot(&b, &b, &self.norm)?;
                    out.push((self.norm.to_vec()?[0] as f64).sqrt());
                    Ok(())
                };
                if self.track_residuals {
                    residual(&mut stats.residuals)?;
                }
                for it in 0..newton.max(1) {
                    assemble(if it == 0 { 1 } else { 0 })?;
                    delta.fill(0.0)?;
                    let report = sparse::cg(a, &b, &delta, Precond::Jacobi, &options)?;
                    match report.stop {
                        Stop::Converged => {}
                        Stop::MaxIterations => stats.cg_unconverged += 1,
                        stop => {
                            return Err(wp::Error::InvalidArgument {
                                what: format!(
                                    "implicit_cloth: backward Euler's CG stopped: {stop:?}"
                                ),
                            })
                        }
                    }
                    stats.cg_iterations.push(report.iterations);
                    wp::launch(be_update, np, (&self.v, &self.delta), dev)?;
                    if self.track_residuals {
                        residual(&mut stats.residuals)?;
                    }
                }
                wp::launch(be_positions, np, (&self.x, &self.v, dt), dev)?;
            }
        }
        Ok(stats)
    }

    /// Positions and velocities, in f64.
    pub fn state(&self) -> wp::Result<(Vec<DVec3>, Vec<DVec3>)> {
        let f = |a: &wp::Array<Vec3>| -> wp::Result<Vec<DVec3>> {
            Ok(a.to_vec()?.iter().map(|p| p.as_dvec3()).collect())
        };
        Ok((f(&self.x)?, f(&self.v)?))
    }
}

/// What a run measured.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Stayed finite with every spring below `STRETCH_LIMIT` rest lengths at every check.
    pub stable: bool,
    /// Why not, if not.
    pub why: String,
    /// Steps run (to the end, or to the check that found the blow-up).
    pub steps: usize,
    /// The state at the end (meaningless when unstable).
    pub x: Vec<DVec3>,
    pub v: Vec<DVec3>,
    /// `(t, (E(t) - E(0)) / energy_scale)` at each check.
    pub energy: Vec<(f64, f64)>,
    /// Seconds of stepping (synchronised; checks excluded).
    pub seconds: f64,
    /// CG iterations of each Newton iteration of every step (backward Euler).
    pub cg_iterations: Vec<usize>,
    /// Solves that stopped at their iteration limit.
    pub cg_unconverged: usize,
    /// Each step's Newton residuals (with `track_residuals`).
    pub residuals: Vec<Vec<f64>>,
}

impl Outcome {
    /// The energy change at the end, relative to the energy scale (NaN when unstable).
    pub fn drift(&self) -> f64 {
        match (self.stable, self.energy.last()) {
            (true, Some(&(_, e))) => e,
            _ => f64::NAN,
        }
    }

    /// The largest |energy change| over the checks, relative to the energy scale.
    pub fn max_drift(&self) -> f64 {
        self.energy.iter().map(|e| e.1.abs()).fold(0.0, f64::max)
    }

    /// Mean CG iterations per Newton iteration (NaN for none).
    pub fn mean_cg(&self) -> f64 {
        if self.cg_iterations.is_empty() {
            return f64::NAN;
        }
        self.cg_iterations.iter().sum::<usize>() as f64 / self.cg_iterations.len() as f64
    }

    /// The largest distance of a particle from `reference`.
    pub fn error(&self, reference: &[DVec3]) -> f64 {
        if !self.stable {
            return f64::NAN;
        }
        self.x
            .iter()
            .zip(reference)
            .map(|(a, b)| a.distance(*b))
            .fold(
                0.0,
                |a: f64, b| if b.is_nan() { f64::NAN } else { a.max(b) },
            )
    }
}

/// Runs `series` on a cloth of `params` with step about `dt` until `t_end` (the step count
/// `t_end / dt` rounded to the nearest, at least 1, and the step `t_end` over it), checking
/// the state (finite, stretch, energy) `checks` times along the way; `track` records Newton's
/// residuals. A warm-up step on a throwaway cloth
/// loads the kernels first (outside the timing).
pub fn simulate(
    params: Params,
    series: Series,
    dt: f64,
    t_end: f64,
    checks: usize,
    track: bool,
    dev: &wp::Device,
) -> wp::Result<Outcome> {
    let steps = ((t_end / dt).round() as usize).max(1);
    // The step actually taken: t_end in whole steps, so every run ends where the reference does.
    let dt = t_end / steps as f64;
    let mut warm = Cloth::new(params, dev)?;
    warm.prepare(series, dev)?;
    warm.step(series, dt as f32, dev)?;
    let mut cloth = Cloth::new(params, dev)?;
    cloth.track_residuals = track;
    cloth.prepare(series, dev)?;
    let springs = params.springs();
    let (x0, v0) = (params.start(), vec![DVec3::ZERO; params.particles()]);
    let e0 = params.energy(&springs, &x0, &v0);
    let scale = params.energy_scale();
    let mut out = Outcome {
        stable: true,
        why: String::new(),
        steps: 0,
        x: x0,
        v: v0,
        energy: vec![(0.0, 0.0)],
        seconds: 0.0,
        cg_iterations: Vec::new(),
        cg_unconverged: 0,
        residuals: Vec::new(),
    };
    let chunk = steps.div_ceil(checks.max(1));
    wp::synchronize()?;
    while out.steps < steps {
        let todo = chunk.min(steps - out.steps);
        let t = Instant::now();
        for _ in 0..todo {
            match cloth.step(series, dt as f32, dev) {
                Ok(s) => {
                    out.cg_iterations.extend(&s.cg_iterations);
                    out.cg_unconverged += s.cg_unconverged;
                    if track {
                        out.residuals.push(s.residuals);
                    }
                }
                // A CG breakdown or non-finite residual: the system blew up.
                Err(wp::Error::InvalidArgument { what }) if what.starts_with("implicit_cloth") => {
                    out.stable = false;
                    out.why = format!("by step {}: {what}", out.steps + 1);
                    break;
                }
                Err(e) => return Err(e),
            }
            out.steps += 1;
        }
        wp::synchronize()?;
        out.seconds += t.elapsed().as_secs_f64();
        if !out.stable {
            break;
        }
        let (x, v) = cloth.state()?;
        let stretch = params.max_stretch(&springs, &x);
        let finite = x.iter().chain(&v).all(|p| p.is_finite());
        if !finite || stretch.is_nan() || stretch > STRETCH_LIMIT {
            out.stable = false;
            out.why = if finite && !stretch.is_nan() {
                format!(
                    "by step {}: a spring at {stretch:.3} rest lengths",
                    out.steps
                )
            } else {
                format!("by step {}: not finite", out.steps)
            };
            break;
        }
        let t_now = out.steps as f64 * dt;
        out.energy
            .push((t_now, (params.energy(&springs, &x, &v) - e0) / scale));
        out.x = x;
        out.v = v;
    }
    Ok(out)
}

/// The observed order `log2(e_h / e_{h/2})` between a step and its half.
pub fn order(coarse: f64, fine: f64) -> f64 {
    (coarse / fine).log2()
}

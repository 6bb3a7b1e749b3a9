//! A hanging mass-spring chain: its kernels (semi-implicit Euler and XPBD), its energy, and
//! an f64 reference integrator on the host. Shared by the `springs` example and the
//! stability tests (tests/suite/stability.rs includes this file), so that the tests check
//! the very kernels the scene runs.
//!
//! The chain: `SEGMENTS` springs of rest length `REST`, `SEGMENTS + 1` particles of mass
//! `MASS`, particle 0 pinned at the origin, released at rest along +x under gravity -y.
//! Many identical chains run side by side (`Array<Vec3, 2>` of shape (chains, particles)),
//! so that a GPU has work; they all compute the same thing.

#![allow(dead_code)] // the test uses part of it

use warp_lang as wp;
use wp::prelude::*;
// The sparse tier, named by the including file (`use warp_lang::sparse;` in the example, whose
// crate turns on the facade's `sparse` feature; `use warp_runtime::sparse;` in the tests and
// benchmarks, which get the tier from the runtime dev-dependency).
use super::sparse::{Adjacency, Coloring};

pub const SEGMENTS: usize = 20;
pub const PARTICLES: usize = SEGMENTS + 1;
pub const REST: f64 = 0.05; // m: a chain 1 m long
pub const MASS: f64 = 0.05; // kg per particle
pub const G: f64 = 9.81; // m/s^2, along -y

/// The force on a particle at `a` from the spring to `b`: k (|b - a| - rest) along b - a.
#[wp::func]
fn spring_force(a: Vec3, b: Vec3, k: f32, rest: f32) -> Vec3 {
    let d = b - a;
    let len = length(d);
    d * (k * (len - rest) / len)
}

/// One semi-implicit (symplectic) Euler step, a thread per particle: v += dt F(x) / m, then
/// x_new = x + dt v. Reads `x`, writes `x_new` (the caller swaps them), so that every
/// thread sees the same positions. Stable for dt < 2 / omega_max, about sqrt(m / k).
#[wp::kernel]
pub fn euler_step(
    x: Array<Vec3, 2>,
    v: Array<Vec3, 2>,
    x_new: Array<Vec3, 2>,
    k: f32,
    rest: f32,
    mass: f32,
    gravity: Vec3,
    dt: f32,
) {
    let (c, i) = tid();
    let n = x.shape()[1];
    let xi = x[(c, i)];
    if i == 0 {
        x_new[(c, i)] = xi; // pinned
    } else {
        let mut f = gravity * mass + spring_force(xi, x[(c, i - 1)], k, rest);
        if i + 1 < n {
            f += spring_force(xi, x[(c, i + 1)], k, rest);
        }
        let vi = v[(c, i)] + f * (dt / mass);
        v[(c, i)] = vi;
        x_new[(c, i)] = xi + vi * dt;
    }
}

/// One XPBD step (Macklin et al. 2016) split into `substeps` substeps (Macklin et al.
/// 2019, "Small steps in physics simulation"), a thread per chain. Each substep predicts
/// under gravity, runs `iterations` Gauss-Seidel sweeps down the chain projecting each spring
/// with compliance 1 / k, and takes velocities from the change in position. `x_prev` and
/// `lambda` are scratch. Stable at any step: a stiffer spring or a larger step only makes
/// the chain act more like a rod (and, with too few sweeps, a stretchier one).
#[wp::kernel]
pub fn xpbd_step(
    x: Array<Vec3, 2>,
    v: Array<Vec3, 2>,
    x_prev: Array<Vec3, 2>,
    lambda: Array<f32, 2>,
    compliance: f32,
    rest: f32,
    mass: f32,
    gravity: Vec3,
    dt: f32,
    substeps: i32,
    iterations: i32,
) {
    let c = tid();
    let n = x.shape()[1];
    let h = dt / substeps as f32;
    let alpha = compliance / (h * h);
    let w = 1.0 / mass;
    for _sub in 0..substeps {
        for i in 1..n {
            let xi = x[(c, i)];
            x_prev[(c, i)] = xi;
            x[(c, i)] = xi + (v[(c, i)] + gravity * h) * h;
        }
        for s in 0..n - 1 {
            lambda[(c, s)] = 0.0;
        }
        for _sweep in 0..iterations {
            for s in 0..n - 1 {
                let a = x[(c, s)];
                let b = x[(c, s + 1)];
                let d = b - a;
                let len = length(d);
                // The pinned particle does not move: inverse mass 0.
                let mut wa = w;
                if s == 0 {
                    wa = 0.0;
                }
                let l = lambda[(c, s)];
                let dl = (rest - len - alpha * l) / (wa + w + alpha);
                lambda[(c, s)] = l + dl;
                let dir = d / len;
                x[(c, s)] = a - dir * (wa * dl);
                x[(c, s + 1)] = b + dir * (w * dl);
            }
        }
        for i in 1..n {
            v[(c, i)] = (x[(c, i)] - x_prev[(c, i)]) / h;
        }
    }
}

/// XPBD by colour, part 1 of a substep: a thread per particle predicts under gravity (the
/// pinned particle 0 stays) and keeps the position before it; the thread of particle `i` below
/// `SEGMENTS` also zeroes spring `i`'s multiplier.
#[wp::kernel]
pub fn xpbd_predict(
    x: Array<Vec3, 2>,
    v: Array<Vec3, 2>,
    x_prev: Array<Vec3, 2>,
    lambda: Array<f32, 2>,
    gravity: Vec3,
    h: f32,
) {
    let (c, i) = tid();
    if i < lambda.shape()[1] {
        lambda[(c, i)] = 0.0;
    }
    if i > 0 {
        let xi = x[(c, i)];
        x_prev[(c, i)] = xi;
        x[(c, i)] = xi + (v[(c, i)] + gravity * h) * h;
    }
}

/// XPBD by colour, part 2: a thread per spring of one colour (`order[start + tid]`; spring
/// `c * SEGMENTS + s` joins particles `s` and `s + 1` of chain `c`) projects its spring with
/// compliance `alpha` (already over h^2). The springs of a colour share no particle, so the
/// threads write disjoint particles; the colours run one after another (Gauss-Seidel across
/// colours, Jacobi within one).
#[wp::kernel]
pub fn xpbd_project_colour(
    x: Array<Vec3, 2>,
    lambda: Array<f32, 2>,
    order: Array<i32>,
    start: i32,
    alpha: f32,
    rest: f32,
    mass: f32,
) {
    let id = order[start as usize + tid()] as usize;
    let segments = lambda.shape()[1];
    let c = id / segments;
    let s = id % segments;
    let w = 1.0 / mass;
    let a = x[(c, s)];
    let b = x[(c, s + 1)];
    let d = b - a;
    let len = length(d);
    // The pinned particle does not move: inverse mass 0.
    let mut wa = w;
    if s == 0 {
        wa = 0.0;
    }
    let l = lambda[(c, s)];
    let dl = (rest - len - alpha * l) / (wa + w + alpha);
    lambda[(c, s)] = l + dl;
    let dir = d / len;
    x[(c, s)] = a - dir * (wa * dl);
    x[(c, s + 1)] = b + dir * (w * dl);
}

/// XPBD by colour, part 3: velocities from the change in position, a thread per particle.
#[wp::kernel]
pub fn xpbd_velocity(x: Array<Vec3, 2>, v: Array<Vec3, 2>, x_prev: Array<Vec3, 2>, h: f32) {
    let (c, i) = tid();
    if i > 0 {
        v[(c, i)] = (x[(c, i)] - x_prev[(c, i)]) / h;
    }
}

/// The springs of `chains` chains as constraints (pairs of particles, the particles of chain
/// `c` numbered from `c * PARTICLES`), spring `c * SEGMENTS + s` joining particles `s` and
/// `s + 1` of chain `c`.
pub fn constraints(chains: usize) -> Vec<IVec2> {
    (0..chains)
        .flat_map(|c| {
            (0..SEGMENTS).map(move |s| {
                let p = (c * PARTICLES + s) as i32;
                IVec2::new(p, p + 1)
            })
        })
        .collect()
}

/// The start state of one chain: along +x at rest lengths, at rest.
pub fn start() -> Vec<DVec3> {
    (0..PARTICLES)
        .map(|i| DVec3::new(i as f64 * REST, 0.0, 0.0))
        .collect()
}

/// Total energy of one chain (kinetic, gravitational, elastic), in f64.
pub fn energy(x: &[DVec3], v: &[DVec3], k: f64) -> f64 {
    let kinetic: f64 = v.iter().map(|v| 0.5 * MASS * v.length_squared()).sum();
    let gravity: f64 = x.iter().map(|x| MASS * G * x.y).sum();
    let elastic: f64 = x
        .windows(2)
        .map(|p| 0.5 * k * ((p[1] - p[0]).length() - REST).powi(2))
        .sum();
    kinetic + gravity + elastic
}

/// The energy scale drifts are measured against: the whole chain falling its own length.
pub fn energy_scale() -> f64 {
    PARTICLES as f64 * MASS * G * SEGMENTS as f64 * REST
}

/// Accelerations of one chain (particle 0 pinned), in f64.
fn accelerations(x: &[DVec3], k: f64, out: &mut [DVec3]) {
    out[0] = DVec3::ZERO;
    for i in 1..x.len() {
        let mut f = DVec3::new(0.0, -G * MASS, 0.0);
        for j in [i - 1, i + 1] {
            if j < x.len() {
                let d = x[j] - x[i];
                let len = d.length();
                f += d * (k * (len - REST) / len);
            }
        }
        out[i] = f / MASS;
    }
}

/// The chain at `t_end` by classical Runge-Kutta in f64 with step `dt`: the reference.
pub fn reference(k: f64, t_end: f64, dt: f64) -> Vec<DVec3> {
    let n = PARTICLES;
    let mut x = start();
    let mut v = vec![DVec3::ZERO; n];
    let steps = (t_end / dt).round() as usize;
    let h = t_end / steps as f64;
    let (mut a1, mut a2, mut a3, mut a4) = (
        vec![DVec3::ZERO; n],
        vec![DVec3::ZERO; n],
        vec![DVec3::ZERO; n],
        vec![DVec3::ZERO; n],
    );
    let mut xs = vec![DVec3::ZERO; n];
    for _ in 0..steps {
        // Stage derivatives (dx, dv) = (v, a(x)).
        accelerations(&x, k, &mut a1);
        let v1 = v.clone();
        for i in 0..n {
            xs[i] = x[i] + v1[i] * (h / 2.0);
        }
        accelerations(&xs, k, &mut a2);
        let v2: Vec<DVec3> = (0..n).map(|i| v[i] + a1[i] * (h / 2.0)).collect();
        for i in 0..n {
            xs[i] = x[i] + v2[i] * (h / 2.0);
        }
        accelerations(&xs, k, &mut a3);
        let v3: Vec<DVec3> = (0..n).map(|i| v[i] + a2[i] * (h / 2.0)).collect();
        for i in 0..n {
            xs[i] = x[i] + v3[i] * h;
        }
        accelerations(&xs, k, &mut a4);
        let v4: Vec<DVec3> = (0..n).map(|i| v[i] + a3[i] * h).collect();
        for i in 0..n {
            x[i] += (v1[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]) * (h / 6.0);
            v[i] += (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i]) * (h / 6.0);
        }
    }
    x
}

/// The highest angular frequency of the chain's springs, about 2 sqrt(k / m).
pub fn omega_max(k: f64) -> f64 {
    2.0 * (k / MASS).sqrt()
}

/// Which integrator a run uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    Euler,
    Xpbd {
        substeps: i32,
        iterations: i32,
    },
    /// XPBD with the springs coloured on the device (`Adjacency::of_constraints`, then
    /// `Coloring`): each substep launches a thread per spring of a colour, colour after colour,
    /// instead of a thread per chain sweeping its springs in order.
    XpbdColored {
        substeps: i32,
        iterations: i32,
    },
}

/// Device state of `chains` chains and a stepper for them.
pub struct Chains {
    pub x: wp::Array<Vec3, 2>,
    pub v: wp::Array<Vec3, 2>,
    scratch: wp::Array<Vec3, 2>,
    lambda: wp::Array<f32, 2>,
    chains: usize,
    /// The springs by colour (`Coloring::order`) and each colour's range in it, made at the
    /// first coloured step.
    colored: Option<(wp::Array<i32>, Vec<std::ops::Range<usize>>)>,
}

impl Chains {
    pub fn new(chains: usize, dev: &wp::Device) -> wp::Result<Self> {
        let one: Vec<Vec3> = start().iter().map(|p| p.as_vec3()).collect();
        let all: Vec<Vec3> = (0..chains).flat_map(|_| one.iter().copied()).collect();
        Ok(Chains {
            x: wp::Array::from_slice(&all, dev)?.reshape((chains, PARTICLES))?,
            v: wp::Array::zeros((chains, PARTICLES), dev)?,
            scratch: wp::Array::zeros((chains, PARTICLES), dev)?,
            lambda: wp::Array::zeros((chains, SEGMENTS), dev)?,
            chains,
            colored: None,
        })
    }

    /// One step of `solver` with stiffness `k` and step `dt`.
    pub fn step(&mut self, solver: Solver, k: f32, dt: f32, dev: &wp::Device) -> wp::Result<()> {
        let (rest, mass) = (REST as f32, MASS as f32);
        let gravity = Vec3::new(0.0, -G as f32, 0.0);
        match solver {
            Solver::Euler => {
                wp::launch(
                    euler_step,
                    (self.chains, PARTICLES),
                    (&self.x, &self.v, &self.scratch, k, rest, mass, gravity, dt),
                    dev,
                )?;
                std::mem::swap(&mut self.x, &mut self.scratch);
            }
            Solver::Xpbd {
                substeps,
                iterations,
            } => wp::launch(
                xpbd_step,
                self.chains,
                (
                    &self.x,
                    &self.v,
                    &self.scratch,
                    &self.lambda,
                    1.0 / k,
                    rest,
                    mass,
                    gravity,
                    dt,
                    substeps,
                    iterations,
                ),
                dev,
            )?,
            Solver::XpbdColored {
                substeps,
                iterations,
            } => {
                let h = dt / substeps as f32;
                let alpha = 1.0 / k / (h * h);
                let (order, colours) = self.colouring(dev)?.clone();
                let dims = (self.chains, PARTICLES);
                for _sub in 0..substeps {
                    let (x, v, p, l) = (&self.x, &self.v, &self.scratch, &self.lambda);
                    wp::launch(xpbd_predict, dims, (x, v, p, l, gravity, h), dev)?;
                    for _sweep in 0..iterations {
                        for r in &colours {
                            let args = (x, l, &order, r.start as i32, alpha, rest, mass);
                            wp::launch(xpbd_project_colour, r.len(), args, dev)?;
                        }
                    }
                    wp::launch(xpbd_velocity, dims, (x, v, p, h), dev)?;
                }
            }
        }
        Ok(())
    }

    /// The springs' colouring (made once, on the device): the order of the springs by colour
    /// and each colour's range in it.
    pub fn colouring(
        &mut self,
        dev: &wp::Device,
    ) -> wp::Result<&(wp::Array<i32>, Vec<std::ops::Range<usize>>)> {
        if self.colored.is_none() {
            let c = wp::Array::from_slice(&constraints(self.chains), dev)?;
            let g = Adjacency::of_constraints(self.chains * PARTICLES, &c)?;
            let colouring = Coloring::new(&g, 0)?;
            let ranges = colouring.ranges()?;
            self.colored = Some((colouring.order, ranges));
        }
        Ok(self.colored.as_ref().expect("made above"))
    }

    /// Whether every particle of every chain is within `radius` of the pin: a chain that
    /// left that ball has blown up even if it is still finite.
    pub fn within(&self, radius: f32) -> wp::Result<bool> {
        Ok(self.x.to_vec()?.iter().all(|p| p.length() <= radius))
    }

    /// Chain 0's positions and velocities, in f64.
    pub fn first(&self) -> wp::Result<(Vec<DVec3>, Vec<DVec3>)> {
        let x = self.x.to_vec()?;
        let v = self.v.to_vec()?;
        let f = |a: &[Vec3]| a[..PARTICLES].iter().map(|p| p.as_dvec3()).collect();
        Ok((f(&x), f(&v)))
    }
}

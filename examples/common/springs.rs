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
    Xpbd { substeps: i32, iterations: i32 },
}

/// Device state of `chains` chains and a stepper for them.
pub struct Chains {
    pub x: wp::Array<Vec3, 2>,
    pub v: wp::Array<Vec3, 2>,
    scratch: wp::Array<Vec3, 2>,
    lambda: wp::Array<f32, 2>,
    chains: usize,
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
        }
        Ok(())
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

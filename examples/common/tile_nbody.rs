//! The all-pairs n-body of `examples/tile_nbody.rs`, shared with its test
//! (`examples/tests/tile_nbody.rs`) and the GPU benchmark's `--tile-nbody` section (benches/gpu.rs
//! includes this file), so that all three run the same kernels: the start state, the two step
//! kernels (tiled and scalar) and the float64 references.
//!
//! Physics (G = 1): the acceleration of body i is `sum_j m_j d / (|d|^2 + eps^2)^(3/2)`,
//! `d = x_j - x_i`, every j including i itself (its term is exactly zero: `d = 0` and the
//! softening keeps the denominator at least `eps^3 > 0`, so coincident bodies pull each other
//! with zero force instead of 0/0). One launch is one step of leapfrog in its staggered form:
//! the state is `(x_k, v_{k-1/2})`, and a step computes `a_k = a(x_k)`, then
//! `v_{k+1/2} = v_{k-1/2} + a_k dt` and `x_{k+1} = x_k + v_{k+1/2} dt` (Warp's
//! example_tile_nbody integrates the same way), writing into the other half of double-buffered
//! arrays because every body reads every other body's position.
//!
//! - **Tiled** (`step_tiled`): the positions and masses are one `(n, 4)` f32 array, a row
//!   `(x, y, z, m)` per body (tiles hold scalars, not `Vec3`, so a body is a row of a 2-D tile).
//!   A block of `block_dim` lanes owns `block_dim` bodies, one per lane; it walks all bodies
//!   `TILE` at a time, `tile_load`ing each chunk into shared memory once for the whole block, and
//!   every lane adds the chunk's pulls on its own body, reading the tile's elements (`t[(j, c)]`).
//!   Each position is read from global memory once per block instead of once per thread.
//! - **Scalar** (`step_scalar`): examples/nbody.rs's kernel, one thread per body reading every
//!   other body from global memory, with `Vec3` positions and f32 masses in arrays of their own.
//!
//! Both sum the pulls in the same order (j ascending) with the same operations, so on the CPU
//! they give the same bits; rows past the end of the array (the last chunk when `n` is not a
//! multiple of `TILE`) load as zeros, a massless body whose pull is exactly zero.
//!
//! **Range.** Every term is finite while `m_j / eps^3` is (the largest factor: at `d = 0`, the
//! body's own term), i.e. `m_j <= f32::MAX eps^3` (4.2e34 at eps = 0.05); a larger mass makes
//! the body's own term `0 * inf = NaN`, and accelerations past f32's range are infinite.
//! [`Sim::check_finite`] reports either by name. Tiny masses (1e-30, subnormal ones) are
//! harmless: their pulls are tiny or zero.

// Each includer uses its own subset.
#![allow(dead_code)]
// The code the kernel macro generates for a tiled kernel's CPU block rounds up by hand, and
// clippy reports it at the kernel (as in tile_fft.rs).
#![allow(clippy::manual_div_ceil)]

use glam::DVec3;
use rand::{Rng as _, SeedableRng as _};
use warp_lang as wp;
use wp::prelude::*;

/// Bodies a block loads into shared memory at a time: a `TILE x 4` f32 tile (1 KiB).
pub const TILE: usize = 64;

/// The softening length of the start state and the example's default.
pub const SOFTENING: f64 = 0.05;

/// One leapfrog step, tiled: `bodies` is `(n, 4)`, rows `(x, y, z, m)` at step k, `v` is
/// `v_{k-1/2}`; writes `a_k` to `a`, `v_{k+1/2}` to `v_out` and the rows at step k + 1 to
/// `bodies_out`. Lane `l` of block `b` owns body `b block_dim + l`; lanes past `n` take part in
/// the block's loads and write nothing.
#[wp::kernel]
pub fn step_tiled(
    bodies: Array<f32, 2>,
    v: Array<Vec3>,
    bodies_out: Array<f32, 2>,
    v_out: Array<Vec3>,
    a: Array<Vec3>,
    eps2: f32,
    dt: f32,
) {
    let n = bodies.shape()[0];
    let i = tid() * block_dim() as usize + lane();
    let live = i < n;
    // A lane past the end keeps a zero position: its sums are computed and thrown away (the
    // tile loads are the whole block's, so no lane may skip the loop).
    let xi = if live {
        Vec3::new(bodies[(i, 0)], bodies[(i, 1)], bodies[(i, 2)])
    } else {
        Vec3::ZERO
    };
    let mut acc = Vec3::ZERO;
    for k in 0..(n + TILE - 1) / TILE {
        let t = tile_load::<TILE, 4>(bodies, ((k * TILE) as i32, 0));
        for j in 0..TILE {
            let d = Vec3::new(t[(j, 0)], t[(j, 1)], t[(j, 2)]) - xi;
            let r2 = dot(d, d) + eps2;
            acc += d * (t[(j, 3)] / (r2 * sqrt(r2)));
        }
    }
    if live {
        a[i] = acc;
        let vn = v[i] + acc * dt;
        v_out[i] = vn;
        let xn = xi + vn * dt;
        bodies_out[(i, 0)] = xn.x;
        bodies_out[(i, 1)] = xn.y;
        bodies_out[(i, 2)] = xn.z;
        bodies_out[(i, 3)] = bodies[(i, 3)];
    }
}

/// The same step, one thread per body (examples/nbody.rs's sum): positions `x` and masses `m`
/// in arrays of their own.
#[wp::kernel]
pub fn step_scalar(
    x: Array<Vec3>,
    m: Array<f32>,
    v: Array<Vec3>,
    x_out: Array<Vec3>,
    v_out: Array<Vec3>,
    a: Array<Vec3>,
    eps2: f32,
    dt: f32,
) {
    let i = tid();
    let xi = x[i];
    let mut acc = Vec3::ZERO;
    for j in 0..x.len() {
        let d = x[j] - xi;
        let r2 = dot(d, d) + eps2;
        acc += d * (m[j] / (r2 * sqrt(r2)));
    }
    a[i] = acc;
    let vn = v[i] + acc * dt;
    v_out[i] = vn;
    x_out[i] = xi + vn * dt;
}

/// Which kernel a [`Sim`] steps with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// `step_tiled`, `launch_tiled` with the given threads per block.
    Tiled { block_dim: usize },
    /// `step_scalar`, one thread per body.
    Scalar,
}

impl Kernel {
    pub fn name(self) -> &'static str {
        match self {
            Kernel::Tiled { .. } => "tiled",
            Kernel::Scalar => "scalar",
        }
    }
}

/// Where each kernel keeps the positions and masses, double-buffered.
enum Bodies {
    Packed([wp::Array<f32, 2>; 2]),
    Split([wp::Array<Vec3>; 2], wp::Array<f32>),
}

/// An f32 run on a device: the state `(x_k, v_{k-1/2})` and the last step's accelerations.
pub struct Sim {
    kernel: Kernel,
    dev: wp::Device,
    n: usize,
    bodies: Bodies,
    v: [wp::Array<Vec3>; 2],
    a: wp::Array<Vec3>,
    /// The buffer that holds the current state.
    cur: usize,
    eps2: f32,
    dt: f32,
}

fn invalid(what: String) -> wp::Error {
    wp::Error::InvalidArgument { what }
}

impl Sim {
    /// A run from positions `x`, velocities `v_half` (`v_{-1/2}`) and masses `m`, rounded to
    /// f32. An error names the argument when the lengths differ, there are no bodies, the
    /// softening is not positive and finite (without it coincident bodies divide 0 by 0), `dt`
    /// is not finite, or the tiled kernel's block size is 0.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        kernel: Kernel,
        x: &[DVec3],
        v_half: &[DVec3],
        m: &[f64],
        softening: f64,
        dt: f64,
        dev: &wp::Device,
    ) -> wp::Result<Sim> {
        let n = x.len();
        if n == 0 || v_half.len() != n || m.len() != n {
            return Err(invalid(format!(
                "tile_nbody Sim::new: x, v_half and m need the same positive length (got {}, {}, {})",
                n,
                v_half.len(),
                m.len()
            )));
        }
        let eps2 = (softening * softening) as f32;
        if !(softening.is_finite() && eps2 > 0.0 && eps2.is_finite()) {
            return Err(invalid(format!(
                "tile_nbody Sim::new: softening must be positive with a finite, nonzero square in f32 (got {softening:?})"
            )));
        }
        if !dt.is_finite() {
            return Err(invalid(format!(
                "tile_nbody Sim::new: dt must be finite (got {dt:?})"
            )));
        }
        // The kernels index bodies with i32 tile offsets.
        if n > i32::MAX as usize {
            return Err(invalid(format!(
                "tile_nbody Sim::new: at most {} bodies (the kernels' tile offsets are i32), got {n}",
                i32::MAX
            )));
        }
        if kernel == (Kernel::Tiled { block_dim: 0 }) {
            return Err(invalid(
                "tile_nbody Sim::new: block_dim must be at least 1 (got 0)".into(),
            ));
        }
        let f3 = |p: &DVec3| p.as_vec3();
        let vel: Vec<Vec3> = v_half.iter().map(f3).collect();
        let v = [
            wp::Array::from_vec(vel, dev)?,
            wp::Array::<Vec3>::zeros(n, dev)?,
        ];
        let bodies = match kernel {
            Kernel::Tiled { .. } => {
                let rows: Vec<f32> = x
                    .iter()
                    .zip(m)
                    .flat_map(|(p, &m)| [p.x as f32, p.y as f32, p.z as f32, m as f32])
                    .collect();
                Bodies::Packed([
                    wp::Array::from_slice_shape(&rows, (n, 4), dev)?,
                    wp::Array::<f32, 2>::zeros((n, 4), dev)?,
                ])
            }
            Kernel::Scalar => Bodies::Split(
                [
                    wp::Array::from_vec(x.iter().map(f3).collect(), dev)?,
                    wp::Array::<Vec3>::zeros(n, dev)?,
                ],
                wp::Array::from_vec(m.iter().map(|&m| m as f32).collect(), dev)?,
            ),
        };
        Ok(Sim {
            kernel,
            dev: dev.clone(),
            n,
            bodies,
            v,
            a: wp::Array::zeros(n, dev)?,
            cur: 0,
            eps2,
            dt: dt as f32,
        })
    }

    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    /// One step: one launch, from the current buffers into the others (asynchronous on a GPU).
    pub fn step(&mut self) -> wp::Result<()> {
        let (c, o) = (self.cur, 1 - self.cur);
        let (eps2, dt, dev) = (self.eps2, self.dt, &self.dev);
        let (v, a) = (&self.v, &self.a);
        match (&self.bodies, self.kernel) {
            (Bodies::Packed(b), Kernel::Tiled { block_dim }) => wp::launch_tiled(
                step_tiled,
                self.n.div_ceil(block_dim),
                (&b[c], &v[c], &b[o], &v[o], a, eps2, dt),
                block_dim,
                dev,
            )?,
            (Bodies::Split(x, m), _) => wp::launch(
                step_scalar,
                self.n,
                (&x[c], m, &v[c], &x[o], &v[o], a, eps2, dt),
                dev,
            )?,
            (Bodies::Packed(_), Kernel::Scalar) => {
                unreachable!("Sim::new pairs layouts and kernels")
            }
        }
        self.cur = o;
        Ok(())
    }

    /// The last step's accelerations `a_k` (at the positions that step started from).
    pub fn accelerations(&self) -> wp::Result<Vec<DVec3>> {
        Ok(self.a.to_vec()?.iter().map(|p| p.as_dvec3()).collect())
    }

    /// The current positions `x_k` and masses as the kernel holds them (f32, widened).
    pub fn bodies(&self) -> wp::Result<(Vec<DVec3>, Vec<f64>)> {
        match &self.bodies {
            Bodies::Packed(b) => {
                let rows = b[self.cur].to_vec()?;
                Ok(rows
                    .chunks_exact(4)
                    .map(|r| {
                        (
                            DVec3::new(r[0] as f64, r[1] as f64, r[2] as f64),
                            r[3] as f64,
                        )
                    })
                    .unzip())
            }
            Bodies::Split(x, m) => Ok((
                x[self.cur].to_vec()?.iter().map(|p| p.as_dvec3()).collect(),
                m.to_vec()?.iter().map(|&m| m as f64).collect(),
            )),
        }
    }

    /// The current half-step velocities `v_{k-1/2}` (widened).
    pub fn velocities(&self) -> wp::Result<Vec<DVec3>> {
        Ok(self.v[self.cur]
            .to_vec()?
            .iter()
            .map(|p| p.as_dvec3())
            .collect())
    }

    /// An [`wp::Error::Diverged`] naming the kernel and the array (accelerations or velocities)
    /// that holds a NaN or an infinity, with its index and value.
    pub fn check_finite(&self) -> wp::Result<()> {
        let name = self.kernel.name();
        self.a
            .check_finite(&format!("{name} n-body accelerations"))?;
        self.v[self.cur].check_finite(&format!("{name} n-body velocities"))
    }
}

/// `n` bodies of total mass 1 uniform in the unit ball, with velocities uniform in the unit ball
/// (isotropic, mean square speed 3/5: kinetic energy 3/10 against the ball's potential -3/5, near
/// virial equilibrium), centre of mass at rest at the origin; seeded ChaCha8 (examples/nbody.rs
/// starts alike, with normal velocities). Returns positions,
/// velocities and masses, each already rounded to f32 (widened back), so that the float64
/// references see exactly the state the kernels are handed.
pub fn start(n: usize, seed: u64) -> (Vec<DVec3>, Vec<DVec3>, Vec<f64>) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut in_ball = || loop {
        let p = DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
        if p.length_squared() <= 1.0 {
            return p;
        }
    };
    let mut x: Vec<DVec3> = (0..n).map(|_| in_ball()).collect();
    // Uniform in the unit ball too: the mean square speed is then 3/5, the virial one.
    let mut v: Vec<DVec3> = (0..n).map(|_| in_ball()).collect();
    let cx = x.iter().sum::<DVec3>() / n.max(1) as f64;
    let cv = v.iter().sum::<DVec3>() / n.max(1) as f64;
    let round = |p: DVec3| p.as_vec3().as_dvec3();
    x.iter_mut().for_each(|p| *p = round(*p - cx));
    v.iter_mut().for_each(|p| *p = round(*p - cv));
    let m = vec![(1.0 / n.max(1) as f64) as f32 as f64; n];
    (x, v, m)
}

/// Body i's acceleration in float64 with the kernels' formula and softening, and the sum of
/// the terms' lengths `sum_j |m_j d / r^3|`: the scale of the rounding error of an f32 sum of
/// them (the sum itself may cancel to about 0, the terms' lengths do not).
pub fn acceleration_f64(x: &[DVec3], m: &[f64], softening: f64, i: usize) -> (DVec3, f64) {
    let eps2 = softening * softening;
    let (mut a, mut scale) = (DVec3::ZERO, 0.0);
    for (xj, mj) in x.iter().zip(m) {
        let d = *xj - x[i];
        let r2 = d.length_squared() + eps2;
        let term = d * (mj / (r2 * r2.sqrt()));
        a += term;
        scale += term.length();
    }
    (a, scale)
}

/// The worst error of the accelerations `a` over the bodies `checked`:
/// `max_c |a_ic - A_ic| / sum_j |term_ij|`, `A` the float64 acceleration of the same (f32)
/// state `x`, `m`. NaN when any checked acceleration is not finite.
pub fn acceleration_error(
    a: &[DVec3],
    x: &[DVec3],
    m: &[f64],
    softening: f64,
    checked: &[usize],
) -> f64 {
    let mut worst = 0.0f64;
    for &i in checked {
        let (want, scale) = acceleration_f64(x, m, softening, i);
        let err = (a[i] - want).abs().max_element();
        if !err.is_finite() {
            return f64::NAN;
        }
        // A body whose every term is zero (all others massless, or coincident) has an exact sum.
        if scale > 0.0 {
            worst = worst.max(err / scale);
        }
    }
    worst
}

/// The bound the acceleration error must meet for an f32 sum of `n` terms, relative to the sum
/// of the terms' lengths: `(n + 16) u`, u = 2^-24. A recursive sum of `n` terms rounds `n - 1`
/// times, each addition's error at most `u` times a partial sum that is at most the sum of the
/// terms' magnitudes (Higham, Accuracy and Stability of Numerical Algorithms, 4.2): `(n - 1) u`.
/// Each term carries its own error of about 14 u to first order (the difference's rounding,
/// amplified by the 3/2 power of `r^2`, then the sqrt, product, quotient and scaling): 16 u covers
/// it with room. Typical errors are far smaller (the roundings are about as often up as down,
/// so they grow as `sqrt(n) u`), but the bound is the one every order of summation meets.
pub fn error_bound(n: usize) -> f64 {
    (n as f64 + 16.0) * f32::EPSILON as f64 / 2.0
}

/// Total energy (kinetic plus the softened potential `-m_i m_j / sqrt(r^2 + eps^2)` over
/// pairs) in float64.
pub fn energy(x: &[DVec3], v: &[DVec3], m: &[f64], softening: f64) -> f64 {
    let eps2 = softening * softening;
    let kinetic: f64 = v
        .iter()
        .zip(m)
        .map(|(v, m)| 0.5 * m * v.length_squared())
        .sum();
    let mut potential = 0.0;
    for i in 0..x.len() {
        for j in i + 1..x.len() {
            potential -= m[i] * m[j] / (x[i].distance_squared(x[j]) + eps2).sqrt();
        }
    }
    kinetic + potential
}

/// The velocities half a step `h` (signed) on from `v`, under the float64 accelerations of `x`:
/// `v_{-1/2}` from `v_0` (h = -dt/2) and `v_k` from `v_{k-1/2}` (h = dt/2), so that the
/// energy is measured at whole steps.
pub fn half_kick(x: &[DVec3], v: &[DVec3], m: &[f64], softening: f64, h: f64) -> Vec<DVec3> {
    (0..x.len())
        .map(|i| v[i] + acceleration_f64(x, m, softening, i).0 * h)
        .collect()
}

/// Bodies checked against float64: all of them, or `samples` seeded ones.
pub fn checked_bodies(n: usize, samples: usize) -> Vec<usize> {
    if n <= samples {
        return (0..n).collect();
    }
    let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    (0..samples).map(|_| r.random_range(0..n)).collect()
}

/// A small system that probes the kernels' range: what [`stability`] runs.
pub struct Case {
    pub name: &'static str,
    pub x: Vec<DVec3>,
    pub m: Vec<f64>,
    /// Whether the accelerations are representable (finite) in f32: the kernels must then
    /// return finite ones within [`error_bound`]; otherwise [`Sim::check_finite`] must report.
    pub finite: bool,
}

/// The range probes at softening [`SOFTENING`]: two coincident bodies (the softening makes
/// their pull on each other exactly zero instead of 0/0), masses from 1e-40 (an f32 subnormal)
/// to 1e30 in one system, and a pair of coincident bodies of mass 1e36 > f32::MAX eps^3, whose
/// own terms overflow (0 * inf = NaN), which must be reported, not returned silently.
pub fn cases() -> Vec<Case> {
    let p = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    vec![
        Case {
            name: "two coincident bodies and a third",
            x: vec![p(0.25, 0.0, 0.0), p(0.25, 0.0, 0.0), p(-0.75, 0.5, 0.0)],
            m: vec![1.0, 1.0, 1.0],
            finite: true,
        },
        Case {
            name: "masses 1e-40 to 1e30",
            x: vec![
                p(0.0, 0.0, 0.0),
                p(1.0, 0.0, 0.0),
                p(0.0, 0.5, 0.0),
                p(0.0, 0.0, 0.25),
                p(0.0, 0.0, 0.25),
            ],
            m: vec![1e30, 1e-30, 1.0, 1e-40, 1e-40],
            finite: true,
        },
        Case {
            name: "coincident bodies of mass 1e36 (> f32::MAX eps^3)",
            x: vec![p(0.0, 0.0, 0.0), p(0.0, 0.0, 0.0), p(1.0, 0.0, 0.0)],
            m: vec![1e36, 1e36, 1.0],
            finite: false,
        },
    ]
}

/// One step of `case` with `kernel`: the accelerations' error against float64 (as
/// [`acceleration_error`], over all bodies), or the error [`Sim::check_finite`] reports.
pub fn stability(case: &Case, kernel: Kernel, dev: &wp::Device) -> wp::Result<f64> {
    let x: Vec<DVec3> = case.x.iter().map(|p| p.as_vec3().as_dvec3()).collect();
    let m: Vec<f64> = case.m.iter().map(|&m| m as f32 as f64).collect();
    let v = vec![DVec3::ZERO; x.len()];
    let mut sim = Sim::new(kernel, &x, &v, &m, SOFTENING, 1e-3, dev)?;
    sim.step()?;
    sim.check_finite()?;
    let all: Vec<usize> = (0..x.len()).collect();
    Ok(acceleration_error(
        &sim.accelerations()?,
        &x,
        &m,
        SOFTENING,
        &all,
    ))
}

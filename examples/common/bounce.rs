//! A bouncing ball's kernels, shared by the `bounce` scene and its test
//! (tests/suite/scenes.rs includes this file), so that the test checks the very kernels the
//! scene runs.
//!
//! A ball of radius `radius` (a point whose centre stays `radius` above the floor y = 0) moves
//! in the x-y plane under gravity and bounces on the floor with restitution `e` (the normal
//! velocity is reversed and scaled by `e`; no friction). Each step is semi-implicit Euler,
//! v' = v + g dt, x' = x + v' dt, reading one state and writing the next (so a tape can replay
//! every step), one thread per ball. The two kernels differ only in the step where the ball
//! reaches the floor:
//!
//! - `step_naive` takes the full step, finds the ball beneath the floor and reverses its
//!   velocity there. The ball stays beneath the floor for that step, and where it ends up
//!   depends on how deep it went: a change of the launch velocity that makes the ball hit the
//!   floor later also makes it go deeper, which the reflection then turns into a *lower*
//!   position. The program's derivative is the slope of these sawtooth teeth, not of the
//!   physical motion (DiffTaichi, Hu et al. 2020, section 6: the same failure, with the
//!   gradient's sign wrong);
//! - `step_toi` finds the time of impact toi in [0, dt) along the step's straight path,
//!   toi = (y - r) / (-v'_y), moves there, reverses the velocity *the ball has at that time*
//!   (v + g toi), and integrates the rest of the step, dt - toi, from the contact point. Where
//!   toi reaches dt this is the free step followed by the reflection, and where it reaches 0 it
//!   is the reflection followed by the free step, so the state after the step is continuous in
//!   the launch velocity and its derivative is the derivative of the motion.

#![allow(dead_code)] // the test uses part of it

use warp_lang as wp;
use wp::prelude::*;

/// Gravity, m/s^2.
pub const GRAVITY: f64 = -9.81;

/// One step with the naive contact: reflect the velocity after the step, leave the position
/// beneath the floor.
#[wp::kernel]
pub fn step_naive(
    x0: Array<DVec2>,
    v0: Array<DVec2>,
    x1: Array<DVec2>,
    v1: Array<DVec2>,
    gravity: DVec2,
    radius: f64,
    restitution: f64,
    dt: f64,
) {
    let i = tid();
    let v = v0[i] + gravity * dt;
    let x = x0[i] + v * dt;
    if x.y < radius && v.y < 0.0 {
        let mut r = v;
        r.y = -restitution * v.y;
        v1[i] = r;
    } else {
        v1[i] = v;
    }
    x1[i] = x;
}

/// One step with the time of impact: move to the contact at toi, reflect the velocity the
/// ball has there, integrate the remaining dt - toi.
#[wp::kernel]
pub fn step_toi(
    x0: Array<DVec2>,
    v0: Array<DVec2>,
    x1: Array<DVec2>,
    v1: Array<DVec2>,
    gravity: DVec2,
    radius: f64,
    restitution: f64,
    dt: f64,
) {
    let i = tid();
    let x = x0[i];
    let vm = v0[i] + gravity * dt;
    let free = x + vm * dt;
    if free.y < radius && vm.y < 0.0 {
        // Along the step's path x + vm t, the floor is reached at toi (clamped: a ball that
        // starts the step beneath the floor is reflected at once).
        let toi = clamp((x.y - radius) / (-vm.y), 0.0, dt);
        let hit = x + vm * toi;
        let mut vh = v0[i] + gravity * toi;
        vh.y = -restitution * vh.y;
        let rest = dt - toi;
        let v = vh + gravity * rest;
        v1[i] = v;
        x1[i] = hit + v * rest;
    } else {
        v1[i] = vm;
        x1[i] = free;
    }
}

/// Each ball's squared distance from its target, into `per_ball` and summed into `loss`.
#[wp::kernel]
pub fn distance_sq(x: Array<DVec2>, target: Array<DVec2>, per_ball: Array<f64>, loss: Array<f64>) {
    let i = tid();
    let d = x[i] - target[i];
    let l = d.dot(d);
    per_ball[i] = l;
    atomic_add(loss, 0, l);
}

/// Which contact treatment a run uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Contact {
    Naive,
    Toi,
}

impl Contact {
    pub fn name(self) -> &'static str {
        match self {
            Contact::Naive => "naive",
            Contact::Toi => "time of impact",
        }
    }
}

/// The scene's constants.
#[derive(Clone, Copy, Debug)]
pub struct Setup {
    pub radius: f64,
    pub restitution: f64,
    pub dt: f64,
    pub steps: usize,
    /// Launch position (the same for every ball).
    pub start: DVec2,
}

impl Default for Setup {
    fn default() -> Self {
        Setup {
            radius: 0.05,
            restitution: 0.8,
            dt: 0.01,
            steps: 100,
            start: DVec2::new(0.0, 1.0),
        }
    }
}

/// The device state of `balls` balls over a whole trajectory: positions and velocities of
/// every step (each with a gradient), the targets and the losses. `vs[0]` is the launch
/// velocity, the parameter.
pub struct Balls {
    pub setup: Setup,
    pub xs: Vec<wp::Array<DVec2>>,
    pub vs: Vec<wp::Array<DVec2>>,
    pub target: wp::Array<DVec2>,
    pub per_ball: wp::Array<f64>,
    pub loss: wp::Array<f64>,
    pub balls: usize,
}

impl Balls {
    /// `balls` balls launched at `v0[b]`, aiming at `target[b]`.
    pub fn new(
        setup: Setup,
        v0: &[DVec2],
        target: &[DVec2],
        dev: &wp::Device,
    ) -> wp::Result<Balls> {
        let n = v0.len();
        if target.len() != n {
            return Err(wp::Error::InvalidArgument {
                what: format!(
                    "bounce: {} launch velocities but {} targets",
                    n,
                    target.len()
                ),
            });
        }
        let mut xs = vec![wp::Array::from_slice(&vec![setup.start; n], dev)?.with_grad()?];
        let mut vs = vec![wp::Array::from_slice(v0, dev)?.with_grad()?];
        for _ in 0..setup.steps {
            xs.push(wp::Array::<DVec2>::zeros(n, dev)?.with_grad()?);
            vs.push(wp::Array::<DVec2>::zeros(n, dev)?.with_grad()?);
        }
        Ok(Balls {
            setup,
            xs,
            vs,
            target: wp::Array::from_slice(target, dev)?,
            per_ball: wp::Array::<f64>::zeros(n, dev)?.with_grad()?,
            loss: wp::Array::<f64>::zeros(1, dev)?.with_grad()?,
            balls: n,
        })
    }

    /// Runs the trajectory from `vs[0]` with `contact` and the loss (launched on whatever tape
    /// records on this thread); returns the summed loss.
    pub fn forward(&self, contact: Contact, dev: &wp::Device) -> wp::Result<f64> {
        let s = &self.setup;
        let g = DVec2::new(0.0, GRAVITY);
        self.loss.fill(0.0)?;
        for k in 0..s.steps {
            let args = (
                &self.xs[k],
                &self.vs[k],
                &self.xs[k + 1],
                &self.vs[k + 1],
                g,
                s.radius,
                s.restitution,
                s.dt,
            );
            match contact {
                Contact::Naive => wp::launch(step_naive, self.balls, args, dev)?,
                Contact::Toi => wp::launch(step_toi, self.balls, args, dev)?,
            }
        }
        let last = &self.xs[s.steps];
        wp::launch(
            distance_sq,
            self.balls,
            (last, &self.target, &self.per_ball, &self.loss),
            dev,
        )?;
        Ok(self.loss.to_vec()?[0])
    }

    /// The loss and its gradient with respect to the launch velocities (one per ball), by a
    /// tape. Leaves every gradient zeroed but the launch velocities'.
    pub fn gradient(&self, contact: Contact, dev: &wp::Device) -> wp::Result<(f64, Vec<DVec2>)> {
        let tape = wp::Tape::new();
        let loss = {
            let _rec = tape.record();
            self.forward(contact, dev)?
        };
        tape.backward(&self.loss)?;
        let g = self.vs[0].grad().expect("with_grad").to_vec()?;
        // Zero the intermediate gradients for the next backward; the caller's optimiser reads
        // and then zeroes the launch velocities' own.
        for a in self.xs.iter().chain(&self.vs[1..]) {
            a.zero_grad()?;
        }
        self.per_ball.zero_grad()?;
        self.loss.zero_grad()?;
        Ok((loss, g))
    }

    /// Each ball's loss at launch velocities `v0` (forward only; `vs[0]` is restored after).
    pub fn losses_at(
        &self,
        contact: Contact,
        v0: &[DVec2],
        dev: &wp::Device,
    ) -> wp::Result<Vec<f64>> {
        let keep = self.vs[0].to_vec()?;
        self.vs[0].copy_from(&wp::Array::from_slice(v0, dev)?)?;
        self.forward(contact, dev)?;
        let l = self.per_ball.to_vec()?;
        self.vs[0].copy_from(&wp::Array::from_slice(&keep, dev)?)?;
        Ok(l)
    }

    /// Central differences of each ball's loss along component `c` (0: x, 1: y) of its
    /// launch velocity, with step `h`: two forward runs for all balls at once (the balls are
    /// independent).
    pub fn central_difference(
        &self,
        contact: Contact,
        c: usize,
        h: f64,
        dev: &wp::Device,
    ) -> wp::Result<Vec<f64>> {
        let v = self.vs[0].to_vec()?;
        let shift = |s: f64| -> Vec<DVec2> {
            v.iter()
                .map(|&p| {
                    let mut q = p;
                    q[c] += s;
                    q
                })
                .collect()
        };
        let plus = self.losses_at(contact, &shift(h), dev)?;
        let minus = self.losses_at(contact, &shift(-h), dev)?;
        Ok(plus
            .iter()
            .zip(&minus)
            .map(|(p, m)| (p - m) / (2.0 * h))
            .collect())
    }

    /// Final positions.
    pub fn final_positions(&self) -> wp::Result<Vec<DVec2>> {
        self.xs[self.setup.steps].to_vec()
    }
}

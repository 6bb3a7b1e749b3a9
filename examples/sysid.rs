//! System identification on the seed program: recover the drag coefficient b and the mass m
//! from an observed trajectory, by gradient descent through the simulation.
//!
//! ```text
//! cargo run --release --example sysid -- [--device cpu|cuda:0] [--particles N] [--steps 200]
//!     [--iterations 2000] [--lr 0.05] [--tol 1e-3] [--plot-dir DIR]
//! ```
//! The seed program: particles under gravity with linear drag, semi-implicit Euler,
//! a = -(b / m) v + g + F(t) / m, v' = v + a dt, x' = x + v' dt (here in f64, dt = 10 ms).
//!
//! **Why a known push F.** Under gravity and drag alone, a = -(b/m) v + g depends on b and m
//! only through b/m: every (b, m) with the true ratio yields the same trajectory, so no
//! trajectory can tell b and m apart (the scene shows it: without the push the loss at
//! (2 b, 2 m) is exactly that at (b, m), zero). A known, time-varying applied force F(t)
//! (a push of a few newtons, as a test rig would apply) enters as F/m, so the response
//! measures m, and then the drag measures b. Each particle gets its own push (an amplitude and
//! a phase), so that several trajectories constrain the fit.
//!
//! The "observed" trajectory is the program run with the true b = 0.05 kg/s, m = 0.1 kg (the
//! seed program's values). From the guess b = 0.02, m = 0.3 (wrong ratio too), Adam minimises
//! the mean squared position mismatch over every step of every particle, with respect to
//! (ln b, ln m) (log space: both stay positive and their scales do not matter). The tape
//! records one launch per step (each writes the next row of the trajectory, so backward
//! replays them all) and one for the loss. Printed: the gradient against central differences
//! at the guess, the optimisation table, the recovered b and m with their relative errors,
//! the plot `<plot-dir>/sysid.svg`, and a verdict line: the exit status is 1 unless both
//! are within `--tol` (1e-3) relative of the truth.

mod common;

use clap::Parser;
use rand::Rng as _;
use rand_distr::StandardNormal;
use warp_lang as wp;
use warp_report::frame::{Frame, Lines, Points};
use warp_report::{sci, Table};
use wp::prelude::*;

/// One step of the seed program with a known applied force, for every particle: reads row `s`
/// of the trajectory, writes row `s + 1`. `theta` = (ln b, ln m).
#[wp::kernel]
fn step(
    x: Array<DVec3, 2>,
    v: Array<DVec3, 2>,
    force: Array<DVec3, 2>,
    theta: Array<f64>,
    gravity: DVec3,
    dt: f64,
    s: i32,
) {
    let i = tid();
    let b = exp(theta[0]);
    let m = exp(theta[1]);
    let vs = v[(s, i)];
    let a = -b * vs / m + gravity + force[(s, i)] / m;
    let vn = vs + a * dt;
    v[(s + 1, i)] = vn;
    x[(s + 1, i)] = x[(s, i)] + vn * dt;
}

/// loss += scale |x - observed|^2 over every step after the first and every particle.
#[wp::kernel]
fn mismatch(x: Array<DVec3, 2>, observed: Array<DVec3, 2>, scale: f64, loss: Array<f64>) {
    let (s, i) = tid();
    let d = x[(s + 1, i)] - observed[(s + 1, i)];
    atomic_add(loss, 0, scale * d.dot(d));
}

const B_TRUE: f64 = 0.05;
const M_TRUE: f64 = 0.1;
const DT: f64 = 0.01;

/// The trajectories of `particles` particles over `steps` steps, on a device.
struct Rig {
    x: wp::Array<DVec3, 2>,
    v: wp::Array<DVec3, 2>,
    force: wp::Array<DVec3, 2>,
    zero_force: wp::Array<DVec3, 2>,
    loss: wp::Array<f64>,
    steps: usize,
    particles: usize,
}

impl Rig {
    fn new(particles: usize, steps: usize, dev: &wp::Device) -> wp::Result<Rig> {
        let mut rng = common::rng(11);
        let mut x0 = Vec::new();
        let mut v0 = Vec::new();
        let mut pushes = Vec::new();
        for _ in 0..particles {
            x0.push(DVec3::new(
                rng.sample::<f64, _>(StandardNormal),
                1.0 + rng.random::<f64>(),
                rng.sample::<f64, _>(StandardNormal),
            ));
            v0.push(DVec3::new(
                rng.sample::<f64, _>(StandardNormal),
                2.0 * rng.random::<f64>(),
                rng.sample::<f64, _>(StandardNormal),
            ));
            // Amplitude 0.5-2 N, angular frequency 2-6 rad/s, a phase.
            pushes.push((
                0.5 + 1.5 * rng.random::<f64>(),
                2.0 + 4.0 * rng.random::<f64>(),
                std::f64::consts::TAU * rng.random::<f64>(),
            ));
        }
        // The known push at each step: a force turning in the horizontal plane with a vertical
        // part, F(t) = A (cos(w t + p), 0.5 sin(2 w t), sin(w t + p)).
        let mut force = Vec::with_capacity(steps * particles);
        for s in 0..steps {
            let t = s as f64 * DT;
            for &(a, w, p) in &pushes {
                force.push(DVec3::new(
                    a * (w * t + p).cos(),
                    0.5 * a * (2.0 * w * t).sin(),
                    a * (w * t + p).sin(),
                ));
            }
        }
        let mut x = vec![DVec3::ZERO; (steps + 1) * particles];
        let mut v = x.clone();
        x[..particles].copy_from_slice(&x0);
        v[..particles].copy_from_slice(&v0);
        Ok(Rig {
            x: wp::Array::from_slice_shape(&x, (steps + 1, particles), dev)?.with_grad()?,
            v: wp::Array::from_slice_shape(&v, (steps + 1, particles), dev)?.with_grad()?,
            force: wp::Array::from_slice_shape(&force, (steps, particles), dev)?,
            zero_force: wp::Array::zeros((steps, particles), dev)?,
            loss: wp::Array::zeros(1, dev)?.with_grad()?,
            steps,
            particles,
        })
    }

    /// Runs the trajectory with `theta` (with the push or without it) and, given observations,
    /// the loss; launches go onto any tape recording on this thread. Returns the loss.
    fn run(
        &self,
        theta: &wp::Array<f64>,
        push: bool,
        observed: Option<&wp::Array<DVec3, 2>>,
        dev: &wp::Device,
    ) -> wp::Result<f64> {
        let g = DVec3::new(0.0, -9.81, 0.0);
        let force = if push { &self.force } else { &self.zero_force };
        for s in 0..self.steps {
            wp::launch(
                step,
                self.particles,
                (&self.x, &self.v, force, theta, g, DT, s as i32),
                dev,
            )?;
        }
        self.loss.fill(0.0)?;
        if let Some(obs) = observed {
            let scale = 1.0 / (self.steps * self.particles) as f64;
            wp::launch(
                mismatch,
                (self.steps, self.particles),
                (&self.x, obs, scale, &self.loss),
                dev,
            )?;
        }
        Ok(self.loss.to_vec()?[0])
    }

    /// A copy of the current trajectory (the observations, after a run with the truth).
    fn snapshot(&self, dev: &wp::Device) -> wp::Result<wp::Array<DVec3, 2>> {
        let o = wp::Array::zeros((self.steps + 1, self.particles), dev)?;
        o.copy_from(&self.x)?;
        Ok(o)
    }

    /// The loss at (ln b, ln m) = `t`, forward only.
    fn loss_at(
        &self,
        t: [f64; 2],
        push: bool,
        obs: &wp::Array<DVec3, 2>,
        dev: &wp::Device,
    ) -> wp::Result<f64> {
        let theta = wp::Array::from_slice(&t, dev)?;
        self.run(&theta, push, Some(obs), dev)
    }

    /// The loss and its gradient with respect to theta by a tape (theta's gradient is added
    /// to; the trajectory's are zeroed after).
    fn gradient(
        &self,
        theta: &wp::Array<f64>,
        obs: &wp::Array<DVec3, 2>,
        dev: &wp::Device,
    ) -> wp::Result<(f64, [f64; 2])> {
        let tape = wp::Tape::new();
        let loss = {
            let _rec = tape.record();
            self.run(theta, true, Some(obs), dev)?
        };
        tape.backward(&self.loss)?;
        let g = theta.grad().expect("with_grad").to_vec()?;
        self.x.zero_grad()?;
        self.v.zero_grad()?;
        self.loss.zero_grad()?;
        Ok((loss, [g[0], g[1]]))
    }
}

/// Central-difference step in ln b and ln m, and the tolerance of the check: the loss is
/// about 5 m^2 at the guess with derivatives of order 1, in f64. Truncation h^2 |L'''| / 6 is
/// about 1e-10; the loss is a sum of steps x particles terms (819,200 with 4096 particles),
/// whose rounding, about eps sqrt(terms) |L| (1e-13 relative; on a GPU also the atomics'
/// order), divided by h gives about 1e-8: 1e-6 leaves a margin. (At h = 1e-6 the rounding
/// part was measured at 1.3e-7 with 4096 particles.)
const H_FD: f64 = 1e-5;
const TOL_FD: f64 = 1e-6;

/// System identification on the seed program: the drag coefficient and the mass recovered
/// from an observed trajectory by gradient descent through the simulation.
#[derive(Parser)]
struct Cli {
    /// Particles observed [default: 4096 on a GPU, 16 on the CPU]
    #[arg(long, value_name = "N", value_parser = common::num::<usize>)]
    particles: Option<usize>,
    /// Steps of the observed trajectory
    #[arg(long, default_value_t = 200, value_parser = common::num::<usize>)]
    steps: usize,
    /// Most gradient-descent iterations
    #[arg(long, default_value_t = 2000, value_parser = common::num::<usize>)]
    iterations: usize,
    /// The learning rate
    #[arg(long, default_value_t = 0.05)]
    lr: f64,
    /// Converged when both parameters are within this relative error of the truth
    #[arg(long, default_value_t = 1e-3)]
    tol: f64,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let particles = cli
        .particles
        .unwrap_or(if dev.is_cuda() { 4096 } else { 16 });
    let (steps, iterations, lr, tol) = (cli.steps, cli.iterations, cli.lr, cli.tol);
    if particles == 0 || steps == 0 {
        eprintln!("--particles and --steps must be at least 1");
        std::process::exit(2);
    }
    let guess = [0.02f64, 0.3f64];
    println!(
        "sysid: the seed program (linear drag, semi-implicit Euler, f64) with a known push, \
         {particles} particle(s) x {steps} steps of {DT} s on \"{dev}\"; truth b = {B_TRUE} kg/s, \
         m = {M_TRUE} kg; guess b = {}, m = {}; loss = mean |x - x_observed|^2 over all steps",
        guess[0], guess[1]
    );
    let rig = Rig::new(particles, steps, &dev)?;
    let truth = [B_TRUE.ln(), M_TRUE.ln()];

    // Identifiability: without the push only b/m matters.
    let truth_arr = wp::Array::from_slice(&truth, &dev)?;
    rig.run(&truth_arr, false, None, &dev)?;
    let obs_free = rig.snapshot(&dev)?;
    let doubled = [truth[0] + 2f64.ln(), truth[1] + 2f64.ln()];
    let free_same = rig.loss_at(doubled, false, &obs_free, &dev)?;
    rig.run(&truth_arr, true, None, &dev)?;
    let obs = rig.snapshot(&dev)?;
    let pushed_same = rig.loss_at(doubled, true, &obs, &dev)?;
    println!(
        "identifiability: loss at (2 b, 2 m) against the truth's trajectory: without the push \
         {} (b and m are not identifiable: only b/m enters), with the push {}",
        sci(free_same),
        sci(pushed_same)
    );

    // The gradient check at the guess.
    let theta = wp::Array::from_slice(&[guess[0].ln(), guess[1].ln()], &dev)?.with_grad()?;
    let (loss0, g) = rig.gradient(&theta, &obs, &dev)?;
    theta.zero_grad()?;
    let t0 = theta.to_vec()?;
    println!(
        "\ngradient at the guess (loss {}), central differences with h = {} in ln b, ln m:",
        sci(loss0),
        sci(H_FD)
    );
    let mut table = Table::new(["parameter", "tape", "central difference", "rel. error"]);
    let mut check_ok = true;
    for (k, name) in ["dL/d ln b", "dL/d ln m"].iter().enumerate() {
        let (mut p, mut q) = ([t0[0], t0[1]], [t0[0], t0[1]]);
        p[k] += H_FD;
        q[k] -= H_FD;
        let fd =
            (rig.loss_at(p, true, &obs, &dev)? - rig.loss_at(q, true, &obs, &dev)?) / (2.0 * H_FD);
        let e = common::rel_err(g[k], fd, 1e-8);
        check_ok &= e < TOL_FD;
        table.push([
            name.to_string(),
            format!("{:.9}", g[k]),
            format!("{fd:.9}"),
            sci(e),
        ]);
    }
    print!("{table}");
    println!("(tolerance {})", sci(TOL_FD));

    // Adam in log space.
    let mut log = common::OptLog::new(
        &format!("sysid: Adam (lr {lr}) on (ln b, ln m), {particles} x {steps} steps, on {dev}"),
        "loss",
        &["b", "m", "rel. err b", "rel. err m"],
        10,
    )
    .progress(iterations as u64);
    let mut adam = wp::optim::Adam::new(lr);
    adam.add(&theta)?;
    let rel = |t: &[f64]| {
        (
            ((t[0].exp() - B_TRUE) / B_TRUE).abs(),
            ((t[1].exp() - M_TRUE) / M_TRUE).abs(),
        )
    };
    let mut its = iterations;
    for it in 1..=iterations {
        let (loss, g) = rig.gradient(&theta, &obs, &dev)?;
        let t = theta.to_vec()?;
        let (eb, em) = rel(&t);
        let done = eb < tol && em < tol;
        log.record(
            "Adam, tape gradient",
            it,
            loss,
            (g[0] * g[0] + g[1] * g[1]).sqrt(),
            &[
                format!("{:.6}", t[0].exp()),
                format!("{:.6}", t[1].exp()),
                sci(eb),
                sci(em),
            ],
            done || it == iterations,
        );
        if done {
            its = it;
            break;
        }
        adam.step()?;
        adam.zero_grad()?;
    }
    log.finish("sysid");
    let t = theta.to_vec()?;
    let (eb, em) = rel(&t);
    println!(
        "\nrecovered after {its} iterations: b = {:.6} kg/s (truth {B_TRUE}, rel. error {}), \
         m = {:.6} kg (truth {M_TRUE}, rel. error {})",
        t[0].exp(),
        sci(eb),
        t[1].exp(),
        sci(em)
    );
    // The frame: up to 8 particles' observed trajectories (lines) and those of the recovered
    // parameters (dots, every 5th step), which should lie on them.
    let shown = particles.min(8);
    let observed = obs.to_vec()?;
    rig.run(&theta, true, None, &dev)?;
    let fitted = rig.x.to_vec()?;
    let track = |all: &[DVec3], p: usize| -> Vec<[f64; 3]> {
        (0..=steps)
            .map(|s| common::p3(all[s * particles + p]))
            .collect()
    };
    let tracks: Vec<Vec<[f64; 3]>> = (0..shown).map(|p| track(&observed, p)).collect();
    let (lo, hi) = common::bounds(&tracks.concat());
    let mut frame = Frame::new(
        format!(
            "sysid: {shown} of {particles} observed trajectories and the fit (b = {:.4}, m = {:.4})",
            t[0].exp(),
            t[1].exp()
        ),
        common::camera(lo, hi, [0.8, 0.5, 1.4], [0.0, 1.0, 0.0]),
    )
    .note("gravity, drag and a known push; lines: observed; dots: recovered parameters, every 5th step, colour: time (s)");
    for tr in &tracks {
        frame = frame.lines(Lines::polyline(tr).colour([150, 150, 150]).width(1.0));
    }
    let dots: Vec<(usize, usize)> = (0..shown)
        .flat_map(|p| (0..=steps).step_by(5).map(move |s| (p, s)))
        .collect();
    let frame = frame.points(
        Points::new(
            dots.iter()
                .map(|&(p, s)| common::p3(fitted[s * particles + p])),
            0.006 * common::diagonal(lo, hi),
        )
        .values("time (s)", dots.iter().map(|&(_, s)| s as f64 * DT)),
    );
    common::write_frame("sysid", &frame);
    cli.scene.record_last("sysid", &frame);
    common::print_compiled();
    let converged = eb < tol && em < tol;
    common::verdict(
        "sysid",
        check_ok && converged,
        &format!(
            "tape gradient within {} of central differences: {}; b and m both within {} \
             relative of the truth in at most {iterations} iterations: {}",
            sci(TOL_FD),
            if check_ok { "yes" } else { "no" },
            sci(tol),
            if converged { "yes" } else { "no" }
        ),
    );
    Ok(())
}

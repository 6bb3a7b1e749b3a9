//! Optimising a cloth's initial velocities through a mass-spring simulation: a square cloth
//! held at two corners must swing so that its centre of mass is at a target at time T.
//!
//! ```text
//! cargo run --release --example cloth -- [--device cpu|cuda:0] [--n 16] [--t-end 0.3]
//!     [--iterations 30] [--tol 1e-3] [--offset 0,0.1,0.05]
//!     [--plot-dir DIR]
//! ```
//! The cloth: 1 m x 1 m, 0.2 kg, an n x n grid of particles (`--n`: 64, 4096 particles, on a
//! GPU; 16 on the CPU) joined by structural springs (to the 4 nearest neighbours, 100 N/m),
//! shear springs (the 4 diagonals, 100 N/m) and bending springs (2 apart along the grid,
//! 5 N/m), each with damping along the spring, and a little air drag. It starts flat and at
//! rest in the horizontal plane y = 0, held at the two corners of its edge z = 0, and falls
//! and swings under gravity for `--t-end` seconds. Semi-implicit Euler, a thread per particle,
//! each step reading one state and writing the next (so the tape replays every step), the
//! step a safe margin under the explicit stability bound (which shrinks as the grid refines:
//! a 64 x 64 cloth takes about 4 times the steps of a 16 x 16 one).
//!
//! The parameters are the initial velocities: a smooth field, bilinear between 4 x 4 control
//! velocities (`--field 4`, 48 numbers) added to small random ones, or (`--field 0`) every
//! particle's own (3 n^2 numbers; the two held corners' have no effect). The gradient check
//! is per particle. The target is the centre of mass the cloth reaches from rest, moved by
//! `--offset` (0, 0.1, 0.05) m: up and forward, so the cloth must be thrown up and swing;
//! loss = |com_T - target|^2. Because the corners are held, the centre of mass is not linear
//! in the initial velocities: the springs carry the kicks to the held corners and back.
//!
//! Printed: the tape gradient against central differences for a few components, in an f64
//! instance of the same (generic) kernels, next to the f32 tape's; then Gauss-Newton on the
//! f64 simulation until the centre of mass is within `--tol` (1 mm) of the target. The loss
//! has three residuals (com_T - target) and 3 n^2 parameters, so each iteration records one
//! forward pass and runs three backward passes, one per component of the centre of mass
//! (the Jacobian's rows), and takes the smallest velocity change that cancels the residual to
//! first order, halving the step when the loss rises. (First-order methods do badly here:
//! with a step per particle of the same size, Adam kicks every particle alike and the stiff
//! springs near the held corners oscillate; plain gradient descent on the 64 x 64 cloth stalled
//! at 4 mm, and in f32 on a GPU its gradient became NaN once the kicks reached 2.8 m/s.) Then
//! the table (loss, gradient norm, distance, time per iteration), the plot
//! `<plot-dir>/cloth.svg`, and a verdict line; the exit status is 1 if the check fails or the
//! optimisation does not converge.

mod common;

use clap::Parser;
use rand::Rng as _;
use rand_distr::StandardNormal;
use warp_lang as wp;
use warp_report::frame::{Frame, Points, TriMesh};
use warp_report::{sci, Table};
use wp::prelude::*;

/// The force on particle (r, c) from the spring to (r + dr, c + dc), if that particle exists:
/// stiffness `k` toward the rest length h |(dr, dc)|, damping `kd` of the relative velocity
/// along the spring.
#[wp::func]
fn spring<T: Float>(
    x: Array<Vec3<T>, 2>,
    v: Array<Vec3<T>, 2>,
    r: i32,
    c: i32,
    dr: i32,
    dc: i32,
    k: T,
    kd: T,
    h: T,
) -> Vec3<T> {
    let rows = x.shape()[0] as i32;
    let cols = x.shape()[1] as i32;
    let rr = r + dr;
    let cc = c + dc;
    let mut f = Vec3::<T>::splat(0.0);
    if rr >= 0 && rr < rows && cc >= 0 && cc < cols {
        let i = r as usize;
        let j = c as usize;
        let p = rr as usize;
        let q = cc as usize;
        let d = x[(p, q)] - x[(i, j)];
        let len = length(d);
        let dir = d / len;
        let rest = h * sqrt((dr * dr + dc * dc) as T);
        let dv = v[(p, q)] - v[(i, j)];
        f = dir * (k * (len - rest) + kd * dot(dv, dir));
    }
    f
}

/// One semi-implicit Euler step of the cloth: (x0, v0) -> (x1, v1). The two corners of row 0
/// are held.
#[wp::kernel]
fn cloth_step<T: Float>(
    x0: Array<Vec3<T>, 2>,
    v0: Array<Vec3<T>, 2>,
    x1: Array<Vec3<T>, 2>,
    v1: Array<Vec3<T>, 2>,
    springs: Vec3<T>,
    kd: T,
    h: T,
    mass: T,
    drag: T,
    gravity: Vec3<T>,
    dt: T,
) {
    let (r, c) = tid();
    let cols = x0.shape()[1];
    if r == 0 && (c == 0 || c == cols - 1) {
        x1[(r, c)] = x0[(r, c)];
        v1[(r, c)] = Vec3::<T>::splat(0.0);
    } else {
        let ri = r as i32;
        let ci = c as i32;
        // springs = (structural, shear, bending) stiffness.
        let ks = springs.x;
        let kx = springs.y;
        let kb = springs.z;
        let mut f = gravity * mass - v0[(r, c)] * drag;
        f += spring::<T>(x0, v0, ri, ci, 0, 1, ks, kd, h);
        f += spring::<T>(x0, v0, ri, ci, 0, -1, ks, kd, h);
        f += spring::<T>(x0, v0, ri, ci, 1, 0, ks, kd, h);
        f += spring::<T>(x0, v0, ri, ci, -1, 0, ks, kd, h);
        f += spring::<T>(x0, v0, ri, ci, 1, 1, kx, kd, h);
        f += spring::<T>(x0, v0, ri, ci, 1, -1, kx, kd, h);
        f += spring::<T>(x0, v0, ri, ci, -1, 1, kx, kd, h);
        f += spring::<T>(x0, v0, ri, ci, -1, -1, kx, kd, h);
        f += spring::<T>(x0, v0, ri, ci, 0, 2, kb, kd, h);
        f += spring::<T>(x0, v0, ri, ci, 0, -2, kb, kd, h);
        f += spring::<T>(x0, v0, ri, ci, 2, 0, kb, kd, h);
        f += spring::<T>(x0, v0, ri, ci, -2, 0, kb, kd, h);
        let v = v0[(r, c)] + f * (dt / mass);
        v1[(r, c)] = v;
        x1[(r, c)] = x0[(r, c)] + v * dt;
    }
}

/// com += x / count, over every particle.
#[wp::kernel]
fn centre<T: Float>(x: Array<Vec3<T>, 2>, inv_count: T, com: Array<Vec3<T>>) {
    let (r, c) = tid();
    atomic_add(com, 0, x[(r, c)] * inv_count);
}

/// loss = |com - target|^2.
#[wp::kernel]
fn distance_sq<T: Float>(com: Array<Vec3<T>>, target: Vec3<T>, loss: Array<T>) {
    let d = com[0] - target;
    loss[0] = dot(d, d);
}

/// The cloth's constants.
#[derive(Clone, Copy, Debug)]
struct Setup {
    n: usize,
    steps: usize,
    dt: f64,
    spacing: f64,
    mass: f64,
}

const SIZE: f64 = 1.0; // m
const TOTAL_MASS: f64 = 0.2; // kg
const K_STRUCT: f64 = 100.0; // N/m
const K_SHEAR: f64 = 100.0;
const K_BEND: f64 = 5.0;
const K_DAMP: f64 = 0.002; // N s/m along a spring
const AIR: f64 = 1e-4; // N s/m per particle
const G: f64 = -9.81;

impl Setup {
    /// An n x n cloth simulated for `t_end` with the largest step that keeps a margin of 2
    /// under the stability bound of semi-implicit Euler, 2 / omega_max, with omega_max^2
    /// bounded by 2 (sum of a particle's spring stiffnesses) / m (Gershgorin).
    fn new(n: usize, t_end: f64) -> Setup {
        let mass = TOTAL_MASS / (n * n) as f64;
        let ksum = 4.0 * (K_STRUCT + K_SHEAR + K_BEND);
        let omega = (2.0 * ksum / mass).sqrt();
        let steps = (t_end * omega).ceil() as usize;
        Setup {
            n,
            steps,
            dt: t_end / steps as f64,
            spacing: SIZE / (n - 1) as f64,
            mass,
        }
    }

    /// The flat start: row r along z, column c along x, in the plane y = 0.
    fn start(&self) -> Vec<DVec3> {
        let mut x = Vec::with_capacity(self.n * self.n);
        for r in 0..self.n {
            for c in 0..self.n {
                x.push(DVec3::new(
                    c as f64 * self.spacing,
                    0.0,
                    r as f64 * self.spacing,
                ));
            }
        }
        x
    }
}

/// The cloth's state over a trajectory, in one precision: `$s` the scalar, `$v` its Vec3.
macro_rules! cloth {
    ($name:ident, $s:ty, $v:ty) => {
        struct $name {
            setup: Setup,
            xs: Vec<wp::Array<$v, 2>>,
            vs: Vec<wp::Array<$v, 2>>,
            com: wp::Array<$v>,
            loss: wp::Array<$s>,
        }

        impl $name {
            fn new(setup: Setup, dev: &wp::Device) -> wp::Result<$name> {
                let n = setup.n;
                let start: Vec<$v> = setup
                    .start()
                    .iter()
                    .map(|p| <$v>::from(p.to_array().map(|c| c as $s)))
                    .collect();
                let mut xs = vec![wp::Array::from_slice_shape(&start, (n, n), dev)?.with_grad()?];
                let mut vs = vec![wp::Array::<$v, 2>::zeros((n, n), dev)?.with_grad()?];
                for _ in 0..setup.steps {
                    xs.push(wp::Array::<$v, 2>::zeros((n, n), dev)?.with_grad()?);
                    vs.push(wp::Array::<$v, 2>::zeros((n, n), dev)?.with_grad()?);
                }
                Ok($name {
                    setup,
                    xs,
                    vs,
                    com: wp::Array::zeros(1, dev)?.with_grad()?,
                    loss: wp::Array::zeros(1, dev)?.with_grad()?,
                })
            }

            /// The trajectory from vs[0], the centre of mass at T and the loss against
            /// `target` (onto any tape recording on this thread); returns (com, loss).
            fn forward(&self, target: DVec3, dev: &wp::Device) -> wp::Result<(DVec3, f64)> {
                let s = &self.setup;
                let n = s.n;
                let springs = <$v>::new(K_STRUCT as $s, K_SHEAR as $s, K_BEND as $s);
                let gravity = <$v>::new(0.0, G as $s, 0.0);
                for k in 0..s.steps {
                    wp::launch(
                        cloth_step,
                        (n, n),
                        (
                            &self.xs[k],
                            &self.vs[k],
                            &self.xs[k + 1],
                            &self.vs[k + 1],
                            springs,
                            K_DAMP as $s,
                            s.spacing as $s,
                            s.mass as $s,
                            AIR as $s,
                            gravity,
                            s.dt as $s,
                        ),
                        dev,
                    )?;
                }
                self.com.fill(<$v>::ZERO)?;
                let inv = 1.0 / (n * n) as $s;
                wp::launch(centre, (n, n), (&self.xs[s.steps], inv, &self.com), dev)?;
                let t = <$v>::new(target.x as $s, target.y as $s, target.z as $s);
                wp::launch(distance_sq, 1, (&self.com, t, &self.loss), dev)?;
                let c = self.com.to_vec()?[0];
                let com = DVec3::new(c.x as f64, c.y as f64, c.z as f64);
                Ok((com, self.loss.to_vec()?[0] as f64))
            }

            /// (com, loss) and the gradient of the loss with respect to the initial
            /// velocities (added to vs[0]'s gradient; every other gradient zeroed after).
            fn gradient(&self, target: DVec3, dev: &wp::Device) -> wp::Result<(DVec3, f64)> {
                let tape = wp::Tape::new();
                let out = {
                    let _rec = tape.record();
                    self.forward(target, dev)?
                };
                tape.backward(&self.loss)?;
                for a in self.xs.iter().chain(&self.vs[1..]) {
                    a.zero_grad()?;
                }
                self.com.zero_grad()?;
                self.loss.zero_grad()?;
                Ok(out)
            }

            /// The initial velocities' gradient, in f64.
            fn v0_grad(&self) -> wp::Result<Vec<DVec3>> {
                Ok(self.vs[0]
                    .grad()
                    .expect("with_grad")
                    .to_vec()?
                    .iter()
                    .map(|g| DVec3::new(g.x as f64, g.y as f64, g.z as f64))
                    .collect())
            }

            // (Only the f64 instance optimises.)
            #[allow(dead_code)]
            /// (com, loss) and the Jacobian of the centre of mass at T with respect to the
            /// initial velocities: one recorded forward pass and three backward passes, each
            /// seeded with one component of the centre of mass (row k: d com_k / d v0).
            fn jacobian(
                &self,
                target: DVec3,
                dev: &wp::Device,
            ) -> wp::Result<(DVec3, f64, [Vec<DVec3>; 3])> {
                let tape = wp::Tape::new();
                let out = {
                    let _rec = tape.record();
                    self.forward(target, dev)?
                };
                let mut rows: [Vec<DVec3>; 3] = Default::default();
                for (k, row) in rows.iter_mut().enumerate() {
                    self.zero_grads()?;
                    let mut seed = <$v>::ZERO;
                    seed[k] = 1.0;
                    self.com.grad().expect("with_grad").fill(seed)?;
                    tape.backward_from_grads()?;
                    *row = self.v0_grad()?;
                }
                self.zero_grads()?;
                Ok((out.0, out.1, rows))
            }

            #[allow(dead_code)]
            /// Zeroes every gradient of the trajectory.
            fn zero_grads(&self) -> wp::Result<()> {
                for a in self.xs.iter().chain(&self.vs) {
                    a.zero_grad()?;
                }
                self.com.zero_grad()?;
                self.loss.zero_grad()
            }

            /// Sets the initial velocities.
            fn set_v0(&self, v: &[DVec3], dev: &wp::Device) -> wp::Result<()> {
                let v: Vec<$v> = v
                    .iter()
                    .map(|p| <$v>::from(p.to_array().map(|c| c as $s)))
                    .collect();
                let n = self.setup.n;
                self.vs[0].copy_from(&wp::Array::from_slice_shape(&v, (n, n), dev)?)
            }
        }
    };
}

cloth!(Cloth32, f32, Vec3);
cloth!(Cloth64, f64, DVec3);

/// The gradient check, in f64. The free edge whips, so some components have a large third
/// derivative: on the 32 x 32 cloth the far edge's vertical one is off by 4e-3 relative with
/// a central difference of h = 4e-4 m/s and by 2e-4 at h = 1e-4, while below h = 1e-5 the
/// rounding of the difference (about eps |L| / h, grown over the steps) takes over. So the
/// check takes Richardson's extrapolation of two central differences,
/// (4 D(h/2) - D(h)) / 3, which cancels the h^2 term, with h = H_FD. Errors are relative to
/// each derivative but at least SCALE_FLOOR of the largest probed one: the held corner's and
/// the sideways derivatives are 1e-3 to 1e-4 of the vertical ones, where the difference's
/// rounding (about 3e-12 absolute on the 64 x 64 cloth) is all that is left. Measured worst:
/// 2e-6 on the 16 x 16 cloth, 3e-5 on the 32 x 32 one, 2e-5 on the 64 x 64 one; TOL_FD
/// leaves a margin over that.
const H_FD: f64 = 1e-4;
const TOL_FD: f64 = 1e-4;
const SCALE_FLOOR: f64 = 1e-2;

/// The initial velocities as parameters: every particle's velocity is a fixed start `base` plus
/// a piecewise-bilinear interpolation of the velocities `theta` at a k x k grid of control
/// nodes spread over the cloth (`--field k`; k = 1 is one velocity for the whole cloth), or,
/// with k = 0, every particle's own velocity. A smooth field keeps the swing coherent: per
/// particle, the 64 x 64 cloth's first step already kicks the free edge into a whip that the
/// linearisation does not see, and Gauss-Newton stalls at about 1 cm (gradient descent at
/// 4 mm).
struct Field {
    n: usize,
    k: usize,
}

impl Field {
    /// How many parameters (each a velocity).
    fn nodes(&self) -> usize {
        if self.k == 0 {
            self.n * self.n
        } else {
            self.k * self.k
        }
    }

    /// Particle `i`'s nodes and their weights.
    fn weights(&self, i: usize) -> Vec<(usize, f64)> {
        let (n, k) = (self.n, self.k);
        match k {
            0 => vec![(i, 1.0)],
            1 => vec![(0, 1.0)],
            _ => {
                let at = |x: usize| {
                    let s = x as f64 / (n - 1) as f64 * (k - 1) as f64;
                    let a = (s.floor() as usize).min(k - 2);
                    (a, s - a as f64)
                };
                let ((a, fa), (b, fb)) = (at(i / n), at(i % n));
                vec![
                    (a * k + b, (1.0 - fa) * (1.0 - fb)),
                    (a * k + b + 1, (1.0 - fa) * fb),
                    ((a + 1) * k + b, fa * (1.0 - fb)),
                    ((a + 1) * k + b + 1, fa * fb),
                ]
            }
        }
    }

    /// Every particle's velocity.
    fn velocities(&self, base: &[DVec3], theta: &[DVec3]) -> Vec<DVec3> {
        (0..base.len())
            .map(|i| {
                base[i]
                    + self
                        .weights(i)
                        .iter()
                        .map(|&(a, w)| theta[a] * w)
                        .sum::<DVec3>()
            })
            .collect()
    }

    /// The Jacobian's rows with respect to the parameters, from those with respect to every
    /// particle's velocity (the chain rule through the interpolation).
    fn project(&self, rows: &[Vec<DVec3>; 3]) -> [Vec<DVec3>; 3] {
        let mut out: [Vec<DVec3>; 3] = Default::default();
        for (k, row) in rows.iter().enumerate() {
            out[k] = vec![DVec3::ZERO; self.nodes()];
            for (i, g) in row.iter().enumerate() {
                for (a, w) in self.weights(i) {
                    out[k][a] += *g * w;
                }
            }
        }
        out
    }
}

/// The Gauss-Newton step for the three residuals r = com_T - target: the smallest change of
/// the initial velocities that cancels r to first order, dv = -J^T (J J^T)^-1 r (J's rows
/// `rows`), scaled by `alpha`, added to `v`. J J^T is 3 x 3 and, with the cloth free to move
/// in every direction, well conditioned; a relative damping of 1e-9 of its trace keeps the
/// solve defined if it were not (Levenberg-Marquardt).
fn gauss_newton(v: &[DVec3], r: DVec3, rows: &[Vec<DVec3>; 3], alpha: f64) -> Vec<DVec3> {
    let dot = |a: &[DVec3], b: &[DVec3]| a.iter().zip(b).map(|(p, q)| p.dot(*q)).sum::<f64>();
    let mut jjt = DMat3::ZERO;
    for i in 0..3 {
        for j in 0..3 {
            jjt.col_mut(j)[i] = dot(&rows[i], &rows[j]);
        }
    }
    let damping = 1e-9 * (jjt.x_axis.x + jjt.y_axis.y + jjt.z_axis.z);
    let y = (jjt + DMat3::from_diagonal(DVec3::splat(damping))).inverse() * r;
    (0..v.len())
        .map(|i| v[i] - alpha * (rows[0][i] * y.x + rows[1][i] * y.y + rows[2][i] * y.z))
        .collect()
}

/// A cloth held at two corners: Gauss-Newton finds the initial velocities that bring its
/// centre of mass to a target.
#[derive(Parser)]
struct Cli {
    /// Particles per side of the cloth [default: 64 on a GPU, 16 on the CPU]
    #[arg(long, value_parser = common::num::<usize>)]
    n: Option<usize>,
    /// Simulated time (s)
    #[arg(long, default_value_t = 0.3)]
    t_end: f64,
    /// Most Gauss-Newton iterations
    #[arg(long, default_value_t = 30, value_parser = common::num::<usize>)]
    iterations: usize,
    /// The initial velocities: a bilinear field over k x k control nodes (1: one velocity
    /// for the whole cloth; 0: every particle's own)
    #[arg(long, value_name = "K", default_value_t = 4, value_parser = common::num::<usize>)]
    field: usize,
    /// Converged when the centre of mass is within this distance of the target (m)
    #[arg(long, default_value_t = 1e-3)]
    tol: f64,
    /// The target: the centre of mass the cloth reaches from rest, moved by x,y,z (m)
    #[arg(long, value_name = "X,Y,Z", default_value = "0,0.1,0.05", value_parser = parse_offset)]
    offset: DVec3,
    #[command(flatten)]
    scene: common::SceneArgs,
}

/// `--offset x,y,z`: three numbers (metres).
fn parse_offset(text: &str) -> Result<DVec3, String> {
    let c: Vec<f64> = text
        .split(',')
        .map(|c| c.trim().parse::<f64>().map_err(|e| e.to_string()))
        .collect::<Result<_, _>>()?;
    match c[..] {
        [x, y, z] => Ok(DVec3::new(x, y, z)),
        _ => Err("want three numbers, x,y,z (metres)".into()),
    }
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let n = cli.n.unwrap_or(if dev.is_cuda() { 64 } else { 16 });
    let (t_end, iterations, field_k) = (cli.t_end, cli.iterations, cli.field);
    let field_nodes = Field { n, k: field_k }.nodes();
    let field_what = match field_k {
        0 => "every particle's own".to_string(),
        1 => "one for the whole cloth".to_string(),
        k => format!("a bilinear field over {k} x {k} control nodes"),
    };
    let (tol, offset) = (cli.tol, cli.offset);
    if n < 3 || t_end <= 0.0 || field_k > n {
        eprintln!("--n must be at least 3, --t-end positive and --field at most --n");
        std::process::exit(2);
    }
    let setup = Setup::new(n, t_end);
    println!(
        "cloth: {n} x {n} = {} particles on \"{dev}\", structural + shear + bending springs, \
         held at two corners, {} steps of {} s (t_end {t_end} s); parameters: the initial \
         velocities, {field_what} ({} numbers)",
        n * n,
        setup.steps,
        sci(setup.dt),
        3 * field_nodes
    );

    // The target: where the cloth's centre of mass gets from rest, moved.
    let c64 = Cloth64::new(setup, &dev)?;
    let (rest_com, _) = c64.forward(DVec3::ZERO, &dev)?;
    let target = rest_com + offset;
    println!(
        "centre of mass at T from rest: ({:.4}, {:.4}, {:.4}) m; target ({:.4}, {:.4}, {:.4}) m",
        rest_com.x, rest_com.y, rest_com.z, target.x, target.y, target.z
    );

    // The gradient check at the start (initial velocities of about 1 cm/s, not zero, so that
    // the check is not at a special point): f64 tape against central differences, and
    // the f32 tape beside them.
    let mut rng = common::rng(3);
    let v_start: Vec<DVec3> = (0..n * n)
        .map(|_| {
            DVec3::new(
                rng.sample::<f64, _>(StandardNormal),
                rng.sample::<f64, _>(StandardNormal),
                rng.sample::<f64, _>(StandardNormal),
            ) * 0.01
        })
        .collect();
    c64.set_v0(&v_start, &dev)?;
    let (_, loss64) = c64.gradient(target, &dev)?;
    let g64 = c64.v0_grad()?;
    let c32 = Cloth32::new(setup, &dev)?;
    c32.set_v0(&v_start, &dev)?;
    c32.gradient(target, &dev)?;
    let g32 = c32.v0_grad()?;
    let probes = [
        (n - 1, 0, "far corner"),
        (n - 1, n / 2, "far edge, middle"),
        (n / 2, n / 2, "centre"),
        (0, n / 2, "held edge, middle"),
        (0, 0, "held corner"),
    ];
    let h = H_FD;
    println!(
        "\ngradient at the start (loss {}), f64 tape against central differences \
         (Richardson's extrapolation from h = {} m/s and h/2), and the f32 tape:",
        sci(loss64),
        sci(h)
    );
    let mut t = Table::new([
        "particle (row, col)",
        "component",
        "central difference",
        "f64 tape",
        "rel. error",
        "f32 tape",
        "rel. error",
    ]);
    // Central differences of every probed component first: errors are relative to each
    // derivative, or to SCALE_FLOOR of the largest one for derivatives much smaller than
    // that (a held corner's are about 0), where the difference's rounding dominates.
    let mut rows = Vec::new();
    for &(r, c, what) in &probes {
        let i = r * n + c;
        for k in 0..3 {
            let mut d = [0.0f64; 2];
            for (j, step) in [h, h / 2.0].into_iter().enumerate() {
                let mut v = v_start.clone();
                v[i][k] += step;
                c64.set_v0(&v, &dev)?;
                let (_, lp) = c64.forward(target, &dev)?;
                v[i][k] -= 2.0 * step;
                c64.set_v0(&v, &dev)?;
                let (_, lm) = c64.forward(target, &dev)?;
                d[j] = (lp - lm) / (2.0 * step);
            }
            rows.push((r, c, what, i, k, (4.0 * d[1] - d[0]) / 3.0));
        }
    }
    let scale = rows.iter().fold(0.0f64, |m, r| m.max(r.5.abs()));
    let mut worst64 = 0.0f64;
    let mut worst32 = 0.0f64;
    for &(r, c, what, i, k, fd) in &rows {
        let (e64, e32) = (
            common::rel_err(g64[i][k], fd, SCALE_FLOOR * scale),
            common::rel_err(g32[i][k], fd, SCALE_FLOOR * scale),
        );
        worst64 = worst64.max(e64);
        worst32 = worst32.max(e32);
        t.push([
            format!("({r}, {c}) {what}"),
            ["x", "y", "z"][k].to_string(),
            format!("{fd:.6e}"),
            format!("{:.6e}", g64[i][k]),
            sci(e64),
            format!("{:.6e}", g32[i][k]),
            sci(e32),
        ]);
    }
    print!("{t}");
    println!(
        "worst (relative, with a floor of {} x the largest derivative): f64 tape {} \
         (tolerance {}), f32 tape {} (reported, not judged: f32 rounding over {} steps)",
        sci(SCALE_FLOOR),
        sci(worst64),
        sci(TOL_FD),
        sci(worst32),
        setup.steps
    );
    let check_ok = worst64 < TOL_FD;
    drop(c32);

    // Gauss-Newton on the f64 simulation (Levenberg-Marquardt damped, with backtracking).
    let mut log = common::OptLog::new(
        &format!(
            "cloth: Gauss-Newton (minimum-norm steps) on {} numbers, the initial velocities ({}), {n} x {n} cloth, {} steps, on {dev}",
            3 * field_nodes,
            field_what,
            setup.steps
        ),
        "loss",
        &["|com_T - target| (m)"],
        1,
    )
    .progress(iterations as u64);
    let field = Field { n, k: field_k };
    let mut theta = vec![DVec3::ZERO; field.nodes()];
    c64.set_v0(&field.velocities(&v_start, &theta), &dev)?;
    let mut kept = theta.clone();
    let mut kept_loss = f64::INFINITY;
    let mut last: Option<(DVec3, [Vec<DVec3>; 3])> = None;
    let mut alpha = 1.0f64;
    let mut backtracks = 0;
    let mut miss = f64::INFINITY;
    let mut its = iterations;
    let mut nonfinite = None;
    for it in 1..=iterations {
        let (com, loss, rows) = c64.jacobian(target, &dev)?;
        if !loss.is_finite() || loss > kept_loss {
            // Back to the last accepted parameters with half the step.
            backtracks += 1;
            alpha *= 0.5;
            log.record(
                "Gauss-Newton, f64",
                it,
                kept_loss,
                f64::NAN,
                &[format!("{} (step halved)", sci(miss))],
                it == iterations,
            );
            let (r, rows) = last.as_ref().expect("the first iteration is accepted");
            theta = gauss_newton(&kept, *r, rows, alpha);
            c64.set_v0(&field.velocities(&v_start, &theta), &dev)?;
            continue;
        }
        if rows.iter().flatten().any(|g| !g.is_finite()) {
            nonfinite = Some(it);
            break;
        }
        let rows = field.project(&rows);
        kept.clone_from(&theta);
        kept_loss = loss;
        miss = (com - target).length();
        // The loss's gradient with respect to the parameters, 2 J^T r.
        let r = com - target;
        let gnorm = (0..rows[0].len())
            .map(|i| {
                (2.0 * (rows[0][i] * r.x + rows[1][i] * r.y + rows[2][i] * r.z)).length_squared()
            })
            .sum::<f64>()
            .sqrt();
        let done = miss < tol;
        log.record(
            "Gauss-Newton, f64",
            it,
            loss,
            gnorm,
            &[sci(miss)],
            done || it == iterations,
        );
        if done {
            its = it;
            break;
        }
        alpha = (2.0 * alpha).min(1.0);
        theta = gauss_newton(&kept, r, &rows, alpha);
        c64.set_v0(&field.velocities(&v_start, &theta), &dev)?;
        last = Some((r, rows));
    }
    if backtracks > 0 {
        println!("(the step was halved {backtracks} time(s) after a step that raised the loss)");
    }
    if let Some(it) = nonfinite {
        println!("non-finite gradient at iteration {it}: stopped (the simulation went unstable)");
    }
    log.finish("cloth");
    let vmax = field
        .velocities(&v_start, &kept)
        .iter()
        .map(|p| p.length())
        .fold(0.0f64, f64::max);
    println!(
        "\nafter {its} iterations: |com_T - target| = {} m; largest initial speed {:.3} m/s",
        sci(miss),
        vmax
    );
    // The frame: the trajectory from the kept initial velocities, the cloth at its start, half
    // way and at T, the centre of mass at T and the target.
    c64.set_v0(&field.velocities(&v_start, &kept), &dev)?;
    let (com, _) = c64.forward(target, &dev)?;
    let steps = c64.setup.steps;
    let grid = common::grid_triangles(n);
    let cloth_at = |k: usize| -> wp::Result<Vec<[f64; 3]>> {
        Ok(c64.xs[k].to_vec()?.iter().map(|&p| common::p3(p)).collect())
    };
    let (start, middle, end) = (cloth_at(0)?, cloth_at(steps / 2)?, cloth_at(steps)?);
    let all: Vec<[f64; 3]> = [&start[..], &middle[..], &end[..]].concat();
    let (lo, hi) = common::bounds(&all);
    let frame = Frame::new(
        format!("cloth: {n} x {n} particles thrown to the target (t = 0, T/2, T = {t_end} s)"),
        common::camera(lo, hi, [1.4, 0.5, 1.0], [0.0, 1.0, 0.0]),
    )
    .note(format!(
        "held at two corners; wireframes: t = 0 and T/2; the centre of mass at T (black) is \
         {} m from the target (red)",
        sci((com - target).length())
    ))
    .mesh(
        TriMesh::new(start, grid.clone())
            .wireframe()
            .colour([170, 170, 170]),
    )
    .mesh(
        TriMesh::new(middle, grid.clone())
            .wireframe()
            .colour([110, 140, 200]),
    )
    .mesh(TriMesh::new(end, grid.clone()).colour([220, 120, 90]))
    .points(Points::new([common::p3(com)], 0.02).colour([20, 20, 20]))
    .points(Points::new([common::p3(target)], 0.02).colour([200, 30, 30]));
    common::write_frame("cloth", &frame);
    let mut rec = cli.scene.recorder("cloth");
    if rec.is_on() {
        // The recording: the same trajectory (every step is on the tape), about 100 frames of
        // it, the cloth shaded with the target beside it.
        let every = common::record::every(steps);
        for k in (0..=steps).filter(|&k| k % every == 0 || k == steps) {
            let t = k as f64 * c64.setup.dt;
            let frame = Frame::new(
                format!("cloth: {n} x {n} particles thrown to the target, t = {t:.3} s"),
                common::camera(lo, hi, [1.4, 0.5, 1.0], [0.0, 1.0, 0.0]),
            )
            .note("held at two corners; the target of the centre of mass at T (red)")
            .mesh(TriMesh::new(cloth_at(k)?, grid.clone()).colour([220, 120, 90]))
            .points(Points::new([common::p3(target)], 0.02).colour([200, 30, 30]));
            rec.frame(k, t, &frame);
        }
        rec.finish();
    }
    common::print_compiled();
    let converged = miss < tol;
    common::verdict(
        "cloth",
        check_ok && converged,
        &format!(
            "f64 tape gradient within {} of central differences: {}; centre of mass within {} m \
             of the target in at most {iterations} iterations: {}",
            sci(TOL_FD),
            if check_ok { "yes" } else { "no" },
            sci(tol),
            if converged { "yes" } else { "no" }
        ),
    );
    Ok(())
}

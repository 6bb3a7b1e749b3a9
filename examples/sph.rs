//! A 3-D SPH dam break and a hydrostatic column: weakly compressible SPH with neighbours found
//! through a `HashGrid` queried from the kernels.
//!
//! The scheme (Monaghan 1992/1994; walls as in DualSPHysics's dynamic boundary particles,
//! Crespo et al. 2007): cubic-spline kernel with support 2h, h = 1.2 dx; density by summation
//! over fluid and wall particles; Tait's equation of state p = B ((rho / rho0)^7 - 1), B =
//! rho0 c0^2 / 7, negative pressure clamped to zero (a free surface, no tension); symmetric
//! pressure force and Monaghan's artificial viscosity (alpha = 0.1); three layers of fixed wall
//! particles that take part in the density and the forces like fluid, but never move; the
//! speed of sound c0 = 10 sqrt(2 g H) keeps density variations near 1%; semi-implicit Euler
//! with dt = cfl h / c0.
//!
//! What it reports (error next to run time, as tables and plots):
//! 1. hydrostatic column, swept over particle spacing: after settling, the relative RMS error
//!    of the pressure of the column's interior particles against rho0 g depth;
//! 2. dam break, swept over dt (as the CFL number) and over particle count: the largest
//!    compression rho / rho0 - 1 over the run (WCSPH's own error measure: the fluid is meant
//!    to be incompressible; summation's deficit at the free surface is not counted, the
//!    clamped pressure ignores it), the run time, and where it blew up: the stability limit
//!    in the CFL number.
//!
//! `--graph` also runs both with the steps captured into a graph, 64 steps (grid builds,
//! density and force kernels) recorded once and replayed, as series of their own (`.. graph`):
//! the run times (the capture included) beside the uncaptured ones, and the same errors (the
//! replays do the same work in the same order, and the checks come after the same steps).

mod common;

use clap::Parser;
use std::time::Instant;

use warp_lang as wp;
use warp_report::frame::{Frame, Lines, Points};
use warp_report::{Run, Sweep};
use wp::prelude::*;

const PI_F: f32 = std::f32::consts::PI;

/// The cubic spline's derivative dW/dr over r (so that grad W = r_vec * (dW/dr / r)), for
/// support 2h; zero at r = 0 and beyond the support.
#[wp::func]
fn grad_w_over_r(r: f32, h: f32) -> f32 {
    let q = r / h;
    let sigma = 1.0 / (PI_F * h * h * h);
    let mut d = 0.0;
    if q < 1.0 {
        d = sigma / h * (-3.0 * q + 2.25 * q * q);
    } else if q < 2.0 {
        d = sigma / h * (-0.75 * (2.0 - q) * (2.0 - q));
    }
    if r > 0.0 {
        d = d / r;
    }
    d
}

/// The cubic spline W(r, h) with support 2h.
#[wp::func]
fn kernel_w(r: f32, h: f32) -> f32 {
    let q = r / h;
    let sigma = 1.0 / (PI_F * h * h * h);
    let mut w = 0.0;
    if q < 1.0 {
        w = sigma * (1.0 - 1.5 * q * q + 0.75 * q * q * q);
    } else if q < 2.0 {
        w = sigma * 0.25 * (2.0 - q) * (2.0 - q) * (2.0 - q);
    }
    w
}

/// Density by summation, and pressure from Tait's equation (clamped at zero).
#[wp::kernel]
fn density(
    grid: HashGrid,
    x: Array<Vec3>,
    rho: Array<f32>,
    p: Array<f32>,
    mass: f32,
    h: f32,
    rho0: f32,
    b: f32,
) {
    let i = hash_grid_point_id(grid, tid());
    let xi = x[i];
    let mut sum = 0.0;
    for j in hash_grid_query(grid, xi, 2.0 * h) {
        sum += mass * kernel_w(length(xi - x[j]), h);
    }
    rho[i] = sum;
    let ratio = sum / rho0;
    let r2 = ratio * ratio;
    p[i] = max(b * (r2 * r2 * r2 * ratio - 1.0), 0.0);
}

/// Pressure force, artificial viscosity and gravity; then semi-implicit Euler for fluid
/// particles (`fluid[i] != 0`). Reads `x`, `v`, writes `x_new`, `v_new` (every thread sees
/// the same state).
#[wp::kernel]
fn step(
    grid: HashGrid,
    x: Array<Vec3>,
    v: Array<Vec3>,
    x_new: Array<Vec3>,
    v_new: Array<Vec3>,
    rho: Array<f32>,
    p: Array<f32>,
    fluid: Array<i32>,
    mass: f32,
    h: f32,
    c0: f32,
    alpha: f32,
    gravity: Vec3,
    dt: f32,
) {
    let i = hash_grid_point_id(grid, tid());
    let xi = x[i];
    let vi = v[i];
    if fluid[i] == 0 {
        x_new[i] = xi;
        v_new[i] = vi;
    } else {
        let rho_i = rho[i];
        let p_i = p[i];
        let mut a = gravity;
        for j in hash_grid_query(grid, xi, 2.0 * h) {
            if j != i {
                let d = xi - x[j];
                let r = length(d);
                if r < 2.0 * h && r > 0.0 {
                    let rho_j = rho[j];
                    let p_j = p[j];
                    let mut coef = p_i / (rho_i * rho_i) + p_j / (rho_j * rho_j);
                    let vd = dot(vi - v[j], d);
                    if vd < 0.0 {
                        let mu = h * vd / (r * r + 0.01 * h * h);
                        coef += -alpha * c0 * mu / (0.5 * (rho_i + rho_j));
                    }
                    a -= d * (mass * coef * grad_w_over_r(r, h));
                }
            }
        }
        let vn = vi + a * dt;
        v_new[i] = vn;
        x_new[i] = xi + vn * dt;
    }
}

/// Fluid and wall particles on the device, and the scheme's constants.
struct Sph {
    x: wp::Array<Vec3>,
    v: wp::Array<Vec3>,
    x2: wp::Array<Vec3>,
    v2: wp::Array<Vec3>,
    rho: wp::Array<f32>,
    p: wp::Array<f32>,
    fluid: wp::Array<i32>,
    grid: wp::HashGrid,
    n_fluid: usize,
    h: f32,
    mass: f32,
    rho0: f32,
    c0: f32,
    b: f32,
    gravity: Vec3,
    dev: wp::Device,
}

/// A box [0, size] with walls of three layers below, around, and (if `lid`) above, and fluid
/// filling [0, fluid_size] from the corner at the origin, on a lattice of spacing `dx`.
fn layout(size: Vec3, fluid_size: Vec3, dx: f32) -> (Vec<Vec3>, Vec<i32>) {
    let mut x = Vec::new();
    let mut fluid = Vec::new();
    let n = |l: f32| (l / dx).round() as i32;
    let (nx, ny, nz) = (n(size.x), n(size.y), n(size.z));
    let (fx, fy, fz) = (n(fluid_size.x), n(fluid_size.y), n(fluid_size.z));
    for a in -3..nx + 3 {
        for b in -3..ny {
            for c in -3..nz + 3 {
                let p = Vec3::new(
                    (a as f32 + 0.5) * dx,
                    (b as f32 + 0.5) * dx,
                    (c as f32 + 0.5) * dx,
                );
                let wall = a < 0 || a >= nx || b < 0 || c < 0 || c >= nz;
                let water = a < fx && b < fy && c < fz && !wall;
                if wall || water {
                    x.push(p);
                    fluid.push(i32::from(water));
                }
            }
        }
    }
    (x, fluid)
}

impl Sph {
    fn new(x0: &[Vec3], fluid: &[i32], dx: f32, depth: f32, dev: &wp::Device) -> wp::Result<Sph> {
        let n = x0.len();
        let rho0 = 1000.0f32;
        let g = 9.81f32;
        let c0 = 10.0 * (2.0 * g * depth).sqrt();
        let h = 1.2 * dx;
        let mut grid = wp::HashGrid::new(128, 128, 128, dev)?;
        grid.reserve(n)?;
        Ok(Sph {
            x: wp::Array::from_slice(x0, dev)?,
            v: wp::Array::zeros(n, dev)?,
            x2: wp::Array::zeros(n, dev)?,
            v2: wp::Array::zeros(n, dev)?,
            rho: wp::Array::zeros(n, dev)?,
            p: wp::Array::zeros(n, dev)?,
            fluid: wp::Array::from_slice(fluid, dev)?,
            grid,
            n_fluid: fluid.iter().filter(|&&f| f != 0).count(),
            h,
            mass: rho0 * dx * dx * dx,
            rho0,
            c0,
            b: rho0 * c0 * c0 / 7.0,
            gravity: Vec3::new(0.0, -g, 0.0),
            dev: dev.clone(),
        })
    }

    /// One step of `dt`: a grid build, density and pressure, forces and integration.
    fn step(&mut self, dt: f32) -> wp::Result<()> {
        let n = self.x.len();
        self.grid.build(&self.x, 2.0 * self.h)?;
        let args = (
            &self.grid, &self.x, &self.rho, &self.p, self.mass, self.h, self.rho0, self.b,
        );
        wp::launch(density, n, args, &self.dev)?;
        let args = (
            &self.grid,
            &self.x,
            &self.v,
            &self.x2,
            &self.v2,
            &self.rho,
            &self.p,
            &self.fluid,
            self.mass,
            self.h,
            self.c0,
            0.1f32,
            self.gravity,
            dt,
        );
        wp::launch(step, n, args, &self.dev)?;
        std::mem::swap(&mut self.x, &mut self.x2);
        std::mem::swap(&mut self.v, &mut self.v2);
        Ok(())
    }

    fn dt(&self, cfl: f32) -> f32 {
        cfl * self.h / self.c0
    }
}

/// The steps one graph replay runs (`--graph`): even, since each step swaps the old and new
/// arrays (after a replay they are where the capture found them).
const GRAPH_STEPS: usize = 64;
const _: () = assert!(GRAPH_STEPS.is_multiple_of(2));

/// Runs steps `1..steps` of `s` (step 0, the warm-up, is the caller's: on a GPU it compiles
/// the kernels and loads the grid build's, which a capture may not), in chunks of
/// [`GRAPH_STEPS`] (with `graph`, each whole chunk a replay of a captured one: the scenes'
/// `common::Stepper`); `check(s, k)` after step `k` whenever `every` (a multiple of the chunk)
/// divides `k` and after the last step, so after the same steps either way; it returns
/// `Some(why)` to stop (a blow-up). The run time (the capture included), and why it stopped.
fn run_steps(
    s: &mut Sph,
    steps: usize,
    dt: f32,
    graph: bool,
    every: usize,
    mut check: impl FnMut(&Sph, usize) -> wp::Result<Option<String>>,
) -> wp::Result<(f64, Option<String>)> {
    debug_assert!(every.is_multiple_of(GRAPH_STEPS));
    let dev = s.dev.clone();
    let mut stepper = common::Stepper::new(graph, GRAPH_STEPS);
    wp::synchronize()?;
    let t = Instant::now();
    let mut k = 1;
    while k < steps {
        let n = GRAPH_STEPS.min(steps - k);
        stepper.advance(&dev, n, &mut || s.step(dt))?;
        let last = k + n - 1;
        if last.is_multiple_of(every) || last + 1 == steps {
            if let Some(why) = check(s, last)? {
                return Ok((t.elapsed().as_secs_f64(), Some(why)));
            }
        }
        k = last + 1;
    }
    wp::synchronize()?;
    Ok((t.elapsed().as_secs_f64(), None))
}

/// Weakly compressible SPH: a hydrostatic column's pressure against rho0 g depth, and a dam
/// break's compression and stability limit against dt.
#[derive(Parser)]
struct Cli {
    /// Particle spacing (m) [default: 0.015 on a GPU, 0.03 on the CPU]
    #[arg(long)]
    dx: Option<f32>,
    /// Also run the scenes with the steps captured into a graph (64 steps recorded once and
    /// replayed): printed beside the uncaptured runs
    #[arg(long)]
    graph: bool,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let gpu = dev.to_string() != "cpu";
    let dx = cli.dx.unwrap_or(if gpu { 0.015 } else { 0.03 });
    println!("SPH (WCSPH, cubic spline, dynamic wall particles) on \"{dev}\"");
    let modes = common::graph_modes(cli.graph);
    hydrostatic(&dev, dx, modes)?;
    dam_break(&dev, dx, modes)?;
    let mut rec = cli.scene.recorder("sph");
    if rec.is_on() {
        record_dam_break(&dev, dx, &mut rec)?;
        rec.finish();
    }
    common::print_compiled();
    Ok(())
}

/// A column of water 0.4 m deep at rest in a box, settled for 1 s (the viscosity damps the
/// start-up waves), then the pressure of the particles at least 2 dx from every wall and the
/// surface against rho0 g depth (depth from the fluid's top, the highest fluid particle plus
/// half a spacing).
fn hydrostatic(dev: &wp::Device, dx: f32, modes: &[bool]) -> wp::Result<()> {
    let depth = 0.4f32;
    let mut sweep = Sweep::new(
        format!("hydrostatic column on {dev}: RMS |p - rho0 g d| / (rho0 g H)"),
        "dx (m)",
    )
    .with_extras(&["particles", "max rho/rho0 - 1"])
    .progress(3 * modes.len() as u64);
    println!("\n1. hydrostatic column, {depth} m deep, settled 1 s, CFL 0.25");
    for (k, &graph) in [2.0f32, 1.5, 1.0]
        .into_iter()
        .flat_map(|k| modes.iter().map(move |g| (k, g)))
    {
        let series = if graph { "f32 graph" } else { "f32" };
        let dx = dx * k;
        let size = Vec3::new(0.3, depth * 1.5, 0.3);
        let (x0, fluid) = layout(size, Vec3::new(0.3, depth, 0.3), dx);
        let mut s = Sph::new(&x0, &fluid, dx, depth, dev)?;
        let dt = s.dt(0.25);
        let steps = (1.0 / dt).ceil() as usize;
        s.step(dt)?;
        let (seconds, unstable) = run_steps(&mut s, steps, dt, graph, 256, |s, k| {
            Ok(s.x
                .check_finite("x")
                .err()
                .map(|e| format!("step {k}: {e}")))
        })?;
        if let Some(why) = unstable {
            sweep.record(series, dx as f64, Run::unstable(steps as u64, seconds, why));
            continue;
        }
        let (x, p, rho) = (s.x.to_vec()?, s.p.to_vec()?, s.rho.to_vec()?);
        let top = x
            .iter()
            .zip(&fluid)
            .filter(|(_, &f)| f != 0)
            .map(|(p, _)| p.y)
            .fold(f32::MIN, f32::max)
            + 0.5 * dx;
        let scale = (s.rho0 * 9.81 * depth) as f64;
        let (mut sq, mut count, mut worst_rho) = (0.0f64, 0usize, 0.0f64);
        for i in 0..x.len() {
            if fluid[i] == 0 {
                continue;
            }
            worst_rho = worst_rho.max((rho[i] / s.rho0 - 1.0) as f64);
            let q = x[i];
            let inside = q.x > 2.0 * dx
                && q.x < size.x - 2.0 * dx
                && q.z > 2.0 * dx
                && q.z < size.z - 2.0 * dx
                && q.y > 2.0 * dx
                && q.y < top - 2.0 * dx;
            if inside {
                let want = (s.rho0 * 9.81 * (top - q.y)) as f64;
                sq += ((p[i] as f64 - want) / scale).powi(2);
                count += 1;
            }
        }
        if count == 0 {
            let why = "no particle 2 dx inside the column: a finer dx is needed";
            sweep.record(series, dx as f64, Run::unstable(steps as u64, seconds, why));
            continue;
        }
        let err = (sq / count as f64).sqrt();
        sweep.record(
            series,
            dx as f64,
            Run::stable(steps as u64, err, seconds)
                .extra(s.n_fluid as f64)
                .extra(worst_rho),
        );
    }
    common::finish(&sweep, "sph_hydrostatic");
    Ok(())
}

/// A 0.4 m cube of water collapsing in a 1.2 m x 0.6 m x 0.4 m tank for 0.5 s: the largest
/// density deviation over the run, against the CFL number (up to past the limit) and against
/// the particle count.
fn dam_break(dev: &wp::Device, dx: f32, modes: &[bool]) -> wp::Result<()> {
    let (size, water, t_end) = (DAM_TANK, DAM_WATER, DAM_T_END);
    println!("\n2. dam break: a {water} m block in a {size} m tank, {t_end} s");
    let mut sweep = Sweep::new(
        format!("dam break on {dev}: max compression rho/rho0 - 1 over the run"),
        "CFL number (dt c0 / h)",
    )
    .with_extras(&["particles", "front x (m)"])
    // Six CFL numbers at the coarse spacing, the three up to 0.4 at the fine one.
    .progress((6 + 3) * modes.len() as u64);
    let cfls = [0.1f32, 0.2, 0.4, 0.8, 1.6, 3.2];
    // The frame: the water at t_end of the last stable run (finest spacing, largest CFL).
    let mut shown: Option<(Vec<Vec3>, Vec<f32>, f32, f32)> = None;
    for (k, spacing) in [(2.0f32, dx * 2.0), (1.0, dx)] {
        let (x0, fluid) = layout(size, water, spacing);
        for (&cfl, &graph) in cfls.iter().flat_map(|c| modes.iter().map(move |g| (c, g))) {
            // The finer resolution only at the usual CFL numbers (its runs are 8x longer).
            if k == 1.0 && cfl > 0.4 {
                continue;
            }
            let mut s = Sph::new(&x0, &fluid, spacing, water.y, dev)?;
            let dt = s.dt(cfl);
            let steps = (t_end / dt).ceil() as usize;
            s.step(dt)?;
            let mut worst = 0.0f64;
            let (seconds, why) = run_steps(&mut s, steps, dt, graph, 64, |s, k| {
                let rho = s.rho.to_vec()?;
                let dev_max = rho
                    .iter()
                    .zip(&fluid)
                    .filter(|(_, &f)| f != 0)
                    .map(|(r, _)| (r / s.rho0 - 1.0) as f64)
                    .fold(0.0f64, |a, b| if b.is_nan() { f64::NAN } else { a.max(b) });
                if !dev_max.is_finite() || dev_max > 0.2 {
                    return Ok(Some(format!("step {k}: max rho/rho0 - 1 = {dev_max:.2e}")));
                }
                worst = worst.max(dev_max);
                Ok(None)
            })?;
            let series = format!(
                "{} fluid particles{}",
                s.n_fluid,
                if graph { " graph" } else { "" }
            );
            let run = match why {
                Some(w) => Run::unstable(steps as u64, seconds, w),
                None => {
                    let (x, v) = (s.x.to_vec()?, s.v.to_vec()?);
                    let speed: Vec<f32> = v
                        .iter()
                        .zip(&fluid)
                        .filter(|(_, &f)| f != 0)
                        .map(|(v, _)| v.length())
                        .collect();
                    let water: Vec<Vec3> = x
                        .iter()
                        .zip(&fluid)
                        .filter(|(_, &f)| f != 0)
                        .map(|(p, _)| *p)
                        .collect();
                    let front = water.iter().map(|p| p.x).fold(0.0f32, f32::max);
                    // Fluid that went through a wall (too large a step lets a particle cross
                    // the three wall layers in one step) is a blow-up too.
                    let left = water.iter().filter(|p| {
                        p.x < -spacing
                            || p.x > size.x + spacing
                            || p.z < -spacing
                            || p.z > size.z + spacing
                            || p.y < -spacing
                    });
                    match left.count() {
                        0 => {
                            shown = Some((water.clone(), speed, spacing, cfl));
                            Run::stable(steps as u64, worst, seconds)
                                .extra(s.n_fluid as f64)
                                .extra(front as f64)
                        }
                        k => Run::unstable(
                            steps as u64,
                            seconds,
                            format!("{k} fluid particles left the tank"),
                        ),
                    }
                }
            };
            sweep.record(&series, cfl as f64, run);
        }
    }
    common::finish(&sweep, "sph_dam_break");
    if let Some((water, speed, spacing, cfl)) = shown {
        let title = format!(
            "sph: dam break at t = {t_end} s, {} fluid particles (dx = {spacing} m, CFL {cfl})",
            water.len()
        );
        let frame = water_frame(&water, &speed, DAM_TANK, DAM_WATER, spacing, title);
        common::write_frame("sph", &frame);
    }
    Ok(())
}

/// The dam break's tank and water block (m), and its duration (s).
const DAM_TANK: Vec3 = Vec3::new(1.2, 0.6, 0.4);
const DAM_WATER: Vec3 = Vec3::new(0.4, 0.4, 0.4);
const DAM_T_END: f32 = 0.5;

/// The water (fluid particles, walls not drawn) in its tank, coloured by speed.
fn water_frame(
    water: &[Vec3],
    speed: &[f32],
    tank: Vec3,
    block: Vec3,
    spacing: f32,
    title: String,
) -> Frame {
    let (lo, hi) = ([0.0; 3], common::p3(tank));
    Frame::new(
        title,
        common::camera(lo, hi, [0.7, 1.0, 1.8], [0.0, 1.0, 0.0]),
    )
    .note(format!(
        "a {block} m block released in a {tank} m tank (walls not drawn); colour: speed"
    ))
    .lines(Lines::bounding_box(lo, hi))
    .points(
        Points::new(water.iter().map(|&p| common::p3(p)), 0.5 * spacing as f64)
            .values("speed (m/s)", speed.iter().map(|&v| v as f64)),
    )
}

/// `--rerun`: the dam break once more at spacing `dx` and CFL 0.4, about 100 frames of it
/// (outside the sweep, so its timings are untouched).
fn record_dam_break(
    dev: &wp::Device,
    dx: f32,
    rec: &mut common::record::Recorder,
) -> wp::Result<()> {
    let cfl = 0.4f32;
    let (x0, fluid) = layout(DAM_TANK, DAM_WATER, dx);
    let mut s = Sph::new(&x0, &fluid, dx, DAM_WATER.y, dev)?;
    let dt = s.dt(cfl);
    let steps = (DAM_T_END / dt).ceil() as usize;
    let every = common::record::every(steps);
    let n_fluid = fluid.iter().filter(|&&f| f != 0).count();
    let stride = common::record::stride(n_fluid);
    let mut snap = |s: &Sph, k: usize| -> wp::Result<()> {
        let (x, v) = (s.x.to_vec()?, s.v.to_vec()?);
        let fluid_ids = (0..x.len()).filter(|&i| fluid[i] != 0).step_by(stride);
        let (water, speed): (Vec<Vec3>, Vec<f32>) =
            fluid_ids.map(|i| (x[i], v[i].length())).unzip();
        let t = k as f64 * dt as f64;
        let title = format!(
            "sph: dam break at t = {t:.3} s, {n_fluid} fluid particles (dx = {dx} m, CFL {cfl})"
        );
        rec.frame(
            k,
            t,
            &water_frame(&water, &speed, DAM_TANK, DAM_WATER, dx, title),
        );
        Ok(())
    };
    snap(&s, 0)?;
    for k in 1..=steps {
        s.step(dt)?;
        if k % every == 0 || k == steps {
            snap(&s, k)?;
        }
    }
    Ok(())
}

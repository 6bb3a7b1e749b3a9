//! The seed's DEM: a cohesive granular material settling under gravity, neighbours found
//! through a `HashGrid` queried from the force kernel, and the accuracy of its contact model.
//!
//! Contact model (per pair, and between a particle and the ground plane y = 0): a linear
//! spring-dashpot in the normal direction, `f_n = k_n overlap - c_n v_n` (positive pushes
//! apart; damping on approach and on separation, the model whose coefficient of restitution
//! has a closed form), a spring in tension up to a cohesion gap (the material sticks), and
//! Coulomb friction `|f_t| = min(k_t |v_t|, mu |f_n|)` against the tangential slip.
//! Semi-implicit Euler: v += dt (f / m + g), x += dt v.
//!
//! What it reports (error next to run time, every table also as a plot):
//! 1. restitution: a two-particle head-on collision, swept over dt, against the closed form
//!    e = exp(-zeta pi / sqrt(1 - zeta^2)), zeta = c_n / (2 sqrt(k_n m_eff));
//! 2. energy drift of an undamped, frictionless gas of particles in a closed box, against dt;
//! 3. the largest stable dt against the contact stiffness, beside the linear bound 2/omega;
//! 4. the settling pile (100K+ particles on a GPU): ms per frame, the largest overlap
//!    relative to the radius, and whether every particle stayed in the box. `--preset warp`
//!    runs Warp's example_dem configuration instead (65,536 particles, 64 substeps a frame,
//!    a 128^3 grid queried at 5 radii): the figure compared with Warp's.
//!
//! `--graph` also runs the energy drift, the pile and Warp's configuration with each frame
//! (all its substeps: the grid builds, the force and integration kernels) captured once into
//! a graph and replayed frame after frame, as Warp's example does (captured before the clock
//! starts, as there), as series of their own (`.. graph`): ms per frame beside the uncaptured
//! run's, and the same errors (the replays do the same work in the same order, so the
//! particles end where the uncaptured run leaves them, bit for bit).

mod common;

use clap::Parser;
use rand::Rng as _;
use rand_distr::StandardNormal;
use std::time::Instant;

use warp_lang as wp;
use warp_report::frame::{Frame, Lines, Points};
use warp_report::{Run, Sweep, Table};
use wp::prelude::*;

/// The contact force on a particle from a contact with normal `n` (pointing at the
/// particle), relative velocity `vrel`, `overlap` (negative: a gap, attracting within the
/// cohesion range), normal stiffness and damping, tangential stiffness, friction coefficient.
#[wp::func]
fn contact_force(n: Vec3, vrel: Vec3, overlap: f32, k_n: f32, c_n: f32, k_t: f32, mu: f32) -> Vec3 {
    let vn = dot(n, vrel);
    let f_n = k_n * overlap - c_n * vn;
    let vt = vrel - n * vn;
    // sqrt(dot(..)), not `length`: Warp's `length` is this plain formula (see `forces`).
    let slip = sqrt(dot(vt, vt));
    let mut f = n * f_n;
    if slip > 0.0 {
        let f_t = min(k_t * slip, mu * abs(f_n));
        f -= vt * (f_t / slip);
    }
    f
}

/// The force on each particle: pairs found through the grid (threads in the grid's cell
/// order, so neighbouring threads read neighbouring particles), the ground, and the box's
/// side walls at |x|, |z| = `half_width` (no walls when it is infinite).
#[wp::kernel]
fn forces(
    grid: HashGrid,
    x: Array<Vec3>,
    v: Array<Vec3>,
    f: Array<Vec3>,
    radius: f32,
    query_radius: f32,
    k_n: f32,
    c_n: f32,
    k_t: f32,
    mu: f32,
    cohesion: f32,
    half_width: f32,
    ceiling: f32,
) {
    let i = hash_grid_point_id(grid, tid());
    let xi = x[i];
    let vi = v[i];
    let mut total = Vec3::ZERO;
    for j in hash_grid_query(grid, xi, query_radius) {
        if j != i {
            let d = xi - x[j];
            // The plain sqrt(dot(d, d)), which is what Warp's `length` computes. warp-lang's
            // `length` rescales the vector so that it neither overflows nor underflows (for
            // components beyond about 1e19 or below 1e-19): 11 more instructions for each of
            // the ~400 candidates a query visits, 12% of this kernel's instructions (ncu, H200).
            // Distances here are about a radius, far from either limit.
            let dist = sqrt(dot(d, d));
            let overlap = 2.0 * radius - dist;
            if overlap > -cohesion && dist > 0.0 {
                total += contact_force(d / dist, vi - v[j], overlap, k_n, c_n, k_t, mu);
            }
        }
    }
    // Walls: the ground y = 0, the ceiling, and the four sides; no cohesion with them.
    let o = radius - xi.y;
    if o > 0.0 {
        total += contact_force(Vec3::Y, vi, o, k_n, c_n, k_t, mu);
    }
    let o = xi.y + radius - ceiling;
    if o > 0.0 {
        total += contact_force(-Vec3::Y, vi, o, k_n, c_n, k_t, mu);
    }
    let o = xi.x + radius - half_width;
    if o > 0.0 {
        total += contact_force(-Vec3::X, vi, o, k_n, c_n, k_t, mu);
    }
    let o = radius - half_width - xi.x;
    if o > 0.0 {
        total += contact_force(Vec3::X, vi, o, k_n, c_n, k_t, mu);
    }
    let o = xi.z + radius - half_width;
    if o > 0.0 {
        total += contact_force(-Vec3::Z, vi, o, k_n, c_n, k_t, mu);
    }
    let o = radius - half_width - xi.z;
    if o > 0.0 {
        total += contact_force(Vec3::Z, vi, o, k_n, c_n, k_t, mu);
    }
    f[i] = total;
}

/// Semi-implicit Euler.
#[wp::kernel]
fn integrate(
    x: Array<Vec3>,
    v: Array<Vec3>,
    f: Array<Vec3>,
    gravity: Vec3,
    inv_mass: f32,
    dt: f32,
) {
    let i = tid();
    let vi = v[i] + (f[i] * inv_mass + gravity) * dt;
    v[i] = vi;
    x[i] += vi * dt;
}

/// The material and the container.
#[derive(Clone, Copy, Debug)]
struct Material {
    radius: f32,
    mass: f32,
    k_n: f32,
    c_n: f32,
    k_t: f32,
    mu: f32,
    cohesion: f32,
    gravity: Vec3,
    /// Side walls at |x|, |z| = half_width (infinite: none).
    half_width: f32,
    /// A ceiling at y = ceiling (infinite: none).
    ceiling: f32,
}

/// Particles on the device, their grid, and how the grid is queried.
struct Scene {
    m: Material,
    x: wp::Array<Vec3>,
    v: wp::Array<Vec3>,
    f: wp::Array<Vec3>,
    grid: wp::HashGrid,
    /// Cell width of the grid and radius of each query: at least the interaction range
    /// (2 radius + cohesion) plus what a particle may move between two builds.
    query_radius: f32,
    /// Substeps between two grid builds.
    rebuild_every: usize,
    dev: wp::Device,
}

impl Scene {
    fn new(
        m: Material,
        x0: &[Vec3],
        v0: &[Vec3],
        grid_dim: usize,
        query_radius: f32,
        rebuild_every: usize,
        dev: &wp::Device,
    ) -> wp::Result<Scene> {
        Ok(Scene {
            m,
            x: wp::Array::from_slice(x0, dev)?,
            v: wp::Array::from_slice(v0, dev)?,
            f: wp::Array::zeros(x0.len(), dev)?,
            grid: wp::HashGrid::new(grid_dim, grid_dim, grid_dim, dev)?,
            query_radius,
            rebuild_every,
            dev: dev.clone(),
        })
    }

    /// [`Scene::frame`] captured into a graph, whose replays run the frame again (from the
    /// particles as they are then). A plain frame must come first: on a GPU it compiles the
    /// kernels and loads the grid build's (nothing is compiled inside a capture), and it gives
    /// the grid room for the points (nothing is allocated there).
    fn capture(&mut self, substeps: usize, dt: f32) -> wp::Result<wp::Graph> {
        let dev = self.dev.clone();
        wp::capture(&dev, || self.frame(substeps, dt))
    }

    /// `substeps` steps of `dt`, the grid rebuilt every `rebuild_every` of them.
    fn frame(&mut self, substeps: usize, dt: f32) -> wp::Result<()> {
        let n = self.x.len();
        let m = self.m;
        for step in 0..substeps {
            if step % self.rebuild_every == 0 {
                self.grid.build(&self.x, self.query_radius)?;
            }
            let args = (
                &self.grid,
                &self.x,
                &self.v,
                &self.f,
                m.radius,
                self.query_radius,
                m.k_n,
                m.c_n,
                m.k_t,
                m.mu,
                m.cohesion,
                m.half_width,
                m.ceiling,
            );
            wp::launch(forces, n, args, &self.dev)?;
            let args = (&self.x, &self.v, &self.f, m.gravity, 1.0 / m.mass, dt);
            wp::launch(integrate, n, args, &self.dev)?;
        }
        Ok(())
    }
}

/// A cohesive granular material (DEM): restitution, energy drift and the stability limit of
/// its contact model, then a pile settling in a box.
#[derive(Parser)]
struct Cli {
    /// Particles settling in the box [default: 110592 on a GPU, 8000 on the CPU]
    #[arg(long, value_name = "PARTICLES", value_parser = common::num::<usize>)]
    n: Option<usize>,
    /// Frames of the settling run, or of Warp's configuration with `--preset warp` [default:
    /// 60; 100 with `--preset warp`]
    #[arg(long, value_parser = common::num::<usize>)]
    frames: Option<usize>,
    /// `warp`: only Warp's example_dem configuration, timed
    #[arg(long, value_parser = ["warp"])]
    preset: Option<String>,
    /// Also run the timed frames (energy drift, pile, Warp's configuration) captured into a
    /// graph, one frame recorded once and replayed: printed beside the uncaptured run
    #[arg(long)]
    graph: bool,
    /// With `--preset warp`: also time NVIDIA Warp's own example_dem on the same device, in
    /// this run (`python3 benches/py/warp_dem.py`, with Warp importable), and print the ratio
    #[arg(long)]
    compare_warp: bool,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let gpu = dev.to_string() != "cpu";
    if cli.preset.as_deref() == Some("warp") {
        let frames = cli.frames.unwrap_or(100);
        return warp_preset(&dev, frames, &cli.scene, cli.graph, cli.compare_warp);
    }
    println!("DEM on \"{dev}\": linear spring-dashpot contacts, cohesion, Coulomb friction");
    restitution(&dev)?;
    energy_drift(&dev, cli.graph)?;
    stability_limit(&dev)?;
    let n = cli.n.unwrap_or(if gpu { 110_592 } else { 8_000 });
    let frames = cli.frames.unwrap_or(60);
    settle(&dev, n, frames, &cli.scene, cli.graph)?;
    common::print_compiled();
    Ok(())
}

/// Two equal particles colliding head on, no gravity, friction or cohesion: the measured
/// coefficient of restitution against the closed form of the linear spring-dashpot, swept
/// over dt. The error is O(dt) (the contact starts and ends between steps).
fn restitution(dev: &wp::Device) -> wp::Result<()> {
    let m = Material {
        radius: 0.05,
        mass: 0.01,
        k_n: 1e4,
        c_n: 0.2,
        k_t: 0.0,
        mu: 0.0,
        cohesion: 0.0,
        gravity: Vec3::ZERO,
        half_width: f32::INFINITY,
        ceiling: f32::INFINITY,
    };
    let m_eff = m.mass as f64 / 2.0;
    let zeta = m.c_n as f64 / (2.0 * (m.k_n as f64 * m_eff).sqrt());
    let e_exact = (-zeta * std::f64::consts::PI / (1.0 - zeta * zeta).sqrt()).exp();
    let omega = (m.k_n as f64 / m_eff).sqrt();
    let t_contact = std::f64::consts::PI / (omega * (1.0 - zeta * zeta).sqrt());
    println!(
        "\n1. restitution: k_n = {}, c_n = {}, m = {}: zeta = {zeta:.4}, e = {e_exact:.6}, \
         contact time {t_contact:.3e} s",
        m.k_n, m.c_n, m.mass
    );
    // PAIRS independent pairs, far apart along z, whose contacts start at phases spread over
    // one step (the gap closes in 4 + k / PAIRS steps): where in a step the contact starts and
    // ends decides the O(dt) error, so the error reported is the worst over the phases.
    const PAIRS: usize = 32;
    let speed = 1.0f32;
    let mut sweep = Sweep::new(
        format!("two-particle collision on {dev}: max over {PAIRS} phases of |e - e_exact|"),
        "dt (s)",
    )
    .with_extras(&["steps per contact"])
    .progress(8);
    for k in 0..8 {
        let dt = (t_contact / 10.0 / 2f64.powi(k)) as f32;
        let mut x0 = Vec::with_capacity(2 * PAIRS);
        let mut v0 = Vec::with_capacity(2 * PAIRS);
        for p in 0..PAIRS {
            let gap = speed * (4.0 + p as f32 / PAIRS as f32) * dt;
            let z = p as f32 * 10.0 * m.radius;
            x0.push(Vec3::new(-m.radius - gap / 2.0, 0.0, z));
            x0.push(Vec3::new(m.radius + gap / 2.0, 0.0, z));
            v0.push(Vec3::new(speed / 2.0, 0.0, 0.0));
            v0.push(Vec3::new(-speed / 2.0, 0.0, 0.0));
        }
        let mut s = Scene::new(m, &x0, &v0, 64, 4.0 * m.radius, 1, dev)?;
        let steps = ((t_contact / dt as f64) * 1.5) as usize + 8;
        let t = Instant::now();
        s.frame(steps, dt)?;
        let v = s.v.to_vec()?;
        let seconds = t.elapsed().as_secs_f64();
        let err = (0..PAIRS)
            .map(|p| ((v[2 * p + 1].x - v[2 * p].x) as f64 / speed as f64 - e_exact).abs())
            .fold(0.0f64, f64::max);
        sweep.record(
            "f32, semi-implicit Euler",
            dt as f64,
            Run::stable(steps as u64, err, seconds).extra(t_contact / dt as f64),
        );
    }
    common::finish(&sweep, "dem_restitution");
    Ok(())
}

/// A jittered lattice of `n` particles filling a fraction of a box, with random velocities.
fn gas(n: usize, radius: f32, half_width: f32, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut rng = common::rng(seed);
    let side = (n as f64).cbrt().ceil() as usize;
    let spacing = 2.0 * half_width / side as f32;
    assert!(spacing > 2.0 * radius, "the lattice overlaps");
    let mut x = Vec::with_capacity(n);
    let mut v = Vec::with_capacity(n);
    for k in 0..n {
        let (a, b, c) = (k % side, (k / side) % side, k / (side * side));
        let jitter =
            |r: &mut common::Rng| (r.random::<f64>() as f32 - 0.5) * (spacing - 2.0 * radius) * 0.5;
        x.push(Vec3::new(
            -half_width + (a as f32 + 0.5) * spacing + jitter(&mut rng),
            (b as f32 + 0.5) * spacing + jitter(&mut rng),
            -half_width + (c as f32 + 0.5) * spacing + jitter(&mut rng),
        ));
        v.push(Vec3::new(
            rng.sample::<f64, _>(StandardNormal) as f32,
            rng.sample::<f64, _>(StandardNormal) as f32,
            rng.sample::<f64, _>(StandardNormal) as f32,
        ));
    }
    (x, v)
}

/// Kinetic plus elastic energy, in f64 on the host, by brute force over pairs (independent
/// of the grid, so a missed neighbour would show as an error).
fn energy(m: &Material, x: &[Vec3], v: &[Vec3]) -> f64 {
    let k = m.k_n as f64;
    let r = m.radius as f64;
    let mut e = 0.0;
    for i in 0..x.len() {
        let xi = x[i].as_dvec3();
        e += 0.5 * m.mass as f64 * v[i].as_dvec3().length_squared();
        for xj in &x[i + 1..] {
            let o = 2.0 * r - (xi - xj.as_dvec3()).length();
            if o > 0.0 {
                e += 0.5 * k * o * o;
            }
        }
        let hw = m.half_width as f64;
        for o in [
            r - xi.y,
            xi.y + r - m.ceiling as f64,
            xi.x + r - hw,
            r - hw - xi.x,
            xi.z + r - hw,
            r - hw - xi.z,
        ] {
            if o > 0.0 {
                e += 0.5 * k * o * o;
            }
        }
    }
    e
}

/// The gas of `energy_drift` and `stability_limit`: elastic (no damping, friction, cohesion
/// or gravity), closed box.
fn gas_material(k_n: f32) -> Material {
    Material {
        radius: 0.03,
        mass: 0.01,
        k_n,
        c_n: 0.0,
        k_t: 0.0,
        mu: 0.0,
        cohesion: 0.0,
        gravity: Vec3::ZERO,
        half_width: 0.5,
        ceiling: 1.0,
    }
}

/// Runs the gas for `t_end` seconds at `dt`; the relative energy change, or why it blew up.
/// With `graph`, the frames after the first are replays of it captured.
fn run_gas(
    dev: &wp::Device,
    m: Material,
    n: usize,
    dt: f32,
    t_end: f32,
    graph: bool,
) -> wp::Result<Run> {
    let (x0, v0) = gas(n, m.radius, m.half_width, 7);
    let e0 = energy(&m, &x0, &v0);
    // The grid is rebuilt every step, with a margin of one radius: no particle outruns it
    // (speeds are about 1 m/s, a step moves far less than a radius at every dt swept).
    let substeps = 64usize;
    let mut s = Scene::new(m, &x0, &v0, 32, 3.0 * m.radius, 1, dev)?;
    let steps = (t_end / dt).ceil() as usize;
    let frames = steps.div_ceil(substeps);
    let t = Instant::now();
    let mut captured: Option<wp::Graph> = None;
    for fr in 0..frames {
        // A blow-up shows as a non-finite point refused by the grid's build (reported by the
        // check's synchronisation after a replay), or at the check after the frame: either
        // way the run is unstable, and the table says where.
        let built = match &captured {
            Some(g) => g.launch(),
            None => s.frame(substeps, dt),
        };
        if graph && fr == 0 && built.is_ok() {
            captured = Some(s.capture(substeps, dt)?);
        }
        if let Err(e) = built.and_then(|()| s.x.check_finite("x")) {
            return Ok(Run::unstable(
                ((fr + 1) * substeps) as u64,
                t.elapsed().as_secs_f64(),
                format!("frame {fr}: {e}"),
            ));
        }
    }
    wp::synchronize()?;
    let seconds = t.elapsed().as_secs_f64();
    let (x, v) = (s.x.to_vec()?, s.v.to_vec()?);
    let e1 = energy(&m, &x, &v);
    let drift = (e1 - e0) / e0;
    let escaped = x.iter().any(|p| {
        p.x.abs() > m.half_width + m.radius
            || p.z.abs() > m.half_width + m.radius
            || p.y < -m.radius
            || p.y > m.ceiling + m.radius
    });
    Ok(if !drift.is_finite() || drift.abs() > 1.0 || escaped {
        Run::unstable(
            (frames * substeps) as u64,
            seconds,
            format!("energy drift {drift:.1e}, particles escaped: {escaped}"),
        )
    } else {
        Run::stable((frames * substeps) as u64, drift.abs(), seconds)
    })
}

/// Energy drift of the undamped gas against dt (symplectic Euler: bounded oscillation for a
/// smooth force; contacts switching on and off between steps leave O(dt) per collision).
fn energy_drift(dev: &wp::Device, graph: bool) -> wp::Result<()> {
    let m = gas_material(1e4);
    let n = 1000;
    let omega = (2.0 * m.k_n as f64 / m.mass as f64).sqrt();
    println!(
        "\n2. energy drift: {n} particles, elastic contacts k_n = {}, 0.25 s; 2/omega = {:.3e} s",
        m.k_n,
        2.0 / omega
    );
    let modes = common::graph_modes(graph);
    let mut sweep = Sweep::new(
        format!("undamped gas on {dev}: |E(0.25 s) - E(0)| / E(0)"),
        "dt (s)",
    )
    .progress(5 * modes.len() as u64);
    for k in 0..5 {
        let dt = (0.4 / omega / 2f64.powi(k)) as f32;
        for &captured in modes {
            let run = run_gas(dev, m, n, dt, 0.25, captured)?;
            let series = if captured {
                "f32, semi-implicit Euler graph"
            } else {
                "f32, semi-implicit Euler"
            };
            sweep.record(series, dt as f64, run);
        }
    }
    common::finish(&sweep, "dem_energy");
    Ok(())
}

/// The largest stable dt on a grid of halvings, against the stiffness, beside 2/omega of a
/// pair (omega = sqrt(k / m_eff), m_eff = m/2): the bound of the linear oscillator that
/// semi-implicit Euler integrates.
fn stability_limit(dev: &wp::Device) -> wp::Result<()> {
    println!("\n3. stability limit: 512 particles of the gas, 0.25 s, dt = 2^-j x 1e-2 s");
    let mut table = Table::new([
        "k_n (N/m)",
        "2/omega (s)",
        "largest stable dt (s)",
        "ratio",
        "first unstable",
    ]);
    for k_n in [1e2f32, 1e3, 1e4, 1e5, 1e6] {
        let m = gas_material(k_n);
        let bound = 2.0 / (2.0 * k_n as f64 / m.mass as f64).sqrt();
        let mut stable = None;
        let mut failed = String::from("-");
        for j in 0..16 {
            let dt = 1e-2f32 / 2f32.powi(j);
            let run = run_gas(dev, m, 512, dt, 0.25, false)?;
            if run.stability.is_stable() {
                stable = Some(dt);
                break;
            }
            if let warp_report::Stability::Unstable(why) = &run.stability {
                failed = format!("dt = {dt:.2e}: {why}");
            }
        }
        table.push([
            format!("{k_n:.0e}"),
            format!("{bound:.2e}"),
            stable.map_or("-".into(), |d| format!("{d:.2e}")),
            stable.map_or("-".into(), |d| format!("{:.2}", d as f64 / bound)),
            failed,
        ]);
    }
    println!("\n{table}");
    Ok(())
}

/// The cohesive pile settling into a box: ms per frame (128 substeps, a grid build each), and
/// the largest overlap relative to the radius at the end of each reported frame. With
/// `graph`, the run again with each frame a replay of one captured, beside the first.
fn settle(
    dev: &wp::Device,
    n: usize,
    frames: usize,
    args: &common::SceneArgs,
    graph: bool,
) -> wp::Result<()> {
    let m = Material {
        radius: 0.01,
        mass: 1e-3,
        k_n: 1e3,
        c_n: 0.5,
        k_t: 1.0,
        mu: 0.5,
        cohesion: 0.002,
        gravity: Vec3::new(0.0, -9.81, 0.0),
        half_width: 0.0,
        ceiling: f32::INFINITY,
    };
    // A column of particles above the floor of a box sized to hold them two layers deep.
    let side = (n as f64).cbrt().ceil() as usize;
    let spacing = 2.05 * m.radius;
    let half_width = 0.75 * side as f32 * spacing;
    let m = Material { half_width, ..m };
    let mut rng = common::rng(11);
    let mut x0 = Vec::with_capacity(n);
    for k in 0..n {
        let (a, b, c) = (k % side, k / (side * side), (k / side) % side);
        let j = |r: &mut common::Rng| (r.random::<f64>() as f32 - 0.5) * 0.02 * m.radius;
        x0.push(Vec3::new(
            (a as f32 - side as f32 / 2.0) * spacing + j(&mut rng),
            m.radius + b as f32 * spacing * 1.5 + j(&mut rng),
            (c as f32 - side as f32 / 2.0) * spacing + j(&mut rng),
        ));
    }
    let v0 = vec![Vec3::ZERO; n];
    // 128 substeps: a third of the pair bound 2/omega. A dense pile's many contacts lower the
    // limit well below the pair's (about half of it in the gas of the stability table, less
    // in a pile): at two thirds of the bound the pile heats up and particles fly at 12 m/s.
    let (frame_dt, substeps) = (1.0f32 / 60.0, 128usize);
    let dt = frame_dt / substeps as f32;
    // The grid is rebuilt every substep; its margin covers the fastest motion over one,
    // free fall from the top of the column (sqrt(2 g h)), checked at each report.
    let h = side as f32 * spacing * 1.5;
    let vmax = (2.0 * 9.81 * h).sqrt();
    let query = 2.0 * m.radius + m.cohesion + 1.5 * vmax * dt;
    let omega = (2.0 * m.k_n / m.mass).sqrt();
    // About two cells per particle along each axis of the pile: a build clears every cell, so
    // a CPU run with few particles should not pay for 128^3 of them.
    let dim = ((n as f64).cbrt() as usize * 2)
        .next_power_of_two()
        .clamp(16, 128);
    println!(
        "\n4. settling: {n} particles (radius {} m) into a box of half-width {half_width:.3} m, \
         {frames} frames of {substeps} substeps (dt = {dt:.2e} s, 2/omega = {:.2e} s), grid \
         {dim}^3 rebuilt every substep, queried at {query:.4} m",
        m.radius,
        2.0 / omega
    );
    let modes = common::graph_modes(graph);
    let mut sweep = Sweep::new(
        format!("cohesive pile on {dev}: max overlap / radius"),
        "simulated time (s)",
    )
    .with_extras(&["ms per frame"])
    .progress((frames * modes.len()) as u64);
    // With `--rerun`, every frame of the (uncaptured) run, its natural cadence, outside the
    // timing.
    let mut rec = args.recorder("dem");
    let stride = common::record::stride(n);
    let picture = |x: &[Vec3], fr: usize| {
        let t = fr as f64 * frame_dt as f64;
        let title = format!("dem: {n} particles after {fr} frames ({t:.2} s)");
        pile_frame(x, stride, m.radius as f64, half_width as f64, title)
    };
    // Per mode: ms per frame and the particles at the end.
    let mut results: Vec<(f64, Vec<Vec3>)> = Vec::new();
    for &captured in modes {
        let mut s = Scene::new(m, &x0, &v0, dim, query, 1, dev)?;
        // Warm-up: compiles on a GPU (and, captured, loads what the capture may not).
        s.frame(1, dt)?;
        let graph = if captured {
            Some(s.capture(substeps, dt)?)
        } else {
            None
        };
        wp::synchronize()?;
        let series = if captured { "f32 graph" } else { "f32" };
        let recording = rec.is_on() && !captured;
        if recording {
            rec.frame(0, 0.0, &picture(&s.x.to_vec()?, 0));
        }
        let mut elapsed = 0.0f64;
        for fr in 0..frames {
            let t = Instant::now();
            match &graph {
                Some(g) => g.launch()?,
                None => s.frame(substeps, dt)?,
            }
            wp::synchronize()?;
            elapsed += t.elapsed().as_secs_f64();
            if recording {
                let sim_t = (fr + 1) as f64 * frame_dt as f64;
                rec.frame(fr + 1, sim_t, &picture(&s.x.to_vec()?, fr + 1));
            }
            if (fr + 1) % (frames / 6).max(1) == 0 || fr + 1 == frames {
                let x = s.x.to_vec()?;
                let fastest =
                    s.v.to_vec()?
                        .iter()
                        .map(|v| v.length())
                        .fold(0.0f32, f32::max);
                if fastest * dt > query - 2.0 * m.radius - m.cohesion {
                    println!("warning: a particle at {fastest:.2} m/s outruns the grid's margin");
                }
                let stable = x.iter().all(|p| p.is_finite())
                    && x.iter().all(|p| {
                        p.y > -m.radius
                            && p.x.abs() < half_width + m.radius
                            && p.z.abs() < half_width + m.radius
                    });
                let ms = elapsed * 1e3 / (fr + 1) as f64;
                let run = if stable {
                    Run::stable(
                        ((fr + 1) * substeps) as u64,
                        max_overlap(&x, m.radius) / m.radius as f64,
                        elapsed,
                    )
                } else {
                    Run::unstable(((fr + 1) * substeps) as u64, elapsed, "NaN or escaped")
                };
                sweep.record(series, (fr + 1) as f64 * frame_dt as f64, run.extra(ms));
            }
        }
        results.push((elapsed * 1e3 / frames as f64, s.x.to_vec()?));
    }
    common::finish(&sweep, "dem_settle");
    rec.finish();
    let (ms, x) = &results[0];
    let title = format!(
        "dem: {n} particles after {frames} frames ({:.2} s)",
        frames as f32 * frame_dt
    );
    let frame = pile_frame(x, 1, m.radius as f64, half_width as f64, title);
    common::write_frame("dem", &frame);
    println!(
        "settling: {ms:.2} ms per frame ({substeps} substeps, a grid build each) on \"{dev}\""
    );
    if let Some((ms_graph, x_graph)) = results.get(1) {
        print_graph_line("settling", *ms, *ms_graph, x, x_graph);
    }
    Ok(())
}

/// The line comparing a run whose frames were graph replays (`ms_graph` per frame, particles
/// at `x_graph`) with the uncaptured run (`ms`, `x`).
fn print_graph_line(what: &str, ms: f64, ms_graph: f64, x: &[Vec3], x_graph: &[Vec3]) {
    let same = x.len() == x_graph.len()
        && x.iter()
            .zip(x_graph)
            .all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits));
    println!(
        "{what}, graph-captured: {ms_graph:.2} ms per frame against {ms:.2} uncaptured \
         ({:.2}x); particles bit for bit those of the uncaptured run: {same}",
        ms_graph / ms
    );
}

/// The pile (one particle in `stride`) in its box of half-width `w`, up to its top, coloured
/// by height.
fn pile_frame(x: &[Vec3], stride: usize, radius: f64, w: f64, title: String) -> Frame {
    let pos: Vec<[f64; 3]> = x.iter().step_by(stride).map(|&p| common::p3(p)).collect();
    let top = common::bounds(&pos).1[1].max(0.0);
    let (lo, hi) = ([-w, 0.0, -w], [w, top, w]);
    Frame::new(
        title,
        common::camera(lo, hi, [1.0, 0.9, 1.6], [0.0, 1.0, 0.0]),
    )
    .note("cohesive spring-dashpot contacts with Coulomb friction, in a box; colour: height")
    .lines(Lines::bounding_box(lo, hi))
    .points(Points::new(pos.iter().copied(), radius).values("height (m)", pos.iter().map(|p| p[1])))
}

/// The largest overlap of two particles, on the host through a coarse hash of the points
/// (independent of the device's grid).
fn max_overlap(x: &[Vec3], radius: f32) -> f64 {
    use std::collections::HashMap;
    let h = 2.0 * radius as f64;
    let key = |p: &Vec3| {
        let c = (p.as_dvec3() / h).floor();
        (c.x as i64, c.y as i64, c.z as i64)
    };
    let mut buckets: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::new();
    for (i, p) in x.iter().enumerate() {
        buckets.entry(key(p)).or_default().push(i);
    }
    let mut worst = 0.0f64;
    for (i, p) in x.iter().enumerate() {
        let (a, b, c) = key(p);
        for da in -1..=1 {
            for db in -1..=1 {
                for dc in -1..=1 {
                    if let Some(js) = buckets.get(&(a + da, b + db, c + dc)) {
                        for &j in js {
                            if j > i {
                                let d = (p.as_dvec3() - x[j].as_dvec3()).length();
                                worst = worst.max(h - d);
                            }
                        }
                    }
                }
            }
        }
    }
    worst
}

/// Warp's example_dem configuration (warp/examples/core/example_dem.py): 32 x 64 x 32
/// particles of radius 0.1 spaced 2 radii from (0, 0.5, 0) with jitter, thrown at 15 m/s
/// along z, k_n = 8000, c_n = 2, k_t = 1, mu = 1e5, inverse mass 64, 64 substeps of a 1/60 s
/// frame, a 128^3 grid with cells of 5 radii queried at 5 radii, built once per frame.
/// Differences: the ground here has the particles' friction (Warp's: k_t 100, mu 0.5, and a
/// cohesion of 0.02), and damping acts on separation too (Warp's only on approach); the
/// arithmetic per pair is the same.
fn warp_preset(
    dev: &wp::Device,
    frames: usize,
    args: &common::SceneArgs,
    graph: bool,
    compare_warp: bool,
) -> wp::Result<()> {
    let m = Material {
        radius: 0.1,
        mass: 1.0 / 64.0,
        k_n: 8000.0,
        c_n: 2.0,
        k_t: 1.0,
        mu: 1e5,
        cohesion: 0.0075,
        gravity: Vec3::new(0.0, -9.8, 0.0),
        half_width: f32::INFINITY,
        ceiling: f32::INFINITY,
    };
    let (nx, ny, nz) = (32usize, 64usize, 32usize);
    let mut rng = common::rng(3);
    let mut x0 = Vec::with_capacity(nx * ny * nz);
    for a in 0..nx {
        for b in 0..ny {
            for c in 0..nz {
                let mut j = || rng.random::<f64>() as f32 * m.radius * 0.1;
                x0.push(Vec3::new(
                    a as f32 * 2.0 * m.radius + j(),
                    0.5 + b as f32 * 2.0 * m.radius + j(),
                    c as f32 * 2.0 * m.radius + j(),
                ));
            }
        }
    }
    let v0 = vec![Vec3::new(0.0, 0.0, 15.0); x0.len()];
    let (frame_dt, substeps) = (1.0f32 / 60.0, 64usize);
    let dt = frame_dt / substeps as f32;
    // With `--rerun`, every frame of the uncaptured run, the clock stopped while one is
    // recorded.
    let mut rec = args.recorder("dem");
    let stride = common::record::stride(x0.len());
    let picture = |x: &[Vec3], fr: usize| {
        let pos: Vec<[f64; 3]> = x.iter().step_by(stride).map(|&p| common::p3(p)).collect();
        let (lo, hi) = common::bounds(&pos);
        let t = fr as f64 * frame_dt as f64;
        Frame::new(
            format!(
                "dem (Warp's example_dem): {} particles, frame {fr} ({t:.2} s)",
                x.len()
            ),
            common::camera(lo, hi, [1.0, 0.9, 1.6], [0.0, 1.0, 0.0]),
        )
        .points(
            Points::new(pos.iter().copied(), m.radius as f64)
                .values("height (m)", pos.iter().map(|p| p[1])),
        )
    };
    let modes = common::graph_modes(graph);
    // Per mode: ms per frame and the particles at the end.
    let mut results: Vec<(f64, Vec<Vec3>)> = Vec::new();
    for &captured in modes {
        let mut s = Scene::new(m, &x0, &v0, 128, 5.0 * m.radius, substeps, dev)?;
        // Warm-up: compiles on a GPU (and, captured, loads what the capture may not).
        s.frame(1, dt)?;
        // Warp captures one frame (its grid build and substeps) and replays it.
        let graph = if captured {
            Some(s.capture(substeps, dt)?)
        } else {
            None
        };
        wp::synchronize()?;
        let recording = rec.is_on() && !captured;
        if recording {
            rec.frame(0, 0.0, &picture(&s.x.to_vec()?, 0));
        }
        let mut elapsed = 0.0;
        let mut t = Instant::now();
        for fr in 1..=frames {
            match &graph {
                Some(g) => g.launch()?,
                None => s.frame(substeps, dt)?,
            }
            if recording {
                wp::synchronize()?;
                elapsed += t.elapsed().as_secs_f64();
                rec.frame(
                    fr,
                    fr as f64 * frame_dt as f64,
                    &picture(&s.x.to_vec()?, fr),
                );
                t = Instant::now();
            }
        }
        wp::synchronize()?;
        elapsed += t.elapsed().as_secs_f64();
        let ms = elapsed * 1e3 / frames as f64;
        let x = s.x.to_vec()?;
        let finite = x.iter().all(|p| p.is_finite());
        println!(
            "Warp's example_dem configuration on \"{dev}\"{}: {} particles, {frames} frames of \
             {substeps} substeps: {ms:.2} ms per frame; max overlap / radius {:.3}, all \
             finite: {finite}",
            if captured { ", graph-captured" } else { "" },
            x0.len(),
            max_overlap(&x, m.radius) / m.radius as f64
        );
        results.push((ms, x));
    }
    rec.finish();
    if let [(ms, x), (ms_graph, x_graph)] = &results[..] {
        print_graph_line("Warp's configuration", *ms, *ms_graph, x, x_graph);
    }
    if compare_warp {
        // Our best mode against Warp's (which replays a captured graph).
        let ours = results.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
        match warp_side(frames) {
            Ok((warp_ms, n, finite)) => println!(
                "NVIDIA Warp's example_dem on this device, same run: {warp_ms:.2} ms per frame \
                 ({n} particles, all finite: {finite}); ours / Warp: {:.2}",
                ours / warp_ms
            ),
            Err(why) => println!("NVIDIA Warp's example_dem not timed: {why}"),
        }
    } else {
        println!(
            "(Warp 1.19's own figure for this configuration, H100, graph-captured: 13.0 ms per \
             frame; `--compare-warp` times Warp here)"
        );
    }
    common::print_compiled();
    Ok(())
}

/// Runs benches/py/warp_dem.py for `frames` frames: Warp's ms per frame, its particle count
/// and whether its particles stayed finite; or why it could not run.
fn warp_side(frames: usize) -> Result<(f64, usize, bool), String> {
    // From the repository root, from examples/, or where this example was built.
    let script = [
        "benches/py/warp_dem.py",
        "../benches/py/warp_dem.py",
        concat!(env!("CARGO_MANIFEST_DIR"), "/../benches/py/warp_dem.py"),
    ]
    .into_iter()
    .find(|p| std::path::Path::new(p).exists())
    .ok_or("benches/py/warp_dem.py not found")?;
    let out = std::process::Command::new("python3")
        .arg(script)
        .arg(frames.to_string())
        .output()
        .map_err(|e| format!("python3: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(err.lines().last().unwrap_or("failed").to_string());
    }
    // `warp_dem_ms_per_frame <ms> particles <n> finite <0|1>`
    let words: Vec<&str> = text
        .lines()
        .last()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    match words[..] {
        ["warp_dem_ms_per_frame", ms, "particles", n, "finite", f] => Ok((
            ms.parse().map_err(|_| format!("bad time {ms}"))?,
            n.parse().map_err(|_| format!("bad count {n}"))?,
            f == "1",
        )),
        _ => Err(format!("unexpected output: {text}")),
    }
}

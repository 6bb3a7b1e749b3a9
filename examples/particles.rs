//! The seed program: particles under gravity with linear drag, integrated by semi-implicit
//! Euler, as in the Warp introduction this project grew from.
//!
//! ```text
//! cargo run --release --example particles -- [--n 10000000] [--steps 100] [--device cpu|cuda:0]
//! ```
//!
//! It prints the first final positions, the run time, and two errors:
//! - against the closed-form solution of the ODE  v' = -(b/m) v + g  (this is the time
//!   discretisation error of the scheme, O(dt));
//! - against the exact solution of the discrete recurrence evaluated in f64 (this is the
//!   rounding error of running the scheme in f32, which is what the kernel is responsible for).

use std::time::Instant;
use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn integrate(x: Array<Vec3>, v: Array<Vec3>, b: f32, mass: f32, gravity: Vec3, dt: f32) {
    let i = tid();
    let a = -b * v[i] / mass + gravity;
    v[i] += a * dt;
    x[i] += v[i] * dt;
}

struct Options {
    n: usize,
    steps: usize,
    device: Option<String>,
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options {
        n: 10_000_000,
        steps: 100,
        device: None,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value"));
        match a.as_str() {
            "--n" => {
                o.n = value("--n")?
                    .replace('_', "")
                    .parse()
                    .map_err(|e| format!("--n: {e}"))?
            }
            "--steps" => {
                o.steps = value("--steps")?
                    .parse()
                    .map_err(|e| format!("--steps: {e}"))?
            }
            "--device" => o.device = Some(value("--device")?),
            "-h" | "--help" => {
                println!("usage: particles [--n COUNT] [--steps STEPS] [--device cpu|cuda:N]");
                std::process::exit(0);
            }
            other => return Err(format!("unknown argument {other} (try --help)")),
        }
    }
    Ok(o)
}

/// SplitMix64: a small, well-known generator, so that the start state is reproducible
/// without extra dependencies.
struct Rng(u64);
impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
    fn uniform_vec3(&mut self, lo: f32, hi: f32) -> Vec3 {
        let mut c = || lo + (hi - lo) * self.next_f64() as f32;
        Vec3::new(c(), c(), c())
    }
}

fn main() -> wp::Result<()> {
    let opts = parse_args().unwrap_or_else(|e| {
        eprintln!("particles: {e}");
        std::process::exit(2)
    });
    wp::init();
    let dev = match &opts.device {
        Some(name) => wp::get_device(name)?,
        None => wp::get_preferred_device(),
    };

    // The seed's constants.
    let mass = 0.1f32; // kg
    let g = 9.81f32; // m/s^2
    let b = 0.05f32; // kg/s
    let dt = 0.01 * (2.0 * mass / b); // s
    let gravity = Vec3::new(0.0, 0.0, -g);

    let mut rng = Rng(12345);
    let x0: Vec<Vec3> = (0..opts.n).map(|_| rng.uniform_vec3(-1.0, 1.0)).collect();
    let v0: Vec<Vec3> = (0..opts.n).map(|_| rng.uniform_vec3(-0.5, 0.5)).collect();
    let x = wp::Array::from_slice(&x0, &dev)?;
    let v = wp::Array::from_slice(&v0, &dev)?;

    // One warm-up launch on copies, so that the timing below excludes first-launch costs.
    let (xw, vw) = (
        wp::Array::from_slice(&x0[..1], &dev)?,
        wp::Array::from_slice(&v0[..1], &dev)?,
    );
    wp::launch(integrate, 1, (&xw, &vw, b, mass, gravity, dt), &dev)?;
    wp::synchronize()?;

    let t0 = Instant::now();
    for _ in 0..opts.steps {
        wp::launch(integrate, opts.n, (&x, &v, b, mass, gravity, dt), &dev)?;
    }
    wp::synchronize()?;
    let elapsed = t0.elapsed();
    let xs = x.to_vec()?;

    // Errors, in f64.
    let k = (b / mass) as f64;
    let (dt64, steps) = (dt as f64, opts.steps as i32);
    let t = dt64 * opts.steps as f64;
    let r = 1.0 - k * dt64; // the scheme's per-step velocity factor
    let mut err_ode = 0.0f64;
    let mut err_discrete = 0.0f64;
    for i in 0..opts.n {
        for c in 0..3 {
            let gc = gravity[c] as f64;
            let (xi, vi) = (x0[i][c] as f64, v0[i][c] as f64);
            let vinf = gc / k; // terminal velocity
                               // Closed form of x' = v, v' = -k v + g.
            let exact = xi + vinf * t + (vi - vinf) * (1.0 - (-k * t).exp()) / k;
            // Closed form of v_{n+1} = r v_n + g dt, x_{n+1} = x_n + v_{n+1} dt.
            let geometric = r * (1.0 - r.powi(steps)) / (1.0 - r);
            let discrete = xi + dt64 * (opts.steps as f64 * vinf + (vi - vinf) * geometric);
            let got = xs[i][c] as f64;
            err_ode = err_ode.max((got - exact).abs());
            err_discrete = err_discrete.max((got - discrete).abs());
        }
    }

    println!(
        "particles: {} particles x {} steps on \"{}\" (dt = {dt} s)",
        opts.n, opts.steps, dev
    );
    for (i, p) in xs.iter().take(3).enumerate() {
        println!("  x[{i}] = [{:.6}, {:.6}, {:.6}]", p.x, p.y, p.z);
    }
    let ms = elapsed.as_secs_f64() * 1e3;
    println!(
        "  time: {ms:.2} ms ({:.3} ms/step, {:.1} GB/s effective)",
        ms / opts.steps as f64,
        // Each step reads and writes x and v: 4 x 12 bytes per particle.
        (48.0 * opts.n as f64 * opts.steps as f64) / elapsed.as_secs_f64() / 1e9
    );
    println!(
        "  max |x - closed form of the ODE|       = {err_ode:.3e} m (time discretisation, O(dt))"
    );
    println!("  max |x - exact discrete solution, f64| = {err_discrete:.3e} m (f32 rounding)");
    Ok(())
}

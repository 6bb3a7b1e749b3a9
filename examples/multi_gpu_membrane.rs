//! A particle scene split across GPUs by domain decomposition, with a halo exchange every step:
//! a hanging membrane of mass points joined by springs, its rows divided among the GPUs.
//!
//! ```text
//! cargo run --release --example multi_gpu_membrane -- [--gpus 4] [--rows 8192] [--cols 8192]
//!     [--steps 200] [--plot-dir DIR]
//! ```
//! The membrane: `rows x cols` particles 1 cm apart, each joined to its four neighbours by a
//! spring (stiffness 5000 N/m, rest length 1 cm), 1 g each, under gravity, its top row pinned;
//! semi-implicit Euler with dt = 0.1 ms and light velocity damping. It sags and ripples.
//!
//! The decomposition: rank `r` of `G` owns a band of consecutive rows and keeps one ghost row
//! above and below it, copies of its neighbours' edge rows. Each step every rank updates its
//! own rows, reading the ghosts where a spring crosses the band's edge, then sends its first
//! and last rows to the ranks above and below and receives their edge rows into its ghosts
//! (NCCL send/recv in one group per rank, one host thread per GPU). The particles of this
//! scene keep their neighbours (a Lagrangian mesh), so nothing migrates between bands.
//!
//! Printed:
//! 1. the result on G GPUs against the same scene on one GPU: every position equal **bit for
//!    bit** (tolerance 0: each particle's update is the same floating-point operations on the
//!    same inputs in the same order, whatever band it is in), and the sag at the centre;
//! 2. strong scaling (the same membrane on 1, 2, .. G GPUs): ms per step, speed-up,
//!    efficiency `T1 / (G TG)` and the share of the step spent in the halo exchange (GPU time
//!    between events around the exchange, the slowest rank's);
//! 3. weak scaling (`--rows` rows per GPU): efficiency `T1 / TG`.
//!
//! Both scalings are plotted, ms per step against the GPU count with the ideal of each, to
//! `<--plot-dir or target/report>/multi_gpu_membrane.svg`; a progress bar counts the runs.

mod common;

use clap::Parser;
use std::sync::Arc;
use std::time::Instant;

use warp_lang as wp;
use warp_report::{sci, Table};
use wp::distributed::{group, Communicator};
use wp::prelude::*;

/// The force of the spring from `p` to its neighbour `q`.
#[wp::func]
fn spring(p: Vec3, q: Vec3, k: f32, rest: f32) -> Vec3 {
    let d = q - p;
    let l = length(d);
    d * (k * (l - rest) / l)
}

/// One step of the rank's own rows (local rows 1..=band; rows 0 and band + 1 are ghosts).
/// `first` is the global index of local row 1, `rows` the membrane's global row count.
#[wp::kernel]
fn membrane_step(
    x: Array<Vec3, 2>,
    v: Array<Vec3, 2>,
    x_out: Array<Vec3, 2>,
    v_out: Array<Vec3, 2>,
    first: usize,
    rows: usize,
    cols: usize,
    k: f32,
    rest: f32,
    mass: f32,
    damping: f32,
    dt: f32,
) {
    let (a, j) = tid();
    let i = a + 1;
    let global = first + a;
    let p = x[(i, j)];
    if global == 0 {
        x_out[(i, j)] = p;
        v_out[(i, j)] = vec3(0.0, 0.0, 0.0);
    } else {
        let mut f = vec3(0.0, -9.81 * mass, 0.0);
        f += spring(p, x[(i - 1, j)], k, rest);
        if global + 1 < rows {
            f += spring(p, x[(i + 1, j)], k, rest);
        }
        if j > 0 {
            f += spring(p, x[(i, j - 1)], k, rest);
        }
        if j + 1 < cols {
            f += spring(p, x[(i, j + 1)], k, rest);
        }
        let vn = (v[(i, j)] + f * (dt / mass)) * damping;
        v_out[(i, j)] = vn;
        x_out[(i, j)] = p + vn * dt;
    }
}

#[derive(Parser, Debug)]
#[command(about = "A membrane split across GPUs by rows, with a halo exchange every step")]
struct Args {
    /// The most GPUs to use (all visible ones by default); runs 1, 2, 4, .. up to it.
    #[arg(long, value_parser = common::cli::num::<usize>)]
    gpus: Option<usize>,
    /// Rows of the membrane in the strong-scaling runs, and per GPU in the weak-scaling runs.
    #[arg(long, default_value = "8192", value_parser = common::cli::num::<usize>)]
    rows: usize,
    /// Columns of the membrane.
    #[arg(long, default_value = "8192", value_parser = common::cli::num::<usize>)]
    cols: usize,
    /// Steps per run (the first 10 are not timed).
    #[arg(long, default_value = "200", value_parser = common::cli::num::<usize>)]
    steps: usize,
    #[command(flatten)]
    plot: common::PlotDirArg,
}

const SPACING: f32 = 0.01;
const K: f32 = 5000.0;
const MASS: f32 = 1e-3;
const DT: f32 = 1e-4;
const DAMPING: f32 = 0.9995;
const WARMUP: usize = 10;

/// What one rank measured, and its rows at the end.
struct Band {
    rows: Vec<Vec3>,
    per_step: f64,
    halo_share: f64,
}

/// Rank `comm.rank()`'s part: global rows `first .. first + band` of a `rows x cols` membrane.
fn run_band(
    comm: &Communicator,
    first: usize,
    band: usize,
    rows: usize,
    cols: usize,
    steps: usize,
) -> wp::Result<Band> {
    let dev = comm.device().clone();
    let (rank, world) = (comm.rank(), comm.world_size());
    // Local row k is global row first - 1 + k; ghosts that lie outside the membrane stay unused.
    let init: Vec<Vec3> = (0..band + 2)
        .flat_map(|k| {
            let gi = first as f32 - 1.0 + k as f32;
            (0..cols).map(move |j| Vec3::new(j as f32 * SPACING, -gi * SPACING, 0.0))
        })
        .collect();
    let mut x = wp::Array::from_slice_shape(&init, (band + 2, cols), &dev)?;
    let mut v = wp::Array::<Vec3, 2>::zeros((band + 2, cols), &dev)?;
    let mut x2 = wp::Array::from_slice_shape(&init, (band + 2, cols), &dev)?;
    let mut v2 = wp::Array::<Vec3, 2>::zeros((band + 2, cols), &dev)?;
    let stream = wp::get_stream(&dev)?;
    let mut marks = Vec::new();
    comm.synchronize()?;
    let mut start = Instant::now();
    for s in 0..steps {
        if s == WARMUP {
            comm.synchronize()?;
            start = Instant::now();
        }
        wp::launch(
            membrane_step,
            (band, cols),
            (
                &x, &v, &x2, &v2, first, rows, cols, K, SPACING, MASS, DAMPING, DT,
            ),
            &dev,
        )?;
        std::mem::swap(&mut x, &mut x2);
        std::mem::swap(&mut v, &mut v2);
        // The halo exchange: edge rows out, ghost rows in.
        let before = wp::Event::new(&dev, true)?;
        before.record(&stream)?;
        group(|| {
            if rank > 0 {
                comm.send(&x.row(1)?, rank - 1)?;
                comm.recv(&x.row(0)?, rank - 1)?;
            }
            if rank + 1 < world {
                comm.send(&x.row(band)?, rank + 1)?;
                comm.recv(&x.row(band + 1)?, rank + 1)?;
            }
            Ok(())
        })?;
        let after = wp::Event::new(&dev, true)?;
        after.record(&stream)?;
        if s >= WARMUP {
            marks.push((before, after));
        }
    }
    comm.synchronize()?;
    let timed = start.elapsed().as_secs_f64() / (steps - WARMUP).max(1) as f64;
    let mut halo = 0.0;
    for (b, a) in &marks {
        halo += b.elapsed_ms(a)? as f64 * 1e-3;
    }
    let halo_per_step = halo / marks.len().max(1) as f64;
    Ok(Band {
        rows: x.view(1..band + 1)?.to_vec()?,
        per_step: timed,
        halo_share: halo_per_step / timed,
    })
}

/// The membrane of `rows` rows on the first `g` GPUs: every rank's band, in order.
fn run(gpus: &[wp::Device], g: usize, rows: usize, args: &Args) -> wp::Result<Vec<Band>> {
    let comms = Arc::new(Communicator::for_devices(&gpus[..g])?);
    let per = rows / g;
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..g)
            .map(|r| {
                let comms = comms.clone();
                s.spawn(move || {
                    let band = if r == g - 1 {
                        rows - per * (g - 1)
                    } else {
                        per
                    };
                    run_band(&comms[r], r * per, band, rows, args.cols, args.steps)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("rank thread panicked"))
            .collect()
    })
}

fn main() {
    let args = Args::parse();
    if let Err(e) = real_main(&args) {
        eprintln!("multi_gpu_membrane: {e}");
        std::process::exit(1);
    }
}

fn real_main(args: &Args) -> wp::Result<()> {
    wp::init();
    args.plot.init();
    let all: Vec<wp::Device> = wp::devices().into_iter().filter(|d| d.is_cuda()).collect();
    let max = args.gpus.unwrap_or(all.len()).min(all.len());
    if max == 0 || !wp::distributed::nccl_available() {
        return Err(wp::Error::NoDevice {
            name: "cuda".into(),
            reason: format!(
                "this example needs CUDA GPUs and NCCL ({} GPU(s); NCCL: {:?})",
                all.len(),
                wp::distributed::nccl_version()
            ),
        });
    }
    if args.rows < 2 * max || args.cols < 2 || args.steps <= WARMUP {
        return Err(wp::Error::InvalidArgument {
            what: format!(
                "--rows {} must be at least 2 per GPU ({max} GPUs), --cols {} at least 2, \
                 --steps {} more than {WARMUP}",
                args.rows, args.cols, args.steps
            ),
        });
    }
    let counts: Vec<usize> = std::iter::successors(Some(1usize), |g| Some(g * 2))
        .take_while(|g| *g <= max)
        .collect();
    println!(
        "membrane {} x {} particles, {} steps, GPUs: {}, NCCL {:?}",
        args.rows,
        args.cols,
        args.steps,
        all[..max]
            .iter()
            .map(|d| d.name().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        wp::distributed::nccl_version()?
    );
    let mut strong = Table::new([
        "GPUs",
        "ms / step",
        "speed-up",
        "efficiency",
        "halo exchange",
        "positions differing from 1 GPU",
        "centre sag (m)",
    ]);
    let mut reference: Option<(Vec<Vec3>, f64)> = None;
    let mut all_equal = true;
    // One tick per run: strong and weak scaling, each on 1, 2, .. G GPUs.
    let bar = common::progress(2 * counts.len() as u64);
    let (mut strong_ms, mut weak_ms) = (Vec::new(), Vec::new());
    for &g in &counts {
        bar.set_message(format!("strong scaling, {g} GPUs"));
        let bands = run(&all, g, args.rows, args)?;
        bar.inc(1);
        let t = bands.iter().map(|b| b.per_step).fold(0.0, f64::max);
        let h = bands.iter().map(|b| b.halo_share).fold(0.0, f64::max);
        let positions: Vec<Vec3> = bands.into_iter().flat_map(|b| b.rows).collect();
        let (ref_pos, t1) = reference.get_or_insert_with(|| (positions.clone(), t));
        let differing = ref_pos
            .iter()
            .zip(&positions)
            .filter(|(a, b)| a.to_array().map(f32::to_bits) != b.to_array().map(f32::to_bits))
            .count();
        all_equal &= differing == 0;
        let centre = (args.rows / 2) * args.cols + args.cols / 2;
        let sag = -((args.rows / 2) as f32) * SPACING - positions[centre].y;
        strong_ms.push((g, t * 1e3));
        strong.push([
            g.to_string(),
            format!("{:.3}", t * 1e3),
            format!("{:.2}", *t1 / t),
            format!("{:.0}%", 100.0 * *t1 / (g as f64 * t)),
            format!("{:.1}%", 100.0 * h),
            differing.to_string(),
            sci(sag as f64),
        ]);
    }
    let mut weak = Table::new(["GPUs", "rows", "ms / step", "efficiency", "halo exchange"]);
    let mut t1 = None;
    for &g in &counts {
        bar.set_message(format!("weak scaling, {g} GPUs"));
        let bands = run(&all, g, args.rows * g, args)?;
        bar.inc(1);
        let t = bands.iter().map(|b| b.per_step).fold(0.0, f64::max);
        let h = bands.iter().map(|b| b.halo_share).fold(0.0, f64::max);
        let t1 = *t1.get_or_insert(t);
        weak_ms.push((g, t * 1e3));
        weak.push([
            g.to_string(),
            (args.rows * g).to_string(),
            format!("{:.3}", t * 1e3),
            format!("{:.0}%", 100.0 * t1 / t),
            format!("{:.1}%", 100.0 * h),
        ]);
    }
    bar.finish_and_clear();
    println!(
        "\nStrong scaling: {} x {} membrane\n\n{strong}",
        args.rows, args.cols
    );
    println!("\nWeak scaling: {} rows per GPU\n\n{weak}", args.rows);
    common::write_scaling_plot(
        "multi_gpu_membrane",
        &format!(
            "membrane: strong ({} x {}) and weak ({} rows per GPU) scaling",
            args.rows, args.cols, args.rows
        ),
        "ms / step",
        &strong_ms,
        &weak_ms,
    );
    println!(
        "\n{}: every position on 1..{} GPUs equal bit for bit (tolerance 0)",
        if all_equal { "PASS" } else { "FAIL" },
        counts.last().unwrap()
    );
    if !all_equal {
        std::process::exit(1);
    }
    Ok(())
}

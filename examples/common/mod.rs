//! What the scenes share: their common options, the device, and printing a sweep with its plot and
//! what was compiled.

#![allow(dead_code)] // each example uses its own subset

use std::path::PathBuf;
use std::sync::OnceLock;

use warp_lang as wp;
use warp_report::Sweep;

pub mod cli;
pub mod record;

#[allow(unused_imports)] // a scene without integer options has no use for `num`
pub use cli::{num, DeviceArg};

/// Where plots go unless `--plot-dir` says otherwise (`target/report`, beside the build).
pub const DEFAULT_PLOT_DIR: &str = "target/report";

/// The output folder the scene's command line named (set once by `SceneArgs::init`).
static PLOT_DIR: OnceLock<PathBuf> = OnceLock::new();

/// `--plot-dir` alone, for the examples that are not scenes (their own device options) but
/// write plots.
#[derive(clap::Args, Debug, Clone)]
pub struct PlotDirArg {
    /// Folder for the example's plots (SVG), created if missing
    #[arg(long, value_name = "DIR", default_value = DEFAULT_PLOT_DIR)]
    pub plot_dir: PathBuf,
}

impl PlotDirArg {
    /// Records the output folder for `write_plot` (as `SceneArgs::init` does).
    pub fn init(&self) {
        let _ = PLOT_DIR.set(self.plot_dir.clone());
    }
}

/// The options every scene has; each scene's own `#[derive(Parser)]` struct flattens them.
#[derive(clap::Args, Debug, Clone)]
pub struct SceneArgs {
    #[command(flatten)]
    pub device: DeviceArg,
    /// Folder for the scene's plots (SVG), created if missing
    #[arg(long, value_name = "DIR", default_value = DEFAULT_PLOT_DIR)]
    pub plot_dir: PathBuf,
    /// Record the run's particles and meshes, every few steps, into this rerun file (view it
    /// with `rerun FILE.rrd`); needs the examples built with `--features rerun`
    #[arg(long, value_name = "FILE.rrd", value_parser = record::parse_rrd_path)]
    pub rerun: Option<PathBuf>,
}

impl SceneArgs {
    /// Records the output folder for `finish`, `write_plot` and `OptLog::finish`, initialises
    /// warp-lang and returns the device (`--device`, else the preferred one).
    pub fn init(&self) -> wp::Result<wp::Device> {
        // A second call keeps the first folder (a scene parses its command line once).
        let _ = PLOT_DIR.set(self.plot_dir.clone());
        self.device.get()
    }

    /// For a scene whose only picture is its last frame: `--rerun` records that one frame (at
    /// step 0, time 0).
    pub fn record_last(&self, scene: &str, frame: &warp_report::frame::Frame) {
        let mut rec = self.recorder(scene);
        if rec.is_on() {
            rec.frame(0, 0.0, frame);
            rec.finish();
        }
    }

    /// For a scene that draws no frame: `--rerun` is refused (exit status 2) rather than
    /// ignored.
    pub fn no_recording(&self, scene: &str) {
        if self.rerun.is_some() {
            eprintln!("error: --rerun: {scene} draws no frame (it prints tables and plots)");
            std::process::exit(2);
        }
    }

    /// The recording `--rerun` asked for (one that records nothing without it). A file that
    /// cannot be created ends the scene with a message and exit status 1, before it runs.
    pub fn recorder(&self, scene: &str) -> record::Recorder {
        record::Recorder::new(scene, self.rerun.as_deref()).unwrap_or_else(|e| {
            eprintln!("{scene}: --rerun: {e}");
            std::process::exit(1);
        })
    }
}

/// The folder plots are written to: `--plot-dir`, else `target/report`.
pub fn plot_dir() -> PathBuf {
    PLOT_DIR
        .get()
        .cloned()
        .unwrap_or_else(|| PathBuf::from(DEFAULT_PLOT_DIR))
}

/// Prints the sweep's table, writes its plot to `<--plot-dir or target/report>/<name>.svg`,
/// and prints what the run compiled.
pub fn finish(sweep: &Sweep, name: &str) {
    sweep.finish();
    println!("\n{}", sweep.table());
    write_plot(name, |path| {
        sweep.write_svg(path).map_err(|e| e.to_string())
    });
}

/// Writes a plot through `write` to `<--plot-dir or target/report>/<name>.svg` (creating the
/// folder) and prints where, or why not.
pub fn write_plot(name: &str, write: impl FnOnce(&std::path::Path) -> Result<(), String>) {
    let dir = plot_dir();
    let path = dir.join(format!("{name}.svg"));
    match std::fs::create_dir_all(&dir)
        .map_err(|e| e.to_string())
        .and_then(|()| write(&path))
    {
        Ok(()) => println!("plot: {}", path.display()),
        Err(e) => println!("plot not written: {e}"),
    }
}

/// A progress bar of `total` runs on stderr, in the style of the sweeps' bars
/// (`warp_report::Sweep::progress`), for an example whose runs are not a sweep. indicatif
/// draws it only on a terminal, so logs and CI output stay clean; `finish_and_clear` it before
/// printing a table.
pub fn progress(total: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(total);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{msg:>28} [{bar:30}] {pos}/{len} {elapsed}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// The grids of a resolution sweep `res`, `2 res - 1`, .. up to `max` (each halves the
/// spacing and keeps the nodes): how many runs its progress bar counts.
pub fn grid_count(res: usize, max: usize) -> u64 {
    std::iter::successors(Some(res.max(2)), |r| Some(2 * r - 1))
        .take_while(|&r| r <= max)
        .count() as u64
}

/// Milliseconds per step (or iteration) on 1, 2, .. G GPUs, strong and weak scaling, against
/// the ideal of each (strong: T1 / G; weak: T1), plotted to `<plot-dir>/<name>.svg` with the
/// GPU count on the horizontal axis and the time on a log axis.
pub fn write_scaling_plot(
    name: &str,
    title: &str,
    unit: &str,
    strong: &[(usize, f64)],
    weak: &[(usize, f64)],
) {
    let mut c = warp_report::Curves::new(title, unit);
    for (series, runs, ideal) in [("strong", strong, true), ("weak", weak, false)] {
        let Some(&(_, t1)) = runs.first() else {
            continue;
        };
        for &(g, t) in runs {
            c.push(&format!("{series} scaling"), g as f64, t);
            let best = if ideal { t1 / g as f64 } else { t1 };
            let label = if ideal { "T1 / G" } else { "T1" };
            c.push(&format!("{series}: ideal ({label})"), g as f64, best);
        }
    }
    write_plot(name, |path| c.write_svg(path).map_err(|e| e.to_string()));
}

/// Writes the scene's last frame to `<--plot-dir or target/report>/<name>_frame.svg` and
/// prints where, or why not.
pub fn write_frame(name: &str, frame: &warp_report::frame::Frame) {
    let path = plot_dir().join(format!("{name}_frame.svg"));
    match std::fs::create_dir_all(plot_dir())
        .map_err(|e| e.to_string())
        .and_then(|()| frame.write_svg(&path).map_err(|e| e.to_string()))
    {
        Ok(()) => println!("frame: {}", path.display()),
        Err(e) => println!("frame not written: {e}"),
    }
}

/// A position for the frame renderer (which works in f64 arrays).
pub fn p3(v: impl Into<glam::DVec3>) -> [f64; 3] {
    v.into().to_array()
}

/// A perspective camera looking at the middle of the box `lo`..`hi` from the direction
/// `from` (towards the eye), 2.5 box diagonals away, `up` up; the frame zooms to fit.
pub fn camera(
    lo: [f64; 3],
    hi: [f64; 3],
    from: [f64; 3],
    up: [f64; 3],
) -> warp_report::frame::Camera {
    let (lo, hi, from) = (
        glam::DVec3::from(lo),
        glam::DVec3::from(hi),
        glam::DVec3::from(from),
    );
    let centre = (lo + hi) / 2.0;
    let eye = centre + from.normalize_or(glam::DVec3::Z) * 2.5 * (hi - lo).length().max(1e-9);
    warp_report::frame::Camera::perspective(eye.to_array(), centre.to_array(), up)
}

/// The triangles of an n x n grid of points numbered row by row (`r * n + c`), two a cell
/// (the cloth scenes' frames draw their cloth with them).
pub fn grid_triangles(n: usize) -> Vec<[usize; 3]> {
    let at = |r: usize, c: usize| r * n + c;
    (0..n.saturating_sub(1))
        .flat_map(|r| (0..n - 1).map(move |c| (r, c)))
        .flat_map(|(r, c)| {
            [
                [at(r, c), at(r, c + 1), at(r + 1, c + 1)],
                [at(r, c), at(r + 1, c + 1), at(r + 1, c)],
            ]
        })
        .collect()
}

/// The smallest box holding `points` (a unit box at the origin for none).
pub fn bounds(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    if points.is_empty() {
        return ([-0.5; 3], [0.5; 3]);
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points.iter().filter(|p| p.iter().all(|c| c.is_finite())) {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// The length of the box's diagonal.
pub fn diagonal(lo: [f64; 3], hi: [f64; 3]) -> f64 {
    (glam::DVec3::from(hi) - glam::DVec3::from(lo)).length()
}

/// The log of an optimisation: every iteration goes into the curves (the plot); every
/// `every`-th, the first and the last also into the printed table, with the elapsed time since
/// the log started, the mean time per iteration so far and the gradient's norm.
pub struct OptLog {
    table: warp_report::Table,
    pub curves: warp_report::Curves,
    start: std::time::Instant,
    every: usize,
    bar: Option<indicatif::ProgressBar>,
}

impl OptLog {
    /// A log whose table has the columns series, iteration, `value`, |grad|, the `extra`
    /// columns, elapsed (s) and ms/iteration.
    pub fn new(title: &str, value: &str, extra: &[&str], every: usize) -> OptLog {
        let mut headers = vec!["series", "iteration", value, "|grad|"];
        headers.extend_from_slice(extra);
        headers.extend_from_slice(&["elapsed (s)", "ms/iter"]);
        OptLog {
            table: warp_report::Table::new(headers),
            curves: warp_report::Curves::new(title, value),
            start: std::time::Instant::now(),
            every: every.max(1),
            bar: None,
        }
    }

    /// Shows a progress bar of at most `total` iterations (all series together; an
    /// optimisation that converges early ends its bar there), as `common::progress` draws it.
    pub fn progress(mut self, total: u64) -> OptLog {
        self.bar = Some(progress(total));
        self
    }

    /// Restarts the clock (for a second series timed from its own start).
    pub fn restart_clock(&mut self) {
        self.start = std::time::Instant::now();
    }

    /// Records iteration `it` (counted from 1) of `series`; `last` forces a table row.
    pub fn record(
        &mut self,
        series: &str,
        it: usize,
        value: f64,
        grad_norm: f64,
        extra: &[String],
        last: bool,
    ) {
        self.curves.push(series, it as f64, value);
        if let Some(bar) = &self.bar {
            bar.set_message(format!("{series}, iteration {it}"));
            bar.inc(1);
        }
        if it == 1 || it.is_multiple_of(self.every) || last {
            let secs = self.start.elapsed().as_secs_f64();
            let mut row = vec![
                series.to_string(),
                it.to_string(),
                warp_report::sci(value),
                warp_report::sci(grad_norm),
            ];
            row.extend(extra.iter().cloned());
            row.push(format!("{secs:.3}"));
            row.push(format!("{:.2}", secs * 1e3 / it as f64));
            self.table.push(row);
        }
    }

    /// Prints the table and writes the plot `<plot dir>/<name>.svg`.
    pub fn finish(&self, name: &str) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
        println!("\n{}\n\n{}", self.curves.title(), self.table);
        write_plot(name, |path| {
            self.curves.write_svg(path).map_err(|e| e.to_string())
        });
    }
}

/// |a - b| / |b|, or |a - b| where |b| < `floor` (a component whose true value is about 0).
pub fn rel_err(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / b.abs().max(floor)
}

/// Prints the scene's verdict line and exits with status 1 when it did not converge (so a CI
/// or GPU run can trust the exit status).
pub fn verdict(scene: &str, converged: bool, criterion: &str) {
    println!(
        "\n{scene}: converged: {} ({criterion})",
        if converged { "yes" } else { "NO" }
    );
    if !converged {
        std::process::exit(1);
    }
}

/// Prints what the process compiled at run time (ask 3: only what was launched).
pub fn print_compiled() {
    print!("\n{}", wp::compile_summary());
}

/// The scenes' random start states: ChaCha8 (rand_chacha) seeded by the scene, so that every
/// run, on every platform, starts from the same state and reports the same accuracy (its
/// stream is fixed by the algorithm, unlike `rand`'s `StdRng`, which may change between
/// releases). Uniform samples come from `rand::Rng::random`, normal ones from
/// `rand_distr::StandardNormal`.
pub type Rng = rand_chacha::ChaCha8Rng;

/// The generator of `seed`.
pub fn rng(seed: u64) -> Rng {
    rand::SeedableRng::seed_from_u64(seed)
}

/// The scenes' `--graph`: the timed runs once with plain launches and once as replays of
/// captured graphs (`wp::capture`), as two series of the sweep (`"<series> graph"`); the same
/// kernels in the same order, so the errors agree and the times show the speed-up.
pub fn graph_modes(graph: bool) -> &'static [bool] {
    if graph {
        &[false, true]
    } else {
        &[false]
    }
}

/// A scene's step loop advanced in chunks of `len` steps. With `graph`, a chunk of exactly
/// `len` steps is one replay of a graph that captured `len` calls of the step (captured at the
/// first such chunk, so the step's kernels are loaded before: the scenes warm up first); other
/// chunks, and every chunk without `graph`, are launched plainly. A step that swaps arrays
/// must leave them as it found them after `len` steps (the scenes pick `len` a multiple of
/// the swap's period).
pub struct Stepper {
    graph: bool,
    len: usize,
    captured: Option<wp::Graph>,
}

impl Stepper {
    pub fn new(graph: bool, len: usize) -> Stepper {
        Stepper {
            graph,
            len,
            captured: None,
        }
    }

    /// The chunk length.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Runs `n` steps of `step` on `dev`.
    pub fn advance(
        &mut self,
        dev: &wp::Device,
        n: usize,
        step: &mut dyn FnMut() -> wp::Result<()>,
    ) -> wp::Result<()> {
        if self.graph && n == self.len {
            if self.captured.is_none() {
                let graph = wp::capture(dev, || {
                    for _ in 0..n {
                        step()?;
                    }
                    Ok(())
                })?;
                self.captured = Some(graph);
            }
            return self.captured.as_ref().expect("captured above").launch();
        }
        for _ in 0..n {
            step()?;
        }
        Ok(())
    }
}

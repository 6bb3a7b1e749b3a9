//! What the scenes share: arguments, the device, and printing a sweep with its plot and
//! what was compiled.

#![allow(dead_code)] // each example uses its own subset

use std::path::PathBuf;

use warp_lang as wp;
use warp_report::Sweep;

/// Checks the command line against the scene's options (each `--name VALUE`): prints
/// `usage` for `-h`/`--help`, and stops with a message on an unknown option or a missing value.
/// `--device` and `--plot-dir` are known to every scene.
pub fn check_args(known: &[&str], usage: &str) {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut k = 0;
    while k < args.len() {
        let a = args[k].as_str();
        if a == "-h" || a == "--help" {
            println!("usage: {usage}");
            std::process::exit(0);
        }
        // `--graph` (in `known` where a scene has it) takes no value.
        if a == "--graph" && known.contains(&a) {
            k += 1;
            continue;
        }
        if !(known.contains(&a) || a == "--device" || a == "--plot-dir") {
            eprintln!("unknown argument {a}\nusage: {usage}");
            std::process::exit(2);
        }
        if k + 1 == args.len() {
            eprintln!("{a} needs a value");
            std::process::exit(2);
        }
        k += 2;
    }
}

/// The value after `--name` on the command line, if given.
pub fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    let k = args.iter().position(|a| a == name)?;
    args.get(k + 1).cloned()
}

/// Whether `--name` is on the command line.
pub fn flag(name: &str) -> bool {
    std::env::args().any(|a| a == name)
}

/// `--name VALUE` parsed, or `default`; a value that does not parse stops the scene with a
/// message naming the argument.
pub fn parsed<T: std::str::FromStr>(name: &str, default: T) -> T
where
    T::Err: std::fmt::Display,
{
    match arg(name) {
        None => default,
        Some(v) => v.replace('_', "").parse().unwrap_or_else(|e| {
            eprintln!("{name} {v}: {e}");
            std::process::exit(2)
        }),
    }
}

/// `--device NAME`, else the preferred device (the first GPU, or the CPU without one).
pub fn device() -> wp::Result<wp::Device> {
    wp::init();
    match arg("--device") {
        Some(d) => wp::get_device(&d),
        None => Ok(wp::get_preferred_device()),
    }
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
    let dir = PathBuf::from(arg("--plot-dir").unwrap_or_else(|| "target/report".into()));
    let path = dir.join(format!("{name}.svg"));
    match std::fs::create_dir_all(&dir)
        .map_err(|e| e.to_string())
        .and_then(|()| write(&path))
    {
        Ok(()) => println!("plot: {}", path.display()),
        Err(e) => println!("plot not written: {e}"),
    }
}

/// The log of an optimisation: every iteration goes into the curves (the plot); every
/// `every`-th, the first and the last also into the printed table, with the elapsed time since
/// the log started, the mean time per iteration so far and the gradient's norm.
pub struct OptLog {
    table: warp_report::Table,
    pub curves: warp_report::Curves,
    start: std::time::Instant,
    every: usize,
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
        }
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

/// SplitMix64: a small, well-known generator, so that start states are reproducible
/// without extra dependencies.
pub struct Rng(pub u64);

impl Rng {
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u = 1.0 - self.next_f64(); // (0, 1]: the log is finite
        let w = self.next_f64();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * w).cos()
    }
}

/// The scenes' `--graph`: the timed runs once with plain launches and once as replays of
/// captured graphs (`wp::capture`), as two series of the sweep (`"<series> graph"`); the same
/// kernels in the same order, so the errors agree and the times show the speed-up.
pub fn graph_modes() -> &'static [bool] {
    if flag("--graph") {
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

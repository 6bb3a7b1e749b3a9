//! Work-precision sweeps for warp-lang scenes.
//!
//! A scene runs itself over a sweep (a time step, a resolution, a precision, a solver) and
//! records, for each run, the swept parameter, the steps taken, the error against its
//! reference, the run time and whether the run stayed stable. [`Sweep`] then prints the
//! work-precision table ([`Sweep::table`], markdown, so it can go into a README as is) and
//! writes the same as a log-log plot of error against run time, one line per series
//! ([`Sweep::write_svg`]). Long sweeps show a progress bar on a terminal ([`Sweep::progress`]).
//!
//! [`Curves`] plots an optimiser's loss (or any value) against iteration, for the
//! differentiable scenes.
//!
//! [`frame::Frame`] draws a still picture of a scene (particles, lines and triangle meshes
//! seen by a camera) into an SVG, for a README or a report.
//!
//! This crate knows nothing about kernels or devices: a scene measures its own run, and
//! says what "error" and "stable" mean for it. It is optional: `warp-lang` re-exports it as
//! `wp::report` behind the `report` feature, so that simulations that do not report pull in
//! neither the plotting nor the progress crate.
//!
//! ```
//! use warp_report::{Run, Sweep};
//! let mut sweep = Sweep::new("decay x' = -x until t = 1", "dt");
//! for dt in [0.1, 0.01] {
//!     let steps = (1.0f64 / dt).round() as u64;
//!     let t = std::time::Instant::now();
//!     let x = (0..steps).fold(1.0f64, |x, _| x - dt * x);
//!     let error = (x - (-1.0f64).exp()).abs();
//!     sweep.record("explicit Euler", dt, Run::stable(steps, error, t.elapsed().as_secs_f64()));
//! }
//! assert!(sweep.table().contains("explicit Euler"));
//! ```
// Every public type can be printed in a test or a log line.
#![warn(missing_debug_implementations)]

use std::fmt;
use std::path::Path;

mod curves;
pub mod frame;
mod plot;
mod table;

pub use curves::Curves;
pub use plot::PlotError;
pub use table::Table;

/// Whether a run stayed stable, and if not, what gave it away.
#[derive(Clone, Debug, PartialEq)]
pub enum Stability {
    Stable,
    /// The reason, as the scene's divergence guard reported it ("NaN in x at step 384, index 7").
    Unstable(String),
}

impl Stability {
    pub fn is_stable(&self) -> bool {
        matches!(self, Stability::Stable)
    }
}

/// What one run of a scene measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Run {
    /// Time steps taken (those taken before a blow-up was detected, for an unstable run).
    pub steps: u64,
    /// Error against the scene's reference; NaN where there is none (an unstable run).
    pub error: f64,
    /// Wall-clock seconds of the run, without warm-up or reference computation.
    pub seconds: f64,
    pub stability: Stability,
    /// Values of the sweep's extra columns, in the order of [`Sweep::extras`].
    pub extras: Vec<f64>,
}

impl Run {
    /// A run that stayed stable.
    pub fn stable(steps: u64, error: f64, seconds: f64) -> Self {
        Run {
            steps,
            error,
            seconds,
            stability: Stability::Stable,
            extras: Vec::new(),
        }
    }

    /// A run that blew up (or was stopped by a guard) after `steps` steps.
    pub fn unstable(steps: u64, seconds: f64, reason: impl Into<String>) -> Self {
        Run {
            steps,
            error: f64::NAN,
            seconds,
            stability: Stability::Unstable(reason.into()),
            extras: Vec::new(),
        }
    }

    /// Adds the value of the next extra column (energy drift, momentum drift, ...).
    pub fn extra(mut self, value: f64) -> Self {
        self.extras.push(value);
        self
    }
}

/// One row of a sweep: a run and what it was run with.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The solver, precision or variant this run belongs to: one line in the plot.
    pub series: String,
    /// The swept parameter's value.
    pub param: f64,
    pub run: Run,
}

/// A work-precision sweep: rows of runs, printed as a table and plotted.
pub struct Sweep {
    title: String,
    param: String,
    extras: Vec<String>,
    rows: Vec<Row>,
    bar: Option<indicatif::ProgressBar>,
}

impl fmt::Debug for Sweep {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Sweep")
            .field("title", &self.title)
            .field("param", &self.param)
            .field("extras", &self.extras)
            .field("rows", &self.rows)
            .finish()
    }
}

impl Sweep {
    /// A sweep over the parameter named `param` ("dt", "r", "stiffness").
    pub fn new(title: impl Into<String>, param: impl Into<String>) -> Self {
        Sweep {
            title: title.into(),
            param: param.into(),
            extras: Vec::new(),
            rows: Vec::new(),
            bar: None,
        }
    }

    /// Names extra columns (each [`Run`] then gives their values with [`Run::extra`]).
    pub fn with_extras(mut self, names: &[&str]) -> Self {
        self.extras = names.iter().map(|s| s.to_string()).collect();
        self
    }

    /// Shows a progress bar of `total` runs on stderr. It draws only on a terminal, so logs
    /// and CI output stay clean.
    pub fn progress(mut self, total: u64) -> Self {
        let bar = indicatif::ProgressBar::new(total);
        if let Ok(style) =
            indicatif::ProgressStyle::with_template("{msg:>28} [{bar:30}] {pos}/{len} {elapsed}")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        self.bar = Some(bar);
        self
    }

    pub fn title(&self) -> &str {
        &self.title
    }

    pub fn extras(&self) -> &[String] {
        &self.extras
    }

    pub fn rows(&self) -> &[Row] {
        &self.rows
    }

    /// Records a run.
    pub fn record(&mut self, series: &str, param: f64, run: Run) -> &Row {
        if let Some(bar) = &self.bar {
            bar.set_message(format!("{series}, {} = {}", self.param, sci(param)));
            bar.inc(1);
        }
        self.rows.push(Row {
            series: series.to_string(),
            param,
            run,
        });
        self.rows.last().expect("just pushed")
    }

    /// Runs `f` and records what it measured; an `Err` (a failure of the scene itself, not a
    /// blow-up, which is a [`Run::unstable`]) is passed on and records nothing.
    pub fn run<E>(
        &mut self,
        series: &str,
        param: f64,
        f: impl FnOnce() -> Result<Run, E>,
    ) -> Result<&Row, E> {
        let run = f()?;
        Ok(self.record(series, param, run))
    }

    /// The series in the order they first appear.
    pub fn series(&self) -> Vec<&str> {
        let mut names: Vec<&str> = Vec::new();
        for r in &self.rows {
            if !names.contains(&r.series.as_str()) {
                names.push(&r.series);
            }
        }
        names
    }

    /// The largest parameter value at which `series` ran stable (the sweep's grid spacing
    /// bounds how close that is to the true limit).
    pub fn largest_stable(&self, series: &str) -> Option<f64> {
        self.rows
            .iter()
            .filter(|r| r.series == series && r.run.stability.is_stable())
            .map(|r| r.param)
            .fold(None, |m, p| Some(m.map_or(p, |m: f64| m.max(p))))
    }

    /// Removes the progress bar (call before printing the table).
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }

    /// The work-precision table, in markdown.
    pub fn table(&self) -> String {
        let mut headers = vec![
            "series".to_string(),
            self.param.clone(),
            "steps".to_string(),
            "error".to_string(),
            "time (ms)".to_string(),
        ];
        headers.extend(self.extras.iter().cloned());
        headers.push("stable".to_string());
        let mut t = Table::new(headers);
        for r in &self.rows {
            let mut cells = vec![
                r.series.clone(),
                sci(r.param),
                r.run.steps.to_string(),
                if r.run.error.is_nan() {
                    "-".to_string()
                } else {
                    sci(r.run.error)
                },
                format!("{:.2}", r.run.seconds * 1e3),
            ];
            cells.extend(
                (0..self.extras.len()).map(|k| r.run.extras.get(k).map_or("-".into(), |&v| sci(v))),
            );
            cells.push(match &r.run.stability {
                Stability::Stable => "yes".to_string(),
                Stability::Unstable(why) => format!("no: {why}"),
            });
            t.push(cells);
        }
        format!("{}\n\n{t}", self.title)
    }

    /// Writes the log-log plot of error against run time (one line per series; unstable runs
    /// and runs without a positive error are left out, and the legend says how many).
    pub fn write_svg(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        plot::write_svg(self, path.as_ref())
    }
}

/// A number in the short scientific form the tables use: `1.00e-3`, and plain for integers
/// of moderate size (`60`, `1024`).
pub fn sci(x: f64) -> String {
    if x.is_finite() && x == x.trunc() && x.abs() < 1e6 {
        format!("{x:.0}")
    } else if x.is_finite() && (1e-2..1e4).contains(&x.abs()) {
        // Four significant digits, trailing zeros dropped: 0.25, 1.01, 16.67.
        let digits = (3 - x.abs().log10().floor() as i32).max(0) as usize;
        let s = format!("{x:.digits$}");
        // Trailing zeros are dropped only after a decimal point: 1279.96 prints as 1280.
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{x:.2e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sci_keeps_the_zeros_of_whole_numbers() {
        assert_eq!(sci(1279.96), "1280");
        assert_eq!(sci(100.04), "100");
        assert_eq!(sci(16.6667), "16.67");
        assert_eq!(sci(0.25), "0.25");
        assert_eq!(sci(1024.0), "1024");
        assert_eq!(sci(2.5e-4), "2.50e-4");
    }

    fn sample() -> Sweep {
        let mut s = Sweep::new("test sweep", "dt").with_extras(&["energy drift"]);
        s.record("a", 0.1, Run::stable(10, 2e-3, 0.001).extra(3e-4));
        s.record("a", 0.05, Run::stable(20, 5e-3, 0.002).extra(1e-4));
        s.record("b", 0.1, Run::unstable(7, 0.0005, "NaN in x at step 7"));
        s.record("b", 0.05, Run::stable(20, 1e-6, 0.004).extra(2e-7));
        s
    }

    #[test]
    fn table_lists_every_row_with_its_columns() {
        let t = sample().table();
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines[0], "test sweep");
        assert!(lines[2].contains("energy drift") && lines[2].contains("time (ms)"));
        // Header, rule and four rows.
        assert_eq!(lines.len(), 2 + 2 + 4, "{t}");
        assert!(lines[6].contains("no: NaN in x at step 7"), "{t}");
        assert!(
            lines[6].contains(" - "),
            "an unstable run has no error: {t}"
        );
        assert!(
            lines[4].contains("2.00e-3") && lines[4].contains("3.00e-4"),
            "{t}"
        );
    }

    #[test]
    fn largest_stable_ignores_unstable_runs() {
        let s = sample();
        assert_eq!(s.largest_stable("a"), Some(0.1));
        assert_eq!(s.largest_stable("b"), Some(0.05));
        assert_eq!(s.largest_stable("c"), None);
        assert_eq!(s.series(), vec!["a", "b"]);
    }

    #[test]
    fn sci_forms() {
        assert_eq!(sci(60.0), "60");
        assert_eq!(sci(0.25), "0.25");
        assert_eq!(sci(1.01), "1.01");
        assert_eq!(sci(16.6666), "16.67");
        assert_eq!(sci(0.0123456), "0.01235");
        assert_eq!(sci(1e-3), "1.00e-3");
        assert_eq!(sci(1e7), "1.00e7");
        assert_eq!(sci(f64::INFINITY), "inf");
    }

    #[test]
    fn svg_has_one_line_per_series_and_skips_unstable_points() {
        let dir = std::env::temp_dir().join(format!("warp-report-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("sweep.svg");
        sample().write_svg(&path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..100.min(svg.len())]);
        assert!(svg.contains("test sweep"));
        let texts: Vec<&str> = svg.lines().map(str::trim).collect();
        assert!(texts.contains(&"a"), "legend entry of series a");
        assert!(
            texts.contains(&"b (1 unstable left out)"),
            "the legend notes the left-out run"
        );
        // Three points labelled 0.1 (a), 0.05 (a, b): the unstable b run is not drawn.
        assert_eq!(texts.iter().filter(|t| **t == "0.1").count(), 1);
        assert_eq!(texts.iter().filter(|t| **t == "0.05").count(), 2);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn svg_without_plottable_points_is_an_error() {
        let mut s = Sweep::new("nothing", "dt");
        s.record("a", 1.0, Run::unstable(1, 0.1, "NaN"));
        let err = s
            .write_svg(std::env::temp_dir().join("never.svg"))
            .unwrap_err();
        assert!(err.to_string().contains("no stable run"), "{err}");
    }
}

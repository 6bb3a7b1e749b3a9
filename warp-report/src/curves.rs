//! Convergence curves: a value (a loss, an error) against an iteration count, one line per
//! series, plotted with a log value axis.

use std::fmt;
use std::path::Path;

use plotters::prelude::*;

use crate::plot::PlotError;

/// Curves of a value against iteration, such as an optimiser's loss: one series per
/// optimiser or gradient, written as an SVG plot with a linear iteration axis and a log value
/// axis ([`Curves::write_svg`]).
///
/// ```
/// use warp_report::Curves;
/// let mut c = Curves::new("gradient descent on x^2", "loss");
/// let mut x = 1.0f64;
/// for it in 0..20 {
///     c.push("lr 0.1", it as f64, x * x);
///     x -= 0.1 * 2.0 * x;
/// }
/// assert_eq!(c.series(), vec!["lr 0.1"]);
/// assert!(c.last("lr 0.1").unwrap().1 < 1e-3);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Curves {
    title: String,
    value: String,
    lines: Vec<(String, Vec<(f64, f64)>)>,
}

impl Curves {
    /// Curves titled `title` of the quantity named `value` ("loss", "|x_T - target|").
    pub fn new(title: impl Into<String>, value: impl Into<String>) -> Self {
        Curves {
            title: title.into(),
            value: value.into(),
            lines: Vec::new(),
        }
    }

    pub fn title(&self) -> &str {
        &self.title
    }

    /// Adds the point (`iteration`, `value`) to `series` (created at its first point).
    pub fn push(&mut self, series: &str, iteration: f64, value: f64) {
        match self.lines.iter_mut().find(|(name, _)| name == series) {
            Some((_, pts)) => pts.push((iteration, value)),
            None => self
                .lines
                .push((series.to_string(), vec![(iteration, value)])),
        }
    }

    /// The series in the order they first appeared.
    pub fn series(&self) -> Vec<&str> {
        self.lines.iter().map(|(name, _)| name.as_str()).collect()
    }

    /// The points of `series`, in the order pushed.
    pub fn points(&self, series: &str) -> Option<&[(f64, f64)]> {
        self.lines
            .iter()
            .find(|(name, _)| name == series)
            .map(|(_, pts)| pts.as_slice())
    }

    /// The last point of `series`.
    pub fn last(&self, series: &str) -> Option<(f64, f64)> {
        self.points(series).and_then(|p| p.last().copied())
    }

    /// Writes the plot: iteration on a linear axis, the value on a log axis. Points whose value
    /// is not positive and finite cannot be shown on a log axis and are left out (the legend
    /// says how many).
    ///
    /// # Errors
    /// When no series has a plottable point, or the file cannot be written.
    pub fn write_svg(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        let path = path.as_ref();
        let ok = |v: f64| v.is_finite() && v > 0.0;
        let all = self
            .lines
            .iter()
            .flat_map(|(_, p)| p.iter())
            .filter(|p| ok(p.1) && p.0.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) =
            (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, 0.0f64);
        let mut any = false;
        for &(x, y) in all {
            any = true;
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if !any {
            return Err(PlotError::new(format!(
                "nothing to plot for \"{}\": no point with a positive, finite value",
                self.title
            )));
        }
        if x1 <= x0 {
            x1 = x0 + 1.0;
        }
        let (y0, y1) = (y0 / 2.0, y1 * 2.0);
        let err = crate::plot::drawing::<std::io::Error>(path);
        let root = SVGBackend::new(path, (860, 600)).into_drawing_area();
        root.fill(&WHITE).map_err(&err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, ("sans-serif", 20))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(x0..x1, (y0..y1).log_scale())
            .map_err(&err)?;
        chart
            .configure_mesh()
            .x_desc("iteration")
            .y_desc(self.value.as_str())
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.0e}"))
            .draw()
            .map_err(&err)?;
        for (k, (name, pts)) in self.lines.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            let xy: Vec<(f64, f64)> = pts
                .iter()
                .copied()
                .filter(|p| ok(p.1) && p.0.is_finite())
                .collect();
            let label = match pts.len() - xy.len() {
                0 => name.clone(),
                n => format!("{name} ({n} non-positive left out)"),
            };
            chart
                .draw_series(LineSeries::new(xy, color.stroke_width(2)))
                .map_err(&err)?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(&err)?;
        root.present().map_err(&err)?;
        Ok(())
    }
}

impl fmt::Display for Curves {
    /// The last point of each series, one line each.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "{}", self.title)?;
        for (name, pts) in &self.lines {
            if let Some((it, v)) = pts.last() {
                writeln!(
                    f,
                    "  {name}: {} = {} at iteration {it}",
                    self.value,
                    crate::sci(*v)
                )?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_has_a_line_per_series_and_notes_left_out_points() {
        let mut c = Curves::new("test curves", "loss");
        for it in 0..10 {
            c.push("adam", it as f64, 1.0 / (1.0 + it as f64));
            c.push("sgd", it as f64, if it == 3 { 0.0 } else { 0.5 });
        }
        assert_eq!(c.series(), vec!["adam", "sgd"]);
        assert_eq!(c.points("adam").unwrap().len(), 10);
        assert_eq!(c.last("sgd"), Some((9.0, 0.5)));
        let dir = std::env::temp_dir().join(format!("warp-report-curves-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("curves.svg");
        c.write_svg(&path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg"));
        assert!(svg.contains("test curves"));
        let texts: Vec<&str> = svg.lines().map(str::trim).collect();
        assert!(texts.contains(&"adam"), "legend entry of adam");
        assert!(texts.contains(&"sgd (1 non-positive left out)"));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn nothing_plottable_is_an_error() {
        let mut c = Curves::new("zeros", "loss");
        c.push("a", 0.0, 0.0);
        let e = c
            .write_svg(std::env::temp_dir().join("never-curves.svg"))
            .unwrap_err();
        assert!(e.to_string().contains("nothing to plot"), "{e}");
    }
}

//! The work-precision plot: log-log error against run time, one line per series.

use std::path::Path;

use plotters::prelude::*;

use crate::{sci, Sweep};

/// Why a plot could not be written: nothing to plot, or the SVG file could not be written
/// (then plotters' or the file system's error is the
/// [`source`](std::error::Error::source), which the message does not repeat).
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct PlotError {
    message: String,
    #[source]
    source: Option<Box<dyn std::error::Error + Send + Sync + 'static>>,
}

impl PlotError {
    /// A failure with nothing below it.
    pub(crate) fn new(message: String) -> Self {
        PlotError {
            message,
            source: None,
        }
    }

    /// A failure caused by `source` (kept as the error's source).
    pub(crate) fn caused_by(
        message: String,
        source: impl std::error::Error + Send + Sync + 'static,
    ) -> Self {
        PlotError {
            message,
            source: Some(Box::new(source)),
        }
    }
}

/// plotters' error while drawing into `path`, as a [`PlotError`] naming the path, with
/// plotters' error as its source (not repeated in the message: reporters print the chain).
pub(crate) fn drawing<E: std::error::Error + Send + Sync + 'static>(
    path: &Path,
) -> impl Fn(DrawingAreaErrorKind<E>) -> PlotError + '_ {
    move |e| PlotError::caused_by(cannot_write(path), e)
}

/// The message of a [`PlotError`] whose source says why `path` could not be written.
pub(crate) fn cannot_write(path: &Path) -> String {
    format!("cannot write {}", path.display())
}

/// Bounds of a log axis around positive values, padded by a factor on each side.
fn log_bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    (lo / 2.0, hi * 2.0)
}

pub(crate) fn write_svg(sweep: &Sweep, path: &Path) -> Result<(), PlotError> {
    // Points a log-log plot can show: stable runs with a positive error and run time.
    let plottable =
        |r: &&crate::Row| r.run.stability.is_stable() && r.run.error > 0.0 && r.run.seconds > 0.0;
    let points: Vec<&crate::Row> = sweep.rows().iter().filter(plottable).collect();
    if points.is_empty() {
        return Err(PlotError::new(format!(
            "nothing to plot for \"{}\": no stable run with a positive error and run time",
            sweep.title()
        )));
    }
    let (x0, x1) = log_bounds(points.iter().map(|r| r.run.seconds));
    let (y0, y1) = log_bounds(points.iter().map(|r| r.run.error));

    let err = drawing(path);
    let root = SVGBackend::new(path, (860, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(&err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(sweep.title(), ("sans-serif", 20))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(&err)?;
    chart
        .configure_mesh()
        .x_desc("run time (s)")
        .y_desc("error")
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .draw()
        .map_err(&err)?;

    for (k, name) in sweep.series().into_iter().enumerate() {
        let color = Palette99::pick(k).to_rgba();
        let mut pts: Vec<&crate::Row> = points
            .iter()
            .copied()
            .filter(|r| r.series == name)
            .collect();
        pts.sort_by(|a, b| a.run.seconds.total_cmp(&b.run.seconds));
        let left_out = sweep.rows().iter().filter(|r| r.series == name).count() - pts.len();
        let label = match left_out {
            0 => name.to_string(),
            n => format!("{name} ({n} unstable left out)"),
        };
        let xy: Vec<(f64, f64)> = pts.iter().map(|r| (r.run.seconds, r.run.error)).collect();
        chart
            .draw_series(LineSeries::new(xy.clone(), color.stroke_width(2)))
            .map_err(&err)?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart
            .draw_series(xy.iter().map(|&p| Circle::new(p, 3, color.filled())))
            .map_err(&err)?;
        // Each point names its parameter value, so the plot reads without the table.
        chart
            .draw_series(pts.iter().map(|r| {
                Text::new(
                    sci(r.param),
                    (r.run.seconds, r.run.error),
                    ("sans-serif", 11).into_font().color(&color),
                )
            }))
            .map_err(&err)?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::error::Error as _;

    /// A frame written where it cannot be: the message names the path, the source says why.
    fn unwritable() -> PlotError {
        let camera = crate::frame::Camera::orthographic([0.0, 0.0, 5.0], [0.0; 3], [0.0, 1.0, 0.0]);
        crate::frame::Frame::new("t", camera)
            .write_svg(Path::new("/nonexistent-warp-report-dir/plot.svg"))
            .expect_err("no such directory")
    }

    #[test]
    fn the_message_does_not_repeat_its_source() {
        let e = unwritable();
        assert_eq!(
            e.to_string(),
            "cannot write /nonexistent-warp-report-dir/plot.svg"
        );
        let source = e.source().expect("the I/O error").to_string();
        assert!(!e.to_string().contains(&source), "{e} repeats {source}");
        assert!(PlotError::new("nothing to plot".into()).source().is_none());
    }

    #[test]
    fn a_chain_walk_prints_the_cause_once() {
        let e = unwritable();
        let cause = e.source().expect("the I/O error").to_string();
        let mut report = e.to_string();
        let mut source = e.source();
        while let Some(s) = source {
            report.push_str(&format!(": {s}"));
            source = s.source();
        }
        assert_eq!(report.matches(&cause).count(), 1, "{report}");
    }
}

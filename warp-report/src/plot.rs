//! The work-precision plot: log-log error against run time, one line per series.

use std::path::Path;

use plotters::prelude::*;

use crate::{sci, Sweep};

/// Why a plot could not be written: nothing to plot, or the SVG file could not be written
/// (then plotters' error is the [`source`](std::error::Error::source)).
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

/// plotters' error while drawing into `path`, as a [`PlotError`] naming the path (and
/// repeating plotters' message, so that printing only the top error loses nothing).
pub(crate) fn drawing<E: std::error::Error + Send + Sync + 'static>(
    path: &Path,
) -> impl Fn(DrawingAreaErrorKind<E>) -> PlotError + '_ {
    move |e| PlotError {
        message: format!("writing {}: {e}", path.display()),
        source: Some(Box::new(e)),
    }
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

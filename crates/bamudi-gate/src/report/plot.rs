//! The figures' one style: a palette with fixed meanings (truth, before, after, band, prior),
//! a ten-colour categorical palette that never recycles within a figure, and the line plot
//! every report draws with, whose legend sits in its own strip beside the data.

use crate::error::{GateAppError, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// The known truth (synthetic studies).
pub const TRUTH: RGBColor = RGBColor(0, 0, 0);
/// Before calibration (the nominal model), or "without" a correction.
pub const BEFORE: RGBColor = RGBColor(200, 60, 40);
/// After calibration: the calibrated answer.
pub const AFTER: RGBColor = RGBColor(30, 90, 200);
/// A 95 % band around [`AFTER`].
pub const BAND: RGBColor = RGBColor(120, 160, 230);
/// The strongest baseline: the best calibration without a discrepancy.
pub const NO_DELTA: RGBColor = RGBColor(110, 110, 110);
/// The prior.
pub const PRIOR: RGBColor = RGBColor(150, 150, 150);
/// An alarm (a detected change) and its onset interval.
pub const ALARM: RGBColor = RGBColor(255, 127, 14);
/// Ten distinguishable colours (matplotlib's tab10) for series without a fixed meaning.
pub const CATEGORICAL: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Width of the legend strip (px).
const LEGEND_WIDTH: u32 = 230;

/// One labelled polyline (an empty label keeps it out of the legend).
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Colour.
    pub color: RGBColor,
    /// Points `(x, y)`.
    pub points: Vec<(f64, f64)>,
    /// Dashed line.
    pub dashed: bool,
    /// Draw a marker at every point.
    pub markers: bool,
    /// Join the points by a line (off for a scatter).
    pub line: bool,
}

impl Series {
    /// A solid line.
    pub fn new(label: &str, color: RGBColor, points: Vec<(f64, f64)>) -> Self {
        Self {
            label: label.into(),
            color,
            points,
            dashed: false,
            markers: false,
            line: true,
        }
    }

    /// Markers only (a scatter).
    pub fn scatter(label: &str, color: RGBColor, points: Vec<(f64, f64)>) -> Self {
        Self {
            markers: true,
            line: false,
            ..Self::new(label, color, points)
        }
    }

    /// The series from separate coordinate slices.
    pub fn xy(label: &str, color: RGBColor, xs: &[f64], ys: &[f64]) -> Self {
        Self::new(
            label,
            color,
            xs.iter().copied().zip(ys.iter().copied()).collect(),
        )
    }

    /// Dashed.
    pub fn dashed(mut self) -> Self {
        self.dashed = true;
        self
    }

    /// With a marker at each point.
    pub fn markers(mut self) -> Self {
        self.markers = true;
        self
    }
}

/// Title, axis labels (with units) and optional ranges of one chart.
#[derive(Debug, Clone, Default)]
pub struct Axes {
    /// Title.
    pub title: String,
    /// x-axis label with its unit.
    pub x_label: String,
    /// y-axis label with its unit.
    pub y_label: String,
    /// x range (default: the data, padded 5 %).
    pub x_range: Option<(f64, f64)>,
    /// y range (default: the data, padded 5 %).
    pub y_range: Option<(f64, f64)>,
}

impl Axes {
    /// Axes with a title and labels; ranges from the data.
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            ..Self::default()
        }
    }
}

/// The finite range of `values`, padded 5 % (a unit range when there is nothing finite).
pub fn padded_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = 0.05 * (hi - lo).max(1e-9 * (1.0 + hi.abs()));
    (lo - pad, hi + pad)
}

/// Compact tick labels: no trailing zeros, at most 6 decimals (ticks of a narrow range
/// stay distinct), scientific notation outside `[1e-3, 1e6)`.
pub fn tick(v: &f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e6).contains(&a) {
        return format!("{v:.2e}");
    }
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// A figure's drawing area.
pub type Canvas<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// What drawing code returns (plotters' errors boxed).
pub type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

/// Draws a figure of `size` px in memory and writes it to `path` atomically (temporary name,
/// then rename): a failed or killed run never leaves a truncated SVG.
pub fn svg_figure(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&Canvas<'_>) -> DrawResult,
) -> Result<()> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        let drawn = root
            .fill(&WHITE)
            .map_err(|e| e.to_string())
            .and_then(|_| draw(&root).map_err(|e| e.to_string()))
            .and_then(|_| root.present().map_err(|e| e.to_string()));
        drawn.map_err(|e| GateAppError::plot(path, e))?;
    }
    Ok(bamudi::data::write_atomic(path, svg.as_bytes())?)
}

/// Writes a line plot: the title across the top (long titles are not clipped by the chart's
/// width), the legend in a strip at the right.
pub fn line_plot(path: &Path, axes: &Axes, series: &[Series]) -> Result<()> {
    svg_figure(path, (960, 560), |root| {
        let (head, body) = root.split_vertically(34);
        head.draw(&Text::new(axes.title.clone(), (14, 10), ("sans-serif", 17)))?;
        let (plot, legend) = body.split_horizontally(960 - LEGEND_WIDTH);
        let untitled = Axes {
            title: String::new(),
            ..axes.clone()
        };
        draw_chart(&plot, &untitled, series)?;
        draw_legend(&legend, series)
    })
}

/// Draws one chart into `area` (used for multi-panel figures too).
pub fn draw_chart(area: &Canvas<'_>, axes: &Axes, series: &[Series]) -> DrawResult {
    let xr = axes
        .x_range
        .unwrap_or_else(|| padded_range(series.iter().flat_map(|s| s.points.iter().map(|p| p.0))));
    let yr = axes
        .y_range
        .unwrap_or_else(|| padded_range(series.iter().flat_map(|s| s.points.iter().map(|p| p.1))));
    let mut builder = ChartBuilder::on(area);
    if !axes.title.is_empty() {
        builder.caption(&axes.title, ("sans-serif", 16));
    }
    let mut chart = builder
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(80)
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)?;
    chart
        .configure_mesh()
        .x_desc(&axes.x_label)
        .y_desc(&axes.y_label)
        .x_labels(6)
        .y_labels(8)
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .draw()?;
    let inside = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
    for s in series {
        let style = ShapeStyle::from(&s.color).stroke_width(2);
        let pts: Vec<(f64, f64)> = s.points.iter().copied().filter(inside).collect();
        if s.line && s.dashed {
            chart.draw_series(DashedLineSeries::new(pts.clone(), 6, 4, style))?;
        } else if s.line {
            chart.draw_series(LineSeries::new(pts.clone(), style))?;
        }
        if s.markers {
            chart.draw_series(pts.iter().map(|p| Circle::new(*p, 3, s.color.filled())))?;
        }
    }
    Ok(())
}

/// The legend entries of the labelled series, one per line, in a strip of their own.
pub fn draw_legend(area: &Canvas<'_>, series: &[Series]) -> DrawResult {
    let mut y = 30;
    for s in series.iter().filter(|s| !s.label.is_empty()) {
        let style = ShapeStyle::from(&s.color).stroke_width(2);
        if s.dashed {
            area.draw(&PathElement::new(vec![(8, y), (18, y)], style))?;
            area.draw(&PathElement::new(vec![(24, y), (34, y)], style))?;
        } else {
            area.draw(&PathElement::new(vec![(8, y), (34, y)], style))?;
        }
        area.draw(&Text::new(s.label.clone(), (42, y - 8), ("sans-serif", 14)))?;
        y += 22;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_compact() {
        assert_eq!(tick(&2.0), "2");
        assert_eq!(tick(&90.05), "90.05");
        assert_eq!(tick(&-0.0), "0");
        assert_eq!(tick(&2_000_000.0), "2.00e6");
    }
}

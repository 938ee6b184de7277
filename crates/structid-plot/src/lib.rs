//! Pure SVG plotting helpers for structid.
//!
//! The crate renders four kinds of figures, all as SVG (no font rasterisation,
//! no system libraries):
//!
//! * 2-D charts of one or more [`Series`] (lines, dots, shaded bands), see
//!   [`Chart`], [`render_chart_svg`] and [`write_chart_svg`];
//! * several charts tiled in one figure, see [`render_grid_svg`];
//! * heat maps of scalar fields on rectilinear grids with a colour bar, see
//!   [`HeatMap`] and [`render_heatmaps_svg`];
//! * correlation functions as bars over their lags with a confidence band
//!   (residual tests), see [`CorrelationChart`] and [`render_correlation_svg`].
//!
//! Inputs are plain slices so the crate is independent of the rest of
//! structid. Bad input (empty data, mismatched lengths, non-finite
//! coordinates, ...) is reported through [`PlotError`]; the functions never
//! panic on it. Non-finite data values are skipped.
//!
//! ```
//! use structid_plot::{Chart, Series, write_chart_svg};
//!
//! let x: Vec<f64> = (0..50).map(|i| i as f64 / 10.0).collect();
//! let y: Vec<f64> = x.iter().map(|v| v.sin()).collect();
//! let chart = Chart::new("sine", "x", "sin(x)").with(Series::line("sin", &x, &y));
//! let path = std::env::temp_dir().join("structid_plot_crate_doc.svg");
//! write_chart_svg(&path, &chart).unwrap();
//! # std::fs::remove_file(&path).ok();
//! ```

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Default size in pixels of a single chart, `(width, height)`.
pub const DEFAULT_SIZE: (u32, u32) = (800, 500);

/// Smallest accepted width or height of a chart or panel in pixels.
///
/// Smaller drawing areas cannot hold the title, axes, tick labels and
/// colour bar legibly.
pub const MIN_PANEL_SIZE: u32 = 200;

/// Largest accepted width or height of a whole figure in pixels.
pub const MAX_FIGURE_SIZE: u32 = 100_000;

/// Errors produced while rendering or writing a figure.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlotError {
    /// There is nothing to draw (no series, an empty series, no finite point, ...).
    #[error("empty data: {0}")]
    EmptyData(String),
    /// Two slices that must have the same length do not.
    #[error("length mismatch for {what}: {x} vs {y}")]
    LengthMismatch {
        /// Which slices were compared.
        what: String,
        /// Length of the reference slice (e.g. `x`, or `xs.len() * ys.len()`).
        x: usize,
        /// Length of the slice compared with it.
        y: usize,
    },
    /// Input that is not empty and has consistent lengths but still cannot be
    /// drawn (non-finite grid coordinates or value range, panel too small, ...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// The plotting backend failed.
    #[error("plotting backend error: {0}")]
    Backend(String),
    /// Writing the output file failed.
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
}

fn backend_err<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError::Backend(e.to_string())
}

/// How a [`Series`] is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SeriesStyle<'a> {
    /// A polyline through the points; it is broken at non-finite points.
    Line,
    /// One filled circle per finite point.
    Dots,
    /// A semi-transparent filled area between `lower` and `upper` at the
    /// series' `x` (which should be sorted). If the series' `y` is not
    /// empty it is drawn as a line on top of the band (e.g. a mean with its
    /// confidence interval). The band is broken at non-finite points.
    Band {
        /// Lower edge of the band, same length as `x`.
        lower: &'a [f64],
        /// Upper edge of the band, same length as `x`.
        upper: &'a [f64],
    },
}

/// One data series on a 2-D chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series<'a> {
    /// Legend label (the legend is shown when a chart has more than one series).
    pub label: String,
    /// Abscissae.
    pub x: &'a [f64],
    /// Ordinates, same length as `x` (may be empty for [`SeriesStyle::Band`]).
    pub y: &'a [f64],
    /// How the series is drawn.
    pub style: SeriesStyle<'a>,
}

impl<'a> Series<'a> {
    /// A series drawn as a line.
    pub fn line(label: impl Into<String>, x: &'a [f64], y: &'a [f64]) -> Self {
        Self {
            label: label.into(),
            x,
            y,
            style: SeriesStyle::Line,
        }
    }

    /// A series drawn as dots (a scatter plot).
    pub fn dots(label: impl Into<String>, x: &'a [f64], y: &'a [f64]) -> Self {
        Self {
            label: label.into(),
            x,
            y,
            style: SeriesStyle::Dots,
        }
    }

    /// A shaded band between `lower` and `upper`, with an optional centre
    /// line `y` (pass an empty slice for none).
    pub fn band(
        label: impl Into<String>,
        x: &'a [f64],
        y: &'a [f64],
        lower: &'a [f64],
        upper: &'a [f64],
    ) -> Self {
        Self {
            label: label.into(),
            x,
            y,
            style: SeriesStyle::Band { lower, upper },
        }
    }

    /// Checks lengths and emptiness.
    fn validate(&self) -> Result<(), PlotError> {
        if self.x.is_empty() {
            return Err(PlotError::EmptyData(format!(
                "series '{}' has no points",
                self.label
            )));
        }
        let check = |name: &str, len: usize| {
            if len != self.x.len() {
                Err(PlotError::LengthMismatch {
                    what: format!("series '{}': x vs {name}", self.label),
                    x: self.x.len(),
                    y: len,
                })
            } else {
                Ok(())
            }
        };
        match self.style {
            SeriesStyle::Line | SeriesStyle::Dots => check("y", self.y.len()),
            SeriesStyle::Band { lower, upper } => {
                if !self.y.is_empty() {
                    check("y", self.y.len())?;
                }
                check("lower", lower.len())?;
                check("upper", upper.len())
            }
        }
    }

    /// Feeds every finite drawn point to `f`.
    fn for_each_finite_point(&self, mut f: impl FnMut(f64, f64)) {
        let mut visit = |ys: &[f64]| {
            for (&x, &y) in self.x.iter().zip(ys) {
                if x.is_finite() && y.is_finite() {
                    f(x, y);
                }
            }
        };
        visit(self.y);
        if let SeriesStyle::Band { lower, upper } = self.style {
            visit(lower);
            visit(upper);
        }
    }
}

/// A 2-D chart: title, axis labels and a list of series.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart<'a> {
    /// Title drawn above the plot.
    pub title: String,
    /// Label of the horizontal axis.
    pub x_label: String,
    /// Label of the vertical axis.
    pub y_label: String,
    /// The series, drawn in order with distinct colours.
    pub series: Vec<Series<'a>>,
    /// `(width, height)` in pixels when rendered alone (default 800x500);
    /// ignored by [`render_grid_svg`], which uses its `panel_size`.
    pub size: (u32, u32),
}

impl<'a> Chart<'a> {
    /// An empty chart of the default size ([`DEFAULT_SIZE`]).
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            size: DEFAULT_SIZE,
        }
    }

    /// Adds a series (builder style).
    pub fn with(mut self, s: Series<'a>) -> Self {
        self.series.push(s);
        self
    }

    /// Sets the size `(width, height)` in pixels (builder style).
    pub fn size(mut self, size: (u32, u32)) -> Self {
        self.size = size;
        self
    }

    /// Validates the series and computes the padded axis ranges.
    fn ranges(&self) -> Result<(Range<f64>, Range<f64>), PlotError> {
        if self.series.is_empty() {
            return Err(PlotError::EmptyData(format!(
                "chart '{}' has no series",
                self.title
            )));
        }
        let mut xb = Bounds::default();
        let mut yb = Bounds::default();
        for s in &self.series {
            s.validate()?;
            s.for_each_finite_point(|x, y| {
                xb.add(x);
                yb.add(y);
            });
        }
        match (xb.padded(), yb.padded()) {
            (Some(xr), Some(yr)) => Ok((xr, yr)),
            _ => Err(PlotError::EmptyData(format!(
                "chart '{}' has no finite data point",
                self.title
            ))),
        }
    }
}

/// Running min/max of finite values.
#[derive(Default)]
struct Bounds {
    lo: f64,
    hi: f64,
    any: bool,
}

impl Bounds {
    fn add(&mut self, v: f64) {
        if !v.is_finite() {
            return;
        }
        if self.any {
            self.lo = self.lo.min(v);
            self.hi = self.hi.max(v);
        } else {
            (self.lo, self.hi, self.any) = (v, v, true);
        }
    }

    /// The range padded by 5% on each side (widened if degenerate).
    fn padded(&self) -> Option<Range<f64>> {
        if !self.any {
            return None;
        }
        let (lo, hi) = widen(self.lo, self.hi);
        let pad = 0.05 * (hi - lo);
        Some(lo - pad..hi + pad)
    }
}

fn clamp_finite(v: f64) -> f64 {
    v.clamp(-f64::MAX, f64::MAX)
}

/// Largest magnitude used for an axis or colour-scale limit. Larger finite
/// data is drawn but the axis stops here (plotters' tick computation needs a
/// finite span).
const AXIS_LIMIT: f64 = 1e300;

/// Smallest span of an axis or colour scale; plotters' tick computation
/// does not terminate on spans that underflow.
const MIN_SPAN: f64 = 1e-200;

/// Makes `lo < hi` with a finite span that is resolvable in floating point
/// (clamping to [`AXIS_LIMIT`] and widening degenerate ranges).
fn widen(lo: f64, hi: f64) -> (f64, f64) {
    let lo = lo.clamp(-AXIS_LIMIT, AXIS_LIMIT);
    let hi = hi.clamp(-AXIS_LIMIT, AXIS_LIMIT);
    let scale = lo.abs().max(hi.abs());
    if hi - lo >= (scale * 1e-9).max(MIN_SPAN) {
        return (lo, hi);
    }
    let mid = lo / 2.0 + hi / 2.0;
    let half = if scale < MIN_SPAN {
        1.0
    } else {
        (scale * 0.1).max(MIN_SPAN)
    };
    (mid - half, mid + half)
}

/// Distinct colours (Tableau 10), cycled.
const PALETTE: [RGBColor; 10] = [
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

/// Colour of the `i`-th series of a chart.
fn series_colour(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

const FONT: &str = "sans-serif";
const TITLE_SIZE: u32 = 24;
const DESC_SIZE: u32 = 19;
const TICK_SIZE: u32 = 16;
const X_LABEL_AREA: u32 = 50;
const Y_LABEL_AREA: u32 = 70;
const MARGIN: u32 = 12;

/// Tick-label formatter for an axis spanning `lo..hi`: enough decimals to
/// distinguish ticks, scientific notation for very large or small numbers.
fn tick_formatter(lo: f64, hi: f64) -> impl Fn(&f64) -> String {
    let span = (hi / 2.0 - lo / 2.0) * 2.0;
    let step = (span / 8.0).abs();
    let mag = lo.abs().max(hi.abs());
    let scientific = mag >= 1e5 || (mag > 0.0 && mag < 1e-3);
    move |v: &f64| {
        let v = *v;
        if !v.is_finite() {
            return v.to_string();
        }
        if v == 0.0 || (step > 0.0 && v.abs() < step * 1e-6) {
            return "0".to_string();
        }
        if scientific {
            let digits = if step > 0.0 && v.abs() > 0.0 {
                ((v.abs().log10().floor() - step.log10().floor()).max(0.0) as usize).min(6)
            } else {
                2
            };
            trim_scientific(&format!("{v:.digits$e}"))
        } else {
            let decimals = if step > 0.0 {
                (-step.log10().floor()).clamp(0.0, 8.0) as usize
            } else {
                2
            };
            format!("{v:.decimals$}")
        }
    }
}

/// `1.500e3` -> `1.5e3`.
fn trim_scientific(s: &str) -> String {
    match s.split_once('e') {
        Some((m, e)) if m.contains('.') => {
            let m = m.trim_end_matches('0').trim_end_matches('.');
            format!("{m}e{e}")
        }
        _ => s.to_string(),
    }
}

/// Compact number formatting for colour-bar extremes (4 significant digits).
fn format_value(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return v.to_string();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        trim_scientific(&format!("{v:.3e}"))
    } else {
        let decimals = (3.0 - a.log10().floor()).clamp(0.0, 6.0) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    }
}

fn check_size(size: (u32, u32), what: &str) -> Result<(), PlotError> {
    if size.0 < MIN_PANEL_SIZE || size.1 < MIN_PANEL_SIZE {
        return Err(PlotError::InvalidInput(format!(
            "{what} size {}x{} is smaller than the minimum {MIN_PANEL_SIZE}x{MIN_PANEL_SIZE}",
            size.0, size.1
        )));
    }
    if size.0 > MAX_FIGURE_SIZE || size.1 > MAX_FIGURE_SIZE {
        return Err(PlotError::InvalidInput(format!(
            "{what} size {}x{} exceeds the maximum {MAX_FIGURE_SIZE}x{MAX_FIGURE_SIZE}",
            size.0, size.1
        )));
    }
    Ok(())
}

/// Maximum numbers of x and y tick labels that fit in an area without
/// overlapping.
fn label_counts(area: &DrawingArea<SVGBackend<'_>, Shift>) -> (usize, usize) {
    let (w, h) = area.dim_in_pixel();
    let x = (w.saturating_sub(Y_LABEL_AREA) / 70).clamp(2, 10) as usize;
    let y = (h.saturating_sub(X_LABEL_AREA + TITLE_SIZE) / 35).clamp(2, 10) as usize;
    (x, y)
}

/// Contiguous runs of indices for which `ok(i)` holds.
fn runs(n: usize, ok: impl Fn(usize) -> bool) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    let mut start = None;
    for i in 0..n {
        match (ok(i), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push(s..i);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push(s..n);
    }
    out
}

/// Draws one chart into a drawing area (the chart's own `size` is ignored).
fn draw_chart(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    chart: &Chart<'_>,
) -> Result<(), PlotError> {
    let (xr, yr) = chart.ranges()?;
    area.fill(&WHITE).map_err(backend_err)?;

    let mut cc = ChartBuilder::on(area)
        .caption(&chart.title, (FONT, TITLE_SIZE))
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(xr.clone(), yr.clone())
        .map_err(backend_err)?;

    let xf = tick_formatter(xr.start, xr.end);
    let yf = tick_formatter(yr.start, yr.end);
    let (xn, yn) = label_counts(area);
    cc.configure_mesh()
        .x_labels(xn)
        .y_labels(yn)
        .x_desc(chart.x_label.as_str())
        .y_desc(chart.y_label.as_str())
        .axis_desc_style((FONT, DESC_SIZE))
        .label_style((FONT, TICK_SIZE))
        .x_label_formatter(&xf)
        .y_label_formatter(&yf)
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(backend_err)?;

    // Bands first so that lines and dots stay visible on top of them.
    let mut order: Vec<usize> = (0..chart.series.len()).collect();
    order.sort_by_key(|&i| !matches!(chart.series[i].style, SeriesStyle::Band { .. }));

    for i in order {
        let s = &chart.series[i];
        let colour = series_colour(i);
        let line_style = colour.stroke_width(2);
        let finite_xy = |k: usize| s.x[k].is_finite() && s.y[k].is_finite();

        // An empty series carrying the legend entry, so that the legend is
        // right even when no segment of this series can be drawn.
        let anno = cc
            .draw_series(LineSeries::new(
                std::iter::empty::<(f64, f64)>(),
                line_style,
            ))
            .map_err(backend_err)?;
        anno.label(s.label.as_str());
        match s.style {
            SeriesStyle::Line => anno.legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            }),
            SeriesStyle::Dots => {
                anno.legend(move |(x, y)| Circle::new((x + 10, y), 3, colour.filled()))
            }
            SeriesStyle::Band { .. } => anno.legend(move |(x, y)| {
                Rectangle::new([(x, y - 5), (x + 20, y + 5)], colour.mix(0.3).filled())
            }),
        };

        match s.style {
            SeriesStyle::Line => {
                for r in runs(s.x.len(), finite_xy) {
                    cc.draw_series(LineSeries::new(r.map(|k| (s.x[k], s.y[k])), line_style))
                        .map_err(backend_err)?;
                }
            }
            SeriesStyle::Dots => {
                let pts = (0..s.x.len())
                    .filter(|&k| finite_xy(k))
                    .map(|k| Circle::new((s.x[k], s.y[k]), 3, colour.filled()));
                cc.draw_series(pts).map_err(backend_err)?;
            }
            SeriesStyle::Band { lower, upper } => {
                let ok =
                    |k: usize| s.x[k].is_finite() && lower[k].is_finite() && upper[k].is_finite();
                for r in runs(s.x.len(), ok) {
                    let mut poly: Vec<(f64, f64)> = r.clone().map(|k| (s.x[k], upper[k])).collect();
                    poly.extend(r.rev().map(|k| (s.x[k], lower[k])));
                    cc.draw_series(std::iter::once(Polygon::new(
                        poly,
                        colour.mix(0.25).filled(),
                    )))
                    .map_err(backend_err)?;
                }
                if !s.y.is_empty() {
                    for r in runs(s.x.len(), finite_xy) {
                        cc.draw_series(LineSeries::new(r.map(|k| (s.x[k], s.y[k])), line_style))
                            .map_err(backend_err)?;
                    }
                }
            }
        }
    }

    if chart.series.len() > 1 {
        cc.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .label_font((FONT, TICK_SIZE))
            .draw()
            .map_err(backend_err)?;
    }
    Ok(())
}

/// Renders a chart to an in-memory SVG string of size `chart.size`.
///
/// Axis ranges come from the finite data (non-finite values are ignored),
/// padded by 5% on each side; constant data gets a widened range. A legend
/// is drawn when there is more than one series, and every series gets a
/// distinct colour.
///
/// # Errors
/// [`PlotError::EmptyData`] if there is no series, a series is empty or no
/// point is finite; [`PlotError::LengthMismatch`] if a series' slices differ
/// in length; [`PlotError::InvalidInput`] if the size is out of range.
///
/// ```
/// use structid_plot::{Chart, Series, render_chart_svg};
///
/// let x = [0.0, 1.0, 2.0, 3.0];
/// let y = [0.0, 1.0, 4.0, 9.0];
/// let svg = render_chart_svg(
///     &Chart::new("squares", "x", "x^2").with(Series::dots("data", &x, &y)),
/// )
/// .unwrap();
/// assert!(svg.starts_with("<svg"));
/// ```
pub fn render_chart_svg(chart: &Chart<'_>) -> Result<String, PlotError> {
    check_size(chart.size, "chart")?;
    // Validate before allocating the backend.
    chart.ranges()?;
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, chart.size).into_drawing_area();
        draw_chart(&root, chart)?;
        root.present().map_err(backend_err)?;
    }
    Ok(buf)
}

/// Renders a chart (see [`render_chart_svg`]) and writes it to `path`.
///
/// The file is written directly (not atomically); callers that need atomic
/// writes should use [`render_chart_svg`] and write the string themselves.
///
/// # Errors
/// Those of [`render_chart_svg`], plus [`PlotError::Io`] if writing fails.
///
/// ```
/// use structid_plot::{Chart, Series, write_chart_svg};
///
/// let x = [0.0, 1.0, 2.0, 3.0];
/// let mean = [0.0, 1.0, 0.5, 2.0];
/// let lo = [-0.5, 0.4, 0.0, 1.2];
/// let hi = [0.5, 1.6, 1.0, 2.8];
/// let chart = Chart::new("estimate", "t", "y")
///     .with(Series::band("95% band", &x, &mean, &lo, &hi))
///     .with(Series::dots("measured", &x, &[0.1, 0.9, 0.7, 1.8]))
///     .size((640, 400));
/// let path = std::env::temp_dir().join("structid_plot_write_doc.svg");
/// write_chart_svg(&path, &chart).unwrap();
/// # std::fs::remove_file(&path).ok();
/// ```
pub fn write_chart_svg(path: &Path, chart: &Chart<'_>) -> Result<(), PlotError> {
    let svg = render_chart_svg(chart)?;
    std::fs::write(path, svg)?;
    Ok(())
}

/// Validates the panel layout and returns `(cols, rows, total_size)`.
fn grid_layout(
    n: usize,
    cols: usize,
    panel_size: (u32, u32),
) -> Result<(usize, usize, (u32, u32)), PlotError> {
    check_size(panel_size, "panel")?;
    let cols = cols.clamp(1, n.max(1));
    let rows = n.div_ceil(cols);
    let too_big = || {
        PlotError::InvalidInput(format!(
            "figure of {rows}x{cols} panels of {}x{} pixels is too large",
            panel_size.0, panel_size.1
        ))
    };
    let w = u32::try_from(cols)
        .ok()
        .and_then(|c| c.checked_mul(panel_size.0))
        .ok_or_else(too_big)?;
    let h = u32::try_from(rows)
        .ok()
        .and_then(|r| r.checked_mul(panel_size.1))
        .ok_or_else(too_big)?;
    if w > MAX_FIGURE_SIZE || h > MAX_FIGURE_SIZE {
        return Err(too_big());
    }
    Ok((cols, rows, (w, h)))
}

/// Tiles `items` in one SVG figure, row by row with `cols` panels per row: each item is
/// checked before anything is drawn, then drawn into its panel.
fn render_tiled<T>(
    items: &[T],
    cols: usize,
    panel_size: (u32, u32),
    empty: &str,
    check: impl Fn(&T) -> Result<(), PlotError>,
    draw: impl Fn(&DrawingArea<SVGBackend<'_>, Shift>, &T) -> Result<(), PlotError>,
) -> Result<String, PlotError> {
    if items.is_empty() {
        return Err(PlotError::EmptyData(empty.into()));
    }
    let (cols, rows, size) = grid_layout(items.len(), cols, panel_size)?;
    for item in items {
        check(item)?;
    }
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, size).into_drawing_area();
        root.fill(&WHITE).map_err(backend_err)?;
        let panels = root.split_evenly((rows, cols));
        for (panel, item) in panels.iter().zip(items) {
            draw(panel, item)?;
        }
        root.present().map_err(backend_err)?;
    }
    Ok(buf)
}

/// Renders several charts tiled in one SVG figure, row by row with `cols`
/// panels per row (clamped to `1..=charts.len()`), each panel of
/// `panel_size` pixels. The charts' own `size` fields are ignored.
///
/// # Errors
/// [`PlotError::EmptyData`] if `charts` is empty, otherwise as
/// [`render_chart_svg`] for any chart; [`PlotError::InvalidInput`] if the
/// panel or figure size is out of range.
///
/// ```
/// use structid_plot::{Chart, Series, render_grid_svg};
///
/// let x = [0.0, 1.0, 2.0];
/// let f = [0.0, 1.0, 4.0];
/// let g = [1.0, 0.5, 0.25];
/// let charts = [
///     Chart::new("f", "u", "f(u)").with(Series::line("f", &x, &f)),
///     Chart::new("g", "v", "g(v)").with(Series::line("g", &x, &g)),
/// ];
/// let svg = render_grid_svg(&charts, 2, (400, 300)).unwrap();
/// let path = std::env::temp_dir().join("structid_plot_grid_doc.svg");
/// std::fs::write(&path, svg).unwrap();
/// # std::fs::remove_file(&path).ok();
/// ```
pub fn render_grid_svg(
    charts: &[Chart<'_>],
    cols: usize,
    panel_size: (u32, u32),
) -> Result<String, PlotError> {
    render_tiled(
        charts,
        cols,
        panel_size,
        "grid has no charts",
        |c: &Chart<'_>| c.ranges().map(|_| ()),
        draw_chart,
    )
}

/// Heat map of a scalar field on a rectilinear grid.
///
/// `values[i + j * xs.len()]` is the value at `(xs[i], ys[j])`. Each value
/// fills the cell around its grid point (cell edges halfway between
/// neighbouring grid points). Coordinates should be monotonic.
#[derive(Debug, Clone, PartialEq)]
pub struct HeatMap<'a> {
    /// Title drawn above the panel.
    pub title: String,
    /// Label of the horizontal axis.
    pub x_label: String,
    /// Label of the vertical axis.
    pub y_label: String,
    /// Grid abscissae (finite).
    pub xs: &'a [f64],
    /// Grid ordinates (finite).
    pub ys: &'a [f64],
    /// Field values, `xs.len() * ys.len()` of them, `x` varying fastest.
    /// Non-finite values are drawn in light grey.
    pub values: &'a [f64],
    /// Colour scale `(min, max)`; `None` uses the finite data range. Give
    /// several maps the same range for a side-by-side comparison. Values
    /// outside the range get the end colours.
    pub value_range: Option<(f64, f64)>,
}

impl<'a> HeatMap<'a> {
    /// A heat map with an automatic colour scale.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        xs: &'a [f64],
        ys: &'a [f64],
        values: &'a [f64],
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            xs,
            ys,
            values,
            value_range: None,
        }
    }

    /// Sets a fixed colour scale `(min, max)` (builder style).
    pub fn with_range(mut self, min: f64, max: f64) -> Self {
        self.value_range = Some((min, max));
        self
    }

    /// Validates the map; returns the colour scale `(lo, hi)` with `lo < hi`.
    fn validate(&self) -> Result<(f64, f64), PlotError> {
        if self.xs.is_empty() || self.ys.is_empty() {
            return Err(PlotError::EmptyData(format!(
                "heat map '{}' has an empty grid ({}x{})",
                self.title,
                self.xs.len(),
                self.ys.len()
            )));
        }
        let n = self.xs.len().checked_mul(self.ys.len()).ok_or_else(|| {
            PlotError::InvalidInput(format!("heat map '{}' grid is too large", self.title))
        })?;
        if self.values.len() != n {
            return Err(PlotError::LengthMismatch {
                what: format!("heat map '{}': xs.len()*ys.len() vs values", self.title),
                x: n,
                y: self.values.len(),
            });
        }
        if self.xs.iter().chain(self.ys).any(|v| !v.is_finite()) {
            return Err(PlotError::InvalidInput(format!(
                "heat map '{}' has non-finite grid coordinates",
                self.title
            )));
        }
        let (lo, hi) = match self.value_range {
            Some((a, b)) => {
                if !a.is_finite() || !b.is_finite() {
                    return Err(PlotError::InvalidInput(format!(
                        "heat map '{}' value range ({a}, {b}) is not finite",
                        self.title
                    )));
                }
                (a.min(b), a.max(b))
            }
            None => {
                let mut b = Bounds::default();
                self.values.iter().for_each(|&v| b.add(v));
                if !b.any {
                    return Err(PlotError::EmptyData(format!(
                        "heat map '{}' has no finite value",
                        self.title
                    )));
                }
                (b.lo, b.hi)
            }
        };
        Ok(widen(lo, hi))
    }
}

/// Cell edges around grid points (`n + 1` edges for `n` points).
fn cell_edges(c: &[f64]) -> Vec<f64> {
    let n = c.len();
    if n == 1 {
        let half = if c[0] != 0.0 { c[0].abs() * 0.05 } else { 0.5 };
        return vec![c[0] - half, c[0] + half];
    }
    let mut e = Vec::with_capacity(n + 1);
    e.push(c[0] - (c[1] / 2.0 - c[0] / 2.0));
    for k in 0..n - 1 {
        e.push(c[k] / 2.0 + c[k + 1] / 2.0);
    }
    e.push(c[n - 1] + (c[n - 1] / 2.0 - c[n - 2] / 2.0));
    e.iter_mut().for_each(|v| *v = clamp_finite(*v));
    e
}

fn edge_range(e: &[f64]) -> Range<f64> {
    let lo = e.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = e.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = widen(lo, hi);
    lo..hi
}

/// Viridis anchor colours at 0, 0.1, ..., 1.
const VIRIDIS: [(u8, u8, u8); 11] = [
    (0x44, 0x01, 0x54),
    (0x48, 0x24, 0x75),
    (0x41, 0x44, 0x87),
    (0x35, 0x5f, 0x8d),
    (0x2a, 0x78, 0x8e),
    (0x21, 0x91, 0x8c),
    (0x22, 0xa8, 0x84),
    (0x44, 0xbf, 0x70),
    (0x7a, 0xd1, 0x51),
    (0xbd, 0xdf, 0x26),
    (0xfd, 0xe7, 0x25),
];

/// Colour for missing (non-finite) values.
const MISSING: RGBColor = RGBColor(200, 200, 200);

/// Viridis-like colour for `t` in `[0, 1]` (clamped).
fn viridis(t: f64) -> RGBColor {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let pos = t * (VIRIDIS.len() - 1) as f64;
    let k = (pos.floor() as usize).min(VIRIDIS.len() - 2);
    let f = pos - k as f64;
    let (a, b) = (VIRIDIS[k], VIRIDIS[k + 1]);
    let mix = |p: u8, q: u8| {
        (p as f64 + (q as f64 - p as f64) * f)
            .round()
            .clamp(0.0, 255.0) as u8
    };
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// Width of the colour-bar strip (bar and labels) for a panel `w` pixels wide.
fn colour_bar_width(w: u32) -> u32 {
    (w / 5).clamp(80, 100)
}
const COLOUR_BAR_STEPS: usize = 64;
const COLOUR_BAR_THICKNESS: u32 = 22;

fn draw_heatmap(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    map: &HeatMap<'_>,
) -> Result<(), PlotError> {
    let (vlo, vhi) = map.validate()?;
    area.fill(&WHITE).map_err(backend_err)?;
    let body = area
        .titled(&map.title, (FONT, TITLE_SIZE))
        .map_err(backend_err)?;
    let (w, _) = body.dim_in_pixel();
    let bar_w = colour_bar_width(w);
    let (plot_area, bar_area) = body.split_horizontally(w.saturating_sub(bar_w));

    let ex = cell_edges(map.xs);
    let ey = cell_edges(map.ys);
    let (xr, yr) = (edge_range(&ex), edge_range(&ey));
    let mut cc = ChartBuilder::on(&plot_area)
        .margin(MARGIN)
        .margin_right(4)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(xr.clone(), yr.clone())
        .map_err(backend_err)?;
    let xf = tick_formatter(xr.start, xr.end);
    let yf = tick_formatter(yr.start, yr.end);
    let (xn, yn) = label_counts(&plot_area);
    cc.configure_mesh()
        .disable_mesh()
        .x_labels(xn)
        .y_labels(yn)
        .x_desc(map.x_label.as_str())
        .y_desc(map.y_label.as_str())
        .axis_desc_style((FONT, DESC_SIZE))
        .label_style((FONT, TICK_SIZE))
        .x_label_formatter(&xf)
        .y_label_formatter(&yf)
        .draw()
        .map_err(backend_err)?;

    let nx = map.xs.len();
    let span = vhi - vlo;
    let cells = (0..map.values.len()).map(|idx| {
        let (i, j) = (idx % nx, idx / nx);
        let v = map.values[idx];
        let colour = if v.is_finite() {
            viridis((v - vlo) / span)
        } else {
            MISSING
        };
        Rectangle::new([(ex[i], ey[j]), (ex[i + 1], ey[j + 1])], colour.filled())
    });
    cc.draw_series(cells).map_err(backend_err)?;

    // Colour bar, vertically aligned with the plot area; tick labels at the
    // minimum, the maximum and three evenly spaced values in between.
    let mut bar = ChartBuilder::on(&bar_area)
        .margin_top(MARGIN)
        .margin_bottom(MARGIN)
        .margin_left(8)
        .margin_right(bar_w.saturating_sub(8 + COLOUR_BAR_THICKNESS))
        .x_label_area_size(X_LABEL_AREA)
        .build_cartesian_2d(0.0f64..1.0f64, vlo..vhi)
        .map_err(backend_err)?;
    let steps = (0..COLOUR_BAR_STEPS).map(|k| {
        let (a, b) = (
            k as f64 / COLOUR_BAR_STEPS as f64,
            (k + 1) as f64 / COLOUR_BAR_STEPS as f64,
        );
        Rectangle::new(
            [(0.0, vlo + span * a), (1.0, vlo + span * b)],
            viridis((a + b) / 2.0).filled(),
        )
    });
    bar.draw_series(steps).map_err(backend_err)?;
    bar.draw_series(std::iter::once(Rectangle::new(
        [(0.0, vlo), (1.0, vhi)],
        BLACK.stroke_width(1),
    )))
    .map_err(backend_err)?;
    let label_style = TextStyle::from((FONT, TICK_SIZE).into_font())
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    let ticks = (0..=4).map(|k| {
        let v = if k == 4 {
            vhi
        } else {
            vlo + span * k as f64 / 4.0
        };
        EmptyElement::at((1.0, v))
            + PathElement::new(vec![(0, 0), (5, 0)], BLACK)
            + Text::new(format_value(v), (8, 0), label_style.clone())
    });
    bar.draw_series(ticks).map_err(backend_err)?;
    Ok(())
}

/// Renders heat maps tiled in one SVG figure, row by row with `cols` panels
/// per row (clamped to `1..=maps.len()`), each panel of `panel_size` pixels.
///
/// Each panel has the map's title, labelled axes and a viridis-like colour
/// bar whose end labels are the minimum and maximum of the colour scale.
///
/// # Errors
/// [`PlotError::EmptyData`] if `maps` is empty, a grid is empty or a map
/// without `value_range` has no finite value; [`PlotError::LengthMismatch`]
/// if `values.len() != xs.len() * ys.len()`; [`PlotError::InvalidInput`] for
/// non-finite coordinates or value range, or an out-of-range size.
///
/// ```
/// use structid_plot::{HeatMap, render_heatmaps_svg};
///
/// let xs: Vec<f64> = (0..20).map(|i| i as f64 / 19.0).collect();
/// let ys = xs.clone();
/// let values: Vec<f64> = ys
///     .iter()
///     .flat_map(|y| xs.iter().map(move |x| x * y))
///     .collect();
/// let map = HeatMap::new("x*y", "x", "y", &xs, &ys, &values).with_range(0.0, 1.0);
/// let svg = render_heatmaps_svg(&[map], 1, (500, 400)).unwrap();
/// let path = std::env::temp_dir().join("structid_plot_heatmap_doc.svg");
/// std::fs::write(&path, svg).unwrap();
/// # std::fs::remove_file(&path).ok();
/// ```
pub fn render_heatmaps_svg(
    maps: &[HeatMap<'_>],
    cols: usize,
    panel_size: (u32, u32),
) -> Result<String, PlotError> {
    render_tiled(
        maps,
        cols,
        panel_size,
        "no heat maps",
        |m: &HeatMap<'_>| m.validate().map(|_| ()),
        draw_heatmap,
    )
}

/// A correlation function drawn as bars over its lags, with a symmetric
/// confidence band `±bound` (a residual test).
///
/// Bars whose value lies outside the band are marked with a circle; with
/// `exempt_zero` the bar at lag 0 is never marked (the lag 0 of an
/// autocorrelation is 1 by definition).
#[derive(Debug, Clone, PartialEq)]
pub struct CorrelationChart<'a> {
    /// Title drawn above the panel.
    pub title: String,
    /// Label of the horizontal axis.
    pub x_label: String,
    /// Label of the vertical axis.
    pub y_label: String,
    /// The lags (finite, e.g. integers as `f64`).
    pub lags: &'a [f64],
    /// The correlation at each lag, same length as `lags`; non-finite
    /// values are skipped.
    pub values: &'a [f64],
    /// Half-width of the band (finite, non-negative).
    pub bound: f64,
    /// Never mark lag 0 as outside the band.
    pub exempt_zero: bool,
}

impl<'a> CorrelationChart<'a> {
    /// A correlation chart; lag 0 is marked like any other lag (see
    /// [`CorrelationChart::exempt_zero`]).
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        lags: &'a [f64],
        values: &'a [f64],
        bound: f64,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            lags,
            values,
            bound,
            exempt_zero: false,
        }
    }

    /// Never marks lag 0 (builder style), for autocorrelations.
    pub fn exempt_zero(mut self) -> Self {
        self.exempt_zero = true;
        self
    }

    /// Whether the value at index `k` is drawn as outside the band.
    fn is_outside(&self, k: usize) -> bool {
        let v = self.values[k];
        v.is_finite() && v.abs() > self.bound && !(self.exempt_zero && self.lags[k] == 0.0)
    }

    /// Validates the chart; returns the axis ranges and the bar width.
    fn layout(&self) -> Result<(Range<f64>, Range<f64>, f64), PlotError> {
        if self.lags.is_empty() {
            return Err(PlotError::EmptyData(format!(
                "correlation chart '{}' has no lags",
                self.title
            )));
        }
        if self.values.len() != self.lags.len() {
            return Err(PlotError::LengthMismatch {
                what: format!("correlation chart '{}': lags vs values", self.title),
                x: self.lags.len(),
                y: self.values.len(),
            });
        }
        if self.lags.iter().any(|l| !l.is_finite()) {
            return Err(PlotError::InvalidInput(format!(
                "correlation chart '{}' has non-finite lags",
                self.title
            )));
        }
        if !(self.bound.is_finite() && self.bound >= 0.0) {
            return Err(PlotError::InvalidInput(format!(
                "correlation chart '{}' has the band half-width {}; it must be finite and non-negative",
                self.title, self.bound
            )));
        }
        let mut sorted = self.lags.to_vec();
        sorted.sort_by(f64::total_cmp);
        // Bars take 60 % of the closest spacing of the lags, so they never overlap.
        let spacing = sorted
            .windows(2)
            .map(|w| w[1] - w[0])
            .filter(|d| *d > 0.0)
            .fold(f64::INFINITY, f64::min);
        let spacing = if spacing.is_finite() { spacing } else { 1.0 };
        let (lo, hi) = widen(sorted[0] - spacing, sorted[sorted.len() - 1] + spacing);
        let mut yb = Bounds::default();
        for v in self.values.iter().chain([&0.0, &self.bound, &-self.bound]) {
            yb.add(*v);
        }
        // 0 is always added, so the bounds are never empty.
        let yr = yb.padded().unwrap_or(-1.0..1.0);
        Ok((lo..hi, yr, 0.6 * spacing))
    }
}

/// Colour of the band and of the marks outside it.
const BAND_COLOUR: RGBColor = RGBColor(214, 39, 40);

fn draw_correlation(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    chart: &CorrelationChart<'_>,
) -> Result<(), PlotError> {
    let (xr, yr, width) = chart.layout()?;
    area.fill(&WHITE).map_err(backend_err)?;
    let mut cc = ChartBuilder::on(area)
        .caption(&chart.title, (FONT, TITLE_SIZE))
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(xr.clone(), yr.clone())
        .map_err(backend_err)?;
    let xf = tick_formatter(xr.start, xr.end);
    let yf = tick_formatter(yr.start, yr.end);
    let (xn, yn) = label_counts(area);
    cc.configure_mesh()
        .x_labels(xn)
        .y_labels(yn)
        .x_desc(chart.x_label.as_str())
        .y_desc(chart.y_label.as_str())
        .axis_desc_style((FONT, DESC_SIZE))
        .label_style((FONT, TICK_SIZE))
        .x_label_formatter(&xf)
        .y_label_formatter(&yf)
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(backend_err)?;

    let bar_colour = series_colour(0);
    let b = chart.bound;
    cc.draw_series(std::iter::once(Rectangle::new(
        [(xr.start, -b), (xr.end, b)],
        BAND_COLOUR.mix(0.08).filled(),
    )))
    .map_err(backend_err)?;
    cc.draw_series(
        chart
            .lags
            .iter()
            .zip(chart.values)
            .filter(|(_, v)| v.is_finite())
            .map(|(&l, &v)| {
                Rectangle::new(
                    [(l - width / 2.0, 0.0), (l + width / 2.0, v)],
                    bar_colour.filled(),
                )
            }),
    )
    .map_err(backend_err)?
    .label("correlation")
    .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], bar_colour.filled()));
    let band_style = BAND_COLOUR.stroke_width(2);
    for (i, level) in [b, -b].into_iter().enumerate() {
        let s = cc
            .draw_series(LineSeries::new(
                [(xr.start, level), (xr.end, level)],
                band_style,
            ))
            .map_err(backend_err)?;
        if i == 0 {
            s.label(format!("band ±{}", format_value(b)))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], band_style));
        }
    }
    let outside: Vec<usize> = (0..chart.lags.len())
        .filter(|&k| chart.is_outside(k))
        .collect();
    if !outside.is_empty() {
        cc.draw_series(outside.iter().map(|&k| {
            Circle::new(
                (chart.lags[k], chart.values[k]),
                5,
                BAND_COLOUR.stroke_width(2),
            )
        }))
        .map_err(backend_err)?
        .label(format!("outside the band ({})", outside.len()))
        .legend(move |(x, y)| Circle::new((x + 10, y), 5, BAND_COLOUR.stroke_width(2)));
    }
    cc.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .label_font((FONT, TICK_SIZE))
        .draw()
        .map_err(backend_err)?;
    Ok(())
}

/// Renders correlation charts (residual tests) tiled in one SVG figure, row
/// by row with `cols` panels per row (clamped to `1..=charts.len()`), each
/// panel of `panel_size` pixels: bars over the lags, the band `±bound` as a
/// shaded strip between two lines, and a circle on every bar outside it.
///
/// # Errors
/// [`PlotError::EmptyData`] if `charts` is empty or a chart has no lags;
/// [`PlotError::LengthMismatch`] if `lags` and `values` differ in length;
/// [`PlotError::InvalidInput`] for non-finite lags, a negative or
/// non-finite bound, or an out-of-range size.
///
/// ```
/// use structid_plot::{CorrelationChart, render_correlation_svg};
///
/// let lags: Vec<f64> = (0..=10).map(f64::from).collect();
/// let values: Vec<f64> = lags.iter().map(|l| 0.7f64.powf(*l)).collect();
/// let chart = CorrelationChart::new("autocorrelation", "lag", "R(τ)", &lags, &values, 0.1)
///     .exempt_zero();
/// let svg = render_correlation_svg(&[chart], 1, (500, 350)).unwrap();
/// assert!(svg.contains("outside the band (6)"));
/// ```
pub fn render_correlation_svg(
    charts: &[CorrelationChart<'_>],
    cols: usize,
    panel_size: (u32, u32),
) -> Result<String, PlotError> {
    render_tiled(
        charts,
        cols,
        panel_size,
        "no correlation charts",
        |c: &CorrelationChart<'_>| c.layout().map(|_| ()),
        draw_correlation,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(h: &str, n: &str) -> usize {
        h.matches(n).count()
    }

    /// Whether the SVG has a `<text>` element with exactly this content.
    fn has_text(svg: &str, t: &str) -> bool {
        svg.lines().any(|l| l == t)
    }

    #[test]
    fn line_dots_band_chart() {
        let x: Vec<f64> = (0..40).map(|i| i as f64 * 0.25).collect();
        let y: Vec<f64> = x.iter().map(|v| v.sin()).collect();
        let lo: Vec<f64> = y.iter().map(|v| v - 0.3).collect();
        let hi: Vec<f64> = y.iter().map(|v| v + 0.3).collect();
        let noisy: Vec<f64> = y
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.1 * ((i * 7 % 5) as f64 - 2.0))
            .collect();
        let chart = Chart::new("Estimated map f", "u", "f(u)")
            .with(Series::band("confidence band", &x, &[], &lo, &hi))
            .with(Series::line("estimate", &x, &y))
            .with(Series::dots("measurements", &x, &noisy));
        let svg = render_chart_svg(&chart).unwrap();
        assert!(svg.starts_with("<svg"));
        assert!(has_text(&svg, "Estimated map f"));
        for l in ["confidence band", "estimate", "measurements", "u", "f(u)"] {
            assert!(has_text(&svg, l), "missing {l}");
        }
        assert!(count(&svg, "<circle") >= x.len());
        assert!(svg.contains("<polygon"));
    }

    #[test]
    fn single_series_has_no_legend_and_escapes_text() {
        let x = [1.0, 2.0];
        let chart = Chart::new("a < b & c", "x", "y").with(Series::line("only-label", &x, &x));
        let svg = render_chart_svg(&chart).unwrap();
        assert!(svg.contains("a &lt; b &amp; c"));
        assert!(!svg.contains("only-label"));
    }

    #[test]
    fn mismatched_lengths() {
        let x = [1.0, 2.0, 3.0];
        let y = [1.0, 2.0];
        let c = Chart::new("t", "x", "y").with(Series::line("s", &x, &y));
        assert!(matches!(
            render_chart_svg(&c),
            Err(PlotError::LengthMismatch { x: 3, y: 2, .. })
        ));
        let c = Chart::new("t", "x", "y").with(Series::band("b", &x, &[], &x, &y));
        assert!(matches!(
            render_chart_svg(&c),
            Err(PlotError::LengthMismatch { x: 3, y: 2, .. })
        ));
        let c = Chart::new("t", "x", "y").with(Series::band("b", &x, &y, &x, &x));
        assert!(matches!(
            render_chart_svg(&c),
            Err(PlotError::LengthMismatch { .. })
        ));
    }

    #[test]
    fn empty_inputs() {
        let c = Chart::new("t", "x", "y");
        assert!(matches!(render_chart_svg(&c), Err(PlotError::EmptyData(_))));
        let c = Chart::new("t", "x", "y").with(Series::line("s", &[], &[]));
        assert!(matches!(render_chart_svg(&c), Err(PlotError::EmptyData(_))));
        let nan = [f64::NAN, f64::INFINITY];
        let c = Chart::new("t", "x", "y").with(Series::dots("s", &nan, &nan));
        assert!(matches!(render_chart_svg(&c), Err(PlotError::EmptyData(_))));
        assert!(matches!(
            render_grid_svg(&[], 2, (300, 200)),
            Err(PlotError::EmptyData(_))
        ));
        assert!(matches!(
            render_heatmaps_svg(&[], 2, (300, 200)),
            Err(PlotError::EmptyData(_))
        ));
    }

    #[test]
    fn nan_values_are_skipped() {
        let x = [0.0, 1.0, f64::NAN, 3.0, 4.0, 5.0];
        let y = [1.0, f64::NAN, 2.0, 3.0, f64::INFINITY, 2.0];
        let lo = [0.0, 0.0, 0.0, f64::NAN, 0.0, 0.0];
        let chart = Chart::new("nan", "x", "y")
            .with(Series::line("l", &x, &y))
            .with(Series::dots("d", &x, &y))
            .with(Series::band("b", &x, &y, &lo, &y));
        let svg = render_chart_svg(&chart).unwrap();
        assert!(svg.starts_with("<svg"));
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
        // Only the finite points (0,1), (3,3), (5,2) are drawn as dots.
        assert_eq!(count(&svg, "<circle"), 3 + 1);
    }

    #[test]
    fn all_nan_series_next_to_finite_one_keeps_legend() {
        let x = [0.0, 1.0];
        let nan = [f64::NAN, f64::NAN];
        let chart = Chart::new("t", "x", "y")
            .with(Series::line("finite", &x, &x))
            .with(Series::line("all-nan", &x, &nan));
        let svg = render_chart_svg(&chart).unwrap();
        assert!(svg.contains("all-nan") && svg.contains("finite"));
    }

    #[test]
    fn constant_and_extreme_data() {
        for v in [
            0.0,
            1.0,
            -3e-12,
            1e-250,
            1e-310,
            7.5e200,
            f64::MAX,
            -f64::MAX,
        ] {
            let x = [v, v, v];
            let y = [v, v, v];
            let c = Chart::new("const", "x", "y").with(Series::line("s", &x, &y));
            let svg = render_chart_svg(&c).unwrap();
            assert!(svg.starts_with("<svg"), "value {v}");
        }
        for (a, b) in [
            (-f64::MAX, f64::MAX),
            (1e-300, 2e-300),
            (1.0, 1.0 + 1e-15),
            (1e-310, 3e-310),
            (-1e305, 1e-305),
        ] {
            let x = [a, b];
            let c = Chart::new("extreme", "x", "y").with(Series::dots("s", &x, &x));
            assert!(render_chart_svg(&c).unwrap().starts_with("<svg"), "{a} {b}");
            let v = [a, b, b, a];
            let m = HeatMap::new("extreme", "x", "y", &x, &x, &v);
            let svg = render_heatmaps_svg(&[m], 1, (300, 300)).unwrap();
            assert!(count(&svg, "<rect") >= 4);
        }
    }

    #[test]
    fn bad_sizes() {
        let x = [0.0, 1.0];
        let c = Chart::new("t", "x", "y")
            .with(Series::line("s", &x, &x))
            .size((0, 0));
        assert!(matches!(
            render_chart_svg(&c),
            Err(PlotError::InvalidInput(_))
        ));
        let c = c.size((MIN_PANEL_SIZE, MIN_PANEL_SIZE));
        render_chart_svg(&c).unwrap();
        assert!(matches!(
            render_grid_svg(std::slice::from_ref(&c), 1, (10, 10)),
            Err(PlotError::InvalidInput(_))
        ));
        assert!(matches!(
            render_grid_svg(&[c.clone(), c.clone()], 2, (60_000, 300)),
            Err(PlotError::InvalidInput(_))
        ));
        // cols = 0 is clamped to 1.
        render_grid_svg(&[c.clone(), c], 0, (250, 200)).unwrap();
    }

    #[test]
    fn grid_of_three() {
        let x = [0.0, 1.0, 2.0];
        let charts: Vec<Chart> = ["beta = 0.1", "beta = 1", "beta = 10"]
            .iter()
            .map(|t| Chart::new(*t, "x", "y").with(Series::line("s", &x, &x)))
            .collect();
        for cols in [1, 2, 3, 7] {
            let svg = render_grid_svg(&charts, cols, (400, 300)).unwrap();
            assert!(svg.starts_with("<svg"));
            for t in ["beta = 0.1", "beta = 1", "beta = 10"] {
                assert!(has_text(&svg, t), "missing {t}");
            }
        }
        let svg = render_grid_svg(&charts, 2, (400, 300)).unwrap();
        assert!(svg.contains(r#"width="800" height="600""#));
    }

    fn field(nx: usize, ny: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let xs: Vec<f64> = (0..nx).map(|i| i as f64 / 4.0 - 2.0).collect();
        let ys: Vec<f64> = (0..ny).map(|j| j as f64 * 0.3).collect();
        let mut v = Vec::with_capacity(nx * ny);
        for y in &ys {
            for x in &xs {
                v.push((x * x + y).sin());
            }
        }
        (xs, ys, v)
    }

    #[test]
    fn heatmap_renders_cells() {
        let (nx, ny) = (17, 11);
        let (xs, ys, v) = field(nx, ny);
        let map = HeatMap::new("Dispersion field", "u", "v", &xs, &ys, &v);
        let svg = render_heatmaps_svg(&[map], 1, (600, 450)).unwrap();
        assert!(svg.starts_with("<svg"));
        assert!(has_text(&svg, "Dispersion field"));
        assert!(count(&svg, "<rect") >= nx * ny);
        assert!(has_text(&svg, "u") && has_text(&svg, "v"));
    }

    #[test]
    fn heatmaps_side_by_side_with_shared_range_and_nan() {
        let (xs, ys, mut v) = field(6, 5);
        v[3] = f64::NAN;
        let a = HeatMap::new("left", "x", "y", &xs, &ys, &v).with_range(-1.0, 1.0);
        let b = HeatMap {
            title: "right".into(),
            ..a.clone()
        };
        let svg = render_heatmaps_svg(&[a, b], 2, (400, 320)).unwrap();
        assert!(has_text(&svg, "left") && has_text(&svg, "right"));
        assert!(count(&svg, "<rect") >= 2 * 30);
        // Colour-bar extremes.
        assert!(has_text(&svg, "-1") && has_text(&svg, "1"));
    }

    #[test]
    fn heatmap_bad_inputs() {
        let xs = [0.0, 1.0];
        let ys = [0.0, 1.0, 2.0];
        let v = [0.0; 5];
        let m = HeatMap::new("m", "x", "y", &xs, &ys, &v);
        assert!(matches!(
            render_heatmaps_svg(&[m], 1, (300, 300)),
            Err(PlotError::LengthMismatch { x: 6, y: 5, .. })
        ));
        let m = HeatMap::new("m", "x", "y", &[], &ys, &[]);
        assert!(matches!(
            render_heatmaps_svg(&[m], 1, (300, 300)),
            Err(PlotError::EmptyData(_))
        ));
        let nan = [f64::NAN; 6];
        let m = HeatMap::new("m", "x", "y", &xs, &ys, &nan);
        assert!(matches!(
            render_heatmaps_svg(std::slice::from_ref(&m), 1, (300, 300)),
            Err(PlotError::EmptyData(_))
        ));
        // With an explicit range an all-missing map still renders.
        render_heatmaps_svg(&[m.with_range(0.0, 1.0)], 1, (300, 300)).unwrap();
        let bad = [0.0, f64::NAN];
        let m = HeatMap::new("m", "x", "y", &bad, &ys, &[0.0; 6]);
        assert!(matches!(
            render_heatmaps_svg(&[m], 1, (300, 300)),
            Err(PlotError::InvalidInput(_))
        ));
        let m = HeatMap::new("m", "x", "y", &xs, &ys, &[0.0; 6]).with_range(0.0, f64::NAN);
        assert!(matches!(
            render_heatmaps_svg(&[m], 1, (300, 300)),
            Err(PlotError::InvalidInput(_))
        ));
    }

    #[test]
    fn heatmap_degenerate_grids() {
        // Single point, constant values, decreasing coordinates, reversed range.
        let one = [2.0];
        let m = HeatMap::new("one", "x", "y", &one, &one, &[5.0]);
        render_heatmaps_svg(&[m], 1, (300, 300)).unwrap();
        let xs = [3.0, 2.0, 1.0];
        let ys = [0.0, 0.0];
        let v = [1.0; 6];
        let m = HeatMap::new("deg", "x", "y", &xs, &ys, &v).with_range(2.0, -2.0);
        let svg = render_heatmaps_svg(&[m], 1, (300, 300)).unwrap();
        assert!(count(&svg, "<rect") >= 6);
    }

    #[test]
    fn viridis_endpoints() {
        assert_eq!(viridis(0.0), RGBColor(0x44, 0x01, 0x54));
        assert_eq!(viridis(1.0), RGBColor(0xfd, 0xe7, 0x25));
        assert_eq!(viridis(-3.0), viridis(0.0));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
    }

    #[test]
    fn formatting() {
        assert_eq!(format_value(1.0), "1");
        assert_eq!(format_value(-0.25), "-0.25");
        assert_eq!(format_value(123456.0), "1.235e5");
        let f = tick_formatter(0.0, 1.0);
        assert_eq!(f(&0.5), "0.5");
        let f = tick_formatter(0.0, 1e-6);
        assert_eq!(f(&5e-7), "5e-7");
    }

    #[test]
    fn write_to_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.svg");
        let x = [0.0, 1.0];
        write_chart_svg(
            &p,
            &Chart::new("file", "x", "y").with(Series::line("s", &x, &x)),
        )
        .unwrap();
        let s = std::fs::read_to_string(&p).unwrap();
        assert!(s.starts_with("<svg") && s.contains("file"));
        let bad = dir.path().join("missing-dir").join("c.svg");
        assert!(matches!(
            write_chart_svg(
                &bad,
                &Chart::new("f", "x", "y").with(Series::line("s", &x, &x))
            ),
            Err(PlotError::Io(_))
        ));
    }

    #[test]
    fn correlation_chart_marks_the_lags_outside_the_band() {
        let lags: Vec<f64> = (-5..=5).map(f64::from).collect();
        let values = [
            0.0,
            0.05,
            -0.3,
            0.0,
            0.02,
            1.0,
            0.01,
            0.2,
            f64::NAN,
            -0.05,
            0.0,
        ];
        let auto = CorrelationChart::new("ε vs ε", "lag", "R", &lags, &values, 0.1).exempt_zero();
        let svg = render_correlation_svg(std::slice::from_ref(&auto), 1, (500, 350)).unwrap();
        // Lags −3 and 2 are outside; lag 0 (value 1) is exempt; NaN is skipped.
        assert!(svg.contains("outside the band (2)"), "{svg}");
        assert!(has_text(&svg, "band ±0.1"));
        let cross = CorrelationChart {
            exempt_zero: false,
            ..auto.clone()
        };
        let svg = render_correlation_svg(&[auto, cross], 2, (400, 300)).unwrap();
        assert!(svg.contains("outside the band (3)"));
        assert!(svg.contains(r#"width="800" height="300""#));
        // Nothing outside: no marks, no legend entry for them.
        let quiet = [0.01; 11];
        let c = CorrelationChart::new("quiet", "lag", "R", &lags, &quiet, 0.1);
        let svg = render_correlation_svg(&[c], 1, (400, 300)).unwrap();
        assert!(!svg.contains("outside the band") && !svg.contains("<circle"));
    }

    #[test]
    fn correlation_chart_bad_inputs() {
        let lags = [0.0, 1.0];
        let c = CorrelationChart::new("c", "lag", "R", &lags, &[1.0], 0.1);
        assert!(matches!(
            render_correlation_svg(&[c], 1, (300, 300)),
            Err(PlotError::LengthMismatch { x: 2, y: 1, .. })
        ));
        let c = CorrelationChart::new("c", "lag", "R", &[], &[], 0.1);
        assert!(matches!(
            render_correlation_svg(&[c], 1, (300, 300)),
            Err(PlotError::EmptyData(_))
        ));
        for bound in [-1.0, f64::NAN, f64::INFINITY] {
            let c = CorrelationChart::new("c", "lag", "R", &lags, &lags, bound);
            assert!(matches!(
                render_correlation_svg(&[c], 1, (300, 300)),
                Err(PlotError::InvalidInput(_))
            ));
        }
        let bad = [f64::NAN, 1.0];
        let c = CorrelationChart::new("c", "lag", "R", &bad, &lags, 0.1);
        assert!(matches!(
            render_correlation_svg(&[c], 1, (300, 300)),
            Err(PlotError::InvalidInput(_))
        ));
        assert!(matches!(
            render_correlation_svg(&[], 1, (300, 300)),
            Err(PlotError::EmptyData(_))
        ));
        // A single lag and an all-NaN correlation still render.
        let one = [3.0];
        let c = CorrelationChart::new("one", "lag", "R", &one, &[f64::NAN], 0.0);
        assert!(
            render_correlation_svg(&[c], 1, (300, 300))
                .unwrap()
                .starts_with("<svg")
        );
    }
}

//! 2-D charts of [`Series`] (lines, dots, shaded bands), alone or tiled in one figure.

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axes::{Bounds, FONT, MARGIN, TICK_SIZE, TITLE_SIZE, draw_axes};
use crate::error::{PlotError, backend_err};
use crate::layout::{DEFAULT_SIZE, check_size, render_tiled};

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
    pub(crate) fn ranges(&self) -> Result<(Range<f64>, Range<f64>), PlotError> {
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
pub(crate) fn series_colour(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
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
pub(crate) fn draw_chart(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    chart: &Chart<'_>,
) -> Result<(), PlotError> {
    let (xr, yr) = chart.ranges()?;
    area.fill(&WHITE).map_err(backend_err)?;
    // The legend gets a strip of its own right of the plotting area, so that it never hides
    // data, wherever the data lie.
    let legend = chart.series.len() > 1;
    let (plot, strip) = if legend {
        let (w, _) = area.dim_in_pixel();
        let (l, r) = area.split_horizontally(w.saturating_sub(legend_width(chart, w)));
        (l, Some(r))
    } else {
        (area.clone(), None)
    };

    let labels = (chart.x_label.as_str(), chart.y_label.as_str());
    let mut cc = draw_axes(&plot, Some(&chart.title), &xr, &yr, labels, false)?;

    // Scatters at the back (the data behind a fit), then bands, then lines on top of both.
    let mut order: Vec<usize> = (0..chart.series.len()).collect();
    order.sort_by_key(|&i| match chart.series[i].style {
        SeriesStyle::Dots => 0,
        SeriesStyle::Band { .. } => 1,
        SeriesStyle::Line => 2,
    });

    for i in order {
        let s = &chart.series[i];
        let colour = series_colour(i);
        let line_style = colour.stroke_width(2);
        let finite_xy = |k: usize| s.x[k].is_finite() && s.y[k].is_finite();

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

    if let Some(strip) = strip {
        draw_legend(&strip, chart)?;
    }
    Ok(())
}

/// Width in pixels of the legend strip of a chart `width` pixels wide: room for the longest
/// label (about 0.6 em per character) and its glyph, at most a third of the chart.
fn legend_width(chart: &Chart<'_>, width: u32) -> u32 {
    let chars = chart
        .series
        .iter()
        .map(|s| s.label.chars().count())
        .max()
        .unwrap_or(0) as u32;
    (chars * TICK_SIZE * 6 / 10 + 48).clamp(90, width / 3)
}

/// The legend, one entry per series (its glyph and label), top-down in the strip right of the
/// plotting area.
fn draw_legend(
    strip: &DrawingArea<SVGBackend<'_>, Shift>,
    chart: &Chart<'_>,
) -> Result<(), PlotError> {
    let top = (MARGIN + TITLE_SIZE + 20) as i32;
    let step = (TICK_SIZE + 8) as i32;
    let font = (FONT, TICK_SIZE).into_font().color(&BLACK);
    let per_line = label_chars(strip.dim_in_pixel().0);
    let mut y = top;
    for (i, s) in chart.series.iter().enumerate() {
        let colour = series_colour(i);
        let x = 6;
        match s.style {
            SeriesStyle::Line => strip.draw(&PathElement::new(
                vec![(x, y), (x + 20, y)],
                colour.stroke_width(2),
            )),
            SeriesStyle::Dots => strip.draw(&Circle::new((x + 10, y), 3, colour.filled())),
            SeriesStyle::Band { .. } => strip.draw(&Rectangle::new(
                [(x, y - 5), (x + 20, y + 5)],
                colour.mix(0.3).filled(),
            )),
        }
        .map_err(backend_err)?;
        // A label longer than the strip is wrapped onto lines of its own, indented under
        // its first, so that it never runs off the canvas.
        for line in wrap(&s.label, per_line) {
            strip
                .draw(&Text::new(
                    line,
                    (x + 26, y - (TICK_SIZE as i32) / 2),
                    font.clone(),
                ))
                .map_err(backend_err)?;
            y += step;
        }
    }
    Ok(())
}

/// How many characters of a label fit on one line of a legend strip `width` pixels wide (the
/// glyph takes 32 pixels; a character about 0.6 em), at least 8.
fn label_chars(width: u32) -> usize {
    ((width.saturating_sub(32) * 10 / (6 * TICK_SIZE)) as usize).max(8)
}

/// `label` broken at spaces into lines of at most `width` characters; a word longer than a
/// line is cut.
fn wrap(label: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in label.split_whitespace() {
        let mut word: Vec<char> = word.chars().collect();
        while word.len() > width {
            if !line.is_empty() {
                lines.push(std::mem::take(&mut line));
            }
            lines.push(word.drain(..width).collect());
        }
        let word: String = word.into_iter().collect();
        let needed = line.chars().count() + usize::from(!line.is_empty()) + word.chars().count();
        if !line.is_empty() && needed > width {
            lines.push(std::mem::take(&mut line));
        }
        if !word.is_empty() {
            if !line.is_empty() {
                line.push(' ');
            }
            line.push_str(&word);
        }
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines
}

/// Renders a chart to an in-memory SVG string of size `chart.size`.
///
/// Axis ranges come from the finite data (non-finite values are ignored),
/// padded by 5% on each side; constant data gets a widened range. A legend
/// is drawn when there is more than one series, in a strip right of the
/// plotting area (it never hides data), and every series gets a distinct
/// colour. Scatters are drawn first, bands over them and lines on top.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MIN_PANEL_SIZE;
    use crate::tests::{count, has_text};

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

    /// The x coordinate of the `<text>` element whose content is `label`.
    fn text_x(svg: &str, label: &str) -> f64 {
        let lines: Vec<&str> = svg.lines().collect();
        let i = lines.iter().position(|l| *l == label).expect("label drawn");
        let open = lines[..i]
            .iter()
            .rev()
            .find(|l| l.contains("<text"))
            .expect("inside a text element");
        let at = open.find(" x=\"").expect("x attribute") + 4;
        open[at..].split('"').next().unwrap().parse().unwrap()
    }

    /// The largest x of any point of the SVG's polylines.
    fn max_polyline_x(svg: &str) -> f64 {
        svg.split("<polyline")
            .skip(1)
            .flat_map(|p| {
                let at = p.find("points=\"").unwrap() + 8;
                p[at..]
                    .split('"')
                    .next()
                    .unwrap()
                    .split_whitespace()
                    .map(|xy| xy.split(',').next().unwrap().parse::<f64>().unwrap())
                    .collect::<Vec<_>>()
            })
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// A label longer than the strip is wrapped, every character kept, no line wider than the
    /// strip.
    #[test]
    fn long_legend_labels_are_wrapped_within_the_strip() {
        let label = "asymmetric saturation (named, in augmented model) with a longer tail";
        for width in [8usize, 12, 20, 40] {
            let lines = wrap(label, width);
            assert!(
                lines.iter().all(|l| l.chars().count() <= width),
                "{lines:?}"
            );
            // Every character is kept, in order (a word longer than a line is cut).
            let kept: String = lines.concat().chars().filter(|c| *c != ' ').collect();
            assert_eq!(kept, label.replace(' ', ""));
        }
        assert_eq!(wrap("a", 8), vec!["a"]);
        assert_eq!(wrap("", 8), vec![""]);
        assert_eq!(wrap("abcdefghij", 4), vec!["abcd", "efgh", "ij"]);
        // The strip of a 900-pixel chart is a third of it; its lines fit in it.
        let chars = label_chars(300);
        assert!((chars * 6 * TICK_SIZE as usize) / 10 + 32 <= 300);
    }

    /// Data filling every corner, including the upper right where legends used to sit: the
    /// legend is drawn right of all of it.
    #[test]
    fn the_legend_never_covers_data() {
        let x: Vec<f64> = (0..200).map(|i| i as f64 / 199.0).collect();
        let up: Vec<f64> = x.clone();
        let down: Vec<f64> = x.iter().map(|v| 1.0 - v).collect();
        let chart = Chart::new("corners", "x", "y")
            .with(Series::line("rising line", &x, &up))
            .with(Series::line("falling line", &x, &down));
        let svg = render_chart_svg(&chart).unwrap();
        let right = max_polyline_x(&svg);
        for l in ["rising line", "falling line"] {
            assert!(
                text_x(&svg, l) > right,
                "{l} at {} left of data at {right}",
                text_x(&svg, l)
            );
        }
    }

    /// 10⁵ samples, thinned for display, make a small SVG that still shows the spike.
    #[test]
    fn a_long_decimated_record_stays_small() {
        let n = 100_000;
        let x: Vec<f64> = (0..n).map(|k| k as f64).collect();
        let mut y: Vec<f64> = x.iter().map(|t| (t * 1e-3).sin()).collect();
        y[77_777] = 5.0;
        let (xd, yd) = crate::decimate_min_max(&x, &y, 1000);
        let svg = render_chart_svg(&Chart::new("long", "k", "y").with(Series::line("y", &xd, &yd)))
            .unwrap();
        assert!(svg.len() < 100_000, "{} bytes", svg.len());
        // The spike is the highest point drawn: some polyline reaches the top of the range.
        let full = render_chart_svg(&Chart::new("long", "k", "y").with(Series::line("y", &x, &y)))
            .unwrap();
        assert!(
            full.len() > 5 * svg.len(),
            "thinning pays: {} vs {}",
            full.len(),
            svg.len()
        );
        assert!(yd.contains(&5.0));
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
}

//! Correlation functions as bars over their lags with a confidence band (residual tests).

use std::ops::Range;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axes::{Bounds, FONT, TICK_SIZE, draw_axes, format_value, widen};
use crate::chart::series_colour;
use crate::error::{PlotError, backend_err};
use crate::layout::render_tiled;

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
    let labels = (chart.x_label.as_str(), chart.y_label.as_str());
    let mut cc = draw_axes(area, Some(&chart.title), &xr, &yr, labels, false)?;

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
    use crate::tests::has_text;

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

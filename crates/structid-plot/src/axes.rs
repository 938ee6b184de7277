//! Axes: data ranges, tick labels and the fonts and areas of titles and labels.

use std::ops::Range;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::error::{PlotError, backend_err};

/// Running min/max of finite values.
#[derive(Default)]
pub(crate) struct Bounds {
    pub(crate) lo: f64,
    pub(crate) hi: f64,
    pub(crate) any: bool,
}

impl Bounds {
    pub(crate) fn add(&mut self, v: f64) {
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
    pub(crate) fn padded(&self) -> Option<Range<f64>> {
        if !self.any {
            return None;
        }
        let (lo, hi) = widen(self.lo, self.hi);
        let pad = 0.05 * (hi - lo);
        Some(lo - pad..hi + pad)
    }
}

pub(crate) fn clamp_finite(v: f64) -> f64 {
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
pub(crate) fn widen(lo: f64, hi: f64) -> (f64, f64) {
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

pub(crate) const FONT: &str = "sans-serif";
pub(crate) const TITLE_SIZE: u32 = 24;
pub(crate) const DESC_SIZE: u32 = 19;
pub(crate) const TICK_SIZE: u32 = 16;
pub(crate) const X_LABEL_AREA: u32 = 50;
pub(crate) const Y_LABEL_AREA: u32 = 70;
pub(crate) const MARGIN: u32 = 12;

/// Tick-label formatter for an axis spanning `lo..hi`: enough decimals to
/// distinguish ticks, scientific notation for very large or small numbers.
pub(crate) fn tick_formatter(lo: f64, hi: f64) -> impl Fn(&f64) -> String {
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

/// A number with four significant digits, in scientific notation outside [10⁻³, 10⁵), trailing
/// zeros dropped: how the figures' labels and the reports print values.
///
/// ```
/// use structid_plot::format_value;
/// assert_eq!(format_value(0.012345), "0.01235");
/// assert_eq!(format_value(123.0), "123");
/// assert_eq!(format_value(1.5e-7), "1.5e-7");
/// assert_eq!(format_value(-0.0), "0");
/// ```
pub fn format_value(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    if v == 0.0 {
        return "0".into();
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

/// Maximum numbers of x and y tick labels that fit in an area without
/// overlapping.
pub(crate) fn label_counts(area: &DrawingArea<SVGBackend<'_>, Shift>) -> (usize, usize) {
    let (w, h) = area.dim_in_pixel();
    let x = (w.saturating_sub(Y_LABEL_AREA) / 70).clamp(2, 10) as usize;
    let y = (h.saturating_sub(X_LABEL_AREA + TITLE_SIZE) / 35).clamp(2, 10) as usize;
    (x, y)
}

/// The coordinate system of a panel: `f64` on both axes.
pub(crate) type PanelCoords<'c, 'b> =
    ChartContext<'c, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Builds the `xr` by `yr` axes of a panel on `area` and draws them: tick labels that fit
/// the area, the axis descriptions `labels` (x, y) and, when given, `title` as the caption.
/// A `heat_map` panel has a narrow right margin (its colour bar follows) and no grid lines
/// (the cells would hide them); other panels get light grid lines.
pub(crate) fn draw_axes<'c, 'b>(
    area: &DrawingArea<SVGBackend<'b>, Shift>,
    title: Option<&str>,
    xr: &Range<f64>,
    yr: &Range<f64>,
    labels: (&str, &str),
    heat_map: bool,
) -> Result<PanelCoords<'c, 'b>, PlotError> {
    let mut builder = ChartBuilder::on(area);
    if let Some(title) = title {
        builder.caption(title, (FONT, TITLE_SIZE));
    }
    builder.margin(MARGIN);
    if heat_map {
        builder.margin_right(4);
    }
    let mut cc = builder
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(xr.clone(), yr.clone())
        .map_err(backend_err)?;
    let xf = tick_formatter(xr.start, xr.end);
    let yf = tick_formatter(yr.start, yr.end);
    let (xn, yn) = label_counts(area);
    let mut mesh = cc.configure_mesh();
    if heat_map {
        mesh.disable_mesh();
    }
    mesh.x_labels(xn)
        .y_labels(yn)
        .x_desc(labels.0)
        .y_desc(labels.1)
        .axis_desc_style((FONT, DESC_SIZE))
        .label_style((FONT, TICK_SIZE))
        .x_label_formatter(&xf)
        .y_label_formatter(&yf);
    if !heat_map {
        mesh.light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(215, 215, 215));
    }
    mesh.draw().map_err(backend_err)?;
    Ok(cc)
}

#[cfg(test)]
mod tests {
    use super::*;

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
}

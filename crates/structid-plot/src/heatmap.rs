//! Heat maps of scalar fields on rectilinear grids, with a colour bar.

use std::ops::Range;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::axes::{
    Bounds, FONT, MARGIN, TICK_SIZE, TITLE_SIZE, X_LABEL_AREA, clamp_finite, draw_axes,
    format_value, widen,
};
use crate::error::{PlotError, backend_err};
use crate::layout::render_tiled;

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
    pub(crate) fn validate(&self) -> Result<(f64, f64), PlotError> {
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

pub(crate) fn draw_heatmap(
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
    let labels = (map.x_label.as_str(), map.y_label.as_str());
    let mut cc = draw_axes(&plot_area, None, &xr, &yr, labels, true)?;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tests::{count, has_text};

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
}

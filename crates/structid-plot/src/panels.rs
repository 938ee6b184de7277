//! Figures that mix charts and heat maps, tiled as [`crate::render_grid_svg`] tiles charts.

use crate::chart::{Chart, draw_chart};
use crate::error::PlotError;
use crate::heatmap::{HeatMap, draw_heatmap};
use crate::layout::render_tiled;

/// One panel of a figure that mixes charts and heat maps ([`render_panels_svg`]).
#[derive(Clone, Debug)]
pub enum Panel<'a> {
    /// A line, dot and band chart.
    Chart(Chart<'a>),
    /// A heat map of a function of two variables.
    Heat(HeatMap<'a>),
}

/// Renders charts and heat maps tiled row by row in one SVG figure, `cols` panels a row, each
/// `panel_size` pixels (as [`crate::render_grid_svg`] and [`crate::render_heatmaps_svg`] do
/// for one kind): a map of two variables beside the scatter that checks it, say.
///
/// ```
/// use structid_plot::{Chart, HeatMap, Panel, Series, render_panels_svg};
/// let xs = [0.0, 0.5, 1.0];
/// let values: Vec<f64> = (0..9).map(|i| i as f64).collect();
/// let d = [0.0, 8.0];
/// let panels = [
///     Panel::Heat(HeatMap::new("N", "z0", "z1", &xs, &xs, &values)),
///     Panel::Chart(Chart::new("check", "N̂", "ŵ + r").with(Series::line("diagonal", &d, &d))),
/// ];
/// let svg = render_panels_svg(&panels, 2, (400, 300)).unwrap();
/// assert!(svg.contains("check") && svg.contains("z1"));
/// ```
///
/// # Errors
/// [`PlotError`] when there is no panel, a panel's data are invalid or the figure is too
/// small or too large.
pub fn render_panels_svg(
    panels: &[Panel<'_>],
    cols: usize,
    panel_size: (u32, u32),
) -> Result<String, PlotError> {
    render_tiled(
        panels,
        cols,
        panel_size,
        "no panels",
        |p: &Panel<'_>| match p {
            Panel::Chart(c) => c.ranges().map(|_| ()),
            Panel::Heat(h) => h.validate().map(|_| ()),
        },
        |area, p: &Panel<'_>| match p {
            Panel::Chart(c) => draw_chart(area, c),
            Panel::Heat(h) => draw_heatmap(area, h),
        },
    )
}

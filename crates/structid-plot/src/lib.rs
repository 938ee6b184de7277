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
//! * long records thinned for display with their envelope kept, see [`decimate_min_max`];
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

mod axes;
mod chart;
mod correlation;
mod decimate;
mod error;
mod heatmap;
mod layout;
mod panels;

pub use axes::format_value;
pub use chart::{Chart, Series, SeriesStyle, render_chart_svg, render_grid_svg, write_chart_svg};
pub use correlation::{CorrelationChart, render_correlation_svg};
pub use decimate::decimate_min_max;
pub use error::PlotError;
pub use heatmap::{HeatMap, render_heatmaps_svg};
pub use layout::{DEFAULT_SIZE, MAX_FIGURE_SIZE, MIN_PANEL_SIZE};
pub use panels::{Panel, render_panels_svg};

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn count(h: &str, n: &str) -> usize {
        h.matches(n).count()
    }

    /// Whether the SVG has a `<text>` element with exactly this content.
    pub(crate) fn has_text(svg: &str, t: &str) -> bool {
        svg.lines().any(|l| l == t)
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
}

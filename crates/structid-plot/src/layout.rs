//! Figure and panel sizes, and panels tiled row by row in one figure.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::error::{PlotError, backend_err};

/// Default size in pixels of a single chart, `(width, height)`.
pub const DEFAULT_SIZE: (u32, u32) = (800, 500);

/// Smallest accepted width or height of a chart or panel in pixels.
///
/// Smaller drawing areas cannot hold the title, axes, tick labels and
/// colour bar legibly.
pub const MIN_PANEL_SIZE: u32 = 200;

/// Largest accepted width or height of a whole figure in pixels.
pub const MAX_FIGURE_SIZE: u32 = 100_000;

pub(crate) fn check_size(size: (u32, u32), what: &str) -> Result<(), PlotError> {
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
pub(crate) fn render_tiled<T>(
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

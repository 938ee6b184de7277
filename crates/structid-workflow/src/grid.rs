//! Grids over a signal's range, on which maps are evaluated for tables and figures.

/// Points of a one-input grid.
pub const GRID_1D: usize = 201;
/// Points per axis of a two-input grid.
pub const GRID_2D: usize = 41;
/// Most data points drawn as dots in one series.
pub const MAX_DOTS: usize = 2000;
/// Half-width of the 95 % band in standard deviations.
pub const BAND_Z: f64 = 1.96;

/// `n` equally spaced points from `lo` to `hi` inclusive.
pub fn linspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    match n {
        0 => Vec::new(),
        1 => vec![0.5 * (lo + hi)],
        _ => (0..n)
            .map(|i| {
                let t = i as f64 / (n - 1) as f64;
                if i == n - 1 { hi } else { lo + t * (hi - lo) }
            })
            .collect(),
    }
}

/// [min, max] of the finite values, widened to a non-empty interval when all are equal.
pub fn span(x: &[f64]) -> (f64, f64) {
    let (lo, hi) = x
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    if hi > lo {
        (lo, hi)
    } else {
        let h = if lo == 0.0 { 0.5 } else { 0.5 * lo.abs() };
        (lo - h, hi + h)
    }
}

/// At most `max` indices spread evenly over `0..len`.
pub fn subsample(len: usize, max: usize) -> Vec<usize> {
    if len <= max {
        (0..len).collect()
    } else {
        (0..max).map(|i| i * len / max).collect()
    }
}

/// Mean of a slice (0 for an empty one).
pub fn mean(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        x.iter().sum::<f64>() / x.len() as f64
    }
}

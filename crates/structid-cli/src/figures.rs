//! Grids over the data range and SVG figures of estimated maps.

use structid_core::{BlockEstimate, Interpolant};
use structid_lti::Signal;
use structid_plot::{Chart, HeatMap, PlotError, Series, render_chart_svg, render_heatmaps_svg};

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

/// An estimated map evaluated for output.
pub enum MapGrid {
    /// One input: grid points and values.
    One {
        /// Grid.
        xs: Vec<f64>,
        /// N̂ on the grid.
        values: Vec<f64>,
    },
    /// Two inputs: a rectangular grid, values x fastest.
    Two {
        /// First-input grid.
        xs: Vec<f64>,
        /// Second-input grid.
        ys: Vec<f64>,
        /// N̂ on the grid, `values[i + j·xs.len()]`.
        values: Vec<f64>,
    },
    /// Three or more inputs: the data points.
    Points,
}

impl MapGrid {
    /// Evaluates `map` on a grid over the range of `z` (one point per sample).
    pub fn new(map: &dyn Interpolant, z: &Signal) -> Self {
        match z.channels() {
            1 => {
                let (lo, hi) = span(&z.channel(0));
                let xs = linspace(lo, hi, GRID_1D);
                let values = xs.iter().map(|&x| map.eval(&[x])).collect();
                MapGrid::One { xs, values }
            }
            2 => {
                let (x0, x1) = span(&z.channel(0));
                let (y0, y1) = span(&z.channel(1));
                let xs = linspace(x0, x1, GRID_2D);
                let ys = linspace(y0, y1, GRID_2D);
                let values = grid_values(map, &xs, &ys);
                MapGrid::Two { xs, ys, values }
            }
            _ => MapGrid::Points,
        }
    }

    /// The evaluation points, one per sample, in the order of [`MapGrid::columns`]: the 1-D
    /// grid, the 2-D grid with the first input fastest, or the data points `z`.
    pub fn points(&self, z: &Signal) -> Signal {
        match self {
            MapGrid::One { xs, .. } => Signal::from_fn(xs.len(), 1, |k, _| xs[k]),
            MapGrid::Two { xs, ys, .. } => Signal::from_fn(xs.len() * ys.len(), 2, |k, c| {
                if c == 0 {
                    xs[k % xs.len()]
                } else {
                    ys[k / xs.len()]
                }
            }),
            MapGrid::Points => z.clone(),
        }
    }

    /// CSV columns: the inputs then `value` (points: the data points and ŵ), then the
    /// posterior standard deviation `std` when given (at [`MapGrid::points`]).
    pub fn columns(&self, est: &BlockEstimate, std: Option<&[f64]>) -> Vec<Vec<f64>> {
        let mut cols = self.value_columns(est);
        if let Some(s) = std {
            cols.push(s.to_vec());
        }
        cols
    }

    fn value_columns(&self, est: &BlockEstimate) -> Vec<Vec<f64>> {
        match self {
            MapGrid::One { xs, values } => vec![xs.clone(), values.clone()],
            MapGrid::Two { xs, ys, values } => {
                let mut a = Vec::with_capacity(values.len());
                let mut b = Vec::with_capacity(values.len());
                for &y in ys {
                    for &x in xs {
                        a.push(x);
                        b.push(y);
                    }
                }
                vec![a, b, values.clone()]
            }
            MapGrid::Points => {
                let mut cols: Vec<Vec<f64>> =
                    (0..est.z.channels()).map(|c| est.z.channel(c)).collect();
                cols.push(est.w_hat.clone());
                cols
            }
        }
    }
}

/// `map` on the grid xs × ys, x fastest.
pub fn grid_values(map: &dyn Interpolant, xs: &[f64], ys: &[f64]) -> Vec<f64> {
    let mut values = Vec::with_capacity(xs.len() * ys.len());
    for &y in ys {
        for &x in xs {
            values.push(map.eval(&[x, y]));
        }
    }
    values
}

/// The SVG figure of one block's estimate: for one input, the estimate over the grid, the
/// points (z_k, ŵ_k), the truth and, with the posterior standard deviation `std` (at
/// [`MapGrid::points`]), the shaded 95 % band N̂ ± 1.96·std; for two inputs, heat maps of the
/// estimate, the truth and the standard deviation; for more, ŵ against the truth at the data
/// points (or ŵ over time without a truth).
pub fn map_svg(
    est: &BlockEstimate,
    grid: &MapGrid,
    truth: Option<&dyn Interpolant>,
    input_names: &[String],
    std: Option<&[f64]>,
) -> Result<String, PlotError> {
    let name = &est.name;
    let idx = subsample(est.w_hat.len(), MAX_DOTS);
    match grid {
        MapGrid::One { xs, values } => {
            let zc = est.z.channel(0);
            let dz: Vec<f64> = idx.iter().map(|&k| zc[k]).collect();
            let dw: Vec<f64> = idx.iter().map(|&k| est.w_hat[k]).collect();
            let tv: Vec<f64> = truth
                .map(|t| xs.iter().map(|&x| t.eval(&[x])).collect())
                .unwrap_or_default();
            let (lower, upper): (Vec<f64>, Vec<f64>) = std
                .map(|s| {
                    values
                        .iter()
                        .zip(s)
                        .map(|(v, s)| (v - BAND_Z * s, v + BAND_Z * s))
                        .unzip()
                })
                .unwrap_or_default();
            let mut chart = Chart::new(
                format!("{name}: estimated map"),
                input_names.first().cloned().unwrap_or_else(|| "z0".into()),
                format!("w = {name}(z)"),
            );
            if std.is_some() {
                chart = chart.with(Series::band("95 % band", xs, &[], &lower, &upper));
            }
            chart = chart
                .with(Series::dots("ŵ at the data points", &dz, &dw))
                .with(Series::line("estimate", xs, values));
            if truth.is_some() {
                chart = chart.with(Series::line("truth", xs, &tv));
            }
            render_chart_svg(&chart)
        }
        MapGrid::Two { xs, ys, values } => {
            let (xl, yl) = (
                input_names.first().cloned().unwrap_or_else(|| "z0".into()),
                input_names.get(1).cloned().unwrap_or_else(|| "z1".into()),
            );
            let tv: Vec<f64> = truth.map(|t| grid_values(t, xs, ys)).unwrap_or_default();
            let mut maps = vec![HeatMap::new(
                format!("{name}: estimate"),
                &xl,
                &yl,
                xs,
                ys,
                values,
            )];
            if truth.is_some() {
                let (lo, hi) = span(&[values.as_slice(), tv.as_slice()].concat());
                maps[0] = maps[0].clone().with_range(lo, hi);
                maps.push(
                    HeatMap::new(format!("{name}: truth"), &xl, &yl, xs, ys, &tv)
                        .with_range(lo, hi),
                );
            }
            if let Some(s) = std {
                maps.push(HeatMap::new(
                    format!("{name}: posterior std"),
                    &xl,
                    &yl,
                    xs,
                    ys,
                    s,
                ));
            }
            let n = maps.len();
            render_heatmaps_svg(&maps, n, (560, 480))
        }
        MapGrid::Points => {
            let dw: Vec<f64> = idx.iter().map(|&k| est.w_hat[k]).collect();
            match truth {
                Some(t) => {
                    let tv: Vec<f64> = idx.iter().map(|&k| t.eval(est.z.sample(k))).collect();
                    let (lo, hi) = span(&[tv.as_slice(), dw.as_slice()].concat());
                    let diag = [lo, hi];
                    render_chart_svg(
                        &Chart::new(
                            format!("{name}: estimate against truth at the data points"),
                            "truth",
                            "estimate",
                        )
                        .with(Series::dots("(truth, ŵ)", &tv, &dw))
                        .with(Series::line("ŵ = truth", &diag, &diag)),
                    )
                }
                None => {
                    let k: Vec<f64> = idx.iter().map(|&k| k as f64).collect();
                    render_chart_svg(
                        &Chart::new(format!("{name}: estimated map output"), "sample k", "ŵ_k")
                            .with(Series::dots("ŵ", &k, &dw)),
                    )
                }
            }
        }
    }
}

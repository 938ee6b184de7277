//! Grids over the data range and SVG figures of estimated maps and linear parts (`map_<block>.svg`
//! of `structid identify` and `structid refine`, linear.svg of `structid linear`).

use structid_core::{BlockEstimate, Identification, Interpolant, Lft};
use structid_lti::Signal;
use structid_plot::{
    Chart, HeatMap, Panel, PlotError, Series, render_chart_svg, render_panels_svg,
};

use crate::grid::{BAND_Z, GRID_1D, GRID_2D, MAX_DOTS, linspace, span, subsample};

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

/// Markov parameters summed for the energy gain of a path in [`partial_residuals`]: enough
/// for any stable path of structid's records to have decayed.
const GAIN_TERMS: usize = 2000;

/// The partial residuals of the block writing w channel `output`: ŵ_k plus the output
/// residual r = L_ye·ê mapped back to the block's output, δ = L_ywᵀ·r / ‖h‖² (h the impulse
/// response of the block's path L_yw to y). The adjoint undoes the path exactly when it is a
/// gain or a delay (the paper's examples: y = f(u) + g(u_(k−2)) + e); through a filter it is
/// the matched filter scaled by its energy, a smoothed view of what the map leaves
/// unexplained. `None` when the path does not reach y.
pub fn partial_residuals(lft: &Lft, id: &Identification, output: usize) -> Option<Vec<f64>> {
    let len = id.e_hat.len();
    let t_ye = lft.t_ye();
    let mut r = vec![0.0; len * t_ye.outputs()];
    t_ye.apply_long(id.e_hat.as_slice(), &mut r);
    let path = lft.t_yw_channel(output);
    let gain2: f64 = path
        .markov_parameters(len.min(GAIN_TERMS))
        .iter()
        .map(|h| h.norm_squared())
        .sum();
    if !(gain2.is_finite() && gain2 > 0.0) {
        return None;
    }
    let mut back = vec![0.0; len];
    path.apply_adjoint_long(&r, &mut back);
    let w = id.w_hat.channel(output);
    Some(w.iter().zip(&back).map(|(w, d)| w + d / gain2).collect())
}

/// The SVG figure of one block's estimate: for one input, the estimate over the grid, the
/// scatter of its partial residuals (`partial`, [`partial_residuals`]; the points (z_k, ŵ_k)
/// without them) behind it, the truth and, with the posterior standard deviation `std` (at
/// [`MapGrid::points`]), the shaded 95 % band N̂ ± 1.96·std; for two inputs, heat maps of the
/// estimate, the truth and the standard deviation, beside the partial residuals against the
/// estimate at the data points (the staticness check) when given; for more, that check, else ŵ
/// against the truth at the data points (or ŵ over time without a truth).
pub fn map_svg(
    est: &BlockEstimate,
    grid: &MapGrid,
    truth: Option<&dyn Interpolant>,
    input_names: &[String],
    std: Option<&[f64]>,
    partial: Option<&[f64]>,
) -> Result<String, PlotError> {
    let name = &est.name;
    let idx = subsample(est.w_hat.len(), MAX_DOTS);
    match grid {
        MapGrid::One { xs, values } => {
            let zc = est.z.channel(0);
            let dz: Vec<f64> = idx.iter().map(|&k| zc[k]).collect();
            let (dots, label) = match partial {
                Some(p) if p.len() == est.w_hat.len() => (p, "partial residuals ŵ + r"),
                _ => (est.w_hat.as_slice(), "ŵ at the data points"),
            };
            let dw: Vec<f64> = idx.iter().map(|&k| dots[k]).collect();
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
                .with(Series::dots(label, &dz, &dw))
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
            let check = partial_check(est, partial, &idx);
            let mut panels: Vec<Panel<'_>> = maps.into_iter().map(Panel::Heat).collect();
            if let Some((fit, dots, diag)) = &check {
                panels.push(Panel::Chart(partial_chart(name, fit, dots, diag)));
            }
            let n = panels.len();
            render_panels_svg(&panels, n, (560, 480))
        }
        MapGrid::Points => {
            let dw: Vec<f64> = idx.iter().map(|&k| est.w_hat[k]).collect();
            if let Some((fit, dots, diag)) = &partial_check(est, partial, &idx) {
                return render_chart_svg(&partial_chart(name, fit, dots, diag));
            }
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

/// The staticness check of a map of two or more inputs, whose partial residuals cannot be
/// drawn over z: the partial residuals ŵ_k + r_k against the estimate N̂(z_k) at the samples
/// `idx`, with the diagonal from the smallest to the largest of either. A static map leaves a
/// band around the diagonal as wide as the noise; a dynamic one, loops or a spread that
/// grows with the motion. `None` without partial residuals.
fn partial_check(
    est: &BlockEstimate,
    partial: Option<&[f64]>,
    idx: &[usize],
) -> Option<(Vec<f64>, Vec<f64>, [f64; 2])> {
    let p = partial.filter(|p| p.len() == est.w_hat.len())?;
    let fit: Vec<f64> = idx.iter().map(|&k| est.map.eval(est.z.sample(k))).collect();
    let dots: Vec<f64> = idx.iter().map(|&k| p[k]).collect();
    let (lo, hi) = span(&[fit.as_slice(), dots.as_slice()].concat());
    Some((fit, dots, [lo, hi]))
}

/// The chart of [`partial_check`].
fn partial_chart<'a>(name: &str, fit: &'a [f64], dots: &'a [f64], diag: &'a [f64; 2]) -> Chart<'a> {
    Chart::new(
        format!("{name}: partial residuals against the estimate"),
        format!("{name}(z) estimated at the data points"),
        "partial residuals ŵ + r",
    )
    .with(Series::dots("(N̂(z_k), ŵ_k + r_k)", fit, dots))
    .with(Series::line("static: on the diagonal", diag, diag))
}

/// Frequencies of the Bode plot: log-spaced over three decades below Nyquist.
const BODE_POINTS: usize = 300;

/// The figure of a linear part: Bode magnitude (dB, with the ±2σ band of the parameter
/// `covariance` when the fit has one) and phase over log₁₀ frequency, the step response and
/// the pole–zero map with the unit circle. One curve per input, named by `input_names`;
/// frequencies and time in Hz and seconds when the model has a sample time.
pub fn linear_svg(
    model: &structid_linear::PolynomialModel,
    covariance: Option<&nalgebra::DMatrix<f64>>,
    input_names: &[String],
) -> crate::Result<String> {
    use structid_linear::response::{bode, poles, step_response, zeros};
    let ts = model.sample_time;
    let scale = ts.map_or(1.0, |t| 1.0 / t);
    let f_unit = if ts.is_some() { "Hz" } else { "cycles/sample" };
    let freqs: Vec<f64> = (0..BODE_POINTS)
        .map(|i| 0.5 * 10f64.powf(-3.0 + 3.0 * i as f64 / (BODE_POINTS - 1) as f64))
        .collect();
    let logf: Vec<f64> = freqs.iter().map(|f| (f * scale).log10()).collect();
    let db = |m: f64| 20.0 * m.max(f64::MIN_POSITIVE).log10();
    // Settle within the record of the step plot: 5 time constants of the slowest pole.
    let radius = poles(model)
        .iter()
        .map(|p| p.0.hypot(p.1))
        .fold(0.0, f64::max);
    let steps = if radius < 1.0 && radius > 0.0 {
        ((-5.0 / radius.ln()).ceil() as usize).clamp(20, 2000)
    } else {
        200
    };
    let time: Vec<f64> = (0..steps).map(|k| k as f64 / scale).collect();
    struct Curves {
        name: String,
        mag: Vec<f64>,
        lo: Vec<f64>,
        hi: Vec<f64>,
        phase: Vec<f64>,
        step: Vec<f64>,
        zeros: (Vec<f64>, Vec<f64>),
    }
    let mut curves = Vec::new();
    for i in 0..model.inputs() {
        let b = bode(model, i, &freqs, covariance).map_err(crate::WorkflowError::Linear)?;
        let band: Option<(Vec<f64>, Vec<f64>)> = b
            .iter()
            .map(|p| {
                p.magnitude_std
                    .filter(|s| s.is_finite())
                    .map(|s| (db(p.magnitude - 2.0 * s), db(p.magnitude + 2.0 * s)))
            })
            .collect::<Option<Vec<_>>>()
            .map(|v| v.into_iter().unzip());
        let (lo, hi) = band.unwrap_or_default();
        let z = zeros(model, i);
        curves.push(Curves {
            name: input_names
                .get(i)
                .cloned()
                .unwrap_or_else(|| format!("u{i}")),
            mag: b.iter().map(|p| db(p.magnitude)).collect(),
            lo,
            hi,
            phase: b.iter().map(|p| p.phase.to_degrees()).collect(),
            step: step_response(model, i, steps).map_err(crate::WorkflowError::Linear)?,
            zeros: (
                z.iter().map(|z| z.0).collect(),
                z.iter().map(|z| z.1).collect(),
            ),
        });
    }
    let p = poles(model);
    let (pr, pi): (Vec<f64>, Vec<f64>) = p.iter().copied().unzip();
    let circle: Vec<(f64, f64)> = (0..=120)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 120.0;
            (a.cos(), a.sin())
        })
        .collect();
    let (cx, cy): (Vec<f64>, Vec<f64>) = circle.into_iter().unzip();
    let x_label = format!("log₁₀ frequency ({f_unit})");
    let mut magnitude = Chart::new("Bode magnitude", x_label.as_str(), "|G| (dB)");
    let mut phase = Chart::new("Bode phase", x_label.as_str(), "arg G (degrees)");
    let mut step = Chart::new(
        "Step response",
        if ts.is_some() { "time (s)" } else { "sample" },
        "y",
    );
    let mut pz = Chart::new("Poles and zeros", "Re z", "Im z")
        .with(Series::line("unit circle", &cx, &cy))
        .with(Series::dots("poles", &pr, &pi));
    for c in &curves {
        if !c.lo.is_empty() {
            magnitude = magnitude.with(Series::band(
                format!("±2σ ({})", c.name),
                &logf,
                &[],
                &c.lo,
                &c.hi,
            ));
        }
        magnitude = magnitude.with(Series::line(c.name.as_str(), &logf, &c.mag));
        phase = phase.with(Series::line(c.name.as_str(), &logf, &c.phase));
        step = step.with(Series::line(c.name.as_str(), &time, &c.step));
        if !c.zeros.0.is_empty() {
            pz = pz.with(Series::dots(
                format!("zeros ({})", c.name),
                &c.zeros.0,
                &c.zeros.1,
            ));
        }
    }
    Ok(structid_plot::render_grid_svg(
        &[magnitude, phase, step, pz],
        2,
        (640, 440),
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use structid_core::{IdentifySettings, KernelDispersion, identify, paper};

    /// In the paper's spray example y = f(u_k) + g(u_(k−2)) + e, so the residual mapped back
    /// to f is ê itself and to g is ê two samples later: the partial residuals are exactly
    /// ŵ_f + ê and ŵ_g,k + ê_(k+2).
    #[test]
    fn partial_residuals_undo_gains_and_delays() {
        let d = Arc::new(KernelDispersion::gaussian(0.1).unwrap());
        let exp = paper::spray(300, 0.5, d, 3).unwrap();
        let settings = IdentifySettings::builder().beta(0.01).build().unwrap();
        let id = identify(&exp.model, &exp.data, &settings).unwrap();
        let lft = exp.model.lft();
        let e = id.e_hat.channel(0);
        let f = partial_residuals(lft, &id, 0).unwrap();
        let wf = id.w_hat.channel(0);
        for k in 0..300 {
            assert!((f[k] - (wf[k] + e[k])).abs() < 1e-9, "f at {k}");
        }
        let g = partial_residuals(lft, &id, 1).unwrap();
        let wg = id.w_hat.channel(1);
        for k in 0..298 {
            assert!((g[k] - (wg[k] + e[k + 2])).abs() < 1e-9, "g at {k}");
        }
        // The last two samples of g never reach the record.
        assert!((g[299] - wg[299]).abs() < 1e-12);
    }

    /// A two-input map cannot carry its partial residuals over z: its figure adds the check
    /// of them against the estimate, and for the paper's static multi-input map they scatter
    /// about the diagonal by no more than the noise mapped back through L_yw (whose inverse
    /// has a gain of at most 3).
    #[test]
    fn a_map_of_two_inputs_draws_its_partial_residuals_against_the_estimate() {
        let noise = 0.05;
        let d = Arc::new(KernelDispersion::gaussian(0.8).unwrap());
        let exp = paper::multi_input(400, noise, d, 2).unwrap();
        let settings = IdentifySettings::builder().beta(1e-3).build().unwrap();
        let id = identify(&exp.model, &exp.data, &settings).unwrap();
        let p = partial_residuals(exp.model.lft(), &id, 0).unwrap();
        let est = &id.blocks[0];
        let grid = MapGrid::new(est.map.as_ref(), &est.z);
        assert!(matches!(grid, MapGrid::Two { .. }));
        let names = ["u0".to_string(), "u1".to_string()];
        let with = map_svg(est, &grid, None, &names, None, Some(&p)).unwrap();
        let without = map_svg(est, &grid, None, &names, None, None).unwrap();
        assert!(with.contains("partial residuals against the estimate"));
        assert!(!without.contains("partial residuals"));
        let idx = subsample(est.w_hat.len(), MAX_DOTS);
        let (fit, dots, diag) = partial_check(est, Some(&p), &idx).unwrap();
        let off: f64 = fit
            .iter()
            .zip(&dots)
            .map(|(f, d)| (d - f).powi(2))
            .sum::<f64>()
            / fit.len() as f64;
        assert!(
            off.sqrt() < 3.0 * noise,
            "RMS off the diagonal {}",
            off.sqrt()
        );
        assert!(diag[0] <= fit.iter().copied().fold(f64::INFINITY, f64::min));
        assert!(diag[1] >= dots.iter().copied().fold(f64::NEG_INFINITY, f64::max));
        // a partial-residual vector of the wrong length is ignored, not drawn
        assert!(partial_check(est, Some(&p[1..]), &idx).is_none());
    }
}

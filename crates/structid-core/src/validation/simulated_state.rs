//! A window's initial state for a model whose z the record does not give: fitted to y through
//! the simulation with the maps in the loop.
//!
//! [`super::windows::window_state`] makes the state fit linear by holding the maps' outputs at
//! their values at the measured z, ŵ = N̂(z). Beyond measurability there is no measured z: a
//! block reads another map's output of the same sample (D_zw ≠ 0), sits behind a sensor map
//! whose inverse alone would reach its input, or reads a state no sensor measures. The state
//! then reaches y only through the maps, and the fit is the nonlinear least-squares problem
//!
//! ```text
//!   x̂_s = argmin over x of  Σ_{k ∈ F} |y_k − ŷ_k(x)|²,
//! ```
//!
//! ŷ(x) the simulation of the LFT with the maps N̂ in the loop (e = 0) from x at the window's
//! first sample s, F the same fitted samples as the linear estimate uses (the first half of the
//! window), so that both estimates trade the same noise against the same missing effects.
//!
//! **Start and unseen directions.** The search starts from x⁰, the state that the simulation
//! of the previous window reached at s (zero for the first window): continuity is the best
//! guess the model itself offers, and it is where a direction of x that y does not see over F
//! stays. Such directions (a state the maps hide, a mode the sensor does not see over the
//! window) would make the normal equations singular, and a solver would move along them on
//! round-off alone. The search is therefore restricted to the directions y sees: with the
//! Jacobian J = ∂ŷ_F/∂x at x⁰ (central differences: the model gives no derivatives of its
//! maps) and its singular value decomposition J = U·Σ·Vᵀ, the state is x = x⁰ + V_r·c over
//! the right singular vectors V_r whose singular values exceed [`CUTOFF`]·σ_max, and c is
//! fitted by the workspace's Levenberg–Marquardt. Because the maps are nonlinear, what y sees
//! can grow away from x⁰ (a saturated sensor at x⁰ that the fitted state brings back into its
//! range); the search is then repeated from its result over the larger set of directions.

use std::ops::Range;

use nalgebra::{DMatrix, DVector};
use structid_linear::levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, LmSettings};
use structid_lti::Signal;

use crate::error::{Error, Result};
use crate::model::interpolant::Interpolant;
use crate::model::{Data, Model};

/// Singular values of J below this share of the largest count as directions y does not see.
/// Central differences are accurate to about 10⁻¹⁰ relative, so a direction y truly does not
/// see shows near there; a direction seen a hundred million times more weakly than the best
/// one is not determined by noisy data anyway.
const CUTOFF: f64 = 1e-8;

/// The central-difference step relative to the state's scale: truncation error ~ step² and
/// round-off ~ ε/step, both near 10⁻¹⁰ of the Jacobian.
const STEP: f64 = 1e-5;

/// Levenberg–Marquardt iterations per search: a state enters ŷ linearly wherever the maps are
/// smooth over the window, so Gauss–Newton steps converge in a few; more only where a map
/// bends sharply (a saturation the start is far beyond).
const MAX_ITERATIONS: usize = 20;

/// The window's state x̂_s fitted to y over the samples `fitted` of `data` by simulation with
/// `maps` in the loop, searched from `start` (see the [module documentation](self)).
///
/// Errors: the simulation's ([`Model::simulate`]) when it fails from `start`, and
/// [`Error::Numerical`] when its output is not finite there.
pub(crate) fn simulated_window_state(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    fitted: Range<usize>,
    start: &[f64],
) -> Result<Vec<f64>> {
    let n = model.lft().dims().states;
    if n == 0 {
        return Ok(Vec::new());
    }
    let mut problem = StateFit {
        model,
        maps,
        u: data.u().slice(fitted.clone()),
        y: DVector::from_column_slice(data.y().slice(fitted.clone()).as_slice()),
        origin: start.to_vec(),
        basis: DMatrix::identity(n, n),
        step: 0.0,
    };
    // The start must simulate: its error is the one the window's simulation would report.
    let end = problem.simulate(start)?;
    problem.step = STEP * scale(start, &end);
    let lm = LevenbergMarquardt::new(
        LmSettings::builder()
            .max_iterations(MAX_ITERATIONS)
            .build()?,
    );
    let mut x = start.to_vec();
    let mut searched = 0;
    while searched < n {
        problem.origin = x.clone();
        problem.basis = DMatrix::identity(n, n);
        let Some(jacobian) = problem.central_jacobian(&vec![0.0; n]) else {
            break;
        };
        let basis = seen_directions(&jacobian);
        if basis.ncols() <= searched {
            break;
        }
        searched = basis.ncols();
        problem.basis = basis;
        let fit = lm.minimize(&mut problem, &vec![0.0; searched])?;
        x = problem.state(&fit.theta);
    }
    Ok(x)
}

/// The right singular vectors of `jacobian` whose singular values exceed [`CUTOFF`] of the
/// largest, as columns (none when it is zero or not finite).
fn seen_directions(jacobian: &DMatrix<f64>) -> DMatrix<f64> {
    let n = jacobian.ncols();
    if jacobian.iter().any(|v| !v.is_finite()) {
        return DMatrix::zeros(n, 0);
    }
    // Zero rows make a short fit's Jacobian square, so that its SVD has all n right vectors.
    let j = if jacobian.nrows() < n {
        jacobian.clone().resize_vertically(n, 0.0)
    } else {
        jacobian.clone()
    };
    let svd = j.svd(false, true);
    let smax = svd.singular_values.max();
    let v_t = svd.v_t.as_ref().expect("SVD computed with V");
    let seen: Vec<DVector<f64>> = (0..n)
        .filter(|&i| smax > 0.0 && svd.singular_values[i] > CUTOFF * smax)
        .map(|i| v_t.row(i).transpose())
        .collect();
    if seen.is_empty() {
        DMatrix::zeros(n, 0)
    } else {
        DMatrix::from_columns(&seen)
    }
}

/// The scale of the state for the difference step: the larger of the start and the state the
/// window's input drives it to, 1 when both are zero.
fn scale(start: &[f64], end: &[f64]) -> f64 {
    let s = start.iter().chain(end).fold(0.0_f64, |m, v| m.max(v.abs()));
    if s > 0.0 && s.is_finite() { s } else { 1.0 }
}

/// r(c) = ŷ_F(x⁰ + V_r·c) − y_F over the fitted samples, time-major.
struct StateFit<'a> {
    model: &'a Model,
    maps: &'a [&'a dyn Interpolant],
    /// The input over the fitted samples.
    u: Signal,
    /// The measured output over the fitted samples, time-major.
    y: DVector<f64>,
    /// x⁰.
    origin: Vec<f64>,
    /// V_r, n × r.
    basis: DMatrix<f64>,
    /// The central-difference step in the units of the state.
    step: f64,
}

impl StateFit<'_> {
    fn state(&self, c: &[f64]) -> Vec<f64> {
        let dx = &self.basis * DVector::from_column_slice(c);
        self.origin
            .iter()
            .zip(dx.iter())
            .map(|(a, b)| a + b)
            .collect()
    }

    /// The simulation's final state from `x`, checking that its output is finite.
    fn simulate(&self, x: &[f64]) -> Result<Vec<f64>> {
        let sim = self.model.simulate(self.maps, &self.u, None, Some(x))?;
        if sim.y.as_slice().iter().any(|v| !v.is_finite()) {
            return Err(Error::Numerical(
                "the simulation with the maps in the loop is not finite from the window's \
                 starting state"
                    .into(),
            ));
        }
        Ok(sim.final_state)
    }

    /// ŷ_F(x) − y_F, `None` when the simulation fails or is not finite.
    fn residual_at(&self, x: &[f64]) -> Option<DVector<f64>> {
        let sim = self
            .model
            .simulate(self.maps, &self.u, None, Some(x))
            .ok()?;
        let r = DVector::from_column_slice(sim.y.as_slice()) - &self.y;
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    /// ∂r/∂c at `c` by central differences along each column of V_r.
    fn central_jacobian(&self, c: &[f64]) -> Option<DMatrix<f64>> {
        let x = self.state(c);
        let mut j = DMatrix::zeros(self.y.len(), self.basis.ncols());
        for i in 0..self.basis.ncols() {
            let shifted = |sign: f64| -> Vec<f64> {
                x.iter()
                    .enumerate()
                    .map(|(k, v)| v + sign * self.step * self.basis[(k, i)])
                    .collect()
            };
            let plus = self.residual_at(&shifted(1.0))?;
            let minus = self.residual_at(&shifted(-1.0))?;
            j.set_column(i, &((plus - minus) / (2.0 * self.step)));
        }
        Some(j)
    }
}

impl LeastSquaresProblem for StateFit<'_> {
    fn residuals(&mut self, c: &[f64]) -> Option<DVector<f64>> {
        self.residual_at(&self.state(c))
    }

    fn jacobian(&mut self, c: &[f64], _residuals: &DVector<f64>) -> Option<DMatrix<f64>> {
        self.central_jacobian(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validation::windows::{Scoring, Windows, simulate_scored};
    use crate::{Lft, LftMatrices};
    use nalgebra::dmatrix;
    use proptest::prelude::*;

    pub(crate) fn actuator(z: &[f64]) -> f64 {
        (1.5 * z[0]).tanh()
    }

    pub(crate) fn sensor(z: &[f64]) -> f64 {
        z[0] + 0.1 * z[0].powi(3)
    }

    fn input(len: usize, phase: f64) -> Signal {
        Signal::from_fn(len, 1, |k, _| {
            let t = k as f64;
            (0.05 * t + phase).sin() + 0.6 * (0.31 * t).sin() + 0.3 * (1.7 * t + phase).cos()
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// For any stable second-order G (a complex or real pole pair inside radius 0.95)
        /// and any initial state, the state fitted through the simulation from a start far
        /// from the truth reproduces the noiseless output on the fitted samples, and
        /// windowed scoring of the exact model is at round-off on every scored sample.
        #[test]
        fn the_fitted_state_reproduces_the_noiseless_output(
            radius in 0.2..0.95_f64,
            angle in 0.0..3.0_f64,
            b in prop::array::uniform3(-1.0..1.0_f64),
            x0 in prop::array::uniform2(-2.0..2.0_f64),
            start in prop::array::uniform2(-3.0..3.0_f64),
            phase in 0.0..6.0_f64,
        ) {
            let a = [-2.0 * radius * angle.cos(), radius * radius];
            prop_assume!(b.iter().map(|v| v.abs()).sum::<f64>() > 0.3);
            let model = crate::scenarios::actuator_sensor_series(a, b).unwrap();
            let maps: [&dyn Interpolant; 2] = [&actuator, &sensor];
            let u = input(600, phase);
            let y = model.simulate(&maps, &u, None, Some(&x0)).unwrap().y;
            let scale = crate::validation::metrics::rms(&y.channel(0)).max(1e-3);
            let data = Data::new(u, y).unwrap();
            let x = simulated_window_state(&model, &maps, &data, 0..60, &start).unwrap();
            let fitted = model.simulate(&maps, &data.u().slice(0..60), None, Some(&x)).unwrap().y;
            for k in 0..60 {
                let d = (fitted.get(k, 0) - data.y().get(k, 0)).abs();
                prop_assert!(d < 1e-8 * scale, "sample {}: {} (scale {})", k, d, scale);
            }
            let s = Scoring::Windowed(Windows::new(120, 20).unwrap());
            let win = simulate_scored(&model, &maps, &data, s, None, 0).unwrap();
            let rms = win.rms(data.y(), 0);
            prop_assert!(rms < 1e-8 * scale, "windowed RMS {} (scale {})", rms, scale);
        }
    }

    /// A direction of the state that y does not see keeps its start value, however the
    /// Jacobian's round-off would point: here a third state, mixed into the other two by a
    /// change of coordinates, that feeds nothing.
    #[test]
    fn an_unseen_direction_keeps_its_start_value() {
        let base = crate::scenarios::actuator_sensor_series([-1.5, 0.7], [0.2, 0.1, 0.1]).unwrap();
        let m = base.lft().matrices();
        // x' = T·x with the unseen third state along (1, 1, 1)ᵀ in the new coordinates.
        let t = dmatrix![1.0, 0.0, 1.0; 0.0, 1.0, 1.0; 0.0, 0.0, 1.0];
        let ti = t.clone().try_inverse().unwrap();
        let grow = |x: &DMatrix<f64>, rows: usize, cols: usize| {
            let mut g = DMatrix::zeros(rows, cols);
            g.view_mut((0, 0), (x.nrows(), x.ncols())).copy_from(x);
            g
        };
        let mut a = grow(&m.a, 3, 3);
        a[(2, 2)] = 0.5;
        let lft = Lft::new(LftMatrices {
            a: &t * a * &ti,
            bu: &t * grow(&m.bu, 3, 1),
            be: &t * grow(&m.be, 3, 1),
            bw: &t * grow(&m.bw, 3, 2),
            cy: grow(&m.cy, 1, 3) * &ti,
            dyu: m.dyu.clone(),
            dye: m.dye.clone(),
            dyw: m.dyw.clone(),
            cz: grow(&m.cz, 2, 3) * &ti,
            dzu: m.dzu.clone(),
            dze: m.dze.clone(),
            dzw: m.dzw.clone(),
        })
        .unwrap();
        let model = Model::new(lft, base.blocks().to_vec()).unwrap();
        let maps: [&dyn Interpolant; 2] = [&actuator, &sensor];
        let u = input(300, 0.4);
        let truth = [0.5, -1.0, 0.0];
        let y = model.simulate(&maps, &u, None, Some(&truth)).unwrap().y;
        let data = Data::new(u, y).unwrap();
        let start = [3.0, 2.0, 0.7];
        let x = simulated_window_state(&model, &maps, &data, 0..80, &start).unwrap();
        // The states y cannot tell apart are truth + t·n, n = T·e₃ ∝ (1, 1, 1); the fit keeps
        // the start's component along n and takes the rest from y: x̂ = truth + n·nᵀ·(start −
        // truth) for a unit n.
        let n = DVector::from_element(3, 1.0 / 3f64.sqrt());
        let (truth, start) = (
            DVector::from_row_slice(&truth),
            DVector::from_row_slice(&start),
        );
        let want = &truth + &n * n.dot(&(&start - &truth));
        for i in 0..3 {
            assert!(
                (x[i] - want[i]).abs() < 1e-8,
                "{i}: {} vs {}",
                x[i],
                want[i]
            );
        }
        assert!((n.dot(&(DVector::from_column_slice(&x) - &start))).abs() < 1e-9);
    }
}

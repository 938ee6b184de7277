//! The output-error polish of a named family's parameters.

use nalgebra::{DMatrix, DVector};

use structid_core::Data;
use structid_linear::levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, LmSettings};

use crate::effects::{Effect, EffectFit};
use crate::hypotheses::Hypothesis;

use super::DiscoverSettings;
use super::direction::simulation_residual;

/// Refines a named family's parameters by output error: Levenberg–Marquardt on the
/// estimation record's simulation error with the parametric map in the loop, from the map
/// fit's values, with forward-difference derivatives (a family has at most four parameters).
/// The map fit is to a smoothed estimate; the simulation error weighs each part of the map by
/// how much the data say about it. The 95 % intervals come from s²·(JᵀJ)⁻¹ at the optimum.
/// A family whose parameters move a quantiser's steps is left as fitted (its simulation
/// error is piecewise constant in the step).
pub(super) fn polish(
    fit: &EffectFit,
    h: &Hypothesis,
    est_h: &Data,
    settings: &DiscoverSettings,
) -> EffectFit {
    if fit.effect == Effect::Quantisation {
        return fit.clone();
    }
    let effect = fit.effect;
    let lm_settings = LmSettings::builder()
        .max_iterations(30)
        .tolerance(1e-10)
        .initial_damping(1e-3)
        .damping_increase(4.0)
        .damping_decrease(3.0)
        .min_damping(1e-12)
        .max_damping(f64::INFINITY)
        .max_step_attempts(10)
        .build();
    let mut problem = PolishProblem {
        effect,
        h,
        est_h,
        settings,
    };
    // A start whose simulation fails leaves the map fit as it is.
    let Ok(lm) =
        lm_settings.and_then(|s| LevenbergMarquardt::new(s).minimize(&mut problem, &fit.values()))
    else {
        return fit.clone();
    };
    let cov = lm.covariance(&mut problem);
    let names = effect.parameter_names();
    let parameters = lm
        .theta
        .iter()
        .enumerate()
        .map(|(i, &value)| {
            let half = cov
                .as_ref()
                .map(|cv| 1.96 * cv[(i, i)].max(0.0).sqrt())
                .unwrap_or(f64::INFINITY);
            crate::effects::Parameter {
                name: names[i].clone(),
                value,
                interval: (value - half, value + half),
            }
        })
        .collect();
    EffectFit {
        effect,
        parameters,
        expression: effect.expression(&lm.theta),
        ..fit.clone()
    }
}

/// The output-error problem of [`polish`]: the simulation residual of the estimation record
/// with the family's map in the loop; a θ whose simulation fails is rejected.
pub(super) struct PolishProblem<'a> {
    effect: Effect,
    h: &'a Hypothesis,
    est_h: &'a Data,
    settings: &'a DiscoverSettings,
}

impl LeastSquaresProblem for PolishProblem<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        let effect = self.effect;
        let map = |z: &[f64]| effect.eval(theta, z[0]);
        simulation_residual(
            &self.h.model,
            self.h.location,
            &map,
            self.est_h,
            self.settings,
        )
        .map(DVector::from_vec)
    }

    /// Forward differences (a family has at most four parameters, each costs a simulation).
    fn jacobian(&mut self, theta: &[f64], r: &DVector<f64>) -> Option<DMatrix<f64>> {
        let mut j = DMatrix::zeros(r.len(), theta.len());
        for i in 0..theta.len() {
            let step = 1e-6 * theta[i].abs().max(1e-3);
            let mut t = theta.to_vec();
            t[i] += step;
            let ri = self.residuals(&t)?;
            for k in 0..r.len() {
                j[(k, i)] = (ri[k] - r[k]) / step;
            }
        }
        Some(j)
    }
}

//! Validation simulation error by refitting.

use crate::error::{Error, Result};
use crate::identify::{Identification, IdentifySettings, identify_problem};
use crate::model::{Data, Model};
use crate::problem::Problem;
use crate::simulate::MapBinding;

use super::score::BetaScore;

/// Validation simulation error by refitting.
pub(super) struct ValidationScore<'a> {
    pub(super) problem: Problem,
    pub(super) model: Model,
    pub(super) validation: &'a Data,
    pub(super) settings: IdentifySettings,
}

/// Mean squared error of simulating `model` with `id`'s maps in the loop on `data` (zero
/// initial state, e = 0).
pub(crate) fn simulation_mse(model: &Model, id: &Identification, data: &Data) -> Result<f64> {
    data.require_single_record("the validation record of the selection")?;
    let bindings: Vec<MapBinding<'_>> = model
        .blocks()
        .iter()
        .zip(&id.blocks)
        .map(|(b, est)| MapBinding {
            inputs: &b.inputs,
            output: b.output,
            map: est.map.as_ref(),
        })
        .collect();
    let sim = model.lft().simulate(&bindings, data.u(), None, None)?;
    let (y, ys) = (data.y().as_slice(), sim.y.as_slice());
    let mse = y
        .iter()
        .zip(ys)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        / y.len() as f64;
    if !mse.is_finite() {
        return Err(Error::Numerical(
            "the validation simulation diverged (non-finite output)".into(),
        ));
    }
    Ok(mse)
}

impl BetaScore for ValidationScore<'_> {
    fn score(&mut self, beta: f64) -> Result<(f64, Option<f64>)> {
        let id = identify_problem(&self.problem, &self.settings.with_beta(beta)?)?.converged()?;
        Ok((simulation_mse(&self.model, &id, self.validation)?, None))
    }

    fn method(&self) -> String {
        format!(
            "validation simulation error on {} samples (one fit and one simulation per β)",
            self.validation.len()
        )
    }
}

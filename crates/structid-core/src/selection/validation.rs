//! Validation simulation error by refitting.

use crate::error::{Error, Result};
use crate::identify::problem::Problem;
use crate::identify::{Identification, IdentifySettings, identify_problem};
use crate::model::simulate::MapBinding;
use crate::model::{Data, Model};

use super::score::BetaScore;

/// Validation simulation error by refitting.
pub(super) struct ValidationScore<'a> {
    pub(super) problem: Problem,
    pub(super) model: Model,
    pub(super) validation: &'a Data,
    pub(super) settings: IdentifySettings,
}

/// Mean squared error of simulating `model` with `id`'s maps in the loop on `data` (each
/// record from a zero initial state, e = 0), pooled over the samples of every record.
pub(crate) fn simulation_mse(model: &Model, id: &Identification, data: &Data) -> Result<f64> {
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
    let pooled = crate::validation::simulate_records_from_rest(model.lft(), &bindings, data, 0)?;
    let mse = pooled.rms().powi(2);
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
            "validation simulation error on {} samples{} (one fit and one simulation per β)",
            self.validation.len(),
            match self.validation.record_count() {
                1 => String::new(),
                n => format!(" of {n} records, each simulated from rest"),
            }
        )
    }
}

//! The commands that read a stored estimate (estimate.json): `simulate --estimate FILE.json`
//! and `predict` (`validate --estimate FILE.json` is in [`crate::validate`]); the workflows are
//! [`structid_workflow::stored`]'s.

use std::path::Path;

use structid_workflow::stored::{PredictRequest, SimulateStored};

use crate::error::CliError;
use crate::{PredictArgs, SimulateArgs};

/// `structid simulate --estimate FILE.json`.
pub fn simulate(a: &SimulateArgs, path: &Path, noise_std: f64) -> Result<(), CliError> {
    let text = structid_workflow::stored::simulate_stored(&SimulateStored {
        estimate: path,
        input: &a.input,
        out: &a.out,
        noise_std,
        seed: a.seed,
        vars: crate::data::vars(),
    })?;
    print!("{text}");
    Ok(())
}

/// `structid predict`.
pub fn predict(a: PredictArgs) -> Result<(), CliError> {
    let text = structid_workflow::stored::predict(&PredictRequest {
        estimate: &a.estimate,
        data: &a.data,
        horizon: a.horizon,
        out: &a.out,
        initial_state: a.initial_state.into(),
        settle: a.settle,
        vars: crate::data::vars(),
    })?;
    print!("{text}");
    Ok(())
}

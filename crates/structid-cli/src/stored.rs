//! `structid predict`, which reads a stored estimate (estimate.json); `simulate --estimate` is
//! in [`crate::simulate`] and `validate --estimate` in [`crate::validate`]. The workflows are
//! [`structid_workflow::stored`]'s.

use structid_workflow::stored::PredictRequest;

use crate::PredictArgs;
use crate::error::CliError;

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

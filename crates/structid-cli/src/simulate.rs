//! `structid simulate` ([`structid_workflow::simulate`], or with a stored estimate
//! [`structid_workflow::stored`]).

use structid_workflow::simulate::{SimulateRequest, simulate_to_csv};

use crate::SimulateArgs;
use crate::error::CliError;

/// Runs `structid simulate`.
pub fn run(a: SimulateArgs) -> Result<(), CliError> {
    let noise_std = crate::error::noise_std("--noise-std", a.noise_std)?;
    let model_path = match (&a.model, &a.estimate) {
        (_, Some(e)) => return crate::stored::simulate(&a, e, noise_std),
        (Some(m), None) => m.clone(),
        (None, None) => {
            return Err(CliError::input(
                "give --model MODEL.toml or --estimate FILE.json",
            ));
        }
    };
    let text = simulate_to_csv(&SimulateRequest {
        model: &model_path,
        input: &a.input,
        out: &a.out,
        noise_std,
        seed: a.seed,
        vars: crate::data::vars(),
    })?;
    print!("{text}");
    Ok(())
}

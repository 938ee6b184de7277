//! `structid simulate` ([`structid_workflow::simulate`]).

use structid_workflow::simulate::{SimulateRequest, SimulationSource, simulate};

use crate::SimulateArgs;
use crate::error::CliError;

/// Runs `structid simulate`.
pub fn run(a: SimulateArgs) -> Result<(), CliError> {
    let noise_std = crate::error::noise_std("--noise-std", a.noise_std)?;
    let source = match (&a.model, &a.estimate) {
        (_, Some(e)) => SimulationSource::Estimate(e),
        (Some(m), None) => SimulationSource::ModelFile(m),
        (None, None) => {
            return Err(CliError::input(
                "give --model MODEL.toml or --estimate FILE.json",
            ));
        }
    };
    let text = simulate(&SimulateRequest {
        source,
        input: &a.input,
        out: &a.out,
        noise_std,
        seed: a.seed,
        vars: crate::data::vars(),
    })?;
    print!("{text}");
    Ok(())
}

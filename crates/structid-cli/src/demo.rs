//! `structid demo`: the paper's examples end to end ([`structid_workflow::demo`]).

use structid_workflow::demo::{self, DemoRequest};

use crate::error::CliError;
use crate::{MultiInputArgs, SprayArgs};

/// Runs `structid demo spray`.
pub fn spray(a: SprayArgs) -> Result<(), CliError> {
    let text = demo::spray(&DemoRequest {
        out: &a.out,
        samples: a.samples,
        seed: a.seed,
    })?;
    print!("{text}");
    println!(
        "re-run the identification with:\n  structid identify --model {} --data {} --out {}",
        a.out.join("model.toml").display(),
        a.out.join("data.csv").display(),
        a.out.join("identify").display()
    );
    Ok(())
}

/// Runs `structid demo multi-input`.
pub fn multi_input(a: MultiInputArgs) -> Result<(), CliError> {
    let noise_std = crate::error::noise_std("--noise-std", a.noise_std)?;
    let text = demo::multi_input(
        &DemoRequest {
            out: &a.out,
            samples: a.samples,
            seed: a.seed,
        },
        noise_std,
    )?;
    print!("{text}");
    Ok(())
}

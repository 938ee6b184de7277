//! The errors of discovery: those of the identification, simulation and validation it runs
//! ([`structid_core::Error`]), and the refusals of its own.

/// Why [`discover`](crate::discover::discover) or
/// [`discover_effects`](crate::discover::discover_effects) could not run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DiscoverError {
    /// An error of the identification, simulation or validation underneath (bad records, a
    /// malformed nominal model, a solver that failed).
    #[error(transparent)]
    Core(#[from] structid_core::Error),

    /// The nominal model simulates a record far worse than a constant (by more than
    /// [`WORSE_THAN_CONSTANT`](crate::discover::WORSE_THAN_CONSTANT)) or diverges: its gap
    /// would measure the nominal model, not a missing effect. `model_rms` is infinite for a
    /// simulation that diverged.
    #[error(
        "the nominal model is not usable on the {record} record: {}; check its units, its \
         sign, its input delay and any offset in the data, or estimate a linear model from the \
         data (output error, with integrators held for a plant that integrates)",
        poor_nominal_text(*.model_rms, *.constant_rms, .scoring)
    )]
    PoorNominal {
        /// Which record (`estimation`).
        record: String,
        /// The simulation RMS of the nominal model (infinite when it diverged).
        model_rms: f64,
        /// The RMS of y about its mean: what a constant achieves.
        constant_rms: f64,
        /// How the simulation was scored (`one free run` or `windows`).
        scoring: &'static str,
    },
}

/// Result alias of `structid-discover`'s entry points.
pub type Result<T, E = DiscoverError> = std::result::Result<T, E>;

fn poor_nominal_text(model: f64, constant: f64, scoring: &str) -> String {
    if model.is_finite() {
        format!(
            "its simulation ({scoring}) has RMS {model:.4e}, {:.1}× the RMS {constant:.4e} of \
             y about its mean: it is worse than a constant (the mean of y)",
            model / constant.max(f64::MIN_POSITIVE)
        )
    } else {
        format!("its simulation ({scoring}) diverged (y about its mean has RMS {constant:.4e})")
    }
}

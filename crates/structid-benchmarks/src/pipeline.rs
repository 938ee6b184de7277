//! Building blocks shared by the measured-benchmark pipelines ([`crate::silverbox`],
//! [`crate::tanks`]).

use std::sync::Arc;

use structid_core::refine::RefineSettings;
use structid_core::selection::{Criterion, SelectionSettings};
use structid_core::{
    Data, Dispersion, Error, FourierDispersion, FourierWeights, IdentifySettings, InitialState,
    PolynomialDispersion, Result, SumDispersion,
};
use structid_io::IoError;
use structid_linear::{OeSettings, PolynomialModel};

pub(crate) fn io(e: IoError) -> Error {
    Error::InvalidStructure(e.to_string())
}

fn linear(e: structid_linear::LinearError) -> Error {
    Error::InvalidStructure(format!("linear estimation: {e}"))
}

/// max − min.
pub(crate) fn range(v: &[f64]) -> f64 {
    let (lo, hi) = v
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
            (l.min(x), h.max(x))
        });
    hi - lo
}

/// RMS of `sim − y` from sample `from` on; infinite when it is not finite.
pub(crate) fn rms_from(sim: &[f64], y: &[f64], from: usize) -> f64 {
    let n = y.len().saturating_sub(from).max(1);
    let r = (sim[from..]
        .iter()
        .zip(&y[from..])
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        / n as f64)
        .sqrt();
    if r.is_finite() { r } else { f64::INFINITY }
}

/// A polynomial map of `degree` (monomial weight `scale`), plus a Gaussian-like Fourier kernel
/// of width `kernel_sigma` when one is given.
pub(crate) fn map_dispersion(
    degree: usize,
    scale: f64,
    kernel_sigma: Option<f64>,
) -> Result<Arc<dyn Dispersion>> {
    let trend = Arc::new(PolynomialDispersion::new(degree)?.with_scale(scale)?);
    let Some(sigma) = kernel_sigma else {
        return Ok(trend);
    };
    let kernel = FourierDispersion::new(FourierWeights::GaussianLike { sigma })?;
    Ok(Arc::new(SumDispersion::new(vec![Arc::new(kernel), trend])?))
}

/// Refinement with β by marginal likelihood on the first pass, x₀ estimated in both steps and
/// output error to a relative decrease of 1e-7.
pub(crate) fn refine_settings(
    max_iterations: usize,
    tolerance: f64,
    settle: usize,
    sample_time: f64,
    tune_sigma: bool,
    posterior: bool,
) -> Result<RefineSettings> {
    let identify = IdentifySettings::builder()
        .initial_state(InitialState::Estimate)
        .posterior(posterior)
        .build()?;
    let selection = SelectionSettings::builder()
        .criterion(Criterion::MarginalLikelihood)
        .tune_sigma(tune_sigma)
        .build()?;
    let oe = OeSettings::builder()
        .sample_time(sample_time)
        .tolerance(1e-7)
        .build()
        .map_err(linear)?;
    RefineSettings::builder()
        .max_iterations(max_iterations)
        .tolerance(tolerance)
        .identify(identify)
        .selection(Some(selection))
        .oe(oe)
        .settle(settle)
        .build()
}

/// The BLA of order n (na = nb = n, nk = 1): ARX, then output error with a free initial state.
pub(crate) fn bla(data: &Data, order: usize, sample_time: f64) -> Result<PolynomialModel> {
    structid_core::refine::best_linear_approximation(data, order, sample_time)
}

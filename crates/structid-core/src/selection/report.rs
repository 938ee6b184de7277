//! What a selection reports: the trials, the chosen values and the fit there.

use crate::identify::Identification;
use crate::model::Model;

use super::settings::Criterion;

/// One evaluation of the criterion.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Trial {
    /// β tried.
    pub beta: f64,
    /// The width of the first block that has one, when σ is tuned.
    pub sigma: Option<f64>,
    /// The criterion's value (lower is better).
    pub value: f64,
}

/// The outcome of [`select`](super::select): the chosen values, how they were found, and the fit there.
#[derive(Debug)]
pub struct Selection {
    /// The chosen β.
    pub beta: f64,
    /// The chosen width of the first block that has one (`None` when σ was not tuned).
    pub sigma: Option<f64>,
    /// The chosen width of every block (`None` for blocks without one), in model order.
    pub widths: Vec<Option<f64>>,
    /// The criterion used.
    pub criterion: Criterion,
    /// How the criterion was evaluated (path, ranks, search).
    pub method: String,
    /// Every trial in the order evaluated.
    pub curve: Vec<Trial>,
    /// The noise variance s² implied at the choice (marginal likelihood and GCV: ŝ² =
    /// L·β·rᵀM⁻¹r/n); `None` for the refitting criteria.
    pub noise_variance: Option<f64>,
    /// Wall-clock seconds for the selection and the final fit.
    pub seconds: f64,
    /// The identification at the chosen values.
    pub identification: Identification,
    /// The model with the chosen widths.
    pub model: Model,
}

/// The chosen β with the criterion at every trial ([`select_beta`](super::select_beta)).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BetaSelection {
    /// The minimiser found.
    pub beta: f64,
    /// The criterion used.
    pub criterion: Criterion,
    /// (β, criterion value) at every trial, in the order evaluated.
    pub curve: Vec<(f64, f64)>,
    /// The noise variance s² implied at the chosen β (ŝ² = L·β·rᵀM⁻¹r/n).
    pub noise_variance: f64,
}

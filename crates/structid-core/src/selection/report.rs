//! What a selection reports: the trials, the chosen values and the fit there.

use crate::identify::Identification;
use crate::model::Model;

use super::settings::Criterion;

/// Which end of a search interval a selected value lies on.
///
/// A β (or σ) chosen at a bound of its search is not a minimiser of the criterion but the
/// edge of where it was looked for: at the lower bound of β the estimate follows the noise
/// (overfitting), at the upper bound the data do not support a map that differs from the
/// dispersion's null space (a constant, or the trend). Either is a failed selection.
///
/// ```
/// use structid_core::selection::Bound;
/// assert_eq!(Bound::Lower.to_string(), "lower");
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    /// The lower end of the search interval.
    Lower,
    /// The upper end of the search interval.
    Upper,
}

impl std::fmt::Display for Bound {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Bound::Lower => "lower",
            Bound::Upper => "upper",
        })
    }
}

impl Bound {
    /// The bound that `x` lies on within `bounds = (lo, hi)` (relative tolerance 1e-9 of the
    /// interval's width), if any.
    pub(crate) fn of(x: f64, bounds: (f64, f64)) -> Option<Bound> {
        let tol = 1e-9 * (bounds.1 - bounds.0).abs().max(f64::MIN_POSITIVE);
        if (x - bounds.0).abs() <= tol {
            Some(Bound::Lower)
        } else if (x - bounds.1).abs() <= tol {
            Some(Bound::Upper)
        } else {
            None
        }
    }
}

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
    /// The bound of [`SelectionSettings::beta_bounds`](super::SelectionSettings) that the
    /// chosen β lies on, if any (`None` too when β was not tuned): a failed selection, see
    /// [`Bound`]. A criterion that is flat (relative 10⁻⁶) from the choice to the largest or
    /// smallest β tried counts as that bound: the search stopped on a plateau that reaches
    /// towards it.
    pub beta_at_bound: Option<Bound>,
    /// The bound of the σ search (±`sigma_decades` around the dispersion's width) that the
    /// chosen σ lies on, if any (`None` too when σ was not tuned).
    pub sigma_at_bound: Option<Bound>,
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

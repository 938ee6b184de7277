//! The criterion as a function of β, and the ML/GCV formulas shared by the feature and dense paths.

use crate::error::{Error, Result};

use super::settings::Criterion;

/// A criterion as a function of β for fixed everything else.
pub(super) trait BetaScore {
    /// The criterion at β and, for the likelihood-based criteria, the implied s².
    fn score(&mut self, beta: f64) -> Result<(f64, Option<f64>)>;
    /// How it is evaluated, for the report.
    fn method(&self) -> String;
}

/// ML or GCV from the eigendecomposition A = U·S·Uᵀ of the k×k matrix of a factor V
/// (M' = V·Vᵀ + L·β·I in whitened rows), h = Uᵀ·Vᵀ·r', rr = |r'|²; `logdet_a` = ln det A.
pub(super) fn factored_value(
    s: &[f64],
    h: &[f64],
    rr: f64,
    n: usize,
    lb: f64,
    logdet_a: f64,
    criterion: Criterion,
) -> Result<(f64, f64)> {
    let k = s.len();
    let nf = n as f64;
    let mut quad_sum = 0.0;
    // k may exceed n (more features than rows): VᵀV then has k − n zero eigenvalues whose
    // terms cancel the negative n − k exactly
    let rows_minus_k = n as f64 - k as f64;
    let mut logdet = rows_minus_k * lb.ln();
    let mut fitted = 0.0;
    let mut trace = rows_minus_k;
    for j in 0..k {
        let sj = s[j].max(0.0);
        let d = sj + lb;
        let h2 = h[j] * h[j];
        quad_sum += h2 / d;
        logdet += d.ln();
        fitted += sj * h2 / (d * d);
        trace += lb / d;
    }
    // rᵀM⁻¹r in the original units (A⁻¹-weighted)
    let quad = (rr - quad_sum) / lb;
    let s2 = lb * quad / nf;
    let value = match criterion {
        Criterion::MarginalLikelihood => 0.5 * nf * (quad / nf).ln() + 0.5 * (logdet + logdet_a),
        _ => {
            let rss = rr - 2.0 * quad_sum + fitted;
            nf * rss / (trace * trace)
        }
    };
    if !(value.is_finite() && quad > 0.0) {
        return Err(Error::Numerical(format!(
            "the {} criterion is not finite at L·β = {:.3e} (rᵀM⁻¹r = {quad:.3e})",
            criterion.describe(),
            lb
        )));
    }
    Ok((value, s2))
}

pub(super) fn free_state_unsupported() -> Error {
    Error::Unsupported(
        "marginal likelihood and GCV with an estimated initial state are not supported; use cross-validation or validation selection, or a zero initial state"
            .into(),
    )
}

//! The initial state of the linear block: how it is treated ([`InitialState`]) and its
//! least-squares estimate from a free response ([`estimate_initial_state`]).
//!
//! Identification ([`crate::identify()`]), validation ([`crate::validate`]) and prediction
//! ([`crate::estimate::predict`]) share the enum. The estimate is the one of validation and
//! prediction (x₀ given the maps) and of the output-error start in [`crate::refine`]; the
//! solvers estimate x₀ jointly with the maps inside their own normal equations instead.

use faer::{Mat, MatRef};
use nalgebra::{DMatrix, DVector};
use structid_lti::kalman::KalmanWhitener;

use crate::error::{Error, Result};

/// How the initial state x₀ of the LFT's linear block is treated.
///
/// ```
/// use structid_core::InitialState;
/// assert_eq!(InitialState::default(), InitialState::Zero);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum InitialState {
    /// The record starts at rest, x₀ = 0 (the paper's assumption).
    #[default]
    Zero,
    /// x₀ is estimated: in identification as unpenalised parameters together with the maps
    /// (real records rarely start at rest); in validation and prediction, with the maps
    /// fixed, by generalised least squares from the one-step residual
    /// ([`estimate_initial_state`], see [`crate::validation`]).
    Estimate,
}

/// x̂₀ = argmin ‖W·(v − O·x₀)‖² by SVD, where the columns of `o` (rows × n) are the free
/// responses of the n unit initial states and `v` (rows) the residual they should explain;
/// W is the Kalman whitening operator of the noise path (generalised least squares) or the
/// identity (ordinary least squares) without a whitener. Singular values below
/// 10⁻¹²·σ_max count as zero, so directions of x₀ that O does not resolve get the
/// minimum-norm value (0); an all-zero O gives x̂₀ = 0.
///
/// Errors when `v` does not have one value per row of `o`, when the whitener is for another
/// number of rows, or when the (whitened) free response or residual is not finite.
///
/// ```
/// use faer::Mat;
/// use structid_core::initial_state::estimate_initial_state;
/// // y_k = 0.5^k·x₀ observed with x₀ = 2; the second state does not reach y.
/// let o = Mat::from_fn(5, 2, |k, j| if j == 0 { 0.5f64.powi(k as i32) } else { 0.0 });
/// let v: Vec<f64> = (0..5).map(|k| 2.0 * 0.5f64.powi(k)).collect();
/// let x0 = estimate_initial_state(o.as_ref(), &v, None).unwrap();
/// assert!((x0[0] - 2.0).abs() < 1e-12 && x0[1] == 0.0);
/// ```
pub fn estimate_initial_state(
    o: MatRef<'_, f64>,
    v: &[f64],
    whitener: Option<&KalmanWhitener>,
) -> Result<Vec<f64>> {
    let (rows, n) = (o.nrows(), o.ncols());
    if v.len() != rows {
        return Err(Error::DimensionMismatch {
            what:
                "residual for the initial-state estimate (one value per row of the free response)"
                    .into(),
            expected: rows.to_string(),
            found: v.len().to_string(),
        });
    }
    if let Some(w) = whitener
        && w.len() * w.outputs() != rows
    {
        return Err(Error::DimensionMismatch {
            what: "rows of the free response for the whitener (len · outputs)".into(),
            expected: (w.len() * w.outputs()).to_string(),
            found: rows.to_string(),
        });
    }
    let (ow, vw) = match whitener {
        Some(w) => {
            let mut ow = Mat::<f64>::zeros(rows, n);
            w.whiten_columns(o, ow.as_mut());
            let mut vw = vec![0.0; rows];
            w.whiten(v, &mut vw);
            (ow, vw)
        }
        None => (o.to_owned(), v.to_vec()),
    };
    let a = DMatrix::from_fn(rows, n, |i, j| ow[(i, j)]);
    if a.iter().chain(&vw).any(|x| !x.is_finite()) {
        return Err(Error::Numerical(
            "the whitened free response is not finite; the initial state cannot be estimated on this \
             record (is the noise model's predictor unstable?)"
                .into(),
        ));
    }
    let svd = a.svd(true, true);
    let smax = svd.singular_values.max();
    if smax == 0.0 {
        // No state reaches y: x₀ is irrelevant.
        return Ok(vec![0.0; n]);
    }
    let x = svd
        .solve(&DVector::from_vec(vw), 1e-12 * smax)
        .map_err(|e| Error::Numerical(format!("least squares for the initial state: {e}")))?;
    Ok(x.iter().copied().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_and_errors() {
        // Two states observed through y_k = x₀₁·0.9^k + x₀₂·(−0.5)^k, plus an exact fit.
        let o = Mat::from_fn(30, 2, |k, j| [0.9f64, -0.5][j].powi(k as i32));
        let v: Vec<f64> = (0..30)
            .map(|k| 1.5 * 0.9f64.powi(k) - 2.0 * (-0.5f64).powi(k))
            .collect();
        let x0 = estimate_initial_state(o.as_ref(), &v, None).unwrap();
        assert!((x0[0] - 1.5).abs() < 1e-12 && (x0[1] + 2.0).abs() < 1e-12);
        assert!(matches!(
            estimate_initial_state(o.as_ref(), &v[..29], None),
            Err(Error::DimensionMismatch { .. })
        ));
        let mut bad = v.clone();
        bad[3] = f64::NAN;
        assert!(matches!(
            estimate_initial_state(o.as_ref(), &bad, None),
            Err(Error::Numerical(_))
        ));
        let zero = Mat::<f64>::zeros(30, 2);
        assert_eq!(
            estimate_initial_state(zero.as_ref(), &v, None).unwrap(),
            vec![0.0, 0.0]
        );
    }
}

//! The low-rank Gaussian: finitely many features for the Gaussian kernel, from a pivoted
//! (partial) Cholesky factorisation of its Gram matrix, i.e. the Nyström approximation.
//!
//! Greedy pivoting on the residual diagonal picks k points z_P until the trace of the residual
//! K − K̃ is at most `tolerance · trace(K)`. The features are φ(z) = L_PP⁻¹·k(z_P, z), with L_PP
//! the pivot rows of the partial factor, so K̃(z₁, z₂) = φ(z₁)ᵀφ(z₂) reproduces the factor at
//! the data and extends it to any z (Nyström). K − K̃ is positive semi-definite, so
//! ‖K − K̃‖₂ ≤ trace(K − K̃) ≤ tolerance · trace(K): the bound the tests use.
//!
//! Pivots are chosen among at most `max_candidates` samples (evenly spaced through the record)
//! so that building the features costs O(candidates · k²) however long the record is.

use std::sync::Arc;

use nalgebra::DMatrix;
use structid_lti::Signal;

use crate::dispersion::fourier::FeaturePenalty;
use crate::dispersion::kernel::{GaussianKernel, Kernel};
use crate::dispersion::{Dispersion, FeatureMap, Penalty};
use crate::error::{Error, Result, positive_finite};

/// A Gaussian dispersion approximated by k ≪ L Nyström features (any number of inputs).
///
/// ```
/// use structid_core::{Dispersion, LowRankGaussian};
/// let d = LowRankGaussian::new(0.3, 1e-8).unwrap();
/// assert!(d.describe().starts_with("low-rank gaussian"));
/// assert!(LowRankGaussian::new(0.3, 0.0).is_err());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct LowRankGaussian {
    kernel: GaussianKernel,
    tolerance: f64,
    max_rank: usize,
    max_candidates: usize,
}

impl LowRankGaussian {
    /// Width σ and relative trace tolerance (0 < tolerance < 1); at most 512 features and 20 000
    /// candidate points by default.
    pub fn new(sigma: f64, tolerance: f64) -> Result<Self> {
        let tolerance = positive_finite("tolerance", tolerance)?;
        if tolerance >= 1.0 {
            return Err(Error::InvalidParameter {
                name: "tolerance".into(),
                value: tolerance,
                reason: "the relative trace tolerance must be below 1".into(),
            });
        }
        Ok(Self {
            kernel: GaussianKernel::new(sigma)?,
            tolerance,
            max_rank: 512,
            max_candidates: 20_000,
        })
    }

    /// Caps the number of features.
    pub fn with_max_rank(mut self, k: usize) -> Self {
        self.max_rank = k.max(1);
        self
    }

    /// Builds the features for the sample points `z`.
    pub fn features_for(&self, z: &Signal) -> Result<NystromFeatures> {
        let len = z.len();
        if len == 0 {
            return Err(Error::InvalidStructure(
                "no samples to build low-rank features from".into(),
            ));
        }
        let step = len.div_ceil(self.max_candidates.max(1)).max(1);
        let cand: Vec<usize> = (0..len).step_by(step).collect();
        let nc = cand.len();
        let p = z.channels();
        let c0 = self.kernel.normalisation(p);
        let mut resid = vec![c0; nc];
        let total = c0 * nc as f64;
        let mut cols: Vec<Vec<f64>> = Vec::new(); // partial factor columns over the candidates
        let mut piv: Vec<usize> = Vec::new();
        while piv.len() < self.max_rank.min(nc) {
            let left: f64 = resid.iter().sum();
            if left <= self.tolerance * total {
                break;
            }
            let (j, &dj) = resid
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .expect("non-empty");
            if dj <= 0.0 {
                break;
            }
            let zj = z.sample(cand[j]);
            let mut col: Vec<f64> = cand
                .iter()
                .map(|&i| self.kernel.eval(z.sample(i), zj))
                .collect();
            for prev in &cols {
                let f = prev[j];
                col.iter_mut().zip(prev).for_each(|(c, p)| *c -= f * p);
            }
            let s = dj.sqrt();
            col.iter_mut().for_each(|c| *c /= s);
            for (r, c) in resid.iter_mut().zip(&col) {
                *r = (*r - c * c).max(0.0);
            }
            resid[j] = 0.0;
            cols.push(col);
            piv.push(j);
        }
        let k = piv.len();
        let l_pp = DMatrix::from_fn(k, k, |a, b| if b <= a { cols[b][piv[a]] } else { 0.0 });
        let centres = Signal::from_fn(k, p, |a, c| z.get(cand[piv[a]], c));
        Ok(NystromFeatures {
            kernel: self.kernel,
            centres,
            l_pp,
            weights: vec![1.0; k],
            trace_error: resid.iter().sum::<f64>() / total,
        })
    }
}

impl Dispersion for LowRankGaussian {
    fn describe(&self) -> String {
        format!(
            "low-rank gaussian(sigma={}, tolerance={})",
            self.kernel.sigma(),
            self.tolerance
        )
    }

    fn parameters(&self) -> Vec<(String, f64)> {
        vec![
            ("sigma".into(), self.kernel.sigma()),
            ("tolerance".into(), self.tolerance),
        ]
    }

    fn width(&self) -> Option<f64> {
        Some(self.kernel.sigma())
    }

    fn with_width(&self, width: f64) -> Option<Result<Arc<dyn Dispersion>>> {
        Some(GaussianKernel::new(width).map(|kernel| {
            Arc::new(Self {
                kernel,
                ..self.clone()
            }) as Arc<dyn Dispersion>
        }))
    }

    fn penalty(&self, z: &Signal) -> Result<Penalty> {
        Ok(FeaturePenalty::of(self.features_for(z)?, z))
    }
}

/// Nyström features φ(z) = L_PP⁻¹·k(z_P, z) of a Gaussian kernel.
#[derive(Clone, Debug)]
pub struct NystromFeatures {
    kernel: GaussianKernel,
    centres: Signal,
    l_pp: DMatrix<f64>,
    weights: Vec<f64>,
    trace_error: f64,
}

impl NystromFeatures {
    /// trace(K − K̃)/trace(K) over the candidate points when the factorisation stopped.
    pub fn relative_trace_error(&self) -> f64 {
        self.trace_error
    }

    fn to_stored(&self) -> crate::stored::StoredKernel {
        let r = self.l_pp.nrows();
        crate::stored::StoredKernel::Nystrom(crate::stored::NystromStored {
            sigma: self.kernel.sigma(),
            centres: crate::stored::StoredPoints::from_signal(&self.centres),
            l_pp: (0..r * r).map(|i| self.l_pp[(i / r, i % r)]).collect(),
            weights: self.weights.clone(),
            trace_error: self.trace_error,
        })
    }

    /// The features from their stored numbers, checked for consistent sizes.
    pub(crate) fn from_stored(s: &crate::stored::NystromStored) -> Result<Self> {
        let r = s.weights.len();
        let centres = s.centres.to_signal()?;
        if centres.len() < r || s.l_pp.len() != r * r || (0..r).any(|i| s.l_pp[i * r + i] == 0.0) {
            return Err(Error::InconsistentStored {
                item: "Nyström features".into(),
                detail: format!(
                    "rank {r}, {} centres and a factor of {} values do not fit together",
                    centres.len(),
                    s.l_pp.len()
                ),
            });
        }
        Ok(Self {
            kernel: GaussianKernel::new(s.sigma)?,
            centres,
            l_pp: DMatrix::from_row_slice(r, r, &s.l_pp),
            weights: s.weights.clone(),
            trace_error: s.trace_error,
        })
    }
}

impl FeatureMap for NystromFeatures {
    fn stored_features(&self) -> Option<crate::stored::StoredKernel> {
        Some(self.to_stored())
    }

    fn dim(&self) -> usize {
        self.weights.len()
    }

    fn weights(&self) -> &[f64] {
        &self.weights
    }

    fn eval_into(&self, z: &[f64], out: &mut [f64]) {
        let k = self.weights.len();
        for a in 0..k {
            let mut v = self.kernel.eval(self.centres.sample(a), z);
            for b in 0..a {
                v -= self.l_pp[(a, b)] * out[b];
            }
            out[a] = v / self.l_pp[(a, a)];
        }
    }
}

impl Kernel for NystromFeatures {
    fn stored_kernel(&self) -> Option<crate::stored::StoredKernel> {
        Some(self.to_stored())
    }

    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        let k = self.weights.len();
        let (mut pa, mut pb) = (vec![0.0; k], vec![0.0; k]);
        self.eval_into(a, &mut pa);
        self.eval_into(b, &mut pb);
        pa.iter().zip(&pb).map(|(x, y)| x * y).sum()
    }

    fn describe(&self) -> String {
        format!(
            "nystrom-gaussian(sigma={}, rank={})",
            self.kernel.sigma(),
            self.weights.len()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nystrom_reproduces_the_gram_matrix_within_the_trace_tolerance() {
        for p in [1, 2] {
            let z = Signal::from_fn(300, p, |i, c| {
                (((i * 37 + c * 11) % 101) as f64 / 50.0) - 1.0
            });
            let g = GaussianKernel::new(0.4).unwrap();
            let lr = LowRankGaussian::new(0.4, 1e-10).unwrap();
            let f = lr.features_for(&z).unwrap();
            assert!(f.relative_trace_error() <= 1e-10);
            assert!(f.dim() < 300, "rank {}", f.dim());
            let trace = g.normalisation(p) * 300.0;
            let mut err_trace = 0.0;
            for i in 0..300 {
                let d = g.eval(z.sample(i), z.sample(i)) - f.eval(z.sample(i), z.sample(i));
                assert!(d >= -1e-9, "K − K̃ must be PSD: diagonal {d}");
                err_trace += d;
                for j in (0..300).step_by(7) {
                    let e =
                        (g.eval(z.sample(i), z.sample(j)) - f.eval(z.sample(i), z.sample(j))).abs();
                    // |E_ij| ≤ √(E_ii E_jj) ≤ trace(E).
                    assert!(e <= 1e-10 * trace + 1e-12, "entry error {e}");
                }
            }
            assert!(err_trace <= 1e-10 * trace * 1.0001 + 1e-12);
        }
    }
}

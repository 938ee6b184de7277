//! Marginal likelihood and GCV in feature space, from one pass over the record.

use nalgebra::{DMatrix, DVector};

use crate::dispersion::Penalty;
use crate::error::Result;
use crate::identify::problem::Problem;
use crate::solver::features::{FeatureGram, gram};

use super::score::{BetaScore, factored_value, free_state_unsupported};
use super::settings::Criterion;

/// ML/GCV in feature space from one pass over the record.
pub(super) struct FeatureScore {
    gram: FeatureGram,
    /// the weights λ in use (feature order)
    lambda: Vec<f64>,
    /// per block: the width the weights belong to
    widths: Vec<Option<f64>>,
    /// eigenvalues of A and h, for `lambda`
    eig: (Vec<f64>, Vec<f64>),
    n: usize,
    len: usize,
    logdet_a: f64,
}

impl FeatureScore {
    pub(super) fn new(problem: &Problem) -> Result<Self> {
        if problem.free_response().is_some() {
            return Err(free_state_unsupported());
        }
        let gram = gram(problem, false, None)?;
        let lambda: Vec<f64> = gram
            .maps
            .iter()
            .flat_map(|(f, _)| f.weights().to_vec())
            .collect();
        let widths = problem
            .blocks()
            .iter()
            .map(|b| b.dispersion.width())
            .collect();
        let n = problem.len() * problem.outputs();
        let logdet_a = gram.noise_log_det(problem.len());
        let eig = eigen_of(&gram, &lambda);
        Ok(Self {
            gram,
            lambda,
            widths,
            eig,
            n,
            len: problem.len(),
            logdet_a,
        })
    }

    /// The same pass for `problem`'s widths, if only the weights change (same features, no
    /// more harmonics needed); `None` when a new pass is needed.
    pub(super) fn reweighted(mut self, problem: &Problem) -> Option<Self> {
        let widths: Vec<Option<f64>> = problem
            .blocks()
            .iter()
            .map(|b| b.dispersion.width())
            .collect();
        if widths == self.widths {
            return Some(self);
        }
        let penalties = crate::solver::penalties(problem).ok()?;
        let mut lambda = Vec::with_capacity(self.lambda.len());
        for (((map, _), w), p) in self.gram.maps.iter().zip(&widths).zip(&penalties) {
            let dim_needed = match p {
                Penalty::Quadratic(q) => q.features()?.0.dim(),
                _ => return None,
            };
            if dim_needed > map.dim() {
                return None;
            }
            lambda.extend(map.weights_at_width((*w)?)?);
        }
        self.eig = eigen_of(&self.gram, &lambda);
        self.lambda = lambda;
        self.widths = widths;
        Some(self)
    }
}

/// Eigenvalues of A = Λ^½·G_FF·Λ^½ and h = Uᵀ·Λ^½·G_Fr. Features whose weight is below
/// 1e-16 of the largest are left out: they contribute nothing at f64 precision, and their
/// underflowing weights (exp(−2π²σ²n²) for high harmonics) upset the eigensolver.
fn eigen_of(g: &FeatureGram, lambda: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let rcol = g.m + g.nx;
    let top = lambda.iter().copied().fold(0.0, f64::max);
    let keep: Vec<usize> = (0..g.m).filter(|&j| lambda[j] > 1e-16 * top).collect();
    let k = keep.len();
    let sl: Vec<f64> = keep.iter().map(|&j| lambda[j].sqrt()).collect();
    let a = DMatrix::<f64>::from_fn(k, k, |i, j| sl[i] * g.g[(keep[i], keep[j])] * sl[j]);
    let gr = DVector::<f64>::from_fn(k, |i, _| sl[i] * g.g[(keep[i], rcol)]);
    let e = a.symmetric_eigen();
    let h: DVector<f64> = e.eigenvectors.transpose() * gr;
    (e.eigenvalues.as_slice().to_vec(), h.as_slice().to_vec())
}

/// Borrows the cached [`FeatureScore`] as a [`BetaScore`].
pub(super) struct FeatureRef<'a> {
    pub(super) score: &'a mut FeatureScore,
    pub(super) criterion: Criterion,
}

impl BetaScore for FeatureRef<'_> {
    fn score(&mut self, beta: f64) -> Result<(f64, Option<f64>)> {
        let s = &*self.score;
        let rr = s.gram.g[(s.gram.m + s.gram.nx, s.gram.m + s.gram.nx)];
        let lb = s.len as f64 * beta;
        let (v, s2) = factored_value(&s.eig.0, &s.eig.1, rr, s.n, lb, s.logdet_a, self.criterion)?;
        Ok((v, Some(s2)))
    }

    fn method(&self) -> String {
        format!(
            "{}, feature space (m = {}; one pass over the data, O(m) per β)",
            self.criterion.describe(),
            self.score.gram.m
        )
    }
}

//! Marginal likelihood and GCV on the dense matrices, by a growing low-rank factor or Cholesky.

use faer::Mat;
use faer::linalg::solvers::Solve;
use nalgebra::{DMatrix, DVector};

use crate::dispersion::QuadraticPenalty;
use crate::error::{Error, Result};
use crate::problem::Problem;
use crate::solver::exact::{add_noise_term, assemble};

use super::score::{BetaScore, factored_value, free_state_unsupported};
use super::settings::Criterion;

/// ML/GCV on the dense matrices A and B (live rows), by a growing low-rank factor of B in
/// whitened rows when the noise path is static, else by a Cholesky factorisation per β.
pub(super) struct DenseScore {
    criterion: Criterion,
    len: usize,
    /// A (identity when whitened)
    a: Mat<f64>,
    b: Mat<f64>,
    r: Vec<f64>,
    /// ln det A of the original rows (added so values match the general formula)
    logdet_a: f64,
    /// the pivoted Cholesky factor of the whitened B, when the noise path is static
    low: Option<LowRank>,
    exact_trials: usize,
    trials: usize,
}

/// Peak memory of [`DenseScore::new`] for `len` samples of `outputs` outputs, in bytes: B and
/// A (n×n, n = L·n_y), the block Q (n×L) and the Gram buffer.
fn memory_bytes(len: usize, outputs: usize) -> u64 {
    let n = (len as u64).saturating_mul(outputs as u64);
    let l = len as u64;
    let g = 256.min(len.max(1)) as u64;
    n.saturating_mul(n)
        .saturating_mul(2)
        .saturating_add(n.saturating_mul(l))
        .saturating_add(l * g)
        .saturating_mul(8)
}

/// Refuses ([`Error::TooLarge`]) a dense selection whose matrices would not fit in the memory
/// budget `limit` (bytes), before anything is allocated.
pub(super) fn check_memory(problem: &Problem, limit: u64) -> Result<()> {
    let (len, ny) = (problem.len(), problem.outputs());
    let need = memory_bytes(len, ny);
    if need <= limit {
        return Ok(());
    }
    // The longest record that fits: memory grows with L.
    let (mut lo, mut hi) = (0usize, len);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if memory_bytes(mid, ny) <= limit {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Err(Error::TooLarge {
        solver: "β/σ selection (dense marginal likelihood or GCV)".into(),
        needed_mib: need >> 20,
        limit_mib: limit >> 20,
        size: len * ny,
        suggestion: format!(
            "Selecting β by marginal likelihood or GCV on a dispersion without features stores \
             dense {n}×{n} matrices. Give β (and σ) instead of selecting them, select them on a \
             window of at most about {lo} samples, or use a dispersion with features (fourier, \
             gaussian-lowrank), whose selection is linear in L.",
            n = len * ny
        ),
    })
}

impl DenseScore {
    pub(super) fn new(problem: &Problem, criterion: Criterion) -> Result<Self> {
        if problem.free_response().is_some() {
            return Err(free_state_unsupported());
        }
        let len = problem.len();
        let ny = problem.outputs();
        let n = len * ny;
        let penalties: Vec<Box<dyn QuadraticPenalty>> = problem
            .blocks()
            .iter()
            .map(|b| crate::solver::quadratic_penalty(b, "β-selection"))
            .collect::<Result<_>>()?;
        let mut b = Mat::<f64>::zeros(n, n);
        let mut q = vec![0.0; n * len];
        let mut gram_buf = vec![0.0; len * 256.min(len.max(1))];
        assemble(
            problem,
            &penalties,
            0.0,
            &mut b,
            faer::MatMut::from_column_major_slice_mut(&mut q, n, len),
            &mut gram_buf,
        );
        drop(q);
        let mut a = Mat::<f64>::zeros(n, n);
        add_noise_term(problem.noise(), len, 1.0, &mut a);
        let r_all = problem.residual().as_slice();
        // A static noise path with D·Dᵀ > 0: whiten the rows sample by sample (A → I).
        if problem.noise().order() == 0 {
            let sm = DMatrix::from_fn(ny, ny, |i, j| a[(i, j)]);
            if let Some(ch) = sm.clone().cholesky() {
                let l = ch.l();
                let logdet_a = len as f64 * 2.0 * l.diagonal().iter().map(|v| v.ln()).sum::<f64>();
                let linv = l
                    .clone()
                    .try_inverse()
                    .expect("a Cholesky factor is invertible");
                let whiten = |x: &mut [f64]| {
                    for t in 0..len {
                        let blk = DVector::from_column_slice(&x[t * ny..(t + 1) * ny]);
                        let w = &linv * blk;
                        x[t * ny..(t + 1) * ny].copy_from_slice(w.as_slice());
                    }
                };
                let mut col = vec![0.0; n];
                for j in 0..n {
                    (0..n).for_each(|i| col[i] = b[(i, j)]);
                    whiten(&mut col);
                    (0..n).for_each(|i| b[(i, j)] = col[i]);
                }
                for i in 0..n {
                    (0..n).for_each(|j| col[j] = b[(i, j)]);
                    whiten(&mut col);
                    (0..n).for_each(|j| b[(i, j)] = col[j]);
                }
                let mut r = r_all.to_vec();
                whiten(&mut r);
                let a = Mat::<f64>::identity(n, n);
                let low = Some(LowRank::new(&b, &r));
                return Ok(Self {
                    criterion,
                    len,
                    a,
                    b,
                    r,
                    logdet_a,
                    low,
                    exact_trials: 0,
                    trials: 0,
                });
            }
        }
        // Rows that depend on neither e nor w are identities 0 = r: leave them out.
        let scale = (0..n).map(|i| a[(i, i)] + b[(i, i)]).fold(0.0, f64::max);
        let kept: Vec<usize> = (0..n)
            .filter(|&i| a[(i, i)] + b[(i, i)] > 1e-14 * scale)
            .collect();
        if kept.is_empty() {
            return Err(Error::Numerical(
                "no output depends on e or w: β cannot be chosen".into(),
            ));
        }
        let pick =
            |m: &Mat<f64>| Mat::from_fn(kept.len(), kept.len(), |i, j| m[(kept[i], kept[j])]);
        Ok(Self {
            criterion,
            len,
            a: pick(&a),
            b: pick(&b),
            r: kept.iter().map(|&i| r_all[i]).collect(),
            logdet_a: 0.0,
            low: None,
            exact_trials: 0,
            trials: 0,
        })
    }

    /// The criterion at β by a Cholesky factorisation of M, and the implied s².
    pub(super) fn exact(&self, beta: f64) -> Result<(f64, f64)> {
        let n = self.r.len();
        let lb = self.len as f64 * beta;
        let m = Mat::from_fn(n, n, |i, j| self.b[(i, j)] + lb * self.a[(i, j)]);
        let llt = m.llt(faer::Side::Lower).map_err(|e| {
            Error::Numerical(format!(
                "M(β = {beta:.3e}) is not positive definite ({e:?}); the noise path must reach every output"
            ))
        })?;
        let r = faer::Col::<f64>::from_fn(n, |i| self.r[i]);
        let minv_r = llt.solve(&r);
        let quad: f64 = (0..n).map(|i| self.r[i] * minv_r[i]).sum();
        let s2 = lb * quad / n as f64;
        let value = match self.criterion {
            Criterion::MarginalLikelihood => {
                let l = llt.L();
                let logdet: f64 = (0..n).map(|i| l[(i, i)].ln()).sum::<f64>() * 2.0;
                0.5 * n as f64 * (quad / n as f64).ln() + 0.5 * (logdet + self.logdet_a)
            }
            _ => {
                // ‖W(I − H)r‖² = (L·β)²·λᵀAλ with λ = M⁻¹r, and tr(I − H) = L·β·tr(M⁻¹A)
                let minv_a = llt.solve(&self.a);
                let trace = lb * (0..n).map(|i| minv_a[(i, i)]).sum::<f64>();
                let a_lambda = &self.a * &minv_r;
                let rss = lb * lb * (0..n).map(|i| minv_r[i] * a_lambda[i]).sum::<f64>();
                n as f64 * rss / (trace * trace)
            }
        };
        if !value.is_finite() {
            return Err(Error::Numerical(format!(
                "the {} criterion is not finite at β = {beta:.3e}",
                self.criterion.describe()
            )));
        }
        Ok((value, s2))
    }
}

impl BetaScore for DenseScore {
    fn score(&mut self, beta: f64) -> Result<(f64, Option<f64>)> {
        self.trials += 1;
        let n = self.r.len();
        let lb = self.len as f64 * beta;
        if let Some(low) = self.low.as_mut() {
            // criterion error ≤ (n + 1)·t/(2·L·β) ≤ 1e-4
            let target = 2e-4 * lb / (n as f64 + 1.0);
            if low.extend(&self.b, target) {
                let (s, h) = low.eigen();
                let rr: f64 = self.r.iter().map(|v| v * v).sum();
                let (v, s2) = factored_value(s, h, rr, n, lb, self.logdet_a, self.criterion)?;
                return Ok((v, Some(s2)));
            }
        }
        self.exact_trials += 1;
        let (v, s2) = self.exact(beta)?;
        Ok((v, Some(s2)))
    }

    fn method(&self) -> String {
        match &self.low {
            Some(low) => format!(
                "{}, dense (n = {}), whitened rows with a pivoted-Cholesky factor of rank {} (exact Cholesky at {} of {} trials)",
                self.criterion.describe(),
                self.r.len(),
                low.rank(),
                self.exact_trials,
                self.trials
            ),
            None => format!(
                "{}, dense (n = {}), one Cholesky factorisation of M per trial",
                self.criterion.describe(),
                self.r.len()
            ),
        }
    }
}

/// A pivoted (partial) Cholesky factor B ≈ V·Vᵀ grown on demand.
struct LowRank {
    /// the columns of V
    v: Vec<Vec<f64>>,
    /// the diagonal of B − V·Vᵀ
    diag: Vec<f64>,
    /// the eigendecomposition of VᵀV and h = Uᵀ·Vᵀ·r for the current rank
    eig: Option<(Vec<f64>, Vec<f64>)>,
    r: Vec<f64>,
    kmax: usize,
}

impl LowRank {
    fn new(b: &Mat<f64>, r: &[f64]) -> Self {
        let n = b.nrows();
        Self {
            v: Vec::new(),
            diag: (0..n).map(|i| b[(i, i)].max(0.0)).collect(),
            eig: None,
            r: r.to_vec(),
            kmax: n / 3,
        }
    }

    fn rank(&self) -> usize {
        self.v.len()
    }

    fn trace(&self) -> f64 {
        self.diag.iter().sum()
    }

    /// Grows the factor until the trace of the remainder is at most `target`; false when that
    /// would need a rank above n/3 (then an exact factorisation is cheaper).
    fn extend(&mut self, b: &Mat<f64>, target: f64) -> bool {
        let n = self.diag.len();
        while self.trace() > target {
            if self.v.len() >= self.kmax {
                return false;
            }
            let (p, &d) = self
                .diag
                .iter()
                .enumerate()
                .max_by(|x, y| x.1.total_cmp(y.1))
                .expect("n > 0");
            if d <= 0.0 {
                break;
            }
            let mut col: Vec<f64> = (0..n).map(|i| b[(i, p)]).collect();
            for vj in &self.v {
                let f = vj[p];
                col.iter_mut().zip(vj).for_each(|(c, v)| *c -= v * f);
            }
            let s = d.sqrt();
            col.iter_mut().for_each(|c| *c /= s);
            for (dd, c) in self.diag.iter_mut().zip(&col) {
                *dd = (*dd - c * c).max(0.0);
            }
            self.diag[p] = 0.0;
            self.v.push(col);
            self.eig = None;
        }
        true
    }

    fn eigen(&mut self) -> (&[f64], &[f64]) {
        if self.eig.is_none() && self.v.is_empty() {
            // Rank 0 (B is zero to the target, e.g. a one-sample record through a path without
            // direct term): no eigenpairs, and nalgebra cannot decompose a 0×0 matrix.
            self.eig = Some((Vec::new(), Vec::new()));
        }
        if self.eig.is_none() {
            let k = self.v.len();
            let vtv = DMatrix::<f64>::from_fn(k, k, |i, j| {
                self.v[i]
                    .iter()
                    .zip(&self.v[j])
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
            });
            let g: DVector<f64> = DVector::from_fn(k, |i, _| {
                self.v[i]
                    .iter()
                    .zip(&self.r)
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
            });
            let e = vtv.symmetric_eigen();
            let h: DVector<f64> = e.eigenvectors.transpose() * g;
            self.eig = Some((e.eigenvalues.as_slice().to_vec(), h.as_slice().to_vec()));
        }
        let (s, h) = self.eig.as_ref().expect("just set");
        (s, h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dense_selection_beyond_the_budget_is_refused_before_allocating() {
        // 10⁶ samples: 16 TB of matrices.
        assert!(memory_bytes(1_000_000, 1) > 1 << 40);
        assert_eq!(memory_bytes(usize::MAX, 2), u64::MAX);
        assert!(memory_bytes(100, 1) < 1 << 20);
        let lim = memory_bytes(1000, 1);
        assert!(memory_bytes(1001, 1) > lim);
    }

    #[test]
    fn a_zero_b_gives_rank_zero_without_panicking() {
        // One sample whose path has no direct term: B = T·K·Tᵀ = 0.
        let b = Mat::<f64>::zeros(1, 1);
        let mut low = LowRank::new(&b, &[0.3]);
        assert!(low.extend(&b, 1e-6));
        assert_eq!(low.rank(), 0);
        let (s, h) = low.eigen();
        assert!(s.is_empty() && h.is_empty());
    }
}

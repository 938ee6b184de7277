//! Marginal likelihood and GCV on the dense matrices: by growing low-rank factors of the Gram
//! matrices (no n×n matrix), of the assembled B, by one eigendecomposition of B (whitened rows),
//! or by a Cholesky factorisation per β (dynamic noise paths).

use faer::linalg::solvers::Solve;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef, Par};
use nalgebra::{DMatrix, DVector};
use structid_lti::{LinearSystem, StateSpace};

use crate::dispersion::QuadraticPenalty;
use crate::error::{Error, Result};
use crate::identify::problem::Problem;
use crate::solver::exact::{add_noise_term, assemble};

use super::score::{BetaScore, factored_value, free_state_unsupported};
use super::settings::Criterion;

/// ML/GCV on the dense matrices A and B (live rows), by a growing low-rank factor of B in
/// whitened rows when the noise path is static, else by a Cholesky factorisation per β.
pub(super) struct DenseScore {
    criterion: Criterion,
    len: usize,
    /// A (`None`: the identity, rows whitened)
    a: Option<Mat<f64>>,
    b: Mat<f64>,
    r: Vec<f64>,
    /// ln det A of the original rows (added so values match the general formula)
    logdet_a: f64,
    /// the pivoted Cholesky factor of the whitened B, when the noise path is static
    low: Option<LowRank>,
    /// pivoted Cholesky factors of the Gram matrices pushed through the whitened paths
    gram: Option<GramFactors>,
    /// what B is assembled from when the Gram factors do not suffice (whitened rows)
    deferred: Option<Deferred>,
    exact_trials: usize,
    /// the eigenvalues of the whitened B and h = Uᵀ·r, once a trial needed them
    spectrum: Option<(Vec<f64>, Vec<f64>)>,
    /// trials decided by the B factor (`low`)
    low_trials: usize,
    trials: usize,
}

/// The problem, penalties and whitening kept to assemble B on demand.
struct Deferred {
    problem: Problem,
    penalties: Vec<Box<dyn QuadraticPenalty>>,
    /// W with WᵀW = (D·Dᵀ)⁻¹ per sample
    w: Mat<f64>,
}

/// Peak memory of [`DenseScore::new`] for `len` samples of `outputs` outputs, in bytes: B and
/// A (n×n, n = L·n_y; A is not stored when the rows are whitened, but a dynamic noise path
/// needs it), and the panels of the assembly.
fn memory_bytes(len: usize, outputs: usize) -> u64 {
    let n = (len as u64).saturating_mul(outputs as u64);
    let l = len as u64;
    let g = 256.min(len.max(1)) as u64;
    n.saturating_mul(n)
        .saturating_mul(2)
        .saturating_add(n.saturating_mul(g))
        .saturating_add(l.saturating_mul(g))
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
        let r_all = problem.residual().as_slice();
        // A static noise path with D·Dᵀ > 0: whiten the rows sample by sample (A → I).
        if problem.noise().order() == 0
            && let Some(ch) = static_noise_covariance(problem.noise()).cholesky()
        {
            let l = ch.l();
            let logdet_a = len as f64 * 2.0 * l.diagonal().iter().map(|v| v.ln()).sum::<f64>();
            let linv = l.try_inverse().expect("a Cholesky factor is invertible");
            let w = Mat::<f64>::from_fn(ny, ny, |i, j| linv[(i, j)]);
            let mut r = Mat::<f64>::from_fn(n, 1, |i, _| r_all[i]);
            whiten_rows(r.as_mut(), w.as_ref());
            let r: Vec<f64> = (0..n).map(|i| r[(i, 0)]).collect();
            let gram = GramFactors::new(problem, &penalties, w.as_ref(), &r);
            let mut score = Self {
                criterion,
                len,
                a: None,
                b: Mat::new(),
                r,
                logdet_a,
                low: None,
                gram,
                deferred: Some(Deferred {
                    problem: problem.clone(),
                    penalties,
                    w,
                }),
                exact_trials: 0,
                spectrum: None,
                low_trials: 0,
                trials: 0,
            };
            if score.gram.is_none() {
                score.assemble_whitened();
            }
            return Ok(score);
        }
        let mut b = Mat::<f64>::zeros(n, n);
        assemble(problem, &penalties, 0.0, b.as_mut());
        let mut a = Mat::<f64>::zeros(n, n);
        add_noise_term(problem.noise(), len, 1.0, a.as_mut());
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
            a: Some(pick(&a)),
            b: pick(&b),
            r: kept.iter().map(|&i| r_all[i]).collect(),
            logdet_a: 0.0,
            low: None,
            gram: None,
            deferred: None,
            exact_trials: 0,
            spectrum: None,
            low_trials: 0,
            trials: 0,
        })
    }

    /// Assembles the whitened B and its pivoted-Cholesky factor, once, when the Gram factors
    /// do not reach a trial's accuracy (or do not apply).
    fn assemble_whitened(&mut self) {
        let Some(d) = self.deferred.take() else {
            return;
        };
        let n = self.r.len();
        let mut b = Mat::<f64>::zeros(n, n);
        assemble(&d.problem, &d.penalties, 0.0, b.as_mut());
        whiten_rows(b.as_mut(), d.w.as_ref());
        whiten_rows(b.as_mut().transpose_mut(), d.w.as_ref());
        let mut low = LowRank::new(&b, &self.r);
        // Beyond rank n/10 the one eigendecomposition of B (`spectral`) is the cheaper exact route.
        low.kmax = n / 10;
        self.low = Some(low);
        self.b = b;
    }

    /// The eigenvalues s of the whitened B = U·diag(s)·Uᵀ and h = diag(s)^½·Uᵀ·r, computed
    /// once: with them every β is exact in O(n) by the formulas of the factored criterion
    /// (V = U·diag(s)^½, k = n).
    fn spectral(&mut self) -> Result<(&[f64], &[f64])> {
        if self.spectrum.is_none() {
            self.assemble_whitened();
            let n = self.r.len();
            let eig = self.b.self_adjoint_eigen(faer::Side::Lower).map_err(|e| {
                Error::Numerical(format!("the eigendecomposition of B failed ({e:?})"))
            })?;
            let r = faer::Col::<f64>::from_fn(n, |i| self.r[i]);
            let h = eig.U().transpose() * &r;
            let s = eig.S().column_vector();
            // B = V·Vᵀ with V = U·diag(s)^½: the factored formulas with h = diag(s)^½·Uᵀ·r
            let s: Vec<f64> = (0..n).map(|i| s[i].max(0.0)).collect();
            let h = (0..n).map(|i| s[i].sqrt() * h[i]).collect();
            self.spectrum = Some((s, h));
        }
        let (s, h) = self.spectrum.as_ref().expect("just set");
        Ok((s, h))
    }

    /// The criterion at β by a Cholesky factorisation of M, and the implied s².
    pub(super) fn exact(&mut self, beta: f64) -> Result<(f64, f64)> {
        self.assemble_whitened();
        let n = self.r.len();
        let lb = self.len as f64 * beta;
        let m = match &self.a {
            Some(a) => Mat::from_fn(n, n, |i, j| self.b[(i, j)] + lb * a[(i, j)]),
            None => Mat::from_fn(n, n, |i, j| self.b[(i, j)] + if i == j { lb } else { 0.0 }),
        };
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
                let identity;
                let a = match &self.a {
                    Some(a) => a,
                    None => {
                        identity = Mat::<f64>::identity(n, n);
                        &identity
                    }
                };
                let minv_a = llt.solve(a);
                let trace = lb * (0..n).map(|i| minv_a[(i, i)]).sum::<f64>();
                let a_lambda = a * &minv_r;
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
    fn method(&self) -> String {
        if let Some(g) = &self.gram {
            return format!(
                "{}, dense (n = {}), whitened rows with pivoted-Cholesky factors of the Gram matrices of total rank {} (a factor of the assembled B at {} and its exact eigendecomposition at {} of {} trials)",
                self.criterion.describe(),
                self.r.len(),
                g.rank(),
                self.low_trials,
                self.exact_trials,
                self.trials
            );
        }
        match &self.low {
            Some(low) => format!(
                "{}, dense (n = {}), whitened rows with a pivoted-Cholesky factor of rank {} (the exact eigendecomposition of B at {} of {} trials)",
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

    fn score(&mut self, beta: f64) -> Result<(f64, Option<f64>)> {
        self.trials += 1;
        let n = self.r.len();
        let lb = self.len as f64 * beta;
        // criterion error ≤ (n + 1)·t/(2·L·β) ≤ 1e-4
        let target = 2e-4 * lb / (n as f64 + 1.0);
        if let Some(g) = self.gram.as_mut()
            && g.extend(target)
        {
            let rr = g.rr;
            let (s, h) = g.eigen();
            let (v, s2) = factored_value(s, h, rr, n, lb, self.logdet_a, self.criterion)?;
            return Ok((v, Some(s2)));
        }
        self.assemble_whitened();
        if let Some(low) = self.low.as_mut()
            && low.extend(&self.b, target)
        {
            self.low_trials += 1;
            let (s, h) = low.eigen();
            let rr: f64 = self.r.iter().map(|v| v * v).sum();
            let (v, s2) = factored_value(s, h, rr, n, lb, self.logdet_a, self.criterion)?;
            return Ok((v, Some(s2)));
        }
        self.exact_trials += 1;
        if self.a.is_none() {
            let rr: f64 = self.r.iter().map(|v| v * v).sum();
            let (logdet_a, criterion) = (self.logdet_a, self.criterion);
            let (s, h) = self.spectral()?;
            let (v, s2) = factored_value(s, h, rr, n, lb, logdet_a, criterion)?;
            return Ok((v, Some(s2)));
        }
        let (v, s2) = self.exact(beta)?;
        Ok((v, Some(s2)))
    }
}

/// D·Dᵀ (n_y × n_y) of a static noise path y = D·e.
fn static_noise_covariance(noise: &dyn LinearSystem) -> DMatrix<f64> {
    let d = crate::solver::features::static_gain(noise, noise.outputs(), noise.inputs());
    &d * d.transpose()
}

/// x ← (I ⊗ W)·x: the n_y × n_y matrix `w` applied to every sample's block of n_y rows of `x`.
fn whiten_rows(mut x: MatMut<'_, f64>, w: MatRef<'_, f64>) {
    let ny = w.nrows();
    if ny == 1 {
        let s = w[(0, 0)];
        for j in 0..x.ncols() {
            x.rb_mut().col_mut(j).iter_mut().for_each(|v| *v *= s);
        }
        return;
    }
    let mut tmp = Mat::<f64>::zeros(ny, x.ncols());
    for t in 0..x.nrows() / ny {
        let mut rows = x.rb_mut().subrows_mut(t * ny, ny);
        tmp.copy_from(rows.rb());
        faer::linalg::matmul::matmul(
            rows.rb_mut(),
            Accum::Replace,
            w,
            tmp.as_ref(),
            1.0,
            Par::Seq,
        );
    }
}

/// Pivoted (partial) Cholesky factors K_i ≈ U_i·U_iᵀ of the blocks' Gram matrices, pushed
/// through the whitened paths: B ≈ V·Vᵀ with V = [W·T_1·U_1, W·T_2·U_2, …]. Each pivot costs one
/// Gram column (L kernel evaluations) and one pass of the path over it, so no n×n matrix is
/// formed. B − V·Vᵀ = Σ_i W·T_i·(K_i − U_i·U_iᵀ)·T_iᵀ·Wᵀ is positive semidefinite with trace at
/// most Σ_i c_i·tr(K_i − U_i·U_iᵀ), where c_i = (Σ_k ‖W·h_k‖)² ≥ ‖W·T_i‖₂² bounds the gain of
/// the path from its Markov parameters h_k; that trace bounds the criterion's error as for the
/// factor of B.
struct GramFactors {
    blocks: Vec<GramBlock>,
    /// the columns of V
    v: Vec<Vec<f64>>,
    /// VᵀV, row by row (row j has j + 1 entries: the lower triangle)
    vtv: Vec<Vec<f64>>,
    /// Vᵀ·r
    vr: Vec<f64>,
    /// |r|²
    rr: f64,
    /// the eigendecomposition of VᵀV and h = Uᵀ·Vᵀ·r for the current rank
    eig: Option<(Vec<f64>, Vec<f64>)>,
    kmax: usize,
    w: Mat<f64>,
    r: Vec<f64>,
}

/// One block's Gram factor.
struct GramBlock {
    pen: Box<dyn QuadraticPenalty>,
    path: StateSpace,
    /// c_i, the bound of ‖W·T_i‖₂²
    gain: f64,
    /// the diagonal of K_i − U_i·U_iᵀ
    diag: Vec<f64>,
    /// the columns of U_i
    u: Vec<Vec<f64>>,
    /// scratch: one Gram column
    col: Vec<f64>,
}

impl GramFactors {
    /// `None` when a path is not a state-space system or a penalty cannot give its diagonal.
    fn new(
        problem: &Problem,
        penalties: &[Box<dyn QuadraticPenalty>],
        w: MatRef<'_, f64>,
        r: &[f64],
    ) -> Option<Self> {
        let len = problem.len();
        let mut blocks = Vec::with_capacity(penalties.len());
        for (b, pen) in problem.blocks().iter().zip(penalties) {
            let path = b.path.as_state_space()?.clone();
            let diag = pen.diagonal_at(&b.z)?;
            if diag.len() != len || diag.iter().any(|d| !d.is_finite()) {
                return None;
            }
            let wf = DMatrix::from_fn(w.nrows(), w.ncols(), |i, j| w[(i, j)]);
            let l1: f64 = path
                .markov_parameters(len)
                .iter()
                .map(|h| (&wf * h).norm())
                .sum();
            if !l1.is_finite() {
                return None;
            }
            // Re-box the penalty: the blocks keep their own (a Box is not Clone).
            let pen = crate::solver::quadratic_penalty(b, "β-selection").ok()?;
            blocks.push(GramBlock {
                pen,
                path,
                gain: l1 * l1,
                diag: diag.into_iter().map(|d| d.max(0.0)).collect(),
                u: Vec::new(),
                col: vec![0.0; len],
            });
        }
        let n = r.len();
        Some(Self {
            blocks,
            v: Vec::new(),
            vtv: Vec::new(),
            vr: Vec::new(),
            rr: r.iter().map(|x| x * x).sum(),
            eig: None,
            // beyond this the assembled B (its factor, or its eigendecomposition) is cheaper
            kmax: n / 10,
            w: w.to_owned(),
            r: r.to_vec(),
        })
    }

    fn rank(&self) -> usize {
        self.v.len()
    }

    /// The bound Σ_i c_i·tr(K_i − U_i·U_iᵀ) of tr(B − V·Vᵀ).
    fn trace_bound(&self) -> f64 {
        self.blocks
            .iter()
            .map(|b| b.gain * b.diag.iter().sum::<f64>())
            .sum()
    }

    /// Grows the factors until the trace bound is at most `target`; false when that would
    /// need a total rank above n/3.
    fn extend(&mut self, target: f64) -> bool {
        while self.trace_bound() > target {
            if self.v.len() >= self.kmax {
                return false;
            }
            // the block whose remainder weighs most
            let (bi, _) = self
                .blocks
                .iter()
                .enumerate()
                .map(|(i, b)| (i, b.gain * b.diag.iter().sum::<f64>()))
                .max_by(|x, y| x.1.total_cmp(&y.1))
                .expect("at least one block");
            let blk = &mut self.blocks[bi];
            let (p, &d) = blk
                .diag
                .iter()
                .enumerate()
                .max_by(|x, y| x.1.total_cmp(y.1))
                .expect("L > 0");
            if d <= 0.0 {
                // this block's remainder is numerically zero
                blk.diag.iter_mut().for_each(|x| *x = 0.0);
                continue;
            }
            let len = blk.diag.len();
            blk.pen.fill_columns(
                p..p + 1,
                MatMut::from_column_major_slice_mut(&mut blk.col, len, 1),
            );
            let mut col = std::mem::take(&mut blk.col);
            for uj in &blk.u {
                let f = uj[p];
                col.iter_mut().zip(uj).for_each(|(c, u)| *c -= u * f);
            }
            let s = d.sqrt();
            col.iter_mut().for_each(|c| *c /= s);
            for (dd, c) in blk.diag.iter_mut().zip(&col) {
                *dd = (*dd - c * c).max(0.0);
            }
            blk.diag[p] = 0.0;
            // v = W·T_i·u
            let n = self.r.len();
            let mut v = Mat::<f64>::zeros(n, 1);
            blk.path.apply(
                &col,
                v.col_mut(0)
                    .try_as_col_major_mut()
                    .expect("a column")
                    .as_slice_mut(),
            );
            whiten_rows(v.as_mut(), self.w.as_ref());
            let v: Vec<f64> = (0..n).map(|i| v[(i, 0)]).collect();
            blk.col = vec![0.0; len];
            blk.u.push(col);
            let row: Vec<f64> = self
                .v
                .iter()
                .chain(std::iter::once(&v))
                .map(|vj| vj.iter().zip(&v).map(|(a, b)| a * b).sum())
                .collect();
            self.vtv.push(row);
            self.vr
                .push(v.iter().zip(&self.r).map(|(a, b)| a * b).sum());
            self.v.push(v);
            self.eig = None;
        }
        true
    }

    fn eigen(&mut self) -> (&[f64], &[f64]) {
        if self.eig.is_none() {
            let k = self.v.len();
            if k == 0 {
                self.eig = Some((Vec::new(), Vec::new()));
            } else {
                let vtv = DMatrix::<f64>::from_fn(k, k, |i, j| {
                    if j <= i {
                        self.vtv[i][j]
                    } else {
                        self.vtv[j][i]
                    }
                });
                let g = DVector::from_column_slice(&self.vr);
                let e = vtv.symmetric_eigen();
                let h: DVector<f64> = e.eigenvectors.transpose() * g;
                self.eig = Some((e.eigenvalues.as_slice().to_vec(), h.as_slice().to_vec()));
            }
        }
        let (s, h) = self.eig.as_ref().expect("just set");
        (s, h)
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

    /// The one eigendecomposition of the whitened B gives the criterion of the exact Cholesky
    /// factorisation at every β (both criteria, a dynamic path, two blocks).
    #[test]
    fn the_spectral_route_equals_the_cholesky_factorisation() {
        let exp = crate::paper::spray(
            120,
            0.5,
            std::sync::Arc::new(crate::KernelDispersion::gaussian(0.05).unwrap()),
            3,
        )
        .unwrap();
        let problem = Problem::from_model(&exp.model, &exp.data).unwrap();
        for criterion in [Criterion::MarginalLikelihood, Criterion::Gcv] {
            let mut score = DenseScore::new(&problem, criterion).unwrap();
            for beta in [1e-6, 1e-3, 1e-1, 10.0] {
                let (want, s2) = score.exact(beta).unwrap();
                let n = score.r.len();
                let rr: f64 = score.r.iter().map(|v| v * v).sum();
                let (logdet_a, lb) = (score.logdet_a, score.len as f64 * beta);
                let (s, h) = score.spectral().unwrap();
                let (got, s2_got) = factored_value(s, h, rr, n, lb, logdet_a, criterion).unwrap();
                assert!(
                    (want - got).abs() <= 1e-9 * want.abs().max(1.0),
                    "{criterion:?} β {beta}: {want} vs {got}"
                );
                assert!((s2 - s2_got).abs() <= 1e-9 * s2, "{s2} vs {s2_got}");
            }
        }
    }

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

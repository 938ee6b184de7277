//! Posterior uncertainty bands of the estimated maps, for quadratic dispersions.
//!
//! # The Gaussian-process reading of J
//! J is, up to a constant factor, the negative log posterior of the model
//!
//! ```text
//! w_i ~ N(0, c·K_i),   e ~ N(0, s²·I),   c = s²/(L·β),   r = T_ye·e + Σ_i T_i·w_i (+ O·x₀)
//! ```
//!
//! so the estimate N̂_i is a posterior mean, and the posterior of N_i at a point z is Gaussian
//! with that mean and the variance (Hsu et al. 2006; any GP regression text)
//!
//! ```text
//! Var N_i(z) | r = c·( k_i(z,z) − (T_i·k_z)ᵀ·P·(T_i·k_z) ),   k_z = (k_i(z_1,z), …, k_i(z_L,z))
//! ```
//!
//! with P = M⁻¹ and M = L·β·T_ye·T_yeᵀ + Σ_i T_i·K_i·T_iᵀ the exact solver's matrix. k_z is a
//! signal over time: T_i·k_z is one run of the block's path (by recursion, never a Toeplitz
//! matrix), and (T_i·k_z)ᵀM⁻¹(T_i·k_z) = |L_M⁻¹·T_i·k_z|² is one triangular solve with the
//! Cholesky factor L_M that the solve already computed.
//!
//! **Noise level.** s² is not known; it is estimated by maximising the marginal likelihood of
//! r over c (profiled): ĉ = rᵀP·r/(n − n_x), ŝ² = L·β·ĉ, with n the number of live output
//! samples (those the solver keeps) and n_x the number of estimated initial states (0 with a
//! zero initial state). Since L·β·rᵀP·r = Σ|ê_k|² + L·β·Σ_i D_i = L·Ĵ at the optimum,
//! ŝ² = L·Ĵ/(n − n_x).
//!
//! When the exact solver had to add a diagonal jitter to M (reported in the diagnostics), the
//! kept factor includes it, i.e. the band treats the jitter as a little extra white noise,
//! consistently with the estimate.
//!
//! **Unknown initial state.** x₀ gets a flat prior, i.e. P becomes the projected
//! P = M⁻¹ − M⁻¹O(OᵀM⁻¹O)⁻¹OᵀM⁻¹: with U an orthonormal basis of L_M⁻¹O,
//! vᵀPv = |L_M⁻¹v|² − |Uᵀ·L_M⁻¹v|². Integrating x₀ out leaves n − n_x degrees of freedom for s².
//!
//! **Feature path.** With K_i = Ψ_iΛ_iΨ_iᵀ and b the whitened coefficients of the feature
//! solver (w_i = Ψ_iΛ_i^½b_i, prior b ~ N(0, c·I)), the posterior covariance of (b, x₀) is
//! s²·H⁻¹ with H = [[XᵀX + L·β·I, X_bᵀX_O], [X_OᵀX_b, X_OᵀX_O]] the m-space matrix the solver
//! factorised (X the whitened regressors), so Var N_i(z) = s²·|L_H⁻¹·φ̃(z)|² with
//! φ̃ = Λ_i^½·ψ_i(z) in block i's coefficient rows and zero elsewhere, and
//! ŝ² = (weighted SSE + L·β·|b|²)/(n − n_x), the same ŝ² as the dense formula.
//!
//! **Meaning.** N̂_i(z) ± 1.96·std is a 95 % credible band: it covers the true map at 95 % of
//! the points *if* the map is a draw from the prior above with the β used (so β should fit
//! the data, e.g. from [`crate::selection`]). For a fixed map that is much smoother or
//! rougher than the prior says, the coverage can differ. With several blocks feeding one
//! output, constants (and anything else the data cannot attribute) are shared between the
//! blocks, and each block's band includes that ambiguity.
//!
//! **Cost.** Per batch of G points: G kernel columns (O(G·L)), G runs of T_i (O(G·L·n_s), n_s
//! the order of the block's path), one triangular solve with G right-hand sides (O(G·n²) with
//! n = L·n_y live rows), in batches of [`BATCH`] points. Memory: the exact path keeps M's buffer (its Cholesky factor, n×n f64, so
//! 8·n² bytes — 32 MB at n = 2000, 800 MB at n = 10 000) for as long as the
//! [`crate::Identification`] lives, plus n·n_x for the basis U; the feature path keeps the
//! (m + n_x)² factor.
//!
//! ```
//! use std::sync::Arc;
//! use structid_core::{identify, paper, IdentifySettings, KernelDispersion, Signal};
//! let exp = paper::spray(400, 1.0, Arc::new(KernelDispersion::gaussian(0.1).unwrap()), 5).unwrap();
//! let settings = IdentifySettings::builder().beta(0.01).posterior(true).build().unwrap();
//! let id = identify(&exp.model, &exp.data, &settings).unwrap();
//! let post = id.posterior.as_ref().unwrap();
//! assert!(post.noise_variance() > 0.5 && post.noise_variance() < 2.0); // the true s² is 1
//! let grid = Signal::from_fn(5, 1, |k, _| -0.8 + 0.4 * k as f64);
//! let std = id.posterior_std(0, &grid).unwrap().unwrap();
//! assert!(std.iter().all(|s| *s > 0.0 && s.is_finite()));
//! ```

use std::fmt;
use std::sync::Arc;

use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat};
use structid_lti::{LinearSystem, Signal};

use crate::dispersion::{FeatureMap, QuadraticPenalty};
use crate::error::{Error, Result};
use crate::solver::square_buffer::SquareBuffer;

/// Points evaluated per batch by [`Posterior::std`]: the workspace is BATCH·(L + 2·n) f64 on
/// the exact path.
pub const BATCH: usize = 256;

/// What a solver kept to evaluate the posterior standard deviation of the maps (see the
/// [module documentation](self)): the noise level ŝ² and the Cholesky factor of the system it
/// solved. Obtained from [`crate::Identification::posterior`] when
/// [`crate::IdentifySettingsBuilder::posterior`] is on and the solver is exact or feature-based.
pub struct Posterior {
    noise_variance: f64,
    degrees_of_freedom: usize,
    inner: Inner,
}

enum Inner {
    Dense(Dense),
    Features(Features),
}

/// One block of the dense posterior: its path T_i and its penalty (for k_i(z_k, ·)).
pub(crate) struct DenseBlock {
    pub(crate) path: Arc<dyn LinearSystem>,
    pub(crate) penalty: Arc<dyn QuadraticPenalty>,
    pub(crate) inputs: usize,
}

struct Dense {
    /// M's buffer after the in-place Cholesky: the lower triangle of its leading nk×nk block is
    /// L_M (the rest is not read).
    factor: SquareBuffer,
    /// Live rows (indices into the L·n_y stacked output) in the order of the factor.
    kept: Vec<usize>,
    /// L·n_y.
    rows: usize,
    len: usize,
    blocks: Vec<DenseBlock>,
    /// Orthonormal basis U of L_M⁻¹O (nk × n_x), when x₀ is estimated.
    free_basis: Option<Mat<f64>>,
    /// ĉ = ŝ²/(L·β).
    scale: f64,
}

/// One block of the feature posterior.
pub(crate) struct FeatureBlock {
    pub(crate) map: Arc<dyn FeatureMap>,
    /// First coefficient row of the block in the m-space system.
    pub(crate) offset: usize,
    /// Λ^½ of the block's features.
    pub(crate) sqrt_weights: Vec<f64>,
    pub(crate) inputs: usize,
}

struct Features {
    /// L_H (lower triangular), H the (m + n_x)² matrix of the feature solver.
    factor: Mat<f64>,
    blocks: Vec<FeatureBlock>,
}

impl fmt::Debug for Posterior {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Posterior")
            .field("path", &self.path())
            .field("noise_variance", &self.noise_variance)
            .field("degrees_of_freedom", &self.degrees_of_freedom)
            .field("blocks", &self.blocks())
            .field("memory_bytes", &self.memory_bytes())
            .finish()
    }
}

impl Posterior {
    /// The dense (exact-solver) posterior. `factor` is M's buffer after the in-place Cholesky
    /// of its leading `kept.len()` block; `free` the free-response matrix O (L·n_y × n_x) when
    /// x₀ is estimated; `quad` = rᵀP·r (= (r − O·x̂₀)ᵀλ); `lb` = L·β. Errs with the reason when
    /// no posterior can be formed (no degrees of freedom left for s²).
    pub(crate) fn dense(
        factor: SquareBuffer,
        kept: Vec<usize>,
        len: usize,
        blocks: Vec<DenseBlock>,
        free: Option<&Mat<f64>>,
        quad: f64,
        lb: f64,
    ) -> std::result::Result<Self, String> {
        let nk = kept.len();
        let nx = free.map_or(0, |o| o.ncols());
        let dof = nk
            .checked_sub(nx)
            .filter(|d| *d > 0)
            .ok_or("no output sample is left to estimate the noise level")?;
        let scale = quad / dof as f64;
        if !(scale.is_finite() && scale >= 0.0) {
            return Err(format!("the quadratic form rᵀM⁻¹r = {quad} is not usable"));
        }
        let rows = factor.nrows();
        let free_basis = match free {
            Some(o) if nx > 0 => {
                let mut x = Mat::<f64>::from_fn(nk, nx, |i, j| o[(kept[i], j)]);
                solve_lower_triangular_in_place(
                    factor.as_ref().submatrix(0, 0, nk, nk),
                    x.as_mut(),
                    faer::get_global_parallelism(),
                );
                Some(x.qr().compute_thin_Q())
            }
            _ => None,
        };
        Ok(Self {
            noise_variance: lb * scale,
            degrees_of_freedom: dof,
            inner: Inner::Dense(Dense {
                factor,
                kept,
                rows,
                len,
                blocks,
                free_basis,
                scale,
            }),
        })
    }

    /// The feature-space posterior: `factor` is L_H (k × k, lower), `weighted_sse + lb·|b|²`
    /// the minimum of L·J, `observations` = L·n_y, `free` = n_x.
    pub(crate) fn features(
        factor: Mat<f64>,
        blocks: Vec<FeatureBlock>,
        min_lj: f64,
        observations: usize,
        free: usize,
    ) -> std::result::Result<Self, String> {
        let dof = observations
            .checked_sub(free)
            .filter(|d| *d > 0)
            .ok_or("no output sample is left to estimate the noise level")?;
        let s2 = min_lj / dof as f64;
        if !(s2.is_finite() && s2 >= 0.0) {
            return Err(format!("the minimum of L·J = {min_lj} is not usable"));
        }
        Ok(Self {
            noise_variance: s2,
            degrees_of_freedom: dof,
            inner: Inner::Features(Features { factor, blocks }),
        })
    }

    /// ŝ², the noise variance estimated by the profiled marginal likelihood
    /// (ŝ² = L·Ĵ/(n − n_x), see the [module documentation](self)).
    pub fn noise_variance(&self) -> f64 {
        self.noise_variance
    }

    /// n − n_x: live output samples less estimated initial states.
    pub fn degrees_of_freedom(&self) -> usize {
        self.degrees_of_freedom
    }

    /// `"exact"` or `"features"`: which solver's factor is kept.
    pub fn path(&self) -> &'static str {
        match &self.inner {
            Inner::Dense(_) => "exact",
            Inner::Features(_) => "features",
        }
    }

    /// Number of blocks.
    pub fn blocks(&self) -> usize {
        match &self.inner {
            Inner::Dense(d) => d.blocks.len(),
            Inner::Features(f) => f.blocks.len(),
        }
    }

    /// Bytes held: the kept factor (8·n² on the exact path, where n = L·n_y) and the basis of
    /// the initial-state directions.
    pub fn memory_bytes(&self) -> u64 {
        let words = match &self.inner {
            Inner::Dense(d) => {
                d.factor.nrows() * d.factor.nrows()
                    + d.free_basis.as_ref().map_or(0, |u| u.nrows() * u.ncols())
                    + d.kept.len()
            }
            Inner::Features(f) => {
                f.factor.nrows() * f.factor.ncols()
                    + f.blocks.iter().map(|b| b.sqrt_weights.len()).sum::<usize>()
            }
        };
        8 * words as u64
    }

    /// The posterior standard deviation of block `block`'s map (block order of the problem,
    /// i.e. of [`crate::Identification::blocks`]) at every sample of `points` (one point per
    /// sample, as many channels as the block has inputs).
    ///
    /// `Ok(None)` when the block's penalty cannot evaluate its kernel at new points
    /// ([`QuadraticPenalty::cross_columns`] unsupported, e.g. a user-defined penalty).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a block index out of range, [`Error::DimensionMismatch`]
    /// when `points` has the wrong number of channels, [`Error::NonFiniteData`] for a NaN or
    /// infinite coordinate.
    pub fn std(&self, block: usize, points: &Signal) -> Result<Option<Vec<f64>>> {
        let inputs = match &self.inner {
            Inner::Dense(d) => d.blocks.get(block).map(|b| b.inputs),
            Inner::Features(f) => f.blocks.get(block).map(|b| b.inputs),
        };
        let Some(inputs) = inputs else {
            return Err(block_out_of_range(block, self.blocks()));
        };
        check_points(points, inputs)?;
        let var = match &self.inner {
            Inner::Dense(d) => d.variance(block, points)?,
            Inner::Features(f) => Some(f.variance(block, points, self.noise_variance)),
        };
        Ok(var.map(|v| v.into_iter().map(|v| v.max(0.0).sqrt()).collect()))
    }
}

pub(crate) fn block_out_of_range(block: usize, blocks: usize) -> Error {
    Error::InvalidParameter {
        name: "block".into(),
        value: block as f64,
        reason: format!("the model has {blocks} block(s), numbered from 0"),
    }
}

/// Points must have `inputs` channels and finite coordinates.
pub(crate) fn check_points(points: &Signal, inputs: usize) -> Result<()> {
    if points.channels() != inputs && !points.is_empty() {
        return Err(Error::DimensionMismatch {
            what: "channels of the evaluation points (one per block input)".into(),
            expected: inputs.to_string(),
            found: points.channels().to_string(),
        });
    }
    for k in 0..points.len() {
        for (c, &v) in points.sample(k).iter().enumerate() {
            if !v.is_finite() {
                return Err(Error::NonFiniteData {
                    signal: "evaluation points".into(),
                    sample: k,
                    channel: c,
                    value: v,
                });
            }
        }
    }
    Ok(())
}

impl Dense {
    /// Posterior variances (before the clamp at 0) of block `block` at `points`.
    fn variance(&self, block: usize, points: &Signal) -> Result<Option<Vec<f64>>> {
        let b = &self.blocks[block];
        let total = points.len();
        if total == 0 {
            return Ok(Some(Vec::new()));
        }
        let Some(diag) = b.penalty.diagonal_at(points) else {
            return Ok(None);
        };
        let nk = self.kept.len();
        let l = self.factor.as_ref().submatrix(0, 0, nk, nk);
        let par = faer::get_global_parallelism();
        let width = BATCH.min(total);
        let mut kz = Mat::<f64>::zeros(self.len, width);
        let mut v = Mat::<f64>::zeros(self.rows, width);
        let mut q = Mat::<f64>::zeros(nk, width);
        let mut out = Vec::with_capacity(total);
        for start in (0..total).step_by(BATCH) {
            let g = BATCH.min(total - start);
            let pts = points.slice(start..start + g);
            // k_z for each point, through the block's path: v = T_i·k_z.
            if !b.penalty.cross_columns(&pts, kz.as_mut().subcols_mut(0, g)) {
                return Ok(None);
            }
            b.path.apply_columns(
                kz.as_ref().subcols(0, g),
                v.as_mut().subcols_mut(0, g),
                Accum::Replace,
                1.0,
            );
            let mut qg = q.as_mut().subcols_mut(0, g);
            for j in 0..g {
                for (ii, &i) in self.kept.iter().enumerate() {
                    qg[(ii, j)] = v[(i, j)];
                }
            }
            solve_lower_triangular_in_place(l, qg.rb_mut(), par);
            for j in 0..g {
                let col = qg.rb().col(j);
                let mut explained: f64 = col.iter().map(|x| x * x).sum();
                if let Some(u) = &self.free_basis {
                    // vᵀPv = |L⁻¹v|² − |Uᵀ·L⁻¹v|² (flat prior on x₀).
                    for c in 0..u.ncols() {
                        let p: f64 = u.col(c).iter().zip(col.iter()).map(|(a, b)| a * b).sum();
                        explained -= p * p;
                    }
                }
                out.push(self.scale * (diag[start + j] - explained));
            }
        }
        if out.iter().any(|v| !v.is_finite()) {
            return Err(Error::Numerical(
                "the posterior variance is not finite at some points".into(),
            ));
        }
        Ok(Some(out))
    }
}

impl Features {
    fn variance(&self, block: usize, points: &Signal, s2: f64) -> Vec<f64> {
        let b = &self.blocks[block];
        let k = self.factor.nrows();
        let m = b.sqrt_weights.len();
        let par = faer::get_global_parallelism();
        let total = points.len();
        let mut out = Vec::with_capacity(total);
        let mut psi = vec![0.0; m];
        let mut rhs = Mat::<f64>::zeros(k, BATCH.min(total));
        for start in (0..total).step_by(BATCH) {
            let g = BATCH.min(total - start);
            let mut x = rhs.as_mut().subcols_mut(0, g);
            x.fill(0.0);
            for j in 0..g {
                b.map.eval_into(points.sample(start + j), &mut psi);
                for a in 0..m {
                    x[(b.offset + a, j)] = b.sqrt_weights[a] * psi[a];
                }
            }
            solve_lower_triangular_in_place(self.factor.as_ref(), x.rb_mut(), par);
            for j in 0..g {
                out.push(s2 * x.rb().col(j).iter().map(|v| v * v).sum::<f64>());
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dispersion::fourier::{FourierDispersion, FourierWeights};
    use crate::dispersion::low_rank::LowRankGaussian;
    use crate::dispersion::{Dispersion, KernelDispersion, quadratic_penalty};

    #[test]
    fn cross_columns_and_diagonal_match_the_kernel_for_every_quadratic_penalty() {
        for p in [1, 2] {
            let z = Signal::from_fn(40, p, |k, c| ((k * 7 + c * 3) % 13) as f64 / 6.0 - 1.0);
            let pts = Signal::from_fn(9, p, |k, c| -0.9 + 0.2 * k as f64 + 0.05 * c as f64);
            let dispersions: Vec<Box<dyn Dispersion>> = vec![
                Box::new(KernelDispersion::gaussian(0.4).unwrap()),
                Box::new(
                    FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.4 }).unwrap(),
                ),
                Box::new(LowRankGaussian::new(0.4, 1e-10).unwrap()),
            ];
            for d in &dispersions {
                let pen = quadratic_penalty(d.as_ref(), &z);
                let mut cross = Mat::<f64>::zeros(40, 9);
                assert!(pen.cross_columns(&pts, cross.as_mut()));
                // The cross-Gram against the samples themselves is the Gram matrix.
                let mut gram = Mat::<f64>::zeros(40, 40);
                pen.fill(gram.as_mut());
                let mut self_cross = Mat::<f64>::zeros(40, 40);
                assert!(pen.cross_columns(&z, self_cross.as_mut()));
                let scale = (0..40).map(|i| gram[(i, i)]).fold(0.0, f64::max);
                for i in 0..40 {
                    for j in 0..40 {
                        assert!(
                            (gram[(i, j)] - self_cross[(i, j)]).abs() < 1e-11 * scale,
                            "{} p={p}",
                            d.describe()
                        );
                    }
                }
                let diag = pen.diagonal_at(&pts).unwrap();
                let diag_z = pen.diagonal_at(&z).unwrap();
                for i in 0..40 {
                    assert!((diag_z[i] - gram[(i, i)]).abs() < 1e-11 * scale);
                }
                assert!(diag.iter().all(|v| *v > 0.0));
                // Wrong shapes are refused, not a panic.
                let wrong = Signal::zeros(3, p + 1);
                assert!(!pen.cross_columns(&wrong, Mat::<f64>::zeros(40, 3).as_mut()));
                assert!(!pen.cross_columns(&pts, Mat::<f64>::zeros(39, 9).as_mut()));
                assert!(pen.diagonal_at(&wrong).is_none());
            }
        }
    }

    #[test]
    fn bad_points_are_typed_errors() {
        assert!(matches!(
            check_points(&Signal::zeros(2, 2), 1),
            Err(Error::DimensionMismatch { .. })
        ));
        let nan = Signal::from_fn(3, 1, |k, _| if k == 2 { f64::NAN } else { 0.0 });
        assert!(matches!(
            check_points(&nan, 1),
            Err(Error::NonFiniteData { sample: 2, .. })
        ));
        assert!(check_points(&Signal::zeros(0, 0), 3).is_ok());
    }
}

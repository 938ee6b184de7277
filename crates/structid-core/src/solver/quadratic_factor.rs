//! A quadratic block as a linear map of finitely many coefficients, for the ADMM solver of
//! mixed models: w = Ψ̃·η with D(w) = ‖η‖², Ψ̃ an L × k matrix with K = Ψ̃Ψ̃ᵀ (exactly, or up to a
//! certified residual).
//!
//! * A block with features (Fourier, polynomial, Nyström, sums of them), K = ΨΛΨᵀ, uses the
//!   whitened features Ψ̃ = Ψ·Λ^½: the problem is the one the feature and exact solvers solve,
//!   with no approximation, and the map is the feature expansion with coefficients Λ^½·η.
//! * Any other kernel (a plain Gaussian, say) is factored by a pivoted Cholesky factorisation of
//!   its Gram matrix, computed column by column from [`QuadraticPenalty::fill_columns`] (O(L·k²)
//!   time, L·k memory, never the L × L matrix): greedy pivoting on the residual diagonal until
//!   its largest entry is at most [`PIVOT_TOLERANCE`] times the largest diagonal entry of K,
//!   i.e. until the factor reproduces K to rounding. Then Ψ̃ = K_{:,P}·L_PP⁻ᵀ (L_PP the pivot
//!   rows), so w = K·α with α zero except α_P = L_PP⁻ᵀ·η, and D = αᵀKα = ‖η‖²: the map is the
//!   kernel expansion on the pivots, and the solution is the exact problem's up to the
//!   residual of the factor (directions of w on which K is below rounding, which the penalty
//!   wᵀK⁻¹w forbids anyway).

use std::sync::Arc;

use structid_lti::Signal;

use crate::dispersion::fourier::FeatureExpansion;
use crate::dispersion::{FeatureMap, QuadraticPenalty};
use crate::error::{Error, Result};
use crate::solver::BlockPart;

/// The pivoted Cholesky factorisation stops when the largest residual diagonal entry is at most
/// this times the largest diagonal entry of K (the factor then reproduces K to rounding).
pub const PIVOT_TOLERANCE: f64 = 1e-14;

/// How the coefficients η map back to the block's function.
enum Kind {
    /// Features ψ with Ψ̃ = Ψ·Λ^½: the expansion's coefficients are Λ^½·η.
    Features {
        map: Arc<dyn FeatureMap>,
        sqrt_weights: Vec<f64>,
    },
    /// Pivoted Cholesky: α_P = L_PP⁻ᵀ·η on the pivots P.
    Pivoted {
        pivots: Vec<usize>,
        /// L_PP (k × k, row-major, lower triangular).
        lpp: Vec<f64>,
    },
}

/// A quadratic block's factor Ψ̃ (L × k) with K ≈ Ψ̃Ψ̃ᵀ; see the module documentation.
pub(crate) struct QuadraticFactor {
    /// Ψ̃, row-major (L × k).
    pub(crate) rows: Vec<f64>,
    /// k.
    pub(crate) rank: usize,
    /// The largest residual diagonal entry of K − Ψ̃Ψ̃ᵀ relative to the largest of K (0 for
    /// features).
    pub(crate) residual: f64,
    /// Whether the factorisation stopped at its rank limit before reaching the tolerance.
    pub(crate) capped: bool,
    kind: Kind,
}

impl QuadraticFactor {
    /// The factor of `pen` at the sample points `z` with at most `max_rank` columns.
    ///
    /// # Errors
    /// [`Error::Unsupported`] when the penalty has no features, cannot evaluate its diagonal and
    /// the record is too long to read it off its columns.
    pub(crate) fn new(
        pen: &dyn QuadraticPenalty,
        z: &Signal,
        max_rank: usize,
        name: &str,
    ) -> Result<Self> {
        let len = pen.len();
        if let Some((map, points)) = pen.features()
            && map.dim() <= max_rank
            && points.len() == len
        {
            let m = map.dim();
            let sqrt_weights: Vec<f64> = map.weights().iter().map(|l| l.max(0.0).sqrt()).collect();
            let mut rows = vec![0.0; len * m];
            for (k, row) in rows.chunks_mut(m.max(1)).enumerate().take(len) {
                map.eval_into(points.sample(k), row);
                row.iter_mut().zip(&sqrt_weights).for_each(|(v, s)| *v *= s);
            }
            return Ok(Self {
                rows,
                rank: m,
                residual: 0.0,
                capped: false,
                kind: Kind::Features { map, sqrt_weights },
            });
        }
        let diag = match pen.diagonal_at(z) {
            Some(d) if d.len() == len => d,
            _ if len <= DIAGONAL_BY_COLUMNS => {
                let mut col = faer::Mat::<f64>::zeros(len, 1);
                (0..len)
                    .map(|j| {
                        pen.fill_columns(j..j + 1, col.as_mut());
                        col[(j, 0)]
                    })
                    .collect()
            }
            _ => {
                return Err(Error::Unsupported(format!(
                    "the admm solver factors the Gram matrix of block `{name}` column by column and needs its \
                     diagonal, which this kernel cannot evaluate; give the block finitely many features \
                     (fourier, low-rank gaussian, polynomial) or use a record of at most \
                     {DIAGONAL_BY_COLUMNS} samples"
                )));
            }
        };
        Ok(Self::pivoted(pen, &diag, max_rank))
    }

    /// Pivoted (partial) Cholesky factorisation from the diagonal and single columns of K.
    fn pivoted(pen: &dyn QuadraticPenalty, diag: &[f64], max_rank: usize) -> Self {
        let len = diag.len();
        let top = diag.iter().copied().fold(0.0f64, f64::max);
        let mut resid: Vec<f64> = diag.iter().map(|d| d.max(0.0)).collect();
        let mut cols: Vec<Vec<f64>> = Vec::new();
        let mut pivots: Vec<usize> = Vec::new();
        let mut col = faer::Mat::<f64>::zeros(len, 1);
        let mut capped = false;
        let tol = PIVOT_TOLERANCE * top;
        while let Some((p, &rp)) = resid.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) {
            // NaN or at most the tolerance: done.
            if rp.is_nan() || rp <= tol {
                break;
            }
            if pivots.len() >= max_rank.min(len) {
                capped = true;
                break;
            }
            pen.fill_columns(p..p + 1, col.as_mut());
            let mut c: Vec<f64> = (0..len).map(|i| col[(i, 0)]).collect();
            for prev in &cols {
                let f = prev[p];
                if f != 0.0 {
                    c.iter_mut().zip(prev).for_each(|(ci, pi)| *ci -= f * pi);
                }
            }
            let s = 1.0 / rp.sqrt();
            c.iter_mut().for_each(|v| *v *= s);
            // Earlier pivots are exactly reproduced: their entries are zero by construction.
            for &q in &pivots {
                c[q] = 0.0;
            }
            c[p] = rp.sqrt();
            resid.iter_mut().zip(&c).for_each(|(r, v)| *r -= v * v);
            resid[p] = 0.0;
            for &q in &pivots {
                resid[q] = 0.0;
            }
            pivots.push(p);
            cols.push(c);
        }
        let k = pivots.len();
        let mut rows = vec![0.0; len * k];
        for (j, c) in cols.iter().enumerate() {
            for (i, v) in c.iter().enumerate() {
                rows[i * k + j] = *v;
            }
        }
        let mut lpp = vec![0.0; k * k];
        for (a, &p) in pivots.iter().enumerate() {
            for b in 0..=a {
                lpp[a * k + b] = rows[p * k + b];
            }
        }
        let residual = if top > 0.0 {
            resid.iter().copied().fold(0.0f64, f64::max) / top
        } else {
            0.0
        };
        Self {
            rows,
            rank: k,
            residual,
            capped,
            kind: Kind::Pivoted { pivots, lpp },
        }
    }

    /// Whether the factor came from the block's features (no approximation).
    #[cfg(test)]
    pub(crate) fn is_featured(&self) -> bool {
        matches!(self.kind, Kind::Features { .. })
    }

    /// w = Ψ̃·η at the samples.
    pub(crate) fn values(&self, eta: &[f64]) -> Vec<f64> {
        let k = self.rank;
        if k == 0 {
            return vec![0.0; self.rows.len()];
        }
        self.rows
            .chunks_exact(k)
            .map(|r| r.iter().zip(eta).map(|(a, b)| a * b).sum())
            .collect()
    }

    /// The block's part (ŵ, D = ‖η‖², the map) for the coefficients η.
    pub(crate) fn part(&self, pen: &dyn QuadraticPenalty, eta: &[f64], len: usize) -> BlockPart {
        let mut w_hat = self.values(eta);
        w_hat.resize(len, 0.0);
        let dispersion_value = eta.iter().map(|v| v * v).sum();
        let map: Box<dyn crate::model::interpolant::Interpolant> = match &self.kind {
            Kind::Features { map, sqrt_weights } => Box::new(FeatureExpansion::new(
                Arc::clone(map),
                eta.iter().zip(sqrt_weights).map(|(e, s)| e * s).collect(),
            )),
            Kind::Pivoted { pivots, lpp } => {
                // L_PPᵀ·α_P = η, back substitution (L_PP lower triangular).
                let k = pivots.len();
                let mut a = eta.to_vec();
                for i in (0..k).rev() {
                    let mut s = a[i];
                    for j in i + 1..k {
                        s -= lpp[j * k + i] * a[j];
                    }
                    a[i] = s / lpp[i * k + i];
                }
                let mut alpha = vec![0.0; len];
                for (&p, v) in pivots.iter().zip(a) {
                    alpha[p] = v;
                }
                pen.interpolant(alpha)
            }
        };
        BlockPart {
            w_hat,
            dispersion_value,
            map,
        }
    }
}

/// Longest record whose Gram diagonal is read off single columns when the kernel cannot
/// evaluate it directly (O(L²) kernel evaluations).
const DIAGONAL_BY_COLUMNS: usize = 20_000;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dispersion::quadratic_penalty;
    use crate::{KernelDispersion, PolynomialDispersion};

    #[test]
    fn pivoted_factor_reproduces_the_gram_matrix_and_its_interpolant() {
        let len = 300;
        let z = Signal::from_fn(len, 1, |k, _| {
            ((k as f64 * 0.754_877_666).fract() - 0.5) * 4.0
        });
        let pen = quadratic_penalty(&KernelDispersion::gaussian(0.5).unwrap(), &z);
        let f = QuadraticFactor::new(pen.as_ref(), &z, 1000, "f").unwrap();
        assert!(
            !f.is_featured() && !f.capped && f.rank < 60,
            "rank {}",
            f.rank
        );
        let mut gram = faer::Mat::<f64>::zeros(len, len);
        pen.fill(gram.as_mut());
        let k = f.rank;
        let mut err = 0.0f64;
        for i in 0..len {
            for j in 0..len {
                let approx: f64 = (0..k).map(|l| f.rows[i * k + l] * f.rows[j * k + l]).sum();
                err = err.max((approx - gram[(i, j)]).abs());
            }
        }
        assert!(err < 1e-10, "{err}");
        let eta: Vec<f64> = (0..k).map(|l| (l as f64 * 0.37).sin()).collect();
        let part = f.part(pen.as_ref(), &eta, len);
        for i in (0..len).step_by(7) {
            let v = part.map.eval(z.sample(i));
            assert!(
                (v - part.w_hat[i]).abs() < 1e-7,
                "{i}: {v} vs {}",
                part.w_hat[i]
            );
        }
    }

    #[test]
    fn features_give_an_exact_factor() {
        let len = 50;
        let z = Signal::from_fn(len, 1, |k, _| k as f64 / 49.0 - 0.5);
        let pen = quadratic_penalty(&PolynomialDispersion::new(3).unwrap(), &z);
        let f = QuadraticFactor::new(pen.as_ref(), &z, 100, "f").unwrap();
        assert!(f.is_featured());
        assert_eq!(f.rank, 4);
        let part = f.part(pen.as_ref(), &[1.0, 0.5, -0.25, 0.125], len);
        for i in 0..len {
            assert!((part.map.eval(z.sample(i)) - part.w_hat[i]).abs() < 1e-12);
        }
    }
}

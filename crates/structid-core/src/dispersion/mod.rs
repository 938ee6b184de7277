//! Dispersion functions D(z, w): how complex it is to interpolate the points (z_k, w_k).
//!
//! A dispersion is turned into a [`Penalty`] once the sample points z are known. The penalty is
//! what a solver sees; its kind (quadratic, or graph total variation) decides which
//! solvers can handle it, so [`crate::identify()`] never needs to know the concrete dispersion type.

pub mod fourier;
pub mod graph;
pub mod kernel;
pub mod low_rank;
pub mod neighbours;
pub mod polynomial;
pub mod sum;
pub mod total_variation;
pub mod user;

use std::fmt;
use std::ops::Range;
use std::sync::Arc;

use structid_lti::Signal;

use crate::dispersion::graph::TvPenalty;
use crate::dispersion::kernel::{GaussianKernel, Kernel, KernelExpansion};
use crate::error::Result;
use crate::model::interpolant::Interpolant;

/// A dispersion function D(z, w) for one nonlinear block.
pub trait Dispersion: Send + Sync + fmt::Debug {
    /// A short description, e.g. `gaussian(sigma=0.4)`.
    fn describe(&self) -> String;

    /// Named numeric parameters for reports (σ, …).
    fn parameters(&self) -> Vec<(String, f64)> {
        Vec::new()
    }

    /// The penalty on w once the block's inputs `z` (one point per sample) are fixed.
    fn penalty(&self, z: &Signal) -> Result<Penalty>;

    /// The width σ of a dispersion that has one (a length scale in units of z), for
    /// automatic selection ([`crate::selection`]); `None` (the default) when it has none.
    fn width(&self) -> Option<f64> {
        None
    }

    /// The same dispersion with width `width` (> 0); `None` (the default) when it has no width.
    fn with_width(&self, width: f64) -> Option<Result<Arc<dyn Dispersion>>> {
        let _ = width;
        None
    }

    /// The user-defined kernels and feature maps the dispersion is built on (those whose
    /// stored form is [`crate::stored::StoredKernel::User`]), so that an estimate made with it
    /// keeps them ([`user`]); empty (the default) for the built-in dispersions.
    fn user_kernels(&self) -> user::UserKernels {
        user::UserKernels::new()
    }
}

/// What a dispersion looks like to a solver once its sample points are fixed.
#[non_exhaustive]
pub enum Penalty {
    /// D(w) = wᵀK⁻¹w for a positive semi-definite Gram matrix K (an RKHS norm). Solvers use K
    /// only through its columns and never invert it.
    Quadratic(Box<dyn QuadraticPenalty>),
    /// D(w) = Σ_(a,b)∈E c_ab·|v_a − v_b|, a graph total variation on node values (a conic,
    /// non-smooth penalty): see [`crate::dispersion::total_variation`].
    TotalVariation(TvPenalty),
}

impl fmt::Debug for Penalty {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Penalty::Quadratic(q) => write!(f, "Quadratic(len = {})", q.len()),
            Penalty::TotalVariation(p) => write!(f, "TotalVariation({p:?})"),
        }
    }
}

/// The quadratic penalty of `d` at the points `z`, for tests of what only quadratic penalties
/// have; panics for any other penalty.
#[cfg(test)]
pub(crate) fn quadratic_penalty(d: &dyn Dispersion, z: &Signal) -> Box<dyn QuadraticPenalty> {
    match d.penalty(z).unwrap() {
        Penalty::Quadratic(q) => q,
        other => panic!("expected a quadratic penalty, got {other:?}"),
    }
}

/// [`FeatureMap::eval_rows`] by [`FeatureMap::eval_into`], one sample at a time: the
/// trait's default, and what a map with a faster evaluation falls back to where that does not
/// apply.
pub(crate) fn eval_rows_by_sample<M: FeatureMap + ?Sized>(
    map: &M,
    z: &Signal,
    t0: usize,
    scale: &[f64],
    rows: &mut [f64],
) {
    let m = map.dim();
    for (k, row) in rows.chunks_exact_mut(m).enumerate() {
        map.eval_into(z.sample(t0 + k), row);
        row.iter_mut().zip(scale).for_each(|(v, s)| *v *= s);
    }
}

/// [`FeatureMap::eval_cols`] by whole rows of [`FeatureMap::eval_rows`], keeping the columns
/// `cols`: the trait's default, and what a map with a faster evaluation falls back to where
/// that does not apply.
pub(crate) fn eval_cols_by_rows<M: FeatureMap + ?Sized>(
    map: &M,
    z: &Signal,
    t0: usize,
    cols: Range<usize>,
    scale: &[f64],
    rows: &mut [f64],
) {
    let (m, w) = (map.dim(), cols.len());
    if w == 0 {
        return;
    }
    let mut full = vec![0.0; m];
    for (k, row) in rows.chunks_exact_mut(w).enumerate() {
        map.eval_rows(z, t0 + k, scale, &mut full);
        row.copy_from_slice(&full[cols.clone()]);
    }
}

/// Gram columns per panel of [`QuadraticPenalty::gram_times`] (narrow: the panel adds to the
/// exact solver's L×L memory).
const GRAM_TIMES_PANEL: usize = 64;

/// A quadratic penalty wᵀK⁻¹w given through its Gram matrix K (L × L).
pub trait QuadraticPenalty: Send + Sync {
    /// Number of sample points L.
    fn len(&self) -> usize;

    /// Whether there are no samples.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Writes columns `cols` of K into `out` ([`QuadraticPenalty::len`] × `cols.len()`, any
    /// layout; solvers pass row-major panels).
    fn fill_columns(&self, cols: Range<usize>, out: faer::MatMut<'_, f64>);

    /// Writes the whole K (L × L) into `out`; override to exploit symmetry.
    fn fill(&self, out: faer::MatMut<'_, f64>) {
        self.fill_columns(0..self.len(), out);
    }

    /// K·α (L values) without storing K: by default from panels of
    /// [`QuadraticPenalty::fill_columns`]; override to exploit symmetry.
    fn gram_times(&self, alpha: &[f64]) -> Vec<f64> {
        let len = self.len();
        let panel = GRAM_TIMES_PANEL.min(len).max(1);
        let mut out = vec![0.0; len];
        let mut scratch = vec![0.0; len * panel];
        for j0 in (0..len).step_by(panel) {
            let w = panel.min(len - j0);
            let g = &mut scratch[..len * w];
            self.fill_columns(
                j0..j0 + w,
                faer::MatMut::from_row_major_slice_mut(g, len, w),
            );
            let a = &alpha[j0..j0 + w];
            for (o, row) in out.iter_mut().zip(g.chunks_exact(w)) {
                *o += row.iter().zip(a).map(|(x, y)| x * y).sum::<f64>();
            }
        }
        out
    }

    /// The interpolant N̂(z) = Σ_k α_k K(z, z_k) for the dual coefficients α (ŵ = Kα).
    fn interpolant(&self, alpha: Vec<f64>) -> Box<dyn Interpolant>;

    /// The finite feature form K = ΨΛΨᵀ with the sample points, when the penalty has one. Solvers
    /// that work in feature space (cost linear in L) use it.
    fn features(&self) -> Option<(Arc<dyn FeatureMap>, &Signal)> {
        None
    }

    /// Writes the cross-Gram matrix K(z_k, p_j) between the sample points z_k (rows, L of
    /// them) and new points p_j (columns, one per sample of `points`) into `out`
    /// ([`QuadraticPenalty::len`] × `points.len()`, any layout). Returns `false`, leaving `out`
    /// unspecified, when the penalty cannot evaluate its kernel away from the samples (the
    /// default) or when `points` has the wrong number of channels or `out` the wrong shape.
    ///
    /// The posterior band of the exact solver ([`crate::identify::posterior`]) needs it; every penalty of
    /// this crate's quadratic dispersions implements it.
    ///
    /// ```
    /// use structid_core::{Dispersion, KernelDispersion, Penalty, Signal};
    /// let z = Signal::from_fn(5, 1, |k, _| k as f64 / 4.0);
    /// let Penalty::Quadratic(pen) = KernelDispersion::gaussian(0.3).unwrap().penalty(&z).unwrap()
    /// else { unreachable!() };
    /// let points = Signal::from_fn(2, 1, |k, _| 0.1 + k as f64);
    /// let mut out = faer::Mat::<f64>::zeros(5, 2);
    /// assert!(pen.cross_columns(&points, out.as_mut()));
    /// assert!(out[(0, 0)] > out[(4, 0)]);
    /// ```
    fn cross_columns(&self, points: &Signal, out: faer::MatMut<'_, f64>) -> bool {
        let _ = (points, out);
        false
    }

    /// The kernel's diagonal k(p, p) at every sample of `points`, or `None` when the penalty
    /// cannot evaluate its kernel away from the samples (the default) or `points` has the
    /// wrong number of channels.
    ///
    /// ```
    /// use structid_core::{Dispersion, KernelDispersion, Penalty, Signal};
    /// let z = Signal::from_fn(5, 1, |k, _| k as f64);
    /// let Penalty::Quadratic(pen) = KernelDispersion::gaussian(0.5).unwrap().penalty(&z).unwrap()
    /// else { unreachable!() };
    /// let d = pen.diagonal_at(&Signal::from_fn(3, 1, |k, _| k as f64)).unwrap();
    /// assert!((d[2] - 1.0 / (2.0 * std::f64::consts::PI * 0.25).sqrt()).abs() < 1e-14);
    /// ```
    fn diagonal_at(&self, points: &Signal) -> Option<Vec<f64>> {
        let _ = points;
        None
    }
}

/// A finite feature map ψ: ℝᵖ → ℝᵐ with weights λ (the diagonal of Λ), defining the kernel
/// K(z₁, z₂) = Σ_j λ_j·ψ_j(z₁)·ψ_j(z₂) and the dispersion D = aᵀΛ⁻¹a of the map w = ψᵀa.
pub trait FeatureMap: Send + Sync {
    /// Number of features m.
    fn dim(&self) -> usize;

    /// The weights λ_j > 0.
    fn weights(&self) -> &[f64];

    /// Writes ψ(z) into `out` (length m).
    fn eval_into(&self, z: &[f64], out: &mut [f64]);

    /// Writes the scaled features `scale_j·ψ_j(z_t)` of the samples `t = t0, t0 + 1, …` of `z`
    /// into the rows of the row-major `rows` (m values per sample, `rows.len() / m` samples).
    /// The default evaluates [`eval_into`](Self::eval_into) sample by sample; a map with a
    /// faster batched evaluation overrides it with the same values.
    fn eval_rows(&self, z: &Signal, t0: usize, scale: &[f64], rows: &mut [f64]) {
        eval_rows_by_sample(self, z, t0, scale, rows)
    }

    /// [`eval_rows`](Self::eval_rows) for the features `cols` only: writes
    /// `scale_j·ψ_j(z_t)` for `j` in `cols` into the rows of the row-major `rows`
    /// (`cols.len()` values per sample; `scale` has all m weights). The feature solver's
    /// threads evaluate the columns each of them pushes through the paths, so that no
    /// evaluated feature crosses between cores. The default evaluates whole rows with
    /// [`eval_rows`](Self::eval_rows) and keeps the columns asked for; the values are the
    /// same.
    fn eval_cols(
        &self,
        z: &Signal,
        t0: usize,
        cols: Range<usize>,
        scale: &[f64],
        rows: &mut [f64],
    ) {
        eval_cols_by_rows(self, z, t0, cols, scale, rows)
    }

    /// Values per sample that [`prepare_rows`](Self::prepare_rows) writes: the part of the
    /// evaluation that every column range needs (a one-input Fourier map's cos and sin of 2πt),
    /// so that the feature solver's threads, which evaluate different columns of the same
    /// samples, compute it once between them. 0 (the default): nothing is shared.
    fn prepared_len(&self) -> usize {
        0
    }

    /// Writes [`prepared_len`](Self::prepared_len) values per sample for the samples
    /// `t = t0, t0 + 1, …` of `z` into `out` (`out.len() / prepared_len` samples), for
    /// [`eval_cols_prepared`](Self::eval_cols_prepared). The default writes nothing.
    fn prepare_rows(&self, z: &Signal, t0: usize, out: &mut [f64]) {
        let _ = (z, t0, out);
    }

    /// [`eval_cols`](Self::eval_cols) from the values [`prepare_rows`](Self::prepare_rows)
    /// wrote for the same samples; the same values as `eval_cols`, bit for bit. The default
    /// ignores `prepared` and calls `eval_cols`.
    fn eval_cols_prepared(
        &self,
        z: &Signal,
        t0: usize,
        cols: Range<usize>,
        scale: &[f64],
        prepared: &[f64],
        rows: &mut [f64],
    ) {
        let _ = prepared;
        self.eval_cols(z, t0, cols, scale, rows)
    }

    /// Writes `Σ_j coef_j·ψ_j(z_t)` for the samples `t = t0, …, t0 + out.len() − 1` of `z`
    /// into `out` (the map's value at each sample for the coefficients `coef`, m values). The
    /// default evaluates [`eval_into`](Self::eval_into) sample by sample and sums in feature
    /// order; a faster override returns the same values.
    fn combine_rows(&self, z: &Signal, t0: usize, coef: &[f64], out: &mut [f64]) {
        let mut psi = vec![0.0; self.dim()];
        for (k, o) in out.iter_mut().enumerate() {
            self.eval_into(z.sample(t0 + k), &mut psi);
            *o = psi.iter().zip(coef).map(|(p, c)| p * c).sum();
        }
    }

    /// The weights λ of the same features at another kernel width, when only the weights
    /// depend on the width (as for the Gaussian-like Fourier family); `None` (the default)
    /// otherwise. Width selection then reuses one pass over the data for every width tried.
    fn weights_at_width(&self, width: f64) -> Option<Vec<f64>> {
        let _ = width;
        None
    }

    /// The feature map as plain data ([`crate::stored::StoredKernel`]), so that a feature
    /// expansion on it can be stored in an [`crate::estimate::Estimate`]; `None` (the default)
    /// for a feature map without a stored form.
    fn stored_features(&self) -> Option<crate::stored::StoredKernel> {
        None
    }
}

/// K(a, b) = ψ(a)ᵀΛψ(b) of a feature map: the [`Kernel::eval`] of a kernel that is given by
/// its features.
pub(crate) fn feature_kernel(map: &dyn FeatureMap, a: &[f64], b: &[f64]) -> f64 {
    let m = map.dim();
    let (mut pa, mut pb) = (vec![0.0; m], vec![0.0; m]);
    map.eval_into(a, &mut pa);
    map.eval_into(b, &mut pb);
    pa.iter()
        .zip(&pb)
        .zip(map.weights())
        .map(|((x, y), l)| x * y * l)
        .sum()
}

/// Any [`Kernel`] as a quadratic dispersion: D(z, w) = wᵀK⁻¹w with K_ij = k(z_i, z_j).
///
/// ```
/// use structid_core::{Dispersion, GaussianKernel, KernelDispersion};
/// let d = KernelDispersion::gaussian(0.4).unwrap();
/// assert_eq!(d.describe(), "gaussian(sigma=0.4)");
/// ```
#[derive(Debug, Clone)]
pub struct KernelDispersion<K: Kernel> {
    kernel: Arc<K>,
}

impl<K: Kernel + 'static> KernelDispersion<K> {
    /// Wraps a kernel.
    pub fn new(kernel: K) -> Self {
        Self {
            kernel: Arc::new(kernel),
        }
    }

    /// The kernel.
    pub fn kernel(&self) -> &K {
        &self.kernel
    }
}

impl KernelDispersion<GaussianKernel> {
    /// The Gaussian RKHS dispersion of width `sigma` (> 0).
    pub fn gaussian(sigma: f64) -> Result<Self> {
        Ok(Self::new(GaussianKernel::new(sigma)?))
    }
}

impl<K: Kernel + 'static> Dispersion for KernelDispersion<K> {
    fn describe(&self) -> String {
        self.kernel.describe()
    }

    fn parameters(&self) -> Vec<(String, f64)> {
        self.kernel.parameters()
    }

    fn width(&self) -> Option<f64> {
        self.kernel.width()
    }

    fn with_width(&self, width: f64) -> Option<Result<Arc<dyn Dispersion>>> {
        self.kernel.with_width(width).map(|k| {
            k.map(|k| {
                Arc::new(KernelDispersion {
                    kernel: Arc::new(k),
                }) as Arc<dyn Dispersion>
            })
        })
    }

    fn penalty(&self, z: &Signal) -> Result<Penalty> {
        Ok(Penalty::Quadratic(Box::new(KernelGram {
            kernel: Arc::clone(&self.kernel),
            z: z.clone(),
        })))
    }

    fn user_kernels(&self) -> user::UserKernels {
        user::user_kernel_of(&self.kernel)
    }
}

struct KernelGram<K: Kernel> {
    kernel: Arc<K>,
    z: Signal,
}

impl<K: Kernel + 'static> QuadraticPenalty for KernelGram<K> {
    fn len(&self) -> usize {
        self.z.len()
    }

    fn fill_columns(&self, cols: Range<usize>, out: faer::MatMut<'_, f64>) {
        self.kernel.fill_gram_columns(&self.z, cols, out);
    }

    fn fill(&self, out: faer::MatMut<'_, f64>) {
        self.kernel.fill_gram(&self.z, out);
    }

    /// Half the kernel evaluations of the default: each panel of columns j₀..j₀+w is evaluated
    /// on rows 0..j₀+w only (the kernel on the leading samples), and the entries above the
    /// panel's diagonal block also stand for their mirror images K_ji = K_ij.
    fn gram_times(&self, alpha: &[f64]) -> Vec<f64> {
        let len = self.z.len();
        let p = self.z.channels();
        let panel = GRAM_TIMES_PANEL.min(len).max(1);
        let mut out = vec![0.0; len];
        let mut scratch = vec![0.0; len * panel];
        let data = self.z.as_slice();
        for j0 in (0..len).step_by(panel) {
            let w = panel.min(len - j0);
            let rows = j0 + w;
            let lead = Signal::new(p, data[..rows * p].to_vec())
                .expect("a prefix of a signal is a signal");
            let g = &mut scratch[..rows * w];
            self.kernel.fill_gram_columns(
                &lead,
                j0..j0 + w,
                faer::MatMut::from_row_major_slice_mut(g, rows, w),
            );
            let a = &alpha[j0..j0 + w];
            let (above, block) = g.split_at(j0 * w);
            let mut back = vec![0.0; w];
            for (i, row) in above.chunks_exact(w).enumerate() {
                out[i] += row.iter().zip(a).map(|(x, y)| x * y).sum::<f64>();
                let ai = alpha[i];
                back.iter_mut().zip(row).for_each(|(b, x)| *b += x * ai);
            }
            for (ii, row) in block.chunks_exact(w).enumerate() {
                out[j0 + ii] += row.iter().zip(a).map(|(x, y)| x * y).sum::<f64>();
            }
            out[j0..j0 + w]
                .iter_mut()
                .zip(&back)
                .for_each(|(o, b)| *o += b);
        }
        out
    }

    fn interpolant(&self, alpha: Vec<f64>) -> Box<dyn Interpolant> {
        Box::new(KernelExpansion::new(
            Arc::clone(&self.kernel),
            self.z.clone(),
            alpha,
        ))
    }

    fn cross_columns(&self, points: &Signal, out: faer::MatMut<'_, f64>) -> bool {
        if points.channels() != self.z.channels()
            || out.nrows() != self.z.len()
            || out.ncols() != points.len()
        {
            return false;
        }
        self.kernel.fill_cross(&self.z, points, out);
        true
    }

    fn diagonal_at(&self, points: &Signal) -> Option<Vec<f64>> {
        (points.channels() == self.z.channels()).then(|| {
            (0..points.len())
                .map(|j| self.kernel.eval(points.sample(j), points.sample(j)))
                .collect()
        })
    }
}

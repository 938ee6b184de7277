//! Sums of quadratic dispersions: the kernel K = K₁ + K₂ + … of independent parts.
//!
//! If N = N₁ + N₂ with N_i in the RKHS of K_i, the smallest combined norm of a map is the RKHS
//! norm of K₁ + K₂, so D(z, w) = wᵀ(K₁ + K₂)⁻¹w and every solver works unchanged. The typical
//! use is semi-parametric: a stationary kernel (Gaussian, Fourier) plus a
//! [`crate::PolynomialDispersion`] trend that carries the estimate outside the data.
//!
//! When every part has finite features, the sum has the stacked features
//! ψ = [ψ₁; ψ₂; …] with Λ = diag(Λ₁, Λ₂, …), so the feature solver (cost linear in L) and
//! feature-space hyperparameter selection apply. Otherwise the Gram matrices are added.
//!
//! The width (σ) of the sum is that of its first part that has one; automatic σ selection
//! changes that part only.

use std::fmt;
use std::ops::Range;
use std::sync::Arc;

use faer::Mat;
use structid_lti::Signal;

use crate::dispersion::fourier::FeaturePenalty;
use crate::dispersion::kernel::Kernel;
use crate::dispersion::{Dispersion, FeatureMap, Penalty, QuadraticPenalty};
use crate::error::{Error, Result};
use crate::model::interpolant::Interpolant;

/// The dispersion of the kernel K₁ + K₂ + … of quadratic dispersions.
///
/// ```
/// use std::sync::Arc;
/// use structid_core::{
///     Dispersion, FourierDispersion, FourierWeights, Penalty, PolynomialDispersion, Signal,
///     SumDispersion,
/// };
/// let fourier = FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.1 }).unwrap();
/// let d = SumDispersion::new(vec![
///     Arc::new(fourier),
///     Arc::new(PolynomialDispersion::new(3).unwrap()),
/// ])
/// .unwrap();
/// assert_eq!(d.width(), Some(0.1));
/// let z = Signal::from_fn(100, 1, |k, _| (k as f64 / 99.0).sin());
/// let Penalty::Quadratic(p) = d.penalty(&z).unwrap() else { unreachable!() };
/// // Stacked features: the Fourier series and the 4 monomials.
/// assert!(p.features().is_some());
/// ```
#[derive(Clone)]
pub struct SumDispersion {
    parts: Vec<Arc<dyn Dispersion>>,
}

impl fmt::Debug for SumDispersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "SumDispersion({})", self.describe())
    }
}

impl SumDispersion {
    /// The sum of at least one quadratic dispersion. Total variation cannot be summed (it is
    /// not a kernel norm); that is reported when the penalty is built.
    pub fn new(parts: Vec<Arc<dyn Dispersion>>) -> Result<Self> {
        if parts.is_empty() {
            return Err(Error::InvalidStructure(
                "a sum of dispersions needs at least one part".into(),
            ));
        }
        Ok(Self { parts })
    }

    /// The parts, in order.
    pub fn parts(&self) -> &[Arc<dyn Dispersion>] {
        &self.parts
    }

    fn width_part(&self) -> Option<usize> {
        self.parts.iter().position(|p| p.width().is_some())
    }
}

impl Dispersion for SumDispersion {
    fn describe(&self) -> String {
        self.parts
            .iter()
            .map(|p| p.describe())
            .collect::<Vec<_>>()
            .join(" + ")
    }

    fn parameters(&self) -> Vec<(String, f64)> {
        self.parts.iter().flat_map(|p| p.parameters()).collect()
    }

    fn width(&self) -> Option<f64> {
        self.width_part().and_then(|i| self.parts[i].width())
    }

    fn with_width(&self, width: f64) -> Option<Result<Arc<dyn Dispersion>>> {
        let i = self.width_part()?;
        let part = self.parts[i].with_width(width)?;
        Some(part.map(|part| {
            let mut parts = self.parts.clone();
            parts[i] = part;
            Arc::new(Self { parts }) as Arc<dyn Dispersion>
        }))
    }

    fn user_kernels(&self) -> crate::dispersion::user::UserKernels {
        self.parts
            .iter()
            .fold(Default::default(), |acc, p| acc.merged(p.user_kernels()))
    }

    fn penalty(&self, z: &Signal) -> Result<Penalty> {
        let mut parts = Vec::with_capacity(self.parts.len());
        for (i, d) in self.parts.iter().enumerate() {
            match d.penalty(z)? {
                Penalty::Quadratic(q) => parts.push(q),
                _ => {
                    return Err(Error::Unsupported(format!(
                        "part {} of a dispersion sum ({}) is not a kernel norm; only quadratic \
                         dispersions can be summed",
                        i + 1,
                        d.describe()
                    )));
                }
            }
        }
        let maps: Option<Vec<Arc<dyn FeatureMap>>> =
            parts.iter().map(|q| q.features().map(|(m, _)| m)).collect();
        if let Some(maps) = maps {
            let width_part = self.width_part();
            return Ok(FeaturePenalty::of(
                StackedFeatures::new(maps, width_part),
                z,
            ));
        }
        Ok(Penalty::Quadratic(Box::new(SumGram { parts })))
    }
}

/// The features [ψ₁; ψ₂; …] with weights diag(Λ₁, Λ₂, …).
pub struct StackedFeatures {
    maps: Vec<Arc<dyn FeatureMap>>,
    offsets: Vec<usize>,
    weights: Vec<f64>,
    width_part: Option<usize>,
}

impl fmt::Debug for StackedFeatures {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "StackedFeatures(dims = {:?})", self.offsets)
    }
}

impl StackedFeatures {
    /// Stacks feature maps; `width_part` is the map whose weights follow a width change.
    pub fn new(maps: Vec<Arc<dyn FeatureMap>>, width_part: Option<usize>) -> Self {
        let mut offsets = vec![0];
        let mut weights = Vec::new();
        for m in &maps {
            weights.extend_from_slice(m.weights());
            offsets.push(weights.len());
        }
        Self {
            maps,
            offsets,
            weights,
            width_part,
        }
    }
}

impl StackedFeatures {
    fn to_stored(&self) -> Option<crate::stored::StoredKernel> {
        Some(crate::stored::StoredKernel::Stacked {
            parts: self
                .maps
                .iter()
                .map(|m| m.stored_features())
                .collect::<Option<_>>()?,
            width_part: self.width_part,
        })
    }
}

impl FeatureMap for StackedFeatures {
    fn stored_features(&self) -> Option<crate::stored::StoredKernel> {
        self.to_stored()
    }

    fn dim(&self) -> usize {
        self.weights.len()
    }

    fn weights(&self) -> &[f64] {
        &self.weights
    }

    fn eval_into(&self, z: &[f64], out: &mut [f64]) {
        for (i, m) in self.maps.iter().enumerate() {
            m.eval_into(z, &mut out[self.offsets[i]..self.offsets[i + 1]]);
        }
    }

    fn weights_at_width(&self, width: f64) -> Option<Vec<f64>> {
        let mut w = Vec::with_capacity(self.weights.len());
        for (i, m) in self.maps.iter().enumerate() {
            if Some(i) == self.width_part {
                w.extend(m.weights_at_width(width)?);
            } else {
                w.extend_from_slice(m.weights());
            }
        }
        Some(w)
    }
}

impl Kernel for StackedFeatures {
    fn stored_kernel(&self) -> Option<crate::stored::StoredKernel> {
        self.to_stored()
    }

    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        crate::dispersion::feature_kernel(self, a, b)
    }

    fn describe(&self) -> String {
        format!("stacked features ({})", self.dim())
    }
}

/// K = Σ K_i through the parts' Gram matrices.
struct SumGram {
    parts: Vec<Box<dyn QuadraticPenalty>>,
}

impl QuadraticPenalty for SumGram {
    fn len(&self) -> usize {
        self.parts[0].len()
    }

    fn fill_columns(&self, cols: Range<usize>, mut out: faer::MatMut<'_, f64>) {
        self.parts[0].fill_columns(cols.clone(), out.as_mut());
        let mut tmp = Mat::<f64>::zeros(out.nrows(), out.ncols());
        for p in &self.parts[1..] {
            p.fill_columns(cols.clone(), tmp.as_mut());
            out += &tmp;
        }
    }

    fn interpolant(&self, alpha: Vec<f64>) -> Box<dyn Interpolant> {
        // Σ_k α_k (K₁ + K₂)(z, z_k) = N̂₁(z) + N̂₂(z) with the same α.
        Box::new(SumInterpolant(
            self.parts
                .iter()
                .map(|p| p.interpolant(alpha.clone()))
                .collect(),
        ))
    }

    fn cross_columns(&self, points: &Signal, mut out: faer::MatMut<'_, f64>) -> bool {
        if !self.parts[0].cross_columns(points, out.as_mut()) {
            return false;
        }
        let mut tmp = Mat::<f64>::zeros(out.nrows(), out.ncols());
        for p in &self.parts[1..] {
            if !p.cross_columns(points, tmp.as_mut()) {
                return false;
            }
            out += &tmp;
        }
        true
    }

    fn diagonal_at(&self, points: &Signal) -> Option<Vec<f64>> {
        let mut d = self.parts[0].diagonal_at(points)?;
        for p in &self.parts[1..] {
            d.iter_mut()
                .zip(p.diagonal_at(points)?)
                .for_each(|(a, b)| *a += b);
        }
        Some(d)
    }
}

/// N̂ = Σ_i N̂_i: the map of a sum dispersion (the same α on every part's kernel).
pub(crate) struct SumInterpolant(pub(crate) Vec<Box<dyn Interpolant>>);

impl Interpolant for SumInterpolant {
    fn eval(&self, z: &[f64]) -> f64 {
        self.0.iter().map(|f| f.eval(z)).sum()
    }

    fn stored(&self) -> Option<crate::stored::StoredMap> {
        Some(crate::stored::StoredMap::Sum {
            parts: self.0.iter().map(|m| m.stored()).collect::<Option<_>>()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dispersion::quadratic_penalty;
    use crate::{FourierDispersion, FourierWeights, KernelDispersion, PolynomialDispersion};

    fn gram(p: &dyn QuadraticPenalty) -> Mat<f64> {
        let mut k = Mat::zeros(p.len(), p.len());
        p.fill_columns(0..p.len(), k.as_mut());
        k
    }

    #[test]
    fn the_gram_matrix_of_a_sum_is_the_sum_of_the_gram_matrices() {
        let z = Signal::from_fn(30, 1, |k, _| (0.37 * k as f64).sin());
        let poly: Arc<dyn Dispersion> = Arc::new(PolynomialDispersion::new(3).unwrap());
        for first in [
            Arc::new(KernelDispersion::gaussian(0.3).unwrap()) as Arc<dyn Dispersion>,
            Arc::new(FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.3 }).unwrap()),
        ] {
            let sum = SumDispersion::new(vec![first.clone(), poly.clone()]).unwrap();
            let (ks, k1, k2) = (
                gram(&*quadratic_penalty(&sum, &z)),
                gram(&*quadratic_penalty(&*first, &z)),
                gram(&*quadratic_penalty(&*poly, &z)),
            );
            let err = (&ks - &k1 - &k2).norm_max();
            assert!(err < 1e-12 * k1.norm_max(), "{}: {err}", sum.describe());
            // Interpolants add with a common α; cross columns and diagonals add.
            let alpha: Vec<f64> = (0..30).map(|k| (k as f64 * 0.7).cos()).collect();
            let p = Signal::from_channels(&[vec![-1.3, 0.2, 0.9]]).unwrap();
            let s = quadratic_penalty(&sum, &z).interpolant(alpha.clone());
            let (a, b) = (
                quadratic_penalty(&*first, &z).interpolant(alpha.clone()),
                quadratic_penalty(&*poly, &z).interpolant(alpha),
            );
            let mut cs = Mat::zeros(30, 3);
            assert!(quadratic_penalty(&sum, &z).cross_columns(&p, cs.as_mut()));
            let diag = quadratic_penalty(&sum, &z).diagonal_at(&p).unwrap();
            for j in 0..3 {
                let x = p.sample(j);
                assert!((s.eval(x) - a.eval(x) - b.eval(x)).abs() < 1e-9);
                let k_sum = first_kernel_at(&*first, &z, x) + first_kernel_at(&*poly, &z, x);
                assert!((diag[j] - k_sum).abs() < 1e-9 * k_sum.abs().max(1.0));
            }
        }
    }

    fn first_kernel_at(d: &dyn Dispersion, z: &Signal, x: &[f64]) -> f64 {
        let p = Signal::from_channels(&[vec![x[0]]]).unwrap();
        quadratic_penalty(d, z).diagonal_at(&p).unwrap()[0]
    }

    #[test]
    fn width_follows_the_first_part_that_has_one() {
        let sum = SumDispersion::new(vec![
            Arc::new(PolynomialDispersion::new(1).unwrap()),
            Arc::new(
                FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.2 })
                    .unwrap()
                    .with_harmonics(10),
            ),
        ])
        .unwrap();
        assert_eq!(sum.width(), Some(0.2));
        let wider = sum.with_width(0.5).unwrap().unwrap();
        assert_eq!(wider.width(), Some(0.5));
        assert!(wider.describe().contains("polynomial"));
        // Feature weights at another width: the Fourier block changes, the monomials do not.
        let z = Signal::from_fn(40, 1, |k, _| k as f64 / 39.0);
        let (m, _) = quadratic_penalty(&sum, &z)
            .features()
            .map(|(m, z)| (m, z.len()))
            .unwrap();
        let direct = quadratic_penalty(&*wider, &z)
            .features()
            .unwrap()
            .0
            .weights()
            .to_vec();
        let reweighted = m.weights_at_width(0.5).unwrap();
        assert_eq!(direct.len(), reweighted.len());
        for (a, b) in direct.iter().zip(&reweighted) {
            assert!((a - b).abs() <= 1e-12 * a.abs().max(1e-300));
        }
    }

    #[test]
    fn total_variation_cannot_be_summed() {
        let sum = SumDispersion::new(vec![
            Arc::new(PolynomialDispersion::new(1).unwrap()),
            Arc::new(crate::TotalVariation::new()),
        ])
        .unwrap();
        let z = Signal::from_fn(10, 1, |k, _| k as f64);
        assert!(matches!(sum.penalty(&z), Err(Error::Unsupported(_))));
        assert!(SumDispersion::new(vec![]).is_err());
    }
}

//! A polynomial dispersion: the finite-dimensional kernel of all monomials up to a degree.
//!
//! With the block's inputs normalised by their data range, t_j = (z_j − c_j)/h_j (c the centre
//! and h the half-range, so the data occupy [−1, 1]), the features are the monomials
//! ψ_α(z) = Π_j t_j^{α_j} of total degree |α| ≤ d, and every feature has the same weight λ:
//!
//! ```text
//!   K(z₁, z₂) = λ·Σ_{|α| ≤ d} ψ_α(z₁)·ψ_α(z₂),        D(z, w) = ‖a‖²/λ   for w = ψ(z)ᵀa.
//! ```
//!
//! On its own it is ridge regression on a polynomial (a parametric model). Its main use is as
//! the *trend* of a semi-parametric dispersion ([`crate::SumDispersion`]): a Gaussian or Fourier
//! kernel plus a polynomial. The kernel part then models what the polynomial misses inside the
//! data, and outside the data, where every stationary kernel reverts to zero, the estimate
//! follows the polynomial. This is what extrapolating a stiffness such as y³ needs (the
//! Silverbox arrow test leaves the estimation range by 40 %).
//!
//! The normalisation is fixed when the data are seen and travels with the estimate, so N̂ is
//! evaluated with the same t at new points.

use structid_lti::Signal;

use crate::dispersion::fourier::FeaturePenalty;
use crate::dispersion::kernel::Kernel;
use crate::dispersion::{Dispersion, FeatureMap, Penalty};
use crate::error::{Error, Result, positive_finite};

/// Largest number of monomials a polynomial dispersion may create.
pub const MAX_MONOMIALS: usize = 4096;

/// Settings of a polynomial dispersion; the normalisation is fixed when the data are seen.
///
/// ```
/// use structid_core::{Dispersion, PolynomialDispersion, Penalty, Signal};
/// let d = PolynomialDispersion::new(3).unwrap();
/// assert_eq!(d.describe(), "polynomial(degree=3, scale=1)");
/// let z = Signal::from_fn(50, 1, |k, _| k as f64 / 49.0);
/// let Penalty::Quadratic(p) = d.penalty(&z).unwrap() else { unreachable!() };
/// assert_eq!(p.features().unwrap().0.dim(), 4);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct PolynomialDispersion {
    degree: usize,
    scale: f64,
}

impl PolynomialDispersion {
    /// All monomials up to total degree `degree`, each with prior weight λ = 1.
    pub fn new(degree: usize) -> Result<Self> {
        if degree > 64 {
            return Err(Error::InvalidParameter {
                name: "degree".into(),
                value: degree as f64,
                reason: "a polynomial dispersion allows degrees up to 64".into(),
            });
        }
        Ok(Self { degree, scale: 1.0 })
    }

    /// Sets the weight λ (> 0) of every normalised monomial: the prior variance of its
    /// coefficient relative to 1/β. Larger means a weaker penalty.
    pub fn with_scale(mut self, scale: f64) -> Result<Self> {
        self.scale = positive_finite("scale", scale)?;
        Ok(self)
    }

    /// The total degree d.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// The weight λ of every monomial.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// The concrete features for inputs `z` (normalised by their data range).
    pub fn features_for(&self, z: &Signal) -> Result<PolynomialFeatures> {
        let affine = (0..z.channels())
            .map(|c| {
                let (lo, hi) =
                    (0..z.len()).fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), k| {
                        let v = z.get(k, c);
                        (l.min(v), h.max(v))
                    });
                if !(lo.is_finite() && hi.is_finite()) {
                    (0.0, 1.0)
                } else if hi > lo {
                    (0.5 * (lo + hi), 0.5 * (hi - lo))
                } else {
                    (lo, 1.0)
                }
            })
            .collect();
        PolynomialFeatures::new(self.degree, self.scale, affine)
    }
}

impl Dispersion for PolynomialDispersion {
    fn describe(&self) -> String {
        format!("polynomial(degree={}, scale={})", self.degree, self.scale)
    }

    fn parameters(&self) -> Vec<(String, f64)> {
        vec![
            ("degree".into(), self.degree as f64),
            ("scale".into(), self.scale),
        ]
    }

    fn penalty(&self, z: &Signal) -> Result<Penalty> {
        Ok(FeaturePenalty::of(self.features_for(z)?, z))
    }
}

/// The monomial features ψ_α(z) = Π_j ((z_j − c_j)/h_j)^{α_j}, |α| ≤ d, with equal weights.
///
/// ```
/// use structid_core::{FeatureMap, Kernel, PolynomialFeatures};
/// // t = (z − 1)/2, degree 2: ψ = [1, t, t²].
/// let f = PolynomialFeatures::new(2, 1.0, vec![(1.0, 2.0)]).unwrap();
/// let mut psi = [0.0; 3];
/// f.eval_into(&[5.0], &mut psi);
/// assert_eq!(psi, [1.0, 2.0, 4.0]);
/// assert_eq!(f.eval(&[5.0], &[3.0]), 1.0 + 2.0 * 1.0 + 4.0 * 1.0);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct PolynomialFeatures {
    affine: Vec<(f64, f64)>,
    exponents: Vec<Vec<u32>>,
    weights: Vec<f64>,
}

impl PolynomialFeatures {
    /// Monomials of total degree ≤ `degree` in p = `affine.len()` inputs, each input normalised
    /// as t = (z − centre)/half_width with `affine[j] = (centre, half_width)`, all with weight
    /// `scale`.
    pub fn new(degree: usize, scale: f64, affine: Vec<(f64, f64)>) -> Result<Self> {
        positive_finite("scale", scale)?;
        if affine
            .iter()
            .any(|&(c, h)| !(c.is_finite() && h.is_finite() && h > 0.0))
        {
            return Err(Error::InvalidStructure(
                "a polynomial normalisation needs a finite centre and a positive half-width".into(),
            ));
        }
        let mut exponents = vec![Vec::new()];
        for _ in 0..affine.len() {
            let mut next = Vec::new();
            for e in &exponents {
                let used: u32 = e.iter().sum();
                for a in 0..=(degree as u32).saturating_sub(used) {
                    let mut e2 = e.clone();
                    e2.push(a);
                    next.push(e2);
                }
                if next.len() > MAX_MONOMIALS {
                    return Err(Error::InvalidStructure(format!(
                        "a polynomial of degree {degree} in {} inputs has more than {MAX_MONOMIALS} monomials",
                        affine.len()
                    )));
                }
            }
            exponents = next;
        }
        // Order by total degree so that the constant comes first and the coefficients read
        // naturally in reports.
        exponents.sort_by_key(|e| (e.iter().sum::<u32>(), std::cmp::Reverse(e.clone())));
        let weights = vec![scale; exponents.len()];
        Ok(Self {
            affine,
            exponents,
            weights,
        })
    }

    pub(crate) fn to_stored(&self) -> crate::stored::PolynomialStored {
        crate::stored::PolynomialStored {
            affine: self.affine.clone(),
            exponents: self.exponents.clone(),
            weights: self.weights.clone(),
        }
    }

    /// The features from their stored numbers, checked to fit together (one exponent per
    /// input, one weight per feature), so that evaluation cannot index out of range.
    pub(crate) fn from_stored(s: &crate::stored::PolynomialStored) -> Result<Self> {
        let p = s.affine.len();
        if p > 0 && s.exponents.len() == s.weights.len() && s.exponents.iter().all(|e| e.len() == p)
        {
            Ok(Self {
                affine: s.affine.clone(),
                exponents: s.exponents.clone(),
                weights: s.weights.clone(),
            })
        } else {
            Err(Error::InconsistentStored {
                item: "polynomial features".into(),
                detail: "exponents, inputs and weights do not fit together".into(),
            })
        }
    }

    /// The exponents α of each feature, in feature order.
    pub fn exponents(&self) -> &[Vec<u32>] {
        &self.exponents
    }

    /// The normalisation (centre, half-width) of each input.
    pub fn normalisation(&self) -> &[(f64, f64)] {
        &self.affine
    }
}

impl FeatureMap for PolynomialFeatures {
    fn stored_features(&self) -> Option<crate::stored::StoredKernel> {
        Some(crate::stored::StoredKernel::Polynomial(self.to_stored()))
    }

    fn dim(&self) -> usize {
        self.exponents.len()
    }

    fn weights(&self) -> &[f64] {
        &self.weights
    }

    fn eval_into(&self, z: &[f64], out: &mut [f64]) {
        let t: Vec<f64> = self
            .affine
            .iter()
            .zip(z)
            .map(|(&(c, h), v)| (v - c) / h)
            .collect();
        for (o, e) in out.iter_mut().zip(&self.exponents) {
            *o = e
                .iter()
                .zip(&t)
                .map(|(&a, &tj)| tj.powi(a as i32))
                .product();
        }
    }

    /// The monomials do not depend on any width.
    fn weights_at_width(&self, _width: f64) -> Option<Vec<f64>> {
        Some(self.weights.clone())
    }
}

impl Kernel for PolynomialFeatures {
    fn stored_kernel(&self) -> Option<crate::stored::StoredKernel> {
        Some(crate::stored::StoredKernel::Polynomial(self.to_stored()))
    }

    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        crate::dispersion::feature_kernel(self, a, b)
    }

    fn describe(&self) -> String {
        format!("polynomial(monomials={})", self.dim())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monomial_count_is_the_binomial_coefficient() {
        // C(p + d, d) monomials of total degree ≤ d in p inputs.
        for (p, d, n) in [(1, 3, 4), (2, 2, 6), (3, 3, 20), (2, 0, 1)] {
            let f = PolynomialFeatures::new(d, 1.0, vec![(0.0, 1.0); p]).unwrap();
            assert_eq!(f.dim(), n, "p={p} d={d}");
            assert!(
                f.exponents()
                    .iter()
                    .all(|e| e.iter().sum::<u32>() <= d as u32)
            );
            assert_eq!(f.exponents()[0], vec![0; p]);
        }
    }

    #[test]
    fn normalisation_maps_the_data_to_the_unit_interval() {
        let z = Signal::from_channels(&[vec![2.0, 4.0, 6.0]]).unwrap();
        let f = PolynomialDispersion::new(1)
            .unwrap()
            .features_for(&z)
            .unwrap();
        let mut psi = [0.0; 2];
        f.eval_into(&[2.0], &mut psi);
        assert_eq!(psi, [1.0, -1.0]);
        f.eval_into(&[6.0], &mut psi);
        assert_eq!(psi, [1.0, 1.0]);
    }

    #[test]
    fn bad_parameters_are_errors() {
        assert!(PolynomialDispersion::new(65).is_err());
        assert!(
            PolynomialDispersion::new(2)
                .unwrap()
                .with_scale(0.0)
                .is_err()
        );
        assert!(PolynomialFeatures::new(2, 1.0, vec![(0.0, 0.0)]).is_err());
        assert!(PolynomialFeatures::new(30, 1.0, vec![(0.0, 1.0); 6]).is_err());
    }
}

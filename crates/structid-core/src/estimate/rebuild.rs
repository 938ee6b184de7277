//! Stored maps back to maps: the inverse of [`Interpolant::stored`], checked so that numbers
//! read from a file that do not fit together are errors rather than panics.

use std::sync::Arc;

use structid_lti::Signal;

use crate::dispersion::FeatureMap;
use crate::dispersion::fourier::{FeatureExpansion, FourierKernel};
use crate::dispersion::kernel::{GaussianKernel, Kernel, KernelExpansion};
use crate::dispersion::low_rank::NystromFeatures;
use crate::dispersion::neighbours::{KdTree, PiecewiseLinear, ScatteredInterpolant, Weighting};
use crate::dispersion::polynomial::PolynomialFeatures;
use crate::dispersion::sum::{StackedFeatures, SumInterpolant};
use crate::dispersion::total_variation::{PiecewiseLinearMap, ScaledScattered};
use crate::dispersion::user::{DynKernel, UserKernel, UserKernels};
use crate::error::{Error, Result};
use crate::model::interpolant::Interpolant;
use crate::model::maps::{ExprMap, LookupTable};
use crate::stored::{StoredKernel, StoredMap};

impl StoredKernel {
    /// The feature map this describes.
    ///
    /// # Errors
    /// [`Error::InvalidStructure`] when the stored numbers are inconsistent, or for a kernel
    /// without finite features (Gaussian).
    pub fn feature_map(&self) -> Result<Arc<dyn FeatureMap>> {
        self.feature_map_with(&UserKernels::new())
    }

    /// The feature map this describes, with a user-defined one ([`StoredKernel::User`]) taken
    /// from `user`.
    ///
    /// # Errors
    /// As [`StoredKernel::feature_map`], and [`Error::UserKernelMissing`] for a user feature
    /// map that `user` does not hold.
    pub fn feature_map_with(&self, user: &UserKernels) -> Result<Arc<dyn FeatureMap>> {
        Ok(match self {
            StoredKernel::Gaussian { .. } => {
                return Err(Error::InvalidStructure(
                    "a Gaussian kernel has no finite feature map; it is stored as a kernel expansion"
                        .into(),
                ));
            }
            StoredKernel::Fourier(k) => Arc::new(FourierKernel::from_stored(k)?),
            StoredKernel::Polynomial(k) => Arc::new(PolynomialFeatures::from_stored(k)?),
            StoredKernel::Nystrom(n) => Arc::new(NystromFeatures::from_stored(n)?),
            StoredKernel::Stacked { parts, width_part } => {
                Arc::new(stacked(parts, *width_part, user)?)
            }
            StoredKernel::User { name, .. } => match user.get(name)? {
                UserKernel::Features(f) => Arc::clone(f),
                UserKernel::Kernel(_) => return Err(user_mismatch(name, "a kernel", "features")),
            },
        })
    }

    /// N̂(z) = Σ_k α_k k(z, z_k) with this kernel.
    pub(crate) fn expansion(
        &self,
        centres: Signal,
        alpha: Vec<f64>,
        user: &UserKernels,
    ) -> Result<Box<dyn Interpolant>> {
        fn boxed<K: Kernel + 'static>(k: K, c: Signal, a: Vec<f64>) -> Box<dyn Interpolant> {
            Box::new(KernelExpansion::new(Arc::new(k), c, a))
        }
        Ok(match self {
            StoredKernel::Gaussian { sigma } => boxed(GaussianKernel::new(*sigma)?, centres, alpha),
            StoredKernel::Fourier(k) => boxed(FourierKernel::from_stored(k)?, centres, alpha),
            StoredKernel::Polynomial(k) => {
                boxed(PolynomialFeatures::from_stored(k)?, centres, alpha)
            }
            StoredKernel::Nystrom(n) => boxed(NystromFeatures::from_stored(n)?, centres, alpha),
            StoredKernel::Stacked { parts, width_part } => {
                boxed(stacked(parts, *width_part, user)?, centres, alpha)
            }
            StoredKernel::User { name, width } => match user.get(name)? {
                UserKernel::Kernel(k) => {
                    boxed(DynKernel(k.at_width(name, *width)?), centres, alpha)
                }
                UserKernel::Features(_) => {
                    return Err(user_mismatch(name, "a feature map", "a kernel"));
                }
            },
        })
    }

    /// The number of inputs p the kernel reads, when it says.
    fn inputs(&self) -> Option<usize> {
        match self {
            StoredKernel::Gaussian { .. } => None,
            StoredKernel::Fourier(k) => Some(k.affine.len()),
            StoredKernel::Polynomial(k) => Some(k.affine.len()),
            StoredKernel::Nystrom(n) => Some(n.centres.channels),
            StoredKernel::Stacked { parts, .. } => parts.iter().find_map(StoredKernel::inputs),
            StoredKernel::User { .. } => None,
        }
    }
}

/// The error for a registry entry of the wrong kind: `name` is `registered` but the stored
/// estimate needs `needed`.
fn user_mismatch(name: &str, registered: &str, needed: &str) -> Error {
    Error::InconsistentStored {
        item: format!("user kernel `{name}`"),
        detail: format!("it is registered as {registered}, but the estimate needs {needed}"),
    }
}

/// Stacked features rebuilt from their stored parts.
fn stacked(
    parts: &[StoredKernel],
    width_part: Option<usize>,
    user: &UserKernels,
) -> Result<StackedFeatures> {
    if parts.is_empty() || width_part.is_some_and(|w| w >= parts.len()) {
        return Err(Error::InvalidStructure(format!(
            "stored stacked features: {} part(s) and width part {width_part:?}",
            parts.len()
        )));
    }
    let maps = parts
        .iter()
        .map(|p| p.feature_map_with(user))
        .collect::<Result<Vec<_>>>()?;
    Ok(StackedFeatures::new(maps, width_part))
}

impl StoredMap {
    /// The map as an [`Interpolant`] that evaluates exactly as the one it was stored from.
    ///
    /// # Errors
    /// [`Error::InconsistentStored`] when the stored numbers are inconsistent (lengths that do
    /// not match, knots that are not increasing, …), [`Error::Expression`] for an expression
    /// that does not parse.
    ///
    /// ```
    /// use structid_core::Interpolant;
    /// use structid_core::stored::StoredMap;
    /// let m = StoredMap::PiecewiseLinear { knots: vec![0.0, 1.0], values: vec![0.0, 2.0] };
    /// assert_eq!(m.interpolant().unwrap().eval(&[0.25]), 0.5);
    /// let bad = StoredMap::PiecewiseLinear { knots: vec![1.0, 0.0], values: vec![0.0, 2.0] };
    /// assert!(bad.interpolant().is_err());
    /// ```
    pub fn interpolant(&self) -> Result<Box<dyn Interpolant>> {
        self.interpolant_with(&UserKernels::new())
    }

    /// [`StoredMap::interpolant`], with the user-defined kernels and feature maps the map is
    /// built on ([`StoredKernel::User`]) taken from `user`.
    ///
    /// # Errors
    /// As [`StoredMap::interpolant`], and [`Error::UserKernelMissing`] for a user kernel that
    /// `user` does not hold.
    pub fn interpolant_with(&self, user: &UserKernels) -> Result<Box<dyn Interpolant>> {
        let bad = |detail: String| Error::InconsistentStored {
            item: "map".into(),
            detail,
        };
        Ok(match self {
            StoredMap::KernelExpansion {
                kernel,
                centres,
                alpha,
            } => {
                if centres.len() != alpha.len() {
                    return Err(bad(format!(
                        "{} centres but {} coefficients",
                        centres.len(),
                        alpha.len()
                    )));
                }
                if let Some(p) = kernel.inputs()
                    && p != centres.channels
                {
                    return Err(bad(format!(
                        "the kernel reads {p} input(s) but the centres have {}",
                        centres.channels
                    )));
                }
                kernel.expansion(centres.to_signal()?, alpha.clone(), user)?
            }
            StoredMap::FeatureExpansion {
                features,
                coefficients,
            } => {
                let map = features.feature_map_with(user)?;
                if map.dim() != coefficients.len() {
                    return Err(bad(format!(
                        "{} features but {} coefficients",
                        map.dim(),
                        coefficients.len()
                    )));
                }
                Box::new(FeatureExpansion::new(map, coefficients.clone()))
            }
            StoredMap::Sum { parts } => {
                if parts.is_empty() {
                    return Err(bad("a sum without parts".into()));
                }
                let parts = parts
                    .iter()
                    .map(|p| p.interpolant_with(user))
                    .collect::<Result<Vec<_>>>()?;
                Box::new(SumInterpolant(parts))
            }
            StoredMap::PiecewiseLinear { knots, values } => {
                if knots.is_empty() || knots.len() != values.len() {
                    return Err(bad(format!(
                        "{} knots and {} values (need as many, at least one)",
                        knots.len(),
                        values.len()
                    )));
                }
                if knots
                    .windows(2)
                    .any(|w| w[0].partial_cmp(&w[1]) != Some(std::cmp::Ordering::Less))
                {
                    return Err(bad("the knots must be strictly increasing".into()));
                }
                Box::new(PiecewiseLinearMap(PiecewiseLinear::new(
                    knots.clone(),
                    values.clone(),
                )))
            }
            StoredMap::Scattered {
                nodes,
                values,
                inverse_distance_neighbours,
                lo,
                scale,
            } => {
                let p = nodes.channels;
                if nodes.len() != values.len()
                    || values.is_empty()
                    || lo.len() != p
                    || scale.len() != p
                    || nodes.data.len() != nodes.len() * p
                {
                    return Err(bad(format!(
                        "{} nodes of {p} coordinate(s), {} values, {} offsets and {} scales do not match",
                        nodes.len(),
                        values.len(),
                        lo.len(),
                        scale.len()
                    )));
                }
                let weighting = match inverse_distance_neighbours {
                    None => Weighting::Nearest,
                    Some(k) => Weighting::InverseDistance {
                        neighbours: *k,
                        power: 2.0,
                    },
                };
                Box::new(ScaledScattered {
                    inner: ScatteredInterpolant::new(
                        KdTree::new(&nodes.data, p),
                        values.clone(),
                        weighting,
                    ),
                    lo: lo.clone(),
                    scale: scale.clone(),
                })
            }
            StoredMap::Expression { expression, inputs } => {
                Box::new(ExprMap::parse(expression, *inputs)?)
            }
            StoredMap::Table { rows } => Box::new(LookupTable::from_rows(rows)?),
        })
    }
}

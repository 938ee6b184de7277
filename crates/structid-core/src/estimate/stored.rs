//! Serialisable forms of estimated maps and of the kernels and feature maps they are built on.
//!
//! An estimated map is an [`Interpolant`] (a trait object); [`Interpolant::stored`] turns the
//! maps of this crate into a [`StoredMap`], plain data that serde writes and reads, and
//! [`StoredMap::interpolant`] turns it back into a map that evaluates to the same floating-point
//! numbers: the stored form holds every number the evaluation uses (centres, coefficients,
//! feature weights and normalisations, nodes), so no fit or factorisation is repeated.
//!
//! | estimate | stored as |
//! |---|---|
//! | kernel expansion N̂(z) = Σ_k α_k k(z, z_k) | [`StoredMap::KernelExpansion`]: the kernel, the centres z_k and α |
//! | feature expansion N̂(z) = ψ(z)ᵀc (Fourier, polynomial, Nyström, stacked) | [`StoredMap::FeatureExpansion`]: the feature map and c |
//! | a sum of maps (sum dispersions) | [`StoredMap::Sum`] |
//! | total variation on one input: piecewise linear through the nodes | [`StoredMap::PiecewiseLinear`] |
//! | total variation on p ≥ 2 inputs: scattered interpolation | [`StoredMap::Scattered`] |
//! | an expression or a lookup table (known maps) | [`StoredMap::Expression`], [`StoredMap::Table`] |
//!
//! A user-defined kernel or interpolant has no stored form unless it implements
//! [`Kernel::stored_kernel`] / [`Interpolant::stored`]; writing such an estimate is an error that
//! names the block.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use structid_lti::Signal;

use crate::dispersion::FeatureMap;
use crate::error::{Error, Result};
use crate::fourier::{FeatureExpansion, FourierKernel};
use crate::interpolant::Interpolant;
use crate::kernel::{GaussianKernel, Kernel, KernelExpansion};
use crate::low_rank::NystromFeatures;
use crate::maps::{ExprMap, LookupTable};
use crate::neighbours::{KdTree, PiecewiseLinear, ScatteredInterpolant, Weighting};
use crate::polynomial::PolynomialFeatures;
use crate::sum::StackedFeatures;
use crate::total_variation::PiecewiseLinearMap;

/// Points z_k as plain data: `channels` values per sample, sample-major.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoredPoints {
    /// Values per point (p).
    pub channels: usize,
    /// The coordinates, point after point.
    pub data: Vec<f64>,
}

impl StoredPoints {
    /// The points of a signal.
    pub fn from_signal(s: &Signal) -> Self {
        Self {
            channels: s.channels(),
            data: s.as_slice().to_vec(),
        }
    }

    /// The points as a signal.
    ///
    /// # Errors
    /// [`Error::InconsistentStored`] when the data are not a whole number of points.
    pub fn to_signal(&self) -> Result<Signal> {
        if self.channels == 0 || self.data.len() % self.channels != 0 {
            return Err(Error::InconsistentStored {
                item: "points".into(),
                detail: format!(
                    "{} values are not a whole number of points of {} coordinate(s)",
                    self.data.len(),
                    self.channels
                ),
            });
        }
        Ok(Signal::new(self.channels, self.data.clone())?)
    }

    fn len(&self) -> usize {
        self.data.len().checked_div(self.channels).unwrap_or(0)
    }
}

/// A kernel or feature map as plain data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
#[non_exhaustive]
pub enum StoredKernel {
    /// [`GaussianKernel`] of width σ.
    Gaussian {
        /// σ.
        sigma: f64,
    },
    /// [`FourierKernel`] with its domain normalisation, harmonics and weights.
    Fourier(FourierKernel),
    /// [`PolynomialFeatures`].
    Polynomial(PolynomialFeatures),
    /// [`NystromFeatures`] of a Gaussian kernel.
    Nystrom(NystromStored),
    /// [`StackedFeatures`]: the parts in order.
    Stacked {
        /// The stacked feature maps.
        parts: Vec<StoredKernel>,
        /// The part whose weights follow a width change.
        width_part: Option<usize>,
    },
}

/// The numbers that define [`NystromFeatures`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NystromStored {
    /// σ of the Gaussian kernel.
    pub sigma: f64,
    /// The landmark points z_P.
    pub centres: StoredPoints,
    /// The Cholesky factor L_PP (rank × rank, row-major, lower triangle used).
    pub l_pp: Vec<f64>,
    /// Feature weights.
    pub weights: Vec<f64>,
    /// trace(K − K̃)/trace(K) when the factorisation stopped.
    pub trace_error: f64,
}

impl StoredKernel {
    /// The feature map this describes.
    ///
    /// # Errors
    /// [`Error::InvalidStructure`] when the stored numbers are inconsistent, or for a kernel
    /// without finite features (Gaussian).
    pub fn feature_map(&self) -> Result<Arc<dyn FeatureMap>> {
        Ok(match self {
            StoredKernel::Gaussian { .. } => {
                return Err(Error::InvalidStructure(
                    "a Gaussian kernel has no finite feature map; it is stored as a kernel expansion"
                        .into(),
                ));
            }
            StoredKernel::Fourier(k) => {
                k.check_stored()?;
                Arc::new(k.clone())
            }
            StoredKernel::Polynomial(k) => {
                k.check_stored()?;
                Arc::new(k.clone())
            }
            StoredKernel::Nystrom(n) => Arc::new(NystromFeatures::from_stored(n)?),
            StoredKernel::Stacked { parts, width_part } => Arc::new(stacked(parts, *width_part)?),
        })
    }

    /// N̂(z) = Σ_k α_k k(z, z_k) with this kernel.
    fn expansion(&self, centres: Signal, alpha: Vec<f64>) -> Result<Box<dyn Interpolant>> {
        fn boxed<K: Kernel + 'static>(k: K, c: Signal, a: Vec<f64>) -> Box<dyn Interpolant> {
            Box::new(KernelExpansion::new(Arc::new(k), c, a))
        }
        Ok(match self {
            StoredKernel::Gaussian { sigma } => boxed(GaussianKernel::new(*sigma)?, centres, alpha),
            StoredKernel::Fourier(k) => {
                k.check_stored()?;
                boxed(k.clone(), centres, alpha)
            }
            StoredKernel::Polynomial(k) => {
                k.check_stored()?;
                boxed(k.clone(), centres, alpha)
            }
            StoredKernel::Nystrom(n) => boxed(NystromFeatures::from_stored(n)?, centres, alpha),
            StoredKernel::Stacked { parts, width_part } => {
                boxed(stacked(parts, *width_part)?, centres, alpha)
            }
        })
    }

    /// The number of inputs p the kernel reads, when it says.
    fn inputs(&self) -> Option<usize> {
        match self {
            StoredKernel::Gaussian { .. } => None,
            StoredKernel::Fourier(k) => Some(k.inputs()),
            StoredKernel::Polynomial(k) => Some(k.normalisation().len()),
            StoredKernel::Nystrom(n) => Some(n.centres.channels),
            StoredKernel::Stacked { parts, .. } => parts.iter().find_map(StoredKernel::inputs),
        }
    }
}

/// Stacked features rebuilt from their stored parts.
fn stacked(parts: &[StoredKernel], width_part: Option<usize>) -> Result<StackedFeatures> {
    if parts.is_empty() || width_part.is_some_and(|w| w >= parts.len()) {
        return Err(Error::InconsistentStored {
            item: "stacked features".into(),
            detail: format!("{} part(s) and width part {width_part:?}", parts.len()),
        });
    }
    let maps = parts
        .iter()
        .map(StoredKernel::feature_map)
        .collect::<Result<Vec<_>>>()?;
    Ok(StackedFeatures::new(maps, width_part))
}

/// An estimated (or known) static map as plain data; see the [module documentation](self).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
#[non_exhaustive]
pub enum StoredMap {
    /// N̂(z) = Σ_k α_k k(z, z_k).
    KernelExpansion {
        /// The kernel k.
        kernel: StoredKernel,
        /// The centres z_k.
        centres: StoredPoints,
        /// The coefficients α_k.
        alpha: Vec<f64>,
    },
    /// N̂(z) = ψ(z)ᵀc.
    FeatureExpansion {
        /// The feature map ψ.
        features: StoredKernel,
        /// The coefficients c.
        coefficients: Vec<f64>,
    },
    /// N̂ = Σ_i N̂_i.
    Sum {
        /// The parts.
        parts: Vec<StoredMap>,
    },
    /// Piecewise linear through (knot, value) pairs, constant outside the knots.
    PiecewiseLinear {
        /// Increasing knots.
        knots: Vec<f64>,
        /// Values at the knots.
        values: Vec<f64>,
    },
    /// Scattered interpolation over nodes in inputs scaled to \[0, 1\] by q = (z − lo)·scale.
    Scattered {
        /// The nodes, in scaled coordinates.
        nodes: StoredPoints,
        /// The value at each node.
        values: Vec<f64>,
        /// `None`: the nearest node; `Some(k)`: inverse squared distance over the k nearest.
        inverse_distance_neighbours: Option<usize>,
        /// Per input: the offset of the scaling.
        lo: Vec<f64>,
        /// Per input: the factor of the scaling.
        scale: Vec<f64>,
    },
    /// An expression in z (or z0, z1, …).
    Expression {
        /// The expression text.
        expression: String,
        /// Number of inputs.
        inputs: usize,
    },
    /// A lookup table, one row per point: p inputs then the value.
    Table {
        /// The rows.
        rows: Vec<Vec<f64>>,
    },
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
    /// use structid_core::estimate::StoredMap;
    /// let m = StoredMap::PiecewiseLinear { knots: vec![0.0, 1.0], values: vec![0.0, 2.0] };
    /// assert_eq!(m.interpolant().unwrap().eval(&[0.25]), 0.5);
    /// let bad = StoredMap::PiecewiseLinear { knots: vec![1.0, 0.0], values: vec![0.0, 2.0] };
    /// assert!(bad.interpolant().is_err());
    /// ```
    pub fn interpolant(&self) -> Result<Box<dyn Interpolant>> {
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
                kernel.expansion(centres.to_signal()?, alpha.clone())?
            }
            StoredMap::FeatureExpansion {
                features,
                coefficients,
            } => {
                let map = features.feature_map()?;
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
                    .map(StoredMap::interpolant)
                    .collect::<Result<Vec<_>>>()?;
                Box::new(SumOfMaps(parts))
            }
            StoredMap::PiecewiseLinear { knots, values } => {
                if knots.is_empty() || knots.len() != values.len() {
                    return Err(bad(format!(
                        "{} knots and {} values (need as many, at least one)",
                        knots.len(),
                        values.len()
                    )));
                }
                if knots.windows(2).any(|w| !(w[0] < w[1])) {
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
                Box::new(ScaledScatteredMap::new(
                    ScatteredInterpolant::new(
                        KdTree::new(&nodes.data, p),
                        values.clone(),
                        weighting,
                    ),
                    lo.clone(),
                    scale.clone(),
                ))
            }
            StoredMap::Expression { expression, inputs } => {
                Box::new(ExprMap::parse(expression, *inputs)?)
            }
            StoredMap::Table { rows } => Box::new(LookupTable::from_rows(rows)?),
        })
    }
}

/// N̂ = Σ_i N̂_i.
struct SumOfMaps(Vec<Box<dyn Interpolant>>);

impl Interpolant for SumOfMaps {
    fn eval(&self, z: &[f64]) -> f64 {
        self.0.iter().map(|f| f.eval(z)).sum()
    }

    fn stored(&self) -> Option<StoredMap> {
        Some(StoredMap::Sum {
            parts: self.0.iter().map(|m| m.stored()).collect::<Option<_>>()?,
        })
    }
}

/// Builds [`StoredMap::Sum`] from parts (used by the sum dispersion's interpolant).
pub(crate) fn sum_of(parts: Vec<Box<dyn Interpolant>>) -> Box<dyn Interpolant> {
    Box::new(SumOfMaps(parts))
}

/// Scattered interpolation in inputs scaled to \[0, 1\]: q = (z − lo)·scale.
pub(crate) struct ScaledScatteredMap {
    inner: ScatteredInterpolant,
    lo: Vec<f64>,
    scale: Vec<f64>,
}

impl ScaledScatteredMap {
    pub(crate) fn new(inner: ScatteredInterpolant, lo: Vec<f64>, scale: Vec<f64>) -> Self {
        Self { inner, lo, scale }
    }
}

impl Interpolant for ScaledScatteredMap {
    fn eval(&self, z: &[f64]) -> f64 {
        let q: Vec<f64> = z
            .iter()
            .zip(self.lo.iter().zip(&self.scale))
            .map(|(v, (l, s))| (v - l) * s)
            .collect();
        self.inner.eval(&q)
    }

    fn stored(&self) -> Option<StoredMap> {
        let tree = self.inner.tree();
        let p = tree.dim();
        let mut data = Vec::with_capacity(tree.len() * p);
        for i in 0..tree.len() {
            data.extend_from_slice(tree.point(i));
        }
        Some(StoredMap::Scattered {
            nodes: StoredPoints { channels: p, data },
            values: self.inner.values().to_vec(),
            inverse_distance_neighbours: match self.inner.weighting() {
                Weighting::Nearest => None,
                Weighting::InverseDistance { neighbours, .. } => Some(neighbours),
            },
            lo: self.lo.clone(),
            scale: self.scale.clone(),
        })
    }
}

//! Serialisable forms of estimated maps and of the kernels and feature maps they are built on.
//!
//! An estimated map is an [`Interpolant`](crate::Interpolant) (a trait object); [`crate::Interpolant::stored`] turns the
//! maps of this crate into a [`StoredMap`], plain data that serde writes and reads, and
//! `StoredMap::interpolant` (in [`crate::estimate`]) turns it back into a map that evaluates to the same floating-point
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
//! [`crate::Kernel::stored_kernel`] / [`crate::Interpolant::stored`]; writing such an estimate is an error that
//! names the block. A user kernel or feature map may be stored by name
//! ([`StoredKernel::User`]) and supplied again when the estimate is read
//! ([`crate::dispersion::user`]).

use serde::{Deserialize, Serialize};
use structid_lti::Signal;

use crate::error::{Error, Result};

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
    /// [`Error::InvalidStructure`] when the data are not a whole number of points.
    pub fn to_signal(&self) -> Result<Signal> {
        if self.channels == 0 || !self.data.len().is_multiple_of(self.channels) {
            return Err(Error::InvalidStructure(format!(
                "stored points: {} values are not a whole number of points of {} coordinate(s)",
                self.data.len(),
                self.channels
            )));
        }
        Ok(Signal::new(self.channels, self.data.clone())?)
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.data.len().checked_div(self.channels).unwrap_or(0)
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A kernel or feature map as plain data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
#[non_exhaustive]
pub enum StoredKernel {
    /// The Gaussian kernel of width σ.
    Gaussian {
        /// σ.
        sigma: f64,
    },
    /// The Fourier-series kernel with its domain normalisation, harmonics and weights.
    Fourier(FourierStored),
    /// Monomial features.
    Polynomial(PolynomialStored),
    /// Nyström features of a Gaussian kernel.
    Nystrom(NystromStored),
    /// Stacked feature maps: the parts in order.
    Stacked {
        /// The stacked feature maps.
        parts: Vec<StoredKernel>,
        /// The part whose weights follow a width change.
        width_part: Option<usize>,
    },
    /// A user-defined kernel or feature map ([`crate::dispersion::user`]): its name only, since
    /// its code cannot be stored. Reading the estimate back takes it from a
    /// [`crate::dispersion::user::UserKernels`] registry.
    User {
        /// The name it is registered under.
        name: String,
        /// The width it was used at, when it has one (a selected σ is not the registered
        /// kernel's own).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        width: Option<f64>,
    },
}

/// The numbers that define the Fourier-series kernel: per input the affine map t = offset +
/// scale·z and the weights λ₀…λ_N, the feature weights and, for tensor products, each
/// feature's (harmonic, cos/sin) per input.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FourierStored {
    /// Per input: (offset, scale).
    pub affine: Vec<(f64, f64)>,
    /// Per input: λ₀…λ_N.
    pub lambda: Vec<Vec<f64>>,
    /// Additive (Σ_j N_j(z_j)) rather than tensor-product features.
    pub additive: bool,
    /// Feature weights in feature order.
    pub weights: Vec<f64>,
    /// Tensor features: (harmonic, 0 = cos / 1 = sin) per input, per feature.
    pub index: Vec<Vec<(usize, u8)>>,
    /// Whether λ is the Gaussian-like family.
    pub gaussian_like: bool,
}

/// The numbers that define monomial features: per input (centre, half-width), the exponents
/// of each feature and the feature weights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolynomialStored {
    /// Per input: (centre, half-width).
    pub affine: Vec<(f64, f64)>,
    /// Per feature: one exponent per input.
    pub exponents: Vec<Vec<u32>>,
    /// Feature weights.
    pub weights: Vec<f64>,
}

/// The numbers that define Nyström features of a Gaussian kernel.
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

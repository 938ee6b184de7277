//! Model files: the known linear block, the signal names and the unknown static maps, in TOML.
//!
//! # Format
//!
//! ```toml
//! [lft]                      # discrete-time realisation of the known block, paper eq. (7)
//! sample_time = 1.0          # optional
//! A = [[0.5]]                # n×n ; an empty list [] when n = 0
//! Bu = [[1.0]]
//! Be = [[0.0]]
//! Bw = [[1.0]]
//! Cy = [[1.0]]
//! Dyu = [[0.0]]
//! Dye = [[1.0]]
//! Dyw = [[0.0]]
//! Cz = [[0.0]]
//! Dzu = [[1.0]]
//! Dze = [[0.0]]
//! Dzw = [[0.0]]
//!
//! [signals]
//! u = ["u0"]                 # CSV column names of the known inputs, in order
//! y = ["y0"]                 # CSV column names of the measured outputs, in order
//! # z = ["z0"]               # optional: measured z columns; otherwise z is computed from u and y
//!
//! [[nonlinearity]]
//! name = "f"
//! inputs = [0]               # indices into z
//! output = 0                 # index into w
//! dispersion = { kind = "gaussian", sigma = 0.4 }
//! truth = "tanh(z0)"         # optional, used by `simulate` and for error reports
//! ```
//!
//! ## `[lft]`
//! The twelve matrices of x⁺ = A x + Bu u + Be e + Bw w, y = Cy x + Dyu u + Dye e + Dyw w,
//! z = Cz x + Dzu u + Dze e + Dzw w, each a list of rows. Dimensions are inferred: n from the
//! rows of A, n_u from `[signals].u`, n_y from `[signals].y`, n_e from the columns of Be, Dye or
//! Dze, n_w from the columns of Bw, Dyw or Dzw, and n_z from the rows of Cz, Dzu, Dze or Dzw
//! (or from `[signals].z`). A matrix with a zero dimension may be written `[]` (for example
//! `A = []`, `Bu = []` and `Cy = []` when n = 0). An omitted matrix is all zeros. Integers are
//! accepted where numbers are expected.
//!
//! `time = "continuous"` (with `sample_time` required) declares A, Bu, Be and Bw as a
//! continuous-time realisation, discretised by a zero-order hold on the whole input [u e w]
//! (C and D are unchanged). The default is `time = "discrete"`.
//!
//! ## `[linear]` (instead of `[lft]`)
//! A polynomial linear block G with one output, y = Σ_i B_i(q)/F(q)·u_i, placed in a named
//! structure from which the LFT is built ([`LinearSpec`]):
//!
//! ```toml
//! [linear]
//! structure = "output-feedback"
//! sample_time = 0.1              # optional (T_s of rate feedback; 1 when omitted)
//! den = [1.0, -1.2, 0.5]         # F(q) = 1 + f₁q⁻¹ + f₂q⁻²
//! num = [[0.0, 0.3, 0.2]]        # per input u: coefficients of 1, q⁻¹, … (leading zeros = delay)
//! # num_w = [0.0, -0.3, -0.2]    # output feedback only: the feedback path's own numerator
//! ```
//!
//! | `structure` | model | z (measurable because) |
//! |---|---|---|
//! | `"output-feedback"` | y = G·(u − N(y)) + e | z = y, measured |
//! | `"input"` | y = G·N(u) + e | z = u |
//! | `"output"` | y = N(G·u) + e (a sensor map) | z = G·u, depends on u only |
//! | `"rate-feedback"` | y = G·(u − N(ẏ)) + e, ẏ_k = (y_k − y_(k−1))/T_s | z = Δy/T_s = Ψ(q)·y with the LTI Ψ = (1 − q⁻¹)/T_s, a dynamic Ψ_M |
//! | `"lti"` | y = G·u + e | no map |
//!
//! `num` has one numerator per input u; `input`, `output` and `rate-feedback` take exactly one
//! input. The feedback structures need a delay in G (num starting with 0), otherwise y_k would
//! depend on N(y_k) or N(ẏ_k); `num_w` applies to `output-feedback` only. Every structure but
//! `lti` has one map (`inputs = [0]`, `output = 0`); `[signals].z` is not used. Only
//! `output-feedback` and `input` can be refined by `structid refine`.
//!
//! ## `[[nonlinearity]]`
//! One table per unknown static map: a unique `name`, the z channels it reads (`inputs`, indices
//! into z), the w channel it writes (`output`), its `dispersion` and optionally its `truth`.
//! Every w channel must be written by exactly one block — except in a *nominal* `[lft]` model
//! (a file without blocks), whose w columns and z rows are declared injection points and signals
//! for `structid discover` (see `[discover]`); [`ModelFile::model_lft`] and
//! [`ModelFile::to_model`] drop the w columns (w = 0).
//!
//! * `dispersion = { kind = "gaussian", sigma = 0.4 }`: the Gaussian RKHS dispersion. When
//!   `sigma` is omitted (or the whole `dispersion` key is), σ is chosen when the data are known:
//!   **σ = 0.1 × the largest range (max − min) of the block's input channels of z** (0.1 when
//!   that range is zero). Supported kinds: `gaussian`.
//! * `truth = "tanh(z0)"`: the true map as an expression in `z0, z1, …` (the block's inputs in
//!   order, or `z` for a single input); see [`structid_core::ExprMap`].
//! * `truth = { table = "file.csv" }` (or `table = "file.csv"` in the block): a lookup table, a
//!   CSV file with a header and columns `z…, value` (piecewise linear in one input, bilinear on
//!   a complete grid in two), the path relative to the model file's directory. A trailing
//!   column `std` (the posterior standard deviation in the map files of `structid identify`)
//!   is ignored.
//!
//! ## `[discover]` (nominal models only)
//! What a nominal model ([`DiscoverSpec`]) declares for `structid discover`: extra candidate
//! locations of a missing block on its declared channels, and states named for localisation.
//!
//! ```toml
//! [discover]
//! locations = [ { name = "spring", z = 0, w = 0 } ]   # a block reading z row 0, writing w column 0
//! states = [ { name = "velocity", state = 1 } ]        # state 1 of the LFT, named
//! ```
//!
//! Indices are 0-based and must exist (z < n_z, w < n_w, state < n); names are non-empty and
//! unique, and a location may not be called like a built-in one ([`BUILT_IN_LOCATIONS`],
//! `declared-<i>`); each (z, w) pair is declared once. The section is rejected in a file with
//! `[[nonlinearity]]` blocks. Both keys are optional (`[[discover.locations]]` tables work too).
//!
//! Every error names the line of the offending key.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::DMatrix;
use serde::Deserialize;
use structid_core::paper::gaussian_noise;
use structid_core::refine::LinearStructure;
use structid_core::{
    Combination, Data, Dispersion, ExprMap, FourierDispersion, FourierWeights, GraphInterpolation,
    Interpolant, KernelDispersion, Lft, LftMatrices, LookupTable, LowRankGaussian, MapBinding,
    Model, NonlinearBlock, PolynomialDispersion, Simulation, Site, SumDispersion, TotalVariation,
};
use structid_linear::PolynomialModel;
use structid_lti::{ContinuousStateSpace, Signal};
use toml::Spanned;

use crate::data_file::{DataTable, format_number};
use crate::error::IoError;

/// The names of the data columns that carry each signal.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SignalNames {
    /// Columns of the known inputs u, in order (n_u of them).
    pub u: Vec<String>,
    /// Columns of the measured outputs y, in order (n_y of them).
    pub y: Vec<String>,
    /// Columns of measured z, when z is measured (n_z of them); otherwise z is computed from u
    /// and y.
    pub z: Option<Vec<String>>,
}

/// The dispersion of a block as written in the model file.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum DispersionSpec {
    /// The Gaussian RKHS dispersion of width σ; `None` picks σ from the data (see
    /// [`default_sigma`]).
    Gaussian {
        /// Kernel width σ (> 0), if given.
        sigma: Option<f64>,
    },
    /// The Gaussian with k ≪ L Nyström features ([`structid_core::LowRankGaussian`]).
    LowRankGaussian {
        /// Kernel width σ (> 0), if given.
        sigma: Option<f64>,
        /// Relative trace tolerance of the pivoted Cholesky factorisation (default 1e-8).
        tolerance: Option<f64>,
    },
    /// The Fourier-series kernel with Gaussian-like weights (the periodised Gaussian of width σ),
    /// see [`structid_core::FourierDispersion`].
    Fourier {
        /// Width σ (> 0) in units of z, if given (otherwise as for the Gaussian).
        sigma: Option<f64>,
        /// Harmonics per input, if given (otherwise chosen from σ).
        harmonics: Option<usize>,
        /// Additive instead of tensor-product combination of several inputs.
        additive: bool,
    },
    /// Ridge regression on the monomials up to a total degree
    /// ([`structid_core::PolynomialDispersion`]).
    Polynomial {
        /// Total degree d.
        degree: usize,
        /// Weight λ of each normalised monomial (default 1).
        scale: Option<f64>,
    },
    /// A kernel dispersion plus a polynomial trend ([`structid_core::SumDispersion`]): the key
    /// `trend = d` or `trend = { degree = d, scale = λ }` on a Gaussian, low-rank Gaussian or
    /// Fourier dispersion. Outside the data the estimate follows the polynomial.
    WithTrend {
        /// The kernel part.
        kernel: Box<DispersionSpec>,
        /// Total degree of the trend.
        degree: usize,
        /// Weight λ of each normalised monomial of the trend (default 1).
        scale: Option<f64>,
    },
    /// The total-variation dispersion ([`structid_core::TotalVariation`]); needs the clarabel or
    /// admm solver (chosen automatically).
    TotalVariation {
        /// k of the k-nearest-neighbour graph for blocks with several inputs (default 8).
        neighbours: Option<usize>,
        /// Interpolation between nodes for several inputs (default inverse distance).
        interpolation: Option<GraphInterpolation>,
    },
}

/// The dispersion kinds a model file may name.
pub const SUPPORTED_DISPERSIONS: &[&str] = &[
    "gaussian",
    "gaussian-lowrank",
    "fourier",
    "polynomial",
    "tv",
];

/// The default kernel width for a block whose inputs are `z` (one point per sample):
/// 0.1 × the largest range (max − min) over its channels, or 0.1 when every channel is
/// constant.
///
/// ```
/// use structid_io::default_sigma;
/// use structid_lti::Signal;
/// let z = Signal::from_channels(&[vec![-1.0, 3.0], vec![0.0, 1.0]]).unwrap();
/// assert!((default_sigma(&z) - 0.4).abs() < 1e-15);
/// ```
pub fn default_sigma(z: &Signal) -> f64 {
    let mut widest = 0.0f64;
    for c in 0..z.channels() {
        let (lo, hi) = z
            .channel(c)
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        if hi > lo {
            widest = widest.max(hi - lo);
        }
    }
    if widest.is_finite() && widest > 0.0 {
        0.1 * widest
    } else {
        0.1
    }
}

impl DispersionSpec {
    /// The kind as written in the file (`"gaussian"`).
    pub fn kind(&self) -> &'static str {
        match self {
            DispersionSpec::Gaussian { .. } => "gaussian",
            DispersionSpec::Fourier { .. } => "fourier",
            DispersionSpec::LowRankGaussian { .. } => "gaussian-lowrank",
            DispersionSpec::TotalVariation { .. } => "tv",
            DispersionSpec::Polynomial { .. } => "polynomial",
            DispersionSpec::WithTrend { kernel, .. } => kernel.kind(),
        }
    }

    /// The kernel width given in the file, if any.
    pub fn sigma(&self) -> Option<f64> {
        match self {
            DispersionSpec::Gaussian { sigma }
            | DispersionSpec::Fourier { sigma, .. }
            | DispersionSpec::LowRankGaussian { sigma, .. } => *sigma,
            DispersionSpec::WithTrend { kernel, .. } => kernel.sigma(),
            DispersionSpec::TotalVariation { .. } | DispersionSpec::Polynomial { .. } => None,
        }
    }

    /// The same dispersion with σ set to `sigma` (kinds without σ are returned unchanged).
    ///
    /// ```
    /// use structid_io::DispersionSpec;
    /// let d = DispersionSpec::Gaussian { sigma: None }.with_sigma(Some(0.3));
    /// assert_eq!(d.sigma(), Some(0.3));
    /// ```
    pub fn with_sigma(&self, sigma: Option<f64>) -> Self {
        let mut out = self.clone();
        match &mut out {
            DispersionSpec::Gaussian { sigma: s }
            | DispersionSpec::Fourier { sigma: s, .. }
            | DispersionSpec::LowRankGaussian { sigma: s, .. } => *s = sigma,
            DispersionSpec::WithTrend { kernel, .. } => **kernel = kernel.with_sigma(sigma),
            DispersionSpec::TotalVariation { .. } | DispersionSpec::Polynomial { .. } => {}
        }
        out
    }

    /// Builds the dispersion. `sigma_override` replaces the file's σ; without either, σ is
    /// [`default_sigma`] of `block_z` (the block's input samples), which is then required.
    pub fn build(
        &self,
        sigma_override: Option<f64>,
        block_z: Option<&Signal>,
    ) -> Result<Arc<dyn Dispersion>, IoError> {
        if let DispersionSpec::TotalVariation {
            neighbours,
            interpolation,
        } = self
        {
            let mut tv = TotalVariation::new();
            if let Some(k) = neighbours {
                tv = tv.with_neighbours(*k)?;
            }
            if let Some(i) = interpolation {
                tv = tv.with_interpolation(*i);
            }
            return Ok(Arc::new(tv));
        }
        if let DispersionSpec::Polynomial { degree, scale } = self {
            return Ok(Arc::new(polynomial(*degree, *scale)?));
        }
        if let DispersionSpec::WithTrend {
            kernel,
            degree,
            scale,
        } = self
        {
            let k = kernel.build(sigma_override, block_z)?;
            return Ok(Arc::new(SumDispersion::new(vec![
                k,
                Arc::new(polynomial(*degree, *scale)?),
            ])?));
        }
        let s = match (sigma_override, self.sigma(), block_z) {
            (Some(s), _, _) | (None, Some(s), _) => s,
            (None, None, Some(z)) => default_sigma(z),
            (None, None, None) => {
                return Err(IoError::InvalidArgument(format!(
                    "the {} dispersion has no sigma and no data were given to choose one",
                    self.kind()
                )));
            }
        };
        match self {
            DispersionSpec::Gaussian { .. } => Ok(Arc::new(KernelDispersion::gaussian(s)?)),
            DispersionSpec::LowRankGaussian { tolerance, .. } => Ok(Arc::new(
                LowRankGaussian::new(s, tolerance.unwrap_or(1e-8))?,
            )),
            DispersionSpec::TotalVariation { .. }
            | DispersionSpec::Polynomial { .. }
            | DispersionSpec::WithTrend { .. } => unreachable!("handled above"),
            DispersionSpec::Fourier {
                harmonics,
                additive,
                ..
            } => {
                let mut d = FourierDispersion::new(FourierWeights::GaussianLike { sigma: s })?;
                if let Some(n) = harmonics {
                    d = d.with_harmonics(*n);
                }
                if *additive {
                    d = d.with_combination(Combination::Additive);
                }
                Ok(Arc::new(d))
            }
        }
    }
}

fn polynomial(degree: usize, scale: Option<f64>) -> Result<PolynomialDispersion, IoError> {
    let p = PolynomialDispersion::new(degree)?;
    Ok(match scale {
        Some(s) => p.with_scale(s)?,
        None => p,
    })
}

/// The true map of a block, when the model file gives one.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum TruthSpec {
    /// An expression in `z0, z1, …` (see [`structid_core::ExprMap`]).
    Expression(String),
    /// A lookup table read from a CSV file.
    Table {
        /// The file name as written in the model file (relative to its directory).
        file: String,
        /// The table.
        table: LookupTable,
    },
}

impl TruthSpec {
    /// The map as an interpolant of `dim` inputs.
    pub fn to_interpolant(&self, dim: usize) -> Result<Box<dyn Interpolant>, IoError> {
        match self {
            TruthSpec::Expression(text) => Ok(Box::new(ExprMap::parse(text, dim)?)),
            TruthSpec::Table { table, file } => {
                if table.dim() != dim {
                    return Err(IoError::InvalidArgument(format!(
                        "truth table `{file}` has {} input column(s) but the block has {dim} input(s)",
                        table.dim()
                    )));
                }
                Ok(Box::new(table.clone()))
            }
        }
    }

    /// A one-line description: the expression, or `table <file>`.
    pub fn describe(&self) -> String {
        match self {
            TruthSpec::Expression(t) => t.clone(),
            TruthSpec::Table { file, .. } => format!("table {file}"),
        }
    }
}

/// One `[[nonlinearity]]` entry.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockSpec {
    /// Unique name, used in reports and output file names.
    pub name: String,
    /// Indices into z of the block's inputs.
    pub inputs: Vec<usize>,
    /// Index into w of the block's output.
    pub output: usize,
    /// Its dispersion.
    pub dispersion: DispersionSpec,
    /// Its true map, if known.
    pub truth: Option<TruthSpec>,
}

impl BlockSpec {
    /// The true map as an interpolant, if the block has one.
    pub fn truth_map(&self) -> Result<Option<Box<dyn Interpolant>>, IoError> {
        self.truth
            .as_ref()
            .map(|t| t.to_interpolant(self.inputs.len()))
            .transpose()
    }
}

/// A parsed and validated model file.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelFile {
    /// The known linear block (discrete time).
    pub lft: Lft,
    /// The polynomial form of the linear block when the file gives `[linear]` instead of
    /// `[lft]` (then `lft` is its realisation).
    pub linear: Option<LinearSpec>,
    /// Data column names.
    pub signals: SignalNames,
    /// The unknown static maps, in file order.
    pub blocks: Vec<BlockSpec>,
    /// The `[discover]` section of a nominal model (one without blocks): declared candidate
    /// locations and named states for `structid discover`.
    pub discover: Option<DiscoverSpec>,
    /// The file it was read from.
    pub path: Option<PathBuf>,
}

/// A candidate location declared in `[discover]`: a block reading z row `z` and writing
/// w column `w` of the nominal model's LFT.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeclaredLocationSpec {
    /// Its name (unique, not empty, not the key of a built-in location), e.g. `spring`.
    pub name: String,
    /// The z row the block reads (< n_z).
    pub z: usize,
    /// The w column the block writes (< n_w).
    pub w: usize,
}

/// A state of the nominal model's LFT named in `[discover]` for localisation.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NamedStateSpec {
    /// Its name (unique, not empty), e.g. `velocity`.
    pub name: String,
    /// The state's index in the LFT (< n).
    pub state: usize,
}

/// The `[discover]` section: what a nominal model (a file without `[[nonlinearity]]` blocks)
/// declares for `structid discover`, in file order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DiscoverSpec {
    /// Extra candidate locations of the missing block, besides the built-in ones.
    pub locations: Vec<DeclaredLocationSpec>,
    /// Named states, offered as candidate signals when localising an effect.
    pub states: Vec<NamedStateSpec>,
}

/// The keys of the built-in discovery locations; a declared location may not take one of
/// these names (nor `declared-<i>`), since `structid discover --locations` accepts both.
pub const BUILT_IN_LOCATIONS: &[&str] = &["input", "output", "output-feedback", "rate-feedback"];

// ---------------------------------------------------------------------------------------------
// Raw (serde) form

type RawMatrix = Spanned<Vec<Spanned<Vec<f64>>>>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    lft: Option<Spanned<RawLft>>,
    linear: Option<Spanned<RawLinear>>,
    signals: Spanned<RawSignals>,
    #[serde(default)]
    nonlinearity: Vec<Spanned<RawBlock>>,
    discover: Option<Spanned<RawDiscover>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDiscover {
    #[serde(default)]
    locations: Vec<Spanned<RawLocation>>,
    #[serde(default)]
    states: Vec<Spanned<RawState>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLocation {
    name: Spanned<String>,
    z: Spanned<i64>,
    w: Spanned<i64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawState {
    name: Spanned<String>,
    state: Spanned<i64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLft {
    time: Option<Spanned<String>>,
    sample_time: Option<Spanned<f64>>,
    #[serde(rename = "A", alias = "a")]
    a: Option<RawMatrix>,
    #[serde(rename = "Bu", alias = "bu", alias = "B_u")]
    bu: Option<RawMatrix>,
    #[serde(rename = "Be", alias = "be", alias = "B_e")]
    be: Option<RawMatrix>,
    #[serde(rename = "Bw", alias = "bw", alias = "B_w")]
    bw: Option<RawMatrix>,
    #[serde(rename = "Cy", alias = "cy", alias = "C_y")]
    cy: Option<RawMatrix>,
    #[serde(rename = "Dyu", alias = "dyu", alias = "D_yu")]
    dyu: Option<RawMatrix>,
    #[serde(rename = "Dye", alias = "dye", alias = "D_ye")]
    dye: Option<RawMatrix>,
    #[serde(rename = "Dyw", alias = "dyw", alias = "D_yw")]
    dyw: Option<RawMatrix>,
    #[serde(rename = "Cz", alias = "cz", alias = "C_z")]
    cz: Option<RawMatrix>,
    #[serde(rename = "Dzu", alias = "dzu", alias = "D_zu")]
    dzu: Option<RawMatrix>,
    #[serde(rename = "Dze", alias = "dze", alias = "D_ze")]
    dze: Option<RawMatrix>,
    #[serde(rename = "Dzw", alias = "dzw", alias = "D_zw")]
    dzw: Option<RawMatrix>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLinear {
    structure: Spanned<String>,
    sample_time: Option<Spanned<f64>>,
    den: Spanned<Vec<f64>>,
    num: Spanned<Vec<Vec<f64>>>,
    num_w: Option<Spanned<Vec<f64>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSignals {
    u: Option<Spanned<Vec<String>>>,
    y: Option<Spanned<Vec<String>>>,
    z: Option<Spanned<Vec<String>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBlock {
    name: Spanned<String>,
    inputs: Spanned<toml::Value>,
    output: Spanned<i64>,
    dispersion: Option<Spanned<toml::Value>>,
    truth: Option<Spanned<toml::Value>>,
    table: Option<Spanned<String>>,
}

// ---------------------------------------------------------------------------------------------
// Locations

pub(crate) struct Source<'a> {
    text: &'a str,
    line_starts: Vec<usize>,
}

impl<'a> Source<'a> {
    pub(crate) fn new(text: &'a str) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        Self { text, line_starts }
    }

    /// One-based (line, column) of a byte offset; the column counts characters.
    pub(crate) fn line_col(&self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.text.len());
        let line = self.line_starts.partition_point(|&s| s <= offset).max(1);
        let start = self.line_starts[line - 1];
        let col = self
            .text
            .get(start..offset)
            .map_or(offset - start, |s| s.chars().count())
            + 1;
        (line, col)
    }

    pub(crate) fn line(&self, offset: usize) -> usize {
        self.line_col(offset).0
    }

    fn line_text(&self, line: usize) -> &str {
        let start = self
            .line_starts
            .get(line - 1)
            .copied()
            .unwrap_or(self.text.len());
        let end = self
            .line_starts
            .get(line)
            .copied()
            .unwrap_or(self.text.len());
        self.text
            .get(start..end)
            .unwrap_or("")
            .trim_end_matches(['\n', '\r'])
    }
}

pub(crate) fn err_at(line: usize, message: impl Into<String>) -> IoError {
    IoError::Model {
        path: None,
        line: Some(line),
        column: None,
        message: message.into(),
    }
}

fn plural(n: usize, word: &str) -> String {
    if n == 1 {
        format!("{n} {word}")
    } else {
        format!("{n} {word}s")
    }
}

fn entries(n: usize) -> String {
    if n == 1 {
        "1 entry".into()
    } else {
        format!("{n} entries")
    }
}

// ---------------------------------------------------------------------------------------------
// Matrices and dimensions

struct MatIn {
    name: &'static str,
    given: bool,
    line: usize,
    rows: Vec<Vec<f64>>,
    row_lines: Vec<usize>,
}

impl MatIn {
    fn new(
        name: &'static str,
        raw: Option<RawMatrix>,
        src: &Source<'_>,
        fallback_line: usize,
    ) -> Result<Self, IoError> {
        let Some(raw) = raw else {
            return Ok(Self {
                name,
                given: false,
                line: fallback_line,
                rows: Vec::new(),
                row_lines: Vec::new(),
            });
        };
        let line = src.line(raw.span().start);
        let mut rows = Vec::new();
        let mut row_lines = Vec::new();
        for r in raw.into_inner() {
            row_lines.push(src.line(r.span().start));
            rows.push(r.into_inner());
        }
        let m = Self {
            name,
            given: true,
            line,
            rows,
            row_lines,
        };
        if let Some(first) = m.rows.first() {
            for (i, r) in m.rows.iter().enumerate() {
                if r.len() != first.len() {
                    return Err(err_at(
                        m.row_lines[i],
                        format!(
                            "matrix {name}: row {} has {} but row 1 has {}; all rows need the same length",
                            i + 1,
                            entries(r.len()),
                            entries(first.len()),
                        ),
                    ));
                }
                if let Some(j) = r.iter().position(|v| !v.is_finite()) {
                    return Err(err_at(
                        m.row_lines[i],
                        format!(
                            "matrix {name} has the non-finite entry {} at row {}, column {}",
                            r[j],
                            i + 1,
                            j + 1
                        ),
                    ));
                }
            }
        }
        Ok(m)
    }

    /// Rows, when the matrix is given and not `[]`.
    fn known_rows(&self) -> Option<usize> {
        (self.given && !self.rows.is_empty()).then_some(self.rows.len())
    }

    /// Columns, when the matrix is given and has at least one row.
    fn known_cols(&self) -> Option<usize> {
        self.rows.first().map(Vec::len)
    }

    fn to_matrix(&self, rows: &Dim, cols: &Dim) -> Result<DMatrix<f64>, IoError> {
        let (r, c) = (rows.value, cols.value);
        if !self.given {
            return Ok(DMatrix::zeros(r, c));
        }
        if self.rows.is_empty() {
            if r == 0 || c == 0 {
                return Ok(DMatrix::zeros(r, c));
            }
            return Err(err_at(
                self.line,
                format!(
                    "matrix {} is empty but must be {r}×{c}: {}, and {}",
                    self.name, rows.source, cols.source
                ),
            ));
        }
        if self.rows.len() != r {
            return Err(err_at(
                self.line,
                format!(
                    "matrix {} has {} but {}",
                    self.name,
                    plural(self.rows.len(), "row"),
                    rows.source
                ),
            ));
        }
        let nc = self.rows[0].len();
        if nc != c {
            return Err(err_at(
                self.line,
                format!(
                    "matrix {} has {} but {}",
                    self.name,
                    plural(nc, "column"),
                    cols.source
                ),
            ));
        }
        Ok(DMatrix::from_fn(r, c, |i, j| self.rows[i][j]))
    }
}

/// A dimension and a phrase saying where it comes from, for error messages.
struct Dim {
    value: usize,
    source: String,
    line: Option<usize>,
}

fn infer_cols(mats: &[&MatIn], what: &str, sym: &str) -> Dim {
    for m in mats {
        if let Some(c) = m.known_cols() {
            return Dim {
                value: c,
                source: format!(
                    "{} has {} ({sym} = {})",
                    m.name,
                    plural(c, "column"),
                    plural(c, what)
                ),
                line: Some(m.line),
            };
        }
    }
    let names: Vec<&str> = mats.iter().map(|m| m.name).collect();
    Dim {
        value: 0,
        source: format!("none of {} has a column, so {sym} = 0", names.join(", ")),
        line: None,
    }
}

// ---------------------------------------------------------------------------------------------
// Parsing

pub(crate) fn toml_error(e: &toml::de::Error, src: &Source<'_>) -> IoError {
    let message = e.message().trim().to_string();
    match e.span() {
        Some(span) => {
            let (line, column) = src.line_col(span.start);
            let text = src.line_text(line).trim();
            // Errors about a key or value (reported by the deserialiser) point at the key itself;
            // syntax errors at the start of a line usually come from the line before.
            let about_key = [
                "unknown field",
                "missing field",
                "invalid type",
                "invalid value",
            ]
            .iter()
            .any(|p| message.starts_with(p));
            let mut message = format!("invalid TOML: {message}");
            if column > 1 || line == 1 || about_key {
                if !text.is_empty() {
                    let _ = write!(message, " in `{text}`");
                }
            } else if let Some(prev) = (1..line)
                .rev()
                .map(|l| src.line_text(l).trim())
                .find(|t| !t.is_empty())
            {
                // The parser noticed the problem at the start of a line: the cause is usually at
                // the end of the previous one (an unclosed bracket or string).
                let _ = write!(message, " after `{prev}`");
            }
            IoError::Model {
                path: None,
                line: Some(line),
                column: Some(column),
                message,
            }
        }
        None => IoError::model(format!("invalid TOML: {message}")),
    }
}

fn check_names(
    list: &Spanned<Vec<String>>,
    key: &str,
    src: &Source<'_>,
) -> Result<Vec<String>, IoError> {
    let line = src.line(list.span().start);
    let names = list.get_ref().clone();
    for (i, n) in names.iter().enumerate() {
        if n.trim().is_empty() {
            return Err(err_at(
                line,
                format!("[signals].{key} contains an empty column name"),
            ));
        }
        if names[..i].contains(n) {
            return Err(err_at(
                line,
                format!("[signals].{key} names the column `{n}` twice"),
            ));
        }
    }
    Ok(names)
}

pub(crate) fn value_kind(v: &toml::Value) -> &'static str {
    match v {
        toml::Value::String(_) => "a string",
        toml::Value::Integer(_) => "an integer",
        toml::Value::Float(_) => "a float",
        toml::Value::Boolean(_) => "a boolean",
        toml::Value::Datetime(_) => "a date",
        toml::Value::Array(_) => "an array",
        toml::Value::Table(_) => "a table",
    }
}

/// The `[lft]` section: the twelve matrices, their dimensions and the time base.
fn parse_lft(
    raw_lft: RawLft,
    lft_line: usize,
    u: &[String],
    y: &[String],
    z_names: &Option<(Vec<String>, usize)>,
    src: &Source<'_>,
) -> Result<(Lft, Dim, Dim), IoError> {
    // Matrices.
    let mat = |name, raw| MatIn::new(name, raw, src, lft_line);
    let a = mat("A", raw_lft.a)?;
    let bu = mat("Bu", raw_lft.bu)?;
    let be = mat("Be", raw_lft.be)?;
    let bw = mat("Bw", raw_lft.bw)?;
    let cy = mat("Cy", raw_lft.cy)?;
    let dyu = mat("Dyu", raw_lft.dyu)?;
    let dye = mat("Dye", raw_lft.dye)?;
    let dyw = mat("Dyw", raw_lft.dyw)?;
    let cz = mat("Cz", raw_lft.cz)?;
    let dzu = mat("Dzu", raw_lft.dzu)?;
    let dze = mat("Dze", raw_lft.dze)?;
    let dzw = mat("Dzw", raw_lft.dzw)?;

    let n = a.known_rows().unwrap_or(0);
    if let Some(c) = a.known_cols()
        && c != n
    {
        return Err(err_at(
            a.line,
            format!(
                "matrix A has {} and {}; it must be square (n×n)",
                plural(n, "row"),
                plural(c, "column")
            ),
        ));
    }
    let dn = Dim {
        value: n,
        source: if n > 0 {
            format!("A is {n}×{n} (n = {})", plural(n, "state"))
        } else if a.given {
            "A is empty (n = 0 states)".into()
        } else {
            "A is not given (n = 0 states)".into()
        },
        line: Some(a.line),
    };
    let du = Dim {
        value: u.len(),
        source: format!("[signals].u names {}", plural(u.len(), "input")),
        line: None,
    };
    let dy = Dim {
        value: y.len(),
        source: format!("[signals].y names {}", plural(y.len(), "output")),
        line: None,
    };
    let de = infer_cols(&[&be, &dye, &dze], "noise channel", "n_e");
    let dw = infer_cols(&[&bw, &dyw, &dzw], "map output", "n_w");
    let dz = {
        let from_mat = [&cz, &dzu, &dze, &dzw]
            .into_iter()
            .find_map(|m| m.known_rows().map(|r| (m, r)));
        match (from_mat, z_names) {
            (Some((m, r)), _) => Dim {
                value: r,
                source: format!(
                    "{} has {} (n_z = {})",
                    m.name,
                    plural(r, "row"),
                    plural(r, "map input")
                ),
                line: Some(m.line),
            },
            (None, Some((names, _))) => Dim {
                value: names.len(),
                source: format!("[signals].z names {}", plural(names.len(), "column")),
                line: None,
            },
            (None, None) => Dim {
                value: 0,
                source: "none of Cz, Dzu, Dze, Dzw has a row, so n_z = 0".into(),
                line: None,
            },
        }
    };
    let mut m = LftMatrices {
        a: a.to_matrix(&dn, &dn)?,
        bu: bu.to_matrix(&dn, &du)?,
        be: be.to_matrix(&dn, &de)?,
        bw: bw.to_matrix(&dn, &dw)?,
        cy: cy.to_matrix(&dy, &dn)?,
        dyu: dyu.to_matrix(&dy, &du)?,
        dye: dye.to_matrix(&dy, &de)?,
        dyw: dyw.to_matrix(&dy, &dw)?,
        cz: cz.to_matrix(&dz, &dn)?,
        dzu: dzu.to_matrix(&dz, &du)?,
        dze: dze.to_matrix(&dz, &de)?,
        dzw: dzw.to_matrix(&dz, &dw)?,
    };
    if let Some((names, line)) = z_names
        && names.len() != dz.value
    {
        return Err(err_at(
            *line,
            format!(
                "[signals].z names {} but {}",
                plural(names.len(), "column"),
                dz.source
            ),
        ));
    }

    // Time base.
    let sample_time = match &raw_lft.sample_time {
        Some(ts) => {
            let v = *ts.get_ref();
            if !(v.is_finite() && v > 0.0) {
                return Err(err_at(
                    src.line(ts.span().start),
                    format!(
                        "sample_time = {v} is invalid; it must be a finite number of seconds greater than zero"
                    ),
                ));
            }
            Some(v)
        }
        None => None,
    };
    match raw_lft
        .time
        .as_ref()
        .map(|t| (t.get_ref().as_str(), src.line(t.span().start)))
    {
        None | Some(("discrete", _)) => {}
        Some(("continuous", line)) => {
            let Some(ts) = sample_time else {
                return Err(err_at(
                    line,
                    "time = \"continuous\" needs a sample_time (seconds) for the zero-order-hold discretisation",
                ));
            };
            let (ne, nw, nu) = (de.value, dw.value, du.value);
            let mut b = DMatrix::zeros(n, nu + ne + nw);
            b.columns_mut(0, nu).copy_from(&m.bu);
            b.columns_mut(nu, ne).copy_from(&m.be);
            b.columns_mut(nu + ne, nw).copy_from(&m.bw);
            let sys = ContinuousStateSpace::new(
                m.a.clone(),
                b,
                DMatrix::zeros(0, n),
                DMatrix::zeros(0, nu + ne + nw),
            )
            .and_then(|s| s.discretize_zoh(ts))
            .map_err(|e| {
                err_at(
                    line,
                    format!("cannot discretise the continuous-time block: {e}"),
                )
            })?;
            m.a = sys.a().clone();
            m.bu = sys.b().columns(0, nu).into_owned();
            m.be = sys.b().columns(nu, ne).into_owned();
            m.bw = sys.b().columns(nu + ne, nw).into_owned();
        }
        Some((other, line)) => {
            return Err(err_at(
                line,
                format!(
                    "time = \"{other}\" is not supported; use \"discrete\" (default) or \"continuous\""
                ),
            ));
        }
    }
    let mut lft = Lft::new(m).map_err(|e| err_at(lft_line, e.to_string()))?;
    if let Some(ts) = sample_time {
        lft = lft
            .with_sample_time(ts)
            .map_err(|e| err_at(lft_line, e.to_string()))?;
    }

    Ok((lft, dz, dw))
}

/// The `[linear] structure` names in the order of the documentation: the sites of
/// [`Site::name`] and `lti`, a linear model without a map.
pub const LINEAR_STRUCTURES: [&str; 5] =
    ["output-feedback", "input", "output", "rate-feedback", "lti"];

/// The site a `[linear] structure` name places the block at: `Some(None)` for `lti` (no
/// block), `None` for an unknown name.
pub fn parse_linear_structure(name: &str) -> Option<Option<Site>> {
    if name == "lti" {
        Some(None)
    } else {
        Site::parse(name).map(Some)
    }
}

/// A `[linear]` section: a polynomial linear block G (one output) in a named structure.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearSpec {
    /// Where the block sits (`None`: `structure = "lti"`, no block).
    pub structure: Option<Site>,
    /// G in the structure's form: for output feedback its inputs are [u…, w] (the last
    /// numerator is the effect of w on y, −B_u unless `num_w` was given); for an input map its
    /// one input is w; for an output (sensor) map and rate feedback its one input is u; for
    /// `lti` its inputs are u.
    pub model: PolynomialModel,
    /// Whether the feedback path has its own numerator (`num_w` given).
    pub separate_numerator: bool,
}

impl LinearSpec {
    /// The linear model `g` (its inputs are u) in the structure of `site` (`None`: `lti`):
    /// for output feedback the feedback path starts as the input path, y = G·(u − w), i.e.
    /// num = [B, −B] with a shared numerator.
    ///
    /// ```
    /// use structid_core::Site;
    /// use structid_io::LinearSpec;
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: None };
    /// let spec = LinearSpec::from_linear(&g, Some(Site::OutputFeedback));
    /// assert_eq!(spec.model.num, vec![vec![0.0, 1.0], vec![-0.0, -1.0]]);
    /// assert_eq!(spec.structure_name(), "output-feedback");
    /// ```
    pub fn from_linear(g: &PolynomialModel, site: Option<Site>) -> Self {
        let mut model = g.clone();
        if site == Some(Site::OutputFeedback)
            && let Some(b) = g.num.first()
        {
            model.num.push(b.iter().map(|x| -x).collect());
        }
        Self {
            structure: site,
            model,
            separate_numerator: false,
        }
    }

    /// The `[linear] structure` name: the site's name, or `lti`.
    pub fn structure_name(&self) -> &'static str {
        self.structure.map_or("lti", Site::name)
    }

    /// Whether `structid refine` (a [`LinearStructure`]) supports the structure: output
    /// feedback and an input map.
    pub fn refinable(&self) -> bool {
        matches!(self.structure, Some(Site::OutputFeedback | Site::Input))
    }

    /// The structure as a [`LinearStructure`] for [`structid_core::refine::refine`]; `block`
    /// names the map. `None` for `lti` (no map) and for `output` and `rate-feedback`, which
    /// refinement does not support (see [`LinearSpec::refinable`]).
    pub fn structure(&self, block: &str) -> Option<LinearStructure> {
        let site = self.structure.filter(|_| self.refinable())?;
        LinearStructure::new(block, site)
            .ok()
            .map(|s| s.with_separate_numerator(self.separate_numerator))
    }

    /// The LFT of this linear block in its structure.
    pub fn lft(&self) -> Result<Lft, IoError> {
        Ok(match self.structure {
            Some(Site::OutputFeedback | Site::Input) => self
                .structure(BLOCK_PLACEHOLDER)
                .expect("output feedback and input maps are refinable structures")
                .lft(&self.model)?,
            // The LFT does not depend on the block's dispersion.
            _ => self
                .to_structure(BLOCK_PLACEHOLDER, Arc::new(PolynomialDispersion::new(1)?))
                .lft()?,
        })
    }

    /// The [`Structure`](structid_core::Structure) of this block: G in its structure's form,
    /// the block called `block` at its site with `dispersion`.
    pub fn to_structure(&self, block: &str, d: Arc<dyn Dispersion>) -> structid_core::Structure {
        use structid_core::Structure;
        match self.structure {
            None => Structure::linear(&self.model),
            Some(Site::OutputFeedback) => Structure::output_feedback_with_path(&self.model, d),
            Some(site) => Structure::new(&self.model, site, d),
        }
        .named(block)
    }
}

const BLOCK_PLACEHOLDER: &str = "N";

/// The `[linear]` section: a polynomial G in a named structure, realised as an LFT.
fn parse_linear(
    raw: RawLinear,
    line: usize,
    u: &[String],
    y: &[String],
    z_names: &Option<(Vec<String>, usize)>,
    src: &Source<'_>,
) -> Result<(LinearSpec, Lft, Dim, Dim), IoError> {
    let structure_line = src.line(raw.structure.span().start);
    let Some(structure) = parse_linear_structure(raw.structure.get_ref()) else {
        return Err(err_at(
            structure_line,
            format!(
                "[linear] structure = \"{}\" is unknown; supported: {}",
                raw.structure.get_ref(),
                LINEAR_STRUCTURES
                    .iter()
                    .map(|k| format!("\"{k}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    };
    let structure_name = structure.map_or("lti", Site::name);
    if y.len() != 1 {
        return Err(err_at(
            line,
            format!(
                "[linear] describes a block with one output, but [signals].y names {}",
                plural(y.len(), "output")
            ),
        ));
    }
    if let Some((_, zl)) = z_names {
        return Err(err_at(
            *zl,
            "[signals].z is not used with [linear]: the structure fixes z (y for output feedback, u for an input map, \
             G·u for an output map, Δy/T_s for rate feedback)",
        ));
    }
    let sample_time = match &raw.sample_time {
        Some(ts) if !(ts.get_ref().is_finite() && *ts.get_ref() > 0.0) => {
            return Err(err_at(
                src.line(ts.span().start),
                format!(
                    "sample_time = {} is invalid; it must be a finite number of seconds greater than zero",
                    ts.get_ref()
                ),
            ));
        }
        Some(ts) => Some(*ts.get_ref()),
        None => None,
    };
    let den_line = src.line(raw.den.span().start);
    let den = raw.den.get_ref().clone();
    if den.is_empty() || den[0] == 0.0 || den.iter().any(|v| !v.is_finite()) {
        return Err(err_at(
            den_line,
            "[linear] den must list finite coefficients of 1, q⁻¹, q⁻², … with a nonzero first one",
        ));
    }
    let num_line = src.line(raw.num.span().start);
    let mut num = raw.num.get_ref().clone();
    if num.iter().flatten().any(|v| !v.is_finite()) {
        return Err(err_at(
            num_line,
            "[linear] num has a coefficient that is not finite",
        ));
    }
    let single_input = matches!(
        structure,
        Some(Site::Input | Site::Output | Site::RateFeedback)
    );
    let expected = if single_input { 1 } else { u.len() };
    if single_input && u.len() != 1 {
        return Err(err_at(
            line,
            format!(
                "structure = \"{}\" has one input u, but [signals].u names {}",
                structure_name,
                plural(u.len(), "input")
            ),
        ));
    }
    if num.len() != expected {
        return Err(err_at(
            num_line,
            format!(
                "[linear] num has {} but the structure needs {expected} (one per input u)",
                plural(num.len(), "numerator")
            ),
        ));
    }
    // An all-zero numerator would be read as "no path at all" (the delay is read from the
    // leading zeros), so refinement could never move it.
    if structure.is_some()
        && let Some(i) = num.iter().position(|b| b.iter().all(|v| *v == 0.0))
    {
        return Err(err_at(
            num_line,
            format!(
                "[linear] num[{i}] is all zeros: start from small nonzero coefficients after the \
                 delay (e.g. [0.0, 0.01]) so that the path can be estimated"
            ),
        ));
    }
    if let Some(nw) = &raw.num_w
        && nw.get_ref().iter().all(|v| *v == 0.0)
    {
        return Err(err_at(
            src.line(nw.span().start),
            "[linear] num_w is all zeros: start from small nonzero coefficients after the delay \
             (e.g. [0.0, -0.01]) so that the feedback path can be estimated",
        ));
    }
    let mut separate = false;
    match (&raw.num_w, structure) {
        (Some(nw), Some(Site::OutputFeedback)) => {
            let l = src.line(nw.span().start);
            let nw = nw.get_ref();
            if nw.iter().any(|v| !v.is_finite()) {
                return Err(err_at(
                    l,
                    "[linear] num_w has a coefficient that is not finite",
                ));
            }
            if nw.first().is_some_and(|b| *b != 0.0) {
                return Err(err_at(
                    l,
                    "[linear] num_w starts with a direct term; the feedback path needs a delay \
                     (num_w = [0.0, …]), otherwise y_k depends on N(y_k)",
                ));
            }
            separate = true;
            num.push(nw.clone());
        }
        (Some(nw), _) => {
            return Err(err_at(
                src.line(nw.span().start),
                format!(
                    "num_w (a separate feedback numerator) only applies to structure = \"output-feedback\", not \"{}\"",
                    structure_name
                ),
            ));
        }
        (None, Some(Site::OutputFeedback)) => {
            if u.len() != 1 {
                return Err(err_at(
                    line,
                    "an output-feedback structure with several inputs u needs its feedback numerator num_w",
                ));
            }
            if num[0].first().is_some_and(|b| *b != 0.0) {
                return Err(err_at(
                    num_line,
                    "[linear] num starts with a direct term; the feedback path shares it and needs \
                     a delay (num = [[0.0, …]]), otherwise y_k depends on N(y_k)",
                ));
            }
            let bw: Vec<f64> = num[0].iter().map(|x| -x).collect();
            num.push(if bw.is_empty() { vec![0.0] } else { bw });
        }
        (None, Some(Site::RateFeedback)) => {
            if num[0].first().is_some_and(|b| *b != 0.0) {
                return Err(err_at(
                    num_line,
                    "[linear] num starts with a direct term; rate feedback needs a delay \
                     (num = [[0.0, …]]), otherwise y_k depends on N(ẏ_k)",
                ));
            }
        }
        (None, _) => {}
    }
    let spec = LinearSpec {
        structure,
        model: PolynomialModel {
            num,
            den,
            sample_time,
        },
        separate_numerator: separate,
    };
    let lft = spec.lft().map_err(|e| err_at(line, e.to_string()))?;
    let (nz, nw) = (lft.dims().z, lft.dims().w);
    let what = match structure {
        Some(Site::OutputFeedback) => "one map in feedback from y (z = y)",
        Some(Site::Input) => "one map at the input (z = u)",
        Some(Site::Output) => "one map at the output (z = G·u)",
        Some(Site::RateFeedback) => "one map in feedback from the rate of y (z = Δy/T_s)",
        Some(Site::Declared { .. }) | None => "no map",
    };
    let dim = |value: usize| Dim {
        value,
        source: format!("[linear] structure = \"{structure_name}\" has {what}"),
        line: Some(structure_line),
    };
    Ok((spec, lft, dim(nz), dim(nw)))
}

fn parse_dispersion(
    v: Option<&Spanned<toml::Value>>,
    block: &str,
    src: &Source<'_>,
) -> Result<DispersionSpec, IoError> {
    let Some(v) = v else {
        return Ok(DispersionSpec::Gaussian { sigma: None });
    };
    let line = src.line(v.span().start);
    let owner = format!("block `{block}`");
    match v.get_ref() {
        toml::Value::String(k) => match k.as_str() {
            "gaussian" => Ok(DispersionSpec::Gaussian { sigma: None }),
            "tv" => Ok(DispersionSpec::TotalVariation {
                neighbours: None,
                interpolation: None,
            }),
            "fourier" => Ok(DispersionSpec::Fourier {
                sigma: None,
                harmonics: None,
                additive: false,
            }),
            other => Err(unknown_dispersion_kind(&owner, other, line)),
        },
        toml::Value::Table(t) => dispersion_from_table(t, &owner, &|_| line),
        other => Err(err_at(
            line,
            format!(
                "{owner}: dispersion must be a table such as {{ kind = \"gaussian\", sigma = 0.4 }}, not {}",
                value_kind(other)
            ),
        )),
    }
}

fn unknown_dispersion_kind(owner: &str, kind: &str, line: usize) -> IoError {
    err_at(
        line,
        format!(
            "{owner}: unknown dispersion kind `{kind}`; supported kinds: {}",
            SUPPORTED_DISPERSIONS.join(", ")
        ),
    )
}

/// The keys a dispersion kind takes besides `kind`, or `None` for an unknown kind.
pub(crate) fn dispersion_keys(kind: &str) -> Option<&'static [&'static str]> {
    match kind {
        "gaussian" => Some(&["sigma", "trend"]),
        "fourier" => Some(&["sigma", "harmonics", "combine", "trend"]),
        "gaussian-lowrank" => Some(&["sigma", "tolerance", "trend"]),
        "polynomial" => Some(&["degree", "scale"]),
        "tv" => Some(&["neighbours", "interpolation"]),
        _ => None,
    }
}

/// A dispersion from the keys of a table (`kind` and the kind's parameters). `owner` starts
/// every message (e.g. "block `f`"); `line_of(key)` gives the line to report for a key
/// (`"kind"` for problems with the table as a whole).
pub(crate) fn dispersion_from_table(
    t: &toml::Table,
    owner: &str,
    line_of: &dyn Fn(&str) -> usize,
) -> Result<DispersionSpec, IoError> {
    let base = base_dispersion_from_table(t, owner, line_of)?;
    let Some(trend) = t.get("trend") else {
        return Ok(base);
    };
    let line = line_of("trend");
    let (degree, scale) = match trend {
        toml::Value::Integer(_) => (polynomial_degree(Some(trend), owner, line)?, None),
        toml::Value::Table(tt) => {
            if let Some(key) = tt
                .keys()
                .find(|k| !["degree", "scale"].contains(&k.as_str()))
            {
                return Err(err_at(
                    line,
                    format!(
                        "{owner}: unknown key `{key}` in the trend; it takes `degree`, `scale`"
                    ),
                ));
            }
            (
                polynomial_degree(tt.get("degree"), owner, line)?,
                polynomial_scale(tt.get("scale"), owner, line)?,
            )
        }
        other => {
            return Err(err_at(
                line,
                format!(
                    "{owner}: trend must be a degree (trend = 3) or a table (trend = {{ degree = 3, scale = 10.0 }}), not {}",
                    value_kind(other)
                ),
            ));
        }
    };
    Ok(DispersionSpec::WithTrend {
        kernel: Box::new(base),
        degree,
        scale,
    })
}

fn polynomial_degree(v: Option<&toml::Value>, owner: &str, line: usize) -> Result<usize, IoError> {
    match v {
        Some(toml::Value::Integer(d)) if (0..=64).contains(d) => Ok(*d as usize),
        Some(other) => Err(err_at(
            line,
            format!(
                "{owner}: the polynomial degree must be a whole number from 0 to 64, not {other}"
            ),
        )),
        None => Err(err_at(
            line,
            format!("{owner}: a polynomial needs its `degree`, e.g. degree = 3"),
        )),
    }
}

fn polynomial_scale(
    v: Option<&toml::Value>,
    owner: &str,
    line: usize,
) -> Result<Option<f64>, IoError> {
    let s = match v {
        None => return Ok(None),
        Some(toml::Value::Float(s)) => *s,
        Some(toml::Value::Integer(s)) => *s as f64,
        Some(other) => {
            return Err(err_at(
                line,
                format!(
                    "{owner}: the polynomial scale must be a number, not {}",
                    value_kind(other)
                ),
            ));
        }
    };
    if s.is_finite() && s > 0.0 {
        Ok(Some(s))
    } else {
        Err(err_at(
            line,
            format!("{owner}: the polynomial scale {s} must be a finite number greater than zero"),
        ))
    }
}

fn base_dispersion_from_table(
    t: &toml::Table,
    owner: &str,
    line_of: &dyn Fn(&str) -> usize,
) -> Result<DispersionSpec, IoError> {
    let supported = SUPPORTED_DISPERSIONS.join(", ");
    let line = line_of("kind");
    let kind = match t.get("kind") {
        Some(toml::Value::String(k)) => k.as_str(),
        Some(other) => {
            return Err(err_at(
                line,
                format!(
                    "{owner}: dispersion `kind` must be a string (one of: {supported}), not {}",
                    value_kind(other)
                ),
            ));
        }
        None => {
            return Err(err_at(
                line,
                format!(
                    "{owner}: the dispersion needs a `kind` (one of: {supported}), \
                     e.g. dispersion = {{ kind = \"gaussian\", sigma = 0.4 }}"
                ),
            ));
        }
    };
    let Some(allowed) = dispersion_keys(kind) else {
        return Err(unknown_dispersion_kind(owner, kind, line));
    };
    if let Some(key) = t
        .keys()
        .find(|k| k.as_str() != "kind" && !allowed.contains(&k.as_str()))
    {
        return Err(err_at(
            line_of(key),
            format!(
                "{owner}: unknown key `{key}` in the {kind} dispersion; it takes {}",
                allowed
                    .iter()
                    .map(|k| format!("`{k}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    }
    let sigma = match t.get("sigma") {
        None => None,
        Some(toml::Value::Float(s)) => Some(*s),
        Some(toml::Value::Integer(s)) => Some(*s as f64),
        Some(other) => {
            return Err(err_at(
                line_of("sigma"),
                format!("{owner}: sigma must be a number, not {}", value_kind(other)),
            ));
        }
    };
    if let Some(s) = sigma
        && !(s.is_finite() && s > 0.0)
    {
        return Err(err_at(
            line_of("sigma"),
            format!(
                "{owner}: sigma = {s} is invalid; it must be a finite number greater than zero"
            ),
        ));
    }
    match kind {
        "gaussian" => Ok(DispersionSpec::Gaussian { sigma }),
        "polynomial" => Ok(DispersionSpec::Polynomial {
            degree: polynomial_degree(t.get("degree"), owner, line_of("degree"))?,
            scale: polynomial_scale(t.get("scale"), owner, line_of("scale"))?,
        }),
        "tv" => {
            let neighbours = match t.get("neighbours") {
                None => None,
                Some(toml::Value::Integer(n)) if *n >= 1 && *n <= 1024 => Some(*n as usize),
                Some(other) => {
                    return Err(err_at(
                        line_of("neighbours"),
                        format!(
                            "{owner}: neighbours must be a whole number from 1 to 1024, not {other}"
                        ),
                    ));
                }
            };
            let interpolation = match t.get("interpolation") {
                None => None,
                Some(toml::Value::String(c)) if c == "inverse-distance" => {
                    Some(GraphInterpolation::InverseDistance)
                }
                Some(toml::Value::String(c)) if c == "nearest" => Some(GraphInterpolation::Nearest),
                Some(other) => {
                    return Err(err_at(
                        line_of("interpolation"),
                        format!(
                            "{owner}: interpolation must be \"inverse-distance\" or \"nearest\", not {other}"
                        ),
                    ));
                }
            };
            Ok(DispersionSpec::TotalVariation {
                neighbours,
                interpolation,
            })
        }
        "gaussian-lowrank" => {
            let tolerance = match t.get("tolerance") {
                None => None,
                Some(toml::Value::Float(v)) if *v > 0.0 && *v < 1.0 => Some(*v),
                Some(other) => {
                    return Err(err_at(
                        line_of("tolerance"),
                        format!("{owner}: tolerance must be a number in (0, 1), not {other}"),
                    ));
                }
            };
            Ok(DispersionSpec::LowRankGaussian { sigma, tolerance })
        }
        _ => {
            let harmonics = match t.get("harmonics") {
                None => None,
                Some(toml::Value::Integer(n)) if *n >= 1 && *n <= 4096 => Some(*n as usize),
                Some(other) => {
                    return Err(err_at(
                        line_of("harmonics"),
                        format!(
                            "{owner}: harmonics must be a whole number from 1 to 4096, not {other}"
                        ),
                    ));
                }
            };
            let additive = match t.get("combine") {
                None => false,
                Some(toml::Value::String(c)) if c == "tensor" => false,
                Some(toml::Value::String(c)) if c == "additive" => true,
                Some(other) => {
                    return Err(err_at(
                        line_of("combine"),
                        format!("{owner}: combine must be \"tensor\" or \"additive\", not {other}"),
                    ));
                }
            };
            Ok(DispersionSpec::Fourier {
                sigma,
                harmonics,
                additive,
            })
        }
    }
}

fn load_table_truth(
    file: &str,
    dim: usize,
    block: &str,
    base_dir: Option<&Path>,
    line: usize,
) -> Result<TruthSpec, IoError> {
    let path = match base_dir {
        Some(d) => d.join(file),
        None => PathBuf::from(file),
    };
    let table = DataTable::read(&path).map_err(|e| {
        let cause = match &e {
            IoError::Read { source, .. } => format!("cannot read `{}`: {source}", path.display()),
            other => other.to_string(),
        };
        err_at(line, format!("truth table of block `{block}`: {cause}"))
    })?;
    let mut table = table;
    // The map files of `structid identify` may end with the posterior standard deviation.
    if table.names.len() == dim + 2 && table.names.last().is_some_and(|n| n == "std") {
        table.names.pop();
        table.columns.pop();
    }
    if table.names.len() != dim + 1 {
        return Err(err_at(
            line,
            format!(
                "truth table `{}` of block `{block}` has {} but the block has {} (expected columns z…, value)",
                path.display(),
                plural(table.names.len(), "column"),
                plural(dim, "input"),
            ),
        ));
    }
    if let Some((c, _)) = table
        .columns
        .iter()
        .enumerate()
        .find(|(_, col)| col.iter().any(|v| v.is_nan()))
    {
        return Err(err_at(
            line,
            format!(
                "truth table `{}` of block `{block}` has an empty field in column `{}`",
                path.display(),
                table.names[c]
            ),
        ));
    }
    let rows: Vec<Vec<f64>> = (0..table.len())
        .map(|k| table.columns.iter().map(|c| c[k]).collect())
        .collect();
    let lookup = LookupTable::from_rows(&rows).map_err(|e| {
        err_at(
            line,
            format!("truth table `{}` of block `{block}`: {e}", path.display()),
        )
    })?;
    Ok(TruthSpec::Table {
        file: file.to_string(),
        table: lookup,
    })
}

fn parse_truth(
    raw: &RawBlock,
    block: &str,
    dim: usize,
    base_dir: Option<&Path>,
    src: &Source<'_>,
) -> Result<Option<TruthSpec>, IoError> {
    let table = raw.table.as_ref();
    let truth = raw.truth.as_ref();
    if let (Some(_), Some(t)) = (truth, table) {
        return Err(err_at(
            src.line(t.span().start),
            format!("block `{block}` gives both `truth` and `table`; keep one"),
        ));
    }
    if let Some(t) = table {
        return load_table_truth(t.get_ref(), dim, block, base_dir, src.line(t.span().start))
            .map(Some);
    }
    let Some(truth) = truth else {
        return Ok(None);
    };
    let line = src.line(truth.span().start);
    match truth.get_ref() {
        toml::Value::String(expr) => {
            ExprMap::parse(expr, dim)
                .map_err(|e| err_at(line, format!("truth of block `{block}`: {e}")))?;
            Ok(Some(TruthSpec::Expression(expr.clone())))
        }
        toml::Value::Table(t) => {
            if let Some(key) = t.keys().find(|k| k.as_str() != "table") {
                return Err(err_at(
                    line,
                    format!(
                        "block `{block}`: unknown key `{key}` in truth; use truth = \"expression\" or truth = {{ table = \"file.csv\" }}"
                    ),
                ));
            }
            match t.get("table") {
                Some(toml::Value::String(file)) => {
                    load_table_truth(file, dim, block, base_dir, line).map(Some)
                }
                _ => Err(err_at(
                    line,
                    format!(
                        "block `{block}`: truth = {{ table = \"file.csv\" }} needs a file name string"
                    ),
                )),
            }
        }
        other => Err(err_at(
            line,
            format!(
                "block `{block}`: truth must be an expression string or {{ table = \"file.csv\" }}, not {}",
                value_kind(other)
            ),
        )),
    }
}

fn parse_index_list(
    v: &Spanned<toml::Value>,
    block: &str,
    src: &Source<'_>,
) -> Result<Vec<usize>, IoError> {
    let line = src.line(v.span().start);
    let bad = |what: String| {
        err_at(
            line,
            format!("block `{block}`: inputs {what}; write e.g. inputs = [0]"),
        )
    };
    let items: Vec<&toml::Value> = match v.get_ref() {
        toml::Value::Array(a) => a.iter().collect(),
        single @ toml::Value::Integer(_) => vec![single],
        other => {
            return Err(bad(format!(
                "must be a list of z indices, not {}",
                value_kind(other)
            )));
        }
    };
    let mut out = Vec::with_capacity(items.len());
    for item in items {
        match item {
            toml::Value::Integer(i) if *i >= 0 => {
                let i = usize::try_from(*i).map_err(|_| bad(format!("index {i} is too large")))?;
                if out.contains(&i) {
                    return Err(bad(format!("lists z[{i}] twice")));
                }
                out.push(i);
            }
            toml::Value::Integer(i) => return Err(bad(format!("contains the negative index {i}"))),
            other => {
                return Err(bad(format!(
                    "must contain integers, not {}",
                    value_kind(other)
                )));
            }
        }
    }
    if out.is_empty() {
        return Err(bad("is empty; a block reads at least one z channel".into()));
    }
    Ok(out)
}

/// Whether `name` has the form `declared-<i>`, the key of the i-th declared location.
fn is_declared_key(name: &str) -> bool {
    name.strip_prefix("declared-")
        .is_some_and(|i| !i.is_empty() && i.bytes().all(|b| b.is_ascii_digit()))
}

/// The `[discover]` section, checked against the LFT: indices in range, names unique and not
/// empty, each location once and a valid single-block LFT.
fn parse_discover(
    raw: &RawDiscover,
    lft: &Lft,
    dz: &Dim,
    dw: &Dim,
    src: &Source<'_>,
) -> Result<DiscoverSpec, IoError> {
    let index = |v: &Spanned<i64>, key: &str, owner: &str| -> Result<(usize, usize), IoError> {
        let line = src.line(v.span().start);
        let i = *v.get_ref();
        usize::try_from(i).map(|i| (i, line)).map_err(|_| {
            err_at(
                line,
                format!("{owner}: {key} = {i} is negative; indices start at 0"),
            )
        })
    };
    let name_of = |v: &Spanned<String>, what: &str| -> Result<(String, usize), IoError> {
        let line = src.line(v.span().start);
        let name = v.get_ref().trim().to_string();
        if name.is_empty() {
            return Err(err_at(
                line,
                format!("a [discover] {what} has an empty name"),
            ));
        }
        Ok((name, line))
    };

    let mut out = DiscoverSpec::default();
    let mut lines: Vec<usize> = Vec::new();
    for entry in &raw.locations {
        let entry_line = src.line(entry.span().start);
        let r = entry.get_ref();
        let (name, name_line) = name_of(&r.name, "location")?;
        if BUILT_IN_LOCATIONS.contains(&name.as_str()) || is_declared_key(&name) {
            return Err(err_at(
                name_line,
                format!(
                    "the [discover] location `{name}` has the name of a built-in location key \
                     ({}, declared-<i>); choose another name",
                    BUILT_IN_LOCATIONS.join(", ")
                ),
            ));
        }
        if let Some(j) = out.locations.iter().position(|l| l.name == name) {
            return Err(err_at(
                name_line,
                format!(
                    "two [discover] locations are named `{name}` (lines {} and {name_line}); names \
                     must be unique",
                    lines[j]
                ),
            ));
        }
        let owner = format!("[discover] location `{name}`");
        let (z, z_line) = index(&r.z, "z", &owner)?;
        if z >= dz.value {
            return Err(err_at(
                z_line,
                format!(
                    "{owner} reads z row {z} but the model has {} (indices 0…): {}",
                    plural(dz.value, "z row"),
                    dz.source
                ),
            ));
        }
        let (w, w_line) = index(&r.w, "w", &owner)?;
        if w >= dw.value {
            return Err(err_at(
                w_line,
                format!(
                    "{owner} writes w column {w} but the model has {} (indices 0…): {}",
                    plural(dw.value, "w column"),
                    dw.source
                ),
            ));
        }
        if let Some(j) = out.locations.iter().position(|l| l.z == z && l.w == w) {
            return Err(err_at(
                entry_line,
                format!(
                    "[discover] locations `{}` (line {}) and `{name}` are both z row {z} → w column \
                     {w}; declare each location once",
                    out.locations[j].name, lines[j]
                ),
            ));
        }
        // Safety net: the core builds the block's LFT from the same indices.
        Site::Declared { z, w }
            .insert(lft)
            .map_err(|e| err_at(entry_line, format!("{owner}: {e}")))?;
        out.locations.push(DeclaredLocationSpec { name, z, w });
        lines.push(entry_line);
    }

    let n = lft.dims().states;
    let mut lines: Vec<usize> = Vec::new();
    for entry in &raw.states {
        let r = entry.get_ref();
        let (name, name_line) = name_of(&r.name, "state")?;
        if let Some(j) = out.states.iter().position(|s| s.name == name) {
            return Err(err_at(
                name_line,
                format!(
                    "two [discover] states are named `{name}` (lines {} and {name_line}); names \
                     must be unique",
                    lines[j]
                ),
            ));
        }
        let owner = format!("[discover] state `{name}`");
        let (state, state_line) = index(&r.state, "state", &owner)?;
        if state >= n {
            return Err(err_at(
                state_line,
                format!(
                    "{owner} is state {state} but the model has {} (indices 0…)",
                    plural(n, "state")
                ),
            ));
        }
        out.states.push(NamedStateSpec { name, state });
        lines.push(name_line);
    }
    Ok(out)
}

/// The LFT without its w columns: a nominal model, whose declared injection points carry
/// w = 0 (its z rows are kept).
fn without_w(lft: &Lft) -> Result<Lft, IoError> {
    let m = lft.matrices();
    let d = lft.dims();
    let nominal = Lft::new(LftMatrices {
        a: m.a.clone(),
        bu: m.bu.clone(),
        be: m.be.clone(),
        bw: DMatrix::zeros(d.states, 0),
        cy: m.cy.clone(),
        dyu: m.dyu.clone(),
        dye: m.dye.clone(),
        dyw: DMatrix::zeros(d.y, 0),
        cz: m.cz.clone(),
        dzu: m.dzu.clone(),
        dze: m.dze.clone(),
        dzw: DMatrix::zeros(d.z, 0),
    })?;
    Ok(match lft.sample_time() {
        Some(ts) => nominal.with_sample_time(ts)?,
        None => nominal,
    })
}

impl ModelFile {
    /// Reads and validates a model file. Relative truth-table paths are resolved against the
    /// file's directory.
    pub fn from_path(path: &Path) -> Result<Self, IoError> {
        let text = std::fs::read_to_string(path).map_err(|source| IoError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let base = path.parent().filter(|p| !p.as_os_str().is_empty());
        let mut mf = Self::parse(&text, Some(base.unwrap_or(Path::new("."))))
            .map_err(|e| e.with_path(path))?;
        mf.path = Some(path.to_path_buf());
        Ok(mf)
    }

    /// Parses and validates model-file text. `base_dir` resolves relative truth-table paths
    /// (the current directory when `None`).
    ///
    /// ```
    /// use structid_io::ModelFile;
    /// let text = r#"
    /// [lft]
    /// A = []
    /// Dyw = [[1.0]]
    /// Dye = [[1.0]]
    /// Dzu = [[1.0]]
    /// [signals]
    /// u = ["u"]
    /// y = ["y"]
    /// [[nonlinearity]]
    /// name = "N"
    /// inputs = [0]
    /// output = 0
    /// truth = "tanh(z0)"
    /// "#;
    /// let m = ModelFile::parse(text, None).unwrap();
    /// assert_eq!(m.lft.dims().states, 0);
    /// let bad = text.replace("Dzu = [[1.0]]", "Dzu = [[1.0, 2.0]]");
    /// let e = ModelFile::parse(&bad, None).unwrap_err().to_string();
    /// assert_eq!(e, "model file: matrix Dzu has 2 columns but [signals].u names 1 input (line 6)");
    /// ```
    pub fn parse(text: &str, base_dir: Option<&Path>) -> Result<Self, IoError> {
        let src = Source::new(text);
        let raw: RawFile = toml::from_str(text).map_err(|e| toml_error(&e, &src))?;
        let signals_line = src.line(raw.signals.span().start);
        let raw_signals = raw.signals.into_inner();

        // Signals.
        let u = match &raw_signals.u {
            Some(list) => check_names(list, "u", &src)?,
            None => Vec::new(),
        };
        let (y, y_line) = match &raw_signals.y {
            Some(list) => (check_names(list, "y", &src)?, src.line(list.span().start)),
            None => (Vec::new(), signals_line),
        };
        if y.is_empty() {
            return Err(err_at(
                y_line,
                "[signals].y names no measured output; list the CSV column(s) of y, e.g. y = [\"y0\"]",
            ));
        }
        let z_names = match &raw_signals.z {
            Some(list) => Some((check_names(list, "z", &src)?, src.line(list.span().start))),
            None => None,
        };

        let (lft, dz, dw, lft_line, linear) = match (raw.lft, raw.linear) {
            (Some(raw_lft), None) => {
                let lft_line = src.line(raw_lft.span().start);
                let (lft, dz, dw) =
                    parse_lft(raw_lft.into_inner(), lft_line, &u, &y, &z_names, &src)?;
                (lft, dz, dw, lft_line, None)
            }
            (None, Some(raw_linear)) => {
                let line = src.line(raw_linear.span().start);
                let (spec, lft, dz, dw) =
                    parse_linear(raw_linear.into_inner(), line, &u, &y, &z_names, &src)?;
                (lft, dz, dw, line, Some(spec))
            }
            (Some(_), Some(raw_linear)) => {
                return Err(err_at(
                    src.line(raw_linear.span().start),
                    "the file has both [lft] and [linear]; give the linear block one way",
                ));
            }
            (None, None) => {
                return Err(err_at(
                    1,
                    "the file has neither [lft] (a state-space LFT) nor [linear] (a polynomial \
                     linear block with a named structure)",
                ));
            }
        };

        // Blocks.
        let mut blocks: Vec<BlockSpec> = Vec::with_capacity(raw.nonlinearity.len());
        let mut block_lines: Vec<usize> = Vec::new();
        let mut owner: Vec<Option<usize>> = vec![None; dw.value];
        for entry in &raw.nonlinearity {
            let entry_line = src.line(entry.span().start);
            let rb = entry.get_ref();
            let name = rb.name.get_ref().trim().to_string();
            let name_line = src.line(rb.name.span().start);
            if name.is_empty() {
                return Err(err_at(
                    name_line,
                    "a [[nonlinearity]] block has an empty name",
                ));
            }
            if let Some(j) = blocks.iter().position(|b| b.name == name) {
                return Err(err_at(
                    name_line,
                    format!(
                        "two [[nonlinearity]] blocks are named `{name}` (lines {} and {name_line}); names must be unique",
                        block_lines[j]
                    ),
                ));
            }
            let inputs = parse_index_list(&rb.inputs, &name, &src)?;
            if let Some(&bad) = inputs.iter().find(|&&i| i >= dz.value) {
                return Err(err_at(
                    src.line(rb.inputs.span().start),
                    format!(
                        "block `{name}` reads z[{bad}] but the model has {}: {}",
                        plural(dz.value, "z signal"),
                        dz.source
                    ),
                ));
            }
            let out_line = src.line(rb.output.span().start);
            let output = *rb.output.get_ref();
            if output < 0 || output as u64 >= dw.value as u64 {
                return Err(err_at(
                    out_line,
                    format!(
                        "block `{name}` writes w[{output}] but the model has {} (indices 0…): {}",
                        plural(dw.value, "w signal"),
                        dw.source
                    ),
                ));
            }
            let output = output as usize;
            if let Some(j) = owner[output] {
                return Err(err_at(
                    out_line,
                    format!(
                        "blocks `{}` (line {}) and `{name}` both write w[{output}]; each w channel needs exactly one block",
                        blocks[j].name, block_lines[j]
                    ),
                ));
            }
            owner[output] = Some(blocks.len());
            let dispersion = parse_dispersion(rb.dispersion.as_ref(), &name, &src)?;
            let truth = parse_truth(rb, &name, inputs.len(), base_dir, &src)?;
            blocks.push(BlockSpec {
                name,
                inputs,
                output,
                dispersion,
                truth,
            });
            block_lines.push(entry_line);
        }

        // Discovery: a nominal model's declared locations and named states.
        let discover = match &raw.discover {
            Some(d) => {
                if let Some(first) = block_lines.first() {
                    return Err(err_at(
                        src.line(d.span().start),
                        format!(
                            "[discover] describes a nominal model for `structid discover`, but the \
                             file has {} (the first at line {first}); remove [discover] or the blocks",
                            plural(blocks.len(), "[[nonlinearity]] block")
                        ),
                    ));
                }
                Some(parse_discover(d.get_ref(), &lft, &dz, &dw, &src)?)
            }
            None => None,
        };

        // Every w channel needs its block, except in a nominal [lft] model (no blocks), whose
        // w columns are declared injection points.
        let nominal = blocks.is_empty() && linear.is_none();
        if !nominal && let Some(c) = owner.iter().position(Option::is_none) {
            let unused = if linear.is_none() {
                "; unused w columns (injection points declared for `structid discover`, see \
                 [discover]) are only allowed in a nominal model without [[nonlinearity]] blocks"
            } else {
                ""
            };
            return Err(err_at(
                dw.line.unwrap_or(lft_line),
                format!(
                    "w[{c}] is not produced by any block ({}); add a [[nonlinearity]] with output = {c}{unused}",
                    dw.source
                ),
            ));
        }

        let signals = SignalNames {
            u,
            y,
            z: z_names.map(|(n, _)| n),
        };
        let mf = Self {
            lft,
            linear,
            signals,
            blocks,
            discover,
            path: None,
        };
        // Safety net: the core's own validation must agree.
        mf.to_model(Some(1.0), None)?;
        Ok(mf)
    }

    /// Builds the core [`Model`]: each block's dispersion with σ from `sigma_override`, else
    /// from the file, else [`default_sigma`] of the block's channels of `z_for_defaults` (the
    /// full z signal, L × n_z), which is then required. A nominal model (no blocks) drops its
    /// w columns, the injection points it declares for `structid discover`: there w = 0.
    pub fn to_model(
        &self,
        sigma_override: Option<f64>,
        z_for_defaults: Option<&Signal>,
    ) -> Result<Model, IoError> {
        if let Some(s) = sigma_override
            && !(s.is_finite() && s > 0.0)
        {
            return Err(IoError::InvalidArgument(format!(
                "invalid sigma {s}: it must be a finite number greater than zero"
            )));
        }
        let nz = self.lft.dims().z;
        if let Some(z) = z_for_defaults
            && z.channels() != nz
        {
            return Err(IoError::InvalidArgument(format!(
                "the z signal for default kernel widths has {} channel(s) but the model has {nz}",
                z.channels()
            )));
        }
        let mut blocks = Vec::with_capacity(self.blocks.len());
        for b in &self.blocks {
            let bz = z_for_defaults.map(|z| z.select_channels(&b.inputs));
            let d = b
                .dispersion
                .build(sigma_override, bz.as_ref())
                .map_err(|e| match e {
                    IoError::InvalidArgument(m) => {
                        IoError::InvalidArgument(format!("block `{}`: {m}", b.name))
                    }
                    other => other,
                })?;
            blocks.push(NonlinearBlock::new(
                b.name.clone(),
                b.inputs.clone(),
                b.output,
                d,
            ));
        }
        Ok(Model::new(self.model_lft()?, blocks)?)
    }

    /// The LFT that identification and simulation use: [`ModelFile::lft`] itself, except in a
    /// nominal model (no blocks), whose w columns — injection points declared for
    /// `structid discover` — are dropped (w = 0; the z rows are kept).
    ///
    /// ```
    /// use structid_io::ModelFile;
    /// let m = ModelFile::parse(r#"
    ///     [lft]
    ///     A = [[0.5]]
    ///     Bu = [[1.0]]
    ///     Bw = [[-1.0]]
    ///     Cy = [[1.0]]
    ///     Dye = [[1.0]]
    ///     Cz = [[1.0]]
    ///     [signals]
    ///     u = ["u"]
    ///     y = ["y"]
    ///     [discover]
    ///     locations = [{ name = "spring", z = 0, w = 0 }]
    /// "#, None).unwrap();
    /// assert_eq!(m.lft.dims().w, 1);
    /// assert_eq!(m.model_lft().unwrap().dims().w, 0);
    /// ```
    pub fn model_lft(&self) -> Result<Lft, IoError> {
        if self.blocks.is_empty() && self.lft.dims().w > 0 {
            without_w(&self.lft)
        } else {
            Ok(self.lft.clone())
        }
    }

    /// Simulates the model from rest with `maps` in the loop (one per block, in file order,
    /// e.g. [`ModelFile::truth_maps`]) and, when `noise_std` > 0, white Gaussian noise e of
    /// that standard deviation drawn from `seed` ([`structid_core::paper::gaussian_noise`]):
    /// the record `structid simulate --noise-std --seed` writes. A nominal model's declared w
    /// columns carry w = 0 ([`ModelFile::model_lft`]).
    ///
    /// # Errors
    /// A wrong number of maps, an algebraic loop, an input with the wrong number of channels.
    ///
    /// ```
    /// use structid_io::ModelFile;
    /// use structid_lti::Signal;
    /// let m = ModelFile::parse(r#"
    ///     [lft]
    ///     A = [[0.5]]
    ///     Bw = [[1.0]]
    ///     Cy = [[1.0]]
    ///     Dye = [[1.0]]
    ///     Dzu = [[1.0]]
    ///     [signals]
    ///     u = ["u"]
    ///     y = ["y"]
    ///     [[nonlinearity]]
    ///     name = "N"
    ///     inputs = [0]
    ///     output = 0
    ///     dispersion = { kind = "polynomial", degree = 1 }
    ///     truth = "2*z0"
    /// "#, None).unwrap();
    /// let maps = m.truth_maps().unwrap().unwrap();
    /// let maps: Vec<_> = maps.iter().map(|m| m.as_ref()).collect();
    /// let u = Signal::from_fn(3, 1, |_, _| 1.0);
    /// let sim = m.simulate(&maps, &u, 0.0, 0).unwrap();
    /// assert_eq!(sim.y.channel(0), vec![0.0, 2.0, 3.0]);
    /// ```
    pub fn simulate(
        &self,
        maps: &[&dyn Interpolant],
        u: &Signal,
        noise_std: f64,
        seed: u64,
    ) -> Result<Simulation, IoError> {
        if maps.len() != self.blocks.len() {
            return Err(structid_core::Error::DimensionMismatch {
                what: "number of maps for simulation".into(),
                expected: self.blocks.len().to_string(),
                found: maps.len().to_string(),
            }
            .into());
        }
        let lft = self.model_lft()?;
        let e = (noise_std > 0.0).then(|| gaussian_noise(u.len(), lft.dims().e, noise_std, seed));
        let bindings: Vec<MapBinding<'_>> = self
            .blocks
            .iter()
            .zip(maps)
            .map(|(b, m)| MapBinding {
                inputs: &b.inputs,
                output: b.output,
                map: *m,
            })
            .collect();
        Ok(lft.simulate(&bindings, u, e.as_ref(), None)?)
    }

    /// Gives every block the dispersion `spec` (as `structid identify --dispersion` does). When
    /// `spec` has no σ, each block keeps the σ of its own dispersion, if it had one.
    ///
    /// ```
    /// use structid_io::{DispersionSpec, ModelFile};
    /// let mut m = ModelFile::parse(r#"
    ///     [lft]
    ///     A = []
    ///     Dye = [[1.0]]
    ///     Dyw = [[1.0]]
    ///     Dzu = [[1.0]]
    ///     [signals]
    ///     u = ["u"]
    ///     y = ["y"]
    ///     [[nonlinearity]]
    ///     name = "N"
    ///     inputs = [0]
    ///     output = 0
    ///     dispersion = { kind = "gaussian", sigma = 0.5 }
    /// "#, None).unwrap();
    /// m.replace_dispersions(&DispersionSpec::Fourier { sigma: None, harmonics: None, additive: false });
    /// assert_eq!(m.blocks[0].dispersion.kind(), "fourier");
    /// assert_eq!(m.blocks[0].dispersion.sigma(), Some(0.5));
    /// ```
    pub fn replace_dispersions(&mut self, spec: &DispersionSpec) {
        for b in &mut self.blocks {
            b.dispersion = match spec.sigma() {
                Some(_) => spec.clone(),
                None => spec.with_sigma(b.dispersion.sigma()),
            };
        }
    }

    /// The true maps in block order, when **every** block has a `truth`; `None` otherwise.
    pub fn truth_maps(&self) -> Result<Option<Vec<Box<dyn Interpolant>>>, IoError> {
        let mut out = Vec::with_capacity(self.blocks.len());
        for b in &self.blocks {
            match b.truth_map()? {
                Some(m) => out.push(m),
                None => return Ok(None),
            }
        }
        Ok(Some(out))
    }

    /// Names of the z channels: `[signals].z` when z is measured, otherwise `z0, z1, …`.
    pub fn z_names(&self) -> Vec<String> {
        match &self.signals.z {
            Some(z) => z.clone(),
            None => (0..self.lft.dims().z).map(|i| format!("z{i}")).collect(),
        }
    }

    /// The record named by `[signals]`: u, y and, when listed, measured z.
    pub fn select_data(&self, table: &DataTable) -> Result<Data, IoError> {
        let u = table.select(&self.signals.u)?;
        let y = table.select(&self.signals.y)?;
        let data = Data::new(u, y)?;
        Ok(match &self.signals.z {
            Some(z) => data.with_z(table.select(z)?)?,
            None => data,
        })
    }

    /// z for a record: the measured columns when present, otherwise computed from u and y
    /// (see [`Lft::compute_z`]).
    pub fn z_signal(&self, data: &Data) -> Result<Signal, IoError> {
        match data.z() {
            Some(z) => Ok(z.clone()),
            None => Ok(self.lft.compute_z(data.u(), data.y())?.0),
        }
    }

    /// The model file in canonical form. Parsing the text (with the same base directory for
    /// truth tables) gives back the same [`Lft`], signals, blocks and `[discover]` section. A
    /// continuous-time file is written in its discretised form.
    pub fn to_toml_string(&self) -> String {
        let mut s = String::new();
        let d = self.lft.dims();
        let _ = writeln!(
            s,
            "# structid model file: known linear block (discrete time), signal names, unknown static maps.\n\
             # n = {} states, n_u = {}, n_e = {}, n_w = {}, n_y = {}, n_z = {}.",
            d.states, d.u, d.e, d.w, d.y, d.z
        );
        if let Some(lin) = &self.linear {
            write_linear(&mut s, lin);
        } else {
            write_lft(&mut s, &self.lft);
        }
        s.push_str("\n[signals]\n");
        let _ = writeln!(s, "u = {}", string_list(&self.signals.u));
        let _ = writeln!(s, "y = {}", string_list(&self.signals.y));
        if let Some(z) = &self.signals.z {
            let _ = writeln!(s, "z = {}", string_list(z));
        }
        if let Some(d) = &self.discover {
            write_discover(&mut s, d);
        }
        for b in &self.blocks {
            s.push_str("\n[[nonlinearity]]\n");
            let _ = writeln!(s, "name = {}", toml_string(&b.name));
            let _ = writeln!(
                s,
                "inputs = [{}]",
                b.inputs
                    .iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            let _ = writeln!(s, "output = {}", b.output);
            match &b.dispersion {
                DispersionSpec::Gaussian { sigma: None } => {
                    s.push_str("dispersion = { kind = \"gaussian\" }   # sigma = 0.1 × range of the block's z\n");
                }
                other => {
                    let _ = writeln!(
                        s,
                        "dispersion = {{ {} }}",
                        dispersion_keys_toml(other).join(", ")
                    );
                }
            }
            match &b.truth {
                Some(TruthSpec::Expression(e)) => {
                    let _ = writeln!(s, "truth = {}", toml_string(e));
                }
                Some(TruthSpec::Table { file, .. }) => {
                    let _ = writeln!(s, "truth = {{ table = {} }}", toml_string(file));
                }
                None => {}
            }
        }
        s
    }
}

fn write_lft(s: &mut String, lft: &Lft) {
    let m = lft.matrices();
    s.push_str("[lft]\n");
    if let Some(ts) = lft.sample_time() {
        let _ = writeln!(s, "sample_time = {}", format_number(ts));
    }
    for (name, mat) in [
        ("A", &m.a),
        ("Bu", &m.bu),
        ("Be", &m.be),
        ("Bw", &m.bw),
        ("Cy", &m.cy),
        ("Dyu", &m.dyu),
        ("Dye", &m.dye),
        ("Dyw", &m.dyw),
        ("Cz", &m.cz),
        ("Dzu", &m.dzu),
        ("Dze", &m.dze),
        ("Dzw", &m.dzw),
    ] {
        let _ = writeln!(s, "{name} = {}", matrix_toml(mat));
    }
}

fn write_discover(s: &mut String, d: &DiscoverSpec) {
    s.push_str("\n[discover]\n");
    if !d.locations.is_empty() {
        s.push_str("locations = [   # a block reading z row `z` and writing w column `w`\n");
        for l in &d.locations {
            let _ = writeln!(
                s,
                "  {{ name = {}, z = {}, w = {} }},",
                toml_string(&l.name),
                l.z,
                l.w
            );
        }
        s.push_str("]\n");
    }
    if !d.states.is_empty() {
        s.push_str("states = [   # states of the LFT named for localisation\n");
        for st in &d.states {
            let _ = writeln!(
                s,
                "  {{ name = {}, state = {} }},",
                toml_string(&st.name),
                st.state
            );
        }
        s.push_str("]\n");
    }
}

fn write_linear(s: &mut String, lin: &LinearSpec) {
    let list = |v: &[f64]| {
        format!(
            "[{}]",
            v.iter()
                .map(|x| format_number(*x))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    s.push_str("[linear]\n");
    let _ = writeln!(s, "structure = {}", toml_string(lin.structure_name()));
    if let Some(ts) = lin.model.sample_time {
        let _ = writeln!(s, "sample_time = {}", format_number(ts));
    }
    let _ = writeln!(s, "den = {}", list(&lin.model.den));
    let n_u = match lin.structure {
        Some(Site::OutputFeedback) => lin.model.num.len() - 1,
        _ => lin.model.num.len(),
    };
    let _ = writeln!(
        s,
        "num = [{}]",
        lin.model.num[..n_u]
            .iter()
            .map(|b| list(b))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if lin.separate_numerator {
        let _ = writeln!(s, "num_w = {}", list(&lin.model.num[n_u]));
    }
}

/// The `key = value` pairs of a dispersion's inline table, `kind` first.
fn dispersion_keys_toml(spec: &DispersionSpec) -> Vec<String> {
    let mut parts = vec![format!("kind = \"{}\"", spec.kind())];
    let sigma = |parts: &mut Vec<String>, sigma: &Option<f64>| {
        if let Some(sg) = sigma {
            parts.push(format!("sigma = {}", format_number(*sg)));
        }
    };
    match spec {
        DispersionSpec::Gaussian { sigma: sg } => sigma(&mut parts, sg),
        DispersionSpec::TotalVariation {
            neighbours,
            interpolation,
        } => {
            if let Some(k) = neighbours {
                parts.push(format!("neighbours = {k}"));
            }
            match interpolation {
                Some(GraphInterpolation::Nearest) => {
                    parts.push("interpolation = \"nearest\"".into())
                }
                Some(GraphInterpolation::InverseDistance) => {
                    parts.push("interpolation = \"inverse-distance\"".into())
                }
                None => {}
            }
        }
        DispersionSpec::LowRankGaussian {
            sigma: sg,
            tolerance,
        } => {
            sigma(&mut parts, sg);
            if let Some(t) = tolerance {
                parts.push(format!("tolerance = {}", format_number(*t)));
            }
        }
        DispersionSpec::Fourier {
            sigma: sg,
            harmonics,
            additive,
        } => {
            sigma(&mut parts, sg);
            if let Some(n) = harmonics {
                parts.push(format!("harmonics = {n}"));
            }
            if *additive {
                parts.push("combine = \"additive\"".into());
            }
        }
        DispersionSpec::Polynomial { degree, scale } => {
            parts.push(format!("degree = {degree}"));
            if let Some(sc) = scale {
                parts.push(format!("scale = {}", format_number(*sc)));
            }
        }
        DispersionSpec::WithTrend {
            kernel,
            degree,
            scale,
        } => {
            parts = dispersion_keys_toml(kernel);
            parts.push(match scale {
                Some(sc) => format!(
                    "trend = {{ degree = {degree}, scale = {} }}",
                    format_number(*sc)
                ),
                None => format!("trend = {degree}"),
            });
        }
    }
    parts
}

fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

fn string_list(v: &[String]) -> String {
    format!(
        "[{}]",
        v.iter()
            .map(|s| toml_string(s))
            .collect::<Vec<_>>()
            .join(", ")
    )
}

fn matrix_toml(m: &DMatrix<f64>) -> String {
    if m.nrows() == 0 {
        return "[]".into();
    }
    let row = |i: usize| {
        format!(
            "[{}]",
            (0..m.ncols())
                .map(|j| format_number(m[(i, j)]))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    if m.nrows() == 1 {
        return format!("[{}]", row(0));
    }
    let mut s = String::from("[\n");
    for i in 0..m.nrows() {
        let _ = writeln!(s, "  {},", row(i));
    }
    s.push(']');
    s
}

#[cfg(test)]
mod tests;

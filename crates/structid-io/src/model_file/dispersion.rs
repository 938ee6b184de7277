//! The `dispersion` of a `[[nonlinearity]]` block ([`DispersionSpec`]): its kinds, its keys and
//! the default kernel width.

use std::sync::Arc;

use structid_core::{
    Combination, Dispersion, FourierDispersion, FourierWeights, GraphInterpolation,
    KernelDispersion, LowRankGaussian, PolynomialDispersion, SumDispersion, TotalVariation,
};
use structid_lti::Signal;
use toml::Spanned;

use super::source::{Source, err_at, value_kind};
use crate::error::IoError;

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

pub(super) fn parse_dispersion(
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

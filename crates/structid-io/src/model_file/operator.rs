//! The `operator` key of a `[[nonlinearity]]` block: a hysteresis operator (a block with
//! memory) instead of a static map.
//!
//! ```toml
//! operator = { kind = "play", half_width = 0.3 }
//! operator = { kind = "stop", threshold = 0.5 }
//! operator = { kind = "prandtl-ishlinskii", thresholds = [0.2, 0.4, 0.6], gain = 1.0, weights = [0.1, 0.1, 0.1] }
//! operator = { kind = "bouc-wen", gain = 1.0, weight = 0.5, beta = 0.5, gamma = 0.5, exponent = 1.0 }
//! ```
//!
//! The values are the operator's parameters, or the starting values of a joint fit. An
//! operator block reads one z channel and has no `truth`, `table` or `dispersion`.

use structid_core::{BoucWen, HysteresisOperator, Play, PrandtlIshlinskii, Stop};

use super::source::err_at;
use crate::error::IoError;

/// A hysteresis operator as a model file declares it.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum OperatorSpec {
    /// A play (backlash) of half-width c.
    Play {
        /// c ≥ 0.
        half_width: f64,
    },
    /// An elasto-plastic stop of threshold c.
    Stop {
        /// c > 0.
        threshold: f64,
    },
    /// w = a·z + Σ b_i·stop_(r_i)(z).
    PrandtlIshlinskii {
        /// r_i, strictly increasing and positive (fixed).
        thresholds: Vec<f64>,
        /// a.
        gain: f64,
        /// b_i.
        weights: Vec<f64>,
    },
    /// w = a·z + b·h with Bouc–Wen dynamics of h.
    BoucWen {
        /// a.
        gain: f64,
        /// b.
        weight: f64,
        /// β.
        beta: f64,
        /// γ.
        gamma: f64,
        /// The exponent n ≥ 1 (fixed).
        exponent: f64,
    },
}

impl OperatorSpec {
    /// The operator itself.
    ///
    /// ```
    /// use structid_io::OperatorSpec;
    /// let op = OperatorSpec::Play { half_width: 0.3 }.to_operator().unwrap();
    /// assert_eq!(op.kind(), "play");
    /// assert!(OperatorSpec::Play { half_width: -1.0 }.to_operator().is_err());
    /// ```
    pub fn to_operator(&self) -> Result<Box<dyn HysteresisOperator>, IoError> {
        Ok(match self {
            Self::Play { half_width } => Box::new(Play::new(*half_width)?),
            Self::Stop { threshold } => Box::new(Stop::new(*threshold)?),
            Self::PrandtlIshlinskii {
                thresholds,
                gain,
                weights,
            } => Box::new(PrandtlIshlinskii::new(
                thresholds.clone(),
                *gain,
                weights.clone(),
            )?),
            Self::BoucWen {
                gain: a,
                weight: b,
                beta,
                gamma,
                exponent: n,
            } => Box::new(BoucWen::with_exponent(*a, *b, *beta, *gamma, *n)?),
        })
    }

    /// The spec of an operator with other parameters (as [`HysteresisOperator::parameters`]
    /// orders them), keeping what is fixed: how a fitted operator is written back.
    pub fn with_parameters(&self, p: &[f64]) -> Self {
        match self {
            Self::Play { .. } => Self::Play { half_width: p[0] },
            Self::Stop { .. } => Self::Stop { threshold: p[0] },
            Self::PrandtlIshlinskii { thresholds, .. } => Self::PrandtlIshlinskii {
                thresholds: thresholds.clone(),
                gain: p[0],
                weights: p[1..].to_vec(),
            },
            Self::BoucWen { exponent, .. } => Self::BoucWen {
                gain: p[0],
                weight: p[1],
                beta: p[2],
                gamma: p[3],
                exponent: *exponent,
            },
        }
    }

    /// The inline TOML table that declares it.
    ///
    /// ```
    /// use structid_io::OperatorSpec;
    /// assert_eq!(OperatorSpec::Stop { threshold: 0.5 }.to_toml(), r#"{ kind = "stop", threshold = 0.5 }"#);
    /// ```
    pub fn to_toml(&self) -> String {
        let list = |v: &[f64]| {
            let items: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
            format!("[{}]", items.join(", "))
        };
        match self {
            Self::Play { half_width } => {
                format!(r#"{{ kind = "play", half_width = {half_width:?} }}"#)
            }
            Self::Stop { threshold } => {
                format!(r#"{{ kind = "stop", threshold = {threshold:?} }}"#)
            }
            Self::PrandtlIshlinskii {
                thresholds,
                gain,
                weights,
            } => format!(
                r#"{{ kind = "prandtl-ishlinskii", thresholds = {}, gain = {gain:?}, weights = {} }}"#,
                list(thresholds),
                list(weights)
            ),
            Self::BoucWen {
                gain,
                weight,
                beta,
                gamma,
                exponent,
            } => format!(
                r#"{{ kind = "bouc-wen", gain = {gain:?}, weight = {weight:?}, beta = {beta:?}, gamma = {gamma:?}, exponent = {exponent:?} }}"#
            ),
        }
    }
}

fn number(
    t: &toml::Table,
    key: &str,
    block: &str,
    line: usize,
    default: Option<f64>,
) -> Result<f64, IoError> {
    match (t.get(key), default) {
        (Some(toml::Value::Float(v)), _) => Ok(*v),
        (Some(toml::Value::Integer(v)), _) => Ok(*v as f64),
        (None, Some(d)) => Ok(d),
        (Some(other), _) => Err(err_at(
            line,
            format!(
                "block `{block}`: operator key `{key}` must be a number, not {}",
                other.type_str()
            ),
        )),
        (None, None) => Err(err_at(
            line,
            format!("block `{block}`: the operator needs `{key}`"),
        )),
    }
}

fn numbers(t: &toml::Table, key: &str, block: &str, line: usize) -> Result<Vec<f64>, IoError> {
    let bad = || {
        err_at(
            line,
            format!("block `{block}`: operator key `{key}` must be a list of numbers"),
        )
    };
    match t.get(key) {
        Some(toml::Value::Array(a)) => a
            .iter()
            .map(|v| match v {
                toml::Value::Float(x) => Ok(*x),
                toml::Value::Integer(x) => Ok(*x as f64),
                _ => Err(bad()),
            })
            .collect(),
        Some(_) => Err(bad()),
        None => Err(err_at(
            line,
            format!("block `{block}`: the operator needs `{key}`"),
        )),
    }
}

/// Parses an `operator = { kind = …, … }` value at `line`, checking its parameters.
pub(super) fn parse_operator(
    value: &toml::Value,
    block: &str,
    line: usize,
) -> Result<OperatorSpec, IoError> {
    let Some(t) = value.as_table() else {
        return Err(err_at(
            line,
            format!(
                "block `{block}`: operator must be a table such as {{ kind = \"play\", half_width = 0.3 }}"
            ),
        ));
    };
    let kind = t
        .get("kind")
        .and_then(toml::Value::as_str)
        .unwrap_or_default();
    let allowed: &[&str] = match kind {
        "play" => &["kind", "half_width"],
        "stop" => &["kind", "threshold"],
        "prandtl-ishlinskii" => &["kind", "thresholds", "gain", "weights"],
        "bouc-wen" => &["kind", "gain", "weight", "beta", "gamma", "exponent"],
        other => {
            return Err(err_at(
                line,
                format!(
                    "block `{block}`: unknown operator kind `{other}`; use play, stop, prandtl-ishlinskii or bouc-wen"
                ),
            ));
        }
    };
    if let Some(key) = t.keys().find(|k| !allowed.contains(&k.as_str())) {
        return Err(err_at(
            line,
            format!(
                "block `{block}`: unknown key `{key}` for a {kind} operator (it takes {})",
                allowed[1..].join(", ")
            ),
        ));
    }
    let spec = match kind {
        "play" => OperatorSpec::Play {
            half_width: number(t, "half_width", block, line, None)?,
        },
        "stop" => OperatorSpec::Stop {
            threshold: number(t, "threshold", block, line, None)?,
        },
        "prandtl-ishlinskii" => OperatorSpec::PrandtlIshlinskii {
            thresholds: numbers(t, "thresholds", block, line)?,
            gain: number(t, "gain", block, line, Some(1.0))?,
            weights: numbers(t, "weights", block, line)?,
        },
        _ => OperatorSpec::BoucWen {
            gain: number(t, "gain", block, line, None)?,
            weight: number(t, "weight", block, line, None)?,
            beta: number(t, "beta", block, line, None)?,
            gamma: number(t, "gamma", block, line, None)?,
            exponent: number(t, "exponent", block, line, Some(1.0))?,
        },
    };
    spec.to_operator()
        .map_err(|e| err_at(line, format!("block `{block}`: {e}")))?;
    Ok(spec)
}

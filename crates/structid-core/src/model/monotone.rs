//! A shape declared for a scalar map: nondecreasing or nonincreasing in its input.
//!
//! Physics often says which way a map goes when it says little else: a tank's outflow grows
//! with its level, a spring's force with its extension, a valve's flow with its opening. A map
//! fitted without that knowledge is free to bend back where the data are thin, and free to
//! extrapolate the wrong way where they end. Declaring the direction removes both failures;
//! the joint fit honours it by construction (`structid_joint::MonotoneFeatures`).

use std::fmt;
use std::str::FromStr;

use crate::error::{Error, Result};

/// The direction of a monotone scalar map.
///
/// ```
/// use structid_core::Monotonicity;
/// let m: Monotonicity = "decreasing".parse().unwrap();
/// assert_eq!((m.sign(), m.to_string()), (-1.0, "decreasing".to_string()));
/// assert!(m.holds(&[3.0, 2.0, 2.0, -1.0]));
/// assert!(!Monotonicity::Increasing.holds(&[0.0, 1.0, 0.5]));
/// assert!("upwards".parse::<Monotonicity>().is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Monotonicity {
    /// w never decreases as z grows.
    Increasing,
    /// w never increases as z grows.
    Decreasing,
}

impl Monotonicity {
    /// +1 for increasing, −1 for decreasing.
    pub fn sign(self) -> f64 {
        match self {
            Self::Increasing => 1.0,
            Self::Decreasing => -1.0,
        }
    }

    /// The name used in model files.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Increasing => "increasing",
            Self::Decreasing => "decreasing",
        }
    }

    /// Whether `values`, taken at increasing inputs, go this way (ties allowed).
    pub fn holds(self, values: &[f64]) -> bool {
        values
            .windows(2)
            .all(|p| self.sign() * (p[1] - p[0]) >= 0.0)
    }
}

impl fmt::Display for Monotonicity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Monotonicity {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        match s {
            "increasing" => Ok(Self::Increasing),
            "decreasing" => Ok(Self::Decreasing),
            other => Err(Error::InvalidStructure(format!(
                "unknown shape `{other}`: a map's shape is \"increasing\" or \"decreasing\""
            ))),
        }
    }
}

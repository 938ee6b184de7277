//! Error type of the crate.

/// Errors reported by the checked entry points of `structid-lti`.
///
/// Every message is phrased so that it can be shown directly to a command-line user.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LtiError {
    /// Two objects have incompatible sizes.
    #[error("dimension mismatch in {what}: expected {expected}, found {found}")]
    DimensionMismatch {
        /// What was being checked (e.g. "input signal channels").
        what: String,
        /// The expected size, in words.
        expected: String,
        /// The size that was actually found.
        found: String,
    },
    /// A signal contains a NaN or an infinity.
    #[error("{what} contains the non-finite value {value} at sample {sample}, channel {channel}")]
    NonFinite {
        /// Name of the offending signal.
        what: String,
        /// Time index of the offending sample.
        sample: usize,
        /// Channel of the offending sample.
        channel: usize,
        /// The offending value.
        value: f64,
    },
    /// A matrix (or coefficient vector) contains a NaN or an infinity.
    #[error("matrix {what} contains the non-finite value {value} at row {row}, column {col}")]
    NonFiniteMatrix {
        /// Name of the offending matrix.
        what: String,
        /// Row of the offending entry.
        row: usize,
        /// Column of the offending entry.
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// A scalar parameter or an index is outside its admissible range.
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Name of the parameter.
        name: String,
        /// Why the value was rejected.
        reason: String,
    },
    /// A transfer function is malformed (ragged matrix, zero leading denominator coefficient, ...).
    #[error("invalid transfer function: {0}")]
    InvalidTransferFunction(String),
}

impl LtiError {
    pub(crate) fn dims(
        what: impl Into<String>,
        expected: impl ToString,
        found: impl ToString,
    ) -> Self {
        LtiError::DimensionMismatch {
            what: what.into(),
            expected: expected.to_string(),
            found: found.to_string(),
        }
    }

    pub(crate) fn param(name: impl Into<String>, reason: impl Into<String>) -> Self {
        LtiError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        }
    }
}

/// Checks that every entry of a nalgebra matrix is finite.
pub(crate) fn check_matrix_finite(what: &str, m: &nalgebra::DMatrix<f64>) -> Result<(), LtiError> {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            let v = m[(i, j)];
            if !v.is_finite() {
                return Err(LtiError::NonFiniteMatrix {
                    what: what.to_string(),
                    row: i,
                    col: j,
                    value: v,
                });
            }
        }
    }
    Ok(())
}

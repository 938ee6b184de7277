//! Error type of the crate.

use structid_lti::LtiError;

/// Errors reported by `structid-linear`.
///
/// Every message is phrased so that it can be shown directly to a command-line user.
/// Non-convergence of the output-error iteration is *not* an error: it is reported by
/// [`OeFit::converged`](crate::OeFit::converged).
///
/// ```
/// use structid_linear::LinearError;
/// let e = LinearError::LengthMismatch { input: 10, output: 9 };
/// assert!(e.to_string().contains("10"));
/// ```
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LinearError {
    /// A data signal contains a NaN or an infinity.
    #[error("{signal} contains the non-finite value {value} at sample {sample}, channel {channel}")]
    NonFinite {
        /// Name of the offending signal ("input", "output", "validation input", ...).
        signal: String,
        /// Time index of the offending sample.
        sample: usize,
        /// Channel of the offending sample.
        channel: usize,
        /// The offending value.
        value: f64,
    },
    /// Input and output records have different lengths.
    #[error("the input has {input} samples but the output has {output}")]
    LengthMismatch {
        /// Samples of the input record.
        input: usize,
        /// Samples of the output record.
        output: usize,
    },
    /// Two objects have incompatible sizes (channel counts, number of inputs of a model, ...).
    #[error("dimension mismatch in {what}: expected {expected}, found {found}")]
    DimensionMismatch {
        /// What was being checked.
        what: String,
        /// The expected size, in words.
        expected: String,
        /// The size that was found.
        found: String,
    },
    /// The record is too short for the requested orders.
    #[error("too few samples: {what} needs at least {needed} samples, the record has {available}")]
    TooFewSamples {
        /// What needed the samples (e.g. "ARX with 5 parameters and maximum lag 3").
        what: String,
        /// The minimum number of samples.
        needed: usize,
        /// The number of samples available.
        available: usize,
    },
    /// Model orders are inconsistent (e.g. `nb` and `nk` of different lengths).
    #[error("invalid orders: {0}")]
    InvalidOrders(String),
    /// A polynomial model is malformed (empty or zero-leading denominator, non-finite
    /// coefficients, ...).
    #[error("invalid polynomial model: {0}")]
    InvalidModel(String),
    /// A settings value or argument is outside its admissible range.
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Name of the parameter.
        name: String,
        /// Why the value was rejected.
        reason: String,
    },
    /// The least-squares regression is (numerically) singular: the inputs do not excite the
    /// model enough, or the orders are too high for noise-free data (common factors).
    #[error(
        "singular regression: condition number {condition:.3e} of the column-scaled regressor matrix exceeds {limit:.1e}; \
         lower the orders, use a richer input or set a ridge"
    )]
    SingularRegression {
        /// 2-norm condition estimate of the column-scaled regressor matrix (may be infinite).
        condition: f64,
        /// The admissible limit.
        limit: f64,
    },
    /// The initial model of the output-error iteration has an unstable denominator, so its
    /// simulation diverges.
    #[error(
        "the initial output-error model is unstable: its denominator has a root of modulus {spectral_radius:.6} (must be < 1)"
    )]
    UnstableInitialModel {
        /// Largest root modulus of the initial denominator `F`.
        spectral_radius: f64,
    },
    /// A Levenberg–Marquardt search cannot start: the starting point is empty or not
    /// finite, the problem rejects it, or the cost there is not finite.
    #[error("the least-squares search cannot start: {0}")]
    InvalidStart(String),
    /// The record length is not a whole number of periods.
    #[error("the record of {len} samples is not a whole number of periods of {period} samples")]
    PeriodMismatch {
        /// Record length.
        len: usize,
        /// Period length.
        period: usize,
    },
    /// An error reported by `structid-lti`.
    #[error(transparent)]
    Lti(#[from] LtiError),
}

impl LinearError {
    pub(crate) fn param(name: impl Into<String>, reason: impl Into<String>) -> Self {
        LinearError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        }
    }

    pub(crate) fn dims(
        what: impl Into<String>,
        expected: impl ToString,
        found: impl ToString,
    ) -> Self {
        LinearError::DimensionMismatch {
            what: what.into(),
            expected: expected.to_string(),
            found: found.to_string(),
        }
    }
}

/// Returns [`LinearError::NonFinite`] for the first NaN or infinity of `data`
/// (time-major with `channels` channels).
pub(crate) fn check_finite(signal: &str, data: &[f64], channels: usize) -> Result<(), LinearError> {
    match data.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(LinearError::NonFinite {
            signal: signal.to_string(),
            sample: i / channels.max(1),
            channel: i % channels.max(1),
            value: data[i],
        }),
    }
}

/// Checks a sample time (positive and finite) if given.
pub(crate) fn check_sample_time(ts: Option<f64>) -> Result<(), LinearError> {
    ts.map_or(Ok(()), |t| check_positive("sample_time", t))
}

/// Checks that the setting `name` is positive and finite.
pub(crate) fn check_positive(name: &str, v: f64) -> Result<(), LinearError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(LinearError::param(
            name,
            format!("must be positive and finite, got {v}"),
        ))
    }
}

/// Checks that the setting `name` is non-negative and finite.
pub(crate) fn check_non_negative(name: &str, v: f64) -> Result<(), LinearError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(LinearError::param(
            name,
            format!("must be non-negative and finite, got {v}"),
        ))
    }
}

/// Checks that the count `name` is at least 1.
pub(crate) fn check_at_least_one(name: &str, n: usize) -> Result<(), LinearError> {
    if n == 0 {
        Err(LinearError::param(name, "must be at least 1"))
    } else {
        Ok(())
    }
}

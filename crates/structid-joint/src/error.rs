//! The error type of `structid-joint`.

/// What can go wrong when building or fitting a joint model.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum JointError {
    /// An error of the model layer (dimensions, a cycle of maps, operator parameters, …).
    #[error(transparent)]
    Core(#[from] structid_core::Error),

    /// An error of the linear-systems layer (a realisation, a smoother).
    #[error(transparent)]
    Lti(#[from] structid_lti::LtiError),

    /// A setting or a parameter is outside its range.
    #[error("invalid {name} = {value}: {reason}")]
    InvalidParameter {
        /// Which setting or parameter.
        name: String,
        /// The value given.
        value: f64,
        /// What it must be.
        reason: String,
    },

    /// The model is not one the joint fit can take.
    #[error("invalid joint model: {0}")]
    InvalidModel(String),

    /// The starting model cannot be simulated on the data (it diverges or a map returns a
    /// non-finite value), so there is no cost to start from.
    #[error(
        "the starting model cannot be simulated on record {record} (numbered from 1): {detail}"
    )]
    NoStart {
        /// The record, numbered from 1.
        record: usize,
        /// What failed.
        detail: String,
    },
}

/// `Result` with [`JointError`].
pub type Result<T> = std::result::Result<T, JointError>;

pub(crate) fn invalid(name: &str, value: f64, reason: &str) -> JointError {
    JointError::InvalidParameter {
        name: name.into(),
        value,
        reason: reason.into(),
    }
}

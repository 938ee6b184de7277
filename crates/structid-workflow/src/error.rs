//! The error type of `structid-workflow`: the layers' errors, kept as sources, and the
//! request's own.

/// What can go wrong in a workflow.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WorkflowError {
    /// Reading or writing files, or a malformed model file.
    #[error(transparent)]
    Io(#[from] structid_io::IoError),
    /// The model layer.
    #[error(transparent)]
    Core(#[from] structid_core::Error),
    /// Discovery.
    #[error(transparent)]
    Discover(#[from] structid_discover::DiscoverError),
    /// The joint fit.
    #[error(transparent)]
    Joint(#[from] structid_joint::JointError),
    /// A request that cannot be carried out as given; the message says what to change.
    #[error("{0}")]
    Request(String),
    /// A model file that cannot be the nominal model of a discovery; the message says why
    /// (the remedy: a linear nominal model estimated from the data).
    #[error("{0}")]
    NotNominal(String),
    /// An option out of its range: the front end names it its own way (`--max-iterations`,
    /// `max_iterations`).
    #[error("invalid value {value} for {option}: {rule}")]
    InvalidOption {
        /// The option, in snake case (`max_iterations`).
        option: &'static str,
        /// The value given.
        value: String,
        /// What it must be.
        rule: String,
    },
}

/// `Result` with [`WorkflowError`].
pub type Result<T> = std::result::Result<T, WorkflowError>;

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
    /// A figure that could not be drawn.
    #[error("cannot draw a figure")]
    Plot(#[from] structid_plot::PlotError),
    /// Estimating or analysing a linear block on its data or orders (NaN, too few samples, a
    /// singular regression, an unstable start), kept apart from the model layer's errors.
    #[error("linear estimation")]
    Linear(#[source] structid_linear::LinearError),
    /// A request that cannot be carried out as given; the message says what to change.
    #[error("{0}")]
    Request(String),
    /// A failure while carrying out a request; the message says what failed.
    #[error("{0}")]
    Failed(String),
    /// Another error, with what was being done when it happened.
    #[error("{context}: {source}")]
    InContext {
        /// What was being done (`validation`, `experiment `a`, model …`).
        context: String,
        /// The error.
        source: Box<WorkflowError>,
    },
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
    /// Options that do not go together: the front end names them its own way.
    #[error("{}: {rule}", and_list(options))]
    OptionConflict {
        /// The options, in snake case.
        options: Vec<&'static str>,
        /// Why they conflict.
        rule: String,
    },
}

impl WorkflowError {
    /// The error with what was being done when it happened.
    ///
    /// ```
    /// use structid_workflow::WorkflowError;
    /// let e = WorkflowError::Failed("no solution".into()).context("validation");
    /// assert_eq!(e.to_string(), "validation: no solution");
    /// ```
    pub fn context(self, context: impl Into<String>) -> Self {
        Self::InContext {
            context: context.into(),
            source: Box::new(self),
        }
    }
}

/// `Result` with [`WorkflowError`].
pub type Result<T> = std::result::Result<T, WorkflowError>;

impl From<structid_linear::LinearError> for WorkflowError {
    /// Through the model layer's error, which carries the linear layer's as it is.
    fn from(e: structid_linear::LinearError) -> Self {
        Self::Core(e.into())
    }
}

/// `a`, `a and b`, `a, b and c`.
///
/// ```
/// assert_eq!(structid_workflow::error::and_list(&["a", "b", "c"]), "a, b and c");
/// assert_eq!(structid_workflow::error::and_list(&["a"]), "a");
/// ```
pub fn and_list<S: AsRef<str>>(items: &[S]) -> String {
    match items {
        [] => String::new(),
        [one] => one.as_ref().to_string(),
        [init @ .., last] => format!(
            "{} and {}",
            init.iter()
                .map(AsRef::as_ref)
                .collect::<Vec<_>>()
                .join(", "),
            last.as_ref()
        ),
    }
}

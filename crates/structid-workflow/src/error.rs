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
    /// Options that do not go together where another option does what was meant: the front
    /// end names all of them its own way.
    #[error("{}: {rule}; give {instead} instead", and_list(options))]
    UseInstead {
        /// The options given, in snake case.
        options: Vec<&'static str>,
        /// Why they do not go together.
        rule: String,
        /// The option to give instead, in snake case.
        instead: &'static str,
    },
    /// An option the request needs but was not given: the front end names it its own way.
    #[error("no {option} given: {rule}")]
    MissingOption {
        /// The option, in snake case (`estimate`).
        option: &'static str,
        /// Why it is needed, and what else would do.
        rule: String,
    },
    /// An input file or directory that does not fit the request: the front end names the
    /// input its own way (`--model`, `model`).
    #[error("{input} `{}` {why}", path.display())]
    InvalidInput {
        /// The input, in snake case (`model`, `estimate`).
        input: &'static str,
        /// The file or directory given.
        path: std::path::PathBuf,
        /// What is wrong with it, as a predicate (`is not the model of the estimate: …`).
        why: String,
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The library's messages name options as Python names keyword arguments, never as
    /// command-line flags, and keep the data they carry.
    #[test]
    fn option_errors_name_no_flags_and_carry_their_data() {
        let cases = [
            (
                WorkflowError::InvalidOption {
                    option: "validation_fraction",
                    value: "1.5".into(),
                    rule: "it must lie strictly between 0 and 1".into(),
                },
                vec!["validation_fraction", "1.5", "strictly between"],
            ),
            (
                WorkflowError::UseInstead {
                    options: vec!["validation_fraction", "data"],
                    rule: "one record only".into(),
                    instead: "validation_data",
                },
                vec![
                    "validation_fraction and data",
                    "one record only",
                    "validation_data",
                ],
            ),
            (
                WorkflowError::MissingOption {
                    option: "estimate",
                    rule: "block `N` has no truth".into(),
                },
                vec!["no estimate given", "block `N` has no truth"],
            ),
            (
                WorkflowError::InvalidInput {
                    input: "model",
                    path: "dir/m.toml".into(),
                    why: "is not the model of the estimate".into(),
                },
                vec!["model `dir/m.toml` is not the model of the estimate"],
            ),
        ];
        for (e, parts) in cases {
            let m = e.to_string();
            assert!(!m.contains("--"), "{m}");
            for p in parts {
                assert!(m.contains(p), "`{p}` missing in: {m}");
            }
        }
    }
}

//! Errors of the command-line tool: a message, its causes and an exit code.

use std::fmt;

use structid_io::{ErrorChain, IoError};

/// Exit code for invalid usage or input.
pub const EXIT_INPUT: u8 = 2;
/// Exit code for failures while running.
pub const EXIT_RUNTIME: u8 = 1;

/// An error to print as `error: <message>` (with its causes) before exiting.
#[derive(Debug)]
pub struct CliError {
    code: u8,
    context: Option<String>,
    error: Box<dyn std::error::Error + Send + Sync + 'static>,
}

#[derive(Debug)]
struct Message(String);

impl fmt::Display for Message {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Message {}

impl CliError {
    /// An input/usage error (exit code 2) with a plain message.
    pub fn input(message: impl Into<String>) -> Self {
        Self {
            code: EXIT_INPUT,
            context: None,
            error: Box::new(Message(message.into())),
        }
    }

    /// A runtime error (exit code 1) with a plain message.
    pub fn runtime(message: impl Into<String>) -> Self {
        Self {
            code: EXIT_RUNTIME,
            context: None,
            error: Box::new(Message(message.into())),
        }
    }

    /// Prefixes the message with `context: `.
    pub fn context(mut self, context: impl Into<String>) -> Self {
        let c = context.into();
        self.context = Some(match self.context.take() {
            Some(old) => format!("{c}: {old}"),
            None => c,
        });
        self
    }

    /// The process exit code.
    pub fn code(&self) -> u8 {
        self.code
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(c) = &self.context {
            write!(f, "{c}: ")?;
        }
        write!(f, "{}", ErrorChain(self.error.as_ref()))
    }
}

impl From<IoError> for CliError {
    fn from(e: IoError) -> Self {
        Self {
            code: if e.is_input_error() {
                EXIT_INPUT
            } else {
                EXIT_RUNTIME
            },
            context: None,
            error: Box::new(e),
        }
    }
}

impl From<structid_core::Error> for CliError {
    fn from(e: structid_core::Error) -> Self {
        Self {
            code: if structid_io::core_is_input_error(&e) {
                EXIT_INPUT
            } else {
                EXIT_RUNTIME
            },
            context: None,
            error: Box::new(e),
        }
    }
}

impl From<structid_linear::LinearError> for CliError {
    /// Estimating a linear block fails on its data or orders (NaN, too few samples, a singular
    /// regression, an unstable start): input errors.
    fn from(e: structid_linear::LinearError) -> Self {
        Self {
            code: EXIT_INPUT,
            context: Some("linear estimation".into()),
            error: Box::new(e),
        }
    }
}

impl From<structid_plot::PlotError> for CliError {
    fn from(e: structid_plot::PlotError) -> Self {
        Self {
            code: EXIT_RUNTIME,
            context: Some("cannot draw a figure".into()),
            error: Box::new(e),
        }
    }
}

/// Checks a command-line number that must be finite and positive.
pub fn positive(flag: &str, v: f64) -> Result<f64, CliError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(CliError::input(format!(
            "invalid value {v} for {flag}: it must be a finite number greater than zero"
        )))
    }
}

/// Checks a command-line number that must be finite and non-negative.
pub fn non_negative(flag: &str, v: f64) -> Result<f64, CliError> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(CliError::input(format!(
            "invalid value {v} for {flag}: it must be a finite number, zero or greater"
        )))
    }
}

//! Errors of the command-line tool: a message, its causes and an exit code.

use std::fmt;

use structid_io::{ErrorChain, IoError};
use structid_workflow::Remedy;

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
    /// The command that does what the failed one could not (the library's errors name no
    /// commands; the tool words them here).
    hint: Option<&'static str>,
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
            hint: None,
            error: Box::new(Message(message.into())),
        }
    }

    /// A runtime error (exit code 1) with a plain message.
    pub fn runtime(message: impl Into<String>) -> Self {
        Self {
            code: EXIT_RUNTIME,
            context: None,
            hint: None,
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
        write!(f, "{}", ErrorChain(self.error.as_ref()))?;
        match self.hint {
            Some(h) => write!(f, "\nhint: {h}"),
            None => Ok(()),
        }
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
            hint: match &e {
                IoError::Core(c) => hint(c),
                _ => None,
            },
            error: Box::new(e),
        }
    }
}

impl From<structid_workflow::WorkflowError> for CliError {
    fn from(e: structid_workflow::WorkflowError) -> Self {
        use structid_workflow::WorkflowError as W;
        match e {
            W::Io(e) => e.into(),
            W::Core(e) => e.into(),
            W::Discover(e) => e.into(),
            W::Plot(e) => e.into(),
            W::Linear(e) => e.into(),
            W::Request(m) => Self::input(m),
            W::Failed(m) => Self::runtime(m),
            W::InContext { context, source } => Self::from(*source).context(context),
            e @ W::NotNominal(_) => Self {
                code: EXIT_INPUT,
                context: None,
                hint: hint(&e),
                error: Box::new(e),
            },
            W::InvalidOption {
                option,
                value,
                rule,
            } => Self::input(format!(
                "invalid value {value} for {}: {rule}",
                flag(option)
            )),
            W::OptionConflict { options, rule } => {
                Self::input(format!("{}: {rule}", flags(&options)))
            }
            W::UseInstead {
                options,
                rule,
                instead,
            } => Self::input(format!(
                "{}: {rule}; give {} instead",
                flags(&options),
                flag(instead)
            )),
            W::MissingOption { option, rule } => {
                Self::input(format!("no {} given: {rule}", flag(option)))
            }
            W::InvalidInput { input, path, why } => {
                Self::input(format!("{} `{}` {why}", flag(input), path.display()))
            }
            other => Self {
                code: EXIT_RUNTIME,
                context: None,
                hint: None,
                error: Box::new(other),
            },
        }
    }
}

/// The flag of a library option named in snake case: `validation_fraction` is
/// `--validation-fraction`.
fn flag(option: &str) -> String {
    format!("--{}", option.replace('_', "-"))
}

/// The flags of library options, as a list (`--data and --validation-fraction`).
fn flags(options: &[&str]) -> String {
    let flags: Vec<String> = options.iter().map(|o| flag(o)).collect();
    structid_workflow::error::and_list(&flags)
}

/// What `structid refine --joint` does that identification by the dispersion cannot.
pub const JOINT_FIT_HINT: &str =
    "`structid refine --joint` fits maps in series and latent blocks by simulation error";

/// How the tool words a library's remedy.
fn hint_text(r: Remedy) -> Option<&'static str> {
    match r {
        Remedy::JointFit => Some(JOINT_FIT_HINT),
        Remedy::LinearNominal => Some(
            "estimate a nominal model from the data with `structid linear` (`--integrators N` \
             for a plant that integrates)",
        ),
        _ => None,
    }
}

/// The command to try after a library error, when the error alone says which one.
fn hint(e: &(dyn std::error::Error + 'static)) -> Option<&'static str> {
    structid_workflow::remedy(e).and_then(hint_text)
}

impl From<structid_core::Error> for CliError {
    fn from(e: structid_core::Error) -> Self {
        Self {
            hint: hint(&e),
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

impl From<structid_discover::DiscoverError> for CliError {
    /// A nominal model that cannot be a starting point is an input error, with the command
    /// that estimates one.
    fn from(e: structid_discover::DiscoverError) -> Self {
        use structid_discover::DiscoverError as D;
        match e {
            D::Core(e) => e.into(),
            e => Self {
                code: if matches!(e, D::PoorNominal { .. }) {
                    EXIT_INPUT
                } else {
                    EXIT_RUNTIME
                },
                context: None,
                hint: hint(&e),
                error: Box::new(e),
            },
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
            hint: None,
            error: Box::new(e),
        }
    }
}

impl From<structid_plot::PlotError> for CliError {
    fn from(e: structid_plot::PlotError) -> Self {
        Self {
            code: EXIT_RUNTIME,
            context: Some("cannot draw a figure".into()),
            hint: None,
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

/// Checks a command-line β (see [`structid_workflow::options::beta`]), naming it `flag`.
pub fn beta(flag: &str, v: f64) -> Result<f64, CliError> {
    structid_workflow::options::beta(v).map_err(|e| match e {
        structid_workflow::WorkflowError::InvalidOption { value, rule, .. } => {
            CliError::input(format!("invalid value {value} for {flag}: {rule}"))
        }
        e => e.into(),
    })
}

/// Checks a noise standard deviation: finite, zero or greater, and with a finite variance
/// (below about 1.3e154: the noise energy and the reports square it).
pub fn noise_std(flag: &str, v: f64) -> Result<f64, CliError> {
    let v = non_negative(flag, v)?;
    if !(v * v).is_finite() {
        return Err(CliError::input(format!(
            "invalid value {v:e} for {flag}: its square, the noise variance, overflows; give a \
             standard deviation below 1e150 (in the units of the data)"
        )));
    }
    Ok(v)
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

#[cfg(test)]
mod tests {
    use super::*;
    use structid_workflow::WorkflowError as W;

    /// The library names options in snake case; the tool words them as its flags.
    #[test]
    fn library_options_are_worded_as_flags() {
        let cases = [
            (
                W::InvalidOption {
                    option: "validation_fraction",
                    value: "0.9".into(),
                    rule: "too few samples".into(),
                },
                "invalid value 0.9 for --validation-fraction: too few samples",
            ),
            (
                W::OptionConflict {
                    options: vec!["beta", "sigma_auto"],
                    rule: "pick one".into(),
                },
                "--beta and --sigma-auto: pick one",
            ),
            (
                W::UseInstead {
                    options: vec!["validation_fraction", "data"],
                    rule: "one record only".into(),
                    instead: "validation_data",
                },
                "--validation-fraction and --data: one record only; give --validation-data instead",
            ),
            (
                W::MissingOption {
                    option: "estimate",
                    rule: "block `N` has no truth".into(),
                },
                "no --estimate given: block `N` has no truth",
            ),
            (
                W::InvalidInput {
                    input: "model",
                    path: "m.toml".into(),
                    why: "is not the model of the estimate".into(),
                },
                "--model `m.toml` is not the model of the estimate",
            ),
        ];
        for (e, expected) in cases {
            let c = CliError::from(e);
            assert_eq!(c.code(), EXIT_INPUT);
            assert_eq!(c.to_string(), expected);
        }
    }
}

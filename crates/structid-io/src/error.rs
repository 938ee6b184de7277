//! The error type of `structid-io`.

use std::fmt;
use std::path::{Path, PathBuf};

/// Everything that can go wrong while reading model or data files and writing results.
///
/// Messages are written for a command-line user: they name the file, the line (and column
/// where it helps) and what to change. Underlying system errors are exposed through
/// [`std::error::Error::source`] rather than repeated in the message.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoError {
    /// A model file is malformed (TOML syntax or content).
    #[error("{}", file_message("model file", path.as_deref(), *line, *column, message))]
    Model {
        /// The model file, when it was read from disk.
        path: Option<PathBuf>,
        /// One-based line of the offending text, when known.
        line: Option<usize>,
        /// One-based column of the offending text, when known.
        column: Option<usize>,
        /// What is wrong.
        message: String,
    },

    /// A sweep configuration file (`structid compare --config`) is malformed.
    #[error("{}", file_message("sweep config", path.as_deref(), *line, *column, message))]
    Sweep {
        /// The configuration file, when it was read from disk.
        path: Option<PathBuf>,
        /// One-based line of the offending text, when known.
        line: Option<usize>,
        /// One-based column of the offending text, when known.
        column: Option<usize>,
        /// What is wrong.
        message: String,
    },

    /// A data (CSV) file is malformed.
    #[error("{}", data_message(path.as_deref(), *line, column.as_deref(), message))]
    Data {
        /// The data file, when it was read from disk.
        path: Option<PathBuf>,
        /// One-based line in the file, when known.
        line: Option<u64>,
        /// Name of the offending column, when known.
        column: Option<String>,
        /// What is wrong.
        message: String,
    },

    /// A data file has more rows than the reader accepts ([`crate::data_file::MAX_ROWS`], or
    /// the limit given to [`crate::DataTable::read_with_limit`]); refused before parsing.
    #[error(
        "data file `{}` has more than {limit} data rows, more than structid reads at once \
         (reading and processing a record costs memory in proportion to its length); use a \
         shorter record, e.g. its first {limit} rows or a decimated copy",
        path.display()
    )]
    TooManyRows {
        /// The data file.
        path: PathBuf,
        /// The largest number of data rows accepted.
        limit: usize,
    },

    /// A column requested from a data file does not exist.
    #[error(
        "{} has no column `{}`; available columns: {}",
        source_name(path.as_deref()),
        clip(column),
        list(available)
    )]
    MissingColumn {
        /// The data file, when known.
        path: Option<PathBuf>,
        /// The column that was asked for.
        column: String,
        /// The columns the file has.
        available: Vec<String>,
    },

    /// A benchmark data file is not where it was expected.
    #[error(
        "the {benchmark} benchmark file was not found at `{}`; {hint}",
        path.display()
    )]
    BenchmarkMissing {
        /// The benchmark (`Silverbox`, `cascaded tanks`).
        benchmark: &'static str,
        /// Where the file was expected.
        path: PathBuf,
        /// Which file is needed and where to get it.
        hint: String,
    },

    /// A benchmark data file does not have the layout of the official file (header, number
    /// of samples, sample time).
    #[error("{}", benchmark_message(benchmark, path, *line, message))]
    Benchmark {
        /// The benchmark (`Silverbox`, `cascaded tanks`).
        benchmark: &'static str,
        /// The file.
        path: PathBuf,
        /// One-based line of the offending row, when known.
        line: Option<u64>,
        /// What is wrong.
        message: String,
    },

    /// A MAT-file, `.npy` or `.npz` data file cannot be read, or lacks a variable asked for.
    #[error("data file `{}`: {source}", path.display())]
    ArrayFile {
        /// The data file.
        path: PathBuf,
        /// What is wrong.
        #[source]
        source: crate::array_file::ArrayFileError,
    },

    /// A file could not be read.
    #[error("cannot read `{}`", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The system error.
        #[source]
        source: std::io::Error,
    },

    /// A file could not be written (or its directory created).
    #[error("cannot write `{}`", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The system error.
        #[source]
        source: std::io::Error,
    },

    /// An output path designates one of the input files.
    #[error(
        "refusing to write `{}`: it is the input file `{}`; choose a different output path",
        path.display(),
        input.display()
    )]
    WouldOverwriteInput {
        /// The output path that was requested.
        path: PathBuf,
        /// The input file it would overwrite.
        input: PathBuf,
    },

    /// An output location cannot be used: a file where a directory is expected (or the
    /// reverse), or a place where files cannot be created. Found before any work is done.
    #[error("cannot write the output `{}`: {message}", path.display())]
    Output {
        /// The output path as given.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },

    /// An argument given by the caller is invalid (σ ≤ 0, mismatched lengths, …).
    #[error("{0}")]
    InvalidArgument(String),

    /// An error from `structid-core` (model structure, identification, …).
    #[error(transparent)]
    Core(#[from] structid_core::Error),

    /// JSON serialisation failed.
    #[error("cannot serialise JSON")]
    Json(#[from] serde_json::Error),

    /// A stored estimate (JSON) cannot be read: malformed JSON, or numbers that do not fit
    /// together.
    #[error("cannot read the estimate `{}`{}: {message}", path.display(), line.map(|l| format!(" (line {l})")).unwrap_or_default())]
    Estimate {
        /// The estimate file.
        path: PathBuf,
        /// The line of a JSON syntax error, when known.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
}

impl IoError {
    /// A model-file error without a location (a location is added by the parser when known).
    pub fn model(message: impl Into<String>) -> Self {
        IoError::Model {
            path: None,
            line: None,
            column: None,
            message: message.into(),
        }
    }

    /// Whether the error is caused by the user's input (files, arguments, model structure) as
    /// opposed to a failure while running (writing files, numerical breakdown, memory).
    ///
    /// The command-line tool maps input errors to exit code 2 and the rest to exit code 1.
    pub fn is_input_error(&self) -> bool {
        match self {
            IoError::Model { .. }
            | IoError::Estimate { .. }
            | IoError::Sweep { .. }
            | IoError::Data { .. }
            | IoError::TooManyRows { .. }
            | IoError::MissingColumn { .. }
            | IoError::BenchmarkMissing { .. }
            | IoError::Benchmark { .. }
            | IoError::Read { .. }
            | IoError::ArrayFile { .. }
            | IoError::WouldOverwriteInput { .. }
            | IoError::Output { .. }
            | IoError::InvalidArgument(_) => true,
            IoError::Write { .. } | IoError::Json(_) => false,
            IoError::Core(e) => core_is_input_error(e),
        }
    }

    pub(crate) fn with_path(mut self, p: &Path) -> Self {
        match &mut self {
            IoError::Model { path, .. }
            | IoError::Sweep { path, .. }
            | IoError::Data { path, .. }
            | IoError::MissingColumn { path, .. }
                if path.is_none() =>
            {
                *path = Some(p.to_path_buf());
            }
            _ => {}
        }
        self
    }
}

/// Whether a `structid-core` error is caused by the user's input (see [`IoError::is_input_error`]).
pub fn core_is_input_error(e: &structid_core::Error) -> bool {
    use structid_core::Error as E;
    match e {
        E::InRecord { source, .. } => core_is_input_error(source),
        E::TooLarge { .. } | E::Numerical(_) | E::Clarabel(_) | E::NotConverged { .. } => false,
        _ => true,
    }
}

fn source_name(path: Option<&Path>) -> String {
    match path {
        Some(p) => format!("data file `{}`", p.display()),
        None => "the data".to_string(),
    }
}

fn list(names: &[String]) -> String {
    if names.is_empty() {
        return "(none)".into();
    }
    /// Columns listed in full; more are counted.
    const SHOWN: usize = 20;
    let mut s = names
        .iter()
        .take(SHOWN)
        .map(|n| format!("`{}`", clip(n)))
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > SHOWN {
        s.push_str(&format!(" and {} more", names.len() - SHOWN));
    }
    s
}

/// `message` about the file of kind `what` (e.g. "model file") at `path`, with the line and
/// column where known.
fn file_message(
    what: &str,
    path: Option<&Path>,
    line: Option<usize>,
    column: Option<usize>,
    message: &str,
) -> String {
    let mut s = match path {
        Some(p) => format!("{what} `{}`: {message}", p.display()),
        None => format!("{what}: {message}"),
    };
    match (line, column) {
        (Some(l), Some(c)) => s.push_str(&format!(" (line {l}, column {c})")),
        (Some(l), None) => s.push_str(&format!(" (line {l})")),
        _ => {}
    }
    s
}

fn data_message(
    path: Option<&Path>,
    line: Option<u64>,
    column: Option<&str>,
    message: &str,
) -> String {
    let mut s = match path {
        Some(p) => format!("data file `{}`", p.display()),
        None => "data".to_string(),
    };
    if let Some(l) = line {
        s.push_str(&format!(", line {l}"));
    }
    if let Some(c) = column {
        s.push_str(&format!(", column `{}`", clip(c)));
    }
    s.push_str(": ");
    s.push_str(message);
    s
}

fn benchmark_message(benchmark: &str, path: &Path, line: Option<u64>, message: &str) -> String {
    match line {
        Some(l) => format!(
            "{benchmark} benchmark file `{}`, line {l}: {message}",
            path.display()
        ),
        None => format!("{benchmark} benchmark file `{}`: {message}", path.display()),
    }
}

/// Formats an error and its chain of causes on one line each: `message`, then
/// `  caused by: cause` lines. Used by the command-line tool.
pub struct ErrorChain<'a>(pub &'a (dyn std::error::Error + 'static));

impl fmt::Display for ErrorChain<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)?;
        let mut cur = self.0.source();
        let mut last = self.0.to_string();
        while let Some(e) = cur {
            let s = e.to_string();
            // `#[error(transparent)]` wrappers repeat their source's message; skip repeats.
            if s != last && !last.ends_with(&s) {
                write!(f, "\n  caused by: {s}")?;
            }
            last = s;
            cur = e.source();
        }
        Ok(())
    }
}

pub use crate::echo::{ECHO_CHARS, clip};

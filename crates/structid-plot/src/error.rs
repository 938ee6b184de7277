//! The error of every rendering function.

/// Errors produced while rendering or writing a figure.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlotError {
    /// There is nothing to draw (no series, an empty series, no finite point, ...).
    #[error("empty data: {0}")]
    EmptyData(String),
    /// Two slices that must have the same length do not.
    #[error("length mismatch for {what}: {x} vs {y}")]
    LengthMismatch {
        /// Which slices were compared.
        what: String,
        /// Length of the reference slice (e.g. `x`, or `xs.len() * ys.len()`).
        x: usize,
        /// Length of the slice compared with it.
        y: usize,
    },
    /// Input that is not empty and has consistent lengths but still cannot be
    /// drawn (non-finite grid coordinates or value range, panel too small, ...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// The plotting backend failed.
    #[error("plotting backend error: {0}")]
    Backend(String),
    /// Writing the output file failed.
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
}

pub(crate) fn backend_err<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError::Backend(e.to_string())
}

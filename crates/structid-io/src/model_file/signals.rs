//! The `[signals]` section: the data columns that carry u, y and, optionally, z.

use serde::Deserialize;
use toml::Spanned;

use super::source::{Source, err_at};
use crate::error::IoError;

/// The names of the data columns that carry each signal.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SignalNames {
    /// Columns of the known inputs u, in order (n_u of them).
    pub u: Vec<String>,
    /// Columns of the measured outputs y, in order (n_y of them).
    pub y: Vec<String>,
    /// Columns of measured z, when z is measured (n_z of them); otherwise z is computed from u
    /// and y.
    pub z: Option<Vec<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSignals {
    pub(super) u: Option<Spanned<Vec<String>>>,
    pub(super) y: Option<Spanned<Vec<String>>>,
    pub(super) z: Option<Spanned<Vec<String>>>,
}

pub(super) fn check_names(
    list: &Spanned<Vec<String>>,
    key: &str,
    src: &Source<'_>,
) -> Result<Vec<String>, IoError> {
    let line = src.line(list.span().start);
    let names = list.get_ref().clone();
    for (i, n) in names.iter().enumerate() {
        if n.trim().is_empty() {
            return Err(err_at(
                line,
                format!("[signals].{key} contains an empty column name"),
            ));
        }
        if names[..i].contains(n) {
            return Err(err_at(
                line,
                format!("[signals].{key} names the column `{n}` twice"),
            ));
        }
    }
    Ok(names)
}

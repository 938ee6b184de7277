//! Line numbers in the model file's text and the errors that name them (shared with the sweep
//! file).

use std::fmt::Write as _;

use crate::error::IoError;

pub(crate) struct Source<'a> {
    text: &'a str,
    line_starts: Vec<usize>,
}

impl<'a> Source<'a> {
    pub(crate) fn new(text: &'a str) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        Self { text, line_starts }
    }

    /// One-based (line, column) of a byte offset; the column counts characters.
    pub(crate) fn line_col(&self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.text.len());
        let line = self.line_starts.partition_point(|&s| s <= offset).max(1);
        let start = self.line_starts[line - 1];
        let col = self
            .text
            .get(start..offset)
            .map_or(offset - start, |s| s.chars().count())
            + 1;
        (line, col)
    }

    pub(crate) fn line(&self, offset: usize) -> usize {
        self.line_col(offset).0
    }

    fn line_text(&self, line: usize) -> &str {
        let start = self
            .line_starts
            .get(line - 1)
            .copied()
            .unwrap_or(self.text.len());
        let end = self
            .line_starts
            .get(line)
            .copied()
            .unwrap_or(self.text.len());
        self.text
            .get(start..end)
            .unwrap_or("")
            .trim_end_matches(['\n', '\r'])
    }
}

pub(crate) fn err_at(line: usize, message: impl Into<String>) -> IoError {
    IoError::Model {
        path: None,
        line: Some(line),
        column: None,
        message: message.into(),
    }
}

/// Refuses a second entry named `name` (at `line`) among `what` (e.g. "[discover] states"):
/// `earlier` is the index of the entry already so named, if any, and `lines` holds the lines
/// of the entries read so far.
pub(super) fn check_unique_name(
    what: &str,
    name: &str,
    line: usize,
    earlier: Option<usize>,
    lines: &[usize],
) -> Result<(), IoError> {
    match earlier {
        Some(j) => Err(err_at(
            line,
            format!(
                "two {what} are named `{name}` (lines {} and {line}); names must be unique",
                lines[j]
            ),
        )),
        None => Ok(()),
    }
}

pub(super) fn plural(n: usize, word: &str) -> String {
    if n == 1 {
        format!("{n} {word}")
    } else {
        format!("{n} {word}s")
    }
}

pub(super) fn entries(n: usize) -> String {
    if n == 1 {
        "1 entry".into()
    } else {
        format!("{n} entries")
    }
}

pub(crate) fn toml_error(e: &toml::de::Error, src: &Source<'_>) -> IoError {
    let message = e.message().trim().to_string();
    match e.span() {
        Some(span) => {
            let (line, column) = src.line_col(span.start);
            let text = src.line_text(line).trim();
            // Errors about a key or value (reported by the deserialiser) point at the key itself;
            // syntax errors at the start of a line usually come from the line before.
            let about_key = [
                "unknown field",
                "missing field",
                "invalid type",
                "invalid value",
            ]
            .iter()
            .any(|p| message.starts_with(p));
            let mut message = format!("invalid TOML: {message}");
            if column > 1 || line == 1 || about_key {
                if !text.is_empty() {
                    let _ = write!(message, " in `{text}`");
                }
            } else if let Some(prev) = (1..line)
                .rev()
                .map(|l| src.line_text(l).trim())
                .find(|t| !t.is_empty())
            {
                // The parser noticed the problem at the start of a line: the cause is usually at
                // the end of the previous one (an unclosed bracket or string).
                let _ = write!(message, " after `{prev}`");
            }
            IoError::Model {
                path: None,
                line: Some(line),
                column: Some(column),
                message,
            }
        }
        None => IoError::model(format!("invalid TOML: {message}")),
    }
}

pub(crate) fn value_kind(v: &toml::Value) -> &'static str {
    match v {
        toml::Value::String(_) => "a string",
        toml::Value::Integer(_) => "an integer",
        toml::Value::Float(_) => "a float",
        toml::Value::Boolean(_) => "a boolean",
        toml::Value::Datetime(_) => "a date",
        toml::Value::Array(_) => "an array",
        toml::Value::Table(_) => "a table",
    }
}

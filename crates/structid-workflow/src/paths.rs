//! Paths as the reports name them and as the output files are named: absolute forms for
//! reports that must not depend on the working directory, lists of data files for messages,
//! file-name-safe block names, and the inputs a command must never overwrite.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use structid_io::{ModelFile, OutputGuard, TruthSpec};

use crate::{Result, WorkflowError};

/// A file-name-safe form of a block name: letters, digits, `_`, `-` and `.` are kept, anything
/// else becomes `_`; names that collide get a numeric suffix.
///
/// ```
/// let s = structid_workflow::paths::file_stems(["f", "a/b", "a b"]);
/// assert_eq!(s, ["f", "a_b", "a_b_2"]);
/// ```
pub fn file_stems<'a>(names: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let mut seen = HashSet::new();
    let mut out = Vec::new();
    for name in names {
        let mut s: String = name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        if s.starts_with('.') {
            s.insert(0, '_');
        }
        let mut candidate = s.clone();
        let mut i = 2;
        while !seen.insert(candidate.to_lowercase()) {
            candidate = format!("{s}_{i}");
            i += 1;
        }
        out.push(candidate);
    }
    out
}

/// The files of an estimate's blocks: `map_<stem>.csv` and `map_<stem>.svg` per block of `mf`.
pub fn map_files(mf: &ModelFile) -> Vec<String> {
    file_stems(mf.blocks.iter().map(|b| b.name.as_str()))
        .iter()
        .flat_map(|s| [format!("map_{s}.csv"), format!("map_{s}.svg")])
        .collect()
}

/// Protects the model file, the other input files `others` and the model's truth tables.
pub fn protect_inputs(
    guard: &mut OutputGuard,
    model: &ModelFile,
    model_path: &Path,
    others: &[&Path],
) {
    guard.protect(model_path);
    for p in others {
        guard.protect(p);
    }
    let base = model_path
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default();
    for b in &model.blocks {
        if let Some(TruthSpec::Table { file, .. }) = &b.truth {
            guard.protect(&base.join(file));
        }
    }
}

/// The data files for messages: `a.csv`, or `a.csv, b.csv`.
pub fn files_label(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The absolute paths of several data files for a report, or none for one file (which
/// `data_file_absolute` names).
pub fn absolute_files(paths: &[PathBuf]) -> Vec<String> {
    if paths.len() > 1 {
        paths
            .iter()
            .map(|p| absolute(p).display().to_string())
            .collect()
    } else {
        Vec::new()
    }
}

/// An absolute, canonical form of an existing path (absolute but not canonical when it cannot
/// be resolved), for reports that must not depend on the working directory.
pub fn absolute(p: &Path) -> PathBuf {
    std::fs::canonicalize(p)
        .or_else(|_| std::path::absolute(p))
        .unwrap_or_else(|_| p.to_path_buf())
}

/// The names of the files among `paths`, for a report's `files` list.
pub fn file_names(paths: &[PathBuf]) -> Vec<String> {
    paths
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect()
}

/// The name of an initial-state choice as the command line and the reports spell it.
pub fn initial_state_name(s: structid_core::InitialState) -> &'static str {
    match s {
        structid_core::InitialState::Zero => "zero",
        structid_core::InitialState::Estimate => "estimate",
    }
}

/// A JSON document as the reports are written: pretty, with a final newline.
pub fn json_text(doc: &serde_json::Value) -> crate::Result<String> {
    let mut text = serde_json::to_string_pretty(doc)
        .map_err(|e| crate::WorkflowError::Failed(format!("cannot serialise the report: {e}")))?;
    text.push('\n');
    Ok(text)
}

/// Refuses a file of a result set whose run did not finish: its directory's completion marker
/// (see [`structid_io::output`]) does not list it. Files in directories without a marker
/// (written by hand, or by an older structid) are taken as they are.
pub fn check_complete(path: &Path) -> Result<()> {
    if path.is_file() && !structid_io::output::is_complete(path) {
        let dir = path.parent().unwrap_or(Path::new("."));
        return Err(WorkflowError::Request(format!(
            "`{}` belongs to an incomplete set of results: the run that wrote it did not finish \
             (it is not listed in `{}`); run that command again",
            path.display(),
            dir.join(structid_io::output::COMPLETE_MARKER).display()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_stems_are_safe_and_unique() {
        let s = file_stems(["f", "a/b", "a b", ".hidden", "F"]);
        assert_eq!(s, ["f", "a_b", "a_b_2", "_.hidden", "F_2"]);
    }
}

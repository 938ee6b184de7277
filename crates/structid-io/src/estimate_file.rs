//! The estimate file: an [`Estimate`] as one self-contained JSON document.
//!
//! `structid identify`, `refine` and `discover` write it (`estimate.json`); `validate`,
//! `simulate` and `predict` read it with no access to the estimation data and no
//! re-identification. Numbers are written so that they read back bit for bit (serde_json's
//! `float_roundtrip`), so a read estimate simulates exactly as the one that was written.

use std::path::Path;

use structid_core::Estimate;

use crate::error::IoError;

/// The estimate as pretty-printed JSON, newline-terminated.
///
/// # Errors
/// [`IoError::Json`] when serialisation fails (it does not for finite numbers).
pub fn estimate_json(estimate: &Estimate) -> Result<Vec<u8>, IoError> {
    let mut text = serde_json::to_string_pretty(estimate)?;
    text.push('\n');
    Ok(text.into_bytes())
}

/// Reads an estimate file written by [`estimate_json`].
///
/// # Errors
/// [`IoError::Read`]-style errors for a missing file, [`IoError::Estimate`] with the line for
/// malformed JSON or numbers that do not fit together (the message says which).
///
/// ```
/// let dir = std::env::temp_dir().join(format!("structid-doc-{}", std::process::id()));
/// std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("bad.json");
/// std::fs::write(&path, "{\n  \"format_version\": 1,\n  oops\n}").unwrap();
/// let err = structid_io::read_estimate(&path).unwrap_err();
/// assert!(err.to_string().contains("line 3"), "{err}");
/// ```
pub fn read_estimate(path: &Path) -> Result<Estimate, IoError> {
    let text = std::fs::read_to_string(path).map_err(|e| IoError::Estimate {
        path: path.to_path_buf(),
        line: None,
        message: e.to_string(),
    })?;
    serde_json::from_str(&text).map_err(|e| IoError::Estimate {
        path: path.to_path_buf(),
        line: (e.line() > 0).then_some(e.line()),
        message: e.to_string(),
    })
}

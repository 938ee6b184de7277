//! Finding the measured benchmark files (`/work/shared/data` beside the workspace).
//!
//! Shared by the tests of `structid-io` and, through `#[path]`, those of `structid-cli` and of
//! the root package. The directory is `$STRUCTID_DATA` when that variable is set, otherwise
//! `../shared/data` beside the workspace root (found from the including crate's manifest
//! directory). A test that needs a missing file skips with a message, except under CI (the
//! `CI` variable set), where a missing file is a failure naming the path.
#![allow(dead_code)] // each test crate uses its own subset

use std::path::PathBuf;

/// The workspace root: the nearest directory above the including crate's manifest that
/// holds `Cargo.lock` (so that every crate of the workspace, and the root package, agree).
pub fn workspace_root() -> PathBuf {
    let start = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut dir = start.clone();
    loop {
        if dir.join("Cargo.lock").is_file() {
            return dir;
        }
        if !dir.pop() {
            return start;
        }
    }
}

/// The directory holding the benchmark data.
pub fn data_dir() -> PathBuf {
    match std::env::var_os("STRUCTID_DATA") {
        Some(d) if !d.is_empty() => PathBuf::from(d),
        _ => workspace_root().join("../shared/data"),
    }
}

/// The benchmark file `rel` (e.g. `silverbox/SNLS80mV.csv`) under [`data_dir`], or `None`
/// after printing `skipping: … not found` when it is missing; panics instead when `CI` is set.
pub fn benchmark_file(rel: &str) -> Option<PathBuf> {
    let p = data_dir().join(rel);
    if p.is_file() {
        Some(p)
    } else if std::env::var_os("CI").is_some() {
        panic!(
            "benchmark file {} not found (CI is set, so this fails instead of skipping; \
             set STRUCTID_DATA to the directory holding silverbox/ and cascaded_tanks/)",
            p.display()
        );
    } else {
        eprintln!(
            "skipping: benchmark file {} not found (set STRUCTID_DATA to the data directory)",
            p.display()
        );
        None
    }
}

/// The Silverbox file `silverbox/SNLS80mV.csv`, if present.
pub fn silverbox_file() -> Option<PathBuf> {
    benchmark_file("silverbox/SNLS80mV.csv")
}

/// The cascaded-tanks file `cascaded_tanks/dataBenchmark.csv`, if present.
pub fn tanks_file() -> Option<PathBuf> {
    benchmark_file("cascaded_tanks/dataBenchmark.csv")
}

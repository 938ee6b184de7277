//! Helpers shared by the end-to-end tests: run the `structid` binary and check its exit.
#![allow(dead_code)] // each test crate uses its own subset

use std::path::{Path, PathBuf};
use std::process::Command;

pub const BIN: &str = env!("CARGO_BIN_EXE_structid");

/// What a run of the binary printed, and its exit code.
pub struct Out {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

/// Runs `structid args…` in `cwd` (the test's own when `None`).
pub fn run_in(cwd: Option<&Path>, args: &[&str]) -> Out {
    let mut cmd = Command::new(BIN);
    cmd.args(args);
    if let Some(d) = cwd {
        cmd.current_dir(d);
    }
    let out = cmd.output().expect("the binary runs");
    Out {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

pub fn run(args: &[&str]) -> Out {
    run_in(None, args)
}

/// A command that must succeed.
pub fn ok_in(cwd: Option<&Path>, args: &[&str]) -> Out {
    let o = run_in(cwd, args);
    assert_eq!(
        o.code, 0,
        "structid {args:?} failed:\n{}\n{}",
        o.stdout, o.stderr
    );
    o
}

pub fn ok(args: &[&str]) -> Out {
    ok_in(None, args)
}

/// A command that must fail with a readable input error (exit code 2, no panic); its stderr.
pub fn input_error(args: &[&str]) -> String {
    let o = run(args);
    assert_eq!(
        o.code, 2,
        "structid {args:?}: expected exit code 2\nstdout: {}\nstderr: {}",
        o.stdout, o.stderr
    );
    assert!(o.stderr.starts_with("error: "), "{}", o.stderr);
    assert!(
        !o.stderr.contains("panicked") && !o.stderr.contains("internal error"),
        "{}",
        o.stderr
    );
    assert!(!o.stderr.contains("RUST_BACKTRACE"), "{}", o.stderr);
    o.stderr
}

pub fn p(path: &Path) -> &str {
    path.to_str().expect("utf-8 temp path")
}

/// A model file shipped in `examples/models`.
pub fn example_model(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/models")
        .join(name)
}

/// Where the measured benchmark files are (`$STRUCTID_DATA` or `../shared/data`), with the
/// skip-or-fail-under-CI rule; shared with the tests of `structid-io`.
#[path = "../../../structid-io/tests/common/mod.rs"]
pub mod benchmark_data;

/// A JSON file the binary wrote.
pub fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The column `name` of a CSV file with a header row.
pub fn csv_column(path: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let c = lines
        .next()
        .unwrap()
        .split(',')
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column `{name}` in {}", path.display()));
    lines
        .map(|l| l.split(',').nth(c).unwrap().parse().unwrap())
        .collect()
}

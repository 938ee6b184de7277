//! The Python bindings (`python/`), built and tested from `cargo test`.
//!
//! Creates a virtual environment under `target/python-venv`, installs maturin, numpy and
//! pytest into it from PyPI, builds the extension once in release mode (`maturin develop
//! --release`, into `target/python`; `target` is `$CARGO_TARGET_DIR` when set) and runs `python/tests` with pytest, which compares the
//! bindings with this crate's `structid` binary on the same files. Every step that fails
//! fails the test with its output: a machine without Python 3 or without access to PyPI
//! fails here rather than skipping the bindings silently.
//!
//! The interpreter is `$STRUCTID_PYTHON` when set, otherwise the first of `python3.11` and
//! `python3` on the PATH.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The workspace root (the parent of `crates/`).
fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .expect("crates/structid-cli lies two levels below the workspace root")
        .to_path_buf()
}

/// Runs `cmd`, failing the test with its output when it cannot start or exits non-zero.
fn run(what: &str, cmd: &mut Command) -> Output {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot run {cmd:?}: {e}"));
    if !out.status.success() {
        panic!(
            "{what} failed ({}): {cmd:?}\n--- stdout ---\n{}\n--- stderr ---\n{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    out
}

/// The Python interpreter to build the environment with.
fn python() -> String {
    if let Some(p) = std::env::var_os("STRUCTID_PYTHON").filter(|p| !p.is_empty()) {
        return p.to_string_lossy().into_owned();
    }
    for candidate in ["python3.11", "python3"] {
        let works = Command::new(candidate)
            .args(["-c", "import sys; assert sys.version_info >= (3, 9)"])
            .output()
            .is_ok_and(|o| o.status.success());
        if works {
            return candidate.into();
        }
    }
    panic!(
        "no Python 3.9 or newer found (tried python3.11 and python3): the Python bindings need \
         one; install it or set STRUCTID_PYTHON to an interpreter"
    );
}

#[test]
fn python_bindings_pass_their_tests() {
    let root = workspace_root();
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .filter(|d| !d.is_empty())
        .map_or_else(|| root.join("target"), PathBuf::from);
    let venv = target.join("python-venv");
    let bin = venv.join(if cfg!(windows) { "Scripts" } else { "bin" });
    let venv_python = bin.join(if cfg!(windows) {
        "python.exe"
    } else {
        "python"
    });
    if !venv_python.is_file() {
        run(
            "creating the virtual environment",
            Command::new(python()).args(["-m", "venv"]).arg(&venv),
        );
    }
    run(
        "installing maturin, numpy and pytest",
        Command::new(&venv_python).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "maturin>=1.9,<2",
            "numpy",
            "pytest",
        ]),
    );
    // One release build of the extension, in its own target directory: the bindings are a
    // workspace of their own.
    run(
        "building the extension (maturin develop --release)",
        Command::new(bin.join("maturin"))
            .args(["develop", "--release", "--quiet"])
            .current_dir(root.join("python"))
            .env("VIRTUAL_ENV", &venv)
            .env("CARGO_TARGET_DIR", target.join("python")),
    );
    let out = run(
        "the Python tests (pytest python/tests)",
        Command::new(&venv_python)
            .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
            .arg(root.join("python/tests"))
            .current_dir(root.join("python"))
            .env("STRUCTID_CLI", env!("CARGO_BIN_EXE_structid")),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    // pytest exits 0 also when it ran every test; make sure it ran some.
    assert!(
        stdout.contains(" passed"),
        "pytest reported no passed tests:\n{stdout}"
    );
}

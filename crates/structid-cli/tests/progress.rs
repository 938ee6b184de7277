//! Progress bars: drawn on a terminal, absent when stderr is a pipe (as in these tests and in
//! scripts).

mod common;

use std::path::Path;
use std::process::Command;

use common::{BIN, example_model, ok, p};

/// The hammerstein example simulated on 600 samples of a uniform input, with noise.
fn record(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let model = dir.join("model.toml");
    std::fs::write(
        &model,
        std::fs::read_to_string(example_model("hammerstein.toml")).unwrap(),
    )
    .unwrap();
    let mut state = 7u64;
    let mut text = String::from("u\n");
    for _ in 0..600 {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        text += &format!(
            "{}\n",
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        );
    }
    let (u, data) = (dir.join("u.csv"), dir.join("data.csv"));
    std::fs::write(&u, text).unwrap();
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&data),
        "--noise-std",
        "0.01",
    ]);
    (model, data)
}

#[test]
fn long_commands_are_quiet_off_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (model, data) = record(d);
    let lin = d.join("lin.toml");
    let runs: Vec<Vec<String>> = vec![
        vec![
            "identify",
            "--model",
            p(&model),
            "--data",
            p(&data),
            "--beta",
            "auto",
            "--out",
        ]
        .into_iter()
        .map(String::from)
        .chain([p(&d.join("est")).to_string()])
        .collect(),
        [
            "linear",
            "--data",
            p(&data),
            "--structure",
            "input",
            "--out",
            p(&lin),
        ]
        .map(String::from)
        .to_vec(),
    ];
    for args in &runs {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = ok(&args);
        assert!(
            o.stderr.is_empty(),
            "{args:?} wrote to stderr: {}",
            o.stderr
        );
    }
    let o = ok(&[
        "refine",
        "--model",
        p(&lin),
        "--data",
        p(&data),
        "--out",
        p(&d.join("r")),
    ]);
    assert!(o.stderr.is_empty(), "refine wrote to stderr: {}", o.stderr);
}

/// On a terminal (a pseudo-terminal from `script`), the β search of `identify --beta auto`
/// draws its bar. Skipped where `script` (util-linux) is missing.
#[test]
fn a_terminal_gets_a_progress_bar() {
    if Command::new("script").arg("--version").output().is_err() {
        eprintln!("skipped: no `script` to give the command a terminal");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (model, data) = record(dir.path());
    let line = format!(
        "{BIN} identify --model {} --data {} --beta auto --out {}",
        p(&model),
        p(&data),
        p(&dir.path().join("est"))
    );
    let out = Command::new("script")
        .args(["-qec", &line, "/dev/null"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("β trials"), "no bar on the terminal:\n{text}");
    // The summary is printed as without a terminal.
    assert!(text.contains("selected β ="), "{text}");
}

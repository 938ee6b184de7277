//! `structid identify --beta auto` / `--sigma auto` end to end: the choice is recorded,
//! reproducible by `structid validate`, and bad combinations are readable errors.

use std::path::Path;

mod common;
use common::{p, run as run_out};

fn run(args: &[&str]) -> (i32, String, String) {
    let o = run_out(args);
    (o.code, o.stdout, o.stderr)
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn automatic_beta_and_sigma_are_recorded_and_validate_reproduces_them() {
    let dir = tempfile::tempdir().unwrap();
    let demo = dir.path().join("spray");
    let (code, _, err) = run(&["demo", "spray", "--samples", "400", "--out", p(&demo)]);
    assert_eq!(code, 0, "{err}");
    let (model, data) = (demo.join("model.toml"), demo.join("data.csv"));
    let out = dir.path().join("auto");
    let (code, stdout, err) = run(&[
        "identify",
        "-m",
        p(&model),
        "-d",
        p(&data),
        "-o",
        p(&out),
        "--beta",
        "auto",
        "--sigma",
        "auto",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("selected β ="), "{stdout}");
    let report = json(&out.join("report.json"));
    let sel = &report["selection"];
    assert_eq!(sel["criterion"], "ml");
    let beta = sel["beta"].as_f64().unwrap();
    let sigma = sel["sigma"].as_f64().unwrap();
    assert_eq!(report["settings"]["beta"].as_f64().unwrap(), beta);
    let curve = sel["curve"].as_array().unwrap();
    assert!(curve.len() > 10);
    // the choice is the best trial of its curve
    let best = curve
        .iter()
        .map(|t| t["value"].as_f64().unwrap())
        .fold(f64::INFINITY, f64::min);
    let at_choice = curve
        .iter()
        .filter(|t| t["beta"].as_f64() == Some(beta) && t["sigma"].as_f64() == Some(sigma))
        .map(|t| t["value"].as_f64().unwrap())
        .fold(f64::INFINITY, f64::min);
    assert_eq!(best, at_choice);
    // the fixed-value rerun of `validate` reproduces the estimate (it checks ŵ itself)
    let (code, stdout, err) = run(&[
        "validate",
        "-m",
        p(&model),
        "-e",
        p(&out),
        "-d",
        p(&data),
        "-o",
        p(&dir.path().join("val")),
    ]);
    assert_eq!(code, 0, "{stdout}\n{err}");

    // blocks of different widths: every block's chosen width is recorded and re-applied
    let text = std::fs::read_to_string(&model).unwrap();
    let i = text.rfind("sigma = 0.1").expect("the demo model gives σ");
    let two = dir.path().join("two_widths.toml");
    std::fs::write(
        &two,
        format!("{}sigma = 0.3{}", &text[..i], &text[i + 11..]),
    )
    .unwrap();
    let out2 = dir.path().join("auto2");
    let (code, _, err) = run(&[
        "identify",
        "-m",
        p(&two),
        "-d",
        p(&data),
        "-o",
        p(&out2),
        "--beta",
        "auto",
        "--sigma",
        "auto",
    ]);
    assert_eq!(code, 0, "{err}");
    let widths = json(&out2.join("report.json"))["reproduction"]["block_sigmas"].clone();
    let w: Vec<f64> = widths
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p[1].as_f64().unwrap())
        .collect();
    assert_eq!(w.len(), 2);
    assert!((w[1] / w[0] - 3.0).abs() < 1e-9, "{widths}");
    let (code, stdout, err) = run(&[
        "validate",
        "-m",
        p(&two),
        "-e",
        p(&out2),
        "-d",
        p(&data),
        "-o",
        p(&dir.path().join("val2")),
    ]);
    assert_eq!(code, 0, "{stdout}\n{err}");

    // total variation chooses by cross-validation by default
    let tv = dir.path().join("tv");
    let (code, stdout, err) = run(&[
        "identify",
        "-m",
        p(&model),
        "-d",
        p(&data),
        "-o",
        p(&tv),
        "--beta",
        "auto",
        "--dispersion",
        "tv",
        "--folds",
        "3",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("3-fold cross-validation"), "{stdout}");
    assert_eq!(
        json(&tv.join("report.json"))["selection"]["criterion"],
        "cv"
    );
}

#[test]
fn bad_selection_options_are_readable_errors() {
    let dir = tempfile::tempdir().unwrap();
    let demo = dir.path().join("spray");
    assert_eq!(
        run(&["demo", "spray", "--samples", "100", "--out", p(&demo)]).0,
        0
    );
    let (model, data) = (demo.join("model.toml"), demo.join("data.csv"));
    let out = dir.path().join("o");
    for (args, needle) in [
        (vec!["--beta", "often"], "expected a number or `auto`"),
        (vec!["--selection", "gcv"], "--selection needs --beta auto"),
        (
            vec!["--beta", "auto", "--selection", "validation"],
            "--validation-data",
        ),
        (
            vec!["--beta", "auto", "--selection", "cv", "--folds", "1"],
            "--folds",
        ),
        (
            vec!["--beta", "auto", "--dispersion", "tv", "--selection", "ml"],
            "quadratic",
        ),
        (
            vec!["--beta", "auto", "--sigma", "auto", "--dispersion", "tv"],
            "width",
        ),
    ] {
        let mut all = vec!["identify", "-m", p(&model), "-d", p(&data), "-o", p(&out)];
        all.extend(args.iter().copied());
        let (code, _, err) = run(&all);
        assert!(code == 2 || code == 1, "{args:?}: exit {code}: {err}");
        assert!(err.starts_with("error"), "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}

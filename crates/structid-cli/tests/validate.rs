//! End-to-end tests of `structid validate`: data from `demo spray` and `simulate`, an estimate
//! from `identify`, then validation on a fresh record.

use std::path::{Path, PathBuf};

mod common;
use common::*;

/// A reproducible uniform input on [−a, a] (a small LCG, so the test needs no RNG crate).
fn write_input(path: &Path, len: usize, amplitude: f64, seed: u64) {
    let mut state: u64 = 0x2545_f491_4f6c_dd1d ^ seed;
    let mut s = String::from("u\n");
    for _ in 0..len {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let v = ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
        s.push_str(&format!("{}\n", amplitude * v));
    }
    std::fs::write(path, s).unwrap();
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn refs(a: &[String]) -> Vec<&str> {
    a.iter().map(String::as_str).collect()
}

fn assert_svg(path: &Path) {
    let s = std::fs::read_to_string(path).unwrap();
    assert!(s.starts_with("<svg"), "{} is not an SVG", path.display());
}

/// Estimation data (noise std 0.05) and noise-free validation data from the spray model of
/// `demo spray`, simulated with its true maps on different inputs; then `identify`.
/// Returns (model, estimate dir, validation data).
fn spray_estimate(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let demo = dir.join("demo");
    ok(&["demo", "spray", "--samples", "300", "--out", p(&demo)]);
    let model = demo.join("model.toml");
    let (u_est, u_val) = (dir.join("u_est.csv"), dir.join("u_val.csv"));
    write_input(&u_est, 500, 1.0, 1);
    write_input(&u_val, 300, 0.9, 2);
    let (est, val) = (dir.join("est.csv"), dir.join("val.csv"));
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u_est),
        "--out",
        p(&est),
        "--noise-std",
        "0.05",
    ]);
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u_val),
        "--out",
        p(&val),
    ]);
    let estimate = dir.join("estimate");
    ok(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&est),
        "--out",
        p(&estimate),
        "--beta",
        "0.001",
    ]);
    // The directory of an older `identify`, without the stored estimate: validate rebuilds
    // the estimate from the identification it records, which these tests check.
    std::fs::remove_file(estimate.join("estimate.json")).unwrap();
    (model, estimate, val)
}

#[test]
fn demo_spray_identify_then_validate_on_fresh_noise_free_data() {
    let dir = tempfile::tempdir().unwrap();
    let (model, estimate, val) = spray_estimate(dir.path());
    let report = read_json(&estimate.join("report.json"));
    let rep = &report["reproduction"];
    assert!(Path::new(rep["model_file_absolute"].as_str().unwrap()).is_absolute());
    assert!(Path::new(rep["data_file_absolute"].as_str().unwrap()).is_absolute());
    assert_eq!(rep["solver"], "exact");
    assert_eq!(rep["beta"], 0.001);

    let out = dir.path().join("validation");
    let o = ok(&[
        "validate",
        "--model",
        p(&model),
        "--estimate",
        p(&estimate),
        "--data",
        p(&val),
        "--out",
        p(&out),
    ]);
    for s in [
        "300 samples",
        "ŵ matches estimate.csv",
        "output y: simulation RMS",
        "fit",
        "whiteness of ε",
        "correlation of ε with u",
        "validation.json",
    ] {
        assert!(o.stdout.contains(s), "missing `{s}` in:\n{}", o.stdout);
    }
    for f in ["simulation.svg", "residuals.svg"] {
        assert_svg(&out.join(f));
    }
    let v = read_json(&out.join("validation.json"));
    assert_eq!(v["samples"], 300);
    assert_eq!(v["inputs"]["max_lag"], 25);
    assert_eq!(v["inputs"]["initial_state"], "zero");
    assert!(v["initial_state"].is_null());
    assert!(
        v["estimate"]["w_hat_max_relative_difference"]
            .as_f64()
            .unwrap()
            <= 1e-6
    );
    let y = &v["outputs"][0];
    assert_eq!(y["name"], "y");
    // Noise-free validation data and a good estimate (noise std 0.05 for identification).
    let fit = y["fit_percent"].as_f64().unwrap();
    assert!(fit > 90.0, "fit {fit} %");
    let rms = y["rms"].as_f64().unwrap();
    assert!(rms > 0.0 && rms < 0.2, "{rms}");
    let lags: Vec<i64> = y["whiteness"]["lags"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_i64().unwrap())
        .collect();
    assert_eq!(lags, (0..=25).collect::<Vec<i64>>());
    let cross = &y["input_correlation"][0];
    assert_eq!(cross["input"], "u");
    assert_eq!(cross["lags"].as_array().unwrap().len(), 51);
    assert!(cross["passes"].is_boolean() && cross["lags_outside"].is_array());
    assert_eq!(
        v["files"],
        serde_json::json!([
            "simulation.csv",
            "simulation.svg",
            "residuals.svg",
            "validation.json"
        ])
    );
    // simulation.csv: time, y, y_sim, prediction error; y as in the data, RMS as reported.
    let text = std::fs::read_to_string(out.join("simulation.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next().unwrap(), "time,y,y_sim,y_prediction_error");
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 300);
    let sim_rms = (rows.iter().map(|r| (r[1] - r[2]).powi(2)).sum::<f64>() / 300.0).sqrt();
    assert!(
        (sim_rms - rms).abs() < 1e-12 * rms.max(1.0),
        "{sim_rms} vs {rms}"
    );

    // Estimated initial state: one value per state of the spray LFT (2).
    let out2 = dir.path().join("validation2");
    ok(&[
        "validate",
        "--model",
        p(&model),
        "--estimate",
        p(&estimate),
        "--data",
        p(&val),
        "--out",
        p(&out2),
        "--initial-state",
        "estimate",
        "--max-lag",
        "10",
    ]);
    let v2 = read_json(&out2.join("validation.json"));
    assert_eq!(v2["initial_state"].as_array().unwrap().len(), 2);
    assert_eq!(
        v2["outputs"][0]["whiteness"]["lags"]
            .as_array()
            .unwrap()
            .len(),
        11
    );
}

#[test]
fn relative_paths_at_identify_time_still_validate_from_elsewhere() {
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    std::fs::copy(example_model("hammerstein.toml"), work.join("m.toml")).unwrap();
    write_input(&work.join("u.csv"), 300, 2.0, 3);
    ok_in(
        Some(&work),
        &[
            "simulate",
            "--model",
            "m.toml",
            "--input",
            "u.csv",
            "--out",
            "d.csv",
            "--noise-std",
            "0.05",
        ],
    );
    ok_in(
        Some(&work),
        &[
            "identify", "--model", "m.toml", "--data", "d.csv", "--out", "est", "--sigma", "0.4",
        ],
    );
    let report = read_json(&work.join("est/report.json"));
    assert_eq!(report["data_file"], "d.csv");
    assert_eq!(report["reproduction"]["sigma"], 0.4);
    // As an older `identify` wrote it (no estimate.json), so that validate rebuilds the
    // estimate from the recorded paths.
    std::fs::remove_file(work.join("est/estimate.json")).unwrap();
    // From another directory, with the paths of this one.
    let o = ok_in(
        Some(dir.path()),
        &[
            "validate",
            "-m",
            "work/m.toml",
            "-e",
            "work/est",
            "-d",
            "work/d.csv",
            "-o",
            "val",
        ],
    );
    assert!(o.stdout.contains("ŵ matches estimate.csv"), "{}", o.stdout);
    assert!(dir.path().join("val/validation.json").is_file());
}

#[test]
fn validate_errors_are_readable() {
    let dir = tempfile::tempdir().unwrap();
    let (model, estimate, val) = spray_estimate(dir.path());
    let out = dir.path().join("v");
    let args = |m: &Path, e: &Path, d: &Path, o: &Path| -> Vec<String> {
        [
            "validate",
            "--model",
            p(m),
            "--estimate",
            p(e),
            "--data",
            p(d),
            "--out",
            p(o),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };

    // A model with other blocks.
    let ham = example_model("hammerstein.toml");
    let e = input_error(&refs(&args(&ham, &estimate, &val, &out)));
    assert!(
        e.contains("--model `") && e.contains("is not the model of the estimate"),
        "{e}"
    );
    assert!(e.contains("`N`") && e.contains("`f`, `g`"), "{e}");
    // A missing estimate directory, and a directory that is not an estimate.
    let e = input_error(&refs(&args(&model, &dir.path().join("nope"), &val, &out)));
    assert!(
        e.contains("--estimate `") && e.contains("does not exist"),
        "{e}"
    );
    let e = input_error(&refs(&args(&model, dir.path(), &val, &out)));
    assert!(e.contains("has no report.json"), "{e}");
    // Outputs that would overwrite inputs.
    let e = input_error(&refs(&args(&model, &estimate, &val, &val)));
    assert!(e.contains("refusing to write"), "{e}");
    let e = input_error(&refs(&args(
        &model,
        &estimate,
        &val,
        &estimate.join("estimate.csv"),
    )));
    assert!(e.contains("refusing to write"), "{e}");
    // --max-lag.
    let mut a = args(&model, &estimate, &val, &out);
    a.extend(["--max-lag".to_string(), "300".to_string()]);
    let e = input_error(&refs(&a));
    assert!(e.contains("--max-lag") && e.contains("300"), "{e}");
    // A changed estimation data file: the estimate no longer matches its report.
    let est = dir.path().join("est.csv");
    let text = std::fs::read_to_string(&est).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let yc = header.iter().position(|h| *h == "y").unwrap();
    let mut fields: Vec<String> = lines[10].split(',').map(String::from).collect();
    fields[yc] = (fields[yc].parse::<f64>().unwrap() + 1.0).to_string();
    lines[10] = fields.join(",");
    std::fs::write(&est, lines.join("\n") + "\n").unwrap();
    let e = input_error(&refs(&args(&model, &estimate, &val, &out)));
    assert!(e.contains("does not match its report.json"), "{e}");
    std::fs::write(&est, &text).unwrap();
    // A moved estimation data file.
    let moved = dir.path().join("moved.csv");
    std::fs::rename(&est, &moved).unwrap();
    let e = input_error(&refs(&args(&model, &estimate, &val, &out)));
    assert!(e.contains("does not exist any more"), "{e}");
    std::fs::rename(&moved, &est).unwrap();
    // A report of an older version, without the reproduction record.
    let report_path = estimate.join("report.json");
    let report_text = std::fs::read_to_string(&report_path).unwrap();
    let mut report: serde_json::Value = serde_json::from_str(&report_text).unwrap();
    report.as_object_mut().unwrap().remove("reproduction");
    std::fs::write(&report_path, report.to_string()).unwrap();
    let e = input_error(&refs(&args(&model, &estimate, &val, &out)));
    assert!(e.contains("older structid"), "{e}");
    std::fs::write(&report_path, &report_text).unwrap();
    // Nothing was written, and after all that the directory still validates.
    assert!(!out.exists());
    ok(&refs(&args(&model, &estimate, &val, &out)));
}

#[test]
fn validate_without_estimate_uses_the_true_maps() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A model file with a truth map, and noise-free data simulated from it.
    let model = d.join("model.toml");
    std::fs::write(
        &model,
        std::fs::read_to_string(example_model("hammerstein.toml")).unwrap(),
    )
    .unwrap();
    let (u, val) = (d.join("u.csv"), d.join("val.csv"));
    write_input(&u, 400, 1.0, 7);
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&val),
    ]);
    let out = d.join("validation");
    let o = ok(&[
        "validate",
        "--model",
        p(&model),
        "--data",
        p(&val),
        "--out",
        p(&out),
    ]);
    for s in [
        "validated the true maps",
        "400 samples",
        "no estimate given",
        "output y: simulation RMS",
    ] {
        assert!(o.stdout.contains(s), "missing `{s}` in:\n{}", o.stdout);
    }
    assert!(!o.stdout.contains("estimate.csv"), "{}", o.stdout);
    for f in ["simulation.svg", "residuals.svg"] {
        assert_svg(&out.join(f));
    }
    assert!(out.join("simulation.csv").is_file());
    let v = read_json(&out.join("validation.json"));
    assert_eq!(v["maps"], "truth");
    assert!(v["estimate"].is_null(), "{v}");
    assert!(v["inputs"]["estimate_dir"].is_null(), "{v}");
    assert_eq!(v["truth"][0]["name"], "N");
    assert_eq!(v["truth"][0]["truth"], "tanh(2*z0)");
    assert_eq!(v["samples"], 400);
    let y = &v["outputs"][0];
    let fit = y["fit_percent"].as_f64().unwrap();
    assert!(fit > 99.9999, "fit {fit} %");
    assert!(y["rms"].as_f64().unwrap() < 1e-9, "{y}");

    // --initial-state estimate works the same way.
    let out2 = d.join("validation2");
    ok(&[
        "validate",
        "--model",
        p(&model),
        "--data",
        p(&val),
        "--out",
        p(&out2),
        "--initial-state",
        "estimate",
    ]);
    let v = read_json(&out2.join("validation.json"));
    assert!(v["outputs"][0]["fit_percent"].as_f64().unwrap() > 99.9999);

    // A block without a truth and no --estimate: an input error naming the blocks.
    let text = std::fs::read_to_string(&model).unwrap();
    let no_truth = d.join("no_truth.toml");
    std::fs::write(
        &no_truth,
        text.lines()
            .filter(|l| !l.starts_with("truth"))
            .collect::<Vec<_>>()
            .join("\n"),
    )
    .unwrap();
    let out3 = d.join("validation3");
    let e = input_error(&[
        "validate",
        "--model",
        p(&no_truth),
        "--data",
        p(&val),
        "--out",
        p(&out3),
    ]);
    assert!(
        e.contains("`N`") && e.contains("truth") && e.contains("--estimate"),
        "{e}"
    );
    assert!(!out3.exists());
}

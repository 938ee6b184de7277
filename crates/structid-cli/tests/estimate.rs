//! The stored estimate from the command line: `identify` and `refine` write estimate.json;
//! `validate`, `simulate` and `predict` read it after the estimation data are gone, and agree
//! with the validation that re-runs the identification.

use std::path::Path;

mod common;
use common::*;

fn write_input(path: &Path, len: usize) {
    let mut s = String::from("u\n");
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    for _ in 0..len {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        s.push_str(&format!(
            "{}\n",
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 2.0
        ));
    }
    std::fs::write(path, s).unwrap();
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn column(path: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let i = header.iter().position(|h| *h == name).unwrap();
    lines
        .map(|l| l.split(',').nth(i).unwrap().parse().unwrap())
        .collect()
}

#[test]
fn identify_writes_an_estimate_that_validates_simulates_and_predicts_without_the_data() {
    let dir = tempfile::tempdir().unwrap();
    let model = example_model("hammerstein.toml");
    let (u, est, val, uv) = (
        dir.path().join("u.csv"),
        dir.path().join("est.csv"),
        dir.path().join("val.csv"),
        dir.path().join("uv.csv"),
    );
    write_input(&u, 600);
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&est),
        "--noise-std",
        "0.05",
        "--seed",
        "3",
    ]);
    write_input(&uv, 400);
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&uv),
        "--out",
        p(&val),
        "--noise-std",
        "0.05",
        "--seed",
        "4",
    ]);
    let out = dir.path().join("fit");
    ok(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&est),
        "--out",
        p(&out),
    ]);
    let stored = out.join("estimate.json");
    assert!(stored.is_file());

    // The validation that re-runs the identification, while the data still exist, from the
    // directory as an older `identify` wrote it (without estimate.json).
    let validate_dir = |to: &Path| {
        ok(&[
            "validate",
            "--model",
            p(&model),
            "--estimate",
            p(&out),
            "--data",
            p(&val),
            "--out",
            p(to),
        ])
    };
    let aside = dir.path().join("estimate.json.aside");
    std::fs::rename(&stored, &aside).unwrap();
    let v1 = dir.path().join("v1");
    validate_dir(&v1);
    std::fs::rename(&aside, &stored).unwrap();
    // The estimation data are deleted: the stored estimate still validates, to the same
    // numbers, given as the file or as the directory that holds it.
    std::fs::remove_file(&est).unwrap();
    let v3 = dir.path().join("v3");
    validate_dir(&v3);
    let v2 = dir.path().join("v2");
    let o = ok(&[
        "validate",
        "--estimate",
        p(&stored),
        "--data",
        p(&val),
        "--out",
        p(&v2),
    ]);
    assert!(o.stdout.contains("stored estimate"), "{}", o.stdout);
    let (a, b) = (
        read_json(&v1.join("validation.json")),
        read_json(&v2.join("validation.json")),
    );
    for key in ["rms", "prediction_rms"] {
        let (x, y) = (
            a["outputs"][0][key].as_f64().unwrap(),
            b["outputs"][0][key].as_f64().unwrap(),
        );
        assert!(
            (x - y).abs() <= 1e-12 * x.abs(),
            "{key}: rebuilt {x} vs stored {y}"
        );
    }
    let sim_rebuilt = column(&v1.join("simulation.csv"), "y_sim");
    let sim_stored = column(&v2.join("simulation.csv"), "y_sim");
    let sim_dir = column(&v3.join("simulation.csv"), "y_sim");
    for ((x, y), z) in sim_rebuilt.iter().zip(&sim_stored).zip(&sim_dir) {
        assert!((x - y).abs() <= 1e-12 * (1.0 + x.abs()));
        assert!((y - z).abs() <= 1e-12 * (1.0 + y.abs()));
    }

    // simulate --estimate on the validation input gives the same simulation.
    let s = dir.path().join("s.csv");
    ok(&[
        "simulate",
        "--estimate",
        p(&stored),
        "--input",
        p(&val),
        "--out",
        p(&s),
    ]);
    let y_sim = column(&s, "y");
    for (x, y) in sim_stored.iter().zip(&y_sim) {
        assert!((x - y).abs() <= 1e-12 * (1.0 + x.abs()));
    }

    // predict: k = 1 is validate's one-step predictor (ŷ = y − ε), k ≥ L the simulation.
    let pr = dir.path().join("p1");
    ok(&[
        "predict",
        "--estimate",
        p(&stored),
        "--data",
        p(&val),
        "--horizon",
        "1",
        "--out",
        p(&pr),
    ]);
    let yhat = column(&pr.join("prediction.csv"), "y_predicted");
    let y = column(&v2.join("simulation.csv"), "y");
    let eps = column(&v2.join("simulation.csv"), "y_prediction_error");
    for k in 0..y.len() {
        assert!((yhat[k] - (y[k] - eps[k])).abs() <= 1e-9, "k = {k}");
    }
    let pl = dir.path().join("pl");
    ok(&[
        "predict",
        "--estimate",
        p(&stored),
        "--data",
        p(&val),
        "--horizon",
        "401",
        "--out",
        p(&pl),
    ]);
    let far = column(&pl.join("prediction.csv"), "y_predicted");
    for (x, y) in far.iter().zip(&sim_stored) {
        assert!((x - y).abs() <= 1e-9 * (1.0 + x.abs()));
    }

    // An estimate on a user-defined kernel stores the kernel's name only; the tool, which
    // cannot run user code, says which kernel it lacks.
    let mut doc = read_json(&stored);
    doc["blocks"][0]["map"]["kernel"] = serde_json::json!({"kind": "user", "name": "matern"});
    let user = dir.path().join("user.json");
    std::fs::write(&user, serde_json::to_string(&doc).unwrap()).unwrap();
    let msg = input_error(&[
        "predict",
        "--estimate",
        p(&user),
        "--data",
        p(&val),
        "--out",
        p(&dir.path().join("pu")),
    ]);
    assert!(msg.contains("user-defined kernel `matern`"), "{msg}");
}

#[test]
fn stored_estimate_errors_are_readable() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{\n \"format_version\": 1,\n nope }").unwrap();
    let val = dir.path().join("v.csv");
    std::fs::write(&val, "u,y\n1,2\n3,4\n").unwrap();
    let msg = input_error(&[
        "predict",
        "--estimate",
        p(&bad),
        "--data",
        p(&val),
        "--out",
        p(&dir.path().join("o")),
    ]);
    assert!(msg.contains("line 3"), "{msg}");
    let msg = input_error(&[
        "predict",
        "--estimate",
        p(&bad),
        "--data",
        p(&val),
        "--horizon",
        "0",
        "--out",
        p(&dir.path().join("o")),
    ]);
    assert!(msg.contains("horizon"), "{msg}");
    let msg = input_error(&[
        "validate",
        "--data",
        p(&val),
        "--out",
        p(&dir.path().join("o")),
    ]);
    assert!(msg.contains("--model"), "{msg}");
}

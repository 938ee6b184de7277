//! `structid discover` on several records: `--data a.csv --data b.csv --validation-data c.csv`,
//! each record an experiment from its own initial state. The gap before is checked against
//! `structid validate` on the same files (each record from its own estimated initial state,
//! pooled), and the augmented model against `structid validate` on the validation record.

mod common;

use std::path::{Path, PathBuf};

use common::{ok, p};

/// The nominal model: G = (0.1q⁻¹ + 0.1q⁻²)/(1 − 1.5q⁻¹ + 0.7q⁻²), output error.
const NOMINAL: &str = r#"[linear]
structure = "lti"
sample_time = 0.05
den = [1.0, -1.5, 0.7]
num = [[0.0, 0.1, 0.1]]

[signals]
u = ["u"]
y = ["y"]
"#;

/// An experiment of `len` samples on the nominal G behind an actuator saturating at ±0.8
/// (slope 1.5), after a warm-up of 300 samples at input level `level` (dropped), so that it
/// starts away from rest; noise std 0.005. Written as a CSV file with columns u, y.
fn experiment(path: &Path, len: usize, level: f64, seed: u64) {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let mut gauss =
        || (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos();
    let warm = 300;
    let n = warm + len;
    let mut s = 0.0;
    let u: Vec<f64> = (0..n)
        .map(|k| {
            s = 0.8 * s + 0.6 * gauss();
            if k < warm { level + 0.2 * s } else { s }
        })
        .collect();
    let f: Vec<f64> = u.iter().map(|v| (1.5 * v).clamp(-0.8, 0.8)).collect();
    let mut x = vec![0.0; n];
    for k in 2..n {
        x[k] = 1.5 * x[k - 1] - 0.7 * x[k - 2] + 0.1 * (f[k - 1] + f[k - 2]);
    }
    let mut text = String::from("u,y\n");
    for k in warm..n {
        text.push_str(&format!("{},{}\n", u[k], x[k] + 0.005 * gauss()));
    }
    std::fs::write(path, text).unwrap();
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn several_records_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = |name: &str| -> PathBuf { d.join(name) };
    experiment(&file("a.csv"), 1200, 1.2, 1);
    experiment(&file("b.csv"), 1000, -1.5, 2);
    experiment(&file("c.csv"), 1500, 0.8, 3);
    let nominal = file("nominal.toml");
    std::fs::write(&nominal, NOMINAL).unwrap();
    let out = file("found");
    let o = ok(&[
        "discover",
        "--model",
        p(&nominal),
        "--data",
        p(&file("a.csv")),
        "--data",
        p(&file("b.csv")),
        "--validation-data",
        p(&file("c.csv")),
        "--out",
        p(&out),
    ]);
    assert!(o.stdout.contains("verdict: missing effect"), "{}", o.stdout);
    assert!(o.stdout.contains("best location: `input`"), "{}", o.stdout);
    assert!(o.stdout.contains("effect: saturation"), "{}", o.stdout);
    assert!(o.stdout.contains("(2 records)"), "{}", o.stdout);

    let j = json(&out.join("report.json"));
    let inputs = &j["inputs"];
    assert_eq!(
        inputs["data_files"].as_array().unwrap().len(),
        2,
        "{inputs}"
    );
    assert_eq!(inputs["validation_files"].as_array().unwrap().len(), 1);
    assert_eq!(inputs["estimation_samples"], 2200);
    let before = &j["gap_before"]["estimation"];
    assert_eq!(before["records"].as_array().unwrap().len(), 2, "{before}");

    // The gap before is each record simulated from its own estimated initial state, pooled:
    // what `structid validate` reports for the same two files.
    ok(&[
        "validate",
        "--model",
        p(&nominal),
        "--data",
        p(&file("a.csv")),
        "--data",
        p(&file("b.csv")),
        "--initial-state",
        "estimate",
        "--out",
        p(&file("nominal-validation")),
    ]);
    let v = json(&file("nominal-validation").join("validation.json"));
    let pooled = v["overall"]["outputs"][0]["rms"].as_f64().unwrap();
    let gap = before["rms"].as_f64().unwrap();
    assert!((gap - pooled).abs() <= 1e-9 * pooled, "{gap} vs {pooled}");
    for (i, r) in before["records"].as_array().unwrap().iter().enumerate() {
        let own = v["records"][i]["outputs"][0]["rms"].as_f64().unwrap();
        let rms = r["rms"].as_f64().unwrap();
        assert!(
            (rms - own).abs() <= 1e-9 * own,
            "record {}: {rms} vs {own}",
            i + 1
        );
    }

    // The named saturation and the augmented model, validated on c.csv as the report says.
    let f = &j["finding"];
    assert_eq!(f["named_effect"]["name"], "saturation", "{f}");
    let after = f["gap_after"]["validation"]["rms"].as_f64().unwrap();
    assert!(
        j["gap_before"]["validation"]["rms"].as_f64().unwrap() > 5.0 * after,
        "{j}"
    );
    let initial_state = j["augmented"]["initial_state"].as_str().unwrap();
    ok(&[
        "validate",
        "--model",
        p(&out.join("augmented.toml")),
        "--data",
        p(&file("c.csv")),
        "--initial-state",
        initial_state,
        "--out",
        p(&file("augmented-validation")),
    ]);
    let v = json(&file("augmented-validation").join("validation.json"));
    let from_model = v["outputs"][0]["rms"].as_f64().unwrap();
    assert!(
        (from_model - after).abs() <= 1e-9 * after,
        "augmented.toml {from_model} vs report {after}"
    );

    // report.md names both files and each record's RMS.
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("(2 records)"), "{md}");
    assert!(md.contains("simulation RMS per record"), "{md}");
    // The reproducing commands repeat --data.
    assert!(
        md.contains(&format!(
            "--data {} --data {}",
            p(&file("a.csv")),
            p(&file("b.csv"))
        )),
        "{md}"
    );
}

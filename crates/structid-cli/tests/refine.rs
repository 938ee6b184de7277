//! `structid linear` → `structid refine` → `structid validate --settle` end to end on data
//! simulated from a Silverbox-like model file (`[linear]` output feedback with a cubic truth).

mod common;

use std::path::Path;

use common::{input_error, ok, p};

const TRUE_MODEL: &str = r#"[linear]
structure = "output-feedback"
sample_time = 0.01
den = [1.0, -1.7553711, 0.9025]
num = [[0.0, 0.1, 0.05]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "stiffness"
inputs = [0]
output = 0
dispersion = { kind = "polynomial", degree = 3 }
truth = "0.5*z0*z0*z0"
"#;

/// Low-pass filtered pseudo-random input, RMS about 0.3.
fn write_input(path: &Path, len: usize, seed: u64) {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut s = 0.0;
    let mut text = String::from("u\n");
    for _ in 0..len {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let r = ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
        s = 0.7 * s + 0.3 * r * 1.7;
        text.push_str(&format!("{}\n", s * 0.3 / 0.42));
    }
    std::fs::write(path, text).unwrap();
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn linear_then_refine_then_validate() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = d.join("truth.toml");
    std::fs::write(&truth, TRUE_MODEL).unwrap();
    for (name, len, seed) in [("est", 3000, 1), ("val", 1500, 2)] {
        let u = d.join(format!("u_{name}.csv"));
        write_input(&u, len, seed);
        ok(&[
            "simulate",
            "--model",
            p(&truth),
            "--input",
            p(&u),
            "--out",
            p(&d.join(format!("{name}.csv"))),
            "--noise-std",
            "0.002",
            "--seed",
            &seed.to_string(),
        ]);
    }
    let (est, val) = (d.join("est.csv"), d.join("val.csv"));

    // The BLA in an output-feedback structure with a cubic map.
    let bla = d.join("bla.toml");
    let o = ok(&[
        "linear",
        "--data",
        p(&est),
        "--orders",
        "2,2,1",
        "--structure",
        "output-feedback",
        "--dispersion",
        "polynomial",
        "--trend",
        "3",
        "--sample-time",
        "0.01",
        "--out",
        p(&bla),
    ]);
    assert!(o.stdout.contains("na = 2"), "{}", o.stdout);
    let text = std::fs::read_to_string(&bla).unwrap();
    assert!(
        text.contains("[linear]") && text.contains("output-feedback"),
        "{text}"
    );
    assert!(text.contains("kind = \"polynomial\", degree = 3"), "{text}");

    // Refinement with a held-out quarter.
    let out = d.join("refined");
    let o = ok(&[
        "refine",
        "--model",
        p(&bla),
        "--data",
        p(&est),
        "--validation-fraction",
        "0.25",
        "--out",
        p(&out),
    ]);
    assert!(o.stdout.contains("refinement:"), "{}", o.stdout);
    for f in [
        "model.toml",
        "refine.csv",
        "refine.svg",
        "estimation.csv",
        "estimate.csv",
        "map_N.csv",
        "map_N.svg",
        "report.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing:\n{}", o.stdout);
    }
    let report = json(&out.join("report.json"));
    let its = report["refinement"]["iterations"].as_array().unwrap();
    assert!(its.len() >= 2, "{report}");
    let best = report["refinement"]["best"].as_u64().unwrap() as usize;
    let first = its[0]["validation_rms"].as_f64().unwrap();
    let kept = its[best]["validation_rms"].as_f64().unwrap();
    assert!(kept <= first, "{first} → {kept}");
    // J never increases with β fixed after the first pass.
    for (k, it) in its.iter().enumerate() {
        if let Some(after) = it["cost_after_linear"].as_f64() {
            assert!(after <= it["cost_after_maps"].as_f64().unwrap() * (1.0 + 1e-9));
            if let Some(next) = its.get(k + 1) {
                assert!(next["cost_after_maps"].as_f64().unwrap() <= after * (1.0 + 1e-9));
            }
        }
    }
    // The estimation part is 3/4 of the data.
    let rows = std::fs::read_to_string(out.join("estimation.csv"))
        .unwrap()
        .lines()
        .count();
    assert_eq!(rows, 1 + 2250);

    // The refined model reproduces through `validate`, and simulates the fresh record well.
    let vout = d.join("validation");
    let o = ok(&[
        "validate",
        "--model",
        p(&out.join("model.toml")),
        "--estimate",
        p(&out),
        "--data",
        p(&val),
        "--settle",
        "20",
        "--out",
        p(&vout),
    ]);
    let v = json(&vout.join("validation.json"));
    assert_eq!(v["inputs"]["settle"], 20);
    let rms = v["outputs"][0]["rms"]
        .as_f64()
        .unwrap_or_else(|| panic!("{v}"));
    assert!(rms < 0.004, "validation simulation RMS {rms}\n{}", o.stdout);

    // The stored estimate of the refinement validates alike with the estimation data gone.
    std::fs::remove_file(&est).unwrap();
    let sout = d.join("validation-stored");
    ok(&[
        "validate",
        "--estimate",
        p(&out.join("estimate.json")),
        "--data",
        p(&val),
        "--settle",
        "20",
        "--out",
        p(&sout),
    ]);
    let s = json(&sout.join("validation.json"));
    let stored = s["outputs"][0]["rms"].as_f64().unwrap();
    assert!(
        (stored - rms).abs() <= 1e-12 * rms,
        "stored {stored} vs rebuilt {rms}"
    );
    assert_eq!(s["estimate"]["workflow"], "refine");
}

#[test]
fn refine_and_linear_reject_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = d.join("truth.toml");
    std::fs::write(&truth, TRUE_MODEL).unwrap();
    let u = d.join("u.csv");
    write_input(&u, 300, 3);
    let data = d.join("data.csv");
    ok(&[
        "simulate",
        "--model",
        p(&truth),
        "--input",
        p(&u),
        "--out",
        p(&data),
    ]);
    let hammerstein = common::example_model("hammerstein.toml");
    let out = d.join("out");
    let e = input_error(&[
        "refine",
        "--model",
        p(&hammerstein),
        "--data",
        p(&data),
        "--out",
        p(&out),
    ]);
    assert!(e.contains("[linear]"), "{e}");
    let e = input_error(&[
        "refine",
        "--model",
        p(&truth),
        "--data",
        p(&data),
        "--validation-fraction",
        "1.5",
        "--out",
        p(&out),
    ]);
    assert!(e.contains("--validation-fraction"), "{e}");
    let e = input_error(&[
        "linear",
        "--data",
        p(&data),
        "--orders",
        "2,2,0",
        "--structure",
        "output-feedback",
        "--out",
        p(&d.join("m.toml")),
    ]);
    assert!(e.contains("delay"), "{e}");
    // Options that would be accepted but ignored, or a file that would not read back.
    let two = d.join("two.csv");
    let text = std::fs::read_to_string(&data).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let mut two_text = format!("{header},u2\n");
    for (k, l) in lines.enumerate() {
        two_text.push_str(&format!("{l},{}\n", (k as f64 * 0.3).sin()));
    }
    std::fs::write(&two, two_text).unwrap();
    let inputs = format!("{},u2", header.split(',').find(|c| *c == "u").unwrap());
    for (args, expect) in [
        (
            vec![
                "--data",
                p(&two),
                "--input",
                &inputs,
                "--structure",
                "output-feedback",
            ],
            "--separate-numerator",
        ),
        (
            vec![
                "--data",
                p(&data),
                "--structure",
                "output-feedback",
                "--trend",
                "65",
            ],
            "--trend",
        ),
        (
            vec![
                "--data",
                p(&data),
                "--method",
                "arx",
                "--initial-state",
                "estimate",
            ],
            "--method oe",
        ),
        (
            vec!["--data", p(&data), "--method", "arx", "--transient", "10"],
            "--method oe",
        ),
    ] {
        let mut all = vec!["linear", "--orders", "2,2,1"];
        all.extend(args);
        let m = d.join("m2.toml");
        all.extend(["--out", p(&m)]);
        let e = input_error(&all);
        assert!(e.contains(expect), "{all:?}: {e}");
    }
    // The model file is an input: never overwritten.
    let e = input_error(&[
        "linear",
        "--data",
        p(&data),
        "--orders",
        "2,2,1",
        "--out",
        p(&data),
    ]);
    assert!(e.contains("input"), "{e}");
}

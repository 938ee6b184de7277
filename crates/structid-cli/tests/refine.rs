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

/// y = G·u + N(u) + e: a map in a path parallel to G, which no structure of refinement has.
const PARALLEL: &str = r#"[lft]
A = [[0.5]]
Bu = [[1.0]]
Be = [[0.0]]
Bw = [[0.0]]
Cy = [[1.0]]
Dyu = [[0.0]]
Dye = [[1.0]]
Dyw = [[1.0]]
Cz = [[0.0]]
Dzu = [[1.0]]
Dze = [[0.0]]
Dzw = [[0.0]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "N"
inputs = [0]
output = 0
dispersion = { kind = "polynomial", degree = 3 }
"#;

/// Rate feedback (friction) y = G·(u − N(ẏ)) + e with G = (0.10q⁻¹ + 0.06q⁻²)/(1 −
/// 1.84093q⁻¹ + 0.9025q⁻²) (poles 0.95·e^{±0.25j}).
const TRUE_RATE: &str = r#"[linear]
structure = "rate-feedback"
sample_time = 1.0
den = [1.0, -1.8409336, 0.9025]
num = [[0.0, 0.10, 0.06]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "friction"
inputs = [0]
output = 0
dispersion = { kind = "fourier", trend = 1 }
truth = "0.1*tanh(z0/0.3) + 0.05*z0"
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
    let out = d.join("out");
    // An [lft] whose map is not at one of the structures around a linear block G: here
    // y = G·u + N(u) + e, a parallel path.
    let parallel = d.join("parallel.toml");
    std::fs::write(&parallel, PARALLEL).unwrap();
    let e = input_error(&[
        "refine",
        "--model",
        p(&parallel),
        "--data",
        p(&data),
        "--out",
        p(&out),
    ]);
    assert!(e.contains("does not say which"), "{e}");
    assert!(!e.contains("not supported"), "{e}");
    // A linear model without a map has nothing to refine around.
    let lti = d.join("lti.toml");
    std::fs::write(
        &lti,
        "[linear]\nstructure = \"lti\"\nden = [1.0, -0.5]\nnum = [[0.0, 1.0]]\n\n\
         [signals]\nu = [\"u\"]\ny = [\"y\"]\n",
    )
    .unwrap();
    let e = input_error(&[
        "refine",
        "--model",
        p(&lti),
        "--data",
        p(&data),
        "--out",
        p(&out),
    ]);
    assert!(e.contains("lti"), "{e}");
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

/// Simulates `model` on a fresh input of `len` samples (seed `seed`, RMS scaled by `gain`).
fn simulate_record(
    d: &Path,
    model: &Path,
    name: &str,
    len: usize,
    seed: u64,
    gain: f64,
) -> std::path::PathBuf {
    let u = d.join(format!("u_{name}.csv"));
    write_input(&u, len, seed);
    if gain != 1.0 {
        let text = std::fs::read_to_string(&u).unwrap();
        let mut lines = text.lines();
        let mut out = format!("{}\n", lines.next().unwrap());
        for l in lines {
            out.push_str(&format!("{}\n", l.parse::<f64>().unwrap() * gain));
        }
        std::fs::write(&u, out).unwrap();
    }
    let data = d.join(format!("{name}.csv"));
    ok(&[
        "simulate",
        "--model",
        p(model),
        "--input",
        p(&u),
        "--out",
        p(&data),
        "--noise-std",
        "0.002",
        "--seed",
        &seed.to_string(),
    ]);
    data
}

/// J never increases through the alternation recorded in report.json.
fn assert_monotone(report: &serde_json::Value) {
    let its = report["refinement"]["iterations"].as_array().unwrap();
    for (k, it) in its.iter().enumerate() {
        if let Some(after) = it["cost_after_linear"].as_f64() {
            assert!(
                after <= it["cost_after_maps"].as_f64().unwrap() * (1.0 + 1e-9),
                "{report}"
            );
            if let Some(next) = its.get(k + 1) {
                assert!(
                    next["cost_after_maps"].as_f64().unwrap() <= after * (1.0 + 1e-9),
                    "{report}"
                );
            }
        }
    }
}

/// `structid refine` on a rate-feedback model file started 20 % off: the refined model is
/// written as rate feedback, J never increases, and it simulates a fresh record at the noise
/// level through `structid validate`.
#[test]
fn refine_rate_feedback_model_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = d.join("truth.toml");
    std::fs::write(&truth, TRUE_RATE).unwrap();
    let est = simulate_record(d, &truth, "est", 2000, 11, 3.0);
    let val = simulate_record(d, &truth, "val", 1000, 12, 3.0);
    // Both continuous-time poles 20 % larger, the numerator 20 % larger.
    let (r, th) = (0.95f64.powf(1.2), 0.25f64 * 1.2);
    let start = d.join("start.toml");
    std::fs::write(
        &start,
        TRUE_RATE
            .replace(
                "den = [1.0, -1.8409336, 0.9025]",
                &format!("den = [1.0, {}, {}]", -2.0 * r * th.cos(), r * r),
            )
            .replace("num = [[0.0, 0.10, 0.06]]", "num = [[0.0, 0.12, 0.072]]"),
    )
    .unwrap();
    let out = d.join("refined");
    let o = ok(&[
        "refine",
        "--model",
        p(&start),
        "--data",
        p(&est),
        "--validation-data",
        p(&val),
        "--beta",
        "1e-6",
        "--out",
        p(&out),
    ]);
    assert!(o.stdout.contains("refinement:"), "{}", o.stdout);
    let report = json(&out.join("report.json"));
    assert_monotone(&report);
    assert!(
        report["refinement"]["structure"]
            .as_str()
            .unwrap()
            .contains("rate feedback"),
        "{report}"
    );
    let its = report["refinement"]["iterations"].as_array().unwrap();
    let best = report["refinement"]["best"].as_u64().unwrap() as usize;
    let first = its[0]["validation_rms"].as_f64().unwrap();
    let kept = its[best]["validation_rms"].as_f64().unwrap();
    assert!(kept < 0.2 * first, "validation RMS {first} → {kept}");
    let refined = structid_io::ModelFile::from_path(&out.join("model.toml")).unwrap();
    let lin = refined.linear.as_ref().unwrap();
    assert_eq!(lin.structure_name(), "rate-feedback");
    let vout = d.join("validation");
    ok(&[
        "validate",
        "--model",
        p(&out.join("model.toml")),
        "--estimate",
        p(&out),
        "--data",
        p(&val),
        "--out",
        p(&vout),
    ]);
    let v = json(&vout.join("validation.json"));
    let rms = v["outputs"][0]["rms"].as_f64().unwrap();
    eprintln!("rate feedback: validation RMS {first} → {kept}, validate {rms}");
    assert!(
        rms < 0.004,
        "validation simulation RMS {rms} (first iteration {first})"
    );
}

/// An `[lft]` model (the Hammerstein example, with its poles and gain moved) is recognised as
/// an input map around G, refined, and written as `[linear]` with structure "input".
#[test]
fn refine_lft_model_file_as_the_structure_it_declares() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = common::example_model("hammerstein.toml");
    let est = simulate_record(d, &truth, "est", 800, 21, 3.0);
    let text = std::fs::read_to_string(&truth).unwrap();
    let wrong = text
        .replace("[1.2, -0.5],", "[1.1, -0.4],")
        .replace("Cy = [[0.5, 0.3]]", "Cy = [[0.6, 0.36]]");
    assert_ne!(wrong, text);
    let start = d.join("start.toml");
    std::fs::write(&start, wrong).unwrap();
    let out = d.join("refined");
    let o = ok(&[
        "refine",
        "--model",
        p(&start),
        "--data",
        p(&est),
        "--validation-fraction",
        "0.25",
        "--out",
        p(&out),
    ]);
    assert!(o.stdout.contains("is input nonlinearity"), "{}", o.stdout);
    let report = json(&out.join("report.json"));
    assert_monotone(&report);
    let its = report["refinement"]["iterations"].as_array().unwrap();
    let best = report["refinement"]["best"].as_u64().unwrap() as usize;
    let first = its[0]["validation_rms"].as_f64().unwrap();
    let kept = its[best]["validation_rms"].as_f64().unwrap();
    assert!(kept < 0.5 * first, "validation RMS {first} → {kept}");
    let refined = structid_io::ModelFile::from_path(&out.join("model.toml")).unwrap();
    let lin = refined.linear.as_ref().unwrap();
    assert_eq!(lin.structure_name(), "input");
    // The true poles 0.6 ± 0.37i: F = 1 − 1.2q⁻¹ + 0.5q⁻².
    let den = &lin.model.den;
    eprintln!("[lft] input map: validation RMS {first} → {kept}, F = {den:?}");
    assert!(
        (den[1] + 1.2).abs() < 0.01 && (den[2] - 0.5).abs() < 0.01,
        "refined F = {den:?} (start 1 − 1.1q⁻¹ + 0.4q⁻²)"
    );
}

/// A `[linear]` rate-feedback model of a mass with viscous damping (position from force,
/// zero-order hold, T = 0.01 s): its integrator stays at z = 1 through refinement while the
/// other pole moves from 20 % off (in the damping) to the truth.
#[test]
fn refine_keeps_the_integrator_of_a_rate_feedback_nominal() {
    let ts = 0.01;
    let mass = |a: f64, gain: f64| {
        let p = (-a * ts).exp();
        let b1 = gain * (a * ts - 1.0 + p) / (a * a);
        let b2 = gain * (1.0 - p - a * ts * p) / (a * a);
        format!(
            "[linear]\nstructure = \"rate-feedback\"\nsample_time = {ts}\n\
             den = [1.0, {}, {p}]\nnum = [[0.0, {b1}, {b2}]]\n\n\
             [signals]\nu = [\"u\"]\ny = [\"y\"]\n\n\
             [[nonlinearity]]\nname = \"friction\"\ninputs = [0]\noutput = 0\n\
             dispersion = {{ kind = \"fourier\", trend = 1 }}\ntruth = \"0.3*tanh(z0/0.02)\"\n",
            -(1.0 + p)
        )
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (truth, start) = (d.join("truth.toml"), d.join("start.toml"));
    std::fs::write(&truth, mass(4.0, 1.0)).unwrap();
    std::fs::write(&start, mass(4.8, 1.2)).unwrap();
    let est = simulate_record(d, &truth, "est", 3000, 31, 3.0);
    let out = d.join("refined");
    ok(&[
        "refine",
        "--model",
        p(&start),
        "--data",
        p(&est),
        "--beta",
        "1e-8",
        "--out",
        p(&out),
    ]);
    assert_monotone(&json(&out.join("report.json")));
    let refined = structid_io::ModelFile::from_path(&out.join("model.toml")).unwrap();
    let den = &refined.linear.as_ref().unwrap().model.den;
    let at_one: f64 = den.iter().sum();
    assert!(at_one.abs() < 1e-9, "F(1) = {at_one}: {den:?}");
    let (p_true, p_start) = ((-4.0 * ts).exp(), (-4.8 * ts).exp());
    eprintln!("integrator: pole {} vs {p_true} (start {p_start})", den[2]);
    assert!(
        (den[2] - p_true).abs() < 0.1 * (p_start - p_true).abs(),
        "pole {} vs {p_true} (start {p_start})",
        den[2]
    );
}

/// The starting model of the multi-record tests: TRUE_MODEL's structure with poles and gain
/// off, a cubic polynomial map.
const WRONG_START: &str = r#"[linear]
structure = "output-feedback"
sample_time = 0.01
den = [1.0, -1.70, 0.85]
num = [[0.0, 0.13, 0.03]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "stiffness"
inputs = [0]
output = 0
dispersion = { kind = "polynomial", degree = 3 }
"#;

/// `refine --data a --data b --validation-data c --validation-data d`: J never increases, the
/// report names every file, and the kept iteration's validation error is the pooled error that
/// `structid validate --data c --data d` computes for the refined estimate, each record
/// simulated from rest. A record given twice refines like the record once (β fixed, feature
/// map: the same problem), and --validation-fraction with several records is refused.
#[test]
fn refine_over_several_records() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = d.join("truth.toml");
    std::fs::write(&truth, TRUE_MODEL).unwrap();
    let start = d.join("start.toml");
    std::fs::write(&start, WRONG_START).unwrap();
    let a = simulate_record(d, &truth, "a", 1500, 31, 1.0);
    let b = simulate_record(d, &truth, "b", 1000, 32, 1.0);
    let va = simulate_record(d, &truth, "va", 700, 33, 1.0);
    let vb = simulate_record(d, &truth, "vb", 500, 34, 1.0);
    let out = d.join("refined");
    let o = ok(&[
        "refine",
        "--model",
        p(&start),
        "--data",
        p(&a),
        "--data",
        p(&b),
        "--validation-data",
        p(&va),
        "--validation-data",
        p(&vb),
        "--out",
        p(&out),
    ]);
    let report = json(&out.join("report.json"));
    assert_monotone(&report);
    let refinement = &report["refinement"];
    let validation = refinement["validation"].as_str().unwrap();
    assert!(
        validation.contains("va.csv") && validation.contains("vb.csv"),
        "{validation}"
    );
    let files = report["reproduction"]["data_files_absolute"]
        .as_array()
        .unwrap();
    assert_eq!(files.len(), 2, "{report}");
    let its = refinement["iterations"].as_array().unwrap();
    let best = refinement["best"].as_u64().unwrap() as usize;
    let first = its[0]["validation_rms"].as_f64().unwrap();
    let kept = its[best]["validation_rms"].as_f64().unwrap();
    assert!(kept < 0.2 * first, "{first} → {kept}\n{}", o.stdout);
    assert!(kept < 0.004, "{kept}");
    // The same number from `validate` over both validation records, from rest.
    let vout = d.join("validation");
    ok(&[
        "validate",
        "--model",
        p(&out.join("model.toml")),
        "--estimate",
        p(&out),
        "--data",
        p(&va),
        "--data",
        p(&vb),
        "--out",
        p(&vout),
    ]);
    let v = json(&vout.join("validation.json"));
    let pooled = v["overall"]["outputs"][0]["rms"].as_f64().unwrap();
    assert!(
        (pooled - kept).abs() <= 1e-8 * kept,
        "validate {pooled} vs refine {kept}"
    );

    // A record given twice is the record once (fixed β, polynomial map).
    let run = |data: &[&Path], name: &str| {
        let out = d.join(name);
        let mut args = vec!["refine", "--model", p(&start), "--beta", "1e-6"];
        for f in data {
            args.extend(["--data", p(f)]);
        }
        args.extend(["--iterations", "3", "--out", p(&out)]);
        ok(&args);
        let text = std::fs::read_to_string(out.join("model.toml")).unwrap();
        structid_io::ModelFile::parse(&text, None)
            .unwrap()
            .linear
            .unwrap()
            .model
    };
    let once = run(&[&a], "once");
    let twice = run(&[&a, &a], "twice");
    for (x, y) in once.parameters().iter().zip(twice.parameters()) {
        assert!((x - y).abs() < 1e-6 * y.abs().max(1e-3), "{x} vs {y}");
    }

    let e = input_error(&[
        "refine",
        "--model",
        p(&start),
        "--data",
        p(&a),
        "--data",
        p(&b),
        "--validation-fraction",
        "0.2",
        "--out",
        p(&d.join("x")),
    ]);
    assert!(
        e.contains("--validation-fraction and --data") && e.contains("give --validation-data"),
        "{e}"
    );
    // A validation record shorter than --settle is named.
    let e = input_error(&[
        "refine",
        "--model",
        p(&start),
        "--data",
        p(&a),
        "--validation-data",
        p(&va),
        "--validation-data",
        p(&vb),
        "--settle",
        "600",
        "--out",
        p(&d.join("y")),
    ]);
    assert!(
        e.contains("validation record 2") && e.contains("vb.csv"),
        "{e}"
    );
}

//! `structid discover` end to end: a nominal LTI model file, records simulated by `structid
//! simulate` from a system with a hidden input saturation (and from the nominal model alone),
//! the reports, the figures and the augmented model file; input errors.

mod common;

use std::path::Path;

use common::{input_error, ok, p};

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

/// The true system: the nominal G behind an actuator that saturates at ±0.8.
const SATURATED: &str = r#"[linear]
structure = "input"
sample_time = 0.05
den = [1.0, -1.5, 0.7]
num = [[0.0, 0.1, 0.1]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "actuator"
inputs = [0]
output = 0
dispersion = { kind = "polynomial", degree = 1 }
truth = "min(max(1.5*z0, -0.8), 0.8)"
"#;

const SAMPLES: usize = 2000;

/// A low-pass filtered Gaussian input of unit standard deviation (s ← 0.8·s + 0.6·n).
fn write_input(path: &Path, len: usize, seed: u64) {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let mut s = 0.0;
    let mut text = String::from("u\n");
    for _ in 0..len {
        let n = (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos();
        s = 0.8 * s + 0.6 * n;
        text.push_str(&format!("{s}\n"));
    }
    std::fs::write(path, text).unwrap();
}

/// Estimation and validation records of the system in `model` (noise std 0.005).
fn records(dir: &Path, model: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let truth = dir.join("truth.toml");
    std::fs::write(&truth, model).unwrap();
    for (name, seed) in [("est", 1), ("val", 2)] {
        let u = dir.join(format!("u_{name}.csv"));
        write_input(&u, SAMPLES, seed);
        ok(&[
            "simulate",
            "--model",
            p(&truth),
            "--input",
            p(&u),
            "--out",
            p(&dir.join(format!("{name}.csv"))),
            "--noise-std",
            "0.005",
            "--seed",
            &seed.to_string(),
        ]);
    }
    (dir.join("est.csv"), dir.join("val.csv"))
}

/// `structid discover` on the nominal model and the two records, writing to `out`; it must
/// succeed.
fn discover(nominal: &Path, est: &Path, val: &Path, out: &Path) -> common::Out {
    ok(&[
        "discover",
        "--model",
        p(nominal),
        "--data",
        p(est),
        "--validate",
        p(val),
        "--out",
        p(out),
    ])
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn rms(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

fn column(path: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let c = header.iter().position(|h| *h == name).unwrap();
    lines
        .map(|l| l.split(',').nth(c).unwrap().parse().unwrap())
        .collect()
}

#[test]
fn a_hidden_input_saturation_is_found_named_and_added() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (est, val) = records(d, SATURATED);
    let nominal = d.join("nominal.toml");
    std::fs::write(&nominal, NOMINAL).unwrap();
    let out = d.join("found");
    let o = discover(&nominal, &est, &val, &out);
    assert!(o.stdout.contains("verdict: missing effect"), "{}", o.stdout);
    assert!(o.stdout.contains("best location: `input`"), "{}", o.stdout);
    assert!(o.stdout.contains("effect: saturation"), "{}", o.stdout);
    assert!(o.stdout.contains("smaller"), "{}", o.stdout);

    // report.md: verdict first, then the gap, the hypotheses, the effect and the gap after.
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("saturation") && md.contains("input"), "{md}");
    let verdict = md
        .find("**Verdict (missing effect):** missing effect")
        .expect("verdict");
    let hypotheses = md.find("hypotheses").expect("hypotheses");
    let after = md.find("The gap after").expect("gap after");
    assert!(verdict < hypotheses && hypotheses < after, "{md}");
    for needle in [
        "Portmanteau",
        "whiteness of ε",
        "Where in time",
        "Where in operating space",
        "Shrink factor",
        "Direction test",
        "structid validate --model",
        "[map.svg](map.svg)",
        "[before_after.svg](before_after.svg)",
    ] {
        assert!(md.contains(needle), "report.md lacks `{needle}`:\n{md}");
    }

    // report.json: the same, machine-readable.
    let j = json(&out.join("report.json"));
    assert!(j["command"].as_str().unwrap().contains("discover"), "{j}");
    assert_eq!(j["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(j["missing_effect"], true);
    let f = &j["finding"];
    assert_eq!(f["location"], "input", "{f}");
    assert_eq!(f["classification"]["kind"], "named", "{f}");
    let named = &f["named_effect"];
    assert_eq!(named["name"], "saturation", "{named}");
    let level = named["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "level")
        .unwrap()["value"]
        .as_f64()
        .unwrap();
    assert!((level - 0.8).abs() < 0.05, "level {level}");
    let before = j["gap_before"]["validation"]["rms"].as_f64().unwrap();
    let after_rms = f["gap_after"]["validation"]["rms"].as_f64().unwrap();
    assert!(before > 3.0 * after_rms, "{before} → {after_rms}");
    // Every built-in location was tried (total variation may add estimates).
    let tried: Vec<&str> = j["hypotheses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|h| h["location"].as_str().unwrap())
        .collect();
    for key in ["input", "output", "output-feedback", "rate-feedback"] {
        assert!(tried.contains(&key), "{}", j["hypotheses"]);
    }
    // augmented.toml, validated with its true map, reproduces the report's validation RMS
    // after (the initial state the report names).
    assert_eq!(j["augmented"]["validation_rms"].as_f64(), Some(after_rms));
    let initial_state = j["augmented"]["initial_state"].as_str().unwrap();
    let from_model = validation_rms(&[
        "--model",
        p(&out.join("augmented.toml")),
        "--data",
        p(&val),
        "--initial-state",
        initial_state,
        "--out",
        p(&d.join("validation-model")),
    ]);
    assert!(
        (from_model - after_rms).abs() <= 1e-9 * after_rms,
        "augmented.toml {from_model} vs report {after_rms}"
    );

    // The figures.
    for f in ["residual.svg", "regions.svg", "map.svg", "before_after.svg"] {
        let svg = std::fs::read_to_string(out.join(f)).unwrap();
        assert!(svg.starts_with("<svg") || svg.contains("<svg"), "{f}");
    }

    // augmented.toml reads back: the nominal G as [linear] input with the named map as truth.
    let path = out.join("augmented.toml");
    let mf = structid_io::ModelFile::from_path(&path).unwrap();
    let lin = mf.linear.as_ref().expect("[linear]");
    assert_eq!(lin.structure, Some(structid_core::Site::Input));
    assert_eq!(mf.blocks.len(), 1);
    // The block's dispersion is the one its map was estimated with.
    match f["estimator"].as_str().unwrap() {
        "total variation" => assert_eq!(mf.blocks[0].dispersion.kind(), "tv"),
        _ => {
            assert_eq!(mf.blocks[0].dispersion.kind(), "fourier");
            assert!(mf.blocks[0].dispersion.sigma().is_some());
        }
    }
    match &mf.blocks[0].truth {
        Some(structid_io::TruthSpec::Expression(e)) => assert!(e.contains("min(max("), "{e}"),
        other => panic!("expected an expression, found {other:?}"),
    }
    assert!(!out.join("N_table.csv").exists());
    // …and simulates the validation record (from rest) about as the report says.
    let sim = d.join("sim.csv");
    ok(&[
        "simulate",
        "--model",
        p(&path),
        "--input",
        p(&val),
        "--out",
        p(&sim),
    ]);
    let r = rms(&column(&sim, "y"), &column(&val, "y"));
    assert!(
        (r - after_rms).abs() < 0.1 * after_rms,
        "{r} vs {after_rms}"
    );

    // estimate.json: the augmented model as a stored estimate, which validates as the report
    // says with the estimation record gone.
    assert!(
        j["files"]
            .as_array()
            .unwrap()
            .contains(&"estimate.json".into()),
        "{j}"
    );
    std::fs::remove_file(&est).unwrap();
    let stored = validation_rms(&[
        "--estimate",
        p(&out.join("estimate.json")),
        "--data",
        p(&val),
        "--initial-state",
        initial_state,
        "--out",
        p(&d.join("validation-estimate")),
    ]);
    assert!(
        (stored - after_rms).abs() <= 1e-9 * after_rms,
        "estimate.json {stored} vs report {after_rms}"
    );
    assert!(
        (stored - from_model).abs() <= 1e-9 * after_rms,
        "estimate.json {stored} vs augmented.toml {from_model}"
    );
    let v = json(&d.join("validation-estimate").join("validation.json"));
    assert_eq!(v["estimate"]["workflow"], "discover", "{v}");
}

/// `structid validate` with `args` (which name its --out directory): the simulation RMS of
/// its validation.json.
fn validation_rms(args: &[&str]) -> f64 {
    let mut all = vec!["validate"];
    all.extend_from_slice(args);
    ok(&all);
    let i = args.iter().position(|a| *a == "--out").unwrap();
    let v = json(&Path::new(args[i + 1]).join("validation.json"));
    v["outputs"][0]["rms"]
        .as_f64()
        .unwrap_or_else(|| panic!("{v}"))
}

#[test]
fn an_lti_record_has_no_missing_effect() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (est, val) = records(d, NOMINAL);
    let nominal = d.join("nominal.toml");
    std::fs::write(&nominal, NOMINAL).unwrap();
    let out = d.join("nothing");
    let o = discover(&nominal, &est, &val, &out);
    assert!(
        o.stdout.contains("verdict: no missing effect detected"),
        "{}",
        o.stdout
    );
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("no missing effect detected"), "{md}");
    assert!(
        md.contains("Portmanteau") && !md.contains("| rank | location"),
        "{md}"
    );
    assert!(!out.join("augmented.toml").exists());
    assert!(!out.join("map.svg").exists());
    let j = json(&out.join("report.json"));
    assert_eq!(j["missing_effect"], false);
    assert!(j["finding"].is_null() && j["augmented"].is_null());
    assert!(j["hypotheses"].as_array().unwrap().is_empty());
    assert!(out.join("residual.svg").is_file() && out.join("regions.svg").is_file());
}

#[test]
fn bad_models_and_arguments_are_input_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let est = d.join("est.csv");
    let mut text = String::from("u,y\n");
    for k in 0..300 {
        text.push_str(&format!(
            "{},{}\n",
            (k as f64 * 0.1).sin(),
            (k as f64 * 0.1).cos()
        ));
    }
    std::fs::write(&est, &text).unwrap();
    let nominal = d.join("nominal.toml");
    std::fs::write(&nominal, NOMINAL).unwrap();
    let out = d.join("out");
    let run = |model: &Path, data: &Path, extra: &[&str]| {
        let mut args = vec![
            "discover",
            "--model",
            p(model),
            "--data",
            p(data),
            "--validate",
            p(&est),
            "--out",
            p(&out),
        ];
        args.extend_from_slice(extra);
        input_error(&args)
    };

    // A model with a map that is not known (no truth) cannot be a nominal model.
    let mapped = d.join("mapped.toml");
    std::fs::write(
        &mapped,
        SATURATED.replace("truth = \"min(max(1.5*z0, -0.8), 0.8)\"\n", ""),
    )
    .unwrap();
    let e = run(&mapped, &est, &[]);
    assert!(e.contains("actuator") && e.contains("truth"), "{e}");

    // Missing files.
    let e = run(&d.join("nowhere.toml"), &est, &[]);
    assert!(e.contains("nowhere.toml"), "{e}");
    let e = run(&nominal, &d.join("missing.csv"), &[]);
    assert!(e.contains("missing.csv"), "{e}");

    // Too short a record for discovery.
    let short = d.join("short.csv");
    std::fs::write(&short, text.lines().take(51).collect::<Vec<_>>().join("\n")).unwrap();
    let e = run(&nominal, &short, &[]);
    assert!(e.contains("100 samples"), "{e}");

    // Two outputs.
    let two = d.join("two.toml");
    std::fs::write(
        &two,
        "[lft]\nA = [[0.5]]\nBu = [[1.0]]\nBe = [[0.0, 0.0]]\nCy = [[1.0], [0.5]]\n\
         Dye = [[1.0, 0.0], [0.0, 1.0]]\n[signals]\nu = [\"u\"]\ny = [\"y\", \"y2\"]\n",
    )
    .unwrap();
    let e = run(&two, &est, &[]);
    assert!(e.contains("one input and one output"), "{e}");

    // Bad options.
    let e = run(&nominal, &est, &["--locations", "input,elsewhere"]);
    assert!(
        e.contains("elsewhere") && e.contains("output-feedback"),
        "{e}"
    );
    let e = run(&nominal, &est, &["--significance", "0.9"]);
    assert!(e.contains("significance") && e.contains("0.9"), "{e}");
    let e = run(&nominal, &est, &["--hysteresis-threshold", "1.5"]);
    assert!(e.contains("--hysteresis-threshold"), "{e}");
    let e = run(&nominal, &est, &["--settle", "300"]);
    assert!(e.contains("--settle"), "{e}");

    // The output directory may not be an input.
    let e = input_error(&[
        "discover",
        "--model",
        p(&nominal),
        "--data",
        p(&est),
        "--validate",
        p(&est),
        "--out",
        p(&est),
    ]);
    assert!(e.contains("refusing") || e.contains("input"), "{e}");
    assert!(!out.exists(), "nothing is written on an input error");
}

/// A nominal model in the wrong units (its gain a thousand times the data's) simulates far
/// worse than the mean of y: an input error that names both RMS values and what to do, and
/// writes nothing.
#[test]
fn a_nominal_worse_than_a_constant_is_an_input_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (est, val) = records(d, NOMINAL);
    let wrong = d.join("wrong_units.toml");
    std::fs::write(
        &wrong,
        NOMINAL.replace("num = [[0.0, 0.1, 0.1]]", "num = [[0.0, 100.0, 100.0]]"),
    )
    .unwrap();
    let out = d.join("out");
    let e = input_error(&[
        "discover",
        "--model",
        p(&wrong),
        "--data",
        p(&est),
        "--validate",
        p(&val),
        "--out",
        p(&out),
    ]);
    for part in [
        "not usable on the estimation record",
        "worse than a constant",
        "RMS",
        "units",
        "\nhint: ",
        "structid linear",
        "--integrators",
    ] {
        assert!(e.contains(part), "{part}: {e}");
    }
    // The ratio printed is the one the gains imply: the error is 999 times y's own size.
    let ratio: f64 = e
        .split("× the RMS")
        .next()
        .and_then(|s| s.rsplit(", ").next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no ratio in {e}"));
    assert!((ratio - 999.0).abs() < 20.0, "{ratio}: {e}");
    assert!(!out.exists(), "nothing is written on an input error");
}

/// A nominal `[lft]` model with a declared location `spring` (z = the measured position, w
/// entering the position equation, unlike the built-in feedback into the input channel) and a
/// named state `velocity`.
const DECLARED: &str = r#"[lft]
sample_time = 0.05
A = [[1.0, 0.05], [-0.1, 0.9]]
Bu = [[0.0], [0.05]]
Bw = [[-0.05], [0.0]]
Cy = [[1.0, 0.0]]
Dye = [[1.0]]
Cz = [[1.0, 0.0]]
Dze = [[1.0]]

[signals]
u = ["u"]
y = ["y"]
"#;

#[test]
fn a_location_the_model_file_declares_is_a_candidate_and_wins_when_the_effect_sits_there() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = format!(
        "{DECLARED}\n[[nonlinearity]]\nname = \"spring\"\ninputs = [0]\noutput = 0\n\
         dispersion = {{ kind = \"polynomial\", degree = 3 }}\ntruth = \"2*z0^3\"\n"
    );
    let (est, val) = records(d, &truth);
    let nominal = d.join("nominal.toml");
    std::fs::write(
        &nominal,
        format!(
            "{DECLARED}\n[discover]\nlocations = [{{ name = \"spring\", z = 0, w = 0 }}]\n\
             states = [{{ name = \"velocity\", state = 1 }}]\n"
        ),
    )
    .unwrap();
    let out = d.join("found");
    let o = discover(&nominal, &est, &val, &out);
    assert!(o.stdout.contains("spring"), "{}", o.stdout);
    let j = json(&out.join("report.json"));
    let f = &j["finding"];
    assert_eq!(f["location"], "declared-0", "{f}");
    assert_eq!(
        f["named_effect"]["family"]["OddPolynomial"]["degree"], 3,
        "{f}"
    );
    // The named state is a candidate signal of the localisation.
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("velocity"), "{md}");
    // A declared location is written in [lft] form and reads back.
    let mf = structid_io::ModelFile::from_path(&out.join("augmented.toml")).unwrap();
    assert!(mf.linear.is_none() && mf.blocks.len() == 1);
}

/// A backlash at an actuator, simulated in continuous time (`structid_testcases::physics`,
/// dynamic seed 0: a non-minimum-phase plant with an input delay of two samples and coloured
/// noise), given to `structid discover` with a nominal estimated from the effect-laden
/// record: the report says dynamic at the input, and report.json carries the play with its
/// half-width within 10 % of the truth.
#[test]
fn a_backlash_behind_an_estimated_nominal_is_reported_with_its_play() {
    use structid_testcases::physics::{PhysicalEffect, PhysicsKind, generate};
    let case = generate(PhysicsKind::Dynamic, 0);
    let Some((PhysicalEffect::Backlash { width, .. }, _)) = case.effect else {
        panic!("dynamic seed 0 is a backlash: {:?}", case.effect);
    };
    let dir = tempfile::tempdir().unwrap();
    let g = &case.nominal;
    let nominal = dir.path().join("nominal.toml");
    std::fs::write(
        &nominal,
        format!(
            "[linear]\nstructure = \"lti\"\nsample_time = {}\nden = {:?}\nnum = {:?}\n\n\
             [signals]\nu = [\"u\"]\ny = [\"y\"]\n",
            g.sample_time.unwrap(),
            g.den,
            g.num
        ),
    )
    .unwrap();
    let csv = |name: &str, d: &structid_core::Data| {
        let path = dir.path().join(name);
        let (u, y) = (d.u().channel(0), d.y().channel(0));
        let mut text = String::from("u,y\n");
        for (u, y) in u.iter().zip(&y) {
            text.push_str(&format!("{u:e},{y:e}\n"));
        }
        std::fs::write(&path, text).unwrap();
        path
    };
    let est = csv("est.csv", &case.estimation);
    let val = csv("val.csv", &case.validation);
    let out = dir.path().join("out");
    let run = discover(&nominal, &est, &val, &out);
    assert!(run.stdout.contains("a play (backlash)"), "{}", run.stdout);
    let report = json(&out.join("report.json"));
    let f = &report["finding"];
    assert_eq!(f["classification"]["kind"], "dynamic", "{f}");
    assert_eq!(f["location"], "input", "{f}");
    let h = &f["input_hysteresis"];
    let threshold = h["threshold"].as_f64().unwrap();
    assert!((threshold - width).abs() <= 0.1 * width, "{h} vs {width}");
    assert!((h["weight"].as_f64().unwrap() + 1.0).abs() <= 0.25, "{h}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("a play (backlash) of half-width"), "{md}");
}

//! `structid discover` on a model that already has maps, and `--effects N`: records of a plant
//! with two effects (an actuator that saturates and a cubic spring acting after it, simulated
//! here by its difference equation, not by structid), the augmented model of a first run used
//! as the nominal model of a second, the iteration, and malformed nominal models.

mod common;

use std::path::{Path, PathBuf};

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

const SAMPLES: usize = 2500;
const NOISE: f64 = 0.005;

/// Standard normal numbers from a seeded LCG (Box–Muller).
fn normals(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    move || {
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (a, b) = (uniform(), uniform());
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    }
}

/// A record of y_k = 1.5·y_(k−1) − 0.7·y_(k−2) + 0.1·(f_(k−1) + f_(k−2)) + e_k with the force
/// f = sat(u) − 0.15·y³ (the saturation at ±0.8 with slope 1.5; the spring reads the measured
/// y), u a low-pass filtered Gaussian.
fn record(path: &Path, seed: u64) {
    let mut n = normals(seed);
    let mut s = 0.0;
    let (mut x, mut f, mut text) = (
        vec![0.0; SAMPLES],
        vec![0.0; SAMPLES],
        String::from("u,y\n"),
    );
    for k in 0..SAMPLES {
        s = 0.8 * s + 0.6 * n();
        let at = |v: &[f64], lag: usize| if k >= lag { v[k - lag] } else { 0.0 };
        x[k] = 1.5 * at(&x, 1) - 0.7 * at(&x, 2) + 0.1 * (at(&f, 1) + at(&f, 2));
        let y = x[k] + NOISE * n();
        f[k] = (1.5 * s).clamp(-0.8, 0.8) - 0.15 * y.powi(3);
        text.push_str(&format!("{s},{y}\n"));
    }
    std::fs::write(path, text).unwrap();
}

fn records(dir: &Path) -> (PathBuf, PathBuf) {
    let (est, val) = (dir.join("est.csv"), dir.join("val.csv"));
    record(&est, 1);
    record(&val, 2);
    (est, val)
}

fn discover(model: &Path, est: &Path, val: &Path, out: &Path, extra: &[&str]) -> common::Out {
    let mut args = vec![
        "discover",
        "--model",
        p(model),
        "--data",
        p(est),
        "--validate",
        p(val),
        "--out",
        p(out),
        // G is the plant's own (refitted jointly with the first map it would take up the
        // second effect's linear part).
        "--keep-nominal",
    ];
    args.extend_from_slice(extra);
    ok(&args)
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// `structid validate --model model --data val --initial-state s`: the simulation RMS.
fn validate(model: &Path, val: &Path, initial_state: &str, out: &Path) -> f64 {
    ok(&[
        "validate",
        "--model",
        p(model),
        "--data",
        p(val),
        "--initial-state",
        initial_state,
        "--out",
        p(out),
    ]);
    json(&out.join("validation.json"))["outputs"][0]["rms"]
        .as_f64()
        .unwrap()
}

/// The augmented model of a first run is the nominal model of a second: the second finds the
/// other effect, and its augmented model (both maps) validates as its report says.
#[test]
fn an_augmented_model_is_a_nominal_model_and_the_next_effect_is_added() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (est, val) = records(d);
    let nominal = d.join("nominal.toml");
    std::fs::write(&nominal, NOMINAL).unwrap();
    let first = d.join("first");
    let o = discover(&nominal, &est, &val, &first, &[]);
    assert!(o.stdout.contains("verdict: missing effect"), "{}", o.stdout);
    let j1 = json(&first.join("report.json"));
    let after_first = j1["finding"]["gap_after"]["validation"]["rms"]
        .as_f64()
        .unwrap();

    let second = d.join("second");
    let o = discover(&first.join("augmented.toml"), &est, &val, &second, &[]);
    assert!(o.stdout.contains("verdict: missing effect"), "{}", o.stdout);
    let j2 = json(&second.join("report.json"));
    // The second run started where the first ended: its nominal model's gap is the first
    // run's gap after (the same model on the same record).
    let before_second = j2["gap_before"]["validation"]["rms"].as_f64().unwrap();
    assert!(
        (before_second - after_first).abs() < 0.05 * after_first,
        "{before_second} vs {after_first}"
    );
    let after_second = j2["finding"]["gap_after"]["validation"]["rms"]
        .as_f64()
        .unwrap();
    assert!(
        after_second < after_first / 3.0,
        "{after_first} → {after_second}"
    );
    // Different locations: the second effect is not the first one again.
    assert_ne!(j1["finding"]["location"], j2["finding"]["location"]);
    // augmented.toml carries both maps, the new block first, and validates as reported.
    let path = second.join("augmented.toml");
    let mf = structid_io::ModelFile::from_path(&path).unwrap();
    assert_eq!(
        mf.blocks.len(),
        2,
        "{}",
        std::fs::read_to_string(&path).unwrap()
    );
    assert_eq!(mf.blocks[0].name, "N2");
    assert_eq!(mf.blocks[1].name, "N");
    assert!(mf.blocks.iter().all(|b| b.truth.is_some()));
    let reported = j2["augmented"]["validation_rms"].as_f64().unwrap();
    let initial_state = j2["augmented"]["initial_state"].as_str().unwrap();
    let from_file = validate(&path, &val, initial_state, &d.join("v2"));
    assert!(
        (from_file - reported).abs() <= 1e-6 * reported,
        "augmented.toml {from_file} vs report {reported}"
    );
}

/// `--effects 3` runs the iteration: two effects adopted, the third step stops it, the report
/// lists every step, and the files are those of the last adopted step.
#[test]
fn the_iteration_finds_two_effects_and_reports_every_step() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (est, val) = records(d);
    let nominal = d.join("nominal.toml");
    std::fs::write(&nominal, NOMINAL).unwrap();
    let out = d.join("out");
    let o = discover(&nominal, &est, &val, &out, &["--effects", "3"]);
    assert!(
        o.stdout.contains("step 1:") && o.stdout.contains("step 2:"),
        "{}",
        o.stdout
    );
    assert!(o.stdout.contains("stopped:"), "{}", o.stdout);
    let j = json(&out.join("report.json"));
    let effects = &j["effects"];
    assert_eq!(effects["effects_found"], 2, "{effects}");
    let steps = effects["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 3, "{effects}");
    assert_eq!(steps[2]["adopted"], false, "{effects}");
    let rms: Vec<f64> = effects["validation_rms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(rms[2] < rms[1] / 3.0 && rms[1] < rms[0], "{rms:?}");
    // The report's sections are the last adopted step's: its gap after is the last RMS.
    let after = j["finding"]["gap_after"]["validation"]["rms"]
        .as_f64()
        .unwrap();
    assert!(
        (after - rms[2]).abs() <= 1e-12 * rms[2],
        "{after} vs {rms:?}"
    );
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let section = md
        .find("Effects, one at a time")
        .expect("the steps section");
    let verdict = md.find("**Verdict").expect("verdict");
    assert!(section < verdict, "{md}");
    // The augmented model has both maps and reproduces the reported RMS.
    let path = out.join("augmented.toml");
    let mf = structid_io::ModelFile::from_path(&path).unwrap();
    assert_eq!(mf.blocks.len(), 2);
    let initial_state = j["augmented"]["initial_state"].as_str().unwrap();
    let from_file = validate(&path, &val, initial_state, &d.join("v"));
    assert!(
        (from_file - after).abs() <= 1e-6 * after,
        "augmented.toml {from_file} vs report {after}"
    );
}

/// Malformed nominal models with maps are input errors that say what is wrong.
#[test]
fn malformed_models_with_maps_are_input_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (est, val) = records(d);
    let out = d.join("out");
    let run = |model: &Path| {
        input_error(&[
            "discover",
            "--model",
            p(model),
            "--data",
            p(&est),
            "--validate",
            p(&val),
            "--out",
            p(&out),
        ])
    };
    let with_block = |block: &str| {
        format!(
            "[linear]\nstructure = \"input\"\nsample_time = 0.05\nden = [1.0, -1.5, 0.7]\n\
             num = [[0.0, 0.1, 0.1]]\n[signals]\nu = [\"u\"]\ny = [\"y\"]\n\n\
             [[nonlinearity]]\nname = \"N\"\ninputs = [0]\noutput = 0\n\
             dispersion = {{ kind = \"polynomial\", degree = 1 }}\n{block}"
        )
    };
    // A table truth whose file is missing.
    let missing = d.join("missing.toml");
    std::fs::write(
        &missing,
        with_block("truth = { table = \"N_table.csv\" }\n"),
    )
    .unwrap();
    let e = run(&missing);
    assert!(e.contains("N_table.csv"), "{e}");
    // A block without a truth: the map is not known.
    let unknown = d.join("unknown.toml");
    std::fs::write(&unknown, with_block("")).unwrap();
    let e = run(&unknown);
    assert!(e.contains("`N`") && e.contains("truth"), "{e}");
    // A truth that is not an expression of z0.
    let bad = d.join("bad.toml");
    std::fs::write(&bad, with_block("truth = \"tanh(x)\"\n")).unwrap();
    let e = run(&bad);
    assert!(e.contains("x"), "{e}");
    // --effects 0.
    let nominal = d.join("nominal.toml");
    std::fs::write(&nominal, NOMINAL).unwrap();
    let e = input_error(&[
        "discover",
        "--model",
        p(&nominal),
        "--data",
        p(&est),
        "--validate",
        p(&val),
        "--out",
        p(&out),
        "--effects",
        "0",
    ]);
    assert!(e.contains("--effects"), "{e}");
    assert!(!out.exists(), "nothing is written on an input error");
}

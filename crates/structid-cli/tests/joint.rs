//! `structid simulate` of a model with a hysteresis operator and a map in series, then
//! `structid refine --joint` from a wrong start; and the errors a user meets on the way.

mod common;

use std::path::Path;

use common::{csv_column, input_error, json, ok, p};

/// y = G·sat(play(u)) + e, the saturation reading the play's output through D_zw.
const TRUTH: &str = r#"[lft]
A = [[0.85]]
Bu = [[0.0]]
Be = [[0.0]]
Bw = [[0.0, 0.15]]
Cy = [[1.0]]
Dyu = [[0.0]]
Dye = [[1.0]]
Dyw = [[0.0, 0.0]]
Cz = [[0.0], [0.0]]
Dzu = [[1.0], [0.0]]
Dze = [[0.0], [0.0]]
Dzw = [[0.0, 0.0], [1.0, 0.0]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "backlash"
inputs = [0]
output = 0
operator = { kind = "play", half_width = 0.2 }

[[nonlinearity]]
name = "limit"
inputs = [1]
output = 1
truth = "0.8*tanh(z0/0.8)"
"#;

fn write_input(path: &Path, len: usize, phase: f64) {
    let mut text = String::from("u\n");
    for k in 0..len {
        let t = k as f64;
        let u =
            1.2 * ((0.011 * t + phase).sin() * (0.053 * t).cos() + 0.4 * (0.0071 * t + 1.0).sin());
        text.push_str(&format!("{u}\n"));
    }
    std::fs::write(path, text).unwrap();
}

/// Simulates the model `text` (written to `dir/<name>.toml`) on the input of `write_input(len,
/// phase)` with noise of standard deviation 0.005 and `seed`: the data file `dir/<name>.csv`.
fn simulated(
    dir: &Path,
    name: &str,
    text: &str,
    len: usize,
    phase: f64,
    seed: u64,
) -> std::path::PathBuf {
    let model = dir.join(format!("{name}.toml"));
    std::fs::write(&model, text).unwrap();
    let u = dir.join(format!("u_{name}.csv"));
    write_input(&u, len, phase);
    let data = dir.join(format!("{name}.csv"));
    let seed = seed.to_string();
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&data),
        "--noise-std",
        "0.005",
        "--seed",
        &seed,
    ]);
    data
}

#[test]
fn a_play_and_a_map_in_series_are_simulated_and_refined_jointly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = d.join("truth.toml");
    std::fs::write(&truth, TRUTH).unwrap();
    for (name, len, phase) in [("est", 3000, 0.0), ("val", 1500, 1.3)] {
        let u = d.join(format!("u_{name}.csv"));
        write_input(&u, len, phase);
        ok(&[
            "simulate",
            "--model",
            p(&truth),
            "--input",
            p(&u),
            "--out",
            p(&d.join(format!("{name}.csv"))),
            "--noise-std",
            "0.005",
            "--seed",
            "3",
        ]);
    }
    // The simulated w of the play follows the play's definition sample by sample.
    let sim = std::fs::read_to_string(d.join("est.csv")).unwrap();
    let mut b = 0.0f64;
    for (k, line) in sim.lines().skip(1).enumerate() {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let (u, w0) = (v[0], v[4]);
        b = if k == 0 {
            w0
        } else {
            b.max(u - 0.2).min(u + 0.2)
        };
        assert!((w0 - b).abs() < 1e-12, "play at {k}: {w0} vs {b}");
    }
    // Start: the pole and the play wrong, the map unknown.
    let start = d.join("start.toml");
    std::fs::write(
        &start,
        TRUTH
            .replace("A = [[0.85]]", "A = [[0.75]]")
            .replace("half_width = 0.2", "half_width = 0.05")
            .replace("truth = \"0.8*tanh(z0/0.8)\"\n", ""),
    )
    .unwrap();
    let out = d.join("fit");
    let o = ok(&[
        "refine",
        "--joint",
        "--model",
        p(&start),
        "--data",
        p(&d.join("est.csv")),
        "--validation-data",
        p(&d.join("val.csv")),
        "--free",
        "A",
        "--out",
        p(&out),
    ]);
    assert!(o.stdout.contains("joint fit of"), "{}", o.stdout);
    let j = json(&out.join("joint.json"));
    let pole = j["free"][0]["value"].as_f64().unwrap();
    assert!((pole - 0.85).abs() < 0.01, "pole {pole}");
    assert!(j["cost"].as_f64().unwrap() <= j["initial_cost"].as_f64().unwrap());
    assert_eq!(j["trials"].as_array().unwrap().len(), 9);
    assert!(j["rms"][0].as_f64().unwrap() < 1.5 * 0.005, "{}", j["rms"]);
    // The written model names the play with its fitted half-width and reads back.
    let written = std::fs::read_to_string(out.join("model.toml")).unwrap();
    let line = written.lines().find(|l| l.starts_with("operator")).unwrap();
    let c: f64 = line
        .split("half_width = ")
        .nth(1)
        .unwrap()
        .trim_end_matches(" }")
        .parse()
        .unwrap();
    assert!((c - 0.2).abs() < 0.02, "{line}");
    ok(&[
        "simulate",
        "--model",
        p(&out.join("model.toml")),
        "--input",
        p(&d.join("u_val.csv")),
        "--out",
        p(&d.join("again.csv")),
    ]);
    // `validate` scores it by its simulation from rest (it has an operator, so no one-step
    // prediction): the same simulation as `simulate`, an error at the noise level.
    let o = ok(&[
        "validate",
        "--model",
        p(&out.join("model.toml")),
        "--data",
        p(&d.join("val.csv")),
        "--out",
        p(&d.join("v")),
    ]);
    assert!(o.stdout.contains("no one-step prediction"), "{}", o.stdout);
    let v = json(&d.join("v").join("validation.json"));
    assert!(v["prediction"].is_null());
    let rms = v["outputs"][0]["simulation_rms"].as_f64().unwrap();
    let (y, again) = (
        csv_column(&d.join("val.csv"), "y"),
        csv_column(&d.join("again.csv"), "y"),
    );
    let direct = (y
        .iter()
        .zip(&again)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        / y.len() as f64)
        .sqrt();
    assert!((rms - direct).abs() <= 1e-9 * direct, "{rms} vs {direct}");
    assert!(rms < 1.5 * 0.005, "{rms}");
    // Over several records the simulation errors are pooled: the record twice pools to its
    // own RMS over twice its samples.
    ok(&[
        "validate",
        "--model",
        p(&out.join("model.toml")),
        "--data",
        p(&d.join("val.csv")),
        "--data",
        p(&d.join("val.csv")),
        "--out",
        p(&d.join("v2")),
    ]);
    let overall = &json(&d.join("v2").join("validation.json"))["overall"]["outputs"][0];
    let pooled = overall["rms"].as_f64().unwrap();
    assert!(
        (pooled - direct).abs() <= 1e-9 * direct,
        "{pooled} vs {direct}"
    );
    assert_eq!(overall["samples"].as_u64().unwrap() as usize, 2 * y.len());
}

#[test]
fn joint_errors_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let u = d.join("u.csv");
    write_input(&u, 200, 0.0);
    // An operator out of range, with the line of its declaration.
    let bad = d.join("bad.toml");
    std::fs::write(&bad, TRUTH.replace("half_width = 0.2", "half_width = -0.2")).unwrap();
    let e = input_error(&[
        "simulate",
        "--model",
        p(&bad),
        "--input",
        p(&u),
        "--out",
        p(&d.join("s.csv")),
    ]);
    assert!(e.contains("line 23") && e.contains("half_width"), "{e}");
    // A cycle of maps names both blocks.
    let cyc = d.join("cycle.toml");
    std::fs::write(
        &cyc,
        TRUTH.replace(
            "Dzw = [[0.0, 0.0], [1.0, 0.0]]",
            "Dzw = [[0.0, 0.5], [1.0, 0.0]]",
        ),
    )
    .unwrap();
    let e = input_error(&[
        "simulate",
        "--model",
        p(&cyc),
        "--input",
        p(&u),
        "--out",
        p(&d.join("s.csv")),
    ]);
    assert!(
        e.contains("algebraic loop") && e.contains("`backlash`") && e.contains("`limit`"),
        "{e}"
    );
    // identify refuses an operator and says what to use instead; --joint needs a β.
    let good = d.join("good.toml");
    std::fs::write(&good, TRUTH).unwrap();
    let data = d.join("data.csv");
    ok(&[
        "simulate",
        "--model",
        p(&good),
        "--input",
        p(&u),
        "--out",
        p(&data),
    ]);
    let e = input_error(&[
        "identify",
        "--model",
        p(&good),
        "--data",
        p(&data),
        "--out",
        p(&d.join("i")),
    ]);
    assert!(
        e.contains("maps in series") && e.contains("joint fit"),
        "{e}"
    );
    let play_only = d.join("play.toml");
    std::fs::write(
        &play_only,
        TRUTH
            .replace(
                "Dzw = [[0.0, 0.0], [1.0, 0.0]]",
                "Dzw = [[0.0, 0.0], [0.0, 0.0]]",
            )
            .replace("Dzu = [[1.0], [0.0]]", "Dzu = [[1.0], [1.0]]"),
    )
    .unwrap();
    let e = input_error(&[
        "identify",
        "--model",
        p(&play_only),
        "--data",
        p(&data),
        "--out",
        p(&d.join("i")),
    ]);
    assert!(
        e.contains("hysteresis operator") && e.contains("joint fit"),
        "{e}"
    );
    let e = input_error(&[
        "refine",
        "--joint",
        "--model",
        p(&good),
        "--data",
        p(&data),
        "--out",
        p(&d.join("r")),
    ]);
    assert!(e.contains("--beta"), "{e}");
    let e = input_error(&[
        "refine",
        "--joint",
        "--model",
        p(&good),
        "--data",
        p(&data),
        "--beta",
        "1e-6",
        "--free",
        "Q[0][0]",
        "--out",
        p(&d.join("r")),
    ]);
    assert!(e.contains("free entry `Q[0][0]`"), "{e}");
}

/// Two tanks with only the lower level measured: `identify` names the latent block and points
/// to the joint fit, which takes the same file.
#[test]
fn identify_names_a_latent_block_and_refine_joint_takes_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let model = d.join("tanks.toml");
    std::fs::write(
        &model,
        r#"[lft]
A = [[1.0, 0.0], [0.0, 1.0]]
Bu = [[0.05], [0.0]]
Be = [[0.0], [0.0]]
Bw = [[-0.05, 0.0], [0.05, -0.05]]
Cy = [[0.0, 1.0]]
Dyu = [[0.0]]
Dye = [[1.0]]
Dyw = [[0.0, 0.0]]
Cz = [[1.0, 0.0], [0.0, 1.0]]
Dzu = [[0.0], [0.0]]
Dze = [[0.0], [1.0]]
Dzw = [[0.0, 0.0], [0.0, 0.0]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "upper_outflow"
inputs = [0]
output = 0
truth = "sqrt(abs(z0))"

[[nonlinearity]]
name = "lower_outflow"
inputs = [1]
output = 1
truth = "sqrt(abs(z0))"
"#,
    )
    .unwrap();
    let u = d.join("u.csv");
    let mut text = String::from("u\n");
    for k in 0..1500 {
        let t = k as f64;
        text.push_str(&format!(
            "{}\n",
            1.0 + 0.6 * (0.013 * t).sin() + 0.3 * (0.041 * t).sin()
        ));
    }
    std::fs::write(&u, text).unwrap();
    let data = d.join("data.csv");
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&data),
        "--noise-std",
        "0.002",
        "--seed",
        "1",
    ]);
    let e = input_error(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&d.join("i")),
    ]);
    assert!(
        e.contains("block `upper_outflow` is latent") && e.contains("refine --joint"),
        "{e}"
    );
    assert!(!e.contains("block `lower_outflow`"), "{e}");
    let o = ok(&[
        "refine",
        "--joint",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--beta",
        "1e-8",
        "--out",
        p(&d.join("fit")),
    ]);
    assert!(o.stdout.contains("joint fit of"), "{}", o.stdout);
}

#[test]
fn maps_in_series_are_validated_with_their_one_step_prediction() {
    // The play replaced by a static dead zone: both blocks' inputs are then computable from u
    // once the upstream map is known, so `validate` predicts, evaluating the maps in order.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = TRUTH.replace(
        r#"operator = { kind = "play", half_width = 0.2 }"#,
        r#"truth = "max(z0 - 0.2, 0) + min(z0 + 0.2, 0)""#,
    );
    let data = simulated(d, "series", &text, 1500, 0.4, 5);
    let model = d.join("series.toml");
    let o = ok(&[
        "validate",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&d.join("v")),
    ]);
    assert!(o.stdout.contains("one-step prediction RMS"), "{}", o.stdout);
    let v = json(&d.join("v").join("validation.json"));
    let out = &v["outputs"][0];
    let (sim, pred) = (
        out["rms"].as_f64().unwrap(),
        out["prediction_rms"].as_f64().unwrap(),
    );
    // White output noise and a record at rest: the one-step predictor of the true model is its
    // simulation, and both leave the noise itself.
    assert!((sim - pred).abs() <= 1e-12 * sim, "{sim} vs {pred}");
    assert!((0.0045..0.0055).contains(&pred), "{pred}");
}

#[test]
fn a_named_family_is_fitted_with_the_play_and_g_and_written_back() {
    // The sensor law is a family s·tanh(z/s) with its level s unknown: `refine --joint` fits s
    // with the play's half-width and the pole, and writes the law back with the fitted s.
    let family = |s: f64| {
        TRUTH.replace(
            "truth = \"0.8*tanh(z0/0.8)\"",
            &format!("truth = \"s*tanh(z0/s)\"\nparameters = {{ s = {s} }}"),
        )
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = simulated(d, "est", &family(0.8), 3000, 0.0, 11);
    let u = d.join("u_est.csv");
    let start = d.join("start.toml");
    std::fs::write(
        &start,
        family(0.4)
            .replace("half_width = 0.2", "half_width = 0.05")
            .replace("A = [[0.85]]", "A = [[0.7]]"),
    )
    .unwrap();
    let out = d.join("fit");
    ok(&[
        "refine",
        "--joint",
        "--model",
        p(&start),
        "--data",
        p(&data),
        "--free",
        "A",
        "--beta",
        "1e-6",
        "--out",
        p(&out),
    ]);
    let j = json(&out.join("joint.json"));
    let pole = j["free"][0]["value"].as_f64().unwrap();
    assert!((pole - 0.85).abs() < 0.01, "pole {pole}");
    let written = std::fs::read_to_string(out.join("model.toml")).unwrap();
    let line = written
        .lines()
        .find(|l| l.starts_with("parameters"))
        .unwrap_or_else(|| panic!("{written}"));
    let s: f64 = line
        .split("{ s = ")
        .nth(1)
        .unwrap()
        .trim_end_matches(" }")
        .parse()
        .unwrap();
    assert!((s - 0.8).abs() < 0.03 * 0.8, "{line}");
    assert!(written.contains("truth = \"s*tanh(z0/s)\""), "{written}");
    assert!(!out.join("map_limit.csv").exists());
    ok(&[
        "simulate",
        "--model",
        p(&out.join("model.toml")),
        "--input",
        p(&u),
        "--out",
        p(&d.join("again.csv")),
    ]);
}

#[test]
fn a_fourier_dispersion_makes_the_joint_map_fourier_features() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = simulated(d, "est", TRUTH, 3000, 0.0, 12);
    let start = d.join("start.toml");
    std::fs::write(
        &start,
        TRUTH.replace(
            "truth = \"0.8*tanh(z0/0.8)\"",
            "dispersion = { kind = \"fourier\", sigma = 0.4, harmonics = 5 }",
        ),
    )
    .unwrap();
    let out = d.join("fit");
    let o = ok(&[
        "refine",
        "--joint",
        "--model",
        p(&start),
        "--data",
        p(&data),
        "--beta",
        "1e-8",
        "--out",
        p(&out),
    ]);
    // The play's half-width, 2·5 Fourier coefficients and an affine part (a Gaussian expansion
    // would have 15 + 2).
    assert!(o.stdout.contains("13 parameters"), "{}", o.stdout);
    let z = csv_column(&out.join("map_limit.csv"), "z1");
    let v = csv_column(&out.join("map_limit.csv"), "value");
    let err = z
        .iter()
        .zip(&v)
        .map(|(z, v)| (v - 0.8 * (z / 0.8).tanh()).powi(2))
        .sum::<f64>()
        / z.len() as f64;
    let range =
        v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min);
    assert!(
        err.sqrt() < 0.05 * range,
        "map error {} of range {range}",
        err.sqrt()
    );
}

#[test]
fn a_shaped_map_is_refined_then_validated_from_the_written_file() {
    // Both maps static and in series; the saturation declared increasing and started from
    // nothing. `refine --joint` keeps the shape in the file it writes, and `validate` of that
    // file runs (its maps are given, so there is nothing to constrain), with an error at the
    // noise level.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = TRUTH.replace(
        r#"operator = { kind = "play", half_width = 0.2 }"#,
        r#"truth = "max(z0 - 0.2, 0) + min(z0 + 0.2, 0)""#,
    );
    let data = simulated(d, "truth", &truth, 2000, 0.0, 3);
    let val = simulated(d, "val", &truth, 1000, 1.1, 4);
    let start = d.join("start.toml");
    std::fs::write(
        &start,
        truth.replace("truth = \"0.8*tanh(z0/0.8)\"", "shape = \"increasing\""),
    )
    .unwrap();
    let out = d.join("fit");
    ok(&[
        "refine",
        "--joint",
        "--model",
        p(&start),
        "--data",
        p(&data),
        "--beta",
        "1e-8",
        "--out",
        p(&out),
    ]);
    let written = std::fs::read_to_string(out.join("model.toml")).unwrap();
    assert!(written.contains("shape = \"increasing\""), "{written}");
    let limit = csv_column(&out.join("map_limit.csv"), "value");
    assert!(limit.windows(2).all(|w| w[1] >= w[0]));
    ok(&[
        "validate",
        "--model",
        p(&out.join("model.toml")),
        "--data",
        p(&val),
        "--out",
        p(&d.join("v")),
    ]);
    let v = json(&d.join("v").join("validation.json"));
    let rms = v["outputs"][0]["rms"].as_f64().unwrap();
    assert!(rms < 0.0075, "{rms}");
}

/// An integrating plant behind an unknown input map, y = (0.05·q⁻¹/(1 − q⁻¹))·tanh(u) + e:
/// its free run drifts, so it is fitted (`refine --joint --windows`) and scored
/// (`validate --scoring`) in the same windows, and the windowed fit reaches the noise.
#[test]
fn an_integrating_plant_is_fitted_by_its_windowed_score() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = "[lft]\nA = [[1.0]]\nBu = [[0.0]]\nBe = [[0.0]]\nBw = [[0.05]]\nCy = [[1.0]]\n\
                 Dyu = [[0.0]]\nDye = [[1.0]]\nDyw = [[0.0]]\nCz = [[0.0]]\nDzu = [[1.0]]\n\
                 Dze = [[0.0]]\nDzw = [[0.0]]\n\n[signals]\nu = [\"u\"]\ny = [\"y\"]\n\n\
                 [[nonlinearity]]\nname = \"N\"\ninputs = [0]\noutput = 0\n";
    let est = simulated(
        d,
        "est",
        &format!("{truth}truth = \"tanh(2*z0)\"\n"),
        2000,
        0.0,
        5,
    );
    let val = simulated(
        d,
        "val",
        &format!("{truth}truth = \"tanh(2*z0)\"\n"),
        1000,
        1.1,
        6,
    );
    let start = d.join("start.toml");
    std::fs::write(&start, truth).unwrap();
    let out = d.join("fit");
    let args = |extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = [
            "refine",
            "--joint",
            "--model",
            p(&start),
            "--data",
            p(&est),
            "--beta",
            "1e-8",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let run = args(&["--windows", "200:20", "--out", p(&out)]);
    ok(&run.iter().map(String::as_str).collect::<Vec<_>>());
    let j = json(&out.join("joint.json"));
    assert!(j["cost"].as_f64().unwrap() <= j["initial_cost"].as_f64().unwrap());
    assert!(j.to_string().contains("\"windows\""), "{j}");
    let scored = d.join("v");
    ok(&[
        "validate",
        "--model",
        p(&out.join("model.toml")),
        "--data",
        p(&val),
        "--scoring",
        "200:20",
        "--out",
        p(&scored),
    ]);
    let v = json(&scored.join("validation.json"));
    let rms = v["outputs"][0]["rms"].as_f64().unwrap();
    assert!(rms < 2.0 * 0.005, "windowed validation RMS {rms}");
    // Windows and segments are two criteria; a window needs LENGTH:INIT.
    let both = args(&[
        "--windows",
        "200:20",
        "--segment-length",
        "50",
        "--out",
        p(&d.join("b")),
    ]);
    let e = input_error(&both.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        e.contains("segment_length") && e.contains("windows") && !e.contains("required"),
        "{e}"
    );
    let bad = args(&["--windows", "200", "--out", p(&d.join("b"))]);
    let e = input_error(&bad.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(e.contains("LENGTH:INIT"), "{e}");
    // A setting the fit refuses is the user's input error too.
    let short = args(&["--segment-length", "1", "--out", p(&d.join("short"))]);
    let e = input_error(&short.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(e.contains("segment_length"), "{e}");
}

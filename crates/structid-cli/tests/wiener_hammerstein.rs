//! `structid wiener-hammerstein` on data that `structid simulate` generated from a known
//! Wiener–Hammerstein model: the division of the poles, the fit, and the written model
//! simulated again against the truth.

mod common;

use std::path::Path;

use common::{csv_column as column, input_error, json, ok, p};

/// x₁⁺ = 0.8x₁ + 0.2u, z = x₁, w = tanh(1.5z), x₂⁺ = 0.5x₂ + 0.5w, y = x₂ + e.
const TRUTH: &str = r#"[lft]
A = [[0.8, 0.0], [0.0, 0.5]]
Bu = [[0.2], [0.0]]
Be = [[0.0], [0.0]]
Bw = [[0.0], [0.5]]
Cy = [[0.0, 1.0]]
Dyu = [[0.0]]
Dye = [[1.0]]
Dyw = [[0.0]]
Cz = [[1.0, 0.0]]
Dzu = [[0.0]]
Dze = [[0.0]]
Dzw = [[0.0]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "N"
inputs = [0]
output = 0
truth = "tanh(1.5*z0)"
"#;

/// A random input (a xorshift sequence through a first-order low-pass), different per `seed`.
fn write_input(path: &Path, len: usize, seed: u64) {
    let mut state = 0x9E37_79B9_7F4A_7C15u64 ^ seed.wrapping_mul(0x2545_F491_4F6C_DD1D);
    let mut v = 0.0;
    let mut text = String::from("u\n");
    for _ in 0..len {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let r = (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
        v = 0.5 * v + r;
        text.push_str(&format!("{}\n", 1.2 * v));
    }
    std::fs::write(path, text).unwrap();
}

/// Writes `truth.toml` from `model` and simulates it into `est.csv` and `val.csv` (noise 0.005)
/// and the noise-free `clean.csv` (the validation input), from inputs drawn with `seeds`.
fn records(d: &Path, model: &str, seeds: [u64; 2]) {
    let truth = d.join("truth.toml");
    std::fs::write(&truth, model).unwrap();
    for (name, seed, noise) in [
        ("est", seeds[0], "0.005"),
        ("val", seeds[1], "0.005"),
        ("clean", seeds[1], "0"),
    ] {
        let u = d.join(format!("u_{name}.csv"));
        write_input(&u, 2000, seed);
        ok(&[
            "simulate",
            "--model",
            p(&truth),
            "--input",
            p(&u),
            "--out",
            p(&d.join(format!("{name}.csv"))),
            "--noise-std",
            noise,
            "--seed",
            "5",
        ]);
    }
}

#[test]
fn a_wiener_hammerstein_model_is_identified_with_both_blocks_unknown() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    records(d, TRUTH, [1, 2]);
    let out = d.join("wh");
    let o = ok(&[
        "wiener-hammerstein",
        "--data",
        p(&d.join("est.csv")),
        "--orders",
        "2,1,2",
        "--validation-data",
        p(&d.join("val.csv")),
        "--out",
        p(&out),
    ]);
    assert!(o.stdout.contains("4 divisions"), "{}", o.stdout);
    // The best division puts the pole 0.8 in front; the scores are sorted.
    let div = json(&out.join("divisions.json"));
    let divisions = div["divisions"].as_array().unwrap();
    assert_eq!(divisions.len(), 4);
    let front = divisions[0]["front"]["den"].as_array().unwrap();
    assert_eq!(front.len(), 2, "{div}");
    assert!((front[1].as_f64().unwrap() + 0.8).abs() < 0.05, "{div}");
    let rms: Vec<f64> = divisions
        .iter()
        .map(|d| d["rms"].as_f64().unwrap())
        .collect();
    assert!(rms.windows(2).all(|w| w[0] <= w[1]), "{rms:?}");
    let j = json(&out.join("joint.json"));
    assert!(j["rms"][0].as_f64().unwrap() < 1.5 * 0.005, "{j}");
    assert_eq!(j["trials"].as_array().unwrap().len(), 9);
    // The written model, simulated on the validation input, follows the noise-free truth.
    ok(&[
        "simulate",
        "--model",
        p(&out.join("model.toml")),
        "--input",
        p(&d.join("u_val.csv")),
        "--out",
        p(&d.join("again.csv")),
    ]);
    let (a, b) = (
        column(&d.join("again.csv"), "y"),
        column(&d.join("clean.csv"), "y"),
    );
    let err = (a.iter().zip(&b).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
    assert!(err < 0.005, "simulation error against the truth {err}");
}

#[test]
fn wiener_hammerstein_errors_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let u = d.join("u.csv");
    write_input(&u, 300, 3);
    let e = input_error(&[
        "wiener-hammerstein",
        "--data",
        p(&u),
        "--orders",
        "2,1",
        "--out",
        p(&d.join("o")),
    ]);
    assert!(e.contains("NA,NB,NK"), "{e}");
    // No output column in the file.
    let e = input_error(&[
        "wiener-hammerstein",
        "--data",
        p(&u),
        "--orders",
        "2,1,1",
        "--out",
        p(&d.join("o")),
    ]);
    assert!(e.contains('y'), "{e}");
    // A NaN in the data is named with its place.
    std::fs::write(d.join("nan.csv"), "u,y\n1,2\nnan,3\n0.5,1\n").unwrap();
    let e = input_error(&[
        "wiener-hammerstein",
        "--data",
        p(&d.join("nan.csv")),
        "--orders",
        "2,1,1",
        "--out",
        p(&d.join("o")),
    ]);
    assert!(
        e.to_lowercase().contains("nan") || e.contains("finite"),
        "{e}"
    );
}

/// w₁ = tanh(1.2u), x⁺ = 0.7x + 0.3w₁, w₂ = 0.8·tanh(x/0.8) + 0.2x, y = w₂ + e.
const HW_TRUTH: &str = r#"[lft]
A = [[0.7]]
Bu = [[0.0]]
Be = [[0.0]]
Bw = [[0.3, 0.0]]
Cy = [[0.0]]
Dyu = [[0.0]]
Dye = [[1.0]]
Dyw = [[0.0, 1.0]]
Cz = [[0.0], [1.0]]
Dzu = [[1.0], [0.0]]
Dze = [[0.0], [0.0]]
Dzw = [[0.0, 0.0], [0.0, 0.0]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "input"
inputs = [0]
output = 0
truth = "tanh(1.2*z0)"

[[nonlinearity]]
name = "output"
inputs = [1]
output = 1
truth = "0.8*tanh(z0/0.8) + 0.2*z0"
"#;

#[test]
fn a_hammerstein_wiener_model_is_identified_with_every_block_unknown() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    records(d, HW_TRUTH, [11, 12]);
    let out = d.join("hw");
    ok(&[
        "hammerstein-wiener",
        "--data",
        p(&d.join("est.csv")),
        "--orders",
        "1,1,1",
        "--out",
        p(&out),
    ]);
    let j = json(&out.join("joint.json"));
    assert!(j["rms"][0].as_f64().unwrap() < 1.5 * 0.005, "{j}");
    assert!(
        json(&out.join("divisions.json"))["divisions"]
            .as_array()
            .unwrap()
            .is_empty()
    );
    ok(&[
        "simulate",
        "--model",
        p(&out.join("model.toml")),
        "--input",
        p(&d.join("u_val.csv")),
        "--out",
        p(&d.join("again.csv")),
    ]);
    let (a, b) = (
        column(&d.join("again.csv"), "y"),
        column(&d.join("clean.csv"), "y"),
    );
    let err = (a.iter().zip(&b).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
    assert!(err < 0.005, "simulation error against the truth {err}");
    // The written model has both maps in it, and `validate` scores it by simulation.
    let o = ok(&[
        "validate",
        "--model",
        p(&out.join("model.toml")),
        "--data",
        p(&d.join("val.csv")),
        "--out",
        p(&d.join("v")),
    ]);
    assert!(o.stdout.contains("simulation RMS"), "{}", o.stdout);
}

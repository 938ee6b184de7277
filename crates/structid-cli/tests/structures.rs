//! End to end with the `[linear]` structures whose z is computed, never measured: a sensor map
//! (`structure = "output"`, z = G·u) and rate feedback (`structure = "rate-feedback"`,
//! z = Δy/T_s, a dynamic Ψ_M): `simulate`, then `identify` on data without z columns,
//! `validate` with the true maps, and `refine`, which re-estimates G in them.

mod common;

use std::path::Path;

use common::{ok, p};

/// G = (0.3q⁻¹ + 0.2q⁻²)/(1 − 1.2q⁻¹ + 0.5q⁻²), T_s = 0.1, with the map N at `structure`.
fn model(structure: &str, truth: &str) -> String {
    format!(
        r#"[linear]
structure = "{structure}"
sample_time = 0.1
den = [1.0, -1.2, 0.5]
num = [[0.0, 0.3, 0.2]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "N"
inputs = [0]
output = 0
dispersion = {{ kind = "polynomial", degree = 3, scale = 100.0 }}
truth = "{truth}"
"#
    )
}

/// Low-pass filtered pseudo-random input: s_k = 0.5·s_(k−1) + a·r_k with r uniform on [−1, 1].
fn write_input(path: &Path, len: usize, amplitude: f64, seed: u64) {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut s = 0.0;
    let mut text = String::from("u\n");
    for _ in 0..len {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let r = ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
        s = 0.5 * s + amplitude * r;
        text.push_str(&format!("{s}\n"));
    }
    std::fs::write(path, text).unwrap();
}

/// Keeps only the columns `keep` of a CSV file.
fn keep_columns(path: &Path, keep: &[&str]) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let idx: Vec<usize> = keep
        .iter()
        .map(|k| header.iter().position(|h| h == k).unwrap())
        .collect();
    let mut out = keep.join(",") + "\n";
    for l in lines {
        let f: Vec<&str> = l.split(',').collect();
        out.push_str(&idx.iter().map(|&i| f[i]).collect::<Vec<_>>().join(","));
        out.push('\n');
    }
    std::fs::write(path, out).unwrap();
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn rate_feedback_and_sensor_models_identify_without_z_columns() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (structure, truth, amplitude, z_source) in [
        // ẏ = Δy/T_s is ten times Δy: a gentle friction keeps the loop stable.
        ("rate-feedback", "0.02*z0 + 0.002*z0^3", 0.3, "Ψ(q)"),
        ("output", "0.5*z0 + 0.3*z0^3", 1.0, "z = L_zu·u"),
    ] {
        let m = d.join(format!("{structure}.toml"));
        std::fs::write(&m, model(structure, truth)).unwrap();
        let (u, data) = (
            d.join(format!("u_{structure}.csv")),
            d.join(format!("d_{structure}.csv")),
        );
        write_input(&u, 1500, amplitude, 3);
        ok(&[
            "simulate",
            "--model",
            p(&m),
            "--input",
            p(&u),
            "--out",
            p(&data),
            "--noise-std",
            "0.001",
        ]);
        // The record has no z column: z must be computed from u and y.
        keep_columns(&data, &["u", "y"]);
        let out = d.join(format!("id_{structure}"));
        let o = ok(&[
            "identify",
            "--model",
            p(&m),
            "--data",
            p(&data),
            "--out",
            p(&out),
            "--beta",
            "1e-9",
        ]);
        let report = json(&out.join("report.json"));
        let zs = report["diagnostics"]["z_source"].as_str().unwrap();
        assert!(zs.contains(z_source), "{structure}: z source `{zs}`");
        assert!(o.stdout.contains(z_source), "{structure}:\n{}", o.stdout);
        // The map comes back: its error against the truth is small next to its range.
        let rows: Vec<Vec<f64>> = std::fs::read_to_string(out.join("map_N.csv"))
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        let range = rows.iter().map(|r| r[1]).fold(f64::NEG_INFINITY, f64::max)
            - rows.iter().map(|r| r[1]).fold(f64::INFINITY, f64::min);
        let rms = report["blocks"][0]["rms_error_vs_truth"].as_f64().unwrap();
        assert!(
            rms < 0.02 * range,
            "{structure}: RMS error {rms} against a range of {range}"
        );

        // The true maps validate on the record they simulated (noise std 0.001).
        let vout = d.join(format!("val_{structure}"));
        ok(&[
            "validate",
            "--model",
            p(&m),
            "--data",
            p(&data),
            "--out",
            p(&vout),
        ]);
        let v = json(&vout.join("validation.json"));
        assert_eq!(v["maps"], "truth");
        let fit = v["outputs"][0]["fit_percent"].as_f64().unwrap();
        assert!(fit > 99.0, "{structure}: fit {fit} %");

        // Refinement re-estimates G in these structures too, and writes them back as they
        // were; from the true G it has nothing to gain, and J does not increase.
        let rout = d.join(format!("refined_{structure}"));
        ok(&[
            "refine",
            "--model",
            p(&m),
            "--data",
            p(&data),
            "--beta",
            "1e-9",
            "--iterations",
            "3",
            "--out",
            p(&rout),
        ]);
        let text = std::fs::read_to_string(rout.join("model.toml")).unwrap();
        assert!(
            text.contains(&format!("structure = \"{structure}\"")),
            "{structure}: {text}"
        );
        let r = json(&rout.join("report.json"));
        let its = r["refinement"]["iterations"].as_array().unwrap();
        for (k, it) in its.iter().enumerate() {
            if let (Some(after), Some(next)) = (it["cost_after_linear"].as_f64(), its.get(k + 1)) {
                let before = it["cost_after_maps"].as_f64().unwrap();
                assert!(after <= before * (1.0 + 1e-9), "{structure}: {r}");
                let again = next["cost_after_maps"].as_f64().unwrap();
                assert!(again <= after * (1.0 + 1e-9), "{structure}: {r}");
            }
        }
    }
}

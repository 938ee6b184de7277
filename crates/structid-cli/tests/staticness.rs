//! `structid static`: the paper's Example 1 (Hsu et al. 2006). One input drives an atan, a
//! first-order filter and a backlash (simulated here by their difference equations); the
//! command must call the atan static, the others not, and rank them as the paper does.

mod common;

use std::path::Path;

use common::{input_error, ok, p};

const SAMPLES: usize = 2000;
const NOISE: f64 = 0.02;

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

/// A CSV file with columns z, atan, lti, backlash (each with white noise of std NOISE).
fn write_record(path: &Path) {
    let mut n = normals(3);
    let z: Vec<f64> = (0..SAMPLES)
        .map(|k| 2.0 * (0.013 * k as f64).sin() + 0.6 * (0.041 * k as f64).sin())
        .collect();
    let mut lti = vec![0.0; SAMPLES];
    let mut play = vec![0.0; SAMPLES];
    for k in 1..SAMPLES {
        lti[k] = 0.9 * lti[k - 1] + 0.1 * z[k - 1];
        let d = z[k] - play[k - 1];
        play[k] = if d > 0.4 {
            z[k] - 0.4
        } else if d < -0.4 {
            z[k] + 0.4
        } else {
            play[k - 1]
        };
    }
    let mut text = String::from("z,atan,lti,backlash\n");
    for k in 0..SAMPLES {
        text += &format!(
            "{},{},{},{}\n",
            z[k],
            z[k].atan() + NOISE * n(),
            lti[k] + NOISE * n(),
            play[k] + NOISE * n()
        );
    }
    std::fs::write(path, text).unwrap();
}

fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

#[test]
fn example_1_atan_is_static_filter_and_backlash_are_not() {
    let t = tempfile::tempdir().unwrap();
    let data = t.path().join("d.csv");
    write_record(&data);
    let mut ratios = Vec::new();
    for (w, verdict) in [
        ("atan", "static"),
        ("lti", ""),
        ("backlash", "direction_dependent"),
    ] {
        let out = t.path().join(w);
        let o = ok(&[
            "static",
            "--data",
            p(&data),
            "--z",
            "z",
            "--w",
            w,
            "--out",
            p(&out),
        ]);
        let r = report(&out);
        let v = r["result"]["verdict"].as_str().unwrap();
        if verdict.is_empty() {
            assert_ne!(v, "static", "{w}: {}", o.stdout);
        } else {
            assert_eq!(v, verdict, "{w}: {}", o.stdout);
        }
        assert!(o.stdout.contains("verdict: "), "{}", o.stdout);
        assert_eq!(
            o.stdout.contains("verdict: static"),
            verdict == "static",
            "{}",
            o.stdout
        );
        // The noise estimated without a model is the noise that was added.
        let noise = r["result"]["noise_variance"].as_f64().unwrap().sqrt();
        if w == "atan" {
            assert!((noise / NOISE - 1.0).abs() < 0.2, "{noise}");
        }
        ratios.push(r["result"]["unexplained_ratio"].as_f64().unwrap());
        // The figure: the scatter (dots) and the fitted map (one line), well-formed.
        let svg = std::fs::read_to_string(out.join("static.svg")).unwrap();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(
            svg.matches("<circle").count() >= 1000,
            "the scatter is drawn"
        );
        assert!(svg.contains("best static map"));
    }
    // The paper's ranking: the atan clearly the most static.
    assert!(ratios[0] < 1.5, "{ratios:?}");
    assert!(
        ratios[1] > 10.0 * ratios[0] && ratios[2] > 10.0 * ratios[0],
        "{ratios:?}"
    );
}

#[test]
fn without_out_nothing_is_written_and_bad_input_is_readable() {
    let t = tempfile::tempdir().unwrap();
    let data = t.path().join("d.csv");
    write_record(&data);
    let o = ok(&[
        "static",
        "--data",
        p(&data),
        "--z",
        "z",
        "--w",
        "atan",
        "--noise-std",
        "0.02",
    ]);
    assert!(o.stdout.contains("(given)"), "{}", o.stdout);
    assert_eq!(std::fs::read_dir(t.path()).unwrap().count(), 1);
    let e = input_error(&["static", "--data", p(&data), "--z", "z", "--w", "nope"]);
    assert!(e.contains("nope"), "{e}");
    let e = input_error(&[
        "static",
        "--data",
        p(&data),
        "--z",
        "z",
        "--w",
        "atan",
        "--noise-std",
        "-1",
    ]);
    assert!(e.contains("noise std"), "{e}");
    let short = t.path().join("short.csv");
    std::fs::write(&short, "z,w\n1,2\n2,3\n3,4\n").unwrap();
    let e = input_error(&["static", "--data", p(&short), "--z", "z", "--w", "w"]);
    assert!(e.contains("too few"), "{e}");
    // The data file is never an output.
    let e = input_error(&[
        "static",
        "--data",
        p(&data),
        "--z",
        "z",
        "--w",
        "atan",
        "--out",
        p(&data),
    ]);
    assert!(!e.is_empty());
}

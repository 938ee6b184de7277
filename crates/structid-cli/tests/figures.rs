//! The figures of `linear`, `refine`, `validate` and `identify`: the panels they must show,
//! well-formed SVG, and a bounded size for long records.

mod common;

use std::path::Path;

use common::{example_model, ok, p};

/// A reproducible uniform input on [−1, 1] (a small LCG).
fn write_input(path: &Path, len: usize, seed: u64) {
    let mut state: u64 = 0x2545_f491_4f6c_dd1d ^ seed;
    let mut s = String::from("u\n");
    for _ in 0..len {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        s.push_str(&format!(
            "{}\n",
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        ));
    }
    std::fs::write(path, s).unwrap();
}

/// The hammerstein example simulated on `len` samples of a fresh input, with noise.
fn record(dir: &Path, len: usize) -> (std::path::PathBuf, std::path::PathBuf) {
    let model = dir.join("model.toml");
    std::fs::write(
        &model,
        std::fs::read_to_string(example_model("hammerstein.toml")).unwrap(),
    )
    .unwrap();
    let (u, data) = (dir.join("u.csv"), dir.join("data.csv"));
    write_input(&u, len, 5);
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&data),
        "--noise-std",
        "0.01",
    ]);
    (model, data)
}

fn svg(path: &Path) -> String {
    let s = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        s.starts_with("<svg") && s.trim_end().ends_with("</svg>"),
        "{}",
        path.display()
    );
    assert_eq!(s.matches("<svg").count(), s.matches("</svg>").count());
    s
}

/// Whether the SVG has a `<text>` element with exactly this content.
fn has_text(svg: &str, t: &str) -> bool {
    svg.lines().any(|l| l == t)
}

#[test]
fn linear_and_refine_draw_bode_step_and_pole_zero_panels() {
    let dir = tempfile::tempdir().unwrap();
    let (_, data) = record(dir.path(), 800);
    // Output error: the fit has a parameter covariance, drawn as a ±2σ band.
    let lin = dir.path().join("lin.toml");
    let o = ok(&[
        "linear",
        "--data",
        p(&data),
        "--orders",
        "2,2,1",
        "--structure",
        "input",
        "--dispersion",
        "polynomial",
        "--trend",
        "3",
        "--out",
        p(&lin),
    ]);
    assert!(o.stdout.contains("lin.svg"), "{}", o.stdout);
    let s = svg(&dir.path().join("lin.svg"));
    for t in [
        "Bode magnitude",
        "Bode phase",
        "Step response",
        "Poles and zeros",
        "poles",
        "±2σ (u)",
    ] {
        assert!(has_text(&s, t), "missing {t}");
    }
    assert!(s.contains("<polygon"), "the band is drawn");
    // Magnitude, phase, step and the unit circle at least.
    assert!(s.matches("<polyline").count() >= 4);

    // Refinement keeps no covariance of G: the same panels, no band.
    let out = dir.path().join("refined");
    let o = ok(&[
        "refine",
        "--model",
        p(&lin),
        "--data",
        p(&data),
        "--out",
        p(&out),
    ]);
    let s = svg(&out.join("linear.svg"));
    for t in [
        "Bode magnitude",
        "Bode phase",
        "Step response",
        "Poles and zeros",
    ] {
        assert!(has_text(&s, t), "missing {t}");
    }
    assert!(!s.contains("±2σ") && !s.contains("<polygon"));
    assert!(o.stdout.contains("linear.svg"), "{}", o.stdout);
}

/// 10⁵ samples: the simulation figure has the error panel under the simulation and stays
/// small (every line thinned to the envelope of about 1000 pixel columns).
#[test]
fn validate_draws_the_error_under_the_simulation_of_a_long_record() {
    let dir = tempfile::tempdir().unwrap();
    let n = 100_000;
    let (model, data) = record(dir.path(), n);
    let out = dir.path().join("validation");
    ok(&[
        "validate",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&out),
    ]);
    let s = svg(&out.join("simulation.svg"));
    assert!(has_text(&s, "y: simulation error"), "the error panel");
    assert!(
        s.lines()
            .any(|l| l.starts_with("y: measured and simulated"))
    );
    // Two series in the first panel, one in the second (a line may break into pieces, never
    // more than the thinned points).
    let lines = s.matches("<polyline").count();
    assert!(lines >= 3, "{lines}");
    assert!(s.len() < 400_000, "{} bytes for {n} samples", s.len());
}

#[test]
fn identify_maps_show_the_partial_residuals() {
    let dir = tempfile::tempdir().unwrap();
    let (model, data) = record(dir.path(), 400);
    let out = dir.path().join("est");
    ok(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--beta",
        "0.01",
        "--out",
        p(&out),
    ]);
    let s = svg(&out.join("map_N.svg"));
    for t in ["partial residuals ŵ + r", "estimate", "95 % band", "truth"] {
        assert!(has_text(&s, t), "missing {t}");
    }
    assert!(s.matches("<circle").count() >= 400, "one dot per sample");
}

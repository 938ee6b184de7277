//! `structid linear --integrators`: an integrating axis fitted with its integrator fixed.

mod common;

use common::*;
use structid_io::ModelFile;

fn p(path: &std::path::Path) -> &str {
    path.to_str().unwrap()
}

/// Deterministic standard normal samples (xorshift64* and Box–Muller), so that the test needs
/// no random-number crate.
fn normals(seed: u64, n: usize) -> Vec<f64> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut uniform = move || {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        ((s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let (a, b) = (uniform(), uniform());
            (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
        })
        .collect()
}

/// The axis `1/(s(2s + 4))` sampled at 0.01 s by its exact zero-order-hold discretisation
/// (closed form, `a = F/M = 2`, `p = e^{−a·ts}`), driven by a force held for 25 samples, with
/// white position noise of 2 % of the output spread. Returns the CSV text and `p`.
fn axis_csv() -> (String, f64) {
    let (m, a, ts) = (2.0, 2.0, 0.01);
    let p = f64::exp(-a * ts);
    let b0 = (ts / a + (p - 1.0) / (a * a)) / m;
    let b1 = -(p * ts / a + (p - 1.0) / (a * a)) / m;
    let n = 4000;
    let levels = normals(7, n / 25 + 1);
    let u: Vec<f64> = (0..n).map(|k| levels[k / 25]).collect();
    let mut y = vec![0.0; n];
    for k in 2..n {
        y[k] = (1.0 + p) * y[k - 1] - p * y[k - 2] + b0 * u[k - 1] + b1 * u[k - 2];
    }
    let mean = y.iter().sum::<f64>() / n as f64;
    let spread = (y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    let e = normals(8, n);
    let mut text = String::from("u,y\n");
    for k in 0..n {
        text.push_str(&format!("{},{}\n", u[k], y[k] + 0.02 * spread * e[k]));
    }
    (text, p)
}

/// The fit per cent printed on the "fitted by" line.
fn printed_fit(stdout: &str) -> f64 {
    let line = stdout.lines().find(|l| l.starts_with("fitted by")).unwrap();
    let after = line.split("simulation fit on the data ").nth(1).unwrap();
    after.split(' ').next().unwrap().parse().unwrap()
}

#[test]
fn a_fixed_integrator_fits_an_integrating_axis() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = d.join("axis.csv");
    let (csv, pole) = axis_csv();
    std::fs::write(&data, csv).unwrap();
    let out = d.join("g.toml");
    let o = ok(&[
        "linear",
        "--data",
        p(&data),
        "--orders",
        "1,2,1",
        "--integrators",
        "1",
        "--sample-time",
        "0.01",
        "--out",
        p(&out),
    ]);
    assert!(
        o.stdout.contains("marginally stable (1 integrator)"),
        "{}",
        o.stdout
    );
    assert!(!o.stdout.contains("UNSTABLE") && !o.stdout.contains("warning"));
    assert!(o.stdout.contains("1 integrator at z = 1"), "{}", o.stdout);
    assert!(printed_fit(&o.stdout) > 80.0, "{}", o.stdout);
    // the written model has the root at 1 exactly and the other pole within 2 %
    let mf = ModelFile::parse(&std::fs::read_to_string(&out).unwrap(), None).unwrap();
    let den = mf.linear.unwrap().model.den;
    assert_eq!(den.len(), 3);
    assert!(den.iter().sum::<f64>().abs() < 1e-12, "{den:?}");
    let other = den[2] / den[0];
    assert!((other - pole).abs() < 0.02 * pole, "{other} vs {pole}");

    // the same fit with ARX has the integrator too
    let o = ok(&[
        "linear",
        "--data",
        p(&data),
        "--orders",
        "1,2,1",
        "--integrators",
        "1",
        "--method",
        "arx",
        "--out",
        p(&d.join("arx.toml")),
    ]);
    assert!(
        o.stdout.contains("marginally stable (1 integrator)"),
        "{}",
        o.stdout
    );

    // out-of-range counts are input errors
    let e = input_error(&[
        "linear",
        "--data",
        p(&data),
        "--integrators",
        "3",
        "--out",
        p(&d.join("bad.toml")),
    ]);
    assert!(e.contains("--integrators"), "{e}");
}

/// A stable lag `0.1 q⁻¹/(1 − 0.9 q⁻¹)` (no integrator) driven like the axis, small noise.
fn lag_csv() -> String {
    let n = 3000;
    let levels = normals(17, n / 25 + 1);
    let e = normals(18, n);
    let mut y = 0.0;
    let mut text = String::from("u,y\n");
    let mut u_prev = 0.0;
    for k in 0..n {
        let u = levels[k / 25];
        y = 0.9 * y + 0.1 * u_prev;
        u_prev = u;
        text.push_str(&format!("{u},{}\n", y + 1e-3 * e[k]));
    }
    text
}

#[test]
fn an_integrator_that_the_data_do_not_show_is_warned_about_by_both_methods() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = d.join("lag.csv");
    std::fs::write(&data, lag_csv()).unwrap();
    for method in ["oe", "arx"] {
        let o = ok(&[
            "linear",
            "--data",
            p(&data),
            "--orders",
            "1,2,1",
            "--integrators",
            "1",
            "--method",
            method,
            "--out",
            p(&d.join(format!("{method}.toml"))),
        ]);
        assert!(
            o.stdout
                .contains("warning: a zero of the fitted numerator cancels the fixed integrator"),
            "{method}: {}",
            o.stdout
        );
    }
}

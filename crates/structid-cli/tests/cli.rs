//! End-to-end tests of the `structid` binary.

use std::path::Path;

mod common;
use common::*;

/// A reproducible uniform input on [−2, 2] (a small LCG, so the test needs no RNG crate).
fn write_input(path: &Path, len: usize, columns: &[&str]) {
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 2.0
    };
    let mut s = columns.join(",");
    s.push('\n');
    for _ in 0..len {
        let row: Vec<String> = columns.iter().map(|_| next().to_string()).collect();
        s.push_str(&row.join(","));
        s.push('\n');
    }
    std::fs::write(path, s).unwrap();
}

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap()).collect())
        .collect();
    (header, rows)
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn assert_svg(path: &Path) {
    let s = std::fs::read_to_string(path).unwrap();
    assert!(s.starts_with("<svg"), "{} is not an SVG", path.display());
}

#[test]
fn simulate_then_identify_the_hammerstein_example() {
    let dir = tempfile::tempdir().unwrap();
    let model = example_model("hammerstein.toml");
    let u = dir.path().join("u.csv");
    let data = dir.path().join("data.csv");
    let out = dir.path().join("result");
    let len = 800;
    write_input(&u, len, &["u"]);
    let o = ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&data),
        "--noise-std",
        "0.05",
        "--seed",
        "7",
    ]);
    assert!(o.stdout.contains("800 samples"), "{}", o.stdout);
    let (header, rows) = read_csv(&data);
    assert_eq!(header, ["u", "y", "z0", "w_N"]);
    assert_eq!(rows.len(), len);
    // z = u and w = tanh(2z) for the Hammerstein model.
    for r in &rows {
        assert_eq!(r[0], r[2]);
        assert!((r[3] - (2.0 * r[2]).tanh()).abs() < 1e-12);
    }

    let o = ok(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&out),
    ]);
    assert!(o.stdout.contains("RMS error vs truth"), "{}", o.stdout);
    assert!(o.stdout.contains("report.json"), "{}", o.stdout);
    let (header, rows) = read_csv(&out.join("estimate.csv"));
    assert_eq!(header, ["N", "e0"]);
    assert_eq!(rows.len(), len);
    let (header, rows) = read_csv(&out.join("map_N.csv"));
    assert_eq!(header, ["z0", "value", "std"]);
    assert_eq!(rows.len(), 201);
    assert!(rows.windows(2).all(|w| w[1][0] > w[0][0]));
    // The posterior standard deviation: positive, and well below the map's range here.
    assert!(rows.iter().all(|r| r[2] > 0.0 && r[2] < 0.2), "{rows:?}");
    assert_svg(&out.join("map_N.svg"));
    let svg = std::fs::read_to_string(out.join("map_N.svg")).unwrap();
    assert!(svg.contains("95 % band"));
    assert!(
        o.stdout.contains("uncertainty: noise variance"),
        "{}",
        o.stdout
    );
    let report = read_json(&out.join("report.json"));
    assert_eq!(report["blocks"][0]["band"], true);
    let s2 = report["blocks"][0]["noise_variance"].as_f64().unwrap();
    // ŝ² = L·Ĵ/n with n = L live samples: the profiled marginal likelihood at the β used (here
    // larger than the β that fits a noise std of 0.05, so ŝ² exceeds 0.05²).
    let j = report["cost"]["total"].as_f64().unwrap();
    assert!((s2 - j).abs() < 1e-9 * j, "ŝ² = {s2}, J = {j}");
    // The map file, std column included, is a valid lookup table for `truth = { table = … }`.
    let table_model = dir.path().join("table.toml");
    let text = std::fs::read_to_string(&model).unwrap();
    let text = text
        .lines()
        .map(|l| {
            if l.trim_start().starts_with("truth") {
                format!(
                    "truth = {{ table = \"{}\" }}",
                    out.join("map_N.csv").display()
                )
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(&table_model, text).unwrap();
    structid_io::ModelFile::from_path(&table_model).unwrap();
    assert_eq!(report["samples"], len);
    assert_eq!(report["settings"]["beta"], 0.01);
    assert_eq!(report["settings"]["blocks"][0]["parameters"]["sigma"], 0.3);
    let b = &report["blocks"][0];
    assert_eq!(b["name"], "N");
    assert_eq!(b["grid_file"], "map_N.csv");
    // The noise std is 0.05 and tanh(2z) spans [−1, 1]: the observed error is about 0.03.
    let rms = b["rms_error_vs_truth"].as_f64().unwrap();
    assert!(rms < 0.06, "RMS error vs truth {rms}");
    assert!(
        report["diagnostics"]["feasibility_residual"]
            .as_f64()
            .unwrap()
            < 1e-9
    );
    assert!(
        report["diagnostics"]["z_source"]
            .as_str()
            .unwrap()
            .contains("L_zu")
    );
    assert!(report["cost"]["total"].as_f64().unwrap() > 0.0);

    // Re-running into the same directory replaces the results; --sigma and --beta are recorded.
    ok(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&out),
        "--sigma",
        "0.5",
        "--beta",
        "0.001",
    ]);
    let report = read_json(&out.join("report.json"));
    assert_eq!(report["settings"]["sigma_override"], 0.5);
    assert_eq!(report["settings"]["blocks"][0]["sigma_source"], "override");
    assert_eq!(report["settings"]["beta"], 0.001);
}

#[test]
fn wiener_example_uses_the_default_sigma() {
    let dir = tempfile::tempdir().unwrap();
    let model = example_model("wiener.toml");
    let (u, data, out) = (
        dir.path().join("u.csv"),
        dir.path().join("d.csv"),
        dir.path().join("out"),
    );
    write_input(&u, 600, &["u"]);
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&data),
        "--noise-std",
        "0.05",
    ]);
    ok(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&out),
    ]);
    let report = read_json(&out.join("report.json"));
    let s = &report["settings"]["blocks"][0];
    assert!(s["sigma_source"].as_str().unwrap().starts_with("default"));
    let range = &report["blocks"][0]["z_range"][0];
    let width = range[1].as_f64().unwrap() - range[0].as_f64().unwrap();
    assert!((s["parameters"]["sigma"].as_f64().unwrap() - 0.1 * width).abs() < 1e-12);
    assert!(report["blocks"][0]["rms_error_vs_truth"].as_f64().unwrap() < 0.08);
}

#[test]
fn demo_spray_output_can_be_identified_again() {
    let dir = tempfile::tempdir().unwrap();
    let demo = dir.path().join("spray");
    let o = ok(&["demo", "spray", "--samples", "600", "--out", p(&demo)]);
    assert!(
        o.stdout.contains("0.001") && o.stdout.contains("fig4.svg"),
        "{}",
        o.stdout
    );
    for f in ["data.csv", "model.toml", "fig4.svg", "summary.json"] {
        assert!(demo.join(f).is_file(), "{f} missing");
    }
    assert_svg(&demo.join("fig4.svg"));
    // examples/models/spray.toml is the demo's model file.
    let shipped = structid_io::ModelFile::from_path(&example_model("spray.toml")).unwrap();
    let written = structid_io::ModelFile::from_path(&demo.join("model.toml")).unwrap();
    assert_eq!(
        (shipped.lft, shipped.blocks, shipped.signals),
        (written.lft, written.blocks, written.signals)
    );
    let model = std::fs::read_to_string(demo.join("model.toml")).unwrap();
    assert!(model.contains("truth = \"-abs(z0)\""), "{model}");
    assert!(
        model.contains("truth = \"0.5*(sin((3*z0)^2) + (2*z0)^2 - 2)\""),
        "{model}"
    );
    let summary = read_json(&demo.join("summary.json"));
    let results = summary["results"].as_array().unwrap();
    assert_eq!(results.len(), 3);
    // The noise (std 1) is large against the maps (centred std ≈ 0.31 for f, 0.80 for g), so
    // the yardstick is the error of a zero estimate, the maps' own spread. Observed at L = 600:
    // f 0.21 / 0.21 / 0.37 and g 0.26 / 0.23 / 0.41 for β = 0.001 / 0.01 / 0.1.
    let (header, rows) = read_csv(&demo.join("data.csv"));
    let spread = |name: &str| {
        let c = header.iter().position(|h| h == name).unwrap();
        let x: Vec<f64> = rows.iter().map(|r| r[c]).collect();
        let m = x.iter().sum::<f64>() / x.len() as f64;
        (x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64).sqrt()
    };
    let (sf, sg) = (spread("f_true"), spread("g_true"));
    for (i, r) in results.iter().enumerate() {
        let (ef, eg) = (
            r["centred_rms_error_f"].as_f64().unwrap(),
            r["centred_rms_error_g"].as_f64().unwrap(),
        );
        assert!(ef.is_finite() && eg.is_finite(), "{r}");
        // β = 0.1 over-smooths (the paper's point); the smaller β recover the maps.
        if i < 2 {
            assert!(
                ef < 0.8 * sf && eg < 0.4 * sg,
                "β = {}: f {ef} (spread {sf}), g {eg} (spread {sg})",
                r["beta"]
            );
        }
    }

    let out = dir.path().join("again");
    ok(&[
        "identify",
        "--model",
        p(&demo.join("model.toml")),
        "--data",
        p(&demo.join("data.csv")),
        "--out",
        p(&out),
    ]);
    let (header, rows) = read_csv(&out.join("estimate.csv"));
    assert_eq!(header, ["f", "g", "e0"]);
    assert_eq!(rows.len(), 600);
    let report = read_json(&out.join("report.json"));
    // Same data, same β = 0.01 and σ = 0.1 as the demo's middle panel: same errors.
    let demo_mid = &results[1];
    for (i, name) in ["f", "g"].iter().enumerate() {
        let b = &report["blocks"][i];
        assert_eq!(b["name"], *name);
        let c = b["centred_rms_error_vs_truth"].as_f64().unwrap();
        let d = demo_mid[format!("centred_rms_error_{name}")]
            .as_f64()
            .unwrap();
        assert!((c - d).abs() < 1e-6, "{name}: {c} vs {d}");
        assert_svg(&out.join(format!("map_{name}.svg")));
    }
}

#[test]
fn demo_multi_input_and_two_input_grids() {
    let dir = tempfile::tempdir().unwrap();
    let demo = dir.path().join("mi");
    let o = ok(&["demo", "multi-input", "--samples", "400", "--out", p(&demo)]);
    assert!(o.stdout.contains("RMS error"), "{}", o.stdout);
    assert_svg(&demo.join("surfaces.svg"));
    let summary = read_json(&demo.join("summary.json"));
    assert!(
        summary["rms_error_at_data_points"].as_f64().unwrap() < 0.3,
        "{summary}"
    );

    let out = dir.path().join("id");
    ok(&[
        "identify",
        "--model",
        p(&demo.join("model.toml")),
        "--data",
        p(&demo.join("data.csv")),
        "--out",
        p(&out),
    ]);
    let (header, rows) = read_csv(&out.join("map_N.csv"));
    assert_eq!(header, ["z0", "z1", "value", "std"]);
    assert_eq!(rows.len(), 41 * 41);
    assert!(rows.iter().all(|r| r[3] > 0.0));
    assert_svg(&out.join("map_N.svg"));
    let report = read_json(&out.join("report.json"));
    let rms = report["blocks"][0]["rms_error_vs_truth"].as_f64().unwrap();
    assert!((rms - summary["rms_error_at_data_points"].as_f64().unwrap()).abs() < 1e-6);
}

#[test]
fn three_input_maps_are_written_at_the_data_points() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("m.toml");
    std::fs::write(
        &model,
        r#"
[lft]
A = []
Dye = [[1.0]]
Dyw = [[1.0]]
Dzu = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
[signals]
u = ["a", "b", "c"]
y = ["y"]
[[nonlinearity]]
name = "N"
inputs = [0, 1, 2]
output = 0
dispersion = { kind = "gaussian", sigma = 1.0 }
truth = "z0 + z1*z2"
"#,
    )
    .unwrap();
    let (u, data, out) = (
        dir.path().join("u.csv"),
        dir.path().join("d.csv"),
        dir.path().join("out"),
    );
    write_input(&u, 300, &["a", "b", "c"]);
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
    ok(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&out),
        "--beta",
        "0.0001",
    ]);
    let (header, rows) = read_csv(&out.join("map_N.csv"));
    assert_eq!(header, ["z0", "z1", "z2", "value", "std"]);
    assert_eq!(rows.len(), 300);
    assert!(rows.iter().all(|r| r[4] > 0.0));
    assert_svg(&out.join("map_N.svg"));
    // --no-bands skips them.
    let out2 = dir.path().join("out2");
    ok(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&out2),
        "--beta",
        "0.0001",
        "--no-bands",
    ]);
    let (header, _) = read_csv(&out2.join("map_N.csv"));
    assert_eq!(header, ["z0", "z1", "z2", "value"]);
    let report = read_json(&out2.join("report.json"));
    assert_eq!(report["blocks"][0]["band"], false);
    assert!(report["blocks"][0]["noise_variance"].is_null());
}

#[test]
fn bad_inputs_give_readable_errors() {
    let dir = tempfile::tempdir().unwrap();
    let model = example_model("hammerstein.toml");
    let m = p(&model);
    let out = dir.path().join("out");
    let o = p(&out);

    // NaN in the data, with its line number.
    let nan = dir.path().join("nan.csv");
    std::fs::write(&nan, "u,y\n0.1,0.2\n0.3,0.4\n0.5,NaN\n").unwrap();
    let e = input_error(&["identify", "--model", m, "--data", p(&nan), "--out", o]);
    assert!(
        e.contains("line 4") && e.contains("`y`") && e.contains("NaN"),
        "{e}"
    );

    // A non-numeric field.
    let txt = dir.path().join("txt.csv");
    std::fs::write(&txt, "u,y\n0.1,0.2\nabc,0.4\n").unwrap();
    let e = input_error(&["identify", "--model", m, "--data", p(&txt), "--out", o]);
    assert!(
        e.contains("line 3") && e.contains("cannot parse `abc`"),
        "{e}"
    );

    // A missing column, listing the available ones.
    let miss = dir.path().join("miss.csv");
    std::fs::write(&miss, "u,yy\n0.1,0.2\n").unwrap();
    let e = input_error(&["identify", "--model", m, "--data", p(&miss), "--out", o]);
    assert!(
        e.contains("no column `y`") && e.contains("`u`, `yy`"),
        "{e}"
    );

    // Malformed TOML, with its line number.
    let bad = dir.path().join("bad.toml");
    let text = std::fs::read_to_string(&model)
        .unwrap()
        .replace("Dye = [[1.0]]", "Dye = [[1.0]");
    std::fs::write(&bad, &text).unwrap();
    let good_data = dir.path().join("good.csv");
    std::fs::write(&good_data, "u,y\n0.1,0.2\n0.3,0.4\n").unwrap();
    let e = input_error(&[
        "identify",
        "--model",
        p(&bad),
        "--data",
        p(&good_data),
        "--out",
        o,
    ]);
    assert!(e.contains("invalid TOML") && e.contains("(line "), "{e}");
    // A dimension error names the matrix and the line.
    let text = std::fs::read_to_string(&model)
        .unwrap()
        .replace("Dyu = [[0.0]]", "Dyu = [[0.0, 1.0]]");
    std::fs::write(&bad, &text).unwrap();
    let e = input_error(&[
        "identify",
        "--model",
        p(&bad),
        "--data",
        p(&good_data),
        "--out",
        o,
    ]);
    assert!(
        e.contains("matrix Dyu has 2 columns but [signals].u names 1 input (line 22)"),
        "{e}"
    );

    // Out-of-range parameters.
    let e = input_error(&[
        "identify",
        "--model",
        m,
        "--data",
        p(&good_data),
        "--out",
        o,
        "--sigma",
        "-1",
    ]);
    assert!(
        e.contains("--sigma") && e.contains("greater than zero"),
        "{e}"
    );
    let e = input_error(&[
        "identify",
        "--model",
        m,
        "--data",
        p(&good_data),
        "--out",
        o,
        "--beta",
        "0",
    ]);
    assert!(
        e.contains("--beta") && e.contains("greater than zero"),
        "{e}"
    );
    let e = input_error(&[
        "identify",
        "--model",
        m,
        "--data",
        p(&good_data),
        "--out",
        o,
        "--beta",
        "-0.1",
    ]);
    assert!(e.contains("--beta"), "{e}");
    input_error(&[
        "identify",
        "--model",
        m,
        "--data",
        p(&good_data),
        "--out",
        o,
        "--beta",
        "nan",
    ]);
    input_error(&[
        "identify",
        "--model",
        m,
        "--data",
        p(&good_data),
        "--out",
        o,
        "--memory-limit-mib",
        "0",
    ]);
    input_error(&["identify", "--model", m, "--data", p(&good_data)]);
    input_error(&["frobnicate"]);

    // Missing files.
    let e = input_error(&[
        "identify",
        "--model",
        "/nonexistent/m.toml",
        "--data",
        p(&good_data),
        "--out",
        o,
    ]);
    assert!(
        e.contains("cannot read `/nonexistent/m.toml`") && e.contains("caused by"),
        "{e}"
    );

    // The output must never overwrite an input.
    let before = std::fs::read_to_string(&good_data).unwrap();
    let e = input_error(&[
        "identify",
        "--model",
        m,
        "--data",
        p(&good_data),
        "--out",
        p(&good_data),
    ]);
    assert!(e.contains("refusing to write"), "{e}");
    let u = dir.path().join("u.csv");
    write_input(&u, 20, &["u"]);
    let u_before = std::fs::read_to_string(&u).unwrap();
    let e = input_error(&["simulate", "--model", m, "--input", p(&u), "--out", p(&u)]);
    assert!(
        e.contains("refusing to write") && e.contains("input file"),
        "{e}"
    );
    let e = input_error(&["simulate", "--model", m, "--input", p(&u), "--out", m]);
    assert!(e.contains("refusing to write"), "{e}");
    // … also when the data file sits in the output directory under an output's name.
    let clash_dir = dir.path().join("clash");
    std::fs::create_dir(&clash_dir).unwrap();
    std::fs::copy(&good_data, clash_dir.join("estimate.csv")).unwrap();
    let e = input_error(&[
        "identify",
        "--model",
        m,
        "--data",
        p(&clash_dir.join("estimate.csv")),
        "--out",
        p(&clash_dir),
    ]);
    assert!(
        e.contains("refusing to write") && e.contains("estimate.csv"),
        "{e}"
    );
    assert_eq!(std::fs::read_dir(&clash_dir).unwrap().count(), 1);
    assert_eq!(std::fs::read_to_string(&good_data).unwrap(), before);
    assert_eq!(std::fs::read_to_string(&u).unwrap(), u_before);

    // D_zw ≠ 0: simulation has an algebraic loop.
    let looped = dir.path().join("loop.toml");
    let text = std::fs::read_to_string(&model)
        .unwrap()
        .replace("Dzw = [[0.0]]", "Dzw = [[0.5]]");
    std::fs::write(&looped, text).unwrap();
    let e = input_error(&[
        "simulate",
        "--model",
        p(&looped),
        "--input",
        p(&u),
        "--out",
        p(&dir.path().join("s.csv")),
    ]);
    assert!(e.contains("algebraic loop") && e.contains("D_zw"), "{e}");

    // A block without a truth cannot be simulated.
    let no_truth = dir.path().join("nt.toml");
    let text = std::fs::read_to_string(&model)
        .unwrap()
        .replace("truth = \"tanh(2*z0)\"", "");
    std::fs::write(&no_truth, text).unwrap();
    let e = input_error(&[
        "simulate",
        "--model",
        p(&no_truth),
        "--input",
        p(&u),
        "--out",
        p(&dir.path().join("s.csv")),
    ]);
    assert!(e.contains("`N`") && e.contains("truth"), "{e}");
    let e = input_error(&[
        "simulate",
        "--model",
        m,
        "--input",
        p(&u),
        "--out",
        p(&dir.path().join("s.csv")),
        "--noise-std",
        "-1",
    ]);
    assert!(e.contains("--noise-std"), "{e}");

    // Nothing was written for the failed runs.
    assert!(!out.exists());
    assert!(!dir.path().join("s.csv").exists());
}

/// The Fourier-series dispersion and the initial-state option work from the command line: a
/// record that does not start at rest is identified with `--initial-state estimate`.
#[test]
fn fourier_dispersion_and_initial_state_from_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(example_model("hammerstein.toml"))
        .unwrap()
        .replace(
            r#"dispersion = { kind = "gaussian", sigma = 0.3 }"#,
            r#"dispersion = { kind = "fourier", sigma = 0.3 }"#,
        );
    assert!(text.contains("fourier"));
    let model = dir.path().join("fourier.toml");
    std::fs::write(&model, text).unwrap();
    let u = dir.path().join("u.csv");
    let data = dir.path().join("data.csv");
    write_input(&u, 600, &["u"]);
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&data),
        "--noise-std",
        "0.05",
    ]);
    // Drop the first 40 rows: the record now starts in motion (the simulation did not).
    let content = std::fs::read_to_string(&data).unwrap();
    let mut lines: Vec<&str> = content.lines().collect();
    lines.drain(1..41);
    let cut = dir.path().join("cut.csv");
    std::fs::write(&cut, lines.join("\n") + "\n").unwrap();
    let rms = |extra: &[&str], out: &str| {
        let out = dir.path().join(out);
        let mut args = vec![
            "identify",
            "--model",
            p(&model),
            "--data",
            p(&cut),
            "--out",
            p(&out),
        ];
        args.extend_from_slice(extra);
        ok(&args);
        let r = read_json(&out.join("report.json"));
        assert!(
            r["settings"]["blocks"][0]["dispersion"]
                .as_str()
                .unwrap()
                .starts_with("fourier")
        );
        (r["blocks"][0]["rms_error_vs_truth"].as_f64().unwrap(), r)
    };
    let (rest, r0) = rms(&[], "rest");
    let (est, r1) = rms(&["--initial-state", "estimate"], "est");
    assert!(r0.get("initial_state").is_none());
    assert_eq!(r1["initial_state"].as_array().unwrap().len(), 2);
    assert_eq!(r1["settings"]["initial_state"], "Estimate");
    assert!(est < 0.08, "RMS with x₀ estimated: {est}");
    assert!(est < rest, "estimating x₀ should help: {est} vs {rest}");
    // The feature solver gives the same estimate, and says so in the report.
    let (feat, r2) = rms(
        &["--initial-state", "estimate", "--solver", "features"],
        "feat",
    );
    assert!(
        r2["diagnostics"]["solver"]
            .as_str()
            .unwrap()
            .starts_with("features"),
        "{}",
        r2["diagnostics"]["solver"]
    );
    assert!((feat - est).abs() < 1e-6, "features {feat} vs exact {est}");
    let e = input_error(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&cut),
        "--out",
        p(&dir.path().join("x")),
        "--initial-state",
        "guess",
    ]);
    assert!(e.contains("guess"), "{e}");
}

#[test]
fn total_variation_from_the_model_file_and_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let model = example_model("friction.toml");
    let u = dir.path().join("u.csv");
    let data = dir.path().join("data.csv");
    write_input(&u, 500, &["u"]);
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&data),
        "--noise-std",
        "0.1",
        "--seed",
        "3",
    ]);
    let identify = |extra: &[&str], out: &str| {
        let out = dir.path().join(out);
        let mut args = vec![
            "identify",
            "--model",
            p(&model),
            "--data",
            p(&data),
            "--out",
            p(&out),
        ];
        args.extend_from_slice(extra);
        let o = ok(&args);
        (read_json(&out.join("report.json")), o.stdout, out)
    };
    // kind = "tv" in the file: the automatic choice is the conic solver at this size, and the
    // summary says so.
    let (r, stdout, out) = identify(&["--beta", "0.003"], "tv");
    assert_eq!(
        r["diagnostics"]["solver"], "clarabel",
        "{}",
        r["diagnostics"]
    );
    assert!(stdout.contains("solver: clarabel (automatic"), "{stdout}");
    assert!(
        r["settings"]["blocks"][0]["dispersion"]
            .as_str()
            .unwrap()
            .starts_with("tv")
    );
    assert_svg(&out.join("map_friction.svg"));
    // No posterior for total variation: no band, no std column.
    assert_eq!(r["blocks"][0]["band"], false);
    assert!(r["blocks"][0]["noise_variance"].is_null());
    let (header, _) = read_csv(&out.join("map_friction.csv"));
    assert_eq!(header, ["z0", "value"]);
    let tv_err = r["blocks"][0]["rms_error_vs_truth"].as_f64().unwrap();
    // --solver admm overrides the choice and agrees.
    let (ra, stdout, _) = identify(&["--beta", "0.003", "--solver", "admm"], "admm");
    assert_eq!(ra["diagnostics"]["solver"], "admm");
    assert!(stdout.contains("iterations"), "{stdout}");
    let admm_err = ra["blocks"][0]["rms_error_vs_truth"].as_f64().unwrap();
    assert!(
        (admm_err - tv_err).abs() < 1e-4 * tv_err.max(1e-3),
        "{admm_err} vs {tv_err}"
    );
    // --dispersion gaussian overrides the file; on this jump the error is larger.
    let (rg, _, _) = identify(&["--dispersion", "gaussian", "--beta", "0.0003"], "gauss");
    assert!(
        rg["settings"]["blocks"][0]["dispersion"]
            .as_str()
            .unwrap()
            .starts_with("gaussian")
    );
    let g_err = rg["blocks"][0]["rms_error_vs_truth"].as_f64().unwrap();
    assert!(tv_err < g_err, "tv {tv_err} vs gaussian {g_err}");
    // And back: --dispersion tv on the Gaussian Hammerstein example.
    let hdata = dir.path().join("h.csv");
    let hmodel = example_model("hammerstein.toml");
    ok(&[
        "simulate",
        "--model",
        p(&hmodel),
        "--input",
        p(&u),
        "--out",
        p(&hdata),
        "--noise-std",
        "0.05",
    ]);
    let hout = dir.path().join("h");
    ok(&[
        "identify",
        "--model",
        p(&hmodel),
        "--data",
        p(&hdata),
        "--out",
        p(&hout),
        "--dispersion",
        "tv",
        "--tolerance",
        "1e-9",
    ]);
    assert_eq!(
        read_json(&hout.join("report.json"))["diagnostics"]["solver"],
        "clarabel"
    );
    // Bad combinations are input errors; an iteration limit that is too small is a runtime error.
    let x = dir.path().join("x");
    let args = |m: &Path, d: &Path, extra: &[&'static str]| -> Vec<String> {
        let mut a: Vec<String> = ["identify", "--model", p(m), "--data", p(d), "--out", p(&x)]
            .iter()
            .map(|s| s.to_string())
            .collect();
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    for (m, d, extra, needle) in [
        (&model, &data, ["--neighbours", "0"], "--neighbours"),
        (&model, &data, ["--solver", "exact"], "clarabel or admm"),
        (&hmodel, &hdata, ["--neighbours", "4"], "total-variation"),
    ] {
        let e = input_error(&refs(&args(m, d, &extra)));
        assert!(e.contains(needle), "{extra:?}: {e}");
    }
    let o = run(&refs(&args(
        &model,
        &data,
        &["--solver", "admm", "--max-iterations", "2"],
    )));
    assert_eq!(o.code, 1, "{}", o.stderr);
    assert!(o.stderr.contains("did not converge"), "{}", o.stderr);
    assert!(!o.stderr.contains("panicked"));
    // The iterate is written all the same, marked as not converged, and the message names a
    // solver that can do the job.
    assert!(
        o.stderr.contains("last iterate was written"),
        "{}",
        o.stderr
    );
    assert!(o.stderr.contains("clarabel"), "{}", o.stderr);
    let r = read_json(&x.join("report.json"));
    assert_eq!(r["diagnostics"]["status"], "max_iterations", "{r}");
    assert!(x.join("estimate.csv").exists() && x.join("estimate.json").exists());
}

fn refs(a: &[String]) -> Vec<&str> {
    a.iter().map(String::as_str).collect()
}

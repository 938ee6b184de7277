//! Several records (`--data a.csv --data b.csv`): one fit over separate experiments, each from
//! its own initial state — not the fit of the concatenated file.

use std::path::{Path, PathBuf};

use structid_core::{Data, IdentifySettings, Signal, SolverChoice, identify};
use structid_io::ModelFile;

mod common;
use common::*;

/// A deterministic input in [−2, 2].
fn write_input(path: &Path, len: usize, seed: u64) {
    let mut s = String::from("u\n");
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15 ^ seed;
    for _ in 0..len {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        s.push_str(&format!(
            "{}\n",
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 2.0
        ));
    }
    std::fs::write(path, s).unwrap();
}

/// The columns of a CSV file with a header row.
fn columns(path: &Path) -> Vec<(String, Vec<f64>)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let mut cols: Vec<(String, Vec<f64>)> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|h| (h.to_string(), Vec::new()))
        .collect();
    for l in lines {
        for (c, v) in cols.iter_mut().zip(l.split(',')) {
            c.1.push(v.parse().unwrap());
        }
    }
    cols
}

fn column(path: &Path, name: &str) -> Vec<f64> {
    columns(path)
        .into_iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("no column {name} in {}", path.display()))
        .1
}

fn record(path: &Path) -> Data {
    let (u, y) = (column(path, "u"), column(path, "y"));
    Data::new(Signal::new(1, u).unwrap(), Signal::new(1, y).unwrap()).unwrap()
}

/// Simulates the Hammerstein example on a fresh input of `len` samples into `out`.
fn simulate(dir: &Path, name: &str, len: usize, seed: u64) -> std::path::PathBuf {
    let model = example_model("hammerstein.toml");
    let u = dir.join(format!("{name}_u.csv"));
    let out = dir.join(format!("{name}.csv"));
    write_input(&u, len, seed);
    ok(&[
        "simulate",
        "--model",
        p(&model),
        "--input",
        p(&u),
        "--out",
        p(&out),
        "--noise-std",
        "0.05",
        "--seed",
        &seed.to_string(),
    ]);
    out
}

fn identify_cli(data: &[&Path], out: &Path) -> Vec<f64> {
    let model = example_model("hammerstein.toml");
    let mut args = vec!["identify", "--model", p(&model)];
    for d in data {
        args.extend(["--data", p(d)]);
    }
    args.extend([
        "--out",
        p(out),
        "--beta",
        "0.01",
        "--solver",
        "exact",
        "--initial-state",
        "estimate",
    ]);
    ok(&args);
    column(&out.join("estimate.csv"), "N")
}

#[test]
fn two_data_files_are_two_records_not_one_concatenated_record() {
    let dir = tempfile::tempdir().unwrap();
    let a = simulate(dir.path(), "a", 120, 1);
    let b = simulate(dir.path(), "b", 90, 2);
    let w = identify_cli(&[&a, &b], &dir.path().join("two"));
    assert_eq!(w.len(), 210);

    // The library on the same two records (its multi-record fit is checked against a dense
    // block-diagonal reference in structid-core's tests).
    let mf = ModelFile::from_path(&example_model("hammerstein.toml")).unwrap();
    let model = mf.to_model(None, None).unwrap();
    let data = Data::from_records(vec![record(&a), record(&b)]).unwrap();
    let settings = IdentifySettings::builder()
        .beta(0.01)
        .solver(SolverChoice::Exact)
        .initial_state(structid_core::InitialState::Estimate)
        .build()
        .unwrap();
    let id = identify(&model, &data, &settings).unwrap();
    let scale = id
        .w_hat
        .as_slice()
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = |x: &[f64], y: &[f64]| {
        x.iter()
            .zip(y)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
    };
    // estimate.csv is written with a few significant digits fewer than f64
    assert!(diff(&w, id.w_hat.as_slice()) < 1e-6 * scale);

    // The concatenated file carries the state of record 1 into record 2: another problem.
    let cat = dir.path().join("ab.csv");
    let (ca, cb) = (columns(&a), columns(&b));
    let mut text = ca
        .iter()
        .map(|c| c.0.as_str())
        .collect::<Vec<_>>()
        .join(",");
    text.push('\n');
    for k in 0..ca[0].1.len() + cb[0].1.len() {
        let row: Vec<String> = ca
            .iter()
            .zip(&cb)
            .map(|(x, y)| {
                let v = if k < x.1.len() {
                    x.1[k]
                } else {
                    y.1[k - x.1.len()]
                };
                format!("{v:?}")
            })
            .collect();
        text.push_str(&row.join(","));
        text.push('\n');
    }
    std::fs::write(&cat, text).unwrap();
    let w_cat = identify_cli(&[&cat], &dir.path().join("cat"));
    assert!(
        diff(&w, &w_cat) > 1e-3 * scale,
        "the concatenated record gave the same estimate"
    );

    // report.json records every file, so that the run can be repeated.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("two/report.json")).unwrap())
            .unwrap();
    let files = report["reproduction"]["data_files_absolute"]
        .as_array()
        .expect("both files recorded");
    assert_eq!(files.len(), 2);
}

/// `--dispersion tv --solver admm` over two data files: ADMM restarts its smoother at each
/// record (one x₀ per record) and gives the conic solver's estimate over the same records, not
/// ADMM's on the concatenated file.
#[test]
fn admm_with_total_variation_takes_two_data_files() {
    let dir = tempfile::tempdir().unwrap();
    let a = simulate(dir.path(), "a", 120, 11);
    let b = simulate(dir.path(), "b", 90, 12);
    let model = example_model("hammerstein.toml");
    let run = |data: &[&Path], solver: &str, out: &Path| {
        let mut args = vec!["identify", "--model", p(&model)];
        for d in data {
            args.extend(["--data", p(d)]);
        }
        args.extend([
            "--out",
            p(out),
            "--beta",
            "0.01",
            "--dispersion",
            "tv",
            "--solver",
            solver,
            "--initial-state",
            "estimate",
            "--tolerance",
            "1e-9",
            "--max-iterations",
            "200000",
        ]);
        let o = ok(&args);
        (column(&out.join("estimate.csv"), "N"), o.stdout)
    };
    let (w, stdout) = run(&[&a, &b], "admm", &dir.path().join("admm"));
    assert_eq!(w.len(), 210);
    assert!(stdout.contains("solver: admm (requested)"), "{stdout}");
    let report = json(&dir.path().join("admm/report.json"));
    assert_eq!(report["diagnostics"]["solver"], "admm", "{report}");
    let x0 = report["initial_state"].as_array().expect("x₀ estimated");
    assert_eq!(x0.len(), 4, "one initial state per record");

    let (w_conic, _) = run(&[&a, &b], "clarabel", &dir.path().join("conic"));
    let scale = w_conic.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = |x: &[f64], y: &[f64]| {
        x.iter()
            .zip(y)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
    };
    assert!(
        diff(&w, &w_conic) < 1e-4 * scale,
        "admm and clarabel differ by {}",
        diff(&w, &w_conic)
    );

    // The concatenated file is another problem.
    let cat = dir.path().join("ab.csv");
    let (ca, cb) = (
        std::fs::read_to_string(&a).unwrap(),
        std::fs::read_to_string(&b).unwrap(),
    );
    let body_b: String = cb.lines().skip(1).map(|l| format!("{l}\n")).collect();
    std::fs::write(&cat, format!("{}{body_b}", ca)).unwrap();
    let (w_cat, _) = run(&[&cat], "admm", &dir.path().join("cat"));
    assert!(
        diff(&w, &w_cat) > 1e-3 * scale,
        "the concatenated record gave the same estimate"
    );
}

#[test]
fn a_record_shorter_than_the_model_order_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let a = simulate(dir.path(), "a", 50, 3);
    let short = dir.path().join("short.csv");
    std::fs::write(&short, "u,y\n0.5,0.1\n").unwrap();
    let model = example_model("hammerstein.toml");
    let out = dir.path().join("out");
    let e = input_error(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&a),
        "--data",
        p(&short),
        "--out",
        p(&out),
        "--beta",
        "0.01",
    ]);
    assert!(e.contains("record 2"), "{e}");
    assert!(e.contains("fewer than the 2 state(s)"), "{e}");
    assert!(e.contains("short.csv"), "{e}");
}

#[test]
fn a_file_without_the_model_signals_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let a = simulate(dir.path(), "a", 50, 4);
    let other = dir.path().join("other.csv");
    std::fs::write(&other, "u,v\n0.5,0.1\n0.2,0.3\n0.1,0.0\n").unwrap();
    let model = example_model("hammerstein.toml");
    let out = dir.path().join("out");
    let e = input_error(&[
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&a),
        "--data",
        p(&other),
        "--out",
        p(&out),
        "--beta",
        "0.01",
    ]);
    assert!(e.contains("other.csv"), "{e}");
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Two simulated records (150 and 100 samples) and the estimate identified on both.
fn two_records_and_their_estimate(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let a = simulate(dir, "a", 150, 5);
    let b = simulate(dir, "b", 100, 6);
    let est = dir.join("est");
    identify_cli(&[&a, &b], &est);
    (a, b, est.join("estimate.json"))
}

/// `structid validate --estimate STORED --data … --out OUT OPTION VALUE`.
fn validate_stored(stored: &Path, data: &[&Path], out: &Path, option: &str, value: &str) {
    let mut args = vec!["validate", "--estimate", p(stored)];
    for d in data {
        args.extend(["--data", p(d)]);
    }
    args.extend(["--out", p(out), option, value]);
    ok(&args);
}

#[test]
fn validate_reports_each_record_and_the_pooled_error() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b, stored) = two_records_and_their_estimate(dir.path());
    let validate =
        |data: &[&Path], out: &Path| validate_stored(&stored, data, out, "--settle", "5");
    let both = dir.path().join("both");
    validate(&[&a, &b], &both);
    // Each record on its own, as a one-record validation computes it.
    let single: Vec<serde_json::Value> = [(&a, "va"), (&b, "vb")]
        .iter()
        .map(|(d, name)| {
            let out = dir.path().join(name);
            validate(&[d.as_path()], &out);
            json(&out.join("validation.json"))
        })
        .collect();
    let doc = json(&both.join("validation.json"));
    let records = doc["records"].as_array().unwrap();
    assert_eq!(records.len(), 2);
    let rms = |v: &serde_json::Value| v["outputs"][0]["rms"].as_f64().unwrap();
    for (r, s) in records.iter().zip(&single) {
        assert_eq!(rms(r), rms(s));
        assert!(
            both.join(r["dir"].as_str().unwrap())
                .join("simulation.csv")
                .is_file()
        );
    }
    // Pooled over the samples after the settling ones: (150 − 5) and (100 − 5).
    let (na, nb) = (145.0, 95.0);
    let pooled = ((na * rms(&single[0]).powi(2) + nb * rms(&single[1]).powi(2)) / (na + nb)).sqrt();
    let overall = doc["overall"]["outputs"][0]["rms"].as_f64().unwrap();
    assert!(
        (overall - pooled).abs() < 1e-9 * pooled,
        "{overall} vs {pooled}"
    );
    assert_eq!(doc["overall"]["outputs"][0]["samples"].as_u64(), Some(240));
}

/// With windowed scoring each record scores its windows, not every sample after the settling
/// ones; the pooled error is over the same windows, so it is the records' own RMS weighted by
/// the samples each scored.
#[test]
fn validate_pools_the_windows_each_record_scored() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b, stored) = two_records_and_their_estimate(dir.path());
    let validate =
        |data: &[&Path], out: &Path| validate_stored(&stored, data, out, "--scoring", "40:10");
    let both = dir.path().join("both");
    validate(&[&a, &b], &both);
    let (mut sse, mut n) = (0.0, 0.0);
    for (d, name) in [(&a, "va"), (&b, "vb")] {
        let out = dir.path().join(name);
        validate(&[d.as_path()], &out);
        let doc = json(&out.join("validation.json"));
        let count: f64 = doc["scored"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| (r[1].as_u64().unwrap() - r[0].as_u64().unwrap()) as f64)
            .sum();
        // Windows of 40 with 10 initialisation samples score 30 of every 40.
        assert!(count <= 0.8 * doc["samples"].as_f64().unwrap(), "{count}");
        sse += count * doc["outputs"][0]["rms"].as_f64().unwrap().powi(2);
        n += count;
    }
    let doc = json(&both.join("validation.json"));
    let overall = doc["overall"]["outputs"][0]["rms"].as_f64().unwrap();
    let pooled = (sse / n).sqrt();
    assert!(
        (overall - pooled).abs() < 1e-9 * pooled,
        "{overall} vs {pooled}"
    );
    assert_eq!(doc["overall"]["outputs"][0]["samples"].as_f64(), Some(n));
}

/// y_k = 1.5·y_(k−1) − 0.7·y_(k−2) + u_(k−1) + 0.5·u_(k−2), from rest.
fn write_lti(path: &Path, len: usize, seed: u64) {
    let u_path = path.with_extension("u.csv");
    write_input(&u_path, len, seed);
    let u = column(&u_path, "u");
    let mut y = vec![0.0; len];
    for k in 0..len {
        let at = |v: &[f64], j: usize| if k >= j { v[k - j] } else { 0.0 };
        y[k] = 1.5 * at(&y, 1) - 0.7 * at(&y, 2) + at(&u, 1) + 0.5 * at(&u, 2);
    }
    let mut s = String::from("u,y\n");
    for k in 0..len {
        s.push_str(&format!("{:?},{:?}\n", u[k], y[k]));
    }
    std::fs::write(path, s).unwrap();
}

#[test]
fn linear_arx_fits_every_record_from_its_own_start() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
    write_lti(&a, 80, 7);
    write_lti(&b, 60, 8);
    let out = dir.path().join("g.toml");
    ok(&[
        "linear",
        "--data",
        p(&a),
        "--data",
        p(&b),
        "--method",
        "arx",
        "--orders",
        "2,2,1",
        "--out",
        p(&out),
    ]);
    let mf = ModelFile::from_path(&out).unwrap();
    let g = mf.linear.unwrap().model;
    let want_den = [1.0, -1.5, 0.7];
    for (x, w) in g.den.iter().zip(want_den) {
        assert!((x - w).abs() < 1e-8, "{:?}", g.den);
    }
    assert!(
        (g.num[0][1] - 1.0).abs() < 1e-8 && (g.num[0][2] - 0.5).abs() < 1e-8,
        "{:?}",
        g.num
    );
    // Order selection over both records (BIC on the ARX fits over both; the noise-free
    // records leave BIC free to take any orders that contain G's) then output error: the
    // model simulates both records from rest exactly.
    let o = ok(&["linear", "--data", p(&a), "--data", p(&b), "--out", p(&out)]);
    assert!(o.stdout.contains("orders selected by BIC"), "{}", o.stdout);
    assert!(
        o.stdout.contains("simulation fit on the data 100.00 %"),
        "{}",
        o.stdout
    );
}

/// The denominator and numerator of the model file `structid linear` wrote.
fn linear_model(path: &Path) -> (Vec<f64>, Vec<f64>) {
    let g = ModelFile::from_path(path).unwrap().linear.unwrap().model;
    (g.den, g.num[0].clone())
}

/// `--method oe` over two records simulated from rest recovers G exactly (each record is
/// simulated from rest, as they were made), with and without a free initial state per record;
/// the file glued from both does not start its second part at rest, so its fit differs.
#[test]
fn linear_oe_fits_every_record_from_rest() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
    write_lti(&a, 120, 17);
    write_lti(&b, 90, 18);
    let want_den = [1.0, -1.5, 0.7];
    let want_num = [0.0, 1.0, 0.5];
    for x0 in ["zero", "estimate"] {
        let out = dir.path().join(format!("oe_{x0}.toml"));
        let o = ok(&[
            "linear",
            "--data",
            p(&a),
            "--data",
            p(&b),
            "--method",
            "oe",
            "--orders",
            "2,2,1",
            "--initial-state",
            x0,
            "--out",
            p(&out),
        ]);
        assert!(o.stdout.contains("simulation error (OE"), "{}", o.stdout);
        let (den, num) = linear_model(&out);
        for (x, w) in den.iter().zip(want_den).chain(num.iter().zip(want_num)) {
            assert!((x - w).abs() < 1e-7, "{x0}: {den:?} {num:?}");
        }
    }
    // The glued file: one record whose second part starts from the first part's final state.
    let glued = dir.path().join("glued.csv");
    let text_b = std::fs::read_to_string(&b).unwrap();
    let body_b: String = text_b.lines().skip(1).map(|l| format!("{l}\n")).collect();
    std::fs::write(&glued, std::fs::read_to_string(&a).unwrap() + &body_b).unwrap();
    let out = dir.path().join("glued.toml");
    ok(&[
        "linear",
        "--data",
        p(&glued),
        "--method",
        "oe",
        "--orders",
        "2,2,1",
        "--out",
        p(&out),
    ]);
    let (den, _) = linear_model(&out);
    let off = den
        .iter()
        .zip(want_den)
        .map(|(x, w)| (x - w).abs())
        .fold(0.0, f64::max);
    assert!(
        off > 1e-4,
        "the glued record fits like the records: {den:?}"
    );
}

//! End-to-end tests of `structid compare`: a tiny sweep (static tanh map, L = 120) with a
//! simulated and a measured experiment, each run in well under a second in release.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

mod common;
use common::*;

const MODEL: &str = r#"
[lft]
A = []
Dye = [[1.0]]
Dyw = [[1.0]]
Dzu = [[1.0]]
[signals]
u = ["u"]
y = ["y"]
[[nonlinearity]]
name = "N"
inputs = [0]
output = 0
dispersion = { kind = "gaussian", sigma = 0.3 }
truth = "tanh(2*z0)"
"#;

const CONFIG: &str = r#"# tiny comparison sweep
[[experiment]]
name = "sim"
model = "model.toml"
[experiment.simulate]
input = "u.csv"
validation_input = "u_val.csv"
noise_std = 0.1
seeds = [4, 9]

[[experiment]]
name = "meas"
model = "model.toml"
estimation = "data.csv"

[[dispersion]]
name = "gauss"
kind = "gaussian"
beta = [0.01, "auto"]

[[dispersion]]
name = "tv"
kind = "tv"
beta = 0.001

[[dispersion]]
name = "broken"
kind = "gaussian"
solver = "features"
beta = 0.01
"#;

/// The case ids CONFIG must give, in order.
const IDS: [&str; 12] = [
    "sim/gauss/beta=0.01/seed=4",
    "sim/gauss/beta=0.01/seed=9",
    "sim/gauss/beta=auto/seed=4",
    "sim/gauss/beta=auto/seed=9",
    "sim/tv/beta=0.001/seed=4",
    "sim/tv/beta=0.001/seed=9",
    "sim/broken/beta=0.01/seed=4",
    "sim/broken/beta=0.01/seed=9",
    "meas/gauss/beta=0.01",
    "meas/gauss/beta=auto",
    "meas/tv/beta=0.001",
    "meas/broken/beta=0.01",
];

/// A reproducible input on [−2, 2] (a small LCG, so the test needs no RNG crate).
fn input_csv(len: usize, seed: u64) -> String {
    let mut state = seed;
    let mut s = String::from("u\n");
    for _ in 0..len {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let u = ((state >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 2.0;
        s.push_str(&format!("{u}\n"));
    }
    s
}

/// Writes the model, inputs, measured data (simulated with `structid simulate`) and CONFIG into
/// `dir`; returns the configuration's path.
fn setup(dir: &Path) -> PathBuf {
    std::fs::write(dir.join("model.toml"), MODEL).unwrap();
    std::fs::write(dir.join("u.csv"), input_csv(120, 1)).unwrap();
    std::fs::write(dir.join("u_val.csv"), input_csv(80, 2)).unwrap();
    ok(&[
        "simulate",
        "--model",
        p(&dir.join("model.toml")),
        "--input",
        p(&dir.join("u.csv")),
        "--out",
        p(&dir.join("data.csv")),
        "--noise-std",
        "0.1",
        "--seed",
        "3",
    ]);
    let config = dir.join("sweep.toml");
    std::fs::write(&config, CONFIG).unwrap();
    config
}

/// results.csv as (header, rows).
fn read_results(dir: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let mut r = csv::Reader::from_path(dir.join("results.csv")).unwrap();
    let header = r.headers().unwrap().iter().map(String::from).collect();
    let rows = r
        .records()
        .map(|rec| rec.unwrap().iter().map(String::from).collect())
        .collect();
    (header, rows)
}

/// results.csv without the run-time column.
fn results_without_time(dir: &Path) -> Vec<Vec<String>> {
    let (header, rows) = read_results(dir);
    let t = header.iter().position(|h| h == "run_time_s").unwrap();
    std::iter::once(header)
        .chain(rows)
        .map(|mut r| {
            r.remove(t);
            r
        })
        .collect()
}

fn case_contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir.join("cases"))
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect()
}

fn sweep(config: &Path, out: &Path, extra: &[&str]) -> Out {
    let mut args = vec![
        "compare",
        "--config",
        p(config),
        "--out",
        p(out),
        "--jobs",
        "2",
    ];
    args.extend_from_slice(extra);
    ok(&args)
}

#[test]
fn compare_writes_every_file_with_one_row_per_case() {
    let dir = tempfile::tempdir().unwrap();
    let config = setup(dir.path());
    let out = dir.path().join("runs/all");
    let o = sweep(&config, &out, &[]);
    assert!(o.stdout.contains("12 of 12"), "{}", o.stdout);

    let (header, rows) = read_results(&out);
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    assert_eq!(
        header[..7],
        [
            "case",
            "experiment",
            "dispersion",
            "seed",
            "beta",
            "sigma",
            "selection"
        ]
    );
    for c in [
        "map_rms_N",
        "val_rms_y",
        "val_fit_y",
        "cost_noise",
        "cost_dispersion",
    ] {
        col(c);
    }
    let ids: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    assert_eq!(ids, IDS);
    let status = |id: &str| &rows[IDS.iter().position(|i| *i == id).unwrap()][col("status")];
    for r in &rows {
        let id = r[0].as_str();
        if id.contains("/broken/") {
            // The feature solver cannot run a plain Gaussian: an error row, and the sweep went on.
            assert!(status(id).starts_with("error: "), "{id}: {}", status(id));
            assert_eq!(r[col("cost_total")], "");
            continue;
        }
        assert_eq!(status(id), "ok", "{id}");
        // A decent estimate of tanh(2z) from 120 samples with noise 0.1.
        let rms: f64 = r[col("map_rms_N")].parse().unwrap();
        assert!(rms < 0.15, "{id}: map RMS {rms}");
        let validated = id.starts_with("sim/");
        assert_eq!(r[col("val_fit_y")].is_empty(), !validated, "{id}");
        if validated {
            let fit: f64 = r[col("val_fit_y")].parse().unwrap();
            assert!(fit > 80.0, "{id}: fit {fit}");
        }
    }
    let auto = &rows[2];
    assert_eq!(auto[col("selection")], "ml");
    let beta: f64 = auto[col("beta")].parse().unwrap();
    assert!(beta > 0.0 && beta != 0.01);
    assert_eq!(rows[0][col("selection")], "fixed");
    assert_eq!(rows[0][col("sigma")], "0.3");
    assert_eq!(rows[4][col("solver")], "clarabel");
    assert_eq!(rows[8][col("seed")], "");

    // One case file per case, each a JSON object with its id.
    let cases = case_contents(&out);
    assert_eq!(cases.len(), IDS.len());
    for id in IDS {
        let name = format!("{}.json", id.replace('/', "+"));
        let v: serde_json::Value = serde_json::from_slice(&cases[&name]).unwrap();
        assert_eq!(v["id"], id);
    }
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains("## Summary") && md.contains("| sim/gauss/beta=auto/seed=9 |"));
    for f in [
        "overlay_sim.svg",
        "beta_sweep_sim.svg",
        "overlay_meas.svg",
        "beta_sweep_meas.svg",
    ] {
        let s = std::fs::read_to_string(out.join(f)).unwrap();
        assert!(s.starts_with("<svg") && s.contains("truth"), "{f}");
    }
    let overlay = std::fs::read_to_string(out.join("overlay_sim.svg")).unwrap();
    // The legend's labels, each line of a label wrapped to its strip joined back by a space.
    let texts: Vec<&str> = overlay
        .split("<text")
        .skip(1)
        .filter_map(|t| t.split('>').nth(1)?.split('<').next())
        .map(str::trim)
        .collect();
    let joined = texts.join(" ");
    assert!(
        joined.contains("gauss (auto ml: β = ") && joined.contains("tv (β = 0.001)"),
        "{texts:?}"
    );
}

#[test]
fn shards_merged_equal_an_unsharded_run() {
    let dir = tempfile::tempdir().unwrap();
    let config = setup(dir.path());
    let runs = dir.path().join("runs");
    sweep(&config, &runs.join("all"), &[]);
    sweep(&config, &runs.join("shard-0"), &["--shard", "0/2"]);
    sweep(&config, &runs.join("shard-1"), &["--shard", "1/2"]);
    assert_eq!(case_contents(&runs.join("shard-0")).len(), 6);
    assert_eq!(case_contents(&runs.join("shard-1")).len(), 6);
    let o = ok(&[
        "compare",
        "merge",
        p(&runs.join("shard-0")),
        p(&runs.join("shard-1")),
        "--out",
        p(&runs.join("merged")),
    ]);
    assert!(o.stdout.contains("merged 12 case(s) of 12"), "{}", o.stdout);
    assert_eq!(
        results_without_time(&runs.join("merged")),
        results_without_time(&runs.join("all"))
    );
    for f in ["overlay_sim.svg", "beta_sweep_meas.svg", "results.md"] {
        assert!(runs.join("merged").join(f).is_file(), "{f}");
    }

    // Identical duplicates are fine (shard 0 given twice, and the full run).
    ok(&[
        "compare",
        "merge",
        p(&runs.join("shard-0")),
        p(&runs.join("all")),
        p(&runs.join("shard-0")),
        "--out",
        p(&runs.join("merged2")),
    ]);
    assert_eq!(
        results_without_time(&runs.join("merged2")),
        results_without_time(&runs.join("all"))
    );

    // A duplicate with other results is refused, naming the case.
    let changed = runs.join("changed");
    std::fs::create_dir_all(changed.join("cases")).unwrap();
    let name = "meas+gauss+beta=0.01.json";
    let text = std::fs::read_to_string(runs.join("all/cases").join(name)).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["blocks"][0]["rms_error"] = serde_json::json!(123.0);
    std::fs::write(changed.join("cases").join(name), v.to_string()).unwrap();
    let e = input_error(&[
        "compare",
        "merge",
        p(&runs.join("all")),
        p(&changed),
        "--out",
        p(&runs.join("merged3")),
    ]);
    assert!(
        e.contains("case `meas/gauss/beta=0.01`") && e.contains("different results"),
        "{e}"
    );
    // Merging into a directory that already has case files, or from a non-run directory.
    let e = input_error(&[
        "compare",
        "merge",
        p(&runs.join("shard-0")),
        "--out",
        p(&runs.join("merged")),
    ]);
    assert!(e.contains("already holds case files"), "{e}");
    let e = input_error(&[
        "compare",
        "merge",
        p(dir.path()),
        "--out",
        p(&runs.join("m4")),
    ]);
    assert!(e.contains("has no case files"), "{e}");
}

#[test]
fn resume_does_not_redo_finished_cases() {
    let dir = tempfile::tempdir().unwrap();
    let config = setup(dir.path());
    let out = dir.path().join("out");
    sweep(&config, &out, &[]);
    let before = case_contents(&out);
    let gone = "sim+gauss+beta=auto+seed=9.json";
    std::fs::remove_file(out.join("cases").join(gone)).unwrap();
    // An interrupted write leaves a truncated file at worst (writes are atomic, but a user may
    // copy one); it does not parse and is recomputed.
    let truncated = "meas+tv+beta=0.001.json";
    let t = &before[truncated];
    std::fs::write(out.join("cases").join(truncated), &t[..t.len() / 2]).unwrap();

    // Without --resume the directory is refused.
    let e = input_error(&["compare", "--config", p(&config), "--out", p(&out)]);
    assert!(e.contains("--resume"), "{e}");

    let o = sweep(&config, &out, &["--resume"]);
    assert!(
        o.stdout.contains("ran 2 case(s) (10 skipped"),
        "{}",
        o.stdout
    );
    let after = case_contents(&out);
    assert_eq!(after.len(), before.len());
    for (name, bytes) in &before {
        if name == gone || name == truncated {
            let v: serde_json::Value = serde_json::from_slice(&after[name]).unwrap();
            assert_eq!(v["status"], "ok", "{name}");
        } else {
            // Untouched: the content includes the run time, which a rerun would change.
            assert_eq!(&after[name], bytes, "{name} was rewritten");
        }
    }
    let (_, rows) = read_results(&out);
    assert_eq!(rows.len(), IDS.len());

    // A changed configuration is not mixed with old results.
    std::fs::write(
        &config,
        CONFIG.replace("noise_std = 0.1", "noise_std = 0.2"),
    )
    .unwrap();
    let e = input_error(&[
        "compare",
        "--config",
        p(&config),
        "--out",
        p(&out),
        "--resume",
    ]);
    assert!(
        e.contains("cannot resume") && e.contains("sim/gauss"),
        "{e}"
    );
}

#[test]
fn malformed_configs_name_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let config = setup(dir.path());
    let out = dir.path().join("out");
    for (from, to, line, needle) in [
        (
            "beta = 0.001",
            "beta = -0.001",
            24,
            "beta = -0.001 is invalid",
        ),
        (
            "kind = \"tv\"",
            "kind = \"tvv\"",
            23,
            "unknown dispersion kind `tvv`",
        ),
        ("seeds = [4, 9]", "seeds = [4, 9", 11, "invalid TOML"),
        (
            "name = \"meas\"",
            "name = \"sim\"",
            12,
            "two experiments are named `sim`",
        ),
    ] {
        std::fs::write(&config, CONFIG.replace(from, to)).unwrap();
        let e = input_error(&["compare", "--config", p(&config), "--out", p(&out)]);
        assert!(
            e.contains(&format!("sweep config `{}`", config.display())) && e.contains(needle),
            "{to}: {e}"
        );
        assert!(
            e.contains(&format!("(line {line}")),
            "{to}: expected line {line}: {e}"
        );
    }
    // Files named by the configuration are checked before any case runs.
    std::fs::write(&config, CONFIG.replace("\"data.csv\"", "\"missing.csv\"")).unwrap();
    let e = input_error(&["compare", "--config", p(&config), "--out", p(&out)]);
    assert!(
        e.contains("experiment `meas`: estimation data `missing.csv` (line 14)"),
        "{e}"
    );
    assert!(!out.exists(), "nothing is written for a bad configuration");
}

#[test]
fn bad_shards_and_jobs_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let config = setup(dir.path());
    let out = dir.path().join("out");
    for (shard, needle) in [
        (
            "2/2",
            "shard index 2 is not less than the number of shards 2",
        ),
        ("0/0", "at least 1"),
        ("1", "not of the form i/n"),
        ("x/3", "not a whole number"),
    ] {
        let e = input_error(&[
            "compare",
            "--config",
            p(&config),
            "--out",
            p(&out),
            "--shard",
            shard,
        ]);
        assert!(e.contains("--shard") && e.contains(needle), "{shard}: {e}");
    }
    let e = input_error(&[
        "compare",
        "--config",
        p(&config),
        "--out",
        p(&out),
        "--jobs",
        "0",
    ]);
    assert!(e.contains("--jobs"), "{e}");
    assert!(!out.exists());
}

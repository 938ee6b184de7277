//! Data files as MATLAB MAT-files and NumPy arrays: `--vars` picks the signals, and the
//! results are those of the same record as CSV.

mod common;

use std::path::Path;

use common::{input_error, ok, p};

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
dispersion = { kind = "gaussian", sigma = 0.5 }
"#;

/// u on [−2, 2] and y = u² plus a deterministic disturbance.
fn record() -> (Vec<f64>, Vec<f64>) {
    let n = 200;
    let u: Vec<f64> = (0..n)
        .map(|k| -2.0 + 4.0 * ((k * 37) % n) as f64 / (n - 1) as f64)
        .collect();
    let y = u
        .iter()
        .enumerate()
        .map(|(k, v)| v * v + 0.05 * (1.3 * k as f64).sin())
        .collect();
    (u, y)
}

fn le32(v: u32) -> [u8; 4] {
    v.to_le_bytes()
}

/// An uncompressed MAT v5 element, padded to 8 bytes.
fn element(ty: u32, data: &[u8]) -> Vec<u8> {
    let mut out = le32(ty).to_vec();
    out.extend(le32(data.len() as u32));
    out.extend(data);
    while !out.len().is_multiple_of(8) {
        out.push(0);
    }
    out
}

/// A double matrix variable.
fn variable(name: &str, rows: usize, cols: usize, values: &[f64]) -> Vec<u8> {
    let mut body = element(6, &[6, 0, 0, 0, 0, 0, 0, 0]);
    let mut dims = le32(rows as u32).to_vec();
    dims.extend(le32(cols as u32));
    body.extend(element(5, &dims));
    body.extend(element(1, name.as_bytes()));
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    body.extend(element(9, &data));
    element(14, &body)
}

fn mat_file(vars: &[Vec<u8>]) -> Vec<u8> {
    let mut out = format!("{:<116}", "MATLAB 5.0 MAT-file, Platform: test").into_bytes();
    out.extend([0; 8]);
    out.extend([0, 1]);
    out.extend(b"IM");
    for v in vars {
        out.extend(v);
    }
    out
}

/// A `.npy` file of an L×2 float64 array (C order).
fn npy(u: &[f64], y: &[f64]) -> Vec<u8> {
    let header = format!(
        "{{'descr': '<f8', 'fortran_order': False, 'shape': ({}, 2), }}",
        u.len()
    );
    let header = format!("{header:<117}\n");
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    for (a, b) in u.iter().zip(y) {
        out.extend(a.to_le_bytes());
        out.extend(b.to_le_bytes());
    }
    out
}

fn files(dir: &Path) {
    let (u, y) = record();
    std::fs::write(dir.join("model.toml"), MODEL).unwrap();
    let mut csv = String::from("u,y\n");
    for (a, b) in u.iter().zip(&y) {
        csv.push_str(&format!("{a:?},{b:?}\n"));
    }
    std::fs::write(dir.join("d.csv"), csv).unwrap();
    // u as a row vector, y as a column, plus a matrix and a text variable.
    let both: Vec<f64> = y.iter().chain(&u).copied().collect();
    let mat = mat_file(&[
        variable("vir", 1, u.len(), &u),
        variable("qm", y.len(), 1, &y),
        variable("yu", y.len(), 2, &both),
    ]);
    std::fs::write(dir.join("d.mat"), mat).unwrap();
    std::fs::write(dir.join("d.npy"), npy(&u, &y)).unwrap();
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap()
}

#[test]
fn identify_on_a_mat_file_equals_identify_on_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    files(d);
    let model = d.join("model.toml");
    let run = |data: &str, vars: Option<&str>, out: &str| {
        let data = d.join(data);
        let out = d.join(out);
        let mut args = vec![
            "identify",
            "--model",
            p(&model),
            "--data",
            p(&data),
            "--out",
            p(&out),
            "--beta",
            "0.01",
        ];
        if let Some(v) = vars {
            args.extend(["--vars", v]);
        }
        ok(&args);
        (
            read(&out.join("estimate.csv")),
            read(&out.join("map_N.csv")),
        )
    };
    let csv = run("d.csv", None, "csv");
    assert_eq!(run("d.mat", Some("u=vir,y=qm"), "mat"), csv);
    assert_eq!(run("d.mat", Some("y=yu#0,u=yu#1"), "mat_columns"), csv);
    assert_eq!(run("d.npy", Some("u=#0,y=#1"), "npy"), csv);

    // validate and predict on the MAT-file, with the stored estimate.
    let estimate = d.join("mat/estimate.json");
    let mat = d.join("d.mat");
    let v = d.join("validation");
    ok(&[
        "validate",
        "--estimate",
        p(&estimate),
        "--data",
        p(&mat),
        "--out",
        p(&v),
        "--vars",
        "u=vir,y=qm",
    ]);
    let vc = d.join("validation_csv");
    let csvp = d.join("d.csv");
    ok(&[
        "validate",
        "--estimate",
        p(&estimate),
        "--data",
        p(&csvp),
        "--out",
        p(&vc),
    ]);
    assert_eq!(
        read(&v.join("simulation.csv")),
        read(&vc.join("simulation.csv"))
    );
    // --vars before the subcommand works too (a global option).
    let pr = d.join("prediction");
    ok(&[
        "--vars",
        "u=vir,y=qm",
        "predict",
        "--estimate",
        p(&estimate),
        "--data",
        p(&mat),
        "--out",
        p(&pr),
    ]);
}

#[test]
fn data_csv_converts_a_mat_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    files(d);
    let (mat, out) = (d.join("d.mat"), d.join("out.csv"));
    let o = ok(&[
        "data",
        "csv",
        "--file",
        p(&mat),
        "--vars",
        "u=vir,y=qm",
        "--range",
        "10..",
        "--out",
        p(&out),
    ]);
    assert!(
        o.stdout
            .contains("190 samples (rows 10..200 of 200 data rows), columns u, y"),
        "{}",
        o.stdout
    );
    let converted = structid_io::DataTable::read(&out).unwrap();
    let original = structid_io::DataTable::read(&d.join("d.csv")).unwrap();
    assert_eq!(converted.names, ["u", "y"]);
    for c in 0..2 {
        assert_eq!(converted.columns[c], original.columns[c][10..]);
    }
}

#[test]
fn mat_file_errors_are_input_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    files(d);
    let model = d.join("model.toml");
    let mat = d.join("d.mat");
    let out = d.join("out");
    let id = |data: &Path, vars: Option<&str>| {
        let mut args = vec![
            "identify",
            "--model",
            p(&model),
            "--data",
            p(data),
            "--out",
            p(&out),
        ];
        if let Some(v) = vars {
            args.extend(["--vars", v]);
        }
        input_error(&args)
    };
    // Without --vars the variables are the columns: the model's u and y are missing.
    let e = id(&mat, None);
    assert!(
        e.contains("has no column `u`") && e.contains("`vir`, `qm`, `yu#0`, `yu#1`"),
        "{e}"
    );
    let e = id(&mat, Some("u=vir,y=q"));
    assert!(
        e.contains("the file has no variable `q`; it holds vir (1×200), qm (200×1), yu (200×2)"),
        "{e}"
    );
    let e = id(&mat, Some("u=yu,y=qm"));
    assert!(e.contains("200×2 matrix") && e.contains("`yu#0`"), "{e}");
    let e = id(&mat, Some("u=vir,,y=qm"));
    assert!(e.contains("invalid variable selection"), "{e}");
    // A v7.3 file.
    let v73 = d.join("v73.mat");
    let mut bytes = format!("{:<116}", "MATLAB 7.3 MAT-file, Platform: GLNXA64").into_bytes();
    bytes.resize(512, 0);
    bytes.extend(b"\x89HDF\r\n\x1a\n");
    std::fs::write(&v73, bytes).unwrap();
    let e = id(&v73, Some("u=vir,y=qm"));
    assert!(
        e.contains("MATLAB v7.3 MAT-file (HDF5)") && e.contains("'-v7'"),
        "{e}"
    );
    // A truncated file.
    let cut = d.join("cut.mat");
    let full = std::fs::read(&mat).unwrap();
    std::fs::write(&cut, &full[..full.len() / 2]).unwrap();
    let e = id(&cut, Some("u=vir,y=qm"));
    assert!(e.contains("truncated"), "{e}");
    // --vars on a command that reads no data file, or with text-file options.
    let e = input_error(&[
        "data",
        "csv",
        "--file",
        p(&mat),
        "--columns",
        "u",
        "--out",
        p(&out),
    ]);
    assert!(e.contains("choose and name its signals with --vars"), "{e}");
    let csv = d.join("d.csv");
    let e = input_error(&[
        "data",
        "csv",
        "--file",
        p(&csv),
        "--vars",
        "u=u",
        "--out",
        p(&out),
    ]);
    assert!(e.contains("is a text file"), "{e}");
    let e = input_error(&[
        "data",
        "silverbox",
        "--file",
        p(&mat),
        "--split",
        "all",
        "--vars",
        "u=vir",
        "--out",
        p(&out),
    ]);
    assert!(e.contains("--vars selects"), "{e}");
    let e = input_error(&["demo", "spray", "--vars", "u=vir", "--out", p(&out)]);
    assert!(e.contains("--vars selects"), "{e}");
    assert!(!out.exists());
}

//! `structid input`: designed excitations written as CSV files.

mod common;

use common::{input_error, ok, p};

fn column(path: &std::path::Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let c = header.iter().position(|h| *h == name).expect("column");
    lines
        .map(|l| l.split(',').nth(c).unwrap().parse().unwrap())
        .collect()
}

#[test]
fn prbs_is_balanced_periodic_and_reproducible() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.csv");
    let o = ok(&[
        "input",
        "prbs",
        "--length",
        "2046",
        "--order",
        "10",
        "--amplitude",
        "0.5",
        "--offset",
        "1",
        "--out",
        p(&a),
    ]);
    assert!(o.stdout.contains("PRBS: 2046 samples"), "{}", o.stdout);
    let u = column(&a, "u");
    assert_eq!(u.len(), 2046);
    assert_eq!(u[..1023], u[1023..]);
    assert_eq!(u[..1023].iter().filter(|&&v| v == 1.5).count(), 512);
    assert_eq!(u[..1023].iter().filter(|&&v| v == 0.5).count(), 511);
    // The same seed gives the same file; another seed another start.
    let b = dir.path().join("b.csv");
    ok(&[
        "input",
        "prbs",
        "--length",
        "2046",
        "--order",
        "10",
        "--amplitude",
        "0.5",
        "--offset",
        "1",
        "--out",
        p(&b),
    ]);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let c = dir.path().join("c.csv");
    ok(&[
        "input",
        "prbs",
        "--length",
        "2046",
        "--order",
        "10",
        "--seed",
        "9",
        "--out",
        p(&c),
    ]);
    assert_ne!(
        column(&c, "u"),
        column(&a, "u")
            .iter()
            .map(|v| 2.0 * (v - 1.0))
            .collect::<Vec<_>>()
    );
}

#[test]
fn every_kind_writes_a_readable_file() {
    let dir = tempfile::tempdir().unwrap();
    let runs: Vec<Vec<&str>> = vec![
        vec![
            "multisine",
            "--odd",
            "--min-crest",
            "--band",
            "1,20",
            "--sample-time",
            "0.01",
        ],
        vec!["multisine", "--lines", "3,5,9", "--period", "128"],
        vec!["noise", "--band", "0.05,0.2", "--amplitude", "2"],
        vec!["chirp", "--sweep", "log", "--band", "0.01,0.4"],
        vec![
            "steps",
            "--hold",
            "5,20",
            "--name",
            "force",
            "--time",
            "--sample-time",
            "0.5",
        ],
    ];
    for (i, args) in runs.iter().enumerate() {
        let out = dir.path().join(format!("{i}.csv"));
        let mut all = vec!["input"];
        all.extend(args.iter().copied());
        all.extend(["--length", "512", "--out", p(&out)]);
        ok(&all);
        let name = if i == 4 { "force" } else { "u" };
        let u = column(&out, name);
        assert_eq!(u.len(), 512, "{args:?}");
        assert!(u.iter().all(|v| v.is_finite()));
    }
    let t = column(&dir.path().join("4.csv"), "time");
    assert_eq!(t[..3], [0.0, 0.5, 1.0]);
    // The file reads back as a data file.
    let u = column(&dir.path().join("0.csv"), "u");
    assert!((u.iter().fold(0.0f64, |m, v| m.max(v.abs())) - 1.0).abs() < 1e-12);
}

#[test]
fn bad_arguments_are_input_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("u.csv");
    let o = p(&out);
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["prbs", "--length", "0", "--out", o], "invalid length"),
        (
            vec!["prbs", "--length", "100", "--order", "40", "--out", o],
            "invalid order",
        ),
        (
            vec!["prbs", "--length", "100", "--band", "0.1,0.3", "--out", o],
            "lower edge",
        ),
        (
            vec!["noise", "--length", "100", "--band", "0.3,0.2", "--out", o],
            "invalid band",
        ),
        (
            vec!["noise", "--length", "100", "--band", "0,0.7", "--out", o],
            "Nyquist",
        ),
        (
            vec!["noise", "--length", "100", "--band", "x", "--out", o],
            "for --band",
        ),
        (
            vec!["chirp", "--length", "100", "--amplitude", "-1", "--out", o],
            "invalid amplitude",
        ),
        (
            vec!["chirp", "--length", "100", "--sample-time", "0", "--out", o],
            "invalid sample time",
        ),
        (
            vec!["multisine", "--length", "100", "--lines", "3,x", "--out", o],
            "for --lines",
        ),
        (
            vec!["multisine", "--length", "100", "--lines", "60", "--out", o],
            "harmonic 60",
        ),
        (
            vec!["steps", "--length", "100", "--hold", "5", "--out", o],
            "for --hold",
        ),
        (
            vec!["steps", "--length", "100", "--hold", "9,3", "--out", o],
            "invalid hold",
        ),
        (
            vec!["steps", "--length", "100", "--name", " ", "--out", o],
            "--name",
        ),
        (
            vec!["prbs", "--length", "100", "--out", p(dir.path())],
            "cannot write the output",
        ),
        (
            vec!["prbs", "--length", "100", "--vars", "u=x", "--out", o],
            "--vars",
        ),
    ];
    for (args, want) in cases {
        let mut all = vec!["input"];
        all.extend(args.iter().copied());
        let e = input_error(&all);
        assert!(e.contains(want), "{args:?}: want `{want}` in {e}");
    }
    assert!(!out.exists());
}

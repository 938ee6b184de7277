//! Killed runs leave no corrupt results. SIGKILL at moments spread over a whole `identify`
//! (the last ones during its writes), and twice during a `compare` sweep, leaves under the
//! final names only files written in full, `.complete` lists only files that exist, and the
//! next run (`--resume` for the sweep) finishes, lists its whole set and leaves no temporary
//! file behind.

#![cfg(unix)]

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::*;

/// Every file under a final name in `dir` is whole: JSON parses, every CSV row has the
/// header's number of fields and the file ends with a newline, an SVG is closed. Returns the
/// names found.
fn assert_whole(dir: &Path, when: &str) -> Vec<String> {
    let mut names = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return names;
    };
    for e in entries {
        let e = e.unwrap();
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || e.file_type().unwrap().is_dir() {
            continue;
        }
        let text = std::fs::read_to_string(e.path()).unwrap();
        if name.ends_with(".json") {
            assert!(
                serde_json::from_str::<serde_json::Value>(&text).is_ok(),
                "{when}: {name} is not whole JSON ({} bytes)",
                text.len()
            );
        } else if name.ends_with(".csv") {
            assert!(text.ends_with('\n'), "{when}: {name} is cut short");
            let mut lines = text.lines();
            let fields = lines.next().unwrap().split(',').count();
            for (k, l) in lines.enumerate() {
                assert_eq!(
                    l.split(',').count(),
                    fields,
                    "{when}: {name}, row {k} is cut"
                );
            }
        } else if name.ends_with(".svg") {
            assert!(
                text.trim_end().ends_with("</svg>"),
                "{when}: {name} is cut short"
            );
        }
        names.push(name);
    }
    if let Ok(listed) = std::fs::read_to_string(dir.join(".complete")) {
        for l in listed
            .lines()
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
        {
            assert!(
                names.iter().any(|n| n == l),
                "{when}: .complete lists missing {l}"
            );
        }
    }
    names
}

#[test]
fn sigkill_during_identify_leaves_whole_files_or_none_and_the_next_run_recovers() {
    let dir = tempfile::tempdir().unwrap();
    let demo = dir.path().join("demo");
    ok(&["demo", "spray", "--out", p(&demo), "--samples", "1200"]);
    let model = demo.join("model.toml");
    let data = demo.join("data.csv");
    let out = dir.path().join("result");
    let args = [
        "identify",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&out),
        "--beta",
        "auto",
    ];
    // The length of a whole run, to spread the kills over it.
    let t = Instant::now();
    ok(&args);
    let whole = t.elapsed();
    let expected = assert_whole(&out, "after a whole run");
    std::fs::remove_dir_all(&out).unwrap();

    for share in [0.3, 0.6, 0.8, 0.9, 0.95, 0.98, 1.0, 1.02] {
        let mut child = Command::new(BIN)
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(whole.mul_f64(share));
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        assert_whole(&out, &format!("killed at {:.0} % of a run", 100.0 * share));
    }
    // An interrupted directory is not trusted as a result until a run finishes in it.
    ok(&args);
    let mut names = assert_whole(&out, "after the recovering run");
    names.sort();
    let mut expected = expected;
    expected.sort();
    assert_eq!(names, expected);
    let temporary: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp-"))
        .collect();
    assert!(temporary.is_empty(), "temporary files left: {temporary:?}");
    let listed = std::fs::read_to_string(out.join(".complete")).unwrap();
    for n in &expected {
        assert!(listed.lines().any(|l| l == n), ".complete misses {n}");
    }
    assert!(whole < Duration::from_secs(60));
}

/// A `compare` sweep (the paper's 36 cases) killed twice part-way, then resumed: every file
/// under a final name is whole after each kill, and `--resume` finishes the sweep with one
/// whole result per case and no temporary file left.
#[test]
fn sigkill_during_a_compare_sweep_leaves_whole_files_and_resume_finishes_it() {
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/compare/paper.toml");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sweep");
    let args = |resume: bool| {
        let mut a = vec![
            "compare".to_string(),
            "--config".into(),
            p(&config).into(),
            "--out".into(),
            p(&out).into(),
        ];
        if resume {
            a.push("--resume".into());
        }
        a
    };
    for (resume, after) in [(false, 1.5), (true, 0.8)] {
        let mut child = Command::new(BIN)
            .args(args(resume))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_secs_f64(after));
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        let when = format!("killed after {after} s");
        assert_whole(&out, &when);
        assert_whole(&out.join("cases"), &when);
    }
    let a = args(true);
    ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert_whole(&out, "after the resumed sweep");
    let cases = assert_whole(&out.join("cases"), "after the resumed sweep");
    assert_eq!(cases.len(), 36, "{cases:?}");
    let results = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(results.lines().count(), 37, "a header and one row per case");
    for d in [out.clone(), out.join("cases")] {
        let temporary: Vec<String> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp-"))
            .collect();
        assert!(
            temporary.is_empty(),
            "temporary files left in {d:?}: {temporary:?}"
        );
    }
}

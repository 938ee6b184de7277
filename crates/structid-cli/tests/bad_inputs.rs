//! A corpus of bad inputs run through every command of the `structid` binary.
//!
//! Each case names the command line, the exit code it must give (2 for input mistakes, the
//! same for every `--out` mistake in every command), a phrase of stderr that names the
//! problem, and the output paths that must not exist afterwards. Every case also checks that
//! nothing panicked, that no backtrace hint was printed, that stderr stays short (fields are
//! not echoed in full) and that the input files are byte-for-byte unchanged.
//!
//! The 10⁷-row data file is written once (40 MB of `0,0` rows, a single write); the commands
//! refuse it after counting its first 10⁶ + 1 rows, before parsing anything
//! (`structid_io::data_file::MAX_ROWS`), so it costs milliseconds per command. `data csv`, the
//! tool that cuts long files, is limited by the available memory instead and reads it when the
//! machine has the memory (about 2 GB and 9 s here): it is not run on that file.
//!
//! Two more tests check what a killed run leaves: stale `.tmp-PID` files are removed by the
//! next run into their directory, a result directory's `.complete` lists a set only once it is
//! written in full, and `compare --resume` reruns incomplete cases.
//!
//! Set `BAD_INPUTS_SHOW=1` to print every case's stderr.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

mod common;
use common::*;

/// The model of the corpus: the Hammerstein example (map N at the input of a known G).
fn model_text() -> String {
    std::fs::read_to_string(example_model("hammerstein.toml")).unwrap()
}

/// A reproducible input on [−1, 1] (a small LCG).
fn input_csv(len: usize, seed: u64) -> String {
    let mut state = seed;
    let mut s = String::from("u\n");
    for _ in 0..len {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let u = ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
        s.push_str(&format!("{u}\n"));
    }
    s
}

/// 64-bit FNV-1a of a file's bytes (`None` when it does not exist).
fn hash_file(path: &Path) -> Option<(u64, u64)> {
    let bytes = std::fs::read(path).ok()?;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in &bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    Some((bytes.len() as u64, h))
}

/// One command line of the corpus and what it must give.
struct Case {
    name: String,
    args: Vec<String>,
    code: i32,
    phrases: Vec<String>,
    /// Final output names that must not exist after the run.
    absent: Vec<PathBuf>,
    /// Whether the run succeeds and its outputs are removed afterwards.
    cleanup: bool,
}

/// A case expecting exit code 2 and `phrase` in stderr.
fn case(name: &str, args: &[&str], phrase: &str) -> Case {
    Case {
        name: name.into(),
        args: args.iter().map(|s| s.to_string()).collect(),
        code: 2,
        phrases: if phrase.is_empty() {
            Vec::new()
        } else {
            vec![phrase.to_string()]
        },
        absent: Vec::new(),
        cleanup: false,
    }
}

impl Case {
    fn absent(mut self, p: &Path) -> Self {
        self.absent.push(p.to_path_buf());
        self
    }
}

/// The fixtures: a model, records, a stored estimate, a nominal model and a sweep.
struct Fixtures {
    dir: tempfile::TempDir,
}

impl Fixtures {
    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
    fn s(&self, name: &str) -> String {
        p(&self.path(name)).to_string()
    }
    fn write(&self, name: &str, text: &str) -> String {
        std::fs::write(self.path(name), text).unwrap();
        self.s(name)
    }
    /// The model file with `from` replaced by `to` (which must change it).
    fn model_variant(&self, name: &str, from: &str, to: &str) -> String {
        let text = model_text();
        assert!(text.contains(from), "{from}");
        self.write(name, &text.replacen(from, to, 1))
    }
}

fn fixtures() -> Fixtures {
    let f = Fixtures {
        dir: tempfile::tempdir().unwrap(),
    };
    f.write("model.toml", &model_text());
    f.write("u.csv", &input_csv(300, 1));
    f.write("u_val.csv", &input_csv(200, 2));
    for (input, out, seed) in [("u.csv", "data.csv", "3"), ("u_val.csv", "val.csv", "4")] {
        ok(&[
            "simulate",
            "--model",
            &f.s("model.toml"),
            "--input",
            &f.s(input),
            "--out",
            &f.s(out),
            "--noise-std",
            "0.05",
            "--seed",
            seed,
        ]);
    }
    ok(&[
        "identify",
        "--model",
        &f.s("model.toml"),
        "--data",
        &f.s("data.csv"),
        "--out",
        &f.s("est"),
        "--no-bands",
    ]);
    ok(&[
        "linear",
        "--data",
        &f.s("data.csv"),
        "--orders",
        "2,2,1",
        "--method",
        "arx",
        "--out",
        &f.s("lti.toml"),
    ]);
    std::fs::write(f.path("existing.txt"), "not a directory\n").unwrap();
    std::fs::create_dir(f.path("existing_dir")).unwrap();
    f.write(
        "sweep.toml",
        "[[experiment]]\nname = \"meas\"\nmodel = \"model.toml\"\nestimation = \"data.csv\"\n\n\
         [[dispersion]]\nname = \"gauss\"\nkind = \"gaussian\"\nbeta = 0.01\n",
    );

    ok(&[
        "compare",
        "--config",
        &f.s("sweep.toml"),
        "--out",
        &f.s("cmp"),
        "--jobs",
        "1",
    ]);
    // Input files under an output's name inside the output directory.
    let clash = f.path("clash");
    std::fs::create_dir(&clash).unwrap();
    for name in ["estimate.csv", "simulation.csv", "prediction.csv"] {
        std::fs::copy(f.path("data.csv"), clash.join(name)).unwrap();
    }

    // The data corpus (columns u, y).
    let good_rows: String = (0..50)
        .map(|k| format!("{},{}\n", (k as f64 * 0.1).sin(), (k as f64 * 0.1).cos()))
        .collect();
    f.write("empty.csv", "");
    f.write("header_only.csv", "u,y\n");
    f.write("one_row.csv", "u,y\n0.1,0.2\n");
    f.write("constant.csv", &format!("u,y\n{}", "0.5,0.7\n".repeat(300)));
    f.write(
        "nan.csv",
        &format!("u,y\n0.1,0.2\n0.3,0.4\n0.5,NaN\n{good_rows}"),
    );
    f.write("inf.csv", &format!("u,y\n0.1,0.2\ninf,0.4\n{good_rows}"));
    f.write("ragged.csv", &format!("u,y\n0.1,0.2\n0.3\n{good_rows}"));
    f.write("wrong_names.csv", &format!("a,b\n{good_rows}"));
    f.write(
        "missing_y.csv",
        &format!(
            "u\n{}",
            (0..50).map(|k| format!("{k}\n")).collect::<String>()
        ),
    );
    let big_field = "x".repeat(2 << 20);
    f.write("big_field.csv", &format!("u,y\n0.1,0.2\n0.3,{big_field}\n"));
    // 10⁷ rows in one write.
    let mut huge = Vec::with_capacity(4 + 4 * 10_000_000);
    huge.extend_from_slice(b"u,y\n");
    for _ in 0..10_000_000 {
        huge.extend_from_slice(b"0,0\n");
    }
    std::fs::write(f.path("huge.csv"), huge).unwrap();
    f
}

/// The data-file corpus: each file and the phrase its refusal must contain.
const DATA_CORPUS: [(&str, &str); 11] = [
    ("empty.csv", "the file is empty"),
    ("header_only.csv", "has a header row but no data rows"),
    ("one_row.csv", ""),
    ("constant.csv", ""),
    ("nan.csv", "line 4, column `y`: value is NaN"),
    ("inf.csv", "line 3, column `u`: value is infinite"),
    ("ragged.csv", "line 3: expected 2 field(s)"),
    (
        "wrong_names.csv",
        "has no column `u`; available columns: `a`, `b`",
    ),
    ("missing_y.csv", "has no column `y`; available columns: `u`"),
    ("big_field.csv", "(2097152 characters)"),
    ("huge.csv", "has more than 1000000 data rows"),
];

/// What a command must do with a data file of the corpus whose refusal is command-specific
/// (one row, constant) or that it accepts: `None` to skip, `Some((0, ""))` when the file is a
/// valid input, else the exit code and the phrase.
fn data_expectation(cmd: &str, file: &str, phrase: &'static str) -> Option<(i32, &'static str)> {
    let excitation = "is constant";
    Some(match (file, cmd) {
        // `data csv` cuts long files; it is limited by the memory, not by the row limit, and
        // reads 10⁷ rows when the machine has the memory: not run here.
        ("huge.csv", "data csv") => return None,
        ("one_row.csv" | "constant.csv", "identify" | "refine") => (2, excitation),
        ("one_row.csv" | "constant.csv", "discover --data") => (2, "u is constant"),
        ("one_row.csv" | "constant.csv", "discover --validate") => (2, "u is constant"),
        ("one_row.csv", "linear") => (2, "too few samples"),
        ("constant.csv", "linear") => (2, "singular regression"),
        ("one_row.csv", "validate" | "validate --estimate") => (2, "--max-lag"),
        // Simulation reads the inputs only.
        ("missing_y.csv", "simulate" | "simulate --estimate") => (0, ""),
        // Simulating, predicting, validating on or cutting a short or constant record is fine.
        ("one_row.csv" | "constant.csv", _) => (0, ""),
        _ => (2, phrase),
    })
}

fn corpus(f: &Fixtures) -> Vec<Case> {
    let mut cases = Vec::new();
    let m = f.s("model.toml");
    let data = f.s("data.csv");
    let val = f.s("val.csv");
    let u = f.s("u.csv");
    let est = f.s("est/estimate.json");
    let out_dir = f.path("out");
    let o = p(&out_dir).to_string();
    let out_csv = f.path("out.csv");
    let oc = p(&out_csv).to_string();
    let out_toml = f.path("out.toml");
    let ot = p(&out_toml).to_string();
    let lti = f.s("lti.toml");
    let sweep = f.s("sweep.toml");

    // Every command that reads a data file, with the data file as its last-but-two argument.
    type Make = Box<dyn Fn(&str) -> (Vec<String>, PathBuf)>;
    let sv = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let readers: Vec<(&str, Make)> = {
        let (m, o, oc, ot, est, lti, val, data) = (
            m.clone(),
            o.clone(),
            oc.clone(),
            ot.clone(),
            est.clone(),
            lti.clone(),
            val.clone(),
            data.clone(),
        );
        let (od, ocp, otp) = (out_dir.clone(), out_csv.clone(), out_toml.clone());
        vec![
            ("identify", {
                let (m, o, od) = (m.clone(), o.clone(), od.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&["identify", "--model", &m, "--data", d, "--out", &o]),
                        od.clone(),
                    )
                })
            }),
            ("simulate", {
                let (m, oc, ocp) = (m.clone(), oc.clone(), ocp.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&["simulate", "--model", &m, "--input", d, "--out", &oc]),
                        ocp.clone(),
                    )
                })
            }),
            ("simulate --estimate", {
                let (est, oc, ocp) = (est.clone(), oc.clone(), ocp.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&["simulate", "--estimate", &est, "--input", d, "--out", &oc]),
                        ocp.clone(),
                    )
                })
            }),
            ("validate", {
                let (m, o, od) = (m.clone(), o.clone(), od.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&["validate", "--model", &m, "--data", d, "--out", &o]),
                        od.clone(),
                    )
                })
            }),
            ("validate --estimate", {
                let (est, o, od) = (est.clone(), o.clone(), od.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&["validate", "--estimate", &est, "--data", d, "--out", &o]),
                        od.clone(),
                    )
                })
            }),
            ("predict", {
                let (est, o, od) = (est.clone(), o.clone(), od.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&["predict", "--estimate", &est, "--data", d, "--out", &o]),
                        od.clone(),
                    )
                })
            }),
            ("linear", {
                let (ot, otp) = (ot.clone(), otp.clone());
                Box::new(move |d: &str| (sv(&["linear", "--data", d, "--out", &ot]), otp.clone()))
            }),
            ("refine", {
                let (m, o, od) = (m.clone(), o.clone(), od.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&["refine", "--model", &m, "--data", d, "--out", &o]),
                        od.clone(),
                    )
                })
            }),
            ("discover --data", {
                let (lti, val, o, od) = (lti.clone(), val.clone(), o.clone(), od.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&[
                            "discover",
                            "--model",
                            &lti,
                            "--data",
                            d,
                            "--validate",
                            &val,
                            "--out",
                            &o,
                        ]),
                        od.clone(),
                    )
                })
            }),
            ("discover --validate", {
                let (lti, data, o, od) = (lti.clone(), data.clone(), o.clone(), od.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&[
                            "discover",
                            "--model",
                            &lti,
                            "--data",
                            &data,
                            "--validate",
                            d,
                            "--out",
                            &o,
                        ]),
                        od.clone(),
                    )
                })
            }),
            ("data csv", {
                let (oc, ocp) = (oc.clone(), ocp.clone());
                Box::new(move |d: &str| {
                    (
                        sv(&["data", "csv", "--file", d, "--columns", "u,y", "--out", &oc]),
                        ocp.clone(),
                    )
                })
            }),
        ]
    };
    for (file, phrase) in DATA_CORPUS {
        for (cmd, make) in &readers {
            let Some((code, phrase)) = data_expectation(cmd, file, phrase) else {
                continue;
            };
            let (args, out) = make(&f.s(file));
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let mut c = case(&format!("{cmd} / {file}"), &args, phrase);
            c.code = code;
            if code != 0 {
                c = c.absent(&out);
            }
            c.cleanup = code == 0;
            cases.push(c);
        }
    }
    // A sweep whose measured experiment's data file is bad.
    for (file, phrase) in [
        ("nan.csv", "value is NaN"),
        ("huge.csv", "more than 1000000 data rows"),
    ] {
        let cfg = f.write(
            &format!("sweep_{file}.toml"),
            &std::fs::read_to_string(f.path("sweep.toml"))
                .unwrap()
                .replace("data.csv", file),
        );
        cases.push(
            case(
                &format!("compare / {file}"),
                &["compare", "--config", &cfg, "--out", &o],
                phrase,
            )
            .absent(&out_dir),
        );
    }

    // The model: an unstable linear block, z that cannot be computed from the data, an
    // algebraic loop, an unknown function in a truth, a huge matrix entry.
    let unstable = f.model_variant("unstable.toml", "  [1.2, -0.5],", "  [1.5, 0.0],");
    let diverging = f.model_variant("diverging.toml", "  [1.2, -0.5],", "  [20.0, 0.0],");
    let hidden = f.model_variant("hidden_z.toml", "Cz = [[0.0, 0.0]]", "Cz = [[1.0, 0.0]]");
    let hidden = f.write(
        "hidden_z.toml",
        &std::fs::read_to_string(&hidden)
            .unwrap()
            .replace("Dzu = [[1.0]]", "Dzu = [[0.0]]")
            .replace("Cy = [[0.5, 0.3]]", "Cy = [[0.0, 0.0]]"),
    );
    let looped = f.model_variant("loop.toml", "Dzw = [[0.0]]", "Dzw = [[0.5]]");
    let unknown = f.model_variant("unknown_fn.toml", "tanh(2*z0)", "frobnicate(2*z0)");
    let huge_a = f.model_variant("huge_a.toml", "  [1.0, 0.0],\n]", "  [1e308, 0.0],\n]");
    cases.extend([
        case(
            "identify / unstable model",
            &[
                "identify", "--model", &unstable, "--data", &data, "--out", &o,
            ],
            "unstable model: the path w → y of the linear block has a pole of modulus 1.5",
        )
        .absent(&out_dir),
        case(
            "simulate / diverging model",
            &[
                "simulate", "--model", &diverging, "--input", &u, "--out", &oc,
            ],
            "unstable model: the simulation diverged",
        )
        .absent(&out_csv),
        case(
            "validate / diverging model",
            &[
                "validate", "--model", &diverging, "--data", &data, "--out", &o,
            ],
            "unstable model",
        )
        .absent(&out_dir),
        case(
            "identify / z not measurable",
            &["identify", "--model", &hidden, "--data", &data, "--out", &o],
            "z is not measurable",
        )
        .absent(&out_dir),
        // A latent model is validated by its simulation from rest, which has no initial state
        // to estimate.
        case(
            "validate / latent model with an estimated initial state",
            &[
                "validate",
                "--model",
                &hidden,
                "--data",
                &data,
                "--out",
                &o,
                "--initial-state",
                "estimate",
            ],
            "has no one-step predictor (block `N` is latent)",
        )
        .absent(&out_dir),
        case(
            "identify / algebraic loop",
            &["identify", "--model", &looped, "--data", &data, "--out", &o],
            "algebraic loop: D_zw has a non-zero entry (0.5)",
        )
        .absent(&out_dir),
        case(
            "simulate / algebraic loop",
            &["simulate", "--model", &looped, "--input", &u, "--out", &oc],
            "algebraic loop: D_zw has a non-zero entry (0.5)",
        )
        .absent(&out_csv),
        case(
            "validate / algebraic loop",
            &["validate", "--model", &looped, "--data", &data, "--out", &o],
            "algebraic loop: D_zw has a non-zero entry (0.5)",
        )
        .absent(&out_dir),
        case(
            "simulate / unknown function in truth",
            &["simulate", "--model", &unknown, "--input", &u, "--out", &oc],
            "unknown function `frobnicate`",
        )
        .absent(&out_csv),
        case(
            "validate / unknown function in truth",
            &[
                "validate", "--model", &unknown, "--data", &data, "--out", &o,
            ],
            "unknown function `frobnicate`",
        )
        .absent(&out_dir),
        case(
            "identify / unknown function in truth",
            &[
                "identify", "--model", &unknown, "--data", &data, "--out", &o,
            ],
            "unknown function `frobnicate`",
        )
        .absent(&out_dir),
        case(
            "identify / A = 1e308",
            &["identify", "--model", &huge_a, "--data", &data, "--out", &o],
            "unstable model: the paths w → y overflow",
        )
        .absent(&out_dir),
        case(
            "simulate / A = 1e308",
            &["simulate", "--model", &huge_a, "--input", &u, "--out", &oc],
            "unstable model: the simulation diverged",
        )
        .absent(&out_csv),
        case(
            "validate / A = 1e308",
            &["validate", "--model", &huge_a, "--data", &data, "--out", &o],
            "unstable model",
        )
        .absent(&out_dir),
    ]);

    // σ and β.
    for (flag, cmd) in [
        ("--sigma", "identify"),
        ("--beta", "identify"),
        ("--sigma", "refine"),
        ("--beta", "refine"),
    ] {
        for v in ["0", "-1", "1e308", "NaN", "inf"] {
            let name = format!("{cmd} / {flag} {v}");
            let phrase = format!("invalid value {v} for {flag}");
            let args = [cmd, "--model", &m, "--data", &data, "--out", &o, flag, v];
            cases.push(case(&name, &args, &phrase).absent(&out_dir));
        }
    }
    cases.extend([
        case(
            "simulate / --noise-std 1e308",
            &[
                "simulate",
                "--model",
                &m,
                "--input",
                &u,
                "--out",
                &oc,
                "--noise-std",
                "1e308",
            ],
            "--noise-std",
        )
        .absent(&out_csv),
        case(
            "simulate / --noise-std 1e309 (overflows to inf)",
            &[
                "simulate",
                "--model",
                &m,
                "--input",
                &u,
                "--out",
                &oc,
                "--noise-std",
                "1e309",
            ],
            "--noise-std",
        )
        .absent(&out_csv),
        case(
            "simulate / --noise-std -1",
            &[
                "simulate",
                "--model",
                &m,
                "--input",
                &u,
                "--out",
                &oc,
                "--noise-std",
                "-1",
            ],
            "--noise-std",
        )
        .absent(&out_csv),
        case(
            "simulate --estimate / --noise-std 1e308",
            &[
                "simulate",
                "--estimate",
                &est,
                "--input",
                &u,
                "--out",
                &oc,
                "--noise-std",
                "1e308",
            ],
            "--noise-std",
        )
        .absent(&out_csv),
        case(
            "demo multi-input / --noise-std 1e308",
            &["demo", "multi-input", "--out", &o, "--noise-std", "1e308"],
            "--noise-std",
        )
        .absent(&out_dir),
        case(
            "demo spray / --samples 10000000",
            &["demo", "spray", "--out", &o, "--samples", "10000000"],
            "--samples",
        )
        .absent(&out_dir),
        case(
            "identify / --memory-limit-mib 100000000",
            &[
                "identify",
                "--model",
                &m,
                "--data",
                &data,
                "--out",
                &o,
                "--memory-limit-mib",
                "100000000",
            ],
            "--memory-limit-mib",
        )
        .absent(&out_dir),
        case(
            "linear / --orders 200,200,1",
            &[
                "linear",
                "--data",
                &data,
                "--out",
                &ot,
                "--orders",
                "200,200,1",
            ],
            "NA and NB can be at most 30",
        )
        .absent(&out_toml),
        case(
            "linear / --max-order 200",
            &[
                "linear",
                "--data",
                &data,
                "--out",
                &ot,
                "--max-order",
                "200",
            ],
            "at most 30",
        )
        .absent(&out_toml),
        case(
            "linear / --max-delay huge",
            &[
                "linear",
                "--data",
                &data,
                "--out",
                &ot,
                "--max-delay",
                "1000000000",
            ],
            "narrow the delay range",
        )
        .absent(&out_toml),
        case(
            "linear / --orders 2,2,huge",
            &[
                "linear",
                "--data",
                &data,
                "--out",
                &ot,
                "--orders",
                "2,2,18446744073709551615",
            ],
            "the delay NK is longer than any record",
        )
        .absent(&out_toml),
        case(
            "compare / --shard 3/2",
            &["compare", "--config", &sweep, "--out", &o, "--shard", "3/2"],
            "shard index 3 is not less than the number of shards 2",
        )
        .absent(&out_dir),
        case(
            "compare / --jobs 0",
            &["compare", "--config", &sweep, "--out", &o, "--jobs", "0"],
            "--jobs",
        )
        .absent(&out_dir),
    ]);
    cases.extend(out_cases(f));
    cases
}

/// A directory in which files cannot be created, when the test can make one: a read-only
/// directory (not for root, who writes anyway), else a path under `/sys` on Linux.
fn unwritable_dir(f: &Fixtures) -> Option<PathBuf> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let ro = f.path("read_only");
        std::fs::create_dir(&ro).unwrap();
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
        if std::fs::write(ro.join("probe"), "x").is_err() {
            return Some(ro);
        }
        let _ = std::fs::remove_file(ro.join("probe"));
    }
    let sys = PathBuf::from("/sys/structid-bad-inputs");
    (Path::new("/sys").is_dir() && std::fs::create_dir(&sys).is_err()).then_some(sys)
}

/// `--out` mistakes, the same for every command: an input, a file where a directory is
/// expected (and the reverse), a place below a file, a place that cannot be written.
fn out_cases(f: &Fixtures) -> Vec<Case> {
    let m = f.s("model.toml");
    let data = f.s("data.csv");
    let u = f.s("u.csv");
    let est = f.s("est/estimate.json");
    let lti = f.s("lti.toml");
    let val = f.s("val.csv");
    let sweep = f.s("sweep.toml");
    let cmp = f.s("cmp");
    let file = f.s("existing.txt");
    let dir = f.s("existing_dir");
    let below = p(&f.path("existing.txt").join("out")).to_string();
    let unwritable = unwritable_dir(f).map(|d| p(&d.join("out")).to_string());

    // Commands writing a directory: (name, arguments before --out).
    let dir_commands: Vec<(&str, Vec<&str>)> = vec![
        ("identify", vec!["identify", "--model", &m, "--data", &data]),
        ("validate", vec!["validate", "--model", &m, "--data", &data]),
        (
            "validate --estimate",
            vec!["validate", "--estimate", &est, "--data", &data],
        ),
        (
            "predict",
            vec!["predict", "--estimate", &est, "--data", &data],
        ),
        ("refine", vec!["refine", "--model", &m, "--data", &data]),
        (
            "discover",
            vec![
                "discover",
                "--model",
                &lti,
                "--data",
                &data,
                "--validate",
                &val,
            ],
        ),
        ("demo spray", vec!["demo", "spray"]),
        ("demo multi-input", vec!["demo", "multi-input"]),
        ("compare", vec!["compare", "--config", &sweep]),
        ("compare merge", vec!["compare", "merge", &cmp]),
        (
            "data silverbox --split all",
            vec!["data", "silverbox", "--file", &data, "--split", "all"],
        ),
    ];
    // Commands writing one file.
    let file_commands: Vec<(&str, Vec<&str>)> = vec![
        ("simulate", vec!["simulate", "--model", &m, "--input", &u]),
        (
            "simulate --estimate",
            vec!["simulate", "--estimate", &est, "--input", &u],
        ),
        ("linear", vec!["linear", "--data", &data]),
        ("data csv", vec!["data", "csv", "--file", &data]),
        (
            "data silverbox",
            vec![
                "data",
                "silverbox",
                "--file",
                &data,
                "--split",
                "estimation",
            ],
        ),
    ];
    let with_out = |base: &[&str], out: &str| {
        let mut v: Vec<String> = base.iter().map(|s| s.to_string()).collect();
        v.push("--out".into());
        v.push(out.into());
        v
    };
    let mk = |name: String, args: Vec<String>, phrase: &str| {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        case(&name, &args, phrase)
    };
    let mut cases = Vec::new();
    for (name, base) in &dir_commands {
        cases.push(mk(
            format!("{name} / --out is a file"),
            with_out(base, &file),
            "it exists and is not a directory",
        ));
        cases.push(
            mk(
                format!("{name} / --out below a file"),
                with_out(base, &below),
                "is a file, not a directory",
            )
            .absent(&PathBuf::from(&below)),
        );
        if let Some(uw) = &unwritable {
            cases.push(
                mk(
                    format!("{name} / --out unwritable"),
                    with_out(base, uw),
                    "cannot create files in",
                )
                .absent(&PathBuf::from(uw)),
            );
        }
    }
    for (name, base) in &file_commands {
        cases.push(mk(
            format!("{name} / --out is a directory"),
            with_out(base, &dir),
            "it is an existing directory",
        ));
        let target = format!("{below}.csv");
        cases.push(
            mk(
                format!("{name} / --out below a file"),
                with_out(base, &target),
                "is a file, not a directory",
            )
            .absent(&PathBuf::from(&target)),
        );
        if let Some(uw) = &unwritable {
            let target = format!("{uw}.csv");
            cases.push(
                mk(
                    format!("{name} / --out unwritable"),
                    with_out(base, &target),
                    "cannot create files in",
                )
                .absent(&PathBuf::from(&target)),
            );
        }
    }
    // --out is an input, or a directory holding an input under an output's name.
    let clash = |n: &str| f.s(&format!("clash/{n}"));
    let clash_dir = f.s("clash");
    for (name, args) in [
        (
            "identify",
            vec!["identify", "--model", &m, "--data", &data, "--out", &data],
        ),
        (
            "simulate",
            vec!["simulate", "--model", &m, "--input", &u, "--out", &u],
        ),
        (
            "simulate (model)",
            vec!["simulate", "--model", &m, "--input", &u, "--out", &m],
        ),
        ("linear", vec!["linear", "--data", &data, "--out", &data]),
        (
            "data csv",
            vec!["data", "csv", "--file", &data, "--out", &data],
        ),
        (
            "validate",
            vec!["validate", "--model", &m, "--data", &data, "--out", &m],
        ),
        (
            "predict",
            vec![
                "predict",
                "--estimate",
                &est,
                "--data",
                &data,
                "--out",
                &est,
            ],
        ),
        (
            "refine",
            vec!["refine", "--model", &m, "--data", &data, "--out", &data],
        ),
        (
            "discover",
            vec![
                "discover",
                "--model",
                &lti,
                "--data",
                &data,
                "--validate",
                &val,
                "--out",
                &val,
            ],
        ),
        (
            "compare",
            vec!["compare", "--config", &sweep, "--out", &sweep],
        ),
    ] {
        cases.push(case(
            &format!("{name} / --out is an input"),
            &args,
            "refusing to write",
        ));
    }
    let e_clash = clash("estimate.csv");
    let s_clash = clash("simulation.csv");
    let p_clash = clash("prediction.csv");
    for (name, args) in [
        (
            "identify",
            vec![
                "identify", "--model", &m, "--data", &e_clash, "--out", &clash_dir,
            ],
        ),
        (
            "validate",
            vec![
                "validate", "--model", &m, "--data", &s_clash, "--out", &clash_dir,
            ],
        ),
        (
            "predict",
            vec![
                "predict",
                "--estimate",
                &est,
                "--data",
                &p_clash,
                "--out",
                &clash_dir,
            ],
        ),
    ] {
        cases.push(case(
            &format!("{name} / --out holds the input under an output's name"),
            &args,
            "refusing to write",
        ));
    }
    cases.push(case(
        "compare merge / --out is an input directory",
        &["compare", "merge", &cmp, "--out", &cmp],
        "also an input directory",
    ));
    cases
}

#[test]
fn every_command_refuses_bad_inputs_readably() {
    let f = fixtures();
    let show = std::env::var_os("BAD_INPUTS_SHOW").is_some();
    let cases = corpus(&f);
    let mut failures: Vec<String> = Vec::new();
    let mut seen = BTreeMap::new();
    for c in &cases {
        assert!(
            seen.insert(c.name.clone(), ()).is_none(),
            "duplicate {}",
            c.name
        );
        // Inputs: every argument that names an existing file.
        let inputs: Vec<(PathBuf, Option<(u64, u64)>)> = c
            .args
            .iter()
            .map(PathBuf::from)
            .filter(|p| p.is_file())
            .map(|p| {
                let h = hash_file(&p);
                (p, h)
            })
            .collect();
        let args: Vec<&str> = c.args.iter().map(String::as_str).collect();
        let t = std::time::Instant::now();
        let o = run(&args);
        let secs = t.elapsed().as_secs_f64();
        let first = o.stderr.lines().next().unwrap_or("").to_string();
        if show {
            eprintln!(
                "[{}] code {} ({secs:.2} s): {}",
                c.name,
                o.code,
                o.stderr.chars().take(400).collect::<String>()
            );
        }
        let mut problems = Vec::new();
        if o.code != c.code {
            problems.push(format!("exit code {} (expected {})", o.code, c.code));
        }
        for ph in &c.phrases {
            if !o.stderr.contains(ph.as_str()) {
                problems.push(format!("stderr lacks `{ph}`"));
            }
        }
        if o.stderr.contains("panicked")
            || o.stderr.contains("RUST_BACKTRACE")
            || o.stderr.contains("internal error")
        {
            problems.push("a panic".into());
        }
        if o.stderr.len() > 4000 {
            problems.push(format!("stderr is {} bytes long", o.stderr.len()));
        }
        for a in &c.absent {
            if a.exists() {
                problems.push(format!("`{}` exists", a.display()));
                let _ = std::fs::remove_dir_all(a).or_else(|_| std::fs::remove_file(a));
            }
        }
        for (path, h) in &inputs {
            if hash_file(path) != *h {
                problems.push(format!("input `{}` changed", path.display()));
            }
        }
        // Nothing is left in a directory given where a file was expected, and no temporary
        // or probe file is left beside the inputs.
        if std::fs::read_dir(f.path("existing_dir"))
            .unwrap()
            .next()
            .is_some()
        {
            problems.push("`existing_dir` is not empty".into());
        }
        let temps: Vec<String> = std::fs::read_dir(f.dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp-"))
            .collect();
        if !temps.is_empty() {
            problems.push(format!("temporary files left: {temps:?}"));
        }
        // Outputs of accepted cases, so that the next case starts clean.
        if c.cleanup {
            for p in [f.path("out"), f.path("out.csv"), f.path("out.toml")] {
                let _ = std::fs::remove_dir_all(&p).or_else(|_| std::fs::remove_file(&p));
            }
        }
        if !problems.is_empty() {
            failures.push(format!(
                "[{}] {}\n    stderr: {}",
                c.name,
                problems.join("; "),
                first.chars().take(300).collect::<String>()
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

/// The id of a process that has exited (its temporary files are stale).
fn dead_pid() -> u32 {
    let mut child = std::process::Command::new(BIN)
        .arg("--version")
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let pid = child.id();
    child.wait().unwrap();
    pid
}

/// The files `.complete` lists in `dir` (`None` without one).
fn listed(dir: &Path) -> Option<Vec<String>> {
    let text = std::fs::read_to_string(dir.join(".complete")).ok()?;
    Some(
        text.lines()
            .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
            .map(String::from)
            .collect(),
    )
}

/// A killed write leaves `.name.tmp-PID-N`; the next run into the directory removes those of
/// dead processes. A result directory's files are listed in `.complete` only once the whole
/// set is written: a run that stops half-way leaves its files unlisted, and the commands that
/// read an estimate refuse it until a run finishes.
#[test]
fn stale_temporary_files_are_removed_and_result_sets_are_marked_complete() {
    let f = Fixtures {
        dir: tempfile::tempdir().unwrap(),
    };
    let m = f.write("model.toml", &model_text());
    let u = f.write("u.csv", &input_csv(200, 5));
    let data = f.s("data.csv");
    ok(&[
        "simulate",
        "--model",
        &m,
        "--input",
        &u,
        "--out",
        &data,
        "--noise-std",
        "0.05",
    ]);
    let res = f.path("res");
    let r = p(&res).to_string();
    let set = [
        "estimate.csv",
        "estimate.json",
        "map_N.csv",
        "map_N.svg",
        "report.json",
    ];
    let identify = [
        "identify",
        "--model",
        &m,
        "--data",
        &data,
        "--out",
        &r,
        "--no-bands",
    ];
    ok(&identify);
    assert_eq!(listed(&res).unwrap(), set);

    // A killed run's temporary file, and one of a live process (this test).
    let stale = res.join(format!(".report.json.tmp-{}-0", dead_pid()));
    let live = res.join(format!(".other.csv.tmp-{}-0", std::process::id()));
    std::fs::write(&stale, "partial").unwrap();
    std::fs::write(&live, "in progress").unwrap();
    // A run that stops half-way: map_N.svg cannot be written (a directory holds its name),
    // after estimate.json, estimate.csv and map_N.csv were.
    std::fs::remove_file(res.join("map_N.svg")).unwrap();
    std::fs::create_dir(res.join("map_N.svg")).unwrap();
    let o = run(&identify);
    assert_eq!(o.code, 1, "{}", o.stderr);
    assert!(o.stderr.contains("map_N.svg"), "{}", o.stderr);
    assert!(!stale.exists(), "the dead process's temporary file is left");
    assert!(live.exists(), "a live process's temporary file was removed");
    assert_eq!(listed(&res).unwrap(), Vec::<String>::new());
    // The estimate of the unfinished set is refused by every command that reads it.
    let est = p(&res.join("estimate.json")).to_string();
    let val = f.s("val");
    let e = input_error(&[
        "validate",
        "--estimate",
        &est,
        "--data",
        &data,
        "--out",
        &val,
    ]);
    assert!(e.contains("incomplete set of results"), "{e}");
    let e = input_error(&[
        "predict",
        "--estimate",
        &est,
        "--data",
        &data,
        "--out",
        &val,
    ]);
    assert!(e.contains("incomplete set of results"), "{e}");
    let e = input_error(&[
        "simulate",
        "--estimate",
        &est,
        "--input",
        &u,
        "--out",
        &f.s("s.csv"),
    ]);
    assert!(e.contains("incomplete set of results"), "{e}");
    let e = input_error(&[
        "validate",
        "--model",
        &m,
        "--estimate",
        &r,
        "--data",
        &data,
        "--out",
        &val,
    ]);
    assert!(e.contains("incomplete set of results"), "{e}");
    assert!(!f.path("val").exists() && !f.path("s.csv").exists());

    // A finished rerun lists the set again; a second set beside it keeps the first listed.
    std::fs::remove_dir(res.join("map_N.svg")).unwrap();
    ok(&identify);
    assert_eq!(listed(&res).unwrap(), set);
    ok(&["validate", "--estimate", &est, "--data", &data, "--out", &r]);
    let all = listed(&res).unwrap();
    for name in set.iter().chain(&[
        "residuals.svg",
        "simulation.csv",
        "simulation.svg",
        "validation.json",
    ]) {
        assert!(all.iter().any(|l| l == name), "{name} not in {all:?}");
    }
    // No temporary files of this run are left.
    let temps: Vec<String> = std::fs::read_dir(&res)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp-") && !n.starts_with(".other.csv"))
        .collect();
    assert!(temps.is_empty(), "{temps:?}");
}

/// `compare --resume` runs again the cases whose files are not finished records (truncated,
/// or claiming success without a result) and removes the temporary files of a killed run; the
/// directory is listed as complete only at the end.
#[test]
fn compare_resume_reruns_incomplete_cases() {
    let f = Fixtures {
        dir: tempfile::tempdir().unwrap(),
    };
    let m = f.write("model.toml", &model_text());
    let u = f.write("u.csv", &input_csv(150, 7));
    ok(&[
        "simulate",
        "--model",
        &m,
        "--input",
        &u,
        "--out",
        &f.s("data.csv"),
        "--noise-std",
        "0.05",
    ]);
    let config = f.write(
        "sweep.toml",
        "[[experiment]]\nname = \"meas\"\nmodel = \"model.toml\"\nestimation = \"data.csv\"\n\n\
         [[dispersion]]\nname = \"gauss\"\nkind = \"gaussian\"\nbeta = [0.01, 0.1, 1.0]\n",
    );
    let out = f.path("out");
    let o = p(&out).to_string();
    ok(&["compare", "--config", &config, "--out", &o, "--jobs", "1"]);
    let done = listed(&out).unwrap();
    assert!(done.iter().any(|l| l == "results.csv"), "{done:?}");
    let cases = out.join("cases");
    let file = |b: &str| cases.join(format!("meas+gauss+beta={b}.json"));
    let kept = std::fs::read(file("1.0")).unwrap();

    // A killed run: a truncated case, a record that says ok without its result, a temporary
    // file, and the directory's set unlisted.
    let text = std::fs::read_to_string(file("0.01")).unwrap();
    std::fs::write(file("0.01"), &text[..text.len() / 2]).unwrap();
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(file("0.1")).unwrap()).unwrap();
    v["cost"] = serde_json::Value::Null;
    std::fs::write(file("0.1"), serde_json::to_string_pretty(&v).unwrap()).unwrap();
    let stale = cases.join(format!(".meas+gauss+beta=1.0.json.tmp-{}-0", dead_pid()));
    std::fs::write(&stale, "{\"format\":").unwrap();
    std::fs::write(out.join(".complete"), "# interrupted\n").unwrap();

    let r = ok(&[
        "compare", "--config", &config, "--out", &o, "--resume", "--jobs", "1",
    ]);
    assert!(
        r.stderr
            .contains("(2 incomplete case file(s) are recomputed)"),
        "{}",
        r.stderr
    );
    assert!(
        r.stdout.contains("ran 2 case(s) (1 skipped"),
        "{}",
        r.stdout
    );
    for b in ["0.01", "0.1"] {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(file(b)).unwrap()).unwrap();
        assert_eq!(v["status"], "ok", "{b}");
        assert!(v["cost"].is_object(), "{b}: {v}");
    }
    assert_eq!(
        std::fs::read(file("1.0")).unwrap(),
        kept,
        "a finished case was rerun"
    );
    assert!(!stale.exists(), "the killed run's temporary file is left");
    assert_eq!(listed(&out).unwrap(), done);
}

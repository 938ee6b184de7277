//! The entry points shared by the fuzz targets `model_file`, `data_file` and `sweep_file`
//! (`fuzz/fuzz_targets/`, which include this file) and the stable-toolchain harness
//! `tests/mutations.rs`.
//!
//! Each takes arbitrary bytes, runs the loader on them and, when it accepts the input, drives
//! what the command-line tool does next with the result (build the model, simulate it, select
//! data, build the dispersions, write the file back and read it again). Errors are expected
//! and collected as their displayed messages; only a panic (or a hang) is a failure.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use structid_core::{Interpolant, LookupTable};
use structid_io::{ColumnRef, CsvOptions, DataTable, ErrorChain, IoError, ModelFile, SweepFile};
use structid_lti::Signal;

/// A model file naming the columns `u` and `y`, used to select data from fuzzed CSV files.
const SELECT_MODEL: &str = r#"
[lft]
A = [[0.5]]
Bu = [[1.0]]
Bw = [[1.0]]
Cy = [[1.0]]
Dye = [[1.0]]
Cz = [[1.0]]
[signals]
u = ["u"]
y = ["y"]
[[nonlinearity]]
name = "f"
inputs = [0]
output = 0
"#;

/// A directory with the truth tables that seed model files refer to (`table.csv`, one input;
/// `grid.csv`, two inputs on a grid; `std.csv`, a map file with a `std` column):
/// `structid-fuzz-fixtures` in `/dev/shm` when it exists (data files that are not UTF-8 are
/// written there and read back, much faster in memory), else in the temporary directory.
/// The tables are (re)written once per process, atomically, so processes can share it.
pub fn fixture_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let in_memory = Path::new("/dev/shm").join("structid-fuzz-fixtures");
        let dir = if std::fs::create_dir_all(&in_memory).is_ok() {
            in_memory
        } else {
            let dir = std::env::temp_dir().join("structid-fuzz-fixtures");
            std::fs::create_dir_all(&dir).expect("create the fixture directory");
            dir
        };
        let files = [
            ("table.csv", "z,value\n-1,-0.5\n0,0\n1,2\n"),
            ("grid.csv", "z0,z1,value\n0,0,1\n0,1,2\n1,0,3\n1,1,4\n"),
            ("std.csv", "z,value,std\n-1,1,0.1\n1,-1,0.1\n"),
        ];
        for (name, text) in files {
            let partial = dir.join(format!("{name}.{}", std::process::id()));
            std::fs::write(&partial, text).expect("write a fixture table");
            std::fs::rename(&partial, dir.join(name)).expect("move a fixture table in place");
        }
        dir
    })
}

/// Whether a model file may name a special file as a truth table (a device that never ends
/// would make reading it hang). Such inputs are skipped; everything else is run.
pub fn names_special_file(text: &str) -> bool {
    ["/dev", "/proc", "/sys", ".."]
        .iter()
        .any(|p| text.contains(p))
}

/// What an entry point saw: whether the loader accepted the input, and the messages of every
/// error met (by the loader or downstream), each of which must be non-empty.
#[derive(Debug, Default)]
pub struct Outcome {
    /// The loader accepted the input.
    pub accepted: bool,
    /// Displayed error messages.
    pub errors: Vec<String>,
}

fn record<T>(errors: &mut Vec<String>, r: Result<T, IoError>) -> Option<T> {
    match r {
        Ok(v) => Some(v),
        Err(e) => {
            let _ = e.is_input_error();
            errors.push(ErrorChain(&e).to_string());
            None
        }
    }
}

fn record_core<T>(errors: &mut Vec<String>, r: Result<T, structid_core::Error>) -> Option<T> {
    record(errors, r.map_err(IoError::from))
}

/// A short deterministic record of `channels` channels with a few awkward values.
fn probe_signal(len: usize, channels: usize) -> Signal {
    Signal::from_fn(len, channels, |k, c| match (k + c) % 5 {
        0 => 0.0,
        1 => -1.5,
        2 => 2.0,
        3 => 1e-3,
        _ => (k as f64).sin(),
    })
}

/// Parses a model file and drives the model builder: `to_model` with default and explicit
/// σ, the nominal LFT, the truth maps and a short simulation with them, the measured z, and
/// writing the file back and parsing it again.
pub fn model_file(bytes: &[u8]) -> Outcome {
    let mut errors = Vec::new();
    let text = String::from_utf8_lossy(bytes);
    if names_special_file(&text) {
        return Outcome::default();
    }
    let Some(mf) = record(&mut errors, ModelFile::parse(&text, Some(fixture_dir()))) else {
        return Outcome {
            accepted: false,
            errors,
        };
    };
    let dims = mf.lft.dims();
    let z = probe_signal(6, dims.z);
    record(&mut errors, mf.to_model(None, Some(&z)));
    record(&mut errors, mf.to_model(Some(0.25), None));
    record(&mut errors, mf.to_model(Some(f64::NAN), None));
    record(
        &mut errors,
        mf.to_model(None, Some(&probe_signal(6, dims.z + 1))),
    );
    record(&mut errors, mf.model_lft());
    let _ = mf.z_names();
    for b in &mf.blocks {
        let _ = (b.dispersion.kind(), b.dispersion.sigma());
        let _ = b.truth.as_ref().map(|t| t.describe());
        if let Some(Some(map)) = record(&mut errors, b.truth_map()) {
            for v in [0.0, -1.0, 2.5, f64::NAN, f64::INFINITY] {
                let _ = map.eval(&vec![v; b.inputs.len()]);
            }
        }
    }
    if let Some(Some(maps)) = record(&mut errors, mf.truth_maps()) {
        let maps: Vec<&dyn Interpolant> = maps.iter().map(|m| m.as_ref()).collect();
        let u = probe_signal(8, dims.u);
        record(&mut errors, mf.simulate(&maps, &u, 0.1, 7));
    }
    if let Some(lin) = &mf.linear {
        let _ = (lin.structure_name(), lin.refinable());
        record(&mut errors, lin.lft());
    }
    // A record in the file's own columns, then z from it.
    let names: Vec<String> = mf
        .signals
        .u
        .iter()
        .chain(&mf.signals.y)
        .chain(mf.signals.z.iter().flatten())
        .cloned()
        .collect();
    let mut unique = names.clone();
    unique.sort();
    unique.dedup();
    let columns = vec![probe_signal(6, 1).channel(0); unique.len()];
    if let Some(table) = record(&mut errors, DataTable::new(unique, columns))
        && let Some(data) = record(&mut errors, mf.select_data(&table))
    {
        record(&mut errors, mf.z_signal(&data));
    }
    let written = mf.to_toml_string();
    record(&mut errors, ModelFile::parse(&written, Some(fixture_dir())));
    Outcome {
        accepted: true,
        errors,
    }
}

/// The [`CsvOptions`] of a fuzz input: default unless it starts with the byte 0xFF, which is
/// followed by two option bytes (delimiter, header, skipped lines, column selection, names).
pub fn csv_options(bytes: &[u8]) -> (CsvOptions, &[u8]) {
    let [0xFF, a, b, rest @ ..] = bytes else {
        return (CsvOptions::default(), bytes);
    };
    let delimiter = match a % 8 {
        0 => b',',
        1 => b';',
        2 => b'\t',
        3 => b' ',
        4 => b'|',
        5 => b'"',
        _ => *b,
    };
    let columns = (a & 0x40 != 0).then(|| match b % 4 {
        0 => vec![ColumnRef::Index(usize::from(b >> 4))],
        1 => vec![ColumnRef::Name("u".into()), ColumnRef::Index(0)],
        2 => vec![ColumnRef::Name("y".into())],
        _ => Vec::new(),
    });
    let names = (a & 0x80 != 0).then(|| match b % 3 {
        0 => vec!["u".to_string(), "y".to_string()],
        1 => vec!["u".to_string()],
        _ => vec!["c".to_string(), "c".to_string(), String::new()],
    });
    let options = CsvOptions {
        delimiter,
        header: a & 0x08 == 0,
        skip_rows: usize::from((a >> 4) & 0x03),
        columns,
        names,
    };
    (options, rest)
}

/// Reads a data file (through `parse_with`, or from disk through `read_with` when the bytes
/// are not UTF-8) and drives what follows: column access and selection, writing the table
/// back, a lookup table from its rows, and selecting a record for a model with columns u, y.
pub fn data_file(bytes: &[u8]) -> Outcome {
    let mut errors = Vec::new();
    let (options, body) = csv_options(bytes);
    let table = match std::str::from_utf8(body) {
        Ok(text) => DataTable::parse_with(text, None, &options),
        Err(_) => {
            let path = fixture_dir().join(format!(
                "input-{}-{:?}.csv",
                std::process::id(),
                std::thread::current().id()
            ));
            std::fs::write(&path, body).expect("write the data file");
            let table = DataTable::read_with(&path, &options);
            let _ = std::fs::remove_file(&path);
            table
        }
    };
    let Some(table) = record(&mut errors, table) else {
        return Outcome {
            accepted: false,
            errors,
        };
    };
    let _ = (
        table.len(),
        table.is_empty(),
        table.header_line(),
        table.path(),
    );
    for k in 0..=table.len() {
        let _ = table.line_of_row(k);
    }
    for name in &table.names {
        let _ = table.column(name);
        record(&mut errors, table.select(&[name]));
    }
    record(&mut errors, table.select(&table.names));
    if let Some(bytes) = record(
        &mut errors,
        structid_io::csv_bytes(&table.names, &table.columns),
    ) {
        let text = String::from_utf8(bytes).expect("csv_bytes writes UTF-8");
        record(&mut errors, DataTable::parse(&text, None));
    }
    // The truth-table loader's path: rows of (z…, value) into a lookup table.
    if (2..=3).contains(&table.names.len())
        && table
            .columns
            .iter()
            .all(|c| c.iter().all(|v| v.is_finite()))
    {
        let rows: Vec<Vec<f64>> = (0..table.len())
            .map(|k| table.columns.iter().map(|c| c[k]).collect())
            .collect();
        if let Some(lookup) = record_core(&mut errors, LookupTable::from_rows(&rows)) {
            let p = table.names.len() - 1;
            for v in [0.0, -1e300, 1e300, 0.5, f64::NAN, f64::NEG_INFINITY] {
                let _ = lookup.eval(&vec![v; p]);
            }
            for row in &rows {
                let _ = lookup.eval(&row[..p]);
            }
        }
    }
    static MODEL: OnceLock<ModelFile> = OnceLock::new();
    let model = MODEL.get_or_init(|| ModelFile::parse(SELECT_MODEL, None).expect("valid model"));
    if let Some(data) = record(&mut errors, model.select_data(&table))
        && let Some(z) = record(&mut errors, model.z_signal(&data))
    {
        record(&mut errors, model.to_model(None, Some(&z)));
    }
    Outcome {
        accepted: true,
        errors,
    }
}

/// Parses a sweep configuration of `structid compare` and drives what follows: paths, seeds,
/// β labels and every dispersion built with and without data for the default σ.
pub fn sweep_file(bytes: &[u8]) -> Outcome {
    let mut errors = Vec::new();
    let text = String::from_utf8_lossy(bytes);
    let Some(sweep) = record(&mut errors, SweepFile::parse(&text, Some(fixture_dir()))) else {
        return Outcome {
            accepted: false,
            errors,
        };
    };
    for e in &sweep.experiments {
        let _ = (e.has_validation(), e.seeds().map(<[u64]>::len));
        let _ = sweep.resolve(&e.model);
    }
    let z = probe_signal(6, 1);
    for d in &sweep.dispersions {
        let _ = (d.is_total_variation(), d.selection.name(), d.spec.kind());
        for b in &d.betas {
            let _ = b.label();
        }
        record(&mut errors, d.spec.build(None, Some(&z)));
        record(&mut errors, d.spec.build(None, None));
        record(&mut errors, d.spec.build(Some(0.3), None));
    }
    Outcome {
        accepted: true,
        errors,
    }
}

//! The reports of a discovery, the presentation layer of `structid_discover`: `report.md`
//! ([`markdown()`]), `report.json` ([`json()`]) and the summary a run prints ([`summary`]),
//! with the records they describe ([`Record`]); the figures ([`figures`]) and the writing of
//! every file of a run ([`files`]).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use structid_core::Data;
use structid_io::{DataTable, IoError, ModelFile, format_number};

use structid_core::validation::Scoring;

use structid_discover::augmented::{AugmentedFile, BLOCK, ESTIMATE_FILE, initial_state_name};
use structid_discover::discover::{
    AugmentedMap, Classification, Discovery, Effects, Finding, initial_state, rms_text,
};
use structid_discover::effects::EffectFit;
use structid_discover::gap::Gap;
use structid_discover::hypotheses::{Nominal, Site};

/// Rows of the window table in report.md per record.
const MAX_WINDOW_ROWS: usize = 20;

/// The time axis of a record: a `time` (or `t`) column, the model's sample time, or the sample
/// index.
#[derive(Clone, Debug)]
pub struct TimeAxis {
    /// The time (or sample index) of each sample.
    pub values: Vec<f64>,
    /// The axis label: `time`, `time [s]` or `sample`.
    pub label: &'static str,
    /// Whether the values are times (not sample indices).
    pub is_time: bool,
}

impl TimeAxis {
    /// The time axis of a record of `len` samples read as `table`, from a model with
    /// `sample_time`.
    pub fn new(table: &DataTable, len: usize, sample_time: Option<f64>) -> Self {
        for name in ["time", "t"] {
            if let Some(c) = table.column(name)
                && c.len() == len
            {
                return Self {
                    values: c.to_vec(),
                    label: "time",
                    is_time: true,
                };
            }
        }
        match sample_time {
            Some(ts) => Self {
                values: (0..len).map(|k| k as f64 * ts).collect(),
                label: "time [s]",
                is_time: true,
            },
            None => Self {
                values: (0..len).map(|k| k as f64).collect(),
                label: "sample",
                is_time: false,
            },
        }
    }

    /// The time of sample `k` (NaN past the end).
    pub fn at(&self, k: usize) -> f64 {
        self.values.get(k).copied().unwrap_or(f64::NAN)
    }
}

/// The time axes of several records one after the other: each record's axis shifted to start
/// one of its own steps after the end of the one before, so that figures run forward.
pub(super) fn continued<'a>(axes: impl Iterator<Item = &'a [f64]>) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for axis in axes {
        let step = match axis {
            [a, b, ..] => b - a,
            _ => 1.0,
        };
        let shift = match (out.last(), axis.first()) {
            (Some(end), Some(start)) => end + step - start,
            _ => 0.0,
        };
        out.extend(axis.iter().map(|t| t + shift));
    }
    out
}

/// One record as read, or several ([`Record::join`]).
#[derive(Clone, Debug)]
pub struct Record {
    /// The file as given (the first, for several records).
    pub path: PathBuf,
    /// Every file, one per record of `data`.
    pub paths: Vec<PathBuf>,
    /// Its columns.
    pub table: DataTable,
    /// The columns the model file's `[signals]` name.
    pub data: Data,
    /// Its time axis.
    pub time: TimeAxis,
}

impl Record {
    /// Reads the record at `path` with the columns `mf`'s `[signals]` name.
    ///
    /// # Errors
    /// An unreadable or malformed file, missing columns.
    pub fn read(mf: &ModelFile, path: &Path) -> Result<Self, IoError> {
        let table = DataTable::read(path)?;
        let data = mf.select_data(&table)?;
        let time = TimeAxis::new(&table, data.len(), mf.lft.sample_time());
        Ok(Self {
            path: path.to_path_buf(),
            paths: vec![path.to_path_buf()],
            table,
            data,
            time,
        })
    }

    /// Records read one per file as one [`Record`] of several records
    /// ([`Data::from_records`]): `data` and `time` stacked in the files' order (each record's
    /// time axis shifted to continue the one before, for the figures), `table` the first
    /// file's. One record is returned as it is.
    ///
    /// # Errors
    /// No record, or records whose channels differ.
    pub fn join(records: Vec<Record>) -> structid_core::Result<Self> {
        let mut records = records;
        if records.len() == 1 {
            return Ok(records.pop().expect("one record"));
        }
        let first = records.first().ok_or_else(|| {
            structid_core::Error::InvalidStructure("no data record was given".into())
        })?;
        let (path, table, time) = (first.path.clone(), first.table.clone(), &first.time);
        let (label, is_time) = (time.label, time.is_time);
        let data = Data::from_records(records.iter().map(|r| r.data.clone()).collect())?;
        Ok(Self {
            path,
            paths: records.iter().flat_map(|r| r.paths.clone()).collect(),
            table,
            data,
            time: TimeAxis {
                values: continued(records.iter().map(|r| r.time.values.as_slice())),
                label,
                is_time,
            },
        })
    }

    /// The files, as a command line gives them: `FLAG a.csv FLAG b.csv …` (without the first
    /// flag).
    pub fn files(&self, flag: &str) -> String {
        self.paths
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(&format!(" {flag} "))
    }

    /// The files for a sentence: `a.csv` or `a.csv`, `b.csv` (2 records).
    fn names(&self) -> String {
        let names: Vec<String> = self
            .paths
            .iter()
            .map(|p| format!("`{}`", p.display()))
            .collect();
        if names.len() == 1 {
            names[0].clone()
        } else {
            format!("{} ({} records)", names.join(", "), names.len())
        }
    }
}

/// What the reports say besides the [`Discovery`] itself: the run's inputs, settings and
/// outputs.
#[derive(Clone, Copy, Debug)]
pub struct ReportContext<'a> {
    /// The tool's version, e.g. `0.1.0`.
    pub version: &'a str,
    /// The run: its inputs, settings and output directory.
    pub run: &'a files::DiscoveryFiles<'a>,
    /// The augmented model file written (`augmented.toml`), if any.
    pub augmented: Option<&'a AugmentedFile>,
    /// The figures written: file name and what it shows.
    pub figures: &'a [(String, String)],
    /// Lags of the gap's tests.
    pub max_lag: usize,
}

mod effects;
pub mod figures;
pub mod files;
mod json;
mod markdown;

pub use effects::{effects_json, effects_markdown, effects_summary};
pub use json::{json, summary};
pub use markdown::{location_text, markdown};
#[allow(unused_imports)]
use {effects::*, json::*, markdown::*};

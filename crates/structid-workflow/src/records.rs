//! Data files read as records: CSV, MAT-files and NumPy files, with the signals a [`Vars`]
//! selection picks, as the signals a model file's `[signals]` names.

use std::path::{Path, PathBuf};

use structid_core::Data;
use structid_io::{DataTable, IoError, ModelFile, Vars};

use crate::{Result, WorkflowError};

/// Reads a data file: CSV, MAT-file, `.npy` or `.npz`, with the signals and names of `vars`
/// (the command line's `--vars`).
pub fn read_table(path: &Path, vars: Option<&Vars>) -> std::result::Result<DataTable, IoError> {
    DataTable::read_vars(path, vars)
}

/// The records of the data files, one per file, as the signals the model file's `[signals]`
/// names; several files are several records of one [`Data`].
pub fn read_records(mf: &ModelFile, paths: &[PathBuf], vars: Option<&Vars>) -> Result<Data> {
    let mut records = Vec::with_capacity(paths.len());
    let order = mf.lft.dims().states;
    for (i, p) in paths.iter().enumerate() {
        let table = read_table(p, vars)?;
        let data = mf.select_data(&table)?;
        // Checked here too (identification checks it) to name the file.
        if paths.len() > 1 && data.len() < order {
            return Err(WorkflowError::Core(structid_core::Error::RecordTooShort {
                record: i + 1,
                len: data.len(),
                order,
            })
            .context(format!("data file `{}`", p.display())));
        }
        records.push(data);
    }
    Data::from_records(records).map_err(|e| {
        let files: Vec<String> = paths
            .iter()
            .enumerate()
            .map(|(i, p)| format!("record {} = `{}`", i + 1, p.display()))
            .collect();
        WorkflowError::Core(e).context(format!("the data files ({})", files.join(", ")))
    })
}

/// A record of a discovery read with [`read_table`].
pub fn read_record(
    mf: &ModelFile,
    path: &Path,
    vars: Option<&Vars>,
) -> std::result::Result<crate::discover_report::Record, IoError> {
    let table = read_table(path, vars)?;
    let data = mf.select_data(&table)?;
    let time = crate::discover_report::TimeAxis::new(&table, data.len(), mf.lft.sample_time());
    Ok(crate::discover_report::Record {
        path: path.to_path_buf(),
        paths: vec![path.to_path_buf()],
        table,
        data,
        time,
    })
}

/// The time axis of a record of `len` samples and its label: seconds with a sample time,
/// samples without.
pub fn time_axis(sample_time: Option<f64>, len: usize) -> (Vec<f64>, &'static str) {
    match sample_time {
        Some(ts) => ((0..len).map(|k| k as f64 * ts).collect(), "time [s]"),
        None => ((0..len).map(|k| k as f64).collect(), "sample"),
    }
}

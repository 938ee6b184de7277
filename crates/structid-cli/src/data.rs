//! `structid data`: benchmark splits and column selection as plain `u,y` CSV files.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use clap::{Args, Subcommand};
use structid_io::{
    CascadedTanks, ColumnRef, CsvOptions, DataTable, IoError, OutputGuard, Record, Silverbox,
    SilverboxSplit, TanksSplit, Vars,
};

use crate::error::CliError;

/// The signals `--vars` selects from every data file of this run (set once by `main`).
static VARS: OnceLock<Vars> = OnceLock::new();

/// Sets the `--vars` selection of this run.
pub fn set_vars(vars: Vars) {
    // Set once, before any file is read.
    let _ = VARS.set(vars);
}

/// The `--vars` selection of this run, if any.
pub fn vars() -> Option<&'static Vars> {
    VARS.get()
}

/// Parses `--vars`.
pub fn parse_vars(s: &str) -> Result<Vars, String> {
    s.parse()
        .map_err(|e: structid_io::ArrayFileError| e.to_string())
}

/// Reads a data file named on the command line (--data, --validation-data, --validate,
/// --input): CSV, MAT-file, `.npy` or `.npz`, with the signals and names of `--vars`.
pub fn read_table(path: &Path) -> Result<DataTable, IoError> {
    DataTable::read_vars(path, VARS.get())
}

/// Subcommands of `structid data`.
#[derive(Debug, Subcommand)]
pub enum DataCommand {
    /// Extract a split of the Silverbox benchmark (SNLS80mV.csv) as a CSV file with columns u,y.
    ///
    /// Each column's mean over the whole record is removed first. Splits (sample indices of
    /// the file, 0-based, end exclusive): estimation [40650, 105712), test-arrow-full
    /// [100, 40575), test-arrow-no-extrapolation [100, 32100), test-multisine
    /// [105712, 127400). The first 50 samples of a test split may settle the initial state and
    /// are not scored.
    Silverbox(BenchmarkArgs),
    /// Extract a record of the cascaded-tanks benchmark (dataBenchmark.csv) as a CSV file with
    /// columns u,y.
    ///
    /// Splits: estimation (uEst, yEst) and test (uVal, yVal), 1024 samples each, Ts = 4 s.
    Tanks(BenchmarkArgs),
    /// Select, reorder, rename and cut the columns of any delimited text file, or convert
    /// the signals of a MAT-file or NumPy file (chosen with --vars) to CSV.
    ///
    /// Writes a CSV file with a header row that the other commands read.
    Csv(CsvArgs),
}

/// Arguments of `structid data silverbox` and `structid data tanks`.
#[derive(Debug, Args)]
pub struct BenchmarkArgs {
    /// The official benchmark file.
    #[arg(long, short = 'f', value_name = "PATH")]
    file: PathBuf,
    /// The split to extract (Silverbox: estimation, test-arrow-full,
    /// test-arrow-no-extrapolation, test-multisine; tanks: estimation, test), or `all` to
    /// write every split as OUT/<split>.csv.
    #[arg(long, short = 's', value_name = "NAME")]
    split: String,
    /// The CSV file to write, or the directory with `--split all` (never the input file).
    #[arg(long, short = 'o', value_name = "OUT")]
    out: PathBuf,
}

/// Arguments of `structid data csv`.
#[derive(Debug, Args)]
pub struct CsvArgs {
    /// The file to read.
    #[arg(long, short = 'f', value_name = "PATH")]
    file: PathBuf,
    /// The columns to keep, in this order, comma-separated: header names, or `#N` for the
    /// column at zero-based position N (default: all columns).
    #[arg(long, value_name = "COLS")]
    columns: Option<String>,
    /// Names of the kept columns, comma-separated, one per column (default: the header's
    /// names, or c0, c1, … with --no-header).
    #[arg(long, value_name = "NAMES")]
    names: Option<String>,
    /// The field delimiter: one ASCII character, or `tab`.
    #[arg(long, value_name = "CHAR", default_value = ",")]
    delimiter: String,
    /// The file has no header row (the first row is data).
    #[arg(long)]
    no_header: bool,
    /// Lines at the start of the file to ignore (before the header).
    #[arg(long, value_name = "N", default_value_t = 0)]
    skip_rows: usize,
    /// Keep data rows A to B−1 only (0-based, end exclusive; `A..` and `..B` allowed).
    #[arg(long, value_name = "A..B")]
    range: Option<String>,
    /// Subtract each kept column's mean over the whole file (before --range, as for Silverbox).
    #[arg(long)]
    remove_mean: bool,
    /// The CSV file to write (never the input file).
    #[arg(long, short = 'o', value_name = "OUT")]
    out: PathBuf,
}

/// Runs `structid data …`.
pub fn run(cmd: DataCommand) -> Result<(), CliError> {
    match cmd {
        DataCommand::Silverbox(a) => {
            let splits = parse_splits(
                &a.split,
                "Silverbox",
                &SilverboxSplit::ALL,
                SilverboxSplit::name,
            )?;
            let (guard, targets) = targets(&a, &splits, SilverboxSplit::name)?;
            let sb = Silverbox::load(&a.file)?;
            let means = format!(
                "; means removed: u {:.5e} V, y {:.5e} V",
                sb.means.0, sb.means.1
            );
            write_records(&guard, &a, &targets, |s| sb.split(*s), &means)
        }
        DataCommand::Tanks(a) => {
            let splits = parse_splits(
                &a.split,
                "cascaded tanks",
                &TanksSplit::ALL,
                TanksSplit::name,
            )?;
            let (guard, targets) = targets(&a, &splits, TanksSplit::name)?;
            let tanks = CascadedTanks::load(&a.file)?;
            write_records(&guard, &a, &targets, |s| tanks.split(*s).clone(), "")
        }
        DataCommand::Csv(a) => csv(a),
    }
}

/// The splits named by `--split` (`all` for every one).
fn parse_splits<T: Copy>(
    arg: &str,
    benchmark: &str,
    all: &[T],
    name: fn(T) -> &'static str,
) -> Result<Vec<T>, CliError> {
    let arg = arg.trim();
    if arg == "all" {
        return Ok(all.to_vec());
    }
    match all.iter().find(|s| name(**s) == arg) {
        Some(s) => Ok(vec![*s]),
        None => Err(CliError::input(format!(
            "unknown {benchmark} split `{arg}` for --split; valid splits: {}, all",
            all.iter().map(|s| name(*s)).collect::<Vec<_>>().join(", ")
        ))),
    }
}

/// The output file of each split, checked against the input before anything is read.
fn targets<T: Copy>(
    a: &BenchmarkArgs,
    splits: &[T],
    name: fn(T) -> &'static str,
) -> Result<(OutputGuard, Vec<(T, PathBuf)>), CliError> {
    let mut guard = OutputGuard::new();
    guard.protect(&a.file);
    let all = a.split.trim() == "all";
    if all {
        guard.check_out_dir(&a.out, splits.iter().map(|s| format!("{}.csv", name(*s))))?;
    } else {
        guard.check_out_file(&a.out)?;
    }
    let targets: Vec<(T, PathBuf)> = if all {
        splits
            .iter()
            .map(|s| (*s, a.out.join(format!("{}.csv", name(*s)))))
            .collect()
    } else {
        splits.iter().map(|s| (*s, a.out.clone())).collect()
    };
    for (_, p) in &targets {
        guard.check(p)?;
    }
    Ok((guard, targets))
}

/// Writes each split's record as `u,y` and prints one summary line per file.
fn write_records<T>(
    guard: &OutputGuard,
    a: &BenchmarkArgs,
    targets: &[(T, PathBuf)],
    record: impl Fn(&T) -> Record,
    extra: &str,
) -> Result<(), CliError> {
    let all = a.split.trim() == "all";
    let names: Vec<PathBuf> = targets.iter().map(|(_, p)| p.clone()).collect();
    let names = structid_io::output::file_names(&names);
    if all {
        guard.begin_set(&a.out, Some(&names))?;
    }
    for (s, path) in targets {
        let r = record(s);
        guard.write_csv(path, &["u", "y"], &[r.u.clone(), r.y.clone()])?;
        println!(
            "{}: {} samples (file rows {}..{}), sample time {} s, scored from sample {}{extra}; wrote {}",
            r.name,
            r.len(),
            r.range.start,
            r.range.end,
            r.sample_time,
            r.settle,
            path.display()
        );
    }
    if all {
        guard.finish_set(&a.out, &names)?;
    }
    Ok(())
}

/// Bytes of memory per data row that reading a file and writing the kept columns take, as
/// measured for two columns (about 210 bytes a row while parsing, the text of the output
/// after it) and rounded up.
const CSV_BYTES_PER_ROW: u64 = 512;

/// The largest file `structid data csv` reads: the rows that fit in three quarters of the
/// available memory at [`CSV_BYTES_PER_ROW`], and never fewer than the
/// [`structid_io::data_file::MAX_ROWS`] every other command reads. `data csv` is the tool
/// that cuts a long record to a length the others accept, so it is limited by memory only.
fn csv_row_limit() -> usize {
    let available =
        structid_core::identify::settings::available_memory_bytes().unwrap_or(4 << 30) / 4 * 3;
    usize::try_from(available / CSV_BYTES_PER_ROW)
        .unwrap_or(usize::MAX)
        .max(structid_io::data_file::MAX_ROWS)
}

/// `structid data csv`.
fn csv(a: CsvArgs) -> Result<(), CliError> {
    let delimiter = parse_delimiter(&a.delimiter)?;
    let columns = a
        .columns
        .as_deref()
        .map(ColumnRef::parse_list)
        .transpose()
        .map_err(|e| CliError::from(e).context("--columns"))?;
    let names = a
        .names
        .as_deref()
        .map(|n| n.split(',').map(|s| s.trim().to_string()).collect());
    let range = a.range.as_deref().map(parse_range).transpose()?;
    let mut guard = OutputGuard::new();
    guard.protect(&a.file);
    guard.check_out_file(&a.out)?;
    let text_options =
        columns.is_some() || names.is_some() || a.no_header || a.skip_rows > 0 || delimiter != b',';
    let table = if is_array_file(&a.file) {
        // A MAT-file or NumPy file: converted to CSV, its signals chosen by --vars.
        if text_options {
            return Err(CliError::input(format!(
                "`{}` is a MAT-file or NumPy file: choose and name its signals with --vars \
                 (e.g. --vars u=vir,y=qm); --columns, --names, --delimiter, --no-header and \
                 --skip-rows apply to text files",
                a.file.display()
            )));
        }
        read_table(&a.file)?
    } else {
        if VARS.get().is_some() {
            return Err(CliError::input(format!(
                "`{}` is a text file: choose and name its columns with --columns and --names \
                 (--vars selects the variables of MAT-files and NumPy files here)",
                a.file.display()
            )));
        }
        let options = CsvOptions {
            delimiter,
            header: !a.no_header,
            skip_rows: a.skip_rows,
            columns,
            names,
        };
        DataTable::read_with_limit(&a.file, &options, csv_row_limit())?
    };
    // Every kept column needs a value in every row (an empty field is reported with its line).
    let signal = table.select(&table.names)?;
    let mut cols: Vec<Vec<f64>> = (0..signal.channels()).map(|c| signal.channel(c)).collect();
    let len = table.len();
    let mut means = String::new();
    if a.remove_mean {
        let parts: Vec<String> = table
            .names
            .iter()
            .zip(cols.iter_mut())
            .map(|(n, c)| format!("{n} {}", remove_mean(c)))
            .collect();
        means = format!("; means removed: {}", parts.join(", "));
    }
    let rows = resolve_range(range, len, a.range.as_deref())?;
    let cols: Vec<Vec<f64>> = cols.iter().map(|c| c[rows.clone()].to_vec()).collect();
    guard.write_csv(&a.out, &table.names, &cols)?;
    println!(
        "{}: {} samples (rows {}..{} of {} data rows), columns {}{means}; wrote {}",
        a.file.display(),
        rows.len(),
        rows.start,
        rows.end,
        len,
        table.names.join(", "),
        a.out.display()
    );
    Ok(())
}

/// Whether `path` is a MAT-file, `.npy` or `.npz` file (by its first bytes, or its
/// extension when it cannot be read).
fn is_array_file(path: &Path) -> bool {
    use std::io::Read;
    let mut head = Vec::new();
    if let Ok(f) = std::fs::File::open(path) {
        let _ = f.take(16).read_to_end(&mut head);
    }
    let extension = path.extension().and_then(|e| e.to_str());
    structid_io::array_file::Format::detect(&head, extension)
        != structid_io::array_file::Format::Csv
}

/// `--delimiter`: one ASCII character, or `tab` / `\t`.
fn parse_delimiter(s: &str) -> Result<u8, CliError> {
    match s {
        "tab" | "\\t" | "\t" => Ok(b'\t'),
        _ if s.len() == 1 && s.is_ascii() => Ok(s.as_bytes()[0]),
        _ => Err(CliError::input(format!(
            "invalid value `{s}` for --delimiter: give one ASCII character such as `;` or `tab`"
        ))),
    }
}

/// `--range A..B` with either end optional.
fn parse_range(s: &str) -> Result<(Option<usize>, Option<usize>), CliError> {
    let bad = || {
        CliError::input(format!(
            "invalid value `{s}` for --range: expected A..B (0-based data rows, end exclusive; A.. and ..B allowed)"
        ))
    };
    let (a, b) = s.trim().split_once("..").ok_or_else(bad)?;
    let end = |x: &str| -> Result<Option<usize>, CliError> {
        let x = x.trim();
        if x.is_empty() {
            Ok(None)
        } else {
            x.parse().map(Some).map_err(|_| bad())
        }
    };
    Ok((end(a)?, end(b)?))
}

/// The rows of `--range` within a table of `len` rows.
fn resolve_range(
    range: Option<(Option<usize>, Option<usize>)>,
    len: usize,
    text: Option<&str>,
) -> Result<Range<usize>, CliError> {
    let (a, b) = range.unwrap_or((None, None));
    let (a, b) = (a.unwrap_or(0), b.unwrap_or(len));
    if a >= b || b > len {
        return Err(CliError::input(format!(
            "invalid value `{}` for --range: the file has {len} data rows (0..{len}); the range must be non-empty and within them",
            text.unwrap_or("")
        )));
    }
    Ok(a..b)
}

/// Subtracts the mean of `v` and returns it.
fn remove_mean(v: &mut [f64]) -> f64 {
    let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
    v.iter_mut().for_each(|x| *x -= mean);
    mean
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_and_delimiters() {
        assert_eq!(parse_range("3..7").unwrap(), (Some(3), Some(7)));
        assert_eq!(parse_range("3..").unwrap(), (Some(3), None));
        assert_eq!(parse_range("..7").unwrap(), (None, Some(7)));
        assert!(parse_range("3-7").is_err());
        assert!(parse_range("a..7").is_err());
        assert_eq!(resolve_range(Some((Some(2), None)), 5, None).unwrap(), 2..5);
        assert_eq!(resolve_range(None, 5, None).unwrap(), 0..5);
        assert!(resolve_range(Some((Some(3), Some(3))), 5, None).is_err());
        assert!(resolve_range(Some((None, Some(6))), 5, None).is_err());
        assert_eq!(parse_delimiter(";").unwrap(), b';');
        assert_eq!(parse_delimiter("tab").unwrap(), b'\t');
        assert!(parse_delimiter(";;").is_err());
        assert!(parse_delimiter("é").is_err());
    }

    #[test]
    fn split_names() {
        let all = parse_splits(
            "all",
            "Silverbox",
            &SilverboxSplit::ALL,
            SilverboxSplit::name,
        )
        .unwrap();
        assert_eq!(all.len(), 4);
        let e = parse_splits("val", "cascaded tanks", &TanksSplit::ALL, TanksSplit::name)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "unknown cascaded tanks split `val` for --split; valid splits: estimation, test, all"
        );
    }
}

//! Loaders of the measured benchmark records of nonlinearbenchmark.org.
//!
//! * [`Silverbox`]: the electronic Duffing oscillator of Wigren and Schoukens (ECC 2013),
//!   file `SNLS80mV.csv` (header `"V1","V2",`, 131072 samples at fs = 10⁷/2¹⁴ Hz ≈ 610.35 Hz).
//!   Each column's mean over the whole record is removed on loading (the input has offset
//!   errors); [`Silverbox::split`] cuts the record into the splits of the official loader
//!   ([`SilverboxSplit`]).
//! * [`CascadedTanks`]: the two water tanks of Schoukens, Mattsson, Wigren and Noël (2016),
//!   file `dataBenchmark.csv` (columns `uEst, uVal, yEst, yVal, Ts`, 1024 samples, Ts = 4 s),
//!   with an estimation and a test record ([`TanksSplit`]). No mean is removed.
//!
//! Both loaders take the path of the official file and check its header and number of
//! samples; errors name the file and the line ([`IoError::BenchmarkMissing`],
//! [`IoError::Benchmark`], or [`IoError::Data`] for a field that is not a finite number).
//! Each split is a [`Record`]: input, output, sample time, the sample indices it covers in
//! the file, and the number of leading samples that may settle the initial state and are left
//! out of the score ([`Record::scored_rms`]).
//!
//! ```
//! use std::path::Path;
//! use structid_io::{IoError, Silverbox, SilverboxSplit};
//! let split: SilverboxSplit = "test-arrow-full".parse().unwrap();
//! assert_eq!(split.range(), 100..40575);
//! assert_eq!(split.settle(), 50);
//! let e = Silverbox::load(Path::new("no/such/SNLS80mV.csv")).unwrap_err();
//! assert!(matches!(e, IoError::BenchmarkMissing { .. }));
//! assert!(e.to_string().contains("Silverbox benchmark file was not found at `no/such/SNLS80mV.csv`"));
//! ```

use std::fmt;
use std::ops::Range;
use std::path::Path;
use std::str::FromStr;

use structid_core::Data;
use structid_lti::Signal;

use crate::data_file::DataTable;
use crate::error::IoError;

/// One record of a benchmark: input and output, sample time, and where scoring starts.
///
/// ```
/// use structid_io::Record;
/// let r = Record {
///     name: "example".into(),
///     u: vec![0.0, 1.0, 2.0, 3.0],
///     y: vec![0.0, 1.0, 2.0, 3.0],
///     sample_time: 0.5,
///     range: 10..14,
///     settle: 2,
/// };
/// // Only samples 2 and 3 are scored.
/// let rms = r.scored_rms(&[5.0, 5.0, 2.5, 3.5]).unwrap();
/// assert!((rms - 0.5).abs() < 1e-15);
/// assert_eq!(r.data().unwrap().len(), 4);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// A name such as `silverbox-estimation` or `cascaded-tanks-test`.
    pub name: String,
    /// The input u.
    pub u: Vec<f64>,
    /// The measured output y.
    pub y: Vec<f64>,
    /// Sample time in seconds.
    pub sample_time: f64,
    /// The samples of the record, as indices of the data rows of the original file (0-based,
    /// end exclusive).
    pub range: Range<usize>,
    /// Leading samples that may set the initial state and are not scored.
    pub settle: usize,
}

impl Record {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.y.len()
    }

    /// Whether the record has no samples (never true for a loaded record).
    pub fn is_empty(&self) -> bool {
        self.y.is_empty()
    }

    /// The record as identification data: u and y as one-channel signals.
    ///
    /// Fails only for a record built by hand with u and y of different lengths, no samples
    /// or non-finite values.
    pub fn data(&self) -> Result<Data, IoError> {
        let u = Signal::new(1, self.u.clone()).map_err(|e| IoError::Core(e.into()))?;
        let y = Signal::new(1, self.y.clone()).map_err(|e| IoError::Core(e.into()))?;
        Ok(Data::new(u, y)?)
    }

    /// The RMS of `y − y_sim` over the scored samples `settle..`, in the units of y (volts for
    /// both benchmarks; the Silverbox literature quotes millivolts).
    ///
    /// Fails when `y_sim` does not have one value per sample, holds a non-finite value, or no
    /// sample is scored.
    pub fn scored_rms(&self, y_sim: &[f64]) -> Result<f64, IoError> {
        if y_sim.len() != self.y.len() {
            return Err(IoError::InvalidArgument(format!(
                "{}: the simulated output has {} samples but the record has {}",
                self.name,
                y_sim.len(),
                self.y.len()
            )));
        }
        if let Some(k) = y_sim.iter().position(|v| !v.is_finite()) {
            return Err(IoError::InvalidArgument(format!(
                "{}: the simulated output is {} at sample {k}",
                self.name, y_sim[k]
            )));
        }
        if self.settle >= self.y.len() {
            return Err(IoError::InvalidArgument(format!(
                "{}: nothing to score: the record has {} samples and the first {} settle the state",
                self.name,
                self.y.len(),
                self.settle
            )));
        }
        let scored = &self.y[self.settle..];
        let sum: f64 = scored
            .iter()
            .zip(&y_sim[self.settle..])
            .map(|(y, s)| (y - s) * (y - s))
            .sum();
        Ok((sum / scored.len() as f64).sqrt())
    }
}

/// An error for a split name that is not one of `valid`.
fn unknown_split(benchmark: &str, s: &str, valid: &[&str]) -> IoError {
    IoError::InvalidArgument(format!(
        "unknown {benchmark} split `{s}`; valid splits: {}",
        valid.join(", ")
    ))
}

/// The splits of the Silverbox record used by the official loader.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SilverboxSplit {
    /// Estimation: samples `[40650, 105712)` (65062 samples of multisines).
    Estimation,
    /// Arrow-head test, full: samples `[100, 40575)` (40475 samples); its last part is
    /// extrapolation in amplitude.
    TestArrowFull,
    /// Arrow-head test without extrapolation: the first 32000 samples of the full arrow test,
    /// `[100, 32100)`.
    TestArrowNoExtrapolation,
    /// Multisine test: samples `[105712, 127400)` (21688 samples).
    TestMultisine,
}

impl SilverboxSplit {
    /// Every split, in the order of the text names below.
    pub const ALL: [Self; 4] = [
        Self::Estimation,
        Self::TestArrowFull,
        Self::TestArrowNoExtrapolation,
        Self::TestMultisine,
    ];

    /// The three test splits (every split but the estimation one).
    pub const TESTS: [Self; 3] = [
        Self::TestArrowFull,
        Self::TestArrowNoExtrapolation,
        Self::TestMultisine,
    ];

    /// The text name: `estimation`, `test-arrow-full`, `test-arrow-no-extrapolation` or
    /// `test-multisine`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Estimation => "estimation",
            Self::TestArrowFull => "test-arrow-full",
            Self::TestArrowNoExtrapolation => "test-arrow-no-extrapolation",
            Self::TestMultisine => "test-multisine",
        }
    }

    /// The split with text name `s` (see [`SilverboxSplit::name`]).
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|x| x.name() == s)
    }

    /// The samples of the split (0-based, end exclusive) in the file's data rows.
    pub fn range(self) -> Range<usize> {
        match self {
            Self::Estimation => 40650..105712,
            Self::TestArrowFull => 100..40575,
            Self::TestArrowNoExtrapolation => 100..32100,
            Self::TestMultisine => 105712..127400,
        }
    }

    /// Leading samples that may settle the initial state and are not scored: 50 for the test
    /// splits, 0 for estimation.
    pub fn settle(self) -> usize {
        match self {
            Self::Estimation => 0,
            _ => Silverbox::SETTLE,
        }
    }
}

impl fmt::Display for SilverboxSplit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SilverboxSplit {
    type Err = IoError;

    /// Like [`SilverboxSplit::parse`], with an error listing the valid names.
    fn from_str(s: &str) -> Result<Self, IoError> {
        Self::parse(s).ok_or_else(|| unknown_split("Silverbox", s, &Self::ALL.map(Self::name)))
    }
}

/// The Silverbox record, mean removed.
#[derive(Clone, Debug, PartialEq)]
pub struct Silverbox {
    /// The input u (column `V1`, volts) minus its mean.
    pub u: Vec<f64>,
    /// The output y (column `V2`, volts) minus its mean.
    pub y: Vec<f64>,
    /// The removed means of u and y.
    pub means: (f64, f64),
    /// Sample time in seconds, 2¹⁴/10⁷ = 1.6384 ms.
    pub sample_time: f64,
}

impl Silverbox {
    /// Number of samples of the official file.
    pub const SAMPLES: usize = 131072;
    /// Sample time of the record in seconds (fs = 10⁷/2¹⁴ Hz).
    pub const SAMPLE_TIME: f64 = 16384.0 / 1e7;
    /// Leading samples of a test split that settle the state and are not scored.
    pub const SETTLE: usize = 50;

    /// Reads the official `SNLS80mV.csv` and removes each column's mean.
    ///
    /// Fails with [`IoError::BenchmarkMissing`] when the file does not exist,
    /// [`IoError::Benchmark`] when the header is not `"V1","V2"` or the file does not have
    /// 131072 samples, and [`IoError::Data`] (with the line) for a field that is not a finite
    /// number.
    pub fn load(path: &Path) -> Result<Self, IoError> {
        const NAME: &str = "Silverbox";
        let t = read_benchmark(
            path,
            NAME,
            "it is `SNLS80mV.csv` from the Silverbox benchmark of nonlinearbenchmark.org (in this \
             project's layout `../shared/data/silverbox/SNLS80mV.csv` beside the project root)",
        )?;
        check_layout(&t, path, NAME, &["V1", "V2"], Self::SAMPLES)?;
        let mut u = column(&t, "V1")?;
        let mut y = column(&t, "V2")?;
        let mu = remove_mean(&mut u);
        let my = remove_mean(&mut y);
        Ok(Self {
            u,
            y,
            means: (mu, my),
            sample_time: Self::SAMPLE_TIME,
        })
    }

    /// The samples of split `s` as a [`Record`] named `silverbox-<split>`.
    ///
    /// The range is clipped to the samples present, so a hand-built, shorter `Silverbox`
    /// gives a shorter record rather than a panic.
    pub fn split(&self, s: SilverboxSplit) -> Record {
        let len = self.u.len().min(self.y.len());
        let r = s.range();
        let range = r.start.min(len)..r.end.min(len);
        Record {
            name: format!("silverbox-{}", s.name()),
            u: self.u[range.clone()].to_vec(),
            y: self.y[range.clone()].to_vec(),
            sample_time: self.sample_time,
            range,
            settle: s.settle(),
        }
    }
}

/// The two records of the cascaded-tanks benchmark.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TanksSplit {
    /// Estimation: columns `uEst`, `yEst`.
    Estimation,
    /// Test (validation): columns `uVal`, `yVal`.
    Test,
}

impl TanksSplit {
    /// Both splits.
    pub const ALL: [Self; 2] = [Self::Estimation, Self::Test];

    /// The text name: `estimation` or `test`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Estimation => "estimation",
            Self::Test => "test",
        }
    }

    /// The split with text name `s` (see [`TanksSplit::name`]).
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|x| x.name() == s)
    }
}

impl fmt::Display for TanksSplit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for TanksSplit {
    type Err = IoError;

    /// Like [`TanksSplit::parse`], with an error listing the valid names.
    fn from_str(s: &str) -> Result<Self, IoError> {
        Self::parse(s).ok_or_else(|| unknown_split("cascaded tanks", s, &Self::ALL.map(Self::name)))
    }
}

/// The cascaded-tanks benchmark: estimation and test records (no mean removed).
#[derive(Clone, Debug, PartialEq)]
pub struct CascadedTanks {
    /// The estimation record `cascaded-tanks-estimation` (uEst, yEst).
    pub estimation: Record,
    /// The test record `cascaded-tanks-test` (uVal, yVal).
    pub test: Record,
}

impl CascadedTanks {
    /// Number of samples of each record in the official file.
    pub const SAMPLES: usize = 1024;

    /// Reads the official `dataBenchmark.csv`.
    ///
    /// The sample time is the `Ts` value of the first data row (4 s in the official file;
    /// the column is empty below it). Fails with [`IoError::BenchmarkMissing`] when the file
    /// does not exist, [`IoError::Benchmark`] when the header is not
    /// `uEst,uVal,yEst,yVal,Ts`, the file does not have 1024 samples or Ts is missing or not
    /// positive, and [`IoError::Data`] (with the line) for a field that is not a finite number.
    pub fn load(path: &Path) -> Result<Self, IoError> {
        const NAME: &str = "cascaded tanks";
        let t = read_benchmark(
            path,
            NAME,
            "it is `dataBenchmark.csv` from the cascaded-tanks benchmark of nonlinearbenchmark.org \
             (in this project's layout `../shared/data/cascaded_tanks/dataBenchmark.csv` beside \
             the project root)",
        )?;
        check_layout(
            &t,
            path,
            NAME,
            &["uEst", "uVal", "yEst", "yVal", "Ts"],
            Self::SAMPLES,
        )?;
        let line = t.line_of_row(0);
        let ts = t.column("Ts").and_then(|c| c.first().copied());
        let sample_time = match ts {
            Some(ts) if ts > 0.0 => ts,
            Some(ts) if ts.is_nan() => {
                return Err(IoError::Benchmark {
                    benchmark: NAME,
                    path: path.to_path_buf(),
                    line,
                    message: "the sample time Ts is missing: the first data row needs a value in column `Ts`".into(),
                });
            }
            _ => {
                return Err(IoError::Benchmark {
                    benchmark: NAME,
                    path: path.to_path_buf(),
                    line,
                    message: format!(
                        "the sample time Ts = {} must be greater than zero",
                        ts.unwrap_or(f64::NAN)
                    ),
                });
            }
        };
        let record = |split: TanksSplit, u: &str, y: &str| -> Result<Record, IoError> {
            Ok(Record {
                name: format!("cascaded-tanks-{}", split.name()),
                u: column(&t, u)?,
                y: column(&t, y)?,
                sample_time,
                range: 0..Self::SAMPLES,
                settle: 0,
            })
        };
        Ok(Self {
            estimation: record(TanksSplit::Estimation, "uEst", "yEst")?,
            test: record(TanksSplit::Test, "uVal", "yVal")?,
        })
    }

    /// The record of split `s`.
    pub fn split(&self, s: TanksSplit) -> &Record {
        match s {
            TanksSplit::Estimation => &self.estimation,
            TanksSplit::Test => &self.test,
        }
    }
}

/// Reads a benchmark file; a missing file becomes [`IoError::BenchmarkMissing`].
fn read_benchmark(path: &Path, benchmark: &'static str, hint: &str) -> Result<DataTable, IoError> {
    match DataTable::read(path) {
        Err(IoError::Read { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
            Err(IoError::BenchmarkMissing {
                benchmark,
                path: path.to_path_buf(),
                hint: format!("pass the path of the official file: {hint}"),
            })
        }
        other => other,
    }
}

/// Checks the header and the number of data rows of a benchmark file.
fn check_layout(
    t: &DataTable,
    path: &Path,
    benchmark: &'static str,
    header: &[&str],
    samples: usize,
) -> Result<(), IoError> {
    let err = |line: Option<u64>, message: String| IoError::Benchmark {
        benchmark,
        path: path.to_path_buf(),
        line,
        message,
    };
    if t.names != header {
        return Err(err(
            t.header_line(),
            format!(
                "expected the header {} but found {}; is this the official file?",
                header.join(","),
                t.names.join(",")
            ),
        ));
    }
    if t.len() != samples {
        let message = if t.len() > samples {
            format!(
                "expected {samples} samples but the file has {}; the first extra row is at line {}",
                t.len(),
                t.line_of_row(samples).unwrap_or(0)
            )
        } else {
            format!(
                "expected {samples} samples but the file ends after {} (the last data row is at line {})",
                t.len(),
                t.line_of_row(t.len().saturating_sub(1)).unwrap_or(0)
            )
        };
        let line = t.line_of_row(samples.min(t.len().saturating_sub(1)));
        return Err(err(line, message));
    }
    Ok(())
}

/// One column with every field present (an empty field is an error naming its line).
fn column(t: &DataTable, name: &str) -> Result<Vec<f64>, IoError> {
    Ok(t.select(&[name])?.into_vec())
}

/// Subtracts the mean of `v` and returns it.
fn remove_mean(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    for x in v.iter_mut() {
        *x -= mean;
    }
    mean
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    /// A file with the layout of `SNLS80mV.csv` and `rows` synthetic rows.
    fn silverbox_text(rows: usize) -> String {
        let mut s = String::from("\"V1\",\"V2\",\n");
        for k in 0..rows {
            s.push_str(&format!(
                "{},{},\n",
                (k % 7) as f64 * 0.01,
                (k % 5) as f64 * -0.02
            ));
        }
        s
    }

    #[test]
    fn silverbox_synthetic_file_splits_and_means() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(dir.path(), "sb.csv", &silverbox_text(Silverbox::SAMPLES));
        let sb = Silverbox::load(&p).unwrap();
        assert_eq!(sb.u.len(), Silverbox::SAMPLES);
        assert!(sb.u.iter().sum::<f64>().abs() / (sb.u.len() as f64) < 1e-12);
        let lens = [65062, 40475, 32000, 21688];
        for (s, len) in SilverboxSplit::ALL.into_iter().zip(lens) {
            let r = sb.split(s);
            assert_eq!(r.len(), len, "{s}");
            assert_eq!(r.range, s.range());
            assert_eq!(SilverboxSplit::parse(s.name()), Some(s));
            assert_eq!(r.u[0], sb.u[s.range().start]);
        }
        assert_eq!(sb.split(SilverboxSplit::TestMultisine).settle, 50);
        assert_eq!(sb.split(SilverboxSplit::Estimation).settle, 0);
        // A hand-built short record is clipped, not a panic.
        let short = Silverbox {
            u: vec![0.0; 200],
            y: vec![0.0; 200],
            means: (0.0, 0.0),
            sample_time: 1.0,
        };
        assert_eq!(short.split(SilverboxSplit::TestArrowFull).range, 100..200);
        assert!(short.split(SilverboxSplit::Estimation).is_empty());
    }

    #[test]
    fn silverbox_layout_errors_name_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(dir.path(), "short.csv", &silverbox_text(10));
        let e = Silverbox::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("short.csv`, line 11")
                && e.contains("expected 131072 samples")
                && e.contains("ends after 10"),
            "{e}"
        );
        let p = write(
            dir.path(),
            "long.csv",
            &silverbox_text(Silverbox::SAMPLES + 3),
        );
        let e = Silverbox::load(&p).unwrap_err().to_string();
        assert!(e.contains("line 131074") && e.contains("131075"), "{e}");
        let p = write(dir.path(), "hdr.csv", "# note\nu,y\n1,2\n");
        let e = Silverbox::load(&p).unwrap_err();
        assert!(matches!(e, IoError::Benchmark { line: Some(2), .. }), "{e}");
        assert!(
            e.to_string()
                .contains("expected the header V1,V2 but found u,y"),
            "{e}"
        );
        let mut text = silverbox_text(Silverbox::SAMPLES);
        text = text.replacen("0.01,", "0.0x1,", 1);
        let p = write(dir.path(), "bad.csv", &text);
        let e = Silverbox::load(&p).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("`0.0x1`"), "{e}");
        let text = silverbox_text(5).replacen("0.02", "NaN", 1);
        let p = write(dir.path(), "nan.csv", &text);
        let e = Silverbox::load(&p).unwrap_err().to_string();
        assert!(e.contains("NaN") && e.contains("line "), "{e}");
        let e = Silverbox::load(&dir.path().join("missing.csv")).unwrap_err();
        assert!(e.is_input_error());
        let e = e.to_string();
        assert!(
            e.contains("Silverbox") && e.contains("missing.csv") && e.contains("SNLS80mV.csv"),
            "{e}"
        );
    }

    fn tanks_text(rows: usize, ts: &str) -> String {
        let mut s = String::from("\"uEst\",\"uVal\",\"yEst\",\"yVal\",\"Ts\",\n");
        for k in 0..rows {
            let ts = if k == 0 { ts } else { "" };
            s.push_str(&format!("{k},{},{},{},{ts},\n", k + 1, k + 2, k + 3));
        }
        s.push('\n');
        s
    }

    #[test]
    fn tanks_synthetic_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(dir.path(), "t.csv", &tanks_text(1024, "4"));
        let t = CascadedTanks::load(&p).unwrap();
        assert_eq!(t.estimation.u[5], 5.0);
        assert_eq!(t.estimation.y[5], 7.0);
        assert_eq!(t.split(TanksSplit::Test).u[5], 6.0);
        assert_eq!(t.test.y[1023], 1026.0);
        assert_eq!(t.test.sample_time, 4.0);
        assert_eq!(t.test.name, "cascaded-tanks-test");
        assert_eq!("test".parse::<TanksSplit>().unwrap(), TanksSplit::Test);
        let e = "val".parse::<TanksSplit>().unwrap_err().to_string();
        assert!(e.contains("valid splits: estimation, test"), "{e}");

        let p = write(dir.path(), "nots.csv", &tanks_text(1024, ""));
        let e = CascadedTanks::load(&p).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("Ts is missing"), "{e}");
        let p = write(dir.path(), "negts.csv", &tanks_text(1024, "-4"));
        let e = CascadedTanks::load(&p).unwrap_err().to_string();
        assert!(e.contains("greater than zero"), "{e}");
        let p = write(dir.path(), "short.csv", &tanks_text(1000, "4"));
        let e = CascadedTanks::load(&p).unwrap_err().to_string();
        assert!(e.contains("expected 1024 samples"), "{e}");
        // An empty u or y field names its line.
        let text = tanks_text(1024, "4").replacen("\n5,6,7,8,,", "\n5,,7,8,,", 1);
        let p = write(dir.path(), "gap.csv", &text);
        let e = CascadedTanks::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("line 7") && e.contains("`uVal`") && e.contains("empty"),
            "{e}"
        );
    }

    #[test]
    fn scored_rms_checks_its_input() {
        let r = Record {
            name: "r".into(),
            u: vec![0.0; 3],
            y: vec![1.0, 2.0, 3.0],
            sample_time: 1.0,
            range: 0..3,
            settle: 1,
        };
        assert_eq!(r.scored_rms(&[0.0, 2.0, 3.0]).unwrap(), 0.0);
        assert!(r.scored_rms(&[0.0, 2.0]).is_err());
        assert!(r.scored_rms(&[0.0, f64::NAN, 3.0]).is_err());
        let all_settle = Record {
            settle: 3,
            ..r.clone()
        };
        assert!(all_settle.scored_rms(&[1.0, 2.0, 3.0]).is_err());
        let bad = Record {
            u: vec![0.0; 2],
            ..r
        };
        assert!(bad.data().is_err());
    }
}

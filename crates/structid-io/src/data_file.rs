//! Data files: CSV with a header row of column names and numeric rows.
//!
//! The reader is strict about content and lenient about layout:
//!
//! * every value must parse as a finite number; a non-numeric field, `NaN` or `inf` is an
//!   error that names the line and the column;
//! * every row must have as many fields as the header;
//! * column names must be unique and non-empty;
//! * quoted fields (`"V1","V2"`), whitespace around fields, blank lines, lines starting with
//!   `#`, a UTF-8 byte-order mark and a trailing comma on every line (as in the Silverbox
//!   benchmark file, header `"V1","V2",`) are accepted;
//! * an **empty** field is kept as a gap in its column; it is an error only when that column is
//!   selected ([`DataTable::select`]). Files such as the cascaded-tanks benchmark, whose `Ts`
//!   column holds a single value, can therefore be read and their other columns used.
//!
//! ```
//! use structid_io::DataTable;
//! let t = DataTable::parse("\"u0\",\"y0\",\n1.0, 2.0,\n3.0, 4.0,\n", None).unwrap();
//! assert_eq!(t.names, ["u0", "y0"]);
//! let y = t.select(&["y0"]).unwrap();
//! assert_eq!(y.channel(0), vec![2.0, 4.0]);
//! let e = DataTable::parse("u0,y0\n1,2\n3,abc\n", None).unwrap_err().to_string();
//! assert_eq!(e, "data, line 3, column `y0`: cannot parse `abc` as a number");
//! ```

use std::path::{Path, PathBuf};

use structid_lti::Signal;

use crate::error::IoError;
use crate::output::{OutputGuard, write_atomic};

/// A table of named numeric columns read from a CSV file.
///
/// `columns[c][k]` is the value of column `names[c]` in data row `k`. An empty field in the
/// file is stored as NaN and remembered, so that [`DataTable::select`] can report it with its
/// line number; values given in the file are always finite.
#[derive(Clone, Debug, PartialEq)]
pub struct DataTable {
    /// Column names, in file order.
    pub names: Vec<String>,
    /// Column values, one vector per name, all of the same length.
    pub columns: Vec<Vec<f64>>,
    /// One-based file line of each data row.
    lines: Vec<u64>,
    /// For each column, the line of its first empty field.
    first_empty: Vec<Option<u64>>,
    /// The file the table was read from.
    path: Option<PathBuf>,
}

/// The name the specification uses for the reader: `DataFile::read(path)`.
pub type DataFile = DataTable;

fn data_err(
    path: Option<&Path>,
    line: Option<u64>,
    column: Option<&str>,
    message: impl Into<String>,
) -> IoError {
    IoError::Data {
        path: path.map(Path::to_path_buf),
        line,
        column: column.map(str::to_string),
        message: message.into(),
    }
}

impl DataTable {
    /// A table from explicit columns (all finite, equal lengths, unique non-empty names).
    pub fn new(names: Vec<String>, columns: Vec<Vec<f64>>) -> Result<Self, IoError> {
        if names.len() != columns.len() {
            return Err(IoError::InvalidArgument(format!(
                "{} column names for {} columns",
                names.len(),
                columns.len()
            )));
        }
        check_names(&names, None, None)?;
        let len = columns.first().map_or(0, Vec::len);
        for (name, col) in names.iter().zip(&columns) {
            if col.len() != len {
                return Err(IoError::InvalidArgument(format!(
                    "column `{name}` has {} values but column `{}` has {len}",
                    col.len(),
                    names[0]
                )));
            }
            if let Some(k) = col.iter().position(|v| !v.is_finite()) {
                return Err(IoError::InvalidArgument(format!(
                    "column `{name}` has the non-finite value {} in row {k}",
                    col[k]
                )));
            }
        }
        Ok(Self {
            first_empty: vec![None; names.len()],
            lines: (0..len as u64).map(|k| k + 2).collect(),
            names,
            columns,
            path: None,
        })
    }

    /// Reads a CSV file (see the module documentation for the accepted format).
    pub fn read(path: &Path) -> Result<Self, IoError> {
        let bytes = std::fs::read(path).map_err(|source| IoError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let mut t = Self::parse_bytes(&bytes, Some(path))?;
        t.path = Some(path.to_path_buf());
        Ok(t)
    }

    /// Parses CSV text; `path` is only used in error messages.
    pub fn parse(text: &str, path: Option<&Path>) -> Result<Self, IoError> {
        Self::parse_bytes(text.as_bytes(), path)
    }

    fn parse_bytes(bytes: &[u8], path: Option<&Path>) -> Result<Self, IoError> {
        let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        // Comment lines are blanked rather than left to the csv crate, which does not count
        // them in its line numbers.
        let is_comment = |l: &[u8]| l.trim_ascii_start().first() == Some(&b'#');
        let uncommented: Vec<u8>;
        let bytes = if bytes.split(|&b| b == b'\n').any(is_comment) {
            let mut out = Vec::with_capacity(bytes.len());
            for (i, l) in bytes.split(|&b| b == b'\n').enumerate() {
                if i > 0 {
                    out.push(b'\n');
                }
                if !is_comment(l) {
                    out.extend_from_slice(l);
                }
            }
            uncommented = out;
            &uncommented[..]
        } else {
            bytes
        };
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(bytes);
        // The csv crate does not count blank lines in `Position::line`, so lines are derived
        // from byte offsets: the first non-blank byte at or after the record's start.
        let line_starts: Vec<usize> = std::iter::once(0)
            .chain(
                bytes
                    .iter()
                    .enumerate()
                    .filter(|(_, b)| **b == b'\n')
                    .map(|(i, _)| i + 1),
            )
            .collect();
        let line_at = |pos: &csv::Position| -> u64 {
            let mut b = (pos.byte() as usize).min(bytes.len());
            while b < bytes.len() && bytes[b].is_ascii_whitespace() {
                b += 1;
            }
            line_starts.partition_point(|&s| s <= b) as u64
        };
        let mut records = reader.records();
        let csv_err = |e: csv::Error| {
            let line = e.position().map(line_at);
            let msg = match e.kind() {
                csv::ErrorKind::Utf8 { .. } => "the file is not valid UTF-8 text".to_string(),
                _ => format!("malformed CSV: {e}"),
            };
            data_err(path, line, None, msg)
        };
        // Header: the first record that is not blank.
        let header = loop {
            match records.next() {
                None => {
                    return Err(data_err(
                        path,
                        None,
                        None,
                        "the file is empty; expected a header row with column names followed by numeric rows",
                    ));
                }
                Some(r) => {
                    let r = r.map_err(csv_err)?;
                    if !is_blank(&r) {
                        break r;
                    }
                }
            }
        };
        let header_line = header.position().map(line_at);
        let mut names: Vec<String> = header.iter().map(|s| s.trim().to_string()).collect();
        if names.len() > 1 && names.last().is_some_and(String::is_empty) {
            names.pop();
        }
        check_names(&names, path, header_line)?;
        if names.iter().all(|n| n.parse::<f64>().is_ok()) {
            return Err(data_err(
                path,
                header_line,
                None,
                format!(
                    "the first row ({}) looks numeric; the file needs a header row naming the columns",
                    names.join(",")
                ),
            ));
        }
        let ncols = names.len();
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); ncols];
        let mut first_empty: Vec<Option<u64>> = vec![None; ncols];
        let mut lines = Vec::new();
        for r in records {
            let r = r.map_err(csv_err)?;
            if is_blank(&r) {
                continue;
            }
            let line = r.position().map_or(0, line_at);
            let mut fields: Vec<&str> = r.iter().collect();
            if fields.len() == ncols + 1 && fields.last().is_some_and(|f| f.is_empty()) {
                fields.pop();
            }
            if fields.len() != ncols {
                return Err(data_err(
                    path,
                    Some(line),
                    None,
                    format!(
                        "expected {ncols} field(s) as in the header ({}) but found {}",
                        names.join(","),
                        fields.len()
                    ),
                ));
            }
            for (c, field) in fields.iter().enumerate() {
                let field = field.trim();
                let v = if field.is_empty() {
                    if first_empty[c].is_none() {
                        first_empty[c] = Some(line);
                    }
                    f64::NAN
                } else {
                    let v: f64 = field.parse().map_err(|_| {
                        data_err(
                            path,
                            Some(line),
                            Some(&names[c]),
                            format!("cannot parse `{field}` as a number"),
                        )
                    })?;
                    if v.is_nan() {
                        return Err(data_err(path, Some(line), Some(&names[c]), "value is NaN"));
                    }
                    if v.is_infinite() {
                        return Err(data_err(
                            path,
                            Some(line),
                            Some(&names[c]),
                            format!("value is infinite (`{field}`)"),
                        ));
                    }
                    v
                };
                columns[c].push(v);
            }
            lines.push(line);
        }
        if lines.is_empty() {
            return Err(data_err(
                path,
                header_line,
                None,
                "the file has a header row but no data rows",
            ));
        }
        Ok(Self {
            names,
            columns,
            lines,
            first_empty,
            path: path.map(Path::to_path_buf),
        })
    }

    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    /// Whether there are no data rows (never true for a table read from a file).
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }

    /// The file the table was read from, if any.
    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }

    /// The values of column `name`, if present (empty fields are NaN).
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.index_of(name).map(|c| self.columns[c].as_slice())
    }

    fn index_of(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// The columns `names`, in that order, as one signal (channel i = `names[i]`).
    ///
    /// Fails with [`IoError::MissingColumn`] (listing the available columns) when a name is
    /// absent, and with [`IoError::Data`] naming the line when a selected column has an empty
    /// field.
    pub fn select<S: AsRef<str>>(&self, names: &[S]) -> Result<Signal, IoError> {
        let mut cols = Vec::with_capacity(names.len());
        for name in names {
            let name = name.as_ref();
            let c = self.index_of(name).ok_or_else(|| IoError::MissingColumn {
                path: self.path.clone(),
                column: name.to_string(),
                available: self.names.clone(),
            })?;
            if let Some(line) = self.first_empty[c] {
                return Err(data_err(
                    self.path.as_deref(),
                    Some(line),
                    Some(name),
                    "empty field; every selected column needs a value in every row",
                ));
            }
            cols.push(self.columns[c].clone());
        }
        if cols.is_empty() {
            return Ok(Signal::zeros(self.len(), 0));
        }
        Signal::from_channels(&cols).map_err(|e| IoError::InvalidArgument(e.to_string()))
    }

    /// The one-based file line of data row `k`, if it exists.
    pub fn line_of_row(&self, k: usize) -> Option<u64> {
        self.lines.get(k).copied()
    }
}

fn is_blank(r: &csv::StringRecord) -> bool {
    r.iter().all(|f| f.trim().is_empty())
}

fn check_names(names: &[String], path: Option<&Path>, line: Option<u64>) -> Result<(), IoError> {
    for (i, n) in names.iter().enumerate() {
        if n.is_empty() {
            return Err(data_err(
                path,
                line,
                None,
                format!("header column {} has an empty name", i + 1),
            ));
        }
        if let Some(j) = names[..i].iter().position(|m| m == n) {
            return Err(data_err(
                path,
                line,
                None,
                format!(
                    "duplicate column name `{n}` (header columns {} and {})",
                    j + 1,
                    i + 1
                ),
            ));
        }
    }
    Ok(())
}

/// Formats a number so that it parses back to the same `f64` (shortest round-trip form,
/// scientific notation for very large or small magnitudes).
pub fn format_number(v: f64) -> String {
    format!("{v:?}")
}

/// The bytes of a CSV file with a header `names` and one row per sample.
///
/// Fails when `names` and `columns` differ in number, the columns differ in length, or a name
/// is repeated.
pub fn csv_bytes<S: AsRef<str>>(names: &[S], columns: &[Vec<f64>]) -> Result<Vec<u8>, IoError> {
    if names.len() != columns.len() {
        return Err(IoError::InvalidArgument(format!(
            "{} column names for {} columns",
            names.len(),
            columns.len()
        )));
    }
    let owned: Vec<String> = names.iter().map(|n| n.as_ref().to_string()).collect();
    check_names(&owned, None, None)
        .map_err(|e| IoError::InvalidArgument(format!("cannot write CSV: {e}")))?;
    let len = columns.first().map_or(0, Vec::len);
    if let Some(c) = columns.iter().position(|c| c.len() != len) {
        return Err(IoError::InvalidArgument(format!(
            "column `{}` has {} values but column `{}` has {len}",
            owned[c],
            columns[c].len(),
            owned[0]
        )));
    }
    let mut w =
        csv::WriterBuilder::new().from_writer(Vec::with_capacity(len * columns.len() * 12 + 64));
    let to_io = |e: csv::Error| IoError::InvalidArgument(format!("cannot format CSV: {e}"));
    w.write_record(&owned).map_err(to_io)?;
    let mut row = Vec::with_capacity(columns.len());
    for k in 0..len {
        row.clear();
        row.extend(columns.iter().map(|c| format_number(c[k])));
        w.write_record(&row).map_err(to_io)?;
    }
    w.into_inner()
        .map_err(|e| IoError::InvalidArgument(format!("cannot format CSV: {e}")))
}

/// Writes a CSV file atomically (see [`write_atomic`]).
pub fn write_csv<S: AsRef<str>>(
    path: &Path,
    names: &[S],
    columns: &[Vec<f64>],
) -> Result<(), IoError> {
    write_atomic(path, &csv_bytes(names, columns)?, &[])
}

impl OutputGuard {
    /// Writes a CSV file atomically unless `path` is a protected input.
    pub fn write_csv<S: AsRef<str>>(
        &self,
        path: &Path,
        names: &[S],
        columns: &[Vec<f64>],
    ) -> Result<(), IoError> {
        self.write(path, &csv_bytes(names, columns)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trailing_comma_and_quoted_header_like_silverbox() {
        let text = "\"V1\",\"V2\",\n0.0057756,0.0093978,\n0.0066102,0.012971,\n";
        let t = DataTable::parse(text, None).unwrap();
        assert_eq!(t.names, ["V1", "V2"]);
        assert_eq!(t.len(), 2);
        assert_eq!(t.column("V2").unwrap(), &[0.0093978, 0.012971]);
    }

    #[test]
    fn whitespace_blank_lines_comments_and_bom() {
        let text = "\u{feff}# a comment\n  u0 , y0 \n\n 1 ,  2\n# more\n3,4\n\n";
        let t = DataTable::parse(text, None).unwrap();
        assert_eq!(t.names, ["u0", "y0"]);
        assert_eq!(t.columns, vec![vec![1.0, 3.0], vec![2.0, 4.0]]);
        assert_eq!(t.line_of_row(0), Some(4));
        assert_eq!(t.line_of_row(1), Some(6));
        let e = DataTable::parse("a,b\n\n\n1,2\r\n\r\n# c,\"\n3,x\n", None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 7"), "{e}");
    }

    #[test]
    fn nan_and_infinity_are_rejected_with_line_numbers() {
        let mut text = String::from("u0,y0\n");
        for k in 0..15 {
            text.push_str(&format!("{k},{k}\n"));
        }
        text.push_str("1,NaN\n");
        let e = DataTable::parse(&text, Some(Path::new("d.csv")))
            .unwrap_err()
            .to_string();
        assert_eq!(e, "data file `d.csv`, line 17, column `y0`: value is NaN");
        let e = DataTable::parse("u0,y0\n1,2\n-inf,3\n", None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 3") && e.contains("`u0`") && e.contains("infinite"),
            "{e}"
        );
    }

    #[test]
    fn non_numeric_field_names_line_and_column() {
        let e = DataTable::parse("u0,y0\n1,2\n3,abc\n", Some(Path::new("x.csv")))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "data file `x.csv`, line 3, column `y0`: cannot parse `abc` as a number"
        );
    }

    #[test]
    fn wrong_field_count_empty_file_and_duplicates() {
        let e = DataTable::parse("a,b\n1,2\n1,2,3\n", None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 3") && e.contains("expected 2 field(s)") && e.contains("found 3"),
            "{e}"
        );
        let e = DataTable::parse("", None).unwrap_err().to_string();
        assert!(e.contains("empty"), "{e}");
        let e = DataTable::parse("a,b\n", None).unwrap_err().to_string();
        assert!(e.contains("no data rows"), "{e}");
        let e = DataTable::parse("a,b,a\n1,2,3\n", None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("duplicate column name `a`"), "{e}");
        let e = DataTable::parse("1,2\n3,4\n", None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("header"), "{e}");
    }

    #[test]
    fn missing_column_lists_available_ones() {
        let t = DataTable::parse("u0,y0\n1,2\n", Some(Path::new("d.csv"))).unwrap();
        let e = t.select(&["u0", "y1"]).unwrap_err().to_string();
        assert_eq!(
            e,
            "data file `d.csv` has no column `y1`; available columns: `u0`, `y0`"
        );
    }

    #[test]
    fn empty_fields_only_matter_when_selected() {
        // Like the cascaded-tanks file: Ts has one value only.
        let text = "\"uEst\",\"yEst\",\"Ts\",\n3.2,5.2,4,\n3.1,5.3,,\n";
        let t = DataTable::parse(text, None).unwrap();
        assert_eq!(t.select(&["uEst", "yEst"]).unwrap().len(), 2);
        let e = t.select(&["Ts"]).unwrap_err().to_string();
        assert!(
            e.contains("line 3") && e.contains("`Ts`") && e.contains("empty"),
            "{e}"
        );
    }

    #[test]
    fn csv_round_trip_is_exact() {
        let cols = vec![vec![0.1, -1e-300, 12345.678], vec![1.0 / 3.0, 2e20, -0.0]];
        let bytes = csv_bytes(&["a", "b"], &cols).unwrap();
        let t = DataTable::parse(std::str::from_utf8(&bytes).unwrap(), None).unwrap();
        assert_eq!(t.columns, cols);
        assert!(csv_bytes(&["a", "a"], &cols).is_err());
        assert!(csv_bytes(&["a"], &cols).is_err());
    }
}

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
//! [`DataTable::read_with`] and [`CsvOptions`] add another delimiter, files without a header,
//! leading lines to skip, and the selection, order and renaming of columns ([`ColumnRef`]).
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

use crate::array_file::{ArrayFile, Format, Vars};
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
    /// One-based file line of the header row, when the table was read with one.
    header_line: Option<u64>,
    /// The file the table was read from.
    path: Option<PathBuf>,
}

/// The name the specification uses for the reader: `DataFile::read(path)`.
pub type DataFile = DataTable;

/// How [`DataTable::read_with`] reads a delimited text file.
///
/// The default reads a comma-separated file whose first non-blank, non-comment line is the
/// header, keeping every column under its header name: exactly [`DataTable::read`].
///
/// * `delimiter`: the field separator (`b','`; `b';'` and `b'\t'` are common). Any ASCII
///   character except a quote, `#` or a line break.
/// * `header`: whether the first row (after `skip_rows`) names the columns. Without a header
///   the columns are called `c0, c1, …` unless `names` names them.
/// * `skip_rows`: physical lines at the start of the file to ignore, whatever they hold
///   (comment or title lines of instrument logs). Line numbers in errors still count them.
/// * `columns`: the columns to keep, in this order (see [`ColumnRef`]); `None` keeps all.
///   Fields of the other columns are not parsed, and an empty field in a selected column is
///   an error naming its line.
/// * `names`: the names of the kept columns, one per selected column (or per file column
///   when `columns` is `None`): renames header columns or names headerless ones.
///
/// ```
/// use structid_io::{CsvOptions, DataTable};
/// let options = CsvOptions { header: false, names: Some(vec!["u".into(), "y".into()]), ..Default::default() };
/// let t = DataTable::parse_with("1,2,\n3,4,\n\n", None, &options).unwrap();
/// assert_eq!(t.names, ["u", "y"]);
/// assert_eq!(t.column("y").unwrap(), &[2.0, 4.0]);
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CsvOptions {
    /// The field separator (default `b','`).
    pub delimiter: u8,
    /// Whether the first row names the columns (default `true`).
    pub header: bool,
    /// Lines at the start of the file to ignore (default 0).
    pub skip_rows: usize,
    /// The columns to keep, in order (default: all, in file order).
    pub columns: Option<Vec<ColumnRef>>,
    /// Names of the kept columns (default: the header's names, or `c0, c1, …` without header).
    pub names: Option<Vec<String>>,
}

impl Default for CsvOptions {
    fn default() -> Self {
        Self {
            delimiter: b',',
            header: true,
            skip_rows: 0,
            columns: None,
            names: None,
        }
    }
}

/// A column of a data file, by header name or by zero-based position.
///
/// In text form (`FromStr`, used by `structid data csv --columns`), `#` followed by digits is
/// a zero-based index (`#0` is the first column) and anything else is a name, digits included
/// (`3` is the column whose header is `3`). Surrounding whitespace is ignored.
///
/// ```
/// use structid_io::ColumnRef;
/// assert_eq!("#2".parse::<ColumnRef>().unwrap(), ColumnRef::Index(2));
/// assert_eq!("V1".parse::<ColumnRef>().unwrap(), ColumnRef::Name("V1".into()));
/// assert_eq!("3".parse::<ColumnRef>().unwrap(), ColumnRef::Name("3".into()));
/// assert!("#x".parse::<ColumnRef>().is_err());
/// assert_eq!(ColumnRef::parse_list("u, #1").unwrap(), [ColumnRef::Name("u".into()), ColumnRef::Index(1)]);
/// assert_eq!(ColumnRef::Index(4).to_string(), "#4");
/// ```
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum ColumnRef {
    /// The column with this header name.
    Name(String),
    /// The column at this zero-based position.
    Index(usize),
}

impl ColumnRef {
    /// Parses a comma-separated list such as `V1,V2` or `#0,#3`.
    pub fn parse_list(list: &str) -> Result<Vec<Self>, IoError> {
        list.split(',').map(str::parse).collect()
    }
}

impl std::str::FromStr for ColumnRef {
    type Err = IoError;

    fn from_str(s: &str) -> Result<Self, IoError> {
        let s = s.trim();
        if s.is_empty() {
            return Err(IoError::InvalidArgument(
                "empty column reference; give a column name or `#` and a zero-based index".into(),
            ));
        }
        match s.strip_prefix('#') {
            Some(digits) => digits
                .parse::<usize>()
                .ok()
                .filter(|_| digits.bytes().all(|b| b.is_ascii_digit()))
                .map(ColumnRef::Index)
                .ok_or_else(|| {
                    IoError::InvalidArgument(format!(
                        "invalid column reference `{s}`: `#` must be followed by a zero-based column index such as `#0`"
                    ))
                }),
            None => Ok(ColumnRef::Name(s.to_string())),
        }
    }
}

impl std::fmt::Display for ColumnRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ColumnRef::Name(n) => f.write_str(n),
            ColumnRef::Index(i) => write!(f, "#{i}"),
        }
    }
}

/// The [`CsvOptions`] that select the columns of `vars` from a CSV file with a header.
fn csv_options(vars: &Vars) -> Result<CsvOptions, IoError> {
    let columns = vars
        .refs()
        .map(|r| match (&r.variable, r.column) {
            (Some(v), None) => Ok(ColumnRef::Name(v.clone())),
            (None, Some(j)) => Ok(ColumnRef::Index(j)),
            _ => Err(IoError::InvalidArgument(format!(
                "invalid variable selection `{r}` for a CSV file: name a column of the header \
                 (`V1`) or give its zero-based position (`#0`)"
            ))),
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(CsvOptions {
        columns: Some(columns),
        names: Some(vars.names().map(str::to_string).collect()),
        ..CsvOptions::default()
    })
}

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
            header_line: None,
            lines: (0..len as u64).map(|k| k + 2).collect(),
            names,
            columns,
            path: None,
        })
    }

    /// Reads a data file: a CSV file (see the module documentation for the accepted format),
    /// or a MATLAB MAT-file, NumPy `.npy` or `.npz` file ([`crate::array_file`]), recognised
    /// by its first bytes, with every real numeric variable as a column.
    ///
    /// For a CSV file, the same as [`DataTable::read_with`] with the default [`CsvOptions`];
    /// the same as [`DataTable::read_vars`] without a selection.
    pub fn read(path: &Path) -> Result<Self, IoError> {
        Self::read_vars(path, None)
    }

    /// Reads a data file of any format [`DataTable::read`] reads, keeping the signals `vars`
    /// selects under the names it gives them (all columns or variables without it).
    ///
    /// In a MAT-file or `.npz` archive a signal is a variable (`u=vir`), a column of a matrix
    /// variable (`u=data#0`), or, in a `.npy` file, a column of its array (`u=#0`); in a CSV
    /// file it is a column of the header (`u=V1`) or a column by position (`u=#0`).
    ///
    /// ```
    /// use structid_io::{DataTable, Vars};
    /// let dir = tempfile::tempdir().unwrap();
    /// let path = dir.path().join("d.csv");
    /// std::fs::write(&path, "V1,V2\n1,2\n3,4\n").unwrap();
    /// let vars: Vars = "y=V2,u=#0".parse().unwrap();
    /// let t = DataTable::read_vars(&path, Some(&vars)).unwrap();
    /// assert_eq!(t.names, ["y", "u"]);
    /// assert_eq!(t.columns, vec![vec![2.0, 4.0], vec![1.0, 3.0]]);
    /// // A MAT-file that is HDF5 (v7.3) says what to do.
    /// let mat = dir.path().join("d.mat");
    /// let mut bytes = b"MATLAB 7.3 MAT-file".to_vec();
    /// bytes.resize(600, 0);
    /// std::fs::write(&mat, bytes).unwrap();
    /// let e = DataTable::read(&mat).unwrap_err().to_string();
    /// assert!(e.contains("v7.3") && e.contains("-v7"), "{e}");
    /// ```
    pub fn read_vars(path: &Path, vars: Option<&Vars>) -> Result<Self, IoError> {
        let read_err = |source| IoError::Read {
            path: path.to_path_buf(),
            source,
        };
        let mut head = Vec::with_capacity(16);
        {
            use std::io::Read;
            let file = std::fs::File::open(path).map_err(read_err)?;
            file.take(16).read_to_end(&mut head).map_err(read_err)?;
        }
        let extension = path.extension().and_then(|e| e.to_str());
        let format = Format::detect(&head, extension);
        if format == Format::Csv {
            let options = match vars {
                None => CsvOptions::default(),
                Some(v) => csv_options(v)?,
            };
            return Self::read_with(path, &options);
        }
        let bytes = std::fs::read(path).map_err(read_err)?;
        let array_err = |source| IoError::ArrayFile {
            path: path.to_path_buf(),
            source,
        };
        let file = match format {
            Format::Npy => ArrayFile::parse_npy(&bytes),
            Format::Npz => ArrayFile::parse_npz(&bytes),
            _ => ArrayFile::parse_mat(&bytes),
        }
        .map_err(array_err)?;
        drop(bytes);
        let (names, columns) = file.columns(vars).map_err(array_err)?;
        if columns.first().map_or(0, Vec::len) > MAX_ROWS {
            return Err(IoError::TooManyRows {
                path: path.to_path_buf(),
                limit: MAX_ROWS,
            });
        }
        let mut t = Self::new(names, columns).map_err(|e| match e {
            IoError::InvalidArgument(m) => data_err(Some(path), None, None, m),
            e => e,
        })?;
        t.path = Some(path.to_path_buf());
        Ok(t)
    }

    /// Reads a CSV file with explicit [`CsvOptions`]: delimiter, header or not, lines to skip,
    /// column selection and names.
    ///
    /// With [`CsvOptions::columns`] set, the table holds only the selected columns, in the
    /// order given; fields of the other columns are not parsed at all (they may be empty or
    /// non-numeric), and an empty field in a selected column is an error naming its line.
    ///
    /// ```
    /// use structid_io::{ColumnRef, CsvOptions, DataTable};
    /// let dir = tempfile::tempdir().unwrap();
    /// let path = dir.path().join("log.txt");
    /// std::fs::write(&path, "recorded 2024-01-01\n0.5;7;x\n0.25;8;y\n").unwrap();
    /// let options = CsvOptions {
    ///     delimiter: b';',
    ///     header: false,
    ///     skip_rows: 1,
    ///     columns: Some(vec![ColumnRef::Index(1), ColumnRef::Index(0)]),
    ///     names: Some(vec!["u".into(), "y".into()]),
    /// };
    /// let t = DataTable::read_with(&path, &options).unwrap();
    /// assert_eq!(t.names, ["u", "y"]);
    /// assert_eq!(t.columns, vec![vec![7.0, 8.0], vec![0.5, 0.25]]);
    /// assert_eq!(t.line_of_row(1), Some(3));
    /// ```
    pub fn read_with(path: &Path, options: &CsvOptions) -> Result<Self, IoError> {
        Self::read_with_limit(path, options, MAX_ROWS)
    }

    /// [`DataTable::read_with`] with another limit on the number of data rows than
    /// [`MAX_ROWS`]: a file with more than `max_rows` rows is refused with
    /// [`IoError::TooManyRows`] after counting its lines, before anything is parsed, so that an
    /// oversized file costs neither the memory of its parsed rows nor the time to parse them.
    ///
    /// ```
    /// use structid_io::{CsvOptions, DataTable, IoError};
    /// let dir = tempfile::tempdir().unwrap();
    /// let path = dir.path().join("d.csv");
    /// std::fs::write(&path, "u,y\n1,2\n3,4\n5,6\n").unwrap();
    /// let options = CsvOptions::default();
    /// assert_eq!(DataTable::read_with_limit(&path, &options, 3).unwrap().len(), 3);
    /// let e = DataTable::read_with_limit(&path, &options, 2).unwrap_err();
    /// assert!(matches!(e, IoError::TooManyRows { limit: 2, .. }), "{e}");
    /// ```
    pub fn read_with_limit(
        path: &Path,
        options: &CsvOptions,
        max_rows: usize,
    ) -> Result<Self, IoError> {
        let read_err = |source| IoError::Read {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::open(path).map_err(read_err)?;
        if count_rows(file, options, max_rows).map_err(read_err)? > max_rows {
            return Err(IoError::TooManyRows {
                path: path.to_path_buf(),
                limit: max_rows,
            });
        }
        let bytes = std::fs::read(path).map_err(|source| IoError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let mut t = Self::parse_bytes(&bytes, Some(path), options)?;
        t.path = Some(path.to_path_buf());
        Ok(t)
    }

    /// Parses CSV text; `path` is only used in error messages.
    pub fn parse(text: &str, path: Option<&Path>) -> Result<Self, IoError> {
        Self::parse_bytes(text.as_bytes(), path, &CsvOptions::default())
    }

    /// Parses CSV text with explicit [`CsvOptions`] (see [`DataTable::read_with`]); `path` is
    /// only used in error messages.
    ///
    /// ```
    /// use structid_io::{CsvOptions, DataTable};
    /// let options = CsvOptions {
    ///     columns: Some(vec!["V2".parse().unwrap(), "#0".parse().unwrap()]),
    ///     names: Some(vec!["y".into(), "u".into()]),
    ///     ..CsvOptions::default()
    /// };
    /// let t = DataTable::parse_with("\"V1\",\"V2\",\n1,2,\n3,4,\n", None, &options).unwrap();
    /// assert_eq!(t.names, ["y", "u"]);
    /// assert_eq!(t.columns, vec![vec![2.0, 4.0], vec![1.0, 3.0]]);
    /// ```
    pub fn parse_with(
        text: &str,
        path: Option<&Path>,
        options: &CsvOptions,
    ) -> Result<Self, IoError> {
        Self::parse_bytes(text.as_bytes(), path, options)
    }

    fn parse_bytes(
        bytes: &[u8],
        path: Option<&Path>,
        options: &CsvOptions,
    ) -> Result<Self, IoError> {
        let delimiter = options.delimiter;
        if matches!(delimiter, b'"' | b'\n' | b'\r' | b'#') || !delimiter.is_ascii() {
            return Err(IoError::InvalidArgument(format!(
                "invalid CSV delimiter {:?}: use an ASCII character other than a quote, `#` or a line break",
                char::from(delimiter)
            )));
        }
        let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        // Skipped lines and comment lines are blanked rather than left to the csv crate, which
        // does not count them in its line numbers.
        let is_comment = |l: &[u8]| l.trim_ascii_start().first() == Some(&b'#');
        let skip = options.skip_rows;
        let uncommented: Vec<u8>;
        let bytes = if skip > 0 || bytes.split(|&b| b == b'\n').any(is_comment) {
            let mut out = Vec::with_capacity(bytes.len());
            for (i, l) in bytes.split(|&b| b == b'\n').enumerate() {
                if i > 0 {
                    out.push(b'\n');
                }
                if i >= skip && !is_comment(l) {
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
            .delimiter(delimiter)
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
        let csv_err = |e: csv::Error| {
            let line = e.position().map(line_at);
            let msg = match e.kind() {
                csv::ErrorKind::Utf8 { .. } => "the file is not valid UTF-8 text".to_string(),
                _ => format!("malformed CSV: {e}"),
            };
            data_err(path, line, None, msg)
        };
        // Every non-blank record with its line.
        let mut rows: Vec<(u64, csv::StringRecord)> = Vec::new();
        for r in reader.records() {
            let r = r.map_err(csv_err)?;
            if !is_blank(&r) {
                rows.push((r.position().map_or(0, line_at), r));
            }
        }
        let skipped = if skip > 0 {
            format!(" after skipping the first {skip} line(s)")
        } else {
            String::new()
        };
        let (header_line, data, file_names) = if options.header {
            let Some(((line, header), data)) = rows.split_first() else {
                return Err(data_err(
                    path,
                    None,
                    None,
                    format!(
                        "the file is empty{skipped}; expected a header row with column names followed by numeric rows"
                    ),
                ));
            };
            let mut names: Vec<String> = header.iter().map(|s| s.trim().to_string()).collect();
            if names.len() > 1 && names.last().is_some_and(String::is_empty) {
                names.pop();
            }
            if names.iter().all(|n| n.parse::<f64>().is_ok()) {
                return Err(data_err(
                    path,
                    Some(*line),
                    None,
                    format!(
                        "the first row ({}) looks numeric; the file needs a header row naming the columns",
                        clip(&names.join(","))
                    ),
                ));
            }
            if data.is_empty() {
                return Err(data_err(
                    path,
                    Some(*line),
                    None,
                    "the file has a header row but no data rows",
                ));
            }
            (Some(*line), data, names)
        } else {
            let Some((_, first)) = rows.first() else {
                return Err(data_err(
                    path,
                    None,
                    None,
                    format!("the file has no data rows{skipped}"),
                ));
            };
            // A trailing delimiter on every line: the last column is empty in every row.
            let n = first.len();
            let trailing = n > 1
                && rows
                    .iter()
                    .all(|(_, r)| r.get(n - 1).is_none_or(|f| f.trim().is_empty()));
            let width = if trailing { n - 1 } else { n };
            (
                None,
                &rows[..],
                (0..width).map(|c| format!("c{c}")).collect(),
            )
        };
        let width = file_names.len();

        // The selected columns (file indices), in output order.
        let selected: Vec<usize> = match &options.columns {
            None => {
                check_names(&file_names, path, header_line)?;
                (0..width).collect()
            }
            Some(refs) => {
                if refs.is_empty() {
                    return Err(IoError::InvalidArgument(
                        "no columns selected; name at least one column".into(),
                    ));
                }
                let mut sel = Vec::with_capacity(refs.len());
                for r in refs {
                    sel.push(resolve_column(r, &file_names, path, header_line)?);
                }
                sel
            }
        };
        let names: Vec<String> = match &options.names {
            Some(given) => {
                if given.len() != selected.len() {
                    return Err(IoError::InvalidArgument(format!(
                        "{} name(s) given ({}) for {} column(s); give one name per {} column",
                        given.len(),
                        given.join(","),
                        selected.len(),
                        if options.columns.is_some() {
                            "selected"
                        } else {
                            "file"
                        }
                    )));
                }
                let names: Vec<String> = given.iter().map(|n| n.trim().to_string()).collect();
                check_names(&names, None, None).map_err(|e| match e {
                    IoError::Data { message, .. } => {
                        IoError::InvalidArgument(format!("column names: {message}"))
                    }
                    other => other,
                })?;
                names
            }
            None => {
                let names: Vec<String> = selected.iter().map(|&c| file_names[c].clone()).collect();
                if let Some(n) = (0..names.len())
                    .find(|&i| names[..i].contains(&names[i]))
                    .map(|i| &names[i])
                {
                    return Err(IoError::InvalidArgument(format!(
                        "column `{n}` is selected twice; give the copies distinct names to select a column more than once"
                    )));
                }
                names
            }
        };
        // Errors are reported in file order: by line, then by column.
        let mut order: Vec<usize> = (0..selected.len()).collect();
        order.sort_by_key(|&j| selected[j]);
        // Column names in error messages: as in the file when it has a header, otherwise as
        // named by the caller.
        let err_name = |j: usize| -> &str {
            if header_line.is_some() {
                &file_names[selected[j]]
            } else {
                &names[j]
            }
        };
        let strict_empty = options.columns.is_some();
        let mut columns: Vec<Vec<f64>> = vec![Vec::with_capacity(data.len()); selected.len()];
        let mut first_empty: Vec<Option<u64>> = vec![None; selected.len()];
        let mut lines = Vec::with_capacity(data.len());
        for (line, r) in data {
            let line = *line;
            let mut found = r.len();
            if found == width + 1 && r.get(width).is_some_and(|f| f.trim().is_empty()) {
                found = width;
            }
            if found != width {
                let expected = match header_line {
                    Some(_) => format!("as in the header ({})", clip(&file_names.join(","))),
                    None => format!("as in the first row (line {})", data[0].0),
                };
                return Err(data_err(
                    path,
                    Some(line),
                    None,
                    format!("expected {width} field(s) {expected} but found {found}"),
                ));
            }
            for &j in &order {
                let field = r.get(selected[j]).unwrap_or("").trim();
                let v = if field.is_empty() {
                    if strict_empty {
                        return Err(data_err(
                            path,
                            Some(line),
                            Some(err_name(j)),
                            "empty field; every selected column needs a value in every row",
                        ));
                    }
                    if first_empty[j].is_none() {
                        first_empty[j] = Some(line);
                    }
                    f64::NAN
                } else {
                    parse_value(field)
                        .map_err(|msg| data_err(path, Some(line), Some(err_name(j)), msg))?
                };
                columns[j].push(v);
            }
            lines.push(line);
        }
        Ok(Self {
            names,
            columns,
            lines,
            first_empty,
            header_line,
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

    /// The one-based file line of the header row (`None` for a table read without a header
    /// or built with [`DataTable::new`]).
    pub fn header_line(&self) -> Option<u64> {
        self.header_line
    }

    /// The one-based file line of data row `k`, if it exists.
    pub fn line_of_row(&self, k: usize) -> Option<u64> {
        self.lines.get(k).copied()
    }
}

/// The largest number of data rows [`DataTable::read`] and [`DataTable::read_with`] accept:
/// one million.
///
/// The bound comes from the cost of a record, not of the file: reading keeps the file and its
/// parsed rows in memory (about 200 bytes a row for two columns), and every command then
/// holds several copies of the record as signals and writes results as text (`simulate`
/// writes about 100 bytes a row), so 10⁶ rows is already on the order of a gigabyte at the
/// peak, and the quadratic-memory exact solver of `identify` stops far below it (about
/// 40 000 samples per 16 GiB). A longer file is refused before it is parsed
/// ([`IoError::TooManyRows`]) instead of exhausting the memory; `structid data csv` reads
/// with a limit set by the available memory ([`DataTable::read_with_limit`]) to cut it.
pub const MAX_ROWS: usize = 1_000_000;

/// Counts the rows a parse of the file would see (non-blank, non-comment lines after the
/// skipped ones, without the header), stopping as soon as the count exceeds `limit`: the
/// cost is bounded by `limit` lines whatever the size of the file, and the memory by the
/// buffer.
fn count_rows(
    file: impl std::io::Read,
    options: &CsvOptions,
    limit: usize,
) -> std::io::Result<usize> {
    use std::io::BufRead;
    let mut reader = std::io::BufReader::with_capacity(1 << 16, file);
    let header = usize::from(options.header);
    let stop = limit.saturating_add(header).saturating_add(1);
    let (mut line, mut counted) = (0usize, 0usize);
    // State of the current line: whether a non-blank byte was seen, and whether it was `#`.
    let (mut content, mut comment) = (false, false);
    loop {
        let buf = reader.fill_buf()?;
        if buf.is_empty() {
            break;
        }
        let n = buf.len();
        for &b in buf {
            if b == b'\n' {
                if content && !comment && line >= options.skip_rows {
                    counted += 1;
                }
                line += 1;
                (content, comment) = (false, false);
                if counted >= stop {
                    return Ok(counted - header);
                }
            } else if !content && !b.is_ascii_whitespace() && b != 0xEF && b != 0xBB && b != 0xBF {
                content = true;
                comment = b == b'#';
            }
        }
        reader.consume(n);
    }
    if content && !comment && line >= options.skip_rows {
        counted += 1;
    }
    Ok(counted.saturating_sub(header))
}

// The echo of a field in messages lives with the errors that print it.
pub use crate::error::{ECHO_CHARS, clip};

/// Parses one non-empty field as a finite number; the error is the message to report.
fn parse_value(field: &str) -> Result<f64, String> {
    let v: f64 = field
        .parse()
        .map_err(|_| format!("cannot parse `{}` as a number", clip(field)))?;
    if v.is_nan() {
        return Err("value is NaN".into());
    }
    if v.is_infinite() {
        return Err(format!("value is infinite (`{}`)", clip(field)));
    }
    Ok(v)
}

/// The file index of a selected column.
fn resolve_column(
    r: &ColumnRef,
    names: &[String],
    path: Option<&Path>,
    header_line: Option<u64>,
) -> Result<usize, IoError> {
    match r {
        ColumnRef::Index(i) => {
            if *i < names.len() {
                Ok(*i)
            } else {
                Err(data_err(
                    path,
                    None,
                    None,
                    format!(
                        "there is no column #{i}: the file has {} column(s), #0 to #{} ({}); column indices count from zero",
                        names.len(),
                        names.len().saturating_sub(1),
                        names
                            .iter()
                            .map(|n| format!("`{}`", clip(n)))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ))
            }
        }
        ColumnRef::Name(name) => {
            let mut found = names.iter().enumerate().filter(|(_, n)| *n == name);
            match (found.next(), found.next()) {
                (Some((c, _)), None) => Ok(c),
                (Some((a, _)), Some((b, _))) => Err(data_err(
                    path,
                    header_line,
                    None,
                    format!(
                        "the header names column `{}` twice (columns #{a} and #{b}); select it by index instead",
                        clip(name)
                    ),
                )),
                _ => Err(IoError::MissingColumn {
                    path: path.map(Path::to_path_buf),
                    column: name.clone(),
                    available: names.to_vec(),
                }),
            }
        }
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
                    "duplicate column name `{}` (header columns {} and {})",
                    clip(n),
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

    fn opts(columns: Option<&str>, names: Option<&str>) -> CsvOptions {
        CsvOptions {
            columns: columns.map(|c| ColumnRef::parse_list(c).unwrap()),
            names: names.map(|n| n.split(',').map(str::to_string).collect()),
            ..CsvOptions::default()
        }
    }

    #[test]
    fn options_trailing_delimiter_and_quoted_header() {
        let text = "\"V1\",\"V2\",\n0.5,0.25,\n1.5,1.25,\n\n\n";
        let t = DataTable::parse_with(text, None, &opts(Some("V2"), None)).unwrap();
        assert_eq!(t.names, ["V2"]);
        assert_eq!(t.columns, vec![vec![0.25, 1.25]]);
        assert_eq!(t.header_line(), Some(1));
        // Headerless: a last column empty in every row is a trailing delimiter and dropped …
        let no_header = CsvOptions {
            header: false,
            ..CsvOptions::default()
        };
        let t = DataTable::parse_with("1,2,\n3,4,\n", None, &no_header).unwrap();
        assert_eq!(t.names, ["c0", "c1"]);
        assert_eq!(t.header_line(), None);
        // … but kept, with its gaps, when some row has a value there.
        let t = DataTable::parse_with("1,2,\n3,4,5\n", None, &no_header).unwrap();
        assert_eq!(t.names, ["c0", "c1", "c2"]);
        assert!(t.column("c2").unwrap()[0].is_nan());
        assert_eq!(t.column("c2").unwrap()[1], 5.0);
    }

    #[test]
    fn options_select_by_name_and_index_and_rename() {
        let text = "a,b,c\n1,2,3\n4,5,6\n";
        let t = DataTable::parse_with(text, None, &opts(Some("c,#0"), None)).unwrap();
        assert_eq!(t.names, ["c", "a"]);
        assert_eq!(t.columns, vec![vec![3.0, 6.0], vec![1.0, 4.0]]);
        let t = DataTable::parse_with(text, None, &opts(Some("#1, c"), Some("u,y"))).unwrap();
        assert_eq!(t.names, ["u", "y"]);
        assert_eq!(t.columns, vec![vec![2.0, 5.0], vec![3.0, 6.0]]);
        // Renaming every column without a selection.
        let t = DataTable::parse_with(text, None, &opts(None, Some("x,y,z"))).unwrap();
        assert_eq!(t.names, ["x", "y", "z"]);
        // A column selected twice needs distinct names.
        let e = DataTable::parse_with(text, None, &opts(Some("a,a"), None)).unwrap_err();
        assert!(e.to_string().contains("selected twice"), "{e}");
        let t = DataTable::parse_with(text, None, &opts(Some("a,a"), Some("a1,a2"))).unwrap();
        assert_eq!(t.columns[0], t.columns[1]);
        // Wrong number of names, duplicate names.
        let e = DataTable::parse_with(text, None, &opts(Some("a,b"), Some("u"))).unwrap_err();
        assert!(
            e.to_string()
                .contains("1 name(s) given (u) for 2 column(s)"),
            "{e}"
        );
        let e = DataTable::parse_with(text, None, &opts(Some("a,b"), Some("u,u"))).unwrap_err();
        assert!(e.to_string().contains("duplicate column name `u`"), "{e}");
    }

    #[test]
    fn options_missing_column_is_named() {
        let text = "a,b\n1,2\n";
        let e = DataTable::parse_with(text, Some(Path::new("d.csv")), &opts(Some("a,V9"), None))
            .unwrap_err();
        assert!(matches!(&e, IoError::MissingColumn { column, .. } if column == "V9"));
        assert_eq!(
            e.to_string(),
            "data file `d.csv` has no column `V9`; available columns: `a`, `b`"
        );
        let e = DataTable::parse_with(text, None, &opts(Some("#2"), None))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no column #2") && e.contains("2 column(s), #0 to #1"),
            "{e}"
        );
        let e = DataTable::parse_with("a,b,a\n1,2,3\n", None, &opts(Some("a"), None))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 1") && e.contains("`a` twice"), "{e}");
        // The duplicate does not matter when it is not selected.
        assert!(DataTable::parse_with("a,b,a\n1,2,3\n", None, &opts(Some("b"), None)).is_ok());
    }

    #[test]
    fn options_headerless_skip_rows_and_delimiter() {
        let text = "instrument log\nstarted 12:00; 2 channels\n0.5;7\n\n0.25;8\n";
        let options = CsvOptions {
            delimiter: b';',
            header: false,
            skip_rows: 2,
            names: Some(vec!["u".into(), "y".into()]),
            ..CsvOptions::default()
        };
        let t = DataTable::parse_with(text, None, &options).unwrap();
        assert_eq!(t.names, ["u", "y"]);
        assert_eq!(t.columns, vec![vec![0.5, 0.25], vec![7.0, 8.0]]);
        assert_eq!((t.line_of_row(0), t.line_of_row(1)), (Some(3), Some(5)));
        // Tab-separated with a header after one skipped line; names by header.
        let options = CsvOptions {
            delimiter: b'\t',
            skip_rows: 1,
            ..CsvOptions::default()
        };
        let t = DataTable::parse_with("title\nu\ty\n1\t2\n", None, &options).unwrap();
        assert_eq!(t.names, ["u", "y"]);
        // Headerless columns are selected by index (or by their default names).
        let options = CsvOptions {
            header: false,
            columns: Some(vec![ColumnRef::Index(1), ColumnRef::Name("c0".into())]),
            ..CsvOptions::default()
        };
        let t = DataTable::parse_with("1,2\n3,4\n", None, &options).unwrap();
        assert_eq!(t.names, ["c1", "c0"]);
        assert_eq!(t.columns, vec![vec![2.0, 4.0], vec![1.0, 3.0]]);
        // Skipping everything, a bad delimiter.
        let options = CsvOptions {
            skip_rows: 5,
            ..CsvOptions::default()
        };
        let e = DataTable::parse_with("a\n1\n", None, &options)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("empty after skipping the first 5 line(s)"),
            "{e}"
        );
        let options = CsvOptions {
            delimiter: b'"',
            ..CsvOptions::default()
        };
        assert!(DataTable::parse_with("a\n1\n", None, &options).is_err());
        // Headerless wrong field count names the line and the first row.
        let options = CsvOptions {
            header: false,
            ..CsvOptions::default()
        };
        let e = DataTable::parse_with("1,2\n3,4\n5\n", None, &options)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 3")
                && e.contains("as in the first row (line 1)")
                && e.contains("found 1"),
            "{e}"
        );
    }

    #[test]
    fn options_malformed_number_reports_its_line() {
        let text = "title line\n# comment\nu;y;note\n1;2;ok\n\n3;x4;fine\n";
        let options = CsvOptions {
            delimiter: b';',
            skip_rows: 1,
            columns: Some(vec![
                ColumnRef::Name("u".into()),
                ColumnRef::Name("y".into()),
            ]),
            ..CsvOptions::default()
        };
        let e = DataTable::parse_with(text, Some(Path::new("m.csv")), &options)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "data file `m.csv`, line 6, column `y`: cannot parse `x4` as a number"
        );
        // Headerless: the error names the column as the caller named it.
        let options = CsvOptions {
            header: false,
            names: Some(vec!["u".into(), "y".into()]),
            ..CsvOptions::default()
        };
        let e = DataTable::parse_with("1,2\n3,NaN\n", None, &options)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "data, line 2, column `y`: value is NaN");
    }

    #[test]
    fn options_unselected_columns_may_be_empty_or_text() {
        // Like the cascaded-tanks file: Ts holds one value; `note` is text.
        let text = "\"uEst\",\"yEst\",\"Ts\",\"note\",\n3.2,5.2,4,a,\n3.1,5.3,,,\n";
        let t = DataTable::parse_with(text, None, &opts(Some("uEst,yEst"), Some("u,y"))).unwrap();
        assert_eq!(t.columns, vec![vec![3.2, 3.1], vec![5.2, 5.3]]);
        // A selected column with an empty field is an error at once, naming the line.
        let e = DataTable::parse_with(text, None, &opts(Some("Ts"), None))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 3") && e.contains("`Ts`") && e.contains("empty"),
            "{e}"
        );
        let e = DataTable::parse_with(text, None, &opts(Some("note"), None))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 2") && e.contains("cannot parse `a`"),
            "{e}"
        );
    }

    #[test]
    fn row_count_matches_the_parser_and_stops_at_the_limit() {
        let cases = [
            ("u,y\n1,2\n3,4\n", CsvOptions::default()),
            (
                "\u{feff}# c\n  u , y \n\n 1 , 2\n# more\n3,4\n\n5,6",
                CsvOptions::default(),
            ),
            (
                "title\nmore\n1;2\n\n3;4\n",
                CsvOptions {
                    delimiter: b';',
                    header: false,
                    skip_rows: 2,
                    ..CsvOptions::default()
                },
            ),
            ("u\r\n1\r\n2\r\n3\r\n", CsvOptions::default()),
        ];
        for (text, options) in &cases {
            let parsed = DataTable::parse_with(text, None, options).unwrap().len();
            let counted = count_rows(text.as_bytes(), options, usize::MAX).unwrap();
            assert_eq!(counted, parsed, "{text:?}");
            // Past the limit the count stops at limit + 1.
            assert_eq!(
                count_rows(text.as_bytes(), options, 1).unwrap(),
                2,
                "{text:?}"
            );
        }
        // The reader refuses a file over the limit before parsing it: a bad field beyond the
        // limit is never reached.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("long.csv");
        std::fs::write(&path, "u\n1\n2\n3\nnot a number\n").unwrap();
        let e = DataTable::read_with_limit(&path, &CsvOptions::default(), 3).unwrap_err();
        assert!(matches!(e, IoError::TooManyRows { limit: 3, .. }), "{e}");
        assert!(e.to_string().contains("more than 3 data rows"), "{e}");
        assert!(e.is_input_error());
        let e = DataTable::read_with_limit(&path, &CsvOptions::default(), 4).unwrap_err();
        assert!(e.to_string().contains("cannot parse `not a number`"), "{e}");
    }

    #[test]
    fn huge_fields_and_names_are_clipped_in_messages() {
        let field = "x".repeat(2 << 20);
        let e = DataTable::parse(&format!("u,y\n1,{field}\n"), None)
            .unwrap_err()
            .to_string();
        assert!(e.len() < 200, "{} bytes", e.len());
        assert!(
            e.contains(&format!("`{}… (2097152 characters)`", "x".repeat(60))),
            "{e}"
        );
        let t = DataTable::parse(&format!("u,{field}\n1,2\n"), None).unwrap();
        let e = t.select(&["y"]).unwrap_err().to_string();
        assert!(e.len() < 200 && e.contains("`u`, `xxx"), "{e}");
        // Multi-byte characters are cut at a character boundary.
        assert_eq!(
            clip(&"é".repeat(61)),
            format!("{}… (61 characters)", "é".repeat(60))
        );
    }

    #[test]
    fn column_refs_parse() {
        assert_eq!(
            ColumnRef::parse_list("V1,#3, 3").unwrap(),
            [
                ColumnRef::Name("V1".into()),
                ColumnRef::Index(3),
                ColumnRef::Name("3".into())
            ]
        );
        for bad in ["", "#", "#-1", "#+1", "# 1", "#1x", "a,,b"] {
            assert!(ColumnRef::parse_list(bad).is_err(), "{bad}");
        }
    }
}

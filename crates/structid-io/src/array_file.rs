//! Numeric arrays from MATLAB and NumPy files: MAT v5 (`.mat`, compressed or not), `.npy`
//! and `.npz`.
//!
//! Published benchmark records are mostly MAT-files; [`ArrayFile`] reads their real numeric
//! variables (double, single, integer and logical classes) as 2-D arrays of `f64`, and
//! [`Vars`] picks the signals out of them by variable name:
//!
//! * MAT v5 (`MATLAB 5.0 MAT-file` header, the format of `save -v6` and `save -v7`, of
//!   Octave's `save -mat` and of SciPy's `savemat`), with compressed variables (`-v7`) and
//!   either byte order. A v7.3 file is HDF5, which is not read: [`ArrayFileError::MatV73`]
//!   says how to save it as v7 or export it as CSV. Cell arrays, structs, objects, character
//!   and sparse arrays are listed but cannot be selected, and neither can complex arrays or
//!   arrays of more than two dimensions.
//! * NumPy `.npy`: one array of a real numeric dtype (`f8`, `f4`, integer, bool), 1-D or 2-D,
//!   either byte order, C or Fortran order; the columns of a 2-D array are `#0`, `#1`, … (or
//!   `c0`, `c1`, … as column names, as for a CSV file without header). A structured array
//!   (`dtype=[('u', '<f8'), ('y', '<f8')]`) gives one variable per field, named by the field.
//! * NumPy `.npz` (`numpy.savez` and `savez_compressed`): a zip archive of `.npy` files, one
//!   variable per member, named by the member without `.npy`.
//!
//! Vectors (`1×N` or `N×1`, NumPy shape `(N,)`) are columns of N samples; the rows of a
//! matrix are samples and its columns are channels, referred to as `name#0`, `name#1`, … .
//! The format is recognised by the file's first bytes, whatever its extension.
//!
//! A malformed file gives an [`ArrayFileError`] that says what is wrong, never a panic.
//!
//! ```
//! use structid_io::array_file::{ArrayFile, Vars};
//! // A NumPy .npy file holding a 3×2 float64 array.
//! let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
//! let header = "{'descr': '<f8', 'fortran_order': False, 'shape': (3, 2), }";
//! let header = format!("{header:<117}\n");
//! bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
//! bytes.extend_from_slice(header.as_bytes());
//! for v in [1.0f64, 10.0, 2.0, 20.0, 3.0, 30.0] {
//!     bytes.extend_from_slice(&v.to_le_bytes());
//! }
//! let file = ArrayFile::parse(&bytes).unwrap();
//! let vars: Vars = "u=#0,y=#1".parse().unwrap();
//! let (names, columns) = file.columns(Some(&vars)).unwrap();
//! assert_eq!(names, ["u", "y"]);
//! assert_eq!(columns, vec![vec![1.0, 2.0, 3.0], vec![10.0, 20.0, 30.0]]);
//! ```

use std::io::Read;

use crate::echo::clip;

/// The most bytes a compressed variable or archive member may expand to (4 GiB): a bound on
/// the memory a small malicious file can claim.
pub const MAX_EXPANDED_BYTES: u64 = 4 << 30;

/// Everything that can be wrong with a MAT-file, a `.npy` or a `.npz` file, or with the
/// variables asked of it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ArrayFileError {
    /// A MATLAB v7.3 MAT-file, which is an HDF5 file.
    #[error(
        "this is a MATLAB v7.3 MAT-file (HDF5), which structid does not read; in MATLAB save the \
         variables as version 7 with `save('file.mat', 'u', 'y', '-v7')`, or export them as CSV \
         with `writematrix([u y], 'data.csv')` (with a header row naming the columns)"
    )]
    MatV73,
    /// A file of a format that is not read (neither MAT v5, `.npy` nor `.npz`).
    #[error("{0}")]
    UnknownFormat(String),
    /// The file ends before the structure it announces.
    #[error("the file is truncated: {0}")]
    Truncated(String),
    /// The file's structure is inconsistent.
    #[error("the file is malformed: {0}")]
    Malformed(String),
    /// A compressed part cannot be expanded.
    #[error("cannot decompress {what}: {message}")]
    Decompress {
        /// Which part.
        what: String,
        /// The decompressor's message.
        message: String,
    },
    /// A variable that is not a real numeric array (a struct, a cell array, text, …).
    #[error(
        "variable `{}` is {what}; only real numeric arrays (double, single, integer or logical) \
         can be read as signals",
        clip(name)
    )]
    Unsupported {
        /// The variable.
        name: String,
        /// What it is instead.
        what: String,
    },
    /// A complex variable.
    #[error(
        "variable `{}` is complex; structid reads real signals only: save its real part \
         (`real(x)`) or its real and imaginary parts as separate variables",
        clip(name)
    )]
    Complex {
        /// The variable.
        name: String,
    },
    /// A variable of more than two dimensions.
    #[error(
        "variable `{}` has {dims} dimensions ({shape}); only vectors and 2-D matrices \
         (samples × channels) can be read",
        clip(name)
    )]
    TooManyDims {
        /// The variable.
        name: String,
        /// Its number of dimensions.
        dims: usize,
        /// Its size, as `a×b×c`.
        shape: String,
    },
    /// A variable asked for is not in the file.
    #[error(
        "the file has no variable `{}`; it holds {}",
        clip(name),
        list(available)
    )]
    MissingVariable {
        /// The variable asked for.
        name: String,
        /// The variables in the file, with their sizes.
        available: Vec<String>,
    },
    /// A column index beyond the columns of a variable.
    #[error("{}", column_message(name, *column, *columns))]
    MissingColumn {
        /// The variable (empty for the array of a `.npy` file).
        name: String,
        /// The column asked for.
        column: usize,
        /// How many columns it has.
        columns: usize,
    },
    /// A matrix was named without a column.
    #[error(
        "variable `{}` is a {rows}×{cols} matrix; name one of its columns as `{}#0` … `{}#{}` \
         (rows are samples, columns are channels)",
        clip(name), clip(name), clip(name), cols.saturating_sub(1)
    )]
    NotAVector {
        /// The variable.
        name: String,
        /// Its rows.
        rows: usize,
        /// Its columns.
        cols: usize,
    },
    /// The selected signals have different lengths.
    #[error(
        "the selected signals have different lengths: `{}` has {first_len} samples but `{}` has \
         {len}",
        clip(first),
        clip(name)
    )]
    LengthMismatch {
        /// The first signal.
        first: String,
        /// Its length.
        first_len: usize,
        /// A signal of another length.
        name: String,
        /// Its length.
        len: usize,
    },
    /// A selected signal holds NaN or an infinity.
    #[error(
        "signal `{}` has the non-finite value {value} at sample {sample} (0-based); structid \
         needs finite samples: cut or fill the gap first",
        clip(name)
    )]
    NonFinite {
        /// The signal.
        name: String,
        /// The 0-based sample.
        sample: usize,
        /// The value, as text.
        value: String,
    },
    /// A `--vars` specification is malformed.
    #[error("invalid variable selection `{}`: {message}", clip(text))]
    InvalidVars {
        /// The text given.
        text: String,
        /// What is wrong.
        message: String,
    },
}

fn list(names: &[String]) -> String {
    if names.is_empty() {
        return "no real numeric variable".into();
    }
    const SHOWN: usize = 20;
    let mut s = names
        .iter()
        .take(SHOWN)
        .map(|n| clip(n).into_owned())
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > SHOWN {
        s.push_str(&format!(" and {} more", names.len() - SHOWN));
    }
    s
}

fn column_message(name: &str, column: usize, columns: usize) -> String {
    let what = if name.is_empty() {
        "the array".to_string()
    } else {
        format!("variable `{}`", clip(name))
    };
    format!(
        "{what} has {columns} column{} (#0 … #{}), so it has no column #{column}",
        if columns == 1 { "" } else { "s" },
        columns.saturating_sub(1)
    )
}

/// A real 2-D array of samples (rows) × channels (columns), stored column by column.
#[derive(Clone, Debug, PartialEq)]
pub struct Array {
    /// Number of rows (samples).
    pub rows: usize,
    /// Number of columns (channels).
    pub cols: usize,
    /// The values, column-major: column `j` is `data[j * rows..(j + 1) * rows]`.
    pub data: Vec<f64>,
}

impl Array {
    /// Column `j` (`None` beyond the last, or when `data` is shorter than `rows × cols`).
    ///
    /// ```
    /// use structid_io::array_file::Array;
    /// let a = Array { rows: 2, cols: 2, data: vec![1.0, 2.0, 3.0, 4.0] };
    /// assert_eq!(a.column(1), Some(&[3.0, 4.0][..]));
    /// assert_eq!(a.column(2), None);
    /// ```
    pub fn column(&self, j: usize) -> Option<&[f64]> {
        let start = j.checked_mul(self.rows)?;
        (j < self.cols)
            .then(|| self.data.get(start..start.checked_add(self.rows)?))
            .flatten()
    }

    /// Whether the array is a vector (one row or one column); a vector is read as one
    /// column of samples.
    pub fn is_vector(&self) -> bool {
        self.rows == 1 || self.cols == 1
    }
}

/// One variable of a file: a real numeric array, or the reason it cannot be used.
#[derive(Clone, Debug, PartialEq)]
pub struct Variable {
    /// Its name (the MAT-file variable, the `.npz` member without `.npy`, a structured
    /// field; empty for the plain array of a `.npy` file).
    pub name: String,
    /// The array, or why it is not one that can be read.
    pub value: Result<Array, ArrayFileError>,
}

/// The format of a data file, recognised by its first bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Text (CSV).
    Csv,
    /// A MAT-file (any version; only v5 is read).
    Mat,
    /// A NumPy `.npy` file.
    Npy,
    /// A zip archive (`.npz`).
    Npz,
}

const HDF5_SIGNATURE: &[u8] = b"\x89HDF\r\n\x1a\n";

impl Format {
    /// The format of a file that starts with `head` (its first 128 bytes or more) and has
    /// the given extension (which only matters when the content is not recognised: a `.mat`,
    /// `.npy` or `.npz` file that is none of them is an error, not a CSV file).
    ///
    /// ```
    /// use structid_io::array_file::Format;
    /// assert_eq!(Format::detect(b"\x93NUMPY\x01\x00", None), Format::Npy);
    /// assert_eq!(Format::detect(b"MATLAB 5.0 MAT-file", None), Format::Mat);
    /// assert_eq!(Format::detect(b"PK\x03\x04", Some("npz")), Format::Npz);
    /// assert_eq!(Format::detect(b"u,y\n1,2\n", Some("csv")), Format::Csv);
    /// assert_eq!(Format::detect(b"", Some("MAT")), Format::Mat);
    /// ```
    pub fn detect(head: &[u8], extension: Option<&str>) -> Format {
        if head.starts_with(b"MATLAB") || head.starts_with(HDF5_SIGNATURE) {
            Format::Mat
        } else if head.starts_with(b"\x93NUMPY") {
            Format::Npy
        } else if head.starts_with(b"PK\x03\x04") || head.starts_with(b"PK\x05\x06") {
            Format::Npz
        } else {
            match extension.map(str::to_ascii_lowercase).as_deref() {
                Some("mat") => Format::Mat,
                Some("npy") => Format::Npy,
                Some("npz") => Format::Npz,
                _ => Format::Csv,
            }
        }
    }
}

/// The variables of a MAT-file, `.npy` or `.npz` file.
#[derive(Clone, Debug, PartialEq)]
pub struct ArrayFile {
    /// The variables, in file order.
    pub variables: Vec<Variable>,
}

impl ArrayFile {
    /// Parses a MAT v5, `.npy` or `.npz` file, recognised by its first bytes.
    ///
    /// ```
    /// use structid_io::array_file::{ArrayFile, ArrayFileError};
    /// let mut v73 = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: ...".to_vec();
    /// v73.resize(512, b' ');
    /// v73.extend_from_slice(b"\x89HDF\r\n\x1a\n");
    /// assert_eq!(ArrayFile::parse(&v73).unwrap_err(), ArrayFileError::MatV73);
    /// assert!(ArrayFile::parse(b"u,y\n").unwrap_err().to_string().contains("neither"));
    /// ```
    pub fn parse(bytes: &[u8]) -> Result<Self, ArrayFileError> {
        match Format::detect(bytes, None) {
            Format::Mat => Self::parse_mat(bytes),
            Format::Npy => Self::parse_npy(bytes),
            Format::Npz => Self::parse_npz(bytes),
            Format::Csv => Err(ArrayFileError::UnknownFormat(
                "the file is neither a MAT-file (MATLAB 5.0 header), a NumPy .npy file nor a \
                 .npz archive"
                    .into(),
            )),
        }
    }

    /// Parses a MAT v5 file (see the module documentation).
    pub fn parse_mat(bytes: &[u8]) -> Result<Self, ArrayFileError> {
        mat::parse(bytes).map(|variables| Self { variables })
    }

    /// Parses a NumPy `.npy` file (see the module documentation).
    pub fn parse_npy(bytes: &[u8]) -> Result<Self, ArrayFileError> {
        npy::parse(bytes, "").map(|variables| Self { variables })
    }

    /// Parses a NumPy `.npz` archive (see the module documentation).
    pub fn parse_npz(bytes: &[u8]) -> Result<Self, ArrayFileError> {
        npy::parse_npz(bytes).map(|variables| Self { variables })
    }

    /// The variables that can be read, with their sizes (`vir (1024×1)`), for messages.
    ///
    /// ```
    /// use structid_io::array_file::{Array, ArrayFile, ArrayFileError, Variable};
    /// let file = ArrayFile { variables: vec![
    ///     Variable { name: "u".into(), value: Ok(Array { rows: 2, cols: 1, data: vec![1.0, 2.0] }) },
    ///     Variable { name: "z".into(), value: Err(ArrayFileError::Complex { name: "z".into() }) },
    /// ]};
    /// assert_eq!(file.describe(), ["u (2×1)", "z (complex, not readable)"]);
    /// assert_eq!(file.get(Some("u")).unwrap().data, [1.0, 2.0]);
    /// assert!(file.get(Some("z")).is_err());
    /// assert!(file.get(None).is_err()); // two variables: name one
    /// ```
    pub fn describe(&self) -> Vec<String> {
        self.variables
            .iter()
            .map(|v| {
                let name = if v.name.is_empty() {
                    "the array"
                } else {
                    &v.name
                };
                match &v.value {
                    Ok(a) => format!("{} ({}×{})", clip(name), a.rows, a.cols),
                    Err(ArrayFileError::Unsupported { what, .. }) => {
                        format!("{} ({what}, not readable)", clip(name))
                    }
                    Err(ArrayFileError::Complex { .. }) => {
                        format!("{} (complex, not readable)", clip(name))
                    }
                    Err(_) => format!("{} (not readable)", clip(name)),
                }
            })
            .collect()
    }

    /// The array of variable `name` (`None` or an empty name: the only variable of the
    /// file, e.g. the array of a `.npy` file).
    pub fn get(&self, name: Option<&str>) -> Result<&Array, ArrayFileError> {
        let found = match name.filter(|n| !n.is_empty()) {
            Some(n) => self.variables.iter().find(|v| v.name == n),
            None if self.variables.len() == 1 => self.variables.first(),
            None => {
                return Err(ArrayFileError::InvalidVars {
                    text: "#N".into(),
                    message: format!(
                        "a column without a variable name (`#N`) needs a file with one array; \
                         this one holds {}: write `name#N`",
                        list(&self.describe())
                    ),
                });
            }
        };
        match found {
            Some(v) => v.value.as_ref().map_err(Clone::clone),
            None => Err(ArrayFileError::MissingVariable {
                name: name.unwrap_or_default().to_string(),
                available: self.describe(),
            }),
        }
    }

    /// The signals selected by `vars` as named columns of equal length, or, without `vars`,
    /// every readable variable: a vector as one column named by the variable, a matrix as
    /// columns `name#0`, `name#1`, … (`c0`, `c1`, … for the unnamed array of a `.npy` file).
    ///
    /// Every value must be finite and all columns of the same length.
    ///
    /// ```
    /// use structid_io::array_file::{Array, ArrayFile, Variable, Vars};
    /// let file = ArrayFile { variables: vec![
    ///     Variable { name: "vir".into(), value: Ok(Array { rows: 1, cols: 3, data: vec![1.0, 2.0, 3.0] }) },
    ///     Variable { name: "qm".into(), value: Ok(Array { rows: 3, cols: 1, data: vec![4.0, 5.0, 6.0] }) },
    /// ]};
    /// let (names, cols) = file.columns(Some(&"u=vir,y=qm".parse::<Vars>().unwrap())).unwrap();
    /// assert_eq!(names, ["u", "y"]);
    /// assert_eq!(cols[0], [1.0, 2.0, 3.0]);
    /// let (names, _) = file.columns(None).unwrap();
    /// assert_eq!(names, ["vir", "qm"]);
    /// let e = file.columns(Some(&"u=v".parse::<Vars>().unwrap())).unwrap_err();
    /// assert_eq!(e.to_string(), "the file has no variable `v`; it holds vir (1×3), qm (3×1)");
    /// ```
    pub fn columns(
        &self,
        vars: Option<&Vars>,
    ) -> Result<(Vec<String>, Vec<Vec<f64>>), ArrayFileError> {
        let mut names = Vec::new();
        let mut columns: Vec<Vec<f64>> = Vec::new();
        match vars {
            Some(vars) => {
                for (target, r) in &vars.0 {
                    let a = self.get(r.variable.as_deref())?;
                    let var = r.variable.clone().unwrap_or_default();
                    let col = match r.column {
                        Some(j) => a.column(j).ok_or(ArrayFileError::MissingColumn {
                            name: var,
                            column: j,
                            columns: a.cols,
                        })?,
                        None if a.is_vector() => &a.data[..],
                        None => {
                            return Err(ArrayFileError::NotAVector {
                                name: if var.is_empty() {
                                    "the array".into()
                                } else {
                                    var
                                },
                                rows: a.rows,
                                cols: a.cols,
                            });
                        }
                    };
                    names.push(target.clone());
                    columns.push(col.to_vec());
                }
            }
            None => {
                for v in &self.variables {
                    let Ok(a) = &v.value else { continue };
                    if a.is_vector() {
                        names.push(if v.name.is_empty() {
                            "c0".to_string()
                        } else {
                            v.name.clone()
                        });
                        columns.push(a.data.clone());
                        continue;
                    }
                    for j in 0..a.cols {
                        names.push(match (v.name.is_empty(), a.cols) {
                            (true, _) => format!("c{j}"),
                            (false, 1) => v.name.clone(),
                            (false, _) => format!("{}#{j}", v.name),
                        });
                        columns.push(a.column(j).unwrap_or_default().to_vec());
                    }
                }
                if columns.is_empty() {
                    return Err(ArrayFileError::Malformed(format!(
                        "the file holds no real numeric array (it holds {})",
                        list(&self.describe())
                    )));
                }
            }
        }
        for (name, c) in names.iter().zip(&columns) {
            if c.len() != columns[0].len() {
                return Err(ArrayFileError::LengthMismatch {
                    first: names[0].clone(),
                    first_len: columns[0].len(),
                    name: name.clone(),
                    len: c.len(),
                });
            }
            if let Some(k) = c.iter().position(|v| !v.is_finite()) {
                return Err(ArrayFileError::NonFinite {
                    name: name.clone(),
                    sample: k,
                    value: c[k].to_string(),
                });
            }
        }
        Ok((names, columns))
    }
}

/// A reference to a signal in a file: a variable, a column of a variable, or a column.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct VarRef {
    /// The variable (a column name in a CSV file); `None` for `#N` alone.
    pub variable: Option<String>,
    /// The zero-based column (`#N`); `None` for a whole vector.
    pub column: Option<usize>,
}

impl std::fmt::Display for VarRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(v) = &self.variable {
            f.write_str(v)?;
        }
        if let Some(j) = self.column {
            write!(f, "#{j}")?;
        }
        Ok(())
    }
}

/// Which signals to read from a data file and under which names: `u=vir,y=qm` (the `--vars`
/// option of the command-line tool).
///
/// Each comma-separated item is `NAME=REF` or just `REF` (kept under its own name), where
/// `REF` is a variable (`vir`), a column of a matrix variable (`data#1`, zero-based), or a
/// column of a file with a single array (`#1`, e.g. a `.npy` file or a CSV column by
/// position). In a CSV file a variable is a column of the header. The names are those the
/// model file's `[signals]` use.
///
/// ```
/// use structid_io::array_file::{VarRef, Vars};
/// let v: Vars = "u = vir, y=data#1, #0".parse().unwrap();
/// assert_eq!(v.names().collect::<Vec<_>>(), ["u", "y", "#0"]);
/// assert_eq!(v.refs().nth(1), Some(&VarRef { variable: Some("data".into()), column: Some(1) }));
/// assert!("u=vir,u=qm".parse::<Vars>().unwrap_err().to_string().contains("twice"));
/// assert!("u=".parse::<Vars>().is_err());
/// assert!("u=x#a".parse::<Vars>().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Vars(pub Vec<(String, VarRef)>);

impl Vars {
    /// The names the signals are given, in order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.0.iter().map(|(n, _)| n.as_str())
    }

    /// What each signal is read from, in order.
    pub fn refs(&self) -> impl Iterator<Item = &VarRef> {
        self.0.iter().map(|(_, r)| r)
    }
}

impl std::str::FromStr for Vars {
    type Err = ArrayFileError;

    fn from_str(text: &str) -> Result<Self, ArrayFileError> {
        let bad = |message: String| ArrayFileError::InvalidVars {
            text: text.to_string(),
            message,
        };
        let mut out: Vec<(String, VarRef)> = Vec::new();
        for item in text.split(',') {
            let item = item.trim();
            if item.is_empty() {
                return Err(bad(
                    "an empty item; write NAME=VARIABLE items separated by commas, e.g. u=vir,y=qm"
                        .into(),
                ));
            }
            let (name, r) = match item.split_once('=') {
                Some((n, r)) => (n.trim(), r.trim()),
                None => (item, item),
            };
            if name.is_empty() || r.is_empty() {
                return Err(bad(format!(
                    "`{}` needs a name and a variable on both sides of `=`, e.g. u=vir",
                    clip(item)
                )));
            }
            let (variable, column) = match r.rsplit_once('#') {
                Some((v, digits)) => {
                    let j = digits
                        .parse::<usize>()
                        .ok()
                        .filter(|_| digits.bytes().all(|b| b.is_ascii_digit()))
                        .ok_or_else(|| {
                            bad(format!(
                                "in `{}`, `#` must be followed by a zero-based column index such as `#0`",
                                clip(item)
                            ))
                        })?;
                    ((!v.is_empty()).then(|| v.to_string()), Some(j))
                }
                None => (Some(r.to_string()), None),
            };
            if out.iter().any(|(n, _)| n == name) {
                return Err(bad(format!("the name `{}` is given twice", clip(name))));
            }
            out.push((name.to_string(), VarRef { variable, column }));
        }
        Ok(Vars(out))
    }
}

impl std::fmt::Display for Vars {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, (n, r)) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(",")?;
            }
            write!(f, "{n}={r}")?;
        }
        Ok(())
    }
}

/// Expands a zlib stream, refusing more than [`MAX_EXPANDED_BYTES`].
fn inflate(data: &[u8], what: &dyn Fn() -> String) -> Result<Vec<u8>, ArrayFileError> {
    let mut out = Vec::new();
    flate2::read::ZlibDecoder::new(data)
        .take(MAX_EXPANDED_BYTES + 1)
        .read_to_end(&mut out)
        .map_err(|e| ArrayFileError::Decompress {
            what: what(),
            message: e.to_string(),
        })?;
    if out.len() as u64 > MAX_EXPANDED_BYTES {
        return Err(ArrayFileError::Decompress {
            what: what(),
            message: format!("it expands to more than {} GiB", MAX_EXPANDED_BYTES >> 30),
        });
    }
    Ok(out)
}

/// Converts `count` numbers of the given element type from `bytes` to `f64`; `None` when
/// `bytes` is too short or the type is not numeric.
fn numbers(bytes: &[u8], kind: Num, big_endian: bool, count: usize) -> Option<Vec<f64>> {
    let size = kind.size();
    if bytes.len() / size < count {
        return None;
    }
    let mut out = Vec::with_capacity(count);
    for c in bytes.chunks_exact(size).take(count) {
        let mut b = [0u8; 8];
        b[..size].copy_from_slice(c);
        if big_endian {
            b[..size].reverse();
        }
        out.push(match kind {
            Num::I8 => b[0] as i8 as f64,
            Num::U8 => b[0] as f64,
            Num::Bool => (b[0] != 0) as u8 as f64,
            Num::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Num::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Num::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Num::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Num::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Num::I64 => i64::from_le_bytes(b) as f64,
            Num::U64 => u64::from_le_bytes(b) as f64,
            Num::F64 => f64::from_le_bytes(b),
        });
    }
    Some(out)
}

/// Numeric element types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Num {
    I8,
    U8,
    Bool,
    I16,
    U16,
    I32,
    U32,
    F32,
    I64,
    U64,
    F64,
}

impl Num {
    fn size(self) -> usize {
        match self {
            Num::I8 | Num::U8 | Num::Bool => 1,
            Num::I16 | Num::U16 => 2,
            Num::I32 | Num::U32 | Num::F32 => 4,
            Num::I64 | Num::U64 | Num::F64 => 8,
        }
    }
}

fn shape_text(dims: &[usize]) -> String {
    dims.iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join("×")
}

/// The 2-D size of `dims` (trailing singleton dimensions dropped), or the error for more.
fn two_d(name: &str, dims: &[usize]) -> Result<(usize, usize), ArrayFileError> {
    let mut d: Vec<usize> = dims.to_vec();
    while d.len() > 2 && d.last() == Some(&1) {
        d.pop();
    }
    match d.as_slice() {
        [] => Ok((1, 1)),
        [n] => Ok((*n, 1)),
        [r, c] => Ok((*r, *c)),
        _ => Err(ArrayFileError::TooManyDims {
            name: name.to_string(),
            dims: d.len(),
            shape: shape_text(dims),
        }),
    }
}

mod mat;

mod npy;

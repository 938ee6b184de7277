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

mod mat {
    //! MAT v5: a 128-byte header, then data elements (tag: type and byte count, then data,
    //! padded to 8 bytes; "small" elements of at most 4 bytes packed in the tag).

    use super::*;

    const MI_INT8: u32 = 1;
    const MI_UINT8: u32 = 2;
    const MI_INT16: u32 = 3;
    const MI_UINT16: u32 = 4;
    const MI_INT32: u32 = 5;
    const MI_UINT32: u32 = 6;
    const MI_SINGLE: u32 = 7;
    const MI_DOUBLE: u32 = 9;
    const MI_INT64: u32 = 12;
    const MI_UINT64: u32 = 13;
    const MI_MATRIX: u32 = 14;
    const MI_COMPRESSED: u32 = 15;
    const MI_UTF8: u32 = 16;

    fn num_of(data_type: u32) -> Option<Num> {
        Some(match data_type {
            MI_INT8 => Num::I8,
            MI_UINT8 => Num::U8,
            MI_INT16 => Num::I16,
            MI_UINT16 => Num::U16,
            MI_INT32 => Num::I32,
            MI_UINT32 => Num::U32,
            MI_SINGLE => Num::F32,
            MI_DOUBLE => Num::F64,
            MI_INT64 => Num::I64,
            MI_UINT64 => Num::U64,
            _ => return None,
        })
    }

    fn class_name(class: u32) -> &'static str {
        match class {
            1 => "a cell array",
            2 => "a struct",
            3 => "an object",
            4 => "a character array (text)",
            5 => "a sparse matrix (convert it with `full(x)` first)",
            16 => "a function handle",
            17 => "a MATLAB object (e.g. a string, table or timeseries)",
            _ => "of an unknown class",
        }
    }

    struct Reader<'a> {
        buf: &'a [u8],
        pos: usize,
        big_endian: bool,
    }

    /// One data element.
    struct Element<'a> {
        data_type: u32,
        data: &'a [u8],
        /// Offset of its tag in the buffer.
        at: usize,
    }

    impl<'a> Reader<'a> {
        fn u32_at(&self, at: usize) -> Option<u32> {
            let b: [u8; 4] = self.buf.get(at..at + 4)?.try_into().ok()?;
            Some(if self.big_endian {
                u32::from_be_bytes(b)
            } else {
                u32::from_le_bytes(b)
            })
        }

        fn done(&self) -> bool {
            self.pos >= self.buf.len()
        }

        /// The next element; `what` names it in errors. Compressed elements are not padded.
        fn element(&mut self, what: &str) -> Result<Element<'a>, ArrayFileError> {
            let at = self.pos;
            let first = self.u32_at(at).ok_or_else(|| {
                ArrayFileError::Truncated(format!("{what} at byte {at} has no complete tag"))
            })?;
            if first >> 16 != 0 {
                // Small element: type in the low half, byte count in the high half.
                let n = (first >> 16) as usize;
                let data = self.buf.get(at + 4..at + 8).ok_or_else(|| {
                    ArrayFileError::Truncated(format!("{what} at byte {at} has no complete tag"))
                })?;
                if n > 4 {
                    return Err(ArrayFileError::Malformed(format!(
                        "{what} at byte {at}: a small element of {n} bytes (at most 4)"
                    )));
                }
                self.pos = at + 8;
                return Ok(Element {
                    data_type: first & 0xffff,
                    data: &data[..n],
                    at,
                });
            }
            let n = self.u32_at(at + 4).ok_or_else(|| {
                ArrayFileError::Truncated(format!("{what} at byte {at} has no complete tag"))
            })? as usize;
            let start = at + 8;
            let end = start.checked_add(n).filter(|&e| e <= self.buf.len());
            let Some(end) = end else {
                return Err(ArrayFileError::Truncated(format!(
                    "{what} at byte {at} announces {n} bytes but only {} follow",
                    self.buf.len().saturating_sub(start)
                )));
            };
            let padded = if first == MI_COMPRESSED {
                end
            } else {
                end.div_ceil(8) * 8
            };
            self.pos = padded.min(self.buf.len());
            Ok(Element {
                data_type: first,
                data: &self.buf[start..end],
                at,
            })
        }
    }

    pub(super) fn parse(bytes: &[u8]) -> Result<Vec<Variable>, ArrayFileError> {
        if bytes.starts_with(b"MATLAB 7.3")
            || bytes.starts_with(HDF5_SIGNATURE)
            || bytes.get(512..520) == Some(HDF5_SIGNATURE)
        {
            return Err(ArrayFileError::MatV73);
        }
        if !bytes.starts_with(b"MATLAB 5.0 MAT-file") {
            return Err(ArrayFileError::UnknownFormat(
                "not a MAT-file of version 5 to 7: it does not start with the text \
                 `MATLAB 5.0 MAT-file` (MATLAB v4 files are not read; save the variables with \
                 `save('file.mat', 'u', 'y', '-v7')` or export them as CSV)"
                    .into(),
            ));
        }
        if bytes.len() < 128 {
            return Err(ArrayFileError::Truncated(format!(
                "the MAT-file header has 128 bytes but the file has {}",
                bytes.len()
            )));
        }
        let big_endian = match &bytes[126..128] {
            b"IM" => false,
            b"MI" => true,
            other => {
                return Err(ArrayFileError::Malformed(format!(
                    "the MAT-file header's byte-order mark is {other:?}, neither `IM` nor `MI`"
                )));
            }
        };
        let mut out = Vec::new();
        elements(&bytes[128..], big_endian, true, 128, &mut out)?;
        Ok(out)
    }

    /// Reads the variables of a sequence of top-level elements; `offset` is the position of
    /// `buf` in the file (for messages).
    fn elements(
        buf: &[u8],
        big_endian: bool,
        allow_compressed: bool,
        offset: usize,
        out: &mut Vec<Variable>,
    ) -> Result<(), ArrayFileError> {
        let mut r = Reader {
            buf,
            pos: 0,
            big_endian,
        };
        while !r.done() {
            // Trailing zero padding after the last element.
            if r.buf[r.pos..].iter().all(|&b| b == 0) {
                break;
            }
            let e = r.element("a variable")?;
            let at = offset + e.at;
            match e.data_type {
                MI_MATRIX => {
                    if let Some(v) = matrix(e.data, big_endian, at)? {
                        out.push(v);
                    }
                }
                MI_COMPRESSED if allow_compressed => {
                    let inner =
                        inflate(e.data, &|| format!("the compressed variable at byte {at}"))?;
                    elements(&inner, big_endian, false, at, out).map_err(|err| match err {
                        ArrayFileError::Truncated(m) | ArrayFileError::Malformed(m) => {
                            ArrayFileError::Malformed(format!(
                                "in the compressed variable at byte {at}: {m}"
                            ))
                        }
                        other => other,
                    })?;
                }
                t => {
                    return Err(ArrayFileError::Malformed(format!(
                        "the element at byte {at} has data type {t}, not a variable (miMATRIX \
                         or miCOMPRESSED)"
                    )));
                }
            }
        }
        Ok(())
    }

    /// One miMATRIX element: `None` for an empty one.
    fn matrix(
        data: &[u8],
        big_endian: bool,
        at: usize,
    ) -> Result<Option<Variable>, ArrayFileError> {
        if data.is_empty() {
            return Ok(None);
        }
        let mut r = Reader {
            buf: data,
            pos: 0,
            big_endian,
        };
        let malformed =
            |m: String| ArrayFileError::Malformed(format!("the variable at byte {at}: {m}"));
        let flags = r.element("the array flags")?;
        if flags.data_type != MI_UINT32 || flags.data.len() < 8 {
            return Err(malformed(format!(
                "its array flags have type {} and {} bytes (expected miUINT32, 8 bytes)",
                flags.data_type,
                flags.data.len()
            )));
        }
        let word = |b: &[u8]| -> u32 {
            let b: [u8; 4] = [b[0], b[1], b[2], b[3]];
            if big_endian {
                u32::from_be_bytes(b)
            } else {
                u32::from_le_bytes(b)
            }
        };
        let f = word(&flags.data[..4]);
        let class = f & 0xff;
        let complex = f & 0x0800 != 0;
        let logical = f & 0x0200 != 0;
        let name_of = |e: &Element| -> Result<String, ArrayFileError> {
            if e.data_type != MI_INT8 && e.data_type != MI_UINT8 && e.data_type != MI_UTF8 {
                return Err(malformed(format!(
                    "its name has data type {} (expected miINT8)",
                    e.data_type
                )));
            }
            Ok(String::from_utf8_lossy(e.data).into_owned())
        };
        if class == 17 {
            // Objects (mxOPAQUE): the name follows the flags directly.
            let name = name_of(&r.element("the variable name")?)?;
            return Ok(Some(Variable {
                value: Err(ArrayFileError::Unsupported {
                    name: name.clone(),
                    what: class_name(17).into(),
                }),
                name,
            }));
        }
        let dims_el = r.element("the dimensions")?;
        if dims_el.data_type != MI_INT32 || dims_el.data.len() % 4 != 0 {
            return Err(malformed(format!(
                "its dimensions have type {} and {} bytes (expected miINT32)",
                dims_el.data_type,
                dims_el.data.len()
            )));
        }
        let dims: Vec<usize> = dims_el
            .data
            .chunks_exact(4)
            .map(|c| word(c) as i32)
            .map(|d| usize::try_from(d).unwrap_or(usize::MAX))
            .collect();
        if dims.len() < 2 || dims.contains(&usize::MAX) {
            return Err(malformed(format!(
                "invalid dimensions {:?}",
                dims_el
                    .data
                    .chunks_exact(4)
                    .map(|c| word(c) as i32)
                    .collect::<Vec<_>>()
            )));
        }
        let name = name_of(&r.element("the variable name")?)?;
        let unsupported = |what: &str| {
            Ok(Some(Variable {
                name: name.clone(),
                value: Err(ArrayFileError::Unsupported {
                    name: name.clone(),
                    what: what.to_string(),
                }),
            }))
        };
        if !(6..=15).contains(&class) {
            return unsupported(class_name(class));
        }
        if complex {
            return Ok(Some(Variable {
                name: name.clone(),
                value: Err(ArrayFileError::Complex { name }),
            }));
        }
        let (rows, cols) = match two_d(&name, &dims) {
            Ok(rc) => rc,
            Err(e) => {
                return Ok(Some(Variable {
                    name,
                    value: Err(e),
                }));
            }
        };
        let count = dims
            .iter()
            .try_fold(1usize, |p, &d| p.checked_mul(d))
            .filter(|&c| c <= data.len())
            .ok_or_else(|| {
                malformed(format!(
                    "`{}` of size {} holds more values than the file has bytes",
                    clip(&name),
                    shape_text(&dims)
                ))
            })?;
        let real = r.element("the real part")?;
        let kind = num_of(real.data_type).ok_or_else(|| {
            malformed(format!(
                "`{}`: its values have data type {}, not a numeric type",
                clip(&name),
                real.data_type
            ))
        })?;
        let kind = if logical && kind == Num::U8 {
            Num::Bool
        } else {
            kind
        };
        let values = numbers(real.data, kind, big_endian, count).ok_or_else(|| {
            malformed(format!(
                "`{}` of size {} needs {count} values but its data hold {} bytes of {}-byte values",
                clip(&name),
                shape_text(&dims),
                real.data.len(),
                kind.size()
            ))
        })?;
        Ok(Some(Variable {
            name,
            value: Ok(Array {
                rows,
                cols,
                data: values,
            }),
        }))
    }
}

mod npy {
    //! NumPy `.npy`: magic, version, a Python-literal header dict (descr, fortran_order,
    //! shape), then the raw data; `.npz`: a zip archive of them.

    use super::*;

    /// A Python literal of the header.
    #[derive(Clone, Debug, PartialEq)]
    enum Lit {
        Str(String),
        Int(u64),
        Bool(bool),
        None,
        Seq(Vec<Lit>),
        Dict(Vec<(Lit, Lit)>),
    }

    struct Parser<'a> {
        s: &'a [u8],
        pos: usize,
    }

    const MAX_DEPTH: usize = 16;

    impl Parser<'_> {
        fn skip_ws(&mut self) {
            while self.pos < self.s.len() && self.s[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
        }

        fn peek(&mut self) -> Option<u8> {
            self.skip_ws();
            self.s.get(self.pos).copied()
        }

        fn err(&self, m: &str) -> String {
            format!("{m} at character {} of the header", self.pos)
        }

        fn value(&mut self, depth: usize) -> Result<Lit, String> {
            if depth > MAX_DEPTH {
                return Err(self.err("nesting too deep"));
            }
            match self.peek() {
                Some(q @ (b'\'' | b'"')) => {
                    self.pos += 1;
                    let start = self.pos;
                    while self.pos < self.s.len() && self.s[self.pos] != q {
                        self.pos += 1;
                    }
                    if self.pos >= self.s.len() {
                        return Err(self.err("unterminated string"));
                    }
                    let text = String::from_utf8_lossy(&self.s[start..self.pos]).into_owned();
                    self.pos += 1;
                    Ok(Lit::Str(text))
                }
                Some(open @ (b'(' | b'[' | b'{')) => {
                    self.pos += 1;
                    let close = match open {
                        b'(' => b')',
                        b'[' => b']',
                        _ => b'}',
                    };
                    let mut items = Vec::new();
                    let mut pairs = Vec::new();
                    loop {
                        if self.peek() == Some(close) {
                            self.pos += 1;
                            break;
                        }
                        let v = self.value(depth + 1)?;
                        if open == b'{' {
                            if self.peek() != Some(b':') {
                                return Err(self.err("expected `:`"));
                            }
                            self.pos += 1;
                            let w = self.value(depth + 1)?;
                            pairs.push((v, w));
                        } else {
                            items.push(v);
                        }
                        match self.peek() {
                            Some(b',') => self.pos += 1,
                            Some(c) if c == close => {}
                            _ => return Err(self.err("expected `,` or a closing bracket")),
                        }
                    }
                    Ok(if open == b'{' {
                        Lit::Dict(pairs)
                    } else {
                        Lit::Seq(items)
                    })
                }
                Some(c) if c.is_ascii_alphanumeric() || c == b'-' => {
                    let start = self.pos;
                    while self.pos < self.s.len()
                        && (self.s[self.pos].is_ascii_alphanumeric() || self.s[self.pos] == b'-')
                    {
                        self.pos += 1;
                    }
                    let word = std::str::from_utf8(&self.s[start..self.pos]).unwrap_or("");
                    match word {
                        "True" => Ok(Lit::Bool(true)),
                        "False" => Ok(Lit::Bool(false)),
                        "None" => Ok(Lit::None),
                        w => w
                            .trim_end_matches('L')
                            .parse::<u64>()
                            .map(Lit::Int)
                            .map_err(|_| self.err(&format!("unexpected `{}`", clip(w)))),
                    }
                }
                Some(_) => Err(self.err("unexpected character")),
                None => Err(self.err("unexpected end")),
            }
        }
    }

    /// A simple dtype: `None` for the reason it is not readable.
    fn dtype(descr: &str) -> Result<(Num, bool), String> {
        let (order, rest) = match descr.as_bytes().first() {
            Some(b'<' | b'|' | b'=') => (false, &descr[1..]),
            Some(b'>') => (true, &descr[1..]),
            _ => (false, descr),
        };
        let kind = match rest {
            "f8" | "d" => Num::F64,
            "f4" | "f" => Num::F32,
            "i1" | "b" => Num::I8,
            "u1" | "B" => Num::U8,
            "b1" | "?" => Num::Bool,
            "i2" | "h" => Num::I16,
            "u2" | "H" => Num::U16,
            "i4" | "i" => Num::I32,
            "u4" | "I" => Num::U32,
            "i8" | "q" => Num::I64,
            "u8" | "Q" => Num::U64,
            _ => return Err(rest.to_string()),
        };
        Ok((kind, order))
    }

    fn size_of(descr: &str) -> Option<usize> {
        let digits: String = descr
            .chars()
            .skip_while(|c| !c.is_ascii_digit())
            .take_while(char::is_ascii_digit)
            .collect();
        digits.parse().ok()
    }

    /// What an unreadable dtype holds: `complex`, `text`, … .
    fn what_dtype(descr: &str) -> String {
        let rest = descr.trim_start_matches(['<', '>', '|', '=']);
        match rest.chars().next() {
            Some('c') => "complex".into(),
            Some('O') => "Python objects (pickled; not read for safety)".into(),
            Some('U' | 'S' | 'a') => "text".into(),
            Some('M' | 'm') => "dates or time deltas".into(),
            _ => format!("dtype `{}`", clip(descr)),
        }
    }

    pub(super) fn parse(bytes: &[u8], name: &str) -> Result<Vec<Variable>, ArrayFileError> {
        let what = if name.is_empty() {
            String::new()
        } else {
            format!("member `{}`: ", clip(name))
        };
        let malformed = |m: String| ArrayFileError::Malformed(format!("{what}{m}"));
        let truncated = |m: String| ArrayFileError::Truncated(format!("{what}{m}"));
        if !bytes.starts_with(b"\x93NUMPY") {
            return Err(malformed(
                "not a NumPy .npy array (no `\\x93NUMPY` magic)".into(),
            ));
        }
        let major = *bytes
            .get(6)
            .ok_or_else(|| truncated("the .npy header is incomplete".into()))?;
        let (len, start) = match major {
            1 => (
                bytes
                    .get(8..10)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]) as usize),
                10,
            ),
            2 | 3 => (
                bytes
                    .get(8..12)
                    .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize),
                12,
            ),
            v => {
                return Err(malformed(format!(
                    ".npy format version {v} is not known (1 to 3 are)"
                )));
            }
        };
        let len = len.ok_or_else(|| truncated("the .npy header is incomplete".into()))?;
        let header = bytes.get(start..start + len).ok_or_else(|| {
            truncated(format!(
                "the .npy header announces {len} bytes but only {} follow",
                bytes.len().saturating_sub(start)
            ))
        })?;
        let data = &bytes[start + len..];
        let mut p = Parser { s: header, pos: 0 };
        let dict = match p
            .value(0)
            .map_err(|m| malformed(format!("bad .npy header: {m}")))?
        {
            Lit::Dict(d) => d,
            _ => return Err(malformed("the .npy header is not a dictionary".into())),
        };
        let key = |k: &str| {
            dict.iter()
                .find(|(n, _)| *n == Lit::Str(k.into()))
                .map(|(_, v)| v)
                .ok_or_else(|| malformed(format!("the .npy header has no `{k}`")))
        };
        let fortran = match key("fortran_order")? {
            Lit::Bool(b) => *b,
            _ => return Err(malformed("`fortran_order` is not True or False".into())),
        };
        let shape: Vec<usize> = match key("shape")? {
            Lit::Seq(items) => items
                .iter()
                .map(|i| match i {
                    Lit::Int(n) => usize::try_from(*n).ok(),
                    _ => None,
                })
                .collect::<Option<_>>()
                .ok_or_else(|| malformed("`shape` is not a tuple of sizes".into()))?,
            _ => return Err(malformed("`shape` is not a tuple".into())),
        };
        let count = shape
            .iter()
            .try_fold(1usize, |p, &d| p.checked_mul(d))
            .ok_or_else(|| malformed(format!("the shape {shape:?} overflows")))?;
        let var = |value| Variable {
            name: name.to_string(),
            value,
        };
        match key("descr")? {
            Lit::Str(descr) => {
                let (kind, big_endian) = match dtype(descr) {
                    Ok(k) => k,
                    Err(_) => {
                        let what = what_dtype(descr);
                        let e = if what == "complex" {
                            ArrayFileError::Complex {
                                name: name.to_string(),
                            }
                        } else {
                            ArrayFileError::Unsupported {
                                name: if name.is_empty() {
                                    "the array".into()
                                } else {
                                    name.into()
                                },
                                what: format!("an array of {what}"),
                            }
                        };
                        return Ok(vec![var(Err(e))]);
                    }
                };
                let (rows, cols) = match two_d(name, &shape) {
                    Ok(rc) => rc,
                    Err(e) => return Ok(vec![var(Err(e))]),
                };
                if count
                    .checked_mul(kind.size())
                    .is_none_or(|n| n > data.len())
                {
                    return Err(truncated(format!(
                        "the array of shape {shape:?} needs {count} values of {} bytes but {} \
                         bytes of data follow the header",
                        kind.size(),
                        data.len()
                    )));
                }
                let values = numbers(data, kind, big_endian, count).unwrap_or_default();
                let data = if fortran || cols == 1 {
                    values
                } else {
                    let mut t = vec![0.0; count];
                    for i in 0..rows {
                        for j in 0..cols {
                            t[j * rows + i] = values[i * cols + j];
                        }
                    }
                    t
                };
                Ok(vec![var(Ok(Array { rows, cols, data }))])
            }
            Lit::Seq(fields) => {
                structured(fields, &shape, count, data, name, &malformed, &truncated)
            }
            _ => Err(malformed(
                "`descr` is neither a dtype nor a list of fields".into(),
            )),
        }
    }

    /// A structured array: one variable per numeric field.
    fn structured(
        fields: &[Lit],
        shape: &[usize],
        count: usize,
        data: &[u8],
        file: &str,
        malformed: &dyn Fn(String) -> ArrayFileError,
        truncated: &dyn Fn(String) -> ArrayFileError,
    ) -> Result<Vec<Variable>, ArrayFileError> {
        // (name, offset, dtype text, subarray shape given)
        let mut layout = Vec::new();
        let mut offset = 0usize;
        for f in fields {
            let Lit::Seq(parts) = f else {
                return Err(malformed("a field of `descr` is not a tuple".into()));
            };
            let (Some(Lit::Str(n)), Some(d)) = (parts.first(), parts.get(1)) else {
                return Err(malformed("a field of `descr` is not (name, dtype)".into()));
            };
            let Lit::Str(d) = d else {
                // A nested structure.
                return Err(malformed(format!(
                    "field `{}` is a nested structure, which is not read",
                    clip(n)
                )));
            };
            let size = size_of(d)
                .ok_or_else(|| malformed(format!("field `{}` has dtype `{}`", clip(n), clip(d))))?;
            let sub = parts.len() > 2;
            layout.push((n.clone(), offset, d.clone(), sub));
            offset = offset
                .checked_add(size)
                .ok_or_else(|| malformed("the record size overflows".into()))?;
        }
        let record = offset;
        let rows = match shape {
            [] => 1,
            [n] => *n,
            _ => {
                return Err(ArrayFileError::TooManyDims {
                    name: if file.is_empty() {
                        "the array".into()
                    } else {
                        file.into()
                    },
                    dims: shape.len(),
                    shape: shape_text(shape),
                });
            }
        };
        if count.checked_mul(record).is_none_or(|n| n > data.len()) {
            return Err(truncated(format!(
                "{count} records of {record} bytes need more than the {} bytes of data",
                data.len()
            )));
        }
        let mut out = Vec::new();
        for (n, at, d, sub) in layout {
            if n.is_empty() {
                continue; // padding
            }
            let value = match dtype(&d) {
                _ if sub => Err(ArrayFileError::Unsupported {
                    name: n.clone(),
                    what: "a field with a sub-array shape".into(),
                }),
                Ok((kind, be)) => {
                    let mut v = Vec::with_capacity(rows);
                    for k in 0..rows {
                        let s = k * record + at;
                        let x = data
                            .get(s..s + kind.size())
                            .and_then(|b| numbers(b, kind, be, 1))
                            .and_then(|x| x.first().copied())
                            .ok_or_else(|| truncated("a record is incomplete".into()))?;
                        v.push(x);
                    }
                    Ok(Array {
                        rows,
                        cols: 1,
                        data: v,
                    })
                }
                Err(_) if what_dtype(&d) == "complex" => {
                    Err(ArrayFileError::Complex { name: n.clone() })
                }
                Err(_) => Err(ArrayFileError::Unsupported {
                    name: n.clone(),
                    what: format!("a field of {}", what_dtype(&d)),
                }),
            };
            out.push(Variable { name: n, value });
        }
        Ok(out)
    }

    pub(super) fn parse_npz(bytes: &[u8]) -> Result<Vec<Variable>, ArrayFileError> {
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| {
            ArrayFileError::Malformed(format!("not a readable .npz (zip) archive: {e}"))
        })?;
        let mut out = Vec::new();
        for i in 0..zip.len() {
            let mut member = zip.by_index(i).map_err(|e| {
                ArrayFileError::Malformed(format!("member {i} of the .npz archive: {e}"))
            })?;
            if member.is_dir() {
                continue;
            }
            let full = member
                .name()
                .map_err(|e| {
                    ArrayFileError::Malformed(format!("member {i} of the .npz archive: {e}"))
                })?
                .to_string();
            let Some(name) = full.strip_suffix(".npy") else {
                continue;
            };
            let mut data = Vec::new();
            member
                .by_ref()
                .take(MAX_EXPANDED_BYTES + 1)
                .read_to_end(&mut data)
                .map_err(|e| ArrayFileError::Decompress {
                    what: format!("member `{}` of the .npz archive", clip(&full)),
                    message: e.to_string(),
                })?;
            if data.len() as u64 > MAX_EXPANDED_BYTES {
                return Err(ArrayFileError::Decompress {
                    what: format!("member `{}` of the .npz archive", clip(&full)),
                    message: format!("it expands to more than {} GiB", MAX_EXPANDED_BYTES >> 30),
                });
            }
            let mut vars = parse(&data, name)?;
            if vars.len() > 1 || vars.first().is_some_and(|v| v.name != name) {
                // A structured member: its fields are `member.field`.
                for v in &mut vars {
                    v.name = format!("{name}.{}", v.name);
                }
            }
            out.extend(vars);
        }
        Ok(out)
    }
}

//! MAT-files (v5, compressed or not, either byte order), NumPy `.npy` and `.npz` files: files
//! written by SciPy/NumPy (tests/data/arrays, see make_fixtures.py there), files built byte by
//! byte here following the formats, and a corpus of malformed files that must give clear
//! errors and never panic.

use std::io::Write;
use std::path::{Path, PathBuf};

use structid_io::array_file::{ArrayFile, ArrayFileError, Vars};
use structid_io::{DataTable, IoError};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/arrays")
        .join(name)
}

fn u_y() -> (Vec<f64>, Vec<f64>) {
    let u: Vec<f64> = (0..8).map(|k| (0.7 * k as f64).sin()).collect();
    let y = u.iter().map(|v| 0.5 * v * v - 0.25).collect();
    (u, y)
}

fn vars(s: &str) -> Vars {
    s.parse().unwrap()
}

fn close(a: &[f64], b: &[f64], tol: f64) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        assert!((x - y).abs() <= tol, "{a:?} vs {b:?}");
    }
}

#[test]
fn scipy_mat_files_compressed_or_not() {
    let (u, y) = u_y();
    for name in ["signals_v5.mat", "signals_v7.mat"] {
        let path = fixture(name);
        let t = DataTable::read_vars(&path, Some(&vars("u=vir,y=qm"))).unwrap();
        assert_eq!(t.names, ["u", "y"]);
        assert_eq!(t.columns, vec![u.clone(), y.clone()], "{name}");
        let t = DataTable::read_vars(
            &path,
            Some(&vars("a=data#1, b=data#0, counts, gain, valid")),
        )
        .unwrap();
        assert_eq!(t.names, ["a", "b", "counts", "gain", "valid"]);
        assert_eq!(t.columns[0], y);
        assert_eq!(t.columns[1], u);
        assert_eq!(
            t.columns[2],
            (0..8).map(|k| (3 * k - 7) as f64).collect::<Vec<_>>()
        );
        close(
            &t.columns[3],
            &(0..8).map(|k| k as f64 / 4.0).collect::<Vec<_>>(),
            0.0,
        );
        assert_eq!(
            t.columns[4],
            (0..8)
                .map(|k| f64::from(u8::from(k > 2)))
                .collect::<Vec<_>>()
        );
        // Without a selection: every readable variable, matrices by column.
        let t = DataTable::read(&path).unwrap();
        assert_eq!(
            t.names,
            ["vir", "qm", "data#0", "data#1", "counts", "gain", "valid"],
            "{name}"
        );
        assert_eq!(t.path(), Some(path.as_path()));
        // The unreadable ones give reasons.
        let msg = |v: &str| {
            DataTable::read_vars(&path, Some(&vars(&format!("u={v}"))))
                .unwrap_err()
                .to_string()
        };
        assert!(
            msg("title").contains("is a character array (text)"),
            "{}",
            msg("title")
        );
        assert!(msg("meta").contains("is a struct"), "{}", msg("meta"));
        assert!(
            msg("pieces").contains("is a cell array"),
            "{}",
            msg("pieces")
        );
        assert!(
            msg("spectrum").contains("is complex"),
            "{}",
            msg("spectrum")
        );
        assert!(msg("sparse").contains("sparse matrix"), "{}", msg("sparse"));
        assert!(
            msg("cube").contains("3 dimensions (2×2×2)"),
            "{}",
            msg("cube")
        );
        let e = msg("data");
        assert!(
            e.contains("8×2 matrix") && e.contains("`data#0` … `data#1`"),
            "{e}"
        );
        let e = msg("data#2");
        assert!(
            e.contains("has 2 columns (#0 … #1), so it has no column #2"),
            "{e}"
        );
        let e = msg("qn");
        assert!(
            e.starts_with(&format!("data file `{}`: the file has no variable `qn`; it holds vir (1×8), qm (8×1), data (8×2)", path.display())),
            "{e}"
        );
        assert!(e.contains("meta (a struct, not readable)"), "{e}");
    }
}

#[test]
fn numpy_files() {
    let (u, y) = u_y();
    let t = DataTable::read_vars(&fixture("signals.npy"), Some(&vars("y=#1,u=#0"))).unwrap();
    assert_eq!(t.columns, vec![y.clone(), u.clone()]);
    assert_eq!(
        DataTable::read(&fixture("signals.npy")).unwrap().names,
        ["c0", "c1"]
    );
    // Fortran order, big-endian float32.
    let t =
        DataTable::read_vars(&fixture("signals_fortran_f4.npy"), Some(&vars("u=#0,y=#1"))).unwrap();
    close(&t.columns[0], &u, 1e-7);
    close(&t.columns[1], &y, 1e-7);
    // Structured: fields are named columns.
    let t = DataTable::read(&fixture("signals_structured.npy")).unwrap();
    assert_eq!(t.names, ["u", "y", "n"]);
    assert_eq!(t.columns[..2], [u.clone(), y.clone()]);
    let t = DataTable::read_vars(&fixture("signals_structured.npy"), Some(&vars("out=y"))).unwrap();
    assert_eq!(t.columns, vec![y.clone()]);
    let e = DataTable::read(&fixture("complex.npy"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("no real numeric array"), "{e}");
    let e = DataTable::read_vars(&fixture("complex.npy"), Some(&vars("u=#0")))
        .unwrap_err()
        .to_string();
    assert!(e.contains("complex"), "{e}");
    for name in ["signals.npz", "signals_compressed.npz"] {
        let t = DataTable::read_vars(&fixture(name), Some(&vars("u=vir,y=data#1"))).unwrap();
        assert_eq!(t.columns, vec![u.clone(), y.clone()], "{name}");
        let e = DataTable::read_vars(&fixture(name), Some(&vars("u=#0")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs a file with one array"), "{e}");
    }
}

#[test]
fn mat_file_equals_csv() {
    let csv = DataTable::read(&fixture("signals.csv")).unwrap();
    let mat = DataTable::read_vars(&fixture("signals_v7.mat"), Some(&vars("u=vir,y=qm"))).unwrap();
    assert_eq!(csv.names, mat.names);
    assert_eq!(csv.columns, mat.columns);
}

#[test]
fn csv_files_take_vars_too() {
    let t = DataTable::read_vars(&fixture("signals.csv"), Some(&vars("out=y,in=#0"))).unwrap();
    assert_eq!(t.names, ["out", "in"]);
    let e = DataTable::read_vars(&fixture("signals.csv"), Some(&vars("u=x#1")))
        .unwrap_err()
        .to_string();
    assert!(e.contains("for a CSV file"), "{e}");
    let e = DataTable::read_vars(&fixture("signals.csv"), Some(&vars("u=v")))
        .unwrap_err()
        .to_string();
    assert!(e.contains("no column `v`"), "{e}");
}

// ---------------------------------------------------------------------------------------
// MAT v5 written byte by byte.

const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT16: u32 = 3;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
const MX_DOUBLE: u32 = 6;

struct Mat {
    big_endian: bool,
}

impl Mat {
    fn u32(&self, v: u32) -> [u8; 4] {
        if self.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    }

    /// A data element, padded to 8 bytes (small elements packed in the tag).
    fn element(&self, ty: u32, data: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        if data.len() <= 4 && ty != MI_MATRIX && !data.is_empty() {
            out.extend(self.u32(((data.len() as u32) << 16) | ty));
            out.extend(data);
            out.resize(8, 0);
            return out;
        }
        out.extend(self.u32(ty));
        out.extend(self.u32(data.len() as u32));
        out.extend(data);
        while !out.len().is_multiple_of(8) {
            out.push(0);
        }
        out
    }

    fn doubles(&self, v: &[f64]) -> Vec<u8> {
        v.iter()
            .flat_map(|x| {
                if self.big_endian {
                    x.to_be_bytes()
                } else {
                    x.to_le_bytes()
                }
            })
            .collect()
    }

    /// A miMATRIX element of class `class` with the real part `real` (`ty`, raw bytes).
    fn matrix(&self, name: &str, flags: u32, dims: &[i32], ty: u32, real: &[u8]) -> Vec<u8> {
        let mut body = Vec::new();
        let mut f = self.u32(flags).to_vec();
        f.extend([0; 4]);
        body.extend(self.element(MI_UINT32, &f));
        let d: Vec<u8> = dims.iter().flat_map(|&x| self.u32(x as u32)).collect();
        body.extend(self.element(MI_INT32, &d));
        body.extend(self.element(MI_INT8, name.as_bytes()));
        body.extend(self.element(ty, real));
        self.element(MI_MATRIX, &body)
    }

    fn compressed(&self, element: &[u8]) -> Vec<u8> {
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(element).unwrap();
        let z = z.finish().unwrap();
        let mut out = self.u32(MI_COMPRESSED).to_vec();
        out.extend(self.u32(z.len() as u32));
        out.extend(z);
        out
    }

    fn file(&self, elements: &[Vec<u8>]) -> Vec<u8> {
        let mut out = format!(
            "{:<116}",
            "MATLAB 5.0 MAT-file, written by the structid tests"
        )
        .into_bytes();
        out.extend([0; 8]);
        if self.big_endian {
            out.extend([0x01, 0x00]);
            out.extend(b"MI");
        } else {
            out.extend([0x00, 0x01]);
            out.extend(b"IM");
        }
        for e in elements {
            out.extend(e);
        }
        out
    }
}

/// A file with u (1×5 double), y (5×1 stored as int16, as MATLAB does for small integers),
/// m (5×2 single), one variable compressed.
fn built(big_endian: bool) -> Vec<u8> {
    let m = Mat { big_endian };
    let u = [0.5, -1.0, 2.0, 0.25, 3.0];
    let y_int: Vec<u8> = [1i16, -2, 3, -4, 5]
        .iter()
        .flat_map(|x| {
            if big_endian {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            }
        })
        .collect();
    let singles: Vec<u8> = (0..10)
        .map(|k| k as f32 * 0.5)
        .flat_map(|x| {
            if big_endian {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            }
        })
        .collect();
    m.file(&[
        m.matrix("u", MX_DOUBLE, &[1, 5], MI_DOUBLE, &m.doubles(&u)),
        m.compressed(&m.matrix("y", MX_DOUBLE, &[5, 1], MI_INT16, &y_int)),
        m.matrix("m", 7, &[5, 2], MI_SINGLE, &singles),
    ])
}

#[test]
fn built_mat_files_both_byte_orders() {
    for be in [false, true] {
        let f = ArrayFile::parse(&built(be)).unwrap();
        let (names, cols) = f.columns(Some(&vars("u,y,m1=m#1"))).unwrap();
        assert_eq!(names, ["u", "y", "m1"]);
        assert_eq!(cols[0], [0.5, -1.0, 2.0, 0.25, 3.0]);
        assert_eq!(cols[1], [1.0, -2.0, 3.0, -4.0, 5.0]);
        assert_eq!(cols[2], [2.5, 3.0, 3.5, 4.0, 4.5]);
    }
}

#[test]
fn small_elements_and_empty_variables() {
    let m = Mat { big_endian: false };
    // A 1×1 uint8 stored as a small element; an empty matrix.
    let bytes = m.file(&[
        m.matrix("k", 9, &[1, 1], MI_UINT8, &[7]),
        m.matrix("e", MX_DOUBLE, &[0, 0], MI_DOUBLE, &[]),
    ]);
    let f = ArrayFile::parse(&bytes).unwrap();
    assert_eq!(f.get(Some("k")).unwrap().data, [7.0]);
    assert_eq!(f.get(Some("e")).unwrap().rows, 0);
}

// ---------------------------------------------------------------------------------------
// Malformed files: clear errors, never a panic.

fn mat_error(bytes: &[u8]) -> String {
    ArrayFile::parse(bytes).unwrap_err().to_string()
}

#[test]
fn version_7_3_and_version_4_say_what_to_do() {
    let mut v73 = format!(
        "{:<116}",
        "MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon"
    )
    .into_bytes();
    v73.resize(512, 0);
    v73.extend(b"\x89HDF\r\n\x1a\n");
    v73.resize(2048, 0);
    assert_eq!(ArrayFile::parse(&v73).unwrap_err(), ArrayFileError::MatV73);
    let e = ArrayFileError::MatV73.to_string();
    assert!(
        e.contains("v7.3") && e.contains("'-v7'") && e.contains("CSV"),
        "{e}"
    );
    // A bare HDF5 file.
    assert_eq!(
        ArrayFile::parse(b"\x89HDF\r\n\x1a\n\0\0\0\0").unwrap_err(),
        ArrayFileError::MatV73
    );
    // Through DataTable, with the path.
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("rec.mat");
    std::fs::write(&p, &v73).unwrap();
    let e = DataTable::read_vars(&p, Some(&vars("u=vir"))).unwrap_err();
    assert!(matches!(
        e,
        IoError::ArrayFile {
            source: ArrayFileError::MatV73,
            ..
        }
    ));
    assert!(e.is_input_error());
    assert!(e.to_string().starts_with(&format!(
        "data file `{}`: this is a MATLAB v7.3",
        p.display()
    )));
    // A v4 file (no text header) with a .mat extension.
    let p4 = dir.path().join("old.mat");
    std::fs::write(&p4, [0u8, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]).unwrap();
    let e = DataTable::read(&p4).unwrap_err().to_string();
    assert!(e.contains("MATLAB v4 files are not read"), "{e}");
    // An empty .mat / .npy / .npz file.
    for ext in ["mat", "npy", "npz"] {
        let p = dir.path().join(format!("empty.{ext}"));
        std::fs::write(&p, b"").unwrap();
        let e = DataTable::read(&p).unwrap_err();
        assert!(matches!(e, IoError::ArrayFile { .. }), "{ext}: {e}");
    }
}

#[test]
fn malformed_mat_files() {
    let m = Mat { big_endian: false };
    let good = built(false);
    // Wrong byte-order mark.
    let mut bad = good.clone();
    bad[126..128].copy_from_slice(b"XX");
    assert!(mat_error(&bad).contains("byte-order mark"));
    // Header only cut.
    assert!(
        mat_error(&good[..100]).contains("truncated"),
        "{}",
        mat_error(&good[..100])
    );
    // A variable that announces more bytes than the file has.
    let e = mat_error(&good[..good.len() - 8]);
    assert!(e.contains("truncated") && e.contains("announces"), "{e}");
    // Wrong class: a cell array is listed but cannot be selected.
    let cell = m.file(&[m.matrix("c", 1, &[1, 1], MI_DOUBLE, &m.doubles(&[1.0]))]);
    let e = ArrayFile::parse(&cell)
        .unwrap()
        .columns(Some(&vars("u=c")))
        .unwrap_err();
    assert!(e.to_string().contains("is a cell array"), "{e}");
    // Complex flag.
    let z = m.file(&[m.matrix(
        "z",
        MX_DOUBLE | 0x0800,
        &[2, 1],
        MI_DOUBLE,
        &m.doubles(&[1.0, 2.0]),
    )]);
    let e = ArrayFile::parse(&z)
        .unwrap()
        .columns(Some(&vars("u=z")))
        .unwrap_err();
    assert_eq!(e, ArrayFileError::Complex { name: "z".into() });
    // Fewer values than the dimensions say.
    let short = m.file(&[m.matrix("s", MX_DOUBLE, &[4, 1], MI_DOUBLE, &m.doubles(&[1.0, 2.0]))]);
    let e = mat_error(&short);
    assert!(e.contains("needs 4 values"), "{e}");
    // Huge dimensions in a tiny file.
    let huge = m.file(&[m.matrix(
        "h",
        MX_DOUBLE,
        &[i32::MAX, i32::MAX],
        MI_DOUBLE,
        &m.doubles(&[1.0]),
    )]);
    assert!(mat_error(&huge).contains("more values than the file has bytes"));
    // Negative dimension.
    let neg = m.file(&[m.matrix("n", MX_DOUBLE, &[-1, 1], MI_DOUBLE, &m.doubles(&[1.0]))]);
    assert!(mat_error(&neg).contains("invalid dimensions"));
    // Values of a non-numeric type.
    let text = m.file(&[m.matrix("t", MX_DOUBLE, &[1, 1], 16, b"abcdefgh")]);
    assert!(mat_error(&text).contains("not a numeric type"));
    // A corrupt compressed stream.
    let mut z = m.compressed(&m.matrix("y", MX_DOUBLE, &[1, 1], MI_DOUBLE, &m.doubles(&[1.0])));
    let n = z.len();
    z[n - 6..].copy_from_slice(&[0xff; 6]);
    let e = mat_error(&m.file(&[z]));
    assert!(
        e.contains("cannot decompress the compressed variable at byte 128"),
        "{e}"
    );
    // A top-level element that is not a variable.
    let e = mat_error(&m.file(&[m.element(MI_DOUBLE, &m.doubles(&[1.0]))]));
    assert!(e.contains("not a variable"), "{e}");
    // Names of a non-text type.
    let mut body = Vec::new();
    body.extend(m.element(MI_UINT32, &[6, 0, 0, 0, 0, 0, 0, 0]));
    body.extend(m.element(MI_INT32, &[1, 0, 0, 0, 1, 0, 0, 0]));
    body.extend(m.element(MI_DOUBLE, &m.doubles(&[1.0])));
    let e = mat_error(&m.file(&[m.element(MI_MATRIX, &body)]));
    assert!(e.contains("its name has data type 9"), "{e}");
}

#[test]
fn lengths_and_non_finite_values() {
    let m = Mat { big_endian: false };
    let f = m.file(&[
        m.matrix(
            "a",
            MX_DOUBLE,
            &[3, 1],
            MI_DOUBLE,
            &m.doubles(&[1.0, 2.0, 3.0]),
        ),
        m.matrix("b", MX_DOUBLE, &[2, 1], MI_DOUBLE, &m.doubles(&[1.0, 2.0])),
        m.matrix(
            "c",
            MX_DOUBLE,
            &[3, 1],
            MI_DOUBLE,
            &m.doubles(&[1.0, f64::NAN, 3.0]),
        ),
    ]);
    let f = ArrayFile::parse(&f).unwrap();
    let e = f.columns(Some(&vars("u=a,y=b"))).unwrap_err().to_string();
    assert_eq!(
        e,
        "the selected signals have different lengths: `u` has 3 samples but `y` has 2"
    );
    let e = f.columns(Some(&vars("u=a,y=c"))).unwrap_err().to_string();
    assert!(
        e.contains("`y` has the non-finite value NaN at sample 1"),
        "{e}"
    );
}

/// A deterministic generator for the corruption corpus.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
}

fn corpus() -> Vec<(String, Vec<u8>)> {
    let mut files = vec![
        ("built-le".to_string(), built(false)),
        ("built-be".to_string(), built(true)),
    ];
    for name in [
        "signals_v5.mat",
        "signals_v7.mat",
        "signals.npy",
        "signals_fortran_f4.npy",
        "signals_structured.npy",
        "signals.npz",
        "signals_compressed.npz",
    ] {
        files.push((name.to_string(), std::fs::read(fixture(name)).unwrap()));
    }
    files
}

/// Every prefix and many corrupted copies of every file: an error or a smaller file, never a
/// panic; selecting from what was read never panics either.
#[test]
fn truncated_and_corrupted_files_never_panic() {
    let mut rng = Lcg(7);
    let v = vars("u=vir,y=qm");
    for (name, bytes) in corpus() {
        for cut in 0..bytes.len() {
            let r = std::panic::catch_unwind(|| {
                if let Ok(f) = ArrayFile::parse(&bytes[..cut]) {
                    let _ = f.columns(Some(&v));
                    let _ = f.columns(None);
                }
            });
            assert!(r.is_ok(), "{name} cut at {cut} panicked");
        }
        for _ in 0..400 {
            let mut b = bytes.clone();
            for _ in 0..1 + rng.next() % 4 {
                let i = (rng.next() as usize) % b.len();
                b[i] = rng.next() as u8;
            }
            let r = std::panic::catch_unwind(|| {
                if let Ok(f) = ArrayFile::parse(&b) {
                    let _ = f.columns(Some(&v));
                    let _ = f.columns(None);
                }
            });
            assert!(r.is_ok(), "{name} corrupted panicked: {b:?}");
        }
    }
}

#[test]
fn malformed_npy_and_npz() {
    let npy = |header: &str, data: &[u8]| {
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend((header.len() as u16).to_le_bytes());
        b.extend(header.as_bytes());
        b.extend(data);
        b
    };
    let f8 = |v: &[f64]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let ok = npy(
        "{'descr': '<f8', 'fortran_order': False, 'shape': (2,), }",
        &f8(&[1.0, 2.0]),
    );
    assert_eq!(
        ArrayFile::parse(&ok).unwrap().get(None).unwrap().data,
        [1.0, 2.0]
    );
    // Python 2 style long integers.
    let ok = npy(
        "{'descr': '<f8', 'fortran_order': False, 'shape': (2L, 1L), }",
        &f8(&[1.0, 2.0]),
    );
    assert_eq!(ArrayFile::parse(&ok).unwrap().get(None).unwrap().rows, 2);
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (
            npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (3,), }",
                &f8(&[1.0]),
            ),
            "needs 3 values",
        ),
        (
            npy("{'descr': '<f8', 'shape': (1,), }", &f8(&[1.0])),
            "no `fortran_order`",
        ),
        (
            npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (1,), ",
                &f8(&[1.0]),
            ),
            "bad .npy header",
        ),
        (npy("['descr']", &[]), "not a dictionary"),
        (
            npy(
                "{'descr': '<f8', 'fortran_order': 1, 'shape': (1,)}",
                &f8(&[1.0]),
            ),
            "fortran_order",
        ),
        (
            npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (99999999999, 99999999999, 99999999999)}",
                &[],
            ),
            "overflows",
        ),
        (
            npy(
                &format!(
                    "{{'descr': '<f8', 'fortran_order': False, 'shape': {}1,{}}}",
                    "(".repeat(50),
                    ")".repeat(50)
                ),
                &[],
            ),
            "nesting too deep",
        ),
        (b"\x93NUMPY\x09\x00".to_vec(), "version 9"),
        (
            b"\x93NUMPY\x01\x00\xff\x00{".to_vec(),
            "announces 255 bytes",
        ),
        (b"PK\x03\x04garbage".to_vec(), "not a readable .npz"),
    ];
    for (bytes, want) in cases {
        let e = ArrayFile::parse(&bytes).unwrap_err().to_string();
        assert!(e.contains(want), "want `{want}` in: {e}");
    }
    let lazy: Vec<(Vec<u8>, &str)> = vec![
        (
            npy(
                "{'descr': '<c16', 'fortran_order': False, 'shape': (1,), }",
                &[0; 16],
            ),
            "is complex",
        ),
        (
            npy(
                "{'descr': '|O', 'fortran_order': False, 'shape': (1,), }",
                &[0; 8],
            ),
            "Python objects",
        ),
        (
            npy(
                "{'descr': '<U3', 'fortran_order': False, 'shape': (1,), }",
                &[0; 12],
            ),
            "text",
        ),
        (
            npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 1, 2), }",
                &f8(&[1.0, 2.0]),
            ),
            "3 dimensions",
        ),
    ];
    for (bytes, want) in lazy {
        let e = ArrayFile::parse(&bytes)
            .unwrap()
            .columns(Some(&vars("u=#0")))
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "want `{want}` in: {e}");
    }
}

#[test]
fn npz_written_here() {
    let npy_of = |v: &[f64]| {
        let header = format!(
            "{{'descr': '<f8', 'fortran_order': False, 'shape': ({},), }}",
            v.len()
        );
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend((header.len() as u16).to_le_bytes());
        b.extend(header.as_bytes());
        b.extend(v.iter().flat_map(|x| x.to_le_bytes()));
        b
    };
    let mut z = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, v, method) in [
        ("u.npy", vec![1.0, 2.0], zip::CompressionMethod::Stored),
        ("y.npy", vec![3.0, 4.0], zip::CompressionMethod::Deflated),
        ("notes.txt", vec![], zip::CompressionMethod::Stored),
    ] {
        let opts = zip::write::SimpleFileOptions::default().compression_method(method);
        z.start_file(name, opts).unwrap();
        z.write_all(&npy_of(&v)).unwrap();
    }
    let bytes = z.finish().unwrap().into_inner();
    let f = ArrayFile::parse(&bytes).unwrap();
    let (names, cols) = f.columns(None).unwrap();
    assert_eq!(names, ["u", "y"]);
    assert_eq!(cols, vec![vec![1.0, 2.0], vec![3.0, 4.0]]);
}

#[test]
fn vars_syntax() {
    for (text, want) in [
        ("", "an empty item"),
        ("u=vir,", "an empty item"),
        ("=vir", "needs a name and a variable"),
        ("u=#", "zero-based column index"),
        ("u=a#-1", "zero-based column index"),
        ("u=a,u=b", "given twice"),
    ] {
        let e = text.parse::<Vars>().unwrap_err().to_string();
        assert!(e.contains(want), "`{text}`: {e}");
    }
    let v = vars("u=vir, y = data#3");
    assert_eq!(v.to_string(), "u=vir,y=data#3");
}

//! Atomic output files that never overwrite an input.
//!
//! [`write_atomic`] writes to a temporary file in the destination directory, flushes it to disk
//! and renames it over the destination, so a reader sees either the old file or the complete
//! new one, never a partial write. Missing parent directories are created. A destination that
//! is one of the given input files (compared after resolving symbolic links and `..`, and on
//! Unix also by device and inode, so hard links are caught) is refused with
//! [`IoError::WouldOverwriteInput`].
//!
//! ```
//! use structid_io::{IoError, OutputGuard};
//! let dir = tempfile::tempdir().unwrap();
//! let input = dir.path().join("data.csv");
//! std::fs::write(&input, "u,y\n1,2\n").unwrap();
//! let mut guard = OutputGuard::new();
//! guard.protect(&input);
//! guard.write(&dir.path().join("out/report.json"), b"{}").unwrap();
//! let e = guard.write(&dir.path().join("out/../data.csv"), b"oops").unwrap_err();
//! assert!(matches!(e, IoError::WouldOverwriteInput { .. }));
//! assert_eq!(std::fs::read_to_string(&input).unwrap(), "u,y\n1,2\n");
//! ```

use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::IoError;

/// A set of input files that must never be overwritten, and atomic writes that respect it.
#[derive(Clone, Debug, Default)]
pub struct OutputGuard {
    /// (path as given, resolved path)
    inputs: Vec<(PathBuf, PathBuf)>,
}

impl OutputGuard {
    /// A guard protecting nothing yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds an input file to protect.
    pub fn protect(&mut self, input: &Path) -> &mut Self {
        self.inputs.push((input.to_path_buf(), resolve(input)));
        self
    }

    /// The protected inputs, as given.
    pub fn inputs(&self) -> impl Iterator<Item = &Path> {
        self.inputs.iter().map(|(p, _)| p.as_path())
    }

    /// Fails with [`IoError::WouldOverwriteInput`] when `path` designates a protected input.
    pub fn check(&self, path: &Path) -> Result<(), IoError> {
        let target = resolve(path);
        for (given, resolved) in &self.inputs {
            if *resolved == target || same_file(given, path) {
                return Err(IoError::WouldOverwriteInput {
                    path: path.to_path_buf(),
                    input: given.clone(),
                });
            }
        }
        Ok(())
    }

    /// Checks an output directory before a command does any work: neither `dir` nor any of
    /// the `files` it will write there is a protected input, and `dir`, if it exists, is a
    /// directory ([`IoError::InvalidArgument`] otherwise).
    ///
    /// ```
    /// use std::path::Path;
    /// use structid_io::OutputGuard;
    /// let dir = std::env::temp_dir().join("structid-doc-check-out-dir");
    /// let input = dir.join("data.csv");
    /// let mut guard = OutputGuard::new();
    /// guard.protect(&input);
    /// assert!(guard.check_out_dir(&dir, ["report.json"]).is_ok());
    /// assert!(guard.check_out_dir(&dir, ["data.csv"]).is_err());
    /// ```
    pub fn check_out_dir<P: AsRef<Path>>(
        &self,
        dir: &Path,
        files: impl IntoIterator<Item = P>,
    ) -> Result<(), IoError> {
        self.check(dir)?;
        for f in files {
            self.check(&dir.join(f))?;
        }
        if dir.exists() && !dir.is_dir() {
            return Err(IoError::InvalidArgument(format!(
                "--out `{}` exists and is not a directory",
                dir.display()
            )));
        }
        Ok(())
    }

    /// [`write_atomic`] with this guard's inputs protected.
    pub fn write(&self, path: &Path, bytes: &[u8]) -> Result<(), IoError> {
        self.check(path)?;
        write_unchecked(path, bytes)
    }

    /// Creates directory `dir` (and its parents) unless it exists; fails when `dir` is a
    /// protected input or an existing non-directory.
    pub fn create_dir(&self, dir: &Path) -> Result<(), IoError> {
        self.check(dir)?;
        create_dir(dir)
    }
}

/// Writes `bytes` to `path` atomically (temporary file in the same directory, `fsync`, rename),
/// creating missing parent directories. Refuses to write when `path` is one of `inputs`.
pub fn write_atomic(path: &Path, bytes: &[u8], inputs: &[&Path]) -> Result<(), IoError> {
    let mut guard = OutputGuard::new();
    for i in inputs {
        guard.protect(i);
    }
    guard.write(path, bytes)
}

fn create_dir(dir: &Path) -> Result<(), IoError> {
    if dir.as_os_str().is_empty() {
        return Ok(());
    }
    if dir.exists() && !dir.is_dir() {
        return Err(IoError::Write {
            path: dir.to_path_buf(),
            source: std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "it exists and is not a directory",
            ),
        });
    }
    fs::create_dir_all(dir).map_err(|source| IoError::Write {
        path: dir.to_path_buf(),
        source,
    })
}

static COUNTER: AtomicU64 = AtomicU64::new(0);

fn write_unchecked(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    let werr = |source: std::io::Error| IoError::Write {
        path: path.to_path_buf(),
        source,
    };
    let name = path.file_name().ok_or_else(|| {
        werr(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the path does not name a file",
        ))
    })?;
    if path.is_dir() {
        return Err(werr(std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            "it is an existing directory",
        )));
    }
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    create_dir(&dir)?;
    let tmp = dir.join(format!(
        ".{}.tmp-{}-{}",
        name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| -> std::io::Result<()> {
        let mut f = OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)?;
        // Make the rename durable; not all platforms can open a directory, so ignore failures.
        if let Ok(d) = File::open(&dir) {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(werr(e));
    }
    Ok(())
}

/// An absolute, normalised form of `p`: symbolic links resolved for the longest existing
/// prefix, `.` and `..` removed lexically for the rest.
fn resolve(p: &Path) -> PathBuf {
    if let Ok(c) = fs::canonicalize(p) {
        return c;
    }
    let abs = if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir()
            .map(|d| d.join(p))
            .unwrap_or_else(|_| p.to_path_buf())
    };
    // Find the longest existing ancestor and canonicalise it.
    let mut existing = abs.clone();
    let mut rest: Vec<std::ffi::OsString> = Vec::new();
    loop {
        if let Ok(c) = fs::canonicalize(&existing) {
            let mut out = c;
            for part in rest.iter().rev() {
                match Path::new(part).components().next() {
                    Some(Component::ParentDir) => {
                        out.pop();
                    }
                    Some(Component::CurDir) | None => {}
                    _ => out.push(part),
                }
            }
            return out;
        }
        match (
            existing.file_name().map(|n| n.to_os_string()),
            existing.parent(),
        ) {
            (Some(name), Some(parent)) => {
                rest.push(name);
                existing = parent.to_path_buf();
            }
            _ => {
                // `..` at the end, or nothing exists: normalise lexically.
                let mut out = PathBuf::new();
                for c in abs.components() {
                    match c {
                        Component::ParentDir => {
                            out.pop();
                        }
                        Component::CurDir => {}
                        other => out.push(other.as_os_str()),
                    }
                }
                return out;
            }
        }
    }
}

#[cfg(unix)]
fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (fs::metadata(a), fs::metadata(b)) {
        (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_a: &Path, _b: &Path) -> bool {
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_to_overwrite_an_input_by_any_spelling() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.csv");
        fs::write(&input, "keep").unwrap();
        let sub = dir.path().join("sub");
        fs::create_dir(&sub).unwrap();
        for spelling in [
            input.clone(),
            sub.join("../in.csv"),
            dir.path().join("./in.csv"),
        ] {
            let e = write_atomic(&spelling, b"x", &[&input]).unwrap_err();
            assert!(matches!(e, IoError::WouldOverwriteInput { .. }), "{e}");
        }
        #[cfg(unix)]
        {
            let link = dir.path().join("link.csv");
            std::os::unix::fs::symlink(&input, &link).unwrap();
            assert!(write_atomic(&link, b"x", &[&input]).is_err());
            let hard = dir.path().join("hard.csv");
            fs::hard_link(&input, &hard).unwrap();
            assert!(write_atomic(&hard, b"x", &[&input]).is_err());
        }
        assert_eq!(fs::read_to_string(&input).unwrap(), "keep");
    }

    #[test]
    fn writes_atomically_and_creates_directories() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a/b/c.txt");
        write_atomic(&out, b"one", &[]).unwrap();
        write_atomic(&out, b"two", &[]).unwrap();
        assert_eq!(fs::read_to_string(&out).unwrap(), "two");
        // No temporary files are left behind.
        let names: Vec<_> = fs::read_dir(dir.path().join("a/b"))
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1);
        // A directory cannot be overwritten.
        assert!(write_atomic(&dir.path().join("a"), b"x", &[]).is_err());
        // A file in the way of a directory is an error, not a panic.
        let e = write_atomic(&out.join("d.txt"), b"x", &[]).unwrap_err();
        assert!(matches!(e, IoError::Write { .. }));
    }
}

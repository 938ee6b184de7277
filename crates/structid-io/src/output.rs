//! Atomic output files that never overwrite an input.
//!
//! [`write_atomic`] writes to a temporary file in the destination directory, flushes it to disk
//! and renames it over the destination, so a reader sees either the old file or the complete
//! new one, never a partial write. Missing parent directories are created. A destination that
//! is one of the given input files (compared after resolving symbolic links and `..`, and on
//! Unix also by device and inode, so hard links are caught) is refused with
//! [`IoError::WouldOverwriteInput`].
//!
//! Output locations are checked before a command does any work ([`OutputGuard::check_out_dir`],
//! [`OutputGuard::check_out_file`]): an output that is an input, a file where a directory is
//! expected (or the reverse), and a location that cannot be written are refused with an input
//! error ([`IoError::WouldOverwriteInput`] or [`IoError::Output`]).
//!
//! **Temporary files.** A write in progress is `.<name>.tmp-<pid>-<n>` in the destination's
//! directory. A process killed while writing leaves it behind; the first write of a later run
//! into that directory removes the temporary files of processes that no longer run
//! ([`remove_stale_temp_files`]).
//!
//! **Result sets.** Each file is atomic, a set of files (a result directory) is not: a run
//! killed half-way leaves some new files beside old ones. A directory's [`COMPLETE_MARKER`]
//! (`.complete`) lists the files that belong to sets written in full: [`OutputGuard::begin_set`]
//! takes a set's names off the list before its first write and [`OutputGuard::finish_set`]
//! adds them after its last, so a file listed there is never one of a set still being written
//! or left incomplete. [`is_complete`] asks; a directory without the marker predates it.
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
            return Err(IoError::Output {
                path: dir.to_path_buf(),
                message: "it exists and is not a directory; give a directory for the results"
                    .into(),
            });
        }
        check_writable(dir, dir)
    }

    /// Checks an output file before a command does any work: it is not a protected input, not
    /// an existing directory, and its directory exists or can be created and is writable
    /// ([`IoError::Output`] otherwise). Nothing is left behind.
    ///
    /// ```
    /// use structid_io::{IoError, OutputGuard};
    /// let dir = tempfile::tempdir().unwrap();
    /// let guard = OutputGuard::new();
    /// assert!(guard.check_out_file(&dir.path().join("new/out.csv")).is_ok());
    /// assert!(!dir.path().join("new").exists());
    /// let e = guard.check_out_file(dir.path()).unwrap_err();
    /// assert!(matches!(e, IoError::Output { .. }), "{e}");
    /// ```
    pub fn check_out_file(&self, path: &Path) -> Result<(), IoError> {
        self.check(path)?;
        if path.is_dir() {
            return Err(IoError::Output {
                path: path.to_path_buf(),
                message: "it is an existing directory; give the name of a file".into(),
            });
        }
        if path.file_name().is_none() {
            return Err(IoError::Output {
                path: path.to_path_buf(),
                message: "it does not name a file".into(),
            });
        }
        match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => check_writable(path, p),
            _ => check_writable(path, Path::new(".")),
        }
    }

    /// Starts writing the set of files `names` into directory `dir` (created if needed): takes
    /// them off `dir`'s [`COMPLETE_MARKER`] (all of its entries when `names` is `None`),
    /// creating the marker if `dir` has none, so that until [`OutputGuard::finish_set`] a
    /// reader knows these files are not a complete set. Also removes the stale temporary files
    /// of killed runs in `dir`.
    pub fn begin_set<S: AsRef<str>>(&self, dir: &Path, names: Option<&[S]>) -> Result<(), IoError> {
        self.create_dir(dir)?;
        clean_once(dir);
        let mut listed = completed_files(dir).unwrap_or_default();
        match names {
            Some(names) => listed.retain(|f| !names.iter().any(|n| n.as_ref() == f)),
            None => listed.clear(),
        }
        self.write_marker(dir, &listed)
    }

    /// Ends a set begun by [`OutputGuard::begin_set`]: adds the files `names`, all written, to
    /// `dir`'s [`COMPLETE_MARKER`].
    pub fn finish_set<S: AsRef<str>>(&self, dir: &Path, names: &[S]) -> Result<(), IoError> {
        let mut listed = completed_files(dir).unwrap_or_default();
        listed.extend(names.iter().map(|n| n.as_ref().to_string()));
        self.write_marker(dir, &listed)
    }

    fn write_marker(&self, dir: &Path, names: &[String]) -> Result<(), IoError> {
        let mut names: Vec<&str> = names.iter().map(String::as_str).collect();
        names.sort_unstable();
        names.dedup();
        let mut text = String::from(MARKER_HEADER);
        for n in names {
            text.push_str(n);
            text.push('\n');
        }
        self.write(&dir.join(COMPLETE_MARKER), text.as_bytes())
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

/// The file of a result directory that lists its complete files (see the
/// [module documentation](self)).
pub const COMPLETE_MARKER: &str = ".complete";

const MARKER_HEADER: &str = "# Files of this directory written in full by structid, one a line. A file not listed\n\
# here belongs to a set of results that is being written or whose run was interrupted.\n";

/// The files listed in `dir`'s [`COMPLETE_MARKER`]; `None` when `dir` has no marker.
pub fn completed_files(dir: &Path) -> Option<Vec<String>> {
    let text = fs::read_to_string(dir.join(COMPLETE_MARKER)).ok()?;
    Some(
        text.lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
            .map(String::from)
            .collect(),
    )
}

/// Whether `file` is complete: listed in its directory's [`COMPLETE_MARKER`], or in a
/// directory without one (written before markers existed, or by hand).
///
/// ```
/// use structid_io::OutputGuard;
/// use structid_io::output::is_complete;
/// let dir = tempfile::tempdir().unwrap();
/// let guard = OutputGuard::new();
/// guard.begin_set(dir.path(), Some(&["a.csv", "b.csv"])).unwrap();
/// guard.write(&dir.path().join("a.csv"), b"1").unwrap();
/// assert!(!is_complete(&dir.path().join("a.csv")));
/// guard.write(&dir.path().join("b.csv"), b"2").unwrap();
/// guard.finish_set(dir.path(), &["a.csv", "b.csv"]).unwrap();
/// assert!(is_complete(&dir.path().join("a.csv")));
/// ```
pub fn is_complete(file: &Path) -> bool {
    let dir = match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let Some(name) = file.file_name() else {
        return false;
    };
    match completed_files(dir) {
        None => true,
        Some(list) => list.iter().any(|f| std::ffi::OsStr::new(f) == name),
    }
}

/// Fails with [`IoError::Output`] about `output` unless files can be created in `dir`, or,
/// when `dir` does not exist, in its nearest existing ancestor (which must be a directory). A
/// probe file is created and removed at once; nothing else is touched.
fn check_writable(output: &Path, dir: &Path) -> Result<(), IoError> {
    let bad = |message: String| IoError::Output {
        path: output.to_path_buf(),
        message,
    };
    let mut at = if dir.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        dir.to_path_buf()
    };
    loop {
        match fs::metadata(&at) {
            Ok(m) if m.is_dir() => break,
            Ok(_) => {
                return Err(bad(if at == output {
                    "it exists and is not a directory".into()
                } else {
                    format!("`{}` is a file, not a directory", at.display())
                }));
            }
            Err(_) => match at.parent() {
                Some(p) if !p.as_os_str().is_empty() => at = p.to_path_buf(),
                _ => {
                    at = PathBuf::from(".");
                    if fs::metadata(&at).is_err() {
                        return Err(bad("no part of it exists".into()));
                    }
                    break;
                }
            },
        }
    }
    let probe = at.join(format!(
        ".probe.tmp-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    match OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(f) => {
            drop(f);
            let _ = fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(bad(format!(
            "cannot create files in `{}` ({})",
            at.display(),
            e.kind()
        ))),
    }
}

/// Temporary files of dead processes older than this are removed where liveness cannot be
/// checked (no `/proc`).
const STALE_AGE: std::time::Duration = std::time::Duration::from_secs(24 * 3600);

/// The process id of a temporary file name `.<name>.tmp-<pid>-<n>`, if it is one.
fn temp_file_pid(name: &str) -> Option<u32> {
    if !name.starts_with('.') {
        return None;
    }
    let (_, tail) = name.rsplit_once(".tmp-")?;
    let (pid, n) = tail.split_once('-')?;
    if pid.is_empty() || n.is_empty() || !n.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    pid.parse().ok()
}

/// Whether process `pid` runs: `Some` where `/proc` tells, `None` where it cannot.
fn process_alive(pid: u32) -> Option<bool> {
    if pid == std::process::id() {
        return Some(true);
    }
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return None;
    }
    Some(proc.join(pid.to_string()).exists())
}

/// Removes the temporary files (`.<name>.tmp-<pid>-<n>`) that killed writes left in `dir`:
/// those of processes that no longer run (checked in `/proc`; where it is missing, those
/// older than a day). Returns how many were removed. Files of running processes, this one
/// included, are kept.
///
/// ```
/// use structid_io::output::remove_stale_temp_files;
/// let dir = tempfile::tempdir().unwrap();
/// let mine = dir.path().join(format!(".a.csv.tmp-{}-0", std::process::id()));
/// std::fs::write(&mine, "in progress").unwrap();
/// assert_eq!(remove_stale_temp_files(dir.path()).unwrap(), 0);
/// assert!(mine.exists());
/// ```
pub fn remove_stale_temp_files(dir: &Path) -> std::io::Result<usize> {
    let mut removed = 0;
    for entry in fs::read_dir(dir)? {
        let Ok(entry) = entry else { continue };
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(temp_file_pid) else {
            continue;
        };
        let Ok(meta) = entry.metadata() else { continue };
        if !meta.is_file() {
            continue;
        }
        let stale = match process_alive(pid) {
            Some(alive) => !alive,
            None => meta
                .modified()
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age > STALE_AGE),
        };
        if stale && fs::remove_file(entry.path()).is_ok() {
            removed += 1;
        }
    }
    Ok(removed)
}

/// [`remove_stale_temp_files`] once per directory and process (errors are ignored: the
/// cleanup must never stop a write).
fn clean_once(dir: &Path) {
    static CLEANED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    let key = resolve(dir);
    {
        let mut done = CLEANED.lock().unwrap_or_else(|p| p.into_inner());
        if done.contains(&key) {
            return;
        }
        done.push(key);
    }
    let _ = remove_stale_temp_files(dir);
}

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
    clean_once(&dir);
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

/// The file names of `paths` (their last components), as [`OutputGuard::finish_set`] lists
/// them.
///
/// ```
/// use std::path::PathBuf;
/// let names = structid_io::output::file_names(&[PathBuf::from("out/a.csv"), PathBuf::from("b.svg")]);
/// assert_eq!(names, ["a.csv", "b.svg"]);
/// ```
pub fn file_names(paths: &[std::path::PathBuf]) -> Vec<String> {
    paths
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect()
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

    /// The id of a process that has exited.
    fn dead_pid() -> u32 {
        let mut child = std::process::Command::new(std::env::current_exe().unwrap())
            .arg("--list")
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let pid = child.id();
        child.wait().unwrap();
        pid
    }

    #[test]
    fn stale_temp_files_of_dead_processes_are_removed_by_the_next_write() {
        assert_eq!(temp_file_pid(".a.csv.tmp-123-4"), Some(123));
        assert_eq!(temp_file_pid(".x.tmp-1.tmp-77-0"), Some(77));
        for not in [
            "a.csv.tmp-1-2",
            ".a.csv",
            ".a.tmp-x-1",
            ".a.tmp-1-",
            ".a.tmp-1-x",
        ] {
            assert_eq!(temp_file_pid(not), None, "{not}");
        }
        let dir = tempfile::tempdir().unwrap();
        let dead = dead_pid();
        let stale = dir.path().join(format!(".report.json.tmp-{dead}-3"));
        let mine = dir
            .path()
            .join(format!(".other.csv.tmp-{}-0", std::process::id()));
        let lookalike = dir.path().join(format!("report.json.tmp-{dead}-3"));
        for f in [&stale, &mine, &lookalike] {
            fs::write(f, "partial").unwrap();
        }
        write_atomic(&dir.path().join("report.json"), b"{}", &[]).unwrap();
        if Path::new("/proc/self").exists() {
            assert!(!stale.exists(), "the dead process's temporary file is left");
        }
        assert!(mine.exists() && lookalike.exists());
        assert_eq!(
            fs::read_to_string(dir.path().join("report.json")).unwrap(),
            "{}"
        );
    }

    #[test]
    fn a_set_is_listed_as_complete_only_after_its_last_file() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().join("result");
        let guard = OutputGuard::new();
        let set = ["estimate.json", "report.json"];
        // A directory without a marker predates markers: its files count as complete.
        fs::create_dir(&d).unwrap();
        fs::write(d.join("old.csv"), "1").unwrap();
        assert!(is_complete(&d.join("old.csv")));
        // A first set: nothing listed until it is finished.
        guard.begin_set(&d, Some(&set)).unwrap();
        assert_eq!(completed_files(&d), Some(Vec::new()));
        guard.write(&d.join("estimate.json"), b"1").unwrap();
        assert!(!is_complete(&d.join("estimate.json")));
        guard.write(&d.join("report.json"), b"1").unwrap();
        guard.finish_set(&d, &set).unwrap();
        assert!(set.iter().all(|f| is_complete(&d.join(f))));
        // Another set beside it keeps the first listed.
        guard.begin_set(&d, Some(&["validation.json"])).unwrap();
        guard.write(&d.join("validation.json"), b"1").unwrap();
        guard.finish_set(&d, &["validation.json"]).unwrap();
        assert_eq!(
            completed_files(&d).unwrap(),
            ["estimate.json", "report.json", "validation.json"]
        );
        // A rerun of the first set that stops half-way (no finish) leaves its files unlisted,
        // the other set listed.
        guard.begin_set(&d, Some(&set)).unwrap();
        guard.write(&d.join("estimate.json"), b"2").unwrap();
        assert!(!is_complete(&d.join("estimate.json")));
        assert!(!is_complete(&d.join("report.json")));
        assert!(is_complete(&d.join("validation.json")));
        // `None` takes every file off the list.
        guard.begin_set::<&str>(&d, None).unwrap();
        assert_eq!(completed_files(&d), Some(Vec::new()));
    }

    #[test]
    fn output_locations_are_checked_before_any_work() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("data.csv");
        fs::write(&file, "u\n1\n").unwrap();
        let guard = OutputGuard::new();
        // A file where a directory is expected, and below a file.
        for bad in [file.clone(), file.join("out")] {
            let e = guard.check_out_dir(&bad, ["a.csv"]).unwrap_err();
            assert!(matches!(e, IoError::Output { .. }), "{e}");
            assert!(e.is_input_error());
        }
        let e = guard.check_out_file(&file.join("x.csv")).unwrap_err();
        assert!(e.to_string().contains("is a file, not a directory"), "{e}");
        // New directories are fine and not created by the check; no probe is left.
        guard
            .check_out_dir(&dir.path().join("a/b"), ["c.csv"])
            .unwrap();
        guard.check_out_file(&dir.path().join("a/b/c.csv")).unwrap();
        let names: Vec<_> = fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let ro = dir.path().join("ro");
            fs::create_dir(&ro).unwrap();
            fs::set_permissions(&ro, fs::Permissions::from_mode(0o555)).unwrap();
            // Root writes anyway; the check then agrees with the write.
            let writable = File::create(ro.join("t")).is_ok();
            let e = guard.check_out_dir(&ro.join("out"), ["a.csv"]);
            assert_eq!(e.is_ok(), writable, "{e:?}");
            fs::set_permissions(&ro, fs::Permissions::from_mode(0o755)).unwrap();
        }
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

//! `structid compare merge`: combining the case files of shard directories and rebuilding the
//! tables and figures from them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use structid_io::OutputGuard;

use crate::compare::figures::write_figures;
use crate::error::CliError;
use structid_workflow::compare::results::{
    CASE_FORMAT, CASES_DIR, CaseRecord, case_files, write_tables,
};

/// Runs `structid compare merge DIR... --out OUT`.
pub fn merge(dirs: &[PathBuf], out: &Path) -> Result<(), CliError> {
    if dirs.is_empty() {
        return Err(CliError::input(
            "compare merge needs at least one directory",
        ));
    }
    let mut guard = OutputGuard::new();
    let resolve = |p: &Path| std::fs::canonicalize(p).ok();
    let out_resolved = resolve(out);
    // Case id → (record, its file, the file's bytes).
    let mut by_id: BTreeMap<String, (CaseRecord, PathBuf, Vec<u8>)> = BTreeMap::new();
    let mut list: Option<(String, usize, PathBuf)> = None;
    for d in dirs {
        if !d.is_dir() {
            return Err(CliError::input(format!(
                "`{}` is not a directory; give the output directories of `structid compare` runs",
                d.display()
            )));
        }
        if out_resolved.is_some() && resolve(d) == out_resolved {
            return Err(CliError::input(format!(
                "--out `{}` is also an input directory; merge into a new directory",
                out.display()
            )));
        }
        let files = case_files(d)?;
        if files.is_empty() {
            return Err(CliError::input(format!(
                "`{}` has no case files ({}/*.json); is it the output directory of a `structid compare` run?",
                d.display(),
                CASES_DIR
            )));
        }
        for f in files {
            guard.protect(&f);
            let bytes = std::fs::read(&f).map_err(|source| structid_io::IoError::Read {
                path: f.clone(),
                source,
            })?;
            let rec = std::str::from_utf8(&bytes)
                .ok()
                .and_then(|t| serde_json::from_str::<CaseRecord>(t).ok())
                .filter(|r| r.format == CASE_FORMAT)
                .ok_or_else(|| {
                    CliError::input(format!(
                        "`{}` is not a complete case file of this version of structid compare; \
                         re-run its case (structid compare --resume) or remove it",
                        f.display()
                    ))
                })?;
            match &list {
                None => list = Some((rec.case_list.clone(), rec.case_count, f.clone())),
                Some((hash, count, first))
                    if *hash != rec.case_list || *count != rec.case_count =>
                {
                    return Err(CliError::input(format!(
                        "`{}` and `{}` come from different sweeps (their case lists differ: {count} and {} cases); \
                         merge only the shards of one configuration",
                        first.display(),
                        f.display(),
                        rec.case_count
                    )));
                }
                Some(_) => {}
            }
            match by_id.get(&rec.id) {
                Some((prev, prev_file, _)) => {
                    if prev.content_without_time() != rec.content_without_time() {
                        return Err(CliError::input(format!(
                            "case `{}` appears in `{}` and `{}` with different results; \
                             remove one of the two files and merge again",
                            rec.id,
                            prev_file.display(),
                            f.display()
                        )));
                    }
                }
                None => {
                    if let Some((other, (_, other_file, _))) =
                        by_id.iter().find(|(_, (r, _, _))| r.index == rec.index)
                    {
                        return Err(CliError::input(format!(
                            "cases `{other}` (`{}`) and `{}` (`{}`) have the same index {}; the files come from different sweeps",
                            other_file.display(),
                            rec.id,
                            f.display(),
                            rec.index
                        )));
                    }
                    by_id.insert(rec.id.clone(), (rec, f, bytes));
                }
            }
        }
    }
    guard.check_out_dir(out, ["results.csv", "results.md"])?;
    if !case_files(out)?.is_empty() {
        return Err(CliError::input(format!(
            "--out `{}` already holds case files; merge into a new or empty directory",
            out.display()
        )));
    }
    guard.begin_set::<&str>(out, None)?;
    guard.create_dir(&out.join(CASES_DIR))?;
    let mut records: BTreeMap<usize, CaseRecord> = BTreeMap::new();
    let total = list.as_ref().map_or(0, |l| l.1);
    for (rec, file, bytes) in by_id.into_values() {
        let name = file
            .file_name()
            .map(|n| n.to_os_string())
            .unwrap_or_default();
        guard.write(&out.join(CASES_DIR).join(name), &bytes)?;
        records.insert(rec.index, rec);
    }
    write_tables(&guard, out, &records, total)?;
    let figs = write_figures(&guard, out, &records)?;
    let mut set = vec![String::from("results.csv"), String::from("results.md")];
    set.extend(structid_io::output::file_names(&figs));
    guard.finish_set(out, &set)?;
    let failed = records.values().filter(|r| !r.is_ok()).count();
    println!(
        "merged {} case(s) of {total} from {} director{} into {}{}",
        records.len(),
        dirs.len(),
        if dirs.len() == 1 { "y" } else { "ies" },
        out.display(),
        if failed > 0 {
            format!(" ({failed} failed; see the status column)")
        } else {
            String::new()
        }
    );
    if records.len() < total {
        println!(
            "note: {} case(s) of the sweep are in none of the directories",
            total - records.len()
        );
    }
    println!("wrote:");
    for f in ["results.csv", "results.md"]
        .iter()
        .map(|f| out.join(f))
        .chain(figs)
    {
        println!("  {}", f.display());
    }
    Ok(())
}

//! Running the cases of a sweep: in parallel with rayon, with a progress bar, each result
//! written at once, and `--resume` skipping finished cases.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use rayon::prelude::*;
use structid_io::OutputGuard;
use structid_workflow::compare::case::{Context, case_is_complete, run_case, skeleton};
use structid_workflow::compare::cases::{Case, Shard, case_list, case_list_hash, file_stem};
use structid_workflow::compare::config::load;
use structid_workflow::compare::results::{
    CASES_DIR, CaseRecord, case_files, read_case, write_tables,
};

use crate::compare::figures::write_figures;
use crate::error::CliError;

/// What `structid compare` was asked to do.
pub struct RunOptions {
    /// The sweep configuration.
    pub config: PathBuf,
    /// The output directory.
    pub out: PathBuf,
    /// Skip cases whose case file is complete.
    pub resume: bool,
    /// Run only this shard of the case list.
    pub shard: Option<Shard>,
    /// Worker threads (default: all cores).
    pub jobs: Option<usize>,
}

fn check_output_dir(guard: &OutputGuard, out: &Path, resume: bool) -> Result<(), CliError> {
    guard.check_out_dir(out, ["results.csv", "results.md"])?;
    if !resume && !case_files(out)?.is_empty() {
        return Err(CliError::input(format!(
            "--out `{}` already holds results of a sweep ({}/*.json); pass --resume to continue it, \
             or choose another directory",
            out.display(),
            CASES_DIR
        )));
    }
    Ok(())
}

/// Runs `structid compare --config … --out …`.
pub fn run(opts: RunOptions) -> Result<(), CliError> {
    if opts.jobs == Some(0) {
        return Err(CliError::input(
            "invalid value 0 for --jobs: it must be at least 1",
        ));
    }
    let sweep = load(&opts.config)?;
    let cases = case_list(&sweep.file);
    let mut guard = OutputGuard::new();
    for p in &sweep.inputs {
        guard.protect(p);
    }
    check_output_dir(&guard, &opts.out, opts.resume)?;
    let ctx = Context {
        sweep: &sweep,
        case_count: cases.len(),
        case_list: case_list_hash(&cases),
    };
    let mine: Vec<&Case> = cases
        .iter()
        .filter(|c| opts.shard.is_none_or(|s| s.contains(c.index)))
        .collect();
    let cases_dir = opts.out.join(CASES_DIR);
    let path_of = |c: &Case| cases_dir.join(format!("{}.json", file_stem(&c.id)));

    let mut done: BTreeMap<usize, CaseRecord> = BTreeMap::new();
    let mut rerun_incomplete = 0usize;
    if opts.resume {
        for c in &mine {
            let p = path_of(c);
            if !p.exists() {
                continue;
            }
            match read_case(&p).filter(|r| case_is_complete(r, &ctx)) {
                Some(r) if r.id == c.id && r.fingerprint == skeleton(&ctx, c).fingerprint => {
                    done.insert(c.index, r);
                }
                Some(_) => {
                    return Err(CliError::input(format!(
                        "cannot resume: `{}` was computed with other settings or input files than \
                         case `{}` of `{}` now has; choose another --out directory, or delete the \
                         file to recompute the case",
                        p.display(),
                        c.id,
                        opts.config.display()
                    )));
                }
                None => rerun_incomplete += 1,
            }
        }
    }
    let pending: Vec<&Case> = mine
        .iter()
        .copied()
        .filter(|c| !done.contains_key(&c.index))
        .collect();
    // The directory's files (tables and figures) are a set: listed as complete in its
    // marker only once the run has finished. Case files are complete one by one.
    guard.begin_set::<&str>(&opts.out, None)?;
    guard.create_dir(&cases_dir)?;
    let _ = structid_io::output::remove_stale_temp_files(&cases_dir);
    write_tables(&guard, &opts.out, &done, cases.len())?;

    let pool = {
        let mut b = rayon::ThreadPoolBuilder::new();
        if let Some(j) = opts.jobs {
            b = b.num_threads(j);
        }
        b.build()
            .map_err(|e| CliError::runtime(format!("cannot start the worker threads: {e}")))?
    };
    let shard_note = opts
        .shard
        .map(|s| format!(" (shard {s})"))
        .unwrap_or_default();
    eprintln!(
        "{} case(s) of {}{shard_note}: {} to run, {} already done{}; {} worker thread(s)",
        mine.len(),
        cases.len(),
        pending.len(),
        done.len(),
        if rerun_incomplete > 0 {
            format!(" ({rerun_incomplete} incomplete case file(s) are recomputed)")
        } else {
            String::new()
        },
        pool.current_num_threads()
    );
    let skipped = done.len();
    let state = Mutex::new(done);
    let pb = crate::progress::bar(Some(pending.len() as u64), "cases");
    let result: Result<(), CliError> = pool.install(|| {
        pending.par_iter().try_for_each(|c| {
            let rec = run_case(&ctx, c);
            if !rec.is_ok() {
                pb.suspend(|| eprintln!("case {}: {}", rec.id, rec.status));
            }
            guard.write(&path_of(c), rec.to_json()?.as_bytes())?;
            {
                // The tables are rewritten after every case, so an interrupted sweep keeps them.
                let mut s = state.lock().unwrap_or_else(|p| p.into_inner());
                pb.set_message(rec.id.clone());
                s.insert(rec.index, rec);
                write_tables(&guard, &opts.out, &s, cases.len())?;
            }
            pb.inc(1);
            Ok(())
        })
    });
    pb.finish_and_clear();
    result?;
    let records = state.into_inner().unwrap_or_else(|p| p.into_inner());
    let figures = write_figures(&guard, &opts.out, &records)?;
    let mut set = vec![String::from("results.csv"), String::from("results.md")];
    set.extend(structid_io::output::file_names(&figures));
    guard.finish_set(&opts.out, &set)?;

    let failed = records.values().filter(|r| !r.is_ok()).count();
    println!(
        "ran {} case(s){}{shard_note}, {} of {} in {} now done; {} failed{}",
        pending.len(),
        if skipped > 0 {
            format!(" ({skipped} skipped, already done)")
        } else {
            String::new()
        },
        records.len(),
        cases.len(),
        opts.out.display(),
        failed,
        if failed > 0 {
            " (see the status column)"
        } else {
            ""
        }
    );
    println!("wrote:");
    println!("  {}/*.json", cases_dir.display());
    for f in ["results.csv", "results.md"]
        .iter()
        .map(|f| opts.out.join(f))
        .chain(figures)
    {
        println!("  {}", f.display());
    }
    Ok(())
}

//! Running the cases of a sweep: in parallel with rayon, with a progress bar, each result
//! written at once, and `--resume` skipping finished cases.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use rayon::prelude::*;
use structid_core::validation::metrics::{centred_rms_difference, rms_difference};
use structid_core::{Identification, IdentifySettings, Signal, identify};
use structid_io::sweep_file::{BetaChoice, SelectionMethod, SweepDispersion};
use structid_io::{DispersionSpec, OutputGuard};

use crate::compare::cases::{Case, Fnv, Shard, case_list, case_list_hash, file_stem};
use crate::compare::config::{Experiment, Sweep, load};
use crate::compare::figures::write_figures;
use crate::compare::results::{
    BlockRecord, CASE_FORMAT, CASES_DIR, CaseRecord, CostRecord, GridRecord, OutputRecord, Values,
    case_files, finite, read_case, write_tables,
};
use crate::error::CliError;
use crate::figures::{GRID_1D, linspace, mean, span};

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

/// β where an automatic search starts.
const AUTO_BETA_START: f64 = 0.01;

/// Everything a case needs that is shared by all cases.
struct Context<'a> {
    sweep: &'a Sweep,
    case_count: usize,
    case_list: String,
}

/// The fingerprint of a case: its experiment's files and settings, its dispersion's settings,
/// β and seed. Resuming refuses a case file whose fingerprint differs.
fn fingerprint(exp: &Experiment, disp: &SweepDispersion, case: &Case) -> String {
    let mut h = Fnv::new();
    h.write(&exp.fingerprint.to_le_bytes());
    h.write(
        format!(
            "{}|{:?}|{}|{:?}|{:?}|{}|{:?}",
            disp.name,
            disp.spec,
            disp.tune_sigma,
            disp.selection,
            disp.solver,
            case.beta.label(),
            case.seed
        )
        .as_bytes(),
    );
    format!("{:016x}", h.finish())
}

fn criterion(m: SelectionMethod) -> structid_core::selection::Criterion {
    match m {
        SelectionMethod::MarginalLikelihood => {
            structid_core::selection::Criterion::MarginalLikelihood
        }
        SelectionMethod::Gcv => structid_core::selection::Criterion::Gcv,
        SelectionMethod::CrossValidation { folds } => {
            structid_core::selection::Criterion::CrossValidation { folds }
        }
        SelectionMethod::Validation => structid_core::selection::Criterion::Validation,
    }
}

/// One-line error text with its causes.
fn one_line(e: &dyn std::fmt::Display) -> String {
    e.to_string()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("; ")
}

/// The record of a case before it ran: names and columns known from the configuration, so that a
/// failed case still has its row.
fn skeleton(ctx: &Context<'_>, case: &Case) -> CaseRecord {
    let exp = &ctx.sweep.experiments[case.experiment];
    let disp = &ctx.sweep.file.dispersions[case.dispersion];
    CaseRecord {
        format: CASE_FORMAT.into(),
        id: case.id.clone(),
        index: case.index,
        case_count: ctx.case_count,
        case_list: ctx.case_list.clone(),
        fingerprint: fingerprint(exp, disp, case),
        experiment: exp.name.clone(),
        dispersion: disp.name.clone(),
        beta_setting: case.beta.label(),
        seed: case.seed,
        selection: match case.beta {
            BetaChoice::Fixed(_) => "fixed".into(),
            BetaChoice::Auto => disp.selection.name().into(),
        },
        beta: match case.beta {
            BetaChoice::Fixed(b) => Some(b),
            BetaChoice::Auto => None,
        },
        blocks: exp
            .model
            .blocks
            .iter()
            .zip(&exp.truth)
            .zip(&exp.centred)
            .map(|((b, t), &centred)| BlockRecord {
                name: b.name.clone(),
                centred,
                has_truth: t.is_some(),
                rms_error: None,
                sigma: None,
                grid: None,
            })
            .collect(),
        validation: if exp.has_validation {
            exp.outputs
                .iter()
                .map(|n| OutputRecord {
                    name: n.clone(),
                    rms: None,
                    fit_percent: None,
                })
                .collect()
        } else {
            Vec::new()
        },
        cost: None,
        solver: disp.solver.name().into(),
        seconds: 0.0,
        status: "ok".into(),
        selection_curve: Vec::new(),
        noise_variance: None,
    }
}

/// Fills `rec` with the results of the case; an error leaves the rest of `rec` as it is.
fn execute(ctx: &Context<'_>, case: &Case, rec: &mut CaseRecord) -> Result<(), CliError> {
    let exp = &ctx.sweep.experiments[case.experiment];
    let disp = &ctx.sweep.file.dispersions[case.dispersion];
    let (data, validation) = exp.records(case.seed)?;
    let mut mf = exp.model.clone();
    mf.replace_dispersions(&disp.spec);
    let needs_z = mf.blocks.iter().any(|b| {
        b.dispersion.sigma().is_none()
            && !matches!(b.dispersion, DispersionSpec::TotalVariation { .. })
    });
    let z = if needs_z {
        Some(mf.z_signal(&data)?)
    } else {
        None
    };
    let model = mf.to_model(None, z.as_ref())?;
    let settings = IdentifySettings::builder()
        .beta(match case.beta {
            BetaChoice::Fixed(b) => b,
            BetaChoice::Auto => AUTO_BETA_START,
        })
        .solver(disp.solver)
        .posterior(true)
        .build()?;
    let (id, model): (Identification, _) = match case.beta {
        BetaChoice::Fixed(_) => (identify(&model, &data, &settings)?, model),
        BetaChoice::Auto => {
            let sel_settings = structid_core::selection::SelectionSettings::builder()
                .criterion(criterion(disp.selection))
                .tune_sigma(disp.tune_sigma)
                .build()?;
            let sel = structid_core::selection::select(
                &model,
                &data,
                validation.as_ref(),
                &settings,
                &sel_settings,
            )?;
            rec.beta = Some(sel.beta);
            rec.selection_curve = sel.curve;
            rec.noise_variance = sel.noise_variance.and_then(finite);
            (sel.identification, sel.model)
        }
    };
    let id = id.converged()?;
    rec.solver = id.diagnostics.solver.to_string();
    rec.cost = Some(CostRecord {
        noise: id.cost.noise,
        dispersion: id.cost.dispersions.iter().sum(),
        total: id.cost.total,
    });
    for (i, est) in id.blocks.iter().enumerate() {
        let Some(k) = exp.model.blocks.iter().position(|b| b.name == est.name) else {
            return Err(CliError::runtime(format!(
                "the identification returned an unknown block `{}`",
                est.name
            )));
        };
        let truth = exp.truth[k].as_deref();
        let b = &mut rec.blocks[k];
        b.sigma = est
            .parameters
            .iter()
            .find(|(n, _)| n == "sigma")
            .map(|(_, v)| *v);
        let truth_at_data = truth.map(|t| t.eval_many(&est.z));
        if let Some(tv) = &truth_at_data {
            b.rms_error = finite(if b.centred {
                centred_rms_difference(&est.w_hat, tv)
            } else {
                rms_difference(&est.w_hat, tv)
            });
        }
        if est.z.channels() == 1 {
            let (lo, hi) = span(&est.z.channel(0));
            let xs = linspace(lo, hi, GRID_1D);
            let points = Signal::new(1, xs.clone()).map_err(structid_core::Error::from)?;
            b.grid = Some(GridRecord {
                estimate: Values(xs.iter().map(|&x| est.map.eval(&[x])).collect()),
                std: id.posterior_std(i, &points)?.map(Values),
                truth: truth.map(|t| Values(xs.iter().map(|&x| t.eval(&[x])).collect())),
                z: Values(xs),
                estimate_mean: mean(&est.w_hat),
                truth_mean: truth_at_data.as_deref().map(mean),
            });
        }
    }
    if let Some(v) = &validation {
        let report = structid_core::validation::validate(
            &model,
            &id.maps(),
            v,
            &structid_core::validation::ValidationSettings::default(),
        )
        .map_err(|e| CliError::from(e).context("validation"))?;
        for (o, (rms, fit)) in rec
            .validation
            .iter_mut()
            .zip(report.rms.iter().zip(&report.fit_percent))
        {
            o.rms = finite(*rms);
            o.fit_percent = finite(*fit);
        }
    }
    Ok(())
}

/// Runs one case; failures (including panics, which are bugs) become its status.
fn run_case(ctx: &Context<'_>, case: &Case) -> CaseRecord {
    let t0 = Instant::now();
    let mut rec = skeleton(ctx, case);
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        execute(ctx, case, &mut rec)
    }));
    match outcome {
        Ok(Ok(())) => {}
        Ok(Err(e)) => rec.status = format!("error: {}", one_line(&e)),
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown cause".into());
            rec.status = format!(
                "error: internal error (a bug in structid): {}",
                one_line(&msg)
            );
        }
    }
    rec.seconds = t0.elapsed().as_secs_f64();
    rec
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

/// Whether a case file that parses is a finished case of this sweep: the record of a run that
/// got as far as writing its result. A record of another length of case list, or one that
/// says `ok` without the cost of its estimate, is not (a file written by hand, or by a
/// version that wrote records before finishing them); `--resume` runs such a case again.
fn case_is_complete(r: &CaseRecord, ctx: &Context<'_>) -> bool {
    r.case_count == ctx.case_count
        && r.case_list == ctx.case_list
        && (!r.is_ok() || r.cost.is_some())
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_line_joins_causes() {
        assert_eq!(one_line(&"a\n  caused by: b\n"), "a; caused by: b");
    }
}

//! The records and files of a refinement (`structid refine`): the estimation and validation
//! records (validation files, or the held-out end of the one data file), refine.csv and
//! refine.svg (the alternations), linear.svg, the refined model file and the files of its
//! estimate, and the summaries of the alternation and of the joint fit.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use structid_core::refine::{RefineIteration, Refinement};
use structid_core::{Data, InitialState};
use structid_io::{ModelFile, OutputGuard, Reproduction, Vars};
use structid_plot::{Chart, Series, render_chart_svg};

use crate::paths::{absolute, absolute_files, files_label, initial_state_name};
use crate::records::read_records;
use crate::{RefineOutcome, Result, WorkflowError};

/// Splits a record at sample `at`: (first part, rest).
fn split(data: &Data, at: usize) -> Result<(Data, Data)> {
    let part = |r: std::ops::Range<usize>| Data::new(data.u().slice(r.clone()), data.y().slice(r));
    Ok((part(0..at)?, part(at..data.len())?))
}

/// The estimation and validation records of a refinement, and what the report says of them.
pub struct RefineRecords {
    /// The estimation records.
    pub data: Data,
    /// The validation records, if any.
    pub validation: Option<Data>,
    /// How the report names the validation.
    pub validation_note: Option<String>,
    /// Where the estimation part is written when it was cut from the data file.
    pub estimation_file: Option<PathBuf>,
    /// How the data files are named in messages and reports.
    pub data_label: String,
}

/// Where a refinement's records come from.
pub struct RefineData<'a> {
    /// The estimation data files.
    pub data: &'a [PathBuf],
    /// The validation data files.
    pub validation_data: &'a [PathBuf],
    /// The held-out fraction of the one data file, instead of validation files.
    pub validation_fraction: Option<f64>,
    /// Leading validation samples that are not scored.
    pub settle: usize,
    /// The output directory (where a held-out estimation part is written).
    pub out: &'a Path,
    /// The signals picked from the data files.
    pub vars: Option<&'a Vars>,
}

/// The records of the data files, and the validation: validation files, or the end of the
/// one data record (a validation fraction), simulated from the start of the file.
pub fn split_records(mf: &ModelFile, a: &RefineData<'_>) -> Result<RefineRecords> {
    if let Some(f) = a.validation_fraction
        && !(f > 0.0 && f < 1.0)
    {
        return Err(WorkflowError::InvalidOption {
            option: "validation_fraction",
            value: f.to_string(),
            rule: "it must lie strictly between 0 and 1".into(),
        });
    }
    if a.validation_fraction.is_some() && a.data.len() > 1 {
        return Err(WorkflowError::UseInstead {
            options: vec!["validation_fraction", "data"],
            rule: format!(
                "a validation fraction holds out the end of one record, and {} data records were \
                 given: the held-out samples of a record do not start at rest, and each record \
                 would need its own settling; hold out whole records",
                a.data.len()
            ),
            instead: "validation_data",
        });
    }
    let data_label = files_label(a.data);
    let all = read_records(mf, a.data, a.vars)?;
    let (data, validation, validation_note, estimation_file) = match (
        a.validation_data.is_empty(),
        a.validation_fraction,
    ) {
        (false, _) => {
            let vd = read_records(mf, a.validation_data, a.vars).map_err(|e| {
                e.context(format!(
                    "the validation data files ({})",
                    files_label(a.validation_data)
                ))
            })?;
            (all, Some(vd), Some(files_label(a.validation_data)), None)
        }
        (true, Some(f)) => {
            let at = ((1.0 - f) * all.len() as f64).round() as usize;
            if at < 10 || all.len() - at <= a.settle {
                return Err(WorkflowError::InvalidOption {
                    option: "validation_fraction",
                    value: f.to_string(),
                    rule: format!(
                        "it leaves {at} estimation and {} validation samples (after {} settling \
                         ones); both parts need samples",
                        all.len() - at,
                        a.settle
                    ),
                });
            }
            // The validation record is the whole file, simulated from its start and scored
            // after the estimation part: the held-out samples do not start at rest.
            let (est, _) = split(&all, at)?;
            let note = format!(
                "the last {} samples of {} (fraction {f}), simulated from the start of the file",
                all.len() - at,
                data_label
            );
            (
                est,
                Some(all),
                Some(note),
                Some(a.out.join("estimation.csv")),
            )
        }
        (true, None) => (all, None, None, None),
    };
    Ok(RefineRecords {
        data,
        validation,
        validation_note,
        estimation_file,
        data_label,
    })
}

/// The files `structid refine` may write for the model file `mf`, in order.
pub fn refine_outputs(mf: &ModelFile) -> Vec<String> {
    [
        "model.toml",
        "refine.csv",
        "refine.svg",
        "linear.svg",
        "estimation.csv",
        "report.json",
        "estimate.json",
        "estimate.csv",
    ]
    .into_iter()
    .map(String::from)
    .chain(crate::paths::map_files(mf))
    .collect()
}

/// refine.csv (one row per alternation) and refine.svg (the estimation and validation RMS
/// against the iteration) in `out`; returns their paths.
fn write_iterations(
    out: &Path,
    guard: &mut OutputGuard,
    r: &Refinement,
    with_validation: bool,
) -> Result<(PathBuf, PathBuf)> {
    let csv_path = out.join("refine.csv");
    let n = r.iterations.len();
    let col =
        |f: &dyn Fn(&RefineIteration) -> f64| -> Vec<f64> { r.iterations.iter().map(f).collect() };
    guard.write_csv(
        &csv_path,
        &[
            "iteration",
            "cost_after_maps",
            "noise_after_maps",
            "dispersion_term",
            "cost_after_linear",
            "estimation_rms",
            "validation_rms",
            "oe_iterations",
            "seconds",
        ],
        &[
            (0..n).map(|i| i as f64).collect(),
            col(&|i| i.cost_after_maps),
            col(&|i| i.noise_after_maps),
            col(&|i| i.dispersion_term),
            col(&|i| i.cost_after_linear.unwrap_or(f64::NAN)),
            col(&|i| i.estimation_rms),
            col(&|i| i.validation_rms.unwrap_or(f64::NAN)),
            col(&|i| i.oe_iterations as f64),
            col(&|i| i.seconds),
        ],
    )?;
    let svg_path = out.join("refine.svg");
    let x: Vec<f64> = (0..n).map(|i| i as f64).collect();
    let est = col(&|i| i.estimation_rms);
    let val = col(&|i| i.validation_rms.unwrap_or(f64::NAN));
    let mut chart = Chart::new(
        "Alternating refinement",
        "iteration",
        "RMS simulation error",
    )
    .with(Series::line("estimation record", &x, &est));
    if with_validation {
        chart = chart.with(Series::line("validation record", &x, &val));
    }
    guard.write(&svg_path, render_chart_svg(&chart)?.as_bytes())?;
    Ok((csv_path, svg_path))
}

/// What `structid validate` needs to re-run the final identification of a refinement.
fn reproduction(
    data: &[PathBuf],
    initial_state: InitialState,
    model_path: &Path,
    data_file: &Path,
    r: &Refinement,
) -> Reproduction {
    Reproduction {
        model_file_absolute: absolute(model_path).display().to_string(),
        data_file_absolute: absolute(data_file).display().to_string(),
        data_files_absolute: absolute_files(data),
        beta: r.beta,
        sigma: None,
        solver_requested: "auto".into(),
        solver: r.identification.diagnostics.solver.name().to_string(),
        initial_state: initial_state_name(initial_state).into(),
        memory_limit_mib: None,
        dispersion: None,
        neighbours: None,
        tolerance: None,
        max_iterations: None,
        block_sigmas: Vec::new(),
    }
}

/// Writes the record `data` as CSV with the model file's column names.
fn write_record(guard: &mut OutputGuard, path: &Path, mf: &ModelFile, data: &Data) -> Result<()> {
    let names: Vec<String> = mf.signals.u.iter().chain(&mf.signals.y).cloned().collect();
    let mut columns: Vec<Vec<f64>> = (0..data.u().channels())
        .map(|c| data.u().channel(c))
        .collect();
    columns.extend((0..data.y().channels()).map(|c| data.y().channel(c)));
    guard.write_csv(path, &names, &columns)?;
    Ok(())
}

/// Writes a refinement as the result set `planned` in `out`: model.toml, the held-out
/// estimation part, refine.csv, refine.svg, linear.svg and the files of the estimate
/// ([`crate::estimate_files::write_estimate`]). `data` are the data files and `initial_state`
/// the refinement's, for the reproduction record. Returns the paths written.
#[allow(clippy::too_many_arguments)]
pub fn write_refinement(
    out: &Path,
    guard: &mut OutputGuard,
    planned: &[String],
    outcome: &RefineOutcome,
    records: &RefineRecords,
    data: &[PathBuf],
    initial_state: InitialState,
    no_bands: bool,
) -> Result<Vec<PathBuf>> {
    let (r, refined) = (&outcome.refinement, &outcome.refined);
    guard.begin_set(out, Some(planned))?;
    let model_path = out.join("model.toml");
    guard.write(&model_path, refined.to_toml_string().as_bytes())?;
    let data_file = match &records.estimation_file {
        Some(path) => {
            write_record(guard, path, refined, &records.data)?;
            path.clone()
        }
        None => data
            .first()
            .cloned()
            .ok_or_else(|| WorkflowError::Request("no estimation data file was given".into()))?,
    };
    let mut report = outcome.report.clone();
    report.model_file = Some(model_path.display().to_string());
    report.data_file = Some(if records.estimation_file.is_some() {
        data_file.display().to_string()
    } else {
        records.data_label.clone()
    });
    report.reproduction = Some(reproduction(
        data,
        initial_state,
        &model_path,
        &data_file,
        r,
    ));

    // The iteration table and figure.
    let (csv_path, svg_path) = write_iterations(out, guard, r, records.validation.is_some())?;
    // The alternation keeps no parameter covariance of G (its fits run through the map): the
    // figure has no band.
    let linear_path = out.join("linear.svg");
    let svg = crate::figures::linear_svg(&r.linear, None, &refined.signals.u)?;
    guard.write(&linear_path, svg.as_bytes())?;

    let mut written = crate::estimate_files::write_estimate(
        out,
        guard,
        refined,
        &r.identification,
        &outcome.estimate,
        &mut report,
        no_bands,
    )?;
    written.splice(0..0, [model_path, csv_path, svg_path, linear_path]);
    if let Some(p) = &records.estimation_file {
        written.insert(1, p.clone());
    }
    guard.finish_set(out, &structid_io::output::file_names(&written))?;
    Ok(written)
}

/// What `structid refine` prints: the alternations, the linear part and the files `written`.
pub fn refine_summary(r: &Refinement, written: &[PathBuf], seconds: f64) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "refinement: {} iteration(s), kept iteration {} ({}); β = {}",
        r.iterations.len(),
        r.best,
        r.stop_reason,
        crate::text::short(r.beta)
    );
    let _ = writeln!(
        s,
        "  it  J after maps  J after linear  estimation RMS  validation RMS"
    );
    for (i, it) in r.iterations.iter().enumerate() {
        let _ = writeln!(
            s,
            "  {i:>2}  {:>12.5e}  {:>14}  {:>14.5e}  {:>14}",
            it.cost_after_maps,
            it.cost_after_linear
                .map(|c| format!("{c:.5e}"))
                .unwrap_or_else(|| "—".into()),
            it.estimation_rms,
            it.validation_rms
                .map(|v| format!("{v:.5e}"))
                .unwrap_or_else(|| "—".into()),
        );
    }
    let den: Vec<String> = r.linear.den.iter().map(|v| format!("{v:.6}")).collect();
    let _ = writeln!(s, "linear part: den = [{}]", den.join(", "));
    for (i, b) in r.linear.num.iter().enumerate() {
        let nums: Vec<String> = b.iter().map(|v| format!("{v:.6}")).collect();
        let _ = writeln!(s, "             num[{i}] = [{}]", nums.join(", "));
    }
    let _ = writeln!(s, "wrote ({seconds:.1} s):");
    for p in written {
        let _ = writeln!(s, "  {}", p.display());
    }
    s
}

/// What `structid refine --joint` prints: the fit of the model file `model_path` (output names
/// `y_names`), the β trials and the directory `out` written.
pub fn joint_summary(
    model_path: &Path,
    y_names: &[String],
    o: &crate::JointOutcome,
    out: &Path,
    seconds: f64,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "joint fit of {} by simulation error: cost {:.4e} → {:.4e} (β = {:.1e}, {} parameters, {:.2} s)",
        model_path.display(),
        o.fit.initial_cost,
        o.fit.cost,
        o.beta,
        o.fit.model.parameters().len(),
        seconds
    );
    for (name, rms) in y_names.iter().zip(&o.fit.rms) {
        let _ = writeln!(s, "  {name}: simulation RMS {rms:.4e}");
    }
    for t in &o.trials {
        let _ = writeln!(
            s,
            "  β = {:.1e}: validation RMS {:?}",
            t.beta, t.validation_rms
        );
    }
    let _ = writeln!(
        s,
        "wrote {}/model.toml, joint.json and the map tables",
        out.display()
    );
    s
}

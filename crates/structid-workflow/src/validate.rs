//! Validation on records (`structid validate`): the true maps of a model file, or an estimate
//! rebuilt from the report of an older `structid identify` directory and checked against its
//! estimate.csv, simulated on a record with the maps in the loop, with the one-step prediction
//! errors and their correlation tests; a model without a one-step predictor by its simulation
//! alone; and several records, each on its own, pooled. (A stored estimate is validated by
//! [`crate::stored::validate_stored`].)

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use structid_core::validation::metrics::PooledFit;
use structid_core::validation::records::pool_record;
use structid_core::validation::{Scoring, ValidationReport, ValidationSettings, validate};
use structid_core::{Identification, IdentifySettings, InitialState, Interpolant, identify};
use structid_io::{DataTable, ModelFile, OutputGuard, ReportRecord, Reproduction, Vars};

use crate::estimate_files::estimate_columns;
use crate::paths::{absolute, file_names, initial_state_name, json_text, protect_inputs};
use crate::validation_files::{
    OUTPUTS, RecordScore, check_lengths, fmt_pct, outputs_json, pass, residuals_svg, scored_json,
    simulation_names, simulation_svg,
};
use crate::{Result, WorkflowError};

/// Largest relative difference (max |Δŵ| / max |ŵ| per block) between the recomputed estimate
/// and DIR/estimate.csv for the directory to count as reproduced.
pub const W_TOLERANCE: f64 = 1e-6;

/// How one record is validated.
#[derive(Clone, Debug)]
pub struct ValidationOptions {
    /// The validation record.
    pub data: PathBuf,
    /// The output directory.
    pub out: PathBuf,
    /// The initial state of the record.
    pub initial_state: InitialState,
    /// Largest lag of the correlation tests.
    pub max_lag: usize,
    /// Leading samples left out of the simulation RMS and fit.
    pub settle: usize,
    /// How the simulation is scored.
    pub scoring: Scoring,
}

impl ValidationOptions {
    /// The validation settings these options ask for.
    pub fn settings(&self) -> Result<ValidationSettings> {
        Ok(ValidationSettings::builder()
            .initial_state(self.initial_state)
            .max_lag(self.max_lag)
            .settle(self.settle)
            .scoring(self.scoring)
            .build()?)
    }
}

/// One record's validation: what it scored and the summary to print.
pub struct RecordValidation {
    /// What the record scored, with its validation.json.
    pub score: RecordScore,
    /// The summary.
    pub summary: String,
}

fn list<S: AsRef<str>>(names: &[S]) -> String {
    names
        .iter()
        .map(|n| format!("`{}`", n.as_ref()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Refuses a largest lag of zero.
pub fn check_max_lag(max_lag: usize) -> Result<()> {
    if max_lag == 0 {
        return Err(WorkflowError::InvalidOption {
            option: "max_lag",
            value: "0".into(),
            rule: "it must be at least 1".into(),
        });
    }
    Ok(())
}

/// Checks that the model file has the blocks of the estimate (same names, same number of inputs).
fn check_blocks(model: &ModelFile, model_path: &Path, record: &ReportRecord) -> Result<()> {
    let mut ours: Vec<&str> = model.blocks.iter().map(|b| b.name.as_str()).collect();
    let mut theirs: Vec<&str> = record.blocks.iter().map(|b| b.name.as_str()).collect();
    ours.sort_unstable();
    theirs.sort_unstable();
    if ours != theirs {
        return Err(WorkflowError::InvalidInput {
            input: "model",
            path: model_path.to_path_buf(),
            why: format!(
                "is not the model of the estimate: its blocks are {} but the estimate's are {}",
                list(&ours),
                list(&theirs)
            ),
        });
    }
    for b in &model.blocks {
        if let Some(r) = record.blocks.iter().find(|r| r.name == b.name)
            && r.inputs.len() != b.inputs.len()
        {
            return Err(WorkflowError::InvalidInput {
                input: "model",
                path: model_path.to_path_buf(),
                why: format!(
                    "is not the model of the estimate: block `{}` reads {} input(s) there but {} in the estimate",
                    b.name,
                    b.inputs.len(),
                    r.inputs.len()
                ),
            });
        }
    }
    Ok(())
}

/// The largest relative difference between the recomputed ŵ and DIR/estimate.csv, or an error
/// when it exceeds [`W_TOLERANCE`] or the file does not fit.
fn check_estimate(dir: &Path, mf: &ModelFile, id: &Identification) -> Result<f64> {
    let mismatch = |detail: String| {
        WorkflowError::Request(format!(
            "the estimate directory `{}` does not match its report.json: {detail}. The model or data file may \
             have changed since the identification wrote it; run the identification again",
            dir.display()
        ))
    };
    let path = dir.join("estimate.csv");
    if !path.is_file() {
        return Err(mismatch("estimate.csv is missing".into()));
    }
    let table = DataTable::read(&path)?;
    let (names, columns) = estimate_columns(mf, id);
    let mut worst = 0.0f64;
    for (name, ours) in names.iter().zip(&columns).take(id.w_hat.channels()) {
        let stored = table
            .column(name)
            .ok_or_else(|| mismatch(format!("estimate.csv has no column `{name}`")))?;
        if stored.len() != ours.len() {
            return Err(mismatch(format!(
                "estimate.csv has {} rows but the recomputed estimate has {}",
                stored.len(),
                ours.len()
            )));
        }
        let amax = |x: &[f64]| x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let scale = amax(stored).max(amax(ours));
        let diff = stored
            .iter()
            .zip(ours)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        if scale > 0.0 {
            worst = worst.max(diff / scale);
        }
    }
    if worst.is_nan() || worst > W_TOLERANCE {
        return Err(mismatch(format!(
            "re-running the identification gives ŵ with a relative difference of {worst:.2e} from estimate.csv \
             (tolerance {W_TOLERANCE:e})"
        )));
    }
    Ok(worst)
}

/// The directory of an older `structid identify` (without estimate.json), opened: its report
/// and the record of how to reproduce the estimate, and the model file to validate with.
pub struct EstimateDir {
    /// The directory.
    pub dir: PathBuf,
    /// Its report.json.
    pub report_path: PathBuf,
    /// The report.
    pub record: ReportRecord,
    /// How to reproduce the estimate.
    pub reproduction: Reproduction,
    /// The model file given to validate with (`--model`), checked to have the estimate's
    /// blocks.
    pub model: ModelFile,
}

/// Checks the estimate directory `dir` and its report, and the model file `model_path` against
/// it.
pub fn open_estimate_dir(dir: &Path, model_path: &Path) -> Result<EstimateDir> {
    if !dir.is_dir() {
        return Err(WorkflowError::InvalidInput {
            input: "estimate",
            path: dir.to_path_buf(),
            why: "does not exist or is not a directory; give the output directory of an \
                  identification"
                .into(),
        });
    }
    if !dir.join("report.json").is_file() {
        return Err(WorkflowError::Request(format!(
            "`{}` has no report.json: it is not the output directory of an identification",
            dir.display()
        )));
    }
    crate::paths::check_complete(&dir.join("report.json"))?;
    let model = ModelFile::from_path(model_path)?;
    let report_path = dir.join("report.json");
    let record = ReportRecord::read(&report_path)?;
    let reproduction = record.reproduction.clone().ok_or_else(|| {
        WorkflowError::Request(format!(
            "`{}` was written by an older structid that does not record how to reproduce the estimate; \
             run the identification again",
            report_path.display()
        ))
    })?;
    // --model must be the estimate's model.
    check_blocks(&model, model_path, &record)?;
    Ok(EstimateDir {
        dir: dir.to_path_buf(),
        report_path,
        record,
        reproduction,
        model,
    })
}

impl EstimateDir {
    /// What was being done, for errors of the rebuild.
    pub fn context(&self) -> String {
        format!(
            "re-running the identification recorded in `{}`",
            self.report_path.display()
        )
    }

    /// Refuses a rebuild whose recorded model or data files no longer exist.
    pub fn check_files(&self, model: &Path, data: &[PathBuf]) -> Result<()> {
        let files =
            std::iter::once(("model", model)).chain(data.iter().map(|d| ("data", d.as_path())));
        for (what, p) in files {
            if !p.is_file() {
                return Err(WorkflowError::Request(format!(
                    "the {what} file `{}` recorded in `{}` does not exist any more, so the estimate cannot be rebuilt",
                    p.display(),
                    self.report_path.display()
                )));
            }
        }
        Ok(())
    }

    /// The recorded identification, loaded (not run yet): its model file `model` read from
    /// `model_path` (with the widths a selection of σ chose), its data files, settings and σ.
    pub fn recorded(
        self,
        model_path: PathBuf,
        data: Vec<PathBuf>,
        settings: IdentifySettings,
        sigma: Option<f64>,
        mut model: ModelFile,
    ) -> Result<Recorded> {
        // widths chosen by `--sigma auto`, block by block
        for (name, w) in &self.reproduction.block_sigmas {
            let b = model
                .blocks
                .iter_mut()
                .find(|b| &b.name == name)
                .ok_or_else(|| {
                    WorkflowError::Request(format!(
                        "`{}` records a width for block `{name}`, which its model file does not have",
                        self.report_path.display()
                    ))
                })?;
            b.dispersion = b.dispersion.with_sigma(Some(*w));
        }
        Ok(Recorded {
            dir: self,
            model_path,
            data,
            settings,
            sigma,
            model,
        })
    }
}

/// The recorded identification of an estimate directory, loaded but not run yet.
pub struct Recorded {
    /// The directory, its report and the model file to validate with.
    pub dir: EstimateDir,
    /// The recorded model file.
    pub model_path: PathBuf,
    /// The recorded data files.
    pub data: Vec<PathBuf>,
    /// The recorded settings.
    pub settings: IdentifySettings,
    /// The recorded σ.
    pub sigma: Option<f64>,
    /// The recorded model file, read.
    pub model: ModelFile,
}

/// An estimate rebuilt from its directory and checked against it.
struct Rebuilt {
    recorded: Recorded,
    id: Identification,
    w_difference: f64,
}

/// Re-runs the recorded identification and checks it against the directory.
fn rebuild(recorded: Recorded, vars: Option<&Vars>) -> Result<Rebuilt> {
    let context = recorded.dir.context();
    let edata = crate::records::read_records(&recorded.model, &recorded.data, vars)
        .map_err(|e| e.context(context.clone()))?;
    let emodel = crate::core_model(&recorded.model, recorded.sigma, &edata)
        .map_err(|e| e.context(context.clone()))?;
    let id = identify(&emodel, &edata, &recorded.settings)
        .and_then(|id| id.converged())
        .map_err(|e| WorkflowError::from(e).context(context))?;
    let w_difference = check_estimate(&recorded.dir.dir, &recorded.model, &id)?;
    Ok(Rebuilt {
        recorded,
        id,
        w_difference,
    })
}

/// The maps a model file is validated with.
pub enum Maps {
    /// The `truth` of every block of the model file.
    Truth,
    /// The estimate of an older `structid identify` directory, rebuilt by re-running the
    /// identification it records.
    Rebuilt(Box<Recorded>),
}

/// A validation of a model file's maps on one record.
pub struct ValidateRequest<'a> {
    /// The model file.
    pub model_path: &'a Path,
    /// The maps.
    pub maps: Maps,
    /// The record and the settings.
    pub options: &'a ValidationOptions,
    /// The signals picked from the record.
    pub vars: Option<&'a Vars>,
}

/// Validates a model file's maps on one record: the files of a validation in the output
/// directory, and the summary. A model without a one-step predictor is validated by its
/// simulation alone.
pub fn validate_model_file(r: ValidateRequest<'_>) -> Result<RecordValidation> {
    let t0 = std::time::Instant::now();
    let (o, model_path) = (r.options, r.model_path);
    let mut guard = OutputGuard::new();
    let (vmf, recorded) = match r.maps {
        Maps::Rebuilt(rec) => {
            // Never overwrite an input: the files of the command, the estimate directory's
            // files and the files of the recorded identification.
            let dir = &rec.dir.dir;
            let mut others: Vec<PathBuf> = vec![
                o.data.clone(),
                rec.dir.report_path.clone(),
                dir.join("estimate.csv"),
            ];
            others.extend(rec.dir.record.files.iter().map(|f| dir.join(f)));
            let others_ref: Vec<&Path> = others.iter().map(PathBuf::as_path).collect();
            protect_inputs(&mut guard, &rec.dir.model, model_path, &others_ref);
            let recorded_data: Vec<&Path> = rec.data.iter().map(PathBuf::as_path).collect();
            protect_inputs(&mut guard, &rec.model, &rec.model_path, &recorded_data);
            (rec.dir.model.clone(), Some(*rec))
        }
        Maps::Truth => {
            let vmf = ModelFile::from_path(model_path)?;
            if let Some(why) = crate::why_simulation_only(&vmf)? {
                return simulation_only(o, &vmf, model_path, &why, r.vars);
            }
            let missing: Vec<&str> = vmf
                .blocks
                .iter()
                .filter(|b| b.truth.is_none())
                .map(|b| b.name.as_str())
                .collect();
            if !missing.is_empty() {
                return Err(WorkflowError::MissingOption {
                    option: "estimate",
                    rule: format!(
                        "without an estimate the validation checks the true maps of `{}`, but \
                         block(s) {} have no `truth`; give every block a truth (truth = \
                         \"expression in z0, z1, …\" or truth = {{ table = \"file.csv\" }}), or \
                         validate an estimate",
                        model_path.display(),
                        list(&missing)
                    ),
                });
            }
            protect_inputs(&mut guard, &vmf, model_path, &[&o.data]);
            (vmf, None)
        }
    };
    guard.check_out_dir(&o.out, OUTPUTS)?;

    // The validation record, checked before the (possibly long) re-identification.
    let table = crate::records::read_table(&o.data, r.vars)?;
    let vdata = vmf.select_data(&table)?;
    check_lengths(o.settle, o.max_lag, &o.data, &vdata)?;

    // The maps: the estimate rebuilt and checked against its directory, or the true maps.
    let rebuilt = recorded.map(|rec| rebuild(rec, r.vars)).transpose()?;
    let mut warnings = Vec::new();
    if let Some(rb) = &rebuilt
        && vmf.lft != rb.recorded.model.lft
    {
        warnings.push(format!(
            "the linear block of the model file `{}` differs from that of the estimate's model file `{}`; the maps \
             were estimated with the latter",
            model_path.display(),
            rb.recorded.model_path.display()
        ));
    }
    let report = run_validation(&vmf, rebuilt.as_ref(), &vdata, o)?;
    guard.begin_set(&o.out, Some(&OUTPUTS))?;
    let mut written = write_files(&guard, &vmf, &report, &vdata, o)?;
    let json_path = o.out.join("validation.json");
    written.push(json_path.clone());
    let doc = validation_json(
        &vmf,
        model_path,
        rebuilt.as_ref(),
        &report,
        &warnings,
        &written,
        o,
    )?;
    guard.write(&json_path, json_text(&doc)?.as_bytes())?;
    guard.finish_set(&o.out, &structid_io::output::file_names(&written))?;
    let summary = summary(
        &report,
        model_path,
        &vmf,
        o,
        rebuilt.as_ref().map(|r| &r.recorded.dir.dir as &Path),
        rebuilt.as_ref().map(|r| r.w_difference),
        &warnings,
        &written,
        t0.elapsed().as_secs_f64(),
    );
    Ok(RecordValidation {
        score: RecordScore {
            y: vdata.y().clone(),
            simulated: report.simulated,
            scored: report.scored,
            doc,
        },
        summary,
    })
}

/// The validation of `vmf` with the rebuilt estimate's maps, or its true maps, on `vdata`.
fn run_validation(
    vmf: &ModelFile,
    rebuilt: Option<&Rebuilt>,
    vdata: &structid_core::Data,
    o: &ValidationOptions,
) -> Result<ValidationReport> {
    let truth = match rebuilt {
        Some(_) => None,
        None => Some(
            vmf.truth_maps()?
                .ok_or_else(|| WorkflowError::Failed("a block has no truth map".into()))?,
        ),
    };
    // Validate: the maps are given, so dispersions (and shapes) play no part.
    let vmodel = vmf.structure_model()?;
    let maps: Vec<&dyn Interpolant> = vmodel
        .blocks()
        .iter()
        .map(|b| match (rebuilt, &truth) {
            (Some(r), _) => r.id.block(&b.name).map(|e| e.map.as_ref()).ok_or_else(|| {
                WorkflowError::Failed(format!("the estimate has no block `{}`", b.name))
            }),
            (None, Some(t)) => vmf
                .blocks
                .iter()
                .position(|s| s.name == b.name)
                .map(|i| t[i].as_ref())
                .ok_or_else(|| {
                    WorkflowError::Failed(format!("no true map for block `{}`", b.name))
                }),
            (None, None) => Err(WorkflowError::Failed("no maps to validate".into())),
        })
        .collect::<Result<_>>()?;
    Ok(validate(&vmodel, &maps, vdata, &o.settings()?)?)
}

/// simulation.csv, simulation.svg and residuals.svg of a validation; returns their paths.
fn write_files(
    guard: &OutputGuard,
    vmf: &ModelFile,
    report: &ValidationReport,
    vdata: &structid_core::Data,
    o: &ValidationOptions,
) -> Result<Vec<PathBuf>> {
    let y_names = &vmf.signals.y;
    let u_names = &vmf.signals.u;
    let (time, time_label) = crate::records::time_axis(vmf.lft.sample_time(), report.samples);
    let mut columns = vec![time.clone()];
    for c in 0..y_names.len() {
        columns.push(vdata.y().channel(c));
        columns.push(report.simulated.channel(c));
        columns.push(report.prediction_error.channel(c));
    }
    let mut written = Vec::new();
    let path = o.out.join("simulation.csv");
    guard.write_csv(&path, &simulation_names(y_names), &columns)?;
    written.push(path);
    let path = o.out.join("simulation.svg");
    let svg = simulation_svg(report, vdata.y(), &time, y_names, time_label)?;
    guard.write(&path, svg.as_bytes())?;
    written.push(path);
    let path = o.out.join("residuals.svg");
    guard.write(&path, residuals_svg(report, y_names, u_names)?.as_bytes())?;
    written.push(path);
    Ok(written)
}

/// validation.json of a model file's validation; `written` lists its files.
fn validation_json(
    vmf: &ModelFile,
    model_path: &Path,
    rebuilt: Option<&Rebuilt>,
    report: &ValidationReport,
    warnings: &[String],
    written: &[PathBuf],
    o: &ValidationOptions,
) -> Result<Value> {
    let estimate = match rebuilt {
        Some(r) => {
            let rec = &r.recorded.dir;
            json!({
                "report": rec.report_path.display().to_string(),
                "model_file": rec.reproduction.model_file_absolute,
                "data_file": rec.reproduction.data_file_absolute,
                "samples": rec.record.samples,
                "beta": rec.reproduction.beta,
                "solver": rec.reproduction.solver,
                "w_hat_max_relative_difference": r.w_difference,
                "w_hat_tolerance": W_TOLERANCE,
            })
        }
        None => Value::Null,
    };
    let estimate_dir = rebuilt.map(|r| r.recorded.dir.dir.as_path());
    let mut doc = json!({
        "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
        "inputs": {
            "model_file": model_path.display().to_string(),
            "model_file_absolute": absolute(model_path).display().to_string(),
            "estimate_dir": estimate_dir.map(|d| d.display().to_string()),
            "estimate_dir_absolute": estimate_dir.map(|d| absolute(d).display().to_string()),
            "data_file": o.data.display().to_string(),
            "data_file_absolute": absolute(&o.data).display().to_string(),
            "initial_state": initial_state_name(o.initial_state),
            "max_lag": o.max_lag,
            "settle": o.settle,
        },
        "maps": if rebuilt.is_some() { "estimate" } else { "truth" },
        "estimate": estimate,
        "samples": report.samples,
        "scored": scored_json(report),
        "sample_time": vmf.lft.sample_time(),
        "initial_state": report.initial_state,
        "outputs": outputs_json(report, &vmf.signals.y, &vmf.signals.u)?,
        "whiteness_passes": report.whiteness_passes(),
        "input_correlation_passes": report.input_correlation_passes(),
        "warnings": warnings,
        "files": file_names(written),
    });
    if rebuilt.is_none()
        && let Value::Object(m) = &mut doc
    {
        let truths: Vec<Value> = vmf
            .blocks
            .iter()
            .map(|b| json!({"name": b.name, "truth": b.truth.as_ref().map(|t| t.describe())}))
            .collect();
        m.insert("truth".into(), json!(truths));
    }
    Ok(doc)
}

/// The validation of a model without a one-step predictor (`why`): the simulation from rest
/// and its scores ([`crate::score_simulation`]); no one-step prediction.
fn simulation_only(
    o: &ValidationOptions,
    vmf: &ModelFile,
    model_path: &Path,
    why: &str,
    vars: Option<&Vars>,
) -> Result<RecordValidation> {
    if matches!(o.initial_state, InitialState::Estimate) {
        return Err(WorkflowError::InvalidOption {
            option: "initial_state",
            value: "estimate".into(),
            rule: format!(
                "`{}` has no one-step predictor ({why}): it is validated by its simulation \
                 from rest, with a zero initial state",
                model_path.display()
            ),
        });
    }
    let mut guard = OutputGuard::new();
    protect_inputs(&mut guard, vmf, model_path, &[&o.data]);
    let files = ["validation.json", "simulation.csv"];
    guard.check_out_dir(&o.out, files)?;
    let table = crate::records::read_table(&o.data, vars)?;
    let vdata = vmf.select_data(&table)?;
    let score = crate::score_simulation(vmf, &vdata, o.settle)?;
    guard.begin_set(&o.out, Some(&files))?;
    let mut names = vec!["time".to_string()];
    let mut columns = vec![(0..vdata.len()).map(|k| k as f64).collect::<Vec<f64>>()];
    for (c, n) in vmf.signals.y.iter().enumerate() {
        names.extend([
            n.clone(),
            format!("{n}_sim"),
            format!("{n}_simulation_error"),
        ]);
        let (y, s) = (vdata.y().channel(c), score.simulated.channel(c));
        columns.push(y.clone());
        columns.push(s.clone());
        columns.push(y.iter().zip(&s).map(|(a, b)| a - b).collect());
    }
    let csv = o.out.join("simulation.csv");
    guard.write_csv(&csv, &names, &columns)?;
    let outputs: Vec<Value> = vmf
        .signals
        .y
        .iter()
        .enumerate()
        .map(|(c, n)| json!({"name": n, "simulation_rms": score.rms[c], "fit_percent": score.fit_percent[c]}))
        .collect();
    let doc = json!({
        "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
        "inputs": {
            "model_file": model_path.display().to_string(),
            "data_file": o.data.display().to_string(),
            "settle": o.settle,
        },
        "maps": "truth",
        "prediction": Value::Null,
        "why_no_prediction": format!(
            "{why}: the one-step predictor and the residual tests need every block's input computable \
             from u and y (maps in series evaluated in order) and no operator; the model is validated by its simulation from rest"
        ),
        "samples": vdata.len(),
        "outputs": outputs,
        "files": files,
    });
    let json_path = o.out.join("validation.json");
    let text = serde_json::to_string_pretty(&doc)
        .map_err(|e| WorkflowError::Failed(format!("cannot serialise the report: {e}")))?;
    guard.write(&json_path, text.as_bytes())?;
    guard.finish_set(&o.out, &structid_io::output::file_names(&[csv, json_path]))?;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "validation of {} on {} by simulation from rest ({why}; no one-step prediction):",
        model_path.display(),
        o.data.display()
    );
    for (c, n) in vmf.signals.y.iter().enumerate() {
        let _ = writeln!(
            s,
            "  {n}: simulation RMS {:.4e}, fit {:.1} %",
            score.rms[c], score.fit_percent[c]
        );
    }
    let _ = writeln!(
        s,
        "wrote {}/validation.json and simulation.csv",
        o.out.display()
    );
    let scored = std::iter::once(o.settle.min(vdata.len())..vdata.len()).collect();
    Ok(RecordValidation {
        score: RecordScore {
            y: vdata.y().clone(),
            simulated: score.simulated,
            scored,
            doc,
        },
        summary: s,
    })
}

/// The directories of the records of a validation on `n` records: `record_1`, ….
pub fn record_dirs(n: usize) -> Vec<String> {
    (1..=n).map(|i| format!("record_{i}")).collect()
}

/// A validation on several records, each validated on its own, from its own initial state,
/// into `out/record_<i>/` by `one(i, file, dir)`; `out/validation.json` lists them and pools the
/// free-run simulation error (after the settling samples of each record) over all records.
/// Returns the lines to print after the records'.
pub fn validate_records<E: From<WorkflowError>>(
    data: &[PathBuf],
    out: &Path,
    settle: usize,
    mut one: impl FnMut(usize, &Path, PathBuf) -> std::result::Result<RecordScore, E>,
) -> std::result::Result<String, E> {
    let mut guard = OutputGuard::new();
    for d in data {
        guard.protect(d);
    }
    let dirs = record_dirs(data.len());
    guard
        .check_out_dir(
            out,
            dirs.iter().chain(["validation.json".to_string()].iter()),
        )
        .map_err(WorkflowError::from)?;
    let mut records = Vec::with_capacity(data.len());
    // Per output, the fit pooled over the samples each record's own validation scored (after
    // its settling samples, or its windows), so that it agrees with the records' own figures.
    let mut pooled: Vec<PooledFit> = Vec::new();
    let mut names: Vec<String> = Vec::new();
    for (i, (file, dir)) in data.iter().zip(&dirs).enumerate() {
        let r = one(i, file, out.join(dir))?;
        pool_record(&mut pooled, &r.y, &r.simulated, &r.scored);
        let doc = r.doc;
        if names.is_empty() {
            names = doc["outputs"]
                .as_array()
                .into_iter()
                .flatten()
                .map(|o| o["name"].as_str().unwrap_or_default().to_string())
                .collect();
        }
        records.push(json!({
            "record": i + 1,
            "data_file": file.display().to_string(),
            "data_file_absolute": absolute(file).display().to_string(),
            "dir": dir,
            "samples": doc["samples"],
            "initial_state": doc["initial_state"],
            "outputs": doc["outputs"],
            "whiteness_passes": doc["whiteness_passes"],
            "input_correlation_passes": doc["input_correlation_passes"],
        }));
    }
    let mut overall = Vec::new();
    let mut s = String::new();
    for (name, pool) in names.iter().zip(&pooled) {
        let (rms, fit, count) = (pool.rms(), pool.fit_percent(), pool.samples());
        overall.push(json!({
            "name": name,
            "rms": rms,
            "fit_percent": if fit.is_finite() { json!(fit) } else { Value::Null },
            "samples": count,
        }));
        let _ = writeln!(
            s,
            "all {} records, output {name}: simulation RMS {rms:.4e}, fit {} over {count} samples",
            data.len(),
            fmt_pct(fit)
        );
    }
    let doc = json!({
        "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
        "records": records,
        "overall": {
            "scoring": "each record scored as its own validation scores it (its own initial state; after its settling samples, or its windows), pooled",
            "settle": settle,
            "outputs": overall,
        },
    });
    let write = || -> Result<PathBuf> {
        let text = json_text(&doc)?;
        guard.begin_set(out, Some(&["validation.json"]))?;
        let path = out.join("validation.json");
        guard.write(&path, text.as_bytes())?;
        guard.finish_set(out, &["validation.json"])?;
        Ok(path)
    };
    let path = write()?;
    let _ = writeln!(s, "wrote {}", path.display());
    Ok(s)
}

/// What `structid validate` prints for one record of a model file.
#[allow(clippy::too_many_arguments)]
fn summary(
    report: &ValidationReport,
    model_path: &Path,
    vmf: &ModelFile,
    o: &ValidationOptions,
    estimate_dir: Option<&Path>,
    w_difference: Option<f64>,
    warnings: &[String],
    written: &[PathBuf],
    seconds: f64,
) -> String {
    let (y_names, u_names) = (&vmf.signals.y, &vmf.signals.u);
    let mut s = String::new();
    let what = match estimate_dir {
        Some(dir) => format!("the estimate in `{}`", dir.display()),
        None => format!("the true maps of `{}`", model_path.display()),
    };
    let _ = writeln!(
        s,
        "validated {what} on {} samples of `{}` ({:.2} s)",
        report.samples,
        o.data.display(),
        seconds
    );
    match w_difference {
        Some(w) => {
            let _ = writeln!(
                s,
                "estimate rebuilt from its report.json: ŵ matches estimate.csv (max relative difference {w:.1e})"
            );
        }
        None => {
            let _ = writeln!(s, "maps: the `truth` of every block (no estimate given)");
        }
    }
    match &report.initial_state {
        Some(x0) => {
            let v: Vec<String> = x0.iter().map(|v| format!("{v:.4e}")).collect();
            let _ = writeln!(s, "initial state: estimated, x₀ = [{}]", v.join(", "));
        }
        None => {
            let _ = writeln!(s, "initial state: zero (the record starts at rest)");
        }
    }
    for (c, name) in y_names.iter().enumerate() {
        write_output_scores(&mut s, report, c, name);
        for (j, u) in u_names.iter().enumerate() {
            let _ = writeln!(
                s,
                "  correlation of ε with {u}: {}",
                pass(&report.input_correlation[c][j])
            );
        }
    }
    for w in warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    let _ = writeln!(s, "wrote:");
    for p in written {
        let _ = writeln!(s, "  {}", p.display());
    }
    s
}

/// The summary lines of output `c` (named `name`): its simulation and one-step prediction
/// scores and the whiteness of its residual, as both validations print them.
pub(crate) fn write_output_scores(s: &mut String, report: &ValidationReport, c: usize, name: &str) {
    let _ = writeln!(
        s,
        "output {name}: simulation RMS {:.4e}, fit {}; one-step prediction RMS {:.4e}",
        report.rms[c],
        fmt_pct(report.fit_percent[c]),
        report.prediction_rms[c]
    );
    let _ = writeln!(s, "  whiteness of ε: {}", pass(&report.whiteness[c]));
}

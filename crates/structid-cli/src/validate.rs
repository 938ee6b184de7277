//! `structid validate`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Parser;
use serde_json::{Value, json};
use structid_core::validation::metrics::PooledFit;
use structid_core::validation::records::pool_record;
use structid_core::validation::{ValidationReport, ValidationSettings, validate};
use structid_core::{Identification, InitialState, Interpolant, identify};
use structid_io::{DataTable, ModelFile, OutputGuard, ReportRecord, Reproduction};

use crate::error::CliError;
use crate::identify::{absolute, estimate_columns, load, protect_inputs};
use crate::validation_files::{
    OUTPUTS, RecordScore, check_lengths, fmt_pct, outputs_json, pass, residuals_svg,
    simulation_names, simulation_svg,
};
use crate::{Cli, Command, IdentifyArgs, InitialStateArg, ValidateArgs};

/// Largest relative difference (max |Δŵ| / max |ŵ| per block) between the recomputed estimate
/// and DIR/estimate.csv for the directory to count as reproduced.
pub const W_TOLERANCE: f64 = 1e-6;

fn list<S: AsRef<str>>(names: &[S]) -> String {
    names
        .iter()
        .map(|n| format!("`{}`", n.as_ref()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The arguments of the identification recorded in a report, parsed like a command line so
/// that options added later take their defaults.
fn identify_args(rep: &Reproduction, dir: &Path, report: &Path) -> Result<IdentifyArgs, CliError> {
    // `flag=value`, so that no value is taken for a flag; `{:?}` is the shortest form that
    // parses back to the same f64.
    let mut argv: Vec<String> = vec![
        "structid".into(),
        "identify".into(),
        format!("--model={}", rep.model_file_absolute),
        format!("--out={}", dir.display()),
        format!("--beta={:?}", rep.beta),
        // The solver that ran, not `auto`: the automatic choice depends on the free memory.
        format!("--solver={}", rep.solver),
        format!("--initial-state={}", rep.initial_state),
    ];
    if rep.data_files_absolute.is_empty() {
        argv.push(format!("--data={}", rep.data_file_absolute));
    }
    argv.extend(
        rep.data_files_absolute
            .iter()
            .map(|f| format!("--data={f}")),
    );
    let mut opt = |flag: &str, v: Option<String>| {
        if let Some(v) = v {
            argv.push(format!("{flag}={v}"));
        }
    };
    opt("--sigma", rep.sigma.map(|v| format!("{v:?}")));
    opt(
        "--memory-limit-mib",
        rep.memory_limit_mib.map(|v| v.to_string()),
    );
    opt("--dispersion", rep.dispersion.clone());
    opt("--neighbours", rep.neighbours.map(|v| v.to_string()));
    opt("--tolerance", rep.tolerance.map(|v| format!("{v:?}")));
    opt(
        "--max-iterations",
        rep.max_iterations.map(|v| v.to_string()),
    );
    let invalid = |detail: String| {
        CliError::input(format!(
            "`{}` records identification settings that this version of structid does not accept: {detail}",
            report.display()
        ))
    };
    match Cli::try_parse_from(&argv) {
        Ok(Cli {
            command: Command::Identify(a),
            ..
        }) => Ok(a),
        Ok(_) => Err(invalid("not an identify command".into())),
        Err(e) => Err(invalid(
            e.to_string()
                .lines()
                .next()
                .unwrap_or_default()
                .trim_start_matches("error: ")
                .to_string(),
        )),
    }
}

/// Checks that `--model` has the blocks of the estimate (same names, same number of inputs).
fn check_blocks(
    model: &ModelFile,
    model_path: &Path,
    record: &ReportRecord,
) -> Result<(), CliError> {
    let mut ours: Vec<&str> = model.blocks.iter().map(|b| b.name.as_str()).collect();
    let mut theirs: Vec<&str> = record.blocks.iter().map(|b| b.name.as_str()).collect();
    ours.sort_unstable();
    theirs.sort_unstable();
    if ours != theirs {
        return Err(CliError::input(format!(
            "--model `{}` is not the model of the estimate: its blocks are {} but the estimate's are {}",
            model_path.display(),
            list(&ours),
            list(&theirs)
        )));
    }
    for b in &model.blocks {
        if let Some(r) = record.blocks.iter().find(|r| r.name == b.name)
            && r.inputs.len() != b.inputs.len()
        {
            return Err(CliError::input(format!(
                "--model `{}` is not the model of the estimate: block `{}` reads {} input(s) there but {} in the estimate",
                model_path.display(),
                b.name,
                b.inputs.len(),
                r.inputs.len()
            )));
        }
    }
    Ok(())
}

/// The largest relative difference between the recomputed ŵ and DIR/estimate.csv, or an error
/// when it exceeds [`W_TOLERANCE`] or the file does not fit.
fn check_estimate(dir: &Path, mf: &ModelFile, id: &Identification) -> Result<f64, CliError> {
    let mismatch = |detail: String| {
        CliError::input(format!(
            "the estimate directory `{}` does not match its report.json: {detail}. The model or data file may \
             have changed since `structid identify` wrote it; run `structid identify` again",
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

/// The recorded identification of `--estimate DIR`, loaded but not run yet.
struct Recorded {
    dir: PathBuf,
    report_path: PathBuf,
    record: ReportRecord,
    rep: Reproduction,
    args: IdentifyArgs,
    id_settings: structid_core::IdentifySettings,
    sigma: Option<f64>,
    model: ModelFile,
}

/// An estimate rebuilt from its directory and checked against it.
struct Rebuilt {
    recorded: Recorded,
    id: Identification,
    w_difference: f64,
}

/// Checks the estimate directory and its report, and `--model` against it; loads the
/// recorded identification.
fn recorded(dir: &Path, vmf: &ModelFile, model_path: &Path) -> Result<Recorded, CliError> {
    let report_path = dir.join("report.json");
    let record = ReportRecord::read(&report_path)?;
    let rep = record.reproduction.clone().ok_or_else(|| {
        CliError::input(format!(
            "`{}` was written by an older structid that does not record how to reproduce the estimate; \
             run `structid identify` again",
            report_path.display()
        ))
    })?;

    // --model must be the estimate's model.
    check_blocks(vmf, model_path, &record)?;

    // The recorded identification, loaded (not run yet) so that its files can be protected.
    let args = identify_args(&rep, dir, &report_path)?;
    let files =
        std::iter::once(("model", &args.model)).chain(args.data.iter().map(|d| ("data", d)));
    for (what, p) in files {
        if !p.is_file() {
            return Err(CliError::input(format!(
                "the {what} file `{}` recorded in `{}` does not exist any more, so the estimate cannot be rebuilt",
                p.display(),
                report_path.display()
            )));
        }
    }
    let context = format!(
        "re-running the identification recorded in `{}`",
        report_path.display()
    );
    let (id_settings, sigma, mut emf) = load(&args).map_err(|e| e.context(context))?;
    // widths chosen by `--sigma auto`, block by block
    for (name, w) in &rep.block_sigmas {
        let b = emf
            .blocks
            .iter_mut()
            .find(|b| &b.name == name)
            .ok_or_else(|| {
                CliError::input(format!(
                    "`{}` records a width for block `{name}`, which its model file does not have",
                    report_path.display()
                ))
            })?;
        b.dispersion = b.dispersion.with_sigma(Some(*w));
    }
    Ok(Recorded {
        dir: dir.to_path_buf(),
        report_path,
        record,
        rep,
        args,
        id_settings,
        sigma,
        model: emf,
    })
}

/// Re-runs the recorded identification and checks it against the directory.
fn rebuild(recorded: Recorded) -> Result<Rebuilt, CliError> {
    let context = format!(
        "re-running the identification recorded in `{}`",
        recorded.report_path.display()
    );
    let edata = crate::identify::read_records(&recorded.model, &recorded.args.data)
        .map_err(|e| e.context(context.clone()))?;
    let emodel = structid_workflow::core_model(&recorded.model, recorded.sigma, &edata)
        .map_err(|e| CliError::from(e).context(context.clone()))?;
    let id = identify(&emodel, &edata, &recorded.id_settings)
        .and_then(|id| id.converged())
        .map_err(|e| CliError::from(e).context(context))?;
    let w_difference = check_estimate(&recorded.dir, &recorded.model, &id)?;
    Ok(Rebuilt {
        recorded,
        id,
        w_difference,
    })
}

/// Runs `structid validate`.
pub fn run(mut a: ValidateArgs) -> Result<(), CliError> {
    // An output directory of this version carries its estimate as a file: that file is the
    // estimate, and the estimation data need not exist any more.
    if let Some(dir) = &a.estimate
        && dir.is_dir()
        && dir.join("estimate.json").is_file()
    {
        a.estimate = Some(dir.join("estimate.json"));
    }
    if a.data.len() > 1 {
        return run_records(a);
    }
    validate_record(a).map(|_| ())
}

/// `structid validate` on one record (the files of `a.out`).
fn validate_record(a: ValidateArgs) -> Result<RecordScore, CliError> {
    if let Some(p) = &a.estimate
        && p.is_file()
    {
        return crate::stored::validate(&a, p);
    }
    let model_path = a.model.clone().ok_or_else(|| {
        CliError::input(
            "--model is required, except with --estimate FILE.json (a stored estimate, which carries its model)",
        )
    })?;
    let model_path = model_path.as_path();
    let t0 = Instant::now();
    if a.max_lag == 0 {
        return Err(CliError::input(
            "invalid value 0 for --max-lag: it must be at least 1",
        ));
    }
    let mut guard = OutputGuard::new();
    let (vmf, recorded) = match &a.estimate {
        Some(dir) => {
            // The estimate directory and its report.
            if !dir.is_dir() {
                return Err(CliError::input(format!(
                    "the estimate directory `{}` does not exist or is not a directory; give the --out directory of \
                     `structid identify`",
                    dir.display()
                )));
            }
            if !dir.join("report.json").is_file() {
                return Err(CliError::input(format!(
                    "`{}` has no report.json: it is not an output directory of `structid identify`",
                    dir.display()
                )));
            }
            crate::stored::check_complete(&dir.join("report.json"))?;
            let vmf = ModelFile::from_path(model_path)?;
            let rec = recorded(dir, &vmf, model_path)?;
            // Never overwrite an input: the files of the command, the estimate directory's
            // files and the files of the recorded identification.
            let mut others: Vec<PathBuf> = vec![
                a.data[0].clone(),
                rec.report_path.clone(),
                dir.join("estimate.csv"),
            ];
            others.extend(rec.record.files.iter().map(|f| dir.join(f)));
            let others_ref: Vec<&Path> = others.iter().map(PathBuf::as_path).collect();
            protect_inputs(&mut guard, &vmf, model_path, &others_ref);
            let recorded_data: Vec<&Path> = rec.args.data.iter().map(PathBuf::as_path).collect();
            protect_inputs(&mut guard, &rec.model, &rec.args.model, &recorded_data);
            (vmf, Some(rec))
        }
        None => {
            let vmf = ModelFile::from_path(model_path)?;
            if let Some(why) = structid_workflow::why_simulation_only(&vmf)? {
                return simulation_only(&a, &vmf, model_path, &why);
            }
            let missing: Vec<&str> = vmf
                .blocks
                .iter()
                .filter(|b| b.truth.is_none())
                .map(|b| b.name.as_str())
                .collect();
            if !missing.is_empty() {
                return Err(CliError::input(format!(
                    "without --estimate, `structid validate` checks the true maps of `{}`, but block(s) {} have \
                     no `truth`; give every block a truth (truth = \"expression in z0, z1, …\" or \
                     truth = {{ table = \"file.csv\" }}), or validate an estimate with --estimate DIR",
                    model_path.display(),
                    list(&missing)
                )));
            }
            protect_inputs(&mut guard, &vmf, model_path, &[&a.data[0]]);
            (vmf, None)
        }
    };
    guard.check_out_dir(&a.out, OUTPUTS)?;

    // The validation record, checked before the (possibly long) re-identification.
    let table = crate::data::read_table(&a.data[0])?;
    let vdata = vmf.select_data(&table)?;
    check_lengths(&a, &vdata)?;

    // The maps: the estimate rebuilt and checked against its directory, or the true maps.
    let rebuilt = recorded.map(rebuild).transpose()?;
    let mut warnings = Vec::new();
    if let Some(r) = &rebuilt
        && vmf.lft != r.recorded.model.lft
    {
        warnings.push(format!(
            "the linear block of --model `{}` differs from that of the estimate's model file `{}`; the maps \
             were estimated with the latter",
            model_path.display(),
            r.recorded.args.model.display()
        ));
    }
    let truth = match &rebuilt {
        Some(_) => None,
        None => Some(
            vmf.truth_maps()?
                .ok_or_else(|| CliError::runtime("a block has no truth map"))?,
        ),
    };

    // Validate: the maps are given, so dispersions (and shapes) play no part.
    let vmodel = vmf.structure_model()?;
    let maps: Vec<&dyn Interpolant> = vmodel
        .blocks()
        .iter()
        .map(|b| match (&rebuilt, &truth) {
            (Some(r), _) => r.id.block(&b.name).map(|e| e.map.as_ref()).ok_or_else(|| {
                CliError::runtime(format!("the estimate has no block `{}`", b.name))
            }),
            (None, Some(t)) => vmf
                .blocks
                .iter()
                .position(|s| s.name == b.name)
                .map(|i| t[i].as_ref())
                .ok_or_else(|| CliError::runtime(format!("no true map for block `{}`", b.name))),
            (None, None) => Err(CliError::runtime("no maps to validate")),
        })
        .collect::<Result<_, _>>()?;
    let initial_state = match a.initial_state {
        InitialStateArg::Zero => InitialState::Zero,
        InitialStateArg::Estimate => InitialState::Estimate,
    };
    let settings = ValidationSettings::builder()
        .initial_state(initial_state)
        .max_lag(a.max_lag)
        .settle(a.settle)
        .scoring(a.scoring)
        .build()?;
    let report = validate(&vmodel, &maps, &vdata, &settings)?;

    // Outputs.
    guard.begin_set(&a.out, Some(&OUTPUTS))?;
    let y_names = vmf.signals.y.clone();
    let u_names = vmf.signals.u.clone();
    let len = report.samples;
    let (time, time_label) = match vmf.lft.sample_time() {
        Some(ts) => (
            (0..len).map(|k| k as f64 * ts).collect::<Vec<f64>>(),
            "time [s]",
        ),
        None => ((0..len).map(|k| k as f64).collect(), "sample"),
    };
    let mut columns = vec![time.clone()];
    for c in 0..y_names.len() {
        columns.push(vdata.y().channel(c));
        columns.push(report.simulated.channel(c));
        columns.push(report.prediction_error.channel(c));
    }
    let mut written = Vec::new();
    let path = a.out.join("simulation.csv");
    guard.write_csv(&path, &simulation_names(&y_names), &columns)?;
    written.push(path);
    let path = a.out.join("simulation.svg");
    let svg = simulation_svg(&report, vdata.y(), &time, &y_names, time_label)?;
    guard.write(&path, svg.as_bytes())?;
    written.push(path);
    let path = a.out.join("residuals.svg");
    guard.write(
        &path,
        residuals_svg(&report, &y_names, &u_names)?.as_bytes(),
    )?;
    written.push(path);

    let outputs = outputs_json(&report, &y_names, &u_names)?;
    let json_path = a.out.join("validation.json");
    let files: Vec<String> = written
        .iter()
        .chain(std::iter::once(&json_path))
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    let estimate = match &rebuilt {
        Some(r) => {
            let rec = &r.recorded;
            json!({
                "report": rec.report_path.display().to_string(),
                "model_file": rec.rep.model_file_absolute,
                "data_file": rec.rep.data_file_absolute,
                "samples": rec.record.samples,
                "beta": rec.rep.beta,
                "solver": rec.rep.solver,
                "w_hat_max_relative_difference": r.w_difference,
                "w_hat_tolerance": W_TOLERANCE,
            })
        }
        None => Value::Null,
    };
    let truths: Vec<Value> = match &rebuilt {
        Some(_) => Vec::new(),
        None => vmf
            .blocks
            .iter()
            .map(|b| {
                json!({
                    "name": b.name,
                    "truth": b.truth.as_ref().map(|t| t.describe()),
                })
            })
            .collect(),
    };
    let mut doc = json!({
        "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
        "inputs": {
            "model_file": model_path.display().to_string(),
            "model_file_absolute": absolute(model_path).display().to_string(),
            "estimate_dir": a.estimate.as_ref().map(|d| d.display().to_string()),
            "estimate_dir_absolute": a.estimate.as_ref().map(|d| absolute(d).display().to_string()),
            "data_file": a.data[0].display().to_string(),
            "data_file_absolute": absolute(&a.data[0]).display().to_string(),
            "initial_state": crate::identify::value_name(a.initial_state),
            "max_lag": a.max_lag,
            "settle": a.settle,
        },
        "maps": if rebuilt.is_some() { "estimate" } else { "truth" },
        "estimate": estimate,
        "samples": len,
        "scored": crate::validation_files::scored_json(&report),
        "sample_time": vmf.lft.sample_time(),
        "initial_state": report.initial_state,
        "outputs": outputs,
        "whiteness_passes": report.whiteness_passes(),
        "input_correlation_passes": report.input_correlation_passes(),
        "warnings": warnings,
        "files": files,
    });
    if rebuilt.is_none()
        && let Value::Object(m) = &mut doc
    {
        m.insert("truth".into(), json!(truths));
    }
    let mut text = serde_json::to_string_pretty(&doc)
        .map_err(|e| CliError::runtime(format!("cannot serialise the report: {e}")))?;
    text.push('\n');
    guard.write(&json_path, text.as_bytes())?;
    written.push(json_path);
    guard.finish_set(&a.out, &structid_io::output::file_names(&written))?;

    print!(
        "{}",
        summary(
            &report,
            model_path,
            &y_names,
            &u_names,
            &a,
            rebuilt.as_ref().map(|r| r.w_difference),
            &warnings,
            &written,
            t0.elapsed().as_secs_f64()
        )
    );
    Ok(RecordScore {
        y: vdata.y().clone(),
        simulated: report.simulated,
        scored: report.scored,
        doc,
    })
}

/// `structid validate` of a model without a one-step predictor (`why`): the simulation from rest
/// and its scores ([`structid_workflow::score_simulation`]); no one-step prediction.
fn simulation_only(
    a: &ValidateArgs,
    vmf: &ModelFile,
    model_path: &Path,
    why: &str,
) -> Result<RecordScore, CliError> {
    if matches!(a.initial_state, InitialStateArg::Estimate) {
        return Err(CliError::input(format!(
            "`{}` has no one-step predictor ({why}): it is validated by its simulation from \
             rest; drop --initial-state estimate",
            model_path.display()
        )));
    }
    let mut guard = OutputGuard::new();
    protect_inputs(&mut guard, vmf, model_path, &[&a.data[0]]);
    let files = ["validation.json", "simulation.csv"];
    guard.check_out_dir(&a.out, files)?;
    let table = crate::data::read_table(&a.data[0])?;
    let vdata = vmf.select_data(&table)?;
    let score = structid_workflow::score_simulation(vmf, &vdata, a.settle)?;
    guard.begin_set(&a.out, Some(&files))?;
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
    let csv = a.out.join("simulation.csv");
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
            "data_file": a.data[0].display().to_string(),
            "settle": a.settle,
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
    let json_path = a.out.join("validation.json");
    let text = serde_json::to_string_pretty(&doc)
        .map_err(|e| CliError::runtime(format!("cannot serialise the report: {e}")))?;
    guard.write(&json_path, text.as_bytes())?;
    guard.finish_set(&a.out, &structid_io::output::file_names(&[csv, json_path]))?;
    println!(
        "validation of {} on {} by simulation from rest ({why}; no one-step prediction):",
        model_path.display(),
        a.data[0].display()
    );
    for (c, n) in vmf.signals.y.iter().enumerate() {
        println!(
            "  {n}: simulation RMS {:.4e}, fit {:.1} %",
            score.rms[c], score.fit_percent[c]
        );
    }
    println!(
        "wrote {}/validation.json and simulation.csv",
        a.out.display()
    );
    let scored = std::iter::once(a.settle.min(vdata.len())..vdata.len()).collect();
    Ok(RecordScore {
        y: vdata.y().clone(),
        simulated: score.simulated,
        scored,
        doc,
    })
}

/// `structid validate` with several --data files: each record is validated on its own, from
/// its own initial state, into DIR2/record_<i>/ (the files of one record); DIR2/validation.json
/// lists them and pools the free-run simulation error (after the settling samples of each
/// record) over all records.
fn run_records(a: ValidateArgs) -> Result<(), CliError> {
    let mut guard = OutputGuard::new();
    for d in &a.data {
        guard.protect(d);
    }
    let dirs: Vec<String> = (1..=a.data.len()).map(|i| format!("record_{i}")).collect();
    guard.check_out_dir(
        &a.out,
        dirs.iter().chain(["validation.json".to_string()].iter()),
    )?;
    let mut records = Vec::with_capacity(a.data.len());
    // Per output, the fit pooled over the samples each record's own validation scored (after
    // its settling samples, or its windows), so that it agrees with the records' own figures.
    let mut pooled: Vec<PooledFit> = Vec::new();
    let mut names: Vec<String> = Vec::new();
    for (i, (file, dir)) in a.data.iter().zip(&dirs).enumerate() {
        let one = ValidateArgs {
            data: vec![file.clone()],
            out: a.out.join(dir),
            ..a.clone()
        };
        println!("record {} (`{}`):", i + 1, file.display());
        let r = validate_record(one)
            .map_err(|e| e.context(format!("record {} (`{}`)", i + 1, file.display())))?;
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
            a.data.len(),
            fmt_pct(fit)
        );
    }
    let doc = json!({
        "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
        "records": records,
        "overall": {
            "scoring": "each record scored as its own validation scores it (its own initial state; after its settling samples, or its windows), pooled",
            "settle": a.settle,
            "outputs": overall,
        },
    });
    let mut text = serde_json::to_string_pretty(&doc)
        .map_err(|e| CliError::runtime(format!("cannot serialise the report: {e}")))?;
    text.push('\n');
    guard.begin_set(&a.out, Some(&["validation.json"]))?;
    let path = a.out.join("validation.json");
    guard.write(&path, text.as_bytes())?;
    guard.finish_set(&a.out, &["validation.json"])?;
    let _ = writeln!(s, "wrote {}", path.display());
    print!("{s}");
    Ok(())
}

fn summary(
    report: &ValidationReport,
    model_path: &Path,
    y_names: &[String],
    u_names: &[String],
    a: &ValidateArgs,
    w_difference: Option<f64>,
    warnings: &[String],
    written: &[PathBuf],
    seconds: f64,
) -> String {
    let mut s = String::new();
    let what = match &a.estimate {
        Some(dir) => format!("the estimate in `{}`", dir.display()),
        None => format!("the true maps of `{}`", model_path.display()),
    };
    let _ = writeln!(
        s,
        "validated {what} on {} samples of `{}` ({:.2} s)",
        report.samples,
        a.data[0].display(),
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
            let _ = writeln!(s, "maps: the `truth` of every block (no --estimate given)");
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
        let _ = writeln!(
            s,
            "output {name}: simulation RMS {:.4e}, fit {}; one-step prediction RMS {:.4e}",
            report.rms[c],
            fmt_pct(report.fit_percent[c]),
            report.prediction_rms[c]
        );
        let _ = writeln!(s, "  whiteness of ε: {}", pass(&report.whiteness[c]));
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

#[cfg(test)]
mod tests {
    use super::*;

    fn reproduction() -> Reproduction {
        Reproduction {
            model_file_absolute: "/m.toml".into(),
            data_file_absolute: "/d.csv".into(),
            data_files_absolute: Vec::new(),
            beta: 0.1 + 0.2,
            sigma: Some(1e-7),
            solver_requested: "auto".into(),
            solver: "admm".into(),
            initial_state: "estimate".into(),
            memory_limit_mib: Some(64),
            dispersion: Some("tv".into()),
            neighbours: Some(5),
            tolerance: Some(1e-9),
            max_iterations: Some(300),
            block_sigmas: Vec::new(),
        }
    }

    #[test]
    fn recorded_settings_parse_back_exactly() {
        let rep = reproduction();
        let a = identify_args(&rep, Path::new("-odd dir"), Path::new("r.json")).unwrap();
        assert_eq!(a.beta, crate::AutoOr::Value(0.1 + 0.2));
        assert_eq!(a.sigma, Some(crate::AutoOr::Value(1e-7)));
        assert_eq!(a.out, Path::new("-odd dir"));
        assert_eq!(a.model, Path::new("/m.toml"));
        assert!(matches!(a.solver, crate::SolverArg::Admm));
        assert!(matches!(a.initial_state, InitialStateArg::Estimate));
        assert!(matches!(a.dispersion, Some(crate::DispersionArg::Tv)));
        assert_eq!(
            (
                a.memory_limit_mib,
                a.neighbours,
                a.tolerance,
                a.max_iterations
            ),
            (Some(64), Some(5), Some(1e-9), Some(300))
        );
        let bad = Reproduction {
            solver: "magic".into(),
            ..rep
        };
        let e = identify_args(&bad, Path::new("d"), Path::new("r.json"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("r.json") && e.contains("magic"), "{e}");
        assert!(!e.contains('\n'), "{e}");
    }
}

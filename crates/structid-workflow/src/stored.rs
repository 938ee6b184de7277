//! The workflows that read a stored estimate (estimate.json): its validation on a record and
//! its k-step-ahead prediction (`structid validate --estimate FILE.json`, `structid predict`;
//! its simulation is [`crate::simulate`]'s, a source of [`crate::simulate::SimulateRequest`]).
//! None of them needs the model
//! file or the estimation data: the estimate carries the linear block, the maps and the
//! channel names.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde_json::json;
use structid_core::estimate::PredictionSettings;
use structid_core::{Data, Estimate, InitialState};
use structid_io::{OutputGuard, Vars, read_estimate};

use crate::paths::{absolute, initial_state_name, json_text};
use crate::validate::{RecordValidation, ValidationOptions, write_output_scores};
use crate::validation_files::{
    OUTPUTS, RecordScore, check_lengths, fmt_pct, outputs_json, residuals_svg, scored_json,
    simulation_names, simulation_svg,
};
use crate::{Result, WorkflowError};

/// The estimate and the names of its channels (u0, u1, … / y0, … when it has none).
pub(crate) fn load(path: &Path) -> Result<(Estimate, Vec<String>, Vec<String>)> {
    crate::paths::check_complete(path)?;
    let estimate = read_estimate(path)?;
    let d = estimate.lft().dims();
    let (u, y) = match estimate.signals() {
        Some(s) => (s.u.clone(), s.y.clone()),
        None => (
            (0..d.u).map(|i| format!("u{i}")).collect(),
            (0..d.y).map(|i| format!("y{i}")).collect(),
        ),
    };
    Ok((estimate, u, y))
}

/// The record of `path` with the estimate's input and output columns.
fn record(path: &Path, u: &[String], y: &[String], vars: Option<&Vars>) -> Result<Data> {
    let table = crate::records::read_table(path, vars)?;
    let us = table
        .select(u)
        .map_err(|e| WorkflowError::from(e).context("reading the estimate's input columns"))?;
    let ys = table
        .select(y)
        .map_err(|e| WorkflowError::from(e).context("reading the estimate's output columns"))?;
    Ok(Data::new(us, ys)?)
}

/// Validates the stored estimate `path` on the record of `o` (the model file `model`, if
/// given, is only protected): the files of a validation in `o.out` and the summary.
pub fn validate_stored(
    path: &Path,
    model: Option<&Path>,
    o: &ValidationOptions,
    vars: Option<&Vars>,
) -> Result<RecordValidation> {
    let t0 = std::time::Instant::now();
    crate::validate::check_max_lag(o.max_lag)?;
    let mut guard = OutputGuard::new();
    guard.protect(path);
    guard.protect(&o.data);
    if let Some(m) = model {
        guard.protect(m);
    }
    guard.check_out_dir(&o.out, OUTPUTS)?;
    let (estimate, u_names, y_names) = load(path)?;
    let data = record(&o.data, &u_names, &y_names, vars)?;
    check_lengths(o.settle, o.max_lag, &o.data, &data)?;
    let report = estimate.validate(&data, &o.settings()?)?;

    guard.begin_set(&o.out, Some(&OUTPUTS))?;
    let len = report.samples;
    let (time, time_label) = crate::records::time_axis(estimate.lft().sample_time(), len);
    let mut columns = vec![time.clone()];
    for c in 0..y_names.len() {
        columns.push(data.y().channel(c));
        columns.push(report.simulated.channel(c));
        columns.push(report.prediction_error.channel(c));
    }
    let mut written: Vec<PathBuf> = Vec::new();
    let p = o.out.join("simulation.csv");
    guard.write_csv(&p, &simulation_names(&y_names), &columns)?;
    written.push(p);
    let p = o.out.join("simulation.svg");
    guard.write(
        &p,
        simulation_svg(&report, data.y(), &time, &y_names, time_label)?.as_bytes(),
    )?;
    written.push(p);
    let p = o.out.join("residuals.svg");
    guard.write(&p, residuals_svg(&report, &y_names, &u_names)?.as_bytes())?;
    written.push(p);
    let json_path = o.out.join("validation.json");
    let prov = estimate.provenance();
    let doc = json!({
        "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
        "inputs": {
            "estimate_file": path.display().to_string(),
            "estimate_file_absolute": absolute(path).display().to_string(),
            "data_file": o.data.display().to_string(),
            "data_file_absolute": absolute(&o.data).display().to_string(),
            "initial_state": initial_state_name(o.initial_state),
            "max_lag": o.max_lag,
            "settle": o.settle,
        },
        "maps": "stored estimate",
        "estimate": {
            "workflow": prov.workflow,
            "fitted_on": prov.fitted_on,
            "solver": prov.solver,
            "beta": prov.settings.as_ref().map(|s| s.beta()),
            "blocks": estimate.blocks().iter().map(|b| json!({"name": b.name, "dispersion": b.dispersion})).collect::<Vec<_>>(),
        },
        "samples": len,
        "scored": scored_json(&report),
        "sample_time": estimate.lft().sample_time(),
        "initial_state": report.initial_state,
        "outputs": outputs_json(&report, &y_names, &u_names)?,
        "whiteness_passes": report.whiteness_passes(),
        "input_correlation_passes": report.input_correlation_passes(),
        "warnings": Vec::<String>::new(),
        "files": ["simulation.csv", "simulation.svg", "residuals.svg", "validation.json"],
    });
    guard.write(&json_path, json_text(&doc)?.as_bytes())?;
    written.push(json_path);
    guard.finish_set(&o.out, &structid_io::output::file_names(&written))?;

    let mut s = String::new();
    let _ = writeln!(
        s,
        "validated the stored estimate `{}` on {len} samples of `{}` ({:.2} s)",
        path.display(),
        o.data.display(),
        t0.elapsed().as_secs_f64()
    );
    if let Some(x0) = &report.initial_state {
        let v: Vec<String> = x0.iter().map(|v| format!("{v:.4e}")).collect();
        let _ = writeln!(s, "initial state: estimated, x₀ = [{}]", v.join(", "));
    }
    for (c, name) in y_names.iter().enumerate() {
        write_output_scores(&mut s, &report, c, name);
    }
    let _ = writeln!(s, "wrote:");
    for p in &written {
        let _ = writeln!(s, "  {}", p.display());
    }
    Ok(RecordValidation {
        score: RecordScore {
            y: data.y().clone(),
            simulated: report.simulated,
            scored: report.scored,
            doc,
        },
        summary: s,
    })
}

/// The files of a prediction.
const PREDICT_OUTPUTS: [&str; 2] = ["prediction.csv", "prediction.json"];

/// A k-step-ahead prediction of a stored estimate on a record.
pub struct PredictRequest<'a> {
    /// The stored estimate.
    pub estimate: &'a Path,
    /// The record.
    pub data: &'a Path,
    /// The horizon k ≥ 1.
    pub horizon: usize,
    /// The output directory.
    pub out: &'a Path,
    /// The initial state of the record.
    pub initial_state: InitialState,
    /// Leading samples left out of the RMS and fit.
    pub settle: usize,
    /// The signals picked from the record.
    pub vars: Option<&'a Vars>,
}

/// Predicts the record k steps ahead with the stored estimate; writes prediction.csv and
/// prediction.json and returns the summary.
pub fn predict(r: &PredictRequest<'_>) -> Result<String> {
    let t0 = std::time::Instant::now();
    let mut guard = OutputGuard::new();
    guard.protect(r.estimate);
    guard.protect(r.data);
    guard.check_out_dir(r.out, PREDICT_OUTPUTS)?;
    let settings = PredictionSettings::builder()
        .horizon(r.horizon)
        .initial_state(r.initial_state)
        .settle(r.settle)
        .build()?;
    let (estimate, u_names, y_names) = load(r.estimate)?;
    let data = record(r.data, &u_names, &y_names, r.vars)?;
    let pred = estimate.predict(&data, &settings)?;
    guard.begin_set(r.out, Some(&PREDICT_OUTPUTS))?;
    let (time, _) = crate::records::time_axis(estimate.lft().sample_time(), data.len());
    let mut names = vec!["time".to_string()];
    let mut columns = vec![time];
    for (c, y) in y_names.iter().enumerate() {
        names.push(y.clone());
        names.push(format!("{y}_predicted"));
        columns.push(data.y().channel(c));
        columns.push(pred.predicted.channel(c));
    }
    let csv = r.out.join("prediction.csv");
    guard.write_csv(&csv, &names, &columns)?;
    let outputs: Vec<_> = y_names
        .iter()
        .enumerate()
        .map(|(c, n)| json!({"name": n, "rms": pred.rms[c], "fit_percent": pred.fit_percent[c]}))
        .collect();
    let json_path = r.out.join("prediction.json");
    let doc = json!({
        "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
        "estimate_file": r.estimate.display().to_string(),
        "data_file": r.data.display().to_string(),
        "horizon": r.horizon,
        "initial_state": pred.initial_state,
        "settle": r.settle,
        "samples": data.len(),
        "outputs": outputs,
    });
    guard.write(&json_path, json_text(&doc)?.as_bytes())?;
    guard.finish_set(r.out, &PREDICT_OUTPUTS)?;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}-step-ahead prediction of `{}` on {} samples of `{}` ({:.2} s)",
        r.horizon,
        r.estimate.display(),
        data.len(),
        r.data.display(),
        t0.elapsed().as_secs_f64()
    );
    for (c, n) in y_names.iter().enumerate() {
        let _ = writeln!(
            s,
            "output {n}: RMS {:.4e}, fit {}",
            pred.rms[c],
            fmt_pct(pred.fit_percent[c])
        );
    }
    let _ = writeln!(s, "wrote:\n  {}\n  {}", csv.display(), json_path.display());
    Ok(s)
}

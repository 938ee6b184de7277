//! The commands that read a stored estimate (estimate.json): `validate --estimate FILE.json`,
//! `simulate --estimate FILE.json` and `predict`. None of them needs the model file or the
//! estimation data: the estimate carries the linear block, the maps and the channel names.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde_json::json;
use structid_core::estimate::PredictionSettings;
use structid_core::paper::gaussian_noise;
use structid_core::validation::ValidationSettings;
use structid_core::{Data, Estimate, InitialState};
use structid_io::{OutputGuard, read_estimate};

use crate::error::CliError;
use crate::identify::absolute;
use crate::validation_files::RecordScore;
use crate::validation_files::{
    fmt_pct, outputs_json, pass, residuals_svg, simulation_names, simulation_svg,
};
use crate::{InitialStateArg, PredictArgs, SimulateArgs, ValidateArgs};

/// The estimate and the names of its channels (u0, u1, … / y0, … when it has none).
fn load(path: &Path) -> Result<(Estimate, Vec<String>, Vec<String>), CliError> {
    check_complete(path)?;
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

/// Refuses a file of a result set whose run did not finish: its directory's completion marker
/// (see [`structid_io::output`]) does not list it. Files in directories without a marker
/// (written by hand, or by an older structid) are taken as they are.
pub(crate) fn check_complete(path: &Path) -> Result<(), CliError> {
    if path.is_file() && !structid_io::output::is_complete(path) {
        let dir = path.parent().unwrap_or(Path::new("."));
        return Err(CliError::input(format!(
            "`{}` belongs to an incomplete set of results: the run that wrote it did not finish \
             (it is not listed in `{}`); run that command again",
            path.display(),
            dir.join(structid_io::output::COMPLETE_MARKER).display()
        )));
    }
    Ok(())
}

fn record(path: &Path, u: &[String], y: &[String]) -> Result<Data, CliError> {
    let table = crate::data::read_table(path)?;
    let us = table
        .select(u)
        .map_err(|e| CliError::from(e).context("reading the estimate's input columns"))?;
    let ys = table
        .select(y)
        .map_err(|e| CliError::from(e).context("reading the estimate's output columns"))?;
    Ok(Data::new(us, ys)?)
}

fn initial(a: InitialStateArg) -> InitialState {
    match a {
        InitialStateArg::Zero => InitialState::Zero,
        InitialStateArg::Estimate => InitialState::Estimate,
    }
}

fn time_axis(estimate: &Estimate, len: usize) -> (Vec<f64>, &'static str) {
    match estimate.lft().sample_time() {
        Some(ts) => ((0..len).map(|k| k as f64 * ts).collect(), "time [s]"),
        None => ((0..len).map(|k| k as f64).collect(), "sample"),
    }
}

fn write_json(guard: &OutputGuard, path: &Path, doc: &serde_json::Value) -> Result<(), CliError> {
    let mut text = serde_json::to_string_pretty(doc)
        .map_err(|e| CliError::runtime(format!("cannot serialise the report: {e}")))?;
    text.push('\n');
    guard.write(path, text.as_bytes())?;
    Ok(())
}

/// `structid validate --estimate FILE.json`.
pub fn validate(a: &ValidateArgs, path: &Path) -> Result<RecordScore, CliError> {
    let t0 = Instant::now();
    if a.max_lag == 0 {
        return Err(CliError::input(
            "invalid value 0 for --max-lag: it must be at least 1",
        ));
    }
    let mut guard = OutputGuard::new();
    guard.protect(path);
    guard.protect(&a.data[0]);
    if let Some(m) = &a.model {
        guard.protect(m);
    }
    guard.check_out_dir(&a.out, crate::validation_files::OUTPUTS)?;
    let (estimate, u_names, y_names) = load(path)?;
    let data = record(&a.data[0], &u_names, &y_names)?;
    crate::validation_files::check_lengths(a, &data)?;
    let settings = ValidationSettings::builder()
        .initial_state(initial(a.initial_state))
        .max_lag(a.max_lag)
        .settle(a.settle)
        .scoring(a.scoring)
        .build()?;
    let report = estimate.validate(&data, &settings)?;

    guard.begin_set(&a.out, Some(&crate::validation_files::OUTPUTS))?;
    let len = report.samples;
    let (time, time_label) = time_axis(&estimate, len);
    let mut columns = vec![time.clone()];
    for c in 0..y_names.len() {
        columns.push(data.y().channel(c));
        columns.push(report.simulated.channel(c));
        columns.push(report.prediction_error.channel(c));
    }
    let mut written: Vec<PathBuf> = Vec::new();
    let p = a.out.join("simulation.csv");
    guard.write_csv(&p, &simulation_names(&y_names), &columns)?;
    written.push(p);
    let p = a.out.join("simulation.svg");
    guard.write(
        &p,
        simulation_svg(&report, data.y(), &time, &y_names, time_label)?.as_bytes(),
    )?;
    written.push(p);
    let p = a.out.join("residuals.svg");
    guard.write(&p, residuals_svg(&report, &y_names, &u_names)?.as_bytes())?;
    written.push(p);
    let json_path = a.out.join("validation.json");
    let prov = estimate.provenance();
    let doc = json!({
        "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
        "inputs": {
            "estimate_file": path.display().to_string(),
            "estimate_file_absolute": absolute(path).display().to_string(),
            "data_file": a.data[0].display().to_string(),
            "data_file_absolute": absolute(&a.data[0]).display().to_string(),
            "initial_state": crate::identify::value_name(a.initial_state),
            "max_lag": a.max_lag,
            "settle": a.settle,
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
        "scored": crate::validation_files::scored_json(&report),
        "sample_time": estimate.lft().sample_time(),
        "initial_state": report.initial_state,
        "outputs": outputs_json(&report, &y_names, &u_names)?,
        "whiteness_passes": report.whiteness_passes(),
        "input_correlation_passes": report.input_correlation_passes(),
        "warnings": Vec::<String>::new(),
        "files": ["simulation.csv", "simulation.svg", "residuals.svg", "validation.json"],
    });
    write_json(&guard, &json_path, &doc)?;
    written.push(json_path);
    guard.finish_set(&a.out, &structid_io::output::file_names(&written))?;

    println!(
        "validated the stored estimate `{}` on {len} samples of `{}` ({:.2} s)",
        path.display(),
        a.data[0].display(),
        t0.elapsed().as_secs_f64()
    );
    if let Some(x0) = &report.initial_state {
        let v: Vec<String> = x0.iter().map(|v| format!("{v:.4e}")).collect();
        println!("initial state: estimated, x₀ = [{}]", v.join(", "));
    }
    for (c, name) in y_names.iter().enumerate() {
        println!(
            "output {name}: simulation RMS {:.4e}, fit {}; one-step prediction RMS {:.4e}",
            report.rms[c],
            fmt_pct(report.fit_percent[c]),
            report.prediction_rms[c]
        );
        println!("  whiteness of ε: {}", pass(&report.whiteness[c]));
    }
    println!("wrote:");
    for p in &written {
        println!("  {}", p.display());
    }
    Ok(RecordScore {
        y: data.y().clone(),
        simulated: report.simulated,
        scored: report.scored,
        doc,
    })
}

/// `structid simulate --estimate FILE.json`.
pub fn simulate(a: &SimulateArgs, path: &Path, noise_std: f64) -> Result<(), CliError> {
    let mut guard = OutputGuard::new();
    guard.protect(path);
    guard.protect(&a.input);
    guard.check_out_file(&a.out)?;
    let (estimate, u_names, y_names) = load(path)?;
    let table = crate::data::read_table(&a.input)?;
    let u = table
        .select(&u_names)
        .map_err(|e| CliError::from(e).context("reading the estimate's input columns"))?;
    let dims = estimate.lft().dims();
    let e = (noise_std > 0.0).then(|| gaussian_noise(u.len(), dims.e, noise_std, a.seed));
    let sim = estimate
        .model()
        .simulate(&estimate.maps(), &u, e.as_ref(), None)?;
    let mut names = u_names.clone();
    names.extend(y_names.iter().cloned());
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            return Err(CliError::input(format!(
                "the estimate's channel name `{n}` appears twice; cannot write distinct columns"
            )));
        }
    }
    let mut columns: Vec<Vec<f64>> = (0..dims.u).map(|c| u.channel(c)).collect();
    columns.extend((0..dims.y).map(|c| sim.y.channel(c)));
    crate::error::finite_columns(&names, &columns, noise_std)?;
    guard.write_csv(&a.out, &names, &columns)?;
    println!(
        "simulated the stored estimate `{}` on {} samples ({} noise, std {noise_std}); wrote {} with columns {}",
        path.display(),
        u.len(),
        if noise_std > 0.0 { "Gaussian" } else { "no" },
        a.out.display(),
        names.join(", ")
    );
    Ok(())
}

/// The files of `structid predict`.
const PREDICT_OUTPUTS: [&str; 2] = ["prediction.csv", "prediction.json"];

/// `structid predict`.
pub fn predict(a: PredictArgs) -> Result<(), CliError> {
    let t0 = Instant::now();
    let mut guard = OutputGuard::new();
    guard.protect(&a.estimate);
    guard.protect(&a.data);
    guard.check_out_dir(&a.out, PREDICT_OUTPUTS)?;
    let settings = PredictionSettings::builder()
        .horizon(a.horizon)
        .initial_state(initial(a.initial_state))
        .settle(a.settle)
        .build()?;
    let (estimate, u_names, y_names) = load(&a.estimate)?;
    let data = record(&a.data, &u_names, &y_names)?;
    let pred = estimate.predict(&data, &settings)?;
    guard.begin_set(&a.out, Some(&PREDICT_OUTPUTS))?;
    let (time, _) = time_axis(&estimate, data.len());
    let mut names = vec!["time".to_string()];
    let mut columns = vec![time];
    for (c, y) in y_names.iter().enumerate() {
        names.push(y.clone());
        names.push(format!("{y}_predicted"));
        columns.push(data.y().channel(c));
        columns.push(pred.predicted.channel(c));
    }
    let csv = a.out.join("prediction.csv");
    guard.write_csv(&csv, &names, &columns)?;
    let outputs: Vec<_> = y_names
        .iter()
        .enumerate()
        .map(|(c, n)| json!({"name": n, "rms": pred.rms[c], "fit_percent": pred.fit_percent[c]}))
        .collect();
    let json_path = a.out.join("prediction.json");
    write_json(
        &guard,
        &json_path,
        &json!({
            "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
            "estimate_file": a.estimate.display().to_string(),
            "data_file": a.data.display().to_string(),
            "horizon": a.horizon,
            "initial_state": pred.initial_state,
            "settle": a.settle,
            "samples": data.len(),
            "outputs": outputs,
        }),
    )?;
    guard.finish_set(&a.out, &PREDICT_OUTPUTS)?;
    println!(
        "{}-step-ahead prediction of `{}` on {} samples of `{}` ({:.2} s)",
        a.horizon,
        a.estimate.display(),
        data.len(),
        a.data.display(),
        t0.elapsed().as_secs_f64()
    );
    for (c, n) in y_names.iter().enumerate() {
        println!(
            "output {n}: RMS {:.4e}, fit {}",
            pred.rms[c],
            fmt_pct(pred.fit_percent[c])
        );
    }
    println!("wrote:\n  {}\n  {}", csv.display(), json_path.display());
    Ok(())
}

//! report.json and the summary a run prints.

use super::*;

pub(super) fn json_value<T: serde::Serialize>(v: &T) -> Result<Value, serde_json::Error> {
    serde_json::to_value(v)
}

pub(super) fn gap_json(g: &Gap, time: &TimeAxis) -> Result<Value, serde_json::Error> {
    let regions = g
        .regions
        .iter()
        .map(|r| {
            let mut v = json_value(r)?;
            if let Value::Object(m) = &mut v {
                m.insert("description".into(), json!(r.describe()));
            }
            Ok(v)
        })
        .collect::<Result<Vec<Value>, serde_json::Error>>()?;
    Ok(json!({
        "rms": g.rms,
        "prediction_rms": g.prediction_rms,
        "fit_percent": g.fit_percent,
        "noise_std": g.noise_std,
        "noise": json_value(&g.noise)?,
        "tests": g.tests.iter().map(|t| json!({
            "name": t.name,
            "statistic": t.statistic,
            "critical": t.critical,
            "lags": t.lags,
            "passes": t.passes(),
        })).collect::<Vec<_>>(),
        "windows": g.windows.iter().map(|w| json!({
            "start": w.start,
            "end": w.end,
            "time_start": time.is_time.then(|| time.at(w.start)),
            "time_end": time.is_time.then(|| time.at(w.end.saturating_sub(1))),
        })).collect::<Vec<_>>(),
        "regions": regions,
        "lattice": json_value(&g.lattice)?,
        "missing_effect": g.missing_effect,
        "verdict": g.verdict,
        "records": json_value(&g.records)?,
    }))
}

pub(super) fn parameter_json(p: &structid_discover::effects::Parameter) -> Value {
    json!({
        "name": p.name,
        "value": p.value,
        "interval": [p.interval.0, p.interval.1],
    })
}

pub(super) fn fit_json(
    fit: &EffectFit,
    validation_rms: Option<f64>,
) -> Result<Value, serde_json::Error> {
    Ok(json!({
        "name": fit.effect.name(),
        "family": json_value(&fit.effect)?,
        "expression": fit.expression,
        "parameters": fit.parameters.iter().map(parameter_json).collect::<Vec<_>>(),
        "derived": fit.derived().iter().map(parameter_json).collect::<Vec<_>>(),
        "rms": fit.rms,
        "bic": fit.bic,
        "validation_rms": validation_rms,
    }))
}

/// report.json: the discovery `d` and its context, machine-readable; `files` are the files
/// the run wrote.
///
/// # Errors
/// A part of the discovery that does not serialise (never for finite and non-finite numbers,
/// which become numbers and `null`).
pub fn json(
    d: &Discovery,
    r: &ReportContext<'_>,
    files: &[String],
) -> Result<Value, serde_json::Error> {
    let hypotheses: Vec<Value> = d
        .hypotheses
        .iter()
        .map(|h| {
            json!({
                "location": r.run.nominal.key(h.location),
                "description": r.run.nominal.describe(h.location),
                "dispersion": h.dispersion,
                "beta": h.beta,
                "sigma": h.sigma,
                "noise_term": h.noise_term,
                "dispersion_value": h.dispersion_value,
                "estimation_rms": h.estimation_rms,
                "validation_rms": h.validation_rms,
                "seconds": h.seconds,
                "failure": h.failure,
            })
        })
        .collect();
    let finding = match &d.finding {
        None => Value::Null,
        Some(f) => {
            let (kind, named) = match &f.classification {
                Classification::Named(fit) => (
                    "named",
                    fit_json(fit, Some(f.augmented.validation_gap.rms))?,
                ),
                Classification::Unnamed => ("unnamed", Value::Null),
                Classification::Dynamic => ("dynamic", Value::Null),
                Classification::TimeVarying(fit) => ("time-varying", fit_json(fit, None)?),
            };
            let families = f
                .naming
                .ranked
                .iter()
                .enumerate()
                .map(|(i, fit)| fit_json(fit, f.family_rms.get(i).copied().flatten()))
                .collect::<Result<Vec<Value>, serde_json::Error>>()?;
            let curve = Some(json_value(&f.hypothesis.curve)?);
            let map = match &f.augmented.map {
                AugmentedMap::Expression(x) => json!({ "expression": x }),
                AugmentedMap::Table { z, .. } => {
                    json!({ "table": table_name(r, f), "points": z.len() })
                }
            };
            json!({
                "location": r.run.nominal.key(f.location),
                "description": r.run.nominal.describe(f.location),
                "equivalent_locations": f.equivalent_locations.iter().map(|l| r.run.nominal.key(*l)).collect::<Vec<_>>(),
                "classification": { "kind": kind, "description": f.effect() },
                "named_effect": named,
                "estimator": f.estimator,
                "nonparametric_validation_rms": f.nonparametric_rms,
                "total_variation_validation_rms": f.total_variation_rms,
                "families": families,
                "candidate_table": json_value(&f.table)?,
                "stationarity": json_value(&f.stationarity)?,
                "poor_model": f.poor_model,
                "selection": json_value(&f.selection)?,
                "direction": json_value(&f.direction)?,
                "input_hysteresis": json_value(&f.input_hysteresis)?,
                "remarks": f.remarks,
                "map": map,
                "curve": curve,
                "gap_after": {
                    "estimation": gap_json(&f.augmented.estimation_gap, &r.run.estimation.time)?,
                    "validation": gap_json(&f.augmented.validation_gap, &r.run.validation.time)?,
                },
                "shrink": f.shrink,
            })
        }
    };
    let augmented = match (r.augmented, &d.finding) {
        (Some(w), Some(f)) => json!({
            "model_file": "augmented.toml",
            "form": w.form,
            "table_file": w.table.as_ref().map(|t| t.name.as_str()),
            "block": block_name(f),
            "initial_state": initial_state_name(w.initial_state),
            "estimate_file": ESTIMATE_FILE,
            "validation_rms": f.augmented.validation_gap.rms,
            "nominal_refinement": f.nominal_refinement,
            "reproduce": validate_command(r, w, d.scoring),
            "reproduce_estimate": validate_estimate_command(r, w, d.scoring),
            "reestimate": identify_command(r, f),
        }),
        _ => Value::Null,
    };
    let s = r.run.settings;
    Ok(json!({
        "tool": format!("structid {}", r.version),
        "version": r.version,
        "command": r.run.command,
        "inputs": {
            "model_file": r.run.model_path.display().to_string(),
            "model_file_absolute": absolute(r.run.model_path).display().to_string(),
            "data_file": r.run.estimation.path.display().to_string(),
            "data_file_absolute": absolute(&r.run.estimation.path).display().to_string(),
            "validation_file": r.run.validation.path.display().to_string(),
            "validation_file_absolute": absolute(&r.run.validation.path).display().to_string(),
            "data_files": r.run.estimation.paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "validation_files": r.run.validation.paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "estimation_samples": r.run.estimation.data.len(),
            "validation_samples": r.run.validation.data.len(),
            "sample_time": r.run.model.lft.sample_time(),
        },
        "settings": {
            "locations": s.locations().map(|l| l.iter().map(|l| r.run.nominal.key(*l)).collect::<Vec<_>>()),
            "total_variation": s.total_variation(),
            "settle": s.settle(),
            "sigma_fraction": s.sigma_fraction(),
            "trend_degree": s.trend_degree(),
            "tune_sigma": s.tune_sigma(),
            "significance": s.significance(),
            "hysteresis_threshold": s.hysteresis_threshold(),
            "band": s.gap().band,
            "noise_ratio": s.gap().noise_ratio,
            "max_lag": r.max_lag,
        },
        "verdict": d.verdict,
        "verdict_kind": d.verdict_kind,
        "missing_effect": d.missing_effect,
        "scoring": d.scoring.describe(),
        "input_noise_ratio": d.input_noise,
        "noise": json_value(&d.noise)?,
        "linear_rival": json_value(&d.linear_rival)?,
        "seconds": d.seconds,
        "gap_before": {
            "estimation": gap_json(&d.estimation_gap, &r.run.estimation.time)?,
            "validation": gap_json(&d.validation_gap, &r.run.validation.time)?,
        },
        "hypotheses": hypotheses,
        "finding": finding,
        "augmented": augmented,
        "files": files,
    }))
}

/// The summary printed after a run: the verdict, the effect and the shrink, the files
/// `written` and those `removed` (outputs of an earlier run), and the wall-clock `seconds`.
pub fn summary(
    d: &Discovery,
    r: &ReportContext<'_>,
    written: &[PathBuf],
    removed: &[PathBuf],
    seconds: f64,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "discovery on {} ({} samples) and {} ({} samples), {:.1} s",
        r.run.estimation.names(),
        r.run.estimation.data.len(),
        r.run.validation.names(),
        r.run.validation.data.len(),
        seconds
    );
    let _ = writeln!(s, "verdict: {}", d.verdict);
    if let Some(f) = &d.finding {
        let _ = writeln!(
            s,
            "best location: {} (of {} hypotheses)",
            location_text(r.run.nominal, f.location),
            d.hypotheses.len()
        );
        match &f.classification {
            Classification::Named(fit) => {
                let _ = writeln!(
                    s,
                    "effect: {} ({}): N(z) = {}",
                    fit.effect.name(),
                    fit.parameters
                        .iter()
                        .chain(&fit.derived())
                        .map(|p| format!("{} = {}", p.name, g4(p.value)))
                        .collect::<Vec<_>>()
                        .join(", "),
                    fit.expression
                );
            }
            other => match &f.input_hysteresis {
                Some(h) => {
                    let _ = writeln!(
                        s,
                        "effect: {}: {}, with G re-estimated, validation RMS {} (the model files \
                         hold its static approximation)",
                        other.describe(),
                        h.describe(),
                        e(h.validation_rms)
                    );
                }
                None => {
                    let _ = writeln!(s, "effect: {} (map kept as a table)", other.describe());
                }
            },
        }
        let (rms, fit) = validation_change(d, f);
        let _ = writeln!(s, "validation RMS: {rms}, fit {fit}");
        if let Some(w) = r.augmented {
            let _ = writeln!(
                s,
                "augmented model: augmented.toml ({}) and {ESTIMATE_FILE}",
                w.form
            );
        }
    } else {
        let _ = writeln!(
            s,
            "validation RMS {} (fit {}), noise level σ̂ = {}",
            e(d.validation_gap.rms),
            pct(d.validation_gap.fit_percent),
            e(d.noise.std)
        );
    }
    let _ = writeln!(s, "wrote:");
    for p in written {
        let _ = writeln!(s, "  {}", p.display());
    }
    for p in removed {
        let _ = writeln!(s, "removed (from an earlier run): {}", p.display());
    }
    s
}

/// `p` made absolute (canonical when it exists), for reports that outlive the working
/// directory.
pub(super) fn absolute(p: &Path) -> PathBuf {
    std::fs::canonicalize(p)
        .or_else(|_| std::path::absolute(p))
        .unwrap_or_else(|_| p.to_path_buf())
}

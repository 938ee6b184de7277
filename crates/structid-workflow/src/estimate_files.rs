//! The files of an estimate (`structid identify`, `structid refine`): estimate.json,
//! estimate.csv, a table and a figure per block, and report.json listing them.

use std::path::{Path, PathBuf};

use structid_core::Identification;
use structid_core::estimate::{Estimate, SignalNames};
use structid_io::{ModelFile, OutputGuard, Report, estimate_json};

use crate::figures::{MapGrid, map_svg, partial_residuals};
use crate::paths::{file_names, file_stems};
use crate::{Result, WorkflowError};

/// Writes the files of an estimate into `out` (created): estimate.json (the fitted model,
/// self-contained: `validate`, `simulate` and `predict` read it without the data),
/// estimate.csv, `map_<block>.csv` and `map_<block>.svg` per block (with the posterior band unless
/// `no_bands`), and report.json, whose `files` list they fill. Returns the paths written,
/// report.json last.
pub fn write_estimate(
    out: &Path,
    guard: &mut OutputGuard,
    mf: &ModelFile,
    id: &Identification,
    stored: &Estimate,
    report: &mut Report,
    no_bands: bool,
) -> Result<Vec<PathBuf>> {
    let mut written: Vec<PathBuf> = Vec::new();

    let stored = stored.clone().with_signal_names(SignalNames {
        u: mf.signals.u.clone(),
        y: mf.signals.y.clone(),
    })?;
    let path = out.join("estimate.json");
    guard.write(&path, &estimate_json(&stored)?)?;
    written.push(path);

    // estimate.csv: ŵ by block name (in w order), then ê.
    let (names, columns) = estimate_columns(mf, id);
    let path = out.join("estimate.csv");
    guard.write_csv(&path, &names, &columns)?;
    written.push(path);

    // Per-block grids and figures.
    let stems = file_stems(mf.blocks.iter().map(|b| b.name.as_str()));
    let z_names = mf.z_names();
    for (bi, est) in id.blocks.iter().enumerate() {
        let i = mf
            .blocks
            .iter()
            .position(|b| b.name == est.name)
            .ok_or_else(|| {
                WorkflowError::Failed(format!(
                    "block `{}` is missing from the model file",
                    est.name
                ))
            })?;
        let (spec, stem) = (&mf.blocks[i], &stems[i]);
        let input_names = grid_input_names(&z_names, &spec.inputs, mf.signals.z.is_some());
        let grid = MapGrid::new(est.map.as_ref(), &est.z);
        // Posterior standard deviation at the grid (or data) points, when a posterior was kept.
        let std = if no_bands {
            None
        } else {
            id.posterior_std(bi, &grid.points(&est.z))?
        };
        let mut header = input_names.clone();
        header.push("value".into());
        if std.is_some() {
            header.push("std".into());
        }
        let grid_path = out.join(format!("map_{stem}.csv"));
        guard.write_csv(&grid_path, &header, &grid.columns(est, std.as_deref()))?;
        let truth = spec.truth_map()?;
        let partial = partial_residuals(&mf.lft, id, est.output);
        let svg = map_svg(
            est,
            &grid,
            truth.as_deref(),
            &input_names,
            std.as_deref(),
            partial.as_deref(),
        )?;
        let svg_path = out.join(format!("map_{stem}.svg"));
        guard.write(&svg_path, svg.as_bytes())?;
        if let Some(b) = report.block_mut(&est.name) {
            b.grid_file = Some(format!("map_{stem}.csv"));
            b.plot_file = Some(format!("map_{stem}.svg"));
            b.band = std.is_some();
        }
        written.push(grid_path);
        written.push(svg_path);
    }
    let report_path = out.join("report.json");
    written.push(report_path.clone());
    report.files = file_names(&written);
    written.pop();
    guard.write(&report_path, report.to_json_string()?.as_bytes())?;
    written.push(report_path);
    Ok(written)
}

/// Names for the inputs of a block in its grid file: the measured z column names, or the
/// block-local `z0, z1, …` of truth expressions.
fn grid_input_names(z_names: &[String], inputs: &[usize], measured: bool) -> Vec<String> {
    let local = || {
        (0..inputs.len())
            .map(|i| format!("z{i}"))
            .collect::<Vec<_>>()
    };
    if !measured {
        return local();
    }
    let names: Vec<String> = inputs
        .iter()
        .map(|&i| z_names.get(i).cloned().unwrap_or_default())
        .collect();
    if names.iter().any(|n| n.is_empty() || n == "value") {
        local()
    } else {
        names
    }
}

/// Columns of estimate.csv: one ŵ column per w channel named after its block, then the
/// estimated noise `e0, e1, …` (`e_hat0, …` if a block is called `e0`, …).
pub fn estimate_columns(mf: &ModelFile, id: &Identification) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut names = Vec::new();
    let mut columns = Vec::new();
    for c in 0..id.w_hat.channels() {
        let name = mf
            .blocks
            .iter()
            .find(|b| b.output == c)
            .map_or_else(|| format!("w{c}"), |b| b.name.clone());
        names.push(name);
        columns.push(id.w_hat.channel(c));
    }
    let ne = id.e_hat.channels();
    let prefix = if (0..ne).any(|i| names.contains(&format!("e{i}"))) {
        "e_hat"
    } else {
        "e"
    };
    for i in 0..ne {
        names.push(format!("{prefix}{i}"));
        columns.push(id.e_hat.channel(i));
    }
    (names, columns)
}

/// The files `structid identify` writes for the model file `mf`, in order.
pub fn identify_outputs(mf: &ModelFile) -> Vec<String> {
    ["estimate.csv", "estimate.json", "report.json"]
        .into_iter()
        .map(String::from)
        .chain(crate::paths::map_files(mf))
        .collect()
}

/// The widths selected for the blocks by a selection of σ, by block name, for the report's
/// reproduction record.
pub fn selected_widths(outcome: &crate::IdentifyOutcome) -> Vec<(String, f64)> {
    outcome
        .model
        .blocks()
        .iter()
        .zip(&outcome.widths)
        .filter_map(|(b, w)| w.map(|w| (b.name.clone(), w)))
        .collect()
}

/// Writes an identification as the result set `planned` in `out`: the outcome's report, named
/// `data_label` and carrying `reproduction`, and the files of [`write_estimate`]. Returns the
/// paths written.
#[allow(clippy::too_many_arguments)]
pub fn write_identification(
    out: &Path,
    guard: &mut OutputGuard,
    planned: &[String],
    mf: &ModelFile,
    outcome: &crate::IdentifyOutcome,
    data_label: String,
    reproduction: structid_io::Reproduction,
    no_bands: bool,
) -> Result<(Report, Vec<PathBuf>)> {
    guard.begin_set(out, Some(planned))?;
    let mut report = outcome.report.clone();
    report.data_file = Some(data_label);
    report.reproduction = Some(reproduction);
    let written = write_estimate(
        out,
        guard,
        mf,
        &outcome.identification,
        &outcome.estimate,
        &mut report,
        no_bands,
    )?;
    guard.finish_set(out, &structid_io::output::file_names(&written))?;
    Ok((report, written))
}

/// The failure of an identification whose iterate stopped at a limit (`error`), written all the
/// same to `out`.
pub fn not_converged(
    error: impl std::fmt::Display,
    out: &Path,
    id: &Identification,
) -> WorkflowError {
    WorkflowError::Failed(format!(
        "{error}; the last iterate was written to `{}`, marked as not converged (report.json: \
         diagnostics.status = {})",
        out.display(),
        serde_json::to_string(&id.diagnostics.status).unwrap_or_default()
    ))
}

/// A number as the identification summary prints it.
fn fmt_num(v: f64) -> String {
    if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// What `structid identify` prints: the identification, its selection, cost, solver,
/// uncertainty, per-block errors against the truth, warnings and the files `written`.
pub fn identify_summary(
    report: &Report,
    id: &Identification,
    written: &[PathBuf],
    seconds: f64,
) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let d = &id.diagnostics;
    let _ = writeln!(
        s,
        "identified {} block(s) from {} samples with β = {} ({} solver, {:.2} s)",
        id.blocks.len(),
        report.samples,
        crate::text::short(report.settings.beta),
        d.solver,
        seconds
    );
    if let Some(sel) = &report.selection {
        let _ = writeln!(
            s,
            "selected β = {:.4e}{} by {} ({} trials): {}",
            sel.beta,
            sel.sigma
                .map(|v| format!(", σ = {v:.4}"))
                .unwrap_or_default(),
            sel.criterion_description,
            sel.curve.len(),
            sel.method
        );
    }
    let disp: Vec<String> = id
        .blocks
        .iter()
        .zip(&id.cost.dispersions)
        .map(|(b, v)| format!("D_{} = {}", b.name, fmt_num(*v)))
        .collect();
    let _ = writeln!(
        s,
        "cost: J = {} = noise (1/L)·Σ|ê|² {} + β·ΣD ({})",
        fmt_num(id.cost.total),
        fmt_num(id.cost.noise),
        disp.join(", ")
    );
    let _ = writeln!(s, "solver: {} ({})", d.solver, d.solver_reason);
    if let (Some(p), Some(q)) = (d.primal_residual, d.dual_residual) {
        let _ = writeln!(
            s,
            "  {} iterations, primal residual {:.2e}, dual residual {:.2e}",
            d.iterations, p, q
        );
    }
    let _ = writeln!(s, "z: {}", id.z_source.describe());
    if let Some(p) = &id.posterior {
        let with: Vec<&str> = report
            .blocks
            .iter()
            .filter(|b| b.band)
            .map(|b| b.name.as_str())
            .collect();
        if !with.is_empty() {
            let _ = writeln!(
                s,
                "uncertainty: noise variance ŝ² = {} (profiled marginal likelihood); 95 % bands N̂ ± 1.96·std for {} \
                 (column `std` of the map files)",
                fmt_num(p.noise_variance()),
                with.join(", ")
            );
        }
    }
    for b in &report.blocks {
        let _ = write!(s, "  {}: {}", b.name, b.dispersion);
        if let (Some(r), Some(c)) = (b.rms_error_vs_truth, b.centred_rms_error_vs_truth) {
            let _ = write!(
                s,
                ", RMS error vs truth {} (centred {})",
                fmt_num(r),
                fmt_num(c)
            );
        }
        s.push('\n');
    }
    if !id.cost.total.is_finite() {
        let _ = writeln!(
            s,
            "warning: the cost is not finite; the data are probably badly scaled (rescale u and y)"
        );
    }
    if d.feasibility_residual > 1e-6 {
        let _ = writeln!(
            s,
            "warning: relative feasibility residual {:.2e}",
            d.feasibility_residual
        );
    }
    for w in &d.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    let _ = writeln!(s, "wrote:");
    for p in written {
        let _ = writeln!(s, "  {}", p.display());
    }
    s
}

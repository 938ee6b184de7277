//! `structid identify`.

use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use structid_core::estimate::{Estimate, SignalNames};
use structid_io::estimate_json;

use structid_core::selection::Criterion;
use structid_core::{Data, Identification, IdentifySettings, InitialState, SolverChoice};
use structid_io::{DispersionSpec, ModelFile, OutputGuard, Report, Reproduction, TruthSpec};
use structid_workflow::{IdentifyRequest, SolveOptions, identify_model_file};

use crate::IdentifyArgs;
use crate::error::{CliError, positive};
use crate::figures::{MapGrid, map_svg, partial_residuals};

/// A file-name-safe form of a block name: letters, digits, `_`, `-` and `.` are kept, anything
/// else becomes `_`; names that collide get a numeric suffix.
pub fn file_stems<'a>(names: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let mut seen = HashSet::new();
    let mut out = Vec::new();
    for name in names {
        let mut s: String = name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        if s.starts_with('.') {
            s.insert(0, '_');
        }
        let mut candidate = s.clone();
        let mut i = 2;
        while !seen.insert(candidate.to_lowercase()) {
            candidate = format!("{s}_{i}");
            i += 1;
        }
        out.push(candidate);
    }
    out
}

/// Protects the model file, the data file and the model's truth tables.
pub fn protect_inputs(
    guard: &mut OutputGuard,
    model: &ModelFile,
    model_path: &Path,
    others: &[&Path],
) {
    guard.protect(model_path);
    for p in others {
        guard.protect(p);
    }
    let base = model_path
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default();
    for b in &model.blocks {
        if let Some(TruthSpec::Table { file, .. }) = &b.truth {
            guard.protect(&base.join(file));
        }
    }
}

/// Builds the settings from the command line.
fn settings(a: &IdentifyArgs) -> Result<IdentifySettings, CliError> {
    Ok(SolveOptions {
        beta: match a.beta {
            crate::AutoOr::Value(b) => Some(b),
            crate::AutoOr::Auto => None,
        },
        // Bands for quadratic dispersions (the exact and feature solvers keep their factor).
        bands: !a.no_bands,
        initial_state: match a.initial_state {
            crate::InitialStateArg::Zero => InitialState::Zero,
            crate::InitialStateArg::Estimate => InitialState::Estimate,
        },
        solver: match a.solver {
            crate::SolverArg::Auto => SolverChoice::Auto,
            crate::SolverArg::Exact => SolverChoice::Exact,
            crate::SolverArg::Features => SolverChoice::Features,
            crate::SolverArg::Clarabel => SolverChoice::Clarabel,
            crate::SolverArg::Admm => SolverChoice::Admm,
        },
        tolerance: a.tolerance,
        max_iterations: a.max_iterations,
        memory_limit_mib: a.memory_limit_mib,
    }
    .settings()?)
}

/// Applies `--dispersion` and `--neighbours` to every block.
fn override_dispersions(mf: &mut ModelFile, a: &IdentifyArgs) -> Result<(), CliError> {
    if let Some(k) = a.neighbours
        && !(1..=structid_core::TotalVariation::MAX_NEIGHBOURS).contains(&k)
    {
        return Err(CliError::input(format!(
            "invalid value {k} for --neighbours: the nearest-neighbour graph needs 1 ≤ k ≤ {}",
            structid_core::TotalVariation::MAX_NEIGHBOURS
        )));
    }
    let Some(kind) = a.dispersion else {
        if a.neighbours.is_some()
            && !mf
                .blocks
                .iter()
                .any(|b| matches!(b.dispersion, DispersionSpec::TotalVariation { .. }))
        {
            return Err(CliError::input(
                "--neighbours applies to total-variation blocks; add --dispersion tv or use kind = \"tv\" in the model file",
            ));
        }
        for b in &mut mf.blocks {
            if let DispersionSpec::TotalVariation { neighbours, .. } = &mut b.dispersion
                && a.neighbours.is_some()
            {
                *neighbours = a.neighbours;
            }
        }
        return Ok(());
    };
    if a.neighbours.is_some() && !matches!(kind, crate::DispersionArg::Tv) {
        return Err(CliError::input(
            "--neighbours applies to --dispersion tv only",
        ));
    }
    let spec = match kind {
        crate::DispersionArg::Gaussian => DispersionSpec::Gaussian { sigma: None },
        crate::DispersionArg::GaussianLowrank => DispersionSpec::LowRankGaussian {
            sigma: None,
            tolerance: None,
        },
        crate::DispersionArg::Fourier => DispersionSpec::Fourier {
            sigma: None,
            harmonics: None,
            additive: false,
        },
        crate::DispersionArg::Tv => DispersionSpec::TotalVariation {
            neighbours: a.neighbours,
            interpolation: None,
        },
    };
    // The file's σ is kept: shared with `structid compare`, which swaps dispersions the same way.
    mf.replace_dispersions(&spec);
    Ok(())
}

fn fmt_num(v: f64) -> String {
    if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// The settings, the σ override and the model file (with `--dispersion` and `--neighbours`
/// applied) of an identification, from its arguments.
pub(crate) fn load(
    a: &IdentifyArgs,
) -> Result<(IdentifySettings, Option<f64>, ModelFile), CliError> {
    let settings = settings(a)?;
    let sigma = match a.sigma {
        Some(crate::AutoOr::Value(s)) => Some(positive("--sigma", s)?),
        _ => None,
    };
    let mut mf = ModelFile::from_path(&a.model)?;
    override_dispersions(&mut mf, a)?;
    Ok((settings, sigma, mf))
}

/// The records of the data files, one per file, as the signals the model file's `[signals]`
/// names; several files are several records of one [`Data`].
pub(crate) fn read_records(mf: &ModelFile, paths: &[PathBuf]) -> Result<Data, CliError> {
    let mut records = Vec::with_capacity(paths.len());
    let order = mf.lft.dims().states;
    for (i, p) in paths.iter().enumerate() {
        let table = crate::data::read_table(p)?;
        let data = mf.select_data(&table)?;
        // Checked here too (identification checks it) to name the file.
        if paths.len() > 1 && data.len() < order {
            return Err(CliError::from(structid_core::Error::RecordTooShort {
                record: i + 1,
                len: data.len(),
                order,
            })
            .context(format!("data file `{}`", p.display())));
        }
        records.push(data);
    }
    Data::from_records(records).map_err(|e| {
        let files: Vec<String> = paths
            .iter()
            .enumerate()
            .map(|(i, p)| format!("record {} = `{}`", i + 1, p.display()))
            .collect();
        CliError::from(e).context(format!("the --data files ({})", files.join(", ")))
    })
}

/// The data files for messages: `a.csv`, or `a.csv, b.csv`.
pub(crate) fn files_label(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The absolute paths of several data files for a report, or none for one file (which
/// `data_file_absolute` names).
pub(crate) fn absolute_files(paths: &[PathBuf]) -> Vec<String> {
    if paths.len() > 1 {
        paths
            .iter()
            .map(|p| absolute(p).display().to_string())
            .collect()
    } else {
        Vec::new()
    }
}

/// An absolute, canonical form of an existing path (absolute but not canonical when it cannot
/// be resolved), for reports that must not depend on the working directory.
pub(crate) fn absolute(p: &Path) -> PathBuf {
    std::fs::canonicalize(p)
        .or_else(|_| std::path::absolute(p))
        .unwrap_or_else(|_| p.to_path_buf())
}

/// The name of a command-line value, as `clap` parses it back.
pub(crate) fn value_name(v: impl clap::ValueEnum) -> String {
    v.to_possible_value()
        .map(|p| p.get_name().to_string())
        .unwrap_or_default()
}

/// What `structid validate` needs to re-run this identification exactly.
/// `beta` and `sigma` are the values used (chosen ones after `auto`), so that the rerun is a
/// fixed-value identification.
fn reproduction(
    a: &IdentifyArgs,
    id: &Identification,
    beta: f64,
    sigma: Option<f64>,
) -> Reproduction {
    Reproduction {
        model_file_absolute: absolute(&a.model).display().to_string(),
        data_file_absolute: absolute(&a.data[0]).display().to_string(),
        data_files_absolute: absolute_files(&a.data),
        beta,
        sigma,
        solver_requested: value_name(a.solver),
        // `features (m = 63)` → `features`
        solver: id.diagnostics.solver.name().to_string(),
        initial_state: value_name(a.initial_state),
        memory_limit_mib: a.memory_limit_mib,
        dispersion: a.dispersion.map(value_name),
        neighbours: a.neighbours,
        tolerance: a.tolerance,
        max_iterations: a.max_iterations,
        block_sigmas: Vec::new(),
    }
}

/// Records longer than this show a spinner while they are identified (the exact solver is
/// cubic in the length and takes minutes beyond it).
const LONG_SOLVE_SAMPLES: usize = 5000;

/// Runs `structid identify`.
pub fn run(a: IdentifyArgs) -> Result<(), CliError> {
    let t0 = Instant::now();
    let (settings, sigma, mf) = load(&a)?;
    let cannot =
        |e| CliError::from(e).context(format!("cannot identify with `{}`", a.model.display()));
    // A block whose z the data do not give (latent, or behind another map) is the joint fit's:
    // the error's hint says so, before any data are read.
    structid_workflow::identify::check_identifiable(&mf).map_err(cannot)?;
    let auto_sigma = a.sigma == Some(crate::AutoOr::Auto);
    let auto_beta = a.beta == crate::AutoOr::Auto;
    if a.folds < 2 && a.selection == Some(crate::SelectionArg::Cv) {
        return Err(CliError::input("--folds must be at least 2"));
    }
    if a.validation_data.is_some() != (a.selection == Some(crate::SelectionArg::Validation)) {
        return Err(CliError::input(
            "--selection validation and --validation-data V.csv go together",
        ));
    }
    if a.selection.is_some() && !(auto_beta || auto_sigma) {
        return Err(CliError::input(
            "--selection needs --beta auto and/or --sigma auto",
        ));
    }
    let mut guard = OutputGuard::new();
    let mut inputs: Vec<&Path> = a.data.iter().map(PathBuf::as_path).collect();
    if let Some(v) = &a.validation_data {
        inputs.push(v);
    }
    protect_inputs(&mut guard, &mf, &a.model, &inputs);
    // Refuse a bad output directory before the (possibly long) identification.
    let stems = file_stems(mf.blocks.iter().map(|b| b.name.as_str()));
    let planned: Vec<String> = ["estimate.csv", "estimate.json", "report.json"]
        .into_iter()
        .map(String::from)
        .chain(
            stems
                .iter()
                .flat_map(|s| [format!("map_{s}.csv"), format!("map_{s}.svg")]),
        )
        .collect();
    guard.check_out_dir(&a.out, &planned)?;
    let data = read_records(&mf, &a.data)?;
    let validation = match &a.validation_data {
        Some(v) => Some(mf.select_data(&crate::data::read_table(v)?)?),
        None => None,
    };
    let criterion = a.selection.map(|s| match s {
        crate::SelectionArg::Ml => Criterion::MarginalLikelihood,
        crate::SelectionArg::Gcv => Criterion::Gcv,
        crate::SelectionArg::Cv => Criterion::CrossValidation { folds: a.folds },
        crate::SelectionArg::Validation => Criterion::Validation,
    });
    // A selection counts its trials; one solve reports nothing on its way, and above this
    // size takes long enough that a terminal should show it is running.
    let pb = if auto_beta || auto_sigma {
        let pb = crate::progress::bar(None, "β trials");
        let shown = criterion.unwrap_or_else(|| structid_workflow::default_criterion(&mf, a.folds));
        pb.set_message(format!("selecting by {}", shown.describe()));
        pb
    } else if data.len() > LONG_SOLVE_SAMPLES {
        crate::progress::spinner(format!("identifying from {} samples", data.len()))
    } else {
        indicatif::ProgressBar::hidden()
    };
    let outcome = identify_model_file(&IdentifyRequest {
        model: &mf,
        data: &data,
        data_label: files_label(&a.data),
        validation: validation.as_ref(),
        beta: (!auto_beta).then(|| settings.beta()),
        sigma,
        sigma_label: "--sigma".into(),
        sigma_auto: auto_sigma,
        selection: criterion,
        folds: a.folds,
        settings,
        dispersions: Vec::new(),
        progress: crate::progress::observer(&pb),
    });
    pb.finish_and_clear();
    let outcome = outcome?;
    let id = &outcome.identification;
    let block_sigmas: Vec<(String, f64)> = if auto_sigma {
        outcome
            .model
            .blocks()
            .iter()
            .zip(&outcome.widths)
            .filter_map(|(b, w)| w.map(|w| (b.name.clone(), w)))
            .collect()
    } else {
        Vec::new()
    };
    // An iterate that stopped at a limit is written all the same, its status and the
    // solver's warning in report.json, and then reported as a runtime failure: the run is
    // not taken for a converged estimate, and the work is not lost.
    let unconverged = id.check_converged().err();

    guard.begin_set(&a.out, Some(&planned))?;
    let mut report = outcome.report.clone();
    report.data_file = Some(files_label(&a.data));
    let mut rec = reproduction(&a, id, outcome.settings.beta(), sigma);
    rec.block_sigmas = block_sigmas;
    report.reproduction = Some(rec);
    let written = write_estimate(
        &a.out,
        &mut guard,
        &mf,
        id,
        &outcome.estimate,
        &mut report,
        a.no_bands,
    )?;
    guard.finish_set(&a.out, &structid_io::output::file_names(&written))?;

    print!(
        "{}",
        summary(&report, id, &written, t0.elapsed().as_secs_f64())
    );
    match unconverged {
        Some(e) => Err(CliError::runtime(format!(
            "{e}; the last iterate was written to `{}`, marked as not converged (report.json: \
             diagnostics.status = {})",
            a.out.display(),
            serde_json::to_string(&id.diagnostics.status).unwrap_or_default()
        ))),
        None => Ok(()),
    }
}

/// Writes the files of an estimate into `out` (created): estimate.json (the fitted model,
/// self-contained: `validate`, `simulate` and `predict` read it without the data),
/// estimate.csv, map_<block>.csv and map_<block>.svg per block (with the posterior band unless
/// `no_bands`), and report.json, whose `files` list they fill. Returns the paths written,
/// report.json last.
pub(crate) fn write_estimate(
    out: &Path,
    guard: &mut OutputGuard,
    mf: &ModelFile,
    id: &Identification,
    stored: &Estimate,
    report: &mut Report,
    no_bands: bool,
) -> Result<Vec<PathBuf>, CliError> {
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
                CliError::runtime(format!(
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
    report.files = written
        .iter()
        .chain(std::iter::once(&report_path))
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
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
pub(crate) fn estimate_columns(
    mf: &ModelFile,
    id: &Identification,
) -> (Vec<String>, Vec<Vec<f64>>) {
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

fn summary(report: &Report, id: &Identification, written: &[PathBuf], seconds: f64) -> String {
    let mut s = String::new();
    let d = &id.diagnostics;
    let _ = writeln!(
        s,
        "identified {} block(s) from {} samples with β = {} ({} solver, {:.2} s)",
        id.blocks.len(),
        report.samples,
        structid_workflow::text::short(report.settings.beta),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_stems_are_safe_and_unique() {
        let s = file_stems(["f", "a/b", "a b", ".hidden", "F"]);
        assert_eq!(s, ["f", "a_b", "a_b_2", "_.hidden", "F_2"]);
    }
}

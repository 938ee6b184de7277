//! `structid identify`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use structid_core::selection::Criterion;
use structid_core::{Data, Identification, IdentifySettings, InitialState, SolverChoice};
use structid_io::{DispersionSpec, ModelFile, OutputGuard, Reproduction};
use structid_workflow::estimate_files;
pub(crate) use structid_workflow::paths::{absolute, absolute_files, files_label, protect_inputs};
use structid_workflow::{IdentifyRequest, SolveOptions, identify_model_file};

use crate::IdentifyArgs;
use crate::error::{CliError, positive};

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

/// The records of the data files (see [`structid_workflow::records::read_records`]).
pub(crate) fn read_records(mf: &ModelFile, paths: &[PathBuf]) -> Result<Data, CliError> {
    Ok(structid_workflow::records::read_records(
        mf,
        paths,
        crate::data::vars(),
    )?)
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
    let planned = estimate_files::identify_outputs(&mf);
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
    // An iterate that stopped at a limit is written all the same, its status and the
    // solver's warning in report.json, and then reported as a runtime failure: the run is
    // not taken for a converged estimate, and the work is not lost.
    let unconverged = id.check_converged().err();
    let mut rec = reproduction(&a, id, outcome.settings.beta(), sigma);
    if auto_sigma {
        rec.block_sigmas = estimate_files::selected_widths(&outcome);
    }
    let (report, written) = estimate_files::write_identification(
        &a.out,
        &mut guard,
        &planned,
        &mf,
        &outcome,
        files_label(&a.data),
        rec,
        a.no_bands,
    )?;
    print!(
        "{}",
        estimate_files::identify_summary(&report, id, &written, t0.elapsed().as_secs_f64())
    );
    match unconverged {
        Some(e) => Err(estimate_files::not_converged(e, &a.out, id).into()),
        None => Ok(()),
    }
}

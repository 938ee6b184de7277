//! `structid refine`: alternate between identifying the maps and re-estimating the linear part
//! of a model file with a `[linear]` section ([`structid_workflow::refine_model_file`], its
//! records and files in [`structid_workflow::refine_files`]), or fit it jointly.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use structid_core::IdentifySettings;
use structid_core::selection::Criterion;
use structid_io::{ModelFile, OutputGuard};
use structid_workflow::refine_files::{self, RefineData, RefineRecords};
use structid_workflow::{RefineRequest, refine_model_file};

use crate::error::CliError;
use crate::{AutoOr, InitialStateArg};

/// Arguments of `structid refine`.
#[derive(Debug, Args)]
pub struct RefineArgs {
    /// The model file: a `[linear]` section with a structure ("output-feedback",
    /// "rate-feedback", "input" or "output": the starting linear part, e.g. from `structid
    /// linear`) and the map's `[[nonlinearity]]`; or an `[lft]` whose one map sits at a
    /// declared location that is one of those structures around a linear block G (the
    /// refined model is then written as `[linear]`).
    #[arg(long, short = 'm', value_name = "MODEL.toml")]
    model: PathBuf,
    /// The estimation data (CSV with the columns of `[signals]`). Repeat it for several
    /// records of the same system: both steps restart at every record (each simulated from
    /// rest, or from its own estimated initial state with --initial-state estimate) and J is
    /// the mean over all their samples.
    #[arg(long, short = 'd', value_name = "DATA.csv", required = true)]
    data: Vec<PathBuf>,
    /// Output directory (created if needed).
    #[arg(long, short = 'o', value_name = "DIR")]
    out: PathBuf,
    /// A validation record (CSV like --data): the alternation stops when its simulation error
    /// stops improving, and the best iteration is kept. Repeat it for several validation
    /// records: each is simulated from rest (its first --settle samples not scored) and the
    /// squared errors are pooled.
    #[arg(long, value_name = "V.csv", conflicts_with = "validation_fraction")]
    validation_data: Vec<PathBuf>,
    /// Hold out the last fraction of --data as the validation record instead (0 < F < 1): the
    /// maps and G are estimated on the rest, and the validation error is that of a simulation
    /// of the whole file, scored on the held-out samples. One --data file only: with several
    /// records, hold out whole records with --validation-data.
    #[arg(long, value_name = "F")]
    validation_fraction: Option<f64>,
    /// Leading validation samples that only settle the state and are not scored.
    #[arg(long, value_name = "N", default_value_t = 0)]
    settle: usize,
    /// Largest number of alternations (default 10); with --joint, of Levenberg–Marquardt
    /// iterations per stage (default 100).
    #[arg(long, value_name = "N")]
    iterations: Option<usize>,
    /// Stop when the validation error (without one, J) improves by less than this fraction.
    #[arg(long, value_name = "TOL", default_value_t = 1e-3)]
    tolerance: f64,
    /// β > 0, or `auto` (chosen on the first pass by --selection, then kept so that J can only
    /// decrease).
    #[arg(
        long,
        value_name = "B|auto",
        allow_negative_numbers = true,
        default_value = "auto"
    )]
    beta: AutoOr,
    /// Kernel width σ > 0 of the map, or `auto` (chosen with β on the first pass). Default:
    /// the model file's, else 0.1 × the range of the map's input.
    #[arg(long, value_name = "S|auto", allow_negative_numbers = true)]
    sigma: Option<AutoOr>,
    /// Criterion of automatic β/σ: `ml` (marginal likelihood) or `gcv`.
    #[arg(long, value_name = "ml|gcv", default_value = "ml")]
    selection: RefineSelectionArg,
    /// Initial state: `zero` (the record starts at rest) or `estimate` (estimated in both
    /// steps; use it for records cut from a longer experiment).
    #[arg(long, value_name = "zero|estimate", default_value = "zero")]
    initial_state: InitialStateArg,
    /// Skip the posterior uncertainty band of the map.
    #[arg(long)]
    no_bands: bool,
    /// Fit the whole model at once by its simulation error instead of alternating: G's free
    /// entries (--free), every static map as a Gaussian kernel expansion, every `operator`
    /// block's parameters and the initial state, by Levenberg–Marquardt. Takes any `[lft]` or
    /// `[linear]` model file: maps in series, maps of unmeasured states, hysteresis operators.
    /// β: a number, or `auto` with --validation-data (the best of 10⁻¹⁰ … 10⁻² by the
    /// validation simulation RMS).
    #[arg(long)]
    joint: bool,
    /// With --joint: an entry of G to fit, `Bw[1][0]`, or a matrix name (`A`) for all its
    /// non-zero entries. Repeat it. The others stay as the model file gives them.
    #[arg(long, value_name = "ENTRY", requires = "joint")]
    free: Vec<String>,
    /// With --joint: kernel centres per static map (per input for a map of two inputs).
    #[arg(long, value_name = "N", default_value_t = 15, requires = "joint")]
    centres: usize,
    /// With --joint: samples per multiple-shooting segment (default: single shooting).
    #[arg(long, value_name = "N", requires = "joint")]
    segment_length: Option<usize>,
    /// With --joint: fit by the score of a simulation in windows of LENGTH samples, each from
    /// a state fitted to its first half and scored after its first INIT samples (plants with
    /// integrators, as `--scoring LENGTH:INIT` scores them).
    #[arg(long, value_name = "LENGTH:INIT", requires = "joint", value_parser = crate::refine::parse_windows)]
    windows: Option<structid_core::validation::Windows>,
}

/// `LENGTH:INIT` as windows (the syntax of `--scoring`).
pub(crate) fn parse_windows(s: &str) -> Result<structid_core::validation::Windows, String> {
    match structid_workflow::discover::parse_scoring(s)? {
        structid_core::validation::Scoring::Windowed(w) => Ok(w),
        _ => Err(format!("`{s}` is not LENGTH:INIT (e.g. 500:25)")),
    }
}

/// Values of `refine --selection`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RefineSelectionArg {
    /// Maximum marginal likelihood.
    Ml,
    /// Generalised cross-validation.
    Gcv,
}

/// Runs `structid refine`.
pub fn run(a: RefineArgs) -> Result<(), CliError> {
    if a.joint {
        return run_joint(a);
    }
    let t0 = Instant::now();
    let iterations = a.iterations.unwrap_or(10);
    let read = ModelFile::from_path(&a.model)?;
    // The structure is checked before any data are read.
    let (mf, _, _, recognised) =
        structid_workflow::refine::refinable(&read, &a.model.display().to_string())?;
    if iterations == 0 {
        return Err(CliError::input(
            "invalid value 0 for --iterations: it must be at least 1",
        ));
    }
    let mut guard = OutputGuard::new();
    guard.protect(&a.model);
    for d in a.data.iter().chain(&a.validation_data) {
        guard.protect(d);
    }
    let planned = refine_files::refine_outputs(&mf);
    guard.check_out_dir(&a.out, &planned)?;

    // Records.
    let sigma = match a.sigma {
        Some(AutoOr::Value(s)) => Some(crate::error::positive("--sigma", s)?),
        _ => None,
    };
    let records = refine_files::split_records(
        &mf,
        &RefineData {
            data: &a.data,
            validation_data: &a.validation_data,
            validation_fraction: a.validation_fraction,
            settle: a.settle,
            out: &a.out,
            vars: crate::data::vars(),
        },
    )?;
    let RefineRecords {
        data,
        validation,
        validation_note,
        data_label,
        ..
    } = &records;
    let settle = match a.validation_fraction {
        Some(_) => data.len() + a.settle,
        None => a.settle,
    };
    let identify_settings = IdentifySettings::builder()
        .initial_state(a.initial_state.into())
        .posterior(!a.no_bands)
        .build()?;
    let pb = crate::progress::bar(Some(iterations as u64), "alternations");
    let outcome = refine_model_file(&RefineRequest {
        model: &mf,
        model_label: a.model.display().to_string(),
        data,
        data_label: data_label.clone(),
        validation: validation.as_ref(),
        validation_labels: a
            .validation_data
            .iter()
            .map(|p| p.display().to_string())
            .collect(),
        validation_note: validation_note.clone(),
        beta: match a.beta {
            AutoOr::Value(b) => Some(crate::error::beta("--beta", b)?),
            AutoOr::Auto => None,
        },
        sigma,
        sigma_label: "--sigma".into(),
        sigma_auto: a.sigma == Some(AutoOr::Auto),
        criterion: match a.selection {
            RefineSelectionArg::Ml => Criterion::MarginalLikelihood,
            RefineSelectionArg::Gcv => Criterion::Gcv,
        },
        iterations,
        tolerance: a.tolerance,
        settle,
        identify: identify_settings,
        progress: crate::progress::observer(&pb),
        selection_progress: crate::progress::message_observer(&pb, "first pass"),
    });
    pb.finish_and_clear();
    let outcome = outcome?;
    let written = refine_files::write_refinement(
        &a.out,
        &mut guard,
        &planned,
        &outcome,
        &records,
        &a.data,
        a.initial_state.into(),
        a.no_bands,
    )?;
    if let Some(note) = recognised {
        println!("{note}");
    }
    print!(
        "{}",
        refine_files::refine_summary(&outcome.refinement, &written, t0.elapsed().as_secs_f64())
    );
    Ok(())
}

/// `structid refine --joint`: parses the arguments into a request for
/// [`structid_workflow::refine_joint`], writes its outputs and prints a summary.
fn run_joint(a: RefineArgs) -> Result<(), CliError> {
    use structid_workflow::{BetaChoice, JointRequest, JointWorkflowSettings};
    let t0 = Instant::now();
    let mf = ModelFile::from_path(&a.model)?;
    if a.validation_fraction.is_some() {
        return Err(CliError::input(
            "--joint scores β on whole validation records: pass them as --validation-data V.csv",
        ));
    }
    let mut guard = OutputGuard::new();
    guard.protect(&a.model);
    for d in a.data.iter().chain(&a.validation_data) {
        guard.protect(d);
    }
    let data = crate::identify::read_records(&mf, &a.data)?;
    let validation = match a.validation_data.is_empty() {
        true => None,
        false => Some(crate::identify::read_records(&mf, &a.validation_data)?),
    };
    let given = match a.beta {
        AutoOr::Value(b) => Some(b),
        AutoOr::Auto => None,
    };
    let beta = BetaChoice::from_options(given, validation).map_err(|e| {
        CliError::from(e).context("--joint: give --beta B or --validation-data V.csv")
    })?;
    let fit = structid_workflow::FitOptions {
        iterations: a.iterations.unwrap_or(100),
        estimate_initial_state: matches!(a.initial_state, InitialStateArg::Estimate),
        segment_length: a.segment_length,
        windows: a.windows,
    };
    let settings = JointWorkflowSettings {
        beta,
        centres: a.centres,
        free: a.free.clone(),
        fit: fit.settings().map_err(|e| CliError::input(e.to_string()))?,
        ..JointWorkflowSettings::default()
    };
    let out = structid_workflow::refine_joint(&JointRequest {
        model: &mf,
        data: &data,
        settings,
    })
    .map_err(|e| {
        CliError::from(e).context(format!("cannot refine `{}` jointly", a.model.display()))
    })?;
    structid_workflow::write_joint_outputs(&out, &a.out, &guard)?;
    print!(
        "{}",
        refine_files::joint_summary(
            &a.model,
            &mf.signals.y,
            &out,
            &a.out,
            t0.elapsed().as_secs_f64()
        )
    );
    Ok(())
}

//! `structid refine`: alternate between identifying the maps and re-estimating the linear part
//! of a model file with a `[linear]` section.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use structid_core::selection::Criterion;
use structid_core::{Data, IdentifySettings, InitialState};
use structid_io::{ModelFile, OutputGuard, Reproduction};
use structid_plot::{Chart, Series, render_chart_svg};
use structid_workflow::{RefineRequest, refine_model_file};

use crate::error::CliError;
use crate::identify::{absolute, absolute_files, write_estimate};
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
}

/// Values of `refine --selection`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RefineSelectionArg {
    /// Maximum marginal likelihood.
    Ml,
    /// Generalised cross-validation.
    Gcv,
}

/// Splits a record at sample `at`: (first part, rest).
fn split(data: &Data, at: usize) -> Result<(Data, Data), CliError> {
    let part = |r: std::ops::Range<usize>| Data::new(data.u().slice(r.clone()), data.y().slice(r));
    Ok((part(0..at)?, part(at..data.len())?))
}

/// The estimation and validation records of a refinement, and what the report says of them.
struct Split {
    data: Data,
    validation: Option<Data>,
    validation_note: Option<String>,
    /// Where the estimation part is written when it was cut from the data file.
    estimation_file: Option<PathBuf>,
}

/// The records of `--data`, and the validation: `--validation-data` files, or the end of the
/// one `--data` record (`--validation-fraction`), simulated from the start of the file.
fn split_records(a: &RefineArgs, mf: &ModelFile, data_label: &str) -> Result<Split, CliError> {
    if let Some(f) = a.validation_fraction
        && !(f > 0.0 && f < 1.0)
    {
        return Err(CliError::input(format!(
            "invalid value {f} for --validation-fraction: it must lie strictly between 0 and 1"
        )));
    }
    if a.validation_fraction.is_some() && a.data.len() > 1 {
        return Err(CliError::input(format!(
            "--validation-fraction holds out the end of one record, and {} --data records were \
             given: the held-out samples of a record do not start at rest, and each record would \
             need its own settling; hold out whole records instead, passing them as \
             --validation-data V.csv (repeat it for several)",
            a.data.len()
        )));
    }
    let all = crate::identify::read_records(mf, &a.data)?;
    let (data, validation, validation_note, estimation_file) = match (
        a.validation_data.is_empty(),
        a.validation_fraction,
    ) {
        (false, _) => {
            let vd = crate::identify::read_records(mf, &a.validation_data).map_err(|e| {
                e.context(format!(
                    "the --validation-data files ({})",
                    crate::identify::files_label(&a.validation_data)
                ))
            })?;
            (
                all,
                Some(vd),
                Some(crate::identify::files_label(&a.validation_data)),
                None,
            )
        }
        (true, Some(f)) => {
            let at = ((1.0 - f) * all.len() as f64).round() as usize;
            if at < 10 || all.len() - at <= a.settle {
                return Err(CliError::input(format!(
                    "--validation-fraction {f} leaves {at} estimation and {} validation samples \
                     (after {} settling ones); both parts need samples",
                    all.len() - at,
                    a.settle
                )));
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
    Ok(Split {
        data,
        validation,
        validation_note,
        estimation_file,
    })
}

/// refine.csv (one row per alternation) and refine.svg (the estimation and validation RMS
/// against the iteration) in `out`; returns their paths.
fn write_iterations(
    out: &std::path::Path,
    guard: &mut OutputGuard,
    r: &structid_core::refine::Refinement,
    with_validation: bool,
) -> Result<(PathBuf, PathBuf), CliError> {
    let csv_path = out.join("refine.csv");
    let n = r.iterations.len();
    let col = |f: &dyn Fn(&structid_core::refine::RefineIteration) -> f64| -> Vec<f64> {
        r.iterations.iter().map(f).collect()
    };
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
    a: &RefineArgs,
    model_path: &std::path::Path,
    data_file: &std::path::Path,
    r: &structid_core::refine::Refinement,
) -> Reproduction {
    Reproduction {
        model_file_absolute: absolute(model_path).display().to_string(),
        data_file_absolute: absolute(data_file).display().to_string(),
        data_files_absolute: absolute_files(&a.data),
        beta: r.beta,
        sigma: None,
        solver_requested: "auto".into(),
        solver: r.identification.diagnostics.solver.name().to_string(),
        initial_state: crate::identify::value_name(a.initial_state),
        memory_limit_mib: None,
        dispersion: None,
        neighbours: None,
        tolerance: None,
        max_iterations: None,
        block_sigmas: Vec::new(),
    }
}

/// Writes the record `data` as CSV with the model file's column names.
fn write_record(
    guard: &mut OutputGuard,
    path: &std::path::Path,
    mf: &ModelFile,
    data: &Data,
) -> Result<(), CliError> {
    let names: Vec<String> = mf.signals.u.iter().chain(&mf.signals.y).cloned().collect();
    let mut columns: Vec<Vec<f64>> = (0..data.u().channels())
        .map(|c| data.u().channel(c))
        .collect();
    columns.extend((0..data.y().channels()).map(|c| data.y().channel(c)));
    guard.write_csv(path, &names, &columns)?;
    Ok(())
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
    let planned: Vec<String> = [
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
    .chain(
        crate::identify::file_stems(mf.blocks.iter().map(|b| b.name.as_str()))
            .iter()
            .flat_map(|s| [format!("map_{s}.csv"), format!("map_{s}.svg")]),
    )
    .collect();
    guard.check_out_dir(&a.out, &planned)?;

    // Records.
    let sigma = match a.sigma {
        Some(AutoOr::Value(s)) => Some(crate::error::positive("--sigma", s)?),
        _ => None,
    };
    let data_label = crate::identify::files_label(&a.data);
    let Split {
        data,
        validation,
        validation_note,
        estimation_file,
    } = split_records(&a, &mf, &data_label)?;
    let settle = match a.validation_fraction {
        Some(_) => data.len() + a.settle,
        None => a.settle,
    };
    let identify_settings = IdentifySettings::builder()
        .initial_state(match a.initial_state {
            InitialStateArg::Zero => InitialState::Zero,
            InitialStateArg::Estimate => InitialState::Estimate,
        })
        .posterior(!a.no_bands)
        .build()?;
    let pb = crate::progress::bar(Some(iterations as u64), "alternations");
    let outcome = refine_model_file(&RefineRequest {
        model: &mf,
        model_label: a.model.display().to_string(),
        data: &data,
        data_label: data_label.clone(),
        validation: validation.as_ref(),
        validation_labels: a
            .validation_data
            .iter()
            .map(|p| p.display().to_string())
            .collect(),
        validation_note,
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
    let (r, refined) = (&outcome.refinement, &outcome.refined);

    guard.begin_set(&a.out, Some(&planned))?;
    let model_path = a.out.join("model.toml");
    guard.write(&model_path, refined.to_toml_string().as_bytes())?;
    let data_file = match &estimation_file {
        Some(path) => {
            write_record(&mut guard, path, refined, &data)?;
            path.clone()
        }
        None => a.data[0].clone(),
    };
    let id = &r.identification;
    let mut report = outcome.report.clone();
    report.model_file = Some(model_path.display().to_string());
    report.data_file = Some(if estimation_file.is_some() {
        data_file.display().to_string()
    } else {
        data_label.clone()
    });
    report.reproduction = Some(reproduction(&a, &model_path, &data_file, r));

    // The iteration table and figure.
    let (csv_path, svg_path) = write_iterations(&a.out, &mut guard, r, validation.is_some())?;
    // The alternation keeps no parameter covariance of G (its fits run through the map): the
    // figure has no band.
    let linear_path = a.out.join("linear.svg");
    let svg = crate::figures::linear_svg(&r.linear, None, &refined.signals.u)?;
    guard.write(&linear_path, svg.as_bytes())?;

    let mut written = write_estimate(
        &a.out,
        &mut guard,
        refined,
        id,
        &outcome.estimate,
        &mut report,
        a.no_bands,
    )?;
    written.splice(0..0, [model_path, csv_path, svg_path, linear_path]);
    if let Some(p) = estimation_file {
        written.insert(1, p);
    }
    guard.finish_set(&a.out, &structid_io::output::file_names(&written))?;
    if let Some(note) = recognised {
        println!("{note}");
    }
    print!("{}", summary(r, &written, t0.elapsed().as_secs_f64()));
    Ok(())
}

fn summary(r: &structid_core::refine::Refinement, written: &[PathBuf], seconds: f64) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "refinement: {} iteration(s), kept iteration {} ({}); β = {}",
        r.iterations.len(),
        r.best,
        r.stop_reason,
        structid_workflow::text::short(r.beta)
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
    let mut fit = structid_joint::JointSettings::builder()
        .max_iterations(a.iterations.unwrap_or(100))
        .estimate_initial_state(matches!(a.initial_state, InitialStateArg::Estimate));
    if let Some(l) = a.segment_length {
        fit = fit.segment_length(l);
    }
    let settings = JointWorkflowSettings {
        beta,
        centres: a.centres,
        free: a.free.clone(),
        fit: fit.build().map_err(|e| CliError::input(e.to_string()))?,
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
    println!(
        "joint fit of {} by simulation error: cost {:.4e} → {:.4e} (β = {:.1e}, {} parameters, {:.2} s)",
        a.model.display(),
        out.fit.initial_cost,
        out.fit.cost,
        out.beta,
        out.fit.model.parameters().len(),
        t0.elapsed().as_secs_f64()
    );
    for (name, rms) in mf.signals.y.iter().zip(&out.fit.rms) {
        println!("  {name}: simulation RMS {rms:.4e}");
    }
    for t in &out.trials {
        println!(
            "  β = {:.1e}: validation RMS {:?}",
            t.beta, t.validation_rms
        );
    }
    println!(
        "wrote {}/model.toml, joint.json and the map tables",
        a.out.display()
    );
    Ok(())
}

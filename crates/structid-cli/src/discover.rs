//! `structid discover`: from a nominal linear model that almost fits to a named missing effect,
//! its place in the structure and an augmented model file (see
//! `structid_discover::discover`). The workflow, the augmented model and the reports are
//! `structid_discover`'s and [`structid_workflow::discover_report`]'s; this module parses the
//! arguments and prints.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use structid_discover::discover::DiscoverSettings;
use structid_io::{ModelFile, OutputGuard};
use structid_workflow::discover_report::Record;
use structid_workflow::discover_report::files::{
    DiscoveryFiles, OUTPUTS, validation_is_estimation, write_discovery,
};
use structid_workflow::{
    DiscoverOptions, DiscoverOutcome, DiscoverRequest, discover_model_file, nominal_model,
};

use crate::error::CliError;

/// Arguments of `structid discover`.
#[derive(Debug, Args)]
pub struct DiscoverArgs {
    /// The nominal model file: one input, one output, its linear block as `[linear]` with
    /// structure = "lti" (write one with `structid linear --structure lti`) or as `[lft]`; or a
    /// model that already has maps (every `[[nonlinearity]]` with a `truth`, e.g. the
    /// `augmented.toml` of an earlier run), whose maps are kept fixed while the next effect is
    /// found around it.
    #[arg(long, short = 'm', value_name = "MODEL.toml")]
    model: PathBuf,
    /// The estimation record (CSV with the columns named in the model's `[signals]`): every
    /// hypothesis' map is identified on it. Repeat for several records (separate experiments):
    /// each is simulated from its own initial state, and the maps are identified on all.
    #[arg(long, short = 'd', value_name = "EST.csv", required = true)]
    data: Vec<PathBuf>,
    /// The validation record (CSV like --data): hypotheses are ranked, and effects named, by
    /// their simulation error on it. Repeat for several records: the error is pooled over
    /// them, and the report shows each.
    #[arg(
        long = "validation-data",
        visible_alias = "validate",
        value_name = "VAL.csv",
        required = true
    )]
    validate: Vec<PathBuf>,
    /// Output directory (created if needed).
    #[arg(long, short = 'o', value_name = "DIR")]
    out: PathBuf,
    /// Candidate locations of the missing block, comma-separated: `input` (y = G·N(u)),
    /// `output` (y = N(G·u)), `output-feedback` (y = G·(u − N(y))), `rate-feedback`
    /// (y = G·(u − N(ẏ))), or a location the nominal model declares (`declared-i` or its name)
    /// [default: all].
    #[arg(long, value_name = "LOC,…", value_delimiter = ',')]
    locations: Option<Vec<String>>,
    /// Do not try a total-variation estimate when the best family has a kink or a jump.
    #[arg(long)]
    no_tv: bool,
    /// Leading samples of each record left out of the RMS values that rank the hypotheses and
    /// name the effect (the state settles).
    #[arg(long, value_name = "N", default_value_t = 0)]
    settle: usize,
    /// How every simulation is scored: `auto` (windows when the nominal model has a pole on
    /// the unit circle, an integrator, whose free run drifts; one free run otherwise), `free`,
    /// or windows `LENGTH:INIT` (each simulated from a state fitted to its first half, scored after its first INIT samples).
    #[arg(long, value_name = "auto|free|LENGTH:INIT", default_value = "auto")]
    scoring: String,
    /// Keep G exactly as given: no joint re-estimation with the map (for a nominal model known
    /// to be exact, e.g. from first principles with measured parameters).
    #[arg(long)]
    keep_nominal: bool,
    /// Width σ of each hypothesis' Fourier kernel as a fraction of the range of its z.
    #[arg(
        long,
        value_name = "F",
        allow_negative_numbers = true,
        default_value_t = DiscoverSettings::default().sigma_fraction()
    )]
    sigma_fraction: f64,
    /// Degree of the polynomial trend added to the kernel (0: none), so that maps extrapolate.
    #[arg(long, value_name = "D", default_value_t = DiscoverSettings::default().trend_degree())]
    trend: usize,
    /// Tune σ with β by marginal likelihood (default: σ fixed, β tuned).
    #[arg(long)]
    tune_sigma: bool,
    /// Significance level α of the candidate table's selection rule (0 < α ≤ 0.5): a row is
    /// as good as the best unless a paired test of the validation errors over blocks of the
    /// record says it is worse at α; the simplest row as good as the best is chosen.
    #[arg(
        long,
        value_name = "ALPHA",
        allow_negative_numbers = true,
        default_value_t = DiscoverSettings::default().significance()
    )]
    significance: f64,
    /// Share of the deconvolved residual energy (0 < T < 1) that the direction of z must
    /// explain for the effect to be reported as dynamic (hysteresis or backlash suspected).
    #[arg(
        long,
        value_name = "T",
        allow_negative_numbers = true,
        default_value_t = DiscoverSettings::default().hysteresis_threshold()
    )]
    hysteresis_threshold: f64,
    /// Look for up to N effects, one at a time: each step adopts the augmented model of the
    /// one before as its nominal model (its maps fixed in the loop), and the iteration stops
    /// when the gap is noise, when no block explains it, or when a step cuts the validation
    /// RMS by less than 10 %. The files are those of the last adopted step; the report lists
    /// every step.
    #[arg(long, value_name = "N", default_value_t = 1)]
    effects: usize,
}
/// The options of `structid discover` as the workflow takes them.
fn options(a: &DiscoverArgs) -> DiscoverOptions {
    DiscoverOptions {
        total_variation: !a.no_tv,
        settle: a.settle,
        scoring: a.scoring.clone(),
        keep_nominal: a.keep_nominal,
        sigma_fraction: a.sigma_fraction,
        trend: a.trend,
        tune_sigma: a.tune_sigma,
        significance: a.significance,
        hysteresis_threshold: a.hysteresis_threshold,
        locations: a.locations.clone(),
    }
}

/// The command line as typed (arguments with spaces or quotes single-quoted).
fn command_line() -> String {
    let quote = |a: String| {
        if !a.is_empty()
            && a.chars()
                .all(|c| c.is_alphanumeric() || "-_./=,:+@%".contains(c))
        {
            a
        } else {
            format!("'{}'", a.replace('\'', "'\\''"))
        }
    };
    let mut args = std::env::args();
    let _ = args.next();
    std::iter::once("structid".to_string())
        .chain(args.map(quote))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Runs `structid discover`.
pub fn run(a: DiscoverArgs) -> Result<(), CliError> {
    let t0 = Instant::now();
    let mf = ModelFile::from_path(&a.model)?;
    let nominal = nominal_model(&mf, &a.model.display().to_string())?;
    let settings = options(&a).settings(&nominal)?;

    // Never overwrite an input; refuse a bad output directory before the long part.
    let mut guard = OutputGuard::new();
    guard.protect(&a.model);
    for p in a.data.iter().chain(&a.validate) {
        guard.protect(p);
    }
    guard.check_out_dir(&a.out, OUTPUTS)?;

    let read = |paths: &[PathBuf], flag: &str| -> Result<Record, CliError> {
        let records = paths
            .iter()
            .map(|p| structid_workflow::records::read_record(&mf, p, crate::data::vars()))
            .collect::<Result<Vec<_>, _>>()?;
        let lengths: Vec<(usize, String)> = records
            .iter()
            .map(|r| (r.data.len(), format!("{flag} `{}`", r.path.display())))
            .collect();
        structid_workflow::discover::check_settle(a.settle, &lengths)?;
        Record::join(records).map_err(|e| CliError::input(format!("{flag}: {e}")))
    };
    let est = read(&a.data, "--data")?;
    let val = read(&a.validate, "--validation-data")?;
    let pb = crate::progress::bar(Some(0), "locations identified");
    let observed = settings.with_progress(crate::progress::observer(&pb));
    let outcome = discover_model_file(&DiscoverRequest {
        model: &mf,
        nominal: &nominal,
        estimation: &est.data,
        validation: &val.data,
        settings: &observed,
        effects: a.effects,
    });
    pb.finish_and_clear();
    let DiscoverOutcome {
        discovery: d,
        effects,
        model: mf,
        nominal,
    } = outcome?;
    // Said after the run, so that an input error is the first line of stderr.
    if let Some(w) = validation_is_estimation(&a.data, &a.validate) {
        eprintln!("warning: {w}");
    }
    let command = command_line();
    let files = DiscoveryFiles {
        model_path: &a.model,
        out: &a.out,
        command: &command,
        model: &mf,
        nominal: &nominal,
        settings: &settings,
        estimation: &est,
        validation: &val,
    };
    let effects = effects.as_ref().map(|(e, _)| e);
    print!("{}", write_discovery(&files, &guard, &d, effects, t0)?);
    Ok(())
}

//! `structid discover`: from a nominal linear model that almost fits to a named missing effect,
//! its place in the structure and an augmented model file (see
//! `structid_discover::discover`). The workflow, the augmented model and the reports are
//! `structid_discover`'s; this module parses the arguments, draws the figures and writes the
//! files.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use structid_core::estimate::SignalNames;
use structid_discover::augmented::{self, AugmentedFile, ESTIMATE_FILE, TABLE_FILE};
use structid_discover::discover::{
    Classification, DiscoverSettings, Finding, HypothesisResult, candidate_signals,
};
use structid_discover::gap::Gap;
use structid_discover::hypotheses::{Nominal, Site};
use structid_discover::localise::binned_residual;
use structid_io::{ModelFile, OutputGuard, estimate_json};
use structid_plot::{Chart, Series, decimate_min_max, render_chart_svg, render_grid_svg};
use structid_workflow::discover_report::{self as report, Record, ReportContext, TimeAxis};
use structid_workflow::{
    DiscoverOptions, DiscoverOutcome, DiscoverRequest, discover_model_file, nominal_model,
};

use crate::error::CliError;

/// Most points per line in the time-series figures (longer records are drawn decimated).
const MAX_PLOT_POINTS: usize = 4000;
/// Most points drawn as dots in map.svg.
const MAX_DOTS: usize = 2000;
/// Bins of the binned residual in regions.svg.
const REGION_BINS: usize = 20;

/// The tables of blocks `N2` … `N{MAX_TABLE_BLOCKS}` (second and later effects) that an
/// earlier run may have left are removed like the other outputs.
const MAX_TABLE_BLOCKS: usize = 9;

/// Every file `structid discover` may write, in the order of the summary (and the tables of
/// later effects' blocks, `N2_table.csv`, …).
const OUTPUTS: [&str; 9] = [
    "augmented.toml",
    TABLE_FILE,
    ESTIMATE_FILE,
    "report.md",
    "report.json",
    "residual.svg",
    "regions.svg",
    "map.svg",
    "before_after.svg",
];

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
// ---------------------------------------------------------------------------------------------
// Inputs

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

// ---------------------------------------------------------------------------------------------
// Figures

/// Buckets of the thinned lines of the figures ([`decimate_min_max`]): about one per pixel
/// column.
const PLOT_BUCKETS: usize = 1000;

/// Every `step`-th index so that at most [`MAX_PLOT_POINTS`] remain, plus the last one.
fn plot_indices(len: usize) -> Vec<usize> {
    let step = len.div_ceil(MAX_PLOT_POINTS).max(1);
    let mut idx: Vec<usize> = (0..len).step_by(step).collect();
    if len > 0 && idx.last() != Some(&(len - 1)) {
        idx.push(len - 1);
    }
    idx
}

fn pick(v: &[f64], idx: &[usize]) -> Vec<f64> {
    idx.iter().map(|&k| v[k]).collect()
}

/// The residual of the nominal model on the estimation record with its ±band·σ̂ lines and the
/// exceedance windows shaded.
fn residual_svg(g: &Gap, band: f64, time: &TimeAxis) -> Result<String, CliError> {
    let n = g.residual.len();
    // The decimated samples plus the ends of every window, so that short windows show.
    let mut idx = plot_indices(n);
    for w in &g.windows {
        idx.push(w.start.min(n.saturating_sub(1)));
        idx.push(w.end.saturating_sub(1).min(n.saturating_sub(1)));
    }
    idx.sort_unstable();
    idx.dedup();
    let t = pick(&time.values, &idx);
    // The residual itself thinned to its envelope, so that its peaks show however long the
    // record; the band and the shading need only the sampled times.
    let (tr, r) = decimate_min_max(&time.values, &g.residual, PLOT_BUCKETS);
    let limit = band * g.noise_std;
    let upper = vec![limit; t.len()];
    let lower = vec![-limit; t.len()];
    let reach = g
        .residual
        .iter()
        .fold(limit, |m, v| if v.is_finite() { m.max(v.abs()) } else { m });
    let inside = |k: usize| g.windows.iter().any(|w| w.contains(&k));
    let shade_hi: Vec<f64> = idx
        .iter()
        .map(|&k| if inside(k) { reach } else { f64::NAN })
        .collect();
    let shade_lo: Vec<f64> = shade_hi.iter().map(|v| -v).collect();
    let mut chart = Chart::new(
        format!(
            "Residual y − ŷ of the nominal model (estimation record, RMS {:.3e}, σ̂ = {:.3e})",
            g.rms, g.noise_std
        ),
        time.label,
        "y − ŷ",
    )
    .size((1000, 450));
    if !g.windows.is_empty() {
        chart = chart.with(Series::band(
            "windows above the band",
            &t,
            &[],
            &shade_lo,
            &shade_hi,
        ));
    }
    chart = chart
        .with(Series::line("residual", &tr, &r))
        .with(Series::line(format!("+{band}·σ̂"), &t, &upper))
        .with(Series::line(format!("−{band}·σ̂"), &t, &lower));
    Ok(render_chart_svg(&chart)?)
}

/// The binned residual (mean and RMS per quantile bin) against each candidate signal.
fn regions_svg(residual: &[f64], candidates: &[(String, Vec<f64>)]) -> Result<String, CliError> {
    type Binned = (String, Vec<f64>, Vec<f64>, Vec<f64>);
    let binned: Vec<Binned> = candidates
        .iter()
        .map(|(name, s)| -> Binned {
            let b = binned_residual(residual, s, REGION_BINS);
            (
                name.clone(),
                b.iter().map(|x| x.0).collect(),
                b.iter().map(|x| x.1).collect(),
                b.iter().map(|x| x.2).collect(),
            )
        })
        .filter(|(_, x, _, _)| !x.is_empty())
        .collect();
    let charts: Vec<Chart> = binned
        .iter()
        .map(|(name, x, mean, rms)| {
            Chart::new(
                format!("residual binned by {name}"),
                name.as_str(),
                "residual",
            )
            .with(Series::line("mean", x, mean))
            .with(Series::dots("mean (bins)", x, mean))
            .with(Series::line("RMS", x, rms))
        })
        .collect();
    Ok(render_grid_svg(
        &charts,
        3.min(charts.len().max(1)),
        (480, 340),
    )?)
}

fn z_label(location: Site) -> &'static str {
    match location {
        Site::Input => "z = u",
        Site::Output => "z = G·u",
        Site::OutputFeedback => "z = y",
        Site::RateFeedback => "z = ẏ",
        Site::Declared { .. } => "z",
    }
}

/// The best hypothesis' map with its ±2σ band and points, and the map of the augmented model.
fn map_svg(nominal: &Nominal, h: &HypothesisResult, f: &Finding) -> Result<String, CliError> {
    let c = &h.curve;
    let band = c.std.as_ref().map(|s| {
        (
            c.w.iter()
                .zip(s)
                .map(|(w, s)| w - 2.0 * s)
                .collect::<Vec<f64>>(),
            c.w.iter()
                .zip(s)
                .map(|(w, s)| w + 2.0 * s)
                .collect::<Vec<f64>>(),
        )
    });
    let n = h.points.0.len();
    let idx: Vec<usize> = if n <= MAX_DOTS {
        (0..n).collect()
    } else {
        (0..MAX_DOTS).map(|i| i * n / MAX_DOTS).collect()
    };
    let pz = pick(&h.points.0, &idx);
    let pw = pick(&h.points.1, &idx);
    let map = f.augmented.map.interpolant()?;
    let aw: Vec<f64> = c.z.iter().map(|z| map.eval(&[*z])).collect();
    let label = match &f.classification {
        Classification::Named(fit) => format!("{} (named, in augmented.toml)", fit.effect.name()),
        _ => format!("table in augmented.toml ({} estimate)", f.estimator),
    };
    let mut chart = Chart::new(
        format!(
            "Map N {}: {}",
            nominal.key(f.location),
            f.classification.describe_at(f.location)
        ),
        z_label(f.location),
        "w = N(z)",
    )
    .size((900, 560));
    if let Some((lo, hi)) = &band {
        chart = chart.with(Series::band("±2σ", &c.z, &[], lo, hi));
    }
    if !pz.is_empty() {
        chart = chart.with(Series::dots("points (z_k, ŵ_k)", &pz, &pw));
    }
    chart = chart
        .with(Series::line("nonparametric estimate", &c.z, &c.w))
        .with(Series::line(label, &c.z, &aw));
    Ok(render_chart_svg(&chart)?)
}

/// Measured y, the nominal and the augmented simulation on the validation record, and the two
/// residuals.
fn before_after_svg(
    val: &Record,
    before: &Gap,
    after: &Gap,
    shrink: f64,
) -> Result<String, CliError> {
    let n = before.simulated.len();
    let time = &val.time.values[..n.min(val.time.values.len())];
    let thin = |v: &[f64]| decimate_min_max(time, v, PLOT_BUCKETS);
    let y = thin(&val.data.y().channel(0));
    let nominal = thin(&before.simulated);
    let augmented = thin(&after.simulated);
    let r0 = thin(&before.residual);
    let r1 = thin(&after.residual);
    let charts = [
        Chart::new(
            format!(
                "Validation record: measured and simulated (fit {:.1} % → {:.1} %)",
                before.fit_percent, after.fit_percent
            ),
            val.time.label,
            "y",
        )
        .with(Series::line("measured y", &y.0, &y.1))
        .with(Series::line("nominal model", &nominal.0, &nominal.1))
        .with(Series::line("augmented model", &augmented.0, &augmented.1)),
        Chart::new(
            format!(
                "Residuals y − ŷ (RMS {:.3e} → {:.3e}, {})",
                before.rms,
                after.rms,
                structid_discover::gap::shrink_text(shrink, 1)
            ),
            val.time.label,
            "y − ŷ",
        )
        .with(Series::line("nominal model", &r0.0, &r0.1))
        .with(Series::line("augmented model", &r1.0, &r1.1)),
    ];
    Ok(render_grid_svg(&charts, 1, (1000, 400))?)
}

// ---------------------------------------------------------------------------------------------
// Run

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

/// Writes augmented.toml (and the table of an unnamed map) and estimate.json for the finding
/// `f`.
#[allow(clippy::too_many_arguments)]
fn write_augmented(
    a: &DiscoverArgs,
    mf: &ModelFile,
    nominal: &Nominal,
    header: &str,
    f: &Finding,
    settings: &DiscoverSettings,
    est: &Record,
    guard: &OutputGuard,
    written: &mut Vec<PathBuf>,
) -> Result<AugmentedFile, CliError> {
    let file = f.augmented_file(mf, settings.trend_degree())?;
    for t in file.table.iter().chain(&file.known_tables) {
        let path = a.out.join(&t.name);
        guard.write_csv(&path, &["z", "value"], &[t.z.clone(), t.w.clone()])?;
        written.push(path);
    }
    let path = a.out.join("augmented.toml");
    guard.write(&path, file.text(header).as_bytes())?;
    written.push(path);
    let stored = f
        .estimate(nominal, &est.data)?
        .with_signal_names(SignalNames {
            u: mf.signals.u.clone(),
            y: mf.signals.y.clone(),
        })?;
    let path = a.out.join(ESTIMATE_FILE);
    guard.write(&path, &estimate_json(&stored)?)?;
    written.push(path);
    Ok(file)
}

/// The figures of a discovery in `out` (residual.svg, regions.svg, and with a finding map.svg
/// and before_after.svg), each added to `written`; returns each file with its caption.
#[allow(clippy::too_many_arguments)]
fn write_figures(
    out: &std::path::Path,
    guard: &OutputGuard,
    d: &structid_discover::discover::Discovery,
    nominal: &Nominal,
    settings: &DiscoverSettings,
    est: &Record,
    val: &Record,
    written_files: &mut Vec<PathBuf>,
) -> Result<Vec<(String, String)>, CliError> {
    let mut figures: Vec<(String, String)> = Vec::new();
    let band = settings.gap().band;
    let svg = residual_svg(&d.estimation_gap, band, &est.time)?;
    let path = out.join("residual.svg");
    guard.write(&path, svg.as_bytes())?;
    written_files.push(path);
    figures.push((
        "residual.svg".into(),
        format!(
            "the nominal model's residual on the estimation record with ±{band}·σ̂ and the \
             windows above it shaded"
        ),
    ));
    let linear =
        structid_discover::records::stacked(&est.data, |r| nominal.simulate_output(r.u()))?;
    let mut candidates = candidate_signals(
        &est.data,
        &linear,
        nominal.lft().sample_time().unwrap_or(1.0),
    );
    candidates.extend(nominal.state_signals(&est.data)?);
    let path = out.join("regions.svg");
    guard.write(
        &path,
        regions_svg(&d.estimation_gap.residual, &candidates)?.as_bytes(),
    )?;
    written_files.push(path);
    figures.push((
        "regions.svg".into(),
        format!(
            "the residual binned by each candidate signal ({REGION_BINS} quantile bins: mean and \
             RMS), estimation record"
        ),
    ));
    if let Some(f) = &d.finding {
        if let Some(h) = Some(&f.hypothesis).filter(|h| !h.curve.z.is_empty()) {
            let path = out.join("map.svg");
            guard.write(&path, map_svg(nominal, h, f)?.as_bytes())?;
            written_files.push(path);
            figures.push((
                "map.svg".into(),
                "the best hypothesis' nonparametric map with its ±2σ band and points, and the \
                 map of the augmented model"
                    .into(),
            ));
        }
        let path = out.join("before_after.svg");
        guard.write(
            &path,
            before_after_svg(
                val,
                &d.validation_gap,
                &f.augmented.validation_gap,
                f.shrink,
            )?
            .as_bytes(),
        )?;
        written_files.push(path);
        figures.push((
            "before_after.svg".into(),
            "validation record: measured y, the nominal and the augmented simulation, and their \
             residuals"
                .into(),
        ));
    }

    Ok(figures)
}

/// Removes the outputs of an earlier run in `out` that this one did not write (they would
/// contradict the report); returns them.
fn remove_stale(out: &std::path::Path, written: &[PathBuf]) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    for f in planned_outputs() {
        let p = out.join(f);
        if p.is_file() && !written.contains(&p) && std::fs::remove_file(&p).is_ok() {
            removed.push(p);
        }
    }
    removed
}

/// Every file this command may write, earlier runs' extra tables included.
fn planned_outputs() -> Vec<String> {
    OUTPUTS
        .iter()
        .map(|f| f.to_string())
        .chain(
            (2..=MAX_TABLE_BLOCKS)
                .map(|i| augmented::table_file_name(&format!("{}{i}", augmented::BLOCK))),
        )
        .collect()
}

/// Warns when a validation file is also an estimation file: ranking and naming on a record the
/// maps were estimated on favour whatever overfits.
fn warn_if_validation_is_estimation(a: &DiscoverArgs) {
    let canonical = |p: &PathBuf| std::fs::canonicalize(p).ok();
    if a.validate
        .iter()
        .any(|v| a.data.iter().any(|d| canonical(d) == canonical(v)))
    {
        eprintln!(
            "warning: a --validation-data file is a --data file: the hypotheses are ranked and \
             the effect is named on a record they were estimated on, which favours whatever \
             overfits; give a separate validation record"
        );
    }
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
            .map(|p| crate::data::read_record(&mf, p))
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
    warn_if_validation_is_estimation(&a);
    // The gap's lags, as discovery sets them.
    let max_lag = settings
        .gap()
        .max_lag
        .min(structid_discover::records::shortest(&est.data) / 4)
        .max(1);

    guard.begin_set(&a.out, Some(&planned_outputs()))?;
    let command = command_line();
    let mut written_files: Vec<PathBuf> = Vec::new();
    let written = match &d.finding {
        Some(f) => {
            let header = augmented::header(&a.model, &a.out.join("report.md"), &nominal, &d, f);
            Some(write_augmented(
                &a,
                &mf,
                &nominal,
                &header,
                f,
                &settings,
                &est,
                &guard,
                &mut written_files,
            )?)
        }
        None => None,
    };

    let figures = write_figures(
        &a.out,
        &guard,
        &d,
        &nominal,
        &settings,
        &est,
        &val,
        &mut written_files,
    )?;

    // Reports.
    let context = ReportContext {
        version: env!("CARGO_PKG_VERSION"),
        command: &command,
        model_path: &a.model,
        out: &a.out,
        nominal_file: &mf,
        nominal: &nominal,
        settings: &settings,
        estimation: &est,
        validation: &val,
        augmented: written.as_ref(),
        figures: &figures,
        max_lag,
    };
    let md_path = a.out.join("report.md");
    let mut markdown = report::markdown(&d, &context);
    if let Some((effects, _)) = &effects {
        // The iteration's section right after the title and before the reported step's.
        let at = markdown.find("\n\n").map_or(0, |i| i + 2);
        markdown.insert_str(at, &report::effects_markdown(effects));
    }
    guard.write(&md_path, markdown.as_bytes())?;
    written_files.push(md_path);
    let json_path = a.out.join("report.json");
    let files: Vec<String> = written_files
        .iter()
        .chain(std::iter::once(&json_path))
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    let serialise =
        |e: serde_json::Error| CliError::runtime(format!("cannot serialise the report: {e}"));
    let mut value = report::json(&d, &context, &files).map_err(serialise)?;
    if let (Some((effects, _)), Some(object)) = (&effects, value.as_object_mut()) {
        object.insert(
            "effects".into(),
            report::effects_json(effects).map_err(serialise)?,
        );
    }
    let mut text = serde_json::to_string_pretty(&value).map_err(serialise)?;
    text.push('\n');
    guard.write(&json_path, text.as_bytes())?;
    written_files.push(json_path);

    // Outputs of an earlier run that this one did not write would contradict the report.
    let removed = remove_stale(&a.out, &written_files);
    guard.finish_set(&a.out, &structid_io::output::file_names(&written_files))?;

    if let Some((effects, _)) = &effects {
        print!("{}", report::effects_summary(effects));
    }
    print!(
        "{}",
        report::summary(
            &d,
            &context,
            &written_files,
            &removed,
            t0.elapsed().as_secs_f64()
        )
    );
    Ok(())
}

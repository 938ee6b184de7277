//! `structid discover`: from a nominal linear model that almost fits to a named missing effect,
//! its place in the structure and an augmented model file (see
//! `structid_discover::discover`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use serde_json::{Value, json};
use structid_core::validation::{ValidationSettings, validate};
use structid_core::{Data, InitialState, Interpolant, Lft, LookupTable};
use structid_discover::discover::{
    AugmentedMap, Classification, DiscoverSettings, Discovery, Finding, HypothesisResult,
    candidate_signals, discover,
};
use structid_discover::effects::EffectFit;
use structid_discover::gap::Gap;
use structid_discover::hypotheses::{Location, Nominal};
use structid_discover::localise::binned_residual;
use structid_io::{
    BlockSpec, DataTable, DispersionSpec, LinearSpec, ModelFile, OutputGuard, SignalNames,
    TruthSpec, format_number,
};
use structid_lti::LinearSystem as _;
use structid_plot::{Chart, Series, render_chart_svg, render_grid_svg};

use crate::error::CliError;
use crate::identify::absolute;

/// Most points per line in the time-series figures (longer records are drawn decimated).
const MAX_PLOT_POINTS: usize = 4000;
/// Most points drawn as dots in map.svg.
const MAX_DOTS: usize = 2000;
/// Bins of the binned residual in regions.svg.
const REGION_BINS: usize = 20;
/// Largest relative difference between the validation RMS of augmented.toml read back and that
/// of the report.
pub const SELF_CHECK_TOLERANCE: f64 = 1e-6;
/// The name of the block added to the nominal model.
const BLOCK: &str = "N";
/// The file of an unnamed (or dynamic) map's table.
const TABLE_FILE: &str = "N_table.csv";
/// Weight of each normalised monomial of the trend: the value `structid_discover` uses, so
/// that `structid identify` on augmented.toml has the hypothesis' dispersion.
const TREND_SCALE: f64 = 10.0;
/// Rows of the window table in report.md per record.
const MAX_WINDOW_ROWS: usize = 20;

/// Every file `structid discover` may write, in the order of the summary.
const OUTPUTS: [&str; 8] = [
    "augmented.toml",
    TABLE_FILE,
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
    /// The nominal model file: one input, one output, no `[[nonlinearity]]`, its linear block as
    /// `[linear]` with structure = "lti" (write one with `structid linear --structure lti`) or
    /// as `[lft]`.
    #[arg(long, short = 'm', value_name = "MODEL.toml")]
    model: PathBuf,
    /// The estimation record (CSV with the columns named in the model's `[signals]`): every
    /// hypothesis' map is identified on it.
    #[arg(long, short = 'd', value_name = "EST.csv")]
    data: PathBuf,
    /// The validation record (CSV like --data): hypotheses are ranked, and effects named, by
    /// their simulation error on it.
    #[arg(long, value_name = "VAL.csv")]
    validate: PathBuf,
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
    /// A family is named when the validation RMS with its parametric map is at most T times
    /// that with the nonparametric map (or within 1.5 × the noise level); T ≥ 1.
    #[arg(
        long,
        value_name = "T",
        allow_negative_numbers = true,
        default_value_t = DiscoverSettings::default().naming_tolerance()
    )]
    naming_tolerance: f64,
    /// Share of the deconvolved residual energy (0 < T < 1) that the direction of z must
    /// explain for the effect to be reported as dynamic (hysteresis or backlash suspected).
    #[arg(
        long,
        value_name = "T",
        allow_negative_numbers = true,
        default_value_t = DiscoverSettings::default().hysteresis_threshold()
    )]
    hysteresis_threshold: f64,
}

/// The time axis of a record: a `time` (or `t`) column, the model's sample time, or the sample
/// index.
struct TimeAxis {
    values: Vec<f64>,
    label: &'static str,
    /// Whether the values are times (not sample indices).
    is_time: bool,
}

impl TimeAxis {
    fn new(table: &DataTable, len: usize, sample_time: Option<f64>) -> Self {
        for name in ["time", "t"] {
            if let Some(c) = table.column(name)
                && c.len() == len
            {
                return Self {
                    values: c.to_vec(),
                    label: "time",
                    is_time: true,
                };
            }
        }
        match sample_time {
            Some(ts) => Self {
                values: (0..len).map(|k| k as f64 * ts).collect(),
                label: "time [s]",
                is_time: true,
            },
            None => Self {
                values: (0..len).map(|k| k as f64).collect(),
                label: "sample",
                is_time: false,
            },
        }
    }

    fn at(&self, k: usize) -> f64 {
        self.values.get(k).copied().unwrap_or(f64::NAN)
    }
}

/// One record as read.
struct Record {
    path: PathBuf,
    table: DataTable,
    data: Data,
    time: TimeAxis,
}

/// What the augmented model file is and how it was checked.
struct Written {
    /// `[linear] structure = "…"`, or `[lft]`.
    form: String,
    /// The table's file when the map is a table.
    table: Option<String>,
    /// The validation RMS of augmented.toml read back.
    rms: f64,
    /// Its relative difference from the report's.
    difference: f64,
    /// Initial state of the reproduction.
    initial_state: InitialState,
}

// ---------------------------------------------------------------------------------------------
// Inputs

/// The nominal model of a model file, or a clear input error.
fn nominal(mf: &ModelFile, path: &Path) -> Result<Nominal, CliError> {
    let how = "write one with `structid linear --data EST.csv --structure lti --out MODEL.toml`, \
               or give the linear block as [lft] without [[nonlinearity]]";
    if !mf.blocks.is_empty() {
        return Err(CliError::input(format!(
            "`{}` has {} [[nonlinearity]] block(s) ({}); discovery starts from a nominal linear \
             model without maps ({how})",
            path.display(),
            mf.blocks.len(),
            mf.blocks
                .iter()
                .map(|b| format!("`{}`", b.name))
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    if mf.signals.u.len() != 1 || mf.signals.y.len() != 1 {
        return Err(CliError::input(format!(
            "`{}` has {} input(s) and {} output(s) in [signals]; discovery needs a nominal model \
             with one input and one output",
            path.display(),
            mf.signals.u.len(),
            mf.signals.y.len()
        )));
    }
    if mf.signals.z.is_some() {
        return Err(CliError::input(format!(
            "`{}` lists measured z columns ([signals].z); discovery computes z for each \
             candidate location itself: remove [signals].z",
            path.display()
        )));
    }
    let mut nominal = match &mf.linear {
        Some(spec) if spec.structure.is_none() => Nominal::from_polynomial(&spec.model)?,
        Some(spec) => {
            return Err(CliError::input(format!(
                "`{}` has [linear] structure = \"{}\"; discovery needs structure = \"lti\" ({how})",
                path.display(),
                spec.structure_name()
            )));
        }
        None => Nominal::new(mf.lft.clone())?,
    };
    // The locations and states the model file declares ([discover]).
    if let Some(d) = &mf.discover {
        for l in &d.locations {
            nominal = nominal.with_location(&l.name, l.z, l.w)?;
        }
        for st in &d.states {
            nominal = nominal.with_state(&st.name, st.state)?;
        }
    }
    Ok(nominal)
}

/// `--locations`: keys of the built-in locations, `declared-i`, or names of declared ones.
fn parse_locations(
    given: Option<&[String]>,
    nominal: &Nominal,
) -> Result<Option<Vec<Location>>, CliError> {
    let Some(given) = given else {
        return Ok(None);
    };
    let mut out: Vec<Location> = Vec::new();
    for raw in given {
        let s = raw.trim();
        let found = nominal
            .locations()
            .into_iter()
            .find(|l| nominal.key(*l) == s)
            .or_else(|| {
                nominal
                    .declared()
                    .iter()
                    .find(|d| d.name == s)
                    .map(|d| Location::Declared { z: d.z, w: d.w })
            });
        let Some(location) = found else {
            let mut known: Vec<String> = nominal
                .locations()
                .iter()
                .map(|l| format!("`{}`", nominal.key(*l)))
                .collect();
            known.extend(nominal.declared().iter().map(|d| format!("`{}`", d.name)));
            return Err(CliError::input(format!(
                "invalid value `{s}` for --locations: the candidate locations of this nominal \
                 model are {}",
                known.join(", ")
            )));
        };
        if !out.contains(&location) {
            out.push(location);
        }
    }
    if out.is_empty() {
        return Err(CliError::input(
            "--locations names no location; omit it to try every one",
        ));
    }
    Ok(Some(out))
}

fn settings(
    a: &DiscoverArgs,
    locations: Option<Vec<Location>>,
) -> Result<DiscoverSettings, CliError> {
    if !(a.sigma_fraction.is_finite() && a.sigma_fraction > 0.0) {
        return Err(CliError::input(format!(
            "invalid value {} for --sigma-fraction: it must be a finite fraction of the range of z \
             greater than zero",
            a.sigma_fraction
        )));
    }
    if a.trend > 64 {
        return Err(CliError::input(format!(
            "invalid value {} for --trend: the polynomial degree must be at most 64",
            a.trend
        )));
    }
    if !(a.naming_tolerance.is_finite() && a.naming_tolerance >= 1.0) {
        return Err(CliError::input(format!(
            "invalid value {} for --naming-tolerance: it is a ratio of validation RMS values and \
             must be at least 1",
            a.naming_tolerance
        )));
    }
    if !(a.hysteresis_threshold > 0.0 && a.hysteresis_threshold < 1.0) {
        return Err(CliError::input(format!(
            "invalid value {} for --hysteresis-threshold: it is a share of the residual energy \
             and must lie strictly between 0 and 1",
            a.hysteresis_threshold
        )));
    }
    let mut b = DiscoverSettings::builder()
        .total_variation(!a.no_tv)
        .settle(a.settle)
        .sigma_fraction(a.sigma_fraction)
        .trend_degree(a.trend)
        .tune_sigma(a.tune_sigma)
        .naming_tolerance(a.naming_tolerance)
        .hysteresis_threshold(a.hysteresis_threshold);
    if let Some(l) = locations {
        b = b.locations(l);
    }
    Ok(b.build()?)
}

fn read_record(mf: &ModelFile, path: &Path) -> Result<Record, CliError> {
    let table = DataTable::read(path)?;
    let data = mf.select_data(&table)?;
    let time = TimeAxis::new(&table, data.len(), mf.lft.sample_time());
    Ok(Record {
        path: path.to_path_buf(),
        table,
        data,
        time,
    })
}

// ---------------------------------------------------------------------------------------------
// The augmented model file

/// How the initial state is treated at `location` (as `structid_discover` does): estimated,
/// except for the sensor map and the rate, whose z would depend on an unknown x₀.
fn initial_state(location: Location) -> InitialState {
    structid_discover::discover::initial_state(location).1
}

fn initial_state_name(s: InitialState) -> &'static str {
    match s {
        InitialState::Zero => "zero",
        InitialState::Estimate => "estimate",
    }
}

/// The dispersion written for the block: the hypothesis' Fourier kernel (its σ) plus the
/// polynomial trend, so that `structid identify` re-estimates the map as discovery did.
fn block_dispersion(sigma: Option<f64>, trend: usize) -> DispersionSpec {
    let kernel = DispersionSpec::Fourier {
        sigma,
        harmonics: None,
        additive: false,
    };
    if trend == 0 {
        kernel
    } else {
        DispersionSpec::WithTrend {
            kernel: Box::new(kernel),
            degree: trend,
            scale: Some(TREND_SCALE),
        }
    }
}

/// The augmented model file: the nominal file's signals, the block `N` at `location` with
/// `map` as its truth (a table is given as `table_file`, to be written next to the model
/// file), and the linear part as `[linear]` when the nominal file has one and the location is
/// a structure `[linear]` knows, otherwise as the hypothesis' `lft`. Returns the file and its
/// form.
fn augmented_file(
    nominal_mf: &ModelFile,
    location: Location,
    lft: &Lft,
    map: &AugmentedMap,
    dispersion: DispersionSpec,
    table_file: &str,
) -> Result<(ModelFile, String), CliError> {
    // Output feedback gets a shared numerator, as `structid linear --structure
    // output-feedback` writes it: y = B/F·(u − w), i.e. num = [B, −B].
    let linear = match (&nominal_mf.linear, location) {
        (_, Location::Declared { .. }) | (None, _) => None,
        (Some(spec), site) => Some(LinearSpec::from_linear(&spec.model, Some(site))),
    };
    let (lft, form) = match &linear {
        Some(spec) => (
            spec.lft()?,
            format!("[linear] structure = \"{}\"", spec.structure_name()),
        ),
        None => (lft.clone(), "[lft]".to_string()),
    };
    let truth = match map {
        AugmentedMap::Expression(e) => TruthSpec::Expression(e.clone()),
        AugmentedMap::Table { z, w } => TruthSpec::Table {
            file: table_file.to_string(),
            table: LookupTable::one_d(z.clone(), w.clone())?,
        },
    };
    let mf = ModelFile {
        discover: None,
        lft,
        linear,
        signals: SignalNames {
            u: nominal_mf.signals.u.clone(),
            y: nominal_mf.signals.y.clone(),
            z: None,
        },
        blocks: vec![BlockSpec {
            name: BLOCK.into(),
            inputs: vec![0],
            output: 0,
            dispersion,
            truth: Some(truth),
        }],
        path: None,
    };
    Ok((mf, form))
}

/// Reads `path` back and simulates it with its truth map on `val` (columns by the file's own
/// `[signals]`) as `structid validate --model path` does: the simulation RMS.
fn simulate_file(
    path: &Path,
    val: &DataTable,
    initial_state: InitialState,
    max_lag: usize,
) -> Result<f64, CliError> {
    let back = |e: String| {
        CliError::runtime(format!(
            "internal error: `{}` does not read back: {e}",
            path.display()
        ))
    };
    let mf = ModelFile::from_path(path).map_err(|e| back(e.to_string()))?;
    let maps = mf
        .truth_maps()
        .map_err(|e| back(e.to_string()))?
        .ok_or_else(|| back("its block has no truth".into()))?;
    let model = mf.to_model(None, None).map_err(|e| back(e.to_string()))?;
    let data = mf.select_data(val)?;
    let refs: Vec<&dyn Interpolant> = maps.iter().map(|m| m.as_ref()).collect();
    let settings = ValidationSettings::builder()
        .initial_state(initial_state)
        .max_lag(max_lag)
        .build()?;
    let v = validate(&model, &refs, &data, &settings)
        .map_err(|e| back(format!("its simulation fails: {e}")))?;
    Ok(v.rms[0])
}

/// Writes augmented.toml (and the table of an unnamed map), reads it back and checks that it
/// reproduces the validation RMS of the report.
fn write_augmented(
    a: &DiscoverArgs,
    nominal_mf: &ModelFile,
    f: &Finding,
    trend: usize,
    header: &str,
    val: &Record,
    max_lag: usize,
    guard: &OutputGuard,
    written: &mut Vec<PathBuf>,
) -> Result<Written, CliError> {
    let sigma = f
        .augmented
        .model
        .blocks()
        .first()
        .and_then(|b| b.dispersion.width());
    let (mf, form) = augmented_file(
        nominal_mf,
        f.location,
        f.augmented.model.lft(),
        &f.augmented.map,
        match sigma {
            Some(_) => block_dispersion(sigma, trend),
            // The map was estimated with total variation, which has no width.
            None => DispersionSpec::TotalVariation {
                neighbours: None,
                interpolation: None,
            },
        },
        TABLE_FILE,
    )?;
    let table = match &f.augmented.map {
        AugmentedMap::Table { z, w } => {
            let path = a.out.join(TABLE_FILE);
            guard.write_csv(&path, &["z", "value"], &[z.clone(), w.clone()])?;
            written.push(path);
            Some(TABLE_FILE.to_string())
        }
        AugmentedMap::Expression(_) => None,
    };
    let path = a.out.join("augmented.toml");
    let mut text = String::from(header);
    text.push_str(&mf.to_toml_string());
    guard.write(&path, text.as_bytes())?;
    written.push(path.clone());

    let initial_state = initial_state(f.location);
    let expected = f.augmented.validation_gap.rms;
    let rms = simulate_file(&path, &val.table, initial_state, max_lag)?;
    let difference = (rms - expected).abs() / expected.abs().max(f64::MIN_POSITIVE);
    if difference.is_nan() || difference > SELF_CHECK_TOLERANCE {
        // Never leave a model file behind that does not reproduce the report.
        let _ = std::fs::remove_file(&path);
        return Err(CliError::runtime(format!(
            "internal error: the augmented model file does not reproduce the discovery: read back \
             and simulated on `{}` (initial state {}), its validation RMS is {rms:.6e}, but the \
             discovery's is {expected:.6e} (relative difference {difference:.2e} > \
             {SELF_CHECK_TOLERANCE:e}); `{}` was removed",
            val.path.display(),
            initial_state_name(initial_state),
            path.display()
        )));
    }
    Ok(Written {
        form,
        table,
        rms,
        difference,
        initial_state,
    })
}

// ---------------------------------------------------------------------------------------------
// Figures

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
    let r = pick(&g.residual, &idx);
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
        .with(Series::line("residual", &t, &r))
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

fn z_label(location: Location) -> &'static str {
    match location {
        Location::Input => "z = u",
        Location::Output => "z = G·u",
        Location::OutputFeedback => "z = y",
        Location::RateFeedback => "z = ẏ",
        Location::Declared { .. } => "z",
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
            f.classification.describe()
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
    let idx = plot_indices(before.simulated.len());
    let t = pick(&val.time.values, &idx);
    let y = pick(&val.data.y().channel(0), &idx);
    let nominal = pick(&before.simulated, &idx);
    let augmented = pick(&after.simulated, &idx);
    let r0 = pick(&before.residual, &idx);
    let r1 = pick(&after.residual, &idx);
    let charts = [
        Chart::new(
            format!(
                "Validation record: measured and simulated (fit {:.1} % → {:.1} %)",
                before.fit_percent, after.fit_percent
            ),
            val.time.label,
            "y",
        )
        .with(Series::line("measured y", &t, &y))
        .with(Series::line("nominal model", &t, &nominal))
        .with(Series::line("augmented model", &t, &augmented)),
        Chart::new(
            format!(
                "Residuals y − ŷ (RMS {:.3e} → {:.3e}, {:.1}× smaller)",
                before.rms, after.rms, shrink
            ),
            val.time.label,
            "y − ŷ",
        )
        .with(Series::line("nominal model", &t, &r0))
        .with(Series::line("augmented model", &t, &r1)),
    ];
    Ok(render_grid_svg(&charts, 1, (1000, 400))?)
}

// ---------------------------------------------------------------------------------------------
// report.md

fn e(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4e}")
    } else if v.is_nan() {
        "—".into()
    } else {
        "∞".into()
    }
}

fn pct(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.1} %")
    } else {
        "—".into()
    }
}

fn g4(v: f64) -> String {
    if !v.is_finite() {
        return e(v);
    }
    if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// `|`-safe text for a Markdown table cell.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

fn location_text(nominal: &Nominal, l: Location) -> String {
    format!("`{}` ({})", nominal.key(l), nominal.describe(l))
}

fn gap_table(s: &mut String, estimation: &Gap, validation: &Gap) {
    let _ = writeln!(s, "| | estimation record | validation record |");
    let _ = writeln!(s, "|---|---|---|");
    let _ = writeln!(
        s,
        "| simulation RMS of y − ŷ | {} | {} |",
        e(estimation.rms),
        e(validation.rms)
    );
    let _ = writeln!(
        s,
        "| one-step prediction RMS of ε | {} | {} |",
        e(estimation.prediction_rms),
        e(validation.prediction_rms)
    );
    let _ = writeln!(
        s,
        "| fit | {} | {} |",
        pct(estimation.fit_percent),
        pct(validation.fit_percent)
    );
    let _ = writeln!(
        s,
        "| noise level σ̂ (MAD of Δε) | {} | {} |",
        e(estimation.noise_std),
        e(validation.noise_std)
    );
    let _ = writeln!(
        s,
        "| RMS(ε) / σ̂ | {:.2} | {:.2} |",
        estimation.prediction_rms / estimation.noise_std.max(f64::MIN_POSITIVE),
        validation.prediction_rms / validation.noise_std.max(f64::MIN_POSITIVE)
    );
    let _ = writeln!(
        s,
        "| missing effect | {} | {} |",
        if estimation.missing_effect {
            "yes"
        } else {
            "no"
        },
        if validation.missing_effect {
            "yes"
        } else {
            "no"
        }
    );
    s.push('\n');
    let _ = writeln!(
        s,
        "Portmanteau tests (the family at the 0.1 % level, Bonferroni; ε are the one-step \
         prediction errors):\n"
    );
    let _ = writeln!(
        s,
        "| test | record | statistic | critical value | lags | result |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (record, g) in [("estimation", estimation), ("validation", validation)] {
        for t in &g.tests {
            let _ = writeln!(
                s,
                "| {} | {record} | {:.1} | {:.1} | {} | {} |",
                cell(&t.name),
                t.statistic,
                t.critical,
                t.lags,
                if t.passes() { "pass" } else { "**FAIL**" }
            );
        }
    }
    s.push('\n');
    for (record, g) in [("estimation", estimation), ("validation", validation)] {
        let _ = writeln!(s, "- {record} record: {}", g.verdict);
    }
    s.push('\n');
}

fn windows_section(s: &mut String, records: [(&str, &Gap, &TimeAxis); 2], band: f64) {
    for (record, g, time) in records {
        if g.windows.is_empty() {
            let _ = writeln!(
                s,
                "- {record} record: none; the moving RMS of the residual stays below {band}·σ̂ = {}.",
                e(band * g.noise_std)
            );
            continue;
        }
        let samples: usize = g.windows.iter().map(|w| w.len()).sum();
        let _ = writeln!(
            s,
            "- {record} record: {} window(s) above {band}·σ̂ = {}, {samples} of {} samples \
             ({:.1} %):\n",
            g.windows.len(),
            e(band * g.noise_std),
            g.residual.len(),
            100.0 * samples as f64 / g.residual.len().max(1) as f64
        );
        if time.is_time {
            let _ = writeln!(s, "  | samples | {} |", time.label);
            let _ = writeln!(s, "  |---|---|");
        } else {
            let _ = writeln!(s, "  | samples |");
            let _ = writeln!(s, "  |---|");
        }
        for w in g.windows.iter().take(MAX_WINDOW_ROWS) {
            if time.is_time {
                let _ = writeln!(
                    s,
                    "  | {}…{} | {} … {} |",
                    w.start,
                    w.end.saturating_sub(1),
                    g4(time.at(w.start)),
                    g4(time.at(w.end.saturating_sub(1)))
                );
            } else {
                let _ = writeln!(s, "  | {}…{} |", w.start, w.end.saturating_sub(1));
            }
        }
        if g.windows.len() > MAX_WINDOW_ROWS {
            let _ = writeln!(
                s,
                "\n  … and {} more (all in report.json).",
                g.windows.len() - MAX_WINDOW_ROWS
            );
        }
        s.push('\n');
    }
}

fn regions_section(s: &mut String, estimation: &Gap, validation: &Gap) {
    let _ = writeln!(
        s,
        "For each candidate signal, the region where the residual energy concentrates most \
         (candidates ranked by η², the share of the variance of ε² that quantile bins of the \
         signal explain; lift = energy share / sample share):\n"
    );
    let _ = writeln!(
        s,
        "| record | signal | region | share of samples | share of residual energy | lift | η² |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for (record, g) in [("estimation", estimation), ("validation", validation)] {
        for r in &g.regions {
            let _ = writeln!(
                s,
                "| {record} | {} | `{}` | {:.1} % | {:.1} % | {:.2} | {:.3} |",
                cell(&r.signal),
                cell(&r.describe()),
                100.0 * r.sample_share,
                100.0 * r.energy_share,
                r.lift,
                r.eta_squared
            );
        }
    }
    s.push('\n');
}

fn parameters_text(fit: &EffectFit) -> String {
    fit.parameters
        .iter()
        .map(|p| {
            format!(
                "{} = {} [{}, {}]",
                p.name,
                g4(p.value),
                g4(p.interval.0),
                g4(p.interval.1)
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

struct ReportInputs<'a> {
    a: &'a DiscoverArgs,
    nominal_mf: &'a ModelFile,
    nominal: &'a Nominal,
    settings: &'a DiscoverSettings,
    est: &'a Record,
    val: &'a Record,
    d: &'a Discovery,
    written: Option<&'a Written>,
    figures: &'a [(String, String)],
    command: &'a str,
    max_lag: usize,
}

fn nominal_text(mf: &ModelFile) -> String {
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format_number(*x))
            .collect::<Vec<_>>()
            .join(", ")
    };
    match &mf.linear {
        Some(spec) => format!(
            "`[linear]` lti, den = [{}], num = [{}]",
            list(&spec.model.den),
            list(&spec.model.num[0])
        ),
        None => format!("`[lft]` with {} state(s)", mf.lft.dims().states),
    }
}

fn validate_command(r: &ReportInputs<'_>, w: &Written) -> String {
    format!(
        "structid validate --model {} --data {} --out {} --initial-state {}",
        r.a.out.join("augmented.toml").display(),
        r.val.path.display(),
        r.a.out.join("validation").display(),
        initial_state_name(w.initial_state)
    )
}

fn identify_command(r: &ReportInputs<'_>, f: &Finding) -> String {
    let beta = f.hypothesis.beta;
    format!(
        "structid identify --model {} --data {} --out {} --beta {} --initial-state {}",
        r.a.out.join("augmented.toml").display(),
        r.est.path.display(),
        r.a.out.join("identify").display(),
        format_number(beta),
        initial_state_name(initial_state(f.location))
    )
}

fn report_md(r: &ReportInputs<'_>) -> String {
    let d = r.d;
    let mut s = String::new();
    let _ = writeln!(s, "# structid discover\n");
    let _ = writeln!(s, "**Verdict:** {}\n", d.verdict);
    let _ = writeln!(
        s,
        "Nominal model `{}` ({}); estimation record `{}` ({} samples), validation record `{}` \
         ({} samples); {:.1} s.\n",
        r.a.model.display(),
        nominal_text(r.nominal_mf),
        r.est.path.display(),
        r.est.data.len(),
        r.val.path.display(),
        r.val.data.len(),
        d.seconds
    );

    let _ = writeln!(s, "## 1. The gap: nominal model against the records\n");
    gap_table(&mut s, &d.estimation_gap, &d.validation_gap);

    let band = r.settings.gap().band;
    let _ = writeln!(s, "## 2. Where in time\n");
    let _ = writeln!(
        s,
        "Windows where the moving RMS of the residual exceeds {band}·σ̂:\n"
    );
    windows_section(
        &mut s,
        [
            ("estimation", &d.estimation_gap, &r.est.time),
            ("validation", &d.validation_gap, &r.val.time),
        ],
        band,
    );

    let _ = writeln!(s, "## 3. Where in operating space\n");
    regions_section(&mut s, &d.estimation_gap, &d.validation_gap);

    if d.hypotheses.is_empty() {
        let _ = writeln!(
            s,
            "No hypotheses were tried: the nominal model's residual is within {}× its noise \
             level and passes every test on both records.\n",
            r.settings.gap().noise_ratio
        );
    } else {
        if !d.missing_effect {
            let _ = writeln!(
                s,
                "A test of the nominal model's gap failed (section 1), so every candidate \
                 location was tried; none reduces the validation RMS enough to confirm a \
                 missing effect (see the verdict).\n"
            );
        }
        let _ = writeln!(s, "## 4. Where in the structure: hypotheses\n");
        let _ = writeln!(
            s,
            "One unknown static block N at each candidate location, identified on the \
             estimation record (Fourier kernel plus polynomial trend, β by marginal likelihood) \
             and ranked by the simulation RMS on the validation record:\n"
        );
        let _ = writeln!(
            s,
            "| rank | location | dispersion | β | σ | estimation RMS | validation RMS | seconds | failure |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
        for (i, h) in d.hypotheses.iter().enumerate() {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} | {:.2} | {} |",
                i + 1,
                cell(&location_text(r.nominal, h.location)),
                cell(&h.dispersion),
                e(h.beta),
                h.sigma.map(g4).unwrap_or_else(|| "fixed".into()),
                e(h.estimation_rms),
                e(h.validation_rms),
                h.seconds,
                h.failure.as_deref().map(cell).unwrap_or_default()
            );
        }
        s.push('\n');
    }

    if let Some(f) = &d.finding {
        finding_md(&mut s, r, f);
    } else if d.missing_effect {
        let _ = writeln!(
            s,
            "No hypothesis could be identified and simulated, so no augmented model was written.\n"
        );
    }

    let _ = writeln!(s, "## Figures\n");
    for (file, what) in r.figures {
        let _ = writeln!(s, "- [{file}]({file}): {what}");
    }
    s.push('\n');
    let _ = writeln!(s, "## Reproduce\n");
    let _ = writeln!(s, "```sh\n{}", r.command);
    if let (Some(f), Some(w)) = (&d.finding, r.written) {
        let _ = writeln!(s, "{}", validate_command(r, w));
        let _ = writeln!(s, "{}", identify_command(r, f));
        let _ = writeln!(s, "```\n");
        let _ = writeln!(
            s,
            "The first line reruns the discovery. The second simulates `augmented.toml` with its \
             map on the validation record (initial state {}, no settling samples): its RMS is \
             that of the gap after ({}; checked when the file was written, relative difference \
             {:.1e}). The third re-estimates N nonparametrically with the hypothesis' dispersion \
             and β.",
            initial_state_name(w.initial_state),
            e(w.rms),
            w.difference
        );
    } else {
        let _ = writeln!(s, "```");
    }
    s
}

fn finding_md(s: &mut String, r: &ReportInputs<'_>, f: &Finding) {
    let _ = writeln!(s, "## 5. What it is\n");
    let kind = match &f.classification {
        Classification::Named(_) => "named",
        Classification::Unnamed => "unnamed",
        Classification::Dynamic => "dynamic",
    };
    let _ = writeln!(
        s,
        "**{}** ({kind}) {}.\n",
        f.classification.describe(),
        r.nominal.describe(f.location)
    );
    if let Classification::Named(fit) = &f.classification {
        let _ = writeln!(s, "- map: `{}`", fit.expression);
        let _ = writeln!(s, "- parameters (95 % intervals): {}", parameters_text(fit));
    }
    let _ = writeln!(
        s,
        "- named from the {} estimate; its validation RMS {}{}",
        f.estimator,
        e(f.nonparametric_rms),
        f.total_variation_rms
            .map(|v| format!(" (total variation tried: {})", e(v)))
            .unwrap_or_default()
    );
    let _ = writeln!(
        s,
        "- equivalent locations (the same model for a linear G): {}",
        if f.equivalent_locations.len() > 1 {
            f.equivalent_locations
                .iter()
                .map(|l| format!("`{}`", r.nominal.key(*l)))
                .collect::<Vec<_>>()
                .join(", ")
        } else {
            format!("none besides `{}`", r.nominal.key(f.location))
        }
    );
    s.push('\n');
    let _ = writeln!(
        s,
        "Families fitted to the points (z_k, ŵ_k), best BIC first (validation RMS for those \
         simulated; a family is named when it is within {}× the nonparametric map's, or within \
         1.5 σ̂):\n",
        r.settings.naming_tolerance()
    );
    let _ = writeln!(
        s,
        "| rank | family | parameters (95 % interval) | RMS | BIC | validation RMS |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (i, fit) in f.naming.ranked.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1} | {} |",
            i + 1,
            cell(&fit.effect.name()),
            cell(&parameters_text(fit)),
            e(fit.rms),
            fit.bic,
            f.family_rms
                .get(i)
                .copied()
                .flatten()
                .map(e)
                .unwrap_or_else(|| "—".into())
        );
    }
    s.push('\n');
    let _ = writeln!(
        s,
        "Direction test (residual deconvolved to the block's output, split by the direction of \
         z within z-bins): the direction explains {:.1} % of its energy, t = {:.2}, {} samples; \
         threshold {:.0} % → {}.\n",
        100.0 * f.direction.explained,
        f.direction.t_statistic,
        f.direction.samples,
        100.0 * r.settings.hysteresis_threshold(),
        if f.direction.dynamic {
            "dynamic (hysteresis or backlash suspected)"
        } else {
            "static"
        }
    );
    if !f.remarks.is_empty() {
        let _ = writeln!(s, "Remarks:\n");
        for m in &f.remarks {
            let _ = writeln!(s, "- {m}");
        }
        s.push('\n');
    }
    let _ = writeln!(s, "## 6. The gap after: augmented model\n");
    let _ = writeln!(
        s,
        "The nominal model with N {} ({}).\n",
        r.nominal.describe(f.location),
        match &f.augmented.map {
            AugmentedMap::Expression(x) => format!("N(z) = `{x}`"),
            AugmentedMap::Table { z, .. } =>
                format!("N as a table of {} points in `{TABLE_FILE}`", z.len()),
        }
    );
    gap_table(s, &f.augmented.estimation_gap, &f.augmented.validation_gap);
    let _ = writeln!(
        s,
        "**Shrink factor:** validation RMS {} → {} ({:.2}× smaller); fit {} → {}.\n",
        e(r.d.validation_gap.rms),
        e(f.augmented.validation_gap.rms),
        f.shrink,
        pct(r.d.validation_gap.fit_percent),
        pct(f.augmented.validation_gap.fit_percent)
    );
    if let Some(w) = r.written {
        let _ = writeln!(
            s,
            "The augmented model is `augmented.toml` ({}{}; block `{BLOCK}` with the map as its \
             `truth` and the hypothesis' dispersion, so that `structid identify` can re-estimate \
             it).\n",
            w.form,
            w.table
                .as_ref()
                .map(|t| format!(", table `{t}`"))
                .unwrap_or_default()
        );
    }
}

// ---------------------------------------------------------------------------------------------
// report.json

fn json_value<T: serde::Serialize>(v: &T) -> Result<Value, CliError> {
    serde_json::to_value(v)
        .map_err(|e| CliError::runtime(format!("cannot serialise the report: {e}")))
}

fn gap_json(g: &Gap, time: &TimeAxis) -> Result<Value, CliError> {
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
        .collect::<Result<Vec<Value>, CliError>>()?;
    Ok(json!({
        "rms": g.rms,
        "prediction_rms": g.prediction_rms,
        "fit_percent": g.fit_percent,
        "noise_std": g.noise_std,
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
        "missing_effect": g.missing_effect,
        "verdict": g.verdict,
    }))
}

fn fit_json(fit: &EffectFit, validation_rms: Option<f64>) -> Result<Value, CliError> {
    Ok(json!({
        "name": fit.effect.name(),
        "family": json_value(&fit.effect)?,
        "expression": fit.expression,
        "parameters": fit.parameters.iter().map(|p| json!({
            "name": p.name,
            "value": p.value,
            "interval": [p.interval.0, p.interval.1],
        })).collect::<Vec<_>>(),
        "rms": fit.rms,
        "bic": fit.bic,
        "validation_rms": validation_rms,
    }))
}

fn report_json(r: &ReportInputs<'_>, files: &[String]) -> Result<Value, CliError> {
    let d = r.d;
    let hypotheses: Vec<Value> = d
        .hypotheses
        .iter()
        .map(|h| {
            json!({
                "location": r.nominal.key(h.location),
                "description": r.nominal.describe(h.location),
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
            };
            let families = f
                .naming
                .ranked
                .iter()
                .enumerate()
                .map(|(i, fit)| fit_json(fit, f.family_rms.get(i).copied().flatten()))
                .collect::<Result<Vec<Value>, CliError>>()?;
            let curve = Some(json_value(&f.hypothesis.curve)?);
            let map = match &f.augmented.map {
                AugmentedMap::Expression(x) => json!({ "expression": x }),
                AugmentedMap::Table { z, .. } => json!({ "table": TABLE_FILE, "points": z.len() }),
            };
            json!({
                "location": r.nominal.key(f.location),
                "description": r.nominal.describe(f.location),
                "equivalent_locations": f.equivalent_locations.iter().map(|l| r.nominal.key(*l)).collect::<Vec<_>>(),
                "classification": { "kind": kind, "description": f.classification.describe() },
                "named_effect": named,
                "estimator": f.estimator,
                "nonparametric_validation_rms": f.nonparametric_rms,
                "total_variation_validation_rms": f.total_variation_rms,
                "families": families,
                "direction": json_value(&f.direction)?,
                "remarks": f.remarks,
                "map": map,
                "curve": curve,
                "gap_after": {
                    "estimation": gap_json(&f.augmented.estimation_gap, &r.est.time)?,
                    "validation": gap_json(&f.augmented.validation_gap, &r.val.time)?,
                },
                "shrink": f.shrink,
            })
        }
    };
    let augmented = match (r.written, &d.finding) {
        (Some(w), Some(f)) => json!({
            "model_file": "augmented.toml",
            "form": w.form,
            "table_file": w.table,
            "block": BLOCK,
            "initial_state": initial_state_name(w.initial_state),
            "self_check": {
                "validation_rms": w.rms,
                "report_validation_rms": f.augmented.validation_gap.rms,
                "relative_difference": w.difference,
                "tolerance": SELF_CHECK_TOLERANCE,
            },
            "reproduce": validate_command(r, w),
            "reestimate": identify_command(r, f),
        }),
        _ => Value::Null,
    };
    let s = r.settings;
    Ok(json!({
        "tool": format!("structid {}", env!("CARGO_PKG_VERSION")),
        "version": env!("CARGO_PKG_VERSION"),
        "command": r.command,
        "inputs": {
            "model_file": r.a.model.display().to_string(),
            "model_file_absolute": absolute(&r.a.model).display().to_string(),
            "data_file": r.est.path.display().to_string(),
            "data_file_absolute": absolute(&r.est.path).display().to_string(),
            "validation_file": r.val.path.display().to_string(),
            "validation_file_absolute": absolute(&r.val.path).display().to_string(),
            "estimation_samples": r.est.data.len(),
            "validation_samples": r.val.data.len(),
            "sample_time": r.nominal_mf.lft.sample_time(),
        },
        "settings": {
            "locations": s.locations().map(|l| l.iter().map(|l| r.nominal.key(*l)).collect::<Vec<_>>()),
            "total_variation": s.total_variation(),
            "settle": s.settle(),
            "sigma_fraction": s.sigma_fraction(),
            "trend_degree": s.trend_degree(),
            "tune_sigma": s.tune_sigma(),
            "naming_tolerance": s.naming_tolerance(),
            "hysteresis_threshold": s.hysteresis_threshold(),
            "band": s.gap().band,
            "noise_ratio": s.gap().noise_ratio,
            "max_lag": r.max_lag,
        },
        "verdict": d.verdict,
        "missing_effect": d.missing_effect,
        "seconds": d.seconds,
        "gap_before": {
            "estimation": gap_json(&d.estimation_gap, &r.est.time)?,
            "validation": gap_json(&d.validation_gap, &r.val.time)?,
        },
        "hypotheses": hypotheses,
        "finding": finding,
        "augmented": augmented,
        "files": files,
    }))
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

/// Runs `structid discover`.
pub fn run(a: DiscoverArgs) -> Result<(), CliError> {
    let t0 = Instant::now();
    let mf = ModelFile::from_path(&a.model)?;
    let nominal = nominal(&mf, &a.model)?;
    let locations = parse_locations(a.locations.as_deref(), &nominal)?;
    let settings = settings(&a, locations)?;

    // Never overwrite an input; refuse a bad output directory before the long part.
    let mut guard = OutputGuard::new();
    guard
        .protect(&a.model)
        .protect(&a.data)
        .protect(&a.validate);
    guard.check_out_dir(&a.out, OUTPUTS)?;

    let est = read_record(&mf, &a.data)?;
    let val = read_record(&mf, &a.validate)?;
    for (flag, r) in [("--data", &est), ("--validate", &val)] {
        if a.settle >= r.data.len() {
            return Err(CliError::input(format!(
                "invalid value {} for --settle: it must be less than the {} samples of {flag} `{}`",
                a.settle,
                r.data.len(),
                r.path.display()
            )));
        }
    }
    let d = discover(&nominal, &est.data, &val.data, &settings)?;
    // Said after the run, so that an input error is the first line of stderr.
    if std::fs::canonicalize(&a.data).ok() == std::fs::canonicalize(&a.validate).ok() {
        eprintln!(
            "warning: --validate is the --data file: the hypotheses are ranked and the effect is \
             named on the record they were estimated on, which favours whatever overfits; give \
             a separate validation record"
        );
    }
    // The gap's lags, as discovery sets them.
    let max_lag = settings.gap().max_lag.min(est.data.len() / 4).max(1);

    guard.create_dir(&a.out)?;
    let command = command_line();
    let mut written_files: Vec<PathBuf> = Vec::new();
    let written = match &d.finding {
        Some(f) => {
            let header = augmented_header(&a, &nominal, &d, f);
            Some(write_augmented(
                &a,
                &mf,
                f,
                settings.trend_degree(),
                &header,
                &val,
                max_lag,
                &guard,
                &mut written_files,
            )?)
        }
        None => None,
    };

    // Figures.
    let mut figures: Vec<(String, String)> = Vec::new();
    let band = settings.gap().band;
    let svg = residual_svg(&d.estimation_gap, band, &est.time)?;
    let path = a.out.join("residual.svg");
    guard.write(&path, svg.as_bytes())?;
    written_files.push(path);
    figures.push((
        "residual.svg".into(),
        format!(
            "the nominal model's residual on the estimation record with ±{band}·σ̂ and the \
             windows above it shaded"
        ),
    ));
    let linear = nominal
        .model()?
        .lft()
        .t_yu()
        .simulate(est.data.u())
        .map_err(structid_core::Error::from)?
        .channel(0);
    let mut candidates = candidate_signals(
        &est.data,
        &linear,
        nominal.lft().sample_time().unwrap_or(1.0),
    );
    candidates.extend(nominal.state_signals(&est.data)?);
    let path = a.out.join("regions.svg");
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
            let path = a.out.join("map.svg");
            guard.write(&path, map_svg(&nominal, h, f)?.as_bytes())?;
            written_files.push(path);
            figures.push((
                "map.svg".into(),
                "the best hypothesis' nonparametric map with its ±2σ band and points, and the \
                 map of the augmented model"
                    .into(),
            ));
        }
        let path = a.out.join("before_after.svg");
        guard.write(
            &path,
            before_after_svg(
                &val,
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

    // Reports.
    let inputs = ReportInputs {
        a: &a,
        nominal_mf: &mf,
        nominal: &nominal,
        settings: &settings,
        est: &est,
        val: &val,
        d: &d,
        written: written.as_ref(),
        figures: &figures,
        command: &command,
        max_lag,
    };
    let md_path = a.out.join("report.md");
    guard.write(&md_path, report_md(&inputs).as_bytes())?;
    written_files.push(md_path);
    let json_path = a.out.join("report.json");
    let files: Vec<String> = written_files
        .iter()
        .chain(std::iter::once(&json_path))
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    let mut text = serde_json::to_string_pretty(&report_json(&inputs, &files)?)
        .map_err(|e| CliError::runtime(format!("cannot serialise the report: {e}")))?;
    text.push('\n');
    guard.write(&json_path, text.as_bytes())?;
    written_files.push(json_path);

    // Outputs of an earlier run that this one did not write would contradict the report.
    let mut removed = Vec::new();
    for f in OUTPUTS {
        let p = a.out.join(f);
        if p.is_file() && !written_files.contains(&p) && std::fs::remove_file(&p).is_ok() {
            removed.push(p);
        }
    }

    print!(
        "{}",
        summary(
            &inputs,
            &written_files,
            &removed,
            t0.elapsed().as_secs_f64()
        )
    );
    Ok(())
}

/// Comment lines at the top of augmented.toml.
fn augmented_header(a: &DiscoverArgs, nominal: &Nominal, d: &Discovery, f: &Finding) -> String {
    let what = match &f.classification {
        Classification::Named(fit) => format!("{} (named)", fit.effect.name()),
        other => other.describe(),
    };
    format!(
        "# Written by `structid discover`: the nominal model `{}` with the block `{BLOCK}` {}.\n\
         # Missing effect: {what}; validation RMS {:.6e} (nominal {:.6e}).\n\
         # `{BLOCK}`'s truth is the map found; its dispersion is the one discovery identified it with.\n\
         # See {} for the report and how to reproduce it.\n",
        a.model.display(),
        nominal.describe(f.location),
        f.augmented.validation_gap.rms,
        d.validation_gap.rms,
        a.out.join("report.md").display()
    )
}

fn summary(r: &ReportInputs<'_>, written: &[PathBuf], removed: &[PathBuf], seconds: f64) -> String {
    let d = r.d;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "discovery on `{}` ({} samples) and `{}` ({} samples), {:.1} s",
        r.est.path.display(),
        r.est.data.len(),
        r.val.path.display(),
        r.val.data.len(),
        seconds
    );
    let _ = writeln!(s, "verdict: {}", d.verdict);
    if let Some(f) = &d.finding {
        let _ = writeln!(
            s,
            "best location: {} (of {} hypotheses)",
            location_text(r.nominal, f.location),
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
                        .map(|p| format!("{} = {}", p.name, g4(p.value)))
                        .collect::<Vec<_>>()
                        .join(", "),
                    fit.expression
                );
            }
            other => {
                let _ = writeln!(s, "effect: {} (map kept as a table)", other.describe());
            }
        }
        let _ = writeln!(
            s,
            "validation RMS: {} → {} ({:.2}× smaller), fit {} → {}",
            e(d.validation_gap.rms),
            e(f.augmented.validation_gap.rms),
            f.shrink,
            pct(d.validation_gap.fit_percent),
            pct(f.augmented.validation_gap.fit_percent)
        );
        if let Some(w) = r.written {
            let _ = writeln!(
                s,
                "augmented.toml ({}) read back reproduces it (relative difference {:.1e})",
                w.form, w.difference
            );
        }
    } else {
        let _ = writeln!(
            s,
            "validation RMS {} (fit {}), noise level σ̂ = {}",
            e(d.validation_gap.rms),
            pct(d.validation_gap.fit_percent),
            e(d.validation_gap.noise_std)
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

#[cfg(test)]
mod tests {
    use super::*;
    use structid_core::{KernelDispersion, Signal};
    use structid_linear::PolynomialModel;

    fn g() -> PolynomialModel {
        PolynomialModel {
            den: vec![1.0, -1.5, 0.7],
            num: vec![vec![0.0, 0.1, 0.1]],
            sample_time: Some(0.05),
        }
    }

    fn nominal_file() -> ModelFile {
        ModelFile::parse(
            "[linear]\nstructure = \"lti\"\nsample_time = 0.05\nden = [1.0, -1.5, 0.7]\n\
             num = [[0.0, 0.1, 0.1]]\n[signals]\nu = [\"u\"]\ny = [\"y\"]\n",
            None,
        )
        .unwrap()
    }

    /// Every location's augmented file, read back, simulates like the hypothesis' LFT it was
    /// written from (the self-check of `structid discover`, without a discovery).
    #[test]
    fn augmented_files_reproduce_the_hypothesis_at_every_location() {
        let nominal_mf = nominal_file();
        let nominal = Nominal::from_polynomial(&g()).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let n = 600;
        let mut s = 0.0;
        let u: Vec<f64> = (0..n)
            .map(|k| {
                s = 0.8 * s + 0.5 * ((k as f64 * 0.37).sin() + (k as f64 * 0.11).cos());
                s
            })
            .collect();
        let truth = |z: f64| 0.3 * z + 0.05 * z * z * z;
        for (location, map) in [
            (
                Location::Input,
                AugmentedMap::Expression("min(max(1.5*z0, -0.8), 0.8)".into()),
            ),
            (
                Location::Output,
                AugmentedMap::Expression("z0 + 0.2*z0^3".into()),
            ),
            (
                Location::OutputFeedback,
                AugmentedMap::Table {
                    z: (0..41).map(|i| -4.0 + 0.2 * i as f64).collect(),
                    w: (0..41).map(|i| truth(-4.0 + 0.2 * i as f64)).collect(),
                },
            ),
            (
                Location::RateFeedback,
                AugmentedMap::Expression("0.01*z0".into()),
            ),
        ] {
            let h = nominal
                .hypothesis(
                    location,
                    std::sync::Arc::new(KernelDispersion::gaussian(0.3).unwrap()),
                )
                .unwrap();
            let interp = map.interpolant().unwrap();
            let us = Signal::from_fn(n, 1, |k, _| u[k]);
            let sim = h.simulate(interp.as_ref(), &us, None).unwrap();
            let y: Vec<f64> = (0..n)
                .map(|k| sim.y.get(k, 0) + 0.01 * ((k * 7919 % 101) as f64 / 50.0 - 1.0))
                .collect();
            let table = DataTable::new(vec!["u".into(), "y".into()], vec![u.clone(), y]).unwrap();
            let data = nominal_mf.select_data(&table).unwrap();
            let data_h = h.data(&data).unwrap();
            let init = initial_state(location);
            let expected = validate(
                &h.model,
                &[interp.as_ref()],
                &data_h,
                &ValidationSettings::builder()
                    .initial_state(init)
                    .build()
                    .unwrap(),
            )
            .unwrap()
            .rms[0];
            let (mf, form) = augmented_file(
                &nominal_mf,
                location,
                h.model.lft(),
                &map,
                block_dispersion(Some(0.3), 3),
                TABLE_FILE,
            )
            .unwrap();
            let expect_linear = !matches!(location, Location::Declared { .. });
            assert_eq!(form.starts_with("[linear]"), expect_linear, "{form}");
            let sub = dir.path().join(nominal.key(location));
            std::fs::create_dir_all(&sub).unwrap();
            if let AugmentedMap::Table { z, w } = &map {
                structid_io::write_csv(
                    &sub.join(TABLE_FILE),
                    &["z", "value"],
                    &[z.clone(), w.clone()],
                )
                .unwrap();
            }
            let path = sub.join("augmented.toml");
            std::fs::write(&path, mf.to_toml_string()).unwrap();
            let rms = simulate_file(&path, &table, init, 25).unwrap();
            assert!(
                (rms - expected).abs() <= 1e-9 * expected,
                "{location:?}: {rms} vs {expected}"
            );
            let back = ModelFile::from_path(&path).unwrap();
            assert_eq!(back.blocks[0].dispersion.sigma(), Some(0.3));
            assert_eq!(back.blocks[0].dispersion.kind(), "fourier");
        }
    }

    #[test]
    fn locations_parse_by_key_and_reject_unknown_names() {
        let nominal = Nominal::from_polynomial(&g()).unwrap();
        let given = vec![
            "input".to_string(),
            " output-feedback".into(),
            "input".into(),
        ];
        assert_eq!(
            parse_locations(Some(&given), &nominal).unwrap(),
            Some(vec![Location::Input, Location::OutputFeedback])
        );
        let e = parse_locations(Some(&["friction".to_string()]), &nominal)
            .unwrap_err()
            .to_string();
        assert!(e.contains("friction") && e.contains("rate-feedback"), "{e}");
        assert_eq!(parse_locations(None, &nominal).unwrap(), None);
    }
}

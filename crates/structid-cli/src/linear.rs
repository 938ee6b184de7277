//! `structid linear`: estimate the linear part (ARX, then output error) and write it as a model
//! file with a `[linear]` section, ready for `structid refine` or `structid identify`.

use std::path::PathBuf;

use clap::Args;
use structid_core::Site;
use structid_io::{BlockSpec, DispersionSpec, LinearSpec, ModelFile, OutputGuard, SignalNames};
use structid_linear::{
    ArxSettings, OeSettings, OrderCriterion, OrderGrid, Orders, PolynomialModel, arx_records,
    oe_records, select_orders_records,
};
use structid_lti::Signal;

use crate::error::CliError;

/// Arguments of `structid linear`.
#[derive(Debug, Args)]
pub struct LinearArgs {
    /// The estimation data (CSV with a header row). Repeat it for several records of the same
    /// system: the ARX equations (of the fit and of the order selection) of each record start after its own first
    /// samples, so no regressor mixes two records, and output error simulates each record from
    /// rest (or from its own estimated initial state), leaving its first --transient samples
    /// out of the cost.
    #[arg(long, short = 'd', value_name = "DATA.csv", required = true)]
    data: Vec<PathBuf>,
    /// The input column(s), comma-separated.
    #[arg(long, value_name = "COLS", default_value = "u", value_delimiter = ',')]
    input: Vec<String>,
    /// The output column.
    #[arg(long, value_name = "COL", default_value = "y")]
    output: String,
    /// Orders `NA,NB,NK`: denominator order, numerator coefficients and input delay (MATLAB's
    /// arx convention), NA and NB at most 30. Without it, orders are selected by --select.
    #[arg(long, value_name = "NA,NB,NK", value_parser = parse_orders)]
    orders: Option<[usize; 3]>,
    /// Order selection over NA, NB ∈ 1…--max-order and NK ∈ --min-delay…--max-delay: `aic`,
    /// `bic`, `fpe` (ARX criteria) or `validation` (simulation error on --validation-data).
    #[arg(long, value_name = "aic|bic|fpe|validation", default_value = "bic")]
    select: SelectArg,
    /// Largest NA and NB of the selection grid (at most 30; the grid holds at most 2700
    /// candidates, each a least-squares fit).
    #[arg(long, value_name = "N", default_value_t = 6)]
    max_order: usize,
    /// Smallest delay NK of the selection grid (output feedback needs 1).
    #[arg(long, value_name = "N", default_value_t = 1)]
    min_delay: usize,
    /// Largest delay NK of the selection grid.
    #[arg(long, value_name = "N", default_value_t = 3)]
    max_delay: usize,
    /// Validation record for `--select validation`.
    #[arg(long, value_name = "V.csv")]
    validation_data: Option<PathBuf>,
    /// `arx` (least squares) or `oe` (ARX, then output-error refinement by
    /// Levenberg–Marquardt: the simulation error is minimised).
    #[arg(long, value_name = "arx|oe", default_value = "oe")]
    method: MethodArg,
    /// Integrators to fix at z = 1 (0, 1 or 2): the model from the input to (1 − q⁻¹)ᴺ·y is
    /// fitted and its denominator multiplied by (1 − q⁻¹)ᴺ. NA of --orders then counts the
    /// free poles only (the model has NA + N). Use 1 for a position driven by a force.
    #[arg(long, value_name = "N", default_value_t = 0)]
    integrators: usize,
    /// Leading samples left out of the output-error cost (the unknown initial state).
    #[arg(long, value_name = "N", default_value_t = 0)]
    transient: usize,
    /// Initial state of the output-error fit: `zero` (the record starts at rest) or `estimate`
    /// (estimated with the model; for records cut from a longer experiment).
    #[arg(long, value_name = "zero|estimate", default_value = "zero")]
    initial_state: crate::InitialStateArg,
    /// Sample time in seconds, recorded in the model file.
    #[arg(long, value_name = "TS")]
    sample_time: Option<f64>,
    /// Where the estimated block goes: `lti` (y = G·u + e, no map), `output-feedback`
    /// (y = G·(u − N(y)) + e) or `input` (y = G·N(u) + e).
    #[arg(long, value_name = "lti|output-feedback|input", default_value = "lti")]
    structure: StructureArg,
    /// Output feedback only: give the feedback path its own numerator (y = B_u/F·u + B_w/F·N(y)).
    #[arg(long)]
    separate_numerator: bool,
    /// Name of the map of an output-feedback or input structure.
    #[arg(long, value_name = "NAME", default_value = "N")]
    map: String,
    /// Dispersion of the map: `gaussian`, `gaussian-lowrank`, `fourier`, `tv` or `polynomial`.
    #[arg(long, value_name = "KIND", default_value = "fourier")]
    dispersion: MapDispersionArg,
    /// Add a polynomial trend of this degree to a kernel dispersion (the degree itself for
    /// `--dispersion polynomial`): the map then extrapolates like the polynomial.
    #[arg(long, value_name = "D")]
    trend: Option<usize>,
    /// The model file to write (never one of the inputs).
    #[arg(long, short = 'o', value_name = "MODEL.toml")]
    out: PathBuf,
}

/// `(1 − q⁻¹)ᴺ y` (its first N samples set to 0: the order selection starts after the lags).
fn differenced(y: &Signal, n: usize) -> Result<Signal, CliError> {
    if n == 0 {
        return Ok(y.clone());
    }
    Signal::new(
        1,
        structid_linear::integrators::difference(&y.channel(0), n),
    )
    .map_err(|e| CliError::runtime(format!("internal error: differencing the output: {e}")))
}

/// `NA,NB,NK` as three whole numbers.
pub(crate) fn parse_orders(text: &str) -> Result<[usize; 3], String> {
    let v: Vec<usize> = text
        .split(',')
        .map(|x| x.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{text}` is not three whole numbers NA,NB,NK: {e}"))?;
    <[usize; 3]>::try_from(v)
        .map_err(|v| format!("`{text}` has {} numbers; give three: NA,NB,NK", v.len()))
}

/// Values of `--select`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SelectArg {
    /// Akaike's information criterion.
    Aic,
    /// The Bayesian (Schwarz) criterion.
    Bic,
    /// Akaike's final prediction error.
    Fpe,
    /// Simulation error on a validation record.
    Validation,
}

/// Values of `--method`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MethodArg {
    /// Least squares on the equation error.
    Arx,
    /// Simulation (output) error, started from ARX.
    Oe,
}

/// Values of `--structure`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StructureArg {
    /// No map.
    Lti,
    /// A map in feedback from y.
    OutputFeedback,
    /// A map at the input.
    Input,
}

/// Values of `--dispersion` for the map of `structid linear`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MapDispersionArg {
    /// The Gaussian RKHS norm.
    Gaussian,
    /// The Gaussian through Nyström features.
    GaussianLowrank,
    /// The Fourier-series kernel.
    Fourier,
    /// Total variation.
    Tv,
    /// A polynomial (ridge regression on monomials).
    Polynomial,
}

fn read_signals(path: &std::path::Path, a: &LinearArgs) -> Result<(Signal, Signal), CliError> {
    let table = crate::data::read_table(path)?;
    let u = table.select(&a.input)?;
    let y = table.select(std::slice::from_ref(&a.output))?;
    Ok((u, y))
}

fn map_dispersion(a: &LinearArgs) -> Result<DispersionSpec, CliError> {
    let kernel = match a.dispersion {
        MapDispersionArg::Gaussian => DispersionSpec::Gaussian { sigma: None },
        MapDispersionArg::GaussianLowrank => DispersionSpec::LowRankGaussian {
            sigma: None,
            tolerance: None,
        },
        MapDispersionArg::Fourier => DispersionSpec::Fourier {
            sigma: None,
            harmonics: None,
            additive: false,
        },
        MapDispersionArg::Tv => {
            if a.trend.is_some() {
                return Err(CliError::input(
                    "--trend applies to kernel dispersions (gaussian, gaussian-lowrank, fourier), not tv",
                ));
            }
            DispersionSpec::TotalVariation {
                neighbours: None,
                interpolation: None,
            }
        }
        MapDispersionArg::Polynomial => {
            return Ok(DispersionSpec::Polynomial {
                degree: a.trend.unwrap_or(3),
                scale: None,
            });
        }
    };
    Ok(match a.trend {
        Some(degree) => DispersionSpec::WithTrend {
            kernel: Box::new(kernel),
            degree,
            scale: None,
        },
        None => kernel,
    })
}

/// The order-selection grid of the arguments.
fn grid(a: &LinearArgs) -> OrderGrid {
    OrderGrid {
        na: 1..=a.max_order,
        nb: 1..=a.max_order,
        nk: a.min_delay..=a.max_delay,
    }
}

/// Checks the orders (given, or the selection grid) before the data are read: NA and NB at
/// most [`MAX_ORDER`](structid_linear::selection::MAX_ORDER) (the bound of the selection
/// grid, for the same reasons of cost and numerics: the output-error fit of given orders
/// carries one filtered copy of the record per parameter), NK shorter than any record.
fn check_orders(a: &LinearArgs) -> Result<(), CliError> {
    use structid_linear::selection::{MAX_ORDER, check_grid};
    match a.orders {
        Some([na, nb, nk]) => {
            if na > MAX_ORDER || nb > MAX_ORDER {
                return Err(CliError::input(format!(
                    "invalid value {na},{nb},{nk} for --orders: NA and NB can be at most {MAX_ORDER} \
                     (the fit costs about L·(NA + NB)² operations per iteration, and polynomials of \
                     higher order are numerically meaningless)"
                )));
            }
            if nk >= structid_io::data_file::MAX_ROWS {
                return Err(CliError::input(format!(
                    "invalid value {na},{nb},{nk} for --orders: the delay NK is longer than any record \
                     structid reads ({} samples)",
                    structid_io::data_file::MAX_ROWS
                )));
            }
            Ok(())
        }
        None => {
            if a.max_order == 0 || a.min_delay > a.max_delay {
                return Err(CliError::input(
                    "the selection grid is empty: --max-order must be ≥ 1 and --min-delay ≤ --max-delay",
                ));
            }
            check_grid(&grid(a)).map_err(|e| {
                CliError::input(format!(
                    "--max-order {} with delays {}..={}: {e}",
                    a.max_order, a.min_delay, a.max_delay
                ))
            })
        }
    }
}

/// Runs `structid linear`.
pub fn run(a: LinearArgs) -> Result<(), CliError> {
    let mut guard = OutputGuard::new();
    for d in &a.data {
        guard.protect(d);
    }
    if let Some(v) = &a.validation_data {
        guard.protect(v);
    }
    guard.check_out_file(&a.out)?;
    guard.check_out_file(&figure_path(&a.out))?;
    if let Some(ts) = a.sample_time
        && !(ts.is_finite() && ts > 0.0)
    {
        return Err(CliError::input(format!(
            "invalid value {ts} for --sample-time: it must be a finite number of seconds greater than zero"
        )));
    }
    if (a.select == SelectArg::Validation) != a.validation_data.is_some() && a.orders.is_none() {
        return Err(CliError::input(
            "--select validation and --validation-data V.csv go together",
        ));
    }
    if a.structure == StructureArg::Input && a.input.len() != 1 {
        return Err(CliError::input(
            "--structure input takes exactly one input column",
        ));
    }
    if a.separate_numerator && a.structure != StructureArg::OutputFeedback {
        return Err(CliError::input(
            "--separate-numerator applies to --structure output-feedback only",
        ));
    }
    if a.structure == StructureArg::OutputFeedback && a.input.len() > 1 && !a.separate_numerator {
        return Err(CliError::input(
            "--structure output-feedback with several inputs needs --separate-numerator: the \
             feedback path cannot share the numerator of several inputs",
        ));
    }
    if let Some(d) = a.trend
        && d > 64
    {
        return Err(CliError::input(format!(
            "invalid value {d} for --trend: the polynomial degree must be at most 64"
        )));
    }
    if a.method == MethodArg::Arx
        && (a.transient > 0 || matches!(a.initial_state, crate::InitialStateArg::Estimate))
    {
        return Err(CliError::input(
            "--transient and --initial-state estimate apply to the output-error fit (--method oe); \
             an ARX fit ignores them",
        ));
    }
    if a.integrators > structid_linear::integrators::MAX_INTEGRATORS {
        return Err(CliError::input(format!(
            "invalid value {} for --integrators: give 0, 1 or 2",
            a.integrators
        )));
    }
    if a.integrators > 0 && matches!(a.initial_state, crate::InitialStateArg::Estimate) {
        return Err(CliError::input(
            "--integrators with --initial-state estimate is not supported; use --transient to \
             leave the start of the record out of the cost",
        ));
    }
    check_orders(&a)?;
    let records: Vec<(Signal, Signal)> = a
        .data
        .iter()
        .map(|d| read_signals(d, &a))
        .collect::<Result<_, _>>()?;
    let mut arx_settings = ArxSettings::builder().integrators(a.integrators);
    let mut oe_settings = OeSettings::builder()
        .transient(a.transient)
        .integrators(a.integrators);
    if let Some(ts) = a.sample_time {
        arx_settings = arx_settings.sample_time(ts);
        oe_settings = oe_settings.sample_time(ts);
    }
    let arx_settings = arx_settings.build()?;
    let oe_settings = oe_settings.arx(arx_settings.clone()).build()?;

    // Orders: given, or selected on the ARX fits.
    let (orders, selection_note) = match &a.orders {
        Some(o) => (
            Orders::new(o[0], vec![o[1]; a.input.len()], vec![o[2]; a.input.len()])?,
            None,
        ),
        None => {
            let criterion = match a.select {
                SelectArg::Aic => OrderCriterion::Aic,
                SelectArg::Bic => OrderCriterion::Bic,
                SelectArg::Fpe => OrderCriterion::Fpe,
                SelectArg::Validation => {
                    let path = a.validation_data.as_ref().ok_or_else(|| {
                        CliError::input("--select validation needs --validation-data V.csv")
                    })?;
                    let (u, y) = read_signals(path, &a)?;
                    OrderCriterion::Validation {
                        u,
                        y: differenced(&y, a.integrators)?,
                    }
                }
            };
            let grid = grid(&a);
            // The free part is selected on the differenced output, record by record.
            let differenced: Vec<(&Signal, Signal)> = records
                .iter()
                .map(|(u, y)| Ok((u, differenced(y, a.integrators)?)))
                .collect::<Result<_, CliError>>()?;
            let pairs: Vec<(&Signal, &Signal)> = differenced.iter().map(|(u, y)| (*u, y)).collect();
            let pb = crate::progress::bar(Some(0), "candidate orders");
            let sel =
                select_orders_records(&pairs, &grid, &criterion, &arx_settings, &|done, total| {
                    pb.set_length(total);
                    pb.set_position(done);
                });
            pb.finish_and_clear();
            let sel = sel?;
            let note = format!(
                "orders selected by {} over {} candidates",
                criterion.name(),
                sel.table.len()
            );
            (sel.best, Some(note))
        }
    };
    if a.structure == StructureArg::OutputFeedback && orders.nk.contains(&0) {
        return Err(CliError::input(
            "an output-feedback structure needs an input delay NK ≥ 1 (otherwise y_k depends on N(y_k))",
        ));
    }
    let mut warning = None;
    let (model, cost, what, covariance): (PolynomialModel, f64, String, _) = match a.method {
        MethodArg::Arx => {
            let pairs: Vec<(&Signal, &Signal)> = records.iter().map(|(u, y)| (u, y)).collect();
            let fit = arx_records(&pairs, &orders, &arx_settings).map_err(|e| {
                CliError::from(e).context(format!(
                    "the --data files ({})",
                    crate::identify::files_label(&a.data)
                ))
            })?;
            (
                fit.model,
                fit.cost,
                "equation error (ARX)".into(),
                fit.parameter_covariance,
            )
        }
        MethodArg::Oe => {
            let pairs: Vec<(&Signal, &Signal)> = records.iter().map(|(u, y)| (u, y)).collect();
            let context = |e: CliError| {
                if a.data.len() > 1 {
                    e.context(format!(
                        "the --data files ({})",
                        crate::identify::files_label(&a.data)
                    ))
                } else {
                    e
                }
            };
            let fit = match a.initial_state {
                crate::InitialStateArg::Zero => {
                    oe_records(&pairs, &orders, &oe_settings).map_err(|e| context(e.into()))?
                }
                crate::InitialStateArg::Estimate => {
                    let start = arx_records(&pairs, &orders, &arx_settings)
                        .map_err(|e| context(e.into()))?
                        .model;
                    structid_core::refine::output_error_records_with_state(
                        &pairs,
                        &start,
                        &oe_settings,
                        true,
                        0,
                    )
                    .map_err(|e| context(e.into()))?
                }
            };
            let note = if fit.converged {
                format!("simulation error (OE, {} iterations)", fit.iterations)
            } else {
                format!(
                    "simulation error (OE, stopped after {} iterations without converging)",
                    fit.iterations
                )
            };
            warning = fit.warning.clone();
            (fit.model, fit.cost, note, fit.parameter_covariance)
        }
    };
    let structure = match a.structure {
        StructureArg::Lti => None,
        StructureArg::OutputFeedback => Some(Site::OutputFeedback),
        StructureArg::Input => Some(Site::Input),
    };
    // The feedback path starts as the input path: y = G·(u − w).
    let spec = LinearSpec {
        separate_numerator: a.separate_numerator,
        ..LinearSpec::from_linear(&model, structure)
    };
    let lft = spec.lft()?;
    let blocks = match structure {
        None => Vec::new(),
        Some(_) => vec![BlockSpec {
            name: a.map.clone(),
            inputs: vec![0],
            output: 0,
            dispersion: map_dispersion(&a)?,
            truth: None,
            operator: None,
            shape: None,
        }],
    };
    let mf = ModelFile {
        lft,
        linear: Some(spec),
        signals: SignalNames {
            u: a.input.clone(),
            y: vec![a.output.clone()],
            z: None,
        },
        blocks,
        discover: None,
        path: None,
    };
    let text = mf.to_toml_string();
    // The file must read back as written.
    ModelFile::parse(&text, None).map_err(|e| {
        CliError::runtime(format!(
            "internal error: the model file does not read back: {e}"
        ))
    })?;
    guard.write(&a.out, text.as_bytes())?;
    let figure = figure_path(&a.out);
    let svg = crate::figures::linear_svg(&model, covariance.as_ref(), &a.input)?;
    guard.write(&figure, svg.as_bytes())?;

    // The simulation fit over every record, each simulated from rest.
    let (mut y_all, mut sim_all) = (Vec::new(), Vec::new());
    for (u, y) in &records {
        sim_all.extend(model.simulate(u)?);
        y_all.extend(y.channel(0));
    }
    let fit = structid_core::validation::metrics::fit_percent(&y_all, &sim_all);
    println!(
        "linear block: na = {}, nb = {:?}, nk = {:?}{}",
        orders.na,
        orders.nb,
        orders.nk,
        selection_note
            .map(|n| format!(" ({n})"))
            .unwrap_or_default()
    );
    println!(
        "fitted by {what}: mean squared error {cost:.4e}; simulation fit on the data {fit:.2} % ({})",
        model.stability()
    );
    if a.integrators > 0 {
        println!(
            "fixed: {} integrator{} at z = 1 (denominator order {} = {} free + {})",
            a.integrators,
            if a.integrators == 1 { "" } else { "s" },
            model.den.len() - 1,
            orders.na,
            a.integrators
        );
    }
    // ARX knows no warnings of its own: a zero that cancels the fixed integrator is as
    // misleading there as after output error.
    let cancelled = structid_linear::integrators::integrator_cancellation(&model)
        .filter(|&r| r < structid_linear::integrators::CANCELLATION);
    if let Some(w) = warning {
        println!("warning: {w}");
        if a.integrators == 0
            && !matches!(w, structid_linear::OeWarning::IntegratorCancelled { .. })
        {
            println!("hint: `--integrators 1` holds an integrator at z = 1");
        }
    } else if let Some(ratio) = cancelled {
        let w = structid_linear::OeWarning::IntegratorCancelled {
            ratio,
            fit_percent: fit,
        };
        println!("warning: {w}");
    } else if fit < 0.0 {
        println!(
            "warning: the simulation fit ({fit:.1} %) is worse than a constant (0 %); if the plant \
             integrates, fix the integrator with --integrators 1"
        );
    }
    println!(
        "structure: {}{}",
        structure.map_or("lti", Site::name),
        if structure.is_none() {
            String::new()
        } else {
            format!(", map `{}`", a.map)
        }
    );
    println!("wrote {} and {}", a.out.display(), figure.display());
    Ok(())
}

/// The figure of the linear part beside the model file: `model.toml` → `model.svg` (a model
/// file named `*.svg` gets `*.linear.svg`).
fn figure_path(out: &std::path::Path) -> PathBuf {
    if out.extension().is_some_and(|e| e == "svg") {
        out.with_extension("linear.svg")
    } else {
        out.with_extension("svg")
    }
}

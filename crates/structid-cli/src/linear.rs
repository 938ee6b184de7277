//! `structid linear`: estimate the linear part (ARX, then output error) and write it as a model
//! file with a `[linear]` section, ready for `structid refine` or `structid identify`.

use std::path::PathBuf;

use clap::Args;
use structid_core::Site;
use structid_io::OutputGuard;
use structid_linear::OrderCriterion;
use structid_lti::Signal;
use structid_workflow::linear::{
    LinearMethod, LinearOutcome, LinearRequest, MapKind, MapRequest, OrderChoice, fit_linear,
};

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

/// The request the arguments make, without its records (and without the validation record of
/// `--select validation`, which `criterion` reads).
fn request(a: &LinearArgs) -> Result<LinearRequest, CliError> {
    let orders = match a.orders {
        Some(o) => OrderChoice::Given(o),
        None => OrderChoice::Selected {
            criterion: match a.select {
                SelectArg::Aic => OrderCriterion::Aic,
                SelectArg::Bic | SelectArg::Validation => OrderCriterion::Bic,
                SelectArg::Fpe => OrderCriterion::Fpe,
            },
            max_order: a.max_order,
            delays: (a.min_delay, a.max_delay),
        },
    };
    let method = match (a.method, a.initial_state) {
        (MethodArg::Arx, initial)
            if a.transient > 0 || initial == crate::InitialStateArg::Estimate =>
        {
            return Err(CliError::input(
                "--transient and --initial-state estimate apply to the output-error fit \
                 (--method oe); an ARX fit ignores them",
            ));
        }
        (MethodArg::Arx, _) => LinearMethod::Arx,
        (MethodArg::Oe, crate::InitialStateArg::Zero) => LinearMethod::Oe,
        (MethodArg::Oe, crate::InitialStateArg::Estimate) => LinearMethod::OeWithInitialState,
    };
    let site = match a.structure {
        StructureArg::Lti => None,
        StructureArg::OutputFeedback => Some(Site::OutputFeedback),
        StructureArg::Input => Some(Site::Input),
    };
    if site.is_none() && a.separate_numerator {
        return Err(CliError::input(
            "--separate-numerator applies to --structure output-feedback only",
        ));
    }
    let kind = match a.dispersion {
        MapDispersionArg::Gaussian => MapKind::Gaussian,
        MapDispersionArg::GaussianLowrank => MapKind::GaussianLowrank,
        MapDispersionArg::Fourier => MapKind::Fourier,
        MapDispersionArg::Tv => MapKind::Tv,
        MapDispersionArg::Polynomial => MapKind::Polynomial,
    };
    Ok(LinearRequest {
        records: Vec::new(),
        inputs: a.input.clone(),
        output: a.output.clone(),
        orders,
        method,
        integrators: a.integrators,
        transient: a.transient,
        sample_time: a.sample_time,
        map: site.map(|site| MapRequest {
            site,
            name: a.map.clone(),
            kind,
            trend: a.trend,
            separate_numerator: a.separate_numerator,
        }),
    })
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
    if (a.select == SelectArg::Validation) != a.validation_data.is_some() && a.orders.is_none() {
        return Err(CliError::input(
            "--select validation and --validation-data V.csv go together",
        ));
    }
    let mut req = request(&a)?;
    req.check()?;
    if let (OrderChoice::Selected { criterion, .. }, Some(path), SelectArg::Validation) =
        (&mut req.orders, &a.validation_data, a.select)
    {
        let (u, y) = read_signals(path, &a)?;
        *criterion = OrderCriterion::Validation { u, y };
    }
    req.records = a
        .data
        .iter()
        .map(|d| read_signals(d, &a))
        .collect::<Result<_, _>>()?;
    let pb = matches!(req.orders, OrderChoice::Selected { .. })
        .then(|| crate::progress::bar(Some(0), "candidate orders"));
    let fitted = fit_linear(&req, &|done, total| {
        if let Some(pb) = &pb {
            pb.set_length(total);
            pb.set_position(done);
            if done == total {
                pb.finish_and_clear();
            }
        }
    });
    if let Some(pb) = pb {
        pb.finish_and_clear();
    }
    let out = fitted.map_err(|e| {
        let from_records = !matches!(e, structid_workflow::WorkflowError::Request(_));
        let e = CliError::from(e);
        if from_records && (a.data.len() > 1 || a.method == MethodArg::Arx) {
            e.context(format!(
                "the --data files ({})",
                crate::identify::files_label(&a.data)
            ))
        } else {
            e
        }
    })?;
    guard.write(&a.out, out.model_file.to_toml_string().as_bytes())?;
    let figure = figure_path(&a.out);
    let svg =
        structid_workflow::figures::linear_svg(&out.model, out.covariance.as_ref(), &a.input)?;
    guard.write(&figure, svg.as_bytes())?;
    print_summary(&a, &out);
    println!("wrote {} and {}", a.out.display(), figure.display());
    Ok(())
}

fn print_summary(a: &LinearArgs, out: &LinearOutcome) {
    let o = &out.orders;
    let note = out
        .selection
        .as_ref()
        .map(|(c, n)| format!(" (orders selected by {c} over {n} candidates)"))
        .unwrap_or_default();
    println!(
        "linear block: na = {}, nb = {:?}, nk = {:?}{note}",
        o.na, o.nb, o.nk
    );
    let what = match (a.method, out.converged) {
        (MethodArg::Arx, _) => "equation error (ARX)".to_string(),
        (MethodArg::Oe, true) => format!("simulation error (OE, {} iterations)", out.iterations),
        (MethodArg::Oe, false) => format!(
            "simulation error (OE, stopped after {} iterations without converging)",
            out.iterations
        ),
    };
    let fit = out.pooled_fit_percent;
    println!(
        "fitted by {what}: mean squared error {:.4e}; simulation fit on the data {fit:.2} % ({})",
        out.cost,
        out.model.stability()
    );
    if a.integrators > 0 {
        println!(
            "fixed: {} integrator{} at z = 1 (denominator order {} = {} free + {})",
            a.integrators,
            if a.integrators == 1 { "" } else { "s" },
            out.model.den.len() - 1,
            o.na,
            a.integrators
        );
    }
    if let Some(w) = &out.warning {
        println!("warning: {w}");
        if a.integrators == 0
            && !matches!(w, structid_linear::OeWarning::IntegratorCancelled { .. })
        {
            println!("hint: `--integrators 1` holds an integrator at z = 1");
        }
    } else if fit < 0.0 {
        println!(
            "warning: the simulation fit ({fit:.1} %) is worse than a constant (0 %); if the plant \
             integrates, fix the integrator with --integrators 1"
        );
    }
    let site = out.model_file.linear.as_ref().and_then(|l| l.structure);
    println!(
        "structure: {}{}",
        site.map_or("lti", Site::name),
        if site.is_none() {
            String::new()
        } else {
            format!(", map `{}`", a.map)
        }
    );
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

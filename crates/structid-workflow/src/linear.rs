//! The linear part G from records (`structid linear`, Python's `structid.linear`): orders given
//! or selected, an equation-error (ARX) fit, optionally refined by its simulation (output)
//! error, and the model file that carries G in a `[linear]` section, with a map at a site when
//! one is asked for, ready for `identify` or `refine`.
//!
//! With N integrators held at z = 1 the model from u to (1 − q⁻¹)ᴺ·y is fitted, and orders are
//! selected on that differenced output. The simulation fit is pooled over the records, each
//! simulated from rest.

use std::str::FromStr;

use nalgebra::DMatrix;
use structid_core::Site;
use structid_io::{BlockSpec, DispersionSpec, LinearSpec, ModelFile, SignalNames};
use structid_linear::{
    ArxSettings, OeSettings, OeWarning, OrderCriterion, OrderGrid, Orders, PolynomialModel,
    arx_records, oe_records, select_orders_records,
};
use structid_lti::Signal;

use crate::error::{Result, WorkflowError};

/// How the orders are found.
#[derive(Clone, Debug)]
pub enum OrderChoice {
    /// NA, NB (per input) and NK (per input) as given (MATLAB's `arx` convention).
    Given([usize; 3]),
    /// Selected over NA, NB ∈ 1…`max_order` and NK ∈ `delays` by `criterion`.
    Selected {
        /// The criterion (on the differenced output when integrators are held).
        criterion: OrderCriterion,
        /// Largest NA and NB.
        max_order: usize,
        /// Smallest and largest NK.
        delays: (usize, usize),
    },
}

/// How G is fitted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinearMethod {
    /// Least squares on the equation error.
    Arx,
    /// ARX, then Levenberg–Marquardt on the simulation error from rest.
    Oe,
    /// As `Oe`, with each record's initial state estimated with the model.
    OeWithInitialState,
}

/// The dispersion of the map a linear model file carries (`--dispersion`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapKind {
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

impl FromStr for MapKind {
    type Err = WorkflowError;

    fn from_str(s: &str) -> Result<Self> {
        Ok(match s {
            "gaussian" => Self::Gaussian,
            "gaussian-lowrank" => Self::GaussianLowrank,
            "fourier" => Self::Fourier,
            "tv" => Self::Tv,
            "polynomial" => Self::Polynomial,
            other => {
                return Err(WorkflowError::InvalidOption {
                    option: "dispersion",
                    value: other.into(),
                    rule: "give gaussian, gaussian-lowrank, fourier, tv or polynomial".into(),
                });
            }
        })
    }
}

/// The map a linear model file carries at its site.
#[derive(Clone, Debug)]
pub struct MapRequest {
    /// Where: output feedback or the input (other sites are refused).
    pub site: Site,
    /// Its name.
    pub name: String,
    /// Its dispersion.
    pub kind: MapKind,
    /// A polynomial trend of this degree on a kernel dispersion (the degree of a polynomial
    /// one, 3 by default).
    pub trend: Option<usize>,
    /// Output feedback only: the feedback path gets its own numerator.
    pub separate_numerator: bool,
}

/// What [`fit_linear`] asks for.
#[derive(Clone, Debug)]
pub struct LinearRequest {
    /// The records (u, y), y with one channel.
    pub records: Vec<(Signal, Signal)>,
    /// Names of the input columns (one per channel of u).
    pub inputs: Vec<String>,
    /// Name of the output column.
    pub output: String,
    /// The orders.
    pub orders: OrderChoice,
    /// The fit.
    pub method: LinearMethod,
    /// Integrators held at z = 1 (0, 1 or 2).
    pub integrators: usize,
    /// Leading samples of each record left out of the output-error cost.
    pub transient: usize,
    /// Sample time in seconds, recorded in the model.
    pub sample_time: Option<f64>,
    /// A map at a site of G, or none (y = G·u + e).
    pub map: Option<MapRequest>,
}

/// What [`fit_linear`] found.
#[derive(Clone, Debug)]
pub struct LinearOutcome {
    /// The orders used.
    pub orders: Orders,
    /// With selected orders: the criterion's name and the number of candidates.
    pub selection: Option<(String, usize)>,
    /// G.
    pub model: PolynomialModel,
    /// Mean squared error of the fit's own criterion.
    pub cost: f64,
    /// Covariance of the free parameters, when defined.
    pub covariance: Option<DMatrix<f64>>,
    /// Their standard deviations.
    pub parameter_std: Vec<f64>,
    /// Levenberg–Marquardt iterations (0 for ARX).
    pub iterations: usize,
    /// Whether the output-error fit converged (true for ARX).
    pub converged: bool,
    /// What the fit warns about: the output-error fit's own warning, or, after any fit, a zero
    /// that cancels a held integrator.
    pub warning: Option<OeWarning>,
    /// Simulation fit (%) of each record, simulated from rest.
    pub fit_percent: Vec<f64>,
    /// Simulation fit (%) pooled over the records.
    pub pooled_fit_percent: f64,
    /// The model file: G in `[linear]`, and the map when asked for.
    pub model_file: ModelFile,
}

impl LinearRequest {
    /// The checks that need no data: the options' ranges and combinations.
    ///
    /// ```
    /// use structid_workflow::linear::{LinearMethod, LinearRequest, OrderChoice};
    /// let r = LinearRequest {
    ///     records: vec![], inputs: vec!["u".into()], output: "y".into(),
    ///     orders: OrderChoice::Given([2, 2, 1]), method: LinearMethod::Arx,
    ///     integrators: 3, transient: 0, sample_time: None, map: None,
    /// };
    /// assert!(r.check().unwrap_err().to_string().contains("integrators"));
    /// ```
    pub fn check(&self) -> Result<()> {
        use structid_linear::integrators::MAX_INTEGRATORS;
        let invalid = |option, value: String, rule: &str| WorkflowError::InvalidOption {
            option,
            value,
            rule: rule.into(),
        };
        if let Some(ts) = self.sample_time
            && !(ts.is_finite() && ts > 0.0)
        {
            let rule = "it must be a finite number of seconds greater than zero";
            return Err(invalid("sample_time", ts.to_string(), rule));
        }
        if self.integrators > MAX_INTEGRATORS {
            return Err(invalid(
                "integrators",
                self.integrators.to_string(),
                "give 0, 1 or 2",
            ));
        }
        let conflict = |options, rule: &str| WorkflowError::OptionConflict {
            options,
            rule: rule.into(),
        };
        match self.method {
            LinearMethod::Arx if self.transient > 0 => {
                return Err(conflict(
                    vec!["transient", "method"],
                    "the transient applies to the output-error fit; an ARX fit ignores it",
                ));
            }
            LinearMethod::OeWithInitialState if self.integrators > 0 => {
                return Err(conflict(
                    vec!["integrators", "initial_state"],
                    "held integrators with an estimated initial state are not supported; leave \
                     the start of the record out of the cost with the transient instead",
                ));
            }
            _ => {}
        }
        if let Some(m) = &self.map {
            self.check_map(m)?;
        }
        check_orders(&self.orders)
    }

    fn check_map(&self, m: &MapRequest) -> Result<()> {
        let conflict = |options, rule: &str| {
            Err(WorkflowError::OptionConflict {
                options,
                rule: rule.into(),
            })
        };
        if !matches!(m.site, Site::Input | Site::OutputFeedback) {
            return Err(WorkflowError::InvalidOption {
                option: "structure",
                value: m.site.name().to_string(),
                rule: "a linear model file places its map at the input or in output feedback"
                    .into(),
            });
        }
        if m.site == Site::Input && self.inputs.len() != 1 {
            return conflict(
                vec!["structure"],
                "a map at the input takes exactly one input",
            );
        }
        if m.separate_numerator && m.site != Site::OutputFeedback {
            return conflict(
                vec!["separate_numerator", "structure"],
                "a separate numerator applies to output feedback only",
            );
        }
        if m.site == Site::OutputFeedback && self.inputs.len() > 1 && !m.separate_numerator {
            return conflict(
                vec!["structure", "separate_numerator"],
                "output feedback with several inputs needs a separate numerator: the feedback \
                 path cannot share the numerator of several inputs",
            );
        }
        if m.trend.is_some_and(|d| d > 64) {
            return Err(WorkflowError::InvalidOption {
                option: "trend",
                value: m.trend.unwrap_or_default().to_string(),
                rule: "the polynomial degree must be at most 64".into(),
            });
        }
        if m.kind == MapKind::Tv && m.trend.is_some() {
            return conflict(
                vec!["trend", "dispersion"],
                "a trend applies to kernel dispersions (gaussian, gaussian-lowrank, fourier), not tv",
            );
        }
        Ok(())
    }
}

/// Checks the orders before the data are read: NA and NB at most
/// [`MAX_ORDER`](structid_linear::selection::MAX_ORDER) (the output-error fit carries one
/// filtered copy of the record per parameter, and polynomials of higher order are numerically
/// meaningless), NK shorter than any record, a selection grid that is not empty.
fn check_orders(orders: &OrderChoice) -> Result<()> {
    use structid_linear::selection::{MAX_ORDER, check_grid};
    match orders {
        OrderChoice::Given([na, nb, nk]) => {
            let rule = if *na > MAX_ORDER || *nb > MAX_ORDER {
                format!(
                    "NA and NB can be at most {MAX_ORDER} (the fit costs about L·(NA + NB)² \
                     operations per iteration, and polynomials of higher order are numerically \
                     meaningless)"
                )
            } else if *nk >= structid_io::data_file::MAX_ROWS {
                format!(
                    "the delay NK is longer than any record structid reads ({} samples)",
                    structid_io::data_file::MAX_ROWS
                )
            } else {
                return Ok(());
            };
            Err(WorkflowError::InvalidOption {
                option: "orders",
                value: format!("{na},{nb},{nk}"),
                rule,
            })
        }
        OrderChoice::Selected {
            max_order, delays, ..
        } => {
            if *max_order == 0 || delays.0 > delays.1 {
                return Err(WorkflowError::OptionConflict {
                    options: vec!["max_order", "min_delay", "max_delay"],
                    rule: "the selection grid is empty: the largest order must be at least 1 and \
                           the smallest delay at most the largest"
                        .into(),
                });
            }
            check_grid(&grid(*max_order, *delays)).map_err(|e| WorkflowError::InvalidOption {
                option: "max_order",
                value: format!("{max_order} with delays {}..={}", delays.0, delays.1),
                rule: e.to_string(),
            })
        }
    }
}

fn grid(max_order: usize, delays: (usize, usize)) -> OrderGrid {
    OrderGrid {
        na: 1..=max_order,
        nb: 1..=max_order,
        nk: delays.0..=delays.1,
    }
}

/// `(1 − q⁻¹)ᴺ y` (its first N samples set to 0: the order selection starts after the lags).
fn differenced(y: &Signal, n: usize) -> Result<Signal> {
    if n == 0 {
        return Ok(y.clone());
    }
    let d = structid_linear::integrators::difference(&y.channel(0), n);
    Ok(Signal::new(1, d).map_err(structid_core::Error::from)?)
}

/// The records' shapes: at least one, y with one channel, u and y of one length, and every u
/// with the inputs' channels.
fn check_records(r: &LinearRequest) -> Result<()> {
    if r.records.is_empty() {
        return Err(WorkflowError::Request("no records to fit".into()));
    }
    for (i, (u, y)) in r.records.iter().enumerate() {
        let which = if r.records.len() == 1 {
            String::new()
        } else {
            format!(" of record {i}")
        };
        if u.channels() != r.inputs.len() || y.channels() != 1 || u.len() != y.len() {
            return Err(WorkflowError::Request(format!(
                "the data{which} have {} input and {} output channel(s) and {} against {} \
                 samples; the request names {} input(s) and one output, with one sample of each \
                 per instant",
                u.channels(),
                y.channels(),
                u.len(),
                y.len(),
                r.inputs.len()
            )));
        }
    }
    Ok(())
}

/// The orders of `r`, selected when asked, with the criterion's name and candidate count;
/// `progress(done, total)` follows the selection.
fn orders(
    r: &LinearRequest,
    arx: &ArxSettings,
    progress: &dyn Fn(u64, u64),
) -> Result<(Orders, Option<(String, usize)>)> {
    let m = r.inputs.len();
    match &r.orders {
        OrderChoice::Given([na, nb, nk]) => {
            Ok((Orders::new(*na, vec![*nb; m], vec![*nk; m])?, None))
        }
        OrderChoice::Selected {
            criterion,
            max_order,
            delays,
        } => {
            let criterion = match criterion {
                OrderCriterion::Validation { u, y } => OrderCriterion::Validation {
                    u: u.clone(),
                    y: differenced(y, r.integrators)?,
                },
                other => other.clone(),
            };
            let diffs: Vec<(&Signal, Signal)> = r
                .records
                .iter()
                .map(|(u, y)| Ok((u, differenced(y, r.integrators)?)))
                .collect::<Result<_>>()?;
            let pairs: Vec<(&Signal, &Signal)> = diffs.iter().map(|(u, y)| (*u, y)).collect();
            let sel = select_orders_records(
                &pairs,
                &grid(*max_order, *delays),
                &criterion,
                arx,
                progress,
            )?;
            Ok((
                sel.best,
                Some((criterion.name().to_string(), sel.table.len())),
            ))
        }
    }
}

/// Fits G as `r` asks (see the [module documentation](self)); `progress(done, total)` follows
/// an order selection.
///
/// ```
/// use structid_lti::Signal;
/// use structid_workflow::linear::{LinearMethod, LinearRequest, OrderChoice, fit_linear};
/// // y_k = 0.8·y_(k−1) + 0.5·u_(k−1)
/// let u = Signal::from_fn(300, 1, |k, _| ((k * 7919) % 13) as f64 - 6.0);
/// let mut y = vec![0.0; 300];
/// for k in 1..300 { y[k] = 0.8 * y[k - 1] + 0.5 * u.get(k - 1, 0); }
/// let r = LinearRequest {
///     records: vec![(u, Signal::new(1, y).unwrap())], inputs: vec!["u".into()],
///     output: "y".into(), orders: OrderChoice::Given([1, 1, 1]), method: LinearMethod::Oe,
///     integrators: 0, transient: 0, sample_time: None, map: None,
/// };
/// let out = fit_linear(&r, &|_, _| {}).unwrap();
/// assert!((out.model.den[1] + 0.8).abs() < 1e-8 && out.pooled_fit_percent > 99.99);
/// ```
pub fn fit_linear(r: &LinearRequest, progress: &dyn Fn(u64, u64)) -> Result<LinearOutcome> {
    r.check()?;
    check_records(r)?;
    let mut arx = ArxSettings::builder().integrators(r.integrators);
    let mut oe = OeSettings::builder()
        .transient(r.transient)
        .integrators(r.integrators);
    if let Some(ts) = r.sample_time {
        arx = arx.sample_time(ts);
        oe = oe.sample_time(ts);
    }
    let arx = arx.build()?;
    let oe = oe.arx(arx.clone()).build()?;
    let (orders, selection) = orders(r, &arx, progress)?;
    if let Some(m) = &r.map
        && m.site == Site::OutputFeedback
        && orders.nk.contains(&0)
    {
        return Err(WorkflowError::Request(
            "an output-feedback structure needs an input delay NK ≥ 1 (otherwise y_k depends on \
             N(y_k))"
                .into(),
        ));
    }
    let pairs: Vec<(&Signal, &Signal)> = r.records.iter().map(|(u, y)| (u, y)).collect();
    let f = match r.method {
        LinearMethod::Arx => {
            let f = arx_records(&pairs, &orders, &arx)?;
            let (model, cost, cov, std) =
                (f.model, f.cost, f.parameter_covariance, f.parameter_std);
            (model, cost, cov, std, 0, true, None)
        }
        LinearMethod::Oe | LinearMethod::OeWithInitialState => {
            let f = if r.method == LinearMethod::Oe {
                oe_records(&pairs, &orders, &oe)?
            } else {
                let start = arx_records(&pairs, &orders, &arx)?.model;
                structid_core::refine::output_error_records_with_state(
                    &pairs, &start, &oe, true, 0,
                )?
            };
            let (model, cost, cov, std) =
                (f.model, f.cost, f.parameter_covariance, f.parameter_std);
            (model, cost, cov, std, f.iterations, f.converged, f.warning)
        }
    };
    let (model, cost, covariance, parameter_std, iterations, converged, warning) = f;
    let (mut y_all, mut sim_all, mut fit_percent) = (Vec::new(), Vec::new(), Vec::new());
    for (u, y) in &r.records {
        let sim = model.simulate(u)?;
        let y = y.channel(0);
        fit_percent.push(structid_core::validation::metrics::fit_percent(&y, &sim));
        y_all.extend(y);
        sim_all.extend(sim);
    }
    let pooled_fit_percent = structid_core::validation::metrics::fit_percent(&y_all, &sim_all);
    // ARX knows no warnings of its own: a zero that cancels the held integrator is as
    // misleading there as after output error.
    let warning = warning.or_else(|| {
        structid_linear::integrators::integrator_cancellation(&model)
            .filter(|&q| q < structid_linear::integrators::CANCELLATION)
            .map(|ratio| OeWarning::IntegratorCancelled {
                ratio,
                fit_percent: pooled_fit_percent,
            })
    });
    let model_file = model_file(r, &model)?;
    Ok(LinearOutcome {
        orders,
        selection,
        model,
        cost,
        covariance,
        parameter_std,
        iterations,
        converged,
        warning,
        fit_percent,
        pooled_fit_percent,
        model_file,
    })
}

/// G as a model file: `[linear]` with the map's site, and the map's block when asked for (the
/// feedback path starts as the input path, y = G·(u − w)). The file reads back as written.
fn model_file(r: &LinearRequest, g: &PolynomialModel) -> Result<ModelFile> {
    let site = r.map.as_ref().map(|m| m.site);
    let spec = LinearSpec {
        separate_numerator: r.map.as_ref().is_some_and(|m| m.separate_numerator),
        ..LinearSpec::from_linear(g, site)
    };
    let blocks = match &r.map {
        None => Vec::new(),
        Some(m) => vec![BlockSpec {
            name: m.name.clone(),
            inputs: vec![0],
            output: 0,
            dispersion: map_dispersion(m.kind, m.trend),
            truth: None,
            operator: None,
            shape: None,
        }],
    };
    let mf = ModelFile {
        lft: spec.lft()?,
        linear: Some(spec),
        signals: SignalNames {
            u: r.inputs.clone(),
            y: vec![r.output.clone()],
            z: None,
        },
        blocks,
        discover: None,
        path: None,
    };
    ModelFile::parse(&mf.to_toml_string(), None)?;
    Ok(mf)
}

/// The dispersion of a map of `kind`, with a polynomial trend of degree `trend` on a kernel
/// (the degree of a polynomial dispersion, 3 by default).
fn map_dispersion(kind: MapKind, trend: Option<usize>) -> DispersionSpec {
    let kernel = match kind {
        MapKind::Gaussian => DispersionSpec::Gaussian { sigma: None },
        MapKind::GaussianLowrank => DispersionSpec::LowRankGaussian {
            sigma: None,
            tolerance: None,
        },
        MapKind::Fourier => DispersionSpec::Fourier {
            sigma: None,
            harmonics: None,
            additive: false,
        },
        MapKind::Tv => DispersionSpec::TotalVariation {
            neighbours: None,
            interpolation: None,
        },
        MapKind::Polynomial => {
            return DispersionSpec::Polynomial {
                degree: trend.unwrap_or(3),
                scale: None,
            };
        }
    };
    match trend {
        Some(degree) => DispersionSpec::WithTrend {
            kernel: Box::new(kernel),
            degree,
            scale: None,
        },
        None => kernel,
    }
}

//! Output-error (simulation-error) refinement by Levenberg–Marquardt.

use nalgebra::{DMatrix, DVector};
use structid_lti::{Signal, filter_row};

use crate::arx::{ArxSettings, check_integrators, fit_arx_records, prepare_data, std_from};
use crate::error::{LinearError, check_sample_time};
use crate::integrators::{convolve, deflate, difference, full_covariance, integrator_polynomial};
use crate::levenberg_marquardt::{
    LeastSquaresProblem, LevenbergMarquardt, LmFit, LmSettings, LmSettingsBuilder, LmStatus,
};
use crate::normal_equations::NormalEquations;
use crate::orders::Orders;
use crate::polynomial::{PolynomialModel, root_radius, schur_stable, split_parameters};

/// Settings of [`output_error`] and [`oe`] (build with [`OeSettings::builder`];
/// [`Default`] is valid).
///
/// ```
/// use structid_linear::OeSettings;
/// let s = OeSettings::builder().max_iterations(50).transient(20).build().unwrap();
/// assert_eq!((s.max_iterations(), s.transient(), s.tolerance()), (50, 20, 1e-10));
/// assert!(OeSettings::builder().tolerance(-1.0).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct OeSettings {
    /// The refinement's Levenberg–Marquardt settings; the builder sets the iterations, the
    /// tolerance and μ₀, the rest is fixed (see [`Default`]).
    lm: LmSettings,
    transient: usize,
    sample_time: Option<f64>,
    arx: ArxSettings,
    integrators: usize,
}

impl Default for OeSettings {
    /// 100 iterations, relative cost decrease 1e-10, no transient, sample time from the
    /// initial model, initial damping μ₀ = 1e-3, default ARX settings for [`oe`]. The damping
    /// grows × 10 after a failed trial and shrinks ÷ 10 (floor 1e-15) after an accepted step,
    /// up to 1e20, with no limit on the trials of an iteration.
    fn default() -> Self {
        OeSettings {
            lm: LmSettings {
                max_step_attempts: usize::MAX,
                ..LmSettings::default()
            },
            transient: 0,
            sample_time: None,
            arx: ArxSettings::default(),
            integrators: 0,
        }
    }
}

impl OeSettings {
    /// A builder from the defaults.
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::builder().build().unwrap(), OeSettings::default());
    /// ```
    pub fn builder() -> OeSettingsBuilder {
        OeSettingsBuilder(Self::default())
    }
    /// Maximum number of Levenberg–Marquardt iterations (Jacobian evaluations).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::default().max_iterations(), 100);
    /// ```
    pub fn max_iterations(&self) -> usize {
        self.lm.max_iterations()
    }
    /// Convergence threshold on the relative cost decrease of an accepted step.
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::default().tolerance(), 1e-10);
    /// ```
    pub fn tolerance(&self) -> f64 {
        self.lm.tolerance()
    }
    /// Number of samples excluded at the start of the cost (the simulation still starts at
    /// sample 0 from zero initial conditions).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::default().transient(), 0);
    /// ```
    pub fn transient(&self) -> usize {
        self.transient
    }
    /// Sample time of the fitted model (`None`: that of the initial model).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::default().sample_time(), None);
    /// ```
    pub fn sample_time(&self) -> Option<f64> {
        self.sample_time
    }
    /// Initial Marquardt damping μ₀ (relative to `diag(JᵀJ)`).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::default().initial_damping(), 1e-3);
    /// ```
    pub fn initial_damping(&self) -> f64 {
        self.lm.initial_damping()
    }
    /// ARX settings used by [`oe`] for the initial model (its sample time is replaced by
    /// [`sample_time`](Self::sample_time) when that is set).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::default().arx().ridge(), 0.0);
    /// ```
    pub fn arx(&self) -> &ArxSettings {
        &self.arx
    }
    /// Number `N` of integrators fixed at `z = 1` (0 by default). [`oe`] then fits `na` free
    /// poles and returns `F = F'(1 − q⁻¹)ᴺ`, of order `na + N`; [`output_error()`] expects an
    /// initial denominator with `N` roots at `z = 1` and keeps them. Only `F'` must be stable
    /// (see [`crate::integrators`]). This count overrides that of [`arx`](Self::arx).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::default().integrators(), 0);
    /// ```
    pub fn integrators(&self) -> usize {
        self.integrators
    }
}

/// Builder for [`OeSettings`].
///
/// ```
/// use structid_linear::{ArxSettings, OeSettings};
/// let s = OeSettings::builder()
///     .sample_time(0.01)
///     .initial_damping(1e-2)
///     .arx(ArxSettings::builder().ridge(1e-8).build().unwrap())
///     .build()
///     .unwrap();
/// assert_eq!(s.arx().ridge(), 1e-8);
/// ```
#[derive(Clone, Debug)]
pub struct OeSettingsBuilder(OeSettings);

impl OeSettingsBuilder {
    /// Iteration limit (≥ 1).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert!(OeSettings::builder().max_iterations(0).build().is_err());
    /// ```
    pub fn max_iterations(mut self, n: usize) -> Self {
        self.0.lm.max_iterations = n;
        self
    }
    /// Relative cost-decrease tolerance (≥ 0, finite).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert!(OeSettings::builder().tolerance(0.0).build().is_ok());
    /// ```
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.0.lm.tolerance = tol;
        self
    }
    /// Samples excluded at the start of the cost.
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::builder().transient(10).build().unwrap().transient(), 10);
    /// ```
    pub fn transient(mut self, samples: usize) -> Self {
        self.0.transient = samples;
        self
    }
    /// Sample time in seconds (positive, finite).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert!(OeSettings::builder().sample_time(-1.0).build().is_err());
    /// ```
    pub fn sample_time(mut self, ts: f64) -> Self {
        self.0.sample_time = Some(ts);
        self
    }
    /// Initial damping μ₀ (> 0, finite).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert!(OeSettings::builder().initial_damping(0.0).build().is_err());
    /// ```
    pub fn initial_damping(mut self, mu: f64) -> Self {
        self.0.lm.initial_damping = mu;
        self
    }
    /// ARX settings for the initial model of [`oe`].
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// use structid_linear::ArxSettings;
    /// let s = OeSettings::builder().arx(ArxSettings::builder().ridge(1.0).build().unwrap());
    /// assert_eq!(s.build().unwrap().arx().ridge(), 1.0);
    /// ```
    pub fn arx(mut self, arx: ArxSettings) -> Self {
        self.0.arx = arx;
        self
    }
    /// Integrators fixed at `z = 1` (at most
    /// [`MAX_INTEGRATORS`](crate::integrators::MAX_INTEGRATORS)).
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert_eq!(OeSettings::builder().integrators(2).build().unwrap().integrators(), 2);
    /// assert!(OeSettings::builder().integrators(3).build().is_err());
    /// ```
    pub fn integrators(mut self, n: usize) -> Self {
        self.0.integrators = n;
        self
    }
    /// Validates.
    ///
    /// ```
    /// use structid_linear::OeSettings;
    /// assert!(OeSettings::builder().build().is_ok());
    /// ```
    pub fn build(self) -> Result<OeSettings, LinearError> {
        let s = self.0;
        LmSettingsBuilder(s.lm.clone()).build()?;
        check_sample_time(s.sample_time)?;
        check_integrators(s.integrators)?;
        Ok(s)
    }
}

/// Result of [`output_error()`] / [`oe`].
///
/// ```
/// use structid_linear::{oe, OeSettings, Orders};
/// use structid_lti::Signal;
/// let u = Signal::from_fn(200, 1, |k, _| ((k * k) as f64 * 0.37).sin());
/// let mut y = vec![0.0; 200];
/// for k in 1..200 {
///     y[k] = 0.8 * y[k - 1] + u.get(k - 1, 0);
/// }
/// let fit = oe(&u, &Signal::new(1, y).unwrap(), &Orders::siso(1, 1, 1), &OeSettings::default()).unwrap();
/// assert!(fit.converged && fit.cost <= fit.initial_cost);
/// assert_eq!(fit.costs.len(), fit.iterations);
/// assert!((fit.model.den[1] + 0.8).abs() < 1e-9);
/// ```
#[derive(Clone, Debug)]
pub struct OeFit {
    /// The fitted model (`den` = `F`).
    pub model: PolynomialModel,
    /// Mean squared simulation error over the samples after the transient.
    pub cost: f64,
    /// The same cost for the initial model.
    pub initial_cost: f64,
    /// Number of accepted Levenberg–Marquardt steps (`costs.len()`).
    pub iterations: usize,
    /// Cost after each accepted step (strictly decreasing, all below `initial_cost`).
    pub costs: Vec<f64>,
    /// Standard deviations of `θ = (b…, f…)` (order of [`PolynomialModel::parameters`]):
    /// `sqrt(σ̂² diag((ΨᵀΨ)⁻¹))` at the estimate, `σ̂² = SSE/(N − d)`, `Ψ = ∂ŷ/∂θ`
    /// (infinite when `ΨᵀΨ` is singular).
    pub parameter_std: Vec<f64>,
    /// The covariance of the same parameters, `σ̂² (ΨᵀΨ)⁻¹` (`None` when `ΨᵀΨ` is singular),
    /// for the uncertainty of what depends on several of them, such as the frequency
    /// response ([`crate::response`]).
    pub parameter_covariance: Option<DMatrix<f64>>,
    /// `true` when the relative cost decrease fell below the tolerance, or no damped step
    /// could lower the cost any more (a stationary point to working precision); `false` when
    /// the iteration limit stopped the search.
    pub converged: bool,
    /// Integrators fixed at `z = 1` ([`OeSettings::integrators`]).
    pub integrators: usize,
    /// Simulation fit after the transient, `100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖)` % (0 % is the fit
    /// of the constant ȳ; −∞ when the output is constant and not matched).
    pub fit_percent: f64,
    /// Set when the fit is degenerate: worse than a constant, an output near zero, or a fixed
    /// integrator cancelled by a zero. A fit that ends there must not be used as a nominal
    /// model without a look.
    pub warning: Option<OeWarning>,
}

impl OeFit {
    /// The fit of `model` found by a Levenberg–Marquardt search over `samples` scored
    /// samples, with `integrators` poles held at `z = 1`: the solver's sums of squares become
    /// mean costs, and a search that ends because no damped step lowers the cost any more
    /// counts as converged (a stationary point to working precision). What the search alone
    /// does not tell is left unknown: standard deviations NaN (one per parameter of
    /// `fit.theta`), no covariance, fit per cent NaN, no warning; a caller that knows them
    /// sets them.
    ///
    /// ```
    /// # use nalgebra::{DMatrix, DVector};
    /// # use structid_linear::levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
    /// use structid_linear::{OeFit, PolynomialModel};
    /// // Four samples of y = 2 fitted by a gain θ: r(θ) = (θ − 2, θ − 2, θ − 2, θ − 2).
    /// # struct Gain;
    /// # impl LeastSquaresProblem for Gain {
    /// #     fn residuals(&mut self, th: &[f64]) -> Option<DVector<f64>> { Some(DVector::from_element(4, th[0] - 2.0)) }
    /// #     fn jacobian(&mut self, _: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> { Some(DMatrix::from_element(4, 1, 1.0)) }
    /// # }
    /// let lm = LevenbergMarquardt::default().minimize(&mut Gain, &[0.0]).unwrap();
    /// let model = PolynomialModel::new(vec![vec![lm.theta[0]]], vec![1.0], None).unwrap();
    /// let fit = OeFit::from_lm(model, &lm, 4, 0);
    /// assert_eq!((fit.initial_cost, fit.iterations), (4.0, lm.costs.len()));
    /// assert!(fit.converged && fit.parameter_std[0].is_nan() && fit.warning.is_none());
    /// ```
    pub fn from_lm(
        model: PolynomialModel,
        fit: &LmFit,
        samples: usize,
        integrators: usize,
    ) -> Self {
        let n = samples as f64;
        OeFit {
            model,
            cost: fit.cost / n,
            initial_cost: fit.initial_cost / n,
            iterations: fit.costs.len(),
            costs: fit.costs.iter().map(|c| c / n).collect(),
            parameter_std: vec![f64::NAN; fit.theta.len()],
            parameter_covariance: None,
            converged: matches!(fit.status, LmStatus::Converged(_) | LmStatus::NoProgress),
            integrators,
            fit_percent: f64::NAN,
            warning: None,
        }
    }
}

/// A degenerate output-error fit, reported by [`OeFit::warning`].
///
/// ```
/// use structid_linear::output_error::OeWarning;
/// let w = OeWarning::WorseThanConstant { fit_percent: -77.0 };
/// assert!(w.to_string().contains("worse than a constant"));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub enum OeWarning {
    /// The simulated output stays near zero: `‖ŷ‖ < 0.01 ‖y‖`. Typical of an integrating
    /// plant fitted with free (stable) poles, or of an input that does not excite the output.
    OutputNearZero {
        /// `‖ŷ‖ / ‖y‖`.
        ratio: f64,
        /// The fit, per cent.
        fit_percent: f64,
    },
    /// The fit is below 0 %: the constant mean of the output simulates it better.
    WorseThanConstant {
        /// The fit, per cent.
        fit_percent: f64,
    },
    /// A zero of the fitted numerator cancels a fixed integrator
    /// ([`integrator_cancellation`](crate::integrators::integrator_cancellation) below
    /// [`CANCELLATION`](crate::integrators::CANCELLATION)): the model does not integrate,
    /// whatever its denominator says.
    IntegratorCancelled {
        /// `|B(1)| / Σ|bᵢ|`.
        ratio: f64,
        /// The fit, per cent.
        fit_percent: f64,
    },
}

impl std::fmt::Display for OeWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let hint = "if the plant integrates (a position driven by a force, a level driven by a \
                    flow), hold its integrator at z = 1 (`OeSettings::integrators`)";
        match self {
            OeWarning::OutputNearZero { ratio, fit_percent } => write!(
                f,
                "the output-error fit simulates an output near zero ({:.2} % of the data's size; \
                 fit {fit_percent:.1} %): the model explains nothing; {hint}",
                100.0 * ratio
            ),
            OeWarning::WorseThanConstant { fit_percent } => write!(
                f,
                "the output-error fit ({fit_percent:.1} %) is worse than a constant (0 %); {hint}"
            ),
            OeWarning::IntegratorCancelled { ratio, fit_percent } => write!(
                f,
                "a zero of the fitted numerator cancels the fixed integrator (|B(1)| is {:.2} % \
                 of Σ|bᵢ|; fit {fit_percent:.1} %), so the model does not integrate: the record \
                 does not show the integrating behaviour. In closed loop the direct fit of u → y \
                 tends to the controller's negative inverse when the controller's action \
                 dominates the input; friction that holds the output still does the same. Use a \
                 physical nominal, or a record with open-loop or reference excitation",
                100.0 * ratio
            ),
        }
    }
}

/// The fit per cent and the warning of a simulation `ŷ` of `y` over `k ≥ transient`.
pub(crate) fn judge_fit(y: &[f64], yhat: &[f64], transient: usize) -> (f64, Option<OeWarning>) {
    let (y, yhat) = (
        &y[transient.min(y.len())..],
        &yhat[transient.min(yhat.len())..],
    );
    let n = y.len().max(1) as f64;
    let mean = y.iter().sum::<f64>() / n;
    let err: f64 = y.iter().zip(yhat).map(|(a, b)| (a - b).powi(2)).sum();
    let spread: f64 = y.iter().map(|a| (a - mean).powi(2)).sum();
    let fit = if spread > 0.0 {
        100.0 * (1.0 - (err / spread).sqrt())
    } else if err == 0.0 {
        100.0
    } else {
        f64::NEG_INFINITY
    };
    let size: f64 = y.iter().map(|a| a * a).sum();
    let out: f64 = yhat.iter().map(|a| a * a).sum();
    let ratio = if size > 0.0 { (out / size).sqrt() } else { 1.0 };
    let warning = if ratio < 0.01 {
        Some(OeWarning::OutputNearZero {
            ratio,
            fit_percent: fit,
        })
    } else if fit < 0.0 || fit.is_nan() {
        Some(OeWarning::WorseThanConstant { fit_percent: fit })
    } else {
        None
    };
    (fit, warning)
}

/// Output-error refinement by Levenberg–Marquardt starting from `initial` (e.g. an ARX fit,
/// whose `den`/`num` set the orders `nf = na`, `nb`, `nk`; see [`PolynomialModel::orders`]).
///
/// Minimises `V(θ) = 1/N Σ_{k ≥ transient} (y_k − ŷ_k(θ))²` with
/// `ŷ = Σ_i B_i(q)/F(q) u_i` simulated from zero initial conditions. The initial
/// denominator must be stable ([`LinearError::UnstableInitialModel`] otherwise); steps that
/// would make `F` unstable are rejected. Non-convergence within the iteration limit is
/// reported by [`OeFit::converged`], not as an error.
///
/// ```
/// use structid_linear::{output_error, OeSettings, PolynomialModel};
/// use structid_lti::Signal;
/// let truth = PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None).unwrap();
/// let u = Signal::from_fn(300, 1, |k, _| ((k * k) as f64 * 0.37).sin());
/// let y = Signal::new(1, truth.simulate(&u).unwrap()).unwrap();
/// let start = PolynomialModel::new(vec![vec![0.0, 0.9, 0.6]], vec![1.0, -1.4, 0.6], None).unwrap();
/// let fit = output_error(&u, &y, &start, &OeSettings::default()).unwrap();
/// assert!(fit.converged && fit.cost < 1e-20 && fit.cost < fit.initial_cost);
/// assert!((fit.model.den[2] - 0.7).abs() < 1e-8);
/// ```
pub fn output_error(
    u: &Signal,
    y: &Signal,
    initial: &PolynomialModel,
    settings: &OeSettings,
) -> Result<OeFit, LinearError> {
    output_error_records(&[(u, y)], initial, settings)
}

/// [`output_error()`] over several records (experiments) of the same system, given as
/// `(u, y)` pairs: one Levenberg–Marquardt fit of the stacked simulation errors, each record
/// simulated from rest (zero initial conditions at its own first sample) and its first
/// `transient` samples left out of the cost. The sensitivities restart with the records too,
/// so the Jacobian is that of the stacked residual. This is not the fit of the concatenated
/// record, which would carry the state at the end of one record into the next.
///
/// `cost` is the mean over every scored sample of every record; `fit_percent` and the
/// warnings are those of the pooled scored samples. One record gives [`output_error()`]'s fit.
///
/// ```
/// use structid_linear::{output_error, output_error_records, OeSettings, PolynomialModel};
/// use structid_lti::Signal;
/// let truth = PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None)?;
/// let rec = |len: usize, shift: usize| {
///     let u = Signal::from_fn(len, 1, |k, _| (((k + shift) * (k + shift)) as f64 * 0.37).sin());
///     let y = Signal::new(1, truth.simulate(&u).unwrap()).unwrap();
///     (u, y)
/// };
/// let (a, b) = (rec(200, 0), rec(150, 11));
/// let start = PolynomialModel::new(vec![vec![0.0, 0.9, 0.6]], vec![1.0, -1.4, 0.6], None)?;
/// let s = OeSettings::default();
/// let fit = output_error_records(&[(&a.0, &a.1), (&b.0, &b.1)], &start, &s)?;
/// assert!(fit.cost < 1e-20 && (fit.model.den[2] - 0.7).abs() < 1e-8);
/// // One record is output_error itself.
/// let one = output_error_records(&[(&a.0, &a.1)], &start, &s)?;
/// assert_eq!(one.model, output_error(&a.0, &a.1, &start, &s)?.model);
/// # Ok::<(), structid_linear::LinearError>(())
/// ```
pub fn output_error_records(
    records: &[(&Signal, &Signal)],
    initial: &PolynomialModel,
    settings: &OeSettings,
) -> Result<OeFit, LinearError> {
    initial.validate()?;
    let n = settings.integrators;
    let free = if n == 0 {
        initial.clone()
    } else {
        let den = deflate(&initial.den, n).ok_or_else(|| {
            LinearError::InvalidModel(format!(
                "the initial denominator does not have the {n} root(s) at z = 1 that \
                 OeSettings::integrators fixes"
            ))
        })?;
        PolynomialModel::new(initial.num.clone(), den, initial.sample_time)?
    };
    let orders = free.orders();
    orders.validate()?;
    let stacked = Stacked::new(records, initial.inputs())?;
    refine(&stacked, &free, &orders, settings)
}

/// Several `(u, y)` records checked and stacked: input channels, output, and the record
/// bounds `[0, L₁, …, L]`.
pub(crate) struct Stacked {
    pub(crate) u: Vec<Vec<f64>>,
    pub(crate) y: Vec<f64>,
    pub(crate) bounds: Vec<usize>,
}

impl Stacked {
    pub(crate) fn new(records: &[(&Signal, &Signal)], inputs: usize) -> Result<Self, LinearError> {
        if records.is_empty() {
            return Err(LinearError::param("records", "no data record was given"));
        }
        let several = records.len() > 1;
        let mut u: Vec<Vec<f64>> = vec![Vec::new(); inputs];
        let mut y = Vec::new();
        let mut bounds = vec![0];
        for (i, (ui, yi)) in records.iter().enumerate() {
            let prefix = if several {
                format!("record {}: ", i + 1)
            } else {
                String::new()
            };
            let (uc, yv) = prepare_data(ui, yi, inputs, &prefix)?;
            for (c, col) in u.iter_mut().zip(uc) {
                c.extend(col);
            }
            y.extend(yv);
            bounds.push(y.len());
        }
        Ok(Stacked { u, y, bounds })
    }
}

/// The Levenberg–Marquardt iteration of [`output_error()`] on checked data, with the orders
/// given explicitly (they are not re-read from the leading zeros of `initial.num`).
/// `initial` and `orders` are those of the free part: `settings.integrators` poles at
/// `z = 1` are multiplied onto its denominator.
fn refine(
    data: &Stacked,
    initial: &PolynomialModel,
    orders: &Orders,
    settings: &OeSettings,
) -> Result<OeFit, LinearError> {
    let (uc, yv) = (&data.u, &data.y);
    let len = yv.len();
    let d = orders.parameters();
    let needed = settings.transient + d + 1;
    let scored = scored_samples(&data.bounds, settings.transient);
    if scored < d + 1 {
        let records = data.bounds.len() - 1;
        return Err(LinearError::TooFewSamples {
            what: format!(
                "output error with orders {orders} ({d} parameters) after a transient of {} samples{}",
                settings.transient,
                if records > 1 {
                    format!(" in each of {records} records")
                } else {
                    String::new()
                }
            ),
            needed,
            available: if records > 1 {
                scored + settings.transient
            } else {
                len
            },
        });
    }
    if !schur_stable(&initial.den) {
        return Err(LinearError::UnstableInitialModel {
            spectral_radius: root_radius(&initial.den),
        });
    }
    let n_int = settings.integrators;
    let mut problem = Problem {
        u: uc,
        y: yv,
        bounds: &data.bounds,
        orders,
        transient: settings.transient,
        fixed: integrator_polynomial(n_int),
        last: None,
    };
    let fit = LevenbergMarquardt::new(settings.lm.clone())
        .minimize(&mut problem, &parameters_for(initial, orders))
        .map_err(|e| match e {
            // the initial model is finite and stable, so only its simulation can fail
            LinearError::InvalidStart(_) => {
                LinearError::InvalidModel("the simulation of the initial model overflows".into())
            }
            other => other,
        })?;
    let nb_total: usize = orders.nb.iter().sum();
    let parameter_covariance = fit
        .covariance(&mut problem)
        .map(|c| full_covariance(&c, nb_total, orders.na, n_int));
    let parameter_std = parameter_covariance
        .as_ref()
        .map(std_from)
        .unwrap_or_else(|| vec![f64::INFINITY; d + n_int]);
    let theta = &fit.theta;
    let sample_time = settings.sample_time.or(initial.sample_time);
    let free = PolynomialModel::from_parameters(orders, theta, sample_time)?;
    let den = convolve(&free.den, &problem.fixed);
    let model = PolynomialModel::new(free.num, den, sample_time)?;
    problem.simulate_at(theta);
    let (fit_percent, mut warning) = match &problem.last {
        Some((_, yhat)) => {
            // Pooled over the scored samples of every record.
            let (ys, yh): (Vec<f64>, Vec<f64>) =
                problem.scored().map(|(k, _)| (yv[k], yhat[k])).unzip();
            judge_fit(&ys, &yh, 0)
        }
        None => (f64::NAN, None),
    };
    if warning.is_none()
        && n_int > 0
        && let Some(ratio) = crate::integrators::integrator_cancellation(&model)
        && ratio < crate::integrators::CANCELLATION
    {
        warning = Some(OeWarning::IntegratorCancelled { ratio, fit_percent });
    }
    Ok(OeFit {
        parameter_std,
        parameter_covariance,
        fit_percent,
        warning,
        ..OeFit::from_lm(model, &fit, scored, n_int)
    })
}

/// Convenience: [`arx`](crate::arx()) with `orders` (ARX settings from
/// [`OeSettings::arx`]), then [`output_error`] from the ARX model.
///
/// If the ARX denominator happens to be unstable, its roots are first pulled radially
/// inside the unit circle (`a_j ← a_j c^j` with `c = 0.95 / max|root|`), which keeps the
/// shape of the model and makes it a valid starting point. With
/// [`OeSettings::integrators`] `N > 0`, the ARX fit is that of `(1 − q⁻¹)ᴺ y` and `orders.na`
/// counts the free poles only.
///
/// ```
/// use structid_linear::{oe, OeSettings, Orders, PolynomialModel};
/// use structid_lti::Signal;
/// let truth = PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None).unwrap();
/// let u = Signal::from_fn(300, 1, |k, _| ((k * k) as f64 * 0.37).sin());
/// let y = Signal::new(1, truth.simulate(&u).unwrap()).unwrap();
/// let fit = oe(&u, &y, &Orders::siso(2, 2, 1), &OeSettings::default()).unwrap();
/// assert!((fit.model.den[1] + 1.5).abs() < 1e-8);
/// ```
pub fn oe(
    u: &Signal,
    y: &Signal,
    orders: &Orders,
    settings: &OeSettings,
) -> Result<OeFit, LinearError> {
    oe_records(&[(u, y)], orders, settings)
}

/// [`oe`] over several records of the same system: the starting ARX model is fitted on the
/// equations of every record (as [`arx_records`](crate::arx_records)), then
/// [`output_error_records`] refines it with each record simulated from rest. One record gives
/// [`oe`]'s fit.
///
/// ```
/// use structid_linear::{oe_records, OeSettings, Orders, PolynomialModel};
/// use structid_lti::Signal;
/// // A chirp and a square wave through G = (q⁻¹ + 0.5q⁻²)/(1 − 1.5q⁻¹ + 0.7q⁻²).
/// let g = PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None)?;
/// let chirp = Signal::from_fn(200, 1, |k, _| (0.002 * (k * k) as f64).sin());
/// let square = Signal::from_fn(150, 1, |k, _| if (k / 7) % 2 == 0 { 1.0 } else { -1.0 });
/// let outputs = [&chirp, &square].map(|u| Signal::new(1, g.simulate(u).unwrap()).unwrap());
/// let records = [(&chirp, &outputs[0]), (&square, &outputs[1])];
/// let fit = oe_records(&records, &Orders::siso(2, 2, 1), &OeSettings::default())?;
/// assert!((fit.model.den[1] + 1.5).abs() < 1e-8);
/// # Ok::<(), structid_linear::LinearError>(())
/// ```
pub fn oe_records(
    records: &[(&Signal, &Signal)],
    orders: &Orders,
    settings: &OeSettings,
) -> Result<OeFit, LinearError> {
    orders.validate()?;
    let data = Stacked::new(records, orders.inputs())?;
    let mut arx_settings = settings.arx.clone();
    if settings.sample_time.is_some() {
        arx_settings.sample_time = settings.sample_time;
    }
    // The free part A' of an ARX fit of the differenced output starts the search; each record
    // is differenced on its own, its first N samples being no equations.
    let n = settings.integrators;
    let yd: Vec<f64> = data
        .bounds
        .windows(2)
        .flat_map(|w| difference(&data.y[w[0]..w[1]], n))
        .collect();
    let mut initial = fit_arx_records(
        &data.u,
        &yd,
        orders,
        &arx_settings,
        &data.bounds,
        orders.max_lag() + n,
    )?
    .0
    .model;
    if !schur_stable(&initial.den) {
        let r = root_radius(&initial.den);
        let c = 0.95 / r;
        for (j, a) in initial.den.iter_mut().enumerate() {
            *a *= c.powi(j as i32);
        }
    }
    refine(&data, &initial, orders, settings)
}

/// Samples scored by the cost: those of each record after its first `transient`.
fn scored_samples(bounds: &[usize], transient: usize) -> usize {
    bounds
        .windows(2)
        .map(|w| (w[1] - w[0]).saturating_sub(transient))
        .sum()
}

/// `θ = (b…, f…)` of `model` for the given orders (normalised by `den[0]`; missing
/// coefficients are 0).
fn parameters_for(model: &PolynomialModel, orders: &Orders) -> Vec<f64> {
    let a0 = model.den[0];
    let mut theta = Vec::with_capacity(orders.parameters());
    for (i, (&nb, &nk)) in orders.nb.iter().zip(&orders.nk).enumerate() {
        theta.extend((0..nb).map(|j| model.num[i].get(nk + j).map_or(0.0, |v| v / a0)));
    }
    theta.extend((1..=orders.na).map(|j| model.den.get(j).map_or(0.0, |v| v / a0)));
    theta
}

/// All-pole filtered signals and, per parameter, (filtered signal, lag, sign).
type Sensitivities = (Vec<Vec<f64>>, Vec<(usize, usize, f64)>);

/// The data and structure of an output-error problem; parameters `θ = (b…, f…)`,
/// residuals `ε_k = y_k − ŷ_k(θ)` after the transient of each record, rejecting unstable
/// denominators. Each record (`bounds`) is simulated from rest, and so are the sensitivities.
struct Problem<'a> {
    u: &'a [Vec<f64>],
    y: &'a [f64],
    /// Where each record starts, then the total length: `[0, L₁, …, L]`.
    bounds: &'a [usize],
    orders: &'a Orders,
    transient: usize,
    /// The fixed denominator factor `(1 − q⁻¹)ᴺ` (`[1]` without integrators).
    fixed: Vec<f64>,
    /// The last simulation `(θ, ŷ)`: the sensitivities filter all of ŷ (the transient
    /// included), so the normal equations at an accepted θ reuse it instead of simulating
    /// again.
    last: Option<(Vec<f64>, Vec<f64>)>,
}

impl LeastSquaresProblem for Problem<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        if !self.stable(theta) {
            return None;
        }
        let yhat = self.simulate(theta);
        let r = DVector::from_iterator(
            scored_samples(self.bounds, self.transient),
            self.scored().map(|(k, _)| self.y[k] - yhat[k]),
        );
        self.last = Some((theta.to_vec(), yhat));
        Some(r)
    }

    /// `∂ε/∂θ = −Ψ`, materialised (the solver itself uses [`Self::normal_equations`]).
    fn jacobian(&mut self, theta: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> {
        self.simulate_at(theta);
        let Some((_, yhat)) = &self.last else {
            return None;
        };
        let (filtered, cols) = self.sensitivities(theta, yhat);
        let rows: Vec<(usize, usize)> = self.scored().collect();
        Some(DMatrix::from_fn(rows.len(), theta.len(), |row, p| {
            let (f, lag, sign) = cols[p];
            let (k, start) = rows[row];
            if k >= start + lag {
                -sign * filtered[f][k - lag]
            } else {
                0.0
            }
        }))
    }

    fn normal_equations(
        &mut self,
        theta: &[f64],
        _: &DVector<f64>,
    ) -> Option<(DMatrix<f64>, DVector<f64>)> {
        self.simulate_at(theta);
        let Some((_, yhat)) = &self.last else {
            return None;
        };
        let (h, g) = self.psi_normal_equations(theta, yhat);
        // Jᵀε with J = −Ψ
        Some((h, -g))
    }
}

impl Problem<'_> {
    /// The scored samples `(k, first sample of k's record)`, record after record.
    fn scored(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let t = self.transient;
        self.bounds
            .windows(2)
            .flat_map(move |w| ((w[0] + t).min(w[1])..w[1]).map(move |k| (k, w[0])))
    }

    /// Each record's samples `start..end`.
    fn records(&self) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        self.bounds.windows(2).map(|w| w[0]..w[1])
    }

    fn split(&self, theta: &[f64]) -> (Vec<f64>, Vec<Vec<f64>>) {
        split_parameters(self.orders, theta)
    }

    fn stable(&self, theta: &[f64]) -> bool {
        schur_stable(&self.split(theta).0)
    }

    /// `signals` filtered by `num/den`, record by record from rest.
    fn filter<S: AsRef<[f64]>>(&self, num: &[Vec<f64>], den: &[f64], signals: &[S]) -> Vec<f64> {
        let mut out = vec![0.0; self.y.len()];
        for r in self.records() {
            let parts: Vec<&[f64]> = signals.iter().map(|s| &s.as_ref()[r.clone()]).collect();
            filter_row(num, den, &parts, &mut out[r]);
        }
        out
    }

    fn simulate(&self, theta: &[f64]) -> Vec<f64> {
        let (den, num) = self.split(theta);
        let den = convolve(&den, &self.fixed);
        self.filter(&num, &den, self.u)
    }

    /// Makes `last` the simulation at θ (simulating only when it is not).
    fn simulate_at(&mut self, theta: &[f64]) {
        if !matches!(&self.last, Some((t, _)) if t == theta) {
            self.last = Some((theta.to_vec(), self.simulate(theta)));
        }
    }

    /// The sensitivities `∂ŷ/∂b_{i,j} = q^{−(nk_i+j)}/(F'Δ) · u_i` and
    /// `∂ŷ/∂f'_j = −q^{−j}/F' · ŷ` (`Δ` the fixed factor, `F = F'Δ`) as `n_u + 1` all-pole
    /// filtered signals (each record from rest) and, per parameter, (filtered signal, lag,
    /// sign); a lagged sample before its record's start is zero.
    fn sensitivities(&self, theta: &[f64], yhat: &[f64]) -> Sensitivities {
        let (free, _) = self.split(theta);
        let den = convolve(&free, &self.fixed);
        let d = theta.len();
        let one = [vec![1.0]];
        // (filtered signal, lag, sign) per parameter
        let mut filtered: Vec<Vec<f64>> = Vec::new();
        let mut cols: Vec<(usize, usize, f64)> = Vec::with_capacity(d);
        for (i, (&nb, &nk)) in self.orders.nb.iter().zip(&self.orders.nk).enumerate() {
            if nb == 0 {
                continue;
            }
            filtered.push(self.filter(&one, &den, &[&self.u[i]]));
            for j in 0..nb {
                cols.push((filtered.len() - 1, nk + j, 1.0));
            }
        }
        if self.orders.na > 0 {
            filtered.push(self.filter(&one, &free, &[yhat]));
            for j in 1..=self.orders.na {
                cols.push((filtered.len() - 1, j, -1.0));
            }
        }
        (filtered, cols)
    }

    /// `(ΨᵀΨ, Ψᵀε)` over the scored samples, accumulated row by row from the sensitivities
    /// (`O(L·d²)`, Ψ never stored).
    fn psi_normal_equations(&self, theta: &[f64], yhat: &[f64]) -> (DMatrix<f64>, DVector<f64>) {
        let (filtered, cols) = self.sensitivities(theta, yhat);
        let d = theta.len();
        let mut normal = NormalEquations::new(d);
        let mut psi = vec![0.0; d];
        for (k, start) in self.scored() {
            for (p, &(f, lag, sign)) in cols.iter().enumerate() {
                psi[p] = if k >= start + lag {
                    sign * filtered[f][k - lag]
                } else {
                    0.0
                };
            }
            normal.add_row(&psi, self.y[k] - yhat[k]);
        }
        normal.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arx::arx;
    use crate::testutil::*;

    fn truth() -> PolynomialModel {
        PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], Some(0.1)).unwrap()
    }

    #[test]
    fn output_noise_oe_beats_biased_arx() {
        let g = truth();
        let len = 5000;
        let u = white(21, len, 1.0, 1);
        let y0 = g.simulate(&u).unwrap();
        let rms = (y0.iter().map(|v| v * v).sum::<f64>() / len as f64).sqrt();
        // SNR 20 dB: noise std = rms / 10
        let e = white(22, len, rms / 10.0, 1);
        let y = Signal::new(1, y0.iter().zip(e.as_slice()).map(|(a, b)| a + b).collect()).unwrap();
        let orders = Orders::siso(2, 2, 1);
        let arx_fit = arx(&u, &y, &orders, &ArxSettings::default()).unwrap();
        let fit = oe(&u, &y, &orders, &OeSettings::default()).unwrap();
        assert!(fit.converged);
        assert_eq!(fit.model.sample_time, None);
        let t = g.parameters();
        let est = fit.model.parameters();
        for (p, ((a, b), s)) in est.iter().zip(&t).zip(&fit.parameter_std).enumerate() {
            assert!(s.is_finite() && *s > 0.0);
            assert!(
                (a - b).abs() < 3.0 * s,
                "parameter {p}: {a} vs {b}, std {s}"
            );
        }
        let dist = |x: &[f64]| {
            x.iter()
                .zip(&t)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let (d_oe, d_arx) = (dist(&est), dist(&arx_fit.model.parameters()));
        assert!(d_oe < d_arx, "OE error {d_oe} vs ARX error {d_arx}");
        assert!(fit.cost < fit.initial_cost);
        // the cost approaches the noise variance
        let var = (rms / 10.0).powi(2);
        assert!((fit.cost / var - 1.0).abs() < 0.1, "{} vs {var}", fit.cost);
        assert_non_increasing(&fit);
    }

    fn assert_non_increasing(fit: &OeFit) {
        let mut prev = fit.initial_cost;
        for &c in &fit.costs {
            assert!(c <= prev, "cost increased: {c} > {prev}");
            prev = c;
        }
        assert_eq!(fit.costs.len(), fit.iterations);
        assert_eq!(
            fit.costs.last().copied().unwrap_or(fit.initial_cost),
            fit.cost
        );
    }

    #[test]
    fn far_start_transient_and_miso() {
        let g = PolynomialModel::new(
            vec![vec![0.3, 0.4], vec![0.0, 0.0, -0.8]],
            vec![1.0, -1.2, 0.5],
            None,
        )
        .unwrap();
        let u = white(31, 800, 1.0, 2);
        let y = Signal::new(1, g.simulate(&u).unwrap()).unwrap();
        let start = PolynomialModel::new(
            vec![vec![1.0, 0.0], vec![0.0, 0.0, 1.0]],
            vec![1.0, 0.3, 0.0],
            None,
        )
        .unwrap();
        let s = OeSettings::builder()
            .transient(50)
            .sample_time(0.5)
            .build()
            .unwrap();
        let fit = output_error(&u, &y, &start, &s).unwrap();
        assert!(fit.converged, "{fit:?}");
        assert_close(&fit.model.parameters(), &g.parameters(), 1e-7);
        assert_eq!(fit.model.sample_time, Some(0.5));
        assert!(fit.parameter_std.iter().all(|v| v.is_finite()));
        assert_non_increasing(&fit);
        // the iteration limit reports non-convergence, not an error
        let s1 = OeSettings::builder().max_iterations(1).build().unwrap();
        let f1 = output_error(&u, &y, &start, &s1).unwrap();
        assert!(!f1.converged);
        assert!(f1.iterations <= 1);
    }

    #[test]
    fn accumulated_normal_equations_equal_those_of_the_jacobian() {
        // with no fixed factor, and with a fixed integrator (the sensitivities then use F'Δ
        // for the inputs and F' alone for ŷ)
        for fixed in [vec![1.0], vec![1.0, -1.0]] {
            let g = PolynomialModel::new(
                vec![vec![0.3, 0.4], vec![0.0, 0.0, -0.8]],
                vec![1.0, -1.2, 0.5],
                None,
            )
            .unwrap();
            let u = white(51, 300, 1.0, 2);
            let y = white(52, 300, 1.0, 1);
            let orders = g.orders();
            let (uc, yv) = prepare_data(&u, &y, 2, "").unwrap();
            let bounds = [0, yv.len()];
            let mut p = Problem {
                u: &uc,
                y: &yv,
                bounds: &bounds,
                orders: &orders,
                transient: 20,
                fixed: fixed.clone(),
                last: None,
            };
            let theta = parameters_for(&g, &orders);
            let r = p.residuals(&theta).unwrap();
            let j = p.jacobian(&theta, &r).unwrap();
            let (h, jtr) = p.normal_equations(&theta, &r).unwrap();
            let h_ref = j.transpose() * &j;
            let jtr_ref = j.transpose() * &r;
            assert!((&h - &h_ref).norm() <= 1e-12 * h_ref.norm());
            assert!((&jtr - &jtr_ref).norm() <= 1e-12 * jtr_ref.norm());
            // J = −∂ŷ/∂θ: a finite difference of the residuals
            let step = 1e-7;
            let mut t = theta.clone();
            t[4] += step;
            let fd = (p.residuals(&t).unwrap() - &r) / step;
            assert!((fd - j.column(4)).norm() <= 1e-5 * j.column(4).norm());
            // unstable denominators are rejected
            let mut bad = theta.clone();
            bad[4] = 1.5;
            assert!(p.residuals(&bad).is_none());
        }
    }

    /// A record of `truth` simulated from rest with white input and output noise.
    fn record(truth: &PolynomialModel, seed: u64, len: usize, noise: f64) -> (Signal, Signal) {
        let u = white(seed, len, 1.0, truth.inputs());
        let e = white(seed + 1000, len, noise, 1);
        let y0 = truth.simulate(&u).unwrap();
        let y = y0.iter().zip(e.as_slice()).map(|(a, b)| a + b).collect();
        (u, Signal::new(1, y).unwrap())
    }

    /// The stacked cost of `model` computed independently of the fit: each record simulated
    /// from rest by `PolynomialModel::simulate`, its first `transient` samples left out.
    fn stacked_cost(
        model: &PolynomialModel,
        records: &[(Signal, Signal)],
        transient: usize,
    ) -> f64 {
        let (mut s, mut n) = (0.0, 0);
        for (u, y) in records {
            let sim = model.simulate(u).unwrap();
            for k in transient..y.len() {
                s += (y.get(k, 0) - sim[k]).powi(2);
                n += 1;
            }
        }
        s / n as f64
    }

    fn concatenated(records: &[(Signal, Signal)]) -> (Signal, Signal) {
        let cat = |f: &dyn Fn(&(Signal, Signal)) -> &Signal| {
            let ch = f(&records[0]).channels();
            Signal::new(
                ch,
                records
                    .iter()
                    .flat_map(|r| f(r).as_slice().to_vec())
                    .collect(),
            )
            .unwrap()
        };
        (cat(&|r| &r.0), cat(&|r| &r.1))
    }

    #[test]
    fn records_restart_from_rest_where_their_concatenation_does_not() {
        // A slow pole: the state at the end of one record is far from rest.
        let g =
            PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.6, 0.8], None).unwrap();
        let records = vec![record(&g, 61, 300, 0.01), record(&g, 62, 200, 0.01)];
        let pairs: Vec<(&Signal, &Signal)> = records.iter().map(|(u, y)| (u, y)).collect();
        let orders = Orders::siso(2, 2, 1);
        let s = OeSettings::default();
        let fit = oe_records(&pairs, &orders, &s).unwrap();
        assert!(fit.converged);
        assert_non_increasing(&fit);
        let truth = g.parameters();
        let dist = |x: &[f64]| {
            x.iter()
                .zip(&truth)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let est = fit.model.parameters();
        for (p, ((a, b), sd)) in est.iter().zip(&truth).zip(&fit.parameter_std).enumerate() {
            assert!(
                (a - b).abs() < 4.0 * sd,
                "parameter {p}: {a} vs {b}, std {sd}"
            );
        }
        // The reported cost is the stacked cost with each record from rest, and the estimate
        // is its minimum: no coordinate step lowers it.
        let cost = stacked_cost(&fit.model, &records, 0);
        assert!(
            (fit.cost - cost).abs() <= 1e-10 * cost,
            "{} vs {cost}",
            fit.cost
        );
        assert!(
            (cost / 1e-4 - 1.0).abs() < 0.15,
            "noise variance 1e-4, cost {cost}"
        );
        let theta = fit.model.parameters();
        for p in 0..theta.len() {
            for h in [-1e-4, 1e-4] {
                let mut t = theta.clone();
                t[p] += h;
                let m = PolynomialModel::from_parameters(&orders, &t, None).unwrap();
                assert!(
                    stacked_cost(&m, &records, 0) > cost,
                    "parameter {p} step {h}"
                );
            }
        }
        // The concatenated record carries the first record's final state into the second:
        // a different (worse) estimate.
        let (uc, yc) = concatenated(&records);
        let glued = oe(&uc, &yc, &orders, &s).unwrap();
        let d_glued = dist(&glued.model.parameters());
        let d_records = dist(&est);
        assert!(
            d_records < 0.5 * d_glued,
            "records {d_records} vs concatenation {d_glued}"
        );
        assert!(stacked_cost(&glued.model, &records, 0) > cost);
        // One record is oe itself; the records' order does not matter.
        let one = oe_records(&pairs[..1], &orders, &s).unwrap();
        let direct = oe(pairs[0].0, pairs[0].1, &orders, &s).unwrap();
        assert_eq!(one.model, direct.model);
        assert_eq!(one.cost, direct.cost);
        let swapped = oe_records(&[pairs[1], pairs[0]], &orders, &s).unwrap();
        assert_close(&swapped.model.parameters(), &est, 1e-8);
        assert!(oe_records(&[], &orders, &s).is_err());
    }

    #[test]
    fn records_with_a_transient_and_a_fixed_integrator() {
        // G = 0.1 q⁻¹ (1 + 0.5 q⁻¹) / ((1 − 0.6 q⁻¹)(1 − q⁻¹))
        let g = PolynomialModel::new(
            vec![vec![0.0, 0.1, 0.05]],
            convolve(&[1.0, -0.6], &[1.0, -1.0]),
            None,
        )
        .unwrap();
        let records = [record(&g, 71, 250, 0.0), record(&g, 72, 180, 0.0)];
        let pairs: Vec<(&Signal, &Signal)> = records.iter().map(|(u, y)| (u, y)).collect();
        let s = OeSettings::builder()
            .integrators(1)
            .transient(5)
            .build()
            .unwrap();
        let fit = oe_records(&pairs, &Orders::siso(1, 2, 1), &s).unwrap();
        assert_eq!(fit.integrators, 1);
        assert_close(&fit.model.parameters(), &g.parameters(), 1e-7);
        assert!(fit.cost < 1e-20, "{}", fit.cost);
        // Started elsewhere, output_error_records holds the integrator and reaches G too.
        let start = PolynomialModel::new(
            vec![vec![0.0, 0.2, 0.0]],
            convolve(&[1.0, -0.3], &[1.0, -1.0]),
            None,
        )
        .unwrap();
        let fit = output_error_records(&pairs, &start, &s).unwrap();
        assert_close(&fit.model.parameters(), &g.parameters(), 1e-7);
        // A transient longer than a record leaves that record out of the cost.
        let short = record(&g, 73, 4, 0.0);
        let with_short =
            output_error_records(&[pairs[0], pairs[1], (&short.0, &short.1)], &start, &s).unwrap();
        assert_close(&with_short.model.parameters(), &g.parameters(), 1e-7);
        // Too few samples overall names the records.
        let tiny = OeSettings::builder().transient(178).build().unwrap();
        let e = output_error_records(&[(&short.0, &short.1), pairs[1]], &g, &tiny).unwrap_err();
        assert!(e.to_string().contains("each of 2 records"), "{e}");
        // A bad record is named.
        let mut bad = records[1].1.clone();
        bad.as_mut_slice()[3] = f64::NAN;
        let e = output_error_records(&[pairs[0], (&records[1].0, &bad)], &g, &tiny).unwrap_err();
        assert!(e.to_string().contains("record 2"), "{e}");
    }

    #[test]
    fn the_jacobian_over_several_records_is_that_of_the_stacked_residual() {
        for fixed in [vec![1.0], vec![1.0, -1.0]] {
            let g = PolynomialModel::new(
                vec![vec![0.3, 0.4], vec![0.0, 0.0, -0.8]],
                vec![1.0, -1.2, 0.5],
                None,
            )
            .unwrap();
            let u = white(81, 300, 1.0, 2);
            let y = white(82, 300, 1.0, 1);
            let orders = g.orders();
            let (uc, yv) = prepare_data(&u, &y, 2, "").unwrap();
            // three records, the middle one shorter than the transient
            let bounds = [0, 140, 150, 300];
            let transient = 12;
            let mut p = Problem {
                u: &uc,
                y: &yv,
                bounds: &bounds,
                orders: &orders,
                transient,
                fixed: fixed.clone(),
                last: None,
            };
            let theta = parameters_for(&g, &orders);
            let r = p.residuals(&theta).unwrap();
            assert_eq!(r.len(), (140 - 12) + (150 - 12));
            // The residual, independently: each record simulated from rest by the model.
            let model =
                PolynomialModel::new(g.num.clone(), convolve(&g.den, &fixed), None).unwrap();
            let mut expected = Vec::new();
            for w in bounds.windows(2) {
                let ur = u.slice(w[0]..w[1]);
                let sim = model.simulate(&ur).unwrap();
                for k in transient.min(w[1] - w[0])..(w[1] - w[0]) {
                    expected.push(yv[w[0] + k] - sim[k]);
                }
            }
            assert_close(r.as_slice(), &expected, 1e-12);
            let j = p.jacobian(&theta, &r).unwrap();
            let (h, jtr) = p.normal_equations(&theta, &r).unwrap();
            let h_ref = j.transpose() * &j;
            let jtr_ref = j.transpose() * &r;
            assert!((&h - &h_ref).norm() <= 1e-12 * h_ref.norm());
            assert!((&jtr - &jtr_ref).norm() <= 1e-12 * jtr_ref.norm());
            // Every column against central differences of the residual.
            for c in 0..theta.len() {
                let step = 1e-6;
                let (mut tp, mut tm) = (theta.clone(), theta.clone());
                tp[c] += step;
                tm[c] -= step;
                let fd = (p.residuals(&tp).unwrap() - p.residuals(&tm).unwrap()) / (2.0 * step);
                assert!(
                    (&fd - j.column(c)).norm() <= 1e-6 * j.column(c).norm().max(1.0),
                    "column {c}"
                );
            }
        }
    }

    #[test]
    fn errors() {
        let g = truth();
        let u = white(41, 100, 1.0, 1);
        let y = Signal::new(1, g.simulate(&u).unwrap()).unwrap();
        let unstable =
            PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -2.0, 1.05], None).unwrap();
        let e = output_error(&u, &y, &unstable, &OeSettings::default()).unwrap_err();
        match &e {
            LinearError::UnstableInitialModel { spectral_radius } => {
                assert!((spectral_radius - 1.05f64.sqrt()).abs() < 1e-9)
            }
            other => panic!("unexpected {other:?}"),
        }
        assert!(e.to_string().contains("unstable"));
        let s = OeSettings::builder().transient(96).build().unwrap();
        assert!(matches!(
            output_error(&u, &y, &g, &s),
            Err(LinearError::TooFewSamples { needed: 101, .. })
        ));
        let mut yb = y.clone();
        yb.as_mut_slice()[5] = f64::NAN;
        assert!(matches!(
            output_error(&u, &yb, &g, &OeSettings::default()),
            Err(LinearError::NonFinite { sample: 5, .. })
        ));
        assert!(matches!(
            oe(
                &u,
                &y.slice(0..50),
                &Orders::siso(2, 2, 1),
                &OeSettings::default()
            ),
            Err(LinearError::LengthMismatch { .. })
        ));
        assert!(OeSettings::builder().max_iterations(0).build().is_err());
        assert!(OeSettings::builder().initial_damping(0.0).build().is_err());
    }
}

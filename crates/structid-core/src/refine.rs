//! Alternating refinement when the linear part is only approximately known.
//!
//! The seed method assumes the LTI block is exact. On a real system it is a physical model with
//! uncertain parameters or a best linear approximation (BLA) estimated from data. If the linear
//! part G is a polynomial model (a [`PolynomialModel`], y = Σ_i B_i(q)/F(q)·v_i) and the maps
//! enter it as known signals once they are estimated, the two unknowns can be estimated in
//! turn:
//!
//! 1. **Maps, G fixed.** Build the structured model from G ([`LinearStructure::model`]) and
//!    identify the maps with [`identify()`]; β (and σ) are chosen on the first pass by
//!    [`crate::hyperparameters::select`] and then kept.
//! 2. **G, maps fixed.** With the map outputs fixed at their sample values ŵ, the inputs of G
//!    are known signals (for output feedback, u and ŵ = N̂(y) with y measured), so this step is
//!    an output-error estimate of G ([`structid_linear::output_error()`], Levenberg–Marquardt
//!    started at the current G).
//! 3. Repeat until the simulation error on a validation record stops improving.
//!
//! # Why the estimation cost never increases
//! With white output noise (e = y − G·[u; w]) and a zero initial state, step 1 minimises
//!
//! ```text
//!   J(G, w) = (1/L)·‖y − G·[u; w]‖² + β·D(z, w)
//! ```
//!
//! over w for the current G, and step 2 minimises its first term over G for the current ŵ
//! (D does not depend on G because z = y is measured). With β fixed, each step can only lower
//! J: J(G_{k+1}, ŵ_{k+1}) ≤ J(G_{k+1}, ŵ_k) ≤ J(G_k, ŵ_k). [`Refinement::iterations`] records J
//! after both steps so that this can be checked.
//!
//! # Structures
//! A [`LinearStructure`] says where the map sits (a [`Site`]):
//! * [`LinearStructure::output_feedback`]: y = G·(u − w) + e with w = N(y) (Silverbox, Duffing
//!   oscillators, stiffness and friction in a feedback loop). By default the feedback path
//!   shares G's numerator (the physical structure);
//!   [`LinearStructure::with_separate_numerator`] fits y = B_u/F·u + B_w/F·w instead.
//! * [`LinearStructure::input`]: y = G·N(u) + e (Hammerstein).

use std::sync::Arc;
use std::time::Instant;

use structid_linear::{OeFit, OeSettings, PolynomialModel, output_error};
use structid_lti::Signal;

use crate::dispersion::Dispersion;
use crate::error::{Error, Result};
use crate::hyperparameters::{Criterion, Selection, SelectionSettings, select};
use crate::identify::{Identification, IdentifySettings, InitialState, identify};
use crate::initial_state::estimate_initial_state;
use crate::interpolant::Interpolant;
use crate::lft::Lft;
use crate::model::{Data, Model, NonlinearBlock};
use crate::simulate::MapBinding;
use crate::structure::{self, Site};

fn linear_error(e: structid_linear::LinearError) -> Error {
    Error::InvalidStructure(format!("linear estimation: {e}"))
}

/// The LFT of a linear model without maps (white output noise); see [`structure::realise`].
pub use crate::structure::realise as lti_lft;

/// Output-error estimate of `g` from `inputs` to `y`, optionally with a free initial state.
///
/// The free response of a realisation of B/F with n states is any sequence C·Aᵏ·x₀, and these
/// are exactly the responses I(q)/F(q)·δ_k to a unit impulse at k = 0 of a numerator
/// I = i₀ + i₁q⁻¹ + … + i_{n−1}q^{−(n−1)}: both satisfy F(q)·y_k = 0 from k = n on and span n
/// dimensions. So the initial state is estimated by adding an impulse input with its own
/// numerator (sharing F) to the output-error fit, and dropping it afterwards. The criterion is
/// then the one [`identify()`] minimises with [`InitialState::Estimate`].
pub fn output_error_with_state(
    inputs: &Signal,
    y: &Signal,
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
) -> Result<OeFit> {
    // The output-error orders are read from the numerators (nk = leading zeros): an all-zero
    // numerator would have no free coefficient and its path would silently stay at zero.
    if let Some(i) = g
        .num
        .iter()
        .position(|b| !b.is_empty() && b.iter().all(|&v| v == 0.0))
    {
        return Err(Error::InvalidStructure(format!(
            "numerator {i} of the linear part is all zeros, so output error cannot tell its \
             delay and would keep that path at zero; start it from small nonzero coefficients \
             after the delay (e.g. [0.0, 1e-6, 1e-6] for a delay of one sample)"
        )));
    }
    if !free_initial_state {
        return output_error(inputs, y, g, settings).map_err(linear_error);
    }
    let order = g
        .num
        .iter()
        .map(|b| b.len().saturating_sub(1))
        .chain([g.den.len().saturating_sub(1)])
        .max()
        .unwrap_or(0);
    if order == 0 {
        return output_error(inputs, y, g, settings).map_err(linear_error);
    }
    let m = inputs.channels();
    let with_impulse = Signal::from_fn(inputs.len(), m + 1, |k, c| {
        if c < m {
            inputs.get(k, c)
        } else if k == 0 {
            1.0
        } else {
            0.0
        }
    });
    let mut start = g.clone();
    // Start the impulse numerator at the best initial state for `g` (a linear least-squares
    // problem once F is fixed), so that the fit begins at the cost identify() reaches with
    // InitialState::Estimate and can only go below it, however early the iteration stops.
    start.num.push(best_impulse_numerator(inputs, y, g, order)?);
    let mut fit = output_error(&with_impulse, y, &start, settings).map_err(linear_error)?;
    fit.model.num.truncate(m);
    Ok(fit)
}

/// The numerator I (`order` coefficients) whose impulse response I/F·δ best fits the
/// residual y − G·inputs in least squares: the free response of the best initial state for G.
/// Coefficients that come out exactly zero are replaced by a tiny value so that every one
/// stays a free parameter of the output-error fit (the orders are read from the numerators).
fn best_impulse_numerator(
    inputs: &Signal,
    y: &Signal,
    g: &PolynomialModel,
    order: usize,
) -> Result<Vec<f64>> {
    let len = y.len();
    let tiny = |v: Vec<f64>| -> Vec<f64> {
        v.into_iter()
            .map(|c| if c == 0.0 || !c.is_finite() { 1e-12 } else { c })
            .collect()
    };
    if len == 0 || y.channels() != 1 || inputs.len() != len {
        // output_error() reports the mismatch.
        return Ok(vec![1e-12; order]);
    }
    let sim = g.simulate(inputs).map_err(linear_error)?;
    // The impulse response h of 1/F; column j of the regressors is h delayed by j.
    let a0 = g.den[0];
    let den: Vec<f64> = g.den.iter().map(|a| a / a0).collect();
    let mut h = vec![0.0; len];
    structid_lti::filter_row(&[[1.0 / a0]], &den, &[[1.0]], &mut h);
    let phi = faer::Mat::from_fn(len, order, |k, j| if k >= j { h[k - j] } else { 0.0 });
    let r: Vec<f64> = (0..len).map(|k| y.get(k, 0) - sim[k]).collect();
    // The plain least-squares x₀ of validation: a non-finite or failed problem starts the
    // impulse numerator from the tiny default instead of failing the fit.
    let c = estimate_initial_state(phi.as_ref(), &r, None).unwrap_or_else(|_| vec![0.0; order]);
    Ok(tiny(c))
}

fn one_channel(data: &Data, what: &str) -> Result<()> {
    if data.y().channels() != 1 {
        return Err(Error::DimensionMismatch {
            what: format!("{what}: measured outputs"),
            expected: "1".into(),
            found: data.y().channels().to_string(),
        });
    }
    Ok(())
}

/// Where the uncertain linear block's map sits, and how the linear part is re-estimated:
/// one of the [`Site`]s refinement supports, with the map's name.
///
/// * [`LinearStructure::output_feedback`]: y = G·(u − w) + e with w = N(y), z = y. G has one
///   output and the data's inputs. With a shared numerator (the default) the map acts at the
///   input of G exactly like u does: G is a SISO model driven by u − w (one u channel). With a
///   separate numerator ([`LinearStructure::with_separate_numerator`]), y = B_u/F·u + B_w/F·w
///   with a common F (any number of u channels), which also absorbs a feedback path that is
///   not exactly the input path. The feedback path needs a delay (B_w starting at q⁻¹): with a
///   direct term, y_k would depend on N(y_k), an algebraic loop.
/// * [`LinearStructure::input`]: an input nonlinearity (Hammerstein), y = G·N(u) + e, z = u.
///
/// In both, G is kept in the structure's form: for output feedback its inputs are [u…, w]
/// (the last numerator is the path of w, −B for the shared path), for an input map its one
/// input is w.
///
/// ```
/// use std::sync::Arc;
/// use structid_core::{KernelDispersion, refine::LinearStructure};
/// use structid_linear::PolynomialModel;
/// let g = PolynomialModel { num: vec![vec![0.0, 1.0, 0.5]], den: vec![1.0, -1.5, 0.7], sample_time: None };
/// let s = LinearStructure::output_feedback("stiffness");
/// let g = s.initial_from_bla(&g).unwrap();
/// let model = s.model(&g, Arc::new(KernelDispersion::gaussian(0.1).unwrap())).unwrap();
/// assert_eq!(model.blocks()[0].name, "stiffness");
///
/// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: None };
/// let model = LinearStructure::input("actuator")
///     .model(&g, Arc::new(KernelDispersion::gaussian(0.3).unwrap()))
///     .unwrap();
/// assert_eq!(model.lft().dims().z, 1);
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LinearStructure {
    name: String,
    site: Site,
    separate: bool,
}

impl LinearStructure {
    /// Output feedback through G's own numerator; `name` names the map.
    pub fn output_feedback(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            site: Site::OutputFeedback,
            separate: false,
        }
    }

    /// An input map called `name`.
    pub fn input(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            site: Site::Input,
            separate: false,
        }
    }

    /// The map `name` at `site`; refinement supports [`Site::OutputFeedback`] and
    /// [`Site::Input`].
    pub fn new(name: impl Into<String>, site: Site) -> Result<Self> {
        match site {
            Site::OutputFeedback => Ok(Self::output_feedback(name)),
            Site::Input => Ok(Self::input(name)),
            other => Err(unsupported(other)),
        }
    }

    /// Fits the feedback path's numerator separately (y = B_u/F·u + B_w/F·w); only output
    /// feedback has a feedback path.
    pub fn with_separate_numerator(mut self, separate: bool) -> Self {
        self.separate = separate && self.site == Site::OutputFeedback;
        self
    }

    /// Whether the feedback path has its own numerator.
    pub fn separate_numerator(&self) -> bool {
        self.separate
    }

    /// Where the map sits.
    pub fn site(&self) -> Site {
        self.site
    }

    /// A short description for reports, e.g. `output feedback y = G·(u − N(y)) + e`.
    pub fn describe(&self) -> String {
        match (self.site, self.separate) {
            (Site::OutputFeedback, true) => "output feedback y = B_u/F·u + B_w/F·N(y) + e".into(),
            (Site::OutputFeedback, false) => "output feedback y = G·(u − N(y)) + e".into(),
            _ => "input nonlinearity y = G·N(u) + e".into(),
        }
    }

    /// The name of the unknown map.
    pub fn block_name(&self) -> &str {
        &self.name
    }

    /// The LFT for the linear part `g` (in the structure's form): one map reading z\[0\] and
    /// writing w\[0\], white output noise (y = … + e) so that [`refine`]'s cost decreases.
    pub fn lft(&self, g: &PolynomialModel) -> Result<Lft> {
        match self.site {
            Site::OutputFeedback => structure::polynomial_lft(g, Some(Site::OutputFeedback), true)
                .map_err(|e| match e {
                    // Name the block in the message, as the model file's users know it.
                    Error::InvalidStructure(m) if m.starts_with("the feedback path") => {
                        Error::InvalidStructure(m.replacen(
                            "the feedback path",
                            &format!("the feedback path of `{}`", self.name),
                            1,
                        ))
                    }
                    other => other,
                }),
            Site::Input => structure::polynomial_lft(g, Some(Site::Input), false),
            other => Err(unsupported(other)),
        }
    }

    /// The structured model for the linear part `g`, the map having dispersion `dispersion`.
    pub fn model(&self, g: &PolynomialModel, dispersion: Arc<dyn Dispersion>) -> Result<Model> {
        Model::new(
            self.lft(g)?,
            vec![NonlinearBlock::new(
                self.block_name().to_string(),
                vec![0],
                0,
                dispersion,
            )],
        )
    }

    /// Re-estimates the linear part with the maps' outputs fixed at their sample values
    /// `w_hat` (L × n_w), starting from `g`; with `free_initial_state` the initial state is
    /// estimated along with G (see [`output_error_with_state`]).
    pub fn estimate_linear(
        &self,
        data: &Data,
        w_hat: &Signal,
        g: &PolynomialModel,
        settings: &OeSettings,
        free_initial_state: bool,
    ) -> Result<OeFit> {
        match self.site {
            Site::OutputFeedback => {
                one_channel(data, "output feedback")?;
                let (u, len) = (data.u(), data.len());
                let nu = u.channels();
                if self.separate {
                    let inputs = Signal::from_fn(len, nu + 1, |k, c| {
                        if c < nu { u.get(k, c) } else { w_hat.get(k, 0) }
                    });
                    return output_error_with_state(
                        &inputs,
                        data.y(),
                        g,
                        settings,
                        free_initial_state,
                    );
                }
                // Shared numerator: G is SISO from v = u − w; the w column of the result is −B.
                if nu != 1 {
                    return Err(Error::InvalidStructure(
                        "a shared feedback numerator needs exactly one input u; use a separate numerator"
                            .into(),
                    ));
                }
                let v = Signal::from_fn(len, 1, |k, _| u.get(k, 0) - w_hat.get(k, 0));
                let siso = PolynomialModel {
                    num: vec![g.num[0].clone()],
                    den: g.den.clone(),
                    sample_time: g.sample_time,
                };
                let mut fit =
                    output_error_with_state(&v, data.y(), &siso, settings, free_initial_state)?;
                let b = fit.model.num[0].clone();
                fit.model.num.push(b.iter().map(|x| -x).collect());
                Ok(fit)
            }
            Site::Input => {
                one_channel(data, "input nonlinearity")?;
                output_error_with_state(w_hat, data.y(), g, settings, free_initial_state)
            }
            other => Err(unsupported(other)),
        }
    }

    /// A starting linear part for the data: the best linear approximation from u to y
    /// expanded to the structure's inputs, given the BLA `bla` (one output, the data's inputs).
    pub fn initial_from_bla(&self, bla: &PolynomialModel) -> Result<PolynomialModel> {
        match self.site {
            Site::OutputFeedback => {
                if bla.num.is_empty() {
                    return Err(Error::InvalidStructure("the BLA has no inputs".into()));
                }
                let mut g = bla.clone();
                // The feedback path starts as the u path (shared) or as that of the first input.
                let mut bw: Vec<f64> = bla.num[0].iter().map(|x| -x).collect();
                if bw.first().is_some_and(|b| *b != 0.0) {
                    return Err(Error::InvalidStructure(
                        "the BLA has a direct term; estimate it with an input delay nk ≥ 1 for an \
                         output-feedback structure"
                            .into(),
                    ));
                }
                if bw.is_empty() {
                    bw.push(0.0);
                }
                g.num.push(bw);
                Ok(g)
            }
            Site::Input => {
                if bla.num.len() != 1 {
                    return Err(Error::InvalidStructure(
                        "an input nonlinearity needs a BLA with one input".into(),
                    ));
                }
                Ok(bla.clone())
            }
            other => Err(unsupported(other)),
        }
    }
}

fn unsupported(site: Site) -> Error {
    Error::InvalidStructure(format!(
        "refinement re-estimates G for a map in output feedback or at the input, not {}",
        site.describe()
    ))
}

/// Settings of [`refine`]; build with [`RefineSettings::builder`].
#[derive(Clone, Debug)]
pub struct RefineSettings {
    max_iterations: usize,
    tolerance: f64,
    identify: IdentifySettings,
    selection: Option<SelectionSettings>,
    oe: OeSettings,
    settle: usize,
}

impl Default for RefineSettings {
    fn default() -> Self {
        Self {
            max_iterations: 10,
            tolerance: 1e-3,
            identify: IdentifySettings::default(),
            selection: Some(SelectionSettings::default()),
            oe: default_oe(),
            settle: 0,
        }
    }
}

/// Output-error settings of the linear step: a relative cost decrease of 1e-7 ends a step
/// (each alternation restarts from the current G, so a tighter tolerance buys nothing).
fn default_oe() -> OeSettings {
    OeSettings::builder()
        .tolerance(1e-7)
        .build()
        .unwrap_or_default()
}

impl RefineSettings {
    /// A builder starting from the defaults: at most 10 alternations, stop when the
    /// validation error improves by less than 0.1 %, β (and σ if the selection says so) by
    /// marginal likelihood on the first pass, output error to a relative decrease of 1e-7.
    pub fn builder() -> RefineSettingsBuilder {
        RefineSettingsBuilder {
            inner: Self::default(),
        }
    }

    /// Largest number of alternations.
    pub fn max_iterations(&self) -> usize {
        self.max_iterations
    }

    /// Relative improvement of the validation error below which the alternation stops.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// Identification settings (β is used when no selection is given).
    pub fn identify(&self) -> &IdentifySettings {
        &self.identify
    }

    /// Hyperparameter selection for the first pass (`None`: β from [`RefineSettings::identify`]).
    pub fn selection(&self) -> Option<&SelectionSettings> {
        self.selection.as_ref()
    }

    /// Output-error settings of the linear step.
    pub fn oe(&self) -> &OeSettings {
        &self.oe
    }

    /// Leading validation samples that settle the state and are not scored.
    pub fn settle(&self) -> usize {
        self.settle
    }
}

/// Builder of [`RefineSettings`].
#[derive(Clone, Debug)]
pub struct RefineSettingsBuilder {
    inner: RefineSettings,
}

impl RefineSettingsBuilder {
    /// Largest number of alternations (≥ 1).
    pub fn max_iterations(mut self, n: usize) -> Self {
        self.inner.max_iterations = n;
        self
    }

    /// Stop when the validation error improves by less than this fraction (≥ 0).
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.inner.tolerance = tol;
        self
    }

    /// Identification settings of the map step.
    pub fn identify(mut self, s: IdentifySettings) -> Self {
        self.inner.identify = s;
        self
    }

    /// Hyperparameter selection on the first pass; `None` uses the identification's β.
    pub fn selection(mut self, s: Option<SelectionSettings>) -> Self {
        self.inner.selection = s;
        self
    }

    /// Output-error settings of the linear step. Keep `transient` at 0: the cost guarantee
    /// compares the output-error cost with the map step's noise term over all samples.
    pub fn oe(mut self, s: OeSettings) -> Self {
        self.inner.oe = s;
        self
    }

    /// Leading validation samples that settle the state and are not scored.
    pub fn settle(mut self, n: usize) -> Self {
        self.inner.settle = n;
        self
    }

    /// Validates and returns the settings.
    pub fn build(self) -> Result<RefineSettings> {
        let s = self.inner;
        if s.oe.transient() != 0 {
            return Err(Error::InvalidParameter {
                name: "transient".into(),
                value: s.oe.transient() as f64,
                reason: "the output-error step of a refinement scores every sample, as the map \
                         step does (otherwise J could increase); estimate the initial state \
                         instead of skipping a transient"
                    .into(),
            });
        }
        if s.max_iterations == 0 {
            return Err(Error::InvalidParameter {
                name: "max_iterations".into(),
                value: 0.0,
                reason: "refinement needs at least one iteration".into(),
            });
        }
        if !(s.tolerance.is_finite() && s.tolerance >= 0.0) {
            return Err(Error::InvalidParameter {
                name: "tolerance".into(),
                value: s.tolerance,
                reason: "must be a finite number ≥ 0".into(),
            });
        }
        Ok(s)
    }
}

/// One alternation of [`refine`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineIteration {
    /// The linear part used by the map step.
    pub linear: PolynomialModel,
    /// J after the map step: (1/L)·‖ê‖² + β·D.
    pub cost_after_maps: f64,
    /// Its noise term (1/L)·‖ê‖².
    pub noise_after_maps: f64,
    /// β·D after the map step.
    pub dispersion_term: f64,
    /// J after the linear step (the noise term re-fitted, β·D unchanged); `None` on the last
    /// iteration, which does not re-estimate G.
    pub cost_after_linear: Option<f64>,
    /// RMS simulation error on the validation record (maps in the loop, zero initial state,
    /// after `settle` samples); `None` without a validation record.
    pub validation_rms: Option<f64>,
    /// RMS simulation error on the estimation record.
    pub estimation_rms: f64,
    /// Levenberg–Marquardt iterations of the linear step.
    pub oe_iterations: usize,
    /// Seconds spent in this alternation.
    pub seconds: f64,
}

/// The result of [`refine`].
#[derive(Debug)]
pub struct Refinement {
    /// Every alternation, in order.
    pub iterations: Vec<RefineIteration>,
    /// Index of the iteration whose model is returned (best validation error, or the last).
    pub best: usize,
    /// The linear part of the returned model.
    pub linear: PolynomialModel,
    /// The structured model with the returned linear part and the chosen widths.
    pub model: Model,
    /// The identification of the maps with that linear part.
    pub identification: Identification,
    /// The β used.
    pub beta: f64,
    /// The hyperparameter selection of the first pass, if any.
    pub selection: Option<Selection>,
    /// Why the alternation stopped.
    pub stop_reason: String,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// RMS of y − simulation over the samples after `settle`, maps in the loop, zero state.
fn simulation_rms(model: &Model, id: &Identification, data: &Data, settle: usize) -> Result<f64> {
    let maps = id.maps();
    let bindings: Vec<MapBinding<'_>> = model
        .blocks()
        .iter()
        .zip(&maps)
        .map(|(b, m)| MapBinding {
            inputs: &b.inputs,
            output: b.output,
            map: *m as &dyn Interpolant,
        })
        .collect();
    let sim = match model.lft().simulate(&bindings, data.u(), None, None) {
        Ok(sim) => sim,
        // A closed loop that diverges scores as infinitely bad rather than stopping the
        // alternation: another iteration or candidate may be stable.
        Err(Error::Numerical(_)) => return Ok(f64::INFINITY),
        Err(e) => return Err(e),
    };
    let (y, ys) = (data.y(), &sim.y);
    let start = settle.min(y.len());
    let n = (y.len() - start) * y.channels();
    if n == 0 {
        return Err(Error::InvalidStructure(format!(
            "the validation record has no samples after the {settle} settling samples"
        )));
    }
    let mut s = 0.0;
    for k in start..y.len() {
        for c in 0..y.channels() {
            s += (y.get(k, c) - ys.get(k, c)).powi(2);
        }
    }
    let rms = (s / n as f64).sqrt();
    if rms.is_finite() {
        Ok(rms)
    } else {
        Ok(f64::INFINITY)
    }
}

/// Alternates between identifying the maps with the linear part fixed and re-estimating the
/// linear part with the maps fixed; see the [module documentation](self).
///
/// `initial` is the starting linear part in the structure's form (see
/// [`LinearStructure::initial_from_bla`]), `dispersion` the unknown block's dispersion (its
/// width is tuned on the first pass when the selection says so). With a validation record the
/// alternation stops when its simulation error improves by less than the tolerance, and the
/// best iteration is returned; without one, when J improves by less than the tolerance.
pub fn refine(
    structure: &LinearStructure,
    initial: &PolynomialModel,
    dispersion: Arc<dyn Dispersion>,
    data: &Data,
    validation: Option<&Data>,
    settings: &RefineSettings,
) -> Result<Refinement> {
    let t0 = Instant::now();
    let mut g = initial.clone();
    let mut dispersion = dispersion;
    let mut beta = settings.identify.beta();
    let mut selection = None;
    let mut iterations: Vec<RefineIteration> = Vec::new();
    let mut best: Option<(usize, f64, Model, Identification, PolynomialModel)> = None;
    let mut stop_reason = format!("reached {} iterations", settings.max_iterations);
    for it in 0..settings.max_iterations {
        let ti = Instant::now();
        let model = structure.model(&g, Arc::clone(&dispersion))?;
        let id = if it == 0
            && let Some(sel) = &settings.selection
        {
            // The marginal likelihood and GCV are defined for a zero initial state: select
            // with x₀ = 0 (a transient then only inflates the noise estimate a little), and
            // identify with the settings' own initial-state treatment.
            let how = match sel.criterion() {
                Criterion::MarginalLikelihood | Criterion::Gcv => {
                    settings.identify.with_initial_state(InitialState::Zero)
                }
                _ => settings.identify.clone(),
            };
            let s = select(&model, data, validation, &how, sel)?;
            beta = s.beta;
            dispersion = Arc::clone(&s.model.blocks()[0].dispersion);
            let id = identify(&s.model, data, &settings.identify.with_beta(beta)?)?.converged()?;
            selection = Some(s);
            id
        } else {
            identify(&model, data, &settings.identify.with_beta(beta)?)?.converged()?
        };
        let model = structure.model(&g, Arc::clone(&dispersion))?;
        let estimation_rms = simulation_rms(&model, &id, data, 0)?;
        let validation_rms = validation
            .map(|v| simulation_rms(&model, &id, v, settings.settle))
            .transpose()?;
        let score = validation_rms.unwrap_or(id.cost.total);
        let improved = match &best {
            None => true,
            Some((_, s, ..)) => score < *s * (1.0 - settings.tolerance),
        };
        let mut record = RefineIteration {
            linear: g.clone(),
            cost_after_maps: id.cost.total,
            noise_after_maps: id.cost.noise,
            dispersion_term: id.cost.total - id.cost.noise,
            cost_after_linear: None,
            validation_rms,
            estimation_rms,
            oe_iterations: 0,
            seconds: 0.0,
        };
        let better = best.as_ref().is_none_or(|(_, s, ..)| score < *s);
        let last = it + 1 == settings.max_iterations;
        if !improved || last {
            if !improved {
                stop_reason = if validation.is_some() {
                    format!(
                        "the validation error improved by less than {} (relative)",
                        settings.tolerance
                    )
                } else {
                    format!("J improved by less than {} (relative)", settings.tolerance)
                };
            }
            record.seconds = ti.elapsed().as_secs_f64();
            iterations.push(record);
            if better {
                best = Some((it, score, model, id, g.clone()));
            }
            break;
        }
        let free = settings.identify.initial_state() == InitialState::Estimate;
        let fit = structure.estimate_linear(data, &id.w_hat, &g, &settings.oe, free)?;
        record.cost_after_linear = Some(fit.cost + record.dispersion_term);
        record.oe_iterations = fit.iterations;
        record.seconds = ti.elapsed().as_secs_f64();
        iterations.push(record);
        if better {
            best = Some((it, score, model, id, g.clone()));
        }
        g = fit.model;
    }
    let (best, _, model, identification, linear) =
        best.expect("at least one iteration ran (max_iterations ≥ 1)");
    Ok(Refinement {
        iterations,
        best,
        linear,
        model,
        identification,
        beta,
        selection,
        stop_reason,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

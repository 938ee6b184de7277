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
//!    [`crate::selection::select`] and then kept.
//! 2. **G, maps fixed.** With the map outputs fixed at their sample values ŵ, the inputs of G
//!    are known signals (for output feedback, u and ŵ = N̂(y) with y measured), so this step is
//!    an output-error estimate of G ([`structid_linear::output_error()`], Levenberg–Marquardt
//!    started at the current G).
//! 3. Repeat until the simulation error on a validation record stops improving.
//!
//! # Several records
//! Estimation and validation data may hold several records ([`Data::from_records`]). The map
//! step is [`identify()`] over the records; the linear step is output error over the records,
//! each simulated from rest, or from an initial state of its own with
//! [`InitialState::Estimate`] ([`output_error_records_with_state`]); the estimation and
//! validation errors are pooled over the records, each simulated from rest (the settling
//! samples are left out of each validation record). The cost J is then the mean over all
//! samples of all records, and the argument below holds as it is.
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
//! * [`LinearStructure::rate_feedback`]: y = G·(u − w) + e with w = N(ẏ), ẏ_k = (y_k −
//!   y_(k−1))/T_s (friction). z is a fixed filter of the measured y, so D does not depend
//!   on G and the linear step is the one of output feedback: output error from u − ŵ.
//! * [`LinearStructure::input`]: y = G·N(u) + e (Hammerstein).
//! * [`LinearStructure::output`]: y = N(G·u) + e (a sensor map, Wiener). Here z = G·u moves
//!   with G, so the linear step holds the *map* N̂ fixed, not its sample values, and minimises
//!   (1/L)·‖y − N̂(G·u)‖² (output error through the map). The map's penalty then changes with
//!   z: `cost_after_linear` is that noise term plus the previous β·D. For a dispersion whose
//!   D(z, w) is the smallest penalty of a function through the points (kernels, feature
//!   bases), the map already found passes through (z_new, N̂(z_new)), so it bounds J at the
//!   new G from above and the next map step cannot end above it. G's gain is not identifiable
//!   at this site (N(z/k) with k·G is the same system); its poles are.
//! * A location declared in a nominal LFT ([`Site::Declared`], an `[lft]` model) has no G of
//!   its own. [`LinearStructure::from_lft`] recognises when the LFT at that location is one
//!   of the structures above around a polynomial block, and returns that structure and G;
//!   otherwise it says why it cannot (noise dynamics, or a location of no such form).
//!
//! # Integrators
//! A nominal with poles at z = 1 (a position driven by a force) is refined with those poles
//! held: G = B/(F′·(1 − q⁻¹)ⁿ), and the linear step fits B/F′ to the input summed n times
//! (the same output-error cost; see [`output_error_with_integrators`]). By default n is the
//! number of factors (1 − q⁻¹) of the starting denominator
//! ([`LinearStructure::with_integrators`]).
//!
//! # Initial state
//! With [`InitialState::Estimate`] the initial state is estimated in both steps for output
//! feedback and input maps. At the rate and sensor sites z itself depends on x₀ (the previous
//! output, or G·u), and [`identify()`] refuses a free x₀ there, so [`refine`] does too;
//! [`refine_linear`], which holds the map as a function, estimates G's x₀ at every site (at
//! the rate site the first rate is computed with y₋₁ = 0).
//!
//! # Joint refinement with a fitted map
//! [`refine`] alternates a nonparametric map with G; [`Refinement::linear_before`],
//! [`Refinement::cost_before`] and [`Refinement::cost_after`] give what changed.
//! [`refine_linear`] is the linear step alone with a map already fitted (a named family, or
//! any closure), reporting G and the costs before and after in a [`LinearRefinement`].

use std::sync::Arc;
use std::time::Instant;

use structid_linear::{OeFit, OeSettings, PolynomialModel, output_error_records};
use structid_lti::Signal;

use crate::dispersion::Dispersion;
use crate::error::{Error, Result};
use crate::identify::{Identification, IdentifySettings, InitialState, identify};
use crate::initial_state::estimate_initial_state;
use crate::model::interpolant::Interpolant;
use crate::model::lft::Lft;
use crate::model::simulate::MapBinding;
use crate::model::structure::{self, Site};
use crate::model::{Data, Model, NonlinearBlock};
use crate::progress::Progress;
use crate::selection::{Criterion, Selection, SelectionSettings, select};
use crate::validation::simulate_records_from_rest;

mod integrators;
mod linear_structure;
mod output_error;
mod recognise;
mod through_map;

pub use linear_structure::LinearStructure;
pub use output_error::{
    best_linear_approximation, output_error_records_with_state, output_error_with_integrators,
    output_error_with_state,
};
#[allow(unused_imports)]
use {linear_structure::*, output_error::*};

fn linear_error(e: structid_linear::LinearError) -> Error {
    Error::InvalidStructure(format!("linear estimation: {e}"))
}

/// The LFT of a linear model without maps (white output noise); see [`structure::realise`].
pub use crate::model::structure::realise as lti_lft;

/// Settings of [`refine`]; build with [`RefineSettings::builder`].
#[derive(Clone, Debug)]
pub struct RefineSettings {
    max_iterations: usize,
    tolerance: f64,
    identify: IdentifySettings,
    selection: Option<SelectionSettings>,
    oe: OeSettings,
    settle: usize,
    progress: Progress,
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
            progress: Progress::none(),
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

    /// The observer told after each alternation.
    pub fn progress(&self) -> &Progress {
        &self.progress
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

    /// An observer told after each alternation: `(alternations done, Some(max_iterations))`
    /// (default none). The first pass's selection reports its trials through the selection
    /// settings' own observer.
    pub fn progress(mut self, p: Progress) -> Self {
        self.inner.progress = p;
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

/// RMS of y − simulation over the samples after `settle` of each record, maps in the loop,
/// each record from a zero state, pooled over the records.
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
    let pooled = match simulate_records_from_rest(model.lft(), &bindings, data, settle) {
        Ok(p) => p,
        // A closed loop that diverges scores as infinitely bad rather than stopping the
        // alternation: another iteration or candidate may be stable.
        Err(Error::Numerical(_) | Error::Unstable(_)) => return Ok(f64::INFINITY),
        Err(e) => return Err(e),
    };
    if pooled.samples() == 0 {
        return Err(Error::InvalidStructure(format!(
            "the validation record{} no samples after the {settle} settling samples",
            if data.record_count() > 1 {
                "s have"
            } else {
                " has"
            }
        )));
    }
    let rms = pooled.rms();
    Ok(if rms.is_finite() { rms } else { f64::INFINITY })
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
    // The integrators are those of the start for the whole alternation.
    let structure = &structure
        .clone()
        .with_integrators(Some(structure.integrators_of(initial)?));
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
        settings
            .progress
            .report(it as u64 + 1, Some(settings.max_iterations as u64));
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
        let fit = if structure.site == Site::Output {
            structure.estimate_linear_with_map(
                data,
                id.blocks[0].map.as_ref(),
                &g,
                &settings.oe,
                free,
            )?
        } else {
            structure.estimate_linear(data, &id.w_hat, &g, &settings.oe, free)?
        };
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

impl Refinement {
    /// G before refinement: the linear part the first map step used.
    pub fn linear_before(&self) -> &PolynomialModel {
        &self.iterations[0].linear
    }

    /// J = (1/L)·‖ê‖² + β·D after the first map step (G before refinement).
    pub fn cost_before(&self) -> f64 {
        self.iterations[0].cost_after_maps
    }

    /// J after the map step of the returned iteration (G after refinement).
    pub fn cost_after(&self) -> f64 {
        self.iterations[self.best].cost_after_maps
    }
}

/// How a [`refine_linear`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinearRefineStatus {
    /// The linear step converged and the simulation error with the map in the loop fell.
    Improved,
    /// The iteration limit stopped the linear step; the simulation error fell.
    IterationLimit,
    /// The linear step lowered its criterion, but the simulation error with the map in the
    /// loop did not fall (or the simulation diverged): keep G before.
    SimulationWorse,
}

/// The result of [`refine_linear`]: G before and after, and what changed.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LinearRefinement {
    /// G before, in the structure's form.
    pub before: PolynomialModel,
    /// G re-estimated with the map in the loop (returned whatever the status; see
    /// [`LinearRefinement::linear`] for the one to use).
    pub after: PolynomialModel,
    /// The criterion of the linear step at G before: (1/L)·‖y − ŷ‖² with the map's input
    /// measured (feedback and input sites) or simulated through G (sensor map).
    pub cost_before: f64,
    /// The same criterion at G after (≤ `cost_before`).
    pub cost_after: f64,
    /// The criterion after each accepted Levenberg–Marquardt step (decreasing).
    pub costs: Vec<f64>,
    /// RMS simulation error with the map in the loop (zero initial state) at G before;
    /// infinite when the simulation diverges.
    pub simulation_rms_before: f64,
    /// The same at G after.
    pub simulation_rms_after: f64,
    /// Accepted Levenberg–Marquardt steps.
    pub iterations: usize,
    /// How it ended.
    pub status: LinearRefineStatus,
    /// Wall-clock seconds.
    pub seconds: f64,
}

impl LinearRefinement {
    /// The G to use: `after`, unless the simulation error did not fall.
    pub fn linear(&self) -> &PolynomialModel {
        match self.status {
            LinearRefineStatus::SimulationWorse => &self.before,
            _ => &self.after,
        }
    }
}

/// RMS of y − simulation of `lft` with `map` in the loop (each record from a zero state,
/// pooled over the records), ∞ on divergence.
fn map_simulation_rms(lft: &Lft, map: &dyn Interpolant, data: &Data) -> Result<f64> {
    let binding = [MapBinding {
        inputs: &[0],
        output: 0,
        map,
    }];
    let rms = match simulate_records_from_rest(lft, &binding, data, 0) {
        Ok(p) => p.rms(),
        Err(Error::Numerical(_) | Error::Unstable(_)) => return Ok(f64::INFINITY),
        Err(e) => return Err(e),
    };
    Ok(if rms.is_finite() { rms } else { f64::INFINITY })
}

/// Joint refinement with a fitted map: re-estimates G with the map `map` (a nonparametric
/// estimate, a named parametric family, or any closure `|z: &[f64]| …`) held fixed in the
/// loop, and reports G and the costs before and after.
///
/// This is the linear step of [`refine`] on its own
/// ([`LinearStructure::estimate_linear_with_map`]): for the feedback sites and an input map
/// the map's input is measured, so G is an output-error fit from u − N̂(z) (or N̂(u)) to y;
/// for a sensor map it is output error through the map. `g` is in the structure's form
/// ([`LinearStructure::initial_from_bla`] turns a nominal u → y model into it). The
/// initial-state treatment is that of `settings.identify()`, the fit's settings
/// `settings.oe()`; integrators of `g` stay at z = 1 (see
/// [`LinearStructure::with_integrators`]). The simulation error with the map in the loop is
/// reported before and after, and [`LinearRefinement::linear`] keeps G before when it did
/// not fall. To re-estimate the map too, alternate with [`refine`].
///
/// ```
/// use structid_core::refine::{LinearStructure, RefineSettings, refine_linear};
/// use structid_core::{Data, Signal};
/// use structid_linear::PolynomialModel;
/// // y = G·(u − N(y)), N(y) = 0.5·y³, G = 0.2/(q − 0.7); refined from a pole at 0.5.
/// let truth = PolynomialModel { num: vec![vec![0.0, 0.2]], den: vec![1.0, -0.7], sample_time: None };
/// let u = Signal::from_fn(400, 1, |k, _| ((k * k) as f64 * 0.37).sin());
/// let mut y = vec![0.0f64; 400];
/// for k in 1..400 { y[k] = 0.7 * y[k - 1] + 0.2 * (u.get(k - 1, 0) - 0.5 * y[k - 1].powi(3)); }
/// let data = Data::new(u, Signal::new(1, y).unwrap()).unwrap();
/// let s = LinearStructure::output_feedback("N");
/// let start = s.initial_from_bla(&PolynomialModel { den: vec![1.0, -0.5], ..truth }).unwrap();
/// let map = |z: &[f64]| 0.5 * z[0].powi(3);
/// let r = refine_linear(&s, &start, &map, &data, &RefineSettings::default()).unwrap();
/// assert!((r.linear().den[1] + 0.7).abs() < 1e-6 && r.cost_after < r.cost_before);
/// assert!(r.simulation_rms_after < 1e-6 * r.simulation_rms_before.max(1.0));
/// ```
pub fn refine_linear(
    structure: &LinearStructure,
    g: &PolynomialModel,
    map: &dyn Interpolant,
    data: &Data,
    settings: &RefineSettings,
) -> Result<LinearRefinement> {
    let t0 = Instant::now();
    let free = settings.identify.initial_state() == InitialState::Estimate;
    let fit = structure.estimate_linear_with_map(data, map, g, &settings.oe, free)?;
    let before = map_simulation_rms(&structure.lft(g)?, map, data)?;
    let after = match structure.lft(&fit.model) {
        Ok(lft) => map_simulation_rms(&lft, map, data)?,
        Err(_) => f64::INFINITY,
    };
    let status = if after.is_nan() || after >= before {
        LinearRefineStatus::SimulationWorse
    } else if fit.converged {
        LinearRefineStatus::Improved
    } else {
        LinearRefineStatus::IterationLimit
    };
    Ok(LinearRefinement {
        before: g.clone(),
        after: fit.model,
        cost_before: fit.initial_cost,
        cost_after: fit.cost,
        costs: fit.costs,
        simulation_rms_before: before,
        simulation_rms_after: after,
        iterations: fit.iterations,
        status,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

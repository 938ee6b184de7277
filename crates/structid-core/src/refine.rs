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
mod recognise;
mod through_map;

fn linear_error(e: structid_linear::LinearError) -> Error {
    Error::InvalidStructure(format!("linear estimation: {e}"))
}

/// The LFT of a linear model without maps (white output noise); see [`structure::realise`].
pub use crate::model::structure::realise as lti_lft;

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
    oe_fit(&[(inputs, y)], g, settings, free_initial_state, 0)
}

/// The best linear approximation of order n from `data` (one input, one output): na = nb = n
/// with one sample of delay, fitted by ARX and then by output error with a free initial state
/// ([`output_error_with_state`]), so that the criterion is the simulation error.
///
/// ```
/// use structid_core::{Data, refine::best_linear_approximation};
/// use structid_linear::PolynomialModel;
/// use structid_lti::Signal;
/// let g = PolynomialModel { num: vec![vec![0.0, 0.5, 0.2]], den: vec![1.0, -1.2, 0.5], sample_time: None };
/// let u = Signal::from_fn(400, 1, |k, _| ((k * k) as f64 * 0.37).sin());
/// let y = Signal::new(1, g.simulate(&u)?)?;
/// let bla = best_linear_approximation(&Data::new(u, y)?, 2, 1.0)?;
/// assert!((bla.den[1] + 1.2).abs() < 1e-6 && (bla.num[0][1] - 0.5).abs() < 1e-6);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn best_linear_approximation(
    data: &Data,
    order: usize,
    sample_time: f64,
) -> Result<PolynomialModel> {
    let arx_settings = structid_linear::ArxSettings::builder()
        .sample_time(sample_time)
        .build()
        .map_err(linear_error)?;
    let orders = structid_linear::Orders::siso(order, order, 1);
    let start = structid_linear::arx(data.u(), data.y(), &orders, &arx_settings)
        .map_err(linear_error)?
        .model;
    let oe = OeSettings::builder()
        .sample_time(sample_time)
        .build()
        .map_err(linear_error)?;
    Ok(output_error_with_state(data.u(), data.y(), &start, &oe, true)?.model)
}

/// [`output_error_with_state`] with `integrators` poles of `g` held at z = 1.
///
/// G = B/(F′·(1 − q⁻¹)ⁿ) applied to v is B/F′ applied to ṽ = v/(1 − q⁻¹)ⁿ (v summed n times
/// from zero), so the fit is an ordinary output-error fit of the stable B/F′ from ṽ to y with
/// the same cost. Filtering y by (1 − q⁻¹)ⁿ instead would colour the noise and change the
/// criterion. With a free initial state the impulse input is summed too: I/F′ on the summed
/// impulse is I/F on the impulse, the free response of all n + deg F′ states.
pub fn output_error_with_integrators(
    inputs: &Signal,
    y: &Signal,
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
    integrators: usize,
) -> Result<OeFit> {
    oe_fit(&[(inputs, y)], g, settings, free_initial_state, integrators)
}

/// [`output_error_with_integrators`] over several records (experiments) of the same system,
/// given as `(inputs, y)` pairs: one fit of G to the stacked simulation errors, each record
/// simulated from rest ([`structid_linear::output_error_records`]) or, with
/// `free_initial_state`, from an initial state of its own (one impulse input per record, each
/// with its own numerator, as in [`output_error_with_state`]). The cost is the mean over all
/// samples of all records, the criterion [`identify()`] minimises on a [`Data`] of several
/// records. `integrators` poles of `g` stay at z = 1 (0 for none), the inputs being summed
/// record by record from zero. One record gives [`output_error_with_integrators`]'s fit.
///
/// ```
/// use structid_core::refine::output_error_records_with_state;
/// use structid_linear::PolynomialModel;
/// use structid_lti::Signal;
/// let g = PolynomialModel { num: vec![vec![0.0, 0.5]], den: vec![1.0, -0.8], sample_time: None };
/// // Two records, each started from its own state x₀ (free response 2·0.8ᵏ and −1·0.8ᵏ).
/// let rec = |len: usize, shift: usize, x0: f64| {
///     let u = Signal::from_fn(len, 1, |k, _| (((k + shift) * (k + shift)) as f64 * 0.37).sin());
///     let sim = g.simulate(&u).unwrap();
///     let y: Vec<f64> = (0..len).map(|k| sim[k] + x0 * 0.8f64.powi(k as i32)).collect();
///     (u, Signal::new(1, y).unwrap())
/// };
/// let (a, b) = (rec(150, 0, 2.0), rec(100, 5, -1.0));
/// let start = PolynomialModel { num: vec![vec![0.0, 0.4]], den: vec![1.0, -0.6], sample_time: None };
/// let s = structid_linear::OeSettings::default();
/// let fit = output_error_records_with_state(&[(&a.0, &a.1), (&b.0, &b.1)], &start, &s, true, 0)?;
/// assert!((fit.model.den[1] + 0.8).abs() < 1e-8 && fit.cost < 1e-20);
/// assert_eq!(fit.model.num.len(), 1); // the impulse inputs are dropped
/// # Ok::<(), structid_core::Error>(())
/// ```
pub fn output_error_records_with_state(
    records: &[(&Signal, &Signal)],
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
    integrators: usize,
) -> Result<OeFit> {
    oe_fit(records, g, settings, free_initial_state, integrators)
}

/// [`output_error_records_with_state`] on stacked signals with record bounds `[0, L₁, …, L]`.
fn oe_fit_stacked(
    inputs: &Signal,
    y: &Signal,
    bounds: &[usize],
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
    integrators: usize,
) -> Result<OeFit> {
    if bounds.len() <= 2 {
        return oe_fit(&[(inputs, y)], g, settings, free_initial_state, integrators);
    }
    let parts: Vec<(Signal, Signal)> = bounds
        .windows(2)
        .map(|w| (inputs.slice(w[0]..w[1]), y.slice(w[0]..w[1])))
        .collect();
    let pairs: Vec<(&Signal, &Signal)> = parts.iter().map(|(u, y)| (u, y)).collect();
    oe_fit(&pairs, g, settings, free_initial_state, integrators)
}

fn oe_fit(
    records: &[(&Signal, &Signal)],
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
    integrators: usize,
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
    let Some(first) = records.first() else {
        return Err(Error::InvalidStructure("no data record was given".into()));
    };
    let order = g
        .num
        .iter()
        .map(|b| b.len().saturating_sub(1))
        .chain([g.den.len().saturating_sub(1)])
        .max()
        .unwrap_or(0);
    let m = first.0.channels();
    let count = records.len();
    let mut start = g.clone();
    let mut columns: Vec<Signal> = records.iter().map(|(u, _)| (*u).clone()).collect();
    if free_initial_state && order > 0 {
        // One impulse input per record, at that record's first sample (zero in the others).
        for (r, (inputs, _)) in records.iter().enumerate() {
            if inputs.channels() != m {
                // output_error_records() reports the mismatch.
                continue;
            }
            columns[r] = Signal::from_fn(inputs.len(), m + count, |k, c| {
                if c < m {
                    inputs.get(k, c)
                } else if c - m == r && k == 0 {
                    1.0
                } else {
                    0.0
                }
            });
        }
        // Start each impulse numerator at the best initial state of its record for `g` (a
        // linear least-squares problem once F is fixed), so that the fit begins at the cost
        // identify() reaches with InitialState::Estimate and can only go below it, however
        // early the iteration stops.
        for (inputs, y) in records {
            start.num.push(best_impulse_numerator(inputs, y, g, order)?);
        }
    }
    if integrators > 0 {
        start.den = integrators::deflate(&g.den, integrators)?;
        for c in &mut columns {
            *c = integrators::sum(c, integrators)?;
        }
    }
    let pairs: Vec<(&Signal, &Signal)> = columns
        .iter()
        .zip(records)
        .map(|(u, (_, y))| (u, *y))
        .collect();
    // The numerator coefficients of the inputs, then those of the impulse inputs (θ = (b…, f…)).
    let nb = start.orders().nb;
    let (nb_inputs, nb_impulses) = (
        nb.iter().take(m).sum::<usize>(),
        nb.iter().skip(m).sum::<usize>(),
    );
    let mut fit = output_error_records(&pairs, &start, settings).map_err(linear_error)?;
    fit.model.num.truncate(m);
    if nb_impulses > 0 {
        // The initial states are nuisance parameters: G's uncertainty is theirs marginalised,
        // the rows and columns of G's parameters in the joint covariance.
        let keep: Vec<usize> = (0..fit.parameter_std.len())
            .filter(|&i| i < nb_inputs || i >= nb_inputs + nb_impulses)
            .collect();
        fit.parameter_std = keep.iter().map(|&i| fit.parameter_std[i]).collect();
        fit.parameter_covariance = fit.parameter_covariance.map(|c| {
            nalgebra::DMatrix::from_fn(keep.len(), keep.len(), |i, j| c[(keep[i], keep[j])])
        });
    }
    if integrators > 0 {
        fit.model.den = integrators::inflate(&fit.model.den, integrators);
    }
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
/// * [`LinearStructure::rate_feedback`]: y = G·(u − N(ẏ)) + e, z = (y_k − y_(k−1))/T_s. G
///   is SISO from u with an input delay (as for a shared feedback numerator).
/// * [`LinearStructure::output`]: a sensor map, y = N(G·u) + e, z = G·u.
///
/// G is kept in the structure's form: for output feedback its inputs are [u…, w] (the last
/// numerator is the path of w, −B for the shared path), for an input map its one input is
/// w, for rate feedback and a sensor map its inputs are u. A location declared in a nominal
/// LFT is refined through [`LinearStructure::from_lft`].
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
    integrators: Option<usize>,
}

impl LinearStructure {
    /// Output feedback through G's own numerator; `name` names the map.
    pub fn output_feedback(name: impl Into<String>) -> Self {
        Self::at(name, Site::OutputFeedback)
    }

    /// An input map called `name`.
    pub fn input(name: impl Into<String>) -> Self {
        Self::at(name, Site::Input)
    }

    /// Rate feedback y = G·(u − N(ẏ)) + e with ẏ_k = (y_k − y_(k−1))/T_s (friction); `name`
    /// names the map. G has one input and an input delay.
    pub fn rate_feedback(name: impl Into<String>) -> Self {
        Self::at(name, Site::RateFeedback)
    }

    /// A sensor map y = N(G·u) + e called `name` (Wiener). G's gain is not identifiable from
    /// this structure (N(z/k) with k·G is the same system): the linear step keeps the map
    /// fixed, which pins it, and its poles are what the data determine.
    pub fn output(name: impl Into<String>) -> Self {
        Self::at(name, Site::Output)
    }

    fn at(name: impl Into<String>, site: Site) -> Self {
        Self {
            name: name.into(),
            site,
            separate: false,
            integrators: None,
        }
    }

    /// The map `name` at a built-in `site`: [`Site::Input`], [`Site::Output`],
    /// [`Site::OutputFeedback`] or [`Site::RateFeedback`]. A [`Site::Declared`] location
    /// belongs to a nominal LFT, not to a polynomial G: [`LinearStructure::from_lft`] finds
    /// the G that such an LFT puts its map around.
    pub fn new(name: impl Into<String>, site: Site) -> Result<Self> {
        match site {
            Site::Declared { z, w } => Err(Error::InvalidStructure(format!(
                "a declared location (z row {z}, w column {w}) is a channel of a nominal LFT, \
                 not a place in a polynomial G; refine it with LinearStructure::from_lft, \
                 which finds the G that the LFT puts its map around"
            ))),
            site => Ok(Self::at(name, site)),
        }
    }

    /// The structure in which the declared location (z row `z`, w column `w`) of `nominal`
    /// puts its map, and the linear part G in that structure's form.
    ///
    /// A general LFT does not say which of its coefficients are "G": refinement re-estimates
    /// G only when the LFT restricted to that location *is* one of the built-in structures
    /// around a single polynomial block. The transfers from (u, w, e) to (y, z) are compared,
    /// by their Markov parameters, with those of output feedback (shared and separate
    /// numerator), rate feedback, an input map and an output map built from the transfer
    /// that plays G's part (u → y, w → y or u → z, read off the LFT as B/F with
    /// F = det(I − A·q⁻¹)); the first that agrees is returned. Otherwise, and when the noise
    /// path has dynamics (refinement re-estimates G by output error, under white output
    /// noise), the error says why. G keeps the LFT's sample time; modes that the transfer
    /// does not see are dropped only when they are at the origin (e.g. the rate site's
    /// previous-output state).
    ///
    /// ```
    /// use structid_core::{Site, refine::LinearStructure, model::structure::realise};
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { num: vec![vec![0.0, 0.5]], den: vec![1.0, -0.8], sample_time: Some(0.1) };
    /// let lft = Site::RateFeedback.insert(&realise(&g).unwrap()).unwrap();
    /// let (s, found) = LinearStructure::from_lft("friction", &lft, 0, 0).unwrap();
    /// assert_eq!(s.site(), Site::RateFeedback);
    /// assert!((found.den[1] + 0.8).abs() < 1e-12 && (found.num[0][1] - 0.5).abs() < 1e-12);
    /// ```
    pub fn from_lft(
        name: impl Into<String>,
        nominal: &Lft,
        z: usize,
        w: usize,
    ) -> Result<(Self, PolynomialModel)> {
        recognise::from_lft(name.into(), nominal, z, w)
    }

    /// Holds `n` poles of G at z = 1 (integrators) fixed in the linear step: G = B/(F′·(1 −
    /// q⁻¹)ⁿ) and only B and F′ are re-estimated. `None` (the default) holds as many as the
    /// starting G has (factors (1 − q⁻¹) of its denominator, to a relative 1e-8).
    pub fn with_integrators(mut self, n: Option<usize>) -> Self {
        self.integrators = n;
        self
    }

    /// The number of integrators held fixed (`None`: those of the starting G).
    pub fn integrators(&self) -> Option<usize> {
        self.integrators
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
            (Site::RateFeedback, _) => "rate feedback y = G·(u − N(ẏ)) + e".into(),
            (Site::Output, _) => "output (sensor) map y = N(G·u) + e".into(),
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
            site => structure::polynomial_lft(g, Some(site), false),
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
    /// estimated along with G (see [`output_error_with_state`]). The integrators of
    /// [`LinearStructure::with_integrators`] stay at z = 1.
    ///
    /// For output and rate feedback (shared numerator) G is SISO from v = u − ŵ; for an input
    /// map from ŵ. Data of several records are fitted together, each record simulated from
    /// rest or from its own initial state ([`output_error_records_with_state`]). A sensor map ([`Site::Output`]) reads z = G·u, which moves with G, so its
    /// linear step needs the map itself: use [`LinearStructure::estimate_linear_with_map`].
    pub fn estimate_linear(
        &self,
        data: &Data,
        w_hat: &Signal,
        g: &PolynomialModel,
        settings: &OeSettings,
        free_initial_state: bool,
    ) -> Result<OeFit> {
        let integrators = self.integrators_of(g)?;
        if w_hat.len() != data.len() {
            return Err(Error::DimensionMismatch {
                what: "map outputs ŵ of the linear step".into(),
                expected: format!("{} samples, like the data", data.len()),
                found: format!("{} samples", w_hat.len()),
            });
        }
        let fit = |inputs: &Signal, g: &PolynomialModel| {
            oe_fit_stacked(
                inputs,
                data.y(),
                data.record_bounds(),
                g,
                settings,
                free_initial_state,
                integrators,
            )
        };
        match self.site {
            Site::OutputFeedback | Site::RateFeedback => {
                let what = if self.site == Site::RateFeedback {
                    "rate feedback"
                } else {
                    "output feedback"
                };
                one_channel(data, what)?;
                let (u, len) = (data.u(), data.len());
                let nu = u.channels();
                if self.separate {
                    let inputs = Signal::from_fn(len, nu + 1, |k, c| {
                        if c < nu { u.get(k, c) } else { w_hat.get(k, 0) }
                    });
                    return fit(&inputs, g);
                }
                // Shared numerator: G is SISO from v = u − w; for output feedback the w column
                // of the result is −B.
                if nu != 1 {
                    return Err(Error::InvalidStructure(format!(
                        "{what} through G's own numerator needs exactly one input u, not {nu}{}",
                        if self.site == Site::OutputFeedback {
                            "; use a separate numerator"
                        } else {
                            ""
                        }
                    )));
                }
                let v = Signal::from_fn(len, 1, |k, _| u.get(k, 0) - w_hat.get(k, 0));
                let siso = PolynomialModel {
                    num: vec![g.num[0].clone()],
                    den: g.den.clone(),
                    sample_time: g.sample_time,
                };
                let mut fit = fit(&v, &siso)?;
                if self.site == Site::OutputFeedback {
                    let b = fit.model.num[0].clone();
                    fit.model.num.push(b.iter().map(|x| -x).collect());
                }
                Ok(fit)
            }
            Site::Input => {
                one_channel(data, "input nonlinearity")?;
                fit(w_hat, g)
            }
            Site::Output => Err(Error::InvalidStructure(
                "a sensor map y = N(G·u) + e reads z = G·u, which moves with G, so its linear \
                 step needs the map itself, not its sample values: use \
                 LinearStructure::estimate_linear_with_map"
                    .into(),
            )),
            Site::Declared { .. } => unreachable!("LinearStructure::new refuses declared sites"),
        }
    }

    /// Re-estimates the linear part with the map `map` fixed as a function, starting from
    /// `g`: what [`refine_linear`] does. For the feedback sites and an input map the map's
    /// input z is measured (y, its rate, or u), so this is [`LinearStructure::estimate_linear`]
    /// with ŵ = N̂(z). For a sensor map it minimises (1/L)·‖y − N̂(G·u)‖² over G by
    /// Levenberg–Marquardt, with the Jacobian N̂′(z)·∂z/∂θ (N̂′ by a central difference); the
    /// free initial state there enters z (an impulse input with its own numerator, started at
    /// zero).
    pub fn estimate_linear_with_map(
        &self,
        data: &Data,
        map: &dyn Interpolant,
        g: &PolynomialModel,
        settings: &OeSettings,
        free_initial_state: bool,
    ) -> Result<OeFit> {
        one_channel(data, self.site.name())?;
        let z = match self.site {
            Site::Output => {
                let integrators = self.integrators_of(g)?;
                return through_map::fit(data, map, g, settings, free_initial_state, integrators);
            }
            Site::Input => {
                if data.u().channels() != 1 {
                    return Err(Error::DimensionMismatch {
                        what: "input nonlinearity: inputs u".into(),
                        expected: "1".into(),
                        found: data.u().channels().to_string(),
                    });
                }
                data.u().clone()
            }
            Site::OutputFeedback => data.y().clone(),
            Site::RateFeedback => {
                // Each record starts from rest: y₋₁ = 0 at its first sample.
                let ts = g.sample_time.unwrap_or(1.0);
                let y = data.y();
                let starts = data.record_bounds();
                Signal::from_fn(data.len(), 1, |k, _| {
                    let previous = if starts.contains(&k) {
                        0.0
                    } else {
                        y.get(k - 1, 0)
                    };
                    (y.get(k, 0) - previous) / ts
                })
            }
            Site::Declared { .. } => unreachable!("LinearStructure::new refuses declared sites"),
        };
        let w_hat = Signal::new(1, map.eval_many(&z))?;
        self.estimate_linear(data, &w_hat, g, settings, free_initial_state)
    }

    /// The integrators held fixed for the linear part `g`: the structure's number, or those
    /// of `g` (checked to be there).
    fn integrators_of(&self, g: &PolynomialModel) -> Result<usize> {
        match self.integrators {
            None => Ok(integrators::count(&g.den)),
            Some(n) => {
                integrators::deflate(&g.den, n)?;
                Ok(n)
            }
        }
    }

    /// A starting linear part for the data: the best linear approximation from u to y
    /// expanded to the structure's inputs, given the BLA `bla` (one output, the data's inputs).
    /// This is also how a nominal G (u → y) becomes the structure's G: for output feedback
    /// the feedback path is −B; for rate feedback, an input and an output map G is the
    /// nominal itself.
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
            Site::Input | Site::RateFeedback => {
                if bla.num.len() != 1 {
                    return Err(Error::InvalidStructure(format!(
                        "{} needs a linear part with one input, not {}",
                        self.describe(),
                        bla.num.len()
                    )));
                }
                if self.site == Site::RateFeedback && bla.num[0].first().is_some_and(|b| *b != 0.0)
                {
                    return Err(Error::InvalidStructure(
                        "the linear part has a direct term; rate feedback needs an input delay \
                         nk ≥ 1 (otherwise y_k depends on N(ẏ_k), an algebraic loop)"
                            .into(),
                    ));
                }
                Ok(bla.clone())
            }
            Site::Output => {
                if bla.num.is_empty() {
                    return Err(Error::InvalidStructure(
                        "the linear part has no inputs".into(),
                    ));
                }
                Ok(bla.clone())
            }
            Site::Declared { .. } => unreachable!("LinearStructure::new refuses declared sites"),
        }
    }
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

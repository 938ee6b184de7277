//! The cascaded-tanks benchmark (Schoukens, Mattsson, Wigren and Noël, 2016): two water tanks
//! with free outlets fed by a pump, and an overflow.
//!
//! Physics: x₁' = −k₁·√x₁ + k₄·u, x₂' = k₂·√x₁ − k₃·√x₂, y = x₂, and the tanks overflow (y
//! clips at 10 V). Only y is measured, so of the three static maps (√x₁, √x₂ and the overflow)
//! only √x₂ ≈ √y and the clip of y have measured inputs: the paper's measurability condition
//! (z computable from u and y) fails for √x₁, and no structure below can identify it as a map.
//! What the pipeline can do is capture the measured ones and let the linear part approximate
//! the rest.
//!
//! Pipeline ([`run`]):
//! 1. Offsets: u₀ and y₀ are the means of the **estimation** record; every signal (the test
//!    record too) is used as a deviation u − u₀, y − y₀.
//! 2. The estimation record is divided into a fitting part (the first 75 %) and a validation
//!    part (the rest). Nothing is tuned on the test record.
//! 3. For each candidate order n (na = nb = n, nk = 1): the project's best linear
//!    approximation (ARX, then output error with a free initial state) on the fitting part, and
//!    for each structure of [`TanksStructure`] the alternating [`refine`]ment (maps by
//!    [`identify()`](structid_core::identify()) with an estimated initial state and β by marginal
//!    likelihood, G by output error with a free initial state). Each candidate is scored by
//!    its simulation error on the validation part, simulated from the start of the
//!    estimation record (from a zero state; the transient has died out long before the
//!    validation part starts), with and without the overflow clip (see below).
//! 4. For the best order of each structure with a map, a Fourier kernel plus the polynomial
//!    trend ([`SumDispersion`](structid_core::SumDispersion)) replaces the plain polynomial when it lowers the validation
//!    error by more than `kernel_margin`.
//! 5. The best candidate of each structure is simulated on the test record from u alone. By
//!    default it is the model fitted on the fitting part, i.e. exactly the model the
//!    validation part scored; with [`TanksSettings::refit`] it is re-estimated on the whole
//!    estimation record first (alternations chosen by the simulation error on that record).
//!
//! **Overflow.** The overflow is a known static map after the linear part: the simulated
//! output is clipped at the largest level of the estimation record (10 V, 47 samples sit
//! there). Whether a candidate uses the clip is decided on the validation part.
//!
//! **Initial state.** The records do not start at rest, and the benchmark scores all 1024 test
//! samples. The benchmark's description says that both records start from the same unknown
//! state, so the test simulation starts from the initial state estimated on the estimation
//! record: by [`identify()`](structid_core::identify()) with [`InitialState::Estimate`](structid_core::InitialState::Estimate) for a
//! structured model, by least squares on the free response for a linear one. The scores from a
//! zero (deviation) state are reported too ([`TanksModel::test_rms_zero_state`]).

use std::sync::Arc;
use std::time::Instant;

use nalgebra::{DMatrix, DVector};
use structid_core::refine::{LinearStructure, Refinement, lti_lft, refine};
use structid_core::{Data, Dispersion, Error, Lft, Result, Signal};
use structid_io::{CascadedTanks, Record};
use structid_linear::PolynomialModel;

use crate::pipeline::{bla, io, map_dispersion, range, refine_settings};

/// Published RMS simulation errors on the test record, volts (Table 3 of Forgione and Piga,
/// European Journal of Control 2021), as (method, RMS or range).
///
/// ```
/// assert_eq!(structid_benchmarks::tanks::PUBLISHED[0], ("best linear approximation", "0.75"));
/// ```
pub const PUBLISHED: [(&str, &str); 5] = [
    ("best linear approximation", "0.75"),
    ("Volterra", "0.54"),
    ("nonlinear state space", "0.34–0.45"),
    ("neural ODE", "0.33–0.40"),
    ("grey box with physical overflow", "0.18"),
];

/// The structures tried on the cascaded tanks.
///
/// ```
/// use structid_benchmarks::tanks::TanksStructure;
/// assert_eq!(TanksStructure::InputNonlinearity.name(), "y = G·N(u)");
/// assert!(!TanksStructure::Linear.has_map());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
pub enum TanksStructure {
    /// The best linear approximation y = G·u (no map).
    Linear,
    /// Output feedback through G's numerator, y = G·(u − N(y)): N sees the measured y
    /// (√x₂ and, crudely, the overflow).
    OutputFeedback,
    /// Output feedback with its own numerator, y = B_u/F·u + B_w/F·N(y): with a linearised
    /// upper tank, y = k/(s(s+a))·u − 1/s·k₃√y is exactly of this form.
    OutputFeedbackSeparate,
    /// An input map, y = G·N(u) (Hammerstein): the static gain from u to the levels.
    InputNonlinearity,
}

impl TanksStructure {
    /// Every structure, in the order the pipeline tries them.
    pub const ALL: [Self; 4] = [
        Self::Linear,
        Self::OutputFeedback,
        Self::OutputFeedbackSeparate,
        Self::InputNonlinearity,
    ];

    /// A short formula for tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::Linear => "y = G·u (BLA)",
            Self::OutputFeedback => "y = G·(u − N(y))",
            Self::OutputFeedbackSeparate => "y = B_u/F·u + B_w/F·N(y)",
            Self::InputNonlinearity => "y = G·N(u)",
        }
    }

    /// Whether the structure has an unknown map.
    pub fn has_map(self) -> bool {
        self != Self::Linear
    }

    fn linear_structure(self) -> Option<LinearStructure> {
        match self {
            Self::Linear => None,
            Self::OutputFeedback => Some(LinearStructure::output_feedback("N")),
            Self::OutputFeedbackSeparate => {
                Some(LinearStructure::output_feedback("N").with_separate_numerator(true))
            }
            Self::InputNonlinearity => Some(LinearStructure::input("N")),
        }
    }
}

/// Settings of the cascaded-tanks pipeline.
///
/// ```
/// let s = structid_benchmarks::tanks::TanksSettings::default();
/// assert_eq!(s.orders, vec![1, 2, 3, 4]);
/// assert!(s.overflow);
/// ```
#[derive(Clone, Debug)]
pub struct TanksSettings {
    /// Candidate orders n of G (na = nb = n, nk = 1).
    pub orders: Vec<usize>,
    /// Structures to try (the linear one is always computed: it is the baseline).
    pub structures: Vec<TanksStructure>,
    /// Fraction of the estimation record held out for validation (its end).
    pub validation_fraction: f64,
    /// Largest number of alternations of [`refine`].
    pub max_iterations: usize,
    /// Degree of the map's polynomial (the whole map, or the trend under a kernel).
    pub trend_degree: usize,
    /// Weight of each normalised monomial of the polynomial.
    pub trend_scale: f64,
    /// Try a Fourier kernel plus the trend for the best order of each structure with a map.
    pub kernel: bool,
    /// The kernel replaces the plain polynomial only when it lowers the validation error by
    /// more than this fraction.
    pub kernel_margin: f64,
    /// Width of the Gaussian-like Fourier kernel as a fraction of the range of the map's input.
    pub sigma_fraction: f64,
    /// Offer the overflow clip (at the largest estimation output) to every candidate; it is
    /// kept when it lowers the validation error.
    pub overflow: bool,
    /// Re-estimate the chosen candidates on the whole estimation record (alternating up to
    /// `max_iterations` times and keeping the alternation with the lowest simulation error on
    /// that record). Off by default: the models fitted on the fitting part are kept, so the
    /// final model is exactly the one the validation part scored (the refit is unvalidated,
    /// and on this short record it often stops at the first alternation, i.e. the BLA with a
    /// map, see the module documentation).
    pub refit: bool,
}

impl Default for TanksSettings {
    fn default() -> Self {
        Self {
            orders: vec![1, 2, 3, 4],
            structures: TanksStructure::ALL.to_vec(),
            validation_fraction: 0.25,
            max_iterations: 6,
            trend_degree: 3,
            trend_scale: 10.0,
            kernel: true,
            kernel_margin: 0.05,
            sigma_fraction: 0.2,
            overflow: true,
            refit: false,
        }
    }
}

/// One candidate of the search, scored on the validation part of the estimation record.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Candidate {
    /// The structure.
    pub structure: TanksStructure,
    /// Order n of G.
    pub order: usize,
    /// Whether the map had the Fourier kernel besides its polynomial.
    pub kernel: bool,
    /// Validation RMS without the overflow clip, volts (infinite when the simulation
    /// diverged or the estimation failed).
    pub validation_rms: f64,
    /// Validation RMS with the simulated output clipped at the overflow level, volts.
    pub validation_rms_clipped: f64,
    /// Alternations up to the best one (1 for the linear model).
    pub iterations: usize,
    /// Why the candidate failed, if it did.
    pub failure: Option<String>,
    /// Seconds spent.
    pub seconds: f64,
}

impl Candidate {
    /// The candidate's score: the lower of its validation errors (the clip is used when it
    /// helps and is offered).
    pub fn score(&self) -> f64 {
        self.validation_rms.min(self.validation_rms_clipped)
    }

    /// Whether the candidate's score uses the overflow clip.
    pub fn clipped(&self) -> bool {
        self.validation_rms_clipped < self.validation_rms
    }
}

/// The final model of one structure (as validated, or re-estimated on the whole estimation
/// record with [`TanksSettings::refit`]), scored on the test record.
#[derive(Debug)]
pub struct TanksModel {
    /// The candidate it was chosen from (its validation scores).
    pub candidate: Candidate,
    /// Whether the simulated output is clipped at the overflow level.
    pub clipped: bool,
    /// RMS simulation error over the whole estimation record from the estimated initial
    /// state, volts.
    pub estimation_rms: f64,
    /// RMS simulation error over the whole test record, from u alone and the initial state
    /// estimated on the estimation record, volts: the benchmark's figure.
    pub test_rms: f64,
    /// The same from a zero (deviation) state, volts.
    pub test_rms_zero_state: f64,
    /// The initial state used for both records (state coordinates of the model's LFT).
    pub initial_state: Vec<f64>,
    /// The linear part.
    pub linear: PolynomialModel,
    /// The refinement on the whole estimation record (`None` for the linear model).
    pub refinement: Option<Refinement>,
    /// Simulated test output, volts (offset added back).
    pub simulated: Vec<f64>,
}

/// Everything the pipeline produced.
#[derive(Debug)]
pub struct TanksResult {
    /// Every candidate tried, in order.
    pub candidates: Vec<Candidate>,
    /// The final model of each structure tried, in the order of the settings.
    pub models: Vec<TanksModel>,
    /// Index into `models` of the model with the lowest validation error: the pipeline's
    /// answer.
    pub chosen: usize,
    /// The input offset u₀ (mean of the estimation input), volts.
    pub input_offset: f64,
    /// The output offset y₀ (mean of the estimation output), volts.
    pub output_offset: f64,
    /// The overflow level (largest estimation output), volts.
    pub overflow_level: f64,
    /// Samples of the fitting part (the validation part is the rest of the estimation record).
    pub fit_samples: usize,
    /// The measured test output, volts.
    pub measured: Vec<f64>,
    /// Wall-clock seconds.
    pub seconds: f64,
}

fn centred(rec: &Record, u0: f64, y0: f64) -> Result<Data> {
    let u = Signal::new(1, rec.u.iter().map(|v| v - u0).collect())?;
    let y = Signal::new(1, rec.y.iter().map(|v| v - y0).collect())?;
    Data::new(u, y)
}

/// The map's dispersion: the polynomial alone, or with a Gaussian-like Fourier kernel whose
/// width is a fraction of the range of the map's input `z`.
fn dispersion(
    settings: &TanksSettings,
    z: &[f64],
    with_kernel: bool,
) -> Result<Arc<dyn Dispersion>> {
    let sigma = with_kernel.then(|| settings.sigma_fraction * range(z));
    map_dispersion(settings.trend_degree, settings.trend_scale, sigma)
}

/// A model that can be simulated: the linear part alone or a refinement's model and maps.
enum Sim<'a> {
    Linear(Box<Lft>),
    Structured(&'a Refinement),
}

impl Sim<'_> {
    /// The output from `x0` (zero when `None`), clipped at `clip` if given; `None` when the
    /// loop diverged.
    fn run(&self, u: &Signal, x0: Option<&[f64]>, clip: Option<f64>) -> Result<Option<Vec<f64>>> {
        let sim = match self {
            Self::Linear(lft) => lft.simulate(&[], u, None, x0),
            Self::Structured(r) => r.model.simulate(&r.identification.maps(), u, None, x0),
        };
        let mut y = match sim {
            Ok(s) => s.y.channel(0),
            Err(Error::Numerical(_) | Error::Unstable(_)) => return Ok(None),
            Err(e) => return Err(e),
        };
        if y.iter().any(|v| !v.is_finite()) {
            return Ok(None);
        }
        if let Some(c) = clip {
            y.iter_mut().for_each(|v| *v = v.min(c));
        }
        Ok(Some(y))
    }
}

fn rms_from(sim: Option<&[f64]>, y: &[f64], from: usize) -> f64 {
    sim.map_or(f64::INFINITY, |sim| crate::pipeline::rms_from(sim, y, from))
}

/// The initial state of a linear model by least squares on its free response over `data`:
/// y − y_zero-state ≈ O·x₀ with O's columns the free responses to unit initial states.
fn linear_initial_state(lft: &Lft, data: &Data) -> Result<Vec<f64>> {
    let n = lft.dims().states;
    let len = data.len();
    let forced = lft.simulate(&[], data.u(), None, None)?.y.channel(0);
    let zeros = Signal::zeros(len, 1);
    let mut o = DMatrix::zeros(len, n);
    for i in 0..n {
        let mut e = vec![0.0; n];
        e[i] = 1.0;
        let free = lft.simulate(&[], &zeros, None, Some(&e))?.y.channel(0);
        o.column_mut(i).copy_from_slice(&free);
    }
    let y = data.y().channel(0);
    let r = DVector::from_iterator(len, y.iter().zip(&forced).map(|(a, b)| a - b));
    let x0 = o
        .svd(true, true)
        .solve(&r, 1e-10)
        .map_err(|e| Error::Numerical(format!("initial state of the linear model: {e}")))?;
    Ok(x0.iter().copied().collect())
}

struct Context<'a> {
    settings: &'a TanksSettings,
    fit: Data,
    est: Data,
    cut: usize,
    ts: f64,
    clip: Option<f64>,
}

impl Context<'_> {
    /// Validation errors (without, with the clip) of a model simulated from a zero state over
    /// the whole estimation record and scored after the fitting part.
    fn validation(&self, sim: &Sim<'_>) -> Result<(f64, f64)> {
        let y = self.est.y().channel(0);
        let raw = sim.run(self.est.u(), None, None)?;
        let raw_rms = rms_from(raw.as_deref(), &y, self.cut);
        let clipped_rms = match self.clip {
            Some(c) => {
                let s = sim.run(self.est.u(), None, Some(c))?;
                rms_from(s.as_deref(), &y, self.cut)
            }
            None => f64::INFINITY,
        };
        Ok((raw_rms, clipped_rms))
    }

    /// The map's input over the estimation record: y for output feedback, u for an input map.
    fn map_input(&self, s: TanksStructure) -> Vec<f64> {
        match s {
            TanksStructure::InputNonlinearity => self.est.u().channel(0),
            _ => self.est.y().channel(0),
        }
    }

    fn linear_candidate(
        &self,
        g: &PolynomialModel,
        order: usize,
        seconds: f64,
    ) -> Result<Candidate> {
        let (v, vc) = self.validation(&Sim::Linear(Box::new(lti_lft(g)?)))?;
        Ok(Candidate {
            structure: TanksStructure::Linear,
            order,
            kernel: false,
            validation_rms: v,
            validation_rms_clipped: vc,
            iterations: 1,
            failure: None,
            seconds,
        })
    }

    /// Refines one structured candidate on the fitting part and scores it on the validation
    /// part; a failed estimation is recorded, not propagated.
    fn structured_candidate(
        &self,
        s: TanksStructure,
        g: &PolynomialModel,
        order: usize,
        kernel: bool,
    ) -> (Candidate, Option<Refinement>) {
        let t0 = Instant::now();
        let mut c = Candidate {
            structure: s,
            order,
            kernel,
            validation_rms: f64::INFINITY,
            validation_rms_clipped: f64::INFINITY,
            iterations: 0,
            failure: None,
            seconds: 0.0,
        };
        let attempt = || -> Result<(f64, f64, Refinement)> {
            let ls = s
                .linear_structure()
                .ok_or_else(|| Error::InvalidStructure("no map".into()))?;
            let g0 = ls.initial_from_bla(g)?;
            let rs = refine_settings(
                self.settings.max_iterations,
                1e-3,
                self.cut,
                self.ts,
                false,
                false,
            )?;
            let disp = dispersion(self.settings, &self.map_input(s), kernel)?;
            let r = refine(&ls, &g0, disp, &self.fit, Some(&self.est), &rs)?;
            let (v, vc) = self.validation(&Sim::Structured(&r))?;
            Ok((v, vc, r))
        };
        let r = match attempt() {
            Ok((v, vc, r)) => {
                c.validation_rms = v;
                c.validation_rms_clipped = vc;
                c.iterations = r.best + 1;
                Some(r)
            }
            Err(e) => {
                c.failure = Some(e.to_string());
                None
            }
        };
        c.seconds = t0.elapsed().as_secs_f64();
        (c, r)
    }
}

/// Runs the pipeline of the [module documentation](self) on the loaded benchmark.
///
/// Fails when the settings give no order or a validation fraction outside (0, 1), or when
/// every candidate of the linear baseline fails; a structured candidate that fails (an
/// unstable loop, a singular fit) is recorded in [`Candidate::failure`] and skipped.
pub fn run(tanks: &CascadedTanks, settings: &TanksSettings) -> Result<TanksResult> {
    let t0 = Instant::now();
    if settings.orders.is_empty() {
        return Err(Error::InvalidStructure(
            "no candidate orders were given".into(),
        ));
    }
    if !(settings.validation_fraction > 0.0 && settings.validation_fraction < 1.0) {
        return Err(Error::InvalidParameter {
            name: "validation_fraction".into(),
            value: settings.validation_fraction,
            reason: "must lie in (0, 1)".into(),
        });
    }
    let (er, tr) = (&tanks.estimation, &tanks.test);
    let ts = er.sample_time;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (u0, y0) = (mean(&er.u), mean(&er.y));
    let overflow_level = er.y.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let est = centred(er, u0, y0)?;
    let test = centred(tr, u0, y0)?;
    let cut = ((1.0 - settings.validation_fraction) * est.len() as f64).round() as usize;
    let fit = Data::new(est.u().slice(0..cut), est.y().slice(0..cut))?;
    let cx = Context {
        settings,
        fit,
        est,
        cut,
        ts,
        clip: settings.overflow.then_some(overflow_level - y0),
    };

    // Stage 1: every order with every structure, polynomial maps.
    let mut candidates = Vec::new();
    // The refinement of each candidate on the fitting part (`None` for linear ones).
    let mut fitted: Vec<Option<Refinement>> = Vec::new();
    let mut blas = Vec::new();
    for &n in &settings.orders {
        let tb = Instant::now();
        let g = bla(&cx.fit, n, ts)?;
        candidates.push(cx.linear_candidate(&g, n, tb.elapsed().as_secs_f64())?);
        fitted.push(None);
        for &s in settings.structures.iter().filter(|s| s.has_map()) {
            let (c, r) = cx.structured_candidate(s, &g, n, false);
            candidates.push(c);
            fitted.push(r);
        }
        blas.push(g);
    }
    let best_of = |c: &[Candidate], s: TanksStructure| {
        (0..c.len())
            .filter(|&i| c[i].structure == s && c[i].score().is_finite())
            .min_by(|&a, &b| c[a].score().total_cmp(&c[b].score()))
    };
    // Stage 2: the kernel for the best order of each structure with a map.
    let mut structures: Vec<TanksStructure> = vec![TanksStructure::Linear];
    structures.extend(settings.structures.iter().filter(|s| s.has_map()));
    let mut chosen_candidates = Vec::new();
    for &s in &structures {
        let Some(mut best) = best_of(&candidates, s) else {
            continue;
        };
        if s.has_map() && settings.kernel {
            let c = candidates[best].clone();
            let k = settings
                .orders
                .iter()
                .position(|&n| n == c.order)
                .unwrap_or(0);
            let (kc, r) = cx.structured_candidate(s, &blas[k], c.order, true);
            candidates.push(kc);
            fitted.push(r);
            let kc = &candidates[candidates.len() - 1];
            if kc.score() < (1.0 - settings.kernel_margin) * c.score() {
                best = candidates.len() - 1;
            }
        }
        chosen_candidates.push(best);
    }
    if chosen_candidates.is_empty() {
        return Err(Error::InvalidStructure(
            "every candidate failed on the validation part".into(),
        ));
    }

    // Final models on the whole estimation record, scored on the test record.
    let mut models = Vec::new();
    for &i in &chosen_candidates {
        let c = candidates[i].clone();
        let clipped = c.clipped();
        let clip = if clipped { cx.clip } else { None };
        let k = settings
            .orders
            .iter()
            .position(|&n| n == c.order)
            .unwrap_or(0);
        let g = if settings.refit {
            bla(&cx.est, c.order, ts)?
        } else {
            blas[k].clone()
        };
        let (linear, refinement, x0) = match c.structure.linear_structure() {
            None => {
                let x0 = linear_initial_state(&lti_lft(&g)?, &cx.est)?;
                (g, None, x0)
            }
            Some(ls) => {
                let r = if settings.refit {
                    let g0 = ls.initial_from_bla(&g)?;
                    // The alternation with the lowest simulation error on the estimation
                    // record itself (from a zero state) is kept.
                    let rs = refine_settings(settings.max_iterations, 1e-3, 0, ts, false, false)?;
                    let disp = dispersion(settings, &cx.map_input(c.structure), c.kernel)?;
                    refine(&ls, &g0, disp, &cx.est, Some(&cx.est), &rs)?
                } else {
                    fitted[i].take().ok_or_else(|| {
                        Error::InvalidStructure("the chosen candidate has no refinement".into())
                    })?
                };
                // The fitting part starts at the first estimation sample, so its initial
                // state is the estimation record's in both cases.
                let x0 = r
                    .identification
                    .initial_state
                    .clone()
                    .unwrap_or_else(|| vec![0.0; r.model.lft().dims().states]);
                (r.linear.clone(), Some(r), x0)
            }
        };
        let sim = match &refinement {
            None => Sim::Linear(Box::new(lti_lft(&linear)?)),
            Some(r) => Sim::Structured(r),
        };
        let est_y = cx.est.y().channel(0);
        let est_sim = sim.run(cx.est.u(), Some(&x0), clip)?;
        let estimation_rms = rms_from(est_sim.as_deref(), &est_y, 0);
        let score = |s: Option<Vec<f64>>| -> Result<(f64, Vec<f64>)> {
            match s {
                Some(s) => {
                    let abs: Vec<f64> = s.iter().map(|v| v + y0).collect();
                    Ok((tr.scored_rms(&abs).map_err(io)?, abs))
                }
                None => Ok((f64::INFINITY, vec![f64::NAN; tr.len()])),
            }
        };
        let (test_rms, simulated) = score(sim.run(test.u(), Some(&x0), clip)?)?;
        let (test_rms_zero_state, _) = score(sim.run(test.u(), None, clip)?)?;
        drop(sim);
        models.push(TanksModel {
            candidate: c,
            clipped,
            estimation_rms,
            test_rms,
            test_rms_zero_state,
            initial_state: x0,
            linear,
            refinement,
            simulated,
        });
    }
    let chosen = (0..models.len())
        .min_by(|&a, &b| {
            models[a]
                .candidate
                .score()
                .total_cmp(&models[b].candidate.score())
        })
        .unwrap_or(0);
    Ok(TanksResult {
        candidates,
        models,
        chosen,
        input_offset: u0,
        output_offset: y0,
        overflow_level,
        fit_samples: cut,
        measured: tr.y.clone(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

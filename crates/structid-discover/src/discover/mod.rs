//! The discovery workflow: from a nominal linear model that almost fits to a named missing
//! effect, its place in the structure, and the gap it closes.
//!
//! [`discover`] takes a [`Nominal`] model (an LFT without maps, y = G·u + H·e, one input and
//! one output, possibly with declared locations and named states), an estimation record and a
//! validation record, and answers four questions:
//!
//! 1. **Is something missing?** The [`gap`](crate::gap::gap) of the nominal model on both records: simulation
//!    RMS and fit, a model-free noise level σ̂, and portmanteau tests of its innovations ε
//!    (whiteness; ε against u, against u², and ε² against u², together at the 0.1 % level).
//!    When every test passes and RMS(ε) ≤ 1.5·σ̂ on both records, the verdict is "no missing
//!    effect detected" with the statistics behind it, and the workflow stops there.
//!    A nominal model whose simulation diverges, or is worse than the mean of y by more than
//!    [`WORSE_THAN_CONSTANT`], is refused ([`DiscoverError::PoorNominal`]).
//!    A nominal model with a pole on the unit circle (an integrator) is scored in windows
//!    ([`structid_core::validation::windows`]) in this step and in every later one, and gets a
//!    disturbance where its input acts, sized by maximum likelihood
//!    ([`Nominal::with_input_noise`]); [`Discovery::scoring`] and [`Discovery::input_noise`]
//!    say so. That ratio is taken on the nominal model's residual, which holds the missing
//!    effect, and a force acting where the input acts inflates it: each location is also
//!    identified with a ratio a hundred times smaller ([`SMALLER_RATIO`]), and the
//!    fit that validates better is kept. The same inflated ratio lets the one-step predictor
//!    follow the output, so that its innovations pass every test while the windowed
//!    simulation misses by many times σ̂: when that gap exceeds [`PAST_DISTURBANCE_GAP`]·σ̂ on
//!    both records the hypotheses are identified anyway, and a block confirms a missing effect
//!    only by shrinking the validation gap [`PAST_DISTURBANCE_SHRINK`] times (otherwise the
//!    verdict is "no missing effect", the gap being what the disturbance leaves). There are
//!    four verdicts ([`Verdict`]): no missing effect, missing effect, the linear model was
//!    wrong (the block that closes the gap is a gain, or G with one more mode closes it), and
//!    a gap larger than the noise that no candidate block closes.
//! 2. **Where do model and data disagree?** In time (windows where the residual leaves its
//!    noise band) and in operating space (regions of u, y, their rates, the simulated linear
//!    output G·u and the named states where the residual energy concentrates, e.g. `|u| > 0.8`).
//! 3. **Where in the structure does it act?** Each [`Site`] inserts one unknown static
//!    block ([`crate::hypotheses`], [`structid_core::Site::insert`]). Its map is identified by
//!    structid's `identify` with a quadratic dispersion (a Gaussian-like Fourier kernel of width
//!    σ = 0.1 × the range of z plus a cubic polynomial trend: finitely many features, so
//!    O(L·m²)), β by maximum marginal likelihood (σ too, optionally), the initial state
//!    estimated (zero for the sensor and rate locations, whose z an unknown x₀ would make
//!    unmeasurable). Total variation (β by validation, ADMM) is added where a smooth estimate
//!    cannot do: at every location when the best quadratic estimate closes less than half the
//!    gap (e.g. a fine quantiser), otherwise at the best location when a family with a kink or
//!    a jump fits its estimate about as well as the best family. All estimates are ranked by
//!    their simulation RMS on the validation record.
//!
//!    **G jointly with the map.** A nominal G estimated from data is a best linear
//!    approximation, biased by the very effect that is missing: a static block can absorb a
//!    gain error of G but not its dynamic error. When G was given as a polynomial model
//!    ([`Nominal::from_polynomial`]) the best hypothesis is refined jointly
//!    ([`DiscoverSettingsBuilder::refine_nominal`], on by default): G by output error with the
//!    map held fixed (integrators held at 1), then the map identified again around the new G,
//!    while the validation RMS falls by at least 5 % a step. An exact G gains nothing and stays.
//!    Only the best location is refined, since G refitted around a map at the wrong location
//!    absorbs part of the effect too, except when G's zero cancels its integrator: such a G is
//!    the direct fit of a closed-loop record, wrong at every location (it tends to the
//!    controller's negative inverse), and every location is refined, the rate included, the
//!    refits competing on validation, and the search then runs once more around the G kept
//!    (as after a gain error), so that one G ranks every location. A feedback location whose
//!    loop does not simulate around G as given starts from G fitted with the map's input read
//!    from the measured output. Around such a G the loops may still diverge at every
//!    feedback location, so the whole search also runs around a G that integrates: the
//!    cancelling zero moved to z = −1, where a held chain of integrators has its sampling zero,
//!    and the gain fitted to the estimation record; its finding is kept when it
//!    validates clearly better, reported against the nominal model as given.
//!    After naming, G is refitted once more with the named map held fixed;
//!    [`Finding::nominal_refinement`] reports G as given and as kept.
//! 4. **Is it static?** For every estimate within 1.5× of the best validation RMS, the noise
//!    estimate ê (what the static map leaves unexplained) is deconvolved to the block's output
//!    (a ridge-regularised inverse of L_yw, by conjugate gradients, with the adjoint applied by
//!    time reversal) and tested for dependence on the direction of z
//!    ([`crate::hysteresis::direction_dependence`]). If one depends on the direction, the effect
//!    is reported as "dynamic: hysteresis or backlash suspected" at that location, and no
//!    static name is forced (the paper's Example 1). Friction seen from the position depends
//!    on the direction of motion too: a dynamic fit in feedback from the output yields to a
//!    named map of the rate when that validates clearly better, or better and closes the gap
//!    ([`rate_explains`]).
//!    A static map of the rate imitates a
//!    hysteresis anywhere in the loop: when one validates best but leaves more than a quarter
//!    of the RMS of a fit at the input or the sensor whose direction effect explains at least
//!    [`SENSOR_HYSTERESIS_SHARE`] of its residual energy, that dynamic fit is the finding. At
//!    those two sites (z is u or G·u, free of output noise) a real gap with a direction effect
//!    is a missing effect even when the static approximation closes little of it; in feedback
//!    only when the direction explains at least [`FEEDBACK_HYSTERESIS_SHARE`] of the residual
//!    energy (a biased G in a loop leaves weaker direction effects of its own). Such a finding
//!    says that its location is not established ([`UNLOCATED_DIRECTION_EFFECT`]).
//!    A nominal G estimated from a record with a hysteresis at the actuator absorbs part of
//!    its phase lag, and the direction test can then stay quiet while no static block closes
//!    the gap. So when the finding leaves a gap larger than the noise, a hysteresis at the
//!    input (w = u + λ·s with a stop operator s: a play when λ = −1, an elasto-plastic
//!    element when λ > 0, [`InputHysteresis`]) is fitted with G re-estimated behind it; when
//!    it explains more than half of the residual energy that both the static block and G
//!    re-estimated alone leave ([`HYSTERESIS_OVER_STATIC`]), the finding is dynamic at the
//!    input and [`Finding::input_hysteresis`] carries the operator. A finding that the
//!    direction test already calls dynamic at the input gets the operator the same way.
//! 5. **What is it?** The best estimate's points (z_k, ŵ_k) are fitted by every family of the
//!    [`crate::effects`] library. The points are a smoothed estimate, not independent noisy
//!    samples, so BIC alone rewards families that bend to its artefacts; the families whose
//!    map fit is within 25 % of the best one's are offered first, fewest parameters first
//!    ([`parsimonious`] order), then the rest by BIC. The first six whose map fit carries no
//!    flag are refined by output error (Levenberg–Marquardt on the estimation record's
//!    simulation error with the parametric map in the loop; 95 % intervals from
//!    s²·(JᵀJ)⁻¹) and simulated on the validation record. Each is a row of the **candidate
//!    table** ([`crate::table`]) beside the nonparametric map, with its validation errors at
//!    the scored samples; the one selection rule picks the simplest row that a paired test
//!    over blocks of the validation record ([`crate::table::compare_blocks`]) does not call
//!    worse than the best at the level α ([`DiscoverSettings::significance`]). A family chosen is *named*; the
//!    nonparametric map chosen is an "unnamed static effect", kept as a table.
//!    **Is it stationary?** The named family is refined again on [`segment_count`] consecutive
//!    segments of the estimation record, and a trend of a parameter over them larger than
//!    the segments' scatter allows (a t test at α) makes the finding
//!    [`Classification::TimeVarying`] ([`Stationarity`]). A gain in series with the best
//!    model found, at its input and at its output, is tested the same way whatever form was
//!    chosen (even when no block confirmed the gap): a drifting gain that an estimated G or a
//!    static block absorbed on average leaves a gap that looks like another effect.
//! 6. **How much better is the model with it?** The augmented model (named expression or
//!    table) is examined like the nominal one on both records: the gap before and after, and
//!    the shrink of the validation RMS. A gap whose tests failed but which no candidate block
//!    shrinks by [`MIN_CONFIRMING_SHRINK`] is not reported as a missing effect.
//! 7. **Is it a nonlinearity at all?** G alone re-estimated with one more mode
//!    ([`LinearRival`]) is the linear model a finding must beat: when it validates within
//!    `noise_ratio`·σ̂ and the finding (or, with no block confirmed, nothing) is not better
//!    than it by the paired block test at α, the verdict is [`Verdict::LinearModel`]. A
//!    dynamic finding is judged instead by the direction effect the rival's own residual
//!    leaves at its block ([`LinearRival::leaves_direction_effect`]).
//!
//! The search runs in stages: the gap (which builds what every later stage reads), the
//! candidates, the location of the finding, G settled with it, and the verdict.
//!
//! **Several effects.** The nominal model may already carry maps ([`Nominal::from_model`],
//! e.g. the augmented model of an earlier run): they are simulated in every step, and kept
//! fixed while the next block, placed around the whole nominal model, is identified.
//! [`discover_effects`] iterates: it adopts each finding's augmented model as the next nominal
//! model and stops when the gap is noise, when nothing explains it, when an effect is dynamic,
//! or when a step cuts the validation RMS by less than 10 %.
//!
//! Structural ambiguities are reported, not hidden: a gain or offset at the input cannot be
//! told from one at the output of a linear G (both are then listed as equivalent locations),
//! a *gain* means the linear model was wrong, and in a feedback location the map's linear
//! part trades off against G's denominator (F + k·B with N − k·z).
//!
//! ```no_run
//! use structid_discover::discover::{DiscoverSettings, discover};
//! use structid_discover::hypotheses::Nominal;
//! # fn records() -> (structid_core::Data, structid_core::Data) { unimplemented!() }
//! let g = structid_linear::PolynomialModel {
//!     den: vec![1.0, -1.5, 0.7], num: vec![vec![0.0, 0.1, 0.1]], sample_time: Some(0.05),
//! };
//! let (estimation, validation) = records();
//! let d = discover(&Nominal::from_polynomial(&g).unwrap(), &estimation, &validation,
//!                  &DiscoverSettings::default()).unwrap();
//! println!("{}", d.verdict);
//! ```

mod by_simulation;
mod candidates;
mod context;
mod direction;
mod fit;
mod input_hysteresis;
mod iterate;
mod linear_rival;
mod locate;
mod model;
mod naming;
mod noise;
mod polish;
mod refine;
mod restore;
mod second_block;
mod settings;
mod stationarity;
mod total_variation;
mod verdict;

pub use fit::{TREND_SCALE, candidate_signals, initial_state, quadratic_dispersion_spec};
pub use input_hysteresis::{InputHysteresis, PLAY_WEIGHT_TOLERANCE, play_into, stop_into};
pub use iterate::{Effects, EffectsSettings, Step, StopReason, discover_effects};
pub use linear_rival::LinearRival;
pub use model::{Augmented, AugmentedMap, Classification, HypothesisResult, MapCurve};
pub use naming::parsimonious;
pub use noise::SMALLER_RATIO;
pub use second_block::{SecondBlock, second_blocks};
pub use settings::{DiscoverSettings, DiscoverSettingsBuilder};
pub use stationarity::{MIN_SEGMENT_SAMPLES, MIN_SEGMENTS, SEGMENTS, Stationarity, segment_count};
pub use verdict::POOR_MODEL_R2;

use std::time::Instant;

use structid_core::validation::Scoring;
use structid_core::{Data, Error, Result};

use crate::effects::Naming;
use crate::error::DiscoverError;
use crate::gap::Gap;
use crate::hypotheses::{Nominal, Site};
use crate::hysteresis::DirectionTest;

use context::Context;
use fit::Fitted;

/// The validation RMS must shrink by at least this factor for a detected gap to count as a
/// missing effect (see [`discover`]).
pub const MIN_CONFIRMING_SHRINK: f64 = 1.05;

/// A nominal model with a fitted input disturbance whose innovations pass every test, but
/// whose simulation misses by more than this many noise levels σ̂ on both records, goes on to
/// the hypotheses (see [`discover`]).
pub const PAST_DISTURBANCE_GAP: f64 = 3.0;

/// The validation shrink that confirms a missing effect past the tests of a nominal model
/// with a fitted input disturbance ([`PAST_DISTURBANCE_GAP`]): what a static block must
/// explain beyond the random force the disturbance model already allows for.
pub const PAST_DISTURBANCE_SHRINK: f64 = 1.5;

/// Below this validation shrink, a confirmed block whose augmented model still misses by more
/// than the noise explains only part of the gap, and the verdict says so.
pub const PARTIAL_SHRINK: f64 = 2.0;

/// The effect found at the best location.
#[derive(Clone, Debug)]
pub struct Finding {
    /// The best location (lowest validation RMS).
    pub location: Site,
    /// The estimate that was named (one of [`Discovery::hypotheses`]).
    pub hypothesis: HypothesisResult,
    /// Locations that explain the data equally well by construction (e.g. a gain at the
    /// input or at the output of a linear G), including `location`.
    pub equivalent_locations: Vec<Site>,
    /// Which estimate was named: `quadratic` or `total variation`.
    pub estimator: String,
    /// Validation RMS with the nonparametric map that was named.
    pub nonparametric_rms: f64,
    /// The total-variation estimate's validation RMS, when it was tried.
    pub total_variation_rms: Option<f64>,
    /// Every family's fit, best BIC first.
    pub naming: Naming,
    /// Validation RMS with each family's parametric map tried, in the order of
    /// `naming.ranked` (`None` for those not simulated).
    pub family_rms: Vec<Option<f64>>,
    /// The direction test on the deconvolved residual.
    pub direction: DirectionTest,
    /// What the effect is.
    pub classification: Classification,
    /// Remarks for the engineer (e.g. "a gain error means the linear model was wrong").
    pub remarks: Vec<String>,
    /// The augmented model does not predict the validation output better than the output's
    /// mean over each scored stretch (the paired block test at α): whatever its shrink, it is
    /// still a poor model, and the verdict says so.
    pub poor_model: bool,
    /// The augmented model.
    pub augmented: Augmented,
    /// RMS of the validation gap before / after (≥ 1 when the effect helps).
    pub shrink: f64,
    /// G re-estimated with the map in the loop
    /// ([`DiscoverSettingsBuilder::refine_nominal`]), when it was tried.
    pub nominal_refinement: Option<NominalRefinement>,
    /// A hysteresis at the input fitted with G (a play, or an elasto-plastic stop), when it
    /// explained the gap clearly better than any static block
    /// ([`HYSTERESIS_OVER_STATIC`]); the finding is then dynamic at the input. It is fitted
    /// when a static finding, or a dynamic one at the input, leaves a gap above the noise.
    pub input_hysteresis: Option<InputHysteresis>,
    /// The candidate table of the naming step at this location: the nonparametric map and
    /// every refined family, each with its validation errors ([`crate::table`]).
    pub table: Vec<crate::table::Candidate>,
    /// What the selection rule decided on [`Finding::table`].
    pub selection: crate::table::Selection,
    /// The named family re-estimated on consecutive segments of the estimation record, when
    /// it was named ([`Stationarity`]).
    pub stationarity: Option<Stationarity>,
}

/// A hysteresis at the input fitted with G ([`InputHysteresis`]) makes the finding dynamic
/// when its validation RMS is at most this share of the best static block's, and of G
/// re-estimated without it: 1/√2, so that it explains more than half of the residual energy
/// that either leaves. It is tried when the static block leaves a gap larger than the noise.
pub const HYSTERESIS_OVER_STATIC: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// G before and after its re-estimation with the found map in the loop.
#[derive(Clone, Debug, serde::Serialize)]
pub struct NominalRefinement {
    /// G as given, in the structure's form.
    pub before: structid_linear::PolynomialModel,
    /// G re-estimated by output error with the map held fixed.
    pub after: structid_linear::PolynomialModel,
    /// Validation RMS of the augmented model with G before.
    pub validation_rms_before: f64,
    /// The same with G after.
    pub validation_rms_after: f64,
    /// Whether the augmented model was kept with G after (its validation RMS fell).
    pub adopted: bool,
}

/// Fits within this factor of the best validation RMS get the direction test: a hysteresis
/// is approximated statically at other locations too, and a total-variation estimate there
/// can approximate it better than any estimate at its own location.
pub const DIRECTION_WITHIN: f64 = 1.5;

/// A static named fit in rate feedback must leave at most this share of the validation RMS
/// that a dynamic fit in feedback from the output leaves, to be preferred to it (see
/// [`discover`]).
pub const STATIC_OVER_DYNAMIC: f64 = 0.25;

/// A static named map of the rate that leaves at most this share of the validation RMS that
/// a dynamic fit in feedback from the output leaves with its static approximation is preferred
/// to it (see [`rate_explains`]).
pub const RATE_OVER_POSITION: f64 = 0.8;

/// Whether a named map of the rate (augmented validation RMS `rate_rms`, shrink
/// `rate_shrink`) is the explanation of a direction effect seen from the position, whose
/// dynamic fit's static approximation validates at `position_rms`. A map of ẏ depends on the
/// direction of motion, so it takes up part of any hysteresis in the loop: it must validate
/// clearly better ([`RATE_OVER_POSITION`]), or better and close the gap itself (a shrink of
/// at least [`PARTIAL_SHRINK`]). A relay of ẏ that closes a tenth of the gap behind a spring
/// with play, 9 % better than the play's static approximation, is neither.
///
/// ```
/// use structid_discover::discover::rate_explains;
/// assert!(rate_explains(0.7, 1.3, 1.0)); // clearly better
/// assert!(rate_explains(0.9, 8.0, 1.0)); // better, and closes the gap
/// assert!(!rate_explains(0.9, 1.1, 1.0)); // neither
/// assert!(!rate_explains(1.1, 8.0, 1.0)); // worse
/// ```
pub fn rate_explains(rate_rms: f64, rate_shrink: f64, position_rms: f64) -> bool {
    rate_rms < RATE_OVER_POSITION * position_rms
        || (rate_rms < position_rms && rate_shrink >= PARTIAL_SHRINK)
}

/// The share of the residual energy the direction of z must explain at the input or the
/// sensor for a dynamic fit there to be preferred to a better-validating static map of the
/// rate (see [`discover`]): stronger evidence than [`DiscoverSettings::hysteresis_threshold`],
/// since it overrides a better fit.
pub const SENSOR_HYSTERESIS_SHARE: f64 = 0.25;

/// The share of the residual energy the direction of z must explain in feedback for a real
/// gap to be a missing (dynamic) effect however little its static approximation closes (see
/// [`discover`]): a biased G in a loop leaves direction effects of its own, weaker than this on
/// the physics generator's effect-free closed loops.
pub const FEEDBACK_HYSTERESIS_SHARE: f64 = 0.25;

/// When the finding names nothing, does not confirm itself, or explains only part of the gap
/// (a shrink under [`PARTIAL_SHRINK`] that still leaves a missing effect), at most this many
/// other locations (in order of validation RMS) are named too, and the named
/// map among them that validates best, if better than the finding by the table's paired test,
/// is the finding (see `locate::named_alternative`). It bounds the work: each costs a naming.
const ALTERNATIVE_LOCATIONS: usize = 3;

/// A named map at another location replaces a dynamic finding only when its validation RMS is
/// also below this share of the finding's best model's: the effect size at which a static map is taken to
/// explain what the direction test attributed to a hysteresis, which static maps at several
/// locations approximate about equally (a significant but small gain is no evidence).
const ALTERNATIVE_FACTOR: f64 = 0.5;

/// When a fit about as good as the best depends on the direction of its z, the best
/// hypothesis' G re-estimated jointly with its map must bring the validation RMS below this
/// share of what it was to be kept (see [`DiscoverSettingsBuilder::refine_nominal`]).
///
/// A hysteresis is partly a phase lag, which a refitted G takes up: on the generators a
/// Bouc–Wen spring in feedback gains 3.6× that way and then passes for a static saturation,
/// while a static effect behind a biased estimated G that looked direction-dependent gains
/// an order of magnitude (a one-sided sensor clip behind a two-mass BLA: 31×).
pub const DYNAMIC_JOINT_GAIN: f64 = 0.25;

/// How many times narrower than the default kernel the second quadratic estimate at every
/// location is, when the first closes less than half the gap (see [`discover`]).
pub const FINER_SIGMA: f64 = 4.0;

/// The finer estimate at a location replaces the default one when its validation RMS is
/// below this share of the default's.
pub const FINER_GAIN: f64 = 0.9;

/// What a discovery concludes: one of four verdicts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// The nominal model's gap is noise: within the noise level and passing the residual
    /// tests on both records (or a test failed, the simulation RMS is within
    /// `noise_ratio`·σ̂ of [`Discovery::noise`], which allows for coloured noise, and no
    /// candidate block improves on it).
    NoMissingEffect,
    /// A missing effect was found, placed and added ([`Discovery::finding`]).
    MissingEffect,
    /// The gap is larger than the noise, but no single static block at the candidate
    /// locations explains it ([`Discovery::hypotheses`] lists what was tried): a dynamic
    /// effect the library does not cover, several effects at once, or a wrong linear model.
    Unexplained,
    /// The linear model was wrong, not a nonlinearity missing: either the block found is a
    /// gain (with or without an offset), a linear map at any site being a change of G itself
    /// ([`Discovery::finding`] holds the block, whose augmented model is the corrected linear
    /// model), or G alone re-estimated with one more mode closes the gap and no block beats
    /// it ([`Discovery::linear_rival`] holds that G; no finding). Re-estimate G.
    LinearModel,
}

impl Verdict {
    /// The verdict's key, as report.json spells it.
    ///
    /// ```
    /// use structid_discover::discover::Verdict;
    /// assert_eq!(Verdict::LinearModel.key(), "linear-model");
    /// ```
    pub fn key(&self) -> &'static str {
        match self {
            Verdict::NoMissingEffect => "no-missing-effect",
            Verdict::MissingEffect => "missing-effect",
            Verdict::Unexplained => "unexplained",
            Verdict::LinearModel => "linear-model",
        }
    }

    /// The verdict in words, as the reports open with it.
    pub fn describe(&self) -> &'static str {
        match self {
            Verdict::NoMissingEffect => "no missing effect",
            Verdict::MissingEffect => "missing effect",
            Verdict::Unexplained => {
                "a gap that one static block at these locations does not explain"
            }
            Verdict::LinearModel => "the linear model was wrong",
        }
    }
}

/// The noise level the workflow works with: the smallest semivariogram estimate
/// ([`crate::gap::noise_level_coloured`]) over the residuals of the models it examined.
///
/// Every model's residual is the same output noise plus that model's own error, and a
/// model error only adds to a residual's variogram; so each estimate is an upper bound on
/// the noise level up to its sampling error (a few per cent on thousands of samples), and
/// the best model examined gives the tightest. The nominal model's residual holds the
/// missing effect itself, which is why a noise level taken from it alone can be several
/// times too high; a first difference of coloured noise is √(1 − φ) times too low.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct NoiseLevel {
    /// σ̂, the standard deviation of the output noise (of the coloured process itself).
    pub std: f64,
    /// φ̂ of that estimate: its correlation decays as φ̂^k (0 for white noise).
    pub colour: f64,
    /// Whose residual gave it, e.g. `the nominal model on the estimation record`.
    pub source: String,
}

impl NoiseLevel {
    /// The estimate of `fit` from `source`, if it is finite and below `self`'s.
    fn tighten(&mut self, fit: crate::gap::NoiseFit, source: impl FnOnce() -> String) {
        if fit.std.is_finite() && fit.std > 0.0 && fit.std < self.std {
            *self = NoiseLevel {
                std: fit.std,
                colour: fit.colour,
                source: source(),
            };
        }
    }
}

/// Everything [`discover`] found.
#[derive(Clone, Debug)]
pub struct Discovery {
    /// The gap of the nominal model on the estimation record.
    pub estimation_gap: Gap,
    /// The gap of the nominal model on the validation record.
    pub validation_gap: Gap,
    /// Whether a missing effect was detected (on either record): the verdict is not
    /// [`Verdict::NoMissingEffect`].
    pub missing_effect: bool,
    /// The verdict.
    pub verdict_kind: Verdict,
    /// How every simulation was scored (free run, or windows for a nominal model with
    /// integrators).
    pub scoring: Scoring,
    /// The ratio λ of the input disturbance added to the nominal model's noise path
    /// ([`Nominal::with_input_noise`], chosen by maximum likelihood for a nominal model with
    /// integrators), if any.
    pub input_noise: Option<f64>,
    /// The noise level σ̂ (see [`NoiseLevel`]): from the nominal model's residuals, those the
    /// hypotheses leave, and the augmented model's. The naming tolerance "within 1.5·σ̂" and
    /// the verdict "the gap is larger than the noise" use it.
    pub noise: NoiseLevel,
    /// Every hypothesis tried, best validation RMS first (empty when nothing is missing).
    pub hypotheses: Vec<HypothesisResult>,
    /// The effect found (when something is missing and a hypothesis could be identified).
    pub finding: Option<Finding>,
    /// G alone re-estimated with one more mode ([`LinearRival`]), the linear model a finding
    /// must beat: fitted around a polynomial G when a finding other than a gain or a
    /// hysteresis at the input was confirmed (static or dynamic), or when the hypotheses left
    /// a gap larger than the noise unexplained.
    pub linear_rival: Option<LinearRival>,
    /// The verdict in one paragraph.
    pub verdict: String,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// Runs the discovery workflow (see the [module documentation](self)) for the nominal
/// single-input, single-output model `nominal` on the estimation record `est`, ranking and
/// checking on the validation record `val`.
///
/// A gap whose tests fail is confirmed as a missing effect only when the best augmented model
/// shrinks the validation RMS by at least [`MIN_CONFIRMING_SHRINK`]; otherwise the verdict is
/// "no missing effect detected", with the failed test and the best attempt in the text.
///
/// `est` and `val` may each hold several records (`Data::from_records`, separate experiments):
/// every step then runs record by record, each record simulated from its own initial state,
/// and pools (see [`crate::records`]); the RMS values that rank, name and shrink are pooled
/// over the records' scored samples, and [`Gap::records`] holds each record's.
///
/// Errors: several inputs or outputs, a record shorter than 100 samples (named), a constant input, an
/// unstable nominal model (its simulation would diverge), a nominal model whose simulation
/// diverges or is worse than a constant by more than [`WORSE_THAN_CONSTANT`]
/// ([`DiscoverError::PoorNominal`]); a hypothesis that fails is recorded
/// in [`HypothesisResult::failure`] and ranked last instead.
pub fn discover(
    nominal: &Nominal,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> crate::error::Result<Discovery> {
    discover_with(nominal, est, val, settings, true).map(linear_or_not)
}

/// A missing effect whose block is a gain is a change of G (see [`Verdict::LinearModel`]).
fn linear_or_not(mut d: Discovery) -> Discovery {
    let linear = matches!(&d.finding, Some(Finding {
        classification: Classification::Named(fit), ..
    }) if fit.effect == crate::effects::Effect::Gain);
    if d.verdict_kind == Verdict::MissingEffect && linear {
        d.verdict_kind = Verdict::LinearModel;
        let found = d
            .verdict
            .strip_prefix("missing effect: ")
            .unwrap_or(&d.verdict)
            .to_string();
        d.verdict = format!(
            "the linear model was wrong (the block found is a gain, a change of G rather than a \
             nonlinearity: re-estimate G): {found}"
        );
    }
    d
}

/// [`discover`], with `second_pass` allowing the search around a refitted G when the first
/// finding is only a gain error (see [`discover`]'s module documentation), and around a G
/// that integrates when the given one's zero cancels its integrator ([`restore`]).
fn discover_with(
    nominal: &Nominal,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
    second_pass: bool,
) -> crate::error::Result<Discovery> {
    let first = discover_once(nominal, est, val, settings, second_pass, false)?;
    if !second_pass || !settings.refine_nominal || !nominal.known_maps().is_empty() {
        return Ok(first);
    }
    let Some(cancelled) = cancelled_integrator(nominal) else {
        return Ok(first);
    };
    let Some(start) = nominal
        .polynomial()
        .and_then(|g| restore::integrating_start(g, est, settings))
    else {
        return Ok(first);
    };
    let second = Nominal::from_polynomial(&start)
        .map_err(DiscoverError::from)
        .and_then(|n| discover_once(&n, est, val, settings, true, true));
    match second {
        Ok(second) => {
            let mut d = restore::better(first, second, nominal, &start, val, settings)?;
            if let Some(f) = d.finding.as_mut()
                && !f.remarks.contains(&cancelled)
            {
                f.remarks.insert(0, cancelled);
            }
            Ok(d)
        }
        Err(_) => Ok(first),
    }
}

/// One search around `nominal` (see [`discover_with`]), in stages: the gap
/// ([`Context::new`]), the candidates ([`candidates`]), the location ([`locate`]), G settled
/// with the finding ([`settle_g`]) and the verdict ([`verdict`]). With `uncertain_g` every
/// location is refined jointly with G, as behind a G whose zero cancels its integrator.
fn discover_once(
    nominal: &Nominal,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
    second_pass: bool,
    uncertain_g: bool,
) -> crate::error::Result<Discovery> {
    let started = Instant::now();
    fit::check_records(est, val)?;
    // Known maps given as functions: the families they are exactly, for the joint refit.
    let given = naming::recover_families(nominal, est, settings)?.unwrap_or(nominal.clone());
    let (cx, mut noise) = Context::new(given, est, val, settings, started)?;
    if !cx.missing_effect && !cx.past_disturbance {
        let text = verdict::no_missing_effect(&cx);
        return Ok(cx.discovery(Verdict::NoMissingEffect, noise, Vec::new(), None, text));
    }
    let (mut fitted, failed) = candidates::Search::of(&cx, uncertain_g).candidates();
    tighten_by_fits(&mut noise, &fitted, &cx);
    let mut hypotheses: Vec<HypothesisResult> = fitted.iter().map(|f| f.result.clone()).collect();
    hypotheses.extend(failed);
    if fitted
        .first()
        .is_none_or(|f| !f.result.validation_rms.is_finite())
    {
        let text = verdict::nothing_identified(&cx, &hypotheses);
        return Ok(cx.discovery(Verdict::Unexplained, noise, hypotheses, None, text));
    }
    let mut directions = locate::directions(&fitted, &cx.settings);
    let chosen = locate::choose(&fitted, &mut directions, &cx.settings);
    let finding = locate::first_finding(&cx, &mut fitted, &directions, chosen)?;
    // The hysteresis at the input is weighed against the static block found first: a named
    // map elsewhere then replaces a dynamic finding only by a clear margin.
    let finding = locate::hysteresis_at_input(&cx, finding, &mut fitted, &noise);
    let finding = locate::named_alternative(&cx, finding, &mut fitted);
    let finding = settle_g(&cx, finding, second_pass)?;
    Ok(verdict::confirm(cx, finding, hypotheses, noise))
}

/// Each smooth hypothesis's simulation residual on the estimation record bounds the noise
/// level too, and so does what it leaves unexplained there (its noise estimate ê). Not a
/// total-variation estimate's, nor one whose β sits on its search bound: with a knot at
/// nearly every sample, a map of z can memorise the noise of y even when z is simulated.
/// With an input disturbance in the noise path, ê is split between it and the output noise,
/// and is not the output noise alone.
fn tighten_by_fits(noise: &mut NoiseLevel, fitted: &[Fitted], cx: &Context<'_>) {
    let smooth = |f: &&Fitted| f.estimator == "quadratic" && f.result.beta_at_bound.is_none();
    for f in fitted.iter().filter(smooth) {
        if let Some(fit) = f.residual_noise {
            noise.tighten(fit, || {
                format!(
                    "the simulation of the {} estimate {} on the estimation record",
                    f.estimator,
                    cx.nominal.describe(f.result.location)
                )
            });
        }
    }
    if cx.input_noise.is_some() {
        return;
    }
    for f in fitted.iter().filter(smooth) {
        if f.e_hat.channels() > 0 && !f.e_hat.is_empty() {
            noise.tighten(
                crate::gap::noise_level_coloured(&f.e_hat.channel(0)),
                || {
                    format!(
                        "what the {} estimate {} leaves on the estimation record",
                        f.estimator,
                        cx.nominal.describe(f.result.location)
                    )
                },
            );
        }
    }
}

/// G settled with the finding. G is re-estimated with the named map held fixed (a failed
/// refit leaves the joint refinement of the hypotheses standing, and says so). The input
/// disturbance was the identification's noise model; the model handed on keeps the nominal
/// model's own noise path, so that files written from it read back with the same measurable z
/// (the simulations, and so every RMS, do not depend on it). A gain error with G refitted
/// says the linear model was wrong, not what was missing: the search runs once more around
/// the refitted G (the first pass's locations were ranked around the wrong one, where a map
/// of the rate may not even simulate), and an effect it names that validates better is the
/// finding, its shrink against the nominal as given. So does a G refitted from a closed-loop
/// fit (its zero cancelled the integrator): the locations were refitted around it one by one,
/// each G absorbing what its map missed, and one G for all of them ranks them fairly.
fn settle_g(cx: &Context<'_>, mut finding: Finding, second_pass: bool) -> Result<Finding> {
    let settings = &cx.settings;
    if settings.refine_nominal
        && let Some(g) = cx.given.polynomial()
    {
        let joint = finding.nominal_refinement.clone();
        if let Err(e) = refine::refine_nominal(g, &mut finding, cx) {
            finding.nominal_refinement = joint;
            finding.remarks.push(format!(
                "G could not be re-estimated with the named map: {e}"
            ));
        }
    }
    if cx.input_noise.is_some() {
        let dispersion = std::sync::Arc::clone(&finding.augmented.model.blocks()[0].dispersion);
        let base = match &finding.nominal_refinement {
            Some(r) if r.adopted => Nominal::from_polynomial(&refine::u_to_y(&r.after))?,
            _ => cx.given.clone(),
        };
        finding.augmented.model = base.hypothesis(finding.location, dispersion)?.model;
    }
    let gain = matches!(&finding.classification,
        Classification::Named(fit) if fit.effect == crate::effects::Effect::Gain);
    if second_pass
        && settings.refine_nominal
        && (gain || cx.cancelled.is_some())
        && let Some(r) = finding.nominal_refinement.clone().filter(|r| r.adopted)
        && let Some(second) = around_refitted(&r, cx.est, cx.val, settings, &finding)
    {
        finding = second_finding(
            second,
            &r,
            &cx.given,
            &finding,
            &cx.validation_gap,
            cx.val,
            settings,
        )?;
    }
    Ok(finding)
}

/// The remark on a dynamic finding whose static approximation closes little of the gap: the
/// direction effect is real, but nothing says it sits where it was measured.
pub const UNLOCATED_DIRECTION_EFFECT: &str = "the static approximation at this location \
     closes little of the gap, so the direction effect is not located by it: a hysteresis \
     elsewhere in the loop leaves one too, and so does a nonlinearity acting on a state that \
     no location here measures (a tank's outflow √h inside G); a model that declares that \
     state as z (an `[lft]` nominal) tests the latter";

/// The remark on a nominal G whose numerator cancels one of its integrators
/// ([`structid_linear::integrators::integrator_cancellation`]), if it does.
fn cancelled_integrator(nominal: &Nominal) -> Option<String> {
    use structid_linear::integrators::{CANCELLATION, integrator_cancellation};
    let ratio = integrator_cancellation(nominal.polynomial()?)?;
    (ratio < CANCELLATION).then(|| {
        format!(
            "the nominal G does not integrate: a zero of its numerator cancels its integrator \
             (|B(1)| is {:.2} % of Σ|bᵢ|). A G fitted directly to a closed-loop record tends \
             to the controller's negative inverse, so every location was refined jointly with \
             G; a physical nominal or a record with open-loop excitation is still the safer \
             start",
            100.0 * ratio
        )
    })
}

/// The finding of a discovery around the G that `r` refitted, when it names an effect other
/// than a gain and its augmented model validates better than `first`'s.
fn around_refitted(
    r: &NominalRefinement,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
    first: &Finding,
) -> Option<Finding> {
    let nominal = Nominal::from_polynomial(&refine::u_to_y(&r.after)).ok()?;
    let d = discover_with(&nominal, est, val, settings, false).ok()?;
    let f = d.finding?;
    let gain = matches!(&f.classification,
        Classification::Named(fit) if fit.effect == crate::effects::Effect::Gain);
    (d.verdict_kind == Verdict::MissingEffect
        && !gain
        && f.augmented.validation_gap.rms < first.augmented.validation_gap.rms)
        .then_some(f)
}

/// The second pass's finding `f` restated against the nominal model as given: its shrink over
/// the given nominal model's validation gap `before`, G as given and as the second pass kept
/// it (`r` the first pass's refit), and a remark on the first pass.
fn second_finding(
    mut f: Finding,
    r: &NominalRefinement,
    given: &Nominal,
    first: &Finding,
    before: &Gap,
    val: &Data,
    settings: &DiscoverSettings,
) -> Result<Finding> {
    f.remarks.push(format!(
        "a first pass named {} {} with G refitted (validation RMS {}); around that G this \
         effect validates better",
        first.classification.describe(),
        given.describe(first.location),
        rms_text(first.augmented.validation_gap.rms)
    ));
    against_given(
        &mut f,
        given,
        &refine::u_to_y(&r.after),
        before,
        val,
        settings,
    )?;
    Ok(f)
}

/// Restates `f`, found by a search around another G (`searched`, from u to y), against the
/// nominal model as given: G before is `given`'s, G after the one `f` kept (its own refit when
/// adopted, else `searched`), with the validation RMS of `f`'s map around each, and the shrink
/// is over the given nominal model's validation gap `before`.
fn against_given(
    f: &mut Finding,
    given: &Nominal,
    searched: &structid_linear::PolynomialModel,
    before: &Gap,
    val: &Data,
    settings: &DiscoverSettings,
) -> Result<()> {
    let structure = structid_core::refine::LinearStructure::new("N", f.location)?;
    let kept = match &f.nominal_refinement {
        Some(r) if r.adopted => r.after.clone(),
        _ => structure.initial_from_bla(searched)?,
    };
    let g = given
        .polynomial()
        .ok_or_else(|| Error::InvalidStructure("no polynomial G to restate".into()))?;
    let map = f.augmented.map.interpolant()?;
    let dispersion = std::sync::Arc::clone(&f.augmented.model.blocks()[0].dispersion);
    let h = given.hypothesis(f.location, dispersion)?;
    let rms_given = fit::simulation_rms(&h, map.as_ref(), &h.data(val)?, settings);
    f.nominal_refinement = Some(NominalRefinement {
        before: structure.initial_from_bla(g)?,
        after: kept,
        validation_rms_before: rms_given,
        validation_rms_after: f.augmented.validation_gap.rms,
        adopted: true,
    });
    f.shrink = before.rms / f.augmented.validation_gap.rms;
    Ok(())
}

/// A nominal model whose simulation RMS on the estimation record exceeds this multiple of the
/// best constant's (the RMS of y about its mean) is refused ([`DiscoverError::PoorNominal`]).
///
/// A missing effect legitimately makes the nominal model look bad, so the margin is wide. On
/// the generators' cases (30 static, 20 effect-free and 10 hysteresis cases of
/// the synthetic generator; 40 static, 15 dynamic and 15 effect-free cases of the physics one;
/// the positioning axis) the ratio reaches 37 (a stuck actuator: y is G's response to a
/// constant, the nominal's to u) and 26 (a hysteretic spring in a stiff closed loop, scored in
/// windows); a stuck sensor reaches 151 but is exempt: a record whose y stays within three
/// noise levels of its mean is not checked. A nominal model
/// in the wrong units (mm for m) is about 1000.
pub const WORSE_THAN_CONSTANT: f64 = 100.0;

/// Refuses a nominal model that diverges on the estimation record, or whose simulation there
/// (scored as every simulation of the workflow) is worse than the best constant by more than
/// [`WORSE_THAN_CONSTANT`]: its gap would measure the nominal model, not a missing effect.
///
/// A record whose y stays within three noise levels of its mean (RMS(y − ȳ) ≤
/// 3·MAD(Δy)/(0.6745·√2)) is exempt from the ratio: a constant explains it, any model that
/// moves is worse, and that is the missing effect (a stuck sensor or actuator), not a bad
/// nominal model.
fn check_nominal(gap: &Gap, est: &Data, scoring: Scoring) -> crate::error::Result<()> {
    let y = est.y().channel(0);
    let mean = y.iter().sum::<f64>() / y.len().max(1) as f64;
    let constant =
        structid_core::validation::metrics::rms(&y.iter().map(|v| v - mean).collect::<Vec<_>>());
    // A simulation a million times the output's size has diverged, finite or not.
    let diverged = !gap.rms.is_finite()
        || gap.rms > 1e6 * structid_core::validation::metrics::rms(&y).max(f64::MIN_POSITIVE);
    let stuck = constant
        <= 3.0 * crate::gap::noise_level_records(&crate::records::parts(&y, est.record_bounds()));
    if diverged || (!stuck && gap.rms > WORSE_THAN_CONSTANT * constant) {
        return Err(DiscoverError::PoorNominal {
            record: "estimation".into(),
            model_rms: if diverged { f64::INFINITY } else { gap.rms },
            constant_rms: constant,
            scoring: match scoring {
                Scoring::Free => "one free run",
                Scoring::Windowed(_) => "in windows, each from a state fitted to its first half",
            },
        });
    }
    Ok(())
}

/// An RMS for reports: a number, or "diverged" for a simulation that did not stay finite.
pub fn rms_text(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4e}")
    } else if v.is_nan() {
        "—".into()
    } else {
        "diverged".into()
    }
}

/// A hypothesis that could not be identified; `dispersion` names the estimator that was tried
/// (`tv` for total variation, empty for the smooth estimate) so that reports label it.
fn failure(location: Site, dispersion: &str, t: Instant, e: &Error) -> HypothesisResult {
    HypothesisResult {
        location,
        dispersion: dispersion.into(),
        beta: f64::NAN,
        beta_at_bound: None,
        sigma: None,
        noise_term: f64::NAN,
        dispersion_value: f64::NAN,
        estimation_rms: f64::INFINITY,
        validation_rms: f64::INFINITY,
        curve: MapCurve {
            z: Vec::new(),
            w: Vec::new(),
            std: None,
        },
        points: (Vec::new(), Vec::new()),
        seconds: t.elapsed().as_secs_f64(),
        failure: Some(e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::direction::deconvolve;
    use super::*;
    use crate::effects::{Effect, EffectFit};
    use crate::hypotheses::hypothesis;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};
    use std::sync::Arc;
    use structid_core::refine::lti_lft;
    use structid_core::{Dispersion, Model, PolynomialDispersion, Signal};
    use structid_linear::PolynomialModel;
    use structid_lti::LinearSystem as _;

    #[test]
    fn a_verdict_key_is_its_serialised_name() {
        for v in [
            Verdict::NoMissingEffect,
            Verdict::MissingEffect,
            Verdict::Unexplained,
            Verdict::LinearModel,
        ] {
            assert_eq!(serde_json::to_value(v).unwrap(), v.key());
        }
    }

    /// A lightly damped second-order G (T_s = 0.05), the nominal model of the unit tests.
    pub(super) fn nominal() -> PolynomialModel {
        PolynomialModel {
            den: vec![1.0, -1.5, 0.7],
            num: vec![vec![0.0, 0.1, 0.1]],
            sample_time: Some(0.05),
        }
    }

    /// Data of the nominal G with `truth` at `location` (or none), filtered-noise input.
    fn record(location: Option<Site>, truth: fn(f64) -> f64, seed: u64, n: usize) -> Data {
        let g = nominal();
        let mut rng = StdRng::seed_from_u64(seed);
        let norm = Normal::new(0.0, 1.0).unwrap();
        let mut s = 0.0;
        let u = Signal::from_fn(n, 1, |_, _| {
            s = 0.8 * s + 0.6 * norm.sample(&mut rng);
            s
        });
        let noise = Normal::new(0.0, 0.005).unwrap();
        let e = Signal::from_fn(n, 1, |_, _| noise.sample(&mut rng));
        let y = match location {
            None => {
                let model = Model::new(lti_lft(&g).unwrap(), Vec::new()).unwrap();
                model.lft().simulate(&[], &u, Some(&e), None).unwrap().y
            }
            Some(loc) => {
                let h =
                    hypothesis(&g, loc, Arc::new(PolynomialDispersion::new(1).unwrap())).unwrap();
                let f = |z: &[f64]| truth(z[0]);
                h.simulate(&f, &u, Some(&e)).unwrap().y
            }
        };
        Data::new(u, y).unwrap()
    }

    #[test]
    fn a_hidden_input_saturation_is_named_located_and_closes_the_gap() {
        let sat: fn(f64) -> f64 = |z| (1.5 * z).clamp(-0.8, 0.8);
        let est = record(Some(Site::Input), sat, 1, 3000);
        let val = record(Some(Site::Input), sat, 2, 3000);
        let nominal = Nominal::from_polynomial(&nominal()).unwrap();
        let d = discover(&nominal, &est, &val, &DiscoverSettings::default()).unwrap();
        assert!(d.missing_effect);
        // Every built-in location was tried and ranked by validation RMS.
        assert!(d.hypotheses.len() >= 4);
        assert!(
            d.hypotheses
                .windows(2)
                .all(|p| p[0].validation_rms <= p[1].validation_rms)
        );
        let f = d.finding.unwrap();
        assert_eq!(f.location, Site::Input);
        let Classification::Named(fit) = &f.classification else {
            panic!("not named: {:?}", f.classification)
        };
        assert_eq!(fit.effect, Effect::Saturation);
        assert!((fit.values()[0] - 1.5).abs() < 0.05 && (fit.values()[1] - 0.8).abs() < 0.03);
        // The augmented model's gap is the noise (std 0.005) and passes its tests.
        assert!(f.shrink > 20.0, "shrink {}", f.shrink);
        assert!(f.augmented.validation_gap.rms < 0.0065);
        assert!(
            !f.augmented.validation_gap.missing_effect,
            "{}",
            f.augmented.validation_gap.verdict
        );
        // The map written into the model is the named expression, and it is what was scored.
        let AugmentedMap::Expression(e) = &f.augmented.map else {
            panic!("not an expression")
        };
        assert_eq!(e, &fit.expression);
    }

    #[test]
    fn lti_data_give_no_missing_effect_and_no_hypotheses() {
        let est = record(None, |z| z, 3, 3000);
        let val = record(None, |z| z, 4, 3000);
        let nominal = Nominal::from_polynomial(&nominal()).unwrap();
        let d = discover(&nominal, &est, &val, &DiscoverSettings::default()).unwrap();
        assert!(!d.missing_effect, "{}", d.verdict);
        assert!(d.finding.is_none() && d.hypotheses.is_empty());
        assert!(d.verdict.starts_with("no missing effect detected"));
    }

    #[test]
    fn settings_and_records_are_checked() {
        assert!(
            DiscoverSettings::builder()
                .locations(vec![])
                .build()
                .is_err()
        );
        assert!(DiscoverSettings::builder().library(vec![]).build().is_err());
        for alpha in [0.0, 0.6, f64::NAN] {
            assert!(
                DiscoverSettings::builder()
                    .significance(alpha)
                    .build()
                    .is_err()
            );
        }
        assert!(
            DiscoverSettings::builder()
                .hysteresis_threshold(1.0)
                .build()
                .is_err()
        );
        assert!(DiscoverSettings::builder().table_points(1).build().is_err());
        let nominal = Nominal::from_polynomial(&nominal()).unwrap();
        let short = record(None, |z| z, 5, 50);
        let long = record(None, |z| z, 6, 500);
        let e = discover(&nominal, &short, &long, &DiscoverSettings::default()).unwrap_err();
        assert!(e.to_string().contains("100 samples"), "{e}");
        let two = Data::new(
            Signal::from_fn(500, 2, |k, c| (k + c) as f64),
            long.y().clone(),
        )
        .unwrap();
        assert!(discover(&nominal, &two, &long, &DiscoverSettings::default()).is_err());
        // An input without excitation.
        let constant = Data::new(Signal::from_fn(500, 1, |_, _| 0.3), long.y().clone()).unwrap();
        let e = discover(&nominal, &constant, &long, &DiscoverSettings::default()).unwrap_err();
        assert!(e.to_string().contains("constant"), "{e}");
        // An unstable nominal model (a pole at 1.1).
        let unstable = Nominal::from_polynomial(&PolynomialModel {
            den: vec![1.0, -2.1, 1.1],
            num: vec![vec![0.0, 0.1]],
            sample_time: Some(0.05),
        })
        .unwrap();
        let e = discover(&unstable, &long, &long, &DiscoverSettings::default()).unwrap_err();
        assert!(e.to_string().contains("unstable"), "{e}");
    }

    /// A nominal model a thousand times too large (mm for m) simulates about 999 times worse
    /// than the mean of y, and is refused with the numbers and what to do; the right one,
    /// one ten times too large (a gain error discovery can name) and one of the wrong sign
    /// are not.
    #[test]
    fn a_nominal_worse_than_a_constant_is_an_input_error() {
        let est = record(None, |z| z, 7, 1000);
        let scaled = |k: f64| {
            let mut g = nominal();
            g.num[0].iter_mut().for_each(|b| *b *= k);
            Nominal::from_polynomial(&g).unwrap()
        };
        let e = discover(&scaled(1000.0), &est, &est, &DiscoverSettings::default()).unwrap_err();
        let DiscoverError::PoorNominal {
            model_rms,
            constant_rms,
            ..
        } = &e
        else {
            panic!("{e}")
        };
        // y ≈ G·u, the nominal 1000·G·u: its error 999·G·u is 999 times y's size about its
        // mean (up to the noise and the estimated initial state).
        let ratio = model_rms / constant_rms;
        assert!((ratio - 999.0).abs() < 10.0, "{ratio}");
        assert!(ratio > WORSE_THAN_CONSTANT);
        let text = e.to_string();
        for part in ["worse", "constant", "linear model", "integrators", "units"] {
            assert!(text.contains(part), "{part}: {text}");
        }
        for k in [1.0, 10.0, -1.0] {
            assert!(discover(&scaled(k), &est, &est, &DiscoverSettings::default()).is_ok());
        }
        // A stuck sensor (y a constant plus noise) makes every moving model far worse than
        // the mean, and is a missing effect, not a bad nominal model.
        let mut rng = StdRng::seed_from_u64(9);
        let noise = Normal::new(0.0, 0.005).unwrap();
        let stuck = Data::new(
            est.u().clone(),
            Signal::from_fn(est.len(), 1, |_, _| 0.3 + noise.sample(&mut rng)),
        )
        .unwrap();
        let d = discover(&scaled(1.0), &stuck, &stuck, &DiscoverSettings::default());
        assert!(
            !matches!(d, Err(DiscoverError::PoorNominal { .. })),
            "{:?}",
            d.err()
        );
    }

    /// Deconvolution through the sensor location's L_yw = 1 is r/(1 + λ) with λ = 1 % of the
    /// (unit) peak gain; through a dynamic L_yw it reproduces r at the frequencies G passes.
    #[test]
    fn deconvolution_inverts_the_block_path_up_to_its_ridge() {
        let nominal = Nominal::from_polynomial(&nominal()).unwrap();
        let disp: Arc<dyn Dispersion> = Arc::new(PolynomialDispersion::new(1).unwrap());
        let r: Vec<f64> = (0..400).map(|k| (0.05 * k as f64).sin()).collect();
        let sensor = nominal.hypothesis(Site::Output, Arc::clone(&disp)).unwrap();
        let d = deconvolve(&sensor, &r).unwrap();
        let worst = r
            .iter()
            .zip(&d)
            .map(|(a, b)| (a / 1.01 - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{worst}");
        // Input location: L_yw = G. A slow sine passes G, so T·δ̂ ≈ r.
        let input = nominal.hypothesis(Site::Input, disp).unwrap();
        let slow: Vec<f64> = (0..2000).map(|k| (0.01 * k as f64).sin()).collect();
        let delta = deconvolve(&input, &slow).unwrap();
        let s = Signal::from_fn(delta.len(), 1, |k, _| delta[k]);
        let back = input.model.lft().t_yw().simulate(&s).unwrap().channel(0);
        let err = (100..2000)
            .map(|k| (back[k] - slow[k]).powi(2))
            .sum::<f64>()
            .sqrt()
            / (100..2000).map(|k| slow[k].powi(2)).sum::<f64>().sqrt();
        assert!(err < 0.05, "relative error {err}");
    }

    fn fit(effect: Effect, params: usize, rms: f64, bic: f64) -> EffectFit {
        EffectFit {
            effect,
            parameters: (0..params)
                .map(|i| crate::effects::Parameter {
                    name: format!("p{i}"),
                    value: 1.0,
                    interval: (0.9, 1.1),
                })
                .collect(),
            offset: None,
            rss: rms * rms,
            rms,
            bic,
            expression: String::new(),
            support: (-1.0, 1.0),
            refit: None,
            flags: Vec::new(),
        }
    }

    #[test]
    fn parsimonious_order_prefers_fewer_parameters_among_fits_within_a_quarter() {
        let naming = Naming {
            ranked: vec![
                fit(Effect::Stribeck, 4, 1.0, -300.0),
                fit(Effect::AsymmetricSaturation, 3, 1.1, -290.0),
                fit(Effect::Gain, 1, 1.2, -280.0),
                fit(Effect::Offset, 1, 5.0, -10.0),
            ],
            named: None,
        };
        let order: Vec<Effect> = parsimonious(&naming).iter().map(|f| f.effect).collect();
        assert_eq!(
            order,
            vec![
                Effect::Gain,
                Effect::AsymmetricSaturation,
                Effect::Stribeck,
                Effect::Offset
            ]
        );
    }
}

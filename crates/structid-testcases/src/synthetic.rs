//! Synthetic test cases for the discovery workflow: a nominal linear model plus data from a
//! system with one hidden effect.
//!
//! [`generate`] draws, deterministically from a seed, a [`Case`]: the nominal model G the
//! workflow is given, the truth it must find ([`Hidden`]), and an estimation and a validation
//! record. Three kinds of case ([`CaseKind`]):
//!
//! * **static**: one named effect of [`Effect`] at one [`Site`] of G, simulated with
//!   *exactly* the augmented model [`hypothesis`] builds for that location, with the
//!   true map `effect.eval(θ, ·)` in the block (so the workflow's hypotheses contain the
//!   truth). The (effect, location) pairs are the physically sensible ones of
//!   [`STATIC_PAIRS`]: actuator saturation, asymmetric saturation, dead zone, quantisation
//!   and cubic distortion at the input; sensor saturation, quantisation, a square-law sensor
//!   with offset and cubic distortion at the output; cubic (hardening) stiffness and a
//!   saturating spring in feedback from the output; Coulomb + viscous and Stribeck friction
//!   in feedback from the output rate; and, less often, a gain error or a stuck block
//!   (`Offset`, a constant that replaces the signal) at the input or output;
//! * **none**: y = G·u + e, the nominal model is right (the workflow must not invent an
//!   effect);
//! * **hysteresis**: a backlash at the input or a Bouc–Wen hysteretic spring in feedback
//!   from the output ([`Hidden::Backlash`], [`Hidden::BoucWen`], equations there); no static
//!   map explains these and the workflow must report them as dynamic.
//!
//! # How a case is drawn
//!
//! * **G**: a stable discrete second-order system (third-order with probability 0.2: an
//!   extra real pole in 0.3…0.85), poles from a continuous pair with damping ζ ∈ [0.2, 0.7]
//!   and ω_n·T_s ∈ [0.08, 0.6] rad/sample (so the pole radius is 0.66…0.98: neither a
//!   trivial nor a nearly unstable response), one zero in −0.5…0.9, an input delay nk = 1,
//!   DC gain in [0.7, 1.5] and T_s log-uniform in [0.01, 0.1] s. `PolynomialModel { den,
//!   num: vec![[0, b₁, b₂]], sample_time: Some(T_s) }`.
//! * **Input** ([`InputKind`], drawn uniformly): filtered noise, a random-phase multisine,
//!   random steps held for several samples (the slow excitation), or a logarithmic chirp
//!   from well below to about G's bandwidth. Each has its own random parameters relative to
//!   G's −3 dB bandwidth (five times lower for the noise and the multisine of hysteresis
//!   cases, so that the input does not reverse inside the play at every sample); the peak
//!   amplitude is drawn in [0.5, 2]. Random steps are not used with rate feedback (the
//!   velocity is zero between steps, so friction acts only at the edges) nor with hysteresis
//!   (nothing moves between steps, and the direction of motion that tells hysteresis from a
//!   static map is only seen at the edges).
//! * **Parameters** relative to the range of the block's input z in the nominal simulation
//!   (u, G·u, y or ẏ, see [`Site`]): a saturation level at 30–70 % of max |z|, a dead
//!   zone half-width at 10–30 %, 6–20 quantisation levels over the range, a cubic term that
//!   changes the map by 15–60 % at the edge of the range, friction levels of 10–35 % of the
//!   input's RMS, and so on. The slope of saturations, dead zones and input or output
//!   polynomials is 1: the nominal model is the small-signal truth. Feedback gains are set
//!   relative to G's DC gain, and every local slope the map takes over the range (for
//!   friction, the viscous slope) must leave the linearised loop stable (pole radius ≤ 0.99).
//!   Backlash: half-width 10–30 % of max |u|. Bouc–Wen: stiffness 0.5–1.5 / G(1), elastic
//!   share α ∈ [0.05, 0.3], n ∈ {1, 2}, yield level 15–40 % of the peak output.
//! * **Checks**, with a redraw (deterministic from the seed) on failure: the effect must be
//!   active (e.g. a saturation clips 5–70 % of the samples, a dead zone holds 10–80 %), a
//!   hysteresis loop wide (in the plane of the element's input and output, over 20 bins of
//!   the input, rising and falling means at least 8 % of the output's range apart on
//!   average, and the direction of motion explaining at least 20 % of the output's variation
//!   about the bin means), every signal finite and bounded (|y| ≤ 20 × the nominal peak), and
//!   the effect's contribution RMS(y_with_effect − G·u) at least 8 × the noise std on the
//!   estimation record.
//! * **Noise**: white Gaussian e added to the output, std 0.5–2 % of std(y) (of the noise-free
//!   output with the effect; for a stuck block, whose output is nearly constant, of G·u),
//!   capped so that the 8 × rule holds. In the static cases e is the `e` of the LFT, so in
//!   feedback locations the map sees the *measured* output (as the hypotheses assume).
//! * **Validation**: a fresh realisation of the same input kind with the same parameters
//!   and 80–100 % of the amplitude, shrunk further if needed so that the block's input stays
//!   within the estimation range (a nonparametric map cannot be expected to extrapolate), and
//!   fresh noise of the same std.
//!
//! Lengths are 2000–4000 samples, the same for both records.
//!
//! ```
//! use structid_testcases::synthetic::{CaseKind, Hidden, generate};
//! let case = generate(CaseKind::Static, 3);
//! if let Hidden::Static { effect, theta, location } = &case.hidden {
//!     println!("{} at {location:?} with θ = {theta:?}", effect.name());
//!     assert!(case.parameters_within(theta, 0.2));
//!     assert!(case.equivalent_locations().contains(location));
//! }
//! assert_eq!(case.estimation.len(), case.validation.len());
//! assert!(case.noise_std > 0.0);
//! // Deterministic in the seed.
//! assert_eq!(generate(CaseKind::Static, 3).estimation, case.estimation);
//! ```

use std::sync::Arc;

use nalgebra::DVector;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use structid_core::{Data, Error, PolynomialDispersion, Result, Signal};
use structid_linear::PolynomialModel;

use structid_discover::effects::Effect;
use structid_discover::hypotheses::{Site, hypothesis};

/// The kind of input signal of a case; its parameters are drawn per case.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum InputKind {
    /// White Gaussian noise through a second-order low-pass with its cutoff at 0.5–2 × G's
    /// bandwidth (five times lower in hysteresis cases).
    FilteredNoise,
    /// A random-phase multisine with equal amplitudes on the frequency lines k/L from the
    /// lowest up to 1–2 × G's bandwidth (five times lower in hysteresis cases; at most 200
    /// lines, evenly spread).
    Multisine,
    /// Random levels, each held for a random number of samples (at least 5, around G's time
    /// constant): the slow excitation.
    RandomSteps,
    /// A logarithmic frequency sweep from 2–10 % of G's bandwidth to 1–1.5 × the bandwidth.
    Chirp,
}

impl InputKind {
    /// Every input kind.
    pub const ALL: [InputKind; 4] = [
        InputKind::FilteredNoise,
        InputKind::Multisine,
        InputKind::RandomSteps,
        InputKind::Chirp,
    ];
}

/// The effect hidden in a case's data: the truth the workflow must find (and must not see).
#[derive(Clone, Debug, PartialEq)]
pub enum Hidden {
    /// No effect: y = G·u + e.
    None,
    /// A static block N(z) = `effect.eval(theta, z)` at `location`, simulated with the LFT of
    /// [`hypothesis`] for that location and the output noise as its `e` (in feedback
    /// locations the block therefore sees the measured output or rate, as hypothesised).
    Static {
        /// The family.
        effect: Effect,
        /// Its parameters, in the order of [`Effect::parameter_names`].
        theta: Vec<f64>,
        /// Where the block sits.
        location: Site,
    },
    /// A backlash (mechanical play) at the input: v = backlash(u), y = G·v + e, with
    ///
    /// ```text
    ///   v_k = u_k − width   if u_k − v_(k−1) > width
    ///   v_k = u_k + width   if u_k − v_(k−1) < −width
    ///   v_k = v_(k−1)       otherwise,                 v_(−1) = 0
    /// ```
    ///
    /// so `width` is the half-width of the play (10–30 % of max |u|), like the dead zone's.
    Backlash {
        /// Half-width of the play.
        width: f64,
    },
    /// A Bouc–Wen hysteretic spring in feedback from the (true, noise-free) output:
    /// y = G·(u − w) + e with the restoring force
    ///
    /// ```text
    ///   w = α·k·y + (1 − α)·k·h
    ///   dh/dt = A·ẏ − β·|ẏ|·|h|^(n−1)·h − γ·ẏ·|h|^n
    /// ```
    ///
    /// Because the model is rate-independent, dh/dt = (dh/dy)·ẏ, it is integrated in y: at
    /// each sample h is advanced over the increment Δy = y_k − y_(k−1) by explicit Euler
    /// sub-steps of at most 2 % of the yield level h_max = (A/(β + γ))^(1/n), then
    /// w_k = α·k·y_k + (1 − α)·k·h_k enters the next state update of G (nk = 1, so there is
    /// no algebraic loop). Noise is added to y after the loop: the spring acts on the true
    /// displacement. The initial stiffness is k·(α + (1 − α)·A), the yielded one α·k.
    BoucWen {
        /// k, the spring's stiffness scale.
        stiffness: f64,
        /// α ∈ (0, 1), the elastic share.
        alpha: f64,
        /// A, the initial hysteretic slope dh/dy.
        a: f64,
        /// β > 0.
        beta: f64,
        /// γ, with |γ| ≤ β.
        gamma: f64,
        /// n ≥ 1, the sharpness of the yield.
        n: f64,
    },
}

impl Hidden {
    /// Simulates the true system (nominal `g` with this effect) for the input `u`, adding
    /// the output noise `e` when given (entering the loop as described for each variant).
    ///
    /// ```
    /// use structid_testcases::synthetic::Hidden;
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { den: vec![1.0, -0.5], num: vec![vec![0.0, 0.5]], sample_time: Some(0.1) };
    /// let y = Hidden::Backlash { width: 0.5 }.simulate(&g, &[1.0, 1.0, 0.0], None).unwrap();
    /// // v = [0.5, 0.5, 0.5]: y_k = 0.5 y_(k−1) + 0.5 v_(k−1)
    /// assert_eq!(y, vec![0.0, 0.25, 0.375]);
    /// ```
    pub fn simulate(&self, g: &PolynomialModel, u: &[f64], e: Option<&[f64]>) -> Result<Vec<f64>> {
        Ok(trace(g, self, u, e)?.y)
    }
}

/// A test case: what the workflow sees (nominal model and records) and the truth.
#[derive(Clone, Debug, PartialEq)]
pub struct Case {
    /// The seed it was generated from.
    pub seed: u64,
    /// The nominal linear model the workflow is given (one input, nk = 1, with a sample time).
    pub nominal: PolynomialModel,
    /// The truth (the workflow must not see it).
    pub hidden: Hidden,
    /// The kind of both records' input.
    pub input: InputKind,
    /// The std of the white output noise added to y.
    pub noise_std: f64,
    /// The estimation record.
    pub estimation: Data,
    /// The validation record: an independent input realisation of the same kind, fresh noise.
    pub validation: Data,
    /// The noise realisation e of the estimation record (truth, for checks).
    pub estimation_noise: Vec<f64>,
    /// The noise realisation e of the validation record (truth, for checks).
    pub validation_noise: Vec<f64>,
}

/// Which kind of case [`generate`] draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum CaseKind {
    /// One static effect ([`Hidden::Static`]).
    Static,
    /// No effect ([`Hidden::None`]).
    None,
    /// Backlash (even seeds) or Bouc–Wen hysteresis (odd seeds).
    Hysteresis,
}

/// The (effect, location) pairs of the static cases. Seed s uses the pair of slot s mod 30
/// of a schedule in which the first 13 (main) pairs appear twice and the last 4 (gain error
/// and stuck block) once: seeds 0…16 cover every pair once, and any 30 consecutive seeds
/// cover every pair.
pub const STATIC_PAIRS: [(Effect, Site); 17] = [
    (Effect::Saturation, Site::Input),
    (Effect::AsymmetricSaturation, Site::Input),
    (Effect::DeadZone, Site::Input),
    (Effect::Quantisation, Site::Input),
    (Effect::OddPolynomial { degree: 3 }, Site::Input),
    (Effect::Saturation, Site::Output),
    (Effect::Quantisation, Site::Output),
    (Effect::EvenPolynomial { degree: 2 }, Site::Output),
    (Effect::OddPolynomial { degree: 3 }, Site::Output),
    (Effect::OddPolynomial { degree: 3 }, Site::OutputFeedback),
    (Effect::Saturation, Site::OutputFeedback),
    (Effect::CoulombViscous, Site::RateFeedback),
    (Effect::Stribeck, Site::RateFeedback),
    (Effect::Gain, Site::Input),
    (Effect::Gain, Site::Output),
    (Effect::Offset, Site::Input),
    (Effect::Offset, Site::Output),
];

/// The pair a static case of `seed` uses (see [`STATIC_PAIRS`]).
fn static_pair(seed: u64) -> (Effect, Site) {
    let slot = (seed % 30) as usize;
    let main = 13;
    if slot < STATIC_PAIRS.len() {
        STATIC_PAIRS[slot]
    } else {
        STATIC_PAIRS[(slot - STATIC_PAIRS.len()) % main]
    }
}

/// Draws a case of `kind`, deterministically from `seed` (`StdRng::seed_from_u64(seed)`);
/// see the [module documentation](self) for what is drawn and checked.
///
/// ```
/// use structid_testcases::synthetic::{CaseKind, Hidden, generate};
/// let case = generate(CaseKind::None, 1);
/// assert_eq!(case.hidden, Hidden::None);
/// assert!(case.equivalent_locations().is_empty());
/// ```
pub fn generate(kind: CaseKind, seed: u64) -> Case {
    generate_counted(kind, seed).0
}

/// [`generate`] with the number of draws it took.
fn generate_counted(kind: CaseKind, seed: u64) -> (Case, usize) {
    let mut rng = StdRng::seed_from_u64(seed);
    for draws in 1..=10_000 {
        if let Some(case) = attempt(kind, seed, &mut rng) {
            return (case, draws);
        }
    }
    panic!("synthetic: no valid {kind:?} case for seed {seed} after 10000 draws")
}

impl Case {
    /// Locations at which the hidden effect is indistinguishable from where it was put: for
    /// a gain error and a stuck block (`Offset`) at the input or output both of these (G is
    /// linear, so a static gain commutes with it, and a constant in front of G is a constant
    /// behind it once G's transient has died out); otherwise just the location itself. Empty
    /// for [`Hidden::None`] and the hysteresis cases (no static block explains them).
    pub fn equivalent_locations(&self) -> Vec<Site> {
        match &self.hidden {
            Hidden::Static {
                effect: Effect::Gain | Effect::Offset,
                location: location @ (Site::Input | Site::Output),
                ..
            } => {
                let other = if *location == Site::Input {
                    Site::Output
                } else {
                    Site::Input
                };
                vec![*location, other]
            }
            Hidden::Static { location, .. } => vec![*location],
            _ => Vec::new(),
        }
    }

    /// Whether fitted parameters (same family, same order as [`Effect::parameter_names`])
    /// are each within `tolerance` (e.g. 0.2) relative of the truth. Parameters whose sign
    /// the family ignores (saturation level, dead-zone width, quantisation step, Stribeck
    /// velocity) are compared by magnitude, and the asymmetric saturation's limits as
    /// (lower, upper). For a stuck block the constant of either equivalent location is
    /// accepted (c at the input is G(1)·c at the output). Always `false` for [`Hidden::None`]
    /// and the hysteresis cases, or for a different number of parameters.
    pub fn parameters_within(&self, fitted: &[f64], tolerance: f64) -> bool {
        let Hidden::Static {
            effect,
            theta,
            location,
        } = &self.hidden
        else {
            return false;
        };
        if fitted.len() != theta.len() {
            return false;
        }
        let fitted = canonical(*effect, fitted);
        let close = |truth: &[f64]| {
            canonical(*effect, truth)
                .iter()
                .zip(&fitted)
                .all(|(t, f)| (f - t).abs() <= tolerance * t.abs())
        };
        if close(theta) {
            return true;
        }
        if *effect == Effect::Offset {
            let g0 = dc_gain(&self.nominal);
            let other = match location {
                Site::Input => theta[0] * g0,
                Site::Output => theta[0] / g0,
                _ => return false,
            };
            return close(&[other]);
        }
        false
    }
}

/// Parameters in a canonical form (signs the family ignores dropped, limits ordered).
fn canonical(effect: Effect, theta: &[f64]) -> Vec<f64> {
    let mut t = theta.to_vec();
    match effect {
        Effect::Saturation | Effect::DeadZone => t[1] = t[1].abs(),
        Effect::AsymmetricSaturation => {
            let (lo, hi) = (t[1].min(t[2]), t[1].max(t[2]));
            t[1] = lo;
            t[2] = hi;
        }
        Effect::Quantisation => t[0] = t[0].abs(),
        Effect::Stribeck => t[2] = t[2].abs(),
        _ => {}
    }
    t
}

// ---------------------------------------------------------------------------------------
// Simulation of the truth
// ---------------------------------------------------------------------------------------

/// Output, block input and block output of a simulation.
struct Trace {
    y: Vec<f64>,
    z: Vec<f64>,
    w: Vec<f64>,
}

fn signal(v: &[f64]) -> Signal {
    Signal::from_fn(v.len(), 1, |k, _| v[k])
}

fn lift(e: structid_linear::LinearError) -> Error {
    Error::InvalidStructure(e.to_string())
}

fn add_noise(mut y: Vec<f64>, e: Option<&[f64]>) -> Vec<f64> {
    if let Some(e) = e {
        for (y, e) in y.iter_mut().zip(e) {
            *y += e;
        }
    }
    y
}

fn trace(g: &PolynomialModel, hidden: &Hidden, u: &[f64], e: Option<&[f64]>) -> Result<Trace> {
    if let Some(e) = e
        && e.len() != u.len()
    {
        return Err(Error::InvalidStructure(format!(
            "{} noise samples for {} input samples",
            e.len(),
            u.len()
        )));
    }
    match hidden {
        Hidden::None => {
            let y = g.simulate(&signal(u)).map_err(lift)?;
            Ok(Trace {
                y: add_noise(y, e),
                z: u.to_vec(),
                w: u.to_vec(),
            })
        }
        Hidden::Static {
            effect,
            theta,
            location,
        } => static_trace(g, *location, &|z| effect.eval(theta, z), u, e),
        Hidden::Backlash { width } => {
            let v = backlash(u, *width);
            let y = g.simulate(&signal(&v)).map_err(lift)?;
            Ok(Trace {
                y: add_noise(y, e),
                z: u.to_vec(),
                w: v,
            })
        }
        Hidden::BoucWen { .. } => bouc_wen_trace(g, hidden, u, e),
    }
}

/// The augmented model of [`hypothesis`] at `location` simulated with `map` in its block.
fn static_trace(
    g: &PolynomialModel,
    location: Site,
    map: &(dyn Fn(f64) -> f64 + Sync),
    u: &[f64],
    e: Option<&[f64]>,
) -> Result<Trace> {
    let h = hypothesis(g, location, Arc::new(PolynomialDispersion::new(1)?))?;
    let f = |z: &[f64]| map(z[0]);
    let e = e.map(signal);
    let sim = h.simulate(&f, &signal(u), e.as_ref())?;
    Ok(Trace {
        y: sim.y.channel(0),
        z: sim.z.channel(0),
        w: sim.w.channel(0),
    })
}

/// The map that makes the augmented model at `location` the nominal G.
fn nominal_map(location: Site) -> fn(f64) -> f64 {
    match location {
        Site::Input | Site::Output => |z| z,
        Site::OutputFeedback | Site::RateFeedback | Site::Declared { .. } => |_| 0.0,
    }
}

fn backlash(u: &[f64], width: f64) -> Vec<f64> {
    let mut v = 0.0;
    u.iter()
        .map(|&u| {
            if u - v > width {
                v = u - width;
            } else if u - v < -width {
                v = u + width;
            }
            v
        })
        .collect()
}

/// Advances the Bouc–Wen state h over the displacement increment `dy` (explicit Euler in y).
fn bouc_wen_step(mut h: f64, dy: f64, a: f64, beta: f64, gamma: f64, n: f64) -> f64 {
    let h_max = (a / (beta + gamma)).powf(1.0 / n);
    let steps = (dy.abs() / (0.02 * h_max)).ceil().clamp(1.0, 1e6) as usize;
    let d = dy / steps as f64;
    for _ in 0..steps {
        let ha = h.abs();
        h += a * d - beta * d.abs() * ha.powf(n - 1.0) * h - gamma * d * ha.powf(n);
    }
    h
}

fn bouc_wen_trace(
    g: &PolynomialModel,
    hidden: &Hidden,
    u: &[f64],
    e: Option<&[f64]>,
) -> Result<Trace> {
    let Hidden::BoucWen {
        stiffness: k,
        alpha,
        a,
        beta,
        gamma,
        n,
    } = *hidden
    else {
        unreachable!("bouc_wen_trace is called for Bouc–Wen only")
    };
    let ss = g.to_state_space().map_err(lift)?;
    if ss.d()[(0, 0)] != 0.0 {
        return Err(Error::InvalidStructure(
            "Bouc–Wen feedback needs G to have an input delay (nk ≥ 1)".into(),
        ));
    }
    let am = ss.a().clone();
    let b: DVector<f64> = ss.b().column(0).into_owned();
    let c: DVector<f64> = ss.c().row(0).transpose();
    let mut x = DVector::zeros(ss.order());
    let (mut h, mut y_prev) = (0.0, 0.0);
    let len = u.len();
    let (mut y, mut z, mut w) = (
        Vec::with_capacity(len),
        Vec::with_capacity(len),
        Vec::with_capacity(len),
    );
    for k_ in 0..len {
        let yk = c.dot(&x);
        h = bouc_wen_step(h, yk - y_prev, a, beta, gamma, n);
        y_prev = yk;
        let wk = alpha * k * yk + (1.0 - alpha) * k * h;
        x = &am * &x + &b * (u[k_] - wk);
        y.push(yk);
        z.push(yk);
        w.push(wk);
    }
    Ok(Trace {
        y: add_noise(y, e),
        z,
        w,
    })
}

// ---------------------------------------------------------------------------------------
// Small numerical helpers
// ---------------------------------------------------------------------------------------

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn std_dev(v: &[f64]) -> f64 {
    let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn rms_diff(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a.iter().zip(b).map(|(a, b)| a - b).collect();
    rms(&d)
}

fn range(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
            (l.min(*x), h.max(*x))
        })
}

fn fraction(v: &[f64], pred: impl Fn(f64) -> bool) -> f64 {
    v.iter().filter(|x| pred(**x)).count() as f64 / v.len().max(1) as f64
}

fn dc_gain(g: &PolynomialModel) -> f64 {
    g.num[0].iter().sum::<f64>() / g.den.iter().sum::<f64>()
}

/// The −3 dB bandwidth of G in cycles per sample (capped at 0.25).
fn bandwidth(g: &PolynomialModel) -> f64 {
    let mag = |f: f64| {
        let (re, im) = g.frequency_response(0, f).unwrap_or((0.0, 0.0));
        re.hypot(im)
    };
    let level = mag(0.0) / std::f64::consts::SQRT_2;
    (1..=500)
        .map(|i| i as f64 * 0.001)
        .find(|f| mag(*f) < level)
        .unwrap_or(0.5)
        .min(0.25)
}

/// Whether F + s·P stays Schur stable with radius ≤ 0.99 for every s in [lo, hi], where P is
/// G's numerator B (output feedback) or B·(1 − q⁻¹)/T_s (rate feedback).
fn loop_stable(g: &PolynomialModel, lo: f64, hi: f64, rate: bool) -> bool {
    let b = &g.num[0];
    let p: Vec<f64> = if rate {
        let ts = g.sample_time.unwrap_or(1.0);
        (0..=b.len())
            .map(|j| (b.get(j).copied().unwrap_or(0.0) - if j > 0 { b[j - 1] } else { 0.0 }) / ts)
            .collect()
    } else {
        b.clone()
    };
    (0..=20).all(|i| {
        let s = lo + (hi - lo) * i as f64 / 20.0;
        let len = g.den.len().max(p.len());
        let den: Vec<f64> = (0..len)
            .map(|j| g.den.get(j).copied().unwrap_or(0.0) + s * p.get(j).copied().unwrap_or(0.0))
            .collect();
        let cl = PolynomialModel {
            den,
            num: vec![vec![1.0]],
            sample_time: None,
        };
        cl.spectral_radius() <= 0.99
    })
}

/// How hysteretic the points (z_k, w_k) are, from 20 quantile bins of z and the direction
/// in which z last moved:
///
/// * `width`: the mean over bins of |mean w moving up − mean w moving down|, relative to the
///   range of w (the loop's width in the (z, w) plane);
/// * `explained`: the share of the energy of w about its bin means that the direction
///   explains.
///
/// Both are about 0 for a static map.
#[derive(Clone, Copy, Debug)]
struct Loop {
    width: f64,
    explained: f64,
}

fn hysteresis_loop(z: &[f64], w: &[f64]) -> Loop {
    let none = Loop {
        width: 0.0,
        explained: 0.0,
    };
    let n = z.len().min(w.len());
    let mut dir = 0i8;
    let mut samples: Vec<(f64, f64, bool)> = Vec::with_capacity(n);
    for k in 1..n {
        let d = z[k] - z[k - 1];
        if d > 0.0 {
            dir = 1;
        } else if d < 0.0 {
            dir = -1;
        }
        if dir != 0 {
            samples.push((z[k], w[k], dir > 0));
        }
    }
    if samples.len() < 100 {
        return none;
    }
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    let bins = 20;
    let per = samples.len() / bins;
    let (mut gaps, mut between, mut total) = (Vec::new(), 0.0, 0.0);
    for chunk in samples.chunks(per) {
        let (mut su, mut nu, mut sd, mut nd) = (0.0, 0.0, 0.0, 0.0);
        for (_, w, up) in chunk {
            if *up {
                su += w;
                nu += 1.0;
            } else {
                sd += w;
                nd += 1.0;
            }
        }
        let mean = (su + sd) / (nu + nd);
        total += chunk
            .iter()
            .map(|(_, w, _)| (w - mean).powi(2))
            .sum::<f64>();
        if nu >= 5.0 && nd >= 5.0 {
            let (mu, md) = (su / nu, sd / nd);
            gaps.push((mu - md).abs());
            between += nu * (mu - mean).powi(2) + nd * (md - mean).powi(2);
        }
    }
    let (lo, hi) = range(&w[..n]);
    if gaps.len() < bins / 2 || hi <= lo || total <= 0.0 {
        return none;
    }
    Loop {
        width: gaps.iter().sum::<f64>() / gaps.len() as f64 / (hi - lo),
        explained: between / total,
    }
}

// ---------------------------------------------------------------------------------------
// Drawing
// ---------------------------------------------------------------------------------------

fn uniform(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

fn sign(rng: &mut StdRng) -> f64 {
    if rng.random_bool(0.5) { 1.0 } else { -1.0 }
}

fn draw_nominal(rng: &mut StdRng) -> PolynomialModel {
    let ts = (uniform(rng, 0.01f64.ln(), 0.1f64.ln())).exp();
    let zeta = uniform(rng, 0.2, 0.7);
    let wn = uniform(rng, 0.08, 0.6); // ω_n·T_s in rad/sample
    let r = (-zeta * wn).exp();
    let theta = wn * (1.0 - zeta * zeta).sqrt();
    let mut den = vec![1.0, -2.0 * r * theta.cos(), r * r];
    if rng.random_bool(0.2) {
        let p = uniform(rng, 0.3, 0.85);
        den = vec![1.0, den[1] - p, den[2] - p * den[1], -p * den[2]];
    }
    let zero = uniform(rng, -0.5, 0.9);
    let g0 = uniform(rng, 0.7, 1.5);
    let b1 = g0 * den.iter().sum::<f64>() / (1.0 - zero);
    PolynomialModel {
        den,
        num: vec![vec![0.0, b1, -b1 * zero]],
        sample_time: Some(ts),
    }
}

/// An input kind with its parameters (normalised frequencies in cycles per sample).
#[derive(Clone, Copy, Debug)]
struct InputSpec {
    kind: InputKind,
    /// Peak |u| of the estimation record.
    amplitude: f64,
    /// Cutoff (noise), highest line (multisine), shortest hold (steps), start frequency (chirp).
    p1: f64,
    /// Longest hold (steps), end frequency (chirp).
    p2: f64,
}

/// `smooth` lowers the band of the noise and the multisine by 5 (used for hysteresis, so
/// that the input does not reverse within the play at every sample).
fn draw_input_spec(
    rng: &mut StdRng,
    kind: InputKind,
    bw: f64,
    len: usize,
    smooth: bool,
) -> InputSpec {
    let amplitude = uniform(rng, 0.5, 2.0);
    let band = if smooth { 0.2 } else { 1.0 };
    let (p1, p2) = match kind {
        InputKind::FilteredNoise => ((band * bw * uniform(rng, 0.5, 2.0)).min(0.25), 0.0),
        InputKind::Multisine => ((band * bw * uniform(rng, 1.0, 2.0)).min(0.4), 0.0),
        InputKind::RandomSteps => {
            let tau = 1.0 / (2.0 * std::f64::consts::PI * bw);
            let lo = (0.5 * tau).max(5.0);
            let hi = (3.0 * tau).max(lo + 5.0).min(len as f64 / 30.0).max(lo);
            (lo, hi)
        }
        InputKind::Chirp => {
            let f0 = (bw * uniform(rng, 0.02, 0.1)).max(2.0 / len as f64);
            let f1 = (bw * uniform(rng, 1.0, 1.5)).clamp(3.0 * f0, 0.4);
            (f0, f1)
        }
    };
    InputSpec {
        kind,
        amplitude,
        p1,
        p2,
    }
}

/// A realisation of `spec` with peak |u| = `amplitude`.
fn realise(spec: &InputSpec, rng: &mut StdRng, len: usize, amplitude: f64) -> Vec<f64> {
    let normal = Normal::new(0.0, 1.0).expect("unit normal");
    let two_pi = 2.0 * std::f64::consts::PI;
    let raw: Vec<f64> = match spec.kind {
        InputKind::FilteredNoise => {
            let p = (-two_pi * spec.p1).exp();
            let warm = 300;
            let (mut s1, mut s2) = (0.0, 0.0);
            let mut v = Vec::with_capacity(len);
            for k in 0..len + warm {
                s1 = p * s1 + (1.0 - p) * normal.sample(rng);
                s2 = p * s2 + (1.0 - p) * s1;
                if k >= warm {
                    v.push(s2);
                }
            }
            v
        }
        InputKind::Multisine => {
            let top = ((spec.p1 * len as f64).floor() as usize).max(2);
            let lines: Vec<usize> = if top > 200 {
                (0..200).map(|i| 1 + i * (top - 1) / 199).collect()
            } else {
                (1..=top).collect()
            };
            let phases: Vec<f64> = lines.iter().map(|_| two_pi * rng.random::<f64>()).collect();
            (0..len)
                .map(|k| {
                    lines
                        .iter()
                        .zip(&phases)
                        .map(|(l, ph)| (two_pi * *l as f64 * k as f64 / len as f64 + ph).cos())
                        .sum()
                })
                .collect()
        }
        InputKind::RandomSteps => {
            let mut v = Vec::with_capacity(len);
            while v.len() < len {
                let hold = uniform(rng, spec.p1, spec.p2).round().max(1.0) as usize;
                let level = uniform(rng, -1.0, 1.0);
                v.extend(std::iter::repeat_n(level, hold));
            }
            v.truncate(len);
            v
        }
        InputKind::Chirp => {
            let (f0, f1) = if rng.random_bool(0.5) {
                (spec.p1, spec.p2)
            } else {
                (spec.p2, spec.p1)
            };
            let mut phase = two_pi * rng.random::<f64>();
            (0..len)
                .map(|k| {
                    let f = f0 * (f1 / f0).powf(k as f64 / len as f64);
                    let v = phase.sin();
                    phase += two_pi * f;
                    v
                })
                .collect()
        }
    };
    let peak = max_abs(&raw).max(f64::MIN_POSITIVE);
    raw.iter().map(|v| v * amplitude / peak).collect()
}

/// What the parameters are drawn from: the nominal simulation at the location.
struct Nominal<'a> {
    g: &'a PolynomialModel,
    u: &'a [f64],
    z: Vec<f64>,
}

impl Nominal<'_> {
    /// max |y| with the linear feedback N(z) = k·z at `location`.
    fn linear_feedback_peak(&self, location: Site, k: f64) -> Option<f64> {
        let t = static_trace(self.g, location, &|z| k * z, self.u, None).ok()?;
        let m = max_abs(&t.z);
        m.is_finite().then_some(m)
    }
}

/// θ for `effect` at `location`, relative to the nominal z; `None` when the draw is unusable.
fn draw_theta(
    rng: &mut StdRng,
    effect: Effect,
    location: Site,
    nom: &Nominal<'_>,
) -> Option<Vec<f64>> {
    let g = nom.g;
    let g0 = dc_gain(g);
    let zmax = max_abs(&nom.z);
    let (zlo, zhi) = range(&nom.z);
    let feedback = matches!(location, Site::OutputFeedback | Site::RateFeedback);
    let theta = match (effect, feedback) {
        (Effect::Saturation, false) => vec![1.0, uniform(rng, 0.3, 0.7) * zmax],
        (Effect::Saturation, true) => {
            let k = uniform(rng, 0.3, 1.2) / g0;
            if !loop_stable(g, 0.0, k, false) {
                return None;
            }
            let peak = nom.linear_feedback_peak(location, k)?;
            vec![k, uniform(rng, 0.3, 0.7) * k * peak]
        }
        (Effect::AsymmetricSaturation, _) => {
            let f1 = uniform(rng, 0.3, 0.7);
            let mut f2 = uniform(rng, 0.3, 0.7);
            while (f1 - f2).abs() < 0.15 {
                f2 = uniform(rng, 0.3, 0.7);
            }
            vec![1.0, f1 * zlo, f2 * zhi]
        }
        (Effect::DeadZone, _) => vec![1.0, uniform(rng, 0.1, 0.3) * zmax],
        (Effect::Quantisation, _) => {
            let levels = rng.random_range(6..=20) as f64;
            vec![(zhi - zlo) / (levels - 1.0)]
        }
        (Effect::OddPolynomial { degree: 3 }, false) => {
            let rho = if rng.random_bool(0.6) {
                uniform(rng, 0.2, 0.6)
            } else {
                -uniform(rng, 0.15, 0.25)
            };
            vec![1.0, rho / (zmax * zmax)]
        }
        (Effect::OddPolynomial { degree: 3 }, true) => {
            // Hardening stiffness a1·y + a3·y³ with both terms active.
            let a1 = uniform(rng, 0.2, 1.0) / g0;
            let peak = nom.linear_feedback_peak(location, a1)?;
            let a3 = uniform(rng, 0.3, 1.0) * a1 / (peak * peak);
            vec![a1, a3]
        }
        (Effect::EvenPolynomial { degree: 2 }, _) => {
            let a2 = sign(rng) * uniform(rng, 0.5, 1.5) / zmax;
            let a0 = sign(rng) * uniform(rng, 0.2, 0.6) * a2.abs() * zmax * zmax;
            vec![a0, a2]
        }
        (Effect::CoulombViscous | Effect::Stribeck, _) => {
            let u_rms = rms(nom.u);
            let z_rms = rms(&nom.z).max(f64::MIN_POSITIVE);
            let c = uniform(rng, 0.1, 0.35) * u_rms;
            let v = uniform(rng, 0.1, 0.5) * u_rms / z_rms;
            if !loop_stable(g, 0.0, v, true) {
                return None;
            }
            if effect == Effect::CoulombViscous {
                vec![c, v]
            } else {
                let s = c * uniform(rng, 1.5, 2.5);
                let vs = uniform(rng, 0.2, 0.6) * z_rms;
                vec![c, s, vs, v]
            }
        }
        (Effect::Gain, _) => {
            let k = if rng.random_bool(0.5) {
                uniform(rng, 0.6, 0.8)
            } else {
                uniform(rng, 1.25, 1.6)
            };
            vec![k]
        }
        (Effect::Offset, _) => vec![sign(rng) * uniform(rng, 0.2, 1.0) * zmax],
        _ => return None,
    };
    Some(theta)
}

/// Whether the effect is clearly active on the block input `z` of the simulation with it,
/// and (feedback) every local slope over the range leaves the linearised loop stable.
fn active(effect: Effect, theta: &[f64], location: Site, g: &PolynomialModel, z: &[f64]) -> bool {
    let (zlo, zhi) = range(z);
    let zmax = max_abs(z);
    let ok = match effect {
        Effect::Saturation => {
            let edge = theta[1].abs() / theta[0].abs();
            (0.05..=0.7).contains(&fraction(z, |z| z.abs() > edge))
        }
        Effect::AsymmetricSaturation => {
            let (lo, hi) = (theta[1] / theta[0], theta[2] / theta[0]);
            fraction(z, |z| z > hi) >= 0.05
                && fraction(z, |z| z < lo) >= 0.05
                && fraction(z, |z| z > lo && z < hi) >= 0.3
        }
        Effect::DeadZone => (0.1..=0.8).contains(&fraction(z, |z| z.abs() < theta[1])),
        Effect::Quantisation => (5.0..=21.0).contains(&((zhi - zlo) / theta[0])),
        Effect::Stribeck => {
            fraction(z, |z| z.abs() < theta[2]) >= 0.05
                && fraction(z, |z| z.abs() > 2.0 * theta[2]) >= 0.1
        }
        _ => true,
    };
    let stable = match location {
        Site::OutputFeedback => {
            let slope_hi = match effect {
                Effect::OddPolynomial { .. } => theta[0] + 3.0 * theta[1] * zmax * zmax,
                _ => theta[0],
            };
            loop_stable(g, 0.0, slope_hi, false)
        }
        Site::RateFeedback => loop_stable(g, 0.0, theta[theta.len() - 1], true),
        _ => true,
    };
    ok && stable
}

/// Draws the hysteresis truth relative to the nominal simulation.
fn draw_hysteresis(rng: &mut StdRng, bouc_wen: bool, nom: &Nominal<'_>) -> Option<Hidden> {
    if !bouc_wen {
        return Some(Hidden::Backlash {
            width: uniform(rng, 0.1, 0.3) * max_abs(nom.u),
        });
    }
    let g = nom.g;
    let k = uniform(rng, 0.5, 1.5) / dc_gain(g);
    let alpha = uniform(rng, 0.05, 0.3);
    let n = if rng.random_bool(0.5) { 1.0 } else { 2.0 };
    let rho = uniform(rng, 0.3, 1.0);
    // Unloading slope dh/dy reaches A + (β − γ)·h_max^n = 1 + (1 − ρ)/(1 + ρ).
    let unload = 1.0 + (1.0 - rho) / (1.0 + rho);
    if !loop_stable(g, alpha * k, k * (alpha + (1.0 - alpha) * unload), false) {
        return None;
    }
    let peak = nom.linear_feedback_peak(Site::OutputFeedback, k)?;
    let h_max = uniform(rng, 0.15, 0.4) * peak;
    let beta = h_max.powf(-n) / (1.0 + rho);
    Some(Hidden::BoucWen {
        stiffness: k,
        alpha,
        a: 1.0,
        beta,
        gamma: rho * beta,
        n,
    })
}

fn finite_bounded(t: &Trace, bound: f64) -> bool {
    [&t.y, &t.z, &t.w]
        .iter()
        .all(|v| v.iter().all(|x| x.is_finite() && x.abs() <= bound))
}

fn noise(rng: &mut StdRng, std: f64, len: usize) -> Vec<f64> {
    let n = Normal::new(0.0, std).expect("finite positive std");
    (0..len).map(|_| n.sample(rng)).collect()
}

/// One draw of a case; `None` when a check fails.
fn attempt(kind: CaseKind, seed: u64, rng: &mut StdRng) -> Option<Case> {
    let g = draw_nominal(rng);
    let bw = bandwidth(&g);
    let len = rng.random_range(2000..=4000);
    let pair = static_pair(seed);
    let continuous_motion =
        kind == CaseKind::Hysteresis || (kind == CaseKind::Static && pair.1 == Site::RateFeedback);
    let kinds: &[InputKind] = if continuous_motion {
        &[
            InputKind::FilteredNoise,
            InputKind::Multisine,
            InputKind::Chirp,
        ]
    } else {
        &InputKind::ALL
    };
    let input = kinds[rng.random_range(0..kinds.len())];
    let spec = draw_input_spec(rng, input, bw, len, kind == CaseKind::Hysteresis);
    let u = realise(&spec, rng, len, spec.amplitude);
    let y_nominal = g.simulate(&signal(&u)).ok()?;
    let nominal_peak = max_abs(&y_nominal).max(max_abs(&u));
    let bound = 20.0 * nominal_peak;

    let hidden = match kind {
        CaseKind::None => Hidden::None,
        CaseKind::Static => {
            let (effect, location) = pair;
            let nom_trace = static_trace(&g, location, &nominal_map(location), &u, None).ok()?;
            let nom = Nominal {
                g: &g,
                u: &u,
                z: nom_trace.z,
            };
            let theta = draw_theta(rng, effect, location, &nom)?;
            Hidden::Static {
                effect,
                theta,
                location,
            }
        }
        CaseKind::Hysteresis => {
            let nom = Nominal {
                g: &g,
                u: &u,
                z: y_nominal.clone(),
            };
            draw_hysteresis(rng, seed % 2 == 1, &nom)?
        }
    };

    // The effect, noise-free: active, bounded, clearly above the noise.
    let clean = trace(&g, &hidden, &u, None).ok()?;
    if !finite_bounded(&clean, bound) {
        return None;
    }
    match &hidden {
        Hidden::Static {
            effect,
            theta,
            location,
        } => {
            if !active(*effect, theta, *location, &g, &clean.z) {
                return None;
            }
        }
        Hidden::Backlash { .. } | Hidden::BoucWen { .. } => {
            let l = hysteresis_loop(&clean.z, &clean.w);
            if l.width < 0.08 || l.explained < 0.2 {
                return None;
            }
        }
        Hidden::None => {}
    }
    let stuck = matches!(
        hidden,
        Hidden::Static {
            effect: Effect::Offset,
            ..
        }
    );
    let scale = if stuck || hidden == Hidden::None {
        std_dev(&y_nominal)
    } else {
        std_dev(&clean.y)
    };
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    let fraction = if hidden == Hidden::None {
        uniform(rng, 0.005, 0.02)
    } else {
        let contribution = rms_diff(&clean.y, &y_nominal);
        let most = (contribution / (8.0 * scale)).min(0.02);
        if most < 0.005 {
            return None;
        }
        uniform(rng, 0.005, most)
    };
    let noise_std = fraction * scale;
    let e_est = noise(rng, noise_std, len);
    let est = trace(&g, &hidden, &u, Some(&e_est)).ok()?;
    if !finite_bounded(&est, bound) {
        return None;
    }

    // Validation: same kind, fresh realisation, inside the estimation range of z.
    let (zlo, zhi) = range(&clean.z);
    let margin = 0.02 * (zhi - zlo);
    let mut amplitude = spec.amplitude * uniform(rng, 0.8, 1.0);
    let raw = realise(&spec, rng, len, 1.0);
    let mut u_val: Vec<f64> = Vec::new();
    let mut inside = false;
    for _ in 0..40 {
        u_val = raw.iter().map(|v| v * amplitude).collect();
        let t = trace(&g, &hidden, &u_val, None).ok()?;
        let (lo, hi) = range(&t.z);
        if lo >= zlo - margin && hi <= zhi + margin {
            inside = finite_bounded(&t, bound);
            break;
        }
        amplitude *= 0.95;
    }
    if !inside {
        return None;
    }
    let e_val = noise(rng, noise_std, len);
    let val = trace(&g, &hidden, &u_val, Some(&e_val)).ok()?;
    if !finite_bounded(&val, bound) {
        return None;
    }
    Some(Case {
        seed,
        nominal: g,
        hidden,
        input,
        noise_std,
        estimation: Data::new(signal(&u), signal(&est.y)).ok()?,
        validation: Data::new(signal(&u_val), signal(&val.y)).ok()?,
        estimation_noise: e_est,
        validation_noise: e_val,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn static_parts(case: &Case) -> (Effect, Vec<f64>, Site) {
        match &case.hidden {
            Hidden::Static {
                effect,
                theta,
                location,
            } => (*effect, theta.clone(), *location),
            h => panic!("not a static case: {h:?}"),
        }
    }

    #[test]
    fn same_seed_gives_the_same_case() {
        for kind in [CaseKind::Static, CaseKind::None, CaseKind::Hysteresis] {
            for seed in [0, 11, 12] {
                let a = generate(kind, seed);
                let b = generate(kind, seed);
                assert_eq!(a, b, "{kind:?} {seed}");
                let c = generate(kind, seed + 30);
                assert_ne!(a.estimation, c.estimation, "{kind:?} {seed}");
            }
        }
    }

    #[test]
    fn cases_are_finite_with_lengths_noise_and_nominal_in_range() {
        for kind in [CaseKind::Static, CaseKind::None, CaseKind::Hysteresis] {
            for seed in 0..40 {
                let c = generate(kind, seed);
                let g = &c.nominal;
                assert!(
                    g.is_stable() && g.spectral_radius() < 0.99,
                    "{kind:?} {seed}"
                );
                assert_eq!(g.num.len(), 1);
                assert_eq!(g.num[0][0], 0.0, "nk = 1");
                assert_ne!(g.num[0][1], 0.0, "nk = 1");
                let ts = g.sample_time.unwrap();
                assert!((0.01..=0.1).contains(&ts));
                assert!((0.7..=1.5).contains(&dc_gain(g)));
                for d in [&c.estimation, &c.validation] {
                    assert!((2000..=4000).contains(&d.len()));
                    assert!(d.u().as_slice().iter().all(|v| v.is_finite()));
                    assert!(d.y().as_slice().iter().all(|v| v.is_finite()));
                }
                let y_clean = c
                    .hidden
                    .simulate(g, c.estimation.u().as_slice(), None)
                    .unwrap();
                let scale = if matches!(
                    c.hidden,
                    Hidden::None
                        | Hidden::Static {
                            effect: Effect::Offset,
                            ..
                        }
                ) {
                    std_dev(&g.simulate(c.estimation.u()).unwrap())
                } else {
                    std_dev(&y_clean)
                };
                let frac = c.noise_std / scale;
                assert!(
                    (0.005 - 1e-12..=0.02 + 1e-12).contains(&frac),
                    "{kind:?} {seed}: noise {frac}"
                );
                assert!(
                    (std_dev(&c.estimation_noise) / c.noise_std - 1.0).abs() < 0.1,
                    "{kind:?} {seed}"
                );
            }
        }
    }

    #[test]
    fn none_cases_are_the_nominal_model_plus_noise() {
        for seed in 0..10 {
            let c = generate(CaseKind::None, seed);
            for (d, e) in [
                (&c.estimation, &c.estimation_noise),
                (&c.validation, &c.validation_noise),
            ] {
                let y = c.nominal.simulate(d.u()).unwrap();
                let worst = (0..d.len())
                    .map(|k| (d.y().get(k, 0) - y[k] - e[k]).abs())
                    .fold(0.0, f64::max);
                assert!(worst < 1e-12, "{seed}: {worst}");
            }
        }
    }

    #[test]
    fn the_effect_is_active_against_the_noise() {
        for kind in [CaseKind::Static, CaseKind::Hysteresis] {
            for seed in 0..60 {
                let c = generate(kind, seed);
                let u = c.estimation.u().as_slice();
                let with = c.hidden.simulate(&c.nominal, u, None).unwrap();
                let without = c.nominal.simulate(c.estimation.u()).unwrap();
                let contribution = rms_diff(&with, &without);
                assert!(
                    contribution >= 8.0 * c.noise_std * (1.0 - 1e-9),
                    "{kind:?} {seed} {:?}: {contribution} vs noise {}",
                    c.hidden,
                    c.noise_std
                );
            }
        }
    }

    #[test]
    fn every_effect_location_pair_occurs_over_seeds_0_to_200() {
        let mut counts = vec![0usize; STATIC_PAIRS.len()];
        let mut inputs = vec![0usize; InputKind::ALL.len()];
        for seed in 0..200 {
            let c = generate(CaseKind::Static, seed);
            let (effect, theta, location) = static_parts(&c);
            assert_eq!(theta.len(), effect.parameter_names().len());
            let i = STATIC_PAIRS
                .iter()
                .position(|p| *p == (effect, location))
                .unwrap_or_else(|| panic!("{effect:?} at {location:?} is not a listed pair"));
            counts[i] += 1;
            inputs[InputKind::ALL.iter().position(|k| *k == c.input).unwrap()] += 1;
        }
        for (i, n) in counts.iter().enumerate() {
            assert!(*n >= 6, "{:?}: {n} times", STATIC_PAIRS[i]);
        }
        assert!(inputs.iter().all(|n| *n >= 20), "{inputs:?}");
        // Any 30 consecutive seeds cover every pair.
        let pairs: std::collections::HashSet<usize> = (100..130)
            .map(|s| {
                STATIC_PAIRS
                    .iter()
                    .position(|p| *p == static_pair(s))
                    .unwrap()
            })
            .collect();
        assert_eq!(pairs.len(), STATIC_PAIRS.len());
    }

    #[test]
    fn equivalent_locations_of_gain_offset_and_the_rest() {
        let mut seen = 0;
        for seed in 0..30 {
            let c = generate(CaseKind::Static, seed);
            let (effect, _, location) = static_parts(&c);
            let eq = c.equivalent_locations();
            assert_eq!(eq[0], location);
            if matches!(effect, Effect::Gain | Effect::Offset) {
                assert_eq!(eq.len(), 2, "{effect:?}");
                assert!(eq.contains(&Site::Input) && eq.contains(&Site::Output));
                seen += 1;
            } else {
                assert_eq!(eq, vec![location], "{effect:?}");
            }
        }
        assert_eq!(seen, 4);
        assert!(
            generate(CaseKind::None, 0)
                .equivalent_locations()
                .is_empty()
        );
        assert!(
            generate(CaseKind::Hysteresis, 0)
                .equivalent_locations()
                .is_empty()
        );
        assert!(
            generate(CaseKind::Hysteresis, 1)
                .equivalent_locations()
                .is_empty()
        );
    }

    #[test]
    fn parameters_within_accepts_the_truth_and_rejects_25_percent_off() {
        for seed in 0..30 {
            let c = generate(CaseKind::Static, seed);
            let (effect, theta, location) = static_parts(&c);
            assert!(c.parameters_within(&theta, 0.2), "{effect:?}");
            let close: Vec<f64> = theta.iter().map(|t| t * 1.15).collect();
            assert!(c.parameters_within(&close, 0.2), "{effect:?}");
            let g0 = dc_gain(&c.nominal);
            for i in 0..theta.len() {
                for factor in [1.25, 0.75] {
                    let mut off = theta.clone();
                    off[i] *= factor;
                    if effect == Effect::Offset {
                        // Unless it happens to be the other location's constant.
                        let other = theta[0]
                            * if location == Site::Input {
                                g0
                            } else {
                                1.0 / g0
                            };
                        if (off[0] - other).abs() <= 0.2 * other.abs() {
                            continue;
                        }
                    }
                    assert!(
                        !c.parameters_within(&off, 0.2),
                        "{effect:?} at {location:?}: θ{i} × {factor} accepted"
                    );
                }
            }
            assert!(!c.parameters_within(&theta[..theta.len() - 1], 0.2));
            if effect == Effect::Offset {
                // The constant of the other location is accepted too.
                let other = if location == Site::Input {
                    theta[0] * g0
                } else {
                    theta[0] / g0
                };
                assert!(c.parameters_within(&[other], 0.2));
            }
            // Magnitudes and ordering the family ignores.
            if effect == Effect::Saturation {
                assert!(c.parameters_within(&[theta[0], -theta[1]], 0.2));
            }
            if effect == Effect::AsymmetricSaturation {
                assert!(c.parameters_within(&[theta[0], theta[2], theta[1]], 0.2));
            }
        }
        assert!(!generate(CaseKind::None, 0).parameters_within(&[1.0], 0.2));
        let h = generate(CaseKind::Hysteresis, 0);
        let Hidden::Backlash { width } = h.hidden else {
            panic!("even seeds are backlash")
        };
        assert!(!h.parameters_within(&[width], 0.2));
    }

    /// The data are exactly the augmented model the workflow hypothesises with the true map:
    /// re-simulating `hypothesis(nominal, location, ..)` with `effect.eval(θ, ·)` and the case's
    /// noise gives the records; without noise it gives the noise-free part (records − e) at
    /// the input and output, where the noise does not enter the loop.
    #[test]
    fn data_are_the_hypothesised_structure_with_the_true_map() {
        let mut locations = std::collections::HashSet::new();
        for seed in [0, 5, 9, 11, 12, 13, 14] {
            let c = generate(CaseKind::Static, seed);
            let (effect, theta, location) = static_parts(&c);
            locations.insert(format!("{location:?}"));
            let h = hypothesis(
                &c.nominal,
                location,
                Arc::new(PolynomialDispersion::new(1).unwrap()),
            )
            .unwrap();
            let f = |z: &[f64]| effect.eval(&theta, z[0]);
            for (d, e) in [
                (&c.estimation, &c.estimation_noise),
                (&c.validation, &c.validation_noise),
            ] {
                let sim = |e: Option<&Signal>| h.simulate(&f, d.u(), e).unwrap().y;
                let noisy = sim(Some(&signal(e)));
                let worst = (0..d.len())
                    .map(|k| (noisy.get(k, 0) - d.y().get(k, 0)).abs())
                    .fold(0.0, f64::max);
                assert!(worst < 1e-9, "{effect:?} at {location:?}: {worst}");
                if matches!(location, Site::Input | Site::Output) {
                    let clean = sim(None);
                    let worst = (0..d.len())
                        .map(|k| (clean.get(k, 0) + e[k] - d.y().get(k, 0)).abs())
                        .fold(0.0, f64::max);
                    assert!(worst < 1e-9, "{effect:?} at {location:?}: {worst}");
                }
            }
        }
        assert_eq!(locations.len(), 4, "{locations:?}");
    }

    #[test]
    fn validation_stays_within_the_estimation_range() {
        for kind in [CaseKind::Static, CaseKind::Hysteresis, CaseKind::None] {
            for seed in 0..30 {
                let c = generate(kind, seed);
                let z = |d: &Data| {
                    trace(&c.nominal, &c.hidden, d.u().as_slice(), None)
                        .unwrap()
                        .z
                };
                let (lo, hi) = range(&z(&c.estimation));
                let (vlo, vhi) = range(&z(&c.validation));
                let m = 0.02 * (hi - lo) + 1e-12;
                assert!(vlo >= lo - m && vhi <= hi + m, "{kind:?} {seed}");
                // Not a much smaller validation either.
                assert!(vhi - vlo >= 0.4 * (hi - lo), "{kind:?} {seed}");
            }
        }
    }

    #[test]
    fn hysteresis_cases_have_wide_loops() {
        let mut kinds = [0, 0];
        for seed in 0..20 {
            let c = generate(CaseKind::Hysteresis, seed);
            let u = c.estimation.u().as_slice();
            let t = trace(&c.nominal, &c.hidden, u, None).unwrap();
            let l = hysteresis_loop(&t.z, &t.w);
            assert!(l.width >= 0.08 && l.explained >= 0.2, "{seed}: {l:?}");
            assert_ne!(c.input, InputKind::RandomSteps);
            match c.hidden {
                Hidden::Backlash { width } => {
                    let rel = width / max_abs(u);
                    assert!((0.1..=0.3).contains(&rel), "{seed}: {rel}");
                    kinds[0] += 1;
                }
                Hidden::BoucWen {
                    alpha, beta, gamma, ..
                } => {
                    assert!(alpha > 0.0 && alpha < 1.0 && beta > 0.0 && gamma.abs() <= beta);
                    kinds[1] += 1;
                }
                ref h => panic!("{h:?}"),
            }
            // The direction test of the hysteresis module sees it in (z, w) against the
            // binned static fit.
            let r = static_residual(&t.z, &t.w);
            assert!(
                structid_discover::hysteresis::direction_dependence(&t.z, &r, 0.1).dynamic,
                "{seed}"
            );
        }
        assert_eq!(kinds, [10, 10]);
        // A static map has no loop.
        let z: Vec<f64> = (0..2000).map(|k| (k as f64 * 0.01).sin()).collect();
        let w: Vec<f64> = z.iter().map(|z| z.powi(3)).collect();
        let l = hysteresis_loop(&z, &w);
        assert!(l.width < 1e-3 && l.explained < 1e-3, "{l:?}");
    }

    /// w minus its mean in 40 quantile bins of z (a nonparametric static fit).
    fn static_residual(z: &[f64], w: &[f64]) -> Vec<f64> {
        let mut order: Vec<usize> = (0..z.len()).collect();
        order.sort_by(|a, b| z[*a].total_cmp(&z[*b]));
        let mut r = vec![0.0; z.len()];
        for chunk in order.chunks(z.len() / 40) {
            let m = chunk.iter().map(|i| w[*i]).sum::<f64>() / chunk.len() as f64;
            for i in chunk {
                r[*i] = w[*i] - m;
            }
        }
        r
    }

    /// Statistics of the drawn cases (run with `--ignored --nocapture`).
    #[test]
    #[ignore]
    fn print_case_statistics() {
        for kind in [CaseKind::Static, CaseKind::Hysteresis, CaseKind::None] {
            for seed in 0..60 {
                let (c, draws) = generate_counted(kind, seed);
                let u = c.estimation.u().as_slice();
                let t = trace(&c.nominal, &c.hidden, u, None).unwrap();
                let y0 = c.nominal.simulate(c.estimation.u()).unwrap();
                let ratio = rms_diff(&t.y, &y0) / c.noise_std;
                let r = static_residual(&t.z, &t.w);
                let dd = structid_discover::hysteresis::direction_dependence(&t.z, &r, 0.1);
                let what = match &c.hidden {
                    Hidden::Static {
                        effect, location, ..
                    } => format!("{effect:?}@{location:?}"),
                    h => format!("{h:?}").chars().take(40).collect(),
                };
                println!(
                    "{kind:?} {seed:3} draws {draws:3} {:?} L {} ts {:.3} bw {:.4} {what} ratio {ratio:.1} loop {:.3} expl {:.2} dd {:.2}/{:.1}",
                    c.input,
                    c.estimation.len(),
                    c.nominal.sample_time.unwrap(),
                    bandwidth(&c.nominal),
                    hysteresis_loop(&t.z, &t.w).width,
                    hysteresis_loop(&t.z, &t.w).explained,
                    dd.explained,
                    dd.t_statistic
                );
            }
        }
    }

    #[test]
    fn bouc_wen_state_stays_below_its_yield_level() {
        let (a, beta, gamma, n) = (1.0, 2.0, 2.0, 1.0); // h_max = 0.25
        let mut h = 0.0;
        let mut peak = 0.0f64;
        for k in 0..2000 {
            let dy = 0.05 * (k as f64 * 0.01).cos();
            h = bouc_wen_step(h, dy, a, beta, gamma, n);
            peak = peak.max(h.abs());
        }
        assert!(peak <= 0.25 + 1e-9 && peak > 0.2, "{peak}");
        // Small moves from rest follow dh/dy = A.
        assert!((bouc_wen_step(0.0, 1e-4, a, beta, gamma, n) - 1e-4).abs() < 1e-8);
    }
}

//! A hysteresis at the plant input, fitted with G: the memory effect no static block is.
//!
//! The model is the one-stop Prandtl–Ishlinskii operator w = u + λ·s, with s the stop
//! operator of threshold c, s_k = clamp(s_(k−1) + u_k − u_(k−1), −c, c) from s₀ = 0, and
//! y = G·w. It covers the two hysteresis shapes met at actuators:
//! - λ = −1 is a play (backlash) of half-width c: u − s is the follower
//!   b_k = min(max(b_(k−1), u_k − c), u_k + c), which stays put until u has crossed the gap;
//! - λ > 0 is an elasto-plastic (Bouc–Wen-like) hysteresis, α·u + (1 − α)·s up to G's gain
//!   with α = 1/(1 + λ), whose restoring part yields at ±c.
//!
//! Its static approximations (a dead zone, a cubic) close little of the gap, and a nominal G
//! estimated from such a record has absorbed part of its phase lag into its own dynamics, so
//! the direction test on the static fit's residual can stay below its threshold. The operator
//! is fitted directly instead. For each threshold c, two paths y = (B₁·u + B₂·s)/F with G's
//! poles are fitted by output error, λ is B₂'s least-squares multiple of B₁, and G is
//! polished by output error from w = u + λ·s (and, from the nominal, with a play's λ = −1:
//! the better of the two is kept). c is chosen by the estimation record's simulation RMS (a
//! grid over the range of u, then a golden-section search around its best point). The fit
//! is then simulated on the validation record as every hypothesis is.

use std::sync::Arc;

use structid_core::model::hysteresis::apply_from_rest_into;
use structid_core::{Data, Play, PolynomialDispersion, Result, Signal, Stop};
use structid_linear::{OeSettings, PolynomialModel, output_error_records};

use crate::hypotheses::{Nominal, Site};
use crate::records::{self, Simulated};

use super::DiscoverSettings;
use super::fit::scoring_settings;

/// A hysteresis at the input fitted with G (by `discover`, step 4 of the workflow):
/// w = u + λ·s with s the stop operator of threshold c, and y = G·w.
#[derive(Clone, Debug, serde::Serialize)]
pub struct InputHysteresis {
    /// The stop operator's threshold c, in u's units (the play's half-width when λ = −1).
    pub threshold: f64,
    /// The stop operator's weight λ (−1: a play; > 0: elasto-plastic).
    pub weight: f64,
    /// G re-estimated with the hysteresis in front of it.
    pub g: PolynomialModel,
    /// Simulation RMS on the estimation record (the workflow's scoring).
    pub estimation_rms: f64,
    /// Simulation RMS on the validation record.
    pub validation_rms: f64,
    /// Validation RMS of G re-estimated without the hysteresis (c = 0): what the hysteresis
    /// adds to a better G alone.
    pub without_hysteresis_rms: f64,
}

/// A weight within this distance of −1 is a play (backlash).
pub const PLAY_WEIGHT_TOLERANCE: f64 = 0.25;

impl InputHysteresis {
    /// Whether the operator is a play (backlash): λ within [`PLAY_WEIGHT_TOLERANCE`] of −1.
    pub fn is_play(&self) -> bool {
        (self.weight + 1.0).abs() <= PLAY_WEIGHT_TOLERANCE
    }

    /// The operator in words, with its parameters.
    ///
    /// ```
    /// use structid_discover::discover::InputHysteresis;
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel::new(vec![vec![0.0, 1.0]], vec![1.0, -0.5], None).unwrap();
    /// let mut h = InputHysteresis {
    ///     threshold: 0.2, weight: -0.97, g, estimation_rms: 0.0, validation_rms: 0.0,
    ///     without_hysteresis_rms: 0.0,
    /// };
    /// assert!(h.describe().starts_with("a play (backlash) of half-width 0.2"));
    /// h.weight = 3.0;
    /// assert!(h.describe().starts_with("an elasto-plastic hysteresis"));
    /// ```
    pub fn describe(&self) -> String {
        if self.is_play() {
            format!(
                "a play (backlash) of half-width {:.4} at the input (stop weight λ = {:.3})",
                self.threshold, self.weight
            )
        } else {
            format!(
                "an elasto-plastic hysteresis at the input, w = u + λ·s with a stop operator s \
                 of threshold c = {:.4} and λ = {:.3}",
                self.threshold, self.weight
            )
        }
    }
}

/// The play operator of half-width `half_width` on `u`, into `out` (same length), its
/// follower starting at u₀: u − [`stop_into`] with the same threshold.
///
/// The core [`Play`] operator from rest at u₀, with |`half_width`| as its half-width.
///
/// ```
/// use structid_discover::discover::play_into;
/// let u = [0.0, 1.0, 2.0, 1.5, 1.0, 0.0];
/// let mut b = [0.0; 6];
/// play_into(&u, 0.5, &mut b);
/// assert_eq!(b, [0.0, 0.5, 1.5, 1.5, 1.5, 0.5]);
/// ```
///
/// # Panics
/// When `out` is not as long as `u`, or `half_width` is NaN and `u` is not empty.
pub fn play_into(u: &[f64], half_width: f64, out: &mut [f64]) {
    assert_eq!(u.len(), out.len(), "play_into: lengths differ");
    let Some(&first) = u.first() else {
        return;
    };
    let c = half_width.abs();
    if c == f64::INFINITY {
        // The core operator takes finite widths only; an infinite gap is never crossed.
        out.fill(first);
        return;
    }
    let play = Play::new(c).expect("play_into: the half-width is NaN");
    apply_from_rest_into(&play, u, out);
}

/// The stop operator of threshold `threshold` on `u`, into `out` (same length), from s₀ = 0:
/// s_k = clamp(s_(k−1) + u_k − u_(k−1), −c, c).
///
/// The core [`Stop`] operator from rest at u₀, with |`threshold`| as its threshold.
///
/// ```
/// use structid_discover::discover::stop_into;
/// let u = [0.0, 1.0, 2.0, 1.5, 1.0, 0.0];
/// let mut s = [0.0; 6];
/// stop_into(&u, 0.5, &mut s);
/// assert_eq!(s, [0.0, 0.5, 0.5, 0.0, -0.5, -0.5]);
/// ```
///
/// # Panics
/// When `out` is not as long as `u`, or `threshold` is NaN and `u` is not empty.
pub fn stop_into(u: &[f64], threshold: f64, out: &mut [f64]) {
    assert_eq!(u.len(), out.len(), "stop_into: lengths differ");
    let Some(&first) = u.first() else {
        return;
    };
    // The core operator takes thresholds in (0, ∞); the search here starts at c = 0, where the
    // stop yields at once, and an infinite threshold never yields.
    match threshold.abs() {
        0.0 => out.fill(0.0),
        f64::INFINITY => out.iter_mut().zip(u).for_each(|(o, x)| *o = x - first),
        c => {
            let stop = Stop::new(c).expect("stop_into: the threshold is NaN");
            apply_from_rest_into(&stop, u, out);
        }
    }
}

/// Each record's u and its stop operator of threshold `c`.
fn stopped(data: &Data, c: f64) -> Vec<(Vec<f64>, Vec<f64>, Signal)> {
    data.records()
        .into_iter()
        .map(|r| {
            let u = r.u().channel(0);
            let mut s = vec![0.0; u.len()];
            stop_into(&u, c, &mut s);
            (u, s, r.y().clone())
        })
        .collect()
}

/// `records` with w = u + λ·s as their input.
fn with_input(records: &[(Vec<f64>, Vec<f64>, Signal)], weight: f64) -> Result<Data> {
    Data::from_records(
        records
            .iter()
            .map(|(u, s, y)| {
                let w = u.iter().zip(s).map(|(u, s)| u + weight * s).collect();
                Data::new(Signal::new(1, w)?, y.clone())
            })
            .collect::<Result<Vec<_>>>()?,
    )
}

/// Grid points over the range of u (fractions of it), before the golden-section search.
const GRID: [f64; 14] = [
    0.0, 0.0025, 0.005, 0.01, 0.02, 0.03, 0.045, 0.065, 0.09, 0.12, 0.16, 0.21, 0.28, 0.36,
];

/// Golden-section steps after the grid.
const GOLDEN_STEPS: usize = 12;

struct Trial {
    c: f64,
    weight: f64,
    g: PolynomialModel,
    estimation_rms: f64,
}

/// λ and G for the threshold `c` on `est`, and the simulation RMS there; `None` when the
/// simulation fails. Two paths from u and from s with G's poles, y = (B₁·u + B₂·s)/F, are
/// fitted by output error from G and a play (B₂ = −B₁), and λ is B₂'s least-squares multiple
/// of B₁; G is then polished by output error from w = u + λ·s starting from that fit, and
/// from the nominal with a play's λ = −1, and the better on the estimation record is kept
/// (integrators fixed throughout). A threshold of 0 is G re-estimated alone.
fn trial(g: &PolynomialModel, est: &Data, c: f64, settings: &DiscoverSettings) -> Option<Trial> {
    let records = stopped(est, c);
    let oe = OeSettings::builder()
        .max_iterations(30)
        .integrators(super::refine::near_unit_poles(&g.den))
        .build()
        .ok()?;
    let b = g.num.first()?;
    let (mut start, mut weight) = (g.clone(), 0.0);
    if c > 0.0 {
        let two: Vec<(Signal, &Signal)> = records
            .iter()
            .map(|(u, s, y)| {
                let both = u.iter().zip(s).flat_map(|(u, s)| [*u, *s]).collect();
                Signal::new(2, both).map(|x| (x, y))
            })
            .collect::<std::result::Result<_, _>>()
            .ok()?;
        let pairs: Vec<(&Signal, &Signal)> = two.iter().map(|(x, y)| (x, *y)).collect();
        // From a play (B₂ = −B₁): an all-zero path has no delay structure to start from.
        let minus: Vec<f64> = b.iter().map(|v| -v).collect();
        let initial =
            PolynomialModel::new(vec![b.clone(), minus], g.den.clone(), g.sample_time).ok()?;
        if let Ok(f) = output_error_records(&pairs, &initial, &oe) {
            let (b1, b2) = (&f.model.num[0], &f.model.num[1]);
            let norm: f64 = b1.iter().map(|v| v * v).sum();
            weight = b1.iter().zip(b2).map(|(p, q)| p * q).sum::<f64>() / norm;
            if !weight.is_finite() {
                weight = 0.0;
            }
            start = PolynomialModel::new(vec![b1.clone()], f.model.den.clone(), g.sample_time)
                .unwrap_or_else(|_| g.clone());
        }
    }
    // G polished from the two-path fit with its λ, and from the nominal with a play's
    // λ = −1 (the two-path fit can wander into a near pole–zero cancellation that takes up
    // the offsets a wrong λ leaves): the better on the estimation record is kept.
    let candidates: Vec<(f64, &PolynomialModel)> = if c > 0.0 {
        vec![(weight, &start), (-1.0, g)]
    } else {
        vec![(0.0, g)]
    };
    candidates
        .into_iter()
        .filter_map(|(weight, s)| {
            let data = with_input(&records, weight).ok()?;
            let parts = data.records();
            let pairs: Vec<(&Signal, &Signal)> = parts.iter().map(|r| (r.u(), r.y())).collect();
            let fitted = output_error_records(&pairs, s, &oe)
                .map(|f| f.model)
                .unwrap_or_else(|_| s.clone());
            let rms = simulate_linear(&fitted, &data, settings)?.rms;
            Some(Trial {
                c,
                weight,
                g: fitted,
                estimation_rms: rms,
            })
        })
        .min_by(|a, b| a.estimation_rms.total_cmp(&b.estimation_rms))
}

/// G from the input on `data` (u already through the operator), scored as every simulation
/// of the workflow; `None` when it fails or diverges.
pub(super) fn simulate_linear(
    g: &PolynomialModel,
    data: &Data,
    settings: &DiscoverSettings,
) -> Option<Simulated> {
    simulate_linear_as(g, data, settings, Site::Input)
}

/// [`simulate_linear`], with its initial state handled as a hypothesis at `location` handles
/// it (from rest at the sensor and the rate), so that it competes with one on equal terms.
pub(super) fn simulate_linear_as(
    g: &PolynomialModel,
    data: &Data,
    settings: &DiscoverSettings,
    location: Site,
) -> Option<Simulated> {
    let h = Nominal::from_polynomial(g)
        .ok()?
        .hypothesis(Site::Input, Arc::new(PolynomialDispersion::new(1).ok()?))
        .ok()?;
    let identity = structid_core::ExprMap::parse("z0", 1).ok()?;
    let limit =
        1e6 * structid_core::validation::metrics::rms(&data.y().channel(0)).max(f64::MIN_POSITIVE);
    records::simulate(
        &h.model,
        &h.maps(&identity),
        &h.data(data).ok()?,
        &scoring_settings(location, settings),
    )
    .ok()
    .filter(|v| v.rms.is_finite() && v.rms < limit)
}

/// The hysteresis at the input that best explains `est` with G re-estimated behind it (see
/// the module's notes), simulated on `val`; `None` when u is constant or no fit simulates.
pub(super) fn input_hysteresis(
    g: &PolynomialModel,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> Option<InputHysteresis> {
    let u = est.u().channel(0);
    let (lo, hi) = super::fit::minmax(&u);
    let span = hi - lo;
    if !(span > 0.0 && span.is_finite()) {
        return None;
    }
    let trials: Vec<Trial> = GRID
        .iter()
        .filter_map(|f| trial(g, est, f * span, settings))
        .collect();
    let alone = trials.iter().find(|t| t.c == 0.0)?;
    let best = trials
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.estimation_rms.total_cmp(&b.1.estimation_rms))?
        .0;
    // Golden section between the grid neighbours of the best point (indices into GRID only
    // when every grid point simulated; otherwise around the best point's own threshold).
    let at = |i: usize| trials.get(i).map_or(trials[best].c, |t| t.c);
    let (mut a, mut b) = (at(best.saturating_sub(1)), at(best + 1));
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    let rms = |t: &Option<Trial>| t.as_ref().map_or(f64::INFINITY, |t| t.estimation_rms);
    let (mut x1, mut x2) = (b - phi * (b - a), a + phi * (b - a));
    let (mut f1, mut f2) = (trial(g, est, x1, settings), trial(g, est, x2, settings));
    for _ in 0..GOLDEN_STEPS {
        if rms(&f1) <= rms(&f2) {
            (b, x2, f2) = (x2, x1, f1);
            x1 = b - phi * (b - a);
            f1 = trial(g, est, x1, settings);
        } else {
            (a, x1, f1) = (x1, x2, f2);
            x2 = a + phi * (b - a);
            f2 = trial(g, est, x2, settings);
        }
    }
    let mut chosen = &trials[best];
    for t in [&f1, &f2].into_iter().flatten() {
        if t.estimation_rms < chosen.estimation_rms {
            chosen = t;
        }
    }
    let val_rms = |t: &Trial| {
        let records = stopped(val, t.c);
        with_input(&records, t.weight)
            .ok()
            .and_then(|d| simulate_linear(&t.g, &d, settings))
            .map_or(f64::INFINITY, |s| s.rms)
    };
    Some(InputHysteresis {
        threshold: chosen.c,
        weight: chosen.weight,
        validation_rms: val_rms(chosen),
        without_hysteresis_rms: val_rms(alone),
        estimation_rms: chosen.estimation_rms,
        g: chosen.g.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn wavy(len: usize, phase: f64) -> Vec<f64> {
        (0..len)
            .map(|k| {
                let t = k as f64;
                (t * 0.013 + phase).sin() * 1.5 + 0.5 * (t * 0.057 + 2.0 * phase).sin()
            })
            .collect()
    }

    /// The play and stop operators against their definitions by cases, and play = u − stop.
    #[test]
    fn the_play_follows_u_only_across_its_gap_and_is_u_minus_the_stop() {
        let u = wavy(400, 0.3);
        let c = 0.4;
        let (mut b, mut s) = (vec![0.0; u.len()], vec![0.0; u.len()]);
        play_into(&u, c, &mut b);
        stop_into(&u, c, &mut s);
        for k in 1..u.len() {
            // |u − b| ≤ c always, b moves only when the gap is closed, and then with u.
            assert!((u[k] - b[k]).abs() <= c + 1e-12);
            if b[k] != b[k - 1] {
                assert!(((u[k] - b[k]).abs() - c).abs() < 1e-12);
                assert_eq!((b[k] - b[k - 1]).signum(), (u[k] - u[k - 1]).signum());
            }
            assert!((u[k] - s[k] - b[k]).abs() < 1e-12);
        }
        // A zero half-width is the identity.
        play_into(&u, 0.0, &mut b);
        assert_eq!(b, u);
    }

    /// G = (0.2q⁻¹ + 0.1q⁻²)/(1 − 1.2q⁻¹ + 0.5q⁻²).
    fn plant() -> PolynomialModel {
        PolynomialModel::new(vec![vec![0.0, 0.2, 0.1]], vec![1.0, -1.2, 0.5], None).unwrap()
    }

    /// Estimation and validation records of `plant()` behind `operator`, seeded by `seed`.
    fn est_and_val(seed: u64, operator: impl Fn(&[f64]) -> Vec<f64> + Copy) -> (Data, Data) {
        let g = plant();
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let est = record(&g, &mut rng, 0.0, operator);
        let val = record(&g, &mut rng, 1.0, operator);
        (est, val)
    }

    fn record(
        g: &PolynomialModel,
        rng: &mut rand::rngs::StdRng,
        phase: f64,
        operator: impl Fn(&[f64]) -> Vec<f64>,
    ) -> Data {
        let n = Normal::new(0.0, 0.01).unwrap();
        let u = wavy(1500, phase);
        let y: Vec<f64> = g
            .simulate(&Signal::new(1, operator(&u)).unwrap())
            .unwrap()
            .into_iter()
            .map(|v| v + n.sample(rng))
            .collect();
        Data::new(Signal::new(1, u).unwrap(), Signal::new(1, y).unwrap()).unwrap()
    }

    /// A play at the input of a G is found with its half-width and λ = −1, G re-estimated
    /// from a start with a 30 % gain error; it validates at the noise level while G alone
    /// does not.
    #[test]
    fn a_play_at_the_input_is_found_with_its_width() {
        let (est, val) = est_and_val(3, |u: &[f64]| {
            let mut b = vec![0.0; u.len()];
            play_into(u, 0.3, &mut b);
            b
        });
        let start =
            PolynomialModel::new(vec![vec![0.0, 0.14, 0.07]], vec![1.0, -1.2, 0.5], None).unwrap();
        let h = input_hysteresis(&start, &est, &val, &DiscoverSettings::default()).unwrap();
        assert!((h.threshold - 0.3).abs() < 0.03, "{h:?}");
        assert!(h.is_play(), "{h:?}");
        assert!(h.validation_rms < 0.015, "{h:?}");
        assert!(h.without_hysteresis_rms > 4.0 * h.validation_rms, "{h:?}");
    }

    /// An elasto-plastic hysteresis 0.3·u + 0.7·s is found with its threshold and
    /// λ = 0.7/0.3 (G absorbs the 0.3).
    #[test]
    fn an_elasto_plastic_hysteresis_is_found_with_its_weight() {
        let (est, val) = est_and_val(5, |u: &[f64]| {
            let mut s = vec![0.0; u.len()];
            stop_into(u, 0.5, &mut s);
            u.iter().zip(&s).map(|(u, s)| 0.3 * u + 0.7 * s).collect()
        });
        let h = input_hysteresis(&plant(), &est, &val, &DiscoverSettings::default()).unwrap();
        assert!((h.threshold - 0.5).abs() < 0.05, "{h:?}");
        assert!((h.weight - 0.7 / 0.3).abs() < 0.25, "{h:?}");
        assert!(!h.is_play());
        assert!(h.validation_rms < 0.015, "{h:?}");
    }
}

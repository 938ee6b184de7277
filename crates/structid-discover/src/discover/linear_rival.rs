//! G alone, re-estimated with one more mode: the linear model every finding must beat.
//!
//! A nominal G that lacks a mode (an unmodelled resonance) leaves a gap larger than the noise,
//! and a static block at some site imitates part of it. So before a gap is called a missing
//! static effect (or an unexplained one), G alone is re-estimated from the estimation record
//! by output error with two more poles and two more zeros than the given G (its poles all
//! free: a near-integrator is a pole like any other here) and simulated on the validation
//! record as every model is. Output error is not convex, so it starts from an ARX model of the
//! new orders and from G itself with a lightly damped pole pair (and a zero pair on it) at
//! each of [`START_FREQUENCIES`] frequencies spread over the band on a logarithmic scale, and
//! the fit with the smallest estimation RMS is kept.
//!
//! The verdict is "the linear model was wrong" ([`super::Verdict::LinearModel`]) when that G
//! closes the gap, its validation RMS within `noise_ratio`·σ̂ (the level at which the
//! nominal model's own gap would count as noise), and the finding's augmented model is not
//! better than it by the paired test of the validation errors over blocks at α
//! ([`crate::table::compare_blocks`]). A nonlinearity leaves a gap that no linear model of any
//! order closes, and a finding better than the rival at α stands whatever the rival leaves.
//! A dynamic finding's augmented model holds only the static approximation of a direction
//! effect, whose errors do not describe it, so it is judged by what the rival leaves instead:
//! a lightly damped mode that G lacks can leave a residual that depends on the direction of
//! motion, but once the rival holds that mode its own residual, deconvolved to the finding's
//! block as the direction test's is, no longer does; a hysteresis leaves a direction effect
//! that no linear model removes ([`leaves_direction_effect`]). The rival explains a dynamic
//! finding when it closes the gap and leaves no direction effect there.

use structid_core::Data;
use structid_linear::integrators::convolve;
use structid_linear::{OeSettings, Orders, PolynomialModel, oe_records, output_error_records};

use crate::table::{BlockComparison, compare_blocks};

use super::DiscoverSettings;
use crate::hypotheses::{Hypothesis, Site};
use structid_core::Interpolant;

use super::direction::{acts_in_continuous_time, deconvolve, direction_beyond_sampling, transient};
use super::fit::z_of;

use super::input_hysteresis::{simulate_linear, simulate_linear_as};

/// G re-estimated alone with one more mode, two more poles and zeros than the given G, by
/// output error on the estimation record: the linear model a finding must beat. It explains
/// the gap ([`super::Verdict::LinearModel`]) when it validates within `noise_ratio`·σ̂ and the
/// finding is not better than it by the paired block test at α.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LinearRival {
    /// The re-estimated G, from u to y.
    pub g: PolynomialModel,
    /// Its simulation RMS on the validation record, scored as every model of the workflow.
    pub validation_rms: f64,
    /// The paired test of the finding's validation errors against this G's (a: the finding,
    /// b: this G), when there was a finding and the test could be made; the finding is better
    /// at α when `1 − p_worse` < α.
    pub comparison: Option<BlockComparison>,
    /// Whether this G closes the gap and the finding is not better than it at α (for a
    /// dynamic finding: and this G's own residual leaves no direction effect at the
    /// finding's block): the linear model was wrong.
    pub explains: bool,
    /// For a dynamic finding: whether this G's own residual, deconvolved to the finding's
    /// block, still depends on the direction of the block's input
    /// (see `leaves_direction_effect` in this module); `None` when not assessed.
    pub leaves_direction_effect: Option<bool>,
}

/// The extra poles (and zeros) of the rival: one mode.
const EXTRA_ORDER: usize = 2;

/// The rival G for the given polynomial `g`, fitted on `est` and scored on `val` as a
/// hypothesis at `location` is (its initial state from rest at the sensor and the rate);
/// `None` when the fit fails or its simulation diverges.
pub(super) fn fit(
    g: &PolynomialModel,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
    location: Site,
) -> Option<(PolynomialModel, Vec<f64>, f64)> {
    let b = g.num.first()?;
    let nk = b.iter().take_while(|v| **v == 0.0).count();
    let nb = b.len().saturating_sub(nk).max(1);
    let orders = Orders::siso(
        g.den.len().saturating_sub(1) + EXTRA_ORDER,
        nb + EXTRA_ORDER,
        nk,
    );
    let mut builder = OeSettings::builder().max_iterations(50);
    if let Some(ts) = g.sample_time {
        builder = builder.sample_time(ts);
    }
    let oe = builder.build().ok()?;
    let parts = est.records();
    let pairs: Vec<_> = parts.iter().map(|r| (r.u(), r.y())).collect();
    let from_arx = oe_records(&pairs, &orders, &oe).ok().map(|f| f.model);
    let from_modes = (0..START_FREQUENCIES).filter_map(|j| {
        let start = with_mode(g, start_frequency(j))?;
        output_error_records(&pairs, &start, &oe)
            .ok()
            .map(|f| f.model)
    });
    let estimation_rms =
        |m: &PolynomialModel| simulate_linear(m, est, settings).map_or(f64::INFINITY, |s| s.rms);
    let rival = from_arx
        .into_iter()
        .chain(from_modes)
        .map(|m| (estimation_rms(&m), m))
        .filter(|(rms, _)| rms.is_finite())
        .min_by(|a, b| a.0.total_cmp(&b.0))?
        .1;
    let simulated = simulate_linear_as(&rival, val, settings, location)?;
    let errors = simulated.scored_residual();
    Some((rival, errors, simulated.rms))
}

/// How many lightly damped modes output error starts from.
pub const START_FREQUENCIES: usize = 16;

/// The lowest and highest start frequency, in cycles per sample (the Nyquist frequency is
/// 0.5).
const START_BAND: (f64, f64) = (0.002, 0.45);

/// The damping ratio ζ of the starts' pole pairs: light, as a mode that a nominal model
/// misses is.
const START_DAMPING: f64 = 0.05;

/// Start frequency `j` of [`START_FREQUENCIES`], evenly spaced on a logarithmic scale over
/// [`START_BAND`].
fn start_frequency(j: usize) -> f64 {
    let (lo, hi) = START_BAND;
    lo * (hi / lo).powf(j as f64 / (START_FREQUENCIES - 1) as f64)
}

/// G with a pole pair of damping [`START_DAMPING`] at `f` cycles per sample and a zero pair
/// on it: G itself, for output error to move the pair apart.
fn with_mode(g: &PolynomialModel, f: f64) -> Option<PolynomialModel> {
    let w = 2.0 * std::f64::consts::PI * f;
    let radius = (-START_DAMPING * w).exp();
    let mode = [1.0, -2.0 * radius * w.cos(), radius * radius];
    let num = g.num.iter().map(|b| convolve(b, &mode)).collect();
    PolynomialModel::new(num, convolve(&g.den, &mode), g.sample_time).ok()
}

/// The rival's verdict on a finding whose augmented model leaves the validation errors
/// `finding_errors` (`None`: no finding; empty: a finding that cannot be tested against it,
/// which the rival does not overrule), with `gap_level` the RMS below which a model closes
/// the gap.
pub(super) fn judge(
    (g, errors, validation_rms): (PolynomialModel, Vec<f64>, f64),
    finding_errors: Option<&[f64]>,
    gap_level: f64,
    alpha: f64,
) -> LinearRival {
    let comparison = finding_errors.and_then(|f| compare_blocks(f, &errors));
    // A finding that could not be tested against the rival (its simulation failed, or too
    // few blocks) is not overruled by it.
    let finding_better = match (finding_errors, &comparison) {
        (None, _) => false,
        (Some(_), Some(c)) => c.better_at(alpha),
        (Some(_), None) => true,
    };
    LinearRival {
        g,
        validation_rms,
        comparison,
        explains: validation_rms <= gap_level && !finding_better,
        leaves_direction_effect: None,
    }
}

/// The rival's verdict on a dynamic finding, whose augmented model holds only a static
/// approximation and so has no errors to compare: it explains the gap when it closes it and
/// its own residual leaves no direction effect at the finding's block (`leaves`, from
/// [`leaves_direction_effect`]; `None`, not assessed, never overrules).
pub(super) fn judge_dynamic(
    (g, _, validation_rms): (PolynomialModel, Vec<f64>, f64),
    leaves: Option<bool>,
    gap_level: f64,
) -> LinearRival {
    LinearRival {
        g,
        validation_rms,
        comparison: None,
        explains: validation_rms <= gap_level && leaves == Some(false),
        leaves_direction_effect: leaves,
    }
}

/// Whether the rival G's own simulation residual on the estimation record, deconvolved to the
/// output of the block of `h` (as the finding's direction test deconvolves its residual),
/// still depends on the direction of the block's input z, by the direction test's bar on its
/// t statistic ([`crate::hysteresis::DIRECTION_T`]) whatever share of the residual it
/// explains: a hysteresis leaves a direction effect that no linear model removes, while a
/// missing mode that imitated one leaves none once the rival holds that mode. `map` is the finding's static map, for the sampling
/// artefact of a map in feedback ([`direction_beyond_sampling`]). `None` when a record cannot
/// be simulated or deconvolved.
pub(super) fn leaves_direction_effect(
    rival: &PolynomialModel,
    h: &Hypothesis,
    map: Option<&dyn Interpolant>,
    est: &Data,
    settings: &DiscoverSettings,
) -> Option<bool> {
    let (mut z, mut kept, mut bounds) = (Vec::new(), Vec::new(), vec![0]);
    for record in est.records() {
        let simulated = rival.simulate(record.u()).ok()?;
        let r: Vec<f64> = record
            .y()
            .channel(0)
            .iter()
            .zip(&simulated)
            .map(|(y, s)| y - s)
            .collect();
        let delta = deconvolve(h, &r).ok()?;
        let zr = z_of(h, &h.data(&record).ok()?).ok()?;
        // The start of each record carries the rival's transient from rest: left out as the
        // direction test leaves out its own residual's start.
        let skip = transient(delta.len(), settings);
        z.extend_from_slice(&zr[skip..]);
        kept.extend_from_slice(&delta[skip..]);
        bounds.push(z.len());
    }
    // The direction test's own bar on the t statistic, with no bar on the share of energy
    // the direction explains: the rival's residual is mostly noise once it closes the gap, so
    // a hysteresis left in it is a small share of a significant effect.
    let any_share = 0.0;
    let test = direction_beyond_sampling(
        &z,
        &kept,
        &bounds,
        map.filter(|_| acts_in_continuous_time(h.location)),
        any_share,
    );
    Some(test.dynamic)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};
    use structid_core::Signal;

    const NOISE: f64 = 0.01;

    fn nominal() -> PolynomialModel {
        PolynomialModel::new(vec![vec![0.0, 0.1, 0.1]], vec![1.0, -1.5, 0.7], None).unwrap()
    }

    /// G followed by a lightly damped mode of unit static gain at `f` cycles per sample.
    fn with_true_mode(f: f64) -> PolynomialModel {
        let w = 2.0 * std::f64::consts::PI * f;
        let r: f64 = 0.97;
        let den = [1.0, -2.0 * r * w.cos(), r * r];
        let gain: f64 = den.iter().sum();
        let g = nominal();
        let num = vec![convolve(&g.num[0], &[gain])];
        PolynomialModel::new(num, convolve(&g.den, &den), None).unwrap()
    }

    fn record(truth: &PolynomialModel, seed: u64) -> Data {
        let mut rng = StdRng::seed_from_u64(seed);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let mut s = 0.0;
        let u = Signal::from_fn(3000, 1, |_, _| {
            s = 0.5 * s + unit.sample(&mut rng);
            s
        });
        let clean = truth.simulate(&u).unwrap();
        let noise = Normal::new(0.0, NOISE).unwrap();
        let y = clean.iter().map(|v| v + noise.sample(&mut rng)).collect();
        Data::new(u, Signal::new(1, y).unwrap()).unwrap()
    }

    #[test]
    fn the_rival_recovers_a_mode_that_the_nominal_model_lacks() {
        let truth = with_true_mode(0.08);
        let (est, val) = (record(&truth, 1), record(&truth, 2));
        let settings = DiscoverSettings::default();
        let nominal_rms = simulate_linear(&nominal(), &val, &settings).unwrap().rms;
        let (g, errors, rms) = fit(&nominal(), &est, &val, &settings, Site::Input).unwrap();
        assert_eq!(g.den.len(), nominal().den.len() + EXTRA_ORDER);
        // Within the noise that was added, where the nominal model misses by many times it.
        assert!(rms < 1.2 * NOISE, "rival RMS {rms}");
        assert!(nominal_rms > 5.0 * NOISE, "nominal RMS {nominal_rms}");
        // A finding that leaves twice the rival's errors is no better; one that leaves a
        // tenth of them is.
        let worse: Vec<f64> = errors.iter().map(|e| 2.0 * e).collect();
        let better: Vec<f64> = errors.iter().map(|e| 0.1 * e).collect();
        let level = 1.5 * NOISE;
        let fitted = (g, errors, rms);
        assert!(judge(fitted.clone(), Some(&worse), level, 0.05).explains);
        assert!(!judge(fitted.clone(), Some(&better), level, 0.05).explains);
        // A rival that leaves more than the gap level explains nothing, whatever the finding.
        assert!(!judge(fitted, Some(&worse), 0.5 * rms, 0.05).explains);
    }

    /// A play (backlash) of half-width `half` on u.
    fn play(u: &[f64], half: f64) -> Vec<f64> {
        let mut w = vec![0.0; u.len()];
        for k in 0..u.len() {
            let prev: f64 = if k > 0 { w[k - 1] } else { 0.0 };
            w[k] = prev.clamp(u[k] - half, u[k] + half);
        }
        w
    }

    /// The rival G (the truth's linear part) leaves no direction effect at the input of a
    /// plant that only lacks a mode, and keeps the one a backlash at the input leaves: no
    /// linear model removes it.
    #[test]
    fn a_missing_mode_leaves_no_direction_effect_in_the_rival_and_a_backlash_does() {
        use crate::hypotheses::hypothesis;
        let settings = DiscoverSettings::default();
        let dispersion = std::sync::Arc::new(structid_core::PolynomialDispersion::new(1).unwrap());
        let h = hypothesis(&nominal(), Site::Input, dispersion).unwrap();
        let truth = with_true_mode(0.08);
        let mode = record(&truth, 3);
        assert_eq!(
            leaves_direction_effect(&truth, &h, None, &mode, &settings),
            Some(false)
        );
        // The backlash record: y = G·play(u) + noise, with G itself as the rival.
        let base = record(&nominal(), 4);
        let u = base.u().channel(0);
        let w = Signal::new(1, play(&u, 0.5)).unwrap();
        let clean = nominal().simulate(&w).unwrap();
        let noisy: Vec<f64> = clean
            .iter()
            .zip(
                base.y()
                    .channel(0)
                    .iter()
                    .zip(nominal().simulate(base.u()).unwrap()),
            )
            .map(|(c, (y, g))| c + (y - g))
            .collect();
        let backlash = Data::new(base.u().clone(), Signal::new(1, noisy).unwrap()).unwrap();
        assert_eq!(
            leaves_direction_effect(&nominal(), &h, None, &backlash, &settings),
            Some(true)
        );
    }

    #[test]
    fn start_frequencies_span_the_band_in_order() {
        let f: Vec<f64> = (0..START_FREQUENCIES).map(start_frequency).collect();
        assert!((f[0] - START_BAND.0).abs() < 1e-15);
        assert!((f[START_FREQUENCIES - 1] - START_BAND.1).abs() < 1e-12);
        assert!(f.windows(2).all(|w| w[1] > w[0] && w[1] < 0.5));
    }

    #[test]
    fn a_start_is_g_itself() {
        let g = nominal();
        let s = with_mode(&g, 0.1).unwrap();
        for f in [0.01, 0.07, 0.3] {
            let (a, b) = (
                g.frequency_response(0, f).unwrap(),
                s.frequency_response(0, f).unwrap(),
            );
            assert!((a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9);
        }
    }
}

//! Is the model the same over the whole record? Two probes, one test.
//!
//! - The chosen family is refined by output error on each of S consecutive
//!   segments of the estimation record ([`check_stationarity`]).
//! - A gain w = a·z is refined the same way at the input and at the output of the best model
//!   found, whatever its form ([`drifting_gain`]): a gain that drifts (an actuator or a sensor
//!   whose sensitivity changes with temperature, wear or supply) leaves a gap that a static
//!   block at the right site closes only on average, and that may look like any effect.
//!
//! For parameter j with estimates θ_{s,j} on segments s = 1…S at centred times t_s, the
//! least-squares slope is b̂_j = Σ t_s·θ_{s,j} / Σ t_s². Its variance is estimated from the
//! data themselves: the scatter of the estimates about the trend line, RSS_j/(S − 2), which
//! holds whatever makes segment estimates differ in a stationary system (noise, and the
//! model's misfit under each segment's excitation), floored by the mean squared standard error
//! of the segments' output-error fits (s²·(JᵀJ)⁻¹, each widened by √(V̂/γ̂₀), the ratio of its
//! simulation residual's Newey–West long-run variance to its variance, since that residual is
//! correlated over many samples). Then t_j = b̂_j / √(σ̂_j²/Σ t_s²) has a Student t
//! distribution with S − 2 degrees of freedom under a stationary model. The model is
//! *time-varying* when max_j |t_j| exceeds the t quantile at 1 − α/(2·m·F) for m compared
//! parameters in each of the F families of tests the finding meets (Bonferroni), α being the
//! selection rule's significance level: under a stationary model the chance of that verdict
//! is at most α. Neither test is made when the excitation itself changes over the record
//! ([`excitation_changes`]). A drift moves every
//! segment's estimate the same way and leaves little scatter about the line; a misfit that
//! depends on the excitation moves them at random and leaves as much scatter as slope.

use structid_core::Data;
use structid_core::ExprMap;
use structid_core::validation::comparison::{default_bandwidth, long_run_variance};
use structid_core::validation::distributions::student_t_quantile;

use crate::effects::EffectFit;
use crate::hypotheses::{Hypothesis, Nominal, Site};

use super::fit::{simulated, simulation_errors};
use super::polish::polish;
use super::{Classification, DiscoverSettings, Finding};

/// The most consecutive segments S of the estimation record a model is re-estimated on:
/// eight leave the scatter about a straight trend six degrees of freedom, against which a
/// trend test has useful power (the t quantile at 1 − 0.05/8 is 3.5 with six, 8.9 with two).
pub const SEGMENTS: usize = 8;

/// The fewest segments: four leave the scatter two degrees of freedom.
pub const MIN_SEGMENTS: usize = 4;

/// The fewest samples a segment holds when the record allows more than [`MIN_SEGMENTS`]: the
/// segments' output-error intervals and the long-run variance that widens them are
/// large-sample results, and on shorter stretches they understate the scatter, which the
/// trend test then reads as a drift.
pub const MIN_SEGMENT_SAMPLES: usize = 250;

/// How many segments S the records of `est` are cut into: as many as keep
/// [`MIN_SEGMENT_SAMPLES`] in each segment of the shortest record, between [`MIN_SEGMENTS`]
/// and [`SEGMENTS`].
///
/// ```
/// use structid_core::{Data, Signal};
/// use structid_discover::discover::segment_count;
/// let record = |n: usize| {
///     let s = Signal::from_fn(n, 1, |k, _| (0.1 * k as f64).sin());
///     Data::new(s.clone(), s).unwrap()
/// };
/// assert_eq!(segment_count(&record(1200)), 4); // four segments of 300 samples
/// assert_eq!(segment_count(&record(1500)), 6); // 250 each
/// assert_eq!(segment_count(&record(8000)), 8);
/// ```
pub fn segment_count(est: &Data) -> usize {
    let shortest = est.records().iter().map(Data::len).min().unwrap_or(0);
    (shortest / MIN_SEGMENT_SAMPLES).clamp(MIN_SEGMENTS, SEGMENTS)
}

/// The named family refined on each segment of the estimation record, and the verdict.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Stationarity {
    /// The family refined on each segment, in time order.
    pub segments: Vec<EffectFit>,
    /// The largest |t_j| of a parameter's trend over the segments.
    pub statistic: f64,
    /// The parameter it belongs to (`offset` for the offset).
    pub parameter: String,
    /// The critical value: the Student t quantile (S − 2 degrees of freedom) at
    /// 1 − α/(2·m·F), m parameters compared and F ≤ 2 the families of tests the finding meets
    /// (its family's parameters when it is named, and the probe gains).
    pub critical: f64,
    /// Where the probe sat when it was a gain at another site than the finding's (the gain
    /// drifts there); `None` when the finding's own map was re-estimated.
    pub site: Option<Site>,
    /// Whether the map changes over the record: `statistic > critical`.
    pub time_varying: bool,
}

impl Stationarity {
    /// One sentence for reports.
    pub fn describe(&self) -> String {
        let values: Vec<String> = self
            .segments
            .iter()
            .map(|f| {
                f.parameter(&self.parameter)
                    .map_or_else(|| "—".into(), |p| format!("{:.4e}", p.value))
            })
            .collect();
        let probe = self
            .site
            .map_or_else(String::new, |s| format!(" of a gain at the {}", s.name()));
        format!(
            "{}{probe} over {} consecutive segments of the estimation record: {} (trend t = \
             {:.1} against {:.1} at the selection level): {}",
            self.parameter,
            self.segments.len(),
            values.join(", "),
            self.statistic,
            self.critical,
            if self.time_varying {
                "the map changes over the record"
            } else {
                "no evidence that the map changes"
            }
        )
    }
}

/// The trend test for `fit` at `h` on [`segment_count`] segments of `est` (see the [module
/// documentation](self)); `None` when a segment cannot be refined or simulated, or no
/// parameter can be compared.
pub(super) fn stationarity(
    fit: &EffectFit,
    h: &Hypothesis,
    est: &Data,
    settings: &DiscoverSettings,
) -> Option<Stationarity> {
    let fits: Vec<(EffectFit, f64)> = est
        .segments(segment_count(est))
        .ok()?
        .iter()
        .map(|part| segment_fit(fit, h, part, settings))
        .collect::<Option<_>>()?;
    let names: Vec<String> = fit
        .parameters
        .iter()
        .map(|p| p.name.clone())
        .chain(fit.offset.as_ref().map(|_| "offset".to_string()))
        .collect();
    let mut compared = 0usize;
    let mut worst = (0.0_f64, String::new());
    for name in names {
        let Some(t) = trend_statistic(&fits, &name) else {
            continue;
        };
        compared += 1;
        if t > worst.0 || worst.1.is_empty() {
            worst = (t, name);
        }
    }
    if compared == 0 {
        return None;
    }
    let critical = critical_value(settings.significance, compared, fits.len(), TEST_FAMILIES);
    Some(Stationarity {
        segments: fits.into_iter().map(|(f, _)| f).collect(),
        statistic: worst.0,
        parameter: worst.1,
        critical,
        time_varying: worst.0 > critical,
        site: None,
    })
}

/// |t| of the trend of parameter `name` over the segments' fits, `None` when a segment lacks
/// it or its standard error is not finite.
fn trend_statistic(fits: &[(EffectFit, f64)], name: &str) -> Option<f64> {
    let estimates = fits
        .iter()
        .map(|(f, inflation)| {
            let p = f.parameter(name)?;
            Some((p.value, p.half_width() * inflation / 1.96))
        })
        .collect::<Option<Vec<_>>>()?;
    trend_of(&estimates)
}

/// |t| of the trend of the estimates (value, standard error), in time order (see the [module
/// documentation](self)); `None` when a standard error is not finite or the variance is 0.
fn trend_of(estimates: &[(f64, f64)]) -> Option<f64> {
    let at: Vec<(f64, f64, f64)> = estimates
        .iter()
        .enumerate()
        .map(|(i, &(v, se))| (i as f64, v, se))
        .collect();
    trend_at(&at)
}

/// [`trend_of`] for estimates (position, value, standard error) at the given positions in
/// time: the segments that could be estimated, when others could not.
fn trend_at(estimates: &[(f64, f64, f64)]) -> Option<f64> {
    let s = estimates.len();
    if s < 3
        || estimates
            .iter()
            .any(|(_, v, se)| !v.is_finite() || !se.is_finite())
    {
        return None;
    }
    let se2 = estimates.iter().map(|(_, _, se)| se * se).sum::<f64>() / s as f64;
    let centre = estimates.iter().map(|(t, _, _)| t).sum::<f64>() / s as f64;
    let t: Vec<f64> = estimates.iter().map(|(t, _, _)| t - centre).collect();
    let tt: f64 = t.iter().map(|v| v * v).sum();
    let mean = estimates.iter().map(|(_, v, _)| v).sum::<f64>() / s as f64;
    let slope = t
        .iter()
        .zip(estimates)
        .map(|(t, (_, v, _))| t * v)
        .sum::<f64>()
        / tt;
    let rss: f64 = t
        .iter()
        .zip(estimates)
        .map(|(t, (_, v, _))| (v - mean - slope * t).powi(2))
        .sum();
    let variance = (rss / (s - 2) as f64).max(se2);
    if variance > 0.0 && tt > 0.0 {
        Some(slope.abs() / (variance / tt).sqrt())
    } else {
        None
    }
}

/// √(V̂/γ̂₀), at least 1: how much the serial correlation of a residual widens the standard
/// errors computed as if it were white (V̂ its Newey–West long-run variance, γ̂₀ its variance).
fn inflation(errors: &[f64]) -> f64 {
    let lrv = long_run_variance(errors, default_bandwidth(errors));
    let variance = long_run_variance(errors, 0);
    if variance > 0.0 {
        (lrv / variance).max(1.0).sqrt()
    } else {
        1.0
    }
}

/// `fit` refined on `part`, with the factor √(V̂/γ̂₀) (at least 1) by which its residual's
/// serial correlation widens its intervals; `None` when the refit cannot be named or its
/// simulation fails.
fn segment_fit(
    fit: &EffectFit,
    h: &Hypothesis,
    part: &Data,
    settings: &DiscoverSettings,
) -> Option<(EffectFit, f64)> {
    let data = h.data(part).ok()?;
    let refined = polish(fit, h, &data, settings);
    // A family that output error does not refine (a quantiser's steps) says nothing about
    // its segments.
    if !refined.nameable() || refined.refit.is_none() {
        return None;
    }
    let map = ExprMap::parse(&refined.expression, 1).ok()?;
    let errors = simulation_errors(h, &map, &data, settings);
    if errors.len() < 3 {
        return None;
    }
    Some((refined, inflation(&errors)))
}

/// Re-estimates a named finding's family on consecutive segments of the estimation record
/// ([`stationarity`]); a map that changes over the record makes the finding
/// [`Classification::TimeVarying`].
pub(super) fn check_stationarity(
    finding: &mut Finding,
    nominal: &Nominal,
    est: &Data,
    settings: &DiscoverSettings,
) {
    let Classification::Named(fit) = &finding.classification else {
        return;
    };
    if excitation_changes(est, settings.significance) {
        return;
    }
    let h = augmented_hypothesis(finding, nominal);
    let Some(check) = stationarity(fit, &h, est, settings) else {
        return;
    };
    if check.time_varying {
        finding.remarks.push(format!(
            "the map is not stationary: {}; a static name would describe neither half",
            check.describe()
        ));
        finding.classification = Classification::TimeVarying(fit.clone());
    }
    finding.stationarity = Some(check);
}

/// Why stationarity is not tested on a record whose excitation changes.
const EXCITATION_CHANGES: &str = "the excitation changes over the estimation record (its level \
     or its spectrum follows a trend over the segments): a model that drifts cannot be told from \
     an effect that depends on the excitation, so stationarity was not tested";

/// Whether the input's level or spectrum follows a trend over the [`segment_count`] segments
/// of `est` (a sweep, a ramp of amplitude): the input's RMS and its lag-one autocorrelation
/// (the cosine of its mean frequency, for a narrow band) per segment, each tested for a
/// trend against its scatter about the line as the models' parameters are, at α/2 each.
///
/// A trend test over time is calibrated under a model that describes the effect; under an
/// approximate one (the static map of a hysteresis, a family that bends to another's shape)
/// the misfit, and with it every segment's estimate, moves with the excitation, and an
/// excitation that changes over the record turns that into a trend.
pub(super) fn excitation_changes(est: &Data, alpha: f64) -> bool {
    let Ok(parts) = est.segments(segment_count(est)) else {
        return false;
    };
    let (mut level, mut colour) = (Vec::new(), Vec::new());
    for part in &parts {
        let u = part.u().channel(0);
        let n = u.len() as f64;
        let mean = u.iter().sum::<f64>() / n;
        let var = u.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        let lag1 = u
            .windows(2)
            .map(|w| (w[0] - mean) * (w[1] - mean))
            .sum::<f64>()
            / n;
        level.push((var.sqrt(), 0.0));
        colour.push((if var > 0.0 { lag1 / var } else { 0.0 }, 0.0));
    }
    let critical = student_t_quantile(1.0 - alpha / 4.0, parts.len().max(3) - 2);
    [level, colour]
        .iter()
        .any(|v| trend_of(v).is_some_and(|t| t > critical))
}

/// The most families of tests a finding meets, the chosen family's parameters (a named
/// finding only) and the probe gains: α is shared equally among the families a finding
/// meets, so that a stationary model is called time-varying with a chance of at most α in
/// all (Bonferroni).
const TEST_FAMILIES: usize = 2;

/// Where a probe gain sits in series with the best model found: before it (y ≈ M(a·u)) or
/// after it (y ≈ a·M(u)).
const PROBES: [Site; 2] = [Site::Input, Site::Output];

/// Whether a gain in series with the best model found drifts over the estimation record: the
/// augmented model M of `finding`, with every map it found held as fitted, and a gain a at
/// its input (y ≈ M(a·u)) or its output (y ≈ a·M(u)) refined by its simulation error on
/// each of [`segment_count`] consecutive segments, and the trend of a tested as in
/// [`stationarity`] (one Bonferroni share per site). A segment whose simulation fails is left
/// out, the trend fitted at the places of the others (at least [`MIN_SEGMENTS`]). The most significant drift, with the
/// gain refined on the whole record, or `None` when no gain drifts.
///
/// The probe scales the signals M reads and writes, so it is a model whatever M holds at its
/// input or output. A drift is what the best model leaves, whatever form it chose: an actuator
/// or a sensor whose sensitivity drifts is absorbed on average by G or by a static block.
///
/// `families` is the number of families of tests the finding meets (see [`TEST_FAMILIES`]).
pub(super) fn drifting_gain(
    finding: &Finding,
    nominal: &Nominal,
    est: &Data,
    settings: &DiscoverSettings,
    families: usize,
) -> Option<(EffectFit, Stationarity)> {
    let h = augmented_hypothesis(finding, nominal);
    let map = finding.augmented.map.interpolant().ok()?;
    let parts = est.segments(segment_count(est)).ok()?;
    let mut best: Option<Stationarity> = None;
    for site in PROBES {
        // A segment on which the gain cannot be refined (its simulation fails) is left out;
        // the trend is fitted at the others' places, and needs MIN_SEGMENTS of them.
        let at: Vec<(f64, f64, f64)> = parts
            .iter()
            .enumerate()
            .filter_map(|(i, part)| {
                let (a, se) = series_gain(&h, map.as_ref(), part, site, settings)?;
                Some((i as f64, a, se))
            })
            .collect();
        if at.len() < MIN_SEGMENTS {
            continue;
        }
        let Some(statistic) = trend_at(&at) else {
            continue;
        };
        let fits: Vec<(f64, f64)> = at.iter().map(|&(_, a, se)| (a, se)).collect();
        let critical = critical_value(settings.significance, PROBES.len(), fits.len(), families);
        let check = Stationarity {
            segments: fits.iter().map(|&(a, se)| gain_fit(a, se)).collect(),
            statistic,
            parameter: "gain".into(),
            critical,
            time_varying: statistic > critical,
            site: Some(site),
        };
        if check.time_varying && best.as_ref().is_none_or(|b| statistic > b.statistic) {
            best = Some(check);
        }
    }
    let check = best?;
    let site = check.site?;
    let (a, se) = series_gain(&h, map.as_ref(), est, site, settings)?;
    Some((gain_fit(a, se), check))
}

/// The critical value of a trend's |t| over `segments` segments among `tests` parameters of
/// one of `families` families: the Student t quantile with S − 2 degrees of freedom at
/// 1 − α/(2·`tests`·`families`) (Bonferroni over the tests and the families).
fn critical_value(alpha: f64, tests: usize, segments: usize, families: usize) -> f64 {
    let tests = (tests.max(1) * families.max(1)) as f64;
    student_t_quantile(1.0 - alpha / (2.0 * tests), segments.max(3) - 2)
}

/// A gain `a` with standard error `se`, as an effect fit (its 95 % interval a ± 1.96·se).
fn gain_fit(a: f64, se: f64) -> EffectFit {
    let mut fit = crate::effects::fit_effect_with(
        crate::effects::Effect::Gain,
        false,
        &[-1.0, 1.0],
        &[-a, a],
    )
    .expect("a gain fits two points");
    fit.parameters[0].value = a;
    fit.parameters[0].interval = (a - 1.96 * se, a + 1.96 * se);
    fit
}

/// The probe gain of [`drifting_gain`] at `site`, refined on `part`: its value and its
/// standard error √(s²/ΣJ²), widened by √(V̂/γ̂₀) for the residual's serial correlation as
/// the segments' family fits are. At the output the least-squares gain is in closed form;
/// at the input it is found by Gauss–Newton from a = 1. `None` when a simulation fails.
fn series_gain(
    h: &Hypothesis,
    map: &dyn structid_core::Interpolant,
    part: &Data,
    site: Site,
    settings: &DiscoverSettings,
) -> Option<(f64, f64)> {
    let simulate = |a: f64| -> Option<(Vec<f64>, Vec<f64>)> {
        let data = match site {
            Site::Input => scaled_input(part, a).ok()?,
            _ => part.clone(),
        };
        let v = simulated(h, map, &h.data(&data).ok()?, settings)?;
        let k: Vec<usize> = v.scored.iter().flat_map(|r| r.clone()).collect();
        Some((
            k.iter().map(|&k| v.measured[k]).collect(),
            k.iter().map(|&k| v.simulated[k]).collect(),
        ))
    };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let sse = |y: &[f64], q: &[f64]| y.iter().zip(q).map(|(y, q)| (y - q).powi(2)).sum::<f64>();
    let (y, mut yhat) = simulate(1.0)?;
    // dŷ/da at a, by a forward difference.
    let derivative = |a: f64, at: &[f64]| -> Option<Vec<f64>> {
        let step = 1e-4 * a.abs().max(1e-3);
        let (_, ahead) = simulate(a + step)?;
        Some(ahead.iter().zip(at).map(|(p, q)| (p - q) / step).collect())
    };
    let (a, jacobian) = match site {
        Site::Input => {
            let mut a: f64 = 1.0;
            let mut cost = sse(&y, &yhat);
            for _ in 0..20 {
                let jacobian = derivative(a, &yhat)?;
                let r: Vec<f64> = y.iter().zip(&yhat).map(|(y, q)| y - q).collect();
                let jj = dot(&jacobian, &jacobian);
                if jj <= 0.0 {
                    return None;
                }
                let mut delta = dot(&jacobian, &r) / jj;
                // Halve the step until the cost falls (the map makes the error non-quadratic).
                let mut accepted = false;
                for _ in 0..10 {
                    if let Some((_, trial)) = simulate(a + delta) {
                        let c = sse(&y, &trial);
                        if c <= cost {
                            (a, cost, yhat) = (a + delta, c, trial);
                            accepted = true;
                            break;
                        }
                    }
                    delta *= 0.5;
                }
                if !accepted || delta.abs() <= 1e-8 * a.abs().max(1e-8) {
                    break;
                }
            }
            (a, derivative(a, &yhat)?)
        }
        _ => {
            let a = dot(&yhat, &y) / dot(&yhat, &yhat);
            let unscaled = yhat.clone();
            yhat.iter_mut().for_each(|q| *q *= a);
            (a, unscaled)
        }
    };
    let r: Vec<f64> = y.iter().zip(&yhat).map(|(y, q)| y - q).collect();
    let n = r.len();
    let jj = dot(&jacobian, &jacobian);
    if n < 3 || !a.is_finite() || jj.is_nan() || jj <= 0.0 {
        return None;
    }
    let s2 = dot(&r, &r) / (n - 1) as f64;
    Some((a, (s2 / jj).sqrt() * inflation(&r)))
}

/// `part` with every record's input scaled by `a`.
fn scaled_input(part: &Data, a: f64) -> structid_core::Result<Data> {
    let records = part
        .records()
        .into_iter()
        .map(|r| {
            let u = r.u();
            let scaled = Data::new(
                structid_core::Signal::from_fn(u.len(), u.channels(), |k, c| a * u.get(k, c)),
                r.y().clone(),
            )?;
            match r.z() {
                Some(z) => scaled.with_z(z.clone()),
                None => Ok(scaled),
            }
        })
        .collect::<structid_core::Result<Vec<_>>>()?;
    Data::from_records(records)
}

/// Makes `finding` time-varying when a gain in series with its augmented model drifts
/// ([`drifting_gain`]); whether it did.
pub(super) fn check_drift(
    finding: &mut Finding,
    nominal: &Nominal,
    est: &Data,
    settings: &DiscoverSettings,
) -> bool {
    if excitation_changes(est, settings.significance) {
        finding.remarks.push(EXCITATION_CHANGES.into());
        return false;
    }
    // A finding whose family was tested already shares α with that test (`TEST_FAMILIES`).
    let families = if finding.stationarity.is_some() {
        TEST_FAMILIES
    } else {
        1
    };
    let Some((gain, check)) = drifting_gain(finding, nominal, est, settings, families) else {
        return false;
    };
    if let Some(family) = &finding.stationarity {
        finding.remarks.push(format!(
            "the family's own parameters: {}",
            family.describe()
        ));
    }
    finding.remarks.push(format!(
        "a gain drifts over the estimation record: {}; no static name describes the whole \
         record",
        check.describe()
    ));
    finding.classification = Classification::TimeVarying(gain);
    finding.stationarity = Some(check);
    true
}

/// The hypothesis of a finding's augmented model (its LFT, location and known maps).
pub(super) fn augmented_hypothesis(finding: &Finding, nominal: &Nominal) -> Hypothesis {
    Hypothesis {
        location: finding.location,
        model: finding.augmented.model.clone(),
        sample_time: nominal
            .model()
            .ok()
            .and_then(|m| m.lft().sample_time())
            .unwrap_or(1.0),
        known: finding.augmented.known.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::{Effect, fit_effect};

    fn gain(value: f64, half_width: f64) -> (EffectFit, f64) {
        let z = [-1.0, 0.0, 1.0];
        let w = [-value, 0.0, value];
        let mut f = fit_effect(Effect::Gain, &z, &w).unwrap();
        f.parameters[0].value = value;
        f.parameters[0].interval = (value - half_width, value + half_width);
        (f, 1.0)
    }

    #[test]
    fn a_drift_of_fifteen_percent_over_the_segments_passes_the_critical_value() {
        // Eight segments of a gain falling linearly by 15 %, each known to ±2 % (one standard
        // error): the t statistic is the slope over its standard error, √Σt² · 0.15/7 / 0.02.
        let values: Vec<(f64, f64)> = (0..SEGMENTS)
            .map(|s| (1.0 - 0.15 * s as f64 / (SEGMENTS - 1) as f64, 0.02))
            .collect();
        let t = trend_of(&values).unwrap();
        let tt: f64 = (0..SEGMENTS)
            .map(|i| (i as f64 - 0.5 * (SEGMENTS - 1) as f64).powi(2))
            .sum();
        let expected = 0.15 / (SEGMENTS - 1) as f64 / (0.02 / tt.sqrt());
        assert!((t - expected).abs() < 1e-9 * expected, "{t} {expected}");
        let critical = critical_value(0.05, PROBES.len(), SEGMENTS, TEST_FAMILIES);
        // The quantile at 1 − 0.05/8 with six degrees of freedom (tables: 3.52).
        assert!((critical - 3.5212).abs() < 1e-3, "{critical}");
        assert!(t > critical, "{t} against {critical}");
        // The same values out of time order: no trend beyond the scatter.
        let shuffled: Vec<(f64, f64)> = [3, 6, 0, 5, 2, 7, 1, 4]
            .iter()
            .map(|&i| values[i])
            .collect();
        assert!(trend_of(&shuffled).unwrap() < critical);
    }

    /// With a segment left out, the trend is the least-squares slope at the places of the
    /// others, its standard error from those places: the closed form on the positions
    /// 0, 1, 3, 4, 5 of a gain falling by 0.02 a segment, each known to ±0.01.
    #[test]
    fn a_trend_at_the_places_of_the_segments_that_remain() {
        let places = [0.0, 1.0, 3.0, 4.0, 5.0];
        let at: Vec<(f64, f64, f64)> = places.iter().map(|&t| (t, 1.0 - 0.02 * t, 0.01)).collect();
        let centre = places.iter().sum::<f64>() / 5.0;
        let tt: f64 = places.iter().map(|t| (t - centre).powi(2)).sum();
        let expected = 0.02 / (0.01 / tt.sqrt());
        let t = trend_at(&at).unwrap();
        assert!((t - expected).abs() < 1e-9 * expected, "{t} {expected}");
        // Equally spaced places are trend_of's.
        let even: Vec<(f64, f64)> = (0..5).map(|i| (1.0 - 0.02 * i as f64, 0.01)).collect();
        let on_places: Vec<(f64, f64, f64)> = even
            .iter()
            .enumerate()
            .map(|(i, &(v, se))| (i as f64, v, se))
            .collect();
        assert_eq!(trend_of(&even), trend_at(&on_places));
        // One place only repeated: no trend can be fitted.
        assert_eq!(trend_at(&[(2.0, 1.0, 0.01); 4]), None);
    }

    #[test]
    fn a_sweep_or_a_ramp_changes_the_excitation_and_noise_does_not() {
        let len = 4000;
        let data = |u: Vec<f64>| {
            let sig = |v: &[f64]| structid_core::Signal::from_fn(v.len(), 1, |k, _| v[k]);
            Data::new(sig(&u), sig(&vec![0.0; u.len()])).unwrap()
        };
        // Pseudo-random noise of constant level (a fixed linear congruential sequence).
        let mut x: u64 = 12345;
        let noise: Vec<f64> = (0..len)
            .map(|_| {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        assert!(!excitation_changes(&data(noise.clone()), 0.05));
        // The same noise with a level that grows fourfold.
        let ramp: Vec<f64> = noise
            .iter()
            .enumerate()
            .map(|(k, v)| v * (1.0 + 3.0 * k as f64 / len as f64))
            .collect();
        assert!(excitation_changes(&data(ramp), 0.05));
        // A sine sweep from 0.01 to 0.2 cycles per sample at constant level.
        let sweep: Vec<f64> = (0..len)
            .map(|k| {
                let t = k as f64;
                (std::f64::consts::TAU * (0.01 * t + 0.5 * 0.19 * t * t / len as f64)).sin()
            })
            .collect();
        assert!(excitation_changes(&data(sweep), 0.05));
    }

    #[test]
    fn a_straight_drift_is_a_trend_and_scatter_is_not() {
        // A drift: 1.00, 1.05, 1.10, 1.15 with tight intervals.
        let drift: Vec<_> = (0..4).map(|s| gain(1.0 + 0.05 * s as f64, 0.002)).collect();
        let t = trend_statistic(&drift, "gain").unwrap();
        // No scatter about the line: t = slope / (se/√5) with se = 0.002/1.96.
        let expected = 0.05 / ((0.002f64 / 1.96).powi(2) / 5.0).sqrt();
        assert!((t - expected).abs() < 1e-6 * expected, "{t} {expected}");
        // The same spread without order in time: scatter about the line as large as the slope.
        let scatter: Vec<_> = [1.05, 1.15, 1.0, 1.10]
            .iter()
            .map(|v| gain(*v, 0.002))
            .collect();
        let t = trend_statistic(&scatter, "gain").unwrap();
        assert!(t < student_t_quantile(0.975, 2), "{t}");
    }

    #[test]
    fn a_missing_parameter_or_an_infinite_interval_is_not_compared() {
        let mut fits: Vec<_> = (0..4).map(|s| gain(1.0 + s as f64, 0.1)).collect();
        assert!(trend_statistic(&fits, "level").is_none());
        fits[2].0.parameters[0].interval = (f64::NEG_INFINITY, f64::INFINITY);
        assert!(trend_statistic(&fits, "gain").is_none());
    }
}

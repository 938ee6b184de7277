//! Is the named map the same over the whole record? The chosen family is refined by output
//! error on each of [`SEGMENTS`] consecutive segments of the estimation record, and the trend
//! of each parameter over the segments is tested.
//!
//! For parameter j with estimates θ_{s,j} on segments s = 1…S at centred times t_s, the
//! least-squares slope is b̂_j = Σ t_s·θ_{s,j} / Σ t_s². Its variance is estimated from the
//! data themselves: the scatter of the estimates about the trend line, RSS_j/(S − 2), which
//! holds whatever makes segment estimates differ in a stationary system (noise, and the
//! model's misfit under each segment's excitation), floored by the mean squared standard error
//! of the segments' output-error fits (s²·(JᵀJ)⁻¹, each widened by √(V̂/γ̂₀), the ratio of its
//! simulation residual's Newey–West long-run variance to its variance, since that residual is
//! correlated over many samples). Then t_j = b̂_j / √(σ̂_j²/Σ t_s²) has a Student t
//! distribution with S − 2 degrees of freedom under a stationary map. The map is
//! *time-varying* when max_j |t_j| exceeds the t quantile at 1 − α/(2m) for m compared
//! parameters (Bonferroni), α being the selection rule's significance level: under a
//! stationary map the chance of that verdict is at most α. A drift moves every segment's
//! estimate the same way and leaves little scatter about the line; a misfit that depends on
//! the excitation moves them at random and leaves as much scatter as slope.

use structid_core::Data;
use structid_core::ExprMap;
use structid_core::validation::comparison::{default_bandwidth, long_run_variance};

use crate::effects::EffectFit;
use crate::hypotheses::{Hypothesis, Nominal, Site};

use super::fit::simulation_errors;
use super::polish::polish;
use super::{Classification, DiscoverSettings, Finding};

/// How many consecutive segments of the estimation record the map is re-estimated on: four
/// leave the scatter about a straight trend two degrees of freedom.
pub const SEGMENTS: usize = 4;

/// The named family refined on each segment of the estimation record, and the verdict.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Stationarity {
    /// The family refined on each segment, in time order.
    pub segments: Vec<EffectFit>,
    /// The largest |t_j| of a parameter's trend over the segments.
    pub statistic: f64,
    /// The parameter it belongs to (`offset` for the offset).
    pub parameter: String,
    /// The critical value: the Student t quantile (S − 2 degrees of freedom) at 1 − α/(2m).
    pub critical: f64,
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
        format!(
            "{} over {} consecutive segments of the estimation record: {} (trend t = {:.1} \
             against {:.1} at the selection level): {}",
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

/// The trend test for `fit` at `h` on [`SEGMENTS`] segments of `est` (see the [module
/// documentation](self)); `None` when a segment cannot be refined or simulated, or no
/// parameter can be compared.
pub(super) fn stationarity(
    fit: &EffectFit,
    h: &Hypothesis,
    est: &Data,
    settings: &DiscoverSettings,
) -> Option<Stationarity> {
    let fits: Vec<(EffectFit, f64)> = est
        .segments(SEGMENTS)
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
    let critical = student_t2_quantile(1.0 - settings.significance / (2.0 * compared as f64));
    Some(Stationarity {
        segments: fits.into_iter().map(|(f, _)| f).collect(),
        statistic: worst.0,
        parameter: worst.1,
        critical,
        time_varying: worst.0 > critical,
    })
}

/// |t| of the trend of parameter `name` over the segments' fits, `None` when a segment lacks
/// it or its standard error is not finite.
fn trend_statistic(fits: &[(EffectFit, f64)], name: &str) -> Option<f64> {
    let s = fits.len();
    let mut values = Vec::with_capacity(s);
    let mut se2 = 0.0;
    for (f, inflation) in fits {
        let p = f.parameter(name)?;
        let se = p.half_width() * inflation / 1.96;
        if !se.is_finite() {
            return None;
        }
        values.push(p.value);
        se2 += se * se / s as f64;
    }
    let t: Vec<f64> = (0..s).map(|i| i as f64 - 0.5 * (s - 1) as f64).collect();
    let tt: f64 = t.iter().map(|v| v * v).sum();
    let mean = values.iter().sum::<f64>() / s as f64;
    let slope = t.iter().zip(&values).map(|(t, v)| t * v).sum::<f64>() / tt;
    let rss: f64 = t
        .iter()
        .zip(&values)
        .map(|(t, v)| (v - mean - slope * t).powi(2))
        .sum();
    let variance = (rss / (s - 2) as f64).max(se2);
    if variance > 0.0 {
        Some(slope.abs() / (variance / tt).sqrt())
    } else {
        None
    }
}

/// The quantile of Student's t with two degrees of freedom at probability `p` (closed form:
/// t = (2p − 1)/√(2p(1 − p))).
fn student_t2_quantile(p: f64) -> f64 {
    (2.0 * p - 1.0) / (2.0 * p * (1.0 - p)).sqrt()
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
    let lrv = long_run_variance(&errors, default_bandwidth(&errors));
    let variance = long_run_variance(&errors, 0);
    let inflation = if variance > 0.0 {
        (lrv / variance).max(1.0).sqrt()
    } else {
        1.0
    };
    Some((refined, inflation))
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

/// Whether a gap that no static block closes is a linear part that changes over the record:
/// a gain at the finding's location (w = a·z, from the block's neutral value) re-estimated on
/// consecutive segments
/// of the estimation record ([`stationarity`]). A gain that drifts is
/// absorbed on average by an estimated G, which leaves a residual that no static map
/// explains; the segments' gains follow the drift. When they do, the finding becomes [`Classification::TimeVarying`].
pub(super) fn drifting_linear_part(
    finding: &mut Finding,
    nominal: &Nominal,
    est: &Data,
    settings: &DiscoverSettings,
) -> bool {
    // The block's neutral value: w = z where it passes a signal on (input, output), w = 0
    // where it feeds back.
    let neutral = match finding.location {
        Site::OutputFeedback | Site::RateFeedback => 0.0,
        _ => 1.0,
    };
    let Ok(mut gain) = crate::effects::fit_effect_with(
        crate::effects::Effect::Gain,
        false,
        &[-1.0, 1.0],
        &[-1.0, 1.0],
    ) else {
        return false;
    };
    gain.parameters[0].value = neutral;
    let h = augmented_hypothesis(finding, nominal);
    match stationarity(&gain, &h, est, settings) {
        Some(check) if check.time_varying => {
            finding.remarks.push(format!(
                "no static block closes the gap, and a gain at this location drifts over the \
                 estimation record: {}",
                check.describe()
            ));
            let whole = h
                .data(est)
                .map(|data| polish(&gain, &h, &data, settings))
                .unwrap_or(gain);
            finding.classification = Classification::TimeVarying(whole);
            finding.stationarity = Some(check);
            true
        }
        _ => false,
    }
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
    fn the_t2_quantile_matches_the_tables() {
        // Student t, 2 degrees of freedom: 2.920 at 0.95, 4.303 at 0.975, 9.925 at 0.995.
        for (p, t) in [(0.95, 2.920), (0.975, 4.303), (0.995, 9.925)] {
            assert!((student_t2_quantile(p) - t).abs() < 1e-3, "{p}");
        }
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
        assert!(t < student_t2_quantile(0.975), "{t}");
    }

    #[test]
    fn a_missing_parameter_or_an_infinite_interval_is_not_compared() {
        let mut fits: Vec<_> = (0..4).map(|s| gain(1.0 + s as f64, 0.1)).collect();
        assert!(trend_statistic(&fits, "level").is_none());
        fits[2].0.parameters[0].interval = (f64::NEG_INFINITY, f64::INFINITY);
        assert!(trend_statistic(&fits, "gain").is_none());
    }
}

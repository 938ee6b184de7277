//! Is the model the same over the whole record? Two probes, one test.
//!
//! - The chosen family is refined by output error on each of [`SEGMENTS`] consecutive
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
//! *time-varying* when max_j |t_j| exceeds the t quantile at 1 − α/(2m) for m compared
//! parameters over all probes (Bonferroni), α being the selection rule's significance level:
//! under a stationary model the chance of that verdict is at most α. A drift moves every
//! segment's estimate the same way and leaves little scatter about the line; a misfit that
//! depends on the excitation moves them at random and leaves as much scatter as slope.

use structid_core::Data;
use structid_core::ExprMap;
use structid_core::validation::comparison::{default_bandwidth, long_run_variance};
use structid_core::validation::distributions::student_t_quantile;

use crate::effects::EffectFit;
use crate::hypotheses::{Hypothesis, Nominal, Site};

use super::fit::simulation_errors;
use super::polish::polish;
use super::{Classification, DiscoverSettings, Finding};

/// How many consecutive segments of the estimation record the map is re-estimated on: eight
/// leave the scatter about a straight trend six degrees of freedom, against which a trend
/// test has useful power (the t quantile at 1 − 0.05/8 is 3.7 with six, 7.6 with two).
pub const SEGMENTS: usize = 8;

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

/// The trend test for `fit` at `h` on [`SEGMENTS`] segments of `est` (see the [module
/// documentation](self)); `None` when a segment cannot be refined or simulated, or no
/// parameter can be compared.
///
/// `probes` is the number of such tests made on one model (each a Bonferroni share of α).
pub(super) fn stationarity(
    fit: &EffectFit,
    h: &Hypothesis,
    est: &Data,
    settings: &DiscoverSettings,
    probes: usize,
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
    let tests = (compared * probes.max(1)) as f64;
    let critical = student_t_quantile(1.0 - settings.significance / (2.0 * tests), SEGMENTS - 2);
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
    let Some(check) = stationarity(fit, &h, est, settings, 1) else {
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

/// Whether a linear part of `model` drifts over the estimation record: a gain w = a·z at
/// each of `sites` (from the block's neutral value: a = 1 where it passes a signal on, 0
/// where it feeds back) re-estimated on [`SEGMENTS`] consecutive segments ([`stationarity`],
/// one Bonferroni share per site). The most significant drift, with the gain refined on the
/// whole record, or `None` when no gain drifts.
///
/// `model` is the best model found (the augmented model of a finding, or the nominal one when
/// no block closes the gap): a drift is what that model leaves, whatever form it chose.
pub(super) fn drifting_gain(
    model: &Nominal,
    sites: &[Site],
    est: &Data,
    settings: &DiscoverSettings,
) -> Option<(EffectFit, Stationarity)> {
    let dispersion: std::sync::Arc<dyn structid_core::Dispersion> =
        std::sync::Arc::new(structid_core::PolynomialDispersion::new(1).ok()?);
    let mut best: Option<(EffectFit, Stationarity, Hypothesis)> = None;
    for &site in sites {
        let neutral = match site {
            Site::OutputFeedback | Site::RateFeedback => 0.0,
            _ => 1.0,
        };
        let Ok(mut gain) = crate::effects::fit_effect_with(
            crate::effects::Effect::Gain,
            false,
            &[-1.0, 1.0],
            &[-1.0, 1.0],
        ) else {
            continue;
        };
        gain.parameters[0].value = neutral;
        let Ok(h) = model.hypothesis(site, std::sync::Arc::clone(&dispersion)) else {
            continue;
        };
        let Some(mut check) = stationarity(&gain, &h, est, settings, sites.len()) else {
            continue;
        };
        check.site = Some(site);
        let margin = check.statistic / check.critical;
        if check.time_varying
            && best
                .as_ref()
                .is_none_or(|(_, b, _)| margin > b.statistic / b.critical)
        {
            best = Some((gain, check, h));
        }
    }
    let (gain, check, h) = best?;
    let whole = h
        .data(est)
        .map(|data| polish(&gain, &h, &data, settings))
        .unwrap_or(gain);
    Some((whole, check))
}

/// Makes `finding` time-varying when a gain of `model` drifts at one of `sites` (those of
/// them where `model` has a location) or at its input or output ([`drifting_gain`]); whether
/// it did.
pub(super) fn check_drift(
    finding: &mut Finding,
    model: &Nominal,
    sites: &[Site],
    est: &Data,
    settings: &DiscoverSettings,
) -> bool {
    let available = model.locations();
    let mut probes: Vec<Site> = Vec::new();
    for &s in sites.iter().chain(&[Site::Input, Site::Output]) {
        if !probes.contains(&s) && available.contains(&s) {
            probes.push(s);
        }
    }
    let sites = probes;
    let Some((gain, mut check)) = drifting_gain(model, &sites, est, settings) else {
        return false;
    };
    if check.site == Some(finding.location) {
        check.site = None;
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

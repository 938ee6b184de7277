//! The verdict stage of [`discover`](super::discover): whether the finding confirms a missing
//! effect, and the paragraph that says what was found, or why nothing was.

use crate::gap::{Gap, SPIKE};

use super::context::Context;
use super::fit::simulation_errors;
use super::linear_rival::{self, LinearRival};
use super::naming::verdict_text;
use super::stationarity::{augmented_hypothesis, check_drift, check_stationarity};
use super::{
    Classification, Discovery, FEEDBACK_HYSTERESIS_SHARE, Finding, HypothesisResult,
    MIN_CONFIRMING_SHRINK, NoiseLevel, PARTIAL_SHRINK, PAST_DISTURBANCE_SHRINK,
    UNLOCATED_DIRECTION_EFFECT, Verdict, rms_text,
};

/// The verdict when the nominal model's gap passes every test (see
/// [`Context::past_disturbance`] for the one exception that reaches the hypotheses).
pub(super) fn no_missing_effect(cx: &Context<'_>) -> String {
    format!(
        "no missing effect detected: on the estimation record {}; on the validation record {}",
        cx.estimation_gap.verdict, cx.validation_gap.verdict
    )
}

/// The verdict when no hypothesis could be identified and simulated.
pub(super) fn nothing_identified(cx: &Context<'_>, hypotheses: &[HypothesisResult]) -> String {
    format!(
        "{}: the nominal model's gap is not noise ({}), but no hypothesis could be identified \
         and simulated: {}{}",
        Verdict::Unexplained.describe(),
        cx.validation_gap.verdict,
        hypotheses
            .iter()
            .filter_map(|h| h
                .failure
                .as_ref()
                .map(|f| format!("{}: {f}", cx.nominal.key(h.location))))
            .collect::<Vec<_>>()
            .join("; "),
        cancelled_text(cx)
    )
}

fn cancelled_text(cx: &Context<'_>) -> String {
    cx.cancelled
        .as_deref()
        .map(|c| format!(". {c}"))
        .unwrap_or_default()
}

/// Confirmation and the verdict. A failed test that no static block at any candidate location
/// can act on is not reported as a missing effect: the portmanteau family errs 0.1 % of the
/// time on stationary inputs, more on strongly non-stationary ones such as chirps, whose
/// squares a low-order prewhitening cannot whiten. A block must shrink the validation gap by
/// [`MIN_CONFIRMING_SHRINK`] ([`PAST_DISTURBANCE_SHRINK`] past a fitted input disturbance),
/// unless it is a direction effect on a real gap, or a gain that drifts.
pub(super) fn confirm(
    cx: Context<'_>,
    mut finding: Finding,
    hypotheses: Vec<HypothesisResult>,
    mut noise: NoiseLevel,
) -> Discovery {
    for (g, record) in [
        (&finding.augmented.estimation_gap, "estimation"),
        (&finding.augmented.validation_gap, "validation"),
    ] {
        noise.tighten(g.noise, || {
            format!(
                "the augmented model ({} {}) on the {record} record",
                finding.classification.describe(),
                cx.nominal.describe(finding.location)
            )
        });
    }
    let settings = &cx.settings;
    // The simulation RMS against the output noise level: both of the output, whatever noise
    // path the model has. Isolated spikes (outliers of the measurement) are left out: a gap
    // they alone carry is not a missing effect.
    let above_noise = |g: &Gap| g.bulk_rms(noise.std).0 > settings.gap.noise_ratio * noise.std;
    let real = above_noise(&cx.estimation_gap) || above_noise(&cx.validation_gap);
    // A hysteresis is found by its direction effect, not by what a static approximation of
    // it gains: at a sensor a static map closes almost none of a backlash's gap. At the input
    // and the sensor, whose z (u, or G·u) carries no output noise, a real gap with a
    // direction effect is a missing (dynamic) effect whatever the shrink. In feedback z is
    // the noisy measured output, and a biased G in a loop leaves direction effects of its
    // own, so there the shrink must confirm it as it confirms a static map, unless the
    // direction explains a large share of the residual ([`FEEDBACK_HYSTERESIS_SHARE`]).
    let dynamic_found = real
        && finding.classification == Classification::Dynamic
        && (matches!(
            finding.location,
            crate::hypotheses::Site::Input | crate::hypotheses::Site::Output
        ) || finding.direction.explained >= FEEDBACK_HYSTERESIS_SHARE);
    let confirming = if cx.past_disturbance {
        PAST_DISTURBANCE_SHRINK
    } else {
        MIN_CONFIRMING_SHRINK
    };
    let gap_level = settings.gap.noise_ratio * noise.std;
    if finding.shrink < confirming
        && !dynamic_found
        && !(real && check_drift(&mut finding, &cx.nominal, cx.est, settings))
    {
        let (kind, verdict) = unconfirmed(&cx, &finding, &hypotheses, &noise, real);
        let rival = (kind == Verdict::Unexplained)
            .then(|| rival(&cx, None, gap_level))
            .flatten();
        return match rival {
            Some(r) if r.explains => linear_model(cx, r, None, hypotheses, noise, gap_level),
            rival => {
                let mut d = cx.discovery(kind, noise, hypotheses, None, verdict);
                d.linear_rival = rival;
                d
            }
        };
    }
    let rival = rival(&cx, Some(&finding), gap_level);
    if let Some(r) = rival.clone().filter(|r| r.explains) {
        return linear_model(cx, r, Some(&finding), hypotheses, noise, gap_level);
    }
    if let Some(c) = cx.cancelled.clone() {
        finding.remarks.push(c);
    }
    check_stationarity(&mut finding, &cx.nominal, cx.est, settings);
    // Whatever static form was chosen, a linear part that drifts under it makes the effect
    // time-varying. A hysteresis fitted at the input is the chosen model itself, not a static
    // block beside which a gain could drift: the probe's static model is not the one chosen.
    if !matches!(finding.classification, Classification::TimeVarying(_))
        && finding.input_hysteresis.is_none()
    {
        check_drift(&mut finding, &cx.nominal, cx.est, settings);
    }
    let verdict = confirmed(&cx, &mut finding, &noise);
    let mut d = cx.discovery(
        Verdict::MissingEffect,
        noise,
        hypotheses,
        Some(finding),
        verdict,
    );
    d.linear_rival = rival;
    d
}

/// G alone re-estimated with one more mode, judged against the finding (see
/// [`linear_rival`](super::linear_rival)), its initial state handled as the finding's is;
/// `None` for a nominal model without a polynomial G, when the refit fails, or for a finding
/// the rival cannot overrule, where it is not fitted at all: a hysteresis at the input (a
/// fitted operator, not a static approximation) and a gain, itself the linear model's
/// correction (its verdict already says the linear model was wrong). A dynamic finding (a
/// direction effect) is judged by the direction effect the rival's own residual leaves.
fn rival(cx: &Context<'_>, finding: Option<&Finding>, gap_level: f64) -> Option<LinearRival> {
    use crate::hypotheses::Site;
    let exempt = |f: &Finding| {
        let gain = matches!(&f.classification,
            Classification::Named(fit) if fit.effect == crate::effects::Effect::Gain);
        f.input_hysteresis.is_some() || gain
    };
    if finding.is_some_and(exempt) {
        return None;
    }
    let g = cx.given.polynomial()?;
    let location = finding.map_or(Site::Input, |f| f.location);
    let fitted = linear_rival::fit(g, cx.est, cx.val, &cx.settings, location)?;
    if let Some(f) = finding.filter(|f| f.classification == Classification::Dynamic) {
        let h = augmented_hypothesis(f, &cx.nominal);
        let map = f.augmented.map.interpolant().ok();
        let left = linear_rival::leaves_direction_effect(
            &fitted.0,
            &h,
            map.as_deref(),
            cx.est,
            &cx.settings,
        );
        return Some(linear_rival::judge_dynamic(fitted, left, gap_level));
    }
    let errors = finding.map(|f| {
        let h = augmented_hypothesis(f, &cx.nominal);
        let Ok(map) = f.augmented.map.interpolant() else {
            return Vec::new();
        };
        h.data(cx.val).map_or_else(
            |_| Vec::new(),
            |data| simulation_errors(&h, map.as_ref(), &data, &cx.settings),
        )
    });
    Some(linear_rival::judge(
        fitted,
        errors.as_deref(),
        gap_level,
        cx.settings.significance,
    ))
}

/// The verdict "the linear model was wrong" from the rival G that closes the gap.
fn linear_model(
    cx: Context<'_>,
    rival: LinearRival,
    finding: Option<&Finding>,
    hypotheses: Vec<HypothesisResult>,
    noise: NoiseLevel,
    gap_level: f64,
) -> Discovery {
    // The rival overrules a static finding through the paired test, a dynamic one through
    // the direction effect it leaves (see `linear_rival`).
    let block = match (finding, &rival.comparison) {
        (Some(f), Some(c)) => format!(
            ", and the best block ({} {}, validation RMS {}) is not better than it (paired test \
             over {} blocks of the validation record: p = {:.3} that the block is better, at \
             α = {})",
            f.classification.describe(),
            cx.nominal.describe(f.location),
            rms_text(f.augmented.validation_gap.rms),
            c.blocks,
            1.0 - c.p_worse,
            cx.settings.significance
        ),
        (Some(f), None) if rival.leaves_direction_effect == Some(false) => format!(
            ", and its own residual leaves no direction effect at {}, where the best block \
             (validation RMS {}) was called dynamic for one",
            cx.nominal.describe(f.location),
            rms_text(f.augmented.validation_gap.rms),
        ),
        _ => String::new(),
    };
    let verdict = format!(
        "{} (G lacks a mode, not a nonlinearity): G re-estimated alone with {} poles instead \
         of {} validates at RMS {}, within the noise level ({}·σ̂ = {}, σ̂ = {}; the nominal \
         model: {}){block}. Re-estimate G with a higher order, then look for a missing effect \
         again",
        Verdict::LinearModel.describe(),
        rival.g.den.len().saturating_sub(1),
        cx.given
            .polynomial()
            .map_or(0, |g| g.den.len().saturating_sub(1)),
        rms_text(rival.validation_rms),
        cx.settings.gap.noise_ratio,
        rms_text(gap_level),
        rms_text(noise.std),
        rms_text(cx.validation_gap.rms),
    );
    let mut d = cx.discovery(Verdict::LinearModel, noise, hypotheses, None, verdict);
    d.linear_rival = Some(rival);
    d
}

/// The verdict on a confirmed finding. A block that closes a sliver of a large gap is a
/// missing effect, but not the whole story: the verdict must not read as if the model were
/// now complete ([`PARTIAL_SHRINK`]).
fn confirmed(cx: &Context<'_>, finding: &mut Finding, noise: &NoiseLevel) -> String {
    let mut verdict = verdict_text(&cx.nominal, &cx.validation_gap, finding);
    if let Some(h) = &finding.input_hysteresis {
        verdict.push_str(&format!(
            "; {}, with G re-estimated, validates at RMS {} ({})",
            h.describe(),
            rms_text(h.validation_rms),
            crate::gap::shrink_text(cx.validation_gap.rms / h.validation_rms, 1)
        ));
    }
    let left = finding.augmented.validation_gap.rms / noise.std;
    if finding.shrink < PARTIAL_SHRINK && left > cx.settings.gap.noise_ratio {
        let partial = format!(
            "the block explains only part of the gap: the augmented model still misses the \
             validation record by {left:.1}× the noise level σ̂ = {}; another effect, or a \
             dynamic one, remains",
            rms_text(noise.std)
        );
        verdict.push_str(&format!(". Only part of the gap: {partial}"));
        finding.remarks.push(partial);
        if finding.classification == Classification::Dynamic {
            finding.remarks.push(UNLOCATED_DIRECTION_EFFECT.to_string());
        }
    }
    let g = &finding.augmented.validation_gap;
    let gap_level = cx.settings.gap.noise_ratio * noise.std;
    if let Some(r2) = poor_model(&g.residual, &g.simulated, &g.scored, gap_level) {
        let poor = format!(
            "the best model found is still a poor model: on the validation record it explains \
             {:.0} % of the output's variance about its mean (R² = {r2:.2}, below {:.0} %) and \
             misses it by more than the noise; the effect lies beyond the forms tried, or the \
             nominal model is far from the plant",
            100.0 * r2.max(0.0),
            100.0 * POOR_MODEL_R2
        );
        verdict.push_str(&format!(". A poor model: {poor}"));
        finding.remarks.push(poor);
        finding.poor_model = true;
    }
    verdict
}

/// The share of the output's variance a model must explain not to be called poor: a model
/// that leaves more than half of it unexplained says less about the output than it leaves
/// unsaid (R² < 1/2, a fit below 29 %).
pub const POOR_MODEL_R2: f64 = 0.5;

/// Whether a model with simulation residual `residual` and simulated output `simulated` (the
/// measured output is their sum) is a poor model on the `scored` stretches: it explains less
/// than [`POOR_MODEL_R2`] of the output's variance about its mean on each stretch, and its RMS
/// error exceeds `gap_level` (above the noise, so that a record whose output is mostly noise
/// does not make the true model poor). Its R² when poor, `None` otherwise. The shrink of a gap
/// says how much better a model is than the nominal one; this says whether it predicts the
/// output at all.
pub(super) fn poor_model(
    residual: &[f64],
    simulated: &[f64],
    scored: &[std::ops::Range<usize>],
    gap_level: f64,
) -> Option<f64> {
    let (mut total, mut left, mut n) = (0.0, 0.0, 0usize);
    for r in scored {
        let r = r.start.min(residual.len())..r.end.min(residual.len()).min(simulated.len());
        if r.is_empty() {
            continue;
        }
        let mean = r.clone().map(|k| residual[k] + simulated[k]).sum::<f64>() / r.len() as f64;
        total += r
            .clone()
            .map(|k| (residual[k] + simulated[k] - mean).powi(2))
            .sum::<f64>();
        left += residual[r.clone()].iter().map(|e| e * e).sum::<f64>();
        n += r.len();
    }
    if n == 0 || total <= 0.0 {
        return None;
    }
    let r2 = 1.0 - left / total;
    let rms = (left / n as f64).sqrt();
    (r2 < POOR_MODEL_R2 && rms > gap_level).then_some(r2)
}

/// The verdict when no block confirms the gap: the gap is what a fitted input disturbance
/// leaves, or it is larger than the noise (`real`) and unexplained, or it is noise-sized and
/// only a test failed (a false alarm of the test family).
fn unconfirmed(
    cx: &Context<'_>,
    finding: &Finding,
    hypotheses: &[HypothesisResult],
    noise: &NoiseLevel,
    real: bool,
) -> (Verdict, String) {
    let (est_gap, val_gap) = (&cx.estimation_gap, &cx.validation_gap);
    let best = format!(
        "{} {}",
        finding.classification.describe(),
        cx.nominal.describe(finding.location)
    );
    let (before, after) = (
        rms_text(val_gap.rms),
        rms_text(finding.augmented.validation_gap.rms),
    );
    let percent = |shrink: f64| 100.0 * (1.0 - 1.0 / shrink);
    if cx.past_disturbance {
        return (
            Verdict::NoMissingEffect,
            format!(
                "no missing effect detected: with the input disturbance fitted to the nominal \
                 model's residual (ratio {:.3e}) its innovations pass every test (estimation \
                 record: {}; validation record: {}); the simulation gap ({before}, {:.1}× the \
                 noise level σ̂ = {}) is what that disturbance leaves, and the best candidate \
                 block ({best}) reduces the validation RMS by less than {:.0} % ({before} → \
                 {after}). Tried: {}",
                cx.input_noise.unwrap_or(f64::NAN),
                est_gap.verdict,
                val_gap.verdict,
                val_gap.rms / noise.std,
                rms_text(noise.std),
                percent(PAST_DISTURBANCE_SHRINK),
                tried(cx, hypotheses)
            ),
        );
    }
    if real {
        return (
            Verdict::Unexplained,
            format!(
                "{}: the nominal model's gap is larger than the noise (validation record: {}), \
                 but the best candidate block ({best}) reduces the validation RMS by less than \
                 {:.0} % ({before} → {after}). Tried: {}{}",
                Verdict::Unexplained.describe(),
                val_gap.verdict,
                percent(MIN_CONFIRMING_SHRINK),
                tried(cx, hypotheses),
                cancelled_text(cx)
            ),
        );
    }
    let spikes = est_gap.bulk_rms(noise.std).1 + val_gap.bulk_rms(noise.std).1;
    let outliers = if spikes > 0 {
        format!(
            " (without {spikes} isolated samples beyond {SPIKE}·σ̂ from their neighbours: \
             outliers of the measurement, which no missing effect explains)"
        )
    } else {
        String::new()
    };
    (
        Verdict::NoMissingEffect,
        format!(
            "no missing effect detected: the nominal model's gap is within the noise level{outliers} \
             but failed a test (estimation record: {}; validation record: {}), and the best \
             candidate block reduces the validation RMS by less than {:.0} % ({best}, RMS \
             {before} → {after})",
            est_gap.verdict,
            val_gap.verdict,
            percent(MIN_CONFIRMING_SHRINK),
        ),
    )
}

/// Every hypothesis tried, with its estimator and validation RMS or failure.
fn tried(cx: &Context<'_>, hypotheses: &[HypothesisResult]) -> String {
    hypotheses
        .iter()
        .map(|h| {
            format!(
                "{} ({}): {}",
                cx.nominal.key(h.location),
                if h.dispersion.starts_with("tv") {
                    "total variation"
                } else {
                    "quadratic"
                },
                h.failure
                    .clone()
                    .unwrap_or_else(|| format!("validation RMS {}", rms_text(h.validation_rms)))
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod poor_model_tests {
    use super::poor_model;

    /// A deterministic output: two sines and a slow trend.
    fn output(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let t = k as f64;
                (0.05 * t).sin() + 0.5 * (0.31 * t).cos() + 0.2 * (0.003 * t).sin()
            })
            .collect()
    }

    #[test]
    fn a_model_that_predicts_nothing_is_poor_and_a_close_one_is_not() {
        let y = output(2000);
        let scored = [std::ops::Range {
            start: 0,
            end: 2000,
        }];
        // ŷ = 0.01·y, a model whose output is almost zero: R² ≈ 0.02, far above the noise.
        let small: Vec<f64> = y.iter().map(|v| 0.01 * v).collect();
        let r: Vec<f64> = y.iter().zip(&small).map(|(y, s)| y - s).collect();
        let r2 = poor_model(&r, &small, &scored, 0.01).expect("poor");
        let mean = y.iter().sum::<f64>() / y.len() as f64;
        let total: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
        let left: f64 = r.iter().map(|e| e * e).sum();
        assert!((r2 - (1.0 - left / total)).abs() < 1e-12);
        // ŷ = y − e with a small, fast error e: R² near 1.
        let e: Vec<f64> = (0..y.len())
            .map(|k| 0.01 * (1.7 * k as f64).sin())
            .collect();
        let yhat: Vec<f64> = y.iter().zip(&e).map(|(y, e)| y - e).collect();
        assert!(poor_model(&e, &yhat, &scored, 0.001).is_none());
        // Half the output: R² about 0.75, not poor.
        let half: Vec<f64> = y.iter().map(|v| 0.5 * v).collect();
        assert!(poor_model(&half, &half, &scored, 0.01).is_none());
        // A record that is mostly noise: the poor R² is all noise, below the gap level.
        assert!(poor_model(&r, &small, &scored, 10.0).is_none());
    }
}

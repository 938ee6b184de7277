//! Naming the effect: family ranking, structural remarks, the augmented model and the
//! verdict.

use structid_core::{Data, Error, ExprMap, Result};

use crate::effects::{Effect, EffectFit, Naming, NamingSettings, name_effect};
use crate::gap::{Gap, GapSettings, gap};
use crate::hypotheses::{Location, Nominal};
use crate::hysteresis::DirectionTest;

use super::fit::{Fitted, simulation_rms};
use super::fit::{even_indices, minmax, scoring_settings};
use super::polish::polish;
use super::{Augmented, AugmentedMap, Classification, DiscoverSettings, Finding};

/// Remarks and equivalent locations for a named effect.
pub(super) fn structural_remarks(
    location: Location,
    class: &Classification,
) -> (Vec<Location>, Vec<String>) {
    let mut remarks = Vec::new();
    let mut equivalent = vec![location];
    if let Classification::Named(fit) = class {
        let io = matches!(location, Location::Input | Location::Output);
        match fit.effect {
            Effect::Gain => {
                remarks.push(
                    "a gain error means the linear model was wrong: re-estimate G rather than \
                     adding a map"
                        .into(),
                );
                if io {
                    remarks.push(
                        "a gain at the input and one at the output are the same model for a \
                         linear G"
                            .into(),
                    );
                    equivalent = vec![Location::Input, Location::Output];
                }
            }
            Effect::Offset if io => {
                remarks.push(
                    "an offset at the input and one at the output are the same model up to \
                     G's static gain"
                        .into(),
                );
                equivalent = vec![Location::Input, Location::Output];
            }
            _ => {}
        }
        if matches!(location, Location::OutputFeedback | Location::RateFeedback)
            && fit
                .parameter("a1")
                .or_else(|| fit.parameter("viscous"))
                .is_some()
        {
            remarks.push(
                "the linear part of a feedback map trades off against G's denominator \
                 (F + k·B with N − k·z): it is determined here because G is held at the nominal \
                 model"
                    .into(),
            );
        }
    }
    (equivalent, remarks)
}

pub(super) fn non_smooth(effect: Effect) -> bool {
    matches!(
        effect,
        Effect::Saturation
            | Effect::AsymmetricSaturation
            | Effect::DeadZone
            | Effect::CoulombViscous
            | Effect::Stribeck
            | Effect::Quantisation
    )
}

pub(super) fn naming_settings(settings: &DiscoverSettings) -> NamingSettings {
    NamingSettings {
        library: settings.library.clone(),
        noise_std: None,
        tolerance: 1.5,
    }
}

pub(super) fn subsample(z: &[f64], w: &[f64], max: usize) -> (Vec<f64>, Vec<f64>) {
    let idx = even_indices(z.len(), max);
    (
        idx.iter().map(|&k| z[k]).collect(),
        idx.iter().map(|&k| w[k]).collect(),
    )
}

/// The families of `naming` in the order they are offered for naming: those whose map fit is within 25 %
/// of the best family's RMS, fewest parameters first, then the rest by BIC.
///
/// The points (z_k, ŵ_k) are a smoothed estimate, not independent noisy samples, so BIC alone
/// rewards families that bend to the estimate's artefacts (a Stribeck curve for a gain, an
/// asymmetric saturation for a symmetric one). A family with fewer parameters that fits
/// about as well is the better name.
pub fn parsimonious(naming: &Naming) -> Vec<EffectFit> {
    let best = naming
        .ranked
        .iter()
        .map(|f| f.rms)
        .fold(f64::INFINITY, f64::min);
    let near = |f: &EffectFit| f.rms <= 1.25 * best + 1e-12;
    let mut first: Vec<EffectFit> = naming.ranked.iter().filter(|f| near(f)).cloned().collect();
    first.sort_by(|a, b| {
        a.parameters
            .len()
            .cmp(&b.parameters.len())
            .then(a.rms.total_cmp(&b.rms))
    });
    first.extend(naming.ranked.iter().filter(|f| !near(f)).cloned());
    first
}

pub(super) fn verdict_text(nominal: &Nominal, before: &Gap, f: &Finding) -> String {
    let what = match &f.classification {
        Classification::Named(fit) => {
            let params = fit
                .parameters
                .iter()
                .map(|p| format!("{} = {:.4}", p.name, p.value))
                .collect::<Vec<_>>()
                .join(", ");
            format!("{} ({params})", fit.effect.name())
        }
        other => other.describe(),
    };
    format!(
        "missing effect: {what}, {}; validation RMS {:.4e} → {:.4e} ({:.1}× smaller), fit {:.1} % → {:.1} %",
        nominal.describe(f.location),
        before.rms,
        f.augmented.validation_gap.rms,
        f.shrink,
        before.fit_percent,
        f.augmented.validation_gap.fit_percent
    )
}

#[allow(clippy::too_many_arguments)]
pub(super) fn name_and_add(
    best: Fitted,
    direction: DirectionTest,
    total_variation_rms: Option<f64>,
    est: &Data,
    val: &Data,
    est_candidates: &[(String, Vec<f64>)],
    val_candidates: &[(String, Vec<f64>)],
    gap_settings: &GapSettings,
    before: &Gap,
    settings: &DiscoverSettings,
) -> Result<Finding> {
    let location = best.result.location;
    let h = best.hypothesis.clone();
    let val_h = h.data(val)?;
    let est_h = h.data(est)?;
    let (zs, ws) = subsample(&best.z, &best.w_hat, settings.naming_points);
    let mut naming = name_effect(&zs, &ws, &naming_settings(settings))
        .map_err(|e| Error::Numerical(format!("naming the effect: {e}")))?;
    naming.ranked = parsimonious(&naming);
    let nonparametric_rms = best.result.validation_rms;

    let noise = before.noise_std;
    let mut family_rms: Vec<Option<f64>> = vec![None; naming.ranked.len()];
    let mut classification = Classification::Unnamed;
    if direction.dynamic {
        classification = Classification::Dynamic;
    } else {
        // The first three families in parsimonious order are refined and simulated. The
        // simplest that validates within the tolerance is named, unless a richer one that
        // also does cuts its validation RMS by a fifth (a Stribeck hump is a Coulomb level
        // plus something the data can see).
        let mut chosen: Option<(usize, f64)> = None;
        for i in 0..naming.ranked.len().min(3) {
            let fit = polish(&naming.ranked[i], &h, &est_h, settings);
            naming.ranked[i] = fit.clone();
            let Ok(m) = ExprMap::parse(&fit.expression, 1) else {
                continue;
            };
            let rms = simulation_rms(&h.model, location, &m, &val_h, settings);
            family_rms[i] = Some(rms);
            let passes = rms <= settings.naming_tolerance * nonparametric_rms || rms <= 1.5 * noise;
            chosen = match chosen {
                None if passes => Some((i, rms)),
                Some((_, best)) if passes && rms < 0.8 * best => Some((i, rms)),
                other => other,
            };
        }
        if let Some((i, _)) = chosen {
            classification = Classification::Named(naming.ranked[i].clone());
        }
    }
    naming.named = match &classification {
        Classification::Named(fit) => Some(fit.clone()),
        _ => None,
    };
    let (equivalent_locations, mut remarks) = structural_remarks(location, &classification);
    match &classification {
        Classification::Named(_) => {}
        Classification::Unnamed => remarks.push(format!(
            "no family validates within {}× the nonparametric map's RMS (best: {}), so the \
             map is kept as a table",
            settings.naming_tolerance,
            naming
                .ranked
                .first()
                .map(|f| f.effect.name())
                .unwrap_or_else(|| "none".into())
        )),
        Classification::Dynamic => remarks.push(format!(
            "the direction of z explains {:.0} % of the deconvolved residual (t = {:.1}): the \
             effect is not static; the augmented model carries the best static approximation \
             as a table",
            100.0 * direction.explained,
            direction.t_statistic
        )),
    }
    let augmented_map = match &classification {
        Classification::Named(fit) => AugmentedMap::Expression(fit.expression.clone()),
        _ => {
            let (lo, hi) = minmax(&best.z);
            let pad = 0.25 * (hi - lo);
            let n = settings.table_points;
            let z: Vec<f64> = (0..n)
                .map(|i| lo - pad + (hi - lo + 2.0 * pad) * i as f64 / (n - 1) as f64)
                .collect();
            let w = z.iter().map(|z| best.map.eval(&[*z])).collect();
            AugmentedMap::Table { z, w }
        }
    };
    let interp = augmented_map.interpolant()?;
    let gap_settings = &GapSettings {
        initial_state: scoring_settings(location, settings).initial_state(),
        ..gap_settings.clone()
    };
    let estimation_gap = gap(
        &h.model,
        &[interp.as_ref()],
        &est_h,
        est_candidates,
        gap_settings,
    )?;
    let validation_gap = gap(
        &h.model,
        &[interp.as_ref()],
        &val_h,
        val_candidates,
        gap_settings,
    )?;
    let shrink = before.rms / validation_gap.rms;
    Ok(Finding {
        location,
        hypothesis: best.result.clone(),
        equivalent_locations,
        estimator: best.estimator.to_string(),
        nonparametric_rms,
        total_variation_rms,
        naming,
        family_rms,
        direction,
        classification,
        remarks,
        augmented: Augmented {
            location,
            model: h.model.clone(),
            map: augmented_map,
            estimation_gap,
            validation_gap,
        },
        shrink,
    })
}

//! The locating stage of [`discover`](super::discover): which estimate of the candidates
//! stage becomes the finding, by its validation RMS and the direction dependence of what it
//! leaves; then a hysteresis at the input when no static block closes the gap, and a named map
//! elsewhere when the finding names nothing, does not confirm itself or explains only part of
//! the gap.

use crate::hypotheses::Site;
use crate::hysteresis::DirectionTest;

use super::context::Context;
use super::direction::direction_test;
use super::fit::{Fitted, by_validation};
use super::naming::{Memory, name_and_add};
use super::{
    ALTERNATIVE_FACTOR, ALTERNATIVE_LOCATIONS, Classification, DIRECTION_WITHIN, DiscoverSettings,
    Finding, HYSTERESIS_OVER_STATIC, NoiseLevel, NominalRefinement, Result,
    SENSOR_HYSTERESIS_SHARE, STATIC_OVER_DYNAMIC, input_hysteresis, rate_explains, rms_text,
};

/// The direction test of every fit that explains the data about as well as the best
/// ([`DIRECTION_WITHIN`]): a hysteresis may be best approximated statically at a location
/// other than its own. `fitted` is in order of validation RMS.
pub(super) fn directions(
    fitted: &[Fitted],
    settings: &DiscoverSettings,
) -> Vec<Option<DirectionTest>> {
    let best_rms = fitted
        .first()
        .map_or(f64::INFINITY, |f| f.result.validation_rms);
    fitted
        .iter()
        .map(|f| {
            if f.result.validation_rms <= DIRECTION_WITHIN * best_rms {
                f.direction
                    .clone()
                    .or_else(|| direction_test(f, settings).ok())
            } else {
                None
            }
        })
        .collect()
}

/// The index of the fit that becomes the finding: the dynamic fit whose direction explains
/// most, else the best. A map of the rate depends on the direction of motion, so a static
/// map of ẏ imitates a hysteresis anywhere in the loop and often validates best. When it
/// does not explain most of the gap, a strong direction effect at the input or the sensor,
/// whose z (u, or G·u) is free of the output's noise, is the better explanation: a backlash
/// in a sensor's drive is not friction. Friction itself, seen from the sensor, leaves a weak
/// one ([`SENSOR_HYSTERESIS_SHARE`]), and a rate fit that leaves at most
/// [`STATIC_OVER_DYNAMIC`] of what that fit leaves stands. Those fits get their direction
/// test here when they had none.
pub(super) fn choose(
    fitted: &[Fitted],
    directions: &mut [Option<DirectionTest>],
    settings: &DiscoverSettings,
) -> usize {
    let dynamic = directions
        .iter()
        .enumerate()
        .filter_map(|(i, d)| d.as_ref().filter(|d| d.dynamic).map(|d| (i, d.explained)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i);
    if let Some(i) = dynamic {
        return i;
    }
    if fitted
        .first()
        .is_none_or(|f| f.result.location != Site::RateFeedback)
    {
        return 0;
    }
    let at_the_ends = |i: usize| matches!(fitted[i].result.location, Site::Input | Site::Output);
    for (i, f) in fitted.iter().enumerate() {
        if at_the_ends(i) && directions[i].is_none() && f.result.validation_rms.is_finite() {
            directions[i] = direction_test(f, settings).ok();
        }
    }
    let strongest = directions
        .iter()
        .enumerate()
        .filter_map(|(i, d)| {
            d.as_ref()
                .filter(|d| at_the_ends(i) && d.dynamic && d.explained >= SENSOR_HYSTERESIS_SHARE)
                .map(|d| (i, d.explained))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1));
    match strongest {
        Some((i, _))
            if fitted[0].result.validation_rms
                > STATIC_OVER_DYNAMIC * fitted[i].result.validation_rms =>
        {
            i
        }
        _ => 0,
    }
}

/// The validation RMS of the total-variation estimate at `fitted[i]`'s location, if one was
/// made.
fn total_variation_rms(fitted: &[Fitted], i: usize) -> Option<f64> {
    let location = fitted[i].result.location;
    fitted
        .iter()
        .find(|f| f.result.location == location && f.estimator == "total variation")
        .map(|f| f.result.validation_rms)
}

/// Names the estimate `best` and adds it to the nominal model (see
/// [`name_and_add`]); a hypothesis refined jointly with G records G before and after.
fn add(
    cx: &Context<'_>,
    best: Fitted,
    direction: DirectionTest,
    total_variation_rms: Option<f64>,
) -> Result<Finding> {
    add_with(cx, best, direction, total_variation_rms, Memory::Tested)
}

/// [`add`], saying whether the direction test decides the effect's memory or a fitted
/// hysteresis already showed it.
fn add_with(
    cx: &Context<'_>,
    best: Fitted,
    direction: DirectionTest,
    total_variation_rms: Option<f64>,
    memory: Memory,
) -> Result<Finding> {
    let joint = best.linear.clone();
    let mut finding = name_and_add(best, direction, total_variation_rms, memory, cx)?;
    if let (Some(j), Some(g)) = (joint, cx.given.polynomial()) {
        // In the structure's form, as the refinement after naming records it.
        let form = |g: &structid_linear::PolynomialModel| {
            structid_core::refine::LinearStructure::new("N", finding.location)
                .and_then(|s| s.initial_from_bla(g))
                .unwrap_or_else(|_| g.clone())
        };
        finding.nominal_refinement = Some(NominalRefinement {
            before: form(g),
            after: form(&j.g),
            validation_rms_before: j.nominal_validation_rms,
            validation_rms_after: finding.hypothesis.validation_rms,
            adopted: true,
        });
    }
    Ok(finding)
}

/// Removes `fitted[i]` and names and adds it, with the direction test `direction`.
fn add_at(
    cx: &Context<'_>,
    fitted: &mut Vec<Fitted>,
    i: usize,
    direction: DirectionTest,
) -> Result<Finding> {
    let tv = total_variation_rms(fitted, i);
    add(cx, fitted.remove(i), direction, tv)
}

/// The finding from the chosen fit. A direction-dependent force seen from the position (a
/// dynamic fit in feedback from y) is static seen from the rate: a map of ẏ is the simplest
/// map of y that depends on the direction of motion (friction). When the best rate fit
/// (wherever it ranks: a better fit elsewhere, e.g. at the input, does not make the direction
/// effect seen from the position any less a friction) is named and its augmented model
/// validates clearly better than the dynamic fit's static approximation, or better and closes
/// the gap ([`rate_explains`]), it is the explanation. Hysteresis elsewhere (backlash at the
/// input, a sensor) keeps its verdict: no static map of a measured signal explains it.
pub(super) fn first_finding(
    cx: &Context<'_>,
    fitted: &mut Vec<Fitted>,
    directions: &[Option<DirectionTest>],
    chosen: usize,
) -> Result<Finding> {
    let direction_of = |i: usize| directions[i].clone().unwrap_or_else(DirectionTest::none);
    let rate = fitted.iter().position(|f| {
        f.result.location == Site::RateFeedback && f.result.validation_rms.is_finite()
    });
    let position_vs_rate = fitted[chosen].result.location == Site::OutputFeedback
        && directions[chosen].as_ref().is_some_and(|d| d.dynamic);
    let Some(rate) = rate.filter(|&r| position_vs_rate && r != chosen) else {
        let tv = total_variation_rms(fitted, chosen);
        return add(cx, fitted.swap_remove(chosen), direction_of(chosen), tv);
    };
    let (tv_dynamic, tv_static) = (
        total_variation_rms(fitted, chosen),
        total_variation_rms(fitted, rate),
    );
    let (dir_dynamic, dir_static) = (direction_of(chosen), direction_of(rate));
    // Remove the later index first, so the earlier one stays where it is.
    let (dynamic_fit, static_fit) = if chosen > rate {
        let d = fitted.remove(chosen);
        (d, fitted.remove(rate))
    } else {
        let s = fitted.remove(rate);
        (fitted.remove(chosen), s)
    };
    let dynamic_finding = add(cx, dynamic_fit, dir_dynamic, tv_dynamic)?;
    Ok(match add(cx, static_fit, dir_static, tv_static) {
        Ok(f)
            if matches!(f.classification, Classification::Named(_))
                && rate_explains(
                    f.augmented.validation_gap.rms,
                    f.shrink,
                    dynamic_finding.augmented.validation_gap.rms,
                ) =>
        {
            f
        }
        _ => dynamic_finding,
    })
}

/// When the finding names nothing (dynamic, or no family validates), its augmented model does
/// not confirm it (it closes less than [`super::MIN_CONFIRMING_SHRINK`] of the gap), or it
/// explains only part of the gap (a shrink under [`super::PARTIAL_SHRINK`], and what it leaves
/// is still a missing effect by the gap test), a named family elsewhere may explain
/// the data better: a nonparametric estimate in a feedback loop (a spring seen from the noisy
/// measured position under a controller, a friction seen from a differentiated position) can
/// validate worse than the parametric map refined by output error from it, and so rank its
/// location behind another. Up to [`ALTERNATIVE_LOCATIONS`] other locations are named; among
/// the named maps that validate better than the finding's augmented model by the table's
/// paired test at α ([`better_at`]), the one with the lowest validation RMS is the finding. A
/// dynamic finding also asks for less than half the RMS of its best model, its static
/// approximation or the hysteresis fitted at the input ([`ALTERNATIVE_FACTOR`]): a hysteresis
/// is approximated statically at several locations, each a little better or worse, and a
/// significant difference among approximations is no evidence of a static effect. This runs
/// after [`hysteresis_at_input`], which weighs the hysteresis against the static block found
/// first.
pub(super) fn named_alternative(
    cx: &Context<'_>,
    finding: Finding,
    fitted: &mut Vec<Fitted>,
) -> Finding {
    if matches!(finding.classification, Classification::Named(_))
        // A NaN shrink is not "less than the confirming shrink", as the verdict reads it.
        && (finding.shrink >= super::MIN_CONFIRMING_SHRINK || finding.shrink.is_nan())
        && !(finding.shrink < super::PARTIAL_SHRINK
            && finding.augmented.validation_gap.missing_effect)
    {
        return finding;
    }
    by_validation(fitted);
    let dynamic = finding.classification == Classification::Dynamic;
    // A dynamic finding's best model: its static approximation, or the hysteresis fitted at
    // the input when there is one.
    let dynamic_rms = finding
        .input_hysteresis
        .as_ref()
        .map_or(f64::INFINITY, |h| h.validation_rms)
        .min(finding.augmented.validation_gap.rms);
    let alpha = cx.settings.significance;
    let mut tried = vec![finding.location];
    let mut best: Option<Finding> = None;
    let mut attempts = 0;
    let mut i = 0;
    while i < fitted.len() && attempts < ALTERNATIVE_LOCATIONS {
        let location = fitted[i].result.location;
        // A map of the rate depends on the direction of motion and so imitates hysteresis;
        // a dynamic finding yields to it only through the position-vs-rate rule.
        let rate_for_dynamic = location == Site::RateFeedback && dynamic;
        if tried.contains(&location)
            || rate_for_dynamic
            || !fitted[i].result.validation_rms.is_finite()
        {
            i += 1;
            continue;
        }
        tried.push(location);
        attempts += 1;
        let direction = direction_test(&fitted[i], &cx.settings)
            .ok()
            .unwrap_or_else(DirectionTest::none);
        let bar = best
            .as_ref()
            .map_or(f64::INFINITY, |b| b.augmented.validation_gap.rms);
        if let Ok(alt) = add_at(cx, fitted, i, direction)
            && matches!(alt.classification, Classification::Named(_))
            && alt.augmented.validation_gap.rms < bar
            && better_at(&alt, &finding, alpha)
            && (!dynamic || alt.augmented.validation_gap.rms < ALTERNATIVE_FACTOR * dynamic_rms)
        {
            best = Some(alt);
        }
    }
    let Some(mut alt) = best else {
        return finding;
    };
    alt.remarks.push(format!(
        "the best nonparametric fit was at {} ({}, validation RMS {}); this named map \
         validates better ({}, by the paired test of the validation errors over blocks at \
         α = {alpha})",
        cx.nominal.key(finding.location),
        finding.classification.describe(),
        rms_text(finding.augmented.validation_gap.rms),
        rms_text(alt.augmented.validation_gap.rms)
    ));
    alt
}

/// Whether `a`'s augmented model validates better than `b`'s by the candidate table's paired
/// test at level `alpha` ([`crate::table::compare_blocks`]), on the validation samples both
/// score.
fn better_at(a: &Finding, b: &Finding, alpha: f64) -> bool {
    let (ga, gb) = (&a.augmented.validation_gap, &b.augmented.validation_gap);
    let scored = |g: &crate::gap::Gap| {
        let mut mask = vec![false; g.residual.len()];
        for r in &g.scored {
            mask[r.clone()].iter_mut().for_each(|m| *m = true);
        }
        mask
    };
    let (ma, mb) = (scored(ga), scored(gb));
    let (ea, eb): (Vec<f64>, Vec<f64>) = (0..ma.len().min(mb.len()))
        .filter(|&k| ma[k] && mb[k])
        .map(|k| (ga.residual[k], gb.residual[k]))
        .unzip();
    crate::table::compare_blocks(&ea, &eb).is_some_and(|c| c.better_at(alpha))
}

/// A static block that leaves a gap larger than the noise may be the static shadow of a
/// hysteresis at the input (a play, or an elasto-plastic stop), whose phase lag an estimated
/// G has partly absorbed (so that the direction test stays quiet): the hysteresis is fitted
/// with G, and when it explains the record clearly better than the static block and than a
/// better G alone ([`HYSTERESIS_OVER_STATIC`]), the effect is dynamic at the input. A dynamic
/// finding at the input gets the operator's parameters the same way.
pub(super) fn hysteresis_at_input(
    cx: &Context<'_>,
    mut finding: Finding,
    fitted: &mut Vec<Fitted>,
    noise: &NoiseLevel,
) -> Finding {
    let settings = &cx.settings;
    let static_rms = finding.augmented.validation_gap.rms;
    let Some(h) = (finding.classification != Classification::Dynamic
        || finding.location == Site::Input)
        .then_some(())
        .filter(|_| static_rms > settings.gap.noise_ratio * noise.std)
        .and_then(|_| cx.given.polynomial())
        .and_then(|g| input_hysteresis::input_hysteresis(g, cx.est, cx.val, settings))
        .filter(|h| {
            h.validation_rms <= HYSTERESIS_OVER_STATIC * static_rms
                && h.validation_rms <= HYSTERESIS_OVER_STATIC * h.without_hysteresis_rms
        })
    else {
        return finding;
    };
    let static_what = match finding.classification {
        // A dynamic finding's augmented model holds the static approximation at its site.
        Classification::Dynamic => format!(
            "the static approximation {}",
            cx.nominal.describe(finding.location)
        ),
        _ => format!(
            "{} {}",
            finding.classification.describe(),
            cx.nominal.describe(finding.location)
        ),
    };
    if finding.location != Site::Input
        && let Some(i) = fitted.iter().position(|f| f.result.location == Site::Input)
    {
        let mut direction = direction_test(&fitted[i], settings)
            .ok()
            .unwrap_or_else(DirectionTest::none);
        direction.dynamic = true;
        let tv = total_variation_rms(fitted, i);
        if let Ok(f) = add_with(cx, fitted.remove(i), direction, tv, Memory::Shown) {
            finding = f;
        }
    }
    if finding.location == Site::Input {
        finding.classification = Classification::Dynamic;
        finding.direction.dynamic = true;
        // What the augmented model carries is the static approximation, not a name.
        finding.augmented.fit = None;
        finding.remarks.push(format!(
            "{}, with G re-estimated behind it, validates at RMS {}, against {} for the best \
             static block ({static_what}) and {} for G re-estimated alone: the missing effect \
             has memory",
            h.describe(),
            rms_text(h.validation_rms),
            rms_text(static_rms),
            rms_text(h.without_hysteresis_rms)
        ));
        finding.input_hysteresis = Some(h);
    }
    finding
}

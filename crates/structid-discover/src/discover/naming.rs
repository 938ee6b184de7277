//! Naming the effect: family ranking, structural remarks, the augmented model and the
//! verdict.

use structid_core::{Data, Error, ExprMap, Result};

use crate::effects::{Effect, EffectFit, Naming, NamingSettings, fit_effect_with, name_effect};
use crate::gap::{Gap, GapSettings, gap};
use crate::hypotheses::{Hypothesis, Nominal, Site};
use crate::hysteresis::DirectionTest;

use super::context::Context;
use super::direction::direction_test_of;
use super::fit::{Fitted, simulation_errors};
use super::fit::{even_indices, minmax, scoring_settings};
use super::polish::{polish, polish_jointly};
use super::{Augmented, AugmentedMap, Classification, DiscoverSettings, Finding};
use crate::table::{Candidate, Form, select};

/// Remarks and equivalent locations for a named effect.
pub(super) fn structural_remarks(
    location: Site,
    class: &Classification,
) -> (Vec<Site>, Vec<String>) {
    let mut remarks = Vec::new();
    let mut equivalent = vec![location];
    if let Classification::Named(fit) = class {
        let io = matches!(location, Site::Input | Site::Output);
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
                    equivalent = vec![Site::Input, Site::Output];
                }
            }
            Effect::SmoothSaturation if location == Site::RateFeedback => {
                let v = fit.values();
                remarks.push(format!(
                    "a tanh saturation of the velocity is Coulomb friction regularised over a \
                     transition velocity: Fc = level = {:.4e}, transition level/gain = {:.4e}; \
                     the sampled model (a force held over a sample, the rate a backward \
                     difference) simulates a sharp Coulomb jump less well than this smoothed one",
                    v[1],
                    (v[1] / v[0]).abs()
                ));
            }
            Effect::Offset if io => {
                remarks.push(
                    "an offset at the input and one at the output are the same model up to \
                     G's static gain"
                        .into(),
                );
                equivalent = vec![Site::Input, Site::Output];
            }
            _ => {}
        }
        if matches!(location, Site::OutputFeedback | Site::RateFeedback)
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
            | Effect::GapSpring
            | Effect::CoulombViscous
            | Effect::AsymmetricCoulombViscous
            | Effect::Coulomb
            | Effect::Stribeck
            | Effect::AsymmetricStribeck
            | Effect::ClipAbove
            | Effect::ClipBelow
            | Effect::Rectification { .. }
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

/// [`naming_settings`] with the library cut to the families offered at `location`
/// ([`Effect::applies_at`]: a dead zone at the input or output, a gap spring in feedback from
/// the output, friction in feedback from the rate).
pub(super) fn naming_settings_at(settings: &DiscoverSettings, location: Site) -> NamingSettings {
    NamingSettings {
        library: Effect::library_at(&settings.library, location),
        ..naming_settings(settings)
    }
}

/// How many families (in parsimonious order, skipping those whose map fit is flagged) are
/// refined by output error and simulated. The map fit's ranking is only a first sort: a map
/// estimated from a noisy z (an actuator inside a loop, whose input carries the
/// differentiated sensor noise) blurs a saturation's corners, so the family that validates can
/// come fourth or later by its map fit (a saturation behind a gain error, a clip and a cubic).
const REFINED_FAMILIES: usize = 6;

/// How many of the first families a flag remark is written for.
const FLAG_REMARKS: usize = 6;

/// The relay a saturation-like fit describes: its level c and offset, for a Coulomb start (an
/// asymmetric saturation's half span and centre). Elsewhere only a fit flagged as a relay
/// (an unidentifiable slope) says so; in rate feedback any saturation of the velocity does:
/// the estimate sees a Coulomb jump blurred by the measured rate's noise (the rate is a
/// difference of noisy positions) and by the half sample the rate lags, so its steep but
/// finite slope is the blur, not a physical velocity scale.
fn relay_start(fit: &EffectFit, location: Site) -> Option<(f64, f64)> {
    if location != Site::RateFeedback && !fit.flags.iter().any(|f| f.contains("relay")) {
        return None;
    }
    let v = fit.values();
    let off = fit.offset.as_ref().map_or(0.0, |o| o.value);
    let (level, offset) = match fit.effect {
        Effect::Saturation | Effect::SmoothSaturation => (v.get(1)?.abs(), off),
        Effect::AsymmetricSaturation => {
            let (lower, upper) = (*v.get(1)?, *v.get(2)?);
            (0.5 * (upper - lower), off + 0.5 * (upper + lower))
        }
        _ => return None,
    };
    (level.is_finite() && offset.is_finite() && level > 0.0).then_some((level, offset))
}

/// The table's row of the nonparametric map `best` at its own hypothesis, extrapolated as it
/// was ranked and as the augmented model writes it (held at its edges when that validated
/// better).
fn nonparametric_row(
    best: &Fitted,
    h: &Hypothesis,
    val_h: &Data,
    s: &DiscoverSettings,
) -> Candidate {
    let (lo, hi) = minmax(&best.z);
    let held = |z: &[f64]| best.map.eval(&[z[0].clamp(lo, hi)]);
    let errors = if best.hold_edges {
        simulation_errors(h, &held, val_h, s)
    } else {
        simulation_errors(h, best.map.as_ref(), val_h, s)
    };
    let mut row = Candidate::new(
        format!("nonparametric ({})", best.estimator),
        Form::Nonparametric {
            estimator: best.estimator.to_string(),
        },
        0,
    )
    .with_errors(errors);
    row.location = Some(best.result.location);
    row.estimation_rms = Some(best.result.estimation_rms);
    row.g_refitted = best.linear.is_some();
    row
}

/// Refines `fit` by output error at `h` (jointly with the named known maps when that
/// validates better) and returns its row of the table, with the hypothesis of the refitted
/// known maps when those were kept.
fn family_row(
    fit: &mut EffectFit,
    h: &Hypothesis,
    est_h: &Data,
    val_h: &Data,
    settings: &DiscoverSettings,
) -> (Candidate, Option<Hypothesis>) {
    *fit = polish(fit, h, est_h, settings);
    let mut errors = ExprMap::parse(&fit.expression, 1)
        .map(|m| simulation_errors(h, &m, val_h, settings))
        .unwrap_or_default();
    let mut joint = None;
    // With maps named by earlier steps, each family is also refitted together with them, so
    // that the families are compared without the earlier maps' bias.
    if let Some((refitted, known, joint_errors)) = refit_with_known(fit, h, est_h, val_h, settings)
        && crate::table::rms(&joint_errors) < crate::table::rms(&errors)
    {
        *fit = refitted;
        errors = joint_errors;
        joint = Some(known);
    }
    let (parameters, approximate) = parsimony(fit);
    let mut row = Candidate::new(fit.effect.name(), Form::Family { approximate }, parameters)
        .with_errors(errors);
    row.location = Some(h.location);
    row.eligible = fit.nameable();
    (row, joint)
}

/// The Coulomb family started at the relay that a saturation-like fit among `targets` (or
/// any fit) describes ([`relay_start`]), written into `naming`; its index, or `None`.
fn relay_family(
    naming: &mut Naming,
    targets: &[usize],
    zs: &[f64],
    ws: &[f64],
    location: Site,
) -> Option<usize> {
    let (level, offset) = targets
        .iter()
        .find_map(|&i| relay_start(&naming.ranked[i], location))
        .or_else(|| naming.ranked.iter().find_map(|f| relay_start(f, location)))?;
    let i = naming
        .ranked
        .iter()
        .position(|f| f.effect == Effect::Coulomb)?;
    if targets.contains(&i) {
        return None;
    }
    let mut start = fit_effect_with(Effect::Coulomb, true, zs, ws).ok()?;
    start.parameters[0].value = level;
    if let Some(o) = start.offset.as_mut() {
        o.value = offset;
    }
    naming.ranked[i] = start;
    Some(i)
}

pub(super) fn subsample(z: &[f64], w: &[f64], max: usize) -> (Vec<f64>, Vec<f64>) {
    let idx = even_indices(z.len(), max);
    (
        idx.iter().map(|&k| z[k]).collect(),
        idx.iter().map(|&k| w[k]).collect(),
    )
}

/// A family's place in parsimonious order: its parameter count (the offset counts), and
/// among as many parameters the exact forms before the approximate ones.
fn parsimony(f: &EffectFit) -> (usize, bool) {
    let approximate = matches!(
        f.effect,
        Effect::SmoothSaturation | Effect::PowerLaw { linear: false }
    );
    (
        f.parameters.len() + usize::from(f.offset.is_some()),
        approximate,
    )
}

/// The families of `naming` in the order they are offered for naming: those whose map fit is within 25 %
/// of the best family's RMS, fewest parameters first (the offset counts), among as many
/// parameters the exact forms before the approximate ones (the power law without a linear
/// term and the tanh saturation, which bend to a cubic's or a saturation's shape), then the
/// rest by BIC.
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
        parsimony(a)
            .cmp(&parsimony(b))
            .then(a.rms.total_cmp(&b.rms))
    });
    first.extend(naming.ranked.iter().filter(|f| !near(f)).cloned());
    first
}

/// One remark per family among the first few that was not named for a reason other than its
/// RMS (an unidentifiable parameter, a refit that did not converge).
fn flag_remarks(naming: &Naming) -> Vec<String> {
    naming
        .ranked
        .iter()
        .take(FLAG_REMARKS)
        .filter(|f| !f.flags.is_empty())
        .map(|f| format!("{} not named: {}", f.effect.name(), f.flags.join("; ")))
        .collect()
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
            let derived = fit
                .derived()
                .iter()
                .map(|p| format!("; {} = {:.4}", p.name, p.value))
                .collect::<String>();
            format!(
                "{} ({params}{derived})",
                crate::effects::physical_name(fit, f.location)
            )
        }
        _ => f.effect(),
    };
    format!(
        "missing effect: {what}, {}; validation RMS {:.4e} → {:.4e} ({}), fit {:.1} % → {:.1} %",
        nominal.describe(f.location),
        before.rms,
        f.augmented.validation_gap.rms,
        crate::gap::shrink_text(f.shrink, 1),
        before.fit_percent,
        f.augmented.validation_gap.fit_percent
    )
}

/// A known map of a nominal model read from a file is only a function (an expression or a
/// table); when it is exactly a family of the library (a map found and named by an earlier
/// run), that family is recovered, so that its parameters can be refitted jointly with the
/// next effect's. Each known map without a family is sampled at 400 points over the range of
/// its z on `est`, and every family (with and without offset) is fitted to the points; the one
/// with fewest parameters that reproduces them to 10⁻⁶ of their RMS is taken. Returns the
/// nominal model with the families found, or `None` when nothing was to be recovered.
pub(super) fn recover_families(
    nominal: &Nominal,
    est: &Data,
    settings: &DiscoverSettings,
) -> Result<Option<Nominal>> {
    let known = nominal.known_maps();
    if known.iter().all(|k| k.fit.is_some()) {
        return Ok(None);
    }
    // z of every record, each computed from that record alone.
    let lft = nominal.model()?.lft().clone();
    let z = est
        .records()
        .iter()
        .map(|r| Ok(lft.compute_z(r.u(), r.y())?.0))
        .collect::<Result<Vec<_>>>()?;
    let channel = |i: usize| -> Vec<f64> { z.iter().flat_map(|z| z.channel(i)).collect() };
    let count = |f: &EffectFit| f.parameters.len() + usize::from(f.offset.is_some());
    let fits = known
        .iter()
        .enumerate()
        .map(|(i, k)| {
            if k.fit.is_some() {
                return None;
            }
            let (lo, hi) = minmax(&channel(i));
            if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
                return None;
            }
            let zs: Vec<f64> = (0..400)
                .map(|j| lo + (hi - lo) * j as f64 / 399.0)
                .collect();
            let ws: Vec<f64> = zs.iter().map(|v| k.map.eval(&[*v])).collect();
            let scale = (ws.iter().map(|w| w * w).sum::<f64>() / ws.len() as f64).sqrt();
            if !(scale.is_finite() && scale > 0.0) {
                return None;
            }
            let mut best: Option<EffectFit> = None;
            for &effect in &settings.library {
                for offset in [false, true] {
                    if let Ok(f) = fit_effect_with(effect, offset, &zs, &ws)
                        && f.rms <= 1e-6 * scale
                        && best.as_ref().is_none_or(|b| count(&f) < count(b))
                    {
                        best = Some(f);
                    }
                }
            }
            best
        })
        .collect();
    Ok(Some(nominal.clone().with_known_fits(fits)))
}

/// The family `fit` refitted jointly with the named known maps of `h`
/// ([`polish_jointly`]): the refitted family, the hypothesis with the refitted known maps, and
/// the validation errors; `None` when `h` has no named known map or the refit failed.
fn refit_with_known(
    fit: &EffectFit,
    h: &Hypothesis,
    est_h: &Data,
    val_h: &Data,
    settings: &DiscoverSettings,
) -> Option<(EffectFit, Hypothesis, Vec<f64>)> {
    if !h.known.iter().any(|k| k.fit.is_some()) {
        return None;
    }
    let known: Vec<Option<EffectFit>> = h.known.iter().map(|k| k.fit.clone()).collect();
    let (new_fit, refitted) = polish_jointly(fit, &known, h, est_h, settings)?;
    if !new_fit.nameable() {
        return None;
    }
    let mut joint = h.clone();
    for (k, f) in joint.known.iter_mut().zip(refitted) {
        if let Some(f) = f {
            k.map = std::sync::Arc::new(ExprMap::parse(&f.expression, 1).ok()?);
            k.fit = Some(f);
        }
    }
    let m = ExprMap::parse(&new_fit.expression, 1).ok()?;
    let errors = simulation_errors(&joint, &m, val_h, settings);
    Some((new_fit, joint, errors))
}

/// Whether the direction test decides if an effect has memory, or a fitted hysteresis
/// operator already showed it (and the finding is dynamic whatever the test says).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Memory {
    /// The direction test decides.
    Tested,
    /// A fitted hysteresis showed it.
    Shown,
}

/// The direction test of what the family `map` leaves of the fit `best`, whose own test is
/// `own`. Its share is of the residual energy the nonparametric estimate leaves: a family
/// refined by simulation can sit far from the estimate's ŵ along the record's z (a linear
/// term a loop takes up), and that static misfit, added to the residual, would dilute the
/// share of a direction effect it does not remove.
fn family_direction(
    best: &Fitted,
    map: &ExprMap,
    own: &DirectionTest,
    settings: &DiscoverSettings,
) -> Option<DirectionTest> {
    let every = DiscoverSettings {
        hysteresis_threshold: 0.0,
        ..settings.clone()
    };
    let mut t = direction_test_of(best, Some(map), &every).ok()?;
    if own.explained > 0.0 && own.direction_energy > 0.0 {
        let energy = own.direction_energy / own.explained;
        t.explained = (t.direction_energy / energy).min(1.0);
    }
    t.dynamic &= t.explained > settings.hysteresis_threshold;
    Some(t)
}

/// A direction-dependent residual of the nonparametric map at the table's choice: the effect
/// has memory only when the chosen static row at the site leaves the direction effect too (a
/// smoothed kink, or a map estimated around a biased G, leaves one that the family's own
/// curve does not). Only a family refined around the fit's own known maps leaves a residual
/// the fit's ê and ŵ describe, and a memory a fitted hysteresis showed is not re-tested.
/// Returns the direction test that stands, the family still chosen (`None` when the effect
/// has memory) and the remark of a direction effect the family removed.
fn weigh_direction(
    best: &Fitted,
    naming: &Naming,
    joint_known: &[Option<Hypothesis>],
    chosen_family: Option<usize>,
    direction: DirectionTest,
    memory: Memory,
    settings: &DiscoverSettings,
) -> (DirectionTest, Option<usize>, Option<String>) {
    let family_test = chosen_family
        .filter(|&i| memory == Memory::Tested && joint_known[i].is_none())
        .and_then(|i| {
            let map = ExprMap::parse(&naming.ranked[i].expression, 1).ok()?;
            family_direction(best, &map, &direction, settings)
        });
    match family_test {
        Some(t) if !t.dynamic => {
            let remark = format!(
                "the direction of z explains {:.0} % of what the nonparametric map leaves (t = \
                 {:.1}); what the named family leaves depends on it by {:.0} % of that (t = \
                 {:.1}): the direction effect was the estimate's misfit, not memory",
                100.0 * direction.explained,
                direction.t_statistic,
                100.0 * t.explained,
                t.t_statistic
            );
            (t, chosen_family, Some(remark))
        }
        _ => (direction, None, None),
    }
}

/// The most breakpoints a written table gets, whatever the kernel's width.
const MAX_TABLE_POINTS: usize = 20_001;

/// Names the estimate `best` from the candidate table at its location (the nonparametric map
/// and the families refined there, chosen by [`select`]) and examines the augmented model on
/// both records against the search's nominal gap.
pub(super) fn name_and_add(
    best: Fitted,
    direction: DirectionTest,
    total_variation_rms: Option<f64>,
    memory: Memory,
    cx: &Context<'_>,
) -> Result<Finding> {
    let (est, val, settings) = (cx.est, cx.val, &cx.settings);
    let (est_candidates, val_candidates) = (&cx.est_candidates, &cx.val_candidates);
    let (gap_settings, before) = (&cx.gap_settings, &cx.validation_gap);
    let location = best.result.location;
    let h = best.hypothesis.clone();
    let val_h = h.data(val)?;
    let est_h = h.data(est)?;
    let (zs, ws) = subsample(&best.z, &best.w_hat, settings.naming_points);
    let mut naming = name_effect(&zs, &ws, &naming_settings_at(settings, location))
        .map_err(|e| Error::Numerical(format!("naming the effect: {e}")))?;
    naming.ranked = parsimonious(&naming);
    let nonparametric_rms = best.result.validation_rms;

    let mut family_rms: Vec<Option<f64>> = vec![None; naming.ranked.len()];
    // The known maps refitted jointly with family i, when that validated better.
    let mut joint_known: Vec<Option<Hypothesis>> = vec![None; naming.ranked.len()];
    let mut classification = Classification::Unnamed;
    let mut chosen_joint: Option<Hypothesis> = None;
    let mut rows = vec![nonparametric_row(&best, &h, &val_h, settings)];
    let g_refitted = best.linear.is_some();
    let mut row_family: Vec<Option<usize>> = vec![None];
    // The first families in parsimonious order whose map fit is not flagged are refined
    // and simulated; flagged ones stay in the naming table with their flags.
    let targets: Vec<usize> = (0..naming.ranked.len())
        .filter(|&i| naming.ranked[i].nameable())
        .take(REFINED_FAMILIES)
        .collect();
    let mut family = |i: usize, naming: &mut Naming| {
        let (mut row, joint) = family_row(&mut naming.ranked[i], &h, &est_h, &val_h, settings);
        row.g_refitted = g_refitted;
        family_rms[i] = Some(row.validation_rms);
        joint_known[i] = joint;
        rows.push(row);
        row_family.push(Some(i));
    };
    for &i in &targets {
        family(i, &mut naming);
    }
    // A saturation flagged as a relay says "Coulomb" with its level and offset: the relay
    // itself is refined from there (its map fit to a smoothed jump is poor, its refit is
    // not).
    if let Some(i) = relay_family(&mut naming, &targets, &zs, &ws, location) {
        family(i, &mut naming);
    }
    let mut selection = select(&rows, None, settings.significance);
    let chosen_family = selection.chosen.and_then(|c| row_family[c]);
    let (direction, chosen_family, static_direction_remark) = if direction.dynamic {
        weigh_direction(
            &best,
            &naming,
            &joint_known,
            chosen_family,
            direction,
            memory,
            settings,
        )
    } else {
        (direction, chosen_family, None)
    };
    if direction.dynamic {
        classification = Classification::Dynamic;
        // The augmented model carries the nonparametric map (row 0).
        selection.chosen = Some(0);
    }
    if let Some(i) = chosen_family {
        classification = Classification::Named(naming.ranked[i].clone());
        chosen_joint = joint_known[i].take();
    }
    // The maps found by earlier steps were fitted while this effect was unmodelled: when the
    // named family was refitted together with them, the augmented model carries them so.
    let mut h = h;
    let mut joint_remark = None;
    if let Some(joint) = chosen_joint {
        joint_remark = Some(format!(
            "the maps of the earlier steps were refitted jointly with this one (output error, \
             every map in the loop): {}",
            joint
                .known
                .iter()
                .filter_map(|k| k
                    .fit
                    .as_ref()
                    .map(|f| format!("`{}` = {}", k.name, f.expression)))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        h = joint;
    }
    naming.named = match &classification {
        Classification::Named(fit) => Some(fit.clone()),
        _ => None,
    };
    let (equivalent_locations, mut remarks) = structural_remarks(location, &classification);
    remarks.extend(joint_remark);
    remarks.extend(static_direction_remark);
    match &classification {
        Classification::Named(_) | Classification::TimeVarying(_) => {}
        Classification::Unnamed => {
            remarks.push(format!(
                "no family refined is as good as the best row of the candidate table (`{}`, by \
                 the paired test of the validation errors over blocks at α = {}), so the map is \
                 kept as a table",
                rows[selection.best].label, settings.significance
            ));
            remarks.extend(flag_remarks(&naming));
        }
        Classification::Dynamic => remarks.push(format!(
            "the direction of z explains {:.0} % of the deconvolved residual (t = {:.1}): the \
             effect is not static; the augmented model carries the best static approximation \
             as a table",
            100.0 * direction.explained,
            direction.t_statistic
        )),
    }
    let augmented_map = written_map(&best, &classification, settings);
    let interp = augmented_map.interpolant()?;
    let gap_settings = &GapSettings {
        initial_state: scoring_settings(location, settings).initial_state(),
        ..gap_settings.clone()
    };
    let estimation_gap = gap(
        &h.model,
        &h.maps(interp.as_ref()),
        &est_h,
        est_candidates,
        gap_settings,
    )?;
    let validation_gap = gap(
        &h.model,
        &h.maps(interp.as_ref()),
        &val_h,
        val_candidates,
        gap_settings,
    )?;
    let shrink = before.rms / validation_gap.rms;
    let named = naming.named.clone();
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
            fit: named,
            known: h.known.clone(),
            estimation_gap,
            validation_gap,
        },
        shrink,
        nominal_refinement: None,
        input_hysteresis: None,
        table: rows,
        selection,
        stationarity: None,
        poor_model: false,
    })
}

/// The map the augmented model carries: a named family's expression, else the estimate as a
/// table, which extrapolates as the hypothesis was scored: held at the edges of the estimation
/// range, or following the map as estimated over a range as wide again on each side (beyond
/// which any table holds its last value).
fn written_map(
    best: &Fitted,
    classification: &Classification,
    settings: &DiscoverSettings,
) -> AugmentedMap {
    match classification {
        Classification::Named(fit) => AugmentedMap::Expression(fit.expression.clone()),
        _ => {
            let (lo, hi) = minmax(&best.z);
            let pad = if best.hold_edges { 0.0 } else { hi - lo };
            // Four breakpoints per kernel width at least: a map with detail finer than the
            // range (a cogging force) is otherwise cut to a coarser one than was estimated.
            let per_sigma = best
                .result
                .sigma
                .filter(|s| *s > 0.0)
                .map_or(0.0, |s| 4.0 * (hi - lo + 2.0 * pad) / s);
            let n = settings
                .table_points
                .max((per_sigma.ceil() as usize + 1).min(MAX_TABLE_POINTS));
            let z: Vec<f64> = (0..n)
                .map(|i| lo - pad + (hi - lo + 2.0 * pad) * i as f64 / (n - 1) as f64)
                .collect();
            let w = z.iter().map(|z| best.map.eval(&[*z])).collect();
            AugmentedMap::Table { z, w }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::{Refit, fit_effect};

    #[test]
    fn the_complexity_order_puts_exact_forms_and_fewer_parameters_first() {
        let z: Vec<f64> = (0..80).map(|k| k as f64 / 10.0 - 4.0).collect();
        let w: Vec<f64> = z.iter().map(|z| 2.0 * (z / 2.0).tanh()).collect();
        let tanh = fit_effect(Effect::SmoothSaturation, &z, &w).unwrap();
        let power = fit_effect(Effect::PowerLaw { linear: true }, &z, &w).unwrap();
        let saturation = fit_effect(Effect::Saturation, &z, &w).unwrap();
        assert!(parsimony(&tanh) < parsimony(&power));
        // As many parameters: the exact saturation before its tanh approximation.
        assert_eq!(parsimony(&saturation).0, parsimony(&tanh).0);
        assert!(parsimony(&saturation) < parsimony(&tanh));
    }

    #[test]
    fn an_unconverged_refit_may_not_be_chosen() {
        let z: Vec<f64> = (0..50).map(|k| k as f64 / 10.0 - 2.5).collect();
        let w: Vec<f64> = z.iter().map(|z| 2.0 * z).collect();
        let mut stuck = fit_effect(Effect::Gain, &z, &w).unwrap();
        assert!(stuck.nameable());
        stuck.refit = Some(Box::new(Refit::failed("stopped at the iteration limit")));
        assert!(!stuck.nameable());
    }
}

//! Re-estimating G with the found map in the loop, for nominal models estimated from data.

use std::sync::Arc;

use structid_core::refine::{LinearStructure, RefineSettings, refine_linear};
use structid_core::{Data, IdentifySettings, InitialState, Result, Structure};
use structid_linear::PolynomialModel;

use crate::gap::{Gap, gap};

use crate::hypotheses::{Nominal, Site};

use super::context::Context;
use super::fit::{Fitted, JointLinear, identify_hypothesis, initial_state, simulation_rms};
use super::{DiscoverSettings, Finding, NominalRefinement};

/// Refits G (in the structure of the finding's location) by output error with the finding's
/// map held fixed, starting from the finding's G (the nominal `g`, or the G re-estimated
/// jointly with its nonparametric map, [`refine_jointly`]), and keeps the augmented model with
/// the new G when its validation RMS (scored as every simulation of the workflow) falls; the
/// finding's gaps and shrink are then those of the new model. Records G as given and as kept,
/// with the validation RMS of the finding's map around each.
pub(super) fn refine_nominal(
    g: &PolynomialModel,
    finding: &mut Finding,
    cx: &Context<'_>,
) -> Result<()> {
    let (est, val, settings) = (cx.est, cx.val, &cx.settings);
    let (est_candidates, val_candidates) = (&cx.est_candidates, &cx.val_candidates);
    let (gap_settings, before) = (&cx.gap_settings, &cx.validation_gap);
    let location = finding.location;
    let structure = LinearStructure::new("N", location)?;
    let given = structure.initial_from_bla(g)?;
    let joint = finding.nominal_refinement.take().filter(|r| r.adopted);
    let start = match &joint {
        Some(r) => structure.initial_from_bla(&u_to_y(&r.after))?,
        None => given.clone(),
    };
    let map = finding.augmented.map.interpolant()?;
    // `g` is in the structure's form (for feedback from y, its u and feedback numerators);
    // the hypothesis is built from its u → y part, as every location is.
    let hypothesis = |g: &PolynomialModel| -> Result<crate::hypotheses::Hypothesis> {
        let dispersion = Arc::clone(&finding.augmented.model.blocks()[0].dispersion);
        Ok(crate::hypotheses::Hypothesis {
            location,
            model: Structure::new(u_to_y(g), location, dispersion).model()?,
            sample_time: g.sample_time.unwrap_or(1.0),
            known: Vec::new(),
        })
    };
    let rms_of = |g: &PolynomialModel| -> Result<f64> {
        let h = hypothesis(g)?;
        Ok(simulation_rms(&h, map.as_ref(), &h.data(val)?, settings))
    };
    let h_start = hypothesis(&start)?;
    let est_h = h_start.data(est)?;
    let refine_settings = RefineSettings::builder()
        .identify(
            IdentifySettings::builder()
                .initial_state(InitialState::Estimate)
                .build()?,
        )
        .build()?;
    let r = refine_linear(&structure, &start, map.as_ref(), &est_h, &refine_settings)?;
    let rms_given = rms_of(&given)?;
    let rms_start = if joint.is_some() {
        rms_of(&start)?
    } else {
        rms_given
    };
    let rms_after = rms_of(&r.after)?;
    let refined = rms_after < rms_start;
    let (kept, rms_kept) = if refined {
        (r.after, rms_after)
    } else {
        (start, rms_start)
    };
    let adopted = refined || joint.is_some();
    if refined {
        let h_after = hypothesis(&kept)?;
        let (est_after, val_after) = (h_after.data(est)?, h_after.data(val)?);
        let interp = map.as_ref();
        let estimation_gap: Gap = gap(
            &h_after.model,
            &[interp],
            &est_after,
            est_candidates,
            gap_settings,
        )?;
        let validation_gap = gap(
            &h_after.model,
            &[interp],
            &val_after,
            val_candidates,
            gap_settings,
        )?;
        finding.shrink = before.rms / validation_gap.rms;
        finding.augmented.model = h_after.model.clone();
        finding.augmented.estimation_gap = estimation_gap;
        finding.augmented.validation_gap = validation_gap;
    }
    if adopted {
        finding.remarks.push(format!(
            "G was re-estimated with the map in the loop (output error{}): validation RMS of the \
             augmented model {:.4e} with G as given → {:.4e}",
            if joint.is_some() {
                ", alternating with the nonparametric map"
            } else {
                ""
            },
            rms_given,
            rms_kept
        ));
    }
    finding.nominal_refinement = Some(NominalRefinement {
        before: given,
        after: kept,
        validation_rms_before: rms_given,
        validation_rms_after: rms_kept,
        adopted,
    });
    Ok(())
}

/// G from u to y of a linear part in a structure's form (for output feedback the structure's
/// G also carries the feedback path −B, its second input).
pub(super) fn u_to_y(g: &PolynomialModel) -> PolynomialModel {
    PolynomialModel {
        num: g.num.first().cloned().into_iter().collect(),
        den: g.den.clone(),
        sample_time: g.sample_time,
    }
}

/// Whether `g` has more poles within about 10⁻⁴ of z = 1 than `nominal` (integrators, or
/// poles slower than any record resolves): a joint refit that drives a pole there models a
/// drift of the record (an unmeasured disturbance) by the plant, and the map found around it
/// is meaningless.
pub(super) fn adds_integrator(g: &PolynomialModel, nominal: &PolynomialModel) -> bool {
    near_unit_poles(&g.den) > near_unit_poles(&nominal.den)
}

/// The number of roots of `den` within about 10⁻⁴ of z = 1 (successive deflations by
/// (1 − q⁻¹) whose remainder is below 10⁻⁴ of the coefficients' sum).
pub(super) fn near_unit_poles(den: &[f64]) -> usize {
    use structid_linear::integrators::deflate_within;
    let mut n = 0;
    let mut p = den.to_vec();
    while let Some(r) = deflate_within(&p, 1, 1e-4) {
        n += 1;
        p = r;
    }
    n
}

/// Alternations of [`refine_jointly`] at most: each re-estimates G and the map once.
const JOINT_ITERATIONS: usize = 3;

/// A joint step is kept when it lowers the hypothesis' validation RMS below this share of the
/// previous one: a smaller gain is within what a second fit of the same data changes anyway.
const JOINT_GAIN: f64 = 0.95;

/// Re-estimates G jointly with the nonparametric map of `fitted` (a nominal G = `g`, u → y, as
/// estimated from data is a best linear approximation, biased by the very effect that is
/// missing, and a static block cannot absorb a dynamic error of G): the alternation of
/// [`structid_core::refine`] in discovery's own terms. G is refitted with the map held fixed
/// as a function and integrators held at 1: at the input and the output by output error
/// ([`LinearStructure::estimate_linear_with_map`]), in feedback by the scored simulation
/// error with the map in the loop ([`super::polish::polish_linear`]; the measured y or rate
/// would put the output noise into the map's input), then the map is identified again at the
/// same location around the new G (with
/// the nominal model's input disturbance `input_noise`, if any), and so on while the validation
/// RMS, scored as every simulation of the workflow, falls below [`JOINT_GAIN`] of the last.
///
/// Returns the best fit: `fitted` itself when no step helps (an exact G) or when the refined
/// fit's validation RMS is not below `required` times the original's (1 to keep any gain,
/// less to ask for more), otherwise the fit around the re-estimated G, which
/// [`Fitted::linear`] then carries. Locations declared in an `[lft]` model have no G of their
/// own and are returned as they are. (The caller does not refine nominal models with known
/// maps: G is then not the whole linear part.)
pub(super) fn refine_jointly(
    g: &PolynomialModel,
    input_noise: Option<f64>,
    fitted: Fitted,
    est: &Data,
    val: &Data,
    required: f64,
    settings: &DiscoverSettings,
) -> Fitted {
    let location = fitted.result.location;
    let Ok(structure) = LinearStructure::new("N", location) else {
        return fitted;
    };
    let oe = RefineSettings::default().oe().clone();
    let free = initial_state(location).1 == InitialState::Estimate;
    let nominal_validation_rms = fitted.result.validation_rms;
    let same_width = DiscoverSettings {
        sigma_fraction: fitted.sigma_fraction,
        ..settings.clone()
    };
    let mut refined: Option<Fitted> = None;
    for _ in 0..JOINT_ITERATIONS {
        let f_now = refined.as_ref().unwrap_or(&fitted);
        let g_now = f_now.linear.as_ref().map_or(g, |j| &j.g);
        let step = || -> Result<Fitted> {
            let next = match location {
                Site::OutputFeedback | Site::RateFeedback => {
                    let in_loop = |g: &PolynomialModel| {
                        super::polish::polish_linear(g, f_now.map.as_ref(), location, est, settings)
                    };
                    in_loop(g_now)
                        .or_else(|| {
                            // The loop with G as given may not even simulate (a closed-loop
                            // record's direct fit, whose zero cancels the integrator, diverges
                            // with the map fed back): the map's input read from the measured
                            // output gives a biased but stable G to start the loop from.
                            let start = structure.initial_from_bla(g_now).ok()?;
                            let fit = structure
                                .estimate_linear_with_map(
                                    est,
                                    f_now.map.as_ref(),
                                    &start,
                                    &oe,
                                    free,
                                )
                                .ok()?;
                            let open = u_to_y(&fit.model);
                            in_loop(&open).or(Some(open))
                        })
                        .ok_or_else(|| {
                            structid_core::Error::Numerical("the in-loop refit of G failed".into())
                        })?
                }
                _ => {
                    let start = structure.initial_from_bla(g_now)?;
                    let fit = structure.estimate_linear_with_map(
                        est,
                        f_now.map.as_ref(),
                        &start,
                        &oe,
                        free,
                    )?;
                    u_to_y(&fit.model)
                }
            };
            if adds_integrator(&next, g) {
                return Err(structid_core::Error::Numerical(
                    "the refit of G put a pole on z = 1".into(),
                ));
            }
            let mut f = identify_around(&next, input_noise, location, est, val, &same_width)?;
            f.input_noise = input_noise;
            f.linear = Some(JointLinear {
                g: next,
                nominal_validation_rms,
            });
            Ok(f)
        };
        match step() {
            Ok(f)
                if f.result.validation_rms.is_finite()
                    && f.result.validation_rms < JOINT_GAIN * f_now.result.validation_rms =>
            {
                refined = Some(f);
            }
            _ => break,
        }
    }
    match refined {
        Some(f) if f.result.validation_rms < required * nominal_validation_rms => f,
        _ => fitted,
    }
}

/// The quadratic estimate at `location` around G = `g`, with the input disturbance of ratio
/// `input_noise` where it can be used (as [`super::discover`] identifies every location).
fn identify_around(
    g: &PolynomialModel,
    input_noise: Option<f64>,
    location: crate::hypotheses::Site,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> Result<Fitted> {
    let plain = Nominal::from_polynomial(g)?;
    match input_noise {
        Some(ratio) => plain
            .clone()
            .with_input_noise(ratio)
            .and_then(|n| identify_hypothesis(&n, location, est, val, settings))
            .or_else(|_| identify_hypothesis(&plain, location, est, val, settings)),
        None => identify_hypothesis(&plain, location, est, val, settings),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(num: Vec<f64>, den: Vec<f64>) -> PolynomialModel {
        PolynomialModel::new(vec![num], den, Some(0.01)).unwrap()
    }

    #[test]
    fn a_pole_driven_to_one_is_an_added_integrator() {
        let nominal = model(vec![0.0, 0.2, 0.15], vec![1.0, -1.9, 0.9]);
        // (1 − q⁻¹)(1 − 0.99999 q⁻¹): a second pole 10⁻⁵ from z = 1
        let drifted = model(vec![0.0, 0.2, 0.15], vec![1.0, -1.99999, 0.99999]);
        assert!(adds_integrator(&drifted, &nominal));
        // (1 − q⁻¹)(1 − 0.95 q⁻¹): a faster pole is not
        let refit = model(vec![0.0, 0.2, 0.15], vec![1.0, -1.95, 0.95]);
        assert!(!adds_integrator(&refit, &nominal));
        assert!(!adds_integrator(&nominal, &nominal));
        // a stable nominal: a refit with a pole at 0.99999 adds one
        let stable = model(vec![0.0, 0.2], vec![1.0, -0.9]);
        assert!(adds_integrator(
            &model(vec![0.0, 0.2], vec![1.0, -0.99999]),
            &stable
        ));
        // a nominal that has such a slow pole itself may keep it
        let slow = model(vec![0.0, 0.2], vec![1.0, -0.99998]);
        assert!(!adds_integrator(
            &model(vec![0.0, 0.2], vec![1.0, -0.99999]),
            &slow
        ));
    }
}

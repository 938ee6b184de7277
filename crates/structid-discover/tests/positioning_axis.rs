//! The closed-loop positioning axis of `structid_testcases::physics::positioning_axis`:
//! M·q̈ + Fv·q̇ + Fc·sign(q̇) + offset = τ, simulated in continuous time (RK4, 20 steps per
//! sample) under a PD position controller on point-to-point moves, sampled at 1 kHz. The
//! workflow sees the recorded force τ and position q and the physical nominal M·q̈ + Fv·q̇ = τ
//! (an integrator: its free-run simulation drifts). It must score in windows, name Coulomb
//! friction in feedback from the rate with Fc within 15 % (the constant force offset may be
//! carried as the family's offset or as the difference of asymmetric Coulomb levels), and
//! shrink the windowed validation gap at least 5×.

use structid_core::validation::Scoring;
use structid_discover::discover::{Classification, DiscoverSettings, Verdict, discover};
use structid_discover::effects::Effect;
use structid_discover::hypotheses::{Nominal, Site};
use structid_testcases::physics::positioning_axis;

#[test]
fn coulomb_friction_of_a_closed_loop_axis_is_named_in_rate_feedback() {
    let axis = positioning_axis(1);
    let nominal = Nominal::from_polynomial(&axis.nominal).unwrap();
    let d = discover(
        &nominal,
        &axis.estimation,
        &axis.validation,
        &DiscoverSettings::default(),
    )
    .unwrap();
    assert!(matches!(d.scoring, Scoring::Windowed(_)), "{:?}", d.scoring);
    assert_eq!(d.verdict_kind, Verdict::MissingEffect, "{}", d.verdict);
    let f = d.finding.as_ref().unwrap();
    assert_eq!(f.location, Site::RateFeedback, "{}", d.verdict);
    let Classification::Named(fit) = &f.classification else {
        panic!("not named: {}", d.verdict)
    };
    let v = fit.values();
    let offset = fit.offset.as_ref().map_or(0.0, |o| o.value);
    // (Coulomb level, force offset) in the family's own parameters.
    let (fc, off) = match fit.effect {
        Effect::Coulomb | Effect::CoulombViscous | Effect::Stribeck => (v[0], offset),
        Effect::AsymmetricCoulombViscous => (0.5 * (v[0] + v[1]), offset + 0.5 * (v[0] - v[1])),
        other => panic!("named {}: {}", other.name(), d.verdict),
    };
    assert!(
        (fc - axis.coulomb).abs() <= 0.15 * axis.coulomb,
        "Fc {fc} against {}",
        axis.coulomb
    );
    assert!(
        (off - axis.offset).abs() <= 0.15 * axis.offset,
        "offset {off} against {}",
        axis.offset
    );
    assert!(f.shrink >= 5.0, "shrink {}: {}", f.shrink, d.verdict);
}

/// The same axis with the nominal an engineer would estimate from the closed-loop record
/// (`structid linear --orders 1,2,1 --method oe --integrators 1`): the friction and the offset
/// bias it badly (a zero next to the integrator, a hundred times the plant's high-frequency
/// gain), so that a map of the rate around it does not even simulate. The workflow refits G
/// jointly with its first finding (a gain error at the input), searches again around the
/// refitted G, and names the Coulomb friction in rate feedback, Fc within 15 %, with the
/// windowed gap of the nominal as given shrinking at least 5×.
#[test]
fn coulomb_friction_is_named_from_an_estimated_nominal_too() {
    let axis = positioning_axis(1);
    let (g, source) = axis.estimated_nominal();
    assert_ne!(source, structid_testcases::physics::NominalSource::Exact);
    let d = discover(
        &Nominal::from_polynomial(&g).unwrap(),
        &axis.estimation,
        &axis.validation,
        &DiscoverSettings::default(),
    )
    .unwrap();
    assert_eq!(d.verdict_kind, Verdict::MissingEffect, "{}", d.verdict);
    let f = d.finding.as_ref().unwrap();
    assert_eq!(f.location, Site::RateFeedback, "{}", d.verdict);
    let Classification::Named(fit) = &f.classification else {
        panic!("not named: {}", d.verdict)
    };
    let fc = match fit.effect {
        Effect::Coulomb | Effect::CoulombViscous | Effect::Stribeck => fit.values()[0],
        Effect::AsymmetricCoulombViscous => 0.5 * (fit.values()[0] + fit.values()[1]),
        other => panic!("named {}: {}", other.name(), d.verdict),
    };
    assert!(
        (fc - axis.coulomb).abs() <= 0.15 * axis.coulomb,
        "Fc {fc} against {}",
        axis.coulomb
    );
    assert!(f.shrink >= 5.0, "shrink {}: {}", f.shrink, d.verdict);
    // The report shows G as given and as refitted.
    let r = f.nominal_refinement.as_ref().unwrap();
    assert!(r.adopted && r.before.den != r.after.den);
}

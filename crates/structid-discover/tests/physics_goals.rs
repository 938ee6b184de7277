//! The discovery workflow's goals on plants as engineers meet them
//! (`structid_testcases::physics`): continuous-time physics integrated by RK4 and sampled, so
//! that no discrete LFT is exact; integrating axes in open and closed loop, double
//! integrators, two-mass resonances, input delays, non-minimum-phase zeros, white and coloured
//! noise, validation records up to 20 % larger than the estimation record, and in about half
//! of the cases a nominal estimated from the (effect-laden) estimation record by
//! `structid linear` instead of the true G.
//!
//! Per case the workflow sees only the nominal and the two records. The goals of the issue on
//! discovery deciding from one table:
//!
//! | goal | over | at least |
//! |---|---|---|
//! | located (the true site, or a site the finding reports as equivalent) | static | 95 % |
//! | named by the truth's family or a listed near family ([`Expected::accepted`]) | static | 90 % |
//! | key parameters within 20 % | named static with key parameters | 85 % |
//! | reported as dynamic | backlash, Bouc–Wen | 85 % |
//! | no false alarm | LTI + noise | 14 of 15 |
//! | no false alarm | LTI, an unmodelled resonance, outliers in the noise (5 each) | 14 of 15 |
//! | flagged as time-varying | a drifting gain | 80 % |
//! | both found with `--effects 2` | two static effects at two sites | 80 % |
//! | median validation shrink | static | 90 % of the true model's (median ratio) |
//! | wall time on 5000 samples per record, 2 cores | static | median ≤ 10 s, every case ≤ 30 s |
//!
//! The true model's shrink is the nominal's validation gap over that of the true G with the
//! true map at the true site, simulated through the workflow's own discrete LFT and scored as
//! the workflow scored the case. It is the most a static block there can give: the map acts
//! in continuous time, the LFT holds it over a sample (and takes the rate as a backward
//! difference), so that even the truth leaves a gap on some plants (friction under a PD
//! controller most of all).
//!
//! The rules may be tuned on the cases of seeds 0–99 (the `…_tuning_seeds` tests, run with
//! `--ignored`); every figure is asserted and reported on held-out cases of seeds from 1000,
//! fixed before any tuning. The tests that run by default assert the goals that hold and a
//! floor under the others; the goals not met are ignored tests of their own. Each prints one
//! line per case (`cargo test --release -p structid-discover --test physics_goals --
//! --nocapture`).

use std::sync::Arc;

use structid_core::PolynomialDispersion;
use structid_core::validation::{Scoring, ValidationSettings, validate};
use structid_discover::discover::{
    Classification, DiscoverSettings, Discovery, EffectsSettings, FEEDBACK_HYSTERESIS_SHARE,
    PARTIAL_SHRINK, UNLOCATED_DIRECTION_EFFECT, Verdict, discover, discover_effects, initial_state,
    rate_explains,
};
use structid_discover::hypotheses::{Nominal, Site};
use structid_testcases::parallel;
use structid_testcases::physics::{
    Expected, NominalSource, PhysicsCase, PhysicsKind, generate, generate_with_length,
};

/// The held-out seeds the goals are asserted on, fixed before any rule was tuned on them.
const HELD_OUT_STATIC: std::ops::Range<u64> = 1000..1060;
const HELD_OUT_DYNAMIC: std::ops::Range<u64> = 1000..1015;
const HELD_OUT_LTI: std::ops::Range<u64> = 1000..1015;
const HELD_OUT_TIME_VARYING: std::ops::Range<u64> = 1000..1010;
const HELD_OUT_TWO_EFFECTS: std::ops::Range<u64> = 1000..1010;
/// The static cases timed at 5000 samples per record.
const HELD_OUT_SPEED: std::ops::Range<u64> = 1000..1020;
/// Per kind of effect-free case (LTI, an unmodelled resonance, outliers): 15 cases in all.
const HELD_OUT_EFFECT_FREE: std::ops::Range<u64> = 1000..1005;

fn run(case: &PhysicsCase) -> Discovery {
    let nominal = Nominal::from_polynomial(&case.nominal).unwrap();
    discover(
        &nominal,
        &case.estimation,
        &case.validation,
        &DiscoverSettings::default(),
    )
    .unwrap_or_else(|e| panic!("seed {}: discover failed: {e}", case.seed))
}

/// The cases `seeds` of `kind` with their discoveries, run on every core.
fn run_all(kind: PhysicsKind, seeds: std::ops::Range<u64>) -> Vec<(PhysicsCase, Discovery)> {
    let seeds: Vec<u64> = seeds.collect();
    parallel::map(&seeds, |&seed| {
        let case = generate(kind, seed);
        let d = run(&case);
        (case, d)
    })
}

/// Dynamic case `seed` through the workflow; its finding must be dynamic.
fn dynamic_finding(seed: u64) -> (PhysicsCase, Discovery) {
    let case = generate(PhysicsKind::Dynamic, seed);
    let d = run(&case);
    eprintln!("{}", line(&case, &d));
    let f = d
        .finding
        .as_ref()
        .unwrap_or_else(|| panic!("seed {seed}: {}", d.verdict));
    assert_eq!(f.classification, Classification::Dynamic, "{}", d.verdict);
    (case, d)
}

/// The validation RMS of the true G with the true static map at the true site, scored as
/// `scoring` (None for dynamic effects).
fn truth_rms(case: &PhysicsCase, scoring: Scoring) -> Option<f64> {
    let (effect, site) = case.effect.as_ref()?;
    effect.eval(0.0)?;
    let nominal = Nominal::from_polynomial(&case.true_nominal).ok()?;
    let h = nominal
        .hypothesis(*site, Arc::new(PolynomialDispersion::new(1).ok()?))
        .ok()?;
    // The initial state as the workflow treats it at that site (a sensor map's z = G·u is
    // computed from rest).
    let settings = ValidationSettings::builder()
        .initial_state(initial_state(*site).1)
        .scoring(scoring)
        .build()
        .ok()?;
    let map = |z: &[f64]| effect.eval(z[0]).unwrap_or(f64::NAN);
    let v = validate(
        &h.model,
        &[&map],
        &h.data(&case.validation).ok()?,
        &settings,
    )
    .ok()?;
    Some(v.rms[0])
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// One line describing a case and what the workflow reported.
fn line(case: &PhysicsCase, d: &Discovery) -> String {
    let truth = case
        .expected
        .as_ref()
        .map(|e| format!("{} at {}", e.family, e.site.name()))
        .unwrap_or_else(|| "none".into());
    let found = d
        .finding
        .as_ref()
        .map(|f| {
            let what = match &f.classification {
                Classification::Named(fit) => {
                    format!("{} {:.3?}", fit.effect.name(), fit.all_values())
                }
                other => other.describe(),
            };
            format!("{what} at {} (shrink {:.1}×)", f.location.name(), f.shrink)
        })
        .unwrap_or_else(|| "nothing".into());
    // The rival G against σ̂ (it closes the gap within 1.5·σ̂), and the paired test's p that
    // the finding is better than it.
    let rival = d
        .linear_rival
        .as_ref()
        .map(|r| {
            format!(
                " [G+mode RMS {:.2}·σ̂, p better {:.3}]",
                r.validation_rms / d.noise.std,
                r.comparison.as_ref().map_or(f64::NAN, |c| 1.0 - c.p_worse)
            )
        })
        .unwrap_or_default();
    format!(
        "seed {:2} [{:?} {:?} delay {} {:?} {} noise{}]: {truth} → {:?}: {found}{rival}, {:.1} s",
        case.seed,
        case.plant.kind,
        case.control,
        case.plant.delay,
        case.nominal_source,
        if case.validation_scale > 1.0 {
            "larger val,"
        } else {
            ""
        },
        if case.noise_ar.is_some() {
            " coloured"
        } else {
            ""
        },
        d.verdict_kind,
        d.seconds
    )
}

struct Tally {
    cases: usize,
    estimated: usize,
    located: usize,
    named: usize,
    with_keys: usize,
    within: usize,
    shrinks: Vec<f64>,
    /// Shrink over the true model's shrink.
    relative: Vec<f64>,
}

fn static_tally(seeds: std::ops::Range<u64>) -> Tally {
    let mut t = Tally {
        cases: 0,
        estimated: 0,
        located: 0,
        named: 0,
        with_keys: 0,
        within: 0,
        shrinks: Vec::new(),
        relative: Vec::new(),
    };
    for (case, d) in run_all(PhysicsKind::Static, seeds) {
        let expected: &Expected = case.expected.as_ref().unwrap();
        t.cases += 1;
        t.estimated += usize::from(case.nominal_source != NominalSource::Exact);
        let (mut located, mut named, mut within) = (false, false, None);
        let mut shrink = 1.0;
        if let Some(f) = &d.finding {
            located =
                f.location == expected.site || f.equivalent_locations.contains(&expected.site);
            if let Classification::Named(fit) = &f.classification {
                let j = expected.judge(fit, 0.2);
                named = j.named;
                within = j.parameters;
            }
            shrink = f.shrink;
        }
        t.located += usize::from(located);
        t.named += usize::from(named && located);
        t.with_keys += usize::from(named && located && within.is_some());
        t.within += usize::from(named && located && within == Some(true));
        t.shrinks.push(shrink);
        let truth = truth_rms(&case, d.scoring)
            .map(|r| d.validation_gap.rms / r)
            .unwrap_or(f64::NAN);
        t.relative.push(shrink / truth);
        eprintln!(
            "{} | located {located} named {named} params {within:?} | truth shrink {truth:.1}×",
            line(&case, &d)
        );
    }
    t
}

/// The static summary line, and the median shrink and its share of the true model's.
fn summary(t: &Tally) -> (f64, f64) {
    let m = median(t.shrinks.clone());
    let relative = median(
        t.relative
            .iter()
            .map(|r| if r.is_nan() { 0.0 } else { *r })
            .collect(),
    );
    eprintln!(
        "static: {} cases ({} estimated nominals): located {}, named {}, parameters within 20 % {}/{}, median shrink {m:.1}× ({:.0} % of the true model's)",
        t.cases,
        t.estimated,
        t.located,
        t.named,
        t.within,
        t.with_keys,
        100.0 * relative
    );
    assert!(
        (0.35..=0.65).contains(&(t.estimated as f64 / t.cases as f64)),
        "{} estimated nominals of {}",
        t.estimated,
        t.cases
    );
    (m, relative)
}

/// The static cases, held out: a floor under what the workflow achieves, so that a change
/// that loses ground fails. Measured with the candidate table's rule and named alternatives
/// chosen by its paired test: located 53, named 48 of 60, key parameters 35 of 45, a median
/// 100 % of the true model's shrink (with a fixed factor for the alternatives: 52, 46, 35 of
/// 44, 100 %). The issue's goals are [`static_goals_of_the_issue`].
///
/// A saturation at the input is judged by its knee, the actuator's limit in u
/// ([`EffectFit::derived`](structid_discover::effects::EffectFit::derived)): with G estimated
/// along with the map, its fitted level follows G's gain while the knee is the truth's. The
/// misses are mostly friction under a stiff PD controller, whose levels the sampled LFT (a held
/// force, a backward-difference rate) fits lower and whose viscous slopes it fits steeper than
/// the physics, and springs behind nominals estimated in closed loop, reported as dynamic.
#[test]
fn static_effects_on_physical_plants_hold_their_level() {
    let t = static_tally(HELD_OUT_STATIC);
    let (_, relative) = summary(&t);
    let n = t.cases as f64;
    assert!(
        t.located as f64 >= 0.8 * n,
        "located {}/{}",
        t.located,
        t.cases
    );
    assert!(t.named as f64 >= 0.65 * n, "named {}/{}", t.named, t.cases);
    assert!(
        t.within as f64 >= 0.7 * t.with_keys as f64,
        "parameters within 20 % {}/{}",
        t.within,
        t.with_keys
    );
    assert!(
        relative >= 0.9,
        "{:.0} % of the true model's shrink",
        100.0 * relative
    );
}

/// The issue's goals on the held-out static cases (run with `--ignored`; not met: see
/// [`static_effects_on_physical_plants_hold_their_level`]).
#[test]
#[ignore]
fn static_goals_of_the_issue() {
    let t = static_tally(HELD_OUT_STATIC);
    let (_, relative) = summary(&t);
    let n = t.cases as f64;
    assert!(
        t.located as f64 >= 0.95 * n,
        "located {}/{}",
        t.located,
        t.cases
    );
    assert!(t.named as f64 >= 0.9 * n, "named {}/{}", t.named, t.cases);
    assert!(t.within as f64 >= 0.85 * t.with_keys as f64);
    assert!(relative >= 0.9);
}

/// The static cases the rules may be tuned on (run with `--ignored`).
#[test]
#[ignore]
fn static_effects_of_the_tuning_seeds() {
    let t = static_tally(0..60);
    let (_, relative) = summary(&t);
    assert!(t.located as f64 >= 0.9 * t.cases as f64 && relative >= 0.8);
}

fn dynamic_tally(seeds: std::ops::Range<u64>) -> usize {
    let mut dynamic = 0;
    let cases = seeds.end - seeds.start;
    for (case, d) in run_all(PhysicsKind::Dynamic, seeds) {
        assert!(case.expected.as_ref().unwrap().is_dynamic());
        let is_dynamic = d
            .finding
            .as_ref()
            .is_some_and(|f| f.classification == Classification::Dynamic);
        eprintln!("{} | dynamic {is_dynamic}", line(&case, &d));
        dynamic += usize::from(is_dynamic);
    }
    eprintln!("dynamic: {dynamic}/{cases}");
    dynamic
}

/// The held-out hysteresis cases (backlash and Bouc–Wen at the input, the sensor and in
/// feedback): at least 80 % reported as dynamic (measured 12 of 15, with the rules before the
/// candidate table too). The issue asks for 85 %: [`dynamic_goal_of_the_issue`]. The misses
/// are springs with play in feedback behind nominals estimated in closed loop.
#[test]
fn hysteresis_on_physical_plants_is_reported_as_dynamic() {
    let cases = HELD_OUT_DYNAMIC.end - HELD_OUT_DYNAMIC.start;
    let dynamic = dynamic_tally(HELD_OUT_DYNAMIC);
    assert!(dynamic as f64 >= 0.8 * cases as f64, "{dynamic}/{cases}");
}

/// The issue's goal for hysteresis (run with `--ignored`; not met).
#[test]
#[ignore]
fn dynamic_goal_of_the_issue() {
    let cases = HELD_OUT_DYNAMIC.end - HELD_OUT_DYNAMIC.start;
    let dynamic = dynamic_tally(HELD_OUT_DYNAMIC);
    assert!(dynamic as f64 >= 0.85 * cases as f64, "{dynamic}/{cases}");
}

/// The hysteresis cases the rules may be tuned on (run with `--ignored`).
#[test]
#[ignore]
fn dynamic_effects_of_the_tuning_seeds() {
    let dynamic = dynamic_tally(0..30);
    assert!(dynamic >= 24, "{dynamic}/30");
}

/// How many of the drifting-gain cases `seeds` are reported as time-varying.
fn time_varying_tally(seeds: std::ops::Range<u64>) -> usize {
    let mut flagged = 0;
    let cases = seeds.end - seeds.start;
    for (case, d) in run_all(PhysicsKind::TimeVarying, seeds) {
        let time_varying = d
            .finding
            .as_ref()
            .is_some_and(|f| matches!(f.classification, Classification::TimeVarying(_)));
        eprintln!("{} | time-varying {time_varying}", line(&case, &d));
        flagged += usize::from(time_varying);
    }
    eprintln!("time-varying: {flagged}/{cases}");
    flagged
}

/// The held-out drifting gains: at least 60 % flagged as time-varying (measured 7 of 10, and 1
/// of 10 before a gain in series with the best model was probed behind every verdict). The
/// issue asks for 80 %: [`a_drifting_gain_is_flagged_as_time_varying`]. The misses are a
/// drifting actuator inside a stiff position loop, which the loop hides, and gaps that no
/// block explains and where the probe's fit fails on a segment.
#[test]
fn drifting_gains_are_flagged_as_time_varying() {
    let cases = HELD_OUT_TIME_VARYING.end - HELD_OUT_TIME_VARYING.start;
    let flagged = time_varying_tally(HELD_OUT_TIME_VARYING);
    assert!(flagged as f64 >= 0.6 * cases as f64, "{flagged}/{cases}");
}

/// The issue's goal: a gain drifting by 10–20 % over the record is flagged as time-varying
/// in at least 80 % of the cases (run with `--ignored`; not met: 7 of 10).
#[test]
#[ignore]
fn a_drifting_gain_is_flagged_as_time_varying() {
    let cases = HELD_OUT_TIME_VARYING.end - HELD_OUT_TIME_VARYING.start;
    let flagged = time_varying_tally(HELD_OUT_TIME_VARYING);
    assert!(flagged as f64 >= 0.8 * cases as f64, "{flagged}/{cases}");
}

/// The drifting gains the stationarity test may be tuned on (run with `--ignored`; 26 of 40
/// flagged).
#[test]
#[ignore]
fn drifting_gains_of_the_tuning_seeds() {
    let flagged = time_varying_tally(0..40);
    assert!(flagged >= 24, "{flagged}/40");
}

#[test]
fn lti_physical_plants_raise_no_false_alarm() {
    let cases = HELD_OUT_LTI.end - HELD_OUT_LTI.start;
    let mut alarms = 0;
    for (case, d) in run_all(PhysicsKind::None, HELD_OUT_LTI) {
        let alarm = d.verdict_kind != Verdict::NoMissingEffect;
        eprintln!("{} | alarm {alarm}", line(&case, &d));
        alarms += usize::from(alarm);
    }
    eprintln!("LTI: {alarms} false alarms in {cases}");
    assert!(alarms <= 1, "{alarms} false alarms in {cases}");
}

/// An integrating nominal gets an input-disturbance noise path; for an estimated double
/// integrator whose numerator has a zero outside the unit circle that path cannot be whitened
/// stably, and every location used to fail with the solver's refusal. Each location is then
/// identified with the nominal model's own noise path instead.
#[test]
fn a_disturbance_path_that_cannot_be_whitened_falls_back_to_the_nominal_noise_path() {
    let case = generate(PhysicsKind::Static, 52);
    assert_ne!(case.nominal_source, NominalSource::Exact);
    let d = run(&case);
    assert!(d.input_noise.is_some(), "{:?}", d.scoring);
    let identified = d
        .hypotheses
        .iter()
        .filter(|h| h.failure.is_none() && h.validation_rms.is_finite())
        .count();
    assert!(identified >= 1, "{}", d.verdict);
}

/// A nominal fitted by output error to a closed-loop record with friction puts a zero on its
/// fixed integrator (seed 57: a dead zone under a PD controller). Whatever the verdict, it
/// must say that this G does not integrate, and why that matters.
#[test]
fn a_nominal_whose_zero_cancels_its_integrator_is_called_out() {
    let case = generate(PhysicsKind::Static, 57);
    assert_eq!(case.nominal_source, NominalSource::EstimatedOe);
    // independently of the library's ratio: the one zero −b₂/b₁ of B = b₁q⁻¹ + b₂q⁻² is
    // within 0.1 of z = 1
    let b = &case.nominal.num[0];
    assert!((-b[2] / b[1] - 1.0).abs() < 0.1, "{b:?}");
    let d = run(&case);
    let remarks = d
        .finding
        .as_ref()
        .map(|f| f.remarks.join(" "))
        .unwrap_or_default();
    assert!(
        d.verdict.contains("does not integrate") || remarks.contains("does not integrate"),
        "{}",
        d.verdict
    );
    // the exact nominal carries no such remark
    let exact = Nominal::from_polynomial(&case.true_nominal).unwrap();
    let d = discover(
        &exact,
        &case.estimation,
        &case.validation,
        &DiscoverSettings::default(),
    )
    .unwrap();
    assert!(!d.verdict.contains("does not integrate"), "{}", d.verdict);
    assert!(
        d.finding
            .as_ref()
            .is_none_or(|f| f.remarks.iter().all(|r| !r.contains("does not integrate")))
    );
}

/// The discovery of `case`, whose estimated nominal's one zero −b₂/b₁ lies within 0.1 of
/// z = 1 (checked here, independently of the library's ratio), asserted to name a missing
/// effect at the site where the case's effect acts.
fn found_where_it_acts_behind_a_cancelled_g(case: &PhysicsCase) -> Discovery {
    assert_eq!(case.nominal_source, NominalSource::EstimatedOe);
    let b = &case.nominal.num[0];
    assert!((-b[2] / b[1] - 1.0).abs() < 0.1, "{b:?}");
    let d = run(case);
    eprintln!("{}", line(case, &d));
    let f = d.finding.as_ref().expect("a finding");
    assert_eq!(d.verdict_kind, Verdict::MissingEffect, "{}", d.verdict);
    assert_eq!(
        f.location.name(),
        case.expected.as_ref().unwrap().site.name(),
        "{}",
        d.verdict
    );
    d
}

/// Coulomb friction with an offset on an integrating axis under a PD controller (seed 27),
/// behind a nominal fitted by output error to the closed-loop record: its zero cancels the
/// integrator, and with the friction map fed back through it the loop does not even
/// simulate. Refitting G at every location, the rate's loop started from G fitted with the
/// measured rate, must find the friction where it acts and close at least half the gap the
/// true model closes; the G kept must no longer cancel its integrator.
#[test]
fn friction_behind_a_closed_loop_fit_of_g_is_found_at_the_rate() {
    let case = generate(PhysicsKind::Static, 27);
    let d = found_where_it_acts_behind_a_cancelled_g(&case);
    let f = d.finding.as_ref().unwrap();
    let truth = truth_rms(&case, d.scoring).unwrap();
    let true_shrink = d.validation_gap.rms / truth;
    assert!(
        f.shrink >= 0.5 * true_shrink && f.shrink >= 10.0,
        "shrink {:.1}× against the true model's {true_shrink:.1}×",
        f.shrink
    );
    // G as kept: its zero −b₂/b₁ is no longer within 0.1 of z = 1, where it cancelled the
    // integrator
    let kept = &f.nominal_refinement.as_ref().expect("G refitted").after;
    let b = &kept.num[0];
    assert!((-b[2] / b[1] - 1.0).abs() >= 0.1, "{b:?}");
}

/// Coulomb friction with an offset on a double integrator under a PD controller (seed 55),
/// behind an output-error fit of the closed-loop record whose zero cancels an integrator:
/// around that G every feedback loop diverges and no block explains the gap. Around G with
/// the zero moved to z = −1 and its gain fitted, the friction is found where it acts. The
/// report stays against the nominal as given: its gap is that G's own simulation error, and
/// the shrink is over it.
#[test]
fn friction_behind_a_diverging_closed_loop_fit_is_found_around_an_integrating_g() {
    let case = generate(PhysicsKind::Static, 55);
    let d = found_where_it_acts_behind_a_cancelled_g(&case);
    let f = d.finding.as_ref().unwrap();
    assert!(
        f.remarks.iter().any(|r| r.contains("moved to z = −1")),
        "{:?}",
        f.remarks
    );
    // The gap before: the given nominal alone, simulated here as the workflow scores it.
    let given = Nominal::from_polynomial(&case.nominal).unwrap();
    let settings = ValidationSettings::builder()
        .initial_state(DiscoverSettings::default().gap().initial_state)
        .scoring(d.scoring)
        .build()
        .unwrap();
    let v = validate(&given.model().unwrap(), &[], &case.validation, &settings).unwrap();
    assert!(
        (d.validation_gap.rms - v.rms[0]).abs() <= 1e-9 * v.rms[0],
        "{} vs {}",
        d.validation_gap.rms,
        v.rms[0]
    );
    let shrink = v.rms[0] / f.augmented.validation_gap.rms;
    assert!((f.shrink - shrink).abs() <= 1e-9 * shrink);
    assert!(f.shrink >= 4.0, "{}", d.verdict);
    // G before is the nominal as given (its u → y numerator and denominator).
    let before = &f
        .nominal_refinement
        .as_ref()
        .expect("G before and after")
        .before;
    assert_eq!(before.den, case.nominal.den);
    assert_eq!(before.num[0], case.nominal.num[0]);
}

/// Asymmetric friction on an integrating axis under a PD controller, exact nominal: the input
/// disturbance sized on the nominal model's residual lets its one-step predictor follow the
/// output, so that the innovations pass every test although the windowed simulation misses
/// by about ten noise levels. The workflow must still go on to the hypotheses and find the
/// friction where it acts, shrinking the gap by more than a disturbance could.
#[test]
fn friction_that_a_fitted_input_disturbance_hides_from_the_tests_is_still_found() {
    let case = generate(PhysicsKind::Static, 11);
    let expected = case.expected.as_ref().unwrap();
    let d = run(&case);
    eprintln!("{}", line(&case, &d));
    // The situation the rule exists for: every test passed on both records.
    assert!(d.input_noise.is_some());
    assert!(!d.estimation_gap.missing_effect && !d.validation_gap.missing_effect);
    assert!(d.validation_gap.rms > 3.0 * case.noise_std);
    assert_eq!(d.verdict_kind, Verdict::MissingEffect, "{}", d.verdict);
    let f = d.finding.as_ref().unwrap();
    assert!(
        f.location == expected.site || f.equivalent_locations.contains(&expected.site),
        "{}",
        d.verdict
    );
    assert!(f.shrink >= 1.5, "{}", d.verdict);
}

/// A block that closes a sliver of a large gap (dynamic seed 0: a backlash at the input of a
/// non-minimum-phase plant, for which a static map gains about 1.1×) is reported with the part
/// of the gap it leaves, in the verdict and the finding's remarks; a block that closes the
/// gap (static seed 22: a hardening spring in feedback, about 100×) is not.
#[test]
fn a_block_that_explains_part_of_the_gap_says_what_it_leaves() {
    let case = generate(PhysicsKind::Dynamic, 0);
    let d = run(&case);
    eprintln!("{}", line(&case, &d));
    assert_eq!(d.verdict_kind, Verdict::MissingEffect, "{}", d.verdict);
    let f = d.finding.as_ref().unwrap();
    let left = f.augmented.validation_gap.rms / d.noise.std;
    assert!(f.shrink < 2.0 && left > 1.5, "{}", d.verdict);
    assert!(d.verdict.contains("Only part of the gap"), "{}", d.verdict);
    assert!(f.remarks.iter().any(|r| r.contains("explains only part")));
    let case = generate(PhysicsKind::Static, 22);
    let d = run(&case);
    let f = d.finding.as_ref().unwrap();
    assert!(f.shrink > 10.0, "{}", d.verdict);
    assert!(!d.verdict.contains("Only part of the gap"), "{}", d.verdict);
}

/// The hypotheses tried are labelled by the estimator that was tried: a total-variation fit
/// whose β selection ended on its bound is listed as a total-variation attempt with that
/// reason, not as a numerical failure of the smooth estimate (dynamic seed 8: a backlash in
/// feedback that no static block explains).
#[test]
fn an_unexplained_gap_lists_each_attempt_under_its_own_estimator() {
    let case = generate(PhysicsKind::Dynamic, 8);
    let d = run(&case);
    assert_eq!(d.verdict_kind, Verdict::Unexplained, "{}", d.verdict);
    assert!(
        !d.verdict
            .contains("(quadratic): β on its search bound: total variation"),
        "{}",
        d.verdict
    );
    assert!(
        !d.verdict.contains("numerical failure: total variation"),
        "{}",
        d.verdict
    );
    // every failed total-variation attempt is recorded with its estimator
    for h in d.hypotheses.iter().filter(|h| {
        h.failure
            .as_deref()
            .is_some_and(|f| f.contains("total variation: the validation selection"))
    }) {
        assert_eq!(h.dispersion, "tv", "{:?}", h.failure);
    }
    assert!(d.verdict.contains("(total variation)"), "{}", d.verdict);
}

/// A family that the map fit ranks behind others is still named when it is the one that
/// validates (static seed 28: an actuator saturation inside a PD loop, exact nominal). The
/// map's input there is the controller's output, which carries the differentiated sensor
/// noise, so the nonparametric map blurs the saturation's corners and a gain error, a
/// one-sided clip and a cubic fit its points better. Refined by output error, those three
/// validate far worse than the saturation, which comes close to the true model.
#[test]
fn a_family_ranked_behind_others_by_its_map_fit_is_named_when_it_validates() {
    let case = generate(PhysicsKind::Static, 28);
    let d = run(&case);
    eprintln!("{}", line(&case, &d));
    let f = d.finding.as_ref().unwrap();
    let Classification::Named(fit) = &f.classification else {
        panic!("not named: {}", d.verdict)
    };
    let judged = case.expected.as_ref().unwrap().judge(fit, 0.2);
    assert!(
        judged.named && judged.parameters == Some(true),
        "{}",
        d.verdict
    );
    let at = f
        .naming
        .ranked
        .iter()
        .position(|r| r.effect == fit.effect)
        .unwrap();
    let named_rms = f.family_rms[at].unwrap();
    let ahead: Vec<f64> = f.family_rms[..at].iter().flatten().copied().collect();
    assert!(ahead.len() >= 3, "{ahead:?}");
    assert!(
        ahead.iter().all(|r| *r > 5.0 * named_rms),
        "{ahead:?} against {named_rms}"
    );
    let truth = d.validation_gap.rms / truth_rms(&case, d.scoring).unwrap();
    assert!(
        f.shrink >= 0.8 * truth,
        "{} against the truth's {truth}",
        f.shrink
    );
}

/// A map of the rate that barely beats the position's static approximation does not turn a
/// direction effect seen from the position into friction (dynamic seed 5: a spring behind a
/// play under PD control, with a nominal estimated from the record; a relay of ẏ closed a
/// tenth of the gap and was named Coulomb friction at 61× the force the loop can see). The
/// hysteresis is reported where it acts.
#[test]
fn a_rate_map_that_barely_beats_the_position_does_not_hide_a_hysteresis() {
    let (case, d) = dynamic_finding(5);
    let f = d.finding.as_ref().unwrap();
    assert_eq!(
        f.location,
        case.expected.as_ref().unwrap().site,
        "{}",
        d.verdict
    );
    // The rate was tried, and its best fit neither validates clearly better than the
    // finding's static approximation nor closes the gap.
    let rate = d
        .hypotheses
        .iter()
        .filter(|h| h.location == Site::RateFeedback)
        .map(|h| h.validation_rms)
        .fold(f64::INFINITY, f64::min);
    assert!(rate.is_finite());
    assert!(
        !rate_explains(
            rate,
            d.validation_gap.rms / rate,
            f.augmented.validation_gap.rms
        ),
        "rate {rate} against {}, gap {}",
        f.augmented.validation_gap.rms,
        d.validation_gap.rms
    );
}

/// A dynamic finding whose static approximation closes little of the gap says that the
/// direction effect is not located by it (dynamic seed 1: a backlash in a sensor's drive,
/// 1.0×); one that closes most of the gap does not (seed 11: a spring behind a play under PD
/// control, about 60×).
#[test]
fn a_direction_effect_that_no_static_map_reduces_is_not_claimed_located() {
    for (seed, unlocated) in [(1, true), (11, false)] {
        let (_, d) = dynamic_finding(seed);
        let f = d.finding.as_ref().unwrap();
        assert_eq!(f.shrink < PARTIAL_SHRINK, unlocated, "{}", d.verdict);
        assert_eq!(
            f.remarks
                .iter()
                .any(|r| r.as_str() == UNLOCATED_DIRECTION_EFFECT),
            unlocated,
            "{:?}",
            f.remarks
        );
    }
}

/// In feedback a direction effect that explains a large share of the residual is a missing
/// (dynamic) effect however little its static approximation closes (dynamic seed 12: a
/// hysteresis under a stiff PD loop, whose gap a fitted input disturbance takes up in
/// prediction but whose simulation misses by 8× the noise; no static block gains anything).
/// The effect-free closed loops of the generator stay below the share
/// (`lti_physical_plants_raise_no_false_alarm`).
#[test]
fn a_strong_direction_effect_in_feedback_is_missing_whatever_the_shrink() {
    let (_, d) = dynamic_finding(12);
    assert_eq!(d.verdict_kind, Verdict::MissingEffect, "{}", d.verdict);
    let f = d.finding.as_ref().unwrap();
    assert!(
        matches!(f.location, Site::OutputFeedback | Site::RateFeedback),
        "{}",
        d.verdict
    );
    assert!(
        f.direction.explained >= FEEDBACK_HYSTERESIS_SHARE,
        "{:?}",
        f.direction
    );
    assert!(f.shrink < 1.05, "{}", d.verdict);
    assert!(d.validation_gap.rms > 3.0 * d.noise.std, "{}", d.verdict);
}

/// A hysteresis at the actuator behind a nominal estimated from its own record: the estimated
/// G absorbed part of its phase lag, no static block closes more than a sliver of the gap,
/// and the direction test on the static fits stays below its threshold. The hysteresis
/// fitted at the input with G re-estimated behind it makes the finding dynamic, at the
/// input, with its parameters judged against the generator's truth: dynamic seed 0 is a play
/// of half-width 0.133, found as a play (λ near −1) with that half-width to 10 %; seed 9 is a
/// Bouc–Wen element (α = 0.14, n = 1, its hysteretic part saturating at 1/(β + γ) ≈ 160),
/// found as an elasto-plastic stop (λ > 0) yielding within 20 % of that level.
#[test]
fn a_hysteresis_at_the_input_behind_an_estimated_nominal_is_dynamic_with_its_parameters() {
    use structid_testcases::physics::PhysicalEffect;
    for seed in [0, 9] {
        let (case, d) = dynamic_finding(seed);
        assert_ne!(case.nominal_source, NominalSource::Exact);
        let f = d.finding.as_ref().unwrap();
        assert_eq!(f.location, Site::Input, "{}", d.verdict);
        let h = f.input_hysteresis.as_ref().expect("the input hysteresis");
        // It explains more than half of what the static approximation leaves.
        assert!(
            h.validation_rms <= std::f64::consts::FRAC_1_SQRT_2 * f.augmented.validation_gap.rms,
            "{h:?}"
        );
        match case.effect.as_ref().unwrap().0 {
            PhysicalEffect::Backlash { width, .. } => {
                assert!(h.is_play(), "{h:?}");
                assert!(
                    (h.threshold - width).abs() <= 0.1 * width,
                    "{h:?} vs {width}"
                );
            }
            PhysicalEffect::BoucWen { beta, gamma, .. } => {
                assert!(!h.is_play() && h.weight > 0.0, "{h:?}");
                let level = 1.0 / (beta + gamma);
                assert!(
                    (h.threshold - level).abs() <= 0.2 * level,
                    "{h:?} vs {level}"
                );
            }
            ref other => panic!("seed {seed}: {other:?} is not a hysteresis"),
        }
        assert!(d.verdict.contains("at the input"), "{}", d.verdict);
    }
}

/// How many of the two-effect cases `seeds` have both effects located by two adopted steps of
/// [`discover_effects`] (at most two effects).
fn two_effects_tally(seeds: std::ops::Range<u64>) -> usize {
    let mut both = 0;
    let cases = seeds.end - seeds.start;
    for seed in seeds {
        let case = generate(PhysicsKind::TwoEffects, seed);
        let nominal = Nominal::from_polynomial(&case.nominal).unwrap();
        let first = case.expected.as_ref().unwrap();
        let (_, second) = case.second.as_ref().unwrap();
        let effects = match discover_effects(
            &nominal,
            &case.estimation,
            &case.validation,
            &DiscoverSettings::default(),
            &EffectsSettings::default().with_max_effects(2).unwrap(),
        ) {
            Ok(effects) => effects,
            Err(e) => {
                eprintln!(
                    "seed {seed}: {} at {} + {} at {} → failed: {e}",
                    first.family,
                    first.site.name(),
                    second.family,
                    second.site.name()
                );
                continue;
            }
        };
        let findings = effects.findings();
        let at = |site| {
            findings
                .iter()
                .position(|f| f.location == site || f.equivalent_locations.contains(&site))
        };
        let found = matches!((at(first.site), at(second.site)), (Some(a), Some(b)) if a != b);
        let steps: Vec<String> = effects
            .steps
            .iter()
            .map(|s| line(&case, &s.discovery))
            .collect();
        eprintln!(
            "seed {seed}: {} at {} + {} at {} → both {found} ({:?})\n    {}",
            first.family,
            first.site.name(),
            second.family,
            second.site.name(),
            effects.stop,
            steps.join("\n    ")
        );
        both += usize::from(found);
    }
    eprintln!("two effects: both found in {both}/{cases}");
    both
}

/// The issue's goal: with two static effects at two sites, `--effects 2` finds both in at
/// least 80 % of the cases (run with `--ignored`; not met, measured 3 of 10, and 11 of the
/// first 20 cases the iteration may be tuned on: the second-block rows find an effect that the
/// first map hid where the plant is open loop, a static reading of a dynamic-looking step finds
/// friction beside a hardening or cubic spring, and a second map behind a sensor map is fitted
/// by simulation error; Stribeck friction beside a spring, and friction beside an actuator
/// effect in a position loop, still read as a direction effect or leave a second map that
/// gains less than the required share).
#[test]
#[ignore]
fn two_effects_goal_of_the_issue() {
    let cases = HELD_OUT_TWO_EFFECTS.end - HELD_OUT_TWO_EFFECTS.start;
    let both = two_effects_tally(HELD_OUT_TWO_EFFECTS);
    assert!(both as f64 >= 0.8 * cases as f64, "{both}/{cases}");
}

/// The two-effect cases the iteration may be tuned on (run with `--ignored`).
#[test]
#[ignore]
fn two_effects_of_the_tuning_seeds() {
    let seeds = std::env::var("TWO_EFFECTS_SEEDS")
        .ok()
        .and_then(|v| {
            v.split_once("..")
                .map(|(a, b)| (a.parse().ok(), b.parse().ok()))
        })
        .and_then(|(a, b)| Some(a?..b?))
        .unwrap_or(0..10);
    let n = seeds.end - seeds.start;
    let both = two_effects_tally(seeds);
    assert!(both as f64 >= 0.8 * n as f64, "{both}/{n}");
}

/// Friction beside a hardening spring in a position loop leaves a direction dependence at
/// the spring's site, so that the first step reads as dynamic there. Read statically, the
/// spring is named, and the next step finds the friction: together they validate better than
/// the dynamic reading by the required share, and `--effects 2` reports both, the first step
/// keeping its dynamic reading.
#[test]
fn friction_beside_a_spring_is_read_as_two_static_effects() {
    let case = generate(PhysicsKind::TwoEffects, 8);
    let (second, _) = case.second.as_ref().unwrap();
    assert_eq!(
        (case.effect.as_ref().unwrap().1, second.1),
        (Site::OutputFeedback, Site::RateFeedback)
    );
    let nominal = Nominal::from_polynomial(&case.nominal).unwrap();
    let effects = discover_effects(
        &nominal,
        &case.estimation,
        &case.validation,
        &DiscoverSettings::default(),
        &EffectsSettings::default().with_max_effects(2).unwrap(),
    )
    .unwrap();
    let dynamic = effects.steps[0]
        .dynamic
        .as_ref()
        .expect("the first step's dynamic reading");
    let d = dynamic.finding.as_ref().unwrap();
    assert_eq!(
        d.classification,
        Classification::Dynamic,
        "{}",
        dynamic.verdict
    );
    let found: Vec<Site> = effects.findings().iter().map(|f| f.location).collect();
    assert_eq!(found, vec![Site::OutputFeedback, Site::RateFeedback]);
    let last = effects.last().unwrap().augmented.validation_gap.rms;
    assert!(
        last <= 0.9 * d.augmented.validation_gap.rms,
        "{last} vs {d:?}"
    );
}

/// A friction map adopted in a first step reads ẏ, which the input disturbance of an
/// integrating plant drives: with that disturbance as a second noise channel, the map's z has
/// no causal filter from y. The second step then searches with the output noise alone instead
/// of failing.
#[test]
fn a_known_friction_map_behind_an_integrator_is_searched_around() {
    let case = generate(PhysicsKind::TwoEffects, 1);
    let nominal = Nominal::from_polynomial(&case.nominal).unwrap();
    let first = run(&case);
    let f = first.finding.as_ref().expect("a first finding");
    assert_eq!(f.location, Site::RateFeedback, "{}", first.verdict);
    let next = f.augmented.as_nominal(&nominal).unwrap();
    assert_eq!(next.known_maps().len(), 1);
    let second = discover(
        &next,
        &case.estimation,
        &case.validation,
        &DiscoverSettings::default(),
    );
    let second = second.unwrap_or_else(|e| panic!("the second step failed: {e}"));
    assert!(second.input_noise.is_none(), "{:?}", second.input_noise);
}

/// How many effect-free cases of `kinds` over `seeds` raise an alarm: a block claimed as a
/// missing effect. "The linear model was wrong" is the right verdict for an unmodelled
/// resonance, and an unexplained gap claims no effect; both are printed.
fn false_alarms(kinds: &[PhysicsKind], seeds: std::ops::Range<u64>) -> (usize, usize) {
    let (mut alarms, mut cases) = (0, 0);
    for &kind in kinds {
        for (case, d) in run_all(kind, seeds.clone()) {
            let alarm = d.verdict_kind == Verdict::MissingEffect;
            eprintln!("{kind:?} {} | alarm {alarm}", line(&case, &d));
            alarms += usize::from(alarm);
            cases += 1;
        }
    }
    eprintln!("effect-free: {alarms} false alarms in {cases}");
    (alarms, cases)
}

const EFFECT_FREE: [PhysicsKind; 3] = [
    PhysicsKind::None,
    PhysicsKind::Resonance,
    PhysicsKind::Outliers,
];

/// The issue's goal: at most one false alarm in 15 effect-free cases, an unmodelled resonance
/// and outliers in the noise among them. Measured 0 in 15: three resonances are "the linear
/// model was wrong" (one of them, whose residual depends on the direction of motion as a
/// hysteresis's does, since the linear rival also judges dynamic findings; before, it was
/// reported as dynamic), two are "no missing effect", and every outlier case is "no missing
/// effect" (before isolated spikes were left out of the noise comparison, two were
/// unexplained gaps).
#[test]
fn effect_free_goal_of_the_issue() {
    let (alarms, cases) = false_alarms(&EFFECT_FREE, HELD_OUT_EFFECT_FREE);
    assert!(alarms <= 1, "{alarms} false alarms in {cases}");
}

/// The effect-free cases the rules may be tuned on (run with `--ignored`; see
/// [`effect_free_goal_of_the_issue`]).
#[test]
#[ignore]
fn effect_free_cases_of_the_tuning_seeds() {
    let (alarms, cases) = false_alarms(&EFFECT_FREE, 0..5);
    assert!(alarms <= 1, "{alarms} false alarms in {cases}");
}

/// The issue's speed goal: on records of 5000 samples, one discovery takes at most 10 s in
/// the median and 30 s in every case (run with `--ignored --test-threads 1`, nothing else
/// running: wall times; a timed test, so not run by default). Measured: median 3.7 s, slowest
/// 24.3 s. The criterion bench `discover_25k` times one case at 5000 samples.
#[test]
#[ignore]
fn discovery_speed_on_5000_samples() {
    let mut seconds = Vec::new();
    for seed in HELD_OUT_SPEED {
        let case = generate_with_length(PhysicsKind::Static, seed, 5000);
        let d = run(&case);
        eprintln!("{}", line(&case, &d));
        seconds.push(d.seconds);
    }
    let slowest = seconds.iter().copied().fold(0.0, f64::max);
    let median = median(seconds);
    eprintln!("5000 samples: median {median:.1} s, slowest {slowest:.1} s");
    assert!(
        median <= 10.0 && slowest <= 30.0,
        "median {median:.1} s, slowest {slowest:.1} s"
    );
}

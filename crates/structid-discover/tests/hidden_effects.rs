//! The discovery workflow on data with one hidden effect (`structid_testcases::synthetic`):
//! the workflow sees only the nominal model and the two records.
//!
//! * 30 static cases (every effect/location pair of the generator's schedule): the effect is
//!   named and located correctly in ≥ 90 %, its parameters are within 20 % in ≥ 80 %, and the
//!   median shrink of the validation RMS gap is ≥ 5×;
//! * 20 cases without an effect (LTI plus noise): "no missing effect detected" in ≥ 95 %;
//! * 10 hysteresis cases (backlash and Bouc–Wen): reported as dynamic, not forced into a
//!   static name, in ≥ 80 %.

use structid_discover::discover::{Classification, DiscoverSettings, Discovery, discover};
use structid_discover::hypotheses::Nominal;
use structid_testcases::parallel;
use structid_testcases::synthetic::{Case, CaseKind, Hidden, generate};

fn run(case: &Case) -> Discovery {
    let nominal = Nominal::from_polynomial(&case.nominal).unwrap();
    discover(
        &nominal,
        &case.estimation,
        &case.validation,
        &DiscoverSettings::default(),
    )
    .unwrap()
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

#[test]
fn static_effects_are_named_located_and_close_the_gap() {
    let cases = 30;
    let (mut correct, mut params_ok) = (0, 0);
    let mut shrinks = Vec::new();
    let seeds: Vec<u64> = (0..cases).collect();
    let runs = parallel::map(&seeds, |&seed| {
        let case = generate(CaseKind::Static, seed);
        let d = run(&case);
        (case, d)
    });
    for (seed, (case, d)) in seeds.iter().zip(runs) {
        let Hidden::Static {
            effect,
            theta,
            location,
        } = &case.hidden
        else {
            unreachable!()
        };
        let (named, located, within, shrink) = match &d.finding {
            Some(f) => {
                let named = matches!(&f.classification, Classification::Named(fit) if fit.effect == *effect);
                let located = case.equivalent_locations().contains(&f.location);
                let within = match &f.classification {
                    Classification::Named(fit) if fit.effect == *effect => {
                        case.parameters_within(&fit.values(), 0.2)
                    }
                    _ => false,
                };
                (named, located, within, f.shrink)
            }
            None => (false, false, false, 1.0),
        };
        eprintln!(
            "seed {seed:2}: {:<40} {:<16} θ {:?} → {} at {:?} (named {named}, located {located}, params {within}), shrink {shrink:.1}×, {:.1} s, dir {:?}, {}",
            effect.name(),
            location.name(),
            theta,
            d.finding
                .as_ref()
                .map(|f| match &f.classification {
                    Classification::Named(fit) =>
                        format!("{} {:?}", fit.effect.name(), fit.values()),
                    other => other.describe(),
                })
                .unwrap_or_else(|| "nothing".into()),
            d.finding.as_ref().map(|f| f.location.name()),
            d.seconds,
            d.finding
                .as_ref()
                .map(|f| (f.direction.explained, f.direction.t_statistic)),
            d.finding
                .as_ref()
                .map(|f| f.estimator.clone())
                .unwrap_or_default()
        );
        correct += usize::from(named && located);
        params_ok += usize::from(within);
        shrinks.push(shrink);
    }
    let n = cases as f64;
    let m = median(shrinks);
    eprintln!(
        "static: named and located {correct}/{cases}, parameters within 20 % {params_ok}/{cases}, median shrink {m:.1}×"
    );
    assert!(
        correct as f64 >= 0.9 * n,
        "named and located {correct}/{cases}"
    );
    assert!(
        params_ok as f64 >= 0.8 * n,
        "parameters within 20 % {params_ok}/{cases}"
    );
    assert!(m >= 5.0, "median shrink {m:.2}×");
}

#[test]
fn lti_data_gives_no_missing_effect() {
    let cases = 20;
    let mut quiet = 0;
    let seeds: Vec<u64> = (0..cases).collect();
    let runs = parallel::map(&seeds, |&seed| {
        let case = generate(CaseKind::None, seed);
        let d = run(&case);
        (case, d)
    });
    for (seed, (case, d)) in seeds.iter().zip(runs) {
        if !d.missing_effect {
            quiet += 1;
        } else {
            eprintln!(
                "seed {seed}: false alarm: {}\n  est: {}\n  val: {}\n  input {:?}",
                d.verdict, d.estimation_gap.verdict, d.validation_gap.verdict, case.input
            );
        }
    }
    eprintln!("LTI: no missing effect in {quiet}/{cases}");
    assert!(quiet as f64 >= 0.95 * cases as f64, "{quiet}/{cases}");
}

#[test]
fn hysteresis_is_reported_as_dynamic() {
    let cases = 10;
    let mut dynamic = 0;
    let seeds: Vec<u64> = (0..cases).collect();
    let runs = parallel::map(&seeds, |&seed| {
        let case = generate(CaseKind::Hysteresis, seed);
        let d = run(&case);
        (case, d)
    });
    for (seed, (case, d)) in seeds.iter().zip(runs) {
        let f = d.finding.as_ref();
        let is_dynamic = f.is_some_and(|f| f.classification == Classification::Dynamic);
        eprintln!(
            "seed {seed}: {:?} → {} at {:?} (direction explains {:.2}, t = {:.1}), input {:?}",
            match case.hidden {
                Hidden::Backlash { .. } => "backlash",
                _ => "Bouc–Wen",
            },
            f.map(|f| f.classification.describe())
                .unwrap_or_else(|| "nothing".into()),
            f.map(|f| f.location.name()),
            f.map(|f| f.direction.explained).unwrap_or(0.0),
            f.map(|f| f.direction.t_statistic).unwrap_or(0.0),
            case.input,
        );
        dynamic += usize::from(is_dynamic);
        // A map written as a table (dynamic or unnamed) extrapolates as its hypothesis was
        // scored, so the augmented model validates as well as the hypothesis it came from (up
        // to the table's interpolation).
        if let Some(f) = f
            && !matches!(f.classification, Classification::Named(_))
        {
            let (after, nonparametric) = (f.augmented.validation_gap.rms, f.nonparametric_rms);
            assert!(
                after <= 1.05 * nonparametric,
                "seed {seed}: the table validates at {after:.4e}, its hypothesis at {nonparametric:.4e}"
            );
        }
    }
    eprintln!("hysteresis: dynamic in {dynamic}/{cases}");
    assert!(dynamic as f64 >= 0.8 * cases as f64, "{dynamic}/{cases}");
}

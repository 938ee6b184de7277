//! Discovery from a linear start, against plants whose answer is known: a linear plant (the BLA
//! is the plant, nothing is missing) and a Hammerstein plant (an input saturation the BLA
//! cannot follow on a louder test record).

use rand::{RngExt, SeedableRng, rngs::StdRng};
use structid_core::Data;
use structid_discover::discover::Verdict;
use structid_io::Record;
use structid_linear::PolynomialModel;
use structid_lti::Signal;
use structid_workflow::{
    LinearStartRequest, WorkflowError, discover_from_linear_start, split_for_validation,
};

fn plant() -> PolynomialModel {
    PolynomialModel {
        num: vec![vec![0.0, 0.4, 0.2]],
        den: vec![1.0, -1.3, 0.6],
        sample_time: Some(1.0),
    }
}

/// u uniform in ±amplitude, y = G·N(u) + noise.
fn record(
    n: usize,
    amplitude: f64,
    noise: f64,
    map: fn(f64) -> f64,
    seed: u64,
) -> (Vec<f64>, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let u: Vec<f64> = (0..n)
        .map(|_| amplitude * (2.0 * rng.random::<f64>() - 1.0))
        .collect();
    let v = Signal::new(1, u.iter().map(|&x| map(x)).collect()).unwrap();
    let y = plant()
        .simulate(&v)
        .unwrap()
        .into_iter()
        .map(|y| y + noise * (2.0 * rng.random::<f64>() - 1.0))
        .collect();
    (u, y)
}

fn data((u, y): &(Vec<f64>, Vec<f64>)) -> Data {
    Data::new(
        Signal::new(1, u.clone()).unwrap(),
        Signal::new(1, y.clone()).unwrap(),
    )
    .unwrap()
}

fn test_record((u, y): (Vec<f64>, Vec<f64>)) -> Record {
    Record {
        name: "test".into(),
        range: 0..u.len(),
        u,
        y,
        sample_time: 1.0,
        settle: 20,
    }
}

#[test]
fn a_linear_plant_is_its_own_bla_and_misses_nothing() {
    let est = record(1500, 1.0, 0.01, |u| u, 1);
    let tests = [test_record(record(500, 1.0, 0.0, |u| u, 2))];
    let r =
        discover_from_linear_start(&data(&est), &tests, &LinearStartRequest::default()).unwrap();
    for (a, b) in r.bla.den.iter().zip(&plant().den) {
        assert!((a - b).abs() < 0.02, "{:?}", r.bla.den);
    }
    assert_eq!(
        r.discovery.verdict_kind,
        Verdict::NoMissingEffect,
        "{}",
        r.discovery.verdict
    );
    assert!(r.tests.is_empty());
    assert_eq!(r.fit.len() + r.validation.len(), 1500);
}

#[test]
fn an_input_saturation_is_found_and_shrinks_the_test_error() {
    let sat = |u: f64| u.clamp(-0.6, 0.6);
    let est = record(2000, 1.5, 0.005, sat, 3);
    let tests = [test_record(record(600, 1.5, 0.0, sat, 4))];
    let r =
        discover_from_linear_start(&data(&est), &tests, &LinearStartRequest::default()).unwrap();
    assert_eq!(
        r.discovery.verdict_kind,
        Verdict::MissingEffect,
        "{}",
        r.discovery.verdict
    );
    let t = &r.tests[0];
    assert_eq!(t.record, "test");
    assert!(
        t.augmented_rms < 0.3 * t.bla_rms,
        "BLA {} augmented {}",
        t.bla_rms,
        t.augmented_rms
    );
    // The scores are the RMS over the samples after `settle`, recomputed here.
    let rms = |s: &[f64]| {
        let e: f64 = s[20..]
            .iter()
            .zip(&t.measured[20..])
            .map(|(a, b)| (a - b).powi(2))
            .sum();
        (e / (s.len() - 20) as f64).sqrt()
    };
    assert!((rms(&t.simulated) - t.augmented_rms).abs() < 1e-12);
    assert!((rms(&t.bla_simulated) - t.bla_rms).abs() < 1e-12);
}

#[test]
fn the_validation_part_is_the_tail_of_the_record() {
    let est = data(&record(100, 1.0, 0.0, |u| u, 5));
    let (fit, val) = split_for_validation(&est, 0.25).unwrap();
    assert_eq!((fit.len(), val.len()), (75, 25));
    assert_eq!(val.y().get(0, 0), est.y().get(75, 0));
    for bad in [0.0, 1.0, -0.1, f64::NAN, 0.001] {
        assert!(
            matches!(
                split_for_validation(&est, bad),
                Err(WorkflowError::Request(_))
            ),
            "{bad}"
        );
    }
    // A cut through several records would join them: refused.
    let two = Data::from_records(vec![est.clone(), est.clone()]).unwrap();
    assert!(matches!(
        split_for_validation(&two, 0.25),
        Err(WorkflowError::Core(_))
    ));
}

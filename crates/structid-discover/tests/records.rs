//! Discovery on several records (experiments): each record is simulated from its own initial
//! state, and the pooled gap is the pooled per-record simulation error.
//!
//! The records are simulated by the plant's difference equation written out here,
//! y_k = 1.5·y_(k−1) − 0.7·y_(k−2) + 0.1·(f_(k−1) + f_(k−2)) + e_k with f = sat(u), after a
//! warm-up of its own for every record (dropped), so that each record starts from a different
//! state, as separate experiments do.

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use structid_core::validation::{ValidationSettings, validate};
use structid_core::{Data, InitialState, Signal};
use structid_discover::discover::{Classification, DiscoverSettings, Discovery, discover};
use structid_discover::effects::Effect;
use structid_discover::hypotheses::{Nominal, Site};
use structid_linear::PolynomialModel;

const NOISE: f64 = 0.005;

fn g() -> PolynomialModel {
    PolynomialModel {
        den: vec![1.0, -1.5, 0.7],
        num: vec![vec![0.0, 0.1, 0.1]],
        sample_time: Some(0.05),
    }
}

fn saturation(u: f64) -> f64 {
    (1.5 * u).clamp(-0.8, 0.8)
}

/// One experiment of `len` samples after a warm-up of `warm` samples (dropped) on a filtered
/// noise input with an offset `level` during the warm-up, so that the record starts away
/// from rest.
fn experiment(len: usize, warm: usize, level: f64, seed: u64) -> Data {
    let mut rng = StdRng::seed_from_u64(seed);
    let norm = Normal::new(0.0, 1.0).unwrap();
    let noise = Normal::new(0.0, NOISE).unwrap();
    let n = warm + len;
    let mut s = 0.0;
    let u: Vec<f64> = (0..n)
        .map(|k| {
            s = 0.8 * s + 0.6 * norm.sample(&mut rng);
            if k < warm { level + 0.2 * s } else { s }
        })
        .collect();
    let f: Vec<f64> = u.iter().map(|v| saturation(*v)).collect();
    let mut x = vec![0.0; n];
    for k in 2..n {
        x[k] = 1.5 * x[k - 1] - 0.7 * x[k - 2] + 0.1 * (f[k - 1] + f[k - 2]);
    }
    let y: Vec<f64> = x[warm..]
        .iter()
        .map(|v| v + noise.sample(&mut rng))
        .collect();
    let u = &u[warm..];
    Data::new(
        Signal::from_fn(len, 1, |k, _| u[k]),
        Signal::from_fn(len, 1, |k, _| y[k]),
    )
    .unwrap()
}

fn nominal() -> Nominal {
    Nominal::from_polynomial(&g()).unwrap()
}

/// The records of `data` concatenated as one record (no boundaries).
fn concatenated(data: &Data) -> Data {
    Data::new(data.u().clone(), data.y().clone()).unwrap()
}

/// The nominal model's simulation RMS pooled over the records, each simulated on its own
/// with its initial state estimated (core's `validate`, record by record).
fn pooled_nominal_rms(data: &Data) -> f64 {
    let model = nominal().model().unwrap();
    let settings = ValidationSettings::builder()
        .initial_state(InitialState::Estimate)
        .build()
        .unwrap();
    let (mut sse, mut n) = (0.0, 0usize);
    for r in data.records() {
        let v = validate(&model, &[], &r, &settings).unwrap();
        let count: usize = v.scored.iter().map(|s| s.len()).sum();
        sse += v.rms[0].powi(2) * count as f64;
        n += count;
    }
    (sse / n as f64).sqrt()
}

fn named_saturation(d: &Discovery) -> (f64, f64) {
    let f = d.finding.as_ref().expect("a finding");
    assert_eq!(f.location, Site::Input, "{}", d.verdict);
    let Classification::Named(fit) = &f.classification else {
        panic!("not named: {}", d.verdict)
    };
    assert_eq!(fit.effect, Effect::Saturation, "{}", d.verdict);
    (fit.values()[0], fit.values()[1])
}

/// One record given as `Data::from_records(vec![r])` is that record, and discovers the same.
#[test]
fn one_record_as_records_discovers_the_same() {
    let est = experiment(1500, 300, 1.0, 1);
    let val = experiment(1500, 300, -1.0, 2);
    let settings = DiscoverSettings::default();
    let a = discover(&nominal(), &est, &val, &settings).unwrap();
    let b = discover(
        &nominal(),
        &Data::from_records(vec![est.clone()]).unwrap(),
        &Data::from_records(vec![val.clone()]).unwrap(),
        &settings,
    )
    .unwrap();
    assert_eq!(a.verdict_kind, b.verdict_kind);
    assert_eq!(named_saturation(&a), named_saturation(&b));
    let fa = a.finding.as_ref().unwrap();
    let fb = b.finding.as_ref().unwrap();
    for (x, y) in [
        (a.estimation_gap.rms, b.estimation_gap.rms),
        (a.validation_gap.rms, b.validation_gap.rms),
        (
            fa.augmented.validation_gap.rms,
            fb.augmented.validation_gap.rms,
        ),
        (fa.shrink, fb.shrink),
        (a.noise.std, b.noise.std),
    ] {
        assert!((x - y).abs() <= 1e-9 * x.abs().max(1e-12), "{x} vs {y}");
    }
}

/// An input saturation seen in three estimation records and two validation records, each
/// from its own initial state: named with its parameters, the gap closes, and the gap is
/// the records' own simulation error pooled (a concatenation without boundaries carries
/// each record's end state into the next, and is worse).
#[test]
fn a_saturation_in_several_records_is_named_and_its_gap_is_per_record() {
    let est = Data::from_records(vec![
        experiment(1200, 300, 1.2, 11),
        experiment(1000, 300, -1.5, 12),
        experiment(1100, 300, 0.6, 13),
    ])
    .unwrap();
    let val = Data::from_records(vec![
        experiment(1200, 300, -1.0, 14),
        experiment(1000, 300, 1.4, 15),
    ])
    .unwrap();
    let d = discover(&nominal(), &est, &val, &DiscoverSettings::default()).unwrap();
    assert!(d.missing_effect, "{}", d.verdict);
    let (slope, level) = named_saturation(&d);
    assert!((slope - 1.5).abs() < 0.1, "slope {slope}");
    assert!((level - 0.8).abs() < 0.04, "level {level}");
    let f = d.finding.as_ref().unwrap();
    assert!(f.shrink > 5.0, "shrink {}", f.shrink);
    // Per record in the gaps, in the records' order.
    assert_eq!(d.estimation_gap.records.len(), 3);
    assert_eq!(d.validation_gap.records.len(), 2);
    assert_eq!(f.augmented.validation_gap.records.len(), 2);
    for r in &f.augmented.validation_gap.records {
        assert!(r.rms < 2.0 * NOISE, "{r:?}");
    }
    // The gap before is the nominal model's simulation error of each record from its own
    // estimated initial state, pooled.
    for (gap, data) in [(&d.estimation_gap, &est), (&d.validation_gap, &val)] {
        let expected = pooled_nominal_rms(data);
        assert!(
            (gap.rms - expected).abs() < 1e-9 * expected,
            "{} vs {expected}",
            gap.rms
        );
        assert_eq!(gap.residual.len(), data.len());
        // Each record's RMS agrees with its own simulation.
        for (r, record) in gap.records.iter().zip(data.records()) {
            let own = pooled_nominal_rms(&record);
            assert!((r.rms - own).abs() < 1e-9 * own, "{} vs {own}", r.rms);
        }
    }
    // The concatenated records, simulated as one, carry the end state of each record into
    // the next: their gap is no smaller.
    let joined = concatenated(&val);
    let one = pooled_nominal_rms(&joined);
    assert!(
        one >= d.validation_gap.rms * (1.0 - 1e-9),
        "{one} < {}",
        d.validation_gap.rms
    );
}

/// A record too short for discovery is named in the error.
#[test]
fn a_short_record_is_named() {
    let est = Data::from_records(vec![
        experiment(1000, 300, 1.0, 21),
        experiment(60, 300, 1.0, 22),
    ])
    .unwrap();
    let val = experiment(1000, 300, -1.0, 23);
    let e = discover(&nominal(), &est, &val, &DiscoverSettings::default()).unwrap_err();
    let text = e.to_string();
    assert!(text.contains("estimation record 2 (of 2)"), "{text}");
    assert!(text.contains("100 samples"), "{text}");
}

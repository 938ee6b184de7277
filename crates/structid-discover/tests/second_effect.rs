//! A second effect: a nominal model that already carries maps, and the iteration that finds
//! one effect after another.
//!
//! The records are simulated by the difference equation of the plant written out here, not
//! through the workflow's LFTs: y_k = 1.5·y_(k−1) − 0.7·y_(k−2) + 0.1·(f_(k−1) + f_(k−2)) + e_k
//! with the force f = sat(u) − N(y) (an actuator that saturates, and a spring acting after it),
//! so that the test checks the LFTs that put the second block around the first, not only that
//! they agree with themselves.

use std::sync::Arc;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use structid_core::{Data, Interpolant, PolynomialDispersion, Signal};
use structid_discover::discover::{
    Classification, DiscoverSettings, EffectsSettings, Finding, StopReason, discover,
    discover_effects, second_blocks,
};
use structid_discover::effects::{Effect, EffectFit};
use structid_discover::gap::GapSettings;
use structid_discover::hypotheses::{Nominal, Site, hypothesis};
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

/// The plant's output from rest (noise-free part and noisy record), the force
/// f = actuator(u) − spring(y) acting through G = 0.1·(q⁻¹ + q⁻²)/(1 − 1.5·q⁻¹ + 0.7·q⁻²).
fn plant(
    u: &[f64],
    actuator: impl Fn(f64) -> f64,
    spring: impl Fn(f64) -> f64,
    noise: &[f64],
) -> Vec<f64> {
    let n = u.len();
    // x is the noise-free output; the measured y = x + e, and the spring reads the measured
    // position (feedback from y, as the LFT's z = y).
    let mut x = vec![0.0; n];
    let mut f = vec![0.0; n];
    let mut y = vec![0.0; n];
    for k in 0..n {
        let at = |v: &[f64], lag: usize| if k >= lag { v[k - lag] } else { 0.0 };
        x[k] = 1.5 * at(&x, 1) - 0.7 * at(&x, 2) + 0.1 * (at(&f, 1) + at(&f, 2));
        y[k] = x[k] + noise[k];
        f[k] = actuator(u[k]) - spring(y[k]);
    }
    y
}

fn input(seed: u64, n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let norm = Normal::new(0.0, 1.0).unwrap();
    let mut s = 0.0;
    let u: Vec<f64> = (0..n)
        .map(|_| {
            s = 0.8 * s + 0.6 * norm.sample(&mut rng);
            s
        })
        .collect();
    let e = Normal::new(0.0, NOISE).unwrap();
    let noise: Vec<f64> = (0..n).map(|_| e.sample(&mut rng)).collect();
    (u, noise)
}

fn data(u: &[f64], y: &[f64]) -> Data {
    Data::new(
        Signal::from_fn(u.len(), 1, |k, _| u[k]),
        Signal::from_fn(y.len(), 1, |k, _| y[k]),
    )
    .unwrap()
}

const SPRING: f64 = 0.15;

fn two_effects(seed: u64) -> Data {
    let (u, e) = input(seed, 3000);
    let y = plant(&u, saturation, |y| SPRING * y.powi(3), &e);
    assert!(y.iter().all(|v| v.is_finite()));
    data(&u, &y)
}

/// Which of the two effects a named family at a location is: the saturation at the input, the
/// cubic spring in feedback from y, or something else.
fn which(location: Site, fit: Option<&EffectFit>) -> &'static str {
    match (location, fit.map(|f| f.effect)) {
        (Site::Input, Some(Effect::Saturation)) => "saturation",
        // A cubic is a power law of exponent 3: the near family is accepted.
        (
            Site::OutputFeedback,
            Some(Effect::OddPolynomial { degree: 3 } | Effect::PowerLaw { .. }),
        ) => "spring",
        _ => "other",
    }
}

/// The parameters of the final model's two maps are the plant's: the saturation's slope and
/// level, the spring's cubic coefficient.
fn check_parameters(name: &str, fit: &EffectFit) {
    match name {
        "saturation" => {
            let v = fit.values();
            assert!(
                (v[0] - 1.5).abs() < 0.05 * 1.5 && (v[1] - 0.8).abs() < 0.03 * 0.8,
                "saturation {v:?}"
            );
        }
        _ => {
            let value = |n: &str| fit.parameter(n).map(|p| p.value);
            match (value("a3"), value("stiffness"), value("exponent")) {
                (Some(a3), _, _) => assert!((a3 - SPRING).abs() < 0.1 * SPRING, "a3 = {a3}"),
                (None, Some(k), Some(p)) => {
                    assert!((k - SPRING).abs() < 0.1 * SPRING, "stiffness {k}");
                    assert!((p - 3.0).abs() < 0.15, "exponent {p}");
                    let a1 = value("a1").unwrap_or(0.0);
                    assert!(a1.abs() < 0.02, "a1 = {a1}");
                }
                _ => panic!("{fit:?}"),
            }
        }
    }
}

#[test]
fn two_effects_are_found_one_after_the_other_and_the_iteration_stops() {
    let est = two_effects(11);
    let val = two_effects(12);
    let nominal = Nominal::from_polynomial(&g()).unwrap();
    // G is the plant's own: held as given. (Refitted jointly with the first map, the
    // saturation, it takes up the spring's linear part, and the spring found next is smaller.)
    let settings = DiscoverSettings::builder()
        .refine_nominal(false)
        .build()
        .unwrap();
    let effects = discover_effects(
        &nominal,
        &est,
        &val,
        &settings,
        &EffectsSettings::default().with_max_effects(4).unwrap(),
    )
    .unwrap();
    let describe = effects
        .steps
        .iter()
        .map(|s| s.discovery.verdict.clone())
        .collect::<Vec<_>>()
        .join("\n");
    let found = effects.findings();
    assert_eq!(found.len(), 2, "{describe}\nstop: {:?}", effects.stop);
    let named = |f: &Finding| match &f.classification {
        Classification::Named(fit) => Some(fit.clone()),
        _ => None,
    };
    let first = which(found[0].location, named(found[0]).as_ref());
    let second = which(found[1].location, named(found[1]).as_ref());
    let mut names = [first, second];
    names.sort_unstable();
    assert_eq!(names, ["saturation", "spring"], "{describe}");
    // The final model carries both maps, the first refitted with the second: both with the
    // plant's parameters (the first step's alone carried the bias of the unmodelled spring).
    let last = effects.last().unwrap();
    check_parameters(second, last.augmented.fit.as_ref().unwrap());
    let earlier = last.augmented.known[0]
        .fit
        .as_ref()
        .expect("the first map, refitted");
    check_parameters(first, earlier);
    // The second step started from the first one's augmented model: its maps were in it.
    assert_eq!(effects.steps[1].nominal.known_maps().len(), 1);
    assert_eq!(found[1].augmented.model.blocks().len(), 2);
    // The gap after the second effect is the noise, well below the gap after the first.
    let rms = effects.validation_rms();
    assert_eq!(rms.len(), 3);
    assert!(rms[2] < rms[1] / 3.0, "validation RMS {rms:?}");
    assert!(rms[2] < 1.4 * NOISE, "validation RMS {rms:?}");
    // No third effect is named on noise: the third step (if any) stops the iteration.
    assert!(
        matches!(
            effects.stop,
            StopReason::NoMissingEffect | StopReason::NoImprovement { .. }
        ),
        "{:?}\n{describe}",
        effects.stop
    );
    assert_eq!(effects.steps.len(), 3, "{describe}");

    // The augmented model of the last step is the plant: simulated by its own LFT with both
    // maps, it reproduces the independent simulation of a noise-free record.
    let (u, _) = input(13, 800);
    let y = plant(&u, saturation, |y| SPRING * y.powi(3), &[0.0; 800]);
    let maps = last.augmented.maps().unwrap();
    let refs: Vec<&dyn Interpolant> = maps.iter().map(|m| m.as_ref()).collect();
    let sim = last
        .augmented
        .model
        .simulate(&refs, &Signal::from_fn(800, 1, |k, _| u[k]), None, None)
        .unwrap();
    let err = (0..800)
        .map(|k| (sim.y.get(k, 0) - y[k]).powi(2))
        .sum::<f64>()
        .sqrt()
        / y.iter().map(|v| v * v).sum::<f64>().sqrt();
    assert!(err < 0.05, "relative simulation error {err}");
}

/// A nominal model with a known map is simulated with it: its gap is the residual of an
/// independent simulation of that model (same record, from rest), and with the right map the
/// verdict is "no missing effect".
#[test]
fn a_known_map_in_the_nominal_model_is_simulated() {
    let (u, e) = input(21, 2000);
    let y = plant(&u, saturation, |_| 0.0, &e);
    let record = data(&u, &y);
    let first = hypothesis(
        &g(),
        Site::Input,
        Arc::new(PolynomialDispersion::new(1).unwrap()),
    )
    .unwrap();
    let sat: Arc<dyn Interpolant> = Arc::new(|z: &[f64]| saturation(z[0]));
    let nominal = Nominal::from_model(&first.model, vec![sat]).unwrap();
    let gap = GapSettings {
        initial_state: structid_core::InitialState::Zero,
        ..GapSettings::default()
    };
    let settings = DiscoverSettings::builder().gap(gap).build().unwrap();
    let d = discover(&nominal, &record, &record, &settings).unwrap();
    // The independent simulation from rest, without noise: its residual is e.
    let clean = plant(&u, saturation, |_| 0.0, &[0.0; 2000]);
    let rms = ((0..2000).map(|k| (y[k] - clean[k]).powi(2)).sum::<f64>() / 2000.0).sqrt();
    assert!(
        (d.validation_gap.rms - rms).abs() < 1e-9 * rms,
        "{} vs {rms}",
        d.validation_gap.rms
    );
    assert!(!d.missing_effect, "{}", d.verdict);
    // The linear nominal model, without the saturation, has a gap far above the noise.
    let linear = discover(
        &Nominal::from_polynomial(&g()).unwrap(),
        &record,
        &record,
        &DiscoverSettings::builder()
            .gap(GapSettings {
                initial_state: structid_core::InitialState::Zero,
                ..GapSettings::default()
            })
            .locations(vec![Site::Input])
            .build()
            .unwrap(),
    )
    .unwrap();
    assert!(linear.validation_gap.rms > 5.0 * rms);
}

/// A sensor behind an actuator: y = s(G·d(u)) + e with an actuator dead zone d and a
/// saturating sensor s, the record simulated by the difference equation of G written out.
fn actuator_and_sensor(seed: u64) -> Data {
    let (u, e) = input(seed, 3000);
    let x = plant(&u, dead_zone, |_| 0.0, &vec![0.0; u.len()]);
    let y: Vec<f64> = x.iter().zip(&e).map(|(x, e)| sensor(*x) + e).collect();
    data(&u, &y)
}

fn dead_zone(u: f64) -> f64 {
    u.signum() * (u.abs() - 0.4).max(0.0)
}

fn sensor(x: f64) -> f64 {
    (1.2 * x).tanh() / 1.2
}

/// With the actuator known, the sensor map behind it reads G·d(u): not a signal of u and y
/// alone, but of the model with the actuator, and the noise reaches neither the state nor z.
/// Discovery places it at the output and closes the gap to the noise.
#[test]
fn a_sensor_behind_a_known_actuator_is_found() {
    let (est, val) = (actuator_and_sensor(31), actuator_and_sensor(32));
    let first = hypothesis(
        &g(),
        Site::Input,
        Arc::new(PolynomialDispersion::new(1).unwrap()),
    )
    .unwrap();
    let known: Arc<dyn Interpolant> = Arc::new(|z: &[f64]| dead_zone(z[0]));
    let nominal = Nominal::from_model(&first.model, vec![known]).unwrap();
    let d = discover(&nominal, &est, &val, &DiscoverSettings::default()).unwrap();
    let f = d
        .finding
        .as_ref()
        .unwrap_or_else(|| panic!("{}", d.verdict));
    assert_eq!(f.location, Site::Output, "{}", d.verdict);
    assert!(
        f.augmented.validation_gap.rms < 1.5 * NOISE,
        "{}",
        d.verdict
    );
    // The map found is the sensor, up to the noise, over the range of its z.
    let map = f.augmented.map.interpolant().unwrap();
    let (lo, hi) = (
        f.hypothesis.curve.z[0],
        f.hypothesis.curve.z[f.hypothesis.curve.z.len() - 1],
    );
    for k in 0..=20 {
        let z = lo + (hi - lo) * k as f64 / 20.0;
        assert!(
            (map.eval(&[z]) - sensor(z)).abs() < 0.05 * (sensor(hi) - sensor(lo)),
            "at {z}"
        );
    }
}

/// From the linear model alone discovery puts one map where it explains most. Whichever site
/// that is, the second-block rows see the other effect: the map found and a second one at the
/// other end of G, fitted together, validate at least 10 % better than the map alone.
#[test]
fn the_second_block_rows_see_a_sensor_behind_an_actuator() {
    let (est, val) = (actuator_and_sensor(31), actuator_and_sensor(32));
    let nominal = Nominal::from_polynomial(&g()).unwrap();
    let d = discover(&nominal, &est, &val, &DiscoverSettings::default()).unwrap();
    let settings = DiscoverSettings::builder()
        .scoring(d.scoring)
        .build()
        .unwrap();
    let f = d
        .finding
        .as_ref()
        .unwrap_or_else(|| panic!("{}", d.verdict));
    assert!(
        matches!(f.location, Site::Input | Site::Output),
        "{}",
        d.verdict
    );
    let rows = second_blocks(&nominal, f, &est, &val, &settings);
    let other = if f.location == Site::Input {
        Site::Output
    } else {
        Site::Input
    };
    let row = rows
        .iter()
        .find(|r| r.site == other)
        .unwrap_or_else(|| panic!("no row at {other:?}: {rows:?}"));
    assert_eq!(row.first_location, f.location);
    assert!(
        row.validation_rms <= 0.9 * f.augmented.validation_gap.rms,
        "{row:?} against {}",
        f.augmented.validation_gap.rms
    );
}

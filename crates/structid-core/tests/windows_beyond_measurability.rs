//! Windowed simulation scoring of a model beyond measurability: an actuator map, an
//! integrating G with a direct term (maps in series through D_zw) and a sensor map, whose z
//! the record does not give. Each window's state is fitted through the simulation.

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use structid_core::validation::metrics::rms;
use structid_core::validation::{Scoring, ValidationSettings, Windows, simulate_scored, validate};
use structid_core::{Data, Error, Interpolant, Model, Signal};

/// y = N₂(G·N₁(u)) + e, G = (b₀q² + b₁q + b₂)/((q − 1)(q − 0.8)) in controllable form, the
/// noise reaching the state (not an output-error model, whose z would be simulated from rest).
fn model() -> Model {
    structid_core::scenarios::actuator_sensor_series([-1.8, 0.8], [0.01, 0.015, 0.005]).unwrap()
}

fn actuator(z: &[f64]) -> f64 {
    (1.5 * z[0]).tanh()
}

fn sensor(z: &[f64]) -> f64 {
    z[0] + 0.1 * z[0].powi(3)
}

const X0: [f64; 2] = [4.0, 3.9];

/// The noiseless record from X0 and the true state at every sample's start.
fn record(len: usize) -> (Data, Vec<Vec<f64>>) {
    let u = Signal::from_fn(len, 1, |k, _| {
        let t = k as f64;
        (0.05 * t).sin() + 0.5 * (0.23 * t).sin() + 0.3 * (1.3 * t).cos()
    });
    let maps: [&dyn Interpolant; 2] = [&actuator, &sensor];
    let m = model();
    let mut states = vec![X0.to_vec()];
    for k in 1..len {
        let sim = m.simulate(&maps, &u.slice(0..k), None, Some(&X0)).unwrap();
        states.push(sim.final_state);
    }
    let y = m.simulate(&maps, &u, None, Some(&X0)).unwrap().y;
    (Data::new(u, y).unwrap(), states)
}

/// The exact model scores at round-off in every window, each window's state being the true
/// one, while a free run from rest misses the integrated initial state; validation, which
/// needs the one-step predictor, refuses the model earlier.
#[test]
fn the_exact_model_beyond_measurability_scores_zero_in_windows() {
    let (data, truth) = record(2000);
    let model = model();
    let maps: [&dyn Interpolant; 2] = [&actuator, &sensor];
    let windows = Windows::new(200, 25).unwrap();
    let win = simulate_scored(&model, &maps, &data, Scoring::Windowed(windows), None, 0).unwrap();
    let scale = rms(&data.y().channel(0));
    let r = win.rms(data.y(), 0);
    assert!(r < 1e-8 * scale, "windowed RMS {r} of {scale}");
    assert_eq!(win.states.len(), 10);
    for (range, x) in windows.ranges(2000).iter().zip(&win.states) {
        let x = x.as_ref().unwrap();
        let t = &truth[range.start];
        for i in 0..2 {
            assert!(
                (x[i] - t[i]).abs() < 1e-8 * (1.0 + t[i].abs()),
                "window at {}: state {i} {} vs {}",
                range.start,
                x[i],
                t[i]
            );
        }
    }
    let free = simulate_scored(&model, &maps, &data, Scoring::Free, None, 0).unwrap();
    // (from rest instead of X0: the integrated offset stays in every sample)
    assert!(free.rms(data.y(), 0) > 0.3, "{}", free.rms(data.y(), 0));
    let settings = ValidationSettings::builder()
        .scoring(Scoring::Windowed(windows))
        .build()
        .unwrap();
    assert!(matches!(
        validate(&model, &maps, &data, &settings),
        Err(Error::NotMeasurable { .. })
    ));
}

/// With white measurement noise σ on y, the exact model's windowed RMS is σ to within the
/// share of each window's samples that fitted its state.
#[test]
fn with_measurement_noise_the_exact_model_scores_the_noise_level() {
    let (clean, _) = record(4000);
    let sigma = 0.02;
    let noise = Normal::new(0.0, sigma).unwrap();
    let mut rng = StdRng::seed_from_u64(11);
    let y = Signal::from_fn(4000, 1, |k, _| clean.y().get(k, 0) + noise.sample(&mut rng));
    let data = Data::new(clean.u().clone(), y).unwrap();
    let model = model();
    let maps: [&dyn Interpolant; 2] = [&actuator, &sensor];
    let s = Scoring::Windowed(Windows::new(200, 25).unwrap());
    let win = simulate_scored(&model, &maps, &data, s, None, 0).unwrap();
    let r = win.rms(data.y(), 0);
    assert!(
        (r - sigma).abs() < 0.2 * sigma,
        "windowed RMS {r} against σ = {sigma}"
    );
    // A wrong sensor gain is not absorbed by the window states.
    let wrong = |z: &[f64]| 0.9 * sensor(z);
    let maps: [&dyn Interpolant; 2] = [&actuator, &wrong];
    let off = simulate_scored(&model, &maps, &data, s, None, 0).unwrap();
    assert!(
        off.rms(data.y(), 0) > 2.0 * sigma,
        "{}",
        off.rms(data.y(), 0)
    );
}

//! Maps in series are predicted with the maps evaluated in order: z from the record, the
//! one-step predictor against the noise itself, the k-step predictor against its limits.

use std::sync::Arc;

use nalgebra::dmatrix;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use structid_core::estimate::PredictionSettings;
use structid_core::estimate::predict::predict;
use structid_core::validation::{ValidationSettings, validate};
use structid_core::{
    Data, Error, Interpolant, KernelDispersion, Lft, LftMatrices, Model, NonlinearBlock, Signal,
};

/// a(u) → w₀; b reads z₁ = y + 0.5·w₀ (output feedback in series with a) → w₁; c reads
/// z₂ = w₁ − 0.3·w₀ + 0.2·u → w₂. The noise has dynamics of its own (B_e ≠ 0), in innovations
/// form, so the one-step prediction error of the true model is e itself.
fn model() -> Model {
    let lft = Lft::new(LftMatrices {
        a: dmatrix![0.7, 0.2; -0.1, 0.5],
        bu: dmatrix![0.3; 0.0],
        be: dmatrix![0.2; 0.1],
        bw: dmatrix![1.0, 0.0, 0.0; 0.0, -0.2, 0.4],
        cy: dmatrix![0.0, 1.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0, 0.0, 0.0],
        cz: dmatrix![0.0, 0.0; 0.0, 1.0; 0.0, 0.0],
        dzu: dmatrix![1.0; 0.0; 0.2],
        dze: dmatrix![0.0; 1.0; 0.0],
        dzw: dmatrix![0.0, 0.0, 0.0; 0.5, 0.0, 0.0; -0.3, 1.0, 0.0],
    })
    .unwrap();
    let d = Arc::new(KernelDispersion::gaussian(0.5).unwrap());
    // Out of order on purpose: c before the blocks it reads.
    Model::new(
        lft,
        vec![
            NonlinearBlock::new("c", vec![2], 2, d.clone()),
            NonlinearBlock::new("a", vec![0], 0, d.clone()),
            NonlinearBlock::new("b", vec![1], 1, d),
        ],
    )
    .unwrap()
}

fn a(z: &[f64]) -> f64 {
    z[0].tanh()
}
fn b(z: &[f64]) -> f64 {
    z[0].sin() - 0.2
}
fn c(z: &[f64]) -> f64 {
    z[0].clamp(-0.5, 0.5)
}

const MAPS: [&dyn Interpolant; 3] = [&c, &a, &b];

fn record(len: usize, noise: f64) -> (Data, Signal) {
    let u = Signal::from_fn(len, 1, |k, _| {
        (0.13 * k as f64).sin() + 0.8 * (0.71 * k as f64).cos()
    });
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let n = Normal::new(0.0, noise).unwrap();
    let e = Signal::from_fn(len, 1, |_, _| n.sample(&mut rng));
    let sim = model().simulate(&MAPS, &u, Some(&e), None).unwrap();
    (Data::new(u, sim.y).unwrap(), e)
}

#[test]
fn z_of_maps_in_series_is_computed_from_the_record_as_the_simulation_made_it() {
    let (data, e) = record(300, 0.05);
    let sim = model().simulate(&MAPS, data.u(), Some(&e), None).unwrap();
    let z = model()
        .compute_z_with_maps(data.u(), data.y(), &MAPS)
        .unwrap();
    for k in 0..300 {
        for i in 0..3 {
            assert!(
                (z.get(k, i) - sim.z.get(k, i)).abs() < 1e-12,
                "z[{i}] at {k}: {} vs {}",
                z.get(k, i),
                sim.z.get(k, i)
            );
        }
    }
}

#[test]
fn the_one_step_prediction_error_of_the_true_series_model_is_the_noise() {
    let (data, e) = record(600, 0.05);
    let settings = ValidationSettings::builder().max_lag(20).build().unwrap();
    let report = validate(&model(), &MAPS, &data, &settings).unwrap();
    // The Kalman predictor starts from a prior and converges to the innovations form.
    for k in 100..600 {
        let (got, want) = (report.prediction_error.get(k, 0), e.get(k, 0));
        assert!((got - want).abs() < 1e-6, "ε at {k}: {got} vs e = {want}");
    }
    // A wrong downstream map is seen by the predictor.
    let wrong = |z: &[f64]| 0.7 * z[0].clamp(-0.5, 0.5);
    let off = validate(&model(), &[&wrong, &a, &b], &data, &settings).unwrap();
    // An estimated initial state would contradict the z computed from rest: refused.
    let estimate = ValidationSettings::builder()
        .max_lag(20)
        .initial_state(structid_core::InitialState::Estimate)
        .build()
        .unwrap();
    let err = validate(&model(), &MAPS, &data, &estimate).unwrap_err();
    assert!(matches!(err, Error::NotMeasurable { .. }), "{err}");
    let gap: f64 = (100..600)
        .map(|k| (off.prediction_error.get(k, 0) - e.get(k, 0)).powi(2))
        .sum::<f64>()
        / 500.0;
    assert!(
        gap.sqrt() > 0.01,
        "a 30 % error in c moves ε by {}",
        gap.sqrt()
    );
}

#[test]
fn k_step_prediction_of_series_maps_runs_from_one_step_to_the_simulation() {
    let (data, _) = record(200, 0.05);
    let m = model();
    let one = predict(&m, &MAPS, &data, &PredictionSettings::default()).unwrap();
    let report = validate(
        &m,
        &MAPS,
        &data,
        &ValidationSettings::builder().max_lag(20).build().unwrap(),
    )
    .unwrap();
    for k in 0..200 {
        let want = data.y().get(k, 0) - report.prediction_error.get(k, 0);
        assert!(
            (one.predicted.get(k, 0) - want).abs() < 1e-10,
            "k = 1 at {k}"
        );
    }
    // Beyond the record no output is used: the simulation from rest, which `Lft::simulate`
    // orders by its own code.
    let far = PredictionSettings::builder().horizon(201).build().unwrap();
    let free = predict(&m, &MAPS, &data, &far).unwrap();
    let sim = m.simulate(&MAPS, data.u(), None, None).unwrap();
    for k in 0..200 {
        assert!(
            (free.predicted.get(k, 0) - sim.y.get(k, 0)).abs() < 1e-10,
            "k > L at {k}"
        );
    }
}

#[test]
fn a_latent_block_has_no_z_from_the_record_and_says_which() {
    // b now reads the unmeasured state x₁ instead of y.
    let mut mats = model().lft().matrices().clone();
    mats.cz = dmatrix![0.0, 0.0; 1.0, 0.0; 0.0, 0.0];
    mats.dze = dmatrix![0.0; 0.0; 0.0];
    let m = Model::new(Lft::new(mats).unwrap(), model().blocks().to_vec()).unwrap();
    let (data, _) = record(100, 0.05);
    let err = m
        .compute_z_with_maps(data.u(), data.y(), &MAPS)
        .unwrap_err();
    assert!(matches!(err, Error::NotMeasurable { .. }), "{err}");
    assert!(err.to_string().contains("`b`"), "{err}");
    let err = validate(
        &m,
        &MAPS,
        &data,
        &ValidationSettings::builder().max_lag(20).build().unwrap(),
    )
    .unwrap_err();
    assert!(matches!(err, Error::NotMeasurable { .. }), "{err}");
}

/// An output-error Hammerstein–Wiener model: w₀ = N₀(u) drives G, the sensor map N₁ reads
/// G's output (a state: latent for u and y), y = w₁ + e. The noise reaches neither the state
/// nor z, so z is the noise-free simulation's and the one-step predictor is the simulation.
fn hammerstein_wiener(be: f64) -> Model {
    let lft = Lft::new(LftMatrices {
        a: dmatrix![1.2, -0.5; 1.0, 0.0],
        bu: dmatrix![0.0; 0.0],
        be: dmatrix![be; 0.0],
        bw: dmatrix![1.0, 0.0; 0.0, 0.0],
        cy: dmatrix![0.0, 0.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0, 1.0],
        cz: dmatrix![0.0, 0.0; 0.3, 0.2],
        dzu: dmatrix![1.0; 0.0],
        dze: dmatrix![0.0; 0.0],
        dzw: dmatrix![0.0, 0.0; 0.0, 0.0],
    })
    .unwrap();
    let d = Arc::new(KernelDispersion::gaussian(0.5).unwrap());
    Model::new(
        lft,
        vec![
            NonlinearBlock::new("actuator", vec![0], 0, d.clone()),
            NonlinearBlock::new("sensor", vec![1], 1, d),
        ],
    )
    .unwrap()
}

fn dead_zone(z: &[f64]) -> f64 {
    z[0].signum() * (z[0].abs() - 0.3).max(0.0)
}
fn sensor(z: &[f64]) -> f64 {
    (2.0 * z[0]).tanh()
}

#[test]
fn an_output_error_sensor_behind_an_actuator_is_predicted_by_its_simulation() {
    let len = 400;
    let u = Signal::from_fn(len, 1, |k, _| 1.5 * (0.11 * k as f64).sin());
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let n = Normal::new(0.0, 0.02).unwrap();
    let e: Vec<f64> = (0..len).map(|_| n.sample(&mut rng)).collect();
    // The plant written out: x_k = 1.2·x_(k−1) − 0.5·x_(k−2) + dz(u_(k−1)), z₁ = 0.3·x + 0.2·x_(k−1).
    let (mut x, mut y, mut z1) = (vec![0.0; len], vec![0.0; len], vec![0.0; len]);
    for k in 0..len {
        let at = |v: &[f64], lag: usize| if k >= lag { v[k - lag] } else { 0.0 };
        x[k] = 1.2 * at(&x, 1) - 0.5 * at(&x, 2)
            + if k >= 1 {
                dead_zone(&[u.get(k - 1, 0)])
            } else {
                0.0
            };
        z1[k] = 0.3 * x[k] + 0.2 * at(&x, 1);
        y[k] = sensor(&[z1[k]]) + e[k];
    }
    let data = Data::new(u.clone(), Signal::new(1, y).unwrap()).unwrap();
    let maps: [&dyn Interpolant; 2] = [&dead_zone, &sensor];
    let model = hammerstein_wiener(0.0);
    let z = model
        .compute_z_with_maps(data.u(), data.y(), &maps)
        .unwrap();
    for k in 0..len {
        assert!((z.get(k, 1) - z1[k]).abs() < 1e-12, "z₁ at {k}");
    }
    let settings = ValidationSettings::builder()
        .initial_state(structid_core::InitialState::Zero)
        .build()
        .unwrap();
    let report = validate(&model, &maps, &data, &settings).unwrap();
    for k in 0..len {
        assert!(
            (report.prediction_error.get(k, 0) - e[k]).abs() < 1e-12,
            "ε at {k}"
        );
    }
    // With noise inside the state, z is not a function of u alone: still refused.
    let noisy = hammerstein_wiener(0.5);
    assert!(matches!(
        noisy.compute_z_with_maps(data.u(), data.y(), &maps),
        Err(Error::NotMeasurable { .. } | Error::OutOfReach { .. })
    ));
}

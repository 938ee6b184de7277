//! Tests of `validate` against independent answers: the noise that generated the data, a dense
//! conditional-expectation predictor, and the true initial state.

use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;
use structid_lti::{LinearSystem, Signal};

use super::*;
use crate::paper::{Experiment, gaussian, gaussian_noise};
use crate::scenarios;
use crate::{Lft, LftMatrices, NonlinearBlock};

fn tanh_map(z: &[f64]) -> f64 {
    z[0].tanh()
}

fn settings(initial_state: InitialState) -> ValidationSettings {
    ValidationSettings::builder()
        .initial_state(initial_state)
        .build()
        .unwrap()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

/// Output feedback through a saturation: x⁺ = 0.7x + u − 0.4·w, y = x + e, z = y, so z is
/// measurable by output injection (Ψ = 1) and the map sees the noise.
fn feedback_model() -> Model {
    let m = |v: f64| DMatrix::from_element(1, 1, v);
    let lft = Lft::new(LftMatrices {
        a: m(0.7),
        bu: m(1.0),
        be: m(0.0),
        bw: m(-0.4),
        cy: m(1.0),
        dyu: m(0.0),
        dye: m(1.0),
        dyw: m(0.0),
        cz: m(1.0),
        dzu: m(0.0),
        dze: m(1.0),
        dzw: m(0.0),
    })
    .unwrap();
    let block = NonlinearBlock::new("sat", vec![0], 0, gaussian(0.3).unwrap());
    Model::new(lft, vec![block]).unwrap()
}

#[test]
fn true_maps_on_noise_free_data_reproduce_the_record() {
    // Hammerstein (z = u) and output feedback (z = y).
    let ham = scenarios::hammerstein(400, 2, 0.0, gaussian(0.3).unwrap(), 3).unwrap();
    let fb_model = feedback_model();
    let u = gaussian_noise(400, 1, 1.0, 9);
    let fb = Experiment::simulate(fb_model, &[&tanh_map], u, Signal::zeros(400, 1)).unwrap();
    for exp in [ham, fb] {
        for init in [InitialState::Zero, InitialState::Estimate] {
            let r = validate(&exp.model, &[&tanh_map], &exp.data, &settings(init)).unwrap();
            assert_eq!(r.samples, 400);
            let scale = exp
                .data
                .y()
                .as_slice()
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(r.rms[0] < 1e-12 * scale, "{:?}", r.rms);
            assert!(
                (r.fit_percent[0] - 100.0).abs() < 1e-9,
                "{:?}",
                r.fit_percent
            );
            assert!(
                r.prediction_rms[0] < 1e-12 * scale,
                "{:?}",
                r.prediction_rms
            );
            assert!(max_abs_diff(r.simulated.as_slice(), exp.data.y().as_slice()) < 1e-12 * scale);
            match init {
                InitialState::Zero => assert!(r.initial_state.is_none()),
                InitialState::Estimate => {
                    let x0 = r.initial_state.unwrap();
                    assert!(x0.iter().all(|v| v.abs() < 1e-9), "{x0:?}");
                }
            }
        }
    }
}

#[test]
fn with_white_noise_the_prediction_error_is_the_noise_and_mostly_white() {
    // D_ye = 1 and a static noise path: ε = e exactly. Whiteness at 25 lags and the 1 % level
    // passes with probability 0.99²⁵ ≈ 0.78 per record: expect about 15.6 of 20.
    let (mut white, mut independent) = (0, 0);
    for seed in 0..20 {
        let exp = scenarios::hammerstein(500, 2, 0.3, gaussian(0.3).unwrap(), seed).unwrap();
        let r = validate(
            &exp.model,
            &[&tanh_map],
            &exp.data,
            &ValidationSettings::default(),
        )
        .unwrap();
        let d = max_abs_diff(r.prediction_error.as_slice(), exp.noise.as_slice());
        assert!(d < 1e-12, "seed {seed}: {d}");
        // The simulation error is the noise too (z = u is unaffected by e).
        assert!((r.rms[0] - crate::validation::metrics::rms(exp.noise.as_slice())).abs() < 1e-12);
        assert_eq!(r.whiteness[0].lags, (0..=25).collect::<Vec<isize>>());
        assert_eq!(r.input_correlation[0][0].lags.len(), 51);
        white += usize::from(r.whiteness_passes());
        independent += usize::from(r.input_correlation_passes());
    }
    assert!(white >= 12, "whiteness passed in {white} of 20 records");
    // 51 lags: 0.99⁵¹ ≈ 0.60 per record, about 12 of 20.
    assert!(
        independent >= 7,
        "input test passed in {independent} of 20 records"
    );
}

/// A Hammerstein system whose noise has dynamics and more noise channels than outputs, so that
/// its Kalman predictor has a genuine transient: x_e⁺ = 0.8·x_e + e₀, y = G·w + 1.3·x_e + 0.5·e₁.
fn coloured_experiment(len: usize, seed: u64) -> (Experiment, Lft) {
    let g = structid_lti::testing::random_stable_system(seed, 2, 1, 1, 0.9);
    let n = 3;
    let mut a = DMatrix::zeros(n, n);
    a.view_mut((0, 0), (2, 2)).copy_from(g.a());
    a[(2, 2)] = 0.8;
    let mut be = DMatrix::zeros(n, 2);
    be[(2, 0)] = 1.0;
    let mut bw = DMatrix::zeros(n, 1);
    bw.view_mut((0, 0), (2, 1)).copy_from(g.b());
    let mut cy = DMatrix::zeros(1, n);
    cy.view_mut((0, 0), (1, 2)).copy_from(g.c());
    cy[(0, 2)] = 1.3;
    let lft = Lft::new(LftMatrices {
        a,
        bu: DMatrix::zeros(n, 1),
        be,
        bw,
        cy,
        dyu: DMatrix::zeros(1, 1),
        dye: DMatrix::from_row_slice(1, 2, &[0.0, 0.5]),
        dyw: g.d().clone(),
        cz: DMatrix::zeros(1, n),
        dzu: DMatrix::from_element(1, 1, 1.0),
        dze: DMatrix::zeros(1, 2),
        dzw: DMatrix::zeros(1, 1),
    })
    .unwrap();
    let model = Model::new(
        lft.clone(),
        vec![NonlinearBlock::new("N", vec![0], 0, gaussian(0.3).unwrap())],
    )
    .unwrap();
    let u = gaussian_noise(len, 1, 1.0, seed + 100);
    let e = gaussian_noise(len, 2, 0.2, seed + 200);
    (
        Experiment::simulate(model, &[&tanh_map], u, e).unwrap(),
        lft,
    )
}

/// Dense reference of the innovations of v = T_ye·e: v_k − Σ_(k,past)·Σ_past⁻¹·v_past with
/// Σ = T_ye·T_yeᵀ, solved afresh at every k.
fn dense_innovations(noise: &structid_lti::StateSpace, v: &[f64]) -> Vec<f64> {
    let len = v.len();
    let t = noise.toeplitz_dense(len);
    let sigma = &t * t.transpose();
    let mut nu = v.to_vec();
    for k in 1..len {
        let s_pp = sigma.view((0, 0), (k, k)).into_owned();
        let coef = s_pp
            .cholesky()
            .expect("Σ_past positive definite")
            .solve(&DVector::from_column_slice(&v[..k]));
        nu[k] -= (sigma.view((k, 0), (1, k)) * coef)[(0, 0)];
    }
    nu
}

#[test]
fn coloured_noise_prediction_error_is_the_dense_innovation() {
    let len = 60;
    for seed in [1, 2] {
        let (exp, lft) = coloured_experiment(len, seed);
        let r = validate(
            &exp.model,
            &[&tanh_map],
            &exp.data,
            &ValidationSettings::builder().max_lag(10).build().unwrap(),
        )
        .unwrap();
        // v = T_ye·e from the noise that generated the data, not from the data.
        let noise = lft.t_ye();
        assert!(noise.order() > 0);
        let v = noise.simulate(&exp.noise).unwrap();
        let reference = dense_innovations(&noise, v.as_slice());
        let d = max_abs_diff(r.prediction_error.as_slice(), &reference);
        assert!(d < 1e-9, "seed {seed}: {d}");
        // Not trivially the noise itself: the predictor removes a lot.
        assert!(max_abs_diff(&reference, v.as_slice()) > 0.05);
    }
}

#[test]
fn minimum_phase_coloured_noise_is_inverted_exactly() {
    // H = (1 + 0.5q⁻¹)/(1 − 0.8q⁻¹) with D_ye = 1: e is recovered from the past, ε = e.
    let exp = scenarios::hammerstein_coloured(500, 2, 0.2, gaussian(0.3).unwrap(), 4).unwrap();
    let r = validate(
        &exp.model,
        &[&tanh_map],
        &exp.data,
        &ValidationSettings::default(),
    )
    .unwrap();
    let d = max_abs_diff(r.prediction_error.as_slice(), exp.noise.as_slice());
    assert!(d < 1e-10, "{d}");
}

#[test]
fn estimate_recovers_a_nonzero_initial_state_and_zero_does_not() {
    // Static noise path (x₀ over the plant's states) and coloured noise (x₀ also over the noise
    // filter's state).
    let ham = scenarios::hammerstein(300, 2, 0.0, gaussian(0.3).unwrap(), 5).unwrap();
    let col = scenarios::hammerstein_coloured(300, 2, 0.0, gaussian(0.3).unwrap(), 6).unwrap();
    for (exp, x0) in [(ham, vec![1.5, -0.7]), (col, vec![1.5, -0.7, 2.0])] {
        let sim = exp
            .model
            .simulate(&[&tanh_map], exp.data.u(), None, Some(&x0))
            .unwrap();
        let data = Data::new(exp.data.u().clone(), sim.y.clone()).unwrap();
        let est = validate(
            &exp.model,
            &[&tanh_map],
            &data,
            &settings(InitialState::Estimate),
        )
        .unwrap();
        let got = est.initial_state.clone().unwrap();
        assert!(max_abs_diff(&got, &x0) < 1e-8, "{got:?} vs {x0:?}");
        assert!(est.rms[0] < 1e-10, "{}", est.rms[0]);
        assert!(est.prediction_rms[0] < 1e-10, "{}", est.prediction_rms[0]);
        assert!(est.fit_percent[0] > 99.999_999);

        let zero = validate(
            &exp.model,
            &[&tanh_map],
            &data,
            &settings(InitialState::Zero),
        )
        .unwrap();
        assert!(zero.initial_state.is_none());
        assert!(zero.rms[0] > 1e-3, "{}", zero.rms[0]);
        // The unexplained transient is at the start of the record.
        let e0 = zero.prediction_error.get(0, 0).abs() + zero.prediction_error.get(1, 0).abs();
        assert!(e0 > 0.1, "{e0}");
    }
}

/// `--settle` leaves the transient of an unknown x₀ out of the one-step RMS as it does out of
/// the simulation RMS: both equal the RMS over the samples after it.
#[test]
fn the_settling_samples_are_left_out_of_the_one_step_rms_too() {
    let exp = scenarios::hammerstein(400, 2, 0.05, gaussian(0.3).unwrap(), 8).unwrap();
    let sim = exp
        .model
        .simulate(&[&tanh_map], exp.data.u(), None, Some(&[3.0, -2.0]))
        .unwrap();
    let y = Signal::from_fn(400, 1, |k, _| sim.y.get(k, 0) + exp.noise.get(k, 0));
    let data = Data::new(exp.data.u().clone(), y).unwrap();
    let settle = 60;
    let with = |settle: usize| {
        let s = ValidationSettings::builder()
            .initial_state(InitialState::Zero)
            .settle(settle)
            .build()
            .unwrap();
        validate(&exp.model, &[&tanh_map], &data, &s).unwrap()
    };
    let (all, settled) = (with(0), with(settle));
    let tail = &all.prediction_error.channel(0)[settle..];
    let tail_rms = (tail.iter().map(|v| v * v).sum::<f64>() / tail.len() as f64).sqrt();
    assert!((settled.prediction_rms[0] - tail_rms).abs() <= 1e-12 * tail_rms);
    // The transient dominated the whole-record figure; after it, the noise is what is left.
    assert!(all.prediction_rms[0] > 2.0 * settled.prediction_rms[0]);
    assert!((settled.prediction_rms[0] / 0.05 - 1.0).abs() < 0.3);
    assert!(settled.rms[0] < all.rms[0]);
}

#[test]
fn a_wrong_map_fails_the_input_cross_correlation_test() {
    let exp = scenarios::hammerstein(1000, 2, 0.1, gaussian(0.3).unwrap(), 8).unwrap();
    let s = ValidationSettings::default();
    let right = validate(&exp.model, &[&tanh_map], &exp.data, &s).unwrap();
    let half = |z: &[f64]| 0.5 * z[0].tanh();
    let wrong = validate(&exp.model, &[&half], &exp.data, &s).unwrap();
    let (out_right, out_wrong) = (
        right.input_correlation[0][0].outside().len(),
        wrong.input_correlation[0][0].outside().len(),
    );
    // 51 lags at the 1 % level: about 0.5 outside by chance.
    assert!(out_right <= 2, "true map: {out_right} lags outside");
    assert!(!wrong.input_correlation_passes());
    assert!(out_wrong >= 3, "wrong map: {out_wrong} lags outside");
    assert!(wrong.fit_percent[0] < right.fit_percent[0] - 10.0);
    assert!(wrong.prediction_rms[0] > 2.0 * right.prediction_rms[0]);
}

#[test]
fn bad_inputs_are_typed_errors() {
    let exp = scenarios::hammerstein(50, 2, 0.1, gaussian(0.3).unwrap(), 1).unwrap();
    let s = ValidationSettings::default();
    // One map too many.
    let e = validate(&exp.model, &[&tanh_map, &tanh_map], &exp.data, &s).unwrap_err();
    assert!(matches!(e, Error::DimensionMismatch { .. }), "{e}");
    // max_lag ≥ L.
    let long = ValidationSettings::builder().max_lag(50).build().unwrap();
    let e = validate(&exp.model, &[&tanh_map], &exp.data, &long).unwrap_err();
    assert!(
        matches!(&e, Error::InvalidParameter { name, .. } if name == "max_lag"),
        "{e}"
    );
    // Data with two inputs for a one-input model.
    let two = Data::new(Signal::zeros(50, 2), exp.data.y().clone()).unwrap();
    let e = validate(&exp.model, &[&tanh_map], &two, &s).unwrap_err();
    assert!(matches!(e, Error::DimensionMismatch { .. }), "{e}");
    // A map that returns NaN.
    let nan = |_: &[f64]| f64::NAN;
    let e = validate(&exp.model, &[&nan], &exp.data, &s).unwrap_err();
    assert!(matches!(e, Error::Numerical(_)), "{e}");
    // A diverging simulation: a map that explodes in the loop.
    let fb = feedback_model();
    let u = Signal::from_fn(50, 1, |_, _| 1.0);
    let y = fb.simulate(&[&tanh_map], &u, None, None).unwrap().y;
    let data = Data::new(u, y).unwrap();
    let explode = |z: &[f64]| -1e200 * z[0];
    let e = validate(&fb, &[&explode], &data, &s).unwrap_err();
    assert!(matches!(e, Error::Numerical(_) | Error::Unstable(_)), "{e}");
    // Builder.
    assert!(ValidationSettings::builder().max_lag(0).build().is_err());
}

#[test]
fn a_noise_path_without_a_predictor_is_a_clear_error() {
    // Coloured noise that reaches y only through the states (D_ye = 0): S_0 = 0, no predictor.
    let m = |v: f64| DMatrix::from_element(1, 1, v);
    let lft = Lft::new(LftMatrices {
        a: m(0.5),
        bu: m(0.0),
        be: m(1.0),
        bw: m(0.0),
        cy: m(1.0),
        dyu: m(0.0),
        dye: m(0.0),
        dyw: m(1.0),
        cz: m(0.0),
        dzu: m(1.0),
        dze: m(0.0),
        dzw: m(0.0),
    })
    .unwrap();
    let model = Model::new(
        lft,
        vec![NonlinearBlock::new("N", vec![0], 0, gaussian(0.3).unwrap())],
    )
    .unwrap();
    let u = gaussian_noise(40, 1, 1.0, 1);
    let y = model.simulate(&[&tanh_map], &u, None, None).unwrap().y;
    let data = Data::new(u, y).unwrap();
    let e = validate(&model, &[&tanh_map], &data, &ValidationSettings::default()).unwrap_err();
    assert!(
        matches!(&e, Error::InvalidStructure(m) if m.contains("Kalman predictor")),
        "{e}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Property: with the true maps and z = u, both the simulation error y − y_sim and the
    /// one-step prediction error ε equal the noise that generated the data (D_ye = 1, static
    /// noise path), for any plant order, noise level, record length and seed.
    #[test]
    fn prop_true_maps_leave_exactly_the_noise(
        seed in 0u64..10_000, order in 1usize..=3, std in 0.01f64..1.0, len in 30usize..200
    ) {
        let exp = scenarios::hammerstein(len, order, std, gaussian(0.3).unwrap(), seed).unwrap();
        let s = ValidationSettings::builder().max_lag(10).build().unwrap();
        let r = validate(&exp.model, &[&tanh_map], &exp.data, &s).unwrap();
        let e = exp.noise.as_slice();
        prop_assert!(max_abs_diff(r.prediction_error.as_slice(), e) < 1e-10);
        let sim_err: Vec<f64> = exp.data.y().as_slice().iter().zip(r.simulated.as_slice()).map(|(a, b)| a - b).collect();
        prop_assert!(max_abs_diff(&sim_err, e) < 1e-10);
    }

    /// Property: on noise-free data from any initial state, the estimated x₀ is the true one.
    #[test]
    fn prop_estimate_recovers_any_initial_state(
        seed in 0u64..10_000, x0 in proptest::collection::vec(-3.0f64..3.0, 2)
    ) {
        let exp = scenarios::hammerstein(120, 2, 0.0, gaussian(0.3).unwrap(), seed).unwrap();
        let y = exp.model.simulate(&[&tanh_map], exp.data.u(), None, Some(&x0)).unwrap().y;
        let data = Data::new(exp.data.u().clone(), y).unwrap();
        let s = settings(InitialState::Estimate);
        let r = validate(&exp.model, &[&tanh_map], &data, &s).unwrap();
        let got = r.initial_state.unwrap();
        // x₀ is resolved as far as y reveals it: compare the free responses over the record.
        let free = |x: &[f64]| exp.model.simulate(&[&|_: &[f64]| 0.0], &Signal::zeros(120, 1), None, Some(x)).unwrap().y;
        let (a, b) = (free(&got), free(&x0));
        prop_assert!(max_abs_diff(a.as_slice(), b.as_slice()) < 1e-8);
        prop_assert!(r.rms[0] < 1e-8);
    }
}

/// Several records with windowed scoring: the pooled RMS and fit are those of the samples each
/// record's own validation scored, concatenated; a record that fails is named.
#[test]
fn records_pool_exactly_the_samples_each_record_scored() {
    let model = feedback_model();
    let noisy = |len: usize, seed: u64| {
        let u = gaussian_noise(len, 1, 1.0, seed);
        let e = gaussian_noise(len, 1, 0.05, seed + 100);
        Experiment::simulate(feedback_model(), &[&tanh_map], u, e)
            .unwrap()
            .data
    };
    let records = [noisy(400, 1), noisy(260, 2)];
    let data = Data::from_records(records.to_vec()).unwrap();
    let wrong = |z: &[f64]| 0.8 * z[0].tanh();
    let s = ValidationSettings::builder()
        .initial_state(InitialState::Estimate)
        .settle(10)
        .scoring(Scoring::Windowed(Windows::new(100, 30).unwrap()))
        .build()
        .unwrap();
    let pooled = validate_records(&model, &[&wrong], &data, &s).unwrap();
    let (mut y, mut sim) = (Vec::new(), Vec::new());
    for (record, report) in records.iter().zip(&pooled.records) {
        assert_eq!(report, &validate(&model, &[&wrong], record, &s).unwrap());
        for r in &report.scored {
            y.extend_from_slice(&record.y().channel(0)[r.clone()]);
            sim.extend_from_slice(&report.simulated.channel(0)[r.clone()]);
        }
    }
    assert!(y.len() < 400 + 260 - 2 * 10, "windows leave samples out");
    assert_eq!(pooled.samples(), y.len());
    let rms_all = metrics::rms_difference(&y, &sim);
    assert!((pooled.rms()[0] - rms_all).abs() <= 1e-14 * rms_all);
    assert!((pooled.fit_percent()[0] - metrics::fit_percent(&y, &sim)).abs() <= 1e-10);

    let short = Data::from_records(vec![records[0].clone(), noisy(20, 3)]).unwrap();
    let long_lag = ValidationSettings::builder().max_lag(25).build().unwrap();
    match validate_records(&model, &[&wrong], &short, &long_lag) {
        Err(Error::InRecord { record: 2, source }) => {
            assert!(
                matches!(*source, Error::InvalidParameter { .. }),
                "{source}"
            )
        }
        other => panic!("expected an error in record 2, got {other:?}"),
    }
}

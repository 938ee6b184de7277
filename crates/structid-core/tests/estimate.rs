//! The fitted model as a value: stored estimates reproduce the in-memory maps exactly, and the
//! k-step predictor agrees with the one-step predictor of `validate` and with simulation.

use std::sync::Arc;

use nalgebra::DMatrix;
use proptest::prelude::*;
use structid_core::estimate::{Estimate, PredictionSettings, StoredMap};
use structid_core::validation::ValidationSettings;
use structid_core::*;

/// x⁺ = 0.6x + 0.3·x_e + w, y = x + 0.5·x_e + e with a coloured noise state x_e⁺ = 0.7x_e + e,
/// z = (u_0 … u_(p−1)): a MISO Hammerstein system with one p-input map.
fn hammerstein(p: usize) -> Lft {
    let m = |r, c, v: &[f64]| DMatrix::from_row_slice(r, c, v);
    Lft::new(LftMatrices {
        a: m(2, 2, &[0.6, 0.3, 0.0, 0.7]),
        bu: DMatrix::zeros(2, p),
        be: m(2, 1, &[0.0, 1.0]),
        bw: m(2, 1, &[1.0, 0.0]),
        cy: m(1, 2, &[1.0, 0.5]),
        dyu: DMatrix::zeros(1, p),
        dye: m(1, 1, &[1.0]),
        dyw: DMatrix::zeros(1, 1),
        cz: DMatrix::zeros(p, 2),
        dzu: DMatrix::identity(p, p),
        dze: DMatrix::zeros(p, 1),
        dzw: DMatrix::zeros(p, 1),
    })
    .unwrap()
}

/// Output feedback y = G·(u − N(y)) + H·e: x⁺ = 0.8x + 0.5(u − w) + 0.4e, y = x + e, z = y.
fn feedback() -> Lft {
    let s = |v: f64| DMatrix::from_element(1, 1, v);
    Lft::new(LftMatrices {
        a: s(0.8),
        bu: s(0.5),
        be: s(0.4),
        bw: s(-0.5),
        cy: s(1.0),
        dyu: s(0.0),
        dye: s(1.0),
        dyw: s(0.0),
        cz: s(1.0),
        dzu: s(0.0),
        dze: s(1.0),
        dzw: s(0.0),
    })
    .unwrap()
}

fn noise(len: usize, seed: u64, scale: f64) -> Signal {
    // A small LCG keeps the test independent of any RNG crate's stream.
    let mut s = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
    Signal::from_fn(len, 1, |_, _| {
        s = s
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        scale * (((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5)
    })
}

fn record(
    lft: &Lft,
    blocks: Vec<NonlinearBlock>,
    truth: &dyn Interpolant,
    len: usize,
    seed: u64,
) -> (Model, Data) {
    let model = Model::new(lft.clone(), blocks).unwrap();
    let p = lft.dims().u;
    let u = Signal::from_fn(len, p, |k, c| {
        1.5 * ((0.13 + 0.07 * c as f64) * k as f64 + seed as f64).sin()
    });
    let e = noise(len, seed, 0.02);
    let y = model.simulate(&[truth], &u, Some(&e), None).unwrap().y;
    (model, Data::new(u, y).unwrap())
}

fn block(p: usize, d: Arc<dyn Dispersion>) -> NonlinearBlock {
    NonlinearBlock::new("N", (0..p).collect(), 0, d)
}

fn truth(z: &[f64]) -> f64 {
    z.iter().map(|v| v.tanh()).sum::<f64>() + 0.1 * z[0] * z[0]
}

/// Every dispersion family × p: fit, write, delete nothing but the in-memory model, read back,
/// simulate on fresh input; the two simulations agree to 1e-12 (they are in fact identical).
fn roundtrip_matches(d: Arc<dyn Dispersion>, p: usize, len: usize, settings: &IdentifySettings) {
    let lft = hammerstein(p);
    let (model, data) = record(&lft, vec![block(p, d.clone())], &truth, len, 3);
    let estimate = model.fit(&data, settings).unwrap();
    let text = serde_json::to_string(&estimate).unwrap();
    let back: Estimate = serde_json::from_str(&text).unwrap();
    let u = Signal::from_fn(150, p, |k, c| {
        1.2 * ((0.21 + 0.05 * c as f64) * k as f64).cos()
    });
    let a = estimate.simulate(&u, None).unwrap().y;
    let b = back.simulate(&u, None).unwrap().y;
    let id = identify(&model, &data, settings).unwrap();
    let direct = model.simulate(&id.maps(), &u, None, None).unwrap().y;
    for k in 0..u.len() {
        let (x, y, z) = (a.get(k, 0), b.get(k, 0), direct.get(k, 0));
        assert!(
            (x - y).abs() <= 1e-12 * (1.0 + x.abs()),
            "{}: stored {y} vs in-memory {x} at {k}",
            d.describe()
        );
        assert!(
            (x - z).abs() <= 1e-12 * (1.0 + x.abs()),
            "{}: estimate {x} vs identification {z}",
            d.describe()
        );
    }
    assert_eq!(back.provenance().fitted_on, estimate.provenance().fitted_on);
    assert_eq!(back.blocks()[0].inputs, (0..p).collect::<Vec<_>>());
}

#[test]
fn stored_gaussian_fourier_lowrank_polynomial_sum_maps_reproduce_the_simulation_for_p_1_2_3() {
    let s = IdentifySettings::builder().beta(1e-3).build().unwrap();
    for p in 1..=3 {
        let gaussian: Arc<dyn Dispersion> = Arc::new(KernelDispersion::gaussian(0.8).unwrap());
        let fourier: Arc<dyn Dispersion> = Arc::new(
            FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.8 })
                .unwrap()
                .with_combination(if p == 1 {
                    Combination::Tensor
                } else {
                    Combination::Additive
                }),
        );
        let low_rank: Arc<dyn Dispersion> = Arc::new(LowRankGaussian::new(0.8, 1e-8).unwrap());
        let poly_kernel: Arc<dyn Dispersion> = Arc::new(
            SumDispersion::new(vec![
                Arc::new(PolynomialDispersion::new(2).unwrap()),
                Arc::new(KernelDispersion::gaussian(0.8).unwrap()),
            ])
            .unwrap(),
        );
        for d in [gaussian, fourier, low_rank, poly_kernel] {
            roundtrip_matches(d, p, 200, &s);
        }
    }
}

#[test]
fn stored_total_variation_maps_reproduce_the_simulation_for_p_1_2_3() {
    let s = IdentifySettings::builder().beta(1e-3).build().unwrap();
    for p in 1..=3 {
        roundtrip_matches(Arc::new(TotalVariation::new()), p, 150, &s);
    }
}

#[test]
fn the_exact_and_feature_solvers_store_the_same_fourier_map_up_to_rounding() {
    // Two stored forms (centres + α, or coefficients) of one map: they must evaluate alike.
    let d: Arc<dyn Dispersion> =
        Arc::new(FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.5 }).unwrap());
    let (model, data) = record(&hammerstein(1), vec![block(1, d)], &truth, 300, 5);
    let exact = model
        .fit(
            &data,
            &IdentifySettings::builder()
                .beta(1e-3)
                .solver(SolverChoice::Exact)
                .build()
                .unwrap(),
        )
        .unwrap();
    let feat = model
        .fit(
            &data,
            &IdentifySettings::builder()
                .beta(1e-3)
                .solver(SolverChoice::Features)
                .build()
                .unwrap(),
        )
        .unwrap();
    assert!(matches!(
        exact.blocks()[0].map,
        StoredMap::FeatureExpansion { .. } | StoredMap::KernelExpansion { .. }
    ));
    for k in 0..50 {
        let z = [-1.4 + 2.8 * k as f64 / 49.0];
        let (a, b) = (exact.maps()[0].eval(&z), feat.maps()[0].eval(&z));
        assert!((a - b).abs() < 1e-6 * (1.0 + a.abs()), "{a} vs {b}");
    }
}

#[test]
fn a_closure_map_cannot_be_stored_and_the_error_names_the_block() {
    let lft = hammerstein(1);
    let model = Model::new(
        lft,
        vec![block(1, Arc::new(KernelDispersion::gaussian(0.5).unwrap()))],
    )
    .unwrap();
    let f = |z: &[f64]| z[0];
    let err = Estimate::from_maps(&model, &[&f], None, Default::default()).unwrap_err();
    assert!(err.to_string().contains("`N`"), "{err}");
}

#[test]
fn malformed_stored_estimates_are_errors_not_panics() {
    let s = IdentifySettings::builder().beta(1e-3).build().unwrap();
    let (model, data) = record(
        &hammerstein(1),
        vec![block(1, Arc::new(KernelDispersion::gaussian(0.5).unwrap()))],
        &truth,
        100,
        1,
    );
    let text = serde_json::to_string(&model.fit(&data, &s).unwrap()).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    // Fewer coefficients than centres.
    let mut short = v.clone();
    short["blocks"][0]["map"]["alpha"]
        .as_array_mut()
        .unwrap()
        .pop();
    assert!(serde_json::from_value::<Estimate>(short).is_err());
    // A matrix whose entries do not fill its shape.
    let mut bad = v.clone();
    bad["lft"]["a"]["rows"] = serde_json::json!(3);
    assert!(serde_json::from_value::<Estimate>(bad).is_err());
    // A block that reads a z channel the LFT does not have.
    let mut wrong = v.clone();
    wrong["blocks"][0]["inputs"] = serde_json::json!([4]);
    assert!(serde_json::from_value::<Estimate>(wrong).is_err());
    // A newer format.
    v["format_version"] = serde_json::json!(99);
    let err = serde_json::from_value::<Estimate>(v).unwrap_err();
    assert!(err.to_string().contains("newer"), "{err}");
}

/// ŷ(1) from `predict` against y − ε from `validate`, and ŷ(k > L) against the simulation.
fn predictor_agrees(model: &Model, maps: &[&dyn Interpolant], data: &Data, initial: InitialState) {
    let vs = ValidationSettings::builder()
        .initial_state(initial)
        .build()
        .unwrap();
    let report = validate(model, maps, data, &vs).unwrap();
    let one = structid_core::estimate::predict::predict(
        model,
        maps,
        data,
        &PredictionSettings::builder()
            .horizon(1)
            .initial_state(initial)
            .build()
            .unwrap(),
    )
    .unwrap();
    let scale = data
        .y()
        .as_slice()
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    for k in 0..data.len() {
        let expected = data.y().get(k, 0) - report.prediction_error.get(k, 0);
        let got = one.predicted.get(k, 0);
        assert!(
            (expected - got).abs() <= 1e-12 * (1.0 + scale + expected.abs()),
            "k = {k}: {got} vs {expected}"
        );
    }
    let far = structid_core::estimate::predict::predict(
        model,
        maps,
        data,
        &PredictionSettings::builder()
            .horizon(data.len() + 3)
            .initial_state(initial)
            .build()
            .unwrap(),
    )
    .unwrap();
    for k in 0..data.len() {
        let (a, b) = (far.predicted.get(k, 0), report.simulated.get(k, 0));
        assert!(
            (a - b).abs() <= 1e-12 * (1.0 + scale),
            "k = {k}: {a} vs simulated {b}"
        );
    }
    // A horizon in between is no better than one step and no worse than the simulation on
    // average for correct maps: check only that it lies in a sane range.
    let mid = structid_core::estimate::predict::predict(
        model,
        maps,
        data,
        &PredictionSettings::builder()
            .horizon(5)
            .initial_state(initial)
            .build()
            .unwrap(),
    )
    .unwrap();
    assert!(mid.rms[0] >= one.rms[0] * 0.5 && mid.rms[0].is_finite());
}

#[test]
fn one_step_prediction_equals_validate_and_long_horizons_equal_simulation() {
    let sat = |z: &[f64]| z[0].clamp(-0.7, 0.7);
    for initial in [InitialState::Zero, InitialState::Estimate] {
        let (model, data) = record(
            &hammerstein(1),
            vec![block(1, Arc::new(KernelDispersion::gaussian(0.5).unwrap()))],
            &sat,
            300,
            2,
        );
        predictor_agrees(&model, &[&sat], &data, initial);
        let cubic = |z: &[f64]| 0.3 * z[0].powi(3);
        let (model, data) = record(
            &feedback(),
            vec![block(1, Arc::new(KernelDispersion::gaussian(0.5).unwrap()))],
            &cubic,
            300,
            4,
        );
        predictor_agrees(&model, &[&cubic], &data, initial);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// Property: for random stable feedback systems with coloured noise and a random map
    /// slope, the 1-step predictor is validate's and the (L+1)-step one is the simulation.
    #[test]
    fn prediction_horizons_one_and_beyond_the_record_match_their_closed_forms(
        a in -0.9f64..0.9, c in 0.2f64..1.5, h in -0.8f64..0.8, gain in 0.0f64..0.8, seed in 0u64..1000,
    ) {
        // A noise model with a zero outside the unit circle (|a − h·c| > 1) is left out: the
        // predictor started at rest is then exactly H⁻¹, which amplifies rounding without
        // bound, so two correct orders of summation drift apart.
        prop_assume!((a - h * c).abs() < 0.95);
        let s = |v: f64| DMatrix::from_element(1, 1, v);
        let lft = Lft::new(LftMatrices {
            a: s(a), bu: s(0.5), be: s(h), bw: s(-0.5), cy: s(c), dyu: s(0.0), dye: s(1.0),
            dyw: s(0.0), cz: s(c), dzu: s(0.0), dze: s(1.0), dzw: s(0.0),
        }).unwrap();
        let map = move |z: &[f64]| gain * z[0].tanh();
        let (model, data) = record(&lft, vec![block(1, Arc::new(KernelDispersion::gaussian(0.5).unwrap()))], &map, 120, seed);
        predictor_agrees(&model, &[&map], &data, InitialState::Zero);
    }
}

#[test]
fn prediction_rejects_bad_settings_and_records() {
    assert!(PredictionSettings::builder().horizon(0).build().is_err());
    let lft = hammerstein(1);
    let f = |z: &[f64]| z[0];
    let (model, data) = record(
        &lft,
        vec![block(1, Arc::new(KernelDispersion::gaussian(0.5).unwrap()))],
        &f,
        50,
        1,
    );
    let settle = PredictionSettings::builder().settle(50).build().unwrap();
    assert!(structid_core::estimate::predict::predict(&model, &[&f], &data, &settle).is_err());
    assert!(
        structid_core::estimate::predict::predict(
            &model,
            &[],
            &data,
            &PredictionSettings::default()
        )
        .is_err()
    );
}

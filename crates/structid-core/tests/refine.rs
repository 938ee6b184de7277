//! Alternating refinement (`structid_core::refine`) on simulated Silverbox-like data: a
//! second-order G in output feedback with a cubic stiffness, started from a wrong G.

use std::sync::Arc;

use proptest::prelude::*;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use structid_core::refine::{
    InputNonlinearity, LinearStructure, OutputFeedback, RefineSettings, lti_lft, refine,
};
use structid_core::{
    Data, Dispersion, FourierDispersion, FourierWeights, IdentifySettings, InitialState,
    MapBinding, PolynomialDispersion, Signal, SolverChoice, SumDispersion,
};
use structid_linear::{OeSettings, PolynomialModel};

/// G(q) = (b₁q⁻¹ + b₂q⁻²)/(1 + a₁q⁻¹ + a₂q⁻²) with poles r·e^{±jθ}.
fn second_order(r: f64, theta: f64, b: [f64; 2]) -> PolynomialModel {
    PolynomialModel {
        den: vec![1.0, -2.0 * r * theta.cos(), r * r],
        num: vec![vec![0.0, b[0], b[1]]],
        sample_time: None,
    }
}

fn truth() -> PolynomialModel {
    second_order(0.95, std::f64::consts::PI / 8.0, [0.10, 0.05])
}

fn stiffness(y: f64) -> f64 {
    0.5 * y.powi(3) + 0.05 * y * y
}

/// Low-pass filtered Gaussian noise of RMS about `amplitude`.
fn input(len: usize, amplitude: f64, seed: u64) -> Signal {
    let mut rng = StdRng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let mut s = 0.0;
    Signal::from_fn(len, 1, |_, _| {
        s = 0.7 * s + 0.3 * n.sample(&mut rng);
        amplitude * s / 0.42
    })
}

/// y = G·(u − N(y)) + e, simulated from rest.
fn simulate(
    g: &PolynomialModel,
    map: &(dyn Fn(f64) -> f64 + Sync),
    u: &Signal,
    noise: f64,
    seed: u64,
) -> Signal {
    let structure = OutputFeedback::new("N");
    let lft = structure
        .lft(&structure.initial_from_bla(g).unwrap())
        .unwrap();
    let f = |z: &[f64]| map(z[0]);
    let sim = lft
        .simulate(
            &[MapBinding {
                inputs: &[0],
                output: 0,
                map: &f,
            }],
            u,
            None,
            None,
        )
        .unwrap();
    let mut rng = StdRng::seed_from_u64(seed ^ 0x5eed);
    let n = Normal::new(0.0, noise).unwrap();
    Signal::from_fn(u.len(), 1, |k, _| sim.y.get(k, 0) + n.sample(&mut rng))
}

fn dispersion(y: &Signal) -> Arc<dyn Dispersion> {
    let range = {
        let v = y.channel(0);
        v.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - v.iter().cloned().fold(f64::INFINITY, f64::min)
    };
    Arc::new(
        SumDispersion::new(vec![
            Arc::new(
                FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.2 * range })
                    .unwrap(),
            ),
            Arc::new(
                PolynomialDispersion::new(3)
                    .unwrap()
                    .with_scale(10.0)
                    .unwrap(),
            ),
        ])
        .unwrap(),
    )
}

fn settings(beta: f64, x0: InitialState, iterations: usize) -> RefineSettings {
    RefineSettings::builder()
        .max_iterations(iterations)
        .tolerance(0.0)
        .identify(
            IdentifySettings::builder()
                .beta(beta)
                .initial_state(x0)
                .solver(SolverChoice::Features)
                .build()
                .unwrap(),
        )
        .selection(None)
        .oe(OeSettings::builder().tolerance(1e-9).build().unwrap())
        .build()
        .unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 6, ..ProptestConfig::default() })]

    /// Property: with β fixed, J = (1/L)‖ê‖² + β·D never increases, neither in the map step
    /// nor in the linear step, for either numerator form and initial-state treatment.
    #[test]
    fn alternating_refinement_never_increases_the_estimation_cost(
        seed in 0u64..1000,
        r in 0.85f64..0.93,
        gain in 0.7f64..1.4,
        separate in any::<bool>(),
        free_x0 in any::<bool>(),
        log_beta in -8.0f64..-4.0,
    ) {
        let u = input(1500, 0.3, seed);
        let y = simulate(&truth(), &stiffness, &u, 0.01, seed);
        let data = Data::new(u, y.clone()).unwrap();
        let structure = OutputFeedback::new("N").with_separate_numerator(separate);
        let start = structure
            .initial_from_bla(&second_order(r, std::f64::consts::PI / 7.0, [0.1 * gain, 0.02]))
            .unwrap();
        let x0 = if free_x0 { InitialState::Estimate } else { InitialState::Zero };
        let out = refine(
            &structure,
            &start,
            dispersion(&y),
            &data,
            None,
            &settings(10f64.powf(log_beta), x0, 4),
        )
        .unwrap();
        let tol = |j: f64| 1e-9 * j.abs() + 1e-15;
        for (k, it) in out.iterations.iter().enumerate() {
            if let Some(after) = it.cost_after_linear {
                prop_assert!(after <= it.cost_after_maps + tol(it.cost_after_maps),
                    "iteration {k}: linear step raised J from {} to {after}", it.cost_after_maps);
                if let Some(next) = out.iterations.get(k + 1) {
                    prop_assert!(next.cost_after_maps <= after + tol(after),
                        "iteration {}: map step raised J from {after} to {}", k + 1, next.cost_after_maps);
                }
            }
        }
        prop_assert!(out.iterations.len() >= 2);
    }
}

/// From a G with 20 % wrong poles and 40 % wrong gain, the refined model simulates like the
/// true system on a fresh input, and the numerator (which the structure pins down: u enters
/// only through it) is recovered.
#[test]
fn refinement_converges_to_the_true_system_from_a_wrong_linear_part() {
    let u = input(3000, 0.3, 7);
    let y = simulate(&truth(), &stiffness, &u, 0.002, 7);
    let data = Data::new(u, y.clone()).unwrap();
    let structure = OutputFeedback::new("N");
    let wrong = second_order(0.8, std::f64::consts::PI / 6.0, [0.14, 0.03]);
    let start = structure.initial_from_bla(&wrong).unwrap();
    let uv = input(2000, 0.3, 99);
    let yv = simulate(&truth(), &stiffness, &uv, 0.0, 99);
    let validation = Data::new(uv.clone(), yv.clone()).unwrap();
    let out = refine(
        &structure,
        &start,
        dispersion(&y),
        &data,
        Some(&validation),
        &settings(1e-7, InitialState::Zero, 12),
    )
    .unwrap();
    let first = out.iterations[0].validation_rms.unwrap();
    let best = out.iterations[out.best].validation_rms.unwrap();
    let scale = (yv.as_slice().iter().map(|v| v * v).sum::<f64>() / yv.len() as f64).sqrt();
    assert!(
        best < 0.01 * scale,
        "validation RMS {best} vs output RMS {scale} (first iteration {first})"
    );
    assert!(best < 0.1 * first, "no real improvement: {first} → {best}");
    let b = &out.linear.num[0];
    let bt = &truth().num[0];
    for j in 1..3 {
        assert!(
            (b[j] - bt[j]).abs() < 0.02 * bt[1].abs(),
            "b_{j}: {} vs {}",
            b[j],
            bt[j]
        );
    }
    // The structure leaves one direction free: (F + k·B, N − k·y) is the same system. With
    // k read off the denominators, the map plus k·y is the true stiffness.
    let k = (out.linear.den[1] - truth().den[1]) / bt[1];
    let map = out.identification.blocks[0].map.as_ref();
    let top = y.as_slice().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for f in [-0.7, -0.3, 0.2, 0.7] {
        let z = f * top;
        let got = map.eval(&[z]) + k * z;
        assert!(
            (got - stiffness(z)).abs() < 0.03 * stiffness(0.7 * top),
            "N̂({z}) + k·z = {got} vs {}",
            stiffness(z)
        );
    }
}

/// A Hammerstein system y = G·N(u) + e is refined through the same loop.
#[test]
fn input_nonlinearity_refinement_lowers_the_validation_error() {
    let g = second_order(0.9, 0.4, [0.2, 0.1]);
    let structure = InputNonlinearity::new("actuator");
    let lft = structure.lft(&g).unwrap();
    let sat = |z: &[f64]| z[0].tanh();
    let sim = |u: &Signal| {
        lft.simulate(
            &[MapBinding {
                inputs: &[0],
                output: 0,
                map: &sat,
            }],
            u,
            None,
            None,
        )
        .unwrap()
        .y
    };
    let u = input(2000, 1.5, 3);
    let uv = input(1000, 1.5, 4);
    let (y, yv) = (sim(&u), sim(&uv));
    let wrong = second_order(0.8, 0.5, [0.3, 0.0]);
    let out = refine(
        &structure,
        &wrong,
        dispersion(&u),
        &Data::new(u, y).unwrap(),
        Some(&Data::new(uv, yv).unwrap()),
        &settings(1e-8, InitialState::Zero, 8),
    )
    .unwrap();
    let first = out.iterations[0].validation_rms.unwrap();
    let best = out.iterations[out.best].validation_rms.unwrap();
    assert!(best < 0.05 * first, "{first} → {best}");
    // The linear part alone (no map) is a different model: its LFT has no w.
    assert_eq!(lti_lft(&out.linear).unwrap().dims().w, 0);
}

#[test]
fn bad_settings_and_structures_are_errors() {
    assert!(RefineSettings::builder().max_iterations(0).build().is_err());
    assert!(RefineSettings::builder().tolerance(-1.0).build().is_err());
    let structure = OutputFeedback::new("N");
    // A feedback path without delay is an algebraic loop.
    let direct = PolynomialModel {
        den: vec![1.0, -0.5],
        num: vec![vec![1.0, 0.2], vec![0.5, 0.0]],
        sample_time: None,
    };
    let e = structure.lft(&direct).unwrap_err().to_string();
    assert!(e.contains("algebraic loop"), "{e}");
    let bla = PolynomialModel {
        den: vec![1.0, -0.5],
        num: vec![vec![1.0, 0.2]],
        sample_time: None,
    };
    assert!(structure.initial_from_bla(&bla).is_err());
    // A shared numerator needs one input u.
    let two = Data::new(
        Signal::from_fn(50, 2, |k, c| (k + c) as f64),
        Signal::from_fn(50, 1, |k, _| k as f64),
    )
    .unwrap();
    let g = structure.initial_from_bla(&truth()).unwrap();
    let w = Signal::zeros(50, 1);
    assert!(
        structure
            .estimate_linear(&two, &w, &g, &OeSettings::default(), false)
            .is_err()
    );
}

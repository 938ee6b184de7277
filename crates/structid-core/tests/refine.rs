//! Alternating refinement (`structid_core::refine`) on simulated Silverbox-like data: a
//! second-order G in output feedback with a cubic stiffness, started from a wrong G.

use std::sync::Arc;

use proptest::prelude::*;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use structid_core::refine::{
    LinearStructure, RefineSettings, lti_lft, output_error_with_state, refine,
};
use structid_core::{
    Data, Dispersion, FourierDispersion, FourierWeights, IdentifySettings, InitialState,
    MapBinding, PolynomialDispersion, Signal, SolverChoice, SumDispersion,
};
use structid_linear::{OeSettings, PolynomialModel};

/// G(q) = (b₁q⁻¹ + b₂q⁻²)/(1 + a₁q⁻¹ + a₂q⁻²) with poles r·e^{±jθ}.
fn second_order(r: f64, theta: f64, b: [f64; 2]) -> PolynomialModel {
    PolynomialModel {
        num: vec![vec![0.0, b[0], b[1]]],
        den: vec![1.0, -2.0 * r * theta.cos(), r * r],
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
    let structure = LinearStructure::output_feedback("N");
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
        let structure = LinearStructure::output_feedback("N").with_separate_numerator(separate);
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
    let structure = LinearStructure::output_feedback("N");
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
    let structure = LinearStructure::input("actuator");
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
    // A transient in the output-error step would compare J over different samples.
    let e = RefineSettings::builder()
        .oe(OeSettings::builder().transient(10).build().unwrap())
        .build()
        .unwrap_err()
        .to_string();
    assert!(e.contains("transient"), "{e}");
    let structure = LinearStructure::output_feedback("N");
    // A feedback path without delay is an algebraic loop.
    let direct = PolynomialModel {
        num: vec![vec![1.0, 0.2], vec![0.5, 0.0]],
        den: vec![1.0, -0.5],
        sample_time: None,
    };
    let e = structure.lft(&direct).unwrap_err().to_string();
    assert!(e.contains("algebraic loop"), "{e}");
    let bla = PolynomialModel {
        num: vec![vec![1.0, 0.2]],
        den: vec![1.0, -0.5],
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
    // A feedback numerator started at zero has no free coefficient (its orders are read
    // from the leading zeros): an error, not a path silently fixed at zero.
    let separate = LinearStructure::output_feedback("N").with_separate_numerator(true);
    let mut zero_w = g.clone();
    zero_w.num[1] = vec![0.0, 0.0, 0.0];
    let one = Data::new(
        Signal::from_fn(50, 1, |k, _| ((k * k) as f64 * 0.37).sin()),
        Signal::from_fn(50, 1, |k, _| (k as f64 * 0.1).sin()),
    )
    .unwrap();
    for free in [false, true] {
        let e = separate
            .estimate_linear(&one, &w, &zero_w, &OeSettings::default(), free)
            .unwrap_err()
            .to_string();
        assert!(e.contains("all zeros"), "{e}");
    }
    assert!(
        structure
            .estimate_linear(&two, &w, &g, &OeSettings::default(), false)
            .is_err()
    );
}

/// The cost of `g` on (u, y) with its best initial state: least squares on the free responses
/// q^{−j}/F·δ, j < n (what identify() reaches with InitialState::Estimate for this G).
fn best_initial_state_cost(g: &PolynomialModel, u: &Signal, y: &Signal) -> f64 {
    let len = y.len();
    let n = (g.den.len() - 1).max(g.num[0].len() - 1);
    let sim = g.simulate(u).unwrap();
    let r = nalgebra::DVector::from_fn(len, |k, _| y.get(k, 0) - sim[k]);
    let delta = Signal::from_fn(len, 1, |k, _| if k == 0 { 1.0 } else { 0.0 });
    let columns: Vec<Vec<f64>> = (0..n)
        .map(|j| {
            let mut b = vec![0.0; j];
            b.push(1.0);
            let m = PolynomialModel {
                num: vec![b],
                den: g.den.clone(),
                sample_time: None,
            };
            m.simulate(&delta).unwrap()
        })
        .collect();
    let phi = nalgebra::DMatrix::from_fn(len, n, |k, j| columns[j][k]);
    let c = phi.clone().svd(true, true).solve(&r, 1e-14).unwrap();
    (r - phi * c).norm_squared() / len as f64
}

/// The linear step with a free initial state starts where the map step left off (G with its
/// best initial state), so even a single Levenberg–Marquardt iteration cannot end above it:
/// the cost guarantee does not depend on the output-error fit converging.
#[test]
fn free_initial_state_fit_never_ends_above_the_start_with_its_best_state() {
    let g = truth();
    let len = 300;
    let u = input(len, 0.3, 5);
    let free = PolynomialModel {
        num: vec![vec![5.0, -3.0]],
        den: g.den.clone(),
        sample_time: None,
    };
    let delta = Signal::from_fn(len, 1, |k, _| if k == 0 { 1.0 } else { 0.0 });
    let (forced, response) = (g.simulate(&u).unwrap(), free.simulate(&delta).unwrap());
    let y = Signal::from_fn(len, 1, |k, _| {
        forced[k] + response[k] + 0.01 * (1.3 * k as f64).sin().signum()
    });
    let start_cost = best_initial_state_cost(&g, &u, &y);
    for iterations in 1..4 {
        let s = OeSettings::builder()
            .max_iterations(iterations)
            .build()
            .unwrap();
        let fit = output_error_with_state(&u, &y, &g, &s, true).unwrap();
        assert!(
            (fit.initial_cost - start_cost).abs() <= 1e-9 * start_cost,
            "initial cost {} vs the start's best {start_cost}",
            fit.initial_cost
        );
        assert!(
            fit.cost <= start_cost * (1.0 + 1e-12),
            "{iterations} iteration(s): {} > the start's best {start_cost}",
            fit.cost
        );
    }
}

/// With few features (a polynomial plus a Fourier series on 1500 samples) the automatic choice
/// is the feature solver, and its reason reads as one sentence.
#[test]
fn auto_uses_the_feature_solver_when_the_features_are_few() {
    let u = input(1500, 0.3, 11);
    let y = simulate(&truth(), &stiffness, &u, 0.01, 11);
    let structure = LinearStructure::output_feedback("N");
    let model = structure
        .model(
            &structure.initial_from_bla(&truth()).unwrap(),
            dispersion(&y),
        )
        .unwrap();
    let id = structid_core::identify(
        &model,
        &Data::new(u, y).unwrap(),
        &IdentifySettings::builder().beta(1e-6).build().unwrap(),
    )
    .unwrap();
    let reason = &id.diagnostics.solver_reason.to_string();
    assert!(reason.contains("the feature solver"), "{reason}");
    assert!(!reason.contains("  "), "stray spaces: {reason:?}");
}

/// The progress observer hears every alternation, with the largest number as the total.
#[test]
fn refinement_reports_each_alternation() {
    use std::sync::{Arc as SArc, Mutex};
    use structid_core::progress::Progress;
    let g = second_order(0.9, 0.4, [0.2, 0.1]);
    let structure = LinearStructure::input("actuator");
    let lft = structure.lft(&g).unwrap();
    let sat = |z: &[f64]| z[0].tanh();
    let u = input(600, 1.5, 5);
    let y = lft
        .simulate(
            &[MapBinding {
                inputs: &[0],
                output: 0,
                map: &sat,
            }],
            &u,
            None,
            None,
        )
        .unwrap()
        .y;
    let heard = SArc::new(Mutex::new(Vec::new()));
    let h = SArc::clone(&heard);
    let base = settings(1e-8, InitialState::Zero, 4);
    let observed = RefineSettings::builder()
        .max_iterations(base.max_iterations())
        .tolerance(0.0)
        .identify(base.identify().clone())
        .selection(None)
        .progress(Progress::new(move |done, total| {
            h.lock().unwrap().push((done, total))
        }))
        .build()
        .unwrap();
    let wrong = second_order(0.8, 0.5, [0.3, 0.0]);
    let out = refine(
        &structure,
        &wrong,
        dispersion(&u),
        &Data::new(u, y).unwrap(),
        None,
        &observed,
    )
    .unwrap();
    let heard = heard.lock().unwrap();
    let expected: Vec<(u64, Option<u64>)> = (1..=out.iterations.len() as u64)
        .map(|i| (i, Some(4)))
        .collect();
    assert_eq!(*heard, expected);
}

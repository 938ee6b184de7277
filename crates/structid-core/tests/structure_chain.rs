//! Several blocks in one `Structure`: each chain simulated against its recursion written out
//! here, and how identification reaches each block.

use std::sync::Arc;

use structid_core::{BlockAccess, Interpolant, KernelDispersion, Model, Signal, Site, Structure};
use structid_linear::PolynomialModel;

/// G = q⁻¹/(1 − 0.6q⁻¹): x⁺ = 0.6x + v, y = x (+ e).
fn g() -> PolynomialModel {
    PolynomialModel {
        num: vec![vec![0.0, 1.0]],
        den: vec![1.0, -0.6],
        sample_time: Some(0.5),
    }
}

fn d() -> Arc<dyn structid_core::Dispersion> {
    Arc::new(KernelDispersion::gaussian(0.5).unwrap())
}

fn n1(z: &[f64]) -> f64 {
    z[0].tanh()
}
fn n2(z: &[f64]) -> f64 {
    0.3 * z[0] * z[0].abs()
}

fn signals(len: usize) -> (Signal, Signal) {
    let u = Signal::from_fn(len, 1, |k, _| {
        1.5 * (0.21 * k as f64).sin() + 0.4 * (0.9 * k as f64).cos()
    });
    let e = Signal::from_fn(len, 1, |k, _| 0.05 * (2.3 * k as f64).sin());
    (u, e)
}

/// Simulates `model` (maps n1, n2 in block order) and compares y with `recursion(u_k, e_k,
/// x_k) → (y_k, x_(k+1))`.
fn check(model: &Model, recursion: impl Fn(f64, f64, &mut [f64]) -> f64, states: usize) {
    check_with(model, [&n1, &n2], recursion, states);
}

fn check_with(
    model: &Model,
    maps: [&dyn Interpolant; 2],
    recursion: impl Fn(f64, f64, &mut [f64]) -> f64,
    states: usize,
) {
    let (u, e) = signals(150);
    let sim = model.simulate(&maps, &u, Some(&e), None).unwrap();
    let mut x = vec![0.0; states];
    for k in 0..u.len() {
        let y = recursion(u.get(k, 0), e.get(k, 0), &mut x);
        assert!(
            (sim.y.get(k, 0) - y).abs() < 1e-12,
            "y at {k}: {} vs {y}",
            sim.y.get(k, 0)
        );
    }
}

fn access(model: &Model) -> Vec<BlockAccess> {
    model.lft().block_access(&model.places()).unwrap()
}

#[test]
fn an_input_map_around_output_feedback_feeds_g_beside_the_feedback() {
    // y = G·(N₁(u) − N₂(y)) + e.
    let m = Structure::output_feedback(g(), d())
        .then(Site::Input, d())
        .model()
        .unwrap();
    // Block 0 is the feedback (n1), block 1 the input map (n2).
    check(
        &m,
        |u, e, x| {
            let y = x[0] + e;
            x[0] = 0.6 * x[0] + n2(&[u]) - n1(&[y]);
            y
        },
        1,
    );
    assert_eq!(
        access(&m),
        vec![BlockAccess::Computable, BlockAccess::Computable]
    );
}

#[test]
fn feedback_around_an_input_map_makes_the_input_map_read_u_minus_the_feedback() {
    // y = G·N₁(u − N₂(y)) + e: the input map reads the feedback's output in the same sample.
    let m = Structure::hammerstein(g(), d())
        .then(Site::OutputFeedback, d())
        .model()
        .unwrap();
    check(
        &m,
        |u, e, x| {
            let y = x[0] + e;
            x[0] = 0.6 * x[0] + n1(&[u - n2(&[y])]);
            y
        },
        1,
    );
    assert_eq!(
        access(&m),
        vec![
            BlockAccess::InSeries {
                upstream: vec!["N2".into()]
            },
            BlockAccess::Computable
        ]
    );
    assert_eq!(m.evaluation_order().unwrap(), vec![1, 0]);
}

#[test]
fn stiffness_and_friction_in_feedback_together() {
    // y = G·(u − N₁(y) − N₂(ẏ)) + e, ẏ_k = (y_k − y_(k−1))/T_s with T_s = 0.5.
    let m = Structure::output_feedback(g(), d())
        .then(Site::RateFeedback, d())
        .model()
        .unwrap();
    let friction = |z: &[f64]| 0.2 * z[0].tanh();
    check_with(
        &m,
        [&n1, &friction],
        |u, e, s| {
            let y = s[0] + e;
            let rate = (y - s[1]) / 0.5;
            s[1] = y;
            s[0] = 0.6 * s[0] + u - n1(&[y]) - friction(&[rate]);
            y
        },
        2,
    );
    assert!(access(&m).iter().all(BlockAccess::is_computable));
}

#[test]
fn a_sensor_behind_a_feedback_loop_makes_the_loop_latent() {
    // g = G·(u − N₁(g)), y = N₂(g) + e: the feedback reads the plant's output, which only the
    // sensor's map of it reveals.
    let m = Structure::output_feedback(g(), d())
        .then(Site::Output, d())
        .model()
        .unwrap();
    check(
        &m,
        |u, e, x| {
            let gk = x[0];
            x[0] = 0.6 * x[0] + u - n1(&[gk]);
            n2(&[gk]) + e
        },
        1,
    );
    assert_eq!(access(&m), vec![BlockAccess::Latent, BlockAccess::Latent]);
}

#[test]
fn chains_that_cannot_be_built_say_why() {
    // Feedback around an input map whose G has direct feedthrough closes a true cycle: the
    // feedback reads y, which reads the input map, which reads u minus the feedback.
    let direct = PolynomialModel {
        num: vec![vec![1.0, 0.5]],
        den: vec![1.0, -0.6],
        sample_time: None,
    };
    let e = Structure::hammerstein(&direct, d())
        .then(Site::OutputFeedback, d())
        .model()
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("algebraic loop") && e.contains("`N`") && e.contains("`N2`"),
        "{e}"
    );
    // So does feedback around a sensor map behind a G with direct feedthrough.
    let e = Structure::wiener(&direct, d())
        .then(Site::OutputFeedback, d())
        .model()
        .unwrap_err()
        .to_string();
    assert!(e.contains("algebraic loop"), "{e}");
    let e = Structure::output_feedback(g(), d())
        .then(Site::Declared { z: 0, w: 0 }, d())
        .lft()
        .unwrap_err()
        .to_string();
    assert!(e.contains("declared"), "{e}");
    // Names: the last placed block is renamed; a one-block structure keeps its old API.
    let s = Structure::output_feedback(g(), d())
        .named("spring")
        .then(Site::RateFeedback, d())
        .named("friction");
    let names: Vec<&str> = s.blocks().iter().map(|b| b.name.as_str()).collect();
    assert_eq!(names, ["spring", "friction"]);
    assert_eq!(s.site(), Some(Site::OutputFeedback));
}

//! Property tests: random stable systems are recovered from noise-free data.

use proptest::prelude::*;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use structid_lti::Signal;

use crate::testutil::{assert_close, white};
use crate::{ArxSettings, OeSettings, Orders, PolynomialModel, arx, output_error};

/// Polynomial `Π (1 − r q⁻¹)` over real roots and complex pairs `(radius, angle)`.
fn poly(reals: &[f64], pairs: &[(f64, f64)]) -> Vec<f64> {
    let mut p = vec![1.0];
    let mul = |p: &Vec<f64>, f: &[f64]| {
        let mut q = vec![0.0; p.len() + f.len() - 1];
        for (i, a) in p.iter().enumerate() {
            for (j, b) in f.iter().enumerate() {
                q[i + j] += a * b;
            }
        }
        q
    };
    for r in reals {
        p = mul(&p, &[1.0, -r]);
    }
    for (r, w) in pairs {
        p = mul(&p, &[1.0, -2.0 * r * w.cos(), r * r]);
    }
    p
}

/// A random stable system of order `n` (2 or 3) with `nb` coefficients and delay `nk`;
/// its poles have modulus in [0.2, 0.9] and its real zeros keep a distance ≥ 0.25 from them.
fn random_system(seed: u64, n: usize, nb: usize, nk: usize) -> PolynomialModel {
    let mut rng = StdRng::seed_from_u64(seed);
    let (mut reals, mut pairs) = (Vec::new(), Vec::new());
    let mut poles = Vec::new(); // (re, im)
    if rng.random_bool(0.5) {
        let (r, w) = (rng.random_range(0.3..0.9), rng.random_range(0.2..2.9));
        pairs.push((r, w));
        poles.push((r * f64::cos(w), r * f64::sin(w)));
    } else {
        for _ in 0..2 {
            let r = rng.random_range(0.2..0.9) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            reals.push(r);
            poles.push((r, 0.0));
        }
    }
    if n == 3 {
        let r = rng.random_range(-0.9..0.9);
        reals.push(r);
        poles.push((r, 0.0));
    }
    let mut zeros = Vec::new();
    while zeros.len() + 1 < nb {
        let z: f64 = rng.random_range(-1.5..1.5);
        if poles.iter().all(|(re, im)| (z - re).hypot(*im) > 0.25) {
            zeros.push(z);
        }
    }
    let gain = rng.random_range(0.5..2.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let mut num = vec![0.0; nk];
    num.extend(poly(&zeros, &[]).iter().map(|b| gain * b));
    PolynomialModel::new(vec![num], poly(&reals, &pairs), None).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn arx_recovers_noise_free_systems(seed in any::<u64>(), n in 2usize..=3, nb in 1usize..=3, nk in 0usize..=2) {
        let g = random_system(seed, n, nb, nk);
        let u = white(seed ^ 0x5555, 400, 1.0, 1);
        let y = Signal::new(1, g.simulate(&u).unwrap()).unwrap();
        let fit = arx(&u, &y, &Orders::siso(n, nb, nk), &ArxSettings::default()).unwrap();
        assert_close(&fit.model.parameters(), &g.parameters(), 1e-8);
    }

    #[test]
    fn oe_recovers_noise_free_systems_from_a_perturbed_start(
        seed in any::<u64>(), n in 2usize..=3, nb in 1usize..=3, nk in 0usize..=2,
    ) {
        let g = random_system(seed, n, nb, nk);
        let u = white(seed ^ 0xAAAA, 400, 1.0, 1);
        let y = Signal::new(1, g.simulate(&u).unwrap()).unwrap();
        let orders = Orders::siso(n, nb, nk);
        let truth = g.parameters();
        let mut rng = StdRng::seed_from_u64(seed ^ 0x1234);
        let mut size = 0.05;
        let start = loop {
            let theta: Vec<f64> = truth
                .iter()
                .map(|t| t + size * rng.random_range(-1.0..1.0) * t.abs().max(0.1))
                .collect();
            let m = PolynomialModel::from_parameters(&orders, &theta, None).unwrap();
            if m.is_stable() {
                break m;
            }
            size /= 2.0;
        };
        let fit = output_error(&u, &y, &start, &OeSettings::default()).unwrap();
        prop_assert!(fit.converged);
        let mut prev = fit.initial_cost;
        for &c in &fit.costs {
            prop_assert!(c <= prev);
            prev = c;
        }
        assert_close(&fit.model.parameters(), &truth, 1e-6);
    }
}

/// `a_0 y_k = Σ_j b_j u_{k−j} − Σ_{j≥1} a_j y_{k−j}` from rest, written out independently of
/// the library's recursion (no pre-normalisation by `a_0`).
fn difference_equation(num: &[f64], den: &[f64], u: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; u.len()];
    for k in 0..u.len() {
        let mut acc = 0.0;
        for (j, b) in num.iter().enumerate() {
            if j <= k {
                acc += b * u[k - j];
            }
        }
        for (j, a) in den.iter().enumerate().skip(1) {
            if j <= k {
                acc -= a * y[k - j];
            }
        }
        y[k] = acc / den[0];
    }
    y
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The polynomial model and the transfer function are one simulator: for a random stable
    /// `(num, den)` (non-monic), `PolynomialModel::simulate`, `TransferFunction::simulate`, the
    /// state-space realisation and a direct difference-equation recursion agree.
    #[test]
    fn polynomial_model_simulates_as_the_transfer_function(
        seed in any::<u64>(), na in 0usize..=4, nb in 1usize..=5, nk in 0usize..=2,
    ) {
        let mut rng = StdRng::seed_from_u64(seed);
        let reals: Vec<f64> = (0..na % 2).map(|_| rng.random_range(-0.95..0.95)).collect();
        let pairs: Vec<(f64, f64)> = (0..na / 2)
            .map(|_| (rng.random_range(0.1..0.95), rng.random_range(0.0..std::f64::consts::PI)))
            .collect();
        let a0 = rng.random_range(0.5..2.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let den: Vec<f64> = poly(&reals, &pairs).iter().map(|a| a0 * a).collect();
        let mut num = vec![0.0; nk];
        num.extend((0..nb).map(|_| rng.random_range(-2.0..2.0)));
        let u = white(seed ^ 0x7777, 300, 1.0, 1);

        let pm = PolynomialModel::new(vec![num.clone()], den.clone(), None).unwrap();
        let y_pm = pm.simulate(&u).unwrap();
        let y_tf = structid_lti::TransferFunction::siso(num.clone(), den.clone())
            .unwrap()
            .simulate(&u)
            .unwrap()
            .channel(0);
        let y_ss = {
            use structid_lti::LinearSystem;
            pm.to_state_space().unwrap().simulate(&u).unwrap().channel(0)
        };
        let y_ref = difference_equation(&num, &den, &u.channel(0));
        let scale = y_ref.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for k in 0..y_ref.len() {
            for (what, y) in [("PolynomialModel", &y_pm), ("TransferFunction", &y_tf), ("state space", &y_ss)] {
                prop_assert!(
                    (y[k] - y_ref[k]).abs() <= 1e-12 * scale,
                    "{what} at k = {k}: {} vs {} (scale {scale})", y[k], y_ref[k]
                );
            }
        }
    }
}

//! Unit tests of the selection criteria and the β search.

use super::*;
use std::sync::Arc;

use nalgebra::{DMatrix, DVector};
use structid_lti::{LinearSystem, Signal, StateSpace};

use crate::dispersion::KernelDispersion;
use crate::dispersion::kernel::{GaussianKernel, Kernel};
use crate::identify::problem::ProblemBlock;

/// A SISO problem with r = T_yw·w + e, w drawn from N(0, s²K/(Lβ)) and e from N(0, s²).
fn gp_problem(len: usize, beta: f64, sigma: f64, seed: u64) -> (Problem, DMatrix<f64>) {
    let path = structid_lti::testing::random_stable_system(seed, 2, 1, 1, 0.8);
    let mut rng = structid_lti::testing::SplitMix64::new(seed + 100);
    let mut normal = || {
        // Box–Muller from two uniforms.
        let (u1, u2) = (rng.uniform().max(1e-300), rng.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    };
    let z: Vec<f64> = (0..len).map(|_| 4.0 * normal().tanh()).collect();
    let kern = GaussianKernel::new(sigma).unwrap();
    let k = DMatrix::from_fn(len, len, |i, j| kern.eval(&[z[i]], &[z[j]]));
    let s2 = 0.01;
    let jitter = 1e-9 * k.diagonal().max();
    let chol = (&k + DMatrix::identity(len, len) * jitter)
        .cholesky()
        .unwrap();
    let xi = DVector::from_fn(len, |_, _| normal());
    let w = chol.l() * xi * (s2 / (len as f64 * beta)).sqrt();
    let mut tw = vec![0.0; len];
    path.apply(w.as_slice(), &mut tw);
    let r: Vec<f64> = (0..len).map(|i| tw[i] + s2.sqrt() * normal()).collect();
    let noise = StateSpace::static_gain(DMatrix::from_element(1, 1, 1.0)).unwrap();
    let block = ProblemBlock {
        name: "f".into(),
        output: 0,
        path: Arc::new(path),
        z: Signal::new(1, z).unwrap(),
        dispersion: Arc::new(KernelDispersion::gaussian(sigma).unwrap()),
    };
    let problem = Problem::new(Signal::new(1, r).unwrap(), Arc::new(noise), vec![block]).unwrap();
    (problem, k)
}

#[test]
fn criteria_equal_their_dense_definitions() {
    let (problem, k) = gp_problem(60, 1e-2, 0.5, 1);
    let len = 60;
    let path = problem.blocks()[0].path.as_state_space().unwrap().clone();
    let t = path.toeplitz_dense(len);
    let r = DVector::from_column_slice(problem.residual().as_slice());
    for criterion in [Criterion::MarginalLikelihood, Criterion::Gcv] {
        let mut score = DenseScore::new(&problem, criterion).unwrap();
        for beta in [1e-4, 1e-2, 1.0] {
            let lb = len as f64 * beta;
            let m = DMatrix::identity(len, len) * lb + &t * &k * t.transpose();
            let minv = m.clone().try_inverse().unwrap();
            let quad = (r.transpose() * &minv * &r)[(0, 0)];
            let ml = 0.5 * len as f64 * (quad / len as f64).ln() + 0.5 * m.determinant().ln();
            let h = &t * &k * t.transpose() * &minv;
            let i_h = DMatrix::identity(len, len) - &h;
            let gcv = len as f64 * (&i_h * &r).norm_squared() / i_h.trace().powi(2);
            let want = if criterion == Criterion::Gcv { gcv } else { ml };
            // the exact factorisation to rounding
            let (exact, _) = score.exact(beta).unwrap();
            assert!(
                (want - exact).abs() < 1e-8 * want.abs().max(1.0),
                "{criterion:?} β {beta}: {want} vs exact {exact}"
            );
            // the low-rank route within its certified bound (1e-4 in ML; GCV relative)
            let (fast, _) = score.score(beta).unwrap();
            let tol = if criterion == Criterion::Gcv {
                1e-4 * want
            } else {
                2e-4
            };
            assert!(
                (want - fast).abs() < tol,
                "{criterion:?} β {beta}: {want} vs factored {fast}"
            );
        }
    }
}

#[test]
fn marginal_likelihood_recovers_beta_from_its_own_model() {
    let beta0: f64 = 1e-3;
    for seed in [1, 2, 3] {
        let (problem, _) = gp_problem(800, beta0, 0.5, seed);
        let sel = select_beta(&problem, Criterion::MarginalLikelihood, 1.0).unwrap();
        let err = (sel.beta.ln() - beta0.ln()).abs();
        assert!(
            err < 0.5 * std::f64::consts::LN_10,
            "seed {seed}: β̂ = {:.3e}",
            sel.beta
        );
        // The search brackets: the chosen β is not at the end of the curve it walked.
        assert!(sel.curve.len() >= 8);
        assert!(
            (sel.noise_variance / 0.01 - 1.0).abs() < 0.3,
            "ŝ² = {}",
            sel.noise_variance
        );
    }
}

#[test]
fn gcv_finds_a_minimum_near_the_likelihood_choice() {
    let (problem, _) = gp_problem(400, 1e-2, 0.5, 7);
    let ml = select_beta(&problem, Criterion::MarginalLikelihood, 1e-4).unwrap();
    let gcv = select_beta(&problem, Criterion::Gcv, 1e-4).unwrap();
    // The GCV minimum is a true local minimum of its own curve, and within two decades of ML.
    let best = gcv.curve.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    assert_eq!(best, gcv.curve.iter().find(|p| p.0 == gcv.beta).unwrap().1);
    assert!(
        (gcv.beta.log10() - ml.beta.log10()).abs() < 2.0,
        "{} vs {}",
        gcv.beta,
        ml.beta
    );
}

#[test]
fn bad_inputs_are_errors() {
    let (problem, _) = gp_problem(20, 1e-2, 0.5, 1);
    assert!(select_beta(&problem, Criterion::Gcv, 0.0).is_err());
    assert!(select_beta(&problem, Criterion::Gcv, f64::NAN).is_err());
}

#[test]
fn dense_selection_over_the_memory_budget_is_an_error_not_an_allocation() {
    let exp = crate::paper::spray(
        300,
        0.5,
        Arc::new(KernelDispersion::gaussian(0.1).unwrap()),
        2,
    )
    .unwrap();
    let settings = crate::IdentifySettings::builder()
        .memory_limit_bytes(1 << 20)
        .build()
        .unwrap();
    let how = SelectionSettings::builder().build().unwrap();
    let e = select(&exp.model, &exp.data, None, &settings, &how).unwrap_err();
    assert!(matches!(e, crate::Error::TooLarge { .. }), "{e}");
    assert!(e.to_string().contains("window of at most about"), "{e}");
}

/// β and σ chosen by the search (Gram-factor route, warm trials, fallbacks) agree within 0.05
/// decades with a brute-force grid of the marginal likelihood evaluated independently: B from
/// dense Toeplitz and Gram matrices, its full eigendecomposition, ML on a 0.01-decade grid of β
/// for each σ on a 0.02-decade grid around the optimum.
#[test]
fn selected_beta_and_sigma_match_a_brute_force_grid_of_the_likelihood() {
    let len = 150;
    let sigma0 = 0.1;
    let exp = crate::paper::spray(
        len,
        1.0,
        Arc::new(KernelDispersion::gaussian(sigma0).unwrap()),
        1,
    )
    .unwrap();
    let how = SelectionSettings::builder()
        .tune_sigma(true)
        .build()
        .unwrap();
    let sel = select(
        &exp.model,
        &exp.data,
        None,
        &crate::IdentifySettings::default(),
        &how,
    )
    .unwrap();
    let problem = Problem::from_model(&exp.model, &exp.data).unwrap();
    let r = DVector::from_column_slice(problem.residual().as_slice());
    // the static noise path y = D·e with D·Dᵀ = 1: the rows need no whitening
    assert_eq!(problem.noise().order(), 0);
    let toeplitz: Vec<DMatrix<f64>> = problem
        .blocks()
        .iter()
        .map(|b| b.path.as_state_space().unwrap().toeplitz_dense(len))
        .collect();
    let n = len as f64;
    // min over the β grid of ML(β) at width factor 10^lf: (value, log₁₀ β)
    let best_beta = |lf: f64| -> (f64, f64) {
        let sigma = sigma0 * 10f64.powf(lf);
        let kern = GaussianKernel::new(sigma).unwrap();
        let mut b = DMatrix::<f64>::zeros(len, len);
        for (blk, t) in problem.blocks().iter().zip(&toeplitz) {
            let z = &blk.z;
            let k = DMatrix::from_fn(len, len, |i, j| kern.eval(z.sample(i), z.sample(j)));
            b += t * k * t.transpose();
        }
        let e = b.symmetric_eigen();
        let g = e.eigenvectors.transpose() * &r;
        let mut best = (f64::INFINITY, f64::NAN);
        for i in 0..=1400 {
            let lg = -10.0 + 0.01 * i as f64;
            let lb = n * 10f64.powf(lg);
            let (mut quad, mut logdet) = (0.0, 0.0);
            for j in 0..len {
                let d = e.eigenvalues[j].max(0.0) + lb;
                quad += g[j] * g[j] / d;
                logdet += d.ln();
            }
            let ml = 0.5 * n * (quad / n).ln() + 0.5 * logdet;
            if ml < best.0 {
                best = (ml, lg);
            }
        }
        best
    };
    let mut grid = (f64::INFINITY, f64::NAN, f64::NAN);
    for i in 0..=100 {
        let lf = -1.0 + 0.02 * i as f64;
        let (v, lg) = best_beta(lf);
        if v < grid.0 {
            grid = (v, lf, lg);
        }
    }
    let (_, lf, lg) = grid;
    let sel_lf = (sel.sigma.unwrap() / sigma0).log10();
    assert!(
        (sel_lf - lf).abs() <= 0.05 && (sel.beta.log10() - lg).abs() <= 0.05,
        "search: σ = {:.4}, β = {:.4e}; grid: σ = {:.4}, β = {:.4e}",
        sel.sigma.unwrap(),
        sel.beta,
        sigma0 * 10f64.powf(lf),
        10f64.powf(lg)
    );
}

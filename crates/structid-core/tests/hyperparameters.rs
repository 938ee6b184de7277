//! Hyperparameter selection across the paths: recovery from its own model, agreement of the
//! dense and feature paths, cross-validation for total variation, validation selection, and
//! the held-out rows it relies on.

use std::sync::Arc;

use structid_core::paper::{Experiment, gaussian_noise};
use structid_core::scenarios::{Excitation, hammerstein_map};
use structid_core::selection::{Criterion, Selection, SelectionSettings, select};
use structid_core::{
    Dispersion, FeatureMap, FourierDispersion, FourierWeights, Identification, IdentifySettings,
    KernelDispersion, Problem, SolverChoice, TotalVariation, identify_problem,
};
use structid_lti::testing::SplitMix64;

fn normal(rng: &mut SplitMix64) -> f64 {
    let (u1, u2) = (rng.uniform().max(1e-300), rng.uniform());
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

fn fourier(sigma: f64) -> Arc<dyn Dispersion> {
    Arc::new(FourierDispersion::new(FourierWeights::GaussianLike { sigma }).unwrap())
}

/// Data from the GP model itself: a Hammerstein system whose map is drawn from
/// N(0, s²·K/(L·β)) for the Fourier kernel of width `sigma` on the record's z, with white noise
/// of variance s².
fn gp_experiment(len: usize, beta: f64, sigma: f64, s2: f64, seed: u64) -> Experiment {
    let base =
        hammerstein_map(len, 2, 0.0, &|z| z, Excitation::White, fourier(sigma), seed).unwrap();
    let z = base.data.u().clone();
    let kernel = FourierDispersion::new(FourierWeights::GaussianLike { sigma })
        .unwrap()
        .kernel_for(&z)
        .unwrap();
    let mut rng = SplitMix64::new(seed ^ 0x5EED);
    let c = s2 / (len as f64 * beta);
    let coef: Vec<f64> = kernel
        .weights()
        .iter()
        .map(|l| (c * l).sqrt() * normal(&mut rng))
        .collect();
    let map = move |p: &[f64]| {
        let mut psi = vec![0.0; kernel.dim()];
        kernel.eval_into(p, &mut psi);
        psi.iter().zip(&coef).map(|(a, b)| a * b).sum::<f64>()
    };
    let noise = gaussian_noise(len, 1, s2.sqrt(), seed ^ 77);
    Experiment::simulate(base.model, &[&map], z, noise).unwrap()
}

#[test]
fn marginal_likelihood_recovers_beta_and_sigma_from_its_own_model() {
    let (beta0, sigma0, s2) = (1e-3, 0.1, 0.01);
    for seed in [11, 12, 13] {
        let exp = gp_experiment(2000, beta0, sigma0, s2, seed);
        // start away from the truth: σ twice too wide, β at the default start
        let model = exp.model.with_dispersions(|_| fourier(2.0 * sigma0));
        let how = SelectionSettings::builder()
            .criterion(Criterion::MarginalLikelihood)
            .tune_sigma(true)
            .build()
            .unwrap();
        let sel = select(&model, &exp.data, None, &IdentifySettings::default(), &how).unwrap();
        let sigma = sel.sigma.unwrap();
        eprintln!(
            "seed {seed}: β̂ = {:.3e}, σ̂ = {:.4}, ŝ² = {:.4}, {} trials, {:.2} s",
            sel.beta,
            sel.sigma.unwrap(),
            sel.noise_variance.unwrap(),
            sel.curve.len(),
            sel.seconds
        );
        assert!(
            (sel.beta.log10() - beta0.log10()).abs() <= 0.5,
            "seed {seed}: β̂ = {:.3e} (true {beta0:.0e}); {}",
            sel.beta,
            sel.method
        );
        assert!(
            (sigma / sigma0 - 1.0).abs() <= 0.3,
            "seed {seed}: σ̂ = {sigma:.3} (true {sigma0})"
        );
        let nv = sel.noise_variance.unwrap();
        assert!((nv / s2 - 1.0).abs() < 0.2, "seed {seed}: ŝ² = {nv}");
        assert!(sel.method.contains("feature space"), "{}", sel.method);
        assert_eq!(sel.identification.cost.beta, sel.beta);
    }
}

/// Selects β by `criterion` through the dense (exact) and the feature path and checks that
/// they evaluate the same function (equal values at every β both tried) and choose the same β.
fn dense_and_feature_agree(exp: &Experiment, criterion: Criterion) -> (Selection, Selection) {
    let how = SelectionSettings::builder()
        .criterion(criterion)
        .build()
        .unwrap();
    let run = |solver| {
        let settings = IdentifySettings::builder().solver(solver).build().unwrap();
        select(&exp.model, &exp.data, None, &settings, &how).unwrap()
    };
    let (dense, feat) = (run(SolverChoice::Exact), run(SolverChoice::Features));
    assert!(dense.method.contains("dense"), "{}", dense.method);
    assert!(feat.method.contains("feature"), "{}", feat.method);
    for t in &dense.curve {
        if let Some(u) = feat.curve.iter().find(|u| u.beta == t.beta) {
            let tol = if criterion == Criterion::Gcv {
                1e-4 * t.value.abs()
            } else {
                1e-3
            };
            assert!(
                (t.value - u.value).abs() <= tol,
                "{criterion:?} at β {}: {} vs {}",
                t.beta,
                t.value,
                u.value
            );
        }
    }
    assert!(
        (dense.beta.log10() - feat.beta.log10()).abs() <= 0.03,
        "{criterion:?}: dense β {:.4e} vs feature β {:.4e}",
        dense.beta,
        feat.beta
    );
    (dense, feat)
}

#[test]
fn dense_and_feature_paths_choose_the_same_beta() {
    let exp = gp_experiment(400, 1e-2, 0.5, 0.01, 5);
    for criterion in [Criterion::MarginalLikelihood, Criterion::Gcv] {
        dense_and_feature_agree(&exp, criterion);
    }
}

/// Fits `problem` at β = 1e-2 with two solvers; also the largest |ŵ| of the first fit.
fn fit_both(
    problem: &Problem,
    a: SolverChoice,
    b: SolverChoice,
) -> (Identification, Identification, f64) {
    let fit = |solver| {
        let s = IdentifySettings::builder()
            .beta(1e-2)
            .solver(solver)
            .build()
            .unwrap();
        identify_problem(problem, &s).unwrap()
    };
    let (x, y) = (fit(a), fit(b));
    let scale = x.blocks[0].w_hat.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    (x, y, scale)
}

#[test]
fn held_out_rows_give_the_same_fit_in_the_exact_and_conic_solvers() {
    let exp = hammerstein_map(
        120,
        2,
        0.05,
        &|z| z.tanh(),
        Excitation::White,
        Arc::new(KernelDispersion::gaussian(0.5).unwrap()),
        3,
    )
    .unwrap();
    let mut mask = vec![false; 120];
    mask[40..70].iter_mut().for_each(|v| *v = true);
    let problem = Problem::from_model(&exp.model, &exp.data)
        .unwrap()
        .with_held_out(mask.clone())
        .unwrap();
    let (ex, co, scale) = fit_both(&problem, SolverChoice::Exact, SolverChoice::Clarabel);
    for k in 0..120 {
        assert!(
            (ex.blocks[0].w_hat[k] - co.blocks[0].w_hat[k]).abs() < 1e-4 * scale,
            "sample {k}"
        );
    }
    // and leaving rows out changes the fit (the mask is not ignored)
    let full = identify_problem(
        &Problem::from_model(&exp.model, &exp.data).unwrap(),
        &IdentifySettings::builder().beta(1e-2).build().unwrap(),
    )
    .unwrap();
    let diff = (0..120)
        .map(|k| (full.blocks[0].w_hat[k] - ex.blocks[0].w_hat[k]).abs())
        .fold(0.0, f64::max);
    assert!(diff > 1e-6 * scale);
    // ADMM leaves the held-out samples out of its smoother and finds Clarabel's fit
    let s = IdentifySettings::builder()
        .solver(SolverChoice::Admm)
        .admm(
            structid_core::solver::admm::AdmmSettings::builder()
                .tolerance(1e-9)
                .max_iterations(200_000)
                .build()
                .unwrap(),
        )
        .build()
        .unwrap();
    let tv = Problem::from_model(
        &exp.model
            .with_dispersions(|_| Arc::new(TotalVariation::default())),
        &exp.data,
    )
    .unwrap()
    .with_held_out(mask.clone())
    .unwrap();
    let admm = identify_problem(&tv, &s).unwrap();
    let conic = identify_problem(&tv, &s.with_solver(SolverChoice::Clarabel)).unwrap();
    // (The held-out samples' map values, seen through the states only, may be set by the
    // total variation alone, where the minimiser is not unique: compare the others and J.)
    let kept =
        |w: &[f64]| -> Vec<f64> { (0..w.len()).filter(|&k| !mask[k]).map(|k| w[k]).collect() };
    let (wa, wc) = (kept(admm.w_hat.as_slice()), kept(conic.w_hat.as_slice()));
    let num: f64 = wa.iter().zip(&wc).map(|(a, c)| (a - c).powi(2)).sum();
    let den: f64 = wc.iter().map(|c| c * c).sum();
    assert!(
        (num / den).sqrt() < 1e-4,
        "relative ŵ difference {}",
        (num / den).sqrt()
    );
    assert!((admm.cost.total - conic.cost.total).abs() < 1e-6 * conic.cost.total);
}

/// RMS error of the estimated map against the truth on the data points.
fn map_error(
    sel_map: &dyn structid_core::Interpolant,
    z: &[f64],
    truth: &dyn Fn(f64) -> f64,
) -> f64 {
    let se: f64 = z
        .iter()
        .map(|&v| (sel_map.eval(&[v]) - truth(v)).powi(2))
        .sum();
    (se / z.len() as f64).sqrt()
}

#[test]
fn cross_validation_picks_a_good_beta_for_total_variation() {
    let truth = |z: f64| if z.abs() < 0.5 { 0.0 } else { z.signum() };
    let exp = hammerstein_map(
        300,
        2,
        0.1,
        &truth,
        Excitation::White,
        Arc::new(TotalVariation::default()),
        9,
    )
    .unwrap();
    let how = SelectionSettings::builder()
        .criterion(Criterion::CrossValidation { folds: 5 })
        .build()
        .unwrap();
    let settings = IdentifySettings::default();
    let sel = select(&exp.model, &exp.data, None, &settings, &how).unwrap();
    assert!(sel.method.contains("5-fold"), "{}", sel.method);
    let z = exp.data.u().channel(0);
    let err_at = |beta: f64| {
        let p = Problem::from_model(&exp.model, &exp.data).unwrap();
        let id = identify_problem(&p, &settings.with_beta(beta).unwrap()).unwrap();
        map_error(id.blocks[0].map.as_ref(), &z, &truth)
    };
    let chosen = map_error(sel.identification.blocks[0].map.as_ref(), &z, &truth);
    // the choice is far better than two decades off either way
    let (lo, hi) = (err_at(sel.beta * 1e-2), err_at(sel.beta * 1e2));
    assert!(
        chosen < 0.8 * lo.min(hi),
        "chosen {chosen:.4} at β {:.2e}; 100× off: {lo:.4} / {hi:.4}",
        sel.beta
    );
}

#[test]
fn validation_selection_needs_a_record_and_minimises_simulation_error() {
    let truth = |z: f64| (2.0 * z).tanh();
    let est = hammerstein_map(200, 2, 0.1, &truth, Excitation::White, fourier(0.3), 4).unwrap();
    let val = hammerstein_map(200, 2, 0.0, &truth, Excitation::White, fourier(0.3), 5).unwrap();
    // same system (the order-2 path depends on the seed), so rebuild validation data on est's model
    let val = Experiment::simulate(
        est.model.clone(),
        &[&|p: &[f64]| truth(p[0])],
        val.data.u().clone(),
        gaussian_noise(200, 1, 0.0, 1),
    )
    .unwrap();
    let how = SelectionSettings::builder()
        .criterion(Criterion::Validation)
        .build()
        .unwrap();
    let settings = IdentifySettings::default();
    assert!(select(&est.model, &est.data, None, &settings, &how).is_err());
    let sel = select(&est.model, &est.data, Some(&val.data), &settings, &how).unwrap();
    let best = sel
        .curve
        .iter()
        .map(|t| t.value)
        .fold(f64::INFINITY, f64::min);
    // brute force on a grid: no β of the grid beats the search by more than 5 %
    for lg in -5..=1 {
        let beta = 10f64.powi(lg);
        let p = Problem::from_model(&est.model, &est.data).unwrap();
        let id = identify_problem(&p, &settings.with_beta(beta).unwrap()).unwrap();
        let maps: Vec<&dyn structid_core::Interpolant> = vec![id.blocks[0].map.as_ref()];
        let sim = est.model.simulate(&maps, val.data.u(), None, None).unwrap();
        let mse = val
            .data
            .y()
            .as_slice()
            .iter()
            .zip(sim.y.as_slice())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            / 200.0;
        assert!(
            best <= 1.05 * mse,
            "grid β {beta:e}: {mse:.3e} < search {best:.3e}"
        );
    }
}

#[test]
fn bad_selection_settings_are_errors() {
    assert!(
        SelectionSettings::builder()
            .beta_bounds(1.0, 0.1)
            .build()
            .is_err()
    );
    assert!(SelectionSettings::builder().tolerance(0.0).build().is_err());
    assert!(
        SelectionSettings::builder()
            .tune_beta(false)
            .tune_sigma(false)
            .build()
            .is_err()
    );
    // σ cannot be tuned for total variation
    let exp = hammerstein_map(
        50,
        1,
        0.1,
        &|z| z,
        Excitation::White,
        Arc::new(TotalVariation::default()),
        1,
    )
    .unwrap();
    let how = SelectionSettings::builder()
        .tune_sigma(true)
        .criterion(Criterion::CrossValidation { folds: 3 })
        .build()
        .unwrap();
    assert!(
        select(
            &exp.model,
            &exp.data,
            None,
            &IdentifySettings::default(),
            &how
        )
        .is_err()
    );
    // marginal likelihood is for quadratic dispersions
    let how = SelectionSettings::default();
    assert!(
        select(
            &exp.model,
            &exp.data,
            None,
            &IdentifySettings::default(),
            &how
        )
        .is_err()
    );
}

#[test]
fn more_features_than_samples_agree_with_the_dense_path() {
    // σ = 0.05 on this record needs m ≈ 350 features for L = 60 rows
    let exp = gp_experiment(60, 1e-2, 0.05, 0.01, 21);
    for criterion in [Criterion::MarginalLikelihood, Criterion::Gcv] {
        let (_, feat) = dense_and_feature_agree(&exp, criterion);
        let m: usize = feat
            .method
            .split("m = ")
            .nth(1)
            .unwrap()
            .split(';')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(m > 60, "m = {m}");
    }
}

#[test]
fn held_out_rows_give_the_same_fit_in_the_feature_and_exact_solvers() {
    let exp = gp_experiment(150, 1e-2, 0.5, 0.01, 8);
    let mut mask = vec![false; 150];
    mask[50..90].iter_mut().for_each(|v| *v = true);
    let problem = Problem::from_model(&exp.model, &exp.data)
        .unwrap()
        .with_held_out(mask.clone())
        .unwrap();
    let (ex, fe, scale) = fit_both(&problem, SolverChoice::Exact, SolverChoice::Features);
    for k in 0..150 {
        assert!(
            (ex.blocks[0].w_hat[k] - fe.blocks[0].w_hat[k]).abs() < 1e-7 * scale,
            "ŵ at {k}"
        );
        assert!(
            (ex.e_hat.get(k, 0) - fe.e_hat.get(k, 0)).abs() < 1e-7 * scale.max(1.0),
            "ê at {k}"
        );
        if mask[k] {
            assert_eq!(fe.e_hat.get(k, 0), 0.0, "held-out noise estimate at {k}");
        }
    }
    // so cross-validation scores the same through either solver
    let how = SelectionSettings::builder()
        .criterion(Criterion::CrossValidation { folds: 3 })
        .build()
        .unwrap();
    let cv = |solver| {
        let s = IdentifySettings::builder().solver(solver).build().unwrap();
        select(&exp.model, &exp.data, None, &s, &how).unwrap()
    };
    let (a, b) = (cv(SolverChoice::Exact), cv(SolverChoice::Features));
    assert!(
        a.curve[0].value > 1e-4,
        "a held-out error cannot vanish: {}",
        a.curve[0].value
    );
    assert!((a.curve[0].value - b.curve[0].value).abs() < 1e-6 * a.curve[0].value);
}

#[test]
fn a_beta_on_a_search_bound_is_flagged() {
    use structid_core::selection::Bound;
    let (beta0, sigma, s2) = (1e-4, 0.1, 0.01);
    let ml_widened = |lo: f64, hi: f64, widen: f64| {
        SelectionSettings::builder()
            .criterion(Criterion::MarginalLikelihood)
            .beta_bounds(lo, hi)
            .widen_decades(widen)
            .build()
            .unwrap()
    };
    let ml = |lo: f64, hi: f64| ml_widened(lo, hi, 0.0);
    let settings = IdentifySettings::default();
    let exp = gp_experiment(600, beta0, sigma, s2, 21);
    // Interior: the likelihood's maximiser near β₀ = 1e-4 lies well inside [1e-10, 1e4].
    let sel = select(&exp.model, &exp.data, None, &settings, &ml(1e-10, 1e4)).unwrap();
    assert!(sel.beta > 1e-6 && sel.beta < 1e-2, "β = {}", sel.beta);
    assert_eq!(sel.beta_at_bound, None, "β = {}", sel.beta);
    assert_eq!(sel.sigma_at_bound, None);
    // The same data with the search confined above the maximiser: it ends on the floor.
    let sel = select(&exp.model, &exp.data, None, &settings, &ml(1e-2, 1e2)).unwrap();
    assert_eq!(sel.beta_at_bound, Some(Bound::Lower), "β = {}", sel.beta);
    assert!((sel.beta - 1e-2).abs() < 1e-12);
    assert!(
        sel.identification
            .diagnostics
            .warnings
            .iter()
            .any(|w| w.contains("lower bound") && w.contains("less regularisation")),
        "{:?}",
        sel.identification.diagnostics.warnings
    );
    // Widened once (the default), the search looks past the floor and finds the interior
    // maximiser that the full range finds.
    let full = select(&exp.model, &exp.data, None, &settings, &ml(1e-10, 1e4)).unwrap();
    let sel = select(
        &exp.model,
        &exp.data,
        None,
        &settings,
        &ml_widened(1e-2, 1e2, 6.0),
    )
    .unwrap();
    assert_eq!(sel.beta_at_bound, None, "β = {}", sel.beta);
    assert!(
        (sel.beta.log10() - full.beta.log10()).abs() < 0.05,
        "widened β {} against {}",
        sel.beta,
        full.beta
    );
    // Pure noise (the map is zero): the likelihood grows without bound with β (the prior
    // variance of the map shrinks to zero), so β runs to the top of its interval.
    let base = gp_experiment(600, beta0, sigma, s2, 22);
    let z = base.data.u().clone();
    let noise = gaussian_noise(600, 1, s2.sqrt(), 23);
    let zero = |_: &[f64]| 0.0;
    let exp = Experiment::simulate(base.model, &[&zero], z, noise).unwrap();
    let sel = select(&exp.model, &exp.data, None, &settings, &ml(1e-10, 1e4)).unwrap();
    assert_eq!(sel.beta_at_bound, Some(Bound::Upper), "β = {}", sel.beta);
}

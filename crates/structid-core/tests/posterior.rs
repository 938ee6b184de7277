//! Posterior uncertainty bands: the dense formula against a brute-force dense computation, the
//! feature path against the dense path, Monte Carlo coverage on maps drawn from the prior, the
//! coverage on a fixed map (printed), and the cases without a posterior.
//!
//! Run with `cargo test --release -p structid-core --test posterior -- --nocapture` to see the
//! coverage numbers.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector, dmatrix};
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, StandardNormal};
use structid_core::solver::admm::AdmmSettings;
use structid_core::{
    Dispersion, Error, FeatureMap, FourierDispersion, FourierKernel, FourierWeights,
    GaussianKernel, IdentifySettings, InitialState, Kernel, KernelDispersion, Problem,
    ProblemBlock, Signal, SolverChoice, TotalVariation, identify, identify_problem, paper,
};
use structid_lti::{LinearSystem, StateSpace};

// --- problem construction ---------------------------------------------------------------------

/// A SISO state-space system from (A, B, C, D).
fn ss(a: DMatrix<f64>, b: DMatrix<f64>, c: DMatrix<f64>, d: DMatrix<f64>) -> StateSpace {
    StateSpace::new(a, b, c, d).unwrap()
}

/// White noise: y = e.
fn white() -> StateSpace {
    ss(
        DMatrix::zeros(0, 0),
        DMatrix::zeros(0, 1),
        DMatrix::zeros(1, 0),
        dmatrix![1.0],
    )
}

/// Coloured, minimum-phase noise: H(q) = (1 + 0.5q⁻¹)/(1 − 0.7q⁻¹).
fn coloured() -> StateSpace {
    ss(dmatrix![0.7], dmatrix![1.0], dmatrix![1.2], dmatrix![1.0])
}

/// A second-order block path with a direct term.
fn path_a() -> StateSpace {
    ss(
        dmatrix![1.1, -0.3; 1.0, 0.0],
        dmatrix![1.0; 0.0],
        dmatrix![0.5, 0.2],
        dmatrix![1.0],
    )
}

/// A first-order block path with a direct term.
fn path_b() -> StateSpace {
    ss(dmatrix![-0.4], dmatrix![1.0], dmatrix![0.6], dmatrix![0.8])
}

/// One block: its path, inputs, kernel (for the brute force) and dispersion (for the solver).
struct BlockSpec {
    path: StateSpace,
    z: Signal,
    kernel: Arc<dyn Kernel>,
    dispersion: Arc<dyn Dispersion>,
}

fn gaussian_block(path: StateSpace, z: Signal, sigma: f64) -> BlockSpec {
    BlockSpec {
        path,
        z,
        kernel: Arc::new(GaussianKernel::new(sigma).unwrap()),
        dispersion: Arc::new(KernelDispersion::gaussian(sigma).unwrap()),
    }
}

fn fourier_dispersion(sigma: f64, harmonics: usize) -> FourierDispersion {
    FourierDispersion::new(FourierWeights::GaussianLike { sigma })
        .unwrap()
        .with_harmonics(harmonics)
        .with_domain(vec![(-1.0, 1.0)])
        .unwrap()
}

fn fourier_block(path: StateSpace, z: Signal, sigma: f64, harmonics: usize) -> BlockSpec {
    let d = fourier_dispersion(sigma, harmonics);
    BlockSpec {
        kernel: Arc::new(d.kernel_for(&z).unwrap()),
        dispersion: Arc::new(d),
        path,
        z,
    }
}

fn uniform(rng: &mut StdRng, len: usize) -> Signal {
    Signal::from_fn(len, 1, |_, _| rng.random_range(-1.0..1.0))
}

fn normal(rng: &mut StdRng) -> f64 {
    StandardNormal.sample(rng)
}

/// Free-response columns for an estimated initial state (any full-rank O will do).
fn free_response(len: usize) -> faer::Mat<f64> {
    faer::Mat::from_fn(len, 2, |k, j| match j {
        0 => 0.9f64.powi(k as i32),
        _ => 0.8f64.powi(k as i32) * (0.7 * k as f64).cos(),
    })
}

fn problem(
    r: &[f64],
    noise: &StateSpace,
    blocks: &[BlockSpec],
    free: Option<faer::Mat<f64>>,
) -> Problem {
    let pb = blocks
        .iter()
        .enumerate()
        .map(|(i, b)| ProblemBlock {
            name: format!("b{i}"),
            output: i,
            path: Arc::new(b.path.clone()),
            z: b.z.clone(),
            dispersion: Arc::clone(&b.dispersion),
        })
        .collect();
    let p = Problem::new(
        Signal::new(1, r.to_vec()).unwrap(),
        Arc::new(noise.clone()),
        pb,
    )
    .unwrap();
    match free {
        Some(o) => p.with_free_response(o).unwrap(),
        None => p,
    }
}

/// r = Σ_i T_i·N_i(z_i) + T_ye·e (+ O·x₀) with smooth maps and unit-variance e scaled by `s`.
fn residual(
    rng: &mut StdRng,
    noise: &StateSpace,
    blocks: &[BlockSpec],
    s: f64,
    free: Option<&faer::Mat<f64>>,
) -> Vec<f64> {
    let len = blocks[0].z.len();
    let mut r = vec![0.0; len];
    let mut tmp = vec![0.0; len];
    for (i, b) in blocks.iter().enumerate() {
        let w: Vec<f64> = (0..len)
            .map(|k| {
                let x = b.z.get(k, 0);
                if i == 0 {
                    (2.0 * x).tanh()
                } else {
                    x * x - 0.3
                }
            })
            .collect();
        b.path.apply(&w, &mut tmp);
        r.iter_mut().zip(&tmp).for_each(|(a, t)| *a += t);
    }
    let e: Vec<f64> = (0..len).map(|_| s * normal(rng)).collect();
    noise.apply(&e, &mut tmp);
    r.iter_mut().zip(&tmp).for_each(|(a, t)| *a += t);
    if let Some(o) = free {
        for (k, v) in r.iter_mut().enumerate() {
            *v += 0.7 * o[(k, 0)] - 0.4 * o[(k, 1)];
        }
    }
    r
}

fn settings(beta: f64, solver: SolverChoice) -> IdentifySettings {
    IdentifySettings::builder()
        .beta(beta)
        .solver(solver)
        .posterior(true)
        .build()
        .unwrap()
}

// --- brute force --------------------------------------------------------------------------------

/// The dense formulas with explicit Toeplitz matrices, Gram matrices and a dense inverse.
struct BruteForce {
    /// P = M⁻¹, projected for x₀, on the live rows.
    p: DMatrix<f64>,
    live: Vec<usize>,
    c: f64,
    s2: f64,
    r: DVector<f64>,
}

impl BruteForce {
    fn new(
        r: &[f64],
        noise: &StateSpace,
        blocks: &[BlockSpec],
        beta: f64,
        free: Option<&faer::Mat<f64>>,
    ) -> Self {
        let len = r.len();
        let lb = len as f64 * beta;
        let te = noise.toeplitz_dense(len);
        let mut m = lb * &te * te.transpose();
        for b in blocks {
            let t = b.path.toeplitz_dense(len);
            let k = DMatrix::from_fn(len, len, |i, j| b.kernel.eval(b.z.sample(i), b.z.sample(j)));
            m += &t * k * t.transpose();
        }
        let scale = m.diagonal().amax();
        let live: Vec<usize> = (0..len).filter(|&i| m[(i, i)] > 1e-14 * scale).collect();
        let nk = live.len();
        let mk = DMatrix::from_fn(nk, nk, |i, j| m[(live[i], live[j])]);
        let minv = mk.try_inverse().expect("M is invertible");
        let mut p = minv.clone();
        let mut nx = 0;
        if let Some(o) = free {
            nx = o.ncols();
            let ok = DMatrix::from_fn(nk, nx, |i, j| o[(live[i], j)]);
            let mo = &minv * &ok;
            let h = ok.transpose() * &mo;
            p -= &mo * h.try_inverse().unwrap() * mo.transpose();
        }
        let rv = DVector::from_fn(nk, |i, _| r[live[i]]);
        let quad = rv.dot(&(&p * &rv));
        let c = quad / (nk - nx) as f64;
        Self {
            p,
            live,
            c,
            s2: lb * c,
            r: rv,
        }
    }

    /// (posterior mean, posterior std) of block `b` at `points`.
    fn at(&self, blocks: &[BlockSpec], b: usize, points: &Signal) -> (Vec<f64>, Vec<f64>) {
        let spec = &blocks[b];
        let len = spec.z.len();
        let t = spec.path.toeplitz_dense(len);
        let (mut mean, mut std) = (Vec::new(), Vec::new());
        for j in 0..points.len() {
            let pt = points.sample(j);
            let kz = DVector::from_fn(len, |k, _| spec.kernel.eval(spec.z.sample(k), pt));
            let v_all = &t * kz;
            let v = DVector::from_fn(self.live.len(), |i, _| v_all[self.live[i]]);
            let pv = &self.p * &v;
            mean.push(pv.dot(&self.r));
            let var = self.c * (spec.kernel.eval(pt, pt) - v.dot(&pv));
            std.push(var.max(0.0).sqrt());
        }
        (mean, std)
    }
}

fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / y.abs().max(1e-300))
        .fold(0.0, f64::max)
}

fn grid(n: usize, lo: f64, hi: f64) -> Signal {
    Signal::from_fn(n, 1, |k, _| lo + (hi - lo) * k as f64 / (n - 1) as f64)
}

// --- 1. dense formula = brute force -------------------------------------------------------------

#[test]
fn dense_posterior_equals_the_brute_force_formula() {
    let len = 30;
    let beta = 0.02;
    let pts = grid(13, -1.3, 1.3);
    let mut rng = StdRng::seed_from_u64(11);
    // (name, noise path, blocks, x₀ estimated)
    let cases: Vec<(&str, StateSpace, Vec<BlockSpec>, bool)> = vec![
        (
            "one block, white noise",
            white(),
            vec![gaussian_block(path_a(), uniform(&mut rng, len), 0.3)],
            false,
        ),
        (
            "two blocks, coloured noise",
            coloured(),
            vec![
                gaussian_block(path_a(), uniform(&mut rng, len), 0.3),
                gaussian_block(path_b(), uniform(&mut rng, len), 0.5),
            ],
            false,
        ),
        (
            "two blocks, coloured noise, x₀ estimated",
            coloured(),
            vec![
                gaussian_block(path_a(), uniform(&mut rng, len), 0.3),
                gaussian_block(path_b(), uniform(&mut rng, len), 0.5),
            ],
            true,
        ),
        (
            "strictly proper paths: the first sample is dropped",
            ss(dmatrix![0.5], dmatrix![1.0], dmatrix![1.0], dmatrix![0.0]),
            vec![gaussian_block(
                ss(dmatrix![0.3], dmatrix![1.0], dmatrix![1.0], dmatrix![0.0]),
                uniform(&mut rng, len),
                0.4,
            )],
            false,
        ),
    ];
    for (name, noise, blocks, with_x0) in &cases {
        let free = with_x0.then(|| free_response(len));
        let r = residual(&mut rng, noise, blocks, 0.3, free.as_ref());
        let p = problem(&r, noise, blocks, free.clone());
        let id = identify_problem(&p, &settings(beta, SolverChoice::Exact)).unwrap();
        let post = id.posterior.as_ref().expect("posterior kept");
        assert_eq!(post.path(), "exact");
        let bf = BruteForce::new(&r, noise, blocks, beta, free.as_ref());
        let s2_err = (post.noise_variance() - bf.s2).abs() / bf.s2;
        assert!(
            s2_err < 1e-9,
            "{name}: ŝ² {} vs {}",
            post.noise_variance(),
            bf.s2
        );
        for b in 0..blocks.len() {
            let std = id.posterior_std(b, &pts).unwrap().unwrap();
            let (mean_bf, std_bf) = bf.at(blocks, b, &pts);
            let err = max_rel(&std, &std_bf);
            println!("{name}, block {b}: max relative std error {err:.2e}, ŝ² error {s2_err:.1e}");
            assert!(err < 1e-8, "{name}, block {b}: {std:?} vs {std_bf:?}");
            // The GP posterior mean is the estimate (up to the flat-prior x₀ handling).
            let mean = id.blocks[b].map.eval_many(&pts);
            let scale = mean_bf.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            for (a, c) in mean.iter().zip(&mean_bf) {
                assert!((a - c).abs() < 1e-8 * scale, "{name}: mean {a} vs {c}");
            }
        }
        if name.starts_with("strictly") {
            assert_eq!(id.diagnostics.dropped_samples, vec![0]);
            assert_eq!(post.degrees_of_freedom(), len - 1);
        }
        if *with_x0 {
            assert_eq!(post.degrees_of_freedom(), len - 2);
        }
    }
}

// --- 2. feature path = dense path ---------------------------------------------------------------

#[test]
fn feature_posterior_equals_the_dense_posterior_for_a_fourier_kernel() {
    let len = 200;
    let beta = 0.005;
    let pts = grid(25, -1.0, 1.0);
    let mut rng = StdRng::seed_from_u64(5);
    for noise in [white(), coloured()] {
        for with_x0 in [false, true] {
            let blocks = vec![
                fourier_block(path_a(), uniform(&mut rng, len), 0.3, 12),
                fourier_block(path_b(), uniform(&mut rng, len), 0.5, 8),
            ];
            let free = with_x0.then(|| free_response(len));
            let r = residual(&mut rng, &noise, &blocks, 0.2, free.as_ref());
            let p = problem(&r, &noise, &blocks, free);
            let dense = identify_problem(&p, &settings(beta, SolverChoice::Exact)).unwrap();
            let feat = identify_problem(&p, &settings(beta, SolverChoice::Features)).unwrap();
            let (pd, pf) = (
                dense.posterior.as_ref().unwrap(),
                feat.posterior.as_ref().unwrap(),
            );
            assert_eq!(pf.path(), "features");
            let s2_err = (pd.noise_variance() - pf.noise_variance()).abs() / pd.noise_variance();
            assert!(
                s2_err < 1e-8,
                "ŝ²: dense {} vs features {}",
                pd.noise_variance(),
                pf.noise_variance()
            );
            for b in 0..2 {
                let sd = dense.posterior_std(b, &pts).unwrap().unwrap();
                let sf = feat.posterior_std(b, &pts).unwrap().unwrap();
                let err = max_rel(&sf, &sd);
                println!(
                    "noise order {}, x₀ {with_x0}, block {b}: ŝ² = {:.5}, std {:.4}..{:.4}, max relative difference {err:.2e}",
                    noise.order(),
                    pf.noise_variance(),
                    sd.iter().cloned().fold(f64::INFINITY, f64::min),
                    sd.iter().cloned().fold(0.0, f64::max),
                );
                assert!(err < 1e-7, "block {b}: {sf:?} vs {sd:?}");
            }
        }
    }
}

// --- 3. Monte Carlo coverage --------------------------------------------------------------------

/// How the true map is drawn from the prior.
#[derive(Clone, Copy, Debug)]
enum Prior {
    /// Exactly, through the finitely many Fourier features: N = √c·ψᵀΛ^½·ξ.
    Fourier,
    /// Jointly at the samples and the evaluation points, Cholesky of the Gaussian Gram matrix
    /// with a 1e-10 relative jitter.
    Gaussian,
}

/// Empirical coverage of N̂ ± 1.96·std over `reps` records × `pts` points; the maps are drawn
/// from the prior w ~ N(0, c·K) with c = s²/(L·β) at the true β and s², the noise is
/// e ~ N(0, s²) through a coloured noise path, and the band uses the *estimated* ŝ²
/// (profiled marginal likelihood), not the true one.
fn coverage(prior: Prior, solver: SolverChoice, reps: usize, seed: u64) -> (f64, f64) {
    let (len, sigma, harmonics, s) = (200, 0.3, 16, 0.2);
    let c = 0.5; // prior variance scale of the maps
    let beta = s * s / (len as f64 * c);
    let pts = grid(20, -0.95, 0.95);
    let noise = coloured();
    let path = path_a();
    let mut rng = StdRng::seed_from_u64(seed);
    let (mut hits, mut total, mut s2_sum) = (0usize, 0usize, 0.0);
    for _ in 0..reps {
        let z = uniform(&mut rng, len);
        let (block, w, truth) = match prior {
            Prior::Fourier => {
                let block = fourier_block(path.clone(), z.clone(), sigma, harmonics);
                let fk: FourierKernel =
                    fourier_dispersion(sigma, harmonics).kernel_for(&z).unwrap();
                let coef: Vec<f64> = fk
                    .weights()
                    .iter()
                    .map(|l| (c * l).sqrt() * normal(&mut rng))
                    .collect();
                let mut psi = vec![0.0; fk.dim()];
                let mut eval = |x: &[f64]| {
                    fk.eval_into(x, &mut psi);
                    psi.iter().zip(&coef).map(|(a, b)| a * b).sum::<f64>()
                };
                let w: Vec<f64> = (0..len).map(|k| eval(z.sample(k))).collect();
                let truth: Vec<f64> = (0..pts.len()).map(|j| eval(pts.sample(j))).collect();
                (block, w, truth)
            }
            Prior::Gaussian => {
                let block = gaussian_block(path.clone(), z.clone(), sigma);
                let g = GaussianKernel::new(sigma).unwrap();
                let all: Vec<f64> = (0..len)
                    .map(|k| z.get(k, 0))
                    .chain((0..pts.len()).map(|j| pts.get(j, 0)))
                    .collect();
                let n = all.len();
                let k0 = g.eval(&[0.0], &[0.0]);
                let k = DMatrix::from_fn(n, n, |i, j| {
                    g.eval(&[all[i]], &[all[j]]) + if i == j { 1e-10 * k0 } else { 0.0 }
                });
                let l = k.cholesky().expect("jittered Gram is PD").l();
                let xi = DVector::from_fn(n, |_, _| normal(&mut rng));
                let draw = c.sqrt() * l * xi;
                (
                    block,
                    draw.rows(0, len).iter().copied().collect(),
                    draw.rows(len, pts.len()).iter().copied().collect(),
                )
            }
        };
        let mut r = vec![0.0; len];
        path.apply(&w, &mut r);
        let e: Vec<f64> = (0..len).map(|_| s * normal(&mut rng)).collect();
        let mut te = vec![0.0; len];
        noise.apply(&e, &mut te);
        r.iter_mut().zip(&te).for_each(|(a, b)| *a += b);
        let blocks = [block];
        let p = problem(&r, &noise, &blocks, None);
        let id = identify_problem(&p, &settings(beta, solver)).unwrap();
        s2_sum += id.posterior.as_ref().unwrap().noise_variance();
        let std = id.posterior_std(0, &pts).unwrap().unwrap();
        let mean = id.blocks[0].map.eval_many(&pts);
        for j in 0..pts.len() {
            total += 1;
            if (mean[j] - truth[j]).abs() <= 1.96 * std[j] {
                hits += 1;
            }
        }
    }
    (hits as f64 / total as f64, s2_sum / reps as f64 / (s * s))
}

#[test]
fn monte_carlo_coverage_of_the_95_percent_band_on_prior_draws() {
    let t0 = std::time::Instant::now();
    // Both paths: the feature solver on exact Fourier-prior draws, the exact solver on Gaussian
    // draws. (The exact solver on the Fourier prior gives the same band, see the test above, but
    // its Gram assembly through the cosine series costs ~25 ms per record.)
    for (prior, solver, seed) in [
        (Prior::Fourier, SolverChoice::Features, 1),
        (Prior::Gaussian, SolverChoice::Exact, 3),
    ] {
        let t = std::time::Instant::now();
        let (cov, s2_ratio) = coverage(prior, solver, 100, seed);
        println!(
            "{prior:?} prior, {} solver: coverage {:.2} % over 100 records × 20 points (estimated ŝ², mean ŝ²/s² = {s2_ratio:.3}), {:.2} s",
            solver.name(),
            100.0 * cov,
            t.elapsed().as_secs_f64()
        );
        assert!(
            (cov - 0.95).abs() <= 0.03,
            "{prior:?}/{}: coverage {cov}",
            solver.name()
        );
    }
    println!("total {:.2} s", t0.elapsed().as_secs_f64());
}

// --- 4. a fixed map (printed, not asserted) -----------------------------------------------------

#[test]
fn coverage_on_the_fixed_spray_maps_is_reported() {
    let pts = grid(50, -0.95, 0.95);
    let settings = IdentifySettings::builder()
        .beta(0.01)
        .posterior(true)
        .build()
        .unwrap();
    let (mut hits, mut total) = ([0usize; 2], 0usize);
    let mut s2 = Vec::new();
    for seed in 0..5 {
        let exp = paper::spray(
            1000,
            1.0,
            Arc::new(KernelDispersion::gaussian(0.1).unwrap()),
            seed,
        )
        .unwrap();
        let id = identify(&exp.model, &exp.data, &settings).unwrap();
        s2.push(id.posterior.as_ref().unwrap().noise_variance());
        total += pts.len();
        for (b, truth) in [paper::spray_f as fn(f64) -> f64, paper::spray_g]
            .into_iter()
            .enumerate()
        {
            let std = id.posterior_std(b, &pts).unwrap().unwrap();
            let mean = id.blocks[b].map.eval_many(&pts);
            for j in 0..pts.len() {
                if (mean[j] - truth(pts.get(j, 0))).abs() <= 1.96 * std[j] {
                    hits[b] += 1;
                }
            }
        }
    }
    println!(
        "spray example (L = 1000, noise std 1, σ = 0.1, β = 0.01, 5 seeds × 50 points): coverage of the 95 % band \
         f {:.1} %, g {:.1} %; ŝ² = {:?} (true 1)",
        100.0 * hits[0] as f64 / total as f64,
        100.0 * hits[1] as f64 / total as f64,
        s2.iter()
            .map(|v| (v * 1000.0).round() / 1000.0)
            .collect::<Vec<_>>()
    );
}

// --- 5. no posterior, bad input -----------------------------------------------------------------

#[test]
fn no_posterior_for_total_variation_or_when_off_and_typed_errors() {
    let exp = paper::spray(120, 0.1, Arc::new(TotalVariation::new()), 3).unwrap();
    let pts = grid(5, -0.5, 0.5);
    for solver in [SolverChoice::Admm, SolverChoice::Clarabel] {
        let s = IdentifySettings::builder()
            .beta(0.01)
            .solver(solver)
            .posterior(true)
            .admm(
                AdmmSettings::builder()
                    .max_iterations(200_000)
                    .build()
                    .unwrap(),
            )
            .build()
            .unwrap();
        let id = identify(&exp.model, &exp.data, &s).unwrap();
        assert!(id.posterior.is_none());
        assert_eq!(id.posterior_std(0, &pts).unwrap(), None, "{solver:?}");
        // Bad input is an error whether or not there is a posterior.
        assert!(matches!(
            id.posterior_std(2, &pts),
            Err(Error::InvalidParameter { .. })
        ));
    }

    let exp = paper::spray(
        150,
        0.3,
        Arc::new(KernelDispersion::gaussian(0.2).unwrap()),
        3,
    )
    .unwrap();
    let off = identify(&exp.model, &exp.data, &IdentifySettings::default()).unwrap();
    assert!(off.posterior.is_none());
    assert_eq!(off.posterior_std(1, &pts).unwrap(), None);
    let on = identify(
        &exp.model,
        &exp.data,
        &IdentifySettings::builder().posterior(true).build().unwrap(),
    )
    .unwrap();
    assert_eq!(
        on.posterior_std(0, &Signal::zeros(0, 1)).unwrap(),
        Some(vec![])
    );
    for id in [&off, &on] {
        assert!(matches!(
            id.posterior_std(2, &pts),
            Err(Error::InvalidParameter { .. })
        ));
        assert!(matches!(
            id.posterior_std(0, &Signal::zeros(3, 2)),
            Err(Error::DimensionMismatch { .. })
        ));
        let nan = Signal::from_fn(3, 1, |k, _| if k == 1 { f64::NAN } else { 0.1 });
        assert!(matches!(
            id.posterior_std(1, &nan),
            Err(Error::NonFiniteData { sample: 1, .. })
        ));
        let inf = Signal::from_fn(2, 1, |_, _| f64::INFINITY);
        assert!(id.posterior_std(0, &inf).is_err());
    }
    // Far from the data the band widens to the prior's: c·k(z, z).
    let post = on.posterior.as_ref().unwrap();
    let far = on.posterior_std(0, &grid(2, 5.0, 6.0)).unwrap().unwrap();
    let near = on.posterior_std(0, &grid(2, 0.0, 0.1)).unwrap().unwrap();
    assert!(far[0] > 2.0 * near[0], "far {far:?} near {near:?}");
    let beta = on.cost.beta;
    let prior = (post.noise_variance() / (150.0 * beta)
        * GaussianKernel::new(0.2).unwrap().eval(&[5.0], &[5.0]))
    .sqrt();
    assert!(
        (far[0] - prior).abs() < 1e-6 * prior,
        "{} vs {prior}",
        far[0]
    );
}

#[test]
fn the_exact_solver_memory_estimate_includes_the_posterior() {
    let exp = paper::spray(
        300,
        1.0,
        Arc::new(KernelDispersion::gaussian(0.1).unwrap()),
        1,
    )
    .unwrap();
    let on = IdentifySettings::builder()
        .posterior(true)
        .solver(SolverChoice::Exact)
        .build()
        .unwrap();
    let off = IdentifySettings::builder()
        .solver(SolverChoice::Exact)
        .build()
        .unwrap();
    let extra = structid_core::solver::exact::posterior_memory_bytes(&on, 300, 1, 0);
    assert!(extra > 0);
    assert_eq!(
        structid_core::solver::exact::posterior_memory_bytes(&off, 300, 1, 0),
        0
    );
    let a = identify(&exp.model, &exp.data, &on).unwrap();
    let b = identify(&exp.model, &exp.data, &off).unwrap();
    assert_eq!(
        a.diagnostics.peak_memory_bytes,
        b.diagnostics.peak_memory_bytes + extra
    );
    // The kept factor is M's n×n buffer.
    assert!(a.posterior.as_ref().unwrap().memory_bytes() >= 8 * 300 * 300);
    // Initial state estimated: x₀ gets a flat prior, two fewer degrees of freedom.
    let x0 = IdentifySettings::builder()
        .posterior(true)
        .initial_state(InitialState::Estimate)
        .build()
        .unwrap();
    let c = identify(&exp.model, &exp.data, &x0).unwrap();
    assert_eq!(c.posterior.as_ref().unwrap().degrees_of_freedom(), 300 - 2);
}

//! Properties of the exact solver, checked against independent dense computations.
//!
//! The reference is the paper's printed formulation: Q = K⁻¹ (formed explicitly here, on small
//! problems with a well-conditioned Gram matrix), the feasible set parametrised by the null
//! space of [T_ye T_yw], and the resulting least-squares problem solved densely.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;
use structid_core::scenarios;
use structid_core::*;
use structid_lti::testing::random_stable_system;
use structid_lti::{LinearSystem, Signal, StateSpace};

/// A random problem with measured z (paper Definition 1, case 1).
struct Case {
    model: Model,
    data: Data,
    kernels: Vec<GaussianKernel>,
    len: usize,
}

/// Points spread over [−1, 1] with spacing h in a scrambled order; with σ = h the Gram matrix
/// exp(−(i−j)²/2)-like is well conditioned (≈ 70), so forming K⁻¹ in the reference is safe.
fn spread_points(len: usize, seed: u64, shift: usize) -> Vec<f64> {
    let h = 2.0 / len as f64;
    let step = [7usize, 11, 13, 17, 19][(seed as usize + shift) % 5];
    let step = if len.is_multiple_of(step) { 1 } else { step };
    (0..len)
        .map(|k| -1.0 + h * ((k * step + shift) % len) as f64)
        .collect()
}

fn make_case(seed: u64, n: usize, ne: usize, nw: usize, ny: usize, len: usize) -> Case {
    // At least as many noise channels as outputs keeps T_ye·T_yeᵀ, hence M, well conditioned.
    let ne = ne.max(ny);
    let nu = 1;
    let sys = random_stable_system(seed, n, nu + ne + nw, ny, 0.9);
    let mut lft_sys_c = DMatrix::zeros(ny + nw, n);
    lft_sys_c.rows_mut(0, ny).copy_from(sys.c());
    let mut d = DMatrix::zeros(ny + nw, nu + ne + nw);
    d.rows_mut(0, ny).copy_from(sys.d());
    // Make the noise path comfortably full rank.
    for i in 0..ny.min(ne) {
        d[(i, nu + i)] += 1.0;
    }
    let full = StateSpace::new(sys.a().clone(), sys.b().clone(), lft_sys_c, d).unwrap();
    let lft = Lft::from_state_space(&full, nu, ne, ny).unwrap();
    let h = 2.0 / len as f64;
    let kernels: Vec<GaussianKernel> = (0..nw).map(|_| GaussianKernel::new(h).unwrap()).collect();
    let blocks = (0..nw)
        .map(|c| {
            NonlinearBlock::new(
                format!("n{c}"),
                vec![c],
                c,
                Arc::new(KernelDispersion::new(kernels[c])) as Arc<dyn Dispersion>,
            )
        })
        .collect();
    let model = Model::new(lft, blocks).unwrap();
    let mut rng = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut next = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((rng >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    let u = Signal::from_fn(len, nu, |_, _| next());
    let y = Signal::from_fn(len, ny, |_, _| next());
    let zcols: Vec<Vec<f64>> = (0..nw).map(|c| spread_points(len, seed, c)).collect();
    let z = Signal::from_channels(&zcols).unwrap();
    let data = Data::new(u, y).unwrap().with_z(z).unwrap();
    Case {
        model,
        data,
        kernels,
        len,
    }
}

struct Dense {
    t_ye: DMatrix<f64>,
    t_yw: DMatrix<f64>,
    k: DMatrix<f64>,
    r: DVector<f64>,
}

/// Dense operators with the solver's ordering: time-major, w channel c ↔ block c.
fn dense(case: &Case) -> Dense {
    let lft = case.model.lft();
    let len = case.len;
    let t_ye = lft.t_ye().toeplitz_dense(len);
    let t_yw = lft.t_yw().toeplitz_dense(len);
    let nw = lft.dims().w;
    let z = case.data.z().unwrap();
    let mut k = DMatrix::zeros(len * nw, len * nw);
    for c in 0..nw {
        for i in 0..len {
            for j in 0..len {
                k[(i * nw + c, j * nw + c)] = case.kernels[c].eval(&[z.get(i, c)], &[z.get(j, c)]);
            }
        }
    }
    let r = lft.residual(case.data.u(), case.data.y()).unwrap();
    Dense {
        t_ye,
        t_yw,
        k,
        r: DVector::from_column_slice(r.as_slice()),
    }
}

/// The paper's formulation: minimise (1/L)|e|² + β wᵀQw over {T_ye e + T_yw w = r}, Q = K⁻¹.
/// Returns (e, w, null-space basis, Hessian-half H).
fn paper_reference(
    d: &Dense,
    beta: f64,
    len: usize,
) -> (DVector<f64>, DVector<f64>, DMatrix<f64>, DMatrix<f64>) {
    paper_reference_weighted(d, beta, len, d.t_ye.ncols())
}

fn settings(beta: f64) -> IdentifySettings {
    IdentifySettings::builder().beta(beta).build().unwrap()
}

fn rel(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    (a - b).norm() / a.norm().max(b.norm()).max(1e-300)
}

fn stack_w(id: &Identification) -> DVector<f64> {
    DVector::from_column_slice(id.w_hat.as_slice())
}

fn case_strategy() -> impl Strategy<Value = (u64, usize, usize, usize, usize, usize, f64)> {
    (
        any::<u64>(),
        0usize..4,
        1usize..3,
        1usize..3,
        1usize..3,
        6usize..22,
        -3.0f64..1.0,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]

    /// Property 1: the estimate is feasible, T_ye·ê + T_yw·ŵ = r.
    #[test]
    fn prop_estimate_is_feasible((seed, n, ne, nw, ny, len, lb) in case_strategy()) {
        let case = make_case(seed, n, ne, nw, ny, len);
        let id = identify(&case.model, &case.data, &settings(10f64.powf(lb))).unwrap();
        let d = dense(&case);
        let lhs = &d.t_ye * DVector::from_column_slice(id.e_hat.as_slice()) + &d.t_yw * stack_w(&id);
        prop_assert!(rel(&lhs, &d.r) < 1e-9, "relative feasibility error {}", rel(&lhs, &d.r));
    }

    /// Property 2: the estimate equals the paper's Q = K⁻¹ null-space least-squares solution,
    /// and the projected gradient of J vanishes there.
    #[test]
    fn prop_matches_paper_formulation_and_is_stationary((seed, n, ne, nw, ny, len, lb) in case_strategy()) {
        let beta = 10f64.powf(lb);
        let case = make_case(seed, n, ne, nw, ny, len);
        let id = identify(&case.model, &case.data, &settings(beta)).unwrap();
        let d = dense(&case);
        let (e_ref, w_ref, nmat, h) = paper_reference(&d, beta, len);
        let w = stack_w(&id);
        let e = DVector::from_column_slice(id.e_hat.as_slice());
        prop_assert!(rel(&w_ref, &w) < 1e-7, "ŵ differs: {}", rel(&w_ref, &w));
        prop_assert!(rel(&e_ref, &e) < 1e-7, "ê differs: {}", rel(&e_ref, &e));
        let mut x = DVector::zeros(e.len() + w.len());
        x.rows_mut(0, e.len()).copy_from(&e);
        x.rows_mut(e.len(), w.len()).copy_from(&w);
        let grad = &h * &x * 2.0;
        let projected = nmat.transpose() * &grad;
        prop_assert!(projected.norm() <= 1e-7 * grad.norm().max(1e-12),
            "projected gradient {} vs gradient {}", projected.norm(), grad.norm());
        // The reported cost terms agree with J evaluated on the reference.
        let q = d.k.clone().try_inverse().unwrap();
        let j_ref = e_ref.norm_squared() / len as f64 + beta * (w_ref.transpose() * q * &w_ref)[(0, 0)];
        prop_assert!((id.cost.total - j_ref).abs() <= 1e-7 * j_ref.abs().max(1e-12));
    }

    /// Property 3: each interpolant reproduces ŵ at the data points.
    #[test]
    fn prop_interpolant_reproduces_estimate_at_data((seed, n, ne, nw, ny, len, lb) in case_strategy()) {
        let case = make_case(seed, n, ne, nw, ny, len);
        let id = identify(&case.model, &case.data, &settings(10f64.powf(lb))).unwrap();
        for b in &id.blocks {
            let scale = b.w_hat.iter().fold(1e-12f64, |a, v| a.max(v.abs()));
            for k in 0..len {
                let v = b.predict(b.z.sample(k));
                prop_assert!((v - b.w_hat[k]).abs() <= 1e-9 * scale, "block {} sample {k}: {v} vs {}", b.name, b.w_hat[k]);
            }
        }
    }

    /// Property 4: ŵ is linear in the data, ŵ(r₁ + r₂) = ŵ(r₁) + ŵ(r₂).
    #[test]
    fn prop_estimate_is_linear_in_data((seed, n, ne, nw, ny, len, lb) in case_strategy()) {
        let s = settings(10f64.powf(lb));
        let c1 = make_case(seed, n, ne, nw, ny, len);
        let c2 = make_case(seed ^ 0xabcdef, n, ne, nw, ny, len);
        let z = c1.data.z().unwrap().clone();
        let with = |u: &Signal, y: &Signal| Data::new(u.clone(), y.clone()).unwrap().with_z(z.clone()).unwrap();
        let sum = |a: &Signal, b: &Signal| {
            let v: Vec<f64> = a.as_slice().iter().zip(b.as_slice()).map(|(x, y)| x + y).collect();
            Signal::new(a.channels(), v).unwrap()
        };
        let d1 = with(c1.data.u(), c1.data.y());
        let d2 = with(c2.data.u(), c2.data.y());
        let d12 = with(&sum(c1.data.u(), c2.data.u()), &sum(c1.data.y(), c2.data.y()));
        let w1 = stack_w(&identify(&c1.model, &d1, &s).unwrap());
        let w2 = stack_w(&identify(&c1.model, &d2, &s).unwrap());
        let w12 = stack_w(&identify(&c1.model, &d12, &s).unwrap());
        prop_assert!(rel(&w12, &(&w1 + &w2)) < 1e-9);
    }
}

/// Property 5: ŵ → 0 as β → ∞ and ê → 0 as β → 0.
#[test]
fn limits_in_beta() {
    for seed in 0..6 {
        let case = make_case(seed, 2, 1, 1, 1, 16);
        let r = dense(&case).r.norm();
        let big = identify(&case.model, &case.data, &settings(1e9)).unwrap();
        assert!(
            stack_w(&big).norm() < 1e-6 * r,
            "ŵ at β = 1e9: {}",
            stack_w(&big).norm()
        );
        let small = identify(&case.model, &case.data, &settings(1e-12)).unwrap();
        let e = DVector::from_column_slice(small.e_hat.as_slice());
        assert!(e.norm() < 1e-6 * r, "ê at β = 1e-12: {}", e.norm());
        // Monotone in between: the noise share grows with β.
        let mut last = 0.0;
        for b in [1e-4, 1e-2, 1.0, 1e2] {
            let id = identify(&case.model, &case.data, &settings(b)).unwrap();
            assert!(id.cost.noise >= last - 1e-12);
            last = id.cost.noise;
        }
    }
}

/// Samples that depend on neither e nor w are left out, checked for consistency and reported.
#[test]
fn strictly_proper_paths_drop_unreachable_samples() {
    use nalgebra::dmatrix;
    // No noise, w reaches y only through a delay: y_0 = 0 whatever w is.
    let lft = Lft::new(LftMatrices {
        a: dmatrix![0.5],
        bu: dmatrix![0.0],
        be: dmatrix![0.0],
        bw: dmatrix![1.0],
        cy: dmatrix![1.0],
        dyu: dmatrix![1.0],
        dye: dmatrix![0.0],
        dyw: dmatrix![0.0],
        cz: dmatrix![0.0],
        dzu: dmatrix![1.0],
        dze: dmatrix![0.0],
        dzw: dmatrix![0.0],
    })
    .unwrap();
    let kernel = GaussianKernel::new(0.1).unwrap();
    let model = Model::new(
        lft,
        vec![NonlinearBlock::new(
            "f",
            vec![0],
            0,
            Arc::new(KernelDispersion::new(kernel)),
        )],
    )
    .unwrap();
    let len = 20;
    let u = Signal::from_fn(len, 1, |k, _| spread_points(len, 3, 0)[k]);
    let f = |z: &[f64]| z[0].tanh();
    let sim = model.simulate(&[&f], &u, None, None).unwrap();
    let data = Data::new(u, sim.y).unwrap();
    let id = identify(&model, &data, &settings(1e-3)).unwrap();
    assert_eq!(id.diagnostics.dropped_samples, vec![0]);
    assert!(id.diagnostics.dropped_max_abs_residual < 1e-14);
    assert_eq!(id.diagnostics.system_size, len - 1);
    assert!(id.diagnostics.feasibility_residual < 1e-9);
    assert!(
        id.diagnostics
            .warnings
            .iter()
            .any(|w| w.contains("left out"))
    );
    assert!(
        !id.diagnostics
            .warnings
            .iter()
            .any(|w| w.contains("NOT consistent"))
    );
    // Inconsistent data at the dropped sample is reported, not hidden.
    let mut y = data.y().clone();
    y.sample_mut(0)[0] += 1.0;
    let bad = Data::new(data.u().clone(), y).unwrap();
    let id = identify(&model, &bad, &settings(1e-3)).unwrap();
    assert!((id.diagnostics.dropped_max_abs_residual - 1.0).abs() < 1e-12);
    assert!(
        id.diagnostics
            .warnings
            .iter()
            .any(|w| w.contains("NOT consistent"))
    );
}

/// Property 7: z computed through Ψ equals the simulated z, and the three measurability cases
/// are told apart.
#[test]
fn measurability_psi_reproduces_simulated_z() {
    use nalgebra::dmatrix;
    for seed in 0..20u64 {
        let n = 1 + (seed as usize % 4);
        let (nu, ne, nw, ny, nz) = (2, 1 + (seed as usize % 2), 1, 2, 2);
        let s = random_stable_system(seed, n, nu + ne + nw, ny, 0.9);
        let b = s.b();
        let mut dyw = s.d().columns(nu + ne, nw).into_owned();
        dyw.fill(0.0); // D_zw = Ψ·D_yw must vanish for simulation
        let psi = random_stable_system(seed + 100, 0, ny, nz, 0.5).d().clone();
        let dzu = random_stable_system(seed + 200, 0, nu, nz, 0.5).d().clone();
        let m = LftMatrices {
            a: s.a().clone(),
            bu: b.columns(0, nu).into_owned(),
            be: b.columns(nu, ne).into_owned(),
            bw: b.columns(nu + ne, nw).into_owned(),
            cy: s.c().clone(),
            dyu: s.d().columns(0, nu).into_owned(),
            dye: s.d().columns(nu, ne).into_owned(),
            dyw: dyw.clone(),
            cz: &psi * s.c(),
            dzu,
            dze: &psi * s.d().columns(nu, ne),
            dzw: &psi * &dyw,
        };
        let lft = Lft::new(m).unwrap();
        let source = lft.measurability().unwrap();
        assert!(
            matches!(source, ZSource::OutputInjection { .. }),
            "seed {seed}: {source:?}"
        );
        let len = 60;
        let u = Signal::from_fn(len, nu, |k, c| ((k * (c + 3)) as f64 * 0.37).sin());
        let e = Signal::from_fn(len, ne, |k, c| ((k * (c + 5)) as f64 * 0.91).cos() * 0.3);
        let map = |z: &[f64]| (z[0] - 0.5 * z[1]).tanh();
        let sim = lft
            .simulate(
                &[MapBinding {
                    inputs: &[0, 1],
                    output: 0,
                    map: &map,
                }],
                &u,
                Some(&e),
                None,
            )
            .unwrap();
        let (z, _) = lft.compute_z(&u, &sim.y).unwrap();
        let err = z
            .as_slice()
            .iter()
            .zip(sim.z.as_slice())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let scale = sim.z.as_slice().iter().fold(1.0f64, |a, b| a.max(b.abs()));
        assert!(err < 1e-10 * scale, "seed {seed}: max |z − z_sim| = {err}");
    }
    // Case 2: C_z ≠ 0 but orthogonal to everything (e, w) can reach → z = L_zu·u.
    let lft = Lft::new(LftMatrices {
        a: dmatrix![0.5, 0.0; 0.0, 0.3],
        bu: dmatrix![1.0; 1.0],
        be: dmatrix![1.0; 0.0],
        bw: dmatrix![1.0; 0.0],
        cy: dmatrix![1.0, 0.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0],
        cz: dmatrix![0.0, 1.0],
        dzu: dmatrix![0.0],
        dze: dmatrix![0.0],
        dzw: dmatrix![0.0],
    })
    .unwrap();
    assert_eq!(lft.measurability().unwrap(), ZSource::InputOnly);
    // Not measurable: z sees the second state, which w drives but y does not.
    let mut m = lft.matrices().clone();
    m.bw = dmatrix![0.0; 1.0];
    let lft = Lft::new(m).unwrap();
    let err = lft.measurability().unwrap_err();
    assert!(matches!(err, Error::NotMeasurable { .. }));
    assert!(err.to_string().contains("provide z as measured data"));
}

/// Property 8 (library part): bad input gives the right error variant, never a panic.
#[test]
fn bad_input_gives_typed_errors() {
    use nalgebra::dmatrix;
    let case = make_case(1, 2, 1, 1, 1, 12);
    // NaN in data.
    let mut y = case.data.y().clone();
    y.sample_mut(3)[0] = f64::NAN;
    let e = Data::new(case.data.u().clone(), y).unwrap_err();
    assert!(matches!(e, Error::NonFiniteData { sample: 3, .. }), "{e}");
    let mut u = case.data.u().clone();
    u.sample_mut(2)[0] = f64::INFINITY;
    assert!(matches!(
        Data::new(u, case.data.y().clone()),
        Err(Error::NonFiniteData { .. })
    ));
    // Mismatched lengths and channel counts.
    let short = case.data.y().slice(0..5);
    assert!(matches!(
        Data::new(case.data.u().clone(), short),
        Err(Error::DimensionMismatch { .. })
    ));
    let two = Signal::zeros(12, 2);
    let d = Data::new(two, case.data.y().clone()).unwrap();
    assert!(matches!(
        identify(&case.model, &d, &settings(1.0)),
        Err(Error::DimensionMismatch { .. })
    ));
    // σ ≤ 0 and β ≤ 0.
    assert!(matches!(
        KernelDispersion::gaussian(0.0),
        Err(Error::InvalidParameter { .. })
    ));
    assert!(matches!(
        KernelDispersion::gaussian(-1.0),
        Err(Error::InvalidParameter { .. })
    ));
    for b in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            IdentifySettings::builder().beta(b).build(),
            Err(Error::InvalidParameter { .. })
        ));
    }
    // Algebraic loop in simulation.
    let mut m = case.model.lft().matrices().clone();
    m.dzw[(0, 0)] = 0.5;
    let lft = Lft::new(m).unwrap();
    let f = |z: &[f64]| z[0];
    let e = lft
        .simulate(
            &[MapBinding {
                inputs: &[0],
                output: 0,
                map: &f,
            }],
            case.data.u(),
            None,
            None,
        )
        .unwrap_err();
    assert!(
        matches!(e, Error::AlgebraicLoop { row: 0, col: 0, .. }),
        "{e}"
    );
    // Structural errors.
    let bad_lft = Lft::new(LftMatrices {
        a: dmatrix![0.5],
        bu: dmatrix![1.0, 2.0],
        be: dmatrix![0.0],
        bw: dmatrix![1.0],
        cy: dmatrix![1.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0],
        cz: dmatrix![0.0],
        dzu: dmatrix![1.0],
        dze: dmatrix![0.0],
        dzw: dmatrix![0.0],
    });
    assert!(matches!(bad_lft, Err(Error::DimensionMismatch { .. })));
    let disp: Arc<dyn Dispersion> = Arc::new(KernelDispersion::gaussian(0.5).unwrap());
    let lft = case.model.lft().clone();
    assert!(matches!(
        Model::new(
            lft.clone(),
            vec![NonlinearBlock::new("f", vec![3], 0, disp.clone())]
        ),
        Err(Error::MissingZ { index: 3, .. })
    ));
    assert!(matches!(
        Model::new(lft, vec![]),
        Err(Error::InvalidStructure(_))
    ));
    // Too large for memory: refused up front with a size estimate and advice.
    let tiny = IdentifySettings::builder()
        .beta(1.0)
        .memory_limit_bytes(1000)
        .build()
        .unwrap();
    let e = identify(&case.model, &case.data, &tiny).unwrap_err();
    assert!(matches!(e, Error::TooLarge { .. }), "{e}");
    assert!(e.to_string().contains("window of at most"));
}

/// A custom operator (an FIR filter implemented by hand) plugs into `identify_problem` through
/// the `LinearSystem` trait and gives the same estimate as the equivalent state-space model.
#[test]
fn user_linear_system_plugs_into_identify() {
    struct Fir(Vec<f64>);
    impl LinearSystem for Fir {
        fn inputs(&self) -> usize {
            1
        }
        fn outputs(&self) -> usize {
            1
        }
        fn order(&self) -> usize {
            self.0.len() - 1
        }
        fn apply(&self, u: &[f64], y: &mut [f64]) {
            for k in 0..y.len() {
                y[k] = (0..self.0.len())
                    .filter(|&j| j <= k)
                    .map(|j| self.0[j] * u[k - j])
                    .sum();
            }
        }
        fn apply_adjoint(&self, y: &[f64], u: &mut [f64]) {
            for k in 0..u.len() {
                u[k] = (0..self.0.len())
                    .filter(|&j| k + j < y.len())
                    .map(|j| self.0[j] * y[k + j])
                    .sum();
            }
        }
    }
    let taps = vec![1.0, 0.5, -0.25];
    let len = 30;
    let z = Signal::from_channels(&[spread_points(len, 5, 0)]).unwrap();
    let r = Signal::from_fn(len, 1, |k, _| (k as f64 * 0.3).sin());
    let disp: Arc<dyn Dispersion> = Arc::new(KernelDispersion::gaussian(2.0 / len as f64).unwrap());
    let fir_problem = Problem::new(
        r.clone(),
        Arc::new(StateSpace::static_gain(DMatrix::from_element(1, 1, 1.0)).unwrap()),
        vec![ProblemBlock {
            name: "f".into(),
            output: 0,
            path: Arc::new(Fir(taps.clone())),
            z: z.clone(),
            dispersion: disp.clone(),
        }],
    )
    .unwrap();
    let ss = structid_lti::TransferFunction::siso(taps, vec![1.0])
        .unwrap()
        .to_state_space();
    let ss_problem = Problem::new(
        r,
        Arc::new(StateSpace::static_gain(DMatrix::from_element(1, 1, 1.0)).unwrap()),
        vec![ProblemBlock {
            name: "f".into(),
            output: 0,
            path: Arc::new(ss),
            z,
            dispersion: disp,
        }],
    )
    .unwrap();
    let a = identify_problem(&fir_problem, &settings(0.05)).unwrap();
    let b = identify_problem(&ss_problem, &settings(0.05)).unwrap();
    let (wa, wb) = (stack_w(&a), stack_w(&b));
    assert!(rel(&wa, &wb) < 1e-10, "{}", rel(&wa, &wb));
}

/// A singular M (no noise path and repeated z, so K has equal columns) is regularised and
/// reported; the estimate stays finite and still fits the data.
#[test]
fn singular_system_matrix_is_regularised_and_reported() {
    use nalgebra::dmatrix;
    let lft = Lft::new(LftMatrices {
        a: dmatrix![0.0],
        bu: dmatrix![0.0],
        be: dmatrix![0.0],
        bw: dmatrix![0.0],
        cy: dmatrix![0.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![0.0],
        dyw: dmatrix![1.0],
        cz: dmatrix![0.0],
        dzu: dmatrix![1.0],
        dze: dmatrix![0.0],
        dzw: dmatrix![0.0],
    })
    .unwrap();
    let model = Model::new(
        lft,
        vec![NonlinearBlock::new(
            "f",
            vec![0],
            0,
            Arc::new(KernelDispersion::gaussian(0.3).unwrap()),
        )],
    )
    .unwrap();
    let z: Vec<f64> = (0..40).map(|k| ((k % 10) as f64) / 10.0).collect();
    let u = Signal::from_channels(std::slice::from_ref(&z)).unwrap();
    let y = Signal::from_channels(&[z.iter().map(|v| v.sin()).collect()]).unwrap();
    let id = identify(&model, &Data::new(u, y).unwrap(), &settings(0.01)).unwrap();
    assert!(id.w_hat.as_slice().iter().all(|v| v.is_finite()));
    assert!(id.diagnostics.diagonal_jitter > 0.0);
    assert!(
        id.diagnostics.feasibility_residual < 1e-6,
        "{:?}",
        id.diagnostics
    );
    assert!(
        id.diagnostics
            .warnings
            .iter()
            .any(|w| w.contains("numerically singular"))
    );
    for (k, zk) in z.iter().enumerate() {
        assert!(
            (id.w_hat.get(k, 0) - zk.sin()).abs() < 1e-4,
            "sample {k}: {} vs {} ({:?})",
            id.w_hat.get(k, 0),
            zk.sin(),
            id.diagnostics
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, .. ProptestConfig::default() })]

    /// With an unknown initial state, the estimate equals the dense joint minimiser over
    /// (e, w, x₀) with x₀ unpenalised, and it is feasible: T_ye·ê + T_yw·ŵ + O·x̂₀ = r.
    #[test]
    fn prop_initial_state_estimate_matches_dense_joint_minimiser((seed, n, ne, nw, ny, len, lb) in case_strategy()) {
        prop_assume!(n > 0);
        let beta = 10f64.powf(lb);
        let case = make_case(seed, n, ne, nw, ny, len.max(12));
        let len = case.len;
        let s = IdentifySettings::builder().beta(beta).initial_state(InitialState::Estimate).build().unwrap();
        let id = identify(&case.model, &case.data, &s).unwrap();
        let x0 = DVector::from_vec(id.initial_state.clone().unwrap());
        let d = dense(&case);
        let lft = case.model.lft();
        let m = lft.matrices();
        // Dense O: rows k·n_y + i = (C_y A^k)_i.
        let mut o = DMatrix::zeros(len * ny, n);
        let mut cak = m.cy.clone();
        for k in 0..len {
            o.rows_mut(k * ny, ny).copy_from(&cak);
            cak = &cak * &m.a;
        }
        // Reference: the null-space minimiser with x₀ appended as unpenalised variables.
        let mut d2 = Dense { t_ye: DMatrix::zeros(0, 0), t_yw: DMatrix::zeros(0, 0), k: d.k.clone(), r: d.r.clone() };
        let ne_tot = d.t_ye.ncols();
        let mut t_ye_x = DMatrix::zeros(d.r.len(), ne_tot + n);
        t_ye_x.columns_mut(0, ne_tot).copy_from(&d.t_ye);
        t_ye_x.columns_mut(ne_tot, n).copy_from(&o);
        d2.t_ye = t_ye_x;
        d2.t_yw = d.t_yw.clone();
        let (ex_ref, w_ref, _, _) = paper_reference_weighted(&d2, beta, len, ne_tot);
        let x0_ref = ex_ref.rows(ne_tot, n).into_owned();
        let w = stack_w(&id);
        prop_assert!(rel(&w_ref, &w) < 1e-6, "ŵ differs: {}", rel(&w_ref, &w));
        // x₀ through what it does to y (O·x₀): a direction of x₀ that O barely maps to y is
        // as ill-determined for the dense reference as for the solver, and both answers are
        // minimisers when their outputs agree. The reference forms K⁻¹ and the particular
        // solution explicitly and is itself good to about 1e-6 relative (a short record with
        // two outputs and a small β was seen to differ by 1.6e-6 while ŵ agreed to 6e-7), so
        // the bound is 1e-5: a wrong x₀ differs at the scale of O·x₀ itself.
        let (ox_ref, ox) = (&o * &x0_ref, &o * &x0);
        prop_assert!((&ox_ref - &ox).norm() <= 1e-5 * ox_ref.norm().max(1e-3), "O·x₀ {ox_ref} vs {ox}");
        let e = DVector::from_column_slice(id.e_hat.as_slice());
        let lhs = &d.t_ye * &e + &d.t_yw * &w + &o * &x0;
        prop_assert!(rel(&lhs, &d.r) < 1e-9);
    }
}

/// The dense null-space minimiser: the first `ne` columns of `t_ye` are noise (weight 1/L), the
/// remaining ones unpenalised (weight 0), and w is weighted by β·K⁻¹ (formed explicitly; the
/// cases keep K well conditioned). The particular solution is Aᵀ(AAᵀ)⁻¹r: nalgebra's
/// `SVD::solve` lost about 1e-6 of feasibility on well-conditioned cases here. A small rank
/// tolerance keeps genuinely small singular values of A.
fn paper_reference_weighted(
    d: &Dense,
    beta: f64,
    len: usize,
    ne: usize,
) -> (DVector<f64>, DVector<f64>, DMatrix<f64>, DMatrix<f64>) {
    let (nv, nw) = (d.t_ye.ncols(), d.t_yw.ncols());
    let mut a = DMatrix::zeros(d.r.len(), nv + nw);
    a.columns_mut(0, nv).copy_from(&d.t_ye);
    a.columns_mut(nv, nw).copy_from(&d.t_yw);
    let q = d.k.clone().try_inverse().expect("well-conditioned K");
    let mut h = DMatrix::zeros(nv + nw, nv + nw);
    for i in 0..ne {
        h[(i, i)] = 1.0 / len as f64;
    }
    h.view_mut((nv, nv), (nw, nw)).copy_from(&(q * beta));
    let aat = &a * a.transpose();
    let x_p = a.transpose() * aat.cholesky().expect("full row rank").solve(&d.r);
    let svd = a.clone().svd(true, true);
    let tol = 1e-14 * svd.singular_values.max();
    let rank = svd.singular_values.iter().filter(|s| **s > tol).count();
    let v_t = svd.v_t.unwrap();
    let dim = nv + nw;
    let mut basis: Vec<DVector<f64>> = v_t
        .transpose()
        .column_iter()
        .take(rank)
        .map(|c| c.into_owned())
        .collect();
    for i in 0..dim {
        let mut v = DVector::zeros(dim);
        v[i] = 1.0;
        for _ in 0..2 {
            for b in &basis {
                let p = b.dot(&v);
                v -= b * p;
            }
        }
        if v.norm() > 1e-6 {
            basis.push(v.normalize());
        }
        if basis.len() == dim {
            break;
        }
    }
    let nmat = DMatrix::from_columns(&basis[rank..]);
    let v = (nmat.transpose() * &h * &nmat)
        .cholesky()
        .expect("PD reduced Hessian")
        .solve(&(-(nmat.transpose() * &h * &x_p)));
    let x = x_p + &nmat * v;
    (
        x.rows(0, nv).into_owned(),
        x.rows(nv, nw).into_owned(),
        nmat,
        h,
    )
}

/// On noise-free data from a system that does not start at rest, the initial-state option
/// recovers x₀ and gives a better map than assuming rest.
#[test]
fn initial_state_is_recovered_and_improves_the_map() {
    use structid_core::paper::gaussian_noise;
    let exp = scenarios::hammerstein(
        400,
        3,
        0.0,
        Arc::new(KernelDispersion::gaussian(0.3).unwrap()),
        9,
    )
    .unwrap();
    let model = &exp.model;
    let x0_true = vec![3.0, -2.0, 1.5];
    let u = exp.data.u().clone();
    let tanh = |z: &[f64]| z[0].tanh();
    let e = gaussian_noise(u.len(), 1, 0.0, 1);
    let sim = model
        .simulate(&[&tanh], &u, Some(&e), Some(&x0_true))
        .unwrap();
    let data = Data::new(u, sim.y).unwrap();
    let truth = sim.w.channel(0);
    let est = IdentifySettings::builder()
        .beta(1e-6)
        .initial_state(InitialState::Estimate)
        .build()
        .unwrap();
    let zero = IdentifySettings::builder().beta(1e-6).build().unwrap();
    let a = identify(model, &data, &est).unwrap();
    let b = identify(model, &data, &zero).unwrap();
    let x0 = a.initial_state.clone().unwrap();
    let err_x0: f64 = x0
        .iter()
        .zip(&x0_true)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(err_x0 < 0.05 * 3.9, "x₀ = {x0:?}, true {x0_true:?}");
    let ea = structid_core::validation::metrics::rms_difference(&a.blocks[0].w_hat, &truth);
    let eb = structid_core::validation::metrics::rms_difference(&b.blocks[0].w_hat, &truth);
    assert!(
        ea < 0.5 * eb,
        "map error with x₀ estimated {ea}, assuming rest {eb}"
    );
    assert!(b.initial_state.is_none());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, .. ProptestConfig::default() })]

    /// The feature-space solver equals the exact dense solver for the same finite (Fourier)
    /// kernel: several blocks with one and two inputs, MIMO static or coloured noise, with and
    /// without an estimated initial state.
    #[test]
    fn prop_feature_solver_equals_exact_solver(seed in any::<u64>(), n in 1usize..4, ny in 1usize..3,
                                               len in 30usize..160, lb in -3.0f64..0.0, two_inputs in any::<bool>(),
                                               estimate_x0 in any::<bool>(), coloured in any::<bool>()) {
        use nalgebra::DMatrix;
        let (nu, nw) = (1, 2);
        // Coloured noise with one channel more than outputs: D_ye is not square.
        let ne = if coloured { ny + 1 } else { ny };
        let nz = 3;
        let sys = random_stable_system(seed, n, nu + ne + nw, ny, 0.9);
        let b = sys.b();
        let mut dye = DMatrix::identity(ny, ne);
        dye += sys.d().columns(nu, ne) * 0.3;
        let lft = Lft::new(LftMatrices {
            a: sys.a().clone(),
            bu: b.columns(0, nu).into_owned(),
            // Coloured noise: e reaches y through the dynamics too (Kalman whitening).
            be: if coloured { b.columns(nu, ne) * 0.7 } else { DMatrix::zeros(n, ne) },
            bw: b.columns(nu + ne, nw).into_owned(),
            cy: sys.c().clone(),
            dyu: sys.d().columns(0, nu).into_owned(),
            dye,
            dyw: sys.d().columns(nu + ne, nw).into_owned(),
            cz: DMatrix::zeros(nz, n),
            dzu: DMatrix::zeros(nz, nu),
            dze: DMatrix::zeros(nz, ne),
            dzw: DMatrix::zeros(nz, nw),
        }).unwrap();
        let f1: Arc<dyn Dispersion> = Arc::new(FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.3 }).unwrap());
        let f2: Arc<dyn Dispersion> = Arc::new(
            FourierDispersion::new(FourierWeights::SobolevLike { order: 1.5, scale: 0.5 }).unwrap().with_harmonics(4),
        );
        let second_inputs = if two_inputs { vec![1, 2] } else { vec![1] };
        let model = Model::new(lft.clone(), vec![
            NonlinearBlock::new("a", vec![0], 0, f1),
            NonlinearBlock::new("b", second_inputs, 1, f2),
        ]).unwrap();
        let u = structid_lti::testing::random_signal(seed ^ 1, len, nu);
        let y = structid_lti::testing::random_signal(seed ^ 2, len, ny);
        let z = structid_lti::testing::random_signal(seed ^ 3, len, nz);
        let data = Data::new(u, y).unwrap().with_z(z).unwrap();
        let beta = 10f64.powf(lb);
        let init = if estimate_x0 { InitialState::Estimate } else { InitialState::Zero };
        let exact = identify(&model, &data, &IdentifySettings::builder().beta(beta).initial_state(init)
            .solver(SolverChoice::Exact).build().unwrap()).unwrap();
        let feat = identify(&model, &data, &IdentifySettings::builder().beta(beta).initial_state(init)
            .solver(SolverChoice::Features).build().unwrap());
        // Whitening needs a minimum-phase noise model; the solver refuses others (tested below).
        if let Err(Error::Unsupported(msg)) = &feat {
            prop_assume!(!msg.contains("minimum phase"));
        }
        let feat = feat.unwrap();
        let (we, wf) = (stack_w(&exact), stack_w(&feat));
        prop_assert!(rel(&we, &wf) < 1e-8, "ŵ: {} (cond exact {:.2e}, features {:.2e}, feas {:.1e} {:.1e})", rel(&we, &wf),
            exact.diagnostics.condition_lower_bound, feat.diagnostics.condition_lower_bound,
            exact.diagnostics.feasibility_residual, feat.diagnostics.feasibility_residual);
        let (ee, ef) = (DVector::from_column_slice(exact.e_hat.as_slice()), DVector::from_column_slice(feat.e_hat.as_slice()));
        prop_assert!(rel(&ee, &ef) < 1e-8, "ê: {}", rel(&ee, &ef));
        prop_assert!((exact.cost.total - feat.cost.total).abs() <= 1e-8 * exact.cost.total.abs());
        for (a, b) in exact.cost.dispersions.iter().zip(&feat.cost.dispersions) {
            prop_assert!((a - b).abs() <= 1e-7 * a.abs().max(1e-12), "D: {a} vs {b}");
        }
        if estimate_x0 {
            let (xa, xb) = (DVector::from_vec(exact.initial_state.clone().unwrap()), DVector::from_vec(feat.initial_state.clone().unwrap()));
            prop_assert!(rel(&xa, &xb) < 1e-7, "x₀: {xa} vs {xb}");
        }
        prop_assert!(feat.diagnostics.feasibility_residual < 1e-9);
        // Both interpolants agree off the data as well.
        for (be, bf) in exact.blocks.iter().zip(&feat.blocks) {
            let p = be.z.channels();
            let pt = vec![0.123; p];
            let (a, b) = (be.predict(&pt), bf.predict(&pt));
            prop_assert!((a - b).abs() <= 1e-7 * (1.0 + a.abs()), "{}: {a} vs {b}", be.name);
        }
    }
}

/// Features are refused clearly where they do not apply: kernels without finite features, and
/// non-minimum-phase noise models (whose whitening filter is unstable).
#[test]
fn feature_solver_refuses_what_it_cannot_do() {
    use nalgebra::dmatrix;
    // T_ye = 1 + 2q⁻¹ has its zero at −2: W = T_ye⁻¹ would grow like 2^t.
    let lft = Lft::new(LftMatrices {
        a: dmatrix![0.0],
        bu: dmatrix![0.0],
        be: dmatrix![1.0],
        bw: dmatrix![0.0],
        cy: dmatrix![2.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![1.0],
        cz: dmatrix![0.0],
        dzu: dmatrix![1.0],
        dze: dmatrix![0.0],
        dzw: dmatrix![0.0],
    })
    .unwrap();
    let fourier: Arc<dyn Dispersion> =
        Arc::new(FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.3 }).unwrap());
    let model = Model::new(lft, vec![NonlinearBlock::new("f", vec![0], 0, fourier)]).unwrap();
    let u = structid_lti::testing::random_signal(1, 50, 1);
    let y = structid_lti::testing::random_signal(2, 50, 1);
    let data = Data::new(u, y).unwrap();
    let s = IdentifySettings::builder()
        .beta(0.1)
        .solver(SolverChoice::Features)
        .build()
        .unwrap();
    let e = identify(&model, &data, &s).unwrap_err();
    assert!(e.to_string().contains("minimum phase"), "{e}");
    // The exact solver handles the same model.
    let s = IdentifySettings::builder()
        .beta(0.1)
        .solver(SolverChoice::Exact)
        .build()
        .unwrap();
    assert!(identify(&model, &data, &s).is_ok());

    let case = make_case(3, 2, 1, 1, 1, 20);
    let s = IdentifySettings::builder()
        .beta(0.1)
        .solver(SolverChoice::Features)
        .build()
        .unwrap();
    let e = identify(&case.model, &case.data, &s).unwrap_err();
    assert!(matches!(e, Error::Unsupported(_)), "{e}");
    assert!(e.to_string().contains("feature"), "{e}");
}

/// The low-rank (Nyström) Gaussian agrees with the exact Gaussian within a bound derived from
/// its trace tolerance. With white output noise, ŵ = K·Tᵀ(LβI + T·K·Tᵀ)⁻¹r and E = K − K̃ ⪰ 0:
/// ‖ŵ − ŵ̃‖ ≤ ‖E‖·‖T‖·‖r‖/(Lβ)·(1 + ‖K‖·‖T‖/(Lβ)), with ‖E‖ ≤ tol·trace(K) and 2-norms bounded by
/// Frobenius norms (and ‖K‖ ≤ trace K).
#[test]
fn low_rank_gaussian_is_within_its_tolerance_bound_of_the_exact_gaussian() {
    let (len, sigma, beta) = (300, 0.4, 1e-3);
    let exact_d: Arc<dyn Dispersion> = Arc::new(KernelDispersion::gaussian(sigma).unwrap());
    let exp = scenarios::hammerstein(len, 2, 0.1, exact_d, 5).unwrap();
    let exact = identify(&exp.model, &exp.data, &settings(beta)).unwrap();
    let t = exp.model.lft().t_yw().toeplitz_dense(len);
    let t_norm = t.norm();
    let r = exp
        .model
        .lft()
        .residual(exp.data.u(), exp.data.y())
        .unwrap();
    let r_norm = DVector::from_column_slice(r.as_slice()).norm();
    let trace_k = GaussianKernel::new(sigma).unwrap().normalisation(1) * len as f64;
    let lb = len as f64 * beta;
    let mut last = f64::INFINITY;
    for tol in [1e-3, 1e-6, 1e-10] {
        let lr: Arc<dyn Dispersion> = Arc::new(LowRankGaussian::new(sigma, tol).unwrap());
        let model = exp.model.with_dispersions(|_| lr.clone());
        for solver in [SolverChoice::Features, SolverChoice::Exact] {
            let s = IdentifySettings::builder()
                .beta(beta)
                .solver(solver)
                .build()
                .unwrap();
            let id = identify(&model, &exp.data, &s).unwrap();
            let diff = (stack_w(&exact) - stack_w(&id)).norm();
            let bound = tol * trace_k * t_norm * r_norm / lb * (1.0 + trace_k * t_norm / lb);
            eprintln!("tol {tol:e} {solver:?}: ‖Δŵ‖ = {diff:.3e}, bound {bound:.3e}");
            assert!(
                diff <= bound,
                "tol {tol} ({solver:?}): ‖Δŵ‖ = {diff:.3e} > bound {bound:.3e}"
            );
            if solver == SolverChoice::Features {
                assert!(
                    diff <= last,
                    "the error must shrink with the tolerance: {diff} after {last}"
                );
                last = diff;
            }
        }
    }
    assert!(
        last < 1e-6 * stack_w(&exact).norm(),
        "tol 1e-10 leaves {last}"
    );
}

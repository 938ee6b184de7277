//! Several records in one fit, against a dense reference built here from explicit impulse
//! responses: each record has its own Toeplitz block (block-diagonal operators) and its own
//! initial state (block-diagonal free response), which is not the problem of the concatenated
//! record.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector, dmatrix};
use proptest::prelude::*;
use structid_core::*;
use structid_lti::Signal;

/// y = G(q)·f(u) + G_u(q)·u + e with a second-order G (x⁺ = A·x + B_w·w + B_u·u, y = C·x + e).
fn lft() -> Lft {
    Lft::new(LftMatrices {
        a: dmatrix![1.2, -0.5; 1.0, 0.0],
        bu: dmatrix![0.3; 0.0],
        be: dmatrix![0.0; 0.0],
        bw: dmatrix![1.0; 0.0],
        cy: dmatrix![0.4, 0.2],
        dyu: dmatrix![0.1],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0],
        cz: dmatrix![0.0, 0.0],
        dzu: dmatrix![1.0],
        dze: dmatrix![0.0],
        dzw: dmatrix![0.0],
    })
    .unwrap()
}

fn gaussian() -> Arc<dyn Dispersion> {
    Arc::new(KernelDispersion::gaussian(0.5).unwrap())
}

fn fourier() -> Arc<dyn Dispersion> {
    Arc::new(FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.5 }).unwrap())
}

fn model(dispersion: Arc<dyn Dispersion>) -> Model {
    Model::new(
        lft(),
        vec![NonlinearBlock::new("f", vec![0], 0, dispersion)],
    )
    .unwrap()
}

/// One record simulated from its own initial state, with a little deterministic "noise".
fn record(seed: u64, len: usize) -> Data {
    let m = lft().matrices().clone();
    let u: Vec<f64> = (0..len)
        .map(|k| (1.7 * (k as f64 + 0.3 * seed as f64)).sin() * 1.5)
        .collect();
    let mut x = DVector::from_vec(vec![0.8 * seed as f64 - 1.0, 0.5]);
    let mut y = Vec::with_capacity(len);
    for (k, &uk) in u.iter().enumerate() {
        let w = uk.tanh();
        let e = 0.05 * ((k * 7 + seed as usize * 3) as f64).cos();
        y.push((&m.cy * &x)[0] + m.dyu[(0, 0)] * uk + e);
        x = &m.a * &x + &m.bw * w + &m.bu * uk;
    }
    Data::new(Signal::new(1, u).unwrap(), Signal::new(1, y).unwrap()).unwrap()
}

/// The impulse response h₀ = D, h_j = C·A^(j−1)·B of one path as an L×L lower-triangular
/// Toeplitz matrix.
fn toeplitz(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
    d: f64,
    len: usize,
) -> DMatrix<f64> {
    let mut h = vec![d];
    let mut ak_b = b.clone();
    for _ in 1..len {
        h.push((c * &ak_b)[(0, 0)]);
        ak_b = a * ak_b;
    }
    DMatrix::from_fn(len, len, |i, j| if i >= j { h[i - j] } else { 0.0 })
}

/// The free response C·A^k of the n unit initial states over `len` samples.
fn free_response(a: &DMatrix<f64>, c: &DMatrix<f64>, len: usize) -> DMatrix<f64> {
    let mut o = DMatrix::zeros(len, a.nrows());
    let mut cak = c.clone();
    for k in 0..len {
        o.row_mut(k).copy_from(&cak.row(0));
        cak = &cak * a;
    }
    o
}

/// The dense solution (ŵ, x̂₀) for records of the given lengths, taken as separate records
/// (`separate`) or as one concatenated record: T and O block diagonal or whole, then
/// M = L·β·I + T·K·Tᵀ, x₀ = (OᵀM⁻¹O)⁻¹OᵀM⁻¹r, ŵ = K·Tᵀ·M⁻¹(r − O·x₀).
fn dense(
    data: &Data,
    lens: &[usize],
    dispersion: &dyn Dispersion,
    beta: f64,
    estimate_x0: bool,
    separate: bool,
) -> (Vec<f64>, Vec<f64>) {
    let m = lft().matrices().clone();
    let total: usize = lens.iter().sum();
    let parts: Vec<usize> = if separate { lens.to_vec() } else { vec![total] };
    let n = m.a.nrows();
    let mut tw = DMatrix::zeros(total, total);
    let mut tu = DMatrix::zeros(total, total);
    let mut o = DMatrix::zeros(total, n * parts.len());
    let mut at = 0;
    for (r, &l) in parts.iter().enumerate() {
        tw.view_mut((at, at), (l, l))
            .copy_from(&toeplitz(&m.a, &m.bw, &m.cy, m.dyw[(0, 0)], l));
        tu.view_mut((at, at), (l, l))
            .copy_from(&toeplitz(&m.a, &m.bu, &m.cy, m.dyu[(0, 0)], l));
        o.view_mut((at, r * n), (l, n))
            .copy_from(&free_response(&m.a, &m.cy, l));
        at += l;
    }
    let u = DVector::from_column_slice(data.u().as_slice());
    let y = DVector::from_column_slice(data.y().as_slice());
    let r = y - &tu * u;
    let Penalty::Quadratic(q) = dispersion.penalty(data.u()).unwrap() else {
        panic!("a quadratic dispersion")
    };
    let mut kf = faer::Mat::<f64>::zeros(total, total);
    q.fill(kf.as_mut());
    let k = DMatrix::from_fn(total, total, |i, j| kf[(i, j)]);
    let mm = DMatrix::identity(total, total) * (total as f64 * beta) + &tw * &k * tw.transpose();
    let chol = mm.cholesky().expect("M is positive definite");
    let x0 = if estimate_x0 {
        let mo = chol.solve(&o);
        let h = o.transpose() * &mo;
        let g = o.transpose() * chol.solve(&r);
        h.lu().solve(&g).expect("x₀ identifiable")
    } else {
        DVector::zeros(0)
    };
    let rr = if estimate_x0 { &r - &o * &x0 } else { r };
    let lambda = chol.solve(&rr);
    let w = &k * tw.transpose() * lambda;
    (w.iter().copied().collect(), x0.iter().copied().collect())
}

fn identify_with(
    data: &Data,
    dispersion: Arc<dyn Dispersion>,
    solver: SolverChoice,
    beta: f64,
    x0: bool,
) -> Identification {
    let settings = IdentifySettings::builder()
        .beta(beta)
        .solver(solver)
        .initial_state(if x0 {
            InitialState::Estimate
        } else {
            InitialState::Zero
        })
        .build()
        .unwrap();
    identify(&model(dispersion), data, &settings).unwrap()
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn scale(a: &[f64]) -> f64 {
    a.iter().fold(1e-12f64, |m, v| m.max(v.abs()))
}

/// Two records: the solver's estimate is the dense block-diagonal one and not the one of the
/// concatenated record, with a zero and with an estimated initial state.
fn two_records_match_the_block_diagonal_reference(
    dispersion: Arc<dyn Dispersion>,
    solver: SolverChoice,
) {
    let lens = [17, 12];
    let data = Data::from_records(vec![record(1, lens[0]), record(2, lens[1])]).unwrap();
    let beta = 1e-2;
    for x0 in [false, true] {
        let id = identify_with(&data, Arc::clone(&dispersion), solver, beta, x0);
        let w = id.w_hat.as_slice();
        let (w_ref, x_ref) = dense(&data, &lens, dispersion.as_ref(), beta, x0, true);
        let (w_cat, _) = dense(&data, &lens, dispersion.as_ref(), beta, x0, false);
        let tol = 1e-6 * scale(&w_ref);
        assert!(
            max_diff(w, &w_ref) < tol,
            "{solver:?}, x0 {x0}: {}",
            max_diff(w, &w_ref)
        );
        assert!(
            max_diff(&w_cat, &w_ref) > 1e3 * tol,
            "the concatenated problem should differ: {}",
            max_diff(&w_cat, &w_ref)
        );
        if x0 {
            let est = id.initial_state.as_deref().expect("x₀ estimated");
            assert_eq!(est.len(), 4, "one initial state per record");
            assert!(
                max_diff(est, &x_ref) < 1e-6 * scale(&x_ref),
                "{est:?} vs {x_ref:?}"
            );
        }
    }
}

#[test]
fn exact_gaussian_two_records() {
    two_records_match_the_block_diagonal_reference(gaussian(), SolverChoice::Exact);
}

#[test]
fn features_fourier_two_records() {
    two_records_match_the_block_diagonal_reference(fourier(), SolverChoice::Features);
}

/// The total-variation estimate (ŵ, x̂₀) as a dense conic program over the explicit operators:
/// minimise (1/L)·‖e‖² + β·Σ_j c_j·|v_a − v_b| subject to T·S·v + e + O·x₀ = r, with S the
/// sample-to-node map, T and O block diagonal (`separate`) or of the concatenated record.
fn dense_tv(
    data: &Data,
    lens: &[usize],
    beta: f64,
    estimate_x0: bool,
    separate: bool,
) -> (Vec<f64>, Vec<f64>) {
    use clarabel::algebra::CscMatrix;
    use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SupportedConeT};
    let m = lft().matrices().clone();
    let total: usize = lens.iter().sum();
    let parts: Vec<usize> = if separate { lens.to_vec() } else { vec![total] };
    let n = m.a.nrows();
    let mut tw = DMatrix::zeros(total, total);
    let mut tu = DMatrix::zeros(total, total);
    let mut o = DMatrix::zeros(total, n * parts.len());
    let mut at = 0;
    for (r, &l) in parts.iter().enumerate() {
        tw.view_mut((at, at), (l, l))
            .copy_from(&toeplitz(&m.a, &m.bw, &m.cy, m.dyw[(0, 0)], l));
        tu.view_mut((at, at), (l, l))
            .copy_from(&toeplitz(&m.a, &m.bu, &m.cy, m.dyu[(0, 0)], l));
        o.view_mut((at, r * n), (l, n))
            .copy_from(&free_response(&m.a, &m.cy, l));
        at += l;
    }
    if !estimate_x0 {
        o = DMatrix::zeros(total, 0);
    }
    let u = DVector::from_column_slice(data.u().as_slice());
    let r = DVector::from_column_slice(data.y().as_slice()) - &tu * u;
    let Penalty::TotalVariation(p) = TotalVariation::new().penalty(data.u()).unwrap() else {
        panic!("a total-variation penalty")
    };
    let (nodes, edges, nx) = (p.nodes(), p.edges().to_vec(), o.ncols());
    let ts = DMatrix::from_fn(total, nodes, |k, j| {
        let tk: f64 = (0..total)
            .filter(|&i| p.node_of_sample()[i] == j)
            .map(|i| tw[(k, i)])
            .sum();
        tk
    });
    // variables: v (nodes), x₀ (nx), e (total), t (edges)
    let (v0, x0c, e0, t0) = (0, nodes, nodes + nx, nodes + nx + total);
    let nvar = t0 + edges.len();
    let (mut ri, mut ci, mut vals, mut rhs) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for k in 0..total {
        for j in 0..nodes {
            ri.push(k);
            ci.push(v0 + j);
            vals.push(ts[(k, j)]);
        }
        for j in 0..nx {
            ri.push(k);
            ci.push(x0c + j);
            vals.push(o[(k, j)]);
        }
        ri.push(k);
        ci.push(e0 + k);
        vals.push(1.0);
        rhs.push(r[k]);
    }
    let mut q = vec![0.0; nvar];
    let mut row = total;
    for (j, &(a, b, w)) in edges.iter().enumerate() {
        q[t0 + j] = beta * w;
        for sign in [1.0, -1.0] {
            ri.extend([row, row, row]);
            ci.extend([v0 + a, v0 + b, t0 + j]);
            vals.extend([sign, -sign, -1.0]);
            rhs.push(0.0);
            row += 1;
        }
    }
    let a_mat = CscMatrix::new_from_triplets(row, nvar, ri, ci, vals);
    let pe: Vec<usize> = (e0..e0 + total).collect();
    let p_mat =
        CscMatrix::new_from_triplets(nvar, nvar, pe.clone(), pe, vec![2.0 / total as f64; total]);
    let cones = [
        SupportedConeT::ZeroConeT(total),
        SupportedConeT::NonnegativeConeT(row - total),
    ];
    let settings = DefaultSettings {
        verbose: false,
        tol_gap_abs: 1e-10,
        tol_gap_rel: 1e-10,
        tol_feas: 1e-10,
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(&p_mat, &q, &a_mat, &rhs, &cones, settings).unwrap();
    solver.solve();
    let x = &solver.solution.x;
    let w = p.sample_values(&x[v0..v0 + nodes]);
    (w, x[x0c..x0c + nx].to_vec())
}

#[test]
fn tv_clarabel_two_records() {
    let lens = [17, 12];
    let data = Data::from_records(vec![record(1, lens[0]), record(2, lens[1])]).unwrap();
    let beta = 1e-2;
    let tv: Arc<dyn Dispersion> = Arc::new(TotalVariation::new());
    for x0 in [false, true] {
        let id = identify_with(&data, Arc::clone(&tv), SolverChoice::Clarabel, beta, x0);
        let (w_ref, x_ref) = dense_tv(&data, &lens, beta, x0, true);
        let (w_cat, _) = dense_tv(&data, &lens, beta, x0, false);
        let tol = 1e-4 * scale(&w_ref);
        let w = id.w_hat.as_slice();
        assert!(
            max_diff(w, &w_ref) < tol,
            "x0 {x0}: {}",
            max_diff(w, &w_ref)
        );
        assert!(
            max_diff(&w_cat, &w_ref) > 100.0 * tol,
            "{}",
            max_diff(&w_cat, &w_ref)
        );
        if x0 {
            let est = id.initial_state.as_deref().unwrap();
            assert!(
                max_diff(est, &x_ref) < 1e-3 * scale(&x_ref),
                "{est:?} vs {x_ref:?}"
            );
        }
    }
    // ADMM runs over one record: refused with a message, not a wrong answer.
    let settings = IdentifySettings::builder()
        .beta(beta)
        .solver(SolverChoice::Admm)
        .build()
        .unwrap();
    let e = identify(&model(tv), &data, &settings).unwrap_err();
    assert!(
        matches!(e, Error::Unsupported(_)) && e.to_string().contains("2 records"),
        "{e}"
    );
}

/// Beyond the conic solver's automatic size, total variation over several records still goes
/// to the conic solver (ADMM's smoother runs over one record), and `auto` gives what an
/// explicit conic solve gives.
#[test]
fn auto_sends_total_variation_over_several_records_to_the_conic_solver() {
    let data = Data::from_records(vec![record(3, 560), record(4, 480)]).unwrap();
    assert!(data.len() > structid_core::identify::CONIC_AUTO_LIMIT);
    let tv: Arc<dyn Dispersion> = Arc::new(TotalVariation::new());
    let auto = identify_with(&data, Arc::clone(&tv), SolverChoice::Auto, 1e-2, false);
    assert_eq!(auto.diagnostics.solver, SolverKind::Clarabel);
    assert_eq!(
        auto.diagnostics.solver_reason,
        SolverReason::TotalVariationRecords { records: 2 }
    );
    let conic = identify_with(&data, tv, SolverChoice::Clarabel, 1e-2, false);
    assert_eq!(auto.w_hat.as_slice(), conic.w_hat.as_slice());
}

#[test]
fn a_short_record_and_unequal_channels_are_clear_errors() {
    let data = Data::from_records(vec![record(1, 10), record(2, 1)]).unwrap();
    let settings = IdentifySettings::builder().beta(1e-2).build().unwrap();
    let e = identify(&model(gaussian()), &data, &settings).unwrap_err();
    assert!(
        matches!(
            e,
            Error::RecordTooShort {
                record: 2,
                len: 1,
                order: 2
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("record 2"), "{e}");
    let two = Data::new(Signal::zeros(5, 2), Signal::zeros(5, 1)).unwrap();
    let e = Data::from_records(vec![record(1, 10), two]).unwrap_err();
    assert!(e.to_string().contains("u channels in record 2"), "{e}");
}

#[test]
fn record_accessors_round_trip() {
    let (a, b, c) = (record(1, 6), record(2, 4), record(3, 5));
    let data = Data::from_records(vec![a.clone(), b.clone(), c.clone()]).unwrap();
    assert_eq!(data.record_count(), 3);
    assert_eq!(data.record_bounds(), &[0, 6, 10, 15]);
    assert_eq!(data.records(), vec![a.clone(), b, c]);
    assert_eq!(&data.y().as_slice()[..6], a.y().as_slice());
    assert!(Data::from_records(Vec::new()).is_err());
    assert!(data.require_single_record("this").is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// Any split of the samples into records gives the dense block-diagonal estimate, and one
    /// record through `from_records` is the single-record estimate.
    #[test]
    fn any_split_matches_the_dense_reference(
        cuts in proptest::collection::btree_set(3usize..22, 0..4),
        x0 in any::<bool>(),
        features in any::<bool>(),
    ) {
        let total = 25;
        let mut lens = Vec::new();
        let mut last = 0;
        for c in cuts.iter().copied().chain([total]) {
            if c - last >= 3 {
                lens.push(c - last);
                last = c;
            }
        }
        *lens.last_mut().unwrap() += total - last;
        let records: Vec<Data> = lens.iter().enumerate().map(|(i, &l)| record(i as u64 + 1, l)).collect();
        let data = Data::from_records(records.clone()).unwrap();
        let (dispersion, solver) = if features {
            (fourier(), SolverChoice::Features)
        } else {
            (gaussian(), SolverChoice::Exact)
        };
        let beta = 3e-2;
        let id = identify_with(&data, Arc::clone(&dispersion), solver, beta, x0);
        let (w_ref, _) = dense(&data, &lens, dispersion.as_ref(), beta, x0, true);
        prop_assert!(max_diff(id.w_hat.as_slice(), &w_ref) < 1e-6 * scale(&w_ref));
        if records.len() == 1 {
            let one = identify_with(&records[0], Arc::clone(&dispersion), solver, beta, x0);
            prop_assert_eq!(one.w_hat.as_slice(), id.w_hat.as_slice());
        }
    }
}

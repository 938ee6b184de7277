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
    lft_with_noise_state(0.0)
}

/// [`lft`] with the noise also driving the state (B_e = [b_e; 0]): for b_e ≠ 0 the noise path
/// T_ye = 1 + C·(qI − A)⁻¹·B_e is dynamic (coloured noise); for b_e = 0.5 its zeros have
/// modulus √0.6, so it is minimum phase.
fn lft_with_noise_state(be: f64) -> Lft {
    Lft::new(LftMatrices {
        a: dmatrix![1.2, -0.5; 1.0, 0.0],
        bu: dmatrix![0.3; 0.0],
        be: dmatrix![be; 0.0],
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
}

/// Total variation over several records follows the size rules of one record: beyond the
/// conic solver's automatic size it goes to ADMM (whose smoother restarts at every record),
/// within it to the conic solver, and `auto` gives what an explicit solve by the chosen solver
/// gives.
#[test]
fn auto_uses_the_size_rules_for_total_variation_over_several_records() {
    let tv: Arc<dyn Dispersion> = Arc::new(TotalVariation::new());
    let limit = structid_core::identify::CONIC_AUTO_LIMIT;
    let data = Data::from_records(vec![record(3, 560), record(4, 480)]).unwrap();
    assert!(data.len() > limit);
    let auto = identify_with(&data, Arc::clone(&tv), SolverChoice::Auto, 1e-2, false);
    assert_eq!(auto.diagnostics.solver, SolverKind::Admm);
    assert_eq!(
        auto.diagnostics.solver_reason,
        SolverReason::TotalVariationLarge { size: 1040, limit }
    );
    let admm = identify_with(&data, Arc::clone(&tv), SolverChoice::Admm, 1e-2, false);
    assert_eq!(auto.w_hat.as_slice(), admm.w_hat.as_slice());

    let small = Data::from_records(vec![record(3, 17), record(4, 12)]).unwrap();
    let auto = identify_with(&small, Arc::clone(&tv), SolverChoice::Auto, 1e-2, false);
    assert_eq!(auto.diagnostics.solver, SolverKind::Clarabel);
    assert_eq!(
        auto.diagnostics.solver_reason,
        SolverReason::TotalVariationSmall { size: 29, limit }
    );
}

/// Settings under which ADMM and Clarabel meet to ŵ ~ 10⁻⁴ and J ~ 10⁻⁶ (relative): both
/// tighter than their defaults (at Clarabel's default 10⁻⁸ its interior point leaves nodes of
/// a flat segment of the map up to 2·10⁻⁴ apart, at a J above ADMM's).
fn tight(beta: f64, solver: SolverChoice, x0: bool) -> IdentifySettings {
    IdentifySettings::builder()
        .beta(beta)
        .solver(solver)
        .initial_state(if x0 {
            InitialState::Estimate
        } else {
            InitialState::Zero
        })
        .admm(
            structid_core::solver::admm::AdmmSettings::builder()
                .tolerance(1e-9)
                .max_iterations(200_000)
                .build()
                .unwrap(),
        )
        .conic(
            structid_core::solver::conic::ConicSettings::builder()
                .tolerance(1e-11)
                .max_iterations(1000)
                .build()
                .unwrap(),
        )
        .build()
        .unwrap()
}

/// ŵ within 10⁻⁴ of b's scale and J within 10⁻⁶ relative.
fn assert_agree(a: &Identification, b: &Identification, what: &str) {
    assert_agree_seen(a.w_hat.as_slice(), b.w_hat.as_slice(), a, b, what);
}

/// [`assert_agree`] on the given map values (those the data see).
fn assert_agree_seen(wa: &[f64], wb: &[f64], a: &Identification, b: &Identification, what: &str) {
    let dw = max_diff(wa, wb) / scale(wb);
    let dj = (a.cost.total - b.cost.total).abs() / b.cost.total.abs();
    assert!(dw < 1e-4, "{what}: relative ŵ difference {dw:.3e}");
    assert!(dj < 1e-6, "{what}: relative J difference {dj:.3e}");
}

/// ŵ without the last sample of each record: with D_yw = 0 in [`lft`] its map value reaches
/// no output before the record ends, so it is set by the total variation alone and is not
/// unique (any value between its node's neighbours costs the same); solvers may return
/// different minimisers there.
fn seen(w: &[f64], lens: &[usize]) -> Vec<f64> {
    let mut out = Vec::with_capacity(w.len());
    let mut at = 0;
    for &l in lens {
        out.extend_from_slice(&w[at..at + l - 1]);
        at += l;
    }
    out
}

/// The concatenation of the records as one record.
fn concatenated(data: &Data) -> Data {
    Data::new(data.u().clone(), data.y().clone()).unwrap()
}

/// ADMM over two and three records: each record's smoother starts from that record's own
/// state (zero, or a free x₀ per record), so it equals Clarabel over the same records (whose
/// program restarts the dynamics there) and the dense block-diagonal reference, and differs
/// from ADMM on the concatenated record.
#[test]
fn tv_admm_over_records_equals_clarabel_and_not_the_concatenation() {
    let tv: Arc<dyn Dispersion> = Arc::new(TotalVariation::new());
    let beta = 1e-2;
    for lens in [&[17usize, 12][..], &[15, 11, 13]] {
        let records: Vec<Data> = lens
            .iter()
            .enumerate()
            .map(|(i, &l)| record(i as u64 + 1, l))
            .collect();
        let data = Data::from_records(records).unwrap();
        let cat = concatenated(&data);
        for x0 in [false, true] {
            let run = |d: &Data, solver| {
                identify(&model(Arc::clone(&tv)), d, &tight(beta, solver, x0)).unwrap()
            };
            let admm = run(&data, SolverChoice::Admm);
            let conic = run(&data, SolverChoice::Clarabel);
            let what = format!("{lens:?}, x0 {x0}");
            assert_eq!(admm.diagnostics.status, SolveStatus::Solved, "{what}");
            let w = seen(admm.w_hat.as_slice(), lens);
            assert_agree_seen(
                &w,
                &seen(conic.w_hat.as_slice(), lens),
                &admm,
                &conic,
                &what,
            );
            let (w_ref, x_ref) = dense_tv(&data, lens, beta, x0, true);
            let w_ref = seen(&w_ref, lens);
            let w = &w[..];
            assert!(
                max_diff(w, &w_ref) < 1e-4 * scale(&w_ref),
                "{what}: {}",
                max_diff(w, &w_ref)
            );
            let joined = run(&cat, SolverChoice::Admm);
            assert!(
                max_diff(&seen(joined.w_hat.as_slice(), lens), w) > 1e-2 * scale(w),
                "{what}: the concatenated record should give another estimate"
            );
            if x0 {
                let est = admm.initial_state.as_deref().expect("x₀ estimated");
                assert_eq!(est.len(), 2 * lens.len(), "one initial state per record");
                assert!(
                    max_diff(est, &x_ref) < 1e-3 * scale(&x_ref),
                    "{what}: {est:?} vs {x_ref:?}"
                );
            } else {
                assert!(admm.initial_state.is_none());
            }
        }
    }
}

/// Cross-validation over records holds out a whole record: ADMM leaves all its outputs out
/// (its map values reach no kept output) and equals Clarabel on the records that remain, with
/// a zero and an estimated initial state.
#[test]
fn admm_with_a_whole_record_held_out_equals_clarabel() {
    let lens = [15usize, 11, 13];
    let records: Vec<Data> = lens
        .iter()
        .enumerate()
        .map(|(i, &l)| record(i as u64 + 1, l))
        .collect();
    let data = Data::from_records(records).unwrap();
    let tv: Arc<dyn Dispersion> = Arc::new(TotalVariation::new());
    let tv_model = model(tv);
    // Record 2 (samples 15..26) held out.
    let mask: Vec<bool> = (0..39).map(|k| (15..26).contains(&k)).collect();
    for x0 in [false, true] {
        let problem = if x0 {
            Problem::from_model_with_initial_state(&tv_model, &data)
        } else {
            Problem::from_model(&tv_model, &data)
        }
        .unwrap()
        .with_held_out(mask.clone())
        .unwrap();
        let run = |solver| identify_problem(&problem, &tight(1e-2, solver, x0)).unwrap();
        let (admm, conic) = (run(SolverChoice::Admm), run(SolverChoice::Clarabel));
        let what = format!("x0 {x0}");
        assert_eq!(admm.diagnostics.status, SolveStatus::Solved, "{what}");
        // The kept records' samples the data see (record 2's values are set by the total
        // variation alone).
        let kept = |w: &[f64]| -> Vec<f64> {
            let s = seen(w, &lens);
            [&s[..14], &s[24..]].concat()
        };
        assert_agree_seen(
            &kept(admm.w_hat.as_slice()),
            &kept(conic.w_hat.as_slice()),
            &admm,
            &conic,
            &what,
        );
        assert!(admm.diagnostics.feasibility_residual < 1e-7, "{what}");
    }
}

/// A quadratic block next to a total-variation block (ADMM's w-step carries the quadratic
/// block's features), over two records, with and without held-out samples (a
/// cross-validation fold inside each record and one at the end of the first), with a zero and
/// an estimated initial state: ADMM equals Clarabel on the same problem.
#[test]
fn mixed_admm_over_records_with_held_out_samples_equals_clarabel() {
    let smooth: Arc<dyn Dispersion> = Arc::new(
        FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.5 })
            .unwrap()
            .with_harmonics(12),
    );
    let exp = structid_core::scenarios::mixed_hammerstein_with_radius(90, smooth, 0.7, 4).unwrap();
    let (u, y) = (exp.data.u(), exp.data.y());
    let data = Data::from_records(vec![
        Data::new(u.slice(0..50), y.slice(0..50)).unwrap(),
        Data::new(u.slice(50..90), y.slice(50..90)).unwrap(),
    ])
    .unwrap();
    let beta = 1e-2;
    // Samples 10..18 and 60..66 (inside records), and 46..50 (the end of record 1).
    let mask: Vec<bool> = (0..90)
        .map(|k| (10..18).contains(&k) || (60..66).contains(&k) || (46..50).contains(&k))
        .collect();
    for x0 in [false, true] {
        for held in [false, true] {
            let problem = if x0 {
                Problem::from_model_with_initial_state(&exp.model, &data)
            } else {
                Problem::from_model(&exp.model, &data)
            }
            .unwrap();
            let problem = if held {
                problem.with_held_out(mask.clone()).unwrap()
            } else {
                problem
            };
            let run = |solver| identify_problem(&problem, &tight(beta, solver, x0)).unwrap();
            let (admm, conic) = (run(SolverChoice::Admm), run(SolverChoice::Clarabel));
            let what = format!("x0 {x0}, held out {held}");
            assert_eq!(admm.diagnostics.status, SolveStatus::Solved, "{what}");
            if held {
                // The map values of samples held out at the end of a record reach no kept
                // output and are set by the total variation alone, not uniquely: compare J
                // and the values the data see.
                let dj = (admm.cost.total - conic.cost.total).abs() / conic.cost.total.abs();
                assert!(dj < 1e-6, "{what}: relative J difference {dj:.3e}");
                let keep = |w: &[f64]| -> Vec<f64> {
                    w.chunks(2)
                        .enumerate()
                        .filter(|(k, _)| !(46..50).contains(k))
                        .flat_map(|(_, c)| c.to_vec())
                        .collect()
                };
                let (wa, wc) = (keep(admm.w_hat.as_slice()), keep(conic.w_hat.as_slice()));
                assert!(
                    max_diff(&wa, &wc) < 1e-4 * scale(&wc),
                    "{what}: {}",
                    max_diff(&wa, &wc)
                );
            } else {
                assert_agree(&admm, &conic, &what);
            }
            assert!(admm.diagnostics.feasibility_residual < 1e-7, "{what}");
        }
    }
}

/// The feature solver with a coloured (dynamic) noise path over several records whitens each
/// record from its own start: it equals the exact solver (whose operators are block diagonal
/// and which does not whiten) and the dense block-diagonal reference's concatenation differs.
#[test]
fn features_with_coloured_noise_over_records_equal_the_exact_solver() {
    let coloured = Model::new(
        lft_with_noise_state(0.5),
        vec![NonlinearBlock::new("f", vec![0], 0, fourier())],
    )
    .unwrap();
    let beta = 1e-2;
    for lens in [&[17usize, 12][..], &[15, 11, 13]] {
        let records: Vec<Data> = lens
            .iter()
            .enumerate()
            .map(|(i, &l)| record(i as u64 + 1, l))
            .collect();
        let data = Data::from_records(records).unwrap();
        for x0 in [false, true] {
            let settings = |solver| {
                IdentifySettings::builder()
                    .beta(beta)
                    .solver(solver)
                    .initial_state(if x0 {
                        InitialState::Estimate
                    } else {
                        InitialState::Zero
                    })
                    .build()
                    .unwrap()
            };
            let feat = identify(&coloured, &data, &settings(SolverChoice::Features)).unwrap();
            let exact = identify(&coloured, &data, &settings(SolverChoice::Exact)).unwrap();
            let what = format!("{lens:?}, x0 {x0}");
            let (wf, we) = (feat.w_hat.as_slice(), exact.w_hat.as_slice());
            assert!(
                max_diff(wf, we) < 1e-6 * scale(we),
                "{what}: {}",
                max_diff(wf, we)
            );
            let dj = (feat.cost.total - exact.cost.total).abs() / exact.cost.total.abs();
            assert!(dj < 1e-8, "{what}: relative J difference {dj:.3e}");
            let de = max_diff(feat.e_hat.as_slice(), exact.e_hat.as_slice());
            assert!(
                de < 1e-6 * scale(exact.e_hat.as_slice()),
                "{what}: ê {de:.3e}"
            );
            if x0 {
                let (xf, xe) = (
                    feat.initial_state.as_deref().unwrap(),
                    exact.initial_state.as_deref().unwrap(),
                );
                assert_eq!(xf.len(), 2 * lens.len());
                assert!(
                    max_diff(xf, xe) < 1e-6 * scale(xe),
                    "{what}: {xf:?} vs {xe:?}"
                );
            }
            // The concatenated record (whitened across the record boundaries) is another
            // problem.
            let cat = identify(
                &coloured,
                &concatenated(&data),
                &settings(SolverChoice::Features),
            )
            .unwrap();
            assert!(
                max_diff(cat.w_hat.as_slice(), wf) > 1e-3 * scale(wf),
                "{what}: the concatenated record should give another estimate"
            );
        }
    }
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
    #![proptest_config(ProptestConfig::with_cases(6))]

    /// ADMM over any split of the samples into records (each record from its own state)
    /// equals Clarabel over the same split, with a zero or an estimated initial state.
    #[test]
    fn admm_over_any_record_split_equals_clarabel(
        cuts in proptest::collection::btree_set(4usize..26, 0..3),
        x0 in any::<bool>(),
    ) {
        let total = 30;
        let mut lens = Vec::new();
        let mut last = 0;
        for c in cuts.iter().copied().chain([total]) {
            if c - last >= 4 {
                lens.push(c - last);
                last = c;
            }
        }
        *lens.last_mut().unwrap() += total - last;
        let records: Vec<Data> =
            lens.iter().enumerate().map(|(i, &l)| record(i as u64 + 1, l)).collect();
        let data = Data::from_records(records).unwrap();
        let tv: Arc<dyn Dispersion> = Arc::new(TotalVariation::new());
        let run = |solver| identify(&model(Arc::clone(&tv)), &data, &tight(2e-2, solver, x0)).unwrap();
        let (admm, conic) = (run(SolverChoice::Admm), run(SolverChoice::Clarabel));
        prop_assert_eq!(admm.diagnostics.status, SolveStatus::Solved);
        let (wa, wc) = (seen(admm.w_hat.as_slice(), &lens), seen(conic.w_hat.as_slice(), &lens));
        prop_assert!(max_diff(&wa, &wc) < 1e-4 * scale(&wc), "{:?}: {}", lens, max_diff(&wa, &wc));
        let dj = (admm.cost.total - conic.cost.total).abs() / conic.cost.total.abs();
        prop_assert!(dj < 1e-6, "{:?}: relative J difference {:.3e}", lens, dj);
    }
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

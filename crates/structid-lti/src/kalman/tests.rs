//! Tests of the Kalman whitener against the dense formulation `r^T (T T^T)^{-1} r`.

use super::*;
use crate::LinearSystem;
use crate::testing::{SplitMix64, random_signal, random_stable_system};
use faer::Mat;
use nalgebra::DVector;
use proptest::prelude::*;

fn opts() -> WhiteningOptions {
    WhiteningOptions::default()
}

/// Dense reference: Cholesky factor of `T T^T` over `len` samples (well-conditioned cases).
fn dense_chol(noise: &StateSpace, len: usize) -> DMatrix<f64> {
    let t = noise.toeplitz_dense(len);
    let m = &t * t.transpose();
    m.cholesky().expect("T T^T positive definite").l()
}

fn whiten_vec(w: &KalmanWhitener, y: &[f64]) -> Vec<f64> {
    let mut out = vec![f64::NAN; y.len()];
    w.whiten(y, &mut out);
    out
}

fn sq(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum()
}

/// The whitening operator as a dense matrix (columns = whitened unit vectors).
fn dense_w(w: &KalmanWhitener) -> DMatrix<f64> {
    let rows = w.len() * w.outputs();
    let mut wd = DMatrix::zeros(rows, rows);
    let mut e = vec![0.0; rows];
    for j in 0..rows {
        e[j] = 1.0;
        let col = whiten_vec(w, &e);
        e[j] = 0.0;
        for i in 0..rows {
            wd[(i, j)] = col[i];
        }
    }
    wd
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

/// A system with a non-trivial Riccati transient: `n` states, `p` outputs, `ne > p` noise
/// channels.
fn coloured(seed: u64, n: usize, ne: usize, p: usize) -> StateSpace {
    random_stable_system(seed, n, ne, p, 0.9)
}

/// Accurate dense reference `L^{-1}` applied to `r`, with `T T^T = L L^T`, from the QR
/// factorisation of `T^T` (`T T^T = R^T R`, so `L = R^T` up to the signs of the rows of
/// `R`): its forward error scales with `cond(T)`, not `cond(T T^T)`.
fn qr_whiten(t: &DMatrix<f64>, r: &[f64]) -> DVector<f64> {
    let mut rr = t.transpose().qr().r();
    for i in 0..rr.nrows() {
        if rr[(i, i)] < 0.0 {
            rr.row_mut(i).neg_mut();
        }
    }
    rr.transpose()
        .solve_lower_triangular(&DVector::from_column_slice(r))
        .unwrap()
}

/// Relative tolerance of the comparisons with the dense references: `1e-9`, widened by the
/// forward-error scale `eps cond(T T^T)` of the Cholesky reference for the rare
/// ill-conditioned draws (`cond > 1e6`; the worst seen is `cond = 2e10`, where the dense
/// Cholesky reference itself is off by `4e-10` while the Kalman filter is within `6e-12`
/// of an exact rational computation of such a case).
fn dense_tol(m: &DMatrix<f64>) -> f64 {
    let sv = m.singular_values();
    1e-9 + 16.0 * f64::EPSILON * sv.max() / sv.min()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn prop_whitening_matches_dense_quadratic_form(
        seed in any::<u64>(), n in 0usize..=4, p in 1usize..=3, extra in 1usize..=2,
        len in 5usize..=40
    ) {
        let noise = coloured(seed, n, p + extra, p);
        let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
        prop_assert!(w.is_exact());
        let t = noise.toeplitz_dense(len);
        let m = &t * t.transpose();
        let tol = dense_tol(&m);
        let l = m.cholesky().expect("T T^T positive definite").l();
        let r = random_signal(seed ^ 0x55, len, p);
        let omega = whiten_vec(&w, r.as_slice());
        prop_assert!(omega.iter().all(|v| v.is_finite()));
        let z = l.solve_lower_triangular(&DVector::from_column_slice(r.as_slice())).unwrap();
        let (quad, quad_ref) = (sq(&omega), z.norm_squared());
        prop_assert!((quad - quad_ref).abs() <= tol * quad_ref, "{} vs {} (tol {:e})", quad, quad_ref, tol);
        // W is the inverse Cholesky factor: W r equals L^{-1} r itself
        let zq = qr_whiten(&t, r.as_slice());
        prop_assert!((quad - zq.norm_squared()).abs() <= tol * quad_ref);
        prop_assert!(max_abs_diff(&omega, zq.as_slice()) <= tol * (1.0 + zq.amax()));
        let log_det_ref = 2.0 * l.diagonal().map(f64::ln).sum();
        prop_assert!(
            (w.log_det() - log_det_ref).abs() <= tol * (1.0 + log_det_ref.abs()),
            "{} vs {}", w.log_det(), log_det_ref
        );
        // the many-column path gives the same
        let x = Mat::from_fn(len * p, 3, |i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0);
        let mut out = Mat::<f64>::zeros(len * p, 3);
        w.whiten_columns(x.as_ref(), out.as_mut());
        for j in 0..3 {
            let col: Vec<f64> = (0..len * p).map(|i| x[(i, j)]).collect();
            let refc = whiten_vec(&w, &col);
            for i in 0..len * p {
                prop_assert!((out[(i, j)] - refc[i]).abs() <= 1e-12 * (1.0 + refc[i].abs()));
            }
        }
    }
}

#[test]
fn ill_conditioned_draw_found_by_proptest() {
    // cond(T T^T) = 7.8e8. Exact rational arithmetic gives r^T (T T^T)^{-1} r =
    // 7925.881335603272; the Kalman filter is within 5.0e-10 (relative), the dense
    // Cholesky reference within 2.8e-9, the QR reference within 8.6e-13
    let (seed, n, p, len) = (1692729156905877846u64, 4, 2, 11);
    let noise = coloured(seed, n, p + 1, p);
    let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
    let r = random_signal(seed ^ 0x55, len, p);
    let exact = 7925.881335603272;
    let quad = sq(&whiten_vec(&w, r.as_slice()));
    assert!((quad - exact).abs() <= 1e-9 * exact, "{quad}");
    let zq = qr_whiten(&noise.toeplitz_dense(len), r.as_slice());
    assert!((zq.norm_squared() - exact).abs() <= 1e-11 * exact);
}

#[test]
fn w_is_lower_triangular_inverse_cholesky_factor() {
    for (seed, n, ne, p, len) in [
        (1, 3, 3, 2, 12),
        (2, 2, 2, 1, 20),
        (3, 4, 4, 3, 8),
        (4, 1, 2, 1, 30),
    ] {
        let noise = coloured(seed, n, ne, p);
        let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
        let wd = dense_w(&w);
        let rows = len * p;
        for j in 0..rows {
            for i in 0..j {
                assert_eq!(wd[(i, j)], 0.0, "W[{i},{j}] above the diagonal");
            }
            assert!(wd[(j, j)] > 0.0);
        }
        let t = noise.toeplitz_dense(len);
        let m = &t * t.transpose();
        // W M W^T = I
        let wmw = &wd * &m * wd.transpose();
        let err = (&wmw - DMatrix::<f64>::identity(rows, rows)).amax();
        assert!(err < 1e-10, "|W M W^T - I| = {err:e} (seed {seed})");
        // W^T W = M^{-1}
        let minv = m.clone().try_inverse().unwrap();
        let err = (wd.transpose() * &wd - &minv).amax() / minv.amax();
        assert!(err < 1e-10, "|W^T W - M^-1| / |M^-1| = {err:e}");
        // and W = L^{-1} with M = L L^T (uniqueness of the Cholesky factor)
        let l = m.cholesky().unwrap().l();
        let err = (&wd * &l - DMatrix::<f64>::identity(rows, rows)).amax();
        assert!(err < 1e-10, "|W L - I| = {err:e}");
    }
}

#[test]
fn whiten_columns_matches_whiten_long_record() {
    let len = 5000;
    for (seed, n, ne, p, ncols) in [(11, 4, 2, 1, 70), (12, 3, 4, 2, 9), (13, 0, 3, 2, 66)] {
        let noise = coloured(seed, n, ne, p);
        let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
        if n > 0 {
            assert!(
                w.transient_len() > 0 && w.transient_len() < 500,
                "{}",
                w.transient_len()
            );
        } else {
            assert_eq!(w.transient_len(), 0);
        }
        let mut rng = SplitMix64::new(seed);
        let x = Mat::from_fn(len * p, ncols, |_, _| rng.uniform_in(-1.0, 1.0));
        let xt = x.transpose().to_owned(); // for a row-major view
        let mut out = Mat::<f64>::zeros(len * p, ncols);
        let mut out_t = Mat::<f64>::zeros(len * p, ncols);
        w.whiten_columns(x.as_ref(), out.as_mut());
        w.whiten_columns(xt.as_ref().transpose(), out_t.as_mut());
        let mut worst: f64 = 0.0;
        for j in 0..ncols {
            let col: Vec<f64> = (0..len * p).map(|i| x[(i, j)]).collect();
            let refc = whiten_vec(&w, &col);
            let scale = refc.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for i in 0..len * p {
                worst = worst.max((out[(i, j)] - refc[i]).abs() / scale);
                worst = worst.max((out_t[(i, j)] - refc[i]).abs() / scale);
            }
        }
        assert!(worst < 1e-12, "seed {seed}: relative difference {worst:e}");
    }
}

#[test]
fn frozen_gains_at_max_transient() {
    // cap below the convergence time: the gains are frozen, both paths still agree and
    // the result is close to the exact whitener
    let noise = coloured(21, 3, 2, 1);
    let len = 600;
    let exact = KalmanWhitener::new(&noise, len, &opts()).unwrap();
    assert!(exact.transient_len() > 5);
    let capped = KalmanWhitener::new(
        &noise,
        len,
        &WhiteningOptions {
            max_transient: 5,
            ..opts()
        },
    )
    .unwrap();
    assert_eq!(capped.transient_len(), 5);
    assert!(!capped.is_exact());
    let y = random_signal(3, len, 1);
    let a = whiten_vec(&exact, y.as_slice());
    let b = whiten_vec(&capped, y.as_slice());
    assert_eq!(&a[..5], &b[..5]);
    let x = Mat::from_fn(len, 2, |i, j| y.as_slice()[i] * (j as f64 + 1.0));
    let mut out = Mat::<f64>::zeros(len, 2);
    capped.whiten_columns(x.as_ref(), out.as_mut());
    for i in 0..len {
        assert!((out[(i, 1)] - 2.0 * b[i]).abs() <= 1e-12 * (1.0 + b[i].abs()));
    }
    // a record shorter than the transient: all gains time-varying
    let short = KalmanWhitener::new(&noise, 4, &opts()).unwrap();
    assert_eq!(short.transient_len(), 4);
    assert!(short.is_exact());
}

#[test]
fn steady_state_only_converges_to_exact() {
    let len = 3000;
    for (seed, n, ne, p) in [(31, 4, 2, 1), (32, 3, 4, 2), (33, 2, 3, 1)] {
        let noise = coloured(seed, n, ne, p);
        let exact = KalmanWhitener::new(&noise, len, &opts()).unwrap();
        let ss = KalmanWhitener::new(
            &noise,
            len,
            &WhiteningOptions {
                steady_state_only: true,
                ..opts()
            },
        )
        .unwrap();
        assert_eq!(ss.transient_len(), 0);
        assert!(!ss.is_exact());
        // the steady-state filters agree (doubling vs the time-varying limit)
        let (fa, fb) = (exact.steady_state_filter(), ss.steady_state_filter());
        let gap = (fa.b() - fb.b()).amax().max((fa.d() - fb.d()).amax());
        assert!(gap < 1e-10, "steady gains differ by {gap:e}");
        let standalone = steady_state_whitening_filter(&noise).unwrap();
        assert!((standalone.b() - fb.b()).amax() < 1e-14);
        let y = random_signal(seed, len, p);
        let a = whiten_vec(&exact, y.as_slice());
        let b = whiten_vec(&ss, y.as_slice());
        let diff: Vec<f64> = (0..len)
            .map(|t| max_abs_diff(&a[t * p..(t + 1) * p], &b[t * p..(t + 1) * p]))
            .collect();
        let first_below = diff.iter().position(|&d| d < 1e-8).unwrap();
        let settled = (0..len)
            .find(|&t| diff[t..].iter().all(|&d| d < 1e-8))
            .unwrap();
        let tail = diff[len / 2..].iter().fold(0.0f64, |m, &d| m.max(d));
        println!(
            "steady_state_only (seed {seed}, n {n}, ne {ne}, p {p}): diff at t=0 {:.2e}, t=10 {:.2e}, \
             t=50 {:.2e}; first < 1e-8 at t={first_below}, stays below from t={settled}; \
             max over second half {tail:.2e}; exact transient_len {}; steady gain gap {gap:.1e}",
            diff[0],
            diff[10],
            diff[50],
            exact.transient_len()
        );
        assert!(
            settled < 1000,
            "difference did not settle below 1e-8: {settled}"
        );
        // floor: the exact whitener freezes P at the steady-state test, P_inf differs by
        // about tol / (1 - rho^2)
        assert!(tail < 1e-9);
        // log det differs only through the transient
        let ld_gap = (exact.log_det() - ss.log_det()).abs();
        assert!(ld_gap.is_finite());
    }
}

#[test]
fn singular_r_is_a_clear_error() {
    let a = DMatrix::from_element(1, 1, 0.5);
    let b = DMatrix::from_row_slice(1, 2, &[1.0, 0.3]);
    let c = DMatrix::from_row_slice(2, 1, &[1.0, -1.0]);
    // channel 1 = 2 * channel 0 in D
    let d = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 2.0, 1.0]);
    let noise = StateSpace::new(a.clone(), b.clone(), c.clone(), d).unwrap();
    let msg = |r: Result<KalmanWhitener, LtiError>| match r {
        Err(e @ LtiError::InvalidParameter { .. }) => e.to_string(),
        other => panic!("expected an error, got {other:?}"),
    };
    let m = msg(KalmanWhitener::new(&noise, 10, &opts()));
    assert!(m.contains("output channel 1 at sample 0"), "{m}");
    assert!(m.contains("D D^T"), "{m}");
    assert!(!m.contains("NaN"), "{m}");
    let m = msg(KalmanWhitener::new(
        &noise,
        10,
        &WhiteningOptions {
            steady_state_only: true,
            ..opts()
        },
    ));
    assert!(m.contains("output channel 1"), "{m}");
    assert!(steady_state_whitening_filter(&noise).is_err());
    // a noiseless channel: row of D is zero
    let d0 = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 1.0, 0.0]);
    let noise = StateSpace::new(a.clone(), b.clone(), c.clone(), d0).unwrap();
    let m = msg(KalmanWhitener::new(&noise, 10, &opts()));
    assert!(
        m.contains("output channel 0 at sample 0 does not depend on the noise"),
        "{m}"
    );
    // D = 0 (y = C x): T T^T singular although C P C^T fills S from t = 1 on
    let dz = DMatrix::zeros(2, 2);
    let noise = StateSpace::new(a, b, c, dz).unwrap();
    let m = msg(KalmanWhitener::new(&noise, 10, &opts()));
    assert!(m.contains("sample 0"), "{m}");
    // no noise input at all
    let none = StateSpace::static_gain(DMatrix::zeros(1, 0)).unwrap();
    assert!(KalmanWhitener::new(&none, 5, &opts()).is_err());
    // bad tolerance
    let ok = coloured(1, 1, 2, 1);
    assert!(matches!(
        KalmanWhitener::new(
            &ok,
            5,
            &WhiteningOptions {
                steady_state_tol: f64::NAN,
                ..opts()
            }
        ),
        Err(LtiError::InvalidParameter { .. })
    ));
}

#[test]
fn static_noise_path_is_blockdiag_inverse_cholesky() {
    let d = DMatrix::from_row_slice(2, 3, &[1.0, 0.5, -0.2, 0.3, 2.0, 0.1]);
    let noise = StateSpace::static_gain(d.clone()).unwrap();
    let len = 50;
    let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
    assert_eq!((w.transient_len(), w.order(), w.outputs()), (0, 0, 2));
    assert!(w.is_exact());
    let r = &d * d.transpose();
    let l = r.clone().cholesky().unwrap().l();
    let linv = l.clone().try_inverse().unwrap();
    let y = random_signal(5, len, 2);
    let omega = whiten_vec(&w, y.as_slice());
    for t in 0..len {
        let yt = DVector::from_column_slice(y.sample(t));
        let ref_t = &linv * yt;
        assert!(max_abs_diff(&omega[2 * t..2 * t + 2], ref_t.as_slice()) < 1e-14);
    }
    let ld = len as f64 * r.determinant().ln();
    assert!((w.log_det() - ld).abs() < 1e-12 * ld.abs().max(1.0));
    // many columns (static path of whiten_columns)
    let x = Mat::from_fn(len * 2, 5, |i, j| y.as_slice()[i] * (j as f64 - 2.0));
    let mut out = Mat::<f64>::zeros(len * 2, 5);
    w.whiten_columns(x.as_ref(), out.as_mut());
    for j in 0..5 {
        for i in 0..len * 2 {
            assert!((out[(i, j)] - omega[i] * (j as f64 - 2.0)).abs() < 1e-14);
        }
    }
    // and the standalone steady-state filter is L^{-1}
    let f = steady_state_whitening_filter(&noise).unwrap();
    assert!((f.d() - &linv).amax() < 1e-15);
}

#[test]
fn square_invertible_d_gives_inverse_toeplitz() {
    // minimum-phase noise model with as many noise channels as outputs: P_t = 0, the gains
    // are constant from the start and W = T^{-1}
    let noise = StateSpace::new(
        DMatrix::from_row_slice(2, 2, &[0.5, 0.2, -0.1, 0.3]),
        DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.4, 1.0]),
        DMatrix::from_row_slice(2, 2, &[0.3, 0.1, 0.0, 0.2]),
        DMatrix::from_row_slice(2, 2, &[1.0, 0.2, 0.0, 1.5]),
    )
    .unwrap();
    let len = 400;
    let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
    assert_eq!(w.transient_len(), 0);
    // (W T)^T (W T) = I and W T is block lower triangular, so W T = blockdiag(L^{-1} D)
    // with orthogonal blocks: |(W T e)_t| = |e_t| sample by sample
    let e = random_signal(8, len, 2);
    let y = noise.simulate(&e).unwrap();
    let omega = whiten_vec(&w, y.as_slice());
    for t in 0..len {
        let a = sq(&omega[2 * t..2 * t + 2]);
        let b = sq(e.sample(t));
        assert!((a - b).abs() < 1e-12 * (1.0 + b), "t {t}: {a} vs {b}");
    }
}

#[test]
fn scale_invariance() {
    // scaling the noise by s scales W by 1/s; the steady-state test is relative, so the
    // transient length does not depend on the units
    let noise = coloured(41, 3, 3, 2);
    let s = 1e-4;
    let scaled = StateSpace::new(
        noise.a().clone(),
        noise.b() * s,
        noise.c().clone(),
        noise.d() * s,
    )
    .unwrap();
    let len = 400;
    let w1 = KalmanWhitener::new(&noise, len, &opts()).unwrap();
    let w2 = KalmanWhitener::new(&scaled, len, &opts()).unwrap();
    let t1 = w1.transient_len() as i64;
    let t2 = w2.transient_len() as i64;
    assert!((t1 - t2).abs() <= 2, "{t1} vs {t2}");
    let y = random_signal(4, len, 2);
    let a = whiten_vec(&w1, y.as_slice());
    let b: Vec<f64> = whiten_vec(&w2, y.as_slice())
        .iter()
        .map(|v| v * s)
        .collect();
    let scale = a.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    assert!(max_abs_diff(&a, &b) < 1e-11 * scale);
    let ld = 2.0 * (len * 2) as f64 * s.ln();
    assert!((w2.log_det() - w1.log_det() - ld).abs() < 1e-9 * ld.abs());
}

#[test]
fn degenerate_shapes() {
    let noise = coloured(51, 2, 3, 2);
    let w = KalmanWhitener::new(&noise, 0, &opts()).unwrap();
    assert!(w.is_empty());
    assert_eq!(w.log_det(), 0.0);
    w.whiten(&[], &mut []);
    w.whiten_columns(
        Mat::<f64>::zeros(0, 3).as_ref(),
        Mat::<f64>::zeros(0, 3).as_mut(),
    );
    let w = KalmanWhitener::new(&noise, 1, &opts()).unwrap();
    let omega = whiten_vec(&w, &[1.0, 2.0]);
    assert!(omega.iter().all(|v| v.is_finite()));
    // no columns
    let w = KalmanWhitener::new(&noise, 10, &opts()).unwrap();
    w.whiten_columns(
        Mat::<f64>::zeros(20, 0).as_ref(),
        Mat::<f64>::zeros(20, 0).as_mut(),
    );
    assert!(format!("{w:?}").contains("transient_len"));
}

#[test]
fn steady_filter_is_the_lti_tail() {
    // after the transient the whitener is the steady filter started from the carried state:
    // for a long record, whitening equals the steady filter applied to the record up to a
    // decaying start-up difference
    let noise = coloured(61, 4, 2, 1);
    let len = 2000;
    let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
    let f = w.steady_state_filter();
    let y = random_signal(9, len, 1);
    let a = whiten_vec(&w, y.as_slice());
    let mut b = vec![0.0; len];
    f.apply(y.as_slice(), &mut b);
    assert!(max_abs_diff(&a[len / 2..], &b[len / 2..]) < 1e-10);
}

#[test]
fn dare_fallback_and_non_minimum_phase() {
    // an unstable mode that the noise does not excite but the output observes: with
    // eigenvalue 1e60 doubling overflows before it converges and the plain recursion takes
    // over; both agree with the time-varying limit
    let unexcited = |big: f64| {
        StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[big, 0.0, 0.0, 0.5]),
            DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 1.0, 0.5]),
            DMatrix::from_row_slice(1, 2, &[1.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[0.3, 1.0]),
        )
        .unwrap()
    };
    let huge = unexcited(1e60);
    let w = KalmanWhitener::new(&huge, 60, &opts()).unwrap();
    let f = steady_state_whitening_filter(&huge).unwrap();
    assert!((f.b() - w.steady_state_filter().b()).amax() < 1e-12);
    let noise = unexcited(2.0);
    let len = 60;
    let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
    assert!(w.transient_len() < len);
    let f = steady_state_whitening_filter(&noise).unwrap();
    assert!((f.b() - w.steady_state_filter().b()).amax() < 1e-12);
    let l = dense_chol(&noise, len);
    let r = random_signal(1, len, 1);
    let z = l
        .solve_lower_triangular(&DVector::from_column_slice(r.as_slice()))
        .unwrap();
    assert!(max_abs_diff(&whiten_vec(&w, r.as_slice()), z.as_slice()) < 1e-9 * z.amax());

    // non-minimum-phase square noise model H = 1 - 2 z^-1: P_t = 0, W = T^{-1} is the
    // unstable filter 1 / (1 - 2 z^-1), both time-varying and steady state
    let nmp = StateSpace::new(
        DMatrix::zeros(1, 1),
        DMatrix::from_element(1, 1, 1.0),
        DMatrix::from_element(1, 1, -2.0),
        DMatrix::from_element(1, 1, 1.0),
    )
    .unwrap();
    let w = KalmanWhitener::new(&nmp, 30, &opts()).unwrap();
    assert_eq!(w.transient_len(), 0);
    assert_eq!(w.steady_state_filter().a()[(0, 0)], 2.0);
    assert_eq!(
        steady_state_whitening_filter(&nmp).unwrap().a()[(0, 0)],
        2.0
    );
    let mut impulse = vec![0.0; 30];
    impulse[0] = 1.0;
    let h = whiten_vec(&w, &impulse);
    assert_eq!(h[10], 1024.0); // 2^t
    assert_eq!(w.log_det(), 0.0);

    // noise spectrum vanishing on the unit circle: H = (1 - z^-1) [1, 0.5 z^-1]; the
    // whitening filter has a pole at 1
    let uc = StateSpace::new(
        DMatrix::from_row_slice(3, 3, &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
        DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, 0.0, 0.0]),
        DMatrix::from_row_slice(1, 3, &[-1.0, 0.5, -0.5]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
    )
    .unwrap();
    let len = 40;
    let w = KalmanWhitener::new(&uc, len, &opts()).unwrap();
    let f = steady_state_whitening_filter(&uc).unwrap();
    assert!((f.spectral_radius() - 1.0).abs() < 1e-12);
    let l = dense_chol(&uc, len);
    let z = l
        .solve_lower_triangular(&DVector::from_column_slice(r.as_slice()[..len].as_ref()))
        .unwrap();
    assert!(max_abs_diff(&whiten_vec(&w, &r.as_slice()[..len]), z.as_slice()) < 1e-9 * z.amax());
}

/// A full-rank coloured noise path (D with ne ≥ p and a dominant diagonal).
fn coloured_full_rank(seed: u64, n: usize, p: usize) -> StateSpace {
    let ne = p + 1;
    let s = random_stable_system(seed, n, ne, p, 0.9);
    let mut d = s.d().clone();
    for i in 0..p {
        d[(i, i)] += 2.0;
    }
    StateSpace::new(s.a().clone(), s.b().clone(), s.c().clone(), d).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, .. ProptestConfig::default() })]

    /// Whitening chunk by chunk, with arbitrary chunk lengths, equals whitening the whole record.
    #[test]
    fn prop_whitening_stream_equals_whole_record(seed in any::<u64>(), n in 0usize..4, p in 1usize..3,
                                                 len in 1usize..400, ncols in 1usize..6, chunk in 1usize..90) {
        let noise = coloured_full_rank(seed, n, p);
        let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
        let x = Mat::<f64>::from_fn(len * p, ncols, |i, j| (((i * 13 + j * 7) as u64 ^ seed) % 19) as f64 - 9.0);
        let mut whole = Mat::<f64>::zeros(len * p, ncols);
        w.whiten_columns(x.as_ref(), whole.as_mut());
        let mut stream = w.column_stream(ncols);
        let mut got = Mat::<f64>::zeros(len * p, ncols);
        let mut t = 0;
        while t < len {
            let c = chunk.min(len - t);
            stream.push(x.as_ref().subrows(t * p, c * p), got.as_mut().subrows_mut(t * p, c * p)).unwrap();
            t += c;
        }
        let scale = whole.norm_max().max(1.0);
        prop_assert!((&whole - &got).norm_max() <= 1e-10 * scale, "{}", (&whole - &got).norm_max());
    }

    /// The adjoint satisfies ⟨W y, g⟩ = ⟨y, Wᵀ g⟩, and Wᵀ W r = (T·Tᵀ)⁻¹ r.
    #[test]
    fn prop_whitening_adjoint_gives_the_inverse_covariance(seed in any::<u64>(), n in 0usize..4, p in 1usize..3,
                                                           len in 1usize..40) {
        let noise = coloured_full_rank(seed, n, p);
        let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
        let y = random_signal(seed ^ 5, len, p);
        let g = random_signal(seed ^ 9, len, p);
        let mut wy = vec![0.0; len * p];
        w.whiten(y.as_slice(), &mut wy);
        let mut wtg = vec![0.0; len * p];
        w.whiten_adjoint(g.as_slice(), &mut wtg);
        let lhs: f64 = wy.iter().zip(g.as_slice()).map(|(a, b)| a * b).sum();
        let rhs: f64 = y.as_slice().iter().zip(&wtg).map(|(a, b)| a * b).sum();
        prop_assert!((lhs - rhs).abs() <= 1e-9 * (lhs.abs() + rhs.abs()).max(1.0), "{lhs} vs {rhs}");
        let mut back = vec![0.0; len * p];
        w.whiten_adjoint(&wy, &mut back);
        let t = noise.toeplitz_dense(len);
        let sigma = &t * t.transpose();
        let direct = sigma.lu().solve(&DVector::from_column_slice(y.as_slice())).unwrap();
        let got = DVector::from_vec(back);
        prop_assert!((&direct - &got).norm() <= 1e-8 * direct.norm().max(1e-12), "{}", (&direct - &got).norm());
    }
}

/// Dense reference of the innovations: ν_t = y_t − E[y_t | y_0 … y_(t−1)] for Gaussian y with
/// covariance Σ = T·Tᵀ, i.e. y_t − Σ_(t,past)·Σ_past⁻¹·y_past, solved afresh for every t.
fn dense_innovations(noise: &StateSpace, y: &[f64], len: usize) -> Vec<f64> {
    let p = noise.outputs();
    let t = noise.toeplitz_dense(len);
    let sigma = &t * t.transpose();
    let mut nu = y.to_vec();
    for k in 1..len {
        let past = k * p;
        let s_pp = sigma.view((0, 0), (past, past)).into_owned();
        let yp = DVector::from_column_slice(&y[..past]);
        let coef = s_pp.lu().solve(&yp).expect("Σ_past invertible");
        for c in 0..p {
            let row = sigma.view((past + c, 0), (1, past));
            nu[past + c] -= (row * &coef)[(0, 0)];
        }
    }
    nu
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Property: the unscaled innovations are the one-step prediction errors of y given its
    /// past (dense conditional expectation), and whitening is their normalisation by L_t⁻¹.
    #[test]
    fn prop_innovations_are_the_one_step_prediction_errors(
        seed in any::<u64>(), n in 0usize..=3, p in 1usize..=2, extra in 1usize..=2, len in 1usize..=30
    ) {
        let noise = coloured(seed, n, p + extra, p);
        let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
        let y = random_signal(seed ^ 0x77, len, p);
        let mut nu = vec![f64::NAN; len * p];
        w.innovations(y.as_slice(), &mut nu);
        let t = noise.toeplitz_dense(len);
        let tol = dense_tol(&(&t * t.transpose()));
        let reference = dense_innovations(&noise, y.as_slice(), len);
        let scale = reference.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        prop_assert!(max_abs_diff(&nu, &reference) <= tol * scale,
            "{} (tol {tol:e})", max_abs_diff(&nu, &reference));
        if p == 1 {
            // w_t = ν_t / √S_t with √S_t the diagonal of the Cholesky factor of T·Tᵀ.
            let l = dense_chol(&noise, len);
            let omega = whiten_vec(&w, y.as_slice());
            for k in 0..len {
                prop_assert!((omega[k] * l[(k, k)] - nu[k]).abs() <= tol * scale);
            }
        }
    }
}

#[test]
fn innovations_of_a_static_path_are_the_signal_and_of_an_invertible_path_the_noise() {
    // Static noise: nothing to predict from the past.
    let stat =
        StateSpace::static_gain(DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.3, 2.0])).unwrap();
    let w = KalmanWhitener::new(&stat, 5, &opts()).unwrap();
    let y = random_signal(3, 5, 2);
    let mut nu = vec![0.0; 10];
    w.innovations(y.as_slice(), &mut nu);
    assert_eq!(nu, y.as_slice());
    // Square invertible D: e is recovered from the past, so ν_t = D·e_t exactly. A small C
    // keeps the zeros (eigenvalues of A − B·D⁻¹·C) near the stable poles: minimum phase, so
    // the recovery is numerically stable.
    let s = random_stable_system(11, 3, 2, 2, 0.9);
    let mut d = s.d().clone();
    d[(0, 0)] += 2.0;
    d[(1, 1)] += 2.0;
    let sys = StateSpace::new(s.a().clone(), s.b().clone(), s.c() * 0.1, d).unwrap();
    let e = random_signal(4, 300, 2);
    let y = sys.simulate(&e).unwrap();
    let w = KalmanWhitener::new(&sys, 300, &opts()).unwrap();
    let mut nu = vec![0.0; 600];
    w.innovations(y.as_slice(), &mut nu);
    let d = sys.d();
    for k in 0..300 {
        for c in 0..2 {
            let expected = d[(c, 0)] * e.get(k, 0) + d[(c, 1)] * e.get(k, 1);
            assert!((nu[k * 2 + c] - expected).abs() < 1e-9, "{k} {c}");
        }
    }
}

/// The long-signal whitening and its adjoint (blocked steady part) equal the per-sample
/// recursions to 1e-12 relative, with and without a time-varying transient, MIMO included.
#[test]
fn whiten_long_and_adjoint_long_match_the_per_sample_recursions() {
    let len = 3001;
    for (seed, n, ne, p) in [(21, 4, 2, 1), (22, 3, 4, 2), (23, 5, 1, 1), (24, 2, 2, 2)] {
        let mut noise = coloured(seed, n, ne, p);
        if ne == p {
            // square D: no transient; a dominant D keeps the zeros inside the unit circle
            let mut d = noise.d().clone();
            for i in 0..p {
                d[(i, i)] += 10.0;
            }
            noise = StateSpace::new(noise.a().clone(), noise.b().clone(), noise.c().clone(), d)
                .unwrap();
        }
        let w = KalmanWhitener::new(&noise, len, &opts()).unwrap();
        assert_eq!(w.transient_len() == 0, ne == p);
        let y = random_signal(seed, len, p);
        let (mut a, mut b) = (vec![0.0; len * p], vec![0.0; len * p]);
        w.whiten(y.as_slice(), &mut a);
        w.whiten_long(y.as_slice(), &mut b);
        let scale = a.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        let err = max_abs_diff(&a, &b) / scale;
        assert!(err < 1e-12, "whiten, seed {seed}: {err:e}");
        w.whiten_adjoint(y.as_slice(), &mut a);
        w.whiten_adjoint_long(y.as_slice(), &mut b);
        let scale = a.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        let err = max_abs_diff(&a, &b) / scale;
        assert!(err < 1e-12, "adjoint, seed {seed}: {err:e}");
    }
}

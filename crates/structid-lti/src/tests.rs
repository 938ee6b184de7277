//! Unit and property tests of the crate.

use crate::testing::{random_signal, random_stable_system};
use crate::*;
use approx::assert_relative_eq;
use faer::{Accum, Mat};
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |a, &b| a.max(b.abs()))
}

fn assert_close(a: &[f64], b: &[f64], rel: f64) {
    assert_eq!(a.len(), b.len());
    let scale = max_abs(b).max(1.0);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= rel * scale,
            "index {i}: {x} vs {y} (scale {scale})"
        );
    }
}

fn scalar(v: f64) -> DMatrix<f64> {
    DMatrix::from_element(1, 1, v)
}

proptest! {
    #[test]
    fn prop_recursive_apply_equals_dense_toeplitz(
        seed in any::<u64>(), n in 0usize..=5, m in 1usize..=3, p in 1usize..=3, len in 1usize..=40
    ) {
        let sys = random_stable_system(seed, n, m, p, 0.95);
        let t = sys.toeplitz_dense(len);
        let u = random_signal(seed ^ 1, len, m);
        let mut y = vec![0.0; len * p];
        sys.apply(u.as_slice(), &mut y);
        let y_ref = &t * DVector::from_column_slice(u.as_slice());
        assert_close(&y, y_ref.as_slice(), 1e-12);

        let w = random_signal(seed ^ 2, len, p);
        let mut v = vec![0.0; len * m];
        sys.apply_adjoint(w.as_slice(), &mut v);
        let v_ref = t.transpose() * DVector::from_column_slice(w.as_slice());
        assert_close(&v, v_ref.as_slice(), 1e-12);
    }

    #[test]
    fn prop_adjoint_identity(
        seed in any::<u64>(), n in 0usize..=6, m in 1usize..=3, p in 1usize..=3, len in 1usize..=60
    ) {
        let sys = random_stable_system(seed, n, m, p, 0.98);
        let x = random_signal(seed ^ 3, len, m);
        let y = random_signal(seed ^ 4, len, p);
        let mut tx = vec![0.0; len * p];
        let mut tty = vec![0.0; len * m];
        sys.apply(x.as_slice(), &mut tx);
        sys.apply_adjoint(y.as_slice(), &mut tty);
        let lhs: f64 = tx.iter().zip(y.as_slice()).map(|(a, b)| a * b).sum();
        let rhs: f64 = x.as_slice().iter().zip(&tty).map(|(a, b)| a * b).sum();
        let scale = 1.0 + max_abs(&tx) * max_abs(y.as_slice()) * (len * p) as f64;
        prop_assert!((lhs - rhs).abs() <= 1e-12 * scale, "{} vs {}", lhs, rhs);
    }
}

/// Reference: column-by-column `apply` (or `apply_adjoint`).
fn reference_columns(
    sys: &StateSpace,
    x: &Mat<f64>,
    out0: &Mat<f64>,
    accum: Accum,
    alpha: f64,
    adjoint: bool,
) -> Mat<f64> {
    let mut out = out0.clone();
    let mut u = vec![0.0; x.nrows()];
    let mut y = vec![0.0; out.nrows()];
    for j in 0..x.ncols() {
        for i in 0..x.nrows() {
            u[i] = x[(i, j)];
        }
        if adjoint {
            sys.apply_adjoint(&u, &mut y);
        } else {
            sys.apply(&u, &mut y);
        }
        for i in 0..out.nrows() {
            out[(i, j)] = match accum {
                Accum::Replace => alpha * y[i],
                Accum::Add => out[(i, j)] + alpha * y[i],
            };
        }
    }
    out
}

fn assert_mat_close(a: &Mat<f64>, b: &Mat<f64>, rel: f64) {
    assert_eq!((a.nrows(), a.ncols()), (b.nrows(), b.ncols()));
    let mut scale: f64 = 1.0;
    for j in 0..b.ncols() {
        for i in 0..b.nrows() {
            scale = scale.max(b[(i, j)].abs());
        }
    }
    for j in 0..b.ncols() {
        for i in 0..b.nrows() {
            assert!(
                (a[(i, j)] - b[(i, j)]).abs() <= rel * scale,
                "({i}, {j}): {} vs {}",
                a[(i, j)],
                b[(i, j)]
            );
        }
    }
}

fn check_columns(
    sys: &StateSpace,
    len: usize,
    ncols: usize,
    seed: u64,
    transposed: bool,
    add: bool,
    alpha: f64,
) {
    let (m, p) = (sys.inputs(), sys.outputs());
    let accum = if add { Accum::Add } else { Accum::Replace };
    for adjoint in [false, true] {
        let (rin, rout) = if adjoint {
            (len * p, len * m)
        } else {
            (len * m, len * p)
        };
        let xs = random_signal(seed, rin, ncols); // row-major rin x ncols data
        let x_cm = Mat::from_fn(rin, ncols, |i, j| xs.get(i, j));
        // the same matrix stored transposed: x = xt^T
        let xt = Mat::from_fn(ncols, rin, |j, i| xs.get(i, j));
        let os = random_signal(seed ^ 99, rout, ncols);
        let out0 = Mat::from_fn(rout, ncols, |i, j| os.get(i, j));
        let expect = reference_columns(sys, &x_cm, &out0, accum, alpha, adjoint);
        let mut out = out0.clone();
        let xv = if transposed {
            xt.as_ref().transpose()
        } else {
            x_cm.as_ref()
        };
        if adjoint {
            sys.apply_adjoint_columns(xv, out.as_mut(), accum, alpha);
        } else {
            sys.apply_columns(xv, out.as_mut(), accum, alpha);
        }
        assert_mat_close(&out, &expect, 1e-11);
        // also against the trait's default (column loop) implementation
        struct Plain<'a>(&'a StateSpace);
        impl LinearSystem for Plain<'_> {
            fn inputs(&self) -> usize {
                self.0.inputs()
            }
            fn outputs(&self) -> usize {
                self.0.outputs()
            }
            fn order(&self) -> usize {
                self.0.order()
            }
            fn apply(&self, u: &[f64], y: &mut [f64]) {
                self.0.apply(u, y)
            }
            fn apply_adjoint(&self, y: &[f64], u: &mut [f64]) {
                self.0.apply_adjoint(y, u)
            }
        }
        let mut out2 = out0.clone();
        if adjoint {
            Plain(sys).apply_adjoint_columns(xv, out2.as_mut(), accum, alpha);
        } else {
            Plain(sys).apply_columns(xv, out2.as_mut(), accum, alpha);
        }
        assert_mat_close(&out2, &expect, 1e-13);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn prop_apply_columns_matches_apply(
        seed in any::<u64>(), n in 0usize..=5, m in 1usize..=3, p in 1usize..=3,
        len in 1usize..=110, ncols in 1usize..=300, transposed in any::<bool>(),
        add in any::<bool>(), alpha in -2.0f64..2.0
    ) {
        let sys = random_stable_system(seed, n, m, p, 0.95);
        check_columns(&sys, len, ncols, seed ^ 5, transposed, add, alpha);
    }
}

#[test]
fn apply_columns_edge_shapes() {
    // block boundaries, long horizon, wide matrices (exercises the thread split)
    let sys = random_stable_system(11, 4, 1, 1, 0.99);
    for &(len, ncols) in &[(32, 7), (33, 600), (64, 257), (200, 3), (1, 1)] {
        check_columns(&sys, len, ncols, 3, true, false, 1.0);
        check_columns(&sys, len, ncols, 4, false, true, -0.5);
    }
    // static gain, no inputs, no outputs
    let g =
        StateSpace::static_gain(DMatrix::from_row_slice(2, 3, &[1., 2., 3., 4., 5., 6.])).unwrap();
    check_columns(&g, 17, 300, 5, true, true, 0.7);
    let no_in = random_stable_system(3, 2, 0, 2, 0.9);
    check_columns(&no_in, 9, 4, 6, false, false, 1.0);
    check_columns(&no_in, 9, 4, 6, false, true, 1.0);
    let no_out = random_stable_system(3, 2, 2, 0, 0.9);
    check_columns(&no_out, 9, 4, 6, true, false, 1.0);
    check_columns(&no_out, 9, 4, 6, true, true, 1.0);
    // several wide column chunks of a transposed (row-major) operand
    check_columns(&sys, 40, 2100, 8, true, true, 0.3);
    // zero columns
    let mut out = Mat::<f64>::zeros(10, 0);
    sys.apply_columns(
        Mat::<f64>::zeros(10, 0).as_ref(),
        out.as_mut(),
        Accum::Replace,
        1.0,
    );
}

#[test]
fn simulate_from_is_forced_plus_free_response() {
    let sys = random_stable_system(21, 3, 2, 2, 0.9);
    let u = random_signal(1, 25, 2);
    let x0 = [0.3, -1.0, 2.0];
    let (y, x_end) = sys.simulate_from(&x0, &u).unwrap();
    let forced = sys.simulate(&u).unwrap();
    let x0v = DVector::from_column_slice(&x0);
    let mut ak = DMatrix::identity(3, 3);
    for k in 0..25 {
        let free = sys.c() * &ak * &x0v;
        for c in 0..2 {
            assert_relative_eq!(y.get(k, c), forced.get(k, c) + free[c], epsilon = 1e-12);
        }
        ak = sys.a() * ak;
    }
    let (y2, xs) = sys.simulate_states(&x0, &u).unwrap();
    assert_eq!(y, y2);
    assert_eq!(xs.channels(), 3);
    assert_eq!(xs.sample(0), &x0);
    // x_L = A x_{L-1} + B u_{L-1}
    let xl = sys.a() * DVector::from_column_slice(xs.sample(24))
        + sys.b() * DVector::from_column_slice(u.sample(24));
    for i in 0..3 {
        assert_relative_eq!(x_end[i], xl[i], epsilon = 1e-12);
    }
    assert!(sys.simulate_from(&[0.0; 2], &u).is_err());
    assert!(sys.simulate_from(&[f64::NAN, 0.0, 0.0], &u).is_err());
    assert!(sys.simulate_states(&x0, &Signal::zeros(3, 1)).is_err());
}

#[test]
fn constructor_rejects_bad_dims_and_nan() {
    let ok = || {
        (
            DMatrix::<f64>::identity(2, 2) * 0.5,
            DMatrix::<f64>::zeros(2, 1),
            DMatrix::<f64>::zeros(1, 2),
            DMatrix::<f64>::zeros(1, 1),
        )
    };
    let (a, b, c, d) = ok();
    assert!(StateSpace::new(a, b, c, d).is_ok());
    let (_, b, c, d) = ok();
    assert!(matches!(
        StateSpace::new(DMatrix::zeros(2, 3), b, c, d),
        Err(LtiError::DimensionMismatch { .. })
    ));
    let (a, _, c, d) = ok();
    assert!(StateSpace::new(a, DMatrix::zeros(3, 1), c, d).is_err());
    let (a, b, _, d) = ok();
    assert!(StateSpace::new(a, b, DMatrix::zeros(1, 3), d).is_err());
    let (a, b, c, _) = ok();
    assert!(StateSpace::new(a, b, c, DMatrix::zeros(2, 1)).is_err());
    let (mut a, b, c, d) = ok();
    a[(1, 0)] = f64::NAN;
    let err = StateSpace::new(a, b, c, d).unwrap_err();
    assert!(matches!(
        err,
        LtiError::NonFiniteMatrix { row: 1, col: 0, .. }
    ));
    assert!(err.to_string().contains("matrix A"));
    assert!(StateSpace::static_gain(scalar(f64::INFINITY)).is_err());
    let (a, b, c, d) = ok();
    let s = StateSpace::new(a, b, c, d).unwrap();
    assert!(s.clone().with_sample_time(0.0).is_err());
    assert!(s.clone().with_sample_time(f64::NAN).is_err());
    assert_eq!(s.with_sample_time(0.01).unwrap().sample_time(), Some(0.01));
}

#[test]
fn static_gain_applies_d_per_sample() {
    let d = DMatrix::from_row_slice(2, 3, &[1., 2., 3., -1., 0., 0.5]);
    let g = StateSpace::static_gain(d.clone()).unwrap();
    assert_eq!((g.order(), g.inputs(), g.outputs()), (0, 3, 2));
    assert_eq!(g.spectral_radius(), 0.0);
    assert!(g.is_stable());
    let u = random_signal(8, 10, 3);
    let y = g.simulate(&u).unwrap();
    for k in 0..10 {
        let yk = &d * DVector::from_column_slice(u.sample(k));
        assert_close(y.sample(k), yk.as_slice(), 1e-15);
    }
    let mut back = vec![0.0; 30];
    g.apply_adjoint(y.as_slice(), &mut back);
    for k in 0..10 {
        let uk = d.transpose() * DVector::from_column_slice(y.sample(k));
        assert_close(&back[k * 3..k * 3 + 3], uk.as_slice(), 1e-15);
    }
}

#[test]
fn simulate_checks_input() {
    let sys = random_stable_system(2, 2, 2, 1, 0.5);
    assert!(matches!(
        sys.simulate(&Signal::zeros(5, 1)),
        Err(LtiError::DimensionMismatch { .. })
    ));
    let mut u = Signal::zeros(5, 2);
    u.sample_mut(3)[0] = f64::INFINITY;
    assert!(matches!(
        sys.simulate(&u),
        Err(LtiError::NonFinite {
            sample: 3,
            channel: 0,
            ..
        })
    ));
    // a system without inputs still produces L samples
    let free = random_stable_system(2, 2, 0, 1, 0.5);
    let y = free.simulate(&Signal::zeros(6, 0)).unwrap();
    assert_eq!(y.len(), 6);
    assert!(y.as_slice().iter().all(|&v| v == 0.0));
}

#[test]
fn markov_parameters_equal_impulse_response() {
    let sys = random_stable_system(5, 3, 2, 2, 0.9);
    let len = 12;
    let h = sys.markov_parameters(len);
    assert_eq!(h.len(), len);
    assert!(sys.markov_parameters(0).is_empty());
    for input in 0..2 {
        let u = Signal::from_fn(len, 2, |k, c| if k == 0 && c == input { 1.0 } else { 0.0 });
        let y = sys.simulate(&u).unwrap();
        for k in 0..len {
            for out in 0..2 {
                assert_relative_eq!(y.get(k, out), h[k][(out, input)], epsilon = 1e-13);
            }
        }
    }
}

#[test]
fn random_stable_system_respects_radius() {
    for seed in 0..20 {
        let s = random_stable_system(seed, 5, 1, 1, 0.8);
        let r = s.spectral_radius();
        assert!((0.39..=0.8 + 1e-10).contains(&r), "radius {r}");
        assert!(s.is_stable());
    }
    assert_eq!(
        random_stable_system(3, 4, 2, 2, 0.9),
        random_stable_system(3, 4, 2, 2, 0.9)
    );
}

#[test]
fn select_inputs_outputs_and_series() {
    let sys = random_stable_system(9, 3, 3, 2, 0.9)
        .with_sample_time(0.5)
        .unwrap();
    let s1 = sys.select_inputs(&[2, 0]).unwrap();
    assert_eq!(s1.inputs(), 2);
    assert_eq!(s1.b().column(0), sys.b().column(2));
    assert_eq!(s1.sample_time(), Some(0.5));
    assert!(sys.select_inputs(&[3]).is_err());
    let s2 = sys.select_outputs(&[1]).unwrap();
    assert_eq!(s2.c().row(0), sys.c().row(1));
    assert!(sys.select_outputs(&[2]).is_err());

    let g1 = random_stable_system(1, 2, 2, 3, 0.9);
    let g2 = random_stable_system(2, 3, 3, 2, 0.9);
    let ser = g2.series(&g1).unwrap();
    assert_eq!((ser.order(), ser.inputs(), ser.outputs()), (5, 2, 2));
    let u = random_signal(4, 30, 2);
    let y_ref = g2.simulate(&g1.simulate(&u).unwrap()).unwrap();
    let y = ser.simulate(&u).unwrap();
    assert_close(y.as_slice(), y_ref.as_slice(), 1e-12);
    assert!(g1.series(&g1).is_err());
    let a = g1.clone().with_sample_time(0.1).unwrap();
    let b = g2.clone().with_sample_time(0.2).unwrap();
    assert!(b.series(&a).is_err());
}

#[test]
fn zoh_scalar_closed_form() {
    let (a, b, ts) = (1.7, 0.6, 0.05);
    let sys = ContinuousStateSpace::new(scalar(-a), scalar(b), scalar(1.0), scalar(0.0)).unwrap();
    let d = sys.discretize_zoh(ts).unwrap();
    assert_relative_eq!(d.a()[(0, 0)], (-a * ts).exp(), epsilon = 1e-14);
    assert_relative_eq!(
        d.b()[(0, 0)],
        b * (1.0 - (-a * ts).exp()) / a,
        epsilon = 1e-14
    );
    assert_eq!(d.sample_time(), Some(ts));
    assert!(sys.discretize_zoh(-1.0).is_err());
    assert!(sys.discretize_zoh(f64::INFINITY).is_err());
}

#[test]
fn zoh_double_integrator_closed_form() {
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]);
    let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
    let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
    let sys = ContinuousStateSpace::new(a, b, c, DMatrix::zeros(1, 1)).unwrap();
    for ts in [0.01, 0.3, 2.0] {
        let d = sys.discretize_zoh(ts).unwrap();
        let ad = DMatrix::from_row_slice(2, 2, &[1.0, ts, 0.0, 1.0]);
        let bd = DMatrix::from_row_slice(2, 1, &[ts * ts / 2.0, ts]);
        assert_relative_eq!(d.a(), &ad, epsilon = 1e-13);
        assert_relative_eq!(d.b(), &bd, epsilon = 1e-13);
        assert_eq!(d.c(), sys.c());
    }
    // static continuous system
    let g = ContinuousStateSpace::new(
        DMatrix::zeros(0, 0),
        DMatrix::zeros(0, 2),
        DMatrix::zeros(1, 0),
        DMatrix::from_row_slice(1, 2, &[1.0, 2.0]),
    )
    .unwrap();
    assert_eq!(g.discretize_zoh(0.1).unwrap().order(), 0);
    assert!(
        ContinuousStateSpace::new(scalar(f64::NAN), scalar(1.0), scalar(1.0), scalar(0.0)).is_err()
    );
}

/// Long division of num / den (both in q^-1).
fn long_division(num: &[f64], den: &[f64], count: usize) -> Vec<f64> {
    let mut h = vec![0.0; count];
    for k in 0..count {
        let mut v = num.get(k).copied().unwrap_or(0.0);
        for j in 1..=k {
            v -= den.get(j).copied().unwrap_or(0.0) * h[k - j];
        }
        h[k] = v / den[0];
    }
    h
}

#[test]
fn tf_realisation_matches_long_division() {
    let cases: Vec<(Vec<f64>, Vec<f64>)> = vec![
        (vec![1.0], vec![1.0, -0.5]),
        (vec![0.0, 1.0, 0.5], vec![2.0, -1.0, 0.3]),
        (vec![0.3, -0.2, 0.1, 0.05], vec![1.0, 0.4]),
        (vec![2.0], vec![4.0]),
        (vec![], vec![1.0, 0.1]),
        (vec![1.0, 0.0, 0.0], vec![1.0, -0.9, 0.2, 0.0, 0.0]),
    ];
    for (num, den) in cases {
        let ss = TransferFunction::siso(num.clone(), den.clone())
            .unwrap()
            .to_state_space();
        let h = ss.markov_parameters(20);
        let h_ref = long_division(&num, &den, 20);
        for k in 0..20 {
            assert_relative_eq!(h[k][(0, 0)], h_ref[k], epsilon = 1e-13);
        }
    }
    assert_eq!(
        TransferFunction::siso(vec![1.0, 0.0, 0.0], vec![1.0, -0.9, 0.2, 0.0])
            .unwrap()
            .to_state_space()
            .order(),
        2
    );
}

#[test]
fn tf_paper_example_row() {
    let tf = TransferFunction::new(vec![vec![
        Siso {
            num: vec![1.0],
            den: vec![1.0],
        },
        Siso {
            num: vec![0.0, 0.0, 1.0],
            den: vec![1.0],
        },
    ]])
    .unwrap();
    let ss = tf.to_state_space();
    assert_eq!((ss.order(), ss.inputs(), ss.outputs()), (2, 2, 1));
    // y_k = u1_k + u2_{k-2}
    let u = random_signal(3, 12, 2);
    let y = ss.simulate(&u).unwrap();
    for k in 0..12 {
        let expect = u.get(k, 0) + if k >= 2 { u.get(k - 2, 1) } else { 0.0 };
        assert_relative_eq!(y.get(k, 0), expect, epsilon = 1e-15);
    }
}

#[test]
fn tf_mimo_and_validation() {
    let e = |num: Vec<f64>, den: Vec<f64>| Siso { num, den };
    let tf = TransferFunction::new(vec![
        vec![e(vec![1.0], vec![1.0, -0.5]), e(vec![0.0, 1.0], vec![1.0])],
        vec![
            e(vec![0.5, 0.5], vec![1.0]),
            e(vec![1.0], vec![1.0, 0.2, 0.1]),
        ],
    ])
    .unwrap()
    .with_sample_time(0.1)
    .unwrap();
    let ss = tf.to_state_space();
    assert_eq!(ss.sample_time(), Some(0.1));
    assert_eq!((ss.inputs(), ss.outputs()), (2, 2));
    let h = ss.markov_parameters(10);
    for (i, row) in tf.entries().iter().enumerate() {
        for (j, s) in row.iter().enumerate() {
            let r = long_division(&s.num, &s.den, 10);
            for k in 0..10 {
                assert_relative_eq!(h[k][(i, j)], r[k], epsilon = 1e-13);
            }
        }
    }
    assert!(TransferFunction::siso(vec![1.0], vec![0.0, 1.0]).is_err());
    assert!(TransferFunction::siso(vec![1.0], vec![]).is_err());
    assert!(TransferFunction::siso(vec![f64::NAN], vec![1.0]).is_err());
    assert!(TransferFunction::new(vec![]).is_err());
    assert!(matches!(
        TransferFunction::new(vec![vec![e(vec![1.0], vec![1.0])], vec![]]),
        Err(LtiError::InvalidTransferFunction(_))
    ));
}

/// Found by the `lft_problem` fuzz target: finite but huge entries overflow the Krylov basis
/// B, AB, …; the SVD then panicked on NaN singular values. The radius is NaN instead.
#[test]
fn reachable_spectral_radius_of_an_overflowing_system_is_nan_not_a_panic() {
    let huge = DMatrix::from_element(2, 2, 1e300);
    let s = StateSpace::new(
        huge.clone(),
        DMatrix::from_element(2, 1, 1e300),
        DMatrix::from_element(1, 2, 1.0),
        scalar(0.0),
    )
    .unwrap();
    assert!(s.reachable_spectral_radius().is_nan());
    let _ = s.spectral_radius();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    /// The in-place operator equals `apply_columns` / `apply_adjoint_columns` into a separate
    /// matrix, for square MIMO systems (n = 0 included), column- and row-major operands and
    /// enough columns to be split across threads.
    #[test]
    fn prop_in_place_equals_out_of_place(
        seed in any::<u64>(), n in 0usize..=5, m in 1usize..=2, len in 1usize..=90,
        ncols in 1usize..=140, transposed in any::<bool>(), adjoint in any::<bool>()
    ) {
        let sys = random_stable_system(seed, n, m, m, 0.95);
        let x = Mat::<f64>::from_fn(len * m, ncols, |i, j| {
            (((i * 31 + j * 17) as u64 ^ seed) % 23) as f64 - 11.0
        });
        let mut want = Mat::<f64>::zeros(len * m, ncols);
        if adjoint {
            sys.apply_adjoint_columns(x.as_ref(), want.as_mut(), Accum::Replace, 1.0);
        } else {
            sys.apply_columns(x.as_ref(), want.as_mut(), Accum::Replace, 1.0);
        }
        let got = if transposed {
            let mut xt = x.transpose().to_owned();
            sys.apply_columns_in_place(xt.as_mut().transpose_mut(), adjoint);
            xt.transpose().to_owned()
        } else {
            let mut y = x.clone();
            sys.apply_columns_in_place(y.as_mut(), adjoint);
            y
        };
        let scale = want.norm_max().max(1.0);
        prop_assert!((&want - &got).norm_max() <= 1e-12 * scale);
    }
}

//! Kalman whitening of a coloured-noise path.
//!
//! # Problem
//! The identification cost contains the noise term `r^T (T T^T)^{-1} r`, where `T` is the
//! block lower-triangular Toeplitz operator of the *noise path*
//!
//! ```text
//! x_{t+1} = A x_t + B e_t,      y_t = C x_t + D e_t,      x_0 = 0 (known),
//! ```
//!
//! driven by white noise `e` of unit covariance (`ne` channels, `p` outputs). A *whitening
//! operator* `W` satisfies `W^T W = (T T^T)^{-1}`; then `r^T (T T^T)^{-1} r = |W r|^2`.
//! [`KalmanWhitener`] applies the lower-triangular `W` (with positive diagonal, i.e. the
//! inverse of the Cholesky factor of `T T^T`) by recursion, in `O(L (n^2 + n p + p^2))`
//! operations per signal and without forming `T`.
//!
//! # Recursion (time-varying Kalman filter, `P_0 = 0`)
//! Process and measurement noise are correlated (both come from `e`): `Q = B B^T`,
//! `R = D D^T`, `N = B D^T`. With `x^_0 = 0`, `P_0 = 0` and, for `t = 0 .. L-1`,
//!
//! ```text
//! S_t = C P_t C^T + R = L_t L_t^T          (innovation covariance and its Cholesky factor)
//! K_t = (A P_t C^T + N) S_t^{-1}
//! nu_t = y_t - C x^_t,   w_t = L_t^{-1} nu_t  (innovation, whitened output)
//! x^_{t+1} = A x^_t + K_t nu_t
//! P_{t+1} = (A - K_t C) P_t (A - K_t C)^T + (B - K_t D)(B - K_t D)^T
//! ```
//!
//! (the covariance update is the Joseph form of `A P A^T + Q - K S K^T`: a sum of two
//! positive semi-definite terms, so `P_t` stays symmetric positive semi-definite under
//! rounding). The innovations are white with covariances `S_t`, hence
//! `sum_t |w_t|^2 = sum_t nu_t^T S_t^{-1} nu_t = y^T (T T^T)^{-1} y` and
//! `log det (T T^T) = sum_t log det S_t`.
//!
//! # Steady state
//! The Riccati recursion converges (for the usual detectability conditions); once
//! `|P_t - P_{t-1}|_F <= tol (|P_{t-1}|_F + |B B^T|_F)` the gains are frozen and the filter
//! becomes the LTI system ([`steady_state_whitening_filter`])
//!
//! ```text
//! x^+ = (A - K C) x^ + K y,      w = -L^{-1} C x^ + L^{-1} y,
//! ```
//!
//! which [`KalmanWhitener::whiten_columns`] applies with the blocked many-column engine of
//! [`LinearSystem::apply_columns`](crate::LinearSystem::apply_columns), started from the
//! state reached at the end of the time-varying part.
//!
//! When `D` is square (as many noise channels as outputs) and invertible, the noise `e_t`
//! is recovered exactly from `y_0 .. y_t` (the initial state is known), so `P_t = 0` for
//! all `t`, the gains are constant from the start and `W = T^{-1}`. If the noise model then
//! has zeros outside the unit circle (non-minimum phase), `W` is an *unstable* filter: this
//! is the exact `(T T^T)^{-1}` of the model, whose entries grow exponentially with the
//! record length, not a defect of the recursion.

use crate::error::LtiError;
use crate::operator::par_columns;
use crate::riccati::{CholeskyGain, Overflow, Riccati, row_major};
use crate::state_space::StateSpace;
use faer::prelude::ReborrowMut;
use faer::{Accum, MatMut, MatRef};
use nalgebra::DMatrix;

/// Settings of [`KalmanWhitener::new`] (a plain struct; start from `Default::default()`).
#[derive(Clone, Debug, PartialEq)]
pub struct WhiteningOptions {
    /// Relative tolerance of the steady-state test
    /// `|P_t - P_{t-1}|_F <= tol (|P_{t-1}|_F + |B B^T|_F)` (default `1e-13`). Also the
    /// convergence tolerance of the algebraic Riccati equation solver.
    pub steady_state_tol: f64,
    /// `false` (default): the exact time-varying filter until the gains converge.
    /// `true`: use the steady-state (algebraic Riccati) gains from the first sample on;
    /// cheaper to set up, but only *approximately* `W` over the first samples (the
    /// difference decays like the transient of the Riccati recursion).
    pub steady_state_only: bool,
    /// Cap on the number of stored time-varying gains (default `100_000`). If the Riccati
    /// recursion has not converged after this many samples, the gains at that sample are
    /// frozen for the rest of the record (then [`KalmanWhitener::is_exact`] is `false`).
    pub max_transient: usize,
}

impl Default for WhiteningOptions {
    fn default() -> Self {
        WhiteningOptions {
            steady_state_tol: 1e-13,
            steady_state_only: false,
            max_transient: 100_000,
        }
    }
}

/// The whitening operator `W` (`W^T W = (T T^T)^{-1}`, `W` lower triangular with positive
/// diagonal) of a noise path over a fixed record length, applied by a time-varying Kalman
/// filter that turns into an LTI filter once the Riccati recursion has converged.
///
/// See the [module documentation](self) for the recursion.
#[derive(Clone)]
pub struct KalmanWhitener {
    /// record length `L`
    len: usize,
    /// noise state dimension
    n: usize,
    /// outputs
    p: usize,
    /// samples handled by the stored time-varying gains
    transient: usize,
    /// `G_t = K_t L_t` (`n x p`, row-major) for `t < transient`, concatenated
    gains: Vec<f64>,
    /// `L_t^{-1}` (lower triangle packed by rows, `p (p + 1) / 2` values) for `t < transient`
    linv: Vec<f64>,
    /// row-major `A` (`n x n`)
    a: Vec<f64>,
    /// row-major `C` (`p x n`)
    c: Vec<f64>,
    /// the LTI filter used from sample `transient` on
    steady: StateSpace,
    /// `sum_t log det S_t`
    log_det: f64,
    /// the Riccati recursion converged (or the record ended) before the gains were frozen
    exact: bool,
}

impl std::fmt::Debug for KalmanWhitener {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // the stored gains can be long: summarise
        f.debug_struct("KalmanWhitener")
            .field("len", &self.len)
            .field("order", &self.n)
            .field("outputs", &self.p)
            .field("transient_len", &self.transient)
            .field("exact", &self.exact)
            .field("log_det", &self.log_det)
            .field("steady_state_filter", &self.steady)
            .finish()
    }
}

/// What the per-sample recursion writes out: the whitened outputs `w_t` or the innovations
/// `nu_t`.
#[derive(Clone, Copy, PartialEq)]
enum Output {
    Whitened,
    Innovations,
}

/// Steady samples below which the long-signal methods use the per-sample recursion.
const LONG_MIN: usize = 256;

/// One time-major signal as a one-column matrix.
fn column(y: &[f64]) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(y, y.len(), 1)
}

/// [`column`] of a mutable signal.
fn column_mut(y: &mut [f64]) -> MatMut<'_, f64> {
    MatMut::from_column_major_slice_mut(y, y.len(), 1)
}

/// Appends `G` (row-major) to `gains` and the lower triangle of `L^{-1}` (packed by rows)
/// to `packed`: the layout of the stored gains.
fn push_gains(g: &DMatrix<f64>, linv: &DMatrix<f64>, gains: &mut Vec<f64>, packed: &mut Vec<f64>) {
    gains.extend(row_major(g));
    packed.extend((0..linv.nrows()).flat_map(|r| (0..=r).map(move |k| linv[(r, k)])));
}

/// The LTI filter `y -> w` with the gains `g`:
/// `x^+ = (A - K C) x^ + K y`, `w = -L^{-1} C x^ + L^{-1} y`.
fn steady_filter(sys: &StateSpace, g: &CholeskyGain) -> Result<StateSpace, LtiError> {
    let (a, c) = (sys.a(), sys.c());
    let lc = &g.linv * c;
    StateSpace::new(a - &g.k * c, g.k.clone(), -lc, g.linv.clone())
}

fn check_tol(tol: f64) -> Result<(), LtiError> {
    if tol.is_finite() && tol >= 0.0 {
        Ok(())
    } else {
        Err(LtiError::param(
            "steady_state_tol",
            format!("must be finite and non-negative, got {tol}"),
        ))
    }
}

/// The steady-state whitening filter `y -> w` of a noise path: the LTI system
/// `x^+ = (A - K C) x^ + K y`, `w = -L^{-1} C x^ + L^{-1} y` with the gains of the
/// algebraic Riccati equation (the limit of the time-varying Kalman filter started from
/// `P_0 = 0`; see the [module documentation](self)). It has the noise path's order and
/// `p` inputs and outputs.
///
/// Applied to a whole record from zero state it is only an approximation of the exact
/// whitening operator (see [`KalmanWhitener`]) over the first samples.
///
/// Errors: [`LtiError::InvalidParameter`] when `D D^T` is singular (some output without
/// noise of its own) or when the Riccati equation cannot be solved (see the message).
///
/// ```
/// use nalgebra::DMatrix;
/// use structid_lti::kalman::steady_state_whitening_filter;
/// // white noise with standard deviation 2: the whitening filter is the gain 1/2
/// let noise = structid_lti::StateSpace::static_gain(DMatrix::from_element(1, 1, 2.0)).unwrap();
/// let f = steady_state_whitening_filter(&noise).unwrap();
/// assert_eq!(f.order(), 0);
/// assert!((f.d()[(0, 0)] - 0.5).abs() < 1e-15);
/// ```
pub fn steady_state_whitening_filter(noise: &StateSpace) -> Result<StateSpace, LtiError> {
    let tol = WhiteningOptions::default().steady_state_tol;
    let eq = Riccati::new(noise, None);
    let p = eq.dare(tol)?;
    let g = eq
        .cholesky_gain(&p)
        .map_err(|s| s.into_error("(steady state)"))?;
    steady_filter(noise, &g)
}

impl KalmanWhitener {
    /// Builds the whitener of the noise path `noise` (`e -> y`, `ne` noise inputs, `p`
    /// outputs, `n` states) for records of `len` samples: runs the Riccati recursion,
    /// stores the time-varying gains until they converge (or until
    /// `opts.max_transient` samples), then the steady-state filter.
    ///
    /// Cost: `O(t_conv (n^3 + n^2 ne + p^3))` time and `O(t_conv (n p + p^2))` memory,
    /// where `t_conv <= min(len, max_transient)` is [`transient_len`](Self::transient_len).
    ///
    /// Errors:
    /// - [`LtiError::InvalidParameter`] (`noise`) when an innovation covariance `S_t` is
    ///   singular, i.e. `T T^T` is not invertible; in practice when `D D^T` is singular
    ///   (the message names the output channel and sample), or when the recursion
    ///   overflows;
    /// - [`LtiError::InvalidParameter`] (`steady_state_tol`) for a negative or non-finite
    ///   tolerance;
    /// - [`LtiError::DimensionMismatch`] when `len * p` overflows `usize`.
    ///
    /// ```
    /// use nalgebra::{DMatrix, DVector};
    /// use structid_lti::kalman::{KalmanWhitener, WhiteningOptions};
    /// use structid_lti::StateSpace;
    /// // AR(1) noise plus white measurement noise:
    /// // x+ = 0.9 x + e1,  y = x + 0.5 e2
    /// let noise = StateSpace::new(
    ///     DMatrix::from_element(1, 1, 0.9),
    ///     DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::from_row_slice(1, 2, &[0.0, 0.5]),
    /// )
    /// .unwrap();
    /// let len = 200;
    /// let w = KalmanWhitener::new(&noise, len, &WhiteningOptions::default()).unwrap();
    /// assert!(w.transient_len() < len); // the gains converged
    ///
    /// let r: Vec<f64> = (0..len).map(|k| (0.1 * k as f64).sin()).collect();
    /// let mut omega = vec![0.0; len];
    /// w.whiten(&r, &mut omega);
    ///
    /// // dense reference: r^T (T T^T)^{-1} r and log det (T T^T)
    /// let t = noise.toeplitz_dense(len);
    /// let chol = (&t * t.transpose()).cholesky().unwrap();
    /// let z = chol.l().solve_lower_triangular(&DVector::from_vec(r)).unwrap();
    /// let quad: f64 = omega.iter().map(|v| v * v).sum();
    /// assert!((quad - z.norm_squared()).abs() <= 1e-9 * quad);
    /// let log_det = 2.0 * chol.l().diagonal().map(f64::ln).sum();
    /// assert!((w.log_det() - log_det).abs() <= 1e-9 * log_det.abs());
    /// ```
    pub fn new(noise: &StateSpace, len: usize, opts: &WhiteningOptions) -> Result<Self, LtiError> {
        check_tol(opts.steady_state_tol)?;
        let (n, p) = (noise.order(), noise.outputs());
        if len.checked_mul(p).is_none() {
            return Err(LtiError::dims(
                "whitening record length",
                format!("len * outputs to fit in usize ({p} outputs)"),
                format!("{len} samples"),
            ));
        }
        let eq = Riccati::new(noise, None);
        let mut gains_v = Vec::new();
        let mut linv_v = Vec::new();
        let mut log_det = 0.0;
        let (transient, steady_gains, exact) = if opts.steady_state_only {
            let pinf = eq.dare(opts.steady_state_tol)?;
            let g = eq
                .cholesky_gain(&pinf)
                .map_err(|s| s.into_error("(steady state)"))?;
            (0, g, false)
        } else {
            let cap = len.min(opts.max_transient);
            let mut rec = eq.recursion(DMatrix::zeros(n, n), Some(opts.steady_state_tol));
            let (mut transient, mut exact) = (cap, cap == len);
            for t in 0..cap {
                let g = eq
                    .cholesky_gain(rec.covariance())
                    .map_err(|s| s.into_error(&format!("at sample {t}")))?;
                let steady = rec.advance(&g.k).map_err(|Overflow| {
                    LtiError::param(
                        "noise",
                        format!(
                            "the Riccati recursion overflowed at sample {t}: the noise model is \
                             unstable in a direction the outputs do not observe"
                        ),
                    )
                })?;
                if steady {
                    // the gains of step t equal those of P_{t+1} to within the tolerance:
                    // the steady state starts at t, with the gains of P_{t+1}
                    (transient, exact) = (t, true);
                    break;
                }
                push_gains(&g.g, &g.linv, &mut gains_v, &mut linv_v);
                log_det += g.log_det;
            }
            let g = eq
                .cholesky_gain(rec.covariance())
                .map_err(|s| s.into_error(&format!("at sample {transient}")))?;
            (transient, g, exact)
        };
        log_det += (len - transient) as f64 * steady_gains.log_det;
        let steady = steady_filter(noise, &steady_gains)?;
        Ok(KalmanWhitener {
            len,
            n,
            p,
            transient,
            gains: gains_v,
            linv: linv_v,
            a: noise.a().transpose().as_slice().to_vec(),
            c: noise.c().transpose().as_slice().to_vec(),
            steady,
            log_det,
            exact,
        })
    }

    /// Number of output channels `p` (channels of the signals to whiten).
    pub fn outputs(&self) -> usize {
        self.p
    }

    /// Order `n` of the noise path (and of the whitening filter).
    pub fn order(&self) -> usize {
        self.n
    }

    /// The record length `L` the whitener was built for.
    pub fn len(&self) -> usize {
        self.len
    }

    /// `true` for a whitener of empty records.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Number of samples before the gains were declared steady (`len` if never; 0 in
    /// `steady_state_only` mode, and whenever the gains are constant from the start, e.g.
    /// for a static noise path or a square invertible `D`).
    pub fn transient_len(&self) -> usize {
        self.transient
    }

    /// `true` when `W` is the exact whitening operator (to within the steady-state
    /// tolerance); `false` in `steady_state_only` mode and when the gains were frozen at
    /// `max_transient` before the Riccati recursion converged.
    pub fn is_exact(&self) -> bool {
        self.exact
    }

    /// The LTI filter `y -> w` used from sample [`transient_len`](Self::transient_len) on
    /// (`p` inputs and outputs, order `n`), started from the filter state reached there.
    pub fn steady_state_filter(&self) -> &StateSpace {
        &self.steady
    }

    /// `sum_t log det S_t = log det (T T^T)` (for marginal likelihoods).
    pub fn log_det(&self) -> f64 {
        self.log_det
    }

    fn check_rows(&self, rows: usize, what: &str) {
        assert!(
            rows == self.len * self.p,
            "{what} has {rows} values, expected len * outputs = {} * {}",
            self.len,
            self.p
        );
    }

    /// `w = W y` for one signal in time-major layout (`y.len() = out.len() = len * p`).
    /// Overwrites `out`. Panics on inconsistent lengths; non-finite values propagate.
    pub fn whiten(&self, y: &[f64], out: &mut [f64]) {
        self.check_rows(y.len(), "y");
        self.check_rows(out.len(), "out");
        let (n, p, tl) = (self.n, self.p, self.transient);
        let mut xs = vec![0.0; n];
        // the steady-state gains are not needed before `transient`
        let (steady, rows) = ((vec![], vec![]), tl * p);
        let (ym, om) = (column(&y[..rows]), column_mut(&mut out[..rows]));
        self.step_columns((0, tl), &steady, ym, om, &mut xs, Output::Whitened);
        self.steady
            .run(&xs, &y[tl * p..], &mut out[tl * p..], self.len - tl, None);
    }

    /// [`whiten`](Self::whiten) for a long signal: the time-varying transient per sample,
    /// then the steady-state filter by the blocked recursion of
    /// [`StateSpace::apply_long`]. The same values up to rounding. Panics on inconsistent
    /// lengths.
    pub fn whiten_long(&self, y: &[f64], out: &mut [f64]) {
        self.check_rows(y.len(), "y");
        self.check_rows(out.len(), "out");
        let (n, p, tl) = (self.n, self.p, self.transient);
        let rest = self.len - tl;
        if n == 0 || p == 0 || rest < LONG_MIN {
            self.whiten(y, out);
            return;
        }
        let mut xs = vec![0.0; n];
        let (steady, rows) = ((vec![], vec![]), tl * p);
        let (ym, om) = (column(&y[..rows]), column_mut(&mut out[..rows]));
        self.step_columns((0, tl), &steady, ym, om, &mut xs, Output::Whitened);
        self.steady
            .run_long_from(false, &y[rows..], &mut out[rows..], rest, &xs);
    }

    /// [`whiten_adjoint`](Self::whiten_adjoint) for a long signal: the steady part backwards
    /// by the blocked recursion of [`StateSpace::apply_adjoint_long`] (its costate is the λ
    /// of the per-sample recursion), then the transient per sample. The same values up to
    /// rounding. Panics on inconsistent lengths.
    pub fn whiten_adjoint_long(&self, g: &[f64], out: &mut [f64]) {
        self.check_rows(g.len(), "g");
        self.check_rows(out.len(), "out");
        let (n, p, tl) = (self.n, self.p, self.transient);
        let rest = self.len - tl;
        if n == 0 || p == 0 || rest < LONG_MIN {
            self.whiten_adjoint(g, out);
            return;
        }
        let rows = tl * p;
        let lam =
            self.steady
                .run_long_from(true, &g[rows..], &mut out[rows..], rest, &vec![0.0; n]);
        self.adjoint_steps(tl, g, out, lam);
    }

    /// The innovations `nu_t = y_t - C x^_t` of one signal (time-major, `len * p` values),
    /// in the units of `y`: the one-step-ahead prediction errors of the Kalman predictor
    /// `y^_{t|t-1} = C x^_t` of the noise path from `y_0 .. y_{t-1}` (zero initial state,
    /// `P_0 = 0`). [`whiten`](Self::whiten) returns the same innovations normalised,
    /// `w_t = L_t^{-1} nu_t`; here they are not scaled, so `nu_t` has covariance `S_t`.
    /// Overwrites `out`. Panics on inconsistent lengths; non-finite values propagate.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::kalman::{KalmanWhitener, WhiteningOptions};
    /// use structid_lti::StateSpace;
    /// // y = e / (1 - 0.5 q^-1): x+ = 0.5 x + 0.5 e, y = x + e; the predictor of y_t from
    /// // the past is 0.5 y_{t-1}, so the innovation is y_t - 0.5 y_{t-1} = e_t.
    /// let noise = StateSpace::new(
    ///     DMatrix::from_element(1, 1, 0.5),
    ///     DMatrix::from_element(1, 1, 0.5),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::from_element(1, 1, 1.0),
    /// )
    /// .unwrap();
    /// let w = KalmanWhitener::new(&noise, 4, &WhiteningOptions::default()).unwrap();
    /// let y = [2.0, 3.0, -1.0, 0.5];
    /// let mut nu = [0.0; 4];
    /// w.innovations(&y, &mut nu);
    /// for (t, expected) in [2.0, 2.0, -2.5, 1.0].iter().enumerate() {
    ///     assert!((nu[t] - expected).abs() < 1e-12);
    /// }
    /// ```
    pub fn innovations(&self, y: &[f64], out: &mut [f64]) {
        self.filter(y, out, None);
    }

    /// The innovations (as [`innovations`](Self::innovations)) and the one-step predicted
    /// states x̂_(t|t−1) of the noise path, written time-major into `states` (`len · n`
    /// values, n = [`order`](Self::order)): the state the filter holds before it reads y_t.
    /// A k-step-ahead predictor starts from them. Panics on inconsistent lengths.
    ///
    /// ```
    /// use nalgebra::dmatrix;
    /// use structid_lti::StateSpace;
    /// use structid_lti::kalman::{KalmanWhitener, WhiteningOptions};
    /// // v_t = e_t + 0.5·e_(t−1): x⁺ = e, v = 0.5·x + e.
    /// let noise = StateSpace::new(dmatrix![0.0], dmatrix![1.0], dmatrix![0.5], dmatrix![1.0]).unwrap();
    /// let w = KalmanWhitener::new(&noise, 3, &WhiteningOptions::default()).unwrap();
    /// let (mut nu, mut x) = ([0.0; 3], [0.0; 3]);
    /// w.predicted_states(&[1.0, 0.0, 0.0], &mut nu, &mut x);
    /// assert_eq!(x[0], 0.0); // started at rest
    /// // v_t − C·x̂_(t|t−1) is the innovation.
    /// assert!((0.0 - 0.5 * x[1] - nu[1]).abs() < 1e-15);
    /// ```
    pub fn predicted_states(&self, y: &[f64], out: &mut [f64], states: &mut [f64]) {
        assert_eq!(
            states.len(),
            self.len * self.n,
            "states must hold len · n values"
        );
        self.filter(y, out, Some(states));
    }

    fn filter(&self, y: &[f64], out: &mut [f64], states: Option<&mut [f64]>) {
        self.check_rows(y.len(), "y");
        self.check_rows(out.len(), "out");
        let (n, p) = (self.n, self.p);
        let mut xs = vec![0.0; n];
        let steady = self.steady_gains();
        let (y, mut out) = (column(y), column_mut(out));
        match states {
            None => self.step_columns((0, self.len), &steady, y, out, &mut xs, Output::Innovations),
            // One sample at a time, so that the state before each sample can be kept.
            Some(st) => {
                for t in 0..self.len {
                    st[t * n..(t + 1) * n].copy_from_slice(&xs);
                    self.step_columns(
                        (t, 1),
                        &steady,
                        y.subrows(t * p, p),
                        out.rb_mut().subrows_mut(t * p, p),
                        &mut xs,
                        Output::Innovations,
                    );
                }
            }
        }
    }

    /// `out = W x` for many signals at once: each column of `x` (`len * p` rows, any
    /// strides, e.g. a transposed matrix) is one time-major signal. Overwrites `out`.
    ///
    /// The columns are split across faer's global thread pool. Within a part, the first
    /// [`transient_len`](Self::transient_len) samples run the time-varying recursion on
    /// the `n x ncols` filter state (vectorised over the columns); the rest runs the
    /// steady-state filter with the blocked engine of
    /// [`LinearSystem::apply_columns`](crate::LinearSystem::apply_columns), started from
    /// that state. Panics on inconsistent shapes.
    pub fn whiten_columns(&self, x: MatRef<'_, f64>, out: MatMut<'_, f64>) {
        self.check_rows(x.nrows(), "x");
        self.check_rows(out.nrows(), "out");
        assert_eq!(
            x.ncols(),
            out.ncols(),
            "x and out must have the same number of columns"
        );
        if self.p == 0 || self.len == 0 || x.ncols() == 0 {
            return;
        }
        let (n, p, tl) = (self.n, self.p, self.transient);
        let rest = self.len - tl;
        let blocked = (n > 0 && rest > 0).then(|| self.steady.blocked(rest, false));
        let steady = self.steady_gains();
        par_columns(x, out, faer::get_global_parallelism(), &|x, mut out| {
            let w = x.ncols();
            let mut xs = vec![0.0; n * w];
            let xo = (x.subrows(0, tl * p), out.rb_mut().subrows_mut(0, tl * p));
            self.step_columns((0, tl), &steady, xo.0, xo.1, &mut xs, Output::Whitened);
            let (xr, or) = (
                x.subrows(tl * p, rest * p),
                out.subrows_mut(tl * p, rest * p),
            );
            match &blocked {
                Some(b) => {
                    let s0 = MatRef::from_row_major_slice(&xs, n, w);
                    b.leaf(rest, xr, or, Accum::Replace, 1.0, Some(s0), None);
                }
                // static filter: w_t = L^{-1} y_t
                None => self.step_columns((tl, rest), &steady, xr, or, &mut xs, Output::Whitened),
            }
        });
    }

    /// Gains `(G, L⁻¹)` (row-major `n × p` and packed lower `p(p+1)/2`) at sample `t`: the stored
    /// time-varying ones during the transient, the steady-state ones after it.
    fn gains_at<'s>(
        &'s self,
        t: usize,
        steady: &'s (Vec<f64>, Vec<f64>),
    ) -> (&'s [f64], &'s [f64]) {
        let (n, p) = (self.n, self.p);
        let pp = p * (p + 1) / 2;
        if t < self.transient {
            (
                &self.gains[t * n * p..(t + 1) * n * p],
                &self.linv[t * pp..(t + 1) * pp],
            )
        } else {
            (&steady.0, &steady.1)
        }
    }

    /// The steady-state gains in the recursion's form: `L⁻¹ = D_f` and `G = K·L = B_f·D_f⁻¹`
    /// of the steady filter x̂⁺ = (A − KC)x̂ + K·y, ω = L⁻¹(y − C·x̂).
    fn steady_gains(&self) -> (Vec<f64>, Vec<f64>) {
        let dinv = self.steady.d();
        let l = dinv
            .clone()
            .try_inverse()
            .unwrap_or_else(|| DMatrix::identity(self.p, self.p));
        let (mut gr, mut li) = (Vec::new(), Vec::new());
        push_gains(&(self.steady.b() * l), dinv, &mut gr, &mut li);
        (gr, li)
    }

    /// `u = Wᵀ g` for one signal (time-major, `len · p` values): the adjoint of
    /// [`whiten`](Self::whiten), by the backward recursion h_t = g_t + G_tᵀλ_{t+1},
    /// u_t = L_t⁻ᵀh_t, λ_t = Aᵀλ_{t+1} − Cᵀu_t. With it, `Wᵀ(W r) = (T·Tᵀ)⁻¹ r`.
    pub fn whiten_adjoint(&self, g: &[f64], out: &mut [f64]) {
        self.check_rows(g.len(), "g");
        self.check_rows(out.len(), "out");
        self.adjoint_steps(self.len, g, out, vec![0.0; self.n]);
    }

    /// The backward recursion of [`whiten_adjoint`](Self::whiten_adjoint) over the samples
    /// `steps − 1, …, 0`, from the costate `lam` = λ_steps.
    fn adjoint_steps(&self, steps: usize, g: &[f64], out: &mut [f64], mut lam: Vec<f64>) {
        let (n, p) = (self.n, self.p);
        let steady = self.steady_gains();
        let mut lam_next = vec![0.0; n];
        let mut h = vec![0.0; p];
        for t in (0..steps).rev() {
            let (gt, li) = self.gains_at(t, &steady);
            for r in 0..p {
                h[r] = g[t * p + r] + (0..n).map(|i| gt[i * p + r] * lam[i]).sum::<f64>();
            }
            let u = &mut out[t * p..(t + 1) * p];
            for k in 0..p {
                // (L⁻¹)ᵀ: row r of L⁻¹ holds entries (r, 0..=r).
                u[k] = (k..p).map(|r| li[r * (r + 1) / 2 + k] * h[r]).sum();
            }
            for i in 0..n {
                let at: f64 = (0..n).map(|kk| self.a[kk * n + i] * lam[kk]).sum();
                let ct: f64 = (0..p).map(|c| self.c[c * n + i] * u[c]).sum();
                lam_next[i] = at - ct;
            }
            std::mem::swap(&mut lam, &mut lam_next);
        }
    }

    /// A stream that whitens `ncols` signals delivered in consecutive time chunks (see
    /// [`WhiteningStream`]).
    pub fn column_stream(&self, ncols: usize) -> WhiteningStream<'_> {
        let n = self.n;
        WhiteningStream {
            whitener: self,
            engine: (n > 0).then(|| self.steady.blocked(usize::MAX / 2, false)),
            steady: self.steady_gains(),
            t: 0,
            ncols,
            state: vec![0.0; n * ncols],
            next: vec![0.0; n * ncols],
        }
    }

    /// `steps` samples of the recursion from sample `t0` on the columns of `x` and `out`
    /// (`steps * p` rows), vectorised over the columns: `xs` is the filter state
    /// (`n x ncols`, row-major), updated in place; `out` receives `what`. `steady`: the
    /// steady-state gains of [`steady_gains`](Self::steady_gains).
    fn step_columns(
        &self,
        (t0, steps): (usize, usize),
        steady: &(Vec<f64>, Vec<f64>),
        x: MatRef<'_, f64>,
        mut out: MatMut<'_, f64>,
        xs: &mut Vec<f64>,
        what: Output,
    ) {
        let (n, p) = (self.n, self.p);
        let w = x.ncols();
        let mut xn = vec![0.0; n * w];
        let mut nu = vec![0.0; p * w];
        let mut om = vec![0.0; p * w];
        for t in 0..steps {
            let (g, li) = self.gains_at(t0 + t, steady);
            // nu = y_t - C x^
            for c in 0..p {
                let nc = &mut nu[c * w..(c + 1) * w];
                for (j, v) in nc.iter_mut().enumerate() {
                    *v = x[(t * p + c, j)];
                }
                for i in 0..n {
                    let cc = self.c[c * n + i];
                    for (v, s) in nc.iter_mut().zip(&xs[i * w..(i + 1) * w]) {
                        *v -= cc * s;
                    }
                }
                if what == Output::Innovations {
                    for (j, &v) in nc.iter().enumerate() {
                        out[(t * p + c, j)] = v;
                    }
                }
            }
            // w_t = L^{-1} nu
            for r in 0..p {
                let row = &li[r * (r + 1) / 2..r * (r + 1) / 2 + r + 1];
                let orow = &mut om[r * w..(r + 1) * w];
                orow.fill(0.0);
                for (k, &l) in row.iter().enumerate() {
                    for (o, v) in orow.iter_mut().zip(&nu[k * w..(k + 1) * w]) {
                        *o += l * v;
                    }
                }
                if what == Output::Whitened {
                    for (j, &v) in orow.iter().enumerate() {
                        out[(t * p + r, j)] = v;
                    }
                }
            }
            // x^+ = A x^ + G w_t
            for i in 0..n {
                let xi = &mut xn[i * w..(i + 1) * w];
                xi.fill(0.0);
                for k in 0..n {
                    let a = self.a[i * n + k];
                    if a != 0.0 {
                        for (o, v) in xi.iter_mut().zip(&xs[k * w..(k + 1) * w]) {
                            *o += a * v;
                        }
                    }
                }
                for r in 0..p {
                    let gv = g[i * p + r];
                    for (o, v) in xi.iter_mut().zip(&om[r * w..(r + 1) * w]) {
                        *o += gv * v;
                    }
                }
            }
            std::mem::swap(xs, &mut xn);
        }
    }
}

#[cfg(test)]
mod tests;

/// Whitens many signals chunk by chunk with the filter state carried between chunks, so a
/// long record never has to be in memory at once. The result equals
/// [`KalmanWhitener::whiten_columns`] on the whole record.
///
/// Chunks may have any length; the steady part of each chunk runs the blocked engine on a
/// whole number of blocks, and the few samples before it (the transient, and any remainder)
/// run the per-sample recursion vectorised over the columns.
pub struct WhiteningStream<'a> {
    whitener: &'a KalmanWhitener,
    engine: Option<crate::operator::BlockedRecursion>,
    steady: (Vec<f64>, Vec<f64>),
    t: usize,
    ncols: usize,
    /// the filter state (`n x ncols`, row-major) and a buffer of the same shape
    state: Vec<f64>,
    next: Vec<f64>,
}

impl WhiteningStream<'_> {
    /// Whitens the next chunk: `x` and `out` have `samples · p` rows and the stream's columns.
    pub fn push(&mut self, x: MatRef<'_, f64>, mut out: MatMut<'_, f64>) -> Result<(), LtiError> {
        let w = self.whitener;
        let (n, p) = (w.n, w.p);
        let ncols = self.ncols;
        if x.ncols() != ncols
            || out.ncols() != ncols
            || x.nrows() != out.nrows()
            || p == 0
            || x.nrows() % p != 0
        {
            return Err(LtiError::DimensionMismatch {
                what: "whitening stream chunk".into(),
                expected: format!("samples × {p} rows and {ncols} columns, equal for x and out"),
                found: format!(
                    "{}×{} and {}×{}",
                    x.nrows(),
                    x.ncols(),
                    out.nrows(),
                    out.ncols()
                ),
            });
        }
        let c = x.nrows() / p;
        if self.t + c > w.len {
            return Err(LtiError::InvalidParameter {
                name: "chunk".into(),
                reason: format!("the chunks exceed the whitener's record length {}", w.len),
            });
        }
        let b = self.engine.as_ref().map_or(1, |e| e.b);
        // Per-sample steps: through the transient, then until a whole number of blocks is left.
        let per_sample = |k: usize| {
            self.t + k < w.transient || !(c - k).is_multiple_of(b) || self.engine.is_none()
        };
        let k = (0..c).find(|&k| !per_sample(k)).unwrap_or(c);
        let (xk, ok) = (x.subrows(0, k * p), out.rb_mut().subrows_mut(0, k * p));
        w.step_columns(
            (self.t, k),
            &self.steady,
            xk,
            ok,
            &mut self.state,
            Output::Whitened,
        );
        self.t += k;
        if k < c {
            let e = self.engine.as_ref().expect("per-sample steps cover n = 0");
            let rows = (c - k) * p;
            e.leaf(
                c - k,
                x.subrows(k * p, rows),
                out.rb_mut().subrows_mut(k * p, rows),
                Accum::Replace,
                1.0,
                Some(MatRef::from_row_major_slice(&self.state, n, ncols)),
                Some(MatMut::from_row_major_slice_mut(&mut self.next, n, ncols)),
            );
            std::mem::swap(&mut self.state, &mut self.next);
            self.t += c - k;
        }
        Ok(())
    }
}

//! Disturbance smoothing: the most likely inputs of a state-space system that reproduce
//! noise-free outputs exactly.
//!
//! # Problem
//! Given a discrete [`StateSpace`] `(A, B, C, D)` with `n` states, `m` inputs `v` and `p`
//! outputs, a record of `L` samples of outputs `y` and a prior for the inputs,
//! `v_k ~ N(m_k, Q)` independent over `k` with `Q = diag(q_1 .. q_m)`, `q_j >= 0`
//! (`q_j = 0` pins input `j` to its mean), [`DisturbanceSmoother`] computes
//!
//! ```text
//! v^ = argmin_v  1/2 sum_k (v_k - m_k)^T Q^+ (v_k - m_k)
//!      s.t.  x_{k+1} = A x_k + B v_k,   y_k = C x_k + D v_k   (exactly, for every k),
//!            x_0 = 0                       (SmootherInitial::Zero), or
//!            x_0 free and unpenalised      (SmootherInitial::Free, the exact diffuse solution),
//! ```
//!
//! the posterior mean of `v` given `y` (de Jong's / Durbin–Koopman's disturbance smoother,
//! with state and observation disturbances correlated because both come from `v`). With
//! `v = m + delta` and `y' = y - T m` (`T` the input-to-output operator from rest) this is
//! `delta^ = Q T^T (T Q T^T)^+ y'` for a zero initial state, but it is computed in
//! `O(L (n^2 + n m + n p + p^2))` operations without ever forming `T`.
//!
//! # Recursions
//! Filter (the covariance recursion does not depend on the data; it is run once, in
//! [`DisturbanceSmoother::new`]), from `P_0` (0 for a zero initial state, see below for a
//! free one):
//!
//! ```text
//! F_k = C P_k C^T + D Q D^T                      (p x p, may be singular)
//! K_k = (A P_k C^T + B Q D^T) F_k^+
//! P_{k+1} = (A - K_k C) P_k (A - K_k C)^T + (B - K_k D) Q (B - K_k D)^T
//! ```
//!
//! (the Joseph form of `A P A^T + B Q B^T - K F K^T`: equal to it, but positive
//! semi-definite under rounding). `F^+` is the pseudo-inverse through a symmetric
//! eigendecomposition: eigenvalues at or below `1e-12 s_k` count as zero, where `s_k` is
//! the running maximum of `trace F_j` (`j <= k`) and of the a-priori scale
//! `trace(D Q D^T + C P_0 C^T) + |C|_F^2 trace(B Q B^T)` (relative, so the result does not
//! depend on the units of `Q`). The zero eigenvalues are the *null directions* of sample
//! `k`: output combinations with zero predicted variance, which the inputs cannot move
//! (for instance `y_0` when `D = 0` and `x_0 = 0`). The data component along them is not
//! used; for a zero initial state it is the data's *inconsistency* (reported in
//! [`SmoothReport`], not an error).
//!
//! Per call of [`DisturbanceSmoother::smooth`], a forward (mean) pass and a backward
//! (costate) pass:
//!
//! ```text
//! a_0 = 0,   e_k = y'_k - C a_k,   a_{k+1} = A a_k + K_k e_k              (k = 0 .. L-1)
//! r_{L-1} = 0,  u_k = F_k^+ e_k - K_k^T r_k,   delta^_k = Q (D^T u_k + B^T r_k),
//!               r_{k-1} = C^T u_k + A^T r_k                                (k = L-1 .. 0)
//! ```
//!
//! # Free initial state
//! Write `x_0 = xi + eta` with `xi` free (unpenalised) and `eta ~ N(0, P_0)` a proper
//! *base prior*: the sum is still free, so the problem is unchanged (at the optimum
//! `eta^ = 0`, `xi` absorbs everything), and the filter above runs from this `P_0`. This
//! is exact, not a large-`P_0` approximation; `P_0 = s I`, `s` the mean eigenvalue of the
//! `n`-step reachability Gramian `sum_{j<n} A^j B Q B^T (A^j)^T` plus
//! `trace(D Q D^T) / |C|_F^2` (0 when the inputs move no state); the second term keeps
//! `C P_0 C^T` comparable with `D Q D^T`, so `F_0` is no worse conditioned than the problem. A positive `P_0` makes the Riccati recursion converge to the *stabilizing*
//! gains; from `P_0 = 0` it stays on the non-stabilizing solution when the system has
//! transmission zeros outside the unit circle (with as many effective inputs as outputs),
//! and then the recursions below blow up although the free-state problem is
//! well-conditioned.
//!
//! The free part `xi` is handled by augmentation (de Jong). With `O` the free response
//! (`y_k = C A^k x_0`), the innovations of the columns of `O` are `E_k = C Z_k`, `Z_0 = I`,
//! `Z_{k+1} = (A - K_k C) Z_k`; they are computed and stored in
//! [`DisturbanceSmoother::new`] (`p n` values per sample, until `Z_k` has decayed below
//! `1e-20 max_j |Z_j|` in the steady state; at most `L p n`). The innovations of
//! `y' - O xi` are
//! `e_k - E_k xi`, and the cost of the best `(delta, eta)` for a given `xi` is
//! `1/2 sum_k (e_k - E_k xi)^T F_k^+ (e_k - E_k xi)`, *provided* the components of
//! `e_k - E_k xi` along the null directions of `F_k` vanish (they are exact constraints on
//! `xi`; e.g. `y_0 = C x_0` when `D = 0` and the inputs move no state). So `xi^`
//! minimises `x^T G x - 2 b^T x` with `G = sum E_k^T F_k^+ E_k`, `b = sum E_k^T F_k^+ e_k`,
//! over the least-squares solutions of the constraints `H x = h`,
//! `H = sum E_k^T N_k^T N_k E_k`, `h = sum E_k^T N_k^T N_k e_k` (`N_k`: null directions as
//! rows); one step of iterative refinement on the residual innovations `e_k - E_k xi^`
//! recovers the accuracy lost to these normal equations. Without null directions this is
//! the generalised least-squares estimate `xi^ = G^{-1} b`. Directions of `x_0` the outputs
//! do not see get 0. Then `e_k <- e_k - E_k xi^`, the backward pass runs as above (no second
//! forward pass) and `x^_0 = xi^ + P_0 r_{-1}`.
//!
//! # Steady state
//! Once `|P_{k+1} - P_k|_F <= 1e-13 (|P_k|_F + |B Q B^T|_F)` the gains `(F_k^+, K_k)` are
//! frozen and reused for the remaining samples, so the stored gains take
//! `O(t (n + m + p)^2)` memory for a transient of `t` samples
//! ([`DisturbanceSmoother::transient_len`]), not `O(L)` (the `Free` variant also stores
//! `E_k` until the free response has decayed). For speed, each stored step holds the two
//! packed maps of the
//! passes, `[s_k; m_k; y_k] -> [e_k; s_{k+1}]` (the forward pass runs on `y` and the mean
//! directly, `s_k` being the predicted state including the mean's response) and
//! `[e_k; r_k] -> [v^_k - m_k; r_{k-1}]`.
//!
//! # Accuracy and stability
//! The filter works with covariances, so its rounding errors grow like `eps kappa^2` with
//! the condition number `kappa` of the problem (a dense SVD solution: `eps kappa`). Both
//! passes propagate through the closed loop `A - K_k C`; when its spectral radius
//! ([`DisturbanceSmoother::closed_loop_radius`]) exceeds 1, errors grow exponentially with
//! the record length. That is inherent for a zero initial state with transmission zeros
//! outside the unit circle and as many effective inputs as outputs (the problem itself is
//! then exponentially ill-conditioned), but it also happens, as a limitation of this
//! recursion, when null directions persist in the steady state (more outputs than
//! effective inputs reaching them) and the gain restricted to the other directions does
//! not stabilise the loop.

use crate::error::LtiError;
use crate::riccati::{
    Overflow, Riccati, dot, mat_vec_add, mat_vec3, row_major, sym_pinv, symmetrise,
};
use crate::signal::Signal;
use crate::state_space::StateSpace;
use nalgebra::{DMatrix, DVector};

mod step;

use step::{FreeInit, Step, StepRef, accumulate_free, free_base_prior, sample_step, skip_step};

/// Relative threshold of the pseudo-inverses (innovation covariances `F_k` and the `n x n`
/// systems of the free initial state).
const PINV_TOL: f64 = 1e-12;

/// Relative tolerance of the steady-state test on the Riccati recursion.
const STEADY_TOL: f64 = 1e-13;

/// In the steady state, the innovations `E_k = C Z_k` of the free response are dropped once
/// `|Z_k|_F <= E_CUT max_j |Z_j|_F`: far below the rounding of the retained terms, with room
/// for a transient regrowth of `Z` by the (stable) closed loop.
const E_CUT: f64 = 1e-20;

/// The initial state of the smoothing problem.
///
/// ```
/// use structid_lti::SmootherInitial;
/// assert_ne!(SmootherInitial::Zero, SmootherInitial::Free);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SmootherInitial {
    /// `x_0 = 0` (the system starts at rest).
    Zero,
    /// `x_0` is unknown and unpenalised (the exact diffuse solution); it is estimated
    /// together with the inputs and returned in [`SmoothReport::initial_state`].
    Free,
}

/// Diagnostics of one call of [`DisturbanceSmoother::smooth`].
///
/// ```
/// use structid_lti::SmoothReport;
/// let r = SmoothReport { initial_state: None, null_directions: 0, max_inconsistency: 0.0 };
/// assert!(r.initial_state.is_none());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct SmoothReport {
    /// The estimated initial state `x^_0` (length `n`) for [`SmootherInitial::Free`];
    /// `None` for [`SmootherInitial::Zero`].
    pub initial_state: Option<Vec<f64>>,
    /// Total number of null directions of the innovation covariances `F_k`, summed over the
    /// samples (0 when every `F_k` is invertible): output combinations with zero predicted
    /// variance, whose data therefore carry no information about the inputs. For a zero
    /// initial state, combinations the inputs cannot move; for a free one, combinations
    /// that neither the inputs nor `x_0` can move (except when the inputs move no state at
    /// all: then `x_0` enters through exact constraints and every output counts). It does
    /// not depend on the data.
    pub null_directions: usize,
    /// Largest absolute innovation component along a null direction (after removing the
    /// free response of `x^_0`): 0 (up to rounding) when the data can be reproduced
    /// exactly by some input sequence (and initial state); otherwise the size of the part
    /// of the data that nothing in the model can explain, which the smoother ignores.
    pub max_inconsistency: f64,
}

/// The disturbance smoother of a state-space system over a fixed record length: the
/// posterior mean of the inputs given exact outputs, computed by a time-varying Kalman
/// filter (run once, in [`new`](Self::new)) followed, for each record, by a forward and a
/// backward pass. See the [module documentation](self) for the problem and the recursions.
///
/// ```
/// use nalgebra::DMatrix;
/// use structid_lti::{DisturbanceSmoother, LinearSystem, Signal, SmootherInitial, StateSpace};
/// // x+ = 0.5 x + v_0,  y = x + v_1  (v_1: measurement noise)
/// let sys = StateSpace::new(
///     DMatrix::from_element(1, 1, 0.5),
///     DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
///     DMatrix::from_element(1, 1, 1.0),
///     DMatrix::from_row_slice(1, 2, &[0.0, 1.0]),
/// )
/// .unwrap();
/// let len = 50;
/// let smoother = DisturbanceSmoother::new(&sys, &[1.0, 0.1], len, SmootherInitial::Zero).unwrap();
/// let y = Signal::from_fn(len, 1, |k, _| (0.3 * k as f64).sin());
/// let mean = Signal::zeros(len, 2);
/// let mut v = Signal::zeros(len, 2);
/// let report = smoother.smooth(&y, &mean, &mut v).unwrap();
/// assert_eq!(report.null_directions, 0);
/// // the smoothed inputs reproduce the data exactly
/// let y_hat = sys.simulate(&v).unwrap();
/// for k in 0..len {
///     assert!((y_hat.get(k, 0) - y.get(k, 0)).abs() < 1e-10);
/// }
/// ```
#[derive(Clone)]
pub struct DisturbanceSmoother {
    system: StateSpace,
    len: usize,
    n: usize,
    m: usize,
    p: usize,
    initial: SmootherInitial,
    /// the variances `q_j`
    q: Vec<f64>,
    /// samples with stored gains
    transient: usize,
    /// `F_k^+` for `k < transient` (`p^2` each)
    finv: Vec<f64>,
    /// `K_k` for `k < transient` (`n p` each)
    gain: Vec<f64>,
    /// forward maps for `k < transient` (`(p + n)(n + m + p)` each)
    fw: Vec<f64>,
    /// backward maps for `k < transient` (`(m + n)(p + n)` each)
    bw: Vec<f64>,
    /// null rows for `k < transient` (`p^2` slots each, the first `nnull[k]` rows used)
    null: Vec<f64>,
    /// number of null directions for `k < transient`
    nnull: Vec<usize>,
    /// the gains used from sample `transient` on
    steady: Step,
    /// null directions summed over all samples
    null_total: usize,
    /// largest spectral radius of the closed loops `A - K_k C`
    radius: f64,
    free: Option<FreeInit>,
    /// the samples whose outputs are missing (see [`DisturbanceSmoother::with_missing`]), when
    /// any
    missing: Option<Vec<bool>>,
}

impl std::fmt::Debug for DisturbanceSmoother {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // the stored gains can be long: summarise
        f.debug_struct("DisturbanceSmoother")
            .field("len", &self.len)
            .field("order", &self.n)
            .field("inputs", &self.m)
            .field("outputs", &self.p)
            .field("initial", &self.initial)
            .field("variances", &self.q)
            .field("transient_len", &self.transient)
            .field("null_directions", &self.null_total)
            .field("closed_loop_radius", &self.radius)
            .field("system", &self.system)
            .finish()
    }
}

impl DisturbanceSmoother {
    /// Builds the smoother of `system` for records of `len` samples, with input variances
    /// `variances` (`q_j >= 0`, one per input; `q_j = 0` fixes input `j` at its prior
    /// mean) and the initial-state model `initial`: runs the Riccati recursion and stores
    /// its gains until they converge, and for [`SmootherInitial::Free`] the innovations of
    /// the free response (until they have decayed; at most `len * p * n` values).
    ///
    /// Cost: `O(t (n^3 + n^2 (m + p) + p^3))` time and `O(t (n + m + p)^2)` memory for a
    /// transient of `t` samples (the per-sample maps of [`smooth`](Self::smooth) are
    /// precomputed), plus `O(L' n^2 (n + p))` time and `L' p n` values for
    /// [`SmootherInitial::Free`], where `L' <= L` is the length of the free response's
    /// innovations before they decay (`L` if the closed loop is not stable). `len = 0` is
    /// allowed (an empty smoother).
    ///
    /// Errors:
    /// - [`LtiError::DimensionMismatch`] when `variances.len()` is not the number of inputs,
    ///   or `len * max(n, m, p)^2` overflows `usize`;
    /// - [`LtiError::InvalidParameter`] (`variances`) for a negative or non-finite variance;
    /// - [`LtiError::InvalidParameter`] (`system`) when the Riccati recursion overflows
    ///   (unstable modes that the outputs do not observe) or the innovations of the free
    ///   response do (unstable closed loop, see
    ///   [`closed_loop_radius`](Self::closed_loop_radius)).
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::{DisturbanceSmoother, SmootherInitial, StateSpace};
    /// let sys = StateSpace::new(
    ///     DMatrix::from_element(1, 1, 0.9),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::from_element(1, 1, 0.5),
    /// )
    /// .unwrap();
    /// let s = DisturbanceSmoother::new(&sys, &[2.0], 1000, SmootherInitial::Free).unwrap();
    /// assert_eq!(s.len(), 1000);
    /// assert!(s.transient_len() < 1000);
    /// assert!(DisturbanceSmoother::new(&sys, &[-1.0], 10, SmootherInitial::Zero).is_err());
    /// assert!(DisturbanceSmoother::new(&sys, &[1.0, 1.0], 10, SmootherInitial::Zero).is_err());
    /// ```
    pub fn new(
        system: &StateSpace,
        variances: &[f64],
        len: usize,
        initial: SmootherInitial,
    ) -> Result<Self, LtiError> {
        Self::build(system, variances, len, initial, true, &[], None)
    }

    /// [`with_adjoint`](Self::with_adjoint) for a record whose outputs are *missing* at the
    /// samples `k` with `missing[k]` (`missing.len() == len`): their output equations are left
    /// out, so the inputs there are constrained only through the states they move (the
    /// Kalman filter skips the measurement update: `K_k = 0`, no innovation). The inputs at a
    /// missing sample are smoothed like any other (their posterior mean given the outputs
    /// that remain, e.g. their prior mean when they move no state).
    ///
    /// The gains are stored up to the last missing sample and until the recursion is steady
    /// again after it: `O(t (n + m + p)^2)` memory with `t` that many samples.
    ///
    /// Errors: as [`with_adjoint`](Self::with_adjoint), and
    /// [`LtiError::DimensionMismatch`] when `missing` does not have `len` entries.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::{DisturbanceSmoother, Signal, SmootherInitial, StateSpace};
    /// // y_k = v_k: with y_1 missing, v_1 stays at its prior mean
    /// let sys = StateSpace::new(
    ///     DMatrix::zeros(0, 0),
    ///     DMatrix::zeros(0, 1),
    ///     DMatrix::zeros(1, 0),
    ///     DMatrix::from_element(1, 1, 1.0),
    /// )
    /// .unwrap();
    /// let s = DisturbanceSmoother::with_missing(&sys, &[1.0], 3, SmootherInitial::Zero, &[], &[false, true, false])
    ///     .unwrap();
    /// let y = Signal::new(1, vec![1.0, 5.0, 3.0]).unwrap();
    /// let mean = Signal::new(1, vec![0.0, 2.0, 0.0]).unwrap();
    /// let mut v = Signal::zeros(3, 1);
    /// s.smooth(&y, &mean, &mut v).unwrap();
    /// assert_eq!(v.as_slice(), &[1.0, 2.0, 3.0]);
    /// ```
    pub fn with_missing(
        system: &StateSpace,
        variances: &[f64],
        len: usize,
        initial: SmootherInitial,
        adjoint: &[usize],
        missing: &[bool],
    ) -> Result<Self, LtiError> {
        if missing.len() != len {
            return Err(LtiError::dims(
                "missing-output mask",
                format!("{len} (one per sample)"),
                missing.len(),
            ));
        }
        Self::check_adjoint(variances, adjoint)?;
        let missing = missing.iter().any(|&m| m).then_some(missing);
        Self::build(system, variances, len, initial, true, adjoint, missing)
    }

    fn check_adjoint(variances: &[f64], adjoint: &[usize]) -> Result<(), LtiError> {
        if let Some(&j) = adjoint
            .iter()
            .find(|&&j| j >= variances.len() || variances[j] != 0.0)
        {
            return Err(LtiError::param(
                "adjoint",
                format!(
                    "adjoint channel {j} must be an input (< {}) with variance 0",
                    variances.len()
                ),
            ));
        }
        Ok(())
    }

    /// [`new`](Self::new) with *adjoint channels*: inputs `j` in `adjoint` (each with
    /// variance 0, i.e. fixed at its mean) for which [`smooth`](Self::smooth) writes
    /// `mean_j + g_j` instead of `mean_j`, where `g_j = T_j^T (T Q T^T)^+ (y - T mean)` is the
    /// sensitivity of the problem to input `j`: the minimal cost
    /// `1/2 sum_k (v_k - m_k)^T Q^+ (v_k - m_k)` moves by `-g_j^T dm_j` when the (fixed)
    /// input `j` moves by `dm_j` (for [`SmootherInitial::Free`], with `x_0` re-optimised).
    /// The other inputs are smoothed as by [`new`](Self::new); the cost of a call is the
    /// same.
    ///
    /// This lets a caller optimise parameters that enter through fixed inputs (a map given by
    /// features, say) in closed form: the gradient of the cost with respect to them comes out
    /// of the same backward pass.
    ///
    /// Errors: as [`new`](Self::new), and [`LtiError::InvalidParameter`] (`adjoint`) for a
    /// channel out of range or with a non-zero variance.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::{DisturbanceSmoother, Signal, SmootherInitial, StateSpace};
    /// // y = v_0 + v_1 (no states): v_1 fixed at its mean, v_0 ~ N(0, 2)
    /// let sys = StateSpace::new(
    ///     DMatrix::zeros(0, 0),
    ///     DMatrix::zeros(0, 2),
    ///     DMatrix::zeros(1, 0),
    ///     DMatrix::from_row_slice(1, 2, &[1.0, 1.0]),
    /// )
    /// .unwrap();
    /// let s = DisturbanceSmoother::with_adjoint(&sys, &[2.0, 0.0], 1, SmootherInitial::Zero, &[1])
    ///     .unwrap();
    /// let y = Signal::new(1, vec![3.0]).unwrap();
    /// let mean = Signal::new(2, vec![0.0, 1.0]).unwrap();
    /// let mut v = Signal::zeros(1, 2);
    /// s.smooth(&y, &mean, &mut v).unwrap();
    /// // v_0 = y - v_1 = 2; the cost (v_0)^2 / 4 has derivative -(y - v_1) / 2 = -1 in v_1
    /// assert!((v.get(0, 0) - 2.0).abs() < 1e-14);
    /// assert!((v.get(0, 1) - (1.0 + 1.0)).abs() < 1e-14);
    /// assert!(DisturbanceSmoother::with_adjoint(&sys, &[2.0, 1.0], 1, SmootherInitial::Zero, &[1]).is_err());
    /// ```
    pub fn with_adjoint(
        system: &StateSpace,
        variances: &[f64],
        len: usize,
        initial: SmootherInitial,
        adjoint: &[usize],
    ) -> Result<Self, LtiError> {
        Self::check_adjoint(variances, adjoint)?;
        Self::build(system, variances, len, initial, true, adjoint, None)
    }

    /// [`new`](Self::new), optionally never declaring the steady state (test hook), with
    /// adjoint channels (see [`with_adjoint`](Self::with_adjoint)).
    fn build(
        system: &StateSpace,
        variances: &[f64],
        len: usize,
        initial: SmootherInitial,
        allow_steady: bool,
        adjoint: &[usize],
        missing: Option<&[bool]>,
    ) -> Result<Self, LtiError> {
        let (n, m, p) = (system.order(), system.inputs(), system.outputs());
        if variances.len() != m {
            return Err(LtiError::dims(
                "input variances",
                format!("{m} (one per input)"),
                variances.len(),
            ));
        }
        if let Some((j, &q)) = variances
            .iter()
            .enumerate()
            .find(|(_, q)| !(q.is_finite() && **q >= 0.0))
        {
            return Err(LtiError::param(
                "variances",
                format!("variance {j} must be finite and non-negative, got {q}"),
            ));
        }
        let width = n.max(m).max(p).max(1);
        if len.checked_mul(width * width).is_none() {
            return Err(LtiError::dims(
                "smoother record length",
                format!("len * {width}^2 to fit in usize"),
                format!("{len} samples"),
            ));
        }
        let eq = Riccati::new(system, Some(variances));
        let q = DMatrix::from_diagonal(&DVector::from_column_slice(variances));
        // the backward maps scale the sensitivities by Q, except on the adjoint channels
        let mut qb = q.clone();
        for &j in adjoint {
            qb[(j, j)] = 1.0;
        }

        // Riccati recursion until the steady state (or the end of the record)
        let pp = p * p;
        let mut finv = Vec::new();
        let mut gain = Vec::new();
        let mut fw = Vec::new();
        let mut bw = Vec::new();
        let mut null = Vec::new();
        let mut nnull = Vec::new();
        // base prior covariance of x_0 (see the module documentation)
        let p0 = match initial {
            SmootherInitial::Zero => DMatrix::<f64>::zeros(n, n),
            SmootherInitial::Free => free_base_prior(&eq),
        };
        // the a-priori scale of F: trace(D Q D^T + C P_0 C^T) + |C|_F^2 trace(B Q B^T)
        let c = system.c();
        let mut scale = eq.r.trace() + c.norm_squared() * eq.q.trace();
        scale += (c * &p0 * c.transpose()).trace();
        let mut rec = eq.recursion(p0.clone(), allow_steady.then_some(STEADY_TOL));
        let mut steady = Step::default();
        let mut transient = len;
        // the steady state may be declared only after the last missing sample
        let last_missing = missing.and_then(|m| m.iter().rposition(|&x| x));
        for k in 0..len {
            let skip = missing.is_some_and(|m| m[k]);
            let (st, kmat) = if skip {
                skip_step(system, &qb)
            } else {
                sample_step(&eq, &qb, rec.covariance(), &mut scale)
            };
            // no outputs: nothing to filter, the gains are empty and steady from the start
            let is_steady = if p == 0 {
                allow_steady
            } else {
                rec.advance(&kmat).map_err(|Overflow| {
                    LtiError::param(
                        "system",
                        format!(
                            "the Riccati recursion overflowed at sample {k}: the system has \
                             unstable modes that the outputs do not observe"
                        ),
                    )
                })?
            };
            if is_steady && !skip && last_missing.is_none_or(|l| k > l) {
                // the gains of P_k are (to within the tolerance) those of every later step
                transient = k;
                steady = st;
                break;
            }
            finv.extend_from_slice(&st.finv);
            gain.extend_from_slice(&st.gain);
            fw.extend_from_slice(&st.fw);
            bw.extend_from_slice(&st.bw);
            let nn = st.null.len() / p.max(1);
            let mut slot = st.null;
            slot.resize(pp, 0.0);
            null.extend_from_slice(&slot);
            nnull.push(nn);
        }
        let steady_nulls = steady.null.len() / p.max(1);
        let null_total = nnull.iter().sum::<usize>() + (len - transient) * steady_nulls;
        // the largest spectral radius of the closed loops A - K_k C used
        let rho = |kg: &[f64]| {
            let k = DMatrix::from_row_slice(n, p, kg);
            (system.a() - k * system.c())
                .complex_eigenvalues()
                .iter()
                .map(|z| z.norm())
                .fold(0.0, f64::max)
        };
        let mut radius = 0.0f64;
        if n > 0 && len > 0 {
            for kg in gain.chunks_exact(n * p.max(1)).take(transient) {
                radius = radius.max(rho(kg));
            }
            if transient < len {
                radius = radius.max(rho(&steady.gain));
            }
        }

        let mut sm = DisturbanceSmoother {
            system: system.clone(),
            len,
            n,
            m,
            p,
            initial,
            q: variances.to_vec(),
            transient,
            finv,
            gain,
            fw,
            bw,
            null,
            nnull,
            steady,
            null_total,
            radius,
            free: None,
            missing: missing.map(<[bool]>::to_vec),
        };
        if initial == SmootherInitial::Free {
            sm.free = Some(sm.free_init(&p0)?);
        }
        Ok(sm)
    }

    /// The innovations `E_k = C Z_k` of the free response and the maps `R_b`, `R_h` of
    /// `x^_0 = R_b b + R_h h` (see the [module documentation](self)).
    fn free_init(&self, p0: &DMatrix<f64>) -> Result<FreeInit, LtiError> {
        let (n, p, len) = (self.n, self.p, self.len);
        let c = self.system.c();
        let a = self.system.a();
        let mut e_all = Vec::with_capacity(len * p * n);
        let mut z = DMatrix::<f64>::identity(n, n);
        let mut g = DMatrix::<f64>::zeros(n, n);
        let mut h = DMatrix::<f64>::zeros(n, n);
        let mut h_scale = 0.0;
        let mut phi_steady: Option<DMatrix<f64>> = None;
        let mut z_max = z.norm();
        let mut e_len = len;
        for k in 0..len {
            let z_norm = z.norm();
            z_max = z_max.max(z_norm);
            if k >= self.transient && z_norm <= E_CUT * z_max {
                e_len = k;
                break;
            }
            let st = self.step(k);
            let skip = self.missing.as_ref().is_some_and(|m| m[k]);
            // no output at a missing sample: no innovation of the free response
            let e = if skip { DMatrix::zeros(p, n) } else { c * &z }; // p x n
            e_all.extend(e.transpose().iter());
            let finv = DMatrix::from_row_slice(p, p, st.finv);
            g += e.transpose() * &finv * &e;
            let nn = st.null.len() / p.max(1);
            if nn > 0 {
                let nrows = DMatrix::from_row_slice(nn, p, st.null);
                let ne = &nrows * &e;
                h += ne.transpose() * &ne;
            }
            // constraints are judged against the size of the whole free response: a
            // null direction where it is (nearly) zero carries no usable constraint
            h_scale += e.norm_squared();
            let phi = if k < self.transient {
                a - DMatrix::from_row_slice(n, p, &self.gain[k * n * p..(k + 1) * n * p]) * c
            } else {
                phi_steady
                    .get_or_insert_with(|| a - DMatrix::from_row_slice(n, p, &self.steady.gain) * c)
                    .clone()
            };
            z = phi * z;
            if !z.iter().all(|v| v.is_finite()) {
                return Err(LtiError::param(
                    "system",
                    format!(
                        "the free response overflowed at sample {k}: the filter's closed loop \
                         A - K C is unstable (see `closed_loop_radius`)"
                    ),
                ));
            }
        }
        symmetrise(&mut g);
        symmetrise(&mut h);
        // constraints H x = h (least squares): x = H^+ h + U2 z
        let eye = DMatrix::<f64>::identity(n, n);
        let (hinv, hnull) = sym_pinv(&h, PINV_TOL * h_scale);
        let u2 = if hnull.is_empty() {
            DMatrix::zeros(n, 0)
        } else {
            DMatrix::from_columns(&hnull)
        };
        // minimise x^T G x - 2 b^T x over z
        let mut gr = u2.transpose() * &g * &u2;
        symmetrise(&mut gr);
        let (grinv, _) = sym_pinv(&gr, PINV_TOL * g.trace());
        let rb = &u2 * grinv * u2.transpose();
        let rh = (&eye - &rb * &g) * hinv;
        Ok(FreeInit {
            e: e_all,
            e_len,
            rb: row_major(&rb),
            rh: row_major(&rh),
            p0: row_major(p0),
        })
    }

    /// `b = sum_k E_k^T F_k^+ (e_k - E_k x)` and `h = sum_k E_k^T N_k^T N_k (e_k - E_k x)`.
    fn free_sums(&self, fr: &FreeInit, eps: &[f64], x: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (n, p) = (self.n, self.p);
        let mut bv = vec![0.0; n];
        let mut hv = vec![0.0; n];
        let mut e = vec![0.0; p];
        let mut w = vec![0.0; p];
        let mut sample = |k: usize, g: StepRef<'_>| {
            let ek = &fr.e[k * p * n..(k + 1) * p * n];
            e.copy_from_slice(&eps[k * p..(k + 1) * p]);
            mat_vec_add(ek, x, -1.0, &mut e);
            accumulate_free(ek, g, &e, &mut w, &mut bv, &mut hv);
        };
        let tl = self.transient.min(fr.e_len);
        for k in 0..tl {
            sample(k, self.step(k));
        }
        let steady = self.step(self.transient);
        for k in tl..fr.e_len {
            sample(k, steady);
        }
        (bv, hv)
    }

    /// The filter quantities of sample `k`.
    fn step(&self, k: usize) -> StepRef<'_> {
        let (n, p) = (self.n, self.p);
        if k < self.transient {
            let pp = p * p;
            let fws = (p + n) * (n + self.m + p);
            let bws = (self.m + n) * (p + n);
            StepRef {
                finv: &self.finv[k * pp..(k + 1) * pp],
                null: &self.null[k * pp..k * pp + self.nnull[k] * p],
                fw: &self.fw[k * fws..(k + 1) * fws],
                bw: &self.bw[k * bws..(k + 1) * bws],
            }
        } else {
            StepRef {
                finv: &self.steady.finv,
                null: &self.steady.null,
                fw: &self.steady.fw,
                bw: &self.steady.bw,
            }
        }
    }

    /// `(F_k^+, K_k)` (row-major) used at sample `k`, and the base prior `P_0` of a free
    /// initial state (row-major): for comparisons with reference recursions.
    #[cfg(test)]
    pub(crate) fn gains_at(&self, k: usize) -> (Vec<f64>, Vec<f64>, Option<Vec<f64>>) {
        let np = self.n * self.p;
        let gain = if k < self.transient {
            self.gain[k * np..(k + 1) * np].to_vec()
        } else {
            self.steady.gain.clone()
        };
        let p0 = self.free.as_ref().map(|f| f.p0.clone());
        (self.step(k).finv.to_vec(), gain, p0)
    }

    /// The record length `L` the smoother was built for.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Number of samples with stored (time-varying) gains; from this sample on the
    /// steady-state gains are used. `len` when the Riccati recursion did not converge
    /// within the record; 0 when the gains are constant from the start (e.g. `n = 0`).
    pub fn transient_len(&self) -> usize {
        self.transient
    }

    /// `true` for a smoother of empty records.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The largest spectral radius of the filter's closed loops `A - K_k C` over the samples
    /// (the stored gains and the steady-state ones; 0 for `n = 0` or an empty record).
    ///
    /// Both passes of [`smooth`](Self::smooth) propagate through these closed loops (the
    /// backward pass through their transposes), so rounding errors grow like `radius^len`
    /// when it exceeds 1 in the steady state: then the results of long records are
    /// unreliable (and `smooth` fails when they overflow). See the [module documentation](self#accuracy-and-stability)
    /// for when that happens: inherently for a zero initial state with transmission zeros
    /// outside the unit circle (as many effective inputs as outputs), and as a limitation
    /// of the recursion when null directions persist in the steady state.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::{DisturbanceSmoother, SmootherInitial, StateSpace};
    /// // y_k = v_k - 2 v_{k-1}: a zero at 2
    /// let sys = StateSpace::new(
    ///     DMatrix::zeros(1, 1),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::from_element(1, 1, -2.0),
    ///     DMatrix::from_element(1, 1, 1.0),
    /// )
    /// .unwrap();
    /// // x_0 = 0: v_k = y_k + 2 v_{k-1} exactly, an unstable recursion
    /// let s = DisturbanceSmoother::new(&sys, &[1.0], 100, SmootherInitial::Zero).unwrap();
    /// assert!((s.closed_loop_radius() - 2.0).abs() < 1e-12);
    /// // x_0 free: the stabilizing gains move the closed-loop pole to 1/2
    /// let s = DisturbanceSmoother::new(&sys, &[1.0], 100, SmootherInitial::Free).unwrap();
    /// assert!((s.closed_loop_radius() - 0.5).abs() < 1e-9);
    /// ```
    pub fn closed_loop_radius(&self) -> f64 {
        self.radius
    }

    /// The initial-state model the smoother was built with.
    pub fn initial(&self) -> SmootherInitial {
        self.initial
    }

    fn check_signal(&self, s: &Signal, what: &str, channels: usize) -> Result<(), LtiError> {
        if s.len() != self.len || s.channels() != channels {
            return Err(LtiError::dims(
                what,
                format!("{} samples x {channels} channels", self.len),
                format!("{} samples x {} channels", s.len(), s.channels()),
            ));
        }
        Ok(())
    }

    /// Smooths one record: writes the posterior mean of the inputs `v^ = mean + delta^` into
    /// `out` and returns the diagnostics (the estimated initial state for
    /// [`SmootherInitial::Free`], the null directions and the data's inconsistency).
    ///
    /// `y` has `len` samples and `p` channels, `mean` and `out` have `len` samples and `m`
    /// channels. Cost `O(L (n^2 + n m + n p + p^2))` plus `O(L' p n)` for the free initial
    /// state (see [`new`](Self::new)); `O(L p)` scratch memory.
    ///
    /// Errors: [`LtiError::DimensionMismatch`] for wrong shapes, [`LtiError::NonFinite`] for
    /// NaN or infinite values in `y` or `mean`, [`LtiError::InvalidParameter`] (`system`)
    /// when the recursions overflow (only possible when
    /// [`closed_loop_radius`](Self::closed_loop_radius) exceeds 1; `out` then holds
    /// non-finite values).
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::{DisturbanceSmoother, Signal, SmootherInitial, StateSpace};
    /// // y_k = x_k, x_{k+1} = 0.5 x_k + v_k, x_0 unknown
    /// let sys = StateSpace::new(
    ///     DMatrix::from_element(1, 1, 0.5),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::zeros(1, 1),
    /// )
    /// .unwrap();
    /// let s = DisturbanceSmoother::new(&sys, &[1.0], 3, SmootherInitial::Free).unwrap();
    /// // y = (4, 3, 1.5): x_0 = 4 (y_0 = C x_0 exactly), v_0 = 1, v_1 = 0
    /// let y = Signal::new(1, vec![4.0, 3.0, 1.5]).unwrap();
    /// let mut v = Signal::zeros(3, 1);
    /// let report = s.smooth(&y, &Signal::zeros(3, 1), &mut v).unwrap();
    /// let x0 = report.initial_state.unwrap();
    /// assert!((x0[0] - 4.0).abs() < 1e-12);
    /// assert!((v.get(0, 0) - 1.0).abs() < 1e-12 && v.get(1, 0).abs() < 1e-12);
    /// // v_2 does not affect any output: it stays at its mean
    /// assert_eq!(v.get(2, 0), 0.0);
    /// ```
    pub fn smooth(
        &self,
        y: &Signal,
        mean: &Signal,
        out: &mut Signal,
    ) -> Result<SmoothReport, LtiError> {
        let (n, m, p, len) = (self.n, self.m, self.p, self.len);
        self.check_signal(y, "output data y", p)?;
        self.check_signal(mean, "input mean", m)?;
        self.check_signal(out, "smoothed inputs (out)", m)?;
        y.check_finite("output data y")?;
        mean.check_finite("input mean")?;

        // forward (mean) pass on y' = y - T mean, fused with the mean response: with
        // s_k = a_k + (state of T mean), e_k = y_k - C s_k - D m_k and
        // s_{k+1} = A s_k + B m_k + K_k e_k, one packed product per sample
        let (y_s, mean_s) = (y.as_slice(), mean.as_slice());
        let mut eps = vec![0.0; len * p];
        let mut st = vec![0.0; n];
        let mut w = vec![0.0; p + n];
        let tl = self.transient.min(len);
        let free = self.free.as_ref();
        // b and h of the free initial state, accumulated on the way
        let (mut bv, mut hv, mut fbuf) = (vec![0.0; n], vec![0.0; n], vec![0.0; p]);
        let mut forward = |k: usize, g: StepRef<'_>| {
            let mk = &mean_s[k * m..(k + 1) * m];
            let yk = &y_s[k * p..(k + 1) * p];
            mat_vec3(g.fw, &st, mk, yk, &mut w);
            let (e, s_next) = w.split_at(p);
            for (o, &v) in eps[k * p..(k + 1) * p].iter_mut().zip(e) {
                *o = v;
            }
            if let Some(fr) = free
                && k < fr.e_len
            {
                let ek = &fr.e[k * p * n..(k + 1) * p * n];
                accumulate_free(ek, g, e, &mut fbuf, &mut bv, &mut hv);
            }
            for (o, &v) in st.iter_mut().zip(s_next) {
                *o = v;
            }
        };
        for k in 0..tl {
            forward(k, self.step(k));
        }
        let steady = self.step(self.transient);
        for k in tl..len {
            forward(k, steady);
        }

        // the free initial state, with one step of iterative refinement on the residual
        // innovations (the maps R_b, R_h come from normal equations)
        let x0 = free.map(|fr| {
            let mut x0 = vec![0.0; n];
            mat_vec_add(&fr.rb, &bv, 1.0, &mut x0);
            mat_vec_add(&fr.rh, &hv, 1.0, &mut x0);
            let (bv, hv) = self.free_sums(fr, &eps, &x0);
            mat_vec_add(&fr.rb, &bv, 1.0, &mut x0);
            mat_vec_add(&fr.rh, &hv, 1.0, &mut x0);
            x0
        });

        // backward (costate) pass, one packed product per sample on [e_k; r_k]
        let mut r = vec![0.0; n];
        let mut e_buf = vec![0.0; p];
        let mut w = vec![0.0; m + n];
        let mut max_inc = 0.0f64;
        let out_s = out.as_mut_slice();
        let x0_ref = x0.as_deref();
        let mut backward = |k: usize, g: StepRef<'_>| {
            let mut e = &eps[k * p..(k + 1) * p];
            if let (Some(fr), Some(x0)) = (free, x0_ref)
                && k < fr.e_len
            {
                for (o, &v) in e_buf.iter_mut().zip(e) {
                    *o = v;
                }
                mat_vec_add(&fr.e[k * p * n..(k + 1) * p * n], x0, -1.0, &mut e_buf);
                e = &e_buf;
            }
            if !g.null.is_empty() {
                for nr in g.null.chunks_exact(p) {
                    max_inc = max_inc.max(dot(nr, e).abs());
                }
            }
            mat_vec3(g.bw, e, &r, &[], &mut w);
            let (dv, r_next) = w.split_at(m);
            let mk = &mean_s[k * m..(k + 1) * m];
            for ((o, &mj), &dj) in out_s[k * m..(k + 1) * m].iter_mut().zip(mk).zip(dv) {
                *o = mj + dj;
            }
            for (o, &v) in r.iter_mut().zip(r_next) {
                *o = v;
            }
        };
        for k in (tl..len).rev() {
            backward(k, steady);
        }
        for k in (0..tl).rev() {
            backward(k, self.step(k));
        }

        // x_0 = xi + eta: add the smoothed base-prior part eta^ = P_0 r_{-1} (zero in exact
        // arithmetic: the free part xi absorbs everything)
        let mut x0 = x0;
        if let (Some(fr), Some(x0)) = (free, x0.as_mut()) {
            for i in 0..n {
                x0[i] += dot(&fr.p0[i * n..(i + 1) * n], &r);
            }
        }
        let x0_bad = x0
            .as_ref()
            .is_some_and(|x| x.iter().any(|v| !v.is_finite()));
        if let Some(i) = out_s
            .iter()
            .position(|v| !v.is_finite())
            .or(x0_bad.then_some(0))
        {
            return Err(LtiError::param(
                "system",
                format!(
                    "the smoother overflowed (non-finite smoothed input at sample {}, channel \
                     {}): its closed loop A - K C has spectral radius {:.3} > 1, see \
                     `closed_loop_radius`",
                    i / m.max(1),
                    i % m.max(1),
                    self.radius
                ),
            ));
        }
        Ok(SmoothReport {
            initial_state: x0,
            null_directions: self.null_total,
            max_inconsistency: max_inc,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LinearSystem;
    use crate::testing::{SplitMix64, random_signal, random_stable_system};
    use proptest::prelude::*;

    /// A random test problem: system, variances, mean, true x_0, data.
    struct Problem {
        sys: StateSpace,
        q: Vec<f64>,
        mean: Signal,
        x0: Vec<f64>,
        y: Signal,
    }

    fn initial_of(free: bool) -> SmootherInitial {
        if free {
            SmootherInitial::Free
        } else {
            SmootherInitial::Zero
        }
    }

    /// Random system (optionally `D = 0`), variances with some zeros, and *consistent* data
    /// `y = T v + O x_0` with `v_j = mean_j` wherever `q_j = 0`.
    fn problem(
        seed: u64,
        n: usize,
        m: usize,
        p: usize,
        len: usize,
        zero_d: bool,
        free: bool,
    ) -> Problem {
        let mut sys = random_stable_system(seed, n, m, p, 0.9);
        if zero_d {
            sys = StateSpace::new(
                sys.a().clone(),
                sys.b().clone(),
                sys.c().clone(),
                DMatrix::zeros(p, m),
            )
            .unwrap();
        }
        let mut rng = SplitMix64::new(seed ^ 0xABCD);
        let mut q: Vec<f64> = (0..m).map(|_| rng.uniform_in(0.2, 2.0)).collect();
        if m >= 2 && rng.uniform() < 0.6 {
            let j = (rng.next_u64() % m as u64) as usize;
            q[j] = 0.0;
        }
        let mean = random_signal(seed ^ 3, len, m);
        let noise = random_signal(seed ^ 5, len, m);
        let v = Signal::from_fn(len, m, |k, j| {
            mean.get(k, j) + q[j].sqrt() * noise.get(k, j)
        });
        let x0: Vec<f64> = if free {
            (0..n).map(|_| rng.uniform_in(-1.0, 1.0)).collect()
        } else {
            vec![0.0; n]
        };
        let (y, _) = sys.simulate_from(&x0, &v).unwrap();
        Problem {
            sys,
            q,
            mean,
            x0,
            y,
        }
    }

    /// `true` when the smoother's recursions are stable for this problem
    /// (see [`DisturbanceSmoother::closed_loop_radius`]).
    fn stable(pb: &Problem, free: bool) -> bool {
        DisturbanceSmoother::new(&pb.sys, &pb.q, pb.y.len(), initial_of(free))
            .unwrap()
            .closed_loop_radius()
            < 0.99
    }

    /// The first of 50 seeds from `seed` giving a stable problem.
    fn stable_problem(
        seed: u64,
        n: usize,
        m: usize,
        p: usize,
        len: usize,
        zero_d: bool,
        free: bool,
    ) -> Problem {
        (seed..seed + 50)
            .map(|s| problem(s, n, m, p, len, zero_d, free))
            .find(|pb| stable(pb, free))
            .unwrap_or_else(|| panic!("no stable problem for n {n} m {m} p {p} zero_d {zero_d}"))
    }

    /// Moore–Penrose pseudo-inverse by faer's SVD (nalgebra's SVD proved inaccurate on
    /// some of these rank-deficient matrices); singular values below `1e-10 scale` are
    /// dropped (`scale`: the largest singular value when `None`). Checked against the
    /// Penrose condition `A A^+ A = A` (to rounding).
    fn pinv(a: &DMatrix<f64>, scale: Option<f64>) -> DMatrix<f64> {
        let (r, c) = a.shape();
        if r == 0 || c == 0 {
            return DMatrix::zeros(c, r);
        }
        let fa = faer::Mat::from_fn(r, c, |i, j| a[(i, j)]);
        let svd = fa.thin_svd().expect("SVD converges");
        let (u, sv, v) = (svd.U(), svd.S().column_vector(), svd.V());
        let k = sv.nrows();
        let smax = (0..k).map(|l| sv[l]).fold(0.0, f64::max);
        let scale = scale.unwrap_or(smax);
        let keep: Vec<usize> = (0..k).filter(|&l| sv[l] > 1e-10 * scale).collect();
        let ap = DMatrix::from_fn(c, r, |i, j| {
            keep.iter().map(|&l| v[(i, l)] * u[(j, l)] / sv[l]).sum()
        });
        // A A^+ A - A is the dropped part, plus rounding that grows with the condition
        // number of the kept part
        let kappa = keep.iter().map(|&l| smax / sv[l]).fold(1.0, f64::max);
        let dropped = (0..k)
            .filter(|l| !keep.contains(l))
            .map(|l| sv[l] * sv[l])
            .sum::<f64>()
            .sqrt();
        let penrose = (a * &ap * a - a).norm();
        assert!(
            penrose <= 1.01 * dropped + 1e-12 * kappa * a.norm().max(scale),
            "reference pseudo-inverse inaccurate: |A A+ A - A| = {penrose:.3e}"
        );
        ap
    }

    /// Condition number of `a` over its nonzero singular values (above `1e-14 scale`: only
    /// structural zeros, at rounding level, are left out); 1 for a zero matrix.
    fn cond(a: &DMatrix<f64>, scale: Option<f64>) -> f64 {
        if a.is_empty() {
            return 1.0;
        }
        let fa = faer::Mat::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)]);
        let sv = fa.singular_values().expect("SVD converges");
        let smax = sv.iter().copied().fold(0.0, f64::max);
        let scale = scale.unwrap_or(smax);
        let smin = sv
            .iter()
            .copied()
            .filter(|&v| v > 1e-14 * scale)
            .fold(f64::INFINITY, f64::min);
        if smin.is_finite() { smax / smin } else { 1.0 }
    }

    /// Smallest singular value of `a` above `1e-14 scale` (`scale` when there is none).
    fn smallest_singular(a: &DMatrix<f64>, scale: f64) -> f64 {
        if a.is_empty() {
            return scale;
        }
        let fa = faer::Mat::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)]);
        let sv = fa.singular_values().expect("SVD converges");
        let smin = sv
            .iter()
            .copied()
            .filter(|&v| v > 1e-14 * scale)
            .fold(f64::INFINITY, f64::min);
        if smin.is_finite() { smin } else { scale }
    }

    /// Free response matrix `O` (`L p x n`, rows `C A^k`).
    fn free_response(sys: &StateSpace, len: usize) -> DMatrix<f64> {
        let (n, p) = (sys.order(), sys.outputs());
        let mut o = DMatrix::zeros(len * p, n);
        let mut cak = sys.c().clone();
        for k in 0..len {
            o.view_mut((k * p, 0), (p, n)).copy_from(&cak);
            cak = &cak * sys.a();
        }
        o
    }

    /// Dense reference `(v^, x^_0)`: minimises `|Q^{-1/2}(v - mean)|^2` subject to
    /// `y = T v (+ O x_0)`, using only the data rows `rows` (all when `None`), by SVD
    /// pseudo-inverses: with `S = T Q^{1/2}`, `w = (Pi S)^+ Pi y'`, `v = mean + Q^{1/2} w`,
    /// `x_0 = O^+ (y' - S w)`, `Pi` the projector onto the complement of `range(O)`.
    ///
    /// Also returns the condition number of the problem: that of `S` (zero initial state),
    /// or the larger of those of `Pi S` and `O` (free initial state).
    fn dense(pb: &Problem, free: bool, rows: Option<&[usize]>) -> (Vec<f64>, Vec<f64>, f64) {
        let sys = &pb.sys;
        let (n, m) = (sys.order(), sys.inputs());
        let len = pb.y.len();
        let t = sys.toeplitz_dense(len);
        let sq = DVector::from_fn(len * m, |i, _| pb.q[i % m].sqrt());
        let mut s = t.clone();
        for j in 0..len * m {
            s.column_mut(j).scale_mut(sq[j]);
        }
        let mvec = DVector::from_column_slice(pb.mean.as_slice());
        let mut yp = DVector::from_column_slice(pb.y.as_slice()) - &t * &mvec;
        let mut o = free_response(sys, len);
        if let Some(rows) = rows {
            s = s.select_rows(rows.iter());
            yp = yp.select_rows(rows.iter());
            o = o.select_rows(rows.iter());
        }
        let (w, x0, kappa) = if free && n > 0 {
            let opinv = pinv(&o, None);
            let proj = DMatrix::identity(o.nrows(), o.nrows()) - &o * &opinv;
            // thresholds relative to S itself: Pi S can be zero up to rounding
            let s_norm = s.norm();
            let ps = &proj * &s;
            let w = pinv(&ps, Some(s_norm)) * (&proj * &yp);
            let x0 = &opinv * (&yp - &s * &w);
            // sensitivity of w to y: |S| / sigma_min(Pi S) (Pi S can be much smaller
            // than S when range(S) nearly lies in range(O))
            let kappa = cond(&ps, Some(s_norm))
                .max(s_norm / smallest_singular(&ps, s_norm))
                .max(cond(&o, None));
            (w, x0.as_slice().to_vec(), kappa)
        } else {
            let x0 = vec![0.0; if free { n } else { 0 }];
            (pinv(&s, None) * &yp, x0, cond(&s, None))
        };
        let v = mvec + sq.component_mul(&w);
        (v.as_slice().to_vec(), x0, kappa)
    }

    fn max_abs(v: &[f64]) -> f64 {
        v.iter().fold(0.0, |a, &b| a.max(b.abs()))
    }

    fn max_diff(a: &[f64], b: &[f64]) -> f64 {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .fold(0.0, |acc, (x, y)| acc.max((x - y).abs()))
    }

    fn run(pb: &Problem, initial: SmootherInitial) -> (Signal, SmoothReport) {
        let len = pb.y.len();
        let s = DisturbanceSmoother::new(&pb.sys, &pb.q, len, initial).unwrap();
        let mut out = Signal::zeros(len, pb.sys.inputs());
        let rep = s.smooth(&pb.y, &pb.mean, &mut out).unwrap();
        (out, rep)
    }

    /// Compares the smoother with the dense reference (relative to the size of the
    /// correction `v^ - mean` and of `x^_0`) and checks feasibility: `T v^ + O x^_0 = y`.
    ///
    /// The filter works with covariances (`F = C P C^T + D Q D^T`, normal equations for
    /// `x_0`), so its rounding error grows like `eps kappa^2` with the problem's condition
    /// number `kappa`, against `eps kappa` for the SVD reference: the tolerances are
    /// `max(tol, 100 eps kappa^2)` (so `tol = 1e-8` holds as such up to `kappa ~ 670`).
    fn check_against_dense(pb: &Problem, free: bool, tol: f64) -> Result<(), String> {
        let (out, rep) = run(pb, initial_of(free));
        let (v_ref, x0_ref, kappa) = dense(pb, free, None);
        let floor = 100.0 * f64::EPSILON * kappa * kappa;
        let tol = tol.max(floor);
        let delta_ref: Vec<f64> = v_ref
            .iter()
            .zip(pb.mean.as_slice())
            .map(|(v, m)| v - m)
            .collect();
        let what = format!(
            "kappa {kappa:.2e}, n {} m {} p {} q {:?} D = 0: {} free {free}",
            pb.sys.order(),
            pb.sys.inputs(),
            pb.sys.outputs(),
            pb.q,
            pb.sys.d().iter().all(|&v| v == 0.0)
        );
        let scale = max_abs(&delta_ref).max(1e-3 * max_abs(pb.y.as_slice()));
        let err = max_diff(out.as_slice(), &v_ref);
        if err > tol * scale {
            return Err(format!(
                "inputs differ by {err:.3e} (scale {scale:.3e}); {what}"
            ));
        }
        let x0 = rep.initial_state.clone().unwrap_or_default();
        assert_eq!(x0.len(), x0_ref.len());
        let xerr = max_diff(&x0, &x0_ref);
        if xerr > tol * max_abs(&x0_ref).max(1.0) {
            return Err(format!(
                "initial states differ by {xerr:.3e}: {x0:?} vs {x0_ref:?}; {what}"
            ));
        }
        let x0s = if free { x0 } else { vec![0.0; pb.sys.order()] };
        let (y_hat, _) = pb.sys.simulate_from(&x0s, &out).unwrap();
        let ferr = max_diff(y_hat.as_slice(), pb.y.as_slice());
        if ferr > 1e-9f64.max(floor) * max_abs(pb.y.as_slice()) {
            return Err(format!("data not reproduced: {ferr:.3e}; {what}"));
        }
        if rep.max_inconsistency > 1e-9f64.max(floor) * max_abs(pb.y.as_slice()) {
            return Err(format!(
                "consistent data reported inconsistent: {rep:?}; {what}"
            ));
        }
        Ok(())
    }

    fn dense_sweep(free: bool, seed0: u64) {
        let mut seed = seed0;
        for n in 0..=3 {
            for m in 1..=3 {
                for p in 1..=2 {
                    for zero_d in [false, true] {
                        seed += 1000;
                        let pb = stable_problem(seed, n, m, p, 30, zero_d, free);
                        check_against_dense(&pb, free, 1e-8).unwrap();
                    }
                }
            }
        }
    }

    #[test]
    fn matches_dense_least_squares_zero_initial_state() {
        dense_sweep(false, 0);
    }

    #[test]
    fn matches_dense_least_squares_free_initial_state() {
        dense_sweep(true, 500_000);
    }

    #[test]
    fn free_initial_state_is_recovered_when_determined() {
        // D = 0 and p = n: y_0 = C x_0 pins x_0 exactly (the null directions of F_0 act as
        // constraints), whatever the inputs
        let len = 20;
        let pb = (77..200)
            .map(|seed| {
                let sys = random_stable_system(seed, 2, 1, 2, 0.8);
                let sys = StateSpace::new(
                    sys.a().clone(),
                    sys.b().clone(),
                    sys.c().clone(),
                    DMatrix::zeros(2, 1),
                )
                .unwrap();
                let v = random_signal(seed + 1, len, 1);
                let x0 = vec![0.7, -1.3];
                let (y, _) = sys.simulate_from(&x0, &v).unwrap();
                Problem {
                    sys,
                    q: vec![1.5],
                    mean: Signal::zeros(len, 1),
                    x0,
                    y,
                }
            })
            .find(|pb| stable(pb, true))
            .unwrap();
        let (out, rep) = run(&pb, SmootherInitial::Free);
        let x0 = rep.initial_state.clone().unwrap();
        assert!(max_diff(&x0, &pb.x0) < 1e-12, "{x0:?} vs {:?}", pb.x0);
        assert!(rep.null_directions >= 2, "{rep:?}");
        let (v_ref, _, _) = dense(&pb, true, None);
        assert!(max_diff(out.as_slice(), &v_ref) < 1e-9);
    }

    #[test]
    fn unobservable_initial_directions_get_zero() {
        // x = (x_a, x_b) with x_b invisible: A block-diagonal, C = [1, 0]
        let a = DMatrix::from_row_slice(2, 2, &[0.8, 0.0, 0.0, 0.5]);
        let b = DMatrix::from_row_slice(2, 1, &[1.0, 1.0]);
        let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        // D = 2: the zero 0.8 - 1/2 is inside the unit circle (stable closed loop)
        let d = DMatrix::from_element(1, 1, 2.0);
        let sys = StateSpace::new(a, b, c, d).unwrap();
        let len = 25;
        let v = random_signal(9, len, 1);
        let (y, _) = sys.simulate_from(&[0.5, 2.0], &v).unwrap();
        let pb = Problem {
            sys,
            q: vec![1.0],
            mean: Signal::zeros(len, 1),
            x0: vec![0.5, 2.0],
            y,
        };
        let (out, rep) = run(&pb, SmootherInitial::Free);
        let x0 = rep.initial_state.unwrap();
        assert!(x0[1].abs() < 1e-14, "{x0:?}");
        let (v_ref, x0_ref, _) = dense(&pb, true, None);
        assert!(max_diff(&x0, &x0_ref) < 1e-9);
        assert!(max_diff(out.as_slice(), &v_ref) < 1e-9);
    }

    #[test]
    fn singular_first_innovation_is_reported_and_ignored() {
        // D = 0 and x_0 = 0: F_0 = 0, y_0 cannot be reached by any input
        let len = 30;
        for (seed, n, m, p) in [(11, 2, 1, 1), (12_000, 3, 2, 2), (13_000, 1, 2, 1)] {
            let mut pb = stable_problem(seed, n, m, p, len, true, false);
            // make y_0 inconsistent
            for i in 0..p {
                pb.y.sample_mut(0)[i] = 0.25 + i as f64;
            }
            let (out, rep) = run(&pb, SmootherInitial::Zero);
            assert!(rep.null_directions >= p, "{rep:?}");
            // the null directions at sample 0 are an orthonormal basis of R^p
            let norm_y0 = pb.y.sample(0).iter().map(|v| v * v).sum::<f64>().sqrt();
            assert!(
                rep.max_inconsistency >= norm_y0 / (p as f64).sqrt() - 1e-12
                    && rep.max_inconsistency <= norm_y0 + 1e-12,
                "{rep:?}"
            );
            // the reachable samples 1 .. L-1 decide the answer
            let rows: Vec<usize> = (p..len * p).collect();
            let (v_ref, _, kappa) = dense(&pb, false, Some(&rows));
            assert!(kappa < 1e3, "kappa {kappa:.2e}");
            let scale = max_abs(&v_ref).max(1.0);
            let err = max_diff(out.as_slice(), &v_ref);
            assert!(err <= 1e-8 * scale, "error {err:.3e}");
            // and they are reproduced
            let y_hat = pb.sys.simulate(&out).unwrap();
            let ferr = max_diff(&y_hat.as_slice()[p..], &pb.y.as_slice()[p..]);
            assert!(ferr <= 1e-9 * max_abs(pb.y.as_slice()), "{ferr:.3e}");
        }
    }

    #[test]
    fn steady_state_matches_time_varying_gains() {
        let len = 5000;
        for (seed, n, m, p, zero_d, free) in [
            (21, 2, 2, 1, false, false),
            (22_000, 3, 2, 2, true, true),
            (23_000, 2, 1, 2, false, false),
            (24_000, 1, 3, 1, true, true),
            (25_000, 3, 3, 2, false, true),
        ] {
            let initial = initial_of(free);
            // pick a stable problem on a short record, then use the long one
            let seed = (seed..seed + 50)
                .find(|&s| stable(&problem(s, n, m, p, 30, zero_d, free), free))
                .unwrap();
            let pb = problem(seed, n, m, p, len, zero_d, free);
            let fast = DisturbanceSmoother::new(&pb.sys, &pb.q, len, initial).unwrap();
            let slow =
                DisturbanceSmoother::build(&pb.sys, &pb.q, len, initial, false, &[], None).unwrap();
            assert!(fast.transient_len() < len / 2, "{fast:?}");
            assert_eq!(slow.transient_len(), len);
            let mut o1 = Signal::zeros(len, m);
            let mut o2 = Signal::zeros(len, m);
            let r1 = fast.smooth(&pb.y, &pb.mean, &mut o1).unwrap();
            let r2 = slow.smooth(&pb.y, &pb.mean, &mut o2).unwrap();
            assert_eq!(r1.null_directions, r2.null_directions);
            let err = max_diff(o1.as_slice(), o2.as_slice());
            assert!(err <= 1e-9 * max_abs(o2.as_slice()), "error {err:.3e}");
            if let (Some(a), Some(b)) = (&r1.initial_state, &r2.initial_state) {
                assert!(max_diff(a, b) <= 1e-9 * max_abs(b).max(1.0));
            }
            // feasibility over the long record
            let x0 = r1.initial_state.unwrap_or(vec![0.0; n]);
            let (y_hat, _) = pb.sys.simulate_from(&x0, &o1).unwrap();
            let ferr = max_diff(y_hat.as_slice(), pb.y.as_slice());
            assert!(
                ferr <= 1e-9 * max_abs(pb.y.as_slice()),
                "feasibility {ferr:.3e}"
            );
        }
        // and a smoother that went steady matches the dense reference on a short record
        let pb = stable_problem(26, 2, 2, 1, 80, false, false);
        let s = DisturbanceSmoother::new(&pb.sys, &pb.q, 80, SmootherInitial::Zero).unwrap();
        assert!(s.transient_len() < 80, "{s:?}");
        check_against_dense(&pb, false, 1e-8).unwrap();
    }

    #[test]
    fn posterior_mean_of_a_static_example() {
        // y_0 = v_0 + v_1 with q = (1, 3), mean (1, 0), y = 5: v^ = mean + q (5 - 1) / 4
        let sys = StateSpace::static_gain(DMatrix::from_row_slice(1, 2, &[1.0, 1.0])).unwrap();
        let s = DisturbanceSmoother::new(&sys, &[1.0, 3.0], 1, SmootherInitial::Zero).unwrap();
        assert_eq!(s.transient_len(), 0);
        let mut out = Signal::zeros(1, 2);
        let rep = s
            .smooth(
                &Signal::new(1, vec![5.0]).unwrap(),
                &Signal::new(2, vec![1.0, 0.0]).unwrap(),
                &mut out,
            )
            .unwrap();
        assert!((out.get(0, 0) - 2.0).abs() < 1e-14);
        assert!((out.get(0, 1) - 3.0).abs() < 1e-14);
        assert_eq!(rep.null_directions, 0);
        assert_eq!(rep.initial_state, None);
    }

    #[test]
    fn degenerate_shapes() {
        // empty record
        let sys = random_stable_system(31, 2, 2, 1, 0.9);
        for initial in [SmootherInitial::Zero, SmootherInitial::Free] {
            let s = DisturbanceSmoother::new(&sys, &[1.0, 1.0], 0, initial).unwrap();
            assert!(s.is_empty());
            let mut out = Signal::zeros(0, 2);
            let rep = s
                .smooth(&Signal::zeros(0, 1), &Signal::zeros(0, 2), &mut out)
                .unwrap();
            assert_eq!(rep.null_directions, 0);
        }
        // no outputs: the inputs stay at their mean
        let sys0 = random_stable_system(32, 2, 2, 0, 0.9);
        let s = DisturbanceSmoother::new(&sys0, &[1.0, 2.0], 10, SmootherInitial::Free).unwrap();
        let mean = random_signal(33, 10, 2);
        let mut out = Signal::zeros(10, 2);
        let rep = s.smooth(&Signal::zeros(10, 0), &mean, &mut out).unwrap();
        assert_eq!(out, mean);
        assert_eq!(rep.initial_state, Some(vec![0.0, 0.0]));
        // all variances zero: nothing can move, x_0 alone explains the data
        let len = 15;
        let sys = random_stable_system(34, 2, 1, 1, 0.9);
        let mean = random_signal(35, len, 1);
        let (y, _) = sys.simulate_from(&[0.3, -0.4], &mean).unwrap();
        let pb = Problem {
            sys,
            q: vec![0.0],
            mean,
            x0: vec![0.3, -0.4],
            y,
        };
        let (out, rep) = run(&pb, SmootherInitial::Free);
        assert_eq!(out, pb.mean);
        assert_eq!(rep.null_directions, len);
        assert!(max_diff(&rep.initial_state.unwrap(), &pb.x0) < 1e-9);
        assert!(rep.max_inconsistency < 1e-9);
    }

    #[test]
    fn rejects_bad_arguments() {
        let sys = random_stable_system(41, 2, 2, 1, 0.9);
        let z = SmootherInitial::Zero;
        assert!(matches!(
            DisturbanceSmoother::new(&sys, &[1.0], 5, z),
            Err(LtiError::DimensionMismatch { .. })
        ));
        for bad in [-1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                DisturbanceSmoother::new(&sys, &[1.0, bad], 5, z),
                Err(LtiError::InvalidParameter { .. })
            ));
        }
        let s = DisturbanceSmoother::new(&sys, &[1.0, 0.0], 5, z).unwrap();
        let mut out = Signal::zeros(5, 2);
        let y = Signal::zeros(5, 1);
        let mean = Signal::zeros(5, 2);
        assert!(s.smooth(&Signal::zeros(4, 1), &mean, &mut out).is_err());
        assert!(s.smooth(&Signal::zeros(5, 2), &mean, &mut out).is_err());
        assert!(s.smooth(&y, &Signal::zeros(5, 1), &mut out).is_err());
        assert!(s.smooth(&y, &mean, &mut Signal::zeros(6, 2)).is_err());
        let mut ynan = y.clone();
        ynan.sample_mut(3)[0] = f64::NAN;
        assert!(matches!(
            s.smooth(&ynan, &mean, &mut out),
            Err(LtiError::NonFinite { .. })
        ));
        assert!(s.smooth(&y, &mean, &mut out).is_ok());
    }

    /// A transmission zero outside the unit circle with as many effective inputs as outputs:
    /// for `x_0 = 0` the problem is ill-conditioned (the exact answer involves the unstable
    /// inverse), the recursions are unstable (`closed_loop_radius = 2`) and a long record
    /// overflows, reported as an error. With a free initial state the problem is
    /// well-conditioned, and the base prior `P_0 > 0` makes the filter converge to the
    /// stabilizing gains: long records work and short ones match the dense solution.
    #[test]
    fn zero_outside_the_unit_circle() {
        // y_k = v_k - 2 v_{k-1} (- 2 x_0 at k = 0)
        let sys = StateSpace::new(
            DMatrix::zeros(1, 1),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, -2.0),
            DMatrix::from_element(1, 1, 1.0),
        )
        .unwrap();
        let len = 2000;
        let short = DisturbanceSmoother::new(&sys, &[1.0], 30, SmootherInitial::Zero).unwrap();
        assert!((short.closed_loop_radius() - 2.0).abs() < 1e-12);
        let s = DisturbanceSmoother::new(&sys, &[1.0], len, SmootherInitial::Zero).unwrap();
        let y = random_signal(61, len, 1);
        let mut out = Signal::zeros(len, 1);
        let res = s.smooth(&y, &Signal::zeros(len, 1), &mut out);
        assert!(
            matches!(res, Err(LtiError::InvalidParameter { .. })),
            "{res:?}"
        );

        let free = DisturbanceSmoother::new(&sys, &[1.0], len, SmootherInitial::Free).unwrap();
        // the stabilizing gains flip the zero to 1/2
        assert!((free.closed_loop_radius() - 0.5).abs() < 1e-9, "{free:?}");
        assert!(free.transient_len() < 100);
        let rep = free.smooth(&y, &Signal::zeros(len, 1), &mut out).unwrap();
        let (y_hat, _) = sys
            .simulate_from(rep.initial_state.as_ref().unwrap(), &out)
            .unwrap();
        assert!(max_diff(y_hat.as_slice(), y.as_slice()) < 1e-12);
        let pb = Problem {
            sys: sys.clone(),
            q: vec![1.0],
            mean: Signal::zeros(30, 1),
            x0: vec![0.0],
            y: y.slice(0..30),
        };
        check_against_dense(&pb, true, 1e-8).unwrap();
    }

    /// Timing at `L = 1e5`, `n = 2`, `m = 2`, `p = 1` (run with `--ignored --nocapture`).
    #[test]
    #[ignore]
    fn smooth_timing_long_record() {
        let len = 100_000;
        for free in [false, true] {
            let initial = initial_of(free);
            let seed = (51..101)
                .find(|&s| stable(&problem(s, 2, 2, 1, 30, false, free), free))
                .unwrap();
            let pb = problem(seed, 2, 2, 1, len, false, free);
            let t0 = std::time::Instant::now();
            let s = DisturbanceSmoother::new(&pb.sys, &pb.q, len, initial).unwrap();
            let t_new = t0.elapsed();
            let mut out = Signal::zeros(len, 2);
            let mut times = Vec::new();
            for _ in 0..20 {
                let t = std::time::Instant::now();
                s.smooth(&pb.y, &pb.mean, &mut out).unwrap();
                times.push(t.elapsed().as_secs_f64() * 1e3);
            }
            times.sort_by(f64::total_cmp);
            // reference: one plain simulation T v of the same record
            let mut ysim = vec![0.0; len];
            let mut tsim = f64::INFINITY;
            for _ in 0..20 {
                let t = std::time::Instant::now();
                pb.sys.apply(pb.mean.as_slice(), &mut ysim);
                tsim = tsim.min(t.elapsed().as_secs_f64() * 1e3);
            }
            println!("reference: one simulation T v takes {tsim:.3} ms");
            println!(
                "{initial:?} (q {:?}): new {:.3} ms (transient {}), smooth min {:.3} ms, median {:.3} ms",
                pb.q,
                t_new.as_secs_f64() * 1e3,
                s.transient_len(),
                times[0],
                times[10]
            );
        }
    }

    /// The adjoint channels give the derivative of the minimal cost with respect to the mean
    /// of a fixed input (central differences), for both initial-state models, and leave the
    /// other inputs as the plain smoother computes them.
    #[test]
    fn adjoint_channels_give_the_cost_gradient() {
        for free in [false, true] {
            let len = 25;
            let mut pb = stable_problem(11, 2, 3, 1, len, false, free);
            pb.q[2] = 0.0;
            pb.q[0] = pb.q[0].max(0.2);
            pb.q[1] = pb.q[1].max(0.2);
            let initial = initial_of(free);
            let plain = DisturbanceSmoother::new(&pb.sys, &pb.q, len, initial).unwrap();
            let adj =
                DisturbanceSmoother::with_adjoint(&pb.sys, &pb.q, len, initial, &[2]).unwrap();
            let mut v = Signal::zeros(len, 3);
            let mut va = Signal::zeros(len, 3);
            plain.smooth(&pb.y, &pb.mean, &mut v).unwrap();
            adj.smooth(&pb.y, &pb.mean, &mut va).unwrap();
            let cost = |mean: &Signal| {
                let mut out = Signal::zeros(len, 3);
                plain.smooth(&pb.y, mean, &mut out).unwrap();
                (0..len)
                    .map(|k| {
                        (0..2)
                            .map(|j| (out.get(k, j) - mean.get(k, j)).powi(2) / pb.q[j])
                            .sum::<f64>()
                    })
                    .sum::<f64>()
                    / 2.0
            };
            let scale = (0..len).map(|k| va.get(k, 2).abs()).fold(1e-300, f64::max);
            for k in 0..len {
                for j in 0..2 {
                    assert!((v.get(k, j) - va.get(k, j)).abs() < 1e-12 * (1.0 + v.get(k, j).abs()));
                }
                let h = 1e-5;
                let mut up = pb.mean.clone();
                up.sample_mut(k)[2] += h;
                let mut down = pb.mean.clone();
                down.sample_mut(k)[2] -= h;
                let fd = (cost(&up) - cost(&down)) / (2.0 * h);
                let g = va.get(k, 2) - pb.mean.get(k, 2);
                assert!(
                    (fd + g).abs() < 1e-6 * scale,
                    "free {free}, k {k}: finite difference {fd}, adjoint {g}"
                );
            }
        }
        let sys = random_stable_system(3, 1, 2, 1, 0.9);
        assert!(
            DisturbanceSmoother::with_adjoint(&sys, &[1.0, 0.0], 5, SmootherInitial::Zero, &[2])
                .is_err()
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Missing samples: the smoother equals the dense least-squares solution on the rows
        /// that remain (a contiguous block and isolated samples left out).
        #[test]
        fn smoother_with_missing_samples_matches_dense_least_squares(
            seed in any::<u64>(), n in 1usize..=3, m in 1usize..=3, p in 1usize..=2,
            len in 8usize..=30, free in any::<bool>(), start in 0usize..8, width in 1usize..6,
        ) {
            let pb = problem(seed, n, m, p, len, false, free);
            prop_assume!(stable(&pb, free));
            let mut missing = vec![false; len];
            for k in start..(start + width).min(len) {
                missing[k] = true;
            }
            missing[len - 1] = seed % 2 == 0;
            let rows: Vec<usize> = (0..len * p).filter(|r| !missing[r / p]).collect();
            let s = DisturbanceSmoother::with_missing(
                &pb.sys, &pb.q, len, initial_of(free), &[], &missing,
            ).unwrap();
            let mut out = Signal::zeros(len, m);
            let rep = s.smooth(&pb.y, &pb.mean, &mut out).unwrap();
            let (v_ref, x0_ref, kappa) = dense(&pb, free, Some(&rows));
            let tol = 1e-8f64.max(100.0 * f64::EPSILON * kappa * kappa);
            let scale = v_ref
                .iter()
                .zip(pb.mean.as_slice())
                .map(|(v, mu)| (v - mu).abs())
                .fold(1e-3 * max_abs(pb.y.as_slice()), f64::max);
            let err = max_diff(out.as_slice(), &v_ref);
            prop_assert!(err <= tol * scale, "inputs differ by {:.3e} (scale {:.3e}, kappa {:.2e})", err, scale, kappa);
            if free {
                let x0 = rep.initial_state.unwrap();
                // x₀ is determined only when the remaining rows see it; compare where they do
                // through the reproduced data instead.
                let (y_hat, _) = pb.sys.simulate_from(&x0, &out).unwrap();
                let (y_ref, _) = pb.sys.simulate_from(&x0_ref, &Signal::new(m, v_ref.clone()).unwrap()).unwrap();
                for &r in &rows {
                    prop_assert!((y_hat.as_slice()[r] - y_ref.as_slice()[r]).abs() <= tol * max_abs(pb.y.as_slice()).max(1.0) * 10.0);
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        #[test]
        fn smoother_matches_dense_least_squares(
            seed in any::<u64>(), n in 0usize..=3, m in 1usize..=3, p in 1usize..=2,
            len in 1usize..=30, zero_d in any::<bool>(), free in any::<bool>()
        ) {
            let pb = problem(seed, n, m, p, len, zero_d, free);
            // the method's stability condition, see `closed_loop_radius`
            prop_assume!(stable(&pb, free));
            if let Err(e) = check_against_dense(&pb, free, 1e-8) {
                return Err(TestCaseError::fail(e));
            }
        }
    }
}

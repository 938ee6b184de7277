//! Levenberg–Marquardt for nonlinear least squares: the one implementation of the workspace.
//!
//! A problem ([`LeastSquaresProblem`]) gives residuals `r(θ) ∈ ℝᵐ` and their Jacobian
//! `J = ∂r/∂θ` (or only the normal equations, [`NormalEquationsProblem`]); the solver
//! ([`LevenbergMarquardt`], configured by [`LmSettings`]) minimises the cost
//! `C(θ) = Σ_k r_k(θ)²`. Each iteration forms the normal equations at the current θ and
//! tries damped steps with Marquardt scaling,
//!
//! ```text
//! (JᵀJ + μ diag(JᵀJ)) δ = −Jᵀr,        θ_trial = θ + δ,
//! ```
//!
//! solved by a Cholesky factorisation of the Jacobi-scaled matrix (unit diagonal, so `μ` is
//! relative and the solve is well conditioned however differently the parameters are scaled).
//! A trial is accepted only when the problem accepts `θ_trial` (see
//! [`LeastSquaresProblem::residuals`]) and its cost is finite and lower; then `μ` shrinks,
//! otherwise it grows and the step is retried. Accepted costs therefore strictly decrease,
//! and the result is always the best iterate found.
//!
//! The search ends ([`LmStatus`]) when an accepted step lowers the cost by a relative amount
//! at most the tolerance or the cost reaches zero (converged), when no damped step lowers the
//! cost before the damping limit (no progress: a stationary point to working precision, or a
//! problem that rejects every nearby θ), when the Jacobian cannot be evaluated, or at the
//! iteration limit. None of these is an error: [`LevenbergMarquardt::minimize`] fails only
//! when it cannot start.
//!
//! Parameter covariances `s² (JᵀJ)⁻¹`, `s² = C/(m − p)`, come from [`LmFit::covariance`] or
//! [`covariance_from_normal`].
//!
//! ```
//! use nalgebra::{DMatrix, DVector};
//! use structid_linear::levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, LmSettings};
//!
//! /// Fits y = a·exp(b·t).
//! struct Exp { t: Vec<f64>, y: Vec<f64> }
//! impl LeastSquaresProblem for Exp {
//!     fn residuals(&mut self, th: &[f64]) -> Option<DVector<f64>> {
//!         Some(DVector::from_iterator(self.t.len(),
//!             self.t.iter().zip(&self.y).map(|(t, y)| th[0] * (th[1] * t).exp() - y)))
//!     }
//!     fn jacobian(&mut self, th: &[f64], _r: &DVector<f64>) -> Option<DMatrix<f64>> {
//!         Some(DMatrix::from_fn(self.t.len(), 2, |k, c| {
//!             let e = (th[1] * self.t[k]).exp();
//!             if c == 0 { e } else { th[0] * self.t[k] * e }
//!         }))
//!     }
//! }
//! let t: Vec<f64> = (0..20).map(|k| k as f64 / 10.0).collect();
//! let y = t.iter().map(|t| 2.0 * (-1.5 * t).exp()).collect();
//! let mut problem = Exp { t, y };
//! let fit = LevenbergMarquardt::new(LmSettings::default()).minimize(&mut problem, &[1.0, 0.0])?;
//! assert!(fit.converged());
//! assert!((fit.theta[0] - 2.0).abs() < 1e-8 && (fit.theta[1] + 1.5).abs() < 1e-8);
//! # Ok::<(), structid_linear::LinearError>(())
//! ```

use nalgebra::{DMatrix, DVector};

use crate::error::{LinearError, check_at_least_one, check_non_negative, check_positive};

/// A nonlinear least-squares problem `min_θ Σ_k r_k(θ)²`.
///
/// The methods take `&mut self` so that a problem may keep what an evaluation computed for
/// the Jacobian at the same θ (e.g. a simulated output).
///
/// ```
/// use nalgebra::{DMatrix, DVector};
/// use structid_linear::levenberg_marquardt::LeastSquaresProblem;
/// /// r(θ) = θ − 1, rejecting negative θ.
/// struct Shift;
/// impl LeastSquaresProblem for Shift {
///     fn residuals(&mut self, th: &[f64]) -> Option<DVector<f64>> {
///         (th[0] >= 0.0).then(|| DVector::from_element(1, th[0] - 1.0))
///     }
///     fn jacobian(&mut self, _th: &[f64], _r: &DVector<f64>) -> Option<DMatrix<f64>> {
///         Some(DMatrix::from_element(1, 1, 1.0))
///     }
/// }
/// let r = DVector::from_element(1, 2.0);
/// let (jtj, jtr) = Shift.normal_equations(&[3.0], &r).unwrap();
/// assert_eq!((jtj[(0, 0)], jtr[0]), (1.0, 2.0));
/// assert!(Shift.residuals(&[-1.0]).is_none());
/// ```
pub trait LeastSquaresProblem {
    /// The residual vector `r(θ)` (its length must not depend on θ), or `None` when the
    /// problem rejects θ (outside its admissible set, e.g. an unstable denominator, or not
    /// computable): the solver treats a rejected trial as a failed step and raises the
    /// damping.
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>>;

    /// The Jacobian `J = ∂r/∂θ` (`m × p`) at θ, where `residuals = r(θ)`; `None` when it
    /// cannot be evaluated (the search then stops with [`LmStatus::JacobianFailed`]).
    fn jacobian(&mut self, theta: &[f64], residuals: &DVector<f64>) -> Option<DMatrix<f64>>;

    /// The normal equations `(JᵀJ, Jᵀr)` at θ. The default forms them from
    /// [`jacobian`](Self::jacobian); a problem that can accumulate them without storing `J`
    /// overrides this.
    fn normal_equations(
        &mut self,
        theta: &[f64],
        residuals: &DVector<f64>,
    ) -> Option<(DMatrix<f64>, DVector<f64>)> {
        let j = self.jacobian(theta, residuals)?;
        let jtj = j.transpose() * &j;
        let jtr = j.transpose() * residuals;
        Some((jtj, jtr))
    }
}

/// A least-squares problem that accumulates its normal equations `(JᵀJ, Jᵀr)` without ever
/// forming `J` (for a simulation over a long record, `J` would be samples × parameters).
/// Implementing it makes the type a [`LeastSquaresProblem`] whose
/// [`jacobian`](LeastSquaresProblem::jacobian) is `None`, so that no such problem has to
/// spell out a Jacobian it never has. Where both traits are in scope, call its methods
/// through the trait (`NormalEquationsProblem::residuals(&mut p, θ)`): both name a
/// `residuals`.
///
/// ```
/// use nalgebra::{DMatrix, DVector};
/// use structid_linear::levenberg_marquardt::{LevenbergMarquardt, LmSettings, NormalEquationsProblem};
///
/// /// Fits the mean c of the values: r_k = c − v_k, JᵀJ = n, Jᵀr = Σ r_k.
/// struct Mean(Vec<f64>);
/// impl NormalEquationsProblem for Mean {
///     fn residuals(&mut self, th: &[f64]) -> Option<DVector<f64>> {
///         Some(DVector::from_iterator(self.0.len(), self.0.iter().map(|v| th[0] - v)))
///     }
///     fn normal_equations(&mut self, th: &[f64]) -> Option<(DMatrix<f64>, DVector<f64>)> {
///         let n = self.0.len() as f64;
///         let sum = self.0.iter().map(|v| th[0] - v).sum::<f64>();
///         Some((DMatrix::from_element(1, 1, n), DVector::from_element(1, sum)))
///     }
/// }
/// let mut problem = Mean(vec![1.0, 2.0, 6.0]);
/// let fit = LevenbergMarquardt::new(LmSettings::default()).minimize(&mut problem, &[0.0])?;
/// assert!((fit.theta[0] - 3.0).abs() < 1e-9);
/// # Ok::<(), structid_linear::LinearError>(())
/// ```
pub trait NormalEquationsProblem {
    /// As [`LeastSquaresProblem::residuals`].
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>>;

    /// The normal equations `(JᵀJ, Jᵀr)` at θ, whose residuals the solver has just evaluated
    /// (a problem may reuse what that evaluation computed); `None` when they cannot be
    /// evaluated, which stops the search with [`LmStatus::JacobianFailed`].
    fn normal_equations(&mut self, theta: &[f64]) -> Option<(DMatrix<f64>, DVector<f64>)>;
}

impl<P: NormalEquationsProblem> LeastSquaresProblem for P {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        NormalEquationsProblem::residuals(self, theta)
    }

    fn jacobian(&mut self, _theta: &[f64], _residuals: &DVector<f64>) -> Option<DMatrix<f64>> {
        None
    }

    fn normal_equations(
        &mut self,
        theta: &[f64],
        _residuals: &DVector<f64>,
    ) -> Option<(DMatrix<f64>, DVector<f64>)> {
        NormalEquationsProblem::normal_equations(self, theta)
    }
}

/// The Jacobian of `residuals` at θ by forward differences, column i from
/// r(θ + hᵢ·eᵢ) − r(θ) with hᵢ = `relative_step`·max(|θᵢ|, 10⁻³): for problems whose residual
/// is a simulation without derivatives (each column costs one evaluation). `r` is r(θ);
/// `None` when a shifted evaluation is rejected.
///
/// ```
/// use nalgebra::DVector;
/// use structid_linear::levenberg_marquardt::forward_jacobian;
/// // r(θ) = (θ₀², θ₀θ₁): J = [[2θ₀, 0], [θ₁, θ₀]].
/// let mut r = |t: &[f64]| Some(DVector::from_vec(vec![t[0] * t[0], t[0] * t[1]]));
/// let at = [2.0, 3.0];
/// let r0 = r(&at).unwrap();
/// let j = forward_jacobian(&mut r, &at, &r0, 1e-7).unwrap();
/// assert!((j[(0, 0)] - 4.0).abs() < 1e-5 && (j[(1, 0)] - 3.0).abs() < 1e-5);
/// assert!(j[(0, 1)].abs() < 1e-12 && (j[(1, 1)] - 2.0).abs() < 1e-5);
/// ```
pub fn forward_jacobian(
    residuals: &mut dyn FnMut(&[f64]) -> Option<DVector<f64>>,
    theta: &[f64],
    r: &DVector<f64>,
    relative_step: f64,
) -> Option<DMatrix<f64>> {
    let mut j = DMatrix::zeros(r.len(), theta.len());
    for i in 0..theta.len() {
        let step = relative_step * theta[i].abs().max(1e-3);
        let mut t = theta.to_vec();
        t[i] += step;
        let ri = residuals(&t)?;
        for k in 0..r.len() {
            j[(k, i)] = (ri[k] - r[k]) / step;
        }
    }
    Some(j)
}

/// Settings of [`LevenbergMarquardt`] (build with [`LmSettings::builder`]; [`Default`] is
/// valid).
///
/// ```
/// use structid_linear::levenberg_marquardt::LmSettings;
/// let s = LmSettings::builder().max_iterations(30).damping_increase(4.0).build().unwrap();
/// assert_eq!((s.max_iterations(), s.damping_increase(), s.tolerance()), (30, 4.0, 1e-10));
/// assert!(LmSettings::builder().damping_decrease(0.5).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct LmSettings {
    pub(crate) max_iterations: usize,
    pub(crate) tolerance: f64,
    pub(crate) initial_damping: f64,
    pub(crate) damping_increase: f64,
    pub(crate) damping_decrease: f64,
    pub(crate) min_damping: f64,
    pub(crate) max_damping: f64,
    pub(crate) max_step_attempts: usize,
}

impl Default for LmSettings {
    /// 100 iterations, relative cost decrease 1e-10, μ₀ = 1e-3, μ × 10 after a failed step
    /// and ÷ 10 (not below 1e-15) after an accepted one, give up an iteration when μ reaches
    /// 1e20 or after 100 trials.
    fn default() -> Self {
        LmSettings {
            max_iterations: 100,
            tolerance: 1e-10,
            initial_damping: 1e-3,
            damping_increase: 10.0,
            damping_decrease: 10.0,
            min_damping: 1e-15,
            max_damping: 1e20,
            max_step_attempts: 100,
        }
    }
}

impl LmSettings {
    /// A builder from the defaults.
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert_eq!(LmSettings::builder().build().unwrap(), LmSettings::default());
    /// ```
    pub fn builder() -> LmSettingsBuilder {
        LmSettingsBuilder(Self::default())
    }
    /// Maximum number of iterations (evaluations of the normal equations).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert_eq!(LmSettings::default().max_iterations(), 100);
    /// ```
    pub fn max_iterations(&self) -> usize {
        self.max_iterations
    }
    /// Convergence threshold on the relative cost decrease `(C − C_new)/C` of an accepted
    /// step.
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert_eq!(LmSettings::default().tolerance(), 1e-10);
    /// ```
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }
    /// Initial damping μ₀ (relative to `diag(JᵀJ)`).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert_eq!(LmSettings::default().initial_damping(), 1e-3);
    /// ```
    pub fn initial_damping(&self) -> f64 {
        self.initial_damping
    }
    /// Factor applied to μ after a failed trial.
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert_eq!(LmSettings::default().damping_increase(), 10.0);
    /// ```
    pub fn damping_increase(&self) -> f64 {
        self.damping_increase
    }
    /// Divisor applied to μ after an accepted step.
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert_eq!(LmSettings::default().damping_decrease(), 10.0);
    /// ```
    pub fn damping_decrease(&self) -> f64 {
        self.damping_decrease
    }
    /// Floor of μ after an accepted step.
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert_eq!(LmSettings::default().min_damping(), 1e-15);
    /// ```
    pub fn min_damping(&self) -> f64 {
        self.min_damping
    }
    /// An iteration gives up (no progress) once μ reaches this value (may be infinite).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert_eq!(LmSettings::default().max_damping(), 1e20);
    /// ```
    pub fn max_damping(&self) -> f64 {
        self.max_damping
    }
    /// An iteration gives up (no progress) after this many trials.
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert_eq!(LmSettings::default().max_step_attempts(), 100);
    /// ```
    pub fn max_step_attempts(&self) -> usize {
        self.max_step_attempts
    }
}

/// Builder for [`LmSettings`].
///
/// ```
/// use structid_linear::levenberg_marquardt::LmSettings;
/// let s = LmSettings::builder()
///     .tolerance(1e-12)
///     .initial_damping(1e-2)
///     .damping_decrease(3.0)
///     .min_damping(1e-12)
///     .max_damping(f64::INFINITY)
///     .max_step_attempts(10)
///     .build()
///     .unwrap();
/// assert_eq!((s.max_step_attempts(), s.min_damping()), (10, 1e-12));
/// ```
#[derive(Clone, Debug)]
pub struct LmSettingsBuilder(pub(crate) LmSettings);

impl LmSettingsBuilder {
    /// Iteration limit (≥ 1).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert!(LmSettings::builder().max_iterations(0).build().is_err());
    /// ```
    pub fn max_iterations(mut self, n: usize) -> Self {
        self.0.max_iterations = n;
        self
    }
    /// Relative cost-decrease tolerance (≥ 0, finite).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert!(LmSettings::builder().tolerance(f64::NAN).build().is_err());
    /// ```
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.0.tolerance = tol;
        self
    }
    /// Initial damping μ₀ (> 0, finite; at or above the damping limit no trial is made).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert!(LmSettings::builder().initial_damping(0.0).build().is_err());
    /// ```
    pub fn initial_damping(mut self, mu: f64) -> Self {
        self.0.initial_damping = mu;
        self
    }
    /// Factor of μ after a failed trial (> 1, finite).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert!(LmSettings::builder().damping_increase(0.5).build().is_err());
    /// ```
    pub fn damping_increase(mut self, factor: f64) -> Self {
        self.0.damping_increase = factor;
        self
    }
    /// Divisor of μ after an accepted step (≥ 1, finite; 1 keeps μ).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert!(LmSettings::builder().damping_decrease(3.0).build().is_ok());
    /// ```
    pub fn damping_decrease(mut self, factor: f64) -> Self {
        self.0.damping_decrease = factor;
        self
    }
    /// Floor of μ after an accepted step (> 0, finite).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert!(LmSettings::builder().min_damping(-1.0).build().is_err());
    /// ```
    pub fn min_damping(mut self, mu: f64) -> Self {
        self.0.min_damping = mu;
        self
    }
    /// Damping at which an iteration gives up (> 0; may be infinite).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert!(LmSettings::builder().max_damping(0.0).build().is_err());
    /// ```
    pub fn max_damping(mut self, mu: f64) -> Self {
        self.0.max_damping = mu;
        self
    }
    /// Trials per iteration before it gives up (≥ 1).
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert!(LmSettings::builder().max_step_attempts(0).build().is_err());
    /// ```
    pub fn max_step_attempts(mut self, n: usize) -> Self {
        self.0.max_step_attempts = n;
        self
    }
    /// Validates.
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmSettings;
    /// assert!(LmSettings::builder().build().is_ok());
    /// ```
    pub fn build(self) -> Result<LmSettings, LinearError> {
        let s = self.0;
        check_at_least_one("max_iterations", s.max_iterations)?;
        check_at_least_one("max_step_attempts", s.max_step_attempts)?;
        check_non_negative("tolerance", s.tolerance)?;
        check_positive("initial_damping", s.initial_damping)?;
        check_positive("min_damping", s.min_damping)?;
        if !(s.damping_increase.is_finite() && s.damping_increase > 1.0) {
            return Err(LinearError::param(
                "damping_increase",
                format!("must be finite and above 1, got {}", s.damping_increase),
            ));
        }
        if !(s.damping_decrease.is_finite() && s.damping_decrease >= 1.0) {
            return Err(LinearError::param(
                "damping_decrease",
                format!("must be finite and at least 1, got {}", s.damping_decrease),
            ));
        }
        // An infinite limit leaves only the trial limit.
        if s.max_damping.is_nan() || s.max_damping <= 0.0 {
            return Err(LinearError::param(
                "max_damping",
                format!("must be positive, got {}", s.max_damping),
            ));
        }
        Ok(s)
    }
}

/// Why a converged search stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum LmConvergence {
    /// An accepted step lowered the cost by a relative amount at most the tolerance.
    SmallDecrease,
    /// The cost is zero.
    ZeroCost,
}

/// How a Levenberg–Marquardt search ended. In every case [`LmFit::theta`] is the best
/// iterate found.
///
/// ```
/// use structid_linear::levenberg_marquardt::{LmConvergence, LmStatus};
/// assert!(LmStatus::Converged(LmConvergence::ZeroCost).is_converged());
/// assert!(!LmStatus::MaxIterations.is_converged());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum LmStatus {
    /// The convergence test was met.
    Converged(LmConvergence),
    /// No damped step lowered the cost (or the problem rejected every trial) before the
    /// damping limit or the trial limit: a stationary point to working precision, or the
    /// edge of the admissible set.
    NoProgress,
    /// The iteration limit was reached.
    MaxIterations,
    /// The problem could not evaluate the Jacobian at the current iterate.
    JacobianFailed,
}

impl LmStatus {
    /// `true` for [`LmStatus::Converged`].
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LmStatus;
    /// assert!(!LmStatus::NoProgress.is_converged());
    /// ```
    pub fn is_converged(&self) -> bool {
        matches!(self, LmStatus::Converged(_))
    }
}

/// Result of [`LevenbergMarquardt::minimize`].
///
/// ```
/// use nalgebra::{DMatrix, DVector};
/// use structid_linear::levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, LmStatus};
/// struct Line;
/// impl LeastSquaresProblem for Line {
///     fn residuals(&mut self, th: &[f64]) -> Option<DVector<f64>> {
///         Some(DVector::from_vec(vec![th[0] - 1.0, th[0] - 3.0]))
///     }
///     fn jacobian(&mut self, _: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> {
///         Some(DMatrix::from_element(2, 1, 1.0))
///     }
/// }
/// let fit = LevenbergMarquardt::default().minimize(&mut Line, &[0.0]).unwrap();
/// assert!((fit.theta[0] - 2.0).abs() < 1e-6 && (fit.cost - 2.0).abs() < 1e-10);
/// assert_eq!(fit.costs.last(), Some(&fit.cost));
/// // s² = 2/(2 − 1), (JᵀJ)⁻¹ = 1/2
/// assert!((fit.covariance(&mut Line).unwrap()[(0, 0)] - 1.0).abs() < 1e-10);
/// ```
#[derive(Clone, Debug)]
pub struct LmFit {
    /// The best iterate (the start when no step was accepted).
    pub theta: Vec<f64>,
    /// `r(θ)` at [`theta`](Self::theta).
    pub residuals: DVector<f64>,
    /// `Σ r_k²` at [`theta`](Self::theta).
    pub cost: f64,
    /// `Σ r_k²` at the start.
    pub initial_cost: f64,
    /// The cost after each accepted step (strictly decreasing, all below `initial_cost`).
    pub costs: Vec<f64>,
    /// Iterations: evaluations of the normal equations.
    pub iterations: usize,
    /// Evaluations of the residuals, the start included (rejected trials too).
    pub evaluations: usize,
    /// How the search ended.
    pub status: LmStatus,
    /// `JᵀJ` at `theta` when the last iteration evaluated it there (saves one evaluation in
    /// [`covariance`](Self::covariance)).
    normal_matrix: Option<DMatrix<f64>>,
}

impl LmFit {
    /// `true` when [`status`](Self::status) is [`LmStatus::Converged`].
    ///
    /// ```
    /// # use nalgebra::{DMatrix, DVector};
    /// # use structid_linear::levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
    /// # struct Zero;
    /// # impl LeastSquaresProblem for Zero {
    /// #     fn residuals(&mut self, th: &[f64]) -> Option<DVector<f64>> { Some(DVector::from_element(1, th[0])) }
    /// #     fn jacobian(&mut self, _: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> { Some(DMatrix::from_element(1, 1, 1.0)) }
    /// # }
    /// assert!(LevenbergMarquardt::default().minimize(&mut Zero, &[0.0]).unwrap().converged());
    /// ```
    pub fn converged(&self) -> bool {
        self.status.is_converged()
    }

    /// The residual variance `s² = C/(m − p)` (`m − p` floored at 1).
    ///
    /// ```
    /// # use nalgebra::{DMatrix, DVector};
    /// # use structid_linear::levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
    /// # struct Two;
    /// # impl LeastSquaresProblem for Two {
    /// #     fn residuals(&mut self, th: &[f64]) -> Option<DVector<f64>> { Some(DVector::from_vec(vec![th[0] - 1.0, th[0] + 1.0, th[0]])) }
    /// #     fn jacobian(&mut self, _: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> { Some(DMatrix::from_element(3, 1, 1.0)) }
    /// # }
    /// let fit = LevenbergMarquardt::default().minimize(&mut Two, &[5.0]).unwrap();
    /// assert!((fit.residual_variance() - 1.0).abs() < 1e-12);
    /// ```
    pub fn residual_variance(&self) -> f64 {
        let dof = self.residuals.len().saturating_sub(self.theta.len()).max(1);
        self.cost / dof as f64
    }

    /// The parameter covariance `s² (JᵀJ)⁻¹` at [`theta`](Self::theta)
    /// ([`residual_variance`](Self::residual_variance), [`covariance_from_normal`]); `None`
    /// when the problem cannot evaluate `JᵀJ` there or it is singular to working precision.
    /// `problem` must be the one that was minimised.
    ///
    /// See [`LmFit`] for an example.
    pub fn covariance<P: LeastSquaresProblem + ?Sized>(
        &self,
        problem: &mut P,
    ) -> Option<DMatrix<f64>> {
        let s2 = self.residual_variance();
        match &self.normal_matrix {
            Some(h) => covariance_from_normal(h, s2),
            None => {
                let (h, _) = problem.normal_equations(&self.theta, &self.residuals)?;
                covariance_from_normal(&h, s2)
            }
        }
    }
}

/// `s² H⁻¹` of a symmetric positive definite `H = JᵀJ`, by a Cholesky factorisation of the
/// Jacobi-scaled `H` solved against the identity columns (no explicit inversion); `None`
/// when `H` has a non-positive or non-finite diagonal entry, is singular to working
/// precision, or the result is not finite.
///
/// ```
/// use nalgebra::DMatrix;
/// use structid_linear::levenberg_marquardt::covariance_from_normal;
/// let h = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]);
/// let c = covariance_from_normal(&h, 2.0).unwrap();
/// assert!(((&h * &c) - DMatrix::identity(2, 2) * 2.0).norm() < 1e-12);
/// assert!(covariance_from_normal(&DMatrix::from_element(2, 2, 1.0), 1.0).is_none());
/// ```
pub fn covariance_from_normal(h: &DMatrix<f64>, s2: f64) -> Option<DMatrix<f64>> {
    let d = h.nrows();
    if h.ncols() != d {
        return None;
    }
    let s: Vec<f64> = (0..d).map(|i| h[(i, i)].sqrt()).collect();
    if s.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return None;
    }
    let hs = DMatrix::from_fn(d, d, |i, j| h[(i, j)] / (s[i] * s[j]));
    // Cholesky::inverse solves against the identity columns.
    let inv = hs.cholesky()?.inverse();
    let cov = DMatrix::from_fn(d, d, |i, j| s2 * inv[(i, j)] / (s[i] * s[j]));
    cov.iter().all(|v| v.is_finite()).then_some(cov)
}

/// The Levenberg–Marquardt solver.
///
/// ```
/// use structid_linear::levenberg_marquardt::{LevenbergMarquardt, LmSettings};
/// let lm = LevenbergMarquardt::new(LmSettings::builder().max_iterations(20).build().unwrap());
/// assert_eq!(lm.settings().max_iterations(), 20);
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LevenbergMarquardt {
    settings: LmSettings,
}

impl LevenbergMarquardt {
    /// A solver with `settings`.
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::{LevenbergMarquardt, LmSettings};
    /// assert_eq!(LevenbergMarquardt::new(LmSettings::default()), LevenbergMarquardt::default());
    /// ```
    pub fn new(settings: LmSettings) -> Self {
        LevenbergMarquardt { settings }
    }

    /// Its settings.
    ///
    /// ```
    /// use structid_linear::levenberg_marquardt::LevenbergMarquardt;
    /// assert_eq!(LevenbergMarquardt::default().settings().tolerance(), 1e-10);
    /// ```
    pub fn settings(&self) -> &LmSettings {
        &self.settings
    }

    /// Minimises `Σ r_k(θ)²` of `problem` from `start`.
    ///
    /// Errors ([`LinearError::InvalidStart`]) only when the search cannot start: `start` is
    /// empty or not finite, the problem rejects it, or the cost there is not finite.
    /// Non-convergence is reported by [`LmFit::status`] with the best iterate.
    ///
    /// See the [module documentation](self) for an example.
    pub fn minimize<P: LeastSquaresProblem + ?Sized>(
        &self,
        problem: &mut P,
        start: &[f64],
    ) -> Result<LmFit, LinearError> {
        let s = &self.settings;
        if start.is_empty() {
            return Err(LinearError::InvalidStart("no parameters".into()));
        }
        if let Some(i) = start.iter().position(|v| !v.is_finite()) {
            return Err(LinearError::InvalidStart(format!(
                "parameter {i} is {}",
                start[i]
            )));
        }
        let Some(mut r) = problem.residuals(start) else {
            return Err(LinearError::InvalidStart(
                "the problem rejects the starting point".into(),
            ));
        };
        let mut cost = sum_of_squares(&r);
        if !cost.is_finite() {
            return Err(LinearError::InvalidStart(format!(
                "the cost at the starting point is {cost}"
            )));
        }
        let d = start.len();
        let initial_cost = cost;
        let mut theta = start.to_vec();
        let mut costs = Vec::new();
        let mut mu = s.initial_damping;
        let mut iterations = 0;
        let mut evaluations = 1;
        let mut normal_matrix = None;
        let mut status = (cost == 0.0).then_some(LmStatus::Converged(LmConvergence::ZeroCost));
        while status.is_none() && iterations < s.max_iterations {
            iterations += 1;
            let Some((h, g)) = problem.normal_equations(&theta, &r) else {
                status = Some(LmStatus::JacobianFailed);
                break;
            };
            // Jacobi scaling: the damped matrix has unit diagonal plus μ, whatever the
            // parameters' units; columns without influence get a tiny floor so that the
            // Cholesky factorisation exists (their step is zero since their gradient is).
            let scale: Vec<f64> = {
                let dmax = (0..d).map(|i| h[(i, i)]).fold(0.0, f64::max);
                let floor = (dmax * 1e-300).max(f64::MIN_POSITIVE);
                (0..d).map(|i| h[(i, i)].max(floor).sqrt()).collect()
            };
            let hs = DMatrix::from_fn(d, d, |i, j| h[(i, j)] / (scale[i] * scale[j]));
            let gs = DVector::from_fn(d, |i, _| -g[i] / scale[i]);
            normal_matrix = Some(h);
            let mut accepted = None;
            let mut attempts = 0;
            while mu < s.max_damping && attempts < s.max_step_attempts {
                attempts += 1;
                let mut a = hs.clone();
                for i in 0..d {
                    a[(i, i)] += mu * hs[(i, i)].max(1e-12);
                }
                let Some(chol) = a.cholesky() else {
                    mu *= s.damping_increase;
                    continue;
                };
                let ds = chol.solve(&gs);
                let trial: Vec<f64> = (0..d).map(|i| theta[i] + ds[i] / scale[i]).collect();
                if trial.iter().all(|v| v.is_finite()) {
                    evaluations += 1;
                    if let Some(rt) = problem.residuals(&trial) {
                        let ct = sum_of_squares(&rt);
                        if ct.is_finite() && ct < cost {
                            accepted = Some((trial, rt, ct));
                            break;
                        }
                    }
                }
                mu *= s.damping_increase;
            }
            let Some((trial, rt, ct)) = accepted else {
                status = Some(LmStatus::NoProgress);
                break;
            };
            let relative = (cost - ct) / cost;
            theta = trial;
            r = rt;
            cost = ct;
            costs.push(ct);
            normal_matrix = None;
            mu = (mu / s.damping_decrease).max(s.min_damping);
            if cost == 0.0 {
                status = Some(LmStatus::Converged(LmConvergence::ZeroCost));
            } else if relative <= s.tolerance {
                status = Some(LmStatus::Converged(LmConvergence::SmallDecrease));
            }
        }
        Ok(LmFit {
            theta,
            residuals: r,
            cost,
            initial_cost,
            costs,
            iterations,
            evaluations,
            status: status.unwrap_or(LmStatus::MaxIterations),
            normal_matrix,
        })
    }
}

fn sum_of_squares(r: &DVector<f64>) -> f64 {
    r.iter().map(|v| v * v).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `r = Aθ − b`.
    struct Linear {
        a: DMatrix<f64>,
        b: DVector<f64>,
    }

    impl LeastSquaresProblem for Linear {
        fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
            Some(&self.a * DVector::from_column_slice(theta) - &self.b)
        }
        fn jacobian(&mut self, _: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> {
            Some(self.a.clone())
        }
    }

    fn linear_problem() -> Linear {
        // deterministic, well-conditioned but not orthogonal, 30 × 4 with an inconsistent b
        let a = DMatrix::from_fn(30, 4, |k, j| {
            let t = k as f64 / 29.0;
            t.powi(j as i32) + 0.1 * ((k * 7 + j * 3) as f64).sin()
        });
        let b = DVector::from_fn(30, |k, _| (k as f64 * 0.37).cos() + 0.01 * k as f64);
        Linear { a, b }
    }

    #[test]
    fn linear_least_squares_equals_the_qr_solution() {
        let mut p = linear_problem();
        let qr = p.a.clone().qr();
        let qtb = qr.q().transpose() * &p.b;
        let x = qr.r().solve_upper_triangular(&qtb).unwrap();
        let lm = LevenbergMarquardt::new(LmSettings::builder().tolerance(0.0).build().unwrap());
        let fit = lm.minimize(&mut p, &[3.0, -2.0, 1.0, 5.0]).unwrap();
        for i in 0..4 {
            assert!(
                (fit.theta[i] - x[i]).abs() < 1e-10,
                "{i}: {} vs {}",
                fit.theta[i],
                x[i]
            );
        }
        // tolerance 0: only the stalled search (or an exact zero) ends it
        assert_eq!(fit.status, LmStatus::NoProgress);
        let rss = (&p.a * &x - &p.b).norm_squared();
        assert!((fit.cost - rss).abs() <= 1e-12 * rss);
        // covariance: s² (AᵀA)⁻¹ from the normal equations
        let cov = fit.covariance(&mut p).unwrap();
        let ata = p.a.transpose() * &p.a;
        let s2 = rss / 26.0;
        let direct = ata.clone().try_inverse().unwrap() * s2;
        assert!((&cov - &direct).norm() < 1e-10 * direct.norm());
        // covariance when the last iteration accepted a step: evaluated at θ
        let fit2 = LevenbergMarquardt::default()
            .minimize(&mut p, &[3.0, -2.0, 1.0, 5.0])
            .unwrap();
        assert!(fit2.converged());
        assert!((&fit2.covariance(&mut p).unwrap() - &direct).norm() < 1e-8 * direct.norm());
    }

    struct Rosenbrock;

    impl LeastSquaresProblem for Rosenbrock {
        fn residuals(&mut self, t: &[f64]) -> Option<DVector<f64>> {
            Some(DVector::from_vec(vec![
                10.0 * (t[1] - t[0] * t[0]),
                1.0 - t[0],
            ]))
        }
        fn jacobian(&mut self, t: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> {
            Some(DMatrix::from_row_slice(
                2,
                2,
                &[-20.0 * t[0], 10.0, -1.0, 0.0],
            ))
        }
    }

    #[test]
    fn rosenbrock_reaches_one_one() {
        let fit = LevenbergMarquardt::default()
            .minimize(&mut Rosenbrock, &[-1.2, 1.0])
            .unwrap();
        assert!(fit.converged(), "{:?}", fit.status);
        assert!((fit.theta[0] - 1.0).abs() < 1e-8 && (fit.theta[1] - 1.0).abs() < 1e-8);
        assert!(fit.cost < 1e-20);
        assert!(fit.costs.windows(2).all(|w| w[1] < w[0]));
        assert!(fit.costs[0] < fit.initial_cost);
        assert_eq!(fit.costs.last(), Some(&fit.cost));
    }

    /// y = a·exp(b t) + c with noise: a nonzero-residual optimum.
    struct Exponential {
        t: Vec<f64>,
        y: Vec<f64>,
    }

    impl LeastSquaresProblem for Exponential {
        fn residuals(&mut self, th: &[f64]) -> Option<DVector<f64>> {
            Some(DVector::from_iterator(
                self.t.len(),
                self.t
                    .iter()
                    .zip(&self.y)
                    .map(|(t, y)| th[0] * (th[1] * t).exp() + th[2] - y),
            ))
        }
        fn jacobian(&mut self, th: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> {
            Some(DMatrix::from_fn(self.t.len(), 3, |k, c| {
                let e = (th[1] * self.t[k]).exp();
                match c {
                    0 => e,
                    1 => th[0] * self.t[k] * e,
                    _ => 1.0,
                }
            }))
        }
    }

    #[test]
    fn the_gradient_vanishes_at_the_optimum() {
        let t: Vec<f64> = (0..50).map(|k| k as f64 / 10.0).collect();
        let y = t
            .iter()
            .enumerate()
            .map(|(k, t)| 3.0 * (-0.7 * t).exp() + 0.5 + 0.05 * ((k * k) as f64).sin())
            .collect();
        let mut p = Exponential { t, y };
        let lm = LevenbergMarquardt::new(LmSettings::builder().tolerance(1e-15).build().unwrap());
        let fit = lm.minimize(&mut p, &[1.0, -0.1, 0.0]).unwrap();
        assert!(fit.cost > 1e-3, "the optimum has a residual");
        let j = p.jacobian(&fit.theta, &fit.residuals).unwrap();
        let grad = j.transpose() * &fit.residuals;
        // KKT: Jᵀr = 0, relative to the sizes of J and r
        let scale = j.norm() * fit.residuals.norm();
        assert!(grad.norm() < 1e-8 * scale, "{grad} vs {scale}");
        assert!((fit.theta[0] - 3.0).abs() < 0.1 && (fit.theta[1] + 0.7).abs() < 0.05);
    }

    /// The Rosenbrock problem restricted to θ₀ ≤ 0.5 (like the stability guard of output
    /// error), and able to evaluate only `budget` trials after the start.
    struct Fenced {
        rejected: usize,
        budget: usize,
    }

    impl LeastSquaresProblem for Fenced {
        fn residuals(&mut self, t: &[f64]) -> Option<DVector<f64>> {
            if t[0] > 0.5 {
                self.rejected += 1;
                return None;
            }
            if self.budget == 0 {
                return None;
            }
            self.budget -= 1;
            Rosenbrock.residuals(t)
        }
        fn jacobian(&mut self, t: &[f64], r: &DVector<f64>) -> Option<DMatrix<f64>> {
            Rosenbrock.jacobian(t, r)
        }
    }

    #[test]
    fn rejected_steps_return_the_best_iterate() {
        // the guard: trials beyond the fence are failed steps, the search ends on the fence
        let mut p = Fenced {
            rejected: 0,
            budget: usize::MAX,
        };
        let fit = LevenbergMarquardt::default()
            .minimize(&mut p, &[-1.2, 1.0])
            .unwrap();
        assert!(fit.converged(), "{:?}", fit.status);
        assert!(p.rejected > 0);
        assert!(
            fit.theta[0] <= 0.5 && (fit.theta[0] - 0.5).abs() < 1e-3,
            "{:?}",
            fit.theta
        );
        assert!(fit.costs.windows(2).all(|w| w[1] < w[0]));
        // every trial rejected after four: no progress, and the fourth accepted iterate
        let mut p = Fenced {
            rejected: 0,
            budget: 5,
        };
        let fit = LevenbergMarquardt::default()
            .minimize(&mut p, &[-1.2, 1.0])
            .unwrap();
        assert_eq!(fit.status, LmStatus::NoProgress);
        assert!(!fit.converged());
        let accepted = fit.costs.len();
        assert!((1..=4).contains(&accepted), "{accepted}");
        assert!(fit.cost < fit.initial_cost);
        assert_eq!(fit.costs.last(), Some(&fit.cost));
        assert_eq!(Rosenbrock.residuals(&fit.theta).unwrap(), fit.residuals);
        assert_eq!(fit.cost, sum_of_squares(&fit.residuals));
        // the same path as the unrestricted search up to there
        let free = LevenbergMarquardt::new(
            LmSettings::builder()
                .max_iterations(accepted)
                .build()
                .unwrap(),
        )
        .minimize(&mut Rosenbrock, &[-1.2, 1.0])
        .unwrap();
        assert_eq!(free.theta, fit.theta);
        // the iteration limit: also the best iterate, with its own status
        let one = LevenbergMarquardt::new(LmSettings::builder().max_iterations(1).build().unwrap())
            .minimize(&mut Rosenbrock, &[-1.2, 1.0])
            .unwrap();
        assert_eq!(one.status, LmStatus::MaxIterations);
        assert_eq!((one.iterations, one.costs.len()), (1, 1));
        assert!(one.cost < one.initial_cost);
    }

    struct NoJacobian;

    impl LeastSquaresProblem for NoJacobian {
        fn residuals(&mut self, t: &[f64]) -> Option<DVector<f64>> {
            Some(DVector::from_element(1, t[0] - 1.0))
        }
        fn jacobian(&mut self, _: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> {
            None
        }
    }

    #[test]
    fn statuses_and_start_errors() {
        let lm = LevenbergMarquardt::default();
        let fit = lm.minimize(&mut NoJacobian, &[3.0]).unwrap();
        assert_eq!(fit.status, LmStatus::JacobianFailed);
        assert_eq!((fit.theta[0], fit.cost, fit.iterations), (3.0, 4.0, 1));
        assert!(fit.covariance(&mut NoJacobian).is_none());
        let zero = lm.minimize(&mut NoJacobian, &[1.0]).unwrap();
        assert_eq!(zero.status, LmStatus::Converged(LmConvergence::ZeroCost));
        assert_eq!((zero.iterations, zero.evaluations), (0, 1));
        for bad in [&[][..], &[f64::NAN][..]] {
            assert!(matches!(
                lm.minimize(&mut NoJacobian, bad),
                Err(LinearError::InvalidStart(_))
            ));
        }
        let mut fenced = Fenced {
            rejected: 0,
            budget: usize::MAX,
        };
        assert!(matches!(
            lm.minimize(&mut fenced, &[1.0, 1.0]),
            Err(LinearError::InvalidStart(_))
        ));
        assert!(matches!(
            lm.minimize(&mut NoJacobian, &[1e300]),
            Err(LinearError::InvalidStart(_))
        ));
    }

    #[test]
    fn settings_are_validated() {
        let b = LmSettings::builder;
        assert!(b().tolerance(-1.0).build().is_err());
        assert!(b().initial_damping(f64::INFINITY).build().is_err());
        assert!(b().damping_increase(1.0).build().is_err());
        assert!(b().damping_decrease(0.5).build().is_err());
        assert!(b().min_damping(0.0).build().is_err());
        assert!(b().max_damping(f64::NAN).build().is_err());
        assert!(b().max_damping(f64::INFINITY).build().is_ok());
        assert!(b().damping_decrease(1.0).build().is_ok());
    }
}

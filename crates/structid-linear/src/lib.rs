//! Estimating the linear part of a `structid` model from data.
//!
//! On real data the LTI block of a structured model is only approximately known, so it is
//! estimated: an ARX model by linear least squares, refined by output-error (simulation
//! error) Levenberg–Marquardt. The result is a [`PolynomialModel`] whose
//! [`to_state_space`](PolynomialModel::to_state_space) gives a `structid_lti::StateSpace`
//! (with its sample time) that plugs into an LFT.
//!
//! # Model class
//! Discrete time, backward shift `q⁻¹`, multiple inputs `u_i`, one output `y`, one common
//! denominator (so the model is a single SISO/MISO state space):
//!
//! ```text
//! ARX:  A(q) y_k = Σ_i B_i(q) u_{i,k} + e_k
//! OE:   y_k = Σ_i B_i(q)/F(q) u_{i,k} + e_k
//! A = 1 + a_1 q⁻¹ + … + a_na q⁻na        (F likewise, nf = na)
//! B_i = q^{−nk_i} (b_{i,0} + b_{i,1} q⁻¹ + … + b_{i,nb_i−1} q^{−(nb_i−1)})
//! ```
//!
//! in MATLAB's `arx` convention ([`Orders`]: `nb` counts coefficients, `nk` is the delay,
//! `nk = 0` is direct feedthrough). Parameters are ordered `θ = (b_0…, b_1…, …, a…)`
//! ([`PolynomialModel::parameters`]); reported standard deviations follow that order.
//!
//! # ARX ([`arx()`])
//! With `φ_k = (u_{i,k−nk_i−j} …, −y_{k−1} … −y_{k−na})` the equations
//! `y_k = φ_kᵀθ + e_k`, `k = K … L−1` (`K` the largest lag) are solved by least squares,
//! `θ̂ = argmin ‖Y − Φθ‖² (+ λ‖θ‖²)`, with a Householder QR (faer) of the column-scaled
//! `[Φ S⁻¹ | Y]`; `Φ` is built directly from the data in `O(L·d)`. The condition number of
//! `Φ S⁻¹` is reported, and above a limit the regression is refused as singular. Standard
//! deviations: `sqrt(σ̂² diag((ΦᵀΦ)⁻¹))`, `σ̂² = RSS/(N − d)`.
//!
//! # Output error ([`output_error()`], [`oe`])
//! The criterion is the simulation error from zero initial conditions after a transient of
//! `T` samples,
//!
//! ```text
//! V(θ) = 1/N Σ_{k=T}^{L−1} ε_k²,   ε_k = y_k − ŷ_k(θ),   ŷ = Σ_i B_i/F u_i,   N = L − T.
//! ```
//!
//! Its gradient comes from the sensitivities, each one all-pole filter by recursion
//! (`O(L·d)`, never an `L×L` matrix):
//!
//! ```text
//! ∂ŷ_k/∂b_{i,j} =  [q^{−(nk_i+j)} / F(q)] u_{i,k},      ∂ŷ_k/∂f_j = −[q^{−j} / F(q)] ŷ_k,
//! ```
//!
//! stacked as the rows `ψ_kᵀ` of `Ψ`. A Levenberg–Marquardt step with Marquardt scaling
//! solves
//!
//! ```text
//! (ΨᵀΨ + μ diag(ΨᵀΨ)) δ = Ψᵀε
//! ```
//!
//! and is accepted when `F(θ + δ)` is stable (Schur–Cohn test) and the cost decreases
//! (then `μ ← μ/10`); otherwise `μ ← 10 μ` and the step is retried. Accepted costs therefore
//! never increase. The iteration stops when the relative decrease falls below the tolerance
//! or no step lowers the cost (converged), or at the iteration limit (`converged = false`,
//! not an error).
//!
//! The iteration is the workspace's one Levenberg–Marquardt solver, [`levenberg_marquardt`]
//! ([`LevenbergMarquardt`] on a [`LeastSquaresProblem`]), which other crates use for their
//! own nonlinear least-squares fits.
//!
//! # Known integrators ([`integrators`])
//! A pole known to lie at `z = 1` (a position driven by a force) is fixed rather than
//! estimated: with [`ArxSettings::integrators`] / [`OeSettings::integrators`] `= N` the fit
//! estimates `A'` in `A = A'(1 − q⁻¹)ᴺ` (ARX on `(1 − q⁻¹)ᴺ y`; output error with the factor
//! held in the simulation). Only `A'` must be stable; the result is classified by
//! [`PolynomialModel::stability`] as marginally stable, not unstable. An output-error fit that
//! ends worse than a constant or with an output near zero carries an [`OeWarning`].
//!
//! # Order selection ([`select_orders`]) and nonparametric BLA ([`bla_periodic`])
//! ARX fits over a grid of `(na, nb, nk)` scored by AIC `ln V + 2d/N`, BIC `ln V + d ln N/N`,
//! FPE `V (N+d)/(N−d)` or the simulation error on a validation record; and the frequency
//! response `Ĝ(k) = Ȳ(k)/Ū(k)` averaged over the periods of a periodic excitation, with
//! its standard deviation from the spread between periods.
//!
//! # Example
//! ```
//! use structid_linear::{oe, OeSettings, Orders, PolynomialModel};
//! use structid_lti::{LinearSystem, Signal};
//! let truth = PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None)?;
//! let u = Signal::from_fn(500, 1, |k, _| ((k * k) as f64 * 0.37).sin());
//! let y = Signal::new(1, truth.simulate(&u)?)?;
//! let settings = OeSettings::builder().sample_time(0.01).build()?;
//! let fit = oe(&u, &y, &Orders::siso(2, 2, 1), &settings)?;
//! let ss = fit.model.to_state_space()?;
//! assert_eq!((ss.order(), ss.sample_time()), (2, Some(0.01)));
//! let y_ss = ss.simulate(&u)?;
//! assert!((y_ss.get(100, 0) - y.get(100, 0)).abs() < 1e-8);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod arx;
pub mod bla;
pub mod error;
pub mod integrators;
pub mod levenberg_marquardt;
pub mod normal_equations;
pub mod orders;
pub mod output_error;
pub mod polynomial;
pub mod response;
pub mod selection;
pub mod split;

pub use arx::{ArxFit, ArxSettings, ArxSettingsBuilder, arx, arx_records};
pub use bla::{FrequencyResponse, bla_periodic};
pub use error::LinearError;
pub use integrators::Stability;
pub use levenberg_marquardt::{
    LeastSquaresProblem, LevenbergMarquardt, LmConvergence, LmFit, LmSettings, LmSettingsBuilder,
    LmStatus, NormalEquationsProblem, covariance_from_normal,
};
pub use normal_equations::NormalEquations;
pub use orders::Orders;
pub use output_error::{
    OeFit, OeSettings, OeSettingsBuilder, OeWarning, oe, oe_records, output_error,
    output_error_records,
};
pub use polynomial::PolynomialModel;
pub use selection::{
    OrderCriterion, OrderGrid, OrderSelection, select_orders, select_orders_observed,
    select_orders_records,
};
pub use split::{BlockSplit, block_splits};

#[cfg(test)]
mod properties;
#[cfg(test)]
mod testutil;

//! # structid-core: structured nonlinear system identification
//!
//! A system is an interconnection of **known** linear time-invariant blocks and **unknown static**
//! maps, written as one linear fractional transformation (LFT). The known block L (paper eq. 7)
//! maps the known input u, the unknown noise e and the outputs w of the static maps to the
//! measured output y and the maps' inputs z:
//!
//! ```text
//!   y = L_yu·u + L_ye·e + L_yw·w,      z = L_zu·u + L_ze·e + L_zw·w,      w = N(z)
//! ```
//!
//! The nonlinear part is a list of blocks N^\[i\], each reading some z channels and writing one w
//! channel ([`NonlinearBlock`], [`Model`]). z must be *measurable*, i.e. computable from u and y
//! ([`ZSource`], [`Lft::measurability`]).
//!
//! Among all (e, w) consistent with the data, [`identify()`] returns the minimiser of
//!
//! ```text
//!   J(e, w) = (1/L)·Σ_k e_kᵀe_k + β·Σ_i D_i(z^[i], w^[i])            (eq. 4)
//! ```
//!
//! where L is the number of samples and D_i, the **dispersion function** ([`Dispersion`]),
//! measures how complex it is to interpolate the points (z_k, w_k). The estimate N̂_i is the
//! interpolant of (z_k, ŵ_k) ([`Interpolant`]).
//!
//! ## Dispersions
//! * Any positive-definite [`Kernel`] through [`KernelDispersion`]: D = wᵀK⁻¹w, the RKHS norm of
//!   the interpolant. The paper's [`GaussianKernel`] K(z₁,z₂) = (2πσ²)^(−p/2)·exp(−‖z₁−z₂‖²/2σ²)
//!   is built in; a custom kernel is a dozen lines (see `examples/custom_kernel.rs`).
//!
//! * [`FourierDispersion`]: a Fourier-series kernel with finitely many features on a domain
//!   mapped to [0, 1]; [`LowRankGaussian`]: the Gaussian through Nyström features.
//! * [`TotalVariation`]: D = Σ_g |v_(g+1) − v_g| over the z-sorted distinct sample values (the
//!   total variation of the piecewise-linear interpolant) for scalar z, and the graph total
//!   variation over a k-nearest-neighbour graph for several inputs. It keeps jumps and corners
//!   (relays, Coulomb friction, quantisers) that kernel norms round off; see
//!   [`total_variation`](dispersion::total_variation).
//!
//! A dispersion turns into a [`Penalty`] once the sample points are known; solvers only see
//! penalties, so user-defined dispersions run through the same [`identify()`].
//!
//! ## The exact solution without K⁻¹
//! Gaussian Gram matrices are numerically singular, so the paper's printed route through
//! Q = K⁻¹ is replaced by its dual (representer) form. With r = y − T_yu·u and T the block
//! Toeplitz operators of the LTI paths (applied by recursion, never as dense matrices):
//!
//! ```text
//!   M = L·β·T_ye·T_yeᵀ + T_yw·K·T_ywᵀ,   λ = M⁻¹r,   α = T_ywᵀλ,   ŵ = Kα,   ê = L·β·T_yeᵀλ
//!   N̂_i(z) = Σ_k α_{i,k}·K_i(z, z_k)
//! ```
//!
//! See [`solver::exact`] for how M is assembled and factorised.
//!
//! ## Solvers
//! | dispersion | solver | cost |
//! |---|---|---|
//! | any quadratic | [`solver::exact`] (dual solve above) | O((L·n_y)³), memory (L·n_y)² |
//! | finite features (Fourier, low-rank) | [`solver::features`] | O(L·m²) |
//! | total variation | [`solver::conic`]: sparse conic program in state-space form, Clarabel | super-linear in L |
//! | total variation | [`solver::admm`]: Kalman smoother + exact TV prox per iteration | O(L·n²) per iteration |
//!
//! [`SolverChoice::Auto`] picks by dispersion kind and size ([`solver::choose_solver`], the one
//! home of the rule) and records why in [`Diagnostics::solver_reason`]. An iterative solver that
//! stops at its iteration or time limit returns its last iterate with a non-converged
//! [`Diagnostics::status`] and a warning; [`Identification::converged`] makes that an error.
//!
//! ## Validation
//! [`validate()`] checks estimated maps on a record: simulation with the maps in the loop (RMS and
//! fit), one-step-ahead prediction errors (the innovations of the noise path's Kalman
//! predictor) and their whiteness and input cross-correlation tests; see [`validation`].
//! [`Model::fit`] returns an [`Estimate`], the fitted model as a value that simulates, predicts k
//! steps ahead and serialises ([`estimate`]).
//!
//! ## Layout
//!
//! | module | what lives there |
//! |---|---|
//! | [`model`] | the LFT ([`model::lft`]), measurability, simulation with maps in the loop, hysteresis operators ([`model::hysteresis`]), where blocks sit ([`model::structure`]: [`Site`], [`Structure`]), the `Model` and its `Data`, interpolants, known maps (expressions, tables) |
//! | [`dispersion`] | the `Dispersion`/`Penalty` vocabulary and every family: kernels, Fourier features, low rank, polynomial, sums, total variation with its graph and scattered interpolants ([`dispersion::neighbours`]) |
//! | [`identify`](mod@identify) | the executor, its settings and results, the operator-form problem, posterior bands |
//! | [`solver`] | exact, features, conic (Clarabel), ADMM with its proximal operators |
//! | [`selection`] | β and σ by marginal likelihood, GCV, cross-validation or a validation record |
//! | [`validation`] | simulation, one-step prediction, residual tests, metrics |
//! | [`estimate`], [`stored`] | the fitted model as a value and the stored forms of maps |
//! | [`refine`] | alternating refinement of an uncertain linear part |
//! | [`paper`], [`scenarios`] | the paper's examples and test scenarios |
//! | [`progress`] | observers of long work (selection trials, refinement alternations) |
//!
//! ## Example
//! ```
//! use std::sync::Arc;
//! use structid_core::{identify, paper, IdentifySettings, KernelDispersion};
//! // The paper's spray example, 600 samples, unit noise.
//! let exp = paper::spray(600, 1.0, Arc::new(KernelDispersion::gaussian(0.1).unwrap()), 7).unwrap();
//! let settings = IdentifySettings::builder().beta(0.01).build().unwrap();
//! let id = identify(&exp.model, &exp.data, &settings).unwrap();
//! assert_eq!(id.blocks.len(), 2);
//! assert!(id.diagnostics.feasibility_residual < 1e-9);
//! ```

pub mod dispersion;
pub mod error;
pub mod estimate;
pub mod identify;
pub mod initial_state;
pub mod model;
pub mod paper;
pub mod progress;
pub mod refine;
pub mod scenarios;
pub mod selection;
pub mod solver;
pub mod stored;
pub mod validation;

pub use dispersion::fourier::{
    Combination, FeatureExpansion, FourierDispersion, FourierKernel, FourierWeights,
};
pub use dispersion::kernel::{GaussianKernel, Kernel, KernelExpansion};
pub use dispersion::low_rank::{LowRankGaussian, NystromFeatures};
pub use dispersion::polynomial::{PolynomialDispersion, PolynomialFeatures};
pub use dispersion::sum::{StackedFeatures, SumDispersion};
pub use dispersion::total_variation::{
    GraphInterpolation, NodeInterpolation, TotalVariation, TvPenalty,
};
pub use dispersion::{Dispersion, FeatureMap, KernelDispersion, Penalty, QuadraticPenalty};
pub use error::{Error, Result};
pub use estimate::{Estimate, Prediction, PredictionSettings};
pub use identify::posterior::Posterior;
pub use identify::problem::{Problem, ProblemBlock};
pub use identify::{
    BlockEstimate, CostTerms, Diagnostics, Identification, IdentifySettings,
    IdentifySettingsBuilder, InitialState, SolverChoice, Timings, identify, identify_problem,
};
pub use model::access::BlockAccess;
pub use model::interpolant::Interpolant;
pub use model::lft::{Lft, LftDims, LftMatrices};
pub use model::maps::{ExprMap, LookupTable};
pub use model::measurability::ZSource;
pub use model::monotone::Monotonicity;
pub use model::order::BlockPlace;
pub use model::parametric::ParametricMap;
pub use model::simulate::{MapBinding, Simulation};
pub use model::structure::{LinearPart, PlacedBlock, Site, Structure};
pub use model::{Data, Model, NonlinearBlock};
pub use solver::choice::{SolveStatus, SolverKind, SolverReason};
pub use structid_lti::Signal;
pub use validation::{
    RecordsValidation, ValidationReport, ValidationSettings, validate, validate_records,
};

// Dynamic scalar blocks (operators with memory).
pub use model::hysteresis::{
    BoucWen, HysteresisOperator, OperatorJacobian, Play, PrandtlIshlinskii, Stop,
};

//! Choosing β (and the kernel width σ) from the data.
//!
//! J is the negative log posterior of a Gaussian-process model: w ~ N(0, s²·K/(L·β)) and
//! e ~ N(0, s²·I), so the residual r = T_ye·e + T_yw·w is N(0, (s²/(L·β))·M) with
//!
//! ```text
//! M(β) = L·β·A + B,    A = T_ye·T_yeᵀ,    B = Σ_i T_i·K_i·T_iᵀ      (n = L·n_y rows)
//! ```
//!
//! # Criteria
//! * **Maximum marginal likelihood** ([`Criterion::MarginalLikelihood`], quadratic
//!   dispersions). With s² profiled out in closed form (ŝ²/(L·β) = rᵀM⁻¹r/n), minus the log
//!   likelihood is, up to a constant, `ML(β) = (n/2)·ln(rᵀM⁻¹r/n) + ½·ln det M`.
//! * **Generalised cross-validation** ([`Criterion::Gcv`], quadratic dispersions) of the linear
//!   smoother r ↦ T_yw·ŵ = B·M⁻¹·r, in noise-whitened units: with W the whitening
//!   (WᵀW = A⁻¹), `GCV(β) = n·‖W(I − H)r‖² / tr(I − H)²`, where (I − H)·r = L·β·A·M⁻¹·r.
//! * **Blocked K-fold cross-validation** ([`Criterion::CrossValidation`], any dispersion,
//!   total variation included). The record's samples are cut into K contiguous blocks. For
//!   each block, the model is fitted with that block's output equations left out
//!   ([`Problem::with_held_out`](crate::Problem::with_held_out)); ŵ and ê are still estimated at every sample (ŵ_k is the
//!   fitted map at the measured z_k, ê_k its estimate given the other samples — zero for white
//!   noise). The score is the mean squared prediction error of the held-out outputs,
//!   `y_k − (T_yu·u + T_yw·ŵ + T_ye·ê (+ O·x₀))_k`, over all held-out samples of all folds.
//! * **Validation simulation error** ([`Criterion::Validation`], any dispersion): fit on the
//!   estimation record, simulate the model with the fitted maps in the loop on a separate
//!   validation record (zero initial state, e = 0) and score the mean squared simulation
//!   error — the usual practice in system identification. Validation data of several records
//!   are simulated record by record, each from rest, and the squared errors pooled.
//!
//! # Search
//! β is found by a bracketing golden-section search on log₁₀ β (walk downhill by decades
//! from a start until the criterion rises, then narrow to [`SelectionSettings::tolerance`]
//! decades), not a grid. With σ tuned too ([`SelectionSettings::tune_sigma`]), the widths of
//! every block that has one are scaled by one common factor, itself chosen by the same search
//! on log₁₀ of the factor, with β optimised for each factor (a nested 2-D search). Every
//! trial is recorded in [`Selection::curve`].
//!
//! # Cost
//! * **Feature path** (every block with finitely many features, e.g. Fourier or low-rank
//!   Gaussian): one pass over the record accumulates G = [F r]ᵀWᵀW[F r] with the *unscaled*
//!   features; every trial (β, σ) then lives in the m-dimensional space. An eigendecomposition
//!   A = Λ^½G_FFΛ^½ = U·S·Uᵀ per σ makes each β an O(m) evaluation:
//!   `rᵀM⁻¹r = (rᵀWᵀWr − Σ h_j²/(s_j + L·β))/(L·β)` with h = Uᵀ·Λ^½·G_Fr, and
//!   `ln det M = ln det A_noise + (n − m)·ln(L·β) + Σ ln(s_j + L·β)` (determinant lemma). For the
//!   Gaussian-like Fourier family σ changes only Λ, so the pass is reused across σ (it is
//!   redone only when a smaller σ needs more harmonics than the pass has).
//! * **Dense path** (any kernel). With a static noise path the rows are whitened (A = I) and
//!   B is never assembled while low-rank factors suffice: pivoted Cholesky factors of the
//!   Gram matrices, K_i ≈ U_i·U_iᵀ, are grown on demand (one Gram column per pivot) and pushed
//!   through the whitened paths, B ≈ V·Vᵀ with V = [W·T_i·U_i], so that a trial costs O(k)
//!   after O(L·k²) work per σ shared by all β: the same formulas as the feature path with V in
//!   place of F·Λ^½. The discarded part B − V·Vᵀ is positive semidefinite with trace t at most
//!   Σ_i c_i·tr(K_i − U_i·U_iᵀ), c_i = (Σ_k ‖W·h_k‖)² bounding the gain of path i, and t bounds
//!   the error of the criterion by (n + 1)·t/(2·L·β); the rank grows until that bound is
//!   below 1e-4. When that would need a rank above n/10, B is assembled once for that σ and
//!   factored the same way (up to rank n/10), and beyond that its eigendecomposition
//!   B = U·S·Uᵀ, computed once, makes every β exact in O(n). Dynamic noise paths assemble A
//!   and B once per σ and use a Cholesky factorisation of M at every trial.
//! * Cross-validation and validation selection refit the model for every trial (K fits, resp.
//!   one fit and one simulation): they work for any dispersion and solver, at that cost.
//!
//! ```
//! use std::sync::Arc;
//! use structid_core::selection::{select, Criterion, SelectionSettings};
//! use structid_core::{paper, IdentifySettings, KernelDispersion};
//! let exp = paper::spray(300, 1.0, Arc::new(KernelDispersion::gaussian(0.1).unwrap()), 3).unwrap();
//! let how = SelectionSettings::builder().criterion(Criterion::MarginalLikelihood).build().unwrap();
//! let sel = select(&exp.model, &exp.data, None, &IdentifySettings::default(), &how).unwrap();
//! assert!(sel.beta > 0.0 && sel.curve.len() >= 5);
//! assert_eq!(sel.identification.cost.beta, sel.beta);
//! ```

mod cross_validation;
mod dense;
mod features;
mod report;
mod score;
mod search;
mod settings;
mod validation;

pub use report::{BetaSelection, Bound, Selection, Trial};
pub use search::{select, select_beta};
pub use settings::{Criterion, SelectionSettings, SelectionSettingsBuilder};

// the unit tests reach the dense score and the β-score trait through `super::*`
#[cfg(test)]
use crate::identify::problem::Problem;
#[cfg(test)]
use dense::DenseScore;
#[cfg(test)]
use score::BetaScore;

#[cfg(test)]
mod tests;

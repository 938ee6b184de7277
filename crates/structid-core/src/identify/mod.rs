//! The `identify` executor: settings in, an [`Identification`] out.

pub mod posterior;
pub mod problem;
pub mod result;
pub mod settings;

pub use crate::initial_state::InitialState;
pub use result::{BlockEstimate, CostTerms, Diagnostics, Identification, Timings};
pub use settings::{IdentifySettings, IdentifySettingsBuilder, SolverChoice};

use std::time::Instant;

use crate::error::{Error, Result, positive_finite};
use crate::identify::problem::Problem;
use crate::model::{Data, Model};
use crate::solver;
use crate::solver::choice::{SolverKind, SolverReason, choose_with};

pub use crate::solver::choice::CONIC_AUTO_LIMIT;

/// Identifies the static maps of `model` from `data`: the minimiser of the paper's eq. (4),
///
/// J(e, w) = (1/L)·Σ_k e_kᵀe_k + β·Σ_i D_i(z^\[i\], w^\[i\]) subject to T_ye·e + T_yw·w = y − T_yu·u,
///
/// with a zero initial state.
///
/// ```
/// use std::sync::Arc;
/// use nalgebra::dmatrix;
/// use structid_core::*;
/// use structid_lti::Signal;
/// // y_k = tanh(u_k) + e_k, observed without noise here.
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![0.0], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![0.0],
///     cy: dmatrix![0.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![1.0],
///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
/// }).unwrap();
/// let f = NonlinearBlock::new("f", vec![0], 0, Arc::new(KernelDispersion::gaussian(0.3).unwrap()));
/// let model = Model::new(lft, vec![f]).unwrap();
/// let u = Signal::from_fn(200, 1, |k, _| -2.0 + 4.0 * k as f64 / 199.0);
/// let y = Signal::from_fn(200, 1, |k, _| u.get(k, 0).tanh());
/// let data = Data::new(u, y).unwrap();
/// let settings = IdentifySettings::builder().beta(1e-4).build().unwrap();
/// let id = identify(&model, &data, &settings).unwrap();
/// assert!((id.blocks[0].predict(&[0.5]) - 0.5f64.tanh()).abs() < 0.01);
/// ```
pub fn identify(model: &Model, data: &Data, settings: &IdentifySettings) -> Result<Identification> {
    let t0 = Instant::now();
    let problem = match settings.initial_state() {
        InitialState::Zero => Problem::from_model(model, data)?,
        InitialState::Estimate => Problem::from_model_with_initial_state(model, data)?,
    };
    let mut id = identify_problem(&problem, settings)?;
    id.diagnostics.timings.prepare += t0.elapsed().as_secs_f64() - id.diagnostics.timings.total;
    id.diagnostics.timings.total = t0.elapsed().as_secs_f64();
    Ok(id)
}

/// [`identify()`] for a problem posed directly in operator form.
pub fn identify_problem(problem: &Problem, settings: &IdentifySettings) -> Result<Identification> {
    positive_finite("beta", settings.beta())?;
    // A problem without blocks is fine for validation (a nominal linear model), not here.
    if problem.blocks().is_empty() {
        return Err(Error::InvalidStructure(
            "the problem has no nonlinear block to identify".into(),
        ));
    }
    let id = match settings.solver() {
        SolverChoice::Exact => solver::exact::solve(problem, settings)?,
        SolverChoice::Features => solver::features::solve(problem, settings)?,
        SolverChoice::Clarabel => solver::conic::solve(problem, settings)?,
        SolverChoice::Admm => solver::admm::solve(problem, settings)?,
        SolverChoice::Auto => {
            // Build the penalties once: the kind decides the family of solvers.
            let t_start = std::time::Instant::now();
            let penalties = solver::penalties(problem)?;
            let (kind, reason) = choose_with(problem, &penalties, settings);
            let mut id = match kind {
                SolverKind::Clarabel => {
                    solver::conic::solve_with(problem, settings, penalties, t_start)?
                }
                SolverKind::Admm => {
                    solver::admm::solve_with(problem, settings, penalties, t_start)?
                }
                SolverKind::Features { .. } => solver::features::solve(problem, settings)?,
                SolverKind::Exact => solver::exact::solve(problem, settings)?,
            };
            if let SolverReason::ExactOverBudget { needed_bytes, .. } = reason {
                id.diagnostics.warnings.push(format!(
                    "the exact solver would need {} MiB, more than the memory budget; the feature solver was used",
                    needed_bytes >> 20
                ));
            }
            id.diagnostics.solver_reason = reason;
            id
        }
    };
    Ok(id)
}

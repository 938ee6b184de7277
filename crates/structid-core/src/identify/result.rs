//! What [`identify`](super::identify) returns: the estimate of every block, the cost terms and
//! the solver's diagnostics.

use structid_lti::Signal;

use crate::error::Result;
use crate::identify::posterior::Posterior;
use crate::model::interpolant::Interpolant;
use crate::model::measurability::ZSource;
use crate::solver::status::{SolveStatus, SolverKind, SolverReason};

/// The cost terms of eq. (4) at the optimum.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CostTerms {
    /// μ = (1/L)·Σ_k |ê_k|².
    pub noise: f64,
    /// D_i(z^\[i\], ŵ^\[i\]) for each block.
    pub dispersions: Vec<f64>,
    /// β.
    pub beta: f64,
    /// J = μ + β·Σ_i D_i.
    pub total: f64,
}

/// Wall-clock timings in seconds.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Timings {
    /// Computing z, r and the penalties.
    pub prepare: f64,
    /// Forming the system matrix.
    pub assemble: f64,
    /// Factorising it.
    pub factor: f64,
    /// Solving and recovering ŵ, ê and the maps.
    pub solve: f64,
    /// Everything.
    pub total: f64,
}

/// Solver diagnostics.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Diagnostics {
    /// Which solver ran (serialised as its printed name, e.g. `features (m = 63)`).
    pub solver: SolverKind,
    /// Why it was chosen (the automatic choice's rule, or "requested"; serialised as the
    /// printed sentence).
    pub solver_reason: SolverReason,
    /// How the solver stopped: anything but [`SolveStatus::Solved`] or
    /// [`SolveStatus::AlmostSolved`] means the estimate is an unconverged iterate (see
    /// [`Identification::converged`]).
    pub status: SolveStatus,
    /// What the solver reported when it stopped early (residuals, what to try); `None` when it
    /// converged.
    pub status_detail: Option<String>,
    /// Iterations of an iterative solver (0 for the direct ones).
    pub iterations: usize,
    /// Final primal residual of an iterative solver.
    pub primal_residual: Option<f64>,
    /// Final dual residual of an iterative solver.
    pub dual_residual: Option<f64>,
    /// Dimension of the system matrix M (L·n_y, less dropped samples).
    pub system_size: usize,
    /// Output samples (index k·n_y + channel) that depend on neither e nor w and were left out.
    pub dropped_samples: Vec<usize>,
    /// Largest |r| over the dropped samples: their consistency with the model (should be ≈ 0).
    pub dropped_max_abs_residual: f64,
    /// Jitter added to the diagonal of M when it was numerically singular (0 when not needed).
    pub diagonal_jitter: f64,
    /// (max Lᵢᵢ / min Lᵢᵢ)² of the Cholesky factor: a lower bound on the condition number of M.
    pub condition_lower_bound: f64,
    /// ‖T_ye·ê + T_yw·ŵ − r‖ / ‖r‖ over the samples kept.
    pub feasibility_residual: f64,
    /// Estimated peak memory of the solver in bytes.
    pub peak_memory_bytes: u64,
    /// Timings.
    pub timings: Timings,
    /// Anything the user should know about.
    pub warnings: Vec<String>,
}

/// The estimate of one static block.
pub struct BlockEstimate {
    /// Block name.
    pub name: String,
    /// The w channel it produces.
    pub output: usize,
    /// Description of its dispersion, e.g. `gaussian(sigma=0.4)`.
    pub dispersion: String,
    /// The dispersion's parameters.
    pub parameters: Vec<(String, f64)>,
    /// Its input samples z^\[i\].
    pub z: Signal,
    /// ŵ^\[i\] at the samples.
    pub w_hat: Vec<f64>,
    /// D_i(z^\[i\], ŵ^\[i\]).
    pub dispersion_value: f64,
    /// The interpolant N̂_i.
    pub map: Box<dyn Interpolant>,
}

impl BlockEstimate {
    /// N̂_i(z).
    pub fn predict(&self, z: &[f64]) -> f64 {
        self.map.eval(z)
    }
}

impl std::fmt::Debug for BlockEstimate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BlockEstimate")
            .field("name", &self.name)
            .field("output", &self.output)
            .field("dispersion", &self.dispersion)
            .field("dispersion_value", &self.dispersion_value)
            .finish_non_exhaustive()
    }
}

/// The result of [`identify()`](crate::identify()).
#[derive(Debug)]
pub struct Identification {
    /// ŵ (L × n_w), channel c from the block with `output == c`.
    pub w_hat: Signal,
    /// ê (L × n_e).
    pub e_hat: Signal,
    /// One estimate per block, in the problem's block order.
    pub blocks: Vec<BlockEstimate>,
    /// Cost terms.
    pub cost: CostTerms,
    /// How z was obtained.
    pub z_source: ZSource,
    /// The estimated initial state x₀, when it was estimated; with several records, the n
    /// entries of each record's x₀ one record after the other.
    pub initial_state: Option<Vec<f64>>,
    /// Diagnostics.
    pub diagnostics: Diagnostics,
    /// The posterior of the maps, kept by the exact and feature solvers when
    /// [`IdentifySettingsBuilder::posterior`](crate::IdentifySettingsBuilder::posterior) is on (`None` otherwise, and always for the
    /// iterative solvers); see [`Identification::posterior_std`].
    pub posterior: Option<Posterior>,
}

impl Identification {
    /// The identification if its solver converged ([`SolveStatus::is_converged`]), else
    /// [`Error::NotConverged`](crate::Error::NotConverged) with the solver's report: for callers that cannot use an
    /// unconverged iterate.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{identify, paper, IdentifySettings, SolveStatus, TotalVariation};
    /// use structid_core::{SolverChoice, solver::admm::AdmmSettings};
    /// let exp = paper::spray(300, 0.5, Arc::new(TotalVariation::new()), 2).unwrap();
    /// let quick = IdentifySettings::builder()
    ///     .solver(SolverChoice::Admm)
    ///     .admm(AdmmSettings::builder().max_iterations(2).build().unwrap())
    ///     .build()
    ///     .unwrap();
    /// let id = identify(&exp.model, &exp.data, &quick).unwrap();
    /// assert_eq!(id.diagnostics.status, SolveStatus::MaxIterations);
    /// assert!(id.converged().unwrap_err().to_string().contains("did not converge"));
    /// ```
    pub fn converged(self) -> Result<Self> {
        self.check_converged()?;
        Ok(self)
    }

    /// [`converged`](Self::converged) without giving the estimate up: the
    /// [`Error::NotConverged`](crate::Error::NotConverged) it would return, for a caller that keeps the last iterate (the
    /// CLI writes it, marked as not converged, and then reports the error).
    ///
    /// ```
    /// # use std::sync::Arc;
    /// # use structid_core::{identify, paper, IdentifySettings, SolverChoice, TotalVariation};
    /// # use structid_core::solver::admm::AdmmSettings;
    /// let exp = paper::spray(300, 0.5, Arc::new(TotalVariation::new()), 2).unwrap();
    /// let quick = IdentifySettings::builder()
    ///     .solver(SolverChoice::Admm)
    ///     .admm(AdmmSettings::builder().max_iterations(2).build().unwrap())
    ///     .build()
    ///     .unwrap();
    /// let id = identify(&exp.model, &exp.data, &quick).unwrap();
    /// assert!(id.check_converged().is_err());
    /// assert!(!id.blocks[0].w_hat.is_empty()); // the iterate is still there
    /// ```
    pub fn check_converged(&self) -> Result<()> {
        let d = &self.diagnostics;
        if d.status.is_converged() {
            Ok(())
        } else {
            Err(crate::solver::status::not_converged(
                d.solver,
                d.iterations,
                d.status_detail.as_deref(),
                d.status,
            ))
        }
    }

    /// The estimate of the block called `name`.
    pub fn block(&self, name: &str) -> Option<&BlockEstimate> {
        self.blocks.iter().find(|b| b.name == name)
    }

    /// The estimated maps, in block order, ready for [`Model::simulate`](crate::Model::simulate).
    pub fn maps(&self) -> Vec<&dyn Interpolant> {
        self.blocks.iter().map(|b| b.map.as_ref()).collect()
    }

    /// The pointwise posterior standard deviation of block `block`'s map (index into
    /// [`Identification::blocks`]) at every sample of `points` (one point per sample, as many
    /// channels as the block has inputs): N̂ ± 1.96·std is the 95 % band. See
    /// [`crate::identify::posterior`] for the formula, the noise level ŝ² it uses and the cost.
    ///
    /// `Ok(None)` when no posterior was kept: [`IdentifySettingsBuilder::posterior`](crate::IdentifySettingsBuilder::posterior) off, an
    /// iterative solver (total variation, Clarabel, ADMM), or a user-defined penalty that
    /// cannot evaluate its kernel at new points.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) when `block` is out of range, [`Error::DimensionMismatch`](crate::Error::DimensionMismatch)
    /// when `points` has the wrong number of channels, [`Error::NonFiniteData`](crate::Error::NonFiniteData) for NaN or
    /// infinite coordinates (checked whether or not a posterior was kept).
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{identify, paper, IdentifySettings, KernelDispersion, Signal};
    /// let exp = paper::spray(300, 0.5, Arc::new(KernelDispersion::gaussian(0.1).unwrap()), 2).unwrap();
    /// let on = IdentifySettings::builder().beta(0.01).posterior(true).build().unwrap();
    /// let id = identify(&exp.model, &exp.data, &on).unwrap();
    /// let z = Signal::from_fn(3, 1, |k, _| -0.5 + 0.5 * k as f64);
    /// let std = id.posterior_std(1, &z).unwrap().unwrap();
    /// let g = id.blocks[1].map.eval_many(&z);
    /// println!("g(0) in [{:.3}, {:.3}]", g[1] - 1.96 * std[1], g[1] + 1.96 * std[1]);
    /// assert!(id.posterior_std(2, &z).is_err());
    /// // Off by default: no posterior.
    /// let off = identify(&exp.model, &exp.data, &IdentifySettings::default()).unwrap();
    /// assert!(off.posterior_std(1, &z).unwrap().is_none());
    /// ```
    pub fn posterior_std(&self, block: usize, points: &Signal) -> Result<Option<Vec<f64>>> {
        let est = self.blocks.get(block).ok_or_else(|| {
            crate::identify::posterior::block_out_of_range(block, self.blocks.len())
        })?;
        crate::identify::posterior::check_points(points, est.z.channels())?;
        match &self.posterior {
            Some(p) => p.std(block, points),
            None => Ok(None),
        }
    }
}

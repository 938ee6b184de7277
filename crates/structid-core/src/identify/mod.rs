//! The `identify` executor: settings in, an [`Identification`] out.

pub mod posterior;
pub mod problem;

use std::time::Instant;

use structid_lti::Signal;

use crate::error::{Error, Result, positive_finite};
use crate::interpolant::Interpolant;
use crate::measurability::ZSource;
use crate::model::{Data, Model};
use crate::posterior::Posterior;
use crate::problem::Problem;
use crate::solver;
use crate::solver::admm::AdmmSettings;
use crate::solver::choice::{SolveStatus, SolverKind, SolverReason, choose_with};
use crate::solver::conic::ConicSettings;

pub use crate::solver::choice::CONIC_AUTO_LIMIT;

/// Which solver `identify` uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum SolverChoice {
    /// Pick from the dispersions and the problem size.
    #[default]
    Auto,
    /// The exact dual (representer) solve with the dense L·n_y × L·n_y matrix M.
    Exact,
    /// The feature-space solve, linear in L, for dispersions with finitely many features
    /// (e.g. [`crate::FourierDispersion`]).
    Features,
    /// The conic program, solved by the interior-point solver Clarabel
    /// ([`crate::solver::conic`]): exact; sparse for total variation, dense in L for quadratic
    /// blocks, so the one solver for models that mix the two.
    Clarabel,
    /// ADMM for total-variation dispersions ([`crate::solver::admm`]): a Kalman smoother and an
    /// exact proximal step per iteration, linear in L.
    Admm,
}

impl SolverChoice {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            SolverChoice::Auto => "auto",
            SolverChoice::Exact => "exact",
            SolverChoice::Features => "features",
            SolverChoice::Clarabel => "clarabel",
            SolverChoice::Admm => "admm",
        }
    }
}

/// Settings of [`identify()`]; build them with [`IdentifySettings::builder`].
///
/// ```
/// use structid_core::IdentifySettings;
/// let s = IdentifySettings::builder().beta(0.1).build().unwrap();
/// assert_eq!(s.beta(), 0.1);
/// assert!(IdentifySettings::builder().beta(-1.0).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IdentifySettings {
    beta: f64,
    solver: SolverChoice,
    memory_limit_bytes: Option<u64>,
    initial_state: InitialState,
    conic: ConicSettings,
    admm: AdmmSettings,
    posterior: bool,
}

pub use crate::initial_state::InitialState;

impl Default for IdentifySettings {
    /// β = 0.01 (the middle of the paper's range 0.001–0.1), automatic solver, memory limit
    /// three quarters of the memory available when identification starts.
    fn default() -> Self {
        Self {
            beta: 0.01,
            solver: SolverChoice::Auto,
            memory_limit_bytes: None,
            initial_state: InitialState::Zero,
            conic: ConicSettings::default(),
            admm: AdmmSettings::default(),
            posterior: false,
        }
    }
}

impl IdentifySettings {
    /// A builder starting from the defaults.
    pub fn builder() -> IdentifySettingsBuilder {
        IdentifySettingsBuilder {
            inner: Self::default(),
        }
    }

    /// The same settings with the posterior kept or not.
    ///
    /// ```
    /// use structid_core::IdentifySettings;
    /// assert!(IdentifySettings::default().with_posterior(true).posterior());
    /// ```
    pub fn with_posterior(&self, posterior: bool) -> Self {
        Self {
            posterior,
            ..self.clone()
        }
    }

    /// The same settings with another solver choice.
    ///
    /// ```
    /// use structid_core::{IdentifySettings, SolverChoice};
    /// let s = IdentifySettings::default().with_solver(SolverChoice::Exact);
    /// assert_eq!(s.solver(), SolverChoice::Exact);
    /// ```
    pub fn with_solver(&self, solver: SolverChoice) -> Self {
        Self {
            solver,
            ..self.clone()
        }
    }

    /// The same settings with another initial-state treatment.
    pub fn with_initial_state(&self, initial_state: InitialState) -> Self {
        Self {
            initial_state,
            ..self.clone()
        }
    }

    /// The same settings with another β (> 0), e.g. for a sweep.
    ///
    /// ```
    /// use structid_core::IdentifySettings;
    /// let s = IdentifySettings::default().with_beta(0.1).unwrap();
    /// assert_eq!(s.beta(), 0.1);
    /// assert!(IdentifySettings::default().with_beta(0.0).is_err());
    /// ```
    pub fn with_beta(&self, beta: f64) -> Result<Self> {
        positive_finite("beta", beta)?;
        Ok(Self {
            beta,
            ..self.clone()
        })
    }

    /// The weight β of the dispersion against the noise energy.
    pub fn beta(&self) -> f64 {
        self.beta
    }

    /// The solver choice.
    pub fn solver(&self) -> SolverChoice {
        self.solver
    }

    /// How the initial state is treated.
    pub fn initial_state(&self) -> InitialState {
        self.initial_state
    }

    /// Settings of the conic (Clarabel) solver.
    pub fn conic(&self) -> &ConicSettings {
        &self.conic
    }

    /// Settings of the ADMM solver.
    pub fn admm(&self) -> &AdmmSettings {
        &self.admm
    }

    /// Whether the exact and feature solvers keep what the posterior bands need
    /// ([`Identification::posterior`]).
    pub fn posterior(&self) -> bool {
        self.posterior
    }

    /// The memory budget in bytes (`None`: detect at run time).
    pub fn memory_limit_bytes(&self) -> Option<u64> {
        self.memory_limit_bytes
    }

    /// The budget that applies now: the explicit limit, or ¾ of `MemAvailable`
    /// (4 GiB when it cannot be read).
    pub fn effective_memory_limit(&self) -> u64 {
        self.memory_limit_bytes
            .unwrap_or_else(|| available_memory_bytes().map_or(4 << 30, |b| b / 4 * 3))
    }
}

fn available_memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Builder for [`IdentifySettings`]; [`IdentifySettingsBuilder::build`] validates.
#[derive(Clone, Debug)]
pub struct IdentifySettingsBuilder {
    inner: IdentifySettings,
}

impl IdentifySettingsBuilder {
    /// β > 0.
    pub fn beta(mut self, beta: f64) -> Self {
        self.inner.beta = beta;
        self
    }
    /// The solver.
    pub fn solver(mut self, solver: SolverChoice) -> Self {
        self.inner.solver = solver;
        self
    }
    /// Zero or estimated initial state.
    pub fn initial_state(mut self, initial_state: InitialState) -> Self {
        self.inner.initial_state = initial_state;
        self
    }
    /// Settings of the conic (Clarabel) solver.
    pub fn conic(mut self, conic: ConicSettings) -> Self {
        self.inner.conic = conic;
        self
    }
    /// Settings of the ADMM solver.
    pub fn admm(mut self, admm: AdmmSettings) -> Self {
        self.inner.admm = admm;
        self
    }
    /// Keep the posterior of the maps (default `false`): the exact and feature solvers then
    /// store their Cholesky factor and the noise level in [`Identification::posterior`], and
    /// [`Identification::posterior_std`] gives pointwise standard deviations (uncertainty
    /// bands; see [`crate::posterior`]). The exact solver's factor is n×n f64 (n = L·n_y),
    /// kept as long as the identification; its memory estimate includes it.
    ///
    /// ```
    /// use structid_core::IdentifySettings;
    /// assert!(!IdentifySettings::default().posterior());
    /// assert!(IdentifySettings::builder().posterior(true).build().unwrap().posterior());
    /// ```
    pub fn posterior(mut self, keep: bool) -> Self {
        self.inner.posterior = keep;
        self
    }
    /// An explicit memory budget in bytes.
    pub fn memory_limit_bytes(mut self, bytes: u64) -> Self {
        self.inner.memory_limit_bytes = Some(bytes);
        self
    }
    /// Validates and returns the settings.
    pub fn build(self) -> Result<IdentifySettings> {
        positive_finite("beta", self.inner.beta)?;
        if self.inner.memory_limit_bytes == Some(0) {
            return Err(Error::InvalidParameter {
                name: "memory_limit_bytes".into(),
                value: 0.0,
                reason: "must be positive".into(),
            });
        }
        Ok(self.inner)
    }
}

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

/// The result of [`identify()`].
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
    /// The estimated initial state x₀, when it was estimated.
    pub initial_state: Option<Vec<f64>>,
    /// Diagnostics.
    pub diagnostics: Diagnostics,
    /// The posterior of the maps, kept by the exact and feature solvers when
    /// [`IdentifySettingsBuilder::posterior`] is on (`None` otherwise, and always for the
    /// iterative solvers); see [`Identification::posterior_std`].
    pub posterior: Option<Posterior>,
}

impl Identification {
    /// The identification if its solver converged ([`SolveStatus::is_converged`]), else
    /// [`Error::NotConverged`] with the solver's report: for callers that cannot use an
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
        let d = &self.diagnostics;
        if d.status.is_converged() {
            Ok(self)
        } else {
            Err(crate::solver::choice::not_converged(
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

    /// The estimated maps, in block order, ready for [`Model::simulate`].
    pub fn maps(&self) -> Vec<&dyn Interpolant> {
        self.blocks.iter().map(|b| b.map.as_ref()).collect()
    }

    /// The pointwise posterior standard deviation of block `block`'s map (index into
    /// [`Identification::blocks`]) at every sample of `points` (one point per sample, as many
    /// channels as the block has inputs): N̂ ± 1.96·std is the 95 % band. See
    /// [`crate::posterior`] for the formula, the noise level ŝ² it uses and the cost.
    ///
    /// `Ok(None)` when no posterior was kept: [`IdentifySettingsBuilder::posterior`] off, an
    /// iterative solver (total variation, Clarabel, ADMM), or a user-defined penalty that
    /// cannot evaluate its kernel at new points.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] when `block` is out of range, [`Error::DimensionMismatch`]
    /// when `points` has the wrong number of channels, [`Error::NonFiniteData`] for NaN or
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
        let est = self
            .blocks
            .get(block)
            .ok_or_else(|| crate::posterior::block_out_of_range(block, self.blocks.len()))?;
        crate::posterior::check_points(points, est.z.channels())?;
        match &self.posterior {
            Some(p) => p.std(block, points),
            None => Ok(None),
        }
    }
}

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
    let problem = match settings.initial_state {
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
    positive_finite("beta", settings.beta)?;
    // A problem without blocks is fine for validation (a nominal linear model), not here.
    if problem.blocks().is_empty() {
        return Err(Error::InvalidStructure(
            "the problem has no nonlinear block to identify".into(),
        ));
    }
    let id = match settings.solver {
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
                    let tv = solver::tv_from_penalties(problem, penalties, "admm")?;
                    solver::admm::solve_with(problem, settings, tv, t_start)?
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

//! The exact solver for total-variation dispersions: a sparse conic (linear–quadratic) program
//! solved by the interior-point solver Clarabel.
//!
//! With the states x_k of the realisation of [T_ye, T_yw] as variables, the node values v_i of
//! each block (w_k^\[i\] = v_i,node(k)) and one epigraph variable t per graph edge:
//!
//! ```text
//! minimise    (1/L)·Σ_k |e_k|² + β·Σ_i Σ_(a,b)∈E_i c_ab·t_ab
//! subject to  x_(k+1) = A·x_k + B_e·e_k + B_w·w_k          (k = 0 … L−2)
//!             r_k     = C·x_k + D_ye·e_k + D_yw·w_k        (k = 0 … L−1)
//!             x_0 = 0                                       (unless x₀ is estimated)
//!             −t_ab ≤ v_a − v_b ≤ t_ab
//! ```
//!
//! Every constraint row touches O(n + n_e + n_w) variables, so the program has O(L·n) non-zeros
//! and no dense Toeplitz rows. Clarabel's objective is ½·xᵀPx + qᵀx, so P = (2/L)·I on e.
//!
//! The interior-point method's sparse LDLᵀ factorisation couples the time chain (the dynamics)
//! with the z-sorted chain (the edges); with a white-noise input the z order is a random
//! permutation of time and fill-in grows super-linearly (see `BENCHMARKS.md`). Long records use
//! [`super::admm`] instead; [`crate::identify()`] chooses by size.

use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

use crate::error::{Error, Result, positive_finite};
use crate::identify::{Diagnostics, Identification, IdentifySettings, Timings};
use crate::problem::Problem;
use crate::solver::realisation::{joint_realisation, unreachable_samples};
use crate::solver::{finish_tv, tv_penalties};
use crate::total_variation::TvPenalty;

/// Settings of the conic (Clarabel) solver.
///
/// ```
/// use structid_core::solver::conic::ConicSettings;
/// let s = ConicSettings::builder().tolerance(1e-9).max_iterations(300).build().unwrap();
/// assert_eq!(s.tolerance(), 1e-9);
/// assert!(ConicSettings::builder().tolerance(0.0).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ConicSettings {
    tolerance: f64,
    max_iterations: u32,
    time_limit: Option<f64>,
}

impl Default for ConicSettings {
    /// Tolerance 1e-8 (Clarabel's default, for the duality gap and feasibility), 200
    /// iterations, no time limit.
    fn default() -> Self {
        Self {
            tolerance: 1e-8,
            max_iterations: 200,
            time_limit: None,
        }
    }
}

impl ConicSettings {
    /// A builder from the defaults.
    pub fn builder() -> ConicSettingsBuilder {
        ConicSettingsBuilder(Self::default())
    }
    /// Relative and absolute tolerance on the duality gap and the residuals.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }
    /// The iteration limit.
    pub fn max_iterations(&self) -> u32 {
        self.max_iterations
    }
    /// The time limit in seconds, if any.
    pub fn time_limit(&self) -> Option<f64> {
        self.time_limit
    }
}

/// Builder for [`ConicSettings`].
#[derive(Clone, Debug)]
pub struct ConicSettingsBuilder(ConicSettings);

impl ConicSettingsBuilder {
    /// Tolerance (> 0).
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.0.tolerance = tol;
        self
    }
    /// Iteration limit (≥ 1).
    pub fn max_iterations(mut self, n: u32) -> Self {
        self.0.max_iterations = n;
        self
    }
    /// Time limit in seconds (> 0).
    pub fn time_limit(mut self, seconds: f64) -> Self {
        self.0.time_limit = Some(seconds);
        self
    }
    /// Validates.
    pub fn build(self) -> Result<ConicSettings> {
        super::check_iterative(NAME, self.0.tolerance, self.0.max_iterations as usize)?;
        if let Some(t) = self.0.time_limit {
            positive_finite("conic time_limit", t)?;
        }
        Ok(self.0)
    }
}

/// The solver's name in reports.
pub const NAME: &str = "clarabel";

/// Column layout of the conic program's variables.
struct Layout {
    n: usize,
    ne: usize,
    e0: usize,
    v0: Vec<usize>,
    t0: Vec<usize>,
    total: usize,
}

impl Layout {
    fn x(&self, k: usize, j: usize) -> usize {
        k * self.n + j
    }
    fn e(&self, k: usize, j: usize) -> usize {
        self.e0 + k * self.ne + j
    }
}

/// Solves a problem whose blocks all have total-variation dispersions; see the module docs.
pub fn solve(problem: &Problem, settings: &IdentifySettings) -> Result<Identification> {
    let t_start = Instant::now();
    let penalties = tv_penalties(problem, NAME)?;
    solve_with(problem, settings, penalties, t_start)
}

/// [`solve`] with the blocks' penalties already built.
pub(crate) fn solve_with(
    problem: &Problem,
    settings: &IdentifySettings,
    penalties: Vec<TvPenalty>,
    t_start: Instant,
) -> Result<Identification> {
    let beta = settings.beta();
    let conic = settings.conic();
    let real = joint_realisation(problem, NAME)?;
    let (len, ny) = (problem.len(), problem.outputs());
    let ss = &real.ss;
    let (n, ne) = (ss.order(), real.noise_inputs);
    let (a, b, c, d) = (ss.a(), ss.b(), ss.c(), ss.d());
    let dropped = unreachable_samples(&real, len);
    let t_prepared = Instant::now();

    // Block i drives input column ne + output_i of the realisation.
    let blocks = problem.blocks();
    let mut v0 = Vec::with_capacity(blocks.len());
    let mut t0 = Vec::with_capacity(blocks.len());
    let mut next = len * (n + ne);
    for p in &penalties {
        v0.push(next);
        next += p.nodes();
    }
    for p in &penalties {
        t0.push(next);
        next += p.edges().len();
    }
    let lay = Layout {
        n,
        ne,
        e0: len * n,
        v0,
        t0,
        total: next,
    };
    let w_cols: Vec<usize> = blocks.iter().map(|bl| ne + bl.output).collect();

    let (mut ri, mut ci, mut vals) = (Vec::new(), Vec::new(), Vec::new());
    let mut rhs = Vec::new();
    let mut row = 0;
    let mut push = |r: usize, col: usize, v: f64, ri: &mut Vec<usize>, ci: &mut Vec<usize>| {
        if v != 0.0 {
            ri.push(r);
            ci.push(col);
            vals.push(v);
        }
    };
    // Equalities: the initial state, the dynamics and the outputs.
    if !real.free_initial_state {
        for j in 0..n {
            push(row, lay.x(0, j), 1.0, &mut ri, &mut ci);
            rhs.push(0.0);
            row += 1;
        }
    }
    for k in 0..len.saturating_sub(1) {
        for j in 0..n {
            push(row, lay.x(k + 1, j), 1.0, &mut ri, &mut ci);
            for l in 0..n {
                push(row, lay.x(k, l), -a[(j, l)], &mut ri, &mut ci);
            }
            for q in 0..ne {
                push(row, lay.e(k, q), -b[(j, q)], &mut ri, &mut ci);
            }
            for (i, p) in penalties.iter().enumerate() {
                let col = lay.v0[i] + p.node_of_sample()[k];
                push(row, col, -b[(j, w_cols[i])], &mut ri, &mut ci);
            }
            rhs.push(0.0);
            row += 1;
        }
    }
    let mut skip = vec![false; len * ny];
    for &(k, ch) in &dropped {
        skip[k * ny + ch] = true;
    }
    let r = problem.residual().as_slice();
    for k in 0..len {
        for ch in 0..ny {
            if skip[k * ny + ch] {
                continue;
            }
            for l in 0..n {
                push(row, lay.x(k, l), c[(ch, l)], &mut ri, &mut ci);
            }
            for q in 0..ne {
                push(row, lay.e(k, q), d[(ch, q)], &mut ri, &mut ci);
            }
            for (i, p) in penalties.iter().enumerate() {
                let col = lay.v0[i] + p.node_of_sample()[k];
                push(row, col, d[(ch, w_cols[i])], &mut ri, &mut ci);
            }
            rhs.push(r[k * ny + ch]);
            row += 1;
        }
    }
    let equalities = row;
    // −t ≤ v_a − v_b ≤ t as two rows of A·x ≤ b.
    for (i, p) in penalties.iter().enumerate() {
        for (j, &(va, vb, _)) in p.edges().iter().enumerate() {
            let (ca, cb, ct) = (lay.v0[i] + va, lay.v0[i] + vb, lay.t0[i] + j);
            for sign in [1.0, -1.0] {
                push(row, ca, sign, &mut ri, &mut ci);
                push(row, cb, -sign, &mut ri, &mut ci);
                push(row, ct, -1.0, &mut ri, &mut ci);
                rhs.push(0.0);
                row += 1;
            }
        }
    }
    let rows = row;
    let a_mat = CscMatrix::new_from_triplets(rows, lay.total, ri, ci, vals);
    let e_idx: Vec<usize> = (lay.e0..lay.e0 + len * ne).collect();
    let p_mat = CscMatrix::new_from_triplets(
        lay.total,
        lay.total,
        e_idx.clone(),
        e_idx,
        vec![2.0 / len as f64; len * ne],
    );
    let mut q = vec![0.0; lay.total];
    for (i, p) in penalties.iter().enumerate() {
        for (j, &(_, _, w)) in p.edges().iter().enumerate() {
            q[lay.t0[i] + j] = beta * w;
        }
    }
    let mut cones = vec![SupportedConeT::ZeroConeT(equalities)];
    if rows > equalities {
        cones.push(SupportedConeT::NonnegativeConeT(rows - equalities));
    }
    let cl_settings = DefaultSettings {
        verbose: false,
        max_iter: conic.max_iterations(),
        time_limit: conic.time_limit().unwrap_or(f64::INFINITY),
        tol_gap_abs: conic.tolerance(),
        tol_gap_rel: conic.tolerance(),
        tol_feas: conic.tolerance(),
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(&p_mat, &q, &a_mat, &rhs, &cones, cl_settings)
        .map_err(|e| Error::Numerical(format!("clarabel rejected the problem data: {e:?}")))?;
    let t_assembled = Instant::now();
    solver.solve();
    let t_factored = Instant::now();
    let sol = &solver.solution;
    let iterations = sol.iterations as usize;
    let mut warnings = Vec::new();
    match sol.status {
        SolverStatus::Solved => {}
        SolverStatus::AlmostSolved => warnings.push(format!(
            "clarabel reached only reduced accuracy (primal residual {:.2e}, dual residual {:.2e})",
            sol.r_prim, sol.r_dual
        )),
        SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
            return Err(Error::Infeasible {
                solver: NAME.into(),
                detail: "no noise sequence e and map values w reproduce the data. Samples with equal z must share \
                         one w; without a noise path (or with fewer noise channels than outputs) the data may \
                         demand different values there. Check the model's noise path T_ye and the data"
                    .into(),
            });
        }
        status => {
            return Err(Error::NotConverged {
                solver: NAME.into(),
                iterations,
                detail: format!(
                    "status {status:?} (primal residual {:.2e}, dual residual {:.2e}, gap {:.2e}); raise the \
                     iteration or time limit, rescale y and u to order one, or use the admm solver",
                    sol.r_prim,
                    sol.r_dual,
                    (sol.obj_val - sol.obj_val_dual).abs()
                ),
            });
        }
    }
    let x = &sol.x;
    let node_values: Vec<Vec<f64>> = penalties
        .iter()
        .enumerate()
        .map(|(i, p)| x[lay.v0[i]..lay.v0[i] + p.nodes()].to_vec())
        .collect();
    let e_hat = x[lay.e0..lay.e0 + len * ne].to_vec();
    let x0: Option<Vec<f64>> = real
        .free_initial_state
        .then(|| (0..n).map(|j| x[lay.x(0, j)]).collect());
    let out = finish_tv(
        problem,
        &penalties,
        node_values,
        e_hat,
        x0.as_deref(),
        &dropped,
        beta,
    )?;
    warnings.extend(out.warnings);
    let t_end = Instant::now();
    let nnz = a_mat.nnz() + p_mat.nnz();
    Ok(Identification {
        w_hat: out.assembled.w_hat,
        e_hat: out.e_hat,
        blocks: out.assembled.blocks,
        cost: out.cost,
        z_source: problem.z_source().clone(),
        initial_state: x0,
        diagnostics: Diagnostics {
            solver: NAME.into(),
            system_size: lay.total + rows,
            dropped_samples: out.dropped,
            dropped_max_abs_residual: out.dropped_max,
            condition_lower_bound: f64::NAN,
            feasibility_residual: out.feasibility,
            // The KKT matrix and its LDLᵀ factor: a rough guide (fill-in is problem dependent).
            peak_memory_bytes: (nnz as u64) * 16 * 4,
            timings: Timings::from_instants(t_start, t_prepared, t_assembled, t_factored, t_end),
            iterations,
            primal_residual: Some(sol.r_prim),
            dual_residual: Some(sol.r_dual),
            warnings,
            ..Diagnostics::default()
        },
    })
}

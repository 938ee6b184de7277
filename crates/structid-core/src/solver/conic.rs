//! The exact solver for total-variation dispersions, and for models that mix them with quadratic
//! ones: a conic (linear–quadratic) program solved by the interior-point solver Clarabel.
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
//! A quadratic block (any kernel) enters with its sample values w and dual coefficients α:
//! the rows w = K·α and the term β·αᵀKα (P = 2β·K on α), which is wᵀK⁻¹w without K⁻¹. These are
//! dense (L² entries), so mixed models are for records up to a few thousand samples (longer ones
//! go to [`super::admm`]); the memory is estimated first and a problem that would not fit is
//! refused. A purely quadratic model
//! solved this way equals the exact solver's estimate (tested), which cross-checks both.
//!
//! The interior-point method's sparse LDLᵀ factorisation couples the time chain (the dynamics)
//! with the z-sorted chain (the edges); with a white-noise input the z order is a random
//! permutation of time and fill-in grows super-linearly (see `BENCHMARKS.md`). Long records use
//! [`super::admm`] instead; [`crate::identify()`] chooses by size.

use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

use crate::dispersion::total_variation::TvPenalty;
use crate::dispersion::{Penalty, QuadraticPenalty};
use crate::error::{Error, Result};
use crate::identify::problem::Problem;
use crate::identify::result::{Diagnostics, Identification, Timings};
use crate::identify::settings::IdentifySettings;
use crate::solver::choice::{SolveStatus, SolverKind, unconverged_warning};
use crate::solver::realisation::{joint_realisation, unreachable_samples_of_records};
use crate::solver::{BlockPart, finish_tv, penalties, tv_part};

pub use crate::solver::settings::{ConicSettings, ConicSettingsBuilder};

/// The solver's name in reports.
pub const NAME: &str = crate::solver::settings::CONIC_NAME;

/// Column layout of the conic program's variables.
struct Layout {
    n: usize,
    ne: usize,
    e0: usize,
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

/// A block's unknowns in the conic program.
enum BlockVars {
    /// Node values v (G of them) from column `v0` and one epigraph t per edge from `t0`.
    Tv {
        pen: TvPenalty,
        v0: usize,
        t0: usize,
    },
    /// Sample values w (L) from column `w0` and dual coefficients α (L) from `a0`, with w = K·α
    /// and D = αᵀKα = wᵀK⁻¹w without K⁻¹. Dense in L: for small records only.
    Quadratic {
        pen: Box<dyn QuadraticPenalty>,
        w0: usize,
        a0: usize,
    },
}

impl BlockVars {
    /// The column of w at sample k.
    fn column(&self, k: usize) -> usize {
        match self {
            BlockVars::Tv { pen, v0, .. } => v0 + pen.node_of_sample()[k],
            BlockVars::Quadratic { w0, .. } => w0 + k,
        }
    }
}

/// Estimated memory of the conic program with `quadratic` dense blocks over `len` samples:
/// their L² entries in A and P and in the KKT factor, with working copies.
pub fn quadratic_memory_bytes(len: usize, quadratic: usize) -> u64 {
    let l2 = (len as u64) * (len as u64);
    // A: L² (w = Kα rows), P: L²/2, CSC indices and values, triplets, and the factor (≥ L²).
    quadratic as u64 * l2 * (12 + 12 + 8 + 24 + 16)
}

/// Solves the problem as a conic program; see the module docs. Total-variation blocks are
/// sparse; quadratic blocks (any kernel) are dense in L, so a model that mixes a Gaussian block
/// with a total-variation block can be solved for records up to a few thousand samples.
pub fn solve(problem: &Problem, settings: &IdentifySettings) -> Result<Identification> {
    let t_start = Instant::now();
    let penalties = penalties(problem)?;
    solve_with(problem, settings, penalties, t_start)
}

/// [`solve`] with the blocks' penalties already built.
pub(crate) fn solve_with(
    problem: &Problem,
    settings: &IdentifySettings,
    penalties: Vec<Penalty>,
    t_start: Instant,
) -> Result<Identification> {
    let beta = settings.beta();
    let conic = settings.conic();
    let real = joint_realisation(problem, NAME)?;
    let (len, ny) = (problem.len(), problem.outputs());
    let ss = &real.ss;
    let (n, ne) = (ss.order(), real.noise_inputs);
    let (a, b, c, d) = (ss.a(), ss.b(), ss.c(), ss.d());
    // Each record starts from its own state: the dynamics do not link the last sample of a
    // record to the first of the next.
    let bounds = problem.record_bounds();
    let starts = &bounds[..bounds.len() - 1];
    let dropped = unreachable_samples_of_records(&real, bounds);
    let quadratic = penalties
        .iter()
        .filter(|p| matches!(p, Penalty::Quadratic(_)))
        .count();
    if quadratic > 0 {
        let need = quadratic_memory_bytes(len, quadratic);
        let limit = settings.effective_memory_limit();
        if need > limit {
            return Err(Error::TooLarge {
                solver: NAME.into(),
                needed_mib: need >> 20,
                limit_mib: limit >> 20,
                size: len * ny,
                suggestion: format!(
                    "the conic program is dense in the {quadratic} quadratic block(s); use the admm solver \
                     (linear in L) for a model that mixes quadratic and total-variation blocks, or the exact \
                     or feature solver when every block is quadratic"
                ),
            });
        }
    }
    let t_prepared = Instant::now();

    // Block i drives input column ne + output_i of the realisation.
    let blocks = problem.blocks();
    let mut next = len * (n + ne);
    let mut vars = Vec::with_capacity(blocks.len());
    for (bl, pen) in blocks.iter().zip(penalties) {
        match pen {
            Penalty::TotalVariation(p) => {
                if p.len() != len {
                    return Err(Error::DimensionMismatch {
                        what: format!(
                            "samples of the total-variation penalty of block `{}`",
                            bl.name
                        ),
                        expected: len.to_string(),
                        found: p.len().to_string(),
                    });
                }
                let (v0, t0) = (next, next + p.nodes());
                next = t0 + p.edges().len();
                vars.push(BlockVars::Tv { pen: p, v0, t0 });
            }
            Penalty::Quadratic(q) => {
                if q.len() != len {
                    return Err(Error::DimensionMismatch {
                        what: format!("Gram matrix of block `{}`", bl.name),
                        expected: len.to_string(),
                        found: q.len().to_string(),
                    });
                }
                let (w0, a0) = (next, next + len);
                next = a0 + len;
                vars.push(BlockVars::Quadratic { pen: q, w0, a0 });
            }
        }
    }
    let lay = Layout {
        n,
        ne,
        e0: len * n,
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
    // Equalities: the initial state, the dynamics, the outputs and w = K·α.
    let mut record_start = vec![false; len];
    for &s in starts {
        record_start[s] = true;
        if !real.free_initial_state {
            for j in 0..n {
                push(row, lay.x(s, j), 1.0, &mut ri, &mut ci);
                rhs.push(0.0);
                row += 1;
            }
        }
    }
    for k in 0..len.saturating_sub(1) {
        if record_start[k + 1] {
            continue;
        }
        for j in 0..n {
            push(row, lay.x(k + 1, j), 1.0, &mut ri, &mut ci);
            for l in 0..n {
                push(row, lay.x(k, l), -a[(j, l)], &mut ri, &mut ci);
            }
            for q in 0..ne {
                push(row, lay.e(k, q), -b[(j, q)], &mut ri, &mut ci);
            }
            for (i, v) in vars.iter().enumerate() {
                push(row, v.column(k), -b[(j, w_cols[i])], &mut ri, &mut ci);
            }
            rhs.push(0.0);
            row += 1;
        }
    }
    let mut skip = problem
        .held_out()
        .map_or_else(|| vec![false; len * ny], <[bool]>::to_vec);
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
            for (i, v) in vars.iter().enumerate() {
                push(row, v.column(k), d[(ch, w_cols[i])], &mut ri, &mut ci);
            }
            rhs.push(r[k * ny + ch]);
            row += 1;
        }
    }
    // P: (2/L)·I on e and 2β·K on each quadratic block's α (upper triangle).
    let (mut pi, mut pj, mut pv) = (Vec::new(), Vec::new(), Vec::new());
    for idx in lay.e0..lay.e0 + len * ne {
        pi.push(idx);
        pj.push(idx);
        pv.push(2.0 / len as f64);
    }
    let mut gram = faer::Mat::<f64>::zeros(0, 0);
    for v in &vars {
        if let BlockVars::Quadratic { pen, w0, a0 } = v {
            gram.resize_with(len, len, |_, _| 0.0);
            pen.fill(gram.as_mut());
            for k in 0..len {
                push(row, w0 + k, 1.0, &mut ri, &mut ci);
                for l in 0..len {
                    push(row, a0 + l, -gram[(k, l)], &mut ri, &mut ci);
                }
                rhs.push(0.0);
                row += 1;
                for l in k..len {
                    let g = gram[(k, l)];
                    if g != 0.0 {
                        pi.push(a0 + k);
                        pj.push(a0 + l);
                        pv.push(2.0 * beta * g);
                    }
                }
            }
        }
    }
    drop(gram);
    let equalities = row;
    // −t ≤ v_a − v_b ≤ t as two rows of A·x ≤ b.
    let mut q = vec![0.0; lay.total];
    for v in &vars {
        if let BlockVars::Tv { pen, v0, t0 } = v {
            for (j, &(va, vb, w)) in pen.edges().iter().enumerate() {
                let (ca, cb, ct) = (v0 + va, v0 + vb, t0 + j);
                q[ct] = beta * w;
                for sign in [1.0, -1.0] {
                    push(row, ca, sign, &mut ri, &mut ci);
                    push(row, cb, -sign, &mut ri, &mut ci);
                    push(row, ct, -1.0, &mut ri, &mut ci);
                    rhs.push(0.0);
                    row += 1;
                }
            }
        }
    }
    let rows = row;
    let a_mat = CscMatrix::new_from_triplets(rows, lay.total, ri, ci, vals);
    let p_mat = CscMatrix::new_from_triplets(lay.total, lay.total, pi, pj, pv);
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
    let mut solver = DefaultSolver::new(&p_mat, &q, &a_mat, &rhs, &cones, cl_settings)?;
    let t_assembled = Instant::now();
    solver.solve();
    let t_factored = Instant::now();
    let sol = &solver.solution;
    let iterations = sol.iterations as usize;
    let mut warnings = Vec::new();
    // ADMM takes the same models (quadratic blocks through their features or a factor of their
    // Gram matrix) and is linear in L.
    let elsewhere = if quadratic == 0 {
        "or use the admm solver"
    } else {
        "or use the admm solver, which handles the quadratic blocks through their features or a \
         factor of their Gram matrix and is linear in L (the quadratic blocks make this program \
         dense in L)"
    };
    let unconverged_detail = |status: SolverStatus| {
        format!(
            "status {status:?} (primal residual {:.2e}, dual residual {:.2e}, gap {:.2e}); raise the \
             iteration or time limit, rescale y and u to order one, {elsewhere}",
            sol.r_prim,
            sol.r_dual,
            (sol.obj_val - sol.obj_val_dual).abs()
        )
    };
    let (status, status_detail) = match sol.status {
        SolverStatus::Solved => (SolveStatus::Solved, None),
        SolverStatus::AlmostSolved => {
            warnings.push(format!(
                "clarabel reached only reduced accuracy (primal residual {:.2e}, dual residual {:.2e})",
                sol.r_prim, sol.r_dual
            ));
            (SolveStatus::AlmostSolved, None)
        }
        // At a limit the last interior-point iterate is kept; its feasibility residual is in
        // the diagnostics.
        SolverStatus::MaxIterations | SolverStatus::MaxTime => {
            let status = if sol.status == SolverStatus::MaxTime {
                SolveStatus::TimeLimit
            } else {
                SolveStatus::MaxIterations
            };
            let detail = unconverged_detail(sol.status);
            warnings.push(unconverged_warning(
                SolverKind::Clarabel,
                iterations,
                &detail,
                status,
            ));
            (status, Some(detail))
        }
        SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
            return Err(Error::Infeasible {
                solver: NAME.into(),
                detail: "no noise sequence e and map values w reproduce the data. Samples with equal z must share \
                         one w; without a noise path (or with fewer noise channels than outputs) the data may \
                         demand different values there. Check the model's noise path T_ye and the data"
                    .into(),
            });
        }
        // Numerical trouble or no progress: a finite iterate is kept, marked as such, for the
        // caller to judge (the CLI writes it and exits 1); a non-finite one is worth nothing.
        status if sol.x.iter().all(|v| v.is_finite()) => {
            let detail = unconverged_detail(status);
            warnings.push(unconverged_warning(
                SolverKind::Clarabel,
                iterations,
                &detail,
                SolveStatus::NumericalFailure,
            ));
            (SolveStatus::NumericalFailure, Some(detail))
        }
        status => {
            return Err(Error::NotConverged {
                solver: NAME.into(),
                iterations,
                detail: unconverged_detail(status),
            });
        }
    };
    let x = &sol.x;
    let parts: Vec<BlockPart> = vars
        .iter()
        .map(|v| match v {
            BlockVars::Tv { pen, v0, .. } => tv_part(pen, x[*v0..v0 + pen.nodes()].to_vec()),
            BlockVars::Quadratic { pen, w0, a0 } => {
                let w_hat = x[*w0..w0 + len].to_vec();
                let alpha = x[*a0..a0 + len].to_vec();
                // D = αᵀKα = αᵀw at the constraint w = Kα.
                let value = alpha.iter().zip(&w_hat).map(|(a, w)| a * w).sum();
                BlockPart {
                    w_hat,
                    dispersion_value: value,
                    map: pen.interpolant(alpha),
                }
            }
        })
        .collect();
    let e_hat = x[lay.e0..lay.e0 + len * ne].to_vec();
    let x0: Option<Vec<f64>> = real.free_initial_state.then(|| {
        let lay = &lay;
        starts
            .iter()
            .flat_map(|&s| (0..n).map(move |j| x[lay.x(s, j)]))
            .collect()
    });
    let mut out = finish_tv(problem, parts, e_hat, x0.as_deref(), &dropped, beta)?;
    warnings.extend(std::mem::take(&mut out.warnings));
    let t_end = Instant::now();
    let nnz = a_mat.nnz() + p_mat.nnz();
    let diagnostics = Diagnostics {
        solver: SolverKind::Clarabel,
        status,
        status_detail,
        system_size: lay.total + rows,
        // The KKT matrix and its LDLᵀ factor: a rough guide (fill-in is problem dependent).
        peak_memory_bytes: (nnz as u64) * 16 * 4,
        timings: Timings::from_instants(t_start, t_prepared, t_assembled, t_factored, t_end),
        iterations,
        primal_residual: Some(sol.r_prim),
        dual_residual: Some(sol.r_dual),
        warnings,
        ..Diagnostics::default()
    };
    Ok(out.into_identification(problem, x0, diagnostics))
}

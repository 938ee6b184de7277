//! ADMM for total-variation dispersions, alone or mixed with quadratic ones: every iteration is
//! linear in L.
//!
//! Quadratic blocks (a Gaussian spring next to a total-variation friction, say) are not split:
//! each is w_q = Ψ̃·η with D = ‖η‖² (its features, or a pivoted Cholesky factor of its Gram
//! matrix to rounding; see `quadratic_factor`), and the w-step minimises over η exactly, in
//! closed form, together with the total-variation blocks' offsets (see `WStep`). The iteration
//! is then the one of a model with total-variation blocks only, whose w-step carries the
//! quadratic blocks: O(L·(n² + k)) per iteration for factors of rank k, plus k smoother passes
//! whenever ρ changes.
//!
//! Split the per-sample map values w from node values d that carry the penalty
//! (w_k^\[i\] = d_i,node(k), up to the offsets below) and alternate, in scaled form with penalty ρ:
//!
//! ```text
//! w ← argmin_(e,w) (1/L)·Σ|e_k|² + (ρ/2)·‖w − (d − u)‖²  s.t. T_ye·e + T_yw·w = r
//! d ← argmin_d β·Σ_i TV_i(d_i) + (ρ/2)·‖ŵ + u − d‖²       (ŵ = α·w + (1−α)·d, over-relaxation)
//! u ← u + ŵ − d
//! ```
//!
//! * The first step is the posterior mean of (e, w) in the linear-Gaussian model
//!   e_k ~ N(0, (L/2)·I), w_k ~ N(d_k − u_k, ρ⁻¹·I) with the data constraints exact: one pass
//!   of the Kalman disturbance smoother ([`structid_lti::DisturbanceSmoother`]) over the LFT's
//!   states, O(L·n²). Its gains do not depend on the data and are computed once per ρ.
//!   Total variation does not see constants, so each block also carries a free offset c_i
//!   (its map is d_i + c_i on the nodes) that the first step optimises exactly, in closed
//!   form from n_b precomputed smoother responses (see `WStep`). Without it, a constant
//!   combination the data see only weakly, such as (f + c, g − c) when two blocks read the
//!   same z into one output (the spray example: seen only through the first two samples from
//!   rest), converges at a rate ~ 1/L per iteration: 20 000 iterations were not enough at
//!   L = 2000 there, against 60 with the offsets.
//! * The second step is the exact proximal operator of the total variation. Samples that share
//!   a node enter through their mean with weight = their count. On a chain (scalar z) it is the
//!   O(G) dynamic programme [`crate::solver::prox::tv1d`]; on a k-NN graph (p > 1) a warm-started dual
//!   FISTA ([`crate::solver::prox::GraphTv`]) run to a duality gap below a tenth of the outer tolerance.
//!
//! Held-out samples (a cross-validation fold: every output channel of the sample left out)
//! are missing outputs of the smoother ([`DisturbanceSmoother::with_missing`]), so the same
//! iteration fits the remaining outputs. Map values that no kept output sees (samples held out
//! at the end of the record) are set by the total variation alone and are not unique; chains
//! leave those nodes out of the iteration and fill them exactly afterwards (see `TvView`).
//!
//! Several records ([`crate::Data::from_records`]) are independent in time: each record's
//! smoother starts from that record's own initial state (zero, or free with one x₀ per record,
//! returned one record after the other) and ends with it, so the w-step is the posterior mean
//! under the block-diagonal operators (see `RecordSmoother`; the records are smoothed in
//! parallel). Samples no input reaches are found per record, and so are the samples held out
//! at the end of a record, and, with several records, the last samples of every record, whose
//! map values reach no output before the next record restarts (left out of chains and filled
//! as held-out ones are). The d-step, the offsets and the quadratic blocks' coefficients
//! couple the records only through the shared maps. One record runs the smoother on the whole
//! signals, as before.
//!
//! Stopping follows Boyd et al. (2011, §3.3): primal residual ‖w − d‖ ≤ √N·ε_pri + ε_rel·max(‖w‖, ‖d‖)
//! and dual residual ρ·‖d − d_prev‖ ≤ √N·ε_dual + ε_rel·ρ·‖u‖, with ε_rel = tolerance and the
//! absolute parts in each residual's own units, so that the test is unit-free: ε_pri =
//! tolerance × RMS(r)/g in w's units and ε_dual = tolerance × (2/L)·g·RMS(r) in the units of a
//! gradient of (1/L)·Σ|e_k|², with g = (L·q_max/2)^½ the largest gain |G/H| (q_max below). One
//! absolute ε for both, in w's units from a gain-ratio ρ, let ADMM stop 30 % (at ρ = 10·ρ*:
//! 100×) above the optimal J on a nearly integrating plant.
//!
//! The initial penalty is ρ₀ = √(λ_lo·λ_max) of the w-step's curvature, read off the frequency
//! responses: per frequency the curvature is (2/L)·eig(Φ), Φ = Gᴴ(H·Hᴴ)⁻¹G, with G the map
//! paths and H the noise path, and q_max = (2/L)·max λ_max. With λ_lo = λ_min this is
//! Giselsson and Boyd's optimal ρ for a strongly convex quadratic plus any convex term (IEEE
//! TAC 2017), with which the iteration count does not grow with L (14 iterations from
//! L = 2000 to 30 000 on the benchmark problem). λ_lo is floored at 10⁻⁴·λ_max: a sampled
//! plant of relative degree two has a zero near z = −1 where Φ nearly vanishes, and a pole
//! near 1 makes λ_max large, so that √(λ_min·λ_max) was ~10⁻⁶ on rate-feedback hypotheses of
//! a nearly integrating plant, and ADMM ran into its 20 000-iteration limit (the frequencies
//! where Φ is tiny are set by the total variation, not the data). Frequencies where zI − A or
//! H·Hᴴ is singular (an exact integrator at ω = 0) are skipped. When Φ is singular at every
//! frequency (two blocks driving one output) its null space is left to the total variation,
//! and ρ₀ comes from the range of the blocks' own curvatures Φ_ii instead (the spray example:
//! 60 iterations at L = 2000). Only when no frequency can be used is the H₂-gain ratio taken.
//!
//! ρ is then balanced against the residuals (each relative to its tolerance; ρ·√(r_pri/r_dual)
//! every 10 iterations when that moves ρ more than 5-fold, during the first 2000 iterations),
//! within [10⁻⁶, 10]·q_max: the best ρ grows with β (where the total variation makes the map
//! flat it is above q_max, at small β orders below ρ₀), and the bounds, relative to the
//! problem's own curvature, keep ρ from running away in either direction. The returned ŵ is
//! d + c (tied samples share their value exactly) and ê is the least-squares noise that
//! explains r − T_yw·ŵ; the diagnostics report the
//! iterations and both residuals. At the iteration limit the last iterate is returned with
//! [`crate::SolveStatus::MaxIterations`] and a status detail that says in words which residual
//! was above its tolerance, by how much, and where ρ stood: never a silent result.

use std::time::Instant;

use rayon::prelude::*;

use structid_lti::{DisturbanceSmoother, Signal, SmootherInitial, StateSpace};

use crate::dispersion::total_variation::TvPenalty;
use crate::dispersion::{Penalty, QuadraticPenalty};
use crate::error::{Error, Result};
use crate::identify::problem::Problem;
use crate::identify::result::{Diagnostics, Identification, Timings};
use crate::identify::settings::IdentifySettings;
use crate::solver::choice::{SolveStatus, SolverKind, unconverged_warning};
use crate::solver::prox::{GraphTv, Tv1dWorkspace};
use crate::solver::quadratic_factor::QuadraticFactor;
use crate::solver::realisation::{Realisation, joint_realisation, unreachable_samples_of_records};
use crate::solver::{BlockPart, finish_tv, tv_parts};

/// The solver's name in reports.
pub const NAME: &str = crate::solver::settings::ADMM_NAME;

pub use crate::solver::settings::{AdmmSettings, AdmmSettingsBuilder};

/// Iterations during which ρ may be rebalanced (after that it is frozen so that the standard
/// convergence theory applies).
const ADAPT_ITERATIONS: usize = 2000;
/// Balancing looks at the residuals every this many iterations (each change of ρ costs a new
/// smoother, about n_b + 2 iterations' worth).
const ADAPT_EVERY: usize = 10;
/// Balancing changes ρ only when the balanced value differs by more than this factor.
const ADAPT_FACTOR: f64 = 5.0;

/// The proximal step of one block.
enum Prox {
    /// Workspace, edge weights c, and λ = c·β/ρ for the β/ρ it was built at (rebuilt when ρ
    /// changes).
    Chain(Tv1dWorkspace, Vec<f64>, Vec<f64>, f64),
    Graph(Box<GraphTv>),
}

/// Solves a problem with at least one total-variation block (the others may be quadratic);
/// see the module docs.
pub fn solve(problem: &Problem, settings: &IdentifySettings) -> Result<Identification> {
    let t_start = Instant::now();
    let penalties = crate::solver::penalties(problem)?;
    solve_with(problem, settings, penalties, t_start)
}

/// A block of the problem as ADMM sees it: the index into its total-variation or quadratic
/// list.
#[derive(Clone, Copy)]
enum Slot {
    Tv(usize),
    Quadratic(usize),
}

/// [`solve`] with the blocks' penalties already built.
pub(crate) fn solve_with(
    problem: &Problem,
    settings: &IdentifySettings,
    all_penalties: Vec<Penalty>,
    t_start: Instant,
) -> Result<Identification> {
    // Held-out samples (cross-validation) are missing outputs of the smoother.
    let missing = match problem.held_out_samples() {
        Some(m) => Some(m.ok_or_else(|| {
            Error::Unsupported(
                "ADMM leaves out whole samples (every output channel of a sample); this problem holds out \
                 only some channels of a sample: use the conic solver (clarabel)"
                    .into(),
            )
        })?),
        None => None,
    };
    let mut penalties: Vec<TvPenalty> = Vec::new();
    let mut quadratic: Vec<(Box<dyn QuadraticPenalty>, usize)> = Vec::new();
    let mut slots = Vec::with_capacity(all_penalties.len());
    for (bi, (b, pen)) in problem.blocks().iter().zip(all_penalties).enumerate() {
        match pen {
            Penalty::TotalVariation(p) if p.len() == problem.len() => {
                slots.push(Slot::Tv(penalties.len()));
                penalties.push(p);
            }
            Penalty::TotalVariation(p) => {
                return Err(Error::DimensionMismatch {
                    what: format!(
                        "samples of the total-variation penalty of block `{}`",
                        b.name
                    ),
                    expected: problem.len().to_string(),
                    found: p.len().to_string(),
                });
            }
            Penalty::Quadratic(q) if q.len() == problem.len() => {
                slots.push(Slot::Quadratic(quadratic.len()));
                quadratic.push((q, bi));
            }
            Penalty::Quadratic(q) => {
                return Err(Error::DimensionMismatch {
                    what: format!("Gram matrix of block `{}`", b.name),
                    expected: problem.len().to_string(),
                    found: q.len().to_string(),
                });
            }
        }
    }
    if penalties.is_empty() {
        return Err(Error::Unsupported(
            "the admm solver splits total-variation blocks from the data fit, and this model has none; \
             a model with quadratic dispersions only is solved by the exact, feature or clarabel solver (or solver = auto)"
                .into(),
        ));
    }
    let beta = settings.beta();
    let opts = settings.admm();
    let real = joint_realisation(problem, NAME)?;
    // Each record starts from its own state (zero or free): the smoothers restart there.
    let bounds = problem.record_bounds();
    let dropped = unreachable_samples_of_records(&real, bounds);
    let (len, ny) = (problem.len(), problem.outputs());
    let ne = real.noise_inputs;
    let nin = real.ss.inputs();
    // Realisation channels of the total-variation blocks (w_cols) and the quadratic ones.
    let mut w_cols = Vec::with_capacity(penalties.len());
    let mut q_cols = Vec::with_capacity(quadratic.len());
    for (b, slot) in problem.blocks().iter().zip(&slots) {
        match slot {
            Slot::Tv(_) => w_cols.push(ne + b.output),
            Slot::Quadratic(_) => q_cols.push(ne + b.output),
        }
    }
    let nb = penalties.len();
    let factors = quadratic_factors(problem, &quadratic, nb, settings)?;
    let initial = if real.free_initial_state {
        SmootherInitial::Free
    } else {
        SmootherInitial::Zero
    };
    let r = problem.residual();
    let r_rms = (r.as_slice().iter().map(|v| v * v).sum::<f64>() / (len * ny).max(1) as f64)
        .sqrt()
        .max(1e-300);
    let eps_rel = opts.tolerance();
    let scale = default_rho(&real, &w_cols, len);
    let rho0 = scale.rho0;
    // Tolerances in the units of each residual, so that the test reads the same in any units
    // of r and w: the primal residual w − d is in w's units, r/g with g = (L·q_max/2)^½ the
    // largest gain |G/H|, so that a w within it moves the fit by at most tolerance × RMS(r);
    // the dual residual ρ·(d − d_prev) is a gradient of (1/L)·Σ|e_k|², in units of
    // (2/L)·g·r.
    let g_max = (len as f64 * scale.q_max / 2.0).sqrt().max(1e-300);
    let eps_abs_pri = eps_rel * r_rms / g_max;
    let eps_abs_dual = eps_rel * r_rms * g_max * 2.0 / len.max(1) as f64;
    let (rho_lo, rho_hi) = scale.bounds();
    let t_prepared = Instant::now();

    let mut rho = opts.rho().unwrap_or(rho0);
    let adaptive = opts.adaptive();
    let variances = |rho: f64| -> Vec<f64> {
        let mut v = vec![len as f64 / 2.0; nin];
        for &c in &w_cols {
            v[c] = 1.0 / rho;
        }
        for &c in &q_cols {
            v[c] = 0.0;
        }
        v
    };
    let channels = Channels {
        tv: &w_cols,
        quadratic: &q_cols,
        factors: &factors,
        missing: missing.as_deref(),
        bounds,
    };
    let mut wstep = WStep::new(
        &real.ss,
        &variances(rho),
        &channels,
        len,
        initial,
        beta,
        rho,
    )?;
    // The blocks as ADMM iterates them: chains without the nodes that no kept output sees.
    let tv_z: Vec<&Signal> = problem
        .blocks()
        .iter()
        .zip(&slots)
        .filter(|(_, s)| matches!(s, Slot::Tv(_)))
        .map(|(b, _)| &b.z)
        .collect();
    let views: Vec<TvView> = penalties
        .iter()
        .zip(&w_cols)
        .zip(&tv_z)
        .map(|((p, &col), z)| {
            TvView::new(
                p,
                z,
                visible_samples(&real, col, missing.as_deref(), bounds),
            )
        })
        .collect();
    let mut prox: Vec<Prox> = penalties
        .iter()
        .zip(&views)
        .map(|(p, v)| {
            if p.is_chain() {
                Prox::Chain(
                    Tv1dWorkspace::new(),
                    v.weights.clone(),
                    Vec::new(),
                    f64::NAN,
                )
            } else {
                Prox::Graph(Box::new(GraphTv::new(p.nodes(), p.edges().to_vec())))
            }
        })
        .collect();
    let t_assembled = Instant::now();

    // State: d (nodes, per block), u (samples, per block), the smoother's mean and output.
    // The samples' own quantities (u, the w-step's output) are kept in node order: each block's
    // samples sorted by node (`order`, with `sorted_node` the node of each position), so that
    // every pass over the samples reads and writes the node vectors in sequence, and only two
    // passes per block and iteration (the w-step's mean out, its output in) follow time order.
    let orders: Vec<(&[usize], &[usize])> = views
        .iter()
        .map(|v| (&v.order[..], &v.sorted_node[..]))
        .collect();
    let mut d: Vec<Vec<f64>> = views.iter().map(|v| vec![0.0; v.nodes]).collect();
    let mut d_prev = d.clone();
    let mut u: Vec<Vec<f64>> = views.iter().map(|v| vec![0.0; v.order.len()]).collect();
    let mut ws: Vec<f64> = vec![0.0; len];
    let mut mean = Signal::zeros(len, nin);
    let mut vhat = Signal::zeros(len, nin);
    let mut target: Vec<Vec<f64>> = views.iter().map(|v| vec![0.0; v.nodes]).collect();
    let counts: Vec<Vec<f64>> = views.iter().map(|v| v.counts.clone()).collect();
    let alpha = opts.relaxation();
    let sqrt_n = (views.iter().map(|v| v.order.len()).sum::<usize>() as f64).sqrt();
    let mut prox_inner = 0usize;
    let mut prox_unconverged = 0usize;
    let mut rho_changes = 0usize;
    let (mut iterations, mut r_pri, mut r_dual) = (0, f64::INFINITY, f64::INFINITY);
    let (mut eps_pri, mut eps_dual) = (f64::NAN, f64::NAN);
    let mut converged = false;
    let mut params = vec![0.0; wstep.parameters()];
    while iterations < opts.max_iterations() {
        iterations += 1;
        // w-step: smoother with prior mean d − u on the w channels.
        for (i, &(order, sorted_node)) in orders.iter().enumerate() {
            let (m, col) = (mean.as_mut_slice(), w_cols[i]);
            for ((&k, &g), &uj) in order.iter().zip(sorted_node).zip(&u[i]) {
                m[k * nin + col] = d[i][g] - uj;
            }
        }
        wstep.solve(r, &mean, &mut vhat, &mut params, &channels)?;
        // d-step on the relaxed iterate, through node means.
        let (mut w_norm2, mut d_norm2, mut u_norm2, mut pri2, mut dual2) =
            (0.0, 0.0, 0.0, 0.0, 0.0);
        for (i, &(order, sorted_node)) in orders.iter().enumerate() {
            let (v, col) = (vhat.as_slice(), w_cols[i]);
            for (w, &k) in ws.iter_mut().zip(order) {
                *w = v[k * nin + col];
            }
            let (di, ui, ti) = (&d[i], &u[i], &mut target[i]);
            ti.iter_mut().for_each(|t| *t = 0.0);
            for ((&w, &g), &uj) in ws.iter().zip(sorted_node).zip(ui) {
                ti[g] += alpha * w + (1.0 - alpha) * di[g] + uj;
            }
            for (t, c) in ti.iter_mut().zip(&counts[i]) {
                *t /= c;
            }
            std::mem::swap(&mut d[i], &mut d_prev[i]);
            let scale = beta / rho;
            match &mut prox[i] {
                Prox::Chain(ws, weights, lam, at) => {
                    if *at != scale {
                        *lam = weights.iter().map(|c| c * scale).collect();
                        *at = scale;
                    }
                    ws.solve(&target[i], &counts[i], lam, &mut d[i]);
                }
                Prox::Graph(g) => {
                    // The prox is positively homogeneous: solve it on targets scaled to unit
                    // RMS, so that its duality-gap test (relative to 1 + |objective|) is relative.
                    let s = (target[i].iter().map(|t| t * t).sum::<f64>()
                        / target[i].len().max(1) as f64)
                        .sqrt()
                        .max(1e-300);
                    let scaled: Vec<f64> = target[i].iter().map(|t| t / s).collect();
                    let rep = g.solve(
                        &scaled,
                        &counts[i],
                        scale / s,
                        0.1 * eps_rel,
                        100_000,
                        &mut d[i],
                    );
                    d[i].iter_mut().for_each(|v| *v *= s);
                    prox_inner += rep.iterations;
                    prox_unconverged += usize::from(!rep.converged);
                }
            }
            let (di, dp) = (&d[i], &d_prev[i]);
            for ((&w, &g), uj) in ws.iter().zip(sorted_node).zip(u[i].iter_mut()) {
                let (dg, pg) = (di[g], dp[g]);
                let relaxed = alpha * w + (1.0 - alpha) * pg;
                *uj += relaxed - dg;
                w_norm2 += w * w;
                d_norm2 += dg * dg;
                u_norm2 += *uj * *uj;
                pri2 += (w - dg) * (w - dg);
                dual2 += (dg - pg) * (dg - pg);
            }
        }
        r_pri = pri2.sqrt();
        r_dual = rho * dual2.sqrt();
        eps_pri = sqrt_n * eps_abs_pri + eps_rel * w_norm2.sqrt().max(d_norm2.sqrt());
        eps_dual = sqrt_n * eps_abs_dual + eps_rel * rho * u_norm2.sqrt();
        if r_pri <= eps_pri && r_dual <= eps_dual {
            converged = true;
            break;
        }
        if adaptive && iterations <= ADAPT_ITERATIONS && iterations % ADAPT_EVERY == 0 {
            // Residual balancing on the residuals relative to their tolerances (OSQP's rule):
            // ρ·√(r_pri/r_dual), applied when it moves ρ by more than ADAPT_FACTOR, within
            // the bounds.
            let ratio = ((r_pri / eps_pri) / (r_dual / eps_dual).max(1e-300)).sqrt();
            let target = (rho * ratio).clamp(rho_lo, rho_hi);
            if target.is_finite() && (target > ADAPT_FACTOR * rho || target * ADAPT_FACTOR < rho) {
                let factor = target / rho;
                rho = target;
                u.iter_mut().flatten().for_each(|v| *v /= factor);
                wstep = WStep::new(
                    &real.ss,
                    &variances(rho),
                    &channels,
                    len,
                    initial,
                    beta,
                    rho,
                )?;
                rho_changes += 1;
            }
        }
    }
    // The iterate is kept when the limit is reached: ê is recomputed for it below, so the
    // estimate is feasible and its cost is the cost of a valid (if not optimal) point.
    let unconverged = (!converged).then(|| {
        stop_reason(&StopState {
            max_iterations: opts.max_iterations(),
            r_pri,
            eps_pri,
            r_dual,
            eps_dual,
            rho,
            rho0,
            bounds: adaptive.then_some((rho_lo, rho_hi)),
            rho_changes,
            tolerance: eps_rel,
            from_frequency: scale.from_frequency,
        })
    });
    let t_factored = Instant::now();

    // ê: the least-squares noise explaining r − T_yw·ŵ with ŵ = d (w fixed: zero variance).
    let mut fixed = vec![len as f64 / 2.0; nin];
    for &c in w_cols.iter().chain(&q_cols) {
        fixed[c] = 0.0;
    }
    let offsets = &params[..nb];
    // The quadratic blocks' coefficients η and their values Ψ̃·η at the samples.
    let mut etas = Vec::with_capacity(factors.len());
    let mut at = nb;
    for f in &factors {
        etas.push(params[at..at + f.rank].to_vec());
        at += f.rank;
    }
    let q_values: Vec<Vec<f64>> = factors
        .iter()
        .zip(&etas)
        .map(|(f, eta)| f.values(eta))
        .collect();
    // The node values of the whole chains (the nodes left out filled in optimally).
    let mut d: Vec<Vec<f64>> = views.iter().zip(d).map(|(v, d)| v.expand(d)).collect();
    let final_smoother =
        RecordSmoother::new(&real.ss, &fixed, bounds, initial, &[], missing.as_deref())?;
    for k in 0..len {
        let m = mean.sample_mut(k);
        m.iter_mut().for_each(|v| *v = 0.0);
        for (i, p) in penalties.iter().enumerate() {
            m[w_cols[i]] = d[i][p.node_of_sample()[k]] + offsets[i];
        }
        for (j, v) in q_values.iter().enumerate() {
            m[q_cols[j]] = v[k];
        }
    }
    // One initial state per record, in record order (the columns of the free response).
    let x0 = final_smoother.smooth(r, &mean, &mut vhat)?;
    let e_hat: Vec<f64> = (0..len)
        .flat_map(|k| vhat.sample(k)[..ne].to_vec())
        .collect();
    // The maps are the node values plus the blocks' constant offsets.
    for (di, c) in d.iter_mut().zip(offsets) {
        di.iter_mut().for_each(|v| *v += c);
    }
    let mut tv_parts: Vec<Option<BlockPart>> =
        tv_parts(&penalties, d).into_iter().map(Some).collect();
    drop(views);
    let mut q_parts: Vec<Option<BlockPart>> = factors
        .iter()
        .zip(&quadratic)
        .zip(&etas)
        .map(|((f, (pen, _)), eta)| Some(f.part(pen.as_ref(), eta, len)))
        .collect();
    // Each slot indexes its list once, so every part is taken exactly once.
    let parts: Vec<BlockPart> = slots
        .iter()
        .filter_map(|slot| match slot {
            Slot::Tv(j) => tv_parts[*j].take(),
            Slot::Quadratic(j) => q_parts[*j].take(),
        })
        .collect();
    let out = finish_tv(problem, parts, e_hat, x0.as_deref(), &dropped, beta)?;
    let mut warnings = out.warnings;
    let status = if converged {
        SolveStatus::Solved
    } else {
        SolveStatus::MaxIterations
    };
    if let Some(detail) = &unconverged {
        warnings.push(unconverged_warning(
            SolverKind::Admm,
            iterations,
            detail,
            status,
        ));
    }
    if prox_unconverged > 0 {
        warnings.push(format!(
            "{prox_unconverged} graph proximal steps stopped at their iteration limit before their duality-gap \
             test ({prox_inner} inner iterations in total); the estimate may be less accurate than the tolerance"
        ));
    }
    let t_end = Instant::now();
    let rank: usize = factors.iter().map(|f| f.rank).sum();
    let peak = 8
        * (len * (4 * nin + 3 * nb + rank)
            + wstep.smoother.transient_len() * 32
            + len * nb * (nb + rank)) as u64;
    for (f, (_, bi)) in factors.iter().zip(&quadratic) {
        if f.capped {
            warnings.push(format!(
                "the Gram matrix of block `{}` was factored to rank {} only (the limit), with a largest residual \
                 diagonal of {:.1e} relative to K's: the estimate solves an approximation of the problem; give \
                 the block finitely many features or a wider kernel",
                problem.blocks()[*bi].name,
                f.rank,
                f.residual
            ));
        }
    }
    Ok(Identification {
        posterior: None,
        w_hat: out.assembled.w_hat,
        e_hat: out.e_hat,
        blocks: out.assembled.blocks,
        cost: out.cost,
        z_source: problem.z_source().clone(),
        initial_state: x0,
        diagnostics: Diagnostics {
            solver: SolverKind::Admm,
            status,
            status_detail: unconverged,
            system_size: len * nin,
            dropped_samples: out.dropped,
            dropped_max_abs_residual: out.dropped_max,
            condition_lower_bound: f64::NAN,
            feasibility_residual: out.feasibility,
            peak_memory_bytes: peak,
            timings: Timings::from_instants(t_start, t_prepared, t_assembled, t_factored, t_end),
            iterations,
            primal_residual: Some(r_pri),
            dual_residual: Some(r_dual),
            warnings,
            ..Diagnostics::default()
        },
    })
}

/// Where ADMM stood when it reached its iteration limit.
struct StopState {
    max_iterations: usize,
    r_pri: f64,
    eps_pri: f64,
    r_dual: f64,
    eps_dual: f64,
    rho: f64,
    rho0: f64,
    /// The bounds of ρ when it was balanced.
    bounds: Option<(f64, f64)>,
    rho_changes: usize,
    tolerance: f64,
    /// Whether ρ₀ came from the frequency responses.
    from_frequency: bool,
}

/// Why ADMM did not converge, in words: which residual was above its tolerance and by how
/// much, where ρ stood, and what to try.
fn stop_reason(s: &StopState) -> String {
    let over = |r: f64, eps: f64| r / eps.max(f64::MIN_POSITIVE);
    let (p, d) = (over(s.r_pri, s.eps_pri), over(s.r_dual, s.eps_dual));
    let which = match (p > 1.0, d > 1.0) {
        (true, true) => "both residuals were above their tolerances",
        (true, false) => {
            "the primal residual ‖w − d‖ was above its tolerance (w and its copy d still disagree)"
        }
        (false, true) => {
            "the dual residual ρ·‖Δd‖ was above its tolerance (the estimate was still moving)"
        }
        (false, false) => "the residuals were at their tolerances",
    };
    let rho = match s.bounds {
        Some((lo, hi)) => {
            let at = if s.rho <= lo * (1.0 + 1e-12) {
                ", at its lower bound"
            } else if s.rho >= hi * (1.0 - 1e-12) {
                ", at its upper bound"
            } else {
                ""
            };
            format!(
                "ρ = {:.3e}{at} (from ρ₀ = {:.3e}, rebalanced {} times within [{lo:.3e}, {hi:.3e}])",
                s.rho, s.rho0, s.rho_changes
            )
        }
        None => format!("ρ = {:.3e} fixed (balancing off)", s.rho),
    };
    let origin = if s.from_frequency {
        ""
    } else {
        " (ρ₀ from the H₂-gain ratio: no frequency response of the w-step was usable)"
    };
    format!(
        "it stopped at its limit of {} iterations, where {which}: primal residual {:.3e} ({p:.1}× its tolerance \
         {:.3e}), dual residual {:.3e} ({d:.1}× its tolerance {:.3e}); {rho}{origin}; raise max_iterations, \
         loosen the tolerance ({:.1e}), or use the clarabel solver for L up to a few thousand",
        s.max_iterations, s.r_pri, s.eps_pri, s.r_dual, s.eps_dual, s.tolerance
    )
}

/// A total-variation block as ADMM iterates it.
///
/// The samples are sorted by node (a counting sort, stable in time): `order` holds the sample
/// of each sorted position and `sorted_node` its node. When samples are held out at the end of
/// the record (or, with several records, at the end of every record), their w reaches no
/// output that is kept, and a node with only such samples is
/// set by the total variation alone: its value is not unique (any value between its chain
/// neighbours costs the same) and ADMM would creep along it at a sublinear rate. A chain then
/// leaves those nodes out: a run of them between kept nodes a and b becomes one edge of weight
/// min c over the run (the least total variation that joins a to b through it), and after the
/// iteration [`TvView::expand`] fills the run with an exact minimiser: linear in z from a's
/// value to b's when the run's weights are equal (every monotone fill is then optimal, and this
/// one is the map's own piecewise-linear interpolation between a and b), else a's and b's
/// values with the jump at the cheapest edge; runs at an end of the chain take the value of
/// their one neighbour. Graphs (p > 1) keep every node.
struct TvView {
    order: Vec<usize>,
    sorted_node: Vec<usize>,
    /// Nodes iterated.
    nodes: usize,
    /// Samples per node iterated.
    counts: Vec<f64>,
    /// Chain edge weights between consecutive nodes iterated.
    weights: Vec<f64>,
    /// For a reduced chain: the iterated node of each chain node (`None`: left out), the
    /// chain's own weights and the first coordinate of z at each chain node.
    reduced: Option<ReducedChain>,
}

/// See [`TvView::reduced`].
type ReducedChain = (Vec<Option<usize>>, Vec<f64>, Vec<f64>);

impl TvView {
    fn new(p: &TvPenalty, z: &Signal, visible: Option<Vec<bool>>) -> Self {
        let full_weights: Vec<f64> = p.edges().iter().map(|e| e.2).collect();
        let nodes_of = p.node_of_sample();
        let mut seen = vec![false; p.nodes()];
        if let Some(vis) = &visible {
            for (k, &g) in nodes_of.iter().enumerate() {
                seen[g] |= vis[k];
            }
        }
        let reduce = p.is_chain() && visible.is_some() && seen.iter().any(|&s| !s);
        let (map, nodes, weights) = if reduce {
            let mut map = vec![None; p.nodes()];
            let mut weights = Vec::new();
            let mut next = 0usize;
            let mut run_min = f64::INFINITY;
            for g in 0..p.nodes() {
                if seen[g] {
                    if next > 0 {
                        weights.push(run_min);
                    }
                    map[g] = Some(next);
                    next += 1;
                    run_min = f64::INFINITY;
                }
                if g + 1 < p.nodes() {
                    run_min = run_min.min(full_weights[g]);
                }
            }
            (Some(map), next, weights)
        } else {
            (None, p.nodes(), full_weights.clone())
        };
        let node = |k: usize| match &map {
            Some(m) => m[nodes_of[k]],
            None => Some(nodes_of[k]),
        };
        let mut start = vec![0usize; nodes + 1];
        for k in 0..nodes_of.len() {
            if let Some(g) = node(k) {
                start[g + 1] += 1;
            }
        }
        let counts: Vec<f64> = start[1..].iter().map(|&c| c as f64).collect();
        for g in 0..nodes {
            start[g + 1] += start[g];
        }
        let mut order = vec![0usize; start[nodes]];
        let mut sorted_node = vec![0usize; start[nodes]];
        for k in 0..nodes_of.len() {
            if let Some(g) = node(k) {
                order[start[g]] = k;
                sorted_node[start[g]] = g;
                start[g] += 1;
            }
        }
        Self {
            order,
            sorted_node,
            nodes,
            counts,
            weights,
            reduced: map.map(|m| {
                let mut knots = vec![0.0; p.nodes()];
                for (k, &g) in nodes_of.iter().enumerate() {
                    knots[g] = z.sample(k).first().copied().unwrap_or(0.0);
                }
                (m, full_weights, knots)
            }),
        }
    }

    /// The values of every chain node from those iterated (see the type's documentation).
    fn expand(&self, d: Vec<f64>) -> Vec<f64> {
        let Some((map, weights, knots)) = &self.reduced else {
            return d;
        };
        let full = map.len();
        let mut out = vec![0.0; full];
        let kept: Vec<usize> = (0..full).filter(|&g| map[g].is_some()).collect();
        let value = |g: usize| map[g].map_or(0.0, |r| d[r]);
        let (Some(&first), Some(&last)) = (kept.first(), kept.last()) else {
            return out;
        };
        for g in 0..=first {
            out[g] = value(first);
        }
        for g in last..full {
            out[g] = value(last);
        }
        for pair in kept.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let (va, vb) = (value(a), value(b));
            let (lo, hi) = weights[a..b]
                .iter()
                .fold((f64::INFINITY, 0.0f64), |(l, h), &w| (l.min(w), h.max(w)));
            let span = knots[b] - knots[a];
            if hi <= lo * (1.0 + 1e-12) && span.is_finite() && span != 0.0 {
                for g in a..=b {
                    out[g] = va + (vb - va) * (knots[g] - knots[a]) / span;
                }
            } else {
                // The cheapest edge (g, g + 1) of the run: a's value up to g, b's after.
                let cut = (a..b)
                    .min_by(|&x, &y| weights[x].total_cmp(&weights[y]))
                    .unwrap_or(a);
                for g in a..=cut {
                    out[g] = va;
                }
                for g in cut + 1..=b {
                    out[g] = vb;
                }
            }
        }
        out
    }
}

/// The samples whose map value (w channel `col`) reaches an output that is kept, when samples
/// are held out or there are several records: sample k of a record is seen unless k + l₀ is
/// past the last kept sample of its record (each record restarts from its own state, so
/// nothing carries over into the next), l₀ the first non-zero Markov parameter of the
/// channel. With several records the last l₀ samples of every record are unseen even without
/// held-out samples. `None` for one record without held-out samples (every sample but the
/// last l₀ is seen, and those few are left to the iteration as before).
fn visible_samples(
    real: &Realisation,
    col: usize,
    missing: Option<&[bool]>,
    bounds: &[usize],
) -> Option<Vec<bool>> {
    if missing.is_none() && bounds.len() <= 2 {
        return None;
    }
    if let Some(m) = missing {
        m.iter().rposition(|&m| !m)?;
    }
    let held = |k: usize| missing.is_some_and(|m| m[k]);
    let ss = &real.ss;
    let n = ss.order();
    let tol = 1e-14 * (1.0 + ss.a().amax() + ss.b().amax() + ss.c().amax() + ss.d().amax());
    let markov = ss.markov_parameters(n + 1);
    let lead = (0..=n)
        .find(|&l| markov[l].column(col).amax() > tol)
        .unwrap_or(usize::MAX);
    let mut visible = Vec::with_capacity(*bounds.last().unwrap_or(&0));
    for w in bounds.windows(2) {
        let last_kept = (w[0]..w[1]).rposition(|k| !held(k));
        visible.extend(
            (0..w[1] - w[0]).map(|k| last_kept.is_some_and(|last| k.saturating_add(lead) <= last)),
        );
    }
    Some(visible)
}

/// The disturbance smoother over every record, each from its own initial state (zero, or
/// free with one x₀ per record): one [`DisturbanceSmoother`] per record, over its own
/// samples and held-out mask. With one record it is that smoother on the whole signals, with
/// no copies.
struct RecordSmoother {
    /// The record bounds `[0, L₁, …, L]`.
    bounds: Vec<usize>,
    /// The smoother of each record.
    parts: Vec<DisturbanceSmoother>,
}

impl RecordSmoother {
    fn new(
        ss: &StateSpace,
        variances: &[f64],
        bounds: &[usize],
        initial: SmootherInitial,
        adjoint: &[usize],
        missing: Option<&[bool]>,
    ) -> Result<Self> {
        let parts = bounds
            .windows(2)
            .map(|w| {
                let len = w[1] - w[0];
                Ok(match missing {
                    Some(m) => DisturbanceSmoother::with_missing(
                        ss,
                        variances,
                        len,
                        initial,
                        adjoint,
                        &m[w[0]..w[1]],
                    )?,
                    None => {
                        DisturbanceSmoother::with_adjoint(ss, variances, len, initial, adjoint)?
                    }
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            bounds: bounds.to_vec(),
            parts,
        })
    }

    /// Smooths every record ([`DisturbanceSmoother::smooth`] on its samples of `y`, `mean`
    /// and `out`) and returns the estimated initial states, record after record, for a free
    /// initial state.
    fn smooth(&self, y: &Signal, mean: &Signal, out: &mut Signal) -> Result<Option<Vec<f64>>> {
        if let [one] = &self.parts[..] {
            return Ok(one.smooth(y, mean, out)?.initial_state);
        }
        let (ny, nin) = (y.channels(), mean.channels());
        let slice = |s: &Signal, ch: usize, w: &[usize]| {
            Signal::new(ch, s.as_slice()[w[0] * ch..w[1] * ch].to_vec())
        };
        // The records are independent: smoothed in parallel, each bit-identical to a
        // sequential run.
        let results: Vec<(Signal, Option<Vec<f64>>)> = self
            .parts
            .par_iter()
            .zip(self.bounds.par_windows(2))
            .map(|(sm, w)| -> Result<(Signal, Option<Vec<f64>>)> {
                let (yr, mr) = (slice(y, ny, w)?, slice(mean, nin, w)?);
                let mut o = Signal::zeros(w[1] - w[0], nin);
                let report = sm.smooth(&yr, &mr, &mut o)?;
                Ok((o, report.initial_state))
            })
            .collect::<Result<_>>()?;
        let mut x0: Option<Vec<f64>> = None;
        let dst = out.as_mut_slice();
        for ((o, x), w) in results.into_iter().zip(self.bounds.windows(2)) {
            dst[w[0] * nin..w[1] * nin].copy_from_slice(o.as_slice());
            if let Some(x) = x {
                x0.get_or_insert_with(Vec::new).extend(x);
            }
        }
        Ok(x0)
    }

    /// The samples with stored gains, over every record.
    fn transient_len(&self) -> usize {
        self.parts.iter().map(|s| s.transient_len()).sum()
    }
}

/// The realisation channels of the blocks and the quadratic blocks' factors.
struct Channels<'a> {
    /// The w channels of the total-variation blocks.
    tv: &'a [usize],
    /// The w channels of the quadratic blocks.
    quadratic: &'a [usize],
    /// The quadratic blocks' factors Ψ̃ (w = Ψ̃·η, D = ‖η‖²).
    factors: &'a [QuadraticFactor],
    /// The samples whose outputs are held out (cross-validation), when any.
    missing: Option<&'a [bool]>,
    /// Where each record starts, then L ([`Problem::record_bounds`]).
    bounds: &'a [usize],
}

/// The quadratic blocks' factors, with a rank limit from the memory budget.
fn quadratic_factors(
    problem: &Problem,
    quadratic: &[(Box<dyn QuadraticPenalty>, usize)],
    nb: usize,
    settings: &IdentifySettings,
) -> Result<Vec<QuadraticFactor>> {
    if quadratic.is_empty() {
        return Ok(Vec::new());
    }
    let len = problem.len().max(1);
    // Per column of a factor: Ψ̃ itself and the responses of the n_b total-variation channels
    // (8 bytes each, per sample), for every quadratic block.
    let per_column = 8 * (len as u64) * (1 + nb as u64) * quadratic.len() as u64;
    let budget = settings.effective_memory_limit() / 2;
    let max_rank = ((budget / per_column.max(1)) as usize).min(MAX_RANK);
    let mut factors = Vec::with_capacity(quadratic.len());
    for (pen, bi) in quadratic {
        let block = &problem.blocks()[*bi];
        if max_rank == 0 {
            return Err(Error::TooLarge {
                solver: NAME.into(),
                needed_mib: per_column >> 20,
                limit_mib: settings.effective_memory_limit() >> 20,
                size: problem.len() * problem.outputs(),
                suggestion: format!(
                    "even one column of the factor of quadratic block `{}` does not fit; raise the memory \
                     limit or shorten the record",
                    block.name
                ),
            });
        }
        factors.push(QuadraticFactor::new(
            pen.as_ref(),
            &block.z,
            max_rank,
            &block.name,
        )?);
    }
    Ok(factors)
}

/// Largest rank of a quadratic block's factor (each column costs one smoother pass per value
/// of ρ and O(L) per iteration).
const MAX_RANK: usize = 2048;

/// The w-step with its linear parameters solved exactly: the total-variation blocks' constant
/// offsets and the quadratic blocks' coefficients.
///
/// Total variation does not see constants, so the problem is unchanged when w = S·d + E·c with
/// free offsets c ∈ ℝ^(n_b) (E: c_i on every sample of block i) and the ADMM constraint applies
/// to w − E·c only. A quadratic block is w_q = Ψ̃·η with the penalty β·‖η‖²
/// ([`QuadraticFactor`]). Both kinds of parameter p = (c, η) enter the smoother through its prior
/// mean: the offsets on the total-variation channels, Ψ̃·η on the quadratic channels, which have
/// variance 0 (fixed at their mean) and are *adjoint channels* of the smoother
/// ([`DisturbanceSmoother::with_adjoint`]): their output is the sensitivity g = T_qᵀS⁺δ of the
/// w-step's cost to them (δ = r − T·mean, S = T·Q·Tᵀ). The smoother being linear in its mean,
/// with M_j the mean of the unit parameter j, the cost ½δᵀS⁺δ + β‖η‖² is quadratic in p and
/// stationary where H·p = b with b_j = M_jᵀ·Tᵀ S⁺ δ₀ (from the smoother's output for p = 0:
/// ρ·(w − m) on the total-variation channels, g on the quadratic ones) and
/// H_ij = M_iᵀTᵀS⁺T·M_j + 2β·[i = j ∈ η] (from one smoother pass per parameter, once per ρ).
/// The smoother's output for p is that for 0 minus Σ_j p_j·R_j, with R_j = Q·TᵀS⁺T·M_j on the
/// total-variation channels (stored, L·n_b per parameter).
///
/// H is solved by eliminating η (its block is at least 2β·I, positive definite) and taking
/// the pseudo-inverse of the offsets' Schur complement: constants the data do not see at all
/// (e.g. with a free initial state) get the minimum-norm c.
///
/// Without the offsets, a constant combination that the data see only weakly — (f + c, g − c)
/// when two blocks read the same z into one output, seen only through the first samples from
/// rest — has a curvature of order 1/L² against ρ ~ 1/L, and ADMM drifts along it by a fraction
/// ~ 1/L per iteration.
struct WStep {
    smoother: RecordSmoother,
    /// R per sample: entry (k·n_b + i)·P + j is the response on total-variation channel i to
    /// the unit parameter j.
    resp: Vec<f64>,
    /// The solution map p = G·b (P × P, row-major).
    g: Vec<f64>,
    /// n_b.
    nb: usize,
    /// P = n_b + Σ rank.
    np: usize,
    rho: f64,
}

impl WStep {
    fn new(
        ss: &StateSpace,
        variances: &[f64],
        ch: &Channels<'_>,
        len: usize,
        initial: SmootherInitial,
        beta: f64,
        rho: f64,
    ) -> Result<Self> {
        let smoother =
            RecordSmoother::new(ss, variances, ch.bounds, initial, ch.quadratic, ch.missing)?;
        let nb = ch.tv.len();
        let nq: usize = ch.factors.iter().map(|f| f.rank).sum();
        let np = nb + nq;
        let nin = variances.len();
        let zero = Signal::zeros(len, ss.outputs());
        let mut resp = vec![0.0; len * nb * np];
        let mut h = nalgebra::DMatrix::<f64>::zeros(np, np);
        // Parameter j: an offset (channel) or column l of a factor on its channel.
        let params: Vec<(usize, Option<(&QuadraticFactor, usize)>)> = ch
            .tv
            .iter()
            .map(|&c| (c, None))
            .chain(
                ch.factors
                    .iter()
                    .zip(ch.quadratic)
                    .flat_map(|(f, &c)| (0..f.rank).map(move |l| (c, Some((f, l))))),
            )
            .collect();
        // One smoother pass per parameter (independent: in parallel, each bit-identical to
        // a sequential run): the responses on the total-variation channels and the
        // sensitivities on the quadratic ones.
        let nqb = ch.quadratic.len();
        let passes: Vec<(Vec<f64>, Vec<f64>)> = params
            .par_iter()
            .map(|&(col, factor)| -> Result<(Vec<f64>, Vec<f64>)> {
                // The mean −M_j: the smoother's output minus it is Q·TᵀS⁺T·M_j.
                let mut unit = Signal::zeros(len, nin);
                let mut out = Signal::zeros(len, nin);
                for k in 0..len {
                    unit.sample_mut(k)[col] = match factor {
                        None => -1.0,
                        Some((f, l)) => -f.rows[k * f.rank + l],
                    };
                }
                smoother.smooth(&zero, &unit, &mut out)?;
                let diff = |k: usize, c: usize| out.get(k, c) - unit.get(k, c);
                let tv: Vec<f64> = (0..len)
                    .flat_map(|k| ch.tv.iter().map(move |&c| (k, c)))
                    .map(|(k, c)| diff(k, c))
                    .collect();
                let adj: Vec<f64> = (0..len)
                    .flat_map(|k| ch.quadratic.iter().map(move |&c| (k, c)))
                    .map(|(k, c)| diff(k, c))
                    .collect();
                Ok((tv, adj))
            })
            .collect::<Result<_>>()?;
        for (j, (tv, _)) in passes.iter().enumerate() {
            for k in 0..len {
                for i in 0..nb {
                    let v = tv[k * nb + i];
                    resp[(k * nb + i) * np + j] = v;
                    h[(i, j)] += rho * v;
                }
            }
        }
        // The quadratic blocks' rows: Ψ̃_bᵀ·A_b with A_b (L × P) the sensitivities on the
        // block's channel, one product per block (sequential: bit-identical at any thread count).
        let mut at = nb;
        for (b, f) in ch.factors.iter().enumerate() {
            if f.rank == 0 {
                continue;
            }
            let a = faer::Mat::<f64>::from_fn(len, np, |k, j| passes[j].1[k * nqb + b]);
            let psi = faer::MatRef::from_row_major_slice(&f.rows, len, f.rank);
            let mut dst = faer::Mat::<f64>::zeros(f.rank, np);
            faer::linalg::matmul::matmul(
                dst.as_mut(),
                faer::Accum::Replace,
                psi.transpose(),
                a.as_ref(),
                1.0,
                faer::Par::Seq,
            );
            for l in 0..f.rank {
                for j in 0..np {
                    h[(at + l, j)] = dst[(l, j)];
                }
            }
            at += f.rank;
        }
        for i in nb..np {
            h[(i, i)] += 2.0 * beta;
        }
        let h = (&h + h.transpose()) * 0.5;
        let g = solution_map(&h, nb, len, rho);
        Ok(Self {
            smoother,
            resp,
            g,
            nb,
            np,
            rho,
        })
    }

    /// The number of parameters P (offsets, then the quadratic blocks' coefficients).
    fn parameters(&self) -> usize {
        self.np
    }

    /// The w-step for prior mean `mean` (on the total-variation channels: d − u; zero on the
    /// quadratic ones): writes w − E·c into the total-variation channels of `out` (the other
    /// channels keep the smoother's output for p = 0, unused) and the parameters into `p`.
    fn solve(
        &self,
        r: &Signal,
        mean: &Signal,
        out: &mut Signal,
        p: &mut [f64],
        ch: &Channels<'_>,
    ) -> Result<()> {
        self.smoother.smooth(r, mean, out)?;
        let (nb, np) = (self.nb, self.np);
        let mut b = vec![0.0; np];
        gather(out, mean, ch, self.rho, &mut b);
        for (i, pi) in p.iter_mut().enumerate() {
            *pi = self.g[i * np..(i + 1) * np]
                .iter()
                .zip(&b)
                .map(|(g, b)| g * b)
                .sum();
        }
        for k in 0..out.len() {
            let o = out.sample_mut(k);
            let rows = &self.resp[k * nb * np..(k + 1) * nb * np];
            for (i, &col) in ch.tv.iter().enumerate() {
                let row = &rows[i * np..(i + 1) * np];
                o[col] -= row.iter().zip(p.iter()).map(|(a, b)| a * b).sum::<f64>();
            }
        }
        Ok(())
    }
}

/// b_j = M_jᵀ·TᵀS⁺δ from a smoother output `out` for the mean `mean`: ρ times the block sums
/// of out − mean on the total-variation channels, Ψ̃ᵀ(out − mean) on the quadratic (adjoint)
/// channels.
fn gather(out: &Signal, mean: &Signal, ch: &Channels<'_>, rho: f64, b: &mut [f64]) {
    let nb = ch.tv.len();
    b.iter_mut().for_each(|v| *v = 0.0);
    let len = out.len();
    for k in 0..len {
        let (o, m) = (out.sample(k), mean.sample(k));
        for (bi, &col) in b[..nb].iter_mut().zip(ch.tv) {
            *bi += o[col] - m[col];
        }
        let mut at = nb;
        for (f, &col) in ch.factors.iter().zip(ch.quadratic) {
            let g = o[col] - m[col];
            let row = &f.rows[k * f.rank..(k + 1) * f.rank];
            for (bj, psi) in b[at..at + f.rank].iter_mut().zip(row) {
                *bj += psi * g;
            }
            at += f.rank;
        }
    }
    b[..nb].iter_mut().for_each(|v| *v *= rho);
}

/// The map p = G·b solving H·p = b: η eliminated through the Cholesky factor of its block
/// (≥ 2β·I), the offsets through the pseudo-inverse of their Schur complement, whose
/// eigenvalues below a relative 1e-10 (of max(L, λ_max) after dividing by ρ: the entries of the
/// offsets' block are at most ρ·L) count as directions the data do not see.
fn solution_map(h: &nalgebra::DMatrix<f64>, nb: usize, len: usize, rho: f64) -> Vec<f64> {
    use nalgebra::DMatrix;
    let np = h.nrows();
    let nq = np - nb;
    let hcc = h.view((0, 0), (nb, nb)).into_owned();
    let hcq = h.view((0, nb), (nb, nq)).into_owned();
    let hqq = h.view((nb, nb), (nq, nq)).into_owned();
    // H_ηη⁻¹ (symmetric positive definite; eigen-decomposition as a fallback).
    let hqq_inv = match hqq.clone().cholesky() {
        Some(c) => c.inverse(),
        None => pinv_sym(&hqq, 0.0),
    };
    // X = H_ηη⁻¹·H_ηc, Schur complement S = H_cc − H_cη·X.
    let x = &hqq_inv * hcq.transpose();
    let schur = &hcc - &hcq * &x;
    let schur = (&schur + schur.transpose()) * 0.5;
    let k = &schur / rho;
    let eig_max = k.clone().symmetric_eigen().eigenvalues.amax();
    let s_inv = pinv_sym(&k, 1e-10 * (len as f64).max(eig_max)) / rho;
    let mut g = DMatrix::<f64>::zeros(np, np);
    g.view_mut((0, 0), (nb, nb)).copy_from(&s_inv);
    let sx = &s_inv * x.transpose();
    g.view_mut((0, nb), (nb, nq)).copy_from(&(-&sx));
    g.view_mut((nb, 0), (nq, nb)).copy_from(&(-sx.transpose()));
    g.view_mut((nb, nb), (nq, nq))
        .copy_from(&(&hqq_inv + &x * &sx));
    g.transpose().as_slice().to_vec()
}

/// The pseudo-inverse of a symmetric matrix, eigenvalues at or below `cut` left out.
fn pinv_sym(a: &nalgebra::DMatrix<f64>, cut: f64) -> nalgebra::DMatrix<f64> {
    let n = a.nrows();
    let eig = a.clone().symmetric_eigen();
    let mut out = nalgebra::DMatrix::<f64>::zeros(n, n);
    for (l, &lam) in eig.eigenvalues.iter().enumerate() {
        if lam > cut {
            let v = eig.eigenvectors.column(l);
            out += (v * v.transpose()) / lam;
        }
    }
    out
}

/// The penalty's scale read off the w-step's curvature: the initial ρ₀, the bounds within
/// which residual balancing may move it, and the gain used to put the tolerances in units.
#[derive(Clone, Copy, Debug)]
struct RhoScale {
    /// The initial penalty.
    rho0: f64,
    /// The largest curvature q_max = (2/L)·max_ω λ_max(Φ(ω)) (from the gain ratio when the
    /// frequency responses could not be used).
    q_max: f64,
    /// Whether ρ₀ came from the frequency responses (else from the H₂-gain ratio).
    from_frequency: bool,
}

impl RhoScale {
    /// The interval [q_max·10⁻⁶, q_max·10] that balancing keeps ρ in: relative to the
    /// problem's own curvature, so the same in any units of w and r. Above 10·q_max the w-step
    /// is pinned to d and the iteration only crawls; 10⁻⁶·q_max is below any curvature that
    /// the data resolve in 32-bit-like precision, where the TV prox alone sets the iterate.
    fn bounds(&self) -> (f64, f64) {
        (self.q_max * RHO_RANGE_BELOW, self.q_max * RHO_RANGE_ABOVE)
    }
}

/// Lower bound of ρ relative to q_max (see [`RhoScale::bounds`]).
const RHO_RANGE_BELOW: f64 = 1e-6;
/// Upper bound of ρ relative to q_max (see [`RhoScale::bounds`]).
const RHO_RANGE_ABOVE: f64 = 10.0;
/// The smallest curvature ratio λ_lo/λ_max that ρ₀ uses (see [`default_rho`]).
const CURVATURE_FLOOR: f64 = 1e-4;

/// ρ₀ ≈ √(λ_min·λ_max) of the w-step's curvature (Giselsson & Boyd's optimal penalty for a
/// strongly convex quadratic): per frequency the curvature is (2/L)·eig(Φ), Φ = Gᴴ(H·Hᴴ)⁻¹G with
/// G the map paths and H the noise path. When Φ is singular (λ_min at rounding level, relative
/// 1e-10), from the range of its diagonal Φ_ii (each block's own curvature) instead.
///
/// λ_min is floored at [`CURVATURE_FLOOR`]·λ_max: a sampled plant of relative degree two has
/// a zero near z = −1, where Φ nearly vanishes, and a pole near 1 (an integrator) makes λ_max
/// large, so √(λ_min·λ_max) would be orders of magnitude below any curvature that matters
/// (the frequencies where Φ is tiny are the ones the total variation sets, not the data). It
/// was this ρ ≈ 10⁻⁶ that ran ADMM into its iteration limit on rate-feedback hypotheses.
/// Frequencies at which zI − A or H·Hᴴ is singular (a pole or a noise zero on the unit
/// circle, e.g. an exact integrator at ω = 0) are skipped. Falls back to the H₂-gain ratio
/// (`from_frequency` false) when no frequency can be used or every Φ_ii vanishes.
fn default_rho(real: &Realisation, w_cols: &[usize], len: usize) -> RhoScale {
    use nalgebra::{Complex, DMatrix as M};
    let ss = &real.ss;
    let (n, ne, ny) = (ss.order(), real.noise_inputs, ss.outputs());
    let to_c = |m: &M<f64>| m.map(|v| Complex::new(v, 0.0));
    let (a, b, c, d) = (to_c(ss.a()), to_c(ss.b()), to_c(ss.c()), to_c(ss.d()));
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    let (mut diag_lo, mut diag_hi) = (f64::INFINITY, 0.0f64);
    let mut used = 0usize;
    // Frequencies at which Φ is non-singular (λ_min above rounding relative to λ_max there).
    let mut regular = 0usize;
    for i in 0..=256 {
        if ne == 0 {
            break;
        }
        let om = std::f64::consts::PI * i as f64 / 256.0;
        let z = Complex::new(om.cos(), om.sin());
        let resp = if n > 0 {
            let zi_a = M::<Complex<f64>>::identity(n, n) * z - &a;
            match zi_a.lu().solve(&b) {
                Some(x) => &d + &c * x,
                None => continue,
            }
        } else {
            d.clone()
        };
        let h = resp.columns(0, ne).into_owned();
        let g = M::from_fn(ny, w_cols.len(), |r, j| resp[(r, w_cols[j])]);
        let hh = &h * h.adjoint();
        let Some(hh_inv) = hh.try_inverse() else {
            continue;
        };
        let phi = g.adjoint() * hh_inv * &g;
        // Φ is Hermitian: its eigenvalues are real (those of Re Φ alone would lie strictly inside).
        let herm = (&phi + phi.adjoint()) * Complex::new(0.5, 0.0);
        let eig = herm.symmetric_eigenvalues();
        if !(eig.min().is_finite() && eig.max().is_finite()) {
            continue;
        }
        used += 1;
        regular += usize::from(eig.min() > 1e-10 * eig.max());
        lo = lo.min(eig.min());
        hi = hi.max(eig.max());
        for j in 0..w_cols.len() {
            diag_lo = diag_lo.min(herm[(j, j)].re);
            diag_hi = diag_hi.max(herm[(j, j)].re);
        }
    }
    let scale = 2.0 / len.max(1) as f64;
    if used > 0 && hi.is_finite() && hi > 0.0 {
        let q_max = scale * hi;
        // Φ singular at every frequency (eigenvalues at rounding level are zeros) means more
        // blocks than the outputs can tell apart, e.g. two blocks reading the same z into one
        // output. Φ nearly zero at some frequencies only (a zero of G/H near the unit circle)
        // is the floored case.
        let tiny = 1e-10 * hi;
        if regular > 0 {
            let lo = lo.max(CURVATURE_FLOOR * hi);
            return RhoScale {
                rho0: scale * (lo * hi).sqrt(),
                q_max,
                from_frequency: true,
            };
        }
        // The curvature has a null space there, which the total variation alone resolves, so
        // √(λ_min·λ_max) would be 0. Each block on its own (the others fixed) sees the
        // curvature Φ_ii: take the geometric mean of its range (measured ~20 times fewer
        // iterations than balancing from the gain ratio on the spray example).
        if diag_hi > tiny && diag_hi.is_finite() {
            let dlo = diag_lo.max(CURVATURE_FLOOR * diag_hi);
            return RhoScale {
                rho0: scale * (dlo * diag_hi).sqrt(),
                q_max,
                from_frequency: true,
            };
        }
    }
    let markov = ss.markov_parameters(200.min(len.max(1)));
    let h2 = |cols: &[usize]| -> f64 {
        markov
            .iter()
            .map(|h| {
                cols.iter()
                    .map(|&c| h.column(c).norm_squared())
                    .sum::<f64>()
            })
            .sum::<f64>()
    };
    let e_cols: Vec<usize> = (0..ne).collect();
    let gw = h2(w_cols) / w_cols.len().max(1) as f64;
    let ge = h2(&e_cols) / ne.max(1) as f64;
    let ratio = if ge > 0.0 && gw > 0.0 { gw / ge } else { 1.0 };
    // The gain ratio is a rough guess (truncated Markov parameters of a slow plant can be off
    // by orders of magnitude): balancing gets the wider range [10⁻⁴, 10³]·ρ₀.
    RhoScale {
        rho0: scale * ratio,
        q_max: scale * ratio * 100.0,
        from_frequency: false,
    }
}

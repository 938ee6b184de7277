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

mod tv_view;
mod w_step;

#[allow(unused_imports)]
use {tv_view::*, w_step::*};

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
    // The w-step of ADMM penalty ρ (rebuilt when ρ adapts).
    let w_step = |rho: f64| {
        WStep::new(
            &real.ss,
            &variances(rho),
            &channels,
            len,
            initial,
            beta,
            rho,
        )
    };
    let mut wstep = w_step(rho)?;
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
                wstep = w_step(rho)?;
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
    let mut out = finish_tv(problem, parts, e_hat, x0.as_deref(), &dropped, beta)?;
    let mut warnings = std::mem::take(&mut out.warnings);
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
    let diagnostics = Diagnostics {
        solver: SolverKind::Admm,
        status,
        status_detail: unconverged,
        system_size: len * nin,
        peak_memory_bytes: peak,
        timings: Timings::from_instants(t_start, t_prepared, t_assembled, t_factored, t_end),
        iterations,
        primal_residual: Some(r_pri),
        dual_residual: Some(r_dual),
        warnings,
        ..Diagnostics::default()
    };
    Ok(out.into_identification(problem, x0, diagnostics))
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

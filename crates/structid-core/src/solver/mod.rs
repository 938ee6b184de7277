//! Solvers for the identification problem. Each takes a [`crate::Problem`] and settings and
//! returns an [`crate::Identification`]; [`crate::identify()`] chooses between them.

pub mod admm;
pub mod choice;
pub mod conic;
pub mod exact;
pub mod features;
pub mod prox;
mod quadratic_factor;
mod realisation;
pub mod settings;
pub(crate) mod square_buffer;
pub mod status;

use std::time::Instant;

pub use choice::choose_solver;

use structid_lti::Signal;

use crate::dispersion::total_variation::TvPenalty;
use crate::dispersion::{Penalty, QuadraticPenalty};
use crate::error::{Error, Result};
use crate::identify::problem::{Problem, ProblemBlock};
use crate::identify::result::{BlockEstimate, CostTerms, Diagnostics, Identification, Timings};
use crate::model::interpolant::Interpolant;

/// One block's solution before assembly: ŵ at the samples, D_i and the interpolant.
pub(crate) struct BlockPart {
    pub(crate) w_hat: Vec<f64>,
    pub(crate) dispersion_value: f64,
    pub(crate) map: Box<dyn Interpolant>,
}

/// What every solver derives the same way from the block parts.
pub(crate) struct Assembled {
    pub(crate) blocks: Vec<BlockEstimate>,
    /// ŵ as a signal, column c from the block with output c.
    pub(crate) w_hat: Signal,
    /// T_yw·ŵ (L·n_y), for feasibility and residuals.
    pub(crate) fitted: Vec<f64>,
    pub(crate) dispersions: Vec<f64>,
}

/// Builds the block estimates, ŵ and T_yw·ŵ from the parts (in the problem's block order).
pub(crate) fn assemble_blocks(problem: &Problem, parts: Vec<BlockPart>) -> Assembled {
    assemble_blocks_with(problem, parts, |path, w, out| path.apply(w, out))
}

/// [`assemble_blocks`] with T_i·ŵ computed by `apply` (the feature solver's blocked
/// long-signal recursion, for one).
pub(crate) fn assemble_blocks_with(
    problem: &Problem,
    parts: Vec<BlockPart>,
    apply: impl Fn(&dyn structid_lti::LinearSystem, &[f64], &mut [f64]),
) -> Assembled {
    let (len, n) = (problem.len(), problem.len() * problem.outputs());
    let mut w_all = Signal::zeros(len, parts.len());
    let mut fitted = vec![0.0; n];
    let mut tmp = vec![0.0; n];
    let mut dispersions = Vec::with_capacity(parts.len());
    let mut blocks = Vec::with_capacity(parts.len());
    for (block, part) in problem.blocks().iter().zip(parts) {
        apply(block.path.as_ref(), &part.w_hat, &mut tmp);
        fitted.iter_mut().zip(&tmp).for_each(|(f, t)| *f += t);
        // Problem::new guarantees the outputs are exactly 0..n_blocks.
        for (k, w) in part.w_hat.iter().enumerate() {
            w_all.sample_mut(k)[block.output] = *w;
        }
        dispersions.push(part.dispersion_value);
        blocks.push(BlockEstimate {
            name: block.name.clone(),
            output: block.output,
            dispersion: block.dispersion.describe(),
            parameters: block.dispersion.parameters(),
            z: block.z.clone(),
            w_hat: part.w_hat,
            dispersion_value: part.dispersion_value,
            map: part.map,
        });
    }
    Assembled {
        blocks,
        w_hat: w_all,
        fitted,
        dispersions,
    }
}

/// J = μ + β·Σ D_i, refusing a non-finite estimate with advice.
pub(crate) fn cost_terms(mu: f64, beta: f64, assembled: &Assembled) -> Result<CostTerms> {
    let total = mu + beta * assembled.dispersions.iter().sum::<f64>();
    if !total.is_finite() || assembled.w_hat.as_slice().iter().any(|v| !v.is_finite()) {
        return Err(Error::Numerical(format!(
            "the estimate is not finite (J = {total}); the data are probably too large in magnitude for the \
             kernel scaling — rescale y (and u) to order one"
        )));
    }
    Ok(CostTerms {
        noise: mu,
        dispersions: assembled.dispersions.clone(),
        beta,
        total,
    })
}

impl Timings {
    /// Phase durations from the instants that separate them.
    pub(crate) fn from_instants(
        start: Instant,
        prepared: Instant,
        assembled: Instant,
        factored: Instant,
        end: Instant,
    ) -> Self {
        let secs = |a: Instant, b: Instant| (b - a).as_secs_f64();
        Self {
            prepare: secs(start, prepared),
            assemble: secs(prepared, assembled),
            factor: secs(assembled, factored),
            solve: secs(factored, end),
            total: secs(start, end),
        }
    }
}

/// The quadratic penalty of a block, or an error naming the solvers that handle its kind.
pub(crate) fn quadratic_penalty(
    block: &ProblemBlock,
    solver: &str,
) -> Result<Box<dyn QuadraticPenalty>> {
    match block.dispersion.penalty(&block.z)? {
        Penalty::Quadratic(q) => Ok(q),
        Penalty::TotalVariation(_) => Err(Error::Unsupported(format!(
            "block `{}` has a total-variation dispersion ({}), which the {solver} solver cannot handle; \
             use the clarabel or admm solver (or solver = auto)",
            block.name,
            block.dispersion.describe()
        ))),
    }
}

/// Every block's penalty, in block order.
pub(crate) fn penalties(problem: &Problem) -> Result<Vec<Penalty>> {
    problem
        .blocks()
        .iter()
        .map(|b| b.dispersion.penalty(&b.z))
        .collect()
}

/// The block parts of total-variation blocks from their node values.
pub(crate) fn tv_parts(penalties: &[TvPenalty], node_values: Vec<Vec<f64>>) -> Vec<BlockPart> {
    penalties
        .iter()
        .zip(node_values)
        .map(|(p, v)| tv_part(p, v))
        .collect()
}

/// One total-variation block's part from its node values.
pub(crate) fn tv_part(penalty: &TvPenalty, nodes: Vec<f64>) -> BlockPart {
    BlockPart {
        w_hat: penalty.sample_values(&nodes),
        dispersion_value: penalty.value(&nodes),
        map: penalty.interpolant(nodes),
    }
}

/// What the conic and ADMM solvers derive the same way from the block parts, ê and x̂₀.
pub(crate) struct TvOutcome {
    pub(crate) assembled: Assembled,
    pub(crate) cost: CostTerms,
    pub(crate) e_hat: Signal,
    /// ‖T_ye·ê + T_yw·ŵ + O·x̂₀ − r‖ / ‖r‖ over the samples kept.
    pub(crate) feasibility: f64,
    /// Dropped sample indices (k·n_y + channel) and the largest |r| there.
    pub(crate) dropped: Vec<usize>,
    pub(crate) dropped_max: f64,
    pub(crate) warnings: Vec<String>,
}

impl TvOutcome {
    /// The estimate of a total-variation solve (no posterior): this outcome, x̂₀ and the
    /// solver's `diagnostics`, completed with the dropped samples, the feasibility residual
    /// and no condition bound.
    pub(crate) fn into_identification(
        self,
        problem: &Problem,
        x0: Option<Vec<f64>>,
        diagnostics: Diagnostics,
    ) -> Identification {
        Identification {
            posterior: None,
            w_hat: self.assembled.w_hat,
            e_hat: self.e_hat,
            blocks: self.assembled.blocks,
            cost: self.cost,
            z_source: problem.z_source().clone(),
            initial_state: x0,
            diagnostics: Diagnostics {
                dropped_samples: self.dropped,
                dropped_max_abs_residual: self.dropped_max,
                condition_lower_bound: f64::NAN,
                feasibility_residual: self.feasibility,
                ..diagnostics
            },
        }
    }
}

/// Builds the estimate from the block parts, checking feasibility with the problem's own
/// operators (independently of the realisation the solver used).
pub(crate) fn finish_tv(
    problem: &Problem,
    parts: Vec<BlockPart>,
    e_hat: Vec<f64>,
    x0: Option<&[f64]>,
    dropped: &[(usize, usize)],
    beta: f64,
) -> Result<TvOutcome> {
    let (len, ny) = (problem.len(), problem.outputs());
    let ne = problem.noise().inputs();
    let assembled = assemble_blocks(problem, parts);
    let mu = e_hat.iter().map(|v| v * v).sum::<f64>() / len.max(1) as f64;
    let cost = cost_terms(mu, beta, &assembled)?;
    let mut fitted = assembled.fitted.clone();
    let mut tmp = vec![0.0; len * ny];
    if ne > 0 {
        problem.noise().apply(&e_hat, &mut tmp);
        fitted.iter_mut().zip(&tmp).for_each(|(f, t)| *f += t);
    }
    if let (Some(o), Some(x0)) = (problem.free_response(), x0) {
        for (i, f) in fitted.iter_mut().enumerate() {
            *f += (0..o.ncols()).map(|j| o[(i, j)] * x0[j]).sum::<f64>();
        }
    }
    let r = problem.residual().as_slice();
    let mut is_dropped = vec![false; len * ny];
    let mut dropped_idx = Vec::with_capacity(dropped.len());
    for &(k, ch) in dropped {
        is_dropped[k * ny + ch] = true;
        dropped_idx.push(k * ny + ch);
    }
    let (mut res2, mut r2, mut dropped_max) = (0.0, 0.0, 0.0f64);
    // Held-out rows (cross-validation) are not fitted: they do not count in the feasibility.
    let held = problem.held_out();
    for i in 0..len * ny {
        if held.is_some_and(|h| h[i]) {
            continue;
        }
        if is_dropped[i] {
            dropped_max = dropped_max.max(r[i].abs());
        } else {
            res2 += (fitted[i] - r[i]).powi(2);
            r2 += r[i] * r[i];
        }
    }
    let mut warnings = Vec::new();
    if !dropped_idx.is_empty() {
        let scale = r.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
        warnings.push(format!(
            "{} output samples depend on neither e nor w and were left out (max |r| there {dropped_max:.3e}){}",
            dropped_idx.len(),
            if dropped_max > 1e-8 * scale {
                " — the data are NOT consistent with the model at those samples"
            } else {
                ""
            }
        ));
    }
    Ok(TvOutcome {
        assembled,
        cost,
        e_hat: Signal::new(ne, e_hat)?,
        feasibility: relative_residual(res2, r2),
        dropped: dropped_idx,
        dropped_max,
        warnings,
    })
}

/// ‖fit − r‖ / ‖r‖ from the two squared norms; the absolute ‖fit − r‖ when r is zero, so a
/// zero right-hand side still reports how far the fit is from it.
pub(crate) fn relative_residual(res2: f64, r2: f64) -> f64 {
    if r2 > 0.0 {
        (res2 / r2).sqrt()
    } else {
        res2.sqrt()
    }
}

/// (max / min)² from the extreme diagonal (or singular) values of a factor, a lower bound on the
/// condition number of the system it factors; infinite when the smallest is zero.
pub(crate) fn condition_lower_bound(max: f64, min: f64) -> f64 {
    if min > 0.0 {
        (max / min).powi(2)
    } else {
        f64::INFINITY
    }
}

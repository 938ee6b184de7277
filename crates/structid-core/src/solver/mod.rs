//! Solvers for the identification problem. Each takes a [`crate::Problem`] and settings and
//! returns an [`crate::Identification`]; [`crate::identify()`] chooses between them.

pub mod exact;
pub mod features;

use std::time::Instant;

use structid_lti::Signal;

use crate::error::{Error, Result};
use crate::identify::{BlockEstimate, CostTerms, Timings};
use crate::interpolant::Interpolant;
use crate::problem::Problem;

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
    let (len, n) = (problem.len(), problem.len() * problem.outputs());
    let mut w_all = Signal::zeros(len, parts.len());
    let mut fitted = vec![0.0; n];
    let mut tmp = vec![0.0; n];
    let mut dispersions = Vec::with_capacity(parts.len());
    let mut blocks = Vec::with_capacity(parts.len());
    for (block, part) in problem.blocks().iter().zip(parts) {
        block.path.apply(&part.w_hat, &mut tmp);
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

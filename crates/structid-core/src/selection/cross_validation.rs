//! Blocked K-fold cross-validation by refitting.

use crate::error::{Error, Result};
use crate::identify::problem::Problem;
use crate::identify::{Identification, IdentifySettings, SolverChoice, identify_problem};
use crate::solver::choice::SolverKind;

use super::score::BetaScore;

/// Blocked K-fold cross-validation by refitting.
pub(super) struct FoldScore {
    problem: Problem,
    settings: IdentifySettings,
    masks: Vec<Vec<bool>>,
    /// The folds are the records (several records): each is held out whole.
    by_record: bool,
}

impl FoldScore {
    /// With several records the folds are the records, whatever `folds` says: a record is the
    /// natural unit of independent data, and a fold cutting across a boundary would mix them.
    pub(super) fn new(problem: Problem, settings: IdentifySettings, folds: usize) -> Result<Self> {
        let len = problem.len();
        let ny = problem.outputs();
        if problem.record_count() > 1 {
            let masks = problem
                .record_bounds()
                .windows(2)
                .map(|w| {
                    (0..len * ny)
                        .map(|row| (w[0]..w[1]).contains(&(row / ny)))
                        .collect()
                })
                .collect();
            return Ok(Self {
                problem,
                settings,
                masks,
                by_record: true,
            });
        }
        if folds > len {
            return Err(Error::InvalidParameter {
                name: "folds".into(),
                value: folds as f64,
                reason: format!("more folds than the {len} samples"),
            });
        }
        let masks = (0..folds)
            .map(|f| {
                let (a, b) = (f * len / folds, (f + 1) * len / folds);
                (0..len * ny)
                    .map(|row| (a..b).contains(&(row / ny)))
                    .collect()
            })
            .collect();
        Ok(Self {
            problem,
            settings,
            masks,
            by_record: false,
        })
    }
}

/// T_yw·ŵ + T_ye·ê (+ O·x₀): the model's fitted residual at every output row.
pub(crate) fn fitted_residual(problem: &Problem, id: &Identification) -> Vec<f64> {
    let n = problem.len() * problem.outputs();
    let mut out = vec![0.0; n];
    let mut tmp = vec![0.0; n];
    for (b, est) in problem.blocks().iter().zip(&id.blocks) {
        b.path.apply(&est.w_hat, &mut tmp);
        out.iter_mut().zip(&tmp).for_each(|(o, t)| *o += t);
    }
    problem.noise().apply(id.e_hat.as_slice(), &mut tmp);
    out.iter_mut().zip(&tmp).for_each(|(o, t)| *o += t);
    if let (Some(o), Some(x0)) = (problem.free_response(), &id.initial_state) {
        for (i, v) in out.iter_mut().enumerate() {
            *v += (0..x0.len()).map(|j| o[(i, j)] * x0[j]).sum::<f64>();
        }
    }
    out
}

impl BetaScore for FoldScore {
    fn score(&mut self, beta: f64) -> Result<(f64, Option<f64>)> {
        let settings = self.settings.with_beta(beta)?;
        let r = self.problem.residual().as_slice();
        let (mut sse, mut count) = (0.0, 0usize);
        for mask in &self.masks {
            let p = self.problem.clone().with_held_out(mask.clone())?;
            // An unconverged trial cannot be scored: the selection stops with its error. ADMM
            // (chosen automatically for long records) can stall on a fold whose held-out map
            // values the remaining outputs barely see (small β): that fold is refitted by the
            // exact conic solver.
            let id = identify_problem(&p, &settings)?;
            let id = if id.diagnostics.solver == SolverKind::Admm
                && !id.diagnostics.status.is_converged()
                && self.settings.solver() == SolverChoice::Auto
            {
                identify_problem(&p, &settings.with_solver(SolverChoice::Clarabel))?
            } else {
                id
            };
            let id = id.converged()?;
            let fit = fitted_residual(&p, &id);
            for (i, &held) in mask.iter().enumerate() {
                if held {
                    let d = r[i] - fit[i];
                    sse += d * d;
                    count += 1;
                }
            }
        }
        let v = sse / count.max(1) as f64;
        if !v.is_finite() {
            return Err(Error::Numerical(format!(
                "cross-validation error not finite at β = {beta:.3e}"
            )));
        }
        Ok((v, None))
    }

    fn method(&self) -> String {
        if self.by_record {
            return format!(
                "leave-one-record-out cross-validation (each of the {} records held out in turn; {} fits per β)",
                self.masks.len(),
                self.masks.len()
            );
        }
        format!(
            "blocked {}-fold cross-validation (contiguous blocks of samples held out; {} fits per β)",
            self.masks.len(),
            self.masks.len()
        )
    }
}

//! One case of a comparison sweep: its record before it runs ([`skeleton`]), its
//! identification, selection and validation ([`run_case`]), and whether a case file already
//! holds a finished case ([`case_is_complete`]).

use std::time::Instant;

use structid_core::validation::metrics::{centred_rms_difference, rms_difference};
use structid_core::{Identification, IdentifySettings, Signal, identify};
use structid_io::DispersionSpec;
use structid_io::sweep_file::{BetaChoice, SelectionMethod, SweepDispersion};

use crate::compare::cases::{Case, Fnv};
use crate::compare::config::{Experiment, Sweep};
use crate::compare::results::{
    BlockRecord, CASE_FORMAT, CaseRecord, CostRecord, GridRecord, OutputRecord, Values, finite,
};
use crate::error::{Result, WorkflowError};
use crate::grid::{GRID_1D, linspace, mean, span};

/// β where an automatic search starts.
const AUTO_BETA_START: f64 = 0.01;

/// Everything a case needs that is shared by all cases.
pub struct Context<'a> {
    /// The sweep.
    pub sweep: &'a Sweep,
    /// The number of cases of the whole sweep.
    pub case_count: usize,
    /// The fingerprint of the case list ([`crate::compare::cases::case_list_hash`]).
    pub case_list: String,
}

/// The fingerprint of a case: its experiment's files and settings, its dispersion's settings,
/// β and seed. Resuming refuses a case file whose fingerprint differs.
fn fingerprint(exp: &Experiment, disp: &SweepDispersion, case: &Case) -> String {
    let mut h = Fnv::new();
    h.write(&exp.fingerprint.to_le_bytes());
    h.write(
        format!(
            "{}|{:?}|{}|{:?}|{:?}|{}|{:?}",
            disp.name,
            disp.spec,
            disp.tune_sigma,
            disp.selection,
            disp.solver,
            case.beta.label(),
            case.seed
        )
        .as_bytes(),
    );
    format!("{:016x}", h.finish())
}

fn criterion(m: SelectionMethod) -> structid_core::selection::Criterion {
    match m {
        SelectionMethod::MarginalLikelihood => {
            structid_core::selection::Criterion::MarginalLikelihood
        }
        SelectionMethod::Gcv => structid_core::selection::Criterion::Gcv,
        SelectionMethod::CrossValidation { folds } => {
            structid_core::selection::Criterion::CrossValidation { folds }
        }
        SelectionMethod::Validation => structid_core::selection::Criterion::Validation,
    }
}

/// One-line error text with its causes.
fn one_line(e: &dyn std::fmt::Display) -> String {
    e.to_string()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("; ")
}

/// The record of a case before it ran: names and columns known from the configuration, so that a
/// failed case still has its row.
pub fn skeleton(ctx: &Context<'_>, case: &Case) -> CaseRecord {
    let exp = &ctx.sweep.experiments[case.experiment];
    let disp = &ctx.sweep.file.dispersions[case.dispersion];
    CaseRecord {
        format: CASE_FORMAT.into(),
        id: case.id.clone(),
        index: case.index,
        case_count: ctx.case_count,
        case_list: ctx.case_list.clone(),
        fingerprint: fingerprint(exp, disp, case),
        experiment: exp.name.clone(),
        dispersion: disp.name.clone(),
        beta_setting: case.beta.label(),
        seed: case.seed,
        selection: match case.beta {
            BetaChoice::Fixed(_) => "fixed".into(),
            BetaChoice::Auto => disp.selection.name().into(),
        },
        beta: match case.beta {
            BetaChoice::Fixed(b) => Some(b),
            BetaChoice::Auto => None,
        },
        blocks: exp
            .model
            .blocks
            .iter()
            .zip(&exp.truth)
            .zip(&exp.centred)
            .map(|((b, t), &centred)| BlockRecord {
                name: b.name.clone(),
                centred,
                has_truth: t.is_some(),
                rms_error: None,
                sigma: None,
                grid: None,
            })
            .collect(),
        validation: if exp.has_validation {
            exp.outputs
                .iter()
                .map(|n| OutputRecord {
                    name: n.clone(),
                    rms: None,
                    fit_percent: None,
                })
                .collect()
        } else {
            Vec::new()
        },
        cost: None,
        solver: disp.solver.name().into(),
        seconds: 0.0,
        status: "ok".into(),
        selection_curve: Vec::new(),
        noise_variance: None,
    }
}

/// Fills `rec` with the results of the case; an error leaves the rest of `rec` as it is.
fn execute(ctx: &Context<'_>, case: &Case, rec: &mut CaseRecord) -> Result<()> {
    let exp = &ctx.sweep.experiments[case.experiment];
    let disp = &ctx.sweep.file.dispersions[case.dispersion];
    let (data, validation) = exp.records(case.seed)?;
    let mut mf = exp.model.clone();
    mf.replace_dispersions(&disp.spec);
    let needs_z = mf.blocks.iter().any(|b| {
        b.dispersion.sigma().is_none()
            && !matches!(b.dispersion, DispersionSpec::TotalVariation { .. })
    });
    let z = if needs_z {
        Some(mf.z_signal(&data)?)
    } else {
        None
    };
    let model = mf.to_model(None, z.as_ref())?;
    let settings = IdentifySettings::builder()
        .beta(match case.beta {
            BetaChoice::Fixed(b) => b,
            BetaChoice::Auto => AUTO_BETA_START,
        })
        .solver(disp.solver)
        .posterior(true)
        .build()?;
    let (id, model): (Identification, _) = match case.beta {
        BetaChoice::Fixed(_) => (identify(&model, &data, &settings)?, model),
        BetaChoice::Auto => {
            let sel_settings = structid_core::selection::SelectionSettings::builder()
                .criterion(criterion(disp.selection))
                .tune_sigma(disp.tune_sigma)
                .build()?;
            let sel = structid_core::selection::select(
                &model,
                &data,
                validation.as_ref(),
                &settings,
                &sel_settings,
            )?;
            rec.beta = Some(sel.beta);
            rec.selection_curve = sel.curve;
            rec.noise_variance = sel.noise_variance.and_then(finite);
            (sel.identification, sel.model)
        }
    };
    let id = id.converged()?;
    rec.solver = id.diagnostics.solver.to_string();
    rec.cost = Some(CostRecord {
        noise: id.cost.noise,
        dispersion: id.cost.dispersions.iter().sum(),
        total: id.cost.total,
    });
    for (i, est) in id.blocks.iter().enumerate() {
        let Some(k) = exp.model.blocks.iter().position(|b| b.name == est.name) else {
            return Err(WorkflowError::Failed(format!(
                "the identification returned an unknown block `{}`",
                est.name
            )));
        };
        let truth = exp.truth[k].as_deref();
        let b = &mut rec.blocks[k];
        b.sigma = est
            .parameters
            .iter()
            .find(|(n, _)| n == "sigma")
            .map(|(_, v)| *v);
        let truth_at_data = truth.map(|t| t.eval_many(&est.z));
        if let Some(tv) = &truth_at_data {
            b.rms_error = finite(if b.centred {
                centred_rms_difference(&est.w_hat, tv)
            } else {
                rms_difference(&est.w_hat, tv)
            });
        }
        if est.z.channels() == 1 {
            let (lo, hi) = span(&est.z.channel(0));
            let xs = linspace(lo, hi, GRID_1D);
            let points = Signal::new(1, xs.clone()).map_err(structid_core::Error::from)?;
            b.grid = Some(GridRecord {
                estimate: Values(xs.iter().map(|&x| est.map.eval(&[x])).collect()),
                std: id.posterior_std(i, &points)?.map(Values),
                truth: truth.map(|t| Values(xs.iter().map(|&x| t.eval(&[x])).collect())),
                z: Values(xs),
                estimate_mean: mean(&est.w_hat),
                truth_mean: truth_at_data.as_deref().map(mean),
            });
        }
    }
    if let Some(v) = &validation {
        let report = structid_core::validation::validate(
            &model,
            &id.maps(),
            v,
            &structid_core::validation::ValidationSettings::default(),
        )
        .map_err(|e| WorkflowError::from(e).context("validation"))?;
        for (o, (rms, fit)) in rec
            .validation
            .iter_mut()
            .zip(report.rms.iter().zip(&report.fit_percent))
        {
            o.rms = finite(*rms);
            o.fit_percent = finite(*fit);
        }
    }
    Ok(())
}

/// Runs one case; failures (including panics, which are bugs) become its status.
pub fn run_case(ctx: &Context<'_>, case: &Case) -> CaseRecord {
    let t0 = Instant::now();
    let mut rec = skeleton(ctx, case);
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        execute(ctx, case, &mut rec)
    }));
    match outcome {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            rec.status = format!("error: {}", one_line(&structid_io::ErrorChain(&e)));
        }
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown cause".into());
            rec.status = format!(
                "error: internal error (a bug in structid): {}",
                one_line(&msg)
            );
        }
    }
    rec.seconds = t0.elapsed().as_secs_f64();
    rec
}

/// Whether a case file that parses is a finished case of this sweep: the record of a run that
/// got as far as writing its result. A record of another length of case list, or one that
/// says `ok` without the cost of its estimate, is not (a file written by hand, or by a
/// version that wrote records before finishing them); `--resume` runs such a case again.
pub fn case_is_complete(r: &CaseRecord, ctx: &Context<'_>) -> bool {
    r.case_count == ctx.case_count
        && r.case_list == ctx.case_list
        && (!r.is_ok() || r.cost.is_some())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_line_joins_causes() {
        assert_eq!(one_line(&"a\n  caused by: b\n"), "a; caused by: b");
    }
}

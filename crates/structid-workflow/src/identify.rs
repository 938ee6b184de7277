//! The identify workflow: a model file and its records in; the identification, the β and σ
//! used (given or selected), the stored estimate and its report out. `structid identify` and
//! Python's `structid.identify` both run it, and differ only in how they read arguments and
//! show results.
//!
//! The steps, in order: the blocks must be reachable from u and y and the LFT's residual
//! recursion stable; every map input must vary over the data and a given σ must be sensible
//! for it; the model is built with default widths chosen from the data's z; then either one
//! solve at the given β and σ, or a selection of β and/or σ by a criterion (by default the
//! marginal likelihood for quadratic dispersions and cross-validation for total variation).

use std::sync::Arc;

use structid_core::estimate::{Estimate, SignalNames};
use structid_core::progress::Progress;
use structid_core::selection::{Criterion, SelectionSettings, select};
use structid_core::{Data, Dispersion, Identification, IdentifySettings, Model, identify};
use structid_io::{DispersionSpec, ModelFile, Report, SelectionReport};

use crate::error::{Result, WorkflowError};

/// What to identify, and how β and σ are chosen.
#[derive(Clone)]
pub struct IdentifyRequest<'a> {
    /// The model file (with any dispersion already replaced).
    pub model: &'a ModelFile,
    /// The estimation records.
    pub data: &'a Data,
    /// How the data are named in messages (a file name, `the data`).
    pub data_label: String,
    /// The validation record of [`Criterion::Validation`].
    pub validation: Option<&'a Data>,
    /// β, or `None` to select it.
    pub beta: Option<f64>,
    /// σ of every block, or `None` for the model file's (or a default from the data).
    pub sigma: Option<f64>,
    /// How `sigma` is named in messages (`--sigma`, `sigma`).
    pub sigma_label: String,
    /// Select σ too.
    pub sigma_auto: bool,
    /// The selection criterion; `None`: [`default_criterion`].
    pub selection: Option<Criterion>,
    /// Folds of the default cross-validation.
    pub folds: usize,
    /// The solver settings (their β is replaced by the one used).
    pub settings: IdentifySettings,
    /// Dispersions in place of the model file's: one block's by name, or every block's
    /// (`None`), the last one that names a block winning (user kernels from Python).
    pub dispersions: Vec<(Option<String>, Arc<dyn Dispersion>)>,
    /// Where the selection reports its trials.
    pub progress: Progress,
}

/// What an identification produced.
pub struct IdentifyOutcome {
    /// The identification (ŵ, ê, maps, cost, diagnostics, posterior).
    pub identification: Identification,
    /// The model identified (with the widths selected, when σ was).
    pub model: Model,
    /// The settings used, with the β used.
    pub settings: IdentifySettings,
    /// σ given or selected for every block, when one was.
    pub sigma: Option<f64>,
    /// The selection, when β or σ was selected.
    pub selection: Option<SelectionReport>,
    /// The width selected per block (`None` for a block without one, or without selection).
    pub widths: Vec<Option<f64>>,
    /// The fitted model as stored (estimate.json), with the model file's signal names.
    pub estimate: Estimate,
    /// report.json.
    pub report: Report,
}

/// The criterion used when none is asked for: the marginal likelihood when every dispersion is
/// quadratic (a Gaussian-process evidence exists), else `folds`-fold cross-validation.
pub fn default_criterion(model: &ModelFile, folds: usize) -> Criterion {
    criterion_for(model, &[], folds)
}

/// [`default_criterion`] when `replaced` blocks (by name; `None`: every block) have a
/// dispersion of their own in place of the model file's: a kernel or features, quadratic.
fn criterion_for(model: &ModelFile, replaced: &[Option<&str>], folds: usize) -> Criterion {
    let is_replaced = |name: &str| replaced.iter().any(|r| r.is_none_or(|r| r == name));
    let quadratic = !model.blocks.iter().any(|b| {
        !is_replaced(&b.name) && matches!(b.dispersion, DispersionSpec::TotalVariation { .. })
    });
    if quadratic {
        Criterion::MarginalLikelihood
    } else {
        Criterion::CrossValidation { folds }
    }
}

/// The core model of a model file on `data`: σ given, else each block's own, else a default
/// from the data's z.
///
/// # Errors
/// The model file's errors, and a z the data do not give.
pub fn core_model(mf: &ModelFile, sigma: Option<f64>, data: &Data) -> Result<Model> {
    let needs_z = sigma.is_none()
        && mf.blocks.iter().any(|b| {
            b.dispersion.sigma().is_none()
                && !matches!(b.dispersion, DispersionSpec::TotalVariation { .. })
        });
    let z = if needs_z {
        Some(mf.z_of_records(data)?)
    } else {
        None
    };
    Ok(mf.to_model(sigma, z.as_ref())?)
}

/// The model with `dispersions` in place of its blocks' (see
/// [`IdentifyRequest::dispersions`]), each at width `sigma` when given and it has one.
fn with_dispersions(
    model: Model,
    dispersions: &[(Option<String>, Arc<dyn Dispersion>)],
    sigma: Option<f64>,
) -> Result<Model> {
    if let Some(name) = dispersions
        .iter()
        .filter_map(|(b, _)| b.as_deref())
        .find(|name| model.blocks().iter().all(|b| b.name != *name))
    {
        return Err(WorkflowError::Request(format!(
            "the model has no block `{name}` to give a dispersion to"
        )));
    }
    let mut failed = None;
    let model = model.with_dispersions(|b| {
        let Some((_, d)) = dispersions
            .iter()
            .rev()
            .find(|(name, _)| name.as_deref().is_none_or(|n| n == b.name))
        else {
            return Arc::clone(&b.dispersion);
        };
        let Some(s) = sigma else {
            return Arc::clone(d);
        };
        match d.with_width(s) {
            Some(Ok(w)) => w,
            Some(Err(e)) => {
                failed = Some(WorkflowError::Core(e));
                Arc::clone(d)
            }
            None => {
                failed = Some(WorkflowError::Request(format!(
                    "block `{}`: its dispersion {} has no width for sigma to set",
                    b.name,
                    d.describe()
                )));
                Arc::clone(d)
            }
        }
    });
    match failed {
        Some(e) => Err(e),
        None => Ok(model),
    }
}

/// The checks of a model file that need no data: every block's z computable from u and y
/// (else the joint fit's), and a stable residual recursion. [`identify_model_file`] makes them
/// first; a front end may make them before it reads any data.
///
/// # Errors
/// The model file's refusal, which names the blocks out of reach.
pub fn check_identifiable(mf: &ModelFile) -> Result<()> {
    mf.check_z_computable()?;
    mf.lft.check_residual_stable()?;
    Ok(())
}

/// Runs the identify workflow (see the module documentation).
///
/// # Errors
/// A block identification cannot reach, an unstable residual recursion, a map input that
/// does not vary, an absurd σ, and the errors of selection and identification. An iterate
/// that stopped at an iteration limit is returned, not refused: check
/// [`Identification::check_converged`].
pub fn identify_model_file(req: &IdentifyRequest<'_>) -> Result<IdentifyOutcome> {
    let mf = req.model;
    if let Some(s) = req.sigma
        && !(s.is_finite() && s > 0.0)
    {
        return Err(WorkflowError::Request(format!(
            "invalid {} {s}: it must be a finite number greater than zero",
            req.sigma_label
        )));
    }
    check_identifiable(mf)?;
    mf.check_excitation(req.data, &req.data_label)?;
    if let Some(s) = req.sigma {
        mf.check_sigma(s, req.data, &req.sigma_label)?;
    }
    let model = with_dispersions(
        core_model(mf, req.sigma, req.data)?,
        &req.dispersions,
        req.sigma,
    )?;
    let base = match req.beta {
        Some(b) => req.settings.with_beta(crate::options::beta(b)?)?,
        None => req.settings.clone(),
    };
    let (id, settings, model, selection, widths) = if req.beta.is_none() || req.sigma_auto {
        let replaced: Vec<Option<&str>> =
            req.dispersions.iter().map(|(b, _)| b.as_deref()).collect();
        let criterion = req
            .selection
            .unwrap_or_else(|| criterion_for(mf, &replaced, req.folds));
        let how = SelectionSettings::builder()
            .criterion(criterion)
            .tune_beta(req.beta.is_none())
            .tune_sigma(req.sigma_auto)
            .progress(req.progress.clone())
            .build()?;
        let sel = select(&model, req.data, req.validation, &base, &how)?;
        let chosen = base.with_beta(sel.beta)?;
        let report = SelectionReport::new(&sel);
        let widths = sel.widths.clone();
        (sel.identification, chosen, sel.model, Some(report), widths)
    } else {
        let id = identify(&model, req.data, &base)?;
        (id, base, model, None, Vec::new())
    };
    let sigma = selection.as_ref().and_then(|s| s.sigma).or(req.sigma);
    let mut report = Report::new(mf, &id, &settings, req.sigma)?;
    report.selection = selection.clone();
    // A block with a dispersion of its own is not the model file's.
    for b in report.settings.blocks.iter_mut().filter(|b| {
        req.dispersions
            .iter()
            .any(|(name, _)| name.as_deref().is_none_or(|n| n == b.name))
    }) {
        b.kind = "user".into();
        b.sigma_source = match req.sigma {
            Some(_) => "override".into(),
            None => "the dispersion's own".into(),
        };
    }
    let estimate = Estimate::from_identification(&model, &id, req.data, &settings)?
        .with_signal_names(SignalNames {
            u: mf.signals.u.clone(),
            y: mf.signals.y.clone(),
        })?;
    Ok(IdentifyOutcome {
        identification: id,
        model,
        settings,
        sigma,
        selection,
        widths,
        estimate,
        report,
    })
}

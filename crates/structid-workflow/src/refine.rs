//! The refine workflow: a model file with one map around an uncertain linear part G, refined
//! by alternation (identify the map with G fixed, re-estimate G by output error with the map
//! fixed; [`structid_core::refine`]). `structid refine` and Python's `structid.refine` both
//! run it.
//!
//! The model file either has a `[linear]` section with a structure around its one map, or an
//! `[lft]` whose one map sits where one of those structures puts it (recognised by
//! [`LinearStructure::from_lft`]; the refined model is then written as `[linear]`).

use structid_core::estimate::{Estimate, Provenance, SignalNames};
use structid_core::progress::Progress;
use structid_core::refine::{LinearStructure, RefineSettings, Refinement, refine};
use structid_core::selection::{Criterion, SelectionSettings};
use structid_core::{Data, IdentifySettings};
use structid_io::{LinearSpec, ModelFile, RefinementReport, Report, SelectionReport};
use structid_linear::OeSettings;

use crate::error::{Result, WorkflowError};

/// What to refine, and how.
#[derive(Clone)]
pub struct RefineRequest<'a> {
    /// The model file.
    pub model: &'a ModelFile,
    /// How the model file is named in messages.
    pub model_label: String,
    /// The estimation records.
    pub data: &'a Data,
    /// How the data are named in messages.
    pub data_label: String,
    /// Validation records: the alternation keeps the iterate that simulates them best.
    pub validation: Option<&'a Data>,
    /// How each validation record is named in messages (may be empty).
    pub validation_labels: Vec<String>,
    /// What the report says the validation is; `None`: its records and samples.
    pub validation_note: Option<String>,
    /// β, or `None` to select it on the first pass.
    pub beta: Option<f64>,
    /// σ, or `None` for the model file's (or a default from the data).
    pub sigma: Option<f64>,
    /// How `sigma` is named in messages.
    pub sigma_label: String,
    /// Select σ on the first pass too.
    pub sigma_auto: bool,
    /// The selection criterion (marginal likelihood or GCV).
    pub criterion: Criterion,
    /// Alternations at most (≥ 1).
    pub iterations: usize,
    /// Relative decrease of the cost below which the alternation stops (≥ 0).
    pub tolerance: f64,
    /// Samples of each validation record left out of its score.
    pub settle: usize,
    /// Initial state and posterior of the identifications (their β is the one chosen).
    pub identify: IdentifySettings,
    /// Reports the alternations.
    pub progress: Progress,
    /// Reports the first pass's selection trials.
    pub selection_progress: Progress,
}

/// What a refinement produced.
pub struct RefineOutcome {
    /// The refinement: its iterations, the kept iterate, G, the identification.
    pub refinement: Refinement,
    /// The refined model file: the new G, the width used, written as `[linear]`.
    pub refined: ModelFile,
    /// What was recognised when the model file was an `[lft]`.
    pub recognised: Option<String>,
    /// The identification settings with the β used.
    pub settings: IdentifySettings,
    /// The fitted model as stored.
    pub estimate: Estimate,
    /// report.json (its `selection` and `refinement` filled).
    pub report: Report,
}

/// An `[lft]` model file as the `[linear]` one it is: the structure and G that its one map's
/// declared location puts the map around, the block reading z 0 and writing w 0. Returns the
/// file, its `[linear]` section and a sentence saying what was recognised.
///
/// # Errors
/// [`WorkflowError::Request`] for a model with other than one map, a map of several inputs,
/// or a location that is none of the structures.
pub fn as_linear(mf: &ModelFile, label: &str) -> Result<(ModelFile, LinearSpec, String)> {
    let request = |m: String| WorkflowError::Request(m);
    let [block] = mf.blocks.as_slice() else {
        return Err(request(format!(
            "`{label}` has {} maps; refinement of an [lft] model needs exactly one",
            mf.blocks.len()
        )));
    };
    let [z] = block.inputs.as_slice() else {
        return Err(request(format!(
            "the map `{}` of `{label}` reads {} z channels; refinement re-estimates G around a \
             map of one input",
            block.name,
            block.inputs.len()
        )));
    };
    let (structure, g) = LinearStructure::from_lft(&block.name, &mf.lft, *z, block.output)
        .map_err(|e| {
            request(format!(
                "`{label}` cannot be refined: {}",
                e.to_string()
                    .trim_start_matches("invalid model structure: ")
            ))
        })?;
    let spec = LinearSpec {
        structure: Some(structure.site()),
        model: g,
        separate_numerator: structure.separate_numerator(),
    };
    let mut out = mf.clone();
    out.lft = spec.lft()?;
    out.linear = Some(spec.clone());
    out.signals.z = None;
    out.blocks[0].inputs = vec![0];
    out.blocks[0].output = 0;
    out.discover = None;
    let note = format!(
        "the [lft] location of `{}` (z {z}, w {}) is {}; model.toml is written as [linear]",
        block.name,
        block.output,
        structure.describe()
    );
    Ok((out, spec, note))
}

/// The structure of a model file that refinement works on: the file (as `[linear]`), its
/// `[linear]` section, the structure around its one map, and what was recognised when it was an
/// `[lft]`. [`refine_model_file`] starts with it; a front end may call it before it reads any
/// data. `label` names the file in messages.
///
/// # Errors
/// [`WorkflowError::Request`] for a model without exactly one map at one of the structures.
pub fn refinable(
    model: &ModelFile,
    label: &str,
) -> Result<(ModelFile, LinearSpec, LinearStructure, Option<String>)> {
    let request = |m: String| WorkflowError::Request(m);
    let (mf, spec, recognised) = match model.linear.clone() {
        Some(spec) => (model.clone(), spec, None),
        None => {
            let (mf, spec, note) = as_linear(model, label)?;
            (mf, spec, Some(note))
        }
    };
    if spec.structure.is_none() {
        return Err(request(format!(
            "`{label}` has structure = \"lti\", a linear model without a map; refinement \
             re-estimates G around a map (structure = \"output-feedback\", \"rate-feedback\", \
             \"input\" or \"output\")"
        )));
    }
    if mf.blocks.len() != 1 {
        return Err(request(format!(
            "`{label}` has {} maps; refinement needs a structure with exactly one",
            mf.blocks.len()
        )));
    }
    let structure = spec.structure(&mf.blocks[0].name).ok_or_else(|| {
        request(format!(
            "structure = \"{}\" has no map to refine",
            spec.structure_name()
        ))
    })?;
    Ok((mf, spec, structure, recognised))
}

/// The checks of a request's numbers.
fn check_numbers(req: &RefineRequest<'_>) -> Result<()> {
    let request = |m: String| WorkflowError::Request(m);
    let invalid = |option: &'static str, value: String, rule: String| {
        Err(WorkflowError::InvalidOption {
            option,
            value,
            rule,
        })
    };
    if req.iterations == 0 {
        return invalid("iterations", "0".into(), "it must be at least 1".into());
    }
    if !(req.tolerance.is_finite() && req.tolerance >= 0.0) {
        return invalid(
            "tolerance",
            req.tolerance.to_string(),
            "it must be a finite number ≥ 0".into(),
        );
    }
    if let Some(s) = req.sigma
        && !(s.is_finite() && s > 0.0)
    {
        return Err(request(format!(
            "invalid {} {s}: it must be a finite number greater than zero",
            req.sigma_label
        )));
    }
    if let Some(b) = req.beta {
        crate::options::beta(b)?;
    }
    if let Some(v) = req.validation {
        for (i, r) in v.records().iter().enumerate() {
            if req.settle >= r.len() {
                let named = req
                    .validation_labels
                    .get(i)
                    .map(|l| format!(" (`{l}`)"))
                    .unwrap_or_default();
                return invalid(
                    "settle",
                    req.settle.to_string(),
                    format!(
                        "it is not less than the {} samples of validation record {}{named}",
                        r.len(),
                        i + 1
                    ),
                );
            }
        }
    }
    Ok(())
}

/// The refined model file: the new G and the width actually used.
fn refined_file(mf: &ModelFile, spec: &LinearSpec, r: &Refinement) -> Result<ModelFile> {
    let mut refined = mf.clone();
    let mut lin = spec.clone();
    lin.model = r.linear.clone();
    refined.lft = lin.lft()?;
    refined.linear = Some(lin);
    let width = r.model.blocks()[0].dispersion.width();
    refined.blocks[0].dispersion = refined.blocks[0].dispersion.with_sigma(width);
    refined.path = None;
    Ok(refined)
}

/// Runs the refine workflow (see the module documentation).
///
/// # Errors
/// The checks of the request (see [`as_linear`] and the messages), a map input that does not
/// vary, an absurd σ, and the errors of the refinement.
pub fn refine_model_file(req: &RefineRequest<'_>) -> Result<RefineOutcome> {
    let (mf, spec, structure, recognised) = refinable(req.model, &req.model_label)?;
    check_numbers(req)?;
    mf.check_excitation(req.data, &req.data_label)?;
    if let Some(s) = req.sigma {
        mf.check_sigma(s, req.data, &req.sigma_label)?;
    }
    let model = crate::identify::core_model(&mf, req.sigma, req.data)?;
    let identify = req.identify.with_beta(req.beta.unwrap_or(0.01))?;
    let selection = if req.beta.is_none() || req.sigma_auto {
        Some(
            SelectionSettings::builder()
                .criterion(req.criterion)
                .tune_beta(req.beta.is_none())
                .tune_sigma(req.sigma_auto)
                .progress(req.selection_progress.clone())
                .build()?,
        )
    } else {
        None
    };
    let mut oe = OeSettings::builder();
    if let Some(ts) = spec.model.sample_time {
        oe = oe.sample_time(ts);
    }
    let settings = RefineSettings::builder()
        .max_iterations(req.iterations)
        .tolerance(req.tolerance)
        .identify(identify.clone())
        .selection(selection)
        .oe(oe.build().map_err(structid_core::Error::from)?)
        .settle(req.settle)
        .progress(req.progress.clone())
        .build()?;
    let r = refine(
        &structure,
        &spec.model,
        model.blocks()[0].dispersion.clone(),
        req.data,
        req.validation,
        &settings,
    )?;
    let refined = refined_file(&mf, &spec, &r)?;
    let chosen = identify.with_beta(r.beta)?;
    let id = &r.identification;
    let mut report = Report::new(&refined, id, &chosen, None)?;
    report.selection = r.selection.as_ref().map(SelectionReport::new);
    report.refinement = Some(RefinementReport {
        structure: structure.describe(),
        validation: req.validation_note.clone().or_else(|| {
            req.validation.map(|v| match v.record_count() {
                1 => format!("a record of {} samples", v.len()),
                n => format!("{n} records of {} samples in all", v.len()),
            })
        }),
        settle: req.settle,
        iterations: r.iterations.clone(),
        best: r.best,
        stop_reason: r.stop_reason.clone(),
        beta: r.beta,
        seconds: r.seconds,
    });
    let estimate = Estimate::from_identification(&r.model, id, req.data, &chosen)?;
    let provenance = Provenance {
        workflow: "refine".into(),
        ..estimate.provenance().clone()
    };
    let estimate = estimate
        .with_provenance(provenance)
        .with_signal_names(SignalNames {
            u: refined.signals.u.clone(),
            y: refined.signals.y.clone(),
        })?;
    Ok(RefineOutcome {
        refinement: r,
        refined,
        recognised,
        settings: chosen,
        estimate,
        report,
    })
}

//! Refinement of an uncertain linear part: alternate between identifying the map with G fixed
//! and re-estimating G (output error) with the map fixed, as `structid refine`.

use numpy::PyReadonlyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_core::estimate::{Estimate, Provenance, SignalNames};
use structid_core::refine::{RefineSettings, refine};
use structid_core::selection::{Criterion, SelectionSettings};
use structid_core::{Data, IdentifySettings};
use structid_io::{ModelFile, RefinementReport, Report};
use structid_linear::OeSettings;

use crate::convert::{self, error, invalid};
use crate::identify::{Outcome, map_values, named_columns};
use crate::model::Model;

/// What `refine` is asked to do.
struct Request {
    beta: Option<f64>,
    sigma: Option<f64>,
    sigma_auto: bool,
    selection: String,
    iterations: usize,
    tolerance: f64,
    settle: usize,
    initial_state: String,
    bands: bool,
}

/// One or several records (`Data::from_records`) from named columns; `what` names them in
/// messages.
/// A record as named columns, copied out of numpy.
type Named = Vec<(String, Vec<f64>)>;

fn records(mf: &ModelFile, named: Vec<Named>, what: &str) -> PyResult<Data> {
    let mut data = named
        .into_iter()
        .map(|n| convert::record(mf, n))
        .collect::<PyResult<Vec<Data>>>()?;
    match data.len() {
        0 => Err(invalid(format!("no {what} record was given"))),
        1 => Ok(data.pop().expect("one record")),
        _ => Data::from_records(data).map_err(error),
    }
}

fn run(
    model: &Model,
    named: Vec<Named>,
    validation: Option<Vec<Named>>,
    r: &Request,
) -> PyResult<(Outcome, ModelFile)> {
    let mf = &model.file;
    let spec = mf.linear.clone().ok_or_else(|| {
        invalid(
            "refinement needs a model with a [linear] structure (Model.hammerstein, \
             Model.wiener, Model.output_feedback, Model.rate_feedback or a file with [linear])",
        )
    })?;
    if mf.blocks.len() != 1 {
        return Err(invalid(format!(
            "the model has {} maps; refinement needs a structure with exactly one",
            mf.blocks.len()
        )));
    }
    let block = mf.blocks[0].name.clone();
    let structure = spec.structure(&block).ok_or_else(|| {
        invalid(format!(
            "structure = \"{}\" has no map to refine",
            spec.structure_name()
        ))
    })?;
    if r.iterations == 0 {
        return Err(invalid("iterations must be at least 1"));
    }
    if !(r.tolerance.is_finite() && r.tolerance >= 0.0) {
        return Err(invalid(format!(
            "invalid tolerance {}: it must be a finite number ≥ 0",
            r.tolerance
        )));
    }
    if let Some(s) = r.sigma
        && !(s.is_finite() && s > 0.0)
    {
        return Err(invalid(format!(
            "invalid sigma {s}: it must be a finite number greater than zero"
        )));
    }
    let beta = match r.beta {
        Some(b) if !(b.is_finite() && b > 0.0) => {
            return Err(invalid(format!(
                "invalid beta {b}: it must be a finite number greater than zero"
            )));
        }
        Some(b) => b,
        None => 0.01,
    };
    let data: Data = records(mf, named, "estimation")?;
    let validation = validation
        .map(|v| records(mf, v, "validation"))
        .transpose()?;
    if let Some(v) = &validation {
        // Every validation record is scored after its settling samples.
        let several = v.record_count() > 1;
        for (i, rec) in v.records().iter().enumerate() {
            if r.settle >= rec.len() {
                return Err(invalid(format!(
                    "settle {} is not less than the {} samples of the validation record{}",
                    r.settle,
                    rec.len(),
                    if several {
                        format!(" {}", i + 1)
                    } else {
                        String::new()
                    }
                )));
            }
        }
    }
    // The checks of `structid refine`: a map input that does not vary, an absurd σ.
    mf.check_excitation(&data, "the data").map_err(error)?;
    if let Some(s) = r.sigma {
        mf.check_sigma(s, &data, "sigma").map_err(error)?;
    }
    let core = structid_workflow::core_model(mf, r.sigma, &data).map_err(error)?;
    let identify_settings = IdentifySettings::builder()
        .beta(beta)
        .initial_state(convert::initial_state(&r.initial_state)?)
        .posterior(r.bands)
        .build()
        .map_err(error)?;
    let selection = if r.beta.is_none() || r.sigma_auto {
        Some(
            SelectionSettings::builder()
                .criterion(match r.selection.as_str() {
                    "ml" => Criterion::MarginalLikelihood,
                    "gcv" => Criterion::Gcv,
                    other => {
                        return Err(invalid(format!(
                            "selection `{other}` for refinement is neither ml nor gcv"
                        )));
                    }
                })
                .tune_beta(r.beta.is_none())
                .tune_sigma(r.sigma_auto)
                .build()
                .map_err(error)?,
        )
    } else {
        None
    };
    let mut oe = OeSettings::builder();
    if let Some(ts) = spec.model.sample_time {
        oe = oe.sample_time(ts);
    }
    let settings = RefineSettings::builder()
        .max_iterations(r.iterations)
        .tolerance(r.tolerance)
        .identify(identify_settings.clone())
        .selection(selection)
        .oe(oe.build().map_err(error)?)
        .settle(r.settle)
        .build()
        .map_err(error)?;
    let dispersion = core.blocks()[0].dispersion.clone();
    let result = refine(
        &structure,
        &spec.model,
        dispersion,
        &data,
        validation.as_ref(),
        &settings,
    )
    .map_err(error)?;

    // The refined model file: the new linear part, the width actually used.
    let mut refined = mf.clone();
    let mut lin = spec.clone();
    lin.model = result.linear.clone();
    refined.lft = lin.lft().map_err(error)?;
    refined.linear = Some(lin);
    let width = result.model.blocks()[0].dispersion.width();
    refined.blocks[0].dispersion = refined.blocks[0].dispersion.with_sigma(width);
    refined.path = None;

    let id = result.identification;
    let chosen = identify_settings.with_beta(result.beta).map_err(error)?;
    let mut report = Report::new(&refined, &id, &chosen, None).map_err(error)?;
    report.selection = result
        .selection
        .as_ref()
        .map(structid_io::SelectionReport::new);
    report.refinement = Some(RefinementReport {
        structure: structure.describe(),
        validation: validation.as_ref().map(|v| match v.record_count() {
            1 => format!("a record of {} samples", v.len()),
            n => format!("{n} records of {} samples in all", v.len()),
        }),
        settle: r.settle,
        iterations: result.iterations,
        best: result.best,
        stop_reason: result.stop_reason,
        beta: result.beta,
        seconds: result.seconds,
    });
    let estimate =
        Estimate::from_identification(&result.model, &id, &data, &chosen).map_err(error)?;
    let provenance = Provenance {
        workflow: "refine".into(),
        ..estimate.provenance().clone()
    };
    let estimate = estimate
        .with_provenance(provenance)
        .with_signal_names(SignalNames {
            u: refined.signals.u.clone(),
            y: refined.signals.y.clone(),
        })
        .map_err(error)?;
    Ok((
        Outcome {
            maps: map_values(&id)?,
            report: report.to_json_string().map_err(error)?,
            beta: result.beta,
            sigma: width,
            widths: Vec::new(),
            id,
            estimate,
        },
        refined,
    ))
}

/// A record as named numpy columns.
type Columns<'py> = Vec<(String, PyReadonlyArray1<'py, f64>)>;

/// Refines the linear part of a one-map structure (see `structid.refine`).
#[pyfunction]
#[pyo3(signature = (model, records, validation=None, beta=None, sigma=None, sigma_auto=false, selection="ml", iterations=10, tolerance=1e-3, settle=0, initial_state="zero", bands=true))]
pub fn refine_columns<'py>(
    py: Python<'py>,
    model: &Model,
    records: Vec<Columns<'py>>,
    validation: Option<Vec<Columns<'py>>>,
    beta: Option<f64>,
    sigma: Option<f64>,
    sigma_auto: bool,
    selection: &str,
    iterations: usize,
    tolerance: f64,
    settle: usize,
    initial_state: &str,
    bands: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let request = Request {
        beta,
        sigma,
        sigma_auto,
        selection: selection.into(),
        iterations,
        tolerance,
        settle,
        initial_state: initial_state.into(),
        bands,
    };
    // Every estimation record, then every validation record: each restarts from rest (or
    // from its own initial state).
    let named: Vec<_> = records.iter().map(|r| named_columns(r)).collect();
    let validation = validation
        .as_ref()
        .map(|v| v.iter().map(|r| named_columns(r)).collect());
    let model = model.clone();
    let (outcome, refined) = py.detach(move || run(&model, named, validation, &request))?;
    let d = outcome.into_dict(py, Vec::new())?;
    d.set_item("model", Model { file: refined })?;
    Ok(d)
}

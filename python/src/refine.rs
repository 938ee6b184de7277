//! Refinement of an uncertain linear part: alternate between identifying the map with G fixed
//! and re-estimating G (output error) with the map fixed, as `structid refine`.

use numpy::PyReadonlyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_core::progress::Progress;
use structid_core::selection::Criterion;
use structid_core::{Data, IdentifySettings};
use structid_io::ModelFile;
use structid_workflow::{RefineRequest, refine_model_file};

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
    let criterion = match r.selection.as_str() {
        "ml" => Criterion::MarginalLikelihood,
        "gcv" => Criterion::Gcv,
        other => {
            return Err(invalid(format!(
                "selection `{other}` for refinement is neither ml nor gcv"
            )));
        }
    };
    let data: Data = records(mf, named, "estimation")?;
    let validation = validation
        .map(|v| records(mf, v, "validation"))
        .transpose()?;
    let identify = IdentifySettings::builder()
        .initial_state(convert::initial_state(&r.initial_state)?)
        .posterior(r.bands)
        .build()
        .map_err(error)?;
    let out = refine_model_file(&RefineRequest {
        model: mf,
        model_label: "the model".into(),
        data: &data,
        data_label: "the data".into(),
        validation: validation.as_ref(),
        validation_labels: Vec::new(),
        validation_note: None,
        beta: r.beta,
        sigma: r.sigma,
        sigma_label: "sigma".into(),
        sigma_auto: r.sigma_auto,
        criterion,
        iterations: r.iterations,
        tolerance: r.tolerance,
        settle: r.settle,
        identify,
        progress: Progress::none(),
        selection_progress: Progress::none(),
    })
    .map_err(error)?;
    let width = out.refinement.model.blocks()[0].dispersion.width();
    let id = out.refinement.identification;
    Ok((
        Outcome {
            maps: map_values(&id)?,
            report: out.report.to_json_string().map_err(error)?,
            beta: out.refinement.beta,
            sigma: width,
            widths: Vec::new(),
            id,
            estimate: out.estimate,
        },
        out.refined,
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

//! The joint fit of a whole model by its simulation error, as `structid refine --joint`: the
//! arrays are converted and the workflow crate does the rest.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_io::{ModelFile, OutputGuard};
use structid_joint::JointSettings;
use structid_workflow::{BetaChoice, JointRequest, JointWorkflowSettings, refine_joint, write_joint_outputs};

use crate::convert::{self, error, invalid};
use crate::model::Model;

type Named = Vec<(String, Vec<f64>)>;

fn records(mf: &ModelFile, named: Vec<Named>, what: &str) -> PyResult<structid_core::Data> {
    let data = named
        .into_iter()
        .map(|n| convert::record(mf, n))
        .collect::<PyResult<Vec<_>>>()?;
    if data.is_empty() {
        return Err(invalid(format!("no {what} record was given")));
    }
    structid_core::Data::from_records(data).map_err(error)
}

/// Fits `model` as a whole by its simulation error (see `structid refine --joint`). Returns a
/// dict with the fitted `model`, `beta`, `trials`, `cost`, `initial_cost`, `rms`,
/// `initial_states`, `free` (each free entry with its value) and `stages`; writes the output
/// directory `out` when given.
#[pyfunction]
#[pyo3(signature = (model, columns, validation=None, beta=None, free=Vec::new(), centres=15, segment_length=None, iterations=100, initial_state="zero", out=None))]
#[allow(clippy::too_many_arguments)]
pub fn refine_joint_columns<'py>(
    py: Python<'py>,
    model: &Model,
    columns: Vec<Named>,
    validation: Option<Vec<Named>>,
    beta: Option<f64>,
    free: Vec<String>,
    centres: usize,
    segment_length: Option<usize>,
    iterations: usize,
    initial_state: &str,
    out: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let mf = model.file.clone();
    let data = records(&mf, columns, "estimation")?;
    let validation = validation.map(|v| records(&mf, v, "validation")).transpose()?;
    let beta = BetaChoice::from_options(beta, validation).map_err(error)?;
    let estimate_x0 = match initial_state {
        "estimate" => true,
        "zero" => false,
        other => return Err(invalid(format!("initial_state `{other}` is neither \"zero\" nor \"estimate\""))),
    };
    let mut fit = JointSettings::builder().max_iterations(iterations).estimate_initial_state(estimate_x0);
    if let Some(l) = segment_length {
        fit = fit.segment_length(l);
    }
    let settings = JointWorkflowSettings {
        beta,
        centres,
        free,
        fit: fit.build().map_err(error)?,
        ..JointWorkflowSettings::default()
    };
    let outcome = py
        .detach(|| refine_joint(&JointRequest { model: &mf, data: &data, settings }))
        .map_err(error)?;
    if let Some(dir) = &out {
        write_joint_outputs(&outcome, dir, &OutputGuard::new()).map_err(error)?;
    }
    let d = PyDict::new(py);
    d.set_item("model", Model::from_file_value(outcome.model_file.clone())?)?;
    d.set_item("beta", outcome.beta)?;
    let trials: Vec<(f64, Vec<f64>)> = outcome.trials.iter().map(|t| (t.beta, t.validation_rms.clone())).collect();
    d.set_item("trials", trials)?;
    d.set_item("cost", outcome.fit.cost)?;
    d.set_item("initial_cost", outcome.fit.initial_cost)?;
    d.set_item("rms", outcome.fit.rms.clone())?;
    d.set_item("initial_states", outcome.fit.initial_states.clone())?;
    let free: Vec<(String, usize, usize, f64)> = outcome
        .fit
        .model
        .free_entries()
        .iter()
        .zip(outcome.fit.model.parameters())
        .map(|(e, v)| (format!("{:?}", e.matrix), e.row, e.col, v))
        .collect();
    d.set_item("free", free)?;
    let stages: Vec<(String, usize, Vec<f64>, String)> = outcome
        .fit
        .stages
        .iter()
        .map(|s| (s.name.to_string(), s.segments, s.costs.clone(), format!("{:?}", s.status)))
        .collect();
    d.set_item("stages", stages)?;
    Ok(d)
}

//! The joint fit of a whole model by its simulation error, as `structid refine --joint`: the
//! arrays are converted and the workflow crate does the rest.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_core::validation::Windows;
use structid_io::{ModelFile, OutputGuard};
use structid_workflow::{
    BetaChoice, FitOptions, JointRequest, JointWorkflowSettings, refine_joint, write_joint_outputs,
};

use crate::convert::{self, error, invalid};
use crate::model::Model;

type Named = Vec<(String, Vec<f64>)>;

/// Whether the `initial_state` argument (`"zero"` or `"estimate"`) asks for x₀ to be estimated.
fn estimate_initial_state(initial_state: &str) -> PyResult<bool> {
    match initial_state {
        "estimate" => Ok(true),
        "zero" => Ok(false),
        other => Err(invalid(format!(
            "initial_state `{other}` is neither \"zero\" nor \"estimate\""
        ))),
    }
}

/// The joint fit's options from the Python arguments; `windows` is (LENGTH, INIT).
fn fit_options(
    iterations: usize,
    estimate_x0: bool,
    segment_length: Option<usize>,
    windows: Option<(usize, usize)>,
) -> PyResult<FitOptions> {
    let windows = windows
        .map(|(length, init)| Windows::new(length, init))
        .transpose()
        .map_err(error)?;
    Ok(FitOptions {
        iterations,
        estimate_initial_state: estimate_x0,
        segment_length,
        windows,
    })
}

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
#[pyo3(signature = (model, columns, validation=None, beta=None, free=Vec::new(), centres=15, segment_length=None, iterations=100, initial_state="zero", out=None, windows=None))]
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
    windows: Option<(usize, usize)>,
) -> PyResult<Bound<'py, PyDict>> {
    let mf = model.file.clone();
    let data = records(&mf, columns, "estimation")?;
    let validation = validation
        .map(|v| records(&mf, v, "validation"))
        .transpose()?;
    let beta = BetaChoice::from_options(beta, validation).map_err(error)?;
    let estimate_x0 = estimate_initial_state(initial_state)?;
    let fit = fit_options(iterations, estimate_x0, segment_length, windows)?;
    let settings = JointWorkflowSettings {
        beta,
        centres,
        free,
        fit: fit.settings().map_err(error)?,
        ..JointWorkflowSettings::default()
    };
    let outcome = py
        .detach(|| {
            refine_joint(&JointRequest {
                model: &mf,
                data: &data,
                settings,
            })
        })
        .map_err(error)?;
    if let Some(dir) = &out {
        write_joint_outputs(&outcome, dir, &OutputGuard::new()).map_err(error)?;
    }
    let d = PyDict::new(py);
    joint_items(&d, &outcome)?;
    Ok(d)
}

/// The items both joint workflows return: the fitted `model`, `beta`, `trials`, `cost`,
/// `initial_cost`, `rms`, `initial_states`, `free` and `stages`.
fn joint_items(d: &Bound<'_, PyDict>, outcome: &structid_workflow::JointOutcome) -> PyResult<()> {
    d.set_item("model", Model::from_file_value(outcome.model_file.clone())?)?;
    d.set_item("beta", outcome.beta)?;
    let trials: Vec<(f64, Vec<f64>)> = outcome
        .trials
        .iter()
        .map(|t| (t.beta, t.validation_rms.clone()))
        .collect();
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
        .map(|s| {
            (
                s.name.to_string(),
                s.segments,
                s.costs.clone(),
                format!("{:?}", s.status),
            )
        })
        .collect();
    d.set_item("stages", stages)?;
    Ok(())
}

fn wh_records(records: Vec<(Vec<f64>, Vec<f64>)>, what: &str) -> PyResult<structid_core::Data> {
    let data = records
        .into_iter()
        .map(|(u, y)| {
            let n = u.len();
            let u = structid_core::Signal::new(1, u).map_err(error)?;
            let y = structid_core::Signal::new(1, y).map_err(error)?;
            if y.len() != n {
                return Err(invalid(format!(
                    "{what}: u has {n} samples and y {}",
                    y.len()
                )));
            }
            structid_core::Data::new(u, y).map_err(error)
        })
        .collect::<PyResult<Vec<_>>>()?;
    if data.is_empty() {
        return Err(invalid(format!("no {what} record was given")));
    }
    structid_core::Data::from_records(data).map_err(error)
}

/// One division of the best linear approximation between the blocks, for Python: the front
/// block's numerator and denominator, the back block's, and its validation RMS.
type Division = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, f64);

/// A Wiener–Hammerstein model with both blocks unknown (see `structid wiener-hammerstein`).
/// Records are (u, y) pairs of 1-D arrays. Returns a dict with the fitted `model`, `bla`
/// (num, den), `divisions` (front num/den, back num/den, rms; best first), `beta`, `trials`,
/// `cost`, `initial_cost`, `rms`, `initial_states`, `free` and `stages`; writes `out` when given.
#[pyfunction]
#[pyo3(signature = (records, orders, validation=None, beta=None, centres=15, segment_length=None, iterations=100, initial_state="zero", out=None, structure="wiener-hammerstein", windows=None))]
#[allow(clippy::too_many_arguments)]
pub fn wiener_hammerstein_records<'py>(
    py: Python<'py>,
    records: Vec<(Vec<f64>, Vec<f64>)>,
    orders: (usize, usize, usize),
    validation: Option<Vec<(Vec<f64>, Vec<f64>)>>,
    beta: Option<f64>,
    centres: usize,
    segment_length: Option<usize>,
    iterations: usize,
    initial_state: &str,
    out: Option<PathBuf>,
    structure: &str,
    windows: Option<(usize, usize)>,
) -> PyResult<Bound<'py, PyDict>> {
    use structid_joint::WienerHammersteinSettings;
    use structid_workflow::BlockStructure;
    let structure = match structure {
        "wiener-hammerstein" => BlockStructure::WienerHammerstein,
        "hammerstein-wiener" => BlockStructure::HammersteinWiener,
        other => {
            return Err(invalid(format!(
                "structure `{other}` is neither \"wiener-hammerstein\" nor \"hammerstein-wiener\""
            )));
        }
    };
    use structid_workflow::{
        WienerHammersteinRequest, wiener_hammerstein, write_wiener_hammerstein_outputs,
    };
    let data = wh_records(records, "estimation")?;
    let validation = validation
        .map(|v| wh_records(v, "validation"))
        .transpose()?;
    let estimate_x0 = estimate_initial_state(initial_state)?;
    let start = WienerHammersteinSettings::builder()
        .centres(centres)
        .build()
        .map_err(error)?;
    let fit = fit_options(iterations, estimate_x0, segment_length, windows)?;
    let req = WienerHammersteinRequest {
        structure,
        data: &data,
        names: structid_io::SignalNames {
            u: vec!["u".into()],
            y: vec!["y".into()],
            z: None,
        },
        orders: [orders.0, orders.1, orders.2],
        beta: BetaChoice::from_options_or(beta, validation, start.beta()),
        start,
        fit: fit.settings().map_err(error)?,
    };
    let outcome = py.detach(|| wiener_hammerstein(&req)).map_err(error)?;
    if let Some(dir) = &out {
        write_wiener_hammerstein_outputs(&outcome, dir, &OutputGuard::new()).map_err(error)?;
    }
    let d = PyDict::new(py);
    joint_items(&d, &outcome.joint)?;
    d.set_item("bla", (outcome.bla.num[0].clone(), outcome.bla.den.clone()))?;
    let divisions: Vec<Division> = outcome
        .divisions
        .iter()
        .map(|s| {
            (
                s.split.front.num[0].clone(),
                s.split.front.den.clone(),
                s.split.back.num[0].clone(),
                s.split.back.den.clone(),
                s.rms,
            )
        })
        .collect();
    d.set_item("divisions", divisions)?;
    Ok(d)
}

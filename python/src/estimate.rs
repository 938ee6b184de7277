//! The fitted model: simulate, predict, validate, evaluate its maps, and its stored forms (a
//! JSON document for pickling, the tool's result directory for files).

use std::path::PathBuf;
use std::sync::Arc;

use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_core::estimate::{EstimateData, PredictionSettings};
use structid_core::validation::{ValidationReport, ValidationSettings};
use structid_core::{Data, Estimate, Identification};
use structid_io::{OutputGuard, estimate_json, read_estimate};

use crate::convert::{self, block_dict, error, invalid};
use crate::user_kernel::{UserDispersion, detach};

/// A fitted model: the linear block with every estimated map, as `estimate.json` stores it.
/// It simulates, predicts and validates on its own; a fresh fit also keeps the posterior for
/// bands at any point (a pickled or loaded one has none).
#[pyclass(module = "structid._structid", name = "Estimate", frozen)]
pub struct Fitted {
    estimate: Estimate,
    identification: Option<Arc<Identification>>,
    /// The Python kernels and feature maps it is built on (pickled with it).
    kernels: Vec<Py<PyAny>>,
}

impl Fitted {
    /// An estimate, with the identification that produced it when at hand.
    pub fn new(estimate: Estimate, identification: Option<Arc<Identification>>) -> Self {
        Self {
            estimate,
            identification,
            kernels: Vec::new(),
        }
    }

    /// The same, built on the Python kernels and feature maps `kernels`.
    pub fn with_kernels(mut self, kernels: Vec<Py<PyAny>>) -> Self {
        self.kernels = kernels;
        self
    }

    /// An estimate from its stored form with the user kernels `kernels` (`Kernel` and
    /// `FeatureMap` objects).
    fn with_registry(data: EstimateData, kernels: Vec<Bound<'_, PyAny>>) -> PyResult<Self> {
        let tagged: Vec<((), Bound<'_, PyAny>)> = kernels.iter().map(|k| ((), k.clone())).collect();
        let user: Vec<UserDispersion> = UserDispersion::extract_all(&tagged)?
            .into_iter()
            .map(|(_, u)| u)
            .collect();
        let estimate = Estimate::from_data_with_kernels(data, &UserDispersion::registry(&user))
            .map_err(error)?;
        Ok(
            Self::new(estimate, None)
                .with_kernels(kernels.into_iter().map(Bound::unbind).collect()),
        )
    }

    fn block_index(&self, block: &str) -> PyResult<usize> {
        self.estimate
            .blocks()
            .iter()
            .position(|b| b.name == block)
            .ok_or_else(|| {
                let names: Vec<_> = self.estimate.blocks().iter().map(|b| &b.name).collect();
                invalid(format!(
                    "the estimate has no block `{block}` (blocks: {names:?})"
                ))
            })
    }

    fn record(
        &self,
        u: &PyReadonlyArray2<'_, f64>,
        y: &PyReadonlyArray2<'_, f64>,
    ) -> PyResult<Data> {
        let u = convert::signal(u, "u")?;
        let y = convert::signal(y, "y")?;
        if u.len() != y.len() {
            return Err(invalid(format!(
                "u has {} samples but y has {}",
                u.len(),
                y.len()
            )));
        }
        Data::new(u, y).map_err(error)
    }
}

/// What pickling stores: the constructor and its arguments (the JSON document and the kernels).
type Reduced = (Py<PyAny>, (String, Vec<Py<PyAny>>));

#[pymethods]
impl Fitted {
    /// The estimate from its JSON document (`to_json`, or a tool's estimate.json text), with
    /// the `Kernel` and `FeatureMap` objects it was made with, by their names.
    #[staticmethod]
    #[pyo3(signature = (text, kernels=Vec::new()))]
    fn from_json(text: &str, kernels: Vec<Bound<'_, PyAny>>) -> PyResult<Self> {
        let data: EstimateData = serde_json::from_str(text)
            .map_err(|e| invalid(format!("not an estimate document: {e}")))?;
        Self::with_registry(data, kernels)
    }

    /// Reads an estimate file (estimate.json of `structid identify`, `refine`, `discover`),
    /// with the `Kernel` and `FeatureMap` objects it was made with.
    #[staticmethod]
    #[pyo3(signature = (path, kernels=Vec::new()))]
    fn from_file(path: PathBuf, kernels: Vec<Bound<'_, PyAny>>) -> PyResult<Self> {
        if kernels.is_empty() {
            return Ok(Self::new(read_estimate(&path).map_err(error)?, None));
        }
        let text = std::fs::read_to_string(&path)
            .map_err(|e| invalid(format!("cannot read {}: {e}", path.display())))?;
        Self::from_json(&text, kernels)
    }

    /// The JSON document (what estimate.json holds); numbers read back bit for bit.
    fn to_json(&self) -> PyResult<String> {
        String::from_utf8(estimate_json(&self.estimate).map_err(error)?)
            .map_err(|e| invalid(e.to_string()))
    }

    fn __reduce__(&self, py: Python<'_>) -> PyResult<Reduced> {
        let from = py.get_type::<Self>().getattr("from_json")?.unbind();
        let kernels = self.kernels.iter().map(|k| k.clone_ref(py)).collect();
        Ok((from, (self.to_json()?, kernels)))
    }

    /// The blocks: name, z inputs, w output and dispersion.
    #[getter]
    fn blocks<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.estimate
            .blocks()
            .iter()
            .map(|b| {
                let d = block_dict(py, &b.name, &b.inputs, b.output)?;
                d.set_item("dispersion", &b.dispersion)?;
                Ok(d)
            })
            .collect()
    }

    /// How it was produced (workflow, settings, cost, solver, data fingerprint) as JSON.
    #[getter]
    fn provenance(&self) -> PyResult<String> {
        convert::json(self.estimate.provenance())
    }

    /// x̂₀ on the record it was fitted on, when estimated.
    #[getter]
    fn initial_state(&self) -> Option<Vec<f64>> {
        self.estimate.initial_state().map(<[f64]>::to_vec)
    }

    /// Whether bands can be computed (a fresh fit with a posterior).
    #[getter]
    fn has_posterior(&self) -> bool {
        self.identification
            .as_ref()
            .is_some_and(|id| id.posterior.is_some())
    }

    /// N̂ of `block` at `points` (N × p, one point per row).
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        block: &str,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
        let i = self.block_index(block)?;
        let points = convert::signal(&points, "points")?;
        let p = self.estimate.blocks()[i].inputs.len();
        if points.channels() != p {
            return Err(invalid(format!(
                "block `{block}` reads {p} input(s) but the points have {} column(s)",
                points.channels()
            )));
        }
        let estimate = self.estimate.clone();
        let values = detach(py, !self.kernels.is_empty(), move || {
            Ok(estimate.maps()[i].eval_many(&points))
        })?;
        Ok(convert::vector(py, values))
    }

    /// The posterior standard deviation of N̂ of `block` at `points` (the 95 % band is
    /// N̂ ± 1.96·std), or None without a posterior.
    fn band<'py>(
        &self,
        py: Python<'py>,
        block: &str,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Option<Bound<'py, numpy::PyArray1<f64>>>> {
        let i = self.block_index(block)?;
        let points = convert::signal(&points, "points")?;
        let Some(id) = &self.identification else {
            return Ok(None);
        };
        let id = Arc::clone(id);
        let std = detach(py, !self.kernels.is_empty(), move || {
            id.posterior_std(i, &points).map_err(error)
        })?;
        Ok(std.map(|s| convert::vector(py, s)))
    }

    /// y from u alone with the maps in the loop (e = 0), from x0 (zero when None).
    #[pyo3(signature = (u, x0=None))]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray2<'py, f64>,
        x0: Option<Vec<f64>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let u = convert::signal(&u, "u")?;
        let estimate = self.estimate.clone();
        let sim = detach(py, !self.kernels.is_empty(), move || {
            estimate.simulate(&u, x0.as_deref()).map_err(error)
        })?;
        let d = PyDict::new(py);
        d.set_item("y", convert::array(py, &sim.y))?;
        d.set_item("z", convert::array(py, &sim.z))?;
        d.set_item("w", convert::array(py, &sim.w))?;
        Ok(d)
    }

    /// ŷ(t|t−k), the k-step-ahead prediction on a record (as `structid predict`).
    #[pyo3(signature = (u, y, horizon=1, initial_state="zero", settle=0))]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray2<'py, f64>,
        y: PyReadonlyArray2<'py, f64>,
        horizon: usize,
        initial_state: &str,
        settle: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let data = self.record(&u, &y)?;
        let settings = PredictionSettings::builder()
            .horizon(horizon)
            .initial_state(convert::initial_state(initial_state)?)
            .settle(settle)
            .build()
            .map_err(error)?;
        let estimate = self.estimate.clone();
        let p = detach(py, !self.kernels.is_empty(), move || {
            estimate.predict(&data, &settings).map_err(error)
        })?;
        let d = PyDict::new(py);
        d.set_item("horizon", p.horizon)?;
        d.set_item("predicted", convert::array(py, &p.predicted))?;
        d.set_item("rms", p.rms)?;
        d.set_item("fit_percent", p.fit_percent)?;
        d.set_item("initial_state", p.initial_state)?;
        Ok(d)
    }

    /// Simulation and one-step prediction errors with their residual tests on a record (as
    /// `structid validate --estimate`).
    #[pyo3(signature = (u, y, initial_state="zero", max_lag=25, settle=0))]
    fn validate<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray2<'py, f64>,
        y: PyReadonlyArray2<'py, f64>,
        initial_state: &str,
        max_lag: usize,
        settle: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        if max_lag == 0 {
            return Err(invalid("max_lag must be at least 1"));
        }
        let data = self.record(&u, &y)?;
        if max_lag >= data.len() {
            return Err(invalid(format!(
                "max_lag {max_lag} must be less than the {} samples of the record",
                data.len()
            )));
        }
        let settings = validation_settings(initial_state, max_lag, settle)?;
        let estimate = self.estimate.clone();
        let r = detach(py, !self.kernels.is_empty(), move || {
            estimate.validate(&data, &settings).map_err(error)
        })?;
        report_dict(py, &r)
    }

    /// Each record of several (lists `us`, `ys`) validated on its own, and the simulation
    /// errors pooled over every record's scored samples (as `structid validate --data a
    /// --data b`).
    #[pyo3(signature = (us, ys, initial_state="zero", max_lag=25, settle=0))]
    fn validate_records<'py>(
        &self,
        py: Python<'py>,
        us: Vec<PyReadonlyArray2<'py, f64>>,
        ys: Vec<PyReadonlyArray2<'py, f64>>,
        initial_state: &str,
        max_lag: usize,
        settle: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        if us.len() != ys.len() || us.is_empty() {
            return Err(invalid(format!(
                "give one y per u and at least one record ({} u, {} y)",
                us.len(),
                ys.len()
            )));
        }
        let records = us
            .iter()
            .zip(&ys)
            .map(|(u, y)| self.record(u, y))
            .collect::<PyResult<Vec<Data>>>()?;
        let data = Data::from_records(records).map_err(error)?;
        let settings = validation_settings(initial_state, max_lag, settle)?;
        let estimate = self.estimate.clone();
        let r = detach(py, !self.kernels.is_empty(), move || {
            estimate.validate_records(&data, &settings).map_err(error)
        })?;
        let d = PyDict::new(py);
        let reports = r
            .records
            .iter()
            .map(|one| report_dict(py, one))
            .collect::<PyResult<Vec<_>>>()?;
        d.set_item("records", reports)?;
        d.set_item("rms", r.rms())?;
        d.set_item("fit_percent", r.fit_percent())?;
        d.set_item("samples", r.samples())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let names: Vec<_> = self.estimate.blocks().iter().map(|b| &b.name).collect();
        format!("Estimate(blocks={names:?})")
    }
}

/// The settings of `validate` from Python's arguments.
fn validation_settings(
    initial_state: &str,
    max_lag: usize,
    settle: usize,
) -> PyResult<ValidationSettings> {
    ValidationSettings::builder()
        .initial_state(convert::initial_state(initial_state)?)
        .max_lag(max_lag)
        .settle(settle)
        .build()
        .map_err(error)
}

/// A validation report as the keyword arguments of Python's `Validation`.
fn report_dict<'py>(py: Python<'py>, r: &ValidationReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("simulated", convert::array(py, &r.simulated))?;
    d.set_item("rms", r.rms.clone())?;
    d.set_item("fit_percent", r.fit_percent.clone())?;
    d.set_item("prediction_error", convert::array(py, &r.prediction_error))?;
    d.set_item("prediction_rms", r.prediction_rms.clone())?;
    d.set_item("whiteness_passes", r.whiteness_passes())?;
    d.set_item("input_correlation_passes", r.input_correlation_passes())?;
    d.set_item("whiteness", convert::json(&r.whiteness)?)?;
    d.set_item("input_correlation", convert::json(&r.input_correlation)?)?;
    d.set_item("initial_state", r.initial_state.clone())?;
    Ok(d)
}

/// Writes a result directory as `structid identify` does: estimate.json, estimate.csv (ŵ by
/// block name, then ê), report.json and, when given, model.toml; atomically, with the
/// directory's `.complete` list, so that the tool's `validate`, `predict` and `simulate`
/// read it.
#[pyfunction]
#[pyo3(signature = (directory, estimate, report, csv_names, csv_columns, model_toml=None))]
pub fn write_result(
    directory: PathBuf,
    estimate: &Fitted,
    report: &str,
    csv_names: Vec<String>,
    csv_columns: Vec<PyReadonlyArray1<'_, f64>>,
    model_toml: Option<&str>,
) -> PyResult<()> {
    let mut planned = vec!["estimate.json", "estimate.csv", "report.json"];
    if model_toml.is_some() {
        planned.push("model.toml");
    }
    let guard = OutputGuard::new();
    guard.check_out_dir(&directory, &planned).map_err(error)?;
    guard.begin_set(&directory, Some(&planned)).map_err(error)?;
    let bytes = estimate_json(&estimate.estimate).map_err(error)?;
    guard
        .write(&directory.join("estimate.json"), &bytes)
        .map_err(error)?;
    let columns: Vec<Vec<f64>> = csv_columns.iter().map(|c| c.as_array().to_vec()).collect();
    guard
        .write_csv(&directory.join("estimate.csv"), &csv_names, &columns)
        .map_err(error)?;
    if let Some(text) = model_toml {
        guard
            .write(&directory.join("model.toml"), text.as_bytes())
            .map_err(error)?;
    }
    guard
        .write(&directory.join("report.json"), report.as_bytes())
        .map_err(error)?;
    guard.finish_set(&directory, &planned).map_err(error)
}

/// Named columns of a data file: CSV (the tool's estimate.csv, a data file), MAT v5 or
/// NumPy `.npy`/`.npz`, with `vars` choosing and naming them (`u=vir,y=qm`, `y=data#1`, as
/// the command-line tool's `--vars`).
#[pyfunction]
#[pyo3(signature = (path, vars=None))]
pub fn read_columns<'py>(
    py: Python<'py>,
    path: PathBuf,
    vars: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let vars: Option<structid_io::Vars> =
        vars.map(|v| v.parse())
            .transpose()
            .map_err(|e: structid_io::ArrayFileError| {
                invalid(format!("vars {v:?}: {e}", v = vars.unwrap_or_default()))
            })?;
    let table = structid_io::DataTable::read_vars(&path, vars.as_ref()).map_err(error)?;
    let d = PyDict::new(py);
    for (name, column) in table.names.into_iter().zip(table.columns) {
        d.set_item(name, convert::vector(py, column))?;
    }
    Ok(d)
}

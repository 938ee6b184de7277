//! Identification: fixed or automatically selected β and σ, every dispersion and solver, with
//! the results the command-line tool writes (ŵ, ê, maps on a grid with bands, report).

use std::sync::Arc;

use numpy::PyReadonlyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_core::progress::Progress;
use structid_core::selection::Criterion;
use structid_core::{Data, Estimate, Identification, IdentifySettings, Signal};
use structid_workflow::{IdentifyRequest, SolveOptions, identify_model_file};

use crate::convert::{self, error, invalid};
use crate::estimate::Fitted;
use crate::model::Model;
use crate::user_kernel::{UserDispersion, detach};

/// Points of the grid a one-input map is evaluated on (as in the tool's map_<block>.csv).
const GRID_1D: usize = 201;
/// Points per axis of the grid of a two-input map.
const GRID_2D: usize = 41;

/// What `identify` is asked to do, beyond the model and the record.
#[derive(Clone)]
pub struct Request {
    /// β, or `None` to select it.
    pub beta: Option<f64>,
    /// σ for every block, or `None` to keep the model's.
    pub sigma: Option<f64>,
    /// Select σ too.
    pub sigma_auto: bool,
    /// `ml`, `gcv`, `cv` or `validation`; `None`: marginal likelihood for quadratic
    /// dispersions, cross-validation otherwise.
    pub selection: Option<String>,
    /// Folds of cross-validation.
    pub folds: usize,
    /// Solver name.
    pub solver: String,
    /// `zero` or `estimate`.
    pub initial_state: String,
    /// Keep the posterior for bands.
    pub bands: bool,
    /// Tolerance of the iterative solvers.
    pub tolerance: Option<f64>,
    /// Iteration limit of the iterative solvers.
    pub max_iterations: Option<usize>,
    /// Memory budget in MiB.
    pub memory_limit_mib: Option<u64>,
    /// Python kernels and feature maps replacing the dispersion of one block (by name) or
    /// of every block (`None`).
    pub user: Vec<(Option<String>, UserDispersion)>,
}

/// The settings of a request, checked as the command-line tool checks its arguments.
fn settings(r: &Request) -> PyResult<IdentifySettings> {
    SolveOptions {
        beta: r.beta,
        bands: r.bands,
        initial_state: convert::initial_state(&r.initial_state)?,
        solver: convert::solver(&r.solver)?,
        tolerance: r.tolerance,
        max_iterations: r.max_iterations,
        memory_limit_mib: r.memory_limit_mib,
    }
    .settings()
    .map_err(error)
}

/// The criterion asked for; `None`: the workflow's default.
fn criterion(r: &Request) -> PyResult<Option<Criterion>> {
    Ok(match r.selection.as_deref() {
        Some("ml") => Some(Criterion::MarginalLikelihood),
        Some("gcv") => Some(Criterion::Gcv),
        Some("cv") => Some(Criterion::CrossValidation { folds: r.folds }),
        Some("validation") => Some(Criterion::Validation),
        Some(other) => {
            return Err(invalid(format!(
                "selection `{other}` is not one of ml, gcv, cv, validation"
            )));
        }
        None => None,
    })
}

/// Evenly spaced points from `lo` to `hi`.
fn linspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if n < 2 || hi <= lo {
        return vec![lo; n.max(1)];
    }
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
        .collect()
}

fn span(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
            (l.min(*x), h.max(*x))
        })
}

/// The points a block's map is shown on: 201 over the data range for one input, a 41 × 41
/// grid (first input fastest) for two, the data points for more.
pub fn grid(z: &Signal) -> Signal {
    match z.channels() {
        1 => {
            let (lo, hi) = span(&z.channel(0));
            let xs = linspace(lo, hi, GRID_1D);
            Signal::from_fn(xs.len(), 1, |k, _| xs[k])
        }
        2 => {
            let (x0, x1) = span(&z.channel(0));
            let (y0, y1) = span(&z.channel(1));
            let xs = linspace(x0, x1, GRID_2D);
            let ys = linspace(y0, y1, GRID_2D);
            Signal::from_fn(xs.len() * ys.len(), 2, |k, c| {
                if c == 0 {
                    xs[k % xs.len()]
                } else {
                    ys[k / xs.len()]
                }
            })
        }
        _ => z.clone(),
    }
}

/// Everything an identification returns, before it becomes Python objects.
pub(crate) struct Outcome {
    /// The identification (kept for bands).
    pub id: Identification,
    /// The fitted model.
    pub estimate: Estimate,
    /// report.json.
    pub report: String,
    /// β used.
    pub beta: f64,
    /// σ given or chosen for every block.
    pub sigma: Option<f64>,
    /// σ chosen per block by selection.
    pub widths: Vec<Option<f64>>,
    /// Every block's map on its grid, with the posterior standard deviation when kept.
    pub maps: Vec<MapOnGrid>,
}

/// A block's map on the grid it is shown on.
pub(crate) struct MapOnGrid {
    grid: Signal,
    value: Vec<f64>,
    std: Option<Vec<f64>>,
}

impl Outcome {
    /// The dictionary `structid._identify._fit` reads.
    pub(crate) fn into_dict(
        mut self,
        py: Python<'_>,
        kernels: Vec<Py<PyAny>>,
    ) -> PyResult<Bound<'_, PyDict>> {
        let d = PyDict::new(py);
        // ŵ and ê move into numpy (bands need only the blocks and the posterior).
        let w_hat = std::mem::replace(&mut self.id.w_hat, Signal::zeros(0, 0));
        let e_hat = std::mem::replace(&mut self.id.e_hat, Signal::zeros(0, 0));
        d.set_item("w_hat", convert::into_array(py, w_hat))?;
        d.set_item("e_hat", convert::into_array(py, e_hat))?;
        let maps = std::mem::take(&mut self.maps);
        d.set_item("maps", maps_dict(py, &self.id, maps)?)?;
        d.set_item("report", self.report)?;
        d.set_item("beta", self.beta)?;
        d.set_item("sigma", self.sigma)?;
        d.set_item("widths", self.widths)?;
        d.set_item(
            "noise_variance",
            self.id.posterior.as_ref().map(|p| p.noise_variance()),
        )?;
        d.set_item(
            "estimate",
            Fitted::new(self.estimate, Some(Arc::new(self.id))).with_kernels(kernels),
        )?;
        Ok(d)
    }
}

/// Identifies the maps from one or more records (`Data::from_records`; one record is the
/// `Data` as read).
fn run_records(
    model: &Model,
    records: Vec<Vec<(String, Vec<f64>)>>,
    validation: Option<Vec<(String, Vec<f64>)>>,
    r: &Request,
) -> PyResult<Outcome> {
    let settings = settings(r)?;
    let mf = &model.file;
    if r.selection.as_deref() == Some("cv") && r.folds < 2 {
        return Err(invalid("folds must be at least 2"));
    }
    if validation.is_some() != (r.selection.as_deref() == Some("validation")) {
        return Err(invalid(
            "selection=\"validation\" and validation data go together",
        ));
    }
    if r.selection.is_some() && !(r.beta.is_none() || r.sigma_auto) {
        return Err(invalid(
            "a selection criterion needs beta=\"auto\" and/or sigma=\"auto\"",
        ));
    }
    let mut data = records
        .into_iter()
        .map(|named| convert::record(mf, named))
        .collect::<PyResult<Vec<Data>>>()?;
    let data = if data.len() == 1 {
        data.pop().expect("one record")
    } else {
        Data::from_records(data).map_err(error)?
    };
    let validation = validation.map(|v| convert::record(mf, v)).transpose()?;
    let out = identify_model_file(&IdentifyRequest {
        model: mf,
        data: &data,
        data_label: "the data".into(),
        validation: validation.as_ref(),
        beta: r.beta,
        sigma: r.sigma,
        sigma_label: "sigma".into(),
        sigma_auto: r.sigma_auto,
        selection: criterion(r)?,
        folds: r.folds,
        settings,
        dispersions: r
            .user
            .iter()
            .map(|(block, u)| (block.clone(), u.dispersion()))
            .collect(),
        progress: Progress::none(),
    })
    .map_err(error)?;
    out.identification.check_converged().map_err(error)?;
    Ok(Outcome {
        maps: map_values(&out.identification)?,
        report: out.report.to_json_string().map_err(error)?,
        beta: out.settings.beta(),
        sigma: out.sigma,
        widths: out.widths,
        id: out.identification,
        estimate: out.estimate,
    })
}

/// Every block's map on its grid (evaluated without the GIL: a Python kernel may be called
/// from the library's threads).
pub(crate) fn map_values(id: &Identification) -> PyResult<Vec<MapOnGrid>> {
    (0..id.blocks.len())
        .map(|i| {
            let grid = grid(&id.blocks[i].z);
            Ok(MapOnGrid {
                value: id.blocks[i].map.eval_many(&grid),
                std: id.posterior_std(i, &grid).map_err(error)?,
                grid,
            })
        })
        .collect()
}

/// The map of every block: its inputs z at the samples (ŵ is a column of the whole ŵ), the
/// grid, N̂ on it and the posterior standard deviation there when kept.
fn maps_dict<'py>(
    py: Python<'py>,
    id: &Identification,
    maps: Vec<MapOnGrid>,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    id.blocks
        .iter()
        .zip(maps)
        .map(|(b, m)| {
            let d = PyDict::new(py);
            d.set_item("name", &b.name)?;
            d.set_item("dispersion", &b.dispersion)?;
            d.set_item("z", convert::array(py, &b.z))?;
            d.set_item("output", b.output)?;
            d.set_item("grid", convert::array(py, &m.grid))?;
            d.set_item("value", convert::vector(py, m.value))?;
            d.set_item("std", m.std.map(|s| convert::vector(py, s)))?;
            d.set_item("dispersion_value", b.dispersion_value)?;
            Ok(d)
        })
        .collect()
}

/// A record as named numpy columns.
pub(crate) type Columns<'py> = Vec<(String, PyReadonlyArray1<'py, f64>)>;

/// Identifies the model's maps from named columns (see `structid.identify`).
#[pyfunction]
#[pyo3(signature = (model, columns, beta=None, sigma=None, sigma_auto=false, selection=None, folds=5, validation=None, solver="auto", initial_state="zero", bands=true, tolerance=None, max_iterations=None, memory_limit_mib=None, more_records=None, kernels=Vec::new()))]
pub fn identify_columns<'py>(
    py: Python<'py>,
    model: &Model,
    columns: Columns<'py>,
    beta: Option<f64>,
    sigma: Option<f64>,
    sigma_auto: bool,
    selection: Option<String>,
    folds: usize,
    validation: Option<Vec<(String, PyReadonlyArray1<'py, f64>)>>,
    solver: &str,
    initial_state: &str,
    bands: bool,
    tolerance: Option<f64>,
    max_iterations: Option<usize>,
    memory_limit_mib: Option<u64>,
    more_records: Option<Vec<Columns<'py>>>,
    kernels: Vec<(Option<String>, Bound<'py, PyAny>)>,
) -> PyResult<Bound<'py, PyDict>> {
    let user = UserDispersion::extract_all(&kernels)?;
    let request = Request {
        user,
        beta,
        sigma,
        sigma_auto,
        selection,
        folds,
        solver: solver.into(),
        initial_state: initial_state.into(),
        bands,
        tolerance,
        max_iterations,
        memory_limit_mib,
    };
    // the first record, then any further ones: each restarts the model from its own state
    let mut records = vec![named_columns(&columns)];
    records.extend(more_records.iter().flatten().map(|r| named_columns(r)));
    let validation = validation.as_ref().map(|v| named_columns(v));
    let model = model.clone();
    let python_kernels = !kernels.is_empty();
    let kernels = kernels.into_iter().map(|(_, k)| k.unbind()).collect();
    detach(py, python_kernels, move || {
        run_records(&model, records, validation, &request)
    })?
    .into_dict(py, kernels)
}

/// Columns by name, copied out of numpy before the GIL is released.
pub fn named_columns(columns: &[(String, PyReadonlyArray1<'_, f64>)]) -> Vec<(String, Vec<f64>)> {
    columns
        .iter()
        .map(|(name, a)| (name.clone(), a.as_array().to_vec()))
        .collect()
}

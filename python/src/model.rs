//! The model: a model file (an LFT or a `[linear]` structure, signal names, blocks), read from
//! TOML or built from a structure (Hammerstein, Wiener, output or rate feedback).

use std::path::{Path, PathBuf};

use numpy::PyReadonlyArray2;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_core::Signal;
use structid_io::ModelFile;
use structid_linear::PolynomialModel;

use crate::convert::{self, block_dict, error, invalid};

/// A structured model: the known linear block, the names of the data columns and the unknown
/// static maps with their dispersions. Immutable; `with_dispersion` returns a new model.
#[pyclass(module = "structid._structid", frozen)]
#[derive(Clone)]
pub struct Model {
    pub(crate) file: ModelFile,
}

impl Model {
    /// A model from a model file built in code: written as text and parsed back, so that it
    /// passes the same checks as a file and saves to a file that reads back as itself.
    fn checked(file: &ModelFile) -> PyResult<Self> {
        let base = file.path.as_deref().and_then(Path::parent);
        let mut back = ModelFile::parse(&file.to_toml_string(), base).map_err(error)?;
        back.path.clone_from(&file.path);
        Ok(Self { file: back })
    }

    /// The same model with block `block` changed by `change`, checked as a model file is.
    fn with_block(
        &self,
        block: &str,
        change: impl FnOnce(&mut structid_io::BlockSpec),
    ) -> PyResult<Self> {
        let mut file = self.file.clone();
        let b = file
            .blocks
            .iter_mut()
            .find(|b| b.name == block)
            .ok_or_else(|| invalid(format!("the model has no block `{block}`")))?;
        change(b);
        Self::checked(&file)
    }

    /// A model from a model file that a workflow produced (already checked, its tables in
    /// memory).
    pub(crate) fn from_file_value(file: ModelFile) -> PyResult<Self> {
        Ok(Self { file })
    }
}

#[pymethods]
impl Model {
    /// Parses model-file text (TOML). `base_dir` resolves relative truth-table paths.
    #[staticmethod]
    #[pyo3(signature = (text, base_dir=None))]
    fn from_toml(text: &str, base_dir: Option<PathBuf>) -> PyResult<Self> {
        let file = ModelFile::parse(text, base_dir.as_deref()).map_err(error)?;
        Ok(Self { file })
    }

    /// Reads a model file.
    #[staticmethod]
    fn from_file(path: PathBuf) -> PyResult<Self> {
        let file = ModelFile::from_path(&path).map_err(error)?;
        Ok(Self { file })
    }

    /// Unknown static maps `names` placed at `sites` of the linear block
    /// G(q) = num(q⁻¹)/den(q⁻¹), in order: the first in G (`input`: Hammerstein y = G·N(u) + e;
    /// `output`: Wiener y = N(G·u) + e; `output-feedback`: y = G·(u − N(y)) + e;
    /// `rate-feedback`: y = G·(u − N(ẏ)) + e; `lti` alone: no map), each further one at that
    /// site of the model built so far (`structid_io::ModelFile::from_structure`). `num` lists
    /// one numerator per input u; `dispersions` has one entry per site.
    #[staticmethod]
    #[pyo3(signature = (sites, num, den, dispersions, names, sample_time=None, inputs=None, output="y"))]
    #[allow(clippy::too_many_arguments)]
    fn structure(
        sites: Vec<String>,
        num: Vec<Vec<f64>>,
        den: Vec<f64>,
        dispersions: Vec<Bound<'_, PyDict>>,
        names: Vec<String>,
        sample_time: Option<f64>,
        inputs: Option<Vec<String>>,
        output: &str,
    ) -> PyResult<Self> {
        let mut blocks = Vec::new();
        for ((site, d), name) in sites.iter().zip(&dispersions).zip(&names) {
            let parsed = structid_io::parse_linear_structure(site).ok_or_else(|| {
                invalid(format!(
                    "site `{site}` is not one of {}",
                    structid_io::LINEAR_STRUCTURES.join(", ")
                ))
            })?;
            match parsed {
                None if sites.len() == 1 => {}
                None => {
                    return Err(invalid(
                        "`lti` (no map) cannot be combined with other sites",
                    ));
                }
                Some(site) => blocks.push(structid_io::SiteBlock {
                    name: name.clone(),
                    site,
                    dispersion: convert::dispersion(d)?,
                }),
            }
        }
        let inputs = inputs.unwrap_or_else(|| {
            if num.len() == 1 {
                vec!["u".into()]
            } else {
                (0..num.len()).map(|i| format!("u{i}")).collect()
            }
        });
        let g = PolynomialModel {
            num,
            den,
            sample_time,
        };
        let file = ModelFile::from_structure(&g, &blocks, inputs, output.into()).map_err(error)?;
        Ok(Self { file })
    }

    /// The model-file text (TOML, canonical form); `Model.from_toml` reads it back.
    fn to_toml(&self) -> String {
        self.file.to_toml_string()
    }

    /// The same model with every block's dispersion replaced (a block keeps its σ when the
    /// new dispersion gives none), as `structid identify --dispersion` does.
    fn with_dispersion(&self, dispersion: &Bound<'_, PyDict>) -> PyResult<Self> {
        let mut file = self.file.clone();
        file.replace_dispersions(&convert::dispersion(dispersion)?);
        Self::checked(&file)
    }

    /// The same model with block `name`'s truth (a model-file expression in z0, z1, …), for
    /// `simulate`.
    fn with_truth(&self, block: &str, expression: &str) -> PyResult<Self> {
        let truth = structid_io::TruthSpec::Expression(expression.into());
        self.with_block(block, |b| b.truth = Some(truth))
    }

    /// The same model with block `name` declared monotone (`"increasing"`, `"decreasing"`) or,
    /// with `None`, unconstrained; the model file's own rules for `shape` apply.
    #[pyo3(signature = (block, shape))]
    fn with_shape(&self, block: &str, shape: Option<&str>) -> PyResult<Self> {
        let shape = shape
            .map(str::parse::<structid_core::Monotonicity>)
            .transpose()
            .map_err(error)?;
        self.with_block(block, |b| b.shape = shape)
    }

    /// The data columns: `{"u": [...], "y": [...], "z": [...] or None}`.
    #[getter]
    fn signals<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("u", self.file.signals.u.clone())?;
        d.set_item("y", self.file.signals.y.clone())?;
        d.set_item("z", self.file.signals.z.clone())?;
        Ok(d)
    }

    /// The blocks: name, z inputs, w output, dispersion kind and σ, truth, shape
    /// (`"increasing"`, `"decreasing"` or None).
    #[getter]
    fn blocks<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.file
            .blocks
            .iter()
            .map(|b| {
                let d = block_dict(py, &b.name, &b.inputs, b.output)?;
                d.set_item("dispersion", b.dispersion.kind())?;
                d.set_item("sigma", b.dispersion.sigma())?;
                d.set_item("truth", b.truth.as_ref().map(|t| t.describe()))?;
                d.set_item("shape", b.shape.map(|s| s.as_str()))?;
                Ok(d)
            })
            .collect()
    }

    /// The sizes of the LFT: states, u, e, w, y, z.
    #[getter]
    fn dims<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let n = self.file.lft.dims();
        let d = PyDict::new(py);
        for (k, v) in [
            ("states", n.states),
            ("u", n.u),
            ("e", n.e),
            ("w", n.w),
            ("y", n.y),
            ("z", n.z),
        ] {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// Simulates the model with every block's truth in the loop (as `structid simulate`):
    /// u is L × n_u; white Gaussian noise of standard deviation `noise_std` from `seed`.
    /// Returns (y, z, w).
    #[pyo3(signature = (u, noise_std=0.0, seed=0))]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray2<'py, f64>,
        noise_std: f64,
        seed: u64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !(noise_std.is_finite() && noise_std >= 0.0) {
            return Err(invalid(format!(
                "invalid noise_std {noise_std}: it must be a finite number, zero or more"
            )));
        }
        let u: Signal = convert::signal(&u, "u")?;
        if self
            .file
            .blocks
            .iter()
            .any(|b| b.truth.is_none() && b.operator.is_none())
        {
            return Err(invalid(
                "simulation needs a truth for every block (Model.with_truth)",
            ));
        }
        let file = self.file.clone();
        let sim = py
            .detach(move || {
                structid_workflow::simulate_model_file_noisy(&file, &u, noise_std, seed)
            })
            .map_err(error)?;
        let d = PyDict::new(py);
        d.set_item("y", convert::array(py, &sim.y))?;
        d.set_item("z", convert::array(py, &sim.z))?;
        d.set_item("w", convert::array(py, &sim.w))?;
        Ok(d)
    }

    /// Why `validate` scores the model by simulation alone (a latent block or an operator), or
    /// None: then the one-step predictor applies.
    fn why_simulation_only(&self) -> PyResult<Option<String>> {
        structid_workflow::why_simulation_only(&self.file).map_err(error)
    }

    /// How identification reaches each block: (name, "computable" | "in series" | "latent",
    /// the blocks it reads in the same sample).
    fn block_access(&self) -> PyResult<Vec<(String, String, Vec<String>)>> {
        use structid_core::BlockAccess;
        let access = self.file.block_access().map_err(error)?;
        Ok(self
            .file
            .blocks
            .iter()
            .zip(access)
            .map(|(b, a)| match a {
                BlockAccess::Computable => (b.name.clone(), "computable".into(), Vec::new()),
                BlockAccess::InSeries { upstream } => {
                    (b.name.clone(), "in series".into(), upstream)
                }
                BlockAccess::Latent => (b.name.clone(), "latent".into(), Vec::new()),
            })
            .collect())
    }

    /// The simulation from rest on (u, y) and its scores after `settle` samples (as `structid
    /// validate` of a model without a one-step predictor): returns (y_sim, rms, fit_percent).
    #[pyo3(signature = (u, y, settle=0))]
    fn score_simulation<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray2<'py, f64>,
        y: PyReadonlyArray2<'py, f64>,
        settle: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let data = structid_core::Data::new(convert::signal(&u, "u")?, convert::signal(&y, "y")?)
            .map_err(error)?;
        let file = self.file.clone();
        let s = py
            .detach(move || structid_workflow::score_simulation(&file, &data, settle))
            .map_err(error)?;
        let d = PyDict::new(py);
        d.set_item("y_sim", convert::array(py, &s.simulated))?;
        d.set_item("rms", s.rms)?;
        d.set_item("fit_percent", s.fit_percent)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let names: Vec<_> = self.file.blocks.iter().map(|b| b.name.as_str()).collect();
        format!(
            "Model(u={:?}, y={:?}, blocks={names:?})",
            self.file.signals.u, self.file.signals.y
        )
    }

    fn __reduce__(&self, py: Python<'_>) -> PyResult<(Py<PyAny>, (String,))> {
        let from = py.get_type::<Self>().getattr("from_toml")?.unbind();
        Ok((from, (self.file.to_toml_string(),)))
    }
}

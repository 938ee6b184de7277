//! The `report.json` written by `structid identify`.
//!
//! [`Report::new`] collects the settings, the cost terms of eq. (4), the solver diagnostics and,
//! per block, the dispersion value and (when the model file gives a `truth`) the RMS error of
//! the estimate at the data points, plain and centred (see
//! [`structid_core::validation::metrics::centred_rms_difference`]; maps that share an output are identifiable
//! only up to a constant). The caller adds the names of the files it wrote and a
//! [`Reproduction`] record, and serialises with [`Report::to_json_string`].
//!
//! [`ReportRecord`] reads back what `structid validate` needs from a `report.json`.

use std::collections::BTreeMap;

use std::path::Path;

use serde::{Deserialize, Serialize};
use structid_core::validation::metrics::{centred_rms_difference, rms_difference};
use structid_core::{CostTerms, Diagnostics, Identification, IdentifySettings};

use crate::error::IoError;
use crate::model_file::ModelFile;

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Program name and version.
    pub tool: String,
    /// The model file, when known.
    pub model_file: Option<String>,
    /// The data file, when known.
    pub data_file: Option<String>,
    /// Number of samples L.
    pub samples: usize,
    /// The identification settings.
    pub settings: SettingsReport,
    /// Cost terms at the optimum.
    pub cost: CostTerms,
    /// Solver diagnostics.
    pub diagnostics: DiagnosticsReport,
    /// The estimated initial state x₀ (`--initial-state estimate`), otherwise absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub initial_state: Option<Vec<f64>>,
    /// One entry per block, in model order.
    pub blocks: Vec<BlockReport>,
    /// How β (and σ) were chosen, when `auto` (absent for given values).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub selection: Option<SelectionReport>,
    /// Every file written, relative to the output directory.
    pub files: Vec<String>,
    /// How to re-run this identification exactly (absent in reports of older versions).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reproduction: Option<Reproduction>,
    /// The alternating refinement that produced the linear part (`structid refine` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refinement: Option<RefinementReport>,
}

/// What `structid refine` did: every alternation's costs and validation error.
#[derive(Clone, Debug, Serialize)]
pub struct RefinementReport {
    /// The structure, e.g. `output feedback y = G·(u − N(y)) + e`.
    pub structure: String,
    /// The validation record: a file, or the held-out fraction of the data.
    pub validation: Option<String>,
    /// Leading validation samples not scored.
    pub settle: usize,
    /// Every alternation, in order.
    pub iterations: Vec<structid_core::refine::RefineIteration>,
    /// Index of the iteration whose model was kept.
    pub best: usize,
    /// Why the alternation stopped.
    pub stop_reason: String,
    /// The β used (chosen on the first pass when automatic).
    pub beta: f64,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// Everything needed to re-run an identification exactly: the files with absolute
/// (canonical) paths, so that the report does not depend on the working directory it was
/// written from, and the command-line settings as given. `structid validate` rebuilds the
/// estimate from it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reproduction {
    /// The model file, absolute and canonical.
    pub model_file_absolute: String,
    /// The data file, absolute and canonical (the first one when there are several records).
    pub data_file_absolute: String,
    /// Every data file, absolute and canonical, when the identification used several records
    /// (one per file, in order); empty for one record.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub data_files_absolute: Vec<String>,
    /// β.
    pub beta: f64,
    /// The σ override (`--sigma`), if any.
    pub sigma: Option<f64>,
    /// The solver as requested (`auto`, `exact`, `features`, `clarabel`, `admm`).
    pub solver_requested: String,
    /// The solver that ran (one of `exact`, `features`, `clarabel`, `admm`): an automatic
    /// choice depends on the memory available, so the rerun forces this one.
    pub solver: String,
    /// `zero` or `estimate`.
    pub initial_state: String,
    /// The memory budget in MiB (`--memory-limit-mib`), if given.
    pub memory_limit_mib: Option<u64>,
    /// The dispersion override (`--dispersion`: `gaussian`, `gaussian-lowrank`, `fourier`,
    /// `tv`), if any.
    pub dispersion: Option<String>,
    /// `--neighbours`, if given.
    pub neighbours: Option<usize>,
    /// `--tolerance`, if given.
    pub tolerance: Option<f64>,
    /// `--max-iterations`, if given.
    pub max_iterations: Option<usize>,
    /// Per-block widths σ chosen by `--sigma auto` (block name, σ), which replace the model
    /// file's on the rerun; empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub block_sigmas: Vec<(String, f64)>,
}

/// The parts of a `report.json` that are read back (by `structid validate`). Unknown fields
/// are ignored, so reports of any version parse; [`ReportRecord::reproduction`] is `None` for
/// reports written before it existed.
#[derive(Clone, Debug, PartialEq, Deserialize)]
pub struct ReportRecord {
    /// The model file as given on the command line.
    pub model_file: Option<String>,
    /// The data file as given on the command line.
    pub data_file: Option<String>,
    /// Number of samples L.
    pub samples: usize,
    /// The blocks, in model order.
    pub blocks: Vec<RecordBlock>,
    /// The estimated initial state, if it was estimated.
    #[serde(default)]
    pub initial_state: Option<Vec<f64>>,
    /// Every file written, relative to the output directory.
    #[serde(default)]
    pub files: Vec<String>,
    /// How to re-run the identification.
    #[serde(default)]
    pub reproduction: Option<Reproduction>,
}

/// One block of a [`ReportRecord`].
#[derive(Clone, Debug, PartialEq, Deserialize)]
pub struct RecordBlock {
    /// Block name.
    pub name: String,
    /// Indices into z of its inputs.
    pub inputs: Vec<usize>,
    /// Index into w of its output.
    pub output: usize,
}

impl ReportRecord {
    /// Parses the text of a `report.json`; `path` is used in error messages only.
    ///
    /// ```
    /// use structid_io::ReportRecord;
    /// let r = ReportRecord::parse(
    ///     r#"{"samples": 3, "blocks": [{"name": "f", "inputs": [0], "output": 0}], "cost": {}}"#,
    ///     None,
    /// )
    /// .unwrap();
    /// assert_eq!((r.samples, r.blocks[0].name.as_str()), (3, "f"));
    /// assert!(r.reproduction.is_none());
    /// assert!(ReportRecord::parse("{}", None).is_err());
    /// ```
    pub fn parse(text: &str, path: Option<&Path>) -> Result<Self, IoError> {
        serde_json::from_str(text).map_err(|e| {
            let name = path.map_or_else(
                || "the report".to_string(),
                |p| format!("`{}`", p.display()),
            );
            IoError::InvalidArgument(format!(
                "{name} is not the report.json of an identification: {e}"
            ))
        })
    }

    /// Reads and parses a `report.json`.
    pub fn read(path: &Path) -> Result<Self, IoError> {
        let text = std::fs::read_to_string(path).map_err(|source| IoError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, Some(path))
    }
}

/// The automatic choice of hyperparameters: values, criterion, method and curve.
#[derive(Clone, Debug, Serialize)]
pub struct SelectionReport {
    /// `ml`, `gcv`, `cv` or `validation`.
    pub criterion: String,
    /// The criterion in words.
    pub criterion_description: String,
    /// How it was evaluated (path, ranks, search).
    pub method: String,
    /// The chosen β.
    pub beta: f64,
    /// The chosen σ of the first block with a width, when σ was tuned.
    pub sigma: Option<f64>,
    /// The chosen width of every block (null without one).
    pub widths: Vec<Option<f64>>,
    /// ŝ² at the choice (likelihood-based criteria).
    pub noise_variance: Option<f64>,
    /// Every trial (β, σ, value) in the order evaluated.
    pub curve: Vec<structid_core::selection::Trial>,
    /// Seconds for the selection and the final fit.
    pub seconds: f64,
}

impl SelectionReport {
    /// The report of a selection.
    pub fn new(sel: &structid_core::selection::Selection) -> Self {
        Self {
            criterion: sel.criterion.name().into(),
            criterion_description: sel.criterion.describe(),
            method: sel.method.clone(),
            beta: sel.beta,
            sigma: sel.sigma,
            widths: sel.widths.clone(),
            noise_variance: sel.noise_variance,
            curve: sel.curve.clone(),
            seconds: sel.seconds,
        }
    }
}

/// Settings used for the identification.
#[derive(Clone, Debug, Serialize)]
pub struct SettingsReport {
    /// β.
    pub beta: f64,
    /// The solver choice (`Auto`, `Exact`, …).
    pub solver: String,
    /// Explicit memory limit, if one was set.
    pub memory_limit_bytes: Option<u64>,
    /// `Zero` or `Estimate`.
    pub initial_state: String,
    /// The σ that replaced every block's, if any.
    pub sigma_override: Option<f64>,
    /// Per-block dispersion settings.
    pub blocks: Vec<BlockSettings>,
}

/// The dispersion of one block as used.
#[derive(Clone, Debug, Serialize)]
pub struct BlockSettings {
    /// Block name.
    pub name: String,
    /// Dispersion kind (`gaussian`).
    pub kind: String,
    /// Description, e.g. `gaussian(sigma=0.4)`.
    pub dispersion: String,
    /// Numeric parameters (σ, …).
    pub parameters: BTreeMap<String, f64>,
    /// Where σ came from: `override`, `model file` or `default`.
    pub sigma_source: String,
}

/// Solver diagnostics plus how z was obtained.
#[derive(Clone, Debug, Serialize)]
pub struct DiagnosticsReport {
    /// The core's diagnostics (timings, dropped samples, jitter, feasibility, …).
    #[serde(flatten)]
    pub solver: Diagnostics,
    /// Number of dropped output samples.
    pub dropped_sample_count: usize,
    /// How z was obtained (measured, from u, or by output injection).
    pub z_source: String,
}

/// The estimate of one block.
#[derive(Clone, Debug, Serialize)]
pub struct BlockReport {
    /// Block name.
    pub name: String,
    /// Indices into z of its inputs.
    pub inputs: Vec<usize>,
    /// Names of its inputs (measured z columns or `z<i>`).
    pub input_names: Vec<String>,
    /// Index into w of its output.
    pub output: usize,
    /// Dispersion description.
    pub dispersion: String,
    /// D_i(z⁽ⁱ⁾, ŵ⁽ⁱ⁾) at the optimum.
    pub dispersion_value: f64,
    /// [min, max] of each input over the data.
    pub z_range: Vec<[f64; 2]>,
    /// [min, max] of ŵ over the data.
    pub w_hat_range: [f64; 2],
    /// The true map, when the model file gives one.
    pub truth: Option<String>,
    /// RMS of ŵ − truth(z) over the data points.
    pub rms_error_vs_truth: Option<f64>,
    /// RMS of the same difference after removing each side's mean over the data points.
    pub centred_rms_error_vs_truth: Option<f64>,
    /// The grid (or point) evaluation file written for this block.
    pub grid_file: Option<String>,
    /// The figure written for this block.
    pub plot_file: Option<String>,
    /// ŝ², the noise variance estimated by the profiled marginal likelihood, when the solver
    /// kept a posterior (quadratic dispersions; shared by all blocks).
    pub noise_variance: Option<f64>,
    /// Whether posterior uncertainty bands were computed for this block (the `std` column of
    /// its grid file and the shaded band of its figure).
    pub band: bool,
}

fn range(x: &[f64]) -> [f64; 2] {
    x.iter()
        .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], &v| {
            [lo.min(v), hi.max(v)]
        })
}

impl Report {
    /// Builds the report of `id`, obtained from `model` with `settings` and the σ override
    /// `sigma_override`. Truth maps of the model file are evaluated at the data points.
    pub fn new(
        model: &ModelFile,
        id: &Identification,
        settings: &IdentifySettings,
        sigma_override: Option<f64>,
    ) -> Result<Self, IoError> {
        let z_names = model.z_names();
        let mut blocks = Vec::with_capacity(id.blocks.len());
        let mut block_settings = Vec::with_capacity(id.blocks.len());
        for est in &id.blocks {
            let spec = model
                .blocks
                .iter()
                .find(|b| b.name == est.name)
                .ok_or_else(|| {
                    IoError::InvalidArgument(format!(
                        "the identification has a block `{}` that the model file does not",
                        est.name
                    ))
                })?;
            let truth = spec.truth_map()?;
            let (rms, centred) = match &truth {
                Some(t) => {
                    let tv = t.eval_many(&est.z);
                    (
                        Some(rms_difference(&est.w_hat, &tv)),
                        Some(centred_rms_difference(&est.w_hat, &tv)),
                    )
                }
                None => (None, None),
            };
            block_settings.push(BlockSettings {
                name: est.name.clone(),
                kind: spec.dispersion.kind().to_string(),
                dispersion: est.dispersion.clone(),
                parameters: est.parameters.iter().cloned().collect(),
                sigma_source: if sigma_override.is_some() {
                    "override".into()
                } else if spec.dispersion.sigma().is_some() {
                    "model file".into()
                } else {
                    "default (0.1 × largest range of the block's z)".into()
                },
            });
            blocks.push(BlockReport {
                name: est.name.clone(),
                inputs: spec.inputs.clone(),
                input_names: spec
                    .inputs
                    .iter()
                    .map(|&i| z_names.get(i).cloned().unwrap_or_else(|| format!("z{i}")))
                    .collect(),
                output: est.output,
                dispersion: est.dispersion.clone(),
                dispersion_value: est.dispersion_value,
                z_range: (0..est.z.channels())
                    .map(|c| range(&est.z.channel(c)))
                    .collect(),
                w_hat_range: range(&est.w_hat),
                truth: spec.truth.as_ref().map(|t| t.describe()),
                rms_error_vs_truth: rms,
                centred_rms_error_vs_truth: centred,
                grid_file: None,
                plot_file: None,
                noise_variance: id.posterior.as_ref().map(|p| p.noise_variance()),
                band: false,
            });
        }
        Ok(Self {
            tool: format!("structid {}", env!("CARGO_PKG_VERSION")),
            model_file: model.path.as_ref().map(|p| p.display().to_string()),
            data_file: None,
            samples: id.w_hat.len(),
            settings: SettingsReport {
                beta: settings.beta(),
                solver: format!("{:?}", settings.solver()),
                memory_limit_bytes: settings.memory_limit_bytes(),
                initial_state: format!("{:?}", settings.initial_state()),
                sigma_override,
                blocks: block_settings,
            },
            cost: id.cost.clone(),
            diagnostics: DiagnosticsReport {
                dropped_sample_count: id.diagnostics.dropped_samples.len(),
                solver: id.diagnostics.clone(),
                z_source: id.z_source.describe(),
            },
            initial_state: id.initial_state.clone(),
            blocks,
            selection: None,
            files: Vec::new(),
            reproduction: None,
            refinement: None,
        })
    }

    /// The entry of block `name`, for adding file names.
    pub fn block_mut(&mut self, name: &str) -> Option<&mut BlockReport> {
        self.blocks.iter_mut().find(|b| b.name == name)
    }

    /// Pretty-printed JSON (non-finite numbers become `null`).
    pub fn to_json_string(&self) -> Result<String, IoError> {
        let mut s = serde_json::to_string_pretty(self)?;
        s.push('\n');
        Ok(s)
    }
}

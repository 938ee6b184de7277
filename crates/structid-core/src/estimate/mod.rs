//! A fitted model as a value: the [`Estimate`].
//!
//! Identification returns an [`Identification`], full of diagnostics and tied to the [`Model`]
//! and the record it came from. An `Estimate` is what is kept afterwards: the linear block L
//! (all twelve LFT matrices and the sample time, so the noise model H = L_ye comes with it),
//! every block's map in a stored form ([`StoredMap`], see [`crate::stored`]: kernel centres and α, feature
//! coefficients, total-variation nodes, …), the estimated x̂₀, the settings and cost terms that
//! produced it, and a fingerprint of the data it was fitted on. It is plain data for serde, so
//! it can be written to a file and read back on a machine that has neither the data nor the
//! model file, and it simulates, predicts and validates on its own:
//!
//! | method | what |
//! |---|---|
//! | [`Estimate::simulate`] | y from u alone with the maps in the loop (e = 0) |
//! | [`Estimate::predict`] | ŷ_(t∣t−k), the k-step-ahead prediction from u and past y ([`predict`](mod@predict)) |
//! | [`Estimate::validate`] | simulation and one-step errors with their residual tests ([`crate::validate`]) |
//! | [`Estimate::validate_records`] | the same on each of several records, with the simulation errors pooled ([`crate::validate_records`]) |
//!
//! In the style of linfa's `Fit`/`Predict`, fitting is [`Model::fit`], which returns the
//! `Estimate`:
//!
//! ```
//! use std::sync::Arc;
//! use nalgebra::dmatrix;
//! use structid_core::estimate::Estimate;
//! use structid_core::{Data, IdentifySettings, KernelDispersion, Lft, LftMatrices, Model, NonlinearBlock, Signal};
//! // Hammerstein: x⁺ = 0.5x + w, y = x + e, w = N(u).
//! let lft = Lft::new(LftMatrices {
//!     a: dmatrix![0.5], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
//!     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
//!     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
//! }).unwrap();
//! let n = NonlinearBlock::new("N", vec![0], 0, Arc::new(KernelDispersion::gaussian(0.3).unwrap()));
//! let model = Model::new(lft, vec![n]).unwrap();
//! let u = Signal::from_fn(300, 1, |k, _| 2.0 * (0.37 * k as f64).sin());
//! let truth = |z: &[f64]| z[0].tanh();
//! let y = model.simulate(&[&truth], &u, None, None).unwrap().y;
//! let data = Data::new(u.clone(), y.clone()).unwrap();
//! let settings = IdentifySettings::builder().beta(1e-6).build().unwrap();
//! let estimate = model.fit(&data, &settings).unwrap();
//! // Written and read back, it simulates to the same numbers.
//! let text = serde_json::to_string(&estimate).unwrap();
//! let back: Estimate = serde_json::from_str(&text).unwrap();
//! let a = estimate.simulate(&u, None).unwrap().y;
//! assert_eq!(a, back.simulate(&u, None).unwrap().y);
//! assert!(structid_core::validation::metrics::rms_difference(&a.channel(0), &y.channel(0)) < 0.01);
//! //! ```

pub mod predict;
mod rebuild;

use std::sync::Arc;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use structid_lti::Signal;

use crate::dispersion::user::UserKernels;
use crate::dispersion::{Dispersion, Penalty};
use crate::error::{Error, Result};
use crate::identify::{CostTerms, Identification, IdentifySettings, identify};
use crate::model::interpolant::Interpolant;
use crate::model::lft::{Lft, LftMatrices};
use crate::model::simulate::Simulation;
use crate::model::{Data, Model, NonlinearBlock};
use crate::validation::{
    RecordsValidation, ValidationReport, ValidationSettings, validate, validate_records,
};

pub use crate::stored::{
    FourierStored, NystromStored, PolynomialStored, StoredKernel, StoredMap, StoredPoints,
};
pub use predict::{Prediction, PredictionSettings};

/// The version of the stored form written by this library; reading refuses newer ones.
pub const FORMAT_VERSION: u32 = 1;

/// A matrix as plain data, row-major.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoredMatrix {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Entries, row after row.
    pub data: Vec<f64>,
}

impl StoredMatrix {
    fn from_matrix(m: &DMatrix<f64>) -> Self {
        let (rows, cols) = m.shape();
        Self {
            rows,
            cols,
            data: (0..rows * cols).map(|i| m[(i / cols, i % cols)]).collect(),
        }
    }

    fn to_matrix(&self, name: &str) -> Result<DMatrix<f64>> {
        if self.rows.checked_mul(self.cols) != Some(self.data.len()) {
            return Err(Error::InconsistentStored {
                item: format!("matrix {name}"),
                detail: format!(
                    "{} × {} needs {} entries, found {}",
                    self.rows,
                    self.cols,
                    self.rows.saturating_mul(self.cols),
                    self.data.len()
                ),
            });
        }
        Ok(DMatrix::from_row_slice(self.rows, self.cols, &self.data))
    }
}

/// The LFT's twelve matrices and its sample time, as plain data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoredLft {
    /// A.
    pub a: StoredMatrix,
    /// B_u.
    pub bu: StoredMatrix,
    /// B_e.
    pub be: StoredMatrix,
    /// B_w.
    pub bw: StoredMatrix,
    /// C_y.
    pub cy: StoredMatrix,
    /// D_yu.
    pub dyu: StoredMatrix,
    /// D_ye.
    pub dye: StoredMatrix,
    /// D_yw.
    pub dyw: StoredMatrix,
    /// C_z.
    pub cz: StoredMatrix,
    /// D_zu.
    pub dzu: StoredMatrix,
    /// D_ze.
    pub dze: StoredMatrix,
    /// D_zw.
    pub dzw: StoredMatrix,
    /// The sample time T_s, when known.
    pub sample_time: Option<f64>,
}

impl StoredLft {
    /// The stored form of `lft`.
    pub fn from_lft(lft: &Lft) -> Self {
        let m = lft.matrices();
        let s = StoredMatrix::from_matrix;
        Self {
            a: s(&m.a),
            bu: s(&m.bu),
            be: s(&m.be),
            bw: s(&m.bw),
            cy: s(&m.cy),
            dyu: s(&m.dyu),
            dye: s(&m.dye),
            dyw: s(&m.dyw),
            cz: s(&m.cz),
            dzu: s(&m.dzu),
            dze: s(&m.dze),
            dzw: s(&m.dzw),
            sample_time: lft.sample_time(),
        }
    }

    /// The LFT, checked as [`Lft::new`] checks it.
    ///
    /// # Errors
    /// As [`Lft::new`], and [`Error::InconsistentStored`] for a matrix whose entries do not fill
    /// its shape.
    pub fn to_lft(&self) -> Result<Lft> {
        let lft = Lft::new(LftMatrices {
            a: self.a.to_matrix("a")?,
            bu: self.bu.to_matrix("bu")?,
            be: self.be.to_matrix("be")?,
            bw: self.bw.to_matrix("bw")?,
            cy: self.cy.to_matrix("cy")?,
            dyu: self.dyu.to_matrix("dyu")?,
            dye: self.dye.to_matrix("dye")?,
            dyw: self.dyw.to_matrix("dyw")?,
            cz: self.cz.to_matrix("cz")?,
            dzu: self.dzu.to_matrix("dzu")?,
            dze: self.dze.to_matrix("dze")?,
            dzw: self.dzw.to_matrix("dzw")?,
        })?;
        match self.sample_time {
            Some(ts) => lft.with_sample_time(ts),
            None => Ok(lft),
        }
    }
}

/// One block of an [`Estimate`]: where it sits and its map.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimatedBlock {
    /// Block name.
    pub name: String,
    /// The z channels it reads.
    pub inputs: Vec<usize>,
    /// The w channel it writes.
    pub output: usize,
    /// The dispersion it was estimated with, e.g. `gaussian(sigma=0.4)`.
    pub dispersion: String,
    /// The map.
    pub map: StoredMap,
}

/// A fingerprint of a record: its size and a 64-bit FNV-1a hash of the bits of u and y.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DataFingerprint {
    /// Samples L.
    pub samples: usize,
    /// Input channels.
    pub inputs: usize,
    /// Output channels.
    pub outputs: usize,
    /// The hash, 16 hexadecimal digits.
    pub hash: String,
}

impl DataFingerprint {
    /// The fingerprint of `data`. Two records with the same numbers in the same order have the
    /// same fingerprint; any changed sample changes it (up to hash collisions).
    ///
    /// ```
    /// use structid_core::{Data, Signal};
    /// use structid_core::estimate::DataFingerprint;
    /// let d = Data::new(Signal::from_fn(5, 1, |k, _| k as f64), Signal::from_fn(5, 1, |_, _| 1.0)).unwrap();
    /// let e = Data::new(Signal::from_fn(5, 1, |k, _| k as f64), Signal::from_fn(5, 1, |k, _| (k == 4) as u8 as f64)).unwrap();
    /// assert_eq!(DataFingerprint::of(&d), DataFingerprint::of(&d.clone()));
    /// assert_ne!(DataFingerprint::of(&d).hash, DataFingerprint::of(&e).hash);
    /// ```
    pub fn of(data: &Data) -> Self {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for v in data.u().as_slice().iter().chain(data.y().as_slice()) {
            for b in v.to_bits().to_le_bytes() {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0100_0000_01b3);
            }
        }
        Self {
            samples: data.len(),
            inputs: data.u().channels(),
            outputs: data.y().channels(),
            hash: format!("{h:016x}"),
        }
    }
}

/// How an estimate was produced, for the record.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The workflow that wrote it: `identify`, `refine`, `discover`, …
    pub workflow: String,
    /// The identification settings, when one identification produced it.
    pub settings: Option<IdentifySettings>,
    /// The cost terms at the optimum, when known.
    pub cost: Option<CostTerms>,
    /// The solver that ran, when known.
    pub solver: Option<String>,
    /// The record it was fitted on.
    pub fitted_on: Option<DataFingerprint>,
    /// Anything else worth keeping (named parameters, notes), as key and value.
    pub notes: Vec<(String, String)>,
}

/// The serialised form of an [`Estimate`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimateData {
    /// [`FORMAT_VERSION`] of the writer.
    pub format_version: u32,
    /// The linear block.
    pub lft: StoredLft,
    /// The blocks, each with its map.
    pub blocks: Vec<EstimatedBlock>,
    /// x̂₀ on the record it was fitted on, when estimated.
    pub initial_state: Option<Vec<f64>>,
    /// How it was produced.
    pub provenance: Provenance,
    /// The names of the input and output channels, when known (a data file's columns).
    #[serde(default)]
    pub signals: Option<SignalNames>,
}

/// The names of an estimate's input and output channels.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignalNames {
    /// One name per input u.
    pub u: Vec<String>,
    /// One name per output y.
    pub y: Vec<String>,
}

/// A fitted model: the linear block with every map, ready to simulate, predict and validate;
/// see the [module documentation](self).
#[derive(Clone, Serialize, Deserialize)]
#[serde(try_from = "EstimateData", into = "EstimateData")]
pub struct Estimate {
    data: EstimateData,
    model: Model,
    maps: Vec<Arc<dyn Interpolant>>,
}

impl std::fmt::Debug for Estimate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Estimate")
            .field(
                "blocks",
                &self.data.blocks.iter().map(|b| &b.name).collect::<Vec<_>>(),
            )
            .field("provenance", &self.data.provenance)
            .finish_non_exhaustive()
    }
}

impl From<Estimate> for EstimateData {
    fn from(e: Estimate) -> Self {
        e.data
    }
}

impl TryFrom<EstimateData> for Estimate {
    type Error = Error;

    fn try_from(data: EstimateData) -> Result<Self> {
        Self::from_data_with_kernels(data, &UserKernels::new())
    }
}

impl Estimate {
    /// The estimate of its stored form, with the user-defined kernels and feature maps it is
    /// built on ([`crate::stored::StoredKernel::User`]) taken from `kernels`: the way to read
    /// back an estimate made with a kernel of your own ([`crate::dispersion::user`]).
    /// `Estimate::try_from(data)` is this with an empty registry.
    ///
    /// # Errors
    /// As `try_from`, and [`Error::UserKernelMissing`] for a user kernel that `kernels` does
    /// not hold.
    pub fn from_data_with_kernels(data: EstimateData, kernels: &UserKernels) -> Result<Self> {
        if data.format_version > FORMAT_VERSION {
            return Err(Error::InvalidStructure(format!(
                "the estimate was written in format {} by a newer structid; this one reads format {FORMAT_VERSION} and older",
                data.format_version
            )));
        }
        let lft = data.lft.to_lft()?;
        let blocks = data
            .blocks
            .iter()
            .map(|b| {
                NonlinearBlock::new(
                    b.name.clone(),
                    b.inputs.clone(),
                    b.output,
                    Arc::new(Fitted(b.dispersion.clone())) as Arc<dyn Dispersion>,
                )
            })
            .collect();
        let model = Model::new(lft, blocks)?;
        let maps = data
            .blocks
            .iter()
            .map(|b| {
                b.map
                    .interpolant_with(kernels)
                    .map(Arc::from)
                    .map_err(|e| match e {
                        Error::UserKernelMissing { .. } => e,
                        e => Error::InvalidStructure(format!("the map of block `{}`: {e}", b.name)),
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        if let Some(names) = &data.signals {
            check_signal_names(&model, names)?;
        }
        if let Some(x0) = &data.initial_state
            && x0.len() != model.lft().dims().states
        {
            return Err(Error::DimensionMismatch {
                what: "stored initial state".into(),
                expected: model.lft().dims().states.to_string(),
                found: x0.len().to_string(),
            });
        }
        Ok(Self { data, model, maps })
    }
}

/// Whether `names` has one name per input and per output of `model`.
fn check_signal_names(model: &Model, names: &SignalNames) -> Result<()> {
    let d = model.lft().dims();
    if names.u.len() != d.u || names.y.len() != d.y {
        return Err(Error::DimensionMismatch {
            what: "stored signal names (inputs, outputs)".into(),
            expected: format!("({}, {})", d.u, d.y),
            found: format!("({}, {})", names.u.len(), names.y.len()),
        });
    }
    Ok(())
}

/// The dispersion of a block whose map is already fitted: it describes the original one and
/// refuses to pose a new identification (which needs the model file's dispersion).
#[derive(Debug)]
struct Fitted(String);

impl Dispersion for Fitted {
    fn describe(&self) -> String {
        format!("fitted with {}", self.0)
    }

    fn penalty(&self, _z: &Signal) -> Result<Penalty> {
        Err(Error::InvalidStructure(format!(
            "a stored estimate keeps the fitted map, not its dispersion ({}); identify again from the model file",
            self.0
        )))
    }
}

impl Estimate {
    /// An estimate from a model and one map per block (in block order): the form refinement
    /// and discovery produce.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for a wrong number of maps or an initial state of the wrong
    /// size, [`Error::InvalidStructure`] when a map has no stored form (a closure, or a
    /// user-defined kernel whose `stored_kernel` is `None`; the message names the block). A
    /// user kernel stored by name ([`crate::dispersion::user`]) is taken from the model's
    /// dispersions.
    pub fn from_maps(
        model: &Model,
        maps: &[&dyn Interpolant],
        initial_state: Option<Vec<f64>>,
        provenance: Provenance,
    ) -> Result<Self> {
        let blocks = model.blocks();
        if maps.len() != blocks.len() {
            return Err(Error::DimensionMismatch {
                what: "number of maps for an estimate (one per block, in model order)".into(),
                expected: blocks.len().to_string(),
                found: maps.len().to_string(),
            });
        }
        let stored = blocks
            .iter()
            .zip(maps)
            .map(|(b, m)| {
                let map = m.stored().ok_or_else(|| {
                    Error::InvalidStructure(format!(
                        "the map of block `{}` ({}) has no stored form, so the estimate cannot be \
                         written; implement `Interpolant::stored` (or `Kernel::stored_kernel`) for it",
                        b.name,
                        b.dispersion.describe()
                    ))
                })?;
                Ok(EstimatedBlock {
                    name: b.name.clone(),
                    inputs: b.inputs.clone(),
                    output: b.output,
                    dispersion: b.dispersion.describe(),
                    map,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        // A map on a user kernel is stored by the kernel's name; the model's dispersions hold
        // the kernels themselves.
        let kernels = blocks.iter().fold(UserKernels::new(), |acc, b| {
            acc.merged(b.dispersion.user_kernels())
        });
        Self::from_data_with_kernels(
            EstimateData {
                format_version: FORMAT_VERSION,
                lft: StoredLft::from_lft(model.lft()),
                blocks: stored,
                initial_state,
                provenance,
                signals: None,
            },
            &kernels,
        )
    }

    /// The estimate of an identification of `model` on `data` with `settings`.
    ///
    /// # Errors
    /// As [`Estimate::from_maps`].
    pub fn from_identification(
        model: &Model,
        id: &Identification,
        data: &Data,
        settings: &IdentifySettings,
    ) -> Result<Self> {
        // With several records x̂₀ holds one state per estimation record, which describes
        // none of the records an estimate is later used on.
        let initial_state = if data.record_count() == 1 {
            id.initial_state.clone()
        } else {
            None
        };
        Self::from_maps(
            model,
            &id.maps(),
            initial_state,
            Provenance {
                workflow: "identify".into(),
                settings: Some(settings.clone()),
                cost: Some(id.cost.clone()),
                solver: Some(id.diagnostics.solver.to_string()),
                fitted_on: Some(DataFingerprint::of(data)),
                notes: Vec::new(),
            },
        )
    }

    /// The model: the LFT with its blocks (their dispersions only describe the original ones).
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The linear block.
    pub fn lft(&self) -> &Lft {
        self.model.lft()
    }

    /// The maps, in block order.
    pub fn maps(&self) -> Vec<&dyn Interpolant> {
        self.maps.iter().map(|m| m.as_ref()).collect()
    }

    /// The stored blocks, in block order.
    pub fn blocks(&self) -> &[EstimatedBlock] {
        &self.data.blocks
    }

    /// x̂₀ on the record the estimate was fitted on, when it was estimated.
    pub fn initial_state(&self) -> Option<&[f64]> {
        self.data.initial_state.as_deref()
    }

    /// How the estimate was produced.
    pub fn provenance(&self) -> &Provenance {
        &self.data.provenance
    }

    /// The same estimate with another provenance (a workflow that builds on an identification
    /// says so).
    pub fn with_provenance(mut self, provenance: Provenance) -> Self {
        self.data.provenance = provenance;
        self
    }

    /// The names of the input and output channels, when known.
    pub fn signals(&self) -> Option<&SignalNames> {
        self.data.signals.as_ref()
    }

    /// The same estimate with channel names (one per input and per output).
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] when the numbers of names do not match the LFT.
    pub fn with_signal_names(mut self, names: SignalNames) -> Result<Self> {
        check_signal_names(&self.model, &names)?;
        self.data.signals = Some(names);
        Ok(self)
    }

    /// Simulates y from u with the maps in the loop and e = 0, from `x0` (zero when `None`).
    ///
    /// # Errors
    /// As [`Lft::simulate`]: a wrong number of input channels, an algebraic loop, a map that
    /// returns a non-finite value.
    pub fn simulate(&self, u: &Signal, x0: Option<&[f64]>) -> Result<Simulation> {
        self.model.simulate(&self.maps(), u, None, x0)
    }

    /// Validates the estimate on a record ([`crate::validate`]).
    ///
    /// # Errors
    /// As [`crate::validate`].
    pub fn validate(&self, data: &Data, settings: &ValidationSettings) -> Result<ValidationReport> {
        validate(&self.model, &self.maps(), data, settings)
    }

    /// Validates the estimate on every record of `data`, each on its own, and pools the
    /// simulation errors ([`crate::validate_records`]).
    ///
    /// # Errors
    /// As [`crate::validate_records`].
    pub fn validate_records(
        &self,
        data: &Data,
        settings: &ValidationSettings,
    ) -> Result<RecordsValidation> {
        validate_records(&self.model, &self.maps(), data, settings)
    }

    /// The k-step-ahead prediction on a record ([`predict`](mod@predict)).
    ///
    /// # Errors
    /// As [`predict::predict`].
    pub fn predict(&self, data: &Data, settings: &PredictionSettings) -> Result<Prediction> {
        predict::predict(&self.model, &self.maps(), data, settings)
    }
}

impl Model {
    /// Fits the maps to `data` ([`identify()`]) and returns the fitted model as an
    /// [`Estimate`]: linfa's `fit`, with [`Estimate::simulate`] and [`Estimate::predict`] as its
    /// `predict`.
    ///
    /// # Errors
    /// As [`identify()`] and [`Estimate::from_identification`].
    pub fn fit(&self, data: &Data, settings: &IdentifySettings) -> Result<Estimate> {
        let id = identify(self, data, settings)?;
        Estimate::from_identification(self, &id, data, settings)
    }
}

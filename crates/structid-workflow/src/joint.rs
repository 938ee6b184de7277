//! A model file fitted as a whole by its simulation error (`structid refine --joint`).
//!
//! A model with a latent block (one whose input u and y do not reveal,
//! [`structid_core::BlockAccess`]) starts in two steps: the model with every map held to the
//! affine part of its start is fitted by simulation error (the linear start), the maps' inputs
//! and outputs are smoothed from y with it ([`structid_joint::smooth_maps`]), and each latent
//! map, and each map without a `truth`, is fitted through its smoothed pairs with its
//! dispersion. A latent block's `truth` is then only the guess the linear start begins from.
//!
//! From the file: the LFT (its entries named free in the request move, the others stay), each
//! static block as a Gaussian kernel expansion on fixed centres ([`GaussianFeatures`]) or, with
//! a `fourier` dispersion, as Fourier features on its input's range ([`FourierFeatures`]), each
//! block whose `truth` declares `parameters` as that parametric family ([`FamilyMap`], its
//! parameters fitted and written back), and each `operator` block as the hysteresis operator it
//! declares. A static block with a `shape` is a monotone map ([`MonotoneFeatures`], its slope
//! the square of a Gaussian kernel expansion), increasing or decreasing everywhere, beyond the
//! data too. A static block starts from its
//! `truth` when the file gives one (a previous estimate written as a table, a guess), from zero
//! otherwise. Its centres are spread over the range its input covers when the starting model
//! is simulated on the estimation data, so a block of an unmeasured signal gets centres where
//! that signal goes. [`structid_joint::fit()`] then fits everything at once.
//!
//! β is given, or chosen from a grid by the simulation RMS on a validation record, simulated
//! from rest. The fitted model is written back as a model file: the LFT with its fitted
//! entries, each static map as a table of its values over its input's range, each operator
//! with its fitted parameters.

use std::path::Path;
use std::sync::Arc;

use structid_core::validation::Windows;
use structid_core::{Data, Interpolant, LookupTable, Signal, Simulation};
use structid_io::{BlockSpec, DispersionSpec, ModelFile, OutputGuard, TruthSpec};
use structid_joint::LinearInParameters;
use structid_joint::windowed::simulate_windows;
use structid_joint::{
    BlockMap, FamilyMap, FixedMap, FourierFeatures, GaussianFeatures, JointBlock, JointFit,
    JointModel, JointSettings, MonotoneFeatures, OperatorBlock, fit,
};

use crate::error::{Result, WorkflowError};
use crate::free::parse_free;

/// The β grid that `auto` searches on validation records: 10⁻¹⁰, 10⁻⁹, …, 10⁻² (a decade
/// apart, since the validation error changes little within one).
///
/// ```
/// let g = structid_workflow::joint::default_beta_grid();
/// assert_eq!((g.len(), g[0], g[8]), (9, 1e-10, 1e-2));
/// ```
pub fn default_beta_grid() -> Vec<f64> {
    (0..9).map(|i| 10f64.powi(i - 10)).collect()
}

/// How β, the weight of every static map's dispersion, is set.
#[derive(Clone, Debug)]
pub enum BetaChoice {
    /// This β.
    Fixed(f64),
    /// The β of `grid` whose fit simulates `validation` (from rest) with the smallest RMS.
    Validated {
        /// Candidate values.
        grid: Vec<f64>,
        /// The validation record(s).
        validation: Data,
    },
}

impl BetaChoice {
    /// The choice the front ends offer: β when given, else the [`default_beta_grid`] scored on
    /// `validation`; an error naming both options when neither is given.
    ///
    /// ```
    /// use structid_workflow::BetaChoice;
    /// assert!(matches!(BetaChoice::from_options(Some(1e-3), None), Ok(BetaChoice::Fixed(b)) if b == 1e-3));
    /// assert!(BetaChoice::from_options(None, None).is_err());
    /// ```
    pub fn from_options(beta: Option<f64>, validation: Option<Data>) -> Result<Self> {
        match (beta, validation) {
            (Some(b), _) => Ok(Self::Fixed(b)),
            (None, Some(validation)) => Ok(Self::Validated {
                grid: default_beta_grid(),
                validation,
            }),
            (None, None) => Err(WorkflowError::Request(
                "the joint fit needs a β, or validation records to choose it on".into(),
            )),
        }
    }

    /// As [`from_options`](Self::from_options), with `default` when neither is given: for
    /// a workflow whose map has a β that suits most data.
    ///
    /// ```
    /// use structid_workflow::BetaChoice;
    /// assert!(matches!(BetaChoice::from_options_or(None, None, 1e-8), BetaChoice::Fixed(b) if b == 1e-8));
    /// ```
    pub fn from_options_or(beta: Option<f64>, validation: Option<Data>, default: f64) -> Self {
        Self::from_options(beta, validation).unwrap_or(Self::Fixed(default))
    }
}

/// Settings of [`refine_joint`].
#[derive(Clone, Debug)]
pub struct JointWorkflowSettings {
    /// β.
    pub beta: BetaChoice,
    /// Centres per static map (per input dimension for a map of two inputs).
    pub centres: usize,
    /// The kernel width σ as a multiple of the spacing of the centres.
    pub width: f64,
    /// The free entries of G ([`parse_free`]).
    pub free: Vec<String>,
    /// The fit's own settings (segments, iterations, initial states).
    pub fit: JointSettings,
}

impl Default for JointWorkflowSettings {
    /// β = 10⁻⁶, 15 centres, σ = 1.5 spacings, nothing of G free, the fit's defaults.
    fn default() -> Self {
        Self {
            beta: BetaChoice::Fixed(1e-6),
            centres: 15,
            width: 1.5,
            free: Vec::new(),
            fit: JointSettings::default(),
        }
    }
}

/// The joint fit as the front ends ask for it: its iterations, whether each record's initial
/// state is fitted, and its criterion: single shooting (the default), multiple shooting on
/// segments of `segment_length` samples, or the score of a simulation in `windows` (each
/// window from a state fitted to its first half, scored after its first `init` samples; see
/// [`structid_joint::windowed`]).
///
/// ```
/// use structid_core::validation::Windows;
/// use structid_workflow::joint::FitOptions;
/// let o = FitOptions { windows: Some(Windows::new(200, 20).unwrap()), ..FitOptions::default() };
/// let s = o.settings().unwrap();
/// assert_eq!((s.windows(), s.polish(), s.max_iterations()), (o.windows, false, 100));
/// let both = FitOptions { segment_length: Some(100), ..o };
/// assert!(both.settings().is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitOptions {
    /// Levenberg–Marquardt iterations per stage.
    pub iterations: usize,
    /// Whether each record's initial state is fitted (otherwise each starts at rest).
    pub estimate_initial_state: bool,
    /// Samples per multiple-shooting segment.
    pub segment_length: Option<usize>,
    /// The windows whose score is the criterion (not with `segment_length`).
    pub windows: Option<Windows>,
}

impl Default for FitOptions {
    /// 100 iterations, initial states at rest, single shooting.
    fn default() -> Self {
        Self {
            iterations: 100,
            estimate_initial_state: false,
            segment_length: None,
            windows: None,
        }
    }
}

impl FitOptions {
    /// The joint fit's settings (the windowed criterion without the single-shooting polish).
    ///
    /// # Errors
    /// [`WorkflowError::OptionConflict`] for both segments and windows; the fit's own error
    /// for a value it refuses (fewer than 2 samples a segment, no iteration).
    pub fn settings(&self) -> Result<JointSettings> {
        if self.segment_length.is_some() && self.windows.is_some() {
            return Err(WorkflowError::OptionConflict {
                options: vec!["segment_length", "windows"],
                rule: "the windows are the segments of a windowed fit: give one of them".into(),
            });
        }
        let mut fit = JointSettings::builder()
            .max_iterations(self.iterations)
            .estimate_initial_state(self.estimate_initial_state);
        if let Some(l) = self.segment_length {
            fit = fit.segment_length(l);
        }
        if let Some(w) = self.windows {
            fit = fit.polish(false).windows(w);
        }
        Ok(fit.build()?)
    }
}

/// What [`refine_joint`] asks for.
#[derive(Clone, Debug)]
pub struct JointRequest<'a> {
    /// The model file.
    pub model: &'a ModelFile,
    /// The estimation data (one or several records).
    pub data: &'a Data,
    /// Settings.
    pub settings: JointWorkflowSettings,
}

/// One β tried and its validation RMS.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BetaTrial {
    /// β.
    pub beta: f64,
    /// Simulation RMS on the validation record(s), per output.
    pub validation_rms: Vec<f64>,
}

/// A static map's values, written as `map_<block>.csv`.
#[derive(Clone, Debug)]
pub struct MapTable {
    /// The block.
    pub block: String,
    /// File name (relative to the output directory).
    pub file: String,
    /// Column names: the block's z names, then `value`.
    pub names: Vec<String>,
    /// The columns.
    pub columns: Vec<Vec<f64>>,
}

/// The fitted model and how it was found.
#[derive(Clone, Debug)]
pub struct JointOutcome {
    /// The fit with the chosen β.
    pub fit: JointFit,
    /// The chosen β.
    pub beta: f64,
    /// Every β tried (one when β was given).
    pub trials: Vec<BetaTrial>,
    /// The fitted model as a model file (static maps as tables, see [`JointOutcome::tables`]).
    pub model_file: ModelFile,
    /// The static maps' tables.
    pub tables: Vec<MapTable>,
}

fn block_map(b: &BlockSpec, fixed: bool) -> Result<Box<dyn BlockMap>> {
    if let Some(op) = &b.operator {
        return Ok(Box::new(OperatorBlock::new(op.to_operator()?)));
    }
    let truth: Arc<dyn Interpolant> = match b.truth_map()? {
        Some(m) => Arc::from(m),
        None if fixed => {
            return Err(WorkflowError::Request(format!(
                "block `{}` has no `truth`; simulation needs the map of every static block",
                b.name
            )));
        }
        None => Arc::new(|_: &[f64]| 0.0),
    };
    Ok(Box::new(FixedMap::new(truth, b.inputs.len())))
}

/// The model file as a joint model with every static block a fixed map: its truth, or zero
/// unless `require_truth`.
fn fixed_model(mf: &ModelFile, require_truth: bool) -> Result<JointModel> {
    let blocks = mf
        .blocks
        .iter()
        .map(|b| {
            Ok(JointBlock::new(
                b.name.clone(),
                b.inputs.clone(),
                b.output,
                block_map(b, require_truth)?,
            ))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(JointModel::new(mf.model_lft()?, blocks)?)
}

/// Simulates a model file from u alone, with operators and maps in series: each static block
/// by its `truth`, each operator as declared. `x0` is the LFT's initial state (zero by
/// default); operators start at rest. See [`simulate_model_file_noisy`] for noise.
///
/// ```
/// use structid_io::ModelFile;
/// use structid_core::Signal;
/// let m = ModelFile::parse(r#"
///     [lft]
///     A = []
///     Dye = [[1.0]]
///     Dyw = [[1.0]]
///     Dzu = [[1.0]]
///     [signals]
///     u = ["u"]
///     y = ["y"]
///     [[nonlinearity]]
///     name = "backlash"
///     inputs = [0]
///     output = 0
///     operator = { kind = "play", half_width = 0.5 }
/// "#, None).unwrap();
/// let u = Signal::new(1, vec![0.0, 1.0, 0.8, -1.0]).unwrap();
/// let sim = structid_workflow::simulate_model_file(&m, &u, None).unwrap();
/// assert_eq!(sim.y.channel(0), vec![0.0, 0.5, 0.5, -0.5]);
/// ```
pub fn simulate_model_file(mf: &ModelFile, u: &Signal, x0: Option<&[f64]>) -> Result<Simulation> {
    let model = fixed_model(mf, true)?;
    if u.is_empty() {
        return Err(WorkflowError::Request("the input has no samples".into()));
    }
    let xi0 = model.rest_state(u.sample(0), x0)?;
    Ok(model.simulate(u, Some(&xi0))?)
}

/// What `structid simulate` writes: the model file simulated from rest with white Gaussian
/// noise e of standard deviation `noise_std` drawn from `seed`
/// ([`structid_core::paper::gaussian_noise`], the same draw for every kind of model). A model
/// of static maps goes through [`ModelFile::simulate`]; one with hysteresis operators through
/// the joint model, which steps their memory.
pub fn simulate_model_file_noisy(
    mf: &ModelFile,
    u: &Signal,
    noise_std: f64,
    seed: u64,
) -> Result<Simulation> {
    if mf.blocks.iter().all(|b| b.operator.is_none()) {
        let maps = mf.truth_maps()?.ok_or_else(|| {
            WorkflowError::Request(
                "a block has no `truth`; simulation needs the map of every block".into(),
            )
        })?;
        let maps: Vec<&dyn Interpolant> = maps.iter().map(|m| m.as_ref()).collect();
        return Ok(mf.simulate(&maps, u, noise_std, seed)?);
    }
    let model = fixed_model(mf, true)?;
    if u.is_empty() {
        return Err(WorkflowError::Request("the input has no samples".into()));
    }
    let ne = model.lft().dims().e;
    let e = (noise_std > 0.0)
        .then(|| structid_core::paper::gaussian_noise(u.len(), ne, noise_std, seed));
    let xi0 = model.rest_state(u.sample(0), None)?;
    Ok(model.simulate_noisy(u, e.as_ref(), Some(&xi0))?)
}

/// Each block input's range over simulations of every record of `data` from rest.
fn input_ranges(model: &JointModel, data: &Data) -> Result<Vec<(f64, f64)>> {
    let nz = model.lft().dims().z;
    let mut ranges = vec![(f64::INFINITY, f64::NEG_INFINITY); nz];
    for r in data.records() {
        let sim = model.simulate(r.u(), None).map_err(|e| {
            WorkflowError::Request(format!(
                "the starting model cannot be simulated on the estimation data ({e}); give a stable \
                 starting G or starting maps (`truth`) that keep it stable"
            ))
        })?;
        for (c, range) in ranges.iter_mut().enumerate() {
            for v in sim.z.channel(c) {
                range.0 = range.0.min(v);
                range.1 = range.1.max(v);
            }
        }
    }
    Ok(ranges)
}

/// Centres over `ranges` (one per input): `m` per dimension, a grid for several inputs.
fn features(ranges: &[(f64, f64)], m: usize, width: f64, beta: f64) -> Result<GaussianFeatures> {
    let axes: Vec<Vec<f64>> = ranges
        .iter()
        .map(|&(lo, hi)| {
            let pad = 0.05 * (hi - lo).max(1e-6);
            let (lo, hi) = (lo - pad, hi + pad);
            (0..m)
                .map(|j| lo + (hi - lo) * j as f64 / (m - 1) as f64)
                .collect()
        })
        .collect();
    let spacing = axes
        .iter()
        .map(|a| a[1] - a[0])
        .fold(f64::INFINITY, f64::min);
    let mut centres: Vec<Vec<f64>> = vec![Vec::new()];
    for axis in &axes {
        centres = centres
            .iter()
            .flat_map(|c| axis.iter().map(move |v| [c.as_slice(), &[*v]].concat()))
            .collect();
    }
    Ok(GaussianFeatures::new(centres, width * spacing, beta)?)
}

/// A block with a `fourier` dispersion (with or without a trend) as Fourier features on the
/// padded `ranges` of its inputs: σ as given or 0.1 × the largest range, the harmonics as given
/// or as the weights resolve, the combination as given. `None` for the other dispersions.
fn fourier(
    d: &DispersionSpec,
    ranges: &[(f64, f64)],
    beta: f64,
) -> Result<Option<FourierFeatures>> {
    let (sigma, harmonics, additive) = match d {
        DispersionSpec::Fourier {
            sigma,
            harmonics,
            additive,
        } => (*sigma, *harmonics, *additive),
        DispersionSpec::WithTrend { kernel, .. } => return fourier(kernel, ranges, beta),
        _ => return Ok(None),
    };
    let domain: Vec<(f64, f64)> = ranges
        .iter()
        .map(|&(lo, hi)| {
            let pad = 0.05 * (hi - lo).max(1e-6);
            (lo - pad, hi + pad)
        })
        .collect();
    // σ as the Gaussian's default: 0.1 × the largest range of the block's inputs.
    let widest = ranges.iter().map(|(a, b)| b - a).fold(0.0, f64::max);
    let sigma = sigma.unwrap_or(0.1 * widest);
    let kernel = structid_core::FourierKernel::new(
        &structid_core::FourierWeights::GaussianLike { sigma },
        harmonics,
        domain,
        if additive {
            structid_core::Combination::Additive
        } else {
            structid_core::Combination::Tensor
        },
    )?;
    Ok(Some(FourierFeatures::new(kernel, beta)?))
}

/// What every β's start shares: the blocks' start maps (their `truth`, or zero), the ranges
/// their inputs cover, the LFT; and, with a latent block, the linear start and the smoothed
/// signals ([`Base::latent`]), which do not depend on β either.
struct Base {
    fixed: JointModel,
    ranges: Vec<(f64, f64)>,
    lft: structid_core::Lft,
    smoothed: Option<structid_joint::SmoothedMaps>,
}

impl Base {
    fn of(mf: &ModelFile, data: &Data, s: &JointWorkflowSettings) -> Result<Self> {
        let fixed = fixed_model(mf, false)?;
        let ranges = input_ranges(&fixed, data)?;
        let access = mf.block_access()?;
        let latent = mf
            .blocks
            .iter()
            .zip(&access)
            .any(|(b, a)| *a == structid_core::BlockAccess::Latent && b.operator.is_none());
        let base = Self {
            fixed,
            ranges,
            lft: mf.model_lft()?,
            smoothed: None,
        };
        if latent {
            return base.latent(mf, data, s);
        }
        Ok(base)
    }

    /// The starting joint model for `beta`: static blocks as features fitted to their start
    /// maps (or, with a latent block, through their smoothed pairs), and each record's start
    /// state when the smoothing gave one.
    fn start(
        &self,
        mf: &ModelFile,
        s: &JointWorkflowSettings,
        beta: f64,
    ) -> Result<(JointModel, Option<Vec<Vec<f64>>>)> {
        let model = assemble(
            mf,
            &self.fixed,
            &self.ranges,
            self.smoothed.as_ref(),
            s,
            beta,
            self.lft.clone(),
        )?;
        Ok((
            model,
            self.smoothed.as_ref().map(|m| m.initial_states.clone()),
        ))
    }
}

/// The joint model with each static block as features over `ranges` (of its inputs), fitted
/// to its start map, or through its smoothed pairs when `smoothed` is given and the block is
/// latent or has no `truth`; operators as they are.
fn assemble(
    mf: &ModelFile,
    fixed: &JointModel,
    ranges: &[(f64, f64)],
    smoothed: Option<&structid_joint::SmoothedMaps>,
    s: &JointWorkflowSettings,
    beta: f64,
    lft: structid_core::Lft,
) -> Result<JointModel> {
    let mut blocks = Vec::with_capacity(mf.blocks.len());
    let access = mf.block_access()?;
    for ((spec, b), access) in mf.blocks.iter().zip(fixed.blocks()).zip(&access) {
        if spec.operator.is_some() {
            blocks.push(b.clone());
            continue;
        }
        let family = matches!(spec.truth, Some(TruthSpec::Family { .. }));
        if spec.shape.is_some() && (family || spec.inputs.len() != 1) {
            return Err(WorkflowError::Request(format!(
                "block `{}` declares a shape, which only a static map of one input that is not \
                 a named family can have",
                spec.name
            )));
        }
        if let Some(law) = spec
            .truth
            .as_ref()
            .map(|t| t.family(spec.inputs.len()))
            .transpose()?
            .flatten()
        {
            // A named family keeps its law and starts from the values declared.
            blocks.push(JointBlock::new(
                spec.name.clone(),
                spec.inputs.clone(),
                spec.output,
                Box::new(FamilyMap::new(law)),
            ));
            continue;
        }
        let r: Vec<(f64, f64)> = spec.inputs.iter().map(|&i| ranges[i]).collect();
        if r.iter()
            .any(|(lo, hi)| hi.partial_cmp(lo) != Some(std::cmp::Ordering::Greater))
        {
            return Err(WorkflowError::Request(format!(
                "block `{}`: its input does not move when the starting model is simulated on the \
                 estimation data, so its map cannot be placed; a latent block needs an input that \
                 the data excite (check its z row, or start it from a `truth`)",
                spec.name
            )));
        }
        let f = features(&r, s.centres, s.width, beta)?;
        let (points, values): (Vec<Vec<f64>>, Vec<f64>) = match smoothed {
            Some(sm) if spec.truth.is_none() || *access == structid_core::BlockAccess::Latent => (
                (0..sm.z.len())
                    .map(|k| spec.inputs.iter().map(|&c| sm.z.get(k, c)).collect())
                    .collect(),
                sm.w.channel(spec.output),
            ),
            _ => {
                let points = f.centres().to_vec();
                let values = points.iter().map(|z| b.map.eval(&mut [], z)).collect();
                (points, values)
            }
        };
        let map: Box<dyn BlockMap> = match (spec.shape, fourier(&spec.dispersion, &r, beta)?) {
            (Some(_), Some(_)) => {
                return Err(WorkflowError::Request(format!(
                    "block `{}` declares `shape` with a `fourier` dispersion; a monotone map's \
                     slope is a Gaussian kernel expansion, so give it a `gaussian` dispersion",
                    spec.name
                )));
            }
            (Some(direction), None) => {
                let centres = f.centres().iter().map(|c| c[0]).collect();
                let m = MonotoneFeatures::new(centres, f.sigma(), beta, direction)?;
                Box::new(m.fitted_to(&points, &values)?)
            }
            (None, Some(ff)) => Box::new(ff.fitted_to(&points, &values)?),
            (None, None) => Box::new(f.fitted_to(&points, &values)?),
        };
        blocks.push(JointBlock::new(
            spec.name.clone(),
            spec.inputs.clone(),
            spec.output,
            map,
        ));
    }
    parse_free(JointModel::new(lft, blocks)?, &s.free)
}

impl Base {
    /// The start of a model with a latent block, in two steps. First the linear start: every
    /// static map held to the affine part of its start (its `truth`, or zero), fitted by
    /// simulation error with G's free entries and multiple shooting (a range its input does not
    /// cover at the start is widened to a unit one: only the affine part moves). Then the maps'
    /// inputs and outputs are smoothed from y with it ([`structid_joint::smooth_maps`]); each
    /// map's centres are placed over its smoothed input, and a latent map, or one without a
    /// `truth`, is fitted through its smoothed pairs with its dispersion. G's free entries start
    /// at the linear start's values, and each record's LFT state starts at its smoothed x̂₀. A
    /// latent block whose input the linear start does not tie to y (its map stayed flat) is an
    /// error that asks for a start.
    fn latent(self, mf: &ModelFile, data: &Data, s: &JointWorkflowSettings) -> Result<Self> {
        let widened: Vec<(f64, f64)> = self
            .ranges
            .iter()
            .map(|&(lo, hi)| {
                if hi > lo {
                    (lo, hi)
                } else {
                    (lo - 0.5, lo + 0.5)
                }
            })
            .collect();
        let pinned = assemble(
            mf,
            &self.fixed,
            &widened,
            None,
            s,
            PINNED_BETA,
            self.lft.clone(),
        )?;
        let segment = s
            .fit
            .segment_length()
            .unwrap_or((data.len() / 20).clamp(50, 500));
        let settings = JointSettings::builder()
            .segment_length(segment)
            .continuity_weight(s.fit.continuity_weight())
            .max_iterations(s.fit.max_iterations())
            .tolerance(s.fit.tolerance())
            .estimate_initial_state(true)
            .build()?;
        let linear = fit(&pinned, data, None, &settings)?.model;
        let smoothed = structid_joint::smooth_maps(&linear, data, NOISE_SHARE)?;
        let access = mf.block_access()?;
        if let Some(b) = mf.blocks.iter().zip(&access).find_map(|(b, a)| {
            (*a == structid_core::BlockAccess::Latent
                && b.inputs.iter().any(|&c| !smoothed.observable[c]))
            .then_some(b)
        }) {
            return Err(WorkflowError::Request(format!(
                "block `{}` is latent, and the linear start does not tie its input to y (its map \
                 stays flat there, so y carries no trace of that signal): give it a start, a \
                 `truth` with the right sign of slope such as `truth = \"0.1*z0\"`",
                b.name
            )));
        }
        let ranges = (0..smoothed.z.channels())
            .map(|c| {
                let z = smoothed.z.channel(c);
                let lo = z.iter().copied().fold(f64::INFINITY, f64::min);
                (lo, z.iter().copied().fold(f64::NEG_INFINITY, f64::max))
            })
            .collect();
        Ok(Self {
            fixed: self.fixed,
            ranges,
            lft: linear.lft().clone(),
            smoothed: Some(smoothed),
        })
    }
}

/// The β that holds a kernel expansion to its affine part in the linear start of latent blocks.
const PINNED_BETA: f64 = 1e6;

/// The share of y's standard deviation the latent smoothing expects to be noise (its result
/// barely moves between 0.01 and 0.3).
const NOISE_SHARE: f64 = 0.1;

fn validation_rms(model: &JointModel, validation: &Data, windows: Option<Windows>) -> Vec<f64> {
    let ny = validation.y().channels();
    if let Some(w) = windows {
        // A model fitted in windows is scored in the same windows.
        return simulate_windows(model, validation, w)
            .map_or_else(|_| vec![f64::INFINITY; ny], |s| s.rms);
    }
    let mut sum = vec![0.0; ny];
    for r in validation.records() {
        let Ok(sim) = model.simulate(r.u(), None) else {
            return vec![f64::INFINITY; ny];
        };
        for (c, s) in sum.iter_mut().enumerate() {
            *s += r
                .y()
                .channel(c)
                .iter()
                .zip(sim.y.channel(c))
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>();
        }
    }
    sum.iter()
        .map(|s| (s / validation.len() as f64).sqrt())
        .collect()
}

/// Fits the model file as a whole; see the [module documentation](self).
///
/// # Errors
/// A model file whose static block has more than two inputs, a starting model that cannot be
/// simulated, a block whose input does not move, bad free entries, and the fit's errors.
pub fn refine_joint(req: &JointRequest<'_>) -> Result<JointOutcome> {
    let mf = req.model;
    let s = &req.settings;
    if let Some(b) = mf
        .blocks
        .iter()
        .find(|b| b.operator.is_none() && b.inputs.len() > 2)
    {
        return Err(WorkflowError::Request(format!(
            "block `{}` reads {} inputs; the joint fit places its centres on a grid, for maps of one or two inputs",
            b.name,
            b.inputs.len()
        )));
    }
    if s.centres < 2 || !(s.width.is_finite() && s.width > 0.0) {
        return Err(WorkflowError::Request(
            "centres must be at least 2 and the width positive".into(),
        ));
    }
    let base = Base::of(mf, req.data, s)?;
    let (beta, fit, trials) = over_betas(&s.beta, s.fit.windows(), |beta| {
        let (start, x0) = base.start(mf, s, beta)?;
        Ok(fit(&start, req.data, x0.as_deref(), &s.fit)?)
    })?;
    let (model_file, tables) = written(mf, &fit, req.data, s.fit.windows())?;
    Ok(JointOutcome {
        fit,
        beta,
        trials,
        model_file,
        tables,
    })
}

/// Runs `fit_with` for each β of `choice` and keeps the fit with the smallest validation RMS
/// (summed over outputs), or the only one for a fixed β: the chosen β, its fit and every trial.
pub(crate) fn over_betas(
    choice: &BetaChoice,
    windows: Option<Windows>,
    mut fit_with: impl FnMut(f64) -> Result<JointFit>,
) -> Result<(f64, JointFit, Vec<BetaTrial>)> {
    let (grid, validation) = match choice {
        BetaChoice::Fixed(b) => (vec![*b], None),
        BetaChoice::Validated { grid, validation } => (grid.clone(), Some(validation)),
    };
    let mut trials = Vec::new();
    let mut best: Option<(f64, JointFit, f64)> = None;
    for &beta in &grid {
        let f = fit_with(beta)?;
        let score = match validation {
            Some(v) => {
                let rms = validation_rms(&f.model, v, windows);
                let total = rms.iter().map(|r| r * r).sum::<f64>();
                trials.push(BetaTrial {
                    beta,
                    validation_rms: rms,
                });
                total
            }
            None => f.cost,
        };
        if best.as_ref().is_none_or(|(_, _, b)| score < *b) {
            best = Some((beta, f, score));
        }
    }
    let (beta, fit, _) =
        best.ok_or_else(|| WorkflowError::Request("the β grid is empty".into()))?;
    Ok((beta, fit, trials))
}

/// The fitted model as a model file, with each static map tabulated over the range its input
/// covers in the fitted model's simulation of the data (a shaped map over one more range width
/// on each side).
pub(crate) fn written(
    mf: &ModelFile,
    f: &JointFit,
    data: &Data,
    windows: Option<Windows>,
) -> Result<(ModelFile, Vec<MapTable>)> {
    let mut ranges = vec![(f64::INFINITY, f64::NEG_INFINITY); f.model.lft().dims().z];
    let mut widen = |z: &Signal| {
        for (c, range) in ranges.iter_mut().enumerate() {
            for v in z.channel(c) {
                range.0 = range.0.min(v);
                range.1 = range.1.max(v);
            }
        }
    };
    // The z of the simulation the fit was scored by: a model fitted in windows may drift in a
    // free run, away from the z its windows visit.
    match windows {
        Some(w) => widen(&simulate_windows(&f.model, data, w)?.z),
        None => {
            for (r, rec) in data.records().iter().enumerate() {
                widen(&f.model.simulate(rec.u(), Some(&f.initial_states[r]))?.z);
            }
        }
    }
    let z_names = mf.z_names();
    let mut out = mf.clone();
    out.lft = f.model.lft().clone();
    out.linear = None;
    out.path = None;
    let mut tables = Vec::new();
    for (spec, b) in out.blocks.iter_mut().zip(f.model.blocks()) {
        if let Some(op) = &spec.operator {
            spec.operator = Some(op.with_parameters(&b.map.parameters()));
            continue;
        }
        if let Some(TruthSpec::Family { parameters, .. }) = &mut spec.truth {
            for ((_, v), fitted) in parameters.iter_mut().zip(b.map.parameters()) {
                *v = fitted;
            }
            continue;
        }
        // 400 intervals across the range along one input, 40 per axis over two: far finer than
        // the centres, so the table keeps the fitted map. A map with a declared shape goes its
        // way beyond the data by construction, so its table carries on at the same spacing over
        // one more range width on each side, along the map's tail slope; other maps are held at
        // the edges of the range they were fitted on.
        let intervals = if spec.inputs.len() == 1 { 400 } else { 40 };
        let extra = if spec.shape.is_some() { intervals } else { 0 };
        let axes: Vec<Vec<f64>> = spec
            .inputs
            .iter()
            .map(|&i| {
                let (lo, hi) = ranges[i];
                let hi = if hi > lo { hi } else { lo + 1.0 };
                let step = (hi - lo) / intervals as f64;
                (0..=intervals + 2 * extra)
                    .map(|j| lo + step * (j as f64 - extra as f64))
                    .collect()
            })
            .collect();
        let mut rows: Vec<Vec<f64>> = vec![Vec::new()];
        for axis in &axes {
            rows = rows
                .iter()
                .flat_map(|r| axis.iter().map(move |v| [r.as_slice(), &[*v]].concat()))
                .collect();
        }
        for r in &mut rows {
            let v = b.map.eval(&mut [], r);
            r.push(v);
        }
        let table = LookupTable::from_rows(&rows)?;
        let file = format!("map_{}.csv", spec.name);
        let mut names: Vec<String> = spec.inputs.iter().map(|&i| z_names[i].clone()).collect();
        names.push("value".into());
        let columns = (0..names.len())
            .map(|c| rows.iter().map(|r| r[c]).collect())
            .collect();
        tables.push(MapTable {
            block: spec.name.clone(),
            file: file.clone(),
            names,
            columns,
        });
        spec.truth = Some(TruthSpec::Table { file, table });
    }
    Ok((out, tables))
}

/// Writes `model.toml`, the map tables and `joint.json` into `dir` (atomically, never over a
/// protected input of `guard`).
pub fn write_joint_outputs(outcome: &JointOutcome, dir: &Path, guard: &OutputGuard) -> Result<()> {
    guard.create_dir(dir)?;
    for t in &outcome.tables {
        guard.write_csv(&dir.join(&t.file), &t.names, &t.columns)?;
    }
    guard.write(
        &dir.join("model.toml"),
        outcome.model_file.to_toml_string().as_bytes(),
    )?;
    let stages: Vec<serde_json::Value> = outcome
        .fit
        .stages
        .iter()
        .map(|s| {
            serde_json::json!({
                "name": s.name,
                "segments": s.segments,
                "costs": s.costs,
                "status": format!("{:?}", s.status),
            })
        })
        .collect();
    let free: Vec<serde_json::Value> = outcome
        .fit
        .model
        .free_entries()
        .iter()
        .zip(outcome.fit.model.parameters())
        .map(|(e, v)| serde_json::json!({"matrix": format!("{:?}", e.matrix), "row": e.row, "col": e.col, "value": v}))
        .collect();
    let json = serde_json::json!({
        "beta": outcome.beta,
        "trials": outcome.trials,
        "initial_cost": outcome.fit.initial_cost,
        "cost": outcome.fit.cost,
        "rms": outcome.fit.rms,
        "initial_states": outcome.fit.initial_states,
        "free": free,
        "stages": stages,
    });
    let text =
        serde_json::to_string_pretty(&json).map_err(|e| WorkflowError::Request(e.to_string()))?;
    guard.write(&dir.join("joint.json"), text.as_bytes())?;
    Ok(())
}

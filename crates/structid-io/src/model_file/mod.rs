//! Model files: the known linear block, the signal names and the unknown static maps, in TOML.
//!
//! # Format
//!
//! ```toml
//! [lft]                      # discrete-time realisation of the known block, paper eq. (7)
//! sample_time = 1.0          # optional
//! A = [[0.5]]                # n×n ; an empty list [] when n = 0
//! Bu = [[1.0]]
//! Be = [[0.0]]
//! Bw = [[1.0]]
//! Cy = [[1.0]]
//! Dyu = [[0.0]]
//! Dye = [[1.0]]
//! Dyw = [[0.0]]
//! Cz = [[0.0]]
//! Dzu = [[1.0]]
//! Dze = [[0.0]]
//! Dzw = [[0.0]]
//!
//! [signals]
//! u = ["u0"]                 # CSV column names of the known inputs, in order
//! y = ["y0"]                 # CSV column names of the measured outputs, in order
//! # z = ["z0"]               # optional: measured z columns; otherwise z is computed from u and y
//!
//! [[nonlinearity]]
//! name = "f"
//! inputs = [0]               # indices into z
//! output = 0                 # index into w
//! dispersion = { kind = "gaussian", sigma = 0.4 }
//! truth = "tanh(z0)"         # optional, used by `simulate` and for error reports
//! ```
//!
//! ## `[lft]`
//! The twelve matrices of x⁺ = A x + Bu u + Be e + Bw w, y = Cy x + Dyu u + Dye e + Dyw w,
//! z = Cz x + Dzu u + Dze e + Dzw w, each a list of rows. Dimensions are inferred: n from the
//! rows of A, n_u from `[signals].u`, n_y from `[signals].y`, n_e from the columns of Be, Dye or
//! Dze, n_w from the columns of Bw, Dyw or Dzw, and n_z from the rows of Cz, Dzu, Dze or Dzw
//! (or from `[signals].z`). A matrix with a zero dimension may be written `[]` (for example
//! `A = []`, `Bu = []` and `Cy = []` when n = 0). An omitted matrix is all zeros. Integers are
//! accepted where numbers are expected.
//!
//! `time = "continuous"` (with `sample_time` required) declares A, Bu, Be and Bw as a
//! continuous-time realisation, discretised by a zero-order hold on the whole input [u e w]
//! (C and D are unchanged). The default is `time = "discrete"`.
//!
//! ## `[linear]` (instead of `[lft]`)
//! A polynomial linear block G with one output, y = Σ_i B_i(q)/F(q)·u_i, placed in a named
//! structure from which the LFT is built ([`LinearSpec`]):
//!
//! ```toml
//! [linear]
//! structure = "output-feedback"
//! sample_time = 0.1              # optional (T_s of rate feedback; 1 when omitted)
//! den = [1.0, -1.2, 0.5]         # F(q) = 1 + f₁q⁻¹ + f₂q⁻²
//! num = [[0.0, 0.3, 0.2]]        # per input u: coefficients of 1, q⁻¹, … (leading zeros = delay)
//! # num_w = [0.0, -0.3, -0.2]    # output feedback only: the feedback path's own numerator
//! ```
//!
//! | `structure` | model | z (measurable because) |
//! |---|---|---|
//! | `"output-feedback"` | y = G·(u − N(y)) + e | z = y, measured |
//! | `"input"` | y = G·N(u) + e | z = u |
//! | `"output"` | y = N(G·u) + e (a sensor map) | z = G·u, depends on u only |
//! | `"rate-feedback"` | y = G·(u − N(ẏ)) + e, ẏ_k = (y_k − y_(k−1))/T_s | z = Δy/T_s = Ψ(q)·y with the LTI Ψ = (1 − q⁻¹)/T_s, a dynamic Ψ_M |
//! | `"lti"` | y = G·u + e | no map |
//!
//! `num` has one numerator per input u; `input`, `output` and `rate-feedback` take exactly one
//! input. The feedback structures need a delay in G (num starting with 0), otherwise y_k would
//! depend on N(y_k) or N(ẏ_k); `num_w` applies to `output-feedback` only. Every structure but
//! `lti` has one map (`inputs = [0]`, `output = 0`); `[signals].z` is not used. Every
//! structure with a map can be refined by `structid refine` (and an `[lft]` whose one map
//! sits at a location that is one of them; see `structid_core::refine::LinearStructure::from_lft`).
//!
//! ## `[[nonlinearity]]`
//! One table per unknown static map: a unique `name`, the z channels it reads (`inputs`, indices
//! into z), the w channel it writes (`output`), its `dispersion` and optionally its `truth`.
//! Every w channel must be written by exactly one block — except in a *nominal* `[lft]` model
//! (a file without blocks), whose w columns and z rows are declared injection points and signals
//! for `structid discover` (see `[discover]`); [`ModelFile::model_lft`] and
//! [`ModelFile::to_model`] drop the w columns (w = 0).
//!
//! * `dispersion = { kind = "gaussian", sigma = 0.4 }`: the Gaussian RKHS dispersion. When
//!   `sigma` is omitted (or the whole `dispersion` key is), σ is chosen when the data are known:
//!   **σ = 0.1 × the largest range (max − min) of the block's input channels of z** (0.1 when
//!   that range is zero). Supported kinds: `gaussian`.
//! * `truth = "tanh(z0)"`: the true map as an expression in `z0, z1, …` (the block's inputs in
//!   order, or `z` for a single input); see [`structid_core::ExprMap`].
//! * `truth = { table = "file.csv" }` (or `table = "file.csv"` in the block): a lookup table, a
//!   CSV file with a header and columns `z…, value` (piecewise linear in one input, bilinear on
//!   a complete grid in two), the path relative to the model file's directory. A trailing
//!   column `std` (the posterior standard deviation in the map files of `structid identify`)
//!   is ignored.
//!
//! ## `[discover]` (nominal models only)
//! What a nominal model ([`DiscoverSpec`]) declares for `structid discover`: extra candidate
//! locations of a missing block on its declared channels, and states named for localisation.
//!
//! ```toml
//! [discover]
//! locations = [ { name = "spring", z = 0, w = 0 } ]   # a block reading z row 0, writing w column 0
//! states = [ { name = "velocity", state = 1 } ]        # state 1 of the LFT, named
//! ```
//!
//! Indices are 0-based and must exist (z < n_z, w < n_w, state < n); names are non-empty and
//! unique, and a location may not be called like a built-in one ([`BUILT_IN_LOCATIONS`],
//! `declared-<i>`); each (z, w) pair is declared once. The section is rejected in a file with
//! `[[nonlinearity]]` blocks. Both keys are optional (`[[discover.locations]]` tables work too).
//!
//! Every error names the line of the offending key.

mod discover;
mod dispersion;
mod lft;
mod linear;
mod nonlinearity;
mod operator;
mod signals;
mod source;
mod structure;
mod write;

use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use serde::Deserialize;
use structid_core::paper::gaussian_noise;
use structid_core::{
    BlockPlace, Data, Interpolant, Lft, LftMatrices, MapBinding, Model, NonlinearBlock, Simulation,
};
use structid_lti::Signal;
use toml::Spanned;

use crate::data_file::DataTable;
use crate::error::IoError;

pub use discover::{BUILT_IN_LOCATIONS, DeclaredLocationSpec, DiscoverSpec, NamedStateSpec};
pub use dispersion::{DispersionSpec, SUPPORTED_DISPERSIONS, default_sigma};
pub(crate) use dispersion::{dispersion_from_table, dispersion_keys};
pub use linear::{LINEAR_STRUCTURES, LinearSpec, parse_linear_structure};
pub use nonlinearity::{BlockSpec, TruthSpec};
pub use operator::OperatorSpec;
pub use signals::SignalNames;
use source::check_unique_name;
pub(crate) use source::{Source, err_at, toml_error, value_kind};
pub use structure::SiteBlock;

use discover::{RawDiscover, parse_discover};
use dispersion::parse_dispersion;
use lft::{RawLft, parse_lft};
use linear::{RawLinear, parse_linear};
use nonlinearity::{RawBlock, parse_index_list, parse_shape, parse_truth};
use signals::{RawSignals, check_names};
use source::plural;

/// A parsed and validated model file.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelFile {
    /// The known linear block (discrete time).
    pub lft: Lft,
    /// The polynomial form of the linear block when the file gives `[linear]` instead of
    /// `[lft]` (then `lft` is its realisation).
    pub linear: Option<LinearSpec>,
    /// Data column names.
    pub signals: SignalNames,
    /// The unknown static maps, in file order.
    pub blocks: Vec<BlockSpec>,
    /// The `[discover]` section of a nominal model (one without blocks): declared candidate
    /// locations and named states for `structid discover`.
    pub discover: Option<DiscoverSpec>,
    /// The file it was read from.
    pub path: Option<PathBuf>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    lft: Option<Spanned<RawLft>>,
    linear: Option<Spanned<RawLinear>>,
    signals: Spanned<RawSignals>,
    #[serde(default)]
    nonlinearity: Vec<Spanned<RawBlock>>,
    discover: Option<Spanned<RawDiscover>>,
}

/// The LFT without its w columns: a nominal model, whose declared injection points carry
/// w = 0 (its z rows are kept).
fn without_w(lft: &Lft) -> Result<Lft, IoError> {
    let m = lft.matrices();
    let d = lft.dims();
    let nominal = Lft::new(LftMatrices {
        bw: DMatrix::zeros(d.states, 0),
        dyw: DMatrix::zeros(d.y, 0),
        dzw: DMatrix::zeros(d.z, 0),
        ..m.clone()
    })?;
    Ok(match lft.sample_time() {
        Some(ts) => nominal.with_sample_time(ts)?,
        None => nominal,
    })
}

impl ModelFile {
    /// Reads and validates a model file. Relative truth-table paths are resolved against the
    /// file's directory.
    pub fn from_path(path: &Path) -> Result<Self, IoError> {
        let text = std::fs::read_to_string(path).map_err(|source| IoError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let base = path.parent().filter(|p| !p.as_os_str().is_empty());
        let mut mf = Self::parse(&text, Some(base.unwrap_or(Path::new("."))))
            .map_err(|e| e.with_path(path))?;
        mf.path = Some(path.to_path_buf());
        Ok(mf)
    }

    /// Parses and validates model-file text. `base_dir` resolves relative truth-table paths
    /// (the current directory when `None`).
    ///
    /// ```
    /// use structid_io::ModelFile;
    /// let text = r#"
    /// [lft]
    /// A = []
    /// Dyw = [[1.0]]
    /// Dye = [[1.0]]
    /// Dzu = [[1.0]]
    /// [signals]
    /// u = ["u"]
    /// y = ["y"]
    /// [[nonlinearity]]
    /// name = "N"
    /// inputs = [0]
    /// output = 0
    /// truth = "tanh(z0)"
    /// "#;
    /// let m = ModelFile::parse(text, None).unwrap();
    /// assert_eq!(m.lft.dims().states, 0);
    /// let bad = text.replace("Dzu = [[1.0]]", "Dzu = [[1.0, 2.0]]");
    /// let e = ModelFile::parse(&bad, None).unwrap_err().to_string();
    /// assert_eq!(e, "model file: matrix Dzu has 2 columns but [signals].u names 1 input (line 6)");
    /// ```
    pub fn parse(text: &str, base_dir: Option<&Path>) -> Result<Self, IoError> {
        let src = Source::new(text);
        let raw: RawFile = toml::from_str(text).map_err(|e| toml_error(&e, &src))?;
        let signals_line = src.line(raw.signals.span().start);
        let raw_signals = raw.signals.into_inner();

        // Signals.
        let u = match &raw_signals.u {
            Some(list) => check_names(list, "u", &src)?,
            None => Vec::new(),
        };
        let (y, y_line) = match &raw_signals.y {
            Some(list) => (check_names(list, "y", &src)?, src.line(list.span().start)),
            None => (Vec::new(), signals_line),
        };
        if y.is_empty() {
            return Err(err_at(
                y_line,
                "[signals].y names no measured output; list the CSV column(s) of y, e.g. y = [\"y0\"]",
            ));
        }
        let z_names = match &raw_signals.z {
            Some(list) => Some((check_names(list, "z", &src)?, src.line(list.span().start))),
            None => None,
        };

        let (lft, dz, dw, lft_line, linear) = match (raw.lft, raw.linear) {
            (Some(raw_lft), None) => {
                let lft_line = src.line(raw_lft.span().start);
                let (lft, dz, dw) =
                    parse_lft(raw_lft.into_inner(), lft_line, &u, &y, &z_names, &src)?;
                (lft, dz, dw, lft_line, None)
            }
            (None, Some(raw_linear)) => {
                let line = src.line(raw_linear.span().start);
                let (spec, lft, dz, dw) =
                    parse_linear(raw_linear.into_inner(), line, &u, &y, &z_names, &src)?;
                (lft, dz, dw, line, Some(spec))
            }
            (Some(_), Some(raw_linear)) => {
                return Err(err_at(
                    src.line(raw_linear.span().start),
                    "the file has both [lft] and [linear]; give the linear block one way",
                ));
            }
            (None, None) => {
                return Err(err_at(
                    1,
                    "the file has neither [lft] (a state-space LFT) nor [linear] (a polynomial \
                     linear block with a named structure)",
                ));
            }
        };

        // Blocks.
        let mut blocks: Vec<BlockSpec> = Vec::with_capacity(raw.nonlinearity.len());
        let mut block_lines: Vec<usize> = Vec::new();
        let mut owner: Vec<Option<usize>> = vec![None; dw.value];
        for entry in &raw.nonlinearity {
            let entry_line = src.line(entry.span().start);
            let rb = entry.get_ref();
            let name = rb.name.get_ref().trim().to_string();
            let name_line = src.line(rb.name.span().start);
            if name.is_empty() {
                return Err(err_at(
                    name_line,
                    "a [[nonlinearity]] block has an empty name",
                ));
            }
            let earlier = blocks.iter().position(|b| b.name == name);
            check_unique_name(
                "[[nonlinearity]] blocks",
                &name,
                name_line,
                earlier,
                &block_lines,
            )?;
            let inputs = parse_index_list(&rb.inputs, &name, &src)?;
            if let Some(&bad) = inputs.iter().find(|&&i| i >= dz.value) {
                return Err(err_at(
                    src.line(rb.inputs.span().start),
                    format!(
                        "block `{name}` reads z[{bad}] but the model has {}: {}",
                        plural(dz.value, "z signal"),
                        dz.source
                    ),
                ));
            }
            let out_line = src.line(rb.output.span().start);
            let output = *rb.output.get_ref();
            if output < 0 || output as u64 >= dw.value as u64 {
                let what = format!("block `{name}` writes w[{output}]");
                return Err(dw.out_of_range(out_line, &what, "w signal"));
            }
            let output = output as usize;
            if let Some(j) = owner[output] {
                return Err(err_at(
                    out_line,
                    format!(
                        "blocks `{}` (line {}) and `{name}` both write w[{output}]; each w channel needs exactly one block",
                        blocks[j].name, block_lines[j]
                    ),
                ));
            }
            owner[output] = Some(blocks.len());
            let dispersion = parse_dispersion(rb.dispersion.as_ref(), &name, &src)?;
            let truth = parse_truth(rb, &name, inputs.len(), base_dir, &src)?;
            let operator = match &rb.operator {
                Some(op) => {
                    let line = src.line(op.span().start);
                    if truth.is_some() || rb.dispersion.is_some() || inputs.len() != 1 {
                        return Err(err_at(
                            line,
                            format!(
                                "block `{name}` is a hysteresis operator: it reads exactly one z \
                                 channel and has no truth, table or dispersion"
                            ),
                        ));
                    }
                    Some(operator::parse_operator(op.get_ref(), &name, line)?)
                }
                None => None,
            };
            let shape = parse_shape(rb, &name, inputs.len(), truth.as_ref(), &src)?;
            blocks.push(BlockSpec {
                name,
                inputs,
                output,
                dispersion,
                truth,
                operator,
                shape,
            });
            block_lines.push(entry_line);
        }

        // Discovery: a nominal model's declared locations and named states.
        let discover = match &raw.discover {
            Some(d) => {
                if let Some(first) = block_lines.first() {
                    return Err(err_at(
                        src.line(d.span().start),
                        format!(
                            "[discover] describes a nominal model for discovery, but the \
                             file has {} (the first at line {first}); remove [discover] or the blocks",
                            plural(blocks.len(), "[[nonlinearity]] block")
                        ),
                    ));
                }
                Some(parse_discover(d.get_ref(), &lft, &dz, &dw, &src)?)
            }
            None => None,
        };

        // Every w channel needs its block, except in a nominal [lft] model (no blocks), whose
        // w columns are declared injection points.
        let nominal = blocks.is_empty() && linear.is_none();
        if !nominal && let Some(c) = owner.iter().position(Option::is_none) {
            let unused = if linear.is_none() {
                "; unused w columns (injection points declared for discovery, see \
                 [discover]) are only allowed in a nominal model without [[nonlinearity]] blocks"
            } else {
                ""
            };
            return Err(err_at(
                dw.line.unwrap_or(lft_line),
                format!(
                    "w[{c}] is not produced by any block ({}); add a [[nonlinearity]] with output = {c}{unused}",
                    dw.source
                ),
            ));
        }

        let signals = SignalNames {
            u,
            y,
            z: z_names.map(|(n, _)| n),
        };
        let mf = Self {
            lft,
            linear,
            signals,
            blocks,
            discover,
            path: None,
        };
        // Safety net: the core's own validation must agree (an operator block is checked for
        // its place like a static one).
        mf.build_model(Some(1.0), None)?;
        Ok(mf)
    }

    /// Builds the core [`Model`]: each block's dispersion with σ from `sigma_override`, else
    /// from the file, else [`default_sigma`] of the block's channels of `z_for_defaults` (the
    /// full z signal, L × n_z), which is then required. A nominal model (no blocks) drops its
    /// w columns, the injection points it declares for `structid discover`: there w = 0.
    pub fn to_model(
        &self,
        sigma_override: Option<f64>,
        z_for_defaults: Option<&Signal>,
    ) -> Result<Model, IoError> {
        if let Some(s) = sigma_override
            && !(s.is_finite() && s > 0.0)
        {
            return Err(IoError::InvalidArgument(format!(
                "invalid sigma {s}: it must be a finite number greater than zero"
            )));
        }
        let nz = self.lft.dims().z;
        if let Some(z) = z_for_defaults
            && z.channels() != nz
        {
            return Err(IoError::InvalidArgument(format!(
                "the z signal for default kernel widths has {} channel(s) but the model has {nz}",
                z.channels()
            )));
        }
        if let Some(b) = self.blocks.iter().find(|b| b.operator.is_some()) {
            return Err(IoError::InvalidArgument(format!(
                "block `{}` is a hysteresis operator, which identification by the dispersion \
                 criterion cannot fit (it fits static maps); fit the model by its simulation \
                 error with the joint fit",
                b.name
            )));
        }
        if let Some(b) = self.blocks.iter().find(|b| b.shape.is_some()) {
            return Err(IoError::InvalidArgument(format!(
                "block `{}` declares `shape`, which identification by the dispersion criterion \
                 cannot keep (it fits unconstrained maps); fit the model by its simulation error \
                 with the joint fit, or remove `shape`",
                b.name
            )));
        }
        self.build_model(sigma_override, z_for_defaults)
    }

    /// The core [`Model`] of the file's structure, every block with a placeholder dispersion:
    /// what simulates and validates the file with maps that are given (its truths, an
    /// estimate), where dispersions play no part. Unlike [`to_model`](Self::to_model) it
    /// accepts a block with a `shape` (its map is given, so there is nothing to constrain).
    /// A hysteresis operator is still refused: it is no static map.
    pub fn structure_model(&self) -> Result<Model, IoError> {
        if let Some(b) = self.blocks.iter().find(|b| b.operator.is_some()) {
            return Err(IoError::InvalidArgument(format!(
                "block `{}` is a hysteresis operator, not a static map; simulate the model with \
                 its operators through the joint model",
                b.name
            )));
        }
        self.build_model(Some(1.0), None)
    }

    fn build_model(
        &self,
        sigma_override: Option<f64>,
        z_for_defaults: Option<&Signal>,
    ) -> Result<Model, IoError> {
        let mut blocks = Vec::with_capacity(self.blocks.len());
        for b in &self.blocks {
            let bz = z_for_defaults.map(|z| z.select_channels(&b.inputs));
            let d = b
                .dispersion
                .build(sigma_override, bz.as_ref())
                .map_err(|e| match e {
                    IoError::InvalidArgument(m) => {
                        IoError::InvalidArgument(format!("block `{}`: {m}", b.name))
                    }
                    other => other,
                })?;
            blocks.push(NonlinearBlock::new(
                b.name.clone(),
                b.inputs.clone(),
                b.output,
                d,
            ));
        }
        Ok(Model::new(self.model_lft()?, blocks)?)
    }

    /// Simulates the model from rest with `maps` in the loop (one per block, in file order,
    /// e.g. [`ModelFile::truth_maps`]) and, when `noise_std` > 0, white Gaussian noise e of
    /// that standard deviation drawn from `seed` ([`structid_core::paper::gaussian_noise`]):
    /// the record `structid simulate --noise-std --seed` writes. A nominal model's declared w
    /// columns carry w = 0 ([`ModelFile::model_lft`]).
    ///
    /// # Errors
    /// A wrong number of maps, an algebraic loop, an input with the wrong number of channels.
    ///
    /// ```
    /// use structid_io::ModelFile;
    /// use structid_lti::Signal;
    /// let m = ModelFile::parse(r#"
    ///     [lft]
    ///     A = [[0.5]]
    ///     Bw = [[1.0]]
    ///     Cy = [[1.0]]
    ///     Dye = [[1.0]]
    ///     Dzu = [[1.0]]
    ///     [signals]
    ///     u = ["u"]
    ///     y = ["y"]
    ///     [[nonlinearity]]
    ///     name = "N"
    ///     inputs = [0]
    ///     output = 0
    ///     dispersion = { kind = "polynomial", degree = 1 }
    ///     truth = "2*z0"
    /// "#, None).unwrap();
    /// let maps = m.truth_maps().unwrap().unwrap();
    /// let maps: Vec<_> = maps.iter().map(|m| m.as_ref()).collect();
    /// let u = Signal::from_fn(3, 1, |_, _| 1.0);
    /// let sim = m.simulate(&maps, &u, 0.0, 0).unwrap();
    /// assert_eq!(sim.y.channel(0), vec![0.0, 2.0, 3.0]);
    /// ```
    pub fn simulate(
        &self,
        maps: &[&dyn Interpolant],
        u: &Signal,
        noise_std: f64,
        seed: u64,
    ) -> Result<Simulation, IoError> {
        if maps.len() != self.blocks.len() {
            return Err(structid_core::Error::DimensionMismatch {
                what: "number of maps for simulation".into(),
                expected: self.blocks.len().to_string(),
                found: maps.len().to_string(),
            }
            .into());
        }
        self.evaluation_order()?;
        let lft = self.model_lft()?;
        let e = (noise_std > 0.0).then(|| gaussian_noise(u.len(), lft.dims().e, noise_std, seed));
        let places = self.blocks.iter().map(|b| (b.inputs.as_slice(), b.output));
        Ok(lft.simulate(&MapBinding::zip(places, maps), u, e.as_ref(), None)?)
    }

    /// The order in which the blocks are evaluated within a sample: maps in series (D_zw ≠ 0)
    /// after the maps they read ([`Lft::evaluation_order`]).
    ///
    /// # Errors
    /// An algebraic loop naming the blocks of a cycle.
    ///
    /// ```
    /// use structid_io::ModelFile;
    /// // A dead zone feeding a saturation: the saturation reads the dead zone's output.
    /// let m = ModelFile::parse(r#"
    ///     [lft]
    ///     A = []
    ///     Dye = [[1.0]]
    ///     Dyw = [[0.0, 1.0]]
    ///     Dzu = [[0.0], [1.0]]
    ///     Dzw = [[1.0, 0.0], [0.0, 0.0]]
    ///     [signals]
    ///     u = ["u"]
    ///     y = ["y"]
    ///     [[nonlinearity]]
    ///     name = "saturation"
    ///     inputs = [0]
    ///     output = 1
    ///     [[nonlinearity]]
    ///     name = "dead_zone"
    ///     inputs = [1]
    ///     output = 0
    /// "#, None).unwrap();
    /// assert_eq!(m.evaluation_order().unwrap(), vec![1, 0]);
    /// ```
    pub fn evaluation_order(&self) -> Result<Vec<usize>, IoError> {
        Ok(self.model_lft()?.evaluation_order(&self.places())?)
    }

    /// Whether identification can compute z from u and y: with measured z always; otherwise
    /// the maps must not form a cycle (an algebraic loop, naming its blocks), and every block's
    /// input must be computable: an error names each block in series or latent
    /// ([`ModelFile::block_access`]), which the joint fit handles instead.
    pub fn check_z_computable(&self) -> Result<(), IoError> {
        if self.signals.z.is_none() {
            self.evaluation_order()?;
            self.model_lft()?.check_blocks_computable(&self.places())?;
            self.lft.check_no_algebraic_loop()?;
        }
        Ok(())
    }

    /// How the paper's identification reaches each block (in file order): computable from u
    /// and y, in series after other blocks, or latent ([`structid_core::BlockAccess`]); with
    /// measured z every block is computable.
    pub fn block_access(&self) -> Result<Vec<structid_core::BlockAccess>, IoError> {
        if self.signals.z.is_some() {
            return Ok(vec![
                structid_core::BlockAccess::Computable;
                self.blocks.len()
            ]);
        }
        Ok(self.model_lft()?.block_access(&self.places())?)
    }

    fn places(&self) -> Vec<BlockPlace<'_>> {
        self.blocks
            .iter()
            .map(|b| BlockPlace {
                name: &b.name,
                inputs: &b.inputs,
                output: b.output,
            })
            .collect()
    }

    /// The LFT that identification and simulation use: [`ModelFile::lft`] itself, except in a
    /// nominal model (no blocks), whose w columns — injection points declared for
    /// `structid discover` — are dropped (w = 0; the z rows are kept).
    ///
    /// ```
    /// use structid_io::ModelFile;
    /// let m = ModelFile::parse(r#"
    ///     [lft]
    ///     A = [[0.5]]
    ///     Bu = [[1.0]]
    ///     Bw = [[-1.0]]
    ///     Cy = [[1.0]]
    ///     Dye = [[1.0]]
    ///     Cz = [[1.0]]
    ///     [signals]
    ///     u = ["u"]
    ///     y = ["y"]
    ///     [discover]
    ///     locations = [{ name = "spring", z = 0, w = 0 }]
    /// "#, None).unwrap();
    /// assert_eq!(m.lft.dims().w, 1);
    /// assert_eq!(m.model_lft().unwrap().dims().w, 0);
    /// ```
    pub fn model_lft(&self) -> Result<Lft, IoError> {
        if self.blocks.is_empty() && self.lft.dims().w > 0 {
            without_w(&self.lft)
        } else {
            Ok(self.lft.clone())
        }
    }

    /// Gives every block the dispersion `spec` (as `structid identify --dispersion` does). When
    /// `spec` has no σ, each block keeps the σ of its own dispersion, if it had one.
    ///
    /// ```
    /// use structid_io::{DispersionSpec, ModelFile};
    /// let mut m = ModelFile::parse(r#"
    ///     [lft]
    ///     A = []
    ///     Dye = [[1.0]]
    ///     Dyw = [[1.0]]
    ///     Dzu = [[1.0]]
    ///     [signals]
    ///     u = ["u"]
    ///     y = ["y"]
    ///     [[nonlinearity]]
    ///     name = "N"
    ///     inputs = [0]
    ///     output = 0
    ///     dispersion = { kind = "gaussian", sigma = 0.5 }
    /// "#, None).unwrap();
    /// m.replace_dispersions(&DispersionSpec::Fourier { sigma: None, harmonics: None, additive: false });
    /// assert_eq!(m.blocks[0].dispersion.kind(), "fourier");
    /// assert_eq!(m.blocks[0].dispersion.sigma(), Some(0.5));
    /// ```
    pub fn replace_dispersions(&mut self, spec: &DispersionSpec) {
        for b in &mut self.blocks {
            b.dispersion = match spec.sigma() {
                Some(_) => spec.clone(),
                None => spec.with_sigma(b.dispersion.sigma()),
            };
        }
    }

    /// The true maps in block order, when **every** block has a `truth`; `None` otherwise.
    pub fn truth_maps(&self) -> Result<Option<Vec<Box<dyn Interpolant>>>, IoError> {
        let mut out = Vec::with_capacity(self.blocks.len());
        for b in &self.blocks {
            match b.truth_map()? {
                Some(m) => out.push(m),
                None => return Ok(None),
            }
        }
        Ok(Some(out))
    }

    /// Names of the z channels: `[signals].z` when z is measured, otherwise `z0, z1, …`.
    pub fn z_names(&self) -> Vec<String> {
        match &self.signals.z {
            Some(z) => z.clone(),
            None => (0..self.lft.dims().z).map(|i| format!("z{i}")).collect(),
        }
    }

    /// The record named by `[signals]`: u, y and, when listed, measured z.
    pub fn select_data(&self, table: &DataTable) -> Result<Data, IoError> {
        let u = table.select(&self.signals.u)?;
        let y = table.select(&self.signals.y)?;
        let data = Data::new(u, y)?;
        Ok(match &self.signals.z {
            Some(z) => data.with_z(table.select(z)?)?,
            None => data,
        })
    }

    /// z for a record: the measured columns when present, otherwise computed from u and y
    /// (see [`Lft::compute_z`]).
    pub fn z_signal(&self, data: &Data) -> Result<Signal, IoError> {
        match data.z() {
            Some(z) => Ok(z.clone()),
            None => Ok(self.lft.compute_z(data.u(), data.y())?.0),
        }
    }

    /// z for data of one or several records ([`Data::from_records`]): [`ModelFile::z_signal`]
    /// of each record, from its own start, stacked.
    pub fn z_of_records(&self, data: &Data) -> Result<Signal, IoError> {
        if data.record_count() == 1 {
            return self.z_signal(data);
        }
        let mut values = Vec::new();
        let mut channels = 0;
        for r in data.records() {
            let z = self.z_signal(&r)?;
            channels = z.channels();
            values.extend_from_slice(z.as_slice());
        }
        Ok(Signal::new(channels, values).map_err(structid_core::Error::from)?)
    }

    /// Refuses data on which a block's input z does not vary: the data then show its map at
    /// one point only (a single sample, or a constant input), and an estimate would be a guess
    /// everywhere else. `source` names the data in the message (e.g. the file names). Models
    /// whose z cannot be computed from the data are left to the solver. The error is
    /// [`IoError::InvalidArgument`].
    ///
    /// ```
    /// use structid_core::Data;
    /// use structid_io::ModelFile;
    /// use structid_lti::Signal;
    /// let mf = ModelFile::parse(
    ///     "[linear]\nstructure = \"input\"\nden = [1.0, -0.5]\nnum = [[0.0, 1.0]]\n\
    ///      [signals]\nu = [\"u\"]\ny = [\"y\"]\n\
    ///      [[nonlinearity]]\nname = \"N\"\ninputs = [0]\noutput = 0\n\
    ///      dispersion = { kind = \"gaussian\", sigma = 0.3 }\n",
    ///     None,
    /// )?;
    /// let flat = Data::new(Signal::from_fn(50, 1, |_, _| 1.0), Signal::zeros(50, 1))?;
    /// let e = mf.check_excitation(&flat, "flat.csv").unwrap_err();
    /// assert!(e.to_string().contains("is constant"), "{e}");
    /// let ramp = Data::new(Signal::from_fn(50, 1, |k, _| k as f64), Signal::zeros(50, 1))?;
    /// assert!(mf.check_excitation(&ramp, "ramp.csv").is_ok());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn check_excitation(&self, data: &Data, source: &str) -> Result<(), IoError> {
        let Ok(z) = self.z_of_records(data) else {
            return Ok(());
        };
        let names = self.z_names();
        for b in &self.blocks {
            let constant = b.inputs.iter().copied().find(|&i| {
                i < z.channels() && {
                    let c = z.channel(i);
                    c.iter().all(|v| *v == c[0])
                }
            });
            if let Some(i) = constant {
                let z_name = names.get(i).cloned().unwrap_or_else(|| format!("z{i}"));
                return Err(IoError::InvalidArgument(format!(
                    "the input `{z_name}` of block `{}` is constant ({}) over the {} sample(s) of \
                     `{}`: the data show its map at one point only; identify on a record that \
                     excites it",
                    b.name,
                    z.channel(i).first().copied().unwrap_or(f64::NAN),
                    data.len(),
                    source
                )));
            }
        }
        Ok(())
    }

    /// Refuses a kernel width σ that is absurd for the data: more than [`SIGMA_SPAN`] times
    /// wider or narrower than the range of a block's input z (a kernel flat over the data, or
    /// a spike at each sample). `what` names σ in the message (`--sigma`, `sigma`). Models
    /// whose z cannot be computed from the data are left to the solver. The error is
    /// [`IoError::InvalidArgument`].
    ///
    /// ```
    /// use structid_core::Data;
    /// use structid_io::ModelFile;
    /// use structid_lti::Signal;
    /// let mf = ModelFile::parse(
    ///     "[linear]\nstructure = \"input\"\nden = [1.0, -0.5]\nnum = [[0.0, 1.0]]\n\
    ///      [signals]\nu = [\"u\"]\ny = [\"y\"]\n\
    ///      [[nonlinearity]]\nname = \"N\"\ninputs = [0]\noutput = 0\n\
    ///      dispersion = { kind = \"gaussian\", sigma = 0.3 }\n",
    ///     None,
    /// )?;
    /// let data = Data::new(Signal::from_fn(50, 1, |k, _| k as f64 / 49.0), Signal::zeros(50, 1))?;
    /// assert!(mf.check_sigma(0.1, &data, "sigma").is_ok());
    /// let e = mf.check_sigma(1e7, &data, "sigma").unwrap_err();
    /// assert!(e.to_string().starts_with("invalid value 1e7 for sigma"), "{e}");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn check_sigma(&self, sigma: f64, data: &Data, what: &str) -> Result<(), IoError> {
        let Ok(z) = self.z_of_records(data) else {
            return Ok(());
        };
        let names = self.z_names();
        for b in &self.blocks {
            for &i in b.inputs.iter().filter(|&&i| i < z.channels()) {
                let c = z.channel(i);
                let (lo, hi) = c
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                        (l.min(*v), h.max(*v))
                    });
                let range = hi - lo;
                if !(range.is_finite() && range > 0.0) {
                    continue;
                }
                if sigma > SIGMA_SPAN * range || sigma < range / SIGMA_SPAN {
                    let z_name = names.get(i).cloned().unwrap_or_else(|| format!("z{i}"));
                    return Err(IoError::InvalidArgument(format!(
                        "invalid value {sigma:e} for {what}: the input `{z_name}` of block `{}` \
                         spans {range:.4e}, and a kernel {:.0e} times {} than that is {}; give σ \
                         between {:.1e} and {:.1e} ({SIGMA_SPAN:.0e} times narrower or wider than \
                         the range; the default is 0.1 × the range)",
                        b.name,
                        if sigma > range {
                            sigma / range
                        } else {
                            range / sigma
                        },
                        if sigma > range { "wider" } else { "narrower" },
                        if sigma > range {
                            "flat over the data (the map is a constant)"
                        } else {
                            "a spike at each sample (the map is zero between them)"
                        },
                        range / SIGMA_SPAN,
                        range * SIGMA_SPAN
                    )));
                }
            }
        }
        Ok(())
    }
}

/// How many times wider or narrower than the range of a block's input a kernel width σ may
/// be before [`ModelFile::check_sigma`] refuses it.
pub const SIGMA_SPAN: f64 = 1e6;

#[cfg(test)]
mod tests;

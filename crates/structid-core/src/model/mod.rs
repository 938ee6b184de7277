//! The structured model: the known LFT plus its list of unknown static blocks, and the data.

pub mod interpolant;
pub mod lft;
pub mod maps;
pub mod measurability;
pub mod simulate;
pub mod structure;

use std::fmt;
use std::sync::Arc;

use structid_lti::Signal;

use crate::dispersion::Dispersion;
use crate::error::{Error, Result};
use crate::lft::Lft;

/// One unknown static map N^\[i\]: it reads the z channels `inputs` and produces w channel `output`.
#[derive(Clone)]
pub struct NonlinearBlock {
    /// Name used in reports and output files.
    pub name: String,
    /// Indices of the z signals it reads (p_i of them).
    pub inputs: Vec<usize>,
    /// Index of the w signal it produces.
    pub output: usize,
    /// The dispersion that measures the complexity of this map.
    pub dispersion: Arc<dyn Dispersion>,
}

impl NonlinearBlock {
    /// A block reading `inputs` of z and writing w channel `output`.
    pub fn new(
        name: impl Into<String>,
        inputs: Vec<usize>,
        output: usize,
        dispersion: Arc<dyn Dispersion>,
    ) -> Self {
        Self {
            name: name.into(),
            inputs,
            output,
            dispersion,
        }
    }
}

impl fmt::Debug for NonlinearBlock {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("NonlinearBlock")
            .field("name", &self.name)
            .field("inputs", &self.inputs)
            .field("output", &self.output)
            .field("dispersion", &self.dispersion.describe())
            .finish()
    }
}

/// An LFT together with its nonlinear blocks; every w channel is produced by exactly one block.
///
/// ```
/// use std::sync::Arc;
/// use nalgebra::dmatrix;
/// use structid_core::{KernelDispersion, Lft, LftMatrices, Model, NonlinearBlock};
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![0.5], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
/// }).unwrap();
/// let f = NonlinearBlock::new("f", vec![0], 0, Arc::new(KernelDispersion::gaussian(0.4).unwrap()));
/// let model = Model::new(lft, vec![f]).unwrap();
/// assert_eq!(model.blocks().len(), 1);
/// ```
#[derive(Clone, Debug)]
pub struct Model {
    lft: Lft,
    blocks: Vec<NonlinearBlock>,
}

impl Model {
    /// Validates that block inputs index existing z channels, that block names are unique and
    /// that each w channel has exactly one block.
    pub fn new(lft: Lft, blocks: Vec<NonlinearBlock>) -> Result<Self> {
        let dims = lft.dims();
        let mut owner: Vec<Option<&str>> = vec![None; dims.w];
        for (i, b) in blocks.iter().enumerate() {
            if b.name.is_empty() {
                return Err(Error::InvalidStructure(format!(
                    "block {i} has an empty name"
                )));
            }
            if blocks[..i].iter().any(|o| o.name == b.name) {
                return Err(Error::InvalidStructure(format!(
                    "two blocks are named `{}`; names must be unique",
                    b.name
                )));
            }
            if b.inputs.is_empty() {
                return Err(Error::InvalidStructure(format!(
                    "block `{}` reads no z signal (inputs is empty)",
                    b.name
                )));
            }
            if let Some(&bad) = b.inputs.iter().find(|&&j| j >= dims.z) {
                return Err(Error::MissingZ {
                    block: b.name.clone(),
                    index: bad,
                    available: dims.z,
                });
            }
            if b.output >= dims.w {
                return Err(Error::MissingW {
                    block: b.name.clone(),
                    index: b.output,
                    available: dims.w,
                });
            }
            if let Some(other) = owner[b.output] {
                return Err(Error::InvalidStructure(format!(
                    "blocks `{other}` and `{}` both write w[{}]",
                    b.name, b.output
                )));
            }
            owner[b.output] = Some(&b.name);
        }
        if let Some(c) = owner.iter().position(Option::is_none) {
            return Err(Error::InvalidStructure(format!(
                "w[{c}] is not produced by any nonlinear block; add a [[nonlinearity]] with output = {c}"
            )));
        }
        Ok(Self { lft, blocks })
    }

    /// The linear block.
    pub fn lft(&self) -> &Lft {
        &self.lft
    }

    /// The nonlinear blocks, in the order given.
    pub fn blocks(&self) -> &[NonlinearBlock] {
        &self.blocks
    }

    /// A copy with every block's dispersion replaced by `f(block)`.
    pub fn with_dispersions(
        &self,
        mut f: impl FnMut(&NonlinearBlock) -> Arc<dyn Dispersion>,
    ) -> Self {
        let blocks = self
            .blocks
            .iter()
            .map(|b| NonlinearBlock {
                dispersion: f(b),
                ..b.clone()
            })
            .collect();
        Self {
            lft: self.lft.clone(),
            blocks,
        }
    }
}

/// A measured record: known input u, measured output y and, optionally, measured z.
#[derive(Clone, Debug, PartialEq)]
pub struct Data {
    u: Signal,
    y: Signal,
    z: Option<Signal>,
}

fn check_finite(name: &str, s: &Signal) -> Result<()> {
    for k in 0..s.len() {
        for (c, &v) in s.sample(k).iter().enumerate() {
            if !v.is_finite() {
                return Err(Error::NonFiniteData {
                    signal: name.into(),
                    sample: k,
                    channel: c,
                    value: v,
                });
            }
        }
    }
    Ok(())
}

impl Data {
    /// A record of equal-length, finite u and y.
    ///
    /// ```
    /// use structid_core::Data;
    /// use structid_lti::Signal;
    /// let u = Signal::from_fn(10, 1, |k, _| k as f64);
    /// let y = Signal::from_fn(10, 1, |_, _| f64::NAN);
    /// assert!(Data::new(u, y).is_err());
    /// ```
    pub fn new(u: Signal, y: Signal) -> Result<Self> {
        if u.len() != y.len() {
            return Err(Error::DimensionMismatch {
                what: "data length (u and y)".into(),
                expected: format!("{} samples of y like u", u.len()),
                found: format!("{} samples", y.len()),
            });
        }
        if y.is_empty() {
            return Err(Error::InvalidStructure(
                "the data record has no samples".into(),
            ));
        }
        check_finite("u", &u)?;
        check_finite("y", &y)?;
        Ok(Self { u, y, z: None })
    }

    /// Adds measured z (paper Definition 1, case 1).
    pub fn with_z(mut self, z: Signal) -> Result<Self> {
        if z.len() != self.y.len() {
            return Err(Error::DimensionMismatch {
                what: "data length (z)".into(),
                expected: format!("{} samples", self.y.len()),
                found: format!("{} samples", z.len()),
            });
        }
        check_finite("z", &z)?;
        self.z = Some(z);
        Ok(self)
    }

    /// Number of samples L.
    pub fn len(&self) -> usize {
        self.y.len()
    }

    /// Whether the record is empty (never true for a constructed `Data`).
    pub fn is_empty(&self) -> bool {
        self.y.is_empty()
    }

    /// Known input.
    pub fn u(&self) -> &Signal {
        &self.u
    }

    /// Measured output.
    pub fn y(&self) -> &Signal {
        &self.y
    }

    /// Measured z, when supplied.
    pub fn z(&self) -> Option<&Signal> {
        self.z.as_ref()
    }

    /// Checks the record's channel counts against an LFT.
    pub fn check_against(&self, lft: &Lft) -> Result<()> {
        let d = lft.dims();
        let pairs = [("u", self.u.channels(), d.u), ("y", self.y.channels(), d.y)];
        for (name, found, expected) in pairs {
            if found != expected {
                return Err(Error::DimensionMismatch {
                    what: format!("number of {name} channels in the data"),
                    expected: expected.to_string(),
                    found: found.to_string(),
                });
            }
        }
        if let Some(z) = &self.z
            && z.channels() != d.z
        {
            return Err(Error::DimensionMismatch {
                what: "number of measured z channels in the data".into(),
                expected: d.z.to_string(),
                found: z.channels().to_string(),
            });
        }
        Ok(())
    }
}

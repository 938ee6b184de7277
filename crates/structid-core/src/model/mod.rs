//! The structured model: the known LFT plus its list of unknown static blocks, and the data.

pub mod access;
pub mod hysteresis;
pub mod interpolant;
pub mod lft;
pub mod maps;
pub mod measurability;
pub mod monotone;
pub mod order;
pub mod parametric;
pub mod series;
pub mod simulate;
pub mod structure;

use std::fmt;
use std::sync::Arc;

use structid_lti::Signal;

use crate::dispersion::Dispersion;
use crate::error::{Error, Result};
use crate::model::lft::Lft;

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

    /// The order in which the blocks are evaluated within a sample (indices into
    /// [`Model::blocks`]): maps in series after the maps they read through D_zw
    /// ([`Lft::evaluation_order`]).
    ///
    /// # Errors
    /// [`Error::AlgebraicLoop`] naming the blocks of a cycle.
    pub fn evaluation_order(&self) -> Result<Vec<usize>> {
        self.lft.evaluation_order(&self.places())
    }

    /// Where each block sits, for [`Lft::evaluation_order`].
    pub fn places(&self) -> Vec<order::BlockPlace<'_>> {
        self.blocks
            .iter()
            .map(|b| order::BlockPlace {
                name: &b.name,
                inputs: &b.inputs,
                output: b.output,
            })
            .collect()
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

/// Measured data: known input u, measured output y and, optionally, measured z, in one or
/// several records.
///
/// Several records are separate experiments on the same system (MATLAB's multi-experiment
/// `iddata`): each starts from its own initial state, so identification restarts the linear
/// recursions at every record and, when the initial state is estimated, estimates one per
/// record. [`Data::u`], [`Data::y`] and [`Data::z`] return the records stacked one after the
/// other; [`Data::record_bounds`] says where each starts.
#[derive(Clone, Debug, PartialEq)]
pub struct Data {
    u: Signal,
    y: Signal,
    z: Option<Signal>,
    /// Where each record starts, then the total length: `[0, L₁, …, L]`.
    bounds: Vec<usize>,
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
        let bounds = vec![0, y.len()];
        Ok(Self {
            u,
            y,
            z: None,
            bounds,
        })
    }

    /// Data of several records (experiments), each a [`Data`] of its own: same channel counts,
    /// and either all or none with measured z. One record gives it back unchanged.
    ///
    /// ```
    /// use structid_core::Data;
    /// use structid_lti::Signal;
    /// let rec = |len: usize| {
    ///     let u = Signal::from_fn(len, 1, |k, _| k as f64);
    ///     Data::new(u.clone(), u).unwrap()
    /// };
    /// let data = Data::from_records(vec![rec(10), rec(4)]).unwrap();
    /// assert_eq!(data.len(), 14);
    /// assert_eq!(data.record_bounds(), &[0, 10, 14]);
    /// assert_eq!(data.records()[1], rec(4));
    /// // Different channel counts are refused, naming the record.
    /// let two = Data::new(Signal::zeros(5, 2), Signal::zeros(5, 1)).unwrap();
    /// let e = Data::from_records(vec![rec(10), two]).unwrap_err();
    /// assert!(e.to_string().contains("record 2"), "{e}");
    /// ```
    pub fn from_records(records: Vec<Data>) -> Result<Self> {
        let Some(first) = records.first() else {
            return Err(Error::InvalidStructure("no data record was given".into()));
        };
        for (i, r) in records.iter().enumerate().skip(1) {
            let pairs = [
                ("u", first.u.channels(), r.u.channels()),
                ("y", first.y.channels(), r.y.channels()),
            ];
            for (name, expected, found) in pairs {
                if expected != found {
                    return Err(Error::DimensionMismatch {
                        what: format!(
                            "number of {name} channels in record {} (numbered from 1)",
                            i + 1
                        ),
                        expected: format!("{expected} like record 1"),
                        found: found.to_string(),
                    });
                }
            }
            match (&first.z, &r.z) {
                (None, None) => {}
                (Some(a), Some(b)) if a.channels() == b.channels() => {}
                (a, b) => {
                    let count = |z: &Option<Signal>| z.as_ref().map_or(0, Signal::channels);
                    return Err(Error::DimensionMismatch {
                        what: format!(
                            "number of measured z channels in record {} (numbered from 1)",
                            i + 1
                        ),
                        expected: format!("{} like record 1", count(a)),
                        found: count(b).to_string(),
                    });
                }
            }
        }
        let mut records = records;
        if records.len() == 1 {
            return Ok(records.pop().expect("one record"));
        }
        let stack = |part: &dyn Fn(&Data) -> &Signal| {
            let channels = part(&records[0]).channels();
            let values = records
                .iter()
                .flat_map(|r| part(r).as_slice().iter().copied())
                .collect();
            Signal::new(channels, values)
        };
        let u = stack(&|r| &r.u)?;
        let y = stack(&|r| &r.y)?;
        let z = match records[0].z {
            Some(_) => Some(stack(&|r| r.z.as_ref().expect("checked above"))?),
            None => None,
        };
        let mut bounds = vec![0];
        for r in &records {
            bounds.push(bounds.last().expect("non-empty") + r.len());
        }
        Ok(Self { u, y, z, bounds })
    }

    /// Where each record starts, followed by the total length: `[0, L₁, L₁ + L₂, …, L]`
    /// (`[0, L]` for one record).
    pub fn record_bounds(&self) -> &[usize] {
        &self.bounds
    }

    /// Number of records (1 for [`Data::new`]).
    pub fn record_count(&self) -> usize {
        self.bounds.len() - 1
    }

    /// The records as separate [`Data`] (copies of the samples).
    ///
    /// ```
    /// use structid_core::Data;
    /// use structid_lti::Signal;
    /// let d = Data::new(Signal::zeros(6, 1), Signal::zeros(6, 1)).unwrap();
    /// assert_eq!(d.records(), vec![d.clone()]);
    /// ```
    pub fn records(&self) -> Vec<Data> {
        if self.record_count() == 1 {
            return vec![self.clone()];
        }
        self.bounds
            .windows(2)
            .map(|w| Data {
                u: self.u.slice(w[0]..w[1]),
                y: self.y.slice(w[0]..w[1]),
                z: self.z.as_ref().map(|z| z.slice(w[0]..w[1])),
                bounds: vec![0, w[1] - w[0]],
            })
            .collect()
    }

    /// The data cut into `n` consecutive segments in time: every record cut into `n` parts
    /// of (nearly) equal length, and segment i made of the i-th part of every record (each
    /// part a record of its own). A test of stationarity estimates on each and compares.
    ///
    /// ```
    /// use structid_core::Data;
    /// use structid_lti::Signal;
    /// let u = Signal::from_fn(10, 1, |k, _| k as f64);
    /// let parts = Data::new(u.clone(), u).unwrap().segments(4).unwrap();
    /// let lengths: Vec<usize> = parts.iter().map(|p| p.len()).collect();
    /// assert_eq!(lengths, vec![2, 3, 2, 3]);
    /// assert_eq!(parts[1].u().get(0, 0), 2.0);
    /// ```
    ///
    /// # Errors
    /// `n` = 0, or a record shorter than `n` samples.
    pub fn segments(&self, n: usize) -> Result<Vec<Data>> {
        let mut parts: Vec<Vec<Data>> = vec![Vec::new(); n];
        for (i, r) in self.records().into_iter().enumerate() {
            let len = r.len();
            if n == 0 || len < n {
                return Err(Error::InvalidStructure(format!(
                    "record {} has {len} sample(s): it cannot be cut into {n} segments",
                    i + 1
                )));
            }
            for (j, part) in parts.iter_mut().enumerate() {
                let range = j * len / n..(j + 1) * len / n;
                part.push(Data {
                    u: r.u.slice(range.clone()),
                    y: r.y.slice(range.clone()),
                    z: r.z.as_ref().map(|z| z.slice(range.clone())),
                    bounds: vec![0, range.len()],
                });
            }
        }
        parts.into_iter().map(Data::from_records).collect()
    }

    /// Refuses data of several records where `what` handles one record only.
    pub fn require_single_record(&self, what: &str) -> Result<()> {
        if self.record_count() > 1 {
            return Err(Error::Unsupported(format!(
                "{what} takes one data record, and these data have {} records; run it on each record",
                self.record_count()
            )));
        }
        Ok(())
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

    /// Number of samples L (of all records together).
    pub fn len(&self) -> usize {
        self.y.len()
    }

    /// Whether the data are empty (never true for a constructed `Data`).
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

    /// Checks the channel counts against an LFT.
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

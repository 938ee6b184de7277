//! The joint model: an LFT with some entries free, and parametrised blocks in series or in
//! parallel, reading measured or latent signals, static or with memory.
//!
//! Its parameter vector is [G's free entries | block 1's parameters | block 2's | …].

use nalgebra::DMatrix;
use structid_core::{BlockPlace, Lft, LftMatrices};

use crate::block::BlockMap;
use crate::error::{JointError, Result};

/// One of the LFT matrices that the simulation error depends on (the noise matrices B_e,
/// D_ye and D_ze do not enter a simulation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[allow(missing_docs)]
pub enum LftMatrix {
    A,
    Bu,
    Bw,
    Cy,
    Dyu,
    Dyw,
    Cz,
    Dzu,
    Dzw,
}

impl LftMatrix {
    /// Every matrix, in the order above.
    pub const ALL: [Self; 9] = [
        Self::A,
        Self::Bu,
        Self::Bw,
        Self::Cy,
        Self::Dyu,
        Self::Dyw,
        Self::Cz,
        Self::Dzu,
        Self::Dzw,
    ];

    /// The matrix of `m`.
    pub fn of(self, m: &LftMatrices) -> &DMatrix<f64> {
        match self {
            Self::A => &m.a,
            Self::Bu => &m.bu,
            Self::Bw => &m.bw,
            Self::Cy => &m.cy,
            Self::Dyu => &m.dyu,
            Self::Dyw => &m.dyw,
            Self::Cz => &m.cz,
            Self::Dzu => &m.dzu,
            Self::Dzw => &m.dzw,
        }
    }

    fn of_mut(self, m: &mut LftMatrices) -> &mut DMatrix<f64> {
        match self {
            Self::A => &mut m.a,
            Self::Bu => &mut m.bu,
            Self::Bw => &mut m.bw,
            Self::Cy => &mut m.cy,
            Self::Dyu => &mut m.dyu,
            Self::Dyw => &mut m.dyw,
            Self::Cz => &mut m.cz,
            Self::Dzu => &mut m.dzu,
            Self::Dzw => &mut m.dzw,
        }
    }
}

/// One free entry of G: matrix, row, column.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct LftEntry {
    /// Which matrix.
    pub matrix: LftMatrix,
    /// Row.
    pub row: usize,
    /// Column.
    pub col: usize,
}

/// A block of the joint model: `w[output] = map(z[inputs])`.
#[derive(Clone, Debug)]
pub struct JointBlock {
    /// Name, for reports and errors.
    pub name: String,
    /// z channels read.
    pub inputs: Vec<usize>,
    /// w channel written.
    pub output: usize,
    /// The parametrised map.
    pub map: Box<dyn BlockMap>,
}

impl JointBlock {
    /// A block reading `inputs` and writing `output`.
    pub fn new(
        name: impl Into<String>,
        inputs: Vec<usize>,
        output: usize,
        map: Box<dyn BlockMap>,
    ) -> Self {
        Self {
            name: name.into(),
            inputs,
            output,
            map,
        }
    }
}

/// An LFT with free entries and parametrised blocks, fitted as a whole by
/// [`fit`](crate::fit()).
///
/// ```
/// use nalgebra::dmatrix;
/// use structid_core::{Lft, LftMatrices, Signal};
/// use structid_joint::{GaussianFeatures, JointBlock, JointModel, LftMatrix};
/// // x⁺ = a·x + w, y = x, w = N(u): a Hammerstein model with the pole free.
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![0.5], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
/// }).unwrap();
/// let map = GaussianFeatures::on_interval(-1.0, 1.0, 5, 0.5, 1e-6).unwrap();
/// let model = JointModel::new(lft, vec![JointBlock::new("N", vec![0], 0, Box::new(map))]).unwrap()
///     .with_free(LftMatrix::A, 0, 0).unwrap();
/// assert_eq!(model.parameters().len(), 1 + 5 + 2);
/// let sim = model.simulate(&Signal::zeros(4, 1), None).unwrap();
/// assert_eq!(sim.y.len(), 4);
/// ```
#[derive(Clone, Debug)]
pub struct JointModel {
    lft: Lft,
    free: Vec<LftEntry>,
    blocks: Vec<JointBlock>,
    order: Vec<usize>,
}

impl JointModel {
    /// An LFT with every entry fixed and its blocks: each w channel written by exactly one
    /// block, each block's inputs within z, its map's input count equal to its inputs, and no
    /// cycle of maps through D_zw.
    pub fn new(lft: Lft, blocks: Vec<JointBlock>) -> Result<Self> {
        let d = lft.dims();
        let mut writer = vec![None; d.w];
        for b in &blocks {
            if b.inputs.is_empty() || b.inputs.iter().any(|&i| i >= d.z) {
                return Err(JointError::InvalidModel(format!(
                    "block `{}` reads z{:?}, and the LFT has {} z channel(s)",
                    b.name, b.inputs, d.z
                )));
            }
            if b.map.input_len() != b.inputs.len() {
                return Err(JointError::InvalidModel(format!(
                    "block `{}` reads {} z channel(s) but its map takes {}",
                    b.name,
                    b.inputs.len(),
                    b.map.input_len()
                )));
            }
            match writer.get_mut(b.output) {
                Some(slot @ None) => *slot = Some(&b.name),
                Some(Some(other)) => {
                    return Err(JointError::InvalidModel(format!(
                        "blocks `{other}` and `{}` both write w[{}]",
                        b.name, b.output
                    )));
                }
                None => {
                    return Err(JointError::InvalidModel(format!(
                        "block `{}` writes w[{}], and the LFT has {} w channel(s)",
                        b.name, b.output, d.w
                    )));
                }
            }
        }
        if let Some(c) = writer.iter().position(Option::is_none) {
            return Err(JointError::InvalidModel(format!("no block writes w[{c}]")));
        }
        let places: Vec<BlockPlace<'_>> = blocks
            .iter()
            .map(|b| BlockPlace {
                name: &b.name,
                inputs: &b.inputs,
                output: b.output,
            })
            .collect();
        let order = lft.evaluation_order(&places)?;
        Ok(Self {
            lft,
            free: Vec::new(),
            blocks,
            order,
        })
    }

    /// Frees one entry of G (a repeated entry is an error).
    pub fn with_free(mut self, matrix: LftMatrix, row: usize, col: usize) -> Result<Self> {
        let m = matrix.of(self.lft.matrices());
        if row >= m.nrows() || col >= m.ncols() {
            return Err(JointError::InvalidModel(format!(
                "{matrix:?}[{row}][{col}] is outside the {}×{} matrix",
                m.nrows(),
                m.ncols()
            )));
        }
        let entry = LftEntry { matrix, row, col };
        if self.free.contains(&entry) {
            return Err(JointError::InvalidModel(format!(
                "{matrix:?}[{row}][{col}] is freed twice"
            )));
        }
        self.free.push(entry);
        Ok(self)
    }

    /// Frees every non-zero entry of `matrix`: the usual way to let a known structure's
    /// coefficients move while keeping its zeros (and so its structure) fixed.
    pub fn with_free_nonzero(mut self, matrix: LftMatrix) -> Result<Self> {
        let m = matrix.of(self.lft.matrices()).clone();
        for j in 0..m.ncols() {
            for i in 0..m.nrows() {
                let entry = LftEntry {
                    matrix,
                    row: i,
                    col: j,
                };
                if m[(i, j)] != 0.0 && !self.free.contains(&entry) {
                    self.free.push(entry);
                }
            }
        }
        Ok(self)
    }

    /// The model with nothing free: every entry of G fixed and every block held at its
    /// current parameters ([`crate::HeldMap`]). It simulates as `self` does, from the same
    /// stacked initial states, and a fit of it moves only those states
    /// ([`crate::fit_initial_state`]).
    pub fn held(&self) -> Self {
        Self {
            lft: self.lft.clone(),
            free: Vec::new(),
            blocks: self
                .blocks
                .iter()
                .map(|b| JointBlock {
                    map: Box::new(crate::HeldMap::new(b.map.clone())),
                    ..b.clone()
                })
                .collect(),
            order: self.order.clone(),
        }
    }

    /// The LFT at the current parameters.
    pub fn lft(&self) -> &Lft {
        &self.lft
    }

    /// The free entries of G, in parameter order.
    pub fn free_entries(&self) -> &[LftEntry] {
        &self.free
    }

    /// The blocks, in the order given.
    pub fn blocks(&self) -> &[JointBlock] {
        &self.blocks
    }

    /// The order in which the blocks are evaluated within a sample.
    pub fn evaluation_order(&self) -> &[usize] {
        &self.order
    }

    /// Length of the stacked state ξ = [x; s₁; s₂; …] (the LFT's states, then each block's).
    pub fn stacked_state_len(&self) -> usize {
        self.lft.dims().states + self.blocks.iter().map(|b| b.map.state_len()).sum::<usize>()
    }

    /// The parameter vector [G's free entries | each block's parameters].
    pub fn parameters(&self) -> Vec<f64> {
        let m = self.lft.matrices();
        let mut p: Vec<f64> = self
            .free
            .iter()
            .map(|e| e.matrix.of(m)[(e.row, e.col)])
            .collect();
        for b in &self.blocks {
            p.extend(b.map.parameters());
        }
        p
    }

    /// Where each block's parameters start in the parameter vector, and the total length.
    pub fn parameter_offsets(&self) -> Vec<usize> {
        let mut at = vec![self.free.len()];
        for b in &self.blocks {
            at.push(at.last().expect("non-empty") + b.map.parameters().len());
        }
        at
    }

    /// The same model with parameter vector `p`.
    pub fn with_parameters(&self, p: &[f64]) -> Result<Self> {
        let offsets = self.parameter_offsets();
        let total = *offsets.last().expect("non-empty");
        if p.len() != total {
            return Err(JointError::InvalidModel(format!(
                "{} parameters given, the model has {total}",
                p.len()
            )));
        }
        let mut m = self.lft.matrices().clone();
        for (e, v) in self.free.iter().zip(p) {
            e.matrix.of_mut(&mut m)[(e.row, e.col)] = *v;
        }
        let mut lft = Lft::new(m)?;
        if let Some(ts) = self.lft.sample_time() {
            lft = lft.with_sample_time(ts)?;
        }
        let blocks = self
            .blocks
            .iter()
            .enumerate()
            .map(|(i, b)| {
                Ok(JointBlock {
                    map: b.map.with_parameters(&p[offsets[i]..offsets[i + 1]])?,
                    ..b.clone()
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            lft,
            free: self.free.clone(),
            blocks,
            order: self.order.clone(),
        })
    }
}

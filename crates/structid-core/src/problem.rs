//! The identification problem in operator form, independent of how the operators are realised.
//!
//! With r = y − T_yu·u, find (e, w) with T_ye·e + Σ_i T_yw^\[i\]·w^\[i\] = r minimising
//! J = (1/L)·Σ_k e_kᵀe_k + β·Σ_i D_i(z^\[i\], w^\[i\]).
//! The operators are any [`LinearSystem`], so a user can pose a problem with an FIR or
//! impulse-response model directly with [`Problem::new`]; [`Problem::from_model`] builds it from
//! an [`crate::Lft`].

use std::sync::Arc;

use structid_lti::{LinearSystem, Signal};

use crate::dispersion::Dispersion;
use crate::error::{Error, Result};
use crate::measurability::ZSource;
use crate::model::{Data, Model};

/// One nonlinear block as the solver sees it.
#[derive(Clone)]
pub struct ProblemBlock {
    /// Name used in reports.
    pub name: String,
    /// The w channel this block produces (orders the columns of ŵ).
    pub output: usize,
    /// T_yw^\[i\]: the path from this block's output to y (n_y outputs, one input).
    pub path: Arc<dyn LinearSystem>,
    /// The block's input samples z^\[i\] (L × p_i).
    pub z: Signal,
    /// The block's dispersion.
    pub dispersion: Arc<dyn Dispersion>,
}

/// An identification problem: residual, noise path and nonlinear blocks.
#[derive(Clone)]
pub struct Problem {
    residual: Signal,
    noise: Arc<dyn LinearSystem>,
    blocks: Vec<ProblemBlock>,
    z_source: ZSource,
}

impl Problem {
    /// A problem from explicit operators. `residual` is r = y − T_yu·u (L × n_y); `noise` is T_ye
    /// (n_e inputs, n_y outputs); each block's `path` has n_y outputs and one input.
    pub fn new(residual: Signal, noise: Arc<dyn LinearSystem>, blocks: Vec<ProblemBlock>) -> Result<Self> {
        let (len, ny) = (residual.len(), residual.channels());
        if noise.outputs() != ny {
            return Err(Error::DimensionMismatch {
                what: "outputs of the noise path T_ye".into(),
                expected: ny.to_string(),
                found: noise.outputs().to_string(),
            });
        }
        if blocks.is_empty() {
            return Err(Error::InvalidStructure(
                "the problem has no nonlinear block to identify".into(),
            ));
        }
        let mut seen = vec![false; blocks.len()];
        for b in &blocks {
            match seen.get_mut(b.output) {
                Some(s) if !*s => *s = true,
                _ => {
                    return Err(Error::InvalidStructure(format!(
                        "block outputs must be the distinct channels 0..{}; block `{}` has output {}",
                        blocks.len(),
                        b.name,
                        b.output
                    )));
                }
            }
            if b.path.outputs() != ny || b.path.inputs() != 1 {
                return Err(Error::DimensionMismatch {
                    what: format!("path T_yw of block `{}`", b.name),
                    expected: format!("{ny} outputs, 1 input"),
                    found: format!("{} outputs, {} inputs", b.path.outputs(), b.path.inputs()),
                });
            }
            if b.z.len() != len {
                return Err(Error::DimensionMismatch {
                    what: format!("samples of z for block `{}`", b.name),
                    expected: len.to_string(),
                    found: b.z.len().to_string(),
                });
            }
        }
        Ok(Self {
            residual,
            noise,
            blocks,
            z_source: ZSource::Measured,
        })
    }

    /// Builds the problem from a model and a record: checks the data, computes z (measured or
    /// through [`crate::Lft::compute_z`]), r = y − L_yu·u, and splits L_yw by block.
    pub fn from_model(model: &Model, data: &Data) -> Result<Self> {
        let lft = model.lft();
        data.check_against(lft)?;
        let (z, z_source) = match data.z() {
            Some(z) => (z.clone(), ZSource::Measured),
            None => lft.compute_z(data.u(), data.y())?,
        };
        let residual = lft.residual(data.u(), data.y())?;
        let blocks = model
            .blocks()
            .iter()
            .map(|b| ProblemBlock {
                name: b.name.clone(),
                output: b.output,
                path: Arc::new(lft.t_yw_channel(b.output)),
                z: z.select_channels(&b.inputs),
                dispersion: Arc::clone(&b.dispersion),
            })
            .collect();
        let mut p = Self::new(residual, Arc::new(lft.t_ye()), blocks)?;
        p.z_source = z_source;
        Ok(p)
    }

    /// Number of samples L.
    pub fn len(&self) -> usize {
        self.residual.len()
    }

    /// Whether L = 0.
    pub fn is_empty(&self) -> bool {
        self.residual.is_empty()
    }

    /// Number of outputs n_y.
    pub fn outputs(&self) -> usize {
        self.residual.channels()
    }

    /// The residual r = y − T_yu·u.
    pub fn residual(&self) -> &Signal {
        &self.residual
    }

    /// The noise path T_ye.
    pub fn noise(&self) -> &dyn LinearSystem {
        self.noise.as_ref()
    }

    /// The blocks.
    pub fn blocks(&self) -> &[ProblemBlock] {
        &self.blocks
    }

    /// How z was obtained.
    pub fn z_source(&self) -> &ZSource {
        &self.z_source
    }
}

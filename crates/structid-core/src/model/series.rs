//! z of maps in series computed from a record, once the maps are known.
//!
//! With D_zw ≠ 0 a block's input z_k = C_z·x_k + D_zu·u_k + D_ze·e_k + D_zw·w_k reads other
//! blocks' outputs of the same sample. Identification cannot compute such a z from u and y, as
//! w is what it looks for; but once the maps N̂ are known (validation, prediction), it can: split
//! z = z_own + D_zw·w, where z_own is the block's z rows with D_zw set to zero. When z_own is
//! computable from u and y ([`crate::BlockAccess::InSeries`]), evaluating the blocks in their
//! [`Model::evaluation_order`] gives every z exactly, each from outputs ŵ already computed:
//!
//! ```text
//!   z_b = z_own,b(u, y) + D_zw[b, :]·ŵ,   ŵ_b = N̂_b(z_b),   b in evaluation order
//! ```
//!
//! A latent block (its z_own not computable from u and y) has no such z in general: a model
//! with one can be simulated, not predicted one step ahead. The exception is an output-error
//! model, whose noise reaches neither the state nor z (B_e = 0, D_ze = 0): there every z is a
//! function of u alone, the simulation's from rest, and the one-step predictor is the
//! simulation ([`crate::Lft::noise_free_z`]).

use structid_lti::Signal;

use crate::error::{Error, Result};
use crate::model::Model;
use crate::model::access::BlockAccess;
use crate::model::interpolant::Interpolant;

impl Model {
    /// z computed from the record (u, y) with the maps `maps` (one per block, in block order)
    /// evaluated in order where blocks are in series (see the [module docs](self)). With
    /// D_zw = 0 it is [`crate::Lft::compute_z`].
    ///
    /// ```
    /// use nalgebra::{DMatrix, dmatrix};
    /// use structid_core::{Data, GaussianKernel, Interpolant, KernelDispersion, Lft, LftMatrices, Model, NonlinearBlock, Signal};
    /// use std::sync::Arc;
    /// // y = N₂(N₁(u)) + e: z₀ = u, z₁ = w₀ (D_zw), y = w₁ + e.
    /// let lft = Lft::new(LftMatrices {
    ///     a: DMatrix::zeros(0, 0), bu: DMatrix::zeros(0, 1), be: DMatrix::zeros(0, 1),
    ///     bw: DMatrix::zeros(0, 2), cy: DMatrix::zeros(1, 0), dyu: dmatrix![0.0], dye: dmatrix![1.0],
    ///     dyw: dmatrix![0.0, 1.0], cz: DMatrix::zeros(2, 0), dzu: dmatrix![1.0; 0.0],
    ///     dze: dmatrix![0.0; 0.0], dzw: dmatrix![0.0, 0.0; 1.0, 0.0],
    /// }).unwrap();
    /// let d = Arc::new(KernelDispersion::gaussian(0.5).unwrap());
    /// let model = Model::new(lft, vec![
    ///     NonlinearBlock::new("first", vec![0], 0, d.clone()),
    ///     NonlinearBlock::new("second", vec![1], 1, d),
    /// ]).unwrap();
    /// let square = |z: &[f64]| z[0] * z[0];
    /// let half = |z: &[f64]| 0.5 * z[0];
    /// let (maps, u, y): ([&dyn Interpolant; 2], _, _) = ([&square, &half], vec![1.0, 2.0, 3.0], vec![0.0; 3]);
    /// let z = model.compute_z_with_maps(&Signal::new(1, u).unwrap(), &Signal::new(1, y).unwrap(), &maps).unwrap();
    /// assert_eq!(z.channel(1), vec![1.0, 4.0, 9.0]); // z₁ = N₁(u) = u²
    /// ```
    ///
    /// # Errors
    /// [`Error::AlgebraicLoop`] for a cycle, [`Error::NotMeasurable`] naming the latent blocks
    /// (unless the noise reaches neither the state nor z, when z is simulated from rest),
    /// [`Error::DimensionMismatch`] for a wrong number of maps, [`Error::Numerical`] when a map
    /// returns a non-finite value, and [`crate::Lft::compute_z`]'s errors.
    pub fn compute_z_with_maps(
        &self,
        u: &Signal,
        y: &Signal,
        maps: &[&dyn Interpolant],
    ) -> Result<Signal> {
        match self.compute_z_in_order(u, y, maps) {
            Err(Error::NotMeasurable { .. } | Error::OutOfReach { .. })
                if self.lft().noise_free_z() =>
            {
                Ok(self.simulate(maps, u, None, None)?.z)
            }
            other => other,
        }
    }

    /// [`Model::compute_z_with_maps`] without the output-error case: each block's own z
    /// from u and y, the maps evaluated in order.
    fn compute_z_in_order(
        &self,
        u: &Signal,
        y: &Signal,
        maps: &[&dyn Interpolant],
    ) -> Result<Signal> {
        let lft = self.lft();
        let m = lft.matrices();
        if m.dzw.iter().all(|v| *v == 0.0) {
            return Ok(lft.compute_z(u, y)?.0);
        }
        let blocks = self.blocks();
        if maps.len() != blocks.len() {
            return Err(Error::DimensionMismatch {
                what: "number of maps for computing z (one per block, in model order)".into(),
                expected: blocks.len().to_string(),
                found: maps.len().to_string(),
            });
        }
        let order = self.evaluation_order()?;
        let places = self.places();
        let latent: Vec<&str> = lft
            .block_access(&places)?
            .iter()
            .zip(blocks)
            .filter(|(a, _)| **a == BlockAccess::Latent)
            .map(|(_, b)| b.name.as_str())
            .collect();
        if !latent.is_empty() {
            return Err(Error::NotMeasurable {
                explanation: format!(
                    "block(s) {} are latent: their input is a signal that u and y do not reveal, \
                     so z cannot be computed from the record even with the maps known; such a \
                     model can be simulated, not predicted one step ahead",
                    latent
                        .iter()
                        .map(|n| format!("`{n}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            });
        }
        let d = lft.dims();
        let len = u.len();
        let mut z = Signal::zeros(len, d.z);
        let mut w = Signal::zeros(len, d.w);
        let mut done = vec![false; d.z];
        for &b in &order {
            let block = &blocks[b];
            let own = lft.own_rows(&block.inputs)?;
            let (z_own, _) = own.compute_z(u, y)?;
            for k in 0..len {
                for (c, &i) in block.inputs.iter().enumerate() {
                    let series: f64 = (0..d.w).map(|j| m.dzw[(i, j)] * w.get(k, j)).sum();
                    z.sample_mut(k)[i] = z_own.get(k, c) + series;
                }
            }
            block.inputs.iter().for_each(|&i| done[i] = true);
            let values = maps[b].eval_many(&z.select_channels(&block.inputs));
            if let Some(k) = values.iter().position(|v| !v.is_finite()) {
                return Err(Error::Numerical(format!(
                    "the map of block `{}` returned {} at sample {k}",
                    block.name, values[k]
                )));
            }
            for (k, v) in values.iter().enumerate() {
                w.sample_mut(k)[block.output] = *v;
            }
        }
        if done.iter().any(|d| !d) {
            // Rows no block reads: reported, not used; measurable or not, they carry no map.
            let rest: Vec<usize> = (0..d.z).filter(|&i| !done[i]).collect();
            if let Ok((z_rest, _)) = lft.own_rows(&rest)?.compute_z(u, y) {
                for k in 0..len {
                    for (c, &i) in rest.iter().enumerate() {
                        let series: f64 = (0..d.w).map(|j| m.dzw[(i, j)] * w.get(k, j)).sum();
                        z.sample_mut(k)[i] = z_rest.get(k, c) + series;
                    }
                }
            }
        }
        Ok(z)
    }
}

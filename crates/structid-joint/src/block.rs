//! What varies between the blocks of a joint model: a parametrised map w = N(z; θ, s) with an
//! optional internal state s (a hysteresis operator's memory) and an optional quadratic
//! dispersion D(θ) = ‖R·θ‖² that regularises it.

use std::fmt;

use crate::error::Result;

/// Partial derivatives of one evaluation of a block, dense and row-major, with p inputs,
/// n_s states and n_θ parameters. The state s is the one *before* the sample, s⁺ the one after.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockJacobian {
    /// ∂w/∂z (p).
    pub dw_dz: Vec<f64>,
    /// ∂w/∂s (n_s).
    pub dw_ds: Vec<f64>,
    /// ∂w/∂θ (n_θ).
    pub dw_dp: Vec<f64>,
    /// ∂s⁺/∂s (n_s × n_s).
    pub ds_ds: Vec<f64>,
    /// ∂s⁺/∂z (n_s × p).
    pub ds_dz: Vec<f64>,
    /// ∂s⁺/∂θ (n_s × n_θ).
    pub ds_dp: Vec<f64>,
}

impl BlockJacobian {
    /// Zeroed buffers sized for `map`.
    ///
    /// ```
    /// use structid_joint::{BlockJacobian, GaussianFeatures};
    /// let f = GaussianFeatures::on_interval(-1.0, 1.0, 5, 0.5, 0.0).unwrap();
    /// let j = BlockJacobian::for_map(&f);
    /// assert_eq!((j.dw_dz.len(), j.dw_dp.len(), j.ds_ds.len()), (1, 7, 0));
    /// ```
    pub fn for_map(map: &dyn BlockMap) -> Self {
        Self::zeros(map.input_len(), map.state_len(), map.parameters().len())
    }

    /// Zeroed buffers for `p` inputs, `ns` states and `np` parameters.
    pub(crate) fn zeros(p: usize, ns: usize, np: usize) -> Self {
        Self {
            dw_dz: vec![0.0; p],
            dw_ds: vec![0.0; ns],
            dw_dp: vec![0.0; np],
            ds_ds: vec![0.0; ns * ns],
            ds_dz: vec![0.0; ns * p],
            ds_dp: vec![0.0; ns * np],
        }
    }
}

/// A parametrised block of a joint model.
///
/// Static maps have no state; a hysteresis operator keeps its memory in the state. Every
/// method that evaluates takes the state before the sample and overwrites it with the state
/// after, so a caller runs a block over a signal by calling [`BlockMap::eval`] sample by sample.
pub trait BlockMap: Send + Sync + fmt::Debug {
    /// A short name of the kind of map ("gaussian features", "play", …).
    fn kind(&self) -> &'static str;
    /// Number of inputs p.
    fn input_len(&self) -> usize;
    /// Length n_s of the internal state (0 for a static map).
    fn state_len(&self) -> usize {
        0
    }
    /// The parameters θ, in the map's documented order.
    fn parameters(&self) -> Vec<f64>;
    /// The same map with parameters `p`; an error when they are outside the map's range.
    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn BlockMap>>;
    /// Writes the state of the map at rest with input `z0`.
    fn initial_state(&self, _z0: &[f64], _state: &mut [f64]) {}
    /// w for input `z`, advancing `state`.
    fn eval(&self, state: &mut [f64], z: &[f64]) -> f64;
    /// w for input `z`, advancing `state` and writing the partial derivatives into `jac`
    /// (sized by [`BlockJacobian::for_map`]).
    fn eval_jacobian(&self, state: &mut [f64], z: &[f64], jac: &mut BlockJacobian) -> f64;
    /// R of the dispersion D(θ) = ‖R·θ‖² (rows × n_θ), already weighted by the map's β; `None`
    /// for an unregularised map.
    fn regulariser(&self) -> Option<nalgebra::DMatrix<f64>> {
        None
    }
    /// The map's affine part a₀ + aᵀz when it has one that a linear model can stand in for
    /// (the unpenalised trend of a kernel expansion): what [`crate::smooth_maps`] closes the
    /// linear part with. `None` for operators and fixed maps.
    fn affine_part(&self) -> Option<(f64, Vec<f64>)> {
        None
    }
    /// A static map of one input as an expression in `z0` (the syntax of
    /// [`structid_core::ExprMap`]) that evaluates to the same values: how a fitted map is
    /// written without losing its fit. `None` (the default) when the map has no such form.
    fn expression(&self) -> Option<String> {
        None
    }
    /// A boxed copy.
    fn boxed(&self) -> Box<dyn BlockMap>;
}

impl Clone for Box<dyn BlockMap> {
    fn clone(&self) -> Self {
        self.boxed()
    }
}

//! Blocks without free parameters inside a joint model: a known static map ([`FixedMap`]),
//! and a parametrised block whose parameters are held where they are ([`HeldMap`]). Both
//! take part in simulation and in the sensitivities.

use std::sync::Arc;

use structid_core::Interpolant;

use crate::block::{BlockJacobian, BlockMap};
use crate::error::Result;

/// A known map w = f(z) (an expression, a table, a closure) as a [`BlockMap`] without
/// parameters. Its derivative ∂f/∂z, which the sensitivities of the maps around it need, is
/// taken by central differences with a step of 10⁻⁶·max(1, |z|): `f` is given as a value, not
/// as a formula. A map with steps (a quantiser) has a zero derivative almost everywhere, and
/// a fit through it would see no gradient: [`FixedMap::with_derivative_step`] takes the
/// secant over a wider step instead, the map's trend at that resolution. The simulation uses
/// the map itself; the fit's Jacobian uses the secant, so where the fit stops moves by the
/// secant's error (about f‴·h²/6 for a smooth map).
///
/// ```
/// use std::sync::Arc;
/// use structid_joint::{BlockJacobian, BlockMap, FixedMap};
/// let clip = FixedMap::new(Arc::new(|z: &[f64]| z[0].min(10.0)), 1);
/// let mut jac = BlockJacobian::for_map(&clip);
/// assert_eq!(clip.eval_jacobian(&mut [], &[12.0], &mut jac), 10.0);
/// assert!(jac.dw_dz[0].abs() < 1e-9);
/// assert!(clip.parameters().is_empty());
/// ```
#[derive(Clone)]
pub struct FixedMap {
    map: Arc<dyn Interpolant>,
    inputs: usize,
    step: Option<f64>,
}

impl FixedMap {
    /// The map `map` of `inputs` inputs.
    pub fn new(map: Arc<dyn Interpolant>, inputs: usize) -> Self {
        Self {
            map,
            inputs,
            step: None,
        }
    }

    /// The map with its derivative taken as the central secant (f(z + h) − f(z − h))/(2h) of
    /// the fixed step `h`, in z's units (a non-positive or non-finite `h` keeps the default).
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_joint::{BlockJacobian, BlockMap, FixedMap};
    /// // A quantiser of step 0.1: flat between its steps, a unit slope on average.
    /// let q = Arc::new(|z: &[f64]| (z[0] / 0.1).round() * 0.1);
    /// let (fine, coarse) = (FixedMap::new(q.clone(), 1), FixedMap::new(q, 1).with_derivative_step(0.5));
    /// let (mut a, mut b) = (BlockJacobian::for_map(&fine), BlockJacobian::for_map(&coarse));
    /// fine.eval_jacobian(&mut [], &[0.32], &mut a);
    /// coarse.eval_jacobian(&mut [], &[0.32], &mut b);
    /// assert_eq!(a.dw_dz[0], 0.0);
    /// assert!((b.dw_dz[0] - 1.0).abs() < 1e-9);
    /// ```
    pub fn with_derivative_step(mut self, h: f64) -> Self {
        self.step = (h.is_finite() && h > 0.0).then_some(h);
        self
    }
}

impl std::fmt::Debug for FixedMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FixedMap")
            .field("inputs", &self.inputs)
            .finish()
    }
}

impl BlockMap for FixedMap {
    fn kind(&self) -> &'static str {
        "fixed map"
    }

    fn input_len(&self) -> usize {
        self.inputs
    }

    fn parameters(&self) -> Vec<f64> {
        Vec::new()
    }

    fn with_parameters(&self, _p: &[f64]) -> Result<Box<dyn BlockMap>> {
        Ok(Box::new(self.clone()))
    }

    fn eval(&self, _state: &mut [f64], z: &[f64]) -> f64 {
        self.map.eval(z)
    }

    fn eval_jacobian(&self, _state: &mut [f64], z: &[f64], jac: &mut BlockJacobian) -> f64 {
        let mut at = z.to_vec();
        for i in 0..z.len() {
            let h = self.step.unwrap_or(1e-6 * z[i].abs().max(1.0));
            at[i] = z[i] + h;
            let up = self.map.eval(&at);
            at[i] = z[i] - h;
            let down = self.map.eval(&at);
            at[i] = z[i];
            jac.dw_dz[i] = (up - down) / (2.0 * h);
        }
        self.map.eval(z)
    }

    fn boxed(&self) -> Box<dyn BlockMap> {
        Box::new(self.clone())
    }
}
/// A parametrised block with its parameters held: it evaluates, and passes on its
/// derivatives with respect to z and to its state, as the block does, and offers no parameter
/// to a fit. [`JointModel::held`](crate::JointModel::held) holds every block of a model this
/// way, so that a fit moves only the initial states.
///
/// ```
/// use structid_joint::{BlockJacobian, BlockMap, GaussianFeatures, HeldMap};
/// let map = GaussianFeatures::on_interval(-1.0, 1.0, 5, 0.5, 0.0).unwrap();
/// let held = HeldMap::new(Box::new(map.clone()));
/// assert!(held.parameters().is_empty());
/// let (mut a, mut b) = (BlockJacobian::for_map(&held), BlockJacobian::for_map(&map));
/// assert_eq!(held.eval_jacobian(&mut [], &[0.3], &mut a), map.eval_jacobian(&mut [], &[0.3], &mut b));
/// assert_eq!(a.dw_dz, b.dw_dz);
/// ```
///
/// Each evaluation of the Jacobian fills the block's own buffers (its parameter derivatives
/// included, which are then dropped), so a held block costs what the free one does per
/// sample: it is meant for the short fits of initial states.
#[derive(Clone, Debug)]
pub struct HeldMap {
    block: Box<dyn BlockMap>,
    held: usize,
}

impl HeldMap {
    /// `block` with its current parameters held.
    pub fn new(block: Box<dyn BlockMap>) -> Self {
        let held = block.parameters().len();
        Self { block, held }
    }
}

impl BlockMap for HeldMap {
    fn kind(&self) -> &'static str {
        self.block.kind()
    }

    fn input_len(&self) -> usize {
        self.block.input_len()
    }

    fn state_len(&self) -> usize {
        self.block.state_len()
    }

    fn parameters(&self) -> Vec<f64> {
        Vec::new()
    }

    fn with_parameters(&self, _p: &[f64]) -> Result<Box<dyn BlockMap>> {
        Ok(Box::new(self.clone()))
    }

    fn initial_state(&self, z0: &[f64], state: &mut [f64]) {
        self.block.initial_state(z0, state);
    }

    fn eval(&self, state: &mut [f64], z: &[f64]) -> f64 {
        self.block.eval(state, z)
    }

    fn eval_jacobian(&self, state: &mut [f64], z: &[f64], jac: &mut BlockJacobian) -> f64 {
        // The block's own buffers hold its parameter derivatives, which are dropped.
        let mut own = BlockJacobian::zeros(z.len(), state.len(), self.held);
        let w = self.block.eval_jacobian(state, z, &mut own);
        jac.dw_dz.copy_from_slice(&own.dw_dz);
        jac.dw_ds.copy_from_slice(&own.dw_ds);
        jac.ds_ds.copy_from_slice(&own.ds_ds);
        jac.ds_dz.copy_from_slice(&own.ds_dz);
        w
    }

    fn expression(&self) -> Option<String> {
        self.block.expression()
    }

    fn boxed(&self) -> Box<dyn BlockMap> {
        Box::new(self.clone())
    }
}

//! A known static map inside a joint model: it takes part in simulation and in the
//! sensitivities, and has no parameters.

use std::sync::Arc;

use structid_core::Interpolant;

use crate::block::{BlockJacobian, BlockMap};
use crate::error::Result;

/// A known map w = f(z) (an expression, a table, a closure) as a [`BlockMap`] without
/// parameters. Its derivative ∂f/∂z, which the sensitivities of the maps around it need, is
/// taken by central differences with a step of 10⁻⁶·max(1, |z|): `f` is given as a value, not
/// as a formula.
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
}

impl FixedMap {
    /// The map `map` of `inputs` inputs.
    pub fn new(map: Arc<dyn Interpolant>, inputs: usize) -> Self {
        Self { map, inputs }
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
            let h = 1e-6 * z[i].abs().max(1.0);
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

//! A named parametric family inside a joint model: w = f(z; θ) with its parameters θ fitted
//! with the rest of the model, and its exact derivatives ([`structid_core::ParametricMap`]).
//! It carries no dispersion: a law with a few parameters is regularised by its form.

use structid_core::{Interpolant, ParametricMap};

use crate::block::{BlockJacobian, BlockMap};
use crate::error::Result;

/// A parametric family as a [`BlockMap`]; θ is the family's parameters in declaration order.
///
/// ```
/// use structid_core::ParametricMap;
/// use structid_joint::{BlockJacobian, BlockMap, FamilyMap};
/// let f = FamilyMap::new(ParametricMap::parse("c*signum(z0) + v*z0", 1, vec![("c".into(), 0.5), ("v".into(), 2.0)]).unwrap());
/// let mut jac = BlockJacobian::for_map(&f);
/// assert_eq!(f.eval_jacobian(&mut [], &[-1.0], &mut jac), -2.5);
/// assert_eq!((jac.dw_dz[0], jac.dw_dp[0], jac.dw_dp[1]), (2.0, -1.0, -1.0));
/// ```
#[derive(Clone, Debug)]
pub struct FamilyMap {
    map: ParametricMap,
}

impl FamilyMap {
    /// The family `map`, starting from its parameters' values.
    pub fn new(map: ParametricMap) -> Self {
        Self { map }
    }

    /// The family with its current parameters.
    pub fn map(&self) -> &ParametricMap {
        &self.map
    }
}

impl BlockMap for FamilyMap {
    fn kind(&self) -> &'static str {
        "parametric family"
    }

    fn input_len(&self) -> usize {
        self.map.dim()
    }

    fn parameters(&self) -> Vec<f64> {
        self.map.values().to_vec()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn BlockMap>> {
        Ok(Box::new(Self::new(self.map.with_values(p)?)))
    }

    fn eval(&self, _state: &mut [f64], z: &[f64]) -> f64 {
        self.map.eval(z)
    }

    fn eval_jacobian(&self, _state: &mut [f64], z: &[f64], jac: &mut BlockJacobian) -> f64 {
        self.map.gradient(z, &mut jac.dw_dz, &mut jac.dw_dp)
    }

    fn boxed(&self) -> Box<dyn BlockMap> {
        Box::new(self.clone())
    }
}

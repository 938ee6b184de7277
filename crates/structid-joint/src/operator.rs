//! A hysteresis operator of `structid-core` as a block of the joint model: its parameters are
//! fitted with the rest, its memory is part of the stacked state ξ (so it is a free initial
//! state of each shooting segment), and its exact one-step derivatives feed the sensitivities.

use structid_core::{HysteresisOperator, OperatorJacobian};

use crate::block::{BlockJacobian, BlockMap};
use crate::error::Result;

/// A scalar hysteresis operator (play, stop, Prandtl–Ishlinskii, Bouc–Wen) as a [`BlockMap`].
///
/// ```
/// use structid_core::Play;
/// use structid_joint::{BlockMap, OperatorBlock};
/// let b = OperatorBlock::new(Box::new(Play::new(0.5).unwrap()));
/// let mut s = vec![0.0];
/// b.initial_state(&[0.0], &mut s);
/// // The play holds its output until the input has crossed the gap.
/// assert_eq!(b.eval(&mut s, &[0.3]), 0.0);
/// assert!((b.eval(&mut s, &[1.0]) - 0.5).abs() < 1e-15);
/// ```
#[derive(Debug)]
pub struct OperatorBlock {
    op: Box<dyn HysteresisOperator>,
}

impl OperatorBlock {
    /// Wraps `op`.
    pub fn new(op: Box<dyn HysteresisOperator>) -> Self {
        Self { op }
    }

    /// The operator.
    pub fn operator(&self) -> &dyn HysteresisOperator {
        self.op.as_ref()
    }
}

impl BlockMap for OperatorBlock {
    fn kind(&self) -> &'static str {
        self.op.kind()
    }

    fn input_len(&self) -> usize {
        1
    }

    fn state_len(&self) -> usize {
        self.op.state_len()
    }

    fn parameters(&self) -> Vec<f64> {
        self.op.parameters()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn BlockMap>> {
        Ok(Box::new(Self {
            op: self.op.with_parameters(p)?,
        }))
    }

    fn initial_state(&self, z0: &[f64], state: &mut [f64]) {
        self.op.initial_state(z0[0], state);
    }

    fn eval(&self, state: &mut [f64], z: &[f64]) -> f64 {
        self.op.step(state, z[0])
    }

    fn eval_jacobian(&self, state: &mut [f64], z: &[f64], jac: &mut BlockJacobian) -> f64 {
        // The block's buffers have the operator's sizes (n_s, one input, n_p): lend them to the
        // operator, zeroed as `OperatorJacobian::for_operator` gives them, instead of
        // allocating a Jacobian every sample.
        let take = |v: &mut Vec<f64>| {
            let mut v = std::mem::take(v);
            v.fill(0.0);
            v
        };
        let mut oj = OperatorJacobian {
            ds_ds: take(&mut jac.ds_ds),
            ds_dz: take(&mut jac.ds_dz),
            ds_dp: take(&mut jac.ds_dp),
            dw_ds: take(&mut jac.dw_ds),
            dw_dz: 0.0,
            dw_dp: take(&mut jac.dw_dp),
        };
        let w = self.op.step_jacobian(state, z[0], &mut oj);
        jac.dw_dz[0] = oj.dw_dz;
        (jac.ds_ds, jac.ds_dz, jac.ds_dp) = (oj.ds_ds, oj.ds_dz, oj.ds_dp);
        (jac.dw_ds, jac.dw_dp) = (oj.dw_ds, oj.dw_dp);
        w
    }

    fn boxed(&self) -> Box<dyn BlockMap> {
        Box::new(Self {
            op: self.op.boxed(),
        })
    }
}

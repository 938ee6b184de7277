//! An operator over several independent records: [`Recordwise`].
//!
//! Several experiments on the same system are separate records, each starting from its own
//! state. Stacked one after the other they form one long signal, but the operator on that
//! signal is block diagonal (one Toeplitz block per record), not the Toeplitz operator of the
//! concatenation, which would carry the state from the end of one record into the next.

use std::sync::Arc;

use faer::prelude::ReborrowMut;
use faer::{Accum, MatMut, MatRef};

use crate::error::LtiError;
use crate::operator::{LinearSystem, horizon};

/// `T` applied to each record of a stacked signal separately, from a zero state at the start
/// of every record: the block-diagonal operator diag(T_{L₁}, …, T_{L_R}).
///
/// `bounds` are the sample indices where the records start, followed by the total length
/// (`[0, L₁, L₁ + L₂, …, L]`). The fast paths assert that the signals have exactly that
/// total length.
///
/// ```
/// use std::sync::Arc;
/// use nalgebra::dmatrix;
/// use structid_lti::{LinearSystem, Recordwise, StateSpace};
/// // An accumulator y_k = Σ_{j<k} u_j over two records of 3 samples.
/// let acc = StateSpace::new(dmatrix![1.0], dmatrix![1.0], dmatrix![1.0], dmatrix![0.0]).unwrap();
/// let t = Recordwise::new(Arc::new(acc), vec![0, 3, 6]).unwrap();
/// let mut y = vec![0.0; 6];
/// t.apply(&[1.0; 6], &mut y);
/// assert_eq!(y, vec![0.0, 1.0, 2.0, 0.0, 1.0, 2.0]);
/// ```
#[derive(Clone)]
pub struct Recordwise {
    inner: Arc<dyn LinearSystem>,
    bounds: Arc<[usize]>,
}

impl Recordwise {
    /// Wraps `inner`; `bounds` must start at 0 and increase strictly (no empty record).
    pub fn new(inner: Arc<dyn LinearSystem>, bounds: Vec<usize>) -> Result<Self, LtiError> {
        if bounds.len() < 2 || bounds[0] != 0 || bounds.windows(2).any(|w| w[1] <= w[0]) {
            return Err(LtiError::param(
                "bounds",
                format!(
                    "record bounds must start at 0 and increase strictly (one start per record, then \
                     the total length); got {bounds:?}"
                ),
            ));
        }
        Ok(Self {
            inner,
            bounds: bounds.into(),
        })
    }

    /// The record bounds `[0, L₁, …, L]`.
    pub fn bounds(&self) -> &[usize] {
        &self.bounds
    }

    /// The operator of one record.
    pub fn inner(&self) -> &dyn LinearSystem {
        self.inner.as_ref()
    }

    fn check(&self, a_ch: usize, b_ch: usize, a: usize, b: usize) {
        let len = horizon(a_ch, b_ch, a, b);
        let total = *self.bounds.last().expect("at least two bounds");
        assert!(
            len == total || a_ch + b_ch == 0,
            "signal of {len} samples for records totalling {total}"
        );
    }

    /// The channels of `x` and `out` of a forward (`m`, `p`) or adjoint (`p`, `m`)
    /// application, after checking the lengths `x_len` and `out_len` (in samples times
    /// channels) against the record bounds.
    fn checked_channels(&self, adjoint: bool, x_len: usize, out_len: usize) -> (usize, usize) {
        let (m, p) = (self.inputs(), self.outputs());
        if adjoint {
            self.check(m, p, out_len, x_len);
            (p, m)
        } else {
            self.check(m, p, x_len, out_len);
            (m, p)
        }
    }

    /// Runs `f` on each record's part of `x` and `out` (forward or `adjoint`).
    fn per_record(
        &self,
        x: &[f64],
        out: &mut [f64],
        adjoint: bool,
        f: impl Fn(&[f64], &mut [f64]),
    ) {
        let (cx, co) = self.checked_channels(adjoint, x.len(), out.len());
        for (s, l) in self.segments() {
            f(&x[s * cx..(s + l) * cx], &mut out[s * co..(s + l) * co]);
        }
    }

    /// Runs `f` on each record's rows of the column blocks `x` and `out` (forward or
    /// `adjoint`).
    fn per_record_columns(
        &self,
        x: MatRef<'_, f64>,
        mut out: MatMut<'_, f64>,
        adjoint: bool,
        f: impl Fn(MatRef<'_, f64>, MatMut<'_, f64>),
    ) {
        let (cx, co) = self.checked_channels(adjoint, x.nrows(), out.nrows());
        for (s, l) in self.segments() {
            f(
                x.subrows(s * cx, l * cx),
                out.rb_mut().subrows_mut(s * co, l * co),
            );
        }
    }

    fn segments(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.bounds.windows(2).map(|w| (w[0], w[1] - w[0]))
    }
}

impl LinearSystem for Recordwise {
    fn inputs(&self) -> usize {
        self.inner.inputs()
    }

    fn outputs(&self) -> usize {
        self.inner.outputs()
    }

    fn order(&self) -> usize {
        self.inner.order()
    }

    fn as_recordwise(&self) -> Option<&Recordwise> {
        Some(self)
    }

    fn apply(&self, u: &[f64], y: &mut [f64]) {
        self.per_record(u, y, false, |u, y| self.inner.apply(u, y));
    }

    fn apply_adjoint(&self, y: &[f64], u: &mut [f64]) {
        self.per_record(y, u, true, |y, u| self.inner.apply_adjoint(y, u));
    }

    fn apply_columns(&self, x: MatRef<'_, f64>, out: MatMut<'_, f64>, accum: Accum, alpha: f64) {
        self.per_record_columns(x, out, false, |x, out| {
            self.inner.apply_columns(x, out, accum, alpha)
        });
    }

    fn apply_adjoint_columns(
        &self,
        x: MatRef<'_, f64>,
        out: MatMut<'_, f64>,
        accum: Accum,
        alpha: f64,
    ) {
        self.per_record_columns(x, out, true, |x, out| {
            self.inner.apply_adjoint_columns(x, out, accum, alpha)
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing;
    use faer::Mat;

    #[test]
    fn equals_the_block_diagonal_of_dense_toeplitz_blocks() {
        let sys = testing::random_stable_system(7, 3, 2, 2, 0.9);
        let bounds = vec![0, 5, 6, 14];
        let t = Recordwise::new(Arc::new(sys.clone()), bounds.clone()).unwrap();
        let (len, m, p) = (14, 2, 2);
        let mut dense = nalgebra::DMatrix::<f64>::zeros(len * p, len * m);
        for w in bounds.windows(2) {
            let l = w[1] - w[0];
            dense
                .view_mut((w[0] * p, w[0] * m), (l * p, l * m))
                .copy_from(&sys.toeplitz_dense(l));
        }
        let u: Vec<f64> = (0..len * m).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut y = vec![0.0; len * p];
        t.apply(&u, &mut y);
        let want = &dense * nalgebra::DVector::from_column_slice(&u);
        assert!(
            y.iter()
                .zip(want.iter())
                .all(|(a, b)| (a - b).abs() < 1e-12)
        );
        let mut ua = vec![0.0; len * m];
        t.apply_adjoint(&y, &mut ua);
        let want = dense.transpose() * nalgebra::DVector::from_column_slice(&y);
        assert!(
            ua.iter()
                .zip(want.iter())
                .all(|(a, b)| (a - b).abs() < 1e-12)
        );
        // columns, with accumulation
        let x = Mat::from_fn(len * m, 3, |i, j| ((i + 5 * j) as f64).cos());
        let mut out = Mat::from_fn(len * p, 3, |_, _| 1.0);
        t.apply_columns(x.as_ref(), out.as_mut(), Accum::Add, 2.0);
        for j in 0..3 {
            let xj = nalgebra::DVector::from_fn(len * m, |i, _| x[(i, j)]);
            let want = &dense * xj;
            for i in 0..len * p {
                assert!((out[(i, j)] - 1.0 - 2.0 * want[i]).abs() < 1e-12);
            }
        }
        let xa = Mat::from_fn(len * p, 2, |i, j| ((i * 3 + j) as f64).sin());
        let mut outa = Mat::zeros(len * m, 2);
        t.apply_adjoint_columns(xa.as_ref(), outa.as_mut(), Accum::Replace, 1.0);
        for j in 0..2 {
            let want = dense.transpose() * nalgebra::DVector::from_fn(len * p, |i, _| xa[(i, j)]);
            for i in 0..len * m {
                assert!((outa[(i, j)] - want[i]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn bad_bounds_are_errors() {
        let sys = testing::random_stable_system(1, 1, 1, 1, 0.5);
        for b in [vec![0], vec![1, 4], vec![0, 3, 3], vec![0, 4, 2]] {
            assert!(Recordwise::new(Arc::new(sys.clone()), b).is_err());
        }
    }
}

//! Chunk-by-chunk application of a state-space operator to many long signals.
//!
//! Solvers that are linear in the record length (feature-space identification, streaming
//! assembly) push a record through T a time chunk at a time, so that the L × m operand is
//! never in memory at once. The state (n × m) is carried from one chunk to the next.

use faer::{Accum, Mat, MatMut, MatRef};

use crate::error::LtiError;
use crate::operator::{BlockedRecursion, static_columns};
use crate::state_space::StateSpace;

/// Block length of a streamed operator of order `n` (single input and output channels in mind).
/// A block of `b` samples costs about `2 (b + n)² / b` flops per sample and column, half of
/// the `b²` part multiplying the zero triangle of the block Toeplitz matrix: the minimum is
/// at `b = n`, and blocks below 16 samples make the matrix products inefficient. (A fixed 64
/// cost twice the flops of 16 for a 5th-order path and was about 20 % slower over the pass.)
pub(crate) fn stream_block(n: usize) -> usize {
    (2 * n).next_multiple_of(8).clamp(16, 64)
}

/// Applies T (zero initial state) to `ncols` signals delivered in consecutive time chunks.
///
/// Every chunk but the last must hold a multiple of [`ColumnStream::block_len`] samples; a
/// shorter chunk ends the stream. The result equals [`crate::LinearSystem::apply_columns`] on
/// the whole record.
///
/// ```
/// use faer::{Accum, Mat};
/// use structid_lti::{LinearSystem, StateSpace, testing::random_stable_system};
/// let sys: StateSpace = random_stable_system(3, 2, 1, 1, 0.9);
/// let x = Mat::<f64>::from_fn(100, 3, |i, j| ((i * 7 + j) % 11) as f64);
/// let mut whole = Mat::<f64>::zeros(100, 3);
/// sys.apply_columns(x.as_ref(), whole.as_mut(), Accum::Replace, 1.0);
/// let mut stream = sys.column_stream(3);
/// let b = stream.block_len();
/// let mut chunked = Mat::<f64>::zeros(100, 3);
/// let mut t = 0;
/// while t < 100 {
///     let len = (4 * b).min(100 - t);
///     stream.push(x.as_ref().subrows(t, len), chunked.as_mut().subrows_mut(t, len)).unwrap();
///     t += len;
/// }
/// assert!((&whole - &chunked).norm_max() < 1e-12);
/// ```
pub struct ColumnStream {
    engine: Option<BlockedRecursion>,
    d: Mat<f64>,
    inputs: usize,
    outputs: usize,
    state: Mat<f64>,
    next: Mat<f64>,
    ended: bool,
}

impl StateSpace {
    /// A stream that applies this system to `ncols` signals chunk by chunk.
    pub fn column_stream(&self, ncols: usize) -> ColumnStream {
        let n = self.order();
        ColumnStream {
            engine: (n > 0).then(|| self.blocked_with(stream_block(n), false)),
            d: Mat::from_fn(self.outputs(), self.inputs(), |i, j| self.d()[(i, j)]),
            inputs: self.inputs(),
            outputs: self.outputs(),
            state: Mat::zeros(n, ncols),
            next: Mat::zeros(n, ncols),
            ended: false,
        }
    }
}

impl ColumnStream {
    /// The chunk granularity in samples: every chunk but the last is a multiple of it.
    pub fn block_len(&self) -> usize {
        self.engine.as_ref().map_or(1, |e| e.b)
    }

    /// The state after the samples pushed so far (n × ncols).
    pub fn state(&self) -> MatRef<'_, f64> {
        self.state.as_ref()
    }

    /// Writes `out = T x` for the next chunk (`x`: samples·inputs rows, `out`: samples·outputs
    /// rows, both with the stream's column count).
    pub fn push(&mut self, x: MatRef<'_, f64>, out: MatMut<'_, f64>) -> Result<(), LtiError> {
        self.push_with(x, out, Accum::Replace, 1.0)
    }

    /// [`ColumnStream::push`] with the accumulation of [`crate::LinearSystem::apply_columns`]:
    /// `out = alpha · T x` (`Accum::Replace`) or `out += alpha · T x` (`Accum::Add`) for the
    /// next chunk.
    pub fn push_with(
        &mut self,
        x: MatRef<'_, f64>,
        out: MatMut<'_, f64>,
        accum: Accum,
        alpha: f64,
    ) -> Result<(), LtiError> {
        let ncols = self.state.ncols();
        if x.ncols() != ncols || out.ncols() != ncols {
            return Err(LtiError::DimensionMismatch {
                what: "columns of a stream chunk".into(),
                expected: ncols.to_string(),
                found: format!("{} (x) and {} (out)", x.ncols(), out.ncols()),
            });
        }
        let m = self.inputs.max(1);
        if x.nrows() % m != 0 || x.nrows() / m * self.outputs != out.nrows() {
            return Err(LtiError::DimensionMismatch {
                what: "rows of a stream chunk".into(),
                expected: format!(
                    "samples × {} input rows and samples × {} output rows",
                    self.inputs, self.outputs
                ),
                found: format!("{} and {}", x.nrows(), out.nrows()),
            });
        }
        let len = x.nrows() / m;
        if self.ended {
            return Err(LtiError::InvalidParameter {
                name: "chunk".into(),
                reason: format!(
                    "the stream already ended with a chunk that was not a multiple of {} samples",
                    self.block_len()
                ),
            });
        }
        match &self.engine {
            None => static_columns(self.d.as_ref(), len, x, out, accum, alpha),
            Some(e) => {
                let full = len.is_multiple_of(e.b);
                let fin = full.then(|| self.next.as_mut());
                e.leaf(len, x, out, accum, alpha, Some(self.state.as_ref()), fin);
                if full {
                    std::mem::swap(&mut self.state, &mut self.next);
                } else {
                    self.ended = true;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LinearSystem;
    use crate::testing::random_stable_system;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 40, .. ProptestConfig::default() })]

        /// Streaming in chunks (multiples of the block length, then a ragged tail) equals the
        /// whole-record operator, for MIMO systems, n = 0 included, and strided operands.
        #[test]
        fn prop_stream_equals_whole_record(seed in any::<u64>(), n in 0usize..5, m in 1usize..3, p in 1usize..3,
                                           len in 1usize..300, ncols in 1usize..9, chunk_blocks in 1usize..4,
                                           transposed in any::<bool>()) {
            let sys = random_stable_system(seed, n, m, p, 0.95);
            let xs = Mat::<f64>::from_fn(len * m, ncols, |i, j| (((i * 31 + j * 17) as u64 ^ seed) % 23) as f64 - 11.0);
            let xt = xs.transpose().to_owned();
            let x = if transposed { xt.as_ref().transpose() } else { xs.as_ref() };
            let mut whole = Mat::<f64>::zeros(len * p, ncols);
            sys.apply_columns(x, whole.as_mut(), Accum::Replace, 1.0);
            let mut stream = sys.column_stream(ncols);
            let step = chunk_blocks * stream.block_len();
            let mut got = Mat::<f64>::zeros(len * p, ncols);
            let mut t = 0;
            while t < len {
                let l = step.min(len - t);
                stream.push(x.subrows(t * m, l * m), got.as_mut().subrows_mut(t * p, l * p)).unwrap();
                t += l;
            }
            let scale = whole.norm_max().max(1.0);
            prop_assert!((&whole - &got).norm_max() <= 1e-11 * scale);
        }
    }

    #[test]
    fn a_ragged_chunk_ends_the_stream_and_bad_shapes_are_errors() {
        let sys = random_stable_system(5, 3, 1, 1, 0.9);
        let mut s = sys.column_stream(2);
        let b = s.block_len();
        assert!(b > 1);
        let x = Mat::<f64>::zeros(b + 1, 2);
        let mut out = Mat::<f64>::zeros(b + 1, 2);
        s.push(x.as_ref(), out.as_mut()).unwrap();
        assert!(s.push(x.as_ref(), out.as_mut()).is_err());
        let mut s = sys.column_stream(3);
        assert!(s.push(x.as_ref(), out.as_mut()).is_err());
    }
}

//! A square matrix buffer that the exact solver fills and factors in place and the posterior
//! keeps as its Cholesky factor.

use faer::{MatMut, MatRef};

/// An n×n column-major f64 matrix in zero-initialised memory from the allocator, its first
/// column 64-byte aligned. For large sizes the allocator maps fresh pages, which the OS
/// provides zeroed, so unlike `Mat::zeros` there is no serial zeroing pass over the L×L
/// memory before M is filled (at L = 4000 that pass cost about as much as the in-place
/// Toeplitz passes of the assembly).
pub(crate) struct SquareBuffer {
    data: Vec<f64>,
    offset: usize,
    n: usize,
}

impl SquareBuffer {
    /// An n×n matrix of zeros.
    pub(crate) fn zeros(n: usize) -> Self {
        const ALIGN_WORDS: usize = 8;
        let data = vec![0.0; n * n + ALIGN_WORDS];
        // the address only to find the aligned start
        let addr = data.as_ptr() as usize;
        let offset = (64 - addr % 64) % 64 / 8;
        Self { data, offset, n }
    }

    /// The matrix.
    pub(crate) fn as_ref(&self) -> MatRef<'_, f64> {
        MatRef::from_column_major_slice(
            &self.data[self.offset..][..self.n * self.n],
            self.n,
            self.n,
        )
    }

    /// The matrix, mutably.
    pub(crate) fn as_mut(&mut self) -> MatMut<'_, f64> {
        let n = self.n;
        MatMut::from_column_major_slice_mut(&mut self.data[self.offset..][..n * n], n, n)
    }

    /// Its order n.
    pub(crate) fn nrows(&self) -> usize {
        self.n
    }
}

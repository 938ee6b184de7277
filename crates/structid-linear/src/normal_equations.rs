//! The normal equations `(JᵀJ, Jᵀr)` of a least-squares problem, accumulated row by row of
//! `J` without storing `J`.
//!
//! A problem whose residuals are a simulation (output error, a joint fit by simulation error)
//! produces one row of `J` per sample from its forward sensitivities. Adding each row as a
//! rank-one update costs `p²/2` scattered multiply-adds per sample; here rows are gathered into
//! a block of [`BLOCK`] rows and each full block is added as one matrix product
//! `JᵀJ += B·Bᵀ`, `Jᵀr += B·r_B` (`B` is `p × BLOCK`, one row of `J` per column), which runs at
//! matrix-multiply speed. The cost stays `O(L·p²)` for `L` rows; only the constant changes.

use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::{Accum, Mat, Par};
use nalgebra::{DMatrix, DVector};

/// Rows of `J` gathered before they are added as one matrix product.
pub const BLOCK: usize = 256;

/// The number of parameters from which a block's product runs on every thread: a
/// `p × BLOCK` by `BLOCK × p` product of about 2·10⁶ multiply-adds and up, worth splitting.
pub const PARALLEL_DIM: usize = 64;

/// `JᵀJ` and `Jᵀr` for rows of `J` added one at a time.
///
/// ```
/// use structid_linear::normal_equations::NormalEquations;
/// // J = [[1, 2], [3, 4], [0, 1]], r = (1, −1, 2).
/// let mut ne = NormalEquations::new(2);
/// ne.add_row(&[1.0, 2.0], 1.0);
/// ne.add_row(&[3.0, 4.0], -1.0);
/// ne.add_sparse_row(&[1], &[1.0], 2.0);
/// let (jtj, jtr) = ne.finish();
/// assert_eq!((jtj[(0, 0)], jtj[(0, 1)], jtj[(1, 0)], jtj[(1, 1)]), (10.0, 14.0, 14.0, 21.0));
/// assert_eq!((jtr[0], jtr[1]), (-2.0, 0.0));
/// ```
#[derive(Debug, Clone)]
pub struct NormalEquations {
    jtj: Mat<f64>,
    jtr: Mat<f64>,
    /// `p × BLOCK`: column `c` holds the `c`-th pending row of `J`.
    rows: Mat<f64>,
    /// `BLOCK × 1`: the pending rows' residuals.
    residuals: Mat<f64>,
    pending: usize,
}

impl NormalEquations {
    /// Empty normal equations for `p` parameters.
    pub fn new(p: usize) -> Self {
        Self {
            jtj: Mat::zeros(p, p),
            jtr: Mat::zeros(p, 1),
            // Allocated by the first dense row: a system that takes only sparse rows and
            // scattered sub-systems (a multiple-shooting fit's global one) never needs it.
            rows: Mat::zeros(0, 0),
            residuals: Mat::zeros(BLOCK, 1),
            pending: 0,
        }
    }

    /// The number of parameters `p`.
    pub fn dim(&self) -> usize {
        self.jtj.nrows()
    }

    /// Adds a row `j` of `J` (length [`dim`](Self::dim)) with its residual `r`:
    /// `JᵀJ += j·jᵀ`, `Jᵀr += j·r`.
    ///
    /// # Panics
    /// When `j.len() != self.dim()` (a programming error of the caller).
    pub fn add_row(&mut self, j: &[f64], r: f64) {
        assert_eq!(
            j.len(),
            self.dim(),
            "a row of J has one entry per parameter"
        );
        if self.rows.ncols() == 0 {
            self.rows = Mat::zeros(self.dim(), BLOCK);
        }
        let c = self.pending;
        for (i, &v) in j.iter().enumerate() {
            self.rows[(i, c)] = v;
        }
        self.push_residual(r);
    }

    /// Adds a row of `J` that is zero except `vals` at the distinct columns `cols`: a direct
    /// update of the `cols.len()²` entries it reaches, for rows too sparse for a block.
    ///
    /// # Panics
    /// When `cols` and `vals` differ in length or a column is out of range.
    pub fn add_sparse_row(&mut self, cols: &[usize], vals: &[f64], r: f64) {
        assert_eq!(cols.len(), vals.len(), "one value per column");
        for (&ca, &va) in cols.iter().zip(vals) {
            self.jtr[(ca, 0)] += va * r;
            for (&cb, &vb) in cols.iter().zip(vals) {
                self.jtj[(ca, cb)] += va * vb;
            }
        }
    }

    /// Adds the normal equations `other` of parameters that sit at columns `cols` of these
    /// (`cols[i]` is where `other`'s parameter `i` goes; distinct columns).
    ///
    /// # Panics
    /// When `cols.len() != other.dim()` or a column is out of range.
    pub fn add_scattered(&mut self, other: NormalEquations, cols: &[usize]) {
        assert_eq!(
            cols.len(),
            other.dim(),
            "one column per parameter of `other`"
        );
        let (jtj, jtr) = other.into_parts();
        for (a, &ca) in cols.iter().enumerate() {
            self.jtr[(ca, 0)] += jtr[(a, 0)];
            for (b, &cb) in cols.iter().enumerate() {
                self.jtj[(ca, cb)] += jtj[(a, b)];
            }
        }
    }

    /// `(JᵀJ, Jᵀr)` over every row added.
    pub fn finish(self) -> (DMatrix<f64>, DVector<f64>) {
        let (jtj, jtr) = self.into_parts();
        let p = jtj.nrows();
        (
            DMatrix::from_fn(p, p, |i, k| jtj[(i, k)]),
            DVector::from_fn(p, |i, _| jtr[(i, 0)]),
        )
    }

    fn push_residual(&mut self, r: f64) {
        self.residuals[(self.pending, 0)] = r;
        self.pending += 1;
        if self.pending == BLOCK {
            self.flush();
        }
    }

    fn into_parts(mut self) -> (Mat<f64>, Mat<f64>) {
        self.flush();
        // The blocks filled the lower triangle only; every other update wrote both.
        let p = self.dim();
        for k in 0..p {
            for i in k + 1..p {
                self.jtj[(k, i)] = self.jtj[(i, k)];
            }
        }
        (self.jtj, self.jtr)
    }

    /// Threads for a block's product: all of them once the product is large enough to share
    /// ([`PARALLEL_DIM`]), one below that, where splitting costs more than it saves.
    fn parallelism(&self) -> Par {
        if self.dim() >= PARALLEL_DIM {
            Par::rayon(0)
        } else {
            Par::Seq
        }
    }

    /// Adds the pending rows: `JᵀJ += B·Bᵀ` (its lower triangle), `Jᵀr += B·r_B`.
    fn flush(&mut self) {
        let n = self.pending;
        if n == 0 {
            return;
        }
        let par = self.parallelism();
        let b = self.rows.as_ref().subcols(0, n);
        let r = self.residuals.as_ref().subrows(0, n);
        triangular::matmul(
            self.jtj.as_mut(),
            BlockStructure::TriangularLower,
            Accum::Add,
            b,
            BlockStructure::Rectangular,
            b.transpose(),
            BlockStructure::Rectangular,
            1.0,
            par,
        );
        faer::linalg::matmul::matmul(self.jtr.as_mut(), Accum::Add, b, r, 1.0, Par::Seq);
        self.pending = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A system large enough for the block products to run on every thread
    /// ([`PARALLEL_DIM`]) against the dense products of the stored J.
    #[test]
    fn a_large_system_equals_the_dense_products() {
        let (p, rows) = (PARALLEL_DIM + 6, 3 * BLOCK + 17);
        let j = DMatrix::from_fn(rows, p, |k, i| ((k * 31 + i * 17) % 23) as f64 / 11.0 - 1.0);
        let r = DVector::from_fn(rows, |k, _| ((k * 7) % 13) as f64 / 6.0 - 1.0);
        let mut ne = NormalEquations::new(p);
        for k in 0..rows {
            let row: Vec<f64> = j.row(k).iter().copied().collect();
            ne.add_row(&row, r[k]);
        }
        let (jtj, jtr) = ne.finish();
        let (want, want_r) = (j.transpose() * &j, j.transpose() * &r);
        assert!((jtj - &want).amax() <= 1e-12 * want.amax());
        assert!((jtr - &want_r).amax() <= 1e-12 * want.amax());
    }

    proptest! {
        /// Against the dense products of the stored J, across block boundaries, with sparse
        /// rows and a scattered sub-system.
        #[test]
        fn equals_the_dense_products(
            p in 1usize..7,
            rows in 0usize..700,
            seed in 0u64..1000,
        ) {
            let val = |i: usize| (((i as u64 * 2654435761 + seed * 97) % 1999) as f64) / 999.5 - 1.0;
            let mut j = DMatrix::zeros(rows, p);
            let mut r = DVector::zeros(rows);
            let mut ne = NormalEquations::new(p);
            for k in 0..rows {
                r[k] = val(k * 31 + 7);
                if k % 5 == 0 {
                    // Two columns (one when p = 1), off the diagonal of JᵀJ.
                    let cols: Vec<usize> = if p > 1 { vec![k % p, (k + 1) % p] } else { vec![0] };
                    let vals: Vec<f64> = cols.iter().map(|&c| val(k + 3 * c)).collect();
                    for (&c, &v) in cols.iter().zip(&vals) {
                        j[(k, c)] = v;
                    }
                    ne.add_sparse_row(&cols, &vals, r[k]);
                } else {
                    for i in 0..p {
                        j[(k, i)] = val(k * p + i);
                    }
                    let row: Vec<f64> = j.row(k).iter().copied().collect();
                    ne.add_row(&row, r[k]);
                }
            }
            // A sub-system with its own dense rows, scattered onto the last and first columns
            // (in that order): J gains rows that are zero elsewhere.
            let cols: Vec<usize> = if p > 1 { vec![p - 1, 0] } else { vec![0] };
            let mut sub = NormalEquations::new(cols.len());
            let mut extra = DMatrix::zeros(3, p);
            let mut extra_r = DVector::zeros(3);
            for e in 0..3 {
                let row: Vec<f64> = (0..cols.len()).map(|i| val(1000 + 7 * e + i)).collect();
                for (&c, &v) in cols.iter().zip(&row) {
                    extra[(e, c)] = v;
                }
                extra_r[e] = val(2000 + e);
                sub.add_row(&row, extra_r[e]);
            }
            ne.add_scattered(sub, &cols);
            let (jtj, jtr) = ne.finish();
            let want = j.transpose() * &j + extra.transpose() * &extra;
            let want_r = j.transpose() * &r + extra.transpose() * &extra_r;
            let scale = 1.0 + want.amax();
            prop_assert!((jtj - want).amax() <= 1e-12 * scale * rows.max(1) as f64);
            prop_assert!((jtr - want_r).amax() <= 1e-12 * scale * rows.max(1) as f64);
        }
    }
}

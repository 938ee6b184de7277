//! One long signal through a state-space operator by a blocked recursion over time.
//!
//! The per-sample recursion of a single signal is a chain of small dependent steps. Cut into
//! blocks of `b` samples, the record becomes a `(b·inputs) × blocks` matrix U whose columns
//! are the blocks. With the block state S (`n × blocks`, the state when each block starts),
//!
//! ```text
//! Y = [T_b Γ]·[U; S],        S_(k+1) = [R A^b]·[U_k; S_k],
//! ```
//!
//! so the outputs of all blocks are one matrix product, and only the n-dimensional block
//! states run serially (one short matrix-vector product per block). The adjoint runs the
//! same with the blocks in reverse time order. This is the engine of
//! [`crate::LinearSystem::apply_columns`] with the blocks of one signal as its columns.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};

use crate::operator::{BlockedRecursion, horizon};
use crate::state_space::StateSpace;

/// Block length below which a record counts as short (the per-sample recursion is as fast).
const LONG_BLOCK: usize = 64;

/// Below this many blocks the per-sample recursion is as fast.
const MIN_BLOCKS: usize = 4;

impl BlockedRecursion {
    /// `out = Op x` for one signal of `len` samples (`x`: `len · cin` values, `out`:
    /// `len · cout`), from the state `init` (`n` values; `None`: zero) before the first
    /// processed block. Returns the state after the last processed block, which is exact when
    /// that block is whole (always for the adjoint, whose last processed block is the first in
    /// time).
    pub(crate) fn run_signal(
        &self,
        len: usize,
        x: &[f64],
        out: &mut [f64],
        init: Option<&[f64]>,
    ) -> Vec<f64> {
        let (b, cin, cout, n) = (self.b, self.cin, self.cout, self.n);
        let k = b * cin + n;
        let nb = len.div_ceil(b);
        // W = [U; S], one column per block in time order (column-major, k rows), zero-padded
        // past the record
        let mut data = vec![0.0; k * nb];
        for (blk, col) in data.chunks_exact_mut(k).enumerate() {
            let t0 = blk * b;
            let bk = b.min(len - t0);
            col[..bk * cin].copy_from_slice(&x[t0 * cin..(t0 + bk) * cin]);
        }
        // the block states, serially in processing order: s ← m2·[U_k; s], with the rows of
        // m2 as contiguous slices
        let m2: Vec<f64> = (0..n)
            .flat_map(|i| (0..k).map(move |c| (i, c)))
            .map(|(i, c)| self.m2[(i, c)])
            .collect();
        let mut s: Vec<f64> = init.map_or_else(|| vec![0.0; n], <[f64]>::to_vec);
        for step in 0..nb {
            let blk = if self.reverse { nb - 1 - step } else { step };
            let col = &mut data[blk * k..(blk + 1) * k];
            col[b * cin..].copy_from_slice(&s);
            for (si, row) in s.iter_mut().zip(m2.chunks_exact(k)) {
                *si = dot(row, col);
            }
        }
        let w = MatRef::from_column_major_slice(&data, k, nb);
        // Y = m1·W: the whole blocks straight into `out`, a partial last one through a buffer
        let full = len / b;
        // on one thread: the product is small and a shared machine punishes waiting threads
        let par = Par::Seq;
        let head = MatMut::from_column_major_slice_mut(&mut out[..full * b * cout], b * cout, full);
        matmul(
            head,
            Accum::Replace,
            self.m1.as_ref(),
            w.subcols(0, full),
            1.0,
            par,
        );
        if full < nb {
            let bk = len - full * b;
            let mut tail = Mat::<f64>::zeros(b * cout, 1);
            matmul(
                tail.as_mut(),
                Accum::Replace,
                self.m1.as_ref(),
                w.subcols(full, 1),
                1.0,
                par,
            );
            for (i, o) in out[full * b * cout..]
                .iter_mut()
                .enumerate()
                .take(bk * cout)
            {
                *o = tail[(i, 0)];
            }
        }
        s
    }
}

/// Σ a_i·b_i with four partial sums (so that the compiler can vectorise it).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (ac, bc) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (x, y) in ac.zip(bc) {
        for l in 0..4 {
            acc[l] += x[l] * y[l];
        }
    }
    let tail: f64 = ar.iter().zip(br).map(|(x, y)| x * y).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

impl StateSpace {
    /// `y = T u` for one long signal (zero initial state), by a blocked recursion: the record
    /// cut into blocks of 16–64 samples (about twice the order) becomes the columns of a matrix U, the outputs of all
    /// blocks are one matrix product `[T_b Γ]·[U; S]`, and only the block states S run
    /// serially. The same values as
    /// [`LinearSystem::apply`](crate::LinearSystem::apply) up to rounding, many times faster on
    /// long records. Short records and static gains use the per-sample recursion. Panics on
    /// inconsistent lengths, as `apply` does.
    ///
    /// ```
    /// use structid_lti::{LinearSystem, testing::random_stable_system};
    /// let sys = random_stable_system(4, 3, 1, 1, 0.9);
    /// let u: Vec<f64> = (0..1000).map(|k| ((k * 37) % 11) as f64 - 5.0).collect();
    /// let (mut a, mut b) = (vec![0.0; 1000], vec![0.0; 1000]);
    /// sys.apply(&u, &mut a);
    /// sys.apply_long(&u, &mut b);
    /// assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-10));
    /// ```
    pub fn apply_long(&self, u: &[f64], y: &mut [f64]) {
        let len = horizon(self.inputs(), self.outputs(), u.len(), y.len());
        if self.order() == 0 || len < MIN_BLOCKS * LONG_BLOCK {
            crate::LinearSystem::apply(self, u, y);
            return;
        }
        self.blocked_with(crate::stream::stream_block(self.order()), false)
            .run_signal(len, u, y, None);
    }

    /// `u = Tᵀ y` for one long signal, blocked like [`apply_long`](Self::apply_long): the
    /// values of [`LinearSystem::apply_adjoint`](crate::LinearSystem::apply_adjoint) up to
    /// rounding. Panics on inconsistent lengths.
    pub fn apply_adjoint_long(&self, y: &[f64], u: &mut [f64]) {
        let len = horizon(self.inputs(), self.outputs(), u.len(), y.len());
        if self.order() == 0 || len < MIN_BLOCKS * LONG_BLOCK {
            crate::LinearSystem::apply_adjoint(self, y, u);
            return;
        }
        self.blocked_with(crate::stream::stream_block(self.order()), true)
            .run_signal(len, y, u, None);
    }

    /// The blocked recursion of one long signal from a given state: `y` receives the outputs of
    /// `len` samples started from `x0` (forward) or from the costate `x0` after the last sample
    /// (`adjoint`); returns the state after the last processed block (the costate at the
    /// first sample for the adjoint; for the forward recursion exact only when `len` is a
    /// multiple of the block length). Used by the whitening filter after its transient.
    pub(crate) fn run_long_from(
        &self,
        adjoint: bool,
        x: &[f64],
        y: &mut [f64],
        len: usize,
        x0: &[f64],
    ) -> Vec<f64> {
        self.blocked_with(crate::stream::stream_block(self.order()), adjoint)
            .run_signal(len, x, y, Some(x0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LinearSystem;
    use crate::testing::random_stable_system;

    fn signal(seed: u64, len: usize) -> Vec<f64> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..len)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
            })
            .collect()
    }

    /// The blocked long-signal recursion equals the per-sample one (forward and adjoint) to
    /// 1e-12 relative, on random MIMO systems, whole and ragged block counts.
    #[test]
    fn blocked_long_signal_equals_single_signal_recursion() {
        for seed in 0..12u64 {
            let n = 1 + (seed as usize % 6);
            let m = 1 + (seed as usize % 2);
            let p = 1 + (seed as usize / 2 % 2);
            let sys = random_stable_system(seed, n, m, p, 0.95);
            for len in [LONG_BLOCK * MIN_BLOCKS, 1000, 1027, 4096 + 63] {
                let u = signal(seed, len * m);
                let (mut a, mut b) = (vec![0.0; len * p], vec![0.0; len * p]);
                sys.apply(&u, &mut a);
                sys.apply_long(&u, &mut b);
                let scale = a.iter().fold(1.0f64, |s, v| s.max(v.abs()));
                let err = a
                    .iter()
                    .zip(&b)
                    .fold(0.0f64, |s, (x, y)| s.max((x - y).abs()));
                assert!(err <= 1e-12 * scale, "forward seed {seed} len {len}: {err}");

                let y = signal(seed + 100, len * p);
                let (mut a, mut b) = (vec![0.0; len * m], vec![0.0; len * m]);
                sys.apply_adjoint(&y, &mut a);
                sys.apply_adjoint_long(&y, &mut b);
                let scale = a.iter().fold(1.0f64, |s, v| s.max(v.abs()));
                let err = a
                    .iter()
                    .zip(&b)
                    .fold(0.0f64, |s, (x, y)| s.max((x - y).abs()));
                assert!(err <= 1e-12 * scale, "adjoint seed {seed} len {len}: {err}");
            }
        }
    }

    /// Started from a state, the blocked recursion continues the per-sample one.
    #[test]
    fn blocked_long_signal_from_a_state_continues_the_recursion() {
        let sys = random_stable_system(7, 4, 1, 1, 0.9);
        let len = 640;
        let u = signal(3, 2 * len);
        let mut whole = vec![0.0; 2 * len];
        sys.apply(&u, &mut whole);
        let mut first = vec![0.0; len];
        let x_mid = sys.run(&[0.0; 4], &u[..len], &mut first, len, None);
        let mut second = vec![0.0; len];
        let x_end = sys.run_long_from(false, &u[len..], &mut second, len, &x_mid);
        let mut reference = vec![0.0; len];
        let x_ref = sys.run(&x_mid, &u[len..], &mut reference, len, None);
        for (a, b) in whole[len..].iter().zip(&second) {
            assert!((a - b).abs() <= 1e-12 * (1.0 + a.abs()));
        }
        for (a, b) in x_ref.iter().zip(&x_end) {
            assert!((a - b).abs() <= 1e-12 * (1.0 + a.abs()));
        }
    }
}

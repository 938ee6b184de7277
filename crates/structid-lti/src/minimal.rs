//! Removal of unreachable and unobservable states by orthogonal projections.
//!
//! Series connections carry states that the input never reaches or that never reach the
//! output (a noise model's whitening filter in series with a plant path that shares its state
//! vector, say). They change nothing in the operator but cost arithmetic in every recursion,
//! and in a blocked recursion the cost grows with the order. The reduction here is exact up
//! to rounding: the reachable subspace is A-invariant and contains range B, the unobservable
//! one is A-invariant and lies in ker C, so restricting to the first and projecting out the
//! second leaves every Markov parameter C·Aᵏ·B (and D) unchanged.

use nalgebra::DMatrix;

use crate::state_space::StateSpace;

/// Directions whose part left after projecting out the basis found so far is below this
/// fraction of the operand's scale count as already spanned (rounding of exactly dependent
/// directions is some 1e-16 relative; a margin of a few hundred keeps it clear of them).
const RANK_TOL: f64 = 1e-13;

/// An orthonormal basis (n × r) of the smallest A-invariant subspace that contains range `b`
/// (the Krylov space of A on B): block Arnoldi, each block orthonormalised by Gram–Schmidt
/// with column pivoting and reorthogonalisation (rank decisions on the residual norms).
fn reachable_basis(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let mut basis: Vec<nalgebra::DVector<f64>> = Vec::new();
    let scale_a = a.norm().max(f64::MIN_POSITIVE);
    let mut cand: Vec<nalgebra::DVector<f64>> = b.column_iter().map(|c| c.into_owned()).collect();
    let mut scale = b.norm().max(f64::MIN_POSITIVE);
    while basis.len() < n && !cand.is_empty() {
        let mut new = Vec::new();
        loop {
            // twice, so that the residuals are orthogonal to working precision
            for _ in 0..2 {
                for c in cand.iter_mut() {
                    for q in basis.iter().chain(&new) {
                        let h = q.dot(c);
                        c.axpy(-h, q, 1.0);
                    }
                }
            }
            let Some((best, norm)) = cand
                .iter()
                .map(|c| c.norm())
                .enumerate()
                .max_by(|x, y| x.1.total_cmp(&y.1))
            else {
                break;
            };
            if norm <= RANK_TOL * scale || basis.len() + new.len() == n {
                break;
            }
            let q = cand.swap_remove(best) / norm;
            new.push(q);
        }
        if new.is_empty() {
            break;
        }
        cand = new.iter().map(|q| a * q).collect();
        basis.extend(new);
        scale = scale_a;
    }
    if basis.is_empty() {
        return DMatrix::zeros(n, 0);
    }
    DMatrix::from_columns(&basis)
}

impl StateSpace {
    /// A realisation of the same operator without unreachable or unobservable states: the
    /// states are restricted to the reachable subspace of (A, B), then projected onto the
    /// observable subspace of the result, both with orthonormal bases. Every Markov parameter
    /// (hence [`crate::LinearSystem::apply`] from a zero state) agrees with `self` up to
    /// rounding. Returns a clone when no state can be removed. The sample time is kept.
    ///
    /// The rank decisions use a relative tolerance of 1e-13: states that are reachable or
    /// observable only at that level are removed, which changes the output by about as much.
    ///
    /// ```
    /// use nalgebra::dmatrix;
    /// use structid_lti::StateSpace;
    /// // the second state is never excited
    /// let s = StateSpace::new(
    ///     dmatrix![0.5, 0.0; 0.0, 0.2],
    ///     dmatrix![1.0; 0.0],
    ///     dmatrix![1.0, 1.0],
    ///     dmatrix![0.0],
    /// )
    /// .unwrap();
    /// assert_eq!(s.minimal_realisation().order(), 1);
    /// ```
    pub fn minimal_realisation(&self) -> StateSpace {
        let n = self.order();
        if n == 0 {
            return self.clone();
        }
        let v = reachable_basis(self.a(), self.b());
        let (a1, b1, c1) = if v.ncols() < n {
            (
                v.transpose() * self.a() * &v,
                v.transpose() * self.b(),
                self.c() * &v,
            )
        } else {
            (self.a().clone(), self.b().clone(), self.c().clone())
        };
        // observable subspace = reachable subspace of the dual (Aᵀ, Cᵀ)
        let w = reachable_basis(&a1.transpose(), &c1.transpose());
        let (a2, b2, c2) = if w.ncols() < a1.nrows() {
            (w.transpose() * &a1 * &w, w.transpose() * &b1, &c1 * &w)
        } else {
            (a1, b1, c1)
        };
        if a2.nrows() == n {
            return self.clone();
        }
        let s = StateSpace::new(a2, b2, c2, self.d().clone())
            .expect("orthogonal projections of finite matrices are finite and consistent");
        match self.sample_time() {
            Some(ts) => s.with_sample_time(ts).expect("the sample time was valid"),
            None => s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LinearSystem;
    use crate::testing::random_stable_system;

    /// Block-diagonal and series combinations with known unreachable/unobservable parts.
    fn padded(seed: u64, n: usize, extra: usize, m: usize, p: usize) -> (StateSpace, usize) {
        let g = random_stable_system(seed, n, m, p, 0.95);
        let half = extra / 2;
        // `half` states reached but not seen, `extra - half` seen but not reached
        let h1 = random_stable_system(seed ^ 0x5555, half, m, p, 0.9);
        let h2 = random_stable_system(seed ^ 0xaaaa, extra - half, m, p, 0.9);
        let nt = n + extra;
        let mut a = DMatrix::zeros(nt, nt);
        a.view_mut((0, 0), (n, n)).copy_from(g.a());
        a.view_mut((n, n), (half, half)).copy_from(h1.a());
        a.view_mut((n + half, n + half), (extra - half, extra - half))
            .copy_from(h2.a());
        let mut b = DMatrix::zeros(nt, m);
        b.view_mut((0, 0), (n, m)).copy_from(g.b());
        b.view_mut((n, 0), (half, m)).copy_from(h1.b());
        let mut c = DMatrix::zeros(p, nt);
        c.view_mut((0, 0), (p, n)).copy_from(g.c());
        c.view_mut((0, n + half), (p, extra - half))
            .copy_from(h2.c());
        // the unreached states drive the unseen ones: still hidden from y
        if half > 0 && extra > half {
            a[(n, n + half)] = 0.3;
        }
        // a random orthogonal change of coordinates hides the structure
        let q = DMatrix::from_fn(nt, nt, |i, j| {
            ((i * 7 + j * 3 + i * j + seed as usize) % 11) as f64 - 5.0
        })
        .qr()
        .q();
        let s = StateSpace::new(
            q.transpose() * a * &q,
            q.transpose() * b,
            c * &q,
            g.d().clone(),
        )
        .unwrap();
        (s, n)
    }

    fn max_rel(a: &[f64], b: &[f64]) -> f64 {
        let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
            / scale
    }

    /// The reduced system has (nearly always) the minimal order and the same outputs as the original to
    /// 1e-12 relative, on random MIMO systems with hidden unreachable and unobservable states;
    /// minimal systems come back unchanged.
    #[test]
    fn minimal_realisation_keeps_the_operator_and_drops_hidden_states() {
        let mut minimal = 0;
        for seed in 0..40u64 {
            let n = 1 + (seed % 5) as usize;
            let extra = (seed % 4) as usize * 2;
            let (m, p) = (1 + (seed % 2) as usize, 1 + (seed / 2 % 2) as usize);
            let (s, nmin) = padded(seed, n, extra, m, p);
            let r = s.minimal_realisation();
            // a hidden state can leak into view at rounding level when the reachable part is
            // itself barely reachable; keeping it is safe, only slower
            assert!(r.order() >= nmin && r.order() <= s.order());
            minimal += usize::from(r.order() == nmin);
            let len = 300;
            let u: Vec<f64> = (0..len * m)
                .map(|k| (((k as u64 * 2654435761) ^ seed) % 1000) as f64 / 500.0 - 1.0)
                .collect();
            let (mut y0, mut y1) = (vec![0.0; len * p], vec![0.0; len * p]);
            s.apply(&u, &mut y0);
            r.apply(&u, &mut y1);
            let err = max_rel(&y0, &y1);
            assert!(err <= 1e-12, "seed {seed}: {err:e}");
            let (mut a0, mut a1) = (vec![0.0; len * m], vec![0.0; len * m]);
            s.apply_adjoint(&y0, &mut a0);
            r.apply_adjoint(&y0, &mut a1);
            let err = max_rel(&a0, &a1);
            assert!(err <= 1e-12, "seed {seed} (adjoint): {err:e}");
        }
        assert!(
            minimal >= 38,
            "{minimal} of 40 reduced to the minimal order"
        );
        let g = random_stable_system(3, 4, 1, 1, 0.9);
        let r = g.minimal_realisation();
        assert_eq!(r.a(), g.a());
        assert_eq!(r.order(), 4);
    }

    /// The series connection of a whitening filter and a path that share a state vector (each
    /// carrying the other's states as dead weight) reduces to the sum of the minimal orders.
    #[test]
    fn a_series_of_padded_systems_reduces_to_its_minimal_order() {
        let (path, np) = padded(7, 4, 2, 1, 1);
        let (filter, nf) = padded(8, 1, 4, 1, 1);
        let s = filter.series(&path).unwrap();
        let r = s.minimal_realisation();
        assert_eq!(r.order(), np + nf);
        let len = 500;
        let u: Vec<f64> = (0..len).map(|k| ((k * 37) % 11) as f64 - 5.0).collect();
        let (mut y0, mut y1) = (vec![0.0; len], vec![0.0; len]);
        s.apply(&u, &mut y0);
        r.apply(&u, &mut y1);
        assert!(max_rel(&y0, &y1) <= 1e-12);
    }
}

//! The predictor-form Riccati recursion, shared by [`KalmanWhitener`](crate::KalmanWhitener)
//! and [`DisturbanceSmoother`](crate::DisturbanceSmoother), with its steady-state test, the
//! algebraic (steady-state) equation and the small kernels of the per-sample loops.
//!
//! # Model
//! A state-space system driven by white noise `v_t` of covariance `Q_v`,
//!
//! ```text
//! x_{t+1} = A x_t + B v_t,      y_t = C x_t + D v_t,
//! ```
//!
//! (`Q_v = I` for the whitener's noise path, `Q_v = diag(q)` for the smoother's input prior)
//! has process, measurement and cross covariances `Q = B Q_v B^T`, `R = D Q_v D^T`,
//! `S = B Q_v D^T` (correlated: both noises come from `v`).
//!
//! # Recursion
//! With `P_t` the covariance of the one-step prediction error of the state,
//!
//! ```text
//! F_t = C P_t C^T + R                          (innovation covariance)
//! M_t = A P_t C^T + S
//! K_t = M_t F_t^{-1}                           (F_t^+ when F_t is singular)
//! P_{t+1} = A P_t A^T + Q - M_t F_t^{-1} M_t^T
//!         = (A - K_t C) P_t (A - K_t C)^T + (B - K_t D) Q_v (B - K_t D)^T
//! ```
//!
//! [`Riccati::next`] uses the second (Joseph) form: a sum of two positive semi-definite
//! terms, so `P_t` stays symmetric positive semi-definite under rounding; it equals the
//! first for any `K_t` with `K_t F_t = M_t`. The factorisation of `F_t` is the caller's:
//! a checked Cholesky factor for the whitener ([`Riccati::cholesky_gain`], `F_t` must be
//! positive definite), a pseudo-inverse for the smoother (null directions are allowed).
//!
//! # Steady state
//! The recursion is declared steady once `|P_{t+1} - P_t|_F <= tol (|P_t|_F + |Q|_F)`
//! ([`Riccati::converged`], [`Recursion::advance`]); its limit solves the discrete
//! algebraic Riccati equation (DARE)
//! `P = A P A^T + Q - (A P C^T + S)(C P C^T + R)^{-1}(A P C^T + S)^T`, which
//! [`Riccati::dare`] solves directly by doubling.

use crate::error::LtiError;
use crate::state_space::StateSpace;
use nalgebra::{DMatrix, DVector};

/// Relative tolerance on the Cholesky pivots of `F_t`: pivot `c` (the variance of output
/// channel `c` given channels `0 .. c-1`) must exceed `PIVOT_TOL * F_t[c, c]`. This is
/// invariant to the scaling of each output channel.
const PIVOT_TOL: f64 = 1e-12;

/// Doubling iterations before the fall-back to the plain Riccati iteration.
const MAX_DOUBLING: usize = 100;

/// Riccati iterations of the fall-back DARE solver.
const MAX_RICCATI: usize = 1_000_000;

/// A failed Cholesky pivot of an innovation covariance.
#[derive(Debug)]
pub(crate) struct Singular {
    channel: usize,
    pivot: f64,
    variance: f64,
}

impl Singular {
    /// The error of a whitener whose innovation covariance is singular `when` (e.g. "at
    /// sample 3").
    pub(crate) fn into_error(self, when: &str) -> LtiError {
        let (c, pivot, variance) = (self.channel, self.pivot, self.variance);
        let what = if c == 0 || variance.is_nan() || variance <= 0.0 {
            format!("output channel {c} {when} does not depend on the noise")
        } else {
            format!(
                "output channel {c} {when} does not depend on the noise beyond what output \
                 channels 0..{c} already carry (its noise is a combination of theirs)"
            )
        };
        LtiError::param(
            "noise",
            format!(
                "{what}; the innovation covariance S = C P C^T + D D^T is singular (conditional \
                 variance {pivot:.3e} vs variance {variance:.3e}), so the noise covariance T T^T \
                 is not invertible. Every output needs noise of its own: D D^T must be positive \
                 definite (D of full row rank)"
            ),
        )
    }
}

/// `P_{t+1}` was not finite: the recursion overflowed.
#[derive(Debug)]
pub(crate) struct Overflow;

/// The gain of one step through a Cholesky factor `F = L L^T`.
pub(crate) struct CholeskyGain {
    /// `K = M F^{-1}` (`n x p`)
    pub(crate) k: DMatrix<f64>,
    /// `G = K L = M L^{-T}` (`n x p`)
    pub(crate) g: DMatrix<f64>,
    /// `L^{-1}` (`p x p`, lower)
    pub(crate) linv: DMatrix<f64>,
    /// `log det F`
    pub(crate) log_det: f64,
}

/// The system with its noise covariances: the coefficients of the Riccati recursion (see the
/// [module documentation](self)).
pub(crate) struct Riccati<'a> {
    /// the system
    pub(crate) sys: &'a StateSpace,
    /// `Q_v`
    qv: DMatrix<f64>,
    /// `Q = B Q_v B^T`
    pub(crate) q: DMatrix<f64>,
    /// `R = D Q_v D^T` (symmetrised)
    pub(crate) r: DMatrix<f64>,
    /// `S = B Q_v D^T`
    s: DMatrix<f64>,
    /// `|Q|_F`, the scale of the steady-state test
    q_norm: f64,
}

impl<'a> Riccati<'a> {
    /// The recursion of `sys` driven by noise of covariance `diag(variances)`, or of unit
    /// covariance for `None`.
    pub(crate) fn new(sys: &'a StateSpace, variances: Option<&[f64]>) -> Self {
        let (b, d) = (sys.b(), sys.d());
        // products with the identity are exact: the same values as without `Q_v`
        let qv = match variances {
            Some(v) => DMatrix::from_diagonal(&DVector::from_column_slice(v)),
            None => DMatrix::identity(b.ncols(), b.ncols()),
        };
        let (q, mut r, s) = (
            b * &qv * b.transpose(),
            d * &qv * d.transpose(),
            b * &qv * d.transpose(),
        );
        symmetrise(&mut r);
        Riccati {
            sys,
            q_norm: q.norm(),
            qv,
            q,
            r,
            s,
        }
    }

    /// The innovation covariance `F = C P C^T + R` (symmetrised) and `M = A P C^T + S` at
    /// the error covariance `p`; the gain is `K = M F^{-1}`.
    pub(crate) fn innovation(&self, p: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
        let (a, c) = (self.sys.a(), self.sys.c());
        let pct = p * c.transpose();
        let mut f = c * &pct + &self.r;
        symmetrise(&mut f);
        (f, a * &pct + &self.s)
    }

    /// The gain at the error covariance `p` through the checked Cholesky factor of `F`.
    pub(crate) fn cholesky_gain(&self, p: &DMatrix<f64>) -> Result<CholeskyGain, Singular> {
        let (f, m) = self.innovation(p);
        let l = cholesky_checked(&f)?;
        let linv = lower_inverse(&l);
        let g = &m * linv.transpose();
        let k = &g * &linv;
        let log_det = 2.0 * (0..l.nrows()).map(|i| l[(i, i)].ln()).sum::<f64>();
        Ok(CholeskyGain {
            k,
            g,
            linv,
            log_det,
        })
    }

    /// Joseph-form update `P+ = (A - K C) P (A - K C)^T + (B - K D) Q_v (B - K D)^T`.
    pub(crate) fn next(&self, p: &DMatrix<f64>, k: &DMatrix<f64>) -> DMatrix<f64> {
        let sys = self.sys;
        let phi = sys.a() - k * sys.c();
        let e = sys.b() - k * sys.d();
        let mut pn = &phi * p * phi.transpose() + &e * &self.qv * e.transpose();
        symmetrise(&mut pn);
        pn
    }

    /// The steady-state test `|next - prev|_F <= tol (|prev|_F + |Q|_F)`.
    pub(crate) fn converged(&self, prev: &DMatrix<f64>, next: &DMatrix<f64>, tol: f64) -> bool {
        (next - prev).norm() <= tol * (prev.norm() + self.q_norm)
    }

    /// The time-varying recursion from `p0`, with the steady-state test at `tol` (`None`:
    /// never steady).
    pub(crate) fn recursion(&self, p0: DMatrix<f64>, tol: Option<f64>) -> Recursion<'_, 'a> {
        Recursion {
            eq: self,
            p: p0,
            tol,
        }
    }

    /// Solution of the DARE reached by the Riccati recursion from `P_0 = 0` (`R` must be
    /// positive definite).
    ///
    /// Structure-preserving doubling (Chu, Fan, Lin 2005) on the equivalent equation
    /// without cross term, `P = Ab P (I + G P)^{-1} Ab^T + Qb` with `Ab = A - S R^{-1} C`,
    /// `Qb = E Q_v E^T`, `E = B - S R^{-1} D`, `G = C^T R^{-1} C`: its iterate `H_k` equals
    /// the Riccati iterate `P_{2^k}` from `P_0 = 0`, so it converges to the same limit
    /// as the time-varying recursion, quadratically in general. If doubling overflows
    /// (unstable modes of `Ab` that the noise does not excite) or stalls, the plain
    /// recursion is iterated instead.
    pub(crate) fn dare(&self, tol: f64) -> Result<DMatrix<f64>, LtiError> {
        let sys = self.sys;
        let n = sys.order();
        let l0 = cholesky_checked(&self.r).map_err(|s| s.into_error("(steady state)"))?;
        let l0inv = lower_inverse(&l0);
        let nl = &self.s * l0inv.transpose(); // S L^{-T}
        let lc = &l0inv * sys.c(); // L^{-1} C
        let ld = &l0inv * sys.d(); // L^{-1} D
        let abar = sys.a() - &nl * &lc;
        let e = sys.b() - &nl * &ld;
        let mut h = &e * &self.qv * e.transpose();
        symmetrise(&mut h);
        let mut g = lc.transpose() * &lc;
        symmetrise(&mut g);
        // control form: A_0 = Ab^T
        let mut ak = abar.transpose();
        let eye = DMatrix::<f64>::identity(n, n);
        for _ in 0..MAX_DOUBLING {
            let w = &eye + &g * &h;
            let lu = w.lu();
            let (Some(x1), Some(x2)) = (lu.solve(&ak), lu.solve(&g)) else {
                break;
            };
            let mut g1 = &g + &ak * x2 * ak.transpose();
            let mut h1 = &h + ak.transpose() * &h * &x1;
            symmetrise(&mut g1);
            symmetrise(&mut h1);
            let a1 = &ak * &x1;
            if !(all_finite(&a1) && all_finite(&g1) && all_finite(&h1)) {
                break;
            }
            let done = (&h1 - &h).norm() <= tol * (h.norm() + self.q_norm);
            h = h1;
            if done {
                return Ok(h);
            }
            ak = a1;
            g = g1;
        }
        // fall-back: the plain recursion from P_0 = 0
        let mut rec = self.recursion(DMatrix::zeros(n, n), Some(tol));
        for t in 0..MAX_RICCATI {
            let gain = self
                .cholesky_gain(rec.covariance())
                .map_err(|s| s.into_error(&format!("at Riccati iteration {t}")))?;
            match rec.advance(&gain.k) {
                Ok(true) => return Ok(rec.p),
                Ok(false) => {}
                Err(Overflow) => {
                    return Err(LtiError::param(
                        "noise",
                        "the Riccati recursion overflowed: the noise model is unstable in a \
                         direction the outputs do not observe",
                    ));
                }
            }
        }
        Err(LtiError::param(
            "noise",
            format!(
                "the Riccati equation did not converge in {MAX_RICCATI} iterations (the noise \
                 spectrum probably vanishes on the unit circle); use the time-varying filter"
            ),
        ))
    }
}

/// The state of the time-varying recursion: the current `P_t`.
pub(crate) struct Recursion<'e, 'a> {
    eq: &'e Riccati<'a>,
    p: DMatrix<f64>,
    tol: Option<f64>,
}

impl Recursion<'_, '_> {
    /// The current error covariance `P_t`.
    pub(crate) fn covariance(&self) -> &DMatrix<f64> {
        &self.p
    }

    /// Steps to `P_{t+1}` with the gain `k` of `P_t`; `Ok(true)` when the steady-state test
    /// holds between `P_t` and `P_{t+1}` (the gains of `P_t` are, to within the tolerance,
    /// those of every later step), [`Overflow`] when `P_{t+1}` is not finite.
    pub(crate) fn advance(&mut self, k: &DMatrix<f64>) -> Result<bool, Overflow> {
        let pn = self.eq.next(&self.p, k);
        if !all_finite(&pn) {
            return Err(Overflow);
        }
        let steady = self
            .tol
            .is_some_and(|tol| self.eq.converged(&self.p, &pn, tol));
        self.p = pn;
        Ok(steady)
    }
}

/// Lower Cholesky factor of the symmetric `s`, with the relative pivot test of
/// [`PIVOT_TOL`]; never produces NaN.
pub(crate) fn cholesky_checked(s: &DMatrix<f64>) -> Result<DMatrix<f64>, Singular> {
    let p = s.nrows();
    let mut l = DMatrix::<f64>::zeros(p, p);
    for j in 0..p {
        let variance = s[(j, j)];
        let mut pivot = variance;
        for k in 0..j {
            pivot -= l[(j, k)] * l[(j, k)];
        }
        // written so that NaN fails too
        if !(variance > 0.0 && variance.is_finite() && pivot > PIVOT_TOL * variance) {
            return Err(Singular {
                channel: j,
                pivot,
                variance,
            });
        }
        let d = pivot.sqrt();
        l[(j, j)] = d;
        for i in j + 1..p {
            let mut v = s[(i, j)];
            for k in 0..j {
                v -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = v / d;
        }
    }
    Ok(l)
}

/// Inverse of a lower-triangular matrix with nonzero diagonal.
pub(crate) fn lower_inverse(l: &DMatrix<f64>) -> DMatrix<f64> {
    let p = l.nrows();
    let mut inv = DMatrix::<f64>::zeros(p, p);
    for j in 0..p {
        inv[(j, j)] = 1.0 / l[(j, j)];
        for i in j + 1..p {
            let mut v = 0.0;
            for k in j..i {
                v -= l[(i, k)] * inv[(k, j)];
            }
            inv[(i, j)] = v / l[(i, i)];
        }
    }
    inv
}

/// Pseudo-inverse of the symmetric `s` through its eigendecomposition, with eigenvalues
/// `<= tau` treated as zero; also returns the eigenvectors of those (the null directions).
pub(crate) fn sym_pinv(s: &DMatrix<f64>, tau: f64) -> (DMatrix<f64>, Vec<DVector<f64>>) {
    let k = s.nrows();
    let mut pinv = DMatrix::zeros(k, k);
    let mut null = Vec::new();
    if k == 0 {
        return (pinv, null);
    }
    let eig = s.clone().symmetric_eigen();
    for i in 0..k {
        let v = eig.eigenvectors.column(i);
        let l = eig.eigenvalues[i];
        if l > tau {
            pinv += v * v.transpose() / l;
        } else {
            null.push(v.into_owned());
        }
    }
    symmetrise(&mut pinv);
    (pinv, null)
}

/// Replaces the square `m` by `(m + m^T) / 2`, removing the asymmetry rounding leaves in
/// products that are symmetric in exact arithmetic.
pub(crate) fn symmetrise(m: &mut DMatrix<f64>) {
    let n = m.nrows();
    for j in 0..n {
        for i in j + 1..n {
            let v = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}

pub(crate) fn all_finite(m: &DMatrix<f64>) -> bool {
    m.iter().all(|v| v.is_finite())
}

/// The entries of `m` row by row.
pub(crate) fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

/// Dot product of two slices (over the length of the shorter), with straight-line code for
/// the short lengths of the per-sample recursions (the branch is perfectly predictable
/// there).
#[inline(always)]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    match (a, b) {
        ([], _) | (_, []) => 0.0,
        ([a0], [b0, ..]) => a0 * b0,
        ([a0, a1], [b0, b1, ..]) => a0 * b0 + a1 * b1,
        ([a0, a1, a2], [b0, b1, b2, ..]) => a0 * b0 + a1 * b1 + a2 * b2,
        ([a0, a1, a2, a3], [b0, b1, b2, b3, ..]) => (a0 * b0 + a1 * b1) + (a2 * b2 + a3 * b3),
        _ => a.iter().zip(b).map(|(x, y)| x * y).sum(),
    }
}

/// `out = M x` for a row-major `M` with `out.len()` rows and `x.len()` columns.
/// (Rows are split off one by one: `chunks_exact` would cost a division per call, which
/// matters at a few nanoseconds per sample.)
#[inline(always)]
pub(crate) fn mat_vec(mat: &[f64], x: &[f64], out: &mut [f64]) {
    let mut rest = mat;
    for o in out.iter_mut() {
        let (row, tail) = rest.split_at(x.len());
        *o = dot(row, x);
        rest = tail;
    }
}

/// `out = M [x1; x2; x3]` for a row-major `M` with `out.len()` rows (no copy of the
/// stacked vector).
#[inline(always)]
pub(crate) fn mat_vec3(mat: &[f64], x1: &[f64], x2: &[f64], x3: &[f64], out: &mut [f64]) {
    let mut rest = mat;
    for o in out.iter_mut() {
        let (r1, tail) = rest.split_at(x1.len());
        let (r2, tail) = tail.split_at(x2.len());
        let (r3, tail) = tail.split_at(x3.len());
        *o = dot(r1, x1) + dot(r2, x2) + dot(r3, x3);
        rest = tail;
    }
}

/// `out += alpha M x` for a row-major `M` with `out.len()` rows and `x.len()` columns.
#[inline(always)]
pub(crate) fn mat_vec_add(mat: &[f64], x: &[f64], alpha: f64, out: &mut [f64]) {
    let mut rest = mat;
    for o in out.iter_mut() {
        let (row, tail) = rest.split_at(x.len());
        *o += alpha * dot(row, x);
        rest = tail;
    }
}

/// `out += M^T x` for a row-major `M` with `x.len()` rows and `out.len()` columns.
#[inline(always)]
pub(crate) fn mat_t_vec_add(mat: &[f64], x: &[f64], out: &mut [f64]) {
    let mut rest = mat;
    for &xi in x {
        let (row, tail) = rest.split_at(out.len());
        for (o, &mij) in out.iter_mut().zip(row) {
            *o += mij * xi;
        }
        rest = tail;
    }
}

#[cfg(test)]
mod tests;

//! The [`LinearSystem`] operator trait: block lower-triangular Toeplitz operators acting on
//! stacked time-major signals.

use crate::error::LtiError;
use crate::signal::Signal;
use faer::{Accum, MatMut, MatRef};

/// A causal discrete-time LTI system seen as a linear operator `T` on stacked signals.
///
/// All slices are time-major: the value of channel `c` at time `k` is at index
/// `k * channels + c`. `T` is block lower-triangular Toeplitz with blocks `h_{i-j}`
/// (the Markov parameters), and the initial state is always zero.
///
/// # Contract of the fast paths
/// [`apply`](LinearSystem::apply), [`apply_adjoint`](LinearSystem::apply_adjoint) and the
/// `*_columns` methods are internal fast paths: they do **not** return errors and may
/// panic (via `assert!`) when the lengths are inconsistent (`u.len() = L * inputs`,
/// `y.len() = L * outputs` with the same `L`). Non-finite values simply propagate.
/// [`simulate`](LinearSystem::simulate) is the checked entry point.
pub trait LinearSystem: Send + Sync {
    /// Number of input channels `m`.
    fn inputs(&self) -> usize;
    /// Number of output channels `p`.
    fn outputs(&self) -> usize;
    /// Number of states (0 for a static gain); used by solvers to spot static operators.
    fn order(&self) -> usize;

    /// `y = T u` with zero initial state. `u.len() = L * inputs`, `y.len() = L * outputs`
    /// (same `L`). Overwrites `y`.
    fn apply(&self, u: &[f64], y: &mut [f64]);

    /// `u = T^T y` (adjoint), computed by a backward-in-time recursion. Overwrites `u`.
    fn apply_adjoint(&self, y: &[f64], u: &mut [f64]);

    /// Applies `T` to many signals at once: each **column** of `x` is one stacked input
    /// signal (`L * inputs` rows); `out` has `L * outputs` rows and as many columns.
    ///
    /// `Accum::Replace` gives `out = alpha * T x`, `Accum::Add` gives `out += alpha * T x`.
    /// `x` may be any strided view, in particular a transposed one.
    ///
    /// The default implementation loops over the columns with [`apply`](LinearSystem::apply)
    /// through a scratch vector; implementors should override it with a blocked version.
    fn apply_columns(&self, x: MatRef<'_, f64>, out: MatMut<'_, f64>, accum: Accum, alpha: f64) {
        columns_via(
            x,
            out,
            accum,
            alpha,
            self.inputs(),
            self.outputs(),
            |a, b| self.apply(a, b),
        );
    }

    /// Adjoint version of [`apply_columns`](LinearSystem::apply_columns):
    /// `out = alpha * T^T x` (`Replace`) or `out += alpha * T^T x` (`Add`), where `x` has
    /// `L * outputs` rows and `out` has `L * inputs` rows.
    fn apply_adjoint_columns(
        &self,
        x: MatRef<'_, f64>,
        out: MatMut<'_, f64>,
        accum: Accum,
        alpha: f64,
    ) {
        columns_via(
            x,
            out,
            accum,
            alpha,
            self.outputs(),
            self.inputs(),
            |a, b| self.apply_adjoint(a, b),
        );
    }

    /// Checked simulation from zero initial state: verifies that `u` has
    /// [`inputs`](LinearSystem::inputs) channels and only finite values, then returns the
    /// output signal (same length, [`outputs`](LinearSystem::outputs) channels).
    fn simulate(&self, u: &Signal) -> Result<Signal, LtiError> {
        if u.channels() != self.inputs() {
            return Err(LtiError::dims(
                "input signal channels",
                self.inputs(),
                u.channels(),
            ));
        }
        u.check_finite("input signal")?;
        let mut y = Signal::zeros(u.len(), self.outputs());
        self.apply(u.as_slice(), y.as_mut_slice());
        Ok(y)
    }
}

/// Number of samples implied by an input slice of `ulen` values over `m` channels and an
/// output slice of `ylen` values over `p` channels; panics when they are inconsistent.
pub(crate) fn horizon(m: usize, p: usize, ulen: usize, ylen: usize) -> usize {
    let len = if m > 0 {
        assert!(
            ulen % m == 0,
            "input length {ulen} is not a multiple of the {m} input channels"
        );
        ulen / m
    } else if p > 0 {
        assert!(
            ylen % p == 0,
            "output length {ylen} is not a multiple of the {p} output channels"
        );
        ylen / p
    } else {
        0
    };
    assert!(
        ulen == len * m && ylen == len * p,
        "inconsistent lengths: {ulen} input values ({m} channels) vs {ylen} output values ({p} channels)"
    );
    len
}

/// Column-by-column fallback used by the default `*_columns` implementations.
fn columns_via(
    x: MatRef<'_, f64>,
    mut out: MatMut<'_, f64>,
    accum: Accum,
    alpha: f64,
    in_ch: usize,
    out_ch: usize,
    op: impl Fn(&[f64], &mut [f64]),
) {
    assert_eq!(x.ncols(), out.ncols(), "x and out must have the same number of columns");
    let _ = horizon(in_ch, out_ch, x.nrows(), out.nrows());
    let mut u = vec![0.0; x.nrows()];
    let mut y = vec![0.0; out.nrows()];
    for j in 0..x.ncols() {
        for (i, ui) in u.iter_mut().enumerate() {
            *ui = x[(i, j)];
        }
        op(&u, &mut y);
        for (i, &yi) in y.iter().enumerate() {
            let o = &mut out[(i, j)];
            *o = match accum {
                Accum::Replace => alpha * yi,
                Accum::Add => *o + alpha * yi,
            };
        }
    }
}

//! Discrete-time transfer functions in the backward shift operator `q^-1`, and their
//! state-space realisation.

use crate::error::LtiError;
use crate::state_space::StateSpace;
use nalgebra::DMatrix;

/// A SISO transfer function in `q^-1`:
/// `y = (num[0] + num[1] q^-1 + ...) / (den[0] + den[1] q^-1 + ...) u`, with `den[0] != 0`
/// (the realisation normalises by `den[0]`). An empty `num` is the zero transfer function.
#[derive(Clone, Debug, PartialEq)]
pub struct Siso {
    /// Numerator coefficients `b_0, b_1, ...` of `1, q^-1, q^-2, ...`.
    pub num: Vec<f64>,
    /// Denominator coefficients `a_0, a_1, ...` of `1, q^-1, q^-2, ...` (`a_0 != 0`).
    pub den: Vec<f64>,
}

impl Siso {
    fn validate(&self, i: usize, j: usize) -> Result<(), LtiError> {
        let at = format!("entry (output {i}, input {j})");
        let Some(&a0) = self.den.first() else {
            return Err(LtiError::InvalidTransferFunction(format!(
                "{at}: the denominator is empty"
            )));
        };
        if a0 == 0.0 {
            return Err(LtiError::InvalidTransferFunction(format!(
                "{at}: the leading denominator coefficient is zero (non-causal or ill-posed)"
            )));
        }
        for (name, v) in [("numerator", &self.num), ("denominator", &self.den)] {
            if let Some(k) = v.iter().position(|x| !x.is_finite()) {
                return Err(LtiError::InvalidTransferFunction(format!(
                    "{at}: {name} coefficient {k} is not finite ({})",
                    v[k]
                )));
            }
        }
        Ok(())
    }

    /// Observable canonical form `(A, B, C, D)` of this entry, normalised by `den[0]`;
    /// trailing exact zeros of `num`/`den` are dropped first.
    fn realise(&self) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>, f64) {
        let trim = |v: &[f64]| -> Vec<f64> {
            let end = v.iter().rposition(|&x| x != 0.0).map_or(0, |k| k + 1);
            v[..end].to_vec()
        };
        let num = trim(&self.num);
        // `den[0] != 0`, so the trimmed denominator keeps it.
        let den = trim(&self.den);
        let (a, b, c, d) = observable_canonical(std::slice::from_ref(&num), &den);
        (a, b, c, d[(0, 0)])
    }
}

/// Observable canonical form of the common-denominator row `y = Σ_i num[i]/den · u_i`,
/// normalised by `den[0]` (nonzero, checked by the callers), of order
/// `n = max(den.len() − 1, max_i num[i].len() − 1)`: `A` has `−a_1 … −a_n` in its first
/// column and ones on the superdiagonal, `B[r, i] = b_{i,r+1} − b_{i,0} a_{r+1}`,
/// `C = e_1ᵀ`, `D[0, i] = b_{i,0}` (missing coefficients are 0).
fn observable_canonical<N: AsRef<[f64]>>(
    num: &[N],
    den: &[f64],
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let a0 = den[0];
    let m = num.len();
    let n = num
        .iter()
        .map(|b| b.as_ref().len().saturating_sub(1))
        .fold(den.len() - 1, usize::max);
    let a = |j: usize| den.get(j).map_or(0.0, |v| v / a0);
    let b = |i: usize, j: usize| num[i].as_ref().get(j).map_or(0.0, |v| v / a0);
    let mut am = DMatrix::zeros(n, n);
    let mut bm = DMatrix::zeros(n, m);
    let mut cm = DMatrix::zeros(1, n);
    let mut dm = DMatrix::zeros(1, m);
    for r in 0..n {
        am[(r, 0)] = -a(r + 1);
        if r + 1 < n {
            am[(r, r + 1)] = 1.0;
        }
        for i in 0..m {
            bm[(r, i)] = b(i, r + 1) - b(i, 0) * a(r + 1);
        }
    }
    if n > 0 {
        cm[(0, 0)] = 1.0;
    }
    for i in 0..m {
        dm[(0, i)] = b(i, 0);
    }
    (am, bm, cm, dm)
}

/// State-space realisation of a multi-input, single-output row `y = Σ_i num[i]/den · u_i`
/// whose entries share the denominator `den` (coefficients of `1, q^-1, q^-2, …`).
///
/// Unlike [`TransferFunction::to_state_space`], which realises every entry separately, the
/// row is realised jointly in observable canonical form (see [`TransferFunction`]'s
/// realisation for the matrices), so the order is that of the common denominator:
/// `n = max(den.len() − 1, max_i num[i].len() − 1)`. No coefficient is trimmed, so the
/// order follows the given lengths. Errors when `den` is empty, starts with 0, when there
/// is no numerator, or when a coefficient is not finite.
///
/// ```
/// use structid_lti::transfer_function::realise_row;
/// // y = (u_1 + q^-2 u_2) / (1 - 0.5 q^-1)
/// let ss = realise_row(&[vec![1.0], vec![0.0, 0.0, 1.0]], &[1.0, -0.5]).unwrap();
/// assert_eq!((ss.order(), ss.inputs(), ss.outputs()), (2, 2, 1));
/// ```
pub fn realise_row<N: AsRef<[f64]>>(num: &[N], den: &[f64]) -> Result<StateSpace, LtiError> {
    if num.is_empty() {
        return Err(LtiError::InvalidTransferFunction(
            "a row needs at least one numerator (one input)".into(),
        ));
    }
    for (j, b) in num.iter().enumerate() {
        Siso {
            num: b.as_ref().to_vec(),
            den: den.to_vec(),
        }
        .validate(0, j)?;
    }
    let (a, b, c, d) = observable_canonical(num, den);
    StateSpace::new(a, b, c, d)
}

/// The zero-initial-condition response of a common-denominator row,
/// `y_k = Σ_i Σ_j b_{i,j} u_{i,k−j} − Σ_{j≥1} a_j y_{k−j}`, by direct recursion
/// (`O(len·(na + Σ nb))`), written to `y` (`y.len()` samples).
///
/// `den` must be monic: `den[0]` is taken as 1 and not read, because the callers normalise
/// once and then filter many signals. `num[i]` filters `u[i]`; samples past the end of a
/// `u[i]` count as zero, and extra numerators or inputs (beyond the shorter of the two)
/// are ignored. Nothing is checked: an unstable or non-finite filter propagates
/// infinities or NaNs.
///
/// ```
/// use structid_lti::transfer_function::filter_row;
/// // y_k = 0.5 y_{k-1} + u_{k-1}
/// let mut y = vec![0.0; 4];
/// filter_row(&[vec![0.0, 1.0]], &[1.0, -0.5], &[vec![1.0, 0.0, 0.0, 0.0]], &mut y);
/// assert_eq!(y, vec![0.0, 1.0, 0.5, 0.25]);
/// ```
pub fn filter_row<N: AsRef<[f64]>, U: AsRef<[f64]>>(
    num: &[N],
    den: &[f64],
    u: &[U],
    y: &mut [f64],
) {
    for k in 0..y.len() {
        let mut acc = 0.0;
        for (b, ui) in num.iter().zip(u) {
            let ui = ui.as_ref();
            for (j, bj) in b.as_ref().iter().enumerate().take(k + 1) {
                if let Some(x) = ui.get(k - j) {
                    acc += bj * x;
                }
            }
        }
        for (j, aj) in den.iter().enumerate().skip(1).take(k) {
            acc -= aj * y[k - j];
        }
        y[k] = acc;
    }
}

/// A discrete-time MIMO transfer matrix: `entries[i][j]` maps input `j` to output `i`.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunction {
    entries: Vec<Vec<Siso>>,
    sample_time: Option<f64>,
}

impl TransferFunction {
    /// A SISO transfer function `num(q^-1) / den(q^-1)`.
    ///
    /// ```
    /// use structid_lti::TransferFunction;
    /// // y_k = u_k + 0.5 y_{k-1}
    /// let tf = TransferFunction::siso(vec![1.0], vec![1.0, -0.5]).unwrap();
    /// let ss = tf.to_state_space();
    /// let h = ss.markov_parameters(3);
    /// assert_eq!((h[0][(0, 0)], h[1][(0, 0)], h[2][(0, 0)]), (1.0, 0.5, 0.25));
    /// ```
    pub fn siso(num: Vec<f64>, den: Vec<f64>) -> Result<Self, LtiError> {
        Self::new(vec![vec![Siso { num, den }]])
    }

    /// A transfer matrix (`outputs x inputs`, rectangular, at least `1 x 1`); every entry
    /// needs a nonzero leading denominator coefficient and finite coefficients.
    ///
    /// ```
    /// use structid_lti::{Siso, TransferFunction};
    /// // the row [1, q^-2]
    /// let tf = TransferFunction::new(vec![vec![
    ///     Siso { num: vec![1.0], den: vec![1.0] },
    ///     Siso { num: vec![0.0, 0.0, 1.0], den: vec![1.0] },
    /// ]])
    /// .unwrap();
    /// assert_eq!(tf.to_state_space().order(), 2);
    /// ```
    pub fn new(entries: Vec<Vec<Siso>>) -> Result<Self, LtiError> {
        let outputs = entries.len();
        let inputs = entries.first().map_or(0, Vec::len);
        if outputs == 0 || inputs == 0 {
            return Err(LtiError::InvalidTransferFunction(
                "a transfer matrix needs at least one output and one input".into(),
            ));
        }
        for (i, row) in entries.iter().enumerate() {
            if row.len() != inputs {
                return Err(LtiError::InvalidTransferFunction(format!(
                    "ragged transfer matrix: row {i} has {} entries, row 0 has {inputs}",
                    row.len()
                )));
            }
            for (j, e) in row.iter().enumerate() {
                e.validate(i, j)?;
            }
        }
        Ok(TransferFunction {
            entries,
            sample_time: None,
        })
    }

    /// Attaches a sample time (positive, finite), carried over to the realisation.
    pub fn with_sample_time(mut self, ts: f64) -> Result<Self, LtiError> {
        if !(ts.is_finite() && ts > 0.0) {
            return Err(LtiError::param(
                "sample_time",
                format!("must be positive and finite, got {ts}"),
            ));
        }
        self.sample_time = Some(ts);
        Ok(self)
    }

    /// The sample time, if one was attached.
    pub fn sample_time(&self) -> Option<f64> {
        self.sample_time
    }

    /// The entries, `outputs x inputs`.
    pub fn entries(&self) -> &[Vec<Siso>] {
        &self.entries
    }

    /// Number of outputs (rows).
    pub fn outputs(&self) -> usize {
        self.entries.len()
    }

    /// Number of inputs (columns).
    pub fn inputs(&self) -> usize {
        self.entries[0].len()
    }

    /// Simulates the transfer matrix from zero initial conditions, entry by entry with the
    /// difference-equation recursion of [`filter_row`] (each entry normalised by its
    /// `den[0]`), summing the entries of a row. `u` needs [`inputs`](Self::inputs)
    /// channels; the result has [`outputs`](Self::outputs) channels and `u.len()` samples.
    ///
    /// ```
    /// use structid_lti::{Signal, TransferFunction};
    /// // y_k = 0.5 y_{k-1} + u_{k-1}
    /// let tf = TransferFunction::siso(vec![0.0, 1.0], vec![1.0, -0.5]).unwrap();
    /// let y = tf.simulate(&Signal::new(1, vec![1.0, 0.0, 0.0, 0.0]).unwrap()).unwrap();
    /// assert_eq!(y.channel(0), vec![0.0, 1.0, 0.5, 0.25]);
    /// ```
    pub fn simulate(&self, u: &crate::Signal) -> Result<crate::Signal, LtiError> {
        if u.channels() != self.inputs() {
            return Err(LtiError::dims(
                "input channels of the simulated signal",
                self.inputs(),
                u.channels(),
            ));
        }
        let len = u.len();
        let cols: Vec<Vec<f64>> = (0..u.channels()).map(|c| u.channel(c)).collect();
        let p = self.outputs();
        let mut out = vec![0.0; len * p];
        let mut y = vec![0.0; len];
        for (i, row) in self.entries.iter().enumerate() {
            for (e, col) in row.iter().zip(&cols) {
                let a0 = e.den[0];
                let den: Vec<f64> = e.den.iter().map(|v| v / a0).collect();
                let num: Vec<f64> = e.num.iter().map(|v| v / a0).collect();
                filter_row(
                    std::slice::from_ref(&num),
                    &den,
                    std::slice::from_ref(col),
                    &mut y,
                );
                for (k, v) in y.iter().enumerate() {
                    out[k * p + i] += v;
                }
            }
        }
        crate::Signal::new(p, out)
    }

    /// State-space realisation.
    ///
    /// Each entry is realised separately in observable canonical form of order
    /// `max(len num, len den) - 1` (after dropping trailing exact zeros) and the pieces
    /// are assembled block-diagonally. The result is therefore in general **not minimal**
    /// for MIMO matrices (entries sharing poles are not merged), which is harmless for
    /// simulation and for the Toeplitz operators.
    pub fn to_state_space(&self) -> StateSpace {
        let (p, m) = (self.outputs(), self.inputs());
        let parts: Vec<Vec<_>> = self
            .entries
            .iter()
            .map(|row| row.iter().map(Siso::realise).collect())
            .collect();
        let n: usize = parts.iter().flatten().map(|(a, ..)| a.nrows()).sum();
        let mut a = DMatrix::zeros(n, n);
        let mut b = DMatrix::zeros(n, m);
        let mut c = DMatrix::zeros(p, n);
        let mut d = DMatrix::zeros(p, m);
        let mut off = 0;
        for (i, row) in parts.iter().enumerate() {
            for (j, (ai, bi, ci, di)) in row.iter().enumerate() {
                let k = ai.nrows();
                a.view_mut((off, off), (k, k)).copy_from(ai);
                b.view_mut((off, j), (k, 1)).copy_from(bi);
                c.view_mut((i, off), (1, k)).copy_from(ci);
                d[(i, j)] = *di;
                off += k;
            }
        }
        let ss = StateSpace::new(a, b, c, d)
            .expect("realisation of a validated transfer function is well formed");
        match self.sample_time {
            Some(ts) => ss.with_sample_time(ts).expect("sample time validated"),
            None => ss,
        }
    }
}

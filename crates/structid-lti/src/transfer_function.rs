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
        let a0 = self.den[0];
        let trim = |v: &[f64]| -> Vec<f64> {
            let end = v.iter().rposition(|&x| x != 0.0).map_or(0, |k| k + 1);
            v[..end].iter().map(|x| x / a0).collect()
        };
        let mut num = trim(&self.num);
        let mut den = trim(&self.den);
        let order = num.len().max(den.len()).saturating_sub(1);
        num.resize(order + 1, 0.0);
        den.resize(order + 1, 0.0);
        let b0 = num[0];
        let mut a = DMatrix::zeros(order, order);
        let mut b = DMatrix::zeros(order, 1);
        let mut c = DMatrix::zeros(1, order);
        for i in 0..order {
            a[(i, 0)] = -den[i + 1];
            if i + 1 < order {
                a[(i, i + 1)] = 1.0;
            }
            b[(i, 0)] = num[i + 1] - b0 * den[i + 1];
        }
        if order > 0 {
            c[(0, 0)] = 1.0;
        }
        (a, b, c, b0)
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

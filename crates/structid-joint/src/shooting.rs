//! The simulation-error least-squares problem with multiple shooting.
//!
//! Each record is cut into segments k ∈ [t_s, t_(s+1)); segment s starts from a free stacked
//! state ξ_s. With θ the model's parameters the residuals are
//!
//! ```text
//!   y_k − ŷ_k(θ, ξ_s)                                  every sample of every segment
//!   μ·(ξ_(s+1) − Φ_s(θ, ξ_s))                          between consecutive segments of a record
//!   √L·R_b·θ_b                                         every regularised block
//! ```
//!
//! where Φ_s is the state at the segment's end and μ the continuity weight. Their sum of
//! squares is L times the paper's criterion (1/L)·Σ|e_k|² + Σ_b β_b·D_b(θ_b) plus the
//! continuity penalty, which vanishes on a model that is simulated in one piece. Short
//! segments keep each simulation near the data, so an integrator or a poor start does not
//! carry an early error through the whole record.
//!
//! The Jacobian is never stored: the normal equations JᵀJ and Jᵀr are accumulated sample by
//! sample from the forward sensitivities (O(L·P²) per iteration, memory O(P²)). Segment s's
//! rows depend on the global parameters and on ξ_s only, so its sensitivities carry P_g + n_ξ
//! columns however many segments there are.

use nalgebra::{DMatrix, DVector};
use structid_core::Data;
use structid_linear::levenberg_marquardt::LeastSquaresProblem;

use crate::model::JointModel;
use crate::step::Stepper;

/// One segment: its record, its samples (indices into the stacked data) and where its free
/// initial state sits in the full parameter vector (`None` when it is held fixed).
#[derive(Clone, Debug)]
pub(crate) struct Segment {
    pub(crate) start: usize,
    pub(crate) end: usize,
    pub(crate) state_at: Option<usize>,
    /// The state it starts from when held fixed.
    pub(crate) fixed: Vec<f64>,
    /// Whether the next segment continues this one's record.
    pub(crate) continued: bool,
}

/// The multiple-shooting problem over `data` for the parameters of `model`.
pub(crate) struct Shooting<'a> {
    pub(crate) model: &'a JointModel,
    pub(crate) data: &'a Data,
    pub(crate) segments: Vec<Segment>,
    pub(crate) globals: usize,
    pub(crate) weight: f64,
    /// Regulariser rows (√L·R_b) with the parameter column where block b's parameters start.
    pub(crate) regularisers: Vec<(usize, DMatrix<f64>)>,
}

impl<'a> Shooting<'a> {
    pub(crate) fn new(model: &'a JointModel, data: &'a Data, segments: Vec<Segment>, weight: f64) -> Self {
        let offsets = model.parameter_offsets();
        let scale = (data.len() as f64).sqrt();
        let regularisers = model
            .blocks()
            .iter()
            .enumerate()
            .filter_map(|(i, b)| b.map.regulariser().map(|r| (offsets[i], r * scale)))
            .collect();
        Self {
            model,
            data,
            segments,
            globals: *offsets.last().expect("non-empty"),
            weight,
            regularisers,
        }
    }

    /// Total parameter count: globals, then each free segment state.
    pub(crate) fn len(&self) -> usize {
        self.globals
            + self.segments.iter().filter(|s| s.state_at.is_some()).count()
                * self.model.stacked_state_len()
    }

    fn start_state(&self, s: &Segment, theta: &[f64]) -> Vec<f64> {
        let nxi = self.model.stacked_state_len();
        match s.state_at {
            Some(at) => theta[at..at + nxi].to_vec(),
            None => s.fixed.clone(),
        }
    }

    fn regulariser_residuals(&self, theta: &[f64], out: &mut Vec<f64>) {
        for (at, r) in &self.regularisers {
            let th = DVector::from_column_slice(&theta[*at..*at + r.ncols()]);
            out.extend((r * th).iter());
        }
    }
}

impl LeastSquaresProblem for Shooting<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        let model = self.model.with_parameters(&theta[..self.globals]).ok()?;
        let stepper = Stepper::new(&model);
        let ny = stepper.outputs();
        let y = self.data.y();
        let mut r = Vec::with_capacity(self.data.len() * ny);
        let mut ends = Vec::with_capacity(self.segments.len());
        for s in &self.segments {
            let mut xi = self.start_state(s, theta);
            stepper.run(self.data.u(), s.start..s.end, &mut xi, |k, yk| {
                r.extend(y.sample(k).iter().zip(yk).map(|(m, p)| m - p));
            })?;
            ends.push(xi);
        }
        for (i, s) in self.segments.iter().enumerate() {
            if s.continued {
                let next = self.start_state(&self.segments[i + 1], theta);
                r.extend(next.iter().zip(&ends[i]).map(|(a, b)| self.weight * (a - b)));
            }
        }
        self.regulariser_residuals(theta, &mut r);
        r.iter().all(|v| v.is_finite()).then(|| DVector::from_vec(r))
    }

    fn jacobian(&mut self, _theta: &[f64], _r: &DVector<f64>) -> Option<DMatrix<f64>> {
        // The normal equations are accumulated directly; a stored Jacobian would be L × P.
        None
    }

    fn normal_equations(&mut self, theta: &[f64], _r: &DVector<f64>) -> Option<(DMatrix<f64>, DVector<f64>)> {
        let model = self.model.with_parameters(&theta[..self.globals]).ok()?;
        let stepper = Stepper::new(&model);
        let (ny, nxi, pg) = (stepper.outputs(), model.stacked_state_len(), self.globals);
        let p = pg + nxi;
        let total = self.len();
        let mut jtj = DMatrix::zeros(total, total);
        let mut jtr = DVector::zeros(total);
        let y = self.data.y();
        let mut ends: Vec<(Vec<f64>, Vec<f64>)> = Vec::with_capacity(self.segments.len());
        let mut idx = vec![0usize; p];
        for s in &self.segments {
            let mut xi = self.start_state(s, theta);
            let mut t = vec![0.0; nxi * p];
            for i in 0..nxi {
                t[i * p + pg + i] = 1.0;
            }
            // Local columns of a fixed start are zero; they are mapped but never reached.
            let local = s.state_at.unwrap_or(0);
            for (c, slot) in idx.iter_mut().enumerate() {
                *slot = if c < pg { c } else { local + c - pg };
            }
            let live = if s.state_at.is_some() { p } else { pg };
            stepper.run_tangent(self.data.u(), s.start..s.end, &mut xi, &mut t, p, |k, yk, dy| {
                for o in 0..ny {
                    let res = y.sample(k)[o] - yk[o];
                    // J row = −∂ŷ; the sign cancels in JᵀJ and flips Jᵀr.
                    let g = &dy[o * p..o * p + live];
                    accumulate(&mut jtj, &mut jtr, &idx[..live], g, -res);
                }
            })?;
            ends.push((xi, t));
        }
        for (i, s) in self.segments.iter().enumerate() {
            if !s.continued {
                continue;
            }
            let next = &self.segments[i + 1];
            let nstate = self.start_state(next, theta);
            let (end, t) = &ends[i];
            let local = s.state_at;
            for c in 0..nxi {
                // r = μ(ξ_(s+1),c − Φ_c): J = −μ·∂Φ_c on (globals, ξ_s) and +μ on ξ_(s+1),c.
                let mut cols = Vec::with_capacity(p + 1);
                let mut vals = Vec::with_capacity(p + 1);
                for q in 0..p {
                    let col = match (q < pg, local) {
                        (true, _) => q,
                        (false, Some(at)) => at + q - pg,
                        (false, None) => continue,
                    };
                    cols.push(col);
                    vals.push(-self.weight * t[c * p + q]);
                }
                if let Some(at) = next.state_at {
                    cols.push(at + c);
                    vals.push(self.weight);
                }
                let res = self.weight * (nstate[c] - end[c]);
                accumulate(&mut jtj, &mut jtr, &cols, &vals, res);
            }
        }
        for (at, r) in &self.regularisers {
            let th = DVector::from_column_slice(&theta[*at..*at + r.ncols()]);
            let res = r * &th;
            let cols: Vec<usize> = (*at..*at + r.ncols()).collect();
            for i in 0..r.nrows() {
                let row: Vec<f64> = r.row(i).iter().copied().collect();
                accumulate(&mut jtj, &mut jtr, &cols, &row, res[i]);
            }
        }
        Some((jtj, jtr))
    }
}

/// Adds one residual's row `g` (on columns `cols`) to JᵀJ and g·res to Jᵀr.
fn accumulate(jtj: &mut DMatrix<f64>, jtr: &mut DVector<f64>, cols: &[usize], g: &[f64], res: f64) {
    for (a, &ca) in cols.iter().enumerate() {
        let ga = g[a];
        if ga == 0.0 {
            continue;
        }
        jtr[ca] += ga * res;
        for (b, &cb) in cols.iter().enumerate() {
            jtj[(ca, cb)] += ga * g[b];
        }
    }
}

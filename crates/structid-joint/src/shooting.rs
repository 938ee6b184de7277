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
use structid_linear::levenberg_marquardt::NormalEquationsProblem;
use structid_linear::normal_equations::NormalEquations;

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
    pub(crate) regularisers: Regularisers,
}

/// The regulariser rows √L·R_b of every regularised block, each with the parameter column
/// where its block's parameters start: the residuals √L·R_b·θ_b whose squares are
/// L·β_b·D_b(θ_b).
pub(crate) struct Regularisers(Vec<(usize, DMatrix<f64>)>);

impl Regularisers {
    /// The rows of `model`'s blocks, scaled by √L for the samples of `data`.
    pub(crate) fn of(model: &JointModel, data: &Data) -> Self {
        let offsets = model.parameter_offsets();
        let scale = (data.len() as f64).sqrt();
        Self(
            model
                .blocks()
                .iter()
                .enumerate()
                .filter_map(|(i, b)| b.map.regulariser().map(|r| (offsets[i], r * scale)))
                .collect(),
        )
    }

    /// The residual vector: the data's residuals `out`, then √L·R_b·θ_b; `None` when any
    /// is not finite, for a diverged simulation rejects θ.
    pub(crate) fn residuals(&self, theta: &[f64], mut out: Vec<f64>) -> Option<DVector<f64>> {
        for (at, r) in &self.0 {
            let th = DVector::from_column_slice(&theta[*at..*at + r.ncols()]);
            out.extend((r * th).iter());
        }
        out.iter()
            .all(|v| v.is_finite())
            .then(|| DVector::from_vec(out))
    }

    /// Adds their rows (J = R_b on block b's columns) to the normal equations.
    pub(crate) fn add_to(&self, normal: &mut NormalEquations, theta: &[f64]) {
        for (at, r) in &self.0 {
            let th = DVector::from_column_slice(&theta[*at..*at + r.ncols()]);
            let res = r * &th;
            let cols: Vec<usize> = (*at..*at + r.ncols()).collect();
            for i in 0..r.nrows() {
                let row: Vec<f64> = r.row(i).iter().copied().collect();
                normal.add_sparse_row(&cols, &row, res[i]);
            }
        }
    }
}

impl<'a> Shooting<'a> {
    pub(crate) fn new(
        model: &'a JointModel,
        data: &'a Data,
        segments: Vec<Segment>,
        weight: f64,
    ) -> Self {
        let offsets = model.parameter_offsets();
        Self {
            model,
            data,
            segments,
            globals: *offsets.last().expect("non-empty"),
            weight,
            regularisers: Regularisers::of(model, data),
        }
    }

    /// Total parameter count: globals, then each free segment state.
    pub(crate) fn len(&self) -> usize {
        self.globals
            + self
                .segments
                .iter()
                .filter(|s| s.state_at.is_some())
                .count()
                * self.model.stacked_state_len()
    }

    fn start_state(&self, s: &Segment, theta: &[f64]) -> Vec<f64> {
        let nxi = self.model.stacked_state_len();
        match s.state_at {
            Some(at) => theta[at..at + nxi].to_vec(),
            None => s.fixed.clone(),
        }
    }
}

impl NormalEquationsProblem for Shooting<'_> {
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
                r.extend(
                    next.iter()
                        .zip(&ends[i])
                        .map(|(a, b)| self.weight * (a - b)),
                );
            }
        }
        self.regularisers.residuals(theta, r)
    }

    /// Accumulated segment by segment, each on the columns its rows reach.
    fn normal_equations(&mut self, theta: &[f64]) -> Option<(DMatrix<f64>, DVector<f64>)> {
        let model = self.model.with_parameters(&theta[..self.globals]).ok()?;
        let stepper = Stepper::new(&model);
        let (ny, nxi, pg) = (stepper.outputs(), model.stacked_state_len(), self.globals);
        let p = pg + nxi;
        let total = self.len();
        let mut normal = NormalEquations::new(total);
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
            // The segment's rows reach only its `live` columns: accumulate them there and
            // scatter once.
            let mut segment = NormalEquations::new(live);
            stepper.run_tangent(
                self.data.u(),
                s.start..s.end,
                &mut xi,
                &mut t,
                p,
                |k, yk, dy| {
                    for o in 0..ny {
                        let res = y.sample(k)[o] - yk[o];
                        // J row = −∂ŷ; the sign cancels in JᵀJ and flips Jᵀr.
                        segment.add_row(&dy[o * p..o * p + live], -res);
                    }
                },
            )?;
            normal.add_scattered(segment, &idx[..live]);
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
                normal.add_sparse_row(&cols, &vals, res);
            }
        }
        self.regularisers.add_to(&mut normal, theta);
        Some(normal.finish())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::GaussianFeatures;
    use crate::model::{JointBlock, LftMatrix};
    use nalgebra::dmatrix;
    use proptest::prelude::*;
    use structid_core::{Lft, LftMatrices, Signal};

    /// Two states, an input map feeding a map in series (z₁ = w₀ + x₂) and a latent feedback
    /// through the second: every kind of coupling the stepper has.
    /// The first block is a kernel expansion (`first` = 0), a Bouc–Wen operator (1: a state
    /// and parameters of its own) or a parametric family (2: derivatives by dual numbers).
    fn model_with(a: [f64; 4], g: f64, first: u8) -> JointModel {
        let lft = Lft::new(LftMatrices {
            a: dmatrix![a[0], a[1]; a[2], a[3]],
            bu: dmatrix![0.3; 0.0],
            be: dmatrix![0.0; 0.0],
            bw: dmatrix![1.0, 0.0; 0.0, -0.4],
            cy: dmatrix![0.0, 1.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: dmatrix![0.0, g],
            cz: dmatrix![0.0, 0.0; 0.0, 1.0],
            dzu: dmatrix![1.0; 0.0],
            dze: dmatrix![0.0; 0.0],
            dzw: dmatrix![0.0, 0.0; 0.8, 0.0],
        })
        .unwrap();
        let n0: Box<dyn crate::block::BlockMap> = match first {
            1 => {
                let bw = structid_core::BoucWen::new(0.8, 0.5, 0.6, 0.2).unwrap();
                Box::new(crate::operator::OperatorBlock::new(Box::new(bw)))
            }
            2 => {
                let law = structid_core::ParametricMap::parse(
                    "a*tanh(b*z0) + c*z0*abs(z0)",
                    1,
                    vec![("a".into(), 0.7), ("b".into(), 1.2), ("c".into(), 0.1)],
                )
                .unwrap();
                Box::new(crate::family::FamilyMap::new(law))
            }
            _ => Box::new(GaussianFeatures::on_interval(-1.0, 1.0, 4, 0.6, 1e-3).unwrap()),
        };
        let n1 = GaussianFeatures::on_interval(-2.0, 2.0, 3, 0.9, 1e-2).unwrap();
        JointModel::new(
            lft,
            vec![
                JointBlock::new("second", vec![1], 1, Box::new(n1)),
                JointBlock::new("first", vec![0], 0, n0),
            ],
        )
        .unwrap()
        .with_free_nonzero(LftMatrix::A)
        .unwrap()
        .with_free(LftMatrix::Bu, 0, 0)
        .unwrap()
        .with_free(LftMatrix::Dzw, 1, 0)
        .unwrap()
        .with_free(LftMatrix::Dyw, 0, 1)
        .unwrap()
    }

    fn data(len: usize, seed: u64) -> Data {
        let u = Signal::from_fn(len, 1, |k, _| {
            ((k as f64 * 0.31 + seed as f64).sin() + 0.5 * (k as f64 * 0.07).cos()).clamp(-1.0, 1.0)
        });
        let y = Signal::from_fn(len, 1, |k, _| (k as f64 * 0.13 + seed as f64).sin() * 0.5);
        Data::from_records(vec![
            Data::new(u.slice(0..len / 2), y.slice(0..len / 2)).unwrap(),
            Data::new(u.slice(len / 2..len), y.slice(len / 2..len)).unwrap(),
        ])
        .unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        /// The accumulated normal equations equal JᵀJ and Jᵀr of a Jacobian by central
        /// differences of the residuals, with segments, fixed and free starts and continuity.
        #[test]
        fn normal_equations_match_finite_differences(
            a0 in 0.2f64..0.7, a1 in -0.3f64..0.3, a2 in -0.3f64..0.3, a3 in 0.2f64..0.7,
            g in 0.5f64..1.5, seed in 0u64..50, theta_scale in 0.1f64..1.0, free_first: bool,
            first in 0u8..3,
        ) {
            let m = model_with([a0, a1, a2, a3], g, first);
            let d = data(60, seed);
            let mut th = m.parameters();
            let offsets = m.parameter_offsets();
            // The kernel maps' coefficients (an operator or a family keeps its parameters).
            let end = if first == 0 { th.len() } else { offsets[1] };
            for (i, v) in th.iter_mut().enumerate().take(end).skip(offsets[0]) {
                *v = theta_scale * ((i as f64) * 1.7).sin();
            }
            let m = m.with_parameters(&th).unwrap();
            let mut starts: Vec<Vec<f64>> = (0..2).map(|r| vec![0.1 * r as f64, -0.2]).collect();
            for s in &mut starts {
                s.resize(m.stacked_state_len(), 0.05);
            }
            let segs = crate::fit::test_segments(&m, &d, &starts, Some(11), free_first);
            let mut p = Shooting::new(&m, &d, segs, 1.7);
            let mut full = m.parameters();
            for s in &p.segments {
                if s.state_at.is_some() {
                    full.extend(s.fixed.iter().map(|v| v + 0.05));
                }
            }
            let r = p.residuals(&full).unwrap();
            let (jtj, jtr) = p.normal_equations(&full).unwrap();
            let h = 1e-6;
            let mut jac = DMatrix::zeros(r.len(), full.len());
            for c in 0..full.len() {
                let (mut a, mut b) = (full.clone(), full.clone());
                a[c] += h;
                b[c] -= h;
                let col = (p.residuals(&a).unwrap() - p.residuals(&b).unwrap()) / (2.0 * h);
                jac.set_column(c, &col);
            }
            let fd_jtj = jac.transpose() * &jac;
            let fd_jtr = jac.transpose() * &r;
            let scale = fd_jtj.amax().max(1.0);
            prop_assert!((&jtj - &fd_jtj).amax() < 1e-5 * scale, "JᵀJ off by {}", (&jtj - &fd_jtj).amax());
            prop_assert!((&jtr - &fd_jtr).amax() < 1e-5 * fd_jtr.amax().max(1.0), "Jᵀr off by {}", (&jtr - &fd_jtr).amax());
        }
    }
}

//! The criterion of a windowed simulation, as the fit's own.
//!
//! A plant whose free run drifts (an integrator) is scored in windows
//! ([`structid_core::validation::Windows`]): each window of a record starts from a state
//! fitted to its first half (at least `init` samples), and the samples after its first `init`
//! are scored. Fitting the model by that score makes the fit and the scoring one criterion:
//!
//! ```text
//!   min over θ of  Σ_windows Σ_(k ≥ s + init) |y_k − ŷ_k(θ, ξ̂_s(θ))|² + L·Σ_b β_b·D_b(θ_b)
//!   ξ̂_s(θ) = argmin over ξ of Σ_(k in the first half) |y_k − ŷ_k(θ, ξ)|²
//! ```
//!
//! The window states are not parameters of the outer search (a state fitted over the whole
//! window would absorb within it what the maps should explain). They are variables projected
//! out: for each θ, Gauss–Newton steps find ξ̂_s, searched for each record's first window from
//! its given start and for each later one from the state the previous window's simulation
//! reached, so that the criterion is a function of θ alone. The outer Jacobian is the scored
//! rows' total derivative, J = A_S − B_S·(B_Fᵀ B_F)⁻¹·B_Fᵀ A_F, with A and B the
//! sensitivities of ŷ to θ and to ξ on the scored (S) and fitted (F) samples (Kaufman's
//! variable projection).
//!
//! The windows, the fitted and the scored samples are the scoring's. The window state is
//! fitted through the simulation with the maps in the loop, as the scoring fits it for a model
//! beyond measurability; for a measurable model the scoring fits it linearly with the maps'
//! outputs held at the measured z, which agrees with this fit when the model fits the data,
//! not to the last digit otherwise. Settling samples are not left out.

use nalgebra::{DMatrix, DVector};
use structid_core::validation::Windows;
use structid_core::{Data, Signal};
use structid_linear::levenberg_marquardt::NormalEquationsProblem;
use structid_linear::normal_equations::NormalEquations;

use crate::error::{JointError, Result};
use crate::model::JointModel;
use crate::shooting::Regularisers;
use crate::step::Stepper;

/// Gauss–Newton steps of a window's state per evaluation (it starts from the last one).
const STATE_STEPS: usize = 8;

/// One window: its samples, the first `fitted` of them fit its state, those from `scored`
/// on are scored (absolute sample indices); `first` for the first window of a record.
#[derive(Clone, Debug)]
struct Span {
    start: usize,
    fitted: usize,
    scored: usize,
    end: usize,
    first: bool,
}

/// The windowed least-squares problem over the model's parameters.
pub(crate) struct Windowed<'a> {
    model: &'a JointModel,
    data: &'a Data,
    spans: Vec<Span>,
    /// Each record's given start, where its first window's search begins.
    starts: Vec<Vec<f64>>,
    /// Each window's state at the last evaluation.
    pub(crate) states: Vec<Vec<f64>>,
    /// The parameters `states` were projected for (LM asks for the normal equations at the θ
    /// whose residuals it has just evaluated: the projection is not repeated).
    projected_at: Option<Vec<f64>>,
    pub(crate) globals: usize,
    regularisers: Regularisers,
}

impl<'a> Windowed<'a> {
    /// The windows of every record of `data` (as [`Windows::ranges`] cuts them, each scored
    /// after min(init, its length − 1) samples, as the scoring does), each record's first
    /// window searched from its `starts`.
    pub(crate) fn new(
        model: &'a JointModel,
        data: &'a Data,
        windows: Windows,
        starts: &[Vec<f64>],
    ) -> Self {
        let bounds = data.record_bounds();
        let mut spans = Vec::new();
        for r in 0..bounds.len() - 1 {
            for (i, w) in windows
                .ranges(bounds[r + 1] - bounds[r])
                .into_iter()
                .enumerate()
            {
                let (start, end) = (bounds[r] + w.start, bounds[r] + w.end);
                let init = windows.init().min(w.len().saturating_sub(1));
                let half = (w.len() / 2).max(init);
                spans.push(Span {
                    start,
                    fitted: start + half,
                    scored: start + init,
                    end,
                    first: i == 0,
                });
            }
        }
        let states = vec![Vec::new(); spans.len()];
        Self {
            model,
            data,
            spans,
            starts: starts.to_vec(),
            states,
            projected_at: None,
            globals: *model.parameter_offsets().last().expect("non-empty"),
            regularisers: Regularisers::of(model, data),
        }
    }

    /// Each record's first window state.
    pub(crate) fn record_starts(&self) -> Vec<Vec<f64>> {
        self.spans
            .iter()
            .zip(&self.states)
            .filter(|(s, _)| s.first)
            .map(|(_, x)| x.clone())
            .collect()
    }

    /// The window's simulation from `xi` up to `end` with the sensitivities of ŷ to θ and ξ:
    /// for every sample, its residuals and rows ∂ŷ (p = globals + n_ξ columns each).
    fn sensitivities(
        &self,
        stepper: &Stepper<'_>,
        span: &Span,
        end: usize,
        xi: &[f64],
    ) -> Option<(Vec<f64>, Vec<f64>)> {
        let (ny, nxi) = (stepper.outputs(), self.model.stacked_state_len());
        let p = self.globals + nxi;
        let mut x = xi.to_vec();
        let mut t = vec![0.0; nxi * p];
        for i in 0..nxi {
            t[i * p + self.globals + i] = 1.0;
        }
        let y = self.data.y();
        let (mut res, mut rows) = (Vec::new(), Vec::new());
        stepper.run_tangent(
            self.data.u(),
            span.start..end,
            &mut x,
            &mut t,
            p,
            |k, yk, dy| {
                res.extend(y.sample(k).iter().zip(yk).map(|(m, s)| m - s));
                rows.extend_from_slice(&dy[..ny * p]);
            },
        )?;
        Some((res, rows))
    }

    /// ξ̂ of `span` from `xi`: Gauss–Newton on its fitted samples, a step halved until the
    /// fitted error falls. Directions the fitted samples do not see keep their value (a ridge
    /// of 10⁻¹⁰ of the largest curvature).
    fn window_state(&self, stepper: &Stepper<'_>, span: &Span, xi: &[f64]) -> Option<Vec<f64>> {
        let (ny, nxi) = (stepper.outputs(), self.model.stacked_state_len());
        let (p, pg) = (self.globals + nxi, self.globals);
        if nxi == 0 {
            return Some(Vec::new());
        }
        let rows_fitted = (span.fitted - span.start) * ny;
        let mut x = xi.to_vec();
        let mut cost = self.fitted_cost(stepper, span, &x)?;
        for _ in 0..STATE_STEPS {
            let (res, rows) = self.sensitivities(stepper, span, span.fitted, &x)?;
            let (mut h, mut g) = (DMatrix::zeros(nxi, nxi), DVector::zeros(nxi));
            for (i, r) in res[..rows_fitted].iter().enumerate() {
                let b = DVector::from_column_slice(&rows[i * p + pg..(i + 1) * p]);
                h += &b * b.transpose();
                g += &b * *r;
            }
            let ridge = 1e-10 * h.diagonal().max().max(f64::MIN_POSITIVE);
            h.iter_mut().step_by(nxi + 1).for_each(|d| *d += ridge);
            let step = h.cholesky()?.solve(&g);
            let mut scale = 1.0;
            let accepted = (0..10).find_map(|_| {
                let trial: Vec<f64> = x.iter().zip(&step).map(|(a, d)| a + scale * d).collect();
                scale /= 2.0;
                let c = self.fitted_cost(stepper, span, &trial)?;
                (c < cost).then_some((trial, c))
            });
            let Some((trial, c)) = accepted else { break };
            let converged = cost - c <= 1e-12 * cost;
            (x, cost) = (trial, c);
            if converged {
                break;
            }
        }
        Some(x)
    }

    fn fitted_cost(&self, stepper: &Stepper<'_>, span: &Span, xi: &[f64]) -> Option<f64> {
        let mut x = xi.to_vec();
        let y = self.data.y();
        let mut sum = 0.0;
        stepper.run(self.data.u(), span.start..span.fitted, &mut x, |k, yk| {
            sum += y
                .sample(k)
                .iter()
                .zip(yk)
                .map(|(m, s)| (m - s).powi(2))
                .sum::<f64>();
        })?;
        sum.is_finite().then_some(sum)
    }

    /// [`Self::project`] for the parameters `theta` of `stepper`'s model, unless the states
    /// are already theirs.
    fn project_at(&mut self, theta: &[f64], stepper: &Stepper<'_>) -> Option<()> {
        if self.projected_at.as_deref() == Some(theta) {
            return Some(());
        }
        self.projected_at = None;
        self.project(stepper)?;
        self.projected_at = Some(theta.to_vec());
        Some(())
    }

    /// Every window's state for the model of `stepper`: a function of the parameters alone.
    /// Each record's first window is searched from the record's given start, each later one
    /// from the state the previous window's simulation reached (as the scoring of a model
    /// beyond measurability searches it).
    fn project(&mut self, stepper: &Stepper<'_>) -> Option<()> {
        let mut record = 0;
        let mut reached: Vec<f64> = Vec::new();
        for i in 0..self.spans.len() {
            let span = &self.spans[i];
            let from = if span.first {
                record += 1;
                self.starts[record - 1].clone()
            } else {
                reached.clone()
            };
            let x = self.window_state(stepper, span, &from)?;
            reached = x.clone();
            stepper.run(self.data.u(), span.start..span.end, &mut reached, |_, _| {})?;
            self.states[i] = x;
        }
        Some(())
    }
}

impl Windowed<'_> {
    /// The RMS per output of `model` (the problem's with the parameters of the last
    /// evaluation) over the scored samples, from the window states of that evaluation.
    pub(crate) fn scored_rms(&self, model: &JointModel) -> Result<Vec<f64>> {
        Ok(self.simulation(&Stepper::new(model))?.rms)
    }

    /// The simulation at the window states of the last evaluation (see [`simulate_windows`]).
    fn simulation(&self, stepper: &Stepper<'_>) -> Result<WindowedSimulation> {
        let (len, ny) = (self.data.len(), stepper.outputs());
        let nz = self.model.lft().dims().z;
        let (mut y, mut z) = (Signal::zeros(len, ny), Signal::zeros(len, nz));
        let (mut sum, mut count) = (vec![0.0; ny], 0usize);
        for (span, xi) in self.spans.iter().zip(&self.states) {
            let u = self.data.u().slice(span.start..span.end);
            let sim = stepper.simulate(&u, None, xi)?;
            for k in 0..u.len() {
                let at = span.start + k;
                y.sample_mut(at).copy_from_slice(sim.y.sample(k));
                z.sample_mut(at).copy_from_slice(sim.z.sample(k));
                if at >= span.scored {
                    count += 1;
                    for (c, s) in sum.iter_mut().enumerate() {
                        *s += (self.data.y().sample(at)[c] - sim.y.sample(k)[c]).powi(2);
                    }
                }
            }
        }
        let rms = sum
            .iter()
            .map(|s| (s / count.max(1) as f64).sqrt())
            .collect();
        Ok(WindowedSimulation { y, z, rms })
    }
}

/// A model's simulation in windows: ŷ and z at every sample of every record (stacked), each
/// window from the state fitted to its first half, and the RMS of y − ŷ per output over the
/// scored samples (those after each window's first `init`).
#[derive(Clone, Debug)]
pub struct WindowedSimulation {
    /// ŷ, L × n_y.
    pub y: Signal,
    /// z, L × n_z.
    pub z: Signal,
    /// RMS of y − ŷ per output over the scored samples.
    pub rms: Vec<f64>,
}

/// `model` simulated on `data` in `windows`, each record's first window searched from rest:
/// how a model fitted by the windowed criterion is scored and where its maps' inputs go.
///
/// ```
/// use nalgebra::dmatrix;
/// use structid_core::validation::Windows;
/// use structid_core::{Data, Lft, LftMatrices, Signal};
/// use structid_joint::{FixedMap, JointBlock, JointModel};
/// use structid_joint::windowed::simulate_windows;
/// // An integrator behind tanh: its own output is simulated exactly in every window.
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![1.0], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![0.1],
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
/// }).unwrap();
/// let n = FixedMap::new(std::sync::Arc::new(|z: &[f64]| z[0].tanh()), 1);
/// let model = JointModel::new(lft, vec![JointBlock::new("N", vec![0], 0, Box::new(n))]).unwrap();
/// let u = Signal::from_fn(300, 1, |k, _| (0.05 * k as f64).sin());
/// let y = model.simulate(&u, Some(&[3.0])).unwrap().y;
/// let s = simulate_windows(&model, &Data::new(u, y).unwrap(), Windows::new(100, 10).unwrap()).unwrap();
/// assert!(s.rms[0] < 1e-8);
/// ```
///
/// # Errors
/// [`JointError::NoStart`] when a window's simulation diverges; a record whose channels do
/// not match the model.
pub fn simulate_windows(
    model: &JointModel,
    data: &Data,
    windows: Windows,
) -> Result<WindowedSimulation> {
    let bounds = data.record_bounds();
    let starts = (0..bounds.len() - 1)
        .map(|r| model.rest_state(data.u().sample(bounds[r]), None))
        .collect::<Result<Vec<_>>>()?;
    let mut problem = Windowed::new(model, data, windows, &starts);
    let stepper = Stepper::new(model);
    problem
        .project(&stepper)
        .ok_or_else(|| JointError::NoStart {
            record: 1,
            detail: "a window's simulation diverged".into(),
        })?;
    problem.simulation(&stepper)
}

impl NormalEquationsProblem for Windowed<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        let model = self.model.with_parameters(&theta[..self.globals]).ok()?;
        let stepper = Stepper::new(&model);
        self.project_at(&theta[..self.globals], &stepper)?;
        let y = self.data.y();
        let mut r = Vec::new();
        for (span, xi) in self.spans.iter().zip(&self.states) {
            let mut x = xi.clone();
            stepper.run(self.data.u(), span.start..span.end, &mut x, |k, yk| {
                if k >= span.scored {
                    r.extend(y.sample(k).iter().zip(yk).map(|(m, s)| m - s));
                }
            })?;
        }
        self.regularisers.residuals(theta, r)
    }

    /// Accumulated window by window.
    fn normal_equations(&mut self, theta: &[f64]) -> Option<(DMatrix<f64>, DVector<f64>)> {
        let model = self.model.with_parameters(&theta[..self.globals]).ok()?;
        let stepper = Stepper::new(&model);
        self.project_at(&theta[..self.globals], &stepper)?;
        let (ny, nxi, pg) = (stepper.outputs(), model.stacked_state_len(), self.globals);
        let p = pg + nxi;
        let mut normal = NormalEquations::new(pg);
        for (span, xi) in self.spans.iter().zip(&self.states) {
            let (res, rows) = self.sensitivities(&stepper, span, span.end, xi)?;
            let row = |i: usize| DMatrix::from_row_slice(1, p, &rows[i * p..(i + 1) * p]);
            // dξ̂/dθ = −(B_FᵀB_F)⁻¹·B_FᵀA_F on the fitted samples.
            let (mut bb, mut ba) = (DMatrix::zeros(nxi, nxi), DMatrix::zeros(nxi, pg));
            for i in 0..(span.fitted - span.start) * ny {
                let rw = row(i);
                let (a, b) = (rw.columns(0, pg), rw.columns(pg, nxi));
                bb += b.transpose() * b;
                ba += b.transpose() * a;
            }
            let ridge = 1e-10 * bb.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            bb.iter_mut()
                .step_by(nxi + 1)
                .for_each(|d| *d += ridge.max(f64::MIN_POSITIVE));
            let dxi = match nxi {
                0 => DMatrix::zeros(0, pg),
                _ => -bb.cholesky()?.solve(&ba),
            };
            for i in (span.scored - span.start) * ny..(span.end - span.start) * ny {
                let rw = row(i);
                let total = rw.columns(0, pg) + rw.columns(pg, nxi) * &dxi;
                // J row = −dŷ/dθ; the sign cancels in JᵀJ and flips Jᵀr.
                normal.add_row(total.as_slice(), -res[i]);
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

    /// Two states and one kernel map in feedback from the first, its coefficients scaled by
    /// `bend` (0: the map is its affine trend, and ŷ is affine in the state).
    fn model(a: [f64; 2], bend: f64) -> JointModel {
        let lft = Lft::new(LftMatrices {
            a: dmatrix![a[0], 0.2; -0.1, a[1]],
            bu: dmatrix![0.4; 0.1],
            be: dmatrix![0.0; 0.0],
            bw: dmatrix![-0.3; 0.0],
            cy: dmatrix![1.0, 0.5],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: dmatrix![0.0],
            cz: dmatrix![1.0, 0.0],
            dzu: dmatrix![0.0],
            dze: dmatrix![0.0],
            dzw: dmatrix![0.0],
        })
        .unwrap();
        let map = GaussianFeatures::on_interval(-2.0, 2.0, 4, 0.8, 1e-4).unwrap();
        let m = JointModel::new(lft, vec![JointBlock::new("N", vec![0], 0, Box::new(map))])
            .unwrap()
            .with_free(LftMatrix::A, 0, 0)
            .unwrap();
        let mut th = m.parameters();
        for (i, v) in th.iter_mut().enumerate().skip(1).take(4) {
            *v = bend * (1.3 * i as f64).sin();
        }
        // the trend a₀ + a₁z
        let n = th.len();
        th[n - 2] = 0.05;
        th[n - 1] = 0.4;
        m.with_parameters(&th).unwrap()
    }

    fn records(m: &JointModel, seed: u64, noise: f64) -> Data {
        let rec = |len: usize, shift: u64| {
            let u = Signal::from_fn(len, 1, |k, _| {
                ((k as f64 * 0.37 + (seed + shift) as f64).sin() + 0.4 * (k as f64 * 0.11).cos())
                    .clamp(-1.0, 1.0)
            });
            let x0 = [0.3, -0.2];
            let mut y = m.simulate(&u, Some(&x0)).unwrap().y;
            for k in 0..len {
                y.sample_mut(k)[0] += noise * ((k as f64 * 2.9 + seed as f64).sin());
            }
            Data::new(u, y).unwrap()
        };
        Data::from_records(vec![rec(60, 0), rec(47, 5)]).unwrap()
    }

    /// With an affine map, ŷ is affine in a window's state: the state fitted to the first half
    /// by dense least squares and the scored residuals after `init` match the problem's.
    #[test]
    fn residuals_match_a_dense_least_squares_window_state() {
        let m = model([0.7, 0.5], 0.0);
        let d = records(&model([0.75, 0.5], 0.0), 3, 0.05);
        let w = Windows::new(20, 4).unwrap();
        let starts = vec![vec![0.0, 0.0]; 2];
        let mut p = Windowed::new(&m, &d, w, &starts);
        let r = p.residuals(&m.parameters()).unwrap();
        let stepper = Stepper::new(&m);
        let mut expected = Vec::new();
        for data in d.records() {
            for win in w.ranges(data.len()) {
                let u = data.u().slice(win.clone());
                let y = data.y().slice(win.clone());
                let sim = |x: &[f64]| {
                    let mut xi = x.to_vec();
                    let mut out = Vec::new();
                    stepper
                        .run(&u, 0..u.len(), &mut xi, |_, yk| out.push(yk[0]))
                        .unwrap();
                    DVector::from_vec(out)
                };
                let base = sim(&[0.0, 0.0]);
                let o =
                    DMatrix::from_columns(&[sim(&[1.0, 0.0]) - &base, sim(&[0.0, 1.0]) - &base]);
                let half = (win.len() / 2).max(w.init());
                let target =
                    DVector::from_iterator(half, (0..half).map(|k| y.sample(k)[0] - base[k]));
                let of = o.rows(0, half).clone_owned();
                let xi = (of.transpose() * &of)
                    .cholesky()
                    .unwrap()
                    .solve(&(of.transpose() * target));
                let fit = &base + &o * xi;
                expected.extend((w.init()..win.len()).map(|k| y.sample(k)[0] - fit[k]));
            }
        }
        let scored = expected.len();
        let got: Vec<f64> = r.iter().take(scored).copied().collect();
        let gap = got
            .iter()
            .zip(&expected)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(gap < 1e-8, "largest difference {gap}");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(12))]
        /// On records the model itself produced (every window's fitted error zero at its
        /// state), the variable-projection JᵀJ equals that of a Jacobian by central
        /// differences of the residuals with the window states projected out.
        #[test]
        fn normal_equations_match_finite_differences_on_the_model_s_records(
            a0 in 0.3f64..0.8, a1 in 0.2f64..0.7, bend in 0.0f64..1.0, seed in 0u64..40,
        ) {
            let m = model([a0, a1], bend);
            let d = records(&m, seed, 0.0);
            let w = Windows::new(25, 5).unwrap();
            let starts = vec![vec![0.0, 0.0]; 2];
            let mut p = Windowed::new(&m, &d, w, &starts);
            let th = m.parameters();
            let r = p.residuals(&th).unwrap();
            let (jtj, _) = p.normal_equations(&th).unwrap();
            let h = 1e-6;
            let mut jac = DMatrix::zeros(r.len(), th.len());
            for c in 0..th.len() {
                let (mut a, mut b) = (th.clone(), th.clone());
                a[c] += h;
                b[c] -= h;
                let col = (p.residuals(&a).unwrap() - p.residuals(&b).unwrap()) / (2.0 * h);
                jac.set_column(c, &col);
            }
            let fd = jac.transpose() * &jac;
            let scale = fd.amax().max(1.0);
            prop_assert!((&jtj - &fd).amax() < 1e-4 * scale, "JᵀJ off by {} of {scale}", (&jtj - &fd).amax());
        }
    }

    /// The criterion is a function of θ alone: evaluated at θ₁, then far away, then at θ₁
    /// again, it gives the same residuals to the last bit.
    #[test]
    fn the_criterion_does_not_depend_on_the_evaluations_before() {
        let m = model([0.7, 0.5], 0.6);
        let d = records(&model([0.75, 0.5], 0.9), 2, 0.02);
        let w = Windows::new(25, 5).unwrap();
        let mut p = Windowed::new(&m, &d, w, &[vec![0.0, 0.0], vec![0.0, 0.0]]);
        let th = m.parameters();
        let far: Vec<f64> = th
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.3 * (i as f64).cos())
            .collect();
        let first = p.residuals(&th).unwrap();
        p.residuals(&far).unwrap();
        assert_eq!(p.residuals(&th).unwrap(), first);
    }

    /// The fit by the windowed criterion ends no higher than it starts, and from a wrong
    /// pole and a flat map on the model's own records it removes nearly all of the error.
    #[test]
    fn the_windowed_fit_recovers_the_model_s_records() {
        let truth = model([0.75, 0.5], 0.8);
        let d = records(&truth, 7, 0.0);
        let start = model([0.5, 0.5], 0.0);
        let w = Windows::new(25, 5).unwrap();
        let s = crate::JointSettings::builder()
            .polish(false)
            .windows(w)
            .build()
            .unwrap();
        let f = crate::fit(&start, &d, None, &s).unwrap();
        assert!(f.cost <= f.initial_cost);
        assert!(
            f.cost < 1e-3 * f.initial_cost,
            "{} → {}",
            f.initial_cost,
            f.cost
        );
        assert_eq!(f.initial_states.len(), 2);
        assert!(
            crate::JointSettings::builder()
                .segment_length(25)
                .windows(w)
                .build()
                .is_err()
        );
    }
}

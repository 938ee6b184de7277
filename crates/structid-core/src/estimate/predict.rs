//! k-step-ahead prediction ŷ_(t∣t−k) with the maps in the loop.
//!
//! The one-step predictor of [`crate::validation`] uses the measured z (computed from u and y,
//! which is what measurability means) to know ŵ = N̂(z) at every sample, and the Kalman
//! predictor of the noise path H = L_ye for the part of y that the past explains. The k-step
//! predictor extends it. With the state split as x = x_det + ξ, where x_det is driven by u,
//! ŵ and x̂₀ and ξ by e:
//!
//! 1. x̂_(s+1∣s) = x_det(s+1) + ξ̂_(s+1∣s): the deterministic state from the measured ŵ and the
//!    Kalman predictor's state of the noise path, given y_0 … y_s.
//! 2. From there the model runs k − 1 more steps with e = 0 and the maps in the loop: z is then
//!    computed from the predicted signals, since y after s is not known.
//!
//! The measured z_(s+1) is used at the first step, as the one-step predictor uses z_t when it
//! predicts y_t. So k = 1 is exactly [`crate::validate`]'s predictor
//! (ŷ = y − ε), and for k > L (and, when the maps do not feed y directly, for k = L) no output
//! is used and the prediction is the simulation from x̂₀. Cost: O(L·min(k, L)) model steps.

use serde::{Deserialize, Serialize};
use structid_lti::Signal;

use crate::error::{Error, Result};
use crate::initial_state::InitialState;
use crate::model::interpolant::Interpolant;
use crate::model::{Data, Model};
use crate::validation::metrics::{fit_percent, rms_difference};
use crate::validation::{check_record, measured_residual};

/// Settings of [`predict`]; build them with [`PredictionSettings::builder`].
///
/// ```
/// use structid_core::estimate::PredictionSettings;
/// let s = PredictionSettings::builder().horizon(5).build().unwrap();
/// assert_eq!(s.horizon(), 5);
/// assert!(PredictionSettings::builder().horizon(0).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PredictionSettings {
    horizon: usize,
    initial_state: InitialState,
    settle: usize,
}

impl Default for PredictionSettings {
    /// One step ahead, a record at rest, every sample scored.
    fn default() -> Self {
        Self {
            horizon: 1,
            initial_state: InitialState::Zero,
            settle: 0,
        }
    }
}

impl PredictionSettings {
    /// A builder starting from the defaults.
    pub fn builder() -> PredictionSettingsBuilder {
        PredictionSettingsBuilder(Self::default())
    }

    /// The horizon k ≥ 1.
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// How the initial state is treated (as in [`crate::validate`]).
    pub fn initial_state(&self) -> InitialState {
        self.initial_state
    }

    /// Leading samples left out of the RMS and fit.
    pub fn settle(&self) -> usize {
        self.settle
    }
}

/// Builder for [`PredictionSettings`]; [`PredictionSettingsBuilder::build`] validates.
#[derive(Clone, Debug)]
pub struct PredictionSettingsBuilder(PredictionSettings);

impl PredictionSettingsBuilder {
    /// The horizon k ≥ 1 (default 1).
    pub fn horizon(mut self, k: usize) -> Self {
        self.0.horizon = k;
        self
    }

    /// Zero or estimated initial state (default zero).
    pub fn initial_state(mut self, initial_state: InitialState) -> Self {
        self.0.initial_state = initial_state;
        self
    }

    /// Leading samples left out of the RMS and fit (default 0).
    pub fn settle(mut self, samples: usize) -> Self {
        self.0.settle = samples;
        self
    }

    /// Validates and returns the settings.
    pub fn build(self) -> Result<PredictionSettings> {
        if self.0.horizon == 0 {
            return Err(Error::InvalidParameter {
                name: "horizon".into(),
                value: 0.0,
                reason: "must be at least 1 (k = 1 is one step ahead)".into(),
            });
        }
        Ok(self.0)
    }
}

/// What [`predict`] computed.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// The horizon k.
    pub horizon: usize,
    /// ŷ_(t∣t−k), L × n_y.
    pub predicted: Signal,
    /// Per output: RMS(y − ŷ) over the samples after the settling ones.
    pub rms: Vec<f64>,
    /// Per output: the fit 100·(1 − ‖y − ŷ‖/‖y − mean y‖) in percent (NaN for a constant
    /// output).
    pub fit_percent: Vec<f64>,
    /// x̂₀, when estimated.
    pub initial_state: Option<Vec<f64>>,
}

/// Small row-major matrices of the LFT for stepping it one sample at a time.
struct Stepper {
    n: usize,
    nu: usize,
    nw: usize,
    ny: usize,
    nz: usize,
    a: Vec<f64>,
    bu: Vec<f64>,
    bw: Vec<f64>,
    cy: Vec<f64>,
    dyu: Vec<f64>,
    dyw: Vec<f64>,
    cz: Vec<f64>,
    dzu: Vec<f64>,
    dzw: Vec<f64>,
}

fn rows(m: &nalgebra::DMatrix<f64>) -> Vec<f64> {
    let (r, c) = m.shape();
    (0..r * c).map(|i| m[(i / c, i % c)]).collect()
}

/// out = M·x + out for a row-major M.
fn gemv(m: &[f64], x: &[f64], out: &mut [f64]) {
    if x.is_empty() {
        return;
    }
    for (o, row) in out.iter_mut().zip(m.chunks_exact(x.len())) {
        *o += row.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
    }
}

impl Stepper {
    /// z = C_z·x + D_zu·u (e = 0 in a simulation; the maps' same-sample terms D_zw·w are
    /// added block by block, in evaluation order).
    fn z(&self, x: &[f64], u: &[f64], z: &mut [f64]) {
        z.fill(0.0);
        gemv(&self.cz, x, z);
        gemv(&self.dzu, u, z);
    }

    /// y = C_y·x + D_yu·u + D_yw·w.
    fn y(&self, x: &[f64], u: &[f64], w: &[f64], y: &mut [f64]) {
        y.fill(0.0);
        gemv(&self.cy, x, y);
        gemv(&self.dyu, u, y);
        gemv(&self.dyw, w, y);
    }

    /// x ← A·x + B_u·u + B_w·w.
    fn advance(&self, x: &mut Vec<f64>, u: &[f64], w: &[f64], tmp: &mut Vec<f64>) {
        tmp.clear();
        tmp.resize(self.n, 0.0);
        gemv(&self.a, x, tmp);
        gemv(&self.bu, u, tmp);
        gemv(&self.bw, w, tmp);
        std::mem::swap(x, tmp);
    }
}

/// ŷ_(t∣t−k) for `model` with `maps` (one per block, in block order) on `data`; see the
/// [module documentation](self).
///
/// # Errors
/// [`Error::DimensionMismatch`] for a wrong number of maps or channels,
/// [`Error::AlgebraicLoop`] for a cycle of maps, [`Error::NotMeasurable`] when z cannot be
/// computed from the record (maps in series are evaluated in order; a latent block has no z), [`Error::InvalidParameter`] when `settle` is not less than the record
/// length, [`Error::Numerical`] when a map returns a non-finite value or the prediction
/// diverges.
pub fn predict(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    settings: &PredictionSettings,
) -> Result<Prediction> {
    check_record(model, maps, data, settings.settle, "prediction")?;
    let lft = model.lft();
    let order = model.evaluation_order()?;
    let blocks = model.blocks();
    let len = data.len();
    let m = lft.matrices();
    let d = lft.dims();
    let st = Stepper {
        n: d.states,
        nu: d.u,
        nw: d.w,
        ny: d.y,
        nz: d.z,
        a: rows(&m.a),
        bu: rows(&m.bu),
        bw: rows(&m.bw),
        cy: rows(&m.cy),
        dyu: rows(&m.dyu),
        dyw: rows(&m.dyw),
        cz: rows(&m.cz),
        dzu: rows(&m.dzu),
        dzw: rows(&m.dzw),
    };
    let meas = measured_residual(model, maps, data, settings.initial_state)?;
    let n = st.n;
    // ξ̂_(t∣t−1) of the noise path, in the LFT's state coordinates (L_ye shares A).
    let mut xi = vec![0.0; len * n];
    if let (Some(w), true) = (&meas.whitener, meas.dynamic_noise) {
        let mut eps = vec![0.0; len * st.ny];
        w.predicted_states(&meas.v, &mut eps, &mut xi);
    }
    let x0: Vec<f64> = meas
        .x0
        .clone()
        .filter(|x| x.len() == n)
        .unwrap_or_else(|| vec![0.0; n]);
    // x_det(t) driven by u and the measured ŵ.
    let mut x_det = vec![0.0; (len + 1) * n];
    x_det[..n].copy_from_slice(&x0);
    let mut x = x0.clone();
    let mut tmp = Vec::with_capacity(n);
    for t in 0..len {
        st.advance(&mut x, data.u().sample(t), meas.w_hat.sample(t), &mut tmp);
        x_det[(t + 1) * n..(t + 2) * n].copy_from_slice(&x);
    }

    let k = settings.horizon;
    // In evaluation order: a map in series reads, through D_zw, outputs already computed in
    // this sample (its D_zw row is zero in the columns of the blocks still to come).
    let bindings: Vec<(&[usize], usize, &dyn Interpolant)> = order
        .iter()
        .map(|&b| (blocks[b].inputs.as_slice(), blocks[b].output, maps[b]))
        .collect();
    let (mut z, mut w, mut zin) = (vec![0.0; st.nz], vec![0.0; st.nw], Vec::new());
    let mut eval_maps = |x: &[f64], u: &[f64], w: &mut [f64]| {
        st.z(x, u, &mut z);
        for &(inputs, output, map) in &bindings {
            zin.clear();
            zin.extend(inputs.iter().map(|&i| {
                let series: f64 = (0..st.nw).map(|j| st.dzw[i * st.nw + j] * w[j]).sum();
                z[i] + series
            }));
            w[output] = map.eval(&zin);
        }
    };
    let mut predicted = vec![0.0; len * st.ny];
    // Targets whose window starts before the record (s + 1 < 0) share one free simulation.
    let free_until = (k.saturating_sub(1)).min(len);
    {
        let mut x = x0.clone();
        for t in 0..free_until {
            let u = data.u().sample(t);
            eval_maps(&x, u, &mut w);
            st.y(&x, u, &w, &mut predicted[t * st.ny..(t + 1) * st.ny]);
            st.advance(&mut x, u, &w, &mut tmp);
        }
    }
    for t in free_until..len {
        let start = t + 1 - k; // s + 1 ≥ 0
        let mut x: Vec<f64> = (0..n)
            .map(|i| x_det[start * n + i] + xi[start * n + i])
            .collect();
        for j in start..=t {
            let u = data.u().sample(j);
            if j == start {
                w.copy_from_slice(meas.w_hat.sample(j));
            } else {
                eval_maps(&x, u, &mut w);
            }
            if j == t {
                st.y(&x, u, &w, &mut predicted[t * st.ny..(t + 1) * st.ny]);
            } else {
                st.advance(&mut x, u, &w, &mut tmp);
            }
        }
    }
    if let Some(i) = predicted.iter().position(|v| !v.is_finite()) {
        return Err(Error::Numerical(format!(
            "the {k}-step prediction diverged (output {} is not finite at sample {})",
            i % st.ny,
            i / st.ny
        )));
    }
    let predicted = Signal::new(st.ny, predicted)?;
    let s = settings.settle;
    let (mut rms, mut fit) = (Vec::new(), Vec::new());
    for c in 0..st.ny {
        let (y, p) = (data.y().channel(c), predicted.channel(c));
        rms.push(rms_difference(&y[s..], &p[s..]));
        let f = fit_percent(&y[s..], &p[s..]);
        fit.push(if f.is_finite() { f } else { f64::NAN });
    }
    let _ = st.nu;
    Ok(Prediction {
        horizon: k,
        predicted,
        rms,
        fit_percent: fit,
        initial_state: meas.x0,
    })
}

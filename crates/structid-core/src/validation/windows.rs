//! Scoring a model by simulation: over the whole record, or over windows that each start from
//! a state estimated on their first half.
//!
//! A free-run simulation from one x̂₀ means nothing for a plant with poles on the unit circle
//! (an integrating axis, a double integrator): any force offset or small error in the first
//! state makes the simulation drift without bound, and its RMS measures the drift, not the
//! model. The benchmarks' answer is an *initialisation window*: the state is estimated and
//! the simulation scored after the first samples. [`Windows`] applies it throughout a record:
//! the record is cut into consecutive windows of `length` samples (the last one takes the
//! remainder); in each, the state x̂_s at its first sample s is fitted to the first half of
//! the window (at least `init` samples), the model is simulated over the window from x̂_s with
//! the maps in the loop, and the samples after the first `init` are scored.
//!
//! Why half the window: a state fitted to a few noisy samples carries their noise through the
//! window (an integrator turns a velocity error into a drift of order σ·L/n^1.5 over L samples
//! from n), which inflates the window's RMS and colours its residual, so that the residual
//! tests take the exact model for a wrong one; a state fitted to the whole window absorbs much
//! of what a missing effect does within it (a force offset's drift is nearly a free response
//! over a short window). Half the window keeps the first small and the second visible.
//!
//! **The window's state.** With the maps' outputs fixed at their values at the measured z,
//! ŵ = N̂(z), the LFT is linear in its state, and over the fitted samples of a window
//!
//! ```text
//!   y_k = (O_y·x_s)_k + (L_yu·u + L_yw·ŵ)_k + noise,    z_k = (O_z·x_s)_k + (L_zu·u + L_zw·ŵ)_k
//! ```
//!
//! (O the free responses of the unit states over the window, the forced parts from a zero
//! state at s). x̂_s is fitted to y by least squares first; the directions of x_s that y does
//! not see with ŵ fixed (a rate's memory of the previous output, the deterministic copy of a
//! sensor model) are then fitted to the measured z, which is a function of u and y (see
//! [`crate::Lft::measurability`]). A direction that neither sees keeps the value 0: it reaches
//! nothing the simulation scores. [`state_from_record`] is this estimate on any record slice.
//!
//! **Beyond measurability** (maps in series, a sensor map ahead of which z is reached only
//! through the map's inverse, a map of an unmeasured state) there is no measured z to fix ŵ
//! at, and the state reaches y only through the maps. Each window's state is then fitted to y
//! over the same samples by nonlinear least squares through the simulation with the maps in
//! the loop, searched from the state the previous window's simulation reached (module
//! `simulated_state`); the directions y does not see keep that value.
//!
//! [`simulate_scored`] is the one simulation that [`crate::validate`], prediction's fallback and
//! the discovery workflow score models with; [`ScoredSimulation::rms`] is its RMS over the scored
//! samples.

use std::ops::Range;

use nalgebra::{DMatrix, DVector};
use structid_lti::Signal;

use crate::error::{Error, Result};
use crate::model::interpolant::Interpolant;
use crate::model::{Data, Model};
use crate::validation::metrics::fit_percent;
use crate::validation::simulated_state::simulated_window_state;

/// Windows of a windowed simulation: `length` samples each, the state fitted on the first
/// half of them (at least `init`) and all but the first `init` scored. Build with [`Windows::new`] or [`Windows::for_record`].
///
/// ```
/// use structid_core::validation::Windows;
/// let w = Windows::new(200, 20).unwrap();
/// assert_eq!((w.length(), w.init()), (200, 20));
/// assert_eq!(w.ranges(450), vec![0..200, 200..450]);
/// assert!(Windows::new(20, 20).is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Windows {
    length: usize,
    init: usize,
}

impl Windows {
    /// Windows of `length` samples whose first `init` samples are not scored (1 ≤ `init` <
    /// `length`).
    pub fn new(length: usize, init: usize) -> Result<Self> {
        if init == 0 || init >= length {
            return Err(Error::InvalidParameter {
                name: "windows".into(),
                value: init as f64,
                reason: format!(
                    "the initialisation samples ({init}) must be at least 1 and fewer than the \
                     window length ({length}), so that each window scores some samples"
                ),
            });
        }
        Ok(Self { length, init })
    }

    /// The default windows for a record of `len` samples and a model of `states` states: the
    /// first max(4·states, 25) samples of each not scored, windows of max(len/20, 8·init) samples (at
    /// most the record), so that a record gives about twenty windows and each scores most of
    /// its samples.
    ///
    /// ```
    /// use structid_core::validation::Windows;
    /// let w = Windows::for_record(4000, 3);
    /// assert_eq!((w.length(), w.init()), (200, 25));
    /// ```
    pub fn for_record(len: usize, states: usize) -> Self {
        let init = (4 * states).max(25);
        let length = (len / 20).max(8 * init).min(len.max(init + 1));
        Self {
            length,
            init: init.min(length.saturating_sub(1)).max(1),
        }
    }

    /// Samples per window.
    pub fn length(&self) -> usize {
        self.length
    }

    /// Samples at the start of each window that are not scored.
    pub fn init(&self) -> usize {
        self.init
    }

    /// The windows of a record of `len` samples: consecutive, `length` long, the last one
    /// taking the remainder (so it is between `length` and 2·`length` − 1 long); one window
    /// when the record is shorter.
    pub fn ranges(&self, len: usize) -> Vec<Range<usize>> {
        let count = (len / self.length).max(1);
        (0..count)
            .map(|i| {
                let start = i * self.length;
                let end = if i + 1 == count {
                    len
                } else {
                    start + self.length
                };
                start..end
            })
            .collect()
    }
}

/// How a simulation is scored: one run over the record, or windows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Scoring {
    /// One simulation from x₀ (zero or estimated, see [`crate::InitialState`]), scored after the
    /// settling samples.
    #[default]
    Free,
    /// Consecutive windows, each from a state fitted to its first half (see the
    /// [module documentation](self)).
    Windowed(Windows),
}

impl Scoring {
    /// A short description for reports, e.g. `free-run simulation` or `windowed simulation
    /// (windows of 200 samples, each from a state fitted on its first half, scored after its
    /// first 25)`.
    pub fn describe(&self) -> String {
        match self {
            Scoring::Free => "free-run simulation".into(),
            Scoring::Windowed(w) => format!(
                "windowed simulation (windows of {} samples, each from a state fitted on its first \
                 half, scored after its first {})",
                w.length, w.init
            ),
        }
    }
}

/// A simulation with the maps in the loop and the samples it is scored on.
#[derive(Clone, Debug, PartialEq)]
pub struct ScoredSimulation {
    /// The simulated output, L × n_y (in windowed scoring, each window from its own state).
    pub simulated: Signal,
    /// The scored sample ranges.
    pub scored: Vec<Range<usize>>,
    /// The state each segment started from (one per window; one for a free run, `None` inside
    /// when it started at rest).
    pub states: Vec<Option<Vec<f64>>>,
}

impl ScoredSimulation {
    /// RMS of y − ŷ over the scored samples, output `c`.
    pub fn rms(&self, y: &Signal, c: usize) -> f64 {
        let (mut sum, mut n) = (0.0, 0usize);
        for r in &self.scored {
            for k in r.clone() {
                let d = y.get(k, c) - self.simulated.get(k, c);
                sum += d * d;
                n += 1;
            }
        }
        if n == 0 {
            f64::NAN
        } else {
            (sum / n as f64).sqrt()
        }
    }

    /// MATLAB's `compare` fit in percent over the scored samples, output `c`.
    pub fn fit_percent(&self, y: &Signal, c: usize) -> f64 {
        let (mut measured, mut simulated) = (Vec::new(), Vec::new());
        for r in &self.scored {
            for k in r.clone() {
                measured.push(y.get(k, c));
                simulated.push(self.simulated.get(k, c));
            }
        }
        let f = fit_percent(&measured, &simulated);
        if f.is_finite() { f } else { f64::NAN }
    }

    /// The residual y − ŷ at the scored samples (in time order), output `c`.
    pub fn scored_residual(&self, y: &Signal, c: usize) -> Vec<f64> {
        self.scored
            .iter()
            .flat_map(|r| r.clone())
            .map(|k| y.get(k, c) - self.simulated.get(k, c))
            .collect()
    }
}

/// The measured z of `data` for `model`: the data's own z columns, or z computed from u and y,
/// with `maps` evaluated in order where blocks are in series ([`Model::compute_z_with_maps`]).
pub(crate) fn measured_z(model: &Model, maps: &[&dyn Interpolant], data: &Data) -> Result<Signal> {
    match data.z() {
        Some(z) => Ok(z.clone()),
        None if model.lft().dims().z == 0 => Ok(Signal::zeros(data.len(), 0)),
        None => model.compute_z_with_maps(data.u(), data.y(), maps),
    }
}

/// ŵ = N̂(z) at the measured z, L × n_w (the maps' outputs with the loop opened).
pub(crate) fn opened_w(model: &Model, maps: &[&dyn Interpolant], z: &Signal) -> Result<Signal> {
    let nw = model.lft().dims().w;
    let mut w = Signal::zeros(z.len(), nw);
    for (block, map) in model.blocks().iter().zip(maps) {
        let zb = z.select_channels(&block.inputs);
        let values = map.eval_many(&zb);
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            return Err(Error::Numerical(format!(
                "the map of block `{}` returned {} at sample {k} (z = {:?})",
                block.name,
                values[k],
                zb.sample(k)
            )));
        }
        for (k, v) in values.iter().enumerate() {
            w.sample_mut(k)[block.output] = *v;
        }
    }
    Ok(w)
}

/// The state at the first sample of `range` (see the [module documentation](self)): fitted to y
/// over the range's samples by least squares with the maps' outputs `w` fixed, then, in the
/// directions y does not see, to the measured `z`.
///
/// With `from_y` given, that is taken as the fit to y (e.g. the record's GLS estimate) and only
/// the directions y does not see are fitted to z.
pub(crate) fn window_state(
    model: &Model,
    data: &Data,
    z: &Signal,
    w: &Signal,
    range: Range<usize>,
    from_y: Option<&[f64]>,
) -> Result<Vec<f64>> {
    let lft = model.lft();
    let d = lft.dims();
    let n = d.states;
    if n == 0 {
        return Ok(Vec::new());
    }
    let len = range.len();
    let sys = lft.state_space();
    // Inputs [u; e = 0; w], outputs [y; z].
    let inputs = Signal::from_fn(len, d.u + d.e + d.w, |k, c| {
        let t = range.start + k;
        if c < d.u {
            data.u().get(t, c)
        } else if c < d.u + d.e {
            0.0
        } else {
            w.get(t, c - d.u - d.e)
        }
    });
    let (forced, _) = sys.simulate_from(&vec![0.0; n], &inputs)?;
    let none = Signal::zeros(len, d.u + d.e + d.w);
    let mut oy = DMatrix::zeros(len * d.y, n);
    let mut oz = DMatrix::zeros(len * d.z, n);
    for j in 0..n {
        let mut x = vec![0.0; n];
        x[j] = 1.0;
        let (free, _) = sys.simulate_from(&x, &none)?;
        for k in 0..len {
            let s = free.sample(k);
            for c in 0..d.y {
                oy[(k * d.y + c, j)] = s[c];
            }
            for c in 0..d.z {
                oz[(k * d.z + c, j)] = s[d.y + c];
            }
        }
    }
    let vy = DVector::from_fn(len * d.y, |i, _| {
        let (k, c) = (i / d.y, i % d.y);
        data.y().get(range.start + k, c) - forced.get(k, c)
    });
    if oy.iter().chain(vy.iter()).any(|v| !v.is_finite()) {
        return Err(Error::Numerical(format!(
            "the free response or the measured output is not finite in samples {}..{}",
            range.start, range.end
        )));
    }
    // Zero rows make a short window's O_y square, so that its SVD has all n right singular
    // vectors and the directions y does not see are among them.
    if oy.nrows() < n {
        oy = oy.resize_vertically(n, 0.0);
    }
    let vy = if vy.len() < n {
        vy.resize_vertically(n, 0.0)
    } else {
        vy
    };
    let svd = oy.svd(true, true);
    let smax = svd.singular_values.max();
    let tol = 1e-9 * smax.max(f64::MIN_POSITIVE);
    let mut x = if let Some(x) = from_y {
        DVector::from_column_slice(x)
    } else if smax > 0.0 {
        svd.solve(&vy, tol)
            .map_err(|e| Error::Numerical(format!("least squares for a window's state: {e}")))?
    } else {
        DVector::zeros(n)
    };
    let v_t = svd.v_t.as_ref().expect("SVD computed with V");
    let null: Vec<DVector<f64>> = (0..n)
        .filter(|&i| svd.singular_values[i] <= tol)
        .map(|i| v_t.row(i).transpose())
        .collect();
    if !null.is_empty() && d.z > 0 {
        let basis = DMatrix::from_columns(&null);
        let vz = DVector::from_fn(len * d.z, |i, _| {
            let (k, c) = (i / d.z, i % d.z);
            z.get(range.start + k, c) - forced.get(k, d.y + c)
        }) - &oz * &x;
        let a = &oz * &basis;
        if a.iter().chain(vz.iter()).all(|v| v.is_finite()) {
            let svd = a.svd(true, true);
            let smax = svd.singular_values.max();
            if smax > 0.0
                && let Ok(c) = svd.solve(&vz, 1e-9 * smax)
            {
                x += basis * c;
            }
        }
    }
    Ok(x.iter().copied().collect())
}

/// The state at the first sample of `data` fitted to its first `init` samples (the first half of
/// a window in [`simulate_scored`]) with the maps
/// in `maps` fixed at the measured z (see the [module documentation](self)).
///
/// ```
/// use nalgebra::dmatrix;
/// use structid_core::validation::windows::state_from_record;
/// use structid_core::{Data, Lft, LftMatrices, Model, Signal};
/// // A pure integrator x⁺ = x + u, y = x: the state is the first output.
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![1.0], bu: dmatrix![1.0], be: dmatrix![0.0], bw: nalgebra::DMatrix::zeros(1, 0),
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: nalgebra::DMatrix::zeros(1, 0),
///     cz: nalgebra::DMatrix::zeros(0, 1), dzu: nalgebra::DMatrix::zeros(0, 1),
///     dze: nalgebra::DMatrix::zeros(0, 1), dzw: nalgebra::DMatrix::zeros(0, 0),
/// }).unwrap();
/// let model = Model::new(lft, vec![]).unwrap();
/// let u = Signal::from_fn(50, 1, |k, _| (k as f64).sin());
/// let mut x = 7.0;
/// let y = Signal::from_fn(50, 1, |k, _| { let y = x; x += u.get(k, 0); y });
/// let x0 = state_from_record(&model, &[], &Data::new(u, y).unwrap(), 10).unwrap();
/// assert!((x0[0] - 7.0).abs() < 1e-10);
/// ```
pub fn state_from_record(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    init: usize,
) -> Result<Vec<f64>> {
    crate::validation::check_record(model, maps, data, 0, "the state estimate")?;
    let z = measured_z(model, maps, data)?;
    let w = opened_w(model, maps, &z)?;
    window_state(model, data, &z, &w, 0..init.clamp(1, data.len()), None)
}

/// Simulates `model` with `maps` in the loop on `data` and says which samples score it: with
/// [`Scoring::Free`], one run from x₀ (zero, `x0` when given, which
/// [`crate::validate`] passes as its GLS estimate), scored after `settle` samples; with
/// [`Scoring::Windowed`], each window from its own fitted state (see the
/// [module documentation](self)), scored after its initialisation samples (and after
/// `settle`).
///
/// Errors as [`crate::Model::simulate`] ([`Error::Unstable`] when its state diverges);
/// [`Error::Numerical`] when an output is not finite or a map returns a non-finite value.
///
/// ```
/// use nalgebra::dmatrix;
/// use structid_core::validation::windows::{Scoring, Windows, simulate_scored};
/// use structid_core::{Data, Lft, LftMatrices, Model, Signal};
/// // A pure integrator driven by a biased force: a free run from rest drifts away, windows do not.
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![1.0], bu: dmatrix![0.01], be: dmatrix![0.0], bw: nalgebra::DMatrix::zeros(1, 0),
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: nalgebra::DMatrix::zeros(1, 0),
///     cz: nalgebra::DMatrix::zeros(0, 1), dzu: nalgebra::DMatrix::zeros(0, 1),
///     dze: nalgebra::DMatrix::zeros(0, 1), dzw: nalgebra::DMatrix::zeros(0, 0),
/// }).unwrap();
/// let model = Model::new(lft, vec![]).unwrap();
/// let u = Signal::from_fn(2000, 1, |k, _| (0.05 * k as f64).sin());
/// let mut x = 3.0;
/// // The plant sees u + 0.2 (an offset the model lacks).
/// let y = Signal::from_fn(2000, 1, |k, _| { let y = x; x += 0.01 * (u.get(k, 0) + 0.2); y });
/// let data = Data::new(u, y).unwrap();
/// let free = simulate_scored(&model, &[], &data, Scoring::Free, None, 0).unwrap();
/// let windows = Scoring::Windowed(Windows::new(100, 10).unwrap());
/// let win = simulate_scored(&model, &[], &data, windows, None, 0).unwrap();
/// assert!(free.rms(data.y(), 0) > 10.0 * win.rms(data.y(), 0));
/// ```
pub fn simulate_scored(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    scoring: Scoring,
    x0: Option<&[f64]>,
    settle: usize,
) -> Result<ScoredSimulation> {
    crate::validation::check_record(model, maps, data, settle, "simulation")?;
    let len = data.len();
    let ny = model.lft().dims().y;
    let (simulated, scored, states) = match scoring {
        Scoring::Free => {
            let sim = model.simulate(maps, data.u(), None, x0)?;
            // A free run is one segment, scored after the settling samples.
            #[allow(clippy::single_range_in_vec_init)]
            let scored = vec![settle..len];
            (sim.y, scored, vec![x0.map(<[f64]>::to_vec)])
        }
        Scoring::Windowed(windows) => {
            // The maps' outputs at the measured z, or none beyond measurability, where each
            // window's state is fitted through the simulation instead.
            let opened = match measured_z(model, maps, data) {
                Ok(z) => {
                    let w = opened_w(model, maps, &z)?;
                    Some((z, w))
                }
                Err(e) if e.beyond_measurability() => None,
                Err(e) => return Err(e),
            };
            let mut simulated = Signal::zeros(len, ny);
            let mut scored = Vec::new();
            let mut states = Vec::new();
            // The state the previous window's simulation reached: the next one's start.
            let mut carried = vec![0.0; model.lft().dims().states];
            for range in windows.ranges(len) {
                let init = windows.init.min(range.len().saturating_sub(1)).max(1);
                let fitted = range.start..range.start + (range.len() / 2).max(init);
                let x = match &opened {
                    Some((z, w)) => window_state(model, data, z, w, fitted, None)?,
                    None => simulated_window_state(model, maps, data, fitted, &carried)?,
                };
                let u = data.u().slice(range.clone());
                let sim = model.simulate(maps, &u, None, Some(&x))?;
                carried = sim.final_state;
                for k in 0..range.len() {
                    simulated
                        .sample_mut(range.start + k)
                        .copy_from_slice(sim.y.sample(k));
                }
                let from = (range.start + init).max(settle);
                if from < range.end {
                    scored.push(from..range.end);
                }
                states.push(Some(x));
            }
            (simulated, scored, states)
        }
    };
    if let Some(i) = simulated.as_slice().iter().position(|x| !x.is_finite()) {
        return Err(Error::Numerical(format!(
            "the simulation with the maps in the loop diverged (output {} is not finite at sample {})",
            i % ny,
            i / ny
        )));
    }
    if scored.iter().all(|r| r.is_empty()) {
        return Err(Error::InvalidParameter {
            name: "settle".into(),
            value: settle as f64,
            reason: "no sample is left to score after the settling and initialisation samples"
                .into(),
        });
    }
    Ok(ScoredSimulation {
        simulated,
        scored,
        states,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;

    fn integrator(gain: f64) -> Model {
        let lft = crate::Lft::new(crate::LftMatrices {
            a: dmatrix![1.0],
            bu: dmatrix![gain],
            be: dmatrix![0.0],
            bw: DMatrix::zeros(1, 0),
            cy: dmatrix![1.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: DMatrix::zeros(1, 0),
            cz: DMatrix::zeros(0, 1),
            dzu: DMatrix::zeros(0, 1),
            dze: DMatrix::zeros(0, 1),
            dzw: DMatrix::zeros(0, 0),
        })
        .unwrap();
        Model::new(lft, vec![]).unwrap()
    }

    /// Windowed scoring as it was before models beyond measurability were scored: every
    /// window's state by the linear fit at the measured z. A measurable model must still get
    /// exactly this.
    fn linear_windows(
        model: &Model,
        maps: &[&dyn Interpolant],
        data: &Data,
        windows: Windows,
    ) -> (Signal, Vec<Option<Vec<f64>>>) {
        let z = measured_z(model, maps, data).unwrap();
        let w = opened_w(model, maps, &z).unwrap();
        let mut simulated = Signal::zeros(data.len(), model.lft().dims().y);
        let mut states = Vec::new();
        for range in windows.ranges(data.len()) {
            let init = windows.init.min(range.len().saturating_sub(1)).max(1);
            let fitted = range.start..range.start + (range.len() / 2).max(init);
            let x = window_state(model, data, &z, &w, fitted, None).unwrap();
            let u = data.u().slice(range.clone());
            let sim = model.simulate(maps, &u, None, Some(&x)).unwrap();
            for k in 0..range.len() {
                simulated
                    .sample_mut(range.start + k)
                    .copy_from_slice(sim.y.sample(k));
            }
            states.push(Some(x));
        }
        (simulated, states)
    }

    /// A measurable model (a Hammerstein model on a slow plant, with noise in its record) is
    /// scored bit for bit as by the linear window states.
    #[test]
    fn a_measurable_model_keeps_the_linear_window_states_exactly() {
        let lft = crate::Lft::new(crate::LftMatrices {
            a: dmatrix![0.995],
            bu: dmatrix![0.0],
            be: dmatrix![0.0],
            bw: dmatrix![0.05],
            cy: dmatrix![1.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: dmatrix![0.0],
            cz: dmatrix![0.0],
            dzu: dmatrix![1.0],
            dze: dmatrix![0.0],
            dzw: dmatrix![0.0],
        })
        .unwrap();
        let d = std::sync::Arc::new(crate::KernelDispersion::gaussian(0.5).unwrap());
        let model = Model::new(lft, vec![crate::NonlinearBlock::new("N", vec![0], 0, d)]).unwrap();
        let sat = |z: &[f64]| (1.5 * z[0]).tanh();
        let u = Signal::from_fn(1500, 1, |k, _| (0.02 * k as f64).sin() + 0.4);
        let clean = model.simulate(&[&sat], &u, None, Some(&[2.0])).unwrap().y;
        let y = Signal::from_fn(1500, 1, |k, _| {
            clean.get(k, 0) + 0.01 * (k as f64 * 1.3).sin()
        });
        let data = Data::new(u, y).unwrap();
        let windows = Windows::new(200, 20).unwrap();
        let new =
            simulate_scored(&model, &[&sat], &data, Scoring::Windowed(windows), None, 0).unwrap();
        let (simulated, states) = linear_windows(&model, &[&sat], &data, windows);
        assert_eq!(new.simulated, simulated);
        assert_eq!(new.states, states);
        // And the integrator without maps.
        let model = integrator(0.02);
        let u = Signal::from_fn(700, 1, |k, _| (0.03 * k as f64).sin());
        let y = Signal::from_fn(700, 1, |k, _| 1.0 + 0.1 * (0.07 * k as f64).cos());
        let data = Data::new(u, y).unwrap();
        let new = simulate_scored(&model, &[], &data, Scoring::Windowed(windows), None, 0).unwrap();
        let (simulated, states) = linear_windows(&model, &[], &data, windows);
        assert_eq!(new.simulated, simulated);
        assert_eq!(new.states, states);
    }

    #[test]
    fn windows_cover_the_record_once() {
        for (len, length) in [(1000, 100), (1050, 100), (99, 100), (1999, 1000)] {
            let w = Windows::new(length, 10).unwrap();
            let r = w.ranges(len);
            assert_eq!(r[0].start, 0);
            assert_eq!(r.last().unwrap().end, len);
            assert!(r.windows(2).all(|p| p[0].end == p[1].start));
            assert!(r.iter().all(|x| x.len() < 2 * length || r.len() == 1));
        }
    }

    /// The exact model of an integrating record scores zero in every window, from any start
    /// (the state of each window is recovered), while a free run from rest does not.
    #[test]
    fn the_exact_integrating_model_scores_zero_in_windows() {
        let model = integrator(0.02);
        let u = Signal::from_fn(1000, 1, |k, _| (0.03 * k as f64).sin() + 0.1);
        let mut x = -4.0;
        let y = Signal::from_fn(1000, 1, |k, _| {
            let y = x;
            x += 0.02 * u.get(k, 0);
            y
        });
        let data = Data::new(u, y).unwrap();
        let s = Scoring::Windowed(Windows::new(150, 5).unwrap());
        let win = simulate_scored(&model, &[], &data, s, None, 0).unwrap();
        assert!(win.rms(data.y(), 0) < 1e-9, "{}", win.rms(data.y(), 0));
        assert_eq!(win.states.len(), 6);
        let free = simulate_scored(&model, &[], &data, Scoring::Free, None, 0).unwrap();
        assert!((free.rms(data.y(), 0) - 4.0).abs() < 1e-9);
        // Settling samples beyond the record are an error.
        assert!(simulate_scored(&model, &[], &data, s, None, 1000).is_err());
    }

    /// A rate-feedback loop (friction) around an integrating plant: the rate's memory of the
    /// previous output is invisible to y with the map's output fixed, and is fitted to the
    /// measured rate, so every window of the exact model reproduces the record; with that
    /// memory left at zero each window would start with a spurious rate of y/T_s.
    #[test]
    fn a_rate_memory_is_fitted_to_the_measured_rate() {
        use crate::{PolynomialDispersion, Structure};
        use std::sync::Arc;
        use structid_linear::PolynomialModel;
        let ts = 0.01;
        // Position from force: a pole at 1 (integrator) and one at 0.9.
        let g = PolynomialModel::new(
            vec![vec![0.0, 0.004, 0.0038]],
            vec![1.0, -1.9, 0.9],
            Some(ts),
        )
        .unwrap();
        let model = Structure::rate_feedback(g, Arc::new(PolynomialDispersion::new(1).unwrap()))
            .model()
            .unwrap();
        let friction = |z: &[f64]| 0.3 * (z[0] / 0.05).tanh() + 0.2 * z[0];
        let u = Signal::from_fn(3000, 1, |k, _| {
            2.0 * (0.004 * k as f64).sin() + 0.5 * (0.031 * k as f64).sin()
        });
        let n = model.lft().dims().states;
        // Start away from rest: a position of 5 and its memory consistent with it.
        let x0: Vec<f64> = (0..n).map(|i| if i + 1 == n { 5.0 } else { 0.0 }).collect();
        let sim = model.simulate(&[&friction], &u, None, Some(&x0)).unwrap();
        let y = sim.y;
        let z = Signal::from_fn(3000, 1, |k, _| {
            let prev = if k > 0 { y.get(k - 1, 0) } else { 5.0 };
            (y.get(k, 0) - prev) / ts
        });
        let data = Data::new(u, y).unwrap().with_z(z).unwrap();
        let s = Scoring::Windowed(Windows::new(300, 20).unwrap());
        let win = simulate_scored(&model, &[&friction], &data, s, None, 0).unwrap();
        let scale = crate::validation::metrics::rms(&data.y().channel(0));
        assert!(
            win.rms(data.y(), 0) < 1e-8 * scale,
            "{}",
            win.rms(data.y(), 0)
        );
    }
}

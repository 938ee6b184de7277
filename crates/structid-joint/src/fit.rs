//! The joint fit: settings, the executor and its result.
//!
//! [`fit`] minimises the multiple-shooting problem ([`crate::shooting`]) by
//! Levenberg–Marquardt, then polishes the result by single shooting (one segment per record,
//! the continuity penalty gone), and returns the best of the start, the multiple-shooting
//! result and the polish by the single-shooting criterion
//!
//! ```text
//!   C(θ, ξ₀) = Σ_k |y_k − ŷ_k(θ, ξ₀)|² + L·Σ_b β_b·D_b(θ_b)
//! ```
//!
//! so it never ends at a higher cost than it started from.
//!
//! With a continuity weight of zero (allowed only with segments and without the polish) the
//! segments are independent windows, each from its own fitted state: the criterion of a
//! windowed simulation, for a plant whose free run drifts (an integrator) and whose
//! single-shooting criterion therefore measures the drift, not the fit. That criterion is
//! then the fit's own, and the result is the start or the windows' fit, whichever has the
//! lower cost by it.
//!
//! With [`JointSettingsBuilder::windows`] the criterion is instead the score of a windowed
//! simulation ([`crate::windowed`]): each window's state fitted to its first half and
//! projected out of the search, the samples after its first `init` scored.

use structid_core::Data;
use structid_core::validation::Windows;
use structid_linear::levenberg_marquardt::{
    LeastSquaresProblem, LevenbergMarquardt, LmSettings, LmStatus,
};

use crate::error::{JointError, Result, invalid};
use crate::model::JointModel;
use crate::shooting::{Segment, Shooting};
use crate::step::Stepper;
use crate::windowed::Windowed;

/// Settings of [`fit`], built by [`JointSettings::builder`] with validated values.
///
/// ```
/// use structid_joint::JointSettings;
/// let s = JointSettings::builder().segment_length(100).build().unwrap();
/// assert_eq!(s.segment_length(), Some(100));
/// assert!(JointSettings::builder().segment_length(1).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct JointSettings {
    segment_length: Option<usize>,
    continuity_weight: f64,
    max_iterations: usize,
    tolerance: f64,
    estimate_initial_state: bool,
    polish: bool,
    windows: Option<Windows>,
}

impl Default for JointSettings {
    fn default() -> Self {
        Self {
            segment_length: None,
            continuity_weight: 1.0,
            max_iterations: 100,
            tolerance: 1e-9,
            estimate_initial_state: true,
            polish: true,
            windows: None,
        }
    }
}

impl JointSettings {
    /// A builder from the defaults: single shooting, 100 iterations, relative tolerance 1e-9,
    /// initial states estimated, continuity weight 1.
    pub fn builder() -> JointSettingsBuilder {
        JointSettingsBuilder(Self::default())
    }

    /// Samples per shooting segment (`None`: one segment per record, single shooting).
    pub fn segment_length(&self) -> Option<usize> {
        self.segment_length
    }

    /// μ of the continuity residuals μ·(ξ_(s+1) − Φ_s), in units of the output per unit of
    /// state, scaled by √(segment length) so that a defect weighs like the segment it spoils.
    pub fn continuity_weight(&self) -> f64 {
        self.continuity_weight
    }

    /// Largest number of Levenberg–Marquardt iterations of each stage.
    pub fn max_iterations(&self) -> usize {
        self.max_iterations
    }

    /// Relative decrease of the cost under which a stage has converged.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// Whether each record's initial state is fitted (otherwise the given or zero state,
    /// blocks at rest).
    pub fn estimate_initial_state(&self) -> bool {
        self.estimate_initial_state
    }

    /// Whether multiple shooting is followed by a single-shooting polish.
    pub fn polish(&self) -> bool {
        self.polish
    }

    /// The windows whose scoring is the fit's criterion (see [`crate::windowed`]); `None`:
    /// single or multiple shooting.
    pub fn windows(&self) -> Option<Windows> {
        self.windows
    }
}

/// Builder of [`JointSettings`].
#[derive(Clone, Debug)]
pub struct JointSettingsBuilder(JointSettings);

impl JointSettingsBuilder {
    /// Samples per shooting segment (at least 2).
    pub fn segment_length(mut self, len: usize) -> Self {
        self.0.segment_length = Some(len);
        self
    }
    /// Relative tolerance (in (0, 1)).
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.0.tolerance = tol;
        self
    }
    /// Continuity weight μ (> 0; 0 for independent windows, allowed only without the
    /// single-shooting polish).
    pub fn continuity_weight(mut self, mu: f64) -> Self {
        self.0.continuity_weight = mu;
        self
    }
    /// Iterations per stage (≥ 1).
    pub fn max_iterations(mut self, n: usize) -> Self {
        self.0.max_iterations = n;
        self
    }
    /// Whether initial states are fitted.
    pub fn estimate_initial_state(mut self, yes: bool) -> Self {
        self.0.estimate_initial_state = yes;
        self
    }
    /// Whether to polish by single shooting.
    pub fn polish(mut self, yes: bool) -> Self {
        self.0.polish = yes;
        self
    }
    /// Fit by the score of a simulation in `windows` (each window from a state fitted to its
    /// first half, scored after its first `init` samples; see [`crate::windowed`]) instead of
    /// by shooting: that criterion alone, without segments or the polish.
    pub fn windows(mut self, windows: Windows) -> Self {
        self.0.windows = Some(windows);
        self
    }
    /// Validates and returns the settings.
    pub fn build(self) -> Result<JointSettings> {
        let s = self.0;
        if let Some(l) = s.segment_length
            && l < 2
        {
            return Err(invalid(
                "segment_length",
                l as f64,
                "must be at least 2 samples",
            ));
        }
        let independent = s.continuity_weight == 0.0 && !s.polish && s.segment_length.is_some();
        if !(s.continuity_weight.is_finite() && (s.continuity_weight > 0.0 || independent)) {
            return Err(invalid(
                "continuity_weight",
                s.continuity_weight,
                "must be finite and positive (zero, for independent windows, only with segments \
                 and without the single-shooting polish)",
            ));
        }
        if let (Some(_), Some(l)) = (s.windows, s.segment_length) {
            return Err(invalid(
                "segment_length",
                l as f64,
                "cannot be set with windows, whose length is the segments'",
            ));
        }
        if s.max_iterations == 0 {
            return Err(invalid("max_iterations", 0.0, "must be at least 1"));
        }
        if !(s.tolerance > 0.0 && s.tolerance < 1.0) {
            return Err(invalid("tolerance", s.tolerance, "must lie in (0, 1)"));
        }
        Ok(s)
    }
}

/// One stage of the fit, as data.
#[derive(Clone, Debug)]
pub struct Stage {
    /// "multiple shooting" or "single shooting".
    pub name: &'static str,
    /// Segments used.
    pub segments: usize,
    /// The stage's own cost (continuity penalty included) after each accepted step.
    pub costs: Vec<f64>,
    /// How it ended.
    pub status: LmStatus,
}

/// The fitted model and how the fit went.
#[derive(Clone, Debug)]
pub struct JointFit {
    /// The fitted model.
    pub model: JointModel,
    /// Each record's stacked initial state ξ₀ (see [`JointModel::stacked_state_len`]).
    pub initial_states: Vec<Vec<f64>>,
    /// The single-shooting criterion C at the start (the criterion of independent windows
    /// when the continuity weight is zero, see the [module docs](self)).
    pub initial_cost: f64,
    /// The same criterion at the end (never above `initial_cost`).
    pub cost: f64,
    /// RMS simulation error per output channel over all records at the end.
    pub rms: Vec<f64>,
    /// The stages that ran.
    pub stages: Vec<Stage>,
}

/// The stacked initial state ξ₀ = [x₀; s₀] of each record of `data` that best explains it by
/// simulation, with every parameter of `model` held ([`JointModel::held`]): how a fitted
/// model is started on a new record whose first samples may be used to settle its state (a
/// test window that opens in the middle of an excitation). The fit is the single-shooting
/// Levenberg–Marquardt of [`fit`](crate::fit()) with `settings`' iterations and tolerance,
/// from rest.
///
/// ```
/// use nalgebra::dmatrix;
/// use structid_core::{Data, Lft, LftMatrices, Signal};
/// use structid_joint::{FixedMap, JointBlock, JointModel, JointSettings, fit_initial_state};
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![0.9], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
/// }).unwrap();
/// let n = FixedMap::new(std::sync::Arc::new(|z: &[f64]| z[0].tanh()), 1);
/// let model = JointModel::new(lft, vec![JointBlock::new("N", vec![0], 0, Box::new(n))]).unwrap();
/// let u = Signal::from_fn(50, 1, |k, _| (0.3 * k as f64).sin());
/// let y = model.simulate(&u, Some(&[2.0])).unwrap().y;
/// let x0 = fit_initial_state(&model, &Data::new(u, y).unwrap(), &JointSettings::default()).unwrap();
/// assert!((x0[0][0] - 2.0).abs() < 1e-6);
/// ```
///
/// # Errors
/// Those of [`fit`](crate::fit()): data whose channels do not match the model, or a model
/// that cannot be simulated on a record. A model without states gets an empty state per
/// record.
pub fn fit_initial_state(
    model: &JointModel,
    data: &Data,
    settings: &JointSettings,
) -> Result<Vec<Vec<f64>>> {
    if model.stacked_state_len() == 0 {
        // Nothing to fit: the simulation does not depend on a start.
        return Ok(vec![Vec::new(); data.record_count()]);
    }
    let settings = JointSettings {
        segment_length: None,
        windows: None,
        estimate_initial_state: true,
        ..settings.clone()
    };
    Ok(fit(&model.held(), data, None, &settings)?.initial_states)
}

/// Fits `model` to `data` (one or several records) by its simulation error; `x0` optionally
/// gives each record's starting LFT state (zero otherwise).
///
/// # Errors
/// [`JointError::NoStart`] when the starting model cannot be simulated on a record; wrong
/// channel counts; settings errors come from the builder.
pub fn fit(
    model: &JointModel,
    data: &Data,
    x0: Option<&[Vec<f64>]>,
    settings: &JointSettings,
) -> Result<JointFit> {
    let d = model.lft().dims();
    if data.u().channels() != d.u || data.y().channels() != d.y {
        return Err(JointError::InvalidModel(format!(
            "the data have {} input and {} output channel(s), the model {} and {}",
            data.u().channels(),
            data.y().channels(),
            d.u,
            d.y
        )));
    }
    let starts = start_states(model, data, x0)?;
    if let Some(windows) = settings.windows {
        return windowed_fit(model, data, &starts, windows, settings);
    }
    let initial_cost = single_cost(model, data, &starts).ok_or_else(|| JointError::NoStart {
        record: 1,
        detail: "the simulation diverged or a block returned a non-finite value".into(),
    })?;
    let mut best = (model.clone(), starts.clone(), initial_cost);
    let mut stages = Vec::new();
    let mut initial_cost = initial_cost;
    if let Some(len) = settings.segment_length {
        let (m, xi, stage) = run_stage(model, data, &starts, Some(len), settings)?;
        if settings.continuity_weight > 0.0 {
            if let Some(c) = single_cost(&m, data, &xi)
                && c < best.2
            {
                best = (m, xi, c);
            }
        } else {
            // The multiple-shooting criterion is the fit's own.
            let (first, last) = (stage.costs[0], *stage.costs.last().expect("the start"));
            initial_cost = first;
            best = if last < first {
                (m, xi, last)
            } else {
                (model.clone(), starts.clone(), first)
            };
        }
        stages.push(stage);
    }
    if settings.polish || settings.segment_length.is_none() {
        let (m, xi, stage) = run_stage(&best.0, data, &best.1, None, settings)?;
        if let Some(c) = single_cost(&m, data, &xi)
            && c < best.2
        {
            best = (m, xi, c);
        }
        stages.push(stage);
    }
    let rms = simulation_rms(&best.0, data, &best.1);
    Ok(JointFit {
        model: best.0,
        initial_states: best.1,
        initial_cost,
        cost: best.2,
        rms,
        stages,
    })
}

/// The fit by the criterion of a simulation in `windows` ([`crate::windowed`]): the start or
/// the fitted model, whichever scores lower by it.
fn windowed_fit(
    model: &JointModel,
    data: &Data,
    starts: &[Vec<f64>],
    windows: Windows,
    settings: &JointSettings,
) -> Result<JointFit> {
    let mut problem = Windowed::new(model, data, windows, starts);
    let theta = model.parameters();
    let no_start = || JointError::NoStart {
        record: 1,
        detail: "the windowed simulation diverged or a block returned a non-finite value".into(),
    };
    let initial_cost = problem
        .residuals(&theta)
        .ok_or_else(no_start)?
        .norm_squared();
    let out = LevenbergMarquardt::new(lm_settings(settings)?)
        .minimize(&mut problem, &theta)
        .map_err(|e| JointError::InvalidModel(e.to_string()))?;
    // The criterion is a function of θ alone, so the fitted θ is kept only when it scores
    // lower than the start; evaluating the kept one last leaves its window states in place.
    let fitted_cost = problem.residuals(&out.theta).map(|r| r.norm_squared());
    let keep = match fitted_cost {
        Some(c) if c < initial_cost => &out.theta,
        _ => &theta,
    };
    let cost = problem.residuals(keep).ok_or_else(no_start)?.norm_squared();
    let fitted = model.with_parameters(&keep[..problem.globals])?;
    let initial_states = problem.record_starts();
    let rms = problem.scored_rms(&fitted)?;
    let stage = Stage {
        name: "windows",
        segments: problem.states.len(),
        costs: std::iter::once(out.initial_cost)
            .chain(out.costs.iter().copied())
            .collect(),
        status: out.status,
    };
    Ok(JointFit {
        model: fitted,
        initial_states,
        initial_cost,
        cost,
        rms,
        stages: vec![stage],
    })
}

/// The Levenberg–Marquardt settings of a stage: `settings`' iterations and tolerance.
fn lm_settings(settings: &JointSettings) -> Result<LmSettings> {
    LmSettings::builder()
        .max_iterations(settings.max_iterations)
        .tolerance(settings.tolerance)
        .build()
        .map_err(|e| JointError::InvalidModel(e.to_string()))
}

/// Each record's starting stacked state: the given x₀ (or zero), blocks at rest.
fn start_states(model: &JointModel, data: &Data, x0: Option<&[Vec<f64>]>) -> Result<Vec<Vec<f64>>> {
    let bounds = data.record_bounds();
    if let Some(x0) = x0
        && x0.len() != bounds.len() - 1
    {
        return Err(JointError::InvalidModel(format!(
            "{} initial state(s) given for {} record(s)",
            x0.len(),
            bounds.len() - 1
        )));
    }
    (0..bounds.len() - 1)
        .map(|r| model.rest_state(data.u().sample(bounds[r]), x0.map(|x| x[r].as_slice())))
        .collect()
}

/// One LM stage from `model` and stacked starts: segments of `len` samples (one per record
/// when `None`). Returns the fitted model, each record's fitted start and the stage.
fn run_stage(
    model: &JointModel,
    data: &Data,
    starts: &[Vec<f64>],
    len: Option<usize>,
    settings: &JointSettings,
) -> Result<(JointModel, Vec<Vec<f64>>, Stage)> {
    let segments = segments(model, data, starts, len, settings.estimate_initial_state)?;
    let count = segments.len();
    let weight = settings.continuity_weight * (len.unwrap_or(1) as f64).sqrt();
    let mut problem = Shooting::new(model, data, segments, weight);
    let mut theta = model.parameters();
    for s in &problem.segments {
        if s.state_at.is_some() {
            theta.extend(&s.fixed);
        }
    }
    let out = LevenbergMarquardt::new(lm_settings(settings)?)
        .minimize(&mut problem, &theta)
        .map_err(|e| JointError::InvalidModel(e.to_string()))?;
    let fitted = model.with_parameters(&out.theta[..problem.globals])?;
    // Each record's start is its first segment's state.
    let mut firsts = Vec::new();
    let mut new_record = true;
    for s in &problem.segments {
        if new_record {
            firsts.push(match s.state_at {
                Some(at) => out.theta[at..at + s.fixed.len()].to_vec(),
                None => s.fixed.clone(),
            });
        }
        new_record = !s.continued;
    }
    let stage = Stage {
        name: if len.is_some() {
            "multiple shooting"
        } else {
            "single shooting"
        },
        segments: count,
        costs: std::iter::once(out.initial_cost)
            .chain(out.costs.iter().copied())
            .collect(),
        status: out.status,
    };
    Ok((fitted, firsts, stage))
}

/// Cuts each record into segments; the states of later segments start where a simulation of
/// the starting model from the record's start passes (the usual multiple-shooting start).
fn segments(
    model: &JointModel,
    data: &Data,
    starts: &[Vec<f64>],
    len: Option<usize>,
    free_first: bool,
) -> Result<Vec<Segment>> {
    let stepper = Stepper::new(model);
    let bounds = data.record_bounds();
    let nxi = model.stacked_state_len();
    let mut out: Vec<Segment> = Vec::new();
    let mut next_at = *model.parameter_offsets().last().expect("non-empty");
    for r in 0..bounds.len() - 1 {
        let (a, b) = (bounds[r], bounds[r + 1]);
        let step = len.unwrap_or(b - a).max(2);
        let mut xi = starts[r].clone();
        let mut k = a;
        while k < b {
            // A short tail joins the previous segment of its record.
            let end = if b - k < step + step / 2 { b } else { k + step };
            let free = free_first || k > a;
            out.push(Segment {
                start: k,
                end,
                state_at: free.then_some(next_at),
                fixed: xi.clone(),
                continued: end < b,
            });
            if free {
                next_at += nxi;
            }
            // Where the starting model passes; a diverging start keeps the last finite state.
            let mut trial = xi.clone();
            if stepper
                .run(data.u(), k..end, &mut trial, |_, _| {})
                .is_some()
            {
                xi = trial;
            }
            k = end;
        }
    }
    if out.is_empty() {
        return Err(JointError::InvalidModel("the data have no samples".into()));
    }
    Ok(out)
}

#[cfg(test)]
pub(crate) fn test_segments(
    model: &JointModel,
    data: &Data,
    starts: &[Vec<f64>],
    len: Option<usize>,
    free_first: bool,
) -> Vec<Segment> {
    segments(model, data, starts, len, free_first).unwrap()
}

/// The single-shooting criterion C, or `None` when a simulation diverges.
fn single_cost(model: &JointModel, data: &Data, starts: &[Vec<f64>]) -> Option<f64> {
    let segments = segments(model, data, starts, None, false).ok()?;
    let mut p = Shooting::new(model, data, segments, 1.0);
    let theta = model.parameters();
    p.residuals(&theta).map(|r| r.norm_squared())
}

fn simulation_rms(model: &JointModel, data: &Data, starts: &[Vec<f64>]) -> Vec<f64> {
    let stepper = Stepper::new(model);
    let ny = stepper.outputs();
    let bounds = data.record_bounds();
    let mut sum = vec![0.0; ny];
    for r in 0..bounds.len() - 1 {
        let mut xi = starts[r].clone();
        let ok = stepper.run(data.u(), bounds[r]..bounds[r + 1], &mut xi, |k, y| {
            for (o, s) in sum.iter_mut().enumerate() {
                *s += (data.y().sample(k)[o] - y[o]).powi(2);
            }
        });
        if ok.is_none() {
            return vec![f64::INFINITY; ny];
        }
    }
    sum.iter().map(|s| (s / data.len() as f64).sqrt()).collect()
}

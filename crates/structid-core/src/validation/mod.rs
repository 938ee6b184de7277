//! Validation of estimated maps on a record: free-run simulation, one-step-ahead prediction and
//! residual tests.
//!
//! Given the model, one map per block (typically [`crate::Identification::maps`]) and a record
//! (preferably one that was *not* used for identification), [`validate`] answers two questions:
//!
//! 1. **Simulation.** How well does the model reproduce y from u alone? The LFT is run with the
//!    maps in the loop ([`Model::simulate`], e = 0): z is computed from the *simulated* signals,
//!    so errors of the maps propagate through the dynamics. Per output: RMS(y − y_sim) and the
//!    fit 100·(1 − ‖y − y_sim‖/‖y − mean y‖) of MATLAB's `compare`
//!    ([`crate::validation::metrics::fit_percent`]). When the data carry measured z columns, the
//!    simulation still computes z from the LFT's z-equations (C_z, D_zu), which must then
//!    describe how z arises; the measured z serve the prediction only.
//! 2. **One-step prediction.** What does the model leave unexplained? z is measurable (computed
//!    from the measured u and y, see [`crate::Lft::measurability`]), so ŵ_k = N̂(z_k) is known
//!    and
//!
//!    ```text
//!    v = r − T_yw·ŵ − O·x̂₀ = T_ye·e        (r = y − T_yu·u, O·x̂₀ the free response)
//!    ```
//!
//!    is the output of the noise path if the maps are right. The prediction error is the
//!    innovation of v: ε_k = v_k − E[v_k | v_0 … v_(k−1)], from the time-varying Kalman
//!    predictor of the noise path T_ye (started at rest; [`KalmanWhitener::innovations`]),
//!    in the units of y (not normalised). For a static noise path (order 0) nothing is
//!    predictable from the past and ε = v. Equivalently, ε_k = y_k − ŷ_(k|k−1) with
//!
//!    ```text
//!    ŷ_(k|k−1) = (T_yu·u)_k + (O·x̂₀)_k + (T_yw·ŵ)_k + E[v_k | v_0 … v_(k−1)],
//!    ```
//!
//!    which uses u_0 … u_k, the measured z_0 … z_k and y_0 … y_(k−1). (When z is computed by
//!    output injection z = L_zu·u + Ψ·(y − L_yu·u), z_k itself contains y_k; the predictor then
//!    uses the present value of the outputs that z reads, as the model structure implies.)
//!    If the maps and the noise model are right, ε is white and uncorrelated with past inputs;
//!    the residual tests of [`crate::validation::residual_tests`] check both with 99 % bands.
//!
//! **Initial state.** [`InitialState::Zero`] assumes the record starts at rest.
//! [`InitialState::Estimate`] estimates x₀ by generalised least squares from the
//! one-step residual: with the maps fixed, r − T_yw·ŵ = O·x₀ + T_ye·e, so
//! x̂₀ = argmin ‖W·(r − T_yw·ŵ − O·x₀)‖² with W the Kalman whitening operator of T_ye
//! (WᵀW = (T_ye·T_yeᵀ)⁻¹; ordinary least squares when a static noise path leaves some output
//! without noise, so that W does not exist). This is the Gauss–Markov estimate of x₀ given ŵ,
//! the same correction as the exact solver's x̂₀ = (OᵀM⁻¹O)⁻¹OᵀM⁻¹r with the map term of M
//! removed because ŵ is known. Directions of x₀ that do not reach y (numerically rank-deficient
//! O) get the minimum-norm value: they reach neither z nor y, so they change no result.
//! The simulation then starts from x̂₀ and the prediction uses v with O·x̂₀ removed.

pub mod comparison;
pub mod distributions;
pub mod metrics;
pub mod records;
pub mod residual_tests;
mod simulated_state;
pub mod windows;

pub use records::{RecordsValidation, validate_records};
pub use windows::{ScoredSimulation, Scoring, Windows, simulate_scored};

/// The free-run simulation error of `lft` with `bindings` in the loop on every record of
/// `data`, each record from rest (zero state, e = 0), over every output and the samples after
/// the first `settle` of each record, pooled ([`metrics::PooledFit`]).
///
/// This is the score of β selection by validation and of `refine`'s alternations; an error
/// of the simulation (a loop that diverges: [`Error::Numerical`] or [`Error::Unstable`]) is
/// returned for the caller to score as it must.
///
/// ```
/// use nalgebra::dmatrix;
/// use structid_core::validation::simulate_records_from_rest;
/// use structid_core::{Data, Lft, LftMatrices, MapBinding, Signal};
/// // y_k = 0.5·y_(k−1) + tanh(u_(k−1)), two records pooled after 1 settling sample each.
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![0.5], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![0.0], dyw: dmatrix![0.0],
///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
/// }).unwrap();
/// let tanh = |z: &[f64]| z[0].tanh();
/// let binding = [MapBinding { inputs: &[0], output: 0, map: &tanh }];
/// let u = Signal::from_fn(6, 1, |k, _| k as f64 * 0.3);
/// let y = lft.simulate(&binding, &u, None, None).unwrap().y;
/// let one = Data::new(u.clone(), y.clone()).unwrap();
/// let two = Data::from_records(vec![one.clone(), one]).unwrap();
/// let pooled = simulate_records_from_rest(&lft, &binding, &two, 1).unwrap();
/// assert_eq!(pooled.samples(), 10);
/// assert!(pooled.rms() < 1e-15);
/// ```
pub fn simulate_records_from_rest(
    lft: &crate::Lft,
    bindings: &[crate::MapBinding<'_>],
    data: &Data,
    settle: usize,
) -> Result<metrics::PooledFit> {
    let mut pooled = metrics::PooledFit::default();
    for record in data.records() {
        let sim = lft.simulate(bindings, record.u(), None, None)?;
        let y = record.y();
        let start = settle.min(y.len());
        for c in 0..y.channels() {
            pooled.add(&y.channel(c)[start..], &sim.y.channel(c)[start..]);
        }
    }
    Ok(pooled)
}

use structid_lti::Signal;
use structid_lti::kalman::{KalmanWhitener, WhiteningOptions};

use crate::error::{Error, Result};
use crate::identify::problem::Problem;
use crate::initial_state::{InitialState, estimate_initial_state};
use crate::model::interpolant::Interpolant;
use crate::model::{Data, Model};
use crate::validation::metrics::rms;
use crate::validation::residual_tests::{CorrelationTest, autocorrelation, cross_correlation};

/// Settings of [`validate`]; build them with [`ValidationSettings::builder`].
///
/// ```
/// use structid_core::InitialState;
/// use structid_core::validation::ValidationSettings;
/// let s = ValidationSettings::default();
/// assert_eq!((s.initial_state(), s.max_lag()), (InitialState::Zero, 25));
/// let s = ValidationSettings::builder().max_lag(10).initial_state(InitialState::Estimate).build().unwrap();
/// assert_eq!(s.max_lag(), 10);
/// assert!(ValidationSettings::builder().max_lag(0).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ValidationSettings {
    initial_state: InitialState,
    max_lag: usize,
    settle: usize,
    scoring: Scoring,
}

impl Default for ValidationSettings {
    /// A record at rest and correlation lags up to 25 (MATLAB's `resid` default).
    fn default() -> Self {
        Self {
            initial_state: InitialState::Zero,
            max_lag: 25,
            settle: 0,
            scoring: Scoring::Free,
        }
    }
}

impl ValidationSettings {
    /// A builder starting from the defaults.
    pub fn builder() -> ValidationSettingsBuilder {
        ValidationSettingsBuilder {
            inner: Self::default(),
        }
    }

    /// How the initial state is treated.
    pub fn initial_state(&self) -> InitialState {
        self.initial_state
    }

    /// The largest lag of the correlation tests.
    pub fn max_lag(&self) -> usize {
        self.max_lag
    }

    /// Leading samples that only settle the state: the simulation RMS and fit leave them out
    /// (benchmarks score from a given sample on; the Silverbox tests allow 50).
    pub fn settle(&self) -> usize {
        self.settle
    }

    /// How the simulation is scored: one free run (the default) or windows, each from a state
    /// fitted to its first half ([`windows`]; for plants with integrators).
    pub fn scoring(&self) -> Scoring {
        self.scoring
    }
}

/// Builder for [`ValidationSettings`]; [`ValidationSettingsBuilder::build`] validates.
#[derive(Clone, Debug)]
pub struct ValidationSettingsBuilder {
    inner: ValidationSettings,
}

impl ValidationSettingsBuilder {
    /// Zero or estimated initial state.
    pub fn initial_state(mut self, initial_state: InitialState) -> Self {
        self.inner.initial_state = initial_state;
        self
    }

    /// The largest lag of the correlation tests (≥ 1, and less than the record length).
    pub fn max_lag(mut self, max_lag: usize) -> Self {
        self.inner.max_lag = max_lag;
        self
    }

    /// Leading samples left out of the simulation RMS and fit (default 0; less than the
    /// record length).
    pub fn settle(mut self, samples: usize) -> Self {
        self.inner.settle = samples;
        self
    }

    /// Free-run (default) or windowed scoring of the simulation (see [`windows`]).
    pub fn scoring(mut self, scoring: Scoring) -> Self {
        self.inner.scoring = scoring;
        self
    }

    /// Validates and returns the settings.
    pub fn build(self) -> Result<ValidationSettings> {
        if self.inner.max_lag == 0 {
            return Err(Error::InvalidParameter {
                name: "max_lag".into(),
                value: 0.0,
                reason: "must be at least 1 (lag 0 of an autocorrelation is 1 by definition)"
                    .into(),
            });
        }
        Ok(self.inner)
    }
}

/// Everything [`validate`] computed.
#[derive(Clone, Debug, PartialEq)]
pub struct ValidationReport {
    /// y simulated with the maps in the loop from u alone (e = 0, z from the simulated
    /// signals), L × n_y.
    pub simulated: Signal,
    /// Per output: RMS(y − y_sim) over the samples after the settling ones.
    pub rms: Vec<f64>,
    /// Per output: the fit 100·(1 − ‖y − y_sim‖/‖y − mean y‖) in percent over the samples after
    /// the settling ones (100 is perfect, 0 is no better than the mean, NaN for a constant
    /// output).
    pub fit_percent: Vec<f64>,
    /// The one-step-ahead prediction errors ε_k = y_k − ŷ_(k|k−1) (innovations of the noise
    /// path, in output units), L × n_y.
    pub prediction_error: Signal,
    /// Per output: RMS(ε).
    pub prediction_rms: Vec<f64>,
    /// Per output: the autocorrelation of ε at lags 0…max_lag with its 99 % band.
    pub whiteness: Vec<CorrelationTest>,
    /// `[output][input]`: the cross-correlation of ε with u at lags −max_lag…max_lag (a
    /// positive lag pairs ε with past inputs).
    pub input_correlation: Vec<Vec<CorrelationTest>>,
    /// The estimated x₀ ([`InitialState::Estimate`]), otherwise `None`.
    pub initial_state: Option<Vec<f64>>,
    /// Number of samples L.
    pub samples: usize,
    /// How the simulation was scored.
    pub scoring: Scoring,
    /// The sample ranges the simulation RMS and fit are over.
    pub scored: Vec<std::ops::Range<usize>>,
}

impl ValidationReport {
    /// Whether every output's ε passes the whiteness test.
    pub fn whiteness_passes(&self) -> bool {
        self.whiteness.iter().all(CorrelationTest::passes)
    }

    /// Whether every (output, input) pair passes the cross-correlation test.
    pub fn input_correlation_passes(&self) -> bool {
        self.input_correlation
            .iter()
            .flatten()
            .all(CorrelationTest::passes)
    }
}

/// Validates `maps` (one per block of `model`, in model order) on `data`: simulation with the
/// maps in the loop, one-step-ahead prediction errors and their residual tests. See the
/// [module documentation](self) for exactly what is simulated and predicted.
///
/// Errors: [`Error::DimensionMismatch`] when the number of maps differs from the number of
/// blocks or the data's channels do not fit the model; [`Error::InvalidParameter`] when
/// `max_lag` is not less than the record length; [`Error::AlgebraicLoop`] for a cycle of
/// maps; [`Error::NotMeasurable`] when z cannot be computed from the data, with maps in series
/// evaluated in order ([`Model::compute_z_with_maps`]; a latent block has no such z), (or,
/// with an estimated x₀, when x₀ reaches z and y differently); [`Error::Numerical`] when a map
/// returns a non-finite value; [`Error::Unstable`] when the simulation or the one-step
/// predictor diverges; [`Error::InvalidStructure`] when the
/// noise path has no Kalman predictor (some output without noise of its own).
///
/// ```
/// use std::sync::Arc;
/// use nalgebra::dmatrix;
/// use structid_core::validation::{validate, ValidationSettings};
/// use structid_core::{Data, KernelDispersion, Lft, LftMatrices, Model, NonlinearBlock};
/// use structid_lti::Signal;
/// // Hammerstein: x⁺ = 0.5x + w, y = x + e, w = tanh(u).
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![0.5], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
/// }).unwrap();
/// let block = NonlinearBlock::new("N", vec![0], 0, Arc::new(KernelDispersion::gaussian(0.3).unwrap()));
/// let model = Model::new(lft, vec![block]).unwrap();
/// let tanh = |z: &[f64]| z[0].tanh();
/// let u = Signal::from_fn(300, 1, |k, _| (0.37 * k as f64).sin() * 2.0);
/// let y = model.simulate(&[&tanh], &u, None, None).unwrap().y;
/// let data = Data::new(u, y).unwrap();
///
/// let report = validate(&model, &[&tanh], &data, &ValidationSettings::default()).unwrap();
/// assert!(report.rms[0] < 1e-12 && report.fit_percent[0] > 99.999);
/// // A map that is off by 20 % leaves an error that the input explains.
/// let wrong = |z: &[f64]| 0.8 * z[0].tanh();
/// let report = validate(&model, &[&wrong], &data, &ValidationSettings::default()).unwrap();
/// assert!(report.fit_percent[0] < 90.0 && !report.input_correlation_passes());
/// ```
pub fn validate(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    settings: &ValidationSettings,
) -> Result<ValidationReport> {
    check_record(model, maps, data, settings.settle, "validation")?;
    let lft = model.lft();
    let len = data.len();
    let max_lag = settings.max_lag;
    if max_lag == 0 || max_lag >= len {
        return Err(Error::InvalidParameter {
            name: "max_lag".into(),
            value: max_lag as f64,
            reason: format!(
                "must be at least 1 and less than the number of samples ({len}); correlations \
                 need overlapping samples"
            ),
        });
    }
    // A cycle of maps has no z at all; refuse it before the (longer) prediction work.
    model.evaluation_order()?;
    let MeasuredResidual {
        v,
        whitener,
        dynamic_noise,
        x0,
        w_hat,
    } = measured_residual(model, maps, data, settings.initial_state)?;
    let ny = lft.dims().y;

    let eps = match (&whitener, dynamic_noise) {
        (Some(w), true) => {
            let mut eps = vec![0.0; len * ny];
            w.innovations(&v, &mut eps);
            eps
        }
        _ => v,
    };
    if let Some(i) = eps.iter().position(|x| !x.is_finite()) {
        return Err(Error::Unstable(format!(
            "the one-step prediction error is not finite at sample {} (output {}): the noise model's \
             predictor is unstable on this record",
            i / ny,
            i % ny
        )));
    }
    let prediction_error = Signal::new(ny, eps)?;

    // The GLS x̂₀ fits y; the directions of x₀ that y does not see with the maps' outputs
    // fixed (a rate's memory of the previous output) are fitted to the measured z, so that the
    // simulation does not start with a spurious jump.
    let x0 = match x0 {
        Some(x) if !x.is_empty() => {
            let z = windows::measured_z(model, maps, data)?;
            let head = 0..len.min(x.len().max(1) * 50).max(1);
            Some(windows::window_state(
                model,
                data,
                &z,
                &w_hat,
                head,
                Some(&x),
            )?)
        }
        other => other,
    };
    let scored = simulate_scored(
        model,
        maps,
        data,
        settings.scoring,
        x0.as_deref(),
        settings.settle,
    )?;
    let simulated = scored.simulated.clone();
    let mut rms_sim = Vec::with_capacity(ny);
    let mut fit = Vec::with_capacity(ny);
    let mut prediction_rms = Vec::with_capacity(ny);
    let mut whiteness = Vec::with_capacity(ny);
    let mut input_correlation = Vec::with_capacity(ny);
    // The settling samples are left out of the one-step statistics as of the simulation's: a
    // transient from an unknown x₀ would otherwise dominate both.
    let settle = settings.settle;
    let inputs: Vec<Vec<f64>> = (0..data.u().channels())
        .map(|j| data.u().channel(j)[settle..].to_vec())
        .collect();
    for c in 0..ny {
        let e = prediction_error.channel(c)[settle..].to_vec();
        rms_sim.push(scored.rms(data.y(), c));
        fit.push(scored.fit_percent(data.y(), c));
        prediction_rms.push(rms(&e));
        whiteness.push(non_negative_lags(autocorrelation(&e, max_lag)));
        input_correlation.push(
            inputs
                .iter()
                .map(|u| cross_correlation(&e, u, max_lag))
                .collect(),
        );
    }
    Ok(ValidationReport {
        simulated,
        rms: rms_sim,
        fit_percent: fit,
        prediction_error,
        prediction_rms,
        whiteness,
        input_correlation,
        initial_state: x0,
        samples: len,
        scoring: settings.scoring,
        scored: scored.scored,
    })
}

/// The checks every evaluation of maps on a record starts with: one map per block, a record
/// that fits the LFT, and fewer settling samples than samples.
pub(crate) fn check_record(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    settle: usize,
    what: &str,
) -> Result<()> {
    let blocks = model.blocks();
    if maps.len() != blocks.len() {
        return Err(Error::DimensionMismatch {
            what: format!("number of maps for {what} (one per block, in model order)"),
            expected: blocks.len().to_string(),
            found: maps.len().to_string(),
        });
    }
    data.require_single_record(what)?;
    data.check_against(model.lft())?;
    let len = data.len();
    if settle >= len {
        return Err(Error::InvalidParameter {
            name: "settle".into(),
            value: settle as f64,
            reason: format!(
                "must be less than the number of samples ({len}); nothing would be scored"
            ),
        });
    }
    Ok(())
}

/// What the one-step predictor and the k-step predictor share: the measured residual
/// v = r − T_yw·ŵ − O·x̂₀ with ŵ = N̂(z) at the measured z, the Kalman predictor of the noise
/// path, and x̂₀.
pub(crate) struct MeasuredResidual {
    /// v, time-major (L · n_y).
    pub(crate) v: Vec<f64>,
    /// The Kalman predictor of T_ye (`None` for a static path without one).
    pub(crate) whitener: Option<KalmanWhitener>,
    /// Whether T_ye has dynamics.
    pub(crate) dynamic_noise: bool,
    /// x̂₀: `None` with a zero initial state.
    pub(crate) x0: Option<Vec<f64>>,
    /// ŵ = N̂(z) at the measured z, L × n_w.
    pub(crate) w_hat: Signal,
}

/// v = r − T_yw·ŵ − O·x̂₀ (see the [module documentation](self)); the data must already have
/// been checked against the model.
pub(crate) fn measured_residual(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    initial_state: InitialState,
) -> Result<MeasuredResidual> {
    let lft = model.lft();
    let len = data.len();
    // A z filtered from y through a dynamic Ψ(q) with states of its own (a measured rate's
    // memory of the previous output) would depend on the unknown x₀; it is computed from the
    // record with Ψ at rest instead, i.e. taken as measured, as identification takes it.
    // Maps in series: z is computed once, with the maps evaluated in order, and then taken as
    // measured (the one-step predictor needs only z and ŵ = N̂(z), whatever D_zw is).
    // An output-error model with a latent z (a sensor map behind an actuator map) has its z
    // simulated from u, and is treated as maps in series are.
    let with_z;
    // Needed only where z is not given and either the output-error case or an estimated
    // initial state asks how z is computed: computed once, and only then.
    let dzw_zero = lft.matrices().dzw.iter().all(|v| *v == 0.0);
    let asks = (dzw_zero && lft.noise_free_z()) || initial_state == InitialState::Estimate;
    let measurability = if data.z().is_none() && asks {
        Some(lft.measurability())
    } else {
        None
    };
    let series = !dzw_zero || (lft.noise_free_z() && matches!(measurability, Some(Err(_))));
    let data = match (initial_state, data.z()) {
        (InitialState::Estimate, None) if series => {
            return Err(Error::NotMeasurable {
                explanation: "maps in series are predicted from a record at rest: their z is \
                              computed from u, y and the maps upstream from a zero state, which an \
                              estimated initial state would contradict; use the zero initial \
                              state with a settling period instead"
                    .into(),
            });
        }
        (_, None) if series => {
            with_z = data
                .clone()
                .with_z(model.compute_z_with_maps(data.u(), data.y(), maps)?)?;
            &with_z
        }
        (InitialState::Estimate, None) if matches!(measurability, Some(Ok(crate::ZSource::Dynamic { ref system })) if system.order() > 0) =>
        {
            with_z = data.clone().with_z(lft.compute_z(data.u(), data.y())?.0)?;
            &with_z
        }
        _ => data,
    };
    let problem = match initial_state {
        InitialState::Zero => Problem::from_model(model, data)?,
        InitialState::Estimate => Problem::from_model_with_initial_state(model, data)?,
    };
    let ny = problem.outputs();

    // v = r − T_yw·ŵ with ŵ = N̂(z) at the measured (computed) z.
    let mut v = problem.residual().as_slice().to_vec();
    let mut tmp = vec![0.0; len * ny];
    let nw = lft.dims().w;
    let mut w_hat = vec![0.0; len * nw];
    for (block, map) in problem.blocks().iter().zip(maps) {
        let w = map.eval_many(&block.z);
        if let Some(k) = w.iter().position(|x| !x.is_finite()) {
            return Err(Error::Numerical(format!(
                "the map of block `{}` returned {} at sample {k} (z = {:?}) of the validation record",
                block.name,
                w[k],
                block.z.sample(k)
            )));
        }
        for (k, wk) in w.iter().enumerate() {
            w_hat[k * nw + block.output] = *wk;
        }
        block.path.apply(&w, &mut tmp);
        v.iter_mut().zip(&tmp).for_each(|(a, b)| *a -= b);
    }

    let noise = lft.t_ye();
    let dynamic_noise = noise.order() > 0;
    let whitener = match KalmanWhitener::new(&noise, len, &WhiteningOptions::default()) {
        Ok(w) => Some(w),
        // A static path needs no predictor; only the GLS weighting of x₀ is lost.
        Err(_) if !dynamic_noise => None,
        Err(e) => {
            return Err(Error::InvalidStructure(format!(
                "one-step prediction needs the Kalman predictor of the noise path T_ye, which does not \
                 exist for this model: {e}"
            )));
        }
    };

    let x0 = match problem.free_response() {
        Some(o) if o.ncols() > 0 => {
            let x0 = estimate_initial_state(o.as_ref(), &v, whitener.as_ref())?;
            for (i, vi) in v.iter_mut().enumerate() {
                *vi -= (0..o.ncols()).map(|j| o[(i, j)] * x0[j]).sum::<f64>();
            }
            Some(x0)
        }
        Some(_) => Some(Vec::new()),
        None => None,
    };

    Ok(MeasuredResidual {
        v,
        whitener,
        dynamic_noise,
        x0,
        w_hat: Signal::new(nw, w_hat)?,
    })
}

/// An autocorrelation keeps its lags 0…max_lag: it is symmetric, so the negative lags repeat the
/// positive ones and would count every lag outside the band twice.
fn non_negative_lags(t: CorrelationTest) -> CorrelationTest {
    let keep: Vec<usize> = (0..t.lags.len()).filter(|&i| t.lags[i] >= 0).collect();
    CorrelationTest {
        lags: keep.iter().map(|&i| t.lags[i]).collect(),
        values: keep.iter().map(|&i| t.values[i]).collect(),
        ..t
    }
}

#[cfg(test)]
mod tests;

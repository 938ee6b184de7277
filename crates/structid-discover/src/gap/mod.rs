//! The gap between a model and a record: how large it is, whether it is only noise, and where
//! it sits.
//!
//! [`gap`] simulates the model (with its maps, if any) on the record from u alone with the
//! initial state estimated (`structid_core::validate` with
//! [`InitialState::Estimate`]; from rest for maps in series, whose z is computed from a zero
//! state; a model without a one-step predictor, whose z the record does not give, is only
//! simulated, and its prewhitened simulation residual stands for ε) and examines the simulation residual y − ŷ and the
//! one-step prediction errors ε of the model's noise path (for an output-error model, whose
//! noise is white at the output, the two are the same signal; a model with a noise model is
//! judged by its innovations, so that coloured noise it explains is not taken for a missing
//! effect):
//!
//! * the simulation RMS and fit (MATLAB's `compare` NRMSE fit in percent);
//! * a noise level that does not depend on the model, σ̂ = MAD(Δε)/(0.6745·√2) (at least
//!   the quantisation noise q/√12 of an output with few distinct values): first
//!   differences remove the slow part of a model error, and for white noise Δε has standard
//!   deviation √2·σ;
//! * the noise level of the simulation residual allowing for coloured noise
//!   ([`noise_level_coloured`]: the robust semivariogram over lags 1…10 fitted by
//!   σ²·(1 − φ^k) + c·k², so that white noise, AR(1) noise and a slow model error are told
//!   apart), from which the discovery workflow takes its noise level;
//! * portmanteau tests, together at the 0.1 % level (Bonferroni over the tests), so that the whole
//!   family of lags has one error rate (a lag-by-lag band would flag a correct model about
//!   40 % of the time over 50 lags): the
//!   Ljung–Box statistic of ε (whiteness), the Box–Jenkins statistic N·Σ_τ r²_εu(τ) over the lags τ ≥ 1 at which the input leads
//!   (τ ≥ 0 for a model with direct feedthrough; in closed loop the input follows the noise) for each
//!   input with u prewhitened by an AR(10) fit (so that the lags are independent under the null
//!   hypothesis; a coloured input would inflate the statistic), and the same for ε against
//!   u² − mean(u²) and ε² against u² (the nonlinear correlation tests of Billings and Voon,
//!   which see even nonlinearities that leave ε uncorrelated with u itself);
//! * the time windows where the moving RMS of ε exceeds `band`·σ̂, and the operating regions of
//!   the candidate signals where its energy concentrates ([`crate::localise`]).
//!
//! * when every test passes, the lattice of a quantised output ([`output_lattice`]): a
//!   quantiser's error is white and uncorrelated with the input, so the tests cannot see it.
//!
//! The verdict is "no missing effect detected" when every test passes, RMS(ε) ≤
//! `noise_ratio`·σ̂ and the output sits on no lattice; otherwise the failing statistics (or
//! the lattice) are listed.

use std::ops::Range;

use structid_core::validation::distributions::chi_square_quantile;
use structid_core::validation::residual_tests::{autocorrelation, cross_correlation};
use structid_core::validation::{Scoring, ValidationSettings, simulate_scored, validate};
use structid_core::{Data, InitialState, Interpolant, Model, Result, Signal};

use crate::localise::{Region, exceedance_windows, operating_regions};

mod noise;
use noise::quantisation_floor;
pub use noise::{
    LATTICE_COHERENCE, Lattice, NoiseFit, noise_level, noise_level_coloured,
    noise_level_coloured_records, noise_level_records, output_lattice, output_lattice_records,
};

/// Settings of [`gap`].
#[derive(Clone, Debug, PartialEq)]
pub struct GapSettings {
    /// Largest lag of the correlation tests (default 25).
    pub max_lag: usize,
    /// Window of the moving RMS in samples (default: L/50, at least 20).
    pub window: Option<usize>,
    /// A window exceeds the noise band when its RMS is above `band`·σ̂ (default 3).
    pub band: f64,
    /// The gap counts as noise only when RMS(ε) ≤ `noise_ratio`·σ̂ (default 1.5).
    pub noise_ratio: f64,
    /// Smallest share of the samples an operating region may hold (default 0.05).
    pub min_region_share: f64,
    /// The initial state of the simulation (default: estimated; a record that starts at rest
    /// can use zero, and a model whose x₀ reaches z differently from y must).
    pub initial_state: InitialState,
    /// How the simulation is scored (default: one free run; windows for a model with
    /// integrators, see [`structid_core::validation::windows`]).
    pub scoring: Scoring,
}

impl Default for GapSettings {
    fn default() -> Self {
        Self {
            max_lag: 25,
            window: None,
            band: 3.0,
            noise_ratio: 1.5,
            min_region_share: 0.05,
            initial_state: InitialState::Estimate,
            scoring: Scoring::Free,
        }
    }
}

/// One portmanteau test.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Portmanteau {
    /// What is tested, e.g. `whiteness of ε` or `ε against u`.
    pub name: String,
    /// The statistic.
    pub statistic: f64,
    /// Its critical value: the quantile of χ² with `lags` degrees of freedom at 1 − 0.001/m for
    /// m tests (Bonferroni), so that the family errs 0.1 % of the time.
    pub critical: f64,
    /// Degrees of freedom.
    pub lags: usize,
}

impl Portmanteau {
    /// Whether the statistic is below its critical value.
    pub fn passes(&self) -> bool {
        self.statistic <= self.critical
    }
}

/// Everything [`gap`] found.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Gap {
    /// The simulation residual ε = y − ŷ (first output).
    pub residual: Vec<f64>,
    /// The simulated output ŷ (first output).
    pub simulated: Vec<f64>,
    /// RMS of the simulation residual y − ŷ.
    pub rms: f64,
    /// The samples `rms` is taken over, as ranges into `residual` (those after the settling
    /// samples in a free run; the scored part of each window when scored in windows).
    pub scored: Vec<Range<usize>>,
    /// RMS of the one-step prediction errors ε (equal to `rms` for an output-error model).
    pub prediction_rms: f64,
    /// The fit in percent.
    pub fit_percent: f64,
    /// The model-free noise level of the innovations ε from their first differences
    /// ([`noise_level`], at least the quantisation noise of y), which the verdict compares
    /// RMS(ε) with and the time windows are drawn against: a slow effect in ε does not raise
    /// it. It reads coloured noise as white (√(1 − φ) too low for AR(1) noise) and a fast
    /// effect as noise; `noise` is the noise level proper.
    pub noise_std: f64,
    /// The noise level of the simulation residual y − ŷ over its scored samples: σ̂ of the
    /// output noise, coloured or not ([`noise_level_coloured`]). Every model's residual holds
    /// the same noise plus its own error, so the smallest of these over the models tried is
    /// the workflow's noise level ([`crate::discover::Discovery::noise`]).
    pub noise: NoiseFit,
    /// The portmanteau tests.
    pub tests: Vec<Portmanteau>,
    /// Time windows where ε exceeds its band.
    pub windows: Vec<Range<usize>>,
    /// Operating regions, best first.
    pub regions: Vec<Region>,
    /// Whether a missing effect was detected.
    pub missing_effect: bool,
    /// The lattice the measured output sits on, when the tests pass and it does
    /// ([`output_lattice`]): the gap is then a quantiser's, not noise.
    pub lattice: Option<Lattice>,
    /// The verdict in words, with the statistics behind it.
    pub verdict: String,
    /// Each record's simulation RMS and fit (one entry for a record of its own; see
    /// [`Data::from_records`]), in the order of the records.
    pub records: Vec<RecordGap>,
}

/// A residual sample whose departure from the mean of its two neighbours exceeds this many
/// noise levels σ̂ is an isolated spike ([`Gap::bulk_rms`]). For white noise that second
/// difference has standard deviation 1.22·σ̂, so an excursion beyond 6·σ̂ is a 4.9-sigma
/// event, about one sample in a million. A model error seen through a dynamic G moves the
/// residual smoothly from sample to sample and leaves none; one that acts after G (a coarse
/// sensor quantiser) can jump, and is only left out where it jumps alone, a single sample
/// against both neighbours.
pub const SPIKE: f64 = 6.0;

impl Gap {
    /// The RMS of the residual at its scored samples without its isolated spikes (samples
    /// beyond [`SPIKE`]·`noise_std` from the mean of their neighbours, and further than either
    /// neighbour is from its own: outliers of the measurement, not a missing dynamic effect),
    /// and how many were left out.
    ///
    /// ```
    /// use structid_discover::gap::Gap;
    /// let mut r: Vec<f64> = (0..200).map(|k| 0.01 * (0.3 * k as f64).sin()).collect();
    /// r[50] += 1.0;
    /// let (bulk, spikes) = Gap::bulk_rms_of(&r, &[0..200], 0.01);
    /// assert_eq!(spikes, 1);
    /// assert!(bulk < 0.01);
    /// ```
    pub fn bulk_rms(&self, noise_std: f64) -> (f64, usize) {
        Self::bulk_rms_of(&self.residual, &self.scored, noise_std)
    }

    /// [`Gap::bulk_rms`] of a residual `residual` scored over `scored`.
    pub fn bulk_rms_of(residual: &[f64], scored: &[Range<usize>], noise_std: f64) -> (f64, usize) {
        // Neighbours within the same scored range only: records and windows restart there.
        let departure = |range: &Range<usize>, k: usize| {
            if k > range.start && k + 1 < range.end.min(residual.len()) {
                (residual[k] - 0.5 * (residual[k - 1] + residual[k + 1])).abs()
            } else {
                0.0
            }
        };
        // An outlier's neighbours depart from their own neighbours by half of it: the spike
        // is the sample that departs most.
        let spike = |range: &Range<usize>, k: usize| {
            let d = departure(range, k);
            d > SPIKE * noise_std
                && d > departure(range, k.saturating_sub(1))
                && d >= departure(range, k + 1)
        };
        let (mut sum, mut n, mut spikes) = (0.0, 0usize, 0usize);
        for (range, k) in scored.iter().flat_map(|r| r.clone().map(move |k| (r, k))) {
            if spike(range, k) {
                spikes += 1;
            } else {
                sum += residual[k] * residual[k];
                n += 1;
            }
        }
        ((sum / n.max(1) as f64).sqrt(), spikes)
    }
}

/// One record's part of a [`Gap`] over several records.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RecordGap {
    /// The record's simulation RMS over its scored samples.
    pub rms: f64,
    /// The record's fit in percent.
    pub fit_percent: f64,
    /// How many of its samples are scored.
    pub samples: usize,
}

/// The one-step prediction errors of an AR(`order`) model of `s` fitted by least squares
/// (zeros over the first `order` samples): `s` made white, so that its correlations with a
/// white ε are independent across lags.
fn prewhiten(s: &[f64], order: usize) -> Vec<f64> {
    let n = s.len();
    let mean = s.iter().sum::<f64>() / n.max(1) as f64;
    let c: Vec<f64> = s.iter().map(|v| v - mean).collect();
    if n <= 2 * order + 1 || order == 0 {
        return c;
    }
    let rows = n - order;
    let a = nalgebra::DMatrix::from_fn(rows, order, |r, j| c[r + order - 1 - j]);
    let b = nalgebra::DVector::from_fn(rows, |r, _| c[r + order]);
    let svd = a.svd(true, true);
    let tol = 1e-10 * svd.singular_values.max();
    let Ok(phi) = svd.solve(&b, tol) else {
        return c;
    };
    let mut out = vec![0.0; n];
    for k in order..n {
        out[k] = c[k] - (0..order).map(|j| phi[j] * c[k - 1 - j]).sum::<f64>();
    }
    out
}

/// N·Σ_τ r²(ε_k, s_w,(k−τ)) over τ = `first_lag`…max_lag with s prewhitened: χ² with that
/// many degrees of freedom when ε is white and independent of the past of s.
///
/// Only the lags at which s leads ε are tested: a missing effect acts from the input to the
/// output, while in closed loop the input follows the output's noise through the controller,
/// so that ε correlates with the *future* input of a perfect model, and with the present one
/// when the controller reads the sample it acts on (`first_lag` = 1 for a strictly proper
/// model, whose output does not see the present input).
fn portmanteau_cross(
    name: String,
    e: &[f64],
    s: &[f64],
    first_lag: usize,
    max_lag: usize,
) -> Portmanteau {
    let sw = prewhiten(s, 10.min(s.len() / 20));
    let c = cross_correlation(e, &sw, max_lag);
    let n = e.len() as f64;
    let causal: Vec<f64> = c
        .lags
        .iter()
        .zip(&c.values)
        .filter(|(lag, _)| **lag >= first_lag as isize)
        .map(|(_, v)| *v)
        .collect();
    let statistic = n * causal.iter().map(|v| v * v).sum::<f64>();
    Portmanteau {
        name,
        statistic,
        critical: f64::NAN,
        lags: causal.len(),
    }
}

/// Examines the gap between `model` (with `maps`, one per block) and `data`; `candidates` are
/// the signals (name, samples) to localise it in. See the [module documentation](self).
///
/// Data of several records ([`Data::from_records`]) are examined record by record, each
/// simulated from its own initial state (and in its own windows), and pooled: the RMS and fit
/// over every record's scored samples, the noise levels from differences within records, each
/// portmanteau statistic summed over the records (χ² with the summed degrees of freedom, the
/// records being independent), the time windows found in each record, and the operating
/// regions over all samples. No lag or difference pairs samples of two records.
/// [`Gap::records`] holds each record's RMS and fit.
pub fn gap(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    candidates: &[(String, Vec<f64>)],
    settings: &GapSettings,
) -> Result<Gap> {
    if data.record_count() == 1 {
        return Ok(gap_record(model, maps, data, candidates, settings)?.gap);
    }
    let bounds = data.record_bounds();
    let mut parts = Vec::with_capacity(data.record_count());
    for (r, record) in data.records().iter().enumerate() {
        let slice: Vec<(String, Vec<f64>)> = candidates
            .iter()
            .map(|(name, s)| {
                let cut = crate::records::parts(s, bounds);
                (name.clone(), cut[r].to_vec())
            })
            .collect();
        parts.push(
            gap_record(model, maps, record, &slice, settings)
                .map_err(|e| crate::records::in_record(e, r, data))?,
        );
    }
    Ok(pool(parts, data, candidates, settings))
}

/// One record's gap, with what pooling over records needs.
struct RecordPart {
    gap: Gap,
    /// The tested innovations (see [`gap_record`]).
    innovations: Vec<f64>,
    /// The scored samples of the simulation.
    scored: Vec<Range<usize>>,
}

/// The gaps of several records (`parts`, in the order of `data`'s records) as one.
fn pool(
    parts: Vec<RecordPart>,
    data: &Data,
    candidates: &[(String, Vec<f64>)],
    settings: &GapSettings,
) -> Gap {
    let bounds = data.record_bounds();
    let y = data.y().channel(0);
    let residual: Vec<f64> = parts.iter().flat_map(|p| p.gap.residual.clone()).collect();
    let simulated: Vec<f64> = parts.iter().flat_map(|p| p.gap.simulated.clone()).collect();
    let scored: Vec<Range<usize>> = parts
        .iter()
        .zip(bounds)
        .flat_map(|(p, &b)| p.scored.iter().map(move |r| r.start + b..r.end + b))
        .collect();
    let mut pooled = structid_core::validation::metrics::PooledFit::default();
    pooled.add_ranges(&y, &simulated, &scored);
    let (rms, fit_percent) = (pooled.rms(), pooled.fit_percent());
    let floor = quantisation_floor(&y);
    let innovations: Vec<&[f64]> = parts.iter().map(|p| p.innovations.as_slice()).collect();
    let noise_std = noise_level_records(&innovations).max(floor);
    let scored_residual: Vec<Vec<f64>> = parts
        .iter()
        .map(|p| {
            p.scored
                .iter()
                .flat_map(|r| r.clone())
                .map(|k| p.gap.residual[k])
                .collect()
        })
        .collect();
    let scored_parts: Vec<&[f64]> = scored_residual.iter().map(Vec::as_slice).collect();
    let mut noise = noise_level_coloured_records(&scored_parts);
    noise.std = noise.std.max(floor);
    let all: Vec<f64> = innovations.concat();
    let prediction_rms = structid_core::validation::metrics::rms(&all);
    // Each statistic summed over the records, with its degrees of freedom.
    let mut tests: Vec<Portmanteau> = parts[0].gap.tests.clone();
    for p in &parts[1..] {
        for (t, o) in tests.iter_mut().zip(&p.gap.tests) {
            t.statistic += o.statistic;
            t.lags += o.lags;
        }
    }
    let mut windows = Vec::new();
    for (p, &b) in parts.iter().zip(bounds) {
        let window = settings
            .window
            .unwrap_or((p.innovations.len() / 50).max(20));
        windows.extend(
            exceedance_windows(&p.gap.residual, noise_std, settings.band, window)
                .into_iter()
                .map(|r| r.start + b..r.end + b),
        );
    }
    let y_parts = crate::records::parts(&y, bounds);
    let measured = Measured {
        records: parts.into_iter().flat_map(|p| p.gap.records).collect(),
        residual,
        simulated,
        rms,
        scored,
        prediction_rms,
        fit_percent,
        noise_std,
        noise,
        tests,
        windows,
    };
    judge(measured, &y_parts, candidates, settings)
}

/// What a gap measures before its verdict, on one record or pooled over several (the fields
/// of [`Gap`] with the same names).
struct Measured {
    residual: Vec<f64>,
    simulated: Vec<f64>,
    rms: f64,
    scored: Vec<Range<usize>>,
    prediction_rms: f64,
    fit_percent: f64,
    noise_std: f64,
    noise: NoiseFit,
    tests: Vec<Portmanteau>,
    windows: Vec<Range<usize>>,
    records: Vec<RecordGap>,
}

/// The gap of what was `measured`: the operating regions where its residual concentrates
/// among the `candidates`, and the tests' verdict on the outputs `y_parts` (one per record).
fn judge(
    measured: Measured,
    y_parts: &[&[f64]],
    candidates: &[(String, Vec<f64>)],
    settings: &GapSettings,
) -> Gap {
    let m = measured;
    let signals: Vec<(&str, &[f64])> = candidates
        .iter()
        .map(|(name, s)| (name.as_str(), s.as_slice()))
        .collect();
    let regions = operating_regions(&m.residual, &signals, settings.min_region_share);
    let verdict = conclude(m.tests, m.prediction_rms, m.noise_std, y_parts, settings);
    Gap {
        residual: m.residual,
        simulated: m.simulated,
        rms: m.rms,
        scored: m.scored,
        prediction_rms: m.prediction_rms,
        fit_percent: m.fit_percent,
        noise_std: m.noise_std,
        noise: m.noise,
        tests: verdict.tests,
        windows: m.windows,
        regions,
        missing_effect: verdict.missing_effect,
        lattice: verdict.lattice,
        verdict: verdict.text,
        records: m.records,
    }
}

/// A model's simulation on one record, as scored, and its one-step prediction error.
struct Run {
    simulated: Signal,
    scored: Vec<std::ops::Range<usize>>,
    rms: f64,
    fit_percent: f64,
    /// `None` for a model without a one-step predictor: maps in series, or a z that no
    /// filter of y recovers.
    prediction_error: Option<Vec<f64>>,
}

/// The [`Run`] of `model` on `data`. Maps in series are predicted from a record at rest
/// (their z computed from u, y and the maps upstream from a zero state, which an estimated
/// initial state would contradict); a model with no one-step predictor is only simulated.
fn run(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    settings: &GapSettings,
) -> Result<Run> {
    let validation = |initial_state| {
        ValidationSettings::builder()
            .initial_state(initial_state)
            .scoring(settings.scoring)
            .max_lag(settings.max_lag)
            .build()
    };
    for x0 in [settings.initial_state, InitialState::Zero] {
        match validate(model, maps, data, &validation(x0)?) {
            Ok(v) => {
                return Ok(Run {
                    rms: v.rms[0],
                    fit_percent: v.fit_percent[0],
                    prediction_error: Some(v.prediction_error.channel(0)),
                    simulated: v.simulated,
                    scored: v.scored,
                });
            }
            Err(e) if !e.beyond_measurability() => return Err(e),
            Err(_) => {}
        }
    }
    let settle = validation(InitialState::Zero)?.settle();
    let sim = simulate_scored(model, maps, data, settings.scoring, None, settle)?;
    Ok(Run {
        rms: sim.rms(data.y(), 0),
        fit_percent: sim.fit_percent(data.y(), 0),
        prediction_error: None,
        simulated: sim.simulated,
        scored: sim.scored,
    })
}

/// The gap of one record, with its innovations and scored samples.
fn gap_record(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    candidates: &[(String, Vec<f64>)],
    settings: &GapSettings,
) -> Result<RecordPart> {
    let v = run(model, maps, data, settings)?;
    let y = data.y().channel(0);
    let simulated = v.simulated.channel(0);
    let residual: Vec<f64> = y.iter().zip(&simulated).map(|(a, b)| a - b).collect();
    // Without a noise model (output error), the one-step prediction error is the free-run
    // simulation error, which drifts for a model with integrators; the tests then run on the
    // windowed simulation residual at its scored samples instead, as they do for a model
    // without a one-step predictor.
    let one_step =
        !matches!(settings.scoring, Scoring::Windowed(_)) || model.lft().t_ye().order() != 0;
    let tested: Vec<usize> = match &v.prediction_error {
        Some(_) if one_step => (0..residual.len()).collect(),
        _ => v.scored.iter().flat_map(|r| r.clone()).collect(),
    };
    let mut innovations: Vec<f64> = match &v.prediction_error {
        Some(e) if one_step => e.clone(),
        _ => tested.iter().map(|&k| residual[k]).collect(),
    };
    let n = innovations.len();
    // Without a one-step predictor, a model whose noise model colours its residual is judged
    // on that residual prewhitened, so that the colour it explains is not taken for a missing
    // effect (as its innovations would be).
    if v.prediction_error.is_none() && model.lft().t_ye().order() != 0 {
        innovations = prewhiten(&innovations, 10.min(n / 20));
    }
    // A quantised output (few distinct values) makes most differences exactly zero and the
    // MAD collapse; the quantisation error q/√12 is a floor for the noise level.
    let floor = quantisation_floor(&y);
    let noise_std = noise_level(&innovations).max(floor);
    let scored: Vec<f64> = v
        .scored
        .iter()
        .flat_map(|r| r.clone())
        .map(|k| residual[k])
        .collect();
    let mut noise = noise_level_coloured(&scored);
    noise.std = noise.std.max(floor);
    let max_lag = settings.max_lag.min(n.saturating_sub(1)).max(1);

    // Ljung–Box on the residual's autocorrelation.
    let auto = autocorrelation(&innovations, max_lag);
    let nf = n as f64;
    let q: f64 = auto
        .lags
        .iter()
        .zip(&auto.values)
        .filter(|(l, _)| **l > 0)
        .map(|(l, r)| r * r / (nf - *l as f64))
        .sum::<f64>()
        * nf
        * (nf + 2.0);
    let mut tests = vec![Portmanteau {
        name: "whiteness of ε (Ljung–Box)".into(),
        statistic: q,
        critical: f64::NAN,
        lags: max_lag,
    }];
    let centred_square = |s: &[f64]| {
        let m = s.iter().map(|v| v * v).sum::<f64>() / s.len() as f64;
        s.iter().map(|v| v * v - m).collect::<Vec<f64>>()
    };
    // An output-error residual may be coloured noise; its cross-correlations with a
    // prewhitened input then have the χ² null distribution only if it is prewhitened too (the
    // double prewhitening of Haugh's test). A residual the input predicts stays correlated
    // with it through any fixed filter.
    let whitened;
    let crossed: &[f64] = if model.lft().t_ye().order() == 0 {
        whitened = prewhiten(&innovations, 10.min(n / 20));
        &whitened
    } else {
        &innovations
    };
    let e2 = centred_square(crossed);
    let first_lag = usize::from(model.lft().matrices().dyu.iter().all(|d| *d == 0.0));
    for c in 0..data.u().channels() {
        let u: Vec<f64> = tested.iter().map(|&k| data.u().get(k, c)).collect();
        let u2 = centred_square(&u);
        tests.push(portmanteau_cross(
            format!("ε against u{c}"),
            crossed,
            &u,
            first_lag,
            max_lag,
        ));
        tests.push(portmanteau_cross(
            format!("ε against u{c}²"),
            crossed,
            &u2,
            first_lag,
            max_lag,
        ));
        tests.push(portmanteau_cross(
            format!("ε² against u{c}²"),
            &e2,
            &u2,
            first_lag,
            max_lag,
        ));
    }
    let window = settings.window.unwrap_or((n / 50).max(20));
    let windows = exceedance_windows(&residual, noise_std, settings.band, window);
    let measured = Measured {
        records: vec![RecordGap {
            rms: v.rms,
            fit_percent: v.fit_percent,
            samples: v.scored.iter().map(|r| r.len()).sum(),
        }],
        residual,
        simulated,
        rms: v.rms,
        scored: v.scored.clone(),
        prediction_rms: structid_core::validation::metrics::rms(&innovations),
        fit_percent: v.fit_percent,
        noise_std,
        noise,
        tests,
        windows,
    };
    let gap = judge(measured, &[&y], candidates, settings);
    Ok(RecordPart {
        gap,
        innovations,
        scored: v.scored,
    })
}

/// What the tests conclude: the tests with their critical values, whether an effect is
/// missing, the output's lattice, and the verdict in words.
struct Conclusion {
    tests: Vec<Portmanteau>,
    missing_effect: bool,
    lattice: Option<Lattice>,
    text: String,
}

/// The verdict of the portmanteau `tests` (statistics and degrees of freedom), RMS(ε) =
/// `prediction_rms` against the noise level `noise_std`, and the lattice of the measured
/// output (`y`, one slice per record).
fn conclude(
    mut tests: Vec<Portmanteau>,
    prediction_rms: f64,
    noise_std: f64,
    y: &[&[f64]],
    settings: &GapSettings,
) -> Conclusion {
    // Bonferroni: each test at 0.1 %/m, so that a correct model fails any of them 0.1 % of the
    // time. A missing effect worth naming moves these statistics far beyond that.
    let level = 1.0 - 0.001 / tests.len() as f64;
    for t in &mut tests {
        t.critical = chi_square_quantile(level, t.lags);
    }
    let too_large = prediction_rms > settings.noise_ratio * noise_std;
    let failing: Vec<&Portmanteau> = tests.iter().filter(|t| !t.passes()).collect();
    // A quantiser's error passes every test as noise; its lattice shows it.
    let lattice = if too_large || !failing.is_empty() {
        None
    } else {
        output_lattice_records(y)
    };
    let missing_effect = too_large || !failing.is_empty() || lattice.is_some();
    let verdict = if missing_effect {
        let mut why: Vec<String> = failing
            .iter()
            .map(|t| format!("{} = {:.1} > {:.1}", t.name, t.statistic, t.critical))
            .collect();
        if let Some(l) = &lattice {
            why.push(format!(
                "the output sits on a lattice of step {:.4e} (coherence {:.2} over {} changes): \
                 a quantised sensor, whose error passes the tests as noise",
                l.step, l.coherence, l.changes
            ));
        }
        if too_large {
            why.insert(
                0,
                format!(
                    "RMS(ε) = {prediction_rms:.4e} is {:.1}× the noise level σ̂ = {noise_std:.4e}",
                    prediction_rms / noise_std.max(f64::MIN_POSITIVE)
                ),
            );
        }
        format!("missing effect: {}", why.join("; "))
    } else {
        format!(
            "no missing effect detected: RMS(ε) = {prediction_rms:.4e} within {}× σ̂ = {noise_std:.4e}, and ε \
             passes the whiteness and (non)linear input-correlation tests at the 0.1 % level",
            settings.noise_ratio
        )
    };
    Conclusion {
        tests,
        missing_effect,
        lattice,
        text: verdict,
    }
}

/// A validation shrink in words, with `digits` decimals: "3.2× smaller", or for a model that
/// validates worse than the nominal "1.16× larger" (never "0.9× smaller").
///
/// ```
/// use structid_discover::gap::shrink_text;
/// assert_eq!(shrink_text(3.21, 1), "3.2× smaller");
/// assert_eq!(shrink_text(0.8, 2), "1.25× larger");
/// assert_eq!(shrink_text(f64::NAN, 1), "NaN× smaller");
/// ```
pub fn shrink_text(shrink: f64, digits: usize) -> String {
    if shrink < 1.0 && shrink > 0.0 {
        format!("{:.digits$}× larger", 1.0 / shrink)
    } else {
        format!("{shrink:.digits$}× smaller")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};
    use structid_core::{Lft, LftMatrices, Signal};

    #[test]
    fn a_smooth_model_error_has_no_spikes_and_outliers_are_the_spikes() {
        // A model error seen through G: large, but smooth from sample to sample.
        let smooth: Vec<f64> = (0..2000).map(|k| 20.0 * (0.05 * k as f64).sin()).collect();
        let all: Vec<Range<usize>> = std::iter::once(0..2000).collect();
        let (bulk, spikes) = Gap::bulk_rms_of(&smooth, &all, 1.0);
        assert_eq!(spikes, 0);
        assert!((bulk - structid_core::validation::metrics::rms(&smooth)).abs() < 1e-12);
        // Outliers of ten noise levels on a small residual are exactly the spikes, and the
        // bulk RMS is that of the rest.
        let mut r: Vec<f64> = (0..2000).map(|k| 0.5 * (0.9 * k as f64).cos()).collect();
        let clean = structid_core::validation::metrics::rms(&r);
        for k in (100..2000).step_by(300) {
            r[k] += if k % 600 == 100 { 10.0 } else { -10.0 };
        }
        let (bulk, spikes) = Gap::bulk_rms_of(&r, &all, 1.0);
        assert_eq!(spikes, 7);
        assert!(
            (bulk - clean).abs() < 0.01 * clean,
            "{bulk} against {clean}"
        );
        assert!(structid_core::validation::metrics::rms(&r) > 1.5 * clean);
        // Only the scored samples count.
        let (_, scored_spikes) = Gap::bulk_rms_of(&r, std::slice::from_ref(&(0..1000)), 1.0);
        assert_eq!(scored_spikes, 3);
    }

    /// A slow multisine of amplitude 1, quantised to `step` (none for 0), plus white noise.
    fn sensed(step: f64, noise: f64, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let n = Normal::new(0.0, noise.max(1e-300)).unwrap();
        (0..5000)
            .map(|k| {
                let t = k as f64 * 0.01;
                let x = 0.6 * (0.7 * t).sin() + 0.4 * (1.9 * t + 1.0).sin();
                let q = if step > 0.0 {
                    (x / step).round() * step
                } else {
                    x
                };
                q + n.sample(&mut rng)
            })
            .collect()
    }

    #[test]
    fn a_quantised_output_is_found_with_its_step() {
        for (step, noise) in [(0.05, 0.0), (0.05, 0.004), (0.013, 0.001), (0.08, 0.006)] {
            let l = output_lattice(&sensed(step, noise, 1))
                .unwrap_or_else(|| panic!("step {step}, noise {noise}: no lattice"));
            assert!(
                (l.step - step).abs() < 0.03 * step,
                "step {step}, noise {noise}: {l:?}"
            );
            // the coherence is about exp(−4π²σ²/q²) for noise σ after the quantiser
            let expected =
                (-4.0 * std::f64::consts::PI.powi(2) * noise * noise / (step * step)).exp();
            assert!((l.coherence - expected).abs() < 0.08, "{l:?} vs {expected}");
        }
    }

    #[test]
    fn continuous_outputs_sit_on_no_lattice() {
        // continuous, noisy or not
        for noise in [0.0, 1e-4, 0.01] {
            assert_eq!(
                output_lattice(&sensed(0.0, noise, 2)),
                None,
                "noise {noise}"
            );
        }
        // noise coarser than the step hides the lattice (the quantiser is then part of the
        // noise)
        assert_eq!(output_lattice(&sensed(0.01, 0.01, 3)), None);
        // an axis dwelling at a few set points, moving continuously between them
        let mut rng = StdRng::seed_from_u64(4);
        let n = Normal::new(0.0, 1e-3).unwrap();
        let targets = [0.0, 0.37, -0.52, 0.81, 0.13, -0.29];
        let mut y = Vec::new();
        let mut x = 0.0_f64;
        for target in targets.iter().cycle().take(24) {
            for _ in 0..250 {
                x += 0.05 * (target - x);
                y.push(x + n.sample(&mut rng));
            }
        }
        assert_eq!(output_lattice(&y), None);
        // constant and empty records
        assert_eq!(output_lattice(&[1.0; 100]), None);
        assert_eq!(output_lattice(&[]), None);
    }

    /// y = G·u + e with G = 0.5q⁻¹/(1 − 0.8q⁻¹), no map.
    fn nominal() -> Model {
        let lft = Lft::new(LftMatrices {
            a: dmatrix![0.8],
            bu: dmatrix![0.5],
            be: dmatrix![0.0],
            bw: nalgebra::DMatrix::zeros(1, 0),
            cy: dmatrix![1.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: nalgebra::DMatrix::zeros(1, 0),
            cz: nalgebra::DMatrix::zeros(0, 1),
            dzu: nalgebra::DMatrix::zeros(0, 1),
            dze: nalgebra::DMatrix::zeros(0, 1),
            dzw: nalgebra::DMatrix::zeros(0, 0),
        })
        .unwrap();
        Model::new(lft, vec![]).unwrap()
    }

    fn record(seed: u64, effect: Option<fn(f64) -> f64>) -> Data {
        let mut rng = StdRng::seed_from_u64(seed);
        let n = Normal::new(0.0, 1.0).unwrap();
        let mut s = 0.0;
        let u = Signal::from_fn(2000, 1, |_, _| {
            s = 0.6 * s + 0.8 * n.sample(&mut rng);
            s
        });
        // The true system: the nominal one, with an input map when `effect` is given.
        let v = match effect {
            Some(f) => Signal::from_fn(u.len(), 1, |k, _| f(u.get(k, 0))),
            None => u.clone(),
        };
        let y0 = nominal().lft().simulate(&[], &v, None, None).unwrap().y;
        let noise = Normal::new(0.0, 0.05).unwrap();
        let y = Signal::from_fn(u.len(), 1, |k, _| y0.get(k, 0) + noise.sample(&mut rng));
        Data::new(u, y).unwrap()
    }

    fn candidates(d: &Data) -> Vec<(String, Vec<f64>)> {
        vec![
            ("u".into(), d.u().channel(0)),
            ("y".into(), d.y().channel(0)),
        ]
    }

    /// The gap of `model` on `d` with u and y as candidates and default settings.
    fn gap_of(model: &Model, maps: &[&dyn Interpolant], d: &Data) -> Gap {
        gap(model, maps, d, &candidates(d), &GapSettings::default()).unwrap()
    }

    #[test]
    fn the_noise_level_of_white_noise_is_its_standard_deviation() {
        let mut rng = StdRng::seed_from_u64(5);
        let n = Normal::new(0.0, 0.3).unwrap();
        let e: Vec<f64> = (0..20000).map(|_| n.sample(&mut rng)).collect();
        assert!((noise_level(&e) - 0.3).abs() < 0.01, "{}", noise_level(&e));
    }

    /// White noise plus a slow model error: the error's variogram grows as k² over the fitted
    /// lags and is taken for drift, not noise, where the residual's own RMS is three times σ.
    /// AR(1) noise of φ = 0.6 and 0.9: σ̂ is the std of the process, where the first
    /// difference gives σ·√(1 − φ).
    #[test]
    fn the_coloured_noise_level_separates_noise_colour_and_slow_errors() {
        let mut rng = StdRng::seed_from_u64(17);
        let n = Normal::new(0.0, 1.0).unwrap();
        let e: Vec<f64> = (0..5000).map(|_| 0.1 * n.sample(&mut rng)).collect();
        let r: Vec<f64> = e
            .iter()
            .enumerate()
            .map(|(k, v)| v + 0.4 * (0.01 * k as f64).sin())
            .collect();
        assert!(structid_core::validation::metrics::rms(&r) > 2.5 * 0.1);
        let fit = noise_level_coloured(&r);
        assert!((fit.std - 0.1).abs() < 0.01, "{fit:?}");
        assert!(fit.drift > 0.0, "{fit:?}");
        for phi in [0.6, 0.9] {
            let mut x = 0.0;
            let ar: Vec<f64> = (0..20000)
                .map(|_| {
                    x = phi * x + (1.0f64 - phi * phi).sqrt() * 0.2 * n.sample(&mut rng);
                    x
                })
                .collect();
            let fit = noise_level_coloured(&ar);
            assert!((fit.std - 0.2).abs() < 0.02, "φ = {phi}: {fit:?}");
            assert!((fit.colour - phi).abs() < 0.06, "φ = {phi}: {fit:?}");
            let difference = noise_level(&ar);
            assert!(
                (difference - 0.2 * (1.0 - phi).sqrt()).abs() < 0.02,
                "φ = {phi}: {difference}"
            );
        }
    }

    #[test]
    fn the_true_linear_model_leaves_no_missing_effect() {
        let mut flagged = 0;
        for seed in 0..20 {
            let d = record(seed, None);
            let g = gap_of(&nominal(), &[], &d);
            assert!((g.noise_std - 0.05).abs() < 0.01, "σ̂ = {}", g.noise_std);
            if g.missing_effect {
                flagged += 1;
            }
        }
        // The tests together err 0.1 % of the time, plus the RMS criterion: at most 1 of 20.
        assert!(flagged <= 1, "{flagged} of 20 correct models flagged");
    }

    #[test]
    fn a_hidden_saturation_is_detected_and_localised_at_large_inputs() {
        let sat: fn(f64) -> f64 = |u| u.clamp(-1.0, 1.0);
        let d = record(7, Some(sat));
        let g = gap_of(&nominal(), &[], &d);
        assert!(g.missing_effect, "{}", g.verdict);
        let best = &g.regions[0];
        assert!(best.lift > 2.0, "{best:?}");
        assert!(
            matches!(
                best.side,
                crate::localise::Side::OutsideMagnitude
                    | crate::localise::Side::Above
                    | crate::localise::Side::Below
            ),
            "{best:?}"
        );
        assert!(!g.windows.is_empty());
    }

    #[test]
    fn an_even_nonlinearity_is_seen_by_the_nonlinear_correlation_tests() {
        // u + 0.3u²: the square leaves ε uncorrelated with u itself (u is symmetric).
        let even: fn(f64) -> f64 = |u| u + 0.3 * u * u;
        let d = record(3, Some(even));
        let g = gap_of(&nominal(), &[], &d);
        let t = g.tests.iter().find(|t| t.name == "ε against u0²").unwrap();
        assert!(!t.passes(), "{t:?}");
        assert!(g.missing_effect);
    }

    #[test]
    fn maps_in_the_loop_are_used() {
        // With the map that generated the data in the model, the gap closes again.
        let sat = |z: &[f64]| z[0].clamp(-1.0, 1.0);
        let d = record(11, Some(|u| u.clamp(-1.0, 1.0)));
        let lft = Lft::new(LftMatrices {
            a: dmatrix![0.8],
            bu: dmatrix![0.0],
            be: dmatrix![0.0],
            bw: dmatrix![0.5],
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
        let block = structid_core::NonlinearBlock::new(
            "N",
            vec![0],
            0,
            std::sync::Arc::new(structid_core::KernelDispersion::gaussian(0.3).unwrap()),
        );
        let model = Model::new(lft, vec![block]).unwrap();
        let g = gap_of(&model, &[&sat], &d);
        // The residual is the noise (std 0.05) alone.
        assert!(g.rms < 0.055 && g.rms < 1.2 * g.noise_std, "{}", g.verdict);
        let without = gap_of(&nominal(), &[], &d);
        assert!(without.rms > 2.0 * g.rms && without.missing_effect);
    }
}

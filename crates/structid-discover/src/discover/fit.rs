//! Identifying one hypothesis: records and stability checks, the quadratic dispersion, the
//! initial state and simulation RMS of a location, and the fit with its estimates.

use std::sync::Arc;
use std::time::Instant;

use structid_core::selection::{Criterion, SelectionSettings, select};
use structid_core::validation::{Scoring, ValidationSettings, Windows};
use structid_core::{
    Data, Dispersion, Error, IdentifySettings, InitialState, Interpolant, PolynomialDispersion,
    Result, Signal,
};
use structid_io::{DispersionSpec, IoError};

use crate::hypotheses::{Hypothesis, Nominal, Site};

use super::{DiscoverSettings, HypothesisResult, MapCurve};

/// The candidate signals for localisation: u, y, their rates, and the simulated linear output
/// (stacked like `data`'s records; each record's rates start at 0).
pub fn candidate_signals(data: &Data, linear_output: &[f64], ts: f64) -> Vec<(String, Vec<f64>)> {
    let starts = data.record_bounds();
    let rate = |s: &[f64]| -> Vec<f64> {
        (0..s.len())
            .map(|k| {
                if starts.contains(&k) {
                    0.0
                } else {
                    (s[k] - s[k - 1]) / ts
                }
            })
            .collect()
    };
    let u = data.u().channel(0);
    let y = data.y().channel(0);
    vec![
        ("u".to_string(), u.clone()),
        ("y".to_string(), y.clone()),
        ("du/dt".to_string(), rate(&u)),
        ("dy/dt".to_string(), rate(&y)),
        (
            "G·u (simulated linear output)".to_string(),
            linear_output.to_vec(),
        ),
    ]
}

/// The checks of every record of the estimation and validation data: one input and one
/// output, an input that is not constant, and at least 100 samples (naming the record when
/// there are several).
pub(super) fn check_records(est: &Data, val: &Data) -> Result<()> {
    for (set, data) in [("estimation", est), ("validation", val)] {
        for (r, d) in data.records().iter().enumerate() {
            let what = if data.record_count() == 1 {
                format!("the {set} record")
            } else {
                format!("{set} record {} (of {})", r + 1, data.record_count())
            };
            check_record(&what, d)?;
        }
    }
    Ok(())
}

/// [`check_records`] of one record, `what` naming it.
fn check_record(what: &str, d: &Data) -> Result<()> {
    if d.u().channels() != 1 || d.y().channels() != 1 {
        return Err(Error::DimensionMismatch {
            what: format!("channels of {what}"),
            expected: "one input u and one output y".into(),
            found: format!(
                "{} input(s) and {} output(s)",
                d.u().channels(),
                d.y().channels()
            ),
        });
    }
    let u = d.u().channel(0);
    let mean = u.iter().sum::<f64>() / u.len().max(1) as f64;
    let var = u.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / u.len().max(1) as f64;
    if var <= 1e-20 * mean.powi(2).max(f64::MIN_POSITIVE) {
        return Err(Error::InvalidParameter {
            name: format!("input of {what}"),
            value: mean,
            reason: "u is constant: a record without excitation cannot show what the \
                     model is missing"
                .into(),
        });
    }
    if d.u().len() < 100 {
        return Err(Error::InvalidParameter {
            name: format!("length of {what}"),
            value: d.u().len() as f64,
            reason: "discovery needs at least 100 samples per record".into(),
        });
    }
    Ok(())
}

/// A nominal model whose simulation from u diverges cannot be compared with data: its poles
/// must lie inside the unit circle.
/// The scoring of every simulation in the workflow: the user's, or chosen from the nominal
/// model's poles. A pole on or within 10⁻³ of the unit circle (an integrator: a position from a
/// force, a level from a flow) makes a free-run simulation drift with any offset or error in
/// the first state, so the record is scored in windows, each from a state fitted to its first
/// half; a stable model gets one free run. A pole further outside is an error: even a
/// window's simulation would diverge.
pub(super) fn resolve_scoring(
    nominal: &Nominal,
    est: &Data,
    settings: &DiscoverSettings,
) -> Result<Scoring> {
    let a = &nominal.lft().matrices().a;
    let radius = if a.nrows() == 0 {
        0.0
    } else {
        a.complex_eigenvalues()
            .iter()
            .map(|l| l.norm())
            .fold(0.0, f64::max)
    };
    if radius.is_nan() || radius > 1.0 + MARGINAL {
        return Err(Error::InvalidStructure(format!(
            "the nominal model is unstable (spectral radius {radius:.6} > 1): its simulation \
             diverges even over a short window, so its gap to the data means nothing. If the \
             plant integrates (a position from a force), estimate it with its integrators held \
             at z = 1; otherwise re-estimate it by output error"
        )));
    }
    if let Some(s) = settings.scoring {
        return Ok(s);
    }
    Ok(if radius >= 1.0 - MARGINAL {
        // Two states more than the nominal: the rate's memory and a spare.
        // Every record is scored in windows of the same length, sized for the shortest.
        Scoring::Windowed(Windows::for_record(
            crate::records::shortest(est),
            a.nrows() + 2,
        ))
    } else {
        Scoring::Free
    })
}

/// Poles within this distance of the unit circle count as on it (integrators).
const MARGINAL: f64 = 1e-3;

/// The validation settings every simulation of hypothesis at `location` is scored with.
pub(super) fn scoring_settings(location: Site, settings: &DiscoverSettings) -> ValidationSettings {
    // Windows fit their own states; the record's x₀ is the free run's start and the one-step
    // predictor's.
    ValidationSettings::builder()
        .initial_state(initial_state(location).1)
        .settle(settings.settle)
        .scoring(settings.scoring.unwrap_or_default())
        .build()
        .unwrap_or_default()
}

pub(super) fn minmax(v: &[f64]) -> (f64, f64) {
    v.iter()
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
            (l.min(x), h.max(x))
        })
}

/// Weight λ of each normalised monomial of the trend in [`quadratic_dispersion_spec`].
///
/// The trend's monomials are normalised to the range; a weight of 10 keeps them nearly
/// unpenalised relative to the kernel, so the kernel only carries what they cannot.
pub const TREND_SCALE: f64 = 10.0;

/// The quadratic dispersion of every hypothesis, as a model file writes it: a Gaussian-like
/// Fourier kernel of width `sigma` plus, for `trend_degree` > 0, a polynomial trend of that
/// degree weighted [`TREND_SCALE`], so that the map extrapolates.
///
/// It is the one definition of discovery's dispersion: the hypotheses are identified with
/// what this spec builds, and the augmented model file carries it, so that `structid
/// identify` on that file re-estimates the map as discovery did.
///
/// ```
/// use structid_discover::discover::quadratic_dispersion_spec;
/// let spec = quadratic_dispersion_spec(Some(0.3), 3);
/// assert_eq!((spec.kind(), spec.sigma()), ("fourier", Some(0.3)));
/// assert!(spec.build(None, None).unwrap().describe().contains("polynomial"));
/// ```
pub fn quadratic_dispersion_spec(sigma: Option<f64>, trend_degree: usize) -> DispersionSpec {
    let kernel = DispersionSpec::Fourier {
        sigma,
        harmonics: None,
        additive: false,
    };
    if trend_degree == 0 {
        kernel
    } else {
        DispersionSpec::WithTrend {
            kernel: Box::new(kernel),
            degree: trend_degree,
            scale: Some(TREND_SCALE),
        }
    }
}

/// The quadratic dispersion of every hypothesis at σ = `fraction`·range(z)
/// ([`quadratic_dispersion_spec`]).
pub(super) fn quadratic_dispersion(
    range: f64,
    settings: &DiscoverSettings,
) -> Result<Arc<dyn Dispersion>> {
    let sigma = settings.sigma_fraction * range.max(f64::MIN_POSITIVE);
    quadratic_dispersion_spec(Some(sigma), settings.trend_degree)
        .build(None, None)
        .map_err(core_error)
}

/// A model-file error as a core one (building a dispersion fails only on invalid parameters,
/// which are core errors).
pub(crate) fn core_error(e: IoError) -> Error {
    match e {
        IoError::Core(e) => e,
        other => Error::InvalidStructure(other.to_string()),
    }
}

/// z of a hypothesis on a record (measured for the rate, computed otherwise).
pub(super) fn z_of(h: &Hypothesis, data: &Data) -> Result<Vec<f64>> {
    match data.z() {
        Some(z) => Ok(z.channel(0)),
        None => crate::records::stacked(data, |r| {
            match h.model.lft().compute_z(r.u(), r.y()) {
                Ok((z, _)) => Ok(z.channel(0)),
                // A sensor map behind a known actuator map reads the known map's output:
                // its z comes from the record through the LFT identification uses, which
                // takes the known maps' outputs as inputs.
                Err(e) if !h.known.is_empty() => h
                    .identification(r)
                    .and_then(|(model, id)| Ok(model.lft().compute_z(id.u(), id.y())?.0.channel(0)))
                    .map_err(|_| e),
                Err(e) => Err(e),
            }
        }),
    }
}

/// How the initial state is treated at `location` (in identification, and in a free-run
/// simulation): estimated, except for the sensor map, whose z = G·u would depend on an unknown
/// x₀ and no longer be measurable, so the record is taken to start at rest there. (The rate
/// is measured from y, and its memory of the previous output is fitted to it.)
///
/// ```
/// use structid_core::InitialState;
/// use structid_discover::discover::initial_state;
/// use structid_discover::hypotheses::Site;
/// assert_eq!(initial_state(Site::Input).1, InitialState::Estimate);
/// assert_eq!(initial_state(Site::Output).1, InitialState::Zero);
/// assert_eq!(initial_state(Site::RateFeedback).1, InitialState::Estimate);
/// ```
pub fn initial_state(location: Site) -> (InitialState, InitialState) {
    match location {
        Site::Output => (InitialState::Zero, InitialState::Zero),
        _ => (InitialState::Estimate, InitialState::Estimate),
    }
}

/// Simulation RMS of the hypothesis `h` with `map` in its unknown block (and its known maps)
/// on `data`, scored as every simulation of the workflow ([`scoring_settings`]); infinite when
/// the simulation fails or diverges.
pub(super) fn simulation_rms(
    h: &Hypothesis,
    map: &dyn Interpolant,
    data: &Data,
    settings: &DiscoverSettings,
) -> f64 {
    simulated(h, map, data, settings).map_or(f64::INFINITY, |v| v.rms)
}

/// The validation errors y − ŷ of `h` with `map` at the scored samples of every record of
/// `data`, records stacked (the rows of the candidate table, [`crate::table`]); empty when the
/// simulation failed or diverged.
pub(super) fn simulation_errors(
    h: &Hypothesis,
    map: &dyn Interpolant,
    data: &Data,
    settings: &DiscoverSettings,
) -> Vec<f64> {
    simulated(h, map, data, settings).map_or_else(Vec::new, |v| v.scored_residual())
}

/// The simulation of [`simulation_rms`] on every record of `data`, `None` when it fails or
/// diverges.
pub(super) fn simulated(
    h: &Hypothesis,
    map: &dyn Interpolant,
    data: &Data,
    settings: &DiscoverSettings,
) -> Option<crate::records::Simulated> {
    let settings = scoring_settings(h.location, settings);
    // A simulation that runs a million times beyond the output's size has diverged, even if
    // its numbers are still finite.
    let limit =
        1e6 * structid_core::validation::metrics::rms(&data.y().channel(0)).max(f64::MIN_POSITIVE);
    crate::records::simulate(&h.model, &h.maps(map), data, &settings)
        .ok()
        .filter(|v| v.rms.is_finite() && v.rms < limit)
}

/// [`simulation_rms`] with the noise level of the simulation residual over its scored
/// samples ([`crate::gap::noise_level_coloured`]), `None` when the simulation failed or
/// diverged.
pub(super) fn simulation_rms_and_noise(
    h: &Hypothesis,
    map: &dyn Interpolant,
    data: &Data,
    settings: &DiscoverSettings,
) -> (f64, Option<crate::gap::NoiseFit>) {
    match simulated(h, map, data, settings) {
        Some(v) => {
            let residual = v.scored_residual_parts(data.record_bounds());
            let parts: Vec<&[f64]> = residual.iter().map(Vec::as_slice).collect();
            (
                v.rms,
                Some(crate::gap::noise_level_coloured_records(&parts)),
            )
        }
        None => (f64::INFINITY, None),
    }
}

pub(super) fn even_indices(len: usize, max: usize) -> Vec<usize> {
    let step = len.div_ceil(max).max(1);
    (0..len).step_by(step).collect()
}

/// An identified hypothesis with the objects later steps need.
pub(super) struct Fitted {
    pub(super) result: HypothesisResult,
    pub(super) hypothesis: Hypothesis,
    pub(super) map: Box<dyn Interpolant>,
    pub(super) z: Vec<f64>,
    pub(super) w_hat: Vec<f64>,
    /// The noise estimate ê, every noise channel.
    pub(super) e_hat: Signal,
    /// Where each estimation record starts in `z`, `w_hat` and `e_hat`, then their length.
    pub(super) bounds: Vec<usize>,
    /// `quadratic` or `total variation`.
    pub(super) estimator: &'static str,
    /// The noise level of its simulation residual on the estimation record.
    pub(super) residual_noise: Option<crate::gap::NoiseFit>,
    /// Whether the map validated better held at its edge values outside the estimation range
    /// than extrapolated as estimated (its validation RMS is the better of the two).
    pub(super) hold_edges: bool,
    /// G re-estimated jointly with the map ([`super::refine::refine_jointly`]), when that
    /// helped; `None` when the hypothesis is identified around the nominal model's G.
    pub(super) linear: Option<JointLinear>,
    /// Its direction test, once computed.
    pub(super) direction: Option<crate::hysteresis::DirectionTest>,
    /// The ratio of the input disturbance it was identified with (see
    /// [`super::noise::with_smaller_ratio`]); `None` for the nominal model's own noise path.
    pub(super) input_noise: Option<f64>,
    /// The kernel width as a share of z's range it was identified with
    /// ([`DiscoverSettings::sigma_fraction`], a [`super::FINER_SIGMA`]-th of it in the finer
    /// pass), so that a refit around a new G resolves the same detail.
    pub(super) sigma_fraction: f64,
}

/// G (u → y) re-estimated jointly with a hypothesis' map, and the hypothesis' validation RMS
/// around the nominal model's G before.
#[derive(Clone, Debug)]
pub(super) struct JointLinear {
    pub(super) g: structid_linear::PolynomialModel,
    pub(super) nominal_validation_rms: f64,
}

/// The parts of a fit every estimator shares: simulation RMS on both records, the map on a
/// grid, and the naming points.
#[allow(clippy::too_many_arguments)]
pub(super) fn finish_fit(
    location: Site,
    estimator: &'static str,
    h: Hypothesis,
    id: structid_core::Identification,
    beta: f64,
    beta_at_bound: Option<structid_core::selection::Bound>,
    sigma: Option<f64>,
    est_h: &Data,
    val_h: &Data,
    settings: &DiscoverSettings,
    t0: Instant,
) -> Result<Fitted> {
    let block = &id.blocks[0];
    let zk = block.z.channel(0);
    let (lo, hi) = minmax(&zk);
    // Outside the estimation range a map is an extrapolation (a kernel reverts to zero, a
    // trend runs away): a hypothesis is ranked by the better of its map as estimated and the
    // map held at its edge values there, so that the location, not the extrapolation, decides.
    // The augmented model is then written with the extrapolation that won (`held`).
    let held = |z: &[f64]| block.map.eval(&[z[0].clamp(lo, hi)]);
    let as_estimated = simulation_rms(&h, block.map.as_ref(), val_h, settings);
    let held_rms = simulation_rms(&h, &held, val_h, settings);
    let hold_edges = held_rms < as_estimated;
    let validation_rms = as_estimated.min(held_rms);
    let (estimation_rms, residual_noise) =
        simulation_rms_and_noise(&h, block.map.as_ref(), est_h, settings);
    // A map whose simulation diverges on its own estimation record is not a candidate,
    // whatever it does on the validation record.
    let validation_rms = if estimation_rms.is_finite() {
        validation_rms
    } else {
        f64::INFINITY
    };
    let grid: Vec<f64> = (0..101)
        .map(|i| lo + (hi - lo) * i as f64 / 100.0)
        .collect();
    let grid_signal = Signal::from_fn(grid.len(), 1, |k, _| grid[k]);
    let w_grid: Vec<f64> = grid.iter().map(|z| block.predict(&[*z])).collect();
    let std = id.posterior_std(0, &grid_signal).ok().flatten();
    let idx = even_indices(zk.len(), settings.naming_points);
    let points = (
        idx.iter().map(|&k| zk[k]).collect(),
        idx.iter().map(|&k| block.w_hat[k]).collect(),
    );
    let result = HypothesisResult {
        location,
        dispersion: block.dispersion.clone(),
        beta,
        beta_at_bound,
        sigma,
        noise_term: id.cost.noise,
        dispersion_value: block.dispersion_value,
        estimation_rms,
        validation_rms,
        curve: MapCurve {
            z: grid,
            w: w_grid,
            std,
        },
        points,
        seconds: t0.elapsed().as_secs_f64(),
        failure: None,
    };
    let w_hat = block.w_hat.clone();
    let e_hat = id.e_hat.clone();
    let map = id
        .blocks
        .into_iter()
        .next()
        .map(|b| b.map)
        .ok_or_else(|| Error::Numerical("identification returned no block".into()))?;
    Ok(Fitted {
        result,
        hypothesis: h,
        map,
        z: zk,
        w_hat,
        e_hat,
        bounds: est_h.record_bounds().to_vec(),
        estimator,
        residual_noise,
        hold_edges,
        linear: None,
        direction: None,
        input_noise: None,
        sigma_fraction: settings.sigma_fraction,
    })
}

/// The quadratic estimate at `location`: Fourier kernel plus trend, β by marginal likelihood.
pub(super) fn identify_hypothesis(
    nominal: &Nominal,
    location: Site,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> Result<Fitted> {
    let t0 = Instant::now();
    // A first hypothesis only to compute z; the dispersion's width depends on its range.
    let probe = nominal.hypothesis(location, Arc::new(PolynomialDispersion::new(1)?))?;
    let est_h = probe.data(est)?;
    let z = z_of(&probe, &est_h)?;
    let (lo, hi) = minmax(&z);
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return Err(Error::InvalidStructure(format!(
            "z {} is constant on the estimation record",
            nominal.describe(location)
        )));
    }
    let dispersion = quadratic_dispersion(hi - lo, settings)?;
    let h = nominal.hypothesis(location, dispersion)?;
    // Marginal likelihood is defined for x₀ = 0: β and σ are chosen so, and the map is then
    // identified at the chosen values with x₀ estimated.
    let x0 = initial_state(location).0;
    let identify = IdentifySettings::builder()
        .initial_state(InitialState::Zero)
        .posterior(true)
        .build()?;
    // A β on its bound marks the hypothesis (`HypothesisResult::beta_at_bound`), which then
    // does not bound the noise level; widening would trade that flag for a map that
    // interpolates the noise even more closely.
    let selection = SelectionSettings::builder()
        .criterion(Criterion::MarginalLikelihood)
        .tune_sigma(settings.tune_sigma)
        .widen_decades(0.0)
        .build()?;
    // With known maps, the unknown block is identified with their outputs as known inputs.
    let (id_model, id_est) = h.identification(est)?;
    let sel = select(&id_model, &id_est, None, &identify, &selection)?;
    let id = if x0 == InitialState::Zero {
        sel.identification
    } else {
        structid_core::identify(
            &sel.model,
            &id_est,
            &identify.with_initial_state(x0).with_beta(sel.beta)?,
        )?
    };
    let h = h.with_dispersion(std::sync::Arc::clone(&sel.model.blocks()[0].dispersion));
    let val_h = h.data(val)?;
    // The width used: the tuned one, or the fixed fraction of the range.
    let sigma = sel.sigma.or(Some(
        settings.sigma_fraction * (hi - lo).max(f64::MIN_POSITIVE),
    ));
    finish_fit(
        location,
        "quadratic",
        h,
        id,
        sel.beta,
        sel.beta_at_bound,
        sigma,
        &est_h,
        &val_h,
        settings,
        t0,
    )
}

/// Sorts estimates by validation RMS, best first.
pub(super) fn by_validation(v: &mut [Fitted]) {
    v.sort_by(|a, b| a.result.validation_rms.total_cmp(&b.result.validation_rms));
}

//! The gap stage of [`discover`](super::discover): the nominal model's noise path and scoring
//! settled once, and its gaps on both records, which every later stage reads.

use std::time::Instant;

use structid_core::validation::Scoring;
use structid_core::{Data, Error, InitialState, Result};

use crate::gap::{Gap, GapSettings, gap};
use crate::hypotheses::Nominal;

use super::fit::{candidate_signals, resolve_scoring};
use super::{
    DiscoverSettings, Discovery, Finding, HypothesisResult, NoiseLevel, PAST_DISTURBANCE_GAP,
    Verdict, cancelled_integrator, check_nominal, noise,
};

/// One search's nominal model, records and settings, and what the gap stage found.
pub(super) struct Context<'a> {
    /// The nominal model as given (its known maps recovered as families).
    pub given: Nominal,
    /// The nominal model the hypotheses are identified around: `given` with its input
    /// disturbance, when it has one.
    pub nominal: Nominal,
    pub est: &'a Data,
    pub val: &'a Data,
    /// The settings, with the scoring resolved.
    pub settings: DiscoverSettings,
    pub scoring: Scoring,
    /// The ratio of the input disturbance, if the nominal model has one.
    pub input_noise: Option<f64>,
    /// The remark on a G whose zero cancels its integrator, if it does.
    pub cancelled: Option<String>,
    /// The signals the gap's localisation examines on each record.
    pub est_candidates: Vec<(String, Vec<f64>)>,
    pub val_candidates: Vec<(String, Vec<f64>)>,
    pub gap_settings: GapSettings,
    pub estimation_gap: Gap,
    pub validation_gap: Gap,
    /// A test failed on either record.
    pub missing_effect: bool,
    /// No test failed, but the nominal model's input disturbance hides a simulation gap of
    /// more than [`PAST_DISTURBANCE_GAP`] noise levels.
    pub past_disturbance: bool,
    pub started: Instant,
}

impl<'a> Context<'a> {
    /// The gap stage around `given` (the nominal model with its known maps recovered as
    /// families), on records already checked, and the noise level the nominal model's
    /// residuals give; `started` is when the search began.
    pub fn new(
        given: Nominal,
        est: &'a Data,
        val: &'a Data,
        settings: &DiscoverSettings,
        started: Instant,
    ) -> crate::error::Result<(Self, NoiseLevel)> {
        let scoring = resolve_scoring(&given, est, settings)?;
        let settings = DiscoverSettings {
            scoring: Some(scoring),
            ..settings.clone()
        };
        let (input_noise, nominal) = with_input_noise(&given, est, scoring)?;
        let ts = nominal.lft().sample_time().unwrap_or(1.0);
        let nominal_model = nominal.model()?;
        let signals = |d: &Data| -> Result<Vec<(String, Vec<f64>)>> {
            let linear = crate::records::stacked(d, |r| nominal.simulate_output(r.u()))?;
            let mut s = candidate_signals(d, &linear, ts);
            s.extend(nominal.state_signals(d)?);
            Ok(s)
        };
        let (est_candidates, val_candidates) = (signals(est)?, signals(val)?);
        let mut gap_settings = settings.gap.clone();
        gap_settings.scoring = scoring;
        // A known map of a signal that an unknown initial state reaches differently from y
        // (a sensor map adopted in an earlier step reads G·u) leaves no one-step predictor
        // with an estimated x₀: that nominal model is scored from rest, as a sensor map's
        // hypothesis is.
        if gap_settings.initial_state == InitialState::Estimate
            && !nominal.known_maps().is_empty()
            && matches!(
                structid_core::Problem::from_model_with_initial_state(&nominal_model, est),
                Err(Error::NotMeasurable { .. })
            )
        {
            gap_settings.initial_state = InitialState::Zero;
        }
        gap_settings.max_lag = gap_settings
            .max_lag
            .min(crate::records::shortest(est) / 4)
            .max(1);
        let nominal_maps = nominal.maps();
        let estimation_gap = gap(
            &nominal_model,
            &nominal_maps,
            est,
            &est_candidates,
            &gap_settings,
        )?;
        check_nominal(&estimation_gap, est, scoring)?;
        let validation_gap = gap(
            &nominal_model,
            &nominal_maps,
            val,
            &val_candidates,
            &gap_settings,
        )?;
        let mut noise = NoiseLevel {
            std: f64::INFINITY,
            colour: 0.0,
            source: String::new(),
        };
        noise.tighten(estimation_gap.noise, || {
            "the nominal model's residual on the estimation record".into()
        });
        noise.tighten(validation_gap.noise, || {
            "the nominal model's residual on the validation record".into()
        });
        let missing_effect = estimation_gap.missing_effect || validation_gap.missing_effect;
        // The input disturbance is sized on the nominal model's residual, which holds the
        // missing effect: a large ratio lets the one-step predictor follow the output, so
        // that its innovations pass every test while the simulation misses by many times the
        // noise (an integrating axis with friction under a PD controller: ε within 1.5·σ̂, the
        // windowed simulation 10× σ̂). The hypotheses decide then, and a block must shrink the
        // validation gap by [`super::PAST_DISTURBANCE_SHRINK`] to be a missing effect rather
        // than what the disturbance leaves.
        let past_disturbance = !missing_effect
            && input_noise.is_some()
            && [&estimation_gap, &validation_gap]
                .iter()
                .all(|g| g.rms > PAST_DISTURBANCE_GAP * noise.std);
        let cancelled = cancelled_integrator(&given);
        let context = Context {
            given,
            nominal,
            est,
            val,
            settings,
            scoring,
            input_noise,
            cancelled,
            est_candidates,
            val_candidates,
            gap_settings,
            estimation_gap,
            validation_gap,
            missing_effect,
            past_disturbance,
            started,
        };
        Ok((context, noise))
    }

    /// The discovery this search ends with.
    pub fn discovery(
        self,
        verdict_kind: Verdict,
        noise: NoiseLevel,
        hypotheses: Vec<HypothesisResult>,
        finding: Option<Finding>,
        verdict: String,
    ) -> Discovery {
        Discovery {
            estimation_gap: self.estimation_gap,
            validation_gap: self.validation_gap,
            missing_effect: verdict_kind != Verdict::NoMissingEffect,
            verdict_kind,
            scoring: self.scoring,
            input_noise: self.input_noise,
            noise,
            hypotheses,
            finding,
            linear_rival: None,
            verdict,
            seconds: self.started.elapsed().as_secs_f64(),
        }
    }
}

/// A plant with integrators gets a disturbance where its input acts, when the data say so
/// (see [`noise`]); its hypotheses inherit it. A known map of a signal that the disturbance
/// drives (a friction map of ẏ found in an earlier step) leaves z without a causal filter
/// from y once the disturbance is a second noise channel; its one-step predictor does not
/// exist, and the output noise alone is the noise model there, as it is for a disturbance
/// path that cannot be whitened.
fn with_input_noise(
    given: &Nominal,
    est: &Data,
    scoring: Scoring,
) -> Result<(Option<f64>, Nominal)> {
    if let Scoring::Windowed(_) = scoring
        && given.lft().t_ye().order() == 0
        && let Some(ratio) = noise::input_noise_ratio(given, est)?
    {
        let with = given.clone().with_input_noise(ratio)?;
        if with.lft().measurability().is_ok() {
            return Ok((Some(ratio), with));
        }
    }
    Ok((None, given.clone()))
}

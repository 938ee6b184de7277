//! Silverbox refined as a whole by its simulation error (`structid-joint`), from the model of
//! the alternating pipeline ([`crate::silverbox::run`]).
//!
//! The start is that pipeline's G (its LFT, every non-zero entry of A, B_u and B_w free) and
//! its map, re-expressed as a Gaussian kernel expansion with an unpenalised cubic trend (the
//! physics' stiffness, which carries the map beyond the estimation amplitudes the arrow test
//! reaches). β is chosen from a grid by the simulation RMS on the last 20 % of the estimation
//! split (simulated on from the fitted part's start): the largest β whose validation RMS is
//! within [`JointSilverboxSettings::tie`] of the best, since a smaller difference does not
//! tell the maps apart and the smoother one extrapolates more safely (the validation part has
//! the estimation amplitudes and cannot judge extrapolation). The model is then refitted on
//! the whole estimation split with that β. The test splits are simulated once, from rest, as the
//! pipeline scores them.

use std::time::Instant;

use structid_core::{Data, Interpolant, Result, Signal};
use structid_io::{Silverbox, SilverboxSplit};
use structid_joint::{
    GaussianFeatures, JointBlock, JointError, JointFit, JointModel, JointSettings, LftMatrix, fit,
};

use crate::pipeline::io;
use crate::silverbox::SilverboxResult;

/// Settings of the joint refinement of Silverbox.
///
/// ```
/// let s = structid_benchmarks::silverbox_joint::JointSilverboxSettings::default();
/// assert_eq!(s.trend_degree, 3);
/// ```
#[derive(Clone, Debug)]
pub struct JointSilverboxSettings {
    /// Candidate β.
    pub betas: Vec<f64>,
    /// Kernel centres of the map.
    pub centres: usize,
    /// Degree of the map's unpenalised polynomial trend.
    pub trend_degree: usize,
    /// Fraction of the estimation split held out to choose β.
    pub validation_fraction: f64,
    /// Levenberg–Marquardt iterations per stage.
    pub max_iterations: usize,
    /// Relative difference of validation RMS below which two β are a tie (then the larger,
    /// smoother one is chosen).
    pub tie: f64,
}

impl Default for JointSilverboxSettings {
    fn default() -> Self {
        Self {
            betas: vec![1e-6, 1e-2, 1.0],
            centres: 15,
            trend_degree: 3,
            validation_fraction: 0.2,
            max_iterations: 30,
            tie: 0.01,
        }
    }
}

/// The result.
#[derive(Clone, Debug)]
pub struct JointSilverbox {
    /// (β, validation RMS in volts) for each β tried.
    pub trials: Vec<(f64, f64)>,
    /// The chosen β.
    pub beta: f64,
    /// The fit on the whole estimation split.
    pub fit: JointFit,
    /// (split, RMS in volts) for each test split, simulated from rest.
    pub tests: Vec<(String, f64)>,
    /// Seconds of the joint refinement (the alternating pipeline not included).
    pub seconds: f64,
}

fn joint(e: JointError) -> structid_core::Error {
    match e {
        JointError::Core(c) => c,
        other => structid_core::Error::Numerical(other.to_string()),
    }
}

/// The start: the pipeline's LFT and its map as kernel features with a polynomial trend.
fn start(
    base: &SilverboxResult,
    y: &Signal,
    s: &JointSilverboxSettings,
    beta: f64,
) -> Result<JointModel> {
    let map: &dyn Interpolant = base.refinement.identification.blocks[0].map.as_ref();
    let v = y.channel(0);
    let (lo, hi) = v
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(*x), b.max(*x))
        });
    let spacing = (hi - lo) / (s.centres - 1) as f64;
    let f = GaussianFeatures::on_interval(lo, hi, s.centres, 1.5 * spacing, beta)
        .and_then(|f| f.with_trend_degree(s.trend_degree))
        .map_err(joint)?;
    let z: Vec<Vec<f64>> = (0..400)
        .map(|k| vec![lo + (hi - lo) * k as f64 / 399.0])
        .collect();
    let w: Vec<f64> = z.iter().map(|z| map.eval(z)).collect();
    let f = f.fitted_to(&z, &w).map_err(joint)?;
    let b = &base.refinement.model.blocks()[0];
    let model = JointModel::new(
        base.refinement.model.lft().clone(),
        vec![JointBlock::new(
            "N",
            b.inputs.clone(),
            b.output,
            Box::new(f),
        )],
    )
    .and_then(|m| m.with_free_nonzero(LftMatrix::A))
    .and_then(|m| m.with_free_nonzero(LftMatrix::Bu))
    .and_then(|m| m.with_free_nonzero(LftMatrix::Bw))
    .map_err(joint)?;
    Ok(model)
}

fn rms_after(a: &[f64], b: &[f64], from: usize) -> f64 {
    let n = (a.len() - from) as f64;
    (a[from..]
        .iter()
        .zip(&b[from..])
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

/// Runs the joint refinement from the pipeline's result `base`.
pub fn run_joint(
    sb: &Silverbox,
    base: &SilverboxResult,
    s: &JointSilverboxSettings,
) -> Result<JointSilverbox> {
    let t0 = Instant::now();
    let est = sb.split(SilverboxSplit::Estimation).data().map_err(io)?;
    let cut = ((1.0 - s.validation_fraction) * est.len() as f64).round() as usize;
    let part = Data::new(est.u().slice(0..cut), est.y().slice(0..cut))?;
    let settings = JointSettings::builder()
        .max_iterations(s.max_iterations)
        .build()
        .map_err(joint)?;
    let mut trials = Vec::new();
    for &beta in &s.betas {
        let f = fit(&start(base, est.y(), s, beta)?, &part, None, &settings).map_err(joint)?;
        let sim = f
            .model
            .simulate(est.u(), Some(&f.initial_states[0]))
            .map_err(joint)?;
        trials.push((beta, rms_after(&sim.y.channel(0), &est.y().channel(0), cut)));
    }
    let best = trials.iter().map(|t| t.1).fold(f64::INFINITY, f64::min);
    let beta = trials
        .iter()
        .filter(|t| t.1 <= (1.0 + s.tie) * best)
        .map(|t| t.0)
        .fold(f64::NAN, f64::max);
    if !beta.is_finite() {
        return Err(structid_core::Error::InvalidStructure(
            "no β validated".into(),
        ));
    }
    let f = fit(&start(base, est.y(), s, beta)?, &est, None, &settings).map_err(joint)?;
    let mut tests = Vec::new();
    for split in [
        SilverboxSplit::TestArrowFull,
        SilverboxSplit::TestArrowNoExtrapolation,
        SilverboxSplit::TestMultisine,
    ] {
        let rec = sb.split(split);
        let data = rec.data().map_err(io)?;
        let sim = f.model.simulate(data.u(), None).map_err(joint)?;
        tests.push((
            split.name().to_string(),
            rec.scored_rms(&sim.y.channel(0)).map_err(io)?,
        ));
    }
    Ok(JointSilverbox {
        trials,
        beta,
        fit: f,
        tests,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

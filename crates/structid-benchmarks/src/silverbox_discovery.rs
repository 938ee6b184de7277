//! The discovery workflow on the Silverbox benchmark: start from the project's own best linear
//! approximation and let [`discover`] find what is missing.
//!
//! 1. The estimation split is divided into a fitting part (the first 80 %) and a validation
//!    part (the rest); the test splits are not looked at until the end.
//! 2. The nominal model is the BLA of order n (default 2: the physics' mass–spring–damper) on
//!    the fitting part, by ARX then output error with a free initial state
//!    ([`crate::silverbox::bla`]); its model is y = G·u + e.
//! 3. [`discover`] runs over every default location with its default settings: the gap of the
//!    BLA, the four hypotheses (input, output sensor, feedback from y, feedback from ẏ)
//!    identified on the fitting part and ranked on the validation part, the named family and
//!    the augmented model.
//! 4. Each test split is simulated from rest, from u alone, with the BLA and with the
//!    augmented model (the named parametric map in the loop); the first 50 samples settle and
//!    are not scored.
//!
//! The Silverbox is an electronic Duffing oscillator, m·ÿ + d·ẏ + a·y + b·y³ = u: the missing
//! effect is a cubic stiffness acting in feedback from y. Its linear part a·y is already in the
//! BLA (as part of its denominator), so the map's linear coefficient is the BLA's stiffness
//! error: structurally, F + k·B and N − k·y give the same model.

use std::time::Instant;

use structid_core::{Data, Interpolant, Result};
use structid_discover::discover::{DiscoverSettings, Discovery, discover};
use structid_discover::hypotheses::Nominal;
use structid_io::{Silverbox, SilverboxSplit};
use structid_linear::PolynomialModel;

use crate::pipeline::io;
use crate::silverbox::{bla, simulate};

/// Settings of [`run`].
#[derive(Clone, Debug)]
pub struct SilverboxDiscoverySettings {
    /// Order n of the nominal BLA (na = nb = n, nk = 1).
    pub order: usize,
    /// Fraction of the estimation split held out for validation.
    pub validation_fraction: f64,
    /// Settings of the workflow.
    pub discover: DiscoverSettings,
}

impl Default for SilverboxDiscoverySettings {
    /// n = 2, 20 % validation, default discovery settings.
    fn default() -> Self {
        Self {
            order: 2,
            validation_fraction: 0.2,
            discover: DiscoverSettings::default(),
        }
    }
}

/// One test split: the BLA's and the augmented model's simulation RMS.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DiscoveryScore {
    /// Split name.
    pub split: String,
    /// RMS of the nominal BLA, volts.
    pub bla_rms: f64,
    /// RMS of the augmented model, volts.
    pub augmented_rms: f64,
    /// The augmented model's simulated output.
    #[serde(skip)]
    pub simulated: Vec<f64>,
    /// The BLA's simulated output.
    #[serde(skip)]
    pub bla_simulated: Vec<f64>,
    /// The measured output.
    #[serde(skip)]
    pub measured: Vec<f64>,
}

/// Everything [`run`] produced.
pub struct SilverboxDiscovery {
    /// The nominal BLA.
    pub bla: PolynomialModel,
    /// The workflow's result.
    pub discovery: Discovery,
    /// The test scores (empty when no effect was found).
    pub tests: Vec<DiscoveryScore>,
    /// Seconds spent estimating the BLA.
    pub bla_seconds: f64,
    /// Seconds spent in [`discover`].
    pub discover_seconds: f64,
}

/// The fitting and validation parts of the estimation split.
pub fn parts(sb: &Silverbox, validation_fraction: f64) -> Result<(Data, Data)> {
    let est = sb.split(SilverboxSplit::Estimation).data().map_err(io)?;
    let cut = ((1.0 - validation_fraction) * est.len() as f64).round() as usize;
    let part = |r: std::ops::Range<usize>| Data::new(est.u().slice(r.clone()), est.y().slice(r));
    Ok((part(0..cut)?, part(cut..est.len())?))
}

/// Runs the workflow of the [module documentation](self).
pub fn run(sb: &Silverbox, settings: &SilverboxDiscoverySettings) -> Result<SilverboxDiscovery> {
    let (fit, val) = parts(sb, settings.validation_fraction)?;
    let t0 = Instant::now();
    let g = bla(&fit, settings.order, sb.sample_time)?;
    let bla_seconds = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let nominal = Nominal::from_polynomial(&g)?;
    let discovery = discover(&nominal, &fit, &val, &settings.discover)?;
    let discover_seconds = t1.elapsed().as_secs_f64();
    let mut tests = Vec::new();
    if let Some(f) = &discovery.finding {
        let map: Box<dyn Interpolant> = f.augmented.map.interpolant()?;
        let nominal_model = nominal.model()?;
        for split in [
            SilverboxSplit::TestArrowFull,
            SilverboxSplit::TestArrowNoExtrapolation,
            SilverboxSplit::TestMultisine,
        ] {
            let rec = sb.split(split);
            let data = rec.data().map_err(io)?;
            let y_sim = simulate(&f.augmented.model, map.as_ref(), data.u())?;
            let bla_sim = nominal_model
                .lft()
                .simulate(&[], data.u(), None, None)?
                .y
                .channel(0);
            tests.push(DiscoveryScore {
                split: split.name().into(),
                bla_rms: rec.scored_rms(&bla_sim).map_err(io)?,
                augmented_rms: rec.scored_rms(&y_sim).map_err(io)?,
                simulated: y_sim,
                bla_simulated: bla_sim,
                measured: rec.y.clone(),
            });
        }
    }
    Ok(SilverboxDiscovery {
        bla: g,
        discovery,
        tests,
        bla_seconds,
        discover_seconds,
    })
}

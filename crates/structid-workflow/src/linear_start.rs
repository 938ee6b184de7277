//! Discovery from a linear start: a record with no model at all, the best linear approximation
//! (BLA) of a chosen order as the nominal model G, then [`discover`] for what G is missing, and
//! test records simulated with both.
//!
//! 1. The estimation record is divided into a fitting part (the first 1 − f) and a validation
//!    part (the last f); test records are not looked at until the end.
//! 2. G is the BLA of order n on the fitting part, y = G·u + e, fitted by ARX and then by output
//!    error with a free initial state ([`best_linear_approximation`]).
//! 3. [`discover`] runs with the given settings: the gap of G, the hypotheses identified on the
//!    fitting part and ranked on the validation part, the named family and the augmented model.
//! 4. Each test record is simulated from rest, from u alone, with G and with the augmented model
//!    (its map in the loop), and scored over its samples after `settle`
//!    ([`Record::scored_rms`]).

use std::time::Instant;

use structid_core::refine::best_linear_approximation;
use structid_core::{Data, Interpolant, Model};
use structid_discover::discover::{Augmented, DiscoverSettings, Discovery, discover};
use structid_discover::hypotheses::Nominal;
use structid_io::Record;
use structid_linear::PolynomialModel;

use crate::error::{Result, WorkflowError};

/// What [`discover_from_linear_start`] is asked to do.
#[derive(Clone, Debug)]
pub struct LinearStartRequest {
    /// Order n of the BLA (na = nb = n, nk = 1).
    pub order: usize,
    /// Fraction f of the estimation record held out for validation, in (0, 1).
    pub validation_fraction: f64,
    /// Sample time of the records, seconds (the BLA's and the report's time axis).
    pub sample_time: f64,
    /// Settings of [`discover`].
    pub discover: DiscoverSettings,
}

impl Default for LinearStartRequest {
    /// n = 2, 20 % validation, unit sample time, default discovery settings.
    fn default() -> Self {
        Self {
            order: 2,
            validation_fraction: 0.2,
            sample_time: 1.0,
            discover: DiscoverSettings::default(),
        }
    }
}

/// One test record simulated with the BLA and with the augmented model.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TestScore {
    /// The record's name.
    pub record: String,
    /// RMS of the BLA's simulation error over the scored samples.
    pub bla_rms: f64,
    /// RMS of the augmented model's simulation error over the scored samples.
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

/// Everything [`discover_from_linear_start`] produced.
pub struct LinearStartDiscovery {
    /// The nominal BLA.
    pub bla: PolynomialModel,
    /// The nominal model discovery started from (the BLA as an LFT).
    pub nominal: Nominal,
    /// The fitting part of the estimation record.
    pub fit: Data,
    /// The validation part of the estimation record.
    pub validation: Data,
    /// Discovery's result.
    pub discovery: Discovery,
    /// The test scores, in the order of the test records (empty when nothing was found).
    pub tests: Vec<TestScore>,
    /// Seconds spent estimating the BLA.
    pub bla_seconds: f64,
    /// Seconds spent in [`discover`].
    pub discover_seconds: f64,
}

/// The fitting part (the first 1 − f) and the validation part (the last f) of `estimation`.
///
/// Fails when f is not strictly between 0 and 1 or either part would be empty.
pub fn split_for_validation(estimation: &Data, fraction: f64) -> Result<(Data, Data)> {
    check_fraction(fraction)?;
    // A cut through several records would join them into one.
    estimation.require_single_record("the split into fitting and validation parts")?;
    let n = estimation.len();
    let cut = ((1.0 - fraction) * n as f64).round() as usize;
    if cut == 0 || cut >= n {
        return Err(WorkflowError::Request(format!(
            "a validation fraction of {fraction} of {n} samples leaves no fitting or no \
             validation part: each needs at least one sample"
        )));
    }
    let part = |r: std::ops::Range<usize>| {
        Data::new(estimation.u().slice(r.clone()), estimation.y().slice(r))
    };
    Ok((part(0..cut)?, part(cut..n)?))
}

fn check_fraction(fraction: f64) -> Result<()> {
    if fraction > 0.0 && fraction < 1.0 {
        Ok(())
    } else {
        Err(WorkflowError::Request(format!(
            "validation fraction {fraction}: it must lie strictly between 0 and 1"
        )))
    }
}

impl LinearStartRequest {
    /// Checks what can be checked before any data are read: the validation fraction lies
    /// strictly between 0 and 1 and the order is at least 1.
    pub fn check(&self) -> Result<()> {
        check_fraction(self.validation_fraction)?;
        if self.order == 0 {
            return Err(WorkflowError::Request(
                "the order of the BLA must be at least 1".into(),
            ));
        }
        Ok(())
    }
}

/// Runs the workflow of the [module documentation](self) on `estimation` (one input, one
/// output), scoring the augmented model on `tests`.
///
/// ```no_run
/// use structid_io::{Silverbox, SilverboxSplit};
/// use structid_workflow::{LinearStartRequest, discover_from_linear_start};
/// let sb = Silverbox::load(std::path::Path::new("SNLS80mV.csv"))?;
/// let est = sb.split(SilverboxSplit::Estimation).data()?;
/// let tests = [sb.split(SilverboxSplit::TestMultisine)];
/// let request = LinearStartRequest { sample_time: sb.sample_time, ..Default::default() };
/// let r = discover_from_linear_start(&est, &tests, &request)?;
/// for t in &r.tests {
///     println!("{}: {:.3} mV → {:.3} mV", t.record, 1e3 * t.bla_rms, 1e3 * t.augmented_rms);
/// }
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn discover_from_linear_start(
    estimation: &Data,
    tests: &[Record],
    request: &LinearStartRequest,
) -> Result<LinearStartDiscovery> {
    if estimation.u().channels() != 1 || estimation.y().channels() != 1 {
        return Err(WorkflowError::Request(format!(
            "a linear start needs one input and one output; the record has {} and {}",
            estimation.u().channels(),
            estimation.y().channels()
        )));
    }
    request.check()?;
    let (fit, validation) = split_for_validation(estimation, request.validation_fraction)?;
    let t0 = Instant::now();
    let bla = best_linear_approximation(&fit, request.order, request.sample_time)?;
    let bla_seconds = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let nominal = Nominal::from_polynomial(&bla)?;
    let discovery = discover(&nominal, &fit, &validation, &request.discover)?;
    let discover_seconds = t1.elapsed().as_secs_f64();
    let tests = match &discovery.finding {
        Some(f) => score_tests(&nominal.model()?, &f.augmented, tests)?,
        None => Vec::new(),
    };
    Ok(LinearStartDiscovery {
        bla,
        nominal,
        fit,
        validation,
        discovery,
        tests,
        bla_seconds,
        discover_seconds,
    })
}

/// Each test record simulated from rest with the BLA and with the augmented model (every
/// block's map in the loop).
fn score_tests(bla: &Model, augmented: &Augmented, tests: &[Record]) -> Result<Vec<TestScore>> {
    let maps = augmented.maps()?;
    let maps: Vec<&dyn Interpolant> = maps.iter().map(|m| m.as_ref()).collect();
    tests
        .iter()
        .map(|rec| {
            let u = rec.data()?.u().clone();
            let simulated = augmented
                .model
                .simulate(&maps, &u, None, None)?
                .y
                .channel(0);
            let bla_simulated = bla.lft().simulate(&[], &u, None, None)?.y.channel(0);
            Ok(TestScore {
                record: rec.name.clone(),
                bla_rms: rec.scored_rms(&bla_simulated)?,
                augmented_rms: rec.scored_rms(&simulated)?,
                simulated,
                bla_simulated,
                measured: rec.y.clone(),
            })
        })
        .collect()
}

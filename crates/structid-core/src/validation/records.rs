//! Validation over several records: each record is validated on its own ([`validate`]), from
//! its own initial state, and the free-run simulation errors are pooled over the samples that
//! each record's validation scored (after its settling samples, or its windows).
//!
//! The pooled figures are those of all scored samples taken together
//! ([`PooledFit`]), so a short record weighs as much per sample as a long one.

use structid_lti::Signal;

use crate::error::{Error, Result};
use crate::model::interpolant::Interpolant;
use crate::model::{Data, Model};
use crate::validation::metrics::PooledFit;
use crate::validation::{ValidationReport, ValidationSettings, validate};

/// Every record's [`ValidationReport`] and the pooled simulation error per output.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordsValidation {
    /// One report per record, in the records' order.
    pub records: Vec<ValidationReport>,
    /// Per output: the simulation error pooled over every record's scored samples.
    pub pooled: Vec<PooledFit>,
}

impl RecordsValidation {
    /// Per output: the pooled simulation RMS.
    pub fn rms(&self) -> Vec<f64> {
        self.pooled.iter().map(PooledFit::rms).collect()
    }

    /// Per output: the pooled fit in percent (NaN for an output that does not vary).
    pub fn fit_percent(&self) -> Vec<f64> {
        self.pooled.iter().map(PooledFit::fit_percent).collect()
    }

    /// The number of samples pooled (per output).
    pub fn samples(&self) -> usize {
        self.pooled.first().map_or(0, PooledFit::samples)
    }
}

/// Validates `maps` (one per block of `model`) on every record of `data`, each on its own,
/// and pools the simulation errors.
///
/// # Errors
/// As [`validate`], for the first record that fails, wrapped in [`Error::InRecord`] when
/// `data` holds more than one record.
///
/// ```
/// use std::sync::Arc;
/// use nalgebra::dmatrix;
/// use structid_core::validation::{ValidationSettings, validate, validate_records};
/// use structid_core::{Data, KernelDispersion, Lft, LftMatrices, Model, NonlinearBlock};
/// use structid_lti::Signal;
/// // Hammerstein: x⁺ = 0.5x + w, y = x + e, w = tanh(u); the map is off by 10 %.
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![0.5], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
/// }).unwrap();
/// let block = NonlinearBlock::new("N", vec![0], 0, Arc::new(KernelDispersion::gaussian(0.3).unwrap()));
/// let model = Model::new(lft, vec![block]).unwrap();
/// let tanh = |z: &[f64]| z[0].tanh();
/// let record = |len: usize, f: f64| {
///     let u = Signal::from_fn(len, 1, |k, _| (f * k as f64).sin() * 2.0);
///     let y = model.simulate(&[&tanh], &u, None, None).unwrap().y;
///     Data::new(u, y).unwrap()
/// };
/// let (a, b) = (record(300, 0.37), record(200, 0.11));
/// let both = Data::from_records(vec![a.clone(), b.clone()]).unwrap();
/// let wrong = |z: &[f64]| 0.9 * z[0].tanh();
/// let s = ValidationSettings::default();
/// let pooled = validate_records(&model, &[&wrong], &both, &s).unwrap();
/// assert_eq!((pooled.records.len(), pooled.samples()), (2, 500));
/// // The pooled mean square is the sample-weighted mean of the records' own.
/// let (ra, rb) = (validate(&model, &[&wrong], &a, &s).unwrap(), validate(&model, &[&wrong], &b, &s).unwrap());
/// let ms = (300.0 * ra.rms[0].powi(2) + 200.0 * rb.rms[0].powi(2)) / 500.0;
/// assert!((pooled.rms()[0] - ms.sqrt()).abs() < 1e-12);
/// ```
pub fn validate_records(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    settings: &ValidationSettings,
) -> Result<RecordsValidation> {
    let records = data.records();
    let several = records.len() > 1;
    let mut out = RecordsValidation {
        records: Vec::with_capacity(records.len()),
        pooled: vec![PooledFit::default(); data.y().channels()],
    };
    for (i, record) in records.iter().enumerate() {
        let report = validate(model, maps, record, settings).map_err(|e| match several {
            true => Error::InRecord {
                record: i + 1,
                source: Box::new(e),
            },
            false => e,
        })?;
        pool_record(
            &mut out.pooled,
            record.y(),
            &report.simulated,
            &report.scored,
        );
        out.records.push(report);
    }
    Ok(out)
}

/// Adds one record's measured `y` and `simulated` outputs at the samples `scored` to `pooled`
/// (one [`PooledFit`] per output; an empty `pooled` is sized to the outputs first). This is
/// the one pooling rule of validation over records, for a caller that scored its records
/// itself.
///
/// ```
/// use structid_core::validation::metrics::rms_difference;
/// use structid_core::validation::records::pool_record;
/// use structid_lti::Signal;
/// let y = Signal::new(1, vec![1.0, 2.0, 3.0, 4.0]).unwrap();
/// let s = Signal::new(1, vec![0.0, 2.5, 3.0, 3.0]).unwrap();
/// let mut pooled = Vec::new();
/// pool_record(&mut pooled, &y, &s, &[1..2, 3..4]);
/// assert_eq!(pooled[0].samples(), 2);
/// assert_eq!(pooled[0].rms(), rms_difference(&[2.0, 4.0], &[2.5, 3.0]));
/// ```
pub fn pool_record(
    pooled: &mut Vec<PooledFit>,
    y: &Signal,
    simulated: &Signal,
    scored: &[std::ops::Range<usize>],
) {
    if pooled.is_empty() {
        pooled.resize(y.channels(), PooledFit::default());
    }
    for (c, fit) in pooled.iter_mut().enumerate() {
        fit.add_ranges(&y.channel(c), &simulated.channel(c), scored);
    }
}

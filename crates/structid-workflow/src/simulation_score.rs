//! Validation by simulation alone, for models without a one-step predictor.
//!
//! The one-step predictor and the residual tests of `structid validate` need every block's
//! input computable from u and y once the maps are known (maps in series are evaluated in
//! order, [`structid_core::Model::compute_z_with_maps`]) and no block with memory. A model with
//! a latent block or a hysteresis operator (what `refine --joint` writes for such plants) is
//! validated by what it can do: simulate the record from u alone, from rest, and score the
//! simulation error after `settle` samples.

use structid_core::validation::metrics::PooledFit;
use structid_core::validation::records::pool_record;
use structid_core::{BlockAccess, Data, Signal};
use structid_io::ModelFile;

use crate::error::{Result, WorkflowError};
use crate::joint::simulate_model_file;

/// Why `structid validate` scores `mf` by its simulation alone (a latent block, a hysteresis
/// operator), or `None` when the one-step predictor applies.
///
/// # Errors
/// A malformed model (a cycle of maps, channels out of range).
pub fn why_simulation_only(mf: &ModelFile) -> Result<Option<String>> {
    if let Some(b) = mf.blocks.iter().find(|b| b.operator.is_some()) {
        return Ok(Some(format!("block `{}` is a hysteresis operator", b.name)));
    }
    mf.evaluation_order()?;
    let access = mf.block_access()?;
    Ok(mf
        .blocks
        .iter()
        .zip(&access)
        .find(|(_, a)| **a == BlockAccess::Latent)
        .map(|(b, _)| format!("block `{}` is latent", b.name)))
}

/// A model's simulation of one record and its scores.
#[derive(Clone, Debug)]
pub struct SimulationScore {
    /// ŷ from u alone, each record from rest (L × n_y, the records one after the other).
    pub simulated: Signal,
    /// RMS of y − ŷ per output over the samples from `settle` on in each record.
    pub rms: Vec<f64>,
    /// 100·(1 − ‖y − ŷ‖/‖y − ȳ‖) per output over the same samples (MATLAB's `compare` fit);
    /// NaN when y does not move there.
    pub fit_percent: Vec<f64>,
    /// Leading samples of each record left out of the scores.
    pub settle: usize,
}

/// Simulates `mf` (every static block by its `truth`, operators as declared) on each record of
/// `data` from rest and scores it after `settle` samples of each record.
///
/// ```
/// use structid_core::{Data, Signal};
/// use structid_io::ModelFile;
/// let m = ModelFile::parse(r#"
///     [lft]
///     A = []
///     Dye = [[1.0]]
///     Dyw = [[1.0]]
///     Dzu = [[1.0]]
///     [signals]
///     u = ["u"]
///     y = ["y"]
///     [[nonlinearity]]
///     name = "backlash"
///     inputs = [0]
///     output = 0
///     operator = { kind = "play", half_width = 0.5 }
/// "#, None).unwrap();
/// let u = Signal::new(1, vec![0.0, 1.0, 0.8, -1.0]).unwrap();
/// let y = Signal::new(1, vec![0.0, 0.5, 0.5, -0.4]).unwrap();
/// let s = structid_workflow::score_simulation(&m, &Data::new(u, y).unwrap(), 0).unwrap();
/// assert!((s.rms[0] - 0.05).abs() < 1e-12);
/// ```
///
/// # Errors
/// `settle` not below the record's length, and the simulation's errors.
pub fn score_simulation(mf: &ModelFile, data: &Data, settle: usize) -> Result<SimulationScore> {
    let records = data.records();
    if let Some(r) = records.iter().position(|r| settle >= r.len()) {
        return Err(WorkflowError::Request(format!(
            "settle = {settle} leaves none of the {} samples of record {} to score",
            records[r].len(),
            r + 1
        )));
    }
    let ny = data.y().channels();
    let mut simulated = Vec::with_capacity(data.len() * ny);
    let mut pooled = Vec::new();
    for rec in &records {
        let sim = simulate_model_file(mf, rec.u(), None)?;
        let scored = settle..rec.len();
        pool_record(&mut pooled, rec.y(), &sim.y, std::slice::from_ref(&scored));
        simulated.extend_from_slice(sim.y.as_slice());
    }
    let rms = pooled.iter().map(PooledFit::rms).collect();
    let fit = pooled.iter().map(PooledFit::fit_percent).collect();
    Ok(SimulationScore {
        simulated: Signal::new(ny, simulated).map_err(structid_core::Error::from)?,
        rms,
        fit_percent: fit,
        settle,
    })
}

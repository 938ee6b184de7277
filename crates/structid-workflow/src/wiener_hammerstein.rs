//! Block-structured models identified from input–output data with every block unknown: a
//! Wiener–Hammerstein model y = G₂·N(G₁·u) + e (`structid wiener-hammerstein`) or a
//! Hammerstein–Wiener model y = N₂(G·N₁(u)) + e (`structid hammerstein-wiener`, MATLAB's
//! `nlhw`).
//!
//! For Wiener–Hammerstein:
//!
//! 1. The best linear approximation: an output-error model of the given orders (those of the
//!    two blocks together) over every record.
//! 2. Every division of its poles and zeros between a front block G₁ and a back block G₂,
//!    each scored by a map fitted behind it, the best as the start
//!    ([`structid_joint::wiener_hammerstein`]).
//! 3. The joint fit of both blocks, the map and the records' initial states by simulation
//!    error; β is given or chosen on validation records, as for `refine --joint`.
//!
//! For Hammerstein–Wiener, G starts as the best linear approximation and both maps as the
//! identity ([`structid_joint::hammerstein_wiener`]), then the same joint fit.
//!
//! The result is written like `refine --joint`'s: a model file whose LFT holds both blocks
//! (state x = [x₁; x₂]) and whose one block `N` is the map as a table, `joint.json`, and
//! `divisions.json` with the linear approximation and every division's score.

use std::path::Path;

use structid_core::Data;
use structid_io::{BlockSpec, DispersionSpec, ModelFile, OutputGuard, SignalNames};
use structid_joint::{
    JointSettings, SplitScore, WienerHammersteinSettings, fit, hammerstein_wiener_start,
    wiener_hammerstein_start,
};
use structid_linear::{OeSettings, Orders, PolynomialModel, oe_records};

use crate::error::{Result, WorkflowError};
use crate::joint::{BetaChoice, JointOutcome, over_betas, write_joint_outputs, written};

/// Which block structure [`wiener_hammerstein`] identifies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlockStructure {
    /// y = G₂·N(G₁·u) + e.
    WienerHammerstein,
    /// y = N₂(G·N₁(u)) + e.
    HammersteinWiener,
}

/// What [`wiener_hammerstein`] asks for.
#[derive(Clone, Debug)]
pub struct WienerHammersteinRequest<'a> {
    /// The structure.
    pub structure: BlockStructure,
    /// The estimation data: one input, one output, one or several records.
    pub data: &'a Data,
    /// The data's column names (one u, one y), for the model file.
    pub names: SignalNames,
    /// Orders (n_a, n_b, n_k) of the best linear approximation: the poles of both blocks
    /// together, the numerator's coefficients, the delay.
    pub orders: [usize; 3],
    /// β of the map: given, or chosen on validation records.
    pub beta: BetaChoice,
    /// Centres of the map and their margin (its β is overridden by [`Self::beta`]).
    pub start: WienerHammersteinSettings,
    /// The joint fit's settings.
    pub fit: JointSettings,
}

/// The identified model and the evidence for it.
#[derive(Clone, Debug)]
pub struct WienerHammersteinOutcome {
    /// The best linear approximation.
    pub bla: PolynomialModel,
    /// Wiener–Hammerstein: every division of its poles and zeros with its score, best first
    /// (for the chosen β); empty for Hammerstein–Wiener.
    pub divisions: Vec<SplitScore>,
    /// The joint fit from the best division, with the model file it is written as.
    pub joint: JointOutcome,
}

/// Identifies the block-structured model; see the [module documentation](self).
///
/// # Errors
/// Data with more than one input or output, bad orders, a failed linear fit, no division that
/// gives a finite start, and the joint fit's errors.
pub fn wiener_hammerstein(req: &WienerHammersteinRequest<'_>) -> Result<WienerHammersteinOutcome> {
    let data = req.data;
    if data.u().channels() != 1 || data.y().channels() != 1 {
        return Err(WorkflowError::Request(format!(
            "a block-structured model has one input and one output; the data have {} and {}",
            data.u().channels(),
            data.y().channels()
        )));
    }
    if req.names.u.len() != 1 || req.names.y.len() != 1 {
        return Err(WorkflowError::Request(format!(
            "a block-structured model has one input and one output; {} input and {} output name(s) were given",
            req.names.u.len(),
            req.names.y.len()
        )));
    }
    let [na, nb, nk] = req.orders;
    let records = data.records();
    let pairs: Vec<_> = records.iter().map(|r| (r.u(), r.y())).collect();
    let bla = oe_records(&pairs, &Orders::siso(na, nb, nk), &OeSettings::default())
        .map_err(|e| WorkflowError::Request(format!("the best linear approximation: {e}")))?
        .model;
    let mut divisions = Vec::new();
    let (beta, fitted, trials) = over_betas(&req.beta, req.fit.windows(), |beta| {
        let settings = WienerHammersteinSettings::builder()
            .centres(req.start.centres())
            .margin(req.start.margin())
            .beta(beta)
            .build()?;
        let start = match req.structure {
            BlockStructure::WienerHammerstein => {
                let start = wiener_hammerstein_start(&bla, data, &settings)?;
                divisions.push((beta, start.splits));
                start.model
            }
            BlockStructure::HammersteinWiener => hammerstein_wiener_start(&bla, data, &settings)?,
        };
        Ok(fit(&start, data, None, &req.fit)?)
    })?;
    let divisions = divisions
        .into_iter()
        .find(|(b, _)| *b == beta)
        .map(|(_, d)| d)
        .unwrap_or_default();
    let block = |name: &str, input: usize| BlockSpec {
        name: name.into(),
        inputs: vec![input],
        output: input,
        dispersion: DispersionSpec::Gaussian { sigma: None },
        truth: None,
        operator: None,
        shape: None,
    };
    let blocks = match req.structure {
        BlockStructure::WienerHammerstein => vec![block("N", 0)],
        BlockStructure::HammersteinWiener => vec![block("input", 0), block("output", 1)],
    };
    let mf = ModelFile {
        lft: fitted.model.lft().clone(),
        linear: None,
        signals: req.names.clone(),
        blocks,
        discover: None,
        path: None,
    };
    let (model_file, tables) = written(&mf, &fitted, data, req.fit.windows())?;
    Ok(WienerHammersteinOutcome {
        bla,
        divisions,
        joint: JointOutcome {
            fit: fitted,
            beta,
            trials,
            model_file,
            tables,
        },
    })
}

/// Writes [`write_joint_outputs`]'s files and `divisions.json` into `dir`.
pub fn write_wiener_hammerstein_outputs(
    outcome: &WienerHammersteinOutcome,
    dir: &Path,
    guard: &OutputGuard,
) -> Result<()> {
    write_joint_outputs(&outcome.joint, dir, guard)?;
    let divisions: Vec<serde_json::Value> = outcome
        .divisions
        .iter()
        .map(|d| {
            serde_json::json!({
                "front": {"num": d.split.front.num[0], "den": d.split.front.den},
                "back": {"num": d.split.back.num[0], "den": d.split.back.den},
                "rms": if d.rms.is_finite() { Some(d.rms) } else { None },
            })
        })
        .collect();
    let json = serde_json::json!({
        "bla": {"num": outcome.bla.num[0], "den": outcome.bla.den},
        "divisions": divisions,
    });
    let text =
        serde_json::to_string_pretty(&json).map_err(|e| WorkflowError::Request(e.to_string()))?;
    guard.write(&dir.join("divisions.json"), text.as_bytes())?;
    Ok(())
}

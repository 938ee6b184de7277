//! Re-estimating G with the found map in the loop, for nominal models estimated from data.

use std::sync::Arc;

use structid_core::refine::{LinearStructure, RefineSettings, refine_linear};
use structid_core::{Data, IdentifySettings, InitialState, Result, Structure};
use structid_linear::PolynomialModel;

use crate::gap::{Gap, GapSettings, gap};

use super::fit::simulation_rms;
use super::{DiscoverSettings, Finding, NominalRefinement};

/// Refits G (in the structure of the finding's location) by output error with the finding's
/// map held fixed, starting from the nominal `g`, and keeps the augmented model with the new
/// G when its validation RMS (scored as every simulation of the workflow) falls; the finding's
/// gaps and shrink are then those of the new model. Records G before and after either way.
#[allow(clippy::too_many_arguments)]
pub(super) fn refine_nominal(
    g: &PolynomialModel,
    finding: &mut Finding,
    est: &Data,
    val: &Data,
    est_candidates: &[(String, Vec<f64>)],
    val_candidates: &[(String, Vec<f64>)],
    gap_settings: &GapSettings,
    before: &Gap,
    settings: &DiscoverSettings,
) -> Result<()> {
    let location = finding.location;
    let structure = LinearStructure::new("N", location)?;
    let start = structure.initial_from_bla(g)?;
    let map = finding.augmented.map.interpolant()?;
    let hypothesis = |g: &PolynomialModel| -> Result<crate::hypotheses::Hypothesis> {
        let dispersion = Arc::clone(&finding.augmented.model.blocks()[0].dispersion);
        Ok(crate::hypotheses::Hypothesis {
            location,
            model: Structure::new(g, location, dispersion).model()?,
            sample_time: g.sample_time.unwrap_or(1.0),
            known: Vec::new(),
        })
    };
    let h_before = hypothesis(&start)?;
    let val_before = h_before.data(val)?;
    let est_h = h_before.data(est)?;
    let refine_settings = RefineSettings::builder()
        .identify(
            IdentifySettings::builder()
                .initial_state(InitialState::Estimate)
                .build()?,
        )
        .build()?;
    let r = refine_linear(&structure, &start, map.as_ref(), &est_h, &refine_settings)?;
    let rms_before = simulation_rms(&h_before, map.as_ref(), &val_before, settings);
    let h_after = hypothesis(&r.after)?;
    let val_after = h_after.data(val)?;
    let rms_after = simulation_rms(&h_after, map.as_ref(), &val_after, settings);
    let adopted = rms_after < rms_before;
    if adopted {
        let est_after = h_after.data(est)?;
        let interp = map.as_ref();
        let estimation_gap: Gap = gap(
            &h_after.model,
            &[interp],
            &est_after,
            est_candidates,
            gap_settings,
        )?;
        let validation_gap = gap(
            &h_after.model,
            &[interp],
            &val_after,
            val_candidates,
            gap_settings,
        )?;
        finding.shrink = before.rms / validation_gap.rms;
        finding.augmented.model = h_after.model.clone();
        finding.augmented.estimation_gap = estimation_gap;
        finding.augmented.validation_gap = validation_gap;
        finding.remarks.push(format!(
            "G was re-estimated with the map in the loop (output error): validation RMS {:.4e} → {:.4e}",
            rms_before, rms_after
        ));
    }
    finding.nominal_refinement = Some(NominalRefinement {
        before: start,
        after: r.after,
        validation_rms_before: rms_before,
        validation_rms_after: rms_after,
        adopted,
    });
    Ok(())
}

//! The total-variation fallback where a smooth estimate cannot do.

use std::sync::Arc;
use std::time::Instant;

use structid_core::hyperparameters::{Criterion, SelectionSettings, select};
use structid_core::solver::admm::AdmmSettings;
use structid_core::{Data, IdentifySettings, Model, Result, TotalVariation};

use crate::hypotheses::Hypothesis;

use super::DiscoverSettings;
use super::fit::initial_state;
use super::fit::{Fitted, finish_fit};

/// The total-variation estimate at the location of `hyp`, β by validation simulation error.
pub(super) fn total_variation_fit(
    hyp: &Hypothesis,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> Result<Fitted> {
    let t0 = Instant::now();
    let h = Hypothesis {
        model: Model::new(
            hyp.model.lft().clone(),
            vec![structid_core::NonlinearBlock::new(
                "N",
                vec![0],
                0,
                Arc::new(TotalVariation::new()),
            )],
        )?,
        ..hyp.clone()
    };
    let est_h = h.data(est)?;
    let val_h = h.data(val)?;
    // Naming needs the shape of the map, not eight digits of it: a looser ADMM tolerance and
    // a coarser β search keep this step at a fraction of a second per fit.
    let identify = IdentifySettings::builder()
        .initial_state(initial_state(hyp.location).0)
        .admm(AdmmSettings::builder().tolerance(1e-5).build()?)
        .build()?;
    let selection = SelectionSettings::builder()
        .criterion(Criterion::Validation)
        .tolerance(0.25)
        .build()?;
    let sel = select(&h.model, &est_h, Some(&val_h), &identify, &selection)?;
    let h = Hypothesis {
        model: sel.model,
        ..h
    };
    finish_fit(
        hyp.location,
        "total variation",
        h,
        sel.identification,
        sel.beta,
        None,
        &est_h,
        &val_h,
        settings,
        t0,
    )
}

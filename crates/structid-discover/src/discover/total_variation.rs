//! The total-variation fallback where a smooth estimate cannot do.

use std::sync::Arc;
use std::time::Instant;

use structid_core::selection::{Bound, Criterion, Selection, SelectionSettings, select};
use structid_core::solver::admm::AdmmSettings;
use structid_core::{Data, Error, IdentifySettings, Result, TotalVariation};

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
    let h = hyp.with_dispersion(Arc::new(TotalVariation::new()));
    let est_h = h.data(est)?;
    let val_h = h.data(val)?;
    // With known maps, β is selected on the validation record's one-step model: their outputs
    // at the record's z are inputs there ([`Hypothesis::identification`]); the simulations
    // that rank the estimate bind them in the loop.
    let (id_model, id_est) = h.identification(est)?;
    let (_, id_val) = h.identification(val)?;
    // Naming needs the shape of the map, not eight digits of it: a looser ADMM tolerance and
    // a coarser β search keep this step at a fraction of a second per fit.
    let identify = IdentifySettings::builder()
        .initial_state(initial_state(hyp.location).0)
        .admm(AdmmSettings::builder().tolerance(1e-4).build()?)
        .build()?;
    // A bound is this hypothesis' failure, reported as such (`failure_reason`): not widened.
    let selection = SelectionSettings::builder()
        .criterion(Criterion::Validation)
        .tolerance(0.25)
        .widen_decades(0.0)
        .build()?;
    let sel = select(&id_model, &id_est, Some(&id_val), &identify, &selection)?;
    if let Some(why) = failure_reason(&sel, &selection) {
        return Err(why);
    }
    let h = h.with_dispersion(Arc::clone(&sel.model.blocks()[0].dispersion));
    finish_fit(
        hyp.location,
        "total variation",
        h,
        sel.identification,
        sel.beta,
        sel.beta_at_bound,
        None,
        &est_h,
        &val_h,
        settings,
        t0,
    )
}

/// Why a total-variation selection is not an estimate, in words, if it is not: the solver
/// stopped before its tolerances at the chosen β (its own words: which residual, how far, where
/// ρ stood), or the validation search of β ran to a bound of its interval.
fn failure_reason(sel: &Selection, selection: &SelectionSettings) -> Option<Error> {
    let d = &sel.identification.diagnostics;
    if !d.status.is_converged() {
        return Some(Error::NotConverged {
            solver: d.solver.name().into(),
            iterations: d.iterations,
            detail: format!(
                "total variation at the selected β = {:.3e}: {}",
                sel.beta,
                d.status_detail
                    .clone()
                    .unwrap_or_else(|| format!("status: {}", d.status))
            ),
        });
    }
    let (lo, hi) = selection.beta_bounds();
    sel.beta_at_bound.map(|bound| {
        let (value, meaning) = match bound {
            Bound::Lower => (
                lo,
                "the least regularised map validated best, so the estimate follows the noise \
                 (overfitting)",
            ),
            Bound::Upper => (
                hi,
                "the most regularised (flat) map validated best, so the data support no map at \
                 this location",
            ),
        };
        Error::BetaAtBound(format!(
            "total variation: the validation selection of β hit the {bound} bound of its search \
             ({value:.0e}; selected β = {:.3e}, on the bound or on a plateau of the validation \
             error reaching it): {meaning}",
            sel.beta
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use structid_core::{Problem, Signal};

    /// A selection of a constant-free TV map on data that are pure noise.
    fn noise_selection(bounds: (f64, f64)) -> (Selection, SelectionSettings) {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let len = 400;
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let n = Normal::new(0.0, 1.0).unwrap();
        let mut draw = |len: usize| -> Vec<f64> { (0..len).map(|_| n.sample(&mut rng)).collect() };
        let (u, y, uv, yv) = (draw(len), draw(len), draw(len), draw(len));
        let g = structid_linear::PolynomialModel {
            den: vec![1.0, -0.5],
            num: vec![vec![0.0, 1.0]],
            sample_time: Some(1.0),
        };
        let h = crate::hypotheses::hypothesis(
            &g,
            crate::hypotheses::Site::Input,
            Arc::new(TotalVariation::new()),
        )
        .unwrap();
        let sig = |v: &[f64]| Signal::from_fn(v.len(), 1, |k, _| v[k]);
        let est = Data::new(sig(&u), sig(&y)).unwrap();
        let val = Data::new(sig(&uv), sig(&yv)).unwrap();
        assert!(Problem::from_model(&h.model, &est).is_ok());
        let identify = IdentifySettings::builder().build().unwrap();
        let selection = SelectionSettings::builder()
            .criterion(Criterion::Validation)
            .beta_bounds(bounds.0, bounds.1)
            .tolerance(0.5)
            .widen_decades(0.0)
            .build()
            .unwrap();
        let sel = select(&h.model, &est, Some(&val), &identify, &selection).unwrap();
        (sel, selection)
    }

    #[test]
    fn beta_run_to_its_upper_bound_on_pure_noise_is_a_failure_in_words() {
        // y is independent of u: a map from u only adds to the validation error, which falls
        // through β = 1e-6…1e-2 (measured 1.05 at 1e-2 against 0.98 at 1e-1), so the search
        // in that interval ends on its upper bound.
        let (sel, selection) = noise_selection((1e-6, 1e-2));
        assert_eq!(
            sel.beta_at_bound,
            Some(Bound::Upper),
            "β = {}: {:?}",
            sel.beta,
            sel.curve
        );
        let why = failure_reason(&sel, &selection)
            .expect("a failure")
            .to_string();
        assert!(why.contains("upper bound"), "{why}");
        assert!(why.contains("no map at"), "{why}");
    }
}

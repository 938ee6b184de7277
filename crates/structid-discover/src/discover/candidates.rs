//! The candidates stage of [`discover`](super::discover): one unknown static block at every
//! location, identified nonparametrically, then refined where the first estimates cannot do
//! (a finer kernel, G refitted with the map, total variation), ranked by validation RMS.

use std::time::Instant;

use structid_core::{Data, Result};

use crate::effects::name_effect;
use crate::hypotheses::{Hypothesis, Nominal, Site};

use super::by_simulation::{beyond_measurability, fitted_by_simulation};
use super::direction::direction_test;
use super::fit::{Fitted, by_validation, identify_hypothesis};
use super::naming::{naming_settings, non_smooth, subsample};
use super::total_variation::total_variation_fit;
use super::{
    DIRECTION_WITHIN, DYNAMIC_JOINT_GAIN, DiscoverSettings, FINER_GAIN, FINER_SIGMA,
    HypothesisResult, failure, noise, refine,
};

/// What the candidates stage works from.
pub(super) struct Search<'a> {
    /// The nominal model as given.
    pub given: &'a Nominal,
    /// The nominal model with its input disturbance, when it has one.
    pub nominal: &'a Nominal,
    pub est: &'a Data,
    pub val: &'a Data,
    pub settings: &'a DiscoverSettings,
    /// The ratio of the input disturbance, if any.
    pub input_noise: Option<f64>,
    /// Every location is refined jointly with G (a G that does not integrate as it should).
    pub uncertain_g: bool,
    /// G's zero cancels its integrator.
    pub cancelled: bool,
    /// The nominal model's validation RMS.
    pub gap_rms: f64,
}

impl<'a> Search<'a> {
    /// The candidates stage's view of the search `cx`; with `uncertain_g` every location is
    /// refined jointly with G.
    pub fn of(cx: &'a super::context::Context<'a>, uncertain_g: bool) -> Self {
        Search {
            given: &cx.given,
            nominal: &cx.nominal,
            est: cx.est,
            val: cx.val,
            settings: &cx.settings,
            input_noise: cx.input_noise,
            uncertain_g,
            cancelled: cx.cancelled.is_some(),
            gap_rms: cx.validation_gap.rms,
        }
    }

    /// Every location's estimates, best validation RMS first, and the failures.
    pub fn candidates(&self) -> (Vec<Fitted>, Vec<HypothesisResult>) {
        let locations = self
            .settings
            .locations
            .clone()
            .unwrap_or_else(|| self.nominal.locations());
        let mut fitted = Vec::new();
        let mut failed = Vec::new();
        for (i, &location) in locations.iter().enumerate() {
            let t = Instant::now();
            match self.identify_at(location, self.settings, true) {
                Ok(f) => fitted.push(f),
                Err(e) => failed.push(failure(location, "", t, &e)),
            }
            self.settings
                .progress
                .report(i as u64 + 1, Some(locations.len() as u64));
        }
        by_validation(&mut fitted);
        if self.closes_little(&fitted) {
            self.finer(&locations, &mut fitted);
        }
        self.refine_with_g(&mut fitted);
        self.total_variation(&mut fitted, &mut failed);
        (fitted, failed)
    }

    /// The disturbance path is a noise model like any other: where it cannot be used (its
    /// whitening filter is unstable when an estimated G has a zero outside the unit circle),
    /// the location is identified with the nominal model's own noise path. A location whose
    /// z the record does not give is fitted by simulation error instead, when
    /// `by_simulation` ([`super::by_simulation`]).
    fn identify_at(
        &self,
        location: Site,
        settings: &DiscoverSettings,
        by_simulation: bool,
    ) -> Result<Fitted> {
        let (est, val) = (self.est, self.val);
        if by_simulation && beyond_measurability(self.given, location, est) {
            return fitted_by_simulation(self.given, location, est, val, settings);
        }
        match identify_hypothesis(self.nominal, location, est, val, settings) {
            Err(_) if self.input_noise.is_some() => {
                identify_hypothesis(self.given, location, est, val, settings)
            }
            Ok(mut f) => {
                f.input_noise = self.input_noise;
                Ok(match self.input_noise {
                    Some(ratio) => {
                        noise::with_smaller_ratio(self.given, f, ratio, est, val, settings)
                    }
                    None => f,
                })
            }
            other => other,
        }
    }

    /// Whether the best estimate closes less than half the gap.
    fn closes_little(&self, fitted: &[Fitted]) -> bool {
        fitted.first().is_none_or(|best| {
            best.result.validation_rms.is_nan() || best.result.validation_rms > 0.5 * self.gap_rms
        })
    }

    /// The maps may have more detail than a kernel of the default width resolves (a cogging
    /// force with several periods over the range of z): every location is identified again
    /// with σ a [`FINER_SIGMA`]-th as wide, and the finer fit replaces the default one only
    /// when it validates clearly better there (a narrower kernel that merely matches the
    /// default one has only more room to fit the noise).
    fn finer(&self, locations: &[Site], fitted: &mut Vec<Fitted>) {
        let finer = DiscoverSettings {
            sigma_fraction: self.settings.sigma_fraction / FINER_SIGMA,
            ..self.settings.clone()
        };
        for &location in locations {
            // A fit by simulation error has its own resolution, the finer pass's kernel not.
            let Ok(f) = self.identify_at(location, &finer, false) else {
                continue;
            };
            let coarse = fitted.iter().position(|c| c.result.location == location);
            match coarse {
                Some(i)
                    if f.result.validation_rms < FINER_GAIN * fitted[i].result.validation_rms =>
                {
                    fitted[i] = f;
                }
                None if f.result.validation_rms.is_finite() => fitted.push(f),
                _ => {}
            }
        }
        by_validation(fitted);
    }

    /// A nominal G estimated from data is biased by the missing effect itself: the best
    /// hypothesis is refined jointly with G, and keeps the new G when it validates better.
    /// Only the best (unless G is uncertain at every location): G refitted around a map at the
    /// wrong location absorbs part of the effect too, and would make that location look as
    /// good as the right one.
    fn refine_with_g(&self, fitted: &mut Vec<Fitted>) {
        let settings = self.settings;
        let uncertain = self.uncertain_g || self.cancelled;
        let Some(g) = self.given.polynomial() else {
            return;
        };
        // A map of the rate depends on the direction of motion and so imitates hysteresis;
        // with G refitted around it, it imitates a backlash well enough to hide it.
        if !settings.refine_nominal
            || !self.given.known_maps().is_empty()
            || !fitted
                .first()
                .is_some_and(|f| uncertain || f.result.location != Site::RateFeedback)
        {
            return;
        }
        // A hysteresis is partly a phase lag, which a refitted G absorbs: when a fit about as
        // good as the best already depends on the direction of its z, a new G must do much
        // more than that to be believed.
        let best_rms = fitted[0].result.validation_rms;
        for f in fitted.iter_mut() {
            if f.result.validation_rms <= DIRECTION_WITHIN * best_rms {
                f.direction = direction_test(f, settings).ok();
            }
        }
        let dynamic = fitted
            .iter()
            .any(|f| f.direction.as_ref().is_some_and(|d| d.dynamic));
        let required = if dynamic { DYNAMIC_JOINT_GAIN } else { 1.0 };
        // A G whose zero cancels its integrator is the direct fit of a closed-loop record,
        // wrong at every location (it tends to the controller's negative inverse): each
        // location is refined with it, its rate included, and the refits compete.
        let joint = if uncertain { fitted.len() } else { 1 };
        let (est, val) = (self.est, self.val);
        let refitted: Vec<Fitted> = fitted
            .drain(..joint)
            .map(|f| refine::refine_jointly(g, f.input_noise, f, est, val, required, settings))
            .collect();
        fitted.extend(refitted);
        by_validation(fitted);
    }

    /// Total variation, where a smooth estimate cannot do: at every location when the best
    /// quadratic estimate closes less than half the gap (steps and jumps that a kernel of
    /// width σ smooths away, e.g. a fine quantiser), else at the best location when a family
    /// with a kink or a jump fits it about as well as the best family (a smoothed kink looks
    /// like a cubic too).
    fn total_variation(&self, fitted: &mut Vec<Fitted>, failed: &mut Vec<HypothesisResult>) {
        let settings = self.settings;
        let Some(best) = fitted.first().filter(|_| settings.total_variation) else {
            return;
        };
        let everywhere = self.closes_little(fitted);
        let kinked = !everywhere && {
            let (zs, ws) = subsample(&best.z, &best.w_hat, settings.naming_points);
            name_effect(&zs, &ws, &naming_settings(settings))
                .ok()
                .map(|n| {
                    let best = n.ranked.iter().map(|f| f.rms).fold(f64::INFINITY, f64::min);
                    n.ranked
                        .iter()
                        .any(|f| f.rms <= 1.25 * best && non_smooth(f.effect))
                })
                .unwrap_or(false)
        };
        let targets: Vec<Hypothesis> = if everywhere {
            fitted.iter().map(|f| f.hypothesis.clone()).collect()
        } else if kinked {
            vec![best.hypothesis.clone()]
        } else {
            Vec::new()
        };
        for h in targets {
            let t = Instant::now();
            match total_variation_fit(&h, self.est, self.val, settings) {
                Ok(f) => fitted.push(f),
                Err(e) => failed.push(failure(h.location, "tv", t, &e)),
            }
        }
        by_validation(fitted);
    }
}

//! The noise model of a nominal model with integrators: how much of the output's wander is a
//! disturbance acting where the input acts.

use structid_core::{Data, Result};
use structid_lti::kalman::{KalmanWhitener, WhiteningOptions};

use crate::hypotheses::Nominal;

use super::DiscoverSettings;
use super::fit::{Fitted, identify_hypothesis};

/// The maximum-likelihood ratio λ of an input disturbance to the output noise
/// ([`Nominal::with_input_noise`]) on the residual r = y − G·u of the nominal model, or `None`
/// when white output noise alone (λ = 0) is at least as likely.
///
/// Gaussian negative log-likelihood of r under y = G·(u + λ·v) + e with v, e white and of one
/// variance s² (profiled out): L·ln(‖W_λ·r‖²/L) + ln det(T_λ·T_λᵀ), W_λ the Kalman whitener of
/// the noise path T_λ = [1, λ·G]. λ is searched on half decades over ten decades around the
/// ratio of the input's to the output's standard deviation. A nominal model with integrators
/// needs this: without it, the output-error criterion makes the map explain the slow wander
/// that every unmodelled force leaves in a position.
///
/// With several records, each record's residual is simulated and whitened from rest on its
/// own, and the likelihood is that of all records (one s² over them).
pub(super) fn input_noise_ratio(nominal: &Nominal, est: &Data) -> Result<Option<f64>> {
    let u = est.u();
    let len = est.len();
    let r: Vec<f64> = {
        let yu = crate::records::stacked(est, |d| nominal.simulate_output(d.u()))?;
        (0..len).map(|k| est.y().get(k, 0) - yu[k]).collect()
    };
    let records = crate::records::parts(&r, est.record_bounds());
    let nll = |n: &Nominal| -> Option<f64> {
        let noise = n.lft().t_ye();
        let (mut sse, mut log_det) = (0.0, 0.0);
        for part in &records {
            let w = KalmanWhitener::new(&noise, part.len(), &WhiteningOptions::default()).ok()?;
            let mut out = vec![0.0; part.len()];
            w.whiten(part, &mut out);
            sse += out.iter().map(|v| v * v).sum::<f64>();
            log_det += w.log_det();
        }
        let v = len as f64 * (sse / len as f64).ln() + log_det;
        v.is_finite().then_some(v)
    };
    let base = nll(nominal);
    let std = |s: &[f64]| {
        let m = s.iter().sum::<f64>() / s.len() as f64;
        (s.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / s.len() as f64).sqrt()
    };
    let scale = std(&u.channel(0)) / std(&est.y().channel(0)).max(f64::MIN_POSITIVE);
    if !(scale.is_finite() && scale > 0.0) {
        return Ok(None);
    }
    let mut best: Option<(f64, f64)> = base.map(|b| (0.0, b));
    for k in -4..=16 {
        let ratio = scale * 10f64.powf(k as f64 / 2.0);
        let Ok(candidate) = nominal.clone().with_input_noise(ratio) else {
            continue;
        };
        if let Some(v) = nll(&candidate)
            && best.is_none_or(|(_, b)| v < b)
        {
            best = Some((ratio, v));
        }
    }
    Ok(best.and_then(|(ratio, _)| (ratio > 0.0).then_some(ratio)))
}

/// How far below the nominal model's ratio the second ratio tried at every location lies (see
/// the module documentation of `discover`).
pub const SMALLER_RATIO: f64 = 1e-2;

/// The hypothesis `fitted`, identified with the input-disturbance ratio `ratio` of the
/// nominal model's residual, or the same location identified with [`SMALLER_RATIO`] times it,
/// whichever validates better (scored as every simulation of the workflow).
///
/// The nominal model's residual holds the missing effect, and an effect that acts where the
/// input acts (a spring's force, an actuator's saturation, friction) is a force the maximum
/// likelihood ratio takes for a disturbance. For a spring or a saturation that inflated ratio
/// leaves the map too little to explain (its β falls to the floor of its search and the
/// location loses to a worse one: a gap spring under a PD controller validated 6× worse at
/// its own site than the truth does); for friction in rate feedback the large ratio is what
/// keeps the map from explaining the position's wander. Neither ratio is right for every
/// effect, so both are tried and the workflow's own measure decides. `given` is the nominal
/// model without the disturbance.
pub(super) fn with_smaller_ratio(
    given: &Nominal,
    fitted: Fitted,
    ratio: f64,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> Fitted {
    let smaller = SMALLER_RATIO * ratio;
    match given
        .clone()
        .with_input_noise(smaller)
        .and_then(|n| identify_hypothesis(&n, fitted.result.location, est, val, settings))
    {
        Ok(mut f) if f.result.validation_rms < fitted.result.validation_rms => {
            f.input_noise = Some(smaller);
            f
        }
        _ => fitted,
    }
}

//! Whether the data determine what makes a family what it is.
//!
//! A family is not named by a fit in which a parameter that defines it is not identifiable:
//!
//! * a **key parameter** ([`Effect::key_parameters`]) whose 95 % interval is not finite or
//!   wider than its value on either side (the data do not tell it from zero);
//! * a **saturation whose slope is a relay's**: the level is reached within
//!   [`RELAY_FRACTION`] of the range of z, so the slope is only bounded below and the
//!   points say "relay": [`Effect::Coulomb`] describes them with one parameter that is
//!   determined (the same for the asymmetric and the smooth saturation);
//! * a **Stribeck curve whose hump is unresolved**: the Stribeck velocity outside
//!   [[`RELAY_FRACTION`], 1] × the range of |z|, a static level not distinguishable from
//!   the Coulomb level (|s − c| ≤ 1.96·sd(s − c)), or one below it (a dip near z = 0 is not
//!   Stribeck friction; it is what a nonparametric estimate that smooths a Coulomb jump
//!   through zero looks like): the family collapses to Coulomb + viscous;
//! * a **power law with its exponent on a bound** (1 or
//!   [`POWER_LAW_MAX_EXPONENT`]);
//! * an **offset that dwarfs the family**: more than [`OFFSET_DOMINANCE`] times the largest
//!   value the family itself takes over the support, so that the constant, not the family,
//!   describes the map (a fit gone astray, e.g. a clip of size 0.1 beside an offset of −10⁴).

use nalgebra::DMatrix;

use super::family::{Effect, POWER_LAW_MAX_EXPONENT};
use super::result::EffectFit;

/// The fraction of the range of z within which a saturation's level must not be reached for
/// its slope to count as identified (1 %: with a few thousand points spread over the range,
/// fewer than a few dozen lie on the slope, and the smoothing of a nonparametric estimate is
/// itself wider than that).
pub const RELAY_FRACTION: f64 = 0.01;

/// An offset larger than this many times the family's own largest value over the support
/// leaves the family nothing to describe (see the module documentation).
pub const OFFSET_DOMINANCE: f64 = 100.0;

/// The reasons `fit` must not name the effect (empty when it may). `cov` is the covariance
/// of the family's parameters (without the offset), used for differences of parameters.
pub(crate) fn flags(fit: &EffectFit, cov: Option<&DMatrix<f64>>) -> Vec<String> {
    let mut out = Vec::new();
    let effect = fit.effect;
    let v = fit.values();
    let span = (fit.support.1 - fit.support.0).max(f64::MIN_POSITIVE);
    let zmax = fit.support.0.abs().max(fit.support.1.abs());
    for name in effect.key_parameters() {
        if let Some(p) = fit.parameter(name).filter(|p| !p.resolved()) {
            out.push(format!(
                "{} = {:.4e} is not resolved (95 % interval [{:.3e}, {:.3e}])",
                p.name, p.value, p.interval.0, p.interval.1
            ));
        }
    }
    if let Some(offset) = fit.offset.as_ref() {
        let own = (0..=64)
            .map(|i| {
                effect
                    .eval(&v, fit.support.0 + span * i as f64 / 64.0)
                    .abs()
            })
            .fold(0.0f64, f64::max);
        if offset.value.abs() > OFFSET_DOMINANCE * own {
            out.push(format!(
                "the offset {:.4e} is more than {OFFSET_DOMINANCE}× the family's own largest \
                 value {own:.3e} over the data: the constant, not the family, describes the map",
                offset.value
            ));
        }
    }
    let linear_width = match effect {
        Effect::Saturation | Effect::SmoothSaturation => Some(2.0 * v[1].abs() / v[0].abs()),
        Effect::AsymmetricSaturation => Some((v[2] - v[1]).abs() / v[0].abs()),
        _ => None,
    };
    if let Some(width) = linear_width
        && (width.is_nan() || width < RELAY_FRACTION * span)
    {
        out.push(format!(
            "the slope is not identifiable: the level is reached within {:.2} % of the range \
             of z (a relay: Coulomb)",
            100.0 * width / span
        ));
    }
    let unresolved_difference = |a: usize, b: usize| -> bool {
        let d = v[a] - v[b];
        let var = cov.map(|c| c[(a, a)] + c[(b, b)] - 2.0 * c[(a, b)]);
        match var {
            Some(var) if var.is_finite() => d.abs() <= 1.96 * var.max(0.0).sqrt(),
            _ => true,
        }
    };
    let stribeck = match effect {
        Effect::Stribeck => Some((v[2], vec![(1, 0)])),
        Effect::AsymmetricStribeck => Some((v[4], vec![(2, 0), (3, 1)])),
        _ => None,
    };
    if let Some((vs, pairs)) = stribeck {
        if !(vs >= RELAY_FRACTION * zmax && vs <= zmax) {
            out.push(format!(
                "the Stribeck velocity {vs:.3e} is outside the data (|z| ≤ {zmax:.3e}): the \
                 curve collapses to Coulomb + viscous"
            ));
        }
        if pairs
            .iter()
            .any(|&(s, c)| v[s].abs() <= v[c].abs() || v[s] * v[c] < 0.0)
        {
            out.push(
                "a static level is not above its Coulomb level (a dip, not a Stribeck hump: \
                 what a smoothed estimate of a Coulomb jump looks like)"
                    .into(),
            );
        }
        if pairs.iter().any(|&(s, c)| unresolved_difference(s, c)) {
            out.push(
                "a static level is not resolved from its Coulomb level: the curve collapses \
                 to Coulomb + viscous"
                    .into(),
            );
        }
    }
    if let Effect::PowerLaw { .. } = effect {
        let p = v[v.len() - 1];
        if p <= 1.0 + 1e-3 || p >= POWER_LAW_MAX_EXPONENT - 1e-3 {
            out.push(format!(
                "the exponent {p:.4} is on its bound [1, {POWER_LAW_MAX_EXPONENT}]"
            ));
        }
    }
    if let Some(r) = fit.refit.as_ref().filter(|r| !r.converged) {
        out.push(format!(
            "the output-error refit did not converge ({})",
            r.status
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::fit::tests::{noisy, points};
    use super::super::{fit_effect, fit_effect_with};
    use super::*;

    /// An offset beside a family of comparable size is a physical offset (a force offset
    /// with Coulomb friction); one that dwarfs the family leaves it nothing to describe.
    #[test]
    fn an_offset_that_dwarfs_the_family_is_flagged() {
        let z = points(400, 41);
        let w = noisy(|z| 0.4 * z.signum() + 0.3, &z, 0.01, 42);
        let fit = fit_effect_with(Effect::Coulomb, true, &z, &w).unwrap();
        let offset = fit.offset.as_ref().unwrap().value;
        assert!((offset - 0.3).abs() < 0.01, "{offset}");
        assert!(!flags(&fit, None).iter().any(|f| f.contains("offset")));
        let mut astray = fit.clone();
        astray.offset.as_mut().unwrap().value = 1.1 * OFFSET_DOMINANCE * 0.4;
        assert!(flags(&astray, None).iter().any(|f| f.contains("offset")));
        astray.offset.as_mut().unwrap().value = 0.9 * OFFSET_DOMINANCE * 0.4;
        assert!(!flags(&astray, None).iter().any(|f| f.contains("offset")));
    }

    #[test]
    fn a_steep_saturation_is_flagged_as_a_relay() {
        // A relay of level 0.5 on z ∈ [−2, 2]: the saturation fit's slope runs away.
        let z = points(400, 31);
        let w = noisy(|z| 0.5 * z.signum(), &z, 0.01, 32);
        for effect in [
            Effect::Saturation,
            Effect::AsymmetricSaturation,
            Effect::SmoothSaturation,
        ] {
            let fit = fit_effect(effect, &z, &w).unwrap();
            assert!(!fit.nameable(), "{}: {:?}", effect.name(), fit.values());
        }
        let relay = fit_effect(Effect::Coulomb, &z, &w).unwrap();
        assert!(relay.nameable(), "{:?}", relay.flags);
        assert!((relay.values()[0] - 0.5).abs() < 0.005);
    }

    #[test]
    fn a_stribeck_curve_without_a_hump_is_flagged() {
        // Coulomb + viscous points: the static level equals the Coulomb level.
        let z = points(400, 33);
        let w = noisy(|z| 0.5 * z.signum() + 0.2 * z, &z, 0.01, 34);
        for effect in [Effect::Stribeck, Effect::AsymmetricStribeck] {
            let fit = fit_effect(effect, &z, &w).unwrap();
            assert!(!fit.nameable(), "{}: {:?}", effect.name(), fit.values());
        }
        // With a hump it is not.
        let truth = [0.5, 1.0, 0.3, 0.2];
        let w = noisy(|z| Effect::Stribeck.eval(&truth, z), &z, 0.01, 35);
        let fit = fit_effect(Effect::Stribeck, &z, &w).unwrap();
        assert!(fit.nameable(), "{:?}", fit.flags);
    }

    #[test]
    fn a_smoothed_coulomb_jump_is_not_a_stribeck_dip() {
        // 0.4·tanh(z/0.1) + 0.1·z: a relay smoothed through zero, as a kernel estimate shows
        // it. A Stribeck fit bends its static level below the Coulomb level to follow it.
        let z = points(400, 40);
        let w = noisy(|z| 0.4 * (z / 0.1).tanh() + 0.1 * z, &z, 0.002, 41);
        let fit = fit_effect_with(Effect::Stribeck, false, &z, &w).unwrap();
        assert!(
            fit.values()[1].abs() < fit.values()[0].abs(),
            "{:?}",
            fit.values()
        );
        assert!(
            fit.flags.iter().any(|f| f.contains("dip")),
            "{:?}",
            fit.flags
        );
    }

    #[test]
    fn a_power_law_on_its_bound_is_flagged() {
        // A linear map: the best exponent is 1, the bound.
        let z = points(400, 36);
        let w = noisy(|z| 0.7 * z, &z, 0.01, 37);
        let fit = fit_effect_with(Effect::PowerLaw { linear: false }, false, &z, &w).unwrap();
        assert!(
            fit.flags.iter().any(|f| f.contains("bound")),
            "{:?} {:?}",
            fit.values(),
            fit.flags
        );
    }

    #[test]
    fn a_key_parameter_without_support_is_flagged() {
        // A dead zone on points that are a pure gain: the width is not resolved.
        let z = points(400, 38);
        let w = noisy(|z| 1.3 * z, &z, 0.05, 39);
        let fit = fit_effect_with(Effect::DeadZone, false, &z, &w).unwrap();
        assert!(!fit.nameable(), "{:?}", fit.parameters);
    }
}

//! Names in the site's physics: what a family is where it acts.
//!
//! A family says what shape a map has; its site says what it is. A map of ẏ subtracted in
//! rate feedback, y = G·(u − N(ẏ)), is a friction force; a map of y in feedback is a
//! restoring force, a stiffness; at the input it is the actuator, at the output the sensor.
//! [`physical_name`] words a fitted family that way. A saturation of ẏ in rate feedback is the
//! usual regularised Coulomb model: its level is the Coulomb level and its knee the smoothing
//! velocity below which the friction is taken as proportional to ẏ.

use crate::hypotheses::Site;

use super::{Effect, EffectFit};

/// The fitted family `fit` named as what it is at `location` (the family's own name at a
/// declared location).
///
/// ```
/// use structid_discover::effects::{Effect, fit_effect, physical_name};
/// use structid_discover::hypotheses::Site;
/// let z: Vec<f64> = (0..200).map(|k| -1.0 + 0.01 * k as f64).collect();
/// let w: Vec<f64> = z.iter().map(|v: &f64| (20.0 * v).clamp(-2.0, 2.0)).collect();
/// let fit = fit_effect(Effect::Saturation, &z, &w).unwrap();
/// assert_eq!(physical_name(&fit, Site::Input), "actuator saturation");
/// let friction = physical_name(&fit, Site::RateFeedback);
/// assert!(friction.starts_with("Coulomb friction 2.0000 smoothed below |ẏ| = 0.1000"), "{friction}");
/// ```
pub fn physical_name(fit: &EffectFit, location: Site) -> String {
    match location {
        Site::RateFeedback => friction(fit),
        Site::OutputFeedback => stiffness(fit),
        Site::Input => format!("actuator {}", shape(fit.effect)),
        Site::Output => format!("sensor {}", shape(fit.effect)),
        _ => fit.effect.name(),
    }
}

/// A family's name as a shape, for an actuator's or a sensor's map: the families named after
/// a force (a relay is Coulomb friction in rate feedback, a cubic a stiffness in position
/// feedback) are named by their shape there.
fn shape(effect: Effect) -> String {
    match effect {
        Effect::Coulomb => "relay (on–off)".into(),
        Effect::OddPolynomial { degree } => format!("odd polynomial (degree {degree})"),
        other => other.name(),
    }
}

/// A parameter's value by name.
fn value(fit: &EffectFit, name: &str) -> Option<f64> {
    fit.parameters
        .iter()
        .find(|p| p.name == name)
        .map(|p| p.value)
}

/// Whether any of the parameters `names` that the fit carries is negative: a slope, a level
/// or a stiffness whose force then aids the motion instead of opposing it.
fn any_negative(fit: &EffectFit, names: &[&str]) -> bool {
    names.iter().any(|n| value(fit, n).is_some_and(|v| v < 0.0))
}

/// A map of ẏ subtracted from the force: a friction when it opposes the motion.
fn friction(fit: &EffectFit) -> String {
    let family = fit.effect.name();
    let opposing = [
        "gain",
        "coulomb",
        "coulomb_pos",
        "coulomb_neg",
        "static",
        "static_pos",
        "static_neg",
    ];
    if any_negative(fit, &opposing) {
        return format!("force aiding the motion, negative damping ({family} of ẏ)");
    }
    let gain = value(fit, "gain");
    let gain = gain.filter(|k| *k > 0.0);
    match fit.effect {
        Effect::Coulomb
        | Effect::CoulombViscous
        | Effect::Stribeck
        | Effect::AsymmetricCoulombViscous
        | Effect::AsymmetricStribeck => family,
        Effect::Saturation | Effect::SmoothSaturation => match (gain, value(fit, "level")) {
            (Some(k), Some(level)) => format!(
                "Coulomb friction {level:.4} smoothed below |ẏ| = {:.4} ({family} of ẏ)",
                level / k
            ),
            _ => format!("friction: {family} of ẏ"),
        },
        Effect::AsymmetricSaturation => match (gain, value(fit, "lower"), value(fit, "upper")) {
            // Each direction has its own level and so its own knee.
            (Some(k), Some(lower), Some(upper)) => format!(
                "asymmetric Coulomb friction {upper:.4} / {:.4} smoothed for {:.4} < ẏ < {:.4} \
                 ({family} of ẏ)",
                -lower,
                lower / k,
                upper / k
            ),
            _ => format!("friction: {family} of ẏ"),
        },
        Effect::Gain => format!("viscous friction ({family} of ẏ)"),
        _ => format!("friction: {family} of ẏ"),
    }
}

/// A map of y subtracted from the force: a restoring force when its slope is positive.
fn stiffness(fit: &EffectFit) -> String {
    let family = fit.effect.name();
    if any_negative(fit, &["gain", "stiffness"]) {
        return format!("negative stiffness ({family} of y)");
    }
    match fit.effect {
        Effect::OddPolynomial { degree: 3 } | Effect::GapSpring | Effect::PowerLaw { .. } => family,
        Effect::Gain => format!("linear stiffness ({family} of y)"),
        Effect::Saturation | Effect::SmoothSaturation | Effect::AsymmetricSaturation => {
            format!("softening spring ({family} of y)")
        }
        _ => format!("stiffness: {family} of y"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::fit_effect;

    fn fitted(effect: Effect, f: impl Fn(f64) -> f64) -> EffectFit {
        let z: Vec<f64> = (0..400).map(|k| -2.0 + 0.01 * k as f64).collect();
        let w: Vec<f64> = z.iter().map(|v| f(*v)).collect();
        fit_effect(effect, &z, &w).unwrap()
    }

    #[test]
    fn a_force_that_aids_the_motion_is_not_called_friction_or_stiffness() {
        let gain = fitted(Effect::Gain, |z| -3.0 * z);
        assert!(physical_name(&gain, Site::RateFeedback).starts_with("force aiding"));
        assert!(physical_name(&gain, Site::OutputFeedback).starts_with("negative stiffness"));
        let aiding = fitted(Effect::Coulomb, |z| -0.4 * z.signum());
        assert!(physical_name(&aiding, Site::RateFeedback).starts_with("force aiding"));
        let relay = fitted(Effect::Coulomb, |z| 0.4 * z.signum());
        assert_eq!(
            physical_name(&relay, Site::Input),
            "actuator relay (on–off)"
        );
        assert_eq!(
            physical_name(&relay, Site::RateFeedback),
            Effect::Coulomb.name()
        );
    }

    #[test]
    fn every_site_names_its_physics() {
        let gain = fitted(Effect::Gain, |z| 3.0 * z);
        assert_eq!(physical_name(&gain, Site::Input), "actuator gain error");
        assert_eq!(physical_name(&gain, Site::Output), "sensor gain error");
        assert!(physical_name(&gain, Site::OutputFeedback).starts_with("linear stiffness"));
        assert!(physical_name(&gain, Site::RateFeedback).starts_with("viscous friction"));
        let coulomb = fitted(Effect::CoulombViscous, |z| 0.5 * z.signum() + 0.2 * z);
        assert_eq!(
            physical_name(&coulomb, Site::RateFeedback),
            "Coulomb + viscous friction"
        );
        let cubic = fitted(Effect::OddPolynomial { degree: 3 }, |z| z + 0.5 * z.powi(3));
        assert_eq!(
            physical_name(&cubic, Site::OutputFeedback),
            Effect::OddPolynomial { degree: 3 }.name()
        );
    }

    /// The regularised Coulomb reading of a saturation of ẏ: its level, and its knee
    /// level/gain as the smoothing velocity.
    #[test]
    fn a_saturation_of_the_rate_is_a_smoothed_coulomb_friction() {
        let sat = fitted(Effect::AsymmetricSaturation, |z| (8.0 * z).clamp(-1.5, 2.0));
        let name = physical_name(&sat, Site::RateFeedback);
        assert!(
            name.starts_with(
                "asymmetric Coulomb friction 2.0000 / 1.5000 smoothed for -0.1875 < ẏ < 0.2500"
            ),
            "{name}"
        );
        let sat = fitted(Effect::Saturation, |z| (4.0 * z).clamp(-1.0, 1.0));
        assert!(
            physical_name(&sat, Site::RateFeedback)
                .starts_with("Coulomb friction 1.0000 smoothed below |ẏ| = 0.2500"),
        );
    }
}

//! The families: their formulas, parameter names, expressions and the sites they are offered
//! at.

use structid_core::Site;

/// The largest exponent of [`Effect::PowerLaw`]: its `exponent` p is held in [1, 8] and a fit
/// that ends on either bound is not named (the data do not resolve p).
pub const POWER_LAW_MAX_EXPONENT: f64 = 8.0;

/// A parametric family of static maps.
///
/// Every family except [`Effect::Offset`], [`Effect::EvenPolynomial`] (which has its own
/// constant `a0`), [`Effect::Quantisation`] and the two asymmetric friction families (whose
/// separate levels per direction already absorb a constant) may also carry an offset c,
/// f(z; θ) + c: see [`EffectFit::offset`](super::EffectFit::offset) and
/// [`Effect::takes_offset`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum Effect {
    /// Symmetric saturation f = clamp(k·z, −s, s); parameters `gain` k, `level` s > 0.
    Saturation,
    /// Asymmetric saturation f = clamp(k·z, lower, upper); parameters `gain`, `lower` < 0 <
    /// `upper`.
    AsymmetricSaturation,
    /// Dead zone f = k·(z − d) above d, k·(z + d) below −d, 0 between; parameters `gain` k,
    /// `width` d > 0. Offered at the input and output (an actuator or sensor dead band).
    DeadZone,
    /// Coulomb plus viscous friction f = c·sign(z) + v·z; parameters `coulomb` c, `viscous` v.
    CoulombViscous,
    /// Stribeck friction f = (c + (s − c)·exp(−(z/v_s)²))·sign(z) + v·z; parameters `coulomb`
    /// c, `static` s, `stribeck_velocity` v_s > 0, `viscous` v.
    Stribeck,
    /// Odd polynomial Σ a_j·z^j over odd j ≤ degree (a cubic stiffness is degree 3, with the
    /// linear term); parameters `a1`, `a3`, ….
    OddPolynomial {
        /// Highest (odd) power.
        degree: u32,
    },
    /// Even polynomial Σ a_j·z^j over even j ≤ degree; parameters `a0`, `a2`, ….
    EvenPolynomial {
        /// Highest (even) power.
        degree: u32,
    },
    /// Uniform quantiser f = q·round(z/q); parameter `step` q > 0.
    Quantisation,
    /// Constant offset f = c; parameter `offset`.
    Offset,
    /// Gain f = k·z; parameter `gain`. A gain error means the linear model was wrong.
    Gain,
    /// Coulomb friction alone, a relay: f = c·sign(z); parameter `coulomb` c. This is also
    /// what a saturation becomes when its slope is not identifiable (the level is reached
    /// within a tiny fraction of the range of z), so it is offered at every site: an on–off
    /// actuator or sensor at the input or output, friction in rate feedback.
    Coulomb,
    /// Asymmetric Coulomb plus viscous friction
    ///
    /// ```text
    ///   f = Fc⁺ + Fv⁺·z   (z > 0),     f = −Fc⁻ + Fv⁻·z   (z < 0),     f(0) = 0
    /// ```
    ///
    /// parameters `coulomb_pos` Fc⁺, `coulomb_neg` Fc⁻ (both positive for friction that
    /// opposes motion), `viscous_pos` Fv⁺, `viscous_neg` Fv⁻. A symmetric Coulomb level plus a
    /// constant force is the special case Fv⁺ = Fv⁻, which [`Effect::CoulombViscous`] with an
    /// offset describes with one parameter fewer.
    AsymmetricCoulombViscous,
    /// Stribeck friction with separate Coulomb and static levels per direction
    ///
    /// ```text
    ///   f = +(Fc⁺ + (Fs⁺ − Fc⁺)·exp(−(z/v_s)²)) + Fv·z   (z > 0)
    ///   f = −(Fc⁻ + (Fs⁻ − Fc⁻)·exp(−(z/v_s)²)) + Fv·z   (z < 0)
    /// ```
    ///
    /// parameters `coulomb_pos` Fc⁺, `coulomb_neg` Fc⁻, `static_pos` Fs⁺, `static_neg` Fs⁻,
    /// `stribeck_velocity` v_s > 0 and `viscous` Fv. One Stribeck velocity and one viscous
    /// slope are shared by both directions: both are properties of the lubricant film rather
    /// than of the direction, a per-direction slope trades off against the Coulomb level of
    /// its own side when that side's speed range is short, and a seventh parameter would
    /// leave the hump (the part that makes this family Stribeck) worse determined.
    /// Per-direction viscous slopes are [`Effect::AsymmetricCoulombViscous`].
    AsymmetricStribeck,
    /// Contact (gap) spring f = k·(z − g) above g, k·(z + g) below −g, 0 between; parameters
    /// `stiffness` k, `gap` g > 0. The shape of [`Effect::DeadZone`], offered in feedback
    /// from the output, where a stiffness that engages after a clearance is what it means.
    GapSpring,
    /// Hardening power law f = k·z·|z|^(p−1) (p in (1, 8]), with `linear` also a linear term
    /// a1·z; parameters `stiffness` k, `exponent` p, with `linear` first `a1`. p = 2 is the
    /// quadratic spring y·|y|, p = 3 the cubic.
    PowerLaw {
        /// Whether the family has the linear term a1·z.
        linear: bool,
    },
    /// One-sided clipping from above, f = min(k·z, s); parameters `gain` k, `level` s.
    ClipAbove,
    /// One-sided clipping from below, f = max(k·z, s); parameters `gain` k, `level` s.
    ClipBelow,
    /// Rectification f = k·max(z, 0) (`positive`) or k·min(z, 0); parameter `gain` k.
    Rectification {
        /// Whether the positive half passes.
        positive: bool,
    },
    /// Smooth saturation f = s·tanh(k·z/s); parameters `gain` k (the slope at 0) and `level`
    /// s > 0 (the asymptote). An approximation of soft saturating sensors and actuators, not
    /// a physical law: its parameters describe the shape, and the hard
    /// [`Effect::Saturation`] is preferred when the knee is sharp.
    SmoothSaturation,
}

fn sign(z: f64) -> f64 {
    if z > 0.0 {
        1.0
    } else if z < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// The shortest representation that reads back to the same f64 (`{v:?}`), written out in
/// positional notation when that one has an exponent (`1e-5`), which the expression parser
/// does not read.
pub(crate) fn n(v: f64) -> String {
    let short = format!("{v:?}");
    if short.contains('e') {
        format!("{v}")
    } else {
        short
    }
}

impl Effect {
    /// The default library, simplest families first. Where two families have the same shape
    /// (the dead zone and the gap spring), the earlier wins a tie; in discovery each site is
    /// offered only the families that make sense there ([`Effect::library_at`]).
    pub const LIBRARY: [Effect; 21] = [
        Effect::Offset,
        Effect::Gain,
        Effect::Coulomb,
        Effect::Rectification { positive: true },
        Effect::Rectification { positive: false },
        Effect::OddPolynomial { degree: 3 },
        Effect::EvenPolynomial { degree: 2 },
        Effect::Saturation,
        Effect::SmoothSaturation,
        Effect::ClipAbove,
        Effect::ClipBelow,
        Effect::AsymmetricSaturation,
        Effect::DeadZone,
        Effect::GapSpring,
        Effect::PowerLaw { linear: false },
        Effect::PowerLaw { linear: true },
        Effect::CoulombViscous,
        Effect::AsymmetricCoulombViscous,
        Effect::Stribeck,
        Effect::AsymmetricStribeck,
        Effect::Quantisation,
    ];

    /// Whether the family is offered at `site`: a dead zone at the input and output, a gap
    /// spring in feedback from the output, the friction families (Coulomb + viscous,
    /// Stribeck and their asymmetric forms) in feedback from the rate; every other family,
    /// and every family at a declared site, everywhere.
    ///
    /// ```
    /// use structid_core::Site;
    /// use structid_discover::effects::Effect;
    /// assert!(Effect::DeadZone.applies_at(Site::Input));
    /// assert!(!Effect::DeadZone.applies_at(Site::OutputFeedback));
    /// assert!(Effect::GapSpring.applies_at(Site::OutputFeedback));
    /// assert!(!Effect::Stribeck.applies_at(Site::Output));
    /// assert!(Effect::Stribeck.applies_at(Site::Declared { z: 0, w: 0 }));
    /// ```
    pub fn applies_at(&self, site: Site) -> bool {
        match site {
            Site::Declared { .. } => true,
            _ => match self {
                Effect::DeadZone => matches!(site, Site::Input | Site::Output),
                Effect::GapSpring => site == Site::OutputFeedback,
                Effect::CoulombViscous
                | Effect::AsymmetricCoulombViscous
                | Effect::Stribeck
                | Effect::AsymmetricStribeck => site == Site::RateFeedback,
                _ => true,
            },
        }
    }

    /// The families of `library` offered at `site` ([`Effect::applies_at`]), in order.
    ///
    /// ```
    /// use structid_core::Site;
    /// use structid_discover::effects::Effect;
    /// let rate = Effect::library_at(&Effect::LIBRARY, Site::RateFeedback);
    /// assert!(rate.contains(&Effect::AsymmetricStribeck) && !rate.contains(&Effect::GapSpring));
    /// ```
    pub fn library_at(library: &[Effect], site: Site) -> Vec<Effect> {
        library
            .iter()
            .copied()
            .filter(|e| e.applies_at(site))
            .collect()
    }

    /// Whether the family may carry an offset c (f + c). Not for the offset itself, the even
    /// polynomial (its `a0`), the quantiser, and the asymmetric friction families, where a
    /// constant is absorbed by the separate levels per direction and so is not identifiable.
    pub fn takes_offset(&self) -> bool {
        !matches!(
            self,
            Effect::Offset
                | Effect::EvenPolynomial { .. }
                | Effect::Quantisation
                | Effect::AsymmetricCoulombViscous
                | Effect::AsymmetricStribeck
        )
    }

    /// The family with the same shape under another name, whose fit is therefore the same
    /// (the dead zone and the gap spring).
    pub(crate) fn shape_twin(&self) -> Option<Effect> {
        match self {
            Effect::DeadZone => Some(Effect::GapSpring),
            Effect::GapSpring => Some(Effect::DeadZone),
            _ => None,
        }
    }

    /// A short name for reports, e.g. `saturation` or `odd polynomial (degree 3)`.
    pub fn name(&self) -> String {
        match self {
            Effect::Saturation => "saturation".into(),
            Effect::AsymmetricSaturation => "asymmetric saturation".into(),
            Effect::DeadZone => "dead zone".into(),
            Effect::CoulombViscous => "Coulomb + viscous friction".into(),
            Effect::Stribeck => "Stribeck friction".into(),
            Effect::OddPolynomial { degree: 3 } => {
                "cubic stiffness (odd polynomial, degree 3)".into()
            }
            Effect::OddPolynomial { degree } => format!("odd polynomial (degree {degree})"),
            Effect::EvenPolynomial { degree } => format!("even polynomial (degree {degree})"),
            Effect::Quantisation => "quantisation".into(),
            Effect::Offset => "offset".into(),
            Effect::Gain => "gain error".into(),
            Effect::Coulomb => "Coulomb friction (relay)".into(),
            Effect::AsymmetricCoulombViscous => "asymmetric Coulomb + viscous friction".into(),
            Effect::AsymmetricStribeck => "asymmetric Stribeck friction".into(),
            Effect::GapSpring => "contact (gap) spring".into(),
            Effect::PowerLaw { linear: false } => "hardening power law".into(),
            Effect::PowerLaw { linear: true } => "hardening power law with linear term".into(),
            Effect::ClipAbove => "one-sided clipping (from above)".into(),
            Effect::ClipBelow => "one-sided clipping (from below)".into(),
            Effect::Rectification { positive: true } => "rectification (positive half)".into(),
            Effect::Rectification { positive: false } => "rectification (negative half)".into(),
            Effect::SmoothSaturation => "smooth saturation (tanh, approximate)".into(),
        }
    }

    /// The parameter names, in the order of [`EffectFit::parameters`](super::EffectFit).
    pub fn parameter_names(&self) -> Vec<String> {
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect();
        match self {
            Effect::Saturation | Effect::SmoothSaturation => s(&["gain", "level"]),
            Effect::AsymmetricSaturation => s(&["gain", "lower", "upper"]),
            Effect::DeadZone => s(&["gain", "width"]),
            Effect::CoulombViscous => s(&["coulomb", "viscous"]),
            Effect::Stribeck => s(&["coulomb", "static", "stribeck_velocity", "viscous"]),
            Effect::OddPolynomial { degree } => {
                (1..=*degree).step_by(2).map(|j| format!("a{j}")).collect()
            }
            Effect::EvenPolynomial { degree } => {
                (0..=*degree).step_by(2).map(|j| format!("a{j}")).collect()
            }
            Effect::Quantisation => s(&["step"]),
            Effect::Offset => s(&["offset"]),
            Effect::Gain | Effect::Rectification { .. } => s(&["gain"]),
            Effect::Coulomb => s(&["coulomb"]),
            Effect::AsymmetricCoulombViscous => {
                s(&["coulomb_pos", "coulomb_neg", "viscous_pos", "viscous_neg"])
            }
            Effect::AsymmetricStribeck => s(&[
                "coulomb_pos",
                "coulomb_neg",
                "static_pos",
                "static_neg",
                "stribeck_velocity",
                "viscous",
            ]),
            Effect::GapSpring => s(&["stiffness", "gap"]),
            Effect::PowerLaw { linear: false } => s(&["stiffness", "exponent"]),
            Effect::PowerLaw { linear: true } => s(&["a1", "stiffness", "exponent"]),
            Effect::ClipAbove | Effect::ClipBelow => s(&["gain", "level"]),
        }
    }

    /// The parameters that make the family what it is: a fit in which one of them is not
    /// resolved (its 95 % interval is not finite or wider than its value on either side) is
    /// not named by this family.
    pub fn key_parameters(&self) -> Vec<&'static str> {
        match self {
            Effect::Saturation | Effect::SmoothSaturation => vec!["gain", "level"],
            Effect::AsymmetricSaturation => vec!["gain", "lower", "upper"],
            Effect::DeadZone => vec!["gain", "width"],
            Effect::GapSpring => vec!["stiffness", "gap"],
            Effect::Coulomb | Effect::CoulombViscous => vec!["coulomb"],
            Effect::AsymmetricCoulombViscous => vec!["coulomb_pos", "coulomb_neg"],
            Effect::Stribeck => vec!["coulomb", "static", "stribeck_velocity"],
            Effect::AsymmetricStribeck => vec!["stribeck_velocity"],
            // The highest power is what distinguishes the polynomial from the gain below it.
            Effect::OddPolynomial { degree: 1 } => vec!["a1"],
            Effect::OddPolynomial { .. } => vec!["a3"],
            Effect::EvenPolynomial { .. } => vec!["a2"],
            Effect::Quantisation => vec![],
            Effect::Offset => vec!["offset"],
            Effect::Gain | Effect::Rectification { .. } | Effect::ClipAbove | Effect::ClipBelow => {
                vec!["gain"]
            }
            Effect::PowerLaw { .. } => vec!["stiffness", "exponent"],
        }
    }

    /// f(z; θ), without an offset.
    ///
    /// ```
    /// use structid_discover::effects::Effect;
    /// assert_eq!(Effect::Saturation.eval(&[2.0, 1.0], 0.3), 0.6);
    /// assert_eq!(Effect::Saturation.eval(&[2.0, 1.0], -3.0), -1.0);
    /// assert_eq!(Effect::DeadZone.eval(&[2.0, 0.5], 0.2), 0.0);
    /// assert_eq!(Effect::Quantisation.eval(&[0.5], 0.74), 0.5);
    /// assert_eq!(Effect::AsymmetricCoulombViscous.eval(&[1.0, 2.0, 0.5, 0.25], -2.0), -2.5);
    /// assert_eq!(Effect::PowerLaw { linear: false }.eval(&[3.0, 2.0], -2.0), -12.0);
    /// ```
    pub fn eval(&self, theta: &[f64], z: f64) -> f64 {
        match self {
            Effect::Saturation => {
                let s = theta[1].abs();
                (theta[0] * z).clamp(-s, s)
            }
            Effect::AsymmetricSaturation => {
                let (lo, hi) = (theta[1].min(theta[2]), theta[1].max(theta[2]));
                (theta[0] * z).clamp(lo, hi)
            }
            Effect::DeadZone | Effect::GapSpring => {
                let d = theta[1].abs();
                if z > d {
                    theta[0] * (z - d)
                } else if z < -d {
                    theta[0] * (z + d)
                } else {
                    0.0
                }
            }
            Effect::CoulombViscous => theta[0] * sign(z) + theta[1] * z,
            Effect::Stribeck => {
                let vs = theta[2].abs().max(f64::MIN_POSITIVE);
                (theta[0] + (theta[1] - theta[0]) * (-(z / vs).powi(2)).exp()) * sign(z)
                    + theta[3] * z
            }
            Effect::OddPolynomial { .. } | Effect::EvenPolynomial { .. } => {
                let first = if matches!(self, Effect::OddPolynomial { .. }) {
                    1
                } else {
                    0
                };
                theta
                    .iter()
                    .enumerate()
                    .map(|(i, a)| a * z.powi(first + 2 * i as i32))
                    .sum()
            }
            Effect::Quantisation => {
                let q = theta[0].abs().max(f64::MIN_POSITIVE);
                q * (z / q).round()
            }
            Effect::Offset => theta[0],
            Effect::Gain => theta[0] * z,
            Effect::Coulomb => theta[0] * sign(z),
            Effect::AsymmetricCoulombViscous => {
                if z > 0.0 {
                    theta[0] + theta[2] * z
                } else if z < 0.0 {
                    -theta[1] + theta[3] * z
                } else {
                    0.0
                }
            }
            Effect::AsymmetricStribeck => {
                let vs = theta[4].abs().max(f64::MIN_POSITIVE);
                let e = (-(z / vs).powi(2)).exp();
                let level = if z > 0.0 {
                    theta[0] + (theta[2] - theta[0]) * e
                } else if z < 0.0 {
                    -(theta[1] + (theta[3] - theta[1]) * e)
                } else {
                    0.0
                };
                level + theta[5] * z
            }
            Effect::PowerLaw { linear } => {
                let (a1, k, p) = if *linear {
                    (theta[0], theta[1], theta[2])
                } else {
                    (0.0, theta[0], theta[1])
                };
                a1 * z + k * power(z, p)
            }
            Effect::ClipAbove => (theta[0] * z).min(theta[1]),
            Effect::ClipBelow => (theta[0] * z).max(theta[1]),
            Effect::Rectification { positive: true } => theta[0] * z.max(0.0),
            Effect::Rectification { positive: false } => theta[0] * z.min(0.0),
            Effect::SmoothSaturation => {
                let s = theta[1].abs().max(f64::MIN_POSITIVE);
                s * (theta[0] * z / s).tanh()
            }
        }
    }

    /// The map as an expression in `z0` (the syntax of model-file `truth` expressions),
    /// without an offset.
    ///
    /// ```
    /// use structid_discover::effects::Effect;
    /// assert_eq!(Effect::CoulombViscous.expression(&[0.8, 0.3]), "0.8*signum(z0) + 0.3*z0");
    /// ```
    pub fn expression(&self, theta: &[f64]) -> String {
        // (1 ± signum(z0))/2: the indicator of each direction.
        const POS: &str = "0.5*(1 + signum(z0))";
        const NEG: &str = "0.5*(1 - signum(z0))";
        match self {
            Effect::Saturation => {
                let s = theta[1].abs();
                format!("min(max({}*z0, {}), {})", n(theta[0]), n(-s), n(s))
            }
            Effect::AsymmetricSaturation => {
                let (lo, hi) = (theta[1].min(theta[2]), theta[1].max(theta[2]));
                format!("min(max({}*z0, {}), {})", n(theta[0]), n(lo), n(hi))
            }
            Effect::DeadZone | Effect::GapSpring => {
                let d = theta[1].abs();
                format!(
                    "{}*(max(z0 - {}, 0) + min(z0 + {}, 0))",
                    n(theta[0]),
                    n(d),
                    n(d)
                )
            }
            Effect::CoulombViscous => {
                format!("{}*signum(z0) + {}*z0", n(theta[0]), n(theta[1]))
            }
            Effect::Stribeck => format!(
                "({} + ({} - {})*exp(-((z0/{})^2)))*signum(z0) + {}*z0",
                n(theta[0]),
                n(theta[1]),
                n(theta[0]),
                n(theta[2].abs()),
                n(theta[3])
            ),
            Effect::OddPolynomial { .. } | Effect::EvenPolynomial { .. } => {
                let first = usize::from(matches!(self, Effect::OddPolynomial { .. }));
                theta
                    .iter()
                    .enumerate()
                    .map(|(i, a)| match first + 2 * i {
                        0 => n(*a),
                        1 => format!("{}*z0", n(*a)),
                        p => format!("{}*z0^{p}", n(*a)),
                    })
                    .collect::<Vec<_>>()
                    .join(" + ")
            }
            Effect::Quantisation => {
                let q = theta[0].abs();
                format!("{}*round(z0/{})", n(q), n(q))
            }
            Effect::Offset => n(theta[0]),
            Effect::Gain => format!("{}*z0", n(theta[0])),
            Effect::Coulomb => format!("{}*signum(z0)", n(theta[0])),
            Effect::AsymmetricCoulombViscous => format!(
                "{}*{POS} - {}*{NEG} + {}*max(z0, 0) + {}*min(z0, 0)",
                n(theta[0]),
                n(theta[1]),
                n(theta[2]),
                n(theta[3])
            ),
            Effect::AsymmetricStribeck => {
                let e = format!("exp(-((z0/{})^2))", n(theta[4].abs()));
                format!(
                    "{POS}*({} + ({} - {})*{e}) - {NEG}*({} + ({} - {})*{e}) + {}*z0",
                    n(theta[0]),
                    n(theta[2]),
                    n(theta[0]),
                    n(theta[1]),
                    n(theta[3]),
                    n(theta[1]),
                    n(theta[5])
                )
            }
            Effect::PowerLaw { linear } => {
                let (k, p) = if *linear {
                    (theta[1], theta[2])
                } else {
                    (theta[0], theta[1])
                };
                let p = p.clamp(1.0, POWER_LAW_MAX_EXPONENT);
                let law = format!("{}*z0*abs(z0)^{}", n(k), n(p - 1.0));
                if *linear {
                    format!("{}*z0 + {law}", n(theta[0]))
                } else {
                    law
                }
            }
            Effect::ClipAbove => format!("min({}*z0, {})", n(theta[0]), n(theta[1])),
            Effect::ClipBelow => format!("max({}*z0, {})", n(theta[0]), n(theta[1])),
            Effect::Rectification { positive: true } => format!("{}*max(z0, 0)", n(theta[0])),
            Effect::Rectification { positive: false } => format!("{}*min(z0, 0)", n(theta[0])),
            Effect::SmoothSaturation => {
                let s = theta[1].abs();
                format!("{}*tanh({}*z0/{})", n(s), n(theta[0]), n(s))
            }
        }
    }

    /// Columns of the regression when the family is linear in θ, else `None`.
    pub(crate) fn regressors(&self, z: f64) -> Option<Vec<f64>> {
        let (pos, neg) = (f64::from(z > 0.0), f64::from(z < 0.0));
        match self {
            Effect::CoulombViscous => Some(vec![sign(z), z]),
            Effect::OddPolynomial { degree } => {
                Some((1..=*degree).step_by(2).map(|j| z.powi(j as i32)).collect())
            }
            Effect::EvenPolynomial { degree } => {
                Some((0..=*degree).step_by(2).map(|j| z.powi(j as i32)).collect())
            }
            Effect::Offset => Some(vec![1.0]),
            Effect::Gain => Some(vec![z]),
            Effect::Coulomb => Some(vec![sign(z)]),
            Effect::AsymmetricCoulombViscous => Some(vec![pos, -neg, pos * z, neg * z]),
            Effect::Rectification { positive: true } => Some(vec![z.max(0.0)]),
            Effect::Rectification { positive: false } => Some(vec![z.min(0.0)]),
            _ => None,
        }
    }

    /// Parameters in their documented form (positive levels, widths and steps; ordered
    /// bounds; the power law's exponent inside its range).
    pub(crate) fn canonical(&self, mut theta: Vec<f64>) -> Vec<f64> {
        match self {
            Effect::Saturation
            | Effect::DeadZone
            | Effect::GapSpring
            | Effect::SmoothSaturation => theta[1] = theta[1].abs(),
            Effect::AsymmetricSaturation if theta[1] > theta[2] => theta.swap(1, 2),
            Effect::Stribeck => theta[2] = theta[2].abs(),
            Effect::AsymmetricStribeck => theta[4] = theta[4].abs(),
            Effect::Quantisation => theta[0] = theta[0].abs(),
            Effect::PowerLaw { .. } => {
                let last = theta.len() - 1;
                theta[last] = theta[last].clamp(1.0, POWER_LAW_MAX_EXPONENT);
            }
            _ => {}
        }
        theta
    }
}

/// z·|z|^(p−1) with p held in [1, [`POWER_LAW_MAX_EXPONENT`]].
fn power(z: f64, p: f64) -> f64 {
    let p = p.clamp(1.0, POWER_LAW_MAX_EXPONENT);
    if z == 0.0 {
        0.0
    } else {
        z * z.abs().powf(p - 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_core::{ExprMap, Interpolant};

    /// Typical parameters of each family.
    fn theta(effect: Effect) -> Vec<f64> {
        match effect {
            Effect::Saturation | Effect::SmoothSaturation => vec![1.5, 1.2],
            Effect::AsymmetricSaturation => vec![1.0, -0.6, 1.3],
            Effect::DeadZone | Effect::GapSpring => vec![1.2, 0.5],
            Effect::CoulombViscous => vec![0.6, 0.3],
            Effect::Stribeck => vec![0.5, 1.0, 0.3, 0.2],
            Effect::OddPolynomial { .. } => vec![0.4, 0.5],
            Effect::EvenPolynomial { .. } => vec![0.1, 0.6],
            Effect::Quantisation => vec![0.5],
            Effect::Offset => vec![0.7],
            Effect::Gain | Effect::Rectification { .. } => vec![1.7],
            Effect::Coulomb => vec![0.4],
            Effect::AsymmetricCoulombViscous => vec![0.5, 0.8, 0.2, 0.4],
            Effect::AsymmetricStribeck => vec![0.5, 0.7, 1.0, 1.2, 0.3, 0.2],
            Effect::PowerLaw { linear: false } => vec![0.8, 2.5],
            Effect::PowerLaw { linear: true } => vec![0.3, 0.8, 2.5],
            Effect::ClipAbove => vec![1.5, 0.9],
            Effect::ClipBelow => vec![1.5, -0.4],
        }
    }

    #[test]
    fn every_expression_evaluates_like_its_family() {
        for effect in Effect::LIBRARY {
            let th = theta(effect);
            assert_eq!(th.len(), effect.parameter_names().len(), "{effect:?}");
            let m = ExprMap::parse(&effect.expression(&th), 1)
                .unwrap_or_else(|e| panic!("{effect:?}: {e}"));
            for k in 0..81 {
                // Away from 0 and the quantiser's half steps, where the forms may differ by
                // the value of signum(0) or the rounding of a tie.
                let z = -2.0 + 0.05 * k as f64 + 0.013;
                let (a, b) = (effect.eval(&th, z), m.eval(&[z]));
                assert!((a - b).abs() < 1e-12, "{effect:?} at {z}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn tiny_and_huge_numbers_print_in_a_form_the_parser_reads() {
        for v in [8.69e-5, -2.06e-5, 1e-300, 2.87e52, 0.5, -3.0] {
            let m = ExprMap::parse(&format!("{}*z0 + {}", n(v), n(-v)), 1).unwrap();
            assert_eq!(m.eval(&[1.0]), v - v, "{}", n(v));
            assert_eq!(n(v).parse::<f64>().unwrap(), v);
        }
    }

    #[test]
    fn new_families_follow_their_closed_forms() {
        // Asymmetric friction: the levels on each side, and zero at rest.
        let acv = Effect::AsymmetricCoulombViscous;
        assert!((acv.eval(&[0.5, 0.8, 0.2, 0.4], 1.0) - 0.7).abs() < 1e-15);
        assert!((acv.eval(&[0.5, 0.8, 0.2, 0.4], -1.0) + 1.2).abs() < 1e-15);
        assert_eq!(acv.eval(&[0.5, 0.8, 0.2, 0.4], 0.0), 0.0);
        // Asymmetric Stribeck: the static level at 0±, the Coulomb level far out.
        let st = Effect::AsymmetricStribeck;
        let th = [0.5, 0.7, 1.0, 1.2, 0.3, 0.0];
        assert!((st.eval(&th, 1e-9) - 1.0).abs() < 1e-9);
        assert!((st.eval(&th, -1e-9) + 1.2).abs() < 1e-9);
        assert!((st.eval(&th, 30.0) - 0.5).abs() < 1e-12);
        assert!((st.eval(&th, -30.0) + 0.7).abs() < 1e-12);
        // Gap spring: zero inside the gap, k·(z ∓ g) outside.
        assert_eq!(Effect::GapSpring.eval(&[2.0, 0.5], 0.4), 0.0);
        assert_eq!(Effect::GapSpring.eval(&[2.0, 0.5], 1.5), 2.0);
        assert_eq!(Effect::GapSpring.eval(&[2.0, 0.5], -1.5), -2.0);
        // Power law p = 2 is y·|y|; p = 3 the cubic.
        let pl = Effect::PowerLaw { linear: true };
        assert_eq!(pl.eval(&[0.5, 1.0, 2.0], -3.0), -1.5 - 9.0);
        assert!(
            (Effect::PowerLaw { linear: false }.eval(&[1.0, 3.0], 1.7) - 1.7f64.powi(3)).abs()
                < 1e-12
        );
        // Clipping and rectification.
        assert_eq!(Effect::ClipAbove.eval(&[2.0, 1.0], 3.0), 1.0);
        assert_eq!(Effect::ClipAbove.eval(&[2.0, 1.0], -3.0), -6.0);
        assert_eq!(Effect::ClipBelow.eval(&[2.0, -1.0], -3.0), -1.0);
        assert_eq!(
            Effect::Rectification { positive: true }.eval(&[2.0], -3.0),
            0.0
        );
        assert_eq!(
            Effect::Rectification { positive: false }.eval(&[2.0], -3.0),
            -6.0
        );
        // tanh: slope k at 0, asymptote s.
        let ts = Effect::SmoothSaturation;
        assert!((ts.eval(&[3.0, 0.5], 1e-7) / 1e-7 - 3.0).abs() < 1e-6);
        assert!((ts.eval(&[3.0, 0.5], 100.0) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn sites_get_the_families_that_mean_something_there() {
        let at = |site| Effect::library_at(&Effect::LIBRARY, site);
        for site in [Site::Input, Site::Output] {
            assert!(at(site).contains(&Effect::DeadZone));
            assert!(!at(site).contains(&Effect::GapSpring));
            assert!(!at(site).contains(&Effect::CoulombViscous));
        }
        assert!(at(Site::OutputFeedback).contains(&Effect::GapSpring));
        assert!(!at(Site::OutputFeedback).contains(&Effect::DeadZone));
        for friction in [
            Effect::CoulombViscous,
            Effect::AsymmetricCoulombViscous,
            Effect::Stribeck,
            Effect::AsymmetricStribeck,
        ] {
            assert!(at(Site::RateFeedback).contains(&friction));
            assert!(!at(Site::OutputFeedback).contains(&friction));
        }
        assert_eq!(at(Site::Declared { z: 1, w: 0 }), Effect::LIBRARY.to_vec());
    }
}

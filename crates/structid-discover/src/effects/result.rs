//! What fitting a family gives: the fit with its parameters, intervals, offset, refit record
//! and identifiability flags, and the errors of fitting.

use structid_linear::levenberg_marquardt::LmStatus;

use super::family::Effect;

/// Errors of effect fitting.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum EffectError {
    /// The inputs are unusable.
    #[error("invalid points: {0}")]
    InvalidPoints(String),
    /// Too few points for the family's parameters.
    #[error("{family} has {parameters} parameters but only {points} points were given")]
    TooFewPoints {
        /// The family.
        family: String,
        /// Its parameter count.
        parameters: usize,
        /// The number of points.
        points: usize,
    },
    /// An offset was asked of a family that cannot carry one ([`Effect::takes_offset`]).
    #[error("{0} cannot carry an offset (a constant is not identifiable in it)")]
    NoOffset(String),
}

/// One fitted parameter.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Parameter {
    /// Its name.
    pub name: String,
    /// The estimate.
    pub value: f64,
    /// The 95 % interval (value ± 1.96 standard errors; infinite when not identifiable).
    pub interval: (f64, f64),
}

impl Parameter {
    /// Half the width of the interval (∞ when it is not finite).
    pub fn half_width(&self) -> f64 {
        let h = 0.5 * (self.interval.1 - self.interval.0);
        if h.is_finite() { h } else { f64::INFINITY }
    }

    /// Whether the interval is finite and no wider than the value on either side
    /// (|value| ≥ half-width, i.e. the interval does not reach past zero to the value's
    /// mirror image).
    pub fn resolved(&self) -> bool {
        let h = self.half_width();
        h.is_finite() && h <= self.value.abs()
    }
}

/// How the output-error refit of a family (discovery's polish) ended.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Refit {
    /// Whether Levenberg–Marquardt ended at a minimum: its relative-decrease test was met, or
    /// no damped step lowered the cost any more (a local minimum to working precision; the
    /// simulation error of a family with a kink is not smooth there, and this is how a search
    /// on it ends). A refit stopped by the iteration limit, or whose simulation failed, did
    /// not converge: its intervals are not trusted and the family is not named.
    pub converged: bool,
    /// How the search ended, in words.
    pub status: String,
    /// Iterations used.
    pub iterations: usize,
    /// Sum of squared simulation errors at the start (the map fit's parameters).
    pub initial_cost: f64,
    /// … and at the end.
    pub cost: f64,
}

impl Refit {
    /// The refit record of a Levenberg–Marquardt search.
    pub fn from_status(status: LmStatus, iterations: usize, initial_cost: f64, cost: f64) -> Self {
        let words = match status {
            LmStatus::Converged(_) => "converged",
            LmStatus::NoProgress => "stalled: no damped step lowered the cost",
            LmStatus::MaxIterations => "stopped at the iteration limit",
            LmStatus::JacobianFailed => "the simulation failed while differentiating",
            _ => "stopped",
        };
        Self {
            converged: status.is_converged() || status == LmStatus::NoProgress,
            status: words.into(),
            iterations,
            initial_cost,
            cost,
        }
    }

    /// A refit that could not start (the simulation failed at the map fit's parameters).
    pub fn failed(why: &str) -> Self {
        Self {
            converged: false,
            status: why.into(),
            iterations: 0,
            initial_cost: f64::NAN,
            cost: f64::NAN,
        }
    }
}

/// A family fitted to the points.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EffectFit {
    /// The family.
    pub effect: Effect,
    /// Its parameters with intervals (the offset is not among them: see `offset`).
    pub parameters: Vec<Parameter>,
    /// The constant c added to the family, f(z; θ) + c, when the BIC preferred carrying one.
    pub offset: Option<Parameter>,
    /// Residual sum of squares.
    pub rss: f64,
    /// RMS of the residual, sqrt(RSS/n).
    pub rms: f64,
    /// The Bayesian information criterion n·ln(RSS/n) + p·ln n (lower is better; p counts
    /// the offset).
    pub bic: f64,
    /// The fitted map (offset included) as a model-file expression in `z0`.
    pub expression: String,
    /// The range (min, max) of z the family was fitted on.
    pub support: (f64, f64),
    /// The output-error refit, when there was one (`None`: the map fit only).
    pub refit: Option<Box<Refit>>,
    /// Why the family must not name the effect: an unidentifiable parameter (a saturation
    /// whose slope is a relay's, a Stribeck hump the data do not resolve, an exponent on its
    /// bound, a key parameter whose interval is not finite or wider than its value), or a
    /// refit that did not converge. Empty when it may.
    pub flags: Vec<String>,
}

impl EffectFit {
    /// The family's parameter values, in order (without the offset).
    pub fn values(&self) -> Vec<f64> {
        self.parameters.iter().map(|p| p.value).collect()
    }

    /// The family's parameter values followed by the offset, if any.
    pub fn all_values(&self) -> Vec<f64> {
        let mut v = self.values();
        v.extend(self.offset.as_ref().map(|o| o.value));
        v
    }

    /// The parameter called `name` (`offset` is the offset when the fit carries one).
    pub fn parameter(&self, name: &str) -> Option<&Parameter> {
        self.parameters
            .iter()
            .chain(self.offset.as_ref())
            .find(|p| p.name == name)
    }

    /// Quantities the parameters imply that a reader compares with physics: the *knee* of a
    /// saturating family, where |k·z| reaches its level (`knee` = level/gain for a symmetric
    /// saturation, its `tanh` form and one-sided clipping; `lower_knee` and `upper_knee` for
    /// an asymmetric saturation). For a map at the plant input the knee is the actuator's
    /// limit in u's units. It is also what the data determine when G is estimated with the
    /// map: c·N followed by G/c is the same system, so the fitted level follows whatever
    /// gain G was given while the knee does not.
    ///
    /// The interval adds the two parameters' relative half-widths (first order, correlation
    /// ignored: an upper bound on the linearised interval). Empty for other families and
    /// for a gain of zero.
    ///
    /// ```
    /// use structid_discover::effects::{Effect, fit_effect};
    /// // An actuator limited at |u| = 0.15, seen through a G with 0.6 of the true gain:
    /// // the map is 1/0.6 times the saturation, and its level 0.25 is not the limit.
    /// let z: Vec<f64> = (0..400).map(|k| -0.5 + k as f64 / 399.0).collect();
    /// let w: Vec<f64> = z.iter().map(|z| z.clamp(-0.15, 0.15) / 0.6).collect();
    /// let fit = fit_effect(Effect::Saturation, &z, &w).unwrap();
    /// assert!((fit.parameter("level").unwrap().value - 0.25).abs() < 1e-6);
    /// let knee = fit.quantity("knee").unwrap();
    /// assert!((knee.value - 0.15).abs() < 1e-6);
    /// ```
    pub fn derived(&self) -> Vec<Parameter> {
        let p = |name: &str| self.parameter(name);
        let ratio = |name: &str, level: &Parameter, gain: &Parameter| -> Option<Parameter> {
            let value = level.value / gain.value;
            if !value.is_finite() || gain.value == 0.0 {
                return None;
            }
            let rel = level.half_width() / level.value.abs() + gain.half_width() / gain.value.abs();
            let h = rel * value.abs();
            let interval = if h.is_finite() {
                (value - h, value + h)
            } else {
                (f64::NEG_INFINITY, f64::INFINITY)
            };
            Some(Parameter {
                name: name.into(),
                value,
                interval,
            })
        };
        let Some(gain) = p("gain") else {
            return Vec::new();
        };
        let knees: &[(&str, &str)] = match self.effect {
            Effect::Saturation | Effect::SmoothSaturation => &[("knee", "level")],
            Effect::ClipAbove | Effect::ClipBelow => &[("knee", "level")],
            Effect::AsymmetricSaturation => &[("lower_knee", "lower"), ("upper_knee", "upper")],
            _ => &[],
        };
        knees
            .iter()
            .filter_map(|(name, level)| {
                let level = p(level)?;
                // The symmetric families use |level| and are odd in the gain's sign.
                let abs = |q: &Parameter| Parameter {
                    value: q.value.abs(),
                    ..q.clone()
                };
                match self.effect {
                    Effect::Saturation | Effect::SmoothSaturation => {
                        ratio(name, &abs(level), &abs(gain))
                    }
                    _ => ratio(name, level, gain),
                }
            })
            .collect()
    }

    /// The parameter, offset or [derived](Self::derived) quantity called `name`.
    pub fn quantity(&self, name: &str) -> Option<Parameter> {
        self.parameter(name)
            .cloned()
            .or_else(|| self.derived().into_iter().find(|p| p.name == name))
    }

    /// The fitted map at z, offset included.
    ///
    /// ```
    /// use structid_discover::effects::{Effect, fit_effect};
    /// let z: Vec<f64> = (0..200).map(|k| -1.0 + k as f64 / 99.5).collect();
    /// let w: Vec<f64> = z.iter().map(|z| 0.4 * z.signum() + 0.1 * z - 0.3).collect();
    /// let fit = fit_effect(Effect::CoulombViscous, &z, &w).unwrap();
    /// assert!((fit.offset.as_ref().unwrap().value + 0.3).abs() < 1e-9);
    /// assert!((fit.eval(0.5) - (0.4 + 0.05 - 0.3)).abs() < 1e-9);
    /// ```
    pub fn eval(&self, z: f64) -> f64 {
        eval_full(self.effect, self.offset.is_some(), &self.all_values(), z)
    }

    /// The map of this fit's family, with its offset when it carries one, at other values
    /// (family parameters, then the offset).
    pub fn eval_with(&self, theta_all: &[f64], z: f64) -> f64 {
        eval_full(self.effect, self.offset.is_some(), theta_all, z)
    }

    /// Whether the fit may name the effect: no flags, and a refit, if there was one, that
    /// converged.
    pub fn nameable(&self) -> bool {
        self.flags.is_empty() && self.refit.as_ref().is_none_or(|r| r.converged)
    }
}

/// f(z; θ) + c, θ followed by c when `offset`.
pub(crate) fn eval_full(effect: Effect, offset: bool, theta_all: &[f64], z: f64) -> f64 {
    // The family sees only its own parameters (a polynomial's degree is its length).
    match offset {
        true => {
            let (c, theta) = theta_all.split_last().expect("an offset parameter");
            effect.eval(theta, z) + c
        }
        false => effect.eval(theta_all, z),
    }
}

pub(super) fn expression_full(effect: Effect, theta_all: &[f64], offset: bool) -> String {
    let family = &theta_all[..theta_all.len() - usize::from(offset)];
    let e = effect.expression(family);
    match offset.then(|| theta_all[theta_all.len() - 1]) {
        Some(c) if c < 0.0 => format!("{e} - {}", super::family::n(-c)),
        Some(c) => format!("{e} + {}", super::family::n(c)),
        None => e,
    }
}

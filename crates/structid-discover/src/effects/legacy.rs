//! Named static effects: parametric families fitted to a nonparametric map estimate.
//!
//! Each [`Effect`] is a family f(z; θ) with documented parameters. [`fit_effect`] fits one
//! family to points (z_k, w_k) by least squares and gives 95 % intervals; [`name_effect`] fits
//! every family of a library, ranks them by the Bayesian information criterion
//!
//! ```text
//!   BIC = n·ln(RSS/n) + p·ln n          (RSS/n floored at (1e-9·RMS w)², so exact fits tie)
//! ```
//!
//! and names the best one only when its residual is within the noise (otherwise the effect is
//! "unnamed" and the nonparametric map should be kept).
//!
//! Families that are linear in their parameters (polynomials, offset, gain, Coulomb plus
//! viscous friction) are solved exactly by least squares. The others (saturation, dead zone,
//! Stribeck) are fitted by Levenberg–Marquardt from several data-driven starts; quantisation,
//! whose fit is piecewise constant in its step, by a one-dimensional search. Intervals are
//! ±1.96 standard errors from σ̂²·(JᵀJ)⁻¹ with σ̂² = RSS/(n − p), the usual asymptotic ones;
//! at the kinks of the non-smooth families they are approximate.

use nalgebra::{DMatrix, DVector};
use structid_linear::levenberg_marquardt::{
    LeastSquaresProblem, LevenbergMarquardt, LmSettings, covariance_from_normal,
};

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
}

/// A parametric family of static maps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum Effect {
    /// Symmetric saturation f = clamp(k·z, −s, s); parameters `gain` k, `level` s > 0.
    Saturation,
    /// Asymmetric saturation f = clamp(k·z, lower, upper); parameters `gain`, `lower` < 0 <
    /// `upper`.
    AsymmetricSaturation,
    /// Dead zone f = k·(z − d) above d, k·(z + d) below −d, 0 between; parameters `gain` k,
    /// `width` d > 0.
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
}

impl Effect {
    /// The default library, simplest families first.
    pub const LIBRARY: [Effect; 10] = [
        Effect::Offset,
        Effect::Gain,
        Effect::OddPolynomial { degree: 3 },
        Effect::EvenPolynomial { degree: 2 },
        Effect::Saturation,
        Effect::AsymmetricSaturation,
        Effect::DeadZone,
        Effect::CoulombViscous,
        Effect::Stribeck,
        Effect::Quantisation,
    ];

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
        }
    }

    /// The parameter names, in the order of [`EffectFit::parameters`].
    pub fn parameter_names(&self) -> Vec<String> {
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect();
        match self {
            Effect::Saturation => s(&["gain", "level"]),
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
            Effect::Gain => s(&["gain"]),
        }
    }

    /// f(z; θ).
    ///
    /// ```
    /// use structid_discover::effects::Effect;
    /// assert_eq!(Effect::Saturation.eval(&[2.0, 1.0], 0.3), 0.6);
    /// assert_eq!(Effect::Saturation.eval(&[2.0, 1.0], -3.0), -1.0);
    /// assert_eq!(Effect::DeadZone.eval(&[2.0, 0.5], 0.2), 0.0);
    /// assert_eq!(Effect::Quantisation.eval(&[0.5], 0.74), 0.5);
    /// ```
    pub fn eval(&self, theta: &[f64], z: f64) -> f64 {
        let sign = |z: f64| {
            if z > 0.0 {
                1.0
            } else if z < 0.0 {
                -1.0
            } else {
                0.0
            }
        };
        match self {
            Effect::Saturation => {
                let s = theta[1].abs();
                (theta[0] * z).clamp(-s, s)
            }
            Effect::AsymmetricSaturation => {
                let (lo, hi) = (theta[1].min(theta[2]), theta[1].max(theta[2]));
                (theta[0] * z).clamp(lo, hi)
            }
            Effect::DeadZone => {
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
        }
    }

    /// The map as an expression in `z0` (the syntax of model-file `truth` expressions).
    ///
    /// ```
    /// use structid_discover::effects::Effect;
    /// assert_eq!(Effect::CoulombViscous.expression(&[0.8, 0.3]), "0.8*signum(z0) + 0.3*z0");
    /// ```
    pub fn expression(&self, theta: &[f64]) -> String {
        let n = |v: f64| format!("{v:?}");
        match self {
            Effect::Saturation => {
                let s = theta[1].abs();
                format!("min(max({}*z0, {}), {})", n(theta[0]), n(-s), n(s))
            }
            Effect::AsymmetricSaturation => {
                let (lo, hi) = (theta[1].min(theta[2]), theta[1].max(theta[2]));
                format!("min(max({}*z0, {}), {})", n(theta[0]), n(lo), n(hi))
            }
            Effect::DeadZone => {
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
                "({} + ({} - {})*exp(-(z0/{})^2))*signum(z0) + {}*z0",
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
        }
    }

    /// Columns of the regression when the family is linear in θ, else `None`.
    fn regressors(&self, z: f64) -> Option<Vec<f64>> {
        match self {
            Effect::CoulombViscous => Some(vec![z.signum() * f64::from(z != 0.0), z]),
            Effect::OddPolynomial { degree } => {
                Some((1..=*degree).step_by(2).map(|j| z.powi(j as i32)).collect())
            }
            Effect::EvenPolynomial { degree } => {
                Some((0..=*degree).step_by(2).map(|j| z.powi(j as i32)).collect())
            }
            Effect::Offset => Some(vec![1.0]),
            Effect::Gain => Some(vec![z]),
            _ => None,
        }
    }

    /// Data-driven starting points for the nonlinear families.
    fn starts(&self, z: &[f64], w: &[f64]) -> Vec<Vec<f64>> {
        let zmax = z
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()))
            .max(f64::MIN_POSITIVE);
        let wmax = w
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()))
            .max(f64::MIN_POSITIVE);
        let wlo = w.iter().cloned().fold(f64::INFINITY, f64::min);
        let whi = w.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        // The slope near the origin: least squares over the inner quarter of the range.
        let inner: Vec<(f64, f64)> = z
            .iter()
            .zip(w)
            .filter(|(z, _)| z.abs() <= 0.25 * zmax)
            .map(|(a, b)| (*a, *b))
            .collect();
        let szz: f64 = inner.iter().map(|(a, _)| a * a).sum();
        let slope0 = if szz > 0.0 {
            inner.iter().map(|(a, b)| a * b).sum::<f64>() / szz
        } else {
            wmax / zmax
        };
        let szz_all: f64 = z.iter().map(|a| a * a).sum();
        let slope_all = z.iter().zip(w).map(|(a, b)| a * b).sum::<f64>() / szz_all.max(1e-300);
        let fractions = [0.2, 0.4, 0.6, 0.8];
        match self {
            Effect::Saturation => fractions
                .iter()
                .map(|f| vec![wmax / (f * zmax), wmax])
                .chain([vec![slope0, wmax]])
                .collect(),
            Effect::AsymmetricSaturation => fractions
                .iter()
                .map(|f| vec![wmax / (f * zmax), wlo.min(-1e-12), whi.max(1e-12)])
                .chain([vec![slope0, wlo.min(-1e-12), whi.max(1e-12)]])
                .collect(),
            Effect::DeadZone => fractions
                .iter()
                .map(|f| vec![wmax / ((1.0 - f) * zmax), f * zmax])
                .collect(),
            Effect::Stribeck => {
                let c = w.iter().zip(z).map(|(w, z)| w * z.signum()).sum::<f64>() / w.len() as f64;
                fractions
                    .iter()
                    .map(|f| vec![0.7 * c, 1.3 * c, f * zmax, slope_all * 0.5])
                    .collect()
            }
            _ => Vec::new(),
        }
    }
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

/// A family fitted to the points.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EffectFit {
    /// The family.
    pub effect: Effect,
    /// Its parameters with intervals.
    pub parameters: Vec<Parameter>,
    /// Residual sum of squares.
    pub rss: f64,
    /// RMS of the residual, sqrt(RSS/n).
    pub rms: f64,
    /// The Bayesian information criterion n·ln(RSS/n) + p·ln n (lower is better).
    pub bic: f64,
    /// The fitted map as a model-file expression in `z0`.
    pub expression: String,
}

impl EffectFit {
    /// The parameter values, in order.
    pub fn values(&self) -> Vec<f64> {
        self.parameters.iter().map(|p| p.value).collect()
    }

    /// The parameter called `name`.
    pub fn parameter(&self, name: &str) -> Option<&Parameter> {
        self.parameters.iter().find(|p| p.name == name)
    }
}

fn check(z: &[f64], w: &[f64]) -> Result<(), EffectError> {
    if z.len() != w.len() {
        return Err(EffectError::InvalidPoints(format!(
            "{} inputs but {} outputs",
            z.len(),
            w.len()
        )));
    }
    if let Some(k) = z.iter().chain(w).position(|v| !v.is_finite()) {
        return Err(EffectError::InvalidPoints(format!(
            "value {k} is not finite"
        )));
    }
    if z.iter().all(|v| *v == z[0]) {
        return Err(EffectError::InvalidPoints(
            "every input is the same; nothing can be fitted".into(),
        ));
    }
    Ok(())
}

fn rss_of(effect: Effect, theta: &[f64], z: &[f64], w: &[f64]) -> f64 {
    z.iter()
        .zip(w)
        .map(|(z, w)| (w - effect.eval(theta, *z)).powi(2))
        .sum()
}

/// J (n × p) by central differences with steps scaled to each parameter.
fn jacobian(effect: Effect, theta: &[f64], z: &[f64]) -> DMatrix<f64> {
    let p = theta.len();
    let mut j = DMatrix::zeros(z.len(), p);
    for c in 0..p {
        let h = 1e-6 * theta[c].abs().max(1e-6);
        let (mut a, mut b) = (theta.to_vec(), theta.to_vec());
        a[c] += h;
        b[c] -= h;
        for (r, zk) in z.iter().enumerate() {
            j[(r, c)] = (effect.eval(&a, *zk) - effect.eval(&b, *zk)) / (2.0 * h);
        }
    }
    j
}

/// The least-squares problem of fitting `effect` to the points: residuals `w_k − f(z_k; θ)`.
struct EffectProblem<'a> {
    effect: Effect,
    z: &'a [f64],
    w: &'a [f64],
}

impl LeastSquaresProblem for EffectProblem<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        Some(DVector::from_iterator(
            self.z.len(),
            self.z
                .iter()
                .zip(self.w)
                .map(|(zk, wk)| wk - self.effect.eval(theta, *zk)),
        ))
    }

    fn jacobian(&mut self, theta: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> {
        Some(-jacobian(self.effect, theta, self.z))
    }
}

/// Levenberg–Marquardt from `start` (at most 200 iterations of at most 20 trials, relative
/// decrease 1e-12); returns (θ, RSS), the start itself when its RSS is not finite.
fn levenberg_marquardt(effect: Effect, start: &[f64], z: &[f64], w: &[f64]) -> (Vec<f64>, f64) {
    let settings = LmSettings::builder()
        .max_iterations(200)
        .tolerance(1e-12)
        .initial_damping(1e-3)
        .damping_increase(10.0)
        .damping_decrease(10.0)
        .min_damping(1e-12)
        .max_damping(f64::INFINITY)
        .max_step_attempts(20)
        .build();
    let mut problem = EffectProblem { effect, z, w };
    match settings.and_then(|s| LevenbergMarquardt::new(s).minimize(&mut problem, start)) {
        Ok(fit) => (fit.theta, fit.cost),
        Err(_) => (start.to_vec(), rss_of(effect, start, z, w)),
    }
}

/// Fits `effect` to the points (z_k, w_k) by least squares.
///
/// ```
/// use structid_discover::effects::{Effect, fit_effect};
/// let z: Vec<f64> = (0..200).map(|k| -2.0 + 4.0 * k as f64 / 199.0).collect();
/// let w: Vec<f64> = z.iter().map(|z| (1.5 * z).clamp(-1.2, 1.2)).collect();
/// let fit = fit_effect(Effect::Saturation, &z, &w).unwrap();
/// assert!((fit.parameter("level").unwrap().value - 1.2).abs() < 1e-6);
/// ```
pub fn fit_effect(effect: Effect, z: &[f64], w: &[f64]) -> Result<EffectFit, EffectError> {
    check(z, w)?;
    let names = effect.parameter_names();
    let (n, p) = (z.len(), names.len());
    if n <= p {
        return Err(EffectError::TooFewPoints {
            family: effect.name(),
            parameters: p,
            points: n,
        });
    }
    let theta = if let Some(cols) = effect.regressors(z[0]).map(|c| c.len()) {
        let a = DMatrix::from_fn(n, cols, |r, c| effect.regressors(z[r]).expect("linear")[c]);
        let b = DVector::from_column_slice(w);
        let svd = a.svd(true, true);
        let tol = 1e-12 * svd.singular_values.max();
        svd.solve(&b, tol)
            .map(|x| x.iter().copied().collect::<Vec<f64>>())
            .unwrap_or_else(|_| vec![0.0; cols])
    } else if effect == Effect::Quantisation {
        // The RSS is piecewise constant in q: scan steps over a log grid, then refine.
        let zmax = z.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut best = (f64::INFINITY, zmax);
        let grid = 400;
        for i in 0..=grid {
            let q = zmax * 10f64.powf(-2.5 + 2.5 * i as f64 / grid as f64);
            let r = rss_of(effect, &[q], z, w);
            if r < best.0 {
                best = (r, q);
            }
        }
        let (mut lo, mut hi) = (best.1 * 0.98, best.1 * 1.02);
        for _ in 0..60 {
            let (a, b) = (lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0);
            if rss_of(effect, &[a], z, w) <= rss_of(effect, &[b], z, w) {
                hi = b;
            } else {
                lo = a;
            }
        }
        let q = 0.5 * (lo + hi);
        if rss_of(effect, &[q], z, w) <= best.0 {
            vec![q]
        } else {
            vec![best.1]
        }
    } else {
        effect
            .starts(z, w)
            .iter()
            .map(|s| levenberg_marquardt(effect, s, z, w))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(t, _)| t)
            .unwrap_or_else(|| vec![0.0; p])
    };
    let theta = canonical(effect, theta);
    let rss = rss_of(effect, &theta, z, w);
    let sigma2 = rss / (n - p) as f64;
    let j = jacobian(effect, &theta, z);
    let cov = covariance_from_normal(&(j.transpose() * &j), sigma2);
    let parameters = names
        .into_iter()
        .enumerate()
        .map(|(i, name)| {
            let se = cov
                .as_ref()
                .map(|c| c[(i, i)].max(0.0).sqrt())
                .filter(|s| s.is_finite())
                .unwrap_or(f64::INFINITY);
            Parameter {
                name,
                value: theta[i],
                interval: (theta[i] - 1.96 * se, theta[i] + 1.96 * se),
            }
        })
        .collect();
    // Exact fits (noise-free points) all have RSS ≈ 0 at rounding level; flooring RSS/n at
    // (1e-9 × RMS of w)² makes them tie, and the parameter count decides.
    let scale2 = w.iter().map(|v| v * v).sum::<f64>() / n as f64;
    let rss_n = (rss / n as f64).max(1e-18 * scale2).max(f64::MIN_POSITIVE);
    Ok(EffectFit {
        effect,
        parameters,
        rss,
        rms: (rss / n as f64).sqrt(),
        bic: n as f64 * rss_n.ln() + p as f64 * (n as f64).ln(),
        expression: effect.expression(&theta),
    })
}

/// Parameters in their documented form (positive levels, widths and steps; ordered bounds).
fn canonical(effect: Effect, mut theta: Vec<f64>) -> Vec<f64> {
    match effect {
        Effect::Saturation | Effect::DeadZone => theta[1] = theta[1].abs(),
        Effect::AsymmetricSaturation if theta[1] > theta[2] => theta.swap(1, 2),
        Effect::Stribeck => theta[2] = theta[2].abs(),
        Effect::Quantisation => theta[0] = theta[0].abs(),
        _ => {}
    }
    theta
}

/// Settings of [`name_effect`].
#[derive(Clone, Debug, PartialEq)]
pub struct NamingSettings {
    /// The families to try.
    pub library: Vec<Effect>,
    /// The noise level (standard deviation) of the points, if known: a family is named only
    /// when its residual RMS is at most `tolerance` × this.
    pub noise_std: Option<f64>,
    /// See `noise_std` (default 1.5).
    pub tolerance: f64,
}

impl Default for NamingSettings {
    fn default() -> Self {
        Self {
            library: Effect::LIBRARY.to_vec(),
            noise_std: None,
            tolerance: 1.5,
        }
    }
}

/// The outcome of [`name_effect`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Naming {
    /// Every family that could be fitted, best BIC first.
    pub ranked: Vec<EffectFit>,
    /// The named effect: the best BIC when it fits within the noise (always, when no noise
    /// level is given); `None` means "unnamed static effect".
    pub named: Option<EffectFit>,
}

/// Fits every family of the library and names the effect (see the [module documentation](self)).
///
/// ```
/// use structid_discover::effects::{Effect, NamingSettings, name_effect};
/// let z: Vec<f64> = (0..300).map(|k| -1.0 + 2.0 * k as f64 / 299.0).collect();
/// let w: Vec<f64> = z.iter().map(|z| 0.5 * z.signum() + 0.2 * z).collect();
/// let naming = name_effect(&z, &w, &NamingSettings::default()).unwrap();
/// assert_eq!(naming.named.unwrap().effect, Effect::CoulombViscous);
/// ```
pub fn name_effect(z: &[f64], w: &[f64], settings: &NamingSettings) -> Result<Naming, EffectError> {
    check(z, w)?;
    let mut ranked: Vec<EffectFit> = settings
        .library
        .iter()
        .filter_map(|e| fit_effect(*e, z, w).ok())
        .collect();
    ranked.sort_by(|a, b| a.bic.total_cmp(&b.bic));
    let named = ranked
        .first()
        .cloned()
        .filter(|best| match settings.noise_std {
            Some(s) => best.rms <= settings.tolerance * s,
            None => true,
        });
    Ok(Naming { ranked, named })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal, Uniform};

    fn points(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let u = Uniform::new(-2.0, 2.0).unwrap();
        (0..n).map(|_| u.sample(&mut rng)).collect()
    }

    fn noisy(effect: Effect, theta: &[f64], z: &[f64], std: f64, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed ^ 0xabc);
        let n = Normal::new(0.0, std).unwrap();
        z.iter()
            .map(|z| effect.eval(theta, *z) + n.sample(&mut rng))
            .collect()
    }

    /// Each family with typical parameters, on 400 points with 1 % noise.
    fn cases() -> Vec<(Effect, Vec<f64>)> {
        vec![
            (Effect::Saturation, vec![1.5, 1.2]),
            (Effect::AsymmetricSaturation, vec![1.0, -0.6, 1.3]),
            (Effect::DeadZone, vec![1.2, 0.5]),
            (Effect::CoulombViscous, vec![0.6, 0.3]),
            (Effect::Stribeck, vec![0.5, 1.0, 0.3, 0.2]),
            (Effect::OddPolynomial { degree: 3 }, vec![0.4, 0.5]),
            (Effect::EvenPolynomial { degree: 2 }, vec![0.1, 0.6]),
            (Effect::Quantisation, vec![0.5]),
            (Effect::Offset, vec![0.7]),
            (Effect::Gain, vec![1.7]),
        ]
    }

    #[test]
    fn every_family_recovers_its_parameters_within_their_intervals() {
        for (effect, theta) in cases() {
            let z = points(400, 1);
            let w = noisy(effect, &theta, &z, 0.01, 2);
            let fit = fit_effect(effect, &z, &w).unwrap();
            for (p, t) in fit.parameters.iter().zip(&theta) {
                assert!(
                    (p.value - t).abs() <= 0.05 * t.abs().max(0.1),
                    "{}: {} = {} vs {t}",
                    effect.name(),
                    p.name,
                    p.value
                );
                if effect != Effect::Quantisation {
                    // A 95 % interval from a correct model holds the truth (loosely: ×3).
                    let half = 0.5 * (p.interval.1 - p.interval.0);
                    assert!(
                        (p.value - t).abs() <= 3.0 * half,
                        "{}: {} interval {:?} misses {t}",
                        effect.name(),
                        p.name,
                        p.interval
                    );
                }
            }
            assert!(fit.rms < 0.02, "{}: rms {}", effect.name(), fit.rms);
        }
    }

    #[test]
    fn the_bic_names_the_family_that_generated_the_points() {
        let mut wrong = Vec::new();
        for (effect, theta) in cases() {
            let z = points(400, 3);
            let w = noisy(effect, &theta, &z, 0.01, 4);
            let settings = NamingSettings {
                noise_std: Some(0.01),
                ..NamingSettings::default()
            };
            let naming = name_effect(&z, &w, &settings).unwrap();
            let named = naming.named.map(|n| n.effect);
            if named != Some(effect) {
                wrong.push((effect.name(), named.map(|e| e.name())));
            }
        }
        assert!(wrong.is_empty(), "misnamed: {wrong:?}");
    }

    #[test]
    fn a_map_outside_the_library_stays_unnamed() {
        let z = points(400, 5);
        let w: Vec<f64> = z.iter().map(|z| (3.0 * z).sin() * 0.5).collect();
        let settings = NamingSettings {
            noise_std: Some(0.01),
            ..NamingSettings::default()
        };
        let naming = name_effect(&z, &w, &settings).unwrap();
        assert!(naming.named.is_none(), "{:?}", naming.named);
        assert_eq!(naming.ranked.len(), Effect::LIBRARY.len());
    }

    #[test]
    fn expressions_evaluate_like_the_family() {
        // Checked by hand-rolled evaluation of the printed forms on a few points.
        let fit_expr = Effect::OddPolynomial { degree: 3 }.expression(&[0.4, 0.5]);
        assert_eq!(fit_expr, "0.4*z0 + 0.5*z0^3");
        let sat = Effect::AsymmetricSaturation.expression(&[2.0, 1.0, -0.5]);
        assert_eq!(sat, "min(max(2.0*z0, -0.5), 1.0)");
        assert_eq!(
            Effect::DeadZone.expression(&[1.5, 0.2]),
            "1.5*(max(z0 - 0.2, 0) + min(z0 + 0.2, 0))"
        );
    }

    #[test]
    fn bad_points_are_errors() {
        assert!(matches!(
            fit_effect(Effect::Gain, &[1.0, 2.0], &[1.0]),
            Err(EffectError::InvalidPoints(_))
        ));
        assert!(matches!(
            fit_effect(Effect::Gain, &[1.0, f64::NAN], &[1.0, 2.0]),
            Err(EffectError::InvalidPoints(_))
        ));
        assert!(matches!(
            fit_effect(Effect::Gain, &[1.0, 1.0, 1.0], &[1.0, 2.0, 3.0]),
            Err(EffectError::InvalidPoints(_))
        ));
        assert!(matches!(
            fit_effect(Effect::Stribeck, &[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]),
            Err(EffectError::TooFewPoints { .. })
        ));
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

        /// Property: the least-squares fit of a family is at least as good as its truth
        /// (RSS at the estimate ≤ RSS at the generating parameters).
        #[test]
        fn the_fit_is_never_worse_than_the_truth(
            k in 0.5f64..2.0, s in 0.3f64..1.5, seed in 0u64..500,
        ) {
            for (effect, theta) in [
                (Effect::Saturation, vec![k, s]),
                (Effect::DeadZone, vec![k, 0.5 * s]),
                (Effect::CoulombViscous, vec![s, 0.3 * k]),
            ] {
                let z = points(300, seed);
                let w = noisy(effect, &theta, &z, 0.02, seed);
                let fit = fit_effect(effect, &z, &w).unwrap();
                let truth = rss_of(effect, &theta, &z, &w);
                prop_assert!(fit.rss <= truth * (1.0 + 1e-9), "{}: {} > {truth}", effect.name(), fit.rss);
            }
        }
    }
}

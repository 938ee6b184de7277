//! How static is a relation? The paper's Example 1 as a test on a (z, w) scatter.
//!
//! Hsu et al. (2006), Example 1, fit the best static map to the points (z_k, w_k) of three
//! systems driven by the same input: w = atan(z), a first-order filter of z, and a hysteresis.
//! Only the atan leaves nothing but noise: a static map cannot follow the memory of the
//! other two, and their scatter stays wide however the map is chosen. [`staticness`] repeats
//! that experiment on any record:
//!
//! 1. the best static map w ≈ N̂(z) is fitted by the dispersion of structid's `identify`
//!    (a Gaussian kernel through Nyström features, width a fraction of the range of z, β
//!    chosen automatically by marginal likelihood) on the scatter regression problem
//!    y_k = N(z_k) + e_k;
//! 2. the variance it leaves unexplained, mean (w_k − N̂(z_k))², is set against the noise
//!    variance: given, or estimated without a model from the first differences of the
//!    residual in time ([`gap::noise_level`](crate::gap::noise_level)), which a slowly
//!    varying model error barely moves;
//! 3. the residual is split by the direction of motion of z
//!    ([`hysteresis::direction_dependence`](crate::hysteresis::direction_dependence)): a
//!    static map cannot tell rising from falling z.
//!
//! The [`Verdict`] is static when the unexplained variance is within
//! [`StaticnessSettings::ratio_limit`] times the noise variance and the direction does not
//! matter. [`Staticness::unexplained_ratio`] ranks records: the smaller, the more static.
//!
//! ```
//! use structid_discover::staticness::{StaticnessSettings, Verdict, staticness};
//! let z: Vec<f64> = (0..600).map(|k| 2.0 * (0.03 * k as f64).sin()).collect();
//! // A static map plus a deterministic disturbance of standard deviation 0.0062.
//! let w: Vec<f64> = z.iter().enumerate().map(|(k, z)| z.atan() + 0.01 * ((k * 7919 % 13) as f64 - 6.0) / 6.0).collect();
//! let settings = StaticnessSettings::builder().noise_std(0.0062).build().unwrap();
//! let s = staticness(&z, &w, &settings).unwrap();
//! assert_eq!(s.verdict, Verdict::Static);
//! ```

use std::sync::Arc;

use nalgebra::DMatrix;
use structid_core::selection::{Criterion, SelectionSettings, select};
use structid_core::{
    Data, Dispersion, IdentifySettings, Lft, LftMatrices, LowRankGaussian, Model, NonlinearBlock,
    Signal,
};

use crate::gap::noise_level;
use crate::hysteresis::{DirectionTest, direction_dependence};

/// Why [`staticness`] cannot rate a scatter.
#[derive(Debug, thiserror::Error)]
pub enum StaticnessError {
    /// z and w differ in length.
    #[error("z has {z} samples but w has {w}; give one w per z")]
    LengthMismatch {
        /// Samples of z.
        z: usize,
        /// Samples of w.
        w: usize,
    },
    /// Too few samples to fit a map and test the direction.
    #[error("{0} samples are too few: the staticness test needs at least {MIN_SAMPLES}")]
    TooShort(usize),
    /// A sample is NaN or infinite.
    #[error("sample {index} of {what} is not finite ({value})")]
    NotFinite {
        /// `z` or `w`.
        what: &'static str,
        /// Its index.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// z does not vary: the record shows the relation at one point only.
    #[error("z is constant ({0}): the record shows the relation at one point only")]
    ConstantInput(f64),
    /// A setting is out of range.
    #[error("invalid {name} = {value}: {reason}")]
    InvalidSetting {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        reason: &'static str,
    },
    /// The fit of the static map failed.
    #[error("fitting the static map: {0}")]
    Fit(#[from] structid_core::Error),
}

/// The fewest samples [`staticness`] accepts.
pub const MIN_SAMPLES: usize = 20;

/// Points of the grid on which [`Staticness::grid_w`] holds the fitted map.
pub const GRID_POINTS: usize = 201;

/// How [`staticness`] fits and judges; build with [`StaticnessSettings::builder`].
///
/// ```
/// use structid_discover::staticness::StaticnessSettings;
/// let s = StaticnessSettings::builder().noise_std(0.05).ratio_limit(3.0).build().unwrap();
/// assert_eq!(s.noise_std(), Some(0.05));
/// assert!(StaticnessSettings::builder().sigma_fraction(0.0).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StaticnessSettings {
    sigma_fraction: f64,
    sigma: Option<f64>,
    noise_std: Option<f64>,
    ratio_limit: f64,
    direction_threshold: f64,
}

impl Default for StaticnessSettings {
    fn default() -> Self {
        Self {
            sigma_fraction: 0.1,
            sigma: None,
            noise_std: None,
            ratio_limit: 2.0,
            direction_threshold: 0.1,
        }
    }
}

impl StaticnessSettings {
    /// A builder from the defaults: kernel width 0.1 × the range of z, noise estimated,
    /// ratio limit 2, direction threshold 0.1.
    pub fn builder() -> StaticnessSettingsBuilder {
        StaticnessSettingsBuilder(Self::default())
    }

    /// The Gaussian kernel's width as a fraction of the range of z (when no
    /// [`sigma`](Self::sigma) is given); `identify`'s default is 0.1.
    pub fn sigma_fraction(&self) -> f64 {
        self.sigma_fraction
    }

    /// The kernel width σ itself, in the units of z, if given.
    pub fn sigma(&self) -> Option<f64> {
        self.sigma
    }

    /// The noise standard deviation of w, if known; otherwise it is estimated from the
    /// residual's first differences.
    pub fn noise_std(&self) -> Option<f64> {
        self.noise_std
    }

    /// The largest unexplained variance, in noise variances, of a static relation. A static
    /// map with noise leaves about one (a little less: the map absorbs some noise).
    pub fn ratio_limit(&self) -> f64 {
        self.ratio_limit
    }

    /// The share of the residual energy the direction of motion must explain to call the
    /// relation direction dependent (see [`direction_dependence`]).
    pub fn direction_threshold(&self) -> f64 {
        self.direction_threshold
    }
}

/// Builder of [`StaticnessSettings`]; [`build`](Self::build) validates.
#[derive(Clone, Debug)]
pub struct StaticnessSettingsBuilder(StaticnessSettings);

impl StaticnessSettingsBuilder {
    /// Kernel width as a fraction of the range of z (default 0.1).
    pub fn sigma_fraction(mut self, f: f64) -> Self {
        self.0.sigma_fraction = f;
        self
    }

    /// Kernel width in the units of z (default: from [`sigma_fraction`](Self::sigma_fraction)).
    pub fn sigma(mut self, s: f64) -> Self {
        self.0.sigma = Some(s);
        self
    }

    /// The known noise standard deviation of w (default: estimated).
    pub fn noise_std(mut self, s: f64) -> Self {
        self.0.noise_std = Some(s);
        self
    }

    /// The largest unexplained variance of a static relation, in noise variances (default 2).
    pub fn ratio_limit(mut self, r: f64) -> Self {
        self.0.ratio_limit = r;
        self
    }

    /// The direction test's threshold (default 0.1).
    pub fn direction_threshold(mut self, t: f64) -> Self {
        self.0.direction_threshold = t;
        self
    }

    /// Validates and returns the settings.
    pub fn build(self) -> Result<StaticnessSettings, StaticnessError> {
        let s = self.0;
        let positive = |name, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(StaticnessError::InvalidSetting {
                    name,
                    value: v,
                    reason: "it must be a finite number greater than zero",
                })
            }
        };
        positive("sigma fraction", s.sigma_fraction)?;
        if let Some(v) = s.sigma {
            positive("sigma", v)?;
        }
        if let Some(v) = s.noise_std {
            positive("noise std", v)?;
        }
        positive("ratio limit", s.ratio_limit)?;
        if !(s.direction_threshold > 0.0 && s.direction_threshold < 1.0) {
            return Err(StaticnessError::InvalidSetting {
                name: "direction threshold",
                value: s.direction_threshold,
                reason: "it must lie strictly between 0 and 1",
            });
        }
        Ok(s)
    }
}

/// What [`staticness`] concludes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// A static map explains w up to the noise, the same for rising and falling z.
    Static,
    /// The residual depends on the direction of motion of z: hysteresis or backlash.
    DirectionDependent,
    /// The best static map leaves more than the noise unexplained, without a direction
    /// effect: dynamics (w depends on past z) or an input that is not z.
    Unexplained,
}

impl Verdict {
    /// A one-line reading of the verdict.
    ///
    /// ```
    /// use structid_discover::staticness::Verdict;
    /// assert!(Verdict::Static.describe().starts_with("static"));
    /// ```
    pub fn describe(self) -> &'static str {
        match self {
            Verdict::Static => "static: a static map explains w up to the noise",
            Verdict::DirectionDependent => {
                "not static: w depends on the direction of motion of z (hysteresis or backlash suspected)"
            }
            Verdict::Unexplained => {
                "not static: the best static map leaves more than the noise unexplained (dynamics, or an input other than z)"
            }
        }
    }
}

/// The outcome of [`staticness`]: the fitted map, the variances and the direction test.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Staticness {
    /// Samples used.
    pub samples: usize,
    /// The kernel width σ of the fit (units of z).
    pub sigma: f64,
    /// β chosen by marginal likelihood.
    pub beta: f64,
    /// Whether β lies on a bound of its search.
    pub beta_at_bound: bool,
    /// Variance of w around its mean.
    pub total_variance: f64,
    /// mean (w_k − N̂(z_k))²: what the best static map leaves unexplained.
    pub unexplained_variance: f64,
    /// The noise variance it is compared with.
    pub noise_variance: f64,
    /// Whether the noise level was given (otherwise estimated from the residual).
    pub noise_given: bool,
    /// `unexplained_variance / noise_variance`: about 1 for a static relation; the larger,
    /// the less static.
    pub unexplained_ratio: f64,
    /// `1 − unexplained_variance / total_variance`: the share of w's variance the static map
    /// explains.
    pub explained_share: f64,
    /// The direction test on the residual.
    pub direction: DirectionTest,
    /// The conclusion.
    pub verdict: Verdict,
    /// N̂ at the samples (in the order of z).
    #[serde(skip)]
    pub fitted: Vec<f64>,
    /// The grid over the range of z ([`GRID_POINTS`] points).
    #[serde(skip)]
    pub grid_z: Vec<f64>,
    /// N̂ on [`grid_z`](Self::grid_z).
    #[serde(skip)]
    pub grid_w: Vec<f64>,
    /// Warnings of the fit.
    pub warnings: Vec<String>,
}

/// The scatter regression problem y_k = N(z_k) + e_k: an LFT without states, z = u, y = w + e.
fn scatter_model(dispersion: Arc<dyn Dispersion>) -> Result<Model, structid_core::Error> {
    let one = || DMatrix::from_element(1, 1, 1.0);
    let lft = Lft::new(LftMatrices {
        a: DMatrix::zeros(0, 0),
        bu: DMatrix::zeros(0, 1),
        be: DMatrix::zeros(0, 1),
        bw: DMatrix::zeros(0, 1),
        cy: DMatrix::zeros(1, 0),
        dyu: DMatrix::zeros(1, 1),
        dye: one(),
        dyw: one(),
        cz: DMatrix::zeros(1, 0),
        dzu: one(),
        dze: DMatrix::zeros(1, 1),
        dzw: DMatrix::zeros(1, 1),
    })?;
    Model::new(lft, vec![NonlinearBlock::new("N", vec![0], 0, dispersion)])
}

/// Rates how well a static map explains the scatter (z_k, w_k) (in time order); see the
/// [module documentation](self).
///
/// ```
/// use structid_discover::staticness::{StaticnessSettings, Verdict, staticness};
/// // Backlash of half-width 0.3 on a slow sine: not static.
/// let z: Vec<f64> = (0..800).map(|k| (0.02 * k as f64).sin()).collect();
/// let mut w = vec![0.0; z.len()];
/// for k in 1..z.len() {
///     w[k] = if z[k] - w[k - 1] > 0.3 { z[k] - 0.3 } else if z[k] - w[k - 1] < -0.3 { z[k] + 0.3 } else { w[k - 1] };
/// }
/// let settings = StaticnessSettings::builder().noise_std(0.01).build().unwrap();
/// let s = staticness(&z, &w, &settings).unwrap();
/// assert_ne!(s.verdict, Verdict::Static);
/// assert!(s.unexplained_ratio > 10.0);
/// ```
pub fn staticness(
    z: &[f64],
    w: &[f64],
    settings: &StaticnessSettings,
) -> Result<Staticness, StaticnessError> {
    if z.len() != w.len() {
        return Err(StaticnessError::LengthMismatch {
            z: z.len(),
            w: w.len(),
        });
    }
    let n = z.len();
    if n < MIN_SAMPLES {
        return Err(StaticnessError::TooShort(n));
    }
    for (what, x) in [("z", z), ("w", w)] {
        if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(StaticnessError::NotFinite { what, index, value });
        }
    }
    let (lo, hi) = z
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    if hi <= lo {
        return Err(StaticnessError::ConstantInput(lo));
    }
    let sigma = settings
        .sigma
        .unwrap_or(settings.sigma_fraction * (hi - lo));
    // Nyström features keep the fit and the marginal-likelihood search at O(L·m²), so that
    // long records are rated as quickly as short ones.
    let dispersion: Arc<dyn Dispersion> = Arc::new(LowRankGaussian::new(sigma, 1e-8)?);
    let model = scatter_model(dispersion)?;
    let signal = |x: &[f64]| Signal::new(1, x.to_vec()).map_err(structid_core::Error::from);
    let data = Data::new(signal(z)?, signal(w)?)?;
    let how = SelectionSettings::builder()
        .criterion(Criterion::MarginalLikelihood)
        .build()?;
    let sel = select(&model, &data, None, &IdentifySettings::default(), &how)?;
    let block = sel
        .identification
        .blocks
        .first()
        .ok_or_else(|| structid_core::Error::Numerical("the fit returned no map".into()))?;
    let fitted: Vec<f64> = z.iter().map(|&v| block.map.eval(&[v])).collect();
    let residual: Vec<f64> = w.iter().zip(&fitted).map(|(w, f)| w - f).collect();
    let unexplained_variance = residual.iter().map(|r| r * r).sum::<f64>() / n as f64;
    let mean = w.iter().sum::<f64>() / n as f64;
    let total_variance = w.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
    let noise_std = settings.noise_std.unwrap_or_else(|| noise_level(&residual));
    // A noiseless record leaves a noise level of zero; the smallest positive variance keeps
    // the ratio finite and the verdict on the unexplained part.
    let noise_variance = (noise_std * noise_std).max(f64::MIN_POSITIVE);
    let unexplained_ratio = unexplained_variance / noise_variance;
    let direction = direction_dependence(z, &residual, settings.direction_threshold);
    let verdict = if direction.dynamic {
        Verdict::DirectionDependent
    } else if unexplained_ratio > settings.ratio_limit {
        Verdict::Unexplained
    } else {
        Verdict::Static
    };
    let grid_z: Vec<f64> = (0..GRID_POINTS)
        .map(|i| lo + (hi - lo) * i as f64 / (GRID_POINTS - 1) as f64)
        .collect();
    let grid_w = grid_z.iter().map(|&v| block.map.eval(&[v])).collect();
    Ok(Staticness {
        samples: n,
        sigma,
        beta: sel.beta,
        beta_at_bound: sel.beta_at_bound.is_some(),
        total_variance,
        unexplained_variance,
        noise_variance,
        noise_given: settings.noise_std.is_some(),
        unexplained_ratio,
        explained_share: if total_variance > 0.0 {
            1.0 - unexplained_variance / total_variance
        } else {
            1.0
        },
        direction,
        verdict,
        fitted,
        grid_z,
        grid_w,
        warnings: sel.identification.diagnostics.warnings.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};

    /// The paper's Example 1 input: a slow sinusoid plus a little random motion.
    fn input(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let d = Normal::new(0.0, 1.0).unwrap();
        let mut s = 0.0;
        (0..n)
            .map(|k| {
                s = 0.97 * s + 0.03 * d.sample(&mut rng);
                2.0 * (0.013 * k as f64).sin() + 0.6 * (0.041 * k as f64).sin() + s
            })
            .collect()
    }

    fn noisy(w: Vec<f64>, std: f64, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let d = Normal::new(0.0, std).unwrap();
        w.into_iter().map(|v| v + d.sample(&mut rng)).collect()
    }

    fn atan(z: &[f64]) -> Vec<f64> {
        z.iter().map(|v| v.atan()).collect()
    }

    /// w = a first-order filter of z with unit static gain (time constant 10 samples).
    fn lti(z: &[f64]) -> Vec<f64> {
        let mut w = vec![0.0; z.len()];
        for k in 1..z.len() {
            w[k] = 0.9 * w[k - 1] + 0.1 * z[k - 1];
        }
        w
    }

    /// Backlash (play) of half-width 0.4.
    fn backlash(z: &[f64]) -> Vec<f64> {
        let mut w = vec![0.0; z.len()];
        for k in 1..z.len() {
            let d = z[k] - w[k - 1];
            w[k] = if d > 0.4 {
                z[k] - 0.4
            } else if d < -0.4 {
                z[k] + 0.4
            } else {
                w[k - 1]
            };
        }
        w
    }

    /// Bouc–Wen: ḣ = ż − 2|ż|·h − ż·|h|, w = 0.3·z + 0.7·h.
    fn bouc_wen(z: &[f64]) -> Vec<f64> {
        let mut h = 0.0;
        let mut w = vec![0.0; z.len()];
        for k in 1..z.len() {
            let dz = z[k] - z[k - 1];
            h += dz - 2.0 * dz.abs() * h - dz * h.abs();
            w[k] = 0.3 * z[k] + 0.7 * h;
        }
        w
    }

    /// The paper's ranking: the atan is static, the filter and the hysteresis are not, and the
    /// atan's unexplained variance is far below the others' (noise estimated from the data).
    #[test]
    fn example_1_ranks_atan_as_most_static() {
        for seed in 0..3 {
            let z = input(2000, seed);
            let std = 0.02;
            let a = staticness(&z, &noisy(atan(&z), std, seed + 10), &Default::default()).unwrap();
            let l = staticness(&z, &noisy(lti(&z), std, seed + 20), &Default::default()).unwrap();
            let b = staticness(
                &z,
                &noisy(backlash(&z), std, seed + 30),
                &Default::default(),
            )
            .unwrap();
            let h = staticness(
                &z,
                &noisy(bouc_wen(&z), std, seed + 40),
                &Default::default(),
            )
            .unwrap();
            assert_eq!(a.verdict, Verdict::Static, "atan {seed}: {a:?}");
            // The estimated noise is the noise that was added.
            assert!(
                (a.noise_variance.sqrt() / std - 1.0).abs() < 0.2,
                "atan {seed}: {a:?}"
            );
            assert!(a.unexplained_ratio < 1.5, "atan {seed}: {a:?}");
            for (name, s) in [("lti", &l), ("backlash", &b), ("bouc-wen", &h)] {
                assert_ne!(s.verdict, Verdict::Static, "{name} {seed}: {s:?}");
                assert!(
                    s.unexplained_ratio > 10.0 * a.unexplained_ratio,
                    "{name} {seed}: {} against atan {}",
                    s.unexplained_ratio,
                    a.unexplained_ratio
                );
                assert!(s.explained_share < a.explained_share, "{name} {seed}");
            }
            assert_eq!(
                b.verdict,
                Verdict::DirectionDependent,
                "backlash {seed}: {b:?}"
            );
        }
    }

    /// A given noise level is used as given; the fitted map follows the atan.
    #[test]
    fn a_given_noise_level_is_used_and_the_map_is_the_atan() {
        let z = input(1500, 7);
        let w = noisy(atan(&z), 0.05, 8);
        let s = staticness(
            &z,
            &w,
            &StaticnessSettings::builder()
                .noise_std(0.05)
                .build()
                .unwrap(),
        )
        .unwrap();
        assert!(s.noise_given && (s.noise_variance - 0.0025).abs() < 1e-15);
        assert_eq!(s.verdict, Verdict::Static);
        // Inside the data's range (away from its sparse ends) the map is the atan.
        let (lo, hi) = (s.grid_z[0], s.grid_z[GRID_POINTS - 1]);
        for (zg, wg) in s.grid_z.iter().zip(&s.grid_w) {
            if *zg > lo + 0.1 * (hi - lo) && *zg < hi - 0.1 * (hi - lo) {
                assert!((wg - zg.atan()).abs() < 0.05, "at {zg}: {wg}");
            }
        }
        assert_eq!(s.fitted.len(), 1500);
    }

    #[test]
    fn bad_input_is_an_error() {
        let d = StaticnessSettings::default();
        assert!(matches!(
            staticness(&[0.0; 30], &[0.0; 29], &d),
            Err(StaticnessError::LengthMismatch { z: 30, w: 29 })
        ));
        assert!(matches!(
            staticness(&[0.0; 5], &[0.0; 5], &d),
            Err(StaticnessError::TooShort(5))
        ));
        assert!(matches!(
            staticness(&[1.0; 30], &[0.0; 30], &d),
            Err(StaticnessError::ConstantInput(_))
        ));
        let mut z: Vec<f64> = (0..30).map(f64::from).collect();
        z[3] = f64::NAN;
        assert!(matches!(
            staticness(&z, &[0.0; 30], &d),
            Err(StaticnessError::NotFinite {
                what: "z",
                index: 3,
                ..
            })
        ));
        assert!(
            StaticnessSettings::builder()
                .direction_threshold(1.0)
                .build()
                .is_err()
        );
        assert!(
            StaticnessSettings::builder()
                .noise_std(-1.0)
                .build()
                .is_err()
        );
    }
}

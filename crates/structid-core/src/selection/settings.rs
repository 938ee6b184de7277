//! What selection chooses by and within which bounds: the criterion and the settings.

use crate::error::{Error, Result, positive_finite};
use crate::progress::Progress;

/// The criterion that chooses the hyperparameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Criterion {
    /// Maximum marginal likelihood with the noise level profiled out (quadratic dispersions).
    MarginalLikelihood,
    /// Generalised cross-validation of the smoother r ↦ T_yw·ŵ (quadratic dispersions).
    Gcv,
    /// Blocked K-fold cross-validation on held-out output samples (any dispersion).
    CrossValidation {
        /// Number of contiguous folds K (≥ 2).
        folds: usize,
    },
    /// Mean squared simulation error on a separate validation record (any dispersion).
    Validation,
}

impl Criterion {
    /// A short name: `ml`, `gcv`, `cv` or `validation`.
    ///
    /// ```
    /// use structid_core::selection::Criterion;
    /// assert_eq!(Criterion::CrossValidation { folds: 5 }.name(), "cv");
    /// ```
    pub fn name(&self) -> &'static str {
        match self {
            Criterion::MarginalLikelihood => "ml",
            Criterion::Gcv => "gcv",
            Criterion::CrossValidation { .. } => "cv",
            Criterion::Validation => "validation",
        }
    }

    /// A readable description for reports.
    pub fn describe(&self) -> String {
        match self {
            Criterion::MarginalLikelihood => "maximum marginal likelihood".into(),
            Criterion::Gcv => "generalised cross-validation".into(),
            Criterion::CrossValidation { folds } => {
                format!("blocked {folds}-fold cross-validation")
            }
            Criterion::Validation => "validation simulation error".into(),
        }
    }
}

/// How hyperparameters are selected; build with [`SelectionSettings::builder`].
///
/// ```
/// use structid_core::selection::{Criterion, SelectionSettings};
/// let s = SelectionSettings::builder().criterion(Criterion::Gcv).tune_sigma(true).build().unwrap();
/// assert!(s.tune_sigma() && s.tune_beta());
/// assert!(SelectionSettings::builder().criterion(Criterion::CrossValidation { folds: 1 }).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SelectionSettings {
    pub(super) criterion: Criterion,
    pub(super) tune_beta: bool,
    pub(super) tune_sigma: bool,
    pub(super) beta_start: f64,
    pub(super) beta_bounds: (f64, f64),
    pub(super) widen_decades: f64,
    pub(super) sigma_decades: f64,
    pub(super) tolerance: f64,
    #[serde(skip)]
    pub(super) progress: Progress,
}

impl Default for SelectionSettings {
    fn default() -> Self {
        Self {
            criterion: Criterion::MarginalLikelihood,
            tune_beta: true,
            tune_sigma: false,
            beta_start: 0.01,
            beta_bounds: (1e-10, 1e4),
            widen_decades: 6.0,
            sigma_decades: 2.0,
            tolerance: 0.02,
            progress: Progress::none(),
        }
    }
}

impl SelectionSettings {
    /// A builder starting from the defaults: marginal likelihood, β tuned from 0.01 within
    /// [1e-10, 1e4], σ fixed (when tuned: within ±2 decades of the model's), 0.02 decades.
    pub fn builder() -> SelectionSettingsBuilder {
        SelectionSettingsBuilder {
            inner: Self::default(),
        }
    }

    /// The criterion.
    pub fn criterion(&self) -> Criterion {
        self.criterion
    }

    /// Whether β is searched (otherwise the identification settings' β is kept).
    pub fn tune_beta(&self) -> bool {
        self.tune_beta
    }

    /// Whether the kernel widths are searched.
    pub fn tune_sigma(&self) -> bool {
        self.tune_sigma
    }

    /// Where the β search starts.
    pub fn beta_start(&self) -> f64 {
        self.beta_start
    }

    /// The range searched for β.
    pub fn beta_bounds(&self) -> (f64, f64) {
        self.beta_bounds
    }

    /// How many decades the β search is widened by, once, when it ends on a bound of
    /// [`beta_bounds`](Self::beta_bounds) (0: never).
    ///
    /// The Gaussian kernel of the paper is normalised, (2πσ²)^(−p/2)·exp(−‖z − z'‖²/2σ²), so
    /// β carries the units of z^p: data recorded in units 10⁸ times smaller put the same
    /// trade-off 10⁸ times lower in β, below the default floor. A bound is a finding only
    /// after the search has looked past it.
    ///
    /// ```
    /// use structid_core::selection::SelectionSettings;
    /// assert_eq!(SelectionSettings::default().widen_decades(), 6.0);
    /// assert!(SelectionSettings::builder().widen_decades(-1.0).build().is_err());
    /// ```
    pub fn widen_decades(&self) -> f64 {
        self.widen_decades
    }

    /// How many decades either side of the model's widths σ is searched.
    pub fn sigma_decades(&self) -> f64 {
        self.sigma_decades
    }

    /// Width of the final bracket, in decades.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// The observer told after each trial fit: `(trials done, None)`, as the search stops
    /// when it has converged.
    pub fn progress(&self) -> &Progress {
        &self.progress
    }

    /// The same settings with another observer.
    ///
    /// ```
    /// use structid_core::selection::SelectionSettings;
    /// use structid_core::progress::Progress;
    /// let s = SelectionSettings::default().with_progress(Progress::new(|_, _| {}));
    /// assert!(s.progress().is_active());
    /// ```
    pub fn with_progress(&self, progress: Progress) -> Self {
        Self {
            progress,
            ..self.clone()
        }
    }
}

/// Builder of [`SelectionSettings`]; [`build`](Self::build) validates.
#[derive(Clone, Debug)]
pub struct SelectionSettingsBuilder {
    inner: SelectionSettings,
}

impl SelectionSettingsBuilder {
    /// The criterion (default: marginal likelihood).
    pub fn criterion(mut self, c: Criterion) -> Self {
        self.inner.criterion = c;
        self
    }

    /// Whether to search β (default true).
    pub fn tune_beta(mut self, on: bool) -> Self {
        self.inner.tune_beta = on;
        self
    }

    /// Whether to search the kernel widths (default false).
    pub fn tune_sigma(mut self, on: bool) -> Self {
        self.inner.tune_sigma = on;
        self
    }

    /// Start of the β search (default 0.01).
    pub fn beta_start(mut self, beta: f64) -> Self {
        self.inner.beta_start = beta;
        self
    }

    /// Range of the β search (default [1e-10, 1e4]).
    pub fn beta_bounds(mut self, lo: f64, hi: f64) -> Self {
        self.inner.beta_bounds = (lo, hi);
        self
    }

    /// Decades the β search is widened by, once, when it ends on a bound (default 6; 0
    /// never widens). See [`SelectionSettings::widen_decades`].
    pub fn widen_decades(mut self, d: f64) -> Self {
        self.inner.widen_decades = d;
        self
    }

    /// Decades either side of the model's widths searched for σ (default 2).
    pub fn sigma_decades(mut self, d: f64) -> Self {
        self.inner.sigma_decades = d;
        self
    }

    /// Final bracket width in decades (default 0.02).
    pub fn tolerance(mut self, t: f64) -> Self {
        self.inner.tolerance = t;
        self
    }

    /// An observer told after each trial (default none); see [`SelectionSettings::progress`].
    pub fn progress(mut self, p: Progress) -> Self {
        self.inner.progress = p;
        self
    }

    /// Validates and returns the settings.
    pub fn build(self) -> Result<SelectionSettings> {
        let s = self.inner;
        let (lo, hi) = s.beta_bounds;
        positive_finite("lower β bound", lo)?;
        positive_finite("upper β bound", hi)?;
        if lo >= hi {
            return Err(Error::InvalidParameter {
                name: "β bounds".into(),
                value: lo,
                reason: format!("the lower bound must be below the upper bound {hi}"),
            });
        }
        positive_finite("start of the β search", s.beta_start)?;
        if !(s.widen_decades.is_finite() && s.widen_decades >= 0.0) {
            return Err(Error::InvalidParameter {
                name: "widening of the β search (decades)".into(),
                value: s.widen_decades,
                reason: "must be finite and at least 0".into(),
            });
        }
        positive_finite("σ search range (decades)", s.sigma_decades)?;
        positive_finite("tolerance (decades)", s.tolerance)?;
        if let Criterion::CrossValidation { folds } = s.criterion
            && folds < 2
        {
            return Err(Error::InvalidParameter {
                name: "folds".into(),
                value: folds as f64,
                reason: "cross-validation needs at least 2 folds".into(),
            });
        }
        if !s.tune_beta && !s.tune_sigma {
            return Err(Error::InvalidStructure(
                "nothing to select: neither β nor σ is tuned".into(),
            ));
        }
        Ok(s)
    }
}

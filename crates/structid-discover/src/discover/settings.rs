//! Settings of [`discover`](super::discover) and their builder.

use structid_core::progress::Progress;
use structid_core::validation::Scoring;
use structid_core::{Error, Result};

use crate::effects::Effect;
use crate::gap::GapSettings;
use crate::hypotheses::Site;

/// Settings of [`discover`](super::discover); build them with [`DiscoverSettings::builder`].
#[derive(Clone, Debug, PartialEq)]
pub struct DiscoverSettings {
    pub(super) locations: Option<Vec<Site>>,
    pub(super) library: Vec<Effect>,
    pub(super) gap: GapSettings,
    pub(super) sigma_fraction: f64,
    pub(super) trend_degree: usize,
    pub(super) tune_sigma: bool,
    pub(super) total_variation: bool,
    pub(super) significance: f64,
    pub(super) naming_points: usize,
    pub(super) hysteresis_threshold: f64,
    pub(super) table_points: usize,
    pub(super) settle: usize,
    pub(super) scoring: Option<Scoring>,
    pub(super) refine_nominal: bool,
    pub(super) progress: Progress,
}

impl Default for DiscoverSettings {
    /// Every location of the nominal model, the whole effect library, σ = 0.1 × the range of z with a cubic trend,
    /// σ fixed (β by marginal likelihood), total variation for non-smooth estimates, selection
    /// at the 5 % level, 3000 naming points, hysteresis threshold 0.1, 201-point tables, no
    /// settling samples, the scoring chosen from the nominal model (windows for integrators).
    fn default() -> Self {
        Self {
            locations: None,
            library: Effect::LIBRARY.to_vec(),
            gap: GapSettings::default(),
            sigma_fraction: 0.1,
            trend_degree: 3,
            tune_sigma: false,
            total_variation: true,
            significance: crate::table::DEFAULT_SIGNIFICANCE,
            naming_points: 3000,
            hysteresis_threshold: 0.1,
            table_points: 201,
            settle: 0,
            scoring: None,
            refine_nominal: true,
            progress: Progress::none(),
        }
    }
}

impl DiscoverSettings {
    /// The same settings with another progress observer (see
    /// [`DiscoverSettingsBuilder::progress`]).
    ///
    /// ```
    /// use structid_core::progress::Progress;
    /// use structid_discover::discover::DiscoverSettings;
    /// let s = DiscoverSettings::default().with_progress(Progress::new(|_, _| {}));
    /// assert!(s.progress().is_active());
    /// ```
    pub fn with_progress(&self, progress: Progress) -> Self {
        Self {
            progress,
            ..self.clone()
        }
    }

    /// The progress observer.
    pub fn progress(&self) -> &Progress {
        &self.progress
    }

    /// A builder starting from the defaults.
    ///
    /// ```
    /// use structid_discover::discover::DiscoverSettings;
    /// use structid_discover::hypotheses::Site;
    /// let s = DiscoverSettings::builder()
    ///     .locations(vec![Site::Input, Site::OutputFeedback])
    ///     .total_variation(false)
    ///     .build()
    ///     .unwrap();
    /// assert_eq!(s.locations().unwrap().len(), 2);
    /// assert!(DiscoverSettings::builder().sigma_fraction(0.0).build().is_err());
    /// ```
    pub fn builder() -> DiscoverSettingsBuilder {
        DiscoverSettingsBuilder {
            inner: Self::default(),
        }
    }

    /// The candidate locations (`None`: every location of the nominal model).
    pub fn locations(&self) -> Option<&[Site]> {
        self.locations.as_deref()
    }

    /// The families tried when naming.
    pub fn library(&self) -> &[Effect] {
        &self.library
    }

    /// Settings of the gap analysis.
    pub fn gap(&self) -> &GapSettings {
        &self.gap
    }

    /// The Fourier kernel's starting width as a fraction of the range of z.
    pub fn sigma_fraction(&self) -> f64 {
        self.sigma_fraction
    }

    /// Degree of the polynomial trend added to the kernel (0: none).
    pub fn trend_degree(&self) -> usize {
        self.trend_degree
    }

    /// Whether σ is tuned with β by marginal likelihood.
    pub fn tune_sigma(&self) -> bool {
        self.tune_sigma
    }

    /// Whether total variation is tried when the estimate looks non-smooth.
    pub fn total_variation(&self) -> bool {
        self.total_variation
    }

    /// The significance level α of the candidate table's selection rule
    /// ([`crate::table::select`]): the chance of dismissing a row that is as good as the best.
    pub fn significance(&self) -> f64 {
        self.significance
    }

    /// Largest number of points (z_k, ŵ_k) the families are fitted to (evenly spaced in time).
    pub fn naming_points(&self) -> usize {
        self.naming_points
    }

    /// Share of the deconvolved residual energy that the direction of z must explain for the
    /// effect to be called dynamic.
    pub fn hysteresis_threshold(&self) -> f64 {
        self.hysteresis_threshold
    }

    /// Least number of breakpoints of the table written for an unnamed map (more when the
    /// kernel's width σ asks for them: at least four per σ, so that the table follows the
    /// map as estimated).
    pub fn table_points(&self) -> usize {
        self.table_points
    }

    /// Samples at the start of each record left out of the simulation RMS that ranks the
    /// hypotheses, refines and checks the named families (the gaps before and after are over
    /// the whole records).
    pub fn settle(&self) -> usize {
        self.settle
    }
}

impl DiscoverSettings {
    /// Whether G is re-estimated with the found map in the loop (see
    /// [`DiscoverSettingsBuilder::refine_nominal`]).
    pub fn refine_nominal(&self) -> bool {
        self.refine_nominal
    }

    /// How simulations are scored (`None`: chosen from the nominal model, see
    /// [`DiscoverSettingsBuilder::scoring`]).
    pub fn scoring(&self) -> Option<Scoring> {
        self.scoring
    }
}

/// Builder of [`DiscoverSettings`].
#[derive(Clone, Debug)]
pub struct DiscoverSettingsBuilder {
    inner: DiscoverSettings,
}

impl DiscoverSettingsBuilder {
    /// The candidate locations (default: the four built-in ones and those the nominal model
    /// declares).
    pub fn locations(mut self, locations: Vec<Site>) -> Self {
        self.inner.locations = Some(locations);
        self
    }

    /// The families tried when naming (default: [`Effect::LIBRARY`]).
    pub fn library(mut self, library: Vec<Effect>) -> Self {
        self.inner.library = library;
        self
    }

    /// Settings of the gap analysis.
    pub fn gap(mut self, gap: GapSettings) -> Self {
        self.inner.gap = gap;
        self
    }

    /// The kernel's starting width as a fraction of the range of z (default 0.1).
    pub fn sigma_fraction(mut self, f: f64) -> Self {
        self.inner.sigma_fraction = f;
        self
    }

    /// Degree of the polynomial trend (default 3; 0 for none).
    pub fn trend_degree(mut self, d: usize) -> Self {
        self.inner.trend_degree = d;
        self
    }

    /// Whether σ is tuned by marginal likelihood too (default off: the feedback hypotheses
    /// that do not hold drive σ, and with it the number of features, to its limit).
    pub fn tune_sigma(mut self, on: bool) -> Self {
        self.inner.tune_sigma = on;
        self
    }

    /// Whether total variation is tried for non-smooth estimates (default on).
    pub fn total_variation(mut self, on: bool) -> Self {
        self.inner.total_variation = on;
        self
    }

    /// The significance level α of the selection rule (default
    /// [`DEFAULT_SIGNIFICANCE`](crate::table::DEFAULT_SIGNIFICANCE), 0.05); it must lie in
    /// (0, 0.5].
    pub fn significance(mut self, alpha: f64) -> Self {
        self.inner.significance = alpha;
        self
    }

    /// Largest number of naming points (default 3000).
    pub fn naming_points(mut self, n: usize) -> Self {
        self.inner.naming_points = n;
        self
    }

    /// The hysteresis threshold (default 0.1).
    pub fn hysteresis_threshold(mut self, t: f64) -> Self {
        self.inner.hysteresis_threshold = t;
        self
    }

    /// Least breakpoints of a written table (default 201; at least four per kernel width σ).
    pub fn table_points(mut self, n: usize) -> Self {
        self.inner.table_points = n;
        self
    }

    /// Settling samples left out of the ranking and naming RMS (default 0).
    pub fn settle(mut self, n: usize) -> Self {
        self.inner.settle = n;
        self
    }

    /// How every simulation of the workflow is scored: the gaps before and after, the ranking
    /// of the hypotheses, the naming and the polish of the families (default: chosen from the
    /// nominal model: windows, [`Scoring::Windowed`] with
    /// [`structid_core::validation::Windows::for_record`], when it has a pole on or within
    /// 10⁻³ of the unit circle, whose free-run simulation drifts; one free run otherwise).
    pub fn scoring(mut self, scoring: Scoring) -> Self {
        self.inner.scoring = Some(scoring);
        self
    }

    /// Re-estimate G with the map in the loop (default on). A nominal model estimated from
    /// data (a best linear approximation) is biased by the very effect that is missing, and the
    /// map alone cannot absorb G's dynamic error. The best hypothesis is then refined jointly:
    /// G by output error with its nonparametric map held fixed, the map identified again around
    /// the new G, for as long as the validation RMS falls by 5 % a step (at most three steps);
    /// and G is refitted once more with the named map held fixed
    /// ([`structid_core::refine::refine_linear`]). A new G is kept only when the validation RMS
    /// falls, so an exact G stays as it is. The finding reports G before and after
    /// ([`crate::discover::NominalRefinement`]). Only the best location is refined: G refitted
    /// around a map at the wrong location absorbs part of the effect too.
    pub fn refine_nominal(mut self, on: bool) -> Self {
        self.inner.refine_nominal = on;
        self
    }

    /// An observer told after each candidate location is identified: `(locations done,
    /// Some(locations))` (default none). A discovery then names, refines and checks the best
    /// one, which it does not count.
    pub fn progress(mut self, p: Progress) -> Self {
        self.inner.progress = p;
        self
    }

    /// Validates and returns the settings.
    pub fn build(self) -> Result<DiscoverSettings> {
        let s = self.inner;
        let bad = |name: &str, value: f64, reason: &str| Error::InvalidParameter {
            name: name.into(),
            value,
            reason: reason.into(),
        };
        if s.locations.as_ref().is_some_and(Vec::is_empty) {
            return Err(Error::InvalidStructure(
                "discovery needs at least one candidate location".into(),
            ));
        }
        if s.library.is_empty() {
            return Err(Error::InvalidStructure(
                "discovery needs at least one effect family to name".into(),
            ));
        }
        // (parameter, its value, whether it is valid, what it must be)
        let checks = [
            (
                "sigma_fraction",
                s.sigma_fraction,
                s.sigma_fraction.is_finite() && s.sigma_fraction > 0.0,
                "must be a positive fraction of the range of z",
            ),
            (
                "significance",
                s.significance,
                s.significance > 0.0 && s.significance <= 0.5,
                "must be a probability in (0, 0.5]",
            ),
            (
                "naming_points",
                s.naming_points as f64,
                s.naming_points >= 20,
                "must be at least 20",
            ),
            (
                "hysteresis_threshold",
                s.hysteresis_threshold,
                s.hysteresis_threshold > 0.0 && s.hysteresis_threshold < 1.0,
                "must be a share between 0 and 1",
            ),
            (
                "table_points",
                s.table_points as f64,
                s.table_points >= 2,
                "must be at least 2",
            ),
            (
                "trend_degree",
                s.trend_degree as f64,
                s.trend_degree <= 64,
                "must be at most 64",
            ),
        ];
        if let Some(&(name, value, _, reason)) = checks.iter().find(|c| !c.2) {
            return Err(bad(name, value, reason));
        }
        Ok(s)
    }
}

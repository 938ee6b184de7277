//! Settings of the iterative solvers, apart from the solvers so that the identification
//! settings can hold them without depending on the solvers themselves.

use crate::error::{Error, Result, positive_finite};

/// The conic solver's name in reports.
pub(crate) const CONIC_NAME: &str = "clarabel";
/// The ADMM solver's name in reports.
pub(crate) const ADMM_NAME: &str = "admm";

/// Validates the tolerance and iteration limit shared by the iterative solvers' settings.
pub(crate) fn check_iterative(solver: &str, tolerance: f64, max_iterations: usize) -> Result<()> {
    crate::error::positive_finite(&format!("{solver} tolerance"), tolerance)?;
    if max_iterations == 0 {
        return Err(Error::InvalidParameter {
            name: format!("{solver} max_iterations"),
            value: 0.0,
            reason: "must be at least 1".into(),
        });
    }
    Ok(())
}

/// Settings of the conic (Clarabel) solver.
///
/// ```
/// use structid_core::solver::conic::ConicSettings;
/// let s = ConicSettings::builder().tolerance(1e-9).max_iterations(300).build().unwrap();
/// assert_eq!(s.tolerance(), 1e-9);
/// assert!(ConicSettings::builder().tolerance(0.0).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConicSettings {
    tolerance: f64,
    max_iterations: u32,
    time_limit: Option<f64>,
}

impl Default for ConicSettings {
    /// Tolerance 1e-8 (Clarabel's default, for the duality gap and feasibility), 200
    /// iterations, no time limit.
    fn default() -> Self {
        Self {
            tolerance: 1e-8,
            max_iterations: 200,
            time_limit: None,
        }
    }
}

impl ConicSettings {
    /// A builder from the defaults.
    pub fn builder() -> ConicSettingsBuilder {
        ConicSettingsBuilder(Self::default())
    }
    /// Relative and absolute tolerance on the duality gap and the residuals.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }
    /// The iteration limit.
    pub fn max_iterations(&self) -> u32 {
        self.max_iterations
    }
    /// The time limit in seconds, if any.
    pub fn time_limit(&self) -> Option<f64> {
        self.time_limit
    }
}

/// Builder for [`ConicSettings`].
#[derive(Clone, Debug)]
pub struct ConicSettingsBuilder(ConicSettings);

impl ConicSettingsBuilder {
    /// Tolerance (> 0).
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.0.tolerance = tol;
        self
    }
    /// Iteration limit (≥ 1).
    pub fn max_iterations(mut self, n: u32) -> Self {
        self.0.max_iterations = n;
        self
    }
    /// Time limit in seconds (> 0).
    pub fn time_limit(mut self, seconds: f64) -> Self {
        self.0.time_limit = Some(seconds);
        self
    }
    /// Validates.
    pub fn build(self) -> Result<ConicSettings> {
        check_iterative(CONIC_NAME, self.0.tolerance, self.0.max_iterations as usize)?;
        if let Some(t) = self.0.time_limit {
            positive_finite("conic time_limit", t)?;
        }
        Ok(self.0)
    }
}

/// Settings of the ADMM solver.
///
/// ```
/// use structid_core::solver::admm::AdmmSettings;
/// let s = AdmmSettings::builder().tolerance(1e-8).max_iterations(50_000).build().unwrap();
/// assert_eq!(s.max_iterations(), 50_000);
/// assert!(AdmmSettings::builder().relaxation(2.5).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdmmSettings {
    tolerance: f64,
    max_iterations: usize,
    rho: Option<f64>,
    relaxation: f64,
    adaptive: bool,
}

impl Default for AdmmSettings {
    /// Tolerance 1e-7, 20 000 iterations, ρ₀ from the frequency responses with bounded
    /// residual balancing (see the module documentation), over-relaxation 1.6.
    fn default() -> Self {
        Self {
            tolerance: 1e-7,
            max_iterations: 20_000,
            rho: None,
            relaxation: 1.6,
            adaptive: true,
        }
    }
}

impl AdmmSettings {
    /// A builder from the defaults.
    pub fn builder() -> AdmmSettingsBuilder {
        AdmmSettingsBuilder(Self::default())
    }
    /// The relative tolerance ε_rel (ε_abs = ε_rel × RMS of r).
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }
    /// The iteration limit.
    pub fn max_iterations(&self) -> usize {
        self.max_iterations
    }
    /// The initial penalty ρ (`None`: from the paths' gains).
    pub fn rho(&self) -> Option<f64> {
        self.rho
    }
    /// The over-relaxation factor α ∈ (0, 2).
    pub fn relaxation(&self) -> f64 {
        self.relaxation
    }
    /// Whether ρ is balanced against the residuals (on by default), within bounds relative to
    /// the w-step's largest curvature: the frequency-response ρ₀ is optimal for the quadratic
    /// part alone, but where the total variation dominates (large β, a flat map) the best ρ
    /// is orders of magnitude above it, and at small β below. Off, ρ stays at its initial
    /// value (given, or ρ₀).
    pub fn adaptive(&self) -> bool {
        self.adaptive
    }
}

/// Builder for [`AdmmSettings`].
#[derive(Clone, Debug)]
pub struct AdmmSettingsBuilder(AdmmSettings);

impl AdmmSettingsBuilder {
    /// Relative tolerance (> 0).
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.0.tolerance = tol;
        self
    }
    /// Iteration limit (≥ 1).
    pub fn max_iterations(mut self, n: usize) -> Self {
        self.0.max_iterations = n;
        self
    }
    /// Initial ρ (> 0).
    pub fn rho(mut self, rho: f64) -> Self {
        self.0.rho = Some(rho);
        self
    }
    /// Over-relaxation α ∈ (0, 2); 1 is plain ADMM.
    pub fn relaxation(mut self, alpha: f64) -> Self {
        self.0.relaxation = alpha;
        self
    }
    /// Whether ρ adapts to the residuals.
    pub fn adaptive(mut self, adaptive: bool) -> Self {
        self.0.adaptive = adaptive;
        self
    }
    /// Validates.
    pub fn build(self) -> Result<AdmmSettings> {
        check_iterative(ADMM_NAME, self.0.tolerance, self.0.max_iterations)?;
        if let Some(rho) = self.0.rho {
            positive_finite("admm rho", rho)?;
        }
        let a = self.0.relaxation;
        if !(a > 0.0 && a < 2.0) {
            return Err(Error::InvalidParameter {
                name: "admm relaxation".into(),
                value: a,
                reason: "over-relaxation must lie in (0, 2)".into(),
            });
        }
        Ok(self.0)
    }
}

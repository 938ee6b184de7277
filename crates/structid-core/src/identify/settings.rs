//! The settings of [`identify`](super::identify): β, the solver, the initial state, the
//! iterative solvers' settings and the memory budget.

use crate::error::{Error, Result, positive_finite};
use crate::initial_state::InitialState;
use crate::solver::settings::{AdmmSettings, ConicSettings};

/// Which solver `identify` uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum SolverChoice {
    /// Pick from the dispersions and the problem size.
    #[default]
    Auto,
    /// The exact dual (representer) solve with the dense L·n_y × L·n_y matrix M.
    Exact,
    /// The feature-space solve, linear in L, for dispersions with finitely many features
    /// (e.g. [`crate::FourierDispersion`]).
    Features,
    /// The conic program, solved by the interior-point solver Clarabel
    /// ([`crate::solver::conic`]): exact; sparse for total variation, dense in L for quadratic
    /// blocks, so the one solver for models that mix the two.
    Clarabel,
    /// ADMM for total-variation dispersions ([`crate::solver::admm`]): a Kalman smoother and an
    /// exact proximal step per iteration, linear in L.
    Admm,
}

impl SolverChoice {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            SolverChoice::Auto => "auto",
            SolverChoice::Exact => "exact",
            SolverChoice::Features => "features",
            SolverChoice::Clarabel => "clarabel",
            SolverChoice::Admm => "admm",
        }
    }

    /// The choice whose [`name`](Self::name) is `name`, if any.
    ///
    /// ```
    /// use structid_core::SolverChoice;
    /// assert_eq!(SolverChoice::from_name("admm"), Some(SolverChoice::Admm));
    /// assert_eq!(SolverChoice::from_name("newton"), None);
    /// ```
    pub fn from_name(name: &str) -> Option<Self> {
        [
            SolverChoice::Auto,
            SolverChoice::Exact,
            SolverChoice::Features,
            SolverChoice::Clarabel,
            SolverChoice::Admm,
        ]
        .into_iter()
        .find(|c| c.name() == name)
    }
}

/// Settings of [`identify()`](crate::identify()); build them with [`IdentifySettings::builder`].
///
/// ```
/// use structid_core::IdentifySettings;
/// let s = IdentifySettings::builder().beta(0.1).build().unwrap();
/// assert_eq!(s.beta(), 0.1);
/// assert!(IdentifySettings::builder().beta(-1.0).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IdentifySettings {
    beta: f64,
    solver: SolverChoice,
    memory_limit_bytes: Option<u64>,
    initial_state: InitialState,
    conic: ConicSettings,
    admm: AdmmSettings,
    posterior: bool,
}

impl Default for IdentifySettings {
    /// β = 0.01 (the middle of the paper's range 0.001–0.1), automatic solver, memory limit
    /// three quarters of the memory available when identification starts.
    fn default() -> Self {
        Self {
            beta: 0.01,
            solver: SolverChoice::Auto,
            memory_limit_bytes: None,
            initial_state: InitialState::Zero,
            conic: ConicSettings::default(),
            admm: AdmmSettings::default(),
            posterior: false,
        }
    }
}

impl IdentifySettings {
    /// A builder starting from the defaults.
    pub fn builder() -> IdentifySettingsBuilder {
        IdentifySettingsBuilder {
            inner: Self::default(),
        }
    }

    /// The same settings with the posterior kept or not.
    ///
    /// ```
    /// use structid_core::IdentifySettings;
    /// assert!(IdentifySettings::default().with_posterior(true).posterior());
    /// ```
    pub fn with_posterior(&self, posterior: bool) -> Self {
        Self {
            posterior,
            ..self.clone()
        }
    }

    /// The same settings with another solver choice.
    ///
    /// ```
    /// use structid_core::{IdentifySettings, SolverChoice};
    /// let s = IdentifySettings::default().with_solver(SolverChoice::Exact);
    /// assert_eq!(s.solver(), SolverChoice::Exact);
    /// ```
    pub fn with_solver(&self, solver: SolverChoice) -> Self {
        Self {
            solver,
            ..self.clone()
        }
    }

    /// The same settings with another initial-state treatment.
    pub fn with_initial_state(&self, initial_state: InitialState) -> Self {
        Self {
            initial_state,
            ..self.clone()
        }
    }

    /// The same settings with another β (> 0), e.g. for a sweep.
    ///
    /// ```
    /// use structid_core::IdentifySettings;
    /// let s = IdentifySettings::default().with_beta(0.1).unwrap();
    /// assert_eq!(s.beta(), 0.1);
    /// assert!(IdentifySettings::default().with_beta(0.0).is_err());
    /// ```
    pub fn with_beta(&self, beta: f64) -> Result<Self> {
        positive_finite("beta", beta)?;
        Ok(Self {
            beta,
            ..self.clone()
        })
    }

    /// The weight β of the dispersion against the noise energy.
    pub fn beta(&self) -> f64 {
        self.beta
    }

    /// The solver choice.
    pub fn solver(&self) -> SolverChoice {
        self.solver
    }

    /// How the initial state is treated.
    pub fn initial_state(&self) -> InitialState {
        self.initial_state
    }

    /// Settings of the conic (Clarabel) solver.
    pub fn conic(&self) -> &ConicSettings {
        &self.conic
    }

    /// Settings of the ADMM solver.
    pub fn admm(&self) -> &AdmmSettings {
        &self.admm
    }

    /// Whether the exact and feature solvers keep what the posterior bands need
    /// ([`Identification::posterior`](crate::Identification::posterior)).
    pub fn posterior(&self) -> bool {
        self.posterior
    }

    /// The memory budget in bytes (`None`: detect at run time).
    pub fn memory_limit_bytes(&self) -> Option<u64> {
        self.memory_limit_bytes
    }

    /// The budget that applies now: the explicit limit, or ¾ of `MemAvailable`
    /// (4 GiB when it cannot be read).
    pub fn effective_memory_limit(&self) -> u64 {
        self.memory_limit_bytes
            .unwrap_or_else(|| available_memory_bytes().map_or(4 << 30, |b| b / 4 * 3))
    }
}

/// The memory available for new allocations now (`MemAvailable` of `/proc/meminfo`), in
/// bytes; `None` where it cannot be read (other systems than Linux).
pub fn available_memory_bytes() -> Option<u64> {
    meminfo("MemAvailable:")
}

/// The machine's physical memory (`MemTotal` of `/proc/meminfo`), in bytes; `None` where it
/// cannot be read (other systems than Linux). A memory budget above it cannot be honoured.
pub fn total_memory_bytes() -> Option<u64> {
    meminfo("MemTotal:")
}

/// A `kB` field of `/proc/meminfo`, in bytes.
fn meminfo(key: &str) -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    parse_meminfo(&text, key)
}

fn parse_meminfo(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// Builder for [`IdentifySettings`]; [`IdentifySettingsBuilder::build`] validates.
#[derive(Clone, Debug)]
pub struct IdentifySettingsBuilder {
    inner: IdentifySettings,
}

impl IdentifySettingsBuilder {
    /// β > 0.
    pub fn beta(mut self, beta: f64) -> Self {
        self.inner.beta = beta;
        self
    }
    /// The solver.
    pub fn solver(mut self, solver: SolverChoice) -> Self {
        self.inner.solver = solver;
        self
    }
    /// Zero or estimated initial state.
    pub fn initial_state(mut self, initial_state: InitialState) -> Self {
        self.inner.initial_state = initial_state;
        self
    }
    /// Settings of the conic (Clarabel) solver.
    pub fn conic(mut self, conic: ConicSettings) -> Self {
        self.inner.conic = conic;
        self
    }
    /// Settings of the ADMM solver.
    pub fn admm(mut self, admm: AdmmSettings) -> Self {
        self.inner.admm = admm;
        self
    }
    /// Keep the posterior of the maps (default `false`): the exact and feature solvers then
    /// store their Cholesky factor and the noise level in [`Identification::posterior`](crate::Identification::posterior), and
    /// [`Identification::posterior_std`](crate::Identification::posterior_std) gives pointwise standard deviations (uncertainty
    /// bands; see [`crate::identify::posterior`]). The exact solver's factor is n×n f64 (n = L·n_y),
    /// kept as long as the identification; its memory estimate includes it.
    ///
    /// ```
    /// use structid_core::IdentifySettings;
    /// assert!(!IdentifySettings::default().posterior());
    /// assert!(IdentifySettings::builder().posterior(true).build().unwrap().posterior());
    /// ```
    pub fn posterior(mut self, keep: bool) -> Self {
        self.inner.posterior = keep;
        self
    }
    /// An explicit memory budget in bytes.
    pub fn memory_limit_bytes(mut self, bytes: u64) -> Self {
        self.inner.memory_limit_bytes = Some(bytes);
        self
    }
    /// Validates and returns the settings.
    pub fn build(self) -> Result<IdentifySettings> {
        positive_finite("beta", self.inner.beta)?;
        if self.inner.memory_limit_bytes == Some(0) {
            return Err(Error::InvalidParameter {
                name: "memory_limit_bytes".into(),
                value: 0.0,
                reason: "must be positive".into(),
            });
        }
        Ok(self.inner)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meminfo_fields_are_read_in_bytes() {
        let text = "MemTotal:       24684084 kB\nMemFree:        22819832 kB\nMemAvailable:   24240236 kB\n";
        assert_eq!(parse_meminfo(text, "MemTotal:"), Some(24684084 * 1024));
        assert_eq!(parse_meminfo(text, "MemAvailable:"), Some(24240236 * 1024));
        assert_eq!(parse_meminfo(text, "SwapTotal:"), None);
        assert_eq!(parse_meminfo("MemTotal: lots kB\n", "MemTotal:"), None);
        assert_eq!(
            parse_meminfo(&format!("MemTotal: {} kB\n", u64::MAX), "MemTotal:"),
            None
        );
        // On Linux the machine's memory is known and at least what is available.
        if cfg!(target_os = "linux") {
            let total = total_memory_bytes().expect("/proc/meminfo");
            assert!(total > 0 && available_memory_bytes().is_some_and(|a| a <= total));
        }
    }
}

//! The options of an identification as the front ends take them (the CLI's flags, Python's
//! keywords), checked and turned into [`IdentifySettings`]: one place for the rules, so that
//! both refuse the same values for the same reasons.

use structid_core::identify::settings::total_memory_bytes;
use structid_core::solver::admm::AdmmSettings;
use structid_core::solver::conic::ConicSettings;
use structid_core::{IdentifySettings, InitialState, SolverChoice};

use crate::error::{Result, WorkflowError};

/// The largest β accepted: two decades above the top of the automatic search (10⁻¹⁰ … 10⁴).
/// β weighs the dispersion against the mean noise energy per sample; far above that the
/// dispersion outweighs any record's noise and the estimate is what the dispersion leaves free
/// (a constant, or the trend), whatever the data say, and L·β overflows for absurd values
/// such as 1e308.
pub const MAX_BETA: f64 = 1e6;

/// A finite value greater than zero, or [`WorkflowError::InvalidOption`] naming `option`.
///
/// ```
/// use structid_workflow::options::positive;
/// assert_eq!(positive("sigma", 0.5).unwrap(), 0.5);
/// assert!(positive("sigma", f64::NAN).unwrap_err().to_string().contains("for sigma"));
/// ```
pub fn positive(option: &'static str, v: f64) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(invalid(
            option,
            v,
            "it must be a finite number greater than zero",
        ))
    }
}

/// A β: finite, greater than zero, at most [`MAX_BETA`].
pub fn beta(v: f64) -> Result<f64> {
    let v = positive("beta", v)?;
    if v > MAX_BETA {
        return Err(WorkflowError::InvalidOption {
            option: "beta",
            value: format!("{v:e}"),
            rule: format!(
                "above {MAX_BETA:e} the dispersion outweighs the noise energy of any record and \
                 the estimate ignores the data; give 0 < β ≤ {MAX_BETA:e} (typically 1e-4 … 1; \
                 `auto` searches 1e-10 … 1e4)"
            ),
        });
    }
    Ok(v)
}

fn invalid(option: &'static str, value: impl ToString, rule: impl Into<String>) -> WorkflowError {
    WorkflowError::InvalidOption {
        option,
        value: value.to_string(),
        rule: rule.into(),
    }
}

/// How an identification solves: β (when given), bands, initial state, solver and its limits.
#[derive(Clone, Debug, PartialEq)]
pub struct SolveOptions {
    /// β, or `None` for the default (the start of a selection).
    pub beta: Option<f64>,
    /// Keep the posterior for bands.
    pub bands: bool,
    /// Zero or estimated initial state.
    pub initial_state: InitialState,
    /// The solver.
    pub solver: SolverChoice,
    /// Tolerance of the iterative solvers.
    pub tolerance: Option<f64>,
    /// Iteration limit of the iterative solvers.
    pub max_iterations: Option<usize>,
    /// Memory budget in MiB.
    pub memory_limit_mib: Option<u64>,
}

impl Default for SolveOptions {
    fn default() -> Self {
        Self {
            beta: None,
            bands: true,
            initial_state: InitialState::Zero,
            solver: SolverChoice::Auto,
            tolerance: None,
            max_iterations: None,
            memory_limit_mib: None,
        }
    }
}

impl SolveOptions {
    /// The identification settings of these options.
    ///
    /// # Errors
    /// [`WorkflowError::InvalidOption`] for a β out of (0, [`MAX_BETA`]], a tolerance that is
    /// not finite and positive, zero iterations, and a memory budget of zero or above the
    /// machine's memory.
    ///
    /// ```
    /// use structid_workflow::options::SolveOptions;
    /// let o = SolveOptions { beta: Some(1e-3), max_iterations: Some(0), ..Default::default() };
    /// assert!(o.settings().unwrap_err().to_string().contains("max_iterations"));
    /// let o = SolveOptions { beta: Some(1e-3), ..Default::default() };
    /// assert_eq!(o.settings().unwrap().beta(), 1e-3);
    /// ```
    pub fn settings(&self) -> Result<IdentifySettings> {
        let beta = match self.beta {
            Some(b) => beta(b)?,
            None => IdentifySettings::default().beta(),
        };
        let mut b = IdentifySettings::builder()
            .beta(beta)
            .posterior(self.bands)
            .initial_state(self.initial_state)
            .solver(self.solver);
        if self.tolerance.is_some() || self.max_iterations.is_some() {
            let mut conic = ConicSettings::builder();
            let mut admm = AdmmSettings::builder();
            if let Some(t) = self.tolerance {
                let t = positive("tolerance", t)?;
                conic = conic.tolerance(t);
                admm = admm.tolerance(t);
            }
            if let Some(n) = self.max_iterations {
                if n == 0 {
                    return Err(invalid("max_iterations", 0, "it must be at least 1"));
                }
                conic = conic.max_iterations(u32::try_from(n).unwrap_or(u32::MAX));
                admm = admm.max_iterations(n);
            }
            b = b.conic(conic.build()?).admm(admm.build()?);
        }
        if let Some(mib) = self.memory_limit_mib {
            check_memory_limit(mib, total_memory_bytes())?;
            b = b.memory_limit_bytes(mib << 20);
        }
        Ok(b.build()?)
    }
}

/// Refuses a memory budget of zero or above the machine's memory `total` (bytes; unchecked
/// where it is unknown): the solvers would plan for memory that does not exist and fail on an
/// allocation instead of choosing a smaller method or refusing the problem.
fn check_memory_limit(mib: u64, total: Option<u64>) -> Result<()> {
    let rule = match (mib.checked_mul(1 << 20), total) {
        _ if mib == 0 => "it must be at least 1".to_string(),
        (Some(b), Some(t)) if b > t => format!(
            "the machine has {} MiB of memory; give at most that",
            t >> 20
        ),
        (None, _) => "more memory than any machine has".to_string(),
        _ => return Ok(()),
    };
    Err(invalid("memory_limit_mib", mib, rule))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_limits_beyond_the_machine_or_zero_are_refused() {
        let total = Some(8u64 << 30);
        assert!(check_memory_limit(1024, total).is_ok());
        assert!(check_memory_limit(1024, None).is_ok());
        let e = check_memory_limit(9 * 1024, total).unwrap_err().to_string();
        assert!(e.contains("8192 MiB"), "{e}");
        let e = check_memory_limit(0, total).unwrap_err().to_string();
        assert!(e.contains("at least 1"), "{e}");
        let e = check_memory_limit(u64::MAX, None).unwrap_err().to_string();
        assert!(e.contains("any machine"), "{e}");
    }

    #[test]
    fn beta_is_refused_outside_its_range() {
        assert!(beta(1e-3).is_ok());
        assert!(beta(MAX_BETA).is_ok());
        for bad in [0.0, -1.0, f64::INFINITY, f64::NAN, 2.0 * MAX_BETA] {
            assert!(beta(bad).is_err(), "{bad}");
        }
    }
}

//! Which solver ran, why, and how it stopped: the vocabulary of [`crate::Diagnostics`].

use std::fmt;

use crate::error::Error;
use crate::identify::settings::SolverChoice;

/// The solver that ran.
///
/// `Display` (and serde) give the name used on the command line and in reports:
/// `exact`, `features (m = 63)`, `clarabel`, `admm`.
///
/// ```
/// use structid_core::SolverKind;
/// assert_eq!(SolverKind::Features { features: 63 }.to_string(), "features (m = 63)");
/// assert_eq!(SolverKind::Features { features: 63 }.name(), "features");
/// assert_eq!(SolverKind::Admm, "admm");
/// assert_eq!(SolverKind::Features { features: 63 }, "features (m = 63)");
/// assert_ne!(SolverKind::Features { features: 63 }, "features (m = 6)");
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum SolverKind {
    /// The exact dual (representer) solve ([`crate::solver::exact`]); the default only so that
    /// [`crate::Diagnostics`] has one.
    #[default]
    Exact,
    /// The feature-space solve ([`crate::solver::features`]).
    Features {
        /// The number m of features of all blocks together.
        features: usize,
    },
    /// The conic program solved by Clarabel ([`crate::solver::conic`]).
    Clarabel,
    /// ADMM for total variation ([`crate::solver::admm`]).
    Admm,
}

impl SolverKind {
    /// The solver's name without its parameters: `exact`, `features`, `clarabel` or `admm`
    /// (the values of `--solver`).
    pub fn name(self) -> &'static str {
        match self {
            SolverKind::Exact => "exact",
            SolverKind::Features { .. } => "features",
            SolverKind::Clarabel => "clarabel",
            SolverKind::Admm => "admm",
        }
    }

    /// The [`SolverChoice`] that requests this solver.
    pub fn choice(self) -> SolverChoice {
        match self {
            SolverKind::Exact => SolverChoice::Exact,
            SolverKind::Features { .. } => SolverChoice::Features,
            SolverKind::Clarabel => SolverChoice::Clarabel,
            SolverKind::Admm => SolverChoice::Admm,
        }
    }
}

impl fmt::Display for SolverKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SolverKind::Features { features } => write!(f, "features (m = {features})"),
            other => f.write_str(other.name()),
        }
    }
}

impl serde::Serialize for SolverKind {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl PartialEq<str> for SolverKind {
    /// Compares the printed form ([`fmt::Display`]).
    fn eq(&self, other: &str) -> bool {
        match self {
            SolverKind::Features { features } => {
                other
                    .strip_prefix("features (m = ")
                    .and_then(|rest| rest.strip_suffix(')'))
                    == Some(features.to_string().as_str())
            }
            kind => kind.name() == other,
        }
    }
}

impl PartialEq<&str> for SolverKind {
    /// Compares the printed form ([`fmt::Display`]).
    fn eq(&self, other: &&str) -> bool {
        self == *other
    }
}

/// Why the solver that ran was chosen: requested, or one case of the automatic rule (see the
/// [module documentation](self)) with the numbers it compared.
///
/// `Display` (and serde) give the sentence printed by the command line and written to reports.
///
/// ```
/// use structid_core::SolverReason;
/// let r = SolverReason::TotalVariationSmall { size: 800, limit: 1000 };
/// assert_eq!(
///     r.to_string(),
///     "automatic: total variation with L·n_y = 800 ≤ 1000, the exact conic solver"
/// );
/// assert_eq!(SolverReason::Requested.to_string(), "requested");
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum SolverReason {
    /// The settings named the solver.
    #[default]
    Requested,
    /// Quadratic and total-variation blocks together with samples held out in part (some of
    /// their output channels): only Clarabel handles both.
    MixedDispersions,
    /// Quadratic and total-variation blocks together on a small problem: Clarabel, exact.
    MixedSmall {
        /// L·n_y.
        size: usize,
        /// [`MIXED_CONIC_AUTO_LIMIT`](crate::solver::choice::MIXED_CONIC_AUTO_LIMIT).
        limit: usize,
    },
    /// Quadratic and total-variation blocks together on a large problem: ADMM, linear in L.
    MixedLarge {
        /// L·n_y.
        size: usize,
        /// [`MIXED_CONIC_AUTO_LIMIT`](crate::solver::choice::MIXED_CONIC_AUTO_LIMIT).
        limit: usize,
    },
    /// Total variation with samples held out in part (some of their output channels): only
    /// Clarabel handles them.
    TotalVariationHeldOut,
    /// Total variation on a small problem: Clarabel, exact.
    TotalVariationSmall {
        /// L·n_y.
        size: usize,
        /// [`CONIC_AUTO_LIMIT`](crate::solver::choice::CONIC_AUTO_LIMIT).
        limit: usize,
    },
    /// Total variation on a large problem: ADMM, linear in L.
    TotalVariationLarge {
        /// L·n_y.
        size: usize,
        /// [`CONIC_AUTO_LIMIT`](crate::solver::choice::CONIC_AUTO_LIMIT).
        limit: usize,
    },
    /// Every block has finitely many features, few against the output samples.
    FewFeatures {
        /// m, the features of all blocks together.
        features: usize,
        /// L·n_y, the output samples.
        rows: usize,
    },
    /// The exact solver would exceed the memory budget and every block has features.
    ExactOverBudget {
        /// The exact solver's estimated peak memory in bytes.
        needed_bytes: u64,
        /// The budget in bytes.
        limit_bytes: u64,
    },
    /// Quadratic dispersions otherwise: the exact solver (which refuses a problem above the
    /// budget with [`Error::TooLarge`]).
    Quadratic {
        /// The exact solver's estimated peak memory in bytes.
        needed_bytes: u64,
    },
    /// β (and σ) were selected in feature space ([`crate::selection::select`]), so the
    /// final fit uses the feature solver too.
    FeatureSpaceSelection,
}

impl fmt::Display for SolverReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SolverReason::Requested => f.write_str("requested"),
            SolverReason::MixedDispersions => f.write_str(
                "automatic: quadratic and total-variation dispersions together with samples held out \
                 in part, which only the conic solver handles",
            ),
            SolverReason::MixedSmall { size, limit } => write!(
                f,
                "automatic: quadratic and total-variation dispersions together with L·n_y = {size} ≤ \
                 {limit}, the exact conic solver"
            ),
            SolverReason::MixedLarge { size, limit } => write!(
                f,
                "automatic: quadratic and total-variation dispersions together with L·n_y = {size} > \
                 {limit}, ADMM (linear in L)"
            ),
            SolverReason::TotalVariationHeldOut => f.write_str(
                "automatic: total variation with samples held out in part, which only the conic \
                 solver handles",
            ),
            SolverReason::TotalVariationSmall { size, limit } => write!(
                f,
                "automatic: total variation with L·n_y = {size} ≤ {limit}, the exact conic solver"
            ),
            SolverReason::TotalVariationLarge { size, limit } => write!(
                f,
                "automatic: total variation with L·n_y = {size} > {limit}, ADMM (linear in L)"
            ),
            SolverReason::FewFeatures { features, rows } => write!(
                f,
                "automatic: every block has finite features ({features} in all, at most a quarter of \
                 the {rows} output samples), the feature solver"
            ),
            SolverReason::ExactOverBudget { .. } => f.write_str(
                "automatic: the exact solver's memory exceeds the budget and every block has finite \
                 features",
            ),
            SolverReason::Quadratic { .. } => f.write_str(
                "automatic: quadratic dispersions within the memory budget, the exact solver",
            ),
            SolverReason::FeatureSpaceSelection => f.write_str(
                "automatic: the hyperparameters were selected in feature space, so the feature solver",
            ),
        }
    }
}

impl serde::Serialize for SolverReason {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// How the solver stopped (after Clarabel's statuses).
///
/// The direct solvers always report [`SolveStatus::Solved`]. An iterative solver that hits its
/// iteration or time limit, or stops on numerical trouble with a finite iterate, returns that
/// iterate with [`SolveStatus::MaxIterations`], [`SolveStatus::TimeLimit`] or
/// [`SolveStatus::NumericalFailure`] and a warning; [`crate::Identification::converged`] turns that into
/// [`Error::NotConverged`] for callers that need a converged estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum SolveStatus {
    /// The tolerances were met.
    #[default]
    Solved,
    /// Clarabel met only its reduced-accuracy tolerances (a warning says which residuals).
    AlmostSolved,
    /// The iteration limit was reached first: the estimate is the last iterate.
    MaxIterations,
    /// The time limit was reached first: the estimate is the last iterate.
    TimeLimit,
    /// The solver stopped on numerical trouble (Clarabel's `NumericalError` or
    /// `InsufficientProgress`): the estimate is the last iterate, finite but not optimal.
    NumericalFailure,
}

impl SolveStatus {
    /// Whether the estimate met the solver's tolerances ([`SolveStatus::Solved`] or
    /// [`SolveStatus::AlmostSolved`]).
    pub fn is_converged(self) -> bool {
        matches!(self, SolveStatus::Solved | SolveStatus::AlmostSolved)
    }
}

impl fmt::Display for SolveStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SolveStatus::Solved => "solved",
            SolveStatus::AlmostSolved => "almost solved (reduced accuracy)",
            SolveStatus::MaxIterations => "iteration limit reached",
            SolveStatus::TimeLimit => "time limit reached",
            SolveStatus::NumericalFailure => "numerical failure",
        })
    }
}

/// The warning an iterative solver adds when it returns an unconverged iterate: the text of
/// the [`Error::NotConverged`] that [`crate::Identification::converged`] would give.
pub(crate) fn unconverged_warning(
    solver: SolverKind,
    iterations: usize,
    detail: &str,
    status: SolveStatus,
) -> String {
    format!(
        "{}; the estimate is the last iterate",
        not_converged(solver, iterations, Some(detail), status)
    )
}

/// The error that an unconverged iterative solve used to be, built from its diagnostics.
pub(crate) fn not_converged(
    solver: SolverKind,
    iterations: usize,
    detail: Option<&str>,
    status: SolveStatus,
) -> Error {
    Error::NotConverged {
        solver: solver.name().into(),
        iterations,
        detail: detail.map_or_else(|| format!("status: {status}"), str::to_string),
    }
}

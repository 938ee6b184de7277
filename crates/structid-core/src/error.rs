//! The error type of `structid-core`.

use structid_lti::LtiError;

/// Everything that can go wrong while building a model, preparing data or identifying maps.
///
/// Each variant carries enough context for a command-line user to act on it without reading code.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An error from the linear-systems layer (dimensions, non-finite matrix entries, …).
    #[error(transparent)]
    Lti(#[from] LtiError),

    /// An error from the linear-model layer (ARX, output error, polynomial models), kept as the
    /// source.
    #[error("linear estimation: {0}")]
    Linear(#[from] structid_linear::LinearError),

    /// The interior-point solver Clarabel refused the conic program's data or settings.
    #[error("numerical failure: clarabel rejected the problem data: {0}")]
    Clarabel(#[from] clarabel::solver::SolverError),

    /// Two things that must agree in size do not.
    #[error("dimension mismatch in {what}: expected {expected}, found {found}")]
    DimensionMismatch {
        /// What was being checked.
        what: String,
        /// The size that was required.
        expected: String,
        /// The size that was given.
        found: String,
    },

    /// One record of a multi-record data set is shorter than the linear block's order, so its
    /// own start cannot be told apart from its dynamics.
    #[error(
        "record {record} (numbered from 1) has {len} sample(s), fewer than the {order} state(s) of the \
         linear block; every record needs more samples than the model order (drop or merge that record)"
    )]
    RecordTooShort {
        /// One-based record number, as a user counts the `--data` files.
        record: usize,
        /// Its number of samples.
        len: usize,
        /// The number of states n of the linear block.
        order: usize,
    },

    /// An error in one record of several.
    #[error("record {record}: {source}")]
    InRecord {
        /// One-based record number, as a user counts the `--data` files.
        record: usize,
        /// What went wrong in it.
        source: Box<Error>,
    },

    /// A data sample is NaN or infinite.
    #[error("non-finite value {value} in {signal} at sample {sample}, channel {channel}")]
    NonFiniteData {
        /// Which signal (u, y, z, …).
        signal: String,
        /// Zero-based sample index.
        sample: usize,
        /// Zero-based channel index.
        channel: usize,
        /// The offending value.
        value: f64,
    },

    /// A tuning parameter is out of its valid range (σ ≤ 0, β ≤ 0, …).
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: String,
        /// Value that was given.
        value: f64,
        /// What is required instead.
        reason: String,
    },

    /// The nonlinear blocks do not fit the LFT (indices out of range, a w channel without a block, …).
    #[error("invalid model structure: {0}")]
    InvalidStructure(String),

    /// A block reads a z channel that the LFT does not have.
    #[error(
        "invalid model structure: block `{block}` reads z[{index}] but the LFT has only {available} z signal(s)"
    )]
    MissingZ {
        /// Block name.
        block: String,
        /// The z index it reads.
        index: usize,
        /// How many z signals the LFT has.
        available: usize,
    },

    /// A block writes a w channel that the LFT does not have.
    #[error(
        "invalid model structure: block `{block}` writes w[{index}] but the LFT has only {available} w signal(s)"
    )]
    MissingW {
        /// Block name.
        block: String,
        /// The w index it writes.
        index: usize,
        /// How many w signals the LFT has.
        available: usize,
    },

    /// The numbers of a stored form (estimate file, stored features or maps) do not fit
    /// together.
    #[error("invalid model structure: stored {item}: {detail}")]
    InconsistentStored {
        /// What was stored, e.g. `polynomial features`, `matrix A`.
        item: String,
        /// Which numbers disagree.
        detail: String,
    },

    /// A stored estimate names a user-defined kernel or feature map that the reader was not
    /// given (only the name of user code is stored).
    #[error(
        "the estimate uses the user-defined kernel `{name}`, whose code is not stored with it; \
         it can be read only where that kernel is supplied under this name (the library's \
         `Estimate::from_data_with_kernels`, Python's `kernels=`)"
    )]
    UserKernelMissing {
        /// The kernel's name as stored.
        name: String,
    },

    /// A penalty's internal description (nodes, samples, edges) is inconsistent.
    #[error("invalid model structure: {penalty} penalty: {detail}")]
    InconsistentPenalty {
        /// The kind of penalty, e.g. `total-variation`.
        penalty: String,
        /// What is inconsistent.
        detail: String,
    },

    /// Blocks whose input identification by the dispersion criterion cannot compute from u
    /// and y even with the other maps known: latent blocks, and blocks in series behind
    /// another map's output. The joint fit by simulation error takes them.
    #[error("z is not measurable: {explanation}")]
    OutOfReach {
        /// The blocks out of reach, by name.
        blocks: Vec<String>,
        /// Each block and why, and what takes them.
        explanation: String,
    },

    /// z cannot be computed from u and y (paper, Definition 1).
    #[error("z is not measurable: {explanation}")]
    NotMeasurable {
        /// Why, and what to provide instead.
        explanation: String,
    },

    /// The model is unstable where the computation needs it stable: a simulation or a
    /// predictor diverged, or an identification residual would grow without bound.
    #[error("unstable model: {0}")]
    Unstable(String),

    /// The maps form a cycle through D_zw: z_k would depend on w_k = N(z_k) through the maps
    /// named in `cycle`. Maps in series (an acyclic D_zw) are evaluated in order and are not
    /// refused.
    #[error(
        "algebraic loop: D_zw has a non-zero entry ({value}) at row {row}, column {col}, and the maps form a cycle \
         {}: z_k would depend on w_k = N(z_k) through them; simulation needs the maps' dependencies through D_zw \
         to be acyclic (add a delay in the loop or move the direct term into the linear block)",
        cycle_text(cycle)
    )]
    AlgebraicLoop {
        /// Row of D_zw.
        row: usize,
        /// Column of D_zw.
        col: usize,
        /// The non-zero entry.
        value: f64,
        /// The blocks of the cycle in the order one reads the next's output backwards, the
        /// first repeated at the end (`a → b → a`: a reads b, b reads a).
        cycle: Vec<String>,
    },

    /// D_zw ≠ 0 where z must be computed from u and y alone (the paper's identification, the
    /// one-step predictor): a map reads another map's output of the same sample.
    #[error(
        "maps in series: D_zw has a non-zero entry ({value}) at row {row}, column {col}, so z_k depends on \
         another map's output w_k; z cannot be computed from u and y alone, which identification by the \
         dispersion criterion and one-step prediction need. Simulation evaluates maps in series in order, \
         and the joint fit by simulation error identifies them"
    )]
    SeriesMaps {
        /// Row of D_zw.
        row: usize,
        /// Column of D_zw.
        col: usize,
        /// The non-zero entry.
        value: f64,
    },

    /// The problem would not fit in the memory budget of the chosen solver.
    #[error(
        "problem too large for the {solver} solver: it needs about {needed_mib} MiB but the limit is {limit_mib} MiB \
         (L·n_y = {size}). {suggestion}"
    )]
    TooLarge {
        /// Solver that refused.
        solver: String,
        /// Estimated peak memory in MiB.
        needed_mib: u64,
        /// Budget in MiB.
        limit_mib: u64,
        /// Size of the system matrix.
        size: usize,
        /// What to do instead.
        suggestion: String,
    },

    /// No solver supports the combination of dispersions in the model.
    #[error("unsupported dispersion combination: {0}")]
    Unsupported(String),

    /// A numerical step failed in a way that cannot be repaired automatically.
    #[error("numerical failure: {0}")]
    Numerical(String),

    /// A validation selection of β ended on a bound of its search: the data support no map
    /// (upper bound: the flattest map validated best) or only one that follows the noise
    /// (lower bound). Not a numerical failure: the numbers are right, the map is not usable.
    #[error("β on its search bound: {0}")]
    BetaAtBound(String),

    /// The optimisation problem has no solution: the data cannot be explained by the model.
    #[error("the {solver} solver found the problem infeasible: {detail}")]
    Infeasible {
        /// Solver that reported it.
        solver: String,
        /// What it means and what to check.
        detail: String,
    },

    /// An iterative solver stopped before meeting its tolerances.
    #[error("the {solver} solver did not converge after {iterations} iterations: {detail}")]
    NotConverged {
        /// Solver that stopped.
        solver: String,
        /// Iterations run.
        iterations: usize,
        /// Status, residuals and what to try.
        detail: String,
    },

    /// An expression for a static map could not be parsed or uses unknown variables.
    #[error("invalid map expression `{expression}`: {reason}")]
    Expression {
        /// The expression text.
        expression: String,
        /// What is wrong with it.
        reason: String,
    },
}

/// Result alias used across `structid-core`.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Whether the error says that z cannot be computed from u and y (the paper's
    /// measurability): maps in series, a z that no filter of y recovers, or one beyond a
    /// filter's reach, in any record. Such a model is still simulated, and fitted by
    /// simulation error; it has no one-step predictor.
    ///
    /// ```
    /// use structid_core::Error;
    /// let e = Error::SeriesMaps { row: 0, col: 1, value: 1.0 };
    /// assert!(e.beyond_measurability());
    /// let in_record = Error::InRecord { record: 2, source: Box::new(e) };
    /// assert!(in_record.beyond_measurability());
    /// assert!(!Error::Numerical("diverged".into()).beyond_measurability());
    /// ```
    pub fn beyond_measurability(&self) -> bool {
        match self {
            Error::InRecord { source, .. } => source.beyond_measurability(),
            Error::NotMeasurable { .. } | Error::SeriesMaps { .. } | Error::OutOfReach { .. } => {
                true
            }
            _ => false,
        }
    }
}

fn cycle_text(cycle: &[String]) -> String {
    cycle
        .iter()
        .map(|c| format!("`{c}`"))
        .collect::<Vec<_>>()
        .join(" ← ")
}

pub(crate) fn positive_finite(name: &str, value: f64) -> Result<f64> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(Error::InvalidParameter {
            name: name.to_string(),
            value,
            reason: "must be a finite number greater than zero".into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::error::Error as _;

    #[test]
    fn a_linear_error_is_wrapped_with_its_source() {
        let inner = structid_linear::LinearError::LengthMismatch {
            input: 10,
            output: 9,
        };
        let e: Error = inner.into();
        assert!(
            matches!(
                &e,
                Error::Linear(structid_linear::LinearError::LengthMismatch {
                    input: 10,
                    output: 9
                })
            ),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "linear estimation: the input has 10 samples but the output has 9"
        );
        let source = e.source().expect("the linear error is the source");
        assert!(source.is::<structid_linear::LinearError>());
        assert_eq!(
            source.to_string(),
            "the input has 10 samples but the output has 9"
        );
    }

    #[test]
    fn structured_variants_keep_the_messages() {
        let e = Error::MissingZ {
            block: "f".into(),
            index: 3,
            available: 1,
        };
        assert_eq!(
            e.to_string(),
            "invalid model structure: block `f` reads z[3] but the LFT has only 1 z signal(s)"
        );
        let e = Error::InconsistentStored {
            item: "matrix a".into(),
            detail: "2 × 2 needs 4 entries, found 3".into(),
        };
        assert_eq!(
            e.to_string(),
            "invalid model structure: stored matrix a: 2 × 2 needs 4 entries, found 3"
        );
    }
}

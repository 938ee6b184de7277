//! Which solver ran, why, and how it stopped; and the automatic rule that picks the solver.
//!
//! The rule ([`choose_solver`]) is the one place that decides, for [`SolverChoice::Auto`],
//! between the four solvers; [`crate::identify_problem`] runs its choice and
//! [`crate::selection::select`] uses `feature_path` to decide whether β is selected in
//! feature space. In order:
//!
//! 1. quadratic and total-variation blocks together: some samples held out in part (some of
//!    their output channels only) → Clarabel; otherwise L·n_y ≤ [`MIXED_CONIC_AUTO_LIMIT`] →
//!    Clarabel, larger → ADMM (its w-step handles the quadratic blocks through their features
//!    or a factor of their Gram matrix);
//! 2. total variation only: some samples held out in part → Clarabel; otherwise
//!    L·n_y ≤ [`CONIC_AUTO_LIMIT`] → Clarabel, larger → ADMM (whole held-out samples, as in
//!    cross-validation, are missing outputs of its smoother);
//! 3. quadratic only: every block has finitely many features, m in all, and
//!    4·(m + n_x) ≤ L·n_y (n_x the estimated initial states) → the feature solver;
//!    else the exact solver's memory exceeds the budget and every block has features → the
//!    feature solver; else the exact solver.
//!
//! L counts the samples of every record together: several records follow the same rules as
//! one (every solver restarts the dynamics at each record).

use crate::dispersion::Penalty;
use crate::error::Result;
use crate::identify::problem::Problem;
use crate::identify::settings::{IdentifySettings, SolverChoice};

pub(crate) use crate::solver::status::unconverged_warning;
pub use crate::solver::status::{SolveStatus, SolverKind, SolverReason};

/// Largest L·n_y for which the automatic choice uses the conic solver for total variation.
/// Clarabel is exact and takes about 0.4 s at L = 1000 with a white-noise input, but grows like
/// L³ there (3.5 s at 2000, see `BENCHMARKS.md`), while ADMM takes milliseconds.
pub const CONIC_AUTO_LIMIT: usize = 1000;

/// Largest L·n_y for which the automatic choice uses the conic solver for a model that mixes
/// quadratic and total-variation blocks. Clarabel's program is dense in the quadratic blocks (L²
/// entries) and its interior-point iteration meets numerical trouble from about L = 800 with a
/// Gaussian block; ADMM factors the Gram matrix instead and is linear in L.
pub const MIXED_CONIC_AUTO_LIMIT: usize = 500;

/// Whether every block has finitely many features and the feature solver can stream the
/// problem's paths: the condition under which the feature solver minimises the same J as the
/// exact one.
pub(crate) fn all_featured(problem: &Problem, penalties: &[Penalty]) -> bool {
    super::features::unsupported_reason(problem).is_none()
        && penalties
            .iter()
            .all(|p| matches!(p, Penalty::Quadratic(q) if q.features().is_some()))
}

/// The automatic rule (see the [module documentation](self)) for a problem whose penalties
/// are already built. Reads the memory budget only when the rule needs it.
pub(crate) fn choose_with(
    problem: &Problem,
    penalties: &[Penalty],
    settings: &IdentifySettings,
) -> (SolverKind, SolverReason) {
    let tv_blocks = penalties
        .iter()
        .filter(|p| matches!(p, Penalty::TotalVariation(_)))
        .count();
    let size = problem.len() * problem.outputs();
    // ADMM leaves out whole samples only (its smoother's missing outputs).
    let partly_held_out = matches!(problem.held_out_samples(), Some(None));
    if tv_blocks > 0 && tv_blocks < penalties.len() {
        let limit = MIXED_CONIC_AUTO_LIMIT;
        return if partly_held_out {
            (SolverKind::Clarabel, SolverReason::MixedDispersions)
        } else if size <= limit {
            (
                SolverKind::Clarabel,
                SolverReason::MixedSmall { size, limit },
            )
        } else {
            (SolverKind::Admm, SolverReason::MixedLarge { size, limit })
        };
    }
    if tv_blocks > 0 {
        return if partly_held_out {
            (SolverKind::Clarabel, SolverReason::TotalVariationHeldOut)
        } else if size <= CONIC_AUTO_LIMIT {
            let limit = CONIC_AUTO_LIMIT;
            (
                SolverKind::Clarabel,
                SolverReason::TotalVariationSmall { size, limit },
            )
        } else {
            let limit = CONIC_AUTO_LIMIT;
            (
                SolverKind::Admm,
                SolverReason::TotalVariationLarge { size, limit },
            )
        };
    }
    // Quadratic: the exact solve unless the features are few or its M would not fit.
    let noise = problem.noise();
    let nx = problem.free_response().map_or(0, |o| o.ncols());
    let needed_bytes =
        super::exact::peak_memory_bytes(
            problem.len(),
            problem.outputs(),
            noise.inputs(),
            noise.order() > 0,
            nx,
        ) + super::exact::posterior_memory_bytes(settings, problem.len(), problem.outputs(), nx);
    let featured = all_featured(problem, penalties);
    // Both solvers minimise the same J when K = ΨΛΨᵀ; the feature solve costs O(L·m²) against
    // the exact O((L·n_y)³), so it wins whenever the features are few.
    let features: usize = penalties
        .iter()
        .filter_map(|p| match p {
            Penalty::Quadratic(q) => q.features().map(|(m, _)| m.dim()),
            _ => None,
        })
        .sum();
    let rows = size;
    if featured && 4 * (features + nx) <= rows {
        return (
            SolverKind::Features { features },
            SolverReason::FewFeatures { features, rows },
        );
    }
    let limit_bytes = settings.effective_memory_limit();
    if needed_bytes > limit_bytes && featured {
        (
            SolverKind::Features { features },
            SolverReason::ExactOverBudget {
                needed_bytes,
                limit_bytes,
            },
        )
    } else {
        (SolverKind::Exact, SolverReason::Quadratic { needed_bytes })
    }
}

/// The solver [`crate::identify_problem`] runs for `problem` under `settings`, and why: the
/// requested one, or for [`SolverChoice::Auto`] the automatic rule's choice (see the
/// [module documentation](self)).
///
/// # Errors
/// As building the blocks' penalties ([`crate::Dispersion::penalty`]).
///
/// ```
/// use std::sync::Arc;
/// use structid_core::{paper, solver::choose_solver, IdentifySettings, KernelDispersion};
/// use structid_core::{Problem, SolverKind, SolverReason};
/// let exp = paper::spray(300, 0.5, Arc::new(KernelDispersion::gaussian(0.1).unwrap()), 2).unwrap();
/// let problem = Problem::from_model(&exp.model, &exp.data).unwrap();
/// let (kind, reason) = choose_solver(&problem, &IdentifySettings::default()).unwrap();
/// assert_eq!(kind, SolverKind::Exact);
/// assert!(matches!(reason, SolverReason::Quadratic { .. }));
/// ```
pub fn choose_solver(
    problem: &Problem,
    settings: &IdentifySettings,
) -> Result<(SolverKind, SolverReason)> {
    let requested = |kind| Ok((kind, SolverReason::Requested));
    match settings.solver() {
        SolverChoice::Exact => requested(SolverKind::Exact),
        SolverChoice::Clarabel => requested(SolverKind::Clarabel),
        SolverChoice::Admm => requested(SolverKind::Admm),
        SolverChoice::Features => {
            let penalties = super::penalties(problem)?;
            let features = penalties
                .iter()
                .filter_map(|p| match p {
                    Penalty::Quadratic(q) => q.features().map(|(m, _)| m.dim()),
                    _ => None,
                })
                .sum();
            requested(SolverKind::Features { features })
        }
        SolverChoice::Auto => Ok(choose_with(problem, &super::penalties(problem)?, settings)),
    }
}

/// Whether marginal likelihood / GCV run in feature space: always when the feature solver is
/// requested, and for the automatic choice when every block has finitely many features (the
/// final fit then uses the feature solver, [`SolverReason::FeatureSpaceSelection`]).
pub(crate) fn feature_path(problem: &Problem, settings: &IdentifySettings) -> Result<bool> {
    Ok(match settings.solver() {
        SolverChoice::Features => true,
        SolverChoice::Auto => {
            super::features::unsupported_reason(problem).is_none()
                && all_featured(problem, &super::penalties(problem)?)
        }
        _ => false,
    })
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use nalgebra::dmatrix;

    use super::*;
    use crate::error::Error;
    use crate::solver::admm::AdmmSettings;
    use crate::{
        Data, Dispersion, KernelDispersion, Lft, LftMatrices, Model, NonlinearBlock,
        PolynomialDispersion, Signal, TotalVariation, identify,
    };

    /// y_k = f(u_k) + e_k (one block, white noise, no dynamics): r = y, and with w = 0 the
    /// noise is e = y, so J(0) = (1/L)·Σ y_k².
    fn static_model(dispersions: Vec<Arc<dyn Dispersion>>) -> Model {
        let n = dispersions.len();
        let lft = Lft::new(LftMatrices {
            a: dmatrix![0.0],
            bu: dmatrix![0.0],
            be: dmatrix![0.0],
            bw: nalgebra::DMatrix::zeros(1, n),
            cy: dmatrix![0.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: nalgebra::DMatrix::from_element(1, n, 1.0),
            cz: nalgebra::DMatrix::zeros(n, 1),
            dzu: nalgebra::DMatrix::from_element(n, 1, 1.0),
            dze: nalgebra::DMatrix::zeros(n, 1),
            dzw: nalgebra::DMatrix::zeros(n, n),
        })
        .unwrap();
        let blocks = dispersions
            .into_iter()
            .enumerate()
            .map(|(i, d)| NonlinearBlock::new(format!("f{i}"), vec![i], i, d))
            .collect();
        Model::new(lft, blocks).unwrap()
    }

    fn record(len: usize) -> Data {
        // A deterministic, irregular input in [−2, 2] and a saturating map with a ripple.
        let u = Signal::from_fn(len, 1, |k, _| {
            2.0 * ((k as f64 * 0.7548776662).fract() * 2.0 - 1.0)
        });
        let y = Signal::from_fn(len, 1, |k, _| {
            let x = u.get(k, 0);
            x.tanh() + 0.1 * (7.0 * x).sin() + 0.05 * ((k as f64 * 0.5698402910).fract() - 0.5)
        });
        Data::new(u, y).unwrap()
    }

    #[test]
    fn admm_at_its_iteration_limit_returns_a_feasible_iterate_below_the_starting_cost() {
        let len = 400;
        let model = static_model(vec![Arc::new(TotalVariation::new())]);
        let data = record(len);
        let settings = IdentifySettings::builder()
            .beta(0.01)
            .solver(SolverChoice::Admm)
            .admm(
                AdmmSettings::builder()
                    .max_iterations(4)
                    .tolerance(1e-12)
                    .build()
                    .unwrap(),
            )
            .build()
            .unwrap();
        let id = identify(&model, &data, &settings).unwrap();
        let d = &id.diagnostics;
        assert_eq!(d.status, SolveStatus::MaxIterations);
        assert_eq!(d.solver, SolverKind::Admm);
        assert_eq!(d.iterations, 4);
        assert!(d.status_detail.is_some());
        assert!(
            d.warnings
                .iter()
                .any(|w| w.contains("did not converge after 4 iterations")),
            "{:?}",
            d.warnings
        );
        // The iterate is finite and feasible (ê is recomputed for it) ...
        assert!(id.w_hat.as_slice().iter().all(|v| v.is_finite()));
        assert!(id.e_hat.as_slice().iter().all(|v| v.is_finite()));
        assert!(d.feasibility_residual < 1e-9, "{}", d.feasibility_residual);
        // ... and its cost, recomputed here, is no higher than at the start w = 0.
        let y = data.y().as_slice();
        let start = y.iter().map(|v| v * v).sum::<f64>() / len as f64;
        let mu = id.e_hat.as_slice().iter().map(|e| e * e).sum::<f64>() / len as f64;
        assert!(
            (mu - id.cost.noise).abs() <= 1e-9 * start,
            "{mu} vs {}",
            id.cost.noise
        );
        assert!(id.cost.total.is_finite());
        assert!(
            id.cost.total <= start,
            "J = {} > J(0) = {start}",
            id.cost.total
        );
        // A caller that needs convergence gets the error the solver used to return.
        let err = id.converged().unwrap_err();
        assert!(
            matches!(&err, Error::NotConverged { solver, iterations: 4, .. } if solver == "admm"),
            "{err}"
        );
    }

    #[derive(Clone, Copy, Debug)]
    enum Kind {
        Tv,
        /// A polynomial of this degree: finitely many features.
        Poly(usize),
        Gaussian,
    }

    fn dispersion(k: Kind) -> Arc<dyn Dispersion> {
        match k {
            Kind::Tv => Arc::new(TotalVariation::new()),
            Kind::Poly(d) => Arc::new(PolynomialDispersion::new(d).unwrap()),
            Kind::Gaussian => Arc::new(KernelDispersion::gaussian(0.5).unwrap()),
        }
    }

    /// The rule as the documentation states it, from the sizes alone: the solver's name and
    /// the printed reason.
    fn documented(kinds: &[Kind], len: usize, m: usize, over_budget: bool) -> (String, String) {
        let tv = kinds.iter().filter(|k| matches!(k, Kind::Tv)).count();
        let featured = kinds.iter().all(|k| matches!(k, Kind::Poly(_)));
        if tv > 0 && tv < kinds.len() {
            return if len <= 500 {
                (
                    "clarabel".into(),
                    format!(
                        "automatic: quadratic and total-variation dispersions together with L·n_y = {len} ≤ \
                         500, the exact conic solver"
                    ),
                )
            } else {
                (
                    "admm".into(),
                    format!(
                        "automatic: quadratic and total-variation dispersions together with L·n_y = {len} > \
                         500, ADMM (linear in L)"
                    ),
                )
            };
        }
        if tv > 0 {
            return if len <= 1000 {
                (
                    "clarabel".into(),
                    format!(
                        "automatic: total variation with L·n_y = {len} ≤ 1000, the exact conic solver"
                    ),
                )
            } else {
                (
                    "admm".into(),
                    format!(
                        "automatic: total variation with L·n_y = {len} > 1000, ADMM (linear in L)"
                    ),
                )
            };
        }
        if featured && 4 * m <= len {
            return (
                format!("features (m = {m})"),
                format!(
                    "automatic: every block has finite features ({m} in all, at most a quarter of the \
                     {len} output samples), the feature solver"
                ),
            );
        }
        if featured && over_budget {
            return (
                format!("features (m = {m})"),
                "automatic: the exact solver's memory exceeds the budget and every block has finite \
                 features"
                    .into(),
            );
        }
        (
            "exact".into(),
            "automatic: quadratic dispersions within the memory budget, the exact solver".into(),
        )
    }

    #[test]
    fn the_automatic_rule_matches_its_documentation_on_a_grid() {
        let shapes: Vec<Vec<Kind>> = vec![
            vec![Kind::Tv],
            vec![Kind::Tv, Kind::Tv],
            vec![Kind::Tv, Kind::Gaussian],
            vec![Kind::Poly(2), Kind::Tv],
            vec![Kind::Gaussian],
            vec![Kind::Poly(3)],
            vec![Kind::Poly(9)],
            vec![Kind::Poly(4), Kind::Poly(6)],
            vec![Kind::Poly(3), Kind::Gaussian],
        ];
        let mut seen = std::collections::BTreeSet::new();
        for len in [12, 30, 40, 1000, 1001] {
            let data = record(len);
            for kinds in &shapes {
                let model = static_model(kinds.iter().map(|&k| dispersion(k)).collect());
                let problem = Problem::from_model(&model, &data).unwrap();
                // m: the features of all blocks (each polynomial in one input has degree + 1).
                let m: usize = kinds
                    .iter()
                    .map(|k| match k {
                        Kind::Poly(d) => d + 1,
                        _ => 0,
                    })
                    .sum();
                for over_budget in [false, true] {
                    let settings = if over_budget {
                        IdentifySettings::builder()
                            .memory_limit_bytes(1)
                            .build()
                            .unwrap()
                    } else {
                        IdentifySettings::builder()
                            .memory_limit_bytes(1 << 40)
                            .build()
                            .unwrap()
                    };
                    let (kind, reason) = choose_solver(&problem, &settings).unwrap();
                    let want = documented(kinds, len, m, over_budget);
                    let case = format!("{kinds:?}, L = {len}, over budget {over_budget}");
                    assert_eq!((kind.to_string(), reason.to_string()), want, "{case}");
                    assert_eq!(kind.choice().name(), kind.name(), "{case}");
                    seen.insert(kind.name());
                }
            }
        }
        // Every solver is reached by some case.
        assert_eq!(seen.len(), 4, "{seen:?}");
    }

    #[test]
    fn identify_runs_the_chosen_solver_and_records_why() {
        for (kinds, len) in [
            (vec![Kind::Tv], 60),
            (vec![Kind::Poly(3)], 60),
            (vec![Kind::Gaussian], 60),
            (vec![Kind::Tv, Kind::Gaussian], 40),
        ] {
            let model = static_model(kinds.iter().map(|&k| dispersion(k)).collect());
            let data = record(len);
            let settings = IdentifySettings::default();
            let problem = Problem::from_model(&model, &data).unwrap();
            let (kind, reason) = choose_solver(&problem, &settings).unwrap();
            let id = identify(&model, &data, &settings).unwrap();
            assert_eq!(id.diagnostics.solver, kind, "{kinds:?}");
            assert_eq!(id.diagnostics.solver_reason, reason, "{kinds:?}");
            assert_eq!(id.diagnostics.status, SolveStatus::Solved, "{kinds:?}");
            // Requested solvers say so.
            let requested = settings.with_solver(kind.choice());
            let id = identify(&model, &data, &requested).unwrap();
            assert_eq!(id.diagnostics.solver, kind, "{kinds:?}");
            assert_eq!(id.diagnostics.solver_reason, SolverReason::Requested);
        }
    }

    #[test]
    fn names_serialise_as_printed() {
        let d = crate::Diagnostics {
            solver: SolverKind::Features { features: 7 },
            solver_reason: SolverReason::TotalVariationLarge {
                size: 2000,
                limit: CONIC_AUTO_LIMIT,
            },
            status: SolveStatus::MaxIterations,
            ..crate::Diagnostics::default()
        };
        let v = serde_json::to_value(&d).unwrap();
        assert_eq!(v["solver"], "features (m = 7)");
        assert_eq!(
            v["solver_reason"],
            "automatic: total variation with L·n_y = 2000 > 1000, ADMM (linear in L)"
        );
        assert_eq!(v["status"], "max_iterations");
        assert!(SolveStatus::AlmostSolved.is_converged());
        assert!(!SolveStatus::TimeLimit.is_converged());
        assert!(!SolveStatus::NumericalFailure.is_converged());
        assert_eq!(
            serde_json::to_value(SolveStatus::NumericalFailure).unwrap(),
            "numerical_failure"
        );
        assert_eq!(
            SolveStatus::NumericalFailure.to_string(),
            "numerical failure"
        );
    }
}

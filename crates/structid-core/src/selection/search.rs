//! The search over β (and the common width factor of σ): bracketing golden sections on log₁₀.

use std::sync::Arc;
use std::time::Instant;

use crate::dispersion::{Dispersion, Penalty};
use crate::error::{Error, Result, positive_finite};
use crate::identify::problem::Problem;
use crate::identify::{IdentifySettings, InitialState, SolverChoice, identify_problem};
use crate::model::{Data, Model};
use crate::solver::choice::{SolverReason, feature_path};

use super::cross_validation::FoldScore;
use super::dense::DenseScore;
use super::features::{FeatureRef, FeatureScore};
use super::report::{BetaSelection, Bound, Selection, Trial};
use super::score::BetaScore;
use super::settings::{Criterion, SelectionSettings};
use super::validation::ValidationScore;

/// The best β for given widths: β, the criterion there, s², how it was evaluated, and the bound
/// it lies on.
type BetaChoice = (f64, f64, Option<f64>, String, Option<Bound>);

/// Chooses β (and, if asked, σ) for `model` on `data` by `selection`'s criterion, then
/// identifies with the chosen values; see the [module documentation](super). `settings` gives
/// the solver, the initial-state treatment and, when β is not tuned, β. `validation` is
/// required by [`Criterion::Validation`] and ignored otherwise.
pub fn select(
    model: &Model,
    data: &Data,
    validation: Option<&Data>,
    settings: &IdentifySettings,
    selection: &SelectionSettings,
) -> Result<Selection> {
    let t0 = Instant::now();
    let criterion = selection.criterion;
    let validation = match (criterion, validation) {
        (Criterion::Validation, None) => {
            return Err(Error::InvalidStructure(
                "validation selection needs a validation record".into(),
            ));
        }
        (Criterion::Validation, Some(v)) => {
            v.check_against(model.lft())?;
            Some(v)
        }
        _ => None,
    };
    if model.blocks().is_empty() {
        return Err(Error::InvalidStructure(
            "the model has no nonlinear block: there is nothing to select β for".into(),
        ));
    }
    let widths0: Vec<Option<f64>> = model
        .blocks()
        .iter()
        .map(|b| b.dispersion.width())
        .collect();
    if selection.tune_sigma && widths0.iter().all(Option::is_none) {
        return Err(Error::Unsupported(
            "σ cannot be selected: no block's dispersion has a width (σ)".into(),
        ));
    }
    let widths_at = |log_factor: f64| -> Vec<Option<f64>> {
        widths0
            .iter()
            .map(|w| w.map(|w| w * 10f64.powf(log_factor)))
            .collect()
    };
    let model_at = |widths: &[Option<f64>]| -> Result<Model> {
        let mut disp: Vec<Arc<dyn Dispersion>> = Vec::with_capacity(widths.len());
        for (b, w) in model.blocks().iter().zip(widths) {
            disp.push(match w.and_then(|w| b.dispersion.with_width(w)) {
                Some(d) => d?,
                None => Arc::clone(&b.dispersion),
            });
        }
        let mut i = 0;
        Ok(model.with_dispersions(|_| {
            i += 1;
            Arc::clone(&disp[i - 1])
        }))
    };
    let problem_of = |m: &Model| -> Result<Problem> {
        match settings.initial_state() {
            InitialState::Zero => Problem::from_model(m, data),
            InitialState::Estimate => Problem::from_model_with_initial_state(m, data),
        }
    };
    let first_width = |w: &[Option<f64>]| w.iter().flatten().next().copied();

    let mut curve = Vec::new();
    // Trials fitted so far, for the progress observer.
    let mut trials = 0u64;
    // Trials whose criterion could not be evaluated (β, why): skipped, and reported.
    let mut skipped: Vec<(f64, String)> = Vec::new();
    let method: String;
    let mut features: Option<FeatureScore> = None;
    // The best β (and its value and s²) for the given widths.
    let mut best_beta = |widths: &[Option<f64>], curve: &mut Vec<Trial>| -> Result<BetaChoice> {
        let m = model_at(widths)?;
        let problem = problem_of(&m)?;
        let sigma = if selection.tune_sigma {
            first_width(widths)
        } else {
            None
        };
        let mut score: Box<dyn BetaScore + '_> = match criterion {
            Criterion::MarginalLikelihood | Criterion::Gcv => {
                let penalties = crate::solver::penalties(&problem)?;
                if let Some(b) = problem
                    .blocks()
                    .iter()
                    .zip(&penalties)
                    .find_map(|(b, p)| (!matches!(p, Penalty::Quadratic(_))).then_some(b))
                {
                    return Err(Error::Unsupported(format!(
                        "{} needs quadratic dispersions (a Gaussian-process model), but block `{}` has {}; \
                             choose β by cross-validation or validation error instead",
                        criterion.describe(),
                        b.name,
                        b.dispersion.describe()
                    )));
                }
                if feature_path(&problem, settings)? {
                    let f = match features.take().and_then(|f| f.reweighted(&problem)) {
                        Some(f) => f,
                        None => FeatureScore::new(&problem)?,
                    };
                    features = Some(f);
                    Box::new(FeatureRef {
                        score: features.as_mut().expect("just set"),
                        criterion,
                    })
                } else {
                    super::dense::check_memory(&problem, settings.effective_memory_limit())?;
                    Box::new(DenseScore::new(&problem, criterion)?)
                }
            }
            // the trial fits need no posterior: keeping one would cost memory (and sway the
            // automatic solver choice) for nothing
            Criterion::CrossValidation { folds } => Box::new(FoldScore::new(
                problem,
                settings.with_posterior(false),
                folds,
            )?),
            Criterion::Validation => Box::new(ValidationScore {
                problem,
                model: m,
                validation: validation.expect("checked above"),
                settings: settings.with_posterior(false),
            }),
        };
        // s² of every trial, so the choice needs no further evaluation (a CV trial is K fits)
        let mut noise = Vec::new();
        let first_trial = curve.len();
        // A trial whose criterion is not finite (a cross-validation fold that diverges at one
        // β) scores +∞ and the search goes on around it; only when no trial is finite does
        // the search fail.
        let mut first_failure: Option<Error> = None;
        let mut eval = |lg: f64| -> Result<f64> {
            let beta = 10f64.powf(lg);
            let scored = trial(score.score(beta))?;
            trials += 1;
            selection.progress.report(trials, None);
            match scored {
                Ok((value, s2)) => {
                    curve.push(Trial { beta, sigma, value });
                    noise.push((lg, s2));
                    Ok(value)
                }
                Err(why) => {
                    first_failure.get_or_insert_with(|| Error::Numerical(why.clone()));
                    skipped.push((beta, why));
                    Ok(f64::INFINITY)
                }
            }
        };
        let (lg, value, at_bound) = if selection.tune_beta {
            let (lo, hi) = selection.beta_bounds;
            let bounds = (lo.log10(), hi.log10());
            let (mut lg, mut value) = minimise_log10(
                &mut eval,
                selection.beta_start.log10(),
                bounds,
                selection.tolerance,
            )?;
            // A bound is a finding only once the search has looked past it: widened once,
            // from the bound it ended on (β in the units of z^p makes the default range
            // depend on the data's units; see `SelectionSettings::widen_decades`).
            let mut searched = bounds;
            let w = selection.widen_decades;
            if w > 0.0
                && let Some(side) = Bound::of(lg, bounds)
            {
                searched = match side {
                    Bound::Lower => (bounds.0 - w, bounds.1),
                    Bound::Upper => (bounds.0, bounds.1 + w),
                };
                let (lg2, value2) = minimise_log10(&mut eval, lg, searched, selection.tolerance)?;
                if value2 < value {
                    (lg, value) = (lg2, value2);
                }
            }
            let at = Bound::of(lg, searched).or_else(|| plateau(&curve[first_trial..], lg, value));
            (lg, value, at)
        } else {
            let lg = settings.beta().log10();
            (lg, eval(lg)?, None)
        };
        if !value.is_finite() {
            return Err(first_failure.unwrap_or_else(|| {
                Error::Numerical(format!(
                    "the {} criterion is not finite at any β tried",
                    criterion.describe()
                ))
            }));
        }
        let beta = 10f64.powf(lg);
        let s2 = noise.iter().find(|t| t.0 == lg).and_then(|t| t.1);
        Ok((beta, value, s2, score.method(), at_bound))
    };

    type Best = (f64, f64, Option<f64>, f64, String, Option<Bound>);
    let (widths, beta, noise_variance, beta_at_bound, sigma_at_bound) = if selection.tune_sigma {
        let d = selection.sigma_decades;
        let mut best: Option<Best> = None;
        let mut outer = |lf: f64| -> Result<f64> {
            let (beta, value, s2, how, at) = best_beta(&widths_at(lf), &mut curve)?;
            if best.as_ref().is_none_or(|b| value < b.1) {
                best = Some((beta, value, s2, lf, how, at));
            }
            Ok(value)
        };
        minimise_log10(&mut outer, 0.0, (-d, d), selection.tolerance.max(0.01))?;
        let (beta, _, s2, lf, how, at) = best.expect("at least one trial");
        method = how;
        (widths_at(lf), beta, s2, at, Bound::of(lf, (-d, d)))
    } else {
        let (beta, _, s2, how, at) = best_beta(&widths0, &mut curve)?;
        method = how;
        (widths0.clone(), beta, s2, at, None)
    };
    let chosen = model_at(&widths)?;
    let problem = problem_of(&chosen)?;
    // After a feature-space selection the automatic solver choice follows it: the feature
    // solver costs O(L·m²) where the exact one would cost O(L³) for the same kernel.
    let mut final_settings = settings.with_beta(beta)?;
    if features.is_some() && settings.solver() == SolverChoice::Auto {
        final_settings = final_settings.with_solver(SolverChoice::Features);
    }
    let mut identification = identify_problem(&problem, &final_settings)?;
    if features.is_some() && settings.solver() == SolverChoice::Auto {
        identification.diagnostics.solver_reason = SolverReason::FeatureSpaceSelection;
    }
    if !skipped.is_empty() {
        let list = skipped
            .iter()
            .take(5)
            .map(|(b, why)| format!("β = {b:.3e} ({why})"))
            .collect::<Vec<_>>()
            .join("; ");
        identification.diagnostics.warnings.push(format!(
            "the {} criterion could not be evaluated at {} of the β tried, which the search \
             skipped: {list}{}",
            criterion.describe(),
            skipped.len(),
            if skipped.len() > 5 { "; …" } else { "" }
        ));
    }
    if let Some(side) = beta_at_bound {
        identification
            .diagnostics
            .warnings
            .push(bound_warning(side, beta, criterion));
    }
    Ok(Selection {
        beta,
        beta_at_bound,
        sigma_at_bound,
        sigma: if selection.tune_sigma {
            first_width(&widths)
        } else {
            None
        },
        widths,
        criterion,
        method,
        curve,
        noise_variance,
        seconds: t0.elapsed().as_secs_f64(),
        identification,
        model: chosen,
    })
}

/// What one trial of the β search gives: its value and s², or why it is skipped (a criterion
/// that is not finite, a numerical failure of the fit at that β, or a simulation that diverges
/// with that β's map in the loop); any other error ends the search.
type Scored = std::result::Result<(f64, Option<f64>), String>;
fn trial(outcome: Result<(f64, Option<f64>)>) -> Result<Scored> {
    match outcome {
        Ok((value, s2)) if value.is_finite() => Ok(Ok((value, s2))),
        Ok((value, _)) => Ok(Err(format!("the criterion is {value}"))),
        Err(Error::Numerical(why) | Error::Unstable(why)) => Ok(Err(why)),
        Err(e) => Err(e),
    }
}

/// What a β search that ended on a bound (after widening once) means, in words.
fn bound_warning(side: Bound, beta: f64, criterion: Criterion) -> String {
    let criterion = criterion.describe();
    match side {
        Bound::Lower => format!(
            "the {criterion} search put β on its lower bound ({beta:.3e}, after widening once): \
             the data want less regularisation than that, and the map may interpolate the \
             noise; try cross-validation (`Criterion::CrossValidation`), or a smaller σ"
        ),
        Bound::Upper => format!(
            "the {criterion} search put β on its upper bound ({beta:.3e}, after widening once): \
             the flattest map fits best, so the data support no map at this width; check the \
             structure, or try a larger σ"
        ),
    }
}

/// The end of the search that a flat criterion runs to: when the largest (smallest) β tried
/// scores the same as the best (relative 10⁻⁶) and is not the best itself, the criterion is
/// flat from the choice to that end (e.g. the map is already constant there), the search
/// stopped on the plateau, and the choice does not determine β any more than the bound would.
fn plateau(trials: &[Trial], best_lg: f64, best: f64) -> Option<Bound> {
    let same = |v: f64| (v - best).abs() <= 1e-6 * best.abs().max(f64::MIN_POSITIVE);
    let by_beta = |a: &&Trial, b: &&Trial| a.beta.total_cmp(&b.beta);
    let top = trials.iter().max_by(by_beta)?;
    let bottom = trials.iter().min_by(by_beta)?;
    let best_beta = 10f64.powf(best_lg);
    let is_best = |t: &Trial| (t.beta / best_beta - 1.0).abs() < 1e-12;
    if !is_best(top) && same(top.value) {
        Some(Bound::Upper)
    } else if !is_best(bottom) && same(bottom.value) {
        Some(Bound::Lower)
    } else {
        None
    }
}

/// Minimises `f` over x = log₁₀(·) in `bounds`: walks downhill by decades from `start` until
/// the value rises (or a bound is reached), then narrows the bracket by golden sections to
/// `tol`. Returns the best point evaluated and its value.
fn minimise_log10(
    f: &mut dyn FnMut(f64) -> Result<f64>,
    start: f64,
    bounds: (f64, f64),
    tol: f64,
) -> Result<(f64, f64)> {
    let (lo_lim, hi_lim) = bounds;
    let mut best = (f64::NAN, f64::INFINITY);
    let mut eval = |x: f64| -> Result<f64> {
        let v = f(x)?;
        if v < best.1 {
            best = (x, v);
        }
        Ok(v)
    };
    let step = 1.0f64.min(hi_lim - lo_lim);
    let mut x1 = start.clamp(lo_lim, hi_lim);
    let mut f1 = eval(x1)?;
    let (mut x0, mut x2);
    let right = (x1 + step).min(hi_lim);
    let fr = if right > x1 {
        eval(right)?
    } else {
        f64::INFINITY
    };
    if fr < f1 {
        x0 = x1;
        x1 = right;
        f1 = fr;
        loop {
            x2 = (x1 + step).min(hi_lim);
            if x2 <= x1 {
                break;
            }
            let f2 = eval(x2)?;
            if f2 >= f1 {
                break;
            }
            x0 = x1;
            x1 = x2;
            f1 = f2;
        }
    } else {
        x2 = right.max(x1);
        loop {
            x0 = (x1 - step).max(lo_lim);
            if x0 >= x1 {
                break;
            }
            let f0 = eval(x0)?;
            if f0 >= f1 {
                break;
            }
            x2 = x1;
            x1 = x0;
            f1 = f0;
        }
    }
    let _ = f1;
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (x0.min(x2), x0.max(x2));
    if b - a > tol {
        let mut c = b - g * (b - a);
        let mut d = a + g * (b - a);
        let (mut fc, mut fd) = (eval(c)?, eval(d)?);
        while b - a > tol {
            if fc < fd {
                b = d;
                d = c;
                fd = fc;
                c = b - g * (b - a);
                fc = eval(c)?;
            } else {
                a = c;
                c = d;
                fc = fd;
                d = a + g * (b - a);
                fd = eval(d)?;
            }
        }
    }
    Ok(best)
}

/// Chooses β for a problem in operator form whose blocks all have quadratic dispersions, by
/// marginal likelihood or GCV on the dense matrices (see the [module documentation](super)),
/// starting the search at `start` within [1e-10, 1e4].
///
/// ```
/// use std::sync::Arc;
/// use structid_core::selection::{select_beta, Criterion};
/// use structid_core::{paper, KernelDispersion, Problem};
/// let exp = paper::spray(300, 1.0, Arc::new(KernelDispersion::gaussian(0.1).unwrap()), 3).unwrap();
/// let problem = Problem::from_model(&exp.model, &exp.data).unwrap();
/// let sel = select_beta(&problem, Criterion::MarginalLikelihood, 0.01).unwrap();
/// assert!(sel.beta > 0.0 && sel.curve.len() >= 5);
/// ```
pub fn select_beta(problem: &Problem, criterion: Criterion, start: f64) -> Result<BetaSelection> {
    positive_finite("start of the β search", start)?;
    if !matches!(criterion, Criterion::MarginalLikelihood | Criterion::Gcv) {
        return Err(Error::Unsupported(
            "select_beta takes marginal likelihood or GCV; use `select` for the refitting criteria"
                .into(),
        ));
    }
    let mut score = DenseScore::new(problem, criterion)?;
    let mut curve = Vec::new();
    let mut eval = |lg: f64| -> Result<f64> {
        let beta = 10f64.powf(lg);
        let (v, _) = score.score(beta)?;
        curve.push((beta, v));
        Ok(v)
    };
    let (lg, _) = minimise_log10(&mut eval, start.log10(), (-10.0, 4.0), 0.02)?;
    let beta = 10f64.powf(lg);
    let (_, s2) = score.score(beta)?;
    Ok(BetaSelection {
        beta,
        criterion,
        curve,
        noise_variance: s2.unwrap_or(f64::NAN),
    })
}

#[cfg(test)]
mod trial_tests {
    use super::*;

    #[test]
    fn a_trial_that_is_not_finite_is_skipped_and_other_errors_end_the_search() {
        assert_eq!(trial(Ok((1.5, Some(0.1)))).unwrap(), Ok((1.5, Some(0.1))));
        assert!(
            trial(Ok((f64::NAN, None)))
                .unwrap()
                .unwrap_err()
                .contains("NaN")
        );
        assert!(trial(Ok((f64::INFINITY, None))).unwrap().is_err());
        let why = trial(Err(Error::Numerical(
            "cross-validation error not finite".into(),
        )))
        .unwrap()
        .unwrap_err();
        assert!(why.contains("not finite"));
        // A validation simulation that diverges with one β's map is that trial's failure.
        let why = trial(Err(Error::Unstable("the simulation diverged".into())))
            .unwrap()
            .unwrap_err();
        assert!(why.contains("diverged"));
        assert!(trial(Err(Error::Unsupported("total variation".into()))).is_err());
    }

    /// The search goes on around a β whose criterion fails: a convex criterion that cannot
    /// be evaluated on one decade still has its minimum found.
    #[test]
    fn the_search_steps_over_a_trial_that_cannot_be_scored() {
        let mut f = |x: f64| -> Result<f64> {
            let scored = if (x - (-1.0)).abs() < 0.5 {
                trial(Err(Error::Numerical("not finite".into())))?
            } else {
                trial(Ok(((x + 4.0).powi(2), None)))?
            };
            Ok(scored.map_or(f64::INFINITY, |(v, _)| v))
        };
        let (x, v) = minimise_log10(&mut f, -2.0, (-10.0, 4.0), 0.01).unwrap();
        assert!((x + 4.0).abs() < 0.02 && v < 1e-3, "x = {x}, v = {v}");
    }
}

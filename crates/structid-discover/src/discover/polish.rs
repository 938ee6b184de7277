//! The output-error polish of a named family's parameters.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector};

use structid_core::Data;
use structid_linear::levenberg_marquardt::{
    LeastSquaresProblem, LevenbergMarquardt, LmSettings, forward_jacobian,
};

use crate::effects::{Effect, EffectFit, Refit};
use crate::hypotheses::{Hypothesis, Site};
use structid_core::Interpolant;
use structid_linear::PolynomialModel;

use super::DiscoverSettings;
use super::direction::{simulation_residual, simulation_residual_of};

/// Refines a named family's parameters by output error: Levenberg–Marquardt on the
/// estimation record's simulation error with the parametric map in the loop, from the map
/// fit's values (the offset included when the fit carries one), with forward-difference
/// derivatives (a family has at most seven parameters). The map fit is to a smoothed
/// estimate; the simulation error weighs each part of the map by how much the data say about
/// it. The 95 % intervals come from s²·(JᵀJ)⁻¹ at the optimum.
///
/// The result records how the search ended ([`EffectFit::refit`]) and carries the flags of
/// [`crate::effects::identifiability`] at the refitted values; a refit that did not converge
/// is flagged, so the family is not named by it (its intervals are not trusted). A family
/// whose parameters move a quantiser's steps is left as fitted, without a refit record (its
/// simulation error is piecewise constant in the step).
pub(super) fn polish(
    fit: &EffectFit,
    h: &Hypothesis,
    est_h: &Data,
    settings: &DiscoverSettings,
) -> EffectFit {
    polish_with(fit, h, est_h, settings, POLISH_ITERATIONS)
}

/// The iteration limit of [`polish`].
const POLISH_ITERATIONS: usize = 100;

/// The Levenberg–Marquardt settings of every output-error polish.
fn lm_settings(max_iterations: usize) -> Result<LmSettings, structid_linear::LinearError> {
    LmSettings::builder()
        .max_iterations(max_iterations)
        .tolerance(1e-10)
        .initial_damping(1e-3)
        .damping_increase(4.0)
        .damping_decrease(3.0)
        .min_damping(1e-12)
        .max_damping(f64::INFINITY)
        .max_step_attempts(10)
        .build()
}

/// The standard errors √diag(cov) of `n` parameters, infinite where the covariance is
/// missing or not finite.
fn standard_errors(cov: Option<&DMatrix<f64>>, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| {
            cov.map(|cv| cv[(i, i)].max(0.0).sqrt())
                .filter(|s| s.is_finite())
                .unwrap_or(f64::INFINITY)
        })
        .collect()
}

/// [`polish`] with an iteration limit.
pub(super) fn polish_with(
    fit: &EffectFit,
    h: &Hypothesis,
    est_h: &Data,
    discover: &DiscoverSettings,
    max_iterations: usize,
) -> EffectFit {
    if fit.effect == Effect::Quantisation {
        return fit.clone();
    }
    let settings = lm_settings(max_iterations);
    let mut problem = PolishProblem {
        fit,
        h,
        est_h,
        settings: discover,
    };
    // A start whose simulation fails leaves the map fit as it is, flagged.
    let lm = match settings
        .and_then(|s| LevenbergMarquardt::new(s).minimize(&mut problem, &fit.all_values()))
    {
        Ok(lm) => lm,
        Err(e) => {
            let mut out = fit.clone();
            out.refit = Some(Box::new(Refit::failed(&format!(
                "the refit could not start: {e}"
            ))));
            out.flags = crate::effects::identifiability::flags(&out, None);
            return out;
        }
    };
    let cov = lm.covariance(&mut problem);
    let se = standard_errors(cov.as_ref(), lm.theta.len());
    let pf = fit.parameters.len();
    let family_cov = cov.as_ref().map(|c| c.view((0, 0), (pf, pf)).into_owned());
    let mut with_refit = fit.clone();
    with_refit.refit = Some(Box::new(Refit::from_status(
        lm.status,
        lm.iterations,
        lm.initial_cost,
        lm.cost,
    )));
    with_refit.at(&lm.theta, &se, family_cov.as_ref())
}

/// The output-error problem of [`polish`]: the simulation residual of the estimation record
/// with the family's map in the loop; a θ whose simulation fails is rejected.
pub(super) struct PolishProblem<'a> {
    fit: &'a EffectFit,
    h: &'a Hypothesis,
    est_h: &'a Data,
    settings: &'a DiscoverSettings,
}

impl LeastSquaresProblem for PolishProblem<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        let fit = self.fit;
        let map = |z: &[f64]| fit.eval_with(theta, z[0]);
        simulation_residual(self.h, &map, self.est_h, self.settings).map(DVector::from_vec)
    }

    /// Forward differences (each parameter costs a simulation).
    fn jacobian(&mut self, theta: &[f64], r: &DVector<f64>) -> Option<DMatrix<f64>> {
        forward_jacobian(&mut |t| self.residuals(t), theta, r, JACOBIAN_STEP)
    }
}

/// A joint output-error refit of the new block's named family `new` and the known maps'
/// families (`known[i]`, `None` for a known map without one, which stays fixed): one
/// Levenberg–Marquardt search over all their parameters on the estimation record's simulation
/// error, every map in the loop. A map found first was fitted while the later effects were
/// unmodelled, so its parameters carry their bias; refitting them with every effect in the
/// model removes it. Returns the refitted families (with intervals from the joint fit), or
/// `None` when the search did not converge or did not lower the cost.
pub(super) fn polish_jointly(
    new: &EffectFit,
    known: &[Option<EffectFit>],
    h: &Hypothesis,
    est_h: &Data,
    settings: &DiscoverSettings,
) -> Option<(EffectFit, Vec<Option<EffectFit>>)> {
    let fits: Vec<&EffectFit> = std::iter::once(new).chain(known.iter().flatten()).collect();
    let start: Vec<f64> = fits.iter().flat_map(|f| f.all_values()).collect();
    let lm = lm_settings(POLISH_ITERATIONS).ok()?;
    let mut problem = JointProblem {
        new,
        known,
        h,
        est_h,
        settings,
    };
    let lm = LevenbergMarquardt::new(lm)
        .minimize(&mut problem, &start)
        .ok()?;
    let refit = Refit::from_status(lm.status, lm.iterations, lm.initial_cost, lm.cost);
    if !(refit.converged && lm.cost < lm.initial_cost) {
        return None;
    }
    let cov = lm.covariance(&mut problem);
    let se = standard_errors(cov.as_ref(), lm.theta.len());
    let mut at = 0;
    let mut next = |fit: &EffectFit| {
        let n = fit.all_values().len();
        let p = fit.parameters.len();
        let block = cov.as_ref().map(|c| c.view((at, at), (p, p)).into_owned());
        let mut out = fit.clone();
        out.refit = Some(Box::new(refit.clone()));
        let out = out.at(&lm.theta[at..at + n], &se[at..at + n], block.as_ref());
        at += n;
        out
    };
    let new_fit = next(new);
    let known_fits = known.iter().map(|k| k.as_ref().map(&mut next)).collect();
    Some((new_fit, known_fits))
}

/// The problem of [`polish_jointly`]: θ is the new fit's values, then each known fit's.
struct JointProblem<'a> {
    new: &'a EffectFit,
    known: &'a [Option<EffectFit>],
    h: &'a Hypothesis,
    est_h: &'a Data,
    settings: &'a DiscoverSettings,
}

impl LeastSquaresProblem for JointProblem<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        let n0 = self.new.all_values().len();
        let new = self.new;
        let first = |z: &[f64]| new.eval_with(&theta[..n0], z[0]);
        let mut at = n0;
        let mut owned: Vec<Box<dyn structid_core::Interpolant + '_>> = Vec::new();
        for (k, fit) in self.h.known.iter().zip(self.known) {
            match fit {
                Some(f) => {
                    let n = f.all_values().len();
                    let seg = &theta[at..at + n];
                    at += n;
                    owned.push(Box::new(move |z: &[f64]| f.eval_with(seg, z[0])));
                }
                None => owned.push(Box::new(|z: &[f64]| k.map.eval(z))),
            }
        }
        let maps: Vec<&dyn structid_core::Interpolant> =
            std::iter::once(&first as &dyn structid_core::Interpolant)
                .chain(owned.iter().map(|m| m.as_ref()))
                .collect();
        simulation_residual_of(self.h, &maps, self.est_h, self.settings).map(DVector::from_vec)
    }

    /// Forward differences (each parameter costs a simulation).
    fn jacobian(&mut self, theta: &[f64], r: &DVector<f64>) -> Option<DMatrix<f64>> {
        forward_jacobian(&mut |t| self.residuals(t), theta, r, JACOBIAN_STEP)
    }
}

/// Re-estimates the linear part G (u → y, the nominal model's form) of a hypothesis at
/// `location` with its map `map` held fixed **in the loop**: Levenberg–Marquardt on the
/// estimation record's scored simulation error (windows for an integrating plant) over G's
/// free coefficients, the numerator after its leading zeros and the denominator with its
/// integrators held at 1.
///
/// Why not the output-error step of [`structid_core::refine`]: at a feedback location that
/// step reads the map's input from the measured output (y, or its backward difference for a
/// rate), and at a fast sample rate the differenced noise dwarfs the velocity, so that the
/// map's output carries the noise into the regressor and biases G (an errors-in-variables
/// fit). In the loop, z comes from the simulated output, which carries no noise. Returns the
/// refitted G, or `None` when the search could not start or did not lower the cost.
pub(super) fn polish_linear(
    g: &PolynomialModel,
    map: &dyn Interpolant,
    location: Site,
    est: &Data,
    settings: &DiscoverSettings,
) -> Option<PolynomialModel> {
    let parts = LinearParts::of(g)?;
    // The dispersion only shapes the block (nothing is identified), and the record with its
    // measured z depends on the location and the sample time, not on G: both are made once.
    let dispersion: Arc<dyn structid_core::Dispersion> =
        Arc::new(structid_core::PolynomialDispersion::new(1).ok()?);
    let data = crate::hypotheses::hypothesis(g, location, Arc::clone(&dispersion))
        .ok()?
        .data(est)
        .ok()?;
    let mut problem = LinearProblem {
        parts: &parts,
        dispersion,
        map,
        location,
        data: &data,
        settings,
    };
    let lm = LevenbergMarquardt::new(lm_settings(LINEAR_ITERATIONS).ok()?)
        .minimize(&mut problem, &parts.start)
        .ok()?;
    (lm.cost < lm.initial_cost && lm.cost.is_finite())
        .then(|| parts.model(&lm.theta))
        .flatten()
}

/// The iteration limit of [`polish_linear`].
const LINEAR_ITERATIONS: usize = 40;

/// G's free coefficients: those of G with its integrators divided out
/// ([`PolynomialModel::parameters`]), the numerator's in units of its largest coefficient so
/// that every θ is of order one.
struct LinearParts {
    orders: structid_linear::Orders,
    integrators: usize,
    scale: f64,
    sample_time: Option<f64>,
    start: Vec<f64>,
}

impl LinearParts {
    fn of(g: &PolynomialModel) -> Option<Self> {
        let integrators = structid_linear::integrators::count_integrators(&g.den);
        let rest = PolynomialModel {
            num: vec![g.num.first()?.clone()],
            den: structid_linear::integrators::deflate(&g.den, integrators)?,
            sample_time: g.sample_time,
        };
        let orders = rest.orders();
        let nb = orders.nb[0];
        let mut start = rest.parameters();
        let scale = start[..nb].iter().fold(0.0_f64, |m, b| m.max(b.abs()));
        if !(scale > 0.0 && scale.is_finite()) {
            return None;
        }
        start[..nb].iter_mut().for_each(|b| *b /= scale);
        Some(Self {
            orders,
            integrators,
            scale,
            sample_time: g.sample_time,
            start,
        })
    }

    /// G at θ, or `None` when θ gives no valid model.
    fn model(&self, theta: &[f64]) -> Option<PolynomialModel> {
        let nb = self.orders.nb[0];
        let unscaled: Vec<f64> = theta
            .iter()
            .enumerate()
            .map(|(i, t)| if i < nb { t * self.scale } else { *t })
            .collect();
        let mut g =
            PolynomialModel::from_parameters(&self.orders, &unscaled, self.sample_time).ok()?;
        g.den = structid_linear::integrators::convolve(
            &structid_linear::integrators::integrator_polynomial(self.integrators),
            &g.den,
        );
        Some(g)
    }
}

/// The problem of [`polish_linear`]; a θ whose denominator is unstable (beyond the held
/// integrators) or whose simulation fails is rejected.
struct LinearProblem<'a> {
    parts: &'a LinearParts,
    dispersion: Arc<dyn structid_core::Dispersion>,
    map: &'a dyn Interpolant,
    location: Site,
    data: &'a Data,
    settings: &'a DiscoverSettings,
}

impl LeastSquaresProblem for LinearProblem<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        let g = self.parts.model(theta)?;
        if !g.stability().is_acceptable() {
            return None;
        }
        let h =
            crate::hypotheses::hypothesis(&g, self.location, Arc::clone(&self.dispersion)).ok()?;
        simulation_residual(&h, self.map, self.data, self.settings).map(DVector::from_vec)
    }

    fn jacobian(&mut self, theta: &[f64], r: &DVector<f64>) -> Option<DMatrix<f64>> {
        forward_jacobian(&mut |t| self.residuals(t), theta, r, JACOBIAN_STEP)
    }
}

/// The relative step of [`PolishProblem`]'s forward differences.
const JACOBIAN_STEP: f64 = 1e-6;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::fit_effect_with;
    use crate::hypotheses::{Site, hypothesis};
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};
    use std::sync::Arc;
    use structid_core::{PolynomialDispersion, Signal};
    use structid_linear::PolynomialModel;

    const CUBIC: Effect = Effect::OddPolynomial { degree: 3 };

    /// A noise-free record of y = N(G·u) with a cubic sensor distortion plus a bias,
    /// N(z) = a1·z + a3·z³ + c, the hypothesis at the output, and the truth (a1, a3, c).
    fn sensor_case() -> (Hypothesis, Data, [f64; 3]) {
        let g = PolynomialModel {
            den: vec![1.0, -1.5, 0.7],
            num: vec![vec![0.0, 0.1, 0.1]],
            sample_time: Some(0.05),
        };
        let h = hypothesis(
            &g,
            Site::Output,
            Arc::new(PolynomialDispersion::new(1).unwrap()),
        )
        .unwrap();
        let truth = [0.3, 0.5, -0.2];
        let mut rng = StdRng::seed_from_u64(7);
        let norm = Normal::new(0.0, 1.0).unwrap();
        let mut s = 0.0;
        let u = Signal::from_fn(1500, 1, |_, _| {
            s = 0.8 * s + 0.6 * norm.sample(&mut rng);
            s
        });
        let f = |z: &[f64]| truth[0] * z[0] + truth[1] * z[0].powi(3) + truth[2];
        let y = h.simulate(&f, &u, None).unwrap().y;
        assert!(y.channel(0).iter().all(|v| v.is_finite()));
        let data = h.data(&Data::new(u, y).unwrap()).unwrap();
        (h, data, truth)
    }

    /// A map fit 20 % off the truth, with the offset.
    fn start(truth: [f64; 3]) -> EffectFit {
        let z: Vec<f64> = (0..200).map(|k| -1.0 + k as f64 / 99.5).collect();
        let w: Vec<f64> = z
            .iter()
            .map(|z| 1.2 * truth[0] * z + 0.8 * truth[1] * z.powi(3) + 1.2 * truth[2])
            .collect();
        fit_effect_with(CUBIC, true, &z, &w).unwrap()
    }

    /// |G(e^{jω})| of a SISO polynomial model.
    fn magnitude(g: &PolynomialModel, w: f64) -> f64 {
        let at = |c: &[f64]| {
            c.iter().enumerate().fold((0.0, 0.0), |(re, im), (i, x)| {
                (re + x * (i as f64 * w).cos(), im - x * (i as f64 * w).sin())
            })
        };
        let (n, d) = (at(&g.num[0]), at(&g.den));
        ((n.0 * n.0 + n.1 * n.1) / (d.0 * d.0 + d.1 * d.1)).sqrt()
    }

    /// An integrating axis 1/(s·(s + 2)) sampled at 1 kHz (zero-order hold), friction
    /// 0.5·tanh(v/0.05) + 0.3·v in rate feedback, output noise 1e-3: the one-sample rate of
    /// the measured output carries noise of std 1.4 against speeds of about 1.
    #[test]
    fn the_in_loop_refit_of_g_recovers_an_axis_whose_rate_is_mostly_noise() {
        let (a, ts) = (2.0_f64, 1e-3);
        let p = (-a * ts).exp();
        let truth = PolynomialModel {
            num: vec![vec![
                0.0,
                (a * ts - 1.0 + p) / (a * a),
                (1.0 - p - a * ts * p) / (a * a),
            ]],
            den: vec![1.0, -(1.0 + p), p],
            sample_time: Some(ts),
        };
        let h = hypothesis(
            &truth,
            Site::RateFeedback,
            Arc::new(PolynomialDispersion::new(1).unwrap()),
        )
        .unwrap();
        let friction = |z: &[f64]| 0.5 * (z[0] / 0.05).tanh() + 0.3 * z[0];
        let mut rng = StdRng::seed_from_u64(3);
        let norm = Normal::new(0.0, 1.0).unwrap();
        let len = 6000;
        let mut level = 0.0;
        let u = Signal::from_fn(len, 1, |k, _| {
            if k % 400 == 0 {
                level = 3.0 * norm.sample(&mut rng);
            }
            level
        });
        let clean = h.simulate(&friction, &u, None).unwrap().y;
        let y = Signal::from_fn(len, 1, |k, _| {
            clean.get(k, 0) + 1e-3 * norm.sample(&mut rng)
        });
        let est = Data::new(u, y).unwrap();
        let settings = DiscoverSettings::builder()
            .scoring(structid_core::validation::Scoring::Windowed(
                structid_core::validation::Windows::for_record(len, 5),
            ))
            .build()
            .unwrap();
        // A start half the gain, with the mechanical pole twice as fast.
        let q = (-2.0 * a * ts).exp();
        let start = PolynomialModel {
            num: vec![truth.num[0].iter().map(|b| 0.5 * b).collect()],
            den: vec![1.0, -(1.0 + q), q],
            sample_time: Some(ts),
        };
        let g = polish_linear(&start, &friction, Site::RateFeedback, &est, &settings)
            .expect("the refit lowers the cost");
        assert_eq!(structid_linear::integrators::count_integrators(&g.den), 1);
        for w in [2e-3, 2e-2] {
            let ratio = magnitude(&g, w) / magnitude(&truth, w);
            assert!(
                (ratio - 1.0).abs() < 0.08,
                "|G| at ω = {w}: {ratio} of the truth's"
            );
        }
    }

    #[test]
    fn a_converged_refit_recovers_the_map_and_its_offset_with_its_sign() {
        let (h, data, truth) = sensor_case();
        let fit = polish(&start(truth), &h, &data, &DiscoverSettings::default());
        let refit = fit.refit.as_ref().unwrap();
        assert!(refit.converged, "{refit:?}");
        assert!(refit.cost < 0.05 * refit.initial_cost, "{refit:?}");
        let v = fit.all_values();
        for (i, t) in truth.iter().enumerate() {
            assert!((v[i] - t).abs() < 0.03 * t.abs(), "{v:?} vs {truth:?}");
        }
        assert!(fit.nameable(), "{:?}", fit.flags);
        // The intervals come from the converged refit and hold the truth.
        for (p, t) in fit.parameters.iter().chain(fit.offset.as_ref()).zip(truth) {
            assert!(
                p.interval.0 <= t + 1e-9 && t - 1e-9 <= p.interval.1,
                "{p:?} vs {t}"
            );
        }
    }

    #[test]
    fn an_unconverged_refit_is_flagged_and_not_nameable() {
        let (h, data, truth) = sensor_case();
        // One iteration from 20 % off cannot meet a relative-decrease test of 1e-10.
        let fit = polish_with(&start(truth), &h, &data, &DiscoverSettings::default(), 1);
        let refit = fit.refit.as_ref().unwrap();
        assert!(!refit.converged, "{refit:?}");
        assert!(!fit.nameable());
        assert!(fit.flags.iter().any(|f| f.contains("did not converge")));
    }
}

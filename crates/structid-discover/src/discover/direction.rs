//! Is it static? The direction test on the residual deconvolved to the block's output.

use structid_core::validation::validate;
use structid_core::{Data, Interpolant, Model, Result, Signal};
use structid_lti::LinearSystem;

use crate::hypotheses::{Hypothesis, Location};
use crate::hysteresis::{DirectionTest, direction_dependence};

use super::DiscoverSettings;
use super::fit::Fitted;
use super::fit::scoring_settings;

/// The direction test of a fit: its noise estimate ê (what the static map leaves
/// unexplained), through the noise path to the output and deconvolved to the block's output,
/// split by the direction of z.
pub(super) fn direction_test(f: &Fitted, settings: &DiscoverSettings) -> Result<DirectionTest> {
    // The model's output residual is L_ye·ê = L_yw·δ: filter ê through the noise path first
    // (the identity for an output-error model), then invert L_yw.
    let r = f
        .hypothesis
        .model
        .lft()
        .t_ye()
        .simulate(&f.e_hat)?
        .channel(0);
    let delta = deconvolve(&f.hypothesis, &r)?;
    let skip = settings.settle.min(delta.len() / 10).max(delta.len() / 50);
    let mut test =
        direction_dependence(&f.z[skip..], &delta[skip..], settings.hysteresis_threshold);
    // A force acting in continuous time on a fed-back signal differs from the held N(z_k) by
    // about N'(z)·ż·T_s/2, which changes sign with the direction of motion: after any discrete
    // static fit it is a direction effect of its own. Its size is that of the half-sample
    // shift a_k = N̂'(z_k)·(z_(k+1) − z_(k−1))/4; a direction effect within four times its
    // energy (twice its amplitude) is sampling, not hysteresis. Actuator and sensor maps act on
    // held or sampled signals and have no such artefact.
    let feedback = matches!(
        f.result.location,
        Location::OutputFeedback | Location::RateFeedback | Location::Declared { .. }
    );
    if feedback && test.dynamic {
        let artefact = half_sample_artefact(f.map.as_ref(), &f.z);
        let sampling = direction_dependence(&f.z[skip..], &artefact[skip..], 1.0);
        test.sampling_energy = sampling.direction_energy;
        if test.direction_energy <= 4.0 * sampling.direction_energy {
            test.dynamic = false;
        }
    }
    Ok(test)
}

/// a_k = N̂'(z_k)·(z_(k+1) − z_(k−1))/4: what evaluating the map half a sample later changes
/// (central differences; 0 at the ends).
fn half_sample_artefact(map: &dyn Interpolant, z: &[f64]) -> Vec<f64> {
    let n = z.len();
    let (lo, hi) = z
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let h = 1e-3 * (hi - lo).max(f64::MIN_POSITIVE);
    (0..n)
        .map(|k| {
            if k == 0 || k + 1 == n {
                return 0.0;
            }
            let slope = (map.eval(&[z[k] + h]) - map.eval(&[z[k] - h])) / (2.0 * h);
            slope * (z[k + 1] - z[k - 1]) / 4.0
        })
        .collect()
}

/// The simulation residual y − ŷ of `model` with `map` on `data` at the scored samples (as
/// every simulation of the workflow is scored, [`scoring_settings`]), or `None` when the
/// simulation fails.
pub(super) fn simulation_residual(
    model: &Model,
    location: Location,
    map: &dyn Interpolant,
    data: &Data,
    settings: &DiscoverSettings,
) -> Option<Vec<f64>> {
    let settings = scoring_settings(location, settings);
    let v = validate(model, &[map], data, &settings).ok()?;
    let y = data.y().channel(0);
    let r: Vec<f64> = v
        .scored
        .iter()
        .flat_map(|r| r.clone())
        .map(|k| y[k] - v.simulated.get(k, 0))
        .collect();
    r.iter().all(|v| v.is_finite()).then_some(r)
}

/// Ridge deconvolution of `r` through the SISO operator T = L_yw: argmin ‖r − T·δ‖² + λ‖δ‖²
/// by conjugate gradients on (TᵀT + λI)·δ = Tᵀ·r, with Tᵀ applied as time reversal around T.
pub(super) fn deconvolve(h: &Hypothesis, r: &[f64]) -> Result<Vec<f64>> {
    let t = h.model.lft().t_yw();
    let n = r.len();
    let apply = |v: &[f64]| -> Result<Vec<f64>> {
        let s = Signal::from_fn(n, 1, |k, _| v[k]);
        Ok(t.simulate(&s)?.channel(0))
    };
    let adjoint = |v: &[f64]| -> Result<Vec<f64>> {
        let rev: Vec<f64> = v.iter().rev().copied().collect();
        let mut out = apply(&rev)?;
        out.reverse();
        Ok(out)
    };
    // λ = 1 % of the operator's largest gain² (estimated by power iteration), so that only the
    // frequencies T passes at least a tenth of its peak gain are recovered.
    let mut v: Vec<f64> = (0..n).map(|k| ((k * 7919) % 13) as f64 - 6.0).collect();
    let mut gain2 = 1.0;
    for _ in 0..20 {
        let tv = adjoint(&apply(&v)?)?;
        let norm = tv.iter().map(|x| x * x).sum::<f64>().sqrt();
        let vn = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm == 0.0 || vn == 0.0 {
            break;
        }
        gain2 = norm / vn;
        v = tv.iter().map(|x| x / norm).collect();
    }
    let lambda = 0.01 * gain2;
    let normal = |x: &[f64]| -> Result<Vec<f64>> {
        let ttx = adjoint(&apply(x)?)?;
        Ok(ttx.iter().zip(x).map(|(a, b)| a + lambda * b).collect())
    };
    let b = adjoint(r)?;
    let mut x = vec![0.0; n];
    let mut res = b.clone();
    let mut p = res.clone();
    let mut rr: f64 = res.iter().map(|v| v * v).sum();
    let stop = 1e-8 * rr.max(f64::MIN_POSITIVE);
    for _ in 0..100 {
        if rr <= stop {
            break;
        }
        let ap = normal(&p)?;
        let pap: f64 = p.iter().zip(&ap).map(|(a, b)| a * b).sum();
        if pap <= 0.0 {
            break;
        }
        let alpha = rr / pap;
        for k in 0..n {
            x[k] += alpha * p[k];
            res[k] -= alpha * ap[k];
        }
        let rr_new: f64 = res.iter().map(|v| v * v).sum();
        let beta = rr_new / rr;
        rr = rr_new;
        for k in 0..n {
            p[k] = res[k] + beta * p[k];
        }
    }
    Ok(x)
}

//! Is it static? The direction test on the residual deconvolved to the block's output.

use structid_core::{Data, Interpolant, Result, Signal};
use structid_lti::LinearSystem;

use crate::hypotheses::{Hypothesis, Site};
use crate::hysteresis::{DirectionTest, direction_dependence_records};

use super::DiscoverSettings;
use super::fit::Fitted;
use super::fit::scoring_settings;

/// The direction test of a fit: its noise estimate ê (what the static map leaves
/// unexplained), through the noise path to the output and deconvolved to the block's output,
/// split by the direction of z.
pub(super) fn direction_test(f: &Fitted, settings: &DiscoverSettings) -> Result<DirectionTest> {
    direction_test_of(f, None, settings)
}

/// The direction test of what the static map `map` (in place of the fit's own estimate)
/// leaves of `f`'s record: the output residual y − L_yu·u − L_yw·N(z) along the record's z
/// is L_ye·ê + L_yw·(ŵ − N(z)), from the fit's noise estimate ê and map output ŵ. `None`
/// tests the fit's own estimate.
pub(super) fn direction_test_of(
    f: &Fitted,
    map: Option<&dyn Interpolant>,
    settings: &DiscoverSettings,
) -> Result<DirectionTest> {
    // The model's output residual is L_ye·ê = L_yw·δ: filter ê through the noise path first
    // (the identity for an output-error model), then invert L_yw. Record by record, each
    // from rest, and each record's first samples left out.
    let t_ye = f.hypothesis.model.lft().t_ye();
    // ê as long as the records (an estimator may return none: then nothing is tested).
    let len = f.e_hat.len().min(f.z.len());
    let t_yw = match map {
        Some(_) if f.w_hat.len() < len => {
            return Err(structid_core::Error::Numerical(
                "the fit's map output is shorter than its record".into(),
            ));
        }
        Some(_) => Some(f.hypothesis.block_lft()?.t_yw()),
        None => None,
    };
    let records = if f.bounds.last() == Some(&len) {
        f.bounds.clone()
    } else {
        vec![0, len]
    };
    let (mut z, mut kept, mut bounds) = (Vec::new(), Vec::new(), vec![0]);
    for w in records.windows(2) {
        let e = f.e_hat.slice(w[0]..w[1]);
        let mut r = t_ye.simulate(&e)?.channel(0);
        if let (Some(map), Some(t_yw)) = (map, &t_yw) {
            let d = Signal::from_fn(w[1] - w[0], 1, |k, _| {
                f.w_hat[w[0] + k] - map.eval(&[f.z[w[0] + k]])
            });
            let shift = t_yw.simulate(&d)?.channel(0);
            r.iter_mut().zip(shift).for_each(|(r, s)| *r += s);
        }
        let delta = deconvolve(&f.hypothesis, &r)?;
        let skip = transient(delta.len(), settings);
        z.extend_from_slice(&f.z[w[0] + skip..w[1]]);
        kept.extend_from_slice(&delta[skip..]);
        bounds.push(z.len());
    }
    Ok(direction_beyond_sampling(
        &z,
        &kept,
        &bounds,
        // The sampling artefact of the smooth estimate: a steep family (a clip, a relay)
        // would make any direction effect look like one.
        acts_in_continuous_time(f.result.location).then_some(f.map.as_ref()),
        settings.hysteresis_threshold,
    ))
}

/// The leading samples of a record's deconvolved residual left out of a direction test: the
/// transient of a start that the record does not reveal.
pub(super) fn transient(len: usize, settings: &DiscoverSettings) -> usize {
    settings.settle.min(len / 10).max(len / 50)
}

/// Whether a map at `site` acts in continuous time on a fed-back signal, and so has a
/// sampling artefact ([`direction_beyond_sampling`]). Actuator and sensor maps act on held or
/// sampled signals and have none; nor does a map of the measured rate, whose backward
/// difference already sits half a sample back (and whose steep static fits, relays, would
/// call any direction effect an artefact).
pub(super) fn acts_in_continuous_time(site: Site) -> bool {
    matches!(site, Site::OutputFeedback | Site::Declared { .. })
}

/// A direction effect of at most this many times the energy of the half-sample artefact is
/// taken for sampling (see [`direction_beyond_sampling`]).
const SAMPLING_SHARE: f64 = 4.0;

/// The direction test of the residual `r` against `z`, and for a map acting in continuous time
/// on a fed-back signal (`map` given) measured against what sampling alone leaves: such a
/// force differs from the held N(z_k) by about N'(z)·ż·T_s/2, which changes sign with the
/// direction of motion, so after any discrete static fit it is a direction effect of its own.
/// Its size is that of the half-sample shift a_k = N̂'(z_k)·(z_(k+1) − z_(k−1))/4; a
/// direction effect within four times its energy (twice its amplitude) is sampling, not
/// hysteresis. `bounds` are the records' bounds in `z` and `r` (`[0, L]` for one record).
pub(super) fn direction_beyond_sampling(
    z: &[f64],
    r: &[f64],
    bounds: &[usize],
    map: Option<&dyn Interpolant>,
    threshold: f64,
) -> DirectionTest {
    let mut test = direction_dependence_records(z, r, bounds, threshold);
    if let Some(map) = map
        && test.dynamic
    {
        let artefact: Vec<f64> = bounds
            .windows(2)
            .flat_map(|w| half_sample_artefact(map, &z[w[0]..w[1]]))
            .collect();
        test.sampling_energy =
            direction_dependence_records(z, &artefact, bounds, 1.0).direction_energy;
        if test.direction_energy <= SAMPLING_SHARE * test.sampling_energy {
            test.dynamic = false;
        }
    }
    test
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

/// The simulation residual y − ŷ of the hypothesis `h` with `map` in its unknown block (and
/// its known maps) on `data` at the scored samples (as every simulation of the workflow is
/// scored, [`scoring_settings`]), or `None` when the simulation fails.
pub(super) fn simulation_residual(
    h: &Hypothesis,
    map: &dyn Interpolant,
    data: &Data,
    settings: &DiscoverSettings,
) -> Option<Vec<f64>> {
    simulation_residual_of(h, &h.maps(map), data, settings)
}

/// [`simulation_residual`] with every block's map given (`maps`, in the model's block order).
pub(super) fn simulation_residual_of(
    h: &Hypothesis,
    maps: &[&dyn Interpolant],
    data: &Data,
    settings: &DiscoverSettings,
) -> Option<Vec<f64>> {
    let settings = scoring_settings(h.location, settings);
    let v = crate::records::simulate(&h.model, maps, data, &settings).ok()?;
    let r = v.scored_residual();
    r.iter().all(|v| v.is_finite()).then_some(r)
}

/// Ridge deconvolution of `r` through the SISO operator T = L_yw: argmin ‖r − T·δ‖² + λ‖δ‖²
/// by conjugate gradients on (TᵀT + λI)·δ = Tᵀ·r, with Tᵀ applied as time reversal around T.
pub(super) fn deconvolve(h: &Hypothesis, r: &[f64]) -> Result<Vec<f64>> {
    // The unknown block's path alone (known maps' outputs are inputs of this LFT).
    let t = h.block_lft()?.t_yw();
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

#[cfg(test)]
mod tests {
    use super::*;

    fn sine(n: usize, w: f64) -> Vec<f64> {
        (0..n)
            .map(|k| (w * k as f64).sin() + 0.3 * (2.7 * w * k as f64).sin())
            .collect()
    }

    /// The residual a continuous-time map leaves after a discrete static fit is the
    /// half-sample artefact: direction dependent, but not hysteresis; a backlash of a width
    /// many samples of motion wide stays dynamic.
    #[test]
    fn sampling_artefacts_are_static_and_backlash_is_not() {
        let z = sine(4000, 0.05);
        let cubic = |v: &[f64]| v[0] + 2.0 * v[0].powi(3);
        // The map evaluated half a sample later, minus the held value.
        let r: Vec<f64> = (0..z.len())
            .map(|k| {
                if k == 0 || k + 1 == z.len() {
                    return 0.0;
                }
                let half = z[k] + 0.25 * (z[k + 1] - z[k - 1]);
                cubic(&[half]) - cubic(&[z[k]])
            })
            .collect();
        let plain = crate::hysteresis::direction_dependence(&z, &r, 0.1);
        assert!(plain.dynamic, "the artefact alone is direction dependent");
        let aware = direction_beyond_sampling(&z, &r, &[0, z.len()], Some(&cubic), 0.1);
        assert!(!aware.dynamic && aware.sampling_energy > 0.0);
        // Backlash of half-width 0.2 on the same motion, against the static fit w = z.
        let mut w = vec![0.0; z.len()];
        for k in 1..z.len() {
            w[k] = if z[k] - w[k - 1] > 0.2 {
                z[k] - 0.2
            } else if z[k] - w[k - 1] < -0.2 {
                z[k] + 0.2
            } else {
                w[k - 1]
            };
        }
        let rb: Vec<f64> = w.iter().zip(&z).map(|(w, z)| w - z).collect();
        let identity = |v: &[f64]| v[0];
        assert!(direction_beyond_sampling(&z, &rb, &[0, z.len()], Some(&identity), 0.1).dynamic);
    }
}

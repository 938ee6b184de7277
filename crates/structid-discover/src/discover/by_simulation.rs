//! Hypotheses beyond measurability, fitted by simulation error.
//!
//! The paper's criterion needs z computable from the record: z = Ψ(u, y). Once a map is known
//! at the output, the z of a block upstream of it depends on that map's inverse; a block
//! behind another map (D_zw ≠ 0) reads that map's output; a declared block may read a state
//! no sensor measures. Such a hypothesis is not refused: its map is fitted by simulation
//! error, the known maps held as they are, as a kernel expansion N(z) = Σ_j θ_j·k(z, c_j) +
//! cubic trend on fixed centres ([`structid_joint::GaussianFeatures`]),
//!
//! ```text
//!   min over θ, ξ₀ of  (1/L)·Σ_k |y_k − ŷ_k(θ, ξ₀)|² + β·θᵀKθ
//! ```
//!
//! from the neutral map (the identity in the signal path, zero in feedback), ŷ the free-run
//! simulation or, for a model scored in windows, the scoring's own windowed simulation (each
//! window from a state fitted to its first half, [`structid_joint::windowed`]), so that the
//! fit and its score are one criterion. β is a small fixed share of the output's energy per unit of the
//! map's dispersion: the data decide the map. The result is a candidate like any other,
//! scored on the validation record the same way, and named from its curve along the
//! simulated z. The same expansions serve the second-block rows
//! ([`super::second_block`]).

use std::sync::Arc;
use std::time::Instant;

use structid_core::validation::{Scoring, simulate_scored};
use structid_core::{Data, Error, Interpolant, LookupTable, PolynomialDispersion, Result, Signal};
use structid_joint::LinearInParameters;
use structid_joint::{
    BlockMap, FixedMap, GaussianFeatures, JointBlock, JointModel, JointSettings, fit,
};

use crate::hypotheses::{Hypothesis, Nominal, Site};

use super::fit::{
    Fitted, even_indices, minmax, simulated, simulation_rms, simulation_rms_and_noise,
};
use super::{DiscoverSettings, HypothesisResult, MapCurve};

/// Centres of each map's kernel expansion: the resolution of a nonparametric map of the
/// workflow (its Fourier kernel has a width of a tenth of z's range).
pub(super) const CENTRES: usize = 15;

/// The degree of each expansion's unpenalised trend: the cubic trend of the workflow's
/// nonparametric maps, which carries a stiffening spring or a saturating gain beyond the
/// range the centres cover.
const TREND_DEGREE: usize = 3;

/// Points per centre spacing at which a fitted expansion is written as a table, so that the
/// piecewise-linear table follows the expansion's curvature (a Gaussian of width one spacing
/// is resolved by four points within 1 % of its peak).
pub(super) const POINTS_PER_SPACING: usize = 4;

/// The share of the output's mean square that a map's dispersion costs at the scale of its
/// values: small enough that the fit is decided by the data, large enough to keep the normal
/// equations of an expansion with overlapping kernels well posed.
const DISPERSION_SHARE: f64 = 1e-6;

/// Levenberg–Marquardt iterations of one fit by simulation error: candidates are compared,
/// not polished (the named family is polished later, as every finding's is).
pub(super) const ITERATIONS: usize = 30;

/// The estimator's name in [`Fitted::estimator`] and the report.
pub(super) const ESTIMATOR: &str = "simulation error";

/// Whether the record does not give the z of the hypothesis at `location` of `nominal`, as
/// identification by the paper's criterion takes it (the known maps' outputs computed from the
/// record as known inputs): its block reads another map's output (D_zw ≠ 0), or a part of z
/// that no causal filter of y recovers.
pub(super) fn beyond_measurability(nominal: &Nominal, location: Site, est: &Data) -> bool {
    // A built-in site of a model without known maps reads u, y, ẏ or G·u: the paper's class,
    // which identification takes as it is (no second pass over the record on this hot path).
    if nominal.known_maps().is_empty() && !matches!(location, Site::Declared { .. }) {
        return false;
    }
    let Ok(h) = placeholder().and_then(|d| nominal.hypothesis(location, d)) else {
        return false;
    };
    let identification = h
        .data(est)
        .and_then(|data| super::fit::z_of(&h, &data))
        .and_then(|_| h.identification(est));
    match identification {
        Err(e) => e.beyond_measurability(),
        Ok((model, data)) => {
            let lft = model.lft();
            data.z().is_none()
                && (lft.matrices().dzw.iter().any(|v| *v != 0.0) || lft.measurability().is_err())
        }
    }
}

/// The hypothesis at `location` of `nominal`, its unknown map fitted by simulation error on
/// `est` (see the [module docs](self)), scored on `val` as every candidate is.
pub(super) fn fitted_by_simulation(
    nominal: &Nominal,
    location: Site,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> Result<Fitted> {
    let t0 = Instant::now();
    let h = nominal.hypothesis(location, placeholder()?)?;
    let none = |what: &str| Error::Numerical(format!("{what} {}", nominal.describe(location)));
    let range = z_range(&h, est)
        .and_then(padded)
        .ok_or_else(|| none("z has no range"))?;
    let neutral_map = |z: f64| neutral(location) * z;
    let start = with_known(
        &h,
        features_through(range, energy(est), &neutral_map),
        &neutral_map,
        est,
    )
    .ok_or_else(|| none("no kernel expansion of z"))?;
    let fitted = fit(&start, est, None, &joint_settings(settings)?)
        .map_err(|e| Error::Numerical(format!("the fit by simulation error failed: {e}")))?;
    let map = Expansion(fitted.model.blocks()[0].map.boxed());
    let h = h.with_dispersion(super::fit::quadratic_dispersion(
        range.1 - range.0,
        settings,
    )?);
    let (estimation_rms, residual_noise) = simulation_rms_and_noise(&h, &map, est, settings);
    let (z, e) = along_simulation(&h, &map, est, settings).ok_or_else(|| none("no simulation"))?;
    let (lo, hi) = minmax(&z);
    // Ranked, like every candidate, by the better of its map as estimated and held at its
    // edge values beyond the z it was fitted on: the location decides, not the extrapolation.
    let held = |z: &[f64]| map.eval(&[z[0].clamp(lo, hi)]);
    let (as_estimated, held_rms) = (
        simulation_rms(&h, &map, val, settings),
        simulation_rms(&h, &held, val, settings),
    );
    let hold_edges = held_rms < as_estimated;
    let validation_rms = if estimation_rms.is_finite() {
        as_estimated.min(held_rms)
    } else {
        f64::INFINITY
    };
    let grid: Vec<f64> = (0..101)
        .map(|i| lo + (hi - lo) * i as f64 / 100.0)
        .collect();
    let w_hat: Vec<f64> = z.iter().map(|&z| map.eval(&[z])).collect();
    let idx = even_indices(z.len(), settings.naming_points);
    let result = HypothesisResult {
        location,
        dispersion: format!("kernel expansion ({CENTRES} centres, cubic trend) by {ESTIMATOR}"),
        beta: f64::NAN,
        beta_at_bound: None,
        sigma: Some((range.1 - range.0) / (CENTRES - 1) as f64),
        noise_term: fitted.rms.first().map_or(f64::NAN, |r| r * r),
        dispersion_value: f64::NAN,
        estimation_rms,
        validation_rms,
        curve: MapCurve {
            w: grid.iter().map(|&z| map.eval(&[z])).collect(),
            z: grid,
            std: None,
        },
        points: (
            idx.iter().map(|&k| z[k]).collect(),
            idx.iter().map(|&k| w_hat[k]).collect(),
        ),
        seconds: t0.elapsed().as_secs_f64(),
        failure: None,
    };
    Ok(Fitted {
        result,
        hypothesis: h,
        map: Box::new(map),
        e_hat: Signal::from_fn(e.len(), 1, |k, _| e[k]),
        z,
        w_hat,
        bounds: est.record_bounds().to_vec(),
        estimator: ESTIMATOR,
        residual_noise,
        hold_edges,
        linear: None,
        direction: None,
        input_noise: None,
        sigma_fraction: settings.sigma_fraction,
    })
}

/// A fitted expansion as a map of the workflow.
#[derive(Debug)]
pub(super) struct Expansion(pub(super) Box<dyn BlockMap>);

impl Interpolant for Expansion {
    fn eval(&self, z: &[f64]) -> f64 {
        // A static map: no state to advance.
        self.0.eval(&mut [], z)
    }
}

/// z of the unknown block along the simulation of `h` with `map` (records stacked, as the
/// workflow scores them), and the simulation residual y − ŷ; `None` when it fails.
fn along_simulation(
    h: &Hypothesis,
    map: &dyn Interpolant,
    data: &Data,
    settings: &DiscoverSettings,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let sim = simulated(h, map, data, settings)?;
    let e: Vec<f64> = sim
        .measured
        .iter()
        .zip(&sim.simulated)
        .map(|(y, s)| y - s)
        .collect();
    // z along the simulation the residual is of: each window from its own state where the
    // scoring runs in windows (the direction test pairs them sample by sample), else the free
    // run of each record from rest.
    let maps = h.maps(map);
    let z = crate::records::stacked(data, |r| match settings.scoring {
        Some(Scoring::Windowed(w)) => {
            let sim = simulate_scored(&h.model, &maps, r, Scoring::Windowed(w), None, 0)?;
            let mut z = Vec::with_capacity(r.len());
            for (range, x0) in w.ranges(r.len()).into_iter().zip(&sim.states) {
                let u = r.u().slice(range);
                z.extend(
                    h.model
                        .simulate(&maps, &u, None, x0.as_deref())?
                        .z
                        .channel(0),
                );
            }
            Ok(z)
        }
        _ => Ok(h.model.simulate(&maps, r.u(), None, None)?.z.channel(0)),
    })
    .ok()?;
    (z.len() == e.len() && z.iter().all(|v| v.is_finite())).then_some((z, e))
}

/// The joint settings of a fit by simulation error, scored as the workflow scores.
pub(super) fn joint_settings(settings: &DiscoverSettings) -> Result<JointSettings> {
    let joint = JointSettings::builder().max_iterations(ITERATIONS);
    match settings.scoring {
        // The fit's criterion is the scoring's: windows from states fitted to their first half.
        Some(Scoring::Windowed(w)) => joint.polish(false).windows(w),
        _ => joint,
    }
    .build()
    .map_err(|e| Error::InvalidStructure(format!("joint settings: {e}")))
}

/// The joint model of `h` with `unknown` in its unknown block and its known maps held fixed.
fn with_known(
    h: &Hypothesis,
    unknown: Option<GaussianFeatures>,
    start: &(dyn Fn(f64) -> f64 + Sync),
    est: &Data,
) -> Option<JointModel> {
    let model = &h.model;
    let b = &model.blocks()[0];
    let mut blocks = vec![JointBlock::new(
        "unknown",
        b.inputs.clone(),
        b.output,
        Box::new(unknown?),
    )];
    let start = |z: &[f64]| start(z[0]);
    blocks.extend(known_blocks(h, &h.maps(&start), est, 0));
    JointModel::new(model.lft().clone(), blocks).ok()
}

/// The share of a known map's input range on each side of z over which its derivative is
/// taken in a fit by simulation error: a secant over a tenth of the range, the resolution of
/// the workflow's nonparametric maps (see [`CENTRES`]). A known map with finer steps (a
/// quantiser, flat between them) then passes on its trend to the sensitivities of the maps
/// around it, instead of a zero slope or a spike.
const KNOWN_SLOPE_SHARE: f64 = 0.05;

/// The known maps of `h` after the first `skip` as fixed blocks of a joint model, in the
/// model's block order (from block `1 + skip`), each with its derivative taken at the
/// resolution [`KNOWN_SLOPE_SHARE`] of its input's range along the free run of `est` from
/// rest with `maps` in the model's blocks.
pub(super) fn known_blocks(
    h: &Hypothesis,
    maps: &[&dyn Interpolant],
    est: &Data,
    skip: usize,
) -> Vec<JointBlock> {
    let model = &h.model;
    // Each record simulated once; a channel's range over all of them.
    let runs: Option<Vec<Signal>> = est
        .records()
        .iter()
        .map(|r| model.simulate(maps, r.u(), None, None).ok().map(|s| s.z))
        .collect();
    let input_range = |c: usize| {
        let z: Vec<f64> = runs.as_ref()?.iter().flat_map(|z| z.channel(c)).collect();
        let (lo, hi) = minmax(&z);
        (hi > lo && hi.is_finite() && lo.is_finite()).then_some(hi - lo)
    };
    h.known
        .iter()
        .enumerate()
        .skip(skip)
        .map(|(i, k)| {
            let b = &model.blocks()[i + 1];
            let step = b.inputs.first().and_then(|&c| input_range(c));
            let map = FixedMap::new(Arc::clone(&k.map), 1);
            let map = step.map_or(map.clone(), |r| {
                map.with_derivative_step(KNOWN_SLOPE_SHARE * r)
            });
            JointBlock::new(&k.name, b.inputs.clone(), b.output, Box::new(map))
        })
        .collect()
}

/// The mean square of the output of `data`.
pub(super) fn energy(data: &Data) -> f64 {
    let y = data.y().channel(0);
    y.iter().map(|v| v * v).sum::<f64>() / y.len().max(1) as f64
}

/// The dispersion of a hypothesis built only for its structure.
pub(super) fn placeholder() -> Result<Arc<dyn structid_core::Dispersion>> {
    Ok(Arc::new(PolynomialDispersion::new(1)?))
}

/// An interval of z.
pub(super) type Range = (f64, f64);

/// `range` widened by a tenth of its width on each side (a map is asked for a little beyond
/// the z it was fitted on when validated), `None` for an empty or non-finite range.
pub(super) fn padded((lo, hi): Range) -> Option<Range> {
    let pad = 0.1 * (hi - lo);
    (lo.is_finite() && hi.is_finite() && hi > lo).then_some((lo - pad, hi + pad))
}

/// The slope of the neutral map at `site`: 1 where the block sits in the signal path (it
/// passes its input on), 0 where it sits in feedback or at a declared place (it adds
/// nothing).
pub(super) fn neutral(site: Site) -> f64 {
    match site {
        Site::Input | Site::Output => 1.0,
        Site::OutputFeedback | Site::RateFeedback | Site::Declared { .. } => 0.0,
    }
}

/// The range of the unknown block's z on `est`: measured for the input and the feedback
/// sites, else from a simulation of the hypothesis with the block neutral.
pub(super) fn z_range(h: &Hypothesis, est: &Data) -> Option<Range> {
    // Record by record: no difference or simulation runs across a record boundary.
    let z = crate::records::stacked(est, |r| {
        Ok(match h.location {
            Site::Input => r.u().channel(0),
            Site::OutputFeedback => r.y().channel(0),
            Site::RateFeedback => {
                let y = r.y().channel(0);
                y.windows(2)
                    .map(|p| (p[1] - p[0]) / h.sample_time)
                    .collect()
            }
            Site::Output | Site::Declared { .. } => {
                let slope = neutral(h.location);
                let neutral = move |z: &[f64]| slope * z[0];
                let neutral: &dyn Interpolant = &neutral;
                h.model
                    .simulate(&h.maps(neutral), r.u(), None, None)?
                    .z
                    .channel(0)
            }
        })
    })
    .ok()?;
    Some(minmax(&z))
}

/// A kernel expansion on [`CENTRES`] centres over `range`, fitted to `f` there, its β a
/// [`DISPERSION_SHARE`] of the output's mean square `energy` at the scale of its values.
pub(super) fn features_through(
    range: Range,
    energy: f64,
    f: &dyn Fn(f64) -> f64,
) -> Option<GaussianFeatures> {
    let (lo, hi) = range;
    let spacing = (hi - lo) / (CENTRES - 1) as f64;
    let points = 4 * CENTRES;
    let z: Vec<Vec<f64>> = (0..points)
        .map(|k| vec![lo + (hi - lo) * k as f64 / (points - 1) as f64])
        .collect();
    let w: Vec<f64> = z.iter().map(|z| f(z[0])).collect();
    // A map's dispersion scales as (its values)² × (its range).
    let scale = w.iter().map(|v| v * v).sum::<f64>() / points as f64;
    let beta = DISPERSION_SHARE * energy / (scale.max(energy) * (hi - lo)).max(f64::MIN_POSITIVE);
    GaussianFeatures::on_interval(lo, hi, CENTRES, spacing, beta)
        .ok()?
        .with_trend_degree(TREND_DEGREE)
        .ok()?
        .fitted_to(&z, &w)
        .ok()
}

/// `f` sampled over `range` at [`POINTS_PER_SPACING`] points per spacing of [`CENTRES`]
/// centres (the resolution of the workflow's kernels), as a table.
pub(super) fn sampled(f: &dyn Fn(f64) -> f64, (lo, hi): Range) -> Option<super::AugmentedMap> {
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    // Twice the spacings: a widened range keeps the resolution over the estimated one.
    let n = 2 * POINTS_PER_SPACING * (CENTRES - 1) + 1;
    let z: Vec<f64> = (0..n)
        .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
        .collect();
    let w: Vec<f64> = z.iter().map(|&z| f(z)).collect();
    LookupTable::one_d(z.clone(), w.clone()).ok()?;
    Some(super::AugmentedMap::Table { z, w })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Effect;
    use crate::hypotheses::hypothesis;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};

    use super::super::{Classification, discover};

    /// The nominal G with a known sensor map y = x + 0.3·x³.
    fn with_sensor() -> Nominal {
        with_sensor_map(Arc::new(|z: &[f64]| z[0] + 0.3 * z[0].powi(3)))
    }

    /// The nominal G with the known sensor map `sensor`.
    fn with_sensor_map(sensor: Arc<dyn Interpolant>) -> Nominal {
        let first = hypothesis(
            &super::super::tests::nominal(),
            Site::Output,
            placeholder().unwrap(),
        )
        .unwrap();
        Nominal::from_model(&first.model, vec![sensor]).unwrap()
    }

    /// Behind a quantising sensor, whose derivative is zero between its steps, the fit by
    /// simulation error still sees the actuator: the known map passes on its trend to the
    /// sensitivities, and the saturation's fit closes most of the gap of the nominal model.
    #[test]
    fn an_actuator_behind_a_quantising_sensor_is_fitted_by_simulation() {
        let step = 0.05;
        let nominal = with_sensor_map(Arc::new(move |z: &[f64]| (z[0] / step).round() * step));
        let sat: fn(f64) -> f64 = |z| (1.5 * z).clamp(-0.8, 0.8);
        let est = record(&nominal, Site::Input, sat, 5);
        let val = record(&nominal, Site::Input, sat, 6);
        let settings = DiscoverSettings::default();
        let before = nominal.simulate_output(val.u()).unwrap();
        let y = val.y().channel(0);
        let nominal_rms = (y
            .iter()
            .zip(&before)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / y.len() as f64)
            .sqrt();
        let f = fitted_by_simulation(&nominal, Site::Input, &est, &val, &settings).unwrap();
        assert!(
            f.result.validation_rms < 0.3 * nominal_rms,
            "{} against {nominal_rms}",
            f.result.validation_rms
        );
    }

    /// A record of `nominal` with `truth` at `site`, filtered-noise input, output noise 0.005.
    fn record(nominal: &Nominal, site: Site, truth: fn(f64) -> f64, seed: u64) -> Data {
        let mut rng = StdRng::seed_from_u64(seed);
        let norm = Normal::new(0.0, 1.0).unwrap();
        let mut s = 0.0;
        let u = Signal::from_fn(3000, 1, |_, _| {
            s = 0.8 * s + 0.6 * norm.sample(&mut rng);
            s
        });
        let noise = Normal::new(0.0, 0.005).unwrap();
        let e = Signal::from_fn(3000, 1, |_, _| noise.sample(&mut rng));
        let h = nominal.hypothesis(site, placeholder().unwrap()).unwrap();
        let f = move |z: &[f64]| truth(z[0]);
        let y = h.simulate(&f, &u, Some(&e)).unwrap().y;
        Data::new(u, y).unwrap()
    }

    /// Behind a known sensor map, an actuator's z is not computable from the record (it would
    /// take the sensor map's inverse and G's): the hypothesis at the input is fitted by
    /// simulation error, located, named with its parameters, and closes the gap to the noise.
    #[test]
    fn an_actuator_behind_a_known_sensor_is_fitted_by_simulation_and_named() {
        let nominal = with_sensor();
        assert!(beyond_measurability(
            &nominal,
            Site::Input,
            &record(&nominal, Site::Input, |z| z, 9)
        ));
        let sat: fn(f64) -> f64 = |z| (1.5 * z).clamp(-0.8, 0.8);
        let est = record(&nominal, Site::Input, sat, 1);
        let val = record(&nominal, Site::Input, sat, 2);
        let d = discover(&nominal, &est, &val, &DiscoverSettings::default()).unwrap();
        let input = d
            .hypotheses
            .iter()
            .find(|h| h.location == Site::Input)
            .unwrap();
        assert!(input.dispersion.contains(ESTIMATOR), "{}", input.dispersion);
        let f = d.finding.expect("a finding");
        assert_eq!(f.location, Site::Input, "{}", d.verdict);
        let Classification::Named(fit) = &f.classification else {
            panic!("not named: {}", d.verdict)
        };
        assert_eq!(fit.effect, Effect::Saturation, "{}", d.verdict);
        let v = fit.values();
        assert!(
            (v[0] - 1.5).abs() < 0.075 && (v[1] - 0.8).abs() < 0.04,
            "{v:?}"
        );
        // Twice the noise at most is left, against a gap many times the noise.
        assert!(
            d.validation_gap.rms > 10.0 * 0.005,
            "{}",
            d.validation_gap.rms
        );
        assert!(
            f.augmented.validation_gap.rms < 0.01,
            "{}",
            f.augmented.validation_gap.rms
        );
    }

    /// The expansion fitted by simulation error reproduces a map it can represent: with the
    /// truth a saturating spring in feedback behind the known sensor, the fitted map agrees with
    /// the spring over the range of z within a few percent of the spring's largest force.
    #[test]
    fn a_spring_behind_a_known_sensor_is_recovered_over_its_range() {
        let nominal = with_sensor();
        let spring: fn(f64) -> f64 = |z| 0.3 * (0.3 * z).tanh();
        let est = record(&nominal, Site::OutputFeedback, spring, 3);
        let val = record(&nominal, Site::OutputFeedback, spring, 4);
        assert!(beyond_measurability(&nominal, Site::OutputFeedback, &est));
        let settings = DiscoverSettings::default();
        let f =
            fitted_by_simulation(&nominal, Site::OutputFeedback, &est, &val, &settings).unwrap();
        let (lo, hi) = minmax(&f.z);
        let scale = spring(lo).abs().max(spring(hi).abs());
        let worst = f
            .result
            .curve
            .z
            .iter()
            .zip(&f.result.curve.w)
            .map(|(z, w)| (w - spring(*z)).abs())
            .fold(0.0, f64::max);
        assert!(scale > 0.05 && worst < 0.05 * scale, "{worst} of {scale}");
        assert!(
            f.result.validation_rms < 0.0075,
            "{}",
            f.result.validation_rms
        );
    }

    /// A map found in series with a known one (a second sensor map after the first: D_zw ≠ 0)
    /// becomes the nominal model of the next step, which simulates as the composition of G and
    /// the two maps written out.
    #[test]
    fn a_finding_in_series_with_a_known_map_is_the_next_nominal() {
        let nominal = with_sensor();
        let h = nominal
            .hypothesis(Site::Output, placeholder().unwrap())
            .unwrap();
        assert!(h.model.lft().matrices().dzw.iter().any(|v| *v != 0.0));
        let new: Arc<dyn Interpolant> = Arc::new(|z: &[f64]| (2.0 * z[0]).tanh());
        let sensor: Arc<dyn Interpolant> = Arc::new(|z: &[f64]| z[0] + 0.3 * z[0].powi(3));
        let next = Nominal::from_model(&h.model, vec![new, sensor]).unwrap();
        let u = Signal::from_fn(300, 1, |k, _| (0.05 * k as f64).sin() + 0.3);
        let x = Nominal::from_polynomial(&super::super::tests::nominal())
            .unwrap()
            .simulate_output(&u)
            .unwrap();
        let y = next.simulate_output(&u).unwrap();
        let worst = x
            .iter()
            .zip(&y)
            .map(|(x, y)| ((2.0 * (x + 0.3 * x.powi(3))).tanh() - y).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-12, "{worst}");
        assert!(x.iter().any(|x| x.abs() > 0.3));
    }
}

//! The candidate rows "a second block added to the first": the first effect's map and an
//! unknown map at another site, fitted together by simulation error.
//!
//! A map found while a second effect is still unmodelled carries that effect's bias: an
//! input map absorbs part of a sensor saturation, a stiffness map takes on friction's
//! direction dependence, which can make the first step call its effect dynamic. Holding that
//! map fixed, the next step sees only what the biased map leaves, and may find nothing. The
//! remedy is the joint fit of both maps: with N_A the first map (site A) and N_B an unknown
//! map at site B, both kernel expansions on fixed centres ([`structid_joint::GaussianFeatures`]),
//!
//! ```text
//!   min over θ_A, θ_B, ξ₀ of  (1/L)·Σ_k |y_k − ŷ_k(θ_A, θ_B, ξ₀)|² + Σ_b β_b·θ_bᵀK_bθ_b
//! ```
//!
//! from N_A as found and N_B neutral (the identity for a map in the signal path, zero for a
//! map in feedback), G as given. ŷ is the free-run simulation, or for a model scored in
//! windows, a multiple-shooting simulation on segments of the window length. Each row is then
//! scored on the validation record the same way as every other simulation of the workflow.
//! The β_b are a small fixed share of the output's energy per unit of a map's dispersion:
//! the rows compare maps, not regularisations.

use std::sync::Arc;
use std::time::Instant;

use structid_core::validation::Scoring;
use structid_core::{Data, Interpolant, LookupTable, PolynomialDispersion};
use structid_joint::{
    BlockMap, FixedMap, GaussianFeatures, JointBlock, JointModel, JointSettings, fit,
};

use structid_core::selection::{Criterion, SelectionSettings, select};
use structid_core::{IdentifySettings, InitialState, Signal};

use crate::hypotheses::{Hypothesis, Nominal, Site};

use super::DiscoverSettings;
use super::Finding;
use super::fit::{initial_state, simulation_rms};
use super::model::AugmentedMap;

/// One row "the first block and a second one at `site`", fitted jointly.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SecondBlock {
    /// Where the first block sits.
    pub first_location: Site,
    /// Where the second block sits.
    pub site: Site,
    /// Simulation RMS on the estimation record after the joint fit (scored as the workflow
    /// scores).
    pub estimation_rms: f64,
    /// Simulation RMS on the validation record (scored as the workflow scores); infinite
    /// when the simulation failed or diverged.
    pub validation_rms: f64,
    /// The first block's map re-estimated jointly, sampled at its own resolution.
    pub first_map: AugmentedMap,
    /// The second block's map, sampled at its own resolution.
    pub second_map: AugmentedMap,
    /// Wall-clock seconds of the fit and the scoring.
    pub seconds: f64,
}

/// Centres of each map's kernel expansion: the resolution of a nonparametric map of the
/// workflow (its Fourier kernel has a width of a tenth of z's range).
const CENTRES: usize = 15;

/// The degree of each expansion's unpenalised trend: the cubic trend of the workflow's
/// nonparametric maps, which carries a stiffening spring or a saturating gain beyond the
/// range the centres cover.
const TREND_DEGREE: usize = 3;

/// Points per centre spacing at which a fitted expansion is written as a table, so that the
/// piecewise-linear table follows the expansion's curvature (a Gaussian of width one spacing
/// is resolved by four points within 1 % of its peak).
const POINTS_PER_SPACING: usize = 4;

/// The share of the output's mean square that a map's dispersion costs at the scale of its
/// values: small enough that the fit is decided by the data, large enough to keep the normal
/// equations of an expansion with overlapping kernels well posed.
const DISPERSION_SHARE: f64 = 1e-6;

/// Levenberg–Marquardt iterations of one joint fit: the start is close (the first map as
/// found), and rows are compared, not polished.
const ITERATIONS: usize = 30;

/// The second-block rows: for each site of `nominal` other than the first finding's, the
/// first block's map and a map at that site fitted together on `est` and scored on `val` (see
/// the [module docs](self)). `nominal` is the model the first finding was found on, and
/// `settings` those it was found with, their scoring resolved ([`super::Discovery::scoring`]).
/// Rows whose model cannot be built or fitted are left out.
///
/// ```no_run
/// # use structid_core::Data;
/// # use structid_discover::discover::{DiscoverSettings, discover, second_blocks};
/// # use structid_discover::hypotheses::Nominal;
/// # fn rows(nominal: &Nominal, est: &Data, val: &Data) {
/// let d = discover(nominal, est, val, &DiscoverSettings::default()).unwrap();
/// let settings = DiscoverSettings::builder().scoring(d.scoring).build().unwrap();
/// if let Some(first) = &d.finding {
///     for row in second_blocks(nominal, first, est, val, &settings) {
///         println!("{:?} + {:?}: {}", row.first_location, row.site, row.validation_rms);
///     }
/// }
/// # }
/// ```
pub fn second_blocks(
    nominal: &Nominal,
    first: &Finding,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> Vec<SecondBlock> {
    let Ok(with_first) = first.augmented.as_nominal(nominal) else {
        return Vec::new();
    };
    nominal
        .locations()
        .into_iter()
        .filter(|&site| site != first.location)
        .filter_map(|site| second_block(nominal, &with_first, first, site, est, val, settings))
        .collect()
}

/// The row of `site` ([`second_blocks`]): the better validated of the pair identified by
/// the paper's criterion ([`identified_pair`]) and the pair fitted by simulation error
/// ([`jointly_fitted_pair`]); `None` when neither can be built or fitted.
fn second_block(
    nominal: &Nominal,
    with_first: &Nominal,
    first: &Finding,
    site: Site,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> Option<SecondBlock> {
    let t0 = Instant::now();
    let pairs = [
        identified_pair(with_first, site, est, settings),
        jointly_fitted_pair(with_first, first, site, est, settings),
    ];
    let mut best: Option<SecondBlock> = None;
    for (first_map, second_map) in pairs.into_iter().flatten().flatten() {
        let Some(row) = scored(
            nominal, first, site, first_map, second_map, est, val, settings,
        ) else {
            continue;
        };
        if best
            .as_ref()
            .is_none_or(|b| row.validation_rms < b.validation_rms)
        {
            best = Some(row);
        }
    }
    best.map(|b| SecondBlock {
        seconds: t0.elapsed().as_secs_f64(),
        ..b
    })
}

/// Both maps identified together by the paper's criterion, when the first map is the only
/// known one and both blocks' z are computable from the record (an actuator, a stiffness, a
/// friction): the quadratic dispersion of the workflow on each, sized to its z's range, one
/// β by marginal likelihood, as every single block of the workflow is identified.
fn identified_pair(
    with_first: &Nominal,
    site: Site,
    est: &Data,
    settings: &DiscoverSettings,
) -> Option<Vec<(AugmentedMap, AugmentedMap)>> {
    let probe = with_first.hypothesis(site, placeholder()?).ok()?;
    if probe.known.len() != 1 {
        return None;
    }
    let est_h = probe.data(est).ok()?;
    let z = match est_h.z() {
        Some(z) => z.clone(),
        None => probe.model.lft().compute_z(est_h.u(), est_h.y()).ok()?.0,
    };
    let ranges = [
        super::fit::minmax(&z.channel(0)),
        super::fit::minmax(&z.channel(1)),
    ];
    let dispersions: Vec<_> = ranges
        .iter()
        .map(|(lo, hi)| super::fit::quadratic_dispersion(hi - lo, settings).ok())
        .collect::<Option<_>>()?;
    let mut next = dispersions.into_iter();
    let model = probe
        .model
        .with_dispersions(|_| next.next().expect("two blocks"));
    let identify = IdentifySettings::builder()
        .initial_state(InitialState::Zero)
        .build()
        .ok()?;
    let selection = SelectionSettings::builder()
        .criterion(Criterion::MarginalLikelihood)
        .widen_decades(0.0)
        .build()
        .ok()?;
    let sel = select(&model, &est_h, None, &identify, &selection).ok()?;
    let id = match initial_state(site).0 {
        InitialState::Zero => sel.identification,
        x0 => structid_core::identify(
            &sel.model,
            &est_h,
            &identify.with_initial_state(x0).with_beta(sel.beta).ok()?,
        )
        .ok()?,
    };
    let (a, b) = (&id.blocks[1], &id.blocks[0]);
    let range = |z: &Signal| super::fit::minmax(&z.channel(0));
    extrapolations(
        &|z| a.map.eval(&[z]),
        range(&a.z),
        &|z| b.map.eval(&[z]),
        range(&b.z),
    )
}

/// Both maps fitted together by simulation error (see the [module docs](self)).
fn jointly_fitted_pair(
    with_first: &Nominal,
    first: &Finding,
    site: Site,
    est: &Data,
    settings: &DiscoverSettings,
) -> Option<Vec<(AugmentedMap, AugmentedMap)>> {
    let h = with_first.hypothesis(site, placeholder()?).ok()?;
    let (start, first_range, second_range) = joint_start(&h, first, est)?;
    let mut joint = JointSettings::builder()
        .max_iterations(ITERATIONS)
        .polish(segment_length(settings).is_none());
    if let Some(len) = segment_length(settings) {
        // Independent windows, as the model is scored.
        joint = joint.segment_length(len).continuity_weight(0.0);
    }
    let fitted = fit(&start, est, None, &joint.build().ok()?).ok()?;
    let blocks = fitted.model.blocks();
    let (a, b) = (blocks[1].map.as_ref(), blocks[0].map.as_ref());
    let mut pairs = extrapolations(
        &|z| a.eval(&mut [], &[z]),
        first_range,
        &|z| b.eval(&mut [], &[z]),
        second_range,
    )?;
    // The expansions written in their own form keep their fit and their trend exactly.
    if let (Some(ea), Some(eb)) = (a.expression(), b.expression()) {
        pairs.push((AugmentedMap::Expression(ea), AugmentedMap::Expression(eb)));
    }
    Some(pairs)
}

/// The row of a pair of maps: the first map in place of `first`'s in `nominal`, the second
/// in the unknown block of the hypothesis at `site`, scored as every model of the workflow.
#[allow(clippy::too_many_arguments)]
fn scored(
    nominal: &Nominal,
    first: &Finding,
    site: Site,
    first_map: AugmentedMap,
    second_map: AugmentedMap,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
) -> Option<SecondBlock> {
    let mut refitted = first.augmented.clone();
    refitted.map = first_map.clone();
    refitted.fit = None;
    let h = refitted
        .as_nominal(nominal)
        .ok()?
        .hypothesis(site, placeholder()?)
        .ok()?;
    let second = second_map.interpolant().ok()?;
    Some(SecondBlock {
        first_location: first.location,
        site,
        estimation_rms: simulation_rms(&h, second.as_ref(), est, settings),
        validation_rms: simulation_rms(&h, second.as_ref(), val, settings),
        first_map,
        second_map,
        seconds: 0.0,
    })
}

/// The dispersion of a hypothesis built only for its structure.
fn placeholder() -> Option<Arc<dyn structid_core::Dispersion>> {
    Some(Arc::new(PolynomialDispersion::new(1).ok()?))
}

/// Multiple shooting on the scoring's windows for a model scored in windows (its free run
/// drifts); single shooting otherwise.
fn segment_length(settings: &DiscoverSettings) -> Option<usize> {
    match settings.scoring {
        Some(Scoring::Windowed(w)) => Some(w.length()),
        _ => None,
    }
}

/// The joint model of hypothesis `h` (block 0 the second block, block 1 the first finding's,
/// then the nominal model's known maps, held fixed), with the ranges its two expansions cover:
/// the second map neutral over the range of its z, the first map as found over the range it
/// was estimated on.
fn joint_start(h: &Hypothesis, first: &Finding, est: &Data) -> Option<(JointModel, Range, Range)> {
    let model = &h.model;
    let y = est.y().channel(0);
    let energy = y.iter().map(|v| v * v).sum::<f64>() / y.len().max(1) as f64;
    let first_map = first.augmented.map.interpolant().ok()?;
    let first_range = padded(super::fit::minmax(&first.hypothesis.curve.z))?;
    let first_block = features_through(first_range, energy, &|z| first_map.eval(&[z]))?;
    let second_range = padded(second_range(h, est)?)?;
    let slope = neutral(h.location);
    let second_block = features_through(second_range, energy, &|z| slope * z)?;
    let block = |i: usize, name: &str, map: Box<dyn BlockMap>| {
        let b = &model.blocks()[i];
        JointBlock::new(name, b.inputs.clone(), b.output, map)
    };
    let mut blocks = vec![
        block(0, "second", Box::new(second_block)),
        block(1, "first", Box::new(first_block)),
    ];
    // Blocks 2.. are the known maps after the first finding's (h.known[1..]).
    for (i, k) in h.known.iter().enumerate().skip(1) {
        let name = k.name.clone();
        blocks.push(block(
            i + 1,
            &name,
            Box::new(FixedMap::new(Arc::clone(&k.map), 1)),
        ));
    }
    Some((
        JointModel::new(model.lft().clone(), blocks).ok()?,
        first_range,
        second_range,
    ))
}

/// An interval of z.
type Range = (f64, f64);

/// `range` widened by a tenth of its width on each side (a map is asked for a little beyond
/// the z it was fitted on when validated), `None` for an empty or non-finite range.
fn padded((lo, hi): Range) -> Option<Range> {
    let pad = 0.1 * (hi - lo);
    (lo.is_finite() && hi.is_finite() && hi > lo).then_some((lo - pad, hi + pad))
}

/// The slope of the neutral map at `site`: 1 where the block sits in the signal path (it
/// passes its input on), 0 where it sits in feedback or at a declared place (it adds
/// nothing).
fn neutral(site: Site) -> f64 {
    match site {
        Site::Input | Site::Output => 1.0,
        Site::OutputFeedback | Site::RateFeedback | Site::Declared { .. } => 0.0,
    }
}

/// The range of the second block's z on `est`: measured for the input and the feedback
/// sites, else from a simulation of the hypothesis with the block neutral.
fn second_range(h: &Hypothesis, est: &Data) -> Option<(f64, f64)> {
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
    Some(super::fit::minmax(&z))
}

/// A kernel expansion on [`CENTRES`] centres over `range`, fitted to `f` there.
fn features_through(range: Range, energy: f64, f: &dyn Fn(f64) -> f64) -> Option<GaussianFeatures> {
    let (lo, hi) = range;
    let spacing = (hi - lo) / (CENTRES - 1) as f64;
    let points = 4 * CENTRES;
    let z: Vec<Vec<f64>> = (0..points)
        .map(|k| vec![lo + (hi - lo) * k as f64 / (points - 1) as f64])
        .collect();
    let w: Vec<f64> = z.iter().map(|z| f(z[0])).collect();
    // A map's dispersion scales as (its values)² × (its range): β makes it cost
    // DISPERSION_SHARE of the output's mean square at that scale.
    let scale = w.iter().map(|v| v * v).sum::<f64>() / points as f64;
    let beta = DISPERSION_SHARE * energy / (scale.max(energy) * (hi - lo)).max(f64::MIN_POSITIVE);
    GaussianFeatures::on_interval(lo, hi, CENTRES, spacing, beta)
        .ok()?
        .with_trend_degree(TREND_DEGREE)
        .ok()?
        .fitted_to(&z, &w)
        .ok()
}

/// A pair of maps written two ways, as every map of the workflow is ranked: held at their
/// edge values beyond the range they were estimated on, and extrapolated by their own trend
/// over half that range again on each side (and held beyond). Outside the estimation range
/// a map is an extrapolation, and the validation decides which one; the site does not.
fn extrapolations(
    first: &dyn Fn(f64) -> f64,
    first_range: Range,
    second: &dyn Fn(f64) -> f64,
    second_range: Range,
) -> Option<Vec<(AugmentedMap, AugmentedMap)>> {
    let widened = |(lo, hi): Range| (lo - 0.5 * (hi - lo), hi + 0.5 * (hi - lo));
    Some(vec![
        (sampled(first, first_range)?, sampled(second, second_range)?),
        (
            sampled(first, widened(first_range))?,
            sampled(second, widened(second_range))?,
        ),
    ])
}

/// `f` sampled over `range` at [`POINTS_PER_SPACING`] points per spacing of [`CENTRES`]
/// centres (the resolution of the workflow's kernels), as a table.
fn sampled(f: &dyn Fn(f64) -> f64, (lo, hi): Range) -> Option<AugmentedMap> {
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
    Some(AugmentedMap::Table { z, w })
}

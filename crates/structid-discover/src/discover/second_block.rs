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
//! windows, the scoring's windowed simulation ([`structid_joint::windowed`]). Each row is then
//! scored on the validation record the same way as every other simulation of the workflow.
//! The β_b are a small fixed share of the output's energy per unit of a map's dispersion:
//! the rows compare maps, not regularisations.

use std::time::Instant;

use structid_core::selection::{Criterion, SelectionSettings, select};
use structid_core::{Data, IdentifySettings, InitialState, Interpolant, Signal};
use structid_joint::{BlockMap, JointBlock, JointModel, fit};

use crate::hypotheses::{Hypothesis, Nominal, Site};

use super::DiscoverSettings;
use super::Finding;
use super::by_simulation::{
    Range, energy, features_through, joint_settings, known_blocks, neutral, padded, placeholder,
    sampled, z_range,
};
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

/// The second-block rows: for each site of `nominal` other than the first finding's, the
/// first block's map and a map at that site fitted together on `est` and scored on `val` (see
/// the module docs of `second_block`). `nominal` is the model the first finding was found on, and
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
    let probe = with_first.hypothesis(site, placeholder().ok()?).ok()?;
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
    let h = with_first.hypothesis(site, placeholder().ok()?).ok()?;
    let (start, first_range, second_range) = joint_start(&h, first, est)?;
    let fitted = fit(&start, est, None, &joint_settings(settings).ok()?).ok()?;
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
        .hypothesis(site, placeholder().ok()?)
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

/// The joint model of hypothesis `h` (block 0 the second block, block 1 the first finding's,
/// then the nominal model's known maps, held fixed), with the ranges its two expansions cover:
/// the second map neutral over the range of its z, the first map as found over the range it
/// was estimated on.
fn joint_start(h: &Hypothesis, first: &Finding, est: &Data) -> Option<(JointModel, Range, Range)> {
    let model = &h.model;
    let energy = energy(est);
    let first_map = first.augmented.map.interpolant().ok()?;
    let first_range = padded(super::fit::minmax(&first.hypothesis.curve.z))?;
    let first_block = features_through(first_range, energy, &|z| first_map.eval(&[z]))?;
    let second_range = padded(z_range(h, est)?)?;
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
    let neutral_map = |z: &[f64]| slope * z[0];
    let mut start: Vec<&dyn Interpolant> = vec![&neutral_map, first_map.as_ref()];
    start.extend(
        h.known
            .iter()
            .skip(1)
            .map(|k| k.map.as_ref() as &dyn Interpolant),
    );
    blocks.extend(known_blocks(h, &start, est, 1));
    Some((
        JointModel::new(model.lft().clone(), blocks).ok()?,
        first_range,
        second_range,
    ))
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

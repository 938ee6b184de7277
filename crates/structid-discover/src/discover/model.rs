//! What discovery reports per hypothesis and about the effect: map curves, hypothesis
//! results, the classification and the augmented model.

use std::sync::Arc;
use structid_core::selection::Bound;

use structid_core::{ExprMap, Interpolant, LookupTable, Model, Result};

use crate::effects::EffectFit;
use crate::gap::Gap;
use crate::hypotheses::{KnownMap, Nominal, Site};

/// A map estimate drawn for reports: values (and, when available, the ±2σ posterior band) on
/// a grid over the range of z seen in the estimation record.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MapCurve {
    /// Grid of z.
    pub z: Vec<f64>,
    /// N̂(z) on the grid.
    pub w: Vec<f64>,
    /// Posterior standard deviation on the grid, when the solver kept the posterior.
    pub std: Option<Vec<f64>>,
}

/// One identified hypothesis.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HypothesisResult {
    /// Where the block was put.
    pub location: Site,
    /// The dispersion used, e.g. `sum(fourier(sigma=0.1), polynomial(3))`.
    pub dispersion: String,
    /// β chosen.
    pub beta: f64,
    /// The bound of its search interval that β was selected on, if any: a failed selection
    /// (at the lower bound the map follows the noise, at the upper bound the data support no
    /// map beyond the dispersion's null space), which the hypothesis should not be ranked on.
    pub beta_at_bound: Option<Bound>,
    /// The kernel width used (tuned or fixed; `None` for total variation).
    pub sigma: Option<f64>,
    /// The cost terms at the estimate: μ = (1/L)·Σ|ê_k|² and D(z, ŵ).
    pub noise_term: f64,
    /// D(z, ŵ) at the estimate.
    pub dispersion_value: f64,
    /// Simulation RMS on the estimation record (x₀ estimated).
    pub estimation_rms: f64,
    /// Simulation RMS on the validation record (x₀ estimated); infinite when the simulation
    /// diverged.
    pub validation_rms: f64,
    /// The estimated map.
    pub curve: MapCurve,
    /// Points (z_k, ŵ_k), at most [`super::DiscoverSettings::naming_points`], evenly spaced in time.
    pub points: (Vec<f64>, Vec<f64>),
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Why the hypothesis could not be identified or simulated, if so.
    pub failure: Option<String>,
}

/// What the missing effect was found to be.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum Classification {
    /// A family of the library fits within the noise.
    Named(EffectFit),
    /// A static effect no family fits: the nonparametric map is kept.
    Unnamed,
    /// The effect depends on the direction of z: "dynamic: hysteresis or backlash suspected".
    Dynamic,
    /// Re-estimated on consecutive segments of the estimation record, the chosen family's
    /// parameters, or a gain at the input or output of the best model found, follow a trend
    /// larger than their scatter allows ([`Stationarity`](super::Stationarity)): the effect
    /// changes over time. The fit is the whole record's (the family's, or the drifting gain's);
    /// the augmented model carries the best static approximation found.
    TimeVarying(EffectFit),
}

impl Classification {
    /// The name for reports.
    pub fn describe(&self) -> String {
        match self {
            Classification::Named(fit) => fit.effect.name(),
            Classification::Unnamed => "unnamed static effect".into(),
            Classification::Dynamic => "dynamic: hysteresis or backlash suspected".into(),
            Classification::TimeVarying(fit) => {
                format!(
                    "time-varying: {} whose parameters change over the record",
                    fit.effect.name()
                )
            }
        }
    }

    /// The name for reports, in the physics of the site the effect acts at
    /// ([`crate::effects::physical_name`]): a named family as an actuator's, a sensor's, a
    /// stiffness or a friction.
    pub fn describe_at(&self, location: crate::hypotheses::Site) -> String {
        match self {
            Classification::Named(fit) => crate::effects::physical_name(fit, location),
            Classification::TimeVarying(fit) => format!(
                "time-varying: {} whose parameters change over the record",
                crate::effects::physical_name(fit, location)
            ),
            other => other.describe(),
        }
    }
}

/// The map the augmented model carries.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum AugmentedMap {
    /// A map in closed form, its expression in `z0` (model-file `truth` syntax): a named
    /// family, or a kernel expansion written exactly (a second-block row's).
    Expression(String),
    /// The nonparametric estimate sampled on a grid (piecewise linear, edge values held).
    Table {
        /// Breakpoints.
        z: Vec<f64>,
        /// Values.
        w: Vec<f64>,
    },
}

impl AugmentedMap {
    /// The map as an [`Interpolant`] (what `structid simulate` and `validate` will use).
    pub fn interpolant(&self) -> Result<Box<dyn Interpolant>> {
        Ok(match self {
            AugmentedMap::Expression(e) => Box::new(ExprMap::parse(e, 1)?),
            AugmentedMap::Table { z, w } => Box::new(LookupTable::one_d(z.clone(), w.clone())?),
        })
    }
}

/// The nominal model with the found effect added.
#[derive(Clone, Debug)]
pub struct Augmented {
    /// Where the block sits.
    pub location: Site,
    /// The augmented LFT with its blocks: the new one first, then the nominal model's known
    /// maps.
    pub model: Model,
    /// The new block's map.
    pub map: AugmentedMap,
    /// The new block's named family, when it was named.
    pub fit: Option<EffectFit>,
    /// The nominal model's known maps, blocks `1..` of `model` (empty for a linear nominal).
    pub known: Vec<KnownMap>,
    /// The gap of the augmented model on the estimation record.
    pub estimation_gap: Gap,
    /// The gap of the augmented model on the validation record.
    pub validation_gap: Gap,
}

impl Augmented {
    /// Every block's map in block order: the new one, then the known ones (what simulates the
    /// augmented model, e.g. with [`Model::simulate`]).
    pub fn maps(&self) -> Result<Vec<Arc<dyn Interpolant>>> {
        let first: Arc<dyn Interpolant> = Arc::from(self.map.interpolant()?);
        Ok(std::iter::once(first)
            .chain(self.known.iter().map(|k| Arc::clone(&k.map)))
            .collect())
    }

    /// The augmented model as the nominal model of the next discovery: its LFT with every map
    /// fixed ([`Nominal::from_model`]), and the named states of `given` (the nominal model it
    /// was found on) that its states keep.
    pub fn as_nominal(&self, given: &Nominal) -> Result<Nominal> {
        let mut next = Nominal::new(self.model.lft().clone())?;
        let fits =
            std::iter::once(self.fit.clone()).chain(self.known.iter().map(|k| k.fit.clone()));
        for ((block, map), fit) in self.model.blocks().iter().zip(self.maps()?).zip(fits) {
            next = next.with_known(
                block.inputs[0],
                block.output,
                KnownMap {
                    name: block.name.clone(),
                    map,
                    fit,
                },
            )?;
        }
        let states = self.model.lft().dims().states;
        for s in given.states() {
            if s.state < states {
                next = next.with_state(&s.name, s.state)?;
            }
        }
        Ok(next)
    }
}

//! # structid-discover: naming what a model is missing
//!
//! The discovery workflow of structid starts from a model that almost fits: it finds where the
//! simulation and the measurements disagree, inserts an unknown static block at candidate
//! places of the structure, identifies it nonparametrically (structid's `identify`), and
//! names what the estimate shows, then adds it to the model and shows the gap shrink. The
//! workflow is [`discover::discover`] (CLI: `structid discover`); its parts are:
//!
//! * [`discover`](mod@discover): the workflow itself (gap → where → which location → is it static → what is
//!   it → the augmented model and the gap after), with its settings and result;
//! * [`gap`]: how large the gap between a model's simulation and a record is, whether it is
//!   only noise (a model-free noise level and portmanteau tests of whiteness and of linear and
//!   nonlinear input correlation), and where it sits;
//! * [`hypotheses`]: the nominal model ([`hypotheses::Nominal`]: an LFT, without maps or with
//!   the known maps of earlier findings, with declared locations and named states) and the
//!   augmented LFTs that insert one unknown static block at the input, at the output, in feedback from the output or from its rate (a
//!   dynamic Ψ_M in the paper's Definition 1), or at a declared location;
//! * [`known`]: the LFTs of a nominal model that already carries maps (the augmented model
//!   of an earlier discovery), with the next block around it and its maps kept fixed inside;
//! * [`localise`]: where the residual of a model exceeds its noise band in time, and in which
//!   region of which candidate signal its energy concentrates (e.g. `|u| > 0.8`);
//! * [`effects`]: a library of named static effects (saturation, smooth and one-sided
//!   saturation, rectification, dead zone, gap spring, Coulomb, Coulomb + viscous and Stribeck
//!   friction, symmetric and asymmetric, odd and even polynomial and power-law stiffness,
//!   quantisation, offset, gain error; every family may carry an offset),
//!   each a parametric family with documented parameters, fitted to the points (z_k, ŵ_k) of a
//!   nonparametric estimate by least squares with 95 % intervals, ranked by the Bayesian
//!   information criterion, and named only when the best fit is within the noise;
//! * [`hysteresis`]: whether the residual of a static fit depends on the direction of motion
//!   (hysteresis or backlash: an effect that is not static and must not be forced into a name);
//! * [`staticness`]: how well a static map explains a (z, w) scatter at all (the paper's
//!   Example 1): the unexplained variance of the best static fit against the noise, and the
//!   direction test;
//! * [`augmented`]: the augmented model of a finding as a model file and as a stored
//!   estimate;
//! * [`records`]: several records (experiments): each step runs record by record and pools;
//!
//! ```
//! use structid_discover::effects::{Effect, NamingSettings, name_effect};
//! // Points of an estimated map: a saturation at ±1 with slope 2.
//! let z: Vec<f64> = (0..400).map(|k| -1.5 + 3.0 * k as f64 / 399.0).collect();
//! let w: Vec<f64> = z.iter().map(|z| (2.0 * z).clamp(-1.0, 1.0)).collect();
//! let naming = name_effect(&z, &w, &NamingSettings::default()).unwrap();
//! let best = naming.named.unwrap();
//! assert_eq!(best.effect, Effect::Saturation);
//! println!("{}: {}", best.effect.name(), best.expression);
//! ```

pub mod augmented;
pub mod discover;
pub mod effects;
pub mod error;
pub mod gap;
pub mod hypotheses;
pub mod hysteresis;
pub mod known;
pub mod localise;
pub mod records;

pub mod staticness;
pub mod table;

pub use discover::{
    Classification, DiscoverSettings, Discovery, Effects, EffectsSettings, discover,
    discover_effects,
};
pub use effects::{
    Effect, EffectError, EffectFit, Naming, NamingSettings, Parameter, fit_effect, name_effect,
};
pub use error::DiscoverError;

//! The discovery workflow on the Silverbox benchmark: start from the project's own best linear
//! approximation and let [`discover`](structid_discover::discover::discover) find what is missing.
//!
//! 1. The estimation split is divided into a fitting part (the first 80 %) and a validation
//!    part (the rest); the test splits are not looked at until the end.
//! 2. The nominal model is the BLA of order n (default 2: the physics' mass–spring–damper) on
//!    the fitting part, by ARX then output error with a free initial state
//!    ([`structid_core::refine::best_linear_approximation`]); its model is y = G·u + e.
//! 3. [`discover`](structid_discover::discover::discover) runs over every default location with its default settings: the gap of the
//!    BLA, the four hypotheses (input, output sensor, feedback from y, feedback from ẏ)
//!    identified on the fitting part and ranked on the validation part, the named family and
//!    the augmented model.
//! 4. Each test split is simulated from rest, from u alone, with the BLA and with the
//!    augmented model (the named parametric map in the loop); the first 50 samples settle and
//!    are not scored.
//!
//! The Silverbox is an electronic Duffing oscillator, m·ÿ + d·ẏ + a·y + b·y³ = u: the missing
//! effect is a cubic stiffness acting in feedback from y. Its linear part a·y is already in the
//! BLA (as part of its denominator), so the map's linear coefficient is the BLA's stiffness
//! error: structurally, F + k·B and N − k·y give the same model.

use structid::workflow::{LinearStartDiscovery, LinearStartRequest, discover_from_linear_start};
use structid_core::{Data, Error, Result};
use structid_discover::discover::DiscoverSettings;
use structid_io::{Silverbox, SilverboxSplit};

use crate::pipeline::io;

/// Settings of [`run`].
#[derive(Clone, Debug)]
pub struct SilverboxDiscoverySettings {
    /// Order n of the nominal BLA (na = nb = n, nk = 1).
    pub order: usize,
    /// Fraction of the estimation split held out for validation.
    pub validation_fraction: f64,
    /// Settings of the workflow.
    pub discover: DiscoverSettings,
}

impl Default for SilverboxDiscoverySettings {
    /// n = 2, 20 % validation, default discovery settings.
    fn default() -> Self {
        Self {
            order: 2,
            validation_fraction: 0.2,
            discover: DiscoverSettings::default(),
        }
    }
}

/// Runs the workflow of the [module documentation](self): the linear-start discovery of
/// `structid-workflow` on the estimation split, scored on the three test splits.
pub fn run(sb: &Silverbox, settings: &SilverboxDiscoverySettings) -> Result<LinearStartDiscovery> {
    let est: Data = sb.split(SilverboxSplit::Estimation).data().map_err(io)?;
    let tests = SilverboxSplit::TESTS.map(|s| sb.split(s));
    let request = LinearStartRequest {
        order: settings.order,
        validation_fraction: settings.validation_fraction,
        sample_time: sb.sample_time,
        discover: settings.discover.clone(),
    };
    discover_from_linear_start(&est, &tests, &request)
        .map_err(|e| Error::InvalidStructure(e.to_string()))
}

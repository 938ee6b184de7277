//! Stand-in for a library function being written on another branch.
//!
//! * `SHIM(validate)`: [`validate`] and its types → `structid_core::validation::{validate,
//!   ValidationSettings, ValidationReport}`. The stand-in simulates from rest with
//!   [`structid_core::Lft::simulate`] and scores with [`metrics::fit_percent`].

use structid_core::metrics::{self, rms_difference};
use structid_core::{Data, Interpolant, Model, Result};

/// Settings of [`validate`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ValidationSettings {}

/// The result of [`validate`].
#[derive(Clone, Debug, PartialEq)]
pub struct ValidationReport {
    /// Per output: RMS of y − y_sim.
    pub rms: Vec<f64>,
    /// Per output: 100·(1 − ‖y − y_sim‖/‖y − mean y‖).
    pub fit_percent: Vec<f64>,
}

// SHIM(validate): replace by `structid_core::validation::validate` when it lands on main.
/// Simulates `model` with `maps` from rest on the inputs of `data` and compares with its outputs.
pub fn validate(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    settings: &ValidationSettings,
) -> Result<ValidationReport> {
    let _ = settings;
    let sim = model.simulate(maps, data.u(), None, None)?;
    let (mut rms, mut fit_percent) = (Vec::new(), Vec::new());
    for c in 0..data.y().channels() {
        let (y, ys) = (data.y().channel(c), sim.y.channel(c));
        rms.push(rms_difference(&y, &ys));
        fit_percent.push(metrics::fit_percent(&y, &ys));
    }
    Ok(ValidationReport { rms, fit_percent })
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_core::paper;

    #[test]
    fn validate_with_the_true_maps_fits_noise_free_data() {
        let exp = paper::spray(100, 0.0, paper::gaussian(0.1).unwrap(), 1).unwrap();
        let f = |z: &[f64]| paper::spray_f(z[0]);
        let g = |z: &[f64]| paper::spray_g(z[0]);
        let r = validate(
            &exp.model,
            &[&f, &g],
            &exp.data,
            &ValidationSettings::default(),
        )
        .unwrap();
        assert!(
            r.rms[0] < 1e-12 && (r.fit_percent[0] - 100.0).abs() < 1e-9,
            "{r:?}"
        );
    }
}

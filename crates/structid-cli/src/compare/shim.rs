//! Stand-ins for library functions that are being written on other branches.
//!
//! Each item mirrors the planned signature, so that replacing a shim is a change of `use`
//! lines plus deleting it here:
//!
//! * `SHIM(select)`: [`select`] and its types → `structid_core::hyperparameters::{select,
//!   Criterion, SelectionSettings, Selection, Trial}`. The stand-in handles the marginal
//!   likelihood and GCV for quadratic dispersions with
//!   [`structid_core::hyperparameters::select_beta`] (β only) and refuses everything else.
//! * `SHIM(validate)`: [`validate`] and its types → `structid_core::validation::{validate,
//!   ValidationSettings, ValidationReport}`. The stand-in simulates from rest with
//!   [`structid_core::Lft::simulate`] and scores with [`metrics::fit_percent`].
//! * `SHIM(bands)`: [`posterior_std`] → `Identification::posterior_std(&self, block, points)`.
//!   The stand-in has no bands.

use structid_core::hyperparameters::{Criterion as DenseCriterion, select_beta};
use structid_core::metrics::{self, rms_difference};
use structid_core::{
    Data, Error, Identification, IdentifySettings, Interpolant, Model, Problem, Result, Signal,
    identify,
};

/// The criterion that chooses β (and σ).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Criterion {
    /// Maximum marginal likelihood.
    MarginalLikelihood,
    /// Generalised cross-validation.
    Gcv,
    /// K-fold cross-validation.
    CrossValidation {
        /// Number of folds.
        folds: usize,
    },
    /// Simulation error on a validation record.
    Validation,
}

/// Settings of [`select`].
#[derive(Clone, Debug, PartialEq)]
pub struct SelectionSettings {
    criterion: Criterion,
    tune_sigma: bool,
}

/// Builder of [`SelectionSettings`].
#[derive(Clone, Debug)]
pub struct SelectionSettingsBuilder {
    inner: SelectionSettings,
}

impl SelectionSettings {
    /// Starts from the marginal likelihood without σ tuning.
    pub fn builder() -> SelectionSettingsBuilder {
        SelectionSettingsBuilder {
            inner: SelectionSettings {
                criterion: Criterion::MarginalLikelihood,
                tune_sigma: false,
            },
        }
    }
}

impl SelectionSettingsBuilder {
    /// The criterion.
    pub fn criterion(mut self, criterion: Criterion) -> Self {
        self.inner.criterion = criterion;
        self
    }

    /// Whether σ is chosen together with β.
    pub fn tune_sigma(mut self, tune: bool) -> Self {
        self.inner.tune_sigma = tune;
        self
    }

    /// The settings.
    pub fn build(self) -> Result<SelectionSettings> {
        Ok(self.inner)
    }
}

/// One evaluation of the criterion.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Trial {
    /// β tried.
    pub beta: f64,
    /// σ tried, when σ is tuned.
    pub sigma: Option<f64>,
    /// The criterion's value.
    pub value: f64,
}

/// The result of [`select`].
#[derive(Debug)]
pub struct Selection {
    /// The chosen β.
    pub beta: f64,
    /// The chosen σ, when σ was tuned.
    #[allow(dead_code)] // part of the planned library type; σ is read from the estimate
    pub sigma: Option<f64>,
    /// The criterion used.
    #[allow(dead_code)] // part of the planned library type
    pub criterion: Criterion,
    /// Every trial, in the order evaluated.
    pub curve: Vec<Trial>,
    /// The noise variance implied at the chosen β, when the criterion gives one.
    pub noise_variance: Option<f64>,
    /// The identification at the chosen hyperparameters.
    pub identification: Identification,
    /// The model with the chosen σ.
    pub model: Model,
}

/// The kind of a block's dispersion, from its description (`gaussian(sigma=…)` → `gaussian`).
fn kind(describe: &str) -> &str {
    describe.split('(').next().unwrap_or(describe)
}

// SHIM(select): replace by `structid_core::hyperparameters::select` when it lands on main.
/// Chooses β (and σ) by `selection` and identifies with them.
pub fn select(
    model: &Model,
    data: &Data,
    validation: Option<&Data>,
    settings: &IdentifySettings,
    selection: &SelectionSettings,
) -> Result<Selection> {
    let _ = validation;
    if let Some(b) = model
        .blocks()
        .iter()
        .find(|b| kind(&b.dispersion.describe()) == "tv")
    {
        return Err(Error::Unsupported(format!(
            "automatic selection for {} not available yet",
            kind(&b.dispersion.describe())
        )));
    }
    if selection.tune_sigma {
        return Err(Error::Unsupported(
            "automatic selection of sigma not available yet".into(),
        ));
    }
    let dense = match selection.criterion {
        Criterion::MarginalLikelihood => DenseCriterion::MarginalLikelihood,
        Criterion::Gcv => DenseCriterion::Gcv,
        other => {
            return Err(Error::Unsupported(format!(
                "automatic selection by {other:?} not available yet"
            )));
        }
    };
    let problem = Problem::from_model(model, data)?;
    let sel = select_beta(&problem, dense, settings.beta())?;
    let mut b = IdentifySettings::builder()
        .beta(sel.beta)
        .solver(settings.solver())
        .initial_state(settings.initial_state())
        .conic(settings.conic().clone())
        .admm(settings.admm().clone());
    if let Some(m) = settings.memory_limit_bytes() {
        b = b.memory_limit_bytes(m);
    }
    let identification = identify(model, data, &b.build()?)?;
    Ok(Selection {
        beta: sel.beta,
        sigma: None,
        criterion: selection.criterion,
        curve: sel
            .curve
            .iter()
            .map(|&(beta, value)| Trial {
                beta,
                sigma: None,
                value,
            })
            .collect(),
        noise_variance: Some(sel.noise_variance),
        identification,
        model: model.clone(),
    })
}

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

// SHIM(bands): replace by `id.posterior_std(block, points)` when it lands on main.
/// The posterior standard deviation of block `block`'s estimate at `points`, when the
/// identification provides one.
pub fn posterior_std(
    id: &Identification,
    block: usize,
    points: &Signal,
) -> Result<Option<Vec<f64>>> {
    let _ = (id, block, points);
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use structid_core::{TotalVariation, paper};

    #[test]
    fn select_picks_a_beta_and_identifies_with_it() {
        let exp = paper::spray(200, 0.5, paper::gaussian(0.1).unwrap(), 4).unwrap();
        let settings = IdentifySettings::builder().beta(0.01).build().unwrap();
        let sel = select(
            &exp.model,
            &exp.data,
            None,
            &settings,
            &SelectionSettings::builder().build().unwrap(),
        )
        .unwrap();
        assert!(sel.curve.iter().any(|t| t.beta == sel.beta));
        assert_eq!(sel.identification.cost.beta, sel.beta);
        let tv = paper::spray(50, 0.5, Arc::new(TotalVariation::new()), 4).unwrap();
        let e = select(
            &tv.model,
            &tv.data,
            None,
            &settings,
            &SelectionSettings::builder().build().unwrap(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("automatic selection for tv"), "{e}");
    }

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

//! The paper's examples (`structid demo`'s experiments) and the benchmark scenarios, as
//! records and models.

use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_core::paper::{self, Experiment};
use structid_io::{BlockSpec, DispersionSpec, ModelFile, SignalNames};

use crate::convert::{self, error, invalid};
use crate::model::Model;

/// An experiment as Python objects: its model (every block with `dispersion`, as a model file
/// with the experiment's LFT), u, y, the true w and the noise.
fn experiment<'py>(
    py: Python<'py>,
    exp: &Experiment,
    dispersion: DispersionSpec,
) -> PyResult<Bound<'py, PyDict>> {
    let dims = exp.model.lft().dims();
    let names = |prefix: &str, n: usize| -> Vec<String> {
        if n == 1 {
            vec![prefix.into()]
        } else {
            (0..n).map(|i| format!("{prefix}{i}")).collect()
        }
    };
    let file = ModelFile {
        lft: exp.model.lft().clone(),
        linear: None,
        signals: SignalNames {
            u: names("u", dims.u),
            y: names("y", dims.y),
            z: None,
        },
        blocks: exp
            .model
            .blocks()
            .iter()
            .map(|b| BlockSpec {
                name: b.name.clone(),
                inputs: b.inputs.clone(),
                output: b.output,
                dispersion: dispersion.clone(),
                truth: None,
                operator: None,
                shape: None,
            })
            .collect(),
        discover: None,
        path: None,
    };
    let model = ModelFile::parse(&file.to_toml_string(), None).map_err(error)?;
    let d = PyDict::new(py);
    d.set_item("model", Model { file: model })?;
    d.set_item("u", convert::array(py, exp.data.u()))?;
    d.set_item("y", convert::array(py, exp.data.y()))?;
    d.set_item("w_true", convert::array(py, &exp.w_true))?;
    d.set_item("noise", convert::array(py, &exp.noise))?;
    Ok(d)
}

fn check_sigma(sigma: f64) -> PyResult<()> {
    if sigma.is_finite() && sigma > 0.0 {
        Ok(())
    } else {
        Err(invalid(format!(
            "invalid sigma {sigma}: it must be a finite number greater than zero"
        )))
    }
}

/// A paper example with the Gaussian dispersion of width `sigma`, as its model file states it.
fn gaussian_experiment<'py>(
    py: Python<'py>,
    scenario: fn(
        usize,
        f64,
        std::sync::Arc<dyn structid_core::Dispersion>,
        u64,
    ) -> structid_core::Result<Experiment>,
    samples: usize,
    noise_std: f64,
    sigma: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    check_sigma(sigma)?;
    let exp = scenario(
        samples,
        noise_std,
        paper::gaussian(sigma).map_err(error)?,
        seed,
    )
    .map_err(error)?;
    experiment(py, &exp, DispersionSpec::Gaussian { sigma: Some(sigma) })
}

/// The spray-deposition example (section 6.1): y_k = f(u_k) + g(u_(k−2)) + e_k with
/// u_k = sin(0.1k), f(z) = −|z|, g(z) = 0.5·(sin((3z)²) + (2z)² − 2).
#[pyfunction]
#[pyo3(signature = (samples=2000, noise_std=1.0, sigma=0.1, seed=1))]
pub fn spray<'py>(
    py: Python<'py>,
    samples: usize,
    noise_std: f64,
    sigma: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    gaussian_experiment(py, paper::spray, samples, noise_std, sigma, seed)
}

/// The two-input example (section 6.2): one map N(z0, z1) behind a known LTI block.
#[pyfunction]
#[pyo3(signature = (samples=1500, noise_std=0.1, sigma=0.5, seed=1))]
pub fn multi_input<'py>(
    py: Python<'py>,
    samples: usize,
    noise_std: f64,
    sigma: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    gaussian_experiment(py, paper::multi_input, samples, noise_std, sigma, seed)
}

/// The feature solver's benchmark problem (`cargo bench --bench features`,
/// `examples/feature_scaling.rs`): SISO Hammerstein with N = tanh, an IIR L_yw of `order`,
/// coloured noise H = (1 + 0.5q⁻¹)/(1 − 0.8q⁻¹) of standard deviation `noise_std`, white
/// input; the model's block has the Fourier dispersion with Gaussian-like weights of width
/// `sigma` and `harmonics` harmonics.
#[pyfunction]
#[pyo3(signature = (samples, order=4, noise_std=0.3, seed=11, sigma=0.2, harmonics=31))]
pub fn hammerstein_coloured<'py>(
    py: Python<'py>,
    samples: usize,
    order: usize,
    noise_std: f64,
    seed: u64,
    sigma: f64,
    harmonics: usize,
) -> PyResult<Bound<'py, PyDict>> {
    check_sigma(sigma)?;
    let spec = DispersionSpec::Fourier {
        sigma: Some(sigma),
        harmonics: Some(harmonics),
        additive: false,
    };
    let dispersion = spec.build(None, None).map_err(error)?;
    let exp = py
        .detach(|| {
            structid_core::scenarios::hammerstein_coloured(
                samples, order, noise_std, dispersion, seed,
            )
        })
        .map_err(error)?;
    experiment(py, &exp, spec)
}

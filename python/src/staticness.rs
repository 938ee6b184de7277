//! How well a static map explains a (z, w) scatter (`structid static`, the paper's Example 1).

use numpy::PyReadonlyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_discover::staticness::{StaticnessSettings, staticness};

use crate::convert::{error, invalid, json, vector};

/// Fits the best static map w = N(z) (automatic β) and rates what it leaves against the noise
/// level and the direction of motion of z. Returns the report (as `structid static` writes it
/// in report.json) with the fitted values and the map on a grid as arrays.
#[pyfunction]
#[pyo3(signature = (z, w, sigma_fraction=None, sigma=None, noise_std=None, ratio_limit=None,
                    direction_threshold=None))]
pub fn staticness_columns<'py>(
    py: Python<'py>,
    z: PyReadonlyArray1<'py, f64>,
    w: PyReadonlyArray1<'py, f64>,
    sigma_fraction: Option<f64>,
    sigma: Option<f64>,
    noise_std: Option<f64>,
    ratio_limit: Option<f64>,
    direction_threshold: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let finite = |a: &PyReadonlyArray1<'py, f64>, what: &str| -> PyResult<Vec<f64>> {
        let v = a.as_array();
        if let Some((k, x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
            return Err(invalid(format!(
                "{what} has the non-finite value {x} at sample {k}"
            )));
        }
        Ok(v.iter().copied().collect())
    };
    let (z, w) = (finite(&z, "z")?, finite(&w, "w")?);
    let mut b = StaticnessSettings::builder();
    if let Some(f) = sigma_fraction {
        b = b.sigma_fraction(f);
    }
    if let Some(s) = sigma {
        b = b.sigma(s);
    }
    if let Some(s) = noise_std {
        b = b.noise_std(s);
    }
    if let Some(r) = ratio_limit {
        b = b.ratio_limit(r);
    }
    if let Some(t) = direction_threshold {
        b = b.direction_threshold(t);
    }
    let settings = b.build().map_err(error)?;
    let s = py
        .detach(move || staticness(&z, &w, &settings))
        .map_err(error)?;
    let out = PyDict::new(py);
    out.set_item("report", json(&s)?)?;
    out.set_item("verdict_text", s.verdict.describe())?;
    out.set_item("fitted", vector(py, s.fitted))?;
    out.set_item("grid_z", vector(py, s.grid_z))?;
    out.set_item("grid_w", vector(py, s.grid_w))?;
    Ok(out)
}

//! The linear part: ARX and output-error fits of G (`structid linear`) and its frequency and
//! step responses, poles and zeros (the figures `structid linear` draws).

use nalgebra::DMatrix;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_core::Signal;
use structid_core::Site;
use structid_linear::OrderCriterion;
use structid_linear::PolynomialModel;
use structid_linear::response::{bode, poles, step_response, zeros};
use structid_workflow::linear::{LinearMethod, LinearRequest, MapRequest, OrderChoice, fit_linear};

use crate::convert::{error, invalid, signal, vector};

/// Fits G = B(q)/A(q) (one output, the columns of each `u` its inputs) to one or several
/// records ([`structid_workflow::linear::fit_linear`], as `structid linear`): the orders given
/// (`orders = (na, nb, nk)`) or selected (`select` over NA, NB ≤ `max_order` and NK in
/// `delays`, `validation` a record for `select = "validation"`), by ARX (`method = "arx"`) or
/// output error (`"oe"`, each record from rest or, with `initial_state = "estimate"`, from its
/// estimated state), with `integrators` poles held at z = 1 and `transient` samples of each
/// record left out of the OE cost; a map at `structure` (`"lti"`, `"output-feedback"`,
/// `"input"`) when asked. Returns the model's polynomials, the orders and how they were
/// chosen, the cost, the parameter covariance, the simulation fit of every record, and the
/// model file text (as `structid linear -o` writes it).
#[pyfunction]
#[pyo3(signature = (u, y, orders, method, initial_state="zero", integrators=0, sample_time=None,
                    transient=0, inputs=None, output=None, select="bic", max_order=6,
                    delays=(1, 3), validation=None, structure="lti", map="N",
                    dispersion="fourier", trend=None, separate_numerator=false))]
pub fn linear_fit<'py>(
    py: Python<'py>,
    u: Vec<PyReadonlyArray2<'py, f64>>,
    y: Vec<PyReadonlyArray1<'py, f64>>,
    orders: Option<[usize; 3]>,
    method: &str,
    initial_state: &str,
    integrators: usize,
    sample_time: Option<f64>,
    transient: usize,
    inputs: Option<Vec<String>>,
    output: Option<String>,
    select: &str,
    max_order: usize,
    delays: (usize, usize),
    validation: Option<(PyReadonlyArray2<'py, f64>, PyReadonlyArray1<'py, f64>)>,
    structure: &str,
    map: &str,
    dispersion: &str,
    trend: Option<usize>,
    separate_numerator: bool,
) -> PyResult<Bound<'py, PyDict>> {
    if u.len() != y.len() || u.is_empty() {
        return Err(invalid(format!(
            "u and y must hold the same number of records (at least one), not {} and {}",
            u.len(),
            y.len()
        )));
    }
    let mut records: Vec<(Signal, Signal)> = Vec::with_capacity(u.len());
    for (i, (ui, yi)) in u.iter().zip(&y).enumerate() {
        let what = |s: &str| {
            if u.len() == 1 {
                s.to_string()
            } else {
                format!("{s} of record {i}")
            }
        };
        records.push(pair(ui, yi, &what("u"), &what("y"))?);
    }
    let m = records[0].0.channels();
    let inputs = inputs.unwrap_or_else(|| {
        if m == 1 {
            vec!["u".into()]
        } else {
            (0..m).map(|i| format!("u{i}")).collect()
        }
    });
    let method = match (method.to_ascii_lowercase().as_str(), initial_state) {
        ("arx", "zero") => LinearMethod::Arx,
        ("oe", "zero") => LinearMethod::Oe,
        ("oe", "estimate") => LinearMethod::OeWithInitialState,
        ("arx", "estimate") => {
            return Err(invalid(
                "initial_state=\"estimate\" applies to the output-error fit (method=\"oe\")",
            ));
        }
        (m, "zero" | "estimate") => {
            return Err(invalid(format!(
                "unknown method {m:?}: use \"arx\" or \"oe\""
            )));
        }
        (_, s) => {
            return Err(invalid(format!(
                "unknown initial_state {s:?}: use \"zero\" or \"estimate\""
            )));
        }
    };
    let orders = match orders {
        Some(o) => OrderChoice::Given(o),
        None => OrderChoice::Selected {
            criterion: criterion(select, validation)?,
            max_order,
            delays,
        },
    };
    let site = match structure {
        "lti" => None,
        other => Some(Site::parse(other).ok_or_else(|| {
            invalid(format!(
                "unknown structure {other:?}: use \"lti\", \"output-feedback\" or \"input\""
            ))
        })?),
    };
    let map = match site {
        Some(site) => Some(MapRequest {
            site,
            name: map.to_string(),
            kind: dispersion.parse().map_err(error)?,
            trend,
            separate_numerator,
        }),
        None if separate_numerator => {
            return Err(invalid(
                "separate_numerator applies to structure=\"output-feedback\" only",
            ));
        }
        None => None,
    };
    let request = LinearRequest {
        records,
        inputs,
        output: output.unwrap_or_else(|| "y".into()),
        orders,
        method,
        integrators,
        transient,
        sample_time,
        map,
    };
    let f = py
        .detach(|| fit_linear(&request, &|_, _| {}))
        .map_err(error)?;
    let out = PyDict::new(py);
    out.set_item("num", f.model.num.clone())?;
    out.set_item("den", vector(py, f.model.den.clone()))?;
    out.set_item("sample_time", f.model.sample_time)?;
    out.set_item(
        "orders",
        (f.orders.na, f.orders.nb.clone(), f.orders.nk.clone()),
    )?;
    out.set_item("selection", f.selection.clone())?;
    out.set_item("cost", f.cost)?;
    out.set_item("parameter_std", vector(py, f.parameter_std))?;
    out.set_item(
        "covariance",
        f.covariance.map(|c| {
            (0..c.nrows())
                .map(|i| c.row(i).iter().copied().collect::<Vec<f64>>())
                .collect::<Vec<_>>()
        }),
    )?;
    out.set_item("iterations", f.iterations)?;
    out.set_item("converged", f.converged)?;
    out.set_item("warning", f.warning.as_ref().map(ToString::to_string))?;
    out.set_item("fit_percent", f.fit_percent)?;
    out.set_item("toml", f.model_file.to_toml_string())?;
    Ok(out)
}

/// One record (u, y) with y one channel, its values finite and as long as u.
fn pair(
    u: &PyReadonlyArray2<'_, f64>,
    y: &PyReadonlyArray1<'_, f64>,
    u_name: &str,
    y_name: &str,
) -> PyResult<(Signal, Signal)> {
    let us = signal(u, u_name)?;
    let yv: Vec<f64> = y.as_array().iter().copied().collect();
    if let Some((k, x)) = yv.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        return Err(invalid(format!(
            "{y_name} has the non-finite value {x} at sample {k}"
        )));
    }
    if yv.len() != us.len() {
        return Err(invalid(format!(
            "{u_name} has {} samples and {y_name} has {}",
            us.len(),
            yv.len()
        )));
    }
    Ok((us, Signal::new(1, yv).map_err(error)?))
}

/// The order-selection criterion named `select`; `validation` is its record for
/// `"validation"`.
fn criterion(
    select: &str,
    validation: Option<(PyReadonlyArray2<'_, f64>, PyReadonlyArray1<'_, f64>)>,
) -> PyResult<OrderCriterion> {
    Ok(match (select, validation) {
        ("aic", None) => OrderCriterion::Aic,
        ("bic", None) => OrderCriterion::Bic,
        ("fpe", None) => OrderCriterion::Fpe,
        ("validation", Some((u, y))) => {
            let (u, y) = pair(&u, &y, "the validation u", "the validation y")?;
            OrderCriterion::Validation { u, y }
        }
        ("validation", None) | ("aic" | "bic" | "fpe", Some(_)) => {
            return Err(invalid(
                "select=\"validation\" and validation=(u, y) go together",
            ));
        }
        (other, _) => {
            return Err(invalid(format!(
                "unknown select {other:?}: use \"aic\", \"bic\", \"fpe\" or \"validation\""
            )));
        }
    })
}

/// The responses of G = `num[input]`/`den`: the Bode magnitude and unwrapped phase at the
/// normalised `frequencies` (cycles per sample, 0 … 0.5) with the magnitude's standard
/// deviation when the parameter covariance is given, the step response over `steps` samples,
/// and the poles and zeros as (re, im) pairs.
#[pyfunction]
#[pyo3(signature = (num, den, frequencies, steps, input=0, covariance=None, sample_time=None))]
pub fn linear_response<'py>(
    py: Python<'py>,
    num: Vec<Vec<f64>>,
    den: Vec<f64>,
    frequencies: Vec<f64>,
    steps: usize,
    input: usize,
    covariance: Option<Vec<Vec<f64>>>,
    sample_time: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let model = PolynomialModel::new(num, den, sample_time).map_err(error)?;
    if let Some(f) = frequencies
        .iter()
        .find(|f| !(f.is_finite() && (0.0..=0.5).contains(*f)))
    {
        return Err(invalid(format!(
            "frequency {f} is not a normalised frequency in 0 … 0.5 cycles per sample"
        )));
    }
    let cov = match covariance {
        None => None,
        Some(rows) => {
            let n = rows.len();
            if rows.iter().any(|r| r.len() != n) {
                return Err(invalid("the covariance must be a square matrix"));
            }
            Some(DMatrix::from_fn(n, n, |i, j| rows[i][j]))
        }
    };
    let points = bode(&model, input, &frequencies, cov.as_ref()).map_err(error)?;
    let step = step_response(&model, input, steps).map_err(error)?;
    let out = PyDict::new(py);
    out.set_item(
        "magnitude",
        vector(py, points.iter().map(|p| p.magnitude).collect()),
    )?;
    out.set_item(
        "phase",
        vector(py, points.iter().map(|p| p.phase).collect()),
    )?;
    out.set_item(
        "magnitude_std",
        cov.is_some()
            .then(|| vector(py, points.iter().filter_map(|p| p.magnitude_std).collect())),
    )?;
    out.set_item("step", vector(py, step))?;
    out.set_item("poles", poles(&model))?;
    out.set_item("zeros", zeros(&model, input))?;
    Ok(out)
}

//! Every conversion between Python and the library in one place: errors, arrays, records,
//! settings and dispersion specifications.

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyDictMethods};
use structid_core::{Data, InitialState, Signal, SolverChoice};
use structid_io::{DispersionSpec, ErrorChain, ModelFile};

// Named `structid.StructidError`, the name users import it under.
pyo3::create_exception!(
    structid,
    StructidError,
    pyo3::exceptions::PyValueError,
    "An error of the structid library: bad input, a model that cannot be identified as posed, \
     or a numerical failure. The message is the library's, with its causes."
);

/// The library error as a Python `StructidError`, its causes on further lines (as the
/// command-line tool prints them), and the function to try instead when the error says which.
pub fn error(e: impl std::error::Error + 'static) -> PyErr {
    let mut message = ErrorChain(&e).to_string();
    if let Some(hint) = structid_workflow::remedy(&e).and_then(hint) {
        message.push_str("\nhint: ");
        message.push_str(hint);
    }
    StructidError::new_err(message)
}

/// How the Python package words a library's remedy.
fn hint(r: structid_workflow::Remedy) -> Option<&'static str> {
    use structid_workflow::Remedy;
    match r {
        Remedy::JointFit => Some(
            "`structid.refine_joint` fits maps in series and latent blocks by simulation error",
        ),
        Remedy::LinearNominal => Some(
            "estimate a nominal model from the data with `structid.linear` (`integrators=N` \
             for a plant that integrates)",
        ),
        _ => None,
    }
}

/// A `StructidError` with a message of the bindings themselves.
pub fn invalid(message: impl Into<String>) -> PyErr {
    StructidError::new_err(message.into())
}

/// A `Signal` (L × channels) from an L × n array; non-finite values are refused with
/// `what` and the sample.
pub fn signal(a: &PyReadonlyArray2<'_, f64>, what: &str) -> PyResult<Signal> {
    let v = a.as_array();
    let (len, channels) = v.dim();
    let mut data = Vec::with_capacity(len * channels);
    for (k, row) in v.rows().into_iter().enumerate() {
        for (c, x) in row.iter().enumerate() {
            if !x.is_finite() {
                return Err(invalid(format!(
                    "{what} has the non-finite value {x} at sample {k}, channel {c}"
                )));
            }
            data.push(*x);
        }
    }
    Signal::new(channels, data).map_err(error)
}

/// A signal as an L × n numpy array.
pub fn array<'py>(py: Python<'py>, s: &Signal) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_vec((s.len(), s.channels()), s.as_slice().to_vec())
        .expect("a signal is len × channels values")
        .into_pyarray(py)
}

/// A vector as a 1-D numpy array.
pub fn vector<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyArray1<f64>> {
    v.into_pyarray(py)
}

/// The record a model file's `[signals]` names, from named columns, with the checks and
/// messages of a data table ([`DataTable::new`], then [`ModelFile::select_data`]) in one pass
/// over the samples: at L = 10⁶ the table's own copies would cost a tenth of a feature solve.
pub fn record(mf: &ModelFile, mut named: Vec<(String, Vec<f64>)>) -> PyResult<Data> {
    let len = named.first().map_or(0, |(_, c)| c.len());
    for (name, col) in &named {
        if col.len() != len {
            return Err(invalid(format!(
                "column `{name}` has {} values but column `{}` has {len}",
                col.len(),
                named[0].0
            )));
        }
        if let Some(k) = col.iter().position(|v| !v.is_finite()) {
            return Err(invalid(format!(
                "column `{name}` has the non-finite value {} in row {k}",
                col[k]
            )));
        }
    }
    let signals = &mf.signals;
    let uses = |n: &String| {
        signals
            .u
            .iter()
            .chain(&signals.y)
            .chain(signals.z.iter().flatten())
            .filter(|m| *m == n)
            .count()
    };
    let mut select = |names: &[String]| -> PyResult<Signal> {
        let index = names
            .iter()
            .map(|n| {
                named
                    .iter()
                    .position(|(m, _)| m == n)
                    .ok_or_else(|| invalid(format!("no column `{n}` among the data given")))
            })
            .collect::<PyResult<Vec<_>>>()?;
        match index.as_slice() {
            [] => Ok(Signal::zeros(len, 0)),
            // One channel is its column as it is: no copy unless another signal reads it too.
            [i] if uses(&named[*i].0) == 1 => {
                Signal::new(1, std::mem::take(&mut named[*i].1)).map_err(error)
            }
            _ => {
                let mut out = Vec::with_capacity(len * index.len());
                for k in 0..len {
                    out.extend(index.iter().map(|&i| named[i].1[k]));
                }
                Signal::new(index.len(), out).map_err(error)
            }
        }
    };
    let u = select(&signals.u)?;
    let y = select(&signals.y)?;
    let data = Data::new(u, y).map_err(error)?;
    match &signals.z {
        Some(z) => data.with_z(select(z)?).map_err(error),
        None => Ok(data),
    }
}

/// A signal as an L × n numpy array, without copying its samples.
pub fn into_array(py: Python<'_>, s: Signal) -> Bound<'_, PyArray2<f64>> {
    let shape = (s.len(), s.channels());
    Array2::from_shape_vec(shape, s.into_vec())
        .expect("a signal is len × channels values")
        .into_pyarray(py)
}

/// `zero` or `estimate`.
pub fn initial_state(name: &str) -> PyResult<InitialState> {
    match name {
        "zero" => Ok(InitialState::Zero),
        "estimate" => Ok(InitialState::Estimate),
        other => Err(invalid(format!(
            "initial_state `{other}` is neither `zero` nor `estimate`"
        ))),
    }
}

/// `auto`, `exact`, `features`, `clarabel` or `admm`.
pub fn solver(name: &str) -> PyResult<SolverChoice> {
    SolverChoice::from_name(name).ok_or_else(|| {
        invalid(format!(
            "solver `{name}` is not one of auto, exact, features, clarabel, admm"
        ))
    })
}

fn opt<'py, T: FromPyObjectOwned<'py>>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Option<T>> {
    match d.get_item(key)? {
        Some(v) if !v.is_none() => Ok(Some(v.extract().map_err(Into::into)?)),
        _ => Ok(None),
    }
}

/// A dispersion from its dictionary form, the keys of a model file's `dispersion` table:
/// `{"kind": "gaussian", "sigma": 0.3}`, `{"kind": "fourier", "harmonics": 20}`,
/// `{"kind": "tv", "neighbours": 8}`, `{"kind": "gaussian", "trend": 1}`, ….
pub fn dispersion(d: &Bound<'_, PyDict>) -> PyResult<DispersionSpec> {
    let kind: String = opt(d, "kind")?.ok_or_else(|| invalid("a dispersion needs a `kind`"))?;
    let sigma: Option<f64> = opt(d, "sigma")?;
    if let Some(s) = sigma
        && !(s.is_finite() && s > 0.0)
    {
        return Err(invalid(format!(
            "invalid sigma {s}: it must be a finite number greater than zero"
        )));
    }
    let spec = match kind.as_str() {
        "gaussian" => DispersionSpec::Gaussian { sigma },
        "gaussian-lowrank" => DispersionSpec::LowRankGaussian {
            sigma,
            tolerance: opt(d, "tolerance")?,
        },
        "fourier" => DispersionSpec::Fourier {
            sigma,
            harmonics: opt(d, "harmonics")?,
            additive: opt(d, "additive")?.unwrap_or(false),
        },
        "polynomial" => DispersionSpec::Polynomial {
            degree: opt(d, "degree")?
                .ok_or_else(|| invalid("a polynomial dispersion needs a `degree`"))?,
            scale: opt(d, "scale")?,
        },
        "tv" => DispersionSpec::TotalVariation {
            neighbours: opt(d, "neighbours")?,
            interpolation: match opt::<String>(d, "interpolation")?.as_deref() {
                None => None,
                Some("nearest") => Some(structid_core::GraphInterpolation::Nearest),
                Some("inverse-distance") => {
                    Some(structid_core::GraphInterpolation::InverseDistance)
                }
                Some(other) => {
                    return Err(invalid(format!(
                        "interpolation `{other}` is neither `nearest` nor `inverse-distance`"
                    )));
                }
            },
        },
        other => {
            return Err(invalid(format!(
                "dispersion kind `{other}` is not one of {}",
                structid_io::SUPPORTED_DISPERSIONS.join(", ")
            )));
        }
    };
    Ok(match opt::<usize>(d, "trend")? {
        Some(degree) => DispersionSpec::WithTrend {
            kernel: Box::new(spec),
            degree,
            scale: opt(d, "trend_scale")?,
        },
        None => spec,
    })
}

/// A serialisable value as JSON text (Python reads it with `json.loads`).
pub fn json<T: serde::Serialize + ?Sized>(value: &T) -> PyResult<String> {
    serde_json::to_string(value).map_err(|e| invalid(format!("cannot serialise: {e}")))
}

/// A block's dictionary with its `name`, z `inputs` and w `output`; the caller adds the rest.
pub(crate) fn block_dict<'py>(
    py: Python<'py>,
    name: &str,
    inputs: &[usize],
    output: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", name)?;
    d.set_item("inputs", inputs.to_vec())?;
    d.set_item("output", output)?;
    Ok(d)
}

//! Input design: the signals of `structid input` (`structid_input`).

use numpy::PyArray1;
use pyo3::prelude::*;
use structid_input::{Design, Kind, Lines, Sweep, generate};

use crate::convert::{error, invalid, vector};

/// Designs one input signal (`structid input KIND`): `length` samples as a 1-D array.
#[pyfunction]
#[pyo3(signature = (kind_name, length, sample_time=1.0, amplitude=1.0, offset=0.0, band=None,
                    seed=1, order=None, clock=None, period=None, lines=None, odd=false,
                    minimise_crest=false, sweep="linear", hold=(1, 10)))]
pub fn design_input<'py>(
    py: Python<'py>,
    kind_name: &str,
    length: usize,
    sample_time: f64,
    amplitude: f64,
    offset: f64,
    band: Option<(f64, f64)>,
    seed: u64,
    order: Option<u32>,
    clock: Option<usize>,
    period: Option<usize>,
    lines: Option<Vec<usize>>,
    odd: bool,
    minimise_crest: bool,
    sweep: &str,
    hold: (usize, usize),
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let kind = match kind_name {
        "prbs" => Kind::Prbs { order, clock },
        "multisine" => Kind::Multisine {
            period,
            lines: match (lines, odd) {
                (Some(_), true) => {
                    return Err(invalid(
                        "give either lines or odd=True for a multisine, not both",
                    ));
                }
                (Some(l), false) => Lines::Chosen(l),
                (None, true) => Lines::Odd,
                (None, false) => Lines::All,
            },
            minimise_crest,
        },
        "noise" => Kind::Noise,
        "chirp" => Kind::Chirp {
            sweep: match sweep {
                "linear" => Sweep::Linear,
                "logarithmic" | "log" => Sweep::Logarithmic,
                other => {
                    return Err(invalid(format!(
                        "unknown sweep `{other}`: give `linear` or `logarithmic`"
                    )));
                }
            },
        },
        "steps" => Kind::Steps {
            min_hold: hold.0,
            max_hold: hold.1,
        },
        other => {
            return Err(invalid(format!(
                "unknown input kind `{other}`: give prbs, multisine, noise, chirp or steps"
            )));
        }
    };
    let design = Design {
        length,
        sample_time,
        amplitude,
        offset,
        band,
        seed,
    };
    let u = py.detach(move || generate(&design, &kind)).map_err(error)?;
    Ok(vector(py, u))
}

/// The crest factor max |x − x̄| / RMS(x − x̄) of a signal.
#[pyfunction]
pub fn crest_factor(x: Vec<f64>) -> f64 {
    structid_input::crest_factor(&x)
}

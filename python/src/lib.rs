//! `structid._structid`: the native module of the Python package `structid`.
//!
//! A thin layer over the library: one module per concept ([`model`], [`identify`],
//! [`estimate`], [`linear`], [`refine`], [`discover`], [`staticness`], [`design`], [`paper`], [`user_kernel`]), every conversion between Python and Rust in [`convert`]. Long calls release
//! the GIL (`Python::detach`). The Python package (`structid/__init__.py`) turns the
//! dictionaries returned here into dataclasses.

mod convert;
mod design;
mod discover;
mod estimate;
mod identify;
mod joint;
mod linear;
mod model;
mod paper;
mod refine;
mod staticness;
mod user_kernel;

use pyo3::prelude::*;

/// The native module.
#[pymodule]
fn _structid(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("StructidError", m.py().get_type::<convert::StructidError>())?;
    m.add_class::<model::Model>()?;
    m.add_class::<estimate::Fitted>()?;
    m.add_class::<user_kernel::PyKernel>()?;
    m.add_class::<user_kernel::PyFeatures>()?;
    m.add_function(wrap_pyfunction!(identify::identify_columns, m)?)?;
    m.add_function(wrap_pyfunction!(refine::refine_columns, m)?)?;
    m.add_function(wrap_pyfunction!(joint::refine_joint_columns, m)?)?;
    m.add_function(wrap_pyfunction!(joint::wiener_hammerstein_records, m)?)?;
    m.add_function(wrap_pyfunction!(discover::discover_columns, m)?)?;
    m.add_function(wrap_pyfunction!(discover::silverbox_discovery, m)?)?;
    m.add_function(wrap_pyfunction!(staticness::staticness_columns, m)?)?;
    m.add_function(wrap_pyfunction!(design::design_input, m)?)?;
    m.add_function(wrap_pyfunction!(design::crest_factor, m)?)?;
    m.add_function(wrap_pyfunction!(paper::spray, m)?)?;
    m.add_function(wrap_pyfunction!(paper::multi_input, m)?)?;
    m.add_function(wrap_pyfunction!(paper::hammerstein_coloured, m)?)?;
    m.add_function(wrap_pyfunction!(estimate::write_result, m)?)?;
    m.add_function(wrap_pyfunction!(estimate::read_columns, m)?)?;
    m.add_function(wrap_pyfunction!(linear::linear_fit, m)?)?;
    m.add_function(wrap_pyfunction!(linear::linear_response, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}

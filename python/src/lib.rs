//! `cdm._cdm`, the native half of the `cdm` Python package: scenarios, the pre-flight
//! certificate, the in-process simulation and the fleet exports, each computed by the crates the
//! `orchestrator` CLI calls, so a number read in Python is the CLI's number, bit for bit. The
//! pure-Python half (`python/cdm/__init__.py`) turns what this module returns into NumPy arrays
//! and dictionaries.

mod certificate;
mod errors;
mod export;
mod flight;
mod scenario;

use pyo3::prelude::*;

#[pymodule]
fn _cdm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<scenario::PyScenario>()?;
    m.add_class::<certificate::PyCertificate>()?;
    m.add_class::<certificate::PyPhase>()?;
    m.add_class::<certificate::PyClearance>()?;
    m.add_class::<certificate::PyAirspace>()?;
    m.add_function(wrap_pyfunction!(scenario::load, m)?)?;
    m.add_function(wrap_pyfunction!(scenario::parse, m)?)?;
    m.add_function(wrap_pyfunction!(certificate::plan, m)?)?;
    m.add_function(wrap_pyfunction!(certificate::deviation_at, m)?)?;
    m.add_function(wrap_pyfunction!(flight::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(flight::read_telemetry, m)?)?;
    m.add_function(wrap_pyfunction!(export::export, m)?)?;
    Ok(())
}

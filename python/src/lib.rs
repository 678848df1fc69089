//! `ftcbf._ftcbf`: the Python extension module over the ftcbf libraries (issue #34).
//!
//! - `world::World`: a world file loaded with overrides, and `check()`'s structured verdict;
//! - `sim::Simulation`: the closed loop of `ftcbf_sim::runner::Simulation`, stepped from
//!   Python, with a built-in controller or a control law written in Python (`law`);
//! - `batch::batch`: `ftcbf batch` (the same plan, runner, numbers and report), run with the
//!   GIL released.
//!
//! Errors are Python exceptions whose message is what the CLI prints after `error: `.

mod batch;
mod errors;
mod law;
mod sim;
mod world;

use pyo3::prelude::*;

/// Turns a JSON text (a serde value) into Python objects with `json.loads`, so a summary holds
/// exactly the fields and numbers `ftcbf run --json` / `ftcbf batch --out F.json` write.
pub(crate) fn json_to_py<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (text,))
}

#[pymodule]
fn _ftcbf(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("Error", py.get_type::<errors::Error>())?;
    m.add("WorldError", py.get_type::<errors::WorldError>())?;
    m.add("ControlLawError", py.get_type::<errors::ControlLawError>())?;
    m.add_class::<world::World>()?;
    m.add_class::<sim::Simulation>()?;
    m.add_class::<sim::Frame>()?;
    m.add_class::<law::Readings>()?;
    m.add_class::<law::LawConfig>()?;
    m.add_function(wrap_pyfunction!(batch::batch, m)?)?;
    m.add("CONTROLLERS", ftcbf_lab::trials::CONTROLLERS)?;
    Ok(())
}

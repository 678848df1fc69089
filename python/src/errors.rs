//! Rust errors as Python exceptions, with the CLI's messages and its classification: what the
//! CLI reports as an invalid world (exit 2) raises [`WorldError`], an option out of range
//! `ValueError`, anything else [`Error`].

use ftcbf_sim::runner::RunError;
use ftcbf_sim::world::WorldError as WorldFileError;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;

pyo3::create_exception!(
    ftcbf,
    Error,
    PyException,
    "An error of ftcbf; the message is what the `ftcbf` command prints after `error: `."
);
pyo3::create_exception!(
    ftcbf,
    WorldError,
    Error,
    "An invalid world file (the CLI's exit code 2): the message names the file, the key or line, \
     and what was expected."
);
pyo3::create_exception!(
    ftcbf,
    ControlLawError,
    Error,
    "A control law written in Python raised, or returned something that is not an input \
     (a_x, a_y); the law's own exception is the __cause__."
);

/// The CLI's context line for an invalid world.
const INVALID: &str = "invalid world file";

/// A world file that did not load.
pub fn world_error(e: WorldFileError) -> PyErr {
    chain_error(&anyhow::Error::new(e).context(INVALID))
}

/// A run that could not start: an option out of range (`ValueError`), or a world that does not
/// fit the controller or plant (`WorldError`, as `ftcbf run` and `check` report it).
pub fn run_error(e: RunError) -> PyErr {
    match e {
        RunError::Option(message) => PyValueError::new_err(message),
        e => chain_error(&anyhow::Error::new(e).context(INVALID)),
    }
}

/// A command's error chain (`{:#}`, as the CLI prints it): [`WorldError`] when an invalid world
/// is anywhere in it.
pub fn chain_error(e: &anyhow::Error) -> PyErr {
    let text = format!("{e:#}");
    let invalid = e.chain().any(|c| {
        c.is::<WorldFileError>()
            || c.downcast_ref::<RunError>()
                .is_some_and(RunError::is_invalid_world)
    });
    if invalid {
        WorldError::new_err(text)
    } else {
        Error::new_err(text)
    }
}

//! A world compiled for running and for analysis, derived once from a validated
//! [`World`](crate::world::World): the controller's configuration (channels, noise and the
//! drive's identified process noise q with its on-disk cache, barriers, gains, the planned path,
//! γ, θ and η), in [`CompiledWorld`]. The runner ([`crate::runner`]) and the analyses
//! ([`crate::analysis`]) read it; it reads only the world and the modules below it.

mod compiled;
pub mod identify;
pub mod setup;

pub use compiled::{CompiledWorld, Source};
pub use setup::setups_computed;

/// Why a run could not be carried out (the world itself was valid).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The world does not fit the controller or plant.
    #[error("{world}: `{key}`: {message}")]
    Setup {
        /// World file.
        world: String,
        /// Key path.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// A component refused to start.
    #[error("{world}: {what}: {message}")]
    Start {
        /// World file.
        world: String,
        /// Component.
        what: &'static str,
        /// Its error.
        message: String,
    },
    /// A run option is out of range.
    #[error("{0}")]
    Option(String),
}

impl RunError {
    /// Whether it says the world does not fit the controller or plant (a world `check` and
    /// `run` both refuse: the CLI's exit 2), as opposed to a run option out of range.
    pub fn is_invalid_world(&self) -> bool {
        matches!(self, RunError::Setup { .. } | RunError::Start { .. })
    }
}

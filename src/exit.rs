//! Exit codes in one place: every command's error becomes a [`Failure`] with the code it maps
//! to here (book: Reference → Exit codes).

use ftcbf_lab::batch;
use ftcbf_sim::runner::RunError;
use ftcbf_sim::world::WorldError;

/// Exit code: a world file is invalid.
pub const EXIT_INVALID: u8 = 2;
/// Exit code: a run did not meet its world's `[expect]`.
pub const EXIT_EXPECTATION: u8 = 3;
/// Exit code: a verdict failed: `check --strict` and Theorem 3 does not apply to the world, or a
/// batch verdict matched `ftcbf batch --fail-on`.
pub const EXIT_VERDICT: u8 = 4;

/// Exit code: the command line itself is wrong (clap's usage errors, a malformed `--set`, an
/// option value out of range). Distinct from an invalid world (2); sysexits' EX_USAGE.
pub const EXIT_USAGE: u8 = 64;
/// Exit code: an internal error — a panic inside the simulator or a dependency, contained and
/// reported instead of aborting with Rust's 101; sysexits' EX_SOFTWARE.
pub const EXIT_INTERNAL: u8 = 70;

/// An error with the exit code it maps to.
pub struct Failure {
    /// The process exit code.
    pub code: u8,
    /// What went wrong, with its context chain.
    pub error: anyhow::Error,
}

impl From<anyhow::Error> for Failure {
    fn from(error: anyhow::Error) -> Self {
        Failure { code: 1, error }
    }
}

/// An invalid world file (exit 2).
pub fn invalid(e: WorldError) -> Failure {
    Failure {
        code: EXIT_INVALID,
        error: anyhow::Error::new(e).context("invalid world file"),
    }
}

/// A run error as a failure: an invalid world exits 2, an option out of range 64.
pub fn run_failure(e: RunError, what: &'static str) -> Failure {
    let code = match &e {
        RunError::Option(_) => EXIT_USAGE,
        e if e.is_invalid_world() => EXIT_INVALID,
        _ => 1,
    };
    let context = if code == EXIT_INVALID {
        "invalid world file"
    } else {
        what
    };
    Failure {
        code,
        error: anyhow::Error::new(e).context(context),
    }
}

/// The exit code of a command's error chain: an invalid world anywhere in it exits 2.
pub fn code_of(e: &anyhow::Error) -> u8 {
    if e.is::<batch::VerdictFailure>() {
        EXIT_VERDICT
    } else if e.chain().any(|c| {
        c.is::<WorldError>()
            || c.downcast_ref::<RunError>()
                .is_some_and(RunError::is_invalid_world)
    }) {
        EXIT_INVALID
    } else {
        1
    }
}

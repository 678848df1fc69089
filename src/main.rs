//! `ftcbf` — the command-line front end: a thin binary over `ftcbf-lab` and `ftcbf-sim`
//! (ripgrep style): `args` parses, `dispatch` runs one command, `exit` maps every outcome to
//! its exit code, and `main` contains panics.

// The commands' doc comments are their `--help` text (clap derive), written for a terminal:
// `[expect]`, `attacks[0]` and `<world>` are text there, not links or HTML. Since the package has no
// library of the same name any more, `cargo doc` documents this binary too.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

mod args;
mod bars;
mod commands;
mod exit;
mod parsers;

use std::process::ExitCode;

use clap::Parser;

use ftcbf_lab::trials::prepare_batch;

use args::{Cli, Command};
use commands::{batch, check, falsify, gen, regress, report, run};
use exit::{code_of, Failure, EXIT_INTERNAL, EXIT_USAGE};

/// The test hook of the exit-70 path: `FTCBF_TEST_PANIC=main` panics on the main thread inside
/// the command, `FTCBF_TEST_PANIC=worker` in a worker thread of the pool that `batch`,
/// `regress` and `falsify` run their trials on (rayon carries the panic back to the command). It
/// lets `tests/reliability.rs` check what a user sees on a real bug, since no input is known to
/// panic any more. Documented in the book (Development: tests); unset, it does nothing.
const TEST_PANIC_VAR: &str = "FTCBF_TEST_PANIC";

fn test_panic_hook() {
    match std::env::var(TEST_PANIC_VAR).as_deref() {
        Ok("main") => panic!("{TEST_PANIC_VAR}=main: a panic injected to test the exit-70 path"),
        Ok("worker") => {
            use rayon::prelude::*;
            (0..4u32).into_par_iter().for_each(|i| {
                if i == 3 {
                    panic!("{TEST_PANIC_VAR}=worker: a panic injected to test the exit-70 path");
                }
            });
        }
        _ => {}
    }
}

fn dispatch(command: Command) -> Result<(), Failure> {
    test_panic_hook();
    match command {
        Command::Run(a) => run::command(&a),
        Command::Check(a) => check::command(&a),
        Command::Regress(a) => regress::command(&a),
        Command::Batch(a) => batch::command(&a, &prepare_batch(&a.world)).map_err(|e| Failure {
            code: code_of(&e),
            error: e,
        }),
        Command::Merge(a) => batch::merge(&a).map_err(Failure::from),
        Command::Falsify(a) => falsify::command(&a).map_err(|e| Failure {
            code: if e.is::<falsify::UsageError>() {
                EXIT_USAGE
            } else {
                code_of(&e)
            },
            error: e,
        }),
        Command::Gen(a) => gen::command(&a).map_err(Failure::from),
        Command::Report(a) => report::command(&a).map_err(Failure::from),
    }
}

/// The message and place of the last panic, kept by the hook for the error line.
static PANIC: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

/// Restores the default action of SIGPIPE, which Rust's runtime ignores: when the reader of
/// `ftcbf`'s output goes away (`ftcbf check W | head -1`), the process ends as `cat` or `grep`
/// do, killed by the signal (the shell's status 141), instead of `println!` panicking on the
/// broken pipe and the panic being reported as an internal error (exit 70).
fn default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: `signal` with SIG_DFL installs no handler code; called once, first thing in main,
    // before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() -> ExitCode {
    default_sigpipe();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // --help and --version print to stdout and succeed; usage errors exit 64.
            let code = if e.use_stderr() { EXIT_USAGE } else { 0 };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    // A panic anywhere below (the simulator, parry, rapier, a worker thread of a batch) is
    // contained: the hook keeps its message instead of printing Rust's, and the command ends
    // with a typed internal error and exit 70, never 101 or an abort.
    std::panic::set_hook(Box::new(|info| {
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic payload".to_string());
        let place = info
            .location()
            .map_or(String::new(), |l| format!(" at {}:{}", l.file(), l.line()));
        if let Ok(mut slot) = PANIC.lock() {
            slot.get_or_insert(format!("{msg}{place}"));
        }
    }));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| dispatch(cli.command)))
        .unwrap_or_else(|_| {
            let what = PANIC
                .lock()
                .ok()
                .and_then(|s| s.clone())
                .unwrap_or_else(|| "unknown panic".to_string());
            Err(Failure {
                code: EXIT_INTERNAL,
                error: anyhow::anyhow!(
                    "internal error: the simulation stopped on a panic ({what}); this is a bug \
                     — please report it with the world file and command line"
                ),
            })
        });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("error: {:#}", f.error);
            ExitCode::from(f.code)
        }
    }
}

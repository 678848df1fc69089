//! Helpers shared by the tests that drive the `ftcbf` binary as a user does.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::PathBuf;
use std::process::{Command, Output};

/// The package root (where `worlds/` and `tests/` are).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs the `ftcbf` binary with `args` from the package root.
pub fn ftcbf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ftcbf"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("the binary runs")
}

/// stdout then stderr, as one string.
pub fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A path named `name` in a per-process temporary directory `ftcbf-<tag>-<pid>`.
pub fn tmp_in(tag: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ftcbf-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temp dir");
    d.join(name)
}

/// Runs every case of a regression `plan` (the library call behind `ftcbf regress`) and fails
/// with each failing case's world, controller and failures.
pub fn assert_plan_passes(plan: &ftcbf_lab::regress::Plan) {
    let results = plan
        .run(&ftcbf_lab::progress::Silent)
        .unwrap_or_else(|e| panic!("{e}"));
    let failures: Vec<String> = results
        .iter()
        .filter(|r| !r.passed())
        .map(|r| format!("{} / {}: {}", r.world, r.controller, r.failures.join("; ")))
        .collect();
    assert!(
        failures.is_empty(),
        "{} failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

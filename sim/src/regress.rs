//! Worlds as regression cases: run each controller a world's `[expect]` table names and compare.
//! `ftcbf regress` and the test suite both call [`check_world`].

use std::path::{Path, PathBuf};

use crate::runner::{run, RunError, RunOptions};
use crate::summary::RunSummary;
use crate::world::{ControllerKindSpec, ExpectOutcome, World};

/// One controller's run of one world, with its verdict.
#[derive(Debug, Clone)]
pub struct RegressionRow {
    /// World name.
    pub world: String,
    /// The run's summary.
    pub summary: RunSummary,
    /// What was expected.
    pub expected: ExpectOutcome,
    /// Failed expectations (empty = pass), each with the numbers behind it.
    pub failures: Vec<String>,
}

impl RegressionRow {
    /// All expectations held.
    pub fn passed(&self) -> bool {
        self.failures.is_empty()
    }
}

/// The expectations a world states for `kind` (None: not a case for that controller).
pub fn expectation_for(world: &World, kind: ControllerKindSpec) -> Option<ExpectOutcome> {
    let e = world.file.expect.as_ref()?;
    if kind == world.file.control.controller {
        return Some(e.own());
    }
    match kind {
        ControllerKindSpec::Baseline => e.baseline.clone(),
        ControllerKindSpec::Nominal => e.nominal.clone(),
        ControllerKindSpec::FtCbfClf => None,
    }
}

/// The controllers a world's `[expect]` covers: its own, then any comparison tables.
pub fn expected_controllers(world: &World) -> Vec<ControllerKindSpec> {
    [
        world.file.control.controller,
        ControllerKindSpec::FtCbfClf,
        ControllerKindSpec::Baseline,
        ControllerKindSpec::Nominal,
    ]
    .into_iter()
    .fold(Vec::new(), |mut acc, k| {
        if !acc.contains(&k) && expectation_for(world, k).is_some() {
            acc.push(k);
        }
        acc
    })
}

/// Runs `world` with `kind` at the world's seed and checks its expectations.
pub fn check_world(world: &World, kind: ControllerKindSpec) -> Result<RegressionRow, RunError> {
    let expected = expectation_for(world, kind).unwrap_or_default();
    let summary = run(
        world,
        &RunOptions {
            controller: Some(kind),
            ..RunOptions::default()
        },
    )?;
    Ok(RegressionRow {
        world: world.name.clone(),
        failures: expected.failures(&summary),
        expected,
        summary,
    })
}

/// World files named by `paths`: files as given, directories searched (not recursively) for
/// `*.toml`, sorted by path so the order is stable.
pub fn collect_world_files(paths: &[PathBuf]) -> std::io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|x| x == "toml"))
                .collect();
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

/// True when `path` holds a world with an `[expect]` table.
pub fn has_expectations(world: &World) -> bool {
    world.file.expect.is_some()
}

/// Convenience for tests: load `path` and check every controller it has expectations for.
pub fn check_file(path: &Path) -> Result<Vec<RegressionRow>, String> {
    let world = World::load(path, &[]).map_err(|e| e.to_string())?;
    expected_controllers(&world)
        .into_iter()
        .map(|k| check_world(&world, k).map_err(|e| e.to_string()))
        .collect()
}

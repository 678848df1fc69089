//! `ftcbf regress`: the world catalogue as a regression suite.
//!
//! Every world with an `[expect]` table is a case per controller it names (its own, then
//! `[expect.baseline]`, `[expect.nominal]`). Each case runs on the same `seeds = N` seeds:
//! [`regression_seeds`] — the world's seed, then the first N − 1 trial seeds `ftcbf batch` would
//! use with that base seed, so any failing seed re-runs with `ftcbf run --seed`. All runs of all
//! cases share one rayon pool; the verdicts ([`ftcbf_sim::analysis::expectations::failures`]) are pure functions
//! of the summaries, so the table does not depend on the number of threads.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;
use serde::Serialize;

use ftcbf_sim::analysis::expectations::{
    collect_world_files, expectation_for, expected_controllers, failures,
};
use ftcbf_sim::runner::{run, CompiledWorld, RunError, RunOptions};
use ftcbf_sim::summary::{RunSummary, METRICS};
use ftcbf_sim::world::{ControllerKindSpec, ExpectOutcome, World, WorldError};

use crate::batch::trial_seed;
use crate::progress::Progress;

/// Why a regression could not be judged (a failed expectation is not an error: see
/// [`CaseResult::failures`]).
#[derive(Debug, thiserror::Error)]
pub enum RegressError {
    /// A directory or file could not be listed.
    #[error("listing world files under {path}: {source}")]
    Io {
        /// The path given.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Nothing to run.
    #[error("no world files under {0}")]
    NoWorlds(String),
    /// A world file is invalid.
    #[error(transparent)]
    World(#[from] WorldError),
    /// A world's controller setup (γ, θ, η, barriers, CLF, path) could not be computed.
    #[error("{0}")]
    Setup(Box<RunError>),
    /// A run could not be set up or failed.
    #[error("{world} with {controller}, seed {seed}: {source}")]
    Run {
        /// World name.
        world: String,
        /// Controller name.
        controller: String,
        /// Seed.
        seed: u64,
        /// Cause (boxed: a run error is large).
        source: Box<RunError>,
    },
}

/// The seeds a world's expectations are judged over: the world's own seed, then
/// `trial_seed(seed, k)` for k = 0 … n − 2 (the first trials of `ftcbf batch` with that base).
pub fn regression_seeds(world_seed: u64, n: u32) -> Vec<u64> {
    std::iter::once(world_seed)
        .chain((0..u64::from(n.saturating_sub(1))).map(|k| trial_seed(world_seed, k)))
        .collect()
}

/// The seeds of `world`'s `[expect]` (just its seed without one).
pub fn world_seeds(world: &World) -> Vec<u64> {
    regression_seeds(
        world.file.seed,
        ftcbf_sim::analysis::expectations::seed_count(world),
    )
}

/// One controller on one world, over the world's regression seeds.
#[derive(Debug, Clone)]
pub struct Case {
    /// The world, compiled once for all its cases and seeds.
    pub world: Arc<CompiledWorld>,
    /// The controller.
    pub controller: ControllerKindSpec,
    /// What it must show.
    pub expected: ExpectOutcome,
    /// The seeds.
    pub seeds: Vec<u64>,
}

/// The cases of a set of world files (files, or directories searched for `*.toml`), and the
/// files skipped for having no `[expect]` table.
#[derive(Debug, Default)]
pub struct Plan {
    /// In file order, then controller order.
    pub cases: Vec<Case>,
    /// World files without `[expect]`.
    pub skipped: Vec<PathBuf>,
}

impl Plan {
    /// Loads every world file under `paths`.
    pub fn load(paths: &[PathBuf]) -> Result<Plan, RegressError> {
        let mut files = Vec::new();
        for p in paths {
            files.extend(
                collect_world_files(std::slice::from_ref(p)).map_err(|source| {
                    RegressError::Io {
                        path: p.clone(),
                        source,
                    }
                })?,
            );
        }
        if files.is_empty() {
            let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
            return Err(RegressError::NoWorlds(names.join(", ")));
        }
        let mut plan = Plan::default();
        for f in files {
            plan.add(&f)?;
        }
        Ok(plan)
    }

    fn add(&mut self, path: &Path) -> Result<(), RegressError> {
        let world = World::load(path, &[])?;
        let kinds = expected_controllers(&world);
        if kinds.is_empty() {
            self.skipped.push(path.to_path_buf());
            return Ok(());
        }
        let seeds = world_seeds(&world);
        let expected: Vec<_> = kinds
            .iter()
            .map(|&k| expectation_for(&world, k).unwrap_or_default())
            .collect();
        let world =
            Arc::new(CompiledWorld::new(world).map_err(|e| RegressError::Setup(Box::new(e)))?);
        for (k, expected) in kinds.into_iter().zip(expected) {
            self.cases.push(Case {
                world: world.clone(),
                controller: k,
                expected,
                seeds: seeds.clone(),
            });
        }
        Ok(())
    }

    /// Number of closed-loop runs the plan makes.
    pub fn runs(&self) -> usize {
        self.cases.iter().map(|c| c.seeds.len()).sum()
    }

    /// Runs every (case, seed) on the current rayon pool, telling `progress` of each run, and
    /// judges each case.
    pub fn run(&self, progress: &dyn Progress) -> Result<Vec<CaseResult>, RegressError> {
        let jobs: Vec<(usize, u64)> = self
            .cases
            .iter()
            .enumerate()
            .flat_map(|(i, c)| c.seeds.iter().map(move |&s| (i, s)))
            .collect();
        progress.start(jobs.len() as u64, "regress");
        let summaries: Result<Vec<RunSummary>, _> = jobs
            .par_iter()
            .map(|&(i, seed)| {
                let c = &self.cases[i];
                let opts = RunOptions {
                    seed: Some(seed),
                    controller: Some(c.controller),
                    duration: None,
                };
                let r = run(&*c.world, &opts).map_err(|source| RegressError::Run {
                    world: c.world.world().name.clone(),
                    controller: c.controller.name().to_string(),
                    seed,
                    source: Box::new(source),
                });
                progress.advance(1);
                r
            })
            .collect::<Result<_, _>>();
        progress.finish();
        let summaries = summaries?;
        let mut it = summaries.into_iter();
        Ok(self
            .cases
            .iter()
            .map(|c| {
                let runs: Vec<RunSummary> = it.by_ref().take(c.seeds.len()).collect();
                CaseResult {
                    world: c.world.world().name.clone(),
                    controller: c.controller.name().to_string(),
                    failures: failures(&c.expected, &runs),
                    expected: c.expected.clone(),
                    runs,
                }
            })
            .collect())
    }
}

/// One case's runs and verdict.
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    /// World name.
    pub world: String,
    /// Controller name.
    pub controller: String,
    /// What was expected.
    pub expected: ExpectOutcome,
    /// Failed expectations, each with the numbers behind it (empty = pass).
    pub failures: Vec<String>,
    /// One summary per seed, in seed order.
    pub runs: Vec<RunSummary>,
}

impl CaseResult {
    /// All expectations held.
    pub fn passed(&self) -> bool {
        self.failures.is_empty()
    }

    /// The verdict cell: pass or the failures; a case whose runs leave the declared fault model
    /// (attacks on more than one pattern, alone or together) says so, so that it never reads as
    /// a case the guarantee covers.
    pub fn verdict(&self) -> String {
        let v = if self.passed() {
            "pass".to_string()
        } else {
            format!("FAIL: {}", self.failures.join("; "))
        };
        if self.runs.iter().any(|s| s.attacks_outside_fault_patterns) {
            format!("{v} (outside the fault model: no guarantee applies)")
        } else {
            v
        }
    }

    fn count(&self, of: impl Fn(&RunSummary) -> bool) -> String {
        let n = self.runs.iter().filter(|s| of(s)).count();
        format!("{n}/{}", self.runs.len())
    }

    fn worst(&self, key: &str, lowest: bool) -> String {
        let Some(m) = METRICS.iter().find(|m| m.key == key) else {
            return "—".into();
        };
        let v = self
            .runs
            .iter()
            .filter_map(|s| (m.of)(s))
            .reduce(if lowest { f64::min } else { f64::max });
        v.map_or("—".into(), |v| format!("{v:.4}"))
    }
}

/// The table `ftcbf regress` prints: per case the seed counts, the worst seed's margins and the
/// verdict, then a total line.
pub fn table_text(results: &[CaseResult]) -> String {
    use crate::batch::{render_table, Align};
    use std::fmt::Write;
    let rows: Vec<Vec<String>> = results
        .iter()
        .map(|r| {
            vec![
                r.world.clone(),
                r.controller.clone(),
                r.count(|s| s.safe),
                r.count(|s| s.collided),
                r.count(|s| s.goal_reached),
                r.worst("min_h", true),
                r.worst("min_clearance", true),
                r.worst("time_to_goal", false),
                r.verdict(),
            ]
        })
        .collect();
    let (l, rt) = (Align::Left, Align::Right);
    let mut t = render_table(
        &[
            "world",
            "controller",
            "safe",
            "hit",
            "goal",
            "worst h",
            "worst clr[m]",
            "worst t[s]",
            "verdict",
        ],
        &[l, l, rt, rt, rt, rt, rt, rt, l],
        &rows,
    );
    let runs: usize = results.iter().map(|r| r.runs.len()).sum();
    let failed = results.iter().filter(|r| !r.passed()).count();
    let _ = write!(
        t,
        "{} case(s), {runs} run(s), {failed} failed",
        results.len()
    );
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_seed_is_the_worlds_then_batch_trial_seeds() {
        assert_eq!(regression_seeds(7, 1), vec![7]);
        assert_eq!(
            regression_seeds(7, 4),
            vec![7, trial_seed(7, 0), trial_seed(7, 1), trial_seed(7, 2)]
        );
    }
}

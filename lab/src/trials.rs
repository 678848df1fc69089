//! The closed-loop trial runner of one world file, shared by `ftcbf batch`, the examples and the
//! Python package: a [`WorldRunner`] runs the built-in controllers by name on a world compiled
//! once ([`CompiledWorld`]: γ, θ, η, barriers, CLF and planned path computed once for all its
//! trials and controllers), and [`prepare_batch`] loads and compiles a world (with a sweep
//! point's overrides) into the [`batch::PreparedWorld`] that [`batch::run_sweep`] runs.
//! [`check_rolled_out`] is `ftcbf check` with a world with movers rolled out: its liveness
//! verdict decided by runs of the closed loop ([`roll_out`]).

use std::path::Path;

use ftcbf_sim::analysis::check::{self, CheckReport};
use ftcbf_sim::analysis::liveness::rollout::{self, Rollouts, ROLLOUTS, ROLLOUT_SALT};
use ftcbf_sim::analysis::liveness::LivenessReport;
use ftcbf_sim::runner::{run, CompiledWorld, RunOptions};
use ftcbf_sim::summary::RunSummary;
use ftcbf_sim::world::{ControllerKindSpec, Override, Param, World};
use rayon::prelude::*;

use crate::batch;

/// The built-in controllers' names ([`ControllerKindSpec::NAMES`]; parse one with
/// `str::parse::<ControllerKindSpec>`).
pub const CONTROLLERS: [&str; 3] = ControllerKindSpec::NAMES;

/// The closed-loop runner of one compiled world with the built-in controllers: each trial
/// borrows the compiled model and builds only its own state (sensors, attacks, law, plant).
pub struct WorldRunner(pub CompiledWorld);

impl WorldRunner {
    /// Compiles `world` for its trials.
    pub fn new(world: World) -> anyhow::Result<Self> {
        let name = world.path.display().to_string();
        let compiled = CompiledWorld::new(world)
            .map_err(|e| anyhow::Error::new(e).context(format!("compiling {name}")))?;
        Ok(Self(compiled))
    }

    /// The world.
    pub fn world(&self) -> &World {
        self.0.world()
    }
}

impl batch::TrialRunner for WorldRunner {
    fn run_trial(&self, controller: &str, seed: u64) -> anyhow::Result<RunSummary> {
        Ok(run(&self.0, &trial_options(controller, seed)?)?)
    }
}

/// The run options of a batch trial: the built-in `controller` (one of [`CONTROLLERS`]) with
/// `seed`, for the world's duration.
pub fn trial_options(controller: &str, seed: u64) -> anyhow::Result<RunOptions> {
    Ok(RunOptions {
        seed: Some(seed),
        controller: Some(controller.parse::<ControllerKindSpec>()?),
        duration: None,
    })
}

/// A plan of `trials` trials of `world` (loaded from `path`) for `controllers`, from the
/// world's seed: unsharded, no sweep point, no claim (ε), no file digest and no check lines,
/// at the default confidence ([`batch::CONFIDENCE`]).
pub fn plan_for(
    world: &World,
    path: &Path,
    trials: u64,
    controllers: Vec<String>,
) -> batch::BatchPlan {
    batch::BatchPlan {
        world: world.name.clone(),
        world_file: path.display().to_string(),
        world_digest: String::new(),
        theorem3: None,
        liveness: None,
        overrides: Vec::new(),
        trials,
        base_seed: world.file.seed,
        controllers,
        shard: None,
        epsilon: None,
        confidence: batch::CONFIDENCE,
    }
}

/// The batch's view of a compiled world: its name, seed, the ε of its claim (when γ or θ is
/// derived from it) and `ftcbf check`'s Theorem 3 and liveness verdict lines.
pub fn world_info(compiled: &CompiledWorld) -> batch::WorldInfo {
    let world = compiled.world();
    let c = &world.file.control;
    let auto = matches!(c.gamma, Param::Auto) || matches!(c.theta, Param::Auto);
    let report = Some(check_rolled_out(compiled, ROLLOUTS));
    batch::WorldInfo {
        name: world.name.clone(),
        seed: world.file.seed,
        epsilon: auto.then_some(c.epsilon),
        theorem3: report.as_ref().map(|r| r.verdict.line()),
        liveness: report.as_ref().map(|r| r.liveness.line()),
    }
}

/// `check`'s report on `compiled` ([`check::check_compiled`]), with the liveness verdict of a
/// world with movers decided by `runs` runs of the closed loop ([`roll_out`]): what `ftcbf
/// check`, `ftcbf batch` and Python's `World.check` report. `check_world` and `check_compiled`
/// leave it to the search past the movers: the falsifier and `ftcbf gen` call them on every
/// candidate world, where runs would cost more than the search.
pub fn check_rolled_out(compiled: &CompiledWorld, runs: usize) -> CheckReport {
    let mut report = check::check_compiled(compiled);
    roll_out(compiled, &mut report.liveness, runs);
    report
}

/// Runs the closed loop `runs` times with the world's own controller, on the seeds
/// [`batch::trial_seed`]`(S ⊕` [`ROLLOUT_SALT`]`, k)` (S the world's seed: apart from `ftcbf
/// batch`'s trials; in parallel, the result does not depend on the number of threads), and puts
/// what they found in `report` ([`rollout`]), when [`rollout::applies`]; `runs = 0` leaves the
/// search's verdict.
pub fn roll_out(compiled: &CompiledWorld, report: &mut LivenessReport, runs: usize) {
    let world = compiled.world();
    if runs == 0 || !rollout::applies(world, report) {
        return;
    }
    let base_seed = world.file.seed ^ ROLLOUT_SALT;
    let outcomes: Vec<_> = (0..runs as u64)
        .into_par_iter()
        .map(|k| {
            let seed = batch::trial_seed(base_seed, k);
            let opts = RunOptions {
                seed: Some(seed),
                ..RunOptions::default()
            };
            run(compiled, &opts).map(|s| (seed, s.goal_settled, s.final_goal_distance))
        })
        .collect();
    let mut r = Rollouts {
        world: world.path.display().to_string(),
        controller: world.file.control.controller.name(),
        base_seed,
        runs,
        settled: 0,
        first_miss: None,
        error: None,
    };
    for o in outcomes {
        match o {
            Ok((_, true, _)) => r.settled += 1,
            Ok((seed, false, d)) => {
                r.first_miss.get_or_insert((seed, d));
            }
            Err(e) => {
                r.error.get_or_insert_with(|| e.to_string());
            }
        }
    }
    report.rollouts = Some(r);
}

/// What `ftcbf batch` runs for `path`: the world loaded with a [`batch::BatchSpec`]'s overrides
/// and each sweep point's and compiled once, its trials run by a [`WorldRunner`].
pub fn prepare_batch(
    path: &Path,
) -> impl Fn(&[Override]) -> anyhow::Result<batch::PreparedWorld> + '_ {
    move |overrides: &[Override]| {
        let runner = WorldRunner::new(World::load(path, overrides)?)?;
        Ok(batch::PreparedWorld {
            info: world_info(&runner.0),
            runner: Box::new(runner),
        })
    }
}

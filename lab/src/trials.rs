//! The closed-loop trial runner of one world file, shared by `ftcbf batch`, the examples and the
//! Python package: a [`WorldRunner`] runs the built-in controllers by name on a world compiled
//! once ([`CompiledWorld`]: γ, θ, η, barriers, CLF and planned path computed once for all its
//! trials and controllers), and [`prepare_batch`] loads and compiles a world (with a sweep
//! point's overrides) into the [`batch::PreparedWorld`] that [`batch::run_sweep`] runs.

use std::path::Path;

use ftcbf_sim::analysis::check;
use ftcbf_sim::runner::{run, CompiledWorld, RunOptions};
use ftcbf_sim::summary::RunSummary;
use ftcbf_sim::world::{ControllerKindSpec, Override, Param, World};

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
    let report = Some(check::check_compiled(compiled));
    batch::WorldInfo {
        name: world.name.clone(),
        seed: world.file.seed,
        epsilon: auto.then_some(c.epsilon),
        theorem3: report.as_ref().map(|r| r.verdict.line()),
        liveness: report.as_ref().map(|r| r.liveness.line()),
    }
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

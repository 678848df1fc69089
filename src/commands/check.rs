//! `ftcbf check`: the world validated and every hypothesis of the guarantee checked, with
//! the numbers, without simulating.

use std::path::PathBuf;

use ftcbf_sim::analysis::check;
use ftcbf_sim::runner::{preflight, CompiledWorld};
use ftcbf_sim::world::World;

use crate::exit::{invalid, run_failure, Failure, EXIT_VERDICT};

/// `ftcbf check`
#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// The world file (TOML).
    pub world: PathBuf,
    /// Exit with status 4 when Theorem 3 does not apply to the world (for CI).
    #[arg(long)]
    pub strict: bool,
    /// Also search for the smallest change of `[control] cbf_gain` and `input_limit` (one key,
    /// then both) that makes Theorem 3 apply and the path live, and print it as TOML (or say
    /// that none exists in the searched ranges, and why).
    #[arg(long)]
    pub suggest: bool,
    /// In a world with moving obstacles, run the closed loop this many times (seeded apart from
    /// `ftcbf batch`'s trials) and let the runs decide whether the robot settles past the movers;
    /// 0 leaves it to the search past the movers alone.
    #[arg(long, value_name = "N", default_value_t = ftcbf_sim::analysis::liveness::rollout::ROLLOUTS)]
    pub rollouts: usize,
}

/// `ftcbf check`.
pub fn command(a: &CheckArgs) -> Result<(), Failure> {
    let compiled = CompiledWorld::new(World::load(&a.world, &[]).map_err(invalid)?)
        .map_err(|e| run_failure(e, "controller setup"))?;
    let world = compiled.world();
    // Whatever `run` would refuse at its start, `check` refuses too, with the same exit code.
    preflight(&compiled).map_err(|e| run_failure(e, "controller setup"))?;
    println!("world {} ({})", world.name, world.path.display());
    if a.rollouts > 0 && world.has_movers() {
        eprintln!(
            "check: the world has movers: its liveness verdict runs the closed loop {} times where the rows leave the path live (--rollouts 0 skips them)",
            a.rollouts
        );
    }
    let report = ftcbf_lab::trials::check_rolled_out(&compiled, a.rollouts);
    println!("{report}");
    if let Some(r) = &world.robot {
        println!("drive: {}", r.wheels.describe());
    }
    for line in check::condition_4_4_lines(compiled.setup()) {
        println!("{line}");
    }
    if a.suggest {
        let s = check::suggest(world).map_err(|e| run_failure(e, "controller setup"))?;
        println!("{s}");
    }
    if a.strict && !report.verdict.applies {
        return Err(Failure {
            code: EXIT_VERDICT,
            error: anyhow::anyhow!(
                "{}: --strict: {}",
                world.path.display(),
                report.verdict.line()
            ),
        });
    }
    Ok(())
}

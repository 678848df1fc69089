//! `ftcbf batch` and `ftcbf merge`: clap arguments, the commands and their printing (the batch
//! is [`BatchSpec`] run on [`ftcbf_lab::trials::prepare_batch`], the merge [`batch::merge`]).

use std::path::PathBuf;

use anyhow::Context;

use ftcbf_lab::batch::{self, BatchSpec, FailOn, PrepareFn, Shard, Sweep};

use ftcbf_sim::world::ControllerKindSpec;

use crate::bars::RunsBar;
use crate::parsers::{controller_parser, fail_on_parser};

/// Run a world many times with independent seeds and certify its safety claim.
///
/// Every trial k runs each controller with the seed SplitMix64(S, k), so controllers are compared
/// on identical noise and attacks. The fraction of safe trials gets an exact 95 % Clopper–Pearson
/// interval; against the world's claim Pr(x_t in C for all t) >= 1 - epsilon the verdict is
/// `supported` (lower bound >= 1 - epsilon), `refuted` (upper bound < 1 - epsilon) or
/// `unresolved at this N`. Results do not depend on --jobs.
#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Examples:
  ftcbf batch worlds/corridor_spoof.toml --trials 1000
  ftcbf batch worlds/corridor_spoof.toml --trials 500 --controller ft-cbf-clf --out runs.csv --out runs.json
  ftcbf batch worlds/corridor_spoof.toml --sweep 'attacks[0].value=0,0.5,1,2' --trials 200
  # on four machines, then combine:
  ftcbf batch worlds/corridor_spoof.toml --trials 10000 --shard 1/4 --out part1.json
  ftcbf merge part1.json part2.json part3.json part4.json --out all.json

CSV columns (one row per trial and controller): sweep_key, sweep_value, trial, seed, controller,
safe, collided, first_collision_t, first_collision_obstacle, first_violation_t,
first_violation_set, first_violation_value, min_barrier, min_barrier_name, min_clearance,
goal_reached, time_to_goal, step1, clf_relaxed, step2, step3, infeasible, control_steps,
rejected_readings, duration, outside_fault_patterns, goal_settled, final_goal_distance
(empty field = none).

Exit codes: 0 done (and no verdict matched --fail-on); 4 a verdict matched --fail-on (the report
and every --out file are still written); 2 invalid world file; 1 any other error.")]
pub struct BatchArgs {
    /// World file (TOML).
    pub world: PathBuf,
    /// Number of trials N (every controller runs every trial).
    #[arg(long, default_value_t = BatchSpec::DEFAULT_TRIALS, value_parser = clap::value_parser!(u64).range(1..))]
    pub trials: u64,
    /// Worker threads [default: all cores].
    #[arg(long, short = 'j', value_name = "J", value_parser = clap::value_parser!(u64).range(1..))]
    pub jobs: Option<u64>,
    /// Base seed S [default: the world's seed].
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// Controller to run; repeat for a side-by-side comparison on the same seeds.
    #[arg(
        long = "controller",
        value_name = "KIND",
        value_parser = controller_parser(false),
        default_values = BatchSpec::DEFAULT_CONTROLLERS
    )]
    pub controllers: Vec<ControllerKindSpec>,
    /// Write results: FILE.csv (one row per trial) or FILE.json (summary + all trial records,
    /// the input of `ftcbf merge`). Repeatable.
    #[arg(long, value_name = "FILE.csv|FILE.json")]
    pub out: Vec<PathBuf>,
    /// Sweep a numeric world-file value: one batch per value, one table.
    #[arg(long, value_name = "KEY=V1,V2,...")]
    pub sweep: Option<Sweep>,
    /// Run only the K-th of N disjoint slices (trials k with k mod N = K - 1); combine the
    /// slices' JSON files with `ftcbf merge`.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<Shard>,
    /// Exit with code 4 (after printing and writing everything) when a verdict is `refuted`
    /// (--fail-on refuted), or anything but `supported` (--fail-on unresolved: refuted,
    /// unresolved at this N, or no claim because the world sets no ε). Every controller and
    /// sweep point is checked. For CI pipelines.
    #[arg(long, value_name = "LEVEL", value_parser = fail_on_parser())]
    pub fail_on: Option<FailOn>,
}

/// Combine the JSON files of a sharded batch into the result of the whole batch.
///
/// The files must come from the same world (same content), seed, trial count, controllers and
/// sweep, be disjoint and together cover every trial; the merged result is exactly what the
/// unsharded run gives.
#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Example:
  ftcbf merge part1.json part2.json part3.json part4.json --out all.json --out all.csv")]
pub struct MergeArgs {
    /// Batch JSON files written by `ftcbf batch --shard K/N --out FILE.json`.
    #[arg(required = true, value_name = "FILE.json")]
    pub files: Vec<PathBuf>,
    /// Write the merged result: FILE.csv or FILE.json. Repeatable.
    #[arg(long, value_name = "FILE.csv|FILE.json")]
    pub out: Vec<PathBuf>,
    /// Summarise even if some trials are missing (the result carries a warning).
    #[arg(long)]
    pub allow_incomplete: bool,
}

impl BatchArgs {
    /// The batch these arguments describe (no overrides but a sweep's).
    pub fn spec(&self) -> anyhow::Result<BatchSpec> {
        Ok(BatchSpec {
            world: self.world.clone(),
            overrides: Vec::new(),
            trials: self.trials,
            seed: self.seed,
            controllers: self
                .controllers
                .iter()
                .map(|k| k.name().to_string())
                .collect(),
            sweep: self.sweep.clone(),
            shard: self.shard,
            jobs: self
                .jobs
                .map(usize::try_from)
                .transpose()
                .context("--jobs is too large for this machine")?,
            outputs: self.out.clone(),
        })
    }
}

/// Prints the report on stdout, writes the result files and names each on stderr.
fn report_and_write(outputs: &[PathBuf], results: &[batch::BatchResult]) -> anyhow::Result<()> {
    print!("{}", batch::report_text(results));
    for p in batch::write_outputs(outputs, results)? {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

/// `ftcbf batch`: run the trials of worlds from `prepare`, print the report on stdout, write
/// the --out files; then a [`batch::VerdictFailure`] if a verdict matched --fail-on.
pub fn command(args: &BatchArgs, prepare: &PrepareFn<'_>) -> anyhow::Result<()> {
    let spec = args.spec()?;
    let outcome = spec.run(prepare, &RunsBar::new())?;
    report_and_write(&spec.outputs, &outcome.results)?;
    match args.fail_on {
        Some(level) => Ok(level.check(&outcome.results)?),
        None => Ok(()),
    }
}

/// `ftcbf merge`: merge, print the report on stdout, write the --out files.
pub fn merge(args: &MergeArgs) -> anyhow::Result<()> {
    batch::check_outputs(&args.out)?;
    let results = batch::merge(&args.files, args.allow_incomplete)?;
    report_and_write(&args.out, &results)
}

//! Command-line definitions (clap derive). Each command's `--help` carries an example.

use std::path::PathBuf;

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::{Parser, Subcommand, ValueEnum};

use ftcbf::batch::FailOn;
use ftcbf_sim::world::ControllerKindSpec;

/// ftcbf — keep a robot safe while its sensors lie.
///
/// Simulates a differential-drive TurtleBot3 (from URDF, in rapier3d) or the paper's linearised
/// model among obstacles, with redundant noisy sensors under attack, controlled by the
/// fault-tolerant CBF-CLF controller. Runs are described by world files (TOML) and recorded to
/// rerun `.rrd` files.
#[derive(Debug, Parser)]
#[command(name = "ftcbf", version, propagate_version = true)]
#[command(
    after_help = "Examples:\n  ftcbf run worlds/paper_turtlebot.toml\n  ftcbf check worlds/corridor_spoof.toml\n  ftcbf regress worlds/\n  ftcbf batch worlds/paper_linear.toml --trials 1000\n  ftcbf gen --seed 1 --count 40 --out gen_out"
)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Simulate one world headlessly, write a rerun recording and print a summary.
    ///
    /// Exits 0 when the run met the world's [expect] table (or the world has none), 3 when an
    /// expectation failed, 2 when the world file is invalid, 1 on any other error.
    #[command(
        after_help = "Examples:\n  ftcbf run worlds/paper_turtlebot.toml                 # writes runs/paper_turtlebot.rrd\n  ftcbf run worlds/paper_linear.toml --controller baseline --no-record\n  ftcbf run worlds/corridor_spoof.toml --seed 7 --json > summary.json\n\nOpen the recording with the rerun viewer:  rerun runs/paper_turtlebot.rrd"
    )]
    Run(RunArgs),
    /// Validate a world and check every hypothesis of the safety guarantee (Theorem 3) for it,
    /// with the numbers, without simulating; ends with one verdict line.
    ///
    /// Checks disjoint fault patterns, invertible R̄ and detectability (PBH) of every single- and
    /// pair-drop filter, what bounds γ_i and θ_ij, condition 1 (Lemma 1, Prop. 1, Thm. 5), that
    /// the declared attacks stay inside one fault pattern, and whether the goal can be held.
    /// Exits 0 after printing the report (also when the guarantee does not apply), 4 with
    /// --strict when Theorem 3 does not apply, 2 when the world file is invalid, 1 on any other
    /// error.
    #[command(
        after_help = "Examples:\n  ftcbf check worlds/corridor_spoof.toml\n  ftcbf check --strict worlds/paper_turtlebot.toml   # exit 4 when no guarantee applies"
    )]
    Check(CheckArgs),
    /// Run every world that has an [expect] table over its regression seeds and print a
    /// pass/fail table; exits 3 if any case fails.
    ///
    /// Each controller an [expect] table names runs on `seeds = N` seeds: the world's seed, then
    /// the first N − 1 trial seeds of `ftcbf batch` with that base seed. Counts ("safe in at least
    /// K of N seeds") and margins (the worst seed's min h, clearance, time to goal, within a
    /// stated tolerance) are judged over those runs. All runs share one thread pool.
    #[command(
        after_help = "Examples:\n  ftcbf regress                      # every world under worlds/\n  ftcbf regress worlds/paper_linear.toml worlds/corridor_spoof.toml\n  ftcbf regress --json > regress.json # every run's summary and each case's verdict\n\nA failing seed re-runs alone with:  ftcbf run WORLD --seed SEED --no-record"
    )]
    Regress(RegressArgs),
    /// Run N independent trials of a world (paired across controllers) and certify its safety
    /// probability with exact confidence intervals.
    Batch(crate::batch_cmd::BatchArgs),
    /// Merge the JSON results of sharded batches into the summary the unsharded batch gives.
    Merge(crate::batch_cmd::MergeArgs),
    /// Search for the worst attack inside the world's threat model (one fault pattern at a time)
    /// and write it as a world file that `ftcbf run` replays.
    Falsify(crate::falsify_cmd::FalsifyArgs),
    /// Generate seeded world files the way users write them: rooms, corridors, doorways,
    /// clutter fields and L turns; the burger or the waffle; the book's sensor suites; one
    /// attack inside one fault pattern; defaults only (no tuning keys).
    ///
    /// Every world's goal is reachable: the start and the goal disc are at least 0.15 m clear of
    /// every obstacle beyond the robot's footprint, and the project's planner finds a path that
    /// keeps 0.15 m clear (a layout that fails is redrawn). Every file is loaded with the
    /// project's world loader before it is written. The same seed, options and output directory
    /// give byte-identical files; world i of a seed does not depend on --count. Prints one line
    /// per world: file, kind, robot, suite, attack.
    #[command(
        after_help = "Examples:\n  ftcbf gen --seed 1 --count 40 --out gen_out\n  ftcbf gen --seed 7 --count 10 --out doors --kind doorway --robot waffle\n  ftcbf gen --seed 2 --count 5 --out enc --suite encoders --robots /path/to/ftcbf/robots\n\nThen, for each file:  ftcbf check FILE;  ftcbf batch FILE --trials 10 --controller ft-cbf-clf\n(scripts/gen_sweep.sh does both for a whole generated set and prints a table)."
    )]
    Gen(GenArgs),
    /// Render the book's results pages (tables and Pr(safe) figures) from the batch and
    /// falsify JSON stored under results/, stamped with the commit, date, machine and commands
    /// that produced them; with --check, fail when the pages in the book differ.
    ///
    /// The JSON and results/stamp.toml are written by scripts/results.sh (the full
    /// measurement: `scripts/results.sh 1000 400`). Exits 0 when the pages were written (or,
    /// with --check, are up to date), 1 when they differ or a file cannot be read.
    #[command(
        after_help = "Examples:\n  ftcbf report                 # results/*.json → book/src/results/\n  ftcbf report --check         # CI: fail when the committed pages differ\n  scripts/results.sh 100 200   # re-measure (100 trials per world, falsify budget 200), then report"
    )]
    Report(ReportArgs),
}

/// `ftcbf gen`
#[derive(Debug, clap::Args)]
pub struct GenArgs {
    /// Seed of every draw.
    #[arg(long)]
    pub seed: u64,
    /// How many worlds to write (1 to 100000).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub count: u64,
    /// Directory to write the world files to (created when missing). The files' `urdf` keys
    /// are relative to it.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Kind of scene; `all` takes every kind in turn.
    #[arg(long, value_enum, default_value = "all")]
    pub kind: KindArg,
    /// Robot; `any` alternates the burger and the waffle.
    #[arg(long, value_enum, default_value = "any")]
    pub robot: RobotArg,
    /// Sensor suite (book: Generating worlds); `any` takes every suite in turn.
    #[arg(long, value_enum, default_value = "any")]
    pub suite: SuiteArg,
    /// Directory holding turtlebot3_burger.urdf and turtlebot3_waffle.urdf (the project's
    /// `robots/`).
    #[arg(long, value_name = "DIR", default_value = "robots")]
    pub robots: PathBuf,
}

/// `ftcbf gen --kind`
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum KindArg {
    /// Four walls and furniture (tables, shelves, pillars, chairs).
    Room,
    /// A straight corridor, maybe with bins or boxes against its walls.
    Corridor,
    /// A wall with a door, free-standing or between two rooms.
    Doorway,
    /// A field of boxes, bins and balls.
    Clutter,
    /// An L-shaped corridor.
    #[value(name = "l_turn")]
    LTurn,
    /// Every kind in turn.
    All,
}

/// `ftcbf gen --robot`
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RobotArg {
    /// robots/turtlebot3_burger.urdf.
    Burger,
    /// robots/turtlebot3_waffle.urdf.
    Waffle,
    /// The two in turn.
    Any,
}

/// `ftcbf gen --suite`
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SuiteArg {
    /// Two receivers (x, y each) and an IMU heading.
    #[value(name = "two_receivers")]
    TwoReceivers,
    /// Three receivers and a compass.
    #[value(name = "three_receivers")]
    ThreeReceivers,
    /// Two receivers, wheel odometry and a compass.
    Odometry,
    /// Two receivers, wheel encoders → odometry, a gyro fused with a compass.
    Encoders,
    /// Two receivers, the first also reporting velocity, and a compass.
    #[value(name = "receiver_velocity")]
    ReceiverVelocity,
    /// Every suite in turn.
    Any,
}

/// `ftcbf run`
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The world file (TOML).
    pub world: PathBuf,
    /// Where to write the recording [default: runs/<world>.rrd].
    #[arg(long, value_name = "FILE.rrd")]
    pub out: Option<PathBuf>,
    /// Seed of every random source (overrides the world's `seed`).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Controller to run (overrides the world's `control.controller`).
    #[arg(long, value_parser = controller_parser(true))]
    pub controller: Option<ControllerKindSpec>,
    /// Simulated duration in seconds (overrides the world's `duration`; in (0, 3600]).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub duration: Option<f64>,
    /// Override any numeric key of the world, e.g. --set attacks[0].value=0.5 (repeatable).
    #[arg(long = "set", value_name = "KEY=NUMBER")]
    pub set: Vec<String>,
    /// Do not write a recording.
    #[arg(long)]
    pub no_record: bool,
    /// Print the run summary as JSON on stdout instead of the human summary.
    #[arg(long)]
    pub json: bool,
}

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
}

/// `ftcbf regress`
#[derive(Debug, clap::Args)]
pub struct RegressArgs {
    /// World files or directories of world files [default: worlds/].
    pub paths: Vec<PathBuf>,
    /// Print every case (expectations, verdict, failures and each seed's summary) as JSON
    /// instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `ftcbf report`.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// Folder holding stamp.toml and the JSON files it lists (their paths are relative to the
    /// current directory, the repository root).
    #[arg(long, value_name = "DIR", default_value = "results")]
    pub results: PathBuf,
    /// Folder of the book's results pages.
    #[arg(long, value_name = "DIR", default_value = "book/src/results")]
    pub out: PathBuf,
    /// Write nothing; exit 1 when a page in --out differs from what the JSON gives.
    #[arg(long)]
    pub check: bool,
}

/// The value parser of an option whose values are the names of a library type: clap checks the
/// value against `values` and lists them (in `--help`, with their help, and in its errors)
/// exactly as for a `ValueEnum`; the type's own `FromStr` then reads the name, so each type's
/// names are parsed in one place, the library.
fn named<T>(values: impl IntoIterator<Item = PossibleValue>) -> impl TypedValueParser<Value = T>
where
    T: std::str::FromStr + Clone + Send + Sync + 'static,
    T::Err: std::error::Error + Send + Sync + 'static,
{
    PossibleValuesParser::new(values.into_iter().collect::<Vec<_>>()).try_map(|s| s.parse::<T>())
}

/// `--controller` of `run`, `batch` and `falsify`: [`ControllerKindSpec`]'s names, read by its
/// `FromStr`; `described` lists what each controller is in `--help` (as `ftcbf run --help` does).
pub fn controller_parser(described: bool) -> impl TypedValueParser<Value = ControllerKindSpec> {
    named(ControllerKindSpec::ALL.map(|kind| {
        let value = PossibleValue::new(kind.name());
        if !described {
            return value;
        }
        value.help(match kind {
            ControllerKindSpec::FtCbfClf => "Fault-tolerant CBF-CLF (the paper's controller)",
            ControllerKindSpec::Baseline => {
                "CBF-CLF over one Kalman filter that uses every sensor (the paper's comparison)"
            }
            ControllerKindSpec::Nominal => {
                "CLF only, no barriers: what happens without a safety filter"
            }
        })
    }))
}

/// `ftcbf batch --fail-on`: [`FailOn`]'s names, with what each fails on.
pub fn fail_on_parser() -> impl TypedValueParser<Value = FailOn> {
    named(FailOn::ALL.map(|level| {
        PossibleValue::new(level.name()).help(match level {
            FailOn::Refuted => {
                "Fail when a verdict is `refuted` (the interval's upper bound is below 1 − ε)"
            }
            FailOn::Unresolved => "Fail unless every verdict is `supported`",
        })
    }))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use clap::CommandFactory;

    /// The command `ftcbf ARGS…` gives, or clap's error message.
    pub(crate) fn parse(args: &[&str]) -> Result<Command, String> {
        Cli::try_parse_from(std::iter::once("ftcbf").chain(args.iter().copied()))
            .map(|c| c.command)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn every_controller_name_reads_as_its_kind_on_every_command() {
        Cli::command().debug_assert();
        for kind in ControllerKindSpec::ALL {
            let name = kind.name();
            let Ok(Command::Run(r)) = parse(&["run", "w.toml", "--controller", name]) else {
                panic!("run --controller {name} did not parse");
            };
            assert_eq!(r.controller, Some(kind));
            let Ok(Command::Falsify(f)) = parse(&["falsify", "w.toml", "--controller", name])
            else {
                panic!("falsify --controller {name} did not parse");
            };
            assert_eq!(f.controller, Some(kind));
            let Ok(Command::Batch(b)) = parse(&["batch", "w.toml", "--controller", name]) else {
                panic!("batch --controller {name} did not parse");
            };
            assert_eq!(b.controllers, [kind]);
        }
        for command in ["run", "batch", "falsify"] {
            let e = parse(&[command, "w.toml", "--controller", "pid"]).expect_err("pid");
            assert!(
                e.contains("invalid value 'pid' for '--controller <")
                    && e.contains("[possible values: ft-cbf-clf, baseline, nominal]"),
                "{command}: {e}"
            );
        }
        let help = Cli::command()
            .find_subcommand_mut("run")
            .expect("run")
            .render_long_help()
            .to_string();
        assert!(
            help.contains(
                "- nominal:    CLF only, no barriers: what happens without a safety filter"
            ),
            "{help}"
        );
    }
}

//! The command line (clap derive): the top-level parser and its subcommands. Each command's
//! arguments live with the command (`src/commands/`); each command's `--help` carries an
//! example.

use clap::{Parser, Subcommand};

use crate::commands::{batch, check, falsify, gen, regress, report, run};

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
    Run(run::RunArgs),
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
    Check(check::CheckArgs),
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
    Regress(regress::RegressArgs),
    /// Run N independent trials of a world (paired across controllers) and certify its safety
    /// probability with exact confidence intervals.
    Batch(batch::BatchArgs),
    /// Merge the JSON results of sharded batches into the summary the unsharded batch gives.
    Merge(batch::MergeArgs),
    /// Search for the worst attack inside the world's threat model (one fault pattern at a time)
    /// and write it as a world file that `ftcbf run` replays.
    Falsify(falsify::FalsifyArgs),
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
    Gen(gen::GenArgs),
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
    Report(report::ReportArgs),
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;
    use std::path::PathBuf;

    use ftcbf_lab::batch::{BatchSpec, FailOn, Shard};
    use ftcbf_sim::world::ControllerKindSpec;
    use ftcbf_sim::worldgen::{Kind, RobotModel, Suite};

    /// The command `ftcbf ARGS…` gives, or clap's error message.
    fn parse(args: &[&str]) -> Result<Command, String> {
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

    #[test]
    fn gen_options_read_the_worldgen_names_and_every() {
        let Ok(Command::Gen(g)) = parse(&["gen", "--seed", "1", "--count", "2", "--out", "o"])
        else {
            panic!("gen defaults did not parse");
        };
        assert_eq!((g.kind, g.robot, g.suite), (None, None, None));
        for kind in Kind::ALL {
            let Ok(Command::Gen(g)) = parse(&[
                "gen",
                "--seed",
                "1",
                "--count",
                "2",
                "--out",
                "o",
                "--kind",
                kind.name(),
            ]) else {
                panic!("--kind {kind} did not parse");
            };
            assert_eq!(g.kind, Some(kind));
        }
        let Ok(Command::Gen(g)) = parse(&[
            "gen",
            "--seed",
            "1",
            "--count",
            "2",
            "--out",
            "o",
            "--robot",
            "waffle",
            "--suite",
            "receiver_velocity",
        ]) else {
            panic!("--robot/--suite did not parse");
        };
        assert_eq!(
            (g.robot, g.suite),
            (Some(RobotModel::Waffle), Some(Suite::ReceiverVelocity))
        );
        let e = parse(&[
            "gen", "--seed", "1", "--count", "2", "--out", "o", "--kind", "maze",
        ])
        .expect_err("maze");
        assert!(
            e.contains(
                "[possible values: room, corridor, doorway, clutter, l_turn, aisle_crossing, corridor_walker, room_people, dqn_loops, all]"
            ),
            "{e}"
        );
    }

    #[test]
    fn batch_arguments_parse_with_defaults() {
        let Ok(Command::Batch(a)) = parse(&["batch", "w.toml"]) else {
            panic!("batch args did not parse");
        };
        assert_eq!(a.trials, 100);
        assert_eq!(
            a.controllers,
            [ControllerKindSpec::FtCbfClf, ControllerKindSpec::Baseline]
        );
        assert_eq!((a.jobs, a.seed, a.shard, a.sweep), (None, None, None, None));
        let Ok(Command::Batch(a)) = parse(&[
            "batch",
            "w.toml",
            "--trials",
            "7",
            "-j",
            "2",
            "--seed",
            "9",
            "--controller",
            "nominal",
            "--out",
            "a.csv",
            "--out",
            "b.json",
            "--sweep",
            "x.y=1,2",
            "--shard",
            "3/4",
        ]) else {
            panic!("batch args did not parse");
        };
        assert_eq!((a.trials, a.jobs, a.seed), (7, Some(2), Some(9)));
        assert_eq!(a.controllers, [ControllerKindSpec::Nominal]);
        assert_eq!(a.out.len(), 2);
        assert_eq!(
            a.sweep.map(|s| (s.key, s.values)),
            Some(("x.y".to_string(), vec![1.0, 2.0]))
        );
        assert_eq!(a.shard, Some(Shard { index: 3, count: 4 }));
    }

    #[test]
    fn bad_arguments_give_clear_errors() {
        let e = parse(&["batch", "w.toml", "--shard", "5/4"]).expect_err("shard");
        assert!(
            e.contains("invalid shard `5/4`") && e.contains("K out of range"),
            "{e}"
        );
        let e = parse(&["batch", "w.toml", "--sweep", "k=1,nope"]).expect_err("sweep");
        assert!(e.contains("value `nope` is not a number"), "{e}");
        let e = parse(&["batch", "w.toml", "--trials", "0"]).expect_err("trials");
        assert!(e.contains("--trials"), "{e}");
        let e = parse(&["batch", "w.toml", "--controller", "pid"]).expect_err("controller");
        assert!(e.contains("pid") && e.contains("ft-cbf-clf"), "{e}");
        let e = parse(&["merge"]).expect_err("no files");
        assert!(e.contains("FILE.json"), "{e}");
    }

    #[test]
    fn fail_on_parses_its_levels() {
        let Ok(Command::Batch(a)) = parse(&["batch", "w.toml", "--fail-on", "refuted"]) else {
            panic!("--fail-on did not parse");
        };
        assert_eq!(a.fail_on, Some(FailOn::Refuted));
        let e = parse(&["batch", "w.toml", "--fail-on", "sometimes"]).expect_err("bad level");
        assert!(e.contains("refuted") && e.contains("unresolved"), "{e}");
    }

    #[test]
    fn the_spec_is_the_command_line() {
        let Ok(Command::Batch(a)) = parse(&[
            "batch", "w.toml", "--trials", "7", "-j", "2", "--out", "a.json",
        ]) else {
            panic!("batch args did not parse");
        };
        let s = a.spec().expect("spec");
        assert_eq!(
            s,
            BatchSpec {
                trials: 7,
                jobs: Some(2),
                outputs: vec![PathBuf::from("a.json")],
                ..BatchSpec::new("w.toml")
            }
        );
    }
}

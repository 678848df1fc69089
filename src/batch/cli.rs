//! clap arguments and the two commands, `ftcbf batch` and `ftcbf merge`.

use std::path::PathBuf;

use anyhow::Context;

use super::{
    figure, io, merge, run_sweep, table, BatchPlan, BatchResult, Execution, ParamOverride,
    PreparedWorld, Shard, Sweep, Verdict, CONFIDENCE,
};

/// Loads the world with the given overrides and returns its info and trial runner (wired by
/// the CLI to `World::load` + `runner::run`).
pub type PrepareFn<'a> = dyn Fn(&[ParamOverride]) -> anyhow::Result<PreparedWorld> + 'a;

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
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
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
        value_parser = ftcbf_sim::world::ControllerKindSpec::NAMES,
        default_values = ["ft-cbf-clf", "baseline"]
    )]
    pub controllers: Vec<String>,
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
    #[arg(long, value_enum, value_name = "LEVEL")]
    pub fail_on: Option<FailOn>,
}

/// Which batch verdicts make `ftcbf batch --fail-on` fail.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FailOn {
    /// Fail when a verdict is `refuted` (the interval's upper bound is below 1 − ε).
    Refuted,
    /// Fail unless every verdict is `supported`.
    Unresolved,
}

impl FailOn {
    fn name(self) -> &'static str {
        match self {
            FailOn::Refuted => "refuted",
            FailOn::Unresolved => "unresolved",
        }
    }

    /// Whether `verdict` fails at this level.
    pub fn fails(self, verdict: Verdict) -> bool {
        match self {
            FailOn::Refuted => verdict == Verdict::Refuted,
            FailOn::Unresolved => verdict != Verdict::Supported,
        }
    }
}

/// Returned by [`batch_command`] (after the report and every output were written) when a
/// verdict matched `--fail-on`; the CLI maps it to exit code 4.
#[derive(Debug, Clone, PartialEq)]
pub struct VerdictFailure {
    /// The level asked for.
    pub level: FailOn,
    /// One line per failing verdict: world, sweep point, controller, verdict and interval.
    pub failures: Vec<String>,
}

impl std::fmt::Display for VerdictFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} verdict(s) matched --fail-on {}: {}",
            self.failures.len(),
            self.level.name(),
            self.failures.join("; ")
        )
    }
}

impl std::error::Error for VerdictFailure {}

/// The verdicts of `results` that fail at `level`, described for the error message.
pub fn failing_verdicts(results: &[BatchResult], level: FailOn) -> Vec<String> {
    let mut out = Vec::new();
    for res in results {
        let point = res
            .plan
            .overrides
            .iter()
            .map(|o| format!(" at {}={}", o.key, o.value))
            .collect::<String>();
        for s in res.summaries.iter().filter(|s| level.fails(s.verdict)) {
            let claim = s
                .claimed_safety
                .map_or(String::new(), |c| format!(" against the claim {c:.4}"));
            out.push(format!(
                "{}{point} {}: {} (Pr(safe) in [{:.4}, {:.4}]{claim}, {} trials)",
                res.plan.world, s.controller, s.verdict, s.safe_ci.lower, s.safe_ci.upper, s.trials
            ));
        }
    }
    out
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

/// The report printed for a set of results: the full summary for a single batch, one table
/// for a sweep.
fn report(results: &[BatchResult]) -> String {
    match results {
        [one] if one.plan.overrides.is_empty() => table::summary_text(one),
        _ => table::sweep_text(results),
    }
}

/// Run the batch described by `args` and return the results and the report `ftcbf batch`
/// prints (the `--out` files are not written; `progress` shows a bar on a terminal).
pub fn run_batch_args(
    args: &BatchArgs,
    prepare: &PrepareFn<'_>,
    progress: bool,
) -> anyhow::Result<(Vec<BatchResult>, String)> {
    io::check_outputs(&args.out)?;
    let jobs = args
        .jobs
        .map(usize::try_from)
        .transpose()
        .context("--jobs is too large for this machine")?;
    let digest = io::digest_file(&args.world)?;
    let world_file = args.world.display().to_string();
    let plan_for =
        |info: &super::WorldInfo, overrides: Vec<ParamOverride>| -> anyhow::Result<BatchPlan> {
            let plan = BatchPlan {
                world: info.name.clone(),
                world_file: world_file.clone(),
                world_digest: digest.clone(),
                overrides,
                trials: args.trials,
                base_seed: args.seed.unwrap_or(info.seed),
                controllers: args.controllers.clone(),
                shard: args.shard,
                epsilon: info.epsilon,
                confidence: CONFIDENCE,
                theorem3: info.theorem3.clone(),
                liveness: info.liveness.clone(),
            };
            plan.validate()
                .with_context(|| format!("world `{world_file}`"))?;
            Ok(plan)
        };
    let results = run_sweep(
        prepare,
        args.sweep.as_ref(),
        &plan_for,
        Execution { jobs, progress },
    )?;
    let text = report(&results);
    Ok((results, text))
}

/// `ftcbf batch`: run, print the report on stdout, write the --out files.
pub fn batch_command(args: &BatchArgs, prepare: &PrepareFn<'_>) -> anyhow::Result<()> {
    let (results, text) = run_batch_args(args, prepare, true)?;
    print!("{text}");
    io::write_outputs(&args.out, &results)?;
    for p in args
        .out
        .iter()
        .chain(&figure::write_next_to(&args.out, &results)?)
    {
        eprintln!("wrote {}", p.display());
    }
    match args.fail_on {
        Some(level) => {
            let failures = failing_verdicts(&results, level);
            if failures.is_empty() {
                Ok(())
            } else {
                Err(VerdictFailure { level, failures }.into())
            }
        }
        None => Ok(()),
    }
}

/// `ftcbf merge`: merge, print the report on stdout, write the --out files.
pub fn merge_command(args: &MergeArgs) -> anyhow::Result<()> {
    io::check_outputs(&args.out)?;
    let results = merge::merge(&args.files, args.allow_incomplete)?;
    print!("{}", report(&results));
    io::write_outputs(&args.out, &results)?;
    for p in args
        .out
        .iter()
        .chain(&figure::write_next_to(&args.out, &results)?)
    {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::*;
    use super::*;
    use clap::{CommandFactory, Parser};

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(subcommand)]
        cmd: Cmd,
    }

    #[derive(Debug, clap::Subcommand)]
    enum Cmd {
        Batch(BatchArgs),
        Merge(MergeArgs),
    }

    fn parse(args: &[&str]) -> Result<Cmd, String> {
        Cli::try_parse_from(std::iter::once("ftcbf").chain(args.iter().copied()))
            .map(|c| c.cmd)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn clap_definitions_are_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn batch_arguments_parse_with_defaults() {
        let Ok(Cmd::Batch(a)) = parse(&["batch", "w.toml"]) else {
            panic!("batch args did not parse");
        };
        assert_eq!(a.trials, 100);
        assert_eq!(a.controllers, vec!["ft-cbf-clf", "baseline"]);
        assert_eq!((a.jobs, a.seed, a.shard, a.sweep), (None, None, None, None));
        let Ok(Cmd::Batch(a)) = parse(&[
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
        assert_eq!(a.controllers, vec!["nominal"]);
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

    /// A scratch directory unique to this test run.
    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("ftcbf-batch-test-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch dir");
        dir
    }

    /// The synthetic world of these tests (ε = 0.1): safe with probability `p_default`, or the
    /// first override's value under a sweep.
    fn synthetic(o: &[ParamOverride], p_default: f64) -> anyhow::Result<PreparedWorld> {
        Ok(PreparedWorld {
            info: WorldInfo {
                name: "synthetic".into(),
                seed: 42,
                epsilon: Some(0.1),
                theorem3: None,
                liveness: None,
            },
            runner: Box::new(Synthetic {
                p_safe: o.first().map_or(p_default, |o| o.value),
                fail_seed: None,
            }),
        })
    }

    #[test]
    fn batch_then_merge_through_files() {
        let dir = scratch("files");
        let world = dir.join("w.toml");
        std::fs::write(&world, "name = \"synthetic\"\n").expect("world file");
        let prepare = |o: &[ParamOverride]| synthetic(o, 0.9);
        let args = |shard: Option<&str>, out: &str| BatchArgs {
            world: world.clone(),
            trials: 30,
            jobs: Some(2),
            seed: None,
            controllers: vec!["ft-cbf-clf".into(), "baseline".into()],
            out: vec![dir.join(out)],
            sweep: Some("p=0.5,0.95".parse().expect("sweep")),
            shard: shard.map(|s| s.parse().expect("shard")),
            fail_on: None,
        };
        let (full, text) = run_batch_args(&args(None, "full.json"), &prepare, false).expect("full");
        assert_eq!(full.len(), 2);
        assert_eq!(
            full[0].plan.base_seed, 42,
            "the world's seed is the default"
        );
        assert!(text.starts_with("Sweep of p"), "{text}");
        let mut parts = Vec::new();
        for k in 1..=3 {
            let a = args(Some(&format!("{k}/3")), &format!("part{k}.json"));
            let (res, _) = run_batch_args(&a, &prepare, false).expect("shard");
            io::write_outputs(&a.out, &res).expect("write");
            parts.push(a.out[0].clone());
        }
        let merged = merge::merge(&parts, false).expect("merge");
        assert_eq!(merged, full);
        let csv = dir.join("merged.csv");
        io::write_outputs(std::slice::from_ref(&csv), &merged).expect("csv");
        let rows = std::fs::read_to_string(&csv)
            .expect("read csv")
            .lines()
            .count();
        assert_eq!(rows, 1 + 2 * 30 * 2);

        // A bad output name is refused before any trial runs.
        let mut bad = args(None, "x.txt");
        bad.trials = 1;
        let e = run_batch_args(&bad, &prepare, false).expect_err("txt");
        assert!(e.to_string().contains("x.txt"));
        // A missing world file is named.
        let mut gone = args(None, "y.json");
        gone.world = dir.join("missing.toml");
        let e = run_batch_args(&gone, &prepare, false).expect_err("missing");
        assert!(e.to_string().contains("missing.toml"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn fail_on_levels_and_exit_error() {
        let Ok(Cmd::Batch(a)) = parse(&["batch", "w.toml", "--fail-on", "refuted"]) else {
            panic!("--fail-on did not parse");
        };
        assert_eq!(a.fail_on, Some(FailOn::Refuted));
        let e = parse(&["batch", "w.toml", "--fail-on", "sometimes"]).expect_err("bad level");
        assert!(e.contains("refuted") && e.contains("unresolved"), "{e}");
        for (v, refuted, unresolved) in [
            (Verdict::Supported, false, false),
            (Verdict::Refuted, true, true),
            (Verdict::Unresolved, false, true),
            (Verdict::NoClaim, false, true),
        ] {
            assert_eq!(FailOn::Refuted.fails(v), refuted, "{v}");
            assert_eq!(FailOn::Unresolved.fails(v), unresolved, "{v}");
        }

        // ε = 0.1 claims 0.9; 200 trials at p = 0.99 (baseline 0.495) and p = 0.5.
        let dir = scratch("fail-on");
        let world = dir.join("w.toml");
        std::fs::write(&world, "name = \"synthetic\"\n").expect("world file");
        let prepare = |o: &[ParamOverride]| synthetic(o, 0.99);
        let mut args = BatchArgs {
            world: world.clone(),
            trials: 200,
            jobs: Some(1),
            seed: None,
            controllers: vec!["ft-cbf-clf".into()],
            out: vec![dir.join("r.json")],
            sweep: None,
            shard: None,
            fail_on: Some(FailOn::Refuted),
        };
        batch_command(&args, &prepare).expect("p = 0.99 is not refuted");
        args.controllers.push("baseline".into());
        let e = batch_command(&args, &prepare).expect_err("baseline at 0.495 is refuted");
        let f = e.downcast_ref::<VerdictFailure>().expect("typed failure");
        assert_eq!(f.failures.len(), 1, "{f}");
        assert!(
            f.failures[0].starts_with("synthetic baseline: refuted"),
            "{f}"
        );
        assert!(dir.join("r.json").is_file(), "outputs are written first");
        // A sweep names its point.
        args.sweep = Some("p=0.99,0.5".parse().expect("sweep"));
        args.fail_on = Some(FailOn::Unresolved);
        let e = batch_command(&args, &prepare).expect_err("p = 0.5 fails");
        let f = e.downcast_ref::<VerdictFailure>().expect("typed failure");
        assert!(
            f.failures
                .iter()
                .any(|l| l.contains(" at p=0.5 ft-cbf-clf: refuted")),
            "{f}"
        );
        assert!(e.to_string().contains("--fail-on unresolved"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

//! A batch as a program describes it ([`BatchSpec`], no command line), run to its results and
//! report; the report text and the output files that `ftcbf batch` and `ftcbf merge` print and
//! write; the `--fail-on` verdict levels.

use std::path::PathBuf;

use anyhow::Context;

use super::{
    figure, io, run_sweep, table, BatchPlan, BatchResult, Execution, Override, PreparedWorld,
    Shard, Sweep, Verdict, WorldInfo, CONFIDENCE,
};

/// Loads the world with the given overrides and returns its info and trial runner (for the
/// world's own controllers: [`crate::trials::prepare_batch`]).
pub type PrepareFn<'a> = dyn Fn(&[Override]) -> anyhow::Result<PreparedWorld> + 'a;

/// One batch: a world run `trials` times with independent seeds for each controller, maybe
/// over a sweep or as one shard. `ftcbf batch` builds it from its command line, the Python
/// package from its arguments.
///
/// Every trial k runs each controller with the seed [`super::trial_seed`]`(S, k)`, so
/// controllers are compared on identical noise and attacks. Results do not depend on `jobs`.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchSpec {
    /// World file (TOML); the plan names it and carries its digest.
    pub world: PathBuf,
    /// Overrides of the world file's values for every trial, applied before a sweep point's.
    /// They are not part of the plan (a sweep point's are).
    pub overrides: Vec<Override>,
    /// Number of trials N (every controller runs every trial); at least 1.
    pub trials: u64,
    /// Base seed S [`None`: the world's seed].
    pub seed: Option<u64>,
    /// Controllers by name, in report order (built-in ones, or any the runner knows).
    pub controllers: Vec<String>,
    /// One batch per value of a world-file key, reported as one table.
    pub sweep: Option<Sweep>,
    /// Run only this slice of the trials (combine the slices with [`super::merge()`]).
    pub shard: Option<Shard>,
    /// Worker threads [`None`: all cores].
    pub jobs: Option<usize>,
    /// Where the results go, FILE.csv or FILE.json, checked before any trial runs and written
    /// by [`write_outputs`].
    pub outputs: Vec<PathBuf>,
}

/// What a batch gives: its results (one per sweep point) and the report `ftcbf batch` prints.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchOutcome {
    /// One result per sweep point (one without a sweep).
    pub results: Vec<BatchResult>,
    /// The report: [`report_text`] of the results.
    pub report: String,
}

impl BatchSpec {
    /// Trials of a batch unless told otherwise.
    pub const DEFAULT_TRIALS: u64 = 100;
    /// Controllers of a batch unless told otherwise: the paper's comparison.
    pub const DEFAULT_CONTROLLERS: [&'static str; 2] = ["ft-cbf-clf", "baseline"];

    /// A batch of `world` with the defaults: [`Self::DEFAULT_TRIALS`] trials of
    /// [`Self::DEFAULT_CONTROLLERS`] from the world's seed on all cores, no overrides, sweep,
    /// shard or outputs.
    pub fn new(world: impl Into<PathBuf>) -> Self {
        Self {
            world: world.into(),
            overrides: Vec::new(),
            trials: Self::DEFAULT_TRIALS,
            seed: None,
            controllers: Self::DEFAULT_CONTROLLERS.map(String::from).to_vec(),
            sweep: None,
            shard: None,
            jobs: None,
            outputs: Vec::new(),
        }
    }

    /// Runs the batch on worlds from `prepare` (given the overrides, then a sweep point's) and
    /// returns its results and report; writes no file (see [`write_outputs`]). `progress` hears
    /// each sweep point's trials.
    pub fn run(
        &self,
        prepare: &PrepareFn<'_>,
        progress: &dyn crate::progress::Progress,
    ) -> anyhow::Result<BatchOutcome> {
        io::check_outputs(&self.outputs)?;
        let digest = io::digest_file(&self.world)?;
        let world_file = self.world.display().to_string();
        let plan_for = |info: &WorldInfo, overrides: Vec<Override>| -> anyhow::Result<BatchPlan> {
            let plan = BatchPlan {
                world: info.name.clone(),
                world_file: world_file.clone(),
                world_digest: digest.clone(),
                overrides,
                trials: self.trials,
                base_seed: self.seed.unwrap_or(info.seed),
                controllers: self.controllers.clone(),
                shard: self.shard,
                epsilon: info.epsilon,
                confidence: CONFIDENCE,
                theorem3: info.theorem3.clone(),
                liveness: info.liveness.clone(),
            };
            plan.validate()
                .with_context(|| format!("world `{world_file}`"))?;
            Ok(plan)
        };
        let with_base = |point: &[Override]| prepare(&[&self.overrides[..], point].concat());
        let results = run_sweep(
            &with_base,
            self.sweep.as_ref(),
            &plan_for,
            Execution {
                jobs: self.jobs,
                progress,
            },
        )?;
        let report = report_text(&results);
        Ok(BatchOutcome { results, report })
    }
}

/// The report of a set of results: the full summary for a single batch, one table for a
/// sweep (what `ftcbf batch` and `ftcbf merge` print).
pub fn report_text(results: &[BatchResult]) -> String {
    match results {
        [one] if one.plan.overrides.is_empty() => table::summary_text(one),
        _ => table::sweep_text(results),
    }
}

/// Writes `results` to every output path (FILE.csv or FILE.json) and the Pr(safe) figure next
/// to every JSON one (FILE.svg); returns the files written, outputs first.
pub fn write_outputs(outputs: &[PathBuf], results: &[BatchResult]) -> anyhow::Result<Vec<PathBuf>> {
    io::write_outputs(outputs, results)?;
    let figures = figure::write_next_to(outputs, results)?;
    Ok(outputs.iter().cloned().chain(figures).collect())
}

/// Which batch verdicts fail a batch (`ftcbf batch --fail-on`, for CI pipelines).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailOn {
    /// Fail when a verdict is `refuted` (the interval's upper bound is below 1 − ε).
    Refuted,
    /// Fail unless every verdict is `supported`.
    Unresolved,
}

impl FailOn {
    /// Every level, in the order the CLI lists them.
    pub const ALL: [Self; 2] = [Self::Refuted, Self::Unresolved];

    /// The level's name (`refuted`, `unresolved`).
    pub fn name(self) -> &'static str {
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

    /// `Ok` when no verdict of `results` fails at this level, else every failing one.
    pub fn check(self, results: &[BatchResult]) -> Result<(), VerdictFailure> {
        let failures = failing_verdicts(results, self);
        if failures.is_empty() {
            Ok(())
        } else {
            Err(VerdictFailure {
                level: self,
                failures,
            })
        }
    }
}

/// A level name that is neither `refuted` nor `unresolved`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown verdict level `{0}` (expected refuted or unresolved)")]
pub struct UnknownLevel(pub String);

impl std::str::FromStr for FailOn {
    type Err = UnknownLevel;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|l| l.name() == s)
            .ok_or_else(|| UnknownLevel(s.to_string()))
    }
}

/// Returned by [`FailOn::check`] when a verdict fails at its level; `ftcbf batch` returns it
/// after the report and every output were written and maps it to exit code 4.
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

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::*;
    use super::*;

    /// A scratch directory unique to this test run.
    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("ftcbf-batch-test-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch dir");
        dir
    }

    /// The synthetic world of these tests (ε = 0.1): safe with probability `p_default`, or the
    /// last override's value (a sweep point's comes after the spec's own).
    fn synthetic(o: &[Override], p_default: f64) -> anyhow::Result<PreparedWorld> {
        Ok(PreparedWorld {
            info: WorldInfo {
                name: "synthetic".into(),
                seed: 42,
                epsilon: Some(0.1),
                theorem3: None,
                liveness: None,
            },
            runner: Box::new(Synthetic {
                p_safe: o.last().map_or(p_default, |o| o.value),
                fail_seed: None,
            }),
        })
    }

    #[test]
    fn a_new_spec_has_the_documented_defaults() {
        let s = BatchSpec::new("w.toml");
        assert_eq!(s.trials, 100);
        assert_eq!(s.controllers, vec!["ft-cbf-clf", "baseline"]);
        assert_eq!((s.jobs, s.seed, s.shard, s.sweep), (None, None, None, None));
        assert!(s.overrides.is_empty() && s.outputs.is_empty());
    }

    #[test]
    fn batch_then_merge_through_files() {
        let dir = scratch("files");
        let world = dir.join("w.toml");
        std::fs::write(&world, "name = \"synthetic\"\n").expect("world file");
        let prepare = |o: &[Override]| synthetic(o, 0.9);
        let spec = |shard: Option<&str>, out: &str| BatchSpec {
            trials: 30,
            jobs: Some(2),
            outputs: vec![dir.join(out)],
            sweep: Some("p=0.5,0.95".parse().expect("sweep")),
            shard: shard.map(|s| s.parse().expect("shard")),
            ..BatchSpec::new(&world)
        };
        let full = spec(None, "full.json")
            .run(&prepare, &crate::progress::Silent)
            .expect("full");
        assert_eq!(full.results.len(), 2);
        assert_eq!(
            full.results[0].plan.base_seed, 42,
            "the world's seed is the default"
        );
        assert!(full.report.starts_with("Sweep of p"), "{}", full.report);
        assert_eq!(full.report, report_text(&full.results));
        let mut parts = Vec::new();
        for k in 1..=3 {
            let s = spec(Some(&format!("{k}/3")), &format!("part{k}.json"));
            let part = s.run(&prepare, &crate::progress::Silent).expect("shard");
            let written = write_outputs(&s.outputs, &part.results).expect("write");
            assert_eq!(
                written,
                vec![s.outputs[0].clone(), s.outputs[0].with_extension("svg")]
            );
            parts.push(s.outputs[0].clone());
        }
        let merged = merge::merge(&parts, false).expect("merge");
        assert_eq!(merged, full.results);
        let csv = dir.join("merged.csv");
        io::write_outputs(std::slice::from_ref(&csv), &merged).expect("csv");
        let rows = std::fs::read_to_string(&csv)
            .expect("read csv")
            .lines()
            .count();
        assert_eq!(rows, 1 + 2 * 30 * 2);

        // The spec's own overrides come before each sweep point's and stay out of the plan.
        let mut based = spec(None, "based.json");
        based.overrides = vec![Override {
            key: "q".into(),
            value: 0.1,
        }];
        let b = based
            .run(&prepare, &crate::progress::Silent)
            .expect("based");
        assert_eq!(b.results, full.results, "the sweep point's value wins");
        based.sweep = None;
        let b = based
            .run(&prepare, &crate::progress::Silent)
            .expect("based, no sweep");
        assert!(b.results[0].plan.overrides.is_empty());
        assert!(b.results[0].summaries[0].safe_rate < 0.5, "p = 0.1 applies");

        // A bad output name is refused before any trial runs.
        let mut bad = spec(None, "x.txt");
        bad.trials = 1;
        let e = bad
            .run(&prepare, &crate::progress::Silent)
            .expect_err("txt");
        assert!(e.to_string().contains("x.txt"));
        // A missing world file is named.
        let mut gone = spec(None, "y.json");
        gone.world = dir.join("missing.toml");
        let e = gone
            .run(&prepare, &crate::progress::Silent)
            .expect_err("missing");
        assert!(e.to_string().contains("missing.toml"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn fail_on_levels_and_their_failures() {
        for (v, refuted, unresolved) in [
            (Verdict::Supported, false, false),
            (Verdict::Refuted, true, true),
            (Verdict::Unresolved, false, true),
            (Verdict::NoClaim, false, true),
        ] {
            assert_eq!(FailOn::Refuted.fails(v), refuted, "{v}");
            assert_eq!(FailOn::Unresolved.fails(v), unresolved, "{v}");
        }
        for l in FailOn::ALL {
            assert_eq!(l.name().parse::<FailOn>(), Ok(l));
        }
        let e = "sometimes".parse::<FailOn>().expect_err("bad level");
        assert!(e.to_string().contains("refuted or unresolved"), "{e}");

        // ε = 0.1 claims 0.9; 200 trials at p = 0.99 (baseline 0.495) and p = 0.5.
        let dir = scratch("fail-on");
        let world = dir.join("w.toml");
        std::fs::write(&world, "name = \"synthetic\"\n").expect("world file");
        let prepare = |o: &[Override]| synthetic(o, 0.99);
        let mut spec = BatchSpec {
            trials: 200,
            jobs: Some(1),
            controllers: vec!["ft-cbf-clf".into()],
            ..BatchSpec::new(&world)
        };
        let run = |s: &BatchSpec| {
            s.run(&prepare, &crate::progress::Silent)
                .expect("batch")
                .results
        };
        FailOn::Refuted
            .check(&run(&spec))
            .expect("p = 0.99 is not refuted");
        spec.controllers.push("baseline".into());
        let f = FailOn::Refuted
            .check(&run(&spec))
            .expect_err("baseline at 0.495 is refuted");
        assert_eq!(f.failures.len(), 1, "{f}");
        assert!(
            f.failures[0].starts_with("synthetic baseline: refuted"),
            "{f}"
        );
        // A sweep names its point.
        spec.sweep = Some("p=0.99,0.5".parse().expect("sweep"));
        let f = FailOn::Unresolved
            .check(&run(&spec))
            .expect_err("p = 0.5 fails");
        assert!(
            f.failures
                .iter()
                .any(|l| l.contains(" at p=0.5 ft-cbf-clf: refuted")),
            "{f}"
        );
        assert!(f.to_string().contains("--fail-on unresolved"), "{f}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

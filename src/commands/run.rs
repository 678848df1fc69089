//! `ftcbf run`: one world simulated headlessly, recorded, summarised and judged against its
//! `[expect]` table.

use std::path::PathBuf;

use anyhow::Context;
use indicatif::ProgressBar;

use ftcbf_lab::regress;
use ftcbf_sim::observe::{Frame, Observer, Scene};
use ftcbf_sim::record::{Recorder, RecordingName};
use ftcbf_sim::runner::{run, run_observed, CompiledWorld, RunOptions};
use ftcbf_sim::summary::RunSummary;
use ftcbf_sim::world::{ranges, ControllerKindSpec, Override};

use crate::bars::{bar, Unit};
use crate::exit::{invalid, run_failure, Failure, EXIT_EXPECTATION, EXIT_USAGE};
use crate::parsers::controller_parser;

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

/// Shows a progress bar over control steps while forwarding to the recorder.
struct WithProgress<'a> {
    inner: &'a mut dyn Observer,
    bar: ProgressBar,
}

impl Observer for WithProgress<'_> {
    fn scene(&mut self, scene: &Scene) {
        self.inner.scene(scene);
    }
    fn frame(&mut self, frame: &Frame<'_>) {
        self.inner.frame(frame);
        self.bar.inc(1);
    }
}

/// `ftcbf run`.
pub fn command(a: &RunArgs) -> Result<(), Failure> {
    let overrides = a
        .set
        .iter()
        .map(|s| Override::parse(s).map_err(|e| anyhow::anyhow!("--set {e}")))
        .collect::<anyhow::Result<Vec<_>>>()
        .map_err(|error| Failure {
            code: EXIT_USAGE,
            error,
        })?;
    if let Some(d) = a.duration {
        ranges::check_duration(d).map_err(|e| Failure {
            code: EXIT_USAGE,
            error: anyhow::anyhow!(e),
        })?;
    }
    let world = ftcbf_sim::world::World::load(&a.world, &overrides).map_err(invalid)?;
    for note in world.obstacles.iter().filter_map(|o| o.note.as_ref()) {
        eprintln!("warning: {note}");
    }
    let kind = a.controller.unwrap_or(world.file.control.controller);
    let seed = a.seed.unwrap_or(world.file.seed);
    let opts = RunOptions {
        seed: Some(seed),
        controller: Some(kind),
        duration: a.duration,
    };
    // Compiled once: the run and the liveness explanation below share its setup.
    let compiled = CompiledWorld::new(world).map_err(|e| run_failure(e, "run failed"))?;
    let world = compiled.world();
    let summary = if a.no_record {
        run(&compiled, &opts).map_err(|e| run_failure(e, "run failed"))?
    } else {
        run_recorded(a, &compiled, &opts, kind, seed)?
    };
    let expected = ftcbf_sim::analysis::expectations::expectation_for(world, kind);
    let seeds = regress::world_seeds(world);
    // A run is judged by its world's expectations only on one of the regression seeds.
    let judged = expected.as_ref().filter(|_| seeds.contains(&seed));
    let (failures, left) = judged
        .map(|e| ftcbf_sim::analysis::expectations::failures_of_run(e, &summary))
        .unwrap_or_default();
    if a.json {
        let text = serde_json::to_string_pretty(&summary).context("serialising the summary")?;
        println!("{text}");
    } else {
        print!("{summary}");
        let setup = compiled.setup_for(kind);
        if let Some(why) = ftcbf_sim::analysis::liveness::explain_run(world, &setup, &summary) {
            println!("  {why}");
        }
        let judgement = match (&expected, judged) {
            (None, _) => Judgement::NoExpectations,
            (Some(_), None) => Judgement::NotJudged,
            (Some(_), Some(_)) => Judgement::Judged {
                failures: &failures,
                left: &left,
            },
        };
        print_expectations(&summary, seed, &seeds, judgement);
    }
    if let Some(d) = &summary.disagreement {
        // Not a verdict: the run's own numbers contradict each other (exit 1).
        return Err(Failure::from(anyhow::anyhow!(
            "{}: no safety verdict: the run's barrier and physics disagree about obstacle `{}`: {d} (tolerance {} m); the barrier does not describe the obstacle the robot meets",
            world.path.display(),
            d.obstacle,
            ftcbf_sim::summary::DISAGREEMENT_TOLERANCE
        )));
    }
    if failures.is_empty() {
        Ok(())
    } else {
        Err(Failure {
            code: EXIT_EXPECTATION,
            error: anyhow::anyhow!(
                "{}: {} expectation(s) failed: {}",
                world.path.display(),
                failures.len(),
                failures.join("; ")
            ),
        })
    }
}

/// Run `world` while recording it to `--out` (default `runs/<world>.rrd`), with a progress bar
/// over the control steps.
fn run_recorded(
    a: &RunArgs,
    compiled: &CompiledWorld,
    opts: &RunOptions,
    kind: ControllerKindSpec,
    seed: u64,
) -> Result<RunSummary, Failure> {
    let world = compiled.world();
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(format!("{}.rrd", world.name)));
    let name = RecordingName {
        world: world.name.clone(),
        controller: kind.name().to_string(),
        seed,
    };
    let mut rec = Recorder::create(&out, &name).context("recording")?;
    let duration = a.duration.unwrap_or(world.file.duration);
    let bar = bar(world.control_steps(duration), &world.name, Unit::Steps);
    let summary = {
        let mut obs = WithProgress {
            inner: &mut rec,
            bar: bar.clone(),
        };
        run_observed(compiled, opts, Some(&mut obs)).map_err(|e| run_failure(e, "run failed"))?
    };
    bar.finish_and_clear();
    rec.finish().context("recording")?;
    eprintln!(
        "recording: {} (open it with: rerun {})",
        out.display(),
        out.display()
    );
    Ok(summary)
}

/// How a run stands against its world's expectations.
enum Judgement<'a> {
    /// The world has no expectations for this controller.
    NoExpectations,
    /// It has some, but the seed is not one of the regression seeds.
    NotJudged,
    /// Judged: the failed expectations, and those left to `ftcbf regress`.
    Judged {
        failures: &'a [String],
        left: &'a [String],
    },
}

fn print_expectations(s: &RunSummary, seed: u64, seeds: &[u64], judgement: Judgement<'_>) {
    match judgement {
        Judgement::NoExpectations => println!("expectations: none for {}", s.controller),
        Judgement::NotJudged => println!(
            "expectations: not judged (seed {seed} is not one of the world's {} regression seeds)",
            seeds.len()
        ),
        Judgement::Judged { failures, left } => {
            if failures.is_empty() {
                println!("expectations: met");
            }
            for f in failures {
                println!("expectation FAILED: {f}");
            }
            if !left.is_empty() {
                println!(
                    "expectations over all {} seeds left to `ftcbf regress`: {}",
                    seeds.len(),
                    left.join(", ")
                );
            }
        }
    }
}

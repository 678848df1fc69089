//! `ftcbf falsify`: clap arguments, the command and its printing (the search is
//! `ftcbf_lab::falsify`).

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};
use ftcbf_sim::record::{Recorder, RecordingName};
use ftcbf_sim::runner::{run, run_observed, RunOptions};
use ftcbf_sim::world::{ControllerKindSpec, World};
use serde::Serialize;

use ftcbf_lab::falsify::search::MIN_BUDGET;

use crate::bars::RunsBar;
use ftcbf_lab::falsify::{
    falsify, Family, ReplayInfo, Report, Robustness, Settings, WorldTemplate,
};

/// Search for the worst attack inside the world's threat model.
///
/// Every candidate attacks the channels of ONE declared fault pattern (the paper's fault model;
/// patterns are never combined) with one of the 12 injector kinds, parameterised by magnitude or
/// rate, direction, onset, duration and, for the stealthy attacker, its detector threshold. The
/// objective is the run's robustness ρ: the minimum over time of h(x_true) of every safe set and
/// of the signed obstacle clearance (negative = unsafe; a collision ranks below any run without
/// one). A cross-entropy method searches with BUDGET runs, each candidate on 2 seeds, starting
/// from random search's first candidates and carrying its best candidates from one generation to
/// the next, spends its last third of generations on CMA-ES over the continuous parameters of
/// its best (pattern, kind) cells, re-runs its best 3 candidates on held-out seeds, then spends a fourth finalist's
/// runs descending from its worst run so far on that run's seed (with the noise fixed, ρ is a
/// deterministic function of the attack); random search (4 finalists) with the same
/// budget and seeds is run for comparison. The worst run is written as a world file (its attacks, seed and
/// controller) that `ftcbf run` replays to the same ρ, with its recording next to it.
/// The same command gives the same output files (the recording's blueprint ids aside), for any
/// --jobs.
#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Examples:
  ftcbf falsify worlds/paper_turtlebot.toml --controller baseline --budget 200 --out worst.toml
  ftcbf run worst.toml                       # replays the worst run (seed and controller are in the file)
  ftcbf falsify worlds/corridor_spoof.toml --budget 400 --jobs 2 --json corridor.json --no-record
  ftcbf falsify worlds/corridor_spoof.toml --scenario --budget 32 --range obstacle_shift=0.3 --json scen.json")]
pub struct FalsifyArgs {
    /// World file (TOML). Its own `[[attacks]]` are replaced by the searched ones.
    pub world: PathBuf,
    /// Controller under test [default: the world's `control.controller`].
    #[arg(long, value_name = "KIND", value_parser = crate::parsers::controller_parser(false))]
    pub controller: Option<ControllerKindSpec>,
    /// Runs (simulations) per search method (at least 24; plus one run of the world without
    /// attacks per held-out seed, the reference), or in all with --scenario (at least 8).
    #[arg(long, value_name = "N", default_value_t = 200,
          value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub budget: u64,
    /// Base seed S of the candidates and of the run seeds [default: the world's seed].
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// Worker threads [default: all cores].
    #[arg(long, short = 'j', value_name = "J", value_parser = clap::value_parser!(u64).range(1..))]
    pub jobs: Option<u64>,
    /// Where to write the worst run as a world file [default: runs/WORLD-worst-CONTROLLER.toml];
    /// its recording goes next to it (same name, .rrd).
    #[arg(long, value_name = "WORST.toml")]
    pub out: Option<PathBuf>,
    /// Also write every evaluation, the finalists and the comparison as JSON.
    #[arg(long, value_name = "FILE.json")]
    pub json: Option<PathBuf>,
    /// Do not record the worst run.
    #[arg(long)]
    pub no_record: bool,
    /// Skip the random-search comparison (halves the runs).
    #[arg(long)]
    pub no_random: bool,
    /// The attacks searched: `injectors` (every injector kind over its whole range) or
    /// `fallback` (attacks aimed at the safe stop, `[control] fallback = "brake"`: a stealthy
    /// bias at the edge of its evidence test, a ramp timed to reach its full offset at a chosen
    /// moment, a slow alternation, a held offset between the two estimates); the objective is
    /// ρ either way.
    #[arg(long, value_name = "FAMILY", default_value = "injectors", value_parser = parse_family,
          conflicts_with = "scenario")]
    pub family: Family,
    /// Scenario search: also vary the world (obstacles, start, goal, sensor noise, attack onset)
    /// within the ranges of its [falsify] table and --range, keep the variants `ftcbf check`
    /// accepts (Theorem 3 applies, robot predicted live), attack them, and report every unsafe
    /// run there as a defect (written to --defects). --budget is then the total runs.
    #[arg(long)]
    pub scenario: bool,
    /// A scenario range, overriding the [falsify] table: obstacle_shift, obstacle_scale,
    /// start_shift, start_heading, goal_shift, noise, onset_shift (repeatable).
    #[arg(long, value_name = "KEY=VALUE", value_parser = ftcbf_lab::falsify::scenario::parse_range,
          requires = "scenario")]
    pub range: Vec<(String, f64)>,
    /// Where --scenario writes a regression world per defect [default: runs/WORLD-scenario/]
    /// (and its worst run, unless --out says where).
    #[arg(long, value_name = "DIR", requires = "scenario")]
    pub defects: Option<PathBuf>,
}

/// `--family`: `injectors` or `fallback`.
fn parse_family(s: &str) -> Result<Family, String> {
    [Family::Injectors, Family::Fallback]
        .into_iter()
        .find(|f| f.name() == s)
        .ok_or_else(|| format!("`{s}`: expected `injectors` or `fallback`"))
}

/// A command-line value out of range (exit 64, as clap's own usage errors).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// The replay of the written world.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Replay {
    /// Which method found the worst run.
    pub found_by: String,
    /// The world file written.
    pub world_file: String,
    /// The recording, if written.
    pub recording: Option<String>,
    /// ρ of `ftcbf run` on the written file (equal to the witness', checked).
    pub robustness: Robustness,
}

#[derive(Serialize)]
struct JsonOut<'a> {
    #[serde(flatten)]
    report: &'a Report,
    replay: &'a Replay,
}

/// Writes the worst run of `report` as a world file at `out`, runs that file as `ftcbf run`
/// would (recording to `recording` if given) and checks that it reproduces the witness' ρ bit
/// for bit.
pub fn write_worst(
    template: &WorldTemplate,
    report: &Report,
    out: &Path,
    recording: Option<&Path>,
) -> anyhow::Result<Replay> {
    let best = report
        .methods
        .iter()
        .reduce(|a, b| {
            if b.witness
                .robustness
                .cmp_worse(&a.witness.robustness)
                .is_lt()
            {
                b
            } else {
                a
            }
        })
        .ok_or_else(|| anyhow!("no search result"))?;
    let w = &best.witness;
    let name = format!(
        "{}_worst_{}",
        report.world,
        report.controller.replace('-', "_")
    );
    let description = format!(
        "The worst attack `ftcbf falsify` found on {} against {} (seed {}): {}; ρ = {}.",
        report.world,
        report.controller,
        w.seed,
        w.description,
        w.robustness.display()
    );
    let header = vec![
        format!(
            "Written by `ftcbf falsify {} --controller {} --seed {} --budget {}` ({} search).",
            report.world_file,
            report.controller,
            report.seed,
            report.plan.budget,
            best.method.name()
        ),
        format!(
            "The original's [[attacks]] are replaced by the worst run's; `seed` and `control.controller` are that run's."
        ),
        format!(
            "Robustness ρ = {} (min over time of h(x_true) and obstacle clearance).",
            w.robustness.display()
        ),
        "Every attack stays inside one declared fault pattern. The original's [expect] is removed.".into(),
    ];
    let info = ReplayInfo {
        name: &name,
        description: &description,
        seed: w.seed,
        controller: &report.controller,
        header: &header,
    };
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create directory {}", dir.display()))?;
    }
    let text = template.replay_text(&w.attacks, &info, out)?;
    std::fs::write(out, &text).with_context(|| format!("cannot write {}", out.display()))?;
    let world = World::load(out, &[])
        .with_context(|| format!("the written world {} does not load", out.display()))?;
    let opts = RunOptions::default();
    let summary = match recording {
        None => run(&world, &opts)?,
        Some(path) => {
            let name = RecordingName {
                world: world.name.clone(),
                controller: world.file.control.controller.name().to_string(),
                seed: world.file.seed,
            };
            let mut rec = Recorder::create(path, &name).context("recording")?;
            let s = run_observed(&world, &opts, Some(&mut rec))?;
            rec.finish().context("recording")?;
            s
        }
    };
    let robustness = Robustness::of(&world, &summary)
        .ok_or_else(|| anyhow!("the written world has no safe set and no obstacle"))?;
    if robustness != w.robustness {
        return Err(anyhow!(
            "the written world {} replays to ρ = {}, not the searched {}; this is a bug",
            out.display(),
            robustness.display(),
            w.robustness.display()
        ));
    }
    Ok(Replay {
        found_by: best.method.name().into(),
        world_file: out.display().to_string(),
        recording: recording.map(|p| p.display().to_string()),
        robustness,
    })
}

/// `ftcbf falsify --scenario`: search, write every defect's world, print the summary, write the
/// JSON.
fn scenario_command(
    args: &FalsifyArgs,
    template: &WorldTemplate,
    settings: &Settings,
) -> anyhow::Result<()> {
    use ftcbf_lab::falsify::scenario::{scenario, write_defects, write_run, Ranges};
    if args.no_record || args.no_random {
        eprintln!(
            "note: --no-record and --no-random apply to the attack search, not to --scenario"
        );
    }
    let ranges = Ranges::resolve(&template.world, &args.range)?;
    let mut report = scenario(template, settings, &ranges, &RunsBar::new())?;
    let dir = args
        .defects
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(format!("{}-scenario", report.world)));
    write_defects(template, &mut report, &dir)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| dir.join(format!("{}-scenario-worst.toml", report.world)));
    if let Some(w) = report.worst.clone() {
        write_run(
            template,
            &report,
            &w,
            &format!("{}_scenario_worst", report.world),
            "The worst run of the scenario search",
            &out,
        )?;
    }
    print!("{}", report.text());
    if report.worst.is_some() {
        println!(
            "worst run written to {}; `ftcbf run {}` replays it (identical ρ)",
            out.display(),
            out.display()
        );
    }
    if let Some(j) = &args.json {
        let text = serde_json::to_string_pretty(&report).context("serialising the report")?;
        std::fs::write(j, text + "\n").with_context(|| format!("cannot write {}", j.display()))?;
        eprintln!("wrote {}", j.display());
    }
    Ok(())
}

/// `ftcbf falsify`: search, print the summary, write the worst world, its recording and the JSON.
pub fn command(args: &FalsifyArgs) -> anyhow::Result<()> {
    if let Some(j) = &args.json {
        if j.extension().is_none_or(|e| e != "json") {
            return Err(anyhow!(
                "--json {}: expected a .json file name",
                j.display()
            ));
        }
    }
    if let Some(out) = &args.out {
        if out.extension().is_none_or(|e| e != "toml") {
            return Err(anyhow!(
                "--out {}: expected a .toml file name",
                out.display()
            ));
        }
    }
    let least = if args.scenario {
        ftcbf_lab::falsify::scenario::MIN_BUDGET
    } else {
        MIN_BUDGET
    };
    if args.budget < least as u64 {
        return Err(UsageError(format!(
            "--budget {}: expected at least {least} runs{}",
            args.budget,
            if args.scenario {
                " with --scenario"
            } else {
                ""
            }
        ))
        .into());
    }
    let template = WorldTemplate::load(&args.world)?;
    let controller = args
        .controller
        .unwrap_or(template.world.file.control.controller);
    let settings = Settings {
        controller,
        budget: usize::try_from(args.budget).context("--budget is too large")?,
        seed: args.seed.unwrap_or(template.world.file.seed),
        jobs: args
            .jobs
            .map(usize::try_from)
            .transpose()
            .context("--jobs is too large for this machine")?,
        compare_random: !args.no_random,
        family: args.family,
    };
    for w in ftcbf_lab::falsify::model_warnings(&template.world) {
        eprintln!("warning: {w}");
    }
    if args.scenario {
        return scenario_command(args, &template, &settings);
    }
    let runs = settings.runs()?;
    let clock = std::time::Instant::now();
    let report = falsify(&template, &settings, &RunsBar::new())?;
    // The time goes to stderr: the summary on stdout and the JSON stay the same for any --jobs.
    eprintln!(
        "searched {} in {:.1} s ({runs} runs)",
        report.world,
        clock.elapsed().as_secs_f64()
    );
    print!("{}", report.text());
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(format!("{}-worst-{}.toml", report.world, report.controller))
    });
    let recording = (!args.no_record).then(|| out.with_extension("rrd"));
    let replay =
        write_worst(&template, &report, &out, recording.as_deref()).with_context(|| {
            format!(
                "--out `{}`: expected a file path whose folder exists or can be created, for the \
             worst attack's world",
                out.display()
            )
        })?;
    println!();
    println!(
        "worst run ({} search) written to {}; `ftcbf run {}` replays it: ρ = {} (identical)",
        replay.found_by,
        replay.world_file,
        replay.world_file,
        replay.robustness.display()
    );
    if let Some(r) = &replay.recording {
        println!("recording: {r} (open it with: rerun {r})");
    }
    if let Some(j) = &args.json {
        let text = serde_json::to_string_pretty(&JsonOut {
            report: &report,
            replay: &replay,
        })
        .context("serialising the report")?;
        std::fs::write(j, text + "\n").with_context(|| format!("cannot write {}", j.display()))?;
        eprintln!("wrote {}", j.display());
    }
    Ok(())
}

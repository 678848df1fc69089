//! `ftcbf` — the command-line front end: a thin binary over `ftcbf-sim` (ripgrep style).

use ftcbf::runner::prepare_batch;
use ftcbf::{batch, regress, report};
mod batch_cmd;
mod cli;
mod falsify_cmd;

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};

use ftcbf_sim::check;
use ftcbf_sim::observe::{Frame, Observer, Scene};
use ftcbf_sim::record::{Recorder, RecordingName};
use ftcbf_sim::runner::{preflight, run, run_observed, CompiledWorld, RunError, RunOptions};
use ftcbf_sim::summary::RunSummary;
use ftcbf_sim::world::{ranges, ControllerKindSpec, Override, World, WorldError};

use cli::{
    CheckArgs, Cli, Command, GenArgs, KindArg, RegressArgs, ReportArgs, RobotArg, RunArgs, SuiteArg,
};

/// Exit code: a world file is invalid.
const EXIT_INVALID: u8 = 2;
/// Exit code: a run did not meet its world's `[expect]`.
const EXIT_EXPECTATION: u8 = 3;
/// Exit code: a verdict failed: `check --strict` and Theorem 3 does not apply to the world, or a
/// batch verdict matched `ftcbf batch --fail-on`.
const EXIT_VERDICT: u8 = 4;

/// Exit code: the command line itself is wrong (clap's usage errors, a malformed `--set`, an
/// option value out of range). Distinct from an invalid world (2); sysexits' EX_USAGE.
const EXIT_USAGE: u8 = 64;
/// Exit code: an internal error — a panic inside the simulator or a dependency, contained and
/// reported instead of aborting with Rust's 101; sysexits' EX_SOFTWARE.
const EXIT_INTERNAL: u8 = 70;

/// An error with the exit code it maps to.
struct Failure {
    code: u8,
    error: anyhow::Error,
}

impl From<anyhow::Error> for Failure {
    fn from(error: anyhow::Error) -> Self {
        Failure { code: 1, error }
    }
}

fn invalid(e: WorldError) -> Failure {
    Failure {
        code: EXIT_INVALID,
        error: anyhow::Error::new(e).context("invalid world file"),
    }
}

/// A run error as a failure: an invalid world exits 2, an option out of range 64.
fn run_failure(e: RunError, what: &'static str) -> Failure {
    let code = match &e {
        RunError::Option(_) => EXIT_USAGE,
        e if e.is_invalid_world() => EXIT_INVALID,
        _ => 1,
    };
    let context = if code == EXIT_INVALID {
        "invalid world file"
    } else {
        what
    };
    Failure {
        code,
        error: anyhow::Error::new(e).context(context),
    }
}

/// The exit code of a command's error chain: an invalid world anywhere in it exits 2.
fn code_of(e: &anyhow::Error) -> u8 {
    if e.is::<batch::VerdictFailure>() {
        EXIT_VERDICT
    } else if e.chain().any(|c| {
        c.is::<WorldError>()
            || c.downcast_ref::<RunError>()
                .is_some_and(RunError::is_invalid_world)
    }) {
        EXIT_INVALID
    } else {
        1
    }
}

/// The test hook of the exit-70 path: `FTCBF_TEST_PANIC=main` panics on the main thread inside
/// the command, `FTCBF_TEST_PANIC=worker` in a worker thread of the pool that `batch`,
/// `regress` and `falsify` run their trials on (rayon carries the panic back to the command). It
/// lets `tests/reliability.rs` check what a user sees on a real bug, since no input is known to
/// panic any more. Documented in the book (Development: tests); unset, it does nothing.
const TEST_PANIC_VAR: &str = "FTCBF_TEST_PANIC";

fn test_panic_hook() {
    match std::env::var(TEST_PANIC_VAR).as_deref() {
        Ok("main") => panic!("{TEST_PANIC_VAR}=main: a panic injected to test the exit-70 path"),
        Ok("worker") => {
            use rayon::prelude::*;
            (0..4u32).into_par_iter().for_each(|i| {
                if i == 3 {
                    panic!("{TEST_PANIC_VAR}=worker: a panic injected to test the exit-70 path");
                }
            });
        }
        _ => {}
    }
}

fn dispatch(command: Command) -> Result<(), Failure> {
    test_panic_hook();
    match command {
        Command::Run(a) => cmd_run(&a),
        Command::Check(a) => cmd_check(&a),
        Command::Regress(a) => cmd_regress(&a),
        Command::Batch(a) => {
            batch_cmd::batch_command(&a, &prepare_batch(&a.world)).map_err(|e| Failure {
                code: code_of(&e),
                error: e,
            })
        }
        Command::Merge(a) => batch_cmd::merge_command(&a).map_err(Failure::from),
        Command::Falsify(a) => falsify_cmd::falsify_command(&a).map_err(|e| Failure {
            code: if e.is::<falsify_cmd::UsageError>() {
                EXIT_USAGE
            } else {
                code_of(&e)
            },
            error: e,
        }),
        Command::Gen(a) => cmd_gen(&a).map_err(Failure::from),
        Command::Report(a) => cmd_report(&a).map_err(Failure::from),
    }
}

/// The message and place of the last panic, kept by the hook for the error line.
static PANIC: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

/// Restores the default action of SIGPIPE, which Rust's runtime ignores: when the reader of
/// `ftcbf`'s output goes away (`ftcbf check W | head -1`), the process ends as `cat` or `grep`
/// do, killed by the signal (the shell's status 141), instead of `println!` panicking on the
/// broken pipe and the panic being reported as an internal error (exit 70).
fn default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: `signal` with SIG_DFL installs no handler code; called once, first thing in main,
    // before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() -> ExitCode {
    default_sigpipe();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // --help and --version print to stdout and succeed; usage errors exit 64.
            let code = if e.use_stderr() { EXIT_USAGE } else { 0 };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    // A panic anywhere below (the simulator, parry, rapier, a worker thread of a batch) is
    // contained: the hook keeps its message instead of printing Rust's, and the command ends
    // with a typed internal error and exit 70, never 101 or an abort.
    std::panic::set_hook(Box::new(|info| {
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic payload".to_string());
        let place = info
            .location()
            .map_or(String::new(), |l| format!(" at {}:{}", l.file(), l.line()));
        if let Ok(mut slot) = PANIC.lock() {
            slot.get_or_insert(format!("{msg}{place}"));
        }
    }));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| dispatch(cli.command)))
        .unwrap_or_else(|_| {
            let what = PANIC
                .lock()
                .ok()
                .and_then(|s| s.clone())
                .unwrap_or_else(|| "unknown panic".to_string());
            Err(Failure {
                code: EXIT_INTERNAL,
                error: anyhow::anyhow!(
                    "internal error: the simulation stopped on a panic ({what}); this is a bug \
                     — please report it with the world file and command line"
                ),
            })
        });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("error: {:#}", f.error);
            ExitCode::from(f.code)
        }
    }
}

fn load(path: &Path, overrides: &[Override]) -> Result<World, Failure> {
    World::load(path, overrides).map_err(invalid)
}

/// What ran, so the same world + controller + seed gives the same recording name.
fn recording_name(world: &World, kind: ControllerKindSpec, seed: u64) -> RecordingName {
    RecordingName {
        world: world.name.clone(),
        controller: kind.name().to_string(),
        seed,
    }
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

fn steps_bar(len: u64, what: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

fn cmd_run(a: &RunArgs) -> Result<(), Failure> {
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
        if !ranges::DURATION.contains(d) {
            return Err(Failure {
                code: EXIT_USAGE,
                error: anyhow::anyhow!(
                    "--duration {d}: expected a number of seconds in {}",
                    ranges::DURATION.describe()
                ),
            });
        }
    }
    let world = load(&a.world, &overrides)?;
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
    let expected = ftcbf_sim::regress::expectation_for(world, kind);
    let seeds = regress::world_seeds(world);
    // A run is judged by its world's expectations only on one of the regression seeds.
    let judged = expected.as_ref().filter(|_| seeds.contains(&seed));
    let (failures, left) = judged
        .map(|e| ftcbf_sim::regress::failures_of_run(e, &summary))
        .unwrap_or_default();
    if a.json {
        let text = serde_json::to_string_pretty(&summary).context("serialising the summary")?;
        println!("{text}");
    } else {
        print!("{summary}");
        let setup = compiled.setup_for(kind);
        if let Some(why) = ftcbf_sim::liveness::explain_run(world, &setup, &summary) {
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
    let mut rec =
        Recorder::create(&out, &recording_name(world, kind, seed)).context("recording")?;
    let duration = a.duration.unwrap_or(world.file.duration);
    let bar = steps_bar((duration / world.control_dt()).round() as u64, &world.name);
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

fn cmd_check(a: &CheckArgs) -> Result<(), Failure> {
    let compiled =
        CompiledWorld::new(load(&a.world, &[])?).map_err(|e| run_failure(e, "controller setup"))?;
    let world = compiled.world();
    // Whatever `run` would refuse at its start, `check` refuses too, with the same exit code.
    preflight(&compiled).map_err(|e| run_failure(e, "controller setup"))?;
    println!("world {} ({})", world.name, world.path.display());
    let report = check::check_compiled(&compiled);
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

/// `ftcbf gen`: the library generates (`ftcbf_sim::worldgen`); this writes and lists.
/// `ftcbf report`: load, render, then write or compare (the logic is `ftcbf::report`).
fn cmd_report(a: &ReportArgs) -> anyhow::Result<()> {
    let inputs = report::load(&a.results)?;
    let pages = report::render(&inputs)?;
    if a.check {
        let differ = report::differences(&pages, &a.out)?;
        if !differ.is_empty() {
            let list: Vec<String> = differ.iter().map(|p| p.display().to_string()).collect();
            anyhow::bail!(
                "the results pages differ from what `{}` gives: {}; run `ftcbf report` and \
                 commit the pages",
                a.results.join(report::STAMP).display(),
                list.join(", ")
            );
        }
        println!(
            "{} pages and figures in {} are up to date",
            pages.len(),
            a.out.display()
        );
    } else {
        report::write(&pages, &a.out)?;
        println!(
            "wrote {} pages and figures to {}",
            pages.len(),
            a.out.display()
        );
    }
    Ok(())
}

fn cmd_gen(a: &GenArgs) -> anyhow::Result<()> {
    use ftcbf_sim::worldgen::{write_worlds, GenConfig, Generator, Kind, RobotModel, Suite};
    let kind = match a.kind {
        KindArg::Room => Some(Kind::Room),
        KindArg::Corridor => Some(Kind::Corridor),
        KindArg::Doorway => Some(Kind::Doorway),
        KindArg::Clutter => Some(Kind::Clutter),
        KindArg::LTurn => Some(Kind::LTurn),
        KindArg::All => None,
    };
    let robot = match a.robot {
        RobotArg::Burger => Some(RobotModel::Burger),
        RobotArg::Waffle => Some(RobotModel::Waffle),
        RobotArg::Any => None,
    };
    let suite = match a.suite {
        SuiteArg::TwoReceivers => Some(Suite::TwoReceivers),
        SuiteArg::ThreeReceivers => Some(Suite::ThreeReceivers),
        SuiteArg::Odometry => Some(Suite::Odometry),
        SuiteArg::Encoders => Some(Suite::Encoders),
        SuiteArg::ReceiverVelocity => Some(Suite::ReceiverVelocity),
        SuiteArg::Any => None,
    };
    if a.out.exists() && !a.out.is_dir() {
        anyhow::bail!(
            "--out `{}` is not a directory; expected a directory to write the generated worlds \
             into (it is created when missing)",
            a.out.display()
        );
    }
    let out_flag = || {
        format!(
            "--out `{}`: expected a directory the generated worlds can be written into",
            a.out.display()
        )
    };
    let generator = Generator::new(GenConfig {
        seed: a.seed,
        kind,
        robot,
        suite,
        robots_dir: a.robots.clone(),
        out_dir: a.out.clone(),
    })
    .map_err(|e| match e {
        ftcbf_sim::worldgen::GenError::Io { .. } => anyhow::Error::new(e).context(out_flag()),
        e => anyhow::Error::new(e),
    })?;
    let count = usize::try_from(a.count).context("--count")?;
    let worlds = generator.worlds(count)?;
    let paths = write_worlds(&a.out, &worlds).with_context(out_flag)?;
    let rows: Vec<Vec<String>> = worlds
        .iter()
        .zip(&paths)
        .map(|(w, p)| {
            vec![
                p.display().to_string(),
                w.kind.name().to_string(),
                w.robot.name().to_string(),
                w.suite.name().to_string(),
                w.attack_label(),
            ]
        })
        .collect();
    print!(
        "{}",
        ftcbf::batch::render_table(
            &["file", "kind", "robot", "suite", "attack"],
            &[ftcbf::batch::Align::Left; 5],
            &rows
        )
    );
    Ok(())
}

fn cmd_regress(a: &RegressArgs) -> Result<(), Failure> {
    let paths = if a.paths.is_empty() {
        vec![PathBuf::from("worlds")]
    } else {
        a.paths.clone()
    };
    let plan = regress::Plan::load(&paths).map_err(|e| match e {
        regress::RegressError::World(w) => invalid(w),
        other => Failure::from(anyhow::Error::new(other)),
    })?;
    for f in &plan.skipped {
        eprintln!("skipping {} (no [expect] table)", f.display());
    }
    let bar = steps_bar(plan.runs() as u64, "regress");
    let results = plan.run(|| bar.inc(1)).context("regression run")?;
    bar.finish_and_clear();
    if a.json {
        let text = serde_json::to_string_pretty(&results).context("serialising")?;
        println!("{text}");
    } else {
        println!("{}", regress::table_text(&results));
    }
    let failed = results.iter().filter(|r| !r.passed()).count();
    if failed > 0 {
        Err(Failure {
            code: EXIT_EXPECTATION,
            error: anyhow::anyhow!("{failed} regression case(s) failed"),
        })
    } else {
        Ok(())
    }
}

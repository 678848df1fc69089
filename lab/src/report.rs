//! The book's results pages, rendered from stored JSON (`ftcbf report`).
//!
//! `scripts/results.sh` runs `ftcbf batch` and `ftcbf falsify` on the catalogue and writes their
//! JSON files under `results/`, with `results/stamp.toml`: the commit, date, machine and
//! toolchain of the measurement and every command exactly as it was run. [`load`] reads the
//! stamp and the files it lists; [`render`] turns them into the pages (Markdown tables, and the
//! Pr(safe) figure `batch` draws, as SVG); [`write()`] puts them into the book and [`differences`]
//! compares them with what is there (`ftcbf report --check`, run in CI, so the pages in the
//! repository are exactly what the stored JSON gives). Nothing here is measured or typed by
//! hand: every number on the pages comes from a JSON file the stamp names.
//!
//! One file (about 970 lines of code): every results page is one function over the same
//! measured inputs and the same table writers, so `ftcbf report --check` regenerates them all
//! in one place; the data they read are produced by `batch`, `falsify` and `regress`.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use serde::Deserialize;

use crate::batch::{figure, BatchResult, ControllerSummary};

/// The page with the batch tables.
pub const CATALOGUE_PAGE: &str = "catalogue.md";
/// The page with the falsification table.
pub const FALSIFY_PAGE: &str = "falsify.md";
/// The folder of the figures, inside the pages' folder.
pub const FIGURES: &str = "figures";
/// The stamp's file name inside the results folder.
pub const STAMP: &str = "stamp.toml";

/// What `scripts/results.sh` records about a measurement.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stamp {
    /// How `scripts/results.sh` was invoked.
    pub script: String,
    /// `git rev-parse HEAD` when the measurement started (marked when the tree had changes).
    pub commit: String,
    /// UTC start time, RFC 3339.
    pub date: String,
    /// Operating system, architecture, CPU, cores and load at the start.
    pub machine: String,
    /// `rustc --version`.
    pub toolchain: String,
    /// Every command, in the order run.
    #[serde(default)]
    pub run: Vec<StampedRun>,
}

/// One command of a measurement.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StampedRun {
    /// The JSON file it wrote, as `scripts/results.sh` names it from the repository root
    /// (`results/batch/x.json`); read from the results folder it is listed in (see
    /// [`listed_file`]).
    pub json: String,
    /// The command line, with `ftcbf` for the binary.
    pub command: String,
    /// Its wall time \[s\].
    pub seconds: u64,
    /// The commit it ran at, when that is not the stamp's: a world added to the catalogue and
    /// measured alone afterwards (`RESUME=1 scripts/results.sh`). Absent: the stamp's commit.
    #[serde(default)]
    pub commit: Option<String>,
}

/// A batch JSON file as written by `ftcbf batch --out X.json`.
#[derive(Debug, Deserialize)]
struct BatchJson {
    format: String,
    results: Vec<BatchResult>,
}

/// The parts of a falsify JSON file (`ftcbf falsify --json`) the table shows.
#[derive(Debug, Clone, Deserialize)]
pub struct FalsifyJson {
    /// World name.
    pub world: String,
    /// World file as given.
    pub world_file: String,
    /// Controller under test.
    pub controller: String,
    /// The attacks searched (`injectors` or `fallback`; absent in reports written before
    /// `--family`: the injectors).
    #[serde(default)]
    pub family: Option<String>,
    /// The CEM, then random search (when run).
    pub methods: Vec<FalsifyMethod>,
    /// Both methods' best attacks on the same held-out seeds.
    pub paired: Option<FalsifyPaired>,
    /// The world without attacks on the same held-out seeds (absent in reports written before
    /// falsify ran it).
    #[serde(default)]
    pub attack_free: Option<FalsifyAttackFree>,
}

/// The attack-free reference of a falsify report.
#[derive(Debug, Clone, Deserialize)]
pub struct FalsifyAttackFree {
    /// Mean ρ without attacks (`None`: not finite).
    pub mean: Option<f64>,
    /// Each method's best attack against no attack.
    pub moved: Vec<FalsifyMoved>,
}

/// One method's best attack against the attack-free runs, seed by seed.
#[derive(Debug, Clone, Deserialize)]
pub struct FalsifyMoved {
    /// `cem` or `random`.
    pub method: String,
    /// Seeds where the attack is the worse.
    pub attack_worse: usize,
    /// Seeds where no attack is the worse.
    pub attack_free_worse: usize,
    /// Sign test.
    pub p: f64,
}

/// One search method's result.
#[derive(Debug, Clone, Deserialize)]
pub struct FalsifyMethod {
    /// `cem` or `random`.
    pub method: String,
    /// Finalists on the held-out seeds, best (worst for the controller) first.
    pub finalists: Vec<FalsifyEvaluation>,
    /// The worst single run.
    pub witness: FalsifyWitness,
    /// Runs made.
    pub runs: usize,
    /// Of which unsafe.
    pub unsafe_runs: usize,
}

/// A finalist.
#[derive(Debug, Clone, Deserialize)]
pub struct FalsifyEvaluation {
    /// One-line description of the attack.
    pub description: String,
    /// Its runs.
    pub runs: Vec<serde_json::Value>,
    /// Seed-averaged robustness (`None`: not finite).
    pub mean: Option<f64>,
    /// Unsafe runs.
    pub unsafe_runs: usize,
}

/// The worst single run.
#[derive(Debug, Clone, Deserialize)]
pub struct FalsifyWitness {
    /// One-line description of the attack.
    pub description: String,
    /// Its robustness.
    pub robustness: FalsifyRobustness,
}

/// Robustness ρ of one run.
#[derive(Debug, Clone, Deserialize)]
pub struct FalsifyRobustness {
    /// ρ (`None`: not finite, counted as −∞).
    pub value: Option<f64>,
    /// The robot touched an obstacle.
    pub collided: bool,
    /// The margin that attains the minimum.
    pub binding: String,
}

/// The paired comparison of the two methods' best attacks.
#[derive(Debug, Clone, Deserialize)]
pub struct FalsifyPaired {
    /// Seeds compared.
    pub seeds: usize,
    /// Seeds where the CEM's attack is the worse for the controller.
    pub cem_worse: usize,
    /// Seeds where random search's attack is.
    pub random_worse: usize,
    /// Exact two-sided sign test.
    pub p: f64,
}

/// A batch file's results with the command that made them.
pub type MeasuredBatch = (StampedRun, Vec<BatchResult>);

/// Everything a report is rendered from.
#[derive(Debug)]
pub struct Inputs {
    /// The stamp.
    pub stamp: Stamp,
    /// Batch results per stamped run (in stamp order), with the command that made them.
    pub batches: Vec<MeasuredBatch>,
    /// Falsify results per stamped run.
    pub falsify: Vec<(StampedRun, FalsifyJson)>,
}

/// One rendered file, relative to the pages' folder.
#[derive(Debug, Clone, PartialEq)]
pub struct Page {
    /// Path inside the pages' folder.
    pub path: PathBuf,
    /// Its content.
    pub text: String,
}

/// Where a file the stamp lists is, given the results folder the stamp is in: the stamp names
/// files as `scripts/results.sh` wrote them from the repository root (`results/batch/x.json`),
/// so a leading `results/` stands for the results folder itself, wherever it was copied to and
/// whatever the working directory; any other relative path is inside the results folder, and an
/// absolute path is taken as it is.
pub fn listed_file(results: &Path, json: &str) -> PathBuf {
    let listed = Path::new(json);
    if listed.is_absolute() {
        return listed.to_path_buf();
    }
    let inside = listed.strip_prefix("results").unwrap_or(listed);
    results.join(inside)
}

/// Reads `RESULTS/stamp.toml` and every JSON file it lists (see [`listed_file`]: they are
/// found through the results folder, not the working directory). A file whose format is
/// neither a batch nor a falsify result is an error naming it.
pub fn load(results: &Path) -> anyhow::Result<Inputs> {
    let stamp_path = results.join(STAMP);
    let text = std::fs::read_to_string(&stamp_path)
        .with_context(|| format!("could not read `{}`", stamp_path.display()))?;
    let stamp: Stamp =
        toml::from_str(&text).with_context(|| format!("`{}`", stamp_path.display()))?;
    if stamp.run.is_empty() {
        bail!(
            "`{}` lists no runs: run scripts/results.sh first",
            stamp_path.display()
        );
    }
    let mut batches = Vec::new();
    let mut falsify = Vec::new();
    for run in &stamp.run {
        let path = listed_file(results, &run.json);
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!(
                "could not read `{}` (listed in `{}`)",
                path.display(),
                stamp_path.display()
            )
        })?;
        let value: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("`{}` is not JSON", path.display()))?;
        if value.get("format").is_some() {
            let b: BatchJson = serde_json::from_value(value)
                .with_context(|| format!("`{}`: not a batch result", path.display()))?;
            if b.format != crate::batch::FORMAT || b.results.is_empty() {
                bail!(
                    "`{}`: format `{}` with {} results; expected `{}` with at least one",
                    path.display(),
                    b.format,
                    b.results.len(),
                    crate::batch::FORMAT
                );
            }
            batches.push((run.clone(), b.results));
        } else {
            let f: FalsifyJson = serde_json::from_value(value)
                .with_context(|| format!("`{}`: not a falsify result", path.display()))?;
            if f.methods.is_empty() || f.methods.iter().any(|m| m.finalists.is_empty()) {
                bail!("`{}`: a search method without finalists", path.display());
            }
            falsify.push((run.clone(), f));
        }
    }
    Ok(Inputs {
        stamp,
        batches,
        falsify,
    })
}

/// Renders the pages and figures.
pub fn render(inputs: &Inputs) -> anyhow::Result<Vec<Page>> {
    let mut pages = vec![Page {
        path: PathBuf::from(CATALOGUE_PAGE),
        text: catalogue_page(inputs),
    }];
    if !inputs.falsify.is_empty() {
        pages.push(Page {
            path: PathBuf::from(FALSIFY_PAGE),
            text: falsify_page(inputs),
        });
    }
    for (run, results) in &inputs.batches {
        let svg = figure::svg(&figure::from_results(results))
            .with_context(|| format!("the figure of `{}`", run.json))?;
        pages.push(Page {
            path: figure_path(results),
            text: svg,
        });
    }
    Ok(pages)
}

/// Writes the pages under `out`, and removes figures no page uses any more.
pub fn write(pages: &[Page], out: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out.join(FIGURES))
        .with_context(|| format!("could not create `{}`", out.join(FIGURES).display()))?;
    for stale in stale_figures(pages, out)? {
        std::fs::remove_file(&stale)
            .with_context(|| format!("could not remove `{}`", stale.display()))?;
    }
    for p in pages {
        let path = out.join(&p.path);
        std::fs::write(&path, &p.text)
            .with_context(|| format!("could not write `{}`", path.display()))?;
    }
    Ok(())
}

/// The files under `out` that differ from `pages`: missing, different, or a figure that no
/// page renders. Empty when the pages in the book are exactly what the JSON gives.
pub fn differences(pages: &[Page], out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut differ: Vec<PathBuf> = pages
        .iter()
        .filter(|p| std::fs::read_to_string(out.join(&p.path)).ok().as_deref() != Some(&p.text))
        .map(|p| out.join(&p.path))
        .collect();
    differ.extend(stale_figures(pages, out)?);
    Ok(differ)
}

fn stale_figures(pages: &[Page], out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let dir = out.join(FIGURES);
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Ok(Vec::new());
    };
    let mut stale = Vec::new();
    for e in entries {
        let e = e.with_context(|| format!("could not list `{}`", dir.display()))?;
        let rel = Path::new(FIGURES).join(e.file_name());
        if !pages.iter().any(|p| p.path == rel) {
            stale.push(e.path());
        }
    }
    stale.sort();
    Ok(stale)
}

fn figure_path(results: &[BatchResult]) -> PathBuf {
    Path::new(FIGURES).join(format!("{}.svg", results[0].plan.world))
}

/// The start of every page: its title, and where the numbers come from.
fn page_start(title: &str, stamp: &Stamp, kind: &str) -> String {
    let mut out = format!("# {title}\n\n");
    let _ = writeln!(
        out,
        "<!-- Written by `ftcbf report` from results/{STAMP} and the JSON files it lists. Do not \
         edit: edit the code or re-measure (scripts/results.sh), then run `ftcbf report`. -->\n"
    );
    let _ = writeln!(
        out,
        "Measured at commit `{}` on {}, on {} ({}); {kind}. Every number on this page is read \
         from the JSON files below by `ftcbf report`; CI runs `ftcbf report --check`, which \
         fails when this page differs from what they give.\n",
        stamp.commit, stamp.date, stamp.machine, stamp.toolchain
    );
    out
}

fn commands(out: &mut String, stamp: &Stamp, runs: &[&StampedRun]) {
    let _ = writeln!(
        out,
        "## How these numbers were made\n\nThis measurement: `{}`. The full one, 1000 trials per \
         world and a search budget of 400 runs per method on every catalogue world, is one \
         command, `scripts/results.sh` (hours on 2 cores; then commit `results/` and \
         `book/src/results/`).\n",
        stamp.script
    );
    let total: u64 = runs.iter().map(|r| r.seconds).sum();
    let _ = writeln!(
        out,
        "The commands, exactly as run (wall time {}):\n\n```sh",
        minutes(total)
    );
    for r in runs {
        match &r.commit {
            Some(c) => {
                let _ = writeln!(out, "{}   # {} s, at commit {c}", r.command, r.seconds);
            }
            None => {
                let _ = writeln!(out, "{}   # {} s", r.command, r.seconds);
            }
        }
    }
    if runs.iter().any(|r| r.commit.is_some()) {
        let _ = writeln!(
            out,
            "```\n\nA command marked with a commit ran later than the others, at that commit \
             (`RESUME=1 scripts/results.sh`, for a world added to the catalogue since); the rest \
             ran at `{}`.\n",
            stamp.commit
        );
        return;
    }
    let _ = writeln!(out, "```\n");
}

fn minutes(seconds: u64) -> String {
    if seconds < 120 {
        format!("{seconds} s")
    } else {
        format!("{:.0} min", seconds as f64 / 60.0)
    }
}

/// Title of a group of worlds by the folder of their files.
fn group_title(dir: &str) -> String {
    match dir {
        "worlds" => "The world catalogue (`worlds/`)".to_string(),
        "tests/worlds_guarantees" => {
            "Attacks that refuted the claim before (`tests/worlds_guarantees/`)".to_string()
        }
        "tests/worlds_ros" => "Robots from ROS-style packages (`tests/worlds_ros/`)".to_string(),
        "tests/worlds_user" => "Worlds written as a user would (`tests/worlds_user/`)".to_string(),
        other => format!("`{other}/`"),
    }
}

fn world_dir(world_file: &str) -> String {
    Path::new(world_file)
        .parent()
        .map(|p| p.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// `applies`, `applies (T s)` or `no`, from `check`'s verdict line.
fn theorem3_short(line: Option<&str>) -> String {
    match line {
        None => "—".to_string(),
        Some(l) if l.starts_with("Theorem 3 applies") => match l.split("over the run's ").nth(1) {
            Some(t) => format!("applies ({t})"),
            None => "applies".to_string(),
        },
        Some(_) => "no".to_string(),
    }
}

fn applies(r: &BatchResult) -> bool {
    r.plan
        .theorem3
        .as_deref()
        .is_some_and(|l| l.starts_with("Theorem 3 applies"))
}

fn percent(num: u64, den: u64) -> String {
    if den == 0 {
        "—".to_string()
    } else {
        format!("{:.1} %", 100.0 * num as f64 / den as f64)
    }
}

/// "k/N (r γ)" for the honest filter that left its γ in the most trials.
fn over_gamma(s: &ControllerSummary) -> String {
    let worst = s
        .estimation
        .iter()
        .filter(|f| f.honest_trials > 0)
        .max_by(|a, b| {
            a.exceeded_rate.total_cmp(&b.exceeded_rate).then(
                a.worst_ratio
                    .unwrap_or(0.0)
                    .total_cmp(&b.worst_ratio.unwrap_or(0.0)),
            )
        });
    match worst {
        None => "—".to_string(),
        Some(f) => format!(
            "{}/{} ({}{})",
            f.exceeded,
            f.honest_trials,
            f.worst_ratio
                .map_or("—".to_string(), |r| format!("{r:.2} γ")),
            if f.refuted { ", REFUTED" } else { "" }
        ),
    }
}

fn catalogue_page(inputs: &Inputs) -> String {
    let stamp = &inputs.stamp;
    let mut out = page_start(
        "Safety certification (`ftcbf batch`)",
        stamp,
        "the trials per world are each command's `--trials` (the table's `trials` column)",
    );
    let _ = writeln!(
        out,
        "FT-CBF-CLF against the all-sensor baseline, on the same seeds (a paired comparison), \
         under each world's declared attack. The claim is the world's Pr(safe) ≥ 1 − ε; \
         \"Theorem 3\" is `ftcbf check`'s verdict, which `batch` writes with every result (its \
         reasons are listed under each table). \"Entered\" counts trials that were ever inside \
         the goal, \"settled\" trials that stayed inside it over the last 2 s. \"Fallback steps\" \
         are control steps still infeasible after Step 3, where the typed safe action was \
         applied. (*) marks trials whose attacks lie outside the declared fault patterns, where \
         no guarantee applies. \"Honest filters over γ\" is Theorem 1's hypothesis measured: of \
         the filters that read no attacked channel, the one that left its γ_i in the most \
         trials, k/N, with its worst ‖x − x̂_i‖/γ_i; (4.5) asks k/N ≤ ε. \"ω sign changes\" is \
         the share of control steps in which the commanded turn rate changed sign, mean over \
         trials / worst trial. How to read a batch: [Batch runs](../guide/batch.md).\n"
    );

    findings(&mut out, &inputs.batches);

    // Group by folder, in the stamp's order of first appearance.
    let mut groups: Vec<(String, Vec<&MeasuredBatch>)> = Vec::new();
    for b in &inputs.batches {
        let dir = world_dir(&b.1[0].plan.world_file);
        match groups.iter_mut().find(|(d, _)| *d == dir) {
            Some((_, v)) => v.push(b),
            None => groups.push((dir, vec![b])),
        }
    }
    for (dir, items) in &groups {
        let _ = writeln!(out, "## {}\n", group_title(dir));
        let _ = writeln!(
            out,
            "| world | Theorem 3 | controller | trials | safe | P(safe) [95 % CI] | vs 1 − ε | \
             collisions | violations | entered | settled | t_goal p50 [s] | fallback steps | \
             honest filters over γ | ω sign changes | mean \\|Δω\\| [rad/s] |"
        );
        let _ = writeln!(
            out,
            "|---|---|---|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|"
        );
        for (_, results) in items {
            for r in results {
                for s in &r.summaries {
                    let outside = if s.outside_fault_pattern_trials > 0 {
                        " (*)"
                    } else {
                        ""
                    };
                    let _ = writeln!(
                        out,
                        "| {} | {} | {} | {} | {} | {:.3} [{:.4}, {:.4}] | {}{} | {} | {} | {} | {} | {} | {} | {} | {:.2} % / {:.2} % | {:.3} |",
                        r.plan.world,
                        theorem3_short(r.plan.theorem3.as_deref()),
                        s.controller,
                        s.trials,
                        s.safe,
                        s.safe_rate,
                        s.safe_ci.lower,
                        s.safe_ci.upper,
                        s.verdict,
                        outside,
                        s.collisions,
                        s.violations,
                        s.goals,
                        s.settled,
                        s.time_to_goal
                            .as_ref()
                            .map_or("—".to_string(), |t| format!("{:.2}", t.p50)),
                        percent(s.steps.infeasible, s.control_steps),
                        over_gamma(s),
                        100.0 * s.smoothness.omega_sign_change_fraction_mean,
                        100.0 * s.smoothness.omega_sign_change_fraction_max,
                        s.smoothness.mean_abs_domega_mean,
                    );
                }
            }
        }
        let _ = writeln!(out);
        let _ = writeln!(out, "`check`'s verdicts, as `batch` wrote them:\n");
        for (_, results) in items {
            let r = &results[0];
            let _ = writeln!(
                out,
                "- `{}`: {}{}",
                r.plan.world,
                r.plan.theorem3.as_deref().unwrap_or("(not recorded)"),
                r.plan
                    .liveness
                    .as_deref()
                    .map_or(String::new(), |l| format!(". Liveness: {l}"))
            );
        }
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "Pr(safe) with its 95 % interval per controller, against the claimed 1 − ε (the \
             figure `batch` draws next to its JSON):\n"
        );
        for (_, results) in items {
            let _ = writeln!(
                out,
                "![{w}]({p})",
                w = results[0].plan.world,
                p = figure_path(results).display()
            );
        }
        let _ = writeln!(out);
    }
    let runs: Vec<&StampedRun> = inputs.batches.iter().map(|(r, _)| r).collect();
    commands(&mut out, stamp, &runs);
    out
}

/// Statements the tables support, computed from them.
fn findings(out: &mut String, batches: &[MeasuredBatch]) {
    let results: Vec<&BatchResult> = batches.iter().flat_map(|(_, r)| r).collect();
    fn ft<'a>(r: &&'a BatchResult) -> Option<&'a ControllerSummary> {
        r.summaries.iter().find(|s| s.controller == "ft-cbf-clf")
    }
    let certified: Vec<&BatchResult> = results.iter().copied().filter(|r| applies(r)).collect();
    let (k, n) = certified
        .iter()
        .filter_map(ft)
        .fold((0, 0), |(k, n), s| (k + s.safe, n + s.trials));
    let unsafe_certified: Vec<String> = certified
        .iter()
        .filter(|r| ft(r).is_some_and(|s| s.safe < s.trials))
        .map(|r| format!("`{}`", r.plan.world))
        .collect();
    let _ = writeln!(out, "What the tables show:\n");
    let _ = writeln!(
        out,
        "- **Where `check` says Theorem 3 applies** ({} worlds), FT-CBF-CLF was safe in {k} of {n} \
         trials; {}.",
        certified.len(),
        if unsafe_certified.is_empty() {
            "no such world had an unsafe trial".to_string()
        } else {
            format!("unsafe trials in {}", unsafe_certified.join(", "))
        }
    );
    let refuted = summaries_where(&results, |s| s.verdict == crate::batch::Verdict::Refuted);
    let _ = writeln!(
        out,
        "- **Refuted claims** (the interval lies below 1 − ε): {}.",
        listed(&refuted, "none")
    );
    let mut better: BTreeMap<bool, Vec<String>> = BTreeMap::new();
    for r in &results {
        for p in &r.paired {
            if p.p_value < 0.05 && p.first == "ft-cbf-clf" {
                better
                    .entry(p.only_first_safe > p.only_second_safe)
                    .or_default()
                    .push(format!("`{}`", r.plan.world));
            }
        }
    }
    let _ = writeln!(
        out,
        "- **Paired against the baseline** (exact McNemar test, p < 0.05): FT-CBF-CLF is the \
         safer in {}; the baseline in {}; the other paired worlds show no significant \
         difference.",
        listed(better.get(&true).map_or(&[][..], |v| v), "none"),
        listed(better.get(&false).map_or(&[][..], |v| v), "none"),
    );
    let gamma_refuted = summaries_where(&results, |s| s.estimation.iter().any(|f| f.refuted));
    let _ = writeln!(
        out,
        "- **Theorem 1's hypothesis** (honest filters within γ with probability ≥ 1 − ε) is \
         refuted by its interval in: {}.\n",
        listed(&gamma_refuted, "none")
    );
}

/// "`world` (controller)" for every summary that meets `pred`.
fn summaries_where(
    results: &[&BatchResult],
    pred: impl Fn(&ControllerSummary) -> bool,
) -> Vec<String> {
    let pred = &pred;
    results
        .iter()
        .flat_map(move |r| {
            r.summaries
                .iter()
                .filter(move |s| pred(s))
                .map(move |s| format!("`{}` ({})", r.plan.world, s.controller))
        })
        .collect()
}

/// The items joined with commas, or `none` when there are none.
fn listed(items: &[String], none: &str) -> String {
    if items.is_empty() {
        none.to_string()
    } else {
        items.join(", ")
    }
}

fn rho(r: &FalsifyRobustness) -> String {
    let v = r.value.map_or("−∞".to_string(), |v| format!("{v:.4}"));
    if r.collided {
        format!("{v}, collided")
    } else {
        v
    }
}

/// Whether `a` is the worse run for the controller than `b` (a collision ranks below every run
/// without one, then smaller ρ), `None` on a tie.
fn worse(a: &FalsifyRobustness, b: &FalsifyRobustness) -> Option<bool> {
    let key = |r: &FalsifyRobustness| (!r.collided, r.value.unwrap_or(f64::NEG_INFINITY));
    let (ka, kb) = (key(a), key(b));
    match ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1)) {
        std::cmp::Ordering::Less => Some(true),
        std::cmp::Ordering::Greater => Some(false),
        std::cmp::Ordering::Equal => None,
    }
}

fn held_out(e: &FalsifyEvaluation) -> String {
    format!(
        "{} ({}/{})",
        e.mean.map_or("−∞".to_string(), |m| format!("{m:.4}")),
        e.unsafe_runs,
        e.runs.len()
    )
}

fn falsify_page(inputs: &Inputs) -> String {
    let stamp = &inputs.stamp;
    let mut out = page_start(
        "Worst attacks found (`ftcbf falsify`)",
        stamp,
        "the runs per search method are each command's `--budget`",
    );
    let _ = writeln!(
        out,
        "The cross-entropy method (CEM) against random search with the same run count and the \
         same seeds, FT-CBF-CLF under test. \"Worst ρ\" is the worst single run (ρ < 0 is \
         unsafe) and the margin that binds; \"held-out mean ρ\" is the best finalist's mean \
         over the held-out seeds (unsafe seeds / seeds in brackets). \"Paired\" plays both \
         methods' best attacks on the same held-out seeds and counts on how many the CEM's is \
         the worse for the controller and on how many random search's is, with the exact \
         two-sided sign test; \"tie\" when p ≥ 0.05. \"Theorem 3\" is `check`'s verdict, read \
         from the same world's batch result. How the search works: \
         [Searching for the worst attack](../guide/falsify.md).\n"
    );
    let t3: BTreeMap<&str, &BatchResult> = inputs
        .batches
        .iter()
        .flat_map(|(_, r)| r)
        .map(|r| (r.plan.world_file.as_str(), r))
        .collect();
    let mut unsafe_certified = Vec::new();
    let mut unsafe_any = Vec::new();
    let _ = writeln!(
        out,
        "| world | Theorem 3 | CEM worst ρ (binding) | random worst ρ | CEM unsafe runs | random \
         unsafe runs | CEM held-out mean ρ | random held-out mean ρ | worst run: worse for the \
         controller | paired: CEM : random (sign test) | paired: better search | no attack: \
         held-out mean ρ (best attack worse : better, CEM; random) |"
    );
    let _ = writeln!(
        out,
        "|---|---|---:|---:|---:|---:|---:|---:|---|---|---|---|"
    );
    for (_, f) in inputs.falsify.iter().filter(|(_, f)| !f.aims_at_fallback()) {
        let batch = t3.get(f.world_file.as_str()).copied();
        let cem = f.methods.iter().find(|m| m.method == "cem");
        let random = f.methods.iter().find(|m| m.method == "random");
        let unsafe_runs: usize = f.methods.iter().map(|m| m.unsafe_runs).sum();
        if unsafe_runs > 0 {
            unsafe_any.push(format!("`{}`", f.world));
            if batch.is_some_and(applies) {
                unsafe_certified.push(format!("`{}`", f.world));
            }
        }
        let _ = writeln!(out, "{}", falsify_row(f, batch, cem, random));
    }
    let _ = writeln!(out);
    let _ = writeln!(out, "What the table shows:\n");
    let _ = writeln!(
        out,
        "- **Unsafe runs where Theorem 3 applies**: {}.",
        listed(&unsafe_certified, "none, for either method")
    );
    let _ = writeln!(
        out,
        "- **Worlds where some searched attack made FT-CBF-CLF unsafe**: {}.\n",
        listed(&unsafe_any, "none")
    );
    let _ = writeln!(out, "The worst attack each method found:\n");
    for (_, f) in inputs.falsify.iter().filter(|(_, f)| !f.aims_at_fallback()) {
        worst_attacks(&mut out, f);
    }
    let _ = writeln!(out);
    fallback_section(&mut out, inputs);
    let runs: Vec<&StampedRun> = inputs.falsify.iter().map(|(r, _)| r).collect();
    commands(&mut out, stamp, &runs);
    out
}

impl FalsifyJson {
    /// Searched with `--family fallback` (attacks aimed at the safe stop).
    fn aims_at_fallback(&self) -> bool {
        self.family.as_deref() == Some("fallback")
    }
}

/// One line per search method of `f`: the worst attack it found and its ρ.
fn worst_attacks(out: &mut String, f: &FalsifyJson) {
    for m in &f.methods {
        let _ = writeln!(
            out,
            "- `{}`, {}: {} (ρ = {})",
            f.world,
            if m.method == "cem" {
                "CEM"
            } else {
                "random search"
            },
            m.witness.description,
            rho(&m.witness.robustness)
        );
    }
}

/// The searches with `--family fallback`: one row per world and method, then their worst
/// attacks. Nothing when there are none.
fn fallback_section(out: &mut String, inputs: &Inputs) {
    let searched: Vec<&FalsifyJson> = inputs
        .falsify
        .iter()
        .map(|(_, f)| f)
        .filter(|f| f.aims_at_fallback())
        .collect();
    if searched.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        "## Attacks aimed at the safe stop (`--family fallback`)\n\nWorlds where two sources \
         cannot be told apart, so the safe stop (`[control] fallback = \"brake\"`) is what keeps \
         the robot safe, searched with attacks aimed at its weak spots: a stealthy bias whose \
         detector threshold straddles the evidence test's edge, a ramp that reaches its full \
         offset at a moment the search chooses and is held, a slow alternation (the rows \
         conflict, agree, conflict again), and an offset held between the two estimates \
         ([The safe stop](../theory/safe-stop.md)). The objective is ρ, as above.\n"
    );
    let _ = writeln!(
        out,
        "| world | method | runs | unsafe runs | worst ρ (binding) | best attack on held-out \
         seeds: mean ρ (unsafe) | no attack: held-out mean ρ |"
    );
    let _ = writeln!(out, "|---|---|---:|---:|---:|---:|---:|");
    for f in &searched {
        for m in &f.methods {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} ({}) | {} | {} |",
                f.world,
                if m.method == "cem" { "CEM" } else { "random" },
                m.runs,
                m.unsafe_runs,
                rho(&m.witness.robustness),
                m.witness.robustness.binding,
                held_out(&m.finalists[0]),
                f.attack_free.as_ref().map_or("—".to_string(), |a| a
                    .mean
                    .map_or("−∞".to_string(), |v| format!("{v:.4}")))
            );
        }
    }
    let total: usize = searched
        .iter()
        .flat_map(|f| &f.methods)
        .map(|m| m.runs)
        .sum();
    let unsafe_runs: usize = searched
        .iter()
        .flat_map(|f| &f.methods)
        .map(|m| m.unsafe_runs)
        .sum();
    let _ = writeln!(
        out,
        "\n**Unsafe runs under attacks aimed at the safe stop**: {unsafe_runs} of {total}.\n\nThe \
         worst run of each search:\n"
    );
    for f in &searched {
        worst_attacks(out, f);
    }
    let _ = writeln!(out);
}

/// One world's row of the falsify table.
fn falsify_row(
    f: &FalsifyJson,
    batch: Option<&BatchResult>,
    cem: Option<&FalsifyMethod>,
    random: Option<&FalsifyMethod>,
) -> String {
    let cell = |m: Option<&FalsifyMethod>, g: &dyn Fn(&FalsifyMethod) -> String| {
        m.map_or("—".to_string(), g)
    };
    let worst_run = match (cem, random) {
        (Some(c), Some(r)) => match worse(&c.witness.robustness, &r.witness.robustness) {
            Some(true) => "CEM".to_string(),
            Some(false) => "**random**".to_string(),
            None => "tie".to_string(),
        },
        _ => "—".to_string(),
    };
    let (paired, paired_better) = match &f.paired {
        Some(p) => (
            format!(
                "{} : {} of {} (p = {})",
                p.cem_worse,
                p.random_worse,
                p.seeds,
                p_value(p.p)
            ),
            if p.p >= 0.05 {
                "tie".to_string()
            } else if p.cem_worse > p.random_worse {
                "CEM".to_string()
            } else {
                "**random**".to_string()
            },
        ),
        None => ("—".to_string(), "—".to_string()),
    };
    let attack_free = f.attack_free.as_ref().map_or("—".to_string(), |a| {
        let counts: Vec<String> = a
            .moved
            .iter()
            .map(|m| {
                format!(
                    "{} : {}{}",
                    m.attack_worse,
                    m.attack_free_worse,
                    if m.p < 0.05 && m.attack_worse > m.attack_free_worse {
                        ""
                    } else {
                        " (not moved)"
                    }
                )
            })
            .collect();
        format!(
            "{} ({})",
            a.mean.map_or("−∞".to_string(), |v| format!("{v:.4}")),
            counts.join("; ")
        )
    });
    format!(
        "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
        f.world,
        theorem3_short(batch.and_then(|b| b.plan.theorem3.as_deref())),
        cell(cem, &|m| format!(
            "{} ({})",
            rho(&m.witness.robustness),
            m.witness.robustness.binding
        )),
        cell(random, &|m| rho(&m.witness.robustness)),
        cell(cem, &|m| format!("{}/{}", m.unsafe_runs, m.runs)),
        cell(random, &|m| format!("{}/{}", m.unsafe_runs, m.runs)),
        cell(cem, &|m| held_out(&m.finalists[0])),
        cell(random, &|m| held_out(&m.finalists[0])),
        worst_run,
        paired,
        paired_better,
        attack_free,
    )
}

fn p_value(p: f64) -> String {
    if p >= 0.01 {
        format!("{p:.2}")
    } else {
        format!("{p:.1e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rob(value: Option<f64>, collided: bool) -> FalsifyRobustness {
        FalsifyRobustness {
            value,
            collided,
            binding: "floor".into(),
        }
    }

    #[test]
    fn a_collision_or_a_smaller_rho_is_the_worse_run() {
        assert_eq!(
            worse(&rob(Some(0.1), false), &rob(Some(0.2), false)),
            Some(true)
        );
        assert_eq!(
            worse(&rob(Some(0.3), true), &rob(Some(-1.0), false)),
            Some(true)
        );
        assert_eq!(
            worse(&rob(None, false), &rob(Some(-5.0), false)),
            Some(true)
        );
        assert_eq!(worse(&rob(Some(0.2), false), &rob(Some(0.2), false)), None);
        assert_eq!(
            worse(&rob(Some(0.2), false), &rob(Some(0.1), false)),
            Some(false)
        );
    }

    #[test]
    fn theorem3_short_keeps_the_horizon() {
        assert_eq!(
            theorem3_short(Some(
                "Theorem 3 applies: Pr(safe) ≥ 1 − ε = 0.95 for any single fault pattern over the run's 25 s"
            )),
            "applies (25 s)"
        );
        assert_eq!(
            theorem3_short(Some(
                "Theorem 3 applies: Pr(safe) ≥ 1 − ε = 0.95 for any single fault pattern"
            )),
            "applies"
        );
        assert_eq!(theorem3_short(Some("Theorem 3 does NOT apply: x")), "no");
        assert_eq!(theorem3_short(None), "—");
    }

    #[test]
    fn a_run_measured_at_another_commit_says_so() {
        let text = "script = \"s\"\ncommit = \"a\"\ndate = \"d\"\nmachine = \"m\"\ntoolchain = \"t\"\n\n[[run]]\njson = \"x.json\"\ncommand = \"ftcbf batch x\"\nseconds = 3\n\n[[run]]\njson = \"y.json\"\ncommand = \"ftcbf batch y\"\nseconds = 4\ncommit = \"b\"\n";
        let stamp: Stamp = toml::from_str(text).expect("a stamp");
        assert_eq!(stamp.run[0].commit, None);
        assert_eq!(stamp.run[1].commit.as_deref(), Some("b"));
        let runs: Vec<&StampedRun> = stamp.run.iter().collect();
        let mut out = String::new();
        commands(&mut out, &stamp, &runs);
        assert!(out.contains("ftcbf batch x   # 3 s\n"), "{out}");
        assert!(
            out.contains("ftcbf batch y   # 4 s, at commit b\n"),
            "{out}"
        );
        assert!(out.contains("the rest ran at `a`"), "{out}");
    }

    #[test]
    fn a_stamp_with_an_unknown_key_is_refused() {
        let text = "script = \"s\"\ncommit = \"a\"\ndate = \"d\"\nmachine = \"m\"\ntoolchain = \"t\"\nextra = 3\n";
        let e = toml::from_str::<Stamp>(text).expect_err("unknown key");
        assert!(e.to_string().contains("extra"), "{e}");
    }
}

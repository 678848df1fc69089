//! Scenario search (`ftcbf falsify WORLD --scenario`): falsify `ftcbf check` itself.
//!
//! The attack search ([`super::falsify`]) works on one fixed world, and every catalogue world
//! where `check` says Theorem 3 applies comes out safe: that says little about `check`'s verdict
//! on worlds nobody tuned. The scenario search also moves the world inside declared ranges
//! ([`Ranges`]: obstacle positions and sizes, start, goal, sensor noise, the world's own attack
//! onset), keeps only the variants for which `check` says Theorem 3 applies and predicts the
//! robot live, and attacks each of them. Every unsafe run on such a variant whose world (with
//! the unsafe attack declared) `check` still accepts is a **defect** of `check` or of the
//! controller: it is reported and written as a regression world.
//!
//! Variants are edited in memory ([`World::with_file`]: the robot's URDF is not read again) and
//! written as world files only for the defects (the written file replays the run bit for bit,
//! checked).
//!
//! Budget (runs, each one simulation): three quarters screen variants — every accepted variant
//! runs its own (onset-shifted) attacks and [`ATTACKS_PER_VARIANT`] uniform attacks from the
//! attack space, one seed each — and a quarter refines: CMA-ES ([`super::cmaes`]) on the
//! continuous attack parameters of the worst screened searched runs (up to [`REFINED`] distinct
//! variants), each on its run's variant and seed (so ρ is a deterministic function of the
//! attack). Variants are drawn from seeded streams, checked and run on the batch pool and
//! collected in order: the same seed gives the same report for any `--jobs` (the time aside).
//!
//! One file (about 1,100 lines of code): the ranges a variant is drawn from, the variant, its
//! check, the search over variants and the files it writes all read the same [`Ranges`] and
//! [`Variant`]; the attack search it calls is `super::search`.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use crate::progress::{Progress, Silent};
use anyhow::{anyhow, Context};
use ftcbf_sim::analysis::check::check_world;
use ftcbf_sim::attacks::AttackSpec;
use ftcbf_sim::obstacles::{MeshScale, ShapeSpec};
use ftcbf_sim::runner::{run, RunOptions};
use ftcbf_sim::world::{Dynamics, World, WorldFile};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use toml_edit::{Array, DocumentMut, InlineTable, Item};

use super::search::{run_seed, uniform};
use super::space::{Candidate, SearchSpace};
use super::{cmaes, Robustness, Settings, WorldTemplate};
use crate::batch::{run_parallel, trial_seed, worker_pool};

/// Smallest budget of a scenario search: two variants' screens.
pub const MIN_BUDGET: usize = 2 * (ATTACKS_PER_VARIANT + 1);
/// Uniform attacks run on every accepted variant, besides its own attacks.
pub const ATTACKS_PER_VARIANT: usize = 3;
/// Distinct variants whose worst searched run CMA-ES refines.
pub const REFINED: usize = 2;
/// Variants drawn per accepted variant wanted, at most (then the search stops drawing).
const TRIES_PER_ACCEPTED: usize = 4;
/// Stream tags of the variants and of their attacks ("SCN", "SCA", "SCC").
const VARIANT_TAG: u64 = 0x53_43_4e;
const ATTACK_TAG: u64 = 0x53_43_41;
const CMA_TAG: u64 = 0x53_43_43;

/// How far the scenario search may move the world (the `[falsify]` table, then `--range`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Ranges {
    /// Largest shift of each obstacle along x and y \[m\] (half-spaces stay).
    pub obstacle_shift: f64,
    /// Largest relative change of each obstacle's size.
    pub obstacle_scale: f64,
    /// Largest shift of the start along x and y \[m\].
    pub start_shift: f64,
    /// Largest change of the start heading \[rad\].
    pub start_heading: f64,
    /// Largest shift of the goal centre and waypoints along x and y \[m\].
    pub goal_shift: f64,
    /// Largest relative change of every channel's noise standard deviation.
    pub noise: f64,
    /// Largest shift of the world's own attacks' windows \[s\].
    pub onset_shift: f64,
}

/// The keys of [`Ranges`], as the `[falsify]` table and `--range` name them.
pub const RANGE_KEYS: [&str; 7] = [
    "obstacle_shift",
    "obstacle_scale",
    "start_shift",
    "start_heading",
    "goal_shift",
    "noise",
    "onset_shift",
];

impl Default for Ranges {
    /// A ground robot's: obstacles ±0.2 m and ±20 % in size, start ±0.15 m and ±0.2 rad, goal
    /// ±0.2 m, noise ±20 %, attack windows ±2 s.
    fn default() -> Self {
        Ranges {
            obstacle_shift: 0.2,
            obstacle_scale: 0.2,
            start_shift: 0.15,
            start_heading: 0.2,
            goal_shift: 0.2,
            noise: 0.2,
            onset_shift: 2.0,
        }
    }
}

impl Ranges {
    fn slot(&mut self, key: &str) -> Option<&mut f64> {
        Some(match key {
            "obstacle_shift" => &mut self.obstacle_shift,
            "obstacle_scale" => &mut self.obstacle_scale,
            "start_shift" => &mut self.start_shift,
            "start_heading" => &mut self.start_heading,
            "goal_shift" => &mut self.goal_shift,
            "noise" => &mut self.noise,
            "onset_shift" => &mut self.onset_shift,
            _ => return None,
        })
    }

    /// Sets `key` to `v`, or says why not.
    fn set(&mut self, key: &str, v: f64) -> Result<(), String> {
        let relative = matches!(key, "obstacle_scale" | "noise");
        let slot = self.slot(key).ok_or_else(|| {
            format!(
                "unknown range `{key}`; expected one of {}",
                RANGE_KEYS.join(", ")
            )
        })?;
        if !(v.is_finite() && v >= 0.0 && (!relative || v < 1.0)) {
            return Err(format!(
                "`{key}` = {v}: expected a finite number ≥ 0{}",
                if relative {
                    " and < 1 (a relative range)"
                } else {
                    ""
                }
            ));
        }
        *slot = v;
        Ok(())
    }

    /// The defaults, then the world's `[falsify]` table, then `overrides` (`--range KEY=VALUE`).
    pub fn resolve(world: &World, overrides: &[(String, f64)]) -> anyhow::Result<Ranges> {
        let mut r = Ranges::default();
        if let Some(t) = &world.file.falsify {
            // The declared keys (absent ones are not serialised), in the table's names.
            let declared = toml::Table::try_from(t).context("reading the [falsify] table")?;
            for (key, v) in declared {
                let v = v.as_float().unwrap_or(f64::NAN);
                r.set(&key, v)
                    .map_err(|e| anyhow!("{}: [falsify] {e}", world.path.display()))?;
            }
        }
        for (key, v) in overrides {
            r.set(key, *v).map_err(|e| anyhow!("--range {e}"))?;
        }
        Ok(r)
    }
}

/// Parses `--range KEY=VALUE`.
pub fn parse_range(s: &str) -> Result<(String, f64), String> {
    let (k, v) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}`: expected KEY=VALUE, e.g. obstacle_shift=0.3"))?;
    let v: f64 = v
        .trim()
        .parse()
        .map_err(|_| format!("`{s}`: `{}` is not a number", v.trim()))?;
    let k = k.trim();
    if !RANGE_KEYS.contains(&k) {
        return Err(format!(
            "`{s}`: unknown range `{k}`; expected one of {}",
            RANGE_KEYS.join(", ")
        ));
    }
    Ok((k.to_string(), v))
}

/// One variant of the world: what moved, by how much.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Variant {
    /// Index (its random stream).
    pub index: usize,
    /// Per obstacle: shift (x, y) \[m\] and size factor.
    pub obstacles: Vec<([f64; 2], f64)>,
    /// Start shift (x, y) \[m\] and heading change \[rad\].
    pub start: [f64; 3],
    /// Goal shift (x, y) \[m\].
    pub goal: [f64; 2],
    /// Per sensor channel: noise factor.
    pub noise: Vec<f64>,
    /// Shift of the own attacks' windows \[s\].
    pub onset: f64,
}

/// Rounded to `digits` decimals (variants are written to files: short numbers).
fn round_to(x: f64, digits: i32) -> f64 {
    let f = 10f64.powi(digits);
    (x * f).round() / f
}

/// Rounded to 6 significant digits: a moved value (a sum or product of short numbers) is
/// written short, and the in-memory variant holds exactly what the file says.
fn sig6(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    format!("{x:.5e}").parse().unwrap_or(x)
}

/// Uniform in [−r, r], rounded to `digits` decimals.
fn sym(rng: &mut ChaCha8Rng, r: f64, digits: i32) -> f64 {
    if r == 0.0 {
        return 0.0;
    }
    round_to(rng.random_range(-r..=r), digits)
}

fn scaled(shape: &ShapeSpec, f: f64) -> ShapeSpec {
    let mut s = shape.clone();
    let f = |v: &mut f64| *v = sig6(*v * f);
    match &mut s {
        ShapeSpec::Cuboid { half_extents } => half_extents.iter_mut().for_each(f),
        ShapeSpec::Ball { radius } => f(radius),
        ShapeSpec::Cylinder {
            radius,
            half_height,
        }
        | ShapeSpec::Capsule {
            radius,
            half_height,
        }
        | ShapeSpec::Cone {
            radius,
            half_height,
        } => {
            f(radius);
            f(half_height);
        }
        ShapeSpec::ConvexHull { points } => points.iter_mut().flatten().for_each(f),
        ShapeSpec::HalfSpace { .. } | ShapeSpec::OccupancyMap { .. } => {}
        ShapeSpec::TriMesh {
            vertices,
            file,
            scale,
            ..
        } => {
            if file.is_some() {
                *scale = Some(match scale.unwrap_or(MeshScale::Uniform(1.0)) {
                    MeshScale::Uniform(mut k) => {
                        f(&mut k);
                        MeshScale::Uniform(k)
                    }
                    MeshScale::PerAxis(mut k) => {
                        k.iter_mut().for_each(f);
                        MeshScale::PerAxis(k)
                    }
                });
            } else {
                vertices.iter_mut().flatten().for_each(f);
            }
        }
    }
    s
}

impl Variant {
    /// Variant `index` of `world` within `r` (deterministic in `seed` and `index`).
    pub fn draw(world: &World, r: &Ranges, seed: u64, index: usize) -> Variant {
        let mut rng =
            ChaCha8Rng::seed_from_u64(trial_seed(seed, (VARIANT_TAG << 32) + index as u64));
        let f = &world.file;
        let obstacles = f
            .obstacles
            .iter()
            .map(|o| {
                if matches!(o.shape, ShapeSpec::HalfSpace { .. }) {
                    return ([0.0, 0.0], 1.0);
                }
                let dx = sym(&mut rng, r.obstacle_shift, 3);
                let dy = sym(&mut rng, r.obstacle_shift, 3);
                ([dx, dy], 1.0 + sym(&mut rng, r.obstacle_scale, 3))
            })
            .collect();
        let start = [
            sym(&mut rng, r.start_shift, 3),
            sym(&mut rng, r.start_shift, 3),
            sym(&mut rng, r.start_heading, 3),
        ];
        let goal = [
            sym(&mut rng, r.goal_shift, 3),
            sym(&mut rng, r.goal_shift, 3),
        ];
        let noise = f
            .sensors
            .iter()
            .map(|_| 1.0 + sym(&mut rng, r.noise, 3))
            .collect();
        let onset = sym(&mut rng, r.onset_shift, 2);
        Variant {
            index,
            obstacles,
            start,
            goal,
            noise,
            onset,
        }
    }

    /// `file` moved by this variant, with `controller` as its controller.
    pub fn apply(&self, file: &WorldFile, controller: &str) -> WorldFile {
        let mut f = file.clone();
        let add = |v: &mut f64, d: f64| *v = sig6(*v + d);
        for (o, (d, s)) in f.obstacles.iter_mut().zip(&self.obstacles) {
            add(&mut o.position[0], d[0]);
            add(&mut o.position[1], d[1]);
            if *s != 1.0 {
                o.shape = scaled(&o.shape, *s);
            }
        }
        match f.dynamics {
            Dynamics::Rapier => {
                if let Some(rb) = &mut f.robot {
                    add(&mut rb.start.x, self.start[0]);
                    add(&mut rb.start.y, self.start[1]);
                    add(&mut rb.start.theta, self.start[2]);
                }
            }
            Dynamics::Linear => {
                if let Some(l) = &mut f.linear {
                    add(&mut l.x0[0], self.start[0]);
                    add(&mut l.x0[1], self.start[1]);
                }
            }
        }
        add(&mut f.goal.center[0], self.goal[0]);
        add(&mut f.goal.center[1], self.goal[1]);
        for w in &mut f.goal.waypoints {
            add(&mut w[0], self.goal[0]);
            add(&mut w[1], self.goal[1]);
        }
        for (s, k) in f.sensors.iter_mut().zip(&self.noise) {
            s.noise_std = sig6(s.noise_std * k);
        }
        let t = f.duration;
        for a in &mut f.attacks {
            let start = sig6((a.start + self.onset).clamp(0.0, 0.9 * t));
            if let Some(e) = a.end {
                a.end = Some(sig6((e + self.onset).max(start + 0.02)));
            }
            a.start = start;
        }
        f.control.controller = match controller {
            "baseline" => ftcbf_sim::world::ControllerKindSpec::Baseline,
            "nominal" => ftcbf_sim::world::ControllerKindSpec::Nominal,
            _ => ftcbf_sim::world::ControllerKindSpec::FtCbfClf,
        };
        f
    }

    /// What moved, in one line.
    pub fn describe(&self) -> String {
        let moved = self
            .obstacles
            .iter()
            .filter(|(d, s)| d != &[0.0, 0.0] || *s != 1.0)
            .count();
        format!(
            "variant {}: {moved} obstacle(s) moved/resized, start {:+}, {:+} m, {:+} rad, goal {:+}, {:+} m, noise ×[{}], attack windows {:+} s",
            self.index,
            self.start[0],
            self.start[1],
            self.start[2],
            self.goal[0],
            self.goal[1],
            self.noise
                .iter()
                .map(|k| format!("{k}"))
                .collect::<Vec<_>>()
                .join(", "),
            self.onset
        )
    }
}

/// What `check` said about a variant.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Checked {
    /// Theorem 3 applies.
    pub applies: bool,
    /// Liveness predicted.
    pub live: bool,
    /// ε of the verdict.
    pub epsilon: f64,
    /// The verdict line (or why the variant is not a valid world).
    pub verdict: String,
}

/// `check` on `world`.
fn check(world: &World) -> Checked {
    match check_world(world) {
        Ok(r) => Checked {
            applies: r.verdict.applies,
            live: r.liveness.live(),
            epsilon: r.verdict.epsilon,
            verdict: r.verdict.line(),
        },
        Err(e) => Checked {
            applies: false,
            live: false,
            epsilon: 1.0,
            verdict: format!("check failed: {e}"),
        },
    }
}

/// One run of the scenario search.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScenarioRun {
    /// Index of the accepted variant in [`ScenarioReport::accepted`].
    pub variant: usize,
    /// Its seed.
    pub seed: u64,
    /// `own` (the variant's own attacks), `search` (a uniform attack) or `cmaes`.
    pub phase: &'static str,
    /// The attack, in one line.
    pub attack: String,
    /// The searched point (none for the own attacks).
    pub candidate: Option<Candidate>,
    /// Its robustness.
    pub robustness: Robustness,
}

/// An unsafe run on a variant `check` accepts with the run's attack declared.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Defect {
    /// The run.
    pub run: ScenarioRun,
    /// `check`'s verdict on the written world.
    pub verdict: String,
    /// The regression world written (by the command; empty in the report of [`scenario`]).
    pub file: String,
}

/// How the budget is spent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScenarioPlan {
    /// Runs allowed.
    pub budget: usize,
    /// Runs per accepted variant in the screen (own attacks, if any, plus uniform attacks).
    pub runs_per_variant: usize,
    /// Accepted variants wanted.
    pub variants_wanted: usize,
    /// Variants drawn at most.
    pub max_tries: usize,
    /// Runs of the CMA-ES refinement.
    pub refine_runs: usize,
}

impl ScenarioPlan {
    /// A quarter of the budget for the refinement, the rest for the screen.
    pub fn new(budget: usize, own_attacks: bool) -> anyhow::Result<ScenarioPlan> {
        let runs_per_variant = ATTACKS_PER_VARIANT + usize::from(own_attacks);
        if budget < 2 * runs_per_variant {
            return Err(anyhow!(
                "--budget {budget} is too small for --scenario; expected at least {}",
                2 * runs_per_variant
            ));
        }
        let refine_runs = budget / 4;
        let variants_wanted = (budget - refine_runs) / runs_per_variant;
        Ok(ScenarioPlan {
            budget,
            runs_per_variant,
            variants_wanted,
            max_tries: TRIES_PER_ACCEPTED * variants_wanted,
            refine_runs: budget - variants_wanted * runs_per_variant,
        })
    }
}

/// The report of a scenario search (`--json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScenarioReport {
    /// World name.
    pub world: String,
    /// World file as given.
    pub world_file: String,
    /// Controller under test.
    pub controller: String,
    /// Base seed.
    pub seed: u64,
    /// The ranges.
    pub ranges: Ranges,
    /// The plan.
    pub plan: ScenarioPlan,
    /// Variants drawn and checked.
    pub variants_tried: usize,
    /// Of which not valid worlds (e.g. a goal moved off the floor).
    pub variants_invalid: usize,
    /// Of which `check` said Theorem 3 does not apply.
    pub variants_not_applies: usize,
    /// Of which `check` said it applies but predicted the robot not live.
    pub variants_not_live: usize,
    /// Of which accepted (applies and live).
    pub variants_accepted: usize,
    /// The accepted variants, in order.
    pub accepted: Vec<Variant>,
    /// Runs made.
    pub runs: usize,
    /// Of which unsafe.
    pub unsafe_runs: usize,
    /// Unsafe runs on accepted variants where `check`, with the run's attack declared, still
    /// says Theorem 3 applies and the robot is live: defects.
    pub unsafe_where_applies: usize,
    /// Unsafe runs on accepted variants where `check` declines once the run's attack is
    /// declared (e.g. liveness under that attack): outside the guarantee, not defects.
    pub unsafe_check_declines: usize,
    /// The defects.
    pub defects: Vec<Defect>,
    /// The worst run of all.
    pub worst: Option<ScenarioRun>,
    /// The CMA-ES refinements.
    pub cmaes: Vec<ScenarioCma>,
    /// Wall time \[s\] (the only field that differs between two runs of the same command).
    pub time_seconds: f64,
}

/// One CMA-ES refinement of the scenario search.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScenarioCma {
    /// The accepted variant.
    pub variant: usize,
    /// The fixed seed.
    pub seed: u64,
    /// ρ of the starting run.
    pub start: f64,
    /// The lowest ρ found.
    pub best: f64,
    /// Runs.
    pub runs: usize,
    /// Step size at the start and at the end.
    pub sigma: [f64; 2],
}

/// An accepted variant, ready to run.
struct Accepted {
    variant: Variant,
    world: World,
}

/// The variants drawn and checked (phase 1), with the count of each refusal.
struct Drawn {
    accepted: Vec<Accepted>,
    tried: usize,
    invalid: usize,
    not_applies: usize,
    not_live: usize,
}

/// One screening run to make (phase 2): a variant, its seed, and an attack (`None`: the
/// world's own attacks).
struct Task {
    variant: usize,
    seed: u64,
    candidate: Option<Candidate>,
}

/// What every phase of the scenario search reads.
struct ScenarioSearch<'a> {
    template: &'a WorldTemplate,
    settings: &'a Settings,
    ranges: &'a Ranges,
    space: SearchSpace,
    plan: ScenarioPlan,
    pool: rayon::ThreadPool,
    progress: &'a dyn Progress,
}

/// The scenario search on `template`'s world, telling `progress` of its `settings.budget` runs
/// and of each phase, and finishing it when the runs are done.
pub fn scenario(
    template: &WorldTemplate,
    settings: &Settings,
    ranges: &Ranges,
    progress: &dyn Progress,
) -> anyhow::Result<ScenarioReport> {
    let clock = Instant::now();
    let base = &template.world;
    let search = ScenarioSearch {
        template,
        settings,
        ranges,
        space: SearchSpace::new(base).with_context(|| format!("world `{}`", base.name))?,
        plan: ScenarioPlan::new(settings.budget, !base.file.attacks.is_empty())?,
        pool: worker_pool(settings.jobs)?,
        progress,
    };
    progress.start(settings.budget as u64, &base.name);
    let drawn = search.draw_variants()?;
    let mut runs = search.screen(&drawn.accepted)?;
    let cma_traces = search.refine(&drawn.accepted, &mut runs)?;
    progress.finish();
    let unsafe_runs: Vec<&ScenarioRun> = runs.iter().filter(|r| r.robustness.is_unsafe()).collect();
    let (defects, declines) = search.recheck(&drawn.accepted, &unsafe_runs)?;
    let worst = runs
        .iter()
        .reduce(|a, b| {
            if b.robustness.cmp_worse(&a.robustness).is_lt() {
                b
            } else {
                a
            }
        })
        .cloned();
    Ok(ScenarioReport {
        world: base.name.clone(),
        world_file: template.path.display().to_string(),
        controller: settings.controller.name().to_string(),
        seed: settings.seed,
        ranges: *ranges,
        plan: search.plan,
        variants_tried: drawn.tried,
        variants_invalid: drawn.invalid,
        variants_not_applies: drawn.not_applies,
        variants_not_live: drawn.not_live,
        variants_accepted: drawn.accepted.len(),
        accepted: drawn.accepted.into_iter().map(|a| a.variant).collect(),
        unsafe_runs: unsafe_runs.len(),
        runs: runs.len(),
        unsafe_where_applies: defects.len(),
        unsafe_check_declines: declines,
        defects,
        worst,
        cmaes: cma_traces,
        time_seconds: clock.elapsed().as_secs_f64(),
    })
}

impl ScenarioSearch<'_> {
    /// Phase 1: draw and check variants, in batches, until enough are accepted.
    fn draw_variants(&self) -> anyhow::Result<Drawn> {
        let (base, plan, settings) = (&self.template.world, &self.plan, self.settings);
        let controller = settings.controller.name();
        let mut d = Drawn {
            accepted: Vec::new(),
            tried: 0,
            invalid: 0,
            not_applies: 0,
            not_live: 0,
        };
        while d.accepted.len() < plan.variants_wanted && d.tried < plan.max_tries {
            self.progress.phase(&format!(
                "{}: checking variants ({} accepted of {})",
                base.name,
                d.accepted.len(),
                d.tried
            ));
            let n = (plan.variants_wanted - d.accepted.len()).min(plan.max_tries - d.tried);
            let batch: Vec<usize> = (d.tried..d.tried + n).collect();
            let checked = run_parallel(&self.pool, &batch, &Silent, |&i| {
                let v = Variant::draw(base, self.ranges, settings.seed, i);
                let world = base.with_file(v.apply(&base.file, controller)).ok();
                let c = world.as_ref().map(check);
                Ok((v, world, c))
            })?;
            d.tried += n;
            for (v, world, c) in checked {
                match (world, c) {
                    (Some(world), Some(c)) if c.applies && c.live => {
                        if d.accepted.len() < plan.variants_wanted {
                            d.accepted.push(Accepted { variant: v, world });
                        }
                    }
                    (Some(_), Some(c)) if c.applies => d.not_live += 1,
                    (Some(_), _) => d.not_applies += 1,
                    (None, _) => d.invalid += 1,
                }
            }
        }
        Ok(d)
    }

    /// Phase 2, the screen: own attacks and uniform attacks on every accepted variant, one seed
    /// each.
    fn screen(&self, accepted: &[Accepted]) -> anyhow::Result<Vec<ScenarioRun>> {
        let seed = self.settings.seed;
        let mut tasks = Vec::new();
        for (k, a) in accepted.iter().enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(trial_seed(
                seed,
                (ATTACK_TAG << 32) + a.variant.index as u64,
            ));
            let runs = self.plan.runs_per_variant;
            for j in 0..runs {
                let candidate = if j == 0 && runs > ATTACKS_PER_VARIANT {
                    None
                } else {
                    Some(uniform(&self.space, &mut rng))
                };
                tasks.push(Task {
                    variant: k,
                    seed: run_seed(seed, (k * runs + j) as u64),
                    candidate,
                });
            }
        }
        self.progress.phase(&format!(
            "{}: {} accepted variants × {} attacks",
            self.template.world.name,
            accepted.len(),
            self.plan.runs_per_variant
        ));
        run_parallel(&self.pool, &tasks, self.progress, |t| {
            self.one(accepted, t.variant, t.seed, t.candidate.as_ref())
        })
    }

    /// One run of an accepted variant under `candidate` (`None`: its own attacks).
    fn one(
        &self,
        accepted: &[Accepted],
        variant: usize,
        seed: u64,
        candidate: Option<&Candidate>,
    ) -> anyhow::Result<ScenarioRun> {
        let a = &accepted[variant];
        let (world, attack) = match candidate {
            None => (
                None,
                a.world
                    .file
                    .attacks
                    .iter()
                    .map(|s| s.display_label())
                    .collect::<Vec<_>>()
                    .join("; "),
            ),
            Some(c) => (
                Some(
                    self.template
                        .variant_with(&a.world, &self.space.decode(c))?,
                ),
                self.space.describe(c),
            ),
        };
        let w = world.as_ref().unwrap_or(&a.world);
        let opts = RunOptions {
            seed: Some(seed),
            controller: Some(self.settings.controller),
            duration: None,
        };
        let s = run(w, &opts).with_context(|| format!("{}: {attack}", a.variant.describe()))?;
        let robustness = Robustness::of(w, &s)
            .ok_or_else(|| anyhow!("the world has no safe set and no obstacle"))?;
        Ok(ScenarioRun {
            variant,
            seed,
            phase: if candidate.is_some() { "search" } else { "own" },
            attack,
            candidate: candidate.cloned(),
            robustness,
        })
    }

    /// Phase 3, CMA-ES on the worst searched runs of up to REFINED distinct variants; the runs
    /// it makes join `runs`.
    fn refine(
        &self,
        accepted: &[Accepted],
        runs: &mut Vec<ScenarioRun>,
    ) -> anyhow::Result<Vec<ScenarioCma>> {
        let mut order: Vec<&ScenarioRun> = runs.iter().filter(|r| r.candidate.is_some()).collect();
        order.sort_by(|a, b| a.robustness.cmp_worse(&b.robustness));
        let mut starts: Vec<ScenarioRun> = Vec::new();
        for r in order {
            if starts.len() == REFINED {
                break;
            }
            if !starts.iter().any(|s| s.variant == r.variant) {
                starts.push(r.clone());
            }
        }
        let refine_runs = self.plan.refine_runs;
        let mut cma_traces = Vec::new();
        let mut rng = ChaCha8Rng::seed_from_u64(trial_seed(self.settings.seed, u64::MAX - CMA_TAG));
        let n_starts = starts.len().max(1);
        for (i, start) in starts.iter().enumerate() {
            let share = refine_runs / n_starts + usize::from(i < refine_runs % n_starts);
            let Some(c0) = &start.candidate else { continue };
            let lambda = cmaes::default_lambda(c0.z.len()).min(share / 3).max(2);
            let sigma0 = 0.15;
            let mut es = cmaes::Cmaes::new(&c0.z, sigma0, &vec![1.0; c0.z.len()], lambda);
            self.progress.phase(&format!(
                "{}: CMA-ES on variant {}",
                self.template.world.name, accepted[start.variant].variant.index
            ));
            let best = es
                .spend(&mut rng, share, |zs| {
                    let cs: Vec<Candidate> = zs.iter().map(|z| c0.with_z(z)).collect();
                    let rs = run_parallel(&self.pool, &cs, self.progress, |c| {
                        self.one(accepted, start.variant, start.seed, Some(c))
                    })?;
                    let f = rs
                        .iter()
                        .map(|r| {
                            r.robustness.value - if r.robustness.collided { 10.0 } else { 0.0 }
                        })
                        .collect();
                    runs.extend(rs.into_iter().map(|mut r| {
                        r.phase = "cmaes";
                        r
                    }));
                    Ok::<_, anyhow::Error>(f)
                })?
                .min(start.robustness.value);
            cma_traces.push(ScenarioCma {
                variant: start.variant,
                seed: start.seed,
                start: start.robustness.value,
                best,
                runs: share,
                sigma: [sigma0, es.sigma()],
            });
        }
        Ok(cma_traces)
    }

    /// Phase 4, every unsafe run: does `check` still accept its world with the run's attack
    /// declared? The defects (it does), and how many it declines.
    fn recheck(
        &self,
        accepted: &[Accepted],
        unsafe_runs: &[&ScenarioRun],
    ) -> anyhow::Result<(Vec<Defect>, usize)> {
        let rechecked = run_parallel(&self.pool, unsafe_runs, &Silent, |r| {
            let a = &accepted[r.variant];
            let world = match &r.candidate {
                Some(c) => self
                    .template
                    .variant_with(&a.world, &self.space.decode(c))?,
                None => a.world.with_file(a.world.file.clone())?,
            };
            Ok(check(&world))
        })?;
        let mut defects = Vec::new();
        let mut declines = 0;
        for (r, c) in unsafe_runs.iter().zip(rechecked) {
            if c.applies && c.live {
                defects.push(Defect {
                    run: (*r).clone(),
                    verdict: c.verdict,
                    file: String::new(),
                });
            } else {
                declines += 1;
            }
        }
        Ok((defects, declines))
    }
}

/// Sets `key` of the table-like `item` to `value`.
fn set(item: &mut Item, key: &str, value: toml_edit::Value) {
    if let Some(t) = item.as_table_like_mut() {
        t.insert(key, Item::Value(value));
    }
}

fn array<const N: usize>(v: [f64; N]) -> toml_edit::Value {
    toml_edit::Value::Array(v.iter().copied().collect::<Array>())
}

impl WorldTemplate {
    /// The text of a regression world: the original file moved by `variant` (every moved value
    /// written as the in-memory variant holds it), with `attacks`, `seed` and `controller`, and
    /// `header` as its leading comment.
    pub fn scenario_text(
        &self,
        variant: &Variant,
        attacks: &[AttackSpec],
        info: &super::ReplayInfo<'_>,
        out: &Path,
    ) -> anyhow::Result<String> {
        let moved = variant.apply(&self.world.file, info.controller);
        let mut doc: DocumentMut = self.with_attacks(attacks)?;
        if let Some(obs) = doc
            .get_mut("obstacles")
            .and_then(Item::as_array_of_tables_mut)
        {
            for (t, o) in obs.iter_mut().zip(&moved.obstacles) {
                t.insert("position", Item::Value(array(o.position)));
                let shape_text = toml::to_string(&o.shape).context("writing an obstacle shape")?;
                let shape: DocumentMut = shape_text.parse().context("reading back a shape")?;
                let mut inline: InlineTable = shape.as_table().clone().into_inline_table();
                inline.fmt();
                t.insert("shape", Item::Value(toml_edit::Value::InlineTable(inline)));
            }
        }
        if let Some(rb) = &moved.robot {
            if let Some(robot) = doc.get_mut("robot") {
                let mut start = InlineTable::new();
                start.insert("x", rb.start.x.into());
                start.insert("y", rb.start.y.into());
                start.insert("theta", rb.start.theta.into());
                set(robot, "start", toml_edit::Value::InlineTable(start));
            }
        }
        if let Some(l) = &moved.linear {
            if let Some(lin) = doc.get_mut("linear") {
                set(lin, "x0", array(l.x0));
            }
        }
        if let Some(goal) = doc.get_mut("goal") {
            set(goal, "center", array(moved.goal.center));
            if !moved.goal.waypoints.is_empty() {
                let wps: Array = moved
                    .goal
                    .waypoints
                    .iter()
                    .map(|w| toml_edit::Value::Array(w.iter().copied().collect::<Array>()))
                    .collect();
                set(goal, "waypoints", toml_edit::Value::Array(wps));
            }
        }
        if let Some(sensors) = doc
            .get_mut("sensors")
            .and_then(Item::as_array_of_tables_mut)
        {
            for ((t, s), orig) in sensors
                .iter_mut()
                .zip(&moved.sensors)
                .zip(&self.world.file.sensors)
            {
                if s.noise_std != orig.noise_std {
                    t.insert("noise_std", toml_edit::value(s.noise_std));
                }
            }
        }
        doc.remove("falsify");
        self.finish_replay(doc, info, out)
    }
}

/// Writes the world of run `r` of `report` at `out` (header line `what` says why), runs it as
/// `ftcbf run` would, and checks that it replays the run's ρ bit for bit.
pub fn write_run(
    template: &WorldTemplate,
    report: &ScenarioReport,
    r: &ScenarioRun,
    name: &str,
    what: &str,
    out: &Path,
) -> anyhow::Result<()> {
    let variant = &report.accepted[r.variant];
    let space = SearchSpace::new(&template.world)?;
    let attacks = match &r.candidate {
        Some(c) => space.decode(c),
        None => {
            variant
                .apply(&template.world.file, &report.controller)
                .attacks
        }
    };
    let description = format!(
        "{what}: {} on {}; attack {}; ρ = {}.",
        variant.describe(),
        report.world,
        r.attack,
        r.robustness.display()
    );
    let header = vec![
        format!(
            "Written by `ftcbf falsify {} --scenario --controller {} --seed {} --budget {}`.",
            report.world_file, report.controller, report.seed, report.plan.budget
        ),
        format!("{what}."),
        format!("{} (run seed {}).", variant.describe(), r.seed),
        format!("Attack: {}.", r.attack),
        format!("ρ = {}.", r.robustness.display()),
    ];
    let info = super::ReplayInfo {
        name,
        description: &description,
        seed: r.seed,
        controller: &report.controller,
        header: &header,
    };
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let text = template.scenario_text(variant, &attacks, &info, out)?;
    std::fs::write(out, &text).with_context(|| format!("cannot write {}", out.display()))?;
    let world = World::load(out, &[])
        .with_context(|| format!("the written world {} does not load", out.display()))?;
    let s = run(&world, &RunOptions::default())?;
    let rho = Robustness::of(&world, &s).ok_or_else(|| anyhow!("no safe set and no obstacle"))?;
    if rho != r.robustness {
        return Err(anyhow!(
            "the written world {} replays to ρ = {}, not the searched {}; this is a bug",
            out.display(),
            rho.display(),
            r.robustness.display()
        ));
    }
    Ok(())
}

/// Writes every defect of `report` into `dir` ([`write_run`]) and records the file names.
pub fn write_defects(
    template: &WorldTemplate,
    report: &mut ScenarioReport,
    dir: &Path,
) -> anyhow::Result<()> {
    for i in 0..report.defects.len() {
        let d = &report.defects[i];
        let name = format!(
            "{}_scenario_v{}_s{}",
            report.world, report.accepted[d.run.variant].index, d.run.seed
        );
        let out = dir.join(format!("{name}.toml"));
        let what = format!("DEFECT: unsafe where check says \"{}\"", d.verdict);
        write_run(template, report, &d.run, &name, &what, &out)?;
        report.defects[i].file = out.display().to_string();
    }
    Ok(())
}

impl ScenarioReport {
    /// The human-readable summary (the time on its last line).
    pub fn text(&self) -> String {
        let mut s = String::new();
        let p = &self.plan;
        let r = &self.ranges;
        let _ = writeln!(
            s,
            "falsify --scenario {} · controller {} · seed {} · budget {} runs",
            self.world, self.controller, self.seed, p.budget
        );
        let _ = writeln!(
            s,
            "ranges: obstacles ±{} m and ±{} % in size, start ±{} m and ±{} rad, goal ±{} m, noise ±{} %, attack windows ±{} s",
            r.obstacle_shift,
            100.0 * r.obstacle_scale,
            r.start_shift,
            r.start_heading,
            r.goal_shift,
            100.0 * r.noise,
            r.onset_shift
        );
        let _ = writeln!(
            s,
            "plan: up to {} accepted variants × {} runs (own attacks and uniform attacks, one seed each) = {} runs, then CMA-ES on the worst searched runs of up to {REFINED} variants: {} runs",
            p.variants_wanted,
            p.runs_per_variant,
            p.variants_wanted * p.runs_per_variant,
            p.refine_runs
        );
        let _ = writeln!(
            s,
            "variants: {} tried, {} invalid, {} where Theorem 3 does not apply, {} not predicted live, {} accepted",
            self.variants_tried,
            self.variants_invalid,
            self.variants_not_applies,
            self.variants_not_live,
            self.variants_accepted
        );
        for c in &self.cmaes {
            let _ = writeln!(
                s,
                "CMA-ES on variant {} (seed {}): ρ {:.4} → {:.4} in {} runs, σ {:.3} → {:.3}",
                self.accepted[c.variant].index,
                c.seed,
                c.start,
                c.best,
                c.runs,
                c.sigma[0],
                c.sigma[1]
            );
        }
        let _ = writeln!(
            s,
            "runs: {}, unsafe {}, of which {} where check (with the run's attack declared) says Theorem 3 applies, {} where it declines",
            self.runs, self.unsafe_runs, self.unsafe_where_applies, self.unsafe_check_declines
        );
        if let Some(w) = &self.worst {
            let _ = writeln!(
                s,
                "worst run: {} on {} (seed {}): {}",
                w.robustness.display(),
                self.accepted[w.variant].describe(),
                w.seed,
                w.attack
            );
        }
        for d in &self.defects {
            let _ = writeln!(
                s,
                "DEFECT: unsafe where check says Theorem 3 applies: {} · {} · seed {} · ρ = {}{}",
                self.accepted[d.run.variant].describe(),
                d.run.attack,
                d.run.seed,
                d.run.robustness.display(),
                if d.file.is_empty() {
                    String::new()
                } else {
                    format!(" → {}", d.file)
                }
            );
        }
        let _ = writeln!(s, "time: {:.1} s", self.time_seconds);
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_parse_and_reject_bad_values() {
        assert_eq!(
            parse_range("obstacle_shift=0.3"),
            Ok(("obstacle_shift".to_string(), 0.3))
        );
        assert!(parse_range("obstacle_shift").is_err_and(|e| e.contains("KEY=VALUE")));
        assert!(parse_range("nosie=0.1").is_err_and(|e| e.contains("unknown range `nosie`")));
        assert!(parse_range("noise=abc").is_err_and(|e| e.contains("not a number")));
        let mut r = Ranges::default();
        assert!(r.set("noise", 1.0).is_err_and(|e| e.contains("< 1")));
        assert!(r.set("goal_shift", -0.1).is_err_and(|e| e.contains("≥ 0")));
        assert!(r.set("goal_shift", f64::NAN).is_err());
        r.set("goal_shift", 0.5).expect("valid");
        assert_eq!(r.goal_shift, 0.5);
    }

    #[test]
    fn plans_spend_the_budget() {
        for b in [8, 9, 50, 100, 401] {
            let p = ScenarioPlan::new(b, true).expect("plan");
            assert_eq!(
                p.variants_wanted * p.runs_per_variant + p.refine_runs,
                b,
                "{p:?}"
            );
            assert!(p.refine_runs >= b / 4, "{p:?}");
        }
        assert!(ScenarioPlan::new(7, true).is_err());
        assert_eq!(
            ScenarioPlan::new(100, false)
                .expect("plan")
                .runs_per_variant,
            3
        );
    }

    #[test]
    fn shapes_scale_in_every_dimension() {
        let s = scaled(
            &ShapeSpec::Cylinder {
                radius: 0.2,
                half_height: 0.5,
            },
            1.5,
        );
        assert_eq!(
            s,
            // 0.2 × 1.5 is 0.30000000000000004 in f64: scaled sizes keep 6 significant digits.
            ShapeSpec::Cylinder {
                radius: 0.3,
                half_height: 0.75
            }
        );
        let h = ShapeSpec::HalfSpace {
            normal: [0.0, 0.0, 1.0],
        };
        assert_eq!(scaled(&h, 2.0), h);
    }
}

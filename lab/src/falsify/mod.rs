//! Falsification: search for the worst attack inside the declared threat model (`ftcbf falsify`).
//!
//! A batch measures Pr(safe) for the attack a world declares; an attacker *chooses* the attack.
//! `falsify` searches, for one controller, the attack that brings the true state closest to
//! unsafe, over a parameterised family that covers every injector kind of `ftcbf-sim`
//! ([`space`]), confined — as the thesis' fault model is — to the channels of **one** declared
//! fault pattern per candidate (patterns are never combined).
//!
//! - **Objective** ([`Robustness`]): the minimum over time of h(x_true) of every safe set and of
//!   the signed obstacle clearance; negative is unsafe, and a collision ranks below any run
//!   without one.
//! - **Optimiser** ([`search`]): a cross-entropy method over the mixed space: categorical
//!   distributions over the fault pattern and the injector kind, and for each kind an
//!   independent Gaussian per continuous coordinate (clipped to [0, 1]), moved (smoothed) towards
//!   the best quarter of each generation. Its first generation, twice the later ones, is random
//!   search's first candidates on the same seeds (run once, counted in both budgets); each later
//!   generation re-runs the previous one's best candidates on its fresh seeds (elitism), and the
//!   CEM spends the candidates of the last third of the generations on a **CMA-ES refinement**
//!   ([`cmaes`]) of the continuous parameters of its best (pattern, kind) cells, started at each
//!   cell's best candidate with the CEM's spread there as its step, every candidate on the same
//!   2 seeds (common random numbers: the seed-averaged ρ is then a deterministic function of z,
//!   on which CMA-ES converges; the CEM's own update stalls where its elites cluster, issue #31),
//!   and half of every later CEM generation explores: it is random search's own first
//!   candidates of that generation, on the same seeds, so the CEM sees half of random search's
//!   candidates and runs them bit for bit as random search does. Exploring the least-tried
//!   (pattern, kind) cell instead spread those runs thinly over every cell, and on 4 of 24
//!   catalogue pairs random search's best attack lay in a cell the CEM had tried 4 times
//!   (issue #31; the measurements are in the book's falsify history). After a flat generation
//!   (its best candidate ties its first non-elite: a plateau of ρ, where the elites are an
//!   arbitrary pick of equals) the CEM leaves its distribution as it was and spends its own
//!   candidates of the next generation on the least-tried cells.
//!   The elites are ranked by their worst run, then their mean, since the search looks for the
//!   worst run. The CEM pays, from its CMA-ES share, as many runs as one finalist's held-out
//!   re-run for a counterexample refinement after the finalists: the worst run so far
//!   (searched or held-out) fixes a seed, on which ρ is a deterministic function of the attack,
//!   and a (1 + λ) evolution strategy descends from that run's attack on that seed (random
//!   search cannot use a seed this way: its draws ignore what it has seen). Written here rather
//!   than taken from a crate: the maintained CMA-ES crate (`cmaes` 0.2.2) handles continuous
//!   variables only, pulls a second nalgebra (0.33) and rand 0.8, and the categorical part of
//!   the problem is where most of the search happens.
//! - **Noise**: every candidate runs on 2 seeds (common within a generation, fresh for every
//!   generation, the same for both methods); the CEM's elites are ranked by their worst run (then
//!   the mean, collisions first), the finalists by seed-averaged robustness; the best 4 distinct
//!   candidates of each method (a re-run candidate ranked by all its runs) are re-run on
//!   held-out seeds, and both the seed-averaged and the worst robustness are reported.
//! - **Comparison**: random search (uniform over the same space) with the same plan, the same
//!   run count and the same seeds; the paired verdict on the held-out seeds ([`Paired`]).
//! - **Reference** ([`AttackFree`]): the world without attacks on the same held-out seeds
//!   (outside both budgets), against which each method's best attack is paired: whether an
//!   attack moved ρ at all.
//! - **Determinism**: candidates are drawn from seeded ChaCha streams; runs go to the batch
//!   engine's thread pool ([`crate::batch::run_parallel`]) and come back in order, so the result
//!   does not depend on the number of threads.
//! - **Result**: the worst single run (the witness) as a world file that `ftcbf run` replays to
//!   the same robustness, bit for bit.

pub mod cmaes;
mod robustness;
pub mod scenario;
pub mod search;
pub mod space;
mod template;

use std::fmt::Write as _;

use anyhow::Context;
use ftcbf_sim::attacks::validate_attacks;
use ftcbf_sim::world::{ControllerKindSpec, World};
use serde::Serialize;

pub use robustness::{Robustness, CLEARANCE};
pub use search::{Method, MethodResult, Plan, SeedRun};
pub use space::{Candidate, Family, Kind, SearchSpace};
pub use template::{ReplayInfo, WorldTemplate};

use crate::progress::Progress;

use crate::batch::worker_pool;

/// What to search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// The controller under test.
    pub controller: ControllerKindSpec,
    /// Runs per method.
    pub budget: usize,
    /// Base seed S.
    pub seed: u64,
    /// Worker threads (`None` = all cores).
    pub jobs: Option<usize>,
    /// Also run random search with the same budget, for comparison.
    pub compare_random: bool,
    /// The attacks searched ([`Family::Injectors`] unless aimed at the safe stop).
    pub family: Family,
}

impl Settings {
    /// The methods searched: the CEM, then random search if compared.
    fn methods(&self) -> &'static [Method] {
        if self.compare_random {
            &[Method::Cem, Method::Random]
        } else {
            &[Method::Cem]
        }
    }

    /// How many runs [`falsify`] makes: each method's [`Plan`], the first generation, which the
    /// methods share, counted once (the length of its progress bar).
    pub fn runs(&self) -> anyhow::Result<u64> {
        // The first generation is the same candidates on the same seeds for both methods: run
        // once, counted in both budgets.
        let plan = Plan::new(self.budget)?;
        let methods = self.methods().len();
        let shared = (methods - 1) * plan.first * plan.seeds_per_candidate;
        // The attack-free reference runs once, on the held-out seeds, outside both budgets.
        Ok((plan.runs * methods - shared + plan.final_seeds) as u64)
    }
}

/// Everything a search found; serialised as the `--json` file.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// World name.
    pub world: String,
    /// World file as given.
    pub world_file: String,
    /// The controller under test.
    pub controller: String,
    /// Base seed.
    pub seed: u64,
    /// The attacks searched.
    pub family: Family,
    /// How each method spent its budget.
    pub plan: Plan,
    /// The fault patterns searched (one per candidate, never combined).
    pub patterns: Vec<space::Pattern>,
    /// Threat-model statement printed with the result.
    pub threat_model: String,
    /// Warnings about the world's own attacks.
    pub warnings: Vec<String>,
    /// The CEM first, then random search (if run).
    pub methods: Vec<MethodResult>,
    /// The two methods' best attacks compared seed by seed on the common held-out seeds (when
    /// random search ran).
    pub paired: Option<Paired>,
    /// The world without attacks on the held-out seeds, and each method's best attack against it.
    pub attack_free: Option<AttackFree>,
}

/// The CEM's and random search's best attacks (best finalists) on the same held-out seeds: a
/// paired comparison that asks which method found the more damaging attack, with the seeds'
/// luck taken out (each seed is played against both attacks).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Paired {
    /// Held-out seeds compared.
    pub seeds: usize,
    /// Seeds where the CEM's attack is worse for the controller (lower ρ, or a collision).
    pub cem_worse: usize,
    /// Seeds where random search's attack is worse for the controller.
    pub random_worse: usize,
    /// Exact two-sided sign test of `cem_worse` against `random_worse` (ties left out).
    pub p: f64,
    /// Mean over the seeds of ρ_CEM − ρ_random (negative: the CEM's attack is worse).
    pub mean_difference: f64,
}

/// The level of the sign tests that decide a paired verdict: which method's attack is the
/// worse, and whether an attack moved ρ.
const SIGNIFICANCE: f64 = 0.05;

/// Two lists of runs paired by seed: on how many seeds each is the worse for the controller,
/// the exact two-sided sign test (ties left out) and the mean of ρ_a − ρ_b. `None` when no seed
/// is shared.
fn pair_runs(a: &[SeedRun], b: &[SeedRun]) -> Option<(usize, usize, usize, f64, f64)> {
    let (mut a_worse, mut b_worse, mut diff, mut seeds) = (0, 0, 0.0, 0);
    for ra in a {
        let Some(rb) = b.iter().find(|r| r.seed == ra.seed) else {
            continue;
        };
        seeds += 1;
        diff += ra.robustness.value - rb.robustness.value;
        match ra.robustness.cmp_worse(&rb.robustness) {
            std::cmp::Ordering::Less => a_worse += 1,
            std::cmp::Ordering::Greater => b_worse += 1,
            std::cmp::Ordering::Equal => {}
        }
    }
    (seeds > 0).then(|| {
        let p = crate::batch::stats::mcnemar_exact_p(a_worse as u64, b_worse as u64);
        (seeds, a_worse, b_worse, p, diff / seeds as f64)
    })
}

impl Paired {
    /// Pairs the two best finalists' runs by seed.
    fn of(cem: &MethodResult, random: &MethodResult) -> Option<Paired> {
        let (seeds, cem_worse, random_worse, p, mean_difference) =
            pair_runs(&cem.best().runs, &random.best().runs)?;
        Some(Paired {
            seeds,
            cem_worse,
            random_worse,
            p,
            mean_difference,
        })
    }

    /// "the CEM's" / "random search's" / "neither method's" attack is the more damaging at the
    /// 5 % level.
    pub fn verdict(&self) -> &'static str {
        if self.p >= SIGNIFICANCE {
            "neither (no significant difference)"
        } else if self.cem_worse > self.random_worse {
            "the CEM's"
        } else {
            "random search's"
        }
    }
}

/// The world without any attack on the same held-out seeds as the finalists: the reference
/// that says whether an attack moved ρ at all. Where no method's best attack is worse than no
/// attack (sign test), attacks do not move ρ in this world at this seed, and the two methods'
/// best attacks cannot differ by more than the seeds do.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AttackFree {
    /// Its runs, one per held-out seed.
    pub runs: Vec<SeedRun>,
    /// Their mean ρ.
    pub mean: f64,
    /// Unsafe runs without any attack.
    pub unsafe_runs: usize,
    /// Each method's best attack against no attack, paired by seed.
    pub moved: Vec<Moved>,
}

/// One method's best attack (best finalist) against the attack-free runs on the same seeds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Moved {
    /// `cem` or `random`.
    pub method: Method,
    /// Seeds compared.
    pub seeds: usize,
    /// Seeds where the attack made ρ worse than no attack did.
    pub attack_worse: usize,
    /// Seeds where the run without an attack was the worse.
    pub attack_free_worse: usize,
    /// Exact two-sided sign test of the two counts (ties left out).
    pub p: f64,
    /// Mean over the seeds of ρ_attack − ρ_no-attack (negative: the attack moved ρ down).
    pub mean_difference: f64,
}

impl Moved {
    /// The attack made ρ significantly worse than no attack (sign test at the 5 % level).
    pub fn moves_rho(&self) -> bool {
        self.p < SIGNIFICANCE && self.attack_worse > self.attack_free_worse
    }
}

impl AttackFree {
    fn of(runs: Vec<SeedRun>, methods: &[MethodResult]) -> AttackFree {
        let moved = methods
            .iter()
            .filter_map(|m| {
                let (seeds, attack_worse, attack_free_worse, p, mean_difference) =
                    pair_runs(&m.best().runs, &runs)?;
                Some(Moved {
                    method: m.method,
                    seeds,
                    attack_worse,
                    attack_free_worse,
                    p,
                    mean_difference,
                })
            })
            .collect();
        AttackFree {
            mean: runs.iter().map(|r| r.robustness.value).sum::<f64>() / runs.len().max(1) as f64,
            unsafe_runs: runs.iter().filter(|r| r.robustness.is_unsafe()).count(),
            runs,
            moved,
        }
    }
}

/// The threat-model warnings for the world's own attacks: one per attack whose channels do
/// not all lie inside one declared fault pattern.
pub fn model_warnings(world: &World) -> Vec<String> {
    let Ok(targets) = validate_attacks(&world.file.attacks, &world.file.sensors) else {
        return Vec::new();
    };
    world
        .file
        .attacks
        .iter()
        .zip(&targets)
        .enumerate()
        .filter(|(_, (_, t))| !world.patterns.iter().any(|p| t.iter().all(|c| p.contains(c))))
        .map(|(i, (a, _))| {
            format!(
                "the world's own attacks[{i}] ({}) touches channels outside any single declared fault pattern: the world already leaves the paper's threat model, where no guarantee applies. falsify replaces the world's attacks and searches inside the model only.",
                a.display_label()
            )
        })
        .collect()
}

/// Searches the worst attack on `template`'s world, telling `progress` of its
/// [`Settings::runs`] runs (labelled with the world's name, then each phase) and finishing it
/// when they are done.
pub fn falsify(
    template: &WorldTemplate,
    settings: &Settings,
    progress: &dyn Progress,
) -> anyhow::Result<Report> {
    let world = &template.world;
    progress.start(settings.runs()?, &world.name);
    let space = SearchSpace::new(world)
        .with_context(|| format!("world `{}`", world.name))?
        .with_family(settings.family);
    let plan = Plan::new(settings.budget)?;
    let methods = settings.methods();
    let pool = worker_pool(settings.jobs)?;
    let search = search::Search {
        template,
        space: &space,
        plan,
        controller: settings.controller,
        seed: settings.seed,
        pool: &pool,
        progress,
    };
    let results = search.first_generation().and_then(|first| {
        methods
            .iter()
            .map(|&m| search.run(m, Some(&first)))
            .collect::<anyhow::Result<Vec<_>>>()
    });
    let attack_free = match &results {
        Ok(ms) => Some(search.attack_free().map(|runs| AttackFree::of(runs, ms))),
        Err(_) => None,
    };
    progress.finish();
    let attack_free = attack_free.transpose()?;
    let patterns: Vec<String> = space
        .patterns
        .iter()
        .map(|p| {
            let ch: Vec<&str> = p.channels.iter().map(|(n, _)| n.as_str()).collect();
            format!("{} = {{{}}}", p.name, ch.join(", "))
        })
        .collect();
    Ok(Report {
        world: world.name.clone(),
        world_file: template.path.display().to_string(),
        controller: settings.controller.name().to_string(),
        seed: settings.seed,
        family: settings.family,
        plan,
        threat_model: format!(
            "every candidate attacks channels of ONE declared fault pattern ({}); patterns are never combined",
            patterns.join(", ")
        ),
        patterns: space.patterns.clone(),
        warnings: model_warnings(world),
        paired: match &results {
            Ok(ms) => match &ms[..] {
                [cem, random] => Paired::of(cem, random),
                _ => None,
            },
            Err(_) => None,
        },
        methods: results?,
        attack_free,
    })
}

impl Report {
    /// The human-readable summary (deterministic: no timings): the plan, the methods' table,
    /// the comparisons, then each method's worst run and worst attack.
    pub fn text(&self) -> String {
        let mut s = String::new();
        self.write_plan(&mut s);
        self.write_table(&mut s);
        self.write_comparisons(&mut s);
        self.write_details(&mut s);
        s
    }

    /// The header: world, threat model, warnings and the plan.
    fn write_plan(&self, s: &mut String) {
        let p = &self.plan;
        let _ = writeln!(
            s,
            "falsify {} · controller {} · seed {} · budget {} runs per method",
            self.world, self.controller, self.seed, p.budget
        );
        let _ = writeln!(s, "threat model: {}.", self.threat_model);
        if self.family != Family::Injectors {
            let kinds: Vec<&str> = self.family.kinds().iter().map(|k| k.name()).collect();
            let _ = writeln!(
                s,
                "family: {} ({}), attacks aimed at the safe stop's weak spots; the objective is still ρ.",
                self.family.name(),
                kinds.join(", ")
            );
        }
        for w in &self.warnings {
            let _ = writeln!(s, "warning: {w}");
        }
        let _ = writeln!(
            s,
            "plan: {} candidates × {} seeds in {} generations (the first: {} uniform candidates, the same for both methods; then {} each: CEM elites {}, {} carried over, {} of random search's candidates of that generation); the CEM spends generations {}–{} ({} candidates, {} runs = {:.0} % of the budget) on CMA-ES over the continuous parameters of its best {} (pattern, kind) cell(s), seeded from the CEM's elites, on 2 fixed seeds; then the best {} on {} held-out seeds = {} runs; the CEM pays {} of its CMA-ES runs for a descent from its worst run so far on that run's seed, after the held-out runs ({} rounds × {} runs)",
            p.candidates,
            p.seeds_per_candidate,
            p.generations,
            p.first,
            p.population,
            p.elites,
            p.carry,
            p.explore,
            p.cma_from + 1,
            p.generations,
            p.cma_candidates,
            p.cma_candidates * p.seeds_per_candidate,
            100.0 * (p.cma_candidates * p.seeds_per_candidate) as f64 / p.budget as f64,
            p.cma_cells,
            p.finalists,
            p.final_seeds,
            p.runs,
            p.refine_runs(),
            p.refine_rounds,
            p.refine_per_round,
        );
    }

    /// One row per method, then each method's CMA-ES refinements.
    fn write_table(&self, s: &mut String) {
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "{:<8} {:>5} {:>7}  {:<44} best attack on held-out seeds: mean ρ, unsafe",
            "method", "runs", "unsafe", "worst run: ρ (binding)"
        );
        for m in &self.methods {
            let b = m.best();
            let _ = writeln!(
                s,
                "{:<8} {:>5} {:>7}  {:<44} {:.4}, {}/{}",
                m.method.name(),
                m.runs,
                m.unsafe_runs,
                m.witness.robustness.display(),
                b.mean,
                b.unsafe_runs,
                b.runs.len()
            );
        }
        for m in &self.methods {
            for t in &m.cmaes {
                let _ = writeln!(
                    s,
                    "{} CMA-ES on pattern {} × {}: λ = {}, {} candidates in {} generations, σ {:.3} → {:.3}; seed-averaged ρ {:.4} (start) → {:.4} (best)",
                    m.method.name(),
                    self.patterns.get(t.pattern).map_or("?", |p| p.name.as_str()),
                    t.kind.name(),
                    t.lambda,
                    t.candidates,
                    t.generations,
                    t.sigma0,
                    t.final_sigma,
                    t.start_mean,
                    t.best_mean
                );
            }
        }
    }

    /// The CEM against random search, paired on held-out seeds, and against no attack.
    fn write_comparisons(&self, s: &mut String) {
        if let [cem, random] = &self.methods[..] {
            let ord = cem.witness.robustness.cmp_worse(&random.witness.robustness);
            let _ = writeln!(
                s,
                "worst run: the CEM's is {} random search's at the same budget and seeds",
                match ord {
                    std::cmp::Ordering::Less => "worse for the controller than",
                    std::cmp::Ordering::Equal => "as bad as",
                    std::cmp::Ordering::Greater => "NOT as bad as",
                }
            );
        }
        if let Some(p) = &self.paired {
            let _ = writeln!(
                s,
                "best attacks, paired on the {} held-out seeds: the CEM's is the more damaging on {}, random search's on {} (mean ρ_CEM − ρ_random = {:+.4}; sign test p = {:.3}): {} attack is worse for the controller",
                p.seeds,
                p.cem_worse,
                p.random_worse,
                p.mean_difference,
                p.p,
                p.verdict()
            );
        }
        if let Some(f) = &self.attack_free {
            let _ = writeln!(
                s,
                "no attack, on the same {} held-out seeds: mean ρ = {:.4}, unsafe in {}/{}",
                f.runs.len(),
                f.mean,
                f.unsafe_runs,
                f.runs.len()
            );
            for m in &f.moved {
                let _ = writeln!(
                    s,
                    "  {} best attack against no attack: worse on {}, better on {} of {} seeds (mean Δρ = {:+.4}; sign test p = {:.3}): {}",
                    match m.method {
                        Method::Cem => "the CEM's",
                        Method::Random => "random search's",
                    },
                    m.attack_worse,
                    m.attack_free_worse,
                    m.seeds,
                    m.mean_difference,
                    m.p,
                    if m.moves_rho() {
                        "the attack moves ρ"
                    } else {
                        "NOT distinguishable from no attack"
                    }
                );
            }
        }
    }

    /// Each method's worst run and worst attack on average.
    fn write_details(&self, s: &mut String) {
        for m in &self.methods {
            let _ = writeln!(s);
            let _ = writeln!(
                s,
                "{} — worst run (seed {}, found in the {} runs):",
                m.method.name(),
                m.witness.seed,
                m.witness.found_in.name()
            );
            let _ = writeln!(s, "  {}", m.witness.description);
            let _ = writeln!(
                s,
                "  ρ = {} → {}",
                m.witness.robustness.display(),
                if m.witness.robustness.is_unsafe() {
                    "UNSAFE"
                } else {
                    "safe"
                }
            );
            let b = m.best();
            let worst = b.worst();
            let _ = writeln!(
                s,
                "{} — worst attack on average ({} held-out seeds):",
                m.method.name(),
                b.runs.len()
            );
            let _ = writeln!(s, "  {}", b.description);
            let _ = writeln!(
                s,
                "  mean ρ = {:.4}, worst ρ = {} (seed {}), unsafe in {}/{}, collisions {}",
                b.mean,
                worst.robustness.display(),
                worst.seed,
                b.unsafe_runs,
                b.runs.len(),
                b.collisions
            );
        }
    }
}

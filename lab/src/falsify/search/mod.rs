//! The optimiser (a cross-entropy method over the mixed discrete/continuous attack space), the
//! random-search comparison, and the evaluation of candidates on several seeds.

use crate::progress::{Progress, Silent};
use anyhow::{anyhow, Context};
use ftcbf_sim::attacks::AttackSpec;
use ftcbf_sim::runner::{run, CompiledWorld, RunOptions};
use ftcbf_sim::world::ControllerKindSpec;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

use super::cmaes;
use super::robustness::Robustness;
use super::space::{Candidate, Kind, SearchSpace};
use super::template::WorldTemplate;
use crate::batch::{run_parallel, trial_seed};

mod cem;
mod refine;

use cem::*;
use refine::*;

pub(super) use cem::uniform;

/// Smallest budget: enough for two generations and a final re-evaluation.
pub const MIN_BUDGET: usize = 24;
/// Largest budget (keeps final-round seed indices apart from search seeds).
pub const MAX_BUDGET: usize = 1_000_000;
/// Trial index of the first held-out seed of the final re-evaluation.
const FINAL_SEEDS_FROM: u64 = 1 << 32;
/// Weight of the elites in each CEM update of the categorical and Gaussian parameters.
const SMOOTHING: f64 = 0.7;
/// Initial and smallest standard deviation of a continuous coordinate.
const SIGMA0: f64 = 0.3;
const SIGMA_MIN: f64 = 0.02;
/// Smallest probability of a fault pattern (over all patterns) and of a kind (over all kinds),
/// so no arm is ever abandoned for good.
const PATTERN_FLOOR: f64 = 0.1;
/// Stream tag of the CMA-ES refinement's samples ("CMA").
const CMA_TAG: u64 = 0x43_4d_41;
/// Bounds of CMA-ES's initial step size σ₀ (the CEM's spread in the refined cell, averaged).
const CMA_SIGMA0: (f64, f64) = (0.05, 0.3);
/// First and largest step (standard deviation in z) of the counterexample refinement.
const REFINE_SIGMA0: f64 = 0.1;
const REFINE_SIGMA_MAX: f64 = 0.3;
/// Stream tag of the counterexample refinement's perturbations ("REF").
const REFINE_TAG: u64 = 0x52_45_46;
const KIND_FLOOR: f64 = 0.12;

/// How a budget of runs is spent (the same for the CEM and for random search, but for the
/// CEM's counterexample refinement, paid from its CMA-ES candidates).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Plan {
    /// Runs allowed.
    pub budget: usize,
    /// Seeds every searched candidate is run on (common within a generation, fresh per generation).
    pub seeds_per_candidate: usize,
    /// Candidates of the first generation: uniform samples, the same candidates on the same
    /// seeds for both methods (the CEM starts from random search's first candidates).
    pub first: usize,
    /// Candidates per later generation (the last may be smaller).
    pub population: usize,
    /// Candidates searched.
    pub candidates: usize,
    /// Generations, the first included.
    pub generations: usize,
    /// Best candidates of a later generation that steer the next (CEM; the first generation
    /// uses a quarter of its candidates, see [`Plan::elites_of`]).
    pub elites: usize,
    /// Best candidates of a generation that the CEM carries into the next and re-runs on that
    /// generation's seeds (elitism: the best attack stays in the search while it keeps ranking).
    pub carry: usize,
    /// First generation whose candidates the CEM spends on its CMA-ES refinement instead
    /// (random search keeps drawing uniform candidates there): the CEM runs generations
    /// `0 .. cma_from`, then CMA-ES on the continuous parameters of its best (pattern, kind)
    /// cells with the candidates of generations `cma_from ..` less those paying for the
    /// counterexample refinement (`cma_candidates` of them, each on
    /// the 2 seeds of generation `cma_from`, fixed for the whole refinement: common random
    /// numbers make the seed-averaged ρ a deterministic function of z, on which CMA-ES converges).
    pub cma_from: usize,
    /// Candidates of the CMA-ES refinement (CEM).
    pub cma_candidates: usize,
    /// (pattern, kind) cells refined by CMA-ES, best first, `cma_candidates` split evenly.
    pub cma_cells: usize,
    /// Candidates of each later generation that the CEM takes from random search's candidates
    /// of that generation (its first ones; exploration with random search's own draws and runs).
    pub explore: usize,
    /// Rounds of the CEM's counterexample refinement, which comes after the finalists and
    /// makes as many runs as one finalist's held-out re-run, paid from the CMA-ES candidates
    /// (`refine_runs` / `seeds_per_candidate` of them, rounded up): with the worst run's seed
    /// fixed, ρ is a deterministic function of the attack, and
    /// each round runs `refine_per_round` perturbations of the worst attack so far on that seed.
    pub refine_rounds: usize,
    /// Candidates per refinement round (one run each).
    pub refine_per_round: usize,
    /// Best searched candidates re-run on held-out seeds (both methods).
    pub finalists: usize,
    /// Held-out seeds per finalist (the same for every finalist).
    pub final_seeds: usize,
    /// Runs used by random search: candidates × seeds_per_candidate + finalists × final_seeds
    /// ≤ budget (the CEM's are at most as many: its refinement's runs replace as many or more
    /// CMA-ES runs).
    pub runs: usize,
}

impl Plan {
    /// The plan for `budget` runs: a fifth for the final re-evaluation (up to 4 finalists), the
    /// rest for the search at 2 seeds per candidate; generations of an eighth of the candidates
    /// (6 to 24) after a first generation twice that size.
    pub fn new(budget: usize) -> anyhow::Result<Plan> {
        if !(MIN_BUDGET..=MAX_BUDGET).contains(&budget) {
            return Err(anyhow!(
                "--budget {budget} is out of range; expected {MIN_BUDGET} to {MAX_BUDGET} runs"
            ));
        }
        let final_runs = budget / 5;
        let finalists = (final_runs / 2).clamp(1, 4);
        let final_seeds = final_runs / finalists;
        let seeds_per_candidate = 2;
        let candidates = (budget - finalists * final_seeds) / seeds_per_candidate;
        let population = (candidates / 8).clamp(6, 24);
        // At least one later generation: candidates ≥ 10 > population at the smallest budget.
        let first = (2 * population)
            .min(candidates.saturating_sub(population))
            .max(population.min(candidates - 1));
        let generations = 1 + (candidates - first).div_ceil(population);
        // The CEM's counterexample refinement gets as many runs as one finalist's held-out
        // re-run, in rounds of at least two runs where possible, taken from its CMA-ES share: the
        // CEM re-runs as many finalists as random search (the paired verdict compares the best
        // finalist of each, so fewer finalists would be a handicap of its own making, issue #31).
        let cma_from = generations - (generations - 1).div_ceil(3);
        let refine_runs = final_seeds;
        let cma_candidates: usize = candidates
            - first
            - (cma_from - 1) * population
            - refine_runs.div_ceil(seeds_per_candidate);
        let refine_rounds = if refine_runs >= 8 && refine_runs.is_multiple_of(4) {
            4
        } else if refine_runs >= 4 && refine_runs.is_multiple_of(2) {
            2
        } else {
            1
        };
        Ok(Plan {
            budget,
            seeds_per_candidate,
            first,
            population,
            candidates,
            generations,
            elites: Self::elites_of(population),
            carry: (population / 8).max(1),
            cma_from,
            cma_candidates,
            cma_cells: (cma_candidates / 15).clamp(1, 3),
            explore: population / 2,
            refine_rounds,
            refine_per_round: refine_runs / refine_rounds,
            finalists,
            final_seeds,
            runs: candidates * seeds_per_candidate + finalists * final_seeds,
        })
    }

    /// Runs of the CEM's counterexample refinement.
    pub fn refine_runs(&self) -> usize {
        self.refine_rounds * self.refine_per_round
    }

    /// Candidates in generation `g`.
    pub fn generation_size(&self, g: usize) -> usize {
        if g == 0 {
            self.first
        } else {
            let before = self.first + (g - 1) * self.population;
            self.population.min(self.candidates.saturating_sub(before))
        }
    }

    /// Elites of a generation of `n` candidates: a quarter, at least 2.
    pub fn elites_of(n: usize) -> usize {
        (n / 4).max(2).min(n)
    }

    /// The seeds of generation `g` (trial indices g·R … g·R + R − 1 of [`trial_seed`]).
    pub fn generation_seeds(&self, base: u64, g: usize) -> Vec<u64> {
        let r = self.seeds_per_candidate as u64;
        (0..r).map(|i| run_seed(base, g as u64 * r + i)).collect()
    }

    /// The held-out seeds of the final re-evaluation.
    pub fn final_seeds(&self, base: u64) -> Vec<u64> {
        (0..self.final_seeds as u64)
            .map(|i| run_seed(base, FINAL_SEEDS_FROM + i))
            .collect()
    }
}

/// The seed of run index `k`: the batch engine's [`trial_seed`] with its top bit cleared, so it
/// fits the `seed` integer of a TOML world file.
pub fn run_seed(base: u64, k: u64) -> u64 {
    trial_seed(base, k) & (i64::MAX as u64)
}

/// Which search.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The cross-entropy method.
    Cem,
    /// Uniform random sampling of the same space, same plan and seeds.
    Random,
}

impl Method {
    /// `cem` or `random`.
    pub fn name(self) -> &'static str {
        match self {
            Method::Cem => "cem",
            Method::Random => "random",
        }
    }
}

/// One run of a candidate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SeedRun {
    /// The run's seed.
    pub seed: u64,
    /// Its robustness.
    pub robustness: Robustness,
}

/// A candidate and its runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Evaluation {
    /// Generation (search) or `None` (final re-evaluation on held-out seeds).
    pub generation: Option<usize>,
    /// The point of the search space.
    pub candidate: Candidate,
    /// Its decoded `[[attacks]]`.
    pub attacks: Vec<AttackSpec>,
    /// One-line description.
    pub description: String,
    /// Runs, in seed order.
    pub runs: Vec<SeedRun>,
    /// Seed-averaged robustness value.
    pub mean: f64,
    /// Runs that collided.
    pub collisions: usize,
    /// Unsafe runs (collision or negative margin).
    pub unsafe_runs: usize,
    /// A counterexample-refinement candidate (CEM, run after the finalists on the worst run's
    /// seed only, no generation): it takes part in the worst run, not in the choice of finalists.
    pub refinement: bool,
    /// A CMA-ES candidate (CEM, generation `cma_from`'s seeds): it takes part in the choice of
    /// finalists like any searched candidate.
    pub cmaes: bool,
}

impl Evaluation {
    fn new(
        generation: Option<usize>,
        candidate: Candidate,
        space: &SearchSpace,
        runs: Vec<SeedRun>,
    ) -> Self {
        let mean = runs.iter().map(|r| r.robustness.value).sum::<f64>() / runs.len() as f64;
        Evaluation {
            generation,
            attacks: space.decode(&candidate),
            description: space.describe(&candidate),
            collisions: runs.iter().filter(|r| r.robustness.collided).count(),
            unsafe_runs: runs.iter().filter(|r| r.robustness.is_unsafe()).count(),
            candidate,
            runs,
            mean,
            refinement: false,
            cmaes: false,
        }
    }

    /// The worst of its runs.
    pub fn worst(&self) -> &SeedRun {
        self.runs
            .iter()
            .reduce(|a, b| {
                if b.robustness.cmp_worse(&a.robustness).is_lt() {
                    b
                } else {
                    a
                }
            })
            .expect("an evaluation has at least one run")
    }

    /// Ordering for the CEM's elites: more collisions first, then the lower worst run, then the
    /// lower mean. The search looks for the worst run, so the tail of a candidate's runs ranks
    /// it, not only their mean.
    fn cmp_worse_tail(&self, other: &Evaluation) -> std::cmp::Ordering {
        other
            .collisions
            .cmp(&self.collisions)
            .then(
                self.worst()
                    .robustness
                    .value
                    .total_cmp(&other.worst().robustness.value),
            )
            .then(self.mean.total_cmp(&other.mean))
    }

    /// Ordering of candidates (seed-averaged): more collisions first, then the lower mean.
    fn cmp_worse(&self, other: &Evaluation) -> std::cmp::Ordering {
        other
            .collisions
            .cmp(&self.collisions)
            .then(self.mean.total_cmp(&other.mean))
    }
}

/// The worst single run found, which the written world replays.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Witness {
    /// Its attacks.
    pub attacks: Vec<AttackSpec>,
    /// One-line description.
    pub description: String,
    /// The seed.
    pub seed: u64,
    /// The run's robustness.
    pub robustness: Robustness,
    /// Which part of the search made the run.
    pub found_in: Phase,
}

/// The parts of a search that make runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// A generation of the search (2 seeds per candidate).
    Search,
    /// The CEM's CMA-ES refinement of its best cells (2 fixed seeds per candidate).
    Cmaes,
    /// A finalist's re-run on the held-out seeds.
    HeldOut,
    /// The CEM's counterexample refinement (on the worst run's seed).
    Refinement,
}

impl Phase {
    fn of(e: &Evaluation) -> Phase {
        match (e.refinement, e.generation) {
            (true, _) => Phase::Refinement,
            (false, Some(_)) if e.cmaes => Phase::Cmaes,
            (false, Some(_)) => Phase::Search,
            (false, None) => Phase::HeldOut,
        }
    }

    /// Its name in the summary.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Search => "search",
            Phase::Cmaes => "CMA-ES",
            Phase::HeldOut => "held-out",
            Phase::Refinement => "refinement",
        }
    }
}

/// What one search found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MethodResult {
    /// `cem` or `random`.
    pub method: Method,
    /// Every searched candidate, in order.
    pub search: Vec<Evaluation>,
    /// The finalists on the held-out seeds, best (worst for the controller) first.
    pub finalists: Vec<Evaluation>,
    /// The CEM's CMA-ES refinements, one per refined (pattern, kind) cell (empty for random
    /// search).
    pub cmaes: Vec<CmaTrace>,
    /// The worst single run of all.
    pub witness: Witness,
    /// Runs made.
    pub runs: usize,
    /// Of which unsafe.
    pub unsafe_runs: usize,
}

impl MethodResult {
    /// The finalist with the worst seed-averaged robustness on the held-out seeds.
    pub fn best(&self) -> &Evaluation {
        &self.finalists[0]
    }
}

/// What the search needs besides the world.
pub struct Search<'a> {
    /// The world.
    pub template: &'a WorldTemplate,
    /// Its attack space.
    pub space: &'a SearchSpace,
    /// The plan.
    pub plan: Plan,
    /// The controller under test.
    pub controller: ControllerKindSpec,
    /// Base seed S.
    pub seed: u64,
    /// Worker threads.
    pub pool: &'a rayon::ThreadPool,
    /// Advanced once per run.
    pub progress: &'a dyn Progress,
}

impl Search<'_> {
    /// Runs every candidate on every seed (in parallel) and returns one evaluation per candidate.
    fn evaluate(
        &self,
        generation: Option<usize>,
        candidates: Vec<Candidate>,
        seeds: &[u64],
    ) -> anyhow::Result<Vec<Evaluation>> {
        let worlds: Vec<CompiledWorld> = run_parallel(self.pool, &candidates, &Silent, |c| {
            self.template
                .compiled_with(&self.space.decode(c))
                .with_context(|| self.space.describe(c))
        })?;
        let tasks: Vec<(usize, u64)> = (0..candidates.len())
            .flat_map(|i| seeds.iter().map(move |&s| (i, s)))
            .collect();
        let results = run_parallel(self.pool, &tasks, self.progress, |&(i, seed)| {
            self.run_one(&worlds[i], seed, || self.space.describe(&candidates[i]))
        })?;
        let mut runs = results.into_iter();
        Ok(candidates
            .into_iter()
            .map(|c| {
                let r: Vec<SeedRun> = runs.by_ref().take(seeds.len()).collect();
                Evaluation::new(generation, c, self.space, r)
            })
            .collect())
    }

    /// One run of `world` on `seed` under the controller under test, and its robustness;
    /// `what` names the attack in an error.
    fn run_one(
        &self,
        world: &CompiledWorld,
        seed: u64,
        what: impl Fn() -> String,
    ) -> anyhow::Result<SeedRun> {
        let opts = RunOptions {
            seed: Some(seed),
            controller: Some(self.controller),
            duration: None,
        };
        let s = run(world, &opts)
            .with_context(|| format!("run of {} with seed {seed} failed", what()))?;
        let robustness = Robustness::of(world.world(), &s)
            .ok_or_else(|| anyhow!("the world has no safe set and no obstacle"))?;
        Ok(SeedRun { seed, robustness })
    }

    /// The world with no attack at all, on the held-out seeds of the finalists: the reference
    /// that says how far the best attacks moved ρ (runs outside both methods' budgets).
    pub fn attack_free(&self) -> anyhow::Result<Vec<SeedRun>> {
        let world = self.template.compiled_with(&[])?;
        self.progress.phase("no attack, on the held-out seeds");
        run_parallel(
            self.pool,
            &self.plan.final_seeds(self.seed),
            self.progress,
            |&seed| self.run_one(&world, seed, || "the world without attacks".to_string()),
        )
    }

    /// Runs random search's (and the CEM's) first generation; pass it to [`Search::run`] so
    /// that both methods share these runs instead of making them twice.
    pub fn first_generation(&self) -> anyhow::Result<Vec<Evaluation>> {
        let mut proposer = Proposer::new(Method::Random, &self.plan, self.space, self.seed);
        self.progress.phase("first generation (both methods)");
        self.evaluate(
            Some(0),
            proposer.propose(0),
            &self.plan.generation_seeds(self.seed, 0),
        )
    }

    /// One whole search: generations, then the finalists on held-out seeds. `first`, if given,
    /// is [`Search::first_generation`]'s result, used instead of running that generation again
    /// (its runs still count in this method's budget: they are the same runs).
    pub fn run(
        &self,
        method: Method,
        first: Option<&[Evaluation]>,
    ) -> anyhow::Result<MethodResult> {
        let plan = &self.plan;
        let (mut search, cmaes) =
            search_generations(method, plan, self.space, self.seed, |g, candidates| {
                if let Some(f) = first.filter(|_| g == 0) {
                    if f.iter().map(|e| &e.candidate).eq(candidates.iter()) {
                        return Ok(f.to_vec());
                    }
                    return Err(anyhow!(
                        "the shared first generation does not match; this is a bug"
                    ));
                }
                self.progress
                    .phase(&if method == Method::Cem && g >= plan.cma_from {
                        "cem CMA-ES refinement".to_string()
                    } else {
                        format!(
                            "{} generation {}/{}",
                            method.name(),
                            g + 1,
                            plan.generations
                        )
                    });
                self.evaluate(Some(g), candidates, &plan.generation_seeds(self.seed, g))
            })?;
        // Finalists: the best distinct searched candidates, on held-out seeds. A candidate the
        // CEM carried over several generations is ranked by all its runs together.
        let refine = method == Method::Cem;
        let picked: Vec<Candidate> = pooled_ranking(&search)
            .into_iter()
            .take(plan.finalists)
            .cloned()
            .collect();
        self.progress
            .phase(&format!("{} final re-evaluation", method.name()));
        let mut finalists = self.evaluate(None, picked, &plan.final_seeds(self.seed))?;
        finalists.sort_by(|a, b| a.cmp_worse(b));
        // The CEM's refinement (paid from its CMA-ES share): refine the worst run so far,
        // held-out runs included (the finalists' held-out results are final before it starts).
        if refine {
            if let Some(start) = worst_run(search.iter().chain(&finalists)) {
                self.progress
                    .phase(&format!("{} refining the worst run", method.name()));
                let refined = refine_counterexample(plan, self.seed, start, |cs, seeds| {
                    self.evaluate(None, cs, seeds)
                })?;
                search.extend(refined);
            }
        }
        let all = || search.iter().chain(&finalists);
        let worst = worst_run(all()).ok_or_else(|| anyhow!("the search made no run"))?;
        let witness = Witness {
            attacks: worst.0.attacks.clone(),
            description: worst.0.description.clone(),
            seed: worst.1.seed,
            robustness: worst.1.robustness.clone(),
            found_in: Phase::of(worst.0),
        };
        let runs = all().map(|e| e.runs.len()).sum();
        let unsafe_runs = all().map(|e| e.unsafe_runs).sum();
        Ok(MethodResult {
            method,
            search,
            finalists,
            cmaes,
            witness,
            runs,
            unsafe_runs,
        })
    }
}

#[cfg(test)]
mod tests;

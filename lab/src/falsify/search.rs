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

/// The CEM's sampling distribution: categorical over patterns and kinds, an independent
/// Gaussian per coordinate of z for each kind (clipped to [0, 1]).
struct Sampler {
    /// The kinds searched (the space's family), in the order of `kinds`, `mu` and `sigma`.
    family: &'static [Kind],
    patterns: Vec<f64>,
    kinds: Vec<f64>,
    mu: Vec<Vec<f64>>,
    sigma: Vec<Vec<f64>>,
}

impl Sampler {
    fn new(patterns: usize, family: &'static [Kind], dim: usize) -> Self {
        Self {
            family,
            patterns: vec![1.0 / patterns as f64; patterns],
            kinds: vec![1.0 / family.len() as f64; family.len()],
            mu: vec![vec![0.5; dim]; family.len()],
            sigma: vec![vec![SIGMA0; dim]; family.len()],
        }
    }

    fn sample(&self, rng: &mut ChaCha8Rng) -> Candidate {
        let pattern = categorical(&self.patterns, rng);
        let k = categorical(&self.kinds, rng);
        let z = self.mu[k]
            .iter()
            .zip(&self.sigma[k])
            .map(|(m, s)| {
                let n: f64 = StandardNormal.sample(rng);
                (m + s * n).clamp(0.0, 1.0)
            })
            .collect();
        Candidate {
            pattern,
            kind: self.family[k],
            z,
        }
    }

    /// Moves the distribution towards the elites.
    fn update(&mut self, elites: &[&Candidate]) {
        let n = elites.len() as f64;
        let mut fp = vec![0.0; self.patterns.len()];
        let mut fk = vec![0.0; self.kinds.len()];
        for e in elites {
            fp[e.pattern] += 1.0 / n;
            fk[kind_index(self.family, e)] += 1.0 / n;
        }
        blend(&mut self.patterns, &fp, PATTERN_FLOOR);
        blend(&mut self.kinds, &fk, KIND_FLOOR);
        for k in 0..self.family.len() {
            let mine: Vec<&Candidate> = elites
                .iter()
                .copied()
                .filter(|e| kind_index(self.family, e) == k)
                .collect();
            if mine.is_empty() {
                continue;
            }
            let m = mine.len() as f64;
            for d in 0..self.mu[k].len() {
                let mean = mine.iter().map(|e| e.z[d]).sum::<f64>() / m;
                self.mu[k][d] = (1.0 - SMOOTHING) * self.mu[k][d] + SMOOTHING * mean;
                if mine.len() >= 2 {
                    let var = mine.iter().map(|e| (e.z[d] - mean).powi(2)).sum::<f64>() / m;
                    self.sigma[k][d] = ((1.0 - SMOOTHING) * self.sigma[k][d]
                        + SMOOTHING * var.sqrt())
                    .max(SIGMA_MIN);
                }
            }
        }
    }
}

/// The index of `c`'s kind in `family` (0 if it is not one of them).
fn kind_index(family: &[Kind], c: &Candidate) -> usize {
    family.iter().position(|k| *k == c.kind).unwrap_or(0)
}

/// p ← (1 − α) p + α f, then every entry raised to at least `floor / len` and renormalised.
fn blend(p: &mut [f64], f: &[f64], floor: f64) {
    let min = floor / p.len() as f64;
    for (pi, fi) in p.iter_mut().zip(f) {
        *pi = ((1.0 - SMOOTHING) * *pi + SMOOTHING * fi).max(min);
    }
    let s: f64 = p.iter().sum();
    p.iter_mut().for_each(|x| *x /= s);
}

fn categorical(p: &[f64], rng: &mut ChaCha8Rng) -> usize {
    let u: f64 = rng.random();
    let mut acc = 0.0;
    for (i, pi) in p.iter().enumerate() {
        acc += pi;
        if u < acc {
            return i;
        }
    }
    p.len() - 1
}

/// A uniform point of `space`: pattern, kind and every continuous parameter.
pub(super) fn uniform(space: &SearchSpace, rng: &mut ChaCha8Rng) -> Candidate {
    let pattern = rng.random_range(0..space.patterns.len());
    let kinds = space.kinds();
    let kind = kinds[rng.random_range(0..kinds.len())];
    let z = (0..space.dim).map(|_| rng.random::<f64>()).collect();
    Candidate { pattern, kind, z }
}

/// `c` with every continuous coordinate moved by N(0, `sigma`²) (clipped to [0, 1]); the same
/// pattern and kind.
fn perturb(c: &Candidate, sigma: f64, rng: &mut ChaCha8Rng) -> Candidate {
    let z =
        c.z.iter()
            .map(|v| {
                let n: f64 = StandardNormal.sample(rng);
                (v + sigma * n).clamp(0.0, 1.0)
            })
            .collect();
    Candidate {
        pattern: c.pattern,
        kind: c.kind,
        z,
    }
}

/// The seed of a method's candidate stream. The first generation of both methods is drawn
/// from random search's stream, so it is the same candidates.
fn stream(seed: u64, method: Method) -> ChaCha8Rng {
    let tag = match method {
        Method::Cem => 0x43_45_4d,
        Method::Random => 0x52_4e_44,
    };
    ChaCha8Rng::seed_from_u64(trial_seed(seed, u64::MAX - tag))
}

/// What proposes each generation's candidates and learns from their evaluations (no
/// simulation here, so the search logic is testable on its own).
struct Proposer<'a> {
    method: Method,
    plan: &'a Plan,
    space: &'a SearchSpace,
    /// Random search's stream: all of its candidates, the CEM's first generation and the CEM's
    /// exploration candidates.
    shared: ChaCha8Rng,
    /// The CEM's own stream, from its second generation on.
    own: ChaCha8Rng,
    dist: Sampler,
    /// The previous generation's candidates, worst for the controller first.
    ranked: Vec<Candidate>,
    /// The previous generation was flat: its best candidate tied with its first non-elite
    /// (nothing ranked above the rest), so it told the CEM nothing.
    flat: bool,
    /// Candidates proposed so far per (pattern, kind) cell, `pattern · kinds + kind` (the
    /// space's family).
    visits: Vec<usize>,
}

impl<'a> Proposer<'a> {
    fn new(method: Method, plan: &'a Plan, space: &'a SearchSpace, seed: u64) -> Self {
        Self {
            method,
            plan,
            space,
            shared: stream(seed, Method::Random),
            own: stream(seed, Method::Cem),
            dist: Sampler::new(space.patterns.len(), space.kinds(), space.dim),
            ranked: Vec::new(),
            flat: false,
            visits: vec![0; space.patterns.len() * space.kinds().len()],
        }
    }

    /// A candidate with uniform parameters in a (pattern, kind) cell proposed least so far
    /// (ties broken at random), from the CEM's own stream.
    fn least_tried(&mut self) -> Candidate {
        let least = self.visits.iter().copied().min().unwrap_or(0);
        let cells: Vec<usize> = (0..self.visits.len())
            .filter(|&i| self.visits[i] == least)
            .collect();
        let cell = cells[self.own.random_range(0..cells.len())];
        let mut c = uniform(self.space, &mut self.own);
        let kinds = self.space.kinds();
        c.pattern = cell / kinds.len();
        c.kind = kinds[cell % kinds.len()];
        c
    }

    /// Counts `cs` in [`Proposer::visits`].
    fn count(&mut self, cs: &[Candidate]) {
        let kinds = self.space.kinds();
        for c in cs {
            if let Some(v) = self
                .visits
                .get_mut(c.pattern * kinds.len() + kind_index(kinds, c))
            {
                *v += 1;
            }
        }
    }

    /// Random search's candidates of a generation of `n`: the next `n` uniform draws of its
    /// stream.
    fn random_generation(&mut self, n: usize) -> Vec<Candidate> {
        (0..n)
            .map(|_| uniform(self.space, &mut self.shared))
            .collect()
    }

    /// The candidates of generation `g` (call once per generation, in order).
    fn propose(&mut self, g: usize) -> Vec<Candidate> {
        let n = self.plan.generation_size(g);
        let random = self.random_generation(n);
        if g == 0 || self.method == Method::Random {
            self.count(&random);
            return random;
        }
        // Elitism: the previous generation's best, re-run on this generation's seeds.
        let mut out: Vec<Candidate> = Vec::with_capacity(n);
        for c in &self.ranked {
            if out.len() == self.plan.carry.min(n) {
                break;
            }
            if !out.contains(c) {
                out.push(c.clone());
            }
        }
        // Exploration: half of each later generation is random search's own candidates of
        // that generation (the first of them), run on the same seeds, so those runs are
        // random search's runs, bit for bit. The CEM then sees half of what random search
        // sees, and where random search's best attack lies in a cell the CEM's distribution
        // left, the CEM has it among its candidates with a fair chance (issue #31: on the 4 of
        // 24 pairs random search won, its best attack lay in a cell the CEM had tried 4 times).
        let explore = self.plan.explore.min(n - out.len());
        out.extend(random.into_iter().take(explore));
        self.count(&out);
        // The rest is the CEM's own: samples of its distribution, or, after a flat generation
        // (nothing ranked above the rest, so the distribution learnt nothing), uniform
        // parameters in the least-tried (pattern, kind) cells. On a plateau, where nearly every
        // run gives the same ρ (the start's margin) and one rare cell dips below it
        // (`turtlebot_odometry_bias`: 3 patterns × 12 kinds), the CEM then covers the cells
        // instead of following arbitrary tied elites.
        while out.len() < n {
            let c = if self.flat {
                self.least_tried()
            } else {
                self.dist.sample(&mut self.own)
            };
            self.count(std::slice::from_ref(&c));
            out.push(c);
        }
        out
    }

    /// Ranks a generation's evaluations and moves the CEM's distribution towards its elites.
    fn observe(&mut self, evals: &[Evaluation]) {
        let mut order: Vec<&Evaluation> = evals.iter().collect();
        order.sort_by(|a, b| a.cmp_worse_tail(b));
        let e = Plan::elites_of(evals.len());
        // Flat: the best ties the first non-elite, so the elites are an arbitrary pick of
        // equals and moving the distribution towards them would be a random walk.
        self.flat = order.len() > e && order[0].cmp_worse_tail(order[e]).is_eq();
        if self.method == Method::Cem && !self.flat {
            let elites: Vec<&Candidate> = order.iter().take(e).map(|e| &e.candidate).collect();
            self.dist.update(&elites);
        }
        self.ranked = order.into_iter().map(|e| e.candidate.clone()).collect();
    }
}

/// The distinct searched candidates (distinct attacks), worst for the controller first: by the
/// share of their runs that collided, then by their mean robustness over all their runs.
fn pooled_ranking(search: &[Evaluation]) -> Vec<&Candidate> {
    // (candidate, attacks, runs, collisions, sum of ρ)
    let mut pooled: Vec<(&Candidate, &Vec<AttackSpec>, usize, usize, f64)> = Vec::new();
    for e in search {
        let sum: f64 = e.runs.iter().map(|r| r.robustness.value).sum();
        match pooled.iter_mut().find(|p| *p.1 == e.attacks) {
            Some(p) => {
                p.2 += e.runs.len();
                p.3 += e.collisions;
                p.4 += sum;
            }
            None => pooled.push((&e.candidate, &e.attacks, e.runs.len(), e.collisions, sum)),
        }
    }
    // Stable sort: ties keep the order of first evaluation.
    pooled.sort_by(|a, b| {
        let share = |p: &(&Candidate, &Vec<AttackSpec>, usize, usize, f64)| p.3 as f64 / p.2 as f64;
        let mean = |p: &(&Candidate, &Vec<AttackSpec>, usize, usize, f64)| p.4 / p.2 as f64;
        share(b)
            .total_cmp(&share(a))
            .then(mean(a).total_cmp(&mean(b)))
    });
    pooled.into_iter().map(|p| p.0).collect()
}

/// The run with the lowest robustness among `evals` (collisions first), and its candidate.
fn worst_run<'a>(
    evals: impl IntoIterator<Item = &'a Evaluation>,
) -> Option<(&'a Evaluation, &'a SeedRun)> {
    evals.into_iter().map(|e| (e, e.worst())).reduce(|a, b| {
        if b.1.robustness.cmp_worse(&a.1.robustness).is_lt() {
            b
        } else {
            a
        }
    })
}

/// One CMA-ES refinement of a (pattern, kind) cell, as the report states it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CmaTrace {
    /// Index of the fault pattern.
    pub pattern: usize,
    /// Injector kind.
    pub kind: super::space::Kind,
    /// The starting point: the cell's best searched candidate (pooled over its runs).
    pub start: Vec<f64>,
    /// Its seed-averaged ρ in the search.
    pub start_mean: f64,
    /// Initial step size σ₀ (the CEM's spread in the cell, averaged over z, bounded).
    pub sigma0: f64,
    /// Population size λ.
    pub lambda: usize,
    /// Candidates evaluated (each on the 2 fixed seeds).
    pub candidates: usize,
    /// Generations told.
    pub generations: usize,
    /// The lowest seed-averaged ρ among its candidates (collisions count as −10 each).
    pub best_mean: f64,
    /// The step size when the budget ran out.
    pub final_sigma: f64,
}

/// Collisions first: the CMA-ES objective is the seed-averaged ρ minus this per collision.
const COLLISION_PENALTY: f64 = 10.0;

/// The CMA-ES objective of an evaluation (lower is worse for the controller).
fn cma_objective(e: &Evaluation) -> f64 {
    e.mean - COLLISION_PENALTY * e.collisions as f64
}

/// The CEM's CMA-ES refinement: the best `plan.cma_cells` distinct (pattern, kind) cells of the
/// search so far (pooled ranking), each refined on its continuous parameters from its best
/// candidate, with the CEM's spread in that kind as the initial step, for an even share of
/// `plan.cma_candidates` (every candidate on the seeds `evaluate` gives generation
/// `plan.cma_from`, the same throughout).
fn cma_refine(
    plan: &Plan,
    seed: u64,
    dist: &Sampler,
    search: &[Evaluation],
    mut evaluate: impl FnMut(usize, Vec<Candidate>) -> anyhow::Result<Vec<Evaluation>>,
) -> anyhow::Result<(Vec<Evaluation>, Vec<CmaTrace>)> {
    let mut cells: Vec<&Candidate> = Vec::new();
    for c in pooled_ranking(search) {
        if cells.len() == plan.cma_cells {
            break;
        }
        if !cells
            .iter()
            .any(|d| d.pattern == c.pattern && d.kind == c.kind)
        {
            cells.push(c);
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(trial_seed(seed, u64::MAX - CMA_TAG));
    let mut out = Vec::with_capacity(plan.cma_candidates);
    let mut traces = Vec::with_capacity(cells.len());
    let n_cells = cells.len().max(1);
    for (i, start) in cells.into_iter().enumerate() {
        let share = plan.cma_candidates / n_cells + usize::from(i < plan.cma_candidates % n_cells);
        if share == 0 {
            continue;
        }
        let spread = &dist.sigma[kind_index(dist.family, start)];
        let sigma0 = (spread.iter().sum::<f64>() / spread.len().max(1) as f64)
            .clamp(CMA_SIGMA0.0, CMA_SIGMA0.1);
        let lambda = cmaes::default_lambda(start.z.len()).min(share / 3).max(2);
        let mut es = cmaes::Cmaes::new(&start.z, sigma0, spread, lambda);
        let start_mean = search
            .iter()
            .filter(|e| e.candidate == *start)
            .map(|e| e.mean)
            .sum::<f64>()
            / search
                .iter()
                .filter(|e| e.candidate == *start)
                .count()
                .max(1) as f64;
        let best = es.spend(&mut rng, share, |zs| {
            let candidates: Vec<Candidate> = zs.iter().map(|z| start.with_z(z)).collect();
            let mut evals = evaluate(plan.cma_from, candidates)?;
            evals.iter_mut().for_each(|e| e.cmaes = true);
            let f = evals.iter().map(cma_objective).collect();
            out.extend(evals);
            Ok::<_, anyhow::Error>(f)
        })?;
        traces.push(CmaTrace {
            pattern: start.pattern,
            kind: start.kind,
            start: start.z.clone(),
            start_mean,
            sigma0,
            lambda,
            candidates: share,
            generations: es.generation(),
            best_mean: best,
            final_sigma: es.sigma(),
        });
    }
    Ok((out, traces))
}

/// All generations of one method's search; `evaluate(g, candidates)` runs candidates on
/// generation `g`'s seeds. The CEM runs generations `0 .. plan.cma_from`, then its CMA-ES
/// refinement ([`cma_refine`]) on generation `plan.cma_from`'s seeds; random search runs every
/// generation.
fn search_generations(
    method: Method,
    plan: &Plan,
    space: &SearchSpace,
    seed: u64,
    mut evaluate: impl FnMut(usize, Vec<Candidate>) -> anyhow::Result<Vec<Evaluation>>,
) -> anyhow::Result<(Vec<Evaluation>, Vec<CmaTrace>)> {
    let mut proposer = Proposer::new(method, plan, space, seed);
    let mut search: Vec<Evaluation> = Vec::with_capacity(plan.candidates);
    let generations = match method {
        Method::Cem => plan.cma_from,
        Method::Random => plan.generations,
    };
    for g in 0..generations {
        let candidates = proposer.propose(g);
        let evals = evaluate(g, candidates)?;
        proposer.observe(&evals);
        search.extend(evals);
    }
    if method == Method::Random {
        return Ok((search, Vec::new()));
    }
    let (refined, traces) = cma_refine(plan, seed, &proposer.dist, &search, evaluate)?;
    search.extend(refined);
    Ok((search, traces))
}

/// The CEM's counterexample refinement, with the held-out runs of one finalist: the worst run so
/// far (`start`, searched or held-out) fixes a seed, on which ρ is a deterministic function of
/// the attack (the noise is the seed's), and a (1 + λ) evolution strategy descends from that
/// run's attack. Each round runs `refine_per_round` Gaussian perturbations of the incumbent's
/// continuous parameters (same pattern and kind) on that seed, moves the incumbent to the round's
/// worst run if it is worse than the incumbent's, and widens its step (×1.5, at most
/// [`REFINE_SIGMA_MAX`]) after a success, halves it after a failure. `evaluate(candidates,
/// seeds)` runs them; the evaluations come back marked as refinement.
fn refine_counterexample(
    plan: &Plan,
    seed: u64,
    start: (&Evaluation, &SeedRun),
    mut evaluate: impl FnMut(Vec<Candidate>, &[u64]) -> anyhow::Result<Vec<Evaluation>>,
) -> anyhow::Result<Vec<Evaluation>> {
    let mut rng = ChaCha8Rng::seed_from_u64(trial_seed(seed, u64::MAX - REFINE_TAG));
    let mut incumbent = start.0.candidate.clone();
    let (fixed, mut record) = (start.1.seed, start.1.robustness.clone());
    let mut out = Vec::with_capacity(plan.refine_rounds * plan.refine_per_round);
    let mut sigma = REFINE_SIGMA0;
    for _ in 0..plan.refine_rounds {
        let candidates: Vec<Candidate> = (0..plan.refine_per_round)
            .map(|_| perturb(&incumbent, sigma, &mut rng))
            .collect();
        let mut evals = evaluate(candidates, &[fixed])?;
        evals.iter_mut().for_each(|e| e.refinement = true);
        let improved = worst_run(&evals)
            .filter(|(_, r)| r.robustness.cmp_worse(&record).is_lt())
            .map(|(e, r)| (e.candidate.clone(), r.robustness.clone()));
        if let Some((c, r)) = improved {
            incumbent = c;
            record = r;
            sigma = (1.5 * sigma).min(REFINE_SIGMA_MAX);
        } else {
            sigma *= 0.5;
        }
        out.extend(evals);
    }
    Ok(out)
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
mod tests {
    use super::*;
    use crate::falsify::space::{Family, Kind, FALLBACK_KINDS, KINDS};

    #[test]
    fn plans_spend_at_most_the_budget() {
        for b in [MIN_BUDGET, 25, 50, 99, 100, 200, 333, 400, 1000, 5000] {
            let p = Plan::new(b).expect("plan");
            assert!(p.runs <= b && p.runs + 2 > b, "{p:?}");
            assert!(
                p.generations >= 2 && p.finalists >= 1 && p.final_seeds >= 2,
                "{p:?}"
            );
            assert!(p.elites < p.population, "{p:?}");
            assert!(p.first >= p.population && p.first < p.candidates, "{p:?}");
            let sizes: Vec<usize> = (0..p.generations).map(|g| p.generation_size(g)).collect();
            assert_eq!(sizes.iter().sum::<usize>(), p.candidates, "{p:?}");
            assert!(sizes.iter().all(|&n| n > 0), "{p:?} {sizes:?}");
            assert!(p.carry < p.population, "{p:?}");
            assert!((1..p.generations).contains(&p.cma_from), "{p:?}");
            let late: usize = (p.cma_from..p.generations)
                .map(|g| p.generation_size(g))
                .sum();
            assert_eq!(
                late,
                p.cma_candidates + p.refine_runs().div_ceil(p.seeds_per_candidate),
                "{p:?}"
            );
            assert!(p.cma_candidates >= 1, "{p:?}");
            assert!(p.cma_cells >= 1, "{p:?}");
            // The refinement spends one finalist's held-out runs, taken from CMA-ES.
            assert!(p.finalists >= 2, "{p:?}");
            assert_eq!(p.refine_runs(), p.final_seeds, "{p:?}");
            let cem_runs = (p.candidates - p.refine_runs().div_ceil(p.seeds_per_candidate))
                * p.seeds_per_candidate
                + p.refine_runs()
                + p.finalists * p.final_seeds;
            assert!(cem_runs <= p.runs && cem_runs + 2 > p.runs, "{p:?}");
            assert!(p.refine_per_round >= 1, "{p:?}");
        }
        let p = Plan::new(200).expect("plan");
        assert_eq!(
            (
                p.candidates,
                p.first,
                p.population,
                p.generations,
                p.finalists,
                p.final_seeds
            ),
            (80, 20, 10, 7, 4, 10)
        );
        let p = Plan::new(400).expect("plan");
        assert_eq!(
            (
                p.first,
                p.population,
                p.generations,
                p.elites,
                p.carry,
                p.cma_from,
                p.cma_candidates,
                p.cma_cells
            ),
            (40, 20, 7, 5, 2, 5, 30, 2)
        );
        assert!(Plan::new(10).is_err_and(|e| e.to_string().contains("--budget 10")));
    }

    #[test]
    fn seeds_are_fresh_per_generation_and_fit_toml() {
        let p = Plan::new(200).expect("plan");
        let mut all: Vec<u64> = (0..p.generations)
            .flat_map(|g| p.generation_seeds(7, g))
            .chain(p.final_seeds(7))
            .collect();
        assert!(all.iter().all(|&s| s <= i64::MAX as u64));
        let n = all.len();
        all.sort_unstable();
        all.dedup();
        assert_eq!(all.len(), n);
    }

    #[test]
    fn cem_update_concentrates_on_the_elites() {
        let mut d = Sampler::new(2, &KINDS, 7);
        let elite = Candidate {
            pattern: 1,
            kind: KINDS[3],
            z: vec![0.9; 7],
        };
        for _ in 0..6 {
            d.update(&[&elite, &elite]);
        }
        assert!(
            d.patterns[1] > 0.9 && d.patterns[0] > 0.04,
            "{:?}",
            d.patterns
        );
        assert!(d.kinds[3] > 0.85, "{:?}", d.kinds);
        assert!((d.mu[3][0] - 0.9).abs() < 1e-3);
        assert_eq!(d.sigma[3][0], SIGMA_MIN);
        assert!((d.kinds.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let hits = (0..200)
            .filter(|_| {
                let c = d.sample(&mut rng);
                c.pattern == 1 && c.kind == KINDS[3]
            })
            .count();
        assert!(hits > 150, "{hits}");
    }

    fn space(patterns: usize) -> SearchSpace {
        use ftcbf_sim::sensors::Quantity;
        SearchSpace {
            patterns: (0..patterns)
                .map(|i| super::super::space::Pattern {
                    name: format!("p{i}"),
                    channels: vec![
                        (format!("c{i}x"), Quantity::X),
                        (format!("c{i}y"), Quantity::Y),
                    ],
                })
                .collect(),
            duration: 20.0,
            dim: 7,
            family: super::super::space::Family::Injectors,
        }
    }

    /// A made-up robustness: lowest for a stealthy attack on pattern 1 with z near 0.8, with
    /// seed noise of ±0.01.
    fn synthetic(c: &Candidate, seed: u64) -> f64 {
        weak_spot(c, seed, Kind::Stealthy)
    }

    /// A made-up robustness whose weak spot is an attack of `kind` on pattern 1 with z near
    /// 0.8, with seed noise of ±0.01.
    fn weak_spot(c: &Candidate, seed: u64, kind: Kind) -> f64 {
        let arm = if c.pattern == 1 && c.kind == kind {
            0.0
        } else {
            0.5
        };
        let d: f64 = c.z[..5].iter().map(|v| (v - 0.8).powi(2)).sum();
        let noise = (trial_seed(seed, c.z[0].to_bits()) % 2001) as f64 / 1000.0 - 1.0;
        arm + d + 0.01 * noise
    }

    /// Evaluations of `cs` on `seeds` with the made-up robustness `rho(candidate, seed)`.
    fn evals_with(
        g: Option<usize>,
        cs: Vec<Candidate>,
        space: &SearchSpace,
        seeds: &[u64],
        rho: impl Fn(&Candidate, u64) -> f64,
    ) -> Vec<Evaluation> {
        cs.into_iter()
            .map(|c| {
                let runs = seeds
                    .iter()
                    .map(|&s| SeedRun {
                        seed: s,
                        robustness: Robustness {
                            value: rho(&c, s),
                            collided: false,
                            binding: "x".into(),
                        },
                    })
                    .collect();
                Evaluation::new(g, c, space, runs)
            })
            .collect()
    }

    /// Synthetic evaluations of `cs` on `seeds`.
    fn synthetic_evals(
        g: Option<usize>,
        cs: Vec<Candidate>,
        space: &SearchSpace,
        seeds: &[u64],
    ) -> Vec<Evaluation> {
        evals_with(g, cs, space, seeds, synthetic)
    }

    /// One method's searched evaluations, then (the CEM) its refinement from the worst of them,
    /// as [`Search::run`] does without the finalists.
    fn evaluations(method: Method, plan: &Plan, space: &SearchSpace, seed: u64) -> Vec<Evaluation> {
        let (mut search, _) = search_generations(method, plan, space, seed, |g, cs| {
            Ok(synthetic_evals(
                Some(g),
                cs,
                space,
                &plan.generation_seeds(seed, g),
            ))
        })
        .expect("search");
        if method == Method::Cem {
            let start = worst_run(&search).expect("runs");
            let refined = refine_counterexample(plan, seed, start, |cs, seeds| {
                Ok(synthetic_evals(None, cs, space, seeds))
            })
            .expect("refine");
            search.extend(refined);
        }
        search
    }

    /// Half of every later CEM generation is random search's first candidates of that
    /// generation, with the same runs: the CEM sees half of what random search sees.
    #[test]
    fn the_cems_exploration_is_random_searchs_own_candidates_and_runs() {
        let plan = Plan::new(400).expect("plan");
        let sp = space(3);
        for seed in 1..=5 {
            let cem = evaluations(Method::Cem, &plan, &sp, seed);
            let rnd = evaluations(Method::Random, &plan, &sp, seed);
            for g in 1..plan.cma_from {
                let of = |e: &[Evaluation]| -> Vec<Evaluation> {
                    e.iter()
                        .filter(|e| e.generation == Some(g) && !e.cmaes)
                        .cloned()
                        .collect()
                };
                let (c, r) = (of(&cem), of(&rnd));
                let shared = &c[plan.carry..plan.carry + plan.explore];
                assert_eq!(shared, &r[..plan.explore], "seed {seed}, generation {g}");
                // The rest is the CEM's own: carried elites and samples of its distribution.
                assert!(
                    c[plan.carry + plan.explore..]
                        .iter()
                        .all(|e| !r.contains(e)),
                    "seed {seed}, generation {g}"
                );
            }
        }
    }

    /// A plateau: every run gives the start's margin 0.05 (the same for every candidate on a
    /// seed), but for scale attacks on pattern 2 with z₀ < 0.25 if `dip`, which give −0.5.
    fn plateau(c: &Candidate, dip: bool) -> f64 {
        if dip && c.pattern == 2 && c.kind == Kind::Scale && c.z[0] < 0.25 {
            -0.5
        } else {
            0.05
        }
    }

    /// One CEM generation on [`plateau`], as the proposer saw it.
    struct PlateauGeneration {
        /// Its candidates' evaluations.
        evals: Vec<Evaluation>,
        /// The proposer called it flat after observing it.
        flat: bool,
        /// The distribution's kind probabilities before and after it observed them.
        kinds_before: Vec<f64>,
        kinds_after: Vec<f64>,
    }

    /// The CEM's generations before CMA-ES on [`plateau`].
    fn cem_on_plateau(
        plan: &Plan,
        sp: &SearchSpace,
        seed: u64,
        dip: bool,
    ) -> Vec<PlateauGeneration> {
        let mut proposer = Proposer::new(Method::Cem, plan, sp, seed);
        (0..plan.cma_from)
            .map(|g| {
                let evals = evals_with(
                    Some(g),
                    proposer.propose(g),
                    sp,
                    &plan.generation_seeds(seed, g),
                    |c, _| plateau(c, dip),
                );
                let kinds_before = proposer.dist.kinds.clone();
                proposer.observe(&evals);
                PlateauGeneration {
                    evals,
                    flat: proposer.flat,
                    kinds_before,
                    kinds_after: proposer.dist.kinds.clone(),
                }
            })
            .collect()
    }

    /// On a plateau every generation is flat: the CEM does not move its distribution towards
    /// tied elites, and its own candidates go to the least-tried (pattern, kind) cells, so it
    /// tries all 36 cells of a 3-pattern space before CMA-ES. Where one cell dips below the
    /// plateau, the first generation that finds it is not flat, and the next carries the dip.
    #[test]
    fn on_a_plateau_the_cem_covers_every_cell_and_keeps_a_dip_it_finds() {
        let plan = Plan::new(400).expect("plan");
        let sp = space(3);
        let mut kept = 0;
        for seed in 0..20 {
            let gens = cem_on_plateau(&plan, &sp, seed, false);
            let cells: std::collections::BTreeSet<(usize, usize)> = gens
                .iter()
                .flat_map(|gen| gen.evals.iter())
                .map(|e| (e.candidate.pattern, kind_index(&KINDS, &e.candidate)))
                .collect();
            assert_eq!(cells.len(), 3 * KINDS.len(), "seed {seed}");
            for (g, gen) in gens.iter().enumerate() {
                assert!(gen.flat, "seed {seed}, generation {g}");
                assert_eq!(
                    gen.kinds_before, gen.kinds_after,
                    "seed {seed}: a flat generation moved the CEM"
                );
            }
            let gens = cem_on_plateau(&plan, &sp, seed, true);
            let found = gens[..plan.cma_from - 1]
                .iter()
                .position(|gen| gen.evals.iter().any(|e| e.mean < 0.0));
            if let Some(g) = found {
                let dip = gens[g].evals.iter().find(|e| e.mean < 0.0).expect("dip");
                assert!(
                    !gens[g].flat,
                    "seed {seed}: a generation with a dip is flat"
                );
                assert!(
                    gens[g + 1].evals[..plan.carry]
                        .iter()
                        .any(|e| e.candidate == dip.candidate),
                    "seed {seed}: the dip was not carried"
                );
                kept += 1;
            }
        }
        assert!(kept >= 5, "the dip was found on only {kept} of 20 seeds");
    }

    fn worst(e: &[Evaluation]) -> f64 {
        e.iter()
            .flat_map(|e| &e.runs)
            .map(|r| r.robustness.value)
            .fold(f64::INFINITY, f64::min)
    }

    /// The fallback family is what a search with it draws from, every (pattern, kind) cell of
    /// it is tried, and the CEM finds a narrow weak spot inside it (a made-up ρ lowest for a
    /// timed ramp on pattern 1 with z near 0.8, without the counterexample refinement).
    #[test]
    fn the_fallback_family_is_searched_and_its_weak_spot_found() {
        let plan = Plan::new(200).expect("plan");
        let sp = space(2).with_family(Family::Fallback);
        let rho = |c: &Candidate, seed: u64| weak_spot(c, seed, Kind::TimedRamp);
        let mut found = 0;
        for seed in 0..10 {
            let (search, _) = search_generations(Method::Cem, &plan, &sp, seed, |g, cs| {
                Ok(evals_with(
                    Some(g),
                    cs,
                    &sp,
                    &plan.generation_seeds(seed, g),
                    rho,
                ))
            })
            .expect("search");
            assert!(search
                .iter()
                .all(|e| FALLBACK_KINDS.contains(&e.candidate.kind)));
            let mut cells: Vec<(usize, Kind)> = search
                .iter()
                .map(|e| (e.candidate.pattern, e.candidate.kind))
                .collect();
            cells.sort_by_key(|&(p, k)| {
                (
                    p,
                    kind_index(
                        &FALLBACK_KINDS,
                        &Candidate {
                            pattern: p,
                            kind: k,
                            z: vec![],
                        },
                    ),
                )
            });
            cells.dedup();
            assert_eq!(cells.len(), 2 * FALLBACK_KINDS.len(), "seed {seed}");
            let (e, run) = worst_run(&search).expect("runs");
            if e.candidate.pattern == 1
                && e.candidate.kind == Kind::TimedRamp
                && run.robustness.value < 0.2
            {
                found += 1;
            }
        }
        // Measured: on 9 of 10 seeds (worst ρ 0.006 to 0.18); seed 1 ends in an undercut at
        // 0.56. Other arms cannot go below 0.5.
        assert!(found >= 8, "the weak spot was found on {found} of 10 seeds");
    }

    #[test]
    fn the_first_generation_is_random_searchs_and_both_spend_the_same_runs() {
        let plan = Plan::new(400).expect("plan");
        let sp = space(2);
        let cem = evaluations(Method::Cem, &plan, &sp, 3);
        let rnd = evaluations(Method::Random, &plan, &sp, 3);
        let runs = |e: &[Evaluation]| e.iter().map(|e| e.runs.len()).sum::<usize>();
        // The CEM's refinement is paid from its CMA-ES candidates (finalists not simulated here).
        assert_eq!(runs(&rnd), plan.candidates * plan.seeds_per_candidate);
        let paid = plan.refine_runs().div_ceil(plan.seeds_per_candidate) * plan.seeds_per_candidate;
        assert_eq!(runs(&cem), runs(&rnd) - paid + plan.refine_runs());
        assert_eq!(rnd.len(), plan.candidates);
        assert_eq!(cem[..plan.first], rnd[..plan.first]);
        assert_ne!(cem[plan.first..], rnd[plan.first..]);
        let n = |e: &[Evaluation], g: Option<usize>| e.iter().filter(|e| e.generation == g).count();
        for g in 0..plan.generations {
            assert_eq!(n(&rnd, Some(g)), plan.generation_size(g));
        }
        for g in 0..plan.cma_from {
            assert_eq!(n(&cem, Some(g)), plan.generation_size(g));
        }
        // The CEM's later generations' candidates go to CMA-ES, on generation `cma_from`'s seeds.
        assert_eq!(n(&cem, Some(plan.cma_from)), plan.cma_candidates);
        assert_eq!(cem.iter().filter(|e| e.cmaes).count(), plan.cma_candidates);
        assert_eq!(n(&cem, None), plan.refine_runs());
        assert!(cem.iter().all(|e| e.refinement == e.generation.is_none()));
        assert!(rnd.iter().all(|e| !e.refinement));
    }

    /// The CEM's refinement descends from the worst run on that run's seed: every
    /// refinement run uses that seed and the worst run only gets worse (here, on a smooth
    /// objective, strictly on most base seeds).
    #[test]
    fn refinement_descends_on_the_worst_runs_seed() {
        let plan = Plan::new(400).expect("plan");
        assert_eq!((plan.refine_rounds, plan.refine_per_round), (4, 5));
        let sp = space(2);
        let mut strictly = 0;
        for seed in 0..10 {
            let cem = evaluations(Method::Cem, &plan, &sp, seed);
            let (before, after): (Vec<Evaluation>, Vec<Evaluation>) =
                cem.into_iter().partition(|e| !e.refinement);
            let (e, run) = worst_run(&before).expect("runs");
            assert!(after.iter().all(|a| a.runs.len() == 1
                && a.runs[0].seed == run.seed
                && a.candidate.pattern == e.candidate.pattern
                && a.candidate.kind == e.candidate.kind));
            let refined = worst(&after).min(run.robustness.value);
            strictly += usize::from(refined < run.robustness.value);
        }
        assert!(
            strictly >= 8,
            "refinement improved the worst run on {strictly}/10"
        );
    }

    #[test]
    fn elites_survive_and_cmaes_refines_the_best_cells() {
        let plan = Plan::new(400).expect("plan");
        let sp = space(2);
        let cem = evaluations(Method::Cem, &plan, &sp, 11);
        let generation = |g: usize| -> Vec<&Evaluation> {
            cem.iter()
                .filter(|e| e.generation == Some(g) && !e.cmaes)
                .collect()
        };
        for g in 1..plan.cma_from {
            let mut prev = generation(g - 1);
            prev.sort_by(|a, b| a.cmp_worse_tail(b));
            let now = generation(g);
            // The previous generation's best `carry` candidates (its best among them) are re-run
            // in this one.
            for e in &prev[..plan.carry] {
                assert!(
                    now.iter().any(|n| n.candidate == e.candidate),
                    "generation {g} lost an elite"
                );
            }
        }
        // The CEM's late generations are CMA-ES: `cma_candidates` candidates in the best
        // `cma_cells` distinct cells, on generation `cma_from`'s seeds, and it descends: on this
        // smooth objective its best is below the best searched before it, in every cell.
        let cma: Vec<&Evaluation> = cem.iter().filter(|e| e.cmaes).collect();
        assert_eq!(cma.len(), plan.cma_candidates);
        let seeds = plan.generation_seeds(11, plan.cma_from);
        assert!(cma
            .iter()
            .all(|e| e.runs.iter().map(|r| r.seed).eq(seeds.iter().copied())));
        let before: Vec<Evaluation> = cem
            .iter()
            .filter(|e| !e.cmaes && !e.refinement)
            .cloned()
            .collect();
        let (_, traces) = search_generations(Method::Cem, &plan, &sp, 11, |g, cs| {
            Ok(synthetic_evals(
                Some(g),
                cs,
                &sp,
                &plan.generation_seeds(11, g),
            ))
        })
        .expect("search");
        assert_eq!(traces.len(), plan.cma_cells);
        let mut cells: Vec<(usize, Kind)> = Vec::new();
        for c in pooled_ranking(&before) {
            if !cells.contains(&(c.pattern, c.kind)) {
                cells.push((c.pattern, c.kind));
            }
        }
        for (t, cell) in traces.iter().zip(&cells) {
            assert_eq!((t.pattern, t.kind), *cell);
            assert!(t.best_mean < t.start_mean, "{t:?}");
            assert_eq!(t.generations, t.candidates.div_ceil(t.lambda), "{t:?}");
        }
    }

    /// The CEM's CMA-ES stage improves on its starting point, the best candidate of its cell,
    /// in at least 4 of 5 cells over two budgets and five seeds, on the synthetic objective (a
    /// quadratic bowl plus ±0.01 of seed noise; a cell whose start is already within the noise
    /// of its optimum may not improve). Convergence of the CMA-ES itself, on noise-free
    /// functions, is tested in `cmaes`.
    #[test]
    fn cmaes_stage_improves_on_its_start() {
        let sp = space(2);
        let (mut cells, mut improved) = (0, 0);
        for budget in [400, 2000] {
            let plan = Plan::new(budget).expect("plan");
            for seed in 0..5 {
                let (_, traces) = search_generations(Method::Cem, &plan, &sp, seed, |g, cs| {
                    Ok(synthetic_evals(
                        Some(g),
                        cs,
                        &sp,
                        &plan.generation_seeds(seed, g),
                    ))
                })
                .expect("search");
                for t in &traces {
                    cells += 1;
                    improved += usize::from(t.best_mean < t.start_mean);
                }
            }
        }
        assert!(
            improved * 5 >= cells * 4,
            "improved in {improved} of {cells} cells"
        );
    }

    #[test]
    fn cem_beats_random_search_at_the_same_budget_and_seeds() {
        let plan = Plan::new(400).expect("plan");
        let sp = space(2);
        // A deceptive objective: the best arm is 1 of 24 and its average is worse than the
        // others'. Random search can still get lucky on a seed (seed 4 here: 0.090 vs 0.111),
        // so the test asks for most seeds and a clearly lower average. This narrow optimum
        // rewards exploitation; half of every generation now explores (the catalogue rewards
        // that), which moved the CEM's sum from below half of random search's to 0.63 of it.
        let (mut better, mut sum_c, mut sum_r) = (0, 0.0, 0.0);
        for seed in 0..10 {
            let c = worst(&evaluations(Method::Cem, &plan, &sp, seed));
            let r = worst(&evaluations(Method::Random, &plan, &sp, seed));
            better += usize::from(c < r);
            sum_c += c;
            sum_r += r;
        }
        assert!(better >= 8, "CEM strictly better on {better}/10");
        assert!(sum_c < 0.7 * sum_r, "CEM {sum_c} vs random {sum_r}");
    }

    #[test]
    fn finalists_pool_the_runs_of_a_carried_candidate() {
        let sp = space(1);
        let cand = |v: f64| Candidate {
            pattern: 0,
            kind: Kind::Bias,
            z: vec![v; 7],
        };
        let ev = |c: Candidate, values: &[f64]| {
            let runs = values
                .iter()
                .map(|&v| SeedRun {
                    seed: 0,
                    robustness: Robustness {
                        value: v,
                        collided: false,
                        binding: "x".into(),
                    },
                })
                .collect();
            Evaluation::new(Some(0), c, &sp, runs)
        };
        // a: lucky once (0.1), then 0.5 twice → pooled 0.367; b: 0.2 once.
        let search = vec![
            ev(cand(0.9), &[0.1, 0.1]),
            ev(cand(0.2), &[0.2, 0.2]),
            ev(cand(0.9), &[0.5, 0.5]),
            ev(cand(0.9), &[0.5, 0.5]),
        ];
        let r = pooled_ranking(&search);
        assert_eq!(r.len(), 2);
        assert_eq!(*r[0], cand(0.2));
        assert_eq!(*r[1], cand(0.9));
    }
}

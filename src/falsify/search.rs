//! The optimiser (a cross-entropy method over the mixed discrete/continuous attack space), the
//! random-search comparison, and the evaluation of candidates on several seeds.

use anyhow::{anyhow, Context};
use ftcbf_sim::attacks::AttackSpec;
use ftcbf_sim::runner::{run, RunOptions};
use ftcbf_sim::world::{ControllerKindSpec, World};
use indicatif::ProgressBar;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

use super::robustness::Robustness;
use super::space::{Candidate, SearchSpace, KINDS};
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
const KIND_FLOOR: f64 = 0.12;

/// How a budget of runs is spent (the same for the CEM and for random search).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Plan {
    /// Runs allowed.
    pub budget: usize,
    /// Seeds every searched candidate is run on (common within a generation, fresh per generation).
    pub seeds_per_candidate: usize,
    /// Candidates per generation.
    pub population: usize,
    /// Candidates searched.
    pub candidates: usize,
    /// Generations (the last may be smaller).
    pub generations: usize,
    /// Best candidates per generation that steer the next (CEM).
    pub elites: usize,
    /// Best searched candidates re-run on held-out seeds.
    pub finalists: usize,
    /// Held-out seeds per finalist (the same for every finalist).
    pub final_seeds: usize,
    /// Runs used: candidates × seeds_per_candidate + finalists × final_seeds ≤ budget.
    pub runs: usize,
}

impl Plan {
    /// The plan for `budget` runs: a fifth for the final re-evaluation (up to 4 finalists), the
    /// rest for the search at 2 seeds per candidate, in generations of about a fifth of the
    /// candidates (6 to 24).
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
        let population = (candidates / 5).clamp(6, 24);
        let generations = candidates.div_ceil(population);
        let elites = (population / 4).max(2);
        Ok(Plan {
            budget,
            seeds_per_candidate,
            population,
            candidates,
            generations,
            elites,
            finalists,
            final_seeds,
            runs: candidates * seeds_per_candidate + finalists * final_seeds,
        })
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
    pub bar: &'a ProgressBar,
}

/// The CEM's sampling distribution: categorical over patterns and kinds, an independent
/// Gaussian per coordinate of z for each kind (clipped to [0, 1]).
struct Sampler {
    patterns: Vec<f64>,
    kinds: Vec<f64>,
    mu: Vec<Vec<f64>>,
    sigma: Vec<Vec<f64>>,
}

impl Sampler {
    fn new(patterns: usize, dim: usize) -> Self {
        Self {
            patterns: vec![1.0 / patterns as f64; patterns],
            kinds: vec![1.0 / KINDS.len() as f64; KINDS.len()],
            mu: vec![vec![0.5; dim]; KINDS.len()],
            sigma: vec![vec![SIGMA0; dim]; KINDS.len()],
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
            kind: KINDS[k],
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
            fk[kind_index(e)] += 1.0 / n;
        }
        blend(&mut self.patterns, &fp, PATTERN_FLOOR);
        blend(&mut self.kinds, &fk, KIND_FLOOR);
        for k in 0..KINDS.len() {
            let mine: Vec<&Candidate> = elites
                .iter()
                .copied()
                .filter(|e| kind_index(e) == k)
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

fn kind_index(c: &Candidate) -> usize {
    KINDS.iter().position(|k| *k == c.kind).unwrap_or(0)
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

fn uniform(space: &SearchSpace, rng: &mut ChaCha8Rng) -> Candidate {
    let pattern = rng.random_range(0..space.patterns.len());
    let kind = KINDS[rng.random_range(0..KINDS.len())];
    let z = (0..space.dim).map(|_| rng.random::<f64>()).collect();
    Candidate { pattern, kind, z }
}

impl Search<'_> {
    /// Runs every candidate on every seed (in parallel) and returns one evaluation per candidate.
    fn evaluate(
        &self,
        generation: Option<usize>,
        candidates: Vec<Candidate>,
        seeds: &[u64],
    ) -> anyhow::Result<Vec<Evaluation>> {
        let hidden = ProgressBar::hidden();
        let worlds: Vec<World> = run_parallel(self.pool, &candidates, &hidden, |c| {
            self.template
                .world_with(&self.space.decode(c))
                .with_context(|| self.space.describe(c))
        })?;
        let tasks: Vec<(usize, u64)> = (0..candidates.len())
            .flat_map(|i| seeds.iter().map(move |&s| (i, s)))
            .collect();
        let results = run_parallel(self.pool, &tasks, self.bar, |&(i, seed)| {
            let opts = RunOptions {
                seed: Some(seed),
                controller: Some(self.controller),
                duration: None,
            };
            let s = run(&worlds[i], &opts).with_context(|| {
                format!(
                    "run of {} with seed {seed} failed",
                    self.space.describe(&candidates[i])
                )
            })?;
            let robustness = Robustness::of(&worlds[i], &s)
                .ok_or_else(|| anyhow!("the world has no safe set and no obstacle"))?;
            Ok(SeedRun { seed, robustness })
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

    /// One whole search: generations, then the finalists on held-out seeds.
    pub fn run(&self, method: Method) -> anyhow::Result<MethodResult> {
        let plan = &self.plan;
        let tag = match method {
            Method::Cem => 0x43_45_4d,
            Method::Random => 0x52_4e_44,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(trial_seed(self.seed, u64::MAX - tag));
        let mut dist = Sampler::new(self.space.patterns.len(), self.space.dim);
        let mut search: Vec<Evaluation> = Vec::with_capacity(plan.candidates);
        for g in 0..plan.generations {
            let n = plan.population.min(plan.candidates - search.len());
            let candidates: Vec<Candidate> = (0..n)
                .map(|_| match method {
                    Method::Cem if g > 0 => dist.sample(&mut rng),
                    _ => uniform(self.space, &mut rng),
                })
                .collect();
            self.bar.set_message(format!(
                "{} generation {}/{}",
                method.name(),
                g + 1,
                plan.generations
            ));
            let evals = self.evaluate(Some(g), candidates, &plan.generation_seeds(self.seed, g))?;
            if method == Method::Cem {
                let mut order: Vec<&Evaluation> = evals.iter().collect();
                order.sort_by(|a, b| a.cmp_worse(b));
                let elites: Vec<&Candidate> = order
                    .iter()
                    .take(plan.elites)
                    .map(|e| &e.candidate)
                    .collect();
                dist.update(&elites);
            }
            search.extend(evals);
        }
        // Finalists: the best distinct searched candidates, on held-out seeds.
        let mut order: Vec<&Evaluation> = search.iter().collect();
        order.sort_by(|a, b| a.cmp_worse(b));
        let mut picked: Vec<Candidate> = Vec::with_capacity(plan.finalists);
        let mut picked_attacks: Vec<&Vec<AttackSpec>> = Vec::new();
        for e in order {
            if picked.len() == plan.finalists {
                break;
            }
            if !picked_attacks.contains(&&e.attacks) {
                picked_attacks.push(&e.attacks);
                picked.push(e.candidate.clone());
            }
        }
        self.bar
            .set_message(format!("{} final re-evaluation", method.name()));
        let mut finalists = self.evaluate(None, picked, &plan.final_seeds(self.seed))?;
        finalists.sort_by(|a, b| a.cmp_worse(b));
        let all = || search.iter().chain(&finalists);
        let worst = all()
            .map(|e| (e, e.worst()))
            .reduce(|a, b| {
                if b.1.robustness.cmp_worse(&a.1.robustness).is_lt() {
                    b
                } else {
                    a
                }
            })
            .ok_or_else(|| anyhow!("the search made no run"))?;
        let witness = Witness {
            attacks: worst.0.attacks.clone(),
            description: worst.0.description.clone(),
            seed: worst.1.seed,
            robustness: worst.1.robustness.clone(),
        };
        let runs = all().map(|e| e.runs.len()).sum();
        let unsafe_runs = all().map(|e| e.unsafe_runs).sum();
        Ok(MethodResult {
            method,
            search,
            finalists,
            witness,
            runs,
            unsafe_runs,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        }
        let p = Plan::new(200).expect("plan");
        assert_eq!(
            (
                p.candidates,
                p.population,
                p.generations,
                p.finalists,
                p.final_seeds
            ),
            (80, 16, 5, 4, 10)
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
        let mut d = Sampler::new(2, 7);
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
}

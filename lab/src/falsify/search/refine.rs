//! Refinement of the best attack found: CMA-ES on its continuous coordinates
//! ([`crate::falsify::cmaes`]), and the counterexample's final re-evaluation on held-out seeds.

use super::*;

/// One CMA-ES refinement of a (pattern, kind) cell, as the report states it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CmaTrace {
    /// Index of the fault pattern.
    pub pattern: usize,
    /// Injector kind.
    pub kind: crate::falsify::space::Kind,
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
pub(super) const COLLISION_PENALTY: f64 = 10.0;

/// The CMA-ES objective of an evaluation (lower is worse for the controller).
pub(super) fn cma_objective(e: &Evaluation) -> f64 {
    e.mean - COLLISION_PENALTY * e.collisions as f64
}

/// The CEM's CMA-ES refinement: the best `plan.cma_cells` distinct (pattern, kind) cells of the
/// search so far (pooled ranking), each refined on its continuous parameters from its best
/// candidate, with the CEM's spread in that kind as the initial step, for an even share of
/// `plan.cma_candidates` (every candidate on the seeds `evaluate` gives generation
/// `plan.cma_from`, the same throughout).
pub(super) fn cma_refine(
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

/// The CEM's counterexample refinement, with the held-out runs of one finalist: the worst run so
/// far (`start`, searched or held-out) fixes a seed, on which ρ is a deterministic function of
/// the attack (the noise is the seed's), and a (1 + λ) evolution strategy descends from that
/// run's attack. Each round runs `refine_per_round` Gaussian perturbations of the incumbent's
/// continuous parameters (same pattern and kind) on that seed, moves the incumbent to the round's
/// worst run if it is worse than the incumbent's, and widens its step (×1.5, at most
/// [`REFINE_SIGMA_MAX`]) after a success, halves it after a failure. `evaluate(candidates,
/// seeds)` runs them; the evaluations come back marked as refinement.
pub(super) fn refine_counterexample(
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

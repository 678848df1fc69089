//! The search's tests: budgets, determinism, the methods against made-up objectives.

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
fn cem_on_plateau(plan: &Plan, sp: &SearchSpace, seed: u64, dip: bool) -> Vec<PlateauGeneration> {
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

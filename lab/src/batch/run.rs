//! Running a batch on a thread pool, and a sweep of batches.

use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{anyhow, Context};

use crate::progress::Progress;

use super::{
    trial_seed, BatchPlan, BatchResult, Execution, Override, PrepareFn, Sweep, TrialRecord,
    TrialRunner, WorldInfo,
};

/// A pool of `jobs` worker threads (`None` = one per core), on which a command runs its trials.
pub fn worker_pool(jobs: Option<usize>) -> anyhow::Result<rayon::ThreadPool> {
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(j) = jobs {
        pool = pool.num_threads(j.max(1));
    }
    pool.build().context("could not start the worker threads")
}

/// Runs `f` on every item on `pool`, advancing `progress` once per finished item, and returns the
/// results in item order, so the outcome does not depend on the number of threads. After a
/// failure, items not yet started are skipped, and the error of the lowest-index failed item is
/// returned.
pub fn run_parallel<T, R, F>(
    pool: &rayon::ThreadPool,
    items: &[T],
    progress: &dyn Progress,
    f: F,
) -> anyhow::Result<Vec<R>>
where
    T: Sync,
    R: Send,
    F: Fn(&T) -> anyhow::Result<R> + Sync,
{
    use rayon::prelude::*;

    let failed = AtomicBool::new(false);
    let outcomes: Vec<Option<anyhow::Result<R>>> = pool.install(|| {
        items
            .par_iter()
            .map(|item| {
                if failed.load(Ordering::Relaxed) {
                    return None;
                }
                let out = f(item);
                if out.is_err() {
                    failed.store(true, Ordering::Relaxed);
                }
                progress.advance(1);
                Some(out)
            })
            .collect()
    });
    let mut results = Vec::with_capacity(outcomes.len());
    for out in outcomes.into_iter().flatten() {
        results.push(out?);
    }
    if results.len() != items.len() {
        // Unreachable: an item is skipped only after another one failed, whose error is
        // returned above. Kept as a guard so a result is never silently short.
        return Err(anyhow!("stopped early after a failed run"));
    }
    Ok(results)
}

/// Run every trial of `plan` (its shard only, if it has one) with every controller, on
/// `exec.jobs` threads, and aggregate. Trial k of every controller uses [`trial_seed`]`(S, k)`.
/// The result is the same for any number of threads. A failing trial stops the batch (trials
/// not yet started are skipped) with an error naming the lowest failed trial, its seed and
/// controller.
pub fn run_batch(
    runner: &dyn TrialRunner,
    plan: &BatchPlan,
    exec: Execution<'_>,
) -> anyhow::Result<BatchResult> {
    plan.validate()?;
    let tasks: Vec<(u64, &str)> = plan
        .trial_indices()
        .into_iter()
        .flat_map(|k| plan.controllers.iter().map(move |c| (k, c.as_str())))
        .collect();
    exec.progress.start(tasks.len() as u64, &plan.world);
    let pool = worker_pool(exec.jobs)?;
    let records = run_parallel(&pool, &tasks, exec.progress, |&(k, controller)| {
        let seed = trial_seed(plan.base_seed, k);
        runner
            .run_trial(controller, seed)
            .and_then(|s| {
                if s.seed != seed || s.controller != controller {
                    Err(anyhow!(
                        "the runner returned a summary for seed {} / `{}`, not for seed {seed} / `{controller}`",
                        s.seed,
                        s.controller
                    ))
                } else {
                    Ok(TrialRecord::from_summary(k, &s))
                }
            })
            .with_context(|| format!("trial {k} (seed {seed}, controller {controller}) failed"))
    });
    exec.progress.finish();
    BatchResult::from_records(plan.clone(), records?, Vec::new())
}

/// Run `plan_for` once per sweep value (or once without a sweep): for each point the world is
/// prepared by `prepare` with that point's overrides, and `plan_for` turns the prepared world's
/// info and the overrides into the plan.
pub fn run_sweep(
    prepare: &PrepareFn<'_>,
    sweep: Option<&Sweep>,
    plan_for: &dyn Fn(&WorldInfo, Vec<Override>) -> anyhow::Result<BatchPlan>,
    exec: Execution<'_>,
) -> anyhow::Result<Vec<BatchResult>> {
    let points: Vec<Vec<Override>> = match sweep {
        None => vec![Vec::new()],
        Some(s) => s
            .values
            .iter()
            .map(|&value| {
                vec![Override {
                    key: s.key.clone(),
                    value,
                }]
            })
            .collect(),
    };
    let mut results = Vec::with_capacity(points.len());
    for overrides in points {
        let label = overrides
            .iter()
            .map(|o| format!("{}={}", o.key, o.value))
            .collect::<Vec<_>>()
            .join(", ");
        let prepared = prepare(&overrides).with_context(|| {
            if label.is_empty() {
                "could not prepare the world".to_string()
            } else {
                format!("could not prepare the world with {label}")
            }
        })?;
        let plan = plan_for(&prepared.info, overrides)?;
        let result = run_batch(prepared.runner.as_ref(), &plan, exec).with_context(|| {
            if label.is_empty() {
                "batch failed".to_string()
            } else {
                format!("batch at {label} failed")
            }
        })?;
        results.push(result);
    }
    Ok(results)
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::*;
    use super::*;

    #[test]
    fn jobs_do_not_change_the_result() {
        let runner = Synthetic {
            p_safe: 0.9,
            fail_seed: None,
        };
        let plan = plan(200, None);
        let one = run_batch(&runner, &plan, SERIAL).expect("batch");
        let two = run_batch(
            &runner,
            &plan,
            Execution {
                jobs: Some(2),
                progress: &crate::progress::Silent,
            },
        )
        .expect("batch");
        let four = run_batch(
            &runner,
            &plan,
            Execution {
                jobs: Some(4),
                progress: &crate::progress::Silent,
            },
        )
        .expect("batch");
        assert_eq!(one, two);
        assert_eq!(one, four);
        assert_eq!(
            io::to_json(std::slice::from_ref(&one)).ok(),
            io::to_json(&[two]).ok()
        );
        // Same seeds for both controllers of a trial (paired design).
        assert_eq!(one.records.len(), 400);
        for pair in one.records.chunks(2) {
            assert_eq!(pair[0].seed, pair[1].seed);
            assert_eq!(
                (pair[0].controller.as_str(), pair[1].controller.as_str()),
                ("ft-cbf-clf", "baseline")
            );
        }
    }

    #[test]
    fn a_failing_trial_names_trial_seed_and_controller() {
        let bad_seed = trial_seed(42, 17);
        let runner = Synthetic {
            p_safe: 0.9,
            fail_seed: Some(bad_seed),
        };
        let err = run_batch(&runner, &plan(40, None), SERIAL).expect_err("must fail");
        let msg = format!("{err:#}");
        assert!(
            msg.contains("trial 17")
                && msg.contains(&bad_seed.to_string())
                && msg.contains("ft-cbf-clf"),
            "{msg}"
        );
        assert!(msg.contains("synthetic failure"), "{msg}");
    }

    #[test]
    fn invalid_plans_are_rejected() {
        let runner = Synthetic {
            p_safe: 0.9,
            fail_seed: None,
        };
        let mut p = plan(10, None);
        p.controllers = vec!["baseline".into(), "baseline".into()];
        assert!(
            run_batch(&runner, &p, SERIAL).is_err_and(|e| e.to_string().contains("listed twice"))
        );
        let mut p = plan(10, None);
        p.epsilon = Some(1.5);
        assert!(run_batch(&runner, &p, SERIAL).is_err_and(|e| e.to_string().contains("epsilon")));
        let mut p = plan(10, None);
        p.trials = 0;
        assert!(run_batch(&runner, &p, SERIAL).is_err());
        let p = plan(2, Some(Shard { index: 3, count: 3 }));
        assert!(run_batch(&runner, &p, SERIAL).is_err_and(|e| e
            .to_string()
            .contains("shard 3/3 of 2 trials holds no trial")));
        let p = plan(5, Some(Shard { index: 1, count: 0 }));
        assert!(run_batch(&runner, &p, SERIAL).is_err_and(|e| e.to_string().contains("invalid")));
    }
}

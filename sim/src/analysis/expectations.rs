//! Worlds as regression cases: which controllers a world's `[expect]` names, and whether the runs
//! of its seeds meet it. Running the seeds (in parallel, with a table) is `ftcbf_lab::regress`; this
//! module is the judgement, a pure function of the summaries.

use std::path::PathBuf;

use crate::summary::{RunSummary, EVENTS, METRICS};
use crate::world::{ControllerKindSpec, Count, ExpectOutcome, Margin, World};

/// The expectations a world states for `kind` (`None`: not a case for that controller).
pub fn expectation_for(world: &World, kind: ControllerKindSpec) -> Option<ExpectOutcome> {
    let e = world.file.expect.as_ref()?;
    let o = if kind == world.file.control.controller {
        Some(e.own.clone())
    } else {
        match kind {
            ControllerKindSpec::Baseline => e.baseline.clone(),
            ControllerKindSpec::Nominal => e.nominal.clone(),
            ControllerKindSpec::FtCbfClf => None,
        }
    };
    o.filter(|o| !o.is_empty())
}

/// The controllers a world's `[expect]` covers: its own, then any comparison tables.
pub fn expected_controllers(world: &World) -> Vec<ControllerKindSpec> {
    [
        world.file.control.controller,
        ControllerKindSpec::FtCbfClf,
        ControllerKindSpec::Baseline,
        ControllerKindSpec::Nominal,
    ]
    .into_iter()
    .fold(Vec::new(), |mut acc, k| {
        if !acc.contains(&k) && expectation_for(world, k).is_some() {
            acc.push(k);
        }
        acc
    })
}

/// Number of seeds the world's expectations are judged over (1 without `[expect]`).
pub fn seed_count(world: &World) -> u32 {
    world.file.expect.as_ref().map_or(1, |e| e.seeds)
}

/// Why one run shows (or lacks) an event, in words with the numbers behind it.
fn describe(key: &str, s: &RunSummary) -> String {
    match key {
        "safe" | "collided" => match (&s.first_collision, &s.first_violation) {
            (Some(c), _) => format!("collided with {} at t = {:.3} s", c.obstacle, c.t),
            (None, Some(v)) => format!("left {} at t = {:.3} s (h = {:.4})", v.set, v.t, v.value),
            (None, None) => match s.min_clearance {
                Some(c) => format!("stayed safe (min clearance {c:.4} m)"),
                None => "stayed safe".to_string(),
            },
        },
        "reaches_goal" => match s.time_to_goal {
            Some(t) => format!("reached the goal at t = {t:.3} s"),
            None => format!(
                "did not reach the goal (final position ({:.3}, {:.3}) m)",
                s.final_state[0], s.final_state[1]
            ),
        },
        other => format!("{other} differs"),
    }
}

fn count_failure(
    key: &str,
    want: Count,
    runs: &[RunSummary],
    of: fn(&RunSummary) -> bool,
) -> Option<String> {
    let n = runs.len();
    let shown = runs.iter().filter(|s| of(s)).count();
    if want.holds(shown, n) {
        return None;
    }
    // The seeds that went against the expectation, with what happened (at most three).
    let against: Vec<String> = runs
        .iter()
        .filter(|s| match want {
            Count::Every(b) => of(s) != b,
            Count::AtLeast { .. } => !of(s),
            Count::AtMost { .. } => of(s),
        })
        .take(3)
        .map(|s| format!("seed {} {}", s.seed, describe(key, s)))
        .collect();
    let head = match want {
        Count::Every(b) if n == 1 => format!("expected {key} = {b}"),
        Count::Every(b) => format!("expected {key} = {b} in all {n} seeds, got {key} in {shown}"),
        Count::AtLeast { at_least } => {
            format!("expected {key} in at least {at_least} of {n} seeds, got {shown}")
        }
        Count::AtMost { at_most } => {
            format!("expected {key} in at most {at_most} of {n} seeds, got {shown}")
        }
    };
    Some(format!("{head}: {}", against.join("; ")))
}

fn margin_failure(
    key: &str,
    unit: &str,
    m: &Margin,
    runs: &[RunSummary],
    of: fn(&RunSummary) -> Option<f64>,
) -> Vec<String> {
    let values: Vec<(u64, f64)> = runs
        .iter()
        .filter_map(|s| of(s).map(|v| (s.seed, v)))
        .collect();
    let n = runs.len();
    let Some(&first) = values.first() else {
        return vec![format!(
            "expected {key} to be measured, but none of the {n} seed(s) has a value"
        )];
    };
    let worst_of = if n == 1 {
        String::new()
    } else {
        format!(", the worst of {} seeds with a value", values.len())
    };
    let mut out = Vec::new();
    if let Some(lo) = m.at_least {
        let (seed, v) = values
            .iter()
            .copied()
            .fold(first, |a, b| if b.1 < a.1 { b } else { a });
        if v < lo - m.tolerance {
            out.push(format!(
                "expected {key} ≥ {lo}{unit} (tolerance {}), got {v:.4}{unit} in seed {seed}{worst_of}",
                m.tolerance
            ));
        }
    }
    if let Some(hi) = m.at_most {
        let (seed, v) = values
            .iter()
            .copied()
            .fold(first, |a, b| if b.1 > a.1 { b } else { a });
        if v > hi + m.tolerance {
            out.push(format!(
                "expected {key} ≤ {hi}{unit} (tolerance {}), got {v:.4}{unit} in seed {seed}{worst_of}",
                m.tolerance
            ));
        }
    }
    out
}

/// Every expectation the runs of the regression seeds fail, as a sentence with the numbers
/// behind it (empty = pass). `runs` holds one summary per seed.
pub fn failures(expected: &ExpectOutcome, runs: &[RunSummary]) -> Vec<String> {
    let mut out = Vec::new();
    for e in EVENTS {
        if let Some(&want) = expected.counts.get(e.key) {
            out.extend(count_failure(e.key, want, runs, e.of));
        }
    }
    for m in METRICS {
        if let Some(margin) = expected.margins.get(m.key) {
            out.extend(margin_failure(m.key, m.unit, margin, runs, m.of));
        }
    }
    out
}

/// The expectations one run can be judged by alone, when it is one of the regression seeds:
/// every margin (it bounds every seed) and the counts that hold per seed ([`Count::per_run`]).
/// The second list names the counts left to `ftcbf regress`.
pub fn failures_of_run(expected: &ExpectOutcome, run: &RunSummary) -> (Vec<String>, Vec<String>) {
    let mut per_run = expected.clone();
    let mut left = Vec::new();
    per_run.counts.retain(|key, c| {
        let keep = c.per_run();
        if !keep {
            left.push(format!("{key} {c}"));
        }
        keep
    });
    (failures(&per_run, std::slice::from_ref(run)), left)
}

/// World files named by `paths`: files as given, directories searched (not recursively) for
/// `*.toml`, sorted by path so the order is stable.
pub fn collect_world_files(paths: &[PathBuf]) -> std::io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|x| x == "toml"))
                .collect();
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::summary::{CollisionEvent, NamedValue, StepCounts};
    use std::collections::BTreeMap;

    fn summary(seed: u64, collided: bool, clearance: f64, t_goal: Option<f64>) -> RunSummary {
        RunSummary {
            world: "w".into(),
            seed,
            controller: "ft-cbf-clf".into(),
            duration: 20.0,
            safe: !collided,
            non_finite: None,
            disagreement: None,
            collided,
            first_collision: collided.then(|| CollisionEvent {
                t: 3.0,
                obstacle: "wall".into(),
            }),
            first_violation: None,
            min_barrier: vec![NamedValue {
                name: "wall".into(),
                value: clearance,
            }],
            min_clearance: Some(clearance),
            goal_reached: t_goal.is_some(),
            time_to_goal: t_goal,
            steps: StepCounts::default(),
            control_steps: 1000,
            rejected_readings: 0,
            attack_windows: Vec::new(),
            attacks_outside_fault_patterns: false,
            attacks_together_outside_fault_patterns: false,
            fail_closed: Default::default(),
            goal_settled: t_goal.is_some(),
            final_goal_distance: 0.0,
            final_clf_value: None,
            final_state: [0.0; 4],
            smoothness: Default::default(),
            estimation_errors: Vec::new(),
            safe_stop: None,
            collisions: Default::default(),
        }
    }

    fn outcome(
        counts: &[(&'static str, Count)],
        margins: &[(&'static str, Margin)],
    ) -> ExpectOutcome {
        ExpectOutcome {
            counts: counts.iter().copied().collect::<BTreeMap<_, _>>(),
            margins: margins.iter().copied().collect::<BTreeMap<_, _>>(),
        }
    }

    #[test]
    fn counts_over_seeds_name_the_seeds_against_them() {
        let runs = [
            summary(1, false, 0.2, Some(7.0)),
            summary(2, true, -0.001, None),
            summary(3, false, 0.15, Some(8.0)),
        ];
        let e = outcome(&[("safe", Count::AtLeast { at_least: 2 })], &[]);
        assert!(failures(&e, &runs).is_empty());
        let e = outcome(&[("safe", Count::Every(true))], &[]);
        let f = failures(&e, &runs);
        assert_eq!(f.len(), 1);
        assert!(f[0].contains("in all 3 seeds, got safe in 2"), "{f:?}");
        assert!(
            f[0].contains("seed 2 collided with wall at t = 3.000 s"),
            "{f:?}"
        );
        let e = outcome(&[("reaches_goal", Count::AtLeast { at_least: 3 })], &[]);
        let f = failures(&e, &runs);
        assert!(
            f[0].contains("at least 3 of 3 seeds, got 2: seed 2 did not reach"),
            "{f:?}"
        );
    }

    #[test]
    fn margins_judge_the_worst_seed_with_the_tolerance() {
        let runs = [
            summary(1, false, 0.20, Some(7.0)),
            summary(2, false, 0.12, None),
            summary(3, false, 0.15, Some(8.0)),
        ];
        let clr = |lo, tol| Margin {
            at_least: Some(lo),
            at_most: None,
            tolerance: tol,
        };
        // Worst clearance 0.12 m: ≥ 0.125 − 0.01 holds, ≥ 0.125 − 0.004 does not.
        assert!(failures(&outcome(&[], &[("min_clearance", clr(0.125, 0.01))]), &runs).is_empty());
        let f = failures(
            &outcome(&[], &[("min_clearance", clr(0.125, 0.004))]),
            &runs,
        );
        assert_eq!(f.len(), 1);
        assert!(
            f[0].contains("got 0.1200 m in seed 2, the worst of 3 seeds"),
            "{f:?}"
        );
        // Time to goal: only the seeds that reach it; the worst is 8 s.
        let t = |hi| Margin {
            at_least: None,
            at_most: Some(hi),
            tolerance: 0.5,
        };
        assert!(failures(&outcome(&[], &[("time_to_goal", t(7.5))]), &runs).is_empty());
        let f = failures(&outcome(&[], &[("time_to_goal", t(7.4))]), &runs);
        assert!(
            f[0].contains("got 8.0000 s in seed 3, the worst of 2 seeds"),
            "{f:?}"
        );
        // No seed with a value is a failure, not a pass.
        let f = failures(&outcome(&[], &[("time_to_goal", t(7.4))]), &runs[1..2]);
        assert!(f[0].contains("none of the 1 seed(s) has a value"), "{f:?}");
    }

    #[test]
    fn one_run_is_judged_by_what_holds_per_seed() {
        let e = outcome(
            &[
                ("safe", Count::Every(true)),
                ("reaches_goal", Count::AtLeast { at_least: 7 }),
            ],
            &[],
        );
        let (f, left) = failures_of_run(&e, &summary(5, true, -0.01, None));
        assert_eq!(f.len(), 1, "{f:?}");
        assert!(f[0].starts_with("expected safe = true:"), "{f:?}");
        assert_eq!(left, vec!["reaches_goal in at least 7".to_string()]);
    }
}

//! Monte Carlo safety certification: the engine of `ftcbf batch` and `ftcbf merge`.
//!
//! The thesis' problem statement (§3.1) asks for Pr(x_t ∈ C ∀t) ≥ 1 − ε under any fault pattern,
//! and Theorem 3 gives sufficient conditions. A batch *measures* that probability: it runs N
//! independent trials of a world (each with its own seed), records for every trial whether the
//! true state stayed safe, and sets the empirical rate with an exact 95 % Clopper–Pearson
//! interval against the world's claimed 1 − ε.
//!
//! Design:
//! - The core is independent of physics: it drives any [`TrialRunner`] (the CLI wires the
//!   closed-loop runner of `ftcbf-sim`; the tests use synthetic trials).
//! - Trial k uses the seed [`trial_seed`]`(S, k)` for *every* controller, so controllers are
//!   compared on the same noise and attack draws (a paired comparison with an exact McNemar
//!   test).
//! - Results do not depend on the number of threads: per-trial records are sorted by (trial,
//!   controller order) before anything is aggregated, and aggregation is a pure function of the
//!   sorted records ([`BatchResult::from_records`]). Merging shards rebuilds exactly the same
//!   value as the unsharded run.
//!
//! Modules: `plan` (what runs: plan, shards, sweeps), `run` (thread pool, progress, sweeps),
//! `result` (records, summaries, verdicts), [`stats`] (numerics), `io` (CSV/JSON), `merge`
//! (shard merging), `table` (human-readable tables), `spec` (a batch as a program describes it: [`BatchSpec`],
//! its report and outputs, the `--fail-on` levels).

pub mod figure;
mod io;
mod merge;
mod plan;
mod result;
mod run;
mod spec;
pub mod stats;
mod table;

use ftcbf_sim::summary::RunSummary;
/// A sweep point's (and a [`BatchSpec`]'s) overrides of world-file values: the world loader's
/// own type.
use ftcbf_sim::world::Override;

pub use io::{check_outputs, from_csv, to_csv, to_json, CsvTrial, FORMAT};
pub use merge::merge;
pub use plan::{ArgError, BatchPlan, Execution, Shard, Sweep};
pub use result::{
    BatchResult, ControllerSummary, LowerQuantiles, TrialRecord, UpperQuantiles, Verdict,
};
pub use run::{run_batch, run_parallel, run_sweep, worker_pool};
pub use spec::{
    failing_verdicts, report_text, write_outputs, BatchOutcome, BatchSpec, FailOn, PrepareFn,
    UnknownLevel, VerdictFailure,
};
pub use table::{render as render_table, Align};

/// Confidence level of every interval in a batch summary.
pub const CONFIDENCE: f64 = 0.95;

/// How many of the worst trials each controller summary lists.
pub const WORST_LISTED: usize = 5;

/// Runs one closed-loop trial. Must be a deterministic function of (controller, seed): the same
/// arguments give the same [`RunSummary`], bit for bit, on any thread.
pub trait TrialRunner: Sync {
    /// Run `controller` (`ft-cbf-clf`, `baseline` or `nominal`) with `seed`.
    fn run_trial(&self, controller: &str, seed: u64) -> anyhow::Result<RunSummary>;
}

/// What the batch needs to know about the loaded world (besides how to run it).
#[derive(Debug, Clone, PartialEq)]
pub struct WorldInfo {
    /// World name (as the world file gives it).
    pub name: String,
    /// The world's own seed: the default base seed of a batch.
    pub seed: u64,
    /// The ε of the world's claim Pr(x_t ∈ C ∀t) ≥ 1 − ε, if it states one. Must lie in (0, 1).
    pub epsilon: Option<f64>,
    /// `ftcbf check`'s verdict line on Theorem 3 for the world, if it was checked.
    pub theorem3: Option<String>,
    /// `ftcbf check`'s liveness verdict for the world, if it was checked.
    pub liveness: Option<String>,
}

/// A loaded world (with any overrides applied) ready to run trials.
pub struct PreparedWorld {
    /// Name, seed and claim.
    pub info: WorldInfo,
    /// Runs one trial of this world.
    pub runner: Box<dyn TrialRunner>,
}

/// The seed of trial `k` (0-based) of a batch with base seed `base`: the (k + 1)-th output of
/// a SplitMix64 generator whose state starts at `base`, i.e. the SplitMix64 finaliser applied to
/// `base + (k + 1) · 0x9E3779B97F4A7C15` (wrapping). Stable across versions and platforms, so
/// a seed printed by a batch re-runs that exact trial with `ftcbf run --seed`.
pub fn trial_seed(base: u64, k: u64) -> u64 {
    let mut z = base.wrapping_add(k.wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
pub(crate) mod testutil {
    //! A synthetic trial runner: every field is a deterministic function of (controller, seed).

    use super::*;
    use anyhow::anyhow;

    use ftcbf_sim::summary::{CollisionEvent, NamedValue, StepCounts, ViolationEvent};

    /// Uniform [0, 1) from a seed and a stream tag.
    pub fn unit(seed: u64, tag: u64) -> f64 {
        (trial_seed(seed, tag) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Synthetic runner: `ft-cbf-clf` is safe with probability `p_safe`, `baseline` with
    /// `p_safe / 2`; `fail_seed` makes that seed return an error.
    pub struct Synthetic {
        pub p_safe: f64,
        pub fail_seed: Option<u64>,
    }

    impl TrialRunner for Synthetic {
        fn run_trial(&self, controller: &str, seed: u64) -> anyhow::Result<RunSummary> {
            if Some(seed) == self.fail_seed {
                return Err(anyhow!("synthetic failure"));
            }
            let p = if controller == "baseline" {
                self.p_safe / 2.0
            } else {
                self.p_safe
            };
            let u = unit(seed, 1);
            let safe = u < p;
            let margin = (p - u) * 0.4 + 1e-3 * unit(seed, 9);
            let collided = !safe && unit(seed, 2) < 0.5;
            let goal = unit(seed, 3) < 0.8;
            Ok(RunSummary {
                world: "synthetic".into(),
                seed,
                controller: controller.into(),
                duration: 20.0,
                safe,
                non_finite: None,
                disagreement: None,
                collided,
                first_collision: collided.then(|| CollisionEvent {
                    t: 3.0 + unit(seed, 4),
                    obstacle: "pillar, \"east\"".into(),
                }),
                first_violation: (!safe).then(|| ViolationEvent {
                    t: 2.0 + unit(seed, 5),
                    set: "corridor".into(),
                    value: margin,
                }),
                min_barrier: vec![
                    NamedValue {
                        name: "corridor".into(),
                        value: margin,
                    },
                    NamedValue {
                        name: "pillar".into(),
                        value: margin + 0.1 * unit(seed, 6),
                    },
                ],
                min_clearance: Some(margin + 0.05),
                goal_reached: goal,
                time_to_goal: goal.then(|| 10.0 + 5.0 * unit(seed, 7)),
                goal_settled: goal && unit(seed, 10) < 0.5,
                final_goal_distance: 0.2 * unit(seed, 11),
                final_clf_value: Some(unit(seed, 12)),
                steps: StepCounts {
                    step1: 900 + (seed % 50),
                    clf_relaxed: seed % 7,
                    step2: seed % 5,
                    step3: seed % 3,
                    infeasible: u64::from(unit(seed, 8) < 0.1),
                    safe_stop: 0,
                },
                control_steps: 1000,
                rejected_readings: seed % 4,
                fail_closed: Default::default(),
                attack_windows: Vec::new(),
                attacks_outside_fault_patterns: false,
                attacks_together_outside_fault_patterns: false,
                final_state: [1.0, 2.0, 0.0, 0.0],
                smoothness: ftcbf_sim::summary::Smoothness {
                    omega_sign_changes: seed % 40,
                    omega_sign_change_fraction: 0.05 * unit(seed, 13),
                    mean_abs_domega: 0.1 * unit(seed, 14),
                    mean_abs_dv: 0.01 * unit(seed, 15),
                    path_length: 3.0,
                    stalls: seed % 2,
                },
                safe_stop: None,
                collisions: Default::default(),
                estimation_errors: vec![ftcbf_sim::summary::EstimationError {
                    filter: "drop_r1".into(),
                    gamma: Some(0.1),
                    honest: true,
                    max_error: 0.1 * (0.5 + unit(seed, 16)),
                    max_position_error: 0.05,
                    max_velocity_error: 0.05,
                    max_ratio: Some(0.5 + unit(seed, 16)),
                    t_worst: 1.0,
                    steps_over: u64::from(unit(seed, 16) > 0.5),
                }],
            })
        }
    }

    pub fn plan(trials: u64, shard: Option<Shard>) -> BatchPlan {
        BatchPlan {
            world: "synthetic".into(),
            world_file: "worlds/synthetic.toml".into(),
            world_digest: "fnv1a64:0123456789abcdef".into(),
            overrides: Vec::new(),
            trials,
            base_seed: 42,
            controllers: vec!["ft-cbf-clf".into(), "baseline".into()],
            shard,
            epsilon: Some(0.1),
            confidence: CONFIDENCE,
            theorem3: None,
            liveness: None,
        }
    }

    pub const SERIAL: Execution<'static> = Execution {
        jobs: Some(1),
        progress: &crate::progress::Silent,
    };
}

#[cfg(test)]
mod tests {

    use super::*;

    #[test]
    fn trial_seed_is_splitmix64() {
        // Reference outputs of SplitMix64 started from state 0.
        assert_eq!(trial_seed(0, 0), 0xE220_A839_7B1D_CDAF);
        assert_eq!(trial_seed(0, 1), 0x6E78_9E6A_A1B9_65F4);
        assert_eq!(trial_seed(0, 2), 0x06C4_5D18_8009_454F);
        // Distinct seeds for neighbouring bases and trials.
        let mut seen: Vec<u64> = (0..4)
            .flat_map(|b| (0..250).map(move |k| trial_seed(b, k)))
            .collect();
        seen.sort_unstable();
        seen.dedup();
        assert_eq!(seen.len(), 1000);
    }
}

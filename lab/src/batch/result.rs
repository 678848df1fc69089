//! Per-trial records and their aggregation into per-controller summaries.

use std::fmt;

use anyhow::anyhow;
use ftcbf_sim::summary::{RunSummary, StepCounts};
use serde::{Deserialize, Serialize};

use super::stats::{self, Interval};
use super::{io, trial_seed, BatchPlan, WORST_LISTED};

/// One trial of one controller, reduced to what the summary and the CSV need.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialRecord {
    /// Trial index k (0-based).
    pub trial: u64,
    /// Seed of the trial, [`trial_seed`]`(S, k)`.
    pub seed: u64,
    /// Controller kind.
    pub controller: String,
    /// The true state stayed in every safe set and the robot touched nothing.
    pub safe: bool,
    /// The robot touched an obstacle.
    pub collided: bool,
    /// Time of the first contact \[s\].
    #[serde(with = "io::float_or_text::option")]
    pub first_collision_t: Option<f64>,
    /// Obstacle of the first contact.
    pub first_collision_obstacle: Option<String>,
    /// Time of the first safe-set violation \[s\].
    #[serde(with = "io::float_or_text::option")]
    pub first_violation_t: Option<f64>,
    /// Safe set of the first violation.
    pub first_violation_set: Option<String>,
    /// h(x_true) at the first violation.
    #[serde(with = "io::float_or_text::option")]
    pub first_violation_value: Option<f64>,
    /// Smallest h(x_true) over all safe sets and obstacle barriers (`None` without any).
    #[serde(with = "io::float_or_text::option")]
    pub min_barrier: Option<f64>,
    /// The set or obstacle attaining `min_barrier`.
    pub min_barrier_name: Option<String>,
    /// Smallest true robot–obstacle clearance \[m\].
    #[serde(with = "io::float_or_text::option")]
    pub min_clearance: Option<f64>,
    /// The goal set was entered.
    pub goal_reached: bool,
    /// Inside the goal set over the last stretch of the run (see `RunSummary::goal_settled`).
    #[serde(default)]
    pub goal_settled: bool,
    /// Distance to the goal at the end \[m\].
    #[serde(default, with = "io::float_or_text")]
    pub final_goal_distance: f64,
    /// First time in the goal set \[s\].
    #[serde(with = "io::float_or_text::option")]
    pub time_to_goal: Option<f64>,
    /// Which policy step decided, per control step.
    pub steps: StepCounts,
    /// Number of control steps.
    pub control_steps: u64,
    /// Readings rejected as non-finite or absurd.
    pub rejected_readings: u64,
    /// Simulated time \[s\].
    #[serde(with = "io::float_or_text")]
    pub duration: f64,
    /// At least one attack lay outside the declared fault patterns (no guarantee applies).
    pub outside_fault_patterns: bool,
    /// Fraction of control steps whose commanded ω changed strict sign.
    #[serde(default, with = "io::float_or_text")]
    pub omega_sign_change_fraction: f64,
    /// Mean |Δω| per control step [rad/s].
    #[serde(default, with = "io::float_or_text")]
    pub mean_abs_domega: f64,
    /// Stalls the safety filter's tracker detected.
    #[serde(default)]
    pub stalls: u64,
    /// Per filter of the bank: whether it was honest (read no attacked channel), its largest
    /// ‖x − x̂‖/γ and whether it left γ (empty for a law without a bank).
    #[serde(default)]
    pub estimation: Vec<FilterGammaRecord>,
    /// Start of the first safe stop \[s\] (`[control] fallback = "brake"`; absent: none).
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "io::float_or_text::option"
    )]
    pub first_stop_t: Option<f64>,
    /// Why the robot first stopped (absent: it never did).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop_reason: Option<String>,
    /// Contacts that began, by who moved (issue #51): static obstacles, movers while the robot
    /// moved, movers while it stood, walkers while it stood.
    #[serde(default)]
    pub collisions: ftcbf_sim::summary::CollisionCounts,
}

/// One filter's estimation error against its γ in one trial (see
/// `ftcbf_sim::summary::EstimationError`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FilterGammaRecord {
    /// Filter label.
    pub filter: String,
    /// The filter read no attacked channel.
    pub honest: bool,
    /// Largest ‖x − x̂‖/γ (`None` without γ; "inf" for a non-finite estimate).
    #[serde(with = "io::float_or_text::option")]
    pub max_ratio: Option<f64>,
    /// The error left γ at some step.
    pub exceeded: bool,
}

impl FilterGammaRecord {
    fn of(e: &ftcbf_sim::summary::EstimationError) -> Self {
        Self {
            filter: e.filter.clone(),
            honest: e.honest,
            max_ratio: e.max_ratio,
            exceeded: e.exceeded(),
        }
    }
}

/// Over a batch, one filter's share of honest trials whose error left γ (thesis Theorem 1:
/// at most ε), with its Clopper–Pearson interval.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FilterGammaSummary {
    /// Filter label.
    pub filter: String,
    /// Trials in which the filter read no attacked channel.
    pub honest_trials: u64,
    /// Of those, trials whose error left γ.
    pub exceeded: u64,
    /// exceeded / honest_trials (0 without honest trials).
    pub exceeded_rate: f64,
    /// Clopper–Pearson interval of that share (`None` without honest trials).
    pub exceeded_ci: Option<Interval>,
    /// Largest ‖x − x̂‖/γ over the honest trials.
    #[serde(with = "io::float_or_text::option")]
    pub worst_ratio: Option<f64>,
    /// The lower bound of the interval lies above ε: the bound γ is refuted on this robot.
    pub refuted: bool,
}

/// Per filter (in bank order), the share of honest trials over γ.
fn gamma_summaries(
    recs: &[&TrialRecord],
    confidence: f64,
    epsilon: Option<f64>,
) -> Vec<FilterGammaSummary> {
    let Some(first) = recs.iter().find(|r| !r.estimation.is_empty()) else {
        return Vec::new();
    };
    first
        .estimation
        .iter()
        .enumerate()
        .map(|(i, f0)| {
            let rows: Vec<&FilterGammaRecord> = recs
                .iter()
                .filter_map(|r| r.estimation.get(i))
                .filter(|f| f.honest && f.filter == f0.filter)
                .collect();
            let n = rows.len() as u64;
            let k = rows.iter().filter(|f| f.exceeded).count() as u64;
            let ci = stats::clopper_pearson(k, n, confidence);
            let worst_ratio = rows.iter().filter_map(|f| f.max_ratio).reduce(|a, b| {
                if b.is_nan() || b > a {
                    b
                } else {
                    a
                }
            });
            FilterGammaSummary {
                filter: f0.filter.clone(),
                honest_trials: n,
                exceeded: k,
                exceeded_rate: rate(k, n),
                exceeded_ci: ci,
                worst_ratio,
                refuted: matches!((ci, epsilon), (Some(ci), Some(e)) if ci.lower > e),
            }
        })
        .collect()
}

impl TrialRecord {
    /// Reduce a run summary of trial `trial`. The minimum barrier value is the smallest of
    /// `min_barrier` by IEEE total order (the first one on ties).
    pub fn from_summary(trial: u64, s: &RunSummary) -> Self {
        let worst = s.min_barrier.iter().fold(
            None::<&ftcbf_sim::summary::NamedValue>,
            |best, nv| match best {
                Some(b) if b.value.total_cmp(&nv.value).is_le() => Some(b),
                _ => Some(nv),
            },
        );
        TrialRecord {
            trial,
            seed: s.seed,
            controller: s.controller.clone(),
            safe: s.safe,
            collided: s.collided,
            first_collision_t: s.first_collision.as_ref().map(|c| c.t),
            first_collision_obstacle: s.first_collision.as_ref().map(|c| c.obstacle.clone()),
            first_violation_t: s.first_violation.as_ref().map(|v| v.t),
            first_violation_set: s.first_violation.as_ref().map(|v| v.set.clone()),
            first_violation_value: s.first_violation.as_ref().map(|v| v.value),
            min_barrier: worst.map(|w| w.value),
            min_barrier_name: worst.map(|w| w.name.clone()),
            min_clearance: s.min_clearance,
            goal_reached: s.goal_reached,
            goal_settled: s.goal_settled,
            final_goal_distance: s.final_goal_distance,
            time_to_goal: s.time_to_goal,
            steps: s.steps,
            control_steps: s.control_steps,
            rejected_readings: s.rejected_readings,
            duration: s.duration,
            outside_fault_patterns: s.attacks_outside_fault_patterns,
            omega_sign_change_fraction: s.smoothness.omega_sign_change_fraction,
            mean_abs_domega: s.smoothness.mean_abs_domega,
            stalls: s.smoothness.stalls,
            estimation: s
                .estimation_errors
                .iter()
                .map(FilterGammaRecord::of)
                .collect(),
            first_stop_t: s.safe_stop.as_ref().map(|r| r.first_t),
            stop_reason: s.safe_stop.as_ref().map(|r| r.reason.clone()),
            collisions: s.collisions,
        }
    }
}

/// Verdict of the batch on the claim Pr(safe) ≥ 1 − ε, from the two-sided Clopper–Pearson
/// interval at the plan's confidence (95 %). Each side is a one-sided test at level α/2 = 2.5 %:
/// `Supported` means H0 "Pr(safe) < 1 − ε" is rejected, `Refuted` means "Pr(safe) ≥ 1 − ε" is.
/// With several controllers or sweep points, each verdict is a separate test (no multiplicity
/// correction).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// The interval's lower bound is ≥ 1 − ε.
    Supported,
    /// The interval's upper bound is < 1 − ε.
    Refuted,
    /// The interval contains 1 − ε: more trials are needed.
    Unresolved,
    /// The world states no ε.
    NoClaim,
}

impl Verdict {
    /// Decide from the interval and the claimed probability 1 − ε.
    pub fn decide(ci: Interval, claimed: Option<f64>) -> Verdict {
        match claimed {
            None => Verdict::NoClaim,
            Some(c) if ci.lower >= c => Verdict::Supported,
            Some(c) if ci.upper < c => Verdict::Refuted,
            Some(_) => Verdict::Unresolved,
        }
    }
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Verdict::Supported => "supported",
            Verdict::Refuted => "refuted",
            Verdict::Unresolved => "unresolved at this N",
            Verdict::NoClaim => "no claim",
        })
    }
}

/// Upper quantiles of a sample (time to goal): type-7 quantiles, see
/// [`stats::quantile_sorted`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UpperQuantiles {
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// Maximum.
    pub max: f64,
    /// Number of values.
    pub n: u64,
}

/// Lower quantiles of a sample (clearance, barrier value): type-7 quantiles.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LowerQuantiles {
    /// Minimum.
    pub min: f64,
    /// 10th percentile.
    pub p10: f64,
    /// Median.
    pub p50: f64,
    /// Number of values.
    pub n: u64,
}

/// Sort a sample (IEEE total order) and take three quantiles; `None` when empty.
fn three_quantiles(mut values: Vec<f64>, ps: [f64; 3]) -> Option<([f64; 3], u64)> {
    values.sort_by(f64::total_cmp);
    Some((
        [
            stats::quantile_sorted(&values, ps[0])?,
            stats::quantile_sorted(&values, ps[1])?,
            stats::quantile_sorted(&values, ps[2])?,
        ],
        values.len() as u64,
    ))
}

impl UpperQuantiles {
    fn of(values: Vec<f64>) -> Option<Self> {
        three_quantiles(values, [0.5, 0.9, 1.0]).map(|([p50, p90, max], n)| UpperQuantiles {
            p50,
            p90,
            max,
            n,
        })
    }
}

impl LowerQuantiles {
    fn of(values: Vec<f64>) -> Option<Self> {
        three_quantiles(values, [0.0, 0.1, 0.5]).map(|([min, p10, p50], n)| LowerQuantiles {
            min,
            p10,
            p50,
            n,
        })
    }
}

/// A trial listed among a controller's worst.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorstTrial {
    /// Trial index.
    pub trial: u64,
    /// Its seed (re-run it with `ftcbf run --seed`).
    pub seed: u64,
    /// Was it safe?
    pub safe: bool,
    /// Smallest barrier value and where.
    pub min_barrier: Option<f64>,
    /// Set or obstacle of the smallest barrier value.
    pub min_barrier_name: Option<String>,
    /// Smallest clearance \[m\].
    pub min_clearance: Option<f64>,
}

/// Per-controller summary of a batch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControllerSummary {
    /// Controller kind.
    pub controller: String,
    /// Trials run n.
    pub trials: u64,
    /// Safe trials k.
    pub safe: u64,
    /// k / n.
    pub safe_rate: f64,
    /// Clopper–Pearson interval of Pr(safe) at the plan's confidence.
    pub safe_ci: Interval,
    /// The claimed 1 − ε, if any.
    pub claimed_safety: Option<f64>,
    /// The interval against the claim.
    pub verdict: Verdict,
    /// Trials whose attacks lay outside the declared fault patterns (the claim does not cover
    /// them; a verdict over such trials tests more than the theorem promises).
    pub outside_fault_pattern_trials: u64,
    /// Trials with a collision.
    pub collisions: u64,
    /// collisions / n.
    pub collision_rate: f64,
    /// Trials with a safe-set violation.
    pub violations: u64,
    /// Trials that entered the goal.
    pub goals: u64,
    /// goals / n.
    pub goal_rate: f64,
    /// Trials that settled in the goal (inside it over the run's last stretch).
    #[serde(default)]
    pub settled: u64,
    /// settled / n.
    #[serde(default)]
    pub settled_rate: f64,
    /// Trials with a contact with an obstacle that stands still (issue #51).
    #[serde(default)]
    pub static_collision_trials: u64,
    /// Trials with a contact with a moving obstacle the robot moved into (towards its centre).
    #[serde(default)]
    pub mover_hit_while_moving_trials: u64,
    /// Trials with a contact with a moving obstacle while the robot stood or moved only
    /// sideways or away from it (the mover ran into it; see `CollisionCounts`).
    #[serde(default)]
    pub mover_hit_while_stopped_trials: u64,
    /// Of `mover_hit_while_stopped_trials`, those where a walker did.
    #[serde(default)]
    pub walker_hit_while_stopped_trials: u64,
    /// Distance to the goal at the end: median over trials \[m\].
    #[serde(default)]
    pub final_goal_distance_p50: f64,
    /// Time to goal over the trials that reached it: p50, p90, max \[s\].
    pub time_to_goal: Option<UpperQuantiles>,
    /// Minimum clearance over trials with obstacles: min, p10, p50 \[m\].
    pub min_clearance: Option<LowerQuantiles>,
    /// Minimum barrier value over trials: min, p10, p50.
    pub min_barrier: Option<LowerQuantiles>,
    /// Sums over trials of which policy step decided.
    pub steps: StepCounts,
    /// Sum of control steps.
    pub control_steps: u64,
    /// Trials in which at least one control step stayed infeasible after Step 3.
    pub infeasible_trials: u64,
    /// Sum of rejected readings.
    pub rejected_readings: u64,
    /// Trials with at least one rejected reading.
    pub rejected_trials: u64,
    /// The worst trials: unsafe first, then by smallest barrier value, smallest clearance,
    /// trial index. At most [`WORST_LISTED`].
    pub worst: Vec<WorstTrial>,
    /// Smoothness of the commanded (v, ω) over the trials (issue #11).
    #[serde(default)]
    pub smoothness: SmoothnessSummary,
    /// Per filter, the share of honest trials whose estimation error left γ (issue #35).
    #[serde(default)]
    pub estimation: Vec<FilterGammaSummary>,
}

/// Control smoothness over a batch: per-trial figures, averaged and at their worst.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SmoothnessSummary {
    /// Mean over trials of the fraction of control steps where ω changed sign.
    pub omega_sign_change_fraction_mean: f64,
    /// The largest such fraction of a trial.
    pub omega_sign_change_fraction_max: f64,
    /// Mean over trials of the mean |Δω| per step [rad/s].
    pub mean_abs_domega_mean: f64,
    /// The largest per-trial mean |Δω| [rad/s].
    pub mean_abs_domega_max: f64,
    /// Trials in which the tracker detected at least one stall.
    pub stalled_trials: u64,
}

impl SmoothnessSummary {
    fn of(recs: &[&TrialRecord]) -> Self {
        let n = recs.len().max(1) as f64;
        let mean = |f: &dyn Fn(&TrialRecord) -> f64| recs.iter().map(|r| f(r)).sum::<f64>() / n;
        let max = |f: &dyn Fn(&TrialRecord) -> f64| recs.iter().map(|r| f(r)).fold(0.0, f64::max);
        Self {
            omega_sign_change_fraction_mean: mean(&|r| r.omega_sign_change_fraction),
            omega_sign_change_fraction_max: max(&|r| r.omega_sign_change_fraction),
            mean_abs_domega_mean: mean(&|r| r.mean_abs_domega),
            mean_abs_domega_max: max(&|r| r.mean_abs_domega),
            stalled_trials: recs.iter().filter(|r| r.stalls > 0).count() as u64,
        }
    }
}

/// Paired comparison of two controllers on the same seeds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairedComparison {
    /// First controller (the plan's first).
    pub first: String,
    /// Second controller.
    pub second: String,
    /// Trials where both were safe.
    pub both_safe: u64,
    /// Only the first was safe.
    pub only_first_safe: u64,
    /// Only the second was safe.
    pub only_second_safe: u64,
    /// Neither was safe.
    pub neither_safe: u64,
    /// Exact two-sided McNemar p-value of "equally safe".
    pub p_value: f64,
}

/// The result of a batch (or of a merge of shards): plan, summaries, and every trial record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchResult {
    /// What was run.
    pub plan: BatchPlan,
    /// Distinct trial indices present.
    pub trials_covered: u64,
    /// Warnings (e.g. an incomplete merge).
    pub warnings: Vec<String>,
    /// One summary per controller, in plan order.
    pub summaries: Vec<ControllerSummary>,
    /// The first controller against each other one.
    pub paired: Vec<PairedComparison>,
    /// Records sorted by (trial, controller in plan order).
    pub records: Vec<TrialRecord>,
}

impl BatchResult {
    /// Aggregate `records` for `plan`. Records are sorted first, so the result does not depend
    /// on their order. Checks that every record's controller is in the plan, its seed is
    /// [`trial_seed`]`(S, k)`, k < N, and that each covered trial has every controller once.
    pub fn from_records(
        plan: BatchPlan,
        mut records: Vec<TrialRecord>,
        warnings: Vec<String>,
    ) -> anyhow::Result<BatchResult> {
        plan.validate()?;
        check_records(&plan, &records)?;
        let order = |c: &str| plan.controllers.iter().position(|p| p == c);
        records.sort_by_key(|r| (r.trial, order(&r.controller)));
        let nc = plan.controllers.len();
        if !records.len().is_multiple_of(nc) {
            return Err(anyhow!(
                "{} records do not split into whole trials of {nc} controllers",
                records.len()
            ));
        }
        for chunk in records.chunks(nc) {
            for (i, r) in chunk.iter().enumerate() {
                if r.trial != chunk[0].trial || r.controller != plan.controllers[i] {
                    return Err(anyhow!(
                        "trial {}: expected one record per controller ({}), found a duplicate or a gap",
                        chunk[0].trial,
                        plan.controllers.join(", ")
                    ));
                }
            }
        }
        let trials_covered = (records.len() / nc) as u64;
        let summaries = plan
            .controllers
            .iter()
            .enumerate()
            .map(|(i, c)| summarize(&plan, c, records.iter().skip(i).step_by(nc)))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let paired = (1..nc).map(|j| paired(&plan, &records, j)).collect();
        Ok(BatchResult {
            plan,
            trials_covered,
            warnings,
            summaries,
            paired,
            records,
        })
    }
}

/// Every record's controller is in the plan, its trial index is below N, and its seed is the
/// batch seed of that trial.
fn check_records(plan: &BatchPlan, records: &[TrialRecord]) -> anyhow::Result<()> {
    let order = |c: &str| plan.controllers.iter().position(|p| p == c);
    for r in records {
        if order(&r.controller).is_none() {
            return Err(anyhow!(
                "trial {}: controller `{}` is not in the plan",
                r.trial,
                r.controller
            ));
        }
        if r.trial >= plan.trials {
            return Err(anyhow!(
                "trial index {} is out of range (the batch has {} trials)",
                r.trial,
                plan.trials
            ));
        }
        let want = trial_seed(plan.base_seed, r.trial);
        if r.seed != want {
            return Err(anyhow!(
                "trial {} ({}): seed {} is not the batch seed {} for base seed {}",
                r.trial,
                r.controller,
                r.seed,
                want,
                plan.base_seed
            ));
        }
    }
    Ok(())
}

/// The first controller of the plan against controller `j`, trial by trial (`records` sorted
/// by trial, then plan order, whole trials only).
fn paired(plan: &BatchPlan, records: &[TrialRecord], j: usize) -> PairedComparison {
    let nc = plan.controllers.len();
    let mut p = PairedComparison {
        first: plan.controllers[0].clone(),
        second: plan.controllers[j].clone(),
        both_safe: 0,
        only_first_safe: 0,
        only_second_safe: 0,
        neither_safe: 0,
        p_value: 1.0,
    };
    for chunk in records.chunks(nc) {
        match (chunk[0].safe, chunk[j].safe) {
            (true, true) => p.both_safe += 1,
            (true, false) => p.only_first_safe += 1,
            (false, true) => p.only_second_safe += 1,
            (false, false) => p.neither_safe += 1,
        }
    }
    p.p_value = stats::mcnemar_exact_p(p.only_first_safe, p.only_second_safe);
    p
}

fn rate(k: u64, n: u64) -> f64 {
    if n == 0 {
        0.0
    } else {
        k as f64 / n as f64
    }
}

fn summarize<'a>(
    plan: &BatchPlan,
    controller: &str,
    records: impl Iterator<Item = &'a TrialRecord>,
) -> anyhow::Result<ControllerSummary> {
    let recs: Vec<&TrialRecord> = records.collect();
    let n = recs.len() as u64;
    let count = |f: &dyn Fn(&TrialRecord) -> bool| recs.iter().filter(|r| f(r)).count() as u64;
    let safe = count(&|r| r.safe);
    let collisions = count(&|r| r.collided);
    let goals = count(&|r| r.goal_reached);
    let settled = count(&|r| r.goal_settled);
    let final_goal_distance_p50 = median(recs.iter().map(|r| r.final_goal_distance).collect());
    let safe_ci = stats::clopper_pearson(safe, n, plan.confidence)
        .ok_or_else(|| anyhow!("controller `{controller}`: no trials to summarise"))?;
    let claimed_safety = plan.claimed_safety();
    Ok(ControllerSummary {
        controller: controller.to_string(),
        trials: n,
        safe,
        safe_rate: rate(safe, n),
        safe_ci,
        claimed_safety,
        verdict: Verdict::decide(safe_ci, claimed_safety),
        outside_fault_pattern_trials: count(&|r| r.outside_fault_patterns),
        collisions,
        collision_rate: rate(collisions, n),
        violations: count(&|r| r.first_violation_t.is_some()),
        goals,
        goal_rate: rate(goals, n),
        settled,
        settled_rate: rate(settled, n),
        static_collision_trials: count(&|r| r.collisions.static_obstacles > 0),
        mover_hit_while_moving_trials: count(&|r| r.collisions.mover_robot_moving > 0),
        mover_hit_while_stopped_trials: count(&|r| r.collisions.mover_robot_stopped > 0),
        walker_hit_while_stopped_trials: count(&|r| r.collisions.walker_robot_stopped > 0),
        final_goal_distance_p50,
        time_to_goal: UpperQuantiles::of(
            recs.iter()
                .filter(|r| r.goal_reached)
                .filter_map(|r| r.time_to_goal)
                .collect(),
        ),
        min_clearance: LowerQuantiles::of(recs.iter().filter_map(|r| r.min_clearance).collect()),
        min_barrier: LowerQuantiles::of(recs.iter().filter_map(|r| r.min_barrier).collect()),
        steps: total_steps(&recs),
        control_steps: recs.iter().map(|r| r.control_steps).sum(),
        infeasible_trials: count(&|r| r.steps.infeasible > 0),
        rejected_readings: recs.iter().map(|r| r.rejected_readings).sum(),
        rejected_trials: count(&|r| r.rejected_readings > 0),
        worst: worst_trials(&recs),
        smoothness: SmoothnessSummary::of(&recs),
        estimation: gamma_summaries(&recs, plan.confidence, plan.epsilon),
    })
}

/// The median (the mean of the two middle values for an even count; 0 for none).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        0.0
    } else if v.len() % 2 == 1 {
        v[v.len() / 2]
    } else {
        0.5 * (v[v.len() / 2 - 1] + v[v.len() / 2])
    }
}

/// The policy's stage counts summed over the trials.
fn total_steps(recs: &[&TrialRecord]) -> StepCounts {
    let mut steps = StepCounts::default();
    for r in recs {
        steps.step1 += r.steps.step1;
        steps.clf_relaxed += r.steps.clf_relaxed;
        steps.step2 += r.steps.step2;
        steps.step3 += r.steps.step3;
        steps.infeasible += r.steps.infeasible;
        steps.safe_stop += r.steps.safe_stop;
    }
    steps
}

/// Smallest first, `None` last.
fn smallest_first(a: Option<f64>, b: Option<f64>) -> std::cmp::Ordering {
    match (a, b) {
        (Some(x), Some(y)) => x.total_cmp(&y),
        (Some(_), None) => std::cmp::Ordering::Less,
        (None, Some(_)) => std::cmp::Ordering::Greater,
        (None, None) => std::cmp::Ordering::Equal,
    }
}

/// The [`WORST_LISTED`] worst trials: unsafe first; then smallest barrier value (None last),
/// smallest clearance (None last), then trial.
fn worst_trials(recs: &[&TrialRecord]) -> Vec<WorstTrial> {
    let mut worst: Vec<&TrialRecord> = recs.to_vec();
    worst.sort_by(|a, b| {
        a.safe
            .cmp(&b.safe)
            .then(smallest_first(a.min_barrier, b.min_barrier))
            .then(smallest_first(a.min_clearance, b.min_clearance))
            .then(a.trial.cmp(&b.trial))
    });
    worst
        .into_iter()
        .take(WORST_LISTED)
        .map(|r| WorstTrial {
            trial: r.trial,
            seed: r.seed,
            safe: r.safe,
            min_barrier: r.min_barrier,
            min_barrier_name: r.min_barrier_name.clone(),
            min_clearance: r.min_clearance,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::*;
    use super::*;

    #[test]
    fn smoothness_is_averaged_and_maximised_over_trials() {
        let runner = Synthetic {
            p_safe: 0.9,
            fail_seed: None,
        };
        let recs: Vec<TrialRecord> = (0..4u64)
            .map(|k| {
                let s = runner
                    .run_trial("ft-cbf-clf", 100 + k)
                    .expect("synthetic run");
                TrialRecord::from_summary(k, &s)
            })
            .collect();
        let refs: Vec<&TrialRecord> = recs.iter().collect();
        let m = SmoothnessSummary::of(&refs);
        let f: Vec<f64> = recs.iter().map(|r| r.omega_sign_change_fraction).collect();
        let mean = f.iter().sum::<f64>() / 4.0;
        assert!((m.omega_sign_change_fraction_mean - mean).abs() < 1e-15);
        assert_eq!(
            m.omega_sign_change_fraction_max,
            f.iter().copied().fold(0.0, f64::max)
        );
        assert!(m.mean_abs_domega_max >= m.mean_abs_domega_mean && m.mean_abs_domega_mean > 0.0);
        // seeds 101 and 103 stall (seed % 2)
        assert_eq!(m.stalled_trials, 2);
    }

    #[test]
    fn verdicts_from_constructed_counts() {
        let claim = Some(0.9);
        // 100/100: lower = 0.025^(1/100) = 0.9638 ≥ 0.9.
        let ci = stats::clopper_pearson(100, 100, 0.95).unwrap_or(Interval {
            lower: 0.0,
            upper: 1.0,
        });
        assert_eq!(Verdict::decide(ci, claim), Verdict::Supported);
        // 80/100: upper = 0.8724 < 0.9.
        let ci = stats::clopper_pearson(80, 100, 0.95).unwrap_or(Interval {
            lower: 0.0,
            upper: 1.0,
        });
        assert!(ci.upper < 0.9 && ci.upper > 0.87);
        assert_eq!(Verdict::decide(ci, claim), Verdict::Refuted);
        // 9/10: [0.555, 0.997] contains 0.9.
        let ci = stats::clopper_pearson(9, 10, 0.95).unwrap_or(Interval {
            lower: 1.0,
            upper: 0.0,
        });
        assert_eq!(Verdict::decide(ci, claim), Verdict::Unresolved);
        assert_eq!(Verdict::decide(ci, None), Verdict::NoClaim);
        // Boundaries: lower exactly at the claim is supported; upper exactly at it is not refuted.
        assert_eq!(
            Verdict::decide(
                Interval {
                    lower: 0.9,
                    upper: 1.0
                },
                claim
            ),
            Verdict::Supported
        );
        assert_eq!(
            Verdict::decide(
                Interval {
                    lower: 0.5,
                    upper: 0.9
                },
                claim
            ),
            Verdict::Unresolved
        );
        assert_eq!(Verdict::Unresolved.to_string(), "unresolved at this N");
    }

    #[test]
    fn record_takes_the_smallest_named_barrier() {
        let r = Synthetic {
            p_safe: 0.5,
            fail_seed: None,
        };
        let s = r.run_trial("ft-cbf-clf", 7).expect("synthetic trial");
        let rec = TrialRecord::from_summary(3, &s);
        assert_eq!(rec.min_barrier_name.as_deref(), Some("corridor"));
        assert_eq!(rec.min_barrier, Some(s.min_barrier[0].value));
        assert_eq!(rec.trial, 3);
        assert_eq!(rec.seed, 7);
    }

    #[test]
    fn summary_counts_match_the_records() {
        let runner = Synthetic {
            p_safe: 0.9,
            fail_seed: None,
        };
        let res = run_batch(&runner, &plan(300, None), SERIAL).expect("batch");
        assert_eq!(res.trials_covered, 300);
        for (i, s) in res.summaries.iter().enumerate() {
            let recs: Vec<_> = res.records.iter().skip(i).step_by(2).collect();
            assert!(recs.iter().all(|r| r.controller == s.controller));
            let safe = recs.iter().filter(|r| r.safe).count() as u64;
            assert_eq!(s.safe, safe);
            assert_eq!(s.trials, 300);
            assert_eq!(s.safe_rate, safe as f64 / 300.0);
            assert!(s.safe_ci.lower <= s.safe_rate && s.safe_rate <= s.safe_ci.upper);
            assert_eq!(
                s.steps.step3,
                recs.iter().map(|r| r.steps.step3).sum::<u64>()
            );
            assert_eq!(
                s.infeasible_trials,
                recs.iter().filter(|r| r.steps.infeasible > 0).count() as u64
            );
            let min_clear = recs
                .iter()
                .filter_map(|r| r.min_clearance)
                .fold(f64::INFINITY, f64::min);
            assert_eq!(s.min_clearance.map(|c| c.min), Some(min_clear));
            let max_ttg = recs
                .iter()
                .filter_map(|r| r.time_to_goal)
                .fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(s.time_to_goal.map(|t| t.max), Some(max_ttg));
            // Worst trials: unsafe ones first, in ascending barrier order.
            let unsafe_n = (s.trials - s.safe) as usize;
            for (w, pair) in s.worst.iter().zip(s.worst.iter().skip(1)) {
                assert!(!w.safe || pair.safe);
                if w.safe == pair.safe {
                    assert!(w.min_barrier <= pair.min_barrier);
                }
            }
            if unsafe_n > 0 {
                assert!(!s.worst[0].safe);
            }
        }
        // ft-cbf-clf is safe ~90 %, baseline ~45 %: the paired test sees the difference.
        let p = &res.paired[0];
        assert_eq!(
            p.both_safe + p.only_first_safe + p.only_second_safe + p.neither_safe,
            300
        );
        assert_eq!(
            p.only_second_safe, 0,
            "synthetic baseline is safe only where ft-cbf-clf is"
        );
        assert!(p.p_value < 1e-6, "p = {}", p.p_value);
        for s in &res.summaries {
            let ci = stats::clopper_pearson(s.safe, s.trials, CONFIDENCE).unwrap_or(Interval {
                lower: 0.0,
                upper: 1.0,
            });
            assert_eq!(s.safe_ci, ci);
            assert_eq!(s.verdict, Verdict::decide(ci, Some(0.9)));
        }
        // Baseline is safe ~45 % of the time against a claim of 90 %.
        assert_eq!(res.summaries[1].verdict, Verdict::Refuted);
    }

    #[test]
    fn worst_seed_rerun_reproduces_its_record() {
        let runner = Synthetic {
            p_safe: 0.7,
            fail_seed: None,
        };
        let res = run_batch(
            &runner,
            &plan(60, None),
            Execution {
                jobs: Some(2),
                progress: &crate::progress::Silent,
            },
        )
        .expect("batch");
        for s in &res.summaries {
            assert_eq!(s.worst.len(), WORST_LISTED);
            for w in &s.worst {
                let again = runner.run_trial(&s.controller, w.seed).expect("re-run");
                let rec = TrialRecord::from_summary(w.trial, &again);
                let stored = res
                    .records
                    .iter()
                    .find(|r| r.trial == w.trial && r.controller == s.controller)
                    .expect("listed trial has a record");
                assert_eq!(&rec, stored);
                assert_eq!(w.seed, trial_seed(42, w.trial));
            }
        }
    }
}

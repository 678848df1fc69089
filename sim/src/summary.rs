//! The result of one run: what the runner measured against the truth. Serialisable, so the CLI
//! prints it as JSON and `ftcbf batch` aggregates it.

use serde::{Deserialize, Serialize};

/// A named minimum (e.g. the smallest h(x_true) of one safe set over a run).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NamedValue {
    /// Safe-set or obstacle name as the world file gives it.
    pub name: String,
    /// The value.
    pub value: f64,
}

/// The first contact between the robot and an obstacle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CollisionEvent {
    /// Simulation time [s].
    pub t: f64,
    /// Obstacle name.
    pub obstacle: String,
}

/// The first time the true state left a safe set (h(x_true) < 0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViolationEvent {
    /// Simulation time [s].
    pub t: f64,
    /// Safe-set name.
    pub set: String,
    /// h(x_true) at that time.
    pub value: f64,
}

/// How often each step of the policy (§4.1 / §5.1) decided the input over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StepCounts {
    /// Step 1: every active constraint could be met.
    pub step1: u64,
    /// Only the CLF rows had to be relaxed (safety first), no CBF row dropped.
    pub clf_relaxed: u64,
    /// Step 2: constraints of estimators deviating from their pairwise estimators were dropped.
    pub step2: u64,
    /// Step 3: constraints of the largest-residue estimators were dropped.
    pub step3: u64,
    /// Still infeasible after Step 3: the documented safe action was applied.
    pub infeasible: u64,
}

/// Fail-closed events over a run: each is a step where a safety constraint could have
/// vanished silently and the controller did something else, on the record (issue 16).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FailClosedCounts {
    /// Steps with at least one imposed constraint row that was not finite (treated as
    /// violated).
    pub non_finite_row_steps: u64,
    /// Accepted readings a filter could not use (innovation variance not finite and positive),
    /// summed over filters and steps; each flagged its filter.
    pub skipped_updates: u64,
    /// Steps where Step 2 kept the last estimator with barrier rows instead of dropping it.
    pub step2_retained_steps: u64,
    /// Steps where the fallback braked (solver failure or a non-finite row).
    pub brake_steps: u64,
}

impl FailClosedCounts {
    /// True when any counter is non-zero.
    pub fn any(&self) -> bool {
        *self != Self::default()
    }
}

/// The window of one attack, as the world file declared it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AttackWindow {
    /// e.g. `attacks[0] bias on gnss2_y`.
    pub label: String,
    /// [s]
    pub start: f64,
    /// [s]; `None` = until the end of the run.
    pub end: Option<f64>,
    /// True when the attacked channels are not all inside one declared fault pattern
    /// (outside the paper's threat model: no guarantee applies).
    pub outside_fault_patterns: bool,
}

/// Length of the final stretch of a run over which "settled in the goal" is judged [s].
pub const SETTLE_WINDOW: f64 = 2.0;

/// Everything one run measured. The same world + seed gives the same summary, bit for bit, on
/// one machine and toolchain (the platform's libm is on the path; see the README).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// World name.
    pub world: String,
    /// The seed the run used.
    pub seed: u64,
    /// `ft-cbf-clf`, `baseline` or `nominal`.
    pub controller: String,
    /// Simulated time [s].
    pub duration: f64,
    /// The true state stayed in every safe set and the robot never touched an obstacle.
    pub safe: bool,
    /// The robot touched an obstacle.
    pub collided: bool,
    /// First contact, if any.
    pub first_collision: Option<CollisionEvent>,
    /// First safe-set violation, if any.
    pub first_violation: Option<ViolationEvent>,
    /// Smallest h(x_true) per safe set and per obstacle barrier.
    pub min_barrier: Vec<NamedValue>,
    /// Smallest true clearance robot–obstacle over the run [m] (`None` without obstacles).
    pub min_clearance: Option<f64>,
    /// The goal set was entered ("entered the goal": at least one plant tick inside it).
    pub goal_reached: bool,
    /// First time in the goal set [s].
    pub time_to_goal: Option<f64>,
    /// "Settled in the goal": the true state was inside the goal set at every plant tick of the
    /// last [`SETTLE_WINDOW`] seconds of the run (the whole run if it is shorter).
    #[serde(default)]
    pub goal_settled: bool,
    /// Distance to the goal at the end, in the goal's metric (position, or full state) [m].
    #[serde(default)]
    pub final_goal_distance: f64,
    /// The CLF V(x_true) at the end (eq. 6.6; `None` when the CLF could not be built).
    #[serde(default)]
    pub final_clf_value: Option<f64>,
    /// Which step of the policy decided, per control step.
    pub steps: StepCounts,
    /// Number of control steps.
    pub control_steps: u64,
    /// Readings rejected by the controller as non-finite or absurd.
    pub rejected_readings: u64,
    /// Fail-closed events (non-finite rows, unusable readings, Step-2 retention, braking).
    #[serde(default)]
    pub fail_closed: FailClosedCounts,
    /// The attacks of the world.
    pub attack_windows: Vec<AttackWindow>,
    /// The run is outside the declared fault model: at least one attack lies outside the
    /// declared fault patterns, or the attacks together do
    /// (`attacks_together_outside_fault_patterns`). No guarantee applies to such a run.
    pub attacks_outside_fault_patterns: bool,
    /// The union of all attacked channels over the run lies in no single declared fault
    /// pattern, although each attack alone may (e.g. `bias` on gnss2_y and `absurd` on
    /// gnss2_x with patterns {gnss2_x} and {gnss2_y}): outside the single-fault model.
    #[serde(default)]
    pub attacks_together_outside_fault_patterns: bool,
    /// True planar state (p_x, p_y, v_x, v_y) at the end [m, m, m/s, m/s].
    pub final_state: [f64; 4],
}

/// A yes/no outcome of a run that `[expect]` can count over seeds (`safe = true`,
/// `collided = { at_most = 1 }`, …).
#[derive(Debug, Clone, Copy)]
pub struct Event {
    /// The `[expect]` key.
    pub key: &'static str,
    /// Whether the run shows it.
    pub of: fn(&RunSummary) -> bool,
}

/// A number a run measured that `[expect]` can bound with a margin
/// (`min_clearance = { at_least = 0.12, tolerance = 0.01 }`).
#[derive(Debug, Clone, Copy)]
pub struct Metric {
    /// The `[expect]` key.
    pub key: &'static str,
    /// Unit, for messages (`"m"`, `"s"`, `""`).
    pub unit: &'static str,
    /// The value of one run; `None` when the run does not measure it (no obstacles, goal never
    /// reached). Seeds without a value are left out of the margin check.
    pub of: fn(&RunSummary) -> Option<f64>,
}

/// The events `[expect]` accepts. A new yes/no field of [`RunSummary`] becomes an `[expect]`
/// key by one more entry here.
pub const EVENTS: &[Event] = &[
    Event {
        key: "safe",
        of: |s| s.safe,
    },
    Event {
        key: "collided",
        of: |s| s.collided,
    },
    Event {
        key: "reaches_goal",
        of: |s| s.goal_reached,
    },
];

/// The metrics `[expect]` accepts. A new numeric field of [`RunSummary`] becomes an `[expect]`
/// key by one more entry here.
pub const METRICS: &[Metric] = &[
    Metric {
        key: "min_h",
        unit: "",
        of: |s| s.min_barrier.iter().map(|b| b.value).reduce(f64::min),
    },
    Metric {
        key: "min_clearance",
        unit: " m",
        of: |s| s.min_clearance,
    },
    Metric {
        key: "time_to_goal",
        unit: " s",
        of: |s| s.time_to_goal,
    },
    Metric {
        key: "fallback_fraction",
        unit: "",
        of: |s| (s.control_steps > 0).then(|| s.steps.infeasible as f64 / s.control_steps as f64),
    },
];

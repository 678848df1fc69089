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
    /// Simulation time \[s\].
    pub t: f64,
    /// Obstacle name.
    pub obstacle: String,
}

/// The first time the true state left a safe set (h(x_true) < 0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViolationEvent {
    /// Simulation time \[s\].
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
    /// The safe stop (`[control] fallback = "brake"`): Step 3 had no evidence which estimator
    /// lies, so the robot braked instead of dropping one. Left out of the JSON when 0, so a run
    /// that never stops serialises as before.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub safe_stop: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// The safe stops of a run (`[control] fallback = "brake"`): when the robot first stopped and
/// why, in words a user can act on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SafeStopReport {
    /// Start of the first stop \[s\].
    pub first_t: f64,
    /// Why it stopped then (which sources it could not tell apart, and what would help).
    pub reason: String,
    /// Stops (maximal runs of consecutive braking steps).
    pub episodes: u64,
    /// Control steps spent in a stop.
    pub steps: u64,
    /// Start of the last stop \[s\].
    pub last_start: f64,
    /// The run ended in a stop.
    pub stopped_at_end: bool,
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
    /// Steps where Step 3 stopped instead of dropping an estimator whose own barrier rows the
    /// input box cannot meet (the fallback then weighed every estimator still kept).
    #[serde(default)]
    pub step3_saturated_steps: u64,
    /// Heading readings the robot's heading source refused: a noisy compass repeating its last
    /// reading bit for bit (stuck), or, with gyro fusion, a reading outside the innovation gate.
    /// The drive dead-reckons over them.
    #[serde(default)]
    pub refused_headings: u64,
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
    /// \[s\]
    pub start: f64,
    /// \[s\]; `None` = until the end of the run.
    pub end: Option<f64>,
    /// True when the attacked channels are not all inside one declared fault pattern
    /// (outside the paper's threat model: no guarantee applies).
    pub outside_fault_patterns: bool,
}

/// How smooth the body command (v, ω) sent to the wheels was, and how the robot moved.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Smoothness {
    /// Control steps whose commanded ω has the opposite strict sign of the previous step's.
    pub omega_sign_changes: u64,
    /// `omega_sign_changes` over the control steps after the first.
    pub omega_sign_change_fraction: f64,
    /// Mean |ω_k − ω_(k−1)| per control step [rad/s].
    pub mean_abs_domega: f64,
    /// Mean |v_k − v_(k−1)| per control step [m/s].
    pub mean_abs_dv: f64,
    /// Length of the true path, sampled at the control rate \[m\].
    pub path_length: f64,
    /// Stalls the safety filter's nominal tracker detected (each began an escape).
    pub stalls: u64,
}

/// Accumulates [`Smoothness`] step by step.
#[derive(Debug, Clone, Default)]
pub struct SmoothnessMeter {
    last_cmd: Option<[f64; 2]>,
    last_pos: Option<[f64; 2]>,
    sign_changes: u64,
    sum_domega: f64,
    sum_dv: f64,
    pairs: u64,
    path: f64,
    stalls: u64,
}

impl SmoothnessMeter {
    /// The tracker's stall count so far (the controller keeps it).
    pub fn set_stalls(&mut self, stalls: u64) {
        self.stalls = stalls;
    }

    /// One control step: the body command (v, ω) sent [m/s, rad/s] and the true position \[m\].
    pub fn observe(&mut self, cmd: [f64; 2], pos: [f64; 2]) {
        if let Some(last) = self.last_cmd {
            self.pairs += 1;
            self.sum_dv += (cmd[0] - last[0]).abs();
            self.sum_domega += (cmd[1] - last[1]).abs();
            if cmd[1] * last[1] < 0.0 {
                self.sign_changes += 1;
            }
        }
        if let Some(p) = self.last_pos {
            self.path += (pos[0] - p[0]).hypot(pos[1] - p[1]);
        }
        self.last_cmd = Some(cmd);
        self.last_pos = Some(pos);
    }

    /// The figures so far.
    pub fn smoothness(&self) -> Smoothness {
        let n = self.pairs.max(1) as f64;
        Smoothness {
            omega_sign_changes: self.sign_changes,
            omega_sign_change_fraction: self.sign_changes as f64 / n,
            mean_abs_domega: self.sum_domega / n,
            mean_abs_dv: self.sum_dv / n,
            path_length: self.path,
            stalls: self.stalls,
        }
    }
}

/// One filter's estimation error against the truth over a run, next to the bound γ its
/// Step-1 rows assume (thesis Theorem 1, §4.3: Pr(sup_t ‖x_t − x̂_t‖ ≤ γ) ≥ 1 − ε). The error is
/// the 4-D ‖(p_x, p_y, v_x, v_y) − x̂‖ at every control step, after the step's measurement
/// update, against the truth at the sampling instant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EstimationError {
    /// The filter's label (`drop_<pattern>`, `drop_<a>+<b>`, `all`).
    pub filter: String,
    /// γ of this filter: γ_i for a single, γ_ij for a pair, the baseline's γ for `all`
    /// (`None` when no bound was computed for it, e.g. pairs under a hand-set γ).
    pub gamma: Option<f64>,
    /// No attack of the run touched a channel this filter reads: the bound must hold for it.
    pub honest: bool,
    /// Largest ‖x − x̂‖ over the run.
    pub max_error: f64,
    /// Largest position part ‖(p_x, p_y) − (p̂_x, p̂_y)‖ \[m\].
    pub max_position_error: f64,
    /// Largest velocity part ‖(v_x, v_y) − (v̂_x, v̂_y)‖ [m/s].
    pub max_velocity_error: f64,
    /// Largest ‖x − x̂‖/γ (`None` without γ); above 1 the bound was left.
    pub max_ratio: Option<f64>,
    /// When the largest ratio (or error, without γ) occurred \[s\].
    pub t_worst: f64,
    /// Control steps with ‖x − x̂‖ > γ.
    pub steps_over: u64,
}

impl EstimationError {
    /// The error left γ at some step (false without γ). A non-finite error counts as leaving
    /// it: the bound cannot be said to hold on a number that is not one.
    pub fn exceeded(&self) -> bool {
        self.gamma.is_some() && (self.steps_over > 0 || !self.max_error.is_finite())
    }
}

/// How far the barrier's distance and the physics' clearance may disagree in sign before a run
/// has no verdict \[m\]: above the contact solver's allowed penetration (rapier's default,
/// 1 mm) and parry's f32 distance error (~1e-6 m), below any clearance a margin asks for.
pub const DISAGREEMENT_TOLERANCE: f64 = 0.005;

/// An obstacle where the run's barrier and physics contradicted each other.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Disagreement {
    /// Simulation time \[s\].
    pub t: f64,
    /// Obstacle name.
    pub obstacle: String,
    /// Signed distance from the robot's centre to the obstacle, as its barrier computes it (no
    /// margin, no velocity lift; negative inside) \[m\].
    pub centre_distance: f64,
    /// The robot disc's clearance, as its barrier computes it: `centre_distance` − the footprint
    /// radius \[m\].
    pub barrier_clearance: f64,
    /// The physics' clearance between the robot's colliders and the obstacle (negative:
    /// penetration) \[m\].
    pub physics_clearance: f64,
}

impl std::fmt::Display for Disagreement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let where_ = if self.centre_distance < 0.0 {
            format!(
                "puts the robot's centre {:.4} m inside obstacle `{}`",
                -self.centre_distance, self.obstacle
            )
        } else {
            format!(
                "puts the robot's disc {:.4} m clear of obstacle `{}`",
                self.barrier_clearance, self.obstacle
            )
        };
        let physics = if self.physics_clearance < 0.0 {
            format!("{:.4} m of penetration", -self.physics_clearance)
        } else {
            format!("{:.4} m of clearance", self.physics_clearance)
        };
        write!(
            f,
            "at t = {:.3} s the barrier {where_} while the physics measures {physics}",
            self.t
        )
    }
}

/// The consistency rule between a barrier and the physics, for one obstacle at one instant:
/// they disagree when the robot's centre is inside the obstacle by more than
/// [`DISAGREEMENT_TOLERANCE`] by the barrier's distance while the physics has the robot's
/// colliders clear of it by more than that, or when the barrier's disc (which holds the robot's
/// footprint) is clear by more than it while the physics has them penetrating by more than it.
/// Arguments: the barrier's centre distance and disc clearance, the physics' clearance \[m\].
pub fn disagree(centre_distance: f64, barrier_clearance: f64, physics_clearance: f64) -> bool {
    let tol = DISAGREEMENT_TOLERANCE;
    (centre_distance < -tol && physics_clearance > tol)
        || (barrier_clearance > tol && physics_clearance < -tol)
}

/// Length of the final stretch of a run over which "settled in the goal" is judged \[s\].
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
    /// Simulated time \[s\].
    pub duration: f64,
    /// The true state stayed in every safe set, the robot never touched an obstacle, and every
    /// barrier value and the final state are finite numbers (fail closed: see `non_finite`).
    pub safe: bool,
    /// The first quantity of the run that was not a finite number (a barrier's smallest value,
    /// the final state, the clearance), when one was: the run is then reported UNSAFE, since a
    /// verdict on NaN or ∞ would be no verdict at all. Absent when all were finite.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub non_finite: Option<String>,
    /// The first time the run's own geometry contradicted itself (see [`disagree`]): the
    /// barrier's distance and the physics' clearance to one obstacle had opposite signs beyond
    /// [`DISAGREEMENT_TOLERANCE`]. The run then has no verdict: `safe` is false and `ftcbf run`
    /// ends with an error. Absent when they agreed throughout.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub disagreement: Option<Disagreement>,
    /// The robot touched an obstacle.
    pub collided: bool,
    /// First contact, if any.
    pub first_collision: Option<CollisionEvent>,
    /// First safe-set violation, if any.
    pub first_violation: Option<ViolationEvent>,
    /// Smallest h(x_true) per safe set and per obstacle barrier.
    pub min_barrier: Vec<NamedValue>,
    /// Smallest true clearance robot–obstacle over the run \[m\] (`None` without obstacles).
    pub min_clearance: Option<f64>,
    /// The goal set was entered ("entered the goal": at least one plant tick inside it).
    pub goal_reached: bool,
    /// First time in the goal set \[s\].
    pub time_to_goal: Option<f64>,
    /// "Settled in the goal": the true state was inside the goal set at every plant tick of the
    /// last [`SETTLE_WINDOW`] seconds of the run (the whole run if it is shorter).
    #[serde(default)]
    pub goal_settled: bool,
    /// Distance to the goal at the end, in the goal's metric (position, or full state) \[m\].
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
    /// The safe stops, if the robot stopped (absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safe_stop: Option<SafeStopReport>,
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
    /// Smoothness of the command and the path (all zero for the linear plant's command).
    #[serde(default)]
    pub smoothness: Smoothness,
    /// Per filter of the bank, its estimation error against the truth and its γ (empty for a
    /// law without a bank).
    #[serde(default)]
    pub estimation_errors: Vec<EstimationError>,
    /// Collisions (contacts that began) by what was hit and whether the robot moved (issue
    /// #51); static obstacles are counted in every world.
    #[serde(default)]
    pub collisions: CollisionCounts,
}

/// The robot counts as stopped at a contact when its true speed is below this \[m/s\] (about
/// 5 % of a TurtleBot3 burger's 0.22 m/s; the drive's encoder resolution is far below it).
pub const STOPPED_SPEED: f64 = 0.01;

/// Contacts that began during a run, by who moved (issue #51).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CollisionCounts {
    /// With an obstacle that stands still.
    pub static_obstacles: u64,
    /// With a moving obstacle while the robot moved towards it (its velocity's component
    /// towards the mover's centre ≥ [`STOPPED_SPEED`]): the robot's.
    pub mover_robot_moving: u64,
    /// With a moving obstacle while the robot stood, or moved only sideways or away from it
    /// (pushed or fleeing; its velocity's component towards the mover < [`STOPPED_SPEED`]):
    /// the mover ran into it (a walker's among them are also in `walker_robot_stopped`).
    pub mover_robot_stopped: u64,
    /// Of `mover_robot_stopped`, those with a walker: the walker's fault.
    pub walker_robot_stopped: u64,
}

impl CollisionCounts {
    /// Contacts with movers.
    pub fn movers(&self) -> u64 {
        self.mover_robot_moving + self.mover_robot_stopped
    }
}

impl RunSummary {
    /// Whether some honest filter (one that reads no attacked channel) left its γ.
    pub fn honest_gamma_exceeded(&self) -> bool {
        self.estimation_errors
            .iter()
            .any(|e| e.honest && e.exceeded())
    }
}

/// The human summary `ftcbf run` prints: one line per outcome (safety, goal, policy, command,
/// estimation errors, fail-closed counts, attacks), each ending in a newline.
impl std::fmt::Display for RunSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Each line as `ftcbf run` prints it, newline included.
        self.write_outcome(f)?;
        self.write_policy(f)?;
        self.write_estimation(f)?;
        self.write_faults(f)
    }
}

impl RunSummary {
    /// The run line, safety (with its first events and minima), goal and settling.
    fn write_outcome(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = self;
        writeln!(
            f,
            "{} · {} · seed {} · {:.1} s simulated, {} control steps",
            s.world, s.controller, s.seed, s.duration, s.control_steps
        )?;
        let verdict = match (&s.disagreement, s.safe) {
            (Some(_), _) => "NO VERDICT (the run's barrier and physics disagree)",
            (None, true) => "SAFE",
            (None, false) => "UNSAFE",
        };
        writeln!(f, "  safety:    {verdict}")?;
        if let Some(d) = &s.disagreement {
            writeln!(f, "    disagreement: {d}")?;
        }
        if let Some(n) = &s.non_finite {
            writeln!(
                f,
                "    invalid: non-finite {n} — a verdict on it would be no verdict, so UNSAFE"
            )?;
        }
        if let Some(c) = &s.first_collision {
            writeln!(f, "    first collision: {} at t = {:.3} s", c.obstacle, c.t)?;
        }
        if let Some(v) = &s.first_violation {
            writeln!(
                f,
                "    first violation: left {} at t = {:.3} s (h = {:.4})",
                v.set, v.t, v.value
            )?;
        }
        for b in &s.min_barrier {
            // An obstacle's h keeps `obstacle_margin` (and the velocity lift) clear of it: below
            // 0 without a collision is inside that margin, not in contact — said, so a SAFE
            // next to a negative h does not read as a contradiction.
            let note = if s.safe && b.value < 0.0 && b.name.starts_with("obstacle:") {
                " (inside the barrier's margin around the obstacle, not in contact)"
            } else {
                ""
            };
            writeln!(
                f,
                "    min h({}) over the run = {:.4}{note}",
                b.name, b.value
            )?;
        }
        if let Some(c) = s.min_clearance {
            writeln!(f, "    min clearance to obstacles = {c:.4} m")?;
        }
        match s.time_to_goal {
            Some(t) => writeln!(f, "  goal:      entered at t = {t:.2} s")?,
            None => writeln!(f, "  goal:      not entered")?,
        }
        writeln!(
            f,
            "  settled:   {} (inside the goal over the last {} s); final distance to the goal's centre {:.4} m",
            if s.goal_settled { "yes" } else { "no" },
            SETTLE_WINDOW,
            s.final_goal_distance,
        )?;
        Ok(())
    }

    /// The policy stages and the smoothness of the command.
    fn write_policy(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = self;
        let st = &s.steps;
        writeln!(
            f,
            "  policy:    step1 {} · clf relaxed {} · step2 {} · step3 {} · infeasible {}{}",
            st.step1,
            st.clf_relaxed,
            st.step2,
            st.step3,
            st.infeasible,
            if st.safe_stop > 0 {
                format!(" · safe stop {}", st.safe_stop)
            } else {
                String::new()
            }
        )?;
        if let Some(stop) = &s.safe_stop {
            writeln!(
                f,
                "  stopped:   at t = {:.1} s: {}",
                stop.first_t, stop.reason
            )?;
            writeln!(
                f,
                "             {} stop(s), {} braking step(s); {}",
                stop.episodes,
                stop.steps,
                if stop.stopped_at_end {
                    format!(
                        "still stopped at the end (since t = {:.1} s)",
                        stop.last_start
                    )
                } else {
                    "resumed after each".to_string()
                }
            )?;
        }
        let sm = &s.smoothness;
        writeln!(
            f,
            "  command:   ω changes sign in {:.1} % of steps · mean |Δω| {:.4} rad/s · mean |Δv| {:.4} m/s per step · path {:.2} m · stalls {}",
            100.0 * sm.omega_sign_change_fraction,
            sm.mean_abs_domega,
            sm.mean_abs_dv,
            sm.path_length,
            sm.stalls
        )?;
        Ok(())
    }

    /// Each filter's estimation error against the truth and its γ.
    fn write_estimation(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = self;
        if !s.estimation_errors.is_empty() {
            writeln!(
                f,
                "  estimation error against the truth, max over the run (‖x − x̂‖ vs the γ its rows assume):"
            )?;
            for e in &s.estimation_errors {
                let bound = match (e.gamma, e.max_ratio) {
                    (Some(g), Some(r)) => format!(
                        "{:.3}·γ (γ = {g:.4}){}",
                        r,
                        if e.exceeded() {
                            format!(", over γ at {} step(s)", e.steps_over)
                        } else {
                            String::new()
                        }
                    ),
                    _ => "no γ".to_string(),
                };
                writeln!(
                    f,
                    "    {:<22} {:<9} {bound} · position {:.4} m · velocity {:.4} m/s · worst at t = {:.2} s",
                    e.filter,
                    if e.honest { "honest" } else { "attacked" },
                    e.max_position_error,
                    e.max_velocity_error,
                    e.t_worst
                )?;
            }
        }
        Ok(())
    }

    /// Rejected readings, fail-closed counts and the attack windows.
    fn write_faults(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = self;
        if s.rejected_readings > 0 {
            writeln!(
                f,
                "  rejected readings (non-finite or absurd): {}",
                s.rejected_readings
            )?;
        }
        let fc = &s.fail_closed;
        if fc.any() {
            writeln!(
                f,
                "  fail-closed: {} step(s) with non-finite constraint rows · {} unusable reading(s) · {} step(s) where Step 2 kept the last barrier · {} step(s) where Step 3 kept a saturated estimator · {} braking step(s) · {} refused heading reading(s)",
                fc.non_finite_row_steps,
                fc.skipped_updates,
                fc.step2_retained_steps,
                fc.step3_saturated_steps,
                fc.brake_steps,
                fc.refused_headings
            )?;
        }
        for w in &s.attack_windows {
            writeln!(
                f,
                "  attack:    {} in [{}, {}){}",
                w.label,
                w.start,
                w.end.map_or("∞".to_string(), |e| e.to_string()),
                if w.outside_fault_patterns {
                    "  — OUTSIDE the declared fault patterns: no guarantee applies"
                } else {
                    ""
                }
            )?;
        }
        if s.attacks_together_outside_fault_patterns {
            writeln!(
                f,
                "  attacks together: their channels lie in no single declared fault pattern — \
                 OUTSIDE the single-fault model: no guarantee applies"
            )?;
        }
        Ok(())
    }
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
        key: "omega_sign_change_fraction",
        unit: "",
        of: |s| Some(s.smoothness.omega_sign_change_fraction),
    },
    Metric {
        key: "mean_abs_domega",
        unit: " rad/s",
        of: |s| Some(s.smoothness.mean_abs_domega),
    },
    Metric {
        key: "fallback_fraction",
        unit: "",
        of: |s| (s.control_steps > 0).then(|| s.steps.infeasible as f64 / s.control_steps as f64),
    },
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothness_counts_strict_sign_changes_and_mean_steps() {
        let mut m = SmoothnessMeter::default();
        // ω: 0.1, −0.1 (change), 0 (no strict sign), 0.2 (no change: 0 has none), −0.2 (change)
        let omegas = [0.1, -0.1, 0.0, 0.2, -0.2];
        for (k, w) in omegas.iter().enumerate() {
            m.observe([0.1 * k as f64, *w], [k as f64, 0.0]);
        }
        m.set_stalls(1);
        let s = m.smoothness();
        assert_eq!(s.omega_sign_changes, 2);
        assert!((s.omega_sign_change_fraction - 0.5).abs() < 1e-15);
        // |Δω| = 0.2, 0.1, 0.2, 0.4 → mean 0.225; |Δv| = 0.1 each
        assert!((s.mean_abs_domega - 0.225).abs() < 1e-12);
        assert!((s.mean_abs_dv - 0.1).abs() < 1e-12);
        assert!((s.path_length - 4.0).abs() < 1e-12);
        assert_eq!(s.stalls, 1);
    }
}

/// The first non-finite quantity among a run's barrier minima, its smallest clearance and its
/// final state, named for the summary ("min h(floor) = inf", "final_state\[1\] = NaN").
pub fn first_non_finite(
    min_barrier: &[NamedValue],
    min_clearance: Option<f64>,
    final_state: &[f64; 4],
) -> Option<String> {
    const STATE: [&str; 4] = ["p_x", "p_y", "v_x", "v_y"];
    min_barrier
        .iter()
        .find(|b| !b.value.is_finite())
        .map(|b| format!("min h({}) = {}", b.name, b.value))
        .or_else(|| {
            min_clearance
                .filter(|c| !c.is_finite())
                .map(|c| format!("min clearance = {c}"))
        })
        .or_else(|| {
            final_state
                .iter()
                .position(|v| !v.is_finite())
                .map(|i| format!("final state {} = {}", STATE[i], final_state[i]))
        })
}

#[cfg(test)]
mod non_finite_tests {
    use super::*;

    #[test]
    fn the_first_non_finite_quantity_is_named() {
        let b = |name: &str, value: f64| NamedValue {
            name: name.into(),
            value,
        };
        let fine = [b("floor", 0.1), b("obstacle:wall", 0.02)];
        assert_eq!(
            first_non_finite(&fine, Some(0.3), &[1.0, 0.0, 0.0, 0.0]),
            None
        );
        let inf = [b("floor", f64::INFINITY)];
        assert_eq!(
            first_non_finite(&inf, None, &[1.0, 0.0, 0.0, 0.0]).as_deref(),
            Some("min h(floor) = inf")
        );
        assert_eq!(
            first_non_finite(&fine, Some(f64::NAN), &[1.0, 0.0, 0.0, 0.0]).as_deref(),
            Some("min clearance = NaN")
        );
        assert_eq!(
            first_non_finite(&fine, None, &[1.0, f64::NEG_INFINITY, 0.0, 0.0]).as_deref(),
            Some("final state p_y = -inf")
        );
    }
}

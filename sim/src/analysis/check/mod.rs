//! The hypothesis checker behind `ftcbf check`: for a world as written, every hypothesis the
//! guarantee of Theorem 3 (Pr(x_t ∈ C ∀t) ≥ 1 − ε under any single fault pattern) rests on,
//! each with its numbers, and one verdict.
//!
//! Checked, in order:
//! 1. **Disjoint patterns** (§3.1): F(r_i) ∩ F(r_j) = ∅.
//! 2. **Invertible R̄** for every filter (§4.1): the smallest variance of the channels it keeps
//!    (a channel declared noise-free is floored at [`crate::world::structure::MIN_VARIANCE`]).
//! 3. **Detectability** of (F, c̄) for every single-drop filter x̂_i and pair-drop filter x̂_ij
//!    (PBH test, [`ftcbf_controller::params::detectability`]), with the unobservable directions
//!    named in state terms.
//! 4. **Finite γ_i and θ_ij** and what bounds them: the steady state of the Riccati recursion
//!    (detectable filters), or the largest covariance reached over the world's duration from
//!    the declared initial uncertainty `[control] initial_std` (finite horizon). A finite-horizon
//!    bound is accepted for a filter whose unobservable directions are positions only (its
//!    velocity is measured: the position error is an integral of a bounded velocity error —
//!    dead reckoning). A filter that also loses every velocity fix runs open loop: its bound
//!    rests on the assumed process noise alone, nothing measured bounds it, and any
//!    unmodelled actuation (motor lag, slip, clipping) enters it without limit — (4.5) cannot
//!    be certified, and the verdict says so.
//!    4b. **γ covers the transient** (`bounds = "paper"` only): §4.3's γ bounds the steady-state
//!    covariance; a P0 above it makes every filter's error in its first steps larger than γ.
//! 5. **Condition 1 of Theorem 3** as far as it can be decided statically: Lemma 1 for
//!    half-planes, Prop. 1 on the position part of lifted ellipses (θ̄ ≤ √(2(1 − h̄)/λ̄(Φ))),
//!    Thm. 5 at the start for an inside ellipse; for obstacles the lift gives Λ ≠ 0 per filter
//!    and agreement across filters is stated as an assumption.
//! 6. **Condition 1 under the input limit**: the proof of case (i) scales a witness input
//!    without bound. With a box |u_k| ≤ l_k, the honest filter's row must be satisfiable by the
//!    box at rest on its own boundary ĥ_i = 0, where it reads Λu ≥ γ_i‖(K_i c̄_i)ᵀ∂h‖. When the
//!    box cannot give that, the honest row goes infeasible near the boundary, the policy reaches
//!    Step 3, and Step 3's residue ranking cannot tell an honest filter from one fed by a
//!    stealthy attacker (whose residue sits at its nominal level): the guarantee is void.
//!    Exact for half-planes and half-space obstacles; for curved boundaries the worst of 360
//!    normals with the curvature term left out (stated as an assumption).
//!    6b. **The filters' model is true of the drive** (rapier robots): the safety-filter form's
//!    inputs are covered by the identified process noise; the paper form's bang-bang inputs are
//!    not (measured), and the hypothesis fails.
//! 7. **Attacks inside one fault pattern**: the union of the declared attacks' channels lies in
//!    one F(r_i) (the theorem covers one fault at a time).
//! 8. **Holding the goal** (not part of the safety guarantee; reported): at rest the CBF row of
//!    a half-plane needs h(x̂) ≥ h̄_γ + γ‖(Kc̄)ᵀa‖/κ; if no point of the goal set reaches that,
//!    the robot cannot settle there with the guarantee's margins.
//!
//! One file per concern: this one holds the report's types, the order of the checks
//! ([`check_world`]) and the context every check reads (`Ctx`: world, setup, names); the
//! hypotheses on estimation (1–4b, 6b) are in `estimation`, those on the barrier rows and the
//! goal (5–11) in `safety`, the context lines printed before them in `context`, the text and its
//! grouping by barrier in `report`, and `--suggest` in `suggest`.

use std::fmt;

use ftcbf_controller::conditions::{
    check_lemma1, check_theorem5, condition_4_4, Condition44Verdict,
};
use ftcbf_controller::params::{
    detectability, pair_slot, steady_state_gain_product, Detectability,
};
use ftcbf_controller::{Input, State, StateMatrix};

use crate::analysis::liveness::{self, LivenessReport};
use crate::model::setup::{
    channel_mask, ellipse_prop1, initial_covariance, process_model, process_noise, rest_hold,
    ControlSetup, NoiseSource,
};
use crate::model::{CompiledWorld, RunError};
use crate::safe_sets::ellipse_phi_state;
use crate::world::structure::{
    heading_fusion, heading_hold, heading_sensor, sensor_dependents, speed_bound, turn_rate_bound,
    Conversion, MIN_VARIANCE,
};
use crate::world::{Dynamics, GoalMetric, SafeSetSpec, World};

mod context;
pub(crate) mod estimation;
mod report;
mod safety;
mod suggest;

use context::*;
use estimation::*;
use report::*;
use safety::*;

pub use report::group_by_barrier;
pub use suggest::{suggest, Suggestion};

/// Outcome of one hypothesis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Verified from the world.
    Holds,
    /// Verified false: Theorem 3 does not apply.
    Fails,
    /// Cannot be decided statically; stated as an assumption of the verdict.
    Assumed,
    /// Reported only; not a hypothesis of the safety guarantee.
    Info,
}

impl Status {
    fn tag(self) -> &'static str {
        match self {
            Status::Holds => "HOLDS  ",
            Status::Fails => "FAILS  ",
            Status::Assumed => "ASSUMED",
            Status::Info => "INFO   ",
        }
    }
}

/// One checked hypothesis with its numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct Hypothesis {
    /// Short name (e.g. "detectable x̂_12").
    pub name: String,
    /// Outcome.
    pub status: Status,
    /// The numbers behind it.
    pub detail: String,
}

/// What bounds a filter's error covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CovarianceBound {
    /// The Riccati recursion has a steady state.
    SteadyState,
    /// No steady state; the largest covariance over the horizon from the declared P0, accepted
    /// (positions dead-reckoned from measured velocity).
    FiniteHorizon {
        /// Horizon \[s\].
        seconds: f64,
    },
    /// No steady state and no velocity fix: open loop, not certifiable.
    OpenLoop {
        /// Horizon \[s\].
        seconds: f64,
    },
}

/// One filter of the bank.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterCheck {
    /// "x̂_1 (drops gnss1)", "x̂_12 (drops gnss1 ∪ gnss2)".
    pub label: String,
    /// Channels it uses.
    pub channels: Vec<String>,
    /// Smallest variance on the diagonal of R̄ (∞ when it uses no channel).
    pub r_bar_min: f64,
    /// PBH detectability and unobservable directions.
    pub detectability: Detectability,
    /// What bounds its covariance.
    pub bound: CovarianceBound,
    /// γ in force for it (γ_i or γ_ij), when computed.
    pub gamma: Option<f64>,
}

/// Whether the goal can be held at rest with the guarantee's margins, per (half-plane, filter).
#[derive(Debug, Clone, PartialEq)]
pub struct GoalHold {
    /// Barrier name.
    pub barrier: String,
    /// Filter label.
    pub filter: String,
    /// h̄_γ + γ‖(Kc̄)ᵀ a‖/κ: the smallest h(x̂) the CBF row admits at rest.
    pub needed_h: f64,
    /// The largest h on the goal set (at rest for a position goal).
    pub max_h_in_goal: f64,
}

impl GoalHold {
    /// Whether some point of the goal set admits rest.
    pub fn holds(&self) -> bool {
        self.max_h_in_goal >= self.needed_h
    }
}

/// The one-line verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// Theorem 3 applies: Pr(safe) ≥ 1 − ε for any single fault pattern.
    pub applies: bool,
    /// ε.
    pub epsilon: f64,
    /// Why not (empty when it applies).
    pub reasons: Vec<String>,
    /// Conditions it rests on that the checker cannot decide statically.
    pub assumptions: Vec<String>,
    /// Some bound is finite-horizon: the guarantee covers the world's duration only.
    pub horizon: Option<f64>,
    /// What the tracked movers' readings add to the failure probability (their error bounds
    /// fail with probability ≤ this over the run, issue #51); 0 without a tracker.
    pub tracked_epsilon: f64,
}

impl Verdict {
    /// The verdict line.
    pub fn line(&self) -> String {
        if self.applies {
            let over = self
                .horizon
                .map_or(String::new(), |t| format!(" over the run's {t} s"));
            let assuming = if self.assumptions.is_empty() {
                String::new()
            } else {
                format!(", assuming {}", self.assumptions.join("; "))
            };
            if self.tracked_epsilon > 0.0 {
                return format!(
                    "Theorem 3 applies{assuming}: Pr(safe) ≥ 1 − ε − ε_tracked = {} for any single fault pattern{over} (ε_tracked = {}: the tracked movers' readings outside their bounds)",
                    1.0 - (self.epsilon + self.tracked_epsilon),
                    self.tracked_epsilon
                );
            }
            format!(
                "Theorem 3 applies{assuming}: Pr(safe) ≥ 1 − ε = {} for any single fault pattern{over}",
                1.0 - self.epsilon
            )
        } else {
            format!("Theorem 3 does NOT apply: {}", self.reasons.join("; "))
        }
    }

    /// One word for tables: `applies`, `applies (T s)`, either with `, assuming N` (N conditions
    /// `check` cannot decide), or `no`.
    pub fn short(&self) -> String {
        match (self.applies, self.horizon) {
            (true, None) if self.assumptions.is_empty() => "applies".to_string(),
            (true, None) => format!("applies, assuming {}", self.assumptions.len()),
            (true, Some(t)) if self.assumptions.is_empty() => format!("applies ({t} s)"),
            (true, Some(t)) => format!("applies ({t} s), assuming {}", self.assumptions.len()),
            (false, _) => "no".to_string(),
        }
    }
}

/// Everything `ftcbf check` reports.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckReport {
    /// World name.
    pub world: String,
    /// Description lines (plant, control, channels, patterns, parameters).
    pub context: Vec<String>,
    /// The filters of the bank (singles, then pairs).
    pub filters: Vec<FilterCheck>,
    /// Hypotheses in order.
    pub hypotheses: Vec<Hypothesis>,
    /// Goal-holding numbers per half-plane and filter.
    pub goal: Vec<GoalHold>,
    /// The verdict.
    pub verdict: Verdict,
    /// The second verdict: the safe stop's guarantee (`[control] fallback = "brake"`;
    /// [`crate::analysis::safe_stop`]).
    pub safe_stop: crate::analysis::safe_stop::SafeStopVerdict,
    /// Will the robot move and settle (not part of Theorem 3; [`crate::analysis::liveness`]).
    pub liveness: LivenessReport,
    /// The barriers' names (`obstacle:wall_1`, `floor`, …): lines that differ only in the
    /// barrier they name are printed once, listing the barriers ([`group_by_barrier`]).
    pub barrier_names: Vec<String>,
    /// What `[environment]` loaded: kept and dropped elements and why, and the loader's
    /// warnings ([`crate::environment::EnvironmentReport::lines`]); empty without one.
    pub environment: Vec<String>,
}

fn fmt_list(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.6}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The names the report uses: sensors, controller channels (by the sensor they read) and
/// fault patterns.
struct Names<'a> {
    sensors: Vec<&'a str>,
    channels: Vec<String>,
    patterns: Vec<&'a str>,
}

impl<'a> Names<'a> {
    fn new(world: &'a World, setup: &ControlSetup) -> Self {
        let f = &world.file;
        let sensors: Vec<&str> = f.sensors.iter().map(|s| s.name.as_str()).collect();
        let channels: Vec<String> = setup
            .sensor_of_channel
            .iter()
            .zip(&setup.conversion)
            .map(|(&s, c)| match c {
                Conversion::Direct => sensors[s].to_string(),
                Conversion::SpeedX => format!("{}→vx", sensors[s]),
                Conversion::SpeedY => format!("{}→vy", sensors[s]),
            })
            .collect();
        let patterns: Vec<&str> = f.fault_patterns.iter().map(|p| p.name.as_str()).collect();
        Self {
            sensors,
            channels,
            patterns,
        }
    }
}

/// What every check reads: the world as written, its controller setup, and the names the
/// report uses. Passed by value (three references) to each hypothesis of [`check_setup`].
#[derive(Clone, Copy)]
struct Ctx<'a> {
    world: &'a World,
    setup: &'a ControlSetup,
    names: &'a Names<'a>,
}

/// What the checks found so far: the hypotheses in order, why Theorem 3 does not apply, what
/// it rests on, and whether some bound is finite-horizon.
#[derive(Default)]
struct Findings {
    hypotheses: Vec<Hypothesis>,
    reasons: Vec<String>,
    assumptions: Vec<String>,
    finite_horizon: bool,
}

impl Findings {
    /// Records a hypothesis; a failing one's detail is also a reason of the verdict.
    fn record(&mut self, name: String, status: Status, detail: String) {
        if status == Status::Fails {
            self.reasons.push(detail.clone());
        }
        self.hypotheses.push(Hypothesis {
            name,
            status,
            detail,
        });
    }
}

/// Check `world` (see the module docs): compiles it, then [`check_compiled`].
pub fn check_world(world: &World) -> Result<CheckReport, RunError> {
    let setup = ControlSetup::new(world, world.file.control.controller)?;
    Ok(check_setup(world, &setup))
}

/// Check a compiled world (see the module docs), reusing its controller setup.
pub fn check_compiled(compiled: &CompiledWorld) -> CheckReport {
    check_setup(compiled.world(), compiled.setup())
}

/// Condition (4.4) decided exactly on every barrier that runs, at the start estimate x̂(0):
/// (barrier name, verdict) in the setup's barrier order.
pub fn condition_4_4_at_start(setup: &ControlSetup) -> Vec<(&str, Condition44Verdict)> {
    let start = [setup.config.x0];
    setup
        .config
        .barriers
        .iter()
        .zip(&setup.barrier_names)
        .map(|(b, name)| {
            let verdict = condition_4_4(b.as_ref(), &setup.config.model.g, &start);
            (name.as_str(), verdict)
        })
        .collect()
}

/// The lines `ftcbf check` prints for [`condition_4_4_at_start`], grouped by barrier
/// ([`group_by_barrier`]).
/// With more than `MAX_LISTED` barriers, the barriers where it holds share one line (naming
/// three, the count of the rest, and the least margin), and only the others get a line each.
pub fn condition_4_4_lines(setup: &ControlSetup) -> Vec<String> {
    let all = condition_4_4_at_start(setup);
    if all.len() <= MAX_LISTED {
        let lines = all
            .into_iter()
            .map(|(name, v)| format!("(4.4) for {name} at the start estimate: {v}"));
        return group_by_barrier(lines, &setup.barrier_names);
    }
    let (holds, other): (Vec<_>, Vec<_>) = all.into_iter().partition(|(_, v)| v.holds);
    let mut out = Vec::new();
    if !holds.is_empty() {
        let names: Vec<&str> = holds.iter().map(|(n, _)| *n).collect();
        let worst = holds
            .iter()
            .filter_map(|(n, v)| v.margin.map(|m| (m, *n)))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        out.push(format!(
            "(4.4) at the start estimate HOLDS for {} barriers ({}){}",
            names.len(),
            crate::environment::name_list(&names, 3),
            worst.map_or(String::new(), |(m, n)| format!(
                "; least min cos {m:.4} ({n})"
            ))
        ));
    }
    out.extend(
        other
            .into_iter()
            .map(|(name, v)| format!("(4.4) for {name} at the start estimate: {v}")),
    );
    out
}

fn check_setup(world: &World, setup: &ControlSetup) -> CheckReport {
    let f = &world.file;
    let names = Names::new(world, setup);
    let cx = Ctx {
        world,
        setup,
        names: &names,
    };
    let context = context(cx);

    let mut found = Findings::default();
    check_disjoint_patterns(cx, &mut found); // 1
    check_converted_odometry(cx, &mut found); // 1b
    check_drive_heading(cx, &mut found); // 1c
    check_white_noise(cx, &mut found); // 1d
    let filters = check_filters(cx, &mut found); // 2-4
    check_finite_parameters(cx, &mut found); // 4
    report_sensor_timing(cx, &mut found); // 4a
    check_transient(cx, &mut found); // 4b
    check_condition1(cx, &mut found); // 5
    check_input_authority(cx, &filters, &mut found); // 6
    if matches!(f.dynamics, Dynamics::Rapier) {
        check_drive_model(cx, &mut found); // 6b
    }
    check_attacks(cx, &mut found); // 7
    let goal = goal_holding(cx, &filters); // 8
    for g in &goal {
        let h = goal_hypothesis(g);
        if h.status == Status::Fails {
            found.reasons.push(h.detail.clone());
        }
        found.hypotheses.push(h);
    }
    check_start_and_goal(cx, &mut found); // 9
    check_finite_report(&context[usize::from(f.description.is_some())..], &mut found); // fail closed on NaN / ∞

    let liveness = liveness::predict(world, setup);
    check_joint_rows(cx, &liveness, &mut found); // 10
    check_departures(cx, &mut found); // 11
    check_movers(cx, &mut found); // 12

    let applies = found.reasons.is_empty();
    let failed: Vec<crate::analysis::safe_stop::Failed<'_>> = found
        .hypotheses
        .iter()
        .filter(|h| h.status == Status::Fails)
        .map(|h| crate::analysis::safe_stop::Failed {
            name: &h.name,
            detail: &h.detail,
        })
        .collect();
    let safe_stop = crate::analysis::safe_stop::verdict(world, &failed, &liveness);
    let mut liveness = liveness;
    liveness.safe_stop = crate::analysis::safe_stop::predicted_stop_line(world, &failed, &liveness);
    CheckReport {
        environment: environment_lines(world),
        world: world.name.clone(),
        context,
        filters,
        hypotheses: found.hypotheses,
        goal,
        verdict: Verdict {
            applies,
            epsilon: f.control.epsilon,
            reasons: found.reasons,
            assumptions: found.assumptions,
            horizon: (applies && found.finite_horizon).then_some(f.duration),
            tracked_epsilon: if world
                .obstacles
                .iter()
                .any(|o| o.spec.motion.is_some() && o.spec.tracker.is_some())
            {
                f.control.epsilon
            } else {
                0.0
            },
        },
        safe_stop,
        liveness,
        barrier_names: setup.barrier_names.clone(),
    }
}

/// The most barriers a grouped line lists by name; beyond it (a loaded environment's dozens of
/// walls) a line names three and says how many more.
const MAX_LISTED: usize = 6;

//! Liveness prediction (issue #36): will the robot leave its start, move along its path and
//! settle in its goal, with the rows the controller will impose?
//!
//! Theorem 3 is about safety only. A world can be certified safe and still never move: where
//! every input the CBF rows allow pushes the robot back (or no input satisfies them), the
//! safety filter holds the robot still, and a run ends "goal not entered" with nothing said
//! about why. This module predicts that before any run, from the same numbers the controller
//! uses:
//!
//! - **the path**: the safety-filter tracker's points (start, the planned path, the goal where
//!   the rows can hold the robot; `runner::setup`), or start → waypoints → goal for the paper
//!   form; sampled every [`SAMPLE_STEP`] m;
//! - **the rows**: eq. (4.3) of every unit the controller imposes (the single-drop filters x̂_i
//!   for FT-CBF-CLF, the all-channel filter for the baseline), with γ_i, h̄_γ, κ and the filters'
//!   steady-state gain terms M = K c̄ and N = K ν̄ν̄ᵀKᵀ (finite-horizon worst posterior for a
//!   filter with no steady state), `ftcbf_controller::constraints::cbf_row` itself;
//! - **the estimates**: at rest on the path point. Without attack every estimate is there (to
//!   within γ). Under the declared attack, each spoofed filter's estimate is moved by that
//!   filter's own response to what the attack adds to its readings (`Model::responses`: a
//!   steady-state Kalman filter is linear, so the offset does not depend on the state or the
//!   input), when the robot gets there on the planned timeline; where that cannot be computed,
//!   by the attack's reach ([`declared_reach`]) in every direction the attacked channels can
//!   move a position fix. Beyond θ_ia(t), Step 2 drops the spoofed estimate.
//!
//! At each point it solves the 2-D problem "largest acceleration along the path's direction
//! that satisfies every row jointly inside the input box" exactly (vertex enumeration, as
//! `ftcbf_controller::feasibility` decides feasibility). The path is **live** when that is at
//! least [`MIN_PROGRESS`] everywhere; otherwise the prediction names the first point where it
//! is not, whether the rows there are infeasible (Step 3 then drops units by residue, which a
//! stealthy attacker can win) or only push back (a stall), and the obstacles whose rows bind.
//! The goal **holds** when at some point of the goal set u = 0 satisfies every row at rest.
//!
//! This is a prediction about the nominal case, not a proof: the robot does not follow the
//! path exactly, noise moves the estimates by up to γ, and the tracker's stall escape can find
//! a way around. `ftcbf batch` measures the outcome; the README reports how often the two agree.

use std::fmt;

use ftcbf_controller::constraints::{cbf_row, HalfSpace};
use ftcbf_controller::controller::{ControllerKind, ProblemForm};
use ftcbf_controller::params::{
    gain_product, horizon_posterior_max, steady_state_riccati, update_gains,
};
use ftcbf_controller::{Input, State, StateMatrix};

use crate::attacks::{open_loop_offset, AttackKind};
use crate::runner::setup::{channel_mask, initial_covariance, ControlSetup};
use crate::sensors::Quantity;
use crate::summary::RunSummary;
use crate::world::World;

/// Spacing of the path samples \[m\].
pub const SAMPLE_STEP: f64 = 0.05;

/// The least acceleration along the path [m/s²] the rows must leave for the robot to be
/// predicted to move on (below it, the tracker's u_nom is projected to a standstill).
pub const MIN_PROGRESS: f64 = 0.02;

/// The share of the tracker's cruise speed the robot is assumed to make on average (it
/// accelerates, slows near obstacles and turns), for when it reaches each point of the path.
pub const NOMINAL_SPEED_SHARE: f64 = 0.6;

/// Seconds before the robot is assumed to start along the path.
const START_DELAY: f64 = 1.0;

/// Spacing of the times, from the robot's arrival to the end of the run, at which holding is
/// judged [s] (an attack's offset can sweep a spoofed estimate across a thin wall in less).
const HOLD_STEP: f64 = 0.1;

/// How far across the path the robot is looked for a live point \[m\].
pub const LATERAL_REACH: f64 = 0.5;

/// Spacing of the points tried across the path \[m\].
const LATERAL_STEP: f64 = 0.025;

/// Directions tried for a spoofed estimate whose attack moves both position axes.
const DIRECTIONS: usize = 16;

/// One unit of the controller as the rows see it.
#[derive(Debug, Clone)]
struct Unit {
    gamma: f64,
    m: StateMatrix,
    n: StateMatrix,
    /// The channels the filter uses.
    mask: Vec<bool>,
    /// Its steady-state prior covariance (None: no steady state).
    prior: Option<StateMatrix>,
}

/// Why a path point is not live.
#[derive(Debug, Clone, PartialEq)]
pub enum Blocked {
    /// No input in the box satisfies every row (Step 3 then decides by residue).
    Infeasible,
    /// Inputs exist, but the best one along the path is this acceleration [m/s²] (< the least).
    NoProgress(f64),
}

/// The first point of the path that is not live.
#[derive(Debug, Clone, PartialEq)]
pub struct Stall {
    /// Where \[m\].
    pub at: [f64; 2],
    /// How far along the path \[m\].
    pub along: f64,
    /// Why.
    pub blocked: Blocked,
    /// Barriers whose rows demand a push there (ω̄ > 0), most demanding first.
    pub binding: Vec<String>,
    /// The spoofed estimates' offset at the worst direction \[m\] (zero without attack).
    pub offset: [f64; 2],
}

/// One case: without attack, or under the declared attack.
#[derive(Debug, Clone, PartialEq)]
pub struct LivenessCase {
    /// "without attack", "under the declared attack (…)".
    pub name: String,
    /// The spoofed estimates' largest offset \[m\] (0 without attack).
    pub reach: f64,
    /// The first point that is not live.
    pub stall: Option<Stall>,
    /// The least acceleration along the path over the live points [m/s²] and where.
    pub least_progress: (f64, [f64; 2]),
    /// Whether some point of the goal set admits u = 0 at rest.
    pub goal_holds: bool,
}

impl LivenessCase {
    /// Path live and goal held.
    pub fn live(&self) -> bool {
        self.stall.is_none() && self.goal_holds
    }
}

/// A change of the world that makes the prediction live.
#[derive(Debug, Clone, PartialEq)]
pub struct Fix {
    /// The world-file key.
    pub key: String,
    /// The value to set.
    pub value: f64,
}

/// The liveness prediction of a world.
#[derive(Debug, Clone, PartialEq)]
pub struct LivenessReport {
    /// κ the rows were built with.
    pub kappa: f64,
    /// Length of the path \[m\] and the number of points sampled.
    pub path_length: f64,
    /// Points sampled.
    pub samples: usize,
    /// Without attack, then under the declared attack (when there is one).
    pub cases: Vec<LivenessCase>,
    /// The smallest change found that makes every case live (see `smallest_fix`).
    pub fix: Option<Fix>,
    /// What no key of `[control]` can change (e.g. a pair filter with no channel).
    pub structural: Vec<String>,
    /// Not predicted (why), e.g. the nominal controller has no rows.
    pub skipped: Option<String>,
}

impl LivenessReport {
    /// Every case live (a skipped prediction counts as live: nothing holds the robot).
    pub fn live(&self) -> bool {
        self.cases.iter().all(LivenessCase::live)
    }

    /// The verdict line.
    pub fn line(&self) -> String {
        if let Some(why) = &self.skipped {
            return format!("liveness not predicted: {why}");
        }
        let Some(c) = self.cases.iter().find(|c| !c.live()) else {
            return format!(
                "live: the rows leave a forward input at every point of the {:.2} m path and hold the robot in its goal (κ = {})",
                self.path_length, self.kappa
            );
        };
        let mut s = match &c.stall {
            Some(st) => format!(
                "the robot will NOT reach its goal {}: {}",
                c.name,
                stall_text(st)
            ),
            None => format!(
                "the robot can reach but NOT hold its goal {}: no point of the goal set admits rest under every row",
                c.name
            ),
        };
        match &self.fix {
            Some(f) => s.push_str(&format!("; smallest fix: set {} = {}", f.key, f.value)),
            None if self.structural.is_empty() => s.push_str(
                "; no value of cbf_gain or input_limit in the searched ranges makes it live",
            ),
            None => {}
        }
        for t in &self.structural {
            s.push_str("; ");
            s.push_str(t);
        }
        s
    }
}

/// Where and why a stall blocks the path, in one phrase (also `check`'s joint-rows finding).
pub fn stall_text(st: &Stall) -> String {
    let why = match st.blocked {
        Blocked::Infeasible => {
            "no input in the box satisfies every row (Step 3 decides by residue there)".to_string()
        }
        Blocked::NoProgress(a) => format!(
            "the best input the rows allow along the path is {a:.3} m/s² (needs ≥ {MIN_PROGRESS})"
        ),
    };
    let off = if st.offset != [0.0, 0.0] {
        format!(
            ", spoofed estimates off by ({:.2}, {:.2}) m",
            st.offset[0], st.offset[1]
        )
    } else {
        String::new()
    };
    format!(
        "stalls at ({:.2}, {:.2}), {:.2} m along the path{off}: {why}; rows of {}",
        st.at[0],
        st.at[1],
        st.along,
        if st.binding.is_empty() {
            "no barrier".to_string()
        } else {
            st.binding.join(", ")
        }
    )
}

impl fmt::Display for LivenessReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(why) = &self.skipped {
            return write!(f, "  liveness not predicted: {why}");
        }
        writeln!(
            f,
            "liveness (not part of Theorem 3; the rows at rest along the planned path, {:.2} m, {} points, κ = {}):",
            self.path_length, self.samples, self.kappa
        )?;
        for c in &self.cases {
            let tag = match (&c.stall, c.goal_holds) {
                (None, true) => "LIVE   ",
                (Some(_), _) => "STALLS ",
                (None, false) => "NO HOLD",
            };
            let body = match &c.stall {
                Some(st) => stall_text(st),
                None => format!(
                    "a forward input at every point (least {:.3} m/s² at ({:.2}, {:.2}))",
                    c.least_progress.0, c.least_progress.1[0], c.least_progress.1[1]
                ),
            };
            let reach = if c.reach > 0.0 {
                format!(" [spoofed estimates up to {:.3} m off]", c.reach)
            } else {
                String::new()
            };
            writeln!(
                f,
                "  [{tag}] {}{reach}: {body}; goal {}",
                c.name,
                if c.goal_holds {
                    "can be held at rest"
                } else {
                    "can NOT be held at rest"
                }
            )?;
        }
        write!(f, "liveness verdict: {}", self.line())
    }
}

/// The rows' inputs of a world: units, the path, and the attack's geometry.
struct Model<'a> {
    setup: &'a ControlSetup,
    units: Vec<Unit>,
    /// Units whose estimates an attack on the attacked pattern moves, with the honest unit.
    spoofed: Vec<(usize, usize)>,
    /// The number of fault patterns.
    patterns: usize,
    path: Vec<[f64; 2]>,
    goal: [f64; 2],
    goal_radius: f64,
    /// Axes a declared attack moves (x, y).
    axes: [bool; 2],
    /// The speed the robot is assumed to make along the path [m/s] (when it reaches a point).
    speed: f64,
    /// The largest coordinate of the path \[m\] (a `scale` attack's reach).
    max_coord: f64,
    attack_name: String,
    world: &'a World,
    /// Each spoofed unit's estimate offset [m] at every control step under the declared attack,
    /// where it can be computed exactly ([`Model::responses`]); in the order of `spoofed`.
    response: Option<Vec<Vec<[f64; 2]>>>,
}

/// The offsets of every unit's estimate [m], indexed like `Model::units`.
type Offsets = Vec<[f64; 2]>;

/// The unit of a filter that keeps `mask`, with its gain terms: steady state, or the worst
/// posterior over the run from P0 when the recursion has none.
fn unit(world: &World, setup: &ControlSetup, mask: Vec<bool>, gamma: f64) -> Unit {
    let model = &setup.config.model;
    let dt = world.control_dt();
    let ss = steady_state_riccati(model, &mask, dt);
    let steady = ss.converged && ss.posterior.iter().all(|v| v.is_finite());
    let (prior, post) = if steady {
        (ss.prior, ss.posterior)
    } else {
        let n = (world.file.duration / dt).ceil() as usize;
        let post = horizon_posterior_max(model, &mask, dt, &initial_covariance(world), n);
        let d = model.discretize(dt);
        let prior = d.phi * post * d.phi.transpose() + d.qd;
        (prior, post)
    };
    let m = gain_product(model, &mask, &post, dt);
    let diff = (prior - post) / dt;
    Unit {
        gamma,
        m,
        n: (diff + diff.transpose()) * 0.5,
        prior: steady.then_some(prior),
        mask,
    }
}

/// The packed index of pair (i, j), i ≠ j, among m patterns (the order of `ParamReport::theta`).
fn pair_slot(m: usize, i: usize, j: usize) -> usize {
    let (a, b) = (i.min(j), i.max(j));
    a * (2 * m - a - 1) / 2 + (b - a - 1)
}

/// θ between units i and j after `t` seconds: the schedule θ_ij(t) where there is one, else
/// the constant θ_ij (or one value for all).
fn theta_at(setup: &ControlSetup, m: usize, i: usize, j: usize, t: f64) -> f64 {
    let slot = pair_slot(m, i, j);
    if let Some(v) = setup
        .params
        .theta_schedule
        .as_ref()
        .and_then(|s| s.at(slot, t))
    {
        return v;
    }
    let th = &setup.params.theta;
    if th.len() == 1 {
        return th[0];
    }
    th.get(slot).copied().unwrap_or(f64::INFINITY)
}

/// How far the declared attacks move a position fix at time `t` \[m\], and which axes: a bias its
/// value, a ramp or coordinated walk its rate times the time since its start (up to its cap),
/// a stealthy bias its rate times time (up to its cap), a sinusoid its amplitude, a scale its
/// factor's excess over the largest coordinate of the path; a frozen or replayed fix as far as
/// the robot has driven since (at `speed`). Attacks that only remove readings (dropout,
/// non-finite or absurd values the controller rejects, spikes a filter averages) move no fix:
/// 0. An offset on a velocity or speed channel moves the position the filters integrate by the
/// offset times the attacked time, one on a heading by `speed`·sin(offset) times it (θ then
/// decides whether Step 2 drops it). Outside an attack's window: 0.
pub fn declared_reach(world: &World, t: f64, speed: f64, max_coord: f64) -> Reach {
    let f = &world.file;
    let mut reach: f64 = 0.0;
    let mut axes = [false, false];
    let mut exact = true;
    for a in &f.attacks {
        let mut kinds = [false; 2];
        // How a reading's offset becomes a position offset: directly (x, y), integrated over the
        // attacked time (velocity, speed), or turned into a cross-track velocity (heading).
        let mut integrated = false;
        let mut turned = false;
        for c in &a.channels {
            if let Some(s) = f.sensors.iter().find(|s| &s.name == c) {
                match s.measures {
                    Quantity::X => kinds[0] = true,
                    Quantity::Y => kinds[1] = true,
                    Quantity::Vx => {
                        kinds[0] = true;
                        integrated = true;
                    }
                    Quantity::Vy => {
                        kinds[1] = true;
                        integrated = true;
                    }
                    Quantity::Heading => {
                        kinds = [true, true];
                        turned = true;
                    }
                    _ => {
                        kinds = [true, true];
                        integrated = true;
                    }
                }
            }
        }
        axes[0] |= kinds[0];
        axes[1] |= kinds[1];
        if t < a.start || a.end.is_some_and(|e| t >= e) {
            continue;
        }
        let span = t - a.start;
        let per_axis = match &a.kind {
            AttackKind::Bias { value } => value.abs(),
            AttackKind::Ramp { rate, cap } => {
                let r = rate.abs() * span;
                cap.map_or(r, |c| r.min(c.abs()))
            }
            AttackKind::Sinusoid { amplitude, .. } => amplitude.abs(),
            AttackKind::Freeze { .. } | AttackKind::Replay { .. } => speed * span,
            AttackKind::Scale { factor } => (factor - 1.0).abs() * max_coord,
            AttackKind::Stealthy {
                max_rate, max_bias, ..
            } => {
                let r = max_rate.abs() * span;
                max_bias.map_or(r, |c| r.min(c.abs()))
            }
            AttackKind::Coordinated { velocity, cap } => {
                let v = velocity.iter().map(|x| x * x).sum::<f64>().sqrt();
                let r = v * span;
                cap.map_or(r, |c| r.min(c.abs()))
            }
            AttackKind::Dropout {}
            | AttackKind::NonFinite { .. }
            | AttackKind::Absurd { .. }
            | AttackKind::Spikes { .. } => 0.0,
        };
        let r = if matches!(a.kind, AttackKind::Coordinated { .. }) {
            per_axis
        } else {
            per_axis * f64::from(u8::from(kinds[0]) + u8::from(kinds[1])).sqrt()
        };
        let r = if turned {
            speed * r.min(std::f64::consts::PI).sin().abs().max(r.min(1.0)) * span
        } else if integrated {
            r * span
        } else {
            r
        };
        if (turned || integrated) && r > 0.0 {
            exact = false;
        }
        if r > 0.0 {
            reach = reach.max(r);
        }
    }
    Reach { reach, axes, exact }
}

/// What [`declared_reach`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    /// The largest offset of a position fix \[m\].
    pub reach: f64,
    /// The axes it can move (x, y).
    pub axes: [bool; 2],
    /// The offset is the fix's own (a position channel): the spoofed estimate sits there. Not
    /// exact when it is integrated from a velocity or heading: the filters then place the
    /// estimate anywhere up to it, so the worst one Step 2 keeps sits just inside θ.
    pub exact: bool,
}

impl<'a> Model<'a> {
    fn new(world: &'a World, setup: &'a ControlSetup) -> Option<Self> {
        let cfg = &setup.config;
        let q = cfg.model.channels();
        let m = cfg.fault_patterns.len();
        let units: Vec<Unit> = match cfg.kind {
            ControllerKind::Nominal => return None,
            ControllerKind::FtCbfClf => (0..m)
                .map(|i| {
                    let mask = channel_mask(q, &cfg.fault_patterns, &[i]);
                    unit(world, setup, mask, setup.params.gamma[i])
                })
                .collect(),
            ControllerKind::Baseline => vec![unit(
                world,
                setup,
                vec![true; q],
                setup.params.gamma_baseline,
            )],
        };
        let x0 = cfg.x0;
        let mut path = vec![[x0[0], x0[1]]];
        let (goal, goal_radius) = match &cfg.form {
            ProblemForm::SafetyFilter { tracker, .. } => {
                path.extend(tracker.waypoints.iter().copied());
                (tracker.goal, tracker.goal_radius)
            }
            ProblemForm::Paper => {
                path.extend(world.file.goal.waypoints.iter().copied());
                (world.file.goal.center, world.file.goal.radius)
            }
        };
        path.push(goal);
        let max_coord = path
            .iter()
            .map(|p| p[0].abs().max(p[1].abs()))
            .fold(0.0, f64::max);
        // The declared attack: which pattern, which units it moves (those that read it).
        let attacked = attacked_pattern_of(world, setup);
        let axes = declared_reach(world, 0.0, 0.0, max_coord).axes;
        let speed = match &cfg.form {
            ProblemForm::SafetyFilter { tracker, .. } => tracker.cruise_speed,
            ProblemForm::Paper => crate::runner::setup::speed_bound(world).unwrap_or(0.2),
        } * NOMINAL_SPEED_SHARE;
        let spoofed = match (cfg.kind, attacked) {
            (ControllerKind::FtCbfClf, Some(a)) => {
                (0..m).filter(|&i| i != a).map(|i| (i, a)).collect()
            }
            (ControllerKind::Baseline, Some(a)) => vec![(0, a)],
            _ => Vec::new(),
        };
        let attack_name = world
            .file
            .attacks
            .iter()
            .map(|a| format!("{} on {}", a.kind.name(), a.channels.join("+")))
            .collect::<Vec<_>>()
            .join(", ");
        let mut model = Self {
            setup,
            units,
            spoofed,
            path,
            goal,
            goal_radius,
            patterns: m,
            axes,
            speed,
            max_coord,
            attack_name,
            world,
            response: None,
        };
        model.response = model.responses();
        Some(model)
    }

    /// Each spoofed unit's estimate offset at every control step, exact by linearity: a
    /// steady-state Kalman filter's estimate moves by its own response to the offsets the attack
    /// adds to its readings (`update_gains`), whatever the state and the input, so the offset
    /// is that response to [`open_loop_offset`] along the planned timeline ([`Model::truth_at`]).
    /// A position fix attacked in a filter that also reads velocity is pulled back by it, a
    /// velocity offset in one that reads positions stays bounded, a scale follows the true
    /// coordinate where the robot is. `None` (the bound of [`declared_reach`] is used instead)
    /// when an attacked sensor is not a position or velocity fix or a speed the filters read as
    /// world velocity, or when a spoofed filter has no steady state.
    fn responses(&self) -> Option<Vec<Vec<[f64; 2]>>> {
        let f = &self.world.file;
        if f.attacks.is_empty() || self.spoofed.is_empty() {
            return None;
        }
        for a in &f.attacks {
            for c in &a.channels {
                let s = f.sensors.iter().find(|s| &s.name == c)?;
                let direct = matches!(
                    s.measures,
                    Quantity::X | Quantity::Y | Quantity::Vx | Quantity::Vy
                );
                if !(direct || (s.measures == Quantity::Speed && s.world_velocity)) {
                    return None;
                }
            }
        }
        let cfg = &self.setup.config;
        let gains = self
            .spoofed
            .iter()
            .map(|&(ui, _)| {
                let u = &self.units[ui];
                Some(update_gains(&cfg.model, &u.mask, u.prior.as_ref()?))
            })
            .collect::<Option<Vec<_>>>()?;
        let dt = self.world.control_dt();
        let n = (f.duration / dt).ceil() as usize + 1;
        let phi = cfg.model.discretize(dt).phi;
        let q = cfg.model.channels();
        let mut e = vec![State::zeros(); gains.len()];
        let mut out = vec![Vec::with_capacity(n); gains.len()];
        let mut d = vec![0.0; q];
        // Per channel: its sensor, and the attacks on it with the channel's place in each.
        let on_channel: Vec<_> = (0..q)
            .map(|ch| {
                let s = &f.sensors[self.setup.sensor_of_channel[ch]];
                let hits: Vec<_> = f
                    .attacks
                    .iter()
                    .filter_map(|a| Some((a, a.channels.iter().position(|c| c == &s.name)?)))
                    .collect();
                (s, hits)
            })
            .collect();
        for k in 0..n {
            let t = k as f64 * dt;
            // The heading a `speed` channel is read along: the path's direction now.
            let heading = self.truth_at(t).1;
            for ((ch, dk), (s, hits)) in d.iter_mut().enumerate().zip(&on_channel) {
                let truth = |tt: f64| {
                    let (p, tan, v) = self.truth_at(tt);
                    match s.measures {
                        Quantity::X => p[0],
                        Quantity::Y => p[1],
                        Quantity::Vx => v * tan[0],
                        Quantity::Vy => v * tan[1],
                        _ => v,
                    }
                };
                let off: f64 = hits
                    .iter()
                    .map(|&(a, j)| open_loop_offset(a, j, t, &truth))
                    .sum();
                *dk = if s.measures == Quantity::Speed {
                    // Read as world velocity along the heading.
                    off * if cfg.model.c[ch][2] != 0.0 {
                        heading[0]
                    } else {
                        heading[1]
                    }
                } else {
                    off
                };
            }
            for ((ek, g), o) in e.iter_mut().zip(&gains).zip(out.iter_mut()) {
                let mut x = phi * *ek;
                for (ch, kg, ikc) in g {
                    x = ikc * x + kg * d[*ch];
                }
                *ek = x;
                o.push([x[0], x[1]]);
            }
        }
        Some(out)
    }

    /// Where the robot is assumed at time `t` on the planned timeline (still for
    /// [`START_DELAY`], then along the path at `speed`, then at the goal): position, the path's
    /// direction there (the heading), and speed.
    fn truth_at(&self, t: f64) -> ([f64; 2], [f64; 2], f64) {
        let along = ((t - START_DELAY) * self.speed).max(0.0);
        let moving = t > START_DELAY && along < self.length();
        let mut rest = along;
        let mut last = ([self.path[0][0], self.path[0][1]], [1.0, 0.0]);
        for w in self.path.windows(2) {
            let (a, b) = (w[0], w[1]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            if len < 1e-9 {
                continue;
            }
            let tan = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
            if rest <= len {
                let p = [a[0] + tan[0] * rest, a[1] + tan[1] * rest];
                return (p, tan, if moving { self.speed } else { 0.0 });
            }
            rest -= len;
            last = (b, tan);
        }
        (last.0, last.1, 0.0)
    }

    /// The estimates' offsets to try at time `t`: none without attack; under it, the exact
    /// response where there is one, else every direction of the declared reach for every
    /// spoofed unit.
    fn scenarios_at(&self, t: f64, attack: bool) -> Vec<Offsets> {
        let zero = vec![[0.0, 0.0]; self.units.len()];
        if !attack {
            return vec![zero];
        }
        if let Some(resp) = &self.response {
            let mut v = zero;
            for (&(ui, _), r) in self.spoofed.iter().zip(resp) {
                let k = ((t / self.world.control_dt()).round().max(0.0) as usize)
                    .min(r.len().saturating_sub(1));
                v[ui] = r.get(k).copied().unwrap_or([0.0, 0.0]);
            }
            return vec![v];
        }
        offsets(self.axes, self.reach_at(t))
            .into_iter()
            .map(|o| {
                let mut v = zero.clone();
                for &(ui, _) in &self.spoofed {
                    v[ui] = o;
                }
                v
            })
            .collect()
    }

    /// The rows `a·u ≤ b` (unit normals) of every unit at its estimate, with the barrier index
    /// of each, for κ and a given offset of the spoofed units.
    fn rows(
        &self,
        p: [f64; 2],
        offsets: &[[f64; 2]],
        t: f64,
        kappa: f64,
        out: &mut Vec<(HalfSpace, usize, f64)>,
    ) {
        out.clear();
        let cfg = &self.setup.config;
        for (ui, u) in self.units.iter().enumerate() {
            let off = offsets[ui];
            // Step 2 drops an estimate farther than θ_ia(t) from the honest one (the baseline
            // has no Step 2).
            if let Some(&(i, a)) = self.spoofed.iter().find(|(i, _)| *i == ui) {
                if cfg.kind == ControllerKind::FtCbfClf
                    && off[0].hypot(off[1]) > theta_at(self.setup, self.patterns, i, a, t)
                {
                    continue;
                }
            }
            let x = State::new(p[0] + off[0], p[1] + off[1], 0.0, 0.0);
            for (bi, b) in cfg.barriers.iter().enumerate() {
                let eval = b.eval(&x);
                let h_bar = b.h_bar(u.gamma);
                if eval.value - h_bar >= cfg.delta {
                    continue;
                }
                let row = cbf_row(&cfg.model, &eval, &x, &u.m, &u.n, u.gamma, h_bar, kappa);
                out.push((row.half_space(), bi, row.omega_bar));
            }
        }
    }
}

impl Model<'_> {
    /// The best acceleration along `t` the rows allow at rest at `p` or beside it: the robot
    /// does not hold the path exactly (the rows themselves push it sideways), so every point
    /// across the path within [`LATERAL_REACH`] that it can slide to without touching an
    /// obstacle (h ≥ 0 all the way, true position) is tried, nearest first. `Ok` with the first
    /// acceleration ≥ [`MIN_PROGRESS`] and where; `Err` with what blocks the path point itself.
    fn progress_near(
        &self,
        p: [f64; 2],
        t: [f64; 2],
        o: &[[f64; 2]],
        time: f64,
        (kappa, limit): (f64, Option<Input>),
        rows: &mut Vec<(HalfSpace, usize, f64)>,
    ) -> Result<(f64, [f64; 2]), Blocked> {
        let nrm = [-t[1], t[0]];
        let steps = (LATERAL_REACH / LATERAL_STEP).round() as i32;
        let mut first: Option<Blocked> = None;
        let mut open = [true, true];
        for k in 0..=steps {
            for (side, sign) in [(0usize, 1.0), (1usize, -1.0)] {
                if k == 0 && side == 1 {
                    continue;
                }
                if !open[side] {
                    continue;
                }
                let d = sign * f64::from(k) * LATERAL_STEP;
                let q = [p[0] + d * nrm[0], p[1] + d * nrm[1]];
                if k > 0 && !self.clear(q) {
                    open[side] = false;
                    continue;
                }
                self.rows(q, o, time, kappa, rows);
                match best_along(rows, limit, t) {
                    Some(a) if a >= MIN_PROGRESS => return Ok((a, q)),
                    Some(a) => {
                        first.get_or_insert(Blocked::NoProgress(a));
                    }
                    None => {
                        first.get_or_insert(Blocked::Infeasible);
                    }
                }
            }
        }
        Err(first.unwrap_or(Blocked::Infeasible))
    }

    /// The true position `q` (at rest) is inside every safe set and clear of every obstacle.
    fn clear(&self, q: [f64; 2]) -> bool {
        let x = State::new(q[0], q[1], 0.0, 0.0);
        self.setup
            .config
            .barriers
            .iter()
            .all(|b| b.eval(&x).value >= 0.0)
    }
}

impl Model<'_> {
    /// When the robot is assumed to reach `along` metres of the path \[s\].
    fn time_at(&self, along: f64) -> f64 {
        START_DELAY + along / self.speed.max(1e-3)
    }

    /// The spoofed estimates' offset at time `t` \[m\] (see [`Reach::exact`]).
    fn reach_at(&self, t: f64) -> f64 {
        let r = declared_reach(self.world, t, self.speed, self.max_coord);
        if r.exact {
            return r.reach;
        }
        r.reach.min(self.theta_max(t) * (1.0 - 1e-9))
    }

    /// The largest θ_ia(t) over the spoofed units.
    fn theta_max(&self, t: f64) -> f64 {
        self.spoofed
            .iter()
            .map(|&(i, a)| theta_at(self.setup, self.patterns, i, a, t))
            .fold(0.0, f64::max)
    }

    /// Length of the path \[m\].
    fn length(&self) -> f64 {
        self.path
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .sum()
    }
}

/// The declared attack's pattern (the one containing every attacked channel), if any.
fn attacked_pattern_of(world: &World, setup: &ControlSetup) -> Option<usize> {
    let f = &world.file;
    let mut attacked: Vec<usize> = Vec::new();
    for a in &f.attacks {
        for c in &a.channels {
            if let Some(si) = f.sensors.iter().position(|s| &s.name == c) {
                for (ch, &s) in setup.sensor_of_channel.iter().enumerate() {
                    if s == si && !attacked.contains(&ch) {
                        attacked.push(ch);
                    }
                }
            }
        }
    }
    if attacked.is_empty() {
        return None;
    }
    let pats = &setup.config.fault_patterns;
    pats.iter()
        .position(|p| attacked.iter().all(|c| p.contains(c)))
        .or_else(|| {
            pats.iter()
                .position(|p| attacked.iter().any(|c| p.contains(c)))
        })
}

/// The largest `dir·u` over `{u : rows, |u_k| ≤ L_k}` (None: empty), by vertex enumeration.
fn best_along(
    rows: &[(HalfSpace, usize, f64)],
    limit: Option<Input>,
    dir: [f64; 2],
) -> Option<f64> {
    let l = limit.map_or([1e6, 1e6], |l| [l[0], l[1]]);
    let mut lines: Vec<([f64; 2], f64)> = Vec::with_capacity(rows.len() + 4);
    for (h, _, _) in rows {
        let n = h.normal.norm();
        if !(n.is_finite() && h.offset.is_finite()) {
            return None;
        }
        if n < 1e-12 {
            if h.offset < 0.0 {
                return None;
            }
            continue;
        }
        lines.push(([h.normal[0] / n, h.normal[1] / n], h.offset / n));
    }
    lines.push(([1.0, 0.0], l[0]));
    lines.push(([-1.0, 0.0], l[0]));
    lines.push(([0.0, 1.0], l[1]));
    lines.push(([0.0, -1.0], l[1]));
    let scale = lines.iter().map(|(_, b)| b.abs()).fold(1.0, f64::max);
    let tol = 1e-9 * scale;
    let mut best: Option<f64> = None;
    for i in 0..lines.len() {
        for j in (i + 1)..lines.len() {
            let (a1, b1) = lines[i];
            let (a2, b2) = lines[j];
            let det = a1[0] * a2[1] - a1[1] * a2[0];
            if det.abs() < 1e-12 {
                continue;
            }
            let u = [
                (b1 * a2[1] - b2 * a1[1]) / det,
                (a1[0] * b2 - a2[0] * b1) / det,
            ];
            if lines
                .iter()
                .all(|(a, b)| a[0] * u[0] + a[1] * u[1] - b <= tol)
            {
                let v = dir[0] * u[0] + dir[1] * u[1];
                best = Some(best.map_or(v, |b: f64| b.max(v)));
            }
        }
    }
    best
}

/// The path sampled every [`SAMPLE_STEP`] m: (point, unit tangent, distance along), the goal
/// itself excluded (it is judged by holding).
fn samples(path: &[[f64; 2]]) -> Vec<([f64; 2], [f64; 2], f64)> {
    let mut out = Vec::new();
    let mut along = 0.0;
    for w in path.windows(2) {
        let (a, b) = (w[0], w[1]);
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        if len < 1e-9 {
            continue;
        }
        let t = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
        let n = (len / SAMPLE_STEP).ceil() as usize;
        for k in 0..n {
            let s = k as f64 * len / n as f64;
            out.push(([a[0] + t[0] * s, a[1] + t[1] * s], t, along + s));
        }
        along += len;
    }
    out
}

fn offsets(axes: [bool; 2], reach: f64) -> Vec<[f64; 2]> {
    if reach <= 0.0 {
        return vec![[0.0, 0.0]];
    }
    let r = if reach.is_finite() { reach } else { 1e3 };
    match axes {
        [true, false] => vec![[r, 0.0], [-r, 0.0]],
        [false, true] => vec![[0.0, r], [0.0, -r]],
        _ => (0..DIRECTIONS)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / DIRECTIONS as f64;
                [r * a.cos(), r * a.sin()]
            })
            .collect(),
    }
}

/// One case for κ and the box: without attack (`attack = false`), or under the declared attack
/// with the spoofed estimates where the attack has moved them when the robot gets there.
fn case(
    model: &Model,
    name: String,
    attack: bool,
    kappa: f64,
    limit: Option<Input>,
) -> LivenessCase {
    let offs_at = |t: f64| model.scenarios_at(t, attack);
    // The largest offset of a scenario, and that offset.
    let largest = |o: &[[f64; 2]]| {
        o.iter()
            .copied()
            .max_by(|a, b| a[0].hypot(a[1]).total_cmp(&b[0].hypot(b[1])))
            .unwrap_or([0.0, 0.0])
    };
    let mut applied: f64 = 0.0;
    let mut rows = Vec::new();
    let mut least = (f64::INFINITY, model.path[0]);
    let mut stall = None;
    'path: for (p, t, along) in samples(&model.path) {
        let time = model.time_at(along);
        for o in offs_at(time) {
            let big = largest(&o);
            let r = big[0].hypot(big[1]);
            if r <= model.theta_max(time) {
                applied = applied.max(r);
            }
            match model.progress_near(p, t, &o, time, (kappa, limit), &mut rows) {
                Ok((a, q)) => {
                    if a < least.0 {
                        least = (a, q);
                    }
                }
                Err(blocked) => {
                    model.rows(p, &o, time, kappa, &mut rows);
                    stall = Some(Stall {
                        at: p,
                        along,
                        blocked,
                        binding: binding(model, &rows),
                        offset: big,
                    });
                    break 'path;
                }
            }
        }
    }
    // Holding: u = 0 satisfies every row at rest at some point of the goal set, at every time
    // from the robot's arrival to the end of the run.
    let arrive = model.time_at(model.length()).min(model.world.file.duration);
    let n_hold = ((model.world.file.duration - arrive) / HOLD_STEP)
        .ceil()
        .max(0.0) as u32;
    let times: Vec<f64> = (0..=n_hold)
        .map(|k| (arrive + f64::from(k) * HOLD_STEP).min(model.world.file.duration))
        .collect();
    let mut holds_at = |g: [f64; 2]| {
        times.iter().all(|&t| {
            offs_at(t).iter().all(|o| {
                model.rows(g, o, t, kappa, &mut rows);
                rows.iter()
                    .all(|(h, _, _)| h.offset.is_finite() && h.offset >= -1e-12)
            })
        })
    };
    let mut goal_holds = holds_at(model.goal);
    if !goal_holds {
        let r = model.goal_radius * 0.8;
        'ring: for ring in [0.5, 1.0] {
            for k in 0..16 {
                let a = std::f64::consts::TAU * f64::from(k) / 16.0;
                let g = [
                    model.goal[0] + ring * r * a.cos(),
                    model.goal[1] + ring * r * a.sin(),
                ];
                if holds_at(g) {
                    goal_holds = true;
                    break 'ring;
                }
            }
        }
    }
    LivenessCase {
        name,
        reach: applied,
        stall,
        least_progress: least,
        goal_holds,
    }
}

/// The barriers whose rows demand a push (ω̄ > 0), most demanding first, each named once.
fn binding(model: &Model, rows: &[(HalfSpace, usize, f64)]) -> Vec<String> {
    let mut v: Vec<(f64, usize)> = rows
        .iter()
        .filter(|(_, _, w)| *w > 0.0 || !w.is_finite())
        .map(|(_, b, w)| (*w, *b))
        .collect();
    v.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut names: Vec<String> = Vec::new();
    for (_, b) in v {
        let n = model.setup.config.barriers[b].name().to_string();
        if !names.contains(&n) {
            names.push(n);
        }
    }
    names
}

fn cases(model: &Model, kappa: f64, limit: Option<Input>) -> Vec<LivenessCase> {
    let mut out = vec![case(model, "without attack".into(), false, kappa, limit)];
    if !model.spoofed.is_empty() && !model.world.file.attacks.is_empty() {
        out.push(case(
            model,
            format!("under the declared attack ({})", model.attack_name),
            true,
            kappa,
            limit,
        ));
    }
    out
}

/// Values of κ tried by `smallest_fix` (each at most [`kappa_max`]).
pub const KAPPA_CANDIDATES: [f64; 6] = [10.0, 12.5, 15.0, 20.0, 25.0, 30.0];

/// Input limits tried by `smallest_fix` [m/s²].
pub const LIMIT_CANDIDATES: [f64; 6] = [0.75, 1.0, 1.25, 1.5, 2.0, 2.5];

/// The largest κ the rows may use at the world's control rate: κ·dt ≤ 1/2, so that one control
/// period cannot take ĥ from its value past zero (the condition is imposed on a sampled
/// system: with κ·dt → 1 the sampled input already acts on the whole margin in one step).
pub fn kappa_max(world: &World) -> f64 {
    0.5 / world.control_dt()
}

/// Predict liveness for `world` with its controller configuration (see the module docs).
pub fn predict(world: &World, setup: &ControlSetup) -> LivenessReport {
    let cfg = &setup.config;
    let Some(model) = Model::new(world, setup) else {
        return LivenessReport {
            kappa: cfg.cbf_gain,
            path_length: 0.0,
            samples: 0,
            cases: Vec::new(),
            fix: None,
            structural: Vec::new(),
            skipped: Some("the nominal controller imposes no rows".into()),
        };
    };
    let path_length = model.length();
    let n_samples = samples(&model.path).len();
    let cases = cases(&model, cfg.cbf_gain, cfg.input_limit);
    let live = cases.iter().all(LivenessCase::live);
    let mut structural = Vec::new();
    let fix = if live {
        None
    } else {
        smallest_fix(world, &model, cfg.cbf_gain, cfg.input_limit)
    };
    if !live {
        structural_notes(&model, &cases, &mut structural);
    }
    LivenessReport {
        kappa: cfg.cbf_gain,
        path_length,
        samples: n_samples,
        cases,
        fix,
        structural,
        skipped: None,
    }
}

/// The smallest change of one `[control]` key that makes every case live: κ up to
/// `kappa_max` first (it costs nothing physical), then the input box up to 2.5 m/s².
fn smallest_fix(world: &World, model: &Model, kappa: f64, limit: Option<Input>) -> Option<Fix> {
    let kmax = kappa_max(world);
    for &k in KAPPA_CANDIDATES.iter().filter(|&&k| k > kappa && k <= kmax) {
        if cases(model, k, limit).iter().all(LivenessCase::live) {
            return Some(Fix {
                key: "control.cbf_gain".into(),
                value: k,
            });
        }
    }
    let current = limit.map_or(f64::INFINITY, |l| l[0].max(l[1]));
    for &l in LIMIT_CANDIDATES.iter().filter(|&&l| l > current) {
        if cases(model, kappa, Some(Input::new(l, l)))
            .iter()
            .all(LivenessCase::live)
        {
            return Some(Fix {
                key: "control.input_limit".into(),
                value: l,
            });
        }
    }
    None
}

/// What no `[control]` key changes: a spoofed estimate that Step 2 can only drop beyond a θ
/// larger than the passage (a pair filter with no channel of its own).
fn structural_notes(model: &Model, cases: &[LivenessCase], out: &mut Vec<String>) {
    let under_attack_only = cases.first().is_some_and(LivenessCase::live);
    if !under_attack_only {
        return;
    }
    let worst_theta = model.theta_max(model.world.file.duration);
    let reach = cases.iter().map(|c| c.reach).fold(0.0, f64::max);
    if worst_theta > 1.0 {
        out.push(format!(
            "Step 2 can isolate the spoofed filters only beyond θ = {worst_theta:.3} m, so the attack's {reach:.3} m offset is never isolated: the robot cannot tell which estimate is honest and keeps clear of both. Give the pair filters a channel of their own (wheel odometry or encoders with a heading, or a third receiver) so that θ shrinks"
        ));
    } else {
        out.push(format!(
            "the passage is narrower than the robot plus the spread Step 2 tolerates (θ up to {worst_theta:.3} m): widen it, or lower θ with more precise or more redundant sensors"
        ));
    }
}

/// Why a run ended outside its goal, in one line, with what `check` predicted (None when the
/// run settled in its goal): where the robot stopped, how far from the goal, how many steps
/// were infeasible or had Step 3 keep a saturated estimator, how often the tracker saw a stall,
/// and the liveness verdict for the world with `setup`'s controller.
pub fn explain_run(world: &World, setup: &ControlSetup, s: &RunSummary) -> Option<String> {
    if s.goal_settled {
        return None;
    }
    let what = if s.goal_reached {
        "entered but did not settle in its goal"
    } else {
        "did not reach its goal"
    };
    let steps = s.control_steps.max(1);
    let report = predict(world, setup);
    Some(format!(
        "why: the robot {what}: it ended at ({:.2}, {:.2}), {:.2} m from the goal's centre; {} of {steps} steps infeasible ({:.0} %), Step 3 kept a saturated estimator {} times, the tracker saw {} stall(s). check predicted: {}",
        s.final_state[0],
        s.final_state[1],
        s.final_goal_distance,
        s.steps.infeasible,
        100.0 * s.steps.infeasible as f64 / steps as f64,
        s.fail_closed.step3_saturated_steps,
        s.smoothness.stalls,
        report.line()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(n: [f64; 2], o: f64) -> (HalfSpace, usize, f64) {
        (
            HalfSpace {
                normal: Input::new(n[0], n[1]),
                offset: o,
            },
            0,
            -o,
        )
    }

    #[test]
    fn best_along_is_the_lp_optimum_in_the_box() {
        // u_x ≤ 0.3 and the box 1: best along +x is 0.3, along +y is 1.
        let rows = [row([1.0, 0.0], 0.3)];
        let l = Some(Input::new(1.0, 1.0));
        assert!((best_along(&rows, l, [1.0, 0.0]).unwrap() - 0.3).abs() < 1e-12);
        assert!((best_along(&rows, l, [0.0, 1.0]).unwrap() - 1.0).abs() < 1e-12);
        // u_x ≥ 0.5 (−u_x ≤ −0.5): best along −x is −0.5 (a push back).
        let rows = [row([-1.0, 0.0], -0.5)];
        assert!((best_along(&rows, l, [-1.0, 0.0]).unwrap() + 0.5).abs() < 1e-12);
        // u_x ≥ 1.5 is outside the box: infeasible.
        let rows = [row([-1.0, 0.0], -1.5)];
        assert_eq!(best_along(&rows, l, [1.0, 0.0]), None);
        // a non-finite row fails closed.
        let rows = [row([f64::NAN, 0.0], 0.0)];
        assert_eq!(best_along(&rows, l, [1.0, 0.0]), None);
        // two rows: u_x + u_y ≤ 0, u_x − u_y ≤ 0 → best along +x is 0 (at u = 0)... and along
        // −x the box edge, 1.
        let rows = [row([1.0, 1.0], 0.0), row([1.0, -1.0], 0.0)];
        assert!(best_along(&rows, l, [1.0, 0.0]).unwrap().abs() < 1e-12);
        assert!((best_along(&rows, l, [-1.0, 0.0]).unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn samples_cover_the_path_every_step() {
        let s = samples(&[[0.0, 0.0], [1.0, 0.0], [1.0, 0.5]]);
        assert_eq!(s.len(), 20 + 10);
        assert!((s[25].2 - 1.25).abs() < 1e-12);
        assert_eq!(s[25].1, [0.0, 1.0]);
    }

    #[test]
    fn offsets_follow_the_attacked_axes() {
        assert_eq!(offsets([false, true], 0.3), vec![[0.0, 0.3], [0.0, -0.3]]);
        assert_eq!(offsets([true, true], 0.3).len(), DIRECTIONS);
        assert_eq!(offsets([true, true], 0.0), vec![[0.0, 0.0]]);
    }
}

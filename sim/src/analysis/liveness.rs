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
//!   the rows can hold the robot; `model::setup`), or start → waypoints → goal for the paper
//!   form; sampled every [`SAMPLE_STEP`] m (at most [`MAX_SAMPLES`] points: coarser on a path over 1 km);
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
use ftcbf_controller::estimator::{chi_square_z, RESIDUE_WINDOW};
use ftcbf_controller::params::{
    gain_product, horizon_posterior_max, pair_slot, steady_state_riccati, update_gains, FtParams,
};
use ftcbf_controller::{Input, State, StateMatrix};

use crate::attacks::{open_loop_offset, AttackKind, AttackSpec, StealthyPlay};
use crate::model::setup::{channel_mask, initial_covariance, ControlSetup};
use crate::sensors::{ChannelSpec, Quantity};
use crate::summary::{RunSummary, SETTLE_WINDOW};
use crate::world::World;
use rand::SeedableRng;
use rand_chacha::ChaCha20Rng;
use rand_distr::{Distribution, StandardNormal};

/// Spacing of the path samples \[m\], on paths up to [`MAX_SAMPLES`] · this long (1 km).
pub const SAMPLE_STEP: f64 = 0.05;

/// The most path samples: a longer path is sampled every length / this (a 28 km path of far
/// waypoints took 7 s of one core per pass at 5 cm, and `check` makes several). The header line
/// gives the path's length and the number of points, so the spacing is always stated.
pub const MAX_SAMPLES: usize = 20_000;

/// The box [m/s²] that stands for "no `input_limit`" in the search for the best acceleration
/// along the path.
const NO_LIMIT_BOX: f64 = 1e6;

/// A least acceleration along the path at or above this [m/s²] is the stand-in box of a world
/// without `input_limit`, not a bound of the rows: reported as unbounded, not as a number.
const UNBOUNDED_PROGRESS: f64 = NO_LIMIT_BOX / 10.0;

/// The least acceleration along the path [m/s²] the rows must leave for the robot to be
/// predicted to move on (below it, the tracker's u_nom is projected to a standstill).
pub const MIN_PROGRESS: f64 = 0.02;

/// The share of the tracker's cruise speed the robot is assumed to make on average along its
/// planned path, for when it reaches each point of the path (and so what an attack has done to
/// the estimates by then). Measured: path length / (time to enter the goal − 1 s) / cruise
/// speed over the 96 generated worlds of `scripts/gen_sweep.sh 3 100 20` whose trials entered
/// the goal had median 1.03, 10th percentile 0.98, 90th 1.07 (the tracker holds its cruise
/// speed and cuts corners of the planned path). 0.6, the guess it replaced, put the robot at
/// an attack's worst minutes later than it is and predicted stalls that never happened.
pub const NOMINAL_SPEED_SHARE: f64 = 1.0;

/// Seconds before the robot is assumed to start along the path.
const START_DELAY: f64 = 1.0;

/// Spacing of the times, from the robot's arrival to the end of the run, at which holding is
/// judged [s] (an attack's offset can sweep a spoofed estimate across a thin wall in less).
const HOLD_STEP: f64 = 0.1;

/// How far an attack must raise a spoofed unit's windowed χ² score (≈ N(0, 1) when honest)
/// for Step 3's ranking to put it after the honest unit nearly always: the difference of two
/// such scores has standard deviation √2, so a shift of 3 ranks it last in ≈ 98 % of steps.
const RANKING_SHIFT: f64 = 3.0;

/// The stretch at the end of the run over which the goal must be holdable \[s\]: the last
/// [`SETTLE_WINDOW`] that `settled` is judged on and as long again before it, for a robot that
/// a passing offset pushed out to come back (at cruise speed it covers ≥ 0.4 m in 2 s).
pub const HOLD_WINDOW: f64 = 2.0 * SETTLE_WINDOW;

/// Steps of the wait at a blocked point for a time-varying offset to pass \[s\].
const WAIT_STEP: f64 = 0.5;

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
    /// Where the tracker may settle off its goal: the largest offset \[m\] of a spoofed estimate
    /// that Step 2 cannot isolate over the run's last [`SETTLE_WINDOW`] (so Step 3's ranking
    /// may pick it for u_nom), when it exceeds the goal's radius, with the θ \[m\] it stays
    /// under (`+∞` for the baseline, which has no Step 2). Judged where the offsets are computed
    /// exactly (the filters' linear response), not from the declared reach's bound.
    pub misled: Option<(f64, f64)>,
    /// Path points where the rows of every unit together admit no input, but those of the
    /// units the attack does not move do: the robot passes only if Step 3 drops the spoofed
    /// units there (it ranks them by residue).
    pub through_step3: usize,
    /// The first point where the rows of every unit together admit no input (a stall, or a point
    /// passed only through Step 3): where case (i) of Theorem 3's proof fails.
    pub joint_infeasible: Option<Stall>,
    /// How long in all the robot waits for an attack's offset to pass before it can go on \[s\],
    /// and where it first waits.
    pub waited: Option<(f64, [f64; 2])>,
}

impl LivenessCase {
    /// Path live, goal held, and no spoofed estimate the tracker may follow off the goal.
    pub fn live(&self) -> bool {
        self.stall.is_none() && self.goal_holds && self.misled.is_none()
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
    /// The goal's radius \[m\] (the tracker's settling tolerance).
    pub goal_radius: f64,
    /// Where the safe stop (`[control] fallback = "brake"`) is predicted to brake, and why, in
    /// one phrase: set by `check` ([`crate::analysis::safe_stop::predicted_stop_line`]) when a case has
    /// a point where no input meets every kept unit's rows and no pair filter can tell the two
    /// sources apart. The stop is a pause: whether the robot goes on from it is the walk's
    /// (a case that waits there and goes on stays live; one that stalls there stops short).
    pub safe_stop: Option<String>,
    /// Moving obstacles that stop across the path: the robot is blocked for good (issue #51).
    pub movers_blocked: Vec<String>,
    /// Moving obstacles the robot may wait for (they cross the path and move on).
    pub movers_wait: Vec<String>,
}

impl LivenessReport {
    /// Every case live (a skipped prediction counts as live: nothing holds the robot).
    pub fn live(&self) -> bool {
        self.cases.iter().all(LivenessCase::live) && self.movers_blocked.is_empty()
    }

    /// The verdict line.
    pub fn line(&self) -> String {
        if let Some(why) = &self.skipped {
            return format!("liveness not predicted: {why}");
        }
        if let Some(b) = self.movers_blocked.first() {
            return format!("the robot will NOT reach its goal: {b}");
        }
        let stop = self
            .safe_stop
            .as_ref()
            .map_or(String::new(), |stop| format!("; {stop}"));
        let Some(c) = self.cases.iter().find(|c| !c.live()) else {
            let mut s = format!(
                "live: the rows leave a forward input at every point of the {:.2} m path and hold the robot in its goal (κ = {}){stop}",
                self.path_length, (self.kappa * 1e3).round() / 1e3
            );
            for w in &self.movers_wait {
                s.push_str("; ");
                s.push_str(w);
            }
            return s;
        };
        let mut s = match &c.stall {
            // With the safe stop it brakes there (and says why below) rather than push on.
            Some(st) if self.safe_stop.is_some() => format!(
                "the robot may stop short of its goal {}: {}",
                c.name,
                stall_text(st)
            ),
            Some(st) => format!(
                "the robot will NOT reach its goal {}: {}",
                c.name,
                stall_text(st)
            ),
            None if !c.goal_holds => format!(
                "the robot can reach but NOT hold its goal {}: no point of the goal set admits rest under every row",
                c.name
            ),
            None => format!(
                "the robot may NOT settle in its goal {}: {}",
                c.name,
                misled_text(c.misled.unwrap_or_default(), self.goal_radius)
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
        s + &stop
    }
}

/// Why the tracker may settle off the goal, in one phrase.
fn misled_text((offset, theta): (f64, f64), radius: f64) -> String {
    let isolate = if theta.is_finite() {
        format!("Step 2 isolates a spoofed estimate only beyond θ = {theta:.3} m")
    } else {
        "the baseline has no Step 2 to isolate it".to_string()
    };
    format!(
        "in the run's last {SETTLE_WINDOW} s a spoofed estimate is {offset:.3} m off (the goal's radius is {radius:.3} m) and {isolate}, so u_nom may follow it and hold the robot that far from where it believes it is"
    )
}

/// Where and why a stall blocks the path, in one phrase.
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
            self.path_length, self.samples, (self.kappa * 1e3).round() / 1e3
        )?;
        for c in &self.cases {
            let tag = match (&c.stall, c.goal_holds, c.misled) {
                (Some(_), _, _) => "STALLS ",
                (None, false, _) => "NO HOLD",
                (None, true, Some(_)) => "OFF GOAL",
                (None, true, None) => "LIVE   ",
            };
            let body = match &c.stall {
                Some(st) => stall_text(st),
                None if c.least_progress.0 >= UNBOUNDED_PROGRESS => format!(
                    "a forward input at every point (no input_limit, and the rows bound the \
                     forward acceleration nowhere on the path; tightest at ({:.2}, {:.2}))",
                    c.least_progress.1[0], c.least_progress.1[1]
                ),
                None => format!(
                    "a forward input at every point (the rows leave at least {:.3} m/s² of \
                     acceleration along the path, least at ({:.2}, {:.2}))",
                    c.least_progress.0, c.least_progress.1[0], c.least_progress.1[1]
                ),
            };
            let reach = if c.reach > 0.0 {
                format!(" [spoofed estimates up to {:.3} m off]", c.reach)
            } else {
                String::new()
            };
            let step3 = if c.through_step3 > 0 {
                format!(
                    " ({} point(s) pass only if Step 3 drops the spoofed units there, by residue)",
                    c.through_step3
                )
            } else {
                String::new()
            };
            let step3 = match c.waited {
                Some((w, at)) => format!(
                    "{step3} (waits {w:.1} s at ({:.2}, {:.2}) for the attack's offset to pass)",
                    at[0], at[1]
                ),
                None => step3,
            };
            let settle = match c.misled {
                Some(m) => format!("; {}", misled_text(m, self.goal_radius)),
                None => String::new(),
            };
            writeln!(
                f,
                "  [{tag}] {}{reach}: {body}{step3}; goal {}{settle}",
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
    /// With `response`: what the attack adds, per spoofed unit and control step, to the
    /// filter's normalised innovations squared (Σ a²/S over its channels: an honest reading's
    /// e²/S has mean 1, a spoofed one's 1 + a²/S), and the channels the unit reads.
    response_nis: Option<Vec<(Vec<f64>, usize)>>,
}

/// The offsets of every unit's estimate [m], indexed like `Model::units`.
/// A filter's sequential updates: per used channel, its index, Kalman gain and I − K c.
type UpdateGains = Vec<(usize, State, StateMatrix)>;

/// A channel's sensor and the attacks on it: (attack index, attack, the channel's place in it).
type ChannelHits<'a> = (&'a ChannelSpec, Vec<(usize, &'a AttackSpec, usize)>);

/// What the attack offsets of `Model::responses` draw on: the detector a stealthy attacker
/// hides under, each stealthy attack's per-channel state, and the honest innovations' source
/// (seeded by the world).
struct OffsetSource {
    detector: Option<(UpdateGains, Vec<f64>)>,
    players: Vec<Vec<StealthyPlay>>,
    rng: ChaCha20Rng,
}

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

/// θ between units i and j after `t` seconds: the schedule θ_ij(t) where there is one, else
/// the constant θ_ij (or one value for all).
fn theta_at(setup: &ControlSetup, m: usize, i: usize, j: usize, t: f64) -> f64 {
    let scheduled = pair_slot(m, i, j).and_then(|slot| {
        setup
            .params
            .ft
            .theta_schedule
            .as_ref()
            .and_then(|s| s.at(slot, t))
    });
    scheduled
        .or_else(|| FtParams::per_pair(&setup.params.ft.theta, m, i, j))
        .unwrap_or(f64::INFINITY)
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
                    unit(world, setup, mask, setup.params.ft.gamma[i])
                })
                .collect(),
            ControllerKind::Baseline => vec![unit(
                world,
                setup,
                vec![true; q],
                setup.params.ft.gamma_baseline,
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
            ProblemForm::Paper => crate::world::structure::speed_bound(world).unwrap_or(0.2),
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
            response_nis: None,
        };
        if let Some((off, nis)) = model.responses() {
            model.response = Some(off);
            model.response_nis = Some(nis);
        }
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
    ///
    /// With each offset, what the attack adds to the unit's normalised innovations squared
    /// (the innovation a channel sees is the reading's offset minus the estimate's, c·x, before
    /// that channel's sequential update; S is its steady-state innovation variance): how far
    /// Step 3's χ² ranking can tell the spoofed unit from the honest one.
    #[allow(clippy::type_complexity)]
    fn responses(&self) -> Option<(Vec<Vec<[f64; 2]>>, Vec<(Vec<f64>, usize)>)> {
        let f = &self.world.file;
        if f.attacks.is_empty() || self.spoofed.is_empty() || !self.attacks_read_as_fixes() {
            return None;
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
        let variances = self.innovation_variances(&gains);
        let mut nis: Vec<(Vec<f64>, usize)> = gains
            .iter()
            .map(|g| (Vec::with_capacity(n), g.len()))
            .collect();
        let mut offsets = OffsetSource {
            detector: self.stealth_detector(),
            players: f
                .attacks
                .iter()
                .map(|a| vec![StealthyPlay::default(); a.channels.len()])
                .collect(),
            rng: ChaCha20Rng::seed_from_u64(f.seed ^ 0x5354_4541_4c54_4859),
        };
        let mut e_all = State::zeros();
        let on_channel = self.attacks_by_channel();
        for k in 0..n {
            let t = k as f64 * dt;
            let all_prior = phi * e_all;
            self.channel_offsets(t, all_prior, &on_channel, &mut offsets, &mut d);
            if let Some((g, _)) = &offsets.detector {
                let mut x = all_prior;
                for (ch, kg, ikc) in g {
                    x = ikc * x + kg * d[*ch];
                }
                e_all = x;
            }
            for (((ek, g), o), (ni, sv)) in e
                .iter_mut()
                .zip(&gains)
                .zip(out.iter_mut())
                .zip(nis.iter_mut().zip(&variances))
            {
                let mut x = phi * *ek;
                let mut a2 = 0.0;
                for ((ch, kg, ikc), s) in g.iter().zip(sv) {
                    let a = d[*ch] - (cfg.model.c[*ch] * x)[0];
                    a2 += a * a / s;
                    x = ikc * x + kg * d[*ch];
                }
                *ek = x;
                o.push([x[0], x[1]]);
                ni.0.push(a2);
            }
        }
        Some((out, nis))
    }

    /// Whether every attacked channel is a position or velocity fix, or a speed the filters
    /// read as world velocity (the only readings [`Self::responses`] can follow).
    fn attacks_read_as_fixes(&self) -> bool {
        let f = &self.world.file;
        f.attacks.iter().flat_map(|a| &a.channels).all(|c| {
            f.sensors.iter().find(|s| &s.name == c).is_some_and(|s| {
                direct_fix(s.measures) || (s.measures == Quantity::Speed && s.world_velocity)
            })
        })
    }

    /// Per spoofed unit, each sequential update's innovation variance S = c P cᵀ + r.
    fn innovation_variances(&self, gains: &[UpdateGains]) -> Vec<Vec<f64>> {
        let model = &self.setup.config.model;
        self.spoofed
            .iter()
            .zip(gains)
            .map(|(&(ui, _), g)| {
                let mut p = self.units[ui].prior.unwrap_or_default();
                g.iter()
                    .map(|(ch, kg, ikc)| {
                        let c = model.c[*ch];
                        let s = (c * p * c.transpose())[0] + model.r[*ch];
                        p = ikc * p * ikc.transpose() + kg * kg.transpose() * model.r[*ch];
                        s
                    })
                    .collect()
            })
            .collect()
    }

    /// A stealthy attacker hides under the all-channel filter's detector (as in a run): that
    /// filter's response to the attack, and its innovation std per channel, decide how far the
    /// bias can grow. `None` without a stealthy attack or when that filter has no prior.
    fn stealth_detector(&self) -> Option<(UpdateGains, Vec<f64>)> {
        let f = &self.world.file;
        let cfg = &self.setup.config;
        let q = cfg.model.channels();
        let stealthy = f
            .attacks
            .iter()
            .any(|a| matches!(a.kind, AttackKind::Stealthy { .. }));
        stealthy
            .then(|| {
                let all = unit(self.world, self.setup, vec![true; q], 0.0);
                let prior = all.prior?;
                let s: Vec<f64> = (0..q)
                    .map(|ch| {
                        let c = cfg.model.c[ch];
                        ((c * prior * c.transpose())[0] + cfg.model.r[ch]).sqrt()
                    })
                    .collect();
                Some((update_gains(&cfg.model, &all.mask, &prior), s))
            })
            .flatten()
    }

    /// Per channel: its sensor, and the attacks on it with the attack's index and the
    /// channel's place in it.
    fn attacks_by_channel(&self) -> Vec<ChannelHits<'_>> {
        let f = &self.world.file;
        (0..self.setup.config.model.channels())
            .map(|ch| {
                let s = &f.sensors[self.setup.sensor_of_channel[ch]];
                let hits: Vec<_> = f
                    .attacks
                    .iter()
                    .enumerate()
                    .filter_map(|(ai, a)| {
                        Some((ai, a, a.channels.iter().position(|c| c == &s.name)?))
                    })
                    .collect();
                (s, hits)
            })
            .collect()
    }

    /// Each channel's reading offset at `t` into `d`: the sum of the attacks on it, a stealthy
    /// one played against the detector's prior `all_prior` with a drawn honest innovation, and
    /// a `speed` reading turned into world velocity along the path's heading.
    fn channel_offsets(
        &self,
        t: f64,
        all_prior: State,
        on_channel: &[ChannelHits],
        src: &mut OffsetSource,
        d: &mut [f64],
    ) {
        let cfg = &self.setup.config;
        // The heading a `speed` channel is read along: the path's direction now.
        let heading = self.truth_at(t).1;
        for ((ch, dk), (s, hits)) in d.iter_mut().enumerate().zip(on_channel) {
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
            let mut off = 0.0;
            for &(ai, a, j) in hits {
                off += match (&a.kind, &src.detector) {
                    (AttackKind::Stealthy { .. }, Some((_, sd))) if direct_fix(s.measures) => {
                        let nu =
                            sd[ch] * Distribution::<f64>::sample(&StandardNormal, &mut src.rng);
                        let moved = (cfg.model.c[ch] * all_prior)[0];
                        src.players[ai][j].offset(a, j, t, nu, moved, sd[ch])
                    }
                    _ => open_loop_offset(a, j, t, &truth),
                };
            }
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
    }

    /// How far the attack moves the spoofed unit `k` (index into `spoofed`)'s windowed χ²
    /// score over the [`RESIDUE_WINDOW`] ending at `t`, in the score's own units (an honest
    /// filter's score is ≈ N(0, 1)): the attack's a²/S added to the window's expected sum.
    fn ranking_shift(&self, k: usize, t: f64) -> f64 {
        let Some((nis, channels)) = self.response_nis.as_ref().and_then(|v| v.get(k)) else {
            return 0.0;
        };
        let dt = self.world.control_dt();
        let end = ((t / dt).round().max(0.0) as usize).min(nis.len().saturating_sub(1));
        let len = ((RESIDUE_WINDOW / dt).round() as usize).max(1);
        let start = (end + 1).saturating_sub(len);
        let added: f64 = nis[start..=end].iter().sum();
        let dof = (len * channels) as u32;
        chi_square_z(f64::from(dof) + added, dof) - chi_square_z(f64::from(dof), dof)
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
            // Rows out of reach hold for every input of the box: they change neither the best
            // acceleration nor the rows that demand a push (issue #52, crate::active). A moving
            // obstacle's rows are not a place on the path: whether the robot waits for it or is
            // blocked for good is `crate::moving::liveness`'s.
            let far = crate::active::out_of_reach(cfg, &x, (&u.m, &u.n), u.gamma, kappa);
            for (bi, b) in cfg.barriers.iter().enumerate() {
                if far.get(bi) == Some(&true) || b.mover().is_some() {
                    continue;
                }
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
            .filter(|b| b.mover().is_none())
            .all(|b| b.eval(&x).value >= 0.0)
    }
}

impl Model<'_> {
    /// Whether the robot at rest at path point `p` (direction `t`) can go on at `time`, for
    /// every offset scenario of the case: `Ok` with the least progress, where, the largest
    /// spoofed offset, and — when the rows of every unit admit no input but Step 3 drops the
    /// spoofed units (their innovations give them away, [`RANKING_SHIFT`]) and the rest leave
    /// progress — the point as a joint-infeasible one; `Err` with the first blocking scenario.
    #[allow(clippy::type_complexity)]
    fn passable(
        &self,
        p: [f64; 2],
        t: [f64; 2],
        time: f64,
        attack: bool,
        (kappa, limit): (f64, Option<Input>),
        rows: &mut Vec<(HalfSpace, usize, f64)>,
    ) -> Result<(f64, [f64; 2], f64, Option<Stall>), Stall> {
        let mut worst: Option<(f64, [f64; 2])> = None;
        let mut big_r: f64 = 0.0;
        let mut step3 = None;
        for o in self.scenarios_at(time, attack) {
            let big = o
                .iter()
                .copied()
                .max_by(|a, b| a[0].hypot(a[1]).total_cmp(&b[0].hypot(b[1])))
                .unwrap_or([0.0, 0.0]);
            big_r = big_r.max(big[0].hypot(big[1]));
            let stall = |blocked: Blocked, rows: &mut Vec<(HalfSpace, usize, f64)>| {
                self.rows(p, &o, time, kappa, rows);
                Stall {
                    at: p,
                    along: 0.0,
                    blocked,
                    binding: binding(self, rows),
                    offset: big,
                }
            };
            let got = match self.progress_near(p, t, &o, time, (kappa, limit), rows) {
                Ok(x) => x,
                Err(Blocked::Infeasible)
                    if attack
                        && self.setup.config.kind == ControllerKind::FtCbfClf
                        && (0..self.spoofed.len())
                            .all(|k| self.ranking_shift(k, time) >= RANKING_SHIFT) =>
                {
                    // Step 3 drops units by residue, and the attack gives the spoofed ones away.
                    let joint = stall(Blocked::Infeasible, rows);
                    let honest = self.without_spoofed(&o);
                    match self.progress_near(p, t, &honest, time, (kappa, limit), rows) {
                        Ok(x) => {
                            step3.get_or_insert(joint);
                            x
                        }
                        Err(_) => return Err(joint),
                    }
                }
                Err(blocked) => return Err(stall(blocked, rows)),
            };
            if worst.is_none_or(|w| got.0 < w.0) {
                worst = Some(got);
            }
        }
        let (a, q) = worst.unwrap_or((f64::INFINITY, p));
        Ok((a, q, big_r, step3))
    }

    /// `o` with every spoofed unit dropped (an infinite offset: `rows` skips the unit, as Step
    /// 2 skips an isolated one).
    fn without_spoofed(&self, o: &[[f64; 2]]) -> Offsets {
        let mut v = o.to_vec();
        for &(ui, _) in &self.spoofed {
            v[ui] = [f64::INFINITY, f64::INFINITY];
        }
        v
    }

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

/// A position or velocity fix the filters read directly (no conversion).
fn direct_fix(q: Quantity) -> bool {
    matches!(q, Quantity::X | Quantity::Y | Quantity::Vx | Quantity::Vy)
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
    let l = limit.map_or([NO_LIMIT_BOX, NO_LIMIT_BOX], |l| [l[0], l[1]]);
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

/// The path sampled every [`SAMPLE_STEP`] m (every length / [`MAX_SAMPLES`] on a longer path):
/// (point, unit tangent, distance along), the goal itself excluded (it is judged by holding).
fn samples(path: &[[f64; 2]]) -> Vec<([f64; 2], [f64; 2], f64)> {
    let length = |w: &[[f64; 2]]| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
    let total: f64 = path.windows(2).map(length).filter(|l| l.is_finite()).sum();
    let step = SAMPLE_STEP.max(total / MAX_SAMPLES as f64);
    let mut out = Vec::new();
    let mut along = 0.0;
    for w in path.windows(2) {
        let (a, b) = (w[0], w[1]);
        let len = length(w);
        if len < 1e-9 {
            continue;
        }
        let t = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
        let n = (len / step).ceil() as usize;
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
/// with the spoofed estimates where the attack has moved them when the robot gets there. In
/// phases: the walk along the path, the reach while at the goal, whether the goal holds over
/// the hold period, and whether a spoofed estimate misleads the tracker as it settles (the
/// last two from one evaluation of the offsets at each hold time).
fn case(
    model: &Model,
    name: String,
    attack: bool,
    kappa: f64,
    limit: Option<Input>,
) -> LivenessCase {
    let mut rows = Vec::new();
    let walk = walk_path(model, attack, (kappa, limit), &mut rows);
    let reach = reach_at_goal(model, attack, walk.delay, walk.applied);
    // Holding: u = 0 satisfies every row at rest at some point of the goal set, at every time
    // from the robot's arrival (or from HOLD_WINDOW before the end, when it arrives earlier) to
    // the end of the run. `settled` is judged over the run's last SETTLE_WINDOW: an offset that
    // pushes the robot out of its goal earlier and then ends (an attack window that closes)
    // leaves it time to come back.
    let hold: Vec<(f64, Vec<Offsets>)> = hold_times(model, walk.delay)
        .into_iter()
        .map(|t| (t, model.scenarios_at(t, attack)))
        .collect();
    let goal_holds = goal_holds(model, &hold, kappa, &mut rows);
    let misled = if attack && model.response.is_some() {
        misled(model, &hold)
    } else {
        None
    };
    LivenessCase {
        name,
        reach,
        stall: walk.stall,
        least_progress: walk.least,
        goal_holds,
        misled,
        through_step3: walk.through_step3,
        joint_infeasible: walk.joint_infeasible,
        waited: walk.waited,
    }
}

/// What the walk along the path found.
struct PathWalk {
    /// The largest spoofed offset within θ met on the way \[m\].
    applied: f64,
    /// The least progress the rows allowed, and where.
    least: (f64, [f64; 2]),
    /// Where the robot stopped for good, if it did.
    stall: Option<Stall>,
    /// Samples passed only through Step 3's joint problem.
    through_step3: usize,
    /// The first place the joint problem had no solution.
    joint_infeasible: Option<Stall>,
    /// Time waited for offsets to pass \[s\].
    delay: f64,
    /// The total wait and where the robot first waited.
    waited: Option<(f64, [f64; 2])>,
}

/// Walks the path's samples at the planned times: each must be passable; under attack a
/// blocked robot waits where it is (in steps of `WAIT_STEP`) while a time-varying offset may
/// still let it on, and stalls when none does.
fn walk_path(
    model: &Model,
    attack: bool,
    (kappa, limit): (f64, Option<Input>),
    rows: &mut Vec<(HalfSpace, usize, f64)>,
) -> PathWalk {
    let mut w = PathWalk {
        applied: 0.0,
        least: (f64::INFINITY, model.path[0]),
        stall: None,
        through_step3: 0,
        joint_infeasible: None,
        delay: 0.0,
        waited: None,
    };
    let last_wait = model.world.file.duration - HOLD_WINDOW;
    'path: for (p, t, along) in samples(&model.path) {
        let planned = model.time_at(along) + w.delay;
        let mut time = planned;
        loop {
            match model.passable(p, t, time, attack, (kappa, limit), rows) {
                Ok((a, q, r, step3)) => {
                    if r <= model.theta_max(time) {
                        w.applied = w.applied.max(r);
                    }
                    if a < w.least.0 {
                        w.least = (a, q);
                    }
                    if let Some(mut st) = step3 {
                        st.along = along;
                        w.through_step3 += 1;
                        w.joint_infeasible.get_or_insert(st);
                    }
                    break;
                }
                Err(mut st) => {
                    st.along = along;
                    if st.blocked == Blocked::Infeasible && w.joint_infeasible.is_none() {
                        w.joint_infeasible = Some(st.clone());
                    }
                    // A time-varying offset (an attack window that closes, a sinusoid) may
                    // let the robot on later: it waits where it is.
                    if attack && time + WAIT_STEP <= last_wait {
                        time += WAIT_STEP;
                        continue;
                    }
                    let mut st = st;
                    if time > planned {
                        // Blocked until the end: report it where and as it first was.
                        if let Err(first) =
                            model.passable(p, t, planned, attack, (kappa, limit), rows)
                        {
                            st = Stall { along, ..first };
                        }
                    }
                    w.stall = Some(st);
                    break 'path;
                }
            }
        }
        if time > planned {
            w.delay += time - planned;
            w.waited = Some((w.delay, w.waited.map_or(p, |x| x.1)));
        }
    }
    w
}

/// The case's reach: `applied` on the way, raised by the spoofed estimates' offsets within θ
/// while the robot is at its goal (from its arrival, `delay` late, to the end of the run).
fn reach_at_goal(model: &Model, attack: bool, delay: f64, mut applied: f64) -> f64 {
    let duration = model.world.file.duration;
    let at_goal = (model.time_at(model.length()) + delay).min(duration);
    let mut t = at_goal;
    while t <= duration {
        for o in model.scenarios_at(t, attack) {
            for &(ui, _) in &model.spoofed {
                let r = o[ui][0].hypot(o[ui][1]);
                if r <= model.theta_max(t) {
                    applied = applied.max(r);
                }
            }
        }
        t += HOLD_STEP;
    }
    applied
}

/// The hold period's times, `HOLD_STEP` apart: from the robot's arrival (`delay` late), or
/// from `HOLD_WINDOW` before the end when it arrives earlier, to the end of the run.
fn hold_times(model: &Model, delay: f64) -> Vec<f64> {
    let duration = model.world.file.duration;
    let arrive = (model.time_at(model.length()) + delay)
        .max(duration - HOLD_WINDOW)
        .min(duration);
    let n_hold = ((duration - arrive) / HOLD_STEP).ceil().max(0.0) as u32;
    (0..=n_hold)
        .map(|k| (arrive + f64::from(k) * HOLD_STEP).min(duration))
        .collect()
}

/// Whether u = 0 satisfies every row at rest, at every hold time and offset of `hold`, at the
/// goal's centre or else at one of 32 points on two rings inside the goal.
fn goal_holds(
    model: &Model,
    hold: &[(f64, Vec<Offsets>)],
    kappa: f64,
    rows: &mut Vec<(HalfSpace, usize, f64)>,
) -> bool {
    let mut holds_at = |g: [f64; 2]| {
        hold.iter().all(|(t, offs)| {
            offs.iter().all(|o| {
                model.rows(g, o, *t, kappa, rows);
                rows.iter()
                    .all(|(h, _, _)| h.offset.is_finite() && h.offset >= -1e-12)
            })
        })
    };
    if holds_at(model.goal) {
        return true;
    }
    let r = model.goal_radius * 0.8;
    for ring in [0.5, 1.0] {
        for k in 0..16 {
            let a = std::f64::consts::TAU * f64::from(k) / 16.0;
            let g = [
                model.goal[0] + ring * r * a.cos(),
                model.goal[1] + ring * r * a.sin(),
            ];
            if holds_at(g) {
                return true;
            }
        }
    }
    false
}

/// Settling: the tracker follows the kept unit Step 3 ranks first; a spoofed estimate Step 2
/// cannot isolate may rank first, and the robot then rests where that estimate is in the goal.
/// The largest such offset beyond the goal radius over the run's last `SETTLE_WINDOW` of
/// `hold`, with its θ.
fn misled(model: &Model, hold: &[(f64, Vec<Offsets>)]) -> Option<(f64, f64)> {
    let mut misled: Option<(f64, f64)> = None;
    let end = model.world.file.duration;
    for (t, offs) in hold.iter().filter(|(t, _)| *t >= end - SETTLE_WINDOW) {
        let t = *t;
        for o in offs {
            for (k, &(ui, a)) in model.spoofed.iter().enumerate() {
                if model.ranking_shift(k, t) >= RANKING_SHIFT {
                    // Its innovations give it away: the tracker does not follow it.
                    continue;
                }
                let r = o[ui][0].hypot(o[ui][1]);
                let theta = match model.setup.config.kind {
                    ControllerKind::FtCbfClf => theta_at(model.setup, model.patterns, ui, a, t),
                    _ => f64::INFINITY,
                };
                if r <= theta && r > model.goal_radius && misled.is_none_or(|m| r > m.0) {
                    misled = Some((r, theta));
                }
            }
        }
    }
    misled
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

/// Values of κ tried by `smallest_fix` (each at most [`World::kappa_max`]).
pub const KAPPA_CANDIDATES: [f64; 6] = [10.0, 12.5, 15.0, 20.0, 25.0, 30.0];

/// Input limits tried by `smallest_fix` [m/s²].
pub const LIMIT_CANDIDATES: [f64; 6] = [0.75, 1.0, 1.25, 1.5, 2.0, 2.5];

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
            goal_radius: world.file.goal.radius,
            safe_stop: None,
            movers_blocked: Vec::new(),
            movers_wait: Vec::new(),
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
    let points: Vec<[f64; 2]> = samples(&model.path).iter().map(|s| s.0).collect();
    let inputs = crate::moving::LiveInputs {
        obstacles: &world.obstacles,
        barriers: &cfg.barriers,
        gamma: cfg
            .ft
            .gamma
            .iter()
            .copied()
            .fold(cfg.ft.gamma_baseline, f64::max),
        duration: world.file.duration,
        goal: world.file.goal.center,
        v_max: crate::world::structure::speed_bound(world).unwrap_or(f64::INFINITY),
    };
    let (movers_blocked, movers_wait) = crate::moving::liveness(&inputs, &points);
    LivenessReport {
        movers_blocked,
        movers_wait,
        kappa: cfg.cbf_gain,
        path_length,
        samples: n_samples,
        cases,
        fix,
        structural,
        skipped: None,
        goal_radius: model.goal_radius,
        safe_stop: None,
    }
}

/// The smallest change of one `[control]` key that makes every case live: κ up to
/// `kappa_max` first (it costs nothing physical), then the input box up to 2.5 m/s².
fn smallest_fix(world: &World, model: &Model, kappa: f64, limit: Option<Input>) -> Option<Fix> {
    let kmax = world.kappa_max();
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
    let misled = cases
        .iter()
        .any(|c| c.stall.is_none() && c.misled.is_some());
    if worst_theta > 1.0 {
        out.push(format!(
            "Step 2 can isolate the spoofed filters only beyond θ = {worst_theta:.3} m, so the attack's {reach:.3} m offset is never isolated: the robot cannot tell which estimate is honest ({}). Give the pair filters a channel of their own (wheel odometry or encoders with a heading, or a third receiver) so that θ shrinks",
            if misled { "it may settle where the spoofed one is in the goal" } else { "it keeps clear of both" }
        ));
    } else if misled {
        out.push(format!(
            "a spoofed estimate within θ = {worst_theta:.3} m of the honest one can be farther off than the goal's radius: lower θ with more precise or more redundant sensors, or widen the goal"
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
        let far = samples(&[[0.0, 0.0], [20_000.0, 0.0], [20_000.0, 8_000.0]]);
        assert!(far.len() <= MAX_SAMPLES + 2, "{} samples", far.len());
        // Every length / MAX_SAMPLES = 1.4 m at most (each leg split evenly).
        let step = 28_000.0 / MAX_SAMPLES as f64;
        assert!(
            far[1].2 <= step + 1e-9 && far[1].2 > 0.99 * step,
            "{}",
            far[1].2
        );
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

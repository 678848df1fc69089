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
//!   move a position fix. Beyond θ_ia(t), Step 2 drops the spoofed estimate. An attack that
//!   takes readings away (dropout, non-finite values, absurd ones the controller rejects) moves
//!   no fix, but a spoofed filter left with no fix of an axis dead-reckons it: its estimate
//!   runs off at the velocity error it had when the fixes went (`Drift`, taken at 1.645
//!   stds of its steady-state velocity error, `ONE_SIDED_95`), in either direction, and its
//!   rows keep the robot clear of the obstacles from there (the tracker leaves it: its spread
//!   outgrows its γ).
//!
//! At each point it solves the 2-D problem "largest acceleration along the path's direction
//! that satisfies every row jointly inside the input box" exactly (vertex enumeration, as
//! `ftcbf_controller::feasibility` decides feasibility). The path is **live** when that is at
//! least [`MIN_PROGRESS`] everywhere; otherwise the prediction names the first point where it
//! is not, whether the rows there are infeasible (Step 3 then drops units by residue, which a
//! stealthy attacker can win) or only push back (a stall), and the obstacles whose rows bind.
//! The goal **holds** when at some point of the goal set u = 0 satisfies every row at rest.
//! A spoofed estimate the tracker may follow **misleads** it off the goal when its offset, plus
//! 1.645 stds of that filter's own position error, reaches the goal's edge.
//!
//! This is a prediction about the nominal case, not a proof: the robot does not follow the
//! path exactly, noise moves the estimates by up to γ, and the tracker's stall escape can find
//! a way around. `ftcbf batch` measures the outcome; the README reports how often the two agree.
//!
//! Files: this one holds the report's types, the constants and [`predict`]; `model` builds the
//! model the walk reads (units, gains, the attack's responses and offsets over time), `attack`
//! bounds how far a declared attack moves the estimates, and `walk` steps along the path.

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

mod attack;
mod model;
pub mod rollout;
mod walk;

use model::*;
use walk::*;

use attack::{direct_fix, offsets};

pub use attack::{declared_reach, AttackReach};
pub use rollout::Rollouts;

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
    /// Moving obstacles that block the path for good (issue #51): one that stops across it, is
    /// over the goal at the end, or keeps coming back so the robot never gets across.
    pub movers_blocked: Vec<String>,
    /// Moving obstacles the robot may wait for (they cross the path and move on).
    pub movers_wait: Vec<String>,
    /// With movers, the closed loop's own runs ([`rollout`]; set by `ftcbf check` and
    /// `ftcbf batch`): when present, they decide whether the movers let the robot settle.
    pub rollouts: Option<Rollouts>,
}

impl LivenessReport {
    /// Every case live (a skipped prediction counts as live: nothing holds the robot).
    pub fn live(&self) -> bool {
        let movers = match &self.rollouts {
            Some(r) if r.error.is_none() => r.all_settled(),
            _ => self.movers_blocked.is_empty(),
        };
        self.cases.iter().all(LivenessCase::live) && movers
    }

    /// The verdict line.
    pub fn line(&self) -> String {
        if let Some(why) = &self.skipped {
            return format!("liveness not predicted: {why}");
        }
        if let Some(r) = self.rollouts.as_ref().filter(|r| r.error.is_none()) {
            return self.rolled_out_line(r);
        }
        let rollout_error = self
            .rollouts
            .as_ref()
            .map_or(String::new(), |r| format!("; {}", r.text()));
        if let Some(b) = self.movers_blocked.first() {
            return format!("the robot will NOT reach its goal: {b}{rollout_error}");
        }
        let stop = self.stop_suffix();
        let Some(c) = self.cases.iter().find(|c| !c.live()) else {
            let mut s = self.live_text();
            for w in &self.movers_wait {
                s.push_str("; ");
                s.push_str(w);
            }
            return s + &rollout_error;
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

impl LivenessReport {
    /// "; " and the safe stop's phrase, or nothing.
    fn stop_suffix(&self) -> String {
        self.safe_stop
            .as_ref()
            .map_or(String::new(), |stop| format!("; {stop}"))
    }

    /// The live verdict's opening (the path, the goal, κ, the safe stop).
    fn live_text(&self) -> String {
        let stop = self.stop_suffix();
        format!(
            "live: the rows leave a forward input at every point of the {:.2} m path and hold the robot in its goal (κ = {}){stop}",
            self.path_length, (self.kappa * 1e3).round() / 1e3
        )
    }

    /// The verdict line where the rollouts decide (every case live without the movers): the
    /// rollouts, then what the search past the movers found.
    fn rolled_out_line(&self, r: &Rollouts) -> String {
        let mut s = if r.all_settled() {
            format!("{} with the movers: {}", self.live_text(), r.text())
        } else {
            format!(
                "the robot may NOT settle in its goal with the movers: {}{}",
                r.text(),
                self.stop_suffix()
            )
        };
        match self.movers_blocked.first() {
            Some(b) => s.push_str(&format!("; the search past the movers finds no way: {b}")),
            None => {
                for w in &self.movers_wait {
                    s.push_str("; ");
                    s.push_str(w);
                }
            }
        }
        s
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
    /// Where the declared attack takes readings away (dropout, non-finite or absurd values the
    /// controller rejects): per spoofed unit that loses every fix of an axis, its drift
    /// ([`Drift::at`]).
    drifts: Vec<Drift>,
}

/// A spoofed unit left without any fix of an axis (position or velocity) from `start` to
/// `end`: it dead-reckons that axis, and its estimate carries the velocity error it had when
/// the last fix went on (the filters predict with the acceleration the drive realised).
#[derive(Debug, Clone, Copy)]
struct Drift {
    /// The unit (an index into `Model::units`).
    unit: usize,
    /// When the fixes go and, if they come back, when \[s\].
    start: f64,
    end: Option<f64>,
    /// The axes left without a fix (x, y), and the unit's steady-state velocity-error std on
    /// each \[m/s\].
    axes: [bool; 2],
    sigma_v: [f64; 2],
}

/// The one-sided 95 % point of a Gaussian, in stds: the prediction is for ≥ 95 % of runs, and
/// what takes the robot off its goal lies on one side of it. A [`Drift`] is taken at this many
/// stds of the velocity error the unit has when its fixes go (what holds the robot off is an
/// obstacle on one side: the drift's share towards it), and a spoofed estimate the tracker may
/// follow ([`walk::misled`]) misleads it when its offset plus this many stds of its own
/// position error reach the goal's edge.
const ONE_SIDED_95: f64 = 1.645;

impl Drift {
    /// How far the unit has run off along each axis at `t` \[m\] (None: not drifting then).
    fn at(&self, t: f64) -> Option<[f64; 2]> {
        if t < self.start || self.end.is_some_and(|e| t >= e) {
            return None;
        }
        let s = t - self.start;
        let d = [0, 1].map(|a| {
            if self.axes[a] {
                ONE_SIDED_95 * self.sigma_v[a] * s
            } else {
                0.0
            }
        });
        (d[0] > 0.0 || d[1] > 0.0).then_some(d)
    }
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
            rollouts: None,
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
    let (movers_blocked, movers_wait) = mover_liveness(world, setup, &model);
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
        rollouts: None,
    }
}

/// Liveness with the moving obstacles along the planned path ([`crate::movers::passage::liveness`]):
/// the movers that block it for good and those the robot may wait for.
fn mover_liveness(
    world: &World,
    setup: &ControlSetup,
    model: &Model,
) -> (Vec<String>, Vec<String>) {
    let cfg = &setup.config;
    let points: Vec<[f64; 2]> = samples(&model.path).iter().map(|s| s.0).collect();
    let units: Vec<crate::movers::passage::UnitGains> = model
        .units
        .iter()
        .map(|u| crate::movers::passage::UnitGains {
            m: u.m,
            n: u.n,
            gamma: u.gamma,
        })
        .collect();
    let inputs = crate::movers::passage::LiveInputs {
        obstacles: &world.obstacles,
        barriers: &cfg.barriers,
        rest: crate::movers::passage::Rest {
            gamma: cfg
                .ft
                .gamma
                .iter()
                .copied()
                .fold(cfg.ft.gamma_baseline, f64::max),
            rows: Some((&cfg.model, &units, cfg.cbf_gain)),
        },
        duration: world.file.duration,
        goal: world.file.goal.center,
        v_max: crate::world::structure::speed_bound(world).unwrap_or(f64::INFINITY),
        goal_radius: model.goal_radius,
        robot_radius: crate::world::structure::obstacle_barrier_config(world).robot_radius,
    };
    crate::movers::passage::liveness(&inputs, &points)
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
    if let Some(note) = model.drift_note() {
        out.push(note);
    }
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
    // `ftcbf check` decides a world with movers by runs of the closed loop; this line gives its
    // analysis without them (one run is explained, not six more made).
    let who = if world.has_movers() {
        "check's analysis (without its runs of the closed loop)"
    } else {
        "check"
    };
    Some(format!(
        "why: the robot {what}: it ended at ({:.2}, {:.2}), {:.2} m from the goal's centre; {} of {steps} steps infeasible ({:.0} %), Step 3 kept a saturated estimator {} times, the tracker saw {} stall(s). {who} predicted: {}",
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

//! The nominal controller of the safety-filter form: a smooth path-tracking law on the
//! double integrator (eq. 6.2) that proposes u_nom; the FT-CBF QP then returns the closest
//! safe input, min ‖u − u_nom‖²_R over the Ω rows (see [`crate::controller::ProblemForm`]).
//!
//! The law, in the world frame (SI units):
//! - **Path.** A polyline p₀ (the start) → waypoints → goal. Progress along it is the arc length
//!   s of the estimate's projection, searched forward from the last projection only (the law
//!   never turns back to an earlier leg it has passed).
//! - **Carrot.** The point c at arc length s + L (lookahead L) on the path, or the goal.
//! - **Desired velocity.** v_des = min(v_cruise, √(2·a_arrive·r))·(c − p̂)/‖c − p̂‖, with r the
//!   remaining path length: a constant-deceleration approach that arrives at rest.
//! - **Acceleration.** u_nom = k_v·(v_des − v̂), clipped to the input box, then low-pass
//!   filtered (time constant τ) and rate limited (|Δu| ≤ j_max·dt): continuous and with bounded
//!   jerk, so the compensator (6.4) turns it into a smooth ω.
//! - **Stall detection and escape.** Outside the goal, when the remaining distance has not
//!   shrunk by `stall_progress` within `stall_time`, a stall is counted and, for `escape_time`,
//!   the desired direction is turned by ±`escape_angle` (alternating sides between stalls):
//!   a side-step that leaves a deadlock where the safety filter cancels the nominal input
//!   against a barrier. The count is reported ([`PathTracker::stalls`]).
//!
//! Non-finite estimates leave u_nom at its last value (an attack to survive, not a value to
//! track); the QP's barriers, not this law, keep the robot safe.

use crate::types::Input;

/// Errors of tracker construction.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrackerError {
    /// A value out of range.
    #[error("nominal tracker: `{key}` must be {expected}, got {value}")]
    InvalidValue {
        /// Which value.
        key: &'static str,
        /// What is expected.
        expected: &'static str,
        /// The value given.
        value: f64,
    },
}

/// Configuration of a [`PathTracker`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerConfig {
    /// Waypoints to pass before the goal [m, world frame] (may be empty).
    pub waypoints: Vec<[f64; 2]>,
    /// Goal position \[m\].
    pub goal: [f64; 2],
    /// Goal radius \[m\]: no stall is counted within it.
    pub goal_radius: f64,
    /// Cruise speed v_cruise [m/s].
    pub cruise_speed: f64,
    /// Velocity-tracking gain k_v [1/s].
    pub speed_gain: f64,
    /// Deceleration used for the approach a_arrive [m/s²].
    pub arrive_accel: f64,
    /// Lookahead L along the path \[m\].
    pub lookahead: f64,
    /// Input box |u_k| ≤ limit (m/s²), if any.
    pub input_limit: Option<Input>,
    /// Low-pass time constant τ of u_nom \[s\] (0: none).
    pub smoothing: f64,
    /// Jerk limit j_max [m/s³] (None: none).
    pub jerk_limit: Option<f64>,
    /// A stall: less than this progress \[m\] ...
    pub stall_progress: f64,
    /// ... within this time \[s\].
    pub stall_time: f64,
    /// How long an escape lasts \[s\].
    pub escape_time: f64,
    /// How far the desired direction turns during an escape \[rad\].
    pub escape_angle: f64,
}

impl TrackerConfig {
    /// Defaults for a TurtleBot3-class robot going to `goal` (radius `goal_radius`): 0.15 m/s cruise, k_v = 1.5 s⁻¹,
    /// a 0.1 m/s² approach, 0.3 m lookahead, τ = 0.2 s, jerk 2 m/s³, stall after < 5 cm in 4 s,
    /// escape 2 s at 60°.
    pub fn turtlebot(goal: [f64; 2], goal_radius: f64, input_limit: Option<Input>) -> Self {
        Self {
            waypoints: Vec::new(),
            goal,
            goal_radius,
            cruise_speed: 0.15,
            speed_gain: 1.5,
            arrive_accel: 0.1,
            lookahead: 0.3,
            input_limit,
            smoothing: 0.2,
            jerk_limit: Some(2.0),
            stall_progress: 0.05,
            stall_time: 4.0,
            escape_time: 2.0,
            escape_angle: std::f64::consts::FRAC_PI_3,
        }
    }
}

/// The path-tracking nominal law (see the module documentation).
#[derive(Debug, Clone)]
pub struct PathTracker {
    cfg: TrackerConfig,
    /// Path vertices: start, waypoints, goal.
    path: Vec<[f64; 2]>,
    /// Cumulative arc length at each vertex.
    arc: Vec<f64>,
    /// Index of the leg the last projection fell on.
    leg: usize,
    u: Input,
    started: bool,
    /// Remaining distance at the start of the current stall window, and the window's age.
    stall_ref: f64,
    stall_age: f64,
    escape_left: f64,
    escape_side: f64,
    stalls: usize,
}

fn positive(key: &'static str, value: f64) -> Result<(), TrackerError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(TrackerError::InvalidValue {
            key,
            expected: "a positive finite number",
            value,
        })
    }
}

fn finite_point(key: &'static str, p: [f64; 2]) -> Result<(), TrackerError> {
    match p.iter().find(|v| !v.is_finite()) {
        Some(&value) => Err(TrackerError::InvalidValue {
            key,
            expected: "finite coordinates",
            value,
        }),
        None => Ok(()),
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

impl PathTracker {
    /// Validates the configuration; the path starts at `start` \[m\].
    pub fn new(cfg: TrackerConfig, start: [f64; 2]) -> Result<Self, TrackerError> {
        positive("cruise_speed", cfg.cruise_speed)?;
        positive("speed_gain", cfg.speed_gain)?;
        positive("arrive_accel", cfg.arrive_accel)?;
        positive("lookahead", cfg.lookahead)?;
        positive("stall_progress", cfg.stall_progress)?;
        positive("stall_time", cfg.stall_time)?;
        positive("escape_time", cfg.escape_time)?;
        if !(cfg.goal_radius.is_finite() && cfg.goal_radius >= 0.0) {
            return Err(TrackerError::InvalidValue {
                key: "goal_radius",
                expected: "a finite number ≥ 0",
                value: cfg.goal_radius,
            });
        }
        if !(cfg.smoothing.is_finite() && cfg.smoothing >= 0.0) {
            return Err(TrackerError::InvalidValue {
                key: "smoothing",
                expected: "a finite number ≥ 0",
                value: cfg.smoothing,
            });
        }
        if let Some(j) = cfg.jerk_limit {
            positive("jerk_limit", j)?;
        }
        if !(cfg.escape_angle.is_finite() && cfg.escape_angle.abs() <= std::f64::consts::PI) {
            return Err(TrackerError::InvalidValue {
                key: "escape_angle",
                expected: "an angle in [-π, π]",
                value: cfg.escape_angle,
            });
        }
        finite_point("start", start)?;
        finite_point("goal", cfg.goal)?;
        for w in &cfg.waypoints {
            finite_point("waypoints", *w)?;
        }
        let mut path = vec![start];
        path.extend(cfg.waypoints.iter().copied());
        path.push(cfg.goal);
        let mut arc = vec![0.0; path.len()];
        for k in 1..path.len() {
            arc[k] = arc[k - 1] + dist(path[k - 1], path[k]);
        }
        Ok(Self {
            cfg,
            path,
            arc,
            leg: 0,
            u: Input::zeros(),
            started: false,
            stall_ref: f64::INFINITY,
            stall_age: 0.0,
            escape_left: 0.0,
            escape_side: 1.0,
            stalls: 0,
        })
    }

    /// The path's vertices (start, waypoints, goal).
    pub fn path(&self) -> &[[f64; 2]] {
        &self.path
    }

    /// Stalls detected so far.
    pub fn stalls(&self) -> usize {
        self.stalls
    }

    /// The last proposed u_nom [m/s²].
    pub fn last(&self) -> Input {
        self.u
    }

    /// Whether an escape is under way.
    pub fn escaping(&self) -> bool {
        self.escape_left > 0.0
    }

    /// Projects `p` on the path from the current leg on: (arc length, leg).
    fn project(&self, p: [f64; 2]) -> (f64, usize) {
        let mut best = (f64::INFINITY, self.arc[self.leg], self.leg);
        for k in self.leg..self.path.len() - 1 {
            let (a, b) = (self.path[k], self.path[k + 1]);
            let d = [b[0] - a[0], b[1] - a[1]];
            let len2 = d[0] * d[0] + d[1] * d[1];
            let t = if len2 > 0.0 {
                (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let q = [a[0] + t * d[0], a[1] + t * d[1]];
            let e = dist(p, q);
            if e < best.0 {
                best = (e, self.arc[k] + t * len2.sqrt(), k);
            }
        }
        (best.1, best.2)
    }

    /// The point at arc length `s` (clamped to the path).
    fn point_at(&self, s: f64) -> [f64; 2] {
        let total = self.arc[self.arc.len() - 1];
        let s = s.clamp(0.0, total);
        let k = (0..self.path.len() - 1)
            .find(|&k| s <= self.arc[k + 1])
            .unwrap_or(self.path.len() - 2);
        let len = self.arc[k + 1] - self.arc[k];
        let t = if len > 0.0 {
            (s - self.arc[k]) / len
        } else {
            1.0
        };
        let (a, b) = (self.path[k], self.path[k + 1]);
        [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
    }

    /// One step: position estimate `p` \[m\], velocity estimate `v` [m/s], period `dt` \[s\].
    /// Returns u_nom [m/s²].
    pub fn propose(&mut self, p: [f64; 2], v: [f64; 2], dt: f64) -> Input {
        if !(p.iter().chain(v.iter()).all(|x| x.is_finite()) && dt.is_finite() && dt > 0.0) {
            return self.u;
        }
        let (s, leg) = self.project(p);
        self.leg = leg;
        let total = self.arc[self.arc.len() - 1];
        // remaining: along the path from the projection, plus the offset to the path
        let remaining = (total - s).max(0.0) + dist(p, self.point_at(s));
        let carrot = self.point_at(s + self.cfg.lookahead);
        let (dx, dy) = (carrot[0] - p[0], carrot[1] - p[1]);
        let norm = dx.hypot(dy);
        let speed = self
            .cfg
            .cruise_speed
            .min((2.0 * self.cfg.arrive_accel * remaining).sqrt());
        let (mut ex, mut ey) = if norm > 1e-9 {
            (dx / norm, dy / norm)
        } else {
            (0.0, 0.0)
        };
        self.watch_progress(remaining, dt);
        if self.escape_left > 0.0 {
            let a = self.escape_side * self.cfg.escape_angle;
            let (sa, ca) = a.sin_cos();
            (ex, ey) = (ca * ex - sa * ey, sa * ex + ca * ey);
            self.escape_left -= dt;
        }
        let mut target = Input::new(
            self.cfg.speed_gain * (speed * ex - v[0]),
            self.cfg.speed_gain * (speed * ey - v[1]),
        );
        if let Some(l) = self.cfg.input_limit {
            target[0] = target[0].clamp(-l[0], l[0]);
            target[1] = target[1].clamp(-l[1], l[1]);
        }
        if !self.started {
            self.started = true;
            self.u = Input::zeros();
        }
        let alpha = if self.cfg.smoothing > 0.0 {
            dt / (self.cfg.smoothing + dt)
        } else {
            1.0
        };
        let mut delta = (target - self.u) * alpha;
        if let Some(j) = self.cfg.jerk_limit {
            let max = j * dt;
            let n = delta.norm();
            if n > max {
                delta *= max / n;
            }
        }
        self.u += delta;
        self.u
    }

    /// Stall bookkeeping over windows of `stall_time`.
    fn watch_progress(&mut self, remaining: f64, dt: f64) {
        if self.escape_left > 0.0 {
            return;
        }
        if remaining <= self.cfg.goal_radius {
            self.stall_ref = f64::INFINITY;
            return;
        }
        if !self.stall_ref.is_finite() {
            self.stall_ref = remaining;
            self.stall_age = 0.0;
            return;
        }
        self.stall_age += dt;
        if self.stall_ref - remaining >= self.cfg.stall_progress {
            self.stall_ref = remaining;
            self.stall_age = 0.0;
        } else if self.stall_age >= self.cfg.stall_time {
            self.stalls += 1;
            self.escape_left = self.cfg.escape_time;
            self.escape_side = -self.escape_side;
            self.stall_ref = f64::INFINITY;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A double integrator driven by the tracker: (p, v) after each step.
    fn drive(t: &mut PathTracker, p0: [f64; 2], steps: usize, dt: f64) -> Vec<([f64; 2], Input)> {
        let (mut p, mut v) = (p0, [0.0, 0.0]);
        let mut out = Vec::new();
        for _ in 0..steps {
            let u = t.propose(p, v, dt);
            for k in 0..2 {
                p[k] += v[k] * dt + 0.5 * u[k] * dt * dt;
                v[k] += u[k] * dt;
            }
            out.push((p, u));
        }
        out
    }

    #[test]
    fn reaches_the_goal_through_the_waypoints_with_bounded_jerk() {
        let mut cfg = TrackerConfig::turtlebot([2.0, 0.0], 0.05, Some(Input::new(0.5, 0.5)));
        cfg.waypoints = vec![[1.0, 1.0]];
        let mut t = PathTracker::new(cfg, [0.0, 0.0]).expect("tracker");
        let dt = 0.02;
        let run = drive(&mut t, [0.0, 0.0], 2500, dt);
        // passes within 0.15 m of the waypoint (the lookahead cuts the corner by less)
        let near = run
            .iter()
            .map(|(p, _)| dist(*p, [1.0, 1.0]))
            .fold(f64::INFINITY, f64::min);
        assert!(near < 0.15, "closest approach to the waypoint {near} m");
        let end = run.last().expect("steps").0;
        assert!(dist(end, [2.0, 0.0]) < 0.05, "ends at {end:?}");
        // jerk limit 2 m/s³: |Δu| ≤ 0.04 m/s² per 20 ms step
        for w in run.windows(2) {
            assert!((w[1].1 - w[0].1).norm() <= 2.0 * dt + 1e-12);
        }
        assert_eq!(t.stalls(), 0);
    }

    #[test]
    fn a_blocked_robot_stalls_and_side_steps_alternately() {
        let cfg = TrackerConfig::turtlebot([2.0, 0.0], 0.05, None);
        let mut t = PathTracker::new(cfg, [0.0, 0.0]).expect("tracker");
        let dt = 0.02;
        // the robot never moves: after 4 s a stall, then 2 s of escape at +60° or −60°
        let mut dirs = Vec::new();
        for k in 0..700 {
            let u = t.propose([0.0, 0.0], [0.0, 0.0], dt);
            if k % 50 == 49 {
                dirs.push((t.stalls(), t.escaping(), u[1].atan2(u[0])));
            }
        }
        assert_eq!(t.stalls(), 2, "{dirs:?}");
        let (_, esc, a) = dirs[4]; // t = 5 s: in the first escape
        assert!(esc && a.abs() > 0.5, "{dirs:?}");
        let (_, esc, a0) = dirs[2]; // t = 3 s: straight at the goal
        assert!(!esc && a0.abs() < 1e-9, "{dirs:?}");
        // a stall window restarts after the escape: the second stall at t = 10 s; at t = 11 s
        // the second escape turns the other way
        let second = dirs[10];
        assert!(second.1 && second.2.signum() != a.signum(), "{dirs:?}");
    }

    #[test]
    fn non_finite_estimates_keep_the_last_proposal_and_bad_config_is_an_error() {
        let cfg = TrackerConfig::turtlebot([1.0, 0.0], 0.05, None);
        let mut t = PathTracker::new(cfg.clone(), [0.0, 0.0]).expect("tracker");
        let u = t.propose([0.0, 0.0], [0.0, 0.0], 0.02);
        assert_eq!(t.propose([f64::NAN, 0.0], [0.0, 0.0], 0.02), u);
        assert_eq!(t.propose([0.0, 0.0], [f64::INFINITY, 0.0], 0.02), u);
        let mut bad = cfg.clone();
        bad.cruise_speed = 0.0;
        assert!(matches!(
            PathTracker::new(bad, [0.0, 0.0]),
            Err(TrackerError::InvalidValue {
                key: "cruise_speed",
                ..
            })
        ));
        let mut bad = cfg;
        bad.waypoints = vec![[f64::NAN, 0.0]];
        assert!(matches!(
            PathTracker::new(bad, [0.0, 0.0]),
            Err(TrackerError::InvalidValue {
                key: "waypoints",
                ..
            })
        ));
    }
}

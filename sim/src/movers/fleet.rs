//! The moving obstacles of one run (issue #51): each obstacle with a `motion` is moved here —
//! a scripted path ([`Trajectory`]) in closed form, a walker ([`Walker`]) one control step at
//! a time — and read by the controller as a [`MoverState`] per mover.
//!
//! Movers are numbered in the order of the world's obstacles that move; a mover's barrier
//! ([`ftcbf_controller::MovingBarrier`]) reads the state of that number.
//!
//! A walker steps the social force once per control period (from the positions at its start,
//! with the robot as one more body to keep off) and then moves at the velocity found, in a
//! straight line, through the plant ticks of the period: what the controller reads at the
//! step — its position and that velocity — is exactly what it does until the next step. Its
//! velocity jumps between steps by at most its acceleration times the period; the reading's
//! acceleration bound is the social force's driving term's, (v_des + v_cap)/τ, which does not
//! cover the repulsion when it is close to another body (stated, not proven).

use ftcbf_controller::MoverState;
use rand::RngCore;

use crate::movers::tracked::TrackedMover;
use crate::movers::{
    step_crowd, MotionError, Repeat, SocialForce, Surroundings, Trajectory, Walker,
};
use crate::obstacles::{
    BarrierConfig, MotionSpec, Obstacle, ObstacleBarrier, ObstacleSpec, RepeatSpec, ShapeSpec,
};
use crate::sensors::stream_rng;

/// The largest factor a walker's speed may reach over its `speed`: its desired speed is at
/// most 1.2 × `speed` (the per-trial draw) and its speed at most 1.3 × the desired one.
pub const WALKER_SPEED_FACTOR: f64 = 1.2 * 1.3;

/// The scripted path of `spec`, if it has one (a walker and a standing obstacle have none).
pub fn trajectory(spec: &ObstacleSpec) -> Result<Option<Trajectory>, MotionError> {
    let origin = [spec.position[0], spec.position[1]];
    match &spec.motion {
        Some(MotionSpec::Waypoints {
            points,
            speed,
            repeat,
            start,
        }) => {
            let repeat = match repeat {
                RepeatSpec::Loop => Repeat::Loop,
                RepeatSpec::Reverse => Repeat::Reverse,
                RepeatSpec::Once => Repeat::Once,
            };
            Trajectory::waypoints(origin, points, *speed, repeat, *start).map(Some)
        }
        Some(MotionSpec::Velocity { velocity }) => {
            for v in velocity {
                if !v.is_finite() {
                    return Err(MotionError::Value {
                        key: "velocity",
                        expected: "a finite number in m/s",
                        found: *v,
                    });
                }
            }
            Ok(Some(Trajectory::Velocity {
                origin,
                velocity: *velocity,
            }))
        }
        _ => Ok(None),
    }
}

/// A walker's body radius: the radius of its round shape.
pub(crate) fn walker_radius(spec: &ObstacleSpec) -> Option<f64> {
    match spec.shape {
        ShapeSpec::Cylinder { radius, .. }
        | ShapeSpec::Capsule { radius, .. }
        | ShapeSpec::Ball { radius } => Some(radius),
        _ => None,
    }
}

/// Checks an obstacle's `motion` (the key inside it and what was expected on error).
pub fn check_motion(spec: &ObstacleSpec) -> Result<(), String> {
    trajectory(spec).map_err(|e| e.to_string())?;
    match (&spec.motion, &spec.shape) {
        (Some(_), ShapeSpec::HalfSpace { .. } | ShapeSpec::OccupancyMap { .. }) => Err(format!(
            "`kind`: a {} cannot move (expected a bounded shape)",
            spec.shape.kind()
        )),
        (Some(MotionSpec::Walker { goals, speed }), _) => {
            if walker_radius(spec).is_none() {
                return Err(format!(
                    "`kind`: a walker is a round body; expected a cylinder, capsule or ball, \
                     found a {}",
                    spec.shape.kind()
                ));
            }
            if let Some(g) = goals.iter().flatten().find(|g| !g.is_finite()) {
                return Err(format!("`goals`: expected finite numbers, found {g}"));
            }
            Walker::new([0.0, 0.0], 0.1, goals, *speed, 0)
                .map(|_| ())
                .map_err(|e| e.to_string())
        }
        _ => Ok(()),
    }
}

/// The largest speed obstacle `spec` can move at \[m/s\] (0 when it stands still).
pub fn max_speed(spec: &ObstacleSpec) -> f64 {
    match &spec.motion {
        Some(MotionSpec::Walker { speed, .. }) => WALKER_SPEED_FACTOR * speed,
        Some(_) => trajectory(spec)
            .ok()
            .flatten()
            .map_or(0.0, |t| t.max_speed()),
        None => 0.0,
    }
}

/// The indices of the obstacles that move, in mover order.
pub fn mover_indices(obstacles: &[Obstacle]) -> Vec<usize> {
    (0..obstacles.len())
        .filter(|&i| obstacles[i].spec.motion.is_some())
        .collect()
}

/// How one mover moves.
#[derive(Debug, Clone)]
enum Motion {
    Scripted(Trajectory),
    /// Index into the crowd.
    Walker(usize),
}

/// The static obstacles as a walker sees them: distance and direction away from each.
#[derive(Debug, Clone)]
struct Statics {
    barriers: Vec<ObstacleBarrier>,
}

impl Surroundings for Statics {
    fn near(&self, p: [f64; 2], range: f64) -> Vec<(f64, [f64; 2])> {
        const H: f64 = 1e-3;
        let mut out = Vec::new();
        for b in &self.barriers {
            let at = |x: f64, y: f64| b.clearance(nalgebra::Vector2::new(x, y));
            let d = at(p[0], p[1]);
            // NaN (a non-finite position) is not near: skipped
            if d.partial_cmp(&range) != Some(std::cmp::Ordering::Less) {
                continue;
            }
            let g = [
                at(p[0] + H, p[1]) - at(p[0] - H, p[1]),
                at(p[0], p[1] + H) - at(p[0], p[1] - H),
            ];
            let n = g[0].hypot(g[1]);
            if n > 0.0 && n.is_finite() {
                out.push((d, [g[0] / n, g[1] / n]));
            }
        }
        out
    }
}

/// The movers of one run and their state.
#[derive(Debug, Clone)]
pub struct MoverSet {
    /// The obstacle index of each mover.
    obstacles: Vec<usize>,
    /// Each mover's position at t = 0 \[m\].
    origins: Vec<[f64; 2]>,
    motions: Vec<Motion>,
    crowd: Vec<Walker>,
    /// Each walker's position at the start of the current control step, and that step's time.
    crowd_start: Vec<[f64; 2]>,
    step_start: f64,
    /// Each walker's acceleration bound \[m/s²\].
    crowd_accel: Vec<f64>,
    model: SocialForce,
    statics: Statics,
    /// The controller's readings (a tracked mover's from its filter, the others exact).
    states: Vec<MoverState>,
    /// Each mover's tracker, if it has one ([`MoverSet::track`]).
    tracked: Vec<Option<TrackedMover>>,
    /// The true states when some mover is tracked (else `states` are the truth).
    truth: Vec<MoverState>,
}

impl MoverSet {
    /// The movers of `obstacles`, walkers seeded from `seed` and their obstacle's name (so a
    /// rerun with the same seed walks the same). `statics_cfg` is the barrier geometry a walker
    /// keeps off the static obstacles with (its own radius is added by the social force).
    pub fn new(obstacles: &[Obstacle], statics_cfg: &BarrierConfig, seed: u64) -> Self {
        let model = SocialForce::default();
        let mut set = Self {
            obstacles: Vec::new(),
            origins: Vec::new(),
            motions: Vec::new(),
            crowd: Vec::new(),
            crowd_start: Vec::new(),
            step_start: 0.0,
            crowd_accel: Vec::new(),
            model,
            statics: Statics {
                barriers: Vec::new(),
            },
            states: Vec::new(),
            tracked: Vec::new(),
            truth: Vec::new(),
        };
        let bare = BarrierConfig {
            robot_radius: 0.0,
            margin: 0.0,
            k: 0.0,
            ..*statics_cfg
        };
        for (i, o) in obstacles.iter().enumerate() {
            let spec = &o.spec;
            let origin = [spec.position[0], spec.position[1]];
            let motion = match (&spec.motion, trajectory(spec)) {
                (None, _) => {
                    set.statics.barriers.push(o.barrier(&bare));
                    continue;
                }
                (Some(MotionSpec::Walker { goals, speed }), _) => {
                    let mut rng = stream_rng(seed, "walker", &spec.name);
                    let radius = walker_radius(spec).unwrap_or(0.0);
                    // Checked when the world was loaded (`check_motion`).
                    let Ok(w) = Walker::new(origin, radius, goals, *speed, rng.next_u64()) else {
                        continue;
                    };
                    let cap = w.max_speed(&model);
                    set.crowd_accel.push((w.desired_speed() + cap) / model.tau);
                    set.crowd_start.push(origin);
                    set.crowd.push(w);
                    Motion::Walker(set.crowd.len() - 1)
                }
                (Some(_), Ok(Some(t))) => Motion::Scripted(t),
                (Some(_), _) => continue,
            };
            set.obstacles.push(i);
            set.origins.push(origin);
            set.motions.push(motion);
            set.states.push(MoverState::default());
            set.tracked.push(None);
        }
        set
    }

    /// Reads the movers of `obstacles` with a `tracker` through it (issue #51): detections
    /// seeded from `seed` and the obstacle's name, error bounds at `eps_per_sample`
    /// ([`crate::model::setup::tracker_eps`]). Movers without one stay exact.
    pub fn track(&mut self, obstacles: &[Obstacle], eps_per_sample: f64, seed: u64) {
        for (slot, &i) in self.tracked.iter_mut().zip(&self.obstacles) {
            let spec = &obstacles[i].spec;
            *slot = TrackedMover::new(spec, max_speed(spec), eps_per_sample, seed);
        }
    }

    /// The trackers (one slot per mover, None for an exact reading).
    pub fn trackers(&self) -> &[Option<TrackedMover>] {
        &self.tracked
    }

    /// The true states at the current control step (the readings when none is tracked).
    pub fn truth(&self) -> &[MoverState] {
        if self.truth.is_empty() {
            &self.states
        } else {
            &self.truth
        }
    }

    /// Whether there is anything to move.
    pub fn is_empty(&self) -> bool {
        self.obstacles.is_empty()
    }

    /// The obstacle index of each mover.
    pub fn obstacles(&self) -> &[usize] {
        &self.obstacles
    }

    /// The readings of the current control step (see [`MoverSet::control_step`]).
    pub fn states(&self) -> &[MoverState] {
        &self.states
    }

    /// Starts the control step at time `t` \[s\] lasting `dt`: walkers take their social-force
    /// step (keeping off the robot, a disc of `robot.1` at `robot.0`), and every mover's
    /// reading is set to its state at `t`.
    pub fn control_step(&mut self, t: f64, dt: f64, robot: ([f64; 2], f64)) {
        if !self.crowd.is_empty() {
            for (s, w) in self.crowd_start.iter_mut().zip(&self.crowd) {
                *s = w.position;
            }
            step_crowd(&mut self.crowd, &self.model, &self.statics, Some(robot), dt);
            // The crowd's new positions are those of t + dt; within the step each walker moves
            // from its start at its new velocity.
        }
        self.step_start = t;
        let mut states = std::mem::take(&mut self.states);
        self.states_at(t, &mut states);
        if self.tracked.iter().any(Option::is_some) {
            self.truth.clone_from(&states);
            for ((s, tr), truth) in states.iter_mut().zip(&mut self.tracked).zip(&self.truth) {
                if let Some(tr) = tr {
                    *s = tr.step(t, truth);
                }
            }
        }
        self.states = states;
    }

    /// Every mover's state at `tau` \[s\], within the current control step (a walker on its
    /// straight line of this step; a scripted mover exactly).
    pub fn states_at(&self, tau: f64, out: &mut Vec<MoverState>) {
        out.clear();
        for (k, m) in self.motions.iter().enumerate() {
            let o = self.origins[k];
            let (p, v, a) = match m {
                Motion::Scripted(t) => {
                    let (p, v) = t.state(tau);
                    (p, v, 0.0)
                }
                Motion::Walker(w) => {
                    let v = self.crowd[*w].velocity;
                    let s = self.crowd_start[*w];
                    let e = tau - self.step_start;
                    ([s[0] + v[0] * e, s[1] + v[1] * e], v, self.crowd_accel[*w])
                }
            };
            out.push(MoverState {
                displacement: [p[0] - o[0], p[1] - o[1]],
                velocity: v,
                accel_bound: a,
                ..MoverState::default()
            });
        }
    }

    /// Whether mover `k` is a walker.
    pub fn is_walker(&self, k: usize) -> bool {
        matches!(self.motions.get(k), Some(Motion::Walker(_)))
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A round obstacle of radius 0.15 m at (1, 2) that moves by `motion`.
    pub(in crate::movers) fn spec(motion: MotionSpec) -> ObstacleSpec {
        ObstacleSpec {
            name: "m".into(),
            position: [1.0, 2.0, 0.2],
            rpy: [0.0; 3],
            shape: ShapeSpec::Cylinder {
                radius: 0.15,
                half_height: 0.2,
            },
            motion: Some(motion),
            tracker: None,
        }
    }

    #[test]
    fn bad_motions_name_their_key() {
        let e = check_motion(&spec(MotionSpec::Waypoints {
            points: vec![],
            speed: 0.1,
            repeat: RepeatSpec::Loop,
            start: 0.0,
        }))
        .unwrap_err();
        assert!(e.contains("`points`"), "{e}");
        let e = check_motion(&spec(MotionSpec::Walker {
            goals: vec![[0.0, 0.0]],
            speed: f64::NAN,
        }))
        .unwrap_err();
        assert!(e.contains("`speed`"), "{e}");
        let e = check_motion(&spec(MotionSpec::Velocity {
            velocity: [f64::INFINITY, 0.0],
        }))
        .unwrap_err();
        assert!(e.contains("`velocity`"), "{e}");
        let mut boxed = spec(MotionSpec::Walker {
            goals: vec![[0.0, 0.0]],
            speed: 1.0,
        });
        boxed.shape = ShapeSpec::Cuboid {
            half_extents: [0.1; 3],
        };
        assert!(check_motion(&boxed).unwrap_err().contains("round body"));
    }

    #[test]
    fn scripted_readings_are_displacements_from_the_start_and_walkers_repeat_with_the_seed() {
        let cfg = BarrierConfig {
            robot_radius: 0.1,
            centre_height: 0.1,
            margin: 0.0,
            k: 0.0,
            v_max: 0.2,
            fd_step: 2e-3,
        };
        let mk = |s: &ObstacleSpec| Obstacle::from_spec(s, None).unwrap();
        let obstacles = [
            mk(&spec(MotionSpec::Velocity {
                velocity: [0.1, 0.0],
            })),
            mk(&ObstacleSpec {
                name: "w".into(),
                ..spec(MotionSpec::Walker {
                    goals: vec![[4.0, 2.0]],
                    speed: 0.5,
                })
            }),
        ];
        let run = |seed| {
            let mut set = MoverSet::new(&obstacles, &cfg, seed);
            for k in 0..100 {
                set.control_step(k as f64 * 0.02, 0.02, ([10.0, 10.0], 0.1));
            }
            set.states().to_vec()
        };
        let a = run(1);
        // Velocity: 1.98 s at 0.1 m/s.
        assert!((a[0].displacement[0] - 0.198).abs() < 1e-12);
        assert_eq!(a[0].velocity, [0.1, 0.0]);
        assert_eq!(a[0].accel_bound, 0.0);
        // The walker heads +x at about its speed (0.4–0.6 m/s) after 2 s.
        assert!(
            a[1].velocity[0] > 0.3 && a[1].velocity[0] < 0.8,
            "{:?}",
            a[1]
        );
        assert_eq!(a, run(1), "same seed, same walk");
        assert_ne!(a[1], run(2)[1], "another seed, another walk");
    }
}

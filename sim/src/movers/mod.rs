//! How obstacles move (issue #51): scripted paths and walkers.
//!
//! Two kinds of motion, both in the world's x–y plane (z and orientation are the obstacle's
//! own and stay put):
//!
//! - **Scripted**: [`Trajectory`], a closed-form function of time — along waypoints at a
//!   constant speed (`loop`, `reverse` or `once`, from a start time on), or at a constant
//!   velocity. Position and velocity at any t, and the largest speed, which is what a
//!   time-varying barrier's ∂h/∂t needs.
//! - **Walkers**: [`Walker`], the social-force model of Helbing and Molnár (Phys. Rev. E 51,
//!   4282, 1995) with the parameters of Helbing, Farkas and Vicsek (Nature 407, 487, 2000):
//!   relaxation toward the desired velocity (τ = 0.5 s), exponential repulsion from static
//!   obstacles and other walkers (A/m = 2000 N / 80 kg = 25 m/s², B = 0.08 m), speeds capped at
//!   1.3 × the desired speed. Each walker heads for its goals in turn. Its desired speed is
//!   drawn per trial (±10 %, seeded) and a small seeded fluctuation force breaks symmetric
//!   deadlocks, so the same seed gives the same walk bit for bit.
//!
//! The module knows nothing of rapier or parry: a walker sees the static obstacles through
//! [`Surroundings`], which the simulator answers from its shapes.
//!
//! [`fleet`] holds the moving obstacles of one run: the world's movers numbered, moved each
//! step, and read by the controller.

pub mod fleet;
pub mod passage;
pub mod tracked;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// What a scripted path does after its last waypoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Repeat {
    /// Back to the first point (the obstacle's own position) and round again.
    Loop,
    /// Back along the same points, and forth again.
    Reverse,
    /// Stop at the last point.
    Once,
}

/// A polyline travelled at a constant speed, with its legs (start, unit direction, length)
/// and period computed once.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    /// The polyline, starting at the obstacle's own position \[m\].
    pub points: Vec<[f64; 2]>,
    /// Speed along it \[m/s\].
    pub speed: f64,
    /// After the last point.
    pub repeat: Repeat,
    /// Time the motion starts \[s\]; before it the obstacle stands at its first point.
    pub start: f64,
    legs: Vec<([f64; 2], [f64; 2], f64)>,
    period: f64,
}

/// A scripted motion: position and velocity as functions of time.
#[derive(Debug, Clone, PartialEq)]
pub enum Trajectory {
    /// Along a [`Path`] (the obstacle's own position first) at its speed, from its start on.
    Waypoints(Path),
    /// From `origin` at a constant velocity.
    Velocity {
        /// Position at t = 0 \[m\].
        origin: [f64; 2],
        /// \[m/s\]
        velocity: [f64; 2],
    },
}

/// Why a motion cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MotionError {
    /// A number is not finite, or a speed is not positive.
    #[error("`{key}`: expected {expected}, found {found}")]
    Value {
        /// The key.
        key: &'static str,
        /// What was expected.
        expected: &'static str,
        /// The value found.
        found: f64,
    },
    /// A path needs at least one point besides the obstacle's own position.
    #[error("`points`: expected at least one point to move to")]
    NoPoints,
    /// A walker needs a goal.
    #[error("`goals`: expected at least one goal")]
    NoGoals,
}

fn finite(key: &'static str, x: f64) -> Result<f64, MotionError> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(MotionError::Value {
            key,
            expected: "a finite number",
            found: x,
        })
    }
}

fn positive(key: &'static str, x: f64) -> Result<f64, MotionError> {
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(MotionError::Value {
            key,
            expected: "a positive speed in m/s",
            found: x,
        })
    }
}

/// Points along `points` joined in order (and back to the first when `closed`), the first
/// point and then every segment cut into equal pieces of at most `step` \[m\]: where a mover's
/// centre goes along its legs, for the pinning tests of `check` and the generator.
pub fn polyline_points(points: &[[f64; 2]], closed: bool, step: f64) -> Vec<[f64; 2]> {
    let Some(&first) = points.first() else {
        return Vec::new();
    };
    let back = closed.then(|| (points[points.len() - 1], first));
    let mut out = vec![first];
    for (a, b) in points.windows(2).map(|w| (w[0], w[1])).chain(back) {
        let n = ((b[0] - a[0]).hypot(b[1] - a[1]) / step).ceil().max(1.0) as usize;
        out.extend((1..=n).map(|k| {
            let s = k as f64 / n as f64;
            [a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s]
        }));
    }
    out
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn norm(a: [f64; 2]) -> f64 {
    a[0].hypot(a[1])
}

impl Trajectory {
    /// Along `points` from `origin` (the obstacle's own position) at `speed` from `start` on.
    pub fn waypoints(
        origin: [f64; 2],
        points: &[[f64; 2]],
        speed: f64,
        repeat: Repeat,
        start: f64,
    ) -> Result<Trajectory, MotionError> {
        if points.is_empty() {
            return Err(MotionError::NoPoints);
        }
        let speed = positive("speed", speed)?;
        let start = finite("start", start)?;
        let mut all = vec![[
            finite("position", origin[0])?,
            finite("position", origin[1])?,
        ]];
        for p in points {
            all.push([finite("points", p[0])?, finite("points", p[1])?]);
        }
        // The legs travelled in one period: forward, then back (reverse) or to the first (loop).
        let mut ends: Vec<([f64; 2], [f64; 2])> = all.windows(2).map(|w| (w[0], w[1])).collect();
        match repeat {
            Repeat::Loop => ends.push((all[all.len() - 1], all[0])),
            Repeat::Reverse => {
                let back: Vec<_> = ends.iter().rev().map(|&(a, b)| (b, a)).collect();
                ends.extend(back);
            }
            Repeat::Once => {}
        }
        let legs: Vec<_> = ends
            .into_iter()
            .filter_map(|(a, b)| {
                let d = sub(b, a);
                let len = norm(d);
                (len > 0.0).then(|| (a, [d[0] / len, d[1] / len], len))
            })
            .collect();
        let period = legs.iter().map(|l| l.2).sum::<f64>() / speed;
        Ok(Trajectory::Waypoints(Path {
            points: all,
            speed,
            repeat,
            start,
            legs,
            period,
        }))
    }

    /// The largest speed of the motion \[m/s\].
    pub fn max_speed(&self) -> f64 {
        match self {
            Trajectory::Waypoints(path) => path.speed,
            Trajectory::Velocity { velocity, .. } => norm(*velocity),
        }
    }

    /// Position \[m\] and velocity \[m/s\] at time `t` \[s\].
    pub fn state(&self, t: f64) -> ([f64; 2], [f64; 2]) {
        match self {
            Trajectory::Velocity { origin, velocity } => (
                [origin[0] + velocity[0] * t, origin[1] + velocity[1] * t],
                *velocity,
            ),
            Trajectory::Waypoints(path) => path.along(t - path.start),
        }
    }

    /// Where it is at t = 0 \[m\] (its own position).
    pub fn origin(&self) -> [f64; 2] {
        match self {
            Trajectory::Velocity { origin, .. } => *origin,
            Trajectory::Waypoints(path) => path.points[0],
        }
    }
}

impl Path {
    /// Position and velocity after travelling for `tau` seconds.
    fn along(&self, tau: f64) -> ([f64; 2], [f64; 2]) {
        let points = &self.points;
        let (speed, period) = (self.speed, self.period);
        if tau <= 0.0 || period <= 0.0 {
            return (points[0], [0.0, 0.0]);
        }
        let mut s = match self.repeat {
            Repeat::Once if tau >= period => return (points[points.len() - 1], [0.0, 0.0]),
            Repeat::Once => tau * speed,
            _ => (tau % period) * speed,
        };
        for &(a, u, len) in &self.legs {
            if s <= len {
                return (
                    [a[0] + u[0] * s, a[1] + u[1] * s],
                    [u[0] * speed, u[1] * speed],
                );
            }
            s -= len;
        }
        (points[0], [0.0, 0.0])
    }
}

/// What a walker sees of the static world: the distance from a point to the nearest static
/// obstacle's surface and the unit direction away from it, for every obstacle within `range`.
pub trait Surroundings {
    /// (distance \[m\], unit normal pointing away from the obstacle) of each static obstacle
    /// within `range` of `p`.
    fn near(&self, p: [f64; 2], range: f64) -> Vec<(f64, [f64; 2])>;
}

/// The social-force parameters (Helbing, Farkas and Vicsek 2000, per unit mass).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SocialForce {
    /// Relaxation time toward the desired velocity \[s\].
    pub tau: f64,
    /// Repulsion strength per unit mass \[m/s²\].
    pub strength: f64,
    /// Repulsion range \[m\].
    pub range: f64,
    /// Speed cap as a multiple of the desired speed.
    pub max_speed_factor: f64,
    /// A goal counts as reached within this distance \[m\].
    pub goal_reached: f64,
    /// Standard deviation of the fluctuation acceleration \[m/s²\].
    pub fluctuation: f64,
}

impl SocialForce {
    /// The gap \[m\] a walker of desired `speed` \[m/s\] keeps from a body in its way: where the
    /// body's repulsion, `strength`·exp(−gap/`range`), equals the most its goal pulls it with,
    /// `speed`/`tau` (0.39 m at 0.1 m/s with the defaults). Nearer, the repulsion wins and it
    /// steps aside.
    pub fn comfort_gap(&self, speed: f64) -> f64 {
        let pull = speed / self.tau;
        if pull > 0.0 && self.strength > pull {
            self.range * (self.strength / pull).ln()
        } else {
            0.0
        }
    }
}

impl Default for SocialForce {
    fn default() -> Self {
        SocialForce {
            tau: 0.5,
            strength: 2000.0 / 80.0,
            range: 0.08,
            max_speed_factor: 1.3,
            goal_reached: 0.3,
            fluctuation: 0.05,
        }
    }
}

/// One walker of a crowd: its body radius, goals, desired speed and state.
#[derive(Debug, Clone)]
pub struct Walker {
    /// Body radius \[m\].
    pub radius: f64,
    goals: Vec<[f64; 2]>,
    next: usize,
    desired_speed: f64,
    /// Position \[m\].
    pub position: [f64; 2],
    /// Velocity \[m/s\].
    pub velocity: [f64; 2],
    rng: ChaCha8Rng,
}

impl Walker {
    /// A walker at `position` with body `radius`, heading for `goals` in turn at about `speed`
    /// (its desired speed drawn once from N(speed, (0.1 speed)²), kept within ±20 %, from `seed`).
    pub fn new(
        position: [f64; 2],
        radius: f64,
        goals: &[[f64; 2]],
        speed: f64,
        seed: u64,
    ) -> Result<Walker, MotionError> {
        if goals.is_empty() {
            return Err(MotionError::NoGoals);
        }
        let speed = positive("speed", speed)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let jitter: f64 = Normal::new(1.0, 0.1).map_or(1.0, |n| n.sample(&mut rng));
        Ok(Walker {
            radius,
            goals: goals.to_vec(),
            next: 0,
            desired_speed: speed * jitter.clamp(0.8, 1.2),
            position,
            velocity: [0.0, 0.0],
            rng,
        })
    }

    /// The speed this walker wants \[m/s\].
    pub fn desired_speed(&self) -> f64 {
        self.desired_speed
    }

    /// The largest speed it can reach \[m/s\].
    pub fn max_speed(&self, model: &SocialForce) -> f64 {
        model.max_speed_factor * self.desired_speed
    }

    /// The goal it heads for now.
    pub fn goal(&self) -> [f64; 2] {
        self.goals[self.next]
    }
}

/// Advances every walker of `crowd` by `dt` \[s\] (semi-implicit Euler): each is pushed toward
/// its goal, away from the static obstacles, from the other walkers and, when `avoid` is
/// given, from that point (the robot) with `avoid_radius`. All accelerations are computed from
/// the same positions before any walker moves, so the order of the crowd does not matter.
pub fn step_crowd(
    crowd: &mut [Walker],
    model: &SocialForce,
    statics: &dyn Surroundings,
    avoid: Option<([f64; 2], f64)>,
    dt: f64,
) {
    let repulse = |gap: f64| model.strength * (-gap / model.range).exp();
    let see = 10.0 * model.range + 1.0;
    let mut accel = Vec::with_capacity(crowd.len());
    for (i, w) in crowd.iter().enumerate() {
        let to_goal = sub(w.goal(), w.position);
        let d = norm(to_goal);
        let e = if d > 0.0 {
            [to_goal[0] / d, to_goal[1] / d]
        } else {
            [0.0, 0.0]
        };
        let mut a = [
            (w.desired_speed * e[0] - w.velocity[0]) / model.tau,
            (w.desired_speed * e[1] - w.velocity[1]) / model.tau,
        ];
        for (dist, n) in statics.near(w.position, see) {
            let f = repulse(dist - w.radius);
            a = [a[0] + f * n[0], a[1] + f * n[1]];
        }
        let others = crowd
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .map(|(_, o)| (o.position, o.radius))
            .chain(avoid);
        for (p, r) in others {
            let away = sub(w.position, p);
            let dist = norm(away);
            if dist > 0.0 && dist - r - w.radius < see {
                let f = repulse(dist - r - w.radius);
                a = [a[0] + f * away[0] / dist, a[1] + f * away[1] / dist];
            }
        }
        accel.push(a);
    }
    let noise = Normal::new(0.0, model.fluctuation).ok();
    for (w, a) in crowd.iter_mut().zip(accel) {
        let mut xi = [0.0, 0.0];
        if let Some(n) = noise {
            xi = [n.sample(&mut w.rng), n.sample(&mut w.rng)];
        }
        let mut v = [
            w.velocity[0] + (a[0] + xi[0]) * dt,
            w.velocity[1] + (a[1] + xi[1]) * dt,
        ];
        let cap = w.max_speed(model);
        let s = norm(v);
        if s > cap {
            v = [v[0] * cap / s, v[1] * cap / s];
        }
        w.velocity = v;
        w.position = [w.position[0] + v[0] * dt, w.position[1] + v[1] * dt];
        if norm(sub(w.goal(), w.position)) < model.goal_reached {
            w.next = (w.next + 1) % w.goals.len();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 2], b: [f64; 2], tol: f64) -> bool {
        norm(sub(a, b)) <= tol
    }

    #[test]
    fn waypoints_loop_reverse_and_once_at_their_speed() {
        let square = [[1.0, 0.0], [1.0, 1.0]];
        let lp = Trajectory::waypoints([0.0, 0.0], &square, 0.5, Repeat::Loop, 2.0).unwrap();
        // Before the start it stands at its own position.
        assert_eq!(lp.state(1.0), ([0.0, 0.0], [0.0, 0.0]));
        // 1 s after the start: 0.5 m along the first leg, moving +x at 0.5 m/s.
        let (p, v) = lp.state(3.0);
        assert!(close(p, [0.5, 0.0], 1e-12) && close(v, [0.5, 0.0], 1e-12));
        // Legs 1 + 1 + √2 m: the period is (2 + √2) / 0.5 s; one period later, the same place.
        let period = (2.0 + 2f64.sqrt()) / 0.5;
        assert!(close(lp.state(3.0 + period).0, p, 1e-9));
        // On the closing leg, heading back to the origin along the diagonal.
        let (p, v) = lp.state(2.0 + 4.0 + 1.0);
        let u = 0.5 / 2f64.sqrt();
        assert!(close(p, [1.0 - u, 1.0 - u], 1e-9) && close(v, [-u, -u], 1e-9));

        let rev = Trajectory::waypoints([0.0, 0.0], &square, 0.5, Repeat::Reverse, 0.0).unwrap();
        // Out 2 m in 4 s, back along the same legs: at 5 s it is 0.5 m down the second leg.
        let (p, v) = rev.state(5.0);
        assert!(close(p, [1.0, 0.5], 1e-12) && close(v, [0.0, -0.5], 1e-12));
        assert!(close(rev.state(8.0).0, [0.0, 0.0], 1e-12));

        let once = Trajectory::waypoints([0.0, 0.0], &square, 0.5, Repeat::Once, 0.0).unwrap();
        assert_eq!(once.state(100.0), ([1.0, 1.0], [0.0, 0.0]));
        assert_eq!(once.max_speed(), 0.5);
    }

    #[test]
    fn a_constant_velocity_and_bad_values() {
        let t = Trajectory::Velocity {
            origin: [1.0, 2.0],
            velocity: [0.3, -0.4],
        };
        assert_eq!(t.state(2.0), ([1.6, 1.2], [0.3, -0.4]));
        assert!((t.max_speed() - 0.5).abs() < 1e-12);
        assert_eq!(
            Trajectory::waypoints([0.0, 0.0], &[], 1.0, Repeat::Loop, 0.0),
            Err(MotionError::NoPoints)
        );
        let e =
            Trajectory::waypoints([0.0, 0.0], &[[1.0, 0.0]], -1.0, Repeat::Loop, 0.0).unwrap_err();
        assert_eq!(
            e.to_string(),
            "`speed`: expected a positive speed in m/s, found -1"
        );
        assert!(Walker::new([0.0, 0.0], 0.2, &[], 1.0, 0).is_err());
    }

    /// A wall along y = 1 (the half-plane y ≥ 1).
    struct Wall;
    impl Surroundings for Wall {
        fn near(&self, p: [f64; 2], range: f64) -> Vec<(f64, [f64; 2])> {
            let d = 1.0 - p[1];
            if d < range {
                vec![(d, [0.0, -1.0])]
            } else {
                vec![]
            }
        }
    }

    /// Nothing around.
    struct Open;
    impl Surroundings for Open {
        fn near(&self, _: [f64; 2], _: f64) -> Vec<(f64, [f64; 2])> {
            vec![]
        }
    }

    #[test]
    fn a_walker_reaches_its_goals_in_turn_at_about_its_speed() {
        let model = SocialForce::default();
        let mut crowd = [Walker::new([0.0, 0.0], 0.25, &[[5.0, 0.0], [0.0, 0.0]], 1.0, 7).unwrap()];
        let v0 = crowd[0].desired_speed();
        assert!((0.8..=1.2).contains(&v0), "{v0}");
        let mut turned = None;
        for k in 0..2000 {
            step_crowd(&mut crowd, &model, &Open, None, 0.01);
            if turned.is_none() && crowd[0].goal() == [0.0, 0.0] {
                turned = Some(k as f64 * 0.01);
            }
            assert!(norm(crowd[0].velocity) <= 1.3 * v0 + 1e-12);
        }
        // 4.7 m to the turn at v0 (plus about τ to get up to speed).
        let t = turned.expect("reached the first goal");
        let expected = (5.0 - model.goal_reached) / v0 + model.tau;
        assert!(
            (t - expected).abs() < 0.5,
            "turned at {t} s, expected about {expected} s"
        );
    }

    #[test]
    fn walkers_keep_off_a_wall_and_each_other_and_the_same_seed_walks_the_same() {
        let model = SocialForce::default();
        let make = |seed| {
            vec![
                Walker::new([0.0, 0.6], 0.25, &[[6.0, 0.6]], 1.2, seed).unwrap(),
                Walker::new([6.0, 0.5], 0.25, &[[0.0, 0.5]], 1.2, seed + 1).unwrap(),
            ]
        };
        let walk = |seed| {
            let mut crowd = make(seed);
            let mut closest = f64::INFINITY;
            let mut wall = f64::INFINITY;
            for _ in 0..1500 {
                step_crowd(&mut crowd, &model, &Wall, None, 0.01);
                let gap = norm(sub(crowd[0].position, crowd[1].position)) - 0.5;
                closest = closest.min(gap);
                for w in &crowd {
                    wall = wall.min(1.0 - w.position[1] - w.radius);
                }
            }
            (crowd[0].position, crowd[1].position, closest, wall)
        };
        let (a0, b0, closest, wall) = walk(3);
        // Head-on in a corridor against a wall: they pass without their bodies overlapping
        // and without entering the wall.
        assert!(closest > 0.0, "bodies overlapped: gap {closest}");
        assert!(wall > -0.02, "a walker entered the wall by {}", -wall);
        assert!(
            a0[0] > 5.0 && b0[0] < 1.0,
            "they did not pass: {a0:?} {b0:?}"
        );
        let (a1, b1, ..) = walk(3);
        assert_eq!((a0, b0), (a1, b1), "same seed, same walk");
        let (a2, ..) = walk(4);
        assert_ne!(a0, a2, "another seed, another walk");
    }

    #[test]
    fn a_slow_walker_keeps_about_its_comfort_gap_from_a_robot_in_its_way() {
        // A walker at 0.1 m/s heading straight through a robot standing in its way, for 60 s:
        // it comes no nearer than about where the robot's push matches its goal's pull (within
        // 5 cm: its fluctuation jostles it), whatever its seed.
        let model = SocialForce::default();
        let comfort = model.comfort_gap(0.1);
        assert!((comfort - 0.386).abs() < 1e-3, "{comfort}");
        for seed in 1..=5 {
            let mut crowd = [Walker::new([0.0, 0.0], 0.2, &[[4.0, 0.0]], 0.1, seed).unwrap()];
            let robot = ([2.0, 0.0], 0.1);
            let mut closest = f64::INFINITY;
            for _ in 0..6000 {
                step_crowd(&mut crowd, &model, &Open, Some(robot), 0.01);
                closest =
                    closest.min(norm(sub(crowd[0].position, robot.0)) - crowd[0].radius - robot.1);
            }
            assert!((closest - comfort).abs() < 0.05, "seed {seed}: {closest} m");
        }
    }

    #[test]
    fn a_walker_told_to_avoid_the_robot_keeps_off_it() {
        let model = SocialForce::default();
        let run = |avoid: bool| {
            let mut crowd = [Walker::new([0.0, 0.0], 0.25, &[[4.0, 0.0]], 1.0, 1).unwrap()];
            let robot = ([2.0, 0.05], 0.2);
            let mut closest = f64::INFINITY;
            for _ in 0..600 {
                step_crowd(&mut crowd, &model, &Open, avoid.then_some(robot), 0.01);
                closest =
                    closest.min(norm(sub(crowd[0].position, robot.0)) - crowd[0].radius - robot.1);
            }
            closest
        };
        assert!(run(true) > 0.0, "an avoiding walker touched the robot");
        assert!(
            run(false) < 0.0,
            "a walker that does not avoid walks through the robot's place"
        );
    }
}

//! Movers for the generator's moving-obstacle kinds (issue #51): a cart crossing the robot's
//! route on an aisle, a walker coming down a corridor, two people crossing a room, and small
//! cylinders going round waypoint loops at 0.1 m/s as the TurtleBot3 DQN stages' obstacle
//! plugins move theirs (ROBOTIS turtlebot3_gazebo: obstacle1/obstacle2, 0.1 m/s, radius 0.12 m).
//!
//! Movers are placed relative to the planned route (start → path → goal) and kept where they
//! cannot pin the robot (`ftcbf check`'s pinning hypotheses): a scripted mover's whole path
//! and a walker's legs between its goals keep [`Scene::room`] between the mover's body and
//! every static obstacle, and two movers of one world keep [`Scene::apart`] between their
//! bodies wherever either goes (their swept paths, regardless of time); no mover comes within
//! reach of the robot's start in the first seconds. The room is what `check` asks — the
//! robot's diameter and the distance each barrier keeps with the robot at rest, the margin
//! from a static obstacle and margin + k_m·v_o from a mover — with those taken at
//! [`STATIC_SIDE`] and [`MOVER_SIDE`], above what generated worlds give (a test checks every
//! generated mover against `check`).
//! Speeds stay at or below 0.14 m/s (a walker's desired speed at or below 0.12 m/s, so its
//! largest, 1.56 ×, stays below the burger's 0.22 m/s): people at a shuffle, carts at a crawl —
//! the movers a TurtleBot3 can get out of the way of (`ftcbf check` says so per world).
//! Draws come from their own stream, so a world's static layout is the same as without movers.

use rand::Rng;

use super::layout::pick;
use super::text::{dec, list, num, Obstacle, Shape};
use super::Kind;
use crate::movers::{polyline_points, Repeat, Trajectory};
use crate::obstacles::{BarrierConfig, ObstacleBarrier};

/// A mover as written: the obstacle and its `motion = { … }` text.
pub(crate) type Mover = (Obstacle, String);

/// What the movers are placed among.
pub(crate) struct Scene<'a> {
    /// The static obstacles' bare geometry (no footprint, no margin).
    pub statics: &'a [ObstacleBarrier],
    /// Start, then the planned points, the goal last.
    pub route: Vec<[f64; 2]>,
    /// The robot's footprint radius \[m\].
    pub footprint: f64,
    /// The goal's radius \[m\].
    pub goal_radius: f64,
    /// The room a mover's body keeps from a static obstacle \[m\] ([`room_for`]).
    pub room: f64,
    /// The room two movers' bodies keep from each other \[m\] ([`room_for`]).
    pub apart: f64,
}

/// What a static obstacle's barrier keeps from it with the robot at rest, the margin (0.02 m
/// by default), taken at \[m\]:
pub(crate) const STATIC_SIDE: f64 = 0.05;
/// What a mover's barrier keeps from it with the robot at rest, margin + k_m·v_o (at most
/// 0.02 + 1.5 s × 0.14 m/s for the generated movers' speeds), taken at \[m\]:
pub(crate) const MOVER_SIDE: f64 = 0.25;

/// The rooms ([`Scene::room`], [`Scene::apart`]) for a robot of footprint radius `footprint`:
/// its diameter, each side's distance ([`STATIC_SIDE`], [`MOVER_SIDE`]) and 5 cm.
pub(crate) fn room_for(footprint: f64) -> (f64, f64) {
    let d = 2.0 * footprint + 0.05;
    (d + STATIC_SIDE + MOVER_SIDE, d + 2.0 * MOVER_SIDE)
}

/// The geometry settings of the static obstacles as movers see them.
pub(crate) fn bare_config() -> BarrierConfig {
    BarrierConfig {
        robot_radius: 0.0,
        centre_height: 0.2,
        margin: 0.0,
        k: 0.0,
        v_max: 0.0,
        fd_step: 2e-3,
    }
}

impl Scene<'_> {
    /// A body of radius `r` at `p` keeps [`Scene::room`] from every static obstacle.
    fn clear(&self, p: [f64; 2], r: f64) -> bool {
        let q = nalgebra::Vector2::new(p[0], p[1]);
        self.statics.iter().all(|b| b.clearance(q) >= r + self.room)
    }

    fn segment_clear(&self, a: [f64; 2], b: [f64; 2], r: f64) -> bool {
        polyline_points(&[a, b], false, 0.05)
            .into_iter()
            .all(|p| self.clear(p, r))
    }

    /// The point at fraction `f` of the route's length and the unit tangent there.
    fn at(&self, f: f64) -> ([f64; 2], [f64; 2]) {
        let legs: Vec<f64> = self
            .route
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .collect();
        let mut s = f * legs.iter().sum::<f64>();
        for (w, &len) in self.route.windows(2).zip(&legs) {
            if s <= len && len > 0.0 {
                let t = [(w[1][0] - w[0][0]) / len, (w[1][1] - w[0][1]) / len];
                return ([w[0][0] + t[0] * s, w[0][1] + t[1] * s], t);
            }
            s -= len;
        }
        let n = self.route.len();
        (self.route[n - 1], [1.0, 0.0])
    }

    /// Far enough from the robot's start for the first seconds.
    fn off_start(&self, p: [f64; 2], r: f64) -> bool {
        let s = self.route[0];
        (p[0] - s[0]).hypot(p[1] - s[1]) >= self.footprint + r + 0.4
    }

    /// The segment across the route at `p` (normal `n`), as long as it can be up to `half`
    /// on each side (at least 0.5 m) with its whole length clear for a body of radius `r`.
    fn across(&self, p: [f64; 2], n: [f64; 2], half: f64, r: f64) -> Option<([f64; 2], [f64; 2])> {
        let mut l = half;
        while l >= 0.5 {
            let a = [p[0] - n[0] * l, p[1] - n[1] * l];
            let b = [p[0] + n[0] * l, p[1] + n[1] * l];
            if self.segment_clear(a, b, r) {
                return Some((a, b));
            }
            l -= 0.1;
        }
        None
    }
}

fn cylinder(name: &str, p: [f64; 2], r: f64, half_height: f64) -> Obstacle {
    Obstacle {
        name: name.into(),
        position: [dec(p[0], 2), dec(p[1], 2), half_height],
        yaw: 0.0,
        shape: Shape::Cylinder {
            radius: r,
            half_height,
        },
    }
}

fn round2(p: [f64; 2]) -> [f64; 2] {
    [dec(p[0], 2), dec(p[1], 2)]
}

fn waypoints(points: &[[f64; 2]], speed: f64, repeat: &str) -> String {
    let pts: Vec<String> = points.iter().map(|p| list(p)).collect();
    format!(
        "{{ kind = \"waypoints\", points = [{}], speed = {}, repeat = \"{repeat}\" }}",
        pts.join(", "),
        num(speed)
    )
}

fn walker(goals: &[[f64; 2]], speed: f64) -> String {
    let gs: Vec<String> = goals.iter().map(|p| list(p)).collect();
    format!(
        "{{ kind = \"walker\", goals = [{}], speed = {} }}",
        gs.join(", "),
        num(speed)
    )
}

/// A scripted mover keeps off the start for its first 5 s.
fn scripted_off_start(
    scene: &Scene<'_>,
    from: [f64; 2],
    points: &[[f64; 2]],
    speed: f64,
    repeat: Repeat,
    r: f64,
) -> bool {
    let Ok(t) = Trajectory::waypoints(from, points, speed, repeat, 0.0) else {
        return false;
    };
    (0..=50).all(|k| scene.off_start(t.state(k as f64 * 0.1).0, r))
}

/// A cart going up and down an aisle across the route (up to 30 places tried).
fn cart<R: Rng>(rng: &mut R, scene: &Scene<'_>) -> Option<Mover> {
    let r = pick(rng, 0.1, 0.2, 0.01);
    let speed = pick(rng, 0.05, 0.14, 0.01);
    for _ in 0..60 {
        let (p, t) = scene.at(pick(rng, 0.25, 0.75, 0.01));
        let Some((a, b)) = scene.across(p, [-t[1], t[0]], pick(rng, 0.8, 1.5, 0.1), r) else {
            continue;
        };
        let (a, b) = if rng.random_bool(0.5) { (a, b) } else { (b, a) };
        let (a, b) = (round2(a), round2(b));
        if scripted_off_start(scene, a, &[b], speed, Repeat::Reverse, r) {
            return Some((
                cylinder("cart", a, r, 0.3),
                waypoints(&[b], speed, "reverse"),
            ));
        }
    }
    None
}

/// The swept paths (centres every 5 cm) and body radii of the movers placed so far.
type Placed = Vec<(Vec<[f64; 2]>, f64)>;

/// A body of radius `r` along `path` keeps `room` from every placed mover's body, wherever
/// either is on its path.
fn apart(placed: &Placed, path: &[[f64; 2]], r: f64, room: f64) -> bool {
    placed.iter().all(|(q, rq)| {
        path.iter().all(|a| {
            q.iter()
                .all(|b| (a[0] - b[0]).hypot(a[1] - b[1]) >= r + rq + room)
        })
    })
}

/// A person of radius 0.2 m walking between `goals`, starting at the first, on a leg clear of
/// the static obstacles and apart from the movers `placed`.
fn person<R: Rng>(
    rng: &mut R,
    scene: &Scene<'_>,
    placed: &Placed,
    name: &str,
    goals: [[f64; 2]; 2],
) -> Option<(Mover, Vec<[f64; 2]>)> {
    let r = 0.2;
    let speed = pick(rng, 0.06, 0.12, 0.01);
    let [a, b] = [round2(goals[0]), round2(goals[1])];
    let path = polyline_points(&[a, b], false, 0.05);
    (scene.segment_clear(a, b, r) && scene.off_start(a, r) && apart(placed, &path, r, scene.apart))
        .then(|| ((cylinder(name, a, r, 0.85), walker(&[b, a], speed)), path))
}

/// A small cylinder going round a loop of 3–4 clear points near the route at 0.1 m/s, apart
/// from the movers `placed`.
fn looper<R: Rng>(
    rng: &mut R,
    scene: &Scene<'_>,
    placed: &Placed,
    name: &str,
    around: f64,
) -> Option<(Mover, Vec<[f64; 2]>)> {
    let r = 0.12;
    let (c, _) = scene.at(around);
    for _ in 0..40 {
        let n = rng.random_range(3..=4);
        let pts: Vec<[f64; 2]> = (0..n)
            .map(|_| {
                round2([
                    c[0] + pick(rng, -1.2, 1.2, 0.01),
                    c[1] + pick(rng, -1.2, 1.2, 0.01),
                ])
            })
            .collect();
        let closed: Vec<[f64; 2]> = pts.iter().chain(pts.first()).copied().collect();
        let ok = closed
            .windows(2)
            .all(|w| scene.segment_clear(w[0], w[1], r))
            && scripted_off_start(scene, pts[0], &pts[1..], 0.1, Repeat::Loop, r);
        let path = polyline_points(&pts, true, 0.05);
        if ok && apart(placed, &path, r, scene.apart) {
            return Some((
                (
                    cylinder(name, pts[0], r, 0.25),
                    waypoints(&pts[1..], 0.1, "loop"),
                ),
                path,
            ));
        }
    }
    None
}

/// Keeps mover `m` of body radius `r`, if drawn, with its swept path.
fn keep(m: Option<(Mover, Vec<[f64; 2]>)>, r: f64, out: &mut Vec<Mover>, placed: &mut Placed) {
    if let Some((m, path)) = m {
        out.push(m);
        placed.push((path, r));
    }
}

/// The movers of a moving-obstacle `kind` (empty for the static kinds, or where none fits).
pub(crate) fn draw<R: Rng>(rng: &mut R, kind: Kind, scene: &Scene<'_>) -> Vec<Mover> {
    let mut out = Vec::new();
    let mut placed: Placed = Vec::new();
    match kind {
        Kind::AisleCrossing => out.extend(cart(rng, scene)),
        Kind::CorridorWalker => {
            // Down the route from near the goal towards the start, and back: the longest leg
            // that fits, shifted sideways off the route if that is where the room is.
            let goal = scene.route[scene.route.len() - 1];
            let far_ok = |p: &[f64; 2]| {
                (p[0] - goal[0]).hypot(p[1] - goal[1])
                    >= 0.2 + scene.footprint + scene.goal_radius + 0.1
            };
            let legs = [0.85, 0.8, 0.75, 0.7, 0.65].into_iter().flat_map(|f| {
                [0.2, 0.3, 0.4].into_iter().flat_map(move |g| {
                    [0.0, 0.1, -0.1, 0.2, -0.2, 0.3, -0.3].map(|off| (f, g, off))
                })
            });
            for (f, g, off) in legs {
                let (far, near) = (scene.at(f).0, scene.at(g).0);
                let len = (near[0] - far[0]).hypot(near[1] - far[1]);
                if !far_ok(&far) || len < 1.0 {
                    continue;
                }
                let n = [-(near[1] - far[1]) / len, (near[0] - far[0]) / len];
                let shift = |p: [f64; 2]| [p[0] + n[0] * off, p[1] + n[1] * off];
                let m = person(rng, scene, &placed, "person", [shift(far), shift(near)]);
                if m.is_some() {
                    keep(m, 0.2, &mut out, &mut placed);
                    break;
                }
            }
        }
        Kind::RoomPeople => {
            for (name, lo, hi) in [("person_a", 0.2, 0.5), ("person_b", 0.5, 0.8)] {
                for _ in 0..30 {
                    let (p, t) = scene.at(pick(rng, lo, hi, 0.01));
                    let half = pick(rng, 0.9, 1.4, 0.1);
                    let Some((a, b)) = scene.across(p, [-t[1], t[0]], half, 0.2) else {
                        continue;
                    };
                    let (a, b) = if rng.random_bool(0.5) { (a, b) } else { (b, a) };
                    let m = person(rng, scene, &placed, name, [a, b]);
                    if m.is_some() {
                        keep(m, 0.2, &mut out, &mut placed);
                        break;
                    }
                }
            }
        }
        Kind::DqnLoops => {
            for (name, f) in [("obstacle1", 0.4), ("obstacle2", 0.7)] {
                let m = looper(rng, scene, &placed, name, f);
                keep(m, 0.12, &mut out, &mut placed);
            }
        }
        _ => {}
    }
    out
}

//! Scenes drawn as a user lays them out: rooms, straight corridors, doorways, clutter fields and
//! L turns, with sizes and positions from the ranges people type (0.05 m steps for positions,
//! walls 10–20 cm thick, doors 0.7–1.2 m wide, corridors 0.8–2 m wide). Nothing here knows
//! what the controller handles; the generator only rejects a layout whose goal the planner
//! cannot reach with the required clearance (see [`super::SPARE`]).

use rand::Rng;

use super::text::{dec, Obstacle, Shape};
use super::Kind;

/// A drawn scene: obstacles, start and goal positions.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Layout {
    pub obstacles: Vec<Obstacle>,
    pub start: [f64; 2],
    pub goal: [f64; 2],
    /// One phrase for the file's header, e.g. "a 5.5 × 4 m room with 3 pieces of furniture".
    pub summary: String,
}

/// A number in [lo, hi] on the grid of multiples of `step` (as typed: 0.05 m, 0.5 m, 1e-4
/// rad/s/√s, …), rounded to 6 places so that it is written as typed (the first multiple above `lo`
/// when none lies in the range).
pub(crate) fn pick<R: Rng>(rng: &mut R, lo: f64, hi: f64, step: f64) -> f64 {
    let a = (lo / step - 1e-9).ceil() as i64;
    let b = ((hi / step + 1e-9).floor() as i64).max(a);
    let k = rng.random_range(a..=b);
    dec(k as f64 * step, 6)
}

/// Distance from `p` to the obstacle's footprint on the floor (negative inside) \[m\]: only for
/// keeping furniture off the start and goal while drawing; the acceptance test uses the
/// project's own obstacle barriers.
fn footprint_distance(o: &Obstacle, p: [f64; 2]) -> f64 {
    let (dx, dy) = (p[0] - o.position[0], p[1] - o.position[1]);
    match o.shape {
        Shape::Cuboid(h) => {
            let (c, s) = (o.yaw.cos(), o.yaw.sin());
            let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
            let (qx, qy) = (lx.abs() - h[0], ly.abs() - h[1]);
            qx.max(0.0).hypot(qy.max(0.0)) + qx.max(qy).min(0.0)
        }
        Shape::Cylinder { radius, .. } | Shape::Ball { radius } => dx.hypot(dy) - radius,
    }
}

/// What drawing needs to know: the keep-out radii around the start and the goal (the robot's
/// footprint, the required spare and, for the goal, the goal radius).
#[derive(Debug, Clone, Copy)]
pub(crate) struct KeepOut {
    pub start: f64,
    pub goal: f64,
}

struct Scene {
    obstacles: Vec<Obstacle>,
    start: [f64; 2],
    goal: [f64; 2],
    keep: KeepOut,
}

impl Scene {
    fn new(start: [f64; 2], goal: [f64; 2], keep: KeepOut) -> Self {
        Self {
            obstacles: Vec::new(),
            start,
            goal,
            keep,
        }
    }

    fn wall(&mut self, name: &str, from: [f64; 2], to: [f64; 2], half_t: f64, half_h: f64) {
        // axis-aligned: from–to along x or along y
        let c = [
            dec((from[0] + to[0]) / 2.0, 3),
            dec((from[1] + to[1]) / 2.0, 3),
        ];
        let hx = dec((to[0] - from[0]).abs() / 2.0, 3).max(half_t);
        let hy = dec((to[1] - from[1]).abs() / 2.0, 3).max(half_t);
        self.obstacles.push(Obstacle {
            name: name.to_string(),
            position: [c[0], c[1], half_h],
            yaw: 0.0,
            shape: Shape::Cuboid([hx, hy, half_h]),
        });
    }

    /// Adds `o` unless it covers the start's or the goal's keep-out disc.
    fn place(&mut self, o: Obstacle) -> bool {
        if footprint_distance(&o, self.start) < self.keep.start
            || footprint_distance(&o, self.goal) < self.keep.goal
        {
            return false;
        }
        self.obstacles.push(o);
        true
    }

    /// Tries up to 30 positions from `at` for `make(position)`; returns whether one was placed.
    fn place_somewhere<R: Rng>(
        &mut self,
        rng: &mut R,
        mut at: impl FnMut(&mut R) -> [f64; 2],
        make: impl Fn([f64; 2]) -> Obstacle,
    ) -> bool {
        (0..30).any(|_| {
            let p = at(rng);
            self.place(make(p))
        })
    }

    fn finish(self, summary: String) -> Layout {
        Layout {
            obstacles: self.obstacles,
            start: self.start,
            goal: self.goal,
            summary,
        }
    }
}

/// A wall's half thickness \[m\]: 10 cm or 20 cm walls.
fn wall_half_thickness<R: Rng>(rng: &mut R) -> f64 {
    if rng.random_bool(0.7) {
        0.05
    } else {
        0.1
    }
}

/// A wall's half height \[m\].
fn wall_half_height<R: Rng>(rng: &mut R) -> f64 {
    pick(rng, 0.2, 0.5, 0.05)
}

/// A small yaw a user gives a piece of furniture now and then (else 0).
fn maybe_yaw<R: Rng>(rng: &mut R, p: f64) -> f64 {
    if rng.random_bool(p) {
        pick(rng, -0.6, 0.6, 0.05)
    } else {
        0.0
    }
}

/// `o` moved to the floor position `p`.
fn at(o: &Obstacle, p: [f64; 2]) -> Obstacle {
    let mut o = o.clone();
    o.position[0] = p[0];
    o.position[1] = p[1];
    o
}

/// One piece of movable clutter: a box, a bin or a ball.
fn clutter_item<R: Rng>(rng: &mut R, name: String, p: [f64; 2]) -> Obstacle {
    match rng.random_range(0..3) {
        0 => {
            let hh = pick(rng, 0.1, 0.4, 0.05);
            Obstacle {
                name,
                position: [p[0], p[1], hh],
                yaw: maybe_yaw(rng, 0.4),
                shape: Shape::Cuboid([pick(rng, 0.1, 0.35, 0.05), pick(rng, 0.1, 0.35, 0.05), hh]),
            }
        }
        1 => {
            let hh = pick(rng, 0.15, 0.5, 0.05);
            Obstacle {
                name,
                position: [p[0], p[1], hh],
                yaw: 0.0,
                shape: Shape::Cylinder {
                    radius: pick(rng, 0.05, 0.25, 0.01),
                    half_height: hh,
                },
            }
        }
        _ => {
            let r = pick(rng, 0.1, 0.3, 0.01);
            Obstacle {
                name,
                position: [p[0], p[1], r],
                yaw: 0.0,
                shape: Shape::Ball { radius: r },
            }
        }
    }
}

/// A room: four walls, 1–4 pieces of furniture (tables, shelves against a wall, pillars,
/// chairs, round tables); start near one end, goal near the other.
fn room<R: Rng>(rng: &mut R, keep: KeepOut) -> Layout {
    let w = pick(rng, 3.0, 7.0, 0.5);
    let h = pick(rng, 2.5, 5.0, 0.5);
    let t = wall_half_thickness(rng);
    let hh = wall_half_height(rng);
    let start = [pick(rng, 0.5, 1.2, 0.05), pick(rng, 0.5, h - 0.5, 0.05)];
    let goal = [
        pick(rng, w - 1.2, w - 0.5, 0.05),
        pick(rng, 0.5, h - 0.5, 0.05),
    ];
    let mut s = Scene::new(start, goal, keep);
    s.wall("wall_1", [-t, 0.0], [w + t, 0.0], t, hh);
    s.wall("wall_2", [-t, h], [w + t, h], t, hh);
    s.wall("wall_3", [0.0, 0.0], [0.0, h], t, hh);
    s.wall("wall_4", [w, 0.0], [w, h], t, hh);
    let n = rng.random_range(1..=4);
    let mut placed = 0;
    for i in 0..n {
        let ok = match rng.random_range(0..5) {
            0 => {
                let (hx, hy, hz) = (
                    pick(rng, 0.3, 0.6, 0.05),
                    pick(rng, 0.2, 0.45, 0.05),
                    pick(rng, 0.2, 0.4, 0.05),
                );
                let yaw = maybe_yaw(rng, 0.3);
                s.place_somewhere(
                    rng,
                    |r| [pick(r, 0.5, w - 0.5, 0.05), pick(r, 0.5, h - 0.5, 0.05)],
                    |p| Obstacle {
                        name: format!("table_{}", i + 1),
                        position: [p[0], p[1], hz],
                        yaw,
                        shape: Shape::Cuboid([hx, hy, hz]),
                    },
                )
            }
            1 => {
                // a shelf against one of the long walls
                let (depth, len, hz) = (
                    pick(rng, 0.15, 0.25, 0.05),
                    pick(rng, 0.4, 1.0, 0.05),
                    pick(rng, 0.4, 0.9, 0.05),
                );
                let north = rng.random_bool(0.5);
                s.place_somewhere(
                    rng,
                    |r| [pick(r, len, w - len, 0.05), 0.0],
                    |p| {
                        let y = if north {
                            dec(h - t - depth, 3)
                        } else {
                            dec(t + depth, 3)
                        };
                        Obstacle {
                            name: format!("shelf_{}", i + 1),
                            position: [p[0], y, hz],
                            yaw: 0.0,
                            shape: Shape::Cuboid([len, depth, hz]),
                        }
                    },
                )
            }
            2 => {
                let (r0, hz) = (pick(rng, 0.08, 0.2, 0.01), pick(rng, 0.5, 1.0, 0.05));
                s.place_somewhere(
                    rng,
                    |r| [pick(r, 0.5, w - 0.5, 0.05), pick(r, 0.5, h - 0.5, 0.05)],
                    |p| Obstacle {
                        name: format!("pillar_{}", i + 1),
                        position: [p[0], p[1], hz],
                        yaw: 0.0,
                        shape: Shape::Cylinder {
                            radius: r0,
                            half_height: hz,
                        },
                    },
                )
            }
            3 => {
                let (a, hz) = (pick(rng, 0.2, 0.25, 0.01), pick(rng, 0.25, 0.45, 0.05));
                let yaw = maybe_yaw(rng, 0.5);
                s.place_somewhere(
                    rng,
                    |r| [pick(r, 0.5, w - 0.5, 0.05), pick(r, 0.5, h - 0.5, 0.05)],
                    |p| Obstacle {
                        name: format!("chair_{}", i + 1),
                        position: [p[0], p[1], hz],
                        yaw,
                        shape: Shape::Cuboid([a, a, hz]),
                    },
                )
            }
            _ => {
                let (r0, hz) = (pick(rng, 0.3, 0.5, 0.05), pick(rng, 0.35, 0.4, 0.05));
                s.place_somewhere(
                    rng,
                    |r| [pick(r, 0.6, w - 0.6, 0.05), pick(r, 0.6, h - 0.6, 0.05)],
                    |p| Obstacle {
                        name: format!("round_table_{}", i + 1),
                        position: [p[0], p[1], hz],
                        yaw: 0.0,
                        shape: Shape::Cylinder {
                            radius: r0,
                            half_height: hz,
                        },
                    },
                )
            }
        };
        placed += usize::from(ok);
    }
    let things = if placed == 1 { "piece" } else { "pieces" };
    s.finish(format!(
        "a {} × {} m room with {placed} {things} of furniture",
        w, h
    ))
}

/// A straight corridor between two walls, sometimes closed at the far end, with up to two
/// bins or boxes standing against its walls.
fn corridor<R: Rng>(rng: &mut R, keep: KeepOut) -> Layout {
    let len = pick(rng, 3.0, 8.0, 0.5);
    let w = pick(rng, 0.8, 2.0, 0.05);
    let t = wall_half_thickness(rng);
    let hh = wall_half_height(rng);
    let start = [
        pick(rng, 0.2, 0.6, 0.05),
        pick(rng, -w / 4.0, w / 4.0, 0.05),
    ];
    let goal = [
        pick(rng, len - 0.8, len - 0.4, 0.05),
        pick(rng, -w / 4.0, w / 4.0, 0.05),
    ];
    let mut s = Scene::new(start, goal, keep);
    let y = dec(w / 2.0 + t, 3);
    s.wall("left_wall", [0.0, y], [len, y], t, hh);
    s.wall("right_wall", [0.0, -y], [len, -y], t, hh);
    let closed = rng.random_bool(0.3);
    if closed {
        let x = dec(len + t, 3);
        s.wall("end_wall", [x, -y - t], [x, y + t], t, hh);
    }
    let n = rng.random_range(0..=2);
    let mut placed = 0;
    for i in 0..n {
        let left = rng.random_bool(0.5);
        let bin = rng.random_bool(0.5);
        let (a, b, hz) = (
            pick(rng, 0.1, 0.3, 0.05),
            pick(rng, 0.1, 0.3, 0.05),
            pick(rng, 0.2, 0.45, 0.05),
        );
        let side = if left { 1.0 } else { -1.0 };
        let ok = s.place_somewhere(
            rng,
            |r| [pick(r, 1.0, (len - 1.0).max(1.0), 0.05), 0.0],
            |p| {
                if bin {
                    Obstacle {
                        name: format!("bin_{}", i + 1),
                        position: [p[0], dec(side * (w / 2.0 - a), 3), hz],
                        yaw: 0.0,
                        shape: Shape::Cylinder {
                            radius: a,
                            half_height: hz,
                        },
                    }
                } else {
                    Obstacle {
                        name: format!("box_{}", i + 1),
                        position: [p[0], dec(side * (w / 2.0 - b), 3), hz],
                        yaw: 0.0,
                        shape: Shape::Cuboid([a, b, hz]),
                    }
                }
            },
        );
        placed += usize::from(ok);
    }
    s.finish(format!(
        "a {len} m corridor {w} m wide{}{}",
        if closed {
            ", closed at the far end"
        } else {
            ""
        },
        match placed {
            0 => String::new(),
            1 => ", one thing against a wall".to_string(),
            k => format!(", {k} things against the walls"),
        }
    ))
}

/// A wall with a door in it; either free-standing or the partition of two walled rooms.
fn doorway<R: Rng>(rng: &mut R, keep: KeepOut) -> Layout {
    let d = pick(rng, 1.5, 3.0, 0.5);
    let half_span = pick(rng, 1.5, 3.0, 0.5);
    let door = pick(rng, 0.7, 1.2, 0.05);
    let yd = pick(
        rng,
        -half_span + door / 2.0 + 0.3,
        half_span - door / 2.0 - 0.3,
        0.05,
    );
    let t = wall_half_thickness(rng);
    let hh = wall_half_height(rng);
    let enclosed = rng.random_bool(0.5);
    let far = if enclosed {
        dec(d + pick(rng, 1.5, 3.0, 0.5), 3)
    } else {
        d + 2.0
    };
    let (x0, x1) = if enclosed {
        (
            pick(rng, 0.5, d - 0.6, 0.05),
            pick(rng, d + 0.6, far - 0.5, 0.05),
        )
    } else {
        (
            pick(rng, d - 2.0, d - 0.6, 0.05),
            pick(rng, d + 0.6, d + 2.0, 0.05),
        )
    };
    let start = [x0, pick(rng, -half_span + 0.5, half_span - 0.5, 0.05)];
    let goal = [x1, pick(rng, -half_span + 0.5, half_span - 0.5, 0.05)];
    let mut s = Scene::new(start, goal, keep);
    let lo = dec(yd - door / 2.0, 3);
    let hi = dec(yd + door / 2.0, 3);
    s.wall("wall_a", [d, -half_span], [d, lo], t, hh);
    s.wall("wall_b", [d, hi], [d, half_span], t, hh);
    if enclosed {
        s.wall("wall_1", [-t, -half_span], [far + t, -half_span], t, hh);
        s.wall("wall_2", [-t, half_span], [far + t, half_span], t, hh);
        s.wall("wall_3", [0.0, -half_span], [0.0, half_span], t, hh);
        s.wall("wall_4", [far, -half_span], [far, half_span], t, hh);
    }
    let n = rng.random_range(0..=2);
    let (xa, xb) = if enclosed {
        (0.3, far - 0.3)
    } else {
        (d - 2.0, d + 2.0)
    };
    let mut placed = 0;
    for i in 0..n {
        let proto = clutter_item(rng, format!("obstacle_{}", i + 1), [0.0, 0.0]);
        let ok = s.place_somewhere(
            rng,
            |r| {
                [
                    pick(r, xa, xb, 0.05),
                    pick(r, -half_span + 0.3, half_span - 0.3, 0.05),
                ]
            },
            |p| at(&proto, p),
        );
        placed += usize::from(ok);
    }
    // anything drawn across the door's own wall would close it; the planner decides
    s.finish(format!(
        "a wall with a {door} m door{}{}",
        if enclosed { " between two rooms" } else { "" },
        match placed {
            0 => String::new(),
            1 => ", one obstacle in the rooms".to_string(),
            k => format!(", {k} obstacles in the rooms"),
        }
    ))
}

/// A field of 4–12 boxes, bins and balls between the start and the goal, sometimes fenced.
fn clutter<R: Rng>(rng: &mut R, keep: KeepOut) -> Layout {
    let len = pick(rng, 3.0, 6.0, 0.5);
    let half_w = pick(rng, 1.0, 2.5, 0.5);
    let start = [
        pick(rng, -0.2, 0.2, 0.05),
        pick(rng, -half_w / 2.0, half_w / 2.0, 0.05),
    ];
    let goal = [
        pick(rng, len - 0.2, len + 0.2, 0.05),
        pick(rng, -half_w / 2.0, half_w / 2.0, 0.05),
    ];
    let mut s = Scene::new(start, goal, keep);
    let fenced = rng.random_bool(0.3);
    if fenced {
        let t = wall_half_thickness(rng);
        let hh = wall_half_height(rng);
        let y = half_w + 0.5;
        s.wall("fence_1", [-1.0, -y], [len + 1.0, -y], t, hh);
        s.wall("fence_2", [-1.0, y], [len + 1.0, y], t, hh);
    }
    let n = rng.random_range(4..=12);
    let mut placed = 0;
    for i in 0..n {
        let p = [
            pick(rng, 0.8, len - 0.8, 0.05),
            pick(rng, -half_w, half_w, 0.05),
        ];
        let o = clutter_item(rng, format!("obstacle_{}", i + 1), p);
        placed += usize::from(s.place(o));
    }
    s.finish(format!(
        "a {len} × {} m field with {placed} boxes, bins and balls{}",
        2.0 * half_w,
        if fenced { ", fenced on two sides" } else { "" }
    ))
}

/// An L-shaped corridor: a leg along x, a left or right turn, a leg along y; sometimes closed
/// behind the start and at the end.
fn l_turn<R: Rng>(rng: &mut R, keep: KeepOut) -> Layout {
    let w = pick(rng, 0.8, 1.6, 0.05);
    let l1 = pick(rng, 2.0, 5.0, 0.5);
    let l2 = pick(rng, 2.0, 4.5, 0.5);
    let t = wall_half_thickness(rng);
    let hh = wall_half_height(rng);
    let left = rng.random_bool(0.5);
    let m = if left { 1.0 } else { -1.0 }; // mirror of the turn
    let start = [
        pick(rng, 0.2, 0.6, 0.05),
        pick(rng, -w / 4.0, w / 4.0, 0.05),
    ];
    let goal = [
        dec(l1 + pick(rng, -w / 4.0, w / 4.0, 0.05), 3),
        dec(m * (l2 - pick(rng, 0.4, 0.8, 0.05)), 3),
    ];
    let mut s = Scene::new(start, goal, keep);
    let hw = w / 2.0;
    let back = -0.3;
    // outer and inner walls of the first leg, then of the second
    s.wall(
        "outer_wall_1",
        [back, dec(-m * (hw + t), 3)],
        [dec(l1 + hw + 2.0 * t, 3), dec(-m * (hw + t), 3)],
        t,
        hh,
    );
    s.wall(
        "inner_wall_1",
        [back, dec(m * (hw + t), 3)],
        [dec(l1 - hw, 3), dec(m * (hw + t), 3)],
        t,
        hh,
    );
    s.wall(
        "outer_wall_2",
        [dec(l1 + hw + t, 3), dec(-m * (hw + 2.0 * t), 3)],
        [dec(l1 + hw + t, 3), dec(m * l2, 3)],
        t,
        hh,
    );
    s.wall(
        "inner_wall_2",
        [dec(l1 - hw - t, 3), dec(m * hw, 3)],
        [dec(l1 - hw - t, 3), dec(m * l2, 3)],
        t,
        hh,
    );
    let closed = rng.random_bool(0.4);
    if closed {
        s.wall(
            "back_wall",
            [dec(back - t, 3), dec(-(hw + 2.0 * t), 3)],
            [dec(back - t, 3), dec(hw + 2.0 * t, 3)],
            t,
            hh,
        );
        s.wall(
            "end_wall",
            [dec(l1 - hw - 2.0 * t, 3), dec(m * (l2 + t), 3)],
            [dec(l1 + hw + 2.0 * t, 3), dec(m * (l2 + t), 3)],
            t,
            hh,
        );
    }
    let mut placed = 0;
    if rng.random_bool(0.5) {
        let (a, hz) = (pick(rng, 0.1, 0.25, 0.05), pick(rng, 0.2, 0.45, 0.05));
        let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let ok = s.place_somewhere(
            rng,
            |r| [pick(r, 1.0, (l1 - hw).max(1.0), 0.05), 0.0],
            |p| Obstacle {
                name: "box_1".into(),
                position: [p[0], dec(side * (hw - a), 3), hz],
                yaw: 0.0,
                shape: Shape::Cuboid([a, a, hz]),
            },
        );
        placed += usize::from(ok);
    }
    s.finish(format!(
        "an L-shaped corridor {w} m wide, {l1} m then a {} turn and {l2} m{}{}",
        if left { "left" } else { "right" },
        if closed { ", closed at both ends" } else { "" },
        if placed == 1 {
            ", a box on the way"
        } else {
            ""
        }
    ))
}

/// Turns the whole scene by `k` quarter turns about the origin (users lay out scenes along
/// either axis): positions rotate, boxes swap their x and y half extents (a box turned by a
/// quarter turn plus its yaw is the swapped box turned by its yaw).
fn quarter_turns(mut l: Layout, k: u32) -> Layout {
    let turn = |p: [f64; 2]| -> [f64; 2] {
        match k % 4 {
            0 => p,
            1 => [-p[1] + 0.0, p[0]],
            2 => [-p[0] + 0.0, -p[1] + 0.0],
            _ => [p[1], -p[0] + 0.0],
        }
    };
    l.start = turn(l.start);
    l.goal = turn(l.goal);
    for o in &mut l.obstacles {
        let [x, y] = turn([o.position[0], o.position[1]]);
        o.position[0] = x;
        o.position[1] = y;
        if k % 2 == 1 {
            if let Shape::Cuboid(h) = &mut o.shape {
                h.swap(0, 1);
            }
        }
    }
    l
}

/// Draws one layout of `kind`.
pub(crate) fn draw<R: Rng>(rng: &mut R, kind: Kind, keep: KeepOut) -> Option<Layout> {
    let l = match kind {
        Kind::Room => room(rng, keep),
        Kind::Corridor => corridor(rng, keep),
        Kind::Doorway => doorway(rng, keep),
        Kind::Clutter => clutter(rng, keep),
        Kind::LTurn => l_turn(rng, keep),
        // The moving-obstacle kinds are drawn in their static scene (`Kind::scene`).
        Kind::AisleCrossing => clutter(rng, keep),
        Kind::CorridorWalker => corridor(rng, keep),
        Kind::RoomPeople | Kind::DqnLoops => room(rng, keep),
        // a map's scene is the map (super::on_map), not drawn here
        Kind::Map => return None,
    };
    let k = rng.random_range(0..4);
    Some(quarter_turns(l, k))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng as _;

    #[test]
    fn picks_stay_on_their_grid_and_in_range() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut seen = std::collections::BTreeSet::new();
        for _ in 0..1000 {
            let x = pick(&mut rng, -0.3875, 0.3875, 0.05);
            assert!((-0.3875..=0.3875).contains(&x), "{x}");
            let k = (x / 0.05).round();
            assert!((x - k * 0.05).abs() < 1e-12, "{x}");
            seen.insert(k as i64);
        }
        // every multiple of 0.05 in the range: −0.35 … 0.35
        assert_eq!(seen, (-7..=7).collect());
    }

    #[test]
    fn a_quarter_turn_swaps_box_extents_and_keeps_clearances() {
        let keep = KeepOut {
            start: 0.3,
            goal: 0.4,
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let l = room(&mut rng, keep);
        let t = quarter_turns(l.clone(), 1);
        for (a, b) in l.obstacles.iter().zip(&t.obstacles) {
            assert_eq!(
                footprint_distance(a, l.start),
                footprint_distance(b, t.start)
            );
            if let (Shape::Cuboid(ha), Shape::Cuboid(hb)) = (a.shape, b.shape) {
                assert_eq!([ha[1], ha[0], ha[2]], hb);
            }
        }
    }

    #[test]
    fn furniture_keeps_off_the_start_and_goal() {
        let keep = KeepOut {
            start: 0.35,
            goal: 0.5,
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..50 {
            for kind in Kind::ALL {
                let l = draw(&mut rng, kind, keep).expect("a layout kind");
                for o in l.obstacles.iter().filter(|o| !o.name.contains("wall")) {
                    if o.name.starts_with("fence") {
                        continue;
                    }
                    assert!(footprint_distance(o, l.start) >= keep.start, "{o:?}");
                    assert!(footprint_distance(o, l.goal) >= keep.goal, "{o:?}");
                }
            }
        }
    }
}

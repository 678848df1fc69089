//! What `ftcbf check` says about moving obstacles (issue #51): which hypotheses of Theorem 3
//! their rows add, and whether the robot waits for a mover to pass or is blocked for good.
//!
//! **Safety.** A mover's row carries ∂h/∂t (see [`ftcbf_controller::MovingBarrier`]). At rest
//! on its boundary, a mover heading straight at the robot at speed v_o makes ∂h/∂t = −v_o − k·ā
//! (∇d unit, ∇_v h = k∇d), so the row asks k·u_n ≥ v_o + k·ā: an acceleration v_o/k + ā away
//! from it, which the input box must hold. And to keep d from falling for good the robot must
//! outrun it: v_o ≤ v_max. Either failing is a failed hypothesis, with the numbers. Not decided
//! (assumed, stated): that two movers do not pin the robot between them (the joint rows of
//! two moving barriers), the
//! velocity jumps at a path's corners (the row does not see them coming), and a walker's
//! acceleration bound, which covers the social force's driving term only.
//!
//! Two movers pinning the robot between them is decided as for a static obstacle: two
//! scripted movers at the same instants, every 5 cm of the faster one's travel; a walker
//! wherever its legs take it, whenever (it keeps no timetable), so against a walker the test
//! is on the swept paths and errs on the side of refusing.
//!
//! Decided since (the trials of a generated aisle crossing were unsafe where these were
//! assumed): a mover must not pin the robot against a static obstacle (somewhere on its path a
//! gap to a static obstacle narrower than the robot with its margins, 2(r + margin), and wider
//! than 0), and the drive must turn away in time (stopped on the mover's boundary, the robot
//! turns a quarter turn and accelerates to v_o while the mover closes in: that must fit in
//! margin + k·v_o).
//!
//! **Liveness** with movers is [`crate::movers::passage::liveness`] (in the liveness
//! prediction): a mover that ends its motion (`repeat = "once"`, or a zero velocity) where the
//! robot's path passes, or stands over the goal when the run ends, blocks it for good; so do
//! movers that keep coming back over the path where the robot, beside its path (its diameter,
//! or more for a mover that holds it out farther), finds no way past them in space and time
//! ([`crate::movers::passage`]); a mover that crosses the path and goes on makes the robot wait
//! for it to pass.

use crate::model::setup::{mover_lift, quarter_turn_time, ControlSetup};
use crate::movers::fleet::{max_speed, mover_indices};
use crate::obstacles::{BarrierConfig, MotionSpec, Obstacle, ObstacleBarrier, ShapeSpec};
use crate::world::structure::obstacle_barrier_config;
use crate::world::World;

/// One finding: (name, holds: Some(true) holds / Some(false) fails / None assumed or info,
/// whether it is only information, detail).
#[derive(Debug, Clone, PartialEq)]
pub struct MoverFinding {
    /// Short name.
    pub name: String,
    /// `Some(true)`: holds; `Some(false)`: fails (Theorem 3 does not apply); `None`: assumed.
    pub holds: Option<bool>,
    /// The numbers.
    pub detail: String,
}

/// The mover hypotheses of `world` (empty when nothing moves).
pub fn findings(world: &World, setup: &ControlSetup) -> Vec<MoverFinding> {
    let movers = mover_indices(&world.obstacles);
    if movers.is_empty() {
        return Vec::new();
    }
    let bcfg = obstacle_barrier_config(world);
    let v_max = bcfg.v_max;
    let limit = setup.config.input_limit.map(|l| l[0].min(l[1]));
    let mut out = Vec::new();
    for &i in &movers {
        let o = &world.obstacles[i];
        let v_o = max_speed(&o.spec);
        let walker = matches!(o.spec.motion, Some(MotionSpec::Walker { .. }));
        let a_bar = if walker {
            // (v_des + v_cap)/τ with the largest desired speed: see crate::moving.
            v_o * (1.0 / 1.3 + 1.0) / crate::movers::SocialForce::default().tau
        } else {
            0.0
        };
        out.push(MoverFinding {
            name: format!("mover `{}` can be escaped", o.name),
            holds: Some(v_o <= v_max),
            detail: if v_o <= v_max {
                format!(
                    "mover `{}` moves at up to {v_o:.3} m/s ≤ the robot's v_max = {v_max:.3} m/s",
                    o.name
                )
            } else {
                format!(
                    "mover `{}` moves at up to {v_o:.3} m/s, faster than the robot's v_max = {v_max:.3} m/s: it can catch a robot that flees, and no input keeps its barrier ≥ 0 (the guarantee does not apply with it)",
                    o.name
                )
            },
        });
        let k = mover_lift(world, &o.spec, &bcfg);
        if k > 0.0 {
            let need = v_o / k + a_bar;
            let (holds, detail) = match limit {
                Some(l) => (
                    Some(need <= l),
                    format!(
                        "at rest on its boundary with `{}` heading at the robot, the row asks an acceleration v_o/k + ā = {v_o:.3}/{k} + {a_bar:.3} = {need:.3} m/s² away from it; the input box gives {l} m/s²{}",
                        o.name,
                        if need <= l { "" } else { ": it cannot (the guarantee does not apply)" }
                    ),
                ),
                None => (
                    Some(true),
                    format!(
                        "at rest on its boundary with `{}` heading at the robot, the row asks {need:.3} m/s² away from it; no input box limits u",
                        o.name
                    ),
                ),
            };
            out.push(MoverFinding {
                name: format!("input to escape `{}`", o.name),
                holds,
                detail,
            });
        }
        if walker {
            out.push(MoverFinding {
                name: format!("walker `{}`", o.name),
                holds: None,
                detail: format!(
                    "walker `{}`: its reading is {}; its acceleration bound {a_bar:.3} m/s² covers the social force's driving term, not its repulsion near another body; it keeps off the robot by the social force only, so it may walk into a robot that stopped — counted apart (collisions.walker_robot_stopped), the walker's fault",
                    o.name,
                    if o.spec.tracker.is_some() {
                        "its tracker's (below)"
                    } else {
                        "exact (no obstacle sensor)"
                    }
                ),
            });
        } else if matches!(o.spec.motion, Some(MotionSpec::Waypoints { .. })) {
            out.push(MoverFinding {
                name: format!("corners of `{}`", o.name),
                holds: None,
                detail: format!(
                    "`{}` turns at its waypoints with a velocity jump of up to 2 × {v_o:.3} m/s the row does not see coming (its lift k∇d·(v − v_c) jumps with it)",
                    o.name
                ),
            });
        }
    }
    let sides = Sides::new(world);
    for (k, &i) in movers.iter().enumerate() {
        out.push(pin_finding(world, &sides, k, i));
        out.push(turn_finding(world, i));
    }
    for (a, &i) in movers.iter().enumerate() {
        for (b, &j) in movers.iter().enumerate().skip(a + 1) {
            out.push(pair_pin_finding(world, &sides, (a, i), (b, j)));
        }
    }
    out.push(MoverFinding {
        name: "what the guarantee covers with movers".into(),
        holds: None,
        detail: "the guarantee covers the robot's own motion: a mover that does not avoid the robot (a scripted path; a walker keeps off by its social force only) can walk into a robot that has stopped — such contacts are the mover's, counted apart by `ftcbf batch` (mover into the stopped robot), and are outside it".into(),
    });
    out
}

/// What the robot needs on each side not to be pinned (see [`pin_finding`]): its diameter,
/// and from each body the distance its barrier keeps with the robot at rest — a static
/// obstacle's margin, a mover's margin + k_m·v_o (its lift of the mover's approach speed).
/// The rows' estimation-error terms (h̄_γ) are not in it: they are where the rows hold the
/// robot at rest, not what they need to be met.
struct Sides {
    /// 2r \[m\].
    diameter: f64,
    /// The margin \[m\].
    statics: f64,
    /// margin + k_m·v_o per mover (in mover order) \[m\].
    movers: Vec<f64>,
}

impl Sides {
    fn new(world: &World) -> Self {
        let bcfg = obstacle_barrier_config(world);
        let movers = mover_indices(&world.obstacles)
            .iter()
            .map(|&i| {
                let spec = &world.obstacles[i].spec;
                bcfg.margin + mover_lift(world, spec, &bcfg) * max_speed(spec)
            })
            .collect();
        Self {
            diameter: 2.0 * bcfg.robot_radius,
            statics: bcfg.margin,
            movers,
        }
    }
}

/// The mover's planar footprint radius \[m\]: its own for a round body, else the half
/// diagonal of its bounding box in the plane.
fn body_radius(o: &Obstacle) -> f64 {
    match o.spec.shape {
        ShapeSpec::Cylinder { radius, .. }
        | ShapeSpec::Capsule { radius, .. }
        | ShapeSpec::Ball { radius } => radius,
        _ => {
            let b = o.shape().compute_aabb(o.shape_pose());
            let hx = f64::from(b.maxs.x - b.mins.x) / 2.0;
            let hy = f64::from(b.maxs.y - b.mins.y) / 2.0;
            hx.hypot(hy)
        }
    }
}

/// Where mover `o`'s centre goes during the run, every few cm: its scripted path over the
/// run's duration, or a walker's straight legs between its goals (it steers around obstacles
/// off them: the legs are what it aims for).
fn swept_centres(world: &World, o: &Obstacle) -> Vec<[f64; 2]> {
    const STEP: f64 = 0.05;
    let start = [o.spec.position[0], o.spec.position[1]];
    match &o.spec.motion {
        Some(MotionSpec::Walker { goals, .. }) => {
            let legs: Vec<[f64; 2]> = std::iter::once(start)
                .chain(goals.iter().copied())
                .collect();
            crate::movers::polyline_points(&legs, false, STEP)
        }
        _ => match crate::movers::fleet::trajectory(&o.spec) {
            Ok(Some(t)) => {
                let v = t.max_speed().max(1e-3);
                let dt = STEP / v;
                let n = (world.file.duration / dt).ceil().min(1e6) as usize;
                (0..=n).map(|j| t.state(j as f64 * dt).0).collect()
            }
            _ => vec![start],
        },
    }
}

/// Whether mover `i` (the `k`-th mover) can pin the robot against a static obstacle:
/// somewhere along its path the gap between its body and a static obstacle is positive but
/// narrower than the robot needs there ([`Sides`]: its diameter, the static obstacle's margin
/// and the mover's margin + k_m·v_o): a robot in that gap when the mover comes cannot keep
/// both barriers (two at once, which Theorem 3 does not cover).
fn pin_finding(world: &World, sides: &Sides, k: usize, i: usize) -> MoverFinding {
    let o = &world.obstacles[i];
    let bcfg = obstacle_barrier_config(world);
    let bare = BarrierConfig {
        robot_radius: 0.0,
        margin: 0.0,
        k: 0.0,
        ..bcfg
    };
    let need = sides.diameter + sides.statics + sides.movers[k];
    let r_o = body_radius(o);
    let statics: Vec<(String, Vec<ObstacleBarrier>)> = world
        .obstacles
        .iter()
        .filter(|s| s.spec.motion.is_none())
        .map(|s| (s.name.clone(), s.barriers(&bare)))
        .collect();
    // The narrowest gap below `need` (and > 0: a mover that touches an obstacle shuts the gap).
    let mut worst: Option<(f64, [f64; 2], &str)> = None;
    for c in swept_centres(world, o) {
        for (name, bs) in &statics {
            let p = nalgebra::Vector2::new(c[0], c[1]);
            let gap = bs
                .iter()
                .map(|b| b.clearance(p))
                .fold(f64::INFINITY, f64::min)
                - r_o;
            if gap > 0.0 && gap < need && worst.is_none_or(|w| gap < w.0) {
                worst = Some((gap, c, name));
            }
        }
    }
    let width = format!(
        "the robot's diameter and the distance each barrier keeps with the robot at rest, 2r + margin + (margin + k_m·v_o) = {:.3} + {:.3} + {:.3} = {need:.3} m",
        sides.diameter, sides.statics, sides.movers[k]
    );
    MoverFinding {
        name: format!("`{}` cannot pin the robot against a static obstacle", o.name),
        holds: Some(worst.is_none()),
        detail: match worst {
            None => format!(
                "along its path (every 5 cm) the gap between `{}` (body radius {r_o:.3} m) and each static obstacle is 0 or at least {width}",
                o.name
            ),
            Some((gap, c, name)) => format!(
                "at ({:.2}, {:.2}) on its path `{}` (body radius {r_o:.3} m) passes {gap:.3} m from `{name}`, less than {width}: a robot in that gap when it comes is pinned between two barriers, which Theorem 3 does not cover (the guarantee does not apply with it)",
                c[0], c[1], o.name
            ),
        },
    }
}

/// Whether the robot, stopped on mover `i`'s boundary (H = 0, so d = margin + k·v_o) with the
/// mover heading at it square to its heading, can turn and pull away before contact: it turns
/// for t_turn ([`quarter_turn_time`]) while the mover closes v_o·t_turn, then reaches v_o at
/// the brake deceleration a over v_o²/(2a); both within margin + k·v_o.
fn turn_finding(world: &World, i: usize) -> MoverFinding {
    let o = &world.obstacles[i];
    let bcfg = obstacle_barrier_config(world);
    let v_o = max_speed(&o.spec);
    let name = format!("the drive turns away from `{}` in time", o.name);
    let Some(t_turn) = quarter_turn_time(world) else {
        return MoverFinding {
            name,
            holds: Some(true),
            detail: "the point robot accelerates in any direction: no turn".into(),
        };
    };
    let a = world.brake_deceleration();
    let k = mover_lift(world, &o.spec, &bcfg);
    let closes = v_o * t_turn + v_o * v_o / (2.0 * a);
    let room = bcfg.margin + k * v_o;
    // k_m makes them equal at most; a relative 1e-9 leaves the rounding of the sum out.
    let holds = closes <= room * (1.0 + 1e-9);
    MoverFinding {
        name,
        holds: Some(holds),
        detail: format!(
            "stopped on its boundary with `{}` heading at it square to its heading, the robot turns a quarter turn in ≥ {t_turn:.3} s (ω_max and the drive's yaw-rate limit) and reaches v_o at {a} m/s²: the mover closes v_o·t_turn + v_o²/(2a) = {closes:.3} m, {} the room its row keeps, margin + k_m·v_o = {:.3} + {k:.3}·{v_o:.3} = {room:.3} m (k_m: the mover's lift, the world's {:.3} s raised to cover the turn){}",
            o.name,
            if holds { "within" } else { "more than" },
            bcfg.margin,
            bcfg.k,
            if holds { "" } else { " (the guarantee does not apply with it)" }
        ),
    }
}

/// Whether movers `i` and `j` (the `ki`-th and `kj`-th movers) can pin the robot between them:
/// somewhere the gap between their bodies is positive but narrower than the robot needs
/// there, 2r + both movers' margin + k_m·v_o (see [`pin_finding`]). Two scripted
/// movers are compared at the same instants over the run; with a walker, whose timing is its
/// own, every point of one's swept path against every point of the other's.
fn pair_pin_finding(
    world: &World,
    sides: &Sides,
    (ki, i): (usize, usize),
    (kj, j): (usize, usize),
) -> MoverFinding {
    let (oi, oj) = (&world.obstacles[i], &world.obstacles[j]);
    let need = sides.diameter + sides.movers[ki] + sides.movers[kj];
    let reach = body_radius(oi) + body_radius(oj);
    let scripted = |o: &Obstacle| match crate::movers::fleet::trajectory(&o.spec) {
        Ok(Some(t)) if !matches!(o.spec.motion, Some(MotionSpec::Walker { .. })) => Some(t),
        _ => None,
    };
    let mut worst: Option<(f64, [f64; 2], [f64; 2])> = None;
    let mut consider = |a: [f64; 2], b: [f64; 2]| {
        let gap = (a[0] - b[0]).hypot(a[1] - b[1]) - reach;
        if gap > 0.0 && gap < need && worst.is_none_or(|w| gap < w.0) {
            worst = Some((gap, a, b));
        }
    };
    let timed = match (scripted(oi), scripted(oj)) {
        (Some(ti), Some(tj)) => {
            let v = ti.max_speed().max(tj.max_speed()).max(1e-3);
            let dt = 0.05 / v;
            let n = (world.file.duration / dt).ceil().min(1e6) as usize;
            for k in 0..=n {
                let t = k as f64 * dt;
                consider(ti.state(t).0, tj.state(t).0);
            }
            true
        }
        _ => {
            let sj = swept_centres(world, oj);
            for a in swept_centres(world, oi) {
                for &b in &sj {
                    consider(a, b);
                }
            }
            false
        }
    };
    let how = if timed {
        "at the same instants over the run, every 5 cm"
    } else {
        "anywhere on their swept paths, whenever (a walker keeps no timetable)"
    };
    MoverFinding {
        name: format!("`{}` and `{}` cannot pin the robot between them", oi.name, oj.name),
        holds: Some(worst.is_none()),
        detail: match worst {
            None => format!(
                "{how}, the gap between the bodies of `{}` and `{}` is 0 or at least the robot's diameter and the distance each barrier keeps with the robot at rest, 2r + 2 × (margin + k_m·v_o) = {need:.3} m",
                oi.name, oj.name
            ),
            Some((gap, a, b)) => format!(
                "`{}` at ({:.2}, {:.2}) and `{}` at ({:.2}, {:.2}) leave a gap of {gap:.3} m between their bodies ({how}), less than the robot's diameter and the distance each barrier keeps with the robot at rest, 2r + 2 × (margin + k_m·v_o) = {need:.3} m: a robot in it is pinned between two barriers, which Theorem 3 does not cover (the guarantee does not apply with them)",
                oi.name, a[0], a[1], oj.name, b[0], b[1]
            ),
        },
    }
}

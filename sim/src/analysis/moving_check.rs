//! What `ftcbf check` says about moving obstacles (issue #51): which hypotheses of Theorem 3
//! their rows add, and whether the robot waits for a mover to pass or is blocked for good.
//!
//! **Safety.** A mover's row carries ∂h/∂t (see [`ftcbf_controller::MovingBarrier`]). At rest
//! on its boundary, a mover heading straight at the robot at speed v_o makes ∂h/∂t = −v_o − k·ā
//! (∇d unit, ∇_v h = k∇d), so the row asks k·u_n ≥ v_o + k·ā: an acceleration v_o/k + ā away
//! from it, which the input box must hold. And to keep d from falling for good the robot must
//! outrun it: v_o ≤ v_max. Either failing is a failed hypothesis, with the numbers. Not decided
//! (assumed, stated): that a mover does not corner the robot against another obstacle (the
//! joint rows of several barriers), that the drive turns to the escape direction in time, the
//! velocity jumps at a path's corners (the row does not see them coming), and a walker's
//! acceleration bound, which covers the social force's driving term only.
//!
//! **Liveness** with movers is [`crate::moving::liveness`] (in the liveness prediction): a mover
//! that ends its motion (`repeat = "once"`, or a zero velocity) where the robot's path passes,
//! or stands over the goal when the run ends, blocks it for good; a mover that crosses the path
//! and goes on makes the robot wait for it to pass.

use crate::model::setup::ControlSetup;
use crate::moving::{max_speed, mover_indices};
use crate::obstacles::MotionSpec;
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
    let k = bcfg.k;
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
                    "walker `{}`: its reading is exact (no obstacle sensor yet); its acceleration bound {a_bar:.3} m/s² covers the social force's driving term, not its repulsion near another body; it keeps off the robot by the social force only, so it may walk into a robot that stopped — counted apart (collisions.walker_robot_stopped), the walker's fault",
                    o.name
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
    out.push(MoverFinding {
        name: "movers do not corner the robot".into(),
        holds: None,
        detail: "no mover pins the robot against another obstacle or mover (the rows of several barriers at once), and the drive turns to the escape direction in time: not decided".into(),
    });
    out
}

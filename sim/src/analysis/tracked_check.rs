//! What `ftcbf check` says about tracked movers (issue #51): a moving obstacle read through a
//! noisy obstacle sensor and its filter ([`crate::movers::tracked`]).
//!
//! For each tracked mover: its error bounds γ_p, γ_v (the largest over the run, from the first
//! detection, and the settled ones) at the per-sample ε' = ε/(N·M), and the margin they take
//! from its row (h lowered by ‖∇_p h₀‖γ_p + ‖∇_v h₀‖γ_v ≈ γ_p + k·γ_v, with ‖∇_p h₀‖ ≈ 1 and
//! ‖∇_v h₀‖ = k for the lifted distance); the escape hypothesis with the tracked speed bound
//! (at rest on its boundary the row asks (v_o + γ_v)/k + ā away from the mover: ∂h/∂t is
//! lowered by ‖∇_p h₀‖γ_v); and whether its detections are honest: assumed when no attack is
//! declared, and when one is, the guarantee does not cover it — one obstacle sensor leaves no
//! redundancy for Theorem 3's conflict resolution to vote with.

use ftcbf_controller::MoverTracker;

use crate::analysis::moving_check::MoverFinding;
use crate::model::setup::{mover_lift, tracker_eps, ControlSetup};
use crate::movers::fleet::max_speed;
use crate::movers::tracked::tracker_config;
use crate::world::structure::obstacle_barrier_config;
use crate::world::World;

/// The tracked movers' findings of `world` (empty when none is tracked).
pub fn findings(world: &World, setup: &ControlSetup) -> Vec<MoverFinding> {
    let eps = tracker_eps(world);
    let bcfg = obstacle_barrier_config(world);
    let limit = setup.config.input_limit.map(|l| l[0].min(l[1]));
    let mut out = Vec::new();
    for o in &world.obstacles {
        let (Some(spec), Some((cfg, _))) = (
            &o.spec.tracker,
            tracker_config(&o.spec, max_speed(&o.spec), eps),
        ) else {
            continue;
        };
        let name = &o.name;
        let bounds = MoverTracker::horizon_bounds(cfg, world.control_dt(), world.file.duration)
            .and_then(|h| MoverTracker::steady_bounds(cfg).map(|s| (h, s)));
        let ((hp, hv), (sp, sv)) = match bounds {
            Ok(b) => b,
            Err(e) => {
                out.push(MoverFinding {
                    name: format!("tracker of `{name}`"),
                    holds: Some(false),
                    detail: format!("tracker of `{name}`: {e}"),
                });
                continue;
            }
        };
        let k = mover_lift(world, &o.spec, &bcfg);
        let v_o = max_speed(&o.spec);
        out.push(MoverFinding {
            name: format!("tracker of `{name}`"),
            holds: None,
            detail: format!(
                "`{name}` is read through its tracker (detections at {} Hz, σ = {} m per axis, ā = {:.3} m/s², v̄ = {v_o:.3} m/s, ε' = {eps:.3e} per reading): γ_p = {sp:.3} m and γ_v = {sv:.3} m/s once settled, at most {hp:.3} m and {hv:.3} m/s over the run (from the first detection: its velocity is unknown until then); its row's margin grows by ‖∇_p h₀‖γ_p + ‖∇_v h₀‖γ_v ≈ γ_p + k·γ_v = {:.3} m settled, {:.3} m at most (k = {k:.3} s); the tracked readings add ε = {} to the run's failure probability (a union bound over them)",
                spec.rate,
                spec.position_std,
                cfg.accel_bound,
                sp + k * sv,
                hp + k * hv,
                world.file.control.epsilon,
            ),
        });
        if k > 0.0 {
            let need = (v_o + hv) / k + cfg.accel_bound;
            let (holds, tail) = match limit {
                Some(l) if need <= l => (true, format!("the input box gives {l} m/s²")),
                Some(l) => (
                    false,
                    format!(
                        "the input box gives {l} m/s²: it cannot (the guarantee does not apply)"
                    ),
                ),
                None => (true, "no input box limits u".to_string()),
            };
            out.push(MoverFinding {
                name: format!("input to escape tracked `{name}`"),
                holds: Some(holds),
                detail: format!(
                    "at rest on its boundary with `{name}` heading at the robot, the row with the tracked speed bound asks (v_o + γ_v)/k + ā = ({v_o:.3} + {hv:.3})/{k:.3} + {:.3} = {need:.3} m/s² away from it; {tail}",
                    cfg.accel_bound
                ),
            });
        }
        out.push(match &spec.attack {
            None => MoverFinding {
                name: format!("detections of `{name}` are honest"),
                holds: None,
                detail: format!(
                    "the detections of `{name}` are assumed honest (no attack on its tracker is declared): its bounds hold only then"
                ),
            },
            Some(a) => {
                let b = a.bias[0].hypot(a.bias[1]);
                MoverFinding {
                    name: format!("attack on the tracker of `{name}`"),
                    holds: Some(false),
                    detail: format!(
                        "a declared attack biases the detections of `{name}` by ({:.3}, {:.3}) m (‖b‖ = {b:.3} m, {} the settled γ_p = {sp:.3} m) from t = {} s{}: the guarantee does not cover it — one obstacle sensor, no redundancy for Theorem 3's conflict resolution to vote with",
                        a.bias[0],
                        a.bias[1],
                        if b > sp { "more than" } else { "within" },
                        a.start,
                        a.end.map_or(" on".to_string(), |e| format!(" to {e} s")),
                    ),
                }
            }
        });
    }
    out
}

//! How far a declared attack can move the estimates ([`declared_reach`]) and the offsets
//! the prediction tries in each direction it can move them.

use super::*;

/// How far the declared attacks move a position fix at time `t` \[m\], and which axes: a bias its
/// value, a ramp or coordinated walk its rate times the time since its start (up to its cap),
/// a stealthy bias its rate times time (up to its cap), a sinusoid its amplitude, a scale its
/// factor's excess over the largest coordinate of the path; a frozen or replayed fix as far as
/// the robot has driven since (at `speed`). Attacks that only remove readings (dropout,
/// non-finite or absurd values the controller rejects, spikes a filter averages) move no fix:
/// 0 (a filter they leave with no fix of an axis drifts: `Drift`, in the model). An offset on
/// a velocity or speed channel moves the position the filters integrate by the offset times
/// the attacked time, one on a heading by `speed`·sin(offset) times it (θ then decides whether
/// Step 2 drops it). Outside an attack's window: 0.
pub fn declared_reach(world: &World, t: f64, speed: f64, max_coord: f64) -> AttackReach {
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
    AttackReach { reach, axes, exact }
}

/// What [`declared_reach`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttackReach {
    /// The largest offset of a position fix \[m\].
    pub reach: f64,
    /// The axes it can move (x, y).
    pub axes: [bool; 2],
    /// The offset is the fix's own (a position channel): the spoofed estimate sits there. Not
    /// exact when it is integrated from a velocity or heading: the filters then place the
    /// estimate anywhere up to it, so the worst one Step 2 keeps sits just inside θ.
    pub exact: bool,
}

/// A position or velocity fix the filters read directly (no conversion).
pub(super) fn direct_fix(q: Quantity) -> bool {
    matches!(q, Quantity::X | Quantity::Y | Quantity::Vx | Quantity::Vy)
}

pub(super) fn offsets(axes: [bool; 2], reach: f64) -> Vec<[f64; 2]> {
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

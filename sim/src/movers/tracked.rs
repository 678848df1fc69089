//! Tracked movers (issue #51): a moving obstacle with a `tracker` is read by the controller
//! through a noisy obstacle sensor and its own filter ([`ftcbf_controller::MoverTracker`])
//! instead of exactly.
//!
//! Each control step at which a detection is due (every 1/`rate` s, on the control step at or
//! after its time), the detector reports the mover's true centre, world frame, plus white
//! Gaussian noise of `position_std` m per axis drawn from the tracker's own seeded stream
//! (`stream_rng(seed, "tracker", name)`: no other random stream changes), plus a declared
//! attack's bias while it is active. The filter's reading at the step — estimate and error
//! bounds γ_p, γ_v — is the mover's [`MoverState`] for the controller; the truth still moves
//! the obstacle in the physics and judges collisions.
//!
//! Its error bounds hold with probability ≥ 1 − ε' per reading, ε' = ε/(N·M) (the world's
//! `control.epsilon`, N control steps, M tracked movers): over the run the tracked readings
//! add at most ε to the probability that some bound fails (a union bound, beside the robot's
//! own ε). They assume honest detections and the mover's acceleration bound: a walker's
//! (v_des + v_cap)/τ at its largest desired speed (the social force's driving term), 0 for a
//! scripted path (its corners are velocity jumps the bound does not cover).

use ftcbf_controller::{MoverState, MoverTracker, MoverTrackerConfig};
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;

use crate::movers::SocialForce;
use crate::obstacles::{MotionSpec, ObstacleSpec, TrackerAttackSpec, TrackerSpec};
use crate::sensors::stream_rng;

/// The largest detection noise accepted \[m\] (a detector worse than this is not one).
pub const MAX_POSITION_STD: f64 = 10.0;

/// The bound on mover `spec`'s acceleration the tracker's error bound uses \[m/s²\], given its
/// largest speed `v_max` ([`crate::movers::fleet::max_speed`]): a walker's (v_des + v_cap)/τ at
/// its largest desired speed, 0 for a scripted path.
pub fn accel_bound(spec: &ObstacleSpec, v_max: f64) -> f64 {
    match spec.motion {
        Some(MotionSpec::Walker { .. }) => v_max * (1.0 / 1.3 + 1.0) / SocialForce::default().tau,
        _ => 0.0,
    }
}

/// The filter of mover `spec` moving at up to `v_max` m/s
/// ([`crate::movers::fleet::max_speed`]; None without a `tracker`) at per-sample probability
/// `eps_per_sample` (ε/(N·M), see [`crate::model::setup::tracker_eps`]), and its detection
/// period \[s\]: the speed and acceleration bounds of its motion, the gain's `accel_std`
/// (default: the acceleration bound, else the speed bound per second, else the noise's
/// σ·rate²).
pub fn tracker_config(
    spec: &ObstacleSpec,
    v_max: f64,
    eps_per_sample: f64,
) -> Option<(MoverTrackerConfig, f64)> {
    let t = spec.tracker.as_ref()?;
    spec.motion.as_ref()?;
    let a = accel_bound(spec, v_max);
    let v = v_max;
    let design = if a > 0.0 {
        a
    } else if v > 0.0 {
        v
    } else {
        t.position_std * t.rate * t.rate
    };
    let cfg = MoverTrackerConfig {
        position_std: t.position_std,
        accel_std: t.accel_std.unwrap_or(design),
        accel_bound: a,
        speed_bound: v,
        eps_per_sample,
        period: 1.0 / t.rate,
    };
    Some((cfg, 1.0 / t.rate))
}

/// Checks an obstacle's `tracker` against the control rate `rate_hz`: the key inside it and
/// what was expected on error.
pub fn check_tracker(spec: &ObstacleSpec, rate_hz: f64) -> Result<(), (String, String)> {
    let Some(t) = &spec.tracker else {
        return Ok(());
    };
    let bad = |key: &str, msg: String| Err((key.to_string(), msg));
    if spec.motion.is_none() {
        return bad(
            "",
            format!(
                "a tracker follows a moving obstacle; `{}` has no `motion` (remove the tracker, or give it a motion)",
                spec.name
            ),
        );
    }
    let ps = t.position_std;
    if !(ps.is_finite() && ps > 0.0 && ps <= MAX_POSITION_STD) {
        return bad(
            "position_std",
            format!("expected a noise standard deviation in (0, {MAX_POSITION_STD}] m, found {ps}"),
        );
    }
    if !(t.rate.is_finite() && t.rate > 0.0 && t.rate <= rate_hz) {
        return bad(
            "rate",
            format!(
                "expected a detection rate in (0, {rate_hz}] Hz (at most the control rate), found {}",
                t.rate
            ),
        );
    }
    if let Some(a) = t.accel_std {
        if !(a.is_finite() && a > 0.0) {
            return bad(
                "accel_std",
                format!("expected an acceleration standard deviation > 0 m/s², found {a}"),
            );
        }
    }
    if let Some(at) = &t.attack {
        if let Some(b) = at.bias.iter().find(|b| !b.is_finite()) {
            return bad(
                "attack.bias",
                format!("expected finite offsets in m, found {b}"),
            );
        }
        if !(at.start.is_finite() && at.start >= 0.0) {
            return bad(
                "attack.start",
                format!("expected a time ≥ 0 s, found {}", at.start),
            );
        }
        if let Some(e) = at.end {
            if !(e.is_finite() && e > at.start) {
                return bad(
                    "attack.end",
                    format!("expected a time after `start` ({} s), found {e}", at.start),
                );
            }
        }
    }
    Ok(())
}

/// One tracked mover in a run: its detector's noise stream and its filter.
#[derive(Debug, Clone)]
pub struct TrackedMover {
    tracker: MoverTracker,
    rng: ChaCha20Rng,
    /// Detection period \[s\].
    period: f64,
    /// Index of the next detection (due at `next · period`).
    next: u64,
    /// The mover's position at t = 0 (its barrier's) \[m\].
    origin: [f64; 2],
    attack: Option<TrackerAttackSpec>,
    /// Detections the filter refused (gated or malformed).
    pub refused: u64,
}

impl TrackedMover {
    /// The tracked mover of `spec` (moving at up to `v_max` m/s) at `eps_per_sample` for the
    /// run of `seed` (None without a tracker).
    pub fn new(spec: &ObstacleSpec, v_max: f64, eps_per_sample: f64, seed: u64) -> Option<Self> {
        let (cfg, period) = tracker_config(spec, v_max, eps_per_sample)?;
        let TrackerSpec { attack, .. } = spec.tracker.as_ref()?;
        Some(Self {
            // Checked when the world was loaded (`check_tracker`); ε' is in (0, 1).
            tracker: MoverTracker::new(cfg).ok()?,
            rng: stream_rng(seed, "tracker", &spec.name),
            period,
            next: 0,
            origin: [spec.position[0], spec.position[1]],
            attack: attack.clone(),
            refused: 0,
        })
    }

    /// The filter.
    pub fn tracker(&self) -> &MoverTracker {
        &self.tracker
    }

    /// The reading at control step time `t` \[s\] given the mover's true state `truth`: a
    /// detection first when one is due. Before the first detection the reading is NaN (its
    /// rows fail closed).
    pub fn step(&mut self, t: f64, truth: &MoverState) -> MoverState {
        const EPS: f64 = 1e-9;
        if t >= self.next as f64 * self.period - EPS {
            let n: [f64; 2] = [
                self.rng.sample(StandardNormal),
                self.rng.sample(StandardNormal),
            ];
            let sd = self.tracker.config().position_std;
            let mut z = [
                self.origin[0] + truth.displacement[0] + sd * n[0],
                self.origin[1] + truth.displacement[1] + sd * n[1],
            ];
            if let Some(a) = &self.attack {
                if t >= a.start - EPS && a.end.is_none_or(|e| t < e - EPS) {
                    z = [z[0] + a.bias[0], z[1] + a.bias[1]];
                }
            }
            if self.tracker.detect(t, z).is_err() {
                self.refused += 1;
            }
            while t >= self.next as f64 * self.period - EPS {
                self.next += 1;
            }
        }
        match self.tracker.reading(t) {
            Some(r) => r.mover_state(self.origin, truth.accel_bound),
            None => MoverState {
                displacement: [f64::NAN; 2],
                velocity: [f64::NAN; 2],
                accel_bound: truth.accel_bound,
                position_bound: f64::NAN,
                velocity_bound: f64::NAN,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::obstacles::ShapeSpec;

    fn cart(attack: Option<TrackerAttackSpec>) -> ObstacleSpec {
        ObstacleSpec {
            name: "cart".into(),
            position: [1.0, -1.0, 0.2],
            rpy: [0.0; 3],
            shape: ShapeSpec::Cylinder {
                radius: 0.15,
                half_height: 0.2,
            },
            motion: Some(MotionSpec::Velocity {
                velocity: [0.0, 0.1],
            }),
            tracker: Some(TrackerSpec {
                position_std: 0.02,
                rate: 10.0,
                accel_std: None,
                attack,
            }),
        }
    }

    /// Runs `spec`'s tracker over 3 s of 50 Hz control steps against its true motion; the
    /// largest position error of the readings from `from` s on, the readings whose error
    /// exceeds their bound γ_p, and the tracker.
    fn run(spec: &ObstacleSpec, from: f64) -> (f64, usize, TrackedMover) {
        let mut tr = TrackedMover::new(spec, 0.1, 1e-5, 7).expect("tracked");
        let (mut worst, mut over) = (0.0f64, 0);
        for k in 0..150 {
            let t = k as f64 * 0.02;
            let truth = MoverState {
                displacement: [0.0, 0.1 * t],
                velocity: [0.0, 0.1],
                ..MoverState::default()
            };
            let r = tr.step(t, &truth);
            let e = (r.displacement[0] - truth.displacement[0])
                .hypot(r.displacement[1] - truth.displacement[1]);
            over += usize::from(e > r.position_bound);
            if t >= from {
                worst = worst.max(e);
            }
        }
        (worst, over, tr)
    }

    /// Honest detections: none refused, the estimate within a few cm after a second and within
    /// its bound at every step. A bias of 1 m (far past the gate) in [1, 2) s: its 10
    /// detections are refused and the readings stay within their (growing) bounds. A 5 cm bias
    /// passes the gate, moves the estimate, and breaks the bound: an attack on the detections
    /// is outside it.
    #[test]
    fn detections_every_period_and_a_declared_bias_in_its_window() {
        let (honest, over, tr) = run(&cart(None), 1.0);
        assert_eq!((tr.refused, over), (0, 0));
        assert!(honest < 0.05, "{honest}");
        let window = |b: f64| TrackerAttackSpec {
            bias: [b, 0.0],
            start: 1.0,
            end: Some(2.0),
        };
        let (_, over, tr) = run(&cart(Some(window(1.0))), 0.0);
        assert_eq!((tr.refused, over), (10, 0));
        let (small, over, tr) = run(&cart(Some(window(0.05))), 1.5);
        assert_eq!(tr.refused, 0);
        assert!(
            small > honest && over > 0,
            "{small} vs {honest}, {over} over"
        );
    }

    #[test]
    fn a_tracker_on_a_standing_obstacle_or_with_bad_values_is_refused() {
        let mut s = cart(None);
        assert_eq!(check_tracker(&s, 50.0), Ok(()));
        s.motion = None;
        let (key, msg) = check_tracker(&s, 50.0).unwrap_err();
        assert!(key.is_empty() && msg.contains("no `motion`"), "{msg}");
        let mut s = cart(None);
        if let Some(t) = s.tracker.as_mut() {
            t.rate = 60.0;
        }
        assert_eq!(check_tracker(&s, 50.0).unwrap_err().0, "rate");
    }
}

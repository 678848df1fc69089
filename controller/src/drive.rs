//! The compensator (eq. 6.3)–(6.4): planar acceleration u = (a_x, a_y) [m/s², world frame] →
//! body command (v [m/s], ω [rad/s]) of a differential-drive robot with heading θ \[rad\].
//!
//! It belongs to the controller (the drive is part of the control law, not of the plant): the
//! simulator and a real robot both only turn (v, ω) into wheel speeds.
//!
//! - (6.3) v integrates the along-heading acceleration a∥ = u₁cosθ + u₂sinθ:
//!   v ← v + a∥·dt, then |v| ≤ v_max, and |Δv| ≤ dv_max·dt when a rate limit is set.
//! - (6.4) ω = a⊥ / v with a⊥ = u₂cosθ − u₁sinθ. Two documented laws near v = 0
//!   ([`LowSpeedLaw`]):
//!   - `Floor { v_floor }`: ω = a⊥ / (s·max(|v|, v_floor)), s = sign(v) (+1 at 0). Exactly
//!     (6.4) above the floor; discontinuous in v at v = 0 (the sign flips) and it amplifies
//!     noise in a⊥ by 1/v_floor at rest.
//!   - `Regularised { v_soft }`: ω = a⊥·v / (v² + v_soft²). Continuous in v and u everywhere,
//!     equal to (6.4) up to the factor v²/(v² + v_soft²) (within 1 % for |v| ≥ 10·v_soft),
//!     and bounded by |a⊥| / (2·v_soft) (the maximum of v/(v²+v_soft²) is at |v| = v_soft).
//!     At rest it commands no turn: a lateral acceleration first builds forward speed.
//!
//!   Then |ω| ≤ ω_max, and |Δω| ≤ dω_max·dt when a rate limit is set.
//! - The drive's resolution: a robot executes yaw rates in steps of its resolution (a
//!   TurtleBot3's wheel motors take integer velocity units, see `[control.drive]
//!   wheel_speed_resolution`), so a command |ω| below half a step is sent as ω = 0 — what the
//!   robot would execute anyway. The integrator and the rate limiter keep the unrounded value.
//! - Closed loop on the measured speed: [`Compensator::observe_speed`] pulls the integrator
//!   towards a measured/estimated forward speed with gain k ∈ [0, 1] (k = 1 replaces it), and
//!   [`Compensator::saturated`] sets it to the speed actually commanded after wheel saturation,
//!   so the integrator cannot wind up beyond what the wheels deliver.
//! - Non-finite u, θ or dt leave v unchanged and command ω = 0; non-finite measurements are
//!   ignored (they are attacks to survive, not values to integrate).

use crate::types::Input;

/// Errors of compensator construction.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CompensatorError {
    /// A limit or configuration value is out of range.
    #[error("compensator: `{key}` must be {expected}, got {value}")]
    InvalidValue {
        /// Which value.
        key: &'static str,
        /// What is expected.
        expected: &'static str,
        /// The value given.
        value: f64,
    },
}

/// How ω is computed from (6.4) near v = 0 (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LowSpeedLaw {
    /// ω = a⊥ / (s·max(|v|, v_floor)) [v_floor in m/s].
    Floor {
        /// Floor of |v| in the denominator [m/s].
        v_floor: f64,
    },
    /// ω = a⊥·v / (v² + v_soft²) [v_soft in m/s].
    Regularised {
        /// Speed scale below which the turn command fades out [m/s].
        v_soft: f64,
    },
}

impl LowSpeedLaw {
    /// ω before saturation for lateral acceleration `a_perp` [m/s²] at speed `v` [m/s].
    pub fn omega(self, a_perp: f64, v: f64) -> f64 {
        match self {
            Self::Floor { v_floor } => {
                let sign = if v < 0.0 { -1.0 } else { 1.0 };
                a_perp / (sign * v.abs().max(v_floor))
            }
            Self::Regularised { v_soft } => a_perp * v / (v * v + v_soft * v_soft),
        }
    }

    fn scale(self) -> (&'static str, f64) {
        match self {
            Self::Floor { v_floor } => ("v_floor", v_floor),
            Self::Regularised { v_soft } => ("v_soft", v_soft),
        }
    }
}

/// Limits and law of the compensator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensatorConfig {
    /// Maximum |v| [m/s].
    pub v_max: f64,
    /// Maximum |ω| [rad/s].
    pub omega_max: f64,
    /// Maximum |dv/dt| [m/s²]; `None` = no rate limit.
    pub dv_max: Option<f64>,
    /// Maximum |dω/dt| [rad/s²]; `None` = no rate limit.
    pub domega_max: Option<f64>,
    /// The law near v = 0.
    pub low_speed: LowSpeedLaw,
    /// The drive's yaw-rate resolution [rad/s] (0: none): |ω| below half of it is sent as 0.
    pub omega_resolution: f64,
    /// Gain of the speed correction in [`Compensator::observe_speed`], in [0, 1].
    pub speed_gain: f64,
}

/// A body-frame velocity command.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BodyCommand {
    /// Forward speed [m/s].
    pub v: f64,
    /// Yaw rate [rad/s].
    pub omega: f64,
}

/// The world-frame acceleration [m/s²] a unicycle realises over one period of `dt` \[s\] in
/// which its body command goes from `before` to `after` (the commands actually sent, after every
/// limit) while its heading starts at `yaw` \[rad\] and turns at `after.omega`:
/// `(v_after·e(yaw + ω_after·dt) − v_before·e(yaw)) / dt`, e(θ) = (cos θ, sin θ).
///
/// This is u as the drive performed it, not as the controller asked for it: at rest a lateral
/// request turns the robot in place (no lateral acceleration), a speed or yaw-rate limit cuts
/// it, wheel saturation scales it. A filter predicting with it, not with the asked-for u, does
/// not build up a velocity the robot never had. `None` for a non-finite input or `dt ≤ 0`.
pub fn realized_acceleration(
    before: BodyCommand,
    after: BodyCommand,
    yaw: f64,
    dt: f64,
) -> Option<Input> {
    let finite = [before.v, after.v, after.omega, yaw, dt]
        .iter()
        .all(|x| x.is_finite());
    if !finite || dt <= 0.0 {
        return None;
    }
    let (s0, c0) = yaw.sin_cos();
    let (s1, c1) = (yaw + after.omega * dt).sin_cos();
    Some(Input::new(
        (after.v * c1 - before.v * c0) / dt,
        (after.v * s1 - before.v * s0) / dt,
    ))
}

/// The safe stop's braking input on a platform that measures its own forward speed (wheel
/// encoders, not a sensor channel of the attack surface): the world-frame acceleration along
/// the heading `theta` \[rad\] that takes the forward speed `v_body` \[m/s\] to zero in one period
/// `dt` \[s\] if `decel` \[m/s²\] allows, else decelerates at `decel`; no lateral component, so
/// the compensator (6.4) commands ω = 0 and the robot brakes along its path. Because it is
/// projected on the same heading the compensator uses, its forward part is exactly the braking
/// asked for even when that heading is wrong. Zero for a non-finite argument or `dt ≤ 0`,
/// `decel ≤ 0`.
pub fn brake_input(v_body: f64, theta: f64, decel: f64, dt: f64) -> Input {
    let finite = [v_body, theta, decel, dt].iter().all(|x| x.is_finite());
    if !finite || dt <= 0.0 || decel <= 0.0 {
        return Input::zeros();
    }
    let a = (-v_body / dt).clamp(-decel, decel);
    let (s, c) = theta.sin_cos();
    Input::new(a * c, a * s)
}

/// The compensator state: the integrator of (6.3) and the last ω (for the rate limit).
#[derive(Debug, Clone)]
pub struct Compensator {
    cfg: CompensatorConfig,
    v: f64,
    omega: f64,
}

fn positive(key: &'static str, value: f64) -> Result<(), CompensatorError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(CompensatorError::InvalidValue {
            key,
            expected: "a positive finite number",
            value,
        })
    }
}

/// Moves `from` towards `to` by at most `step` (no limit when `step` is `None`).
fn rate_limit(from: f64, to: f64, step: Option<f64>) -> f64 {
    match step {
        Some(s) => from + (to - from).clamp(-s, s),
        None => to,
    }
}

impl Compensator {
    /// A compensator at rest (v = 0, ω = 0).
    pub fn new(cfg: CompensatorConfig) -> Result<Self, CompensatorError> {
        positive("v_max", cfg.v_max)?;
        positive("omega_max", cfg.omega_max)?;
        if let Some(dv) = cfg.dv_max {
            positive("dv_max", dv)?;
        }
        if let Some(dw) = cfg.domega_max {
            positive("domega_max", dw)?;
        }
        let (key, scale) = cfg.low_speed.scale();
        positive(key, scale)?;
        if !(cfg.omega_resolution.is_finite() && cfg.omega_resolution >= 0.0) {
            return Err(CompensatorError::InvalidValue {
                key: "omega_resolution",
                expected: "a finite number ≥ 0",
                value: cfg.omega_resolution,
            });
        }
        if !(0.0..=1.0).contains(&cfg.speed_gain) {
            return Err(CompensatorError::InvalidValue {
                key: "speed_gain",
                expected: "a number in [0, 1]",
                value: cfg.speed_gain,
            });
        }
        Ok(Self {
            cfg,
            v: 0.0,
            omega: 0.0,
        })
    }

    /// One step over `dt` \[s\]: integrates (6.3), applies (6.4) with the low-speed law, the
    /// limits and the rate limits. `u` is the world-frame acceleration, `theta` the heading.
    pub fn command(&mut self, u: Input, theta: f64, dt: f64) -> BodyCommand {
        if !(u[0].is_finite() && u[1].is_finite() && theta.is_finite() && dt.is_finite()) {
            self.omega = 0.0;
            return self.current();
        }
        let dt = dt.max(0.0);
        let (s, c) = theta.sin_cos();
        let a_par = u[0] * c + u[1] * s;
        let a_perp = u[1] * c - u[0] * s;
        let v_max = self.cfg.v_max;
        let v_target = (self.v + a_par * dt).clamp(-v_max, v_max);
        self.v = rate_limit(self.v, v_target, self.cfg.dv_max.map(|d| d * dt));
        let w_max = self.cfg.omega_max;
        let w_target = self
            .cfg
            .low_speed
            .omega(a_perp, self.v)
            .clamp(-w_max, w_max);
        self.omega = rate_limit(self.omega, w_target, self.cfg.domega_max.map(|d| d * dt));
        self.current()
    }

    /// Corrects the integrator towards a measured/estimated forward speed `v_meas` [m/s]:
    /// v ← v + k·(v_meas − v), k = `speed_gain`. Non-finite measurements are ignored.
    pub fn observe_speed(&mut self, v_meas: f64) {
        if v_meas.is_finite() {
            let v = self.v + self.cfg.speed_gain * (v_meas - self.v);
            self.v = v.clamp(-self.cfg.v_max, self.cfg.v_max);
        }
    }

    /// Records the command actually sent after wheel saturation (both v and ω are scaled by
    /// the wheels), so the integrator and the rate limiter continue from it.
    pub fn saturated(&mut self, sent: BodyCommand) {
        if sent.v.is_finite() && sent.omega.is_finite() {
            self.v = sent.v.clamp(-self.cfg.v_max, self.cfg.v_max);
            self.omega = sent.omega.clamp(-self.cfg.omega_max, self.cfg.omega_max);
        }
    }

    /// Resets the integrator to `v` [m/s] (clamped; non-finite → 0) and ω to 0.
    pub fn reset(&mut self, v: f64) {
        self.v = if v.is_finite() {
            v.clamp(-self.cfg.v_max, self.cfg.v_max)
        } else {
            0.0
        };
        self.omega = 0.0;
    }

    /// The current command: the state of (6.3) and the last ω, rounded to 0 below half the
    /// drive's resolution.
    pub fn current(&self) -> BodyCommand {
        let omega = if self.omega.abs() < 0.5 * self.cfg.omega_resolution {
            0.0
        } else {
            self.omega
        };
        BodyCommand { v: self.v, omega }
    }

    /// The configuration.
    pub fn config(&self) -> &CompensatorConfig {
        &self.cfg
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    fn cfg(law: LowSpeedLaw) -> CompensatorConfig {
        CompensatorConfig {
            v_max: 0.22,
            omega_max: 2.84,
            dv_max: None,
            domega_max: None,
            low_speed: law,
            speed_gain: 1.0,
            omega_resolution: 0.0,
        }
    }

    #[test]
    fn realized_acceleration_of_a_unicycle() {
        let cmd = |v, omega| BodyCommand { v, omega };
        // Straight ahead along +y, speeding up 0.1 → 0.2 m/s in 0.1 s: 1 m/s² along +y.
        let a = realized_acceleration(cmd(0.1, 0.0), cmd(0.2, 0.0), FRAC_PI_2, 0.1).unwrap();
        assert!(a[0].abs() < 1e-12 && (a[1] - 1.0).abs() < 1e-12);
        // Turning in place at rest: no acceleration at all, whatever the yaw rate.
        let a = realized_acceleration(cmd(0.0, 0.0), cmd(0.0, 2.0), 0.3, 0.02).unwrap();
        assert_eq!(a, Input::zeros());
        // Constant speed on a circle: |a| → v·ω (centripetal), pointing to the left of e(yaw).
        let (v, w, dt) = (0.2, 1.0, 1e-4);
        let a = realized_acceleration(cmd(v, w), cmd(v, w), 0.0, dt).unwrap();
        assert!((a[1] - v * w).abs() < 1e-4 && a[0].abs() < 1e-4);
        assert!(realized_acceleration(cmd(0.0, 0.0), cmd(f64::NAN, 0.0), 0.0, 0.1).is_none());
        assert!(realized_acceleration(cmd(0.0, 0.0), cmd(0.1, 0.0), 0.0, 0.0).is_none());
    }

    #[test]
    fn regularised_law_is_continuous_at_rest_and_bounded() {
        let law = LowSpeedLaw::Regularised { v_soft: 0.05 };
        assert_eq!(law.omega(0.3, 0.0), 0.0);
        let eps = 1e-6;
        assert!((law.omega(0.3, eps) - law.omega(0.3, -eps)).abs() < 1e-3);
        // Peak |a⊥|/(2 v_soft) = 3 rad/s at v = v_soft.
        assert!((law.omega(0.3, 0.05) - 3.0).abs() < 1e-12);
        for k in -100..=100 {
            let v = f64::from(k) * 0.003;
            assert!(law.omega(0.3, v).abs() <= 3.0 + 1e-12);
        }
        // Within 1 % of (6.4) at |v| = 10 v_soft.
        let exact = 0.3 / 0.5;
        assert!((law.omega(0.3, 0.5) / exact - 1.0).abs() < 0.01);
    }

    #[test]
    fn floor_law_is_eq_6_4_above_the_floor() {
        let law = LowSpeedLaw::Floor { v_floor: 0.05 };
        assert!((law.omega(0.2, 0.1) - 2.0).abs() < 1e-12);
        assert!((law.omega(0.2, 0.0) - 4.0).abs() < 1e-12);
        assert!((law.omega(0.2, -0.1) + 2.0).abs() < 1e-12);
    }

    #[test]
    fn rate_limits_bound_each_step() {
        let mut c = cfg(LowSpeedLaw::Regularised { v_soft: 0.05 });
        c.dv_max = Some(0.5);
        c.domega_max = Some(2.0);
        let mut comp = Compensator::new(c).unwrap();
        let dt = 0.02;
        let mut prev = comp.current();
        for k in 0..200 {
            let sign = if k % 7 < 3 { 1.0 } else { -1.0 };
            let cmd = comp.command(Input::new(5.0, 5.0 * sign), 0.0, dt);
            assert!((cmd.v - prev.v).abs() <= 0.5 * dt + 1e-12);
            assert!((cmd.omega - prev.omega).abs() <= 2.0 * dt + 1e-12);
            assert!(cmd.v.abs() <= 0.22 && cmd.omega.abs() <= 2.84);
            prev = cmd;
        }
    }

    #[test]
    fn speed_feedback_and_saturation_update_the_integrator() {
        let mut c = cfg(LowSpeedLaw::Regularised { v_soft: 0.05 });
        c.speed_gain = 0.5;
        let mut comp = Compensator::new(c).unwrap();
        comp.command(Input::new(1.0, 0.0), 0.0, 0.1); // v = 0.1
        comp.observe_speed(0.2);
        assert!((comp.current().v - 0.15).abs() < 1e-12);
        comp.observe_speed(f64::NAN);
        assert!((comp.current().v - 0.15).abs() < 1e-12);
        comp.saturated(BodyCommand {
            v: 0.12,
            omega: 1.0,
        });
        assert_eq!(
            comp.current(),
            BodyCommand {
                v: 0.12,
                omega: 1.0
            }
        );
        // Next step integrates from the saturated speed.
        let cmd = comp.command(Input::new(0.1, 0.0), 0.0, 0.1);
        assert!((cmd.v - 0.13).abs() < 1e-12);
    }

    #[test]
    fn non_finite_input_holds_speed_and_stops_turning() {
        let mut comp = Compensator::new(cfg(LowSpeedLaw::Floor { v_floor: 0.05 })).unwrap();
        comp.command(Input::new(1.0, 0.5), 0.0, 0.1);
        let v = comp.current().v;
        let cmd = comp.command(Input::new(f64::NAN, 0.0), 0.0, 0.1);
        assert_eq!(cmd, BodyCommand { v, omega: 0.0 });
    }

    #[test]
    fn bad_configuration_is_a_typed_error() {
        let mut c = cfg(LowSpeedLaw::Regularised { v_soft: 0.0 });
        assert!(matches!(
            Compensator::new(c),
            Err(CompensatorError::InvalidValue { key: "v_soft", .. })
        ));
        c.low_speed = LowSpeedLaw::Floor { v_floor: 0.05 };
        c.speed_gain = 1.5;
        assert!(matches!(
            Compensator::new(c),
            Err(CompensatorError::InvalidValue {
                key: "speed_gain",
                ..
            })
        ));
    }

    #[test]
    fn yaw_rates_below_half_the_resolution_are_sent_as_zero() {
        let mut c = Compensator::new(CompensatorConfig {
            omega_resolution: 0.01,
            ..cfg(LowSpeedLaw::Floor { v_floor: 0.05 })
        })
        .expect("valid");
        c.reset(0.2);
        // a⊥ = 0.0008 m/s² at v = 0.2 m/s: ω = 0.004 < 0.005 → 0
        let cmd = c.command(Input::new(0.0, 0.0008), 0.0, 0.02);
        assert_eq!(cmd.omega, 0.0);
        // the unrounded value is kept for the rate limiter and the next step
        assert!((c.omega - 0.004).abs() < 1e-12);
        // a⊥ = 0.0012: ω = 0.006 ≥ 0.005 is sent as is
        let cmd = c.command(Input::new(0.0, 0.0012), 0.0, 0.02);
        assert!((cmd.omega - 0.006).abs() < 1e-9, "{cmd:?}");
        let bad = Compensator::new(CompensatorConfig {
            omega_resolution: -1.0,
            ..cfg(LowSpeedLaw::Floor { v_floor: 0.05 })
        });
        assert!(matches!(
            bad,
            Err(CompensatorError::InvalidValue {
                key: "omega_resolution",
                ..
            })
        ));
    }

    #[test]
    fn brake_input_stops_the_body_speed_within_the_deceleration_and_never_turns() {
        let cfg = CompensatorConfig {
            v_max: 0.22,
            omega_max: 2.84,
            dv_max: None,
            domega_max: None,
            low_speed: LowSpeedLaw::Floor { v_floor: 0.05 },
            speed_gain: 0.0,
            omega_resolution: 0.0,
        };
        let mut comp = Compensator::new(cfg).unwrap();
        comp.reset(0.2);
        let theta = 2.0;
        let dt = 0.02;
        let mut steps = 0;
        // 1e-9: 0.2 − 10 × 0.02 rounds to a few 1e-17, not to 0.
        while comp.current().v > 1e-9 {
            let u = brake_input(comp.current().v, theta, 1.0, dt);
            assert!(
                u.norm() <= 1.0 + 1e-12,
                "the deceleration limit holds: |u| = {}",
                u.norm()
            );
            let cmd = comp.command(u, theta, dt);
            assert!(
                cmd.omega.abs() < 1e-12,
                "braking never turns: ω = {}",
                cmd.omega
            );
            steps += 1;
            assert!(steps <= 11, "0.2 m/s at 1 m/s² stops in 10 steps of 20 ms");
        }
        assert_eq!(steps, 10);
        assert!(comp.current().v.abs() < 1e-12);
        // Backwards too, and garbage in gives no acceleration.
        let u = brake_input(-0.1, 0.0, 1.0, dt);
        assert!((u[0] - 1.0).abs() < 1e-12 && u[1].abs() < 1e-12);
        assert_eq!(brake_input(f64::NAN, 0.0, 1.0, dt), Input::zeros());
        assert_eq!(brake_input(0.1, 0.0, 0.0, dt), Input::zeros());
    }
}

//! The drive chain: planar acceleration u (eq. 6.2) → body command (v, ω) through the
//! compensator (6.3)–(6.4) → wheel angular speeds from the URDF's wheel radius and separation.
//! [`crate::physics::PhysicsWorld::set_wheel_speeds`] turns wheel speeds into joint-motor targets.
//!
//! Compensator (world frame, θ = heading):
//! - (6.3) v integrates the acceleration along the heading: v ← v + (u₁cosθ + u₂sinθ)·dt,
//!   then |v| ≤ v_max.
//! - (6.4) ω = (u₂cosθ − u₁sinθ) / v. **Guard near v = 0**: the denominator is floored,
//!   ω = a⊥ / (s · max(|v|, v_floor)) with s = sign(v) (s = +1 at v = 0). Away from the floor this
//!   is (6.4) exactly; at rest a lateral acceleration turns the robot towards it (ω bounded by
//!   |a⊥|/v_floor) instead of dividing by zero, and the forward speed is still integrated from
//!   the along-heading part only. Then |ω| ≤ ω_max.
//! - Non-finite u, θ or dt (e.g. a corrupted estimate upstream) leave v unchanged and give ω = 0.
//!
//! Wheel kinematics (r = radius, L = separation): ω_left = (v − ωL/2)/r, ω_right = (v + ωL/2)/r;
//! if either exceeds the wheel-speed limit both are scaled down by the same factor (the path's
//! curvature is kept).

use ftcbf_controller::Input;

use crate::robot::{DriveLimits, WheelGeometry};

/// Errors of drive construction.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DriveError {
    /// A geometry/limit/config value is out of range.
    #[error("drive: `{key}` must be {expected}, got {value}")]
    InvalidValue {
        /// Which value.
        key: &'static str,
        /// What is expected.
        expected: &'static str,
        /// The value given.
        value: f64,
    },
}

/// Configuration of the compensator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveConfig {
    /// Floor of |v| in the denominator of (6.4) [m/s]. Default 0.05.
    pub v_floor: f64,
    /// Initial forward speed of the integrator (6.3) [m/s]. Default 0.
    pub v_initial: f64,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self {
            v_floor: 0.05,
            v_initial: 0.0,
        }
    }
}

/// A body-frame velocity command.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BodyCommand {
    /// Forward speed [m/s].
    pub v: f64,
    /// Yaw rate [rad/s].
    pub omega: f64,
}

/// The compensator state and the wheel kinematics.
#[derive(Debug, Clone)]
pub struct Drive {
    geometry: WheelGeometry,
    limits: DriveLimits,
    cfg: DriveConfig,
    v: f64,
}

fn check(key: &'static str, value: f64) -> Result<(), DriveError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(DriveError::InvalidValue {
            key,
            expected: "a positive finite number",
            value,
        })
    }
}

impl Drive {
    /// A drive for the given wheels and limits.
    pub fn new(
        geometry: &WheelGeometry,
        limits: &DriveLimits,
        cfg: DriveConfig,
    ) -> Result<Self, DriveError> {
        check("wheel radius", geometry.radius)?;
        check("wheel separation", geometry.separation)?;
        check("v_max", limits.v_max)?;
        check("omega_max", limits.omega_max)?;
        check("wheel_speed_max", limits.wheel_speed_max)?;
        check("v_floor", cfg.v_floor)?;
        if !cfg.v_initial.is_finite() {
            return Err(DriveError::InvalidValue {
                key: "v_initial",
                expected: "a finite number",
                value: cfg.v_initial,
            });
        }
        Ok(Self {
            geometry: *geometry,
            limits: *limits,
            cfg,
            v: cfg.v_initial.clamp(-limits.v_max, limits.v_max),
        })
    }

    /// One compensator step: integrates (6.3) over `dt` [s] and applies (6.4) with the guard.
    /// `u` is the world-frame acceleration [m/s²], `theta` the heading [rad].
    pub fn command(&mut self, u: Input, theta: f64, dt: f64) -> BodyCommand {
        if !(u[0].is_finite() && u[1].is_finite() && theta.is_finite() && dt.is_finite()) {
            return BodyCommand {
                v: self.v,
                omega: 0.0,
            };
        }
        let (s, c) = theta.sin_cos();
        let a_par = u[0] * c + u[1] * s;
        let a_perp = u[1] * c - u[0] * s;
        self.v = (self.v + a_par * dt.max(0.0)).clamp(-self.limits.v_max, self.limits.v_max);
        let sign = if self.v < 0.0 { -1.0 } else { 1.0 };
        let denom = sign * self.v.abs().max(self.cfg.v_floor);
        let omega = (a_perp / denom).clamp(-self.limits.omega_max, self.limits.omega_max);
        BodyCommand { v: self.v, omega }
    }

    /// Wheel angular speeds (left, right) [rad/s] for a body command, saturated at the wheel
    /// speed limit (both scaled by the same factor). Positive = rolling forward.
    pub fn wheel_speeds(&self, cmd: BodyCommand) -> (f64, f64) {
        let WheelGeometry { radius, separation } = self.geometry;
        let left = (cmd.v - 0.5 * cmd.omega * separation) / radius;
        let right = (cmd.v + 0.5 * cmd.omega * separation) / radius;
        if !(left.is_finite() && right.is_finite()) {
            return (0.0, 0.0);
        }
        let peak = left.abs().max(right.abs());
        if peak > self.limits.wheel_speed_max {
            let k = self.limits.wheel_speed_max / peak;
            (left * k, right * k)
        } else {
            (left, right)
        }
    }

    /// Inverse kinematics: the body command that wheel speeds (left, right) [rad/s] produce.
    pub fn body_from_wheels(&self, left: f64, right: f64) -> BodyCommand {
        let WheelGeometry { radius, separation } = self.geometry;
        BodyCommand {
            v: 0.5 * radius * (left + right),
            omega: radius * (right - left) / separation,
        }
    }

    /// The compensator's current forward speed (the state of (6.3)) [m/s].
    pub fn speed(&self) -> f64 {
        self.v
    }

    /// Resets the integrator of (6.3) to `v` [m/s] (clamped to the limits; non-finite → 0).
    pub fn reset(&mut self, v: f64) {
        self.v = if v.is_finite() {
            v.clamp(-self.limits.v_max, self.limits.v_max)
        } else {
            0.0
        };
    }

    /// The wheel geometry.
    pub fn geometry(&self) -> &WheelGeometry {
        &self.geometry
    }

    /// The drive limits.
    pub fn limits(&self) -> &DriveLimits {
        &self.limits
    }
}

//! The drive chain: planar acceleration u (eq. 6.2) → body command (v, ω) through the
//! compensator (6.3)–(6.4) → wheel angular speeds from the URDF's wheel radius and separation.
//! [`crate::physics::PhysicsWorld::set_wheel_speeds`] turns wheel speeds into joint-motor targets.
//!
//! The compensator itself is [`ftcbf_controller::drive::Compensator`] (it is part of the control
//! law); this module owns the wheel kinematics and configures the compensator with the
//! `Floor` low-speed law of (6.4) (ω = a⊥ / (s·max(|v|, v_floor))) and no rate limits.
//!
//! The loop is closed on the measured speed ([`Drive::step`]): before each compensator step the
//! integrator of (6.3) is pulled towards the forward speed the wheel encoders measure
//! (`speed_gain`, default 0.1 per control step), so the integrator cannot wind up far beyond
//! what the wheels deliver. Feeding the wheel-saturated command back (`feed_back_saturation`) is
//! implemented but the runner leaves it off: with the `Floor` law it traps the robot at low
//! speed (ω = a⊥/v_floor saturates the wheels, the scaled-down v keeps ω large; measured: the
//! goal reached in 0 of 8 seeds of three_gnss and waffle_pillars). The encoders, not a
//! sensor channel of the world, because the channels are the attack surface the fault-tolerant
//! estimator exists to handle (a spoofed `odom_vx` must not reach the drive unfiltered), and
//! because they measure the body-frame speed of (6.3) directly, as the TurtleBot3's motor
//! board does.
//!
//! Wheel kinematics (r = radius, L = separation): ω_left = (v − ωL/2)/r, ω_right = (v + ωL/2)/r;
//! if either exceeds the wheel-speed limit both are scaled down by the same factor (the path's
//! curvature is kept).

pub use ftcbf_controller::drive::BodyCommand;
use ftcbf_controller::drive::{Compensator, CompensatorConfig, CompensatorError, LowSpeedLaw};
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

/// The compensator validates v_max, omega_max and v_floor; its errors read as the drive's.
impl From<CompensatorError> for DriveError {
    fn from(e: CompensatorError) -> Self {
        let CompensatorError::InvalidValue {
            key,
            expected,
            value,
        } = e;
        DriveError::InvalidValue {
            key,
            expected,
            value,
        }
    }
}

/// Configuration of the compensator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveConfig {
    /// Floor of |v| in the denominator of (6.4) [m/s]. Default 0.05.
    pub v_floor: f64,
    /// Initial forward speed of the integrator (6.3) [m/s]. Default 0.
    pub v_initial: f64,
    /// `Some(v_soft)`: the `Regularised` low-speed law ω = a⊥·v/(v² + v_soft²) instead of the
    /// floor. Default None (the floor).
    pub v_soft: Option<f64>,
    /// Rate limit on v [m/s²]. Default None.
    pub dv_max: Option<f64>,
    /// Rate limit on ω [rad/s²]. Default None.
    pub domega_max: Option<f64>,
    /// Gain k ∈ [0, 1] of the correction v ← v + k·(v_measured − v) before each step; 0 is
    /// the open loop. Default 0.1: at a steady acceleration a the integrator may lead the
    /// measured speed by a·dt/k (10 control steps), which the motors' lag needs.
    pub speed_gain: f64,
    /// Resolution of a wheel's speed command [rad/s] (0: none). A yaw rate below half the
    /// drive's step r·Δ/L is sent as 0 (see `ftcbf_controller::drive`). Default 0.
    pub wheel_speed_resolution: f64,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self {
            v_floor: 0.05,
            v_initial: 0.0,
            v_soft: None,
            dv_max: None,
            domega_max: None,
            speed_gain: 0.1,
            wheel_speed_resolution: 0.0,
        }
    }
}

/// The compensator state and the wheel kinematics.
#[derive(Debug, Clone)]
pub struct Drive {
    geometry: WheelGeometry,
    limits: DriveLimits,
    compensator: Compensator,
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
        check("wheel_speed_max", limits.wheel_speed_max)?;
        if !cfg.v_initial.is_finite() {
            return Err(DriveError::InvalidValue {
                key: "v_initial",
                expected: "a finite number",
                value: cfg.v_initial,
            });
        }
        if !(cfg.wheel_speed_resolution.is_finite() && cfg.wheel_speed_resolution >= 0.0) {
            return Err(DriveError::InvalidValue {
                key: "wheel_speed_resolution",
                expected: "a finite number ≥ 0 [rad/s]",
                value: cfg.wheel_speed_resolution,
            });
        }
        let mut compensator = Compensator::new(CompensatorConfig {
            v_max: limits.v_max,
            omega_max: limits.omega_max,
            dv_max: cfg.dv_max,
            domega_max: cfg.domega_max,
            low_speed: match cfg.v_soft {
                Some(v_soft) => LowSpeedLaw::Regularised { v_soft },
                None => LowSpeedLaw::Floor {
                    v_floor: cfg.v_floor,
                },
            },
            speed_gain: cfg.speed_gain,
            omega_resolution: geometry.radius * cfg.wheel_speed_resolution / geometry.separation,
        })?;
        compensator.reset(cfg.v_initial);
        Ok(Self {
            geometry: *geometry,
            limits: *limits,
            compensator,
        })
    }

    /// One compensator step: integrates (6.3) over `dt` \[s\] and applies (6.4) with the guard.
    /// `u` is the world-frame acceleration [m/s²], `theta` the heading \[rad\].
    pub fn command(&mut self, u: Input, theta: f64, dt: f64) -> BodyCommand {
        self.compensator.command(u, theta, dt)
    }

    /// One control period in closed loop: corrects the integrator towards `measured_v`, the
    /// forward speed measured now [m/s] (`None` or non-finite: no correction), runs the
    /// compensator ([`Drive::command`]), saturates at the wheels ([`Drive::wheel_speeds`]) and,
    /// with `feed_back_saturation`, feeds the command the wheels will actually follow back into
    /// the compensator.
    /// Returns that command and the wheel speeds (left, right) [rad/s].
    pub fn step(
        &mut self,
        u: Input,
        theta: f64,
        dt: f64,
        measured_v: Option<f64>,
        feed_back_saturation: bool,
    ) -> (BodyCommand, (f64, f64)) {
        if let Some(v) = measured_v {
            self.compensator.observe_speed(v);
        }
        let cmd = self.command(u, theta, dt);
        let (l, r) = self.wheel_speeds(cmd);
        let sent = self.body_from_wheels(l, r);
        if feed_back_saturation && sent != cmd {
            self.compensator.saturated(sent);
        }
        (sent, (l, r))
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
        self.compensator.current().v
    }

    /// Resets the integrator of (6.3) to `v` [m/s] (clamped to the limits; non-finite → 0).
    pub fn reset(&mut self, v: f64) {
        self.compensator.reset(v);
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

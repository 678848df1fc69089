//! Physical ranges of every number a world file (and the robot it loads) may hold: the one
//! place that decides whether a value is fit for the plant, the planner, parry and the Riccati
//! solver. [`World::load`](super::World::load) checks them (so `check`, `run`, `batch`,
//! `falsify` and `regress` refuse the same files, `--set` and `--sweep` included); the README's
//! world-file reference lists them.
//!
//! The ranges are those of a ground robot: positions within 10 km of the origin, sizes from
//! 0.1 mm to 1 km, control rates from 1 Hz to 10 kHz, runs of at most an hour. A value outside
//! them is refused with its key, not clamped: beyond them the numbers the controller derives
//! (Riccati covariances, h̄_γ bounds, the planner's grid, parry's f32 shapes) overflow, lose
//! all precision or take unbounded time.

/// A closed interval `[min, max]` with its unit, for messages and the README.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Smallest value accepted.
    pub min: f64,
    /// Largest value accepted.
    pub max: f64,
    /// Whether `min` itself is excluded (a strictly positive quantity).
    pub open_min: bool,
    /// Unit, e.g. "m".
    pub unit: &'static str,
}

impl Range {
    const fn closed(min: f64, max: f64, unit: &'static str) -> Self {
        Self {
            min,
            max,
            open_min: false,
            unit,
        }
    }

    const fn positive(max: f64, unit: &'static str) -> Self {
        Self {
            min: 0.0,
            max,
            open_min: true,
            unit,
        }
    }

    /// Whether `v` lies in the range (never for NaN or ±∞).
    pub fn contains(&self, v: f64) -> bool {
        v.is_finite()
            && v <= self.max
            && if self.open_min {
                v > self.min
            } else {
                v >= self.min
            }
    }

    /// "[1, 10000] Hz", "(0, 1000] m".
    pub fn describe(&self) -> String {
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        format!(
            "{}{}, {}]{unit}",
            if self.open_min { "(" } else { "[" },
            fmt_bound(self.min),
            fmt_bound(self.max)
        )
    }
}

/// A value as a message shows it: compact for very large and very small magnitudes
/// (`1e308`, `5e-324`), as written otherwise.
pub fn fmt_value(v: f64) -> String {
    if v.is_finite() && v != 0.0 && (v.abs() >= 1e6 || v.abs() < 1e-4) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

fn fmt_bound(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e5 || v.abs() < 1e-3) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// A world-frame coordinate (start, goal, waypoints, centres, obstacle positions, the linear
/// plant's x0 position) \[m\].
pub const POSITION: Range = Range::closed(-1.0e4, 1.0e4, "m");
/// A size: half extents, radii, half heights, semi-axes, the goal radius \[m\].
pub const SIZE: Range = Range::closed(1.0e-4, 1.0e3, "m");
/// An angle: headings, rpy, an ellipse's rotation \[rad\].
pub const ANGLE: Range = Range::closed(-100.0, 100.0, "rad");
/// A velocity component of the linear plant's x0 [m/s].
pub const VELOCITY: Range = Range::closed(-100.0, 100.0, "m/s");
/// `duration` and `run --duration` \[s\].
pub const DURATION: Range = Range::positive(3600.0, "s");

/// A run's `--duration` (the CLI's option, `RunOptions::duration` from Python and the library)
/// checked against [`DURATION`]: the one place it is validated, with the one message.
pub fn check_duration(d: f64) -> Result<f64, String> {
    if DURATION.contains(d) {
        Ok(d)
    } else {
        Err(format!(
            "--duration {d}: expected a number of seconds in {}",
            DURATION.describe()
        ))
    }
}
/// `control.rate_hz` \[Hz\].
pub const CONTROL_RATE: Range = Range::closed(1.0, 1.0e4, "Hz");
/// A sensor channel's `rate_hz` \[Hz\].
pub const SENSOR_RATE: Range = Range::closed(1.0e-3, 1.0e4, "Hz");
/// `physics.dt` \[s\] (rapier).
pub const PHYSICS_DT: Range = Range::closed(1.0e-5, 0.02, "s");
/// `linear.dt` \[s\].
pub const LINEAR_DT: Range = Range::closed(1.0e-6, 0.1, "s");
/// Control steps of a run, duration × rate_hz (the horizon of `check`'s bounds).
pub const MAX_CONTROL_STEPS: f64 = 5.0e5;
/// Plant steps of a run, duration / plant dt.
pub const MAX_PLANT_STEPS: f64 = 2.0e7;
/// `physics.friction`.
pub const FRICTION: Range = Range::closed(0.0, 10.0, "");
/// A speed limit or cruise speed [m/s].
pub const SPEED: Range = Range::positive(100.0, "m/s");
/// A yaw-rate limit [rad/s].
pub const YAW_RATE: Range = Range::positive(1.0e3, "rad/s");
/// A wheel's angular-speed limit [rad/s].
pub const WHEEL_SPEED: Range = Range::positive(1.0e4, "rad/s");
/// An acceleration bound (`input_limit`, `dv_max`, `arrive_accel`) [m/s² or rad/s²].
pub const ACCELERATION: Range = Range::positive(1.0e3, "m/s²");
/// `control.gamma`, `control.theta`, `control.delta`: error and separation bounds \[m\].
pub const ERROR_BOUND: Range = Range::closed(0.0, 1.0e4, "m");
/// A gain (`cbf_gain`, `clf.rho`, `nominal.speed_gain`) [1/s].
pub const GAIN: Range = Range::positive(1.0e3, "1/s");
/// `control.epsilon`.
pub const EPSILON: Range = Range::closed(1.0e-9, 0.5, "");
/// A process-noise intensity (`control.process_noise`, `linear.process_noise`).
/// (0 is also accepted: no process noise.)
pub const PROCESS_NOISE: Range = Range::closed(1.0e-9, 1.0e3, "unit²/s");
/// `control.initial_std` [m, m/s].
pub const INITIAL_STD: Range = Range::closed(0.0, 100.0, "m or m/s");
/// `control.clf.v_bar`.
pub const CLF_LEVEL: Range = Range::closed(0.0, 1.0e6, "");
/// `control.obstacle_margin` \[m\].
pub const MARGIN: Range = Range::closed(0.0, 10.0, "m");
/// A lift gain k of a relative-degree-2 barrier (`obstacle_lift`, a safe set's `lift`) \[s\].
pub const LIFT: Range = Range::closed(0.0, 100.0, "s");
/// A length of the tracker (`lookahead`, `stall_progress`) \[m\].
pub const TRACKER_LENGTH: Range = Range::positive(1.0e3, "m");
/// A time constant or duration of the tracker (`smoothing`, `stall_time`, `escape_time`) \[s\].
pub const TRACKER_TIME: Range = Range::positive(3600.0, "s");
/// `nominal.smoothing` (0: no low-pass) \[s\].
pub const SMOOTHING: Range = Range::closed(0.0, 3600.0, "s");
/// `nominal.jerk_limit` [m/s³].
pub const JERK: Range = Range::positive(1.0e4, "m/s³");
/// `nominal.escape_angle` \[rad\].
pub const ESCAPE_ANGLE: Range = Range::closed(-std::f64::consts::PI, std::f64::consts::PI, "rad");
/// `drive.low_speed_scale` (v_floor, v_soft) [m/s].
pub const LOW_SPEED_SCALE: Range = Range::positive(10.0, "m/s");
/// `drive.wheel_speed_resolution` [rad/s].
pub const WHEEL_RESOLUTION: Range = Range::closed(0.0, 100.0, "rad/s");
/// A half-plane safe set's normal components `a`.
pub const NORMAL_COMPONENT: Range = Range::closed(-1.0e3, 1.0e3, "");
/// A half-plane safe set's offset `b`.
pub const OFFSET: Range = Range::closed(-1.0e7, 1.0e7, "");
/// A sensor's `noise_std` and `bias_walk_std` [unit].
pub const NOISE_STD: Range = Range::closed(0.0, 1.0e3, "unit");
/// A sensor's `bias` [unit].
pub const BIAS: Range = Range::closed(-1.0e4, 1.0e4, "unit");
/// A wheel encoder's `ticks_per_rev`.
pub const TICKS_PER_REV: Range = Range::closed(1.0, 1.0e7, "");
/// Robot geometry from the URDF: every link origin, collider extent and mesh vertex within this
/// distance of the robot's root \[m\].
pub const ROBOT_EXTENT: f64 = 100.0;
/// A robot collision shape's half extents, radii and half lengths \[m\].
pub const ROBOT_SHAPE: Range = Range::closed(1.0e-5, 100.0, "m");
/// A robot link's mass \[kg\].
pub const MAX_LINK_MASS: f64 = 1.0e6;
/// A robot link's inertia entries [kg·m²].
pub const MAX_LINK_INERTIA: f64 = 1.0e8;
/// A `tri_mesh` obstacle's `scale`.
pub const MESH_SCALE: Range = Range::closed(1.0e-6, 1.0e6, "");
/// The robot's wheel radius, wheel separation and footprint radius \[m\].
pub const ROBOT_SIZE: Range = Range::closed(1.0e-3, 100.0, "m");

/// Most `[[fault_patterns]]` a world may declare (the bank holds 1 + m + m(m−1)/2 filters).
pub const MAX_FAULT_PATTERNS: usize = 12;
/// Most `[[sensors]]` channels.
pub const MAX_SENSORS: usize = 64;
/// Most `[[obstacles]]`.
pub const MAX_OBSTACLES: usize = 256;
/// Most `[[safe_sets]]`.
pub const MAX_SAFE_SETS: usize = 64;
/// Most `[goal] waypoints`.
pub const MAX_WAYPOINTS: usize = 256;
/// Most `[[attacks]]`.
pub const MAX_ATTACKS: usize = 64;
/// Most points of a `convex_hull` obstacle or vertices of a `tri_mesh`.
pub const MAX_SHAPE_POINTS: usize = 100_000;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_refuse_non_finite_and_describe_themselves() {
        for r in [POSITION, SIZE, DURATION, CONTROL_RATE, EPSILON] {
            assert!(!r.contains(f64::NAN));
            assert!(!r.contains(f64::INFINITY));
            assert!(!r.contains(f64::NEG_INFINITY));
        }
        assert!(!DURATION.contains(0.0));
        assert!(DURATION.contains(3600.0));
        assert!(!SIZE.contains(1e-300));
        assert!(!EPSILON.contains(5e-324));
        assert_eq!(CONTROL_RATE.describe(), "[1, 10000] Hz");
        assert_eq!(DURATION.describe(), "(0, 3600] s");
        assert_eq!(SIZE.describe(), "[1e-4, 1000] m");
    }
}

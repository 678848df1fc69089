//! World files: what a run is. A [`World`] is the validated, immutable description (parsed and
//! checked once, like MuJoCo's `mjModel`); the runner keeps the mutable state.
//!
//! One file (about 1,250 lines): [`World`] and its validator, whose checks run section by
//! section in the file's order so that the first error reported is the first one in the file.
//! What stands apart lives beside it: the physical ranges (`ranges`), the sensing structure
//! (`structure`), the error paths of a parse error (`parse_error`), the schema (`crate::spec`).

mod overrides;
mod parse_error;
pub mod ranges;
pub mod sdf;
pub mod structure;
mod toml_limits;

use std::path::{Path, PathBuf};

pub use crate::spec::expect::{Count, Expect, ExpectOutcome, Margin};
pub use crate::spec::schema::*;
pub use overrides::Override;

/// Deceleration of the safe stop's braking \[m/s²\] for a world without `[control]
/// input_limit` (with one, the limit): the braking the safe stop's stopping distance assumes
/// (0.22 m/s → 2.4 cm).
pub const DEFAULT_BRAKE_DECELERATION: f64 = 1.0;

use crate::attacks::validate_attacks;
use crate::obstacles::{Obstacle, ObstacleSpec, ShapeSpec};
use crate::robot::{DriveLimits, LoadOptions, RobotDescription};
use crate::sensors::{resolve_patterns, validate_channels, Quantity};

/// Why a world file cannot be used. Every variant names the file; validation errors also name the
/// key path and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The file cannot be read. (The cause is in the message, not also a `source`, so that
    /// a chain printed with `{:#}` says it once.)
    #[error("{path}: cannot read the world file (expected a readable TOML file): {error}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        error: std::io::Error,
    },
    /// The file is not UTF-8 text (TOML must be).
    #[error("{path}: not UTF-8 text: invalid byte 0x{byte:02x} at byte offset {offset} (line {line}, column {column}); TOML files must be UTF-8")]
    Utf8 {
        /// File.
        path: PathBuf,
        /// Offset of the first invalid byte from the start of the file.
        offset: usize,
        /// The byte.
        byte: u8,
        /// Its line (1-based).
        line: usize,
        /// Its column (1-based, in characters of the valid text before it).
        column: usize,
    },
    /// Not valid TOML (a syntax error).
    #[error("{path}: {message}")]
    Parse {
        /// File.
        path: PathBuf,
        /// The parser's message, with line and column.
        message: String,
    },
    /// Valid TOML that does not fit the world schema (unknown key, wrong type, missing key).
    #[error("{path}{}: `{key}`: {message}{excerpt}", fmt_place(.place))]
    Schema {
        /// File.
        path: PathBuf,
        /// Dotted key path, array indices included, e.g. `obstacles[2].shape.half_extents`.
        key: String,
        /// Line and column of the key in the file (1-based, the column in characters): those of
        /// the deepest part of the path the file contains, for a missing key.
        place: Option<(usize, usize)>,
        /// What was found and what was expected.
        message: String,
        /// The line of the file with a caret under the column (empty without a place).
        excerpt: String,
    },
    /// A value is out of its range or inconsistent with another.
    #[error("{path}: `{key}`: {message}")]
    Invalid {
        /// File.
        path: PathBuf,
        /// Key path, e.g. `attacks[2].channels`.
        key: String,
        /// What was found and what was expected.
        message: String,
    },
    /// An override (`--sweep`, `--set`) does not fit the file.
    #[error("{path}: override (--set or --sweep) {message}")]
    Override {
        /// File.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// `:LINE:COLUMN` after a file name, or nothing.
fn fmt_place(p: &Option<(usize, usize)>) -> String {
    p.map_or(String::new(), |(l, c)| format!(":{l}:{c}"))
}

/// A validated world: the file plus everything derived from it once (robot, obstacles, channel
/// indices). Cheap to share between parallel trials (`&World` is `Sync`).
#[derive(Debug, Clone)]
pub struct World {
    /// World name (the file's `name`, or its stem).
    pub name: String,
    /// The file it came from.
    pub path: PathBuf,
    /// The parsed, checked file (after overrides).
    pub file: WorldFile,
    /// The robot, for `rapier` dynamics.
    pub robot: Option<RobotDescription>,
    /// The obstacles, built.
    pub obstacles: Vec<Obstacle>,
    /// Fault patterns as channel indices into the sensor list.
    pub patterns: Vec<Vec<usize>>,
    /// Physics ticks per control step.
    pub ticks_per_control: u32,
    /// What `[environment] sdf` loaded (its obstacles are in `obstacles` and `file.obstacles`,
    /// after the file's own; `sdf` and `model_paths` are taken out of `file.environment` once
    /// loaded, so that a world edited through [`World::with_file`] does not load it twice).
    pub environment: Option<crate::environment::EnvironmentReport>,
}

impl World {
    /// Reads, parses, overrides and validates a world file.
    pub fn load(path: &Path, overrides: &[Override]) -> Result<World, WorldError> {
        let bytes = std::fs::read(path).map_err(|error| WorldError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        let text = String::from_utf8(bytes).map_err(|e| {
            let offset = e.utf8_error().valid_up_to();
            let bytes = e.as_bytes();
            let valid = String::from_utf8_lossy(&bytes[..offset]);
            let line = valid.matches('\n').count() + 1;
            let column = valid.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            WorldError::Utf8 {
                path: path.to_path_buf(),
                offset,
                byte: bytes[offset],
                line,
                column,
            }
        })?;
        Self::from_str(&text, path, overrides)
    }

    /// Parses and validates world text; `path` names it in errors and anchors relative paths.
    pub fn from_str(text: &str, path: &Path, overrides: &[Override]) -> Result<World, WorldError> {
        let parse_err = |message: String| WorldError::Parse {
            path: path.to_path_buf(),
            message,
        };
        // First the file as written, so errors carry its own line numbers.
        let mut file: WorldFile = parse_error::from_text(text, path)?;
        if !overrides.is_empty() {
            let mut doc: toml::Value =
                toml::from_str(text).map_err(|e| parse_err(e.to_string()))?;
            for ov in overrides {
                overrides::apply(&mut doc, ov).map_err(|message| WorldError::Override {
                    path: path.to_path_buf(),
                    message,
                })?;
            }
            file = parse_error::from_value(doc).map_err(|(key, e)| WorldError::Override {
                path: path.to_path_buf(),
                message: format!(
                    "{}: the overridden file no longer fits the schema: `{key}`: {e}",
                    overrides
                        .iter()
                        .map(|o| o.to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })?;
        }
        let name = file.name.clone().unwrap_or_else(|| {
            path.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "world".into())
        });
        file.resolve_defaults();
        Self::validated(file, name, path, None)
    }

    /// This world with `file` in place of its own (a copy of `self.file` edited in memory:
    /// attacks, obstacles, start, goal, noise, …), validated exactly as [`World::from_str`]
    /// validates a file, without reading anything again: the robot description is this world's
    /// (so `file.robot` must name the same robot — URDF, packages, wheels, limits, xacro
    /// arguments; its `start` may differ). Mesh obstacles are loaded from their files.
    pub fn with_file(&self, file: WorldFile) -> Result<World, WorldError> {
        let mut w = Self::validated(file, self.name.clone(), &self.path, self.robot.clone())?;
        if w.environment.is_none() {
            // The SDF file's obstacles came along in `file.obstacles`; so does its report.
            w.environment = self.environment.clone();
        }
        Ok(w)
    }

    /// Validates a resolved file and checks the control structure; `robot`, if given, is used
    /// instead of loading `file.robot`'s URDF.
    fn validated(
        file: WorldFile,
        name: String,
        path: &Path,
        robot: Option<RobotDescription>,
    ) -> Result<World, WorldError> {
        let world = Validator { path }.validate(file, name, robot)?;
        structure::check_structure(&world).map_err(|e| WorldError::Invalid {
            path: path.to_path_buf(),
            key: e.key,
            message: e.message,
        })?;
        Ok(world)
    }

    /// Directory that relative paths in the file are resolved against.
    pub fn base_dir(&self) -> &Path {
        self.path.parent().unwrap_or_else(|| Path::new("."))
    }

    /// Whether some obstacle moves (has a `motion`).
    pub fn has_movers(&self) -> bool {
        self.obstacles.iter().any(|o| o.spec.motion.is_some())
    }

    /// The largest κ the rows may use at the world's control rate: κ·dt ≤ 1/2, so that one
    /// control period cannot take ĥ from its value past zero (the condition is imposed on a
    /// sampled system: with κ·dt → 1 the sampled input already acts on the whole margin in one
    /// step).
    pub fn kappa_max(&self) -> f64 {
        0.5 / self.control_dt()
    }

    /// Deceleration of the safe stop's braking \[m/s²\]: `[control] input_limit`, or
    /// [`DEFAULT_BRAKE_DECELERATION`] without one.
    pub fn brake_deceleration(&self) -> f64 {
        self.file
            .control
            .input_limit
            .unwrap_or(DEFAULT_BRAKE_DECELERATION)
    }

    /// Control period \[s\].
    pub fn control_dt(&self) -> f64 {
        1.0 / self.file.control.rate_hz
    }

    /// Control steps in a run of `duration` seconds (at least one): the one count the runner
    /// steps and the CLI's progress bar shows.
    pub fn control_steps(&self, duration: f64) -> u64 {
        (duration / self.control_dt()).round().max(1.0) as u64
    }

    /// The control ticks the bounds cover, ⌈T/dt⌉ for the file's duration T (at least 1): the
    /// horizon γ, θ, η, the gap budget and the analyses' worst cases are taken over. Never fewer
    /// than the run's [`World::control_steps`] (a rounded count), so the bounds cover the run.
    pub fn horizon_ticks(&self) -> usize {
        (self.file.duration / self.control_dt()).ceil().max(1.0) as usize
    }

    /// Plant step \[s\] (physics or linear integration).
    pub fn plant_dt(&self) -> f64 {
        match self.file.dynamics {
            Dynamics::Rapier => self.file.physics.dt,
            Dynamics::Linear => self.file.linear.as_ref().map_or(1e-3, |l| l.dt),
        }
    }
}

struct Validator<'a> {
    path: &'a Path,
}

impl Validator<'_> {
    fn err(&self, key: impl Into<String>, message: impl Into<String>) -> WorldError {
        WorldError::Invalid {
            path: self.path.to_path_buf(),
            key: key.into(),
            message: message.into(),
        }
    }

    fn positive(&self, key: &str, v: f64) -> Result<(), WorldError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(self.err(key, format!("expected a finite number > 0, found {v}")))
        }
    }

    fn non_negative(&self, key: &str, v: f64) -> Result<(), WorldError> {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(self.err(key, format!("expected a finite number ≥ 0, found {v}")))
        }
    }

    /// `v` within `r` (the physical ranges of [`ranges`]), else an error naming `key`.
    fn range(&self, key: &str, v: f64, r: ranges::Range) -> Result<(), WorldError> {
        if r.contains(v) {
            Ok(())
        } else {
            Err(self.err(
                key,
                format!(
                    "expected a number in {}, found {}",
                    r.describe(),
                    ranges::fmt_value(v)
                ),
            ))
        }
    }

    /// Every value of `values` within `r`; the key of an element is `key[i]`.
    fn ranges(&self, key: &str, values: &[f64], r: ranges::Range) -> Result<(), WorldError> {
        for (i, v) in values.iter().enumerate() {
            self.range(&format!("{key}[{i}]"), *v, r)?;
        }
        Ok(())
    }

    /// An optional value within `r`.
    fn opt_range(&self, key: &str, v: Option<f64>, r: ranges::Range) -> Result<(), WorldError> {
        v.map_or(Ok(()), |v| self.range(key, v, r))
    }

    /// A process-noise intensity: 0 (none) or within [`ranges::PROCESS_NOISE`] (a subnormal
    /// intensity leaves the Riccati recursion crawling towards its steady state).
    fn noise_intensity(&self, key: &str, q: f64) -> Result<(), WorldError> {
        if q == 0.0 {
            Ok(())
        } else {
            self.range(key, q, ranges::PROCESS_NOISE)
        }
    }

    /// At most `max` entries of `key`.
    fn count(&self, key: &str, n: usize, max: usize) -> Result<(), WorldError> {
        if n <= max {
            Ok(())
        } else {
            Err(self.err(
                key,
                format!("{n} entries; at most {max} are supported (see the world-file reference, book/src/reference/world-file.md)"),
            ))
        }
    }

    fn finite(&self, key: &str, values: &[f64]) -> Result<(), WorldError> {
        match values.iter().find(|v| !v.is_finite()) {
            Some(v) => Err(self.err(key, format!("expected finite numbers, found {v}"))),
            None => Ok(()),
        }
    }

    /// Every number of the file within its physical range ([`ranges`]) and every list within
    /// its size: run before anything is derived from the file. Section by section, in the
    /// file's order, so the first value out of range is the one reported.
    fn check_ranges(&self, file: &WorldFile) -> Result<(), WorldError> {
        self.range("duration", file.duration, ranges::DURATION)?;
        self.check_dynamics_ranges(file)?;
        self.check_robot_ranges(file)?;
        self.check_control_ranges(file)?;
        self.check_goal_ranges(file)?;
        self.check_safe_set_ranges(file)?;
        self.count("obstacles", file.obstacles.len(), ranges::MAX_OBSTACLES)?;
        for (i, o) in file.obstacles.iter().enumerate() {
            self.check_obstacle_ranges(&format!("obstacles[{i}]"), o)?;
        }
        self.check_sensor_ranges(file)?;
        self.count(
            "fault_patterns",
            file.fault_patterns.len(),
            ranges::MAX_FAULT_PATTERNS,
        )?;
        self.count("attacks", file.attacks.len(), ranges::MAX_ATTACKS)?;
        Ok(())
    }

    /// Each `(key, value, range)` of `table` in order: a value that is `None` (left out) is not
    /// checked.
    fn table(&self, table: &[(&str, Option<f64>, ranges::Range)]) -> Result<(), WorldError> {
        table
            .iter()
            .try_for_each(|&(key, v, r)| self.opt_range(key, v, r))
    }

    /// `[physics]` for the rapier plant; `[linear]` (and a process noise the filters can use)
    /// for the linear one.
    fn check_dynamics_ranges(&self, file: &WorldFile) -> Result<(), WorldError> {
        use ranges as r;
        match file.dynamics {
            Dynamics::Rapier => {
                self.range("physics.dt", file.physics.dt, r::PHYSICS_DT)?;
                self.range("physics.friction", file.physics.friction, r::FRICTION)?;
            }
            Dynamics::Linear => {
                if let Some(l) = &file.linear {
                    self.range("linear.dt", l.dt, r::LINEAR_DT)?;
                    self.noise_intensity("linear.process_noise", l.process_noise)?;
                    self.ranges("linear.x0", &l.x0[..2], r::POSITION)?;
                    for i in 2..4 {
                        self.range(&format!("linear.x0[{i}]"), l.x0[i], r::VELOCITY)?;
                    }
                    self.opt_range("linear.v_max", l.v_max, r::SPEED)?;
                    // The filters' q is the plant's unless the file gives its own. A filter
                    // without process noise has no steady state it reaches: its covariance
                    // shrinks as 1/t, and every Riccati recursion of `check` and of the run's
                    // setup runs to its limit of 10⁶ iterations (seconds per filter; the fuzz
                    // found it as a hang). A noiseless plant is fine; the filters need q > 0.
                    if l.process_noise == 0.0 && file.control.process_noise.is_none() {
                        return Err(self.err(
                            "linear.process_noise",
                            format!(
                                "0 (a noiseless plant) would also be the filters' process noise, since control.process_noise is not set, and a filter without process noise has no steady state within reach (its covariance shrinks as 1/t); set control.process_noise to a number in {}",
                                r::PROCESS_NOISE.describe()
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// `[robot]`: the start pose and the drive-limit override.
    fn check_robot_ranges(&self, file: &WorldFile) -> Result<(), WorldError> {
        use ranges as r;
        let Some(rb) = &file.robot else {
            return Ok(());
        };
        let limits = rb.limits;
        self.table(&[
            ("robot.start.x", Some(rb.start.x), r::POSITION),
            ("robot.start.y", Some(rb.start.y), r::POSITION),
            ("robot.start.theta", Some(rb.start.theta), r::ANGLE),
            ("robot.limits.v_max", limits.map(|l| l.v_max), r::SPEED),
            (
                "robot.limits.omega_max",
                limits.map(|l| l.omega_max),
                r::YAW_RATE,
            ),
            (
                "robot.limits.wheel_speed_max",
                limits.map(|l| l.wheel_speed_max),
                r::WHEEL_SPEED,
            ),
        ])
    }

    /// The run's length in control and plant steps within what is supported.
    fn check_step_counts(&self, file: &WorldFile) -> Result<(), WorldError> {
        use ranges as r;
        let rate_hz = file.control.rate_hz;
        let steps = file.duration * rate_hz;
        if steps > r::MAX_CONTROL_STEPS {
            return Err(self.err(
                "duration",
                format!(
                    "{} s at control.rate_hz = {} Hz is {steps} control steps; at most {} are supported",
                    file.duration,
                    rate_hz,
                    r::MAX_CONTROL_STEPS
                ),
            ));
        }
        let plant_dt = match file.dynamics {
            Dynamics::Rapier => file.physics.dt,
            Dynamics::Linear => file.linear.as_ref().map_or(1e-3, |l| l.dt),
        };
        let plant_steps = file.duration / plant_dt;
        if plant_steps > r::MAX_PLANT_STEPS {
            return Err(self.err(
                "duration",
                format!(
                    "{} s at a plant step of {plant_dt} s is {plant_steps} plant steps; at most {} are supported",
                    file.duration,
                    r::MAX_PLANT_STEPS
                ),
            ));
        }
        Ok(())
    }

    /// `[control]` with its `clf`, `nominal` and `drive` tables.
    fn check_control_ranges(&self, file: &WorldFile) -> Result<(), WorldError> {
        use ranges as r;
        let c = &file.control;
        self.range("control.rate_hz", c.rate_hz, r::CONTROL_RATE)?;
        self.check_step_counts(file)?;
        let value = |p: &Param| match p {
            Param::Value(v) => Some(*v),
            _ => None,
        };
        self.table(&[
            ("control.input_limit", c.input_limit, r::ACCELERATION),
            ("control.gamma", value(&c.gamma), r::ERROR_BOUND),
            ("control.theta", value(&c.theta), r::ERROR_BOUND),
            ("control.delta", c.delta, r::ERROR_BOUND),
            ("control.cbf_gain", Some(c.cbf_gain), r::GAIN),
            ("control.epsilon", Some(c.epsilon), r::EPSILON),
        ])?;
        if let Some(q) = c.process_noise {
            self.noise_intensity("control.process_noise", q)?;
        }
        self.ranges("control.initial_std", &c.initial_std, r::INITIAL_STD)?;
        let (n, d) = (&c.nominal, &c.drive);
        self.table(&[
            ("control.clf.v_bar", c.clf.v_bar, r::CLF_LEVEL),
            ("control.clf.rho", c.clf.rho, r::GAIN),
            (
                "control.obstacle_margin",
                Some(c.obstacle_margin),
                r::MARGIN,
            ),
            ("control.obstacle_lift", Some(c.obstacle_lift), r::LIFT),
            ("control.nominal.cruise_speed", n.cruise_speed, r::SPEED),
            ("control.nominal.speed_gain", n.speed_gain, r::GAIN),
            (
                "control.nominal.arrive_accel",
                n.arrive_accel,
                r::ACCELERATION,
            ),
            ("control.nominal.lookahead", n.lookahead, r::TRACKER_LENGTH),
            ("control.nominal.smoothing", n.smoothing, r::SMOOTHING),
            ("control.nominal.jerk_limit", n.jerk_limit, r::JERK),
            (
                "control.nominal.stall_progress",
                n.stall_progress,
                r::TRACKER_LENGTH,
            ),
            ("control.nominal.stall_time", n.stall_time, r::TRACKER_TIME),
            (
                "control.nominal.escape_time",
                n.escape_time,
                r::TRACKER_TIME,
            ),
            (
                "control.nominal.escape_angle",
                n.escape_angle,
                r::ESCAPE_ANGLE,
            ),
            (
                "control.drive.low_speed_scale",
                d.low_speed_scale,
                r::LOW_SPEED_SCALE,
            ),
            ("control.drive.dv_max", d.dv_max, r::ACCELERATION),
            ("control.drive.domega_max", d.domega_max, r::ACCELERATION),
            (
                "control.drive.wheel_speed_resolution",
                d.wheel_speed_resolution,
                r::WHEEL_RESOLUTION,
            ),
        ])
    }

    /// `[goal]`: centre, radius and waypoints.
    fn check_goal_ranges(&self, file: &WorldFile) -> Result<(), WorldError> {
        use ranges as r;
        self.ranges("goal.center", &file.goal.center, r::POSITION)?;
        self.range("goal.radius", file.goal.radius, r::SIZE)?;
        self.count(
            "goal.waypoints",
            file.goal.waypoints.len(),
            r::MAX_WAYPOINTS,
        )?;
        for (i, w) in file.goal.waypoints.iter().enumerate() {
            self.ranges(&format!("goal.waypoints[{i}]"), w, r::POSITION)?;
        }
        Ok(())
    }

    /// `[[safe_sets]]`: their number, and each one's half-plane (a non-zero normal) or ellipse
    /// (positive semi-axes: [`ranges::SIZE`] starts above 0). The one walk over the safe sets'
    /// numbers; [`ranges::Range::contains`] also refuses NaN and ±∞.
    fn check_safe_set_ranges(&self, file: &WorldFile) -> Result<(), WorldError> {
        use ranges as r;
        self.count("safe_sets", file.safe_sets.len(), r::MAX_SAFE_SETS)?;
        for (i, s) in file.safe_sets.iter().enumerate() {
            let key = format!("safe_sets[{i}]");
            match s {
                SafeSetSpec::HalfPlane { a, b, .. } => {
                    self.ranges(&format!("{key}.a"), a, r::NORMAL_COMPONENT)?;
                    self.range(&format!("{key}.b"), *b, r::OFFSET)?;
                    if a.iter().all(|v| *v == 0.0) {
                        return Err(
                            self.err(format!("{key}.a"), "expected a non-zero normal vector")
                        );
                    }
                }
                SafeSetSpec::EllipseInside {
                    center,
                    semi_axes,
                    angle,
                    lift,
                    ..
                }
                | SafeSetSpec::EllipseOutside {
                    center,
                    semi_axes,
                    angle,
                    lift,
                    ..
                } => {
                    self.ranges(&format!("{key}.center"), center, r::POSITION)?;
                    self.ranges(&format!("{key}.semi_axes"), semi_axes, r::SIZE)?;
                    self.range(&format!("{key}.angle"), *angle, r::ANGLE)?;
                    self.range(&format!("{key}.lift"), *lift, r::LIFT)?;
                }
            }
        }
        Ok(())
    }

    /// One `[[obstacles]]` entry (`key`): its placement and its shape's sizes and lists.
    fn check_obstacle_ranges(&self, key: &str, o: &ObstacleSpec) -> Result<(), WorldError> {
        use ranges as r;
        self.ranges(&format!("{key}.position"), &o.position, r::POSITION)?;
        self.ranges(&format!("{key}.rpy"), &o.rpy, r::ANGLE)?;
        let shape = format!("{key}.shape");
        match &o.shape {
            ShapeSpec::Cuboid { half_extents } => {
                self.ranges(&format!("{shape}.half_extents"), half_extents, r::SIZE)?;
            }
            ShapeSpec::Ball { radius } => {
                self.range(&format!("{shape}.radius"), *radius, r::SIZE)?;
            }
            ShapeSpec::Cylinder {
                radius,
                half_height,
            }
            | ShapeSpec::Capsule {
                radius,
                half_height,
            }
            | ShapeSpec::Cone {
                radius,
                half_height,
            } => {
                self.range(&format!("{shape}.radius"), *radius, r::SIZE)?;
                self.range(&format!("{shape}.half_height"), *half_height, r::SIZE)?;
            }
            ShapeSpec::ConvexHull { points } => {
                self.count(
                    &format!("{shape}.points"),
                    points.len(),
                    r::MAX_SHAPE_POINTS,
                )?;
                for (k, p) in points.iter().enumerate() {
                    self.ranges(&format!("{shape}.points[{k}]"), p, r::POSITION)?;
                }
            }
            ShapeSpec::HalfSpace { normal } => {
                self.ranges(&format!("{shape}.normal"), normal, r::NORMAL_COMPONENT)?;
            }
            ShapeSpec::TriMesh {
                vertices,
                indices,
                scale,
                ..
            } => {
                self.count(
                    &format!("{shape}.vertices"),
                    vertices.len(),
                    r::MAX_SHAPE_POINTS,
                )?;
                self.count(
                    &format!("{shape}.indices"),
                    indices.len(),
                    r::MAX_SHAPE_POINTS,
                )?;
                for (k, p) in vertices.iter().enumerate() {
                    self.ranges(&format!("{shape}.vertices[{k}]"), p, r::POSITION)?;
                }
                match scale {
                    Some(crate::obstacles::MeshScale::Uniform(s)) => {
                        self.range(&format!("{shape}.scale"), s.abs(), r::MESH_SCALE)?;
                    }
                    Some(crate::obstacles::MeshScale::PerAxis(s)) => {
                        for (k, v) in s.iter().enumerate() {
                            self.range(&format!("{shape}.scale[{k}]"), v.abs(), r::MESH_SCALE)?;
                        }
                    }
                    None => {}
                }
            }
            // Never read from a world file (the loader builds it from environment.map).
            ShapeSpec::OccupancyMap { .. } => {}
        }
        Ok(())
    }

    /// `[[sensors]]`: their number, and each channel's noise, bias, rate and encoder ticks.
    fn check_sensor_ranges(&self, file: &WorldFile) -> Result<(), WorldError> {
        use ranges as r;
        self.count("sensors", file.sensors.len(), r::MAX_SENSORS)?;
        for (i, s) in file.sensors.iter().enumerate() {
            let key = format!("sensors[{i}]");
            if s.noise_std.is_nan() {
                // Left out (a from_wheels channel has had it set to 0 by resolve_defaults).
                return Err(self.err(
                    format!("{key}.noise_std"),
                    format!(
                        "missing on channel \"{}\": the standard deviation of its noise, in its unit (only a channel derived `from_wheels` may leave it out)",
                        s.name
                    ),
                ));
            }
            self.table(&[
                (&format!("{key}.noise_std"), Some(s.noise_std), r::NOISE_STD),
                (&format!("{key}.bias"), Some(s.bias), r::BIAS),
                (
                    &format!("{key}.bias_walk_std"),
                    Some(s.bias_walk_std),
                    r::NOISE_STD,
                ),
                (&format!("{key}.rate_hz"), s.rate_hz, r::SENSOR_RATE),
                (
                    &format!("{key}.ticks_per_rev"),
                    s.ticks_per_rev.map(f64::from),
                    r::TICKS_PER_REV,
                ),
            ])?;
        }
        Ok(())
    }

    /// The robot the URDF describes within the ranges of a ground robot: link origins,
    /// collider extents and mesh vertices within [`ranges::ROBOT_EXTENT`] of the root, wheel
    /// radius, separation and footprint within [`ranges::ROBOT_SIZE`], limits within theirs.
    fn check_robot(&self, robot: &RobotDescription) -> Result<(), WorldError> {
        use ranges as r;
        // The URDF's own path too: the value out of range is in that file, not the world file.
        let urdf = if robot.origin == "<string>" {
            String::new()
        } else {
            format!("URDF {}: ", robot.origin)
        };
        let bad = |what: String| {
            self.err(
                "robot.urdf",
                format!(
                    "{urdf}robot `{}`: {what} (see the world-file reference, book/src/reference/world-file.md, for the ranges)",
                    robot.name
                ),
            )
        };
        let g = &robot.wheels.geometry;
        for (what, v) in [
            ("wheel radius", g.radius),
            ("wheel separation", g.separation),
            ("footprint radius", robot.footprint_radius),
        ] {
            if !r::ROBOT_SIZE.contains(v) {
                return Err(bad(format!(
                    "{what} {} m is outside {}",
                    r::fmt_value(v),
                    r::ROBOT_SIZE.describe()
                )));
            }
        }
        if !(robot.centre_height.is_finite() && robot.centre_height.abs() <= r::ROBOT_EXTENT) {
            return Err(bad(format!(
                "centre height {} m is outside [-{e}, {e}] m",
                robot.centre_height,
                e = r::ROBOT_EXTENT
            )));
        }
        for (what, v, range) in [
            ("v_max", robot.limits.v_max, r::SPEED),
            ("omega_max", robot.limits.omega_max, r::YAW_RATE),
            (
                "wheel_speed_max",
                robot.limits.wheel_speed_max,
                r::WHEEL_SPEED,
            ),
        ] {
            if !range.contains(v) {
                return Err(bad(format!(
                    "drive limit {what} = {v} is outside {}",
                    range.describe()
                )));
            }
        }
        let within = |v: &nalgebra::Vector3<f64>| {
            v.iter()
                .all(|c| c.is_finite() && c.abs() <= r::ROBOT_EXTENT)
        };
        for j in &robot.joints {
            if !within(&j.frame_in_parent.translation.vector) {
                return Err(bad(format!(
                    "joint `{}` has its origin at {:?} m, beyond {} m of its parent",
                    j.name,
                    j.frame_in_parent.translation.vector.as_slice(),
                    r::ROBOT_EXTENT
                )));
            }
        }
        for b in &robot.bodies {
            if !within(&b.pose_in_root.translation.vector) || !within(&b.com) {
                return Err(bad(format!(
                    "link `{}` lies at {:?} m (centre of mass {:?}), beyond {} m of the root",
                    b.name,
                    b.pose_in_root.translation.vector.as_slice(),
                    b.com.as_slice(),
                    r::ROBOT_EXTENT
                )));
            }
            let heavy = !(b.mass.is_finite() && b.mass <= r::MAX_LINK_MASS);
            let wild_inertia = b
                .inertia
                .iter()
                .any(|v| !(v.is_finite() && v.abs() <= r::MAX_LINK_INERTIA));
            if heavy || wild_inertia {
                return Err(bad(format!(
                    "link `{}` has mass {} kg or an inertia entry beyond {} kg·m² (at most {} kg)",
                    b.name,
                    b.mass,
                    r::MAX_LINK_INERTIA,
                    r::MAX_LINK_MASS
                )));
            }
            for c in &b.colliders {
                check_robot_collider(c, &bad)?;
            }
        }
        Ok(())
    }

    /// The obstacle of `environment.map` (named `map`), when the world has one (an SDF file's
    /// obstacles are in `file.obstacles` by now, see `load_environment`).
    fn environment_map(
        &self,
        file: &WorldFile,
        base: &Path,
    ) -> Result<Option<Obstacle>, WorldError> {
        let Some(env) = &file.environment else {
            return Ok(None);
        };
        let Some(map) = &env.map else {
            if env.unknown.is_some() {
                return Err(self.err(
                    "environment.unknown",
                    "applies to a map: set environment.map too",
                ));
            }
            return Ok(None);
        };
        let spec = ObstacleSpec {
            name: "map".into(),
            position: [0.0; 3],
            rpy: [0.0; 3],
            shape: ShapeSpec::OccupancyMap {
                file: map.clone(),
                unknown: env.unknown.unwrap_or_default(),
            },
            motion: None,
            tracker: None,
        };
        Obstacle::from_spec(&spec, Some(base))
            .map(Some)
            .map_err(|e| self.err("environment.map", e.to_string()))
    }

    /// The start and the goal centre in free cells of the map: a point inside a blocked region
    /// would get a barrier that does not say so (the outline pieces' distance is unsigned), so
    /// it is an error naming the map and the cell.
    fn check_clear_of_map(&self, file: &WorldFile, map: &Obstacle) -> Result<(), WorldError> {
        let Some(field) = map.map_field() else {
            return Ok(());
        };
        let map_file = match &map.spec.shape {
            ShapeSpec::OccupancyMap { file, .. } => file.display().to_string(),
            _ => "the map".into(),
        };
        let start = match (&file.robot, &file.linear) {
            (Some(r), _) => Some(("robot.start", [r.start.x, r.start.y])),
            (None, Some(l)) => Some(("linear.x0", [l.x0[0], l.x0[1]])),
            (None, None) => None,
        };
        let goal = Some(("goal.center", file.goal.center));
        for (key, p) in start.into_iter().chain(goal) {
            if let Some((i, j)) = field.blocked_cell_at(p) {
                let what = if key == "goal.center" {
                    "goal"
                } else {
                    "start"
                };
                return Err(self.err(
                    key,
                    format!(
                        "({:.3}, {:.3}) lies in blocked cell ({i}, {j}) (column, row from the \
                         bottom left) of the map {map_file} ({} m cells): the {what} must be in \
                         a free cell",
                        p[0],
                        p[1],
                        field.resolution()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The parsed file checked, section by section in the file's order, into a [`World`]: the
    /// ranges, the plant, the control rate and parameters, the goal, the safe sets, the robot
    /// (`loaded`, else loaded from `[robot] urdf`), the obstacles, unique names, the channels.
    fn validate(
        &self,
        mut file: WorldFile,
        name: String,
        loaded: Option<RobotDescription>,
    ) -> Result<World, WorldError> {
        self.positive("duration", file.duration)?;
        self.check_ranges(&file)?;
        let base = self.path.parent().unwrap_or_else(|| Path::new("."));
        let plant_dt = self.check_plant(&file)?;
        let ticks = self.check_control(&file, plant_dt)?;
        self.finite("goal.center", &file.goal.center)?;
        self.positive("goal.radius", file.goal.radius)?;
        let robot = match (&file.dynamics, &file.robot) {
            (Dynamics::Rapier, Some(r)) => {
                let robot = match loaded {
                    Some(robot) => robot,
                    None => self.load_robot(base, r)?,
                };
                self.check_robot(&robot)?;
                Some(robot)
            }
            _ => None,
        };
        let environment = self.load_environment(&mut file, base, robot.as_ref())?;
        let mut names = Self::safe_set_names(&file);
        let mut obstacles = Vec::with_capacity(file.obstacles.len());
        for (i, spec) in file.obstacles.iter().enumerate() {
            let ob = Obstacle::from_spec(spec, Some(base))
                .map_err(|e| self.err(format!("obstacles[{i}]"), e.to_string()))?;
            if spec.motion.is_some() {
                let key = format!("obstacles[{i}].motion");
                crate::movers::fleet::check_motion(spec).map_err(|e| self.err(&key, e))?;
                if file.dynamics == Dynamics::Linear {
                    return Err(self.err(
                        key,
                        "obstacles move only in the rapier simulation (dynamics = \"rapier\"); \
                         the linear plant has no moving obstacles",
                    ));
                }
            }
            crate::movers::tracked::check_tracker(spec, file.control.rate_hz).map_err(
                |(key, msg)| {
                    let key = match key.as_str() {
                        "" => format!("obstacles[{i}].tracker"),
                        k => format!("obstacles[{i}].tracker.{k}"),
                    };
                    self.err(key, format!("obstacle `{}`: {msg}", spec.name))
                },
            )?;
            names.push((spec.name.as_str(), format!("obstacles[{i}]")));
            obstacles.push(ob);
        }
        if let Some(ob) = self.environment_map(&file, base)? {
            self.check_clear_of_map(&file, &ob)?;
            names.push(("map", "environment.map".into()));
            obstacles.push(ob);
        }
        self.check_unique_names(&names)?;
        let patterns = self.check_channels(&file)?;
        if file.control.controller == ControllerKindSpec::FtCbfClf && patterns.is_empty() {
            return Err(self.err(
                "fault_patterns",
                "control.controller = \"ft-cbf-clf\" needs at least one [[fault_patterns]] entry (the sets of \
                 channels that may fail together); use controller = \"baseline\" for a world without them",
            ));
        }
        Ok(World {
            name,
            path: self.path.to_path_buf(),
            robot,
            obstacles,
            patterns,
            ticks_per_control: ticks as u32,
            file,
            environment,
        })
    }

    /// `[environment]`: the SDF file's obstacles appended to the file's own (the robot's
    /// height decides what it can touch), and the report of what was kept and dropped.
    fn load_environment(
        &self,
        file: &mut WorldFile,
        base: &Path,
        robot: Option<&RobotDescription>,
    ) -> Result<Option<crate::environment::EnvironmentReport>, WorldError> {
        let Some(env) = file.environment.as_mut() else {
            return Ok(None);
        };
        // Taken out once loaded (the map, if any, stays): a world edited through
        // `World::with_file` keeps these obstacles and does not load the file twice.
        let Some(sdf) = env.sdf.take() else {
            if !env.model_paths.is_empty() {
                return Err(self.err(
                    "environment.model_paths",
                    "applies to an SDF file: set environment.sdf too",
                ));
            }
            return Ok(None);
        };
        let model_paths = std::mem::take(&mut env.model_paths);
        let opts = sdf::SdfOptions {
            model_paths: model_paths.iter().map(|p| base.join(p)).collect(),
            robot_height: robot.map(|r| r.height),
            no_environment_variables: false,
        };
        let loaded = sdf::load(&base.join(sdf), &opts)
            .map_err(|e| self.err("environment.sdf", e.to_string()))?;
        let total = file.obstacles.len() + loaded.obstacles.len();
        if total > ranges::MAX_OBSTACLES {
            return Err(self.err(
                "environment.sdf",
                format!(
                    "{} obstacles kept from the file and {} of the world's own: at most {} are \
                     supported",
                    loaded.obstacles.len(),
                    file.obstacles.len(),
                    ranges::MAX_OBSTACLES
                ),
            ));
        }
        for (i, o) in loaded.obstacles.iter().enumerate() {
            self.check_obstacle_ranges(
                &format!("environment.sdf: obstacle {i} (`{}`)", o.name),
                o,
            )?;
        }
        file.obstacles.extend(loaded.obstacles);
        Ok(Some(loaded.report))
    }

    /// The plant: the rapier robot's `[robot]` and `[physics]`, or the linear plant's
    /// `[linear]`, and not the other's table. Returns the plant step \[s\].
    fn check_plant(&self, file: &WorldFile) -> Result<f64, WorldError> {
        match file.dynamics {
            Dynamics::Rapier => {
                if file.robot.is_none() {
                    return Err(self.err(
                        "robot",
                        "dynamics = \"rapier\" (the default) needs a [robot] table with `urdf`",
                    ));
                }
                if file.linear.is_some() {
                    return Err(self.err(
                        "linear",
                        "a [linear] table only applies to dynamics = \"linear\"",
                    ));
                }
                self.positive("physics.dt", file.physics.dt)?;
                if file.physics.dt > 0.02 {
                    return Err(self.err(
                        "physics.dt",
                        format!(
                            "{} s is too coarse for contact physics; expected ≤ 0.02 s (e.g. 0.004)",
                            file.physics.dt
                        ),
                    ));
                }
                self.non_negative("physics.friction", file.physics.friction)?;
                if let Some(l) = file.robot.as_ref().and_then(|r| r.limits) {
                    self.positive("robot.limits.v_max", l.v_max)?;
                    self.positive("robot.limits.omega_max", l.omega_max)?;
                    self.positive("robot.limits.wheel_speed_max", l.wheel_speed_max)?;
                }
                let st = file.robot.as_ref().map(|r| r.start).unwrap_or_default();
                self.finite("robot.start", &[st.x, st.y, st.theta])?;
                Ok(file.physics.dt)
            }
            Dynamics::Linear => {
                let lin = file.linear.as_ref().ok_or_else(|| {
                    self.err(
                        "linear",
                        "dynamics = \"linear\" needs a [linear] table with `x0`",
                    )
                })?;
                if file.robot.is_some() {
                    return Err(self.err(
                        "robot",
                        "dynamics = \"linear\" simulates eq. 6.2 directly; remove [robot] or use dynamics = \"rapier\"",
                    ));
                }
                self.positive("linear.dt", lin.dt)?;
                self.non_negative("linear.process_noise", lin.process_noise)?;
                self.finite("linear.x0", &lin.x0)?;
                if let Some(v) = lin.v_max {
                    self.positive("linear.v_max", v)?;
                }
                Ok(lin.dt)
            }
        }
    }

    /// `[control]`: a rate that is a whole number of plant steps of `plant_dt`, and the signs
    /// of its parameters. Returns the plant steps per control step.
    fn check_control(&self, file: &WorldFile, plant_dt: f64) -> Result<f64, WorldError> {
        let c = &file.control;
        self.positive("control.rate_hz", c.rate_hz)?;
        let ratio = 1.0 / (c.rate_hz * plant_dt);
        let ticks = ratio.round();
        if ticks < 1.0 || (ratio - ticks).abs() > 1e-6 * ratio {
            let plant_key = match file.dynamics {
                Dynamics::Rapier => "physics.dt",
                Dynamics::Linear => "linear.dt",
            };
            return Err(self.err(
                "control.rate_hz",
                format!(
                    "the control period 1/{} s must be a whole number of plant steps ({plant_key} = {plant_dt} s); \
                     found {ratio:.4} steps — choose a rate that divides {:.6} Hz",
                    c.rate_hz,
                    1.0 / plant_dt
                ),
            ));
        }
        if let Some(l) = c.input_limit {
            self.positive("control.input_limit", l)?;
        }
        if let Param::Value(g) = c.gamma {
            self.non_negative("control.gamma", g)?;
        }
        if let Param::Value(t) = c.theta {
            self.positive("control.theta", t)?;
        }
        self.positive("control.cbf_gain", c.cbf_gain)?;
        if let Some(d) = c.delta {
            self.positive("control.delta", d)?;
        }
        if !(c.epsilon > 0.0 && c.epsilon < 1.0) {
            return Err(self.err(
                "control.epsilon",
                format!("expected a probability in (0, 1), found {}", c.epsilon),
            ));
        }
        if let Some(q) = c.process_noise {
            self.positive("control.process_noise", q)?;
        }
        self.finite("control.initial_std", &c.initial_std)?;
        for v in c.initial_std {
            self.non_negative("control.initial_std", v)?;
        }
        if let Some(v) = c.clf.v_bar {
            self.non_negative("control.clf.v_bar", v)?;
        }
        if let Some(r) = c.clf.rho {
            self.positive("control.clf.rho", r)?;
        }
        self.non_negative("control.obstacle_margin", c.obstacle_margin)?;
        self.non_negative("control.obstacle_lift", c.obstacle_lift)?;
        Ok(ticks)
    }

    /// Each safe set's name with its key, for the uniqueness check (their numbers were checked
    /// with the ranges: [`Validator::check_safe_set_ranges`]).
    fn safe_set_names(file: &WorldFile) -> Vec<(&str, String)> {
        (file.safe_sets.iter().enumerate())
            .map(|(i, s)| (s.name(), format!("safe_sets[{i}]")))
            .collect()
    }

    /// No two safe sets or obstacles share a name (`names`: name and key, in file order).
    fn check_unique_names(&self, names: &[(&str, String)]) -> Result<(), WorldError> {
        for (i, (n, key)) in names.iter().enumerate() {
            if let Some((_, first)) = names[..i].iter().find(|(m, _)| m == n) {
                return Err(self.err(
                    format!("{key}.name"),
                    format!("the name \"{n}\" is already used by {first}; names must be unique"),
                ));
            }
        }
        Ok(())
    }

    /// Sensors, fault patterns and attacks (their own modules validate and name the entry),
    /// then what the plant needs of the channels: no wheel channels on the linear plant, a
    /// heading on the rapier one, x and y on both. Returns the resolved fault patterns.
    fn check_channels(&self, file: &WorldFile) -> Result<Vec<Vec<usize>>, WorldError> {
        if file.sensors.is_empty() {
            return Err(self.err("sensors", "expected at least one [[sensors]] channel"));
        }
        validate_channels(&file.sensors).map_err(|e| self.err("sensors", e.to_string()))?;
        let patterns = resolve_patterns(&file.sensors, &file.fault_patterns)
            .map_err(|e| self.err("fault_patterns", e.to_string()))?;
        validate_attacks(&file.attacks, &file.sensors)
            .map_err(|e| self.err("attacks", e.to_string()))?;
        let measures = |q: Quantity| file.sensors.iter().any(|s| s.measures == q);
        if file.dynamics == Dynamics::Linear {
            if let Some((i, s)) = file
                .sensors
                .iter()
                .enumerate()
                .find(|(_, s)| s.measures.is_wheel() || s.from_wheels.is_some())
            {
                return Err(self.err(
                    format!("sensors[{i}]"),
                    format!(
                        "channel \"{}\" reads the wheels, but dynamics = \"linear\" simulates eq. 6.2, which has none; use a [robot] (dynamics = \"rapier\") or another quantity",
                        s.name
                    ),
                ));
            }
        }
        if file.dynamics == Dynamics::Rapier && !measures(Quantity::Heading) {
            return Err(self.err(
                "sensors",
                "the rapier robot needs a heading channel, and none of the [[sensors]] has one: \
                 add a channel with measures = \"heading\" (the only key that provides one; a \
                 yaw_rate channel, wheel encoders or from_wheels odometry do not, though the \
                 heading channel may fuse a yaw_rate gyro with `gyro = \"NAME\"`): the \
                 compensator (6.3)-(6.4) linearises about the measured heading",
            ));
        }
        for (q, label) in [(Quantity::X, "x"), (Quantity::Y, "y")] {
            if !measures(q) {
                return Err(self.err(
                    "sensors",
                    format!("no channel measures \"{label}\": the position is unobservable"),
                ));
            }
        }
        Ok(patterns)
    }

    fn load_robot(&self, base: &Path, r: &RobotSection) -> Result<RobotDescription, WorldError> {
        let urdf = base.join(&r.urdf);
        let opts = LoadOptions {
            package_paths: r.package_paths.iter().map(|p| base.join(p)).collect(),
            packages: r
                .packages
                .iter()
                .map(|(name, dir)| (name.clone(), base.join(dir)))
                .collect(),
            wheel_joints: r.wheels.clone().map(|[l, rr]| (l, rr)),
            limits: r.limits.map(|l| DriveLimits {
                v_max: l.v_max,
                omega_max: l.omega_max,
                wheel_speed_max: l.wheel_speed_max,
            }),
            xacro: crate::robot::XacroOptions {
                args: r.xacro_args.clone().unwrap_or_default(),
                command: crate::robot::XacroCommand::Auto,
            },
        };
        RobotDescription::from_file(&urdf, &opts).map_err(|e| self.err("robot.urdf", e.to_string()))
    }
}

/// A robot collider within the ranges of a ground robot: its size within
/// [`ranges::ROBOT_SHAPE`] (a mesh's vertices within [`ranges::ROBOT_EXTENT`] instead), its
/// place within [`ranges::ROBOT_EXTENT`] of its body; `bad` makes the error.
fn check_robot_collider(
    c: &crate::robot::RobotCollider,
    bad: &dyn Fn(String) -> WorldError,
) -> Result<(), WorldError> {
    use crate::robot::CollisionShape;
    use ranges as r;
    let within = |v: &nalgebra::Vector3<f64>| {
        v.iter()
            .all(|c| c.is_finite() && c.abs() <= r::ROBOT_EXTENT)
    };
    let extent = match &c.shape {
        CollisionShape::Box { half_extents } => {
            let min = half_extents.iter().copied().fold(f64::INFINITY, f64::min);
            let max = half_extents.iter().copied().fold(0.0, f64::max);
            Some((min, max))
        }
        CollisionShape::Cylinder {
            radius,
            half_length,
        }
        | CollisionShape::Capsule {
            radius,
            half_length,
        } => Some((radius.min(*half_length), radius.max(*half_length))),
        CollisionShape::Sphere { radius } => Some((*radius, *radius)),
        CollisionShape::Mesh { vertices, .. } => {
            if vertices.iter().any(|v| {
                !v.iter()
                    .all(|c| c.is_finite() && c.abs() <= r::ROBOT_EXTENT)
            }) {
                return Err(bad(format!(
                    "a collision mesh of link `{}` has a vertex beyond {} m",
                    c.link,
                    r::ROBOT_EXTENT
                )));
            }
            None
        }
    };
    if let Some((min, max)) = extent {
        if !(min.is_finite() && max.is_finite())
            || min < r::ROBOT_SHAPE.min
            || max > r::ROBOT_SHAPE.max
        {
            return Err(bad(format!(
                "a collision shape of link `{}` has a size outside {} (smallest {min} m, largest {max} m)",
                c.link,
                r::ROBOT_SHAPE.describe()
            )));
        }
    }
    if !within(&c.pose_in_body.translation.vector) {
        return Err(bad(format!(
            "a collision shape of link `{}` lies at {:?} m, beyond {} m of its body",
            c.link,
            c.pose_in_body.translation.vector.as_slice(),
            r::ROBOT_EXTENT
        )));
    }
    Ok(())
}

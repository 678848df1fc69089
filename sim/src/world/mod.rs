//! World files: what a run is. A [`World`] is the validated, immutable description (parsed and
//! checked once, like MuJoCo's `mjModel`); the runner keeps the mutable state.

pub mod expect;
mod overrides;
pub mod schema;

use std::path::{Path, PathBuf};

use serde::Deserialize;

pub use expect::{Count, Expect, ExpectOutcome, Margin};
pub use overrides::Override;
pub use schema::*;

use crate::attacks::validate_attacks;
use crate::obstacles::Obstacle;
use crate::robot::{DriveLimits, LoadOptions, RobotDescription};
use crate::sensors::{resolve_patterns, validate_channels, Quantity};

/// Why a world file cannot be used. Every variant names the file; validation errors also name the
/// key path and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The file cannot be read.
    #[error("{path}: cannot read the world file: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Not valid TOML, or not the world schema (unknown key, wrong type, missing key).
    #[error("{path}: {message}")]
    Parse {
        /// File.
        path: PathBuf,
        /// The parser's message, with line and column.
        message: String,
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
    #[error("{path}: override {message}")]
    Override {
        /// File.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// A validated world: the file plus everything derived from it once (robot, obstacles, channel
/// indices). Cheap to share between parallel trials (`&World` is `Sync`).
#[derive(Debug)]
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
}

impl World {
    /// Reads, parses, overrides and validates a world file.
    pub fn load(path: &Path, overrides: &[Override]) -> Result<World, WorldError> {
        let text = std::fs::read_to_string(path).map_err(|source| WorldError::Io {
            path: path.to_path_buf(),
            source,
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
        let mut file: WorldFile = toml::from_str(text).map_err(|e| parse_err(e.to_string()))?;
        if !overrides.is_empty() {
            let mut doc: toml::Value =
                toml::from_str(text).map_err(|e| parse_err(e.to_string()))?;
            for ov in overrides {
                overrides::apply(&mut doc, ov).map_err(|message| WorldError::Override {
                    path: path.to_path_buf(),
                    message,
                })?;
            }
            file = WorldFile::deserialize(doc).map_err(|e| WorldError::Override {
                path: path.to_path_buf(),
                message: format!(
                    "{}: the overridden file no longer fits the schema: {e}",
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
        Validator { path }.validate(file, name)
    }

    /// Directory that relative paths in the file are resolved against.
    pub fn base_dir(&self) -> &Path {
        self.path.parent().unwrap_or_else(|| Path::new("."))
    }

    /// Control period [s].
    pub fn control_dt(&self) -> f64 {
        1.0 / self.file.control.rate_hz
    }

    /// Plant step [s] (physics or linear integration).
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

    fn finite(&self, key: &str, values: &[f64]) -> Result<(), WorldError> {
        match values.iter().find(|v| !v.is_finite()) {
            Some(v) => Err(self.err(key, format!("expected finite numbers, found {v}"))),
            None => Ok(()),
        }
    }

    fn validate(&self, file: WorldFile, name: String) -> Result<World, WorldError> {
        self.positive("duration", file.duration)?;
        let base = self.path.parent().unwrap_or_else(|| Path::new("."));

        // Plant.
        let plant_dt = match file.dynamics {
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
                file.physics.dt
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
                lin.dt
            }
        };

        // Control.
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

        // Goal.
        self.finite("goal.center", &file.goal.center)?;
        self.positive("goal.radius", file.goal.radius)?;

        // Safe sets.
        let mut names: Vec<(&str, String)> = Vec::new();
        for (i, s) in file.safe_sets.iter().enumerate() {
            let key = format!("safe_sets[{i}]");
            match s {
                SafeSetSpec::HalfPlane { a, b, .. } => {
                    self.finite(&format!("{key}.a"), a)?;
                    self.finite(&format!("{key}.b"), &[*b])?;
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
                    self.finite(&format!("{key}.center"), center)?;
                    self.finite(&format!("{key}.angle"), &[*angle])?;
                    self.positive(&format!("{key}.semi_axes[0]"), semi_axes[0])?;
                    self.positive(&format!("{key}.semi_axes[1]"), semi_axes[1])?;
                    self.non_negative(&format!("{key}.lift"), *lift)?;
                }
            }
            names.push((s.name(), key));
        }

        // Robot and obstacles.
        let robot = match (&file.dynamics, &file.robot) {
            (Dynamics::Rapier, Some(r)) => Some(self.load_robot(base, r)?),
            _ => None,
        };
        let mut obstacles = Vec::with_capacity(file.obstacles.len());
        for (i, spec) in file.obstacles.iter().enumerate() {
            let ob = Obstacle::from_spec(spec, Some(base))
                .map_err(|e| self.err(format!("obstacles[{i}]"), e.to_string()))?;
            names.push((spec.name.as_str(), format!("obstacles[{i}]")));
            obstacles.push(ob);
        }
        for (i, (n, key)) in names.iter().enumerate() {
            if let Some((_, first)) = names[..i].iter().find(|(m, _)| m == n) {
                return Err(self.err(
                    format!("{key}.name"),
                    format!("the name \"{n}\" is already used by {first}; names must be unique"),
                ));
            }
        }

        // Sensors, fault patterns, attacks: their own modules validate and name the entry.
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
                "the rapier robot needs a channel with measures = \"heading\": the compensator (6.3)-(6.4) \
                 linearises about the measured heading",
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
        })
    }

    fn load_robot(&self, base: &Path, r: &RobotSection) -> Result<RobotDescription, WorldError> {
        let urdf = base.join(&r.urdf);
        let opts = LoadOptions {
            package_paths: r.package_paths.iter().map(|p| base.join(p)).collect(),
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

//! The serde schema of a world file (TOML). Every table denies unknown keys, so a typo is an
//! error, not a silently ignored setting. See the book's world-file reference (book/src/reference/world-file.md).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::expect::Expect;
use crate::attacks::AttackSpec;
use crate::obstacles::ObstacleSpec;
use crate::sensors::{ChannelSpec, FaultPatternSpec};

/// The whole file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldFile {
    /// Name used in summaries and as the default recording name (default: the file stem).
    pub name: Option<String>,
    /// Free text shown by `ftcbf check`.
    pub description: Option<String>,
    /// Simulated duration \[s\].
    pub duration: f64,
    /// Seed of every random source of the run (sensor noise, process noise, random attacks).
    #[serde(default)]
    pub seed: u64,
    /// `rapier` (the robot from URDF in physics, default) or `linear` (eq. 6.2 integrated directly).
    #[serde(default)]
    pub dynamics: Dynamics,
    /// The robot (required for `rapier`).
    pub robot: Option<RobotSection>,
    /// Physics settings (`rapier`).
    #[serde(default)]
    pub physics: PhysicsSection,
    /// Linear-model settings (`linear`).
    pub linear: Option<LinearSection>,
    /// The controller (every key has a default: the table may be left out).
    #[serde(default)]
    pub control: ControlSection,
    /// The goal set.
    pub goal: GoalSection,
    /// Safe sets given in closed form over the planar state.
    #[serde(default)]
    pub safe_sets: Vec<SafeSetSpec>,
    /// Obstacles (parry shapes): colliders in physics and barriers for the controller.
    #[serde(default)]
    pub obstacles: Vec<ObstacleSpec>,
    /// Obstacles loaded from files robots already live in (a Gazebo SDF world, an occupancy
    /// map); they add to `obstacles`.
    pub environment: Option<EnvironmentSpec>,
    /// Sensor channels, in the order of the measurement vector y.
    pub sensors: Vec<ChannelSpec>,
    /// Fault patterns F(r_1..r_m): disjoint sets of channels that may fail together.
    #[serde(default)]
    pub fault_patterns: Vec<FaultPatternSpec>,
    /// Attack / fault injectors, applied in this order.
    #[serde(default)]
    pub attacks: Vec<AttackSpec>,
    /// Expectations that make the world a regression case.
    pub expect: Option<Expect>,
    /// The ranges `ftcbf falsify --scenario` varies the world in (no other command reads it).
    pub falsify: Option<FalsifySection>,
}

/// `[environment]`: obstacles loaded from files robots already live in (issue #47).
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentSpec {
    /// A Gazebo SDF world or model file, relative to the world file.
    pub sdf: Option<PathBuf>,
    /// Directories searched for `model://` URIs, relative to the world file.
    #[serde(default)]
    pub model_paths: Vec<PathBuf>,
    /// A ROS map_server map (`map.yaml` naming a PGM or PNG image), relative to the world file.
    pub map: Option<PathBuf>,
    /// What the map's unknown cells are: `"obstacle"` (default) or `"free"`.
    pub unknown: Option<UnknownCells>,
}

pub use crate::environment::UnknownCells;

/// `[falsify]`: how far `ftcbf falsify --scenario` may move the world. Every key is optional
/// (the defaults suit a ground robot) and ≥ 0; relative ranges are below 1.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct FalsifySection {
    /// Largest shift of each obstacle's position along x and y \[m\].
    pub obstacle_shift: Option<f64>,
    /// Largest relative change of each obstacle's size (every dimension by one factor in
    /// [1 − s, 1 + s]).
    pub obstacle_scale: Option<f64>,
    /// Largest shift of the start position along x and y \[m\].
    pub start_shift: Option<f64>,
    /// Largest change of the start heading \[rad\].
    pub start_heading: Option<f64>,
    /// Largest shift of the goal centre (and its waypoints) along x and y \[m\].
    pub goal_shift: Option<f64>,
    /// Largest relative change of every sensor channel's noise standard deviation (±x).
    pub noise: Option<f64>,
    /// Largest shift of the world's own attacks' onset (and end) \[s\].
    pub onset_shift: Option<f64>,
}

/// Which plant the run simulates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dynamics {
    /// The robot from URDF in rapier3d, driven through the compensator (6.3)-(6.4) and wheel motors.
    #[default]
    Rapier,
    /// The paper's linearised model (6.2) integrated with Euler–Maruyama.
    Linear,
}

/// `[robot]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSection {
    /// URDF path, relative to the world file.
    pub urdf: PathBuf,
    /// Directories searched for `package://NAME/...`: `DIR/NAME/...`. Relative to the world file.
    #[serde(default)]
    pub package_paths: Vec<PathBuf>,
    /// Folders of named packages whose folder has another name, e.g. `{ qbot2e =
    /// "quanser_description" }`: `package://NAME/rest` is `FOLDER/rest`. Relative to the world file.
    #[serde(default)]
    pub packages: std::collections::BTreeMap<String, PathBuf>,
    /// Start pose in the world frame.
    #[serde(default)]
    pub start: StartPose,
    /// Names of the left and right drive-wheel joints (default: found from the continuous joints);
    /// a named `fixed` joint is driven as a continuous one.
    pub wheels: Option<[String; 2]>,
    /// Drive limits, for URDFs whose wheel joints carry no `<limit velocity>` (the ROS
    /// TurtleBot3 files do not). Default: derived from the wheel joints' limits.
    pub limits: Option<LimitsSpec>,
    /// `$(arg NAME)` values for a xacro source, e.g. `{ namespace = "" }` (the file's
    /// `<xacro:arg default>` applies to the others).
    pub xacro_args: Option<std::collections::BTreeMap<String, String>>,
}

/// `[robot] limits = { v_max, omega_max, wheel_speed_max }`
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitsSpec {
    /// Maximum forward speed |v| [m/s].
    pub v_max: f64,
    /// Maximum yaw rate |ω| [rad/s].
    pub omega_max: f64,
    /// Maximum wheel angular speed [rad/s].
    pub wheel_speed_max: f64,
}

/// A planar pose.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartPose {
    /// \[m\]
    #[serde(default)]
    pub x: f64,
    /// \[m\]
    #[serde(default)]
    pub y: f64,
    /// Heading \[rad\].
    #[serde(default)]
    pub theta: f64,
}

/// `[physics]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicsSection {
    /// Physics step \[s\] (default 0.005: 200 Hz, 4 plant steps per 50 Hz control step, so the default rates fit together).
    #[serde(default = "default_physics_dt")]
    pub dt: f64,
    /// Coulomb friction coefficient of wheels, ground and obstacles (default 1.0).
    #[serde(default = "default_friction")]
    pub friction: f64,
}

impl Default for PhysicsSection {
    fn default() -> Self {
        Self {
            dt: default_physics_dt(),
            friction: default_friction(),
        }
    }
}

fn default_physics_dt() -> f64 {
    0.005
}
fn default_friction() -> f64 {
    1.0
}

/// `[linear]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinearSection {
    /// Integration step \[s\] (default 0.001).
    #[serde(default = "default_linear_dt")]
    pub dt: f64,
    /// Initial state (p_x, p_y, v_x, v_y).
    pub x0: [f64; 4],
    /// Process-noise intensity: Q = process_noise · I₄ [(unit)²/s] (default 1e-3, the paper's).
    #[serde(default = "default_noise")]
    pub process_noise: f64,
    /// Speed bound [m/s] assumed by the h̄_γ bounds of lifted barriers (ellipse safe sets with
    /// `lift` > 0, obstacles other than half-spaces). The linear plant has no speed limit of
    /// its own, so a world with such barriers must give it; none is invented.
    #[serde(default)]
    pub v_max: Option<f64>,
}

fn default_linear_dt() -> f64 {
    1.0e-3
}
fn default_noise() -> f64 {
    1.0e-3
}

/// The controller to run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
pub enum ControllerKindSpec {
    /// Fault-tolerant CBF-CLF (the paper's).
    #[default]
    #[serde(rename = "ft-cbf-clf")]
    FtCbfClf,
    /// CBF-CLF over one filter using all sensors (the paper's comparison).
    #[serde(rename = "baseline")]
    Baseline,
    /// CLF only, no barriers.
    #[serde(rename = "nominal")]
    Nominal,
}

impl ControllerKindSpec {
    /// Every built-in controller, in the order the CLI lists them.
    pub const ALL: [Self; 3] = [Self::FtCbfClf, Self::Baseline, Self::Nominal];
    /// Their names, as world files, the CLI, summaries and batch files write them (in the
    /// order of [`ControllerKindSpec::ALL`]).
    pub const NAMES: [&'static str; 3] = ["ft-cbf-clf", "baseline", "nominal"];

    /// The name (`ft-cbf-clf`, `baseline`, `nominal`).
    pub fn name(self) -> &'static str {
        match self {
            Self::FtCbfClf => Self::NAMES[0],
            Self::Baseline => Self::NAMES[1],
            Self::Nominal => Self::NAMES[2],
        }
    }
}

impl std::fmt::Display for ControllerKindSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A controller name that is none of [`ControllerKindSpec::NAMES`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown controller `{0}` (expected ft-cbf-clf, baseline or nominal)")]
pub struct UnknownController(pub String);

impl std::str::FromStr for ControllerKindSpec {
    type Err = UnknownController;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| UnknownController(s.to_string()))
    }
}

impl From<ControllerKindSpec> for ftcbf_controller::controller::ControllerKind {
    fn from(k: ControllerKindSpec) -> Self {
        match k {
            ControllerKindSpec::FtCbfClf => Self::FtCbfClf,
            ControllerKindSpec::Baseline => Self::Baseline,
            ControllerKindSpec::Nominal => Self::Nominal,
        }
    }
}

/// A parameter given as a number or computed (`"auto"`, from ε and the noise model, §4.3).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Param {
    /// Computed by the controller crate.
    #[default]
    Auto,
    /// Given.
    Value(f64),
}

impl<'de> Deserialize<'de> for Param {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Num(f64),
            Text(String),
        }
        match Raw::deserialize(d)
            .map_err(|_| serde::de::Error::custom("expected a number or \"auto\""))?
        {
            Raw::Num(v) => Ok(Param::Value(v)),
            Raw::Text(s) if s == "auto" => Ok(Param::Auto),
            Raw::Text(s) => Err(serde::de::Error::custom(format!(
                "expected a number or \"auto\", found \"{s}\""
            ))),
        }
    }
}

/// `[control]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlSection {
    /// Control rate \[Hz\] (default 50).
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// `ft-cbf-clf` (default), `baseline` or `nominal`.
    #[serde(default)]
    pub controller: ControllerKindSpec,
    /// Bound on each component of u [m/s²] (none by default).
    pub input_limit: Option<f64>,
    /// γ_i (§4.3): a number for all fault patterns, or `"auto"` (default).
    #[serde(default)]
    pub gamma: Param,
    /// θ_ij (§4.3): a number for all pairs, or `"auto"` (default).
    #[serde(default)]
    pub theta: Param,
    /// δ of Step 1: constraints are active when ĥ(x̂) < δ (default: always active).
    pub delta: Option<f64>,
    /// Gain κ of the CBF condition `… ≥ −κ·ĥ(x̂)` as the file declares it: a number, or
    /// `"auto"`. Absent: see [`ControlSection::cbf_gain`].
    #[serde(default, rename = "cbf_gain")]
    pub cbf_gain_declared: Option<Param>,
    /// κ as declared, else the form's base value: 10 in the safety-filter form (the floor of
    /// `"auto"`) and 1 (eq. 4.3) in the paper form. A larger κ lets the estimate settle closer to
    /// the boundary: at rest the robust term holds ĥ ≥ γ‖∂h/∂x K c̄‖/κ; with κ = 1 a room's rows
    /// need more than the box within ~1 m of every obstacle and the robot stalls (issue #36).
    /// Set by [`WorldFile::resolve_defaults`]; with [`ControlSection::cbf_gain_auto`] the
    /// controller's κ is chosen from the world at setup (`model::setup::choose_gain`).
    #[serde(skip)]
    pub cbf_gain: f64,
    /// κ is chosen from the world (`cbf_gain = "auto"`, the default of the safety-filter form).
    #[serde(skip)]
    pub cbf_gain_auto: bool,
    /// ε for `"auto"` parameters: the run should be safe with probability ≥ 1 − ε (default 0.05).
    #[serde(default = "default_epsilon")]
    pub epsilon: f64,
    /// The filters' process-noise intensity q (default: the linear plant's, or 1e-2 for a rapier
    /// robot); where it enters is set by `process_model`.
    pub process_noise: Option<f64>,
    /// Where the filters' process noise enters: `acceleration` (Q = diag(0, 0, q, q), white
    /// acceleration, the physically right model for a driven robot) or `isotropic`
    /// (Q = q·I₄ on position and velocity, the paper's §6.2 setting). Default: `isotropic` for
    /// `dynamics = "linear"` (it is the plant's own noise), `acceleration` for a rapier robot.
    pub process_model: Option<ProcessModel>,
    /// The filters' initial uncertainty: standard deviations of the start position \[m\] and the
    /// start velocity [m/s] per axis, P0 = diag(σ_p², σ_p², σ_v², σ_v²) (default [0.01, 0.01]: a
    /// robot placed at a marked start, at rest). Also the start of the finite-horizon bounds
    /// of `check` for filters without a steady state.
    #[serde(default = "default_initial_std")]
    pub initial_std: [f64; 2],
    /// How `"auto"` γ and θ are bounded: `horizon` (default: from `initial_std` over the run,
    /// θ from the covariance of the solution separation x̂_i − x̂_ij) or `paper` (§4.3:
    /// steady-state γ, θ by the triangle inequality).
    #[serde(default)]
    pub bounds: BoundsSpec,
    /// The CLF (eq. 6.6).
    #[serde(default)]
    pub clf: ClfSection,
    /// Obstacle barriers: distance margin \[m\] kept beyond the robot's footprint (default 0.02).
    #[serde(default = "default_margin")]
    pub obstacle_margin: f64,
    /// Obstacle barriers: gain k of the relative-degree-2 lift H = d + k·ḋ \[s\] (default 0.5).
    #[serde(default = "default_lift")]
    pub obstacle_lift: f64,
    /// Which problem the QP solves, as the file declares it: `paper` (problem 5.3, the CLF
    /// drives) or `safety_filter` (a path tracker proposes u_nom; the QP returns the closest
    /// safe input). Absent: see [`ControlSection::form`].
    #[serde(default, rename = "form")]
    pub form_declared: Option<FormSpec>,
    /// The form in force: as declared, else `safety_filter` for a rapier robot (smooth inputs
    /// the drive can follow; the paper form's bang-bang inputs are outside the filters' drive
    /// model, see `ftcbf check`) and `paper` for `dynamics = "linear"` (the thesis' own study).
    /// Set by [`WorldFile::resolve_defaults`].
    #[serde(skip)]
    pub form: FormSpec,
    /// What the policy does where Step 3 would drop an estimator without evidence that it lies,
    /// as the file declares it: `brake` (the safe stop: brake and keep every estimator's rows,
    /// book/src/theory/safe-stop.md) or `paper` (the thesis' Step 3: drop the largest residue).
    /// Absent: see [`ControlSection::fallback`].
    #[serde(default, rename = "fallback")]
    pub fallback_declared: Option<FallbackSpec>,
    /// The fallback in force: as declared, else `paper` for the paper's worlds
    /// (`dynamics = "linear"` or `form = "paper"`, so the thesis' study is reproduced) and
    /// `brake` otherwise. Set by [`WorldFile::resolve_defaults`].
    #[serde(skip)]
    pub fallback: FallbackSpec,
    /// The nominal tracker of `form = "safety_filter"`.
    #[serde(default)]
    pub nominal: NominalSection,
    /// The compensator (6.3)–(6.4) of a rapier robot.
    #[serde(default)]
    pub drive: DriveSection,
}

impl Default for ControlSection {
    /// Every key at its documented default (a world may leave `[control]` out).
    fn default() -> Self {
        Self {
            rate_hz: default_rate(),
            controller: ControllerKindSpec::default(),
            input_limit: None,
            gamma: Param::default(),
            theta: Param::default(),
            delta: None,
            cbf_gain_declared: None,
            cbf_gain: default_cbf_gain(),
            cbf_gain_auto: false,
            epsilon: default_epsilon(),
            process_noise: None,
            process_model: None,
            initial_std: default_initial_std(),
            bounds: BoundsSpec::default(),
            clf: ClfSection::default(),
            obstacle_margin: default_margin(),
            obstacle_lift: default_lift(),
            form_declared: None,
            form: FormSpec::default(),
            fallback_declared: None,
            fallback: FallbackSpec::default(),
            nominal: NominalSection::default(),
            drive: DriveSection::default(),
        }
    }
}

impl WorldFile {
    /// Fills the defaults that depend on other keys: the problem form from the dynamics, a
    /// derived odometry channel's noise (none of its own unless declared), and whether a
    /// `speed` channel reaches the filters (yes when the world has a heading to turn it into a
    /// world-frame velocity, unless `world_velocity = false`).
    pub fn resolve_defaults(&mut self) {
        self.control.form = self.control.form_declared.unwrap_or(match self.dynamics {
            Dynamics::Rapier => FormSpec::SafetyFilter,
            Dynamics::Linear => FormSpec::Paper,
        });
        let paper_world = self.dynamics == Dynamics::Linear || self.control.form == FormSpec::Paper;
        self.control.fallback = self.control.fallback_declared.unwrap_or(if paper_world {
            FallbackSpec::Paper
        } else {
            FallbackSpec::Brake
        });
        let base = match self.control.form {
            FormSpec::SafetyFilter => SAFETY_FILTER_CBF_GAIN,
            FormSpec::Paper => default_cbf_gain(),
        };
        (self.control.cbf_gain, self.control.cbf_gain_auto) = match self.control.cbf_gain_declared {
            Some(Param::Value(k)) => (k, false),
            Some(Param::Auto) => (base, true),
            None => (base, self.control.form == FormSpec::SafetyFilter),
        };
        let has_heading = self
            .sensors
            .iter()
            .any(|s| s.measures == crate::sensors::Quantity::Heading);
        for s in &mut self.sensors {
            if s.noise_std.is_nan() && s.from_wheels.is_some() {
                s.noise_std = 0.0;
            }
            s.world_velocity = s
                .world_velocity_declared
                .unwrap_or(has_heading && s.measures == crate::sensors::Quantity::Speed);
        }
    }
}

/// `[control] form`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FormSpec {
    /// Problem (5.3).
    #[default]
    Paper,
    /// min ‖u − u_nom‖²_R over the same Ω rows.
    SafetyFilter,
}

impl FormSpec {
    /// The name used in world files.
    pub fn as_str(self) -> &'static str {
        match self {
            FormSpec::Paper => "paper",
            FormSpec::SafetyFilter => "safety_filter",
        }
    }
}

/// `[control] fallback`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FallbackSpec {
    /// The thesis' Step 3: drop the estimator with the largest residue until feasible.
    #[default]
    Paper,
    /// The safe stop: drop only on evidence, otherwise brake.
    Brake,
}

impl FallbackSpec {
    /// The name used in world files.
    pub fn as_str(self) -> &'static str {
        match self {
            FallbackSpec::Paper => "paper",
            FallbackSpec::Brake => "brake",
        }
    }
}

/// `[control.nominal]`: the path tracker of the safety-filter form (every key optional; the
/// defaults suit a TurtleBot3, see `ftcbf_controller::TrackerConfig::turtlebot`).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NominalSection {
    /// Cruise speed [m/s] (default 90 % of the robot's v_max; 0.15 for the linear plant).
    pub cruise_speed: Option<f64>,
    /// Velocity-tracking gain k_v [1/s] (default 1.5).
    pub speed_gain: Option<f64>,
    /// Approach deceleration [m/s²] (default 0.1).
    pub arrive_accel: Option<f64>,
    /// Lookahead along the path \[m\] (default 0.3).
    pub lookahead: Option<f64>,
    /// Low-pass time constant of u_nom \[s\] (default 0.2).
    pub smoothing: Option<f64>,
    /// Jerk limit [m/s³] (default 2).
    pub jerk_limit: Option<f64>,
    /// Stall: less progress than this \[m\] (default 0.05) ...
    pub stall_progress: Option<f64>,
    /// ... within this time \[s\] (default 4).
    pub stall_time: Option<f64>,
    /// Escape duration \[s\] (default 2).
    pub escape_time: Option<f64>,
    /// Escape turn of the desired direction \[rad\] (default π/3).
    pub escape_angle: Option<f64>,
    /// Keep the CLF rows Υ as constraints (default false).
    #[serde(default)]
    pub clf: bool,
}

/// `[control.drive]`: the compensator's low-speed law and rate limits.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriveSection {
    /// `floor` (ω = a⊥ / max(|v|, v_floor), the thesis' (6.4); the paper form's default) or
    /// `regularised` (ω = a⊥·v / (v² + v_soft²), continuous at rest; the safety-filter form's
    /// default).
    pub low_speed: Option<LowSpeedSpec>,
    /// v_floor or v_soft [m/s] (default 0.05).
    pub low_speed_scale: Option<f64>,
    /// Rate limit on v [m/s²] (default: none in the paper form; the input box, or 1 m/s²
    /// without one, in the safety-filter form).
    pub dv_max: Option<f64>,
    /// Rate limit on ω [rad/s²] (default: none in the paper form; the robot's ω_max per second
    /// in the safety-filter form).
    pub domega_max: Option<f64>,
    /// Resolution of a wheel's speed command [rad/s] (default none): yaw rates below half the
    /// drive's step r·Δ/L are sent as 0.
    pub wheel_speed_resolution: Option<f64>,
}

/// `[control.drive] low_speed`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LowSpeedSpec {
    /// ω = a⊥ / (s·max(|v|, v_floor)).
    #[default]
    Floor,
    /// ω = a⊥·v / (v² + v_soft²).
    Regularised,
}

/// Where the filters' process noise enters (`[control] process_model`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProcessModel {
    /// White noise on acceleration only: Q = diag(0, 0, q, q).
    Acceleration,
    /// The paper's Q = q·I₄ (noise on position and velocity).
    Isotropic,
}

impl ProcessModel {
    /// The name used in world files.
    pub fn as_str(self) -> &'static str {
        match self {
            ProcessModel::Acceleration => "acceleration",
            ProcessModel::Isotropic => "isotropic",
        }
    }
}

/// `[control] bounds`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BoundsSpec {
    /// Over the run's horizon from the declared initial uncertainty; solution separation.
    #[default]
    Horizon,
    /// The paper's §4.3.
    Paper,
}

impl BoundsSpec {
    /// The name used in world files.
    pub fn as_str(self) -> &'static str {
        match self {
            BoundsSpec::Horizon => "horizon",
            BoundsSpec::Paper => "paper",
        }
    }
}

/// Default `[control] initial_std` [m, m/s].
pub const DEFAULT_INITIAL_STD: [f64; 2] = [0.01, 0.01];

fn default_initial_std() -> [f64; 2] {
    DEFAULT_INITIAL_STD
}

fn default_rate() -> f64 {
    50.0
}
/// The floor of `cbf_gain = "auto"` (and κ of the paper form's `"auto"` base): the value every
/// catalogue robot world was measured with (13 worlds, 200-1000 trials each; book/src/results/catalogue.md).
pub const SAFETY_FILTER_CBF_GAIN: f64 = 10.0;

fn default_cbf_gain() -> f64 {
    1.0
}
fn default_epsilon() -> f64 {
    0.05
}
fn default_margin() -> f64 {
    0.02
}
fn default_lift() -> f64 {
    0.5
}

/// `[control.clf]`
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClfSection {
    /// CLF rows are active when V(x̂) > v_bar (default 0: always).
    pub v_bar: Option<f64>,
    /// Decay rate ρ (default 1/(d·λ̄(P_d)) as in §6.1).
    pub rho: Option<f64>,
}

/// `[goal]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalSection {
    /// Goal position (x, y) \[m\].
    pub center: [f64; 2],
    /// Radius d \[m\].
    pub radius: f64,
    /// `position` (default: ‖p − p_g‖ ≤ d) or `state` (the paper's ‖x − x_g‖ ≤ d over all four states).
    #[serde(default)]
    pub metric: GoalMetric,
    /// Waypoints \[m\] the safety filter's tracker passes before the goal (default none).
    #[serde(default)]
    pub waypoints: Vec<[f64; 2]>,
    /// Plan a path from the start to the goal (through the waypoints) around the declared
    /// obstacles for the safety filter's tracker (default true; ignored by `form = "paper"`).
    #[serde(default = "default_plan")]
    pub plan: bool,
}

fn default_plan() -> bool {
    true
}

/// How the goal set is measured.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GoalMetric {
    /// Position only.
    #[default]
    Position,
    /// Full planar state, velocity included (the paper's G).
    State,
}

super::tagged::kind_tagged! {
/// A closed-form safe set over the planar state: a `[[safe_sets]]` table tagged by `kind`
/// (read through `super::tagged`, so an error names the key inside the table).
#[derive(Debug, Clone, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SafeSetSpec via SafeSetByKind {
    /// h(x) = a·x − b over x = (p_x, p_y, v_x, v_y).
    HalfPlane {
        /// Name in logs.
        name: String,
        /// a.
        a: [f64; 4],
        /// b.
        b: f64,
    },
    /// The inside of an ellipse over the position, lifted to relative degree 2 (h + k·ḣ).
    EllipseInside {
        /// Name in logs.
        name: String,
        /// Centre \[m\].
        center: [f64; 2],
        /// Semi-axes along the ellipse's own x and y \[m\].
        semi_axes: [f64; 2],
        /// Rotation of the ellipse's x axis from the world x axis \[rad\].
        #[serde(default)]
        angle: f64,
        /// Lift gain k \[s\] (default 0.5).
        #[serde(default = "default_lift")]
        lift: f64,
    },
    /// The outside of an ellipse (a round keep-out zone), lifted the same way.
    EllipseOutside {
        /// Name in logs.
        name: String,
        /// Centre \[m\].
        center: [f64; 2],
        /// Semi-axes \[m\].
        semi_axes: [f64; 2],
        /// \[rad\]
        #[serde(default)]
        angle: f64,
        /// Lift gain k \[s\] (default 0.5).
        #[serde(default = "default_lift")]
        lift: f64,
    },
}
}

impl SafeSetSpec {
    /// The set's name.
    pub fn name(&self) -> &str {
        match self {
            SafeSetSpec::HalfPlane { name, .. }
            | SafeSetSpec::EllipseInside { name, .. }
            | SafeSetSpec::EllipseOutside { name, .. } => name,
        }
    }
}

#[cfg(test)]
mod controller_kind_tests {
    use super::*;

    #[test]
    fn names_parse_back_and_others_are_refused() {
        for k in ControllerKindSpec::ALL {
            assert_eq!(k.to_string().parse::<ControllerKindSpec>(), Ok(k));
        }
        let e = "pid".parse::<ControllerKindSpec>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown controller `pid` (expected ft-cbf-clf, baseline or nominal)"
        );
        // The world file's spelling is the same name.
        #[derive(Deserialize)]
        struct C {
            controller: ControllerKindSpec,
        }
        for k in ControllerKindSpec::ALL {
            let c: C = toml::from_str(&format!("controller = \"{k}\"")).expect("parses");
            assert_eq!(c.controller, k);
        }
    }
}

//! Seeded worlds written the way users write them (`ftcbf gen`, issue #36 item 6; the input of
//! #31's scenario campaigns).
//!
//! Each world is a room, a straight corridor, a doorway, a clutter field or an L turn with sizes
//! and positions from the ranges a user types (not from what the controller handles), the
//! TurtleBot3 burger or waffle, one of the README's sensor suites ([`Suite`]) with realistic
//! noise, one fault pattern per receiver (and per other redundant source), and one attack of one
//! of the world file's twelve kinds inside one fault pattern. The file holds only the keys a
//! user needs: `name`, `duration`, `seed`, `[robot]` (`urdf`, `start`), `[goal]`, obstacles,
//! sensors, fault patterns, the attack and at most `[control] input_limit`; every tuning key is
//! left at its default.
//!
//! The one thing the generator does insist on is that the world is possible: the start and the
//! whole goal disc are at least [`SPARE`] clear of every obstacle beyond the robot's footprint,
//! and the project's own planner ([`crate::planner`], the A* the safety filter's tracker uses)
//! finds a path on which the footprint keeps [`SPARE`] clear. A layout that fails is redrawn.
//! Every file is then loaded with [`World::from_str`], the loader `check` and `run` use; a file
//! the loader refuses is a generator bug and an error, never redrawn.
//!
//! World `i` of seed `S` draws from its own random stream (`sensors::stream_rng(S, "gen", i)`),
//! so it does not depend on how many worlds are generated, and the same seed, options and
//! output directory give byte-identical files.
//!
//! One file (about 740 lines of code and 310 of tests): the generator's kinds share one seeded
//! draw and one writer; each kind's geometry is a function here, and the tests at the end pin
//! every kind's determinism and reachability.

mod attack;
mod layout;
mod moving;
mod on_map;
mod suite;
mod text;

use std::fmt;
use std::path::{Component, Path, PathBuf};
use std::str::FromStr;

use rand::seq::SliceRandom;
use rand::Rng;

use crate::obstacles::{BarrierConfig, Obstacle, ObstacleSpec, ShapeSpec};
use crate::planner::{plan, PlannerConfig};
use crate::robot::{LoadOptions, RobotDescription};
use crate::sensors::stream_rng;
use crate::world::{World, WorldError};

pub use attack::ATTACK_KINDS;
use layout::{pick, KeepOut};
pub use on_map::PAIR_DISTANCE;
use text::{dec, Shape, WorldText};

/// Clearance \[m\] the robot's footprint keeps from every obstacle at the start, on the whole
/// goal disc and along the planned path in every generated world.
pub const SPARE: f64 = 0.15;

/// Layouts drawn for one world before giving up.
pub const MAX_DRAWS: usize = 500;

/// What kind of scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    /// Four walls and furniture (tables, shelves, pillars, chairs).
    Room,
    /// A straight corridor, maybe with bins or boxes against its walls.
    Corridor,
    /// A wall with a door, free-standing or between two rooms.
    Doorway,
    /// A field of boxes, bins and balls.
    Clutter,
    /// An L-shaped corridor.
    LTurn,
    /// A clutter field with a cart going up and down an aisle across the route (issue #51).
    AisleCrossing,
    /// A corridor with a person walking down it towards the robot and back.
    CorridorWalker,
    /// A room with two people walking across the route.
    RoomPeople,
    /// A room with two small cylinders on waypoint loops at 0.1 m/s (TurtleBot3 DQN stages).
    DqnLoops,
    /// A start and a goal on an occupancy map (`--map`): drawn only with a map, so not in
    /// [`Kind::ALL`].
    Map,
}

impl Kind {
    /// Every kind, in the order `--kind all` cycles through them.
    pub const ALL: [Kind; 5] = [
        Kind::Room,
        Kind::Corridor,
        Kind::Doorway,
        Kind::Clutter,
        Kind::LTurn,
    ];

    /// The kinds with moving obstacles (issue #51), in the order `--kind movers` cycles
    /// through them; not in [`Kind::ALL`], so `--kind all` draws what it always drew.
    pub const MOVERS: [Kind; 4] = [
        Kind::AisleCrossing,
        Kind::CorridorWalker,
        Kind::RoomPeople,
        Kind::DqnLoops,
    ];

    /// Every kind a name reads as.
    pub const NAMED: [Kind; 9] = [
        Kind::Room,
        Kind::Corridor,
        Kind::Doorway,
        Kind::Clutter,
        Kind::LTurn,
        Kind::AisleCrossing,
        Kind::CorridorWalker,
        Kind::RoomPeople,
        Kind::DqnLoops,
    ];

    /// The name on the command line and in file names.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Room => "room",
            Kind::Corridor => "corridor",
            Kind::Doorway => "doorway",
            Kind::Clutter => "clutter",
            Kind::LTurn => "l_turn",
            Kind::AisleCrossing => "aisle_crossing",
            Kind::CorridorWalker => "corridor_walker",
            Kind::RoomPeople => "room_people",
            Kind::DqnLoops => "dqn_loops",
            Kind::Map => "map",
        }
    }

    /// The static scene a kind's movers are placed in (itself for the static kinds).
    pub fn scene(self) -> Kind {
        match self {
            Kind::AisleCrossing => Kind::Clutter,
            Kind::CorridorWalker => Kind::Corridor,
            Kind::RoomPeople | Kind::DqnLoops => Kind::Room,
            k => k,
        }
    }
}

/// The robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RobotModel {
    /// `robots/turtlebot3_burger.urdf`.
    Burger,
    /// `robots/turtlebot3_waffle.urdf`.
    Waffle,
}

impl RobotModel {
    /// Both robots, in the order `--robot any` alternates them.
    pub const ALL: [RobotModel; 2] = [RobotModel::Burger, RobotModel::Waffle];
    /// Every robot a name reads as.
    pub const NAMED: [RobotModel; 2] = Self::ALL;

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            RobotModel::Burger => "burger",
            RobotModel::Waffle => "waffle",
        }
    }

    /// The URDF's file name in the project's `robots/`.
    pub fn urdf_file(self) -> &'static str {
        match self {
            RobotModel::Burger => "turtlebot3_burger.urdf",
            RobotModel::Waffle => "turtlebot3_waffle.urdf",
        }
    }
}

/// The sensor suites the book's "Your sensors" guide documents (book/src/guide/sensors.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Suite {
    /// Two receivers (x, y each) and an IMU heading (compass).
    TwoReceivers,
    /// Three receivers and a compass.
    ThreeReceivers,
    /// Two receivers, wheel odometry (`speed`, to the filters as world velocity) and a compass.
    Odometry,
    /// Two receivers, wheel encoders → odometry (`from_wheels`), a gyro fused with a compass.
    Encoders,
    /// Two receivers, the first also reporting velocity (vx, vy), and a compass.
    ReceiverVelocity,
}

impl Suite {
    /// Every suite, in the order `--suite any` cycles through them.
    pub const ALL: [Suite; 5] = [
        Suite::TwoReceivers,
        Suite::ThreeReceivers,
        Suite::Odometry,
        Suite::Encoders,
        Suite::ReceiverVelocity,
    ];
    /// Every suite a name reads as.
    pub const NAMED: [Suite; 5] = Self::ALL;

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Suite::TwoReceivers => "two_receivers",
            Suite::ThreeReceivers => "three_receivers",
            Suite::Odometry => "odometry",
            Suite::Encoders => "encoders",
            Suite::ReceiverVelocity => "receiver_velocity",
        }
    }
}

macro_rules! name_parsing {
    ($t:ty, $what:literal) => {
        impl fmt::Display for $t {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.name())
            }
        }

        impl FromStr for $t {
            type Err = String;

            fn from_str(s: &str) -> Result<Self, String> {
                Self::NAMED
                    .into_iter()
                    .find(|k| k.name() == s)
                    .ok_or_else(|| {
                        let names: Vec<&str> = Self::NAMED.iter().map(|k| k.name()).collect();
                        format!(
                            "unknown {} `{s}` (expected one of: {})",
                            $what,
                            names.join(", ")
                        )
                    })
            }
        }
    };
}

name_parsing!(Kind, "kind");
name_parsing!(RobotModel, "robot");
name_parsing!(Suite, "suite");

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct GenConfig {
    /// The seed of every draw.
    pub seed: u64,
    /// One kind of scene, or `None` for every kind in turn.
    pub kind: Option<Kind>,
    /// One robot, or `None` to alternate.
    pub robot: Option<RobotModel>,
    /// One sensor suite, or `None` for every suite in turn.
    pub suite: Option<Suite>,
    /// Where the robots' URDF files are read now (the project's `robots/`).
    pub robots_dir: PathBuf,
    /// Where the world files will be written: their `urdf` key is the path of the robot file
    /// relative to this directory, as a world file's relative paths are (book/src/reference/world-file.md, `[robot]
    /// urdf`).
    pub out_dir: PathBuf,
    /// An occupancy map (map_server YAML) to draw every world on instead of a drawn layout
    /// ([`Kind::Map`]; `kind` must then be `None`).
    pub map: Option<PathBuf>,
}

impl GenConfig {
    /// The command that generates these worlds, for the files' header.
    pub fn command(&self) -> String {
        let mut c = format!("ftcbf gen --seed {}", self.seed);
        if let Some(k) = self.kind {
            c += &format!(" --kind {k}");
        }
        if let Some(r) = self.robot {
            c += &format!(" --robot {r}");
        }
        if let Some(s) = self.suite {
            c += &format!(" --suite {s}");
        }
        if let Some(m) = &self.map {
            c += &format!(" --map {}", m.display());
        }
        c
    }
}

/// One generated world.
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedWorld {
    /// Its index in the seed's sequence (0-based).
    pub index: usize,
    /// The world's `name`.
    pub name: String,
    /// `NAME.toml`.
    pub file_name: String,
    /// The scene.
    pub kind: Kind,
    /// The robot.
    pub robot: RobotModel,
    /// The sensor suite.
    pub suite: Suite,
    /// The attack's kind (one of [`ATTACK_KINDS`]).
    pub attack_kind: &'static str,
    /// The attacked channels.
    pub attack_channels: Vec<String>,
    /// The fault pattern the attack lies in.
    pub attack_pattern: String,
    /// The planned path with [`SPARE`] clearance, start → goal.
    pub reach: Route,
    /// Layouts drawn until one was reachable (1 = the first).
    pub draws: usize,
    /// The file's text.
    pub text: String,
}

impl GeneratedWorld {
    /// `kind[ch1,ch2]`, as run summaries label an attack.
    pub fn attack_label(&self) -> String {
        format!("{}[{}]", self.attack_kind, self.attack_channels.join(","))
    }
}

/// Why generating failed.
#[derive(Debug, thiserror::Error)]
pub enum GenError {
    /// A robot file cannot be loaded.
    #[error("{}: cannot load the robot: {message} (pass the directory that holds turtlebot3_burger.urdf and turtlebot3_waffle.urdf)", path.display())]
    Robot {
        /// The URDF.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// No reachable layout in [`MAX_DRAWS`] draws.
    #[error("world {index} ({kind}, {robot}): no layout with its goal reachable at {SPARE} m clearance in {draws} draws")]
    NoReachableLayout {
        /// World index.
        index: usize,
        /// Its kind.
        kind: Kind,
        /// Its robot.
        robot: RobotModel,
        /// Draws made.
        draws: usize,
    },
    /// The project's loader refuses a generated file: a bug of the generator.
    #[error(
        "generated world {file} is refused by the world loader (a bug of the generator): {error}"
    )]
    Invalid {
        /// The file name.
        file: String,
        /// The loader's error (in the message, not also a `source`, so a chain says it once).
        error: Box<WorldError>,
    },
    /// A drawn obstacle is refused by the obstacle builder: a bug of the generator.
    #[error("world {index}: a drawn obstacle is refused (a bug of the generator): {message}")]
    Obstacle {
        /// World index.
        index: usize,
        /// The builder's error.
        message: String,
    },
    /// The map of `--map` cannot be used.
    #[error("{}: cannot draw worlds on this map: {message}", path.display())]
    Map {
        /// The map's YAML file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// A file or directory cannot be written.
    #[error("{}: {error}", path.display())]
    Io {
        /// Where.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
}

/// How a world's goal is reached with [`SPARE`] (or the spare asked) to spare.
#[derive(Debug, Clone, PartialEq)]
pub struct Route {
    /// The planned points after the start, the goal last \[m\].
    pub path: Vec<[f64; 2]>,
    /// Length of the path from the start \[m\].
    pub length: f64,
    /// The footprint's clearance at the start \[m\].
    pub start_clearance: f64,
    /// The footprint's clearance at the goal centre \[m\] (the goal disc keeps this less its
    /// radius).
    pub goal_clearance: f64,
    /// The smallest footprint clearance along the path, sampled every centimetre \[m\].
    pub path_clearance: f64,
}

/// Why a goal is not reachable with the spare asked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Unreachable {
    /// The start's clearance \[m\] is below the spare.
    Start(f64),
    /// The goal disc's clearance \[m\] (the centre's less the radius) is below the spare.
    Goal(f64),
    /// The planner found no path with the spare; or the smallest clearance \[m\] along the one
    /// it found.
    Path(Option<f64>),
}

impl fmt::Display for Unreachable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Unreachable::Start(c) => write!(f, "the start is {c:.3} m clear"),
            Unreachable::Goal(c) => write!(f, "the goal disc is {c:.3} m clear"),
            Unreachable::Path(None) => write!(f, "the planner finds no path"),
            Unreachable::Path(Some(c)) => write!(f, "the planned path comes {c:.3} m close"),
        }
    }
}

/// Whether the goal at `goal` (radius `goal_radius`) is reachable from `start` among
/// `obstacles` by `robot`'s footprint keeping `spare` clear: the start and the whole goal disc
/// at least `spare` clear, and a path from the project's planner on which the footprint keeps
/// `spare` clear (sampled every centimetre). The planner is asked for half a grid cell's
/// diagonal more (its grid checks clearance at cell centres).
pub fn reach_among(
    obstacles: &[Obstacle],
    robot: &RobotDescription,
    start: [f64; 2],
    goal: [f64; 2],
    goal_radius: f64,
    spare: f64,
) -> Result<Route, Unreachable> {
    let bcfg = BarrierConfig::for_robot(robot, 0.0, 0.0);
    let barriers: Vec<_> = obstacles.iter().flat_map(|o| o.barriers(&bcfg)).collect();
    // A map's pieces measure an unsigned distance to its outline: inside a blocked region
    // the clearance is the field's (negative) instead.
    let fields: Vec<_> = obstacles.iter().filter_map(|o| o.map_field()).collect();
    let clear = |p: [f64; 2]| {
        let inside = fields
            .iter()
            .filter(|f| f.blocked_cell_at(p).is_some())
            .map(|f| f.signed_distance(p).0.min(-f.resolution()) - bcfg.robot_radius)
            .fold(f64::INFINITY, f64::min);
        if inside.is_finite() {
            return inside;
        }
        barriers
            .iter()
            .map(|b| b.clearance(nalgebra::Vector2::new(p[0], p[1])))
            .fold(f64::INFINITY, f64::min)
    };
    let start_clearance = clear(start);
    if start_clearance.is_nan() || start_clearance < spare {
        return Err(Unreachable::Start(start_clearance));
    }
    let goal_clearance = clear(goal);
    if goal_clearance.is_nan() || goal_clearance - goal_radius < spare {
        return Err(Unreachable::Goal(goal_clearance - goal_radius));
    }
    let defaults = PlannerConfig::default();
    let cfg = PlannerConfig {
        inflate: spare + defaults.resolution * std::f64::consts::FRAC_1_SQRT_2,
        ..defaults
    };
    let Ok(p) = plan(start, &[], goal, &clear, &cfg) else {
        return Err(Unreachable::Path(None));
    };
    if p.unplanned_legs > 0 {
        return Err(Unreachable::Path(None));
    }
    let mut length = 0.0;
    let mut path_clearance = f64::INFINITY;
    let mut from = start;
    for &to in &p.points {
        let d = (to[0] - from[0]).hypot(to[1] - from[1]);
        length += d;
        let n = (d / 0.01).ceil().max(1.0) as usize;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let q = [
                from[0] + t * (to[0] - from[0]),
                from[1] + t * (to[1] - from[1]),
            ];
            path_clearance = path_clearance.min(clear(q));
        }
        from = to;
    }
    if path_clearance.is_nan() || path_clearance < spare {
        return Err(Unreachable::Path(Some(path_clearance)));
    }
    Ok(Route {
        path: p.points,
        length,
        start_clearance,
        goal_clearance,
        path_clearance,
    })
}

/// [`reach_among`] for a loaded world: its obstacles, robot, start, goal centre and radius.
/// `None` for a world without a robot (the linear plant).
pub fn reach(world: &World, spare: f64) -> Option<Result<Route, Unreachable>> {
    let robot = world.robot.as_ref()?;
    let start = world
        .file
        .robot
        .as_ref()
        .map_or([0.0, 0.0], |r| [r.start.x, r.start.y]);
    let g = &world.file.goal;
    Some(reach_among(
        &world.obstacles,
        robot,
        start,
        g.center,
        g.radius,
        spare,
    ))
}

/// What the generator reads of a robot.
#[derive(Debug, Clone)]
struct RobotInfo {
    description: RobotDescription,
    /// The `urdf` key as written: relative to the output directory.
    urdf_key: String,
}

/// The generator: the configuration and the robots, loaded once.
#[derive(Debug, Clone)]
pub struct Generator {
    cfg: GenConfig,
    robots: Vec<RobotInfo>,
    map: Option<on_map::MapScene>,
}

/// `path` made absolute and normalised lexically (`.` dropped, `..` applied).
fn normalised(path: &Path) -> PathBuf {
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut out = PathBuf::new();
    for c in abs.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// `to` relative to the directory `from` (both made absolute first); `to` itself, absolute,
/// when they share no root.
pub fn relative_path(from: &Path, to: &Path) -> PathBuf {
    let (from, to) = (normalised(from), normalised(to));
    let (a, b): (Vec<_>, Vec<_>) = (from.components().collect(), to.components().collect());
    if a.first() != b.first() {
        return to;
    }
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut rel = PathBuf::new();
    for _ in common..a.len() {
        rel.push("..");
    }
    for c in &b[common..] {
        rel.push(c);
    }
    rel
}

impl Generator {
    /// Loads both robots from `cfg.robots_dir` and creates `cfg.out_dir` (each world is loaded
    /// from there, relative `urdf` path included, before it is returned).
    pub fn new(cfg: GenConfig) -> Result<Self, GenError> {
        std::fs::create_dir_all(&cfg.out_dir).map_err(|error| GenError::Io {
            path: cfg.out_dir.clone(),
            error,
        })?;
        let robots = RobotModel::ALL
            .into_iter()
            .map(|model| {
                let path = cfg.robots_dir.join(model.urdf_file());
                let description = RobotDescription::from_file(&path, &LoadOptions::default())
                    .map_err(|e| GenError::Robot {
                        path: path.clone(),
                        message: e.to_string(),
                    })?;
                let urdf_key = relative_path(&cfg.out_dir, &path)
                    .to_string_lossy()
                    .replace('\\', "/");
                Ok(RobotInfo {
                    description,
                    urdf_key,
                })
            })
            .collect::<Result<Vec<_>, GenError>>()?;
        let map = match &cfg.map {
            None => None,
            Some(path) if cfg.kind.is_some() => {
                return Err(GenError::Map {
                    path: path.clone(),
                    message: "a kind of scene does not apply to worlds drawn on a map (leave \
                              --kind at `all`)"
                        .into(),
                })
            }
            Some(path) => {
                let footprint = robots
                    .iter()
                    .map(|r| r.description.footprint_radius)
                    .fold(0.0, f64::max);
                Some(on_map::MapScene::load(path, &cfg.out_dir, footprint)?)
            }
        };
        Ok(Self { cfg, robots, map })
    }

    /// The configuration.
    pub fn config(&self) -> &GenConfig {
        &self.cfg
    }

    /// The kind, robot, suite and attack kind of world `i`: kinds and suites in turn (a Latin
    /// square: any 25 consecutive worlds hold every kind × suite pair when both are free), the
    /// robots alternating, the attack kinds a fresh shuffle of all twelve in every block of
    /// twelve worlds.
    pub fn plan_of(&self, i: usize) -> (Kind, RobotModel, Suite, &'static str) {
        let kinds: Vec<Kind> = match (&self.map, self.cfg.kind) {
            (Some(_), _) => vec![Kind::Map],
            (None, k) => k.map_or(Kind::ALL.to_vec(), |k| vec![k]),
        };
        let suites: Vec<Suite> = self.cfg.suite.map_or(Suite::ALL.to_vec(), |s| vec![s]);
        let robots: Vec<RobotModel> = self.cfg.robot.map_or(RobotModel::ALL.to_vec(), |r| vec![r]);
        let kind = kinds[i % kinds.len()];
        let suite = suites[(i + i / kinds.len()) % suites.len()];
        let robot = robots[i % robots.len()];
        let block = i / ATTACK_KINDS.len();
        let mut order = ATTACK_KINDS;
        order.shuffle(&mut stream_rng(
            self.cfg.seed,
            "gen-attacks",
            &block.to_string(),
        ));
        (kind, robot, suite, order[i % ATTACK_KINDS.len()])
    }

    /// Draws layouts of `kind` until the goal (of `goal_radius`) is reachable for robot
    /// `model`, at most [`MAX_DRAWS`] times: the layout, its reach and the draws it took.
    fn draw_reachable<R: Rng>(
        &self,
        i: usize,
        rng: &mut R,
        kind: Kind,
        model: RobotModel,
        goal_radius: f64,
    ) -> Result<(layout::Layout, Route, usize), GenError> {
        let robot = &self.robots[model as usize];
        let unreachable = GenError::NoReachableLayout {
            index: i,
            kind,
            robot: model,
            draws: MAX_DRAWS,
        };
        if let Some(map) = &self.map {
            return map
                .draw_reachable(rng, &robot.description, goal_radius)
                .ok_or(unreachable);
        }
        let fp = robot.description.footprint_radius;
        let keep = KeepOut {
            start: fp + SPARE,
            goal: fp + SPARE + goal_radius,
        };
        for draw in 1..=MAX_DRAWS {
            let Some(l) = layout::draw(rng, kind.scene(), keep) else {
                break;
            };
            let obstacles: Vec<Obstacle> = l
                .obstacles
                .iter()
                .map(|o| Obstacle::from_spec(&spec_of(o), None))
                .collect::<Result<_, _>>()
                .map_err(|e| GenError::Obstacle {
                    index: i,
                    message: e.to_string(),
                })?;
            if let Ok(r) = reach_among(
                &obstacles,
                &robot.description,
                l.start,
                l.goal,
                goal_radius,
                SPARE,
            ) {
                return Ok((l, r, draw));
            }
        }
        Err(unreachable)
    }

    /// World `i` of the seed's sequence.
    pub fn world(&self, i: usize) -> Result<GeneratedWorld, GenError> {
        let (kind, model, suite, attack_kind) = self.plan_of(i);
        // `robots` holds RobotModel::ALL in order
        let robot = &self.robots[model as usize];
        let rng = &mut stream_rng(self.cfg.seed, "gen", &i.to_string());
        let goal_radius = pick(rng, 0.1, 0.2, 0.05);
        let (l, reach, draws) = self.draw_reachable(i, rng, kind, model, goal_radius)?;

        // what a user adds around the scene
        let first = reach.path.first().copied().unwrap_or(l.goal);
        let theta = match rng.random_range(0..5) {
            0 | 1 => 0.0,
            2 | 3 => dec((first[1] - l.start[1]).atan2(first[0] - l.start[0]), 2),
            _ => pick(rng, -std::f64::consts::PI, std::f64::consts::PI, 0.01),
        };
        let v_max = robot.description.limits.v_max;
        // Movers may make the robot wait: half a minute more.
        let waits = if Kind::MOVERS.contains(&kind) {
            30.0
        } else {
            0.0
        };
        let needed = reach.length / (0.5 * v_max) + 10.0 + waits;
        let duration = [30.0, 40.0, 60.0, 90.0, 120.0, 180.0, 240.0]
            .into_iter()
            .find(|&d| d >= needed)
            .unwrap_or(300.0);
        let input_limit = if rng.random_bool(0.35) {
            None
        } else {
            Some([0.5, 1.0, 1.5, 2.0][rng.random_range(0..4)])
        };
        let world_seed = rng.random_range(0..1000u64);
        let sensors = suite::draw(rng, suite);
        let (pattern, channels) =
            sensors.patterns[rng.random_range(0..sensors.patterns.len())].clone();
        let attack = attack::draw(rng, attack_kind, &channels, &sensors.sensors, duration);

        let movers = self.movers(i, kind, &l, &reach, goal_radius, model)?;
        let name = format!("gen{}_{i:03}_{}", self.cfg.seed, kind.name());
        let file_name = format!("{name}.toml");
        let extra_patterns = &sensors.other_patterns;
        let mut header = vec![
            format!("Generated by `{}` (world {i}): {}, the {}.", self.cfg.command(), l.summary, model.urdf_file().trim_end_matches(".urdf")),
            format!(
                "Sensors (suite \"{}\"): {}; one fault pattern per receiver{}.",
                suite.name(),
                sensors.summary,
                if extra_patterns.is_empty() {
                    String::new()
                } else {
                    format!(" and \"{}\"", extra_patterns.join("\", \""))
                }
            ),
            format!(
                "Attack: {} on {} from t = {} s, inside fault pattern \"{pattern}\".",
                attack.kind,
                attack.channels.join(", "),
                text::num(attack.start)
            ),
            format!(
                "Defaults only: no tuning keys (form, cbf_gain, process_noise, drive, nominal, …){}.",
                if input_limit.is_some() {
                    "; the one [control] key is input_limit"
                } else {
                    ", no [control] table"
                }
            ),
        ];
        if !movers.is_empty() {
            let names: Vec<&str> = movers.iter().map(|m| m.0.name.as_str()).collect();
            header.push(format!(
                "Moving obstacles ({}): {}.",
                kind.name(),
                names.join(", ")
            ));
        }
        let mut wt = WorldText {
            header,
            movers,
            name: name.clone(),
            duration,
            seed: world_seed,
            urdf: robot.urdf_key.clone(),
            start: [l.start[0], l.start[1], theta],
            input_limit,
            goal: l.goal,
            goal_radius,
            obstacles: l.obstacles,
            map: self.map.as_ref().map(|m| m.key.clone()),
            sensors: sensors.sensors,
            patterns: sensors.patterns,
            attack: attack.clone(),
        };
        let text = self.render_checked(&mut wt, &file_name)?;
        Ok(GeneratedWorld {
            index: i,
            name,
            file_name,
            kind,
            robot: model,
            suite,
            attack_kind,
            attack_channels: attack.channels,
            attack_pattern: pattern,
            reach,
            draws,
            text,
        })
    }

    /// `wt`'s text, loaded back as `check` and `run` will; without its movers when they do not
    /// keep the room `check` asks for this robot and these movers ([`movers_keep_room`]).
    fn render_checked(&self, wt: &mut WorldText, file_name: &str) -> Result<String, GenError> {
        let load = |text: &str| {
            World::from_str(text, &self.cfg.out_dir.join(file_name), &[]).map_err(|e| {
                GenError::Invalid {
                    file: file_name.to_string(),
                    error: Box::new(e),
                }
            })
        };
        let text = wt.render();
        let world = load(&text)?;
        if wt.movers.is_empty() || movers_keep_room(&world) {
            return Ok(text);
        }
        wt.movers.clear();
        wt.header.retain(|l| !l.starts_with("Moving obstacles"));
        let text = wt.render();
        load(&text)?;
        Ok(text)
    }

    /// The movers of world `i` of a moving-obstacle kind, from their own stream (none for a
    /// static kind).
    fn movers(
        &self,
        i: usize,
        kind: Kind,
        l: &layout::Layout,
        reach: &Route,
        goal_radius: f64,
        model: RobotModel,
    ) -> Result<Vec<moving::Mover>, GenError> {
        if !Kind::MOVERS.contains(&kind) {
            return Ok(Vec::new());
        }
        let bare = moving::bare_config();
        let statics = l
            .obstacles
            .iter()
            .map(|o| Obstacle::from_spec(&spec_of(o), None).map(|ob| ob.barrier(&bare)))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| GenError::Obstacle {
                index: i,
                message: e.to_string(),
            })?;
        let mut route = vec![l.start];
        route.extend(&reach.path);
        let footprint = self.robots[model as usize].description.footprint_radius;
        let (room, apart) = moving::room_for(footprint);
        let scene = moving::Scene {
            statics: &statics,
            route,
            footprint,
            goal_radius,
            room,
            apart,
        };
        let rng = &mut stream_rng(self.cfg.seed, "gen-movers", &i.to_string());
        Ok(moving::draw(rng, kind, &scene))
    }

    /// Worlds `0..count`.
    pub fn worlds(&self, count: usize) -> Result<Vec<GeneratedWorld>, GenError> {
        (0..count).map(|i| self.world(i)).collect()
    }
}

/// Whether every mover of `world` passes `check`'s pinning findings (against the static
/// obstacles and the other movers).
fn movers_keep_room(world: &World) -> bool {
    crate::model::setup::ControlSetup::new(world, crate::world::ControllerKindSpec::FtCbfClf)
        .is_ok_and(|setup| {
            crate::analysis::moving_check::findings(world, &setup)
                .iter()
                .filter(|f| f.name.contains("pin the robot"))
                .all(|f| f.holds == Some(true))
        })
}

/// The loader's spec of a drawn obstacle.
fn spec_of(o: &text::Obstacle) -> ObstacleSpec {
    ObstacleSpec {
        name: o.name.clone(),
        position: o.position,
        rpy: [0.0, 0.0, o.yaw],
        shape: match o.shape {
            Shape::Cuboid(h) => ShapeSpec::Cuboid { half_extents: h },
            Shape::Cylinder {
                radius,
                half_height,
            } => ShapeSpec::Cylinder {
                radius,
                half_height,
            },
            Shape::Ball { radius } => ShapeSpec::Ball { radius },
        },
        motion: None,
        tracker: None,
    }
}

/// Generates `count` worlds as `cfg` says (see [`Generator`]).
pub fn generate(cfg: &GenConfig, count: usize) -> Result<Vec<GeneratedWorld>, GenError> {
    Generator::new(cfg.clone())?.worlds(count)
}

/// Writes each world to `dir/FILE_NAME` (creating `dir`); returns the paths.
pub fn write_worlds(dir: &Path, worlds: &[GeneratedWorld]) -> Result<Vec<PathBuf>, GenError> {
    std::fs::create_dir_all(dir).map_err(|error| GenError::Io {
        path: dir.to_path_buf(),
        error,
    })?;
    worlds
        .iter()
        .map(|w| {
            let path = dir.join(&w.file_name);
            std::fs::write(&path, &w.text).map_err(|error| GenError::Io {
                path: path.clone(),
                error,
            })?;
            Ok(path)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    fn robots_dir() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../robots")
    }

    fn out_dir(tag: &str) -> PathBuf {
        std::env::temp_dir().join(format!("ftcbf-worldgen-{}-{tag}", std::process::id()))
    }

    fn config(seed: u64, tag: &str) -> GenConfig {
        GenConfig {
            seed,
            kind: None,
            robot: None,
            suite: None,
            robots_dir: robots_dir(),
            out_dir: out_dir(tag),
            map: None,
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_text_and_world_i_does_not_depend_on_the_count() {
        let a = generate(&config(5, "det-a"), 12).unwrap_or_else(|e| panic!("{e}"));
        // a sibling directory: the same relative robot path
        let b = generate(&config(5, "det-b"), 12).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(a.len(), 12);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.text, y.text, "{}", x.file_name);
        }
        let g = Generator::new(config(5, "det-a")).unwrap_or_else(|e| panic!("{e}"));
        let w7 = g.world(7).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(w7.text, a[7].text);
        let c = generate(&config(6, "det-c"), 12).unwrap_or_else(|e| panic!("{e}"));
        let same = a.iter().zip(&c).filter(|(x, y)| x.text == y.text).count();
        assert_eq!(same, 0, "seed 6 repeats worlds of seed 5");
    }

    /// The keys a generated file may hold, table by table: what a user needs and no tuning key.
    fn assert_user_keys_only(w: &GeneratedWorld) {
        let doc: toml::Table = toml::from_str(&w.text).unwrap_or_else(|e| panic!("{e}"));
        let allowed: BTreeSet<&str> = [
            "name",
            "duration",
            "seed",
            "robot",
            "control",
            "goal",
            "obstacles",
            "sensors",
            "fault_patterns",
            "attacks",
        ]
        .into();
        for k in doc.keys() {
            assert!(allowed.contains(k.as_str()), "{}: key `{k}`", w.file_name);
        }
        let keys = |t: &str| -> BTreeSet<String> {
            doc.get(t)
                .and_then(|v| v.as_table())
                .map(|t| t.keys().cloned().collect())
                .unwrap_or_default()
        };
        let robot = keys("robot");
        assert_eq!(
            robot,
            ["start".to_string(), "urdf".to_string()].into(),
            "{}",
            w.file_name
        );
        let control = keys("control");
        assert!(
            control.is_empty() || control == ["input_limit".to_string()].into(),
            "{}: [control] {control:?}",
            w.file_name
        );
        assert_eq!(
            doc.get("attacks").and_then(|a| a.as_array()).map(Vec::len),
            Some(1),
            "{}",
            w.file_name
        );
        assert!(w.text.starts_with("# Generated by `ftcbf gen --seed"));
        assert!(w.text.contains("Defaults only: no tuning keys"));
    }

    #[test]
    fn two_hundred_worlds_load_are_reachable_and_hold_only_user_keys() {
        let dir = out_dir("valid");
        let worlds = generate(&config(2024, "valid"), 200).unwrap_or_else(|e| panic!("{e}"));
        let paths = write_worlds(&dir, &worlds).unwrap_or_else(|e| panic!("{e}"));
        let mut redrawn = 0;
        for (w, path) in worlds.iter().zip(&paths) {
            // the loader `check` and `run` use, from the written file
            let world = World::load(path, &[]).unwrap_or_else(|e| panic!("{e}"));
            assert_user_keys_only(w);
            // independently of the generator's own check: start and goal clear, path planned
            let r = reach(&world, SPARE)
                .expect("a rapier robot")
                .unwrap_or_else(|b| panic!("{}: {b}", w.file_name));
            assert!(r.start_clearance >= SPARE && r.path_clearance >= SPARE);
            assert!(r.goal_clearance - world.file.goal.radius >= SPARE);
            let g = &world.file.goal;
            assert!((0.1..=0.2).contains(&g.radius), "{}", w.file_name);
            let start = world.file.robot.as_ref().map(|r| r.start).expect("robot");
            assert!(
                (g.center[0] - start.x).hypot(g.center[1] - start.y) > 1.0,
                "{}: goal next to the start",
                w.file_name
            );
            // the attack lies inside one declared fault pattern
            let a = &world.file.attacks[0];
            assert!(
                world
                    .file
                    .fault_patterns
                    .iter()
                    .any(|p| a.channels.iter().all(|c| p.channels.contains(c))),
                "{}: attack outside every pattern",
                w.file_name
            );
            assert_eq!(a.kind.name(), w.attack_kind);
            redrawn += usize::from(w.draws > 1);
        }
        // the layouts are drawn as users would, not from what fits: some are redrawn
        assert!(redrawn > 0, "no layout was ever redrawn");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn check_runs_on_generated_worlds() {
        let worlds = generate(&config(77, "check"), 40).unwrap_or_else(|e| panic!("{e}"));
        let dir = out_dir("check");
        let mut applies = 0;
        for w in &worlds {
            let world = World::from_str(&w.text, &dir.join(&w.file_name), &[])
                .unwrap_or_else(|e| panic!("{e}"));
            let report = crate::analysis::check::check_world(&world)
                .unwrap_or_else(|e| panic!("{}: check: {e}", w.file_name));
            applies += usize::from(report.verdict.applies);
        }
        // the verdict is the checker's; what is asked here is that it runs on every world
        assert!(applies <= worlds.len());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The moving kinds give their movers room: in every generated world with movers, each
    /// mover keeps from the static obstacles and from the other movers what `check` asks for
    /// the robot not to be pinned, so none of its pinning findings fails; and a fair share of
    /// the worlds get a mover (16 of these 80 at the time of writing).
    #[test]
    fn generated_movers_cannot_pin_the_robot() {
        let dir = out_dir("movers");
        let mut with = 0;
        for kind in Kind::MOVERS {
            let cfg = GenConfig {
                kind: Some(kind),
                ..config(51, "movers")
            };
            for w in &generate(&cfg, 20).unwrap_or_else(|e| panic!("{e}")) {
                let world = World::from_str(&w.text, &dir.join(&w.file_name), &[])
                    .unwrap_or_else(|e| panic!("{e}"));
                let setup = crate::model::setup::ControlSetup::new(
                    &world,
                    crate::world::ControllerKindSpec::FtCbfClf,
                )
                .unwrap_or_else(|e| panic!("{}: {e}", w.file_name));
                let found = crate::analysis::moving_check::findings(&world, &setup);
                with += usize::from(!found.is_empty());
                for f in found.iter().filter(|f| f.name.contains("pin the robot")) {
                    assert_eq!(f.holds, Some(true), "{}: {}", w.file_name, f.detail);
                }
            }
        }
        assert!(with >= 10, "{with} of 80 worlds have a mover");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn every_kind_suite_robot_and_attack_kind_is_produced() {
        let g = Generator::new(config(9, "cover")).unwrap_or_else(|e| panic!("{e}"));
        let worlds = g.worlds(60).unwrap_or_else(|e| panic!("{e}"));
        let kinds: BTreeSet<Kind> = worlds.iter().map(|w| w.kind).collect();
        let suites: BTreeSet<Suite> = worlds.iter().map(|w| w.suite).collect();
        let robots: BTreeSet<RobotModel> = worlds.iter().map(|w| w.robot).collect();
        let attacks: BTreeSet<&str> = worlds.iter().map(|w| w.attack_kind).collect();
        assert_eq!(kinds.len(), Kind::ALL.len());
        assert_eq!(suites.len(), Suite::ALL.len());
        assert_eq!(robots.len(), RobotModel::ALL.len());
        assert_eq!(attacks, ATTACK_KINDS.into_iter().collect());
        // the first 25 hold every kind × suite pair; any 12 consecutive every attack kind
        let pairs: BTreeSet<(Kind, Suite)> =
            worlds[..25].iter().map(|w| (w.kind, w.suite)).collect();
        assert_eq!(pairs.len(), 25);
        for block in worlds.chunks(12) {
            let a: BTreeSet<&str> = block.iter().map(|w| w.attack_kind).collect();
            assert_eq!(a.len(), block.len());
        }
        // and the attacks are not all on receivers: odometry and encoder patterns get theirs
        let patterns: BTreeSet<&str> = worlds.iter().map(|w| w.attack_pattern.as_str()).collect();
        assert!(
            patterns.contains("odometry") || patterns.contains("encoders"),
            "{patterns:?}"
        );
        let _ = std::fs::remove_dir_all(out_dir("cover"));
    }

    #[test]
    fn a_fixed_kind_robot_and_suite_are_kept() {
        let cfg = GenConfig {
            kind: Some(Kind::Doorway),
            robot: Some(RobotModel::Waffle),
            suite: Some(Suite::Encoders),
            ..config(3, "fixed")
        };
        let worlds = generate(&cfg, 6).unwrap_or_else(|e| panic!("{e}"));
        for w in &worlds {
            assert_eq!(
                (w.kind, w.robot, w.suite),
                (Kind::Doorway, RobotModel::Waffle, Suite::Encoders)
            );
            assert!(w.text.contains("turtlebot3_waffle.urdf"));
            assert!(w.text.contains("from_wheels"));
            assert!(w
                .text
                .contains("--kind doorway --robot waffle --suite encoders"));
        }
        let _ = std::fs::remove_dir_all(out_dir("fixed"));
    }

    fn wall(x: f64, half_y: f64) -> Obstacle {
        let spec = ObstacleSpec {
            name: "wall".into(),
            position: [x, 0.0, 0.2],
            rpy: [0.0; 3],
            shape: ShapeSpec::Cuboid {
                half_extents: [0.05, half_y, 0.2],
            },
            motion: None,
            tracker: None,
        };
        Obstacle::from_spec(&spec, None).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn reach_refuses_a_blocked_start_goal_or_path() {
        let robot = RobotDescription::from_file(
            robots_dir().join("turtlebot3_burger.urdf"),
            &LoadOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let fp = robot.footprint_radius;
        // a short wall: the path goes around it with the spare
        let r = reach_among(
            &[wall(1.0, 0.5)],
            &robot,
            [0.0, 0.0],
            [2.0, 0.0],
            0.1,
            SPARE,
        )
        .unwrap_or_else(|b| panic!("{b}"));
        assert!(r.path.len() >= 2, "{:?}", r.path);
        assert!(r.length > 2.0 && r.path_clearance >= SPARE);
        // a wall far longer than the planner's grid: no path
        assert_eq!(
            reach_among(
                &[wall(1.0, 50.0)],
                &robot,
                [0.0, 0.0],
                [2.0, 0.0],
                0.1,
                SPARE
            ),
            Err(Unreachable::Path(None))
        );
        // the start closer to the wall than footprint + spare
        let x = 1.0 - 0.05 - fp - SPARE + 0.01;
        assert!(matches!(
            reach_among(&[wall(1.0, 0.5)], &robot, [x, 0.0], [2.0, 0.0], 0.1, SPARE),
            Err(Unreachable::Start(c)) if c < SPARE
        ));
        // the goal disc reaching within the spare (its centre would do)
        let g = 1.0 + 0.05 + fp + SPARE + 0.05;
        assert!(matches!(
            reach_among(&[wall(1.0, 0.5)], &robot, [0.0, 0.0], [g, 0.0], 0.1, SPARE),
            Err(Unreachable::Goal(c)) if c < SPARE
        ));
        // two walls leaving a door narrower than the footprint plus the spare on both sides
        let door = 2.0 * (fp + SPARE) - 0.05;
        let post = |y: f64| {
            let spec = ObstacleSpec {
                name: "post".into(),
                position: [1.0, y, 0.2],
                rpy: [0.0; 3],
                shape: ShapeSpec::Cuboid {
                    half_extents: [0.05, 25.0, 0.2],
                },
                motion: None,
                tracker: None,
            };
            Obstacle::from_spec(&spec, None).unwrap_or_else(|e| panic!("{e}"))
        };
        let narrow = [post(door / 2.0 + 25.0), post(-door / 2.0 - 25.0)];
        assert!(reach_among(&narrow, &robot, [0.0, 0.0], [2.0, 0.0], 0.1, SPARE).is_err());
        let wide = 2.0 * (fp + SPARE) + 0.15;
        let open = [post(wide / 2.0 + 25.0), post(-wide / 2.0 - 25.0)];
        assert!(reach_among(&open, &robot, [0.0, 0.0], [2.0, 0.0], 0.1, SPARE).is_ok());
    }

    #[test]
    fn robot_paths_are_relative_to_the_output_directory() {
        assert_eq!(
            relative_path(Path::new("/a/b/out"), Path::new("/a/robots/r.urdf")),
            PathBuf::from("../../robots/r.urdf")
        );
        assert_eq!(
            relative_path(Path::new("/a/./b/../c"), Path::new("/a/c/r.urdf")),
            PathBuf::from("r.urdf")
        );
        let g = Generator::new(config(1, "rel")).unwrap_or_else(|e| panic!("{e}"));
        let w = g.world(0).unwrap_or_else(|e| panic!("{e}"));
        let key = w
            .text
            .lines()
            .find_map(|l| l.strip_prefix("urdf = \""))
            .and_then(|l| l.strip_suffix('"'))
            .expect("urdf key");
        let resolved = normalised(&out_dir("rel").join(key));
        assert_eq!(
            resolved,
            normalised(&robots_dir().join(w.robot.urdf_file())),
            "{key}"
        );
        let _ = std::fs::remove_dir_all(out_dir("rel"));
    }

    #[test]
    fn names_parse_back() {
        for k in Kind::ALL {
            assert_eq!(k.name().parse::<Kind>(), Ok(k));
        }
        for s in Suite::ALL {
            assert_eq!(s.name().parse::<Suite>(), Ok(s));
        }
        assert!("kitchen".parse::<Kind>().unwrap_err().contains("l_turn"));
    }
}

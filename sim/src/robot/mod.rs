//! Robot descriptions loaded from URDF (urdf-rs), independent of any physics engine.
//!
//! A [`RobotDescription`] is the validated, immutable model of a differential-drive robot:
//! rigid bodies (URDF links, with links joined by `fixed` joints merged into one body), their
//! mass properties and collision shapes, the movable joints between bodies, the two drive
//! wheels with their radius and separation *read from the URDF*, the drive limits and the
//! planar footprint used by the obstacle barriers. [`crate::physics::PhysicsWorld`] turns it
//! into rapier bodies, colliders and joints.
//!
//! Frames: the *root frame* is the frame of the URDF's root link (for a TurtleBot3,
//! `base_footprint`, on the ground between the wheels), REP-103: x forward, y left, z up.
//!
//! Loading rules:
//! - The XML is read as ROS's urdfdom reads it (`robot/urdf.rs`): unknown elements and attributes are
//!   warnings with their line, missing optional values take the spec's defaults, and what ROS
//!   refuses is a [`RobotError::Parse`] naming the element, its `name` and the line.
//! - `package://NAME/rest` is resolved against the caller's search path ([`LoadOptions`]):
//!   `packages[NAME]/rest` when the caller maps the package to a folder (a package whose folder
//!   has another name), else for each directory `d`, `d/NAME/rest`, then `d/rest` when `d`
//!   itself is named `NAME`.
//!   `file://` paths are used as they are; relative paths are relative to the URDF's directory.
//!   Meshes are read with the `mesh-loader` crate: STL (ASCII or binary), Collada (`.dae`, with
//!   its node transforms, and its `<unit>` applied by this module after them) and Wavefront
//!   OBJ. A missing *visual* mesh is a warning ([`RobotDescription::warnings`]); a missing or
//!   unreadable *collision* mesh is an error naming the file and the package search path.
//! - Links without `<inertial>` (mass 0) are allowed only where they are rigidly attached
//!   (fixed joints) to a body that has mass; a movable body whose merged mass is ≤ 0 is an error,
//!   except a promoted wheel (below), which gets the mass and inertia of its solid collision
//!   cylinder at 1000 kg/m³, with a warning.
//! - Xacro sources (`${...}`, `$(...)`, `<xacro:...>` outside XML comments, CDATA sections and
//!   processing instructions: ROS packages ship plain URDFs with commented-out
//!   `<xacro:include …/>` lines) read from a file are expanded by the real `xacro`
//!   (`robot/xacro.rs`, with [`LoadOptions::xacro`]'s arguments); without xacro the error says
//!   how to install it. From a string, or with [`XacroCommand::Disabled`], they are refused with
//!   the line, the enclosing link/joint and the attribute.
//! - Drive wheels: the two joints named by the caller (a named `fixed` joint is *promoted*: some
//!   published files, e.g. Adept's Pioneer 3-DX, describe their drive wheels with fixed joints,
//!   and it is driven as a continuous joint about the `<axis xyz>` written on it, which ROS
//!   ignores on a fixed joint, else about its child's collision cylinder's axis, with a
//!   warning), otherwise every `continuous` joint on the root body with a lateral axis (±y of
//!   the root frame) whose child link has a cylinder or mesh collision (a swivel caster's wheel
//!   hangs from the swivel, not the root body), grouped
//!   by the side of the root frame's x axis its joint origin lies on (left = +y). Two such
//!   joints make a differential drive; four or more, the same number on each side, make a
//!   skid-steer drive whose wheels on one side all get the same command (as ROS's
//!   diff_drive/skid_steer controllers drive them). A wheel on the centre line or an unequal
//!   number per side is an error naming the joints. Wheel radius = the cylinder's radius, or for
//!   a mesh wheel the largest distance of a mesh vertex from the joint axis (the wheel then
//!   collides as the cylinder of that radius and of the mesh's width along the axis); all wheels
//!   equal within 0.1 mm (1 % when measured from meshes); separation (the effective track
//!   width) = planar distance between the centroids of the left and the right wheel joint
//!   origins.
//! - Drive limits: explicit [`LoadOptions::limits`] if given, else derived from the wheel
//!   joints' `<limit velocity>` (rad/s): `wheel_speed_max = min(velocity)`,
//!   `v_max = r · wheel_speed_max`, `omega_max = 2 r · wheel_speed_max / separation`.
//!   A URDF without wheel velocity limits and no override is an error.

use std::collections::{BTreeMap, HashMap};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

mod build;
mod error;
mod mesh;
mod wheels;

use build::*;
pub use error::*;
pub use mesh::*;
use wheels::*;

pub(crate) mod urdf;
mod xacro;

pub use urdf::MAX_DEPTH as MAX_URDF_DEPTH;
pub use xacro::{XacroCommand, XacroOptions, INSTALL_HINT as XACRO_INSTALL_HINT};

/// Options of [`RobotDescription::from_file`] / [`RobotDescription::from_urdf_str`].
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// Directories that hold ROS packages, used to resolve `package://NAME/...`.
    pub package_paths: Vec<PathBuf>,
    /// Folders of named packages, for a package whose folder has another name (MATLAB's copy of
    /// Quanser's `package://qbot2e/` files is a folder `quanser_description`): `package://NAME/
    /// rest` is `packages[NAME]/rest`, looked up before [`Self::package_paths`].
    pub packages: BTreeMap<String, PathBuf>,
    /// Names of the (left, right) wheel joints; `None` = find the continuous wheel joints. A
    /// named `fixed` joint is driven as a continuous one (see [`RobotDescription::from_file`]).
    pub wheel_joints: Option<(String, String)>,
    /// Explicit drive limits; `None` = derive from the wheel joints' velocity limits.
    pub limits: Option<DriveLimits>,
    /// How a xacro source is expanded (arguments, which xacro).
    pub xacro: XacroOptions,
}

/// Speed limits of the differential drive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveLimits {
    /// Maximum forward speed |v| [m/s].
    pub v_max: f64,
    /// Maximum yaw rate |ω| [rad/s].
    pub omega_max: f64,
    /// Maximum wheel angular speed [rad/s].
    pub wheel_speed_max: f64,
}

/// Where the drive limits came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LimitsSource {
    /// [`LoadOptions::limits`] (a world's `[robot] limits`).
    Explicit,
    /// The wheel joints' `<limit velocity>`.
    WheelJoints,
    /// The maker's published figures for this robot ([`MAKER_LIMITS`]), because the URDF's
    /// wheel joints carry no velocity limit.
    Maker(&'static MakerLimits),
}

/// A robot maker's published speed limits, applied when a URDF of that robot (matched by its
/// `<robot name>`) carries no wheel velocity limits.
#[derive(Debug, PartialEq)]
pub struct MakerLimits {
    /// The URDF `<robot name>` the limits apply to.
    pub robot_name: &'static str,
    /// Maximum forward speed [m/s].
    pub v_max: f64,
    /// Maximum yaw rate [rad/s].
    pub omega_max: f64,
    /// Where the figures are published.
    pub source: &'static str,
}

/// Published limits of the robots the README names. TurtleBot3: ROBOTIS e-manual,
/// "TurtleBot3 › Features › Specifications" (burger: maximum translational velocity 0.22 m/s,
/// maximum rotational velocity 2.84 rad/s; waffle and waffle_pi: 0.26 m/s and 1.82 rad/s).
pub const MAKER_LIMITS: [MakerLimits; 3] = [
    MakerLimits {
        robot_name: "turtlebot3_burger",
        v_max: 0.22,
        omega_max: 2.84,
        source: TURTLEBOT3_SPECS,
    },
    MakerLimits {
        robot_name: "turtlebot3_waffle",
        v_max: 0.26,
        omega_max: 1.82,
        source: TURTLEBOT3_SPECS,
    },
    MakerLimits {
        robot_name: "turtlebot3_waffle_pi",
        v_max: 0.26,
        omega_max: 1.82,
        source: TURTLEBOT3_SPECS,
    },
];

const TURTLEBOT3_SPECS: &str =
    "ROBOTIS e-manual, TurtleBot3 specifications (https://emanual.robotis.com/docs/en/platform/turtlebot3/features/)";

/// Wheel geometry of a differential drive, read from the URDF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelGeometry {
    /// Wheel radius \[m\].
    pub radius: f64,
    /// Distance between the two wheel contact points (track width) \[m\].
    pub separation: f64,
}

/// One drive wheel.
#[derive(Debug, Clone, PartialEq)]
pub struct Wheel {
    /// URDF joint name.
    pub joint_name: String,
    /// Index into [`RobotDescription::joints`].
    pub joint: usize,
    /// Index into [`RobotDescription::bodies`] of the wheel body.
    pub body: usize,
    /// +1 if a positive joint rotation drives the robot forward (joint axis along +y of the
    /// root frame), −1 if it drives it backward.
    pub forward_sign: f64,
    /// Motor torque bound from the joint's `<limit effort>` [N·m], if given (> 0).
    pub effort_limit: Option<f64>,
}

/// The drive wheels, grouped by side. A differential drive has one wheel per side; a
/// skid-steer robot two or more, all of one side driven at the same speed.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveWheels {
    /// Left wheels (+y side of the root frame), front to back.
    pub left: Vec<Wheel>,
    /// Right wheels (−y side), front to back.
    pub right: Vec<Wheel>,
    /// Radius and (effective) separation.
    pub geometry: WheelGeometry,
}

impl DriveWheels {
    /// Every drive wheel: the left ones, then the right ones.
    pub fn all(&self) -> impl Iterator<Item = &Wheel> + '_ {
        self.left.iter().chain(&self.right)
    }

    /// True for a skid-steer layout (more than one wheel per side).
    pub fn is_skid_steer(&self) -> bool {
        self.left.len() > 1
    }

    /// One line for `ftcbf check`: the layout, the wheel joints of each side and the
    /// (effective) track width, e.g. ``skid steer, left [`fl`, `rl`], right [`fr`, `rr`];
    /// effective track width 0.5000 m (between the side centroids), wheel radius 0.1000 m``.
    pub fn describe(&self) -> String {
        let side = |ws: &[Wheel]| {
            ws.iter()
                .map(|w| format!("`{}`", w.joint_name))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let g = self.geometry;
        if self.is_skid_steer() {
            format!(
                "skid steer, {} wheels: left [{}], right [{}] (each side driven as one); \
                 effective track width {:.4} m (between the side centroids), wheel radius {:.4} m",
                self.left.len() + self.right.len(),
                side(&self.left),
                side(&self.right),
                g.separation,
                g.radius
            )
        } else {
            format!(
                "differential, left {}, right {}; track width {:.4} m, wheel radius {:.4} m",
                side(&self.left),
                side(&self.right),
                g.separation,
                g.radius
            )
        }
    }
}

/// A collision shape in its collider frame. Cylinders and capsules stand along the collider
/// frame's **z** axis (URDF convention); the physics converts to parry's y axis.
#[derive(Debug, Clone, PartialEq)]
pub enum CollisionShape {
    /// Box with half extents along x, y, z \[m\].
    Box {
        /// Half extents \[m\].
        half_extents: [f64; 3],
    },
    /// Cylinder along z.
    Cylinder {
        /// Radius \[m\].
        radius: f64,
        /// Half of the length \[m\].
        half_length: f64,
    },
    /// Capsule along z (`half_length` is half the cylindrical part).
    Capsule {
        /// Radius \[m\].
        radius: f64,
        /// Half of the cylindrical part's length \[m\].
        half_length: f64,
    },
    /// Sphere.
    Sphere {
        /// Radius \[m\].
        radius: f64,
    },
    /// Triangle mesh (already scaled, collider frame) \[m\].
    Mesh {
        /// Vertices \[m\].
        vertices: Vec<[f64; 3]>,
        /// Triangles (indices into `vertices`).
        indices: Vec<[u32; 3]>,
    },
}

impl CollisionShape {
    /// Points whose convex hull bounds the shape (box corners, cylinder bounding-box corners,
    /// mesh vertices), in the collider frame.
    fn bounding_points(&self) -> Vec<Point3<f64>> {
        let corners = |h: [f64; 3]| {
            let mut v = Vec::with_capacity(8);
            for sx in [-1.0, 1.0] {
                for sy in [-1.0, 1.0] {
                    for sz in [-1.0, 1.0] {
                        v.push(Point3::new(sx * h[0], sy * h[1], sz * h[2]));
                    }
                }
            }
            v
        };
        match self {
            CollisionShape::Box { half_extents } => corners(*half_extents),
            CollisionShape::Cylinder {
                radius,
                half_length,
            } => corners([*radius, *radius, *half_length]),
            CollisionShape::Capsule {
                radius,
                half_length,
            } => corners([*radius, *radius, half_length + radius]),
            CollisionShape::Sphere { radius } => corners([*radius; 3]),
            CollisionShape::Mesh { vertices, .. } => vertices
                .iter()
                .map(|v| Point3::new(v[0], v[1], v[2]))
                .collect(),
        }
    }
}

/// A collision shape attached to a body.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotCollider {
    /// The URDF link it came from.
    pub link: String,
    /// Collider frame in the body frame.
    pub pose_in_body: Isometry3<f64>,
    /// The shape.
    pub shape: CollisionShape,
    /// True for the collision shapes of the drive wheels (they get ground friction; all other
    /// robot colliders are frictionless against the ground: casters and skids roll or slide).
    pub is_wheel: bool,
}

/// A rigid body: one URDF link plus every link fixed to it.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotBody {
    /// Name of the body's own (top) link; its frame is the body frame.
    pub name: String,
    /// All URDF links merged into this body (the first is `name`).
    pub links: Vec<String>,
    /// Body frame in the root frame, in the URDF's rest configuration (all joints at 0).
    pub pose_in_root: Isometry3<f64>,
    /// Total mass \[kg\].
    pub mass: f64,
    /// Centre of mass in the body frame \[m\].
    pub com: Vector3<f64>,
    /// Inertia tensor about the centre of mass, body-frame axes [kg·m²].
    pub inertia: Matrix3<f64>,
    /// Collision shapes.
    pub colliders: Vec<RobotCollider>,
    /// Visual meshes found on disk (drawing only; physics never reads them).
    pub visuals: Vec<RobotVisual>,
}

/// A URDF `<visual>` mesh of a link, loaded for drawing (STL, scaled to metres).
#[derive(Debug, Clone, PartialEq)]
pub struct RobotVisual {
    /// URDF link it belongs to.
    pub link: String,
    /// Mesh frame in the body frame.
    pub pose_in_body: Isometry3<f64>,
    /// Vertices in the mesh frame \[m\].
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as vertex indices.
    pub indices: Vec<[u32; 3]>,
}

/// Kind of a movable joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JointKind {
    /// Unlimited rotation about the axis.
    Continuous,
    /// Rotation about the axis within [lower, upper] rad.
    Revolute {
        /// Lower limit \[rad\].
        lower: f64,
        /// Upper limit \[rad\].
        upper: f64,
    },
    /// Translation along the axis within [lower, upper] m.
    Prismatic {
        /// Lower limit \[m\].
        lower: f64,
        /// Upper limit \[m\].
        upper: f64,
    },
}

/// A movable joint between two bodies.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotJoint {
    /// URDF joint name.
    pub name: String,
    /// Kind and limits.
    pub kind: JointKind,
    /// Parent body index.
    pub parent: usize,
    /// Child body index.
    pub child: usize,
    /// Joint frame in the parent *body* frame (the child body frame coincides with it at rest).
    pub frame_in_parent: Isometry3<f64>,
    /// Joint axis in the joint frame (unit).
    pub axis: Unit<Vector3<f64>>,
}

/// A validated differential-drive robot model.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotDescription {
    /// The URDF robot name.
    pub name: String,
    /// Where it was loaded from (`"<string>"` when from a string).
    pub origin: String,
    /// Bodies; index 0 is the root body (its frame is the root frame).
    pub bodies: Vec<RobotBody>,
    /// Movable joints.
    pub joints: Vec<RobotJoint>,
    /// The drive wheels (differential or skid steer).
    pub wheels: DriveWheels,
    /// Drive limits.
    pub limits: DriveLimits,
    /// Where [`Self::limits`] came from.
    pub limits_source: LimitsSource,
    /// Circumscribed radius of the robot's collision footprint in the plane, about the root
    /// frame origin \[m\] (the disc the obstacle barriers keep away from obstacles).
    pub footprint_radius: f64,
    /// Height above the ground of the middle of the robot's collision geometry \[m\]; obstacle
    /// distances for the barriers are evaluated at this height.
    pub centre_height: f64,
    /// Height above the ground of the top of the robot's collision geometry \[m\]: what an
    /// environment keeps (an SDF collision wholly above it cannot touch the robot).
    pub height: f64,
    /// Non-fatal problems (missing visual meshes, …).
    pub warnings: Vec<String>,
    /// The expanded URDF when the file was a xacro source (what was read; errors and warnings
    /// name its lines).
    pub xacro_output: Option<PathBuf>,
}

impl RobotDescription {
    /// Loads a URDF file. `package://` meshes are resolved with `opts.package_paths`, relative
    /// mesh paths against the file's directory.
    pub fn from_file(path: impl AsRef<Path>, opts: &LoadOptions) -> Result<Self, RobotError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| RobotError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let base_dir = path.parent().map(Path::to_path_buf);
        let origin = path.display().to_string();
        match check_xacro(&text, &origin) {
            Err(RobotError::Xacro { line, snippet, .. })
                if opts.xacro.command != XacroCommand::Disabled =>
            {
                let expanded = xacro::expand(path, &text, &opts.xacro, (line, &snippet))?;
                let origin = format!("{} (xacro output of {origin})", expanded.path.display());
                let mut r = load(&expanded.text, &origin, base_dir.as_deref(), opts)?;
                r.xacro_output = Some(expanded.path);
                Ok(r)
            }
            Err(e) => Err(e),
            Ok(()) => load(&text, &origin, base_dir.as_deref(), opts),
        }
    }

    /// Loads a URDF from a string (`origin` is used in messages); relative mesh paths are
    /// resolved against the current directory.
    pub fn from_urdf_str(text: &str, opts: &LoadOptions) -> Result<Self, RobotError> {
        load(text, "<string>", None, opts)
    }

    /// Total mass of the robot \[kg\].
    pub fn total_mass(&self) -> f64 {
        self.bodies.iter().map(|b| b.mass).sum()
    }

    /// Index of the body that contains URDF link `link`.
    pub fn body_of_link(&self, link: &str) -> Option<usize> {
        self.bodies
            .iter()
            .position(|b| b.links.iter().any(|l| l == link))
    }
}

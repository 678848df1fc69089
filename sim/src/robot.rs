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

pub(crate) mod urdf;
mod xacro;

pub use urdf::MAX_DEPTH as MAX_URDF_DEPTH;
pub use xacro::{XacroCommand, XacroOptions, INSTALL_HINT as XACRO_INSTALL_HINT};

/// Errors of URDF loading. Every message names the file (when there is one) and what to fix.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The URDF file could not be read.
    #[error("cannot read URDF file {path}: {source}")]
    Io {
        /// File path.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The XML is malformed or does not follow the URDF schema (what ROS's parser would refuse
    /// too): the message names the element and its `name`.
    #[error("{origin}: {}malformed URDF: {message}", line_prefix(*.line))]
    Parse {
        /// File path or `"<string>"`.
        origin: String,
        /// 1-based line of the offending element, when known.
        line: Option<usize>,
        /// What is wrong, naming the element.
        message: String,
    },
    /// Xacro macros or substitutions are still in the file.
    #[error(
        "{origin}: line {line}: xacro leftover `{snippet}` in {context}; \
         this is a xacro source, run `xacro file.urdf.xacro > file.urdf` first"
    )]
    Xacro {
        /// File path or `"<string>"`.
        origin: String,
        /// 1-based line number.
        line: usize,
        /// The offending text.
        snippet: String,
        /// Where it sits (link/joint name and attribute, when found).
        context: String,
    },
    /// The file is a xacro source and no xacro could be run.
    #[error(
        "{origin}: line {line}: `{snippet}` is xacro markup, so this file must be expanded by \
         xacro first, and xacro is not available ({tried}); {}",
        xacro::INSTALL_HINT
    )]
    XacroUnavailable {
        /// File path.
        origin: String,
        /// 1-based line of the first markup.
        line: usize,
        /// The markup.
        snippet: String,
        /// What was tried.
        tried: String,
    },
    /// xacro ran and failed.
    #[error("{origin}: xacro failed (`{command}`): {message}")]
    XacroFailed {
        /// File path.
        origin: String,
        /// The command line.
        command: String,
        /// xacro's message.
        message: String,
    },
    /// The URDF's structure is not a tree the loader can use.
    #[error("{origin}: {message}")]
    Structure {
        /// File path or `"<string>"`.
        origin: String,
        /// What is wrong.
        message: String,
    },
    /// A movable body has no positive mass.
    #[error(
        "{origin}: link `{link}` moves (joint `{joint}`) but its mass is {mass} kg; \
         give it an <inertial> with a positive <mass value>"
    )]
    NonPositiveMass {
        /// File path or `"<string>"`.
        origin: String,
        /// Link name.
        link: String,
        /// Joint that makes it movable ("root" for the root body).
        joint: String,
        /// The (merged) mass.
        mass: f64,
    },
    /// A number in the URDF is invalid (negative size, non-finite value, …).
    #[error("{origin}: {what}")]
    InvalidValue {
        /// File path or `"<string>"`.
        origin: String,
        /// What is wrong, naming the link/joint and attribute.
        what: String,
    },
    /// The drive wheels could not be identified.
    #[error("{origin}: cannot find the drive wheels: {message}")]
    Wheels {
        /// File path or `"<string>"`.
        origin: String,
        /// What is wrong.
        message: String,
    },
    /// A collision mesh could not be resolved or read.
    #[error("{origin}: collision mesh `{filename}` of link `{link}`: {message}")]
    CollisionMesh {
        /// File path or `"<string>"`.
        origin: String,
        /// Link name.
        link: String,
        /// The filename as written in the URDF.
        filename: String,
        /// What went wrong.
        message: String,
    },
}

fn line_prefix(line: Option<usize>) -> String {
    line.map(|l| format!("line {l}: ")).unwrap_or_default()
}

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

// ---------------------------------------------------------------------------------------------

fn load(
    text: &str,
    origin: &str,
    base_dir: Option<&Path>,
    opts: &LoadOptions,
) -> Result<RobotDescription, RobotError> {
    check_xacro(text, origin)?;
    let parsed = urdf::parse(text, origin)?;
    build(&parsed, origin, base_dir, opts)
}

/// Blanks XML comments, CDATA sections and processing instructions (keeping newlines, so line
/// numbers still count), because text inside them is never markup: a commented
/// `<xacro:include filename="$(find pkg)/…"/>` is not a leftover. Each construct ends at its
/// first terminator (`-->`, `]]>`, `?>`) as XML 1.0 §2.5–2.7 defines; an unterminated one blanks
/// the rest, and the URDF parser then reports the malformed XML.
fn mask_non_markup(text: &str) -> String {
    const KINDS: [(&str, &str); 3] = [("<!--", "-->"), ("<![CDATA[", "]]>"), ("<?", "?>")];
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some((start, (_, close))) = KINDS
        .iter()
        .filter_map(|k| rest.find(k.0).map(|i| (i, *k)))
        .min_by_key(|(i, _)| *i)
    {
        out.push_str(&rest[..start]);
        let body = &rest[start..];
        let end = body.find(close).map_or(body.len(), |e| e + close.len());
        out.extend(
            body[..end]
                .chars()
                .map(|c| if c == '\n' { '\n' } else { ' ' }),
        );
        rest = &body[end..];
    }
    out.push_str(rest);
    out
}

/// Rejects xacro leftovers with the line, enclosing element name and attribute. Comments, CDATA
/// and processing instructions are not searched (see [`mask_non_markup`]).
fn check_xacro(text: &str, origin: &str) -> Result<(), RobotError> {
    let masked = mask_non_markup(text);
    let text = masked.as_str();
    // `xmlns:xacro` alone is not a leftover: xacro keeps the namespace declaration in its output.
    let markers = ["<xacro:", "${", "$("];
    let Some(pos) = markers.iter().filter_map(|m| text.find(m)).min() else {
        return Ok(());
    };
    let line = text[..pos].matches('\n').count() + 1;
    let rest = &text[pos..];
    let end = rest
        .find(['}', ')', '>', '\n', '"'])
        .map(|e| (e + 1).min(rest.len()))
        .unwrap_or(rest.len().min(40));
    let snippet = rest[..end].trim_end_matches(['"', '\n']).to_string();
    // Enclosing element: the last `<link name=` / `<joint name=` before the position.
    let before = &text[..pos];
    let mut context = String::from("the robot element");
    let last_link = before.rfind("<link");
    let last_joint = before.rfind("<joint");
    let (kind, at) = match (last_link, last_joint) {
        (Some(l), Some(j)) if j > l => ("joint", Some(j)),
        (Some(l), _) => ("link", Some(l)),
        (None, Some(j)) => ("joint", Some(j)),
        (None, None) => ("", None),
    };
    if let Some(at) = at {
        let elem = &text[at..];
        if let Some(n) = elem.find("name=\"") {
            let name_start = n + 6;
            if let Some(name_len) = elem[name_start..].find('"') {
                context = format!("{kind} `{}`", &elem[name_start..name_start + name_len]);
            }
        }
    }
    // Attribute: `attr="...${` on the same element.
    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
    let segment = &text[line_start..pos];
    if let Some(q) = segment.rfind("=\"") {
        let attr: String = segment[..q]
            .chars()
            .rev()
            .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect();
        if !attr.is_empty() && !segment[q + 2..].contains('"') {
            context = format!("{context}, attribute `{attr}`");
        }
    }
    Err(RobotError::Xacro {
        origin: origin.to_string(),
        line,
        snippet,
        context,
    })
}

fn iso_from_pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    let [x, y, z] = p.xyz.0;
    let [r, pi, yw] = p.rpy.0;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(r, pi, yw),
    )
}

/// Mass properties accumulated in a body frame: mass, first moment, inertia about the
/// body-frame origin.
#[derive(Debug, Clone, Copy)]
struct MassAcc {
    mass: f64,
    moment: Vector3<f64>,
    inertia_origin: Matrix3<f64>,
}

impl MassAcc {
    fn zero() -> Self {
        Self {
            mass: 0.0,
            moment: Vector3::zeros(),
            inertia_origin: Matrix3::zeros(),
        }
    }
    /// Adds a point-mass-distribution with mass m, centre c and inertia `i_com` (about c,
    /// in a frame rotated by `rot` relative to the body frame).
    fn add(&mut self, m: f64, c: Vector3<f64>, rot: &UnitQuaternion<f64>, i_com: &Matrix3<f64>) {
        let r = rot.to_rotation_matrix();
        let i_body = r.matrix() * i_com * r.matrix().transpose();
        let parallel = m * (Matrix3::identity() * c.dot(&c) - c * c.transpose());
        self.mass += m;
        self.moment += m * c;
        self.inertia_origin += i_body + parallel;
    }
    fn finish(&self) -> (f64, Vector3<f64>, Matrix3<f64>) {
        if self.mass <= 0.0 {
            return (self.mass, Vector3::zeros(), Matrix3::zeros());
        }
        let c = self.moment / self.mass;
        let parallel = self.mass * (Matrix3::identity() * c.dot(&c) - c * c.transpose());
        (self.mass, c, self.inertia_origin - parallel)
    }
}

/// A robot description from a parsed URDF, in phases: the link tree, the walk that merges links
/// over fixed joints into bodies, the links' mass and geometry, the bodies' masses, the drive
/// wheels, the drive limits and the footprint.
fn build(
    parsed: &urdf::Parsed,
    origin: &str,
    base_dir: Option<&Path>,
    opts: &LoadOptions,
) -> Result<RobotDescription, RobotError> {
    let cx = Build {
        parsed,
        robot: &parsed.robot,
        origin,
        base_dir,
        opts,
    };
    if cx.robot.links.is_empty() {
        return Err(cx.structure("the URDF has no <link>".into()));
    }
    let tree = cx.link_tree()?;
    let mut kin = cx.walk(&tree)?;
    let (acc, mut warnings) = cx.link_contents(&mut kin)?;
    warnings.append(&mut kin.notes);
    let massless_wheels = cx.body_masses(&mut kin, &acc)?;
    let fixed_wheels = cx.fixed_wheel_joints(&tree, &kin);
    let wheels = find_wheels(
        cx.robot,
        origin,
        &kin.bodies,
        &kin.joints,
        &kin.joint_of_urdf,
        &fixed_wheels,
        opts,
    )?;
    wheel_colliders(&mut kin.bodies, &kin.joints, &wheels);
    cx.massless_wheel_masses(&mut kin, &massless_wheels, &mut warnings)?;
    let (limits, limits_source) = cx.drive_limits(&wheels)?;
    let (footprint_radius, centre_height, height) = cx.footprint(&kin.bodies)?;
    Ok(RobotDescription {
        name: cx.robot.name.clone(),
        origin: origin.to_string(),
        bodies: kin.bodies,
        joints: kin.joints,
        wheels,
        limits,
        limits_source,
        footprint_radius,
        centre_height,
        height,
        warnings,
        xacro_output: None,
    })
}

/// What [`build`] reads and reports against: the parsed file, its origin for messages, the
/// folder meshes resolve from, and the load options.
struct Build<'a> {
    parsed: &'a urdf::Parsed,
    robot: &'a urdf_rs::Robot,
    origin: &'a str,
    base_dir: Option<&'a Path>,
    opts: &'a LoadOptions,
}

/// The links as a tree: index by name, each link's parent joint and child joints, the root.
struct LinkTree<'a> {
    link_index: HashMap<&'a str, usize>,
    parent_joint: Vec<Option<usize>>,
    children: Vec<Vec<usize>>,
    root: usize,
}

/// Where a link went: its body and its pose in that body.
struct LinkInfo {
    body: usize,
    pose_in_body: Isometry3<f64>,
}

/// The bodies and joints the walk from the root makes.
struct Kinematics {
    /// Per link: its body and pose (`None` for a link the walk did not reach).
    info: Vec<Option<LinkInfo>>,
    bodies: Vec<RobotBody>,
    /// Per body: the URDF joint making it movable (`None` for the root).
    body_joint: Vec<Option<usize>>,
    joints: Vec<RobotJoint>,
    /// URDF joint index → index in `joints`.
    joint_of_urdf: HashMap<usize, usize>,
    /// Bodies of fixed joints driven as wheels because `[robot] wheels` names them.
    promoted_bodies: Vec<usize>,
    /// Notes for the warnings (one per promoted joint).
    notes: Vec<String>,
}

/// A body holding one link at its origin, with no mass or geometry yet.
fn empty_body(link: &str, pose_in_root: Isometry3<f64>) -> RobotBody {
    RobotBody {
        name: link.to_string(),
        links: vec![link.to_string()],
        pose_in_root,
        mass: 0.0,
        com: Vector3::zeros(),
        inertia: Matrix3::zeros(),
        colliders: Vec::new(),
        visuals: Vec::new(),
    }
}

impl Build<'_> {
    fn structure(&self, message: String) -> RobotError {
        RobotError::Structure {
            origin: self.origin.to_string(),
            message,
        }
    }

    fn invalid(&self, what: String) -> RobotError {
        RobotError::InvalidValue {
            origin: self.origin.to_string(),
            what,
        }
    }

    /// `joint `x` (line N)`, for messages.
    fn jname(&self, ji: usize) -> String {
        format!(
            "joint `{}` (line {})",
            self.robot.joints[ji].name, self.parsed.joint_lines[ji]
        )
    }

    /// The link tree: every joint names existing links, no link has two parent joints, and
    /// exactly one link has none (the root).
    fn link_tree(&self) -> Result<LinkTree<'_>, RobotError> {
        let robot = self.robot;
        // Names are unique (the reader refuses duplicates).
        let link_index: HashMap<&str, usize> = robot
            .links
            .iter()
            .enumerate()
            .map(|(i, l)| (l.name.as_str(), i))
            .collect();
        let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); robot.links.len()];
        let find = |ji: usize, which: &str, link: &str| {
            link_index.get(link).copied().ok_or_else(|| {
                self.structure(format!(
                    "{} names {which} link `{link}`, which does not exist",
                    self.jname(ji)
                ))
            })
        };
        for (ji, j) in robot.joints.iter().enumerate() {
            let p = find(ji, "parent", &j.parent.link)?;
            let c = find(ji, "child", &j.child.link)?;
            if let Some(first) = parent_joint[c] {
                return Err(self.structure(format!(
                    "link `{}` is the child of two joints, {} and {}",
                    j.child.link,
                    self.jname(first),
                    self.jname(ji)
                )));
            }
            parent_joint[c] = Some(ji);
            children[p].push(ji);
        }
        let roots: Vec<usize> = (0..robot.links.len())
            .filter(|&i| parent_joint[i].is_none())
            .collect();
        if roots.is_empty() {
            // Every link has a parent joint: following parents from any link must cycle.
            return Err(self.structure(format!(
                "no root link: the joints form a cycle ({})",
                joint_cycle(0, &parent_joint, robot, &|ji| self.jname(ji))
            )));
        }
        if roots.len() != 1 {
            let names: Vec<String> = roots
                .iter()
                .map(|&i| {
                    format!(
                        "`{}` (line {})",
                        robot.links[i].name, self.parsed.link_lines[i]
                    )
                })
                .collect();
            return Err(self.structure(format!(
                "the links must form one tree with a single root; roots found: {}",
                names.join(", ")
            )));
        }
        Ok(LinkTree {
            link_index,
            parent_joint,
            children,
            root: roots[0],
        })
    }

    /// Walks the tree from the root: a fixed joint merges its child link into the parent's
    /// body, any other joint starts a body of its own. Refuses loops, unsupported joint types
    /// and links the walk cannot reach.
    fn walk(&self, tree: &LinkTree) -> Result<Kinematics, RobotError> {
        let robot = self.robot;
        let root = tree.root;
        let mut info: Vec<Option<LinkInfo>> = (0..robot.links.len()).map(|_| None).collect();
        info[root] = Some(LinkInfo {
            body: 0,
            pose_in_body: Isometry3::identity(),
        });
        let mut kin = Kinematics {
            info,
            bodies: vec![empty_body(&robot.links[root].name, Isometry3::identity())],
            body_joint: vec![None],
            joints: Vec::new(),
            joint_of_urdf: HashMap::new(),
            promoted_bodies: Vec::new(),
            notes: Vec::new(),
        };
        let mut stack = vec![root];
        let mut visited = 1usize;
        while let Some(l) = stack.pop() {
            let (lbody, lpose) = match &kin.info[l] {
                Some(i) => (i.body, i.pose_in_body),
                None => continue,
            };
            for &ji in &tree.children[l] {
                let j = &robot.joints[ji];
                let c = tree.link_index[j.child.link.as_str()];
                if kin.info[c].is_some() {
                    return Err(
                        self.structure(format!("{} closes a kinematic loop", self.jname(ji)))
                    );
                }
                visited += 1;
                self.joint(&mut kin, ji, c, lbody, lpose)?;
                stack.push(c);
            }
        }
        if visited != robot.links.len() {
            // One root and one parent per link: a link the walk missed hangs off a cycle.
            let missed = (0..robot.links.len())
                .find(|&i| kin.info[i].is_none())
                .unwrap_or(0);
            return Err(self.structure(format!(
                "link `{}` is not connected to the root `{}`: the joints form a cycle ({})",
                robot.links[missed].name,
                robot.links[root].name,
                joint_cycle(missed, &tree.parent_joint, robot, &|ji| self.jname(ji))
            )));
        }
        Ok(kin)
    }

    /// URDF joint `ji` from a link of body `lbody` (at `lpose` in it) to link `c`: merges `c`
    /// into the body over a fixed joint, else makes `c` a body of its own and the joint a
    /// [`RobotJoint`]. A fixed joint that `[robot] wheels` names is driven as continuous.
    fn joint(
        &self,
        kin: &mut Kinematics,
        ji: usize,
        c: usize,
        lbody: usize,
        lpose: Isometry3<f64>,
    ) -> Result<(), RobotError> {
        let j = &self.robot.joints[ji];
        let origin_iso = iso_from_pose(&j.origin);
        // Fixed joints a world names as drive wheels (`[robot] wheels`): some published files
        // describe their drive wheels with fixed joints (a display model: Adept's Pioneer 3-DX
        // fixes `left_hub_joint` with `<!-- type="continuous" -->`); those are driven as
        // continuous joints.
        let named_wheel = self
            .opts
            .wheel_joints
            .as_ref()
            .is_some_and(|(l, r)| *l == j.name || *r == j.name);
        let promoted = j.joint_type == urdf_rs::JointType::Fixed && named_wheel;
        let kind = match j.joint_type {
            urdf_rs::JointType::Fixed if !promoted => {
                kin.info[c] = Some(LinkInfo {
                    body: lbody,
                    pose_in_body: lpose * origin_iso,
                });
                kin.bodies[lbody].links.push(j.child.link.clone());
                return Ok(());
            }
            urdf_rs::JointType::Continuous | urdf_rs::JointType::Fixed => JointKind::Continuous,
            urdf_rs::JointType::Revolute => JointKind::Revolute {
                lower: j.limit.lower,
                upper: j.limit.upper,
            },
            urdf_rs::JointType::Prismatic => JointKind::Prismatic {
                lower: j.limit.lower,
                upper: j.limit.upper,
            },
            ref other => {
                return Err(self.structure(format!(
                    "{} has type {other:?}; only fixed, continuous, revolute and \
                     prismatic joints are supported",
                    self.jname(ji)
                )))
            }
        };
        let axis_v = if promoted {
            self.promoted_joint_axis(ji, c, &mut kin.notes)?
        } else {
            Vector3::from(j.axis.xyz.0)
        };
        let axis = Unit::try_new(axis_v, 1e-9)
            .ok_or_else(|| self.invalid(format!("{}: <axis xyz> is zero", self.jname(ji))))?;
        let frame_in_parent = lpose * origin_iso;
        let pose_in_root = kin.bodies[lbody].pose_in_root * frame_in_parent;
        let b = kin.bodies.len();
        kin.bodies.push(empty_body(&j.child.link, pose_in_root));
        kin.body_joint.push(Some(ji));
        if promoted {
            kin.promoted_bodies.push(b);
        }
        kin.joint_of_urdf.insert(ji, kin.joints.len());
        kin.joints.push(RobotJoint {
            name: j.name.clone(),
            kind,
            parent: lbody,
            child: b,
            frame_in_parent,
            axis,
        });
        kin.info[c] = Some(LinkInfo {
            body: b,
            pose_in_body: Isometry3::identity(),
        });
        Ok(())
    }

    /// The axis of fixed joint `ji` (child link `c`) driven as a wheel, with a note saying
    /// where it came from; an error when the file gives none.
    fn promoted_joint_axis(
        &self,
        ji: usize,
        c: usize,
        notes: &mut Vec<String>,
    ) -> Result<Vector3<f64>, RobotError> {
        let j = &self.robot.joints[ji];
        let (axis_v, from) =
            promoted_axis(self.parsed, ji, &self.robot.links[c]).ok_or_else(|| {
                self.invalid(format!(
                    "{} is `fixed`, and [robot] wheels names it as a drive wheel: \
                     to drive it as a continuous joint it needs an <axis xyz> or \
                     a <cylinder> collision on link `{}` to take the axis from{}",
                    self.jname(ji),
                    j.child.link,
                    wheel_above(self.robot, &j.name)
                ))
            })?;
        // Rounded to 1e-6 (a cylinder turned by rpy -1.57079635 gives 2.7e-9 components);
        // `+ 0.0` prints -0 as 0.
        let short = |x: f64| (x * 1e6).round() / 1e6 + 0.0;
        notes.push(format!(
            "{}: {} is `fixed` in the URDF; [robot] wheels names it, so it \
             is driven as a continuous wheel joint about ({}, {}, {}) ({from})",
            self.origin,
            self.jname(ji),
            short(axis_v.x),
            short(axis_v.y),
            short(axis_v.z)
        ));
        Ok(axis_v)
    }

    /// Each reached link's inertial summed into its body's mass accumulator, its collisions
    /// added to the body's colliders and its visuals to the body's visuals. Returns the
    /// accumulators and the warnings so far (the parser's, then visuals that could not load).
    fn link_contents(
        &self,
        kin: &mut Kinematics,
    ) -> Result<(Vec<MassAcc>, Vec<String>), RobotError> {
        let mut acc = vec![MassAcc::zero(); kin.bodies.len()];
        let mut warnings = self.parsed.warnings.clone();
        for (li, link) in self.robot.links.iter().enumerate() {
            let Some(li_info) = &kin.info[li] else {
                continue;
            };
            let (b, pose) = (li_info.body, li_info.pose_in_body);
            self.add_inertial(link, pose, &mut acc[b])?;
            for col in &link.collision {
                let cpose = pose * iso_from_pose(&col.origin);
                let shape = collision_shape(
                    &col.geometry,
                    &link.name,
                    self.origin,
                    self.base_dir,
                    self.opts,
                )?;
                kin.bodies[b].colliders.push(RobotCollider {
                    link: link.name.clone(),
                    pose_in_body: cpose,
                    shape,
                    is_wheel: false,
                });
            }
            for vis in &link.visual {
                let vpose = pose * iso_from_pose(&vis.origin);
                match visual_mesh(&vis.geometry, &link.name, vpose, self.base_dir, self.opts) {
                    Ok(Some(v)) => kin.bodies[b].visuals.push(v),
                    Ok(None) => {}
                    Err(w) => warnings.push(format!("{}: {w}", self.origin)),
                }
            }
        }
        Ok((acc, warnings))
    }

    /// Adds `link`'s `<inertial>` (the link at `pose` in its body) to `acc`, after checking
    /// that its mass and inertia are finite and non-negative.
    fn add_inertial(
        &self,
        link: &urdf_rs::Link,
        pose: Isometry3<f64>,
        acc: &mut MassAcc,
    ) -> Result<(), RobotError> {
        let inertial = &link.inertial;
        let m = inertial.mass.value;
        if !m.is_finite() || m < 0.0 {
            return Err(self.invalid(format!(
                "link `{}`: <mass value> must be a finite number ≥ 0, got {m}",
                link.name
            )));
        }
        if m > 0.0 {
            let i = &inertial.inertia;
            let vals = [i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz];
            if vals.iter().any(|v| !v.is_finite()) || i.ixx < 0.0 || i.iyy < 0.0 || i.izz < 0.0 {
                return Err(self.invalid(format!(
                    "link `{}`: <inertia> must be finite with ixx, iyy, izz ≥ 0",
                    link.name
                )));
            }
            let i_com = Matrix3::new(
                i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
            );
            let io = pose * iso_from_pose(&inertial.origin);
            acc.add(m, io.translation.vector, &io.rotation, &i_com);
        }
        Ok(())
    }

    /// Each body's mass, centre of mass and inertia from its accumulator; an error for a body
    /// without mass, except a promoted wheel (returned: it gets its mass from its cylinder once
    /// the wheels are known).
    fn body_masses(&self, kin: &mut Kinematics, acc: &[MassAcc]) -> Result<Vec<usize>, RobotError> {
        // A promoted wheel whose links carry no <inertial> (the file fixes them to the chassis
        // and gives them no mass of their own) gets its mass once its wheel cylinder is known.
        let mut massless_wheels: Vec<usize> = Vec::new();
        for (b, a) in acc.iter().enumerate() {
            let (m, c, i) = a.finish();
            if m == 0.0 && kin.promoted_bodies.contains(&b) {
                massless_wheels.push(b);
                continue;
            }
            if m <= 0.0 {
                let joint = match kin.body_joint[b] {
                    Some(ji) => self.robot.joints[ji].name.clone(),
                    None => "root".to_string(),
                };
                return Err(RobotError::NonPositiveMass {
                    origin: self.origin.to_string(),
                    link: kin.bodies[b].name.clone(),
                    joint,
                    mass: m,
                });
            }
            kin.bodies[b].mass = m;
            kin.bodies[b].com = c;
            kin.bodies[b].inertia = i;
        }
        Ok(massless_wheels)
    }

    /// Fixed joints on the chassis shaped like drive wheels (a lateral axis, a wheel-like
    /// collision on the child link), named when no wheel is found.
    fn fixed_wheel_joints(&self, tree: &LinkTree, kin: &Kinematics) -> Vec<String> {
        let robot = self.robot;
        robot
            .joints
            .iter()
            .enumerate()
            .filter(|(ji, j)| {
                let (p, c) = (
                    tree.link_index[j.parent.link.as_str()],
                    tree.link_index[j.child.link.as_str()],
                );
                let Some(parent) = kin.info[p].as_ref().filter(|i| i.body == 0) else {
                    return false;
                };
                let wheel_like = robot.links[c].collision.iter().any(|col| {
                    matches!(
                        col.geometry,
                        urdf_rs::Geometry::Cylinder { .. } | urdf_rs::Geometry::Mesh { .. }
                    )
                });
                let rotation = (parent.pose_in_body * iso_from_pose(&j.origin)).rotation;
                j.joint_type == urdf_rs::JointType::Fixed
                    && wheel_like
                    && promoted_axis(self.parsed, *ji, &robot.links[c])
                        .is_some_and(|(a, _)| (rotation * a.normalize()).y.abs() >= 0.99)
            })
            .map(|(ji, _)| self.jname(ji))
            .collect()
    }

    /// A promoted wheel body without mass of its own gets the mass of its collision cylinder
    /// at [`WHEEL_DENSITY`], with a warning; an error when it has no cylinder.
    fn massless_wheel_masses(
        &self,
        kin: &mut Kinematics,
        massless_wheels: &[usize],
        warnings: &mut Vec<String>,
    ) -> Result<(), RobotError> {
        for &b in massless_wheels {
            let body = &mut kin.bodies[b];
            let cylinder = body.colliders.iter().find_map(|c| match c.shape {
                CollisionShape::Cylinder {
                    radius,
                    half_length,
                } if c.is_wheel => Some((c.pose_in_body, radius, 2.0 * half_length)),
                _ => None,
            });
            let Some((pose, r, width)) = cylinder else {
                return Err(RobotError::NonPositiveMass {
                    origin: self.origin.to_string(),
                    link: body.name.clone(),
                    joint: kin.body_joint[b]
                        .map(|ji| self.robot.joints[ji].name.clone())
                        .unwrap_or_default(),
                    mass: 0.0,
                });
            };
            let m = WHEEL_DENSITY * PI * r * r * width;
            let across = m * (3.0 * r * r + width * width) / 12.0;
            let i_com = Matrix3::from_diagonal(&Vector3::new(across, across, m * r * r / 2.0));
            let mut a = MassAcc::zero();
            a.add(m, pose.translation.vector, &pose.rotation, &i_com);
            let (m, c, i) = a.finish();
            (body.mass, body.com, body.inertia) = (m, c, i);
            warnings.push(format!(
                "{}: wheel link `{}` has no <inertial> (the URDF fixes it to the chassis); \
                 it is given the mass of its collision cylinder (radius {r:.4} m, width {width:.4} m) \
                 at {WHEEL_DENSITY} kg/m³: {m:.4} kg",
                self.origin, body.name
            ));
        }
        Ok(())
    }

    /// The drive limits: the options' override (positive and finite), else from the URDF.
    fn drive_limits(
        &self,
        wheels: &DriveWheels,
    ) -> Result<(DriveLimits, LimitsSource), RobotError> {
        match self.opts.limits {
            Some(l) => {
                let ok = |x: f64| x.is_finite() && x > 0.0;
                if !(ok(l.v_max) && ok(l.omega_max) && ok(l.wheel_speed_max)) {
                    return Err(self.invalid(format!(
                        "drive limits override must be positive and finite, got {l:?}"
                    )));
                }
                Ok((l, LimitsSource::Explicit))
            }
            None => derive_limits(self.parsed, self.origin, wheels),
        }
    }

    /// The footprint: the circumscribed radius of the collision geometry in the plane, and the
    /// middle height of it (from the ground up) and its top; an error when there is no
    /// collision geometry.
    fn footprint(&self, bodies: &[RobotBody]) -> Result<(f64, f64, f64), RobotError> {
        let mut r_max: f64 = 0.0;
        let (mut z_min, mut z_max) = (f64::INFINITY, f64::NEG_INFINITY);
        for body in bodies {
            for c in &body.colliders {
                let to_root = body.pose_in_root * c.pose_in_body;
                for p in c.shape.bounding_points() {
                    let q = to_root * p;
                    r_max = r_max.max(q.x.hypot(q.y));
                    z_min = z_min.min(q.z);
                    z_max = z_max.max(q.z);
                }
            }
        }
        if !z_min.is_finite() {
            return Err(self.structure("the robot has no collision geometry".into()));
        }
        Ok((r_max, 0.5 * (z_min.max(0.0) + z_max), z_max))
    }
}

/// Marks the wheel bodies' colliders as wheels; a wheel measured from its mesh rolls on the
/// cylinder of that extent instead (the mesh's convex hull is a polygon and would roll bumpily).
fn wheel_colliders(bodies: &mut [RobotBody], joints: &[RobotJoint], wheels: &DriveWheels) {
    for w in wheels.all() {
        let axis = joints[w.joint].axis;
        let body = &mut bodies[w.body];
        if wheel_size(body, axis).is_some_and(|s| s.from_mesh) {
            if let Some(m) = mesh_extent(body, axis) {
                let z_to_axis = UnitQuaternion::rotation_between(&Vector3::z(), &axis)
                    .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI));
                let link = body
                    .colliders
                    .iter()
                    .find(|c| matches!(c.shape, CollisionShape::Mesh { .. }))
                    .map(|c| c.link.clone())
                    .unwrap_or_else(|| body.name.clone());
                body.colliders
                    .retain(|c| !matches!(c.shape, CollisionShape::Mesh { .. }));
                body.colliders.push(RobotCollider {
                    link,
                    pose_in_body: Isometry3::from_parts(
                        Translation3::from(axis.into_inner() * m.mid),
                        z_to_axis,
                    ),
                    shape: CollisionShape::Cylinder {
                        radius: m.radius,
                        half_length: m.width / 2.0,
                    },
                    is_wheel: true,
                });
            }
        }
        for c in &mut body.colliders {
            c.is_wheel = true;
        }
    }
}

/// The axis a `fixed` joint named as a drive wheel turns about, and where it came from: the
/// `<axis xyz>` written on it (ROS ignores it on a fixed joint; a file that once had the joint
/// continuous keeps it), else the axis of the child link's first `<cylinder>` collision.
fn promoted_axis(
    parsed: &urdf::Parsed,
    joint: usize,
    child: &urdf_rs::Link,
) -> Option<(Vector3<f64>, String)> {
    if let Some(xyz) = parsed.fixed_axes.get(joint).copied().flatten() {
        let v = Vector3::from(xyz);
        if v.norm() > 1e-9 {
            return Some((
                v,
                "its <axis xyz>, which ROS ignores on a fixed joint".to_string(),
            ));
        }
    }
    child.collision.iter().find_map(|col| {
        matches!(col.geometry, urdf_rs::Geometry::Cylinder { .. }).then(|| {
            (
                iso_from_pose(&col.origin).rotation * Vector3::z(),
                format!("the axis of link `{}`'s <cylinder> collision", child.name),
            )
        })
    })
}

/// The joints met following parent joints up from link `start` until a link repeats, as
/// "joint `a` (line 3) → joint `b` (line 9)" (the cycle itself, in child-to-parent order).
fn joint_cycle(
    start: usize,
    parent_joint: &[Option<usize>],
    robot: &urdf_rs::Robot,
    jname: &dyn Fn(usize) -> String,
) -> String {
    let index = |name: &str| robot.links.iter().position(|l| l.name == name);
    let mut seen: Vec<usize> = Vec::new();
    let mut path: Vec<usize> = Vec::new();
    let mut link = start;
    while !seen.contains(&link) {
        seen.push(link);
        let Some(ji) = parent_joint[link] else {
            break;
        };
        path.push(ji);
        match index(&robot.joints[ji].parent.link) {
            Some(p) => link = p,
            None => break,
        }
    }
    // Keep the part of the path from the first visit of the repeated link.
    let from = seen.iter().position(|&l| l == link).unwrap_or(0);
    path[from.min(path.len())..]
        .iter()
        .map(|&ji| jname(ji))
        .collect::<Vec<_>>()
        .join(" → ")
}

fn collision_shape(
    g: &urdf_rs::Geometry,
    link: &str,
    origin: &str,
    base_dir: Option<&Path>,
    opts: &LoadOptions,
) -> Result<CollisionShape, RobotError> {
    let bad = |what: String| RobotError::InvalidValue {
        origin: origin.to_string(),
        what: format!("link `{link}` collision: {what}"),
    };
    let pos = |x: f64| x.is_finite() && x > 0.0;
    Ok(match g {
        urdf_rs::Geometry::Box { size } => {
            let s = size.0;
            if !s.iter().all(|v| pos(*v)) {
                return Err(bad(format!("<box size> must be positive, got {s:?}")));
            }
            CollisionShape::Box {
                half_extents: [s[0] / 2.0, s[1] / 2.0, s[2] / 2.0],
            }
        }
        urdf_rs::Geometry::Cylinder { radius, length } => {
            if !pos(*radius) || !pos(*length) {
                return Err(bad(format!(
                    "<cylinder radius length> must be positive, got {radius}, {length}"
                )));
            }
            CollisionShape::Cylinder {
                radius: *radius,
                half_length: length / 2.0,
            }
        }
        urdf_rs::Geometry::Capsule { radius, length } => {
            let length_ok = length.is_finite() && *length >= 0.0;
            if !pos(*radius) || !length_ok {
                return Err(bad(format!(
                    "<capsule radius length> must be positive, got {radius}, {length}"
                )));
            }
            CollisionShape::Capsule {
                radius: *radius,
                half_length: length / 2.0,
            }
        }
        urdf_rs::Geometry::Sphere { radius } => {
            if !pos(*radius) {
                return Err(bad(format!(
                    "<sphere radius> must be positive, got {radius}"
                )));
            }
            CollisionShape::Sphere { radius: *radius }
        }
        urdf_rs::Geometry::Mesh { filename, scale } => {
            let scale = scale.map(|s| s.0).unwrap_or([1.0; 3]);
            if !scale.iter().all(|v| v.is_finite() && *v != 0.0) {
                return Err(bad(format!(
                    "mesh scale must be finite and non-zero, got {scale:?}"
                )));
            }
            let mesh_err = |message: String| RobotError::CollisionMesh {
                origin: origin.to_string(),
                link: link.to_string(),
                filename: filename.clone(),
                message,
            };
            let path = resolve_mesh_path(filename, base_dir, &opts.package_paths, &opts.packages)
                .ok_or_else(|| mesh_err(not_found(filename, opts)))?;
            let (vertices, indices) =
                read_mesh(&path).map_err(|m| mesh_err(format!("{}: {m}", path.display())))?;
            let vertices = vertices
                .into_iter()
                .map(|v| [v[0] * scale[0], v[1] * scale[1], v[2] * scale[2]])
                .collect();
            CollisionShape::Mesh { vertices, indices }
        }
    })
}

/// The STL mesh of a `<visual>` (`Ok(None)` for primitives, which the collision shapes already
/// show); a missing or unreadable file is a warning (`Err`), never a load error.
fn visual_mesh(
    g: &urdf_rs::Geometry,
    link: &str,
    pose_in_body: Isometry3<f64>,
    base_dir: Option<&Path>,
    opts: &LoadOptions,
) -> Result<Option<RobotVisual>, String> {
    let urdf_rs::Geometry::Mesh { filename, scale } = g else {
        return Ok(None);
    };
    let what = |m: &str| format!("visual mesh `{filename}` of link `{link}` {m} (ignored)");
    let path = resolve_mesh_path(filename, base_dir, &opts.package_paths, &opts.packages)
        .ok_or_else(|| what("not found"))?;
    let scale = scale.map(|s| s.0).unwrap_or([1.0; 3]);
    if !scale.iter().all(|v| v.is_finite() && *v != 0.0) {
        return Err(what(&format!("has a bad scale {scale:?}")));
    }
    let (vertices, indices) =
        read_mesh(&path).map_err(|m| what(&format!("unreadable ({}: {m})", path.display())))?;
    Ok(Some(RobotVisual {
        link: link.to_string(),
        pose_in_body,
        vertices: vertices
            .into_iter()
            .map(|v| [v[0] * scale[0], v[1] * scale[1], v[2] * scale[2]])
            .collect(),
        indices,
    }))
}

/// Why a mesh file was not found: for `package://NAME/…`, where `NAME` was looked for, and how
/// to map a package whose folder has another name.
fn not_found(filename: &str, opts: &LoadOptions) -> String {
    let Some((pkg, _)) = filename
        .strip_prefix("package://")
        .and_then(|r| r.split_once('/'))
    else {
        return "file not found".to_string();
    };
    if let Some(dir) = opts.packages.get(pkg) {
        return format!(
            "file not found in package `{pkg}`'s folder {} ([robot] packages)",
            dir.display()
        );
    }
    let found = opts
        .package_paths
        .iter()
        .any(|d| d.join(pkg).is_dir() || d.file_name().is_some_and(|n| n == pkg));
    if found {
        format!(
            "file not found in package `{pkg}` (package search path: {:?})",
            opts.package_paths
        )
    } else {
        format!(
            "file not found: no package `{pkg}` in the package search path {:?} (a folder `{pkg}` \
             in one of them, or one of them named `{pkg}`); if the package's folder has another \
             name, map it: \
             [robot] packages = {{ {pkg} = \"path/to/folder\" }}",
            opts.package_paths
        )
    }
}

/// Resolves a mesh filename (`package://`, `file://`, absolute or relative) to an existing file.
/// `package://NAME/rest` is `packages[NAME]/rest` when the map names the package, else the
/// first of `DIR/NAME/rest` and (when `DIR` is itself named `NAME`) `DIR/rest` over
/// `package_paths`.
pub fn resolve_mesh_path(
    filename: &str,
    base_dir: Option<&Path>,
    package_paths: &[PathBuf],
    packages: &BTreeMap<String, PathBuf>,
) -> Option<PathBuf> {
    if let Some(rest) = filename.strip_prefix("package://") {
        let (pkg, rel) = rest.split_once('/')?;
        if let Some(dir) = packages.get(pkg) {
            let cand = dir.join(rel);
            return cand.is_file().then_some(cand);
        }
        for dir in package_paths {
            let cand = dir.join(pkg).join(rel);
            if cand.is_file() {
                return Some(cand);
            }
            if dir.file_name().is_some_and(|n| n == pkg) {
                let cand = dir.join(rel);
                if cand.is_file() {
                    return Some(cand);
                }
            }
        }
        return None;
    }
    let plain = filename.strip_prefix("file://").unwrap_or(filename);
    let p = Path::new(plain);
    let cand = if p.is_absolute() {
        p.to_path_buf()
    } else {
        base_dir
            .map(|d| d.join(p))
            .unwrap_or_else(|| p.to_path_buf())
    };
    cand.is_file().then_some(cand)
}

/// One mesh of a file, placed in the file's frame \[m\].
#[derive(Debug, Clone)]
pub struct MeshPart {
    /// What names it: the mesh's name (a Collada geometry's `id`, else the file's own
    /// name), a Collada geometry's `name` and the names of the nodes that instance it.
    pub names: Vec<String>,
    /// Vertices \[m\], in the file's frame (node transforms and `<unit>` applied).
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as indices into [`Self::vertices`].
    pub triangles: Vec<[u32; 3]>,
}

/// The meshes of a mesh file and what the user should know about how they were read.
#[derive(Debug, Clone, Default)]
pub struct MeshParts {
    /// Every mesh of the file: for Collada, one per instanced geometry (a geometry instanced
    /// by two nodes is two parts; a file without a visual scene gives its geometries as they
    /// are).
    pub parts: Vec<MeshPart>,
    /// Collada's declared `<up_axis>`, when the file declares one.
    pub up_axis: Option<String>,
    /// Non-fatal problems (a Collada `<skew>`, an unresolved `<instance_node>`).
    pub warnings: Vec<String>,
}

/// The meshes of a mesh file, read with `mesh-loader`: STL (ASCII or binary; a binary file
/// whose 80-byte header starts with `solid` is still read as binary), Collada (`.dae`: every
/// instanced geometry placed by its node's composed transform and scaled by the document's
/// `<unit>`, see [`crate::environment::collada`]) or Wavefront OBJ. The format is chosen by the
/// extension, else by the content.
pub fn read_mesh_parts(path: &Path) -> Result<MeshParts, String> {
    // Collada is XML, parsed by a tokenizer that recurses per nesting level: refuse absurd
    // nesting before it can overflow the stack.
    let mut bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
    let mut scene = None;
    if let Ok(text) = std::str::from_utf8(&bytes) {
        if text
            .trim_start_matches('\u{feff}')
            .trim_start()
            .starts_with('<')
        {
            if let Some((line, tag)) = urdf::too_deep(text, MAX_URDF_DEPTH) {
                return Err(format!(
                    "line {line}: <{tag}> is nested more than {MAX_URDF_DEPTH} levels deep; \
                     not a readable Collada mesh"
                ));
            }
            scene = crate::environment::collada::scene(text)
                .map_err(|e| format!("not a readable Collada mesh: {e}"))?;
        }
    }
    if let Some(s) = &scene {
        bytes = s.geometry_text.clone().into_bytes();
    }
    let loaded = mesh_loader::Loader::default()
        .load_from_slice(&bytes, path)
        .map_err(|e| format!("not a readable STL, Collada or OBJ mesh: {e}"))?;
    let mut out = MeshParts::default();
    for mesh in &loaded.meshes {
        if mesh
            .vertices
            .iter()
            .any(|v| !v.iter().all(|c| c.is_finite()))
        {
            return Err("the mesh has non-finite vertices".into());
        }
        let raw: Vec<[f64; 3]> = mesh.vertices.iter().map(|v| v.map(f64::from)).collect();
        let mut triangles = Vec::with_capacity(mesh.faces.len());
        for f in &mesh.faces {
            if f.iter().any(|&i| i as usize >= raw.len()) {
                return Err("the mesh has an out-of-range vertex index".into());
            }
            triangles.push(*f);
        }
        let Some(s) = &scene else {
            out.parts.push(MeshPart {
                names: vec![mesh.name.clone()],
                vertices: raw,
                triangles,
            });
            continue;
        };
        let mut names = vec![mesh.name.clone()];
        names.extend(s.geometry_names.get(&mesh.name).cloned());
        let uses: Vec<_> = s
            .instances
            .iter()
            .filter(|i| i.geometry == mesh.name)
            .collect();
        if uses.is_empty() && s.instances.is_empty() {
            let vertices = raw.iter().map(|v| v.map(|c| c * s.unit)).collect();
            out.parts.push(MeshPart {
                names: names.clone(),
                vertices,
                triangles: triangles.clone(),
            });
        }
        for inst in uses {
            let vertices = raw
                .iter()
                .map(|v| {
                    let p = inst.transform.transform_point(&Point3::from(*v)) * s.unit;
                    [p.x, p.y, p.z]
                })
                .collect();
            let mut names = names.clone();
            names.extend(inst.nodes.iter().filter(|n| !n.is_empty()).cloned());
            out.parts.push(MeshPart {
                names,
                vertices,
                triangles: triangles.clone(),
            });
        }
    }
    if let Some(s) = scene {
        out.up_axis = s.up_axis;
        out.warnings = s.warnings;
    }
    Ok(out)
}

/// Vertices and triangles of a mesh file ([`read_mesh_parts`]): all meshes of the file joined
/// into one, and vertices with identical coordinates (as f32) welded in order of first
/// appearance, so an STL's triangle soup becomes an indexed mesh.
#[allow(clippy::type_complexity)]
pub fn read_mesh(path: &Path) -> Result<(Vec<[f64; 3]>, Vec<[u32; 3]>), String> {
    join_parts(&read_mesh_parts(path)?.parts)
}

/// The parts joined into one mesh, vertices welded (see [`read_mesh`]).
#[allow(clippy::type_complexity)]
pub fn join_parts(parts: &[MeshPart]) -> Result<(Vec<[f64; 3]>, Vec<[u32; 3]>), String> {
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    let mut indices: Vec<[u32; 3]> = Vec::new();
    let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
    for part in parts {
        let mut local = Vec::with_capacity(part.vertices.len());
        for v in &part.vertices {
            let next = u32::try_from(vertices.len())
                .map_err(|_| "the mesh has more than 2³² vertices".to_string())?;
            let id = *weld
                .entry(v.map(|c| (c as f32).to_bits()))
                .or_insert_with(|| {
                    vertices.push(*v);
                    next
                });
            local.push(id);
        }
        for t in &part.triangles {
            indices.push(t.map(|i| local[i as usize]));
        }
    }
    if indices.is_empty() {
        return Err("the mesh has no triangles".into());
    }
    Ok((vertices, indices))
}

/// Size of a wheel body about its joint axis.
#[derive(Debug, Clone, Copy)]
struct WheelSize {
    radius: f64,
    from_mesh: bool,
}

/// Extent of a body's collision meshes about an axis through the body origin.
#[derive(Debug, Clone, Copy)]
struct MeshExtent {
    /// Largest distance of a vertex from the axis \[m\].
    radius: f64,
    /// Extent along the axis \[m\].
    width: f64,
    /// Middle of that extent, along the axis \[m\].
    mid: f64,
}

/// The extent of every collision mesh of `body` about `axis` (body frame; for a wheel body the
/// body frame is the joint frame, so the axis passes through its origin).
fn mesh_extent(body: &RobotBody, axis: Unit<Vector3<f64>>) -> Option<MeshExtent> {
    let (mut r2, mut lo, mut hi) = (0.0f64, f64::INFINITY, f64::NEG_INFINITY);
    for c in &body.colliders {
        let CollisionShape::Mesh { vertices, .. } = &c.shape else {
            continue;
        };
        for v in vertices {
            let p = c.pose_in_body * Point3::new(v[0], v[1], v[2]);
            let a = p.coords.dot(&axis);
            r2 = r2.max((p.coords - axis.into_inner() * a).norm_squared());
            lo = lo.min(a);
            hi = hi.max(a);
        }
    }
    (lo <= hi && r2 > 0.0).then(|| MeshExtent {
        radius: r2.sqrt(),
        width: hi - lo,
        mid: 0.5 * (lo + hi),
    })
}

/// A wheel's radius: its `<cylinder>` collision's, else the extent of its collision meshes
/// about the joint axis.
fn wheel_size(body: &RobotBody, axis: Unit<Vector3<f64>>) -> Option<WheelSize> {
    if let Some(radius) = body.colliders.iter().find_map(|c| match c.shape {
        CollisionShape::Cylinder { radius, .. } => Some(radius),
        _ => None,
    }) {
        return Some(WheelSize {
            radius,
            from_mesh: false,
        });
    }
    let m = mesh_extent(body, axis)?;
    (m.width > 0.0).then_some(WheelSize {
        radius: m.radius,
        from_mesh: true,
    })
}

/// Density [kg/m³] that gives a promoted wheel without `<inertial>` its mass from its
/// collision cylinder: water's, the default MuJoCo uses to infer inertia from geometry.
const WHEEL_DENSITY: f64 = 1000.0;

/// Distance from the root frame's x axis below which a wheel cannot be assigned to a side \[m\].
const CENTRE_LINE_TOLERANCE: f64 = 1e-3;

/// One candidate drive wheel, measured in the root frame.
#[derive(Debug, Clone, Copy)]
struct WheelCandidate {
    joint: usize,
    radius: f64,
    from_mesh: bool,
    position: Vector3<f64>,
    forward_sign: f64,
    effort: Option<f64>,
}

/// The drive wheels, in phases: the candidate joints (those `[robot] wheels` names, else the
/// wheel-like continuous joints on the chassis), each measured in the root frame, split into
/// left and right, and checked for equal radii and a separation.
fn find_wheels(
    robot: &urdf_rs::Robot,
    origin: &str,
    bodies: &[RobotBody],
    joints: &[RobotJoint],
    joint_of_urdf: &HashMap<usize, usize>,
    fixed_wheels: &[String],
    opts: &LoadOptions,
) -> Result<DriveWheels, RobotError> {
    let search = WheelSearch {
        robot,
        origin,
        bodies,
        joints,
    };
    let werr = |message: String| search.error(message);
    let candidates = search.candidates(joint_of_urdf, fixed_wheels, opts)?;
    let wheels = candidates
        .iter()
        .map(|&k| search.measure(k))
        .collect::<Result<Vec<_>, _>>()?;
    let (left, right) = match &opts.wheel_joints {
        // Named: the caller says which is which; it must agree with the geometry.
        Some(_) => {
            let (a, b) = (wheels[0], wheels[1]);
            if a.position.y <= b.position.y {
                return Err(werr(format!(
                    "the left wheel joint `{}` is not on the +y side of the right one `{}`",
                    joints[a.joint].name, joints[b.joint].name
                )));
            }
            (vec![a], vec![b])
        }
        None => group_sides(&wheels, joints, &werr)?,
    };
    search.check_radii(&wheels)?;
    let separation = search.separation(&left, &right)?;
    let radius = wheels.iter().map(|w| w.radius).sum::<f64>() / wheels.len() as f64;
    let mk = |w: &WheelCandidate| Wheel {
        joint_name: joints[w.joint].name.clone(),
        joint: w.joint,
        body: joints[w.joint].child,
        forward_sign: w.forward_sign,
        effort_limit: w.effort,
    };
    Ok(DriveWheels {
        left: left.iter().map(mk).collect(),
        right: right.iter().map(mk).collect(),
        geometry: WheelGeometry { radius, separation },
    })
}

/// What [`find_wheels`] measures: the robot's bodies and joints, and the file for messages.
struct WheelSearch<'a> {
    robot: &'a urdf_rs::Robot,
    origin: &'a str,
    bodies: &'a [RobotBody],
    joints: &'a [RobotJoint],
}

impl WheelSearch<'_> {
    fn error(&self, message: String) -> RobotError {
        RobotError::Wheels {
            origin: self.origin.to_string(),
            message,
        }
    }

    /// The wheel size of joint `k`'s child body, from its collision geometry.
    fn size(&self, k: usize) -> Option<WheelSize> {
        wheel_size(&self.bodies[self.joints[k].child], self.joints[k].axis)
    }

    /// Joint `k`'s frame in the root frame.
    fn frame_in_root(&self, k: usize) -> Isometry3<f64> {
        let j = &self.joints[k];
        self.bodies[j.parent].pose_in_root * j.frame_in_parent
    }

    /// The joints as "`a`, `b`", for messages.
    fn names(&self, ks: &mut dyn Iterator<Item = usize>) -> String {
        ks.map(|k| format!("`{}`", self.joints[k].name))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The candidate wheel joints (indices into the joints): the two `[robot] wheels` names,
    /// else every continuous joint on the chassis with a lateral axis and a wheel-like
    /// collision. An error when fewer than two are found, naming fixed joints that look like
    /// wheels.
    fn candidates(
        &self,
        joint_of_urdf: &HashMap<usize, usize>,
        fixed_wheels: &[String],
        opts: &LoadOptions,
    ) -> Result<Vec<usize>, RobotError> {
        // Lateral in the root frame: a drive wheel's axle, not a swivel's vertical axis.
        let lateral = |k: usize| {
            (self.frame_in_root(k).rotation * self.joints[k].axis.into_inner())
                .y
                .abs()
                >= 0.99
        };
        let candidates: Vec<usize> = match &opts.wheel_joints {
            Some((l, r)) => {
                let mut v = Vec::new();
                for name in [l, r] {
                    let ji = self
                        .robot
                        .joints
                        .iter()
                        .position(|j| &j.name == name)
                        .ok_or_else(|| self.error(format!("no joint named `{name}`")))?;
                    let k = *joint_of_urdf.get(&ji).ok_or_else(|| {
                        self.error(format!("joint `{name}` is not a joint a wheel can turn on"))
                    })?;
                    v.push(k);
                }
                v
            }
            // Continuous joints on the chassis (the root body) with a lateral axis and a
            // cylinder or mesh collision; a caster's wheel hangs from its swivel, not from the
            // chassis.
            None => self
                .joints
                .iter()
                .enumerate()
                .filter(|&(k, j)| {
                    matches!(j.kind, JointKind::Continuous)
                        && j.parent == 0
                        && lateral(k)
                        && self.size(k).is_some()
                })
                .map(|(k, _)| k)
                .collect(),
        };
        if candidates.len() < 2 {
            let fixed = if fixed_wheels.is_empty() {
                String::new()
            } else {
                format!(
                    "; the URDF fixes {} to the chassis, shaped like wheels (a display model \
                     describes its drive wheels so): name two of them in [robot] wheels to drive \
                     them as continuous joints",
                    fixed_wheels.join(", ")
                )
            };
            return Err(self.error(format!(
                "expected 2 (differential drive) or 4 or more (skid steer) continuous joints on the \
                 chassis with a lateral axis whose child link has a <cylinder> or <mesh> collision, \
                 found {} [{}]; name the wheel joints explicitly if the URDF has others{fixed}",
                candidates.len(),
                self.names(&mut candidates.iter().copied())
            )));
        }
        Ok(candidates)
    }

    /// Candidate joint `k` measured in the root frame: its radius, position, which way it turns
    /// forward and its effort limit. An error for a prismatic joint, a wheel without a
    /// cylinder or mesh collision, or an axis that is not lateral.
    fn measure(&self, k: usize) -> Result<WheelCandidate, RobotError> {
        let j = &self.joints[k];
        if matches!(j.kind, JointKind::Prismatic { .. }) {
            return Err(self.error(format!("joint `{}` is prismatic", j.name)));
        }
        let WheelSize { radius, from_mesh } = self.size(k).ok_or_else(|| {
            self.error(format!(
                "wheel link of joint `{}` has no <cylinder> or <mesh> collision to read the \
                 radius from{}",
                j.name,
                wheel_above(self.robot, &j.name)
            ))
        })?;
        let frame_root = self.frame_in_root(k);
        let axis_root = frame_root.rotation * j.axis.into_inner();
        if axis_root.y.abs() < 0.99 {
            return Err(self.error(format!(
                "joint `{}`: the wheel axis in the root frame is {:?}, not lateral (±y)",
                j.name,
                axis_root.as_slice()
            )));
        }
        let urdf_j = self.robot.joints.iter().find(|u| u.name == j.name);
        let effort = urdf_j
            .map(|u| u.limit.effort)
            .filter(|e| e.is_finite() && *e > 0.0);
        Ok(WheelCandidate {
            joint: k,
            radius,
            from_mesh,
            position: frame_root.translation.vector,
            forward_sign: axis_root.y.signum(),
            effort,
        })
    }

    /// The wheels' radii agree: cylinders within 0.1 mm, a radius measured from a mesh within
    /// 1 % (a mesh is a polygon, and left and right meshes are often exported separately).
    fn check_radii(&self, wheels: &[WheelCandidate]) -> Result<(), RobotError> {
        let tolerance = if wheels.iter().any(|w| w.from_mesh) {
            (0.01 * wheels[0].radius).max(1e-4)
        } else {
            1e-4
        };
        match wheels
            .iter()
            .find(|w| (w.radius - wheels[0].radius).abs() > tolerance)
        {
            Some(w) => Err(self.error(format!(
                "the wheels have different radii (`{}` {} m, `{}` {} m)",
                self.joints[wheels[0].joint].name,
                wheels[0].radius,
                self.joints[w.joint].name,
                w.radius
            ))),
            None => Ok(()),
        }
    }

    /// The distance in the plane between the left and right wheels (between the sides'
    /// centroids for a skid steer); an error when it is zero.
    fn separation(
        &self,
        left: &[WheelCandidate],
        right: &[WheelCandidate],
    ) -> Result<f64, RobotError> {
        let centroid = |side: &[WheelCandidate]| {
            side.iter().map(|w| w.position).sum::<Vector3<f64>>() / side.len() as f64
        };
        let separation = if left.len() == 1 {
            (left[0].position.xy() - right[0].position.xy()).norm()
        } else {
            (centroid(left).xy() - centroid(right).xy()).norm()
        };
        if separation <= 0.0 || !separation.is_finite() {
            return Err(self.error(format!(
                "the wheel joints {} and {} are at the same place",
                self.names(&mut left.iter().map(|w| w.joint)),
                self.names(&mut right.iter().map(|w| w.joint))
            )));
        }
        Ok(separation)
    }
}

/// When joint `name`'s parent link is wheel-shaped (a `<cylinder>` or `<mesh>` collision) and is
/// itself fixed by another joint, "; its parent link … : name that joint instead" (Adept's
/// Pioneer 3-DX fixes the tyre `left_wheel` to the hub `left_hub`, which holds the collision, and
/// the hub to the chassis).
fn wheel_above(robot: &urdf_rs::Robot, name: &str) -> String {
    let Some(j) = robot.joints.iter().find(|u| u.name == name) else {
        return String::new();
    };
    let wheel_like = robot
        .links
        .iter()
        .find(|l| l.name == j.parent.link)
        .is_some_and(|l| {
            l.collision.iter().any(|c| {
                matches!(
                    c.geometry,
                    urdf_rs::Geometry::Cylinder { .. } | urdf_rs::Geometry::Mesh { .. }
                )
            })
        });
    let above = robot
        .joints
        .iter()
        .find(|u| u.child.link == j.parent.link && u.joint_type == urdf_rs::JointType::Fixed);
    match above {
        Some(u) if wheel_like => format!(
            "; its parent link `{}` has one and is fixed by joint `{}`: name that joint instead",
            j.parent.link, u.name
        ),
        _ => String::new(),
    }
}

/// Splits automatically found wheels into (left, right) by the side of the root frame's x axis
/// their joint origins lie on, each side sorted front to back. Errors name the joints.
#[allow(clippy::type_complexity)]
fn group_sides(
    wheels: &[WheelCandidate],
    joints: &[RobotJoint],
    werr: &dyn Fn(String) -> RobotError,
) -> Result<(Vec<WheelCandidate>, Vec<WheelCandidate>), RobotError> {
    let describe = |side: &[WheelCandidate]| {
        side.iter()
            .map(|w| format!("`{}` (y = {:+.4} m)", joints[w.joint].name, w.position.y))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let centre: Vec<WheelCandidate> = wheels
        .iter()
        .copied()
        .filter(|w| w.position.y.abs() < CENTRE_LINE_TOLERANCE)
        .collect();
    if !centre.is_empty() {
        return Err(werr(format!(
            "ambiguous wheel layout: {} on the robot's centre line (|y| < {} m), so neither \
             left nor right; name the two drive wheel joints explicitly",
            describe(&centre),
            CENTRE_LINE_TOLERANCE
        )));
    }
    let front_to_back = |mut v: Vec<WheelCandidate>| {
        v.sort_by(|a, b| b.position.x.total_cmp(&a.position.x));
        v
    };
    let left = front_to_back(
        wheels
            .iter()
            .copied()
            .filter(|w| w.position.y > 0.0)
            .collect(),
    );
    let right = front_to_back(
        wheels
            .iter()
            .copied()
            .filter(|w| w.position.y < 0.0)
            .collect(),
    );
    if left.len() != right.len() || left.is_empty() {
        return Err(werr(format!(
            "odd wheel layout: {} wheel(s) on the left [{}] and {} on the right [{}]; a \
             differential drive needs one wheel per side and a skid-steer robot the same number \
             on each side; name the two drive wheel joints explicitly if the others are passive",
            left.len(),
            describe(&left),
            right.len(),
            describe(&right)
        )));
    }
    Ok((left, right))
}

/// Limits from the wheel joints' `<limit velocity>`; when a wheel joint has none, the maker's
/// published limits for a robot of this name ([`MAKER_LIMITS`]); else an error naming the joint
/// and its line.
fn derive_limits(
    parsed: &urdf::Parsed,
    origin: &str,
    wheels: &DriveWheels,
) -> Result<(DriveLimits, LimitsSource), RobotError> {
    let robot = &parsed.robot;
    let g = wheels.geometry;
    let mut w_max = f64::INFINITY;
    for w in wheels.all() {
        let ji = robot.joints.iter().position(|j| j.name == w.joint_name);
        let v = ji.map(|k| robot.joints[k].limit.velocity).unwrap_or(0.0);
        if !(v.is_finite() && v > 0.0) {
            if let Some(m) = MAKER_LIMITS.iter().find(|m| m.robot_name == robot.name) {
                let limits = DriveLimits {
                    v_max: m.v_max,
                    omega_max: m.omega_max,
                    wheel_speed_max: m.v_max / g.radius,
                };
                return Ok((limits, LimitsSource::Maker(m)));
            }
            let line = ji
                .map(|k| format!(" (line {})", parsed.joint_lines[k]))
                .unwrap_or_default();
            return Err(RobotError::InvalidValue {
                origin: origin.to_string(),
                what: format!(
                    "wheel joint `{}`{line} has no <limit velocity> (rad/s) to derive the drive \
                     limits from, and robot `{}` is none of those with published limits ({}); \
                     add one or give [robot] limits in the world",
                    w.joint_name,
                    robot.name,
                    MAKER_LIMITS
                        .iter()
                        .map(|m| m.robot_name)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            });
        }
        w_max = w_max.min(v);
    }
    Ok((
        DriveLimits {
            v_max: g.radius * w_max,
            omega_max: 2.0 * g.radius * w_max / g.separation,
            wheel_speed_max: w_max,
        },
        LimitsSource::WheelJoints,
    ))
}

//! Obstacles: world-file specs (serde) → validated parry shapes with a world pose, which the
//! physics inserts as fixed rapier colliders, and → barrier functions for the controller.
//!
//! World-file conventions (TOML):
//! ```toml
//! [[obstacles]]
//! name = "pillar"
//! position = [1.0, 0.5, 0.0]   # m, world frame (default [0, 0, 0])
//! rpy = [0.0, 0.0, 0.3]        # rad, roll-pitch-yaw of the obstacle frame (default 0)
//! shape = { kind = "cylinder", radius = 0.1, half_height = 0.3 }
//! ```
//! - `cylinder`, `capsule` and `cone` stand along the obstacle frame's **z** axis (centred on
//!   `position`; a cone's apex is at +z); parry's shapes stand along y and are rotated here.
//! - `half_space { normal }`: the solid fills everything *behind* the plane through `position`
//!   with outward `normal` (obstacle frame); the normal points into free space.
//! - `convex_hull { points }`, `tri_mesh { vertices, indices }` are in the obstacle frame;
//!   `tri_mesh { file = "x.stl", scale = 1.0 }` reads a mesh file — STL, Collada `.dae` or OBJ,
//!   see [`crate::robot::read_mesh`] — relative to the world file's directory. A closed mesh
//!   (every edge on two triangles) has an inside (signed distance) whatever the winding of its
//!   triangles: [`orient_mesh`] winds them outward before parry computes its pseudo-normals (an
//!   inward-wound file once put the robot "inside" a box 0.6 m away). An open mesh is a surface:
//!   its distance is never negative, and [`Obstacle::note`] says so, naming it.
//!
//! # Barriers
//! Over the planar state x = (p_x, p_y, v_x, v_y), with the robot a disc of radius r (its
//! footprint radius) centred on p at the height z_c of its geometry:
//! d(p) = sd((p, z_c)) − r, where sd is the signed distance from the point to the solid
//! shape (parry point projection; negative inside), and
//! H(x) = d(p) − margin + k·∇d(p)·v           (a first-order velocity lift, gain k \[s\]).
//! ∇H = (∇d + k∇²d·v, k∇d); ∇²H = [[∇²d + k·D(∇²d·v), k∇²d], [k∇²d, 0]].
//!
//! **What this lift is, and is not.** H = k·(ḣ₀ + h₀/k) with h₀ = d − margin and ḣ₀ = ∇d·v is
//! the high-order (exponential) CBF of a relative-degree-2 constraint with the linear class-K
//! function h₀/k. It is *not* the construction of §4.2.1 (`h₁ = ∂h₀/∂x F x + ½tr(σᵀ∇²h₀σ)
//! − γ‖∂h₀ K c‖ + h₀`): there is no Itô term and no robust term inside the lift, and the
//! velocity term has gain k instead of 1 (the paper's h₁ is H/k with k = 1 plus those two
//! terms; the robust and Itô terms of eq. 4.3 still enter each Ω row built on H). For
//! half-planes the controller crate has the paper's lift
//! ([`ftcbf_controller::barrier::HigherOrderHalfPlane`]); the position-space obstacles here
//! are not half-planes, so it does not apply to them. What H ≥ 0 gives: if H(x_t) ≥ 0 for
//! all t and h₀(p₀) ≥ 0, then ḣ₀ ≥ −h₀/k, so h₀(p_t) ≥ h₀(p₀)e^{−t/k} ≥ 0 — exactly so when
//! the position has no diffusion (ṗ = v) and d is C¹ along the path; with process noise on
//! the position (the controller's Q = q·I) it holds up to that noise's Itô term.
//!
//! **When the h̄_γ bound holds.** h̄(γ) = γ·L bounds H(x) − H(x⁰) for ‖x − x⁰‖ ≤ γ when
//! ‖∇H‖ ≤ L on the segment [x⁰, x]; with ‖∇d‖ ≤ 1 and ‖∇²d‖ ≤ κ that needs (a) speeds
//! ≤ v_max on the segment (the robot's limit, from the URDF or `[robot] limits`; `[linear]
//! v_max` for the linear plant — an estimate within γ of the truth may exceed it by γ, which
//! the bound does not add) and (b) the curvature bound κ of
//! [`ObstacleBarrier::curvature_bound`] valid on the segment: for a robot disc, the centre at
//! least r from a convex obstacle (the disc clear of it); for a point robot, round shapes
//! only, the point outside the shape. Near H = 0 a fast approach can put the disc in contact
//! (d = margin − k∇d·v < 0); there (b) does not hold for edges and vertices and the bound is
//! not proven. No bound is invented where none exists: a point robot with a lifted barrier
//! on a shape with edges is refused (`obstacles[i].shape`).
//! - Closed forms: half-space (∇d = n_xy, ∇²d = 0, so H is the controller's half-plane
//!   h = aᵀx − b with a = (n_xy, k·n_xy)); round obstacles — ball, vertical cylinder at
//!   heights within its length, vertical capsule — where sd = √(|p − c|² + δz²) − R.
//! - Otherwise ∇d is parry's projection direction and ∇²d, D(∇²d·v) are central differences
//!   with step [`BarrierConfig::fd_step`] (default 2 mm: f32 projections are accurate to
//!   ~1e-6 m, giving curvature errors ~1e-3 1/m). The derivatives are exact where d is
//!   smooth (faces, edges, vertices away from Voronoi-region boundaries).
//! - h̄(γ) = γ·L with L = √((1 + k·v_max·κ)² + k²) an upper bound of ‖∇H‖ near H = 0 under
//!   the conditions above: |∇d| ≤ 1 and ‖∇²d‖ ≤ κ (distance to a convex set has curvature
//!   ≤ 1/distance). κ = 0 for half-spaces, so h̄ = γ·‖a‖, the controller's closed form. For
//!   non-convex meshes L is not a proven bound.
//!
//! One file (about 1,300 lines): every shape kind appears in each of its parts — the spec, the
//! parry shape with its pose, the mesh orientation and the barrier ([`ObstacleBarrier`]) — and
//! is added to all of them together. Those four are the seams to split along; moving obstacles
//! (issue #51) change the spec and the barrier, so the split waits for them.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use ftcbf_controller::{Barrier, BarrierEval, State, StateMatrix};
use nalgebra::{Isometry3, Matrix2, Translation3, UnitQuaternion, Vector2, Vector3};
use parry3d::math::{Pose, Vector};
use parry3d::shape::{SharedShape, TriMeshFlags};
use serde::{Deserialize, Serialize};

use crate::environment::outline::{outlines, Outline, DEFAULT_TOLERANCE_CELLS};
use crate::environment::{MapField, OccupancyGrid};
use crate::robot::RobotDescription;

/// Errors of obstacle validation; each names the obstacle and the key.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ObstacleError {
    /// A value is out of range.
    #[error("obstacle `{name}`: `{key}` must be {expected}, got {got}")]
    Invalid {
        /// Obstacle name.
        name: String,
        /// The offending key.
        key: String,
        /// What is expected.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A convex hull that does not enclose a volume.
    #[error(
        "obstacle `{name}`: convex_hull `points` are degenerate ({count} points): need at least \
         4 points that are not all on one plane"
    )]
    DegenerateHull {
        /// Obstacle name.
        name: String,
        /// Number of points given.
        count: usize,
    },
    /// A triangle mesh that cannot be built or read.
    #[error("obstacle `{name}`: tri_mesh: {message}")]
    Mesh {
        /// Obstacle name.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// An occupancy map that cannot be read.
    #[error(transparent)]
    Map(#[from] crate::environment::MapError),
    /// An occupancy map with no blocked cell.
    #[error(
        "{file}: no cell is an obstacle (with environment.unknown = \"free\" only occupied \
         cells are): the map has nothing to avoid"
    )]
    EmptyMap {
        /// The map's YAML file.
        file: String,
    },
}

/// One obstacle as written in a world file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSpec {
    /// Name used in logs, collision reports and barrier names.
    pub name: String,
    /// Position of the obstacle frame, world frame \[m\].
    #[serde(default)]
    pub position: [f64; 3],
    /// Roll, pitch, yaw of the obstacle frame \[rad\].
    #[serde(default)]
    pub rpy: [f64; 3],
    /// The shape in the obstacle frame.
    pub shape: ShapeSpec,
    /// How the obstacle moves (issue #51); absent: it stands still.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<MotionSpec>,
}

/// What `[repeat]` a waypoint path does after its last point (`motion.repeat`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RepeatSpec {
    /// Back to the obstacle's own position and round again (default).
    #[default]
    Loop,
    /// Back along the same points, and forth again.
    Reverse,
    /// Stop at the last point.
    Once,
}

crate::spec::tagged::kind_tagged! {
/// How an obstacle moves, in the world's x–y plane (it keeps its height and orientation).
/// See [`crate::movers`].
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum MotionSpec via MotionByKind {
    /// Along `points` (after the obstacle's own position) at `speed`.
    Waypoints {
        /// Points to move through, world frame \[m\].
        points: Vec<[f64; 2]>,
        /// Speed along the path \[m/s\].
        speed: f64,
        /// After the last point: `loop` (default), `reverse` or `once`.
        #[serde(default)]
        repeat: RepeatSpec,
        /// Time the motion starts \[s\] (default 0).
        #[serde(default)]
        start: f64,
    },
    /// At a constant velocity from the obstacle's own position.
    Velocity {
        /// \[m/s\], world frame.
        velocity: [f64; 2],
    },
    /// A walker (social force, [`crate::movers::Walker`]) heading for `goals` in turn.
    Walker {
        /// Goals, world frame \[m\].
        goals: Vec<[f64; 2]>,
        /// Desired speed \[m/s\] (each trial draws the walker's own within ±20 %).
        speed: f64,
    },
}
}

crate::spec::tagged::kind_tagged! {
/// Obstacle shapes. Cylinders, capsules and cones stand along the obstacle frame's z axis.
/// Written as a table tagged by `kind`, read through `spec::tagged` so that an error names
/// the key inside the table.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec via ShapeByKind {
    /// Box.
    Cuboid {
        /// Half extents along x, y, z \[m\].
        half_extents: [f64; 3],
    },
    /// Sphere.
    Ball {
        /// \[m\]
        radius: f64,
    },
    /// Cylinder along z.
    Cylinder {
        /// \[m\]
        radius: f64,
        /// Half of the height \[m\].
        half_height: f64,
    },
    /// Capsule along z (`half_height` of the cylindrical part).
    Capsule {
        /// \[m\]
        radius: f64,
        /// \[m\]
        half_height: f64,
    },
    /// Cone along z, apex at +half_height.
    Cone {
        /// Base radius \[m\].
        radius: f64,
        /// \[m\]
        half_height: f64,
    },
    /// Convex hull of points (obstacle frame) \[m\].
    ConvexHull {
        /// At least 4 non-coplanar points.
        points: Vec<[f64; 3]>,
    },
    /// Solid half-space behind the plane through `position` with outward `normal`.
    HalfSpace {
        /// Outward normal (obstacle frame), any non-zero length.
        normal: [f64; 3],
    },
    /// An occupancy map (`environment.map`): built by the world loader from the map's files,
    /// never written in `[[obstacles]]`.
    #[serde(skip_deserializing)]
    OccupancyMap {
        /// map_server's YAML file, relative to the world file's directory.
        file: PathBuf,
        /// Whether unknown cells are obstacles.
        unknown: crate::environment::UnknownCells,
    },
    /// Triangle mesh given inline or as an STL file.
    TriMesh {
        /// Vertices (obstacle frame) \[m\].
        #[serde(default)]
        vertices: Vec<[f64; 3]>,
        /// Triangles as vertex indices.
        #[serde(default)]
        indices: Vec<[u32; 3]>,
        /// STL file (instead of vertices/indices), relative to the world file's directory.
        #[serde(default)]
        file: Option<PathBuf>,
        /// Scale applied to the file's vertices (default 1): one factor, or one per axis
        /// `[sx, sy, sz]` as SDF's `<mesh><scale>` writes it.
        #[serde(default)]
        scale: Option<MeshScale>,
    },
}
}

/// A mesh file's scale: one factor for every axis, or one per axis (`[sx, sy, sz]`, obstacle
/// frame; a negative factor mirrors the mesh, as SDF allows).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(untagged)]
pub enum MeshScale {
    /// The same factor on x, y and z.
    Uniform(f64),
    /// Factors on x, y and z.
    PerAxis([f64; 3]),
}

impl MeshScale {
    /// The factors on x, y and z.
    pub fn factors(self) -> [f64; 3] {
        match self {
            MeshScale::Uniform(s) => [s; 3],
            MeshScale::PerAxis(s) => s,
        }
    }
}

impl<'de> Deserialize<'de> for MeshScale {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            One(f64),
            Three(Vec<f64>),
        }
        let expected = "expected a number or three numbers [sx, sy, sz]";
        match Raw::deserialize(d).map_err(|_| serde::de::Error::custom(expected))? {
            Raw::One(s) => Ok(MeshScale::Uniform(s)),
            Raw::Three(v) => <[f64; 3]>::try_from(v.as_slice())
                .map(MeshScale::PerAxis)
                .map_err(|_| {
                    serde::de::Error::custom(format!("{expected}, found {} numbers", v.len()))
                }),
        }
    }
}

impl ShapeSpec {
    /// The `kind` tag as written in a world file.
    pub fn kind(&self) -> &'static str {
        match self {
            ShapeSpec::Cuboid { .. } => "cuboid",
            ShapeSpec::Ball { .. } => "ball",
            ShapeSpec::Cylinder { .. } => "cylinder",
            ShapeSpec::Capsule { .. } => "capsule",
            ShapeSpec::Cone { .. } => "cone",
            ShapeSpec::ConvexHull { .. } => "convex_hull",
            ShapeSpec::HalfSpace { .. } => "half_space",
            ShapeSpec::TriMesh { .. } => "tri_mesh",
            ShapeSpec::OccupancyMap { .. } => "occupancy_map",
        }
    }
}

/// Closed-form geometry used by the barriers where it exists.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Closed {
    /// Solid behind the plane {x : n·(x − p0) = 0}, |n| = 1 (world frame).
    HalfSpace { n: Vector3<f64>, p0: Vector3<f64> },
    /// Points within `radius` of the vertical segment (x, y) = c, z ∈ [z_lo, z_hi]
    /// (ball: z_lo = z_hi; capsule).
    RoundSegment {
        c: Vector2<f64>,
        z_lo: f64,
        z_hi: f64,
        radius: f64,
    },
    /// A vertical cylinder: round only at heights within [z_lo, z_hi].
    VerticalCylinder {
        c: Vector2<f64>,
        z_lo: f64,
        z_hi: f64,
        radius: f64,
    },
}

/// A validated obstacle: a parry shape with its world pose.
#[derive(Debug, Clone)]
pub struct Obstacle {
    /// Name from the spec.
    pub name: String,
    /// The spec it was built from.
    pub spec: ObstacleSpec,
    shape: SharedShape,
    /// Pose of the parry shape in the world (includes the z→y axis change of round shapes).
    shape_pose: Pose,
    closed: Option<Closed>,
    /// What the user should know about the shape: a `tri_mesh` that is not closed is a surface
    /// (unsigned distance), named here with why.
    pub note: Option<String>,
    /// An occupancy map's distance field (its signed distance comes from here, not parry).
    grid: Option<Arc<MapField>>,
    /// An occupancy map's barrier pieces ([`crate::environment::outline`]): the controller
    /// gets one row per piece, not one on the field.
    outlines: Arc<[Outline]>,
}

fn iso(position: [f64; 3], rpy: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(position[0], position[1], position[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}

/// nalgebra f64 isometry → parry pose (f32).
pub(crate) fn to_pose(i: &Isometry3<f64>) -> Pose {
    Pose::from(i.cast::<f32>())
}

fn v3(p: [f64; 3]) -> Vector {
    Vector::new(p[0] as f32, p[1] as f32, p[2] as f32)
}

/// Obstacle `name`'s `key` is not what was `expected`.
fn invalid(name: &str, key: &str, expected: &str, got: String) -> ObstacleError {
    ObstacleError::Invalid {
        name: name.to_string(),
        key: key.to_string(),
        expected: expected.to_string(),
        got,
    }
}

/// `shape.KEY` of obstacle `name` is a positive finite length.
fn positive(name: &str, key: &str, v: f64) -> Result<(), ObstacleError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            name,
            &format!("shape.{key}"),
            "a positive finite number [m]",
            format!("{v}"),
        ))
    }
}

/// `shape.KEY` of obstacle `name` is a finite length ≥ 0.
fn nonneg(name: &str, key: &str, v: f64) -> Result<(), ObstacleError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(
            name,
            &format!("shape.{key}"),
            "a finite number ≥ 0 [m]",
            format!("{v}"),
        ))
    }
}

/// The spec's name is not blank and its position and orientation are finite.
fn check_placement(spec: &ObstacleSpec) -> Result<(), ObstacleError> {
    let name = &spec.name;
    if spec.name.trim().is_empty() {
        return Err(invalid(
            name,
            "name",
            "a non-empty string",
            format!("{:?}", spec.name),
        ));
    }
    if !spec.position.iter().all(|v| v.is_finite()) {
        return Err(invalid(
            name,
            "position",
            "three finite numbers [m]",
            format!("{:?}", spec.position),
        ));
    }
    if !spec.rpy.iter().all(|v| v.is_finite()) {
        return Err(invalid(
            name,
            "rpy",
            "three finite angles [rad]",
            format!("{:?}", spec.rpy),
        ));
    }
    Ok(())
}

/// A built shape: the parry shape, its pose in the world, its closed-form distance when it has
/// one, and a note for the user (a mesh that is a surface only).
type Built = (SharedShape, Isometry3<f64>, Option<Closed>, Option<String>);

/// The spec's shape checked and built: the parry shape, its pose in the world (parry's round
/// shapes stand on y, the spec's on z), the closed-form distance when the shape has one, and
/// the note of an open mesh.
fn shape_of(
    spec: &ObstacleSpec,
    world: Isometry3<f64>,
    base_dir: Option<&Path>,
) -> Result<Built, ObstacleError> {
    let name = spec.name.as_str();
    // Rotation taking parry's y axis to the obstacle frame's z axis.
    let y_to_z = Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0),
    );
    let axis_world = world.rotation * Vector3::z();
    let vertical = axis_world.z.abs() > 1.0 - 1e-9;
    let centre = world.translation.vector;
    let (shape, pose, closed) = match &spec.shape {
        ShapeSpec::Cuboid { half_extents: h } => {
            for (i, v) in h.iter().enumerate() {
                positive(name, &format!("half_extents[{i}]"), *v)?;
            }
            (
                SharedShape::cuboid(h[0] as f32, h[1] as f32, h[2] as f32),
                world,
                None,
            )
        }
        ShapeSpec::Ball { radius } => {
            positive(name, "radius", *radius)?;
            (
                SharedShape::ball(*radius as f32),
                world,
                Some(Closed::RoundSegment {
                    c: centre.xy(),
                    z_lo: centre.z,
                    z_hi: centre.z,
                    radius: *radius,
                }),
            )
        }
        ShapeSpec::Cylinder {
            radius,
            half_height,
        } => {
            positive(name, "radius", *radius)?;
            positive(name, "half_height", *half_height)?;
            (
                SharedShape::cylinder(*half_height as f32, *radius as f32),
                world * y_to_z,
                vertical.then_some(Closed::VerticalCylinder {
                    c: centre.xy(),
                    z_lo: centre.z - half_height,
                    z_hi: centre.z + half_height,
                    radius: *radius,
                }),
            )
        }
        ShapeSpec::Capsule {
            radius,
            half_height,
        } => {
            positive(name, "radius", *radius)?;
            nonneg(name, "half_height", *half_height)?;
            (
                SharedShape::capsule_y(*half_height as f32, *radius as f32),
                world * y_to_z,
                vertical.then_some(Closed::RoundSegment {
                    c: centre.xy(),
                    z_lo: centre.z - half_height,
                    z_hi: centre.z + half_height,
                    radius: *radius,
                }),
            )
        }
        ShapeSpec::Cone {
            radius,
            half_height,
        } => {
            positive(name, "radius", *radius)?;
            positive(name, "half_height", *half_height)?;
            (
                SharedShape::cone(*half_height as f32, *radius as f32),
                world * y_to_z,
                None,
            )
        }
        ShapeSpec::ConvexHull { points } => (convex_hull(name, points)?, world, None),
        ShapeSpec::HalfSpace { normal } => half_space(name, normal, world)?,
        ShapeSpec::OccupancyMap { .. } => {
            return Err(invalid(
                name,
                "shape.kind",
                "a shape a world file may write (an occupancy map comes from environment.map)",
                "occupancy_map".into(),
            ))
        }
        ShapeSpec::TriMesh {
            vertices,
            indices,
            file,
            scale,
        } => {
            let (verts, idx) =
                mesh_data(name, vertices, indices, file.as_deref(), *scale, base_dir)?;
            let (shape, note) = tri_mesh(name, verts, idx)?;
            return Ok((shape, world, None, note));
        }
    };
    Ok((shape, pose, closed, None))
}

/// A half-space below the plane through the obstacle's origin with outward `normal` (in the
/// obstacle frame, non-zero and finite), with its closed-form distance.
fn half_space(
    name: &str,
    normal: &[f64; 3],
    world: Isometry3<f64>,
) -> Result<(SharedShape, Isometry3<f64>, Option<Closed>), ObstacleError> {
    let n = Vector3::from(*normal);
    let norm = n.norm();
    if !(norm.is_finite() && norm > 1e-12) {
        return Err(invalid(
            name,
            "shape.normal",
            "a non-zero finite vector",
            format!("{normal:?}"),
        ));
    }
    let n_local = n / norm;
    let n_world = world.rotation * n_local;
    Ok((
        SharedShape::halfspace(v3([n_local.x, n_local.y, n_local.z]).normalize()),
        world,
        Some(Closed::HalfSpace {
            n: n_world,
            p0: world.translation.vector,
        }),
    ))
}

/// The convex hull of finite `points`, at least four and not in one plane.
fn convex_hull(name: &str, points: &[[f64; 3]]) -> Result<SharedShape, ObstacleError> {
    if points.iter().any(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(invalid(
            name,
            "shape.points",
            "finite coordinates [m]",
            "a non-finite value".into(),
        ));
    }
    let pts: Vec<Vector> = points.iter().map(|p| v3(*p)).collect();
    (pts.len() >= 4 && !coplanar(points))
        .then(|| SharedShape::convex_hull(&pts))
        .flatten()
        .ok_or_else(|| ObstacleError::DegenerateHull {
            name: name.to_string(),
            count: points.len(),
        })
}

fn mesh_err(name: &str, message: String) -> ObstacleError {
    ObstacleError::Mesh {
        name: name.to_string(),
        message,
    }
}

/// A triangle mesh: its vertices \[m\] and its triangles as vertex indices.
type Triangles = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// A triangle mesh's vertices and triangles: read from `file` (relative to `base_dir`) and
/// scaled, or written inline, not both.
fn mesh_data(
    name: &str,
    vertices: &[[f64; 3]],
    indices: &[[u32; 3]],
    file: Option<&Path>,
    scale: Option<MeshScale>,
    base_dir: Option<&Path>,
) -> Result<Triangles, ObstacleError> {
    match file {
        Some(f) => {
            if !vertices.is_empty() || !indices.is_empty() {
                return Err(mesh_err(
                    name,
                    "give either `file` or `vertices`/`indices`, not both".into(),
                ));
            }
            let s = match scale.unwrap_or(MeshScale::Uniform(1.0)) {
                MeshScale::Uniform(s) => {
                    positive(name, "scale", s)?;
                    [s; 3]
                }
                MeshScale::PerAxis(s) => {
                    for (i, v) in s.iter().enumerate() {
                        if !(v.is_finite() && *v != 0.0) {
                            return Err(invalid(
                                name,
                                &format!("shape.scale[{i}]"),
                                "a finite non-zero factor",
                                format!("{v}"),
                            ));
                        }
                    }
                    s
                }
            };
            let path = match base_dir {
                Some(d) if f.is_relative() => d.join(f),
                _ => f.to_path_buf(),
            };
            let (v, i) = crate::robot::read_mesh(&path)
                .map_err(|m| mesh_err(name, format!("{}: {m}", path.display())))?;
            let scaled = v
                .into_iter()
                .map(|p| [p[0] * s[0], p[1] * s[1], p[2] * s[2]])
                .collect();
            Ok((scaled, i))
        }
        None => {
            if scale.is_some() {
                return Err(mesh_err(name, "`scale` applies only to `file`".into()));
            }
            Ok((vertices.to_vec(), indices.to_vec()))
        }
    }
}

/// A triangle mesh from checked vertices and triangles. A closed mesh is wound outward first
/// ([`orient_mesh`]: inside and outside do not depend on the file's winding) and gets parry's
/// pseudo-normals (a signed distance); an open one is a surface (unsigned distance), with a note
/// that names it.
fn tri_mesh(
    name: &str,
    verts: Vec<[f64; 3]>,
    idx: Vec<[u32; 3]>,
) -> Result<(SharedShape, Option<String>), ObstacleError> {
    if idx.is_empty() {
        return Err(mesh_err(name, "no triangles".into()));
    }
    if verts.iter().any(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(mesh_err(name, "non-finite vertex coordinates".into()));
    }
    if let Some(bad) = idx.iter().flatten().find(|&&i| i as usize >= verts.len()) {
        return Err(mesh_err(
            name,
            format!("index {bad} out of range ({} vertices)", verts.len()),
        ));
    }
    let mesh = orient_mesh(&verts, &idx);
    if mesh.triangles.is_empty() {
        return Err(mesh_err(
            name,
            "every triangle repeats a vertex: no triangles".into(),
        ));
    }
    let pts: Vec<Vector> = mesh.vertices.iter().map(|p| v3(*p)).collect();
    let (flags, note) = match &mesh.open {
        None => (TriMeshFlags::ORIENTED, None),
        Some(why) => (
            TriMeshFlags::empty(),
            Some(format!(
                "obstacle `{name}`: tri_mesh is not a closed surface ({why}): it has no inside, \
                 so its distance is unsigned and a robot inside it is not seen as inside"
            )),
        ),
    };
    SharedShape::trimesh_with_flags(pts, mesh.triangles, flags)
        .map(|s| (s, note))
        .map_err(|e| mesh_err(name, format!("{e:?}")))
}

/// A triangle mesh as [`orient_mesh`] leaves it.
#[derive(Debug, Clone, PartialEq)]
pub struct OrientedMesh {
    /// The distinct vertices \[m\].
    pub vertices: Vec<[f64; 3]>,
    /// The triangles, wound outward when the mesh is closed.
    pub triangles: Vec<[u32; 3]>,
    /// Why the mesh is not a closed, orientable surface enclosing a volume (`None` when it is).
    pub open: Option<String>,
}

/// The key of an edge (its vertices in increasing order) and whether triangle `t` runs it
/// forward (from the smaller to the larger vertex).
fn edges_of(t: [u32; 3]) -> [((u32, u32), bool); 3] {
    let e = |a: u32, b: u32| ((a.min(b), a.max(b)), a < b);
    [e(t[0], t[1]), e(t[1], t[2]), e(t[2], t[0])]
}

/// Edge → the triangles on it, with whether each runs it forward.
type EdgeMap = std::collections::HashMap<(u32, u32), Vec<(usize, bool)>>;

/// Merges vertices with equal coordinates (as the f32 parry stores), drops triangles that repeat
/// a vertex, and, when the mesh is closed (every edge on exactly two triangles) and orientable,
/// winds every triangle outward: within each connected piece each pair of neighbours runs their
/// shared edge in opposite directions, and each piece encloses a positive volume. Linear in the
/// number of triangles (hash maps, one breadth-first pass).
pub fn orient_mesh(verts: &[[f64; 3]], idx: &[[u32; 3]]) -> OrientedMesh {
    let mut id: std::collections::HashMap<[u32; 3], u32> = std::collections::HashMap::new();
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    // `+ 0.0` makes −0 and +0 one vertex.
    let remap: Vec<u32> = verts
        .iter()
        .map(|p| {
            let key = p.map(|c| (c as f32 + 0.0).to_bits());
            *id.entry(key).or_insert_with(|| {
                vertices.push(*p);
                (vertices.len() - 1) as u32
            })
        })
        .collect();
    let mut triangles: Vec<[u32; 3]> = idx
        .iter()
        .map(|t| t.map(|i| remap[i as usize]))
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[2] != t[0])
        .collect();
    let mut edges = EdgeMap::new();
    for (ti, t) in triangles.iter().enumerate() {
        for (key, forward) in edges_of(*t) {
            edges.entry(key).or_default().push((ti, forward));
        }
    }
    let boundary = edges.values().filter(|v| v.len() == 1).count();
    let shared = edges.values().filter(|v| v.len() > 2).count();
    let open = |why: String, triangles: Vec<[u32; 3]>, vertices: Vec<[f64; 3]>| OrientedMesh {
        vertices,
        triangles,
        open: Some(why),
    };
    if boundary > 0 || shared > 0 {
        let why =
            format!("{boundary} edge(s) on one triangle only, {shared} edge(s) on more than two");
        return open(why, triangles, vertices);
    }
    let Some(flip) = consistent_flips(&triangles, &edges) else {
        let why = "its triangles cannot be wound consistently: a one-sided surface".to_string();
        return open(why, triangles, vertices);
    };
    for (t, (f, _)) in triangles.iter_mut().zip(&flip) {
        if *f {
            t.swap(1, 2);
        }
    }
    // Each piece's enclosed volume, by the divergence theorem: Σ a·(b × c) / 6.
    let pieces = flip.iter().map(|(_, c)| c + 1).max().unwrap_or(0);
    let mut volume = vec![0.0f64; pieces];
    let v = |i: u32| Vector3::from(vertices[i as usize]);
    for (t, (_, c)) in triangles.iter().zip(&flip) {
        volume[*c] += v(t[0]).dot(&v(t[1]).cross(&v(t[2]))) / 6.0;
    }
    let extent = vertices
        .iter()
        .flatten()
        .fold(0.0f64, |m, c| m.max(c.abs()))
        .max(f64::MIN_POSITIVE);
    if volume.iter().any(|w| w.abs() <= 1e-9 * extent.powi(3)) {
        let why = "a closed piece of it encloses no volume".to_string();
        return open(why, triangles, vertices);
    }
    for (t, (_, c)) in triangles.iter_mut().zip(&flip) {
        if volume[*c] < 0.0 {
            t.swap(1, 2);
        }
    }
    OrientedMesh {
        vertices,
        triangles,
        open: None,
    }
}

/// For a closed mesh: per triangle, whether to reverse it so that neighbours run each shared
/// edge in opposite directions, and its connected piece; `None` when no such choice exists.
fn consistent_flips(triangles: &[[u32; 3]], edges: &EdgeMap) -> Option<Vec<(bool, usize)>> {
    let mut flip: Vec<Option<(bool, usize)>> = vec![None; triangles.len()];
    let mut queue = std::collections::VecDeque::new();
    let mut pieces = 0;
    for seed in 0..triangles.len() {
        if flip[seed].is_some() {
            continue;
        }
        flip[seed] = Some((false, pieces));
        queue.push_back(seed);
        while let Some(t) = queue.pop_front() {
            let (ft, _) = flip[t]?;
            for (key, forward) in edges_of(triangles[t]) {
                // Whether t, as it will be wound, runs the edge forward.
                let runs = forward != ft;
                for &(u, fu) in &edges[&key] {
                    if u == t {
                        continue;
                    }
                    // u must run it the other way: (fu XOR flip_u) = !runs.
                    let want = fu == runs;
                    match flip[u] {
                        None => {
                            flip[u] = Some((want, pieces));
                            queue.push_back(u);
                        }
                        Some((got, _)) if got != want => return None,
                        Some(_) => {}
                    }
                }
            }
        }
        pieces += 1;
    }
    flip.into_iter().collect()
}

impl Obstacle {
    /// Validates a spec. `base_dir` resolves relative `tri_mesh.file` paths. In phases: the
    /// name and placement checked, then the shape (checked and built) with its closed-form
    /// distance where there is one.
    pub fn from_spec(spec: &ObstacleSpec, base_dir: Option<&Path>) -> Result<Self, ObstacleError> {
        check_placement(spec)?;
        if let ShapeSpec::OccupancyMap { file, unknown } = &spec.shape {
            let path = match base_dir {
                Some(d) if file.is_relative() => d.join(file),
                _ => file.clone(),
            };
            return Self::from_map(spec, &OccupancyGrid::load(&path)?, *unknown, &path);
        }
        let world = iso(spec.position, spec.rpy);
        let (shape, pose, closed, note) = shape_of(spec, world, base_dir)?;
        Ok(Self {
            name: spec.name.clone(),
            spec: spec.clone(),
            shape,
            shape_pose: to_pose(&pose),
            closed,
            note,
            grid: None,
            outlines: Arc::new([]),
        })
    }

    /// The obstacle of an occupancy map read from `path` (`spec` names it and says which
    /// cells are blocked): its distance field for the barrier, its blocked cells merged into
    /// boxes for the physics, placed at the map's origin.
    fn from_map(
        spec: &ObstacleSpec,
        grid: &OccupancyGrid,
        unknown: crate::environment::UnknownCells,
        path: &Path,
    ) -> Result<Self, ObstacleError> {
        let shape = grid
            .compound(unknown)
            .ok_or_else(|| ObstacleError::EmptyMap {
                file: path.display().to_string(),
            })?;
        let field = MapField::new(grid, unknown);
        let pieces: Arc<[Outline]> = outlines(grid, unknown, DEFAULT_TOLERANCE_CELLS).into();
        let polygons = pieces.iter().filter(|p| p.is_polygon()).count();
        let note = format!(
            "obstacle `{}` is the occupancy map {} ({} × {} cells of {} m): the controller keeps \
             it with {} barriers, {polygons} convex polygons round blobs and {} segments along \
             the walls, simplified within {} cell(s) ({:.3} m), so the robot may keep up to {:.3} \
             m further from the cells than it needs to",
            spec.name,
            path.display(),
            grid.width,
            grid.height,
            grid.resolution,
            pieces.len(),
            pieces.len() - polygons,
            DEFAULT_TOLERANCE_CELLS,
            DEFAULT_TOLERANCE_CELLS * grid.resolution,
            2.0 * DEFAULT_TOLERANCE_CELLS * grid.resolution,
        );
        Ok(Self {
            name: spec.name.clone(),
            spec: spec.clone(),
            shape,
            shape_pose: to_pose(&grid.pose()),
            closed: None,
            note: Some(note),
            grid: Some(Arc::new(field)),
            outlines: pieces,
        })
    }

    /// The distance field of an occupancy-map obstacle.
    pub fn map_field(&self) -> Option<&MapField> {
        self.grid.as_deref()
    }

    /// An occupancy map's barrier pieces (empty for any other obstacle).
    pub fn outlines(&self) -> &[Outline] {
        &self.outlines
    }

    /// Validates a list of specs; names must be unique.
    pub fn from_specs(
        specs: &[ObstacleSpec],
        base_dir: Option<&Path>,
    ) -> Result<Vec<Self>, ObstacleError> {
        let mut out: Vec<Self> = Vec::with_capacity(specs.len());
        for s in specs {
            if out.iter().any(|o| o.name == s.name) {
                return Err(ObstacleError::Invalid {
                    name: s.name.clone(),
                    key: "name".into(),
                    expected: "a name no other obstacle uses".into(),
                    got: format!("{:?} (duplicate)", s.name),
                });
            }
            out.push(Self::from_spec(s, base_dir)?);
        }
        Ok(out)
    }

    /// The parry shape (in parry's conventions).
    pub fn shape(&self) -> &SharedShape {
        &self.shape
    }

    /// World pose of the parry shape.
    pub fn shape_pose(&self) -> &Pose {
        &self.shape_pose
    }

    /// True for half-spaces (unbounded).
    pub fn is_half_space(&self) -> bool {
        matches!(self.spec.shape, ShapeSpec::HalfSpace { .. })
    }

    /// Signed distance from a world point to the solid shape \[m\] (negative inside).
    pub fn signed_distance(&self, p: Vector3<f64>) -> f64 {
        self.sd_and_grad(p).0
    }

    /// Signed distance and its gradient (world frame) at p.
    fn sd_and_grad(&self, p: Vector3<f64>) -> (f64, Vector3<f64>) {
        if let Some(g) = &self.grid {
            let (d, n) = g.signed_distance([p.x, p.y]);
            return (d, Vector3::new(n.x, n.y, 0.0));
        }
        match self.closed {
            Some(Closed::HalfSpace { n, p0 }) => return (n.dot(&(p - p0)), n),
            Some(Closed::RoundSegment {
                c,
                z_lo,
                z_hi,
                radius,
            }) => return round_sd(p, c, p.z.clamp(z_lo, z_hi), radius),
            Some(Closed::VerticalCylinder {
                c,
                z_lo,
                z_hi,
                radius,
            }) if p.z >= z_lo && p.z <= z_hi => return round_sd(p, c, p.z, radius),
            _ => {}
        }
        let q = Vector::new(p.x as f32, p.y as f32, p.z as f32);
        let proj = self.shape.project_point(&self.shape_pose, q, false);
        let diff = p - Vector3::new(
            proj.point.x as f64,
            proj.point.y as f64,
            proj.point.z as f64,
        );
        let dist = diff.norm();
        let sign = if proj.is_inside { -1.0 } else { 1.0 };
        if dist > 1e-6 {
            (sign * dist, sign * diff / dist)
        } else {
            // On the surface: the direction is undefined; use a central difference of sd.
            let h = 1e-4;
            let sd = |d: Vector3<f64>| {
                let q = d.map(|c| c as f32);
                let pr =
                    self.shape
                        .project_point(&self.shape_pose, Vector::new(q.x, q.y, q.z), false);
                let dd =
                    (d - Vector3::new(pr.point.x as f64, pr.point.y as f64, pr.point.z as f64))
                        .norm();
                if pr.is_inside {
                    -dd
                } else {
                    dd
                }
            };
            let mut g = Vector3::zeros();
            for k in 0..3 {
                let mut e = Vector3::zeros();
                e[k] = h;
                g[k] = (sd(p + e) - sd(p - e)) / (2.0 * h);
            }
            (sign * dist, g)
        }
    }

    /// A barrier for this obstacle (see the module docs).
    pub fn barrier(&self, cfg: &BarrierConfig) -> ObstacleBarrier {
        let map_band = self.grid.as_ref().map(|g| {
            // Where H = d − margin + k∇d·v can be 0: sd within k·G·v_max of r + margin; the
            // h̄_γ segment reaches MAP_BAND_SLACK further.
            let at = cfg.robot_radius + cfg.margin;
            let lift = cfg.k * g.gradient_bound() * cfg.v_max;
            let (gb, kappa) = g.bounds_in(at - lift - MAP_BAND_SLACK, at + lift + MAP_BAND_SLACK);
            MapBand { gb, kappa }
        });
        ObstacleBarrier {
            name: format!("obstacle:{}", self.name),
            obstacle: Arc::new(self.clone()),
            cfg: *cfg,
            map_band,
            piece: None,
        }
    }

    /// How many barriers [`Obstacle::barriers`] gives, without building them: one per piece of
    /// an occupancy map's outline, else one.
    pub fn barrier_count(&self) -> usize {
        self.outlines.len().max(1)
    }

    /// The barriers the controller keeps for this obstacle: one per piece of an occupancy map
    /// (named `obstacle:NAME#k`), else the one of [`Obstacle::barrier`].
    pub fn barriers(&self, cfg: &BarrierConfig) -> Vec<ObstacleBarrier> {
        if self.outlines.is_empty() {
            return vec![self.barrier(cfg)];
        }
        let shared = Arc::new(self.clone());
        self.outlines
            .iter()
            .enumerate()
            .map(|(k, piece)| ObstacleBarrier {
                name: format!("obstacle:{}#{k}", self.name),
                obstacle: shared.clone(),
                cfg: *cfg,
                map_band: None,
                piece: Some(piece.clone()),
            })
            .collect()
    }
}

/// The obstacle that gives the `k`-th of all `obstacles`' barriers taken in order (each
/// obstacle's [`Obstacle::barriers`] in turn): obstacle `k` when each gives one, the map for
/// any of its outline pieces. `None` past the last barrier.
pub fn obstacle_of_barrier(obstacles: &[Obstacle], mut k: usize) -> Option<&Obstacle> {
    obstacles.iter().find(|o| {
        let c = o.barrier_count();
        if k < c {
            true
        } else {
            k -= c;
            false
        }
    })
}

/// Signed distance to the points within `radius` of (c, cz), and its gradient.
fn round_sd(p: Vector3<f64>, c: Vector2<f64>, cz: f64, radius: f64) -> (f64, Vector3<f64>) {
    let e = Vector3::new(p.x - c.x, p.y - c.y, p.z - cz);
    let rho = e.norm();
    if rho > 0.0 {
        (rho - radius, e / rho)
    } else {
        (-radius, Vector3::x())
    }
}

fn coplanar(points: &[[f64; 3]]) -> bool {
    let p: Vec<Vector3<f64>> = points.iter().map(|q| Vector3::from(*q)).collect();
    let scale = p
        .iter()
        .map(|q| (q - p[0]).norm())
        .fold(0.0_f64, f64::max)
        .max(1e-12);
    // Find two independent directions, then test every point against their plane.
    let Some(a) = p.iter().map(|q| q - p[0]).find(|d| d.norm() > 1e-9 * scale) else {
        return true;
    };
    let Some(n) = p
        .iter()
        .map(|q| a.cross(&(q - p[0])))
        .find(|c| c.norm() > 1e-9 * scale * scale)
    else {
        return true;
    };
    let n = n.normalize();
    p.iter().all(|q| n.dot(&(q - p[0])).abs() <= 1e-9 * scale)
}

/// Parameters shared by all obstacle barriers of one robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BarrierConfig {
    /// Robot footprint radius r \[m\].
    pub robot_radius: f64,
    /// Height z_c at which distances are evaluated \[m\].
    pub centre_height: f64,
    /// Safety margin subtracted from the clearance \[m\].
    pub margin: f64,
    /// Gain k of the lift H = d − margin + k∇d·v \[s\].
    pub k: f64,
    /// Speed bound used in the Lipschitz bound of h̄ [m/s].
    pub v_max: f64,
    /// Step of the numerical derivatives \[m\]. Default 2e-3.
    pub fd_step: f64,
}

impl BarrierConfig {
    /// Footprint radius, centre height and v_max from a robot; `margin` \[m\] and `k` \[s\] given.
    pub fn for_robot(robot: &RobotDescription, margin: f64, k: f64) -> Self {
        Self {
            robot_radius: robot.footprint_radius,
            centre_height: robot.centre_height,
            margin,
            k,
            v_max: robot.limits.v_max,
            fd_step: 2e-3,
        }
    }
}

/// The barrier of one obstacle (implements [`ftcbf_controller::Barrier`]).
#[derive(Debug, Clone)]
pub struct ObstacleBarrier {
    name: String,
    obstacle: Arc<Obstacle>,
    cfg: BarrierConfig,
    /// An occupancy map's gradient and curvature bounds over the band of its field around
    /// this barrier's zero level.
    map_band: Option<MapBand>,
    /// One piece of an occupancy map: the barrier is the distance to it, not the field.
    piece: Option<Outline>,
}

/// How far beyond the band where an occupancy map's lifted barrier can be zero its bounds G
/// and κ are taken \[m\]: an h̄_γ segment that moves sd by more (γ·G above it) uses the bounds
/// over the whole free space instead.
pub const MAP_BAND_SLACK: f64 = 0.1;

/// G and κ of an occupancy map over a band of its field.
#[derive(Debug, Clone, Copy)]
struct MapBand {
    gb: f64,
    kappa: f64,
}

impl ObstacleBarrier {
    /// The configuration.
    pub fn config(&self) -> &BarrierConfig {
        &self.cfg
    }

    /// The bound κ on ‖∇²d‖ [1/m] that [`Barrier::h_bar`] uses, and the condition it rests on
    /// (module docs): 0 for a half-space; 1/r for a robot disc of radius r > 0 (the centre at
    /// least r from a convex obstacle); for a point robot (r = 0), 1/R for a ball, a vertical
    /// capsule and a vertical cylinder at heights within its length (the point outside the
    /// shape). `None` for a point robot and any other shape: the distance to an edge or vertex
    /// has unbounded curvature, so no h̄_γ bound exists for the lifted barrier.
    pub fn curvature_bound(&self) -> Option<f64> {
        if let Some(piece) = &self.piece {
            // distance to a convex set: ‖∇²d‖ ≤ 1/ρ, and ρ ≥ r + δ where the disc is clear
            let rho = self.cfg.robot_radius + piece.inflate;
            return (rho > 0.0).then(|| 1.0 / rho);
        }
        if let Some(b) = &self.map_band {
            return Some(b.kappa);
        }
        if self.obstacle.is_half_space() {
            return Some(0.0);
        }
        let r = self.cfg.robot_radius;
        if r > 0.0 {
            return Some(1.0 / r);
        }
        let z = self.cfg.centre_height;
        match self.obstacle.closed {
            Some(Closed::RoundSegment { radius, .. }) => Some(1.0 / radius),
            Some(Closed::VerticalCylinder {
                z_lo, z_hi, radius, ..
            }) if z >= z_lo && z <= z_hi => Some(1.0 / radius),
            _ => None,
        }
    }

    /// Clearance d(p) = sd − r of the robot disc at planar position p \[m\] (no margin, no lift).
    pub fn clearance(&self, p: Vector2<f64>) -> f64 {
        if let Some(piece) = &self.piece {
            return piece.distance_terms(p).0 - self.cfg.robot_radius;
        }
        self.obstacle
            .signed_distance(Vector3::new(p.x, p.y, self.cfg.centre_height))
            - self.cfg.robot_radius
    }

    fn grad2(&self, p: Vector2<f64>) -> Vector2<f64> {
        if let Some(piece) = &self.piece {
            return piece.distance_terms(p).1;
        }
        let (_, g) = self
            .obstacle
            .sd_and_grad(Vector3::new(p.x, p.y, self.cfg.centre_height));
        g.xy()
    }

    fn hess2_numeric(&self, p: Vector2<f64>) -> Matrix2<f64> {
        let h = self.cfg.fd_step;
        let mut m = Matrix2::zeros();
        for j in 0..2 {
            let mut e = Vector2::zeros();
            e[j] = h;
            let col = (self.grad2(p + e) - self.grad2(p - e)) / (2.0 * h);
            m.set_column(j, &col);
        }
        0.5 * (m + m.transpose())
    }

    /// (d, ∇d, ∇²d, D(∇²d·v)) in the plane.
    fn planar_terms(
        &self,
        p: Vector2<f64>,
        v: Vector2<f64>,
    ) -> (f64, Vector2<f64>, Matrix2<f64>, Matrix2<f64>) {
        let z = self.cfg.centre_height;
        let r = self.cfg.robot_radius;
        if let Some(piece) = &self.piece {
            let (d, g, m) = piece.distance_terms(p);
            let dmv = if m == Matrix2::zeros() {
                m
            } else {
                // round at a vertex: the same derivative as a ball's, at ρ = d + δ
                let rho = d + piece.inflate;
                let s = g.dot(&v);
                let w = m * v;
                -(s * m + g * w.transpose() + w * g.transpose()) / rho
            };
            return (d - r, g, m, dmv);
        }
        let p3 = Vector3::new(p.x, p.y, z);
        let round = match self.obstacle.closed {
            Some(Closed::HalfSpace { n, p0 }) => {
                return (
                    n.dot(&(p3 - p0)) - r,
                    n.xy(),
                    Matrix2::zeros(),
                    Matrix2::zeros(),
                )
            }
            Some(Closed::RoundSegment {
                c,
                z_lo,
                z_hi,
                radius,
            }) => Some((c, z - z.clamp(z_lo, z_hi), radius)),
            Some(Closed::VerticalCylinder {
                c,
                z_lo,
                z_hi,
                radius,
            }) if z >= z_lo && z <= z_hi => Some((c, 0.0, radius)),
            _ => None,
        };
        if let Some((c, dz, radius)) = round {
            let e = p - c;
            let rho = (e.norm_squared() + dz * dz).sqrt();
            if rho > 1e-12 {
                let g = e / rho;
                let m = (Matrix2::identity() - g * g.transpose()) / rho;
                let s = g.dot(&v);
                let w = m * v;
                let dmv = -(s * m + g * w.transpose() + w * g.transpose()) / rho;
                return (rho - radius - r, g, m, dmv);
            }
        }
        // Numerical curvature terms around parry's projection normal.
        let (sd, g3) = self.obstacle.sd_and_grad(p3);
        let m = self.hess2_numeric(p);
        let h = self.cfg.fd_step;
        let mut dmv = Matrix2::zeros();
        for j in 0..2 {
            let mut e = Vector2::zeros();
            e[j] = h;
            let col = (self.hess2_numeric(p + e) * v - self.hess2_numeric(p - e) * v) / (2.0 * h);
            dmv.set_column(j, &col);
        }
        (sd - r, g3.xy(), m, 0.5 * (dmv + dmv.transpose()))
    }
}

impl Barrier for ObstacleBarrier {
    fn name(&self) -> &str {
        &self.name
    }

    fn eval(&self, x: &State) -> BarrierEval {
        let p = Vector2::new(x[0], x[1]);
        let v = Vector2::new(x[2], x[3]);
        let k = self.cfg.k;
        let (d, g, m, dmv) = self.planar_terms(p, v);
        let value = d - self.cfg.margin + k * g.dot(&v);
        let gp = g + k * (m * v);
        let gradient = State::new(gp.x, gp.y, k * g.x, k * g.y);
        let pp = m + k * dmv;
        let pv = k * m;
        let mut hessian = StateMatrix::zeros();
        hessian.fixed_view_mut::<2, 2>(0, 0).copy_from(&pp);
        hessian.fixed_view_mut::<2, 2>(0, 2).copy_from(&pv);
        hessian
            .fixed_view_mut::<2, 2>(2, 0)
            .copy_from(&pv.transpose());
        BarrierEval {
            value,
            gradient,
            hessian,
        }
    }

    /// γ·L with L = √((1 + k·v_max·κ)² + k²), κ = [`ObstacleBarrier::curvature_bound`]; see
    /// the module docs for the conditions under which it bounds h̄_γ. +∞ when the lift is on
    /// (k > 0) and no curvature bound is known (the runner refuses such worlds first).
    fn h_bar(&self, gamma: f64) -> f64 {
        let k = self.cfg.k;
        let l = if let (Some(g), Some(band)) = (&self.obstacle.grid, &self.map_band) {
            // The map's ‖∇d‖ ≤ G (not 1): L = √((G + k·v_max·κ)² + (k·G)²), with G and κ of
            // the band around the zero level when the segment stays in it.
            let (gb, kappa) = if gamma.max(0.0) * g.gradient_bound() <= MAP_BAND_SLACK {
                (band.gb, band.kappa)
            } else {
                (g.gradient_bound(), g.curvature_bound())
            };
            ((gb + k * self.cfg.v_max * kappa).powi(2) + (k * gb).powi(2)).sqrt()
        } else if k == 0.0 {
            1.0
        } else {
            match self.curvature_bound() {
                Some(kappa) => ((1.0 + k * self.cfg.v_max * kappa).powi(2) + k * k).sqrt(),
                None => f64::INFINITY,
            }
        };
        gamma.max(0.0) * l
    }
}

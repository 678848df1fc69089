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
//! Files: this one holds [`Obstacle`] (a validated shape with its world pose, the parry shape
//! the physics inserts, its closed form where it has one); `spec` the world file's tables,
//! `mesh` loading and orienting triangle meshes, `barrier` the controller's barrier of an
//! obstacle.

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

mod barrier;
mod mesh;
mod spec;

pub use barrier::*;
pub use mesh::*;
pub use spec::*;

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

//! The static scene of a run, for an observer: obstacles and robot links with their true
//! shapes, safe-set outlines, the goal, and the names of every logged series.

use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use crate::observe::{Geometry, Placed, Scene};
use crate::obstacles::{Obstacle, ShapeSpec};
use crate::robot::{CollisionShape, RobotVisual};
use crate::world::{SafeSetSpec, World};

use crate::model::setup::ControlSetup;

/// Half size of the patch drawn for a half-space wall \[m\].
const HALF_SPACE_PATCH: f64 = 3.0;

fn quat_xyzw(q: &UnitQuaternion<f64>) -> [f32; 4] {
    [q.i as f32, q.j as f32, q.k as f32, q.w as f32]
}

fn mesh_from(vertices: Vec<parry3d::math::Vector>, triangles: Vec<[u32; 3]>) -> Geometry {
    Geometry::Mesh {
        vertices: vertices.iter().map(|v| [v.x, v.y, v.z]).collect(),
        triangles,
    }
}

/// A square patch of a half-space's wall plane, centred on its point, drawn from both sides.
fn half_space_patch(ob: &Obstacle, rot: &UnitQuaternion<f64>, normal: &[f64; 3]) -> Placed {
    let spec = &ob.spec;
    let f = |v: f64| v as f32;
    let n = *rot * Vector3::from(*normal).normalize();
    let helper = if n.z.abs() < 0.9 {
        Vector3::z()
    } else {
        Vector3::x()
    };
    let a = n.cross(&helper).normalize() * HALF_SPACE_PATCH;
    let b = n.cross(&a).normalize() * HALF_SPACE_PATCH;
    let c = Vector3::from(spec.position);
    let corners = [c + a + b, c + a - b, c - a - b, c - a + b];
    Placed {
        name: ob.name.clone(),
        geometry: Geometry::Mesh {
            vertices: corners.iter().map(|p| [f(p.x), f(p.y), f(p.z)]).collect(),
            triangles: vec![[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]],
        },
        translation: [0.0; 3],
        rotation: [0.0, 0.0, 0.0, 1.0],
    }
}

fn obstacle_geometry(ob: &Obstacle) -> Placed {
    let spec = &ob.spec;
    let rot = UnitQuaternion::from_euler_angles(spec.rpy[0], spec.rpy[1], spec.rpy[2]);
    let placed = |geometry: Geometry| Placed {
        name: ob.name.clone(),
        geometry,
        translation: spec.position.map(|v| v as f32),
        rotation: quat_xyzw(&rot),
    };
    // Shapes parry stores in its own frame (meshes) are drawn in the shape's world pose.
    let in_shape_pose = |geometry: Geometry| {
        let pose = ob.shape_pose();
        Placed {
            name: ob.name.clone(),
            geometry,
            translation: [pose.translation.x, pose.translation.y, pose.translation.z],
            rotation: [
                pose.rotation.x,
                pose.rotation.y,
                pose.rotation.z,
                pose.rotation.w,
            ],
        }
    };
    let f = |v: f64| v as f32;
    match &spec.shape {
        ShapeSpec::Cuboid { half_extents } => placed(Geometry::Cuboid {
            half_extents: half_extents.map(f),
        }),
        ShapeSpec::Ball { radius } => placed(Geometry::Ball { radius: f(*radius) }),
        ShapeSpec::Cylinder {
            radius,
            half_height,
        } => placed(Geometry::Cylinder {
            radius: f(*radius),
            half_height: f(*half_height),
        }),
        ShapeSpec::Capsule {
            radius,
            half_height,
        } => placed(Geometry::Capsule {
            radius: f(*radius),
            half_height: f(*half_height),
        }),
        ShapeSpec::Cone { .. } => match ob.shape().as_cone() {
            Some(c) => {
                let (v, t) = c.to_trimesh(32);
                in_shape_pose(mesh_from(v, t))
            }
            None => in_shape_pose(Geometry::Ball { radius: 0.0 }),
        },
        ShapeSpec::ConvexHull { .. } => match ob.shape().as_convex_polyhedron() {
            Some(c) => {
                let (v, t) = c.to_trimesh();
                in_shape_pose(mesh_from(v, t))
            }
            None => in_shape_pose(Geometry::Ball { radius: 0.0 }),
        },
        ShapeSpec::TriMesh { .. } => match ob.shape().as_trimesh() {
            Some(m) => in_shape_pose(mesh_from(m.vertices().to_vec(), m.indices().to_vec())),
            None => in_shape_pose(Geometry::Ball { radius: 0.0 }),
        },
        ShapeSpec::HalfSpace { normal } => half_space_patch(ob, &rot, normal),
        ShapeSpec::OccupancyMap { .. } => in_shape_pose(compound_mesh(ob)),
    }
}

/// A compound of boxes (an occupancy map's blocked cells) as one mesh in the shape's frame.
fn compound_mesh(ob: &Obstacle) -> Geometry {
    let (mut vertices, mut triangles) = (Vec::new(), Vec::new());
    if let Some(c) = ob.shape().as_compound() {
        for (pose, part) in c.shapes() {
            if let Some(b) = part.as_cuboid() {
                let (v, t) = b.to_trimesh();
                let base = vertices.len() as u32;
                vertices.extend(v.into_iter().map(|p| *pose * p));
                triangles.extend(t.into_iter().map(|t| t.map(|k| k + base)));
            }
        }
    }
    mesh_from(vertices, triangles)
}

fn collider_geometry(shape: &CollisionShape) -> Geometry {
    let f = |v: f64| v as f32;
    match shape {
        CollisionShape::Box { half_extents } => Geometry::Cuboid {
            half_extents: half_extents.map(f),
        },
        CollisionShape::Cylinder {
            radius,
            half_length,
        } => Geometry::Cylinder {
            radius: f(*radius),
            half_height: f(*half_length),
        },
        CollisionShape::Capsule {
            radius,
            half_length,
        } => Geometry::Capsule {
            radius: f(*radius),
            half_height: f(*half_length),
        },
        CollisionShape::Sphere { radius } => Geometry::Ball { radius: f(*radius) },
        CollisionShape::Mesh { vertices, indices } => Geometry::Mesh {
            vertices: vertices.iter().map(|v| v.map(f)).collect(),
            triangles: indices.clone(),
        },
    }
}

/// A body's URDF visual meshes as drawable shapes (drawn instead of its collision shapes).
fn visual_shapes(visuals: &[RobotVisual]) -> Vec<Placed> {
    visuals
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let mesh = Geometry::Mesh {
                vertices: v.vertices.iter().map(|p| p.map(|x| x as f32)).collect(),
                triangles: v.indices.clone(),
            };
            placed(format!("{}_visual_{i}", v.link), mesh, &v.pose_in_body)
        })
        .collect()
}

/// A shape at a pose in its body's frame.
fn placed(name: String, geometry: Geometry, pose_in_body: &Isometry3<f64>) -> Placed {
    let t = pose_in_body.translation.vector;
    Placed {
        name,
        geometry,
        translation: [t.x as f32, t.y as f32, t.z as f32],
        rotation: quat_xyzw(&pose_in_body.rotation),
    }
}

fn outline(spec: &SafeSetSpec) -> Vec<[f32; 3]> {
    const Z: f32 = 0.004;
    match spec {
        SafeSetSpec::HalfPlane { a, b, .. } => {
            // Boundary at rest: a0·x + a1·y = b (nothing to draw for velocity-only sets).
            let n2 = a[0] * a[0] + a[1] * a[1];
            if n2 < 1e-18 {
                return Vec::new();
            }
            let p0 = [b * a[0] / n2, b * a[1] / n2];
            let d = [-a[1] / n2.sqrt(), a[0] / n2.sqrt()];
            let l = 2.0 * HALF_SPACE_PATCH;
            vec![
                [(p0[0] - l * d[0]) as f32, (p0[1] - l * d[1]) as f32, Z],
                [(p0[0] + l * d[0]) as f32, (p0[1] + l * d[1]) as f32, Z],
            ]
        }
        SafeSetSpec::EllipseInside {
            center,
            semi_axes,
            angle,
            ..
        }
        | SafeSetSpec::EllipseOutside {
            center,
            semi_axes,
            angle,
            ..
        } => {
            let (s, c) = angle.sin_cos();
            (0..=128)
                .map(|k| {
                    let t = k as f64 / 128.0 * std::f64::consts::TAU;
                    let (ex, ey) = (semi_axes[0] * t.cos(), semi_axes[1] * t.sin());
                    [
                        (center[0] + c * ex - s * ey) as f32,
                        (center[1] + s * ex + c * ey) as f32,
                        Z,
                    ]
                })
                .collect()
        }
    }
}

/// Builds the scene of `world` for a run with `setup`; `filters` and `attacks` name the series.
pub fn build_scene(
    world: &World,
    setup: &ControlSetup,
    filters: &[String],
    attacks: &[(String, f64, Option<f64>)],
) -> Scene {
    let robot_links = world
        .robot
        .as_ref()
        .map(|r| {
            r.bodies
                .iter()
                .map(|b| {
                    if !b.visuals.is_empty() {
                        return (b.name.clone(), visual_shapes(&b.visuals));
                    }
                    let shapes = b
                        .colliders
                        .iter()
                        .enumerate()
                        .map(|(i, c)| {
                            let name = format!("{}_{i}", c.link);
                            placed(name, collider_geometry(&c.shape), &c.pose_in_body)
                        })
                        .collect();
                    (b.name.clone(), shapes)
                })
                .collect()
        })
        .unwrap_or_default();
    Scene {
        world: world.name.clone(),
        obstacles: world.obstacles.iter().map(obstacle_geometry).collect(),
        half_space_walls: world
            .obstacles
            .iter()
            .filter(|ob| matches!(ob.spec.shape, ShapeSpec::HalfSpace { .. }))
            .map(|ob| ob.name.clone())
            .collect(),
        robot_links,
        safe_set_outlines: world
            .file
            .safe_sets
            .iter()
            .map(|s| (s.name().to_string(), outline(s)))
            .filter(|(_, p)| !p.is_empty())
            .collect(),
        goal: (
            [
                world.file.goal.center[0] as f32,
                world.file.goal.center[1] as f32,
            ],
            world.file.goal.radius as f32,
        ),
        channels: world.file.sensors.iter().map(|s| s.name.clone()).collect(),
        filters: filters.to_vec(),
        barriers: setup.barrier_names.clone(),
        attacks: attacks.iter().map(|(l, _, _)| l.clone()).collect(),
        attack_channels: world
            .file
            .attacks
            .iter()
            .map(|a| a.channels.clone())
            .collect(),
        movers: world
            .obstacles
            .iter()
            .filter(|ob| ob.spec.motion.is_some())
            .map(|ob| ob.name.clone())
            .collect(),
    }
}

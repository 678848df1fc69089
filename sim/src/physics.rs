//! The rapier3d world: the robot of a [`RobotDescription`] on a ground plane among fixed
//! obstacle colliders, stepped at a fixed `dt`.
//!
//! - Z up, gravity −g along z, REP-103 (x forward, y left). The ground is the half-space z ≤ 0.
//! - Each robot body gets the URDF mass properties (colliders carry no mass). Movable joints are
//!   rapier impulse joints; the drive wheels are revolute joints with a force-based velocity
//!   motor on `JointAxis::AngX` (the joint frames map the URDF axis onto local x).
//! - Drive wheels with a cylinder collision touch the ground through a ball of the wheel
//!   radius centred on the wheel (a single rolling contact in the wheel's mid-plane, as in the
//!   kinematic model; a wide cylinder's two rim contacts scrub when turning and made turns
//!   ~7 % slow); the cylinder itself is what meets obstacles.
//! - Friction: drive-wheel colliders use [`PhysicsConfig::friction`] against the ground; all
//!   other robot colliders (casters, skids, the base) are frictionless (rule `Min`) — a caster
//!   rolls or swivels freely, which a sliding rigid contact would not model.
//! - Collision groups: robot colliders touch the ground and obstacles, never each other;
//!   the ground and obstacles do not interact.
//! - A *collision* is a contact pair between a robot collider and an obstacle collider that
//!   has an active contact whose distance is ≤ [`PhysicsConfig::contact_distance`].

use std::cmp::Ordering;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude as rp;
use rapier3d::prelude::{
    CoefficientCombineRule, ColliderBuilder, ColliderHandle, GenericJointBuilder, Group,
    ImpulseJointHandle, InteractionGroups, InteractionTestMode, JointAxesMask, JointAxis,
    MassProperties, MotorModel, RigidBodyBuilder, RigidBodyHandle, SharedShape,
};

use crate::obstacles::{to_pose, Obstacle};
use crate::robot::{CollisionShape, JointKind, RobotCollider, RobotDescription};
use crate::state::TruthState;

/// Errors of world construction.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PhysicsError {
    /// A configuration value is out of range.
    #[error("physics config: `{key}` must be {expected}, got {value}")]
    InvalidConfig {
        /// The key.
        key: &'static str,
        /// What is expected.
        expected: &'static str,
        /// The value.
        value: f64,
    },
    /// The start pose is not finite.
    #[error("start pose must be finite, got {0:?}")]
    InvalidStart(Pose2),
    /// A robot collision mesh cannot be turned into a collider.
    #[error("robot link `{link}`: collision mesh rejected by parry: {message}")]
    Mesh {
        /// Link name.
        link: String,
        /// parry's message.
        message: String,
    },
}

/// Physics settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicsConfig {
    /// Time step \[s\]. Default 1/240.
    pub dt: f64,
    /// Friction coefficient of wheels against the ground and of obstacles. Default 1.0.
    pub friction: f64,
    /// Gravity magnitude [m/s²], acting along −z. Default 9.81.
    pub gravity: f64,
    /// Velocity-motor damping factor of the wheel motors. Default 1.0.
    pub motor_damping: f64,
    /// Wheel motor torque bound [N·m] when the URDF joint has no `<limit effort>`. Default 1.5.
    pub motor_max_force: f64,
    /// Solver iterations per step. Default 4.
    pub solver_iterations: usize,
    /// A robot–obstacle contact point at distance ≤ this counts as a collision \[m\]. Default 1e-3.
    pub contact_distance: f64,
    /// rapier's characteristic length \[m\] (scales its allowed penetration and prediction
    /// distance). Default 0.1, the size of a TurtleBot3.
    pub length_unit: f64,
    /// Natural frequency of contacts with fixed colliders (ground, obstacles) \[Hz\]. Default 160
    /// (rapier's 60 Hz with damping ratio 10 let the wheels sink 0.8 mm, making the rolling
    /// radius 2.3 % short; 160 Hz with ratio 1 sinks 0.1 mm without jitter at dt = 1/240).
    pub static_contact_hz: f64,
    /// Damping ratio of contacts with fixed colliders. Default 1.
    pub static_contact_damping_ratio: f64,
}

impl Default for PhysicsConfig {
    fn default() -> Self {
        Self {
            dt: 1.0 / 240.0,
            friction: 1.0,
            gravity: 9.81,
            motor_damping: 1.0,
            motor_max_force: 1.5,
            solver_iterations: 4,
            contact_distance: 1e-3,
            length_unit: 0.1,
            static_contact_hz: 160.0,
            static_contact_damping_ratio: 1.0,
        }
    }
}

/// A planar pose of the robot's root frame, world frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose2 {
    /// \[m\]
    pub x: f64,
    /// \[m\]
    pub y: f64,
    /// Heading \[rad\].
    pub theta: f64,
}

#[derive(Debug, Clone, Copy)]
struct WheelMotor {
    joint: ImpulseJointHandle,
    sign: f64,
    max_force: f64,
}

/// The simulated world.
pub struct PhysicsWorld {
    world: rp::PhysicsWorld,
    cfg: PhysicsConfig,
    bodies: Vec<RigidBodyHandle>,
    link_names: Vec<String>,
    robot_colliders: Vec<ColliderHandle>,
    obstacle_colliders: Vec<ColliderHandle>,
    /// The obstacles' bounding boxes at construction and the poses they were computed at, for
    /// [`PhysicsWorld::clearances_near`] (recomputed for an obstacle whose pose has changed).
    obstacle_aabbs: Vec<(parry3d::math::Pose, parry3d::bounding_volume::Aabb)>,
    obstacles: Vec<Obstacle>,
    /// The kinematic body of each obstacle that moves (by obstacle index).
    mover_bodies: Vec<Option<MoverBody>>,
    /// Motors of the left wheels (one, or several for a skid-steer robot).
    left: Vec<WheelMotor>,
    /// Motors of the right wheels.
    right: Vec<WheelMotor>,
    steps: u64,
    contacts_buf: Vec<usize>,
    /// Accumulated wheel rotation (left, right) \[rad\], integrated from the joint speeds after
    /// every step (what a wheel encoder counts).
    wheel_angles: (f64, f64),
}

impl std::fmt::Debug for PhysicsWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PhysicsWorld")
            .field("cfg", &self.cfg)
            .field("time", &self.time())
            .field("bodies", &self.link_names)
            .field("obstacles", &self.obstacles.len())
            .finish()
    }
}

const ROBOT: Group = Group::GROUP_1;
const GROUND: Group = Group::GROUP_2;
const OBSTACLES: Group = Group::GROUP_3;

fn positive(key: &'static str, value: f64) -> Result<(), PhysicsError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(PhysicsError::InvalidConfig {
            key,
            expected: "a positive finite number",
            value,
        })
    }
}

fn mat3(m: &nalgebra::Matrix3<f64>) -> rp::Matrix {
    let c = m.cast::<f32>();
    rp::Matrix::from_cols_array(&[
        c[(0, 0)],
        c[(1, 0)],
        c[(2, 0)],
        c[(0, 1)],
        c[(1, 1)],
        c[(2, 1)],
        c[(0, 2)],
        c[(1, 2)],
        c[(2, 2)],
    ])
}

fn vec3(v: &Vector3<f64>) -> rp::Vector {
    rp::Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

/// Every setting in range: positive rates, forces and scales, friction and contact distance
/// ≥ 0, at least one solver iteration.
fn check_config(cfg: &PhysicsConfig) -> Result<(), PhysicsError> {
    positive("dt", cfg.dt)?;
    positive("gravity", cfg.gravity)?;
    positive("motor_damping", cfg.motor_damping)?;
    positive("motor_max_force", cfg.motor_max_force)?;
    positive("length_unit", cfg.length_unit)?;
    positive("static_contact_hz", cfg.static_contact_hz)?;
    positive(
        "static_contact_damping_ratio",
        cfg.static_contact_damping_ratio,
    )?;
    if !(cfg.friction.is_finite() && cfg.friction >= 0.0) {
        return Err(PhysicsError::InvalidConfig {
            key: "friction",
            expected: "a finite number ≥ 0",
            value: cfg.friction,
        });
    }
    if !(cfg.contact_distance.is_finite() && cfg.contact_distance >= 0.0) {
        return Err(PhysicsError::InvalidConfig {
            key: "contact_distance",
            expected: "a finite number ≥ 0 [m]",
            value: cfg.contact_distance,
        });
    }
    if cfg.solver_iterations == 0 {
        return Err(PhysicsError::InvalidConfig {
            key: "solver_iterations",
            expected: "at least 1",
            value: 0.0,
        });
    }
    Ok(())
}

/// Collision groups: a member of `member` that meets `filter`.
fn groups(member: Group, filter: Group) -> InteractionGroups {
    InteractionGroups::new(member, filter, InteractionTestMode::And)
}

/// The rapier world with the settings' gravity, step and solver, and the ground: a half-space
/// under z = 0 that meets the robot only.
fn empty_world(cfg: &PhysicsConfig) -> rp::PhysicsWorld {
    let mut world = rp::PhysicsWorld::new();
    world.gravity = rp::Vector::new(0.0, 0.0, -cfg.gravity as f32);
    world.integration_parameters.dt = cfg.dt as f32;
    world.integration_parameters.num_solver_iterations = cfg.solver_iterations;
    world.integration_parameters.length_unit = cfg.length_unit as f32;
    let soft = &mut world.integration_parameters.static_contact_softness;
    soft.natural_frequency = cfg.static_contact_hz as f32;
    soft.damping_ratio = cfg.static_contact_damping_ratio as f32;
    let ground = ColliderBuilder::halfspace(nalgebra::Unit::new_unchecked(rp::Vector::Z))
        .friction(cfg.friction as f32)
        .collision_groups(groups(GROUND, ROBOT))
        .build();
    world.colliders.insert(ground);
    world
}

/// The robot's bodies as dynamic rigid bodies placed from `start`, each with its colliders;
/// returns the body handles (in the description's order) and the collider handles.
fn add_robot_bodies(
    world: &mut rp::PhysicsWorld,
    robot: &RobotDescription,
    start: Pose2,
    cfg: &PhysicsConfig,
) -> Result<(Vec<RigidBodyHandle>, Vec<ColliderHandle>), PhysicsError> {
    let start_iso = Isometry3::from_parts(
        Translation3::new(start.x, start.y, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, start.theta),
    );
    let mut bodies = Vec::with_capacity(robot.bodies.len());
    let mut robot_colliders = Vec::new();
    for b in &robot.bodies {
        let pose = to_pose(&(start_iso * b.pose_in_root));
        let mprops =
            MassProperties::with_inertia_matrix(vec3(&b.com), b.mass as f32, mat3(&b.inertia));
        let rb = RigidBodyBuilder::dynamic()
            .pose(pose)
            .additional_mass_properties(mprops)
            .can_sleep(false)
            .build();
        let h = world.bodies.insert(rb);
        for c in &b.colliders {
            robot_colliders.push(add_robot_collider(world, h, c, cfg)?);
        }
        bodies.push(h);
    }
    Ok((bodies, robot_colliders))
}

/// A robot collider's rapier shape and its pose in the body (rapier's cylinders stand on y,
/// the description's on z).
fn robot_shape(c: &RobotCollider) -> Result<(SharedShape, Isometry3<f64>), PhysicsError> {
    let y_to_z = UnitQuaternion::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0);
    Ok(match &c.shape {
        CollisionShape::Box { half_extents: e } => (
            SharedShape::cuboid(e[0] as f32, e[1] as f32, e[2] as f32),
            c.pose_in_body,
        ),
        CollisionShape::Cylinder {
            radius,
            half_length,
        } => (
            SharedShape::cylinder(*half_length as f32, *radius as f32),
            c.pose_in_body * y_to_z,
        ),
        CollisionShape::Capsule {
            radius,
            half_length,
        } => (
            SharedShape::capsule_z(*half_length as f32, *radius as f32),
            c.pose_in_body,
        ),
        CollisionShape::Sphere { radius } => (SharedShape::ball(*radius as f32), c.pose_in_body),
        CollisionShape::Mesh { vertices, .. } => {
            // A dynamic body's mesh collides as its convex hull.
            let pts: Vec<rp::Vector> = vertices
                .iter()
                .map(|v| rp::Vector::new(v[0] as f32, v[1] as f32, v[2] as f32))
                .collect();
            let shape = SharedShape::convex_hull(&pts).ok_or_else(|| PhysicsError::Mesh {
                link: c.link.clone(),
                message: "the mesh's convex hull is degenerate".into(),
            })?;
            (shape, c.pose_in_body)
        }
    })
}

/// Collider `c` on body `h`. A wheel's cylinder meets obstacles and rolls on a ball of its
/// radius (inserted first) that meets the ground; other wheel colliders have the settings'
/// friction, the chassis none.
fn add_robot_collider(
    world: &mut rp::PhysicsWorld,
    h: RigidBodyHandle,
    c: &RobotCollider,
    cfg: &PhysicsConfig,
) -> Result<ColliderHandle, PhysicsError> {
    let (shape, local) = robot_shape(c)?;
    let wheel_ball = match (&c.shape, c.is_wheel) {
        (CollisionShape::Cylinder { radius, .. }, true) => Some(*radius),
        _ => None,
    };
    let mut builder = ColliderBuilder::new(shape)
        .position(to_pose(&local))
        .density(0.0)
        .restitution(0.0);
    builder = if let Some(radius) = wheel_ball {
        // The wheel's cylinder meets obstacles; its ground contact is the ball below.
        let ball = ColliderBuilder::ball(radius as f32)
            .position(to_pose(&local))
            .density(0.0)
            .restitution(0.0)
            .friction(cfg.friction as f32)
            .collision_groups(groups(ROBOT, GROUND))
            .build();
        world
            .colliders
            .insert_with_parent(ball, h, &mut world.bodies);
        builder
            .friction(cfg.friction as f32)
            .collision_groups(groups(ROBOT, OBSTACLES))
    } else if c.is_wheel {
        builder
            .friction(cfg.friction as f32)
            .collision_groups(groups(ROBOT, GROUND | OBSTACLES))
    } else {
        builder
            .friction(0.0)
            .friction_combine_rule(CoefficientCombineRule::Min)
            .collision_groups(groups(ROBOT, GROUND | OBSTACLES))
    };
    Ok(world
        .colliders
        .insert_with_parent(builder.build(), h, &mut world.bodies))
}

/// The robot's joints as impulse joints between the body handles (the joint axis along the
/// local x of both frames); returns their handles in the description's order.
fn add_joints(
    world: &mut rp::PhysicsWorld,
    robot: &RobotDescription,
    bodies: &[RigidBodyHandle],
) -> Vec<ImpulseJointHandle> {
    let mut joint_handles = Vec::with_capacity(robot.joints.len());
    for j in &robot.joints {
        let x_to_axis = UnitQuaternion::rotation_between(&Vector3::x(), &j.axis)
            .unwrap_or_else(|| UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::PI));
        let frame1 = j.frame_in_parent * Isometry3::from_parts(Translation3::identity(), x_to_axis);
        let frame2 = Isometry3::from_parts(Translation3::identity(), x_to_axis);
        let mut builder = match j.kind {
            JointKind::Continuous => GenericJointBuilder::new(JointAxesMask::LOCKED_REVOLUTE_AXES),
            JointKind::Revolute { lower, upper } => {
                GenericJointBuilder::new(JointAxesMask::LOCKED_REVOLUTE_AXES)
                    .limits(JointAxis::AngX, [lower as f32, upper as f32])
            }
            JointKind::Prismatic { lower, upper } => {
                GenericJointBuilder::new(JointAxesMask::LOCKED_PRISMATIC_AXES)
                    .limits(JointAxis::LinX, [lower as f32, upper as f32])
            }
        };
        builder = builder
            .local_frame1(to_pose(&frame1))
            .local_frame2(to_pose(&frame2))
            .contacts_enabled(false);
        let jh =
            world
                .impulse_joints
                .insert(bodies[j.parent], bodies[j.child], builder.build(), true);
        joint_handles.push(jh);
    }
    joint_handles
}

/// A moving obstacle's kinematic body and the translation it started at.
#[derive(Debug, Clone, Copy)]
struct MoverBody {
    body: RigidBodyHandle,
    start: rp::Vector,
}

/// The obstacles as colliders that meet the robot only, each with its index as user data:
/// fixed, or on a kinematic position-based body for an obstacle that moves (issue #51);
/// returns their handles and the movers' bodies (by obstacle index).
fn add_obstacles(
    world: &mut rp::PhysicsWorld,
    obstacles: &[Obstacle],
    cfg: &PhysicsConfig,
) -> (Vec<ColliderHandle>, Vec<Option<MoverBody>>) {
    let mut obstacle_colliders = Vec::with_capacity(obstacles.len());
    let mut movers = Vec::with_capacity(obstacles.len());
    for (i, o) in obstacles.iter().enumerate() {
        let builder = ColliderBuilder::new(o.shape().clone())
            .friction(cfg.friction as f32)
            .collision_groups(groups(OBSTACLES, ROBOT))
            .user_data(i as u128);
        if o.spec.motion.is_some() {
            let pose = *o.shape_pose();
            let body = world.bodies.insert(
                RigidBodyBuilder::kinematic_position_based()
                    .pose(pose)
                    .build(),
            );
            let h = world
                .colliders
                .insert_with_parent(builder.build(), body, &mut world.bodies);
            obstacle_colliders.push(h);
            movers.push(Some(MoverBody {
                body,
                start: pose.translation,
            }));
        } else {
            let c = builder.position(*o.shape_pose()).build();
            obstacle_colliders.push(world.colliders.insert(c));
            movers.push(None);
        }
    }
    (obstacle_colliders, movers)
}

impl PhysicsWorld {
    /// Builds the world with the robot's root frame at `start` (on the ground) and the
    /// obstacles as fixed colliders (obstacle index = position in `obstacles`). In phases: the
    /// settings checked, the rapier world with its ground, the robot's bodies and colliders,
    /// its joints and wheel motors, the obstacles.
    pub fn new(
        robot: &RobotDescription,
        start: Pose2,
        obstacles: &[Obstacle],
        cfg: &PhysicsConfig,
    ) -> Result<Self, PhysicsError> {
        check_config(cfg)?;
        if !(start.x.is_finite() && start.y.is_finite() && start.theta.is_finite()) {
            return Err(PhysicsError::InvalidStart(start));
        }
        let mut world = empty_world(cfg);
        let (bodies, robot_colliders) = add_robot_bodies(&mut world, robot, start, cfg)?;
        let joint_handles = add_joints(&mut world, robot, &bodies);
        let motor = |w: &crate::robot::Wheel| WheelMotor {
            joint: joint_handles[w.joint],
            sign: w.forward_sign,
            max_force: w.effort_limit.unwrap_or(cfg.motor_max_force),
        };
        let left = robot.wheels.left.iter().map(motor).collect();
        let right = robot.wheels.right.iter().map(motor).collect();
        let (obstacle_colliders, mover_bodies) = add_obstacles(&mut world, obstacles, cfg);
        let link_names = robot.bodies.iter().map(|b| b.name.clone()).collect();
        let obstacle_aabbs = obstacle_colliders
            .iter()
            .map(|&h| {
                let c = &world.colliders[h];
                (*c.position(), c.compute_aabb())
            })
            .collect();
        let mut out = Self {
            world,
            cfg: *cfg,
            bodies,
            link_names,
            robot_colliders,
            obstacle_colliders,
            obstacle_aabbs,
            obstacles: obstacles.to_vec(),
            mover_bodies,
            left,
            right,
            steps: 0,
            contacts_buf: Vec::new(),
            wheel_angles: (0.0, 0.0),
        };
        out.set_wheel_speeds(0.0, 0.0);
        Ok(out)
    }

    /// Sets the wheel motors' velocity targets [rad/s], positive = rolling forward: every wheel
    /// of a side gets that side's speed. Non-finite values are treated as 0.
    pub fn set_wheel_speeds(&mut self, left_rad_s: f64, right_rad_s: f64) {
        let damping = self.cfg.motor_damping as f32;
        let sides = [(&self.left, left_rad_s), (&self.right, right_rad_s)];
        for (m, w) in sides
            .into_iter()
            .flat_map(|(ms, w)| ms.iter().map(move |m| (m, w)))
        {
            let w = if w.is_finite() { w } else { 0.0 };
            if let Some(j) = self.world.impulse_joints.get_mut(m.joint, true) {
                j.data
                    .set_motor_model(JointAxis::AngX, MotorModel::ForceBased)
                    .set_motor_velocity(JointAxis::AngX, (m.sign * w) as f32, damping)
                    .set_motor_max_force(JointAxis::AngX, m.max_force as f32);
            }
        }
    }

    /// Advances the simulation by one `dt`.
    pub fn step(&mut self) {
        self.world.step();
        self.steps += 1;
        let (wl, wr) = self.wheel_speeds();
        self.wheel_angles.0 += wl * self.cfg.dt;
        self.wheel_angles.1 += wr * self.cfg.dt;
        self.contacts_buf.clear();
        for (i, &oc) in self.obstacle_colliders.iter().enumerate() {
            let hit = self.world.narrow_phase.contact_pairs_with(oc).any(|pair| {
                pair.has_any_active_contact()
                    && pair
                        .find_deepest_contact()
                        .is_some_and(|(_, c)| (c.dist as f64) <= self.cfg.contact_distance)
            });
            if hit {
                self.contacts_buf.push(i);
            }
        }
    }

    /// Moves obstacle `i` (one that moves: others are left alone) to `offset` \[m\] from its
    /// starting place in the x–y plane by the end of the next [`PhysicsWorld::step`].
    pub fn move_obstacle(&mut self, i: usize, offset: [f64; 2]) {
        let Some(Some(m)) = self.mover_bodies.get(i) else {
            return;
        };
        let to = m.start + rp::Vector::new(offset[0] as f32, offset[1] as f32, 0.0);
        if let Some(b) = self.world.bodies.get_mut(m.body) {
            b.set_next_kinematic_translation(to);
        }
    }

    /// Simulated time \[s\] (steps × dt).
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.cfg.dt
    }

    /// The configuration.
    pub fn config(&self) -> &PhysicsConfig {
        &self.cfg
    }

    fn root_iso(&self) -> Isometry3<f64> {
        let b = &self.world.bodies[self.bodies[0]];
        Isometry3::<f32>::from(*b.position()).cast::<f64>()
    }

    /// The robot's true planar state; the reference point is the root frame's origin
    /// (base_footprint, on the ground).
    pub fn truth(&self) -> TruthState {
        let root = &self.world.bodies[self.bodies[0]];
        let iso = self.root_iso();
        let r = iso.rotation.to_rotation_matrix();
        let theta = r[(1, 0)].atan2(r[(0, 0)]);
        let p = *root.position();
        let vel = root.velocity_at_point(p.translation);
        let (vx, vy) = (vel.x as f64, vel.y as f64);
        let (s, c) = theta.sin_cos();
        let (wheel_left, wheel_right) = self.wheel_speeds();
        TruthState {
            t: self.time(),
            x: iso.translation.x,
            y: iso.translation.y,
            theta,
            vx,
            vy,
            v_body: vx * c + vy * s,
            omega: root.angvel().z as f64,
            wheel_left,
            wheel_right,
            wheel_angle_left: self.wheel_angles.0,
            wheel_angle_right: self.wheel_angles.1,
        }
    }

    /// Height of the root frame above the ground \[m\] (0 at rest on flat ground).
    pub fn root_height(&self) -> f64 {
        self.root_iso().translation.z
    }

    /// Roll/pitch magnitude: angle between the root frame's z axis and the world z axis \[rad\].
    pub fn tilt(&self) -> f64 {
        let r = self.root_iso().rotation.to_rotation_matrix();
        r[(2, 2)].clamp(-1.0, 1.0).acos()
    }

    /// Indices of the obstacles in contact with any robot collider after the last step.
    pub fn contacts(&self) -> impl Iterator<Item = usize> + '_ {
        self.contacts_buf.iter().copied()
    }

    /// True minimum distance from the robot's colliders to each obstacle \[m\] (parry query on
    /// the current poses); negative = penetration depth. `out` is resized to the obstacle count.
    pub fn clearances(&self, out: &mut Vec<f64>) {
        out.clear();
        out.extend((0..self.obstacle_colliders.len()).map(|i| self.clearance(i)));
    }

    /// The true clearance to obstacle `i` (as in [`PhysicsWorld::clearances`]); +∞ for an
    /// index out of range.
    pub fn clearance(&self, i: usize) -> f64 {
        let Some(o) = self
            .obstacle_colliders
            .get(i)
            .map(|&h| &self.world.colliders[h])
        else {
            return f64::INFINITY;
        };
        let mut best = f64::INFINITY;
        for &rc in &self.robot_colliders {
            let r = &self.world.colliders[rc];
            let d = match parry3d::query::distance(r.position(), r.shape(), o.position(), o.shape())
            {
                Ok(d) if d.distance > 0.0 => d.distance as f64,
                _ => penetration(r, o),
            };
            best = best.min(d);
        }
        best
    }

    /// The clearances where they can matter, found through bounding boxes: `out[i]` is
    /// obstacle i's true clearance (as [`PhysicsWorld::clearances`] computes it) and `exact[i]`
    /// is true, unless the distance between the robot's bounding box and the obstacle's is
    /// above both `within` and the smallest true clearance; then `out[i]` is that distance, a
    /// lower bound of the clearance. So the minimum over `out` is the true minimum, and every
    /// clearance at or below `within` is exact. A non-finite pose gives non-finite boxes and
    /// is always queried exactly (its clearance is then not finite either).
    pub fn clearances_near(&self, within: f64, out: &mut Vec<f64>, exact: &mut Vec<bool>) {
        out.clear();
        exact.clear();
        let mut robot: Option<parry3d::bounding_volume::Aabb> = None;
        for &rc in &self.robot_colliders {
            let b = self.world.colliders[rc].compute_aabb();
            if !finite_aabb(&b) {
                robot = None;
                break;
            }
            robot = Some(match robot {
                Some(a) => merged_aabb(&a, &b),
                None => b,
            });
        }
        let mut least = f64::INFINITY;
        for (&oc, (pose, cached)) in self.obstacle_colliders.iter().zip(&self.obstacle_aabbs) {
            let c = &self.world.colliders[oc];
            let b = if c.position() == pose {
                *cached
            } else {
                c.compute_aabb()
            };
            let lb = robot.map_or(f64::NAN, |r| aabb_gap(&r, &b));
            // NaN (a non-finite pose) is not provably far: queried exactly
            out.push(lb);
            exact.push(lb.partial_cmp(&within) != Some(Ordering::Greater));
        }
        for i in 0..out.len() {
            if exact[i] {
                out[i] = self.clearance(i);
                least = least.min(out[i]);
            }
        }
        for i in 0..out.len() {
            if !exact[i] && out[i].partial_cmp(&least) != Some(Ordering::Greater) {
                out[i] = self.clearance(i);
                exact[i] = true;
                least = least.min(out[i]);
            }
        }
    }

    /// World poses of the robot's bodies: (body link name, translation, rotation xyzw).
    pub fn link_poses(&self) -> impl Iterator<Item = (&str, [f32; 3], [f32; 4])> + '_ {
        self.bodies.iter().zip(&self.link_names).map(|(h, n)| {
            let p = self.world.bodies[*h].position();
            let t = p.translation;
            let q = p.rotation;
            (n.as_str(), [t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
        })
    }

    /// Current wheel angular speeds (left, right) relative to the base [rad/s], positive =
    /// rolling forward; for a skid-steer robot, the mean over the wheels of each side.
    pub fn wheel_speeds(&self) -> (f64, f64) {
        let base = &self.world.bodies[self.bodies[0]];
        let w = |m: &WheelMotor| {
            let Some(j) = self.world.impulse_joints.get(m.joint) else {
                return 0.0;
            };
            let child = &self.world.bodies[j.body2()];
            let axis_local = j.data.local_axis2();
            let axis_world = child.rotation() * axis_local;
            let rel = child.angvel() - base.angvel();
            m.sign * rel.dot(axis_world) as f64
        };
        let mean = |ms: &[WheelMotor]| ms.iter().map(&w).sum::<f64>() / ms.len() as f64;
        (mean(&self.left), mean(&self.right))
    }

    /// The obstacles, in index order.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }
}

/// Signed contact distance (≤ 0: penetration depth) between a robot collider and an obstacle.
/// The depth is symmetric, but parry 0.31.1's `contact(support map, half-space)` applies the
/// relative pose the wrong way round (it passes `pos12` where `pos12⁻¹` is needed; its
/// `distance` does not), which reported −0.47 m for a robot pressed centimetres into a
/// half-space wall. A half-space is therefore always queried as the first shape.
/// Every corner of the box is a finite number.
fn finite_aabb(a: &parry3d::bounding_volume::Aabb) -> bool {
    [a.mins.x, a.mins.y, a.mins.z, a.maxs.x, a.maxs.y, a.maxs.z]
        .iter()
        .all(|v| v.is_finite())
}

/// The smallest box holding both.
fn merged_aabb(
    a: &parry3d::bounding_volume::Aabb,
    b: &parry3d::bounding_volume::Aabb,
) -> parry3d::bounding_volume::Aabb {
    let mut m = *a;
    m.mins.x = a.mins.x.min(b.mins.x);
    m.mins.y = a.mins.y.min(b.mins.y);
    m.mins.z = a.mins.z.min(b.mins.z);
    m.maxs.x = a.maxs.x.max(b.maxs.x);
    m.maxs.y = a.maxs.y.max(b.maxs.y);
    m.maxs.z = a.maxs.z.max(b.maxs.z);
    m
}

/// A lower bound of the distance between anything inside box `a` and anything inside box `b`
/// \[m\]: the boxes' gap, computed in f64 from their f32 corners, less 1 mm (far above the
/// rounding of the boxes and of parry's f32 distance). NaN when a corner is not finite (the
/// caller then queries exactly).
fn aabb_gap(a: &parry3d::bounding_volume::Aabb, b: &parry3d::bounding_volume::Aabb) -> f64 {
    if !(finite_aabb(a) && finite_aabb(b)) {
        return f64::NAN;
    }
    let axis = |amin: f32, amax: f32, bmin: f32, bmax: f32| {
        (f64::from(bmin) - f64::from(amax))
            .max(f64::from(amin) - f64::from(bmax))
            .max(0.0)
    };
    let gx = axis(a.mins.x, a.maxs.x, b.mins.x, b.maxs.x);
    let gy = axis(a.mins.y, a.maxs.y, b.mins.y, b.maxs.y);
    let gz = axis(a.mins.z, a.maxs.z, b.mins.z, b.maxs.z);
    (gx * gx + gy * gy + gz * gz).sqrt() - 1e-3
}

fn penetration(robot: &rp::Collider, obstacle: &rp::Collider) -> f64 {
    let (a, b) = if obstacle.shape().as_halfspace().is_some() {
        (obstacle, robot)
    } else {
        (robot, obstacle)
    };
    parry3d::query::contact(a.position(), a.shape(), b.position(), b.shape(), 0.0)
        .ok()
        .flatten()
        .map(|c| (c.dist as f64).min(0.0))
        .unwrap_or(0.0)
}

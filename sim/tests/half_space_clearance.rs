//! Pressing the robot into a `half_space` wall: the reported clearance is the real (small)
//! penetration of its colliders, cross-checked against support points computed here from the
//! bodies' poses and the URDF shapes — not the −0.47 m that parry 0.31.1's
//! `contact(support map, half-space)` gives (it uses the relative pose the wrong way round).

use std::path::PathBuf;

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};

use ftcbf_sim::drivetrain::{BodyCommand, Drive, DriveConfig};
use ftcbf_sim::obstacles::{Obstacle, ObstacleSpec, ShapeSpec};
use ftcbf_sim::physics::{PhysicsConfig, PhysicsWorld, Pose2};
use ftcbf_sim::robot::{CollisionShape, LoadOptions, RobotDescription};

fn burger() -> RobotDescription {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../robots/turtlebot3_burger.urdf");
    RobotDescription::from_file(p, &LoadOptions::default()).unwrap()
}

/// The point of `shape` (collider frame, z-axis cylinders as in the URDF) farthest along `d`.
fn support(shape: &CollisionShape, d: Vector3<f64>) -> Point3<f64> {
    let s = |x: f64| if x >= 0.0 { 1.0 } else { -1.0 };
    let disc = |r: f64, h: f64| {
        let xy = d.xy();
        let n = xy.norm();
        let (x, y) = if n > 1e-12 {
            (r * xy.x / n, r * xy.y / n)
        } else {
            (0.0, 0.0)
        };
        Point3::new(x, y, s(d.z) * h)
    };
    match shape {
        CollisionShape::Box { half_extents: h } => {
            Point3::new(s(d.x) * h[0], s(d.y) * h[1], s(d.z) * h[2])
        }
        CollisionShape::Cylinder {
            radius,
            half_length,
        } => disc(*radius, *half_length),
        CollisionShape::Sphere { radius } => Point3::from(d.normalize() * *radius),
        CollisionShape::Capsule {
            radius,
            half_length,
        } => Point3::new(0.0, 0.0, s(d.z) * half_length) + d.normalize() * *radius,
        CollisionShape::Mesh { vertices, .. } => vertices
            .iter()
            .map(|v| Point3::new(v[0], v[1], v[2]))
            .max_by(|a, b| a.coords.dot(&d).total_cmp(&b.coords.dot(&d)))
            .unwrap(),
    }
}

/// Signed distance of the robot's deepest collider point to the wall plane (through `p0`,
/// outward normal `n`): negative = that far inside the solid.
fn expected_clearance(
    robot: &RobotDescription,
    w: &PhysicsWorld,
    p0: Vector3<f64>,
    n: Vector3<f64>,
) -> f64 {
    let poses: Vec<Isometry3<f64>> = w
        .link_poses()
        .map(|(_, t, q)| {
            Isometry3::from_parts(
                Translation3::new(t[0] as f64, t[1] as f64, t[2] as f64),
                UnitQuaternion::from_quaternion(Quaternion::new(
                    q[3] as f64,
                    q[0] as f64,
                    q[1] as f64,
                    q[2] as f64,
                )),
            )
        })
        .collect();
    let mut best = f64::INFINITY;
    for (body, pose) in robot.bodies.iter().zip(&poses) {
        for c in &body.colliders {
            let to_world = pose * c.pose_in_body;
            let d_local = to_world.rotation.inverse() * (-n);
            let p = to_world * support(&c.shape, d_local);
            best = best.min(n.dot(&(p.coords - p0)));
        }
    }
    best
}

fn wall(position: [f64; 3], normal: [f64; 3]) -> Obstacle {
    Obstacle::from_spec(
        &ObstacleSpec {
            name: "wall".into(),
            position,
            rpy: [0.0; 3],
            shape: ShapeSpec::HalfSpace { normal },
            motion: None,
            tracker: None,
        },
        None,
    )
    .unwrap()
}

#[test]
fn pressing_into_a_half_space_wall_reports_the_real_penetration() {
    let robot = burger();
    let cfg = PhysicsConfig::default();
    let drive = Drive::new(
        &robot.wheels.geometry,
        &robot.limits,
        DriveConfig::default(),
    )
    .unwrap();
    // Facing the wall head on (the outside_model scene: wall y = −0.3, robot heading −y), at an
    // angle, and backing into a wall behind the robot.
    let cases = [
        (
            "facing −y",
            [0.0, -0.3, 0.0],
            [0.0, 1.0, 0.0],
            -std::f64::consts::FRAC_PI_2,
            1.0,
        ),
        (
            "at 30°",
            [0.5, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            std::f64::consts::FRAC_PI_6,
            1.0,
        ),
        ("reversing", [-0.4, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0, -1.0),
    ];
    for (label, p0, n, theta, dir) in cases {
        let mut w = PhysicsWorld::new(
            &robot,
            Pose2 {
                x: 0.0,
                y: 0.0,
                theta,
            },
            &[wall(p0, n)],
            &cfg,
        )
        .unwrap();
        let (l, r) = drive.wheel_speeds(BodyCommand {
            v: dir * robot.limits.v_max,
            omega: 0.0,
        });
        w.set_wheel_speeds(l, r);
        let (p0, n) = (Vector3::from(p0), Vector3::from(n));
        let mut out = Vec::new();
        let mut min_reported = f64::INFINITY;
        let mut worst_gap: f64 = 0.0;
        let mut touched = false;
        for _ in 0..(4.0 / cfg.dt).round() as usize {
            w.step();
            w.clearances(&mut out);
            let want = expected_clearance(&robot, &w, p0, n);
            worst_gap = worst_gap.max((out[0] - want).abs());
            min_reported = min_reported.min(out[0]);
            touched |= w.contacts().any(|i| i == 0);
        }
        println!(
            "{label}: min clearance {min_reported:.5} m, |reported − support| ≤ {worst_gap:.2e} m"
        );
        assert!(touched, "{label}: the robot never reached the wall");
        // Pressed at full motor force it sinks millimetres into the contact, never decimetres.
        assert!(
            min_reported > -0.02 && min_reported < 0.002,
            "{label}: min clearance {min_reported} m"
        );
        // And the number is the geometry's (f32 physics poses: 1e-4 m).
        assert!(
            worst_gap < 1e-4,
            "{label}: reported clearance differs from the support-point clearance by {worst_gap} m"
        );
    }
}

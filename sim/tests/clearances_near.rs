//! The monitor's pruned clearances (issue #52): exact at or below the threshold and at the
//! minimum, a lower bound of the true clearance elsewhere, and far obstacles not queried.

use std::path::PathBuf;

use ftcbf_sim::drivetrain::{BodyCommand, Drive, DriveConfig};
use ftcbf_sim::obstacles::{Obstacle, ObstacleSpec, ShapeSpec};
use ftcbf_sim::physics::{PhysicsConfig, PhysicsWorld, Pose2};
use ftcbf_sim::robot::{LoadOptions, RobotDescription};

fn burger() -> RobotDescription {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../robots/turtlebot3_burger.urdf");
    RobotDescription::from_file(p, &LoadOptions::default()).unwrap()
}

fn obstacle(name: String, position: [f64; 3], shape: ShapeSpec) -> Obstacle {
    Obstacle::from_spec(
        &ObstacleSpec {
            name,
            position,
            rpy: [0.0; 3],
            shape,
            motion: None,
            tracker: None,
        },
        None,
    )
    .unwrap()
}

#[test]
fn pruned_clearances_keep_the_minimum_and_every_near_value_exact() {
    let robot = burger();
    let cfg = PhysicsConfig::default();
    // A block the robot drives into (contact: negative clearances), one it passes 5 cm
    // beside, and 60 cylinders 2–4 m away.
    let mut obstacles = vec![
        obstacle(
            "ahead".into(),
            [0.9, 0.0, 0.1],
            ShapeSpec::Cuboid {
                half_extents: [0.1, 0.3, 0.1],
            },
        ),
        obstacle(
            "beside".into(),
            [0.3, 0.089 + 0.05 + 0.1, 0.1],
            ShapeSpec::Cuboid {
                half_extents: [0.1, 0.1, 0.1],
            },
        ),
    ];
    for i in 0..60 {
        let y = if i % 2 == 0 { 2.0 } else { -2.0 } + 0.05 * (i / 2) as f64;
        obstacles.push(obstacle(
            format!("c{i}"),
            [-1.0 + 0.1 * i as f64, y, 0.3],
            ShapeSpec::Cylinder {
                radius: 0.1,
                half_height: 0.3,
            },
        ));
    }
    let mut w = PhysicsWorld::new(&robot, Pose2::default(), &obstacles, &cfg).unwrap();
    let drive = Drive::new(
        &robot.wheels.geometry,
        &robot.limits,
        DriveConfig::default(),
    )
    .unwrap();
    let (l, r) = drive.wheel_speeds(BodyCommand { v: 0.2, omega: 0.0 });
    w.set_wheel_speeds(l, r);
    let within = 0.005;
    let (mut full, mut near, mut exact) = (Vec::new(), Vec::new(), Vec::new());
    let (mut queried, mut total, mut least_seen) = (0usize, 0usize, f64::INFINITY);
    for _ in 0..(5.0 / cfg.dt).round() as usize {
        w.step();
        w.clearances(&mut full);
        w.clearances_near(within, &mut near, &mut exact);
        assert_eq!(near.len(), full.len());
        let min_full = full.iter().copied().fold(f64::INFINITY, f64::min);
        let min_near = near.iter().copied().fold(f64::INFINITY, f64::min);
        assert_eq!(min_full.to_bits(), min_near.to_bits(), "t = {}", w.time());
        least_seen = least_seen.min(min_full);
        for i in 0..full.len() {
            if exact[i] {
                assert_eq!(full[i].to_bits(), near[i].to_bits(), "obstacle {i}");
            } else {
                assert!(
                    near[i] <= full[i],
                    "obstacle {i}: bound {} > {}",
                    near[i],
                    full[i]
                );
                assert!(near[i] > within && near[i] > min_full, "obstacle {i}");
            }
            if full[i] <= within {
                assert!(exact[i], "obstacle {i} at {} not queried", full[i]);
            }
        }
        queried += exact.iter().filter(|&&e| e).count();
        total += exact.len();
    }
    assert!(least_seen < 0.0, "the robot never touched the block ahead");
    // The far cylinders are almost never queried: at most a tenth of all the queries.
    assert!(
        queried * 10 <= total,
        "{queried} of {total} clearances queried"
    );
}
